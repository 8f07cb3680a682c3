//! The ISG kernel's volumetric compensation tables (Beckhoff TwinCAT 3 CNC, TF5280), in the
//! "ISG CSV" format: all 21 error functions, so the controller compensates the whole model.
//!
//! Format rules, from the ISG/Beckhoff documentation (infosys.beckhoff.com, TF5280 Volumetric
//! Compensation):
//! - "ISG CSV format" (tf5280_volumetric_comp/296429067): a header line naming the columns
//!   (arguments such as `X` and parameters such as `EXX EYX EZX EAX EBX ECX`), then one record
//!   per line; `//` starts a line comment; a line `#` is a "file break" after which a new header
//!   and its records follow (how the position errors `C0Y`, `B0Z`, `A0Z` share a file with the
//!   component errors of their axis).
//! - "Units of measure" (tf5280_volumetric_comp/296426379): parameter values in millimetres for
//!   offsets and radians for angles; arguments (the axis positions) in millimetres.
//! - "List of parameters supported" (tf5280_volumetric_comp/296423819): ISO 230-1 component
//!   errors `EXX ... ECZ` and position errors `X0X ... C0C` (volcal's `EC0Y`, `EB0Z`, `EA0Z` are
//!   `C0Y`, `B0Z`, `A0Z`).
//! - The tables hold the machine's *errors* (ISO 230-1 deviations, actual minus nominal); the
//!   kernel computes the correction from them through its kinematic chain (P-VOLC-00007 `chain`,
//!   P-VOLC-00008 `workpiece_axes`); P-VOLC-00009 `negate` exists to flip the sign of the
//!   computed compensation ("Modification of compensation values", 296393995). volcal's
//!   functions follow the same convention (DESIGN.md: `e = actual - (commanded + probe offset)`),
//!   so values are written as they are, unnegated.
//! - Records on a grid are interpolated linearly with `Interpolation GRID` (diagnosis IDs 70471,
//!   70474); what linear interpolation between the nodes loses is [`interpolation_residual`].

use crate::compensation::{Nodes, Residual};
use anyhow::{bail, Context, Result};
use nalgebra::{Point3, Vector3};
use std::fmt::Write as _;
use std::path::Path;
use volcal::{Axis, ErrorFunction, ErrorModel, ModelLayout, Representation, Squareness, Travel};
use volcal_sim::controller::{bracket, VolumetricCompensation};

/// volcal's own bound on the records of one axis (the ISG kernel's bound is the configured
/// `vol_comp[i].max_records`, which README.txt says to set): a table this long at 0.01 mm
/// steps would already be finer than any machine's errors vary.
pub const ISG_MAX_RECORDS: usize = 100_000;

/// The six component errors of one axis at its nodes.
#[derive(Clone, Debug, PartialEq)]
pub struct IsgTable {
    pub axis: Axis,
    /// Nodes, metres, ascending, evenly spaced over the identified travel.
    pub nominal_m: Vec<f64>,
    /// `EXK EYK EZK` (metres) and `EAK EBK ECK` (radians) at each node, in that order.
    pub values: Vec<[f64; 6]>,
    /// The position (squareness) errors that belong to this axis, ISG names and radians.
    pub squareness: Vec<(&'static str, f64)>,
}

/// ISG's name of a squareness error: ISO 230-1's without the leading `E` (`EC0Y` -> `C0Y`).
pub fn isg_name(s: Squareness) -> &'static str {
    &s.name()[1..]
}

/// The component errors of each axis at its `nodes` (evenly spaced: `Interpolation GRID`), and
/// the squareness errors with the axis they describe.
pub fn isg(model: &ErrorModel, nodes: &Nodes) -> Result<Vec<IsgTable>> {
    let travel = model.layout.travel;
    Axis::ALL
        .iter()
        .map(|&a| {
            let nominal_m = nodes.along(&travel, a, ISG_MAX_RECORDS, true, "volcal's ISG export")?;
            let values = nominal_m
                .iter()
                .map(|&q| {
                    std::array::from_fn(|m| model.function_value(ErrorFunction::from_index(a.index() * 6 + m), q))
                })
                .collect();
            let squareness =
                Squareness::ALL.iter().filter(|s| s.axis() == a).map(|&s| (isg_name(s), model.squareness(s))).collect();
            Ok(IsgTable { axis: a, nominal_m, values, squareness })
        })
        .collect()
}

