//! `volcal export`: compensation files a controller loads, with a README.txt that says how to
//! load them, what the format expresses and what it drops, and the error that remains.

use anyhow::{Context, Result};
use nalgebra::{Point3, Vector3};
use std::fmt::Write as _;
use std::path::Path;
use volcal::Axis;
use volcal_formats::compensation::{self, CompFileType, Residual};
use volcal_formats::model_file::{self, LoadedModel};

/// The export formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// LinuxCNC per-joint COMP_FILEs (x.comp, y.comp, z.comp), millimetres.
    Linuxcnc,
    /// The volumetric error vector and its U95 on a grid (grid.csv, grid.json).
    Grid,
}

/// Options of `volcal export`.
#[derive(Clone, Debug)]
pub struct ExportOptions {
    pub format: Format,
    /// Node spacing, metres (LinuxCNC default 10 mm; grid default 50 mm).
    pub step_m: Option<f64>,
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
    let LoadedModel { model, covariance, file } = model_file::load(model_path)?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let travel = model.layout.travel;
    let centre = Point3::from(Vector3::from_fn(|i, _| 0.5 * (travel.ranges[i][0] + travel.ranges[i][1])));
    let p = opts.probe;
    let mut said = String::new();
    match opts.format {
        Format::Linuxcnc => {
            let step = opts.step_m.unwrap_or(0.010);
            let point = opts.point.unwrap_or(centre);
            let (b, reversal) = backlash(opts.diagnosis.as_deref())?;
            let tables = compensation::linuxcnc(&model, step, &point, &p, b)?;
            for t in &tables {
                let name = format!("{}.comp", t.axis.letter().to_ascii_lowercase());
                write(out, &name, &t.linuxcnc_text(opts.comp_type))?;
                let _ = writeln!(said, "wrote {} ({} nodes)", out.join(&name).display(), t.nominal_m.len());
            }
            let grid_step = Axis::ALL.iter().map(|&a| travel.length(a)).fold(0.0, f64::max) / 10.0;
            let r = compensation::residual(&model, &tables, grid_step, &p);
            let readme = linuxcnc_readme(&file.topology, opts.comp_type, step, &point, &p, &r, grid_step, &reversal);
            write(out, "README.txt", &readme)?;
            let _ = writeln!(
                said,
                "volumetric error over the volume: RMS {:.3} um, max {:.3} um; after this compensation (positioning only): RMS {:.3} um, max {:.3} um",
                r.rms_before_m * 1e6,
                r.max_before_m * 1e6,
                r.rms_after_m * 1e6,
                r.max_after_m * 1e6
            );
        }
        Format::Grid => {
            let step = opts.step_m.unwrap_or(0.050);
            let pts = compensation::grid(&model, &covariance, step, &p)?;
            let mut csv = String::from("x_mm,y_mm,z_mm,ex_um,ey_um,ez_um,u95_um\n");
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
            write(out, "README.txt", &grid_readme(step, &p))?;
            let _ = writeln!(said, "wrote {} grid points to {}", pts.len(), out.join("grid.csv").display());
        }
    }
    Ok(said)
}

fn linuxcnc_readme(
    topology: &str,
    kind: CompFileType,
    step: f64,
    point: &Point3<f64>,
    p: &Vector3<f64>,
    r: &Residual,
    grid_step: f64,
    reversal: &str,
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

Each line: nominal forward reverse, in millimetres (machine units), nominal ascending, nodes
evenly spaced about {step_mm} mm apart over the identified travel; LinuxCNC interpolates linearly between nodes and
holds the end values outside. COMP_FILE_TYPE {t}: {meaning}. The forward column is used moving
up, the reverse column moving down; they differ by the backlash ({reversal}).

What the format expresses: the positioning error of each joint along its own axis, as a function
of that joint only, taken with the other axes at ({px}, {py}, {pz}) mm and the tool at probe
offset ({ox}, {oy}, {oz}) mm. What it drops: straightness, the angular errors' lever arms away
from that point, and squareness. From the model, over the working volume ({grid_mm} mm grid,
{n} points, same probe offset): volumetric error RMS {b_rms:.3} um, max {b_max:.3} um before;
RMS {a_rms:.3} um, max {a_max:.3} um left after this compensation.
",
        t = kind as u8,
        step_mm = step * 1e3,
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
        b_rms = r.rms_before_m * 1e6,
        b_max = r.max_before_m * 1e6,
        a_rms = r.rms_after_m * 1e6,
        a_max = r.max_after_m * 1e6,
    )
}

fn grid_readme(step: f64, p: &Vector3<f64>) -> String {
    format!(
        "Volumetric error grid written by volcal.

grid.csv: x_mm,y_mm,z_mm,ex_um,ey_um,ez_um,u95_um, one row per node, x varying fastest; nodes
evenly spaced about {step_mm} mm apart over the identified travel, ends included, tool at probe
offset ({ox}, {oy}, {oz}) mm. grid.json: the same as axes and arrays.

error = actual - (commanded + probe offset): a controller with grid compensation adds -error
(interpolated between nodes) to the commanded position. u95_um: expanded uncertainty (k = 2) of
the error vector's largest component direction. All 21 error functions are in it.
",
        step_mm = step * 1e3,
        ox = p.x * 1e3,
        oy = p.y * 1e3,
        oz = p.z * 1e3,
    )
}
