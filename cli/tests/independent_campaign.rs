//! Issue 12 on data we did not simulate: campaigns from an independent simulator
//! (tests/py/independent_campaign.py: NumPy, its own machine, plan and readings from DESIGN.md's
//! conventions alone, none of volcal's code), solved as a new user would, `volcal solve` with
//! the two-line machine file, and checked where no gauge can hide anything: the positioning
//! deviation an interferometer reads along validation lines that are none of the campaign's
//! (`volcal validate --line`), against the simulator's noise-free truth.
//!
//! The truth family (a smooth Gaussian-process draw per function, squared-exponential, length
//! scale 0.15 to 0.4 of the travel) is none of volcal's representations and none of the families
//! `representation_auto` was developed on; the seeds here (101-106) were never used to choose
//! anything. The bounds were set before the test was first run on them: no deviation beyond 5
//! standard uncertainties, at most 1 % beyond 3 (a calibrated uncertainty gives 0.27 %), and
//! the RMS of the deviations over their uncertainties within 0.7 to 1.3 per method.
//!
//! Beside volcal's error, the test prints the oracle's at the same targets: the simulator's
//! Bayes estimator, told the truth's own basis and prior (`--oracle`), the least error any
//! estimator can have on average on this family and these readings. Its uncertainty is asserted
//! to be calibrated (the same 0.7 to 1.3), so that it is a yardstick; the ratio is measured, not
//! bound (README, "On data we did not simulate"). So is the ratio in the issue's own measure, the
//! volumetric map's error over the volume with the gauge removed ([`MapError`]): `volcal map`
//! against the map of the oracle's posterior-mean machine, on the same grid.

use std::path::{Path, PathBuf};
use std::process::Command;

const SEEDS: std::ops::Range<u64> = 101..107;

/// [`SEEDS`], or the range `VOLCAL_INDEPENDENT_SEEDS=FIRST-LAST` names (a longer study by hand:
/// the bounds are the test's on any seeds).
fn seeds() -> std::ops::Range<u64> {
    std::env::var("VOLCAL_INDEPENDENT_SEEDS")
        .ok()
        .and_then(|v| {
            let (a, b) = v.split_once('-')?;
            Some(a.trim().parse().ok()?..b.trim().parse::<u64>().ok()? + 1)
        })
        .unwrap_or(SEEDS)
}

/// Further arguments of the simulator's machine that `VOLCAL_INDEPENDENT_MACHINE` names (for
/// example `--amplitude 10 --length-scale 0.05,0.15`: a study by hand of magnitudes and shapes
/// the seeds here do not have; the bounds are the test's on any machine).
fn machine_args() -> Vec<String> {
    std::env::var("VOLCAL_INDEPENDENT_MACHINE")
        .map(|v| v.split_whitespace().map(str::to_owned).collect())
        .unwrap_or_default()
}

/// The travel `VOLCAL_INDEPENDENT_TRAVEL=XLO,XHI;YLO,YHI;ZLO,ZHI` (metres) names instead of each
/// test's own (a study by hand of machines of other sizes, a large gantry or a small stage: the
/// simulator's functions keep their magnitudes and their length scales as fractions of the
/// travel; the bounds are the test's on any travel).
fn travel_override() -> Option<[[f64; 2]; 3]> {
    let v = std::env::var("VOLCAL_INDEPENDENT_TRAVEL").ok()?;
    let axes: Vec<[f64; 2]> = v
        .split(';')
        .map(|a| {
            let (lo, hi) = a.split_once(',').expect("VOLCAL_INDEPENDENT_TRAVEL: lo,hi per axis");
            [lo.trim().parse().expect("a number"), hi.trim().parse().expect("a number")]
        })
        .collect();
    Some(axes.try_into().expect("VOLCAL_INDEPENDENT_TRAVEL: three axes"))
}

/// The map's grid step: [`MAP_STEP`], or a fifth of the longest axis of
/// [`travel_override`]'s travel (the same five steps along the demo CMM's X).
fn map_step() -> String {
    travel_override()
        .map(|t| format!("{}", t.iter().map(|[lo, hi]| hi - lo).fold(0.0, f64::max) / 5.0))
        .unwrap_or_else(|| MAP_STEP.to_string())
}

/// One validation target: the truth's deviation, the model's prediction and its standard
/// uncertainty.
struct Target {
    line: String,
    /// Index of the target along its line (0 the start, 10 the end).
    index: usize,
    truth_m: f64,
    predicted_m: f64,
    sigma_m: f64,
    /// The oracle's prediction and standard uncertainty (the Bayes estimator under the prior the
    /// truth was drawn from, computed by the simulator: `--oracle`).
    oracle_m: f64,
    oracle_sigma_m: f64,
}

impl Target {
    /// volcal's deviation from the truth in its standard uncertainties.
    fn z(&self) -> f64 {
        (self.predicted_m - self.truth_m) / self.sigma_m
    }

    /// The oracle's deviation from the truth in its standard uncertainties.
    fn oracle_z(&self) -> f64 {
        (self.oracle_m - self.truth_m) / self.oracle_sigma_m
    }
}

