//! One estimator for beams and ranges: weighted least squares with gauge constraints, solved by
//! Gauss-Newton (Levenberg-Marquardt when ranges make it nonlinear), with full covariance.
//!
//! Parameters are `d = [u | Q | x]`: the error-model coefficients `u`, the tracer station
//! positions `Q` (nuisance), and the coefficients `x` of optional [`Effect`]s (used by diagnosis).
//! Every line group (a beam segment, a tracer path) has its own unknown additive origin (the
//! interferometer's arbitrary zero, the tracer's dead path); it is eliminated group by group,
//! which for beams is exactly the patent's barycentre reduction (eq. 2).
//!
//! Beam rows, with `n_j` the beam direction: `l_ij = n_j . (X_ij + p + e(X_ij, p; u)) + c_j`.
//! `n_j` is the least-squares line of the current actual points and is re-estimated every
//! iteration ("re-linearise line directions and iterate").
//! Range rows (paper eq. 4): `l_ij = |Q_i - (X_j + p + e)| - l_i`.
//!
//! Linear algebra: the normal equations are assembled from sparse rows (each reading touches
//! about 75 coefficients); the per-group origin elimination, the null-space projection of the
//! constraints (QR), the Cholesky solve and the eigen-decomposition for identifiability are
//! faer's, in sequential mode so the result is bit-identical run to run.

use crate::beam::{centred_segments, fit_line, orient_with_readings, BeamAlignment};
use crate::campaign::{LineGroup, ObsKind, Observations};
use crate::functions::ErrorFunction;
use crate::gauge::{self, Gauge, GAUGE_DIM};
use crate::halves;
use crate::identify::{self, Identifiability};
use crate::kinematics::AxisFrame;
use crate::model::{ErrorModel, ModelLayout};
use crate::normal;
use crate::nullspace::NullSpace;
use crate::range::multilaterate;
use crate::smoothing::{self, Penalty, Quadratic, ReducedPenalty, Smoothing, SmoothingReport};
use faer::linalg::matmul::matmul;
use faer::linalg::solvers::{DenseSolveCore, Solve};
use faer::{Accum, Mat, Par, Side};
use nalgebra::{Point3, Vector3};

/// Standard uncertainties of the instruments, used as weights.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default))]
pub struct NoiseModel {
    /// Interferometer noise per abscissa, metres.
    pub interferometer_m: f64,
    /// Machine repeatability per axis, metres (enters every reading).
    pub repeatability_m: f64,
    /// Tracer noise per range, metres.
    pub tracer_m: f64,
    /// Tracer length-proportional noise, parts per million of the range.
    pub tracer_ppm: f64,
}

impl Default for NoiseModel {
    fn default() -> Self {
        NoiseModel { interferometer_m: 0.05e-6, repeatability_m: 0.2e-6, tracer_m: 0.1e-6, tracer_ppm: 0.2 }
    }
}

impl NoiseModel {
    /// Standard uncertainty of one reading of `kind` at range `range_m` (tracer only).
    pub fn sigma(&self, kind: ObsKind, range_m: f64) -> f64 {
        let r2 = self.repeatability_m.powi(2);
        match kind {
            ObsKind::Beam => (self.interferometer_m.powi(2) + r2).sqrt(),
            ObsKind::Range => (self.tracer_m.powi(2) + (self.tracer_ppm * 1e-6 * range_m).powi(2) + r2).sqrt(),
        }
    }
}

/// How the reported covariance is scaled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum CovarianceScaling {
    /// From the noise model alone.
    APriori,
    /// Multiplied by the variance factor chi2/dof when it exceeds 1 (never optimistic).
    #[default]
    Birge,
}

/// Options of [`solve`].
#[derive(Clone, Debug, PartialEq)]
pub struct SolveOptions {
    pub gauge: Gauge,
    pub noise: NoiseModel,
    pub max_iterations: usize,
    /// Convergence: largest parameter step, in units of its conditional standard uncertainty
    /// (the solve also stops when steps stagnate below 1e-3 of it: the floating-point floor).
    pub tolerance: f64,
    pub covariance_scaling: CovarianceScaling,
    /// Eigenvalue ratio below which a direction counts as unidentifiable.
    pub rank_tolerance: f64,
    /// Initial station positions for tracer stations (by station id); closed-form otherwise.
    pub initial_stations: Vec<(u32, Point3<f64>)>,
    /// Use only the line groups where this is true (cross-validation); all when `None`.
    pub group_mask: Option<Vec<bool>>,
    /// Starting model coefficients `u` (e.g. a fit of the same machine on more data); zero
    /// errors when `None` or of the wrong length.
    pub initial_model: Option<Vec<f64>>,
    /// Roughness penalties on the error functions, their strength estimated by REML or fixed
    /// ([`crate::smoothing`]; `representation: auto` sets this); none when `None`.
    pub smoothing: Option<Smoothing>,
    /// What each fixed beam is aligned with: the reflector's motion (the patent's procedure,
    /// the default) or the commanded line ([`BeamAlignment`]).
    pub beam_alignment: BeamAlignment,
}

impl Default for SolveOptions {
    fn default() -> Self {
        SolveOptions {
            gauge: Gauge::Patent,
            noise: NoiseModel::default(),
            max_iterations: 50,
            tolerance: 1e-5,
            covariance_scaling: CovarianceScaling::Birge,
            rank_tolerance: 1e-10,
            initial_stations: Vec::new(),
            group_mask: None,
            initial_model: None,
            smoothing: None,
            beam_alignment: BeamAlignment::Motion,
        }
    }
}

/// What an [`Effect`] sees of one reading.
#[derive(Clone, Copy, Debug)]
pub struct ObsContext<'a> {
    pub obs: &'a Observations,
    /// Index of the reading in `obs`.
    pub i: usize,
    pub group: &'a LineGroup,
    /// Unit vector along which the reading increases: the beam direction, or from the station
    /// towards the reflector.
    pub direction: Vector3<f64>,
    /// Current estimate of the actual reflector position.
    pub actual: Point3<f64>,
}

/// A physical effect outside the rigid-body model, linear in its parameters: it adds
/// `sum_k x_k g_k(reading)` to the predicted reading. The diagnosis catalogue implements these.
pub trait Effect: Sync {
    /// Stable id, e.g. `setup_drift`.
    fn id(&self) -> &str;
    /// Names of the parameters (with units), e.g. `drift_x_m_per_s`.
    fn param_names(&self) -> Vec<String>;
    /// Regressors `g_k` of one reading.
    fn regressors(&self, ctx: &ObsContext<'_>, out: &mut [f64]);

    /// The nonzero regressors of one reading as (column, value), in increasing column order
    /// (`idx` and `val` are cleared first). Extension tests ([`Fit::score_parts`]) visit every
    /// reading with them, so an effect whose rows are sparse (a finer basis: a few columns of
    /// many) should give them directly; the default filters [`Effect::regressors`] (`dense`:
    /// scratch of `param_names().len()`).
    fn sparse_regressors(&self, ctx: &ObsContext<'_>, dense: &mut [f64], idx: &mut Vec<usize>, val: &mut Vec<f64>) {
        dense.iter_mut().for_each(|v| *v = 0.0);
        self.regressors(ctx, dense);
        idx.clear();
        val.clear();
        for (j, &v) in dense.iter().enumerate() {
            if v != 0.0 {
                idx.push(j);
                val.push(v);
            }
        }
    }
}

/// Estimated tracer station.
#[derive(Clone, Debug, PartialEq)]
pub struct StationEstimate {
    pub station: u32,
    pub position: Point3<f64>,
    /// Standard uncertainty of each coordinate.
    pub sigma: Vector3<f64>,
}

/// Residual statistics of one line group.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupStats {
    pub n: usize,
    pub rms_m: f64,
    pub max_abs_m: f64,
    /// Beam direction (fixed-beam) or zero (ranges).
    pub direction: Vector3<f64>,
    /// Barycentre of the actual points.
    pub centroid: Point3<f64>,
    /// The eliminated origin (interferometer zero or minus the dead path).
    pub origin_m: f64,
}

/// Residual statistics of the whole fit.
#[derive(Clone, Debug, PartialEq)]
pub struct ResidualStats {
    pub n_obs: usize,
    pub rms_m: f64,
    pub chi2: f64,
    pub dof: usize,
    /// chi2 / dof; 1 when the noise model is right.
    pub variance_factor: f64,
    pub per_group: Vec<GroupStats>,
}

/// Result of [`solve`].
#[derive(Clone, Debug)]
pub struct Solution {
    pub model: ErrorModel,
    /// Covariance of the model coefficients `u` (n_params x n_params).
    pub covariance: Mat<f64>,
    pub stations: Vec<StationEstimate>,
    /// Effect coefficients, in the order of the effects given, with standard uncertainties.
    pub effects: Vec<(String, Vec<(String, f64, f64)>)>,
    /// Covariance of the effect coefficients.
    pub effect_covariance: Mat<f64>,
    /// Residual of every reading (reading minus prediction, origin eliminated), metres.
    pub residuals: Vec<f64>,
    /// Standard uncertainty of every reading from the noise model.
    pub sigmas: Vec<f64>,
    pub stats: ResidualStats,
    pub identifiability: Identifiability,
    /// Directions of the model coefficients `u` that the data leave undetermined beyond the
    /// gauge (orthonormal columns, `n_params x m`; `m = 0` when everything is determined). The
    /// estimate sets them to zero and the covariance has no variance along them, so a quantity
    /// that depends on them is not determined by the data: [`crate::predict`] reports it as such
    /// instead of a number.
    pub undetermined: Mat<f64>,
    /// What the smoothing did (with [`SolveOptions::smoothing`]).
    pub smoothing: Option<SmoothingReport>,
    /// Where along each axis the readings resolve the functions (set by
    /// [`crate::flexibility::solve_auto`]; everywhere otherwise).
    pub resolution: [crate::predict::AxisResolution; 3],
    pub iterations: usize,
    pub converged: bool,
    pub gauge: Gauge,
    pub warnings: Vec<String>,
}

impl Solution {
    /// What predictions from this solution may say: the covariance and the undetermined
    /// directions ([`crate::predict::Uncertainty`]).
    pub fn uncertainty(&self) -> crate::predict::Uncertainty<'_> {
        crate::predict::Uncertainty::new(&self.covariance, &self.undetermined).with_resolution(&self.resolution)
    }
}

/// Why a solve could not produce a result.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("no observations to solve")]
    NoObservations,
    #[error("tracer station {station}: {reason}")]
    Station { station: u32, reason: String },
    #[error("the normal equations are singular even after fixing the unidentifiable directions ({0}): the readings leave a combination of the parameters undetermined that the identifiability analysis did not single out. Check that the machine file's travel is the one the readings cover (each axis's readings spanning most of its travel) and that the readings move every axis")]
    Singular(String),
}

/// Parameter bookkeeping of one solve.
struct Dims {
    n_u: usize,
    stations: Vec<u32>,
    n_e: usize,
    /// Parameters of each effect (`param_names().len()`, asked once: it formats names).
    effect_sizes: Vec<usize>,
}

impl Dims {
    fn n(&self) -> usize {
        self.n_u + 3 * self.stations.len() + self.n_e
    }
    fn station_col(&self, s: usize) -> usize {
        self.n_u + 3 * s
    }
    fn effect_col(&self) -> usize {
        self.n_u + 3 * self.stations.len()
    }
}

/// Current iterate. Not `Clone`: a copy of the points and frames (about 2.7 MB on the patent
/// example) is never needed, see [`State::without_points`].
struct State {
    d: Vec<f64>,
    /// Direction of each group (beams: line direction; ranges: unused).
    dirs: Vec<Vector3<f64>>,
    /// Actual reflector position of every reading at `d` (exact chain).
    actual: Vec<Point3<f64>>,
    /// Per reading and axis, what the exact Jacobian needs.
    frames: Vec<[AxisFrame; 3]>,
}

impl State {
    /// The coefficients and directions alone, for a state that [`update_directions`] completes:
    /// it recomputes the points and frames, which a clone would copy for nothing at every step of
    /// a solve.
    fn without_points(&self) -> State {
        State { d: self.d.clone(), dirs: self.dirs.clone(), actual: Vec::new(), frames: Vec::new() }
    }
}

/// Normal equations of one linearisation.
struct Normal {
    /// n x n, full symmetric; empty for a gradient-only evaluation.
    n: Mat<f64>,
    b: Vec<f64>,
    /// Objective: the weighted chi-square plus the roughness penalty.
    cost: f64,
    /// The weighted chi-square of the readings alone.
    chi2: f64,
    /// Centred residual of every reading and the origin of every group, at this state.
    res: Residuals,
}

/// Everything that stays fixed during a solve.
struct Problem<'a> {
    layout: &'a ModelLayout,
    gauge: Gauge,
    obs: &'a Observations,
    dims: Dims,
    effects: &'a [&'a dyn Effect],
    /// Station index of each group (ranges), usize::MAX for beams.
    group_station: Vec<usize>,
    /// Beam groups sharing a direction (same station and beam id): index of the first.
    dir_owner: Vec<usize>,
    sigma: Vec<f64>,
    /// Per-axis basis spans of every reading, when all six functions of each axis share one
    /// representation (the usual case): enables the tiled normal-matrix kernel.
    structure: Option<Structure>,
    /// Reference energy of each model column (see `reference_energy`).
    ref_energy: Vec<f64>,
    /// Groups taking part in the fit ([`SolveOptions::group_mask`]).
    active: Vec<bool>,
    /// Roughness penalty on the model coefficients (smoothing), with its current parameters.
    penalty: Option<Penalty>,
    beam_alignment: BeamAlignment,
    /// The readings' linearisation horizon, metres ([`horizon`]); fixed with the readings.
    horizon_m: f64,
    /// Least column scale of each parameter (see [`column_scale`]).
    scale_floor: Vec<f64>,
    /// Mean square displacement of the reflector over the readings per pair of parameters
    /// ([`displacement_gram`]).
    displacement: Mat<f64>,
}

impl Problem<'_> {
    /// Readings of the groups taking part in the fit.
    fn active_readings(&self) -> usize {
        (0..self.obs.groups.len()).filter(|&g| self.active[g]).map(|g| self.obs.groups[g].len()).sum()
    }
}

/// Per reading and axis: first coefficient and basis values.
struct Structure {
    k: [usize; 3],
    first: Vec<[usize; 3]>,
    bvals: Vec<f64>,
}

