//! Compensation files that controllers load, computed from an identified model.
//!
//! - [`linuxcnc`]: LinuxCNC's per-joint `COMP_FILE`s (`[JOINT_n] COMP_FILE_TYPE = 0|1`): each line
//!   `nominal forward reverse` in machine units (mm), nominal ascending, at most 256 lines; the
//!   controller interpolates linearly between lines and holds the end values outside.
//!   `COMP_FILE_TYPE 1`: the columns are the offsets added to the commanded position;
//!   `COMP_FILE_TYPE 0`: the columns are where the machine actually is when commanded to the
//!   nominal position (offset = nominal - column).
//! - [`grid`]: the volumetric error vector and its U95 on a 3-D grid over the working volume,
//!   for controllers with grid compensation and any tool downstream.
//! - What the per-axis exports share (here and in [`crate::isg`], [`crate::sinumerik`]): the
//!   nodes of a table ([`Nodes`]: evenly spaced, or at an axis's measured positions), the
//!   model sampled along the reference lines
//!   ([`reference_lines`]) and the error a compensation leaves ([`residual`]).
//!
//! Sign convention (DESIGN.md): `e = actual - (commanded + probe offset)`. A controller that
//! adds `offset(q)` to the command `q` lands at `q + offset + e`, so the correction is
//! `offset = -e`, evaluated at the commanded position.

use anyhow::{bail, Context, Result};
use nalgebra::{Point3, Vector3};
use std::fmt::Write as _;
use std::path::Path;
use volcal::predict::{self, AxisResolution, Uncertainty};
use volcal::{Axis, ErrorModel, Travel};
use volcal_sim::controller::{interpolate, JointCompensation, JointOffsets};

/// LinuxCNC reads at most this many lines of a `COMP_FILE`.
pub const LINUXCNC_MAX_LINES: usize = 256;

/// How a LinuxCNC table states its correction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CompFileType {
    /// Columns: where the machine actually is at the nominal position.
    Actual = 0,
    /// Columns: the offset added to the commanded position.
    Offset = 1,
}

/// The positioning correction of one joint along its travel.
#[derive(Clone, Debug, PartialEq)]
pub struct JointTable {
    pub axis: Axis,
    /// Nominal (commanded) positions, metres, ascending.
    pub nominal_m: Vec<f64>,
    /// Offset to add to the command there, metres, without reversal.
    pub offset_m: Vec<f64>,
    /// Reversal error (backlash) of the joint, metres: moving up, the axis lags by half of it
    /// behind the command, moving down it leads by half (`volcal_sim`'s `reversal`, the
    /// diagnosis catalogue's parameter). Zero when unknown.
    pub backlash_m: f64,
}

impl JointTable {
    /// The offset a controller interpolating this table linearly applies at `q` (end values held
    /// outside), metres.
    pub fn offset_at(&self, q: f64) -> f64 {
        interpolate(&self.nominal_m, &self.offset_m, q)
    }

    /// Offsets moving up (forward) and down (reverse) at node `i`: the backlash's half is added
    /// moving up (the axis lags) and taken off moving down.
    pub fn directional(&self, i: usize) -> (f64, f64) {
        let h = 0.5 * self.backlash_m;
        (self.offset_m[i] + h, self.offset_m[i] - h)
    }

    /// The file text: `nominal forward reverse` in millimetres, one node per line.
    pub fn linuxcnc_text(&self, kind: CompFileType) -> String {
        let mut out = String::new();
        for (i, q) in self.nominal_m.iter().enumerate() {
            let column = |o: f64| match kind {
                CompFileType::Offset => o * 1e3,
                CompFileType::Actual => (q - o) * 1e3,
            };
            let (f, r) = self.directional(i);
            let _ = writeln!(out, "{:.6} {:.9} {:.9}", q * 1e3, column(f), column(r));
        }
        out
    }
}

