//! `cargo bench -p volcal_benches`: time of `volcal::solve` on the patent's example and on a
//! large campaign. Targets on a 2-core machine: under 50 ms and under 1 s.

use criterion::{criterion_group, criterion_main, Criterion};
use std::time::Duration;

fn bench(c: &mut Criterion) {
    for (case, samples) in [(volcal_benches::patent(), 20), (volcal_benches::large(), 10)] {
        assert_eq!(case.obs.len(), if case.layout.n_params < 500 { 7_500 } else { 100_000 });
        let mut g = c.benchmark_group("solve");
        g.sample_size(samples).measurement_time(Duration::from_secs(if samples == 20 { 10 } else { 30 }));
        g.bench_function(case.name, |b| b.iter(|| volcal::solve(&case.layout, &case.obs, &case.options, &[]).unwrap()));
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