impl IsgTable {
    /// The file text: `//` comments, header `K EXK EYK EZK EAK EBK ECK`, one record per node
    /// (position mm, translations mm, rotations rad); then, after a `#` file break, the
    /// squareness errors of this axis (rad) as one record.
    pub fn text(&self, comment: &str) -> String {
        let k = self.axis.letter();
        let mut out = String::new();
        for line in comment.lines() {
            let _ = writeln!(out, "// {line}");
        }
        let names: Vec<String> = (0..6).map(|m| ErrorFunction::from_index(self.axis.index() * 6 + m).name()).collect();
        let _ = writeln!(out, "// {k} in mm; {} in mm; {} in rad", names[..3].join(" "), names[3..].join(" "));
        let _ = writeln!(out, "{k} {}", names.join(" "));
        for (q, v) in self.nominal_m.iter().zip(&self.values) {
            let _ = writeln!(
                out,
                "{:.6} {:.9} {:.9} {:.9} {:.12} {:.12} {:.12}",
                q * 1e3,
                v[0] * 1e3,
                v[1] * 1e3,
                v[2] * 1e3,
                v[3],
                v[4],
                v[5]
            );
        }
        if !self.squareness.is_empty() {
            let _ = writeln!(out, "#");
            let _ = writeln!(out, "// squareness (ISO 230-1 position errors) of the {k} axis, rad");
            let names: Vec<&str> = self.squareness.iter().map(|(n, _)| *n).collect();
            let values: Vec<String> = self.squareness.iter().map(|(_, v)| format!("{v:.12}")).collect();
            let _ = writeln!(out, "{}", names.join(" "));
            let _ = writeln!(out, "{}", values.join(" "));
        }
        out
    }

    /// The six component errors a controller interpolating this table linearly reads at `q`.
    fn interpolated(&self, q: f64) -> [f64; 6] {
        let (i, s) = bracket(&self.nominal_m, q);
        let v = &self.values;
        std::array::from_fn(|m| if s == 0.0 { v[i][m] } else { v[i][m] + s * (v[i + 1][m] - v[i][m]) })
    }
}

/// What the tables lose against the model: the error left where the controller compensates the
/// linearly interpolated functions exactly, on a grid of `step_m` at probe offset `probe`, over
/// the points where `keep` holds ([`crate::compensation::residual_where`]). To first order the
/// difference of a function from its interpolation acts through the same lever arms as the
/// function (`Topology::lever_arm`); squareness is carried exactly.
pub fn interpolation_residual(
    model: &ErrorModel,
    tables: &[IsgTable],
    step_m: f64,
    probe: &Vector3<f64>,
    keep: impl Fn(&Point3<f64>) -> bool,
) -> Residual {
    let topology = &model.layout.topology;
    crate::compensation::residual_where(model, step_m, probe, keep, |x: &Point3<f64>| {
        let mut lost = Vector3::zeros();
        for t in tables {
            let q = x[t.axis.index()];
            let read = t.interpolated(q);
            let d: [f64; 6] = std::array::from_fn(|m| {
                model.function_value(ErrorFunction::from_index(t.axis.index() * 6 + m), q) - read[m]
            });
            let h = topology.lever_arm(t.axis, x, probe);
            lost += Vector3::new(d[0], d[1], d[2]) + Vector3::new(d[3], d[4], d[5]).cross(&h);
        }
        // The controller removes all of the error but what its tables lost.
        lost - model.error(x, probe)
    })
}

