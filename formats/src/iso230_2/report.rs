//! What `volcal iso230-2` prints and writes: the per-target table and the figures as text, and
//! the same as JSON (`volcal-iso230-2 v1`, micrometres, the figures under ISO 230-2:2014 names
//! at the top level so that a script reads `A`, `R`, `B`, `E` without knowing the table).

use super::{Evaluation, Figures, Target};
use anyhow::{Context, Result};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

#[derive(Serialize)]
struct JsonReport<'a> {
    format: &'static str,
    standard: &'static str,
    source: &'a str,
    unit: &'static str,
    #[serde(flatten)]
    figures: Figures,
    targets: Vec<JsonTarget>,
    notes: &'a [String],
}

/// ISO names (B_i, R_i) rather than snake case: the JSON is read by people who know the standard.
#[derive(Serialize)]
#[allow(non_snake_case)]
struct JsonTarget {
    target_mm: f64,
    runs_up: usize,
    runs_down: usize,
    mean_up: f64,
    mean_down: f64,
    s_up: f64,
    s_down: f64,
    mean_bidirectional: f64,
    B_i: f64,
    R_up: f64,
    R_down: f64,
    R_i: f64,
}

impl From<&Target> for JsonTarget {
    fn from(t: &Target) -> JsonTarget {
        JsonTarget {
            target_mm: t.target_mm,
            runs_up: t.up.runs,
            runs_down: t.down.runs,
            mean_up: t.up.mean_um,
            mean_down: t.down.mean_um,
            s_up: t.up.s_um,
            s_down: t.down.s_um,
            mean_bidirectional: t.mean_bidirectional_um(),
            B_i: t.reversal_um(),
            R_up: t.up.repeatability_um(),
            R_down: t.down.repeatability_um(),
            R_i: t.repeatability_um(),
        }
    }
}

/// The evaluation as JSON text.
pub fn to_json(e: &Evaluation) -> Result<String> {
    let r = JsonReport {
        format: "volcal-iso230-2 v1",
        standard: "ISO 230-2:2014",
        source: &e.name,
        unit: "um",
        figures: e.figures,
        targets: e.targets.iter().map(JsonTarget::from).collect(),
        notes: &e.notes,
    };
    Ok(serde_json::to_string_pretty(&r)? + "\n")
}

/// Writes the evaluation as JSON.
pub fn write_json(path: &Path, e: &Evaluation) -> Result<()> {
    std::fs::write(path, to_json(e)?).with_context(|| format!("cannot write {}", path.display()))
}

/// Decimals that give the largest figure five significant digits (at least one, at most nine),
/// so that a sub-micrometre stage and a metre-long axis both print every digit that matters.
pub fn decimals(f: &Figures) -> usize {
    let largest = [f.A, f.E, f.R, f.B, f.M].into_iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    if largest <= 0.0 {
        return 3;
    }
    (4 - largest.log10().floor() as i32).clamp(1, 9) as usize
}

/// The printed report: the per-target table, then the figures with their names.
pub fn text(e: &Evaluation) -> String {
    let f = &e.figures;
    let d = decimals(f);
    let w = d + 6;
    let mut s = String::new();
    let _ = writeln!(s, "ISO 230-2:2014 positioning test: {} ({} targets)", e.name, e.targets.len());
    let _ = writeln!(s, "deviations in micrometres; + approached moving up (ISO ↑), - moving down (↓)\n");
    let heads = ["mean+", "mean-", "s+", "s-", "B_i", "R+", "R-", "R_i"];
    let _ = write!(s, "{:>12} {:>3} {:>3}", "target_mm", "n+", "n-");
    for h in heads {
        let _ = write!(s, " {h:>w$}");
    }
    s.push('\n');
    for t in &e.targets {
        let _ = write!(s, "{:>12} {:>3} {:>3}", fmt_target(t.target_mm), t.up.runs, t.down.runs);
        for v in [
            t.up.mean_um,
            t.down.mean_um,
            t.up.s_um,
            t.down.s_um,
            t.reversal_um(),
            t.up.repeatability_um(),
            t.down.repeatability_um(),
            t.repeatability_um(),
        ] {
            let _ = write!(s, " {v:>w$.d$}");
        }
        s.push('\n');
    }
    s.push('\n');
    let rows: [(&str, &str, f64, f64, f64); 5] = [
        ("A", "accuracy of positioning", f.A, f.A_up, f.A_down),
        ("R", "repeatability of positioning", f.R, f.R_up, f.R_down),
        ("E", "systematic positioning error", f.E, f.E_up, f.E_down),
        ("M", "mean bidirectional positioning error", f.M, f64::NAN, f64::NAN),
        ("B", "reversal value (largest |B_i|)", f.B, f64::NAN, f64::NAN),
    ];
    let _ = writeln!(s, "{:<40} {:>w$} {:>w$} {:>w$}", "figure (um)", "bidir", "up", "down");
    for (sym, what, both, up, down) in rows {
        let label = format!("{sym}  {what}");
        let one = |v: f64| if v.is_nan() { format!("{:>w$}", "") } else { format!("{v:>w$.d$}") };
        let row = format!("{label:<40} {both:>w$.d$} {} {}", one(up), one(down));
        let _ = writeln!(s, "{}", row.trim_end());
    }
    let _ = writeln!(s, "{:<40} {:>w$.d$}", "B_mean  mean reversal value", f.B_mean);
    for n in &e.notes {
        let _ = writeln!(s, "note: {n}");
    }
    s
}

/// A target as written in the file would be: no trailing zeros, at most six decimals.
fn fmt_target(mm: f64) -> String {
    let s = format!("{mm:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}
