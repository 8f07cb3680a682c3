//! Representations of one error function over an axis's travel.
//!
//! Every representation is a linear combination of basis functions, so the whole error model
//! stays linear in its coefficients. Each basis evaluates sparsely (only the non-zero basis
//! functions at a coordinate), which keeps the design matrix sparse for tables and B-splines.
//! Linear functionals used by the gauge constraints (mean, mean slope, value at a point) are
//! computed by composite Gauss-Legendre quadrature over the basis's breakpoints, which is exact
//! for the piecewise-polynomial bases.

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
use std::f64::consts::PI;

/// How one error function is represented over its axis's travel.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(tag = "kind", rename_all = "snake_case"))]
pub enum Representation {
    /// Piecewise-linear table at `nodes` equally spaced values (the patent's table form).
    Table { nodes: usize },
    /// Legendre polynomial series `P_0 .. P_degree` on the normalised travel.
    #[cfg_attr(feature = "serde", serde(alias = "legendre"))]
    Polynomial { degree: usize },
    /// Constant + linear trend + `harmonics` sine/cosine pairs of fundamental period
    /// `period_m` (default: the travel length), e.g. for the pitch error of a ball screw.
    Harmonic {
        harmonics: usize,
        #[cfg_attr(feature = "serde", serde(default))]
        period_m: Option<f64>,
    },
    /// Clamped cubic B-spline with `intervals` equal knot intervals (`intervals + 3`
    /// coefficients).
    #[cfg_attr(feature = "serde", serde(rename = "bspline"))]
    BSpline { intervals: usize },
}

impl Default for Representation {
    /// Cubic B-spline with 12 intervals: follows smooth error functions (a full sine period over
    /// the travel) to about 1e-3 of their amplitude, i.e. nanometres for typical machines.
    fn default() -> Self {
        Representation::BSpline { intervals: 12 }
    }
}

/// Most coefficients of one function's representation. Eighteen functions of a thousand make
/// a normal matrix of 18 000 squared (2.6 GB); far more than any campaign determines, and a
/// representation much larger (a B-spline of 100 000 intervals asked for an 80 GB Gram matrix)
/// would exhaust memory before the first reading is fitted.
pub const MAX_COEFFICIENTS: usize = 1_000;

impl Representation {
    /// Checks the parameters (at least a linear function must be representable).
    pub fn validate(&self) -> Result<(), String> {
        match *self {
            Representation::Table { nodes } if nodes < 2 => Err(format!("a table needs at least 2 nodes, got {nodes}")),
            Representation::Polynomial { degree } if degree < 1 => {
                Err("a polynomial needs degree >= 1 (linear terms carry squareness and the gauge)".into())
            }
            Representation::BSpline { intervals } if intervals < 1 => {
                Err("a B-spline needs at least 1 interval".into())
            }
            Representation::Harmonic { period_m: Some(p), .. } if !(p > 0.0 && p.is_finite()) => {
                Err(format!("harmonic period must be positive, got {p}"))
            }
            Representation::Table { nodes } if nodes > MAX_COEFFICIENTS => {
                Err(format!("a table of {nodes} nodes is too large (max {MAX_COEFFICIENTS})"))
            }
            Representation::BSpline { intervals } if intervals + 3 > MAX_COEFFICIENTS => {
                Err(format!("a B-spline of {intervals} intervals is too large (max {})", MAX_COEFFICIENTS - 3))
            }
            Representation::Harmonic { harmonics, .. } if 2 * harmonics + 2 > MAX_COEFFICIENTS => {
                Err(format!("{harmonics} harmonics are too many (max {})", (MAX_COEFFICIENTS - 2) / 2))
            }
            Representation::Polynomial { degree } if degree > 40 => {
                Err(format!("polynomial degree {degree} is too high (max 40)"))
            }
            _ => Ok(()),
        }
    }

    /// Short human description, e.g. `bspline(12)`.
    pub fn label(&self) -> String {
        match *self {
            Representation::Table { nodes } => format!("table({nodes})"),
            Representation::Polynomial { degree } => format!("legendre({degree})"),
            Representation::Harmonic { harmonics, period_m } => match period_m {
                Some(p) => format!("harmonic({harmonics}, period {p} m)"),
                None => format!("harmonic({harmonics})"),
            },
            Representation::BSpline { intervals } => format!("bspline({intervals})"),
        }
    }
}