/// The model's error vector sampled along one axis's reference line: the axis at each node, the
/// other axes at the reference point. Every per-axis export (LinuxCNC, Sinumerik) reads its
/// tables from these lines, so they all refer to the same points.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceLine {
    pub axis: Axis,
    /// Nodes (commanded positions of `axis`), metres, ascending ([`Nodes::along`]).
    pub nominal_m: Vec<f64>,
    /// The volumetric error `e = actual - (commanded + probe offset)` at each node, metres.
    pub error_m: Vec<Vector3<f64>>,
}

/// Checks a node spacing given on the command line.
pub fn check_step(step_m: f64) -> Result<()> {
    if !(step_m > 0.0 && step_m.is_finite()) {
        bail!("--step-mm must be a positive number of millimetres, got {}", step_m * 1e3);
    }
    Ok(())
}

/// Where the nodes of each axis's table lie (`volcal export --nodes`).
///
/// Evenly spaced by default. Along an axis whose readings contradict the model's interpolation
/// between its measured positions ([`AxisResolution::AtPositions`] with `contradicted`, e.g. a
/// laser tracer's stops over a feature shorter than their spacing), the error is determined by
/// the data only at those positions; [`Nodes::at_measured`] puts the nodes there, so that a
/// table holds only what the data determine and between its nodes there is only the
/// controller's own linear interpolation (which the README of the export says).
#[derive(Clone, Debug, PartialEq)]
pub struct Nodes {
    /// Spacing of evenly placed nodes, metres.
    pub step_m: f64,
    /// Per axis, the measured positions that are the nodes (metres, ascending); `None`: even.
    pub measured: [Option<Vec<f64>>; 3],
}

/// Measured positions closer than this to an even spacing (metres) are taken as evenly spaced
/// by the controllers whose tables need it (ISG `Interpolation GRID`, SINUMERIK): a stop
/// commanded on a regular pitch lands there within rounding.
pub const EVEN_WITHIN_M: f64 = 1e-6;

impl Nodes {
    /// Evenly spaced nodes about `step_m` apart on every axis.
    pub fn even(step_m: f64) -> Nodes {
        Nodes { step_m, measured: [None, None, None] }
    }

    /// Evenly spaced nodes, except on each axis whose readings contradict the interpolation
    /// between its measured positions: there the nodes are the positions. (An axis whose
    /// readings bear the interpolation out keeps even nodes: the model is determined between
    /// its positions, and finer nodes follow it.)
    pub fn at_measured(step_m: f64, resolution: &[AxisResolution; 3]) -> Nodes {
        let measured = std::array::from_fn(|k| match &resolution[k] {
            AxisResolution::AtPositions { positions, contradicted: true, .. } => Some(positions.clone()),
            _ => None,
        });
        Nodes { step_m, measured }
    }

    /// Whether any axis has its nodes at measured positions.
    pub fn any_measured(&self) -> bool {
        self.measured.iter().any(Option::is_some)
    }

    /// The measured positions that are the nodes of `a`, if they are.
    pub fn measured_on(&self, a: Axis) -> Option<&[f64]> {
        self.measured[a.index()].as_deref()
    }

