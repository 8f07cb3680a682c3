//! ISO 230-2:2014 evaluation of a bidirectional positioning test: the runs of one axis in, the
//! standard's figures (A, R, B, E, M and their unidirectional forms) and the per-target table out.
//!
//! The test: the axis approaches each target position `P_i` in both directions, `n` times each
//! (ISO 230-2 asks for five runs per direction and at least five targets per metre). Every
//! approach gives a positional deviation `x_ij = P_ij - P_i` (measured minus commanded, as a laser
//! interferometer reads it). From these, per target and direction, ISO 230-2 defines (↑
//! forward, ↓ reverse):
//!
//! | symbol | definition | term |
//! |---|---|---|
//! | x̄i↑, x̄i↓ | mean of the `n` deviations | mean unidirectional positional deviation |
//! | x̄i | (x̄i↑ + x̄i↓) / 2 | mean bidirectional positional deviation |
//! | Bi | x̄i↑ − x̄i↓ | reversal value at a position |
//! | si↑, si↓ | sample standard deviation (divisor n − 1) | estimator of the unidirectional standard uncertainty |
//! | Ri↑, Ri↓ | 4 si↑, 4 si↓ | unidirectional repeatability at a position |
//! | Ri | max(2 si↑ + 2 si↓ + abs(Bi), Ri↑, Ri↓) | bidirectional repeatability at a position |
//!
//! and over the axis: B = max abs(Bi) (reversal value, reported as a magnitude), B̄ = mean Bi
//! (mean reversal value, signed), R↑ = max Ri↑, R↓ = max Ri↓, R = max Ri, E↑ = max x̄i↑ − min x̄i↑
//! (unidirectional systematic positioning error), E = max(x̄i↑, x̄i↓) − min(x̄i↑, x̄i↓) over both
//! directions (bidirectional systematic positioning error), M = max x̄i − min x̄i (mean
//! bidirectional positioning error), A↑ = max(x̄i↑ + 2 si↑) − min(x̄i↑ − 2 si↑) (unidirectional
//! accuracy) and A = max(x̄i↑ + 2 si↑, x̄i↓ + 2 si↓) − min(x̄i↑ − 2 si↑, x̄i↓ − 2 si↓)
//! (bidirectional accuracy).
//!
//! The standard's text is not public and was not at hand. The formulas are those of a public
//! implementation that quotes the clause numbers of the 2006 edition (`art_rot.m`, "ISO 230-2
//! 2006 Standard", clauses 2.10 to 2.24); they reproduce the per-target tables and the A, B, M and
//! unidirectional figures of a report PSI's ecmc tooling published on a real test to its last
//! printed digit, and of an older one to one unit of it (`tests/data/iso230_2/README.md`). Whether the 2014 edition changed any of them (one
//! later tool prints a root-sum-square form of Ri) is not verified.
//!
//! The evaluation never panics on bad input: [`evaluate`] names the file and the line of the rows
//! that make a target unusable (a direction without runs, fewer than two runs, a run given twice).

pub mod csv;
pub mod report;

use anyhow::{bail, Result};
use std::collections::BTreeMap;

/// Direction of approach to a target.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Direction {
    /// Approached while moving in the positive direction (`+`, ISO ↑).
    Up,
    /// Approached while moving in the negative direction (`-`, ISO ↓).
    Down,
}

impl Direction {
    pub fn symbol(self) -> char {
        match self {
            Direction::Up => '+',
            Direction::Down => '-',
        }
    }
}

/// One approach to one target: one row of the runs file.
#[derive(Clone, Debug, PartialEq)]
pub struct Approach {
    pub target_mm: f64,
    pub run: u32,
    pub direction: Direction,
    /// Measured minus commanded position, micrometres.
    pub deviation_um: f64,
    /// Line of the file it came from (1-based), for messages.
    pub line: usize,
}

/// The approaches of one test, with the name of the file they came from (used in messages).
#[derive(Clone, Debug)]
pub struct Runs {
    pub name: String,
    pub approaches: Vec<Approach>,
}

/// Per target, per direction: the statistics of its runs (micrometres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OneWay {
    pub runs: usize,
    /// x̄i↑ or x̄i↓.
    pub mean_um: f64,
    /// si↑ or si↓ (sample standard deviation, divisor n − 1).
    pub s_um: f64,
}

