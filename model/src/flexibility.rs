//! How flexible an error model the readings support.
//!
//! Two answers live here. [`auto_layout`] is `representation: auto`, the default: per axis a
//! cubic B-spline whose knots the readings' positions along that axis bound, each function
//! smoothed by a roughness penalty whose strength REML estimates ([`crate::smoothing`]): the
//! data choose each function's flexibility. Where the positions bound the knots, they go
//! beyond what the positions determine (twice as far from the start, [`between_positions`];
//! half as far again after a refinement, [`beyond_positions`]), the prior determining the rest:
//! between the positions the uncertainty is then the prior's, not only the noise's. [`choose`]
//! picks among a given representation and coarser ones by the Bayesian information criterion
//! of the plain fit, for a campaign still running (the live diagnosis).
//!
//! Why the second: a representation sized for a whole campaign (e.g. cubic B-splines with 8 intervals)
//! has as many free directions as a part of it has readings. Fitted to the first device
//! positions of a campaign still running, it absorbs what it should reveal: a lost count of
//! 1.3 µm in one beam leaves a residual at the noise floor, and the diagnosis names instead
//! whatever the surplus freedom happens to fit. Of the candidates, the one with the least
//! `BIC = χ² + k ln n` (`k` the parameters the data determine, `n` the readings) is kept: more
//! flexibility only where the readings pay for it.

use crate::axis::{Axis, Travel};
use crate::campaign::Observations;
use crate::estimator::{fit, solve, Effect, Fit, ObsContext, Solution, SolveError, SolveOptions};
use crate::functions::ErrorFunction;
use crate::interpolation::{self, InterpolationCheck};
use crate::model::ModelLayout;
use crate::predict::AxisResolution;
use crate::repr::{Basis, Representation};
use crate::smoothing::Smoothing;
use crate::topology::Topology;

/// `representation: auto`: knots from the data, smoothing by REML.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Auto {
    /// Knot intervals per axis to start from (where the positions determine fewer:
    /// [`between_positions`]).
    pub start_intervals: usize,
    /// Most knot intervals per axis. The penalty, not the knot count, sets the flexibility; the
    /// knots must only be fine enough for the finest detail the readings resolve, which the
    /// refinement test finds. Not the knot count of penalised-spline practice, as many knots as
    /// allowed from the start (Eilers & Marx; an experiment, `start_intervals` 48, not kept):
    /// over a local bump with dense beams it took the map error from 1.52 to 1.40 (FXYZ) and
    /// from 1.74 to 1.65 (FYXZ) times the oracle's, but sparse FYXZ beams from 1.45 to 1.65,
    /// smooth truths with dense beams from 1.04 to 1.09 and 1.16 to 1.19, and the solve 1.6
    /// to 20 times longer (seeds 1-5, every case of issue 12's table; the tracers' knots, bound
    /// by their stops, did not move). Nor a higher limit, 96 (an experiment, not kept; the
    /// refinement test still decides, so only the cases whose readings ask for more move;
    /// dense campaigns of every family, seeds 1-10): only the paper's tables with dense beams
    /// went beyond 48 (Y to 96, its 48 -> 96 test at p 3e-4). Their actual / predicted map
    /// error moved from 1.195 to 1.126 and the solve took 1.16 s instead of 0.57 s. The joint
    /// campaign over the tables took 2.30 s instead of 1.42 s for nothing (0.914 -> 0.921 times
    /// the oracle's map error). The under-statement at the tables' kinks is the prior's
    /// (one smoothing strength for a function whose roughness sits at its nodes), not the
    /// knots'.
    pub max_intervals: usize,
    /// Whether linear tables are tried where the readings show kinks at equally spaced nodes
    /// (`choose_tables`). Off by default for now: over the paper's tables every held-out
    /// figure improves with them, but with sparse beams they lower the map error while the
    /// detail floor's over-statement of the other axes stays, and actual / predicted falls to
    /// 0.586 on `representation_auto`'s seeds, below the 0.6 its test allows
    /// (docs/representation-auto.md, "Linear tables where the readings show kinks").
    pub tables: bool,
}

impl Default for Auto {
    fn default() -> Self {
        Auto { start_intervals: 12, max_intervals: 48, tables: false }
    }
}

/// Why an axis ended with its number of knot intervals.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KnotBound {
    /// The most allowed ([`Auto::max_intervals`]).
    Limit,
    /// The most that the readings' positions along the axis determine: between two of them
    /// the error functions are interpolated (features shorter than the step are not resolved).
    Positions,
    /// The readings do not ask for finer knots (the refinement test).
    Data,
    /// The readings lie at too few positions along the axis to tell the functions' roughness
    /// ([`smoothable`]): the functions are not smoothed, their knots leave one direction each
    /// open ([`few_positions_intervals`]), and away from the positions the data leave them open.
    FewPositions,
}

/// One refinement test of an axis: would doubling its knots explain the readings better than
/// chance? (Score test of the finer basis against the smoothed fit, [`crate::estimator::Fit::score`].)
#[derive(Clone, Debug, PartialEq)]
pub struct RefinementTest {
    pub from: usize,
    pub to: usize,
    /// Chi-square reduction the finer knots would give, and its degrees of freedom.
    pub delta_chi2: f64,
    pub dof: usize,
    pub p_value: f64,
    pub refined: bool,
    /// Whether the readings' geometry and the roughness prior together determine the finer
    /// knots (a refinement that would leave directions undetermined is undone).
    pub determined: bool,
}

/// What the auto representation chose for one axis, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisKnots {
    pub axis: Axis,
    /// Distinct positions of the readings along the axis (to 0.1 um).
    pub positions: usize,
    /// Knot intervals of the axis's cubic B-splines.
    pub intervals: usize,
    /// The most knot intervals the positions determine on their own ([`positions_bound`]).
    /// Where the positions bound the knots, `intervals` exceeds it ([`between_positions`],
    /// [`beyond_positions`]) and the roughness prior determines the rest.
    pub determined: usize,
    pub bound: KnotBound,
    pub tests: Vec<RefinementTest>,
    /// Where the axis's functions are linear tables instead of cubic B-splines
    /// (`choose_tables`).
    pub table: Option<TableChoice>,
}

/// Linear tables chosen for an axis's error functions: the readings show kinks at equally
/// spaced nodes (a machine compensated by tables of that spacing, or the tables of the patent
/// and of Han et al.), which a cubic spline rounds off.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TableChoice {
    /// Intervals of the tables, equal over the travel (`intervals + 1` nodes).
    pub intervals: usize,
    /// How much lower the tables' Akaike criterion is than the smoothing's, on this axis with
    /// the others held (the screening, [`TABLE_INTERVALS`]).
    pub aic_gain: f64,
    /// How much lower it is for the final fit, every chosen axis's tables penalised by REML.
    pub final_gain: f64,
}