    /// The nodes of `a` within `travel`: evenly spaced about `step_m` apart, ends included, or
    /// the measured positions inside the travel. Refused, with what to change, when there are
    /// more than `max_nodes` (`controller` names whose limit it is), or when `evenly` (the
    /// controller's table has one step) and the measured positions are not evenly spaced;
    /// measured positions within [`EVEN_WITHIN_M`] of an even spacing are placed on it.
    pub fn along(
        &self,
        travel: &Travel,
        a: Axis,
        max_nodes: usize,
        evenly: bool,
        controller: &str,
    ) -> Result<Vec<f64>> {
        check_step(self.step_m)?;
        let [lo, hi] = travel.range(a);
        let Some(measured) = self.measured_on(a) else {
            return even_nodes(lo, hi, self.step_m, max_nodes, a, controller);
        };
        let q: Vec<f64> =
            measured.iter().copied().filter(|&q| q >= lo - EVEN_WITHIN_M && q <= hi + EVEN_WITHIN_M).collect();
        if q.len() < 2 {
            bail!(
                "axis {}: {} measured position(s) inside the travel; a table needs at least 2 (use --nodes even)",
                a.letter(),
                q.len()
            );
        }
        if q.len() > max_nodes {
            bail!(
                "axis {}: {} measured positions; {controller} reads at most {max_nodes} nodes per table (use --nodes even)",
                a.letter(),
                q.len()
            );
        }
        if !evenly {
            return Ok(q);
        }
        let (first, last, n) = (q[0], q[q.len() - 1], q.len());
        let even: Vec<f64> = (0..n).map(|i| first + (last - first) * i as f64 / (n - 1) as f64).collect();
        let off = q.iter().zip(&even).map(|(m, e)| (m - e).abs()).fold(0.0, f64::max);
        if off > EVEN_WITHIN_M {
            bail!(
                "axis {}: the {n} measured positions are not evenly spaced ({:.3} mm off an even step), and {controller}'s tables have one step; use --format linuxcnc or grid, or --nodes even",
                a.letter(),
                off * 1e3
            );
        }
        Ok(even)
    }

    /// One line per axis saying where its nodes lie and, on an axis with nodes at measured
    /// positions, what lies between them: the model's interpolation that the readings bear
    /// out, or, where they contradict it, nothing the data determine.
    pub fn describe(&self, travel: &Travel, resolution: &[AxisResolution; 3]) -> String {
        let mut out = Vec::new();
        for a in Axis::ALL {
            let Some(q) = self.measured_on(a) else {
                let [lo, hi] = travel.range(a);
                let n = even_count(lo, hi, self.step_m).max(2);
                out.push(format!(
                    "{}: {n} nodes evenly spaced about {} mm apart over the identified travel, ends included",
                    a.letter(),
                    fmt_mm(self.step_m)
                ));
                continue;
            };
            let between = if resolution[a.index()].is_contradicted() {
                format!(
                    "the readings contradict the model's interpolation between them, so the error there is NOT DETERMINED by the data: the controller's linear interpolation between these nodes is not a measured value (measure at more positions along {} to know it)",
                    a.letter()
                )
            } else {
                "the controller interpolates linearly between them".to_string()
            };
            out.push(format!(
                "{}: {} nodes at the measured positions {} to {} mm (about {} mm apart); {between}",
                a.letter(),
                q.len(),
                fmt_mm(q[0]),
                fmt_mm(q[q.len() - 1]),
                fmt_mm(predict::median_spacing(q))
            ));
        }
        out.join("\n")
    }

    /// The reference point of per-axis tables when none is given: the travel's centre, moved
    /// on each axis with measured nodes to the measured position nearest to it (between two
    /// positions of an axis whose interpolation is contradicted, the other axes' lines would not
    /// be determined).
    pub fn default_point(&self, travel: &Travel) -> Point3<f64> {
        Point3::from(Vector3::from_fn(|i, _| {
            let centre = 0.5 * (travel.ranges[i][0] + travel.ranges[i][1]);
            match &self.measured[i] {
                Some(q) if !q.is_empty() => {
                    q.iter().copied().min_by(|a, b| (a - centre).abs().total_cmp(&(b - centre).abs())).unwrap_or(centre)
                }
                _ => centre,
            }
        }))
    }
}

