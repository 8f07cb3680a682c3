//! The rigid-body error model: 18 error functions plus 3 squareness errors, and the volumetric
//! error it predicts (patent eq. 3-7, generalised to any axis stacking).
//!
//! `e(X, p) = sum_k t_k(q_k) + sum_k r_k(q_k) x h_k + squareness terms`, where `t_k` and `r_k`
//! are the translation and rotation error vectors of axis `k` and `h_k` its lever arm
//! ([`Topology::lever_arm`]). The model is linear in its coefficients `u`; [`ModelLayout::sensitivity`]
//! returns `de/du` sparsely, which is all the estimators need.

use crate::axis::{Axis, Travel};
use crate::functions::{ErrorFunction, Squareness};
use crate::repr::{Basis, Representation, SparseBasis};
use crate::topology::Topology;
use nalgebra::{Point3, Vector3};

/// Where the coefficients of each error function sit in the parameter vector `u`.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelLayout {
    pub topology: Topology,
    pub travel: Travel,
    /// Basis of each of the 18 functions, canonical order ([`ErrorFunction::index`]).
    pub bases: Vec<Basis>,
    /// Offset of each function's coefficients in `u`.
    pub offsets: Vec<usize>,
    /// Total number of coefficients (18 functions + 3 squareness).
    pub n_params: usize,
}

impl ModelLayout {
    /// Layout with one representation per function (canonical order).
    pub fn new(topology: Topology, travel: Travel, reprs: [Representation; 18]) -> ModelLayout {
        let mut bases = Vec::with_capacity(18);
        let mut offsets = Vec::with_capacity(18);
        let mut n = 0;
        for (i, r) in reprs.into_iter().enumerate() {
            let [lo, hi] = travel.range(ErrorFunction::from_index(i).axis);
            let b = Basis::new(r, lo, hi);
            offsets.push(n);
            n += b.n_coeffs();
            bases.push(b);
        }
        ModelLayout { topology, travel, bases, offsets, n_params: n + 3 }
    }

    /// Layout with the same representation for every function.
    pub fn uniform(topology: Topology, travel: Travel, repr: Representation) -> ModelLayout {
        ModelLayout::new(topology, travel, [repr; 18])
    }

    /// Coefficient range of function `f` in `u`.
    pub fn range(&self, f: ErrorFunction) -> std::ops::Range<usize> {
        let i = f.index();
        self.offsets[i]..self.offsets[i] + self.bases[i].n_coeffs()
    }

    pub fn basis(&self, f: ErrorFunction) -> &Basis {
        &self.bases[f.index()]
    }

    /// Index of a squareness error in `u`.
    pub fn squareness_index(&self, s: Squareness) -> usize {
        self.n_params - 3 + s.index()
    }

    /// Which function (or squareness) parameter `k` belongs to.
    pub fn owner(&self, k: usize) -> ParamOwner {
        if k >= self.n_params - 3 {
            return ParamOwner::Squareness(Squareness::ALL[k - (self.n_params - 3)]);
        }
        let i = self.offsets.partition_point(|&o| o <= k) - 1;
        ParamOwner::Function(ErrorFunction::from_index(i), k - self.offsets[i])
    }

    /// Sensitivity `de/du` of the volumetric error at indicated position `x` with probe offset
    /// `p`, written into `out` (cleared first). Evaluation is clamped to the travel.
    pub fn sensitivity_into(&self, x: &Point3<f64>, p: &Vector3<f64>, out: &mut Sensitivity) {
        out.clear();
        let mut b: SparseBasis = Vec::with_capacity(16);
        for axis in Axis::ALL {
            let q = axis.coord(x);
            let h = self.topology.lever_arm(axis, x, p);
            let shared = self.shares_basis(axis);
            if shared {
                self.bases[axis.index() * 6].eval_into(q, false, &mut b);
            }
            for m in 0..6 {
                let f = ErrorFunction::from_index(axis.index() * 6 + m);
                if !shared {
                    self.bases[f.index()].eval_into(q, false, &mut b);
                }
                let dir = f.unit_response(&h);
                if dir == Vector3::zeros() {
                    continue;
                }
                let off = self.offsets[f.index()];
                for &(i, v) in &b {
                    if v != 0.0 {
                        out.push(off + i, dir * v);
                    }
                }
            }
        }
        for s in Squareness::ALL {
            let q = s.axis().coord(x);
            out.push(self.squareness_index(s), s.direction_per_metre() * q);
        }
    }

