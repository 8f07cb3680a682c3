//! Bags that another writer made: Python `rosbags` (not our code) writes a campaign CSV as a
//! rosbag2 bag holding only `/interferometer/info` and `/campaign/pairs`, in metadata versions 8
//! and 9 (Jazzy's QoS lists). `volcal diagnose` and `volcal solve` must give on the bag what they
//! give on the CSV, and a bag without pairs must be refused with the topics and types it has.

use serde_json::Value;
mod common;

use common::run_volcal as volcal;
use std::path::{Path, PathBuf};
use std::process::Command;
use volcal_tests::{checker_python, repo_root, scratch};

/// Writes `csv` as a bag with rosbags (metadata `version`).
fn rosbags_bag(py: &Path, csv: &Path, out: &Path, version: u32) -> PathBuf {
    let _ = std::fs::remove_dir_all(out);
    let root = repo_root();
    let st = Command::new(py)
        .arg(root.join("tests/py/csv_to_rosbag2.py"))
        .arg(csv)
        .arg(out)
        .arg(root.join("msgs/msg"))
        .arg(version.to_string())
        .output()
        .unwrap();
    assert!(st.status.success(), "rosbags writer: {}", String::from_utf8_lossy(&st.stderr));
    out.to_path_buf()
}

/// A diagnosis or model JSON without its provenance (which names the input file and its hash).
fn comparable(json: &Path) -> Value {
    let mut v: Value = serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    v.as_object_mut().unwrap().remove("provenance");
    v
}

#[test]
fn a_rosbags_bag_is_diagnosed_like_its_csv() {
    let Some(py) = checker_python() else { return };
    let dir = scratch("third-party-bags");
    let machines = repo_root().join("launch_configs/machines");
    for (name, machine) in [
        ("clean", "diagnosis_cmm.yaml"),
        ("setup_drift", "diagnosis_cmm.yaml"),
        ("beam_break", "diagnosis_cmm.yaml"),
        ("probe_offset", "diagnosis_cmm_precision.yaml"),
    ] {
        let csv = repo_root().join("bags/concealed").join(format!("{name}.csv"));
        let machine = machines.join(machine);
        let from_csv = dir.join(format!("{name}.csv.json"));
        let (ok, _, err) = volcal(&[&"diagnose", &csv, &"--machine", &machine, &"--json", &from_csv]);
        assert!(ok, "{name}: diagnose CSV: {err}");
        for version in [8, 9] {
            let bag = rosbags_bag(&py, &csv, &dir.join(format!("{name}_v{version}")), version);
            let from_bag = dir.join(format!("{name}_v{version}.json"));
            let (ok, report, err) = volcal(&[&"diagnose", &bag, &"--machine", &machine, &"--json", &from_bag]);
            assert!(ok, "{name} v{version}: diagnose bag: {err}");
            let (a, b) = (comparable(&from_csv), comparable(&from_bag));
            assert!(a == b, "{name} v{version}: the bag's diagnosis differs from the CSV's:\n{report}");
            let effects: Vec<&str> =
                b["effects"].as_array().unwrap().iter().map(|e| e["id"].as_str().unwrap_or("?")).collect();
            eprintln!("{name}, rosbag2 v{version}: same diagnosis as the CSV (effects {effects:?})");
        }
        // And the solve: the same model (functions, covariance, residuals, identifiability).
        let bag = dir.join(format!("{name}_v9"));
        let (m_csv, m_bag) = (dir.join(format!("{name}.model.json")), dir.join(format!("{name}_v9.model.json")));
        assert!(volcal(&[&"solve", &csv, &"--machine", &machine, &"--out", &m_csv]).0);
        assert!(volcal(&[&"solve", &bag, &"--machine", &machine, &"--out", &m_bag]).0);
        assert!(comparable(&m_csv) == comparable(&m_bag), "{name}: the bag's model differs from the CSV's");
    }
}

#[test]
fn a_bag_without_pairs_names_what_it_holds() {
    let Some(py) = checker_python() else { return };
    let dir = scratch("third-party-no-pairs");
    let csv = repo_root().join("bags/concealed/clean.csv");
    let machine = repo_root().join("launch_configs/machines/diagnosis_cmm.yaml");
    for (mode, topic, type_name) in [
        ("info-only", "/interferometer/info", "volcal_msgs/msg/InterferometerInfo"),
        ("foreign", "/chatter", "std_msgs/msg/String"),
    ] {
        let bag = dir.join(mode);
        let _ = std::fs::remove_dir_all(&bag);
        let st = Command::new(&py)
            .arg(repo_root().join("tests/py/csv_to_rosbag2.py"))
            .args([csv.as_os_str(), bag.as_os_str(), repo_root().join("msgs/msg").as_os_str()])
            .args(["9", mode])
            .output()
            .unwrap();
        assert!(st.status.success(), "{}", String::from_utf8_lossy(&st.stderr));
        let model = dir.join("m.json");
        let solve: [&dyn AsRef<std::ffi::OsStr>; 6] = [&"solve", &bag, &"--machine", &machine, &"--out", &model];
        let diagnose: [&dyn AsRef<std::ffi::OsStr>; 4] = [&"diagnose", &bag, &"--machine", &machine];
        for (cmd, args) in [("solve", &solve[..]), ("diagnose", &diagnose[..])] {
            let (ok, _, err) = volcal(args);
            assert!(!ok, "{cmd} {mode}: accepted a bag without pairs");
            for what in ["/campaign/pairs", "volcal_msgs/msg/SyncedPair", topic, type_name] {
                assert!(err.contains(what), "{cmd} {mode}: the error does not name {what}:\n{err}");
            }
            eprintln!("{cmd} on a bag with {topic} only: {}", err.trim());
        }
    }
}