/// Millimetres with no more digits than they need (0.1 um).
fn fmt_mm(m: f64) -> String {
    let s = format!("{:.4}", m * 1e3);
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// How many nodes about `step_m` apart span `[lo, hi]`, ends included (before the minimum of 2).
fn even_count(lo: f64, hi: f64, step_m: f64) -> usize {
    ((hi - lo) / step_m).round() as usize + 1
}

/// Evenly spaced nodes over `[lo, hi]`, about `step_m` apart, ends included; refused with what
/// to change when there are more than `max_nodes`.
fn even_nodes(lo: f64, hi: f64, step_m: f64, max_nodes: usize, a: Axis, controller: &str) -> Result<Vec<f64>> {
    let n = even_count(lo, hi, step_m);
    if n > max_nodes {
        bail!(
            "axis {}: {n} nodes at {} mm over {:.1} mm of travel; {controller} reads at most {max_nodes} nodes per table (use --step-mm {:.3} or more)",
            a.letter(),
            step_m * 1e3,
            (hi - lo) * 1e3,
            (hi - lo) / (max_nodes - 1) as f64 * 1e3
        );
    }
    let n = n.max(2);
    Ok((0..n).map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64).collect())
}

/// The three reference lines through `point` (machine coordinates, metres, inside the travel),
/// tool at probe offset `probe`, nodes as [`Nodes::along`] places them (`evenly`: the
/// controller's tables have one step).
pub fn reference_lines(
    model: &ErrorModel,
    nodes: &Nodes,
    point: &Point3<f64>,
    probe: &Vector3<f64>,
    max_nodes: usize,
    evenly: bool,
    controller: &str,
) -> Result<Vec<ReferenceLine>> {
    let travel = model.layout.travel;
    if !travel.contains(point, 1e-9) {
        bail!(
            "--point ({}, {}, {}) m lies outside the identified travel; the tables refer to a point inside it",
            point.x,
            point.y,
            point.z
        );
    }
    Axis::ALL
        .iter()
        .map(|&a| {
            let nominal_m = nodes.along(&travel, a, max_nodes, evenly, controller)?;
            let error_m = nominal_m
                .iter()
                .map(|&q| {
                    let mut x = *point;
                    x[a.index()] = q;
                    model.error(&x, probe)
                })
                .collect();
            Ok(ReferenceLine { axis: a, nominal_m, error_m })
        })
        .collect()
}

/// The per-joint positioning tables of LinuxCNC: for each axis, its `nodes` over the model's
/// travel, with the other axes at `point` (machine coordinates, metres) and the
/// tool at probe offset `probe`; the correction is minus the error component along the axis,
/// and `backlash_m` (per axis, metres) splits it by direction of travel.
pub fn linuxcnc(
    model: &ErrorModel,
    nodes: &Nodes,
    point: &Point3<f64>,
    probe: &Vector3<f64>,
    backlash_m: [f64; 3],
) -> Result<Vec<JointTable>> {
    let lines = reference_lines(model, nodes, point, probe, LINUXCNC_MAX_LINES, false, "LinuxCNC")?;
    Ok(lines
        .into_iter()
        .map(|l| {
            let k = l.axis.index();
            let offset_m = l.error_m.iter().map(|e| -e[k]).collect();
            JointTable { axis: l.axis, nominal_m: l.nominal_m, offset_m, backlash_m: backlash_m[k] }
        })
        .collect())
}

/// The correction per-joint tables add at `x`: each joint's offset on its own axis.
pub fn joint_correction(tables: &[JointTable], x: &Point3<f64>) -> Vector3<f64> {
    let mut c = Vector3::zeros();
    for t in tables {
        c[t.axis.index()] += t.offset_at(x[t.axis.index()]);
    }
    c
}

