//! Checks of Rerun recordings with the pinned checker venv: the official CLI of the crate's
//! version (`rerun rrd verify`) and the independent reader `check_rrd.py` (rerun-sdk).

use std::path::{Path, PathBuf};
use std::process::Command;

/// The `rerun` entry point of the venv of `py`.
pub fn rerun_cli(py: &Path) -> PathBuf {
    py.parent().unwrap().join("rerun")
}

/// `rerun rrd verify FILE` succeeds (a finished file: a streamed one has no footer).
pub fn verify(py: &Path, rrd: &Path) {
    let verify = Command::new(rerun_cli(py)).args(["rrd", "verify"]).arg(rrd).output().unwrap();
    assert!(
        verify.status.success(),
        "rerun rrd verify {} failed:\n{}{}",
        rrd.display(),
        String::from_utf8_lossy(&verify.stdout),
        String::from_utf8_lossy(&verify.stderr)
    );
}

/// Runs `check_rrd.py ARGS...` (see its usage) and prints what it found.
pub fn check_entities(py: &Path, args: &[&std::ffi::OsStr]) {
    let check = Command::new(py)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/check_rrd.py"))
        .args(args)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&check.stdout);
    assert!(check.status.success(), "check_rrd.py failed:\n{text}{}", String::from_utf8_lossy(&check.stderr));
    eprintln!("{text}");
}
