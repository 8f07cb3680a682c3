//! `volcal export`: compensation files a controller loads, with a README.txt that says how to
//! load them, what the format expresses and what it drops, and the error that remains.

use anyhow::{Context, Result};
use nalgebra::{Point3, Vector3};
use std::fmt::Write as _;
use std::path::Path;
use volcal::Axis;
use volcal_formats::compensation::{self, CompFileType, Nodes, Residual};
use volcal_formats::model_file;
use volcal_formats::{isg, sinumerik};

/// The export formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// LinuxCNC per-joint COMP_FILEs (x.comp, y.comp, z.comp), millimetres.
    Linuxcnc,
    /// The volumetric error vector and its U95 on a grid (grid.csv, grid.json).
    Grid,
    /// ISG kernel / TwinCAT TF5280 volumetric compensation, ISG CSV (isg_x.csv, isg_y.csv, isg_z.csv).
    Isg,
    /// SINUMERIK EEC (eec.mpf, $AA_ENC_COMP) and CEC straightness tables (cec.mpf, $AN_CEC).
    Sinumerik,
}

/// Where the nodes of the tables lie.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum NodePlacement {
    /// Evenly spaced, --step-mm apart, on every axis.
    #[default]
    Even,
    /// At the measured positions (a tracer's stops) on each axis whose readings contradict
    /// the interpolation between them, evenly spaced on the others: the only tables the data
    /// determine there ([`Nodes::at_measured`]).
    Measured,
}

/// Options of `volcal export`.
#[derive(Clone, Debug)]
pub struct ExportOptions {
    pub format: Format,
    /// Node spacing, metres (LinuxCNC and ISG default 10 mm; SINUMERIK 20 mm; grid 50 mm).
    pub step_m: Option<f64>,
    /// Where the nodes lie along the axes with measured positions.
    pub nodes: NodePlacement,
    /// Where the other axes stand for each joint's table (machine coordinates, metres); default
    /// the centre of the travel.
    pub point: Option<Point3<f64>>,
    /// Tool (probe) offset the tables refer to, metres.
    pub probe: Vector3<f64>,
    pub comp_type: CompFileType,
    /// A `volcal diagnose --json` file whose `reversal` effect (backlash per axis) splits the
    /// LinuxCNC columns by direction of travel.
    pub diagnosis: Option<std::path::PathBuf>,
}

/// Backlash per axis (metres) from a diagnosis file's `reversal` effect; zero without one.
fn backlash(diagnosis: Option<&Path>) -> Result<([f64; 3], String)> {
    let Some(path) = diagnosis else {
        return Ok(([0.0; 3], "no diagnosis given: the model has no reversal error".into()));
    };
    let d = crate::diagnosis::DiagnosisFile::read(path)?;
    let Some(e) = d.effects.iter().find(|e| e.id == "reversal") else {
        return Ok(([0.0; 3], format!("{} names no reversal error", path.display())));
    };
    let value = |m: &std::collections::BTreeMap<String, f64>, a: &str| {
        m.get(&format!("backlash_{a}_m")).copied().unwrap_or(0.0)
    };
    let b = ["x", "y", "z"].map(|a| value(&e.parameters, a));
    let each: Vec<String> = ["x", "y", "z"]
        .iter()
        .map(|a| {
            format!(
                "{} {:.3} +- {:.3} um",
                a.to_uppercase(),
                value(&e.parameters, a) * 1e6,
                value(&e.uncertainty, a) * 1e6
            )
        })
        .collect();
    let text = format!("backlash from {}: {}", path.display(), each.join(", "));
    Ok((b, text))
}

fn write(dir: &Path, name: &str, text: &str) -> Result<()> {
    let p = dir.join(name);
    std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))
}

