//! The scenario of Han et al. (2021), "Measurement method of geometric error of coordinate
//! measuring machine using laser tracer" (Advanced Engineering Sciences 53(3)): a bridge CMM of
//! topology FYXZ measured by a laser tracer at 4 stations along the 12 edges of its working
//! cuboid, with the reflector at the end of Z (zero probe offset).
//!
//! This module holds what the paper gives (Table 1: travel and steps; Table 2: the ranges of the
//! 17 identified errors; Table 3: the start points of the laser-interferometer axis lines; the
//! body diagonals of Table 4 are [`volcal::validate::body_diagonals`]) and builds from it a
//! virtual machine whose truth functions have exactly those ranges. The shapes between the
//! ends are ours: the paper publishes ranges only.
//!
//! The representation is the paper's: each function tabulated at the measured steps (70, 50,
//! 70 mm) and interpolated linearly (paper section 3.1, "线性插值"), i.e. an 11-node table per
//! function; the gauge is the paper's datum (errors zero at each axis origin, straightness zero
//! at the far end).

use crate::plan::{Acquisition, Method, Plan};
use nalgebra::Point3;
use volcal::functions::{ErrorFunction, Squareness};
use volcal::gauge::{axis_far_end, axis_origin};
use volcal::{Axis, ErrorModel, ModelLayout, Representation, Topology, Travel};

/// Table 1: travel of X, Y, Z in metres.
pub const TRAVEL_M: [[f64; 2]; 3] = [[0.0, 0.7], [-0.5, 0.0], [-0.7, 0.0]];
/// Table 1: steps of X, Y, Z along the tracer path, metres.
pub const STEP_M: [f64; 3] = [0.07, 0.05, 0.07];
/// Table 1: dwell at each point, seconds.
pub const DWELL_S: f64 = 5.0;
/// The paper's axis stacking from workpiece to tool (W-F-Y-X-Z-T).
pub const TOPOLOGY: &str = "FYXZ";
/// Nodes of each function's table: the path steps over the travel (700/70, 500/50, 700/70
/// intervals).
pub const TABLE_NODES: usize = 11;

/// Table 2: the 17 identified errors of the paper, as `(ISO name, signed range)` in the paper's
/// units (micrometres, microradians) and sign convention: the range is max - min over the
/// travel, negative when the error runs against the positive axis direction.
pub const TABLE2_FUNCTIONS: [(&str, f64); 14] = [
    ("EXX", -27.06),
    ("EYX", 3.39),
    ("EZX", 2.32),
    ("EAX", 3.57),
    ("EBX", -8.85),
    ("EXY", 4.44),
    ("EYY", 43.75),
    ("EZY", 3.15),
    ("EAY", 4.97),
    ("EBY", 3.85),
    ("ECY", -10.90),
    ("EXZ", 3.74),
    ("EYZ", 3.15),
    ("EZZ", 36.76),
];

/// Table 2: squareness errors as the paper states them, `(paper symbol, ISO squareness, value in
/// urad)`: the deviation of the included angle from 90 degrees (negative: less than 90 degrees).
pub const TABLE2_SQUARENESS: [(&str, Squareness, f64); 3] =
    [("E_A0Z", Squareness::EA0Z, -3.62), ("E_B0Z", Squareness::EB0Z, -8.87), ("E_C0X", Squareness::EC0Y, -82.89)];

/// The functions the paper drops because the reflector sits at the end of Z (zero probe
/// offset). They exist on the virtual machine (with these ranges, urad) but no reading sees
/// them; the identifiability analysis must find that out by itself.
pub const UNOBSERVED_WITH_ZERO_OFFSET: [(&str, f64); 4] = [("ECX", 6.0), ("EAZ", 4.0), ("EBZ", -5.0), ("ECZ", 3.0)];

/// The paper's maximum predicted volumetric error, metres, at the limit of the volume.
pub const PAPER_MAX_VOLUMETRIC_M: f64 = 74.64e-6;

