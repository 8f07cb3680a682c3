//! Predictions from an identified model: volumetric error with expanded uncertainty at any
//! point, dense maps, the largest error and where it occurs, and per-axis compensation tables.

use crate::axis::{Axis, Travel};
use crate::functions::ErrorFunction;
use crate::model::{ErrorModel, Sensitivity};
use faer::{Mat, MatRef};
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};

/// Coverage factor of the expanded uncertainties (k = 2, about 95 %).
pub const COVERAGE_K: f64 = 2.0;

/// Relative sensitivity to the undetermined directions above which a predicted quantity is
/// *not determined by the data* (see [`Uncertainty::share`]). A quantity the data determine sees
/// them at the rounding level of the eigen-decomposition that found them (below 1e-8); one that
/// depends on them sees them at order one.
pub const NOT_DETERMINED_ABOVE: f64 = 1e-4;

/// Where along an axis the readings resolve the error functions.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum AxisResolution {
    /// Everywhere over the travel (the readings' positions are at least as dense as the knots).
    #[default]
    Everywhere,
    /// At the measured positions only (the knots are as many as they determine): between two
    /// of them the functions are interpolated, and a feature shorter than their spacing is not
    /// resolved by the readings.
    AtPositions {
        /// Sorted, metres.
        positions: Vec<f64>,
        /// Positions with readings that touch the functions without measuring them
        /// ([`crate::interpolation::measured_positions`]), sorted, metres: between the measured
        /// positions like any coordinate, but where the readings contradict the interpolation
        /// they are still given a number (their readings speak there, [`AxisResolution::leaves_open`]).
        touched: Vec<f64>,
        /// For each of `touched`, the share of its least-pinned function's variance that its own
        /// readings remove ([`crate::interpolation::measured_positions`]): what they add to the
        /// interpolation there ([`with_own_readings`]); 0 (nothing) in files from before it.
        touched_share: Vec<f64>,
        /// How close to a position a coordinate counts as measured, metres.
        tolerance_m: f64,
        /// The readings contradict the interpolation between the positions
        /// ([`crate::interpolation`]): there the functions are not determined by the data,
        /// only at the positions themselves.
        contradicted: bool,
        /// How much larger the variance of the interpolation between the positions is than the
        /// fit states: the factor the leave-one-position-out checks show, pooled over the axes
        /// checked ([`crate::interpolation::variance_scale`]), where it is above 1, else 1
        /// (and 1 where the axis was not checked). The covariance of a prediction between the
        /// positions is scaled by it: the cross-validation estimate of the prior's variance,
        /// which stays right where the prior's shape is not the truth's (Bachoc 2013, *Cross
        /// validation and maximum likelihood estimations of hyper-parameters of Gaussian
        /// processes with model misspecification*), where REML's, a likelihood's, does not.
        /// Never below 1: a factor below one, from a few positions, is no evidence that the
        /// interpolation is better than the fit states, and a metrology tool does not narrow an
        /// uncertainty on it.
        interpolation_scale: f64,
    },
}

impl AxisResolution {
    /// The resolution of readings at `positions` (sorted, distinct): a coordinate within 1 %
    /// of the median spacing of a position counts as measured.
    pub fn at(positions: Vec<f64>) -> AxisResolution {
        let tolerance_m = median_spacing(&positions) * 0.01;
        AxisResolution::AtPositions {
            positions,
            touched: Vec::new(),
            touched_share: Vec::new(),
            tolerance_m,
            contradicted: false,
            interpolation_scale: 1.0,
        }
    }

    /// The same, with the interpolation's variance between the positions scaled by `scale`
    /// (what the leave-one-position-out checks show; a resolution everywhere interpolates nothing).
    pub fn with_interpolation_scale(mut self, scale: f64) -> AxisResolution {
        if let AxisResolution::AtPositions { interpolation_scale, .. } = &mut self {
            *interpolation_scale = scale;
        }
        self
    }

    /// The same, measured at `positions` only (sorted, a subset of the positions), the rest
    /// `touched` (sorted, each with the share its readings remove): their readings touch the
    /// functions without determining them ([`crate::interpolation::measured_positions`]), and
    /// there the functions are interpolated between the measured positions, what the readings
    /// add included ([`with_own_readings`]). The tolerance is the measured positions' own, as
    /// [`AxisResolution::at`] gives it.
    pub fn measured_at(mut self, measured: Vec<f64>, touched: Vec<(f64, f64)>) -> AxisResolution {
        if let AxisResolution::AtPositions { positions, touched: at, touched_share, tolerance_m, .. } = &mut self {
            *tolerance_m = median_spacing(&measured) * 0.01;
            *positions = measured;
            (*at, *touched_share) = touched.into_iter().unzip();
        }
        self
    }

    /// The scale of the variance of a prediction at coordinate `q`: the interpolation's
    /// between the positions, `None` at a position or where the axis is resolved everywhere.
    pub fn interpolation_scale_at(&self, q: f64) -> Option<f64> {
        match self {
            AxisResolution::AtPositions { interpolation_scale, .. } if self.interpolates(q) => {
                Some(*interpolation_scale)
            }
            _ => None,
        }
    }

