//! Development aid: runs the diagnosis on campaigns hiding each effect, for a few seeds.
use nalgebra::Vector3;
use volcal::campaign::prepare;
use volcal::diagnose::{diagnose, geometry::Optics, DiagnoseOptions};
use volcal_formats::machine::Machine;
use volcal_formats::plan::sim_config;
use volcal_sim::effects::{from_spec, EffectContext};
use volcal_sim::{simulate, Acquisition, Plan};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let spec = args.get(1).cloned().unwrap_or_default();
    let seeds: u64 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(3);
    let text = volcal_formats::machine::DEMO_MACHINE.replace("intervals: 12", "intervals: 8");
    let m = Machine::parse(&text).unwrap();
    let plan = Plan {
        directions_per_station: 20,
        points_per_beam: 40,
        bidirectional: true,
        acquisition: Acquisition::OnTheFly { speed_mps: 0.05 },
        speeds_mps: vec![0.02, 0.05, 0.1],
        ..Plan::patent_example()
    };
    for seed in 0..seeds {
        let mut cfg = sim_config(&m, plan.clone(), 100 + seed);
        cfg.environment.record_air = true;
        cfg.environment.air_temp_rate_k_per_h = if spec.contains("air") { 2.5 } else { 0.0 };
        let ctx = EffectContext {
            air_start: cfg.environment.air,
            wavelength_vac_m: cfg.interferometer.wavelength_vac_m,
            air_equation: cfg.interferometer.air_equation,
            travel: m.layout.travel,
        };
        let injections: Vec<Box<dyn volcal_sim::Injection>> =
            spec.split('+').filter(|s| !s.is_empty()).map(|s| from_spec(s, &ctx).unwrap()).collect();
        let refs: Vec<&dyn volcal_sim::Injection> = injections.iter().map(|b| b.as_ref()).collect();
        let out = simulate(&cfg, &refs, 200 + seed).unwrap();
        let prep = prepare(&out.campaign, &m.layout.travel, &m.expansion).unwrap();
        let opts = DiagnoseOptions::new(
            m.solve_options(),
            Optics {
                wavelength_vac_m: cfg.interferometer.wavelength_vac_m,
                air_equation: cfg.interferometer.air_equation,
            },
        );
        let t0 = std::time::Instant::now();
        let d = diagnose(&m.layout, &prep.obs, &opts).unwrap();
        println!(
            "seed {seed} ({} readings, {:.2} s): rms {:.4} -> {:.4} um",
            prep.obs.len(),
            t0.elapsed().as_secs_f64(),
            d.rms_before_m * 1e6,
            d.rms_after_m * 1e6
        );
        for e in &d.effects {
            println!(
                "  {} evidence {:.1} p {:.1e} rank {}: {:?}",
                e.id,
                e.evidence,
                e.p_value,
                e.rank,
                e.parameters.iter().map(|p| format!("{}={:.4e}+-{:.1e}", p.0, p.1, p.2)).collect::<Vec<_>>()
            );
            println!("     {}", e.statement);
        }
        if let Some(u) = &d.unexplained {
            println!("  UNEXPLAINED: {u}");
        }
        for l in d.locations.iter().take(4) {
            println!("  loc {} {} share {:.2} p {:.1e}", l.kind, l.label, l.share, l.p_value);
        }
        if std::env::var_os("ROUNDS").is_some() {
            for (k, r) in d.rounds.iter().enumerate() {
                for c in r {
                    println!(
                        "  round {k}: {:<20} dchi2 {:>9.1} rank {:>3} p {:.1e} ev {:>8.1} share {:.2} cv {:?} {}",
                        c.id,
                        c.delta_chi2,
                        c.rank,
                        c.p_value,
                        c.evidence,
                        c.share,
                        c.cv_gain.map(|v| v.round()),
                        if c.accepted { "ACCEPTED" } else { "" }
                    );
                }
            }
        }
        let truth: Vec<String> = out.truth.injected.iter().map(|i| format!("{} {:?}", i.id, i.parameters)).collect();
        println!("  truth: {truth:?}");
        let _ = Vector3::<f64>::zeros();
    }
}
