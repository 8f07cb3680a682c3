//! The tracer issue's commands end to end through the `volcal` binary: `volcal paper` (the
//! scenario of Han et al. 2021), `volcal validate` on its model, and `volcal merge` + `volcal
//! solve` for a joint fixed-beam and tracer solve.

use std::path::{Path, PathBuf};
use std::process::Command;

fn volcal(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_volcal")).args(args).output().expect("run volcal");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volcal-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

#[test]
fn paper_validate_merge_and_joint_solve() {
    let dir = scratch("paper");
    let (code, out, err) = volcal(&["paper", "--workdir", s(&dir)]);
    assert_eq!(code, 0, "{out}\n{err}");
    // Table 2, the volumetric maximum, the iteration count and every validation line.
    for needle in [
        "Table 2 (Han et al. 2021)",
        "E_XX         -27.06     -27.06",
        "E_C0X        -82.89     -82.89",
        "17 of 21 error functions are identified individually",
        "Largest volumetric error |e| (eq. 3): identified",
        "at a corner of the volume",
        "converged: true",
        "Line X: (0, 0, -700) -> (700, 0, -700) mm",
        "Line Z: (0, -500, -700) -> (0, -500, 0) mm",
        "Line NPP: (700, -500, -700) -> (0, 0, 0) mm",
        "Line PPP: (0, -500, -700) -> (700, 0, 0) mm",
    ] {
        assert!(out.contains(needle), "missing {needle:?} in:\n{out}");
    }
    let iterations: usize = out
        .split("Levenberg-Marquardt ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .expect("iteration count");
    assert!(iterations <= 10, "{iterations}");
    // Prediction and simulated interferometer agree within a micrometre on every line (the
    // paper, on a real machine: 7.43 um on the axes, 10.51 um on the diagonals).
    let worst: f64 = out
        .split("Largest prediction - interferometer difference over all lines: ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .expect("largest difference");
    assert!(worst < 1.0, "{worst} um");
    for f in ["campaign.csv", "truth.json", "model.json", "validation.csv", "paper_cmm.yaml", "paper_tracer.yaml"] {
        assert!(dir.join(f).exists(), "{f}");
    }

    // `volcal validate` on that model.
    let model = dir.join("model.json");
    let (code, out, err) = volcal(&["validate", s(&model), "--axis", "x"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("Line X: (0, -250, -350) -> (700, -250, -350) mm"), "{out}");
    assert!(out.contains("positioning error (range of deviations): predicted"), "{out}");
    let csv = dir.join("diagonals.csv");
    let machine = repo().join("launch_configs/machines/paper_cmm.yaml");
    let (code, out, err) = volcal(&[
        "validate",
        s(&model),
        "--diagonals",
        "--truth",
        s(&dir.join("truth.json")),
        "--machine",
        s(&machine),
        "--out",
        s(&csv),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(out.matches("max |difference|").count(), 4, "{out}");
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().count(), 1 + 4 * 11);
    // The paper's tables are fixed by its 11 nodes, the tracer's stops: nothing interpolated.
    assert!(text.lines().skip(1).all(|l| l.split(',').count() == 12 && l.ends_with(",0")), "{text}");
    for (args, msg) in [
        (vec!["--axis", "q"], "expected x, y or z"),
        (vec![], "say which lines"),
        (vec!["--line", "0,0,0:0,0"], "--line \"0,0,0:0,0\": end"),
        (vec!["--axis", "x", "--points", "1"], "--points must be at least 2"),
    ] {
        let mut a = vec!["validate", s(&model)];
        a.extend(args);
        let (code, _, err) = volcal(&a);
        assert_eq!(code, 1, "{a:?}");
        assert!(err.contains(msg), "{a:?}: {err}");
    }

    // Joint solve: the patent's fixed-beam campaign on the same machine, merged with the
    // tracer campaign; with probe offsets the beams make all 21 functions identifiable.
    let beams = dir.join("beams.csv");
    let (code, _, err) = volcal(&["simulate", "--machine", s(&machine), "--seed", "2", "--out", s(&beams)]);
    assert_eq!(code, 0, "{err}");
    let joint = dir.join("joint.csv");
    let (code, _, err) = volcal(&["merge", s(&beams), s(&dir.join("campaign.csv")), "--out", s(&joint)]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("wrote 8028 readings"), "{err}");
    let (code, out, err) = volcal(&["solve", s(&joint), "--machine", s(&machine), "--out", s(&dir.join("joint.json"))]);
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(out.contains("All 21 error functions are identified"), "{out}");
    assert!(out.contains("Station 3:"), "{out}");

    // Deterministic: the same tracer campaign solved twice gives a byte-identical model.
    let (a, b) = (dir.join("a.json"), dir.join("b.json"));
    for m in [&a, &b] {
        let (code, _, err) = volcal(&["solve", s(&dir.join("campaign.csv")), "--machine", s(&machine), "--out", s(m)]);
        assert_eq!(code, 3, "partial identification (17 of 21) exits with 3: {err}");
    }
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The paper's tracer with three and with five stops per edge, solved with the two-line machine
/// file. Three values along an axis lie on a parabola whatever the errors, and five give two
/// values of roughness: too few for REML to tell how rough the functions are, so `auto` does
/// not smooth them (before, with three stops, REML took the smoothing to its bound and the map
/// between the stops was a parabola stated to a few micrometres; on this campaign its body
/// diagonals were up to 12.2 um off under En 2.91). The functions are determined at the stops
/// only, and the validation lines say so: determined at the targets where a diagonal meets the
/// stops, and there within their uncertainty.
#[test]
fn too_few_stops_per_edge_are_not_interpolated_by_a_prior_they_cannot_inform() {
    for (stops, step, intervals) in [(3, "[0.35, 0.25, 0.35]", 1), (5, "[0.175, 0.125, 0.175]", 3)] {
        too_few_stops(stops, step, intervals);
    }
}

fn too_few_stops(stops: usize, step: &str, intervals: usize) {
    let dir = scratch(&format!("tracer{stops}"));
    let paper = repo().join("launch_configs/machines/paper_cmm.yaml");
    let plan = std::fs::read_to_string(repo().join("launch_configs/plans/paper_tracer.yaml"))
        .unwrap()
        .lines()
        .map(|l| if l.starts_with("path_step_m:") { format!("path_step_m: {step}") } else { l.to_string() })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(dir.join("plan.yaml"), plan).unwrap();
    std::fs::write(dir.join("m.yaml"), "topology: FYXZ\ntravel: {x: [0, 0.7], y: [-0.5, 0], z: [-0.7, 0]}\n").unwrap();
    let (code, out, err) = volcal(&[
        "simulate",
        "--machine",
        s(&paper),
        "--plan",
        s(&dir.join("plan.yaml")),
        "--out",
        s(&dir.join("c.csv")),
        "--truth",
        s(&dir.join("truth.json")),
    ]);
    assert_eq!(code, 0, "{out}\n{err}");
    let (code, out, err) =
        volcal(&["solve", s(&dir.join("c.csv")), "--machine", s(&dir.join("m.yaml")), "--out", s(&dir.join("m.json"))]);
    // Exit 3: directions the data leave open.
    assert_eq!(code, 3, "{out}\n{err}");
    for axis in ["X", "Y", "Z"] {
        let said = format!(
            "  {axis}: cubic B-spline, {intervals} intervals (not smoothed: the readings lie at {stops} position(s)"
        );
        assert!(out.contains(&said), "{said}\n{out}");
    }
    let model: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("m.json")).unwrap()).unwrap();
    let knots = model["representation_choice"]["knots"].as_array().expect("knots");
    assert!(knots.iter().all(|k| k["bound"] == "few_positions"), "{knots:?}");
    let (code, out, err) = volcal(&[
        "validate",
        s(&dir.join("m.json")),
        "--diagonals",
        "--points",
        "21",
        "--truth",
        s(&dir.join("truth.json")),
        "--machine",
        s(&paper),
    ]);
    assert_eq!(code, 0, "{out}\n{err}");
    let summaries: Vec<&str> = out.lines().filter(|l| l.contains("positioning error (range of deviations)")).collect();
    assert_eq!(summaries.len(), 4, "{out}");
    for l in summaries {
        assert!(l.contains(&format!("the data determine the prediction at {stops} of the 21 targets")), "{l}");
        let en: f64 =
            l.split("max En ").nth(1).and_then(|t| t.split(' ').next()).and_then(|v| v.parse().ok()).expect(l);
        // En 1.5 is three standard uncertainties.
        assert!(en < 1.5, "{l}");
    }
}
