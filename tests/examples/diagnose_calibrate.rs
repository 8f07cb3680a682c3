//! Development aid: the SNR calibration of the diagnosis scenarios, and their statistics over
//! seeds at SNR 3. `diagnose_calibrate [ID] [SEEDS] [FIRST_SEED]`.
use volcal_tests::diagnosis::{self, Scenario};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let only = args.get(1).cloned().unwrap_or_default();
    let seeds: u64 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(5);
    let first: u64 = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(0);
    let mut all = diagnosis::scenarios();
    all.push(diagnosis::unmodelled());
    let list: Vec<Scenario> = all.into_iter().filter(|s| only.is_empty() || only == "all" || s.id == only).collect();
    for sc in &list {
        let t0 = std::time::Instant::now();
        let snr_ref = diagnosis::snr(sc, sc.reference, 0);
        let a = sc.reference * 3.0 / snr_ref;
        let raw = diagnosis::snr_raw(sc, sc.reference, 0);
        println!(
            "{}: SNR {:.2} (raw {:.2}) at {:.3e}; SNR 3 at {:.3e}, raw SNR 3 at {:.3e} ({:.1} s)",
            sc.id,
            snr_ref,
            raw,
            sc.reference,
            a,
            sc.reference * 3.0 / raw,
            t0.elapsed().as_secs_f64()
        );
        if std::env::var_os("SNR_ONLY").is_some() {
            continue;
        }
        let a = if std::env::var_os("RAW").is_some() { sc.reference * 3.0 / raw } else { a };
        for seed in first..first + seeds {
            let t0 = std::time::Instant::now();
            let r = diagnosis::run(sc, a, seed);
            let d = &r.diagnosis;
            let names: Vec<&str> = d.effects.iter().map(|e| e.id.as_str()).collect();
            let z = if sc.id == "unmodelled_bump" { Vec::new() } else { diagnosis::check(sc, &r).z };
            println!(
                "  seed {seed} {:.1}s n={} rms {:.4} -> {:.4} (clean {:.4}) um, map {:.4} -> {:.4} um, found {:?} z {:?}{}",
                t0.elapsed().as_secs_f64(),
                d.before.stats.n_obs,
                d.rms_before_m * 1e6,
                d.rms_after_m * 1e6,
                r.rms_clean_m * 1e6,
                r.map_error_before * 1e6,
                r.map_error_after * 1e6,
                names,
                z.iter().map(|z| format!("{z:.2}")).collect::<Vec<_>>(),
                d.unexplained.as_ref().map(|u| format!(" UNEXPLAINED {u}")).unwrap_or_default()
            );
            if std::env::var_os("ROUNDS").is_some() {
                for (k, round) in d.rounds.iter().enumerate() {
                    for c in round {
                        println!(
                            "    round {k}: {:<20} hyper {:?} rank {:>3} p {:.1e} ev {:>8.1} share {:.2} cv {:?} without {:?} {}",
                            c.id,
                            c.hyper,
                            c.rank,
                            c.p_value,
                            c.evidence,
                            c.share,
                            c.cv_gain.map(|v| v.round()),
                            c.without_dominant_p,
                            if c.accepted { "ACCEPTED" } else { "" }
                        );
                    }
                }
                for e in &d.effects {
                    println!("    {}", e.statement);
                }
            }
        }
    }
}
