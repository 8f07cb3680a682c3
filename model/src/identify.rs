//! Identifiability: what the data determine, what the gauge fixes, and what is left undetermined.
//!
//! The analysis works on the normal matrix `N = J^T W J` with Jacobi scaling. It
//! 1. checks that the gauge constraints `C` fix exactly the 24 analytic gauge freedoms (`C N_g`
//!    non-singular) and that the data indeed do not observe them (Schur complement of `N` onto the
//!    model coefficients, evaluated along each freedom);
//! 2. takes the eigen-decomposition (the SVD of the scaled design) of `N` restricted to
//!    `C u = 0`; eigenvalues below `tol * max` span what the data cannot determine;
//! 3. groups that null space by function with the basis-independent projector `W W^T`: a function
//!    whose columns are all zero is *not observed*; functions coupled through the projector are
//!    only determined *in combination*;
//! 4. returns extra constraints that set the undetermined directions to zero (the minimum-norm
//!    choice), so the solve still returns everything the data do determine.

use crate::functions::{ErrorFunction, Motion, Squareness};
use crate::gauge::{self, GAUGE_DIM};
use crate::model::{ModelLayout, ParamOwner};
use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, Side};
use nalgebra::Vector3;

/// Facts about the data used to phrase the report.
#[derive(Clone, Debug, Default)]
pub struct DataSummary {
    pub gauge: gauge::Gauge,
    pub probe_offsets: Vec<Vector3<f64>>,
    pub n_beams: usize,
    pub n_stations: usize,
    pub n_effect_params: usize,
    pub effect_col: usize,
    pub station_col: usize,
    /// Range of the indicated coordinates of the readings, per axis.
    pub coverage: [[f64; 2]; 3],
    /// Distinct positions of each axis (X, Y, Z) where the data have readings, sorted, metres.
    pub axis_positions: [Vec<f64>; 3],
    /// Tracer readings that lie in the common plane of coplanar stations (see
    /// [`crate::station_geometry`]); 0 when the stations are not coplanar.
    pub readings_in_station_plane: usize,
    /// The linearisation horizon, metres (see [`beyond_horizon`]): a direction whose standard
    /// uncertainty, as a displacement of the reflector, exceeds it is not determined. 0: no
    /// such check.
    pub horizon_m: f64,
}

impl DataSummary {
    /// Distinct, sorted axis positions of a set of indicated points (to 0.1 um).
    pub fn positions_of(points: &[nalgebra::Point3<f64>]) -> [Vec<f64>; 3] {
        std::array::from_fn(|a| {
            let mut v: Vec<f64> = points.iter().map(|p| p[a]).collect();
            v.sort_by(|x, y| x.total_cmp(y));
            v.dedup_by(|x, y| (*x - *y).abs() < 1e-7);
            v
        })
    }
}

/// Whether the readings leave part of a function's basis without data: a local basis
/// function (table node, B-spline) whose support holds no reading, or a global basis with fewer
/// distinct positions than coefficients. `None` when positions are not known.
fn coverage_gap(layout: &ModelLayout, f: ErrorFunction, positions: &[f64]) -> Option<bool> {
    if positions.is_empty() {
        return None;
    }
    let b = layout.basis(f);
    let n = b.n_coeffs();
    match b.repr {
        crate::repr::Representation::Table { .. } | crate::repr::Representation::BSpline { .. } => {
            let mut seen = vec![false; n];
            for &q in positions {
                b.visit(q, false, |i, v| seen[i] |= v.abs() > 1e-9);
            }
            Some(seen.iter().any(|s| !s))
        }
        _ => Some(positions.len() < n),
    }
}

/// Positions as a short text in millimetres: all of them when few, else the span and count.
fn positions_text(positions: &[f64]) -> String {
    if positions.len() <= 6 {
        positions.iter().map(|q| format!("{:.0}", q * 1e3)).collect::<Vec<_>>().join(", ") + " mm"
    } else {
        format!(
            "{} positions from {:.0} to {:.0} mm",
            positions.len(),
            positions[0] * 1e3,
            positions[positions.len() - 1] * 1e3
        )
    }
}