impl Structure {
    fn new(layout: &ModelLayout, obs: &Observations) -> Option<Structure> {
        use crate::axis::Axis;
        if !Axis::ALL.iter().all(|&a| layout.shares_basis(a)) {
            return None;
        }
        let k = Axis::ALL.map(|a| {
            layout.bases[a.index() * 6].n_coeffs().min(match layout.bases[a.index() * 6].repr {
                crate::repr::Representation::Table { .. } => 2,
                crate::repr::Representation::BSpline { .. } => 4,
                _ => usize::MAX,
            })
        });
        let kt: usize = k.iter().sum();
        let mut first = Vec::with_capacity(obs.len());
        let mut bvals = Vec::with_capacity(obs.len() * kt);
        let mut buf = Vec::new();
        for i in 0..obs.len() {
            let mut fi = [0; 3];
            for a in Axis::ALL {
                layout.bases[a.index() * 6].eval_into(a.coord(&obs.x[i]), false, &mut buf);
                // Non-zero basis functions are consecutive in every representation.
                debug_assert!(buf.windows(2).all(|w| w[1].0 == w[0].0 + 1) && buf.len() == k[a.index()]);
                fi[a.index()] = buf[0].0;
                bvals.extend(buf.iter().map(|&(_, v)| v));
            }
            first.push(fi);
        }
        Some(Structure { k, first, bvals })
    }

    fn b(&self, i: usize, a: usize) -> &[f64] {
        let kt: usize = self.k.iter().sum();
        let start = i * kt + self.k[..a].iter().sum::<usize>();
        &self.bvals[start..start + self.k[a]]
    }
}

/// Estimates the error model from prepared observations.
pub fn solve(
    layout: &ModelLayout,
    obs: &Observations,
    opts: &SolveOptions,
    effects: &[&dyn Effect],
) -> Result<Solution, SolveError> {
    fit(layout, obs, opts, effects).map(Fit::into_solution)
}

/// A solved problem that keeps what is needed to test extensions of its model: the factorised,
/// constrained normal equations at the solution.
pub struct Fit<'a> {
    prob: Problem<'a>,
    state: State,
    z: NullSpace,
    factor: Reduced,
    scale: Vec<f64>,
    solution: Solution,
    rows: std::sync::OnceLock<ModelRows>,
}

/// Score (nested-model) test of an [`Effect`] against a [`Fit`]: what adding its parameters to
/// the model would change, computed exactly for the linearised problem through the Schur
/// complement of the fitted normal equations (no refit).
#[derive(Clone, Debug)]
pub struct Score {
    /// Reduction of the weighted chi-square.
    pub delta_chi2: f64,
    /// Number of new parameters the data can separate from the model (the rest alias with it).
    pub rank: usize,
    /// One-step estimates of the effect's parameters.
    pub estimate: Vec<f64>,
    /// Their covariance (a priori weights, scaled like the solution's covariance).
    pub covariance: Mat<f64>,
    /// The information the data carry about them beyond the model (the Schur complement) and
    /// the gradient, for out-of-sample checks: the chi-square reduction of parameters `t` is
    /// `2 t . gradient - t . information . t`.
    pub information: Mat<f64>,
    pub gradient: Vec<f64>,
}

impl Score {
    /// Chi-square reduction these data would see from parameters `t` (e.g. fitted elsewhere).
    pub fn gain(&self, t: &[f64]) -> f64 {
        let k = t.len();
        let mut quad = 0.0;
        for i in 0..k {
            for j in 0..k {
                quad += t[i] * self.information[(i, j)] * t[j];
            }
        }
        2.0 * t.iter().zip(&self.gradient).map(|(a, b)| a * b).sum::<f64>() - quad
    }
}

impl<'a> Fit<'a> {
    pub fn solution(&self) -> &Solution {
        &self.solution
    }

    pub fn into_solution(self) -> Solution {
        self.solution
    }

    /// Fitted direction of each group (beams; zero for ranges).
    pub fn directions(&self) -> &[Vector3<f64>] {
        &self.state.dirs
    }

    /// Actual reflector position of every reading at the solution.
    pub fn actual(&self) -> &[Point3<f64>] {
        &self.state.actual
    }

    /// What each fitted effect adds to the readings, with its parameters set to `params[k]`
    /// (one value per parameter of effect `k`, in its order): `g_k(reading) . params[k]` for
    /// every reading, minus its weighted mean over the line, since the line origin absorbs a
    /// constant. This is the effect's own signature in the residuals: the residuals of a fit
    /// without the effect are, to first order, those with it plus this signal.
    ///
    /// # Panics
    /// When `params` does not have one entry per effect of the fit with one value per parameter.
    pub fn effect_signals(&self, params: &[Vec<f64>]) -> Vec<Vec<f64>> {
        let p = &self.prob;
        assert_eq!(params.len(), p.effects.len(), "one parameter vector per effect");
        for (e, v) in p.effects.iter().zip(params) {
            assert_eq!(v.len(), e.param_names().len(), "one value per parameter of {}", e.id());
        }
        let mut out: Vec<Vec<f64>> = vec![vec![0.0; p.obs.len()]; p.effects.len()];
        let mut reg = Vec::new();
        for (gi, g) in p.obs.groups.iter().enumerate() {
            for i in g.range() {
                let (direction, _, actual) = predict_reading(p, &self.state, gi, i);
                let ctx = ObsContext { obs: p.obs, i, group: g, direction, actual };
                for (k, e) in p.effects.iter().enumerate() {
                    reg.clear();
                    reg.resize(params[k].len(), 0.0);
                    e.regressors(&ctx, &mut reg);
                    out[k][i] = reg.iter().zip(&params[k]).map(|(a, b)| a * b).sum();
                }
            }
            for signal in out.iter_mut() {
                let (sw, swv) = g.range().fold((0.0, 0.0), |(sw, swv), i| {
                    let w = 1.0 / (p.sigma[i] * p.sigma[i]);
                    (sw + w, swv + w * signal[i])
                });
                let mean = swv / sw;
                g.range().for_each(|i| signal[i] -= mean);
            }
        }
        out
    }

    /// Tests `effect` as an extension of the fitted model.
    pub fn score(&self, effect: &dyn Effect) -> Score {
        self.score_masked(effect, None)
    }

    /// [`Fit::score`] restricted to the groups where `mask[group]` is true (cross-validation).
    pub fn score_masked(&self, effect: &dyn Effect, mask: Option<&[bool]>) -> Score {
        let k = effect.param_names().len();
        self.score_parts(effect, mask, &[0..k]).pop().expect("one part")
    }

    /// Tests each part of `effect`'s parameters (ranges of its columns) as a separate
    /// extension of the fitted model, with one pass over the readings: what several
    /// [`Fit::score`] calls on effects made of those parts would give.
    pub fn score_parts(
        &self,
        effect: &dyn Effect,
        mask: Option<&[bool]>,
        parts: &[std::ops::Range<usize>],
    ) -> Vec<Score> {
        let p = &self.prob;
        let s = &self.state;
        let rows = self.rows.get_or_init(|| ModelRows::new(p, s));
        let n = p.dims.n();
        let k = effect.param_names().len();
        // The groups in two halves of about equal readings, accumulated side by side and added
        // in a fixed order: the same sums whatever the machine.
        let groups: Vec<usize> = (0..p.obs.groups.len()).filter(|&gi| mask.is_none_or(|m| m[gi])).collect();
        let lens = groups.iter().map(|&gi| p.obs.groups[gi].len());
        let (first, second) = groups.split_at(halves::first_half(lens.clone()));
        let acc = |gs: &[usize]| ScoreSums::over(self, rows, effect, gs, n, k, parts);
        let parallel = lens.sum::<usize>() >= halves::PARALLEL_FROM;
        let (mut sums, other) = halves::both(parallel, || acc(first), || acc(second));
        sums.add(&other);
        let ScoreSums { bt, g2, c } = sums;
        parts
            .iter()
            .zip(block_offsets(parts))
            .map(|(r, at)| {
                let b = Mat::from_fn(n, r.len(), |i, j| bt[(r.start + j) * n + i]);
                let g2 = Mat::from_fn(r.len(), r.len(), |i, j| g2[at + i * r.len() + j]);
                self.schur_score(&b, &g2, &c[r.clone()])
            })
            .collect()
    }

    /// A reading's weight, the inverse of its stated variance.
    fn weight(&self, i: usize) -> f64 {
        1.0 / (self.prob.sigma[i] * self.prob.sigma[i])
    }

    /// `B^T N+ B` for columns `b` over the model's parameters (`n x k`), with `N+` the inverse of
    /// the fitted (penalised) normal matrix on the gauge-constrained subspace.
    fn constrained_quadratic(&self, b: &Mat<f64>) -> Mat<f64> {
        let bs = Mat::from_fn(b.nrows(), b.ncols(), |i, j| b[(i, j)] / self.scale[i]);
        // `Y^T (L L^T)^-1 Y = (L^-1 Y)^T (L^-1 Y)`: one triangular solve instead of two.
        let mut x = self.z.zt(&bs);
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(self.factor.llt.L(), x.as_mut(), Par::Seq);
        x.transpose() * &x
    }

    /// Deletion statistic of each set of readings (indices into the observations): with `e` the
    /// set's residuals over their stated sigmas and `H` its block of the fit's (penalised) hat
    /// matrix, each group's origin included, `t = e^T (I - H)^-1 e`. `(I - H)^-1 e` are the
    /// residuals of the set predicted by the fit without it (exact for the linearised problem,
    /// smoothing held), and `(I - H)^-1` their covariance under the stated noise and the
    /// prior: a fit whose prior describes the data well gives `t` about the set's size (a
    /// chi-square), one that interpolates worse than its uncertainty says, more. `None` for a
    /// set whose readings the others do not predict at all (`I - H` singular).
    pub fn deletion_statistics(&self, sets: &[Vec<usize>]) -> Vec<Option<Deletion>> {
        let centred = Centred::new(self);
        sets.iter()
            .map(|set| {
                let k = set.len();
                let q = self.constrained_quadratic(&centred.columns(set));
                let i_h = centred.complement_of_hat(set, &q);
                let p = &self.prob;
                let e = Mat::from_fn(k, 1, |a, _| self.solution.residuals[set[a]] / p.sigma[set[a]]);
                let leverage = k as f64 - (0..k).map(|a| i_h[(a, a)]).sum::<f64>();
                let llt = i_h.llt(Side::Lower).ok()?;
                let t = (e.transpose() * llt.solve(&e))[(0, 0)];
                t.is_finite().then_some(Deletion { statistic: t, leverage })
            })
            .collect()
    }

    /// What a set of readings contributes to linear functions of the model's parameters: for
    /// each set and each column `s` of its `selectors` (`n_u x m`, over the error model's
    /// coefficients), the variance of `s . u` as fitted and as the fit without the set would
    /// state it, `(with, without)`, in the fit's whitened units (times the noise scale squared
    /// they are the solution's). By Woodbury, with `B` the set's centred whitened rows,
    /// `H = B^T N+ B` (each group's origin included) and `c = B^T N+ s`,
    /// `without = with + c^T (I - H)^-1 c`. `None` for a set without which the fit does not
    /// hold (`I - H` singular).
    ///
    /// Whether the readings at a position determine the functions there, or the fit's
    /// neighbouring readings and its roughness prior do ([`crate::interpolation::measured_positions`]).
    pub fn deletion_variances(&self, sets: &[(Vec<usize>, Mat<f64>)]) -> Vec<Option<Vec<(f64, f64)>>> {
        let centred = Centred::new(self);
        let n = self.prob.dims.n();
        sets.iter()
            .map(|(set, selectors)| {
                let (k, m) = (set.len(), selectors.ncols());
                let rows = centred.columns(set);
                let both = Mat::from_fn(n, k + m, |i, j| {
                    if j < k {
                        rows[(i, j)]
                    } else if i < selectors.nrows() {
                        selectors[(i, j - k)]
                    } else {
                        0.0
                    }
                });
                let q = self.constrained_quadratic(&both);
                let llt = centred.complement_of_hat(set, &q).llt(Side::Lower).ok()?;
                let c = Mat::from_fn(k, m, |a, j| q[(a, k + j)]);
                let extra = llt.solve(&c);
                let out: Vec<(f64, f64)> = (0..m)
                    .map(|j| {
                        let with = q[(k + j, k + j)];
                        let add: f64 = (0..k).map(|a| c[(a, j)] * extra[(a, j)]).sum();
                        (with, with + add)
                    })
                    .collect();
                out.iter().all(|(w, o)| w.is_finite() && o.is_finite()).then_some(out)
            })
            .collect()
    }

    /// Solves the Schur complement of the fitted model for an extension with cross products
    /// `b` (model x extension), `g2` (extension x extension) and gradient `c`.
    fn schur_score(&self, b: &Mat<f64>, g2: &Mat<f64>, c: &[f64]) -> Score {
        let k = b.ncols();
        // Schur complement against the model: S = G - B^T N+ B, with N+ the constrained inverse.
        let q = self.constrained_quadratic(b);
        let schur = Mat::from_fn(k, k, |i, j| 0.5 * ((g2[(i, j)] - q[(i, j)]) + (g2[(j, i)] - q[(j, i)])));
        // Columns that alias completely with the model (their Schur diagonal vanishes relative to
        // their own energy) carry no new information; the rest by a pseudo-inverse.
        let alive: Vec<bool> = (0..k).map(|i| schur[(i, i)] > 1e-10 * g2[(i, i)].max(f64::MIN_POSITIVE)).collect();
        let d: Vec<f64> = (0..k).map(|i| if alive[i] { schur[(i, i)].sqrt() } else { 1.0 }).collect();
        let sn = Mat::from_fn(k, k, |i, j| if alive[i] && alive[j] { schur[(i, j)] / (d[i] * d[j]) } else { 0.0 });
        let (mut pinv, mut rank) = (Mat::<f64>::zeros(k, k), 0);
        if k > 0 {
            if let Ok(eig) = sn.self_adjoint_eigen(Side::Lower) {
                let lam: Vec<f64> = (0..k).map(|i| eig.S().column_vector()[i]).collect();
                let lmax = lam.iter().cloned().fold(0.0, f64::max);
                let kept: Vec<usize> = (0..k).filter(|&m| lam[m] > 1e-9 * lmax.max(f64::MIN_POSITIVE)).collect();
                rank = kept.len();
                let u = eig.U();
                let uk = Mat::from_fn(k, rank, |i, j| u[(i, kept[j])]);
                let us = Mat::from_fn(k, rank, |i, j| u[(i, kept[j])] / lam[kept[j]]);
                pinv = us * uk.transpose();
            }
        }
        let pinv = Mat::from_fn(k, k, |i, j| pinv[(i, j)] / (d[i] * d[j]));
        let estimate: Vec<f64> = (0..k).map(|i| (0..k).map(|j| pinv[(i, j)] * c[j]).sum()).collect();
        let delta_chi2 = estimate.iter().zip(c).map(|(e, c)| e * c).sum::<f64>().max(0.0);
        let factor = self.solution.stats.variance_factor.max(1.0);
        let covariance = Mat::from_fn(k, k, |i, j| pinv[(i, j)] * factor);
        Score { delta_chi2, rank, estimate, covariance, information: schur, gradient: c.to_vec() }
    }
}

