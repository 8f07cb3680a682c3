//! The `line` backend (issue 14): an instrument bridged without Rust. A Python TCP server
//! (`tests/py/line_bridge.py`, the bridge README shows) plays the interferometer and the
//! environment sensors; a campaign records from it through the node set, and every pair holds
//! the reading the bridge sent for that point.

mod common;

use common::*;
use std::io::BufRead;
use std::process::{Command, Stdio};
use std::time::Duration;
use volcal_msgs::msg::{Environment, SyncedPair};
use volcal_msgs::topics;
use volcal_nodes::ros::domain;

#[test]
fn a_campaign_records_from_a_python_bridge() {
    let Some(py) = volcal_tests::checker_python() else { return };
    let lease = domain::lease().unwrap();
    let dir = volcal_tests::scratch("line-backend");
    let log = dir.join("replies.csv");
    let mut bridge = Command::new(py)
        .arg(repo().join("tests/py/line_bridge.py"))
        .args(["0", "--log"])
        .arg(&log)
        .stdout(Stdio::piped())
        .spawn()
        .expect("cannot start the bridge");
    let mut port = String::new();
    std::io::BufReader::new(bridge.stdout.take().unwrap()).read_line(&mut port).unwrap();
    let device = format!("tcp://127.0.0.1:{}", port.trim());
    let machine = repo().join("launch_configs/machines/demo_cmm.yaml");
    let plan = repo().join("tests/data/plans/cell_faults.yaml");
    let launch = dir.join("line.yaml");
    std::fs::write(
        &launch,
        format!(
            r#"launch:
  - arg: {{name: bag}}
  - node: {{pkg: volcal_nodes, exec: volcal_interferometer, name: interferometer,
            param: [{{name: backend, value: line}}, {{name: device, value: "{device}"}}]}}
  - node: {{pkg: volcal_nodes, exec: volcal_environment, name: environment,
            param: [{{name: backend, value: line}}, {{name: device, value: "{device}"}}, {{name: rate_hz, value: "5"}}]}}
  - node: {{pkg: volcal_nodes, exec: volcal_deflector, name: deflector,
            param: [{{name: machine, value: "{m}"}}, {{name: settle_s, value: "0.02"}}]}}
  - node: {{pkg: volcal_nodes, exec: volcal_machine, name: machine, param: [{{name: machine, value: "{m}"}}]}}
  - node: {{pkg: volcal_nodes, exec: volcal_recorder, name: recorder, param: [{{name: bag, value: "$(var bag)"}}]}}
  - node: {{pkg: volcal_nodes, exec: volcal_sequencer, name: sequencer, on_exit: shutdown,
            param: [{{name: machine, value: "{m}"}}, {{name: plan, value: "{p}"}}, {{name: speed_mps, value: "20"}},
                    {{name: dwell_s, value: "0"}}, {{name: station_setup_s, value: "0"}}]}}
"#,
            m = machine.display(),
            p = plan.display()
        ),
    )
    .unwrap();
    let bag = dir.join("bag");
    let (st, out) = Launch::start(&launch, Some(&bag), lease.id, &[]).wait(Duration::from_secs(240));
    let _ = bridge.kill();
    assert!(st.success(), "launch failed:\n{out}");
    assert!(out.contains("the recorder confirmed all 72 acquired points"), "{out}");
    let replies: std::collections::HashMap<(u32, u32, u32), f64> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            ((v[0].parse().unwrap(), v[1].parse().unwrap(), v[2].parse().unwrap()), v[3].parse().unwrap())
        })
        .collect();
    let (mut pairs, mut env) = (Vec::new(), Vec::new());
    volcal_bag::Bag::open(&bag)
        .unwrap()
        .read(|m| {
            if m.topic == topics::PAIRS {
                pairs.push(m.decode::<SyncedPair>()?);
            } else if m.topic == topics::ENVIRONMENT {
                env.push(m.decode::<Environment>()?);
            }
            Ok(())
        })
        .unwrap();
    assert_eq!(pairs.len(), 72);
    for p in &pairs {
        let sent = replies.get(&(p.station, p.line, p.point)).unwrap_or_else(|| panic!("no reply logged for {p:?}"));
        assert_eq!(p.l_m, *sent, "station {} beam {} point {}", p.station, p.line, p.point);
    }
    eprintln!("72 pairs, each with the bridge's reading; {} environment samples", env.len());
    assert!(!env.is_empty() && env.iter().all(|e| e.air_valid && e.air_temp_c == 20.1 && e.machine_temp_c == 20.05));
}

/// README shows the bridge that this test runs, verbatim.
#[test]
fn readme_shows_the_tested_bridge() {
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let bridge = std::fs::read_to_string(repo().join("tests/py/line_bridge.py")).unwrap();
    assert!(
        readme.contains(&format!("```python\n{bridge}```")),
        "README's bridge differs from tests/py/line_bridge.py"
    );
}