/// The identifiability report of a solve.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Identifiability {
    /// Model coefficients.
    pub n_params: usize,
    /// Nuisance and effect parameters (stations, effects).
    pub n_other: usize,
    /// Gauge freedoms fixed by the constraints.
    pub gauge_dim: usize,
    /// Further directions the data do not determine (with smoothing: that neither the readings
    /// nor the roughness prior determine, the directions the model file keeps as undetermined).
    pub extra_null_dim: usize,
    /// Directions the readings alone leave open that the roughness prior of the smoothing
    /// determines (the curvature between the readings, with the prior's uncertainty); 0 without
    /// smoothing.
    pub prior_determined: usize,
    /// Rank of the design: parameters minus gauge minus extra null space.
    pub rank: usize,
    /// Condition number of the determined part (scaled).
    pub condition_number: f64,
    /// Smallest/largest singular value of `C N_g` (0 = constraints do not fix the gauge).
    pub constraint_conditioning: f64,
    /// Largest observability of a gauge freedom relative to the best-observed direction
    /// (should be ~0; large values mean the gauge constraint biases real information).
    pub gauge_observability: f64,
    /// Functions the data do not observe at all.
    pub not_observed: Vec<String>,
    /// Groups of functions (or effect parameters) determined only in combination.
    pub combinations: Vec<Vec<String>>,
    /// Error functions (of 21: 18 + 3 squareness) that are identified individually.
    pub identified_functions: usize,
    /// Plain statements for the report.
    pub statements: Vec<String>,
    pub warnings: Vec<String>,
}

/// Output of [`analyse`].
pub(crate) struct Analysis {
    pub report: Identifiability,
    /// Rows to append to the constraints (empty when everything is identifiable).
    pub extra_constraints: Mat<f64>,
    /// The undetermined directions themselves, unscaled (`dim x m`, columns `S^-1 w`).
    pub directions: Mat<f64>,
    /// The facts about the data the report was phrased with (for [`restate`]).
    pub summary: DataSummary,
    /// Statements the caller appended after the analysis's own (the tracer stations' geometry),
    /// kept when the report is restated.
    pub appended: Vec<String>,
    /// How many of the last columns of `directions` the readings inform, but only beyond the
    /// linearisation horizon ([`beyond_horizon`]).
    pub far: usize,
}

impl Analysis {
    /// An analysis that adds no constraint (`dim` parameters): everything is identifiable, or
    /// the analysis failed and says so in `report`.
    fn without_directions(report: Identifiability, dim: usize, summary: &DataSummary) -> Analysis {
        Analysis {
            report,
            extra_constraints: Mat::zeros(0, dim),
            directions: Mat::zeros(dim, 0),
            summary: summary.clone(),
            appended: Vec::new(),
            far: 0,
        }
    }
}

/// Threshold on a gauge freedom's observability (relative eigenvalue) above which it is
/// reported as observed by the data.
const GAUGE_OBSERVED: f64 = 1e-6;

/// Label of a parameter column beyond the model coefficients.
fn other_label(summary: &DataSummary, k: usize) -> String {
    if k >= summary.effect_col {
        format!("effect parameter {}", k - summary.effect_col)
    } else {
        format!("station {} coordinate", (k - summary.station_col) / 3)
    }
}

/// Runs the analysis on normal matrix `n` (all parameters), given the reduced scaled matrix
/// `m = Z^T N_s Z` (and its Cholesky factor when it has one) on the gauge-constrained subspace with orthonormal basis `z` (scaled
/// coordinates) and the Jacobi scaling `scale`.
pub(crate) fn analyse(
    layout: &ModelLayout,
    summary: &DataSummary,
    n: &Mat<f64>,
    m: &Mat<f64>,
    m_llt: Option<&faer::linalg::solvers::Llt<f64>>,
    z: &crate::nullspace::NullSpace,
    scale: &[f64],
    displacement: &Mat<f64>,
    tol: f64,
) -> Analysis {
    let gauge_basis = gauge::null_basis(layout);
    let cons = gauge::constraints(layout, summary.gauge);
    let dim = n.nrows();
    let n_u = layout.n_params;
    let mut report = Identifiability { n_params: n_u, n_other: dim - n_u, gauge_dim: GAUGE_DIM, ..Default::default() };
    report.constraint_conditioning = gauge::conditioning_of(&cons, &gauge_basis);

    // Fast path: a well-conditioned matrix is certified full rank from its Cholesky factor in
    // O(n^2) instead of the O(n^3) eigen-decomposition.
    if let Some((cond, llt)) = m_llt.and_then(|l| certified_full_rank(m, l, tol).map(|c| (c, l))) {
        report.condition_number = cond;
        report.rank = z.dim();
        let w = beyond_horizon(summary, displacement, z, scale, None, llt.L());
        let lmax = lambda_max_estimate(m);
        return finish(layout, summary, n, lmax, &gauge_basis, Mat::zeros(dim, 0), w, scale, displacement, report);
    }
    // Eigenvalues (the singular values of the scaled, constrained design, squared);
    // eigenvectors only when something is undetermined.
    let lam = match m.self_adjoint_eigenvalues(Side::Lower) {
        Ok(l) => l,
        Err(e) => {
            report.warnings.push(format!("identifiability analysis failed: {e:?}"));
            return Analysis::without_directions(report, dim, summary);
        }
    };
    let lmax = lam.iter().cloned().fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    let null_count = lam.iter().filter(|&&l| l < tol * lmax).count();
    let kept_min = lam.iter().cloned().filter(|&l| l >= tol * lmax).fold(f64::MAX, f64::min);
    report.condition_number = if kept_min < f64::MAX { (lmax / kept_min).sqrt() } else { f64::INFINITY };
    report.extra_null_dim = null_count;
    report.rank = z.dim() - null_count;

    let mut w = Mat::<f64>::zeros(dim, 0);
    let mut far = Mat::<f64>::zeros(dim, 0);
    if null_count > 0 {
        match m.self_adjoint_eigen(Side::Lower) {
            Ok(eig) => {
                // Eigenvalues ascend: the first `null_count` vectors span the null space.
                // W = Z V_null has orthonormal columns in scaled full coordinates.
                let v = eig.U().subcols(0, null_count).to_owned();
                w = z.z(&v);
                let kept = z.dim() - null_count;
                let y = eig.U().subcols(null_count, kept).to_owned();
                let l = Mat::from_fn(kept, kept, |i, j| if i == j { lam[null_count + i].max(0.0).sqrt() } else { 0.0 });
                far = beyond_horizon(summary, displacement, z, scale, Some(&y), l.as_ref());
            }
            Err(e) => report.warnings.push(format!("identifiability analysis failed: {e:?}")),
        }
    } else if let Ok(llt) = m.llt(Side::Lower) {
        far = beyond_horizon(summary, displacement, z, scale, None, llt.L());
    }
    finish(layout, summary, n, lmax, &gauge_basis, w, far, scale, displacement, report)
}

