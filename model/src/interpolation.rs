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
//!
//! Leaving a position out is what finds the bump: the fit with it passes near its readings. A
//! score test of a free value of each of the axis's functions at each inner position, as an
//! extension of the fit (an experiment, not kept), saw 1.05 to 1.36 times the stated variance
//! where the deletion sees 1.31 to 1.60 (sparse tracer over a bump, seeds 1-8), and warned in
//! none of them.
//!
//! The sum over the axis's positions is also what finds it best: the largest single position's
//! statistic (its p times the number of positions, an experiment not kept, meant to say between
//! which positions the interpolation fails) was below the sum's p in only 10 of the 60 axes of
//! the sparse tracer over a bump (seeds 1-20) and 14 of 60 on smooth truths, and would have
//! contradicted no axis the sum does not: each of an axis's six functions carries its own bump,
//! so what the interpolation misses is spread over the positions, not at one of them.
//! For the same reason the variance scale between the positions is the axis's
//! ([`crate::predict::AxisResolution`]), not the interval's: a scale per interval from the
//! deletion statistics of the positions around it (its two ends, or four positions; an
//! experiment, not kept) took the sparse tracer over a bump from 1.535 to 1.492 and 1.510
//! actual / predicted map RMS, and smooth truths from 0.935 to 0.909 and 0.925 (seeds 1-20):
//! little gain, and a local scale adds its own noise.
//!
//! Nor do wider gaps show what a single position left out misses. The paper's linear tables
//! measured by the sparse tracer fail between the stops (errors up to 7.4 times their stated
//! uncertainty over seeds 6001-6100, docs/representation-auto.md), while leaving out one stop their readings are
//! predicted as well as stated. If the prior's interpolation variance grew too fast with the gap
//! for the truth's kinks, leaving out two or three neighbouring stops (gaps of three and four
//! steps instead of two) would show a falling ratio. It does not (a probe, not kept; sets of
//! neighbouring positions through [`crate::estimator::Fit::deletion_statistics`], seeds 1-6,
//! mean over the 18 axes, one, two and three positions left out): the tables 0.929, 0.916 and
//! 0.920; the polynomials with long sinusoids 0.910, 0.913 and 0.921; over a bump 1.312, 1.242
//! and 1.197.

use crate::axis::Axis;
use crate::campaign::Observations;
use crate::diagnose::locate::chi2_sf;
use crate::estimator::Fit;
use crate::functions::ErrorFunction;
use crate::model::ModelLayout;
use crate::predict::median_spacing;
use faer::Mat;

/// Family-wise significance over a campaign's checked axes below which the interpolation is
/// reported as contradicted by the readings: at most one campaign in twenty whose errors are
/// smooth at the step is told to measure again for nothing, the level of a metrology lab's
/// chi-square consistency check. The axes are judged by Holm's step-down procedure: the smallest
/// p against this level over the number of axes checked, the next, once that one is
/// contradicted, over one fewer, and so on (the same family-wise level as Bonferroni's, and
/// never less power).
///
/// Five per cent, not one: a miss costs more than a false alarm here. A missed contradiction
/// prints a map between the stops under an uncertainty that does not cover it; a false one asks
/// for a finer step where the readings would not have needed it. Over a bump, most axes the one
/// per cent level let pass scored p between 0.005 and 0.05 (sparse tracer, seeds 1-20), while on
/// smooth truths the statistic sits below its expectation (ratios 0.7 to 1.15, no axis below p
/// 0.1). Sparse tracer, seeds 1-20, one per cent -> five: over a bump, contradicted in 18 -> 20
/// of 20 campaigns, the points not determined 39 % -> 67 %, the map error at the points still
/// given 2.10 -> 1.66 times the oracle's, actual / predicted 1.54 -> 1.40, the error components
/// beyond 3 sigma between the stops 6.8 % -> 5.8 %, the whole map within its simultaneous band in
/// 6 -> 11 of 20; smooth truths and the paper's tables: no campaign contradicted at either level.
/// The dense tracer (21 stops) over a bump is contradicted in 9 instead of 3 of 20 campaigns (9 %
/// instead of 2 % of the points not determined, the rest unchanged: 1.37 -> 1.35 times the
/// oracle's, actual / predicted 1.05), the paper's tables in 5 instead of 4. On seeds 6001-6100,
/// run once after the choice: the sparse tracer over a bump 2.07 -> 1.73 times the oracle's,
/// actual / predicted 1.46 -> 1.35, 50 -> 69 % not determined; one campaign of 100 with smooth
/// errors contradicted (docs/representation-auto.md, "At five per cent").
pub const INTERPOLATION_ALPHA: f64 = 5e-2;

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
    /// The left-out readings' summed leverage ([`crate::estimator::Deletion::leverage`]): the
    /// part of `readings` that the chi-square's expectation owes to the interpolation's
    /// variance rather than to the readings' noise.
    pub leverage: f64,
    /// Its upper-tail probability.
    pub p_value: f64,
    /// Median spacing of the measured positions, metres.
    pub step_m: f64,
    /// Level this axis is judged at ([`INTERPOLATION_ALPHA`], Holm's step-down over the axes
    /// checked): `INTERPOLATION_ALPHA / (m - k)` for the axis of the k-th smallest p of `m`, up
    /// to the first axis not contradicted; the axes after it are judged at that axis's level.
    pub level: f64,
    /// The same check on a coarser interpolant of the axis, where the fit's knots go further
    /// beyond the positions than the coarser ones (`flexibility::between_positions`): it, not
    /// this one, judges whether the readings contradict the interpolation. This one's chi-square
    /// and leverage still give the variance scale of the fit's interpolation ([`variance_scale`]).
    pub judged_on: Option<Box<InterpolationCheck>>,
}

