//! `volcal solve --rerun`: the recording is verified by the official Rerun CLI of the crate's
//! version (`rerun rrd verify`, from the pinned checker venv) and checked by an independent
//! Python reader (`check_rrd.py`, rerun-sdk) for the entity paths the views rely on.

use std::path::Path;
use std::process::Command;

fn volcal(dir: &Path, args: &[&str]) -> std::process::Output {
    let out = Command::new(env!("CARGO_BIN_EXE_volcal")).current_dir(dir).args(args).output().unwrap();
    assert!(
        out.status.success() || out.status.code() == Some(3),
        "volcal {args:?} failed: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn solve_recording_verifies_and_has_the_expected_entities() {
    let dir = volcal_tests::scratch("rerun-solve");
    std::fs::write(dir.join("machine.yaml"), volcal_nodes::machine::DEMO_MACHINE).unwrap();
    // A small campaign keeps the recording small: 3 stations x 10 beams x 20 points.
    std::fs::write(dir.join("plan.yaml"), "directions_per_station: 10\npoints_per_beam: 20\n").unwrap();
    volcal(
        &dir,
        &["simulate", "--machine", "machine.yaml", "--plan", "plan.yaml", "--seed", "3", "--out", "campaign.csv"],
    );
    volcal(
        &dir,
        &["solve", "campaign.csv", "--machine", "machine.yaml", "--out", "model.json", "--rerun", "solve.rrd"],
    );
    let rrd = dir.join("solve.rrd");
    let size = std::fs::metadata(&rrd).expect("no recording written").len();
    assert!(size < 1_000_000, "recording of a 600-reading campaign is {size} bytes");

    let Some(py) = volcal_tests::checker_python() else { return };
    let rerun = py.parent().unwrap().join("rerun");
    let verify = Command::new(&rerun).args(["rrd", "verify"]).arg(&rrd).output().unwrap();
    assert!(
        verify.status.success(),
        "rerun rrd verify failed:\n{}{}",
        String::from_utf8_lossy(&verify.stdout),
        String::from_utf8_lossy(&verify.stderr)
    );
    let check = Command::new(&py)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/check_rrd.py"))
        .arg(&rrd)
        .arg(dir.join("campaign.csv"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&check.stdout);
    assert!(check.status.success(), "check_rrd.py failed:\n{text}{}", String::from_utf8_lossy(&check.stderr));
    eprintln!("{text}");
}

#[test]
fn bad_rerun_flags_are_refused_before_solving() {
    let dir = volcal_tests::scratch("rerun-flags");
    for (flag, value, says) in
        [("--rerun", "solve.txt", "must end in .rrd"), ("--rerun-connect", "http://", "not a Rerun gRPC address")]
    {
        let out = Command::new(env!("CARGO_BIN_EXE_volcal"))
            .current_dir(&dir)
            .args(["solve", "missing.csv", "--machine", "missing.yaml", "--out", "model.json", flag, value])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains(flag) && err.contains(says) && !err.contains("missing.csv"), "{flag} {value}: {err}");
    }
}
