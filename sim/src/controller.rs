//! A controller's compensation acting on the simulated machine, so that the compensated machine
//! can be measured again (the closed loop of `volcal simulate --compensation`):
//!
//! - [`JointCompensation`]: what a controller adds to each joint's command from per-joint tables
//!   (linear interpolation between table nodes, end values held outside, one column moving up
//!   and one moving down, the last one held when stopped), as LinuxCNC does;
//! - [`GridCompensation`]: a volumetric correction vector on a 3-D grid, interpolated
//!   trilinearly at the commanded position and added to the three axes' commands, as grid
//!   compensation of controllers does. It refers to one tool point: the angular errors act
//!   on any other tool offset uncorrected;
//! - [`AxisTableCompensation`]: tables from one axis's position to a correction of one axis
//!   (itself or another), linear between nodes, ends held, summed: SINUMERIK's leadscrew error
//!   (EEC) and sag/cross (CEC) compensation;
//! - [`VolumetricCompensation`]: the 21 error functions as tables, which the controller turns
//!   into the error at the commanded position and the active tool through the machine's
//!   kinematic chain and removes by moving the three axes, as the ISG kernel's (TwinCAT TF5280)
//!   volumetric compensation does: tool-aware, so it corrects every tool offset.

use crate::inject::{Injection, Sample};
use nalgebra::{Point3, Vector3};
use volcal::{Axis, ErrorModel};

/// Linear interpolation in a table with ascending `x`, end values held outside: how LinuxCNC
/// (and most controllers) read a compensation table between its nodes.
pub fn interpolate(x: &[f64], y: &[f64], q: f64) -> f64 {
    let (i, s) = bracket(x, q);
    if s == 0.0 {
        y[i]
    } else {
        y[i] + s * (y[i + 1] - y[i])
    }
}

/// Where `q` falls in the ascending nodes `x`: the node `i` at or below it and the fraction `s`
/// of the way to node `i + 1` (`s` is 0 on a node and outside the table, at the nearest end).
/// Several columns over the same nodes share one lookup.
pub fn bracket(x: &[f64], q: f64) -> (usize, f64) {
    if q <= x[0] {
        return (0, 0.0);
    }
    if q >= x[x.len() - 1] {
        return (x.len() - 1, 0.0);
    }
    let i = x.partition_point(|v| *v <= q) - 1;
    (i, (q - x[i]) / (x[i + 1] - x[i]))
}

/// One joint's table: offsets (metres) added to the command, by direction of travel.
#[derive(Clone, Debug, PartialEq)]
pub struct JointOffsets {
    pub nominal_m: Vec<f64>,
    pub forward_m: Vec<f64>,
    pub reverse_m: Vec<f64>,
}

/// Per-joint compensation of X, Y, Z (a joint without a table is not compensated).
pub struct JointCompensation {
    pub joints: [Option<JointOffsets>; 3],
}

impl Injection for JointCompensation {
    fn id(&self) -> &str {
        "controller_compensation"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        ["x", "y", "z"]
            .iter()
            .zip(&self.joints)
            .map(|(a, j)| (format!("{a}_nodes"), j.as_ref().map_or(0.0, |j| j.nominal_m.len() as f64)))
            .collect()
    }
    fn describe(&self) -> String {
        "per-joint compensation tables applied by the controller".into()
    }
    /// The joint moves by the offset: the actual position shifts along the joint's axis (the
    /// error functions' change over a few micrometres of travel is negligible).
    fn actual(&self, s: &Sample, actual: &mut Point3<f64>) {
        for (k, j) in self.joints.iter().enumerate() {
            if let Some(j) = j {
                let column = if s.motion[k] < 0.0 { &j.reverse_m } else { &j.forward_m };
                actual[k] += interpolate(&j.nominal_m, column, s.x[k]);
            }
        }
    }
}

/// A volumetric correction on a grid: the vector (metres) a controller adds to the commanded
/// position, at the nodes `x_m` x `y_m` x `z_m` (ascending), `x` varying fastest.
#[derive(Clone, Debug, PartialEq)]
pub struct GridCompensation {
    pub axes_m: [Vec<f64>; 3],
    pub correction_m: Vec<[f64; 3]>,
}