/// Writes the files of `opts.format` for the model in `model_path` into `out`; returns what it
/// printed.
pub fn export_cmd(model_path: &Path, out: &Path, opts: &ExportOptions) -> Result<String> {
    let loaded = model_file::load(model_path)?;
    let (model, file, unc) = (&loaded.model, &loaded.file, loaded.uncertainty());
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let travel = model.layout.travel;
    let p = opts.probe;
    let step = opts.step_m.unwrap_or(match opts.format {
        Format::Linuxcnc | Format::Isg => 0.010,
        Format::Sinumerik => 0.020,
        Format::Grid => 0.050,
    });
    let nodes = match opts.nodes {
        NodePlacement::Even => Nodes::even(step),
        NodePlacement::Measured => Nodes::at_measured(step, &loaded.resolution),
    };
    let placed = nodes.describe(&travel, &loaded.resolution);
    let centre = nodes.default_point(&travel);
    // A refusal says what would be determined: the reference point at a measured position,
    // nodes at the measured positions.
    // The tables `--nodes measured` would write, when they differ from these (an axis is
    // contradicted and the nodes are even): a refusal asks whether they would be determined,
    // and is not computed twice where they are the same.
    let measured = Nodes::at_measured(step, &loaded.resolution);
    let other = (measured != nodes).then_some(&measured);
    let determined = |point: &Point3<f64>, functions: bool| -> Result<()> {
        compensation::require_determined(model, &unc, &nodes, point, &p, functions).map_err(|e| {
            let at_stop = measured.default_point(&travel);
            let mut hints = Vec::new();
            if !functions && unc.leaves_open_at(point) {
                hints.push(format!(
                    "the reference point ({}, {}, {}) m lies between measured positions where the data leave the error open: put --point at a measured position, e.g. ({}, {}, {}) m",
                    point.x, point.y, point.z, at_stop.x, at_stop.y, at_stop.z
                ));
            }
            if other.is_some_and(|m| compensation::require_determined(model, &unc, m, &at_stop, &p, functions).is_ok()) {
                hints.push(MEASURED_NODES_HINT.to_string());
            }
            hints.into_iter().fold(e, |e, h| anyhow::anyhow!("{e:#}; {h}"))
        })
    };
    // What a table leaves of the error is a measured figure only where the data determine it.
    let keep = |x: &Point3<f64>| !unc.leaves_open_at(x);
    let grid_step = residual_step(model);
    let mut said = String::new();
    match opts.nodes {
        NodePlacement::Measured if !nodes.any_measured() => {
            let _ = writeln!(said, "--nodes measured: no axis's readings contradict the interpolation between its measured positions; nodes evenly spaced");
        }
        NodePlacement::Measured => {
            let _ = writeln!(said, "nodes:\n{}", indent(&placed));
        }
        NodePlacement::Even => {}
    }
    match opts.format {
        Format::Linuxcnc => {
            let point = opts.point.unwrap_or(centre);
            determined(&point, false)?;
            let (b, reversal) = backlash(opts.diagnosis.as_deref())?;
            let tables = compensation::linuxcnc(model, &nodes, &point, &p, b)?;
            for t in &tables {
                let name = format!("{}.comp", t.axis.letter().to_ascii_lowercase());
                write(out, &name, &t.linuxcnc_text(opts.comp_type))?;
                let _ = writeln!(said, "wrote {} ({} nodes)", out.join(&name).display(), t.nominal_m.len());
            }
            let r = compensation::residual_where(model, grid_step, &p, keep, |x| {
                compensation::joint_correction(&tables, x)
            });
            let u95 = reference_line_u95(model, &unc, &nodes, &point, &p);
            let u95_text = line_u95_text(&u95, &nodes);
            let readme = linuxcnc_readme(
                &file.topology,
                opts.comp_type,
                &placed,
                &point,
                &p,
                &r,
                grid_step,
                &reversal,
                &u95_text,
            );
            write(out, "README.txt", &readme)?;
            said.push_str(&said_residual(&r, "positioning only"));
            let _ = writeln!(said, "{u95_text}");
        }
        Format::Isg => {
            determined(&centre, true)?;
            let (b, reversal) = backlash(opts.diagnosis.as_deref())?;
            let tables = isg::isg(model, &nodes)?;
            let comment = format!("volcal ISG CSV export (machine {}), model {}", file.topology, model_path.display());
            for t in &tables {
                let name = format!("isg_{}.csv", t.axis.letter().to_ascii_lowercase());
                write(out, &name, &t.text(&comment))?;
                let _ = writeln!(said, "wrote {} ({} records)", out.join(&name).display(), t.nominal_m.len());
            }
            let r = isg::interpolation_residual(model, &tables, grid_step, &p, keep);
            let records: usize = tables.iter().map(|t| t.nominal_m.len() + 1).sum();
            write(
                out,
                "README.txt",
                &isg_readme(&model.layout.topology, &placed, records, &p, &r, grid_step, &reversal, b),
            )?;
            said.push_str(&said_residual(&r, "all 21 functions, linear between the nodes"));
        }
        Format::Sinumerik => {
            let point = opts.point.unwrap_or(centre);
            determined(&point, false)?;
            let (b, reversal) = backlash(opts.diagnosis.as_deref())?;
            let (eec, cec) = sinumerik::sinumerik(model, &nodes, &point, &p)?;
            let comment =
                format!("volcal SINUMERIK export (machine {}), model {}", file.topology, model_path.display());
            write(out, "eec.mpf", &sinumerik::eec_text(&eec, b, &comment))?;
            write(out, "cec.mpf", &sinumerik::cec_text(&cec, &comment))?;
            let _ = writeln!(
                said,
                "wrote {} ({} EEC tables) and {} ({} CEC tables), points per table along {}",
                out.join("eec.mpf").display(),
                eec.len(),
                out.join("cec.mpf").display(),
                cec.len(),
                eec.iter()
                    .map(|t| format!("{} {}", t.input.letter(), t.nominal_m.len()))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            let controller = sinumerik::controller(&eec, &cec);
            let r = compensation::residual_where(model, grid_step, &p, keep, |x| controller.at(x));
            write(
                out,
                "README.txt",
                &sinumerik_readme(&file.topology, &placed, &eec, &point, &p, &r, grid_step, &reversal, b),
            )?;
            said.push_str(&said_residual(&r, "positioning and straightness"));
        }
        Format::Grid => {
            let pts = compensation::grid(model, &unc, &nodes, &p).map_err(|e| {
                match other.map(|m| compensation::grid(model, &unc, m, &p)) {
                    Some(Ok(_)) => anyhow::anyhow!("{e:#}; {MEASURED_NODES_HINT}"),
                    _ => e,
                }
            })?;
            let mut csv = format!("{}\n", volcal_formats::compensation_grid::GRID_HEADER);
            for (x, e, u) in &pts {
                let _ = writeln!(
                    csv,
                    "{},{},{},{},{},{},{}",
                    x.x * 1e3,
                    x.y * 1e3,
                    x.z * 1e3,
                    e.x * 1e6,
                    e.y * 1e6,
                    e.z * 1e6,
                    u * 1e6
                );
            }
            write(out, "grid.csv", &csv)?;
            let axis = |a: usize| -> Vec<f64> {
                let mut v: Vec<f64> = pts.iter().map(|(x, _, _)| x[a] * 1e3).collect();
                v.sort_by(f64::total_cmp);
                v.dedup();
                v
            };
            let json = serde_json::json!({
                "format": "volcal-grid v1",
                "units": {"position": "mm", "error": "um", "u95": "um"},
                "probe_offset_mm": [p.x * 1e3, p.y * 1e3, p.z * 1e3],
                "sign": "error = actual - (commanded + probe offset); a controller adds -error",
                "order": "x varies fastest, then y, then z",
                "x_mm": axis(0), "y_mm": axis(1), "z_mm": axis(2),
                "error_um": pts.iter().map(|(_, e, _)| [e.x * 1e6, e.y * 1e6, e.z * 1e6]).collect::<Vec<_>>(),
                "u95_um": pts.iter().map(|(_, _, u)| u * 1e6).collect::<Vec<_>>(),
                "model": file.provenance.input,
            });
            write(out, "grid.json", &serde_json::to_string_pretty(&json)?)?;
            write(out, "README.txt", &grid_readme(&placed, &p))?;
            let _ = writeln!(said, "wrote {} grid points to {}", pts.len(), out.join("grid.csv").display());
        }
    }
    Ok(said)
}

/// What a refusal adds when tables with nodes at the measured positions would be determined.
const MEASURED_NODES_HINT: &str = "tables with nodes only at the measured positions are determined by the data: \
     `--nodes measured` writes them (between those nodes the controller's linear interpolation is then not a measured value)";

/// The grid the residual is computed on: a tenth of the longest travel.
fn residual_step(model: &volcal::ErrorModel) -> f64 {
    let travel = model.layout.travel;
    Axis::ALL.iter().map(|&a| travel.length(a)).fold(0.0, f64::max) / 10.0
}

/// The README's sentence on the error before and after, over the working volume.
fn volume_residual(r: &Residual, grid_step: f64, p: &Vector3<f64>, left: &str) -> String {
    format!(
        "From the model, over the working volume ({:.1} mm grid, {} points{}, probe offset ({}, {}, {}) mm):\nvolumetric error RMS {:.3} um, max {:.3} um before; RMS {:.3} um, max {:.3} um {left}.",
        grid_step * 1e3,
        r.points,
        r.where_determined(),
        p.x * 1e3,
        p.y * 1e3,
        p.z * 1e3,
        r.rms_before_m * 1e6,
        r.max_before_m * 1e6,
        r.rms_after_m * 1e6,
        r.max_after_m * 1e6
    )
}

fn said_residual(r: &Residual, what: &str) -> String {
    format!(
        "volumetric error over the volume{}: RMS {:.3} um, max {:.3} um; after this compensation ({what}): RMS {:.3} um, max {:.3} um\n",
        if r.points < r.grid_points { format!(" ({} grid points{})", r.points, r.where_determined()) } else { String::new() },
        r.rms_before_m * 1e6,
        r.max_before_m * 1e6,
        r.rms_after_m * 1e6,
        r.max_after_m * 1e6
    )
}

/// Largest expanded uncertainty (k = 2) of the positioning deviation along each axis's reference
/// line through `point` (from the line's lower end, as an interferometer zeroed there measures
/// it; on an axis with nodes at its measured positions, from the first and at the nodes),
/// metres: what a per-axis table carries of the identification.
fn reference_line_u95(
    model: &volcal::ErrorModel,
    unc: &volcal::predict::Uncertainty<'_>,
    nodes: &Nodes,
    point: &Point3<f64>,
    p: &Vector3<f64>,
) -> [f64; 3] {
    Axis::ALL.map(|a| {
        let mut start = *point;
        let measured = nodes.measured_on(a);
        start[a.index()] = measured.map_or(model.layout.travel.range(a)[0], |q| q[0]);
        let line = volcal::validate::axis_line(&model.layout.travel, a, &start);
        let targets = match measured {
            Some(q) => q.iter().map(|v| v - q[0]).collect(),
            None => line.targets(41),
        };
        volcal::validate::predict_positioning(model, unc, &line, p, &targets)
            .iter()
            .map(|t| 2.0 * t.sigma_m)
            .fold(0.0, f64::max)
    })
}

fn line_u95_text(u95: &[f64; 3], nodes: &Nodes) -> String {
    let each: Vec<String> = Axis::ALL
        .iter()
        .map(|&a| {
            let at = if nodes.measured_on(a).is_some() { " (at its nodes)" } else { "" };
            format!("{} {:.3}{at}", a.letter(), u95[a.index()] * 1e6)
        })
        .collect();
    format!("positioning along the reference lines known to U95 {} um (largest along each line)", each.join(", "))
}

#[allow(clippy::too_many_arguments)]
fn linuxcnc_readme(
    topology: &str,
    kind: CompFileType,
    nodes: &str,
    point: &Point3<f64>,
    p: &Vector3<f64>,
    r: &Residual,
    grid_step: f64,
    reversal: &str,
    u95_text: &str,
) -> String {
    format!(
        "LinuxCNC compensation tables written by volcal (machine {topology}).

Load them in the INI file (joint numbers as in your kinematics; trivkins XYZ: X=0, Y=1, Z=2):

  [JOINT_0]
  COMP_FILE = x.comp
  COMP_FILE_TYPE = {t}
  [JOINT_1]
  COMP_FILE = y.comp
  COMP_FILE_TYPE = {t}
  [JOINT_2]
  COMP_FILE = z.comp
  COMP_FILE_TYPE = {t}

Each line: nominal forward reverse, in millimetres (machine units), nominal ascending; LinuxCNC
interpolates linearly between nodes and holds the end values outside. Nodes:
{nodes}
COMP_FILE_TYPE {t}: {meaning}. The forward column is used moving
up, the reverse column moving down; they differ by the backlash ({reversal}).

What the format expresses: the positioning error of each joint along its own axis, as a function
of that joint only, taken with the other axes at ({px}, {py}, {pz}) mm and the tool at probe
offset ({ox}, {oy}, {oz}) mm. What it drops: straightness, the angular errors' lever arms away
from that point, and squareness. From the model, over the working volume ({grid_mm} mm grid,
{n} points{of}, same probe offset): volumetric error RMS {b_rms:.3} um, max {b_max:.3} um before;
RMS {a_rms:.3} um, max {a_max:.3} um left after this compensation.

The tables carry the identification's uncertainty:
  {u95_text}.
A compensated axis keeps errors of that size. To make it smaller, measure the three lines
themselves in the campaign: a plan's `reference_lines` with `runs: 5` (ISO 230-2's five
bidirectional runs), as launch_configs/plans/machine_tool_compensation.yaml does. Verify the compensated machine with a
laser interferometer along each line (`volcal iso230-2`; in simulation `volcal validate
--compensation`).
",
        t = kind as u8,
        meaning = match kind {
            CompFileType::Offset => "the columns are the offsets added to the commanded position",
            CompFileType::Actual => "the columns are where the machine actually is at the nominal position",
        },
        px = point.x * 1e3,
        py = point.y * 1e3,
        pz = point.z * 1e3,
        ox = p.x * 1e3,
        oy = p.y * 1e3,
        oz = p.z * 1e3,
        grid_mm = grid_step * 1e3,
        n = r.points,
        of = r.where_determined(),
        nodes = indent(nodes),
        b_rms = r.rms_before_m * 1e6,
        b_max = r.max_before_m * 1e6,
        a_rms = r.rms_after_m * 1e6,
        a_max = r.max_after_m * 1e6,
    )
}