impl OneWay {
    /// Ri↑ or Ri↓ = 4 s.
    pub fn repeatability_um(&self) -> f64 {
        4.0 * self.s_um
    }
    fn upper(&self) -> f64 {
        self.mean_um + 2.0 * self.s_um
    }
    fn lower(&self) -> f64 {
        self.mean_um - 2.0 * self.s_um
    }
}

/// One row of the per-target table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target {
    pub target_mm: f64,
    pub up: OneWay,
    pub down: OneWay,
}

impl Target {
    /// Bi = x̄i↑ − x̄i↓ (signed).
    pub fn reversal_um(&self) -> f64 {
        self.up.mean_um - self.down.mean_um
    }
    /// x̄i = (x̄i↑ + x̄i↓) / 2.
    pub fn mean_bidirectional_um(&self) -> f64 {
        0.5 * (self.up.mean_um + self.down.mean_um)
    }
    /// Ri = max(2 si↑ + 2 si↓ + |Bi|, Ri↑, Ri↓).
    pub fn repeatability_um(&self) -> f64 {
        let both = 2.0 * self.up.s_um + 2.0 * self.down.s_um + self.reversal_um().abs();
        both.max(self.up.repeatability_um()).max(self.down.repeatability_um())
    }
}

/// The axis figures of ISO 230-2:2014, micrometres, under the standard's names.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[allow(non_snake_case)]
pub struct Figures {
    pub A: f64,
    pub A_up: f64,
    pub A_down: f64,
    pub E: f64,
    pub E_up: f64,
    pub E_down: f64,
    pub R: f64,
    pub R_up: f64,
    pub R_down: f64,
    /// Largest |Bi| (a magnitude, as the standard defines it).
    pub B: f64,
    /// Mean of the signed Bi.
    pub B_mean: f64,
    pub M: f64,
}

/// The evaluation of one test: the per-target table, the axis figures and what falls short of
/// the standard's test conditions (fewer than five runs per direction, fewer than five targets).
#[derive(Clone, Debug)]
pub struct Evaluation {
    pub name: String,
    pub targets: Vec<Target>,
    pub figures: Figures,
    pub notes: Vec<String>,
}

/// Evaluates a test. Fails, naming the file and the lines, when a target has no runs in one
/// direction, fewer than two runs in a direction (no standard deviation), or the same run twice.
pub fn evaluate(runs: &Runs) -> Result<Evaluation> {
    let name = &runs.name;
    if runs.approaches.is_empty() {
        bail!("{name}: no approaches (expected one row per target, run and direction after the header)");
    }
    // Targets keyed by their value's total order, so "10" and "10.0" are one target.
    let mut by_target: BTreeMap<OrdF64, [Vec<&Approach>; 2]> = BTreeMap::new();
    for a in &runs.approaches {
        let slot = &mut by_target.entry(OrdF64(a.target_mm)).or_default()[a.direction as usize];
        if let Some(prev) = slot.iter().find(|p| p.run == a.run) {
            bail!(
                "{name} line {}: target {} mm, run {}, direction {} already given on line {}",
                a.line,
                a.target_mm,
                a.run,
                a.direction.symbol(),
                prev.line
            );
        }
        slot.push(a);
    }
    let mut targets = Vec::with_capacity(by_target.len());
    let mut fewest_runs = usize::MAX;
    for (t, [up, down]) in &by_target {
        let one_way = |rows: &[&Approach], other: &[&Approach], dir: Direction| -> Result<OneWay> {
            if rows.is_empty() {
                bail!(
                    "{name} line {}: target {} mm has runs in direction {} only (lines {}); ISO 230-2 needs both directions at every target",
                    other[0].line,
                    t.0,
                    dir.opposite().symbol(),
                    lines(other)
                );
            }
            if rows.len() < 2 {
                bail!(
                    "{name} line {}: target {} mm has a single run in direction {}; at least two are needed for a standard deviation (ISO 230-2 asks for five)",
                    rows[0].line,
                    t.0,
                    dir.symbol()
                );
            }
            Ok(one_way_stats(rows))
        };
        let u = one_way(up, down, Direction::Up)?;
        let d = one_way(down, up, Direction::Down)?;
        fewest_runs = fewest_runs.min(u.runs).min(d.runs);
        targets.push(Target { target_mm: t.0, up: u, down: d });
    }
    let mut notes = Vec::new();
    if fewest_runs < 5 {
        notes.push(format!(
            "only {fewest_runs} runs in some direction at some target: ISO 230-2 asks for five per direction"
        ));
    }
    if targets.len() < 5 {
        notes.push(format!(
            "only {} target(s): ISO 230-2 asks for at least five per metre of travel, and five on a shorter axis",
            targets.len()
        ));
    }
    Ok(Evaluation { name: name.clone(), figures: figures(&targets), targets, notes })
}