    /// The same, with the readings contradicting the interpolation between the positions (a
    /// resolution everywhere has nothing interpolated to contradict and stays as it is).
    pub fn contradicted(mut self) -> AxisResolution {
        if let AxisResolution::AtPositions { contradicted, .. } = &mut self {
            *contradicted = true;
        }
        self
    }

    /// Whether coordinate `q` lies between measured positions (not at one).
    pub fn interpolates(&self, q: f64) -> bool {
        match self {
            AxisResolution::Everywhere => false,
            AxisResolution::AtPositions { positions, tolerance_m, .. } => !near_any(positions, q, *tolerance_m),
        }
    }

    /// The measured positions either side of coordinate `q` where it lies between two of them
    /// (not at one, nor beyond the first or the last).
    pub fn neighbours(&self, q: f64) -> Option<(f64, f64)> {
        match self {
            AxisResolution::AtPositions { positions, .. } if self.interpolates(q) => {
                let i = positions.partition_point(|&p| p < q);
                (i > 0 && i < positions.len()).then(|| (positions[i - 1], positions[i]))
            }
            _ => None,
        }
    }

    /// The share of a touched position at coordinate `q` (within the tolerance), `None`
    /// elsewhere.
    pub fn touched_share_at(&self, q: f64) -> Option<f64> {
        match self {
            AxisResolution::AtPositions { touched, touched_share, tolerance_m, .. } => {
                near(touched, q, *tolerance_m).map(|k| touched_share.get(k).copied().unwrap_or(0.0))
            }
            AxisResolution::Everywhere => None,
        }
    }

    /// Whether the readings contradict the interpolation between the positions.
    pub fn is_contradicted(&self) -> bool {
        matches!(self, AxisResolution::AtPositions { contradicted: true, .. })
    }

    /// Whether the data leave the functions open at coordinate `q`: between the positions of
    /// an axis whose readings contradict the interpolation there, but for the positions whose
    /// readings touch the functions (there the readings speak, and the interpolation's
    /// uncertainty with its straight-run bound stands).
    pub fn leaves_open(&self, q: f64) -> bool {
        let touched = match self {
            AxisResolution::AtPositions { touched, tolerance_m, .. } => near_any(touched, q, *tolerance_m),
            AxisResolution::Everywhere => false,
        };
        self.is_contradicted() && self.interpolates(q) && !touched
    }
}

/// Whether `q` lies within `tolerance_m` of one of sorted `positions`.
fn near_any(positions: &[f64], q: f64, tolerance_m: f64) -> bool {
    near(positions, q, tolerance_m).is_some()
}

/// The index of the one of sorted `positions` that `q` lies within `tolerance_m` of, if any.
fn near(positions: &[f64], q: f64, tolerance_m: f64) -> Option<usize> {
    let i = positions.partition_point(|&p| p < q);
    [Some(i), i.checked_sub(1)]
        .into_iter()
        .flatten()
        .find(|&k| positions.get(k).is_some_and(|&p| (p - q).abs() <= tolerance_m))
}

/// Median spacing of sorted `positions` (zero for fewer than two).
pub fn median_spacing(positions: &[f64]) -> f64 {
    let mut gaps: Vec<f64> = positions.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_by(f64::total_cmp);
    gaps.get(gaps.len() / 2).copied().unwrap_or(0.0)
}

/// The resolution of every axis: everywhere.
pub const RESOLVED_EVERYWHERE: [AxisResolution; 3] =
    [AxisResolution::Everywhere, AxisResolution::Everywhere, AxisResolution::Everywhere];

/// What is known of an identified model's coefficients: their covariance, and the directions
/// the data left undetermined beyond the gauge ([`crate::estimator::Solution::undetermined`]).
/// A prediction that depends on an undetermined direction has no uncertainty a number could
/// express: it is reported as not determined, never as the minimum-norm value with the
/// covariance's (zero) variance along that direction.
#[derive(Clone, Copy, Debug)]
pub struct Uncertainty<'a> {
    pub covariance: &'a Mat<f64>,
    /// Orthonormal columns (`n_params x m`).
    pub undetermined: MatRef<'a, f64>,
    /// Where the readings resolve the functions along each axis.
    pub resolution: &'a [AxisResolution; 3],
}