/// What leaving a set of readings out shows ([`Fit::deletion_statistics`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Deletion {
    /// `e^T (I - H)^-1 e`: about the set's size when the fit's noise and prior describe it.
    pub statistic: f64,
    /// `tr H` over the set: the share of the statistic's expectation that comes from the fit
    /// without the set, not from the readings' noise. By Woodbury, `(I - H)^-1 = I + P` with
    /// `P` the whitened posterior covariance of the set's values from the fit without it, and
    /// `tr((I - H) (I + F P)) = k + (F - 1) tr H`: where the posterior's variance is `F` times
    /// the stated one, the statistic's expectation exceeds `k` by `(F - 1) tr H`.
    pub leverage: f64,
}

/// The fit's readings as the deletion quantities see them ([`Fit::deletion_statistics`],
/// [`Fit::deletion_variances`]): each group's origin eliminated by centring its rows on the
/// group's weighted mean, and its share of the hat matrix added back.
struct Centred<'f, 'a> {
    fit: &'f Fit<'a>,
    group_of: Vec<usize>,
    mean: Mat<f64>,
    wsum: Vec<f64>,
}

impl<'f, 'a> Centred<'f, 'a> {
    fn new(fit: &'f Fit<'a>) -> Centred<'f, 'a> {
        let p = &fit.prob;
        let rows = fit.rows.get_or_init(|| ModelRows::new(p, &fit.state));
        let n = p.dims.n();
        let mut group_of = vec![0; p.obs.len()];
        let mut mean = Mat::<f64>::zeros(n, p.obs.groups.len());
        let mut wsum = vec![0.0; p.obs.groups.len()];
        for (gi, g) in p.obs.groups.iter().enumerate() {
            for i in g.range() {
                group_of[i] = gi;
                let w = fit.weight(i);
                wsum[gi] += w;
                let (ri, rv) = rows.row(i);
                let col = mean.col_as_slice_mut(gi);
                for (&c, &v) in ri.iter().zip(rv) {
                    col[c] += w * v;
                }
            }
            let w = wsum[gi];
            mean.col_as_slice_mut(gi).iter_mut().for_each(|v| *v /= w);
        }
        Centred { fit, group_of, mean, wsum }
    }

    /// The set's whitened, centred rows as columns (`n x k`).
    fn columns(&self, set: &[usize]) -> Mat<f64> {
        let p = &self.fit.prob;
        let rows = self.fit.rows.get_or_init(|| ModelRows::new(p, &self.fit.state));
        let mut b = Mat::<f64>::zeros(p.dims.n(), set.len());
        for (a, &i) in set.iter().enumerate() {
            let sw = self.fit.weight(i).sqrt();
            let col = b.col_as_slice_mut(a);
            for (c, m) in col.iter_mut().zip(self.mean.col_as_slice(self.group_of[i])) {
                *c = -m * sw;
            }
            let (ri, rv) = rows.row(i);
            for (&c, &v) in ri.iter().zip(rv) {
                col[c] += v * sw;
            }
        }
        b
    }

    /// `I - H` over the set, from the leading `k x k` block of `q` (the set's columns' quadratic
    /// form, [`Fit::constrained_quadratic`]) and each group's origin.
    fn complement_of_hat(&self, set: &[usize], q: &Mat<f64>) -> Mat<f64> {
        let k = set.len();
        Mat::from_fn(k, k, |a, c| {
            let (i, j) = (set[a], set[c]);
            // The origin's own share of the hat matrix.
            let origin = if self.group_of[i] == self.group_of[j] {
                (self.fit.weight(i) * self.fit.weight(j)).sqrt() / self.wsum[self.group_of[i]]
            } else {
                0.0
            };
            f64::from(a == c) - 0.5 * (q[(a, c)] + q[(c, a)]) - origin
        })
    }
}

/// Where each part's square block starts in [`ScoreSums::g2`] (the blocks one after the other)
/// and, last, where they end: `parts.len() + 1` offsets.
fn block_offsets(parts: &[std::ops::Range<usize>]) -> Vec<usize> {
    std::iter::once(0)
        .chain(parts.iter().scan(0, |at, r| {
            *at += r.len() * r.len();
            Some(*at)
        }))
        .collect()
}

/// The cross products of an extension test ([`Fit::score_parts`]) over some of the groups:
/// `bt` (extension x model, row-major `k x n`: `B^T`), `g2` (extension x extension within each
/// part only, as the Schur complements use them: the parts' square blocks, row-major, one after
/// the other ([`block_offsets`])) and the gradient `c`, each group's origin eliminated.
struct ScoreSums {
    bt: Vec<f64>,
    g2: Vec<f64>,
    c: Vec<f64>,
}

impl ScoreSums {
    #[allow(clippy::too_many_arguments)]
    fn over(
        fit: &Fit<'_>,
        rows: &ModelRows,
        effect: &dyn Effect,
        groups: &[usize],
        n: usize,
        k: usize,
        parts: &[std::ops::Range<usize>],
    ) -> ScoreSums {
        let p = &fit.prob;
        let mut bt = vec![0.0; k * n];
        let block = block_offsets(parts);
        let mut g2 = vec![0.0; block[parts.len()]];
        let mut c = vec![0.0; k];
        let mut dense = vec![0.0; k];
        // Part of each extension column (columns outside every part: none), and where each
        // part's block starts in `g2`.
        let mut part_of = vec![usize::MAX; k];
        for (q, r) in parts.iter().enumerate() {
            part_of[r.clone()].iter_mut().for_each(|x| *x = q);
        }
        let (mut nz, mut reg, mut wreg) = (Vec::new(), Vec::new(), Vec::new());
        // Readings in a row that touch the same columns (along a line, within one knot span)
        // are summed in a small dense block first ([`normal::CrossBatch`]); of the extension's
        // own products only those within a part are kept.
        let mut batch = normal::CrossBatch::default();
        let mut segments: Vec<std::ops::Range<usize>> = Vec::new();
        // A segment's block into its part's block of `g2`: the segment's columns are sorted
        // and all in the same part.
        let mut within_parts = |cols: &[usize], sums: &[f64]| {
            let part = part_of[cols[0]];
            let (s, m) = (parts[part].start, parts[part].len());
            for (&j, row) in cols.iter().zip(sums.chunks_exact(cols.len())) {
                let dst = &mut g2[block[part] + (j - s) * m..][..m];
                for (&l, &v) in cols.iter().zip(row) {
                    dst[l - s] += v;
                }
            }
        };
        // Per group, the weighted column sums of model and extension over sqrt(W): the origins
        // are eliminated at the end by one product each, `B^T -= Sg Sa^T`, `G2 -= Sg Sg^T`.
        let mut sa = Mat::<f64>::zeros(n, groups.len());
        let mut sg = Mat::<f64>::zeros(k, groups.len());
        for (q, &gi) in groups.iter().enumerate() {
            let g = &p.obs.groups[gi];
            let mut wsum = 0.0;
            for i in g.range() {
                let w = 1.0 / (p.sigma[i] * p.sigma[i]);
                wsum += w;
                let (ri, rv) = rows.row(i);
                let sac = sa.col_as_slice_mut(q);
                for (&col, &v) in ri.iter().zip(rv) {
                    sac[col] += w * v;
                }
                let ctx =
                    ObsContext { obs: p.obs, i, group: g, direction: rows.direction(i), actual: fit.state.actual[i] };
                effect.sparse_regressors(&ctx, &mut dense, &mut nz, &mut reg);
                if nz.is_empty() {
                    continue;
                }
                wreg.clear();
                wreg.extend(reg.iter().map(|&v| w * v));
                let r = fit.solution.residuals[i];
                let sgc = sg.col_as_slice_mut(q);
                for (&j, &wr) in nz.iter().zip(&wreg) {
                    sgc[j] += wr;
                    c[j] += wr * r;
                }
                if !batch.holds(&nz, ri) {
                    batch.flush(&mut bt, n, &mut within_parts);
                    // `nz` is sorted and the parts are ranges: each part's columns are a run of it.
                    segments.clear();
                    let mut at = 0;
                    while at < nz.len() {
                        let part = part_of[nz[at]];
                        let end = nz[at..].iter().position(|&j| part_of[j] != part).map_or(nz.len(), |e| at + e);
                        if part != usize::MAX {
                            segments.push(at..end);
                        }
                        at = end;
                    }
                    batch.start(&nz, ri, &segments);
                }
                batch.add(&wreg, &reg, rv);
            }
            let sw = wsum.sqrt();
            sa.col_as_slice_mut(q).iter_mut().for_each(|v| *v /= sw);
            sg.col_as_slice_mut(q).iter_mut().for_each(|v| *v /= sw);
        }
        batch.flush(&mut bt, n, &mut within_parts);
        // `bt`, row-major k x n, is B column-major (n x k).
        let btm = faer::MatMut::from_column_major_slice_mut(&mut bt, n, k);
        matmul(btm, Accum::Add, sa.as_ref(), sg.transpose(), -1.0, Par::Seq);
        let gg = sg.as_ref() * sg.transpose();
        for (r, &at) in parts.iter().zip(&block) {
            for j in r.clone() {
                for l in r.clone() {
                    g2[at + (j - r.start) * r.len() + l - r.start] -= gg[(j, l)];
                }
            }
        }
        ScoreSums { bt, g2, c }
    }

    fn add(&mut self, other: &ScoreSums) {
        for (a, b) in [(&mut self.bt, &other.bt), (&mut self.g2, &other.g2), (&mut self.c, &other.c)] {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        }
    }
}

/// The model rows of every reading at a fit's solution, kept for repeated extension tests: two
/// halves of the readings (stored in group order), computed side by side.
struct ModelRows {
    halves: [RowBlock; 2],
}

/// The rows of consecutive readings from `first` on.
struct RowBlock {
    first: usize,
    start: Vec<usize>,
    idx: Vec<usize>,
    val: Vec<f64>,
    dirs: Vec<Vector3<f64>>,
}

impl ModelRows {
    fn new(p: &Problem<'_>, s: &State) -> ModelRows {
        let ng = p.obs.groups.len();
        let cut = halves::first_half(p.obs.groups.iter().map(|g| g.len()));
        let parallel = p.obs.len() >= halves::PARALLEL_FROM;
        let (a, b) = halves::both(parallel, || RowBlock::of(p, s, 0..cut), || RowBlock::of(p, s, cut..ng));
        ModelRows { halves: [a, b] }
    }

    fn block(&self, i: usize) -> (&RowBlock, usize) {
        let b = if i >= self.halves[1].first { &self.halves[1] } else { &self.halves[0] };
        (b, i - b.first)
    }

    fn row(&self, i: usize) -> (&[usize], &[f64]) {
        let (b, k) = self.block(i);
        (&b.idx[b.start[k]..b.start[k + 1]], &b.val[b.start[k]..b.start[k + 1]])
    }

    fn direction(&self, i: usize) -> Vector3<f64> {
        let (b, k) = self.block(i);
        b.dirs[k]
    }
}

impl RowBlock {
    /// The rows of the readings of `groups`, in order.
    fn of(p: &Problem<'_>, s: &State, groups: std::ops::Range<usize>) -> RowBlock {
        let first = p.obs.groups.get(groups.start).map_or(p.obs.len(), |g| g.range().start);
        let readings: usize = groups.clone().map(|gi| p.obs.groups[gi].len()).sum();
        let (mut idx, mut val, mut ebuf) = (Vec::new(), Vec::new(), Vec::new());
        let mut out = RowBlock { first, start: vec![0], idx: Vec::new(), val: Vec::new(), dirs: Vec::new() };
        out.start.reserve(readings);
        out.dirs.reserve(readings);
        for gi in groups {
            for i in p.obs.groups[gi].range() {
                let (_, dir) = row(p, s, gi, i, &mut idx, &mut val, &mut ebuf);
                if out.idx.is_empty() {
                    // Rows are about equally long: room for all at once.
                    out.idx.reserve(idx.len() * readings + readings);
                    out.val.reserve(idx.len() * readings + readings);
                }
                out.dirs.push(dir);
                out.idx.extend_from_slice(&idx);
                out.val.extend_from_slice(&val);
                out.start.push(out.idx.len());
            }
        }
        out
    }
}