impl GridCompensation {
    /// The correction at `q`: trilinear interpolation in the cell holding `q`, end values held
    /// outside the grid (as a per-joint table holds its ends).
    pub fn at(&self, q: &Point3<f64>) -> [f64; 3] {
        // Per axis: the lower node index and the weight of the upper one.
        let cell = |a: usize| -> (usize, f64) {
            let x = &self.axes_m[a];
            if x.len() < 2 || q[a] <= x[0] {
                return (0, 0.0);
            }
            if q[a] >= x[x.len() - 1] {
                return (x.len() - 2, 1.0);
            }
            let i = x.partition_point(|v| *v <= q[a]) - 1;
            (i, (q[a] - x[i]) / (x[i + 1] - x[i]))
        };
        let (nx, ny) = (self.axes_m[0].len(), self.axes_m[1].len());
        let (c, w) = ([cell(0), cell(1), cell(2)], |k: usize, f: f64| if k == 0 { 1.0 - f } else { f });
        let mut out = [0.0; 3];
        for (dz, dy, dx) in (0..8).map(|b| (b >> 2 & 1, b >> 1 & 1, b & 1)) {
            let weight = w(dx, c[0].1) * w(dy, c[1].1) * w(dz, c[2].1);
            if weight == 0.0 {
                continue;
            }
            let (i, j, k) =
                ((c[0].0 + dx).min(nx - 1), (c[1].0 + dy).min(ny - 1), (c[2].0 + dz).min(self.axes_m[2].len() - 1));
            let v = self.correction_m[i + nx * (j + ny * k)];
            for (o, v) in out.iter_mut().zip(v) {
                *o += weight * v;
            }
        }
        out
    }
}

impl Injection for GridCompensation {
    fn id(&self) -> &str {
        "controller_grid_compensation"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        ["x", "y", "z"].iter().zip(&self.axes_m).map(|(a, n)| (format!("{a}_nodes"), n.len() as f64)).collect()
    }
    fn describe(&self) -> String {
        "volumetric grid compensation applied by the controller".into()
    }
    /// The three axes move by the correction at the commanded position.
    fn actual(&self, s: &Sample, actual: &mut Point3<f64>) {
        let c = self.at(&s.x);
        for k in 0..3 {
            actual[k] += c[k];
        }
    }
}

/// One interpolatory table: the position of `input` selects, linearly between `nominal_m`
/// (ascending, end values held outside), the correction (metres) added to `output`'s command.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisTable {
    pub input: Axis,
    pub output: Axis,
    pub nominal_m: Vec<f64>,
    pub correction_m: Vec<f64>,
}

/// Tables from one axis to a correction of one axis, summed (SINUMERIK EEC + CEC).
#[derive(Clone, Debug, PartialEq)]
pub struct AxisTableCompensation {
    pub tables: Vec<AxisTable>,
}

impl AxisTableCompensation {
    /// The correction the tables add to the three axes at the commanded position `x`, metres.
    pub fn at(&self, x: &Point3<f64>) -> Vector3<f64> {
        let mut c = Vector3::zeros();
        for t in &self.tables {
            c[t.output.index()] += interpolate(&t.nominal_m, &t.correction_m, x[t.input.index()]);
        }
        c
    }
}

impl Injection for AxisTableCompensation {
    fn id(&self) -> &str {
        "controller_axis_table_compensation"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![("tables".into(), self.tables.len() as f64)]
    }
    fn describe(&self) -> String {
        "axis tables (leadscrew and cross-axis compensation) applied by the controller".into()
    }
    /// The axes move by the tables' corrections at the commanded position.
    fn actual(&self, s: &Sample, actual: &mut Point3<f64>) {
        *actual += self.at(&s.x);
    }
}

/// Volumetric compensation from the 21 error functions: `tables` holds them (the controller's
/// tables, typically [`volcal::Representation::Table`], linear between nodes) with the machine's
/// topology; the controller computes the error at the commanded position and the tool by the
/// small-angle chain (patent eq. 4, as a controller's kinematic transformation does) and
/// subtracts it.
pub struct VolumetricCompensation {
    pub tables: ErrorModel,
}

impl VolumetricCompensation {
    /// The correction added to the three axes at commanded position `x` with tool offset `p`.
    pub fn at(&self, x: &Point3<f64>, p: &Vector3<f64>) -> Vector3<f64> {
        -self.tables.error_linear(x, p)
    }
}

impl Injection for VolumetricCompensation {
    fn id(&self) -> &str {
        "controller_volumetric_compensation"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        Axis::ALL
            .iter()
            .map(|&a| {
                let f = volcal::ErrorFunction::from_index(a.index() * 6);
                (format!("{}_nodes", a.letter().to_ascii_lowercase()), self.tables.coeffs(f).len() as f64)
            })
            .collect()
    }
    fn describe(&self) -> String {
        "volumetric compensation (21 error functions, tool-aware) applied by the controller".into()
    }
    /// The three axes move by minus the error at the commanded position and the sample's tool.
    fn actual(&self, s: &Sample, actual: &mut Point3<f64>) {
        *actual += self.at(&s.x, &s.p);
    }
}