impl<'a> Uncertainty<'a> {
    pub fn new(covariance: &'a Mat<f64>, undetermined: &'a Mat<f64>) -> Uncertainty<'a> {
        Uncertainty { covariance, undetermined: undetermined.as_ref(), resolution: &RESOLVED_EVERYWHERE }
    }

    /// The same, with where the readings resolve each axis.
    pub fn with_resolution(self, resolution: &'a [AxisResolution; 3]) -> Uncertainty<'a> {
        Uncertainty { resolution, ..self }
    }

    /// A covariance with nothing undetermined (e.g. a model from an older file, a truth).
    pub fn determined(covariance: &'a Mat<f64>) -> Uncertainty<'a> {
        Uncertainty {
            covariance,
            undetermined: MatRef::from_column_major_slice(&[], covariance.nrows(), 0),
            resolution: &RESOLVED_EVERYWHERE,
        }
    }

    /// Whether any axis is resolved only at its measured positions.
    pub fn interpolates_anywhere(&self) -> bool {
        self.resolution.iter().any(|r| *r != AxisResolution::Everywhere)
    }

    /// Whether any direction is undetermined.
    pub fn has_undetermined(&self) -> bool {
        self.undetermined.ncols() > 0
    }

    /// Whether the data determine every prediction: no direction undetermined, and no axis
    /// whose readings contradict the interpolation between its positions. When true, a
    /// prediction need not be asked.
    pub fn determines_everywhere(&self) -> bool {
        !self.has_undetermined() && !self.resolution.iter().any(AxisResolution::is_contradicted)
    }

    /// Whether the data leave the error at `x` open along some axis: `x` lies between the
    /// positions of an axis whose readings contradict the interpolation there
    /// ([`AxisResolution::leaves_open`]).
    pub fn leaves_open_at(&self, x: &Point3<f64>) -> bool {
        Axis::ALL.iter().any(|&a| self.resolution[a.index()].leaves_open(a.coord(x)))
    }

    /// The smallest share of the touched positions `x` lies at ([`AxisResolution::touched_share_at`]).
    pub fn touched_share_at(&self, x: &Point3<f64>) -> Option<f64> {
        Axis::ALL.iter().filter_map(|&a| self.resolution[a.index()].touched_share_at(a.coord(x))).reduce(f64::min)
    }

    /// Where `x` lies between the measured positions of an axis the readings resolve only there
    /// ([`AxisResolution::AtPositions`]), so that a prediction there is interpolated: the scale
    /// of its covariance, the largest interpolation scale of those axes
    /// ([`AxisResolution::interpolation_scale_at`]); `None` where it lies at the positions of
    /// all of them (scale 1).
    pub fn interpolation_scale_at(&self, x: &Point3<f64>) -> Option<f64> {
        Axis::ALL.iter().filter_map(|&a| self.resolution[a.index()].interpolation_scale_at(a.coord(x))).reduce(f64::max)
    }

    /// How much the linear functional with sparse rows `(index, value)` (one row per output
    /// component) depends on the undetermined directions: `||G U||_F / ||G||_F`, 0 to 1.
    pub fn share<'r>(&self, rows: impl Iterator<Item = &'r [(usize, f64)]>) -> f64 {
        let m = self.undetermined.ncols();
        if m == 0 {
            return 0.0;
        }
        let (mut num, mut den) = (0.0, 0.0);
        for row in rows {
            for j in 0..m {
                let v: f64 = row.iter().map(|&(i, g)| g * self.undetermined[(i, j)]).sum();
                num += v * v;
            }
            den += row.iter().map(|&(_, g)| g * g).sum::<f64>();
        }
        if den == 0.0 {
            0.0
        } else {
            (num / den).sqrt()
        }
    }
}

/// Volumetric error at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointError {
    pub x: Point3<f64>,
    pub p: Vector3<f64>,
    /// `e = actual - (X + p)`.
    pub e: Vector3<f64>,
    /// Covariance of `e` (of its determined part; see [`PointError::is_determined`]); between
    /// measured positions scaled by the interpolation's variance scale
    /// ([`Uncertainty::interpolation_scale_at`]), with the interpolation's shape added
    /// ([`interpolation_shape_covariance`]).
    pub cov: Matrix3<f64>,
    /// How much `e` depends on directions the data leave undetermined ([`Uncertainty::share`]).
    pub undetermined: f64,
    /// The point lies between the measured positions of an axis the readings resolve only
    /// there ([`AxisResolution::AtPositions`]): `e` and its uncertainty are interpolated, under
    /// the smoothness the readings showed elsewhere.
    pub interpolated: bool,
    /// The point lies between the measured positions of an axis whose readings contradict the
    /// interpolation ([`AxisResolution::leaves_open`]): the data do not determine `e` here.
    pub between_contradicted: bool,
}

impl PointError {
    /// Whether the data determine `e` here. When not, `e` is the minimum-norm value or an
    /// interpolation the readings contradict, which means nothing, and the uncertainties are
    /// infinite.
    pub fn is_determined(&self) -> bool {
        self.undetermined <= NOT_DETERMINED_ABOVE && !self.between_contradicted
    }

    /// Expanded uncertainty (k = 2) of the error vector along its least favourable direction:
    /// `2 sqrt(lambda_max(cov))`; infinite where not determined.
    pub fn u95(&self) -> f64 {
        if !self.is_determined() {
            return f64::INFINITY;
        }
        let ev = SymmetricEigen::new(self.cov).eigenvalues;
        COVERAGE_K * ev.max().max(0.0).sqrt()
    }