/// The analysis from the directions the readings leave undetermined (`w`, scaled coordinates,
/// orthonormal columns) and those they inform only beyond the linearisation horizon (`far`,
/// orthonormal and orthogonal to `w`).
#[allow(clippy::too_many_arguments)]
fn finish(
    layout: &ModelLayout,
    summary: &DataSummary,
    n: &Mat<f64>,
    lmax: f64,
    gauge_basis: &Mat<f64>,
    w: Mat<f64>,
    far: Mat<f64>,
    scale: &[f64],
    displacement: &Mat<f64>,
    mut report: Identifiability,
) -> Analysis {
    let dim = n.nrows();
    let mut appended = Vec::new();
    let w = if far.ncols() > 0 {
        report.extra_null_dim += far.ncols();
        report.rank -= far.ncols();
        appended.push(format!(
            "{} further direction(s) are informed by the readings only through second-order effects (the cosine of a beam's small tilt from the motion it follows, or a range's error across its line of sight): their standard uncertainty as a displacement of the reflector exceeds {:.0} um, beyond which those effects would no longer be small against the readings' noise, so they are not determined and are set to zero. Measure them with beams or ranges along the errors they carry (other beam directions, probe offsets or lines).",
            far.ncols(),
            summary.horizon_m * 1e6
        ));
        Mat::from_fn(
            dim,
            w.ncols() + far.ncols(),
            |k, c| if c < w.ncols() { w[(k, c)] } else { far[(k, c - w.ncols())] },
        )
    } else {
        w
    };
    let extra = Mat::from_fn(w.ncols(), dim, |r, k| w[(k, r)] * scale[k]);
    let directions = Mat::from_fn(dim, w.ncols(), |k, r| w[(k, r)] / scale[k]);

    gauge_check(layout, summary, n, lmax, gauge_basis, scale, displacement, &mut report);
    describe(layout, summary, n, &w, &mut report);
    report.statements.extend(appended.iter().cloned());
    let far = far.ncols();
    Analysis { report, extra_constraints: extra, directions, summary: summary.clone(), appended, far }
}

/// Standard uncertainties at which the linearisation horizon is drawn ([`beyond_horizon`]).
pub(crate) const HORIZON_COVERAGE: f64 = 3.0;
/// Fraction of the readings' noise that the neglected quadratic may reach there.
pub(crate) const HORIZON_NOISE_FRACTION: f64 = 0.01;