fn run(cmd: &mut Command) -> String {
    let out = cmd.output().expect("runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    // `volcal solve` exits 3 where some functions are not identifiable (the tracer's rotations of
    // Z with the reflector at the tool): the model is written and says so.
    assert!(matches!(out.status.code(), Some(0) | Some(3)), "{cmd:?} failed:\n{text}");
    text
}

/// Simulates `method` for `seed` with the independent simulator, solves it with the two-line
/// machine file and predicts every validation line: the targets given a number, the names of
/// those given none (not determined), and the map's error ([`MapError`]).
fn validated(
    py: &Path,
    dir: &Path,
    method: &str,
    topology: &str,
    travel: [[f64; 2]; 3],
    seed: u64,
    machine: &[String],
) -> (Vec<Target>, Vec<String>, MapError) {
    let root = volcal_tests::repo_root();
    let d = dir.join(format!("{method}-{seed}"));
    let travel = travel_override().unwrap_or(travel);
    let step = map_step();
    let travel_arg = travel.iter().map(|[lo, hi]| format!("{lo},{hi}")).collect::<Vec<_>>().join(";");
    let mut sim = Command::new(py);
    sim.arg(root.join("tests/py/independent_campaign.py"));
    if method == "beams-sparse" {
        sim.arg("--sparse");
    }
    sim.args(machine);
    run(sim.args([
        "--method",
        method.trim_end_matches("-sparse"),
        "--topology",
        topology,
        "--travel",
        &travel_arg,
        "--seed",
        &seed.to_string(),
        "--points",
        match method {
            "tracer" => "11",
            "beams-sparse" => "20",
            _ => "25",
        },
        "--oracle",
        "--map-step",
        &step,
        "--out",
        d.to_str().unwrap(),
    ]));
    // What the beams were aligned with, where the simulator was told: a campaign that knows it
    // says so (the machine file's third line); otherwise the two-line file.
    let stated = machine
        .windows(2)
        .find(|w| w[0] == "--beam-alignment")
        .map(|w| format!("beam_alignment: {}\n", w[1]))
        .unwrap_or_default();
    let machine = d.join("machine.yaml");
    let [x, y, z] = travel;
    std::fs::write(
        &machine,
        format!(
            "topology: {topology}\ntravel: {{x: [{}, {}], y: [{}, {}], z: [{}, {}]}}\n{stated}",
            x[0], x[1], y[0], y[1], z[0], z[1]
        ),
    )
    .unwrap();
    let model = d.join("model.json");
    let exe = env!("CARGO_BIN_EXE_volcal");
    run(Command::new(exe)
        .arg("solve")
        .arg(d.join("campaign.csv"))
        .arg("--machine")
        .arg(&machine)
        .arg("--out")
        .arg(&model));
    if method == "beams" {
        // The 45 beams see each face diagonal's two straightnesses only in combination, and
        // leave their odd part open alike: one smoothing parameter for each pair (issue 12).
        let shared = shared_smoothing(&model);
        for pair in ["EYX+EXY", "EZX+EXZ", "EZY+EYZ"] {
            assert!(
                shared.iter().any(|s| s == pair),
                "{method} seed {seed}: {pair} do not share a smoothing, only {shared:?}"
            );
        }
    }
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(d.join("validation.json")).unwrap()).unwrap();
    let mut probes: Vec<String> = v["lines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| {
            l["probe"].as_array().unwrap().iter().map(|c| c.as_f64().unwrap().to_string()).collect::<Vec<_>>().join(",")
        })
        .collect();
    probes.dedup();
    let map = map_error(&d, &probes);
    let (mut out, mut open) = (Vec::new(), Vec::new());
    for (k, line) in v["lines"].as_array().unwrap().iter().enumerate() {
        let triple = |key: &str| {
            line[key].as_array().unwrap().iter().map(|c| c.as_f64().unwrap().to_string()).collect::<Vec<_>>().join(",")
        };
        let csv = d.join(format!("line{k}.csv"));
        run(Command::new(exe).arg("validate").arg(&model).args([
            "--line",
            &format!("{}:{}", triple("start"), triple("end")),
            "--probe",
            &triple("probe"),
            "--points",
            "11",
            "--out",
            csv.to_str().unwrap(),
        ]));
        let series =
            |key: &str| -> Vec<f64> { line[key].as_array().unwrap().iter().map(|c| c.as_f64().unwrap()).collect() };
        let (truth, oracle, oracle_sigma) = (series("deviation_m"), series("oracle_m"), series("oracle_sd_m"));
        let text = std::fs::read_to_string(&csv).unwrap();
        let mut rows = text.lines();
        let col = columns(rows.next().unwrap());
        let (pc, uc) = (col("predicted_m"), col("u_predicted_m"));
        for (i, row) in rows.enumerate() {
            // The start, where the interferometer is zeroed, has no deviation to test.
            if i == 0 {
                continue;
            }
            let f: Vec<&str> = row.split(',').collect();
            let name = format!("{} p=({})", line["name"].as_str().unwrap(), triple("probe"));
            match (f[pc].parse::<f64>(), f[uc].parse::<f64>()) {
                (Ok(p), Ok(u)) if p.is_finite() && u.is_finite() => {}
                _ => {
                    open.push(name);
                    continue;
                }
            }
            let (p, u) = (f[pc].parse::<f64>().unwrap(), f[uc].parse::<f64>().unwrap());
            out.push(Target {
                line: name,
                index: i,
                truth_m: truth[i],
                predicted_m: p,
                sigma_m: u,
                oracle_m: oracle[i],
                oracle_sigma_m: oracle_sigma[i],
            });
        }
    }
    (out, open, map)
}