    /// Standard uncertainty of each component (infinite where not determined).
    pub fn sigma(&self) -> Vector3<f64> {
        if !self.is_determined() {
            return Vector3::repeat(f64::INFINITY);
        }
        Vector3::new(self.cov[(0, 0)].sqrt(), self.cov[(1, 1)].sqrt(), self.cov[(2, 2)].sqrt())
    }

    /// Standard uncertainty of the magnitude `|e|` (first order; infinite where not determined).
    pub fn sigma_norm(&self) -> f64 {
        if !self.is_determined() {
            return f64::INFINITY;
        }
        let n = self.e.norm();
        if n == 0.0 {
            return (self.cov.trace() / 3.0).sqrt();
        }
        let d = self.e / n;
        (d.transpose() * self.cov * d)[(0, 0)].max(0.0).sqrt()
    }
}

/// `G Cov G^T` for a sparse sensitivity.
pub fn propagate(s: &Sensitivity, cov: &Mat<f64>) -> Matrix3<f64> {
    let mut c = Matrix3::zeros();
    for (a, ga) in s.idx.iter().zip(&s.dedu) {
        let mut acc = Vector3::zeros();
        for (b, gb) in s.idx.iter().zip(&s.dedu) {
            acc += gb * cov[(*a, *b)];
        }
        c += ga * acc.transpose();
    }
    0.5 * (c + c.transpose())
}

/// The share of a value between two measured positions that the readings leave to the
/// interpolation's shape: between two stops they give the values at the stops only, and the
/// same values are met by the smooth curve the fit draws through them and by the chord between
/// them (a table whose nodes are the stops, a guideway error that runs straight between two
/// kinks). The fit states the curve's uncertainty; the difference `d` between the curve and the
/// chord is a further component, taken as a bound: the error lies within `+-d` of the fit's
/// value with any value equally likely, variance `d^2 / 3` (the rectangular distribution of the
/// GUM, JCGM 100 4.3.7). It vanishes at the positions and where the fit runs straight between
/// them, and it is largest mid-way where the fit bends most.
pub const CHORD_BOUND_VARIANCE: f64 = 1.0 / 3.0;

/// The covariance that the interpolation's shape adds at `(x, p)` ([`CHORD_BOUND_VARIANCE`]):
/// for each axis along which `x` lies between two measured positions, with `d` the difference
/// between the error at `x` and its chord between the error at those positions (the other
/// coordinates held), `d d^T / 3`; the axes' contributions are added. Zero where `x` lies at the
/// positions of every axis.
pub fn interpolation_shape_covariance(
    model: &ErrorModel,
    resolution: &[AxisResolution; 3],
    x: &Point3<f64>,
    p: &Vector3<f64>,
) -> Matrix3<f64> {
    chord_offsets(model, resolution, x, p).fold(Matrix3::zeros(), |c, d| c + d * d.transpose() * CHORD_BOUND_VARIANCE)
}

/// [`interpolation_shape_covariance`] projected on the unit direction `n`, `n^T C n`, without
/// forming `C` (a validation line's deviation).
pub fn interpolation_shape_variance_along(
    model: &ErrorModel,
    resolution: &[AxisResolution; 3],
    x: &Point3<f64>,
    p: &Vector3<f64>,
    n: &Vector3<f64>,
) -> f64 {
    chord_offsets(model, resolution, x, p).map(|d| n.dot(&d).powi(2) * CHORD_BOUND_VARIANCE).sum()
}

/// For each axis along which `x` lies between two measured positions, the error at `x` less its
/// chord between the errors at those positions (the other coordinates held). The error at `x`
/// is evaluated once, whichever axes it lies between the positions of.
fn chord_offsets<'a>(
    model: &'a ErrorModel,
    resolution: &'a [AxisResolution; 3],
    x: &'a Point3<f64>,
    p: &'a Vector3<f64>,
) -> impl Iterator<Item = Vector3<f64>> + 'a {
    let mut at_x = None;
    Axis::ALL.into_iter().filter_map(move |a| {
        let i = a.index();
        resolution[i].neighbours(x[i]).map(|ends| {
            let e = *at_x.get_or_insert_with(|| model.error(x, p));
            off_chord(x[i], e, ends, |q| {
                let mut y = *x;
                y[i] = q;
                model.error(&y, p)
            })
        })
    })
}