/// Reads `isg_x.csv`, `isg_y.csv`, `isg_z.csv` from `dir` (as [`IsgTable::text`] writes them) as
/// the volumetric compensation an ISG kernel configured with `topology` applies
/// ([`VolumetricCompensation`]): the functions linear between the nodes, which must be evenly
/// spaced (`Interpolation GRID`), squareness from the `#` section. Read from the text alone, as
/// the controller reads it; errors name the file and line.
pub fn read_isg(dir: &Path, topology: volcal::Topology) -> Result<VolumetricCompensation> {
    let mut columns: Vec<(Vec<f64>, Vec<[f64; 6]>)> = Vec::new();
    let mut squareness: Vec<(Squareness, f64)> = Vec::new();
    for a in Axis::ALL {
        let path = dir.join(format!("isg_{}.csv", a.letter().to_ascii_lowercase()));
        let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
        let (nodes, values, sq) = parse_isg(&text, a).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        columns.push((nodes, values));
        squareness.extend(sq);
    }
    let travel = Travel::new(
        [columns[0].0[0], *columns[0].0.last().unwrap()],
        [columns[1].0[0], *columns[1].0.last().unwrap()],
        [columns[2].0[0], *columns[2].0.last().unwrap()],
    );
    let reprs = std::array::from_fn(|i| Representation::Table { nodes: columns[i / 6].0.len() });
    let mut model = ErrorModel::zero(ModelLayout::new(topology, travel, reprs));
    for (a, (_, values)) in columns.iter().enumerate() {
        for m in 0..6 {
            let c = model.coeffs_mut(ErrorFunction::from_index(a * 6 + m));
            for (ci, v) in c.iter_mut().zip(values) {
                *ci = v[m];
            }
        }
    }
    for (s, v) in squareness {
        model.set_squareness(s, v);
    }
    Ok(VolumetricCompensation { tables: model })
}