/// What the model file of `method`'s campaign for `seed` (in a test's scratch `dir`) records of
/// the beams' alignment (`beam_alignment`).
fn beam_alignment_of(dir: &Path, method: &str, seed: u64) -> serde_json::Value {
    let model = dir.join(format!("{method}-{seed}/model.json"));
    let m: serde_json::Value = serde_json::from_slice(&std::fs::read(&model).unwrap()).unwrap();
    m["beam_alignment"].clone()
}

/// The functions of `model` (a model file of `volcal solve`) that share a smoothing parameter,
/// as `A+B` per function and each function it shares with.
fn shared_smoothing(model: &Path) -> Vec<String> {
    let m: serde_json::Value = serde_json::from_slice(&std::fs::read(model).unwrap()).unwrap();
    let mut out = Vec::new();
    for f in m["representation_choice"]["smoothing"].as_array().into_iter().flatten() {
        for other in f["shared_with"].as_array().into_iter().flatten() {
            out.push(format!("{}+{}", f["name"].as_str().unwrap_or("?"), other.as_str().unwrap_or("?")));
        }
    }
    out
}

/// The column of each name in a CSV header of volcal's (`volcal validate`, `volcal map`).
fn columns(header: &str) -> impl Fn(&str) -> usize + '_ {
    move |name| header.split(',').position(|h| h == name).unwrap_or_else(|| panic!("no column {name} in {header}"))
}

/// Spacing of the map grid on which volcal's map and the oracle's are compared with the truth.
const MAP_STEP: &str = "0.2";

/// The volumetric map's error, the measure of issue 12 ("RMS over the volume, after removing the
/// gauge's rigid-body freedom"), of volcal and of the oracle on one campaign: their squared
/// residuals from the truth once each map's exact turn from the truth's points (Kabsch) and then
/// the difference map's best motion within the gauge (least squares: a rigid motion of the
/// machine and a rotation of the tool's offset) are removed, over the grid points where volcal
/// gives a value.
#[derive(Clone, Copy, Default)]
struct MapError {
    volcal_ss: f64,
    oracle_ss: f64,
    values: usize,
}

impl MapError {
    fn add(self, o: MapError) -> MapError {
        MapError {
            volcal_ss: self.volcal_ss + o.volcal_ss,
            oracle_ss: self.oracle_ss + o.oracle_ss,
            values: self.values + o.values,
        }
    }

    /// RMS of volcal's and of the oracle's residual maps, um.
    fn rms_um(&self) -> (f64, f64) {
        let n = self.values.max(1) as f64;
        ((self.volcal_ss / n).sqrt() * 1e6, (self.oracle_ss / n).sqrt() * 1e6)
    }
}

/// [`MapError`] of the campaign in `d`: `volcal map` at each of its probe offsets, against the
/// simulator's truth and its oracle's map on the same grid (`map.csv`, `--map-step`).
fn map_error(d: &Path, probes: &[String]) -> MapError {
    use nalgebra::{DMatrix, DVector, Vector3};
    let key = |v: &[f64]| -> Vec<i64> { v.iter().map(|c| (c * 1e7).round() as i64).collect() };
    let numbers = |row: &str| -> Vec<f64> { row.split(',').map(|c| c.parse().unwrap_or(f64::NAN)).collect() };
    let reference: std::collections::HashMap<Vec<i64>, Vec<f64>> = std::fs::read_to_string(d.join("map.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|row| {
            let v = numbers(row);
            (key(&v[..6]), v[6..12].to_vec())
        })
        .collect();
    let (mut at, mut truths, mut volcal, mut oracle) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let step = map_step();
    for (k, probe) in probes.iter().enumerate() {
        let out = d.join(format!("map{k}.csv"));
        let args = ["map", "model.json", "--step", &step, "--probe", probe, "--out", out.to_str().unwrap()];
        run(Command::new(env!("CARGO_BIN_EXE_volcal")).current_dir(d).args(args));
        let text = std::fs::read_to_string(&out).unwrap();
        let col = columns(text.lines().next().unwrap());
        let (e, det) = (col("ex_m"), col("determined"));
        for row in text.lines().skip(1) {
            let v = numbers(row);
            if v[det] != 1.0 {
                continue;
            }
            let r = reference.get(&key(&v[..6])).expect("volcal's grid point in the simulator's map");
            let truth = Vector3::new(r[0], r[1], r[2]);
            at.push([Vector3::new(v[0], v[1], v[2]), Vector3::new(v[3], v[4], v[5])]);
            truths.push(truth);
            volcal.push(Vector3::new(v[e], v[e + 1], v[e + 2]) - truth);
            oracle.push(Vector3::new(r[3], r[4], r[5]) - truth);
        }
    }
    let n = at.len();
    if n < 3 {
        return MapError::default();
    }
    // e ~ t + w x X + r x p: the gauge's design matrix, three rows per point. A rigid motion of
    // the machine (t, w) and a rotation of the tool's offset (r: the angular errors' constants,
    // which neither a beam, whose origin is free, nor a range, whose station is, can see).
    let skew = |x: Vector3<f64>, r: usize, c: usize| [[0.0, x.z, -x.y], [-x.z, 0.0, x.x], [x.y, -x.x, 0.0]][r][c];
    let a = DMatrix::from_fn(3 * n, 9, |r, c| {
        let [x, p] = at[r / 3];
        match c {
            0..3 => f64::from(u8::from(c == r % 3)),
            3..6 => skew(x + p, r % 3, c - 3),
            _ => skew(p, r % 3, c - 6),
        }
    });
    let svd = a.clone().svd(true, true);
    // The frames' exact turn first (Kabsch): the gauge's frame is turned from the truth's, and a
    // turn taken out to first order (`w x X`) leaves its second-order part in the difference
    // (`w x e` and `|w|^2 X / 2`). Nanometres at the usual errors; at thirty times, with frames
    // 0.3 mrad apart, it was a quarter of volcal's map error (seed 891: 0.145 -> 0.104 um).
    let truth: Vec<Vector3<f64>> = at.iter().zip(&truths).map(|([x, p], t)| x + p + t).collect();
    let mean = |v: &[Vector3<f64>]| v.iter().sum::<Vector3<f64>>() / v.len() as f64;
    let ct = mean(&truth);
    let unturned = |diff: &[Vector3<f64>]| -> Vec<Vector3<f64>> {
        let other: Vec<Vector3<f64>> = truth.iter().zip(diff).map(|(t, d)| t + d).collect();
        let co = mean(&other);
        let h: nalgebra::Matrix3<f64> = truth.iter().zip(&other).map(|(t, o)| (t - ct) * (o - co).transpose()).sum();
        let svd = h.svd(true, true);
        let (u, v_t) = (svd.u.unwrap(), svd.v_t.unwrap());
        let sign = (v_t.transpose() * u.transpose()).determinant().signum();
        // The turn taking the truth's points onto the other's, and the other's brought back.
        let turn = v_t.transpose() * nalgebra::Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, sign)) * u.transpose();
        truth.iter().zip(&other).map(|(t, o)| turn.transpose() * (o - co) + ct - t).collect()
    };
    let residual_ss = |diff: &[Vector3<f64>]| -> f64 {
        let b = DVector::from_iterator(3 * n, unturned(diff).iter().flat_map(|v| [v.x, v.y, v.z]));
        let fit = svd.solve(&b, 1e-12).unwrap();
        (&b - &a * fit).norm_squared()
    };
    MapError { volcal_ss: residual_ss(&volcal), oracle_ss: residual_ss(&oracle), values: 3 * n }
}