fn grid_readme(nodes: &str, p: &Vector3<f64>) -> String {
    format!(
        "Volumetric error grid written by volcal.

grid.csv: x_mm,y_mm,z_mm,ex_um,ey_um,ez_um,u95_um, one row per node, x varying fastest, tool at
probe offset ({ox}, {oy}, {oz}) mm. grid.json: the same as axes and arrays. Nodes:
{nodes}

error = actual - (commanded + probe offset): a controller with grid compensation adds -error
(interpolated between nodes) to the commanded position. u95_um: expanded uncertainty (k = 2) of
the error vector's largest component direction. All 21 error functions are in it.
",
        nodes = indent(nodes),
        ox = p.x * 1e3,
        oy = p.y * 1e3,
        oz = p.z * 1e3,
    )
}

/// `text`'s lines indented by two spaces.
fn indent(text: &str) -> String {
    text.lines().map(|l| format!("  {l}")).collect::<Vec<_>>().join("\n")
}

#[allow(clippy::too_many_arguments)]
fn isg_readme(
    topo: &volcal::Topology,
    nodes: &str,
    records: usize,
    p: &Vector3<f64>,
    r: &Residual,
    grid_step: f64,
    reversal: &str,
    backlash_m: [f64; 3],
) -> String {
    let topology = topo.to_string();
    let chain: String = topo.chain().iter().map(|a| a.letter()).collect();
    let workpiece_axes = Axis::ALL.iter().filter(|&&a| topo.is_table_axis(a)).count();
    let lose: Vec<String> =
        Axis::ALL.iter().map(|a| format!("{}: {:.0}", a.letter(), backlash_m[a.index()] * 1e7)).collect();
    format!(
        "ISG CSV volumetric compensation tables written by volcal (machine {topology}), for the ISG kernel
(Beckhoff TwinCAT 3 CNC, TF5280 Volumetric Compensation).

Files: isg_x.csv, isg_y.csv, isg_z.csv. Each: `//` comment lines, a header `X EXX EYX EZX EAX EBX ECX`
(resp. Y, Z), then one record per node: the axis position in mm, the translational errors EXK EYK
EZK in mm, the angular errors EAK EBK ECK in rad (the units TF5280 prescribes for every file format:
offsets in millimetres, angles in radians, arguments in millimetres). Nodes:
{nodes}
After a `#` file break, isg_y.csv holds
the squareness C0Y and isg_z.csv B0Z and A0Z (ISO 230-1 position errors, rad; volcal's EC0Y, EB0Z,
EA0Z). {records} records in all.

Load them in the compensation list of VOLCOMP[0] (the file vol_comp[0].file_name names, e.g.
C:\\volcomp\\vol_comp_0.lis), then switch the compensation on in the NC program:

  X                 1      (logical axis numbers of your X, Y, Z: P-VOLC-00001..3)
  Y                 2
  Z                 3
  chain             {chain}    (P-VOLC-00007: volcal's axis stacking {topology}, workpiece to tool)
  workpiece_axes    {workpiece_axes}      (P-VOLC-00008: axes carrying the workpiece in {topology})
  Interpolation     GRID   (P-VOLC-00014: linear interpolation between the records)
  file[0]           C:\\volcomp\\isg_x.csv
  file_format[0]    ISG_CSV
  file[1]           C:\\volcomp\\isg_y.csv
  file_format[1]    ISG_CSV
  file[2]           C:\\volcomp\\isg_z.csv
  file_format[2]    ISG_CSV
  and in the start-up list: vol_comp[0].max_records {records} or more

  N010 #VOLCOMP ON [ID0]       (after a change of the files: #VOLCOMP OFF [ID0],
  ...                           #VOLCOMP [ID0 UPDATE], #VOLCOMP ON [ID0])

Sign: the tables hold the machine's errors, not corrections: ISO 230-1 deviations, volcal's
convention error = actual - (commanded + probe offset), the convention of the ISG kernel, which
computes the compensation from the errors through the kinematic chain (TF5280 \"List of parameters
supported\", \"Units of measure\", \"ISG CSV format\"; infosys.beckhoff.com). Do not set
P-VOLC-00009 negate. The chain and workpiece_axes above are volcal's model of the machine; check the
sign on one point of a workpiece-side (table) axis before production use.

What the format expresses: all 21 error functions (18 component errors and 3 squareness errors),
so the controller compensates the whole identified model, tool at any offset. What it loses: the
functions between the nodes (linear interpolation). {residual}

Backlash is not part of the volumetric compensation: {reversal}. The ISG kernel takes it per axis
in the axis parameters: P-AXIS-00103 getriebe[0].lose in 0.1 um ({lose}) and P-AXIS-00021
lr_param.anwahl_losekomp (the direction the compensation acts in).
",
        nodes = indent(nodes),
        lose = lose.join(", "),
        residual = volume_residual(r, grid_step, p, "left by the interpolation between nodes"),
    )
}

#[allow(clippy::too_many_arguments)]
fn sinumerik_readme(
    topology: &str,
    nodes: &str,
    eec: &[sinumerik::Table],
    point: &Point3<f64>,
    p: &Vector3<f64>,
    r: &Residual,
    grid_step: f64,
    reversal: &str,
    backlash_m: [f64; 3],
) -> String {
    let points = eec.iter().map(|t| t.nominal_m.len()).max().unwrap_or(0);
    let md: Vec<String> = Axis::ALL
        .iter()
        .map(|&a| {
            format!("  MD32450 $MA_BACKLASH[0,{}] = {:.6} mm", sinumerik::axis_name(a), backlash_m[a.index()] * 1e3)
        })
        .collect();
    format!(
        "SINUMERIK compensation tables written by volcal (machine {topology}).

eec.mpf (%_N_AX_EEC_INI): leadscrew / measuring-system error compensation (EEC) of each axis,
$AA_ENC_COMP[0,N,AXi] with $AA_ENC_COMP_STEP, _MIN, _MAX, _IS_MODULO. cec.mpf (%_N_NC_CEC_INI): six
sag/cross compensation (CEC) tables, one per base axis and straightness direction: $AN_CEC[t,N] with
$AN_CEC_INPUT_AXIS (base axis), $AN_CEC_OUTPUT_AXIS (compensated axis), $AN_CEC_STEP, _MIN, _MAX,
_DIRECTION 0, _MULT_BY_TABLE 0, _IS_MODULO 0. Both: CHANDATA(1) ... M17, positions and values in mm
(metric), at most {points} points per table. Nodes:
{nodes}
Axis names: AX1 = X, AX2 = Y, AX3 = Z (edit them if your machine axes differ).

Load (K3 Compensations, SINUMERIK Function Manual Extended Functions): with MD32700
ENC_COMP_ENABLE = 0 and MD32710 CEC_ENABLE = 0, MD38000 $MA_MM_ENC_COMP_MAX_POINTS >= {points} and
MD18342 $MN_MM_CEC_MAX_POINTS[0..5] >= {points} (840D sl; the 828D has eight CEC tables of 200
points), run eec.mpf and cec.mpf, then set MD32700 = 1 and MD32710 = 1 and MD18342/MD32711 as
your machine needs, NCK reset. volcal refuses tables of more than 200 points (--step-mm larger).

Sign: EEC values are the error e = actual - commanded along the axis (K3 4.4.2.1: a positive
compensation value moves the axis in the negative direction); CEC values are the correction
added to the compensated axis, minus its error (K3 4.4.3, the sag example), relative to the
reference point (zero there, so that EEC and CEC do not count the error at the point twice).

What the format expresses: positioning of each axis (EEC) and the straightness of each axis in
the two others (CEC), all taken along the three lines through ({px}, {py}, {pz}) mm with the tool at
probe offset ({ox}, {oy}, {oz}) mm: each table holds the error of its line, including the angular
errors' lever arms there. What it drops: angular errors away from those lines (pitch, yaw, roll
acting through other lever arms) and squareness away from them, and everything between nodes.
{residual}

Backlash ({reversal}): machine data, not a table (SINUMERIK's backlash compensation adds it on
each reversal; positive in the normal case, the measuring system leading the moving part):
{md}
",
        md = md.join("\n"),
        nodes = indent(nodes),
        px = point.x * 1e3,
        py = point.y * 1e3,
        pz = point.z * 1e3,
        ox = p.x * 1e3,
        oy = p.y * 1e3,
        oz = p.z * 1e3,
        residual = volume_residual(r, grid_step, p, "left after this compensation"),
    )
}
