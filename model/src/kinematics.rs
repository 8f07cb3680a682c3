//! Exact kinematic chain of a Cartesian machine with finite error rotations.
//!
//! The small-angle model of [`crate::model`] is the first-order expansion of this chain; the
//! simulator uses the exact chain for the "actual" reflector position so that the estimator is
//! tested against the physics rather than against its own linearisation.
//!
//! Chain from workpiece to tool (frame removed, see [`crate::topology`]):
//! `P = M_1 M_2 M_3 p` with `M_k = Trans(q_k d_k + t_k(q_k)) Rot(r_k(q_k))`, where `d_k` is the
//! axis direction including squareness (Y rotated by `EC0Y` about Z; Z rotated by `EB0Z` about Y
//! and `EA0Z` about X).

use crate::axis::Axis;
use crate::functions::{ErrorFunction, Motion, Squareness};
use crate::model::{ErrorModel, ModelLayout};
use nalgebra::{Matrix3, Point3, Rotation3, Vector3};

/// Displacement per metre of indicated travel of axis `a`, including the squareness errors.
///
/// Squareness is the shear `e_a + sum_s angle_s (about_s x e_a)`, linear in the angles, not a
/// finite rotation of the unit direction. The two differ by a length change of `angle^2 / 2`
/// (5e-10 at 30 urad), which the positioning function of the axis carries either way; the shear
/// makes the squareness/straightness-slope gauge freedom exact instead of exact to first order,
/// which keeps noise-free recovery at the picometre level.
pub fn axis_direction(layout: &ModelLayout, u: &[f64], a: Axis) -> Vector3<f64> {
    let mut d = a.unit();
    for s in Squareness::ALL {
        if s.axis() == a {
            d += s.direction_per_metre() * u[layout.squareness_index(s)];
        }
    }
    d
}

/// Translation and rotation error vectors of axis `a` at its coordinate `q`.
pub fn axis_errors(layout: &ModelLayout, u: &[f64], a: Axis, q: f64) -> (Vector3<f64>, Vector3<f64>) {
    let mut v = [0.0; 6];
    if layout.shares_basis(a) {
        // One basis evaluation for the six functions (canonical order EXa EYa EZa EAa EBa ECa).
        let offs: [usize; 6] = std::array::from_fn(|m| layout.offsets[a.index() * 6 + m]);
        layout.bases[a.index() * 6].visit(q, false, |i, b| {
            for m in 0..6 {
                v[m] += u[offs[m] + i] * b;
            }
        });
    } else {
        for (m, vm) in v.iter_mut().enumerate() {
            let f = ErrorFunction::from_index(a.index() * 6 + m);
            *vm = layout.basis(f).value(&u[layout.range(f)], q);
        }
    }
    let _ = Motion::Translation;
    (Vector3::new(v[0], v[1], v[2]), Vector3::new(v[3], v[4], v[5]))
}

/// Actual reflector position for indicated coordinates `x` and probe offset `p`.
pub fn exact_position(model: &ErrorModel, x: &Point3<f64>, p: &Vector3<f64>) -> Point3<f64> {
    exact_position_with(&model.layout, &model.u, x, p)
}

/// [`exact_position`] for a layout and coefficient vector.
pub fn exact_position_with(layout: &ModelLayout, u: &[f64], x: &Point3<f64>, p: &Vector3<f64>) -> Point3<f64> {
    Chain::new(layout, u).position(x, p)
}

/// The kinematic chain of one coefficient vector, with the axis directions (squareness)
/// evaluated once, for evaluating many positions.
pub struct Chain<'a> {
    layout: &'a ModelLayout,
    u: &'a [f64],
    dirs: [Vector3<f64>; 3],
    order: [Axis; 3],
    shared: [bool; 3],
    offsets: [[usize; 6]; 3],
}

