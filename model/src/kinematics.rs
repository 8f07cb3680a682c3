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
use nalgebra::{Point3, Rotation3, Vector3};

/// Direction of motion of axis `a` including the squareness errors.
pub fn axis_direction(layout: &ModelLayout, u: &[f64], a: Axis) -> Vector3<f64> {
    let sq = |s: Squareness| u[layout.squareness_index(s)];
    match a {
        Axis::X => Vector3::x(),
        Axis::Y => Rotation3::from_axis_angle(&Vector3::z_axis(), sq(Squareness::EC0Y)) * Vector3::y(),
        Axis::Z => {
            let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), sq(Squareness::EB0Z));
            let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), sq(Squareness::EA0Z));
            rx * ry * Vector3::z()
        }
    }
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