impl InterpolationCheck {
    /// Prediction variance of the left-out positions against the one the uncertainty states.
    pub fn ratio(&self) -> f64 {
        self.chi2 / self.readings as f64
    }

    /// The readings contradict the interpolation along this axis (p below its level; that of
    /// the coarser interpolant's check where there is one, [`InterpolationCheck::judged_on`]).
    pub fn contradicted(&self) -> bool {
        match &self.judged_on {
            Some(c) => c.contradicted(),
            None => self.p_value < self.level,
        }
    }

    /// For the report, when contradicted.
    pub fn statement(&self) -> String {
        if let Some(c) = &self.judged_on {
            return c.statement();
        }
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
            let (mut chi2, mut leverage, mut readings, mut left_out) = (0.0, 0.0, 0, 0);
            for (set, d) in sets.iter().zip(stats.by_ref().take(sets.len())) {
                if let Some(d) = d {
                    chi2 += d.statistic / scale;
                    leverage += d.leverage;
                    readings += set.len();
                    left_out += 1;
                }
            }
            (readings > 0).then(|| InterpolationCheck {
                axis,
                positions: left_out,
                readings,
                chi2,
                leverage,
                p_value: chi2_sf(chi2, readings as f64),
                step_m: median_spacing(positions),
                level: INTERPOLATION_ALPHA,
                judged_on: None,
            })
        })
        .collect();
    holm(&mut checks);
    checks
}

/// Share of the best-measured position's that a position's own readings must remove of some
/// function's variance for it to count as measured ([`measured_positions`]).
pub const MEASURED_SHARE: f64 = 0.5;

/// For each of `axes` (with its positions, sorted, and the tolerance within which a reading is at
/// one), the positions at which the readings measure the axis's error functions, and those they
/// only touch with the share of every function's variance their readings remove, the least
/// over the axis's functions (both sorted; what they still add to the interpolation there,
/// [`crate::predict::with_own_readings`]): the
/// measured are the two ends, each inner
/// position without whose readings the fit does not hold, and each whose own readings remove
/// of some function's variance there (its variance as fitted against the fit's without them,
/// [`Fit::deletion_variances`]) at least [`MEASURED_SHARE`] of what the best-measured inner
/// position's remove.
///
/// Why: a laser tracer's stop between a fixed beam's points has readings (four ranges per edge
/// through it), but they pin the functions there far less than the beams' readings at their
/// points; the value there is mostly the prior's interpolation between the beams' points, and a
/// feature between them is missed by more than the stated uncertainty. Counted as measured,
/// such a stop was given neither the interpolation's variance scale nor the straight-run bound.
/// Seen on the independent simulator with a narrow bump on every function (the 45 beams and the
/// tracer, seeds 1081-1100): axis X lines at the stops x = 0.1 and 0.3 m up to 6.9 standard
/// uncertainties off. The share there is 0.19 to 0.57 for the best-pinned function, at the
/// beams' points 0.62 to 0.99 (docs/representation-auto.md, "How much a stop's own readings pin
/// the functions").
///
/// Against the best-measured position, not an absolute share: where the positions are as dense
/// as the knots or denser, the neighbours determine much of each one's value, and a plan of one
/// kind of readings measures all its positions alike (the sparse tracer over the paper's tables:
/// 0.32 to 0.53 along X and Y; over the other truths 0.73 to 0.99). Positions of a kind are
/// measured alike; the rule singles out those read far more weakly than the axis's others.
pub fn measured_positions(
    fit: &Fit<'_>,
    layout: &ModelLayout,
    obs: &Observations,
    axes: &[(Axis, &[f64], f64)],
) -> Vec<PositionKinds> {
    let per_axis: Vec<Vec<(Vec<usize>, Mat<f64>)>> =
        axes.iter().map(|&(a, positions, tol)| inner_position_sets(layout, obs, a, positions, tol)).collect();
    let lens: Vec<usize> = per_axis.iter().map(Vec::len).collect();
    // One pass of the fit's rows for every axis's positions.
    let all: Vec<(Vec<usize>, Mat<f64>)> = per_axis.into_iter().flatten().collect();
    let mut got = fit.deletion_variances(&all).into_iter();
    axes.iter()
        .zip(lens)
        .map(|(&(_, positions, _), len)| {
            // The largest and the smallest share of any function's variance that each inner
            // position's own readings remove; `None` where the fit does not hold without them
            // (then they measure it).
            let shares: Vec<Option<(f64, f64)>> = got
                .by_ref()
                .take(len)
                .map(|v| {
                    v.map(|v| {
                        v.iter()
                            .filter(|&&(_, without)| without > 0.0)
                            .map(|&(with, without)| 1.0 - with / without)
                            .fold((0.0, 1.0), |(hi, lo): (f64, f64), s| (hi.max(s), lo.min(s)))
                    })
                })
                .collect();
            let best = shares.iter().flatten().map(|s| s.0).fold(0.0, f64::max);
            let (mut measured, mut touched) = (Vec::new(), Vec::new());
            for (i, &q) in positions.iter().enumerate() {
                let inner = i > 0 && i + 1 < positions.len();
                match shares.get(i.wrapping_sub(1)).copied().flatten() {
                    // What the position adds to its interpolation is what it adds to every
                    // function: the least-pinned one's share.
                    Some((most, least)) if inner && most < MEASURED_SHARE * best => touched.push((q, least.max(0.0))),
                    _ => measured.push(q),
                }
            }
            PositionKinds { measured, touched }
        })
        .collect()
}