/// Table 3: start points (metres) of the laser-interferometer lines of the axis positioning
/// comparison (figures 7-9); each line runs over the whole travel of its axis.
pub const TABLE3_AXIS_STARTS: [(Axis, [f64; 3]); 3] =
    [(Axis::X, [0.0, 0.0, -0.7]), (Axis::Y, [0.0, 0.0, -0.7]), (Axis::Z, [0.0, -0.5, -0.7])];

/// The paper's largest differences between tracer prediction and interferometer, micrometres:
/// axes X, Y, Z (figures 7-9) and diagonals NPP, NPN, PPN, PPP (figure 12).
pub const PAPER_AXIS_DIFFERENCES_UM: [(&str, f64); 3] = [("X", 4.15), ("Y", 7.43), ("Z", 5.93)];
pub const PAPER_DIAGONAL_DIFFERENCES_UM: [(&str, f64); 4] =
    [("NPP", 4.42), ("NPN", 4.89), ("PPN", 6.77), ("PPP", 10.51)];

/// The paper's travel.
pub fn travel() -> Travel {
    Travel::new(TRAVEL_M[0], TRAVEL_M[1], TRAVEL_M[2])
}

/// The paper's error-model layout: FYXZ, 11-node tables (linear interpolation between the
/// measured steps).
pub fn layout() -> ModelLayout {
    ModelLayout::uniform(Topology::parse(TOPOLOGY).expect("FYXZ is a valid topology"), travel(), representation())
}

/// The paper's representation of every function.
pub fn representation() -> Representation {
    Representation::Table { nodes: TABLE_NODES }
}

/// Shape of a function over the normalised distance `t` in [0, 1] from its axis origin, before
/// scaling to the tabulated range. All shapes are zero at the origin (the datum); straightness
/// shapes also vanish at the far end. `k` varies the shape between functions.
fn shape(f: ErrorFunction, t: f64, k: f64) -> f64 {
    use std::f64::consts::PI;
    if f.is_straightness() {
        (PI * t).sin() + 0.35 * (2.0 * PI * t + k).sin() - 0.35 * k.sin() * (1.0 - t) - 0.35 * (2.0 * PI + k).sin() * t
    } else if f.is_positioning() {
        t + 0.06 * (3.0 * PI * t).sin() + 0.02 * k * (2.0 * PI * t).sin()
    } else {
        t + 0.3 * (2.0 * PI * t + k).sin() - 0.3 * k.sin()
    }
}

/// Node values of function `f` with the signed range `range` (max - min, sign of the larger
/// excursion from the origin).
fn tabulate(layout: &ModelLayout, f: ErrorFunction, range: f64, k: f64) -> Vec<f64> {
    let origin = axis_origin(layout, f);
    let far = axis_far_end(layout, f);
    let basis = layout.basis(f);
    let n = basis.n_coeffs();
    let [lo, hi] = [basis.lo, basis.hi];
    let raw: Vec<f64> = (0..n)
        .map(|i| {
            let q = lo + (hi - lo) * i as f64 / (n - 1) as f64;
            shape(f, (q - origin) / (far - origin), k)
        })
        .collect();
    let max = raw.iter().cloned().fold(f64::MIN, f64::max);
    let min = raw.iter().cloned().fold(f64::MAX, f64::min);
    // Orient so that the larger excursion from the origin (where every shape is 0) is positive.
    let sign = if max.abs() >= min.abs() { 1.0 } else { -1.0 };
    raw.iter().map(|v| sign * v / (max - min) * range).collect()
}

