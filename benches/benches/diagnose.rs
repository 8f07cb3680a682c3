//! `cargo bench -p volcal_benches --bench diagnose`: time of `volcal::diagnose` on the patent's
//! example campaign (7,500 readings, 273 parameters), clean and with a drift and a periodic
//! pitch error hidden in it. Target on a 2-core machine: under 10 s.

use criterion::{criterion_group, criterion_main, Criterion};
use std::time::Duration;
use volcal::diagnose::{diagnose, DiagnoseOptions};

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10).measurement_time(Duration::from_secs(60));
    for (case, expected) in [
        (volcal_benches::patent(), vec![]),
        (volcal_benches::patent_with_effects(), vec!["setup_drift", "periodic_pitch"]),
    ] {
        let opts = DiagnoseOptions::new(case.options.clone(), case.optics);
        // What is timed is a diagnosis that finds what is there.
        let d = diagnose(&case.layout, &case.obs, &opts).unwrap();
        let mut found: Vec<&str> = d.effects.iter().map(|e| e.id.as_str()).collect();
        found.sort_unstable();
        let mut want = expected.clone();
        want.sort_unstable();
        assert_eq!(found, want, "{}: found {found:?}", case.name);
        g.bench_function(case.name, |b| b.iter(|| diagnose(&case.layout, &case.obs, &opts).unwrap()));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