/// An axis's positions by what their readings do ([`measured_positions`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PositionKinds {
    /// Positions the readings measure, sorted.
    pub measured: Vec<f64>,
    /// Positions the readings only touch, sorted, each with the least share of a function's
    /// variance there that its readings remove.
    pub touched: Vec<(f64, f64)>,
}

/// The readings at each inner position of `axis` and the rows selecting each of the axis's
/// functions' values there (`n_u x 6`, over the error model's coefficients).
fn inner_position_sets(
    layout: &ModelLayout,
    obs: &Observations,
    axis: Axis,
    positions: &[f64],
    tolerance_m: f64,
) -> Vec<(Vec<usize>, Mat<f64>)> {
    let functions: Vec<ErrorFunction> = ErrorFunction::all().into_iter().filter(|f| f.axis == axis).collect();
    let n_u = functions.iter().map(|&f| layout.range(f).end).max().unwrap_or(0);
    let inner = positions.get(1..positions.len().saturating_sub(1)).unwrap_or(&[]);
    inner
        .iter()
        .map(|&q| {
            let mut s = Mat::<f64>::zeros(n_u, functions.len());
            for (j, &f) in functions.iter().enumerate() {
                let start = layout.range(f).start;
                layout.basis(f).visit(q, false, |i, v| s[(start + i, j)] = v);
            }
            (readings_at(obs, axis, q, tolerance_m), s)
        })
        .collect()
}

/// The factor on the interpolation's variance that the left-out positions of a campaign's checked
/// axes show, pooled over them: with the posterior's variance `F` times the one the fit states,
/// each chi-square's expectation is `readings + (F - 1) leverage` ([`crate::estimator::Deletion`]),
/// and the sums over the axes give `F`. It is the cross-validation estimate of the prior's
/// variance, which stays right where the prior's shape is not the truth's, where REML's does not
/// (Bachoc 2013). 1 without a check.
///
/// The leverage, not the readings: the excess of the chi-square over its degrees of freedom is the
/// interpolation's, not the noise's, and spread over all the readings (the check's
/// [`InterpolationCheck::ratio`], the scale until stop 39) it understated the factor's excess over
/// 1 about three times (the sparse tracer over a bump, seeds 1-20: the leverage is 15 to 39 % of
/// the readings, median 31 %). Pooled, not per axis: one axis's estimate, from 9 positions,
/// scatters from 0.01 to 1.8 on smooth truths, and taken only where above 1 it over-stated them.
/// Sparse tracer, seeds 1-20, actual / predicted map RMS at the points given, the ratio per axis ->
/// this factor per axis -> pooled: over a bump 1.397 -> 1.293 -> 1.240 (error components beyond 3
/// sigma between the stops 5.8 -> 3.2 -> 2.5 %, largest 9.5 -> 8.0 -> 7.3; the whole map within its
/// simultaneous band in 11 -> 12 -> 14 of 20); polynomials with sinusoids 0.935 -> 0.901 -> 0.940;
/// the paper's tables 1.024 -> 0.956 -> 1.030. On seeds 6001-6100, run once after the choice, the
/// ratio -> pooled: over a bump 1.345 -> 1.150, smooth truths 0.929 -> 0.936, the tables 1.056 ->
/// 1.063 (docs/representation-auto.md, "The factor from the leverage"). A campaign whose
/// readings contradict one axis's interpolation widens the others' with it: the evidence that the
/// prior misjudges the roughness is the campaign's.
pub fn variance_scale(checks: &[InterpolationCheck]) -> f64 {
    let excess: f64 = checks.iter().map(|c| c.chi2 - c.readings as f64).sum();
    let leverage: f64 = checks.iter().map(|c| c.leverage).sum();
    if leverage > 0.0 {
        1.0 + excess / leverage
    } else {
        1.0
    }
}