/// The virtual machine's truth: the 14 functions and 3 squareness errors of Table 2 with exactly
/// the published ranges (node values of the paper's tables), and the 4 functions the paper does
/// not identify, set to the small values of [`UNOBSERVED_WITH_ZERO_OFFSET`]. Every function is
/// zero at its axis origin and every straightness also at its far end: the truth satisfies the
/// datum gauge, so its Table 2 is read off directly.
pub fn truth() -> ErrorModel {
    let layout = layout();
    assert!(matches!(layout.basis(ErrorFunction::from_index(0)).repr, Representation::Table { .. }));
    let mut m = ErrorModel::zero(layout.clone());
    let all = TABLE2_FUNCTIONS.iter().chain(UNOBSERVED_WITH_ZERO_OFFSET.iter());
    for (k, (name, value)) in all.enumerate() {
        let f = ErrorFunction::parse(name).expect("ISO names");
        let c = tabulate(&layout, f, value * 1e-6, 0.7 * k as f64);
        m.coeffs_mut(f).copy_from_slice(&c);
    }
    for (_, s, v) in TABLE2_SQUARENESS {
        // The paper gives the included-angle deviation; convert to the model's parameter.
        let sign = s.included_angle_deviation(1.0);
        m.set_squareness(s, sign * v * 1e-6);
    }
    m
}

/// Tracer station positions, metres. The paper places the tracer on the table at four positions
/// L_T1..L_T4 (its figure 4) without coordinates; these are ours: near the four corners of the
/// table, below the volume, at different heights (one on a riser) so that they are not coplanar.
pub const STATIONS_M: [[f64; 3]; 4] =
    [[-0.10, -0.60, -0.80], [0.80, -0.60, -0.75], [0.80, 0.10, -0.80], [-0.10, 0.10, -0.60]];

/// The paper's campaign: the tracer at [`STATIONS_M`], each station running the 12 edges of the
/// working cuboid with the steps of Table 1, static points with 5 s dwell, reflector at the end
/// of Z (zero probe offset).
pub fn plan() -> Plan {
    Plan {
        method: Method::Tracer,
        stations: STATIONS_M.to_vec(),
        n_stations: None,
        probe_offsets: vec![[0.0, 0.0, 0.0]],
        acquisition: Acquisition::Static { speed_mps: 0.05, dwell_s: DWELL_S },
        path_step_m: STEP_M,
        ..Plan::default()
    }
}

/// The paper's function symbol for an ISO name (`EXX` -> `E_XX`).
pub fn paper_symbol(iso: &str) -> String {
    format!("E_{}", &iso[1..])
}

/// Nominal station positions displaced by `distance_m` in a different direction for each
/// station: the "nominal" start of the estimator in the acceptance tests (the stations are only
/// roughly known where the tracer was set down).
pub fn displaced_stations(stations: &[Point3<f64>], distance_m: f64) -> Vec<Point3<f64>> {
    stations
        .iter()
        .enumerate()
        .map(|(i, q)| {
            let a = 1.3 + 2.1 * i as f64;
            let d = nalgebra::Vector3::new(a.cos(), a.sin(), if i % 2 == 0 { 0.6 } else { -0.6 }).normalize();
            q + d * distance_m
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use volcal::functions::Motion;
    use volcal::predict::function_range;

    #[test]
    fn truth_has_the_ranges_of_table_2() {
        let m = truth();
        for (name, v) in TABLE2_FUNCTIONS.iter().chain(UNOBSERVED_WITH_ZERO_OFFSET.iter()) {
            let f = ErrorFunction::parse(name).unwrap();
            let r = function_range(&m, f, 1001);
            assert!((r.signed_range * 1e6 - v).abs() < 1e-9, "{name}: {} vs {v}", r.signed_range * 1e6);
            let origin = axis_origin(&m.layout, f);
            assert!(m.function_value(f, origin).abs() < 1e-18, "{name} not zero at origin");
            if f.is_straightness() {
                assert!(m.function_value(f, axis_far_end(&m.layout, f)).abs() < 1e-18, "{name} far end");
            }
            assert!(f.motion == Motion::Translation || f.motion == Motion::Rotation);
        }
        for (_, s, v) in TABLE2_SQUARENESS {
            assert!((s.included_angle_deviation(m.squareness(s)) * 1e6 - v).abs() < 1e-12);
        }
    }

    #[test]
    fn plan_follows_table_1() {
        let p = plan();
        p.validate().unwrap();
        let tasks = p.path_tasks(&travel()).unwrap();
        assert_eq!(tasks.len(), 4);
        // 12 edges: 4 along each axis with 10 steps each, both ends included.
        assert_eq!(tasks[0].points.len(), 12 * 11);
    }
}