#[cfg(test)]
mod tests {
    use super::{interpolate, GridCompensation};
    use nalgebra::Point3;

    #[test]
    fn grid_interpolates_trilinearly_and_holds_the_ends() {
        // Correction = (x + 2y + 3z, 1, xyz) on a 2 x 3 x 2 grid: trilinear interpolation
        // reproduces it exactly inside (each component is linear in each coordinate).
        let axes_m = [vec![0.0, 1.0], vec![0.0, 0.5, 1.0], vec![-1.0, 0.0]];
        let f = |x: f64, y: f64, z: f64| [x + 2.0 * y + 3.0 * z, 1.0, x * y * z];
        let mut correction_m = Vec::new();
        for z in &axes_m[2] {
            for y in &axes_m[1] {
                for x in &axes_m[0] {
                    correction_m.push(f(*x, *y, *z));
                }
            }
        }
        let g = GridCompensation { axes_m, correction_m };
        for q in [[0.3, 0.7, -0.2], [0.0, 0.0, -1.0], [1.0, 1.0, 0.0], [0.5, 0.25, -0.5]] {
            let (c, want) = (g.at(&Point3::from(q)), f(q[0], q[1], q[2]));
            for k in 0..3 {
                assert!((c[k] - want[k]).abs() < 1e-12, "{q:?}: {c:?} vs {want:?}");
            }
        }
        // Outside: the nearest face's value.
        assert_eq!(g.at(&Point3::new(2.0, 0.5, -0.5)), g.at(&Point3::new(1.0, 0.5, -0.5)));
    }

    #[test]
    fn interpolates_between_nodes_and_holds_the_ends() {
        let (x, y) = ([0.0, 1.0, 2.0], [1.0, 3.0, -1.0]);
        assert_eq!(interpolate(&x, &y, -5.0), 1.0);
        assert_eq!(interpolate(&x, &y, 0.5), 2.0);
        assert_eq!(interpolate(&x, &y, 1.5), 1.0);
        assert_eq!(interpolate(&x, &y, 9.0), -1.0);
    }

    #[test]
    fn volumetric_compensation_removes_the_error_at_any_tool_and_axis_tables_add_up() {
        use super::{AxisTable, AxisTableCompensation, VolumetricCompensation};
        use nalgebra::Vector3;
        use rand::SeedableRng;
        use volcal::{Axis, ModelLayout, Representation, Travel};
        let layout = ModelLayout::uniform(
            "XFYZ".parse().unwrap(),
            Travel::new([0.0, 0.8], [0.0, 0.5], [-0.5, 0.0]),
            Representation::BSpline { intervals: 6 },
        );
        let m = crate::random_truth(layout, &Default::default(), &mut rand_chacha::ChaCha8Rng::seed_from_u64(9));
        let e_norm = m.error(&Point3::new(0.7, 0.1, -0.4), &Vector3::new(0.1, 0.0, -0.2)).norm();
        let c = VolumetricCompensation { tables: m.clone() };
        for (x, p) in [
            (Point3::new(0.7, 0.1, -0.4), Vector3::new(0.1, 0.0, -0.2)),
            (Point3::new(0.2, 0.45, -0.05), Vector3::new(0.0, 0.0, -0.3)),
        ] {
            // The exact chain differs from the small-angle one only to second order.
            let left = m.error(&x, &p) + c.at(&x, &p);
            assert!(left.norm() < 1e-3 * e_norm, "{left}");
        }
        let t = AxisTableCompensation {
            tables: vec![
                AxisTable { input: Axis::X, output: Axis::X, nominal_m: vec![0.0, 1.0], correction_m: vec![0.0, 2.0] },
                AxisTable { input: Axis::X, output: Axis::Y, nominal_m: vec![0.0, 1.0], correction_m: vec![1.0, 1.0] },
                AxisTable { input: Axis::Z, output: Axis::Y, nominal_m: vec![-1.0, 0.0], correction_m: vec![4.0, 0.0] },
            ],
        };
        assert_eq!(t.at(&Point3::new(0.25, 9.0, -0.5)), Vector3::new(0.5, 3.0, 0.0));
    }
}
