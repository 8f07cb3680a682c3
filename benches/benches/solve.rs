//! `cargo bench -p volcal_benches`: time of `volcal::solve` on the patent's example and on a
//! large campaign, with the benchmark's representation (cubic B-splines of 12 and 52 intervals)
//! and with `representation: auto`. Targets on a 2-core machine: under 50 ms and under 1 s.

use criterion::{criterion_group, criterion_main, Criterion};
use std::time::Duration;

fn bench(c: &mut Criterion) {
    for (case, samples) in [(volcal_benches::patent(), 20), (volcal_benches::large(), 10)] {
        assert_eq!(case.obs.len(), if case.layout.n_params < 500 { 7_500 } else { 100_000 });
        let mut g = c.benchmark_group("solve");
        g.sample_size(samples).measurement_time(Duration::from_secs(if samples == 20 { 10 } else { 30 }));
        g.bench_function(case.name, |b| b.iter(|| volcal::solve(&case.layout, &case.obs, &case.options, &[]).unwrap()));
        // The same readings with `representation: auto` (the default of a machine file that
        // names none): knots from the data, REML smoothing, refinement tests.
        let auto = volcal::flexibility::Auto::default();
        let t = &case.layout;
        g.bench_function(format!("{}, representation: auto", case.name), |b| {
            b.iter(|| {
                volcal::flexibility::solve_auto(&t.topology, t.travel, &case.obs, &case.options, &auto, &[None; 18])
                    .unwrap()
            })
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