/// Reads the `x.comp`, `y.comp`, `z.comp` of `dir` (those present) as LinuxCNC does (lines of
/// three numbers `nominal forward reverse` in mm until the first line that is not, at most
/// [`LINUXCNC_MAX_LINES`]), as the offsets the controller adds to each joint's command.
pub fn read_linuxcnc(dir: &Path, kind: CompFileType) -> Result<JointCompensation> {
    let mut joints: [Option<JointOffsets>; 3] = [None, None, None];
    for (k, a) in ["x", "y", "z"].iter().enumerate() {
        let path = dir.join(format!("{a}.comp"));
        if !path.exists() {
            continue;
        }
        let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
        let mut j = JointOffsets { nominal_m: Vec::new(), forward_m: Vec::new(), reverse_m: Vec::new() };
        for line in text.lines().take(LINUXCNC_MAX_LINES) {
            let v = match line.split_whitespace().map(str::parse).collect::<Result<Vec<f64>, _>>() {
                Ok(v) if v.len() == 3 => v,
                _ => break, // where LinuxCNC stops reading
            };
            let offset = |c: f64| match kind {
                CompFileType::Offset => c * 1e-3,
                CompFileType::Actual => (v[0] - c) * 1e-3,
            };
            j.nominal_m.push(v[0] * 1e-3);
            j.forward_m.push(offset(v[1]));
            j.reverse_m.push(offset(v[2]));
        }
        if j.nominal_m.len() < 2 {
            bail!("{}: fewer than two lines of three numbers (LinuxCNC would ignore the table)", path.display());
        }
        if j.nominal_m.windows(2).any(|w| w[1] <= w[0]) {
            bail!("{}: nominal positions are not ascending", path.display());
        }
        joints[k] = Some(j);
    }
    if joints.iter().all(|j| j.is_none()) {
        bail!("{}: no x.comp, y.comp or z.comp", dir.display());
    }
    Ok(JointCompensation { joints })
}

/// What a set of per-joint tables leaves of the volumetric error, on a grid of `step_m` at probe
/// offset `probe`: RMS and largest length of the error before and after the correction, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Residual {
    /// Grid points the figures are over.
    pub points: usize,
    /// Grid points in all (more than `points` where the data leave the error open at some).
    pub grid_points: usize,
    pub rms_before_m: f64,
    pub max_before_m: f64,
    pub rms_after_m: f64,
    pub max_after_m: f64,
}

/// The error that remains where a controller adds `correction(x)` to the command at `x` (for
/// per-joint tables, [`joint_correction`]: what a per-joint positioning compensation cannot
/// express: straightness, angular errors away from the table's reference point, squareness).
pub fn residual(
    model: &ErrorModel,
    step_m: f64,
    probe: &Vector3<f64>,
    correction: impl Fn(&Point3<f64>) -> Vector3<f64>,
) -> Residual {
    residual_where(model, step_m, probe, |_| true, correction)
}

/// [`residual`] over the grid points where `keep` holds (e.g. where the data determine the
/// error: elsewhere the model's value, and so what a table leaves of it, is no measured figure).
pub fn residual_where(
    model: &ErrorModel,
    step_m: f64,
    probe: &Vector3<f64>,
    keep: impl Fn(&Point3<f64>) -> bool,
    correction: impl Fn(&Point3<f64>) -> Vector3<f64>,
) -> Residual {
    let (mut s0, mut m0, mut s1, mut m1, mut n) = (0.0, 0.0f64, 0.0, 0.0f64, 0usize);
    let grid = predict::grid(&model.layout.travel, step_m);
    let grid_points = grid.len();
    for x in grid.into_iter().filter(|x| keep(x)) {
        let e = model.error(&x, probe);
        let r = e + correction(&x);
        s0 += e.norm_squared();
        s1 += r.norm_squared();
        m0 = m0.max(e.norm());
        m1 = m1.max(r.norm());
        n += 1;
    }
    let k = n.max(1) as f64;
    Residual {
        points: n,
        grid_points,
        rms_before_m: (s0 / k).sqrt(),
        max_before_m: m0,
        rms_after_m: (s1 / k).sqrt(),
        max_after_m: m1,
    }
}

impl Residual {
    /// Empty, or which points the figures are over when not all: `" of N, those where the data
    /// determine the error"`.
    pub fn where_determined(&self) -> String {
        if self.points == self.grid_points {
            String::new()
        } else {
            format!(" of {}, those where the data determine the error", self.grid_points)
        }
    }
}

