//! SINUMERIK (840D sl, 828D) interpolatory compensation tables: the leadscrew/measuring-system
//! error compensation (EEC, `$AA_ENC_COMP`) of each axis and the sag/cross compensation (CEC,
//! `$AN_CEC`) tables carrying the straightness errors from a base axis to a compensated axis.
//!
//! Rules, from the SINUMERIK Function Manual Extended Functions, K3 Compensations
//! (6FC5397-1BP40-3BA1, 03/2013, section 4.4; 6FC5397-1BP20-0BA0, 09/2009, section 5.4):
//! - Both tables are part programs loaded into the NC (`%_N_AX_EEC_INI` / `%_N_NC_CEC_INI`,
//!   `CHANDATA(1)`, assignments, `M17`), positions and values in millimetres (metric system),
//!   loadable only while `MD32700 ENC_COMP_ENABLE` / `MD32710 CEC_ENABLE` are 0.
//! - EEC: `$AA_ENC_COMP[e,N,AXi]` for interpolation points `0 <= N <= MD38000 - 1`, with
//!   `$AA_ENC_COMP_STEP`, `_MIN` (point 0), `_MAX` (the last point); the first and last values
//!   hold outside; linear interpolation between points. "A positive compensation value causes
//!   the corresponding machine axis to move in the negative direction" (4.4.2.1): the value is
//!   the error itself, `e = actual - commanded`.
//! - CEC: `$AN_CEC[t,N]` for `0 <= N <= MD18342[t] - 1`, `$AN_CEC_INPUT_AXIS[t]` (base axis whose
//!   setpoint is the input), `$AN_CEC_OUTPUT_AXIS[t]` (compensation axis the output is applied
//!   to), `$AN_CEC_STEP`, `_MIN`, `_MAX`, `_DIRECTION`, `_MULT_BY_TABLE`, `_IS_MODULO`. The
//!   value is the correction applied to the compensation axis (the manual's example: "+10 um"
//!   lifts a cross-arm that sags): minus the error. The SINUMERIK 828D has eight CEC tables of
//!   200 points each, not extendable (4.4.4.3); the 808D's EEC tables hold 200 points; volcal
//!   keeps every table within [`SINUMERIK_MAX_POINTS`] so the files load on all of them.
//! - Backlash: `MD32450 $MA_BACKLASH[0]` per axis, mm, positive in the normal case (the
//!   measuring system leads the moving part: the axis lags behind its command on a reversal).
//!
//! Straightness goes into CEC as each reference line's cross-axis error relative to the
//! reference point (zero there), so that EEC (which holds the error at the point) and the
//! CEC tables add up to the model's error along the three lines without counting it twice.

use crate::compensation::{reference_lines, ReferenceLine};
use anyhow::{bail, Result};
use nalgebra::{Point3, Vector3};
use std::fmt::Write as _;
use volcal::{Axis, ErrorModel};
use volcal_sim::controller::interpolate;

/// Interpolation points of one table that every SINUMERIK volcal targets accepts (828D CEC: 200
/// fixed; 808D EEC: 200). The 840D sl allows more through MD38000 / MD18342.
pub const SINUMERIK_MAX_POINTS: usize = 200;

/// CEC tables a SINUMERIK 828D offers (the six straightness tables fit).
pub const SINUMERIK_MAX_CEC_TABLES: usize = 8;

/// The general machine-axis name volcal writes for an axis (AX1 = X, AX2 = Y, AX3 = Z).
pub fn axis_name(a: Axis) -> String {
    format!("AX{}", a.index() + 1)
}

/// One interpolatory table: evenly spaced points of the base axis and a value per point, metres.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// The axis whose position is the input.
    pub input: Axis,
    /// The axis the value acts on (equal to `input` for EEC).
    pub output: Axis,
    pub nominal_m: Vec<f64>,
    /// EEC: the error (the controller subtracts it); CEC: the correction (added).
    pub value_m: Vec<f64>,
}

impl Table {
    fn step_m(&self) -> f64 {
        let n = self.nominal_m.len();
        (self.nominal_m[n - 1] - self.nominal_m[0]) / (n - 1) as f64
    }

    /// The value a SINUMERIK reads at `q` (linear between points, end values held).
    pub fn value_at(&self, q: f64) -> f64 {
        interpolate(&self.nominal_m, &self.value_m, q)
    }
}

