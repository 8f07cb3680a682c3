//! `volcal validate`: the paper's validation (Han et al. 2021, section 3.2-3.3) as a command.
//! The ISO 230-2-style positioning error along axis lines and the four body diagonals, predicted
//! from a model with uncertainty ([`volcal::validate`]) and, when the simulation truth is given,
//! compared with a simulated laser-interferometer measurement of the same lines
//! ([`volcal_sim::line_measurement`]).

use anyhow::{bail, Context, Result};
use nalgebra::{Point3, Vector3};
use rand::SeedableRng;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;
use volcal::validate::{self, Line, LineComparison, PositioningPoint};
use volcal::{Axis, ErrorModel, Travel};
use volcal_formats::machine::Machine;
use volcal_formats::model_file;
use volcal_formats::truth_file::TruthFile;
use volcal_sim::inject::Injection;
use volcal_sim::line_measurement::measure_line;
use volcal_sim::{Interferometer, VirtualMachine};

/// Which lines to validate.
#[derive(Clone, Debug, PartialEq)]
pub enum LineSpec {
    /// The line along an axis from a start point (default: lower end, others at the centre).
    Axis { axis: Axis, start: Option<Point3<f64>> },
    /// The four body diagonals of the paper's Table 4.
    Diagonals,
    /// Any line.
    Custom(Line),
}

impl LineSpec {
    /// The lines for a travel.
    pub fn lines(&self, travel: &Travel) -> Vec<Line> {
        match self {
            LineSpec::Axis { axis, start } => {
                let a = start.unwrap_or_else(|| validate::default_axis_start(travel, *axis));
                vec![validate::axis_line(travel, *axis, &a)]
            }
            LineSpec::Diagonals => validate::body_diagonals(travel).to_vec(),
            LineSpec::Custom(l) => vec![l.clone()],
        }
    }
}

/// A simulated laser interferometer on the true machine.
pub struct Measurer {
    pub machine: VirtualMachine,
    pub interferometer: Interferometer,
    /// Bidirectional runs averaged per line (the paper: 5).
    pub runs: usize,
    pub seed: u64,
    /// The controller's compensation acting on the machine (`--compensation`), if any.
    pub controller: Option<Box<dyn Injection>>,
}

impl Measurer {
    /// From a simulation truth file and, for the instruments' noise, the machine file that
    /// simulated it (defaults otherwise).
    pub fn from_files(truth: &Path, machine: Option<&Path>, runs: usize, seed: u64) -> Result<Measurer> {
        let t = TruthFile::load(truth)?;
        let (model, _) = t.model.to_model().with_context(|| format!("truth {}", truth.display()))?;
        let sim = match machine {
            Some(m) => Machine::load(m)?.file.simulation,
            None => Default::default(),
        };
        Ok(Measurer {
            machine: VirtualMachine { truth: model, repeatability_m: sim.repeatability_m, centring_m: 0.0 },
            interferometer: sim.interferometer,
            runs,
            seed,
            controller: None,
        })
    }
}

/// Prediction (and measurement) of one line.
pub struct LineResult {
    pub line: Line,
    pub predicted: Vec<PositioningPoint>,
    pub comparison: Option<LineComparison>,
}

/// Predicts every line at `points` equally spaced targets and, with a measurer, measures it.
pub fn run(
    model: &ErrorModel,
    unc: &volcal::predict::Uncertainty<'_>,
    lines: &[Line],
    points: usize,
    probe: &Vector3<f64>,
    measurer: Option<&Measurer>,
) -> Vec<LineResult> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(measurer.map_or(0, |m| m.seed));
    lines
        .iter()
        .map(|line| {
            let targets = line.targets(points);
            let predicted = validate::predict_positioning(model, unc, line, probe, &targets);
            let comparison = measurer.map(|m| {
                let controller: Vec<&dyn Injection> = m.controller.iter().map(|c| c.as_ref()).collect();
                let meas =
                    measure_line(&m.machine, &m.interferometer, line, probe, &targets, m.runs, &controller, &mut rng);
                validate::compare(line, &predicted, &meas.as_pairs())
            });
            LineResult { line: line.clone(), predicted, comparison }
        })
        .collect()
}

fn mm(p: &Point3<f64>) -> String {
    format!("({:.0}, {:.0}, {:.0})", p.x * 1e3, p.y * 1e3, p.z * 1e3)
}

