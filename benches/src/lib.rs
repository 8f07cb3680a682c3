//! Benchmark cases for the estimator, built in-process with the simulator.
//!
//! - [`patent`]: the patent's example, 3 device positions x 25 beams x 100 points (7,500
//!   readings), 3 probe offsets, cubic B-splines with 12 intervals (273 parameters). It is the
//!   campaign `volcal simulate --machine launch_configs/machines/demo_cmm.yaml --plan
//!   launch_configs/plans/patent_example.yaml --seed 1` produces, up to the truth.
//! - [`large`]: 5 positions x 100 beams x 200 points (100,000 readings) and 52-interval B-splines
//!   (993 parameters) on the same machine.

use rand::SeedableRng;
use volcal::campaign::{prepare, Observations, ScaleExpansion};
use volcal::{ModelLayout, Representation, SolveOptions, Topology, Travel};
use volcal_sim::{
    random_truth, simulate, Deflector, EnvironmentSim, Interferometer, Plan, SimConfig, Tracer, TruthSpec,
    VirtualMachine,
};

/// A ready-to-solve benchmark case.
pub struct Case {
    pub name: &'static str,
    pub layout: ModelLayout,
    pub obs: Observations,
    pub options: SolveOptions,
}

fn build(name: &'static str, intervals: usize, plan: Plan, seed: u64) -> Case {
    let travel = Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]);
    let layout = ModelLayout::uniform(Topology::parse("FXYZ").unwrap(), travel, Representation::BSpline { intervals });
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let truth = random_truth(layout.clone(), &TruthSpec::default(), &mut rng);
    let cfg = SimConfig {
        machine: VirtualMachine { truth, repeatability_m: 0.2e-6, centring_m: 1e-6 },
        interferometer: Interferometer::default(),
        deflector: Deflector::default(),
        tracer: Tracer::default(),
        environment: EnvironmentSim::default(),
        plan,
    };
    let out = simulate(&cfg, &[], seed).expect("benchmark plan is valid");
    let obs = prepare(&out.campaign, &layout.travel, &ScaleExpansion::default()).expect("simulated data are valid").obs;
    Case { name, layout, obs, options: SolveOptions::default() }
}

/// The patent's example campaign (7,500 readings, 273 parameters).
pub fn patent() -> Case {
    build("patent example (7,500 readings, 273 parameters)", 12, Plan::patent_example(), 1)
}

/// A large campaign (100,000 readings, 993 parameters).
pub fn large() -> Case {
    let plan = Plan {
        n_stations: Some(5),
        directions_per_station: 100,
        points_per_beam: 200,
        min_beam_fraction: 0.3,
        ..Plan::patent_example()
    };
    build("large (100,000 readings, 993 parameters)", 52, plan, 2)
}