/// The directions that the readings inform only beyond the linearisation horizon, as orthonormal
/// columns in scaled full coordinates (none when every direction is within it).
///
/// Why: the estimator linearises the readings. A beam fitted to the reflector's own motion reads
/// an error across it only through the cosine of the beam's tilt from the axes (a few tens of
/// microradians when a deflector points it): the linear information on such an error is real
/// but tiny, and its estimate is metres wide, where the neglected quadratic (a displacement `e`
/// across a line of length `L` changes the reading by `e^2 / (2 L)`) is far larger than the
/// noise. Gauss-Newton then chases the noise along it and does not converge (a campaign of
/// ISO 230-2 lines alone, with the deflector's pointing noise, left 2 um residuals at 0.2 um
/// noise). A direction is determined only if its standard uncertainty as a displacement is
/// within the horizon `h`: at [`HORIZON_COVERAGE`] standard uncertainties the quadratic stays
/// below [`HORIZON_NOISE_FRACTION`] of the readings' median noise `sigma` over the travel's
/// diagonal `L`, `(3 h)^2 / (2 L) = sigma / 100`. A displacement is the reflector's, at the
/// readings (root mean square). A campaign that measures a direction at all determines it far
/// within: h is 22 um for the machine tool's travel at 0.2 um noise, and the patent's plan on
/// the demo machine determines every direction to 1.3 % of its h. Over ISO 230-2 lines alone
/// (the machine tool, three lines of five runs) the directions fall in two groups 3 000 times
/// apart, the one from 0.9 to 100 times the 70 um of a tenth of the noise, the other below 0.03
/// um: the hundredth puts the horizon well inside that gap.
///
/// `y` spans the directions the relative test kept, in reduced coordinates (all of them when
/// `None`), `l` is a lower Cholesky factor of `y^T m y`, and `displacement` the mean square
/// displacement of the reflector over the readings per pair of parameters (unscaled).
fn beyond_horizon(
    summary: &DataSummary,
    displacement: &Mat<f64>,
    z: &crate::nullspace::NullSpace,
    scale: &[f64],
    y: Option<&Mat<f64>>,
    l: faer::MatRef<'_, f64>,
) -> Mat<f64> {
    use faer::linalg::triangular_solve::{solve_lower_triangular_in_place, solve_upper_triangular_in_place};
    let h2 = summary.horizon_m * summary.horizon_m;
    let q = l.nrows();
    let dim = scale.len();
    if !(h2 > 0.0 && h2.is_finite()) || q == 0 {
        return Mat::zeros(dim, 0);
    }
    // The displacement Gram in scaled coordinates.
    let b = Mat::from_fn(dim, dim, |i, j| displacement[(i, j)] / (scale[i] * scale[j]));
    let lift = |v: &Mat<f64>| match y {
        Some(y) => y * v,
        None => v.clone(),
    };
    let reduce = |t: &Mat<f64>| {
        let back = z.zt(t);
        match y {
            Some(y) => y.transpose() * &back,
            None => back,
        }
    };
    // The largest displacement variance by power iteration (two triangular solves and two
    // products with Z and the Gram each, O(n^2)): the usual campaign is certified here, an order
    // of magnitude within the horizon, before the dense products below.
    let mut v = Mat::from_fn(q, 1, |i, _| 1.0 + (i as f64 * 0.618_033_988_749).fract());
    let mut largest = 0.0;
    for _ in 0..25 {
        let nv = v.norm_l2();
        if !(nv > 0.0) {
            break;
        }
        v = &v * (1.0 / nv);
        solve_upper_triangular_in_place(l.transpose(), v.as_mut(), faer::Par::Seq);
        v = reduce(&(&b * z.z(&lift(&v))));
        solve_lower_triangular_in_place(l, v.as_mut(), faer::Par::Seq);
        largest = v.norm_l2();
    }
    if largest.is_finite() && largest <= 0.1 * h2 {
        return Mat::zeros(dim, 0);
    }
    // C = L^-1 Y^T Z^T B Z Y L^-T: its eigenvalues are the displacement variances of the
    // directions that extremise them.
    let zbz = z.zt(&z.zt(&b).transpose().to_owned());
    let mut c = match y {
        Some(y) => y.transpose() * &zbz * y,
        None => zbz,
    };
    solve_lower_triangular_in_place(l, c.as_mut(), faer::Par::Seq);
    let mut c = c.transpose().to_owned();
    solve_lower_triangular_in_place(l, c.as_mut(), faer::Par::Seq);
    let c = Mat::from_fn(q, q, |i, j| 0.5 * (c[(i, j)] + c[(j, i)]));
    let Ok(eig) = c.self_adjoint_eigen(Side::Lower) else { return Mat::zeros(dim, 0) };
    let s = eig.S().column_vector();
    let far: Vec<usize> = (0..q).filter(|&i| s[i] > h2).collect();
    if far.is_empty() {
        return Mat::zeros(dim, 0);
    }
    let mut v = Mat::from_fn(q, far.len(), |i, j| eig.U()[(i, far[j])]);
    solve_upper_triangular_in_place(l.transpose(), v.as_mut(), faer::Par::Seq);
    z.z(&lift(&v)).qr().compute_thin_Q()
}