impl AxisKnots {
    /// One line for reports.
    pub fn describe(&self) -> String {
        if let Some(t) = &self.table {
            return format!(
                "{}: linear tables of {} intervals (nodes equally spaced over the travel), their kinks smoothed by \
                 REML, chosen over cubic B-splines: the Akaike criterion of the readings is {:.0} lower with them \
                 on this axis alone and {:.0} lower for the whole fit ({} to {} intervals tried; every interval \
                 holds readings that test the table's line)",
                self.axis.letter(),
                t.intervals,
                t.aic_gain,
                t.final_gain,
                TABLE_INTERVALS[0],
                TABLE_INTERVALS[1]
            );
        }
        let why = match self.bound {
            KnotBound::Limit => format!("the most allowed; {} positions along the axis", self.positions),
            KnotBound::Positions if self.intervals > self.determined => format!(
                "the {} positions along the axis determine {}; the roughness prior determines the rest, and \
                 between the positions the functions are interpolated with its uncertainty",
                self.positions, self.determined
            ),
            KnotBound::Positions => format!(
                "the most that the {} positions along the axis determine; between them the functions are interpolated",
                self.positions
            ),
            KnotBound::Data if self.tests.last().is_some_and(|t| !t.determined) => {
                "neither the readings' geometry nor the roughness prior determines finer knots".to_string()
            }
            KnotBound::Data => "finer knots would not explain the readings better".to_string(),
            KnotBound::FewPositions => format!(
                "not smoothed: the readings lie at {} position(s) along the axis, too few to tell how rough \
                 the functions are (at least {} are needed); away from those positions the functions are not \
                 determined: measure at more positions along {}",
                self.positions,
                MIN_SMOOTHED_POSITIONS,
                self.axis.letter()
            ),
        };
        let tests: Vec<String> = self
            .tests
            .iter()
            .map(|t| {
                format!(
                    "{} -> {}: chi2 {:.1} on {} dof, p {:.1e}{}",
                    t.from,
                    t.to,
                    t.delta_chi2,
                    t.dof,
                    t.p_value,
                    if t.refined {
                        ", refined"
                    } else if !t.determined {
                        ", undone: neither the readings' geometry nor the roughness prior determines the finer knots"
                    } else {
                        ""
                    }
                )
            })
            .collect();
        let tests = if tests.is_empty() { String::new() } else { format!("; tests {}", tests.join("; ")) };
        format!("{}: cubic B-spline, {} intervals ({why}{tests})", self.axis.letter(), self.intervals)
    }
}

/// Whether readings at `positions` (sorted, distinct) determine every coefficient of `basis`:
/// there are positions `t_1 < t_2 < ...`, one per coefficient, each inside its basis function's
/// support (the Schoenberg-Whitney condition; a greedy match finds them when they exist, since
/// the supports move monotonically along the axis).
pub fn positions_determine(basis: &Basis, positions: &[f64]) -> bool {
    let mut next = 0;
    'coefficient: for i in 0..basis.n_coeffs() {
        // A cubic B-spline's coefficient `i` is zero below its first span, `i - 3`: the positions
        // there need not be looked at.
        if let Representation::BSpline { intervals } = basis.repr {
            let start = basis.lo + basis.length() * i.saturating_sub(3) as f64 / intervals as f64;
            next = next.max(positions.partition_point(|&q| q < start));
        }
        while next < positions.len() {
            let q = positions[next];
            next += 1;
            let mut inside = false;
            basis.visit(q, false, |k, v| inside |= k == i && v > 1e-9);
            if inside {
                continue 'coefficient;
            }
        }
        return false;
    }
    true
}

/// The readings' positions along `axis` that lie in its travel (to a nanometre).
fn inside_travel(travel: &Travel, axis: Axis, positions: &[Vec<f64>; 3]) -> Vec<f64> {
    let [lo, hi] = travel.range(axis);
    positions[axis.index()].iter().copied().filter(|q| (lo - 1e-9..=hi + 1e-9).contains(q)).collect()
}

/// Per axis, the most knot intervals (up to `most`) that readings at `positions` determine.
pub fn positions_bound(travel: &Travel, positions: &[Vec<f64>; 3], most: usize) -> [(usize, usize); 3] {
    Axis::ALL.map(|axis| {
        let [lo, hi] = travel.range(axis);
        let inside = inside_travel(travel, axis, positions);
        let most = most.max(1);
        let k = (1..=most.min(inside.len().saturating_sub(3)).max(1))
            .rev()
            .find(|&k| positions_determine(&Basis::new(Representation::BSpline { intervals: k }, lo, hi), &inside))
            .unwrap_or(1);
        (k, inside.len())
    })
}

/// The auto layout with `intervals` per axis; functions with a representation in `overrides`
/// keep it.
fn layout_with(
    topology: &Topology,
    travel: Travel,
    intervals: [usize; 3],
    overrides: &[Option<Representation>; 18],
) -> ModelLayout {
    let reprs: [Representation; 18] = std::array::from_fn(|i| {
        overrides[i]
            .unwrap_or(Representation::BSpline { intervals: intervals[ErrorFunction::from_index(i).axis.index()] })
    });
    ModelLayout::new(topology.clone(), travel, reprs)
}

/// The error functions of `axis` that `auto` chooses (those without a representation in
/// `overrides`), canonical order.
fn auto_functions(axis: Axis, overrides: &[Option<Representation>; 18]) -> Vec<ErrorFunction> {
    (0..6).map(|m| ErrorFunction::from_index(axis.index() * 6 + m)).filter(|f| overrides[f.index()].is_none()).collect()
}

/// Fewest distinct positions along an axis whose readings smooth its functions: the
/// roughness penalty's null space (the quadratics, [`crate::smoothing::PENALTY_ORDER`]) and
/// three values beyond it, as many as the detail floor keeps ([`crate::smoothing`]).
pub const MIN_SMOOTHED_POSITIONS: usize = crate::smoothing::PENALTY_ORDER + 3;

/// Whether readings at `positions` distinct positions along an axis can tell how rough its
/// functions are ([`MIN_SMOOTHED_POSITIONS`]).
///
/// Through three values or fewer a parabola passes whatever the errors: the readings leave
/// the penalised part wholly to the prior, REML takes the smoothing to its upper bound, and
/// the penalised normal matrix holds the readings' one value per position beside a penalty
/// some 1e13 times larger. A campaign whose readings hold Y at one position failed as
/// singular. With four or five the readings give one or two values of roughness, and REML's
/// estimate from them states the functions between the positions far too sharply. Measured on
/// a tracer with n stops per edge (the plan's default four stations), solved with the two-line
/// machine file, its body diagonals and axis lines (21 targets each) against a simulated
/// interferometer, seeds 1-20, the share of determined targets off by more than three standard
/// uncertainties:
/// - over the demo machine's polynomials, 12.7 % at four stops (largest 18.9) and 10.2 % at
///   five (11.4), all between the stops, against 0 % at six and 0.04 % at eight;
/// - over the paper's tables, 0.89 % at four (largest 3.68), 0 % at five and six.
///
/// Now, over the polynomials, 0 % at four (largest 2.76) and 0.18 % at five (3.04), over the
/// tables 0 % at both; held out (the machine tool XFYZ, seeds 101-120, run once) 9.6 and 4.3 %
/// became 0.71 and 0.18 %. The map is then given at the stops only.
///
/// Such an axis's functions are not smoothed; their knots leave one direction each open
/// ([`few_positions_intervals`]): determined at the positions, not determined away from them.
pub fn smoothable(positions: usize) -> bool {
    positions >= MIN_SMOOTHED_POSITIONS
}

/// Knot intervals of an axis that is not [`smoothable`]: one coefficient more than its
/// `positions`, so that the readings determine the functions' values at the positions and
/// leave one direction each open between them (at least one interval).
pub fn few_positions_intervals(positions: usize) -> usize {
    positions.saturating_sub(2).max(1)
}

/// The smoothing of the auto layout: by REML, every function without an override whose axis's
/// `knots` are not bound by too few positions ([`KnotBound::FewPositions`], [`smoothable`]).
fn smoothing_for(overrides: &[Option<Representation>; 18], knots: &[AxisKnots; 3]) -> Smoothing {
    let mut s = Smoothing::reml();
    for (i, o) in overrides.iter().enumerate() {
        let axis = ErrorFunction::from_index(i).axis.index();
        s.penalised[i] = o.is_none() && knots[axis].bound != KnotBound::FewPositions;
    }
    s
}