/// A representation bound to an axis travel `[lo, hi]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Basis {
    pub repr: Representation,
    pub lo: f64,
    pub hi: f64,
}

/// A sparse set of basis values: `(coefficient index, value)`.
pub type SparseBasis = Vec<(usize, f64)>;

impl Basis {
    pub fn new(repr: Representation, lo: f64, hi: f64) -> Basis {
        Basis { repr, lo, hi }
    }

    pub fn length(&self) -> f64 {
        self.hi - self.lo
    }

    /// Number of coefficients.
    pub fn n_coeffs(&self) -> usize {
        match self.repr {
            Representation::Table { nodes } => nodes,
            Representation::Polynomial { degree } => degree + 1,
            Representation::Harmonic { harmonics, .. } => 2 + 2 * harmonics,
            Representation::BSpline { intervals } => intervals + 3,
        }
    }

    /// Normalised coordinate in `[0, 1]`, clamped to the travel.
    fn unit(&self, q: f64) -> f64 {
        ((q - self.lo) / self.length()).clamp(0.0, 1.0)
    }

    /// Calls `f(index, value)` for every non-zero basis function at coordinate `q` (clamped to
    /// the travel), or for their derivatives with respect to `q` when `derivative` is set.
    /// Allocation-free: this sits in the innermost loops of the estimator.
    #[inline]
    pub fn visit(&self, q: f64, derivative: bool, mut f: impl FnMut(usize, f64)) {
        let u = self.unit(q);
        let len = self.length();
        match self.repr {
            Representation::Table { nodes } => {
                let m = (nodes - 1) as f64;
                let pos = u * m;
                let i = (pos.floor() as usize).min(nodes - 2);
                let t = pos - i as f64;
                if derivative {
                    f(i, -m / len);
                    f(i + 1, m / len);
                } else {
                    f(i, 1.0 - t);
                    f(i + 1, t);
                }
            }
            Representation::Polynomial { degree } => {
                let s = 2.0 * u - 1.0;
                // Running Legendre recurrence: P_{k+1} = ((2k+1) s P_k - k P_{k-1}) / (k+1),
                // P'_{k+1} = P'_{k-1} + (2k+1) P_k.
                let (mut p0, mut p1) = (1.0, s);
                let (mut d0, mut d1) = (0.0, 1.0);
                f(0, if derivative { 0.0 } else { 1.0 });
                if degree >= 1 {
                    f(1, if derivative { 2.0 / len } else { s });
                }
                for k in 1..degree {
                    let kf = k as f64;
                    let p2 = ((2.0 * kf + 1.0) * s * p1 - kf * p0) / (kf + 1.0);
                    let d2 = d0 + (2.0 * kf + 1.0) * p1;
                    f(k + 1, if derivative { d2 * 2.0 / len } else { p2 });
                    p0 = p1;
                    p1 = p2;
                    d0 = d1;
                    d1 = d2;
                }
            }
            Representation::Harmonic { harmonics, period_m } => {
                let period = period_m.unwrap_or(len);
                let s = 2.0 * u - 1.0;
                let phi = 2.0 * PI * (u * len) / period;
                let w = 2.0 * PI / period;
                if derivative {
                    f(0, 0.0);
                    f(1, 2.0 / len);
                } else {
                    f(0, 1.0);
                    f(1, s);
                }
                for k in 1..=harmonics {
                    let kf = k as f64;
                    let (sn, cs) = (kf * phi).sin_cos();
                    if derivative {
                        f(2 * k, -kf * w * sn);
                        f(2 * k + 1, kf * w * cs);
                    } else {
                        f(2 * k, cs);
                        f(2 * k + 1, sn);
                    }
                }
            }
            Representation::BSpline { intervals } => {
                let m = intervals as f64;
                let pos = u * m;
                let span = (pos.floor() as usize).min(intervals - 1);
                let (n, dn) = if span >= 3 && span + 4 <= intervals {
                    uniform_cubic(pos - span as f64)
                } else {
                    cubic_bspline_span(intervals, span, pos)
                };
                for j in 0..4 {
                    f(span + j, if derivative { dn[j] * m / len } else { n[j] });
                }
            }
        }
    }

    /// Non-zero basis values at coordinate `q` (clamped to the travel), written to `out`
    /// (cleared first). With `derivative`, the derivatives with respect to `q` instead.
    pub fn eval_into(&self, q: f64, derivative: bool, out: &mut SparseBasis) {
        out.clear();
        self.visit(q, derivative, |i, v| out.push((i, v)));
    }