impl<'a> Chain<'a> {
    pub fn new(layout: &'a ModelLayout, u: &'a [f64]) -> Chain<'a> {
        let dirs = Axis::ALL.map(|a| axis_direction(layout, u, a));
        let mut order = layout.topology.chain();
        order.reverse();
        Chain {
            layout,
            u,
            dirs,
            order,
            shared: Axis::ALL.map(|a| layout.shares_basis(a)),
            offsets: Axis::ALL.map(|a| std::array::from_fn(|m| layout.offsets[a.index() * 6 + m])),
        }
    }

    /// Translation and rotation errors of axis `a` at coordinate `q`.
    #[inline]
    fn errors(&self, a: Axis, q: f64) -> (Vector3<f64>, Vector3<f64>) {
        let ai = a.index();
        if !self.shared[ai] {
            return axis_errors(self.layout, self.u, a, q);
        }
        let offs = &self.offsets[ai];
        let u = self.u;
        let mut v = [0.0; 6];
        self.layout.bases[ai * 6].visit(q, false, |i, b| {
            for m in 0..6 {
                v[m] += u[offs[m] + i] * b;
            }
        });
        (Vector3::new(v[0], v[1], v[2]), Vector3::new(v[3], v[4], v[5]))
    }

    /// Actual reflector position for indicated `x` and offset `p`: `P = M_1 (M_2 (M_3 p))`.
    pub fn position(&self, x: &Point3<f64>, p: &Vector3<f64>) -> Point3<f64> {
        let mut v = *p;
        for &a in &self.order {
            let q = a.coord(x);
            let (t, r) = self.errors(a, q);
            v = self.dirs[a.index()] * q + t + rotate(&r, &v);
        }
        Point3::from(v)
    }

    /// [`Chain::position`] together with, for each axis (indexed by [`Axis::index`]), what the
    /// exact Jacobian of the position needs ([`AxisFrame`]).
    pub fn position_with_frames(&self, x: &Point3<f64>, p: &Vector3<f64>) -> (Point3<f64>, [AxisFrame; 3]) {
        self.frames_with(x, p, |a, q| self.errors(a, q))
    }

    /// [`Chain::position_with_frames`] with the basis values of each axis given (first
    /// coefficient index and values, for a layout whose axes share one representation), so that
    /// repeated evaluations at the same coordinates skip the basis evaluation.
    pub fn position_with_frames_cached(
        &self,
        x: &Point3<f64>,
        p: &Vector3<f64>,
        basis: [(usize, &[f64]); 3],
    ) -> (Point3<f64>, [AxisFrame; 3]) {
        self.frames_with(x, p, |a, _| {
            let (first, b) = basis[a.index()];
            let offs = &self.offsets[a.index()];
            let mut v = [0.0; 6];
            for (m, vm) in v.iter_mut().enumerate() {
                let c = &self.u[offs[m] + first..offs[m] + first + b.len()];
                *vm = c.iter().zip(b).map(|(c, b)| c * b).sum();
            }
            (Vector3::new(v[0], v[1], v[2]), Vector3::new(v[3], v[4], v[5]))
        })
    }

    #[inline]
    fn frames_with(
        &self,
        x: &Point3<f64>,
        p: &Vector3<f64>,
        errors: impl Fn(Axis, f64) -> (Vector3<f64>, Vector3<f64>),
    ) -> (Point3<f64>, [AxisFrame; 3]) {
        let mut frames = [AxisFrame::default(); 3];
        let mut v = *p;
        // Tool end first: the vector each axis carries.
        for &a in &self.order {
            let q = a.coord(x);
            let (t, r) = errors(a, q);
            let carried = rotate(&r, &v);
            frames[a.index()].carried = carried;
            frames[a.index()].r = r;
            v = self.dirs[a.index()] * q + t + carried;
        }
        // Workpiece end first: the rotation accumulated before each axis.
        let mut acc = Matrix3::identity();
        for &a in self.order.iter().rev() {
            frames[a.index()].before = acc;
            acc *= rotation_matrix(&frames[a.index()].r);
        }
        (Point3::from(v), frames)
    }
}