/// The starting `representation: auto` layout for readings at `positions` (per axis, sorted and
/// distinct: [`crate::identify::DataSummary::positions_of`]), before any refinement: per axis
/// `auto.start_intervals`, or, where the positions determine fewer, [`between_positions`] of
/// what they determine. Functions given a representation in `overrides` keep it and are not
/// smoothed.
pub fn auto_layout(
    topology: Topology,
    travel: Travel,
    positions: &[Vec<f64>; 3],
    auto: &Auto,
    overrides: &[Option<Representation>; 18],
) -> (ModelLayout, [AxisKnots; 3], Smoothing) {
    let bound = positions_bound(&travel, positions, auto.max_intervals);
    let (layout, knots) = auto_layout_within(topology, travel, &bound, auto, overrides);
    let smoothing = smoothing_for(overrides, &knots);
    (layout, knots, smoothing)
}

/// Knot intervals of an axis whose readings' positions determine at most `most`: half as many
/// again, up to `auto.max_intervals`, the roughness prior determining the coefficients the
/// positions leave open. For an axis whose refinement reaches `most` (`widen_at_bound`); from
/// the start, where `most` is below `auto.start_intervals`, it was this until stop 73 and is
/// now [`between_positions`].
///
/// Why more than the positions determine: a cubic B-spline with as many coefficients as
/// positions is fixed by its values there, so between two positions it has no freedom left,
/// and its uncertainty there is only the noise's at the positions around. The smoothing prior
/// knows better: between the positions the function may curve as much as the readings show it
/// curving, and with a few coefficients more it says so, with an uncertainty that grows
/// between the positions. Measured (`auto_study`, truth with a local bump, seeds 1-20 and
/// held-out 1001-1020): the laser tracer's 11 stops per edge (8 intervals determined, 12
/// taken) gave 4.30 and 4.64 times the oracle's map error with actual / predicted 3.71 and
/// 3.99, now 2.41 and 2.62 with 1.67 and 1.75 (16 intervals: 2.31 and 1.58 on seeds 1-20); its
/// 21 stops (18 determined, 27 taken once refined to 18) gave 1.45 and 2.33 with 1.14 and
/// 1.81, now 1.38 and 1.42 with 1.09 and 1.11. Smooth truths did not move. Not more than half
/// again after a refinement; from the start not more than twice ([`between_positions`]): with
/// 20 or 24 intervals for the 11 stops the solve no longer held (the prior alone then carries
/// more directions than the readings do, and the penalised normal matrix lost definiteness).
pub fn beyond_positions(most: usize, auto: &Auto) -> usize {
    (3 * most).div_ceil(2).min(auto.max_intervals.max(most))
}

/// Knot intervals of an axis whose readings' positions determine `most` from the start (fewer
/// than `auto.start_intervals`: a laser tracer's stops along the edges): twice as many, up to
/// `auto.max_intervals`, the roughness prior interpolating between the positions.
///
/// Why twice, not [`beyond_positions`]' half as many again: between the positions the function
/// is the prior's interpolant, and the finer the knots, the nearer it comes to the smoothing
/// spline's (the interpolant `int f'''^2` itself chooses); a coarser spline bends between the
/// positions only as its own pieces let it. Where the readings' noise is small against the
/// errors, that, not the noise, is the map's error between the stops. Measured on the
/// independent simulator's tracer (11 stops per edge: 8 intervals determined; map error
/// against its Bayes oracle's, 12 -> 16 intervals): ten times the usual errors 1.83 -> 1.23
/// (seeds 701-710); thirty times, rigid carriages, 3.15 -> 1.56 (821-830); the usual errors
/// 1.09 -> 1.09 (101-106; stop 69's probe: 1.11 -> 1.10 on 201-220). Neither Akaike's criterion
/// (the two differ by -1.5 to +1.6, stop 72) nor the readings left out one position at a time
/// (the squared prediction error at the left-out stops, summed over the axes, is 4 to 13 %
/// larger with 16 intervals, seeds 701-705 at ten times) can tell the two apart: both pass
/// through the stops, and what differs lies between them, where no reading is. The finer
/// interpolant predicts a left-out stop less sharply, so the check of the interpolation is also
/// made on the coarser one ([`stiffer_checks`]). Not more than twice: with 20 or 24 intervals
/// for 11 stops the solve no longer held (stop 69).
pub fn between_positions(most: usize, auto: &Auto) -> usize {
    (2 * most).min(auto.max_intervals.max(most))
}

/// The intervals an axis at `intervals` goes to when that is all its positions determine
/// (`most`) and the limit is not reached: [`between_positions`]. `None` otherwise.
fn widened(intervals: usize, most: usize, auto: &Auto) -> Option<usize> {
    (intervals == most && most < auto.max_intervals).then(|| between_positions(most, auto))
}

/// [`auto_layout`] for the knot bounds `bound` of [`positions_bound`].
fn auto_layout_within(
    topology: Topology,
    travel: Travel,
    bound: &[(usize, usize); 3],
    auto: &Auto,
    overrides: &[Option<Representation>; 18],
) -> (ModelLayout, [AxisKnots; 3]) {
    let knots = Axis::ALL.map(|axis| {
        let (most, n) = bound[axis.index()];
        let intervals = most.min(auto.start_intervals.max(1));
        let (intervals, bound) = match widened(intervals, most, auto) {
            _ if !smoothable(n) => (few_positions_intervals(n), KnotBound::FewPositions),
            Some(to) => (to, KnotBound::Positions),
            None => (intervals, KnotBound::Data),
        };
        AxisKnots { axis, positions: n, intervals, determined: most, bound, tests: Vec::new(), table: None }
    });
    let layout = layout_with(&topology, travel, knots.clone().map(|k| k.intervals), overrides);
    (layout, knots)
}

/// A solve with `representation: auto` and what it chose.
pub struct AutoSolve {
    pub solution: Solution,
    pub knots: [AxisKnots; 3],
    /// The interpolation checks of the axes the readings resolve only at their positions
    /// ([`crate::interpolation`]; judged on the coarser interpolant where an axis was widened
    /// from the start, `stiffer_checks`); a contradicted one is also among the solution's
    /// warnings.
    pub interpolation: Vec<InterpolationCheck>,
}

/// Most rounds of knot refinement (each one fit): two doublings from the start and a retest of
/// axes whose test another axis's unresolved detail had masked.
const REFINE_ROUNDS: usize = 3;
/// Significance below which finer knots are taken: beyond what noise gives in a thousand
/// campaigns. A refinement that only fits noise costs little, since the roughness penalty
/// shrinks what the readings do not support, while one that is missed leaves detail the coarse
/// knots cannot follow in the map and out of its uncertainty. It was 1e-6 (beyond what noise
/// gives in a million campaigns). Measured on issue 12's table (seeds 1-20 / 1001-1020): over a
/// local bump, where tests between 1e-6 and 1e-3 are common, sparse FXYZ beams went from 1.11 /
/// 1.07 to 1.07 / 0.98 times the oracle's map error (actual / predicted 1.06 / 1.19 -> 0.99 /
/// 1.05), sparse FYXZ beams from 1.26 / 0.97 to 1.19 / 0.91 (1.06 / 0.84 -> 1.01 / 0.81), dense
/// beams from 1.76 / 1.63 and 1.77 / 1.61 to 1.74 / 1.62 and 1.70 / 1.59; the polynomial truths'
/// rows are unchanged to the digit, the paper's tables move by 0.04 or less in actual /
/// predicted. The benchmarks' campaigns test at p 0.25 to 0.96 and do not refine at either.
pub const REFINE_P: f64 = 1e-3;