/// The variance at a touched position ([`AxisResolution::touched_share_at`]): the
/// interpolation from the measured positions, whose variance is the fit's without the
/// position's readings (`base / (1 - share)`) plus the straight-run `bound`, combined with what
/// the position's own readings know (the information `share / base` they add to the fit),
/// as two independent estimates are: `1 / (1 / (base / (1 - share) + bound) + share / base)`.
/// `base` where the bound vanishes, `base / share` at most however large it is; `base + bound`
/// for a share of 0 (anywhere but a touched position: the readings there add nothing).
///
/// Why: until stop 78 a touched position was given the whole bound on top of the fit's
/// variance, as if its readings said nothing. On a smooth machine whose curve bends far from its
/// chord between the beams' points that over-stated the joint campaign sevenfold (thirty times
/// the errors on rigid carriages, seeds 891-893: actual / predicted 0.135).
///
/// Which share: the least over the axis's functions
/// ([`crate::interpolation::measured_positions`]). The combination is monotone in the share, so
/// with the least one no function is credited with more than its own readings there give it.
/// The best-pinned function's share (the classification's own number, 0.19 to 0.57 where the
/// least is 0.02 to 0.10) took the thirty-times machine to 0.480 and short length scales
/// (716-718) from 0.650 to 0.908, but over narrow bumps it was less safe on every set run:
/// largest |z| 3.86 -> 4.56 and 15 -> 26 of 5 304 targets beyond 3 sigma (seeds 1081-1100),
/// 6.04 -> 6.49 and 27 -> 38 (1101-1120), 3.57 -> 4.09 and 10 -> 16 of 5 376 (1121-1140, fresh):
/// it credits every function with what the best-pinned one's readings give (an experiment, not
/// kept; docs/representation-auto.md, "What a touched position's readings add").
pub fn with_own_readings(base: f64, bound: f64, share: f64) -> f64 {
    if !(share > 0.0 && share < 1.0) || base <= 0.0 {
        return base + bound;
    }
    let a = base / (1.0 - share) + bound;
    let own = base / share;
    a * own / (a + own)
}

/// [`with_own_readings`] for a covariance: `A - A (A + base / share)^-1 A`, with
/// `A = base / (1 - share) + bound`.
pub fn with_own_readings_cov(base: &Matrix3<f64>, bound: &Matrix3<f64>, share: f64) -> Matrix3<f64> {
    if !(share > 0.0 && share < 1.0) {
        return base + bound;
    }
    let a = base / (1.0 - share) + bound;
    match (a + base / share).try_inverse() {
        Some(inv) => {
            let c = a - a * inv * a;
            0.5 * (c + c.transpose())
        }
        None => base + bound,
    }
}

/// `at_q`, the value at `q`, less its chord between `value(qa)` and `value(qb)`.
fn off_chord<T>(q: f64, at_q: T, (qa, qb): (f64, f64), value: impl Fn(f64) -> T) -> T
where
    T: std::ops::Add<Output = T> + std::ops::Sub<Output = T> + std::ops::Mul<f64, Output = T>,
{
    let t = (q - qa) / (qb - qa);
    at_q - (value(qa) * (1.0 - t) + value(qb) * t)
}

/// How much the error with sensitivity `s` depends on the undetermined directions
/// ([`Uncertainty::share`]).
fn undetermined_share(unc: &Uncertainty<'_>, s: &Sensitivity) -> f64 {
    if !unc.has_undetermined() {
        return 0.0;
    }
    let rows: Vec<Vec<(usize, f64)>> =
        (0..3).map(|k| s.idx.iter().zip(&s.dedu).map(|(&i, d)| (i, d[k])).collect()).collect();
    unc.share(rows.iter().map(|r| r.as_slice()))
}

/// Whether the data determine the error at `(x, p)`: what [`predict`]'s
/// [`PointError::is_determined`] says, without forming the covariance (masks over a map).
pub fn is_determined_at(model: &ErrorModel, unc: &Uncertainty<'_>, x: &Point3<f64>, p: &Vector3<f64>) -> bool {
    if !unc.has_undetermined() {
        return !unc.leaves_open_at(x);
    }
    is_determined_with(unc, x, &model.layout.sensitivity(x, p))
}

/// [`is_determined_at`] for a caller that already holds the point's sensitivity `s`.
pub fn is_determined_with(unc: &Uncertainty<'_>, x: &Point3<f64>, s: &Sensitivity) -> bool {
    !unc.leaves_open_at(x) && undetermined_share(unc, s) <= NOT_DETERMINED_ABOVE
}

/// Volumetric error and its covariance at `(x, p)`, and whether the data determine it.
///
/// For `x` within the model's travel: beyond it the functions hold their end values, which no
/// reading determines, and neither [`PointError::is_determined`] nor the covariance says so (the
/// caller that takes points from outside, `volcal predict`, gives no value there).
pub fn predict(model: &ErrorModel, unc: &Uncertainty<'_>, x: &Point3<f64>, p: &Vector3<f64>) -> PointError {
    let s = model.layout.sensitivity(x, p);
    let undetermined = undetermined_share(unc, &s);
    // Interpolated along some axis, whether along a contradicted one, and the largest scale of
    // the interpolations' variance: one pass over the axes.
    let (mut interpolated, mut between_contradicted, mut scale) = (false, false, None::<f64>);
    for a in Axis::ALL {
        let r = &unc.resolution[a.index()];
        if let Some(s) = r.interpolation_scale_at(a.coord(x)) {
            interpolated = true;
            between_contradicted |= r.leaves_open(a.coord(x));
            scale = Some(scale.map_or(s, |t| t.max(s)));
        }
    }
    PointError {
        x: *x,
        p: *p,
        e: s.apply(&model.u),
        cov: {
            let base = propagate(&s, unc.covariance) * scale.unwrap_or(1.0);
            let bound = if interpolated {
                interpolation_shape_covariance(model, unc.resolution, x, p)
            } else {
                Matrix3::zeros()
            };
            with_own_readings_cov(&base, &bound, unc.touched_share_at(x).unwrap_or(0.0))
        },
        undetermined,
        interpolated,
        between_contradicted,
    }
}