/// The volumetric error and its U95 on a grid: `(x, e, u95)` per point, metres, `x` varying
/// fastest, then `y`, then `z`; the nodes of each axis as `nodes` places them.
pub fn grid(
    model: &ErrorModel,
    unc: &Uncertainty<'_>,
    nodes: &Nodes,
    probe: &Vector3<f64>,
) -> Result<Vec<(Point3<f64>, Vector3<f64>, f64)>> {
    const MAX_POINTS: usize = 5_000_000;
    let travel = model.layout.travel;
    let [xs, ys, zs] = Axis::ALL.map(|a| nodes.along(&travel, a, MAX_POINTS, false, "the grid"));
    let (xs, ys, zs) = (xs?, ys?, zs?);
    let count = xs.len().saturating_mul(ys.len()).saturating_mul(zs.len());
    if count > MAX_POINTS {
        bail!("--step-mm {} gives {count} grid points; use a coarser step", nodes.step_m * 1e3);
    }
    let (xs, ys) = (&xs, &ys);
    let pts = zs.iter().flat_map(|&z| ys.iter().flat_map(move |&y| xs.iter().map(move |&x| Point3::new(x, y, z))));
    let out: Vec<_> = pts
        .map(|x| {
            let e = model.error(&x, probe);
            (x, e, predict::predict(model, unc, &x, probe).u95())
        })
        .collect();
    let undetermined = out.iter().filter(|(_, _, u)| !u.is_finite()).count();
    if undetermined > 0 {
        bail!(
            "the data do not determine the volumetric error at {undetermined} of {} grid nodes, and a controller needs every node: {}",
            out.len(),
            crate::report::what_to_measure(model, unc, probe)
        );
    }
    Ok(out)
}