/// Restates `analysis`'s report for the directions `w` (scaled coordinates, orthonormal
/// columns) that stay undetermined once the roughness prior of the smoothing has determined the
/// others of those the readings left open: the counts, the functions not identified, the
/// combinations and the statements then speak of what the model file keeps as undetermined,
/// not of curvature the prior fixes (which would otherwise read as "set to zero"). `n` is the
/// normal matrix the analysis was made on.
pub(crate) fn restate(layout: &ModelLayout, n: &Mat<f64>, w: &Mat<f64>, analysis: &mut Analysis) {
    let report = &mut analysis.report;
    let open = report.extra_null_dim + report.prior_determined;
    report.extra_null_dim = w.ncols();
    report.prior_determined = open.saturating_sub(w.ncols());
    describe(layout, &analysis.summary, n, w, report);
    report.statements.extend(analysis.appended.iter().cloned());
}

/// How strongly the data observe each analytic gauge freedom, after the nuisance parameters
/// (stations, effects) have absorbed what they can.
#[allow(clippy::too_many_arguments)]
fn gauge_check(
    layout: &ModelLayout,
    summary: &DataSummary,
    n: &Mat<f64>,
    lmax: f64,
    g: &Mat<f64>,
    scale: &[f64],
    displacement: &Mat<f64>,
    report: &mut Identifiability,
) {
    let n_u = layout.n_params;
    let dim = n.nrows();
    let nuu = n.submatrix(0, 0, n_u, n_u).to_owned();
    let schur = if dim > n_u {
        let k = dim - n_u;
        let nss = n.submatrix(n_u, n_u, k, k).to_owned();
        let ridge = (0..k).map(|i| nss[(i, i)]).fold(0.0, f64::max) * 1e-12 + f64::MIN_POSITIVE;
        let nss = Mat::from_fn(k, k, |i, j| nss[(i, j)] + if i == j { ridge } else { 0.0 });
        match nss.llt(Side::Lower) {
            Ok(llt) => {
                let inv = llt.inverse();
                let nus = n.submatrix(0, n_u, n_u, k);
                &nuu - nus * &inv * nus.transpose()
            }
            Err(_) => nuu,
        }
    } else {
        nuu
    };
    // The analysis's own column scale (floored where the readings inform a parameter only
    // weakly, see the estimator's `column_scale`).
    let sc = &scale[..n_u];
    let ss = Mat::from_fn(n_u, n_u, |i, j| schur[(i, j)] / (sc[i] * sc[j]));
    let names = gauge_freedom_names();
    let mut worst: f64 = 0.0;
    for c in 0..GAUGE_DIM {
        let v: Vec<f64> = (0..n_u).map(|k| g[(k, c)] * sc[k]).collect();
        let nv = v.iter().map(|x| x * x).sum::<f64>();
        if nv == 0.0 {
            continue;
        }
        let mut q = 0.0;
        for i in 0..n_u {
            if v[i] == 0.0 {
                continue;
            }
            for j in 0..n_u {
                q += v[i] * ss[(i, j)] * v[j];
            }
        }
        // Beyond the linearisation horizon (see [`beyond_horizon`]) the data inform a freedom
        // only through second-order effects: that is no information the gauge overrides.
        let beyond = || {
            let h = summary.horizon_m;
            let gc = g.subcols(c, 1);
            let displacement2 = (gc.transpose() * displacement.submatrix(0, 0, n_u, n_u) * gc)[(0, 0)];
            h > 0.0 && q * h * h <= displacement2
        };
        let ratio = (q / nv / lmax).max(0.0);
        let ratio = if ratio > GAUGE_OBSERVED && beyond() { 0.0 } else { ratio };
        worst = worst.max(ratio);
        if ratio > GAUGE_OBSERVED {
            report.warnings.push(format!(
                "the data observe the gauge freedom '{}' (relative eigenvalue {ratio:.1e}); the gauge constraint overrides real information there (e.g. the probe offset changes within a line)",
                names[c]
            ));
        }
    }
    report.gauge_observability = worst;
}

/// Names of the 24 gauge freedoms in the order of [`gauge::null_basis`].
pub fn gauge_freedom_names() -> Vec<String> {
    let mut v = Vec::new();
    for a in ['X', 'Y', 'Z'] {
        for c in ['X', 'Y', 'Z'] {
            v.push(format!("constant E{c}{a}"));
        }
    }
    for a in ['X', 'Y', 'Z'] {
        for c in ['A', 'B', 'C'] {
            v.push(format!("constant E{c}{a}"));
        }
    }
    for c in ['X', 'Y', 'Z'] {
        v.push(format!("rigid rotation about {c}"));
    }
    for s in Squareness::ALL {
        v.push(format!("{} versus straightness slope", s.name()));
    }
    v
}

