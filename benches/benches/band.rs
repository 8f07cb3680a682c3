//! `cargo bench -p volcal_benches --bench band`: time of the map's simultaneous band
//! (`volcal::band::simultaneous_band`, 1 000 draws) on the patent example's solution, over the
//! grid the solve report searches for the largest error (21 points along the longest travel)
//! and the example's three probe offsets: what the band adds to `volcal solve` and
//! `volcal report`.

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use std::time::Duration;
use volcal::band::{simultaneous_band, BAND_DRAWS, BAND_LEVEL};
use volcal::{predict, Axis};

fn bench(c: &mut Criterion) {
    let case = volcal_benches::patent();
    let sol = volcal::solve(&case.layout, &case.obs, &case.options, &[]).unwrap();
    let unc = sol.uncertainty();
    let travel = case.layout.travel;
    let step = Axis::ALL.iter().map(|&a| travel.length(a)).fold(0.0, f64::max) / 20.0;
    let grid = predict::grid(&travel, step);
    let mut offsets: Vec<Vector3<f64>> = Vec::new();
    for p in &case.obs.p {
        if !offsets.iter().any(|o| (o - p).norm() < 1e-9) {
            offsets.push(*p);
        }
    }
    let band = simultaneous_band(&sol.model, &unc, &grid, &offsets, BAND_LEVEL, BAND_DRAWS, 0).unwrap();
    eprintln!(
        "band over {} values ({} points x {} offsets): k = {:.3}",
        band.values,
        grid.len(),
        offsets.len(),
        band.k
    );
    let mut g = c.benchmark_group("band");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    g.bench_function(case.name, |b| {
        b.iter(|| simultaneous_band(&sol.model, &unc, &grid, &offsets, BAND_LEVEL, BAND_DRAWS, 0).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
