//! rclpy receives the error model (issue 14): an rclpy node on Fast DDS, with `volcal_msgs`
//! type support built from our `.msg` files by `.ci/build_rclpy_msgs.sh` (the overlay
//! `.rclpy_msgs/`), subscribes to the replay node's latched `/error_model`, once before the
//! launch and once 4 s after it (a late joiner), and each gets the model the solver wrote, field
//! by field (`tests/py/rclpy_error_model.py --model`).

mod common;

use common::cell::{rclpy_python, ros_python};
use common::*;
use std::process::Stdio;
use std::time::Duration;
use volcal_nodes::ros::domain;

#[test]
fn rclpy_receives_the_error_model_early_and_late() {
    let Some(py) = rclpy_python() else { return };
    let overlay = repo().join(".rclpy_msgs");
    if !overlay.join("lib").exists() {
        if std::env::var_os("VOLCAL_REQUIRE_PY").is_some() {
            panic!("no volcal_msgs overlay at {} (.ci/build_rclpy_msgs.sh builds it)", overlay.display());
        }
        eprintln!("skipping: no volcal_msgs overlay (run .ci/build_rclpy_msgs.sh)");
        return;
    }
    let lease = domain::lease().unwrap();
    let dir = volcal_tests::scratch("rclpy-error-model");
    let model = dir.join("model.json");
    let subscriber = |name: &str| {
        ros_python(&py, "rclpy_error_model.py", lease.id)
            .args(["--timeout", "60", "--node-name", name, "--overlay"])
            .arg(&overlay)
            .arg("--model")
            .arg(&model)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("cannot start the rclpy subscriber")
    };
    let early = subscriber("early");
    std::thread::sleep(Duration::from_secs(3));
    // The model (about 0.9 MB) takes seconds to reach a Fast DDS reader: the solver serves it
    // for 60 s here (replay.yaml's default of 2 s is too short for that).
    let out_arg = format!("out:={}", model.display());
    let launch = Launch::start(
        &launch_config("replay.yaml"),
        Some(&repo().join("bags/sim_short")),
        lease.id,
        &[&out_arg, "linger_s:=60"],
    );
    std::thread::sleep(Duration::from_secs(4));
    let late = subscriber("late");
    let (early, late) = (early.wait_with_output().unwrap(), late.wait_with_output().unwrap());
    launch.interrupt();
    let (_, log) = launch.wait(Duration::from_secs(60));
    for (name, o, late_joiner) in
        [("subscribed 3 s before the launch", &early, false), ("subscribed 4 s after the launch", &late, true)]
    {
        let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
        assert!(o.status.success(), "rclpy {name}: {stdout}\n{stderr}\n{log}");
        let j: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap_or("{}")).unwrap();
        assert_eq!(j["model_file"]["match"], true, "rclpy {name}: {j}");
        assert_eq!(j["late_joiner"], late_joiner, "rclpy {name}: {j}");
        eprintln!(
            "rclpy {name}: received {} bytes of model JSON, sha256 {}",
            j["model_json_len"], j["model_json_sha256"]
        );
    }
}