/// Intervals of [`grid`] along axis `a`: the travel over `step`, rounded, at least one.
fn grid_intervals(travel: &Travel, a: Axis, step: f64) -> usize {
    (((travel.length(a)) / step).round() as usize).max(1)
}

/// How many points [`grid`] has for `travel` and `step`, without building it: a caller given
/// the step by a user checks it first (a step in millimetres taken as metres asks for more
/// points than memory holds). A float, so that no step overflows it.
pub fn grid_len(travel: &Travel, step: f64) -> f64 {
    Axis::ALL.iter().map(|&a| grid_intervals(travel, a, step) as f64 + 1.0).product()
}

/// Regular grid over the travel with spacing `step` (at least 2 points per axis, ends
/// included). It allocates all [`grid_len`] points: check that first where the step is a
/// user's.
pub fn grid(travel: &Travel, step: f64) -> Vec<Point3<f64>> {
    let axis_points = |a: Axis| -> Vec<f64> {
        let [lo, hi] = travel.range(a);
        let n = grid_intervals(travel, a, step);
        (0..=n).map(|i| lo + (hi - lo) * i as f64 / n as f64).collect()
    };
    let (xs, ys, zs) = (axis_points(Axis::X), axis_points(Axis::Y), axis_points(Axis::Z));
    let mut out = Vec::with_capacity(xs.len() * ys.len() * zs.len());
    for &z in &zs {
        for &y in &ys {
            for &x in &xs {
                out.push(Point3::new(x, y, z));
            }
        }
    }
    out
}

/// Largest `|e|` over a grid (refined by a finer local search) and where it occurs, among the
/// points where the data determine it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extremum {
    pub at: PointError,
    pub magnitude_m: f64,
    /// Grid points searched, and of them those where the data do not determine the error.
    pub grid_points: usize,
    pub undetermined_points: usize,
}

/// Finds the largest volumetric error magnitude for probe offset `p` where the data determine
/// it (everywhere, when nothing is undetermined). When the data determine it nowhere, the
/// largest minimum-norm value is returned, flagged (`at.is_determined()` is false).
pub fn max_error(model: &ErrorModel, unc: &Uncertainty<'_>, p: &Vector3<f64>, step: f64) -> Extremum {
    let travel = model.layout.travel;
    let mut best = Point3::origin();
    let mut best_m = -1.0;
    let pts = grid(&travel, step);
    let determined = |x: &Point3<f64>| unc.determines_everywhere() || is_determined_at(model, unc, x, p);
    let mask: Vec<bool> = pts.iter().map(determined).collect();
    let undetermined_points = mask.iter().filter(|d| !**d).count();
    let any = undetermined_points < pts.len();
    for (x, &ok) in pts.iter().zip(&mask) {
        if any && !ok {
            continue;
        }
        let m = model.error(x, p).norm();
        if m > best_m {
            best_m = m;
            best = *x;
        }
    }
    // Local refinement by coordinate search inside the travel.
    let mut h = step / 2.0;
    while h > step / 256.0 {
        let mut improved = true;
        while improved {
            improved = false;
            for a in Axis::ALL {
                for sgn in [-1.0, 1.0] {
                    let mut c = best;
                    let [lo, hi] = travel.range(a);
                    c[a.index()] = (c[a.index()] + sgn * h).clamp(lo, hi);
                    let m = model.error(&c, p).norm();
                    if m > best_m + 1e-15 && (!any || determined(&c)) {
                        best_m = m;
                        best = c;
                        improved = true;
                    }
                }
            }
        }
        h /= 2.0;
    }
    Extremum { at: predict(model, unc, &best, p), magnitude_m: best_m, grid_points: pts.len(), undetermined_points }
}

/// One row of a per-axis compensation table: the six functions of an axis at a position.
#[derive(Clone, Debug, PartialEq)]
pub struct CompensationRow {
    pub q_m: f64,
    /// Values of the axis's six functions in canonical order (`EXK EYK EZK EAK EBK ECK`).
    pub values: [f64; 6],
    /// Standard uncertainties of those values (infinite where the data do not determine one).
    pub sigmas: [f64; 6],
}

/// Compensation table of axis `a` at `n` equally spaced positions over its travel.
pub fn compensation_table(model: &ErrorModel, unc: &Uncertainty<'_>, a: Axis, n: usize) -> Vec<CompensationRow> {
    let [lo, hi] = model.layout.travel.range(a);
    let n = n.max(2);
    (0..n)
        .map(|i| {
            let q = lo + (hi - lo) * i as f64 / (n - 1) as f64;
            let mut values = [0.0; 6];
            let mut sigmas = [0.0; 6];
            for m in 0..6 {
                let f = ErrorFunction::from_index(a.index() * 6 + m);
                values[m] = model.function_value(f, q);
                sigmas[m] = function_sigma(model, unc, f, q);
            }
            CompensationRow { q_m: q, values, sigmas }
        })
        .collect()
}