/// The figures of one method over the seeds; asserts the bounds.
fn check(method: &str, targets: &[Target], expected: usize, n_seeds: usize, calibrated: bool) {
    // Where the readings contradict the interpolation between a tracer's stops, the targets there
    // are not determined and get no number; most must get one, or nothing is tested.
    assert!(
        2 * targets.len() >= expected,
        "{method}: only {} of {expected} validation targets were given a number",
        targets.len()
    );
    check_with(method, targets, expected, n_seeds, calibrated)
}

/// RMS of `f` over `of`.
fn rms_over(of: &[&Target], f: &dyn Fn(&Target) -> f64) -> f64 {
    (of.iter().map(|t| f(t).powi(2)).sum::<f64>() / of.len() as f64).sqrt()
}

/// [`check`] without the share of targets given a number; `calibrated`: whether the RMS of the
/// deviations over their uncertainties is bound.
fn check_with(method: &str, targets: &[Target], expected: usize, n_seeds: usize, calibrated: bool) {
    let z: Vec<f64> = targets.iter().map(Target::z).collect();
    let max = z.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let beyond_3 = z.iter().filter(|v| v.abs() > 3.0).count();
    let rms_z = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
    let all: Vec<&Target> = targets.iter().collect();
    let actual = rms_over(&all, &|t| t.predicted_m - t.truth_m);
    let predicted = rms_over(&all, &|t| t.sigma_m);
    eprintln!(
        "{method}: {} validation targets over {} seeds (of {expected} asked; the rest not determined): max |z| {max:.2}, |z| > 3 in {beyond_3}, RMS z {rms_z:.3}; actual / predicted RMS {:.3} ({:.3} um against {:.3} um)",
        targets.len(),
        n_seeds,
        actual / predicted,
        actual * 1e6,
        predicted * 1e6
    );
    // Against the oracle (the least error any estimator can have on this family and these
    // readings, on average), at the same targets; its own uncertainty must be calibrated, or it
    // is no yardstick.
    let oracle = rms_over(&all, &|t| t.oracle_m - t.truth_m);
    let oracle_rms_z = rms_over(&all, &Target::oracle_z);
    // Where the truth itself is a tail draw of its prior, the Bayes estimator is beyond 3 sigma
    // too, and along a whole line at once (its deviations are one direction of the prior): seed
    // 891's XY diagonal puts 30 of that seed's 270 targets there at every magnitude (README).
    let oracle_beyond_3 = targets.iter().filter(|t| t.oracle_z().abs() > 3.0).count();
    // The face diagonals apart: along them fixed beams cannot separate the straightness of one
    // axis from the crossed straightness of the other, and both estimators answer with their
    // prior (the oracle's is the truth's own).
    let off_faces: Vec<&Target> = targets.iter().filter(|t| !t.line.contains("diagonal")).collect();
    let ratio_off_faces =
        rms_over(&off_faces, &|t| t.predicted_m - t.truth_m) / rms_over(&off_faces, &|t| t.oracle_m - t.truth_m);
    eprintln!(
        "{method}: error RMS {:.3} um against the oracle's {:.3} um: {:.2} times ({ratio_off_faces:.2} times but for the face diagonals); the oracle's RMS z {oracle_rms_z:.3}, its |z| > 3 in {oracle_beyond_3}",
        actual * 1e6,
        oracle * 1e6,
        actual / oracle
    );
    // Per line, where the uncertainty is largest: what the readings leave to the prior.
    let mut lines: Vec<String> = targets.iter().map(|t| t.line.clone()).collect();
    lines.sort();
    lines.dedup();
    for l in &lines {
        let of: Vec<&Target> = targets.iter().filter(|t| &t.line == l).collect();
        let rms = |f: &dyn Fn(&Target) -> f64| rms_over(&of, f);
        // The stated uncertainty over the Bayes estimator's, which is what the truth's own prior
        // leaves open given these readings: 1 where volcal states what the readings leave open
        // as it is, above where it over-states it (the face diagonals' open long waves, README).
        let mut stated: Vec<f64> = of.iter().map(|t| t.sigma_m / t.oracle_sigma_m).collect();
        stated.sort_by(f64::total_cmp);
        eprintln!(
            "  {l}: error RMS {:.3} um (the oracle's {:.3} um), standard uncertainty RMS {:.3} um ({:.2} times the oracle's, median), max |z| {:.2} (the oracle's {:.2})",
            rms(&|t| t.predicted_m - t.truth_m) * 1e6,
            rms(&|t| t.oracle_m - t.truth_m) * 1e6,
            rms(&|t| t.sigma_m) * 1e6,
            stated[stated.len() / 2],
            of.iter().map(|t| t.z().abs()).fold(0.0, f64::max),
            of.iter().map(|t| t.oracle_z().abs()).fold(0.0, f64::max)
        );
    }
    assert!(max <= 5.0, "{method}: a validation deviation {max:.2} standard uncertainties from the truth");
    assert!(beyond_3 as f64 <= 0.01 * z.len() as f64, "{method}: {beyond_3} of {} beyond 3 sigma", z.len());
    assert!(!calibrated || (0.7..=1.3).contains(&rms_z), "{method}: RMS of deviation / uncertainty {rms_z:.3}");
    assert!(
        (0.7..=1.3).contains(&oracle_rms_z),
        "{method}: the oracle's RMS of deviation / uncertainty {oracle_rms_z:.3}"
    );
}

