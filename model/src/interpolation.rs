//! Whether the readings bear out the interpolation between the measured positions of an axis.
//!
//! Where an axis's knots are bounded by the positions the readings occupy (a laser tracer's
//! stops along the edges), the error functions between two positions are the roughness prior's
//! interpolation, and so is their uncertainty there ([`crate::predict::AxisResolution`]). The
//! prior's smoothness is what the readings showed as a whole; a feature shorter than the step (a
//! bump of a guideway between two stops) is not in it. Such a feature is nearly invisible at the
//! stops, but not to the neighbouring ones: leaving out every reading at one position, the fit
//! from the others predicts them worse than its own uncertainty says. This module tests that,
//! each inner position of the axis left out in turn ([`crate::estimator::Fit::deletion_statistics`]),
//! and, when the test fails, the error between the positions is not determined by the data
//! ([`crate::predict::AxisResolution::contradicted`]) and the statement says what to measure.

use crate::axis::Axis;
use crate::campaign::Observations;
use crate::diagnose::locate::chi2_sf;
use crate::estimator::Fit;
use crate::predict::median_spacing;

/// Family-wise significance over a campaign's checked axes below which the interpolation is
/// reported as contradicted by the readings: one campaign in a hundred whose errors are smooth at
/// the step is told to measure again for nothing. Each axis is judged at this level over the
/// number of axes checked (Bonferroni).
pub const INTERPOLATION_ALPHA: f64 = 1e-2;

/// Leave-one-position-out check of the interpolation along one axis.
#[derive(Clone, Debug, PartialEq)]
pub struct InterpolationCheck {
    pub axis: Axis,
    /// Inner positions left out, one at a time (the two ends are not: leaving them out
    /// extrapolates).
    pub positions: usize,
    /// Readings at those positions.
    pub readings: usize,
    /// Sum of the positions' deletion statistics over the noise scale of the fit: a chi-square
    /// on `readings` degrees of freedom when the interpolation is as good as its uncertainty.
    pub chi2: f64,
    /// Its upper-tail probability.
    pub p_value: f64,
    /// Median spacing of the measured positions, metres.
    pub step_m: f64,
    /// Level this axis is judged at: [`INTERPOLATION_ALPHA`] over the number of axes checked.
    pub level: f64,
}

impl InterpolationCheck {
    /// Prediction variance of the left-out positions against the one the uncertainty states.
    pub fn ratio(&self) -> f64 {
        self.chi2 / self.readings as f64
    }

    /// The readings contradict the interpolation along this axis (p below its level).
    pub fn contradicted(&self) -> bool {
        self.p_value < self.level
    }

    /// For the report, when contradicted.
    pub fn statement(&self) -> String {
        let a = self.axis.letter();
        format!(
            "Between the measured positions along {a} the readings do not bear out the interpolation: leaving out each of the {} inner positions in turn, the fit from the others predicts its readings with {:.2} times the variance its uncertainty states (chi2 {:.1} on {}, p {:.1e}). A feature shorter than the step (about {:.0} mm) is likely there, which the interpolation misses by more than its uncertainty, so the error between the positions along {a} is reported as not determined: measure at more positions along {a} (e.g. halve the step).",
            self.positions,
            self.ratio(),
            self.chi2,
            self.readings,
            self.p_value,
            self.step_m * 1e3,
        )
    }
}

/// Checks the interpolation of `fit` along each of `axes`, whose readings resolve it only at
/// their positions (sorted; a reading within the tolerance of one is at it). An axis is left
/// out when fewer than three positions leave nothing inside to leave out, or no reading lies at
/// an inner one.
pub fn check_axes(fit: &Fit<'_>, obs: &Observations, axes: &[(Axis, &[f64], f64)]) -> Vec<InterpolationCheck> {
    let per_axis: Vec<Vec<Vec<usize>>> =
        axes.iter().map(|&(a, positions, tol)| left_out_sets(obs, a, positions, tol)).collect();
    // One pass of the fit's rows for every axis's sets.
    let all: Vec<Vec<usize>> = per_axis.iter().flatten().cloned().collect();
    let mut stats = fit.deletion_statistics(&all).into_iter();
    let scale = fit.solution().stats.variance_factor.max(1.0);
    let mut checks: Vec<InterpolationCheck> = axes
        .iter()
        .zip(&per_axis)
        .filter_map(|(&(axis, positions, _), sets)| {
            let (mut chi2, mut readings, mut left_out) = (0.0, 0, 0);
            for (set, t) in sets.iter().zip(stats.by_ref().take(sets.len())) {
                if let Some(t) = t {
                    chi2 += t / scale;
                    readings += set.len();
                    left_out += 1;
                }
            }
            (readings > 0).then(|| InterpolationCheck {
                axis,
                positions: left_out,
                readings,
                chi2,
                p_value: chi2_sf(chi2, readings as f64),
                step_m: median_spacing(positions),
                level: INTERPOLATION_ALPHA,
            })
        })
        .collect();
    let level = INTERPOLATION_ALPHA / checks.len().max(1) as f64;
    checks.iter_mut().for_each(|c| c.level = level);
    checks
}

/// The readings at each inner position of `axis` (the two ends are not left out: that would
/// extrapolate), positions without a reading omitted.
fn left_out_sets(obs: &Observations, axis: Axis, positions: &[f64], tolerance_m: f64) -> Vec<Vec<usize>> {
    let inner = positions.get(1..positions.len().saturating_sub(1)).unwrap_or(&[]);
    inner
        .iter()
        .map(|&q| (0..obs.len()).filter(|&i| (axis.coord(&obs.x[i]) - q).abs() <= tolerance_m).collect())
        .filter(|s: &Vec<usize>| !s.is_empty())
        .collect()
}
