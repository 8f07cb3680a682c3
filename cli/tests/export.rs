//! `volcal export`: the files are read by an independent reader of each format's rules
//! (`tests/py/check_compensation.py`: LinuxCNC's three-number lines, at most 256, ascending
//! nominal; ISG CSV's comments, headers, file breaks and units, the tables composed through the
//! ISO 230-1 chain; SINUMERIK's INI framing, assignments, point indices, STEP/MIN/MAX) and their
//! values checked against `volcal predict` at the same points.

mod common;

use common::run_volcal as volcal;
use std::path::Path;
use std::process::Command;
use volcal_tests::{checker_python, repo_root, scratch};

fn python(py: &Path, args: &[&dyn AsRef<std::ffi::OsStr>]) -> String {
    let out = Command::new(py).arg(repo_root().join("tests/py/check_compensation.py")).args(args).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "the independent reader disagrees:\n{text}");
    text
}

/// A model of the diagnosis machine (1.0 x 0.8 x 0.6 m) from its clean sample campaign.
fn model(dir: &Path) -> std::path::PathBuf {
    let m = dir.join("model.json");
    let (ok, _, err) = volcal(&[
        &"solve",
        &repo_root().join("bags/concealed/clean.csv"),
        &"--machine",
        &repo_root().join("launch_configs/machines/diagnosis_cmm.yaml"),
        &"--out",
        &m,
    ]);
    assert!(ok, "{err}");
    m
}

#[test]
fn linuxcnc_tables_follow_linuxcnc_rules_and_the_model() {
    let Some(py) = checker_python() else { return };
    let dir = scratch("export-linuxcnc");
    let m = model(&dir);
    for comp_type in ["0", "1"] {
        let out = dir.join(format!("type{comp_type}"));
        let point = "0.3,0.2,-0.2";
        let (ok, said, err) = volcal(&[
            &"export",
            &m,
            &"--format",
            &"linuxcnc",
            &"--out",
            &out,
            &"--step-mm",
            &"20",
            &"--point",
            &point,
            &"--comp-type",
            &comp_type,
        ]);
        assert!(ok, "{err}");
        eprint!("{said}");
        let readme = std::fs::read_to_string(out.join("README.txt")).unwrap();
        assert!(
            readme.contains(&format!("COMP_FILE_TYPE = {comp_type}")) && readme.contains("What it drops"),
            "{readme}"
        );
        let points = dir.join(format!("points{comp_type}.csv"));
        python(&py, &[&"points", &out, &point, &points]);
        let pred = dir.join(format!("pred{comp_type}.csv"));
        let (ok, _, err) = volcal(&[&"predict", &m, &points, &"--out", &pred]);
        assert!(ok, "{err}");
        eprint!("{}", python(&py, &[&"linuxcnc", &out, &comp_type, &pred]));
    }
}

#[test]
fn a_grid_follows_the_model() {
    let Some(py) = checker_python() else { return };
    let dir = scratch("export-grid");
    let m = model(&dir);
    let out = dir.join("grid");
    let (ok, said, err) = volcal(&[&"export", &m, &"--format", &"grid", &"--out", &out, &"--step-mm", &"100"]);
    assert!(ok, "{err}");
    eprint!("{said}");
    let points = dir.join("points.csv");
    python(&py, &[&"gridpoints", &out, &points]);
    let pred = dir.join("pred.csv");
    assert!(volcal(&[&"predict", &m, &points, &"--out", &pred]).0);
    eprint!("{}", python(&py, &[&"grid", &out, &pred]));
}

#[test]
fn tables_linuxcnc_cannot_hold_are_refused() {
    let dir = scratch("export-refused");
    let m = model(&dir);
    let (ok, _, err) = volcal(&[&"export", &m, &"--format", &"linuxcnc", &"--out", &dir.join("o"), &"--step-mm", &"1"]);
    assert!(!ok && err.contains("LinuxCNC reads at most 256 nodes") && err.contains("--step-mm"), "{err}");
    let (ok, _, err) =
        volcal(&[&"export", &m, &"--format", &"linuxcnc", &"--out", &dir.join("o"), &"--point", &"5,0,0"]);
    assert!(!ok && err.contains("outside the identified travel"), "{err}");
}

#[test]
fn isg_tables_follow_the_isg_csv_rules_and_the_model() {
    let Some(py) = checker_python() else { return };
    let dir = scratch("export-isg");
    let m = model(&dir);
    let out = dir.join("isg");
    let (ok, said, err) = volcal(&[&"export", &m, &"--format", &"isg", &"--out", &out, &"--step-mm", &"50"]);
    assert!(ok, "{err}");
    eprint!("{said}");
    let readme = std::fs::read_to_string(out.join("README.txt")).unwrap();
    assert!(
        readme.contains("#VOLCOMP ON") && readme.contains("ISG_CSV") && readme.contains("all 21 error functions"),
        "{readme}"
    );
    let points = dir.join("points.csv");
    python(&py, &[&"isgpoints", &out, &points]);
    let pred = dir.join("pred.csv");
    assert!(volcal(&[&"predict", &m, &points, &"--out", &pred]).0);
    // The diagnosis machine's stacking (launch_configs/machines/diagnosis_cmm.yaml).
    eprint!("{}", python(&py, &[&"isg", &out, &"FXYZ", &pred]));
}

#[test]
fn sinumerik_tables_follow_the_k3_rules_and_the_model() {
    let Some(py) = checker_python() else { return };
    let dir = scratch("export-sinumerik");
    let m = model(&dir);
    let out = dir.join("sinumerik");
    let point = "0.3,0.2,-0.2";
    let (ok, said, err) =
        volcal(&[&"export", &m, &"--format", &"sinumerik", &"--out", &out, &"--step-mm", &"20", &"--point", &point]);
    assert!(ok, "{err}");
    eprint!("{said}");
    let readme = std::fs::read_to_string(out.join("README.txt")).unwrap();
    assert!(readme.contains("MD32450") && readme.contains("What it drops"), "{readme}");
    let points = dir.join("points.csv");
    python(&py, &[&"sinumerikpoints", &out, &point, &points]);
    let pred = dir.join("pred.csv");
    assert!(volcal(&[&"predict", &m, &points, &"--out", &pred]).0);
    eprint!("{}", python(&py, &[&"sinumerik", &out, &pred]));
}

#[test]
fn tables_isg_and_sinumerik_cannot_hold_are_refused() {
    let dir = scratch("export-refused-2");
    let m = model(&dir);
    // 1.0 m of X at 2 mm: 501 points, more than a SINUMERIK table's 200.
    let (ok, _, err) =
        volcal(&[&"export", &m, &"--format", &"sinumerik", &"--out", &dir.join("s"), &"--step-mm", &"2"]);
    assert!(!ok && err.contains("axis X") && err.contains("at most 200") && err.contains("--step-mm"), "{err}");
    let (ok, _, err) =
        volcal(&[&"export", &m, &"--format", &"sinumerik", &"--out", &dir.join("s"), &"--point", &"0,0,0.5"]);
    assert!(!ok && err.contains("outside the identified travel"), "{err}");
    let (ok, _, err) = volcal(&[&"export", &m, &"--format", &"isg", &"--out", &dir.join("i"), &"--step-mm", &"-1"]);
    assert!(!ok && err.contains("positive number of millimetres"), "{err}");
}
