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
//! bound (README, "On data we did not simulate").

use std::path::Path;
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

fn run(cmd: &mut Command) -> String {
    let out = cmd.output().expect("runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    // `volcal solve` exits 3 where some functions are not identifiable (the tracer's rotations of
    // Z with the reflector at the tool): the model is written and says so.
    assert!(matches!(out.status.code(), Some(0) | Some(3)), "{cmd:?} failed:\n{text}");
    text
}

/// Simulates `method` for `seed` with the independent simulator, solves it with the two-line
/// machine file and predicts every validation line.
fn campaign(py: &Path, dir: &Path, method: &str, topology: &str, travel: [[f64; 2]; 3], seed: u64) -> Vec<Target> {
    validated(py, dir, method, topology, travel, seed).0
}

/// [`campaign`], and the names of the targets given no number (not determined).
fn validated(
    py: &Path,
    dir: &Path,
    method: &str,
    topology: &str,
    travel: [[f64; 2]; 3],
    seed: u64,
) -> (Vec<Target>, Vec<String>) {
    let root = volcal_tests::repo_root();
    let d = dir.join(format!("{method}-{seed}"));
    let travel_arg = travel.iter().map(|[lo, hi]| format!("{lo},{hi}")).collect::<Vec<_>>().join(";");
    let mut sim = Command::new(py);
    sim.arg(root.join("tests/py/independent_campaign.py"));
    if method == "beams-sparse" {
        sim.arg("--sparse");
    }
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
        "--out",
        d.to_str().unwrap(),
    ]));
    let machine = d.join("machine.yaml");
    let [x, y, z] = travel;
    std::fs::write(
        &machine,
        format!(
            "topology: {topology}\ntravel: {{x: [{}, {}], y: [{}, {}], z: [{}, {}]}}\n",
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
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(d.join("validation.json")).unwrap()).unwrap();
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
        let head: Vec<&str> = rows.next().unwrap().split(',').collect();
        let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
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
    (out, open)
}

/// The figures of one method over the seeds; asserts the bounds.
fn check(method: &str, targets: &[Target], expected: usize) {
    // Where the readings contradict the interpolation between a tracer's stops, the targets there
    // are not determined and get no number; most must get one, or nothing is tested.
    assert!(
        2 * targets.len() >= expected,
        "{method}: only {} of {expected} validation targets were given a number",
        targets.len()
    );
    check_with(method, targets, expected, true)
}

/// RMS of `f` over `of`.
fn rms_over(of: &[&Target], f: &dyn Fn(&Target) -> f64) -> f64 {
    (of.iter().map(|t| f(t).powi(2)).sum::<f64>() / of.len() as f64).sqrt()
}

/// [`check`] without the share of targets given a number; `calibrated`: whether the RMS of the
/// deviations over their uncertainties is bound.
fn check_with(method: &str, targets: &[Target], expected: usize, calibrated: bool) {
    let z: Vec<f64> = targets.iter().map(|t| (t.predicted_m - t.truth_m) / t.sigma_m).collect();
    let max = z.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let beyond_3 = z.iter().filter(|v| v.abs() > 3.0).count();
    let rms_z = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
    let all: Vec<&Target> = targets.iter().collect();
    let actual = rms_over(&all, &|t| t.predicted_m - t.truth_m);
    let predicted = rms_over(&all, &|t| t.sigma_m);
    eprintln!(
        "{method}: {} validation targets over {} seeds (of {expected} asked; the rest not determined): max |z| {max:.2}, |z| > 3 in {beyond_3}, RMS z {rms_z:.3}; actual / predicted RMS {:.3} ({:.3} um against {:.3} um)",
        targets.len(),
        seeds().count(),
        actual / predicted,
        actual * 1e6,
        predicted * 1e6
    );
    // Against the oracle (the least error any estimator can have on this family and these
    // readings, on average), at the same targets; its own uncertainty must be calibrated, or it
    // is no yardstick.
    let oracle = rms_over(&all, &|t| t.oracle_m - t.truth_m);
    let oracle_rms_z = rms_over(&all, &|t| (t.oracle_m - t.truth_m) / t.oracle_sigma_m);
    // The face diagonals apart: along them fixed beams cannot separate the straightness of one
    // axis from the crossed straightness of the other, and both estimators answer with their
    // prior (the oracle's is the truth's own).
    let off_faces: Vec<&Target> = targets.iter().filter(|t| !t.line.contains("diagonal")).collect();
    let ratio_off_faces =
        rms_over(&off_faces, &|t| t.predicted_m - t.truth_m) / rms_over(&off_faces, &|t| t.oracle_m - t.truth_m);
    eprintln!(
        "{method}: error RMS {:.3} um against the oracle's {:.3} um: {:.2} times ({ratio_off_faces:.2} times but for the face diagonals); the oracle's RMS z {oracle_rms_z:.3}",
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
        eprintln!(
            "  {l}: error RMS {:.3} um (the oracle's {:.3} um), standard uncertainty RMS {:.3} um, max |z| {:.2}",
            rms(&|t| t.predicted_m - t.truth_m) * 1e6,
            rms(&|t| t.oracle_m - t.truth_m) * 1e6,
            rms(&|t| t.sigma_m) * 1e6,
            of.iter().map(|t| ((t.predicted_m - t.truth_m) / t.sigma_m).abs()).fold(0.0, f64::max)
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

/// `method`'s campaigns over [`seeds`], every validation line (`lines` per seed, 10 targets each
/// beyond the start) predicted within its uncertainty ([`check`]).
fn predicted_within_uncertainty(label: &str, method: &str, topology: &str, travel: [[f64; 2]; 3], lines: usize) {
    let Some(py) = volcal_tests::checker_python() else { return };
    let dir = volcal_tests::scratch(&format!("independent-{method}-{topology}"));
    let targets: Vec<Target> = seeds().flat_map(|s| campaign(&py, &dir, method, topology, travel, s)).collect();
    check(label, &targets, seeds().count() * lines * 10);
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
    let (mut targets, mut open) = (Vec::new(), Vec::new());
    for s in seeds() {
        let (t, o) = validated(&py, &dir, "beams-sparse", "FXYZ", DEMO_TRAVEL, s);
        targets.extend(t);
        open.extend(o);
    }
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
    check_with("fixed beams, sparse plan, FXYZ", &targets, seeds().count() * 27 * 10, false);
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
    let head: Vec<&str> = map.lines().next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
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
