//! Benchmark cases for the estimator, built in-process with the simulator.
//!
//! - [`patent`]: the patent's example, 3 device positions x 25 beams x 100 points (7,500
//!   readings), 3 probe offsets, cubic B-splines with 12 intervals (273 parameters). It is the
//!   campaign `volcal simulate --machine launch_configs/machines/demo_cmm.yaml --plan
//!   launch_configs/plans/patent_example.yaml --seed 1` produces, up to the truth.
//! - [`patent_with_effects`]: the same campaign with a device drift and a periodic pitch
//!   error injected (the diagnosis benchmark).
//! - [`large`]: 5 positions x 100 beams x 200 points (100,000 readings) and 52-interval B-splines
//!   (993 parameters) on the same machine.

use rand::SeedableRng;
use volcal::campaign::{prepare, Observations, ScaleExpansion};
use volcal::diagnose::geometry::Optics;
use volcal::{ModelLayout, Representation, SolveOptions, Topology, Travel};
use volcal_sim::effects::{from_specs, EffectContext};
use volcal_sim::{
    random_truth, simulate, Deflector, EnvironmentSim, Injection, Interferometer, Plan, SimConfig, Tracer, TruthSpec,
    VirtualMachine,
};

/// A ready-to-solve benchmark case.
pub struct Case {
    pub name: &'static str,
    pub layout: ModelLayout,
    pub obs: Observations,
    pub options: SolveOptions,
    /// The interferometer's optics, for the diagnosis.
    pub optics: Optics,
}

fn build(name: &'static str, intervals: usize, plan: Plan, seed: u64) -> Case {
    build_with(name, intervals, plan, seed, "")
}

/// A case with the physical effects of `effects` injected (`volcal simulate --inject` specs
/// joined by `+`; empty: none).
fn build_with(name: &'static str, intervals: usize, plan: Plan, seed: u64, effects: &str) -> Case {
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
    let injections = from_specs(effects, &EffectContext::new(&cfg, travel)).expect("benchmark effect specs are valid");
    let refs: Vec<&dyn Injection> = injections.iter().map(|b| b.as_ref()).collect();
    let out = simulate(&cfg, &refs, seed).expect("benchmark plan is valid");
    let obs = prepare(&out.campaign, &layout.travel, &ScaleExpansion::default()).expect("simulated data are valid").obs;
    let optics =
        Optics { wavelength_vac_m: cfg.interferometer.wavelength_vac_m, air_equation: cfg.interferometer.air_equation };
    Case { name, layout, obs, options: SolveOptions::default(), optics }
}

/// The patent's example campaign (7,500 readings, 273 parameters).
pub fn patent() -> Case {
    build("patent example (7,500 readings, 273 parameters)", 12, Plan::patent_example(), 1)
}

/// The patent's example campaign with two effects hidden in it, a drift of the device
/// (20 nm/s along X and Z) and a periodic pitch error of X (1 um, period 16 mm): what the
/// diagnosis has to find (two selection rounds and a final one that finds nothing more).
pub fn patent_with_effects() -> Case {
    build_with("patent example with drift and periodic pitch", 12, Plan::patent_example(), 1, PATENT_EFFECTS)
}

/// The effects of [`patent_with_effects`].
pub const PATENT_EFFECTS: &str =
    "setup_drift:vx_m_per_s=2e-8,vy_m_per_s=0,vz_m_per_s=2e-8+periodic_pitch:axis=0,period_m=0.016,amplitude_m=1e-6";

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