    /// Non-zero basis values at `q`.
    pub fn eval(&self, q: f64) -> SparseBasis {
        let mut v = Vec::with_capacity(8);
        self.eval_into(q, false, &mut v);
        v
    }

    /// Function value at `q` for coefficients `c`.
    #[inline]
    pub fn value(&self, c: &[f64], q: f64) -> f64 {
        let mut acc = 0.0;
        self.visit(q, false, |i, b| acc += c[i] * b);
        acc
    }

    /// Derivative at `q` for coefficients `c`.
    pub fn derivative(&self, c: &[f64], q: f64) -> f64 {
        let mut acc = 0.0;
        self.visit(q, true, |i, b| acc += c[i] * b);
        acc
    }

    /// Breakpoints between which the basis is smooth (for quadrature).
    fn breakpoints(&self) -> Vec<f64> {
        let pieces = match self.repr {
            Representation::Table { nodes } => nodes - 1,
            Representation::BSpline { intervals } => intervals,
            Representation::Polynomial { .. } => 1,
            Representation::Harmonic { harmonics, period_m } => {
                let cycles = self.length() / period_m.unwrap_or(self.length());
                ((cycles * harmonics as f64 * 2.0).ceil() as usize).clamp(1, 4096)
            }
        };
        (0..=pieces).map(|i| self.lo + self.length() * i as f64 / pieces as f64).collect()
    }

    /// Quadrature nodes and weights over the travel (weights sum to its length), exact for
    /// products of two basis functions of the piecewise-polynomial representations.
    pub fn quadrature(&self) -> Vec<(f64, f64)> {
        let order = match self.repr {
            Representation::Polynomial { degree } => degree + 2,
            _ => 8,
        };
        let (gx, gw) = gauss_legendre(order);
        let bp = self.breakpoints();
        let mut out = Vec::with_capacity((bp.len() - 1) * order);
        for w in bp.windows(2) {
            let (a, b) = (w[0], w[1]);
            let half = 0.5 * (b - a);
            let mid = 0.5 * (a + b);
            for (x, wt) in gx.iter().zip(&gw) {
                out.push((mid + half * x, half * wt));
            }
        }
        out
    }

    /// Coefficient weights `g` with `g . c` = mean of the function over the travel.
    pub fn mean_functional(&self) -> Vec<f64> {
        let mut g = vec![0.0; self.n_coeffs()];
        let len = self.length();
        for (q, w) in self.quadrature() {
            for (i, b) in self.eval(q) {
                g[i] += w * b / len;
            }
        }
        g
    }

    /// Coefficient weights `g` with `g . c` = least-squares slope of the function over the
    /// travel (the patent's "mean parallelism", eq. 10, in continuous form).
    pub fn slope_functional(&self) -> Vec<f64> {
        let mut g = vec![0.0; self.n_coeffs()];
        let mid = 0.5 * (self.lo + self.hi);
        let sxx = self.length().powi(3) / 12.0;
        for (q, w) in self.quadrature() {
            for (i, b) in self.eval(q) {
                g[i] += w * (q - mid) * b / sxx;
            }
        }
        g
    }

    /// Coefficient weights `g` with `g . c` = function value at `q`.
    pub fn value_functional(&self, q: f64) -> Vec<f64> {
        let mut g = vec![0.0; self.n_coeffs()];
        for (i, b) in self.eval(q) {
            g[i] += b;
        }
        g
    }

    /// Gram matrix `int b_i b_j dq / L` of the basis (for function norms and projections).
    pub fn gram(&self) -> Mat<f64> {
        let n = self.n_coeffs();
        let len = self.length();
        let mut g = Mat::<f64>::zeros(n, n);
        for (q, w) in self.quadrature() {
            let b = self.eval(q);
            for &(i, bi) in &b {
                for &(j, bj) in &b {
                    g[(i, j)] += w * bi * bj / len;
                }
            }
        }
        g
    }

    /// Coefficients of the straight line `a + b q`. A table holds it exactly in its values at the
    /// nodes, with no system to solve (a simulator's truth tabulated every 0.5 mm has thousands
    /// of nodes, and [`Basis::fit`]'s dense Gram factorisation of them took seconds); any other
    /// representation gets the L2 projection ([`Basis::fit`]), exact to rounding for those that
    /// hold lines.
    pub fn line(&self, a: f64, b: f64) -> Vec<f64> {
        match self.repr {
            // A table's nodes are its breakpoints.
            Representation::Table { .. } => self.breakpoints().into_iter().map(|q| a + b * q).collect(),
            _ => self.fit(|q| a + b * q),
        }
    }