/// Solves `obs` with `representation: auto`: starting from [`auto_layout`], the smoothing by
/// REML; then, per axis whose knots are not yet at their bound, a score test of the doubled
/// knots against that fit (the finer B-spline's extra detail as an extension of the model,
/// [`crate::estimator::Fit::score`]); axes where the readings ask for finer detail (p < [`REFINE_P`]) are refined
/// and the campaign solved again, REML starting from the smoothing found. An axis whose test
/// failed is tested again after another axis was refined: the detail the coarse knots of one
/// axis could not fit inflates the residual against which every axis is tested, and part of it
/// aliases onto the others. An axis refined up to what its positions determine then goes half
/// as far again (`widen_at_bound`). `opts` carries the gauge, noise and the rest; its
/// smoothing is replaced.
///
/// Where the readings show kinks at equally spaced nodes, an axis's functions become linear
/// tables instead (`choose_tables`).
///
/// Axes left bounded by their positions then have their interpolation checked against the
/// readings (`check_interpolation`): the variance of a prediction between the positions is
/// scaled up by what leaving each position out showed ([`AxisResolution::with_interpolation_scale`]),
/// and where the readings contradict the interpolation, the solution's resolution of that axis
/// says so ([`AxisResolution::contradicted`]): predictions between its positions are then not
/// determined, and a warning says what to measure.
pub fn solve_auto(
    topology: &Topology,
    travel: Travel,
    obs: &Observations,
    opts: &SolveOptions,
    auto: &Auto,
    overrides: &[Option<Representation>; 18],
) -> Result<AutoSolve, SolveError> {
    let cx = Context { topology, travel, obs, opts, auto, overrides };
    let mut out = choose_knots(&cx)?;
    out = choose_tables(out, &cx);
    let layout = out.solution.model.layout.clone();
    let held = held_fit(&layout, &out.solution, &cx);
    // Every position with readings is left out in turn, those that only touch the functions as
    // well: where they are not measured, the interpolation is what predicts them.
    let own = held.as_ref().map(|f| check_axes_on(f, &out.solution, &cx)).unwrap_or_default();
    let stiffer = stiffer_checks(&out, &cx);
    if let Some(f) = &held {
        let bounded = bounded_axes(&out.solution);
        let split = interpolation::measured_positions(f, &layout, obs, &bounded);
        let axes: Vec<Axis> = bounded.iter().map(|&(a, ..)| a).collect();
        for (a, kinds) in axes.into_iter().zip(split) {
            let r = &mut out.solution.resolution[a.index()];
            *r = std::mem::take(r).measured_at(kinds.measured, kinds.touched);
        }
    }
    // Between the positions of a checked axis the interpolation's variance is what leaving
    // each position out showed, where that is more than the fit states; where the readings
    // contradict the interpolation the map there is not determined by the data: the
    // interpolation is what the readings refute, and its uncertainty with it. Whether they
    // contradict it is judged on the coarser interpolant where the axis has one
    // (`stiffer_checks`).
    let scale = interpolation::variance_scale(&own).max(1.0);
    out.interpolation = own
        .into_iter()
        .map(|c| InterpolationCheck {
            judged_on: stiffer.iter().find(|s| s.axis == c.axis).cloned().map(Box::new),
            ..c
        })
        .collect();
    for c in &out.interpolation {
        let r = &mut out.solution.resolution[c.axis.index()];
        *r = std::mem::take(r).with_interpolation_scale(scale);
        if c.contradicted() {
            *r = std::mem::take(r).contradicted();
            out.solution.warnings.push(c.statement());
        }
    }
    Ok(out)
}

/// The interpolation checks on the coarser interpolant of the axes widened from the start to
/// [`between_positions`]: the same axes at [`beyond_positions`], with `chosen`'s smoothing
/// (the roughness penalty does not depend on the knots, so neither do its parameters). Empty
/// when no axis was so widened.
///
/// Why a second check: the finer knots interpolate a smooth error better between the positions,
/// but leaving a position out they predict it less sharply, and a feature shorter than the step
/// then escapes the check. Over the suite's local bump with the sparse tracer (seeds
/// 10001-10100, stop 69) 16 intervals alone missed it in 6 campaigns where 12 missed 3, and the
/// error components beyond 3 sigma between the stops rose from 1.9 to 2.4 %. The coarser
/// interpolant is the sharper test of whether the errors are smooth at the step, and what it
/// finds holds for any interpolant: the readings then do not determine the error between the
/// positions. With the finer fit's smoothing held it is sharper still than 12 intervals with
/// their own (stop 73, the same seeds, 12 intervals -> 16 checked on 12): the map between the
/// stops not determined at 42 636 -> 51 018 of 69 300 grid points, where it is given 1.76 ->
/// 1.53 times the oracle's error, actual / predicted 1.071 -> 1.081, 1.92 -> 2.04 % of the
/// components beyond 3 sigma between the stops, the whole map within its band in 72 -> 79 of
/// 100; over the polynomials one campaign of 100 contradicted with either, over the paper's
/// tables the same points not determined (864 of 38 400).
fn stiffer_checks(chosen: &AutoSolve, cx: &Context<'_>) -> Vec<InterpolationCheck> {
    let intervals = chosen.knots.each_ref().map(|k| k.intervals);
    let coarser = chosen.knots.each_ref().map(|k| {
        let to = beyond_positions(k.determined, cx.auto);
        let widened = k.bound == KnotBound::Positions && k.table.is_none() && k.determined > 0 && k.intervals > to;
        if widened {
            to
        } else {
            k.intervals
        }
    });
    if coarser == intervals {
        return Vec::new();
    }
    let layout = layout_with(cx.topology, cx.travel, coarser, cx.overrides);
    check_interpolation(&layout, &chosen.solution, cx)
}

/// The leave-one-position-out check ([`crate::interpolation::check_axes`]) of every axis that
/// `chosen`'s resolution bounds by its positions, on a fit of `layout` (`chosen`'s own, or a
/// coarser one: `stiffer_checks`) with `chosen`'s smoothing held (the fit keeps the factorised
/// normal equations the check needs; the solution is `chosen`'s).
fn check_interpolation(layout: &ModelLayout, chosen: &Solution, cx: &Context<'_>) -> Vec<InterpolationCheck> {
    held_fit(layout, chosen, cx).map(|f| check_axes_on(&f, chosen, cx)).unwrap_or_default()
}

/// The axes that `chosen`'s resolution bounds by its positions, with those positions and their
/// tolerance.
fn bounded_axes(chosen: &Solution) -> Vec<(Axis, &[f64], f64)> {
    Axis::ALL
        .iter()
        .filter_map(|&a| match &chosen.resolution[a.index()] {
            AxisResolution::AtPositions { positions, tolerance_m, .. } => Some((a, positions.as_slice(), *tolerance_m)),
            AxisResolution::Everywhere => None,
        })
        .collect()
}

/// A fit of `layout` with `chosen`'s smoothing held, which keeps the factorised normal equations
/// the checks need; `None` where no axis is bounded by its positions (nothing to check) or the
/// fit fails.
fn held_fit<'a>(layout: &'a ModelLayout, chosen: &Solution, cx: &Context<'a>) -> Option<Fit<'a>> {
    if bounded_axes(chosen).is_empty() {
        return None;
    }
    let smoothing = chosen.smoothing.as_ref().map(Smoothing::fixed_from);
    let o = SolveOptions { smoothing: smoothing.or_else(|| cx.opts.smoothing.clone()), ..cx.opts.clone() };
    fit(layout, cx.obs, &o, &[]).ok()
}