/// Identifies which functions the null space `w` (scaled, orthonormal columns) involves.
fn describe(layout: &ModelLayout, summary: &DataSummary, n: &Mat<f64>, w: &Mat<f64>, report: &mut Identifiability) {
    let dim = n.nrows();
    let n_u = layout.n_params;
    // Units: the owner of each column; squareness folds with the others.
    #[derive(Clone, PartialEq)]
    enum Unit {
        F(ErrorFunction),
        S(Squareness),
        Other(String),
    }
    let unit_of = |k: usize| -> Unit {
        if k < n_u {
            match layout.owner(k) {
                ParamOwner::Function(f, _) => Unit::F(f),
                ParamOwner::Squareness(s) => Unit::S(s),
            }
        } else {
            Unit::Other(other_label(summary, k))
        }
    };
    let mut units: Vec<Unit> = Vec::new();
    let mut cols: Vec<Vec<usize>> = Vec::new();
    for k in 0..dim {
        let u = unit_of(k);
        match units.iter().position(|x| *x == u) {
            Some(p) => cols[p].push(k),
            None => {
                units.push(u);
                cols.push(vec![k]);
            }
        }
    }
    let desc = |u: &Unit| match u {
        Unit::F(f) => f.describe(),
        Unit::S(s) => s.describe().to_string(),
        Unit::Other(s) => s.clone(),
    };
    let name = |u: &Unit| match u {
        Unit::F(f) => f.name(),
        Unit::S(s) => s.name().to_string(),
        Unit::Other(s) => s.clone(),
    };
    // Not observed: every column of the unit is zero.
    let dmax = (0..dim).map(|k| n[(k, k)].abs()).fold(0.0, f64::max);
    let unobserved: Vec<bool> =
        cols.iter().map(|c| c.iter().all(|&k| n[(k, k)].abs() <= 1e-300_f64.max(dmax * 1e-28))).collect();
    // Involvement of each unit in the null space: trace of its diagonal block of W W^T.
    let k = w.ncols();
    let block = |a: &[usize], b: &[usize]| -> f64 {
        // Frobenius norm of W_a W_b^T = sqrt(trace(W_a^T W_a W_b^T W_b)).
        let wa = Mat::from_fn(a.len(), k, |i, j| w[(a[i], j)]);
        let wb = Mat::from_fn(b.len(), k, |i, j| w[(b[i], j)]);
        let ga = wa.transpose() * &wa;
        let gb = wb.transpose() * &wb;
        let mut t = 0.0;
        for i in 0..k {
            for j in 0..k {
                t += ga[(i, j)] * gb[(j, i)];
            }
        }
        t.max(0.0).sqrt()
    };
    let involvement: Vec<f64> = cols.iter().map(|c| if k == 0 { 0.0 } else { block(c, c) }).collect();
    let involved: Vec<usize> = (0..units.len()).filter(|&i| involvement[i] > 0.05).collect();
    // Coupling between involved, observed units.
    let coupled: Vec<usize> = involved.iter().cloned().filter(|&i| !unobserved[i]).collect();
    let mut parent: Vec<usize> = (0..units.len()).collect();
    fn find(p: &mut Vec<usize>, i: usize) -> usize {
        if p[i] != i {
            let r = find(p, p[i]);
            p[i] = r;
        }
        p[i]
    }
    for a in 0..coupled.len() {
        for b in a + 1..coupled.len() {
            let (i, j) = (coupled[a], coupled[b]);
            let c = block(&cols[i], &cols[j]) / (involvement[i] * involvement[j]).sqrt();
            if c > 0.1 {
                let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
                parent[ri] = rj;
            }
        }
    }
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for &i in &coupled {
        let r = find(&mut parent, i);
        match groups.iter_mut().find(|g| find(&mut parent.clone(), g[0]) == r) {
            Some(g) => g.push(i),
            None => groups.push(vec![i]),
        }
    }
    let not_observed: Vec<usize> = involved.iter().cloned().filter(|&i| unobserved[i]).collect();
    report.not_observed = not_observed.iter().map(|&i| name(&units[i])).collect();
    report.combinations = groups.iter().map(|g| g.iter().map(|&i| name(&units[i])).collect()).collect();

    // Count identified error functions (of 21).
    let mut deficient = not_observed.iter().filter(|&&i| !matches!(units[i], Unit::Other(_))).count();
    for g in &groups {
        let model_units = g.iter().filter(|&&i| !matches!(units[i], Unit::Other(_))).count();
        let others = g.len() - model_units;
        // A group of m model functions coupled among themselves loses (about) one function;
        // a model function coupled only to an effect loses none of the model's count.
        if model_units >= 2 || (model_units == 1 && others == 0) {
            deficient += 1;
        }
    }
    report.identified_functions = 21usize.saturating_sub(deficient);

    // Statements.
    let last = layout.topology.last_axis();
    let lateral = summary.probe_offsets.iter().any(|p| {
        let mut q = *p;
        q[last.index()] = 0.0;
        q.norm() > 1e-6
    });
    let along: Vec<f64> = summary.probe_offsets.iter().map(|p| p[last.index()]).collect();
    let distinct_along = {
        let mut a = along.clone();
        a.sort_by(|x, y| x.total_cmp(y));
        a.dedup_by(|x, y| (*x - *y).abs() < 1e-6);
        a.len()
    };
    let mut st = Vec::new();
    let prior = report.prior_determined;
    let by_prior = format!(
        "the readings alone leave {} direction(s) open beyond the {GAUGE_DIM} gauge freedoms, and the roughness prior of the smoothing determines {prior} of them (the curvature between the readings, with the prior's uncertainty)",
        report.extra_null_dim + prior
    );
    if report.extra_null_dim == 0 && prior == 0 {
        st.push(format!(
            "All 21 error functions are identified (rank {} of {} parameters after the {} gauge constraints; condition number {:.3e}).",
            report.rank,
            n_u + report.n_other,
            GAUGE_DIM,
            report.condition_number
        ));
    } else if report.extra_null_dim == 0 {
        st.push(format!("All 21 error functions are identified: {by_prior}."));
    } else if prior == 0 {
        st.push(format!(
            "{} of 21 error functions are identified individually; the data leave {} further direction(s) undetermined beyond the {} gauge freedoms, set to zero (minimum norm).",
            report.identified_functions, report.extra_null_dim, GAUGE_DIM
        ));
    } else {
        st.push(format!(
            "{} of 21 error functions are identified individually; {by_prior}; the other {} stay undetermined, set to zero (minimum norm).",
            report.identified_functions, report.extra_null_dim
        ));
    }
    for &i in &not_observed {
        let reason = match &units[i] {
            Unit::F(f) if f.motion == Motion::Rotation && f.axis == last && f.component == last && !lateral => {
                format!("the roll of the last axis ({}) acts only on a probe offset perpendicular to it, and all probe offsets are along {}", last.letter(), last.letter())
            }
            Unit::F(f) if f.motion == Motion::Rotation && f.axis == last => {
                format!("rotations of the last axis ({}) act only through the probe offset, and the probe offsets are zero or parallel to this rotation", last.letter())
            }
            Unit::F(f) if f.motion == Motion::Rotation => format!("its lever arm (the axes {} carries plus the probe offset) is parallel to its rotation axis everywhere the data go", f.axis.letter()),
            Unit::F(f) if summary.axis_positions[f.axis.index()].len() == 1 => {
                format!("axis {} does not move in these data", f.axis.letter())
            }
            Unit::F(f) => format!("no beam or path has a component along {} while {} moves", f.component.letter(), f.axis.letter()),
            Unit::S(_) => "no data constrain this orientation".into(),
            Unit::Other(_) => "no reading depends on it".into(),
        };
        st.push(format!("{} ({}) cannot be identified from these data: {}.", name(&units[i]), desc(&units[i]), reason));
    }
    // Functions that are undetermined only because the data visit their axis at a few positions
    // (gaps inside the covered range): one statement per axis.
    let is_station = |u: &Unit| matches!(u, Unit::Other(s) if s.starts_with("station"));
    let partial = |g: &Vec<usize>| -> Option<crate::axis::Axis> {
        match (g.len(), &units[g[0]]) {
            (1, Unit::F(f)) if coverage_gap(layout, *f, &summary.axis_positions[f.axis.index()]) == Some(true) => {
                Some(f.axis)
            }
            _ => None,
        }
    };
    for a in crate::axis::Axis::ALL {
        let fs: Vec<String> = groups.iter().filter(|g| partial(g) == Some(a)).map(|g| name(&units[g[0]])).collect();
        if !fs.is_empty() {
            st.push(format!(
                "{} are observed only where the data visit axis {} ({}): their values between those positions are not determined and are set by the minimum-norm choice, so predictions there are not calibrated; move {} across its whole travel (e.g. the 12 edges of the working cuboid) to determine them.",
                fs.join(", "),
                a.letter(),
                positions_text(&summary.axis_positions[a.index()]),
                a.letter()
            ));
        }
    }
    for g in groups.iter().filter(|g| g.len() == 1 && partial(g).is_none()) {
        let i = g[0];
        let axis_note = match &units[i] {
            Unit::F(f) => coverage_note(summary, layout, f.axis),
            _ => String::new(),
        };
        let plane_note = if summary.readings_in_station_plane > 0 {
            format!(
                "; {} tracer readings lie in the plane of the coplanar stations, where no range sees the error normal to that plane (see below)",
                summary.readings_in_station_plane
            )
        } else {
            String::new()
        };
        st.push(format!(
            "{} ({}) is only partly determined: part of its shape along the travel is not observed{}{}.",
            name(&units[i]),
            desc(&units[i]),
            axis_note,
            plane_note
        ));
    }
    for g in groups.iter().filter(|g| g.len() > 1) {
        let names: Vec<String> = g.iter().map(|&i| name(&units[i])).collect();
        let last_rot =
            g.iter().any(|&i| matches!(&units[i], Unit::F(f) if f.motion == Motion::Rotation && f.axis == last));
        let hint = if last_rot && distinct_along < 2 {
            format!(
                "; rotations of {} act through the probe offset exactly like straightness of {}: measure with probe offsets of at least two different lengths along {}",
                last.letter(),
                last.letter(),
                last.letter()
            )
        } else if g.iter().any(|&i| is_station(&units[i])) {
            format!(
                "; the positions of the tracer stations cannot be separated from these functions with {} station(s) in this geometry: the tracer method needs at least 4 stations, not coplanar, seeing every point of the path",
                summary.n_stations
            )
        } else if g.iter().any(|&i| matches!(units[i], Unit::Other(_))) {
            "; the effect's signature is indistinguishable from these error functions in this campaign".into()
        } else if summary.readings_in_station_plane > 0 {
            format!(
                "; {} tracer readings lie in the plane of the coplanar stations, where no range sees the error normal to that plane (see below)",
                summary.readings_in_station_plane
            )
        } else {
            "; more beam directions or probe offsets are needed to separate them".into()
        };
        st.push(format!("{} are determined only in combination{}.", names.join(", "), hint));
    }
    for a in crate::axis::Axis::ALL {
        let note = coverage_note(summary, layout, a);
        if !note.is_empty() && report.extra_null_dim > 0 {
            st.push(format!("Coverage: {}.", note.trim_start_matches("; ")));
        }
    }
    if report.constraint_conditioning < 1e-8 {
        st.push(
            "The gauge constraints do not fix all 24 gauge freedoms: the result is arbitrary along some of them."
                .into(),
        );
    }
    report.statements = st;
}

