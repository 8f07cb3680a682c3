//! Quick Monte Carlo of covariance calibration (development aid).
use nalgebra::Vector3;
use volcal::campaign::prepare;
use volcal::{gauge, predict, solve, ErrorModel};
use volcal_nodes::commands::sim_config;
use volcal_nodes::machine::{Machine, DEMO_MACHINE};
use volcal_sim::{simulate, Plan};

fn main() {
    let n: u64 = std::env::args().nth(1).map(|s| s.parse().unwrap()).unwrap_or(20);
    let machine = Machine::parse(DEMO_MACHINE).unwrap();
    let cfg0 = sim_config(&machine, Plan::patent_example(), 7);
    let offsets: Vec<Vector3<f64>> = cfg0.plan.probe_offsets.iter().map(|p| Vector3::new(p[0], p[1], p[2])).collect();
    let truth = cfg0.machine.truth.clone();
    let aligned =
        ErrorModel { layout: machine.layout.clone(), u: gauge::align(&machine.layout, machine.gauge, &truth.u) };
    let pts = predict::grid(&machine.layout.travel, 0.2);
    let (mut zsum2, mut zn) = (0.0, 0usize);
    let (mut act2, mut pred2) = (0.0, 0.0);
    let (mut psum2, mut pn) = (0.0, 0usize);
    for seed in 0..n {
        let out = simulate(&cfg0, &[], 1000 + seed).unwrap();
        let prep = prepare(&out.campaign, &machine.layout.travel, &machine.expansion).unwrap();
        let sol = solve(&machine.layout, &prep.obs, &machine.solve_options(), &[]).unwrap();
        let (mut a2, mut p2) = (0.0, 0.0);
        for x in &pts {
            for p in &offsets {
                let pe = predict::predict(&sol.model, &sol.covariance, x, p);
                let d = sol.model.error(x, p) - aligned.error(x, p);
                for k in 0..3 {
                    let s = pe.cov[(k, k)].sqrt();
                    zsum2 += (d[k] / s).powi(2);
                    zn += 1;
                }
                a2 += d.norm_squared();
                p2 += pe.cov.trace();
            }
        }
        act2 += a2;
        pred2 += p2;
        // parameter-level normalised errors
        for k in 0..machine.layout.n_params {
            let s = sol.covariance[(k, k)];
            if s > 0.0 {
                psum2 += (sol.model.u[k] - aligned.u[k]).powi(2) / s;
                pn += 1;
            }
        }
        println!(
            "seed {seed}: actual rms {:.4} um, predicted {:.4} um, ratio {:.3}, chi2/dof {:.3}",
            (a2 / (pts.len() * 3) as f64).sqrt() * 1e6,
            (p2 / (pts.len() * 3) as f64).sqrt() * 1e6,
            (a2 / p2).sqrt(),
            sol.stats.variance_factor
        );
    }
    println!(
        "overall ratio {:.3}; var(z) volumetric {:.3}; var(z) params {:.3}",
        (act2 / pred2).sqrt(),
        zsum2 / zn as f64,
        psum2 / pn as f64
    );
}