/// The demo CMM's travel (FXYZ beams and joint campaigns) and the paper's (its tracer case).
const DEMO_TRAVEL: [[f64; 2]; 3] = [[0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]];
const PAPER_TRAVEL: [[f64; 2]; 3] = [[0.0, 0.7], [-0.5, 0.0], [-0.7, 0.0]];
/// A gantry's long X ([`fixed_beams_on_a_long_machine_are_predicted_within_their_uncertainty`]).
const LONG_TRAVEL: [[f64; 2]; 3] = [[0.0, 3.0], [0.0, 0.6], [-0.4, 0.0]];

/// `method`'s campaigns over [`seeds`] on the machine [`machine_args`] names, every validation
/// line (`lines` per seed, 10 targets each beyond the start) predicted within its uncertainty
/// ([`check`]).
fn predicted_within_uncertainty(label: &str, method: &str, topology: &str, travel: [[f64; 2]; 3], lines: usize) {
    predicted_within_uncertainty_on(label, method, topology, travel, lines, seeds(), &machine_args(), true);
}

/// [`predicted_within_uncertainty`] over `seeds`, the simulator's machine given `machine`;
/// `calibrated`: whether the RMS of the deviations over their uncertainties is bound
/// ([`check_with`]).
fn predicted_within_uncertainty_on(
    label: &str,
    method: &str,
    topology: &str,
    travel: [[f64; 2]; 3],
    lines: usize,
    seeds: std::ops::Range<u64>,
    machine: &[String],
    calibrated: bool,
) -> Option<PathBuf> {
    let Some(py) = volcal_tests::checker_python() else { return None };
    let dir = volcal_tests::scratch(&format!(
        "independent-{method}-{topology}{}-{}-{}",
        machine.concat(),
        seeds.start,
        seeds.end
    ));
    let (mut targets, mut map) = (Vec::new(), MapError::default());
    for s in seeds.clone() {
        let (t, _, m) = validated(&py, &dir, method, topology, travel, s, machine);
        targets.extend(t);
        map = map.add(m);
    }
    let n_seeds = seeds.count();
    print_map_error(label, &map, n_seeds);
    check(label, &targets, n_seeds * lines * 10, n_seeds, calibrated);
    Some(dir)
}

/// The map's error against the oracle's, pooled over the seeds (measured, not bound).
fn print_map_error(label: &str, map: &MapError, n_seeds: usize) {
    let (volcal, oracle) = map.rms_um();
    eprintln!(
        "{label}: map error (gauge aligned) RMS {volcal:.3} um against the oracle's {oracle:.3} um: {:.2} times ({} values over {n_seeds} seeds, {} m grid)",
        volcal / oracle,
        map.values,
        map_step(),
    );
}

#[test]
fn fixed_beams_from_an_independent_simulator_are_predicted_within_their_uncertainty() {
    // 9 lines at each of the 3 probe offsets.
    predicted_within_uncertainty("fixed beams, FXYZ", "beams", "FXYZ", DEMO_TRAVEL, 27);
}

#[test]
fn fixed_beams_on_the_other_stacking_from_an_independent_simulator_are_predicted_within_their_uncertainty() {
    // The same plan on FYXZ (Y carries X): the issue asks for two topologies. Added at stop 54
    // with the bounds above, set before its first run.
    predicted_within_uncertainty("fixed beams, FYXZ", "beams", "FYXZ", DEMO_TRAVEL, 27);
}