/// Standard uncertainty of one function's value at `q`; infinite where the data do not
/// determine it (it depends on an undetermined direction, or `q` lies between the positions of
/// an axis whose readings contradict the interpolation).
pub fn function_sigma(model: &ErrorModel, unc: &Uncertainty<'_>, f: ErrorFunction, q: f64) -> f64 {
    if unc.resolution[f.axis.index()].leaves_open(q) {
        return f64::INFINITY;
    }
    let off = model.layout.range(f).start;
    let b = model.layout.basis(f).eval(q);
    let row: Vec<(usize, f64)> = b.iter().map(|&(i, v)| (off + i, v)).collect();
    if unc.share(std::iter::once(row.as_slice())) > NOT_DETERMINED_ABOVE {
        return f64::INFINITY;
    }
    let cov = unc.covariance;
    let mut v = 0.0;
    for &(i, bi) in &b {
        for &(j, bj) in &b {
            v += bi * bj * cov[(off + i, off + j)];
        }
    }
    let r = &unc.resolution[f.axis.index()];
    let scale = r.interpolation_scale_at(q).unwrap_or(1.0);
    // The interpolation's shape ([`CHORD_BOUND_VARIANCE`]): the function against its chord.
    let shape = r.neighbours(q).map_or(0.0, |ends| {
        let d = off_chord(q, model.function_value(f, q), ends, |q| model.function_value(f, q));
        d * d * CHORD_BOUND_VARIANCE
    });
    with_own_readings(v * scale, shape, r.touched_share_at(q).unwrap_or(0.0)).max(0.0).sqrt()
}

/// Value and range of a function over its travel, for reports (the paper's Table 2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FunctionRange {
    pub min: f64,
    pub max: f64,
    pub at_min_m: f64,
    pub at_max_m: f64,
    /// `max - min`, signed by the direction of the largest excursion from the datum value.
    pub signed_range: f64,
}