/// Solves and keeps the [`Fit`] for extension tests (see [`Fit::score`]).
pub fn fit<'a>(
    layout: &'a ModelLayout,
    obs: &'a Observations,
    opts: &SolveOptions,
    effects: &'a [&'a dyn Effect],
) -> Result<Fit<'a>, SolveError> {
    if obs.is_empty() || obs.groups.is_empty() {
        return Err(SolveError::NoObservations);
    }
    let stations = obs.stations(ObsKind::Range);
    let effect_sizes: Vec<usize> = effects.iter().map(|e| e.param_names().len()).collect();
    let n_e: usize = effect_sizes.iter().sum();
    let dims = Dims { n_u: layout.n_params, stations: stations.clone(), n_e, effect_sizes };
    let group_station: Vec<usize> =
        obs.groups
            .iter()
            .map(|g| {
                if g.kind == ObsKind::Range {
                    stations.iter().position(|&s| s == g.station).unwrap()
                } else {
                    usize::MAX
                }
            })
            .collect();
    let dir_owner = obs.line_owners();
    let structure = Structure::new(layout, obs);
    let mut kind_of = vec![ObsKind::Beam; obs.len()];
    for g in &obs.groups {
        for i in g.range() {
            kind_of[i] = g.kind;
        }
    }
    let active: Vec<bool> = match &opts.group_mask {
        Some(m) if m.len() == obs.groups.len() => m.clone(),
        _ => vec![true; obs.groups.len()],
    };

    let mut warnings = Vec::new();
    // Initial state: zero errors (or the given model), closed-form stations.
    let mut d = vec![0.0; dims.n()];
    if let Some(u) = opts.initial_model.as_ref().filter(|u| u.len() == layout.n_params) {
        d[..layout.n_params].copy_from_slice(u);
    }
    let mut ranges_at_init = vec![0.0; obs.len()];
    for (s, &st) in stations.iter().enumerate() {
        let given = opts.initial_stations.iter().find(|(id, _)| *id == st).map(|(_, q)| *q);
        let q = match given {
            Some(q) => q,
            None => init_station(obs, st)?,
        };
        for k in 0..3 {
            d[dims.station_col(s) + k] = q[k];
        }
        for (_, g) in obs.groups_of(ObsKind::Range).filter(|(_, g)| g.station == st) {
            for i in g.range() {
                ranges_at_init[i] = (q - (obs.x[i] + obs.p[i])).norm();
            }
        }
    }
    let sigma: Vec<f64> = (0..obs.len()).map(|i| opts.noise.sigma(kind_of[i], ranges_at_init[i])).collect();
    // The penalty starts at zero when REML estimates it: the identifiability analysis below
    // sees the data alone.
    let penalty = opts.smoothing.as_ref().and_then(|s| Penalty::new(layout, s));
    let reml_wanted = penalty.is_some() && opts.smoothing.as_ref().is_some_and(|s| s.estimate);
    let mut prob = Problem {
        layout,
        gauge: opts.gauge,
        obs,
        dims,
        effects,
        group_station,
        dir_owner,
        ref_energy: reference_energy(layout, obs, structure.as_ref(), &sigma, &active),
        active,
        sigma,
        structure,
        penalty,
        beam_alignment: opts.beam_alignment,
        horizon_m: 0.0,
        scale_floor: Vec::new(),
        displacement: Mat::zeros(0, 0),
    };
    prob.horizon_m = horizon(&prob);
    prob.displacement = displacement_gram(&prob);
    prob.scale_floor = scale_floor(&prob);
    let mut state = State { d, dirs: vec![Vector3::zeros(); obs.groups.len()], actual: Vec::new(), frames: Vec::new() };
    update_directions(&prob, &mut state);

    // Constraints: the gauge on u, plus whatever the identifiability analysis adds.
    let n = prob.dims.n();
    let cons = embed(&gauge::constraints(layout, opts.gauge), n);
    let first = assemble(&prob, &state);
    let scale = column_scale(&first.n, &prob.scale_floor);
    let gauge_z = NullSpace::new(&cons, &scale);
    let m0 = reduced_matrix(&first, &gauge_z, &scale, None);
    let f0 = Reduced::from_matrix(m0.clone(), 0.0).ok();
    // The identifiability analysis fixes what the data leave undetermined. If the constrained
    // matrix is still not positive definite (directions at the rounding level of a degenerate
    // campaign), the analysis is repeated with a looser tolerance.
    let mut tol = opts.rank_tolerance;
    let mut f0 = f0;
    let (ident, z, factor) = loop {
        let ident = analyse_at(&prob, &state, &first.n, &m0, f0.as_ref().map(|f| &f.llt), &gauge_z, &scale, tol);
        if ident.extra_constraints.nrows() == 0 {
            if let Some(f) = f0.take() {
                break (ident, NullSpace::new(&cons, &scale), f);
            }
        }
        let z = NullSpace::new(&stack_rows(&cons, &ident.extra_constraints), &scale);
        match Reduced::from_matrix(reduced_matrix(&first, &z, &scale, None), 0.0) {
            Ok(f) => break (ident, z, f),
            Err(e) if tol < 1e-4 => {
                warnings.push(format!(
                    "the constrained normal matrix was not positive definite ({e}); undetermined directions re-detected with tolerance {:.0e}",
                    tol * 1e3
                ));
                tol *= 1e3;
            }
            Err(e) => return Err(e),
        }
    };
    warnings.extend(ident.report.warnings.iter().cloned());
    // With smoothing, the roughness prior determines the curvature that the readings leave
    // open: only what neither determines stays undetermined.
    let (ident, z) = if prob.penalty.is_some() && ident.directions.ncols() > 0 {
        let ident = prior_covered(&mut prob, &first.n, &m0, &gauge_z, &scale, ident, tol);
        let z = NullSpace::new(&stack_rows(&cons, &ident.extra_constraints), &scale);
        (ident, z)
    } else {
        (ident, z)
    };

    let nonlinear = !stations.is_empty();
    let mut normal = first;
    // Smoothing: the parameters by REML on the quadratic model at the start (for beams, linear
    // up to the beam directions, this is the final estimate), the factor with the penalty.
    let mut reml_log =
        RemlLog { open_to_prior: (ident.report.prior_determined > 0).then_some(tol), ..RemlLog::default() };
    let factor = if prob.penalty.is_some() {
        if reml_wanted {
            reml_round(&mut prob, &mut state, &normal.n, &normal, &z, &scale, &mut reml_log);
            normal = Normal { n: std::mem::replace(&mut normal.n, Mat::zeros(0, 0)), ..gradient(&prob, &state) };
        }
        Reduced::new(&prob, &normal, &z, &scale, 0.0)?
    } else {
        factor
    };
    let d0 = state.d.clone();
    let mut lm = levenberg_marquardt(&prob, &mut state, &mut normal, &z, &scale, factor, opts, nonlinear);
    let (mut z, mut scale, mut ident) = (z, scale, ident);
    // Ranges are nonlinear: what the data determine depends on where the stations are, which
    // is only known at the solution (e.g. coplanar stations are only recognised once located).
    // Analyse again with the stations as estimated and the machine errors at zero: what the
    // geometry determines to first order. (At the estimated errors a direction unobservable to
    // first order can look weakly observed through second-order terms, with a sign ambiguity: a
    // ranged point in the stations' plane moved by +e or -e normal to it reads the same.) If
    // this finds further undetermined directions, remove them from the change since the start
    // (they do not change the fit to first order) and iterate again under the new constraints.
    if nonlinear {
        let mut nominal = state.without_points();
        nominal.d[..layout.n_params].fill(0.0);
        update_directions(&prob, &mut nominal);
        let normal_nom = assemble(&prob, &nominal);
        let scale_nom = column_scale(&normal_nom.n, &prob.scale_floor);
        let z_nom = NullSpace::new(&cons, &scale_nom);
        let m_nom = reduced_matrix(&normal_nom, &z_nom, &scale_nom, None);
        let mut ident_f =
            analyse_at(&prob, &nominal, &normal_nom.n, &m_nom, None, &z_nom, &scale_nom, opts.rank_tolerance);
        // What the readings alone left open at the start (before the prior determined part of it).
        let open = ident.report.extra_null_dim + ident.report.prior_determined;
        if ident_f.report.extra_null_dim > open && prob.penalty.is_some() {
            ident_f = prior_covered(&mut prob, &normal_nom.n, &m_nom, &z_nom, &scale_nom, ident_f, opts.rank_tolerance);
        }
        if ident_f.report.extra_null_dim + ident_f.report.prior_determined > open
            && ident_f.directions.ncols() > ident.directions.ncols()
        {
            let w = &ident_f.extra_constraints;
            for r in 0..w.nrows() {
                // Rows are W^T S (unscaled); W has orthonormal columns in scaled coordinates.
                let along: f64 = (0..n).map(|k| w[(r, k)] * (state.d[k] - d0[k])).sum();
                for k in 0..n {
                    state.d[k] -= along * w[(r, k)] / (scale_nom[k] * scale_nom[k]);
                }
            }
            update_directions(&prob, &mut state);
            normal = assemble(&prob, &state);
            scale = column_scale(&normal.n, &prob.scale_floor);
            z = NullSpace::new(&stack_rows(&cons, w), &scale);
            lm = lm.and_again(&prob, &mut state, &mut normal, &z, &scale, opts, nonlinear)?;
            for w in &ident_f.report.warnings {
                if !warnings.contains(w) {
                    warnings.push(w.clone());
                }
            }
            ident = ident_f;
        } else if ident.report.prior_determined > 0 && ident_f.report.prior_determined == 0 {
            // Same null space: report the analysis with the stations as located, for what the
            // prior leaves undetermined.
            ident.report = restated_at(layout, &normal_nom.n, &scale_nom, &ident, ident_f).report;
        } else {
            // Same null space: report the analysis with the stations as located.
            ident.report = ident_f.report;
        }
        // Ranges: REML again on the quadratic model at the solution, and the fit again, until
        // the smoothing parameters settle (a tenth of a decade).
        if reml_wanted {
            for _ in 0..4 {
                let before = prob.penalty.as_ref().map(|p| p.lambda.clone()).unwrap_or_default();
                let n_data = if normal.n.nrows() == n {
                    std::mem::replace(&mut normal.n, Mat::zeros(0, 0))
                } else {
                    assemble(&prob, &state).n
                };
                reml_round(&mut prob, &mut state, &n_data, &normal, &z, &scale, &mut reml_log);
                normal = Normal { n: n_data, ..gradient(&prob, &state) };
                lm = lm.and_again(&prob, &mut state, &mut normal, &z, &scale, opts, nonlinear)?;
                let after = prob.penalty.as_ref().map(|p| p.lambda.clone()).unwrap_or_default();
                let moved = before.iter().zip(&after).map(|(a, b)| (a.ln() - b.ln()).abs()).fold(0.0, f64::max);
                if moved < 0.23 {
                    break;
                }
            }
        }
    }
    warnings.extend(lm.warnings.iter().cloned());
    let (iterations, converged, mut factor, damped) = (lm.iterations, lm.converged, lm.factor, lm.damped);
    if !converged {
        warnings.push(format!("the estimator did not converge in {} iterations", iterations));
    }

    // Covariance and statistics at the solution. For beam-only problems the normal matrix is
    // the frozen one: its rows differ from those at the solution only through the change of
    // the beam directions (the machine's angular errors, ~1e-5 rad), so the covariance differs
    // by a relative amount of the same order, far below the precision to which it is reported.
    let final_res = Residuals { residual: normal.res.residual.clone(), origin: normal.res.origin.clone() };
    if nonlinear || damped {
        factor = Reduced::at_solution(&prob, &normal, &z, &scale)?;
    }
    let mut inverse = factor.llt.inverse();
    // Smoothing parameters estimated from the readings carry uncertainty of their own.
    if reml_wanted {
        if let (Some(pen), Some(noise)) = (prob.penalty.as_ref(), reml_log.scale) {
            let u0 = &state.d[..layout.n_params];
            let rp = match reml_log.reduced.take() {
                Some(mut rp) => {
                    rp.moved_to(pen, n, &scale, u0, |x| z.zt(x));
                    rp
                }
                None => ReducedPenalty::new(pen, n, &scale, u0, |x| z.zt(x)),
            };
            if let Some(dc) = smoothing::lambda_covariance(&rp, &pen.lambda, factor.llt.L(), &reml_log.at_upper, noise)
            {
                inverse += dc;
            }
        }
    }
    let cov_scaled = z.embed(&inverse);
    let active_groups: Vec<usize> = (0..obs.groups.len()).filter(|&g| prob.active[g]).collect();
    let n_obs = prob.active_readings();
    // With smoothing, the curvature the prior determines is not fitted to the readings: the
    // effective number of parameters is the free dimension minus the prior's share.
    let mut smoothing_report = prob.penalty.as_ref().map(|pen| {
        smoothing::report(
            pen,
            factor.llt.L(),
            n,
            &scale,
            |x| z.zt(x),
            z.dim(),
            reml_wanted.then_some((
                reml_log.iterations,
                reml_log.converged,
                reml_log.at_upper.as_slice(),
                reml_log.scale.map_or(1.0, |s| s.phi),
            )),
        )
    });
    let n_free = smoothing_report.as_ref().map_or(z.dim() as f64, |r| r.edf_total);
    let dof = (n_obs as f64 - n_free - active_groups.len() as f64).round().max(1.0) as usize;
    let chi2 = normal.chi2;
    let vf = chi2 / dof as f64;
    let cov_factor = match opts.covariance_scaling {
        CovarianceScaling::APriori => 1.0,
        CovarianceScaling::Birge => vf.max(1.0),
    };
    // Symmetric to the bit (the inverse is symmetric only to rounding): the upper triangle,
    // which is what a model file keeps, so a model read back predicts what the solve did.
    let cov_full = Mat::from_fn(n, n, |i, j| {
        let (i, j) = (i.min(j), i.max(j));
        cov_scaled[(i, j)] / (scale[i] * scale[j]) * cov_factor
    });

    let n_u = layout.n_params;
    let mut covariance = cov_full.submatrix(0, 0, n_u, n_u).to_owned();
    // What the face diagonals' pairs leave open, no smaller than the readings' long waves of the
    // same shapes (`open_pairs`): the roughness prior alone under-states it on smooth machines.
    if let Some(pen) = prob.penalty.as_ref().filter(|p| reml_wanted && !p.open_alike.is_empty()) {
        let n_data = assemble(&prob, &state).n;
        let raised = crate::open_pairs::state_open_long_waves(
            layout,
            opts.gauge,
            &pen.open_alike,
            &state.d[..n_u],
            n_data.submatrix(0, 0, n_u, n_u),
            &mut covariance,
        );
        if let Some(r) = smoothing_report.as_mut() {
            r.open_long_waves = raised;
        }
    }
    let stations_out = stations
        .iter()
        .enumerate()
        .map(|(s, &st)| {
            let c = prob.dims.station_col(s);
            StationEstimate {
                station: st,
                position: Point3::new(state.d[c], state.d[c + 1], state.d[c + 2]),
                sigma: Vector3::new(
                    standard_uncertainty(cov_full[(c, c)]),
                    standard_uncertainty(cov_full[(c + 1, c + 1)]),
                    standard_uncertainty(cov_full[(c + 2, c + 2)]),
                ),
            }
        })
        .collect();
    let e0 = prob.dims.effect_col();
    let effect_covariance = cov_full.submatrix(e0, e0, n_e, n_e).to_owned();
    let mut effects_out = Vec::new();
    let mut k = e0;
    for e in effects {
        let mut ps = Vec::new();
        for name in e.param_names() {
            ps.push((name, state.d[k], standard_uncertainty(cov_full[(k, k)])));
            k += 1;
        }
        effects_out.push((e.id().to_string(), ps));
    }
    let per_group = obs
        .groups
        .iter()
        .enumerate()
        .map(|(gi, g)| {
            let r = &final_res.residual[g.range()];
            let rms = (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt();
            let pts: Vec<Point3<f64>> = g.range().map(|i| actual_point(&prob, &state, i)).collect();
            GroupStats {
                n: g.len(),
                rms_m: rms,
                max_abs_m: r.iter().fold(0.0, |m, v| m.max(v.abs())),
                direction: if g.kind == ObsKind::Beam { state.dirs[gi] } else { Vector3::zeros() },
                centroid: fit_line(&pts).centroid,
                origin_m: final_res.origin[gi],
            }
        })
        .collect();
    let rms =
        (active_groups.iter().flat_map(|&g| obs.groups[g].range()).map(|i| final_res.residual[i].powi(2)).sum::<f64>()
            / n_obs.max(1) as f64)
            .sqrt();
    let active: Vec<LineGroup> = active_groups.iter().map(|&g| obs.groups[g].clone()).collect();
    warnings.extend(crate::misfit::gross_misfit(chi2, dof, &active, &final_res.residual, &prob.sigma));
    let model = ErrorModel { layout: layout.clone(), u: state.d[..n_u].to_vec() };
    let solution = Solution {
        model,
        covariance,
        stations: stations_out,
        effects: effects_out,
        effect_covariance,
        residuals: final_res.residual,
        sigmas: prob.sigma.clone(),
        stats: ResidualStats { n_obs, rms_m: rms, chi2, dof, variance_factor: vf, per_group },
        identifiability: ident.report,
        undetermined: undetermined_directions(&ident.directions, layout.n_params),
        smoothing: smoothing_report,
        resolution: crate::predict::RESOLVED_EVERYWHERE,
        iterations,
        converged,
        gauge: opts.gauge,
        warnings,
    };
    Ok(Fit { prob, state, z, factor, scale, solution, rows: std::sync::OnceLock::new() })
}