/// A machine ten times as wrong (100 um of positioning, 40 um of straightness, 80 urad of
/// rotations): the readings resolve finer detail, and the 45 beams' knots are refined up to what
/// their positions determine. Finer knots leave each function's curvature between the positions
/// open too, and in that larger null space the face diagonals' pairs no longer look alike; until
/// the pairs found on the starting knots were kept through the refinement
/// (`Smoothing::open_alike`), each straightness took its own smoothing again there (found on
/// seed 701 by a study by hand over magnitudes the test seeds do not have, README). Seeds
/// 701-703; the bounds on far deviations as at the usual magnitude. Not bound: the RMS of the
/// deviations over their uncertainties, as for the sparse plan: the face diagonals, which the
/// beams leave to the roughness prior, are over-stated (RMS z 0.585 on these seeds, 0.800 on
/// 701-710; README, "On data we did not simulate").
#[test]
fn fixed_beams_on_a_machine_ten_times_as_wrong_are_predicted_within_their_uncertainty() {
    let ten = ["--amplitude".to_string(), "10".to_string()];
    let label = "fixed beams, FXYZ, ten times the errors";
    predicted_within_uncertainty_on(label, "beams", "FXYZ", DEMO_TRAVEL, 27, 701..704, &ten, false);
}

/// A machine thirty times as wrong (300 um of positioning, 120 um of straightness, 240 urad of
/// rotations: a large gantry robot). The independent simulator points each beam along its
/// commanded line and the machine drifts across it by hundreds of micrometres; volcal takes the
/// beams along the reflector's motion (the patent's procedure), and the two differ by a cosine
/// error that the readings cannot tell from the machine's positioning errors. Until the solve
/// covered the other alignment in its uncertainty where the machine file does not state one
/// (`volcal::alignment`), seeds 821-830 lay up to 5.02 standard uncertainties off, 37 of 2 700
/// beyond 3 (README, "On data we did not simulate"). Seeds 871-873, run once before this test
/// was written and never tuned against; the bounds on far deviations as at the usual magnitude,
/// the RMS not bound (the face diagonals over-stated, as at ten times). Every model says the
/// alignment was not stated and what covering it changed.
#[test]
fn fixed_beams_on_a_machine_thirty_times_as_wrong_are_predicted_within_their_uncertainty() {
    let thirty = ["--amplitude".to_string(), "30".to_string()];
    let label = "fixed beams, FXYZ, thirty times the errors";
    let Some(dir) = predicted_within_uncertainty_on(label, "beams", "FXYZ", DEMO_TRAVEL, 27, 871..874, &thirty, false)
    else {
        return;
    };
    for seed in 871..874 {
        let model = dir.join(format!("beams-{seed}/model.json"));
        let m: serde_json::Value = serde_json::from_slice(&std::fs::read(&model).unwrap()).unwrap();
        let a = &m["beam_alignment"];
        assert_eq!(a["stated"], false, "seed {seed}: {a}");
        assert!(a["separation"].as_f64().unwrap() > volcal::alignment::NEGLIGIBLE_SEPARATION, "seed {seed}: {a}");
        assert!(a["largest_change_m"].as_f64().unwrap() > 0.0, "seed {seed}: {a}");
        let warned = m["warnings"].as_array().unwrap().iter().any(|w| w.as_str().unwrap().contains("beam_alignment"));
        assert!(warned, "seed {seed}: no warning on the beams' alignment");
    }
}

/// The 45 beams on a machine thirty times as wrong as usual, aligned with the reflector's motion
/// (the patent's procedure) and the machine file saying so. With the simulator's default, beams
/// along the commanded lines of the frame its errors are drawn in, seed 831's axis Y line lay
/// 9.72 standard uncertainties off (and the simulator's own oracle 9.3): the cosine of each
/// beam's angle to the motion (up to a milliradian here) is a beam scale that the positioning
/// errors absorb, and the reading along the motion differs from it by what that frame's turn
/// leaves open (README, "On data we did not simulate"). Seeds 831-833, which showed it; with the
/// beams along the motion and the alignment not stated they gave 2.13, 1.43 and 1.68 at most
/// (stop 71, before this test). The bounds on far deviations as at the usual magnitude, the RMS
/// not bound (over-stated at this magnitude).
#[test]
fn fixed_beams_aligned_with_the_motion_on_a_machine_thirty_times_as_wrong_are_predicted_within_their_uncertainty() {
    let machine = ["--amplitude", "30", "--beam-alignment", "motion"].map(String::from);
    let label = "fixed beams (aligned with the motion), FXYZ, thirty times the errors";
    let Some(dir) = predicted_within_uncertainty_on(label, "beams", "FXYZ", DEMO_TRAVEL, 27, 831..834, &machine, false)
    else {
        return;
    };
    for seed in 831..834 {
        let a = beam_alignment_of(&dir, "beams", seed);
        assert_eq!(
            (a["aligned_with"].as_str(), a["stated"].as_bool()),
            (Some("motion"), Some(true)),
            "seed {seed}: {a}"
        );
    }
}