impl Direction {
    fn opposite(self) -> Direction {
        match self {
            Direction::Up => Direction::Down,
            Direction::Down => Direction::Up,
        }
    }
}

/// The axis figures from the per-target table (at least one target).
fn figures(targets: &[Target]) -> Figures {
    let max = |f: &dyn Fn(&Target) -> f64| targets.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
    let min = |f: &dyn Fn(&Target) -> f64| targets.iter().map(f).fold(f64::INFINITY, f64::min);
    let range = |f: &dyn Fn(&Target) -> f64| max(f) - min(f);
    Figures {
        A: max(&|t| t.up.upper().max(t.down.upper())) - min(&|t| t.up.lower().min(t.down.lower())),
        A_up: max(&|t| t.up.upper()) - min(&|t| t.up.lower()),
        A_down: max(&|t| t.down.upper()) - min(&|t| t.down.lower()),
        E: max(&|t| t.up.mean_um.max(t.down.mean_um)) - min(&|t| t.up.mean_um.min(t.down.mean_um)),
        E_up: range(&|t| t.up.mean_um),
        E_down: range(&|t| t.down.mean_um),
        R: max(&|t| t.repeatability_um()),
        R_up: max(&|t| t.up.repeatability_um()),
        R_down: max(&|t| t.down.repeatability_um()),
        B: max(&|t| t.reversal_um().abs()),
        B_mean: targets.iter().map(Target::reversal_um).sum::<f64>() / targets.len() as f64,
        M: range(&|t| t.mean_bidirectional_um()),
    }
}

/// Mean and sample standard deviation (n − 1) of at least two approaches; two passes, so a large
/// common offset does not eat the digits of the spread.
fn one_way_stats(rows: &[&Approach]) -> OneWay {
    let n = rows.len() as f64;
    let mean = rows.iter().map(|a| a.deviation_um).sum::<f64>() / n;
    let ss = rows.iter().map(|a| (a.deviation_um - mean).powi(2)).sum::<f64>();
    OneWay { runs: rows.len(), mean_um: mean, s_um: (ss / (n - 1.0)).sqrt() }
}

fn lines(rows: &[&Approach]) -> String {
    rows.iter().map(|a| a.line.to_string()).collect::<Vec<_>>().join(", ")
}

/// An f64 with a total order, to key targets (the parser admits finite values only).
#[derive(Clone, Copy, Debug, PartialEq)]
struct OrdF64(f64);

impl Eq for OrdF64 {}
impl PartialOrd for OrdF64 {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for OrdF64 {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        // -0.0 and 0.0 are one target.
        (self.0 + 0.0).total_cmp(&(other.0 + 0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn approach(target_mm: f64, run: u32, direction: Direction, deviation_um: f64) -> Approach {
        Approach { target_mm, run, direction, deviation_um, line: 0 }
    }

    /// The hand-computed case of cli/tests/iso230_2.rs, in-process.
    #[test]
    fn two_targets_by_hand() {
        use Direction::*;
        let rows = [
            (0.0, Up, [0.0, 1.0, 2.0]),
            (0.0, Down, [-2.0, -2.0, -2.0]),
            (100.0, Up, [4.0, 4.0, 4.0]),
            (100.0, Down, [1.0, 3.0, 5.0]),
        ];
        let mut approaches = Vec::new();
        for (t, d, devs) in rows {
            for (k, x) in devs.into_iter().enumerate() {
                approaches.push(approach(t, k as u32 + 1, d, x));
            }
        }
        let e = evaluate(&Runs { name: "hand".into(), approaches }).unwrap();
        let f = e.figures;
        let got = [f.A, f.A_up, f.A_down, f.E, f.E_up, f.E_down, f.R, f.R_up, f.R_down, f.B, f.B_mean, f.M];
        let want = [9.0, 5.0, 9.0, 6.0, 3.0, 5.0, 8.0, 4.0, 8.0, 3.0, 2.0, 4.0];
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{got:?} vs {want:?}");
        }
        assert!((e.targets[0].repeatability_um() - 5.0).abs() < 1e-12);
    }
}
