//! Recovery of simulated truth by the fixed-beam estimator.

use nalgebra::{Point3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use volcal::campaign::{prepare, ScaleExpansion};
use volcal::gauge;
use volcal::{solve, ErrorModel, Gauge, ModelLayout, Representation, SolveOptions, Topology, Travel};
use volcal_sim::{
    random_truth, simulate, Deflector, EnvironmentSim, Interferometer, Plan, SimConfig, Tracer, TruthSpec,
    VirtualMachine,
};

fn travel() -> Travel {
    Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0])
}

/// Largest volumetric difference between two models over a grid and probe offsets.
fn max_volumetric_diff(a: &ErrorModel, b: &ErrorModel, offsets: &[Vector3<f64>]) -> f64 {
    let mut worst: f64 = 0.0;
    for x in volcal::predict::grid(&a.layout.travel, 0.1) {
        for p in offsets {
            worst = worst.max((a.error(&x, p) - b.error(&x, p)).norm());
        }
    }
    worst
}

fn config(topology: &str, layout: &ModelLayout, noise: bool, seed: u64) -> SimConfig {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let truth = random_truth(layout.clone(), &TruthSpec::default(), &mut rng);
    let _ = topology;
    SimConfig {
        machine: VirtualMachine {
            truth,
            repeatability_m: if noise { 0.2e-6 } else { 0.0 },
            centring_m: if noise { 1e-6 } else { 0.0 },
        },
        interferometer: Interferometer {
            noise_m: if noise { 0.05e-6 } else { 0.0 },
            resolution_m: if noise { 1e-9 } else { 0.0 },
            ..Default::default()
        },
        deflector: Deflector::default(),
        tracer: Tracer::default(),
        environment: EnvironmentSim::default(),
        plan: Plan::patent_example(),
    }
}

#[test]
fn noise_free_recovery() {
    for topo in ["FXYZ", "FYXZ"] {
        let layout = ModelLayout::uniform(Topology::parse(topo).unwrap(), travel(), Representation::default());
        let cfg = config(topo, &layout, false, 7);
        let out = simulate(&cfg, &[], 1).unwrap();
        let prepared = prepare(&out.campaign, &layout.travel, &ScaleExpansion::default()).unwrap();
        let t0 = std::time::Instant::now();
        let sol = solve(&layout, &prepared.obs, &SolveOptions::default(), &[]).unwrap();
        eprintln!(
            "{topo}: solve {:?}, iterations {}, rms {:.3e}, ident: {:?}",
            t0.elapsed(),
            sol.iterations,
            sol.stats.rms_m,
            sol.identifiability.statements
        );
        let aligned =
            ErrorModel { layout: layout.clone(), u: gauge::align(&layout, Gauge::Patent, &out.truth.model.u) };
        let offsets: Vec<Vector3<f64>> =
            cfg.plan.probe_offsets.iter().map(|p| Vector3::new(p[0], p[1], p[2])).collect();
        let d = max_volumetric_diff(&sol.model, &aligned, &offsets);
        eprintln!("{topo}: max volumetric diff {:.3e} m, warnings {:?}", d, sol.warnings);
        let _ = Point3::<f64>::origin();
        assert!(d < 1e-9, "{topo}: {d}");
    }
}