/// The EEC tables (one per axis) and the CEC tables (one per base axis and straightness
/// direction, six), sampled along the reference lines through `point`.
pub fn sinumerik(
    model: &ErrorModel,
    step_m: f64,
    point: &Point3<f64>,
    probe: &Vector3<f64>,
) -> Result<(Vec<Table>, Vec<Table>)> {
    let lines = reference_lines(model, step_m, point, probe, SINUMERIK_MAX_POINTS, "SINUMERIK")?;
    let at_point = model.error(point, probe);
    let eec = lines
        .iter()
        .map(|l: &ReferenceLine| Table {
            input: l.axis,
            output: l.axis,
            nominal_m: l.nominal_m.clone(),
            value_m: l.error_m.iter().map(|e| e[l.axis.index()]).collect(),
        })
        .collect();
    let mut cec = Vec::new();
    for l in &lines {
        for out in Axis::ALL.into_iter().filter(|&o| o != l.axis) {
            let k = out.index();
            cec.push(Table {
                input: l.axis,
                output: out,
                nominal_m: l.nominal_m.clone(),
                value_m: l.error_m.iter().map(|e| -(e[k] - at_point[k])).collect(),
            });
        }
    }
    if cec.len() > SINUMERIK_MAX_CEC_TABLES {
        bail!("{} CEC tables; a SINUMERIK 828D offers {SINUMERIK_MAX_CEC_TABLES}", cec.len());
    }
    Ok((eec, cec))
}

/// The correction the EEC and CEC tables together apply at `x`, metres (EEC acts against its
/// value, CEC with it).
pub fn correction(eec: &[Table], cec: &[Table], x: &Point3<f64>) -> Vector3<f64> {
    let mut c = Vector3::zeros();
    for t in eec {
        c[t.output.index()] -= t.value_at(x[t.input.index()]);
    }
    for t in cec {
        c[t.output.index()] += t.value_at(x[t.input.index()]);
    }
    c
}

fn mm(v: f64) -> String {
    format!("{:.9}", v * 1e3)
}

/// `eec.mpf`: the EEC tables of the three axes (`$AA_ENC_COMP[0,N,AXi]`, encoder 0), and as
/// comments the backlash each axis's `MD32450 $MA_BACKLASH` should hold.
pub fn eec_text(eec: &[Table], backlash_m: [f64; 3], comment: &str) -> String {
    let mut out = String::from("%_N_AX_EEC_INI\n");
    for line in comment.lines() {
        let _ = writeln!(out, "; {line}");
    }
    out.push_str("CHANDATA(1)\n");
    for t in eec {
        let ax = axis_name(t.input);
        for (n, v) in t.value_m.iter().enumerate() {
            let _ = writeln!(out, "$AA_ENC_COMP[0,{n},{ax}]={}", mm(*v));
        }
        let _ = writeln!(out, "$AA_ENC_COMP_STEP[0,{ax}]={}", mm(t.step_m()));
        let _ = writeln!(out, "$AA_ENC_COMP_MIN[0,{ax}]={}", mm(t.nominal_m[0]));
        let _ = writeln!(out, "$AA_ENC_COMP_MAX[0,{ax}]={}", mm(t.nominal_m[t.nominal_m.len() - 1]));
        let _ = writeln!(out, "$AA_ENC_COMP_IS_MODULO[0,{ax}]=0");
    }
    for a in Axis::ALL {
        let _ = writeln!(
            out,
            "; MD32450 $MA_BACKLASH[0,{}]={} (machine data, not part of this table)",
            axis_name(a),
            mm(backlash_m[a.index()])
        );
    }
    out.push_str("M17\n");
    out
}

/// `cec.mpf`: the six straightness tables, base axis -> compensated axis.
pub fn cec_text(cec: &[Table], comment: &str) -> String {
    let mut out = String::from("%_N_NC_CEC_INI\n");
    for line in comment.lines() {
        let _ = writeln!(out, "; {line}");
    }
    out.push_str("CHANDATA(1)\n");
    for (t, table) in cec.iter().enumerate() {
        let _ = writeln!(
            out,
            "; table {t}: straightness of {} in {} (correction added to {})",
            table.input.letter(),
            table.output.letter(),
            axis_name(table.output)
        );
        for (n, v) in table.value_m.iter().enumerate() {
            let _ = writeln!(out, "$AN_CEC[{t},{n}]={}", mm(*v));
        }
        let _ = writeln!(out, "$AN_CEC_INPUT_AXIS[{t}]=({})", axis_name(table.input));
        let _ = writeln!(out, "$AN_CEC_OUTPUT_AXIS[{t}]=({})", axis_name(table.output));
        let _ = writeln!(out, "$AN_CEC_STEP[{t}]={}", mm(table.step_m()));
        let _ = writeln!(out, "$AN_CEC_MIN[{t}]={}", mm(table.nominal_m[0]));
        let _ = writeln!(out, "$AN_CEC_MAX[{t}]={}", mm(table.nominal_m[table.nominal_m.len() - 1]));
        let _ = writeln!(out, "$AN_CEC_DIRECTION[{t}]=0");
        let _ = writeln!(out, "$AN_CEC_MULT_BY_TABLE[{t}]=0");
        let _ = writeln!(out, "$AN_CEC_IS_MODULO[{t}]=0");
    }
    out.push_str("M17\n");
    out
}
