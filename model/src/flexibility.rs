//! How flexible an error model the readings support: the machine file's representation, or a
//! coarser one, chosen by the Bayesian information criterion of the plain fit.
//!
//! Why: a representation sized for a whole campaign (e.g. cubic B-splines with 8 intervals)
//! has as many free directions as a part of it has readings. Fitted to the first device
//! positions of a campaign still running, it absorbs what it should reveal: a lost count of
//! 1.3 µm in one beam leaves a residual at the noise floor, and the diagnosis names instead
//! whatever the surplus freedom happens to fit. Of the candidates, the one with the least
//! `BIC = χ² + k ln n` (`k` the parameters the data determine, `n` the readings) is kept: more
//! flexibility only where the readings pay for it.

use crate::campaign::Observations;
use crate::estimator::{solve, SolveError, SolveOptions};
use crate::model::ModelLayout;
use crate::repr::Representation;

/// Coarsening factors tried, from the layout as given down to about a third of its knots.
pub const FACTORS: [f64; 4] = [1.0, 0.75, 0.5, 0.375];

/// One candidate layout and its criterion.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// The representations, as `bspline 8`, per distinct representation of the layout.
    pub label: String,
    pub layout_params: usize,
    /// Parameters the readings determine (readings minus degrees of freedom).
    pub determined: usize,
    pub chi2: f64,
    pub bic: f64,
}

/// The choice and every candidate considered.
#[derive(Clone, Debug)]
pub struct Choice {
    pub layout: ModelLayout,
    /// Index of the chosen candidate in `candidates`.
    pub chosen: usize,
    pub candidates: Vec<Candidate>,
}

impl Choice {
    /// One line: what was chosen and against what.
    pub fn describe(&self) -> String {
        let all: Vec<String> = self
            .candidates
            .iter()
            .enumerate()
            .map(|(i, c)| format!("{}{} (BIC {:.1})", if i == self.chosen { "*" } else { "" }, c.label, c.bic))
            .collect();
        format!(
            "representation {} chosen by BIC from the readings: {}",
            self.candidates[self.chosen].label,
            all.join(", ")
        )
    }
}

/// `r` with about `factor` of its flexibility (at least a cubic's worth).
fn coarsen(r: Representation, factor: f64) -> Representation {
    let scale = |k: usize, min: usize| ((k as f64 * factor).round() as usize).clamp(min.min(k), k);
    match r {
        Representation::BSpline { intervals } => Representation::BSpline { intervals: scale(intervals, 2) },
        Representation::Table { nodes } => Representation::Table { nodes: scale(nodes, 3) },
        Representation::Polynomial { degree } => Representation::Polynomial { degree: scale(degree, 3) },
        Representation::Harmonic { harmonics, period_m } => {
            Representation::Harmonic { harmonics: scale(harmonics, 1), period_m }
        }
    }
}

/// `layout` with every function coarsened by `factor`.
pub fn coarsened(layout: &ModelLayout, factor: f64) -> ModelLayout {
    let reprs: Vec<Representation> = layout.bases.iter().map(|b| coarsen(b.repr, factor)).collect();
    ModelLayout::new(layout.topology.clone(), layout.travel, reprs.try_into().expect("18 functions"))
}

fn label(layout: &ModelLayout) -> String {
    let mut seen: Vec<String> = Vec::new();
    for b in &layout.bases {
        let s = match b.repr {
            Representation::BSpline { intervals } => format!("bspline {intervals}"),
            Representation::Table { nodes } => format!("table {nodes}"),
            Representation::Polynomial { degree } => format!("polynomial {degree}"),
            Representation::Harmonic { harmonics, .. } => format!("harmonic {harmonics}"),
        };
        if !seen.contains(&s) {
            seen.push(s);
        }
    }
    seen.join(" / ")
}

/// Chooses among `layout` and its coarsenings ([`FACTORS`]) the one of least BIC for `obs`.
/// Candidates that do not solve are left out; the error of the layout as given is returned
/// when none solves.
pub fn choose(layout: &ModelLayout, obs: &Observations, opts: &SolveOptions) -> Result<Choice, SolveError> {
    let n = obs.len() as f64;
    let mut layouts: Vec<ModelLayout> = Vec::new();
    let mut candidates = Vec::new();
    let mut first_error = None;
    for f in FACTORS {
        let l = coarsened(layout, f);
        if layouts.iter().any(|o| o.bases == l.bases) {
            continue;
        }
        match solve(&l, obs, opts, &[]) {
            Ok(s) => {
                let determined = s.stats.n_obs.saturating_sub(s.stats.dof);
                candidates.push(Candidate {
                    label: label(&l),
                    layout_params: l.n_params,
                    determined,
                    chi2: s.stats.chi2,
                    bic: s.stats.chi2 + determined as f64 * n.ln(),
                });
                layouts.push(l);
            }
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    if candidates.is_empty() {
        return Err(first_error.expect("at least one candidate"));
    }
    let chosen = (0..candidates.len()).min_by(|&a, &b| candidates[a].bic.total_cmp(&candidates[b].bic)).unwrap();
    Ok(Choice { layout: layouts.swap_remove(chosen), chosen, candidates })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelLayout;
    use crate::topology::Topology;
    use crate::Travel;

    #[test]
    fn coarsening_keeps_a_minimum_and_never_grows() {
        assert_eq!(coarsen(Representation::BSpline { intervals: 8 }, 0.5), Representation::BSpline { intervals: 4 });
        assert_eq!(coarsen(Representation::BSpline { intervals: 3 }, 0.375), Representation::BSpline { intervals: 2 });
        assert_eq!(coarsen(Representation::BSpline { intervals: 1 }, 0.375), Representation::BSpline { intervals: 1 });
        assert_eq!(coarsen(Representation::Polynomial { degree: 5 }, 0.375), Representation::Polynomial { degree: 3 });
        let l = ModelLayout::uniform(
            Topology::parse("FXYZ").unwrap(),
            Travel::new([0.0, 1.0], [0.0, 1.0], [0.0, 1.0]),
            Representation::BSpline { intervals: 8 },
        );
        assert!(coarsened(&l, 0.5).n_params < l.n_params);
        assert_eq!(label(&coarsened(&l, 0.75)), "bspline 6");
    }
}
