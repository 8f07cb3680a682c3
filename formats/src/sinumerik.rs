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

use crate::compensation::{reference_lines, Nodes, ReferenceLine};
use anyhow::{bail, Context, Result};
use nalgebra::{Point3, Vector3};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use volcal::{Axis, ErrorModel};
use volcal_sim::controller::{AxisTable, AxisTableCompensation};

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
}

/// The EEC tables (one per axis) and the CEC tables (one per base axis and straightness
/// direction, six), sampled along the reference lines through `point`.
pub fn sinumerik(
    model: &ErrorModel,
    nodes: &Nodes,
    point: &Point3<f64>,
    probe: &Vector3<f64>,
) -> Result<(Vec<Table>, Vec<Table>)> {
    let lines = reference_lines(model, nodes, point, probe, SINUMERIK_MAX_POINTS, true, "SINUMERIK")?;
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

/// The controller's view of EEC and CEC tables: each table as the correction it adds (EEC
/// against its value, CEC with it).
pub fn controller(eec: &[Table], cec: &[Table]) -> AxisTableCompensation {
    let tables = eec
        .iter()
        .map(|t| (t, -1.0))
        .chain(cec.iter().map(|t| (t, 1.0)))
        .map(|(t, sign)| AxisTable {
            input: t.input,
            output: t.output,
            nominal_m: t.nominal_m.clone(),
            correction_m: t.value_m.iter().map(|v| sign * v).collect(),
        })
        .collect();
    AxisTableCompensation { tables }
}

/// Reads `eec.mpf` and `cec.mpf` from `dir` (as [`eec_text`] and [`cec_text`] write them) as a
/// SINUMERIK applies them: the part-program assignments alone (`;` comments, `%_N_..._INI`,
/// `CHANDATA`, `M17`), points at `_MIN + N * _STEP` up to `_MAX`. Errors name the file and
/// line; table options volcal does not simulate (a direction-dependent or multiplied CEC table,
/// modulo axes) are refused.
pub fn read_sinumerik(dir: &Path) -> Result<AxisTableCompensation> {
    let read = |file: &str, eec: bool| -> Result<Vec<Table>> {
        let path = dir.join(file);
        let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
        parse_tables(&text, eec).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
    };
    Ok(controller(&read("eec.mpf", true)?, &read("cec.mpf", false)?))
}

/// The tables of one file (`eec`: EEC tables, else CEC).
fn parse_tables(text: &str, eec: bool) -> Result<Vec<Table>> {
    // Per table key (EEC: axis name; CEC: table number): points and scalar settings.
    let mut points: BTreeMap<String, BTreeMap<usize, f64>> = BTreeMap::new();
    // The line where each table's first point is: what an error about the table as a whole names.
    let mut first_line: BTreeMap<String, usize> = BTreeMap::new();
    let mut settings: BTreeMap<(String, String), (usize, String)> = BTreeMap::new();
    for (i, l) in text.lines().enumerate() {
        let n = i + 1;
        let l = l.split(';').next().unwrap_or("").trim();
        if l.is_empty() || l.starts_with('%') || l == "CHANDATA(1)" || l == "M17" {
            continue;
        }
        let (lhs, rhs) = l.split_once('=').with_context(|| format!("line {n}: not an assignment: {l:?}"))?;
        let (name, args) = lhs
            .strip_suffix(']')
            .and_then(|x| x.split_once('['))
            .with_context(|| format!("line {n}: no [index] in {lhs:?}"))?;
        let args: Vec<&str> = args.split(',').map(str::trim).collect();
        let prefix = if eec { "$AA_ENC_COMP" } else { "$AN_CEC" };
        let Some(field) = name.strip_prefix(prefix) else {
            bail!("line {n}: {name} is not a {} variable", if eec { "EEC ($AA_ENC_COMP)" } else { "CEC ($AN_CEC)" });
        };
        // EEC: [encoder, N, AXi] for points, [encoder, AXi] for settings; CEC: [t, N] / [t].
        let (key, index) = match (eec, field.is_empty(), args.as_slice()) {
            (true, true, [_, k, ax]) => (ax.to_string(), Some(k)),
            (true, false, [_, ax]) => (ax.to_string(), None),
            (false, true, [t, k]) => (t.to_string(), Some(k)),
            (false, false, [t]) => (t.to_string(), None),
            _ => bail!("line {n}: unexpected indices [{}] for {name}", args.join(",")),
        };
        match index {
            Some(k) => {
                let k: usize = k.parse().with_context(|| format!("line {n}: point index {k:?} is not a number"))?;
                let v: f64 = rhs
                    .trim()
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite())
                    .with_context(|| format!("line {n}: value {rhs:?} is not a number"))?;
                first_line.entry(key.clone()).or_insert(n);
                points.entry(key).or_default().insert(k, v * 1e-3);
            }
            None => {
                settings.insert((key, field.to_string()), (n, rhs.trim().to_string()));
            }
        }
    }
    let mut out = Vec::new();
    for (key, pts) in points {
        let get = |f: &str| -> Result<(usize, String)> {
            settings.get(&(key.clone(), f.to_string())).cloned().with_context(|| format!("table {key}: no {f}"))
        };
        let number = |f: &str| -> Result<f64> {
            let (n, v) = get(f)?;
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .with_context(|| format!("line {n}: {f} {v:?} is not a number"))
        };
        let axis = |v: &str, n: usize| -> Result<Axis> {
            let v = v.trim_start_matches('(').trim_end_matches(')');
            Axis::ALL
                .into_iter()
                .find(|a| axis_name(*a) == v)
                .with_context(|| format!("line {n}: axis {v:?} is none of AX1, AX2, AX3"))
        };
        let (input, output) = if eec {
            let a = axis(&key, first_line[&key])?;
            (a, a)
        } else {
            let (ni, vi) = get("_INPUT_AXIS")?;
            let (no, vo) = get("_OUTPUT_AXIS")?;
            for f in ["_DIRECTION", "_MULT_BY_TABLE"] {
                if let Ok((n, v)) = get(f) {
                    if v != "0" {
                        bail!("line {n}: {f} = {v}; volcal simulates only 0 (both directions, not multiplied)");
                    }
                }
            }
            (axis(&vi, ni)?, axis(&vo, no)?)
        };
        if let Ok((n, v)) = get("_IS_MODULO") {
            if v != "0" {
                bail!("line {n}: _IS_MODULO = {v}; modulo axes are not simulated");
            }
        }
        let (step, min, max) = (number("_STEP")? * 1e-3, number("_MIN")? * 1e-3, number("_MAX")? * 1e-3);
        let count = pts.len();
        if pts.keys().copied().ne(0..count) {
            bail!("table {key}: point indices are not 0..{}", count - 1);
        }
        if !(step > 0.0) || ((min + step * (count - 1) as f64) - max).abs() > 1e-9 {
            bail!(
                "table {key}: {count} points from {} mm in steps of {} mm do not end at _MAX {} mm",
                min * 1e3,
                step * 1e3,
                max * 1e3
            );
        }
        let nominal_m = (0..count).map(|k| min + step * k as f64).collect();
        out.push(Table { input, output, nominal_m, value_m: pts.into_values().collect() });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use volcal::{ModelLayout, Representation, Travel};

    #[test]
    fn the_files_read_back_are_the_tables_the_export_computed() {
        let layout = ModelLayout::uniform(
            "FXYZ".parse().unwrap(),
            Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]),
            Representation::BSpline { intervals: 8 },
        );
        let m = volcal_sim::random_truth(layout, &Default::default(), &mut rand_chacha::ChaCha8Rng::seed_from_u64(5));
        let (point, p) = (Point3::new(0.5, 0.4, -0.3), Vector3::zeros());
        let (eec, cec) = sinumerik(&m, &Nodes::even(0.02), &point, &p).unwrap();
        let dir = std::env::temp_dir().join(format!("volcal-sinumerik-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("eec.mpf"), eec_text(&eec, [0.0; 3], "test")).unwrap();
        std::fs::write(dir.join("cec.mpf"), cec_text(&cec, "test")).unwrap();
        let nc = read_sinumerik(&dir).unwrap();
        let want = controller(&eec, &cec);
        assert_eq!(nc.tables.len(), 9);
        for x in [Point3::new(0.13, 0.71, -0.05), Point3::new(0.5, 0.4, -0.3), Point3::new(0.99, 0.0, -0.6)] {
            assert!((nc.at(&x) - want.at(&x)).norm() < 1e-12, "{x}");
        }
        // Along the reference lines EEC and CEC together remove the model's error (to the
        // linear interpolation between 20 mm points).
        for x in [Point3::new(0.21, 0.4, -0.3), Point3::new(0.5, 0.63, -0.3), Point3::new(0.5, 0.4, -0.47)] {
            let left = m.error(&x, &p) + nc.at(&x);
            assert!(left.norm() < 0.05e-6, "{x}: {left}");
        }
        // A table option volcal does not simulate is refused with its line.
        let text =
            std::fs::read_to_string(dir.join("cec.mpf")).unwrap().replacen("_DIRECTION[2]=0", "_DIRECTION[2]=1", 1);
        std::fs::write(dir.join("cec.mpf"), text).unwrap();
        let err = format!("{:#}", read_sinumerik(&dir).err().unwrap());
        assert!(err.contains("cec.mpf: line") && err.contains("_DIRECTION = 1"), "{err}");
    }
}