/// [`interpolation::check_axes`] of `chosen`'s bounded axes on `f`.
fn check_axes_on(f: &Fit<'_>, chosen: &Solution, cx: &Context<'_>) -> Vec<InterpolationCheck> {
    interpolation::check_axes(f, cx.obs, &bounded_axes(chosen))
}

/// The knots and the solution on them ([`solve_auto`] without the interpolation checks).
fn choose_knots(cx: &Context<'_>) -> Result<AutoSolve, SolveError> {
    let &Context { topology, travel, obs, opts, auto, overrides } = cx;
    let positions = crate::identify::DataSummary::positions_of(&obs.x);
    let bound = positions_bound(&travel, &positions, auto.max_intervals);
    let (_, mut knots) = auto_layout_within(topology.clone(), travel, &bound, auto, overrides);
    let mut smoothing = smoothing_for(overrides, &knots);
    // The previous round's solution, knots, layout and directions left open: a refinement that
    // neither the readings' geometry nor the prior determines is undone.
    let mut previous: Option<(Solution, [AxisKnots; 3], ModelLayout, usize)> = None;
    for round in 0..=REFINE_ROUNDS {
        let layout = layout_with(topology, travel, knots.clone().map(|k| k.intervals), overrides);
        let o = SolveOptions { smoothing: Some(smoothing.clone()), ..opts.clone() };
        let f = fit(&layout, obs, &o, &[])?;
        let open = left_open(f.solution(), &layout);
        if let Some((sol, mut kept, kept_layout, before)) = previous.take() {
            if open > before {
                for k in kept.iter_mut() {
                    if let Some(t) = k.tests.last_mut().filter(|t| t.refined) {
                        t.refined = false;
                        t.determined = false;
                    }
                }
                let (sol, kept) = widen_at_bound(sol, kept, &kept_layout, &bound, cx);
                return Ok(finish(sol, kept, &bound, auto, &positions, travel));
            }
        }
        let mut refined = false;
        if round < REFINE_ROUNDS {
            // The axes that may still be refined, tested together in one pass over the readings.
            let mut parts: Vec<(Axis, usize, Refinement)> = Vec::new();
            for a in Axis::ALL {
                let k = &knots[a.index()];
                let most = bound[a.index()].0;
                let functions = auto_functions(a, overrides);
                // An axis whose finer knots the readings and the prior did not determine is not tried again.
                if k.intervals >= most
                    || k.bound == KnotBound::FewPositions
                    || functions.is_empty()
                    || k.tests.last().is_some_and(|t| !t.determined)
                {
                    continue;
                }
                let to = (2 * k.intervals).min(most);
                let [lo, hi] = travel.range(a);
                let basis = Basis::new(Representation::BSpline { intervals: to }, lo, hi);
                parts.push((a, to, Refinement { topology: topology.clone(), axis: a, basis, functions }));
            }
            let ext = Refinements::new(parts.iter().map(|(_, _, r)| r).collect());
            let scores = f.score_parts(&ext, None, &ext.ranges);
            for ((a, to, _), sc) in parts.iter().zip(scores) {
                let k = &mut knots[a.index()];
                let p = refinement_p(sc.delta_chi2, sc.rank, &f.solution().stats);
                let take = p < REFINE_P;
                k.tests.push(RefinementTest {
                    from: k.intervals,
                    to: *to,
                    delta_chi2: sc.delta_chi2,
                    dof: sc.rank,
                    p_value: p,
                    refined: take,
                    determined: true,
                });
                if take {
                    k.intervals = *to;
                    refined = true;
                }
            }
        }
        if !refined {
            let (sol, knots) = widen_at_bound(f.into_solution(), knots, &layout, &bound, cx);
            return Ok(finish(sol, knots, &bound, auto, &positions, travel));
        }
        if let Some(r) = &f.solution().smoothing {
            smoothing = smoothing.continued_from(r);
        }
        // The knots before this round's refinements, with its tests recorded.
        let mut kept = knots.clone();
        for k in kept.iter_mut() {
            if let Some(from) = k.tests.last().filter(|t| t.refined).map(|t| t.from) {
                k.intervals = from;
            }
        }
        previous = Some((f.into_solution(), kept, layout, open));
    }
    unreachable!("the last round never refines")
}

/// Intervals of the linear tables tried per axis (`choose_tables`), equally spaced over the
/// travel: from two (one kink in the middle) to sixteen, beyond which the cubic B-splines'
/// refinement (up to [`Auto::max_intervals`]) follows kinks about as well.
pub const TABLE_INTERVALS: [usize; 2] = [2, 16];

/// Tables are tried only where the readings show detail the starting knots miss: some axis's
/// first refinement test below this level. A kink is such detail; where the readings do not
/// show it even at 10 %, the tables cannot win the comparison either, and the campaign is
/// spared their fits (the benchmarks' campaigns test at p 0.25 to 0.96).
pub const TABLE_GATE_P: f64 = 0.1;

