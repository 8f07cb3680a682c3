//! The viz node end to end over DDS on loopback: it watches a short simulated campaign (the
//! node set launched on a ROS domain of this test's own) and saves the live view to an `.rrd`
//! file; the recording is verified by the official Rerun CLI of the crate's version
//! (`rerun rrd verify`) and read by an independent Python reader (`check_rrd.py --live`), which
//! takes the campaign's lines from the recorded bag (rosbags) and checks that every one has its
//! live entities (commanded beam, points, running fit, one residual per reading), and that the
//! deflector state, the current point, the status and the running RMS are there. A second viz
//! node that never hears the deflector's commands still draws every commanded beam.

mod common;

use common::*;
use std::time::{Duration, Instant};
use volcal_msgs::topics;
use volcal_nodes::ros::domain;

#[test]
fn viz_node_records_a_live_campaign() {
    let lease = domain::lease().unwrap();
    let dir = volcal_tests::scratch("rerun-live");
    let (bag, rrd, report) = (dir.join("short"), dir.join("live.rrd"), dir.join("viz.json"));
    let rerun_arg = format!("rerun:={}", rrd.display());
    let report_arg = format!("report:={}", report.display());

    // The viz node first: it must hear every pair.
    let mut viz = Launch::start(&launch_config("viz.yaml"), None, lease.id, &[&rerun_arg, &report_arg]);
    viz.wait_for("the viz node", Duration::from_secs(60), |l| l.contains("showing the campaign live in Rerun"));
    // A second viewer that never hears `/deflector/command` (remapped away), as a viewer does
    // whose subscription discovery matched after a command went out (the topic is volatile):
    // it must still draw every commanded beam, from the deflector's settled state.
    let blind_rrd = dir.join("live_without_commands.rrd");
    let blind_config = dir.join("viz_without_commands.yaml");
    let config = std::fs::read_to_string(launch_config("viz.yaml")).unwrap().replace(
        "      name: viz\n",
        &format!(
            "      name: viz_without_commands\n      remap:\n        - {{from: {}, to: /unheard}}\n",
            topics::DEFLECTOR_COMMAND
        ),
    );
    assert!(config.contains("/unheard"), "viz.yaml no longer has the node line this test edits");
    std::fs::write(&blind_config, config).unwrap();
    let machine_arg = format!("machine:={}", launch_config("machines/demo_cmm.yaml").display());
    let blind_rerun_arg = format!("rerun:={}", blind_rrd.display());
    let mut blind = Launch::start(&blind_config, None, lease.id, &[&machine_arg, &blind_rerun_arg]);
    blind.wait_for("the viz node without commands", Duration::from_secs(60), |l| {
        l.contains("showing the campaign live in Rerun")
    });
    let probe = test_node("rerun_live_probe", lease.id);
    let t = Instant::now();
    while probe.ros_node().subscription_count(topics::PAIRS) < 2 {
        assert!(t.elapsed() < Duration::from_secs(30), "the viz nodes did not subscribe to {}", topics::PAIRS);
        std::thread::sleep(Duration::from_millis(50));
    }
    drop(probe);

    let started = Instant::now();
    let (st, out) = Launch::start(&launch_config("sim_campaign_short.yaml"), Some(&bag), lease.id, &[])
        .wait(Duration::from_secs(120));
    assert!(st.success(), "campaign launch failed:\n{out}");
    assert!(out.contains("the recorder confirmed all 960 acquired points"), "{out}");
    eprintln!("campaign recorded in {:.1} s", started.elapsed().as_secs_f64());
    // Let the last pairs reach the viz node (generously: CI runs on a loaded machine), then stop
    // it (it finishes the recording).
    std::thread::sleep(Duration::from_millis(2000));
    viz.interrupt();
    blind.interrupt();
    let (st, out) = viz.wait(Duration::from_secs(30));
    assert!(st.success(), "viz launch failed:\n{out}");
    let (st, blind_out) = blind.wait(Duration::from_secs(30));
    assert!(st.success(), "viz launch without commands failed:\n{blind_out}");
    eprintln!("{}", out.lines().filter(|l| l.contains("viz:")).collect::<Vec<_>>().join("\n"));

    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["pairs"], 960, "the viz node received every pair: {r}");
    assert!(r["machine_samples"].as_u64().unwrap() > 0 && r["deflector_messages"].as_u64().unwrap() >= 48, "{r}");
    assert!(std::fs::metadata(&rrd).expect("no recording written").len() > 0);

    let Some(py) = volcal_tests::checker_python() else { return };
    rrd::verify(&py, &rrd);
    rrd::check_entities(&py, &["--live".as_ref(), rrd.as_os_str(), bag.as_os_str()]);
    rrd::verify(&py, &blind_rrd);
    rrd::check_entities(&py, &["--live".as_ref(), blind_rrd.as_os_str(), bag.as_os_str()]);
}
