//! Benchmark: the solve of the paper's tracer scenario (Han et al. 2021): 4 stations x 132
//! points along the 12 edges of the cuboid, 201 error-model coefficients + 12 station
//! coordinates, datum gauge, Levenberg-Marquardt from nominal stations 50 mm off, including the
//! identifiability analysis (twice: at the start and at the solution) and the covariance.
//! Target: under 1 s. Run: `cargo bench -p volcal_benches --bench paper_solve`.

use criterion::{criterion_group, criterion_main, Criterion};
use volcal::campaign::{prepare, ScaleExpansion};
use volcal::{solve, Gauge, SolveOptions};
use volcal_sim::{paper, simulate, Deflector, EnvironmentSim, Interferometer, SimConfig, Tracer, VirtualMachine};

fn paper_solve(c: &mut Criterion) {
    let layout = paper::layout();
    let plan = paper::plan();
    let cfg = SimConfig {
        machine: VirtualMachine { truth: paper::truth(), repeatability_m: 0.2e-6, centring_m: 0.0 },
        interferometer: Interferometer::default(),
        deflector: Deflector::default(),
        tracer: Tracer { noise_m: 0.1e-6, noise_ppm: 0.2, ..Tracer::default() },
        environment: EnvironmentSim::default(),
        plan: plan.clone(),
    };
    let campaign = simulate(&cfg, &[], 1).unwrap().campaign;
    let obs = prepare(&campaign, &layout.travel, &ScaleExpansion::default()).unwrap().obs;
    let nominal = paper::displaced_stations(&plan.station_positions(&layout.travel), 0.05);
    let opts = SolveOptions {
        gauge: Gauge::Datum,
        initial_stations: nominal.iter().enumerate().map(|(i, q)| (i as u32, *q)).collect(),
        ..SolveOptions::default()
    };
    let sol = solve(&layout, &obs, &opts, &[]).unwrap();
    eprintln!(
        "paper scenario: {} readings, {} parameters, {} Levenberg-Marquardt iterations, converged {}, {} functions identified",
        obs.len(),
        layout.n_params + 12,
        sol.iterations,
        sol.converged,
        sol.identifiability.identified_functions
    );
    c.bench_function("paper_tracer_solve", |b| b.iter(|| solve(&layout, &obs, &opts, &[]).unwrap()));
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = paper_solve
}
criterion_main!(benches);