/// Refuses a per-axis export where the data do not determine what its tables hold: the error
/// along the three reference lines through `point` (LinuxCNC, SINUMERIK), or every function
/// over its travel (`functions`, ISG): densely along an axis with even nodes, at the nodes
/// along one whose nodes are its measured positions.
pub fn require_determined(
    model: &ErrorModel,
    unc: &Uncertainty<'_>,
    nodes: &Nodes,
    point: &Point3<f64>,
    probe: &Vector3<f64>,
    functions: bool,
) -> Result<()> {
    if unc.determines_everywhere() {
        return Ok(());
    }
    let travel = model.layout.travel;
    let mut missing: Vec<String> = Vec::new();
    for a in Axis::ALL {
        let [lo, hi] = travel.range(a);
        let qs: Vec<f64> = match nodes.measured_on(a) {
            Some(q) => q.to_vec(),
            None => (0..=100).map(|i| lo + (hi - lo) * i as f64 / 100.0).collect(),
        };
        if functions {
            for m in 0..6 {
                let f = volcal::ErrorFunction::from_index(a.index() * 6 + m);
                if qs.iter().any(|&q| !predict::function_sigma(model, unc, f, q).is_finite()) {
                    missing.push(f.name());
                }
            }
        } else if qs.iter().any(|&q| {
            let mut x = *point;
            x[a.index()] = q;
            !predict::is_determined_at(model, unc, &x, probe)
        }) {
            missing.push(format!("the {} line", a.letter()));
        }
    }
    if missing.is_empty() {
        return Ok(());
    }
    bail!(
        "the data do not determine {} of the model, which the tables need: {}",
        missing.join(", "),
        if functions {
            crate::report::what_to_measure_functions(model, unc)
        } else {
            crate::report::what_to_measure(model, unc, probe)
        }
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> JointTable {
        JointTable { axis: Axis::X, nominal_m: vec![0.0, 0.1, 0.2], offset_m: vec![1e-6, 3e-6, -1e-6], backlash_m: 0.0 }
    }

    #[test]
    fn nodes_lie_at_the_measured_positions_of_a_contradicted_axis_only() {
        let travel = Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]);
        let stops = |n: usize, len: f64, lo: f64| -> Vec<f64> {
            (0..n).map(|i| lo + len * i as f64 / (n - 1) as f64).collect()
        };
        let resolution = [
            AxisResolution::at(stops(11, 1.0, 0.0)).contradicted(),
            AxisResolution::at(stops(11, 0.8, 0.0)),
            AxisResolution::Everywhere,
        ];
        let nodes = Nodes::at_measured(0.1, &resolution);
        assert_eq!(nodes.measured_on(Axis::X), Some(stops(11, 1.0, 0.0).as_slice()));
        assert_eq!(nodes.measured_on(Axis::Y), None, "a borne-out interpolation keeps even nodes");
        assert_eq!(nodes.along(&travel, Axis::X, 256, false, "test").unwrap(), stops(11, 1.0, 0.0));
        assert_eq!(nodes.along(&travel, Axis::Y, 256, false, "test").unwrap(), stops(9, 0.8, 0.0));
        let err = format!("{:#}", nodes.along(&travel, Axis::X, 10, false, "LinuxCNC").unwrap_err());
        assert!(err.contains("11 measured positions") && err.contains("at most 10"), "{err}");
        // The default reference point stands at the stop of X nearest the centre, the centre elsewhere.
        let centre = Nodes::at_measured(
            0.1,
            &[
                AxisResolution::at(vec![0.0, 0.35, 0.7, 1.0]).contradicted(),
                AxisResolution::Everywhere,
                AxisResolution::Everywhere,
            ],
        )
        .default_point(&travel);
        assert_eq!(centre, Point3::new(0.35, 0.4, -0.3));
        // One-step tables: positions within EVEN_WITHIN_M of an even step are placed on it,
        // others refused.
        let mut q = stops(11, 1.0, 0.0);
        q[3] += 0.5e-6;
        let near = Nodes { step_m: 0.1, measured: [Some(q.clone()), None, None] };
        assert_eq!(near.along(&travel, Axis::X, 256, true, "ISG").unwrap(), stops(11, 1.0, 0.0));
        assert_eq!(near.along(&travel, Axis::X, 256, false, "LinuxCNC").unwrap(), q, "any spacing as measured");
        q[3] += 1e-3;
        let off = Nodes { step_m: 0.1, measured: [Some(q), None, None] };
        let err = format!("{:#}", off.along(&travel, Axis::X, 256, true, "SINUMERIK").unwrap_err());
        assert!(err.contains("not evenly spaced") && err.contains("SINUMERIK"), "{err}");
    }

    #[test]
    fn offsets_interpolate_linearly_and_hold_the_ends() {
        let t = table();
        assert_eq!(t.offset_at(-1.0), 1e-6);
        assert!((t.offset_at(0.05) - 2e-6).abs() < 1e-18);
        assert!((t.offset_at(0.15) - 1e-6).abs() < 1e-18);
        assert_eq!(t.offset_at(0.3), -1e-6);
    }

    #[test]
    fn the_two_file_types_state_the_same_correction() {
        let t = table();
        for (l1, l0) in t.linuxcnc_text(CompFileType::Offset).lines().zip(t.linuxcnc_text(CompFileType::Actual).lines())
        {
            let f1: Vec<f64> = l1.split(' ').map(|v| v.parse().unwrap()).collect();
            let f0: Vec<f64> = l0.split(' ').map(|v| v.parse().unwrap()).collect();
            assert_eq!(f1.len(), 3);
            // Type 0: offset = nominal - column.
            assert!((f0[0] - f0[1] - f1[1]).abs() < 1e-9, "{l1} / {l0}");
            assert_eq!(f1[1], f1[2]);
        }
    }

    #[test]
    fn backlash_splits_the_columns_by_direction() {
        let t = JointTable { backlash_m: 2e-6, ..table() };
        let l: Vec<f64> = t
            .linuxcnc_text(CompFileType::Offset)
            .lines()
            .next()
            .unwrap()
            .split(' ')
            .map(|v| v.parse().unwrap())
            .collect();
        // Moving up the axis lags by 1 um: 1 um more offset; moving down 1 um less.
        assert!((l[1] - 2e-3).abs() < 1e-9 && (l[2] - 0.0).abs() < 1e-9, "{l:?}");
    }
}
