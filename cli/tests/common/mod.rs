//! Helpers for the node-set tests: run `volcal launch` as a child process, watch its output,
//! find node pids, stop it.
#![allow(dead_code)]

pub mod cell;
pub mod cyclone_diagnosis;
pub mod rrd;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use volcal_nodes::ros::node::DdsConfig;
use volcal_nodes::ros::{NodeArgs, RosNode};

pub fn volcal() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_volcal"))
}

/// Runs `volcal ARGS...` to the end: whether it succeeded, its stdout and its stderr.
pub fn run_volcal(args: &[&dyn AsRef<std::ffi::OsStr>]) -> (bool, String, String) {
    let out = Command::new(volcal()).args(args).output().expect("volcal runs");
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}

pub fn repo() -> PathBuf {
    volcal_tests::repo_root()
}

pub fn launch_config(name: &str) -> PathBuf {
    repo().join("launch_configs").join(name)
}

/// A node in the test process on the given domain, loopback only.
pub fn test_node(name: &str, domain: u16) -> RosNode {
    RosNode::with_config(NodeArgs::default(), name, DdsConfig { domain_id: domain, localhost_only: true }).unwrap()
}

/// A running `volcal launch`.
pub struct Launch {
    child: Child,
    lines: Arc<Mutex<Vec<String>>>,
}

