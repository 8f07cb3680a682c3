//! Live diagnosis (issue 13, item 5): while the node set records a campaign with a beam break
//! concealed, the solver node in live mode (`launch_configs/live_diagnosis.yaml`) diagnoses the
//! pairs after each completed device position and publishes `/diagnosis`; the broken beam is
//! flagged there before the campaign ends. The viz node shows the flagged beam and the residuals
//! before and after in its Rerun recording.
//!
//! Independent witnesses: `/diagnosis` is received by CycloneDDS (`cyclone_diagnosis.py all`,
//! every sample with the wall-clock time it arrived), the end of the campaign is the log time of
//! the bag's last pair (read with the `mcap` crate, not our reader), and the recording is checked
//! by the Rerun CLI and the Rerun SDK (`check_rrd.py --live`). One ROS domain of its own,
//! loopback only.

mod common;

use common::cyclone_diagnosis::CycloneDiagnosis;
use common::*;
use serde_json::Value;
use std::path::Path;
use std::time::{Duration, Instant};
use volcal_msgs::topics;
use volcal_nodes::ros::domain;
use volcal_tests::{checker_python, scratch};

/// Log time (ns since the epoch) of the last `/campaign/pairs` message of the bag.
fn last_pair_log_time(bag: &Path) -> u64 {
    let mut last = 0;
    for f in std::fs::read_dir(bag).unwrap() {
        let f = f.unwrap().path();
        if f.extension().is_some_and(|e| e == "mcap") {
            let bytes = std::fs::read(&f).unwrap();
            for m in mcap::MessageStream::new(&bytes).unwrap() {
                let m = m.unwrap();
                if m.channel.topic == topics::PAIRS {
                    last = last.max(m.log_time);
                }
            }
        }
    }
    assert!(last > 0, "{}: no pairs", bag.display());
    last
}

/// Whether a `/diagnosis` sample flags `station` `beam` with `id`.
fn flags(s: &Value, station: u64, beam: u64, id: &str) -> bool {
    s["lines"].as_array().unwrap().iter().any(|l| {
        l["station"] == station && l["line"] == beam && l["flagged_by"].as_array().unwrap().iter().any(|f| f == id)
    })
}

fn parameter(s: &Value, effect: usize, name: &str) -> (f64, f64) {
    let p = s["effects"][effect]["parameters"].as_array().unwrap().iter().find(|p| p["name"] == name).unwrap();
    (p["value"].as_f64().unwrap(), p["uncertainty"].as_f64().unwrap())
}

