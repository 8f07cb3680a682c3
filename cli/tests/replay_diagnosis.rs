//! Diagnosis in the replay node (issue 13, item 4): `volcal launch replay.yaml --bag B
//! diagnose:=true` publishes on `/diagnosis` (transient-local) what `volcal diagnose B --json`
//! reports, and the refit model on `/error_model`.
//!
//! The bags are concealed-effect campaigns of `bags/concealed/` written as rosbag2 bags by
//! Python `rosbags` (`tests/py/csv_to_rosbag2.py`, not our writer). The diagnosis is received by
//! a CycloneDDS subscriber (`.ci/checks/cyclone_diagnosis.py`: Python `cyclonedds`, types
//! declared from the `.msg` files, ROS 2's DDS names), independent of our code; the refit model
//! by a node of ours joining late. The key (`tests/fixtures/concealed/`) is read only after the
//! diagnosis, to check the named effect. Each test leases its own ROS domain (loopback only).

mod common;

use common::cyclone_diagnosis::CycloneDiagnosis;
use common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};
use volcal_formats::model_file::{self, ModelFile};
use volcal_formats::truth_file::TruthFile;
use volcal_msgs::msg::{Diagnosis, ErrorModel as ErrorModelMsg};
use volcal_msgs::topics;
use volcal_nodes::ros::{domain, qos};
use volcal_tests::{checker_python, scratch};

/// `csv` written as a rosbag2 bag (metadata version 9) by Python `rosbags`.
fn rosbags_bag(py: &Path, csv: &Path, out: &Path, mode: &str) -> PathBuf {
    let _ = std::fs::remove_dir_all(out);
    let st = Command::new(py)
        .arg(repo().join("tests/py/csv_to_rosbag2.py"))
        .args([csv.as_os_str(), out.as_os_str(), repo().join("msgs/msg").as_os_str()])
        .args(["9", mode])
        .output()
        .unwrap();
    assert!(st.status.success(), "rosbags writer: {}", String::from_utf8_lossy(&st.stderr));
    out.to_path_buf()
}

/// What a replay with `diagnose:=true` published and wrote.
struct Replayed {
    /// The `/diagnosis` sample as CycloneDDS decoded it.
    sample: Value,
    /// `volcal diagnose B --json` of the same bag.
    cli: Value,
    /// `/error_model` as a late joiner received it, and the model file the node wrote.
    model_msg: ErrorModelMsg,
    model_file: ModelFile,
}

/// `volcal diagnose` on `bag`, then the replay launch with `diagnose:=true`, CycloneDDS
/// listening on `/diagnosis` and a late joiner of ours on `/error_model`.
fn replay(py: &Path, bag: &Path, machine: &Path, dir: &Path, name: &str) -> Replayed {
    let json = dir.join(format!("{name}.diagnosis.json"));
    let (ok, _, err) = run_volcal(&[&"diagnose", &bag, &"--machine", &machine, &"--json", &json]);
    assert!(ok, "{name}: volcal diagnose: {err}");
    let cli: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();

    let lease = domain::lease().unwrap();
    let cyclone = CycloneDiagnosis::start(py, lease.id, 240.0, false);
    let model_path = dir.join(format!("{name}.model.json"));
    let args = [
        format!("machine:={}", machine.display()),
        format!("out:={}", model_path.display()),
        "diagnose:=true".to_string(),
        "linger_s:=240".to_string(),
    ];
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let started = Instant::now();
    let mut launch = Launch::start(&launch_config("replay.yaml"), Some(bag), lease.id, &args);
    launch.wait_for("the solver publishing the model", Duration::from_secs(240), |l| {
        l.contains("published the model on /error_model")
    });
    eprintln!("{name}: diagnosed and published in {:.1} s", started.elapsed().as_secs_f64());
    let sample = cyclone.sample();
    let mut late = test_node("late_joiner", lease.id);
    let mut sub = late.subscription::<ErrorModelMsg>(topics::ERROR_MODEL, qos::latched()).unwrap();
    let t = Instant::now();
    let model_msg = loop {
        late.wait(Duration::from_millis(50));
        if let Some(m) = sub.next() {
            break m;
        }
        assert!(t.elapsed() < Duration::from_secs(30), "{name}: no model on /error_model for a late joiner");
    };
    launch.interrupt();
    let (st, out) = launch.wait(Duration::from_secs(30));
    assert!(st.success(), "{name}: replay failed:\n{out}");
    assert!(out.contains("published the diagnosis on /diagnosis"), "{out}");
    let model_file = model_file::load(&model_path).unwrap().file;
    Replayed { sample, cli, model_msg, model_file }
}