/// Pairs of smoothing groups that the readings leave open alike
/// ([`ReducedPenalty::alike_where_open`] on the null space of the reduced data matrix `m_data`,
/// eigenvalues below `tol` of the largest), among the pairs a beam plan can leave open that way:
/// the two straightnesses of one plane (`EXY` and `EYX`, `EXZ` and `EZX`, `EYZ` and `EZY`),
/// which a beam along that plane's face diagonal sees only in combination. Other functions
/// whose shares look alike there are different physics that other beams measure apart: sharing
/// theirs (the same axis's straightnesses, its angles; an experiment, not kept) made sparse
/// beams less accurate and their uncertainty under-stated (docs/representation-auto.md, "One
/// smoothing for a face diagonal's straightnesses").
fn open_alike(m_data: &Mat<f64>, rp: &ReducedPenalty, pen: &Penalty, tol: f64) -> Vec<(usize, usize)> {
    let Ok(eig) = m_data.self_adjoint_eigen(Side::Lower) else { return Vec::new() };
    let lam = eig.S().column_vector();
    let lmax = (0..lam.nrows()).map(|i| lam[i]).fold(0.0, f64::max);
    // Eigenvalues ascend: the null space is the leading columns.
    let k = (0..lam.nrows()).take_while(|&i| lam[i] < tol * lmax).count();
    if k == 0 {
        return Vec::new();
    }
    let v = eig.U().subcols(0, k).to_owned();
    let function = |g: usize| pen.blocks.iter().find(|b| b.group == g).map(|b| b.function);
    rp.alike_where_open(&v, |a, b| match (function(a), function(b)) {
        (Some(fa), Some(fb)) => {
            fa.is_straightness() && fb.is_straightness() && fa.axis == fb.component && fb.axis == fa.component
        }
        _ => false,
    })
}

/// What REML did over its rounds.
#[derive(Default)]
struct RemlLog {
    iterations: usize,
    converged: bool,
    /// Per smoothing parameter: at its upper bound (straight line).
    at_upper: Vec<bool>,
    /// Whether functions determined only together were given one parameter (first round).
    merged: bool,
    /// The rank tolerance of the data's null space, when the readings leave directions that only
    /// the prior determines (the first round then looks for functions open alike there).
    open_to_prior: Option<f64>,
    /// The noise scale of the last round.
    scale: Option<smoothing::Scale>,
    /// The last round's penalties in reduced coordinates, for the covariance at the solution;
    /// none when the last round failed. The last round has the solution's reduction and column
    /// scale (beams have one round; ranges constrain anew only before their later rounds), so
    /// only the estimate they are taken about differs ([`ReducedPenalty::moved_to`]).
    reduced: Option<ReducedPenalty>,
}

/// One round of REML ([`smoothing::reml`]) on the quadratic model of the fit at `state` (data
/// normal matrix `n_data`, gradient and chi-square of `normal`): sets the smoothing parameters of
/// `prob` and moves `state` to the penalised optimum of that model. In the first round,
/// functions whose curvatures the data cannot tell apart are given one parameter.
#[allow(clippy::too_many_arguments)]
fn reml_round(
    prob: &mut Problem<'_>,
    state: &mut State,
    n_data: &Mat<f64>,
    normal: &Normal,
    z: &NullSpace,
    scale: &[f64],
    log: &mut RemlLog,
) {
    log.reduced = None;
    let n = prob.dims.n();
    let n_u = prob.dims.n_u;
    let n_obs = prob.active_readings();
    let Some(pen) = prob.penalty.as_mut() else { return };
    let m_data = z.project(&Mat::from_fn(n, n, |i, j| n_data[(i, j)] / (scale[i] * scale[j])));
    // The data's gradient: `normal.b` is `J' W r - S u`.
    let mut minus_su = vec![0.0; n];
    pen.apply(&state.d[..n_u], &mut minus_su[..n_u]);
    let g_data = z.zt(&Mat::from_fn(n, 1, |i, _| (normal.b[i] - minus_su[i]) / scale[i]));
    let q = Quadratic { m_data: &m_data, g_data: &g_data, chi2: normal.chi2, n_obs };
    let mut rp = ReducedPenalty::new(pen, n, scale, &state.d[..n_u], |x| z.zt(x));
    if !log.merged {
        log.merged = true;
        let mut pairs = rp.overlapping_pairs();
        // Open alike: the pairs an earlier fit of these readings found (`Smoothing::open_alike`),
        // and those found here.
        let group = |f: ErrorFunction| pen.blocks.iter().find(|b| b.function == f).map(|b| b.group);
        let told = |&[a, b]: &[ErrorFunction; 2]| {
            let (ga, gb) = (group(a)?, group(b)?);
            Some((ga.min(gb), ga.max(gb)))
        };
        let mut alike: Vec<(usize, usize)> = pen.open_alike.iter().filter_map(told).collect();
        if let Some(tol) = log.open_to_prior {
            for found in open_alike(&m_data, &rp, pen, tol) {
                if !alike.contains(&found) {
                    alike.push(found);
                }
            }
        }
        if !alike.is_empty() {
            let groups: Vec<usize> = alike.iter().flat_map(|&(a, b)| [a, b]).collect();
            pen.relative_roughness(&groups, |f| prob.layout.basis(f).length());
            let function = |g: usize| pen.blocks.iter().find(|b| b.group == g).map(|b| b.function);
            pen.open_alike = alike.iter().filter_map(|&(a, b)| Some([function(a)?, function(b)?])).collect();
            pairs.extend(alike);
        }
        if !pairs.is_empty() {
            pen.merge(&pairs);
            rp = ReducedPenalty::new(pen, n, scale, &state.d[..n_u], |x| z.zt(x));
        }
    }
    let lambda0 =
        if pen.lambda.iter().all(|&l| l > 0.0) { pen.lambda.clone() } else { smoothing::initial_lambda(&q, &rp) };
    let Some(res) = smoothing::reml(&q, &rp, &lambda0, 60) else {
        // The penalised matrix did not factorise at the start: keep the starting parameters.
        pen.lambda = lambda0;
        return;
    };
    pen.lambda = res.lambda;
    let ds = z.z(&res.y);
    for k in 0..n {
        state.d[k] += ds[(k, 0)] / scale[k];
    }
    update_directions(prob, state);
    log.reduced = Some(rp);
    log.iterations += res.iterations;
    log.converged = res.converged;
    log.at_upper = res.at_upper;
    log.scale = Some(res.scale);
}

/// What stays undetermined once the roughness penalty of `prob` is in the model: the null space
/// of the data's reduced matrix `m0` (on the gauge-constrained subspace `gz`) plus the penalty of
/// every function the readings inform. A function whose roughness lies entirely in the data's
/// null space (not observed at all) does not count: the readings cannot estimate its smoothness,
/// so its prior would be a guess; its directions stay undetermined, and its penalty is removed
/// from `prob` (acting on directions held at their minimum-norm value, it would pull on the
/// determined ones those are coupled with through the gauge). The report keeps what the data
/// alone determine and says what the prior adds.
fn prior_covered(
    prob: &mut Problem<'_>,
    n_full: &Mat<f64>,
    m0: &Mat<f64>,
    gz: &NullSpace,
    scale: &[f64],
    mut ident: identify::Analysis,
    tol: f64,
) -> identify::Analysis {
    let n = prob.dims.n();
    let Some(pen) = prob.penalty.as_mut() else { return ident };
    let k0 = ident.directions.ncols();
    // The data's null space in reduced coordinates, orthonormal.
    let w = Mat::from_fn(n, k0, |i, j| ident.directions[(i, j)] * scale[i]);
    let v = gz.zt(&w);
    // What the readings inform only beyond the linearisation horizon is no information here:
    // only the prior can determine it.
    let mut m = if ident.far > 0 {
        let vf = v.subcols(k0 - ident.far, ident.far);
        let p = Mat::<f64>::identity(v.nrows(), v.nrows()) - vf * vf.transpose();
        &p * m0 * &p
    } else {
        m0.clone()
    };
    let nr = m.nrows();
    let md = (0..nr).map(|i| m0[(i, i)]).sum::<f64>() / nr.max(1) as f64;
    let mut unobserved = Vec::new();
    for (f, bt) in smoothing::block_columns(pen, n, scale, |x| gz.zt(x)) {
        let total = bt.squared_norm_l2();
        let inside = (v.transpose() * &bt).squared_norm_l2();
        if total == 0.0 || total - inside <= 1e-6 * total {
            unobserved.push(f);
            continue;
        }
        let p = &bt * bt.transpose();
        let pd = (0..nr).map(|i| p[(i, i)]).sum::<f64>() / nr as f64;
        let tau = 1e-3 * md / pd.max(f64::MIN_POSITIVE);
        for j in 0..nr {
            for i in 0..nr {
                m[(i, j)] += tau * p[(i, j)];
            }
        }
    }
    pen.remove(&unobserved);
    if pen.blocks.is_empty() {
        prob.penalty = None;
    }
    let Ok(eig) = m.self_adjoint_eigen(Side::Lower) else { return ident };
    let lam: Vec<f64> = (0..nr).map(|i| eig.S().column_vector()[i]).collect();
    let lmax = lam.iter().cloned().fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    let null: Vec<usize> = (0..nr).filter(|&i| lam[i] < tol * lmax).collect();
    let u = eig.U();
    let vn = Mat::from_fn(nr, null.len(), |i, j| u[(i, null[j])]);
    let wn = gz.z(&vn);
    ident.extra_constraints = Mat::from_fn(wn.ncols(), n, |r, k| wn[(k, r)] * scale[k]);
    ident.directions = Mat::from_fn(n, wn.ncols(), |k, r| wn[(k, r)] / scale[k]);
    // The columns are the null space of readings and prior now.
    ident.far = 0;
    if null.len() < k0 {
        identify::restate(prob.layout, n_full, &wn, &mut ident);
    }
    ident
}

/// `fresh`, an analysis of the readings alone at the located stations that found the same
/// null space as `prior`'s readings, restated for what `prior` (after [`prior_covered`]) leaves
/// undetermined: its directions, scaled by `scale` and orthonormalised, in `fresh`'s
/// coordinates.
fn restated_at(
    layout: &ModelLayout,
    n_full: &Mat<f64>,
    scale: &[f64],
    prior: &identify::Analysis,
    mut fresh: identify::Analysis,
) -> identify::Analysis {
    let d = &prior.directions;
    let w = Mat::from_fn(d.nrows(), d.ncols(), |k, r| d[(k, r)] * scale[k]);
    let w = if w.ncols() > 0 { w.qr().compute_thin_Q() } else { w };
    identify::restate(layout, n_full, &w, &mut fresh);
    fresh
}

/// The undetermined directions of the model coefficients: the first `n_u` rows of the
/// identifiability analysis's null directions, orthonormalised (thin QR; directions that live
/// in the nuisance parameters alone are dropped).
fn undetermined_directions(directions: &Mat<f64>, n_u: usize) -> Mat<f64> {
    let m = directions.ncols();
    if m == 0 {
        return Mat::zeros(n_u, 0);
    }
    let a = directions.subrows(0, n_u).to_owned();
    let scale = (0..m).map(|j| a.col(j).norm_l2()).fold(0.0, f64::max);
    if scale == 0.0 {
        return Mat::zeros(n_u, 0);
    }
    let qr = a.qr();
    let r = qr.R();
    let q = qr.compute_thin_Q();
    let keep: Vec<usize> = (0..m.min(n_u)).filter(|&j| r[(j, j)].abs() > 1e-8 * scale).collect();
    Mat::from_fn(n_u, keep.len(), |i, j| q[(i, keep[j])])
}

/// Outcome of one run of [`levenberg_marquardt`].
struct LmRun {
    iterations: usize,
    converged: bool,
    /// Factorisation of the reduced matrix last in use (the frozen one for beams).
    factor: Reduced,
    warnings: Vec<String>,
    /// Whether it ended as damped Levenberg-Marquardt (`factor` is then not at the solution).
    damped: bool,
}

impl LmRun {
    /// This run followed by another from `state` (after its constraints or smoothing changed),
    /// with a fresh factor of `normal`: iterations and warnings of both.
    #[allow(clippy::too_many_arguments)]
    fn and_again(
        self,
        prob: &Problem<'_>,
        state: &mut State,
        normal: &mut Normal,
        z: &NullSpace,
        scale: &[f64],
        opts: &SolveOptions,
        nonlinear: bool,
    ) -> Result<LmRun, SolveError> {
        let factor = Reduced::at_solution(prob, normal, z, scale)?;
        let again = levenberg_marquardt(prob, state, normal, z, scale, factor, opts, nonlinear);
        Ok(LmRun {
            iterations: self.iterations + again.iterations,
            warnings: self.warnings.into_iter().chain(again.warnings).collect(),
            ..again
        })
    }
}

