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
    let reprs: Vec<Representation> = std::env::args()
        .nth(1)
        .map(|a| {
            vec![match a.as_str() {
                "p" => Representation::Polynomial { degree: 6 },
                "t" => Representation::Table { nodes: 8 },
                _ => Representation::BSpline { intervals: a.parse().unwrap() },
            }]
        })
        .unwrap_or(vec![Representation::default()]);
    for repr in reprs {
        let layout = ModelLayout::uniform(Topology::parse("FXYZ").unwrap(), travel, repr);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let truth = random_truth(layout.clone(), &TruthSpec::default(), &mut rng);
        let cfg = SimConfig {
            machine: VirtualMachine { truth, repeatability_m: 0.0, centring_m: 0.0 },
            interferometer: Interferometer { noise_m: 0.0, resolution_m: 0.0, ..Default::default() },
            deflector: Deflector::default(),
            tracer: Tracer::default(),
            environment: EnvironmentSim::default(),
            plan: Plan::patent_example(),
        };
        let out = simulate(&cfg, &[], 1).unwrap();
        let prepared = prepare(&out.campaign, &layout.travel, &ScaleExpansion::default()).unwrap();
        for w in &prepared.warnings {
            println!("warn: {w}");
        }
        let opts = SolveOptions { max_iterations: 5, rank_tolerance: 1e-14, ..Default::default() };
        let sol = solve(&layout, &prepared.obs, &opts, &[]).unwrap();
        println!(
            "{:?}: rank {} extra {} cond {:.3e} its {} rms {:.3e}",
            repr,
            sol.identifiability.rank,
            sol.identifiability.extra_null_dim,
            sol.identifiability.condition_number,
            sol.iterations,
            sol.stats.rms_m
        );
        for s in &sol.identifiability.statements {
            println!("  {s}");
        }
        for s in &sol.identifiability.warnings {
            println!("  W {s}");
        }
    }
}