/// The text report: per line a table of targets, then a summary line. `reference` gives the
/// paper's maximum differences (micrometres) by line name, printed alongside.
pub fn format(results: &[LineResult], reference: &[(&str, f64)]) -> String {
    let mut out = String::new();
    for r in results {
        let l = &r.line;
        let _ = writeln!(out, "Line {}: {} -> {} mm, {:.0} mm", l.name, mm(&l.start), mm(&l.end), l.length() * 1e3);
        // Targets: prediction, and with a measurement the interferometer and the difference.
        let mut head = format!("  {:>8}  {:>26}  {:>11}  {:>11}", "s/mm", "X/mm", "pred/um", "U95/um");
        if r.comparison.is_some() {
            head.push_str(&format!("  {:>11}  {:>7}", "LI/um", "diff/um"));
        }
        let _ = writeln!(out, "{head}");
        for (i, p) in r.predicted.iter().enumerate() {
            let mut row = if p.sigma_m.is_finite() {
                format!(
                    "  {:>8.1}  {:>26}  {:>11.3}  {:>11.3}",
                    p.s_m * 1e3,
                    mm(&p.x),
                    p.deviation_m * 1e6,
                    2.0 * p.sigma_m * 1e6
                )
            } else {
                format!("  {:>8.1}  {:>26}  {:>24}", p.s_m * 1e3, mm(&p.x), "not determined")
            };
            if let Some(k) = r.comparison.as_ref().map(|c| &c.points[i]) {
                row.push_str(&format!("  {:>11.3}", k.measured_m * 1e6));
                if k.is_determined() {
                    row.push_str(&format!("  {:>7.3}", k.difference_m * 1e6));
                }
            }
            if p.interpolated {
                row.push_str("  i");
            }
            let _ = writeln!(out, "{row}");
        }
        if r.predicted.iter().any(|p| p.interpolated) {
            let _ = writeln!(
                out,
                "  i: interpolated, at or from a point between the measured positions of an axis the readings resolve only there (e.g. a tracer's stops): a feature shorter than their step is not seen there"
            );
        }
        let (n, determined) = (r.predicted.len(), r.predicted.iter().filter(|p| p.sigma_m.is_finite()).count());
        // The predicted figures are over the targets the data determine; say so when that is not
        // all of them.
        let over = if determined < n {
            format!(" (the data determine the prediction at {determined} of the {n} targets; the predicted figures are over those)")
        } else {
            String::new()
        };
        let um = |v: Option<f64>| v.map_or("not determined".to_string(), |v| format!("{:.3} um", v * 1e6));
        match &r.comparison {
            Some(c) => {
                let paper = reference
                    .iter()
                    .find(|(n, _)| *n == l.name)
                    .map(|(_, v)| format!(" (paper: {v:.2} um)"))
                    .unwrap_or_default();
                let _ = writeln!(
                    out,
                    "  positioning error (range of deviations): predicted {}, interferometer {:.3} um; max |difference| {}{paper}; max En {}{over}",
                    um(c.predicted_range_m),
                    c.measured_range_m * 1e6,
                    um(c.max_abs_difference_m),
                    c.max_en.map_or("not determined".to_string(), |e| format!("{e:.2}"))
                );
            }
            None => {
                let range = volcal::validate::range(
                    r.predicted.iter().filter(|p| p.sigma_m.is_finite()).map(|p| p.deviation_m),
                );
                let _ = writeln!(out, "  positioning error (range of deviations): predicted {}{over}", um(range));
            }
        }
    }
    out
}

/// Writes all lines as CSV: `line,s_m,x_m,y_m,z_m,predicted_m,u_predicted_m,measured_m,u_measured_m,difference_m,en,interpolated`
/// (measurement columns empty without a measurement; prediction, difference and `en` empty
/// where the data do not determine the prediction; `interpolated` 1 as the table's `i`).
pub fn write_csv(path: &Path, results: &[LineResult]) -> Result<()> {
    let f = std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = std::io::BufWriter::new(f);
    writeln!(w, "line,s_m,x_m,y_m,z_m,predicted_m,u_predicted_m,measured_m,u_measured_m,difference_m,en,interpolated")?;
    for r in results {
        for (i, p) in r.predicted.iter().enumerate() {
            // Where the data do not determine the prediction its cells are empty, as in `volcal
            // map` and `volcal predict`: the minimum-norm value is no prediction.
            let determined = p.sigma_m.is_finite();
            let m = r
                .comparison
                .as_ref()
                .map(|c| {
                    let k = &c.points[i];
                    match (determined, k.en) {
                        (true, Some(en)) => {
                            format!("{},{},{},{}", k.measured_m, k.measured_sigma_m, k.difference_m, en)
                        }
                        _ => format!("{},{},,", k.measured_m, k.measured_sigma_m),
                    }
                })
                .unwrap_or_else(|| ",,,".into());
            let predicted = if determined { format!("{},{}", p.deviation_m, p.sigma_m) } else { ",".to_string() };
            writeln!(
                w,
                "{},{},{},{},{},{},{},{}",
                r.line.name, p.s_m, p.x.x, p.x.y, p.x.z, predicted, m, p.interpolated as u8
            )?;
        }
    }
    w.flush()?;
    Ok(())
}