#[test]
fn a_live_recording_flags_the_broken_beam_before_the_campaign_ends() {
    let Some(py) = checker_python() else { return };
    let lease = domain::lease().unwrap();
    let dir = scratch("live-diagnosis");
    let machine = repo().join("launch_configs/machines/diagnosis_cmm.yaml");
    let (bag, rrd, model) = (dir.join("campaign"), dir.join("live.rrd"), dir.join("refit.json"));
    let machine_arg = format!("machine:={}", machine.display());

    let cyclone = CycloneDiagnosis::start(&py, lease.id, 400.0, true);
    let mut solver = Launch::start(
        &launch_config("live_diagnosis.yaml"),
        None,
        lease.id,
        &[&machine_arg, &format!("out:={}", model.display()), "linger_s:=120"],
    );
    solver.wait_for("the live solver", Duration::from_secs(60), |l| l.contains("live: after each completed position"));
    let mut viz = Launch::start(
        &launch_config("viz.yaml"),
        None,
        lease.id,
        &[&machine_arg, &format!("rerun:={}", rrd.display())],
    );
    viz.wait_for("the viz node", Duration::from_secs(60), |l| l.contains("showing the campaign live in Rerun"));
    let probe = test_node("live_diagnosis_probe", lease.id);
    let t = Instant::now();
    while probe.ros_node().subscription_count(topics::PAIRS) < 2 {
        assert!(
            t.elapsed() < Duration::from_secs(30),
            "the live solver and the viz node did not subscribe to the pairs"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    drop(probe);

    // The break at station 1 (the second of three positions); 3 s to set up each position (a
    // real one takes minutes), in which the diagnosis of the completed positions runs.
    let started = Instant::now();
    let (st, out) = Launch::start(
        &launch_config("sim_campaign_short.yaml"),
        Some(&bag),
        lease.id,
        &[
            &machine_arg,
            "seed:=20",
            "inject:=beam_break:station=1,beam=4,index=10,step_m=-1.3e-6",
            "conceal:=true",
            "station_setup_s:=3",
        ],
    )
    .wait(Duration::from_secs(300));
    assert!(st.success(), "campaign launch failed:\n{out}");
    let campaign_s = started.elapsed().as_secs_f64();

    // The subscriber ends with the final diagnosis.
    let samples = cyclone.samples();
    let end_ns = last_pair_log_time(&bag);
    eprintln!("campaign recorded in {campaign_s:.1} s; /diagnosis samples received (s relative to the last pair):");
    for v in &samples {
        let s = &v["sample"];
        let ids: Vec<&str> = s["effects"].as_array().unwrap().iter().map(|e| e["id"].as_str().unwrap()).collect();
        eprintln!(
            "  {:+7.2} s  partial {}  {} readings  named {:?}  flags station 1 beam 4: {}  RMS {:.4} -> {:.4} um",
            v["received_unix_s"].as_f64().unwrap() - end_ns as f64 * 1e-9,
            s["partial"],
            s["n_readings"],
            ids,
            flags(s, 1, 4, "beam_break"),
            s["rms_before_m"].as_f64().unwrap() * 1e6,
            s["rms_after_m"].as_f64().unwrap() * 1e6
        );
        if s["partial"] == true {
            eprintln!("            {}", s["statements"][0].as_str().unwrap_or(""));
        }
    }
    let first = samples
        .iter()
        .find(|v| flags(&v["sample"], 1, 4, "beam_break"))
        .unwrap_or_else(|| panic!("no /diagnosis flagged station 1 beam 4:\n{samples:#?}"));
    let s = &first["sample"];
    assert_eq!(s["partial"], true, "the first flag came only with the final diagnosis");
    let at = first["received_unix_s"].as_f64().unwrap();
    assert!(
        at < end_ns as f64 * 1e-9,
        "the flag arrived {:.2} s after the campaign's last pair",
        at - end_ns as f64 * 1e-9
    );
    assert_eq!(s["effects"][0]["id"], "beam_break", "{s:#}");
    let (step, u) = parameter(s, 0, "step_m");
    assert!((step + 1.3e-6).abs() <= 3.0 * u, "live step {step:e} +- {u:e}");

    let last = samples.last().unwrap();
    let f = &last["sample"];
    assert_eq!(f["partial"], false, "the subscriber ended without the final diagnosis");
    assert_eq!(f["n_readings"], 960, "the final diagnosis covers the whole campaign");
    assert_eq!(f["effects"][0]["id"], "beam_break");
    assert!(flags(f, 1, 4, "beam_break"));
    let (step, u) = parameter(f, 0, "step_m");
    assert!((step + 1.3e-6).abs() <= 3.0 * u, "final step {step:e} +- {u:e}");
    eprintln!(
        "flagged {:.2} s before the last pair; final step {step:.4e} +- {u:.2e} (injected -1.3e-6)",
        end_ns as f64 * 1e-9 - at
    );

    // The refit model of the whole campaign is written; the viz node's recording holds the
    // flagged beam, the report, the bars before/after and the RMS history.
    let t = Instant::now();
    while !model.exists() {
        assert!(t.elapsed() < Duration::from_secs(30), "no refit model written");
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_millis(1500));
    viz.interrupt();
    let (st, vout) = viz.wait(Duration::from_secs(30));
    assert!(st.success(), "viz launch failed:\n{vout}");
    solver.interrupt();
    let (st, sout) = solver.wait(Duration::from_secs(30));
    assert!(st.success(), "live solver failed:\n{sout}");
    assert!(sout.contains("published the final diagnosis of 960 pairs"), "{sout}");
    rrd::verify(&py, &rrd);
    let entities = [
        "live/flagged",
        "diagnosis/report",
        "diagnosis/residual_rms_before/stations/1",
        "diagnosis/residual_rms_after/stations/1",
        "diagnosis/rms_history/before",
        "diagnosis/rms_history/after",
    ];
    let mut args: Vec<&std::ffi::OsStr> = vec!["--live".as_ref(), rrd.as_os_str(), bag.as_os_str()];
    for e in &entities {
        args.push("--entity".as_ref());
        args.push(e.as_ref());
    }
    rrd::check_entities(&py, &args);
}