/// Numbers compared exactly: the subscriber prints the received doubles in their shortest
/// round-trip form, as `volcal diagnose --json` writes its own, so the same double reads back
/// as the same double.
fn same_number(what: &str, ours: &Value, theirs: &Value) {
    let (a, b) = (ours.as_f64(), theirs.as_f64());
    assert!(a.is_some() && a == b, "{what}: /diagnosis has {ours}, volcal diagnose --json {theirs}");
}

/// A location of the message against one of the JSON file.
fn same_location(what: &str, msg: &Value, file: &Value) {
    for k in ["kind", "label", "detail"] {
        assert_eq!(msg[k], file[k], "{what}: {k}");
    }
    for k in ["excess_chi2", "share", "fraction", "p_value"] {
        same_number(&format!("{what}: {k}"), &msg[k], &file[k]);
    }
}

/// Every figure of the `/diagnosis` sample is the JSON file's.
fn check_same_diagnosis(name: &str, s: &Value, cli: &Value) {
    assert_eq!(s["format"], cli["format"], "{name}: format");
    assert_eq!(s["n_readings"], cli["n_readings"], "{name}: n_readings");
    for k in [
        "rms_before_m",
        "rms_after_m",
        "noise_rms_m",
        "chi2_per_dof_before",
        "chi2_per_dof_after",
        "map_change_rms_m",
        "map_change_max_m",
    ] {
        same_number(&format!("{name}: {k}"), &s[k], &cli[k]);
    }
    for k in ["input", "input_sha256", "machine", "machine_sha256", "software"] {
        assert_eq!(s[k], cli["provenance"][k], "{name}: provenance {k}");
    }
    let (effects, cli_effects) = (s["effects"].as_array().unwrap(), cli["effects"].as_array().unwrap());
    assert_eq!(effects.len(), cli_effects.len(), "{name}: number of effects");
    for (e, c) in effects.iter().zip(cli_effects) {
        let id = c["id"].as_str().unwrap();
        assert_eq!(e["id"], c["id"], "{name}: effect order");
        for k in ["statement", "alternatives"] {
            assert_eq!(e[k], c[k], "{name} {id}: {k}");
        }
        same_number(&format!("{name} {id}: delta_rms_m"), &e["delta_rms_m"], &c["delta_rms_m"]);
        same_number(&format!("{name} {id}: p_value"), &e["p_value"], &c["p_value"]);
        same_number(&format!("{name} {id}: evidence (log10 Bayes factor)"), &e["log10_bayes_factor"], &c["evidence"]);
        let params = e["parameters"].as_array().unwrap();
        assert_eq!(params.len(), c["parameters"].as_object().unwrap().len(), "{name} {id}: parameters");
        for p in params {
            let n = p["name"].as_str().unwrap();
            same_number(&format!("{name} {id}: {n}"), &p["value"], &c["parameters"][n]);
            same_number(&format!("{name} {id}: u({n})"), &p["uncertainty"], &c["uncertainty"][n]);
            assert!(!p["unit"].as_str().unwrap().is_empty(), "{name} {id}: {n} has no unit");
        }
    }
    assert_eq!(s["partial"], false, "{name}: a replay's diagnosis is not partial");
    let (lines, cli_lines) = (s["lines"].as_array().unwrap(), cli["lines"].as_array().unwrap());
    assert_eq!(lines.len(), cli_lines.len(), "{name}: number of lines");
    for (m, f) in lines.iter().zip(cli_lines) {
        for k in ["station", "line", "n_readings", "flagged_by"] {
            assert_eq!(m[k], f[k], "{name}: line {k}");
        }
        same_number(&format!("{name}: line rms_after_m"), &m["rms_after_m"], &f["rms_after_m"]);
    }
    for k in ["locations", "remaining"] {
        let (m, f) = (s[k].as_array().unwrap(), cli[k].as_array().unwrap());
        assert_eq!(m.len(), f.len(), "{name}: number of {k}");
        for (i, (a, b)) in m.iter().zip(f).enumerate() {
            same_location(&format!("{name}: {k}[{i}]"), a, b);
        }
    }
    assert_eq!(s["unexplained"].as_str().unwrap(), cli["unexplained"].as_str().unwrap_or(""), "{name}: unexplained");
    assert_eq!(s["statements"], cli["statements"], "{name}: statements");
    // And the lossless copy is the file itself.
    let embedded: Value = serde_json::from_str(s["diagnosis_json"].as_str().unwrap()).unwrap();
    assert!(&embedded == cli, "{name}: diagnosis_json differs from volcal diagnose --json");
}