    /// L2 projection of `f` onto the basis over the travel. Exact when `f` is representable.
    pub fn fit(&self, f: impl Fn(f64) -> f64) -> Vec<f64> {
        let n = self.n_coeffs();
        let len = self.length();
        let g = self.gram();
        let mut rhs = Mat::<f64>::zeros(n, 1);
        for (q, w) in self.quadrature() {
            let fq = f(q);
            for (i, b) in self.eval(q) {
                rhs[(i, 0)] += w * fq * b / len;
            }
        }
        // The Gram matrix of a basis is symmetric positive definite.
        let llt = g.llt(Side::Lower).expect("basis Gram matrix is positive definite");
        llt.solve_in_place(rhs.as_mut());
        (0..n).map(|i| rhs[(i, 0)]).collect()
    }

    /// Roughness matrix `R_ij = int b_i^(m)(q) b_j^(m)(q) dq` over the travel for derivative
    /// order `m` (2 or 3), so that `c . R c` is the integrated square of the function's `m`-th
    /// derivative (O'Sullivan's penalty for B-splines). Its null space is exactly the
    /// polynomials of degree below `m`, for any representation that contains them: such a
    /// penalty never acts on the constants and slopes that carry the gauge and the squareness.
    /// `None` for a table, whose curvature is concentrated at its nodes.
    ///
    /// Derivatives are central differences of the exact first derivatives at interior
    /// quadrature nodes, with a step of 1e-4 of the piece: exact for the cubic B-spline, whose
    /// first derivative is quadratic on each knot interval.
    pub fn roughness(&self, order: usize) -> Option<Mat<f64>> {
        if matches!(self.repr, Representation::Table { .. }) {
            return None;
        }
        let n = self.n_coeffs();
        let bp = self.breakpoints();
        let h = 1e-4 * self.length() / (bp.len() - 1) as f64;
        let mut r = Mat::<f64>::zeros(n, n);
        let (mut plus, mut minus, mut mid) = (Vec::new(), Vec::new(), Vec::new());
        let mut d2 = vec![0.0; n];
        for (q, w) in self.quadrature() {
            self.eval_into(q + h, true, &mut plus);
            self.eval_into(q - h, true, &mut minus);
            d2.iter_mut().for_each(|v| *v = 0.0);
            if order == 3 {
                self.eval_into(q, true, &mut mid);
                for &(i, v) in &plus {
                    d2[i] += v / (h * h);
                }
                for &(i, v) in &minus {
                    d2[i] += v / (h * h);
                }
                for &(i, v) in &mid {
                    d2[i] -= 2.0 * v / (h * h);
                }
            } else {
                for &(i, v) in &plus {
                    d2[i] += v / (2.0 * h);
                }
                for &(i, v) in &minus {
                    d2[i] -= v / (2.0 * h);
                }
            }
            for i in 0..n {
                if d2[i] == 0.0 {
                    continue;
                }
                for j in 0..n {
                    r[(i, j)] += w * d2[i] * d2[j];
                }
            }
        }
        Some(r)
    }

    /// For a table, one row per inner node: the jump of the slope there, `(v_{k-1} - 2 v_k +
    /// v_{k+1}) / h`, over `sqrt(h)` (the curvature of the kink spread over one interval), so
    /// that the rows' Gram matrix is the table's roughness: the straight lines are free, each
    /// kink costs its squared size. `None` for other representations or a table of one interval.
    pub fn kink_rows(&self) -> Option<Mat<f64>> {
        let Representation::Table { nodes } = self.repr else { return None };
        if nodes < 3 {
            return None;
        }
        let h = self.length() / (nodes - 1) as f64;
        let w = 1.0 / (h * h.sqrt());
        Some(Mat::from_fn(nodes - 2, nodes, |k, j| match j as isize - k as isize {
            0 | 2 => w,
            1 => -2.0 * w,
            _ => 0.0,
        }))
    }