/// Linear tables instead of the cubic smoothing, per axis, where the readings say so.
///
/// A machine compensated by linear tables, or an error stated as one (the patent's tables,
/// the paper's), has kinks at equally spaced nodes. A cubic spline rounds them off whatever its
/// smoothing, and that bias is not in its uncertainty: with the paper's tables the map error
/// was under-stated by 15 % with dense beams, and the whole map lay within its 95 % band in 19
/// of 100 sparse joint campaigns (docs/representation-auto.md).
///
/// Per axis, each table of [`TABLE_INTERVALS`] whose every interval holds a reading strictly
/// inside (so that the readings test the line between the nodes; at a tracer's stops alone a
/// table would only join them) is fitted unpenalised, the other axes' functions held at the
/// smoothing found; the best is taken where its Akaike criterion (chi-square over the noise
/// scale plus twice the effective parameters) is lower than the smoothing's. The chosen axes'
/// tables are then fitted together with their kinks penalised (the slopes' jumps, [`Basis::kink_rows`]),
/// every smoothing parameter by REML, and the result kept only if its criterion is lower still
/// and it leaves no more directions open. The unpenalised screening decides which axes and
/// spacings, since a penalised table would shrink kinks at the wrong nodes too and win the
/// comparison with sparse readings; the penalised fit is what is reported, since it shrinks
/// what the readings say little about, as the smoothing does.
///
/// Akaike's criterion, not Schwarz's (BIC, `ln n` per parameter; an experiment, not kept): BIC
/// prefers tables too coarse to hold the readings, whose few parameters state a small
/// uncertainty. With sparse beams it took X tables in 4 of 20 campaigns, maps 14 to 17 um from
/// the truth under a predicted 6.3 um (largest |z| 10.5), and with dense beams one axis instead
/// of three (map error 1.12 -> 1.37 um; seeds 1-20, docs/representation-auto.md).
fn choose_tables(chosen: AutoSolve, cx: &Context<'_>) -> AutoSolve {
    let Some(report) = chosen.solution.smoothing.clone().filter(|_| cx.auto.tables) else { return chosen };
    let gate = chosen.knots.iter().filter_map(|k| k.tests.first()).map(|t| t.p_value).fold(1.0, f64::min);
    if gate >= TABLE_GATE_P {
        return chosen;
    }
    let intervals = chosen.knots.clone().map(|k| k.intervals);
    let phi = report.noise_scale.max(1.0);
    let aic = |s: &Solution| s.stats.chi2 / phi + 2.0 * (s.stats.n_obs - s.stats.dof) as f64;
    let base_open = left_open(&chosen.solution, &chosen.solution.model.layout);
    let base_aic = aic(&chosen.solution);
    let positions = crate::identify::DataSummary::positions_of(&cx.obs.x);
    let mut reprs = *cx.overrides;
    let mut screened: [Option<(usize, f64)>; 3] = [None; 3];
    for a in Axis::ALL {
        let functions: Vec<usize> = auto_functions(a, cx.overrides).iter().map(|f| f.index()).collect();
        if functions.is_empty() || chosen.knots[a.index()].bound == KnotBound::FewPositions {
            continue;
        }
        // The other axes' smoothing held, this axis's functions unpenalised.
        let mut held = Smoothing::fixed_from(&report);
        functions.iter().for_each(|&i| held.penalised[i] = false);
        let [lo, hi] = cx.travel.range(a);
        let inside = inside_travel(&cx.travel, a, &positions);
        let mut best: Option<(f64, usize)> = None;
        for n in TABLE_INTERVALS[0]..=TABLE_INTERVALS[1] {
            if !table_tested(lo, hi, n, &inside) {
                continue;
            }
            let mut o = *cx.overrides;
            functions.iter().for_each(|&i| o[i] = Some(Representation::Table { nodes: n + 1 }));
            let layout = layout_with(cx.topology, cx.travel, intervals, &o);
            let opts = SolveOptions { smoothing: Some(held.clone()), ..cx.opts.clone() };
            let Ok(f) = fit(&layout, cx.obs, &opts, &[]) else { continue };
            if left_open(f.solution(), &layout) > base_open {
                continue;
            }
            let v = aic(f.solution());
            if best.is_none_or(|(b, _)| v < b) {
                best = Some((v, n));
            }
        }
        if let Some((v, n)) = best.filter(|&(v, _)| v < base_aic) {
            functions.iter().for_each(|&i| reprs[i] = Some(Representation::Table { nodes: n + 1 }));
            screened[a.index()] = Some((n, base_aic - v));
        }
    }
    if screened.iter().all(Option::is_none) {
        return chosen;
    }
    let layout = layout_with(cx.topology, cx.travel, intervals, &reprs);
    let smoothing = smoothing_for(cx.overrides, &chosen.knots).continued_from(&report);
    let opts = SolveOptions { smoothing: Some(smoothing), ..cx.opts.clone() };
    let Ok(f) = fit(&layout, cx.obs, &opts, &[]) else { return chosen };
    let final_gain = base_aic - aic(f.solution());
    if final_gain <= 0.0 || left_open(f.solution(), &layout) > base_open {
        return chosen;
    }
    let mut solution = f.into_solution();
    // What the knots' bounds said of the axes (resolved only at the readings' positions) holds
    // of the tables too: between the positions they interpolate.
    solution.resolution = chosen.solution.resolution.clone();
    let mut knots = chosen.knots;
    for (k, s) in knots.iter_mut().zip(screened) {
        k.table = s.map(|(intervals, aic_gain)| TableChoice { intervals, aic_gain, final_gain });
    }
    AutoSolve { solution, knots, interpolation: chosen.interpolation }
}

/// Whether every one of the `n` equal intervals of `[lo, hi]` holds a position strictly inside
/// (a twentieth of the interval away from its nodes): readings that test a table's line there.
fn table_tested(lo: f64, hi: f64, n: usize, positions: &[f64]) -> bool {
    let h = (hi - lo) / n as f64;
    (0..n).all(|k| {
        let (a, b) = (lo + k as f64 * h + 0.05 * h, lo + (k + 1) as f64 * h - 0.05 * h);
        positions.iter().any(|&q| q > a && q < b)
    })
}

/// What every fit of [`solve_auto`] shares.
struct Context<'a> {
    topology: &'a Topology,
    travel: Travel,
    obs: &'a Observations,
    opts: &'a SolveOptions,
    auto: &'a Auto,
    overrides: &'a [Option<Representation>; 18],
}

/// Axes whose positions could not test their doubled knots ([`interpolated_between`]: refined up
/// to the positions' bound, or short of it by less than half) go half as far again beyond what
/// the positions determine ([`beyond_positions`]), the roughness prior determining the rest, as
/// axes bounded from the start do: one more fit, smoothing starting from `sol`'s, kept unless it
/// fails or leaves more directions undetermined (by the readings and the prior together) than
/// `sol` on its `layout`. Where that fit is not kept and an axis stopped short of its bound, half
/// as far again beyond its own knots is tried, where that is still beyond the bound. The
/// refinement test itself is of the knots the positions determine: detail the readings resolve.
///
/// Where neither is kept, the axes are widened one at a time, each kept where its fit is: one
/// axis's widening that the solve does not hold must not keep the others at knots that leave them
/// no freedom between their positions. Seen on the independent simulator with a narrow bump on
/// every function (`--bump 0.5,0.02,0.05`, the 45 beams and the tracer in one campaign, seeds
/// 1051-1060): Y at its bound (32 intervals for 35 positions) and X, Z refined to 24 short of it;
/// every joint widening took Y to 48, and the penalised normal matrix lost definiteness. X and Z
/// then stayed at 24, resolved "everywhere", and their axis lines lay up to 7.8 standard
/// uncertainties off between the beams' points (docs/representation-auto.md, "Widened one axis at
/// a time").
fn widen_at_bound(
    sol: Solution,
    knots: [AxisKnots; 3],
    layout: &ModelLayout,
    bound: &[(usize, usize); 3],
    cx: &Context<'_>,
) -> (Solution, [AxisKnots; 3]) {
    let before = left_open(&sol, layout);
    let mut tried: Vec<[usize; 3]> = vec![knots.each_ref().map(|k| k.intervals)];
    // The fit on `intervals` where it holds and leaves no more open than `sol`.
    let mut held = |intervals: [usize; 3]| -> Option<Solution> {
        if tried.contains(&intervals) {
            return None;
        }
        tried.push(intervals);
        let mut smoothing = smoothing_for(cx.overrides, &knots);
        if let Some(r) = &sol.smoothing {
            smoothing = smoothing.continued_from(r);
        }
        let wide_layout = layout_with(cx.topology, cx.travel, intervals, cx.overrides);
        let o = SolveOptions { smoothing: Some(smoothing), ..cx.opts.clone() };
        let f = fit(&wide_layout, cx.obs, &o, &[]).ok()?;
        (left_open(f.solution(), &wide_layout) <= before).then(|| f.into_solution())
    };
    // Where axis `a` goes: half as far again beyond its bound or beyond its own knots.
    let widened = |a: usize, from_own_knots: bool| -> Option<usize> {
        let (k, most) = (&knots[a], bound[a].0);
        let to = beyond_positions(if from_own_knots { k.intervals } else { most }, cx.auto);
        (interpolated_between(k, most, cx.auto) && to > most).then_some(to)
    };
    for from_own_knots in [false, true] {
        let mut wide = knots.clone();
        for (a, k) in wide.iter_mut().enumerate() {
            if let Some(to) = widened(a, from_own_knots) {
                k.intervals = to;
            }
        }
        if let Some(s) = held(wide.each_ref().map(|k| k.intervals)) {
            return (s, wide);
        }
    }
    let (mut kept, mut kept_knots) = (None, knots.clone());
    for a in 0..3 {
        for from_own_knots in [false, true] {
            let Some(to) = widened(a, from_own_knots) else { continue };
            let mut wide = kept_knots.clone();
            wide[a].intervals = to;
            if let Some(s) = held(wide.each_ref().map(|k| k.intervals)) {
                (kept, kept_knots) = (Some(s), wide);
                break;
            }
        }
    }
    match kept {
        Some(s) => (s, kept_knots),
        None => (sol, knots),
    }
}