/// The beams and the tracer together on a machine thirty times as wrong as usual, its carriages
/// composing as rigid bodies (`--composition rigid`: each finite rotation turns what the axis
/// carries, errors included), the beams aligned with the motion and the machine file saying so.
/// With the simulator's small-angle sum, which rigid carriages do not have and which at these
/// errors differs from them by up to 0.7 um, seeds 881-883 put 13 of 810 targets beyond 3
/// standard uncertainties (seed 882 4.53; 3.10 composed as rigid bodies); with the beams along
/// the frame the errors are drawn in, seeds 821-830 reached 6.00 (README, "On data we did not
/// simulate"). Seeds 891-893, run once before this test was written and never tuned against
/// (2.34, 2.37 and 2.95 at most); the bounds on far deviations as at the usual magnitude, the
/// RMS not bound (over-stated at this magnitude).
#[test]
fn beams_and_a_tracer_on_rigid_carriages_thirty_times_as_wrong_are_predicted_within_their_uncertainty() {
    let machine = ["--amplitude", "30", "--composition", "rigid", "--beam-alignment", "motion"].map(String::from);
    let label = "beams (aligned with the motion) and tracer, FXYZ, rigid carriages, thirty times the errors";
    predicted_within_uncertainty_on(label, "joint", "FXYZ", DEMO_TRAVEL, 27, 891..894, &machine, false);
}

/// The beams and the tracer together over errors of short length scales (0.06 to 0.15 of the
/// travel): the readings ask for finer knots, and the refinement takes 24 intervals, whose knots
/// hold the beams' 25 points per line; the tracer's stops raise what the positions determine to
/// 32, so that the test of 32 intervals sees nothing between the beams' points. Until such an
/// axis went half as far again beyond its knots (`flexibility::interpolated_between`), its
/// functions were stated as resolved everywhere and seed 717's axis Y line lay 6.7 standard
/// uncertainties off between the beams' points (found by a study by hand over seeds 711-720,
/// README). Seeds 716-718; the bounds of the usual magnitude.
#[test]
fn beams_and_a_tracer_over_short_length_scales_are_predicted_within_their_uncertainty() {
    let short = ["--length-scale".to_string(), "0.06,0.15".to_string()];
    let label = "beams and tracer, FXYZ, short length scales";
    predicted_within_uncertainty_on(label, "joint", "FXYZ", DEMO_TRAVEL, 27, 716..719, &short, true);
}

/// A smooth machine (length scales 0.3 to 0.6 of the travel): what the 45 beams leave open along
/// a face diagonal (the odd long waves of EXY against EYX, and of the other two pairs) is larger
/// for a given detail than the roughness prior allows. Until it was stated no smaller than the
/// long waves the readings measure of the pairs (`open_pairs`), seed 743's XY diagonal lay 2.9 um
/// off under a stated 0.86 um (found by a study by hand over seeds 741-750, README).
/// Seeds 741-743; the bounds of the usual length scales.
#[test]
fn fixed_beams_on_a_smooth_machine_are_predicted_within_their_uncertainty() {
    let smooth = ["--length-scale".to_string(), "0.3,0.6".to_string()];
    let label = "fixed beams, FXYZ, long length scales";
    predicted_within_uncertainty_on(label, "beams", "FXYZ", DEMO_TRAVEL, 27, 741..744, &smooth, true);
}

/// A long machine (3 x 0.6 x 0.4 m, a gantry's long X): the face diagonals' pairs are open alike
/// as on the demo CMM, but the long axis's straightness holds a small part of all the roughness
/// left open (`int f'''^2 dq` goes with the travel to the fifth power). Until each function's
/// share was taken of its own roughness (`ReducedPenalty::alike_where_open`), the XY and XZ
/// pairs were not given one smoothing and the map was 1.72 times the oracle's (FYXZ 2.13, 1.1 %
/// of the targets beyond 3 sigma), found by a study by hand over seeds 1021-1030
/// (`VOLCAL_INDEPENDENT_TRAVEL`, README). Seeds 1041-1043; the bounds of the demo CMM.
#[test]
fn fixed_beams_on_a_long_machine_are_predicted_within_their_uncertainty() {
    let label = "fixed beams, FXYZ, a long machine";
    predicted_within_uncertainty_on(label, "beams", "FXYZ", LONG_TRAVEL, 27, 1041..1044, &[], true);
}

/// The beams and the tracer together over a narrow bump on every function (a Gaussian 2 to 5 cm
/// wide on 1 m, half the function's largest excursion high: the simulator's `--bump`): the
/// readings ask for finer knots, the beams' points and the tracer's stops bound Y at 32
/// intervals, and X and Z stop at 24, short of it. Until each axis was widened on its own
/// (`flexibility::widen_at_bound`), widening the three together failed (Y's 48 intervals lost
/// the normal matrix's definiteness), X and Z stayed at 24, resolved everywhere, and their axis
/// lines lay up to 7.81 standard uncertainties off between the beams' points, 52 of 2 676
/// targets beyond 3 sigma (seeds 1051-1060, a study by hand, README). Seeds 1056-1058, two of
/// which the study found (7.81 and 21 of 810 beyond 3 sigma before, 4.15 and 5 of 786 now); the
/// bounds of the usual magnitude. On fresh seeds 1061-1063, run once, both pass (4.94 and 6 of
/// 786 before, 3.03 and 1 of 762 now). Not the whole case: on 20 further fresh seeds (1081-1100)
/// the joint campaign still put 1.3 % of its targets beyond 3 sigma (6.91 at most), at tracer
/// stops between the beams' points, counted as measured; since they are touched, not measured
/// (`interpolation::measured_positions`), 0.28 % and 3.86, and these seeds 2.97 and none of 786
/// (README, "A narrow bump on every function").
#[test]
fn beams_and_a_tracer_over_local_bumps_are_predicted_within_their_uncertainty() {
    let bump = ["--bump".to_string(), "0.5,0.02,0.05".to_string()];
    let label = "beams and tracer, FXYZ, a local bump on every function";
    predicted_within_uncertainty_on(label, "joint", "FXYZ", DEMO_TRAVEL, 27, 1056..1059, &bump, true);
}