    /// For a cubic B-spline, one row per knot interval: `sqrt(h) b'''` at the interval (the
    /// third derivative is constant on it), so that the rows' Gram matrix is
    /// [`Basis::roughness`]`(3)` and each row is the roughness of one interval. `None` for other
    /// representations.
    pub fn interval_roughness_rows(&self) -> Option<Mat<f64>> {
        let Representation::BSpline { intervals } = self.repr else { return None };
        let n = self.n_coeffs();
        let h = self.length() / intervals as f64;
        let eps = 1e-4 * h;
        let (mut plus, mut minus, mut mid) = (Vec::new(), Vec::new(), Vec::new());
        let mut rows = Mat::<f64>::zeros(intervals, n);
        for i in 0..intervals {
            let q = self.lo + h * (i as f64 + 0.5);
            self.eval_into(q + eps, true, &mut plus);
            self.eval_into(q - eps, true, &mut minus);
            self.eval_into(q, true, &mut mid);
            let w = h.sqrt() / (eps * eps);
            for &(j, v) in &plus {
                rows[(i, j)] += w * v;
            }
            for &(j, v) in &minus {
                rows[(i, j)] += w * v;
            }
            for &(j, v) in &mid {
                rows[(i, j)] -= 2.0 * w * v;
            }
        }
        Some(rows)
    }

    /// RMS of the function over the travel.
    pub fn rms(&self, c: &[f64]) -> f64 {
        let len = self.length();
        let s: f64 = self.quadrature().iter().map(|&(q, w)| w * self.value(c, q).powi(2)).sum();
        (s / len).max(0.0).sqrt()
    }
}

/// Legendre polynomials `P_0..P_n` and their derivatives at `s` in `[-1, 1]`.
pub(crate) fn legendre(n: usize, s: f64) -> (Vec<f64>, Vec<f64>) {
    let mut p = vec![0.0; n + 1];
    let mut dp = vec![0.0; n + 1];
    p[0] = 1.0;
    if n >= 1 {
        p[1] = s;
        dp[1] = 1.0;
    }
    for k in 1..n {
        let kf = k as f64;
        p[k + 1] = ((2.0 * kf + 1.0) * s * p[k] - kf * p[k - 1]) / (kf + 1.0);
        // P'_{k+1} = P'_{k-1} + (2k+1) P_k
        dp[k + 1] = dp[k - 1] + (2.0 * kf + 1.0) * p[k];
    }
    (p, dp)
}