/// Sets each check's level by Holm's step-down procedure at [`INTERPOLATION_ALPHA`].
fn holm(checks: &mut [InterpolationCheck]) {
    let m = checks.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&i, &j| checks[i].p_value.total_cmp(&checks[j].p_value));
    let at = |k: usize| INTERPOLATION_ALPHA / (m - k) as f64;
    // The first step whose axis is borne out; the axes after it are judged at its level.
    let stop = order.iter().enumerate().position(|(k, &i)| checks[i].p_value >= at(k)).unwrap_or(m);
    for (k, &i) in order.iter().enumerate() {
        checks[i].level = at(k.min(stop));
    }
}

/// The readings at each inner position of `axis` (the two ends are not left out: that would
/// extrapolate), positions without a reading omitted.
fn left_out_sets(obs: &Observations, axis: Axis, positions: &[f64], tolerance_m: f64) -> Vec<Vec<usize>> {
    let inner = positions.get(1..positions.len().saturating_sub(1)).unwrap_or(&[]);
    inner.iter().map(|&q| readings_at(obs, axis, q, tolerance_m)).filter(|s: &Vec<usize>| !s.is_empty()).collect()
}

/// The readings at coordinate `q` of `axis`, within `tolerance_m`.
fn readings_at(obs: &Observations, axis: Axis, q: f64, tolerance_m: f64) -> Vec<usize> {
    (0..obs.len()).filter(|&i| (axis.coord(&obs.x[i]) - q).abs() <= tolerance_m).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(axis: Axis, p_value: f64) -> InterpolationCheck {
        InterpolationCheck {
            axis,
            positions: 9,
            readings: 144,
            chi2: 0.0,
            leverage: 0.0,
            p_value,
            step_m: 0.1,
            level: 0.0,
            judged_on: None,
        }
    }

    /// Holm's step-down: the smallest p against alpha / 3, the next against alpha / 2 once the
    /// first is contradicted, and nothing after the first that is not.
    #[test]
    fn holm_steps_down_and_stops_at_the_first_axis_borne_out() {
        let a = INTERPOLATION_ALPHA;
        let mut c = vec![check(Axis::X, 0.44 * a), check(Axis::Y, 1.7e-3 * a), check(Axis::Z, 0.47 * a)];
        holm(&mut c);
        assert!(c.iter().all(InterpolationCheck::contradicted), "{c:?}");
        assert_eq!(c.iter().map(|c| c.level).collect::<Vec<_>>(), [a / 2.0, a / 3.0, a]);

        let mut c = vec![check(Axis::X, 0.17 * a), check(Axis::Y, 0.67 * a), check(Axis::Z, 0.8 * a)];
        holm(&mut c);
        let said: Vec<bool> = c.iter().map(InterpolationCheck::contradicted).collect();
        assert_eq!(said, [true, false, false], "Y fails at alpha / 2, so Z (p below alpha) is not judged: {c:?}");

        let mut c = vec![check(Axis::X, 0.68 * a), check(Axis::Y, 5.7 * a)];
        holm(&mut c);
        assert!(c.iter().all(|c| !c.contradicted()), "{c:?}");
    }

    /// Where a check carries the coarser interpolant's, that one's verdict and statement stand,
    /// whichever way this one's p falls.
    #[test]
    fn the_coarser_interpolants_check_judges() {
        let at = |p: f64| InterpolationCheck { level: INTERPOLATION_ALPHA, ..check(Axis::X, p) };
        let borne_out = InterpolationCheck { judged_on: Some(Box::new(at(1e-4))), ..at(0.5) };
        assert!(borne_out.contradicted());
        assert_eq!(borne_out.statement(), at(1e-4).statement());
        let contradicted = InterpolationCheck { judged_on: Some(Box::new(at(0.5))), ..at(1e-4) };
        assert!(!contradicted.contradicted());
    }
}