/// Arguments of `volcal validate`.
pub struct ValidateArgs<'a> {
    pub model: &'a Path,
    pub lines: LineSpec,
    pub points: usize,
    pub probe: Vector3<f64>,
    pub truth: Option<&'a Path>,
    pub machine: Option<&'a Path>,
    pub runs: usize,
    pub seed: u64,
    pub out: Option<&'a Path>,
    /// The compensation (`volcal export`'s directory) the measured machine's controller applies.
    pub compensation: Option<(&'a Path, volcal_formats::compensation::CompFileType)>,
}

/// `volcal validate`.
pub fn validate_cmd(a: &ValidateArgs<'_>) -> Result<String> {
    if a.points < 2 {
        bail!("--points must be at least 2, got {}", a.points);
    }
    if a.runs == 0 {
        bail!("--runs must be at least 1");
    }
    let loaded = model_file::load(a.model)?;
    let model = &loaded.model;
    let lines = a.lines.lines(&model.layout.travel);
    for l in &lines {
        if !(l.length() > 0.0) {
            bail!("line {} has zero length inside the travel", l.name);
        }
    }
    let measurer = match a.truth {
        Some(t) => {
            let mut m = Measurer::from_files(t, a.machine, a.runs, a.seed)?;
            if let Some((dir, kind)) = a.compensation {
                let topology = m.machine.truth.layout.topology.clone();
                m.controller = Some(crate::commands::load_compensation(dir, kind, topology)?);
            }
            Some(m)
        }
        None if a.compensation.is_some() => bail!("--compensation acts on the simulated machine: give --truth too"),
        None => None,
    };
    let results = run(model, &loaded.uncertainty(), &lines, a.points, &a.probe, measurer.as_ref());
    let mut text = format(&results, &[]);
    if let Some(m) = &measurer {
        let _ = writeln!(
            text,
            "Interferometer: simulated on the truth{}, {} bidirectional run(s) averaged per line, seed {}.",
            a.compensation.map(|(d, _)| format!(" under the compensation in {}", d.display())).unwrap_or_default(),
            m.runs,
            m.seed
        );
    }
    if let Some(out) = a.out {
        write_csv(out, &results)?;
        let _ = writeln!(text, "wrote {}", out.display());
    }
    Ok(text)
}

/// Parses `x0,y0,z0:x1,y1,z1` (metres) as a custom line.
pub fn parse_line(s: &str) -> Result<Line> {
    let (a, b) = s.split_once(':').ok_or_else(|| anyhow::anyhow!("{s:?}: expected x0,y0,z0:x1,y1,z1 in metres"))?;
    let a = crate::commands::parse_vec3(a).with_context(|| format!("--line {s:?}: start"))?;
    let b = crate::commands::parse_vec3(b).with_context(|| format!("--line {s:?}: end"))?;
    if (a - b).norm() == 0.0 {
        bail!("{s:?}: start and end coincide");
    }
    Ok(Line { name: "line".into(), start: Point3::from(a), end: Point3::from(b) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_specs() {
        let t = volcal_sim::paper::travel();
        let x = LineSpec::Axis { axis: Axis::X, start: None }.lines(&t);
        assert_eq!(x[0].start, Point3::new(0.0, -0.25, -0.35));
        assert_eq!(LineSpec::Diagonals.lines(&t).len(), 4);
        let l = parse_line("0,0,-0.7:0.7,-0.5,0").unwrap();
        assert!((l.length() - (0.49f64 + 0.25 + 0.49).sqrt()).abs() < 1e-12);
        assert!(parse_line("0,0,0").is_err());
        assert!(parse_line("0,0,0:0,0,0").is_err());
    }
}