/// One axis's file: nodes (metres), the six component errors at each (metres, radians), and the
/// squareness records. Errors say the line.
#[allow(clippy::type_complexity)]
fn parse_isg(text: &str, a: Axis) -> Result<(Vec<f64>, Vec<[f64; 6]>, Vec<(Squareness, f64)>)> {
    let k = a.letter();
    let names: Vec<String> = (0..6).map(|m| ErrorFunction::from_index(a.index() * 6 + m).name()).collect();
    let want = format!("{k} {}", names.join(" "));
    let lines =
        text.lines().enumerate().map(|(i, l)| (i + 1, l.trim())).filter(|(_, l)| !l.is_empty() && !l.starts_with("//"));
    let (mut nodes, mut values, mut squareness, mut at_line) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    // Sections: the component table, then after each `#` a header and records.
    let mut header: Option<Vec<String>> = None;
    let mut in_table = true;
    for (n, l) in lines {
        if l == "#" {
            (header, in_table) = (None, false);
            continue;
        }
        let fields: Vec<&str> = l.split_whitespace().collect();
        let Some(h) = &header else {
            if in_table && fields.join(" ") != want {
                bail!("line {n}: header {l:?}, expected {want:?}");
            }
            header = Some(fields.iter().map(|s| s.to_string()).collect());
            continue;
        };
        if fields.len() != h.len() {
            bail!("line {n}: {} values under a header of {} columns ({})", fields.len(), h.len(), h.join(" "));
        }
        let v: Vec<f64> = fields
            .iter()
            .zip(h)
            .map(|(f, name)| {
                f.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .with_context(|| format!("line {n}: {name} is not a number: {f:?}"))
            })
            .collect::<Result<_>>()?;
        if in_table {
            // Position and translations in mm, rotations in rad.
            nodes.push(v[0] * 1e-3);
            at_line.push(n);
            values.push([v[1] * 1e-3, v[2] * 1e-3, v[3] * 1e-3, v[4], v[5], v[6]]);
        } else {
            for (name, x) in h.iter().zip(v) {
                let s = Squareness::ALL
                    .into_iter()
                    .find(|s| isg_name(*s) == name && s.axis() == a)
                    .with_context(|| format!("line {n}: {name:?} is not a position error of the {k} axis"))?;
                squareness.push((s, x));
            }
        }
    }
    if nodes.len() < 2 {
        bail!("{} records; a table needs at least 2", nodes.len());
    }
    let step = (nodes[nodes.len() - 1] - nodes[0]) / (nodes.len() - 1) as f64;
    if let Some(i) = (1..nodes.len()).find(|&i| ((nodes[i] - nodes[i - 1]) - step).abs() > 1e-9 + 1e-9 * step.abs()) {
        bail!(
            "line {}: position {} mm breaks the even spacing of {} mm (Interpolation GRID needs evenly spaced, ascending records)",
            at_line[i],
            nodes[i] * 1e3,
            step * 1e3
        );
    }
    if !(step > 0.0) {
        bail!("positions must ascend");
    }
    Ok((nodes, values, squareness))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn model() -> ErrorModel {
        let layout = ModelLayout::uniform(
            "XFYZ".parse().unwrap(),
            Travel::new([0.0, 0.8], [0.0, 0.5], [-0.5, 0.0]),
            Representation::BSpline { intervals: 8 },
        );
        volcal_sim::random_truth(layout, &Default::default(), &mut rand_chacha::ChaCha8Rng::seed_from_u64(3))
    }

    fn written(model: &ErrorModel, step_m: f64, name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("volcal-isg-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for t in isg(model, &Nodes::even(step_m)).unwrap() {
            let file = dir.join(format!("isg_{}.csv", t.axis.letter().to_ascii_lowercase()));
            std::fs::write(file, t.text("test")).unwrap();
        }
        dir
    }

    #[test]
    fn the_tables_read_back_are_the_model_at_the_nodes_and_linear_between() {
        let m = model();
        let dir = written(&m, 0.05, "roundtrip");
        let c = read_isg(&dir, m.layout.topology.clone()).unwrap();
        for f in ErrorFunction::all() {
            let [lo, hi] = m.layout.travel.range(f.axis);
            // Every other point a node (the files' resolution: 1e-12 m or rad), the others
            // half-way, where a controller reads the mean of the two nodes.
            let intervals = ((hi - lo) / 0.05).round() as usize;
            let q = |k: usize| lo + (hi - lo) * k as f64 / (2 * intervals) as f64;
            for k in 0..=2 * intervals {
                let read = c.tables.function_value(f, q(k));
                let want = if k % 2 == 0 {
                    m.function_value(f, q(k))
                } else {
                    0.5 * (m.function_value(f, q(k - 1)) + m.function_value(f, q(k + 1)))
                };
                assert!((read - want).abs() < 1e-12, "{} at {}: {read} vs {want}", f.name(), q(k));
            }
        }
        for s in Squareness::ALL {
            assert!((c.tables.squareness(s) - m.squareness(s)).abs() <= 0.5e-12, "{}", s.name());
        }
        // The controller removes the error to second order where the tables are exact.
        let (x, p) = (Point3::new(0.4, 0.2, -0.1), Vector3::new(0.0, 0.0, -0.15));
        let left = m.error(&x, &p) + c.at(&x, &p);
        assert!(left.norm() < 0.02 * m.error(&x, &p).norm(), "{left}");
    }

    #[test]
    fn a_bad_record_is_named_with_its_line() {
        let m = model();
        let dir = written(&m, 0.1, "bad");
        let file = dir.join("isg_y.csv");
        let text = std::fs::read_to_string(&file).unwrap().replacen("100.000000 ", "100.000000 x", 1);
        std::fs::write(&file, text).unwrap();
        let err = format!("{:#}", read_isg(&dir, m.layout.topology.clone()).err().unwrap());
        assert!(err.contains("isg_y.csv: line 5: EXY is not a number"), "{err}");
        let text = std::fs::read_to_string(&file).unwrap().replacen("Y EXY", "Y EYY", 1);
        std::fs::write(&file, text).unwrap();
        let err = format!("{:#}", read_isg(&dir, m.layout.topology.clone()).err().unwrap());
        assert!(err.contains("isg_y.csv: line 3: header"), "{err}");
    }
}