/// Whether the functions of an axis with knots `k`, whose readings' positions determine `most`
/// intervals ([`positions_bound`]), are interpolated between the positions: at that bound, or
/// short of it where the readings asked
/// for finer knots (a refinement test passed: the errors have detail at the knot spacing), and
/// the positions could not test the doubled knots (`2 intervals > most`), so the test saw at most
/// part of the detail at half the spacing, and a cubic B-spline with nearly as many coefficients
/// as positions has little freedom left between them, nor uncertainty there. Seen on the
/// independent simulator (length scales 0.06 to 0.15 of the travel, the 45 beams and the tracer
/// in one campaign, seed 717): along Y the beams' 25 points per line sit on the knots of the 24
/// intervals the refinement took, and the tracer's stops raise what the positions determine to
/// 32; the test of 32 intervals found nothing (p 0.61), and between the beams' points the map was
/// up to 0.30 um off under a stated 0.045 um (|z| 7.2). Half as far again beyond the knots (36
/// intervals; 48, beyond the positions' 32, left directions open), it is 0.105 um RMS off under
/// 0.177 um (largest |z| 2.6). Not where the readings never asked for finer knots: there the
/// errors are smooth at the knot spacing, and interpolating between the positions of an axis so
/// resolved over-stated the dense tracer over the paper's tables (21 stops, 12 intervals; actual /
/// predicted 0.946 -> 0.756, seeds 1-20). Nor where the positions reach the limit of the knots
/// (`auto.max_intervals`), or the knots are already beyond the positions (a tracer's 11 stops,
/// widened from the start: more knots there and the solve no longer holds, [`beyond_positions`]).
fn interpolated_between(k: &AxisKnots, most: usize, auto: &Auto) -> bool {
    if k.bound == KnotBound::FewPositions {
        return false;
    }
    let refined = k.tests.iter().any(|t| t.refined);
    let short_of_bound = refined && k.intervals < most && 2 * k.intervals > most;
    (k.intervals == most || short_of_bound) && most < auto.max_intervals
}

/// The knots' bounds and the solution's resolution of the chosen layout.
fn finish(
    mut solution: Solution,
    mut knots: [AxisKnots; 3],
    bound: &[(usize, usize); 3],
    auto: &Auto,
    positions: &[Vec<f64>; 3],
    travel: Travel,
) -> AutoSolve {
    for (a, k) in knots.iter_mut().enumerate() {
        if k.bound == KnotBound::FewPositions {
            continue;
        }
        k.bound = if k.intervals >= auto.max_intervals {
            KnotBound::Limit
        } else if k.intervals >= bound[a].0 {
            KnotBound::Positions
        } else {
            KnotBound::Data
        };
        if k.bound == KnotBound::Positions {
            solution.resolution[a] = AxisResolution::at(inside_travel(&travel, k.axis, positions));
        }
    }
    AutoSolve { solution, knots, interpolation: Vec::new() }
}

/// Directions of the functions the readings do not observe at all (beyond each one's gauge
/// constant).
fn unobserved_dim(sol: &Solution, layout: &ModelLayout) -> usize {
    sol.identifiability
        .not_observed
        .iter()
        .filter_map(|name| ErrorFunction::parse(name))
        .map(|f| layout.basis(f).n_coeffs().saturating_sub(1))
        .sum()
}

/// Directions that neither the readings nor the roughness prior determine, beyond those of
/// functions the readings do not observe at all (whose count grows with the knots whatever the
/// readings): what a refinement must not increase.
///
/// Not the directions the readings alone leave open: a refinement the readings ask for (p
/// below [`REFINE_P`]) whose finer detail their geometry does not pin down everywhere is
/// interpolated by the prior there, as between a tracer's stops ([`beyond_positions`]). Undoing
/// it, as the readings-alone count did, left a bump the lines show but cannot fully resolve to
/// the noise scale. Measured (`auto_study`, bump truths, seeds 1-20 and held-out 1001-1020):
/// sparse FXYZ beams 1.91 and 1.81 times the oracle's map error became 1.19 and 1.03, sparse
/// FYXZ 1.60 and 1.84 became 1.36 and 0.97, the sparse joint campaign 2.62 and 2.90 became 1.37
/// and 1.41; actual / predicted moved from 0.92 / 1.00, 0.90 / 0.96 and 1.23 / 1.28 to
/// 1.28 / 1.13, 1.26 / 0.94 and 1.08 / 1.07. Every other case of the study was unchanged.
fn left_open(sol: &Solution, layout: &ModelLayout) -> usize {
    sol.undetermined.ncols().saturating_sub(unobserved_dim(sol, layout))
}

/// p-value of a refinement whose score is `delta_chi2` on `dof` degrees of freedom: the F-test of
/// the reduction per degree of freedom against the residual variance per degree of freedom of
/// the refined fit (so that an instrument noise stated too large or too small neither hides nor
/// invents detail). The refined fit's residual, not the coarse one's: the coarse residual holds
/// the very detail under test, and a bump the coarse knots cannot follow would inflate the
/// yardstick it is measured with (the extra-sum-of-squares F-test).
fn refinement_p(delta_chi2: f64, dof: usize, stats: &crate::estimator::ResidualStats) -> f64 {
    use statrs::distribution::{ContinuousCDF, FisherSnedecor};
    let rest = stats.chi2 - delta_chi2;
    if dof == 0 || stats.dof <= dof || delta_chi2 <= 0.0 {
        return 1.0;
    }
    if rest <= 0.0 {
        return 0.0;
    }
    let f = (delta_chi2 / dof as f64) / (rest / (stats.dof - dof) as f64);
    if !f.is_finite() {
        return 0.0;
    }
    FisherSnedecor::new(dof as f64, (stats.dof - dof) as f64).map(|d| d.sf(f)).unwrap_or(1.0)
}

/// The detail of a finer B-spline on one axis, as an extension of a fitted model: for each of
/// the axis's smoothed functions, the regressors of every other basis function of the finer
/// B-spline (with the coarse one they span the finer space; the score test's Schur complement
/// removes what they share with the model).
struct Refinement {
    topology: Topology,
    axis: Axis,
    basis: Basis,
    functions: Vec<ErrorFunction>,
}

impl Refinement {
    fn n_params(&self) -> usize {
        self.functions.len() * (self.basis.n_coeffs() / 2)
    }
}

/// Several axes' [`Refinement`]s as one extension, their parameters side by side (`ranges`:
/// the columns of each).
struct Refinements<'a> {
    parts: Vec<&'a Refinement>,
    ranges: Vec<std::ops::Range<usize>>,
}

impl<'a> Refinements<'a> {
    fn new(parts: Vec<&'a Refinement>) -> Refinements<'a> {
        let mut start = 0;
        let ranges = parts
            .iter()
            .map(|r| {
                let range = start..start + r.n_params();
                start = range.end;
                range
            })
            .collect();
        Refinements { parts, ranges }
    }
}

impl Effect for Refinements<'_> {
    fn id(&self) -> &str {
        "refinements"
    }

    fn param_names(&self) -> Vec<String> {
        self.parts.iter().flat_map(|r| r.param_names()).collect()
    }

    fn regressors(&self, ctx: &ObsContext<'_>, out: &mut [f64]) {
        for (r, range) in self.parts.iter().zip(&self.ranges) {
            r.regressors(ctx, &mut out[range.clone()]);
        }
    }