/// The refit model: on `/error_model`, written to `out`, with the residual RMS the diagnosis
/// reports after the refit.
fn check_refit_model(name: &str, r: &Replayed) {
    let from_msg: ModelFile = serde_json::from_str(&r.model_msg.model_json).unwrap();
    assert_eq!(from_msg, r.model_file, "{name}: the published model is the written one");
    let rms: Value = serde_json::to_value(from_msg.residuals.as_ref().unwrap().rms_m).unwrap();
    let rms_after = &r.cli["rms_after_m"];
    // Through the same text form as the file's figure (see `same_number`).
    let reread: Value = serde_json::from_str(&serde_json::to_string(&rms).unwrap()).unwrap();
    same_number(&format!("{name}: /error_model residual RMS vs rms_after_m"), &reread, rms_after);
    let ids: Vec<&str> = r.cli["effects"].as_array().unwrap().iter().map(|e| e["id"].as_str().unwrap()).collect();
    for id in &ids {
        assert!(
            from_msg.warnings.iter().any(|w| w.contains("refit by the diagnosis") && w.contains(id)),
            "{name}: the model does not say it is the refit with {id}: {:?}",
            from_msg.warnings
        );
        assert!(r.sample["model"].as_str().unwrap().contains(id), "{name}: Diagnosis.model does not name {id}");
    }
}

/// A concealed beam break: the replay node names it where it is (station, beam, point) with the
/// figures of `volcal diagnose`, and publishes the refit model.
#[test]
fn replay_node_diagnoses_a_concealed_beam_break_like_volcal_diagnose() {
    let Some(py) = checker_python() else { return };
    let dir = scratch("replay-diagnosis-effect");
    let csv = repo().join("bags/concealed/beam_break.csv");
    let machine = repo().join("launch_configs/machines/diagnosis_cmm.yaml");
    let bag = rosbags_bag(&py, &csv, &dir.join("beam_break"), "pairs");
    let r = replay(&py, &bag, &machine, &dir, "beam_break");
    check_same_diagnosis("beam_break", &r.sample, &r.cli);
    check_refit_model("beam_break", &r);
    assert_eq!(r.sample["verdict"], Value::from(Diagnosis::EFFECTS_NAMED));

    // Only now the key.
    let truth = TruthFile::load(&repo().join("tests/fixtures/concealed/beam_break.truth.json")).unwrap();
    let injected = &truth.injected[0];
    let effect = &r.sample["effects"][0];
    assert_eq!(effect["id"].as_str(), Some(injected.id.as_str()), "not named first: {}", r.sample["statements"]);
    let param = |n: &str| {
        let p = effect["parameters"].as_array().unwrap().iter().find(|p| p["name"] == n).unwrap();
        (p["value"].as_f64().unwrap(), p["uncertainty"].as_f64().unwrap(), p["unit"].as_str().unwrap().to_string())
    };
    for (n, v) in &injected.parameters {
        let (est, u, unit) = param(n);
        eprintln!("  {n} = {est:.6e} +- {u:.2e} {unit} (key {v:.6e})");
        if n == "step_m" {
            assert_eq!(unit, "m");
            assert!((est - v).abs() <= 3.0 * u, "step {est:e} +- {u:e}, key {v:e}");
        } else {
            assert_eq!(unit, "index");
            assert_eq!(est, *v, "{n}: where the beam broke");
        }
    }
    let rms = |k: &str| r.sample[k].as_f64().unwrap() * 1e6;
    eprintln!(
        "beam_break over CycloneDDS: {} named (log10 BF {:.1}); RMS {:.4} -> {:.4} um, noise floor {:.4} um; top location {}",
        effect["id"],
        effect["log10_bayes_factor"].as_f64().unwrap(),
        rms("rms_before_m"),
        rms("rms_after_m"),
        rms("noise_rms_m"),
        r.sample["locations"][0]["label"]
    );
}