    /// Whether the six functions of `axis` share one representation (evaluated once).
    #[inline]
    pub fn shares_basis(&self, axis: Axis) -> bool {
        let b = &self.bases[axis.index() * 6..axis.index() * 6 + 6];
        b.iter().all(|x| x == &b[0])
    }

    /// Sensitivity `de/du` at `(x, p)`.
    pub fn sensitivity(&self, x: &Point3<f64>, p: &Vector3<f64>) -> Sensitivity {
        let mut s = Sensitivity { idx: Vec::with_capacity(80), dedu: Vec::with_capacity(80) };
        self.sensitivity_into(x, p, &mut s);
        s
    }

    /// Number of coefficients per function, as a short description (e.g. `bspline(12) x 18`).
    pub fn describe(&self) -> String {
        let first = self.bases[0].repr;
        if self.bases.iter().all(|b| b.repr == first) {
            format!("{} for all 18 functions, {} parameters", first.label(), self.n_params)
        } else {
            format!("mixed representations, {} parameters", self.n_params)
        }
    }
}

/// Owner of a parameter index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamOwner {
    /// Function and coefficient index within it.
    Function(ErrorFunction, usize),
    Squareness(Squareness),
}

/// Sparse sensitivity of the volumetric error vector to the parameters: `de = sum_k dedu[k] du[idx[k]]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sensitivity {
    pub idx: Vec<usize>,
    pub dedu: Vec<Vector3<f64>>,
}

impl Sensitivity {
    pub fn clear(&mut self) {
        self.idx.clear();
        self.dedu.clear();
    }

    pub fn push(&mut self, i: usize, v: Vector3<f64>) {
        self.idx.push(i);
        self.dedu.push(v);
    }

    /// `e = de/du . u`.
    pub fn apply(&self, u: &[f64]) -> Vector3<f64> {
        self.idx.iter().zip(&self.dedu).map(|(&i, d)| d * u[i]).sum()
    }

    /// Projection onto a direction: the row `n^T de/du` as `(index, value)` pairs.
    pub fn project<'a>(&'a self, n: &'a Vector3<f64>) -> impl Iterator<Item = (usize, f64)> + 'a {
        self.idx.iter().zip(&self.dedu).map(move |(&i, d)| (i, n.dot(d)))
    }
}

/// An identified (or simulated) error model: layout plus coefficients.
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorModel {
    pub layout: ModelLayout,
    pub u: Vec<f64>,
}

impl ErrorModel {
    /// A model with all errors zero.
    pub fn zero(layout: ModelLayout) -> ErrorModel {
        let n = layout.n_params;
        ErrorModel { layout, u: vec![0.0; n] }
    }

    /// Volumetric error by the small-angle model of patent eq. (4): `sum t + sum r x h`.
    pub fn error_linear(&self, x: &Point3<f64>, p: &Vector3<f64>) -> Vector3<f64> {
        self.layout.sensitivity(x, p).apply(&self.u)
    }

    /// Value of one error function at axis coordinate `q`.
    pub fn function_value(&self, f: ErrorFunction, q: f64) -> f64 {
        self.layout.basis(f).value(&self.u[self.layout.range(f)], q)
    }

    /// Coefficients of one function.
    pub fn coeffs(&self, f: ErrorFunction) -> &[f64] {
        &self.u[self.layout.range(f)]
    }

    pub fn coeffs_mut(&mut self, f: ErrorFunction) -> &mut [f64] {
        let r = self.layout.range(f);
        &mut self.u[r]
    }

    pub fn squareness(&self, s: Squareness) -> f64 {
        self.u[self.layout.squareness_index(s)]
    }

    pub fn set_squareness(&mut self, s: Squareness, v: f64) {
        let i = self.layout.squareness_index(s);
        self.u[i] = v;
    }

    /// Sets function `f` to the projection of `g` onto its basis.
    pub fn set_function(&mut self, f: ErrorFunction, g: impl Fn(f64) -> f64) {
        let c = self.layout.basis(f).fit(g);
        self.coeffs_mut(f).copy_from_slice(&c);
    }
}