/// `": the data cover X only over [a, b] m of its travel [lo, hi] m"` when less than 95 % of an
/// axis's travel is covered by the readings, else empty.
fn coverage_note(summary: &DataSummary, layout: &ModelLayout, a: crate::axis::Axis) -> String {
    let [lo, hi] = layout.travel.range(a);
    let [c0, c1] = summary.coverage[a.index()];
    if c1 - c0 >= 0.95 * (hi - lo) {
        return String::new();
    }
    format!("; the readings cover {} only over [{c0:.3}, {c1:.3}] m of its travel [{lo:.3}, {hi:.3}] m, so its functions are undetermined beyond", a.letter())
}

/// Largest eigenvalue of a symmetric positive semi-definite matrix by power iteration.
fn lambda_max_estimate(m: &Mat<f64>) -> f64 {
    let n = m.nrows();
    let mut v = Mat::from_fn(n, 1, |i, _| 1.0 + (i as f64 * 0.618_033_988_749).fract());
    let mut lmax = 0.0;
    for _ in 0..40 {
        let nv = v.norm_l2();
        if nv == 0.0 {
            return 0.0;
        }
        v = &v * (1.0 / nv);
        let w = m * &v;
        lmax = w.norm_l2();
        v = w;
    }
    lmax
}

/// `Some(condition number)` when the matrix is certainly of full rank for tolerance `tol`: given
/// its Cholesky factorisation, the smallest eigenvalue, estimated by inverse iteration,
/// exceeds `1e4 tol` times the trace (an upper bound of the largest eigenvalue).
fn certified_full_rank(m: &Mat<f64>, llt: &faer::linalg::solvers::Llt<f64>, tol: f64) -> Option<f64> {
    use faer::linalg::solvers::Solve;
    let n = m.nrows();
    if n == 0 {
        return Some(1.0);
    }
    let trace: f64 = (0..n).map(|i| m[(i, i)]).sum();
    let mut v = Mat::from_fn(n, 1, |i, _| 1.0 + (i as f64 * 0.754_877_666_246).fract());
    let mut lmin = f64::INFINITY;
    for _ in 0..40 {
        let nv = v.norm_l2();
        v = &v * (1.0 / nv);
        llt.solve_in_place(v.as_mut());
        // |M^-1 v| for unit v approaches 1 / lambda_min from below.
        lmin = 1.0 / v.norm_l2();
        if !lmin.is_finite() {
            return None;
        }
    }
    (lmin > 1e4 * tol * trace).then(|| (lambda_max_estimate(m) / lmin).sqrt())
}