/// Gauss-Newton (beams) or Levenberg-Marquardt (ranges) iterations in the null space `z` of the
/// constraints from `state` and its normal equations `normal`, both updated in place; `factor`
/// is the factorisation of the reduced matrix to start from.
#[allow(clippy::too_many_arguments)]
fn levenberg_marquardt(
    prob: &Problem<'_>,
    state: &mut State,
    normal: &mut Normal,
    z: &NullSpace,
    scale: &[f64],
    mut factor: Reduced,
    opts: &SolveOptions,
    nonlinear: bool,
) -> LmRun {
    let n = prob.dims.n();
    let mut warnings = Vec::new();
    let mut mu = if nonlinear { 1e-4 } else { 0.0 };
    let mut converged = false;
    let mut iterations = 0;
    // Beam rows change between iterations only through the beam directions (by ~1e-5 rad),
    // so for beam-only problems the normal matrix of the first linearisation is kept and only
    // the gradient is refreshed; the matrix is re-assembled once at the solution for the
    // covariance. Ranges are nonlinear: full Levenberg-Marquardt.
    // `factor` is the factorisation of the reduced matrix in use; it always stays valid (a
    // refreshed matrix that fails to factorise is not adopted).
    let mut last_step = f64::INFINITY;
    let mut stalls = 0;
    // Beam directions are refitted to the actual points at every step (they are not
    // parameters), which the frozen Gauss-Newton step ignores. On weakly determined campaigns
    // (e.g. half of the lines, for cross-validation) that can make the cost rise; the solve
    // then continues as damped Levenberg-Marquardt with a refreshed matrix at every step.
    let mut damped = nonlinear;
    for it in 0..opts.max_iterations {
        iterations = it + 1;
        let step = if damped {
            match Reduced::new(prob, normal, z, scale, mu) {
                Ok(r) => reduced_step(&r, normal, z, scale),
                Err(_) => {
                    mu = (mu * 10.0).max(1e-6);
                    continue;
                }
            }
        } else {
            reduced_step(&factor, normal, z, scale)
        };
        let mut trial = state.without_points();
        for k in 0..n {
            trial.d[k] += step.delta[k];
        }
        update_directions(prob, &mut trial);
        let ratio = step.max_sigma_ratio / last_step;
        // Frozen normal matrix while steps shrink fast; refreshed when convergence slows (a
        // poorly conditioned gauge amplifies the change of the rows) and always for ranges.
        let refresh = damped || (ratio > 0.1 && step.max_sigma_ratio >= 1e-4);
        let trial_normal = if refresh { assemble(prob, &trial) } else { gradient(prob, &trial) };
        if !damped && trial_normal.cost > normal.cost * (1.0 + 1e-9) && step.max_sigma_ratio >= opts.tolerance {
            damped = true;
            mu = 1e-4;
            *normal = assemble(prob, state);
            continue;
        }
        if damped && trial_normal.cost > normal.cost * (1.0 + 1e-12) {
            if step.max_sigma_ratio < opts.tolerance {
                // A negligible step that does not lower the cost: the minimum is reached to
                // round-off; raising the damping would only spend iterations.
                converged = true;
                break;
            }
            mu = (mu * 10.0).max(1e-6);
            if mu > 1e12 {
                warnings.push("Levenberg-Marquardt could not reduce the cost further".into());
                break;
            }
            continue;
        }
        mu *= 0.1;
        *state = trial;
        *normal = trial_normal;
        if refresh && !damped {
            match Reduced::new(prob, normal, z, scale, 0.0) {
                Ok(r) => factor = r,
                Err(_) => warnings
                    .push("a refreshed normal matrix was not positive definite; the previous one was kept".into()),
            }
        }
        // Converged when the step is negligible, or when steps have stopped shrinking twice in a
        // row while already far below the uncertainty: the floating-point floor (the readings'
        // rounding, ~1e-16 m, amplified by the squared conditioning: 1e-5 to 1e-3 sigma).
        stalls = if ratio > 0.5 { stalls + 1 } else { 0 };
        last_step = step.max_sigma_ratio;
        if step.max_sigma_ratio < opts.tolerance || (stalls >= 2 && step.max_sigma_ratio < 1e-2) {
            converged = true;
            break;
        }
    }
    LmRun { iterations, converged, factor, warnings, damped }
}

fn init_station(obs: &Observations, st: u32) -> Result<Point3<f64>, SolveError> {
    let mut pts = Vec::new();
    let mut ls = Vec::new();
    // Each path has its own dead path; use the path with most points for the closed form.
    let groups: Vec<&LineGroup> =
        obs.groups_of(ObsKind::Range).filter(|(_, g)| g.station == st).map(|(_, g)| g).collect();
    let best = groups.iter().max_by_key(|g| g.len()).unwrap();
    for i in best.range() {
        pts.push(obs.x[i] + obs.p[i]);
        ls.push(obs.l[i]);
    }
    multilaterate(&pts, &ls).map(|s| s.position).ok_or_else(|| SolveError::Station {
        station: st,
        reason: format!("its {} points do not determine a position (at least 5 points, not coplanar, are needed for the closed-form start)", pts.len()),
    })
}

/// Summary of the data that the identifiability report needs.
fn prob_summary(p: &Problem<'_>) -> identify::DataSummary {
    let mut offsets: Vec<Vector3<f64>> = Vec::new();
    for g in &p.obs.groups {
        let v = p.obs.p[g.start];
        if !offsets.iter().any(|o| (o - v).norm() < 1e-6) {
            offsets.push(v);
        }
    }
    let mut coverage = [[f64::INFINITY, f64::NEG_INFINITY]; 3];
    for x in &p.obs.x {
        for a in 0..3 {
            coverage[a][0] = coverage[a][0].min(x[a]);
            coverage[a][1] = coverage[a][1].max(x[a]);
        }
    }
    identify::DataSummary {
        coverage,
        gauge: p.gauge,
        probe_offsets: offsets,
        n_beams: p.obs.groups_of(ObsKind::Beam).count(),
        n_stations: p.dims.stations.len(),
        n_effect_params: p.dims.n_e,
        effect_col: p.dims.effect_col(),
        station_col: p.dims.n_u,
        axis_positions: identify::DataSummary::positions_of(&p.obs.x),
        readings_in_station_plane: 0,
        horizon_m: p.horizon_m,
    }
}

/// The linearisation horizon of the readings taking part (see `identify::beyond_horizon`),
/// from the travel's diagonal and their median noise.
fn horizon(p: &Problem<'_>) -> f64 {
    let mut sigma: Vec<f64> = (0..p.obs.groups.len())
        .filter(|&g| p.active[g])
        .flat_map(|g| p.obs.groups[g].range())
        .map(|i| p.sigma[i])
        .collect();
    if sigma.is_empty() {
        return 0.0;
    }
    sigma.sort_by(f64::total_cmp);
    (2.0 * p.layout.travel.diagonal() * sigma[sigma.len() / 2] * identify::HORIZON_NOISE_FRACTION).sqrt()
        / identify::HORIZON_COVERAGE
}

/// Geometry of the tracer stations at the current iterate and of the points they measured.
fn tracer_geometry(p: &Problem<'_>, s: &State) -> crate::station_geometry::StationGeometry {
    let stations: Vec<Point3<f64>> = (0..p.dims.stations.len())
        .map(|k| {
            let c = p.dims.station_col(k);
            Point3::new(s.d[c], s.d[c + 1], s.d[c + 2])
        })
        .collect();
    let points: Vec<Point3<f64>> =
        p.obs.groups_of(ObsKind::Range).flat_map(|(_, g)| g.range()).map(|i| p.obs.x[i] + p.obs.p[i]).collect();
    crate::station_geometry::assess(&stations, &points)
}

/// Identifiability analysis at a linearisation (`identify::analyse`), with the geometry of the
/// tracer stations of that state added to the report.
#[allow(clippy::too_many_arguments)]
fn analyse_at(
    prob: &Problem<'_>,
    state: &State,
    n: &Mat<f64>,
    m: &Mat<f64>,
    m_llt: Option<&faer::linalg::solvers::Llt<f64>>,
    z: &NullSpace,
    scale: &[f64],
    tol: f64,
) -> identify::Analysis {
    let geometry = (!prob.dims.stations.is_empty()).then(|| tracer_geometry(prob, state));
    let mut summary = prob_summary(prob);
    summary.readings_in_station_plane = geometry.as_ref().map_or(0, |g| g.readings_in_plane);
    let mut ident = identify::analyse(prob.layout, &summary, n, m, m_llt, z, scale, &prob.displacement, tol);
    if let Some(geometry) = geometry {
        let said = geometry.statements();
        if !said.is_empty() {
            ident.report.warnings.push(format!(
                "tracer station geometry: {} station(s){} (see the identifiability report)",
                geometry.n_stations,
                if geometry.coplanar && geometry.n_stations >= crate::station_geometry::MIN_STATIONS {
                    ", coplanar"
                } else {
                    ""
                }
            ));
        }
        ident.report.statements.extend(said.iter().cloned());
        ident.appended.extend(said);
    }
    ident
}

/// Actual reflector position of reading `i` at the current iterate.
fn actual_point(_p: &Problem<'_>, s: &State, i: usize) -> Point3<f64> {
    s.actual[i]
}

/// Recomputes the actual reflector positions by the exact kinematic chain (the small-angle
/// sensitivity serves as the Jacobian only) and re-estimates the beam directions from them
/// (patent: the least-squares line of the machine points), or, for beams aligned with the
/// commanded line, takes the least-squares line of the commanded reflector points.
fn update_directions(p: &Problem<'_>, s: &mut State) {
    let chain = crate::kinematics::Chain::new(p.layout, &s.d[..p.dims.n_u]);
    let (actual, frames): (Vec<_>, Vec<_>) = (0..p.obs.len())
        .map(|i| match &p.structure {
            // The basis values at the readings' coordinates do not change during a solve.
            Some(st) => chain.position_with_frames_cached(
                &p.obs.x[i],
                &p.obs.p[i],
                std::array::from_fn(|a| (st.first[i][a], st.b(i, a))),
            ),
            None => chain.position_with_frames(&p.obs.x[i], &p.obs.p[i]),
        })
        .unzip();
    s.actual = actual;
    s.frames = frames;
    for (gi, g) in p.obs.groups.iter().enumerate() {
        if g.kind != ObsKind::Beam || p.dir_owner[gi] != gi {
            continue;
        }
        let members: Vec<usize> = (0..p.obs.groups.len()).filter(|&k| p.dir_owner[k] == gi).collect();
        let segments: Vec<Vec<Point3<f64>>> = members
            .iter()
            .map(|&k| {
                p.obs.groups[k]
                    .range()
                    .map(|i| match p.beam_alignment {
                        BeamAlignment::Motion => actual_point(p, s, i),
                        BeamAlignment::Commanded => p.obs.x[i] + p.obs.p[i],
                    })
                    .collect()
            })
            .collect();
        let pts = centred_segments(&segments);
        // Each segment's readings about their own mean, as its points.
        let ls: Vec<f64> = members
            .iter()
            .flat_map(|&k| {
                let l = &p.obs.l[p.obs.groups[k].range()];
                let lm = l.iter().sum::<f64>() / l.len() as f64;
                l.iter().map(move |v| v - lm)
            })
            .collect();
        let dir = orient_with_readings(fit_line(&pts).direction, &pts, &ls);
        for &k in &members {
            s.dirs[k] = dir;
        }
    }
}

/// Direction along which reading `i` of group `gi` increases, and its predicted value (without
/// the group origin).
fn predict_reading(p: &Problem<'_>, s: &State, gi: usize, i: usize) -> (Vector3<f64>, f64, Point3<f64>) {
    let pa = actual_point(p, s, i);
    match p.obs.groups[gi].kind {
        ObsKind::Beam => {
            let n = s.dirs[gi];
            (n, n.dot(&pa.coords), pa)
        }
        ObsKind::Range => {
            let c = p.dims.station_col(p.group_station[gi]);
            let q = Point3::new(s.d[c], s.d[c + 1], s.d[c + 2]);
            let v = pa - q;
            let r = v.norm();
            (v / r, r, pa)
        }
    }
}

/// Residual of reading `i` (reading minus prediction, without the group origin) and the
/// direction along which the reading increases; `ebuf` receives the effects' regressors.
fn residual(p: &Problem<'_>, s: &State, gi: usize, i: usize, ebuf: &mut Vec<f64>) -> (f64, Vector3<f64>) {
    let (dir, mut f, actual) = predict_reading(p, s, gi, i);
    ebuf.clear();
    if p.dims.n_e > 0 {
        let ctx = ObsContext { obs: p.obs, i, group: &p.obs.groups[gi], direction: dir, actual };
        let mut col = p.dims.effect_col();
        for (e, &k) in p.effects.iter().zip(&p.dims.effect_sizes) {
            let start = ebuf.len();
            ebuf.resize(start + k, 0.0);
            e.regressors(&ctx, &mut ebuf[start..]);
            for &v in &ebuf[start..] {
                f += v * s.d[col];
                col += 1;
            }
        }
    }
    (p.obs.l[i] - f, dir)
}

/// Calls `emit(column, value)` for every entry of the row of reading `i` with direction `dir`,
/// in increasing column order: for each axis the exact derivatives of `n . P` with respect to
/// its six error values times the basis values of its functions; the squareness errors; the
/// station coordinates (ranges); the effects' regressors (given in `ebuf`).
#[inline]
fn for_each_entry(
    p: &Problem<'_>,
    s: &State,
    gi: usize,
    i: usize,
    dir: &Vector3<f64>,
    ebuf: &[f64],
    mut emit: impl FnMut(usize, f64),
) {
    let x = &p.obs.x[i];
    for a in 0..3 {
        let d = s.frames[i][a].projected(dir);
        for (f, &df) in d.iter().enumerate() {
            let off = p.layout.offsets[a * 6 + f];
            match &p.structure {
                Some(st) => {
                    let col = off + st.first[i][a];
                    for (k, &bk) in st.b(i, a).iter().enumerate() {
                        emit(col + k, df * bk);
                    }
                }
                None => p.layout.bases[a * 6 + f].visit(x[a], false, |k, bk| emit(off + k, df * bk)),
            }
        }
    }
    for sq in crate::functions::Squareness::ALL {
        let a = sq.axis();
        emit(p.layout.squareness_index(sq), s.frames[i][a.index()].projected_squareness(dir, sq, a.coord(x)));
    }
    if p.obs.groups[gi].kind == ObsKind::Range {
        let c = p.dims.station_col(p.group_station[gi]);
        for k in 0..3 {
            emit(c + k, -dir[k]);
        }
    }
    let col = p.dims.effect_col();
    for (k, &v) in ebuf.iter().enumerate() {
        emit(col + k, v);
    }
}