    fn sparse_regressors(&self, ctx: &ObsContext<'_>, _: &mut [f64], idx: &mut Vec<usize>, val: &mut Vec<f64>) {
        idx.clear();
        val.clear();
        for (r, range) in self.parts.iter().zip(&self.ranges) {
            r.visit(ctx, |j, v| {
                idx.push(range.start + j);
                val.push(v);
            });
        }
    }
}

impl Effect for Refinement {
    fn id(&self) -> &str {
        "refinement"
    }

    fn param_names(&self) -> Vec<String> {
        let n = self.basis.n_coeffs() / 2;
        self.functions.iter().flat_map(|f| (0..n).map(move |j| format!("{}_{}", f.name(), 2 * j + 1))).collect()
    }

    fn regressors(&self, ctx: &ObsContext<'_>, out: &mut [f64]) {
        self.visit(ctx, |j, v| out[j] = v);
    }
}

impl Refinement {
    /// The nonzero regressors of one reading, in increasing column order.
    fn visit(&self, ctx: &ObsContext<'_>, mut put: impl FnMut(usize, f64)) {
        let (x, p) = (ctx.obs.x[ctx.i], ctx.obs.p[ctx.i]);
        let n = self.basis.n_coeffs() / 2;
        let h = self.topology.lever_arm(self.axis, &x, &p);
        let mut odd = [(0usize, 0.0f64); 4];
        let mut m = 0;
        self.basis.visit(self.axis.coord(&x), false, |j, b| {
            if j % 2 == 1 && j / 2 < n {
                odd[m] = (j / 2, b);
                m += 1;
            }
        });
        for (k, f) in self.functions.iter().enumerate() {
            let d = ctx.direction.dot(&f.unit_response(&h));
            for &(j, b) in &odd[..m] {
                put(k * n + j, d * b);
            }
        }
    }
}

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

    #[test]
    fn a_table_is_tested_only_where_every_interval_holds_a_reading_inside() {
        // A tracer's 11 stops over the travel: tables of 10 intervals would only join them.
        let stops: Vec<f64> = (0..=10).map(|i| 0.07 * i as f64).collect();
        assert!(!table_tested(0.0, 0.7, 10, &stops));
        assert!(table_tested(0.0, 0.7, 9, &stops));
        assert!(table_tested(0.0, 0.7, 5, &stops));
        // Dense readings test every spacing up to theirs.
        let dense: Vec<f64> = (0..=70).map(|i| 0.01 * i as f64).collect();
        assert!((2..=16).all(|n| table_tested(0.0, 0.7, n, &dense)));
        assert!(!table_tested(0.0, 0.7, 4, &[0.1, 0.3, 0.5]));
    }
    use crate::model::ModelLayout;
    use crate::topology::Topology;
    use crate::Travel;

    #[test]
    fn auto_knots_are_bounded_by_the_positions_the_readings_occupy() {
        let travel = Travel::new([0.0, 0.7], [-0.5, 0.0], [-0.7, 0.0]);
        let even = |lo: f64, hi: f64, n: usize| -> Vec<f64> {
            (0..n).map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64).collect()
        };
        // The paper's tracer steps: 11 positions per axis determine 8 intervals (11
        // coefficients); twice as many, the prior determining 8 coefficients per function.
        let positions = [even(0.0, 0.7, 11), even(-0.5, 0.0, 11), even(-0.7, 0.0, 11)];
        let topo = Topology::parse("FYXZ").unwrap();
        let (layout, knots, smoothing) = auto_layout(topo.clone(), travel, &positions, &Auto::default(), &[None; 18]);
        assert!(
            knots.iter().all(|k| (k.determined, k.intervals, k.bound) == (8, 16, KnotBound::Positions)),
            "{knots:?}"
        );
        assert_eq!(layout.n_params, 18 * 19 + 3);
        assert!(
            knots[0].describe().contains("the 11 positions along the axis determine 8;"),
            "{}",
            knots[0].describe()
        );
        assert!(smoothing.penalised.iter().all(|&p| p));
        // Dense positions: the starting knots, refined later only where the readings ask.
        let dense = [even(0.0, 0.7, 500), even(-0.5, 0.0, 400), even(-0.7, 0.0, 3)];
        let mut over = [None; 18];
        over[ErrorFunction::parse("EXX").unwrap().index()] = Some(Representation::Polynomial { degree: 3 });
        let (layout, knots, smoothing) = auto_layout(topo, travel, &dense, &Auto::default(), &over);
        assert_eq!((knots[0].intervals, knots[0].bound), (12, KnotBound::Data));
        // Three positions say nothing of the roughness (a parabola passes through them): one
        // interval, not smoothed, left open away from the positions.
        assert_eq!((knots[2].determined, knots[2].intervals, knots[2].bound), (1, 1, KnotBound::FewPositions));
        assert!(
            knots[2].describe().contains("not smoothed: the readings lie at 3 position(s)"),
            "{}",
            knots[2].describe()
        );
        assert!((12..18).all(|i| !smoothing.penalised[i]));
        assert!((6..12).all(|i| smoothing.penalised[i]));
        assert_eq!(layout.basis(ErrorFunction::parse("EXX").unwrap()).repr, Representation::Polynomial { degree: 3 });
        assert!(!smoothing.penalised[ErrorFunction::parse("EXX").unwrap().index()]);
        // A gap: positions only in the first half of X cannot carry knots in the second.
        let half = [even(0.0, 0.35, 200), even(-0.5, 0.0, 400), even(-0.7, 0.0, 400)];
        let (_, knots, _) = auto_layout(Topology::parse("FXYZ").unwrap(), travel, &half, &Auto::default(), &[None; 18]);
        assert_eq!(knots[0].determined, 1, "{knots:?}");
    }

    #[test]
    fn refinement_is_measured_against_the_refined_residual() {
        use statrs::distribution::{ContinuousCDF, FisherSnedecor};
        let stats = |chi2: f64, dof: usize| crate::estimator::ResidualStats {
            n_obs: dof + 300,
            rms_m: 0.0,
            chi2,
            dof,
            variance_factor: chi2 / dof as f64,
            per_group: Vec::new(),
        };
        // 400 residual degrees of freedom, noise at its stated level (chi2 400) plus detail
        // (chi2 1400 more) that the coarse knots cannot follow, of which the finer knots (78
        // more parameters) take up a chi2 of 550: against the coarse residual's variance (4.5
        // per dof, inflated by that very detail) the test would not refine at REFINE_P (p 3e-3
        // against 2e-4).
        let p = refinement_p(550.0, 78, &stats(1800.0, 400));
        let f = (550.0 / 78.0) / (1250.0 / 322.0);
        assert_eq!(p, FisherSnedecor::new(78.0, 322.0).unwrap().sf(f));
        assert!(p < REFINE_P, "{p}");
        let coarse = FisherSnedecor::new(78.0, 400.0).unwrap().sf((550.0 / 78.0) / 4.5);
        assert!(coarse > REFINE_P, "{coarse}");
        // Pure noise stays insignificant, and degenerate cases ask for nothing.
        assert!(refinement_p(78.0, 78, &stats(400.0, 400)) > 0.3);
        assert_eq!(refinement_p(10.0, 0, &stats(400.0, 400)), 1.0);
        assert_eq!(refinement_p(10.0, 400, &stats(400.0, 400)), 1.0);
        assert_eq!(refinement_p(0.0, 78, &stats(400.0, 400)), 1.0);
    }

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