/// The four non-zero clamped uniform cubic B-spline basis functions (and their derivatives
/// with respect to the knot-normalised coordinate `pos` in `[0, m]`) on knot span `span`.
/// Cox-de Boor recursion on the clamped knot vector `0,0,0,0,1,2,..,m-1,m,m,m,m`.
fn cubic_bspline_span(m: usize, span: usize, pos: f64) -> ([f64; 4], [f64; 4]) {
    // knot(i) for the clamped vector with 4-fold end knots.
    let knot = |i: isize| -> f64 { (i - 3).clamp(0, m as isize) as f64 };
    let i = span as isize + 3; // index of the knot interval [knot(i), knot(i+1))
    let mut left = [0.0; 4];
    let mut right = [0.0; 4];
    // ndu as in Piegl & Tiller A2.3, degree 3.
    let mut ndu = [[0.0f64; 4]; 4];
    ndu[0][0] = 1.0;
    for j in 1..=3 {
        left[j] = pos - knot(i + 1 - j as isize);
        right[j] = knot(i + j as isize) - pos;
        let mut saved = 0.0;
        for r in 0..j {
            ndu[j][r] = right[r + 1] + left[j - r];
            let temp = ndu[r][j - 1] / ndu[j][r];
            ndu[r][j] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        ndu[j][j] = saved;
    }
    let mut n = [0.0; 4];
    for j in 0..4 {
        n[j] = ndu[j][3];
    }
    // First derivatives: N'_{k,3} = 3 (N_{k,2}/(t_{k+3}-t_k) - N_{k+1,2}/(t_{k+4}-t_{k+1})).
    let mut d = [0.0; 4];
    for r in 0..4 {
        let mut v = 0.0;
        if r >= 1 {
            let denom = ndu[3][r - 1];
            v += ndu[r - 1][2] / denom;
        }
        if r <= 2 {
            let denom = ndu[3][r];
            v -= ndu[r][2] / denom;
        }
        d[r] = 3.0 * v;
    }
    (n, d)
}

/// The four uniform cubic B-spline basis functions on an interior span at local coordinate
/// `t` in `[0, 1)`, and their derivatives (away from the clamped ends every span is uniform).
#[inline]
fn uniform_cubic(t: f64) -> ([f64; 4], [f64; 4]) {
    let t2 = t * t;
    let t3 = t2 * t;
    let s = 1.0 - t;
    (
        [s * s * s / 6.0, (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0, (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0, t3 / 6.0],
        [-0.5 * s * s, 1.5 * t2 - 2.0 * t, -1.5 * t2 + t + 0.5, 0.5 * t2],
    )
}

/// Gauss-Legendre nodes and weights on `[-1, 1]` (Newton iteration on `P_n`).
pub fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; n];
    let mut w = vec![0.0; n];
    for i in 0..n {
        let mut z = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        for _ in 0..100 {
            let (p, dp) = legendre(n, z);
            let dz = p[n] / dp[n];
            z -= dz;
            if dz.abs() < 1e-16 {
                break;
            }
        }
        let (_, dp) = legendre(n, z);
        x[i] = z;
        w[i] = 2.0 / ((1.0 - z * z) * dp[n] * dp[n]);
    }
    (x, w)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all_reprs() -> Vec<Representation> {
        vec![
            Representation::Table { nodes: 9 },
            Representation::Polynomial { degree: 6 },
            Representation::Harmonic { harmonics: 3, period_m: None },
            Representation::BSpline { intervals: 7 },
            Representation::BSpline { intervals: 1 },
        ]
    }

    #[test]
    fn a_tables_kink_rows_spare_lines_and_weigh_each_kink_by_its_size() {
        let b = Basis::new(Representation::Table { nodes: 11 }, -0.5, 0.2);
        let rows = b.kink_rows().unwrap();
        assert_eq!((rows.nrows(), rows.ncols()), (9, 11));
        let apply = |c: &[f64]| (0..9).map(|k| (0..11).map(|j| rows[(k, j)] * c[j]).sum::<f64>()).collect::<Vec<_>>();
        let line = b.fit(|q| 3.0 * q - 0.1);
        assert!(apply(&line).iter().all(|v| v.abs() < 1e-9));
        // |q - q5|: the slope jumps by 2 at node 5 and nowhere else; its row is 2 / sqrt(h).
        let h = 0.07;
        let vee = b.fit(|q| (q + 0.5 - 5.0 * h).abs());
        let r = apply(&vee);
        for (k, v) in r.iter().enumerate() {
            let want = if k + 1 == 5 { 2.0 / h.sqrt() } else { 0.0 };
            assert!((v - want).abs() < 1e-8, "row {k}: {v} against {want}");
        }
        assert!(Basis::new(Representation::Table { nodes: 2 }, 0.0, 1.0).kink_rows().is_none());
        assert!(Basis::new(Representation::BSpline { intervals: 4 }, 0.0, 1.0).kink_rows().is_none());
    }

    #[test]
    fn roughness_is_the_integrated_squared_curvature_and_spares_linear_functions() {
        for r in all_reprs() {
            let b = Basis::new(r, -0.5, 0.2);
            let Some(rough) = b.roughness(2) else {
                assert!(matches!(r, Representation::Table { .. }));
                continue;
            };
            let third = b.roughness(3).unwrap();
            let quad = |m: &Mat<f64>, c: &[f64]| {
                let n = c.len();
                (0..n).map(|i| (0..n).map(|j| c[i] * m[(i, j)] * c[j]).sum::<f64>()).sum::<f64>()
            };
            let lin = b.fit(|q| 3.0 * q - 0.1);
            assert!(quad(&rough, &lin).abs() < 1e-9, "{r:?}: {}", quad(&rough, &lin));
            // f = q^2 and q^3 (in every representation but the single harmonic):
            // int (f'')^2 = 4 L; int (f''')^2 = 0 and 36 L.
            if !matches!(r, Representation::Harmonic { .. }) {
                let par = b.fit(|q| q * q);
                assert!((quad(&rough, &par) - 4.0 * 0.7).abs() < 1e-7, "{r:?}: {}", quad(&rough, &par));
                assert!(quad(&third, &par).abs() < 1e-6, "{r:?}: {}", quad(&third, &par));
                let cub = b.fit(|q| q * q * q);
                assert!((quad(&third, &cub) - 36.0 * 0.7).abs() < 1e-5, "{r:?}: {}", quad(&third, &cub));
            }
        }
    }

    #[test]
    fn interval_rows_add_up_to_the_third_derivative_roughness() {
        for k in [1, 2, 7, 12] {
            let b = Basis::new(Representation::BSpline { intervals: k }, -0.5, 0.2);
            let rows = b.interval_roughness_rows().unwrap();
            let gram = rows.transpose() * &rows;
            let r = b.roughness(3).unwrap();
            let scale = (0..r.nrows()).map(|i| r[(i, i)]).fold(0.0, f64::max);
            for i in 0..r.nrows() {
                for j in 0..r.ncols() {
                    assert!((gram[(i, j)] - r[(i, j)]).abs() < 1e-6 * scale, "{k}: ({i}, {j})");
                }
            }
        }
        assert!(Basis::new(Representation::Polynomial { degree: 4 }, 0.0, 1.0).interval_roughness_rows().is_none());
    }

    /// The line's coefficients are the L2 projection's, to rounding, for every representation.
    #[test]
    fn a_line_is_its_projection() {
        for r in all_reprs() {
            let b = Basis::new(r, -0.5, 0.2);
            for (a, s) in [(1.0, 0.0), (0.0, 1.0), (-0.1, 3.0)] {
                let (line, fit) = (b.line(a, s), b.fit(|q| a + s * q));
                assert!(line.iter().zip(&fit).all(|(x, y)| (x - y).abs() < 1e-12), "{r:?}: {line:?} {fit:?}");
            }
        }
    }

    #[test]
    fn partition_of_unity_and_linear_fit() {
        for r in all_reprs() {
            let b = Basis::new(r, -0.5, 0.2);
            let one = b.fit(|_| 1.0);
            let lin = b.fit(|q| 3.0 * q - 0.1);
            for k in 0..=50 {
                let q = -0.5 + 0.7 * k as f64 / 50.0;
                assert!((b.value(&one, q) - 1.0).abs() < 1e-10, "{r:?}");
                assert!((b.value(&lin, q) - (3.0 * q - 0.1)).abs() < 1e-10, "{r:?}");
                assert!((b.derivative(&lin, q) - 3.0).abs() < 1e-8, "{r:?} at {q}");
            }
            let g = b.mean_functional();
            let s = b.slope_functional();
            let dot = |a: &[f64], c: &[f64]| a.iter().zip(c).map(|(x, y)| x * y).sum::<f64>();
            assert!((dot(&g, &one) - 1.0).abs() < 1e-12);
            assert!((dot(&s, &lin) - 3.0).abs() < 1e-10);
            assert!(dot(&s, &one).abs() < 1e-12);
        }
    }

    #[test]
    fn derivative_matches_finite_difference() {
        for r in all_reprs() {
            let b = Basis::new(r, 0.0, 1.0);
            let c: Vec<f64> = (0..b.n_coeffs()).map(|i| ((i * 7 % 5) as f64 - 2.0) * 0.3).collect();
            for k in 1..20 {
                let q = k as f64 / 20.0 + 0.013;
                let h = 1e-6;
                let fd = (b.value(&c, q + h) - b.value(&c, q - h)) / (2.0 * h);
                assert!((fd - b.derivative(&c, q)).abs() < 1e-6, "{r:?} q={q}");
            }
        }
    }

    #[test]
    fn default_follows_smooth_functions() {
        let b = Basis::new(Representation::default(), 0.0, 1.0);
        let amp = 10e-6;
        let f = |q: f64| amp * (2.0 * PI * q + 0.3).sin() + 5e-6 * q * q;
        let c = b.fit(f);
        let worst = (0..=1000).map(|k| k as f64 / 1000.0).map(|q| (b.value(&c, q) - f(q)).abs()).fold(0.0, f64::max);
        assert!(worst < 0.01 * amp, "representation error {worst}");
    }

    #[test]
    fn uniform_spans_match_de_boor() {
        let m = 9;
        for span in 3..m - 3 {
            for k in 0..7 {
                let pos = span as f64 + k as f64 / 7.0;
                let (a, da) = uniform_cubic(pos - span as f64);
                let (b, db) = cubic_bspline_span(m, span, pos);
                for j in 0..4 {
                    assert!((a[j] - b[j]).abs() < 1e-14 && (da[j] - db[j]).abs() < 1e-13, "span {span} pos {pos}");
                }
            }
        }
    }

    #[test]
    fn gauss_legendre_integrates_polynomials() {
        let (x, w) = gauss_legendre(5);
        let s: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(8)).sum();
        assert!((s - 2.0 / 9.0).abs() < 1e-14);
    }
}