/// Range of a function over its travel, sampled at `samples` points.
pub fn function_range(model: &ErrorModel, f: ErrorFunction, samples: usize) -> FunctionRange {
    let [lo, hi] = model.layout.travel.range(f.axis);
    let samples = samples.max(2);
    let vals: Vec<(f64, f64)> = (0..samples)
        .map(|i| {
            let q = lo + (hi - lo) * i as f64 / (samples - 1) as f64;
            (q, model.function_value(f, q))
        })
        .collect();
    let (mut min, mut max) = (vals[0], vals[0]);
    for &v in &vals {
        if v.1 < min.1 {
            min = v;
        }
        if v.1 > max.1 {
            max = v;
        }
    }
    let datum = model.function_value(f, crate::gauge::axis_origin(&model.layout, f));
    let sign = if (max.1 - datum).abs() >= (min.1 - datum).abs() { 1.0 } else { -1.0 };
    FunctionRange { min: min.1, max: max.1, at_min_m: min.0, at_max_m: max.0, signed_range: sign * (max.1 - min.1) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelLayout;
    use crate::repr::Representation;
    use crate::topology::Topology;

    /// X's positioning error a tent on linear tables of 3 nodes (0 at the ends, 1 um mid-way),
    /// EXX, a zero covariance and no undetermined directions.
    fn tent() -> (ErrorModel, ErrorFunction, Mat<f64>, Mat<f64>) {
        let travel = Travel::new([0.0, 1.0], [0.0, 1.0], [0.0, 1.0]);
        let layout = ModelLayout::uniform(Topology::parse("FXYZ").unwrap(), travel, Representation::Table { nodes: 3 });
        let mut model = ErrorModel::zero(layout);
        let exx = ErrorFunction::parse("EXX").unwrap();
        model.coeffs_mut(exx).copy_from_slice(&[0.0, 1e-6, 0.0]);
        let n = model.layout.n_params;
        (model, exx, Mat::<f64>::zeros(n, n), Mat::<f64>::zeros(n, 0))
    }

    /// X's positioning error a tent (0 at the ends, 1 um mid-way), measured at the ends of X
    /// only: between them the readings cannot tell the tent from its chord (zero), and the
    /// uncertainty there says so, `d^2 / 3` with `d` the tent's height above the chord, even where
    /// the fit's own covariance is zero; at the ends nothing is added.
    #[test]
    fn between_the_positions_the_uncertainty_holds_the_chord() {
        let (mut model, exx, cov, none) = tent();
        let resolution = [AxisResolution::at(vec![0.0, 1.0]), AxisResolution::Everywhere, AxisResolution::Everywhere];
        let unc = Uncertainty::new(&cov, &none).with_resolution(&resolution);
        let p = Vector3::zeros();
        for (q, height) in [(0.5, 1e-6), (0.25, 0.5e-6), (0.0, 0.0), (1.0, 0.0)] {
            let want = height / 3f64.sqrt();
            let s = function_sigma(&model, &unc, exx, q);
            assert!((s - want).abs() <= 1e-15, "EXX at {q}: {s} against {want}");
            let pe = predict(&model, &unc, &Point3::new(q, 0.3, 0.7), &p);
            assert!((pe.cov[(0, 0)].sqrt() - want).abs() <= 1e-15, "x at {q}: {:?}", pe.cov);
            assert_eq!((pe.cov[(1, 1)], pe.cov[(2, 2)]), (0.0, 0.0), "only X's error has a chord");
            // Along a direction, the projection of the same covariance (a validation line).
            let (x, dir) = (Point3::new(q, 0.3, 0.7), Vector3::new(0.6, 0.0, 0.8));
            let along = interpolation_shape_variance_along(&model, &resolution, &x, &p, &dir);
            let projected =
                (dir.transpose() * interpolation_shape_covariance(&model, &resolution, &x, &p) * dir)[(0, 0)];
            assert!((along - projected).abs() <= 1e-27, "{along} against {projected}");
            assert!((along.sqrt() - 0.6 * want).abs() <= 1e-15, "{along} against (0.6 {want})^2");
        }
        // A function straight between the positions has nothing to add.
        model.coeffs_mut(exx).copy_from_slice(&[0.0, 0.5e-6, 1e-6]);
        assert!(function_sigma(&model, &unc, exx, 0.4) <= 1e-15);
    }

    /// A position whose readings touch the functions without measuring them (a tracer's stop
    /// between a beam's points) is interpolated like any coordinate between the measured
    /// positions, the straight-run bound included; where the readings contradict the
    /// interpolation it is still given a number, and only the coordinates no reading speaks
    /// for are left open.
    #[test]
    fn a_touched_position_is_interpolated_and_given_a_number_where_the_interpolation_is_contradicted() {
        let (model, exx, cov, none) = tent();
        let x = AxisResolution::at(vec![0.0, 0.2, 1.0]).measured_at(vec![0.0, 1.0], vec![(0.2, 0.0)]);
        assert!(x.interpolates(0.2) && x.interpolates(0.5) && !x.interpolates(1.0));
        assert_eq!(x.neighbours(0.2), Some((0.0, 1.0)));
        let resolution = [x.clone(), AxisResolution::Everywhere, AxisResolution::Everywhere];
        let unc = Uncertainty::new(&cov, &none).with_resolution(&resolution);
        // The tent is 0.4 um above its chord at 0.2: variance (0.4 um)^2 / 3.
        assert!((function_sigma(&model, &unc, exx, 0.2) - 0.4e-6 / 3f64.sqrt()).abs() <= 1e-15);
        let contradicted = [x.contradicted(), AxisResolution::Everywhere, AxisResolution::Everywhere];
        let unc = Uncertainty::new(&cov, &none).with_resolution(&contradicted);
        let at = |q: f64| predict(&model, &unc, &Point3::new(q, 0.3, 0.7), &Vector3::zeros());
        assert!(at(0.2).is_determined() && at(0.2).interpolated, "the touched position is given, interpolated");
        assert!(!at(0.5).is_determined(), "between the positions no reading speaks for");
        assert!(at(1.0).is_determined() && !at(1.0).interpolated);
        assert!(function_sigma(&model, &unc, exx, 0.2).is_finite());
        assert!(function_sigma(&model, &unc, exx, 0.5).is_infinite());
    }

    /// What a touched position's own readings add to its interpolation: nothing where they
    /// remove no share of the variance, the fit's variance where the bound vanishes, and never
    /// more than the variance their information alone leaves (`base / share`), however large
    /// the bound; the covariance's form agrees with the scalar's along each direction the two
    /// matrices share.
    #[test]
    fn a_touched_position_s_own_readings_cap_its_bound() {
        let (base, bound) = (2.0e-14, 5.0e-13);
        assert_eq!(with_own_readings(base, bound, 0.0), base + bound);
        assert!((with_own_readings(base, 0.0, 0.4) - base).abs() <= 1e-28);
        let capped = with_own_readings(base, 1e6, 0.4);
        assert!(capped <= base / 0.4 && capped > 0.999 * base / 0.4, "{capped}");
        let v = with_own_readings(base, bound, 0.4);
        assert!(v > base && v < base / 0.4 && v < base + bound, "{v}");
        // Diagonal matrices: each axis on its own.
        let b = Matrix3::from_diagonal(&Vector3::new(base, 3.0 * base, 0.5 * base));
        let d = Matrix3::from_diagonal(&Vector3::new(bound, 0.0, 7.0 * bound));
        let c = with_own_readings_cov(&b, &d, 0.4);
        for k in 0..3 {
            let want = with_own_readings(b[(k, k)], d[(k, k)], 0.4);
            assert!((c[(k, k)] - want).abs() <= 1e-12 * want, "{k}: {} against {want}", c[(k, k)]);
        }
        assert_eq!(with_own_readings_cov(&b, &d, 0.0), b + d);
    }
}
