//! Shared helpers for the workspace-level integration tests.

use std::path::PathBuf;

/// Root of the repository.
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// The Python interpreter of the pinned checker venv (`.venv`, made by `.ci/run`), or `None`
/// with a message. Under `VOLCAL_REQUIRE_PY` (set by CI) a missing venv is a test failure.
pub fn checker_python() -> Option<PathBuf> {
    let py = repo_root().join(".venv/bin/python");
    if py.exists() {
        return Some(py);
    }
    if std::env::var_os("VOLCAL_REQUIRE_PY").is_some() {
        panic!("the Python checker venv {} is missing (run .ci/run, or python3 -m venv .venv && .venv/bin/pip install -r .ci/requirements.txt)", py.display());
    }
    eprintln!("skipping: no Python checker venv at {} (create it with .ci/run)", py.display());
    None
}

/// A fresh scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volcal-test-{}-{}", name, std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}