/// A clean campaign: a Diagnosis saying nothing is named; the model is the plain fit.
#[test]
fn replay_node_diagnoses_a_clean_bag_as_clean() {
    let Some(py) = checker_python() else { return };
    let dir = scratch("replay-diagnosis-clean");
    let csv = repo().join("bags/concealed/clean.csv");
    let machine = repo().join("launch_configs/machines/diagnosis_cmm.yaml");
    let bag = rosbags_bag(&py, &csv, &dir.join("clean"), "pairs");
    let r = replay(&py, &bag, &machine, &dir, "clean");
    check_same_diagnosis("clean", &r.sample, &r.cli);
    check_refit_model("clean", &r);
    assert_eq!(r.sample["verdict"], Value::from(Diagnosis::CLEAN), "{}", r.sample["statements"]);
    assert!(r.sample["effects"].as_array().unwrap().is_empty());
    assert_eq!(r.sample["unexplained"], "");
    eprintln!("clean over CycloneDDS: nothing named; {}", r.sample["statements"][0]);
}

/// The first `n` readings of a campaign CSV (its comment header and column line kept).
fn truncated_csv(src: &Path, n: usize, out: &Path) -> PathBuf {
    let text = std::fs::read_to_string(src).unwrap();
    let mut lines = text.lines();
    let mut kept: Vec<&str> = lines.by_ref().take_while(|l| l.starts_with('#')).collect();
    kept.push(text.lines().find(|l| !l.starts_with('#')).unwrap());
    kept.extend(lines.take(n));
    std::fs::write(out, kept.join("\n") + "\n").unwrap();
    out.to_path_buf()
}

/// Runs the replay launch with `diagnose:=true` on `bag` to its end.
fn replay_to_end(bag: &Path, machine: &Path, dir: &Path) -> (std::process::ExitStatus, String) {
    let lease = domain::lease().unwrap();
    let out_arg = format!("out:={}", dir.join("m.json").display());
    let machine_arg = format!("machine:={}", machine.display());
    let args = ["diagnose:=true", "linger_s:=0", &out_arg, &machine_arg];
    Launch::start(&launch_config("replay.yaml"), Some(bag), lease.id, &args).wait(Duration::from_secs(120))
}

/// Bags the diagnosis cannot run on: the node ends with an error naming the bag and what is
/// wrong, not a panic. And a campaign cut short after 300 readings (a few lines of one
/// station), on which the F-test of an effect the campaign does not separate used to panic
/// inside statrs, is diagnosed by both `volcal diagnose` and the node.
#[test]
fn replay_node_refuses_a_bag_it_cannot_diagnose() {
    let Some(py) = checker_python() else { return };
    let dir = scratch("replay-diagnosis-bad");
    let clean = repo().join("bags/concealed/clean.csv");
    let machine = repo().join("launch_configs/machines/diagnosis_cmm.yaml");
    let machine_arg = format!("machine:={}", machine.display());
    let no_pairs = rosbags_bag(&py, &clean, &dir.join("info_only"), "info-only");
    let one = rosbags_bag(&py, &truncated_csv(&clean, 1, &dir.join("one.csv")), &dir.join("one_reading"), "pairs");
    for (bag, what) in [
        (&no_pairs, vec!["/campaign/pairs", "volcal_msgs/msg/SyncedPair"]),
        (&one, vec!["no beam or path has enough points to solve"]),
    ] {
        let lease = domain::lease().unwrap();
        let (st, out) =
            Launch::start(&launch_config("replay.yaml"), Some(bag), lease.id, &["diagnose:=true", &machine_arg])
                .wait(Duration::from_secs(60));
        assert!(!st.success(), "accepted {}:\n{out}", bag.display());
        assert!(!out.contains("panicked"), "{out}");
        assert!(!out.contains("published the diagnosis"), "{out}");
        let name = bag.display().to_string();
        for w in std::iter::once(name.as_str()).chain(what) {
            assert!(out.contains(w), "the error does not name {w}:\n{out}");
        }
        eprintln!("{}", out.lines().find(|l| l.contains("error")).unwrap_or_default());
    }

    let short = rosbags_bag(&py, &truncated_csv(&clean, 300, &dir.join("short.csv")), &dir.join("short"), "pairs");
    let (ok, report, err) = run_volcal(&[&"diagnose", &short, &"--machine", &machine]);
    assert!(ok && !err.contains("panicked"), "volcal diagnose on 300 readings:\n{err}");
    let (st, out) = replay_to_end(&short, &machine, &dir);
    assert!(st.success() && out.contains("published the diagnosis on /diagnosis"), "{out}");
    eprintln!("300 readings: {}", report.lines().find(|l| l.starts_with("Residual RMS")).unwrap_or_default());
}