#[test]
fn a_laser_tracer_from_an_independent_simulator_is_predicted_within_its_uncertainty() {
    // The case: the paper's travel and axis stacking, 4 stations, the 12 edges, 11 stops
    // per edge, one continuous track per station (528 ranges), the reflector at the tool.
    predicted_within_uncertainty("laser tracer, FYXZ", "tracer", "FYXZ", PAPER_TRAVEL, 9);
}

#[test]
fn beams_and_a_tracer_together_from_an_independent_simulator_are_predicted_within_their_uncertainty() {
    // The 45 beams at three probe offsets and the tracer's 4 tracks over the 12 edges (11 stops
    // per edge), one machine, one campaign.
    predicted_within_uncertainty("beams and tracer, FXYZ", "joint", "FXYZ", DEMO_TRAVEL, 27);
}

/// A plan that leaves something open: 12 beams (two axis lines per axis, the mid planes' face
/// diagonals), 20 points, three probe offsets. Its readings do not separate the rolls of the
/// three axes from the squareness EB0Z (a combination no beam of it sees); an axis line does not
/// see it either, a body diagonal does, but for its far corner. `volcal validate` must give the
/// diagonals between their ends no number (not a minimum-norm value with a small uncertainty),
/// and whatever it gives a number must lie within its uncertainty. Not bound: the RMS of the
/// deviations over their uncertainties, since the lines the roughness prior alone determines are
/// over-stated here (README, "On data we did not simulate").
#[test]
fn a_sparse_plan_s_undetermined_lines_are_reported_as_such() {
    let Some(py) = volcal_tests::checker_python() else { return };
    let dir = volcal_tests::scratch("independent-sparse");
    let (mut targets, mut open, mut map) = (Vec::new(), Vec::new(), MapError::default());
    for s in seeds() {
        let (t, o, m) = validated(&py, &dir, "beams-sparse", "FXYZ", DEMO_TRAVEL, s, &machine_args());
        targets.extend(t);
        open.extend(o);
        map = map.add(m);
    }
    print_map_error("fixed beams, sparse plan, FXYZ, where the map is determined", &map, seeds().count());
    open.sort();
    open.dedup();
    eprintln!("not determined: {open:?}");
    // Between its ends: at the far corner the deviation from the start does not depend on the
    // combination left open (it cancels there), and the number stands, as it should.
    for diagonal in ["NPP", "NPN", "PPN", "PPP"] {
        let given: Vec<usize> =
            targets.iter().filter(|t| t.line.starts_with(diagonal) && t.index < 10).map(|t| t.index).collect();
        assert!(
            given.is_empty(),
            "the body diagonal {diagonal} was given a number at targets {given:?} although the readings leave a combination it sees open"
        );
    }
    check_with("fixed beams, sparse plan, FXYZ", &targets, seeds().count() * 27 * 10, seeds().count(), false);
    map_and_tables_say_what_is_open(&dir.join(format!("beams-sparse-{}", seeds().start)));
}

/// The rest of what a user gets from a model whose readings leave directions open (issue 12):
/// `volcal map` writes no value where the error depends on them and says what to measure, and
/// `volcal export` refuses tables it would need them for, naming them, instead of writing the
/// minimum-norm values to a controller.
fn map_and_tables_say_what_is_open(d: &Path) {
    let exe = env!("CARGO_BIN_EXE_volcal");
    let out = Command::new(exe)
        .current_dir(d)
        .args(["map", "model.json", "--step", "0.1", "--out", "map.csv"])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{said}");
    assert!(said.contains("the data do not determine the error at") && said.contains("measure"), "{said}");
    let map = std::fs::read_to_string(d.join("map.csv")).unwrap();
    let col = columns(map.lines().next().unwrap());
    let (e, u, det) = (col("e_norm_m"), col("u95_m"), col("determined"));
    let (mut open, mut given) = (0, 0);
    for row in map.lines().skip(1) {
        let f: Vec<&str> = row.split(',').collect();
        match f[det] {
            "0" => {
                assert!(f[e].is_empty() && f[u].is_empty(), "a value where the data determine none: {row}");
                open += 1;
            }
            _ => {
                let (v, w) = (f[e].parse::<f64>().unwrap(), f[u].parse::<f64>().unwrap());
                assert!(v.is_finite() && w.is_finite() && w > 0.0, "{row}");
                given += 1;
            }
        }
    }
    eprintln!("sparse plan, map: {given} grid points given a value, {open} not determined");
    assert!(open > 0, "every grid point given a value, although the readings leave directions open");
    let out = Command::new(exe)
        .current_dir(d)
        .args(["export", "model.json", "--format", "linuxcnc", "--out", "comp"])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "tables exported from a model that leaves them open");
    assert!(
        said.contains("the data do not determine") && said.contains("undetermined") && said.contains("measure"),
        "{said}"
    );
    assert!(!d.join("comp/x.comp").exists(), "a table written although the export was refused");
}
