//! Predictions from an identified model: volumetric error with expanded uncertainty at any
//! point, dense maps, the largest error and where it occurs, and per-axis compensation tables.

use crate::axis::{Axis, Travel};
use crate::functions::ErrorFunction;
use crate::model::{ErrorModel, Sensitivity};
use faer::Mat;
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};

/// Coverage factor of the expanded uncertainties (k = 2, about 95 %).
pub const COVERAGE_K: f64 = 2.0;

/// Volumetric error at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointError {
    pub x: Point3<f64>,
    pub p: Vector3<f64>,
    /// `e = actual - (X + p)`.
    pub e: Vector3<f64>,
    /// Covariance of `e`.
    pub cov: Matrix3<f64>,
}

impl PointError {
    /// Expanded uncertainty (k = 2) of the error vector along its least favourable direction:
    /// `2 sqrt(lambda_max(cov))`.
    pub fn u95(&self) -> f64 {
        let ev = SymmetricEigen::new(self.cov).eigenvalues;
        COVERAGE_K * ev.max().max(0.0).sqrt()
    }

    /// Standard uncertainty of each component.
    pub fn sigma(&self) -> Vector3<f64> {
        Vector3::new(self.cov[(0, 0)].sqrt(), self.cov[(1, 1)].sqrt(), self.cov[(2, 2)].sqrt())
    }

    /// Standard uncertainty of the magnitude `|e|` (first order).
    pub fn sigma_norm(&self) -> f64 {
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

/// Volumetric error and its covariance at `(x, p)`.
pub fn predict(model: &ErrorModel, cov: &Mat<f64>, x: &Point3<f64>, p: &Vector3<f64>) -> PointError {
    let s = model.layout.sensitivity(x, p);
    PointError { x: *x, p: *p, e: s.apply(&model.u), cov: propagate(&s, cov) }
}

/// Regular grid over the travel with spacing `step` (at least 2 points per axis, ends
/// included).
pub fn grid(travel: &Travel, step: f64) -> Vec<Point3<f64>> {
    let axis_points = |a: Axis| -> Vec<f64> {
        let [lo, hi] = travel.range(a);
        let n = (((hi - lo) / step).round() as usize).max(1);
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

/// Largest `|e|` over a grid (refined by a finer local search) and where it occurs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extremum {
    pub at: PointError,
    pub magnitude_m: f64,
}

/// Finds the largest volumetric error magnitude for probe offset `p`.
pub fn max_error(model: &ErrorModel, cov: &Mat<f64>, p: &Vector3<f64>, step: f64) -> Extremum {
    let travel = model.layout.travel;
    let mut best = Point3::origin();
    let mut best_m = -1.0;
    for x in grid(&travel, step) {
        let m = model.error(&x, p).norm();
        if m > best_m {
            best_m = m;
            best = x;
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
                    if m > best_m + 1e-15 {
                        best_m = m;
                        best = c;
                        improved = true;
                    }
                }
            }
        }
        h /= 2.0;
    }
    Extremum { at: predict(model, cov, &best, p), magnitude_m: best_m }
}

/// One row of a per-axis compensation table: the six functions of an axis at a position.
#[derive(Clone, Debug, PartialEq)]
pub struct CompensationRow {
    pub q_m: f64,
    /// Values of the axis's six functions in canonical order (`EXK EYK EZK EAK EBK ECK`).
    pub values: [f64; 6],
    /// Standard uncertainties of those values.
    pub sigmas: [f64; 6],
}

/// Compensation table of axis `a` at `n` equally spaced positions over its travel.
pub fn compensation_table(model: &ErrorModel, cov: &Mat<f64>, a: Axis, n: usize) -> Vec<CompensationRow> {
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
                sigmas[m] = function_sigma(model, cov, f, q);
            }
            CompensationRow { q_m: q, values, sigmas }
        })
        .collect()
}

/// Standard uncertainty of one function's value at `q`.
pub fn function_sigma(model: &ErrorModel, cov: &Mat<f64>, f: ErrorFunction, q: f64) -> f64 {
    let off = model.layout.range(f).start;
    let b = model.layout.basis(f).eval(q);
    let mut v = 0.0;
    for &(i, bi) in &b {
        for &(j, bj) in &b {
            v += bi * bj * cov[(off + i, off + j)];
        }
    }
    v.max(0.0).sqrt()
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