impl Launch {
    /// Starts `volcal launch FILE [--bag BAG] --domain D ARGS...`.
    pub fn start(file: &Path, bag: Option<&Path>, domain: u16, args: &[&str]) -> Launch {
        let mut cmd = Command::new(volcal());
        cmd.arg("launch").arg(file).arg("--domain").arg(domain.to_string());
        if let Some(b) = bag {
            cmd.arg("--bag").arg(b);
        }
        // Loopback only, whatever the launch file says.
        cmd.env("ROS_LOCALHOST_ONLY", "1");
        cmd.args(args).stdout(Stdio::piped()).stderr(Stdio::piped()).stdin(Stdio::null());
        let mut child = cmd.spawn().expect("cannot start volcal launch");
        let lines = Arc::new(Mutex::new(Vec::new()));
        for s in [
            Box::new(child.stdout.take().unwrap()) as Box<dyn std::io::Read + Send>,
            Box::new(child.stderr.take().unwrap()),
        ] {
            let l = lines.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(s).lines().map_while(Result::ok) {
                    l.lock().unwrap().push(line);
                }
            });
        }
        Launch { child, lines }
    }

    pub fn output(&self) -> String {
        self.lines.lock().unwrap().join("\n")
    }

    /// Waits until a line satisfies `pred`; panics with the output after `timeout`.
    pub fn wait_for(&mut self, what: &str, timeout: Duration, pred: impl Fn(&str) -> bool) -> String {
        let start = Instant::now();
        loop {
            if let Some(l) = self.lines.lock().unwrap().iter().find(|l| pred(l)) {
                return l.clone();
            }
            if let Ok(Some(st)) = self.child.try_wait() {
                std::thread::sleep(Duration::from_millis(200));
                if let Some(l) = self.lines.lock().unwrap().iter().find(|l| pred(l)) {
                    return l.clone();
                }
                panic!("launch ended ({st}) before {what}; output:\n{}", self.output());
            }
            if start.elapsed() > timeout {
                let _ = self.child.kill();
                panic!("timed out waiting for {what}; output:\n{}", self.output());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// The pid of the latest instance of a node, from the launcher's "started"/"respawned" lines.
    pub fn pid_of(&self, node: &str) -> Option<i32> {
        let lines = self.lines.lock().unwrap();
        lines.iter().rev().find_map(|l| {
            let rest = l.strip_prefix("[launch] started ").or_else(|| l.strip_prefix("[launch] respawned "))?;
            let (name, pid) = rest.split_once(" (pid ")?;
            (name == node).then(|| pid.trim_end_matches(')').parse().ok())?
        })
    }

    /// Waits for the launch to end.
    pub fn wait(mut self, timeout: Duration) -> (ExitStatus, String) {
        let start = Instant::now();
        loop {
            if let Some(st) = self.child.try_wait().unwrap() {
                std::thread::sleep(Duration::from_millis(200));
                return (st, self.output());
            }
            if start.elapsed() > timeout {
                let _ = self.child.kill();
                panic!("launch did not end within {timeout:?}; output:\n{}", self.output());
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Whether the launch is still running.
    pub fn running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Ctrl-C.
    pub fn interrupt(&self) {
        signal(self.child.id() as i32, libc::SIGINT);
    }
}

impl Drop for Launch {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            signal(self.child.id() as i32, libc::SIGINT);
            std::thread::sleep(Duration::from_millis(500));
            let _ = self.child.kill();
        }
    }
}

pub fn signal(pid: i32, sig: i32) {
    // SAFETY: signalling a process this test started.
    unsafe {
        libc::kill(pid, sig);
    }
}

/// What an independent reader should find in a bag: counts and header-stamp sums per topic,
/// and checksums of the synchronised pairs, from volcal's own reader.
pub fn our_tally(bag: &Path) -> serde_json::Value {
    use volcal_msgs::cdr;
    use volcal_msgs::msg::SyncedPair;
    use volcal_msgs::std_msgs::msg::Header;
    let mut counts = std::collections::BTreeMap::<String, u64>::new();
    let mut stamps = std::collections::BTreeMap::<String, i128>::new();
    let (mut l, mut pos, mut n, mut broken) = (Neumaier::default(), Neumaier::default(), 0u64, 0u64);
    volcal_bag::Bag::open(bag)
        .unwrap()
        .read(|m| {
            *counts.entry(m.topic.to_string()).or_default() += 1;
            // Every volcal message starts with a std_msgs/Header.
            let h: Header = cdr::decode(m.data)?;
            *stamps.entry(m.topic.to_string()).or_default() += h.stamp.to_nanos() as i128;
            if m.type_name == "volcal_msgs/msg/SyncedPair" {
                let p: SyncedPair = m.decode()?;
                l.add(p.l_m);
                for v in p.position_m {
                    pos.add(v);
                }
                n += 1;
                broken += p.beam_broken as u64;
            }
            Ok(())
        })
        .unwrap();
    serde_json::json!({
        "counts": counts,
        "stamp_sums": stamps.iter().map(|(k, v)| (k.clone(), v.to_string())).collect::<std::collections::BTreeMap<_, _>>(),
        "pairs": {"n": n, "l_m_sum": l.sum(), "position_sum": pos.sum(), "beam_broken": broken},
    })
}

/// Compensated summation (what Python's math.fsum approximates exactly).
#[derive(Default)]
pub struct Neumaier {
    s: f64,
    c: f64,
}

impl Neumaier {
    pub fn add(&mut self, x: f64) {
        let t = self.s + x;
        if self.s.abs() >= x.abs() {
            self.c += (self.s - t) + x;
        } else {
            self.c += (x - t) + self.s;
        }
        self.s = t;
    }

    pub fn sum(&self) -> f64 {
        self.s + self.c
    }
}

/// Runs `.ci/checks/read_bags.py` (rosbags and mcap-ros2-support) on the bags and checks that
/// both readers find what volcal's reader finds. Returns false when the checker venv is absent
/// (skipped locally; `VOLCAL_REQUIRE_PY` makes that a failure).
pub fn check_with_independent_readers(bags: &[PathBuf]) -> bool {
    let Some(py) = volcal_tests::checker_python() else { return false };
    let out = Command::new(py)
        .arg(repo().join(".ci/checks/read_bags.py"))
        .args(bags)
        .output()
        .expect("cannot run the Python checker");
    assert!(out.status.success(), "read_bags.py failed:\n{}", String::from_utf8_lossy(&out.stderr));
    let theirs: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for bag in bags {
        let ours = our_tally(bag);
        let key = bag.display().to_string();
        for reader in ["rosbags", "mcap_ros2"] {
            let t = &theirs[&key][reader];
            let counts: std::collections::BTreeMap<String, u64> = serde_json::from_value(t["counts"].clone()).unwrap();
            let our_counts: std::collections::BTreeMap<String, u64> =
                serde_json::from_value(ours["counts"].clone()).unwrap();
            assert_eq!(counts, our_counts, "{key}: {reader} counts per topic");
            assert_eq!(t["stamp_sums"], ours["stamp_sums"], "{key}: {reader} header stamps");
            let (a, b) = (&t["pairs"], &ours["pairs"]);
            assert_eq!(a["n"], b["n"], "{key}: {reader} pairs");
            assert_eq!(a["beam_broken"], b["beam_broken"], "{key}: {reader} beam_broken flags");
            for f in ["l_m_sum", "position_sum"] {
                let (x, y) = (a[f].as_f64().unwrap(), b[f].as_f64().unwrap());
                assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "{key}: {reader} {f}: {x} vs {y}");
            }
            eprintln!(
                "{key}: {reader} decoded {} messages on {} topics, as volcal does",
                counts.values().sum::<u64>(),
                counts.len()
            );
        }
        let meta = theirs[&key]["rosbags"]["metadata_count"].as_u64().unwrap();
        let total: u64 = serde_json::from_value::<std::collections::BTreeMap<String, u64>>(ours["counts"].clone())
            .unwrap()
            .values()
            .sum();
        assert_eq!(meta, total, "{key}: metadata.yaml message_count");
    }
    true
}

/// A CycloneDDS subscriber (`.ci/checks/cyclone_abscissa.py`) of `/interferometer/abscissa`.
pub struct CycloneSubscriber {
    child: Child,
    lines: Arc<Mutex<Vec<String>>>,
}

impl CycloneSubscriber {
    /// Starts it on `domain` and waits until its reader exists; `None` when the checker venv
    /// is absent (skipped locally).
    pub fn start(domain: u16, count: usize, timeout_s: f64) -> Option<CycloneSubscriber> {
        let py = volcal_tests::checker_python()?;
        let mut child = Command::new(py)
            .arg(repo().join(".ci/checks/cyclone_abscissa.py"))
            .args([domain.to_string(), count.to_string(), timeout_s.to_string()])
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("cannot start the CycloneDDS subscriber");
        let lines = Arc::new(Mutex::new(Vec::new()));
        let l = lines.clone();
        let out = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                l.lock().unwrap().push(line);
            }
        });
        let start = Instant::now();
        while !lines.lock().unwrap().iter().any(|l| l.contains("\"ready\"")) {
            assert!(start.elapsed() < Duration::from_secs(30), "the CycloneDDS subscriber did not start");
            std::thread::sleep(Duration::from_millis(50));
        }
        Some(CycloneSubscriber { child, lines })
    }

    /// Waits for it to finish and returns the samples it received.
    pub fn samples(mut self) -> Vec<serde_json::Value> {
        let st = self.child.wait().unwrap();
        std::thread::sleep(Duration::from_millis(100));
        assert!(st.success(), "the CycloneDDS subscriber failed");
        self.lines
            .lock()
            .unwrap()
            .iter()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .filter(|v| v.get("trigger_id").is_some())
            .collect()
    }
}

/// Writes into `dir` a laser-tracer campaign (`campaign.csv`: 4 stations, the 12 edges, 11
/// stops per edge) over a machine whose guideways carry a bump shorter than the stops' spacing,
/// and the two-line machine file (`machine.yaml`): held-out seed 3001 of `representation_auto`,
/// the first whose readings contradict the interpolation between the stops (of X).
pub fn contradicted_tracer_campaign(dir: &Path) {
    use volcal_tests::auto_study::{campaign, case, Density, Measure};
    use volcal_tests::truth_families::Family;
    let case = case(Family::PiecewiseBump, "FXYZ", Measure::Tracer, Density::Sparse);
    let (c, _) = campaign(&case, 3001);
    volcal_formats::campaign_csv::write(&dir.join("campaign.csv"), &c).unwrap();
    std::fs::write(
        dir.join("machine.yaml"),
        "topology: FXYZ\ntravel: {x: [0.0, 1.0], y: [0.0, 0.8], z: [-0.6, 0.0]}\n",
    )
    .unwrap();
}
