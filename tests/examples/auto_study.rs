//! Issue 12's table: `representation: auto` against the oracle of each truth's own basis.
//!
//! `cargo run --release -p volcal_tests --example auto_study -- [SEEDS] [FIRST_SEED] [FILTER]`
//! prints, per case, the ratio of map errors (auto / oracle), the Monte Carlo calibration
//! (actual / predicted map RMS), the honesty figures (among them in how many campaigns the whole
//! map lies within its 95 % simultaneous band, [`volcal::band`]) and the time of one auto solve.
//! `AUTO_SEEDS=1` adds one line per seed (with the knot intervals per axis, `t` where the axis
//! took linear tables, and the smallest first refinement test, which gates the tables);
//! `AUTO_DEBUG=1` adds each solve's chi-square (also per instrument) and, per function, its
//! error against the truth with its smoothing parameter and effective parameters; with
//! `AUTO_PROFILE=EXY` (a function's name) also that function along its axis (truth, estimate,
//! standard uncertainty, z at 41 positions), to see where an outlier lies.
//! `AUTO_TRACER_STEPS=N` sets the tracer's steps per edge (N + 1 stops) of every case, for
//! robustness sweeps. `AUTO_TABLES=1` tries linear tables (`Auto::tables`)
//! and says in how many campaigns they were taken.

use volcal::flexibility::Auto;
use volcal_tests::auto_study::{run, suite, summarise, Outcome};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seeds: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(20);
    let first: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let filter = args.get(3).cloned().unwrap_or_default();
    let d = Auto::default();
    let env = |k: &str, v: usize| std::env::var(k).ok().and_then(|s| s.parse().ok()).unwrap_or(v);
    let auto = Auto {
        start_intervals: env("AUTO_START", d.start_intervals),
        max_intervals: env("AUTO_MAX", d.max_intervals),
        tables: env("AUTO_TABLES", 0) != 0,
    };
    println!("| case | seeds | auto map RMS um | oracle map RMS um | auto/oracle | actual/predicted (95 % over seeds) | max abs z | abs z > 3 | interpolated: max abs z, abs z > 3 | not determined | whole map within its 95 % simultaneous band (k) | solve s |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for case in suite() {
        if !case.label().contains(&filter) {
            continue;
        }
        let outcomes: Vec<_> = (first..first + seeds).map(|s| run(&case, s, &auto)).collect();
        if std::env::var_os("AUTO_SEEDS").is_some() {
            for (s, o) in (first..).zip(&outcomes) {
                eprintln!(
                    "  seed {s}: auto {:.3} um, oracle {:.3} um, located oracle {:.3} um, predicted {:.3} um, max z {:.2}, edf {:.1}, intervals {}, first refinement test p {:.1e}{}",
                    o.auto_rms_m * 1e6,
                    o.oracle_rms_m * 1e6,
                    o.located_rms_m * 1e6,
                    o.predicted_rms_m * 1e6,
                    o.max_z,
                    o.edf,
                    o.knots.iter().map(|k| format!("{}{}", k.intervals, if k.table.is_some() { "t" } else { "" })).collect::<Vec<_>>().join("/"),
                    o.knots.iter().filter_map(|k| k.tests.first()).map(|t| t.p_value).fold(1.0, f64::min),
                    o.interpolation
                        .iter()
                        .map(|c| format!(", interpolation {} {:.2} (p {:.1e})", c.axis.letter(), c.ratio(), c.p_value))
                        .collect::<String>()
                );
            }
        }
        let s = summarise(&outcomes);
        let mut ks: Vec<f64> = outcomes.iter().map(|o| o.band_k).collect();
        ks.sort_by(f64::total_cmp);
        println!(
            "| {} | {} | {:.4} | {:.4} | {:.3} | {:.3} ({:.2} to {:.2}) | {:.2} | {} of {} | {:.2}, {} of {} | {} of {} | {} of {} ({:.2} to {:.2}) | {:.3} |",
            case.label(),
            s.seeds,
            s.auto_rms_m * 1e6,
            s.oracle_rms_m * 1e6,
            s.oracle_ratio,
            s.mc_ratio,
            s.mc_ratio_95.0,
            s.mc_ratio_95.1,
            s.max_z,
            s.over_3,
            s.values,
            s.max_z_interpolated,
            s.over_3_interpolated,
            s.values_interpolated,
            s.undetermined,
            s.points,
            outcomes.iter().filter(|o| o.within_band).count(),
            outcomes.len(),
            ks[0],
            ks[ks.len() - 1],
            s.mean_s
        );
        eprintln!(
            "  the oracle that must find where the features lie: {:.3} times the oracle's map error; auto {:.3} times its",
            s.located_over_oracle, s.located_ratio
        );
        let k = &outcomes[0].knots;
        eprintln!(
            "  knots: {} / {} / {}; edf {:.1}",
            k[0].describe(),
            k[1].describe(),
            k[2].describe(),
            outcomes[0].edf
        );
        if auto.tables {
            let with: Vec<usize> =
                outcomes.iter().map(|o| o.knots.iter().filter(|k| k.table.is_some()).count()).collect();
            eprintln!(
                "  linear tables taken in {} of {} campaigns ({} axes in all)",
                with.iter().filter(|&&n| n > 0).count(),
                outcomes.len(),
                with.iter().sum::<usize>()
            );
        }
        eprintln!("  actual / predicted at the points the readings resolve: {:.3}", s.mc_ratio_resolved);
        if outcomes.iter().any(|o| !o.interpolation.is_empty()) {
            // The campaigns whose interpolation the readings contradict on some axis, and the rest.
            let (told, quiet): (Vec<Outcome>, Vec<Outcome>) =
                outcomes.iter().cloned().partition(|o| o.interpolation.iter().any(|c| c.contradicted()));
            let ratio = |v: &[Outcome]| if v.is_empty() { f64::NAN } else { summarise(v).mc_ratio };
            eprintln!(
                "  interpolation contradicted in {} of {} campaigns (actual / predicted there {:.3}, elsewhere {:.3})",
                told.len(),
                outcomes.len(),
                ratio(&told),
                ratio(&quiet)
            );
        }
    }
}
