use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use volcal::campaign::{prepare, ScaleExpansion};
use volcal::{solve, ModelLayout, Representation, SolveOptions, Topology, Travel};
use volcal_sim::{
    random_truth, simulate, Deflector, EnvironmentSim, Interferometer, Plan, SimConfig, Tracer, TruthSpec,
    VirtualMachine,
};

fn main() {
    let travel = Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]);
    let layout = ModelLayout::uniform(Topology::parse("FXYZ").unwrap(), travel, Representation::default());
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let truth = random_truth(layout.clone(), &TruthSpec::default(), &mut rng);
    let cfg = SimConfig {
        machine: VirtualMachine { truth, repeatability_m: 0.2e-6, centring_m: 1e-6 },
        interferometer: Interferometer::default(),
        deflector: Deflector::default(),
        tracer: Tracer::default(),
        environment: EnvironmentSim::default(),
        plan: Plan::patent_example(),
    };
    let out = simulate(&cfg, &[], 1).unwrap();
    let prepared = prepare(&out.campaign, &layout.travel, &ScaleExpansion::default()).unwrap();
    for _ in 0..3 {
        let t0 = std::time::Instant::now();
        let sol = solve(&layout, &prepared.obs, &SolveOptions::default(), &[]).unwrap();
        println!("solve {:?} iterations {} chi2/dof {:.3}", t0.elapsed(), sol.iterations, sol.stats.variance_factor);
    }
}