/// Builds the sparse row of reading `i` (sorted column indices); returns its residual and the
/// direction along which the reading increases.
fn row(
    p: &Problem<'_>,
    s: &State,
    gi: usize,
    i: usize,
    idx: &mut Vec<usize>,
    val: &mut Vec<f64>,
    ebuf: &mut Vec<f64>,
) -> (f64, Vector3<f64>) {
    idx.clear();
    val.clear();
    let (r, dir) = residual(p, s, gi, i, ebuf);
    for_each_entry(p, s, gi, i, &dir, ebuf, |k, v| {
        idx.push(k);
        val.push(v);
    });
    (r, dir)
}

/// The gradient `b`, the cost and the centred residuals at a state, without the normal matrix
/// (the frozen-matrix iterations need only these).
fn gradient(p: &Problem<'_>, s: &State) -> Normal {
    let n = p.dims.n();
    let mut b = vec![0.0; n];
    let mut res = Residuals { residual: vec![0.0; p.obs.len()], origin: vec![0.0; p.obs.groups.len()] };
    let mut cost = 0.0;
    let mut ebuf = Vec::new();
    let mut dirs: Vec<Vector3<f64>> = Vec::new();
    let mut regs: Vec<f64> = Vec::new();
    for (gi, g) in p.obs.groups.iter().enumerate() {
        if !p.active[gi] {
            continue;
        }
        dirs.clear();
        regs.clear();
        let (mut wsum, mut wr) = (0.0, 0.0);
        for i in g.range() {
            let (r, dir) = residual(p, s, gi, i, &mut ebuf);
            let w = 1.0 / (p.sigma[i] * p.sigma[i]);
            res.residual[i] = r;
            dirs.push(dir);
            regs.extend_from_slice(&ebuf);
            wsum += w;
            wr += w * r;
        }
        let rm = wr / wsum;
        res.origin[gi] = rm;
        let ne = p.dims.n_e;
        for (j, i) in g.range().enumerate() {
            let rc = res.residual[i] - rm;
            res.residual[i] = rc;
            let w = 1.0 / (p.sigma[i] * p.sigma[i]);
            cost += w * rc * rc;
            let wr = w * rc;
            for_each_entry(p, s, gi, i, &dirs[j], &regs[j * ne..(j + 1) * ne], |k, v| b[k] += wr * v);
        }
    }
    let chi2 = cost;
    let cost = chi2 + penalise(p, s, &mut b);
    Normal { n: Mat::zeros(0, 0), b, cost, chi2, res }
}

/// Assembles the normal equations, eliminating each group's origin. Residuals are centred per
/// group before they enter `b` and the cost, so the large arbitrary origins of the readings never
/// meet the small residuals in one sum.
fn assemble(p: &Problem<'_>, s: &State) -> Normal {
    let with_matrix = true;
    let mut res = Residuals { residual: vec![0.0; p.obs.len()], origin: vec![0.0; p.obs.groups.len()] };
    let n = p.dims.n();
    let ng = p.obs.groups.len();
    let mut upper = normal::Upper::new(if with_matrix { n } else { 0 });
    let mut b = vec![0.0; n];
    // Weighted column sums per group, scaled by 1/sqrt(W): N -= S S^T.
    let mut smat = if with_matrix { Mat::<f64>::zeros(n, ng) } else { Mat::zeros(0, 0) };
    let mut gsum = vec![0.0; n];
    let mut is_touched = vec![false; n];
    let mut touched: Vec<usize> = Vec::new();
    let (mut idx, mut val, mut ebuf) = (Vec::with_capacity(128), Vec::with_capacity(128), Vec::new());
    // Rows of the current group: (start offset into idx/val buffers, residual, weight).
    let mut rows: Vec<(usize, usize, f64, f64)> = Vec::new();
    let mut runs: Vec<normal::Run> = Vec::new();
    let mut tmp_runs: Vec<normal::Run> = Vec::new();
    let mut batch: Vec<(f64, std::ops::Range<usize>)> = Vec::new();
    let mut srows: Vec<normal::StructuredRow<'_>> = Vec::new();
    let mut rowobs: Vec<usize> = Vec::new();
    let mut dirs_of_rows: Vec<Vector3<f64>> = Vec::new();
    let (mut gidx, mut gval): (Vec<usize>, Vec<f64>) = (Vec::new(), Vec::new());
    let mut cost = 0.0;
    for (gi, g) in p.obs.groups.iter().enumerate() {
        if !p.active[gi] {
            continue;
        }
        rows.clear();
        gidx.clear();
        gval.clear();
        let (mut wsum, mut wr) = (0.0, 0.0);
        rowobs.clear();
        dirs_of_rows.clear();
        let mut rows_seen = 0usize;
        for i in g.range() {
            let (r, dir) = row(p, s, gi, i, &mut idx, &mut val, &mut ebuf);
            let w = 1.0 / (p.sigma[i] * p.sigma[i]);
            rowobs.push(i);
            dirs_of_rows.push(dir);
            rows.push((gidx.len(), idx.len(), r, w));
            gidx.extend_from_slice(&idx);
            gval.extend_from_slice(&val);
            wsum += w;
            wr += w * r;
        }
        let rm = wr / wsum;
        res.origin[gi] = rm;
        for (&(start, len, r, w), &i) in rows.iter().zip(&rowobs) {
            let rc = r - rm;
            res.residual[i] = rc;
            cost += w * rc * rc;
            let ri = &gidx[start..start + len];
            let rv = &gval[start..start + len];
            for a in 0..len {
                b[ri[a]] += w * rv[a] * rc;
            }
            if !with_matrix {
                continue;
            }
            for a in 0..len {
                let ia = ri[a];
                // An explicit marker: a running sum can cancel to exactly zero mid-group.
                if !is_touched[ia] {
                    is_touched[ia] = true;
                    touched.push(ia);
                }
                gsum[ia] += w * rv[a];
            }
            if let Some(st) = &p.structure {
                let i = rowobs[rows_seen];
                let dir = dirs_of_rows[rows_seen];
                let n_sq = p.layout.n_params - 3;
                let axes: [normal::AxisSegment<'_>; 3] = std::array::from_fn(|a| normal::AxisSegment {
                    col: std::array::from_fn(|f| p.layout.offsets[a * 6 + f] + st.first[i][a]),
                    d: s.frames[i][a].projected(&dir),
                    b: st.b(i, a),
                });
                let extras: Vec<(usize, f64)> =
                    ri.iter().zip(rv).filter(|(&c, _)| c >= n_sq).map(|(&c, &v)| (c, v)).collect();
                srows.push(normal::StructuredRow { w, axes, extras });
            } else {
                let r0 = runs.len();
                normal::runs_of(ri, &mut tmp_runs);
                runs.extend(tmp_runs.iter().map(|r| normal::Run { at: r.at + start, ..*r }));
                batch.push((w, r0..runs.len()));
            }
            rows_seen += 1;
        }
        if with_matrix {
            if p.structure.is_some() {
                upper.add_structured_batch(&srows);
                srows.clear();
            } else {
                upper.add_batch(&batch, &runs, &gval);
                batch.clear();
                runs.clear();
            }
        }
        if with_matrix {
            let sw = wsum.sqrt();
            for &k in &touched {
                smat[(k, gi)] = gsum[k] / sw;
                gsum[k] = 0.0;
                is_touched[k] = false;
            }
            touched.clear();
        }
    }
    let mut nm = upper.to_mat();
    matmul(nm.as_mut(), Accum::Add, smat.as_ref(), smat.transpose(), -1.0, Par::Seq);
    // Eliminating the origins computes `sum w a^2 - (sum w a)^2 / W`, which cancels for a column
    // that is (nearly) constant within every line and leaves rounding noise of ~eps relative to
    // the raw sum; the Jacobi scaling would amplify it by raw / centred. A column whose centred
    // energy is below 1e-5 of its raw energy therefore carries no information this double-
    // precision solve can resolve (the noise left elsewhere is then below 2e-11, under the rank
    // tolerance): it is set exactly to zero, and the identifiability report names it.
    // Likewise a model column whose centred energy is below 1e-10 of its reference energy (the
    // energy it would have at its nominal first-order sensitivity: a sensitivity below 1e-5 of
    // nominal, e.g. a beam orthogonal to a function up to rounding or seen only at second order)
    // is not observed; the Jacobi scaling would otherwise promote it to information.
    for k in 0..n {
        let raw = upper.data[k * n + k];
        let weak = k < p.ref_energy.len() && nm[(k, k)] <= NOMINAL_FLOOR * p.ref_energy[k];
        if nm[(k, k)] <= CENTRED_FLOOR * raw || weak {
            for j in 0..n {
                nm[(k, j)] = 0.0;
                nm[(j, k)] = 0.0;
            }
        }
    }
    let chi2 = cost;
    let cost = chi2 + penalise(p, s, &mut b);
    Normal { n: nm, b, cost, chi2, res }
}

/// Adds the roughness penalty's part to the gradient `b` and returns its cost (0 without one).
fn penalise(p: &Problem<'_>, s: &State, b: &mut [f64]) -> f64 {
    let n_u = p.dims.n_u;
    p.penalty.as_ref().map_or(0.0, |pen| pen.apply(&s.d[..n_u], &mut b[..n_u]))
}

/// Centred residuals and group origins at a state.
struct Residuals {
    residual: Vec<f64>,
    origin: Vec<f64>,
}

/// Jacobi scaling `s_k = sqrt(N_kk)` (1 for unobserved columns).
///
/// A parameter the readings inform only weakly is scaled as if they informed it to the
/// linearisation horizon (`floor`, from [`scale_floor`]; empty: none). Why: Jacobi scaling makes
/// every column's own information one, so an error the readings see only through a beam's
/// tilt of a few microradians (a straightness along an ISO 230-2 line) would weigh as much as
/// the positioning they measure. The minimum-norm choice along what they determine only in
/// combination would then put metres of straightness where micrometres of positioning fit,
/// far outside the linearisation (found on a campaign of reference lines alone).
fn column_scale(n: &Mat<f64>, floor: &[f64]) -> Vec<f64> {
    (0..n.nrows())
        .map(|k| if n[(k, k)] > 0.0 { n[(k, k)].sqrt().max(floor.get(k).copied().unwrap_or(0.0)) } else { 1.0 })
        .collect()
}

/// The information per unit of each parameter at which its standard uncertainty, as a
/// displacement, is the linearisation horizon (`identify::beyond_horizon`): the square root of
/// that information. Zero where there is no horizon (no readings, or noise-free ones).
fn scale_floor(p: &Problem<'_>) -> Vec<f64> {
    let h = p.horizon_m;
    if !(h > 0.0 && h.is_finite()) {
        return Vec::new();
    }
    let arm = p.layout.travel.diagonal() + p.obs.p.iter().map(|o| o.norm()).fold(0.0, f64::max);
    (0..p.dims.n())
        .map(|k| {
            // The largest displacement of a unit: a metre of translation, a radian over the
            // largest lever arm, a metre of station coordinate; effect parameters none.
            let unit = if k < p.dims.n_u {
                match p.layout.owner(k) {
                    crate::model::ParamOwner::Function(f, _) if f.motion == crate::functions::Motion::Translation => {
                        1.0
                    }
                    _ => arm,
                }
            } else if k < p.dims.effect_col() {
                1.0
            } else {
                0.0
            };
            unit / h
        })
        .collect()
}

/// Readings sampled for [`displacement_gram`]: enough for a mean over smooth functions of the
/// position (a few per beam of the patent's plan), few enough to cost about a millisecond.
const DISPLACEMENT_SAMPLES: usize = 200;

/// The mean square displacement of the reflector over the readings taking part, per pair of
/// parameters: `G = mean_i S_i^T S_i` with `S_i` the sensitivity of the reflector's position at
/// reading `i` (`dim x dim`, unscaled). A tracer station's coordinates displace its ranges as
/// the reflector does; effect parameters are not displacements. Every k-th reading, at most
/// [`DISPLACEMENT_SAMPLES`] of them. Why: what the linearisation horizon bounds is how far the
/// reflector moves where it was read (`identify::beyond_horizon`), not the coefficients: a
/// direction that trades an angle against a straightness can be large in both and move the
/// reflector little.
fn displacement_gram(p: &Problem<'_>) -> Mat<f64> {
    let n = p.dims.n();
    let mut g = Mat::<f64>::zeros(n, n);
    let readings: Vec<usize> =
        (0..p.obs.groups.len()).filter(|&k| p.active[k]).flat_map(|k| p.obs.groups[k].range()).collect();
    let stride = readings.len().div_ceil(DISPLACEMENT_SAMPLES).max(1);
    let mut s = crate::model::Sensitivity::default();
    let mut count = 0usize;
    for &i in readings.iter().step_by(stride) {
        p.layout.sensitivity_into(&p.obs.x[i], &p.obs.p[i], &mut s);
        for (&a, da) in s.idx.iter().zip(&s.dedu) {
            for (&b, db) in s.idx.iter().zip(&s.dedu) {
                g[(a, b)] += da.dot(db);
            }
        }
        count += 1;
    }
    if count > 0 {
        g = &g * (1.0 / count as f64);
    }
    for k in p.dims.n_u..p.dims.effect_col() {
        g[(k, k)] = 1.0;
    }
    g
}

/// Embeds a constraint block on `u` into the full parameter space.
fn embed(c: &Mat<f64>, n: usize) -> Mat<f64> {
    Mat::from_fn(c.nrows(), n, |i, j| if j < c.ncols() { c[(i, j)] } else { 0.0 })
}

fn stack_rows(a: &Mat<f64>, b: &Mat<f64>) -> Mat<f64> {
    Mat::from_fn(a.nrows() + b.nrows(), a.ncols(), |i, j| if i < a.nrows() { a[(i, j)] } else { b[(i - a.nrows(), j)] })
}

struct Step {
    delta: Vec<f64>,
    /// Largest |step| relative to the parameter's standard uncertainty.
    max_sigma_ratio: f64,
}

