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

use crate::compensation::{axis_nodes, Residual};
use anyhow::Result;
use nalgebra::{Point3, Vector3};
use std::fmt::Write as _;
use volcal::{Axis, ErrorFunction, ErrorModel, Squareness};
use volcal_sim::controller::bracket;

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

/// The component errors of each axis at nodes about `step_m` apart, and the squareness errors
/// with the axis they describe.
pub fn isg(model: &ErrorModel, step_m: f64) -> Result<Vec<IsgTable>> {
    let travel = model.layout.travel;
    Axis::ALL
        .iter()
        .map(|&a| {
            let nominal_m = axis_nodes(&travel, a, step_m, ISG_MAX_RECORDS, "volcal's ISG export")?;
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
/// linearly interpolated functions exactly, on a grid of `step_m` at probe offset `probe`. To
/// first order the difference of a function from its interpolation acts through the same lever
/// arms as the function (`Topology::lever_arm`); squareness is carried exactly.
pub fn interpolation_residual(model: &ErrorModel, tables: &[IsgTable], step_m: f64, probe: &Vector3<f64>) -> Residual {
    let topology = &model.layout.topology;
    crate::compensation::residual(model, step_m, probe, |x: &Point3<f64>| {
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