/// Per axis, the parts of the exact Jacobian of the actual position.
///
/// With `M_k = Trans(q d + t) Rot(r)` and `P = R_<k (q d + t + Rot(r) v) + ...`, where `R_<k` is
/// the product of the rotations of the axes between the workpiece and `k`, and `v` what `k`
/// carries: `dP/dt = R_<k`, and `dP/dr = -R_<k [Rot(r) v]x J_l(r)` with the left Jacobian of
/// SO(3) `J_l(r) = I + [r]x / 2 + O(r^2)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisFrame {
    /// `R_<k`.
    pub before: Matrix3<f64>,
    /// `Rot(r) v`: the carried vector, rotated by the axis's own rotation error.
    pub carried: Vector3<f64>,
    /// The axis's rotation error vector at its coordinate.
    pub r: Vector3<f64>,
}

impl Default for AxisFrame {
    fn default() -> Self {
        AxisFrame { before: Matrix3::identity(), carried: Vector3::zeros(), r: Vector3::zeros() }
    }
}

impl AxisFrame {
    /// The derivatives of `n . P` with respect to the axis's six error values
    /// (translations along X, Y, Z; rotations about X, Y, Z).
    #[inline]
    pub fn projected(&self, n: &Vector3<f64>) -> [f64; 6] {
        let nk = self.before.transpose() * n;
        let w = self.carried.cross(&nk);
        let c = 0.5 * w.cross(&self.r);
        [nk.x, nk.y, nk.z, w.x + c.x, w.y + c.y, w.z + c.z]
    }

    /// The derivative of `n . P` with respect to squareness `s` of this axis at coordinate `q`.
    #[inline]
    pub fn projected_squareness(&self, n: &Vector3<f64>, s: Squareness, q: f64) -> f64 {
        (self.before.transpose() * n).dot(&s.direction_per_metre()) * q
    }
}

/// Rotation matrix of a rotation vector; the series to second order for error-sized angles
/// (exact to `|r|^3 / 6`), the trigonometric form beyond.
#[inline]
pub fn rotation_matrix(r: &Vector3<f64>) -> Matrix3<f64> {
    if r.norm_squared() < 1e-6 {
        let k = r.cross_matrix();
        Matrix3::identity() + k + 0.5 * k * k
    } else {
        *Rotation3::new(*r).matrix()
    }
}

/// Rotation of `v` by the rotation vector `r`. For the error rotations (|r| < 1e-3 rad) the
/// series `v + r x v + (r x (r x v))/2` is exact to `|r|^3 |v| / 6` (< 1e-10 m at 1 mrad and
/// 1 m; < 1e-16 m at 10 urad), far cheaper than the trigonometric form, which is used beyond.
#[inline]
pub fn rotate(r: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    if r.norm_squared() < 1e-6 {
        let rv = r.cross(v);
        v + rv + 0.5 * r.cross(&rv)
    } else {
        Rotation3::new(*r) * v
    }
}

/// The exact volumetric error of a model. It lives here, not in [`crate::model`], so that the
/// model's layout and small-angle algebra know nothing of the exact chain built on them.
impl ErrorModel {
    /// Volumetric error `e(X, p)`: actual minus indicated reflector position, by the exact
    /// kinematic chain (finite rotations). It differs from [`ErrorModel::error_linear`] by
    /// second-order terms (rotation squared times lever arm: about 1 nm for 30 urad over 1 m).
    pub fn error(&self, x: &Point3<f64>, p: &Vector3<f64>) -> Vector3<f64> {
        self.exact_position(x, p) - (x + p)
    }

    /// Actual reflector position by the exact homogeneous-transform chain (finite rotations).
    /// The small-angle [`ErrorModel::error`] equals `exact_position - (x + p)` to second order.
    pub fn exact_position(&self, x: &Point3<f64>, p: &Vector3<f64>) -> Point3<f64> {
        exact_position(self, x, p)
    }
}