/// Reduced matrix `Z^T N_s Z` in scaled coordinates, with the roughness penalty `pen` added to
/// `N` when given.
fn reduced_matrix(normal: &Normal, z: &NullSpace, scale: &[f64], pen: Option<&Penalty>) -> Mat<f64> {
    let n = scale.len();
    let mut ns = Mat::from_fn(n, n, |i, j| normal.n[(i, j)] / (scale[i] * scale[j]));
    if let Some(pen) = pen {
        pen.add_scaled(&mut ns, scale);
    }
    z.project(&ns)
}

/// The square root of a covariance's diagonal entry. A variance is never negative; one that
/// rounding took below zero (a parameter the fit pins to the rounding level, e.g. a tracer
/// station a gross reading pushed kilometres away in a fit that did not converge) is zero, not
/// NaN: a NaN would be written to the model file as `null`, which no command could then load.
fn standard_uncertainty(variance: f64) -> f64 {
    variance.max(0.0).sqrt()
}

/// Cholesky factor of the (damped) reduced matrix.
struct Reduced {
    llt: faer::linalg::solvers::Llt<f64>,
}

impl Reduced {
    /// Factor of the reduced matrix of `normal` with the penalty of `prob` and damping `mu`.
    fn new(prob: &Problem<'_>, normal: &Normal, z: &NullSpace, scale: &[f64], mu: f64) -> Result<Reduced, SolveError> {
        Reduced::from_matrix(reduced_matrix(normal, z, scale, prob.penalty.as_ref()), mu)
    }

    /// Undamped, at a solution; a tiny damping if rounding makes it indefinite.
    fn at_solution(prob: &Problem<'_>, normal: &Normal, z: &NullSpace, scale: &[f64]) -> Result<Reduced, SolveError> {
        Reduced::new(prob, normal, z, scale, 0.0).or_else(|_| Reduced::new(prob, normal, z, scale, 1e-12))
    }

    fn from_matrix(mut m: Mat<f64>, mu: f64) -> Result<Reduced, SolveError> {
        if mu > 0.0 {
            for i in 0..m.nrows() {
                let d = m[(i, i)];
                m[(i, i)] = d + mu * d.max(1e-12);
            }
        }
        let n = m.nrows();
        let llt = m.llt(Side::Lower).map_err(|e| {
            SolveError::Singular(match e {
                faer::linalg::solvers::LltError::NonPositivePivot { index } => {
                    format!("pivot {} of the {n} free directions not positive", index + 1)
                }
                #[allow(unreachable_patterns)]
                other => format!("{other:?}"),
            })
        })?;
        Ok(Reduced { llt })
    }
}

fn reduced_step(red: &Reduced, normal: &Normal, z: &NullSpace, scale: &[f64]) -> Step {
    let n = scale.len();
    let bs = Mat::from_fn(n, 1, |i, _| normal.b[i] / scale[i]);
    let mut y = z.zt(&bs);
    red.llt.solve_in_place(y.as_mut());
    let ds = z.z(&y);
    // In scaled coordinates a unit step is one conditional standard uncertainty.
    let max_ratio = (0..n).map(|i| ds[(i, 0)].abs()).fold(0.0, f64::max);
    Step { delta: (0..n).map(|i| ds[(i, 0)] / scale[i]).collect(), max_sigma_ratio: max_ratio }
}

/// Smallest resolvable ratio of a column's centred to raw energy (see `assemble`).
const CENTRED_FLOOR: f64 = 1e-5;
/// Smallest ratio of a model column's energy to its reference energy (see `reference_energy`).
const NOMINAL_FLOOR: f64 = 1e-10;

/// Energy of each model column at its nominal first-order sensitivity: per reading, the basis
/// value times 1 (translations), the reach of the machine (rotations: travel diagonal plus the
/// largest probe offset) or the axis coordinate (squareness), squared and weighted.
fn reference_energy(
    layout: &ModelLayout,
    obs: &Observations,
    structure: Option<&Structure>,
    sigma: &[f64],
    active: &[bool],
) -> Vec<f64> {
    use crate::axis::Axis;
    use crate::functions::{ErrorFunction, Motion, Squareness};
    let t = &layout.travel;
    let diag = (t.length(Axis::X).powi(2) + t.length(Axis::Y).powi(2) + t.length(Axis::Z).powi(2)).sqrt();
    let reach = diag + obs.p.iter().map(|p| p.norm()).fold(0.0, f64::max);
    let typ = |f: ErrorFunction| if f.motion == Motion::Translation { 1.0 } else { reach };
    // The six functions of an axis usually share one basis: its values are computed once.
    let shared = Axis::ALL.map(|a| layout.shares_basis(a));
    let mut e = vec![0.0; layout.n_params];
    for i in obs.groups.iter().enumerate().filter(|(g, _)| active[*g]).flat_map(|(_, g)| g.range()) {
        let w = 1.0 / (sigma[i] * sigma[i]);
        for a in Axis::ALL {
            let functions = (0..6).map(|m| ErrorFunction::from_index(a.index() * 6 + m));
            let q = a.coord(&obs.x[i]);
            if shared[a.index()] {
                let mut add = |k: usize, b: f64| {
                    for f in functions.clone() {
                        e[layout.offsets[f.index()] + k] += w * (typ(f) * b).powi(2);
                    }
                };
                match structure {
                    // The values the solve keeps for every reading.
                    Some(st) => {
                        let first = st.first[i][a.index()];
                        st.b(i, a.index()).iter().enumerate().for_each(|(k, &b)| add(first + k, b));
                    }
                    None => layout.bases[a.index() * 6].visit(q, false, add),
                }
            } else {
                for f in functions {
                    let off = layout.offsets[f.index()];
                    layout.basis(f).visit(q, false, |k, b| e[off + k] += w * (typ(f) * b).powi(2));
                }
            }
        }
        for s in Squareness::ALL {
            e[layout.squareness_index(s)] += w * s.axis().coord(&obs.x[i]).powi(2);
        }
    }
    e
}

/// Number of gauge freedoms (re-exported for reports).
pub const GAUGE_FREEDOMS: usize = GAUGE_DIM;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::axis::Travel;
    use crate::campaign::{prepare, Campaign, CampaignMeta, Reading, ScaleExpansion};
    use crate::repr::Representation;
    use crate::topology::Topology;

    /// Lines parallel to X (a degenerate, symmetric geometry) with arbitrary readings.
    fn problem_data() -> (ModelLayout, Observations) {
        let layout = ModelLayout::uniform(
            Topology::parse("FXYZ").unwrap(),
            Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]),
            Representation::BSpline { intervals: 5 },
        );
        let mut readings = Vec::new();
        for (line, (y, z)) in [(0.1, -0.5), (0.4, -0.3), (0.7, -0.1)].into_iter().enumerate() {
            for k in 0..15 {
                let x = 0.05 + 0.9 * k as f64 / 14.0;
                readings.push(Reading {
                    kind: ObsKind::Beam,
                    station: 0,
                    line: line as u32,
                    t_s: k as f64,
                    l_m: x + 1e-6 * ((k * 7 + line) % 5) as f64,
                    x: Point3::new(x, y, z),
                    p: Vector3::new(0.0, 0.0, -0.1),
                    air: None,
                    machine_temp_c: None,
                    velocity: None,
                    beam_broken: false,
                    source_line: 0,
                });
            }
        }
        let c = Campaign { meta: CampaignMeta::default(), readings };
        let p = prepare(&c, &layout.travel, &ScaleExpansion::default()).unwrap();
        (layout, p.obs)
    }

    #[test]
    fn assembly_matches_brute_force() {
        let (layout, obs) = problem_data();
        let dims = Dims { n_u: layout.n_params, stations: Vec::new(), n_e: 0, effect_sizes: Vec::new() };
        let n = dims.n();
        let prob = Problem {
            layout: &layout,
            gauge: Gauge::Patent,
            obs: &obs,
            dims,
            effects: &[],
            group_station: vec![usize::MAX; obs.groups.len()],
            dir_owner: (0..obs.groups.len()).collect(),
            sigma: vec![1e-7; obs.len()],
            structure: Structure::new(&layout, &obs),
            ref_energy: Vec::new(),
            active: vec![true; obs.groups.len()],
            penalty: None,
            beam_alignment: BeamAlignment::Motion,
            horizon_m: 0.0,
            scale_floor: Vec::new(),
            displacement: Mat::zeros(0, 0),
        };
        assert!(prob.structure.is_some());
        let mut st = State {
            d: vec![0.0; n],
            dirs: vec![Vector3::zeros(); obs.groups.len()],
            actual: Vec::new(),
            frames: Vec::new(),
        };
        update_directions(&prob, &mut st);
        let fast = assemble(&prob, &st);
        let mut dense = Mat::<f64>::zeros(n, n);
        let (mut idx, mut val, mut eb) = (Vec::new(), Vec::new(), Vec::new());
        for (gi, g) in obs.groups.iter().enumerate() {
            let mut rows = Vec::new();
            for i in g.range() {
                row(&prob, &st, gi, i, &mut idx, &mut val, &mut eb);
                let mut a = vec![0.0; n];
                for (&k, &v) in idx.iter().zip(&val) {
                    a[k] += v;
                }
                rows.push(a);
            }
            let w = 1.0 / (1e-7 * 1e-7);
            let mean: Vec<f64> = (0..n).map(|k| rows.iter().map(|r| r[k]).sum::<f64>() / rows.len() as f64).collect();
            for r in &rows {
                for i in 0..n {
                    for j in 0..n {
                        dense[(i, j)] += w * (r[i] - mean[i]) * (r[j] - mean[j]);
                    }
                }
            }
        }
        let ev = fast.n.self_adjoint_eigenvalues(Side::Lower).unwrap();
        let emax = ev.iter().cloned().fold(0.0, f64::max);
        assert!(ev[0] > -1e-10 * emax, "normal matrix not PSD: {} relative", ev[0] / emax);
        let sc = column_scale(&fast.n, &[]);
        let z = NullSpace::new(&embed(&gauge::constraints(&layout, Gauge::Patent), n), &sc);
        let m = reduced_matrix(&fast, &z, &sc, None);
        let evm = m.self_adjoint_eigenvalues(Side::Lower).unwrap();
        let mmax = evm.iter().cloned().fold(0.0, f64::max);
        assert!(evm[0] > -1e-10 * mmax, "reduced matrix not PSD: {} relative", evm[0] / mmax);
        let scale = (0..n).map(|i| dense[(i, i)]).fold(0.0, f64::max);
        for i in 0..n {
            for j in 0..n {
                assert!(
                    (fast.n[(i, j)] - dense[(i, j)]).abs() < 1e-9 * scale,
                    "({i}, {j}): {} vs {}",
                    fast.n[(i, j)],
                    dense[(i, j)]
                );
            }
        }
    }

    /// The structured (tiled) assembly equals the dense normal matrix `sum (a - mean)(a -
    /// mean)^T` per group for tracer ranges too, with rows that carry exact zeros: readings
    /// exactly at table nodes and at z = 0, where the lever arm of X vanishes (the paper's
    /// tracer path is full of both).
    #[test]
    fn range_assembly_matches_dense_with_exact_zeros() {
        use crate::campaign::LineGroup;
        let layout = ModelLayout::uniform(
            Topology::parse("FYXZ").unwrap(),
            Travel::new([0.0, 0.7], [-0.5, 0.0], [-0.7, 0.0]),
            Representation::Table { nodes: 11 },
        );
        let q = [Point3::new(-0.1, -0.6, -0.8), Point3::new(0.8, 0.1, -0.6)];
        let mut obs = Observations::default();
        for (s, qq) in q.iter().enumerate() {
            let start = obs.len();
            for i in 0..=20 {
                let x = Point3::new(0.035 * i as f64, -0.05 * (i % 11) as f64, -0.35 * (i % 3) as f64);
                obs.x.push(x);
                obs.p.push(Vector3::zeros());
                obs.l.push((x - qq).norm());
                obs.t.push(0.0);
                obs.velocity.push(None);
                obs.air.push(None);
                obs.reading.push(obs.reading.len());
            }
            let g = LineGroup { kind: ObsKind::Range, station: s as u32, line: 0, segment: 0, start, end: obs.len() };
            obs.groups.push(g);
        }
        let stations = obs.stations(ObsKind::Range);
        let prob = Problem {
            layout: &layout,
            gauge: Gauge::Datum,
            obs: &obs,
            dims: Dims { n_u: layout.n_params, stations, n_e: 0, effect_sizes: Vec::new() },
            effects: &[],
            group_station: vec![0, 1],
            dir_owner: vec![0, 1],
            sigma: vec![1.0; obs.len()],
            structure: Structure::new(&layout, &obs),
            ref_energy: Vec::new(),
            active: vec![true; obs.groups.len()],
            penalty: None,
            beam_alignment: BeamAlignment::Motion,
            horizon_m: 0.0,
            scale_floor: Vec::new(),
            displacement: Mat::zeros(0, 0),
        };
        assert!(prob.structure.is_some());
        let n = prob.dims.n();
        let mut d = vec![0.0; n];
        for (s, qq) in q.iter().enumerate() {
            for k in 0..3 {
                d[prob.dims.station_col(s) + k] = qq[k];
            }
        }
        let mut state = State { d, dirs: vec![Vector3::zeros(); 2], actual: Vec::new(), frames: Vec::new() };
        update_directions(&prob, &mut state);
        let got = assemble(&prob, &state).n;
        let mut dense = Mat::<f64>::zeros(n, n);
        for (s, qq) in q.iter().enumerate() {
            let rows: Vec<Vec<f64>> = obs.groups[s]
                .range()
                .map(|i| {
                    let dir = (obs.x[i] - qq).normalize();
                    let mut r = vec![0.0; n];
                    for (k, v) in layout.sensitivity(&obs.x[i], &obs.p[i]).project(&dir) {
                        r[k] += v;
                    }
                    for k in 0..3 {
                        r[prob.dims.station_col(s) + k] = -dir[k];
                    }
                    r
                })
                .collect();
            let mean: Vec<f64> = (0..n).map(|c| rows.iter().map(|r| r[c]).sum::<f64>() / rows.len() as f64).collect();
            for r in &rows {
                for i in 0..n {
                    for j in 0..n {
                        dense[(i, j)] += (r[i] - mean[i]) * (r[j] - mean[j]);
                    }
                }
            }
        }
        for i in 0..n {
            for j in 0..n {
                assert!(
                    (got[(i, j)] - dense[(i, j)]).abs() < 1e-12,
                    "({i}, {j}): {} vs {}",
                    got[(i, j)],
                    dense[(i, j)]
                );
            }
        }
    }
}
