//! The CycloneDDS subscriber of `/diagnosis` (`.ci/checks/cyclone_diagnosis.py`: Python
//! `cyclonedds`, types declared from the `.msg` files, ROS 2's DDS names), independent of our
//! code.

use super::repo;
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The subscriber, started and waiting for its first sample.
pub struct CycloneDiagnosis {
    child: std::process::Child,
    lines: Arc<Mutex<Vec<String>>>,
}

impl CycloneDiagnosis {
    /// Joins `domain`; with `every`, it prints every sample until a final (not partial) one,
    /// otherwise it ends after the first.
    pub fn start(py: &Path, domain: u16, timeout_s: f64, every: bool) -> CycloneDiagnosis {
        let mut cmd = Command::new(py);
        cmd.arg(repo().join(".ci/checks/cyclone_diagnosis.py")).args([domain.to_string(), timeout_s.to_string()]);
        if every {
            cmd.arg("all");
        }
        let mut child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("cannot start the CycloneDDS subscriber");
        let lines = Arc::new(Mutex::new(Vec::new()));
        let (l, out) = (lines.clone(), child.stdout.take().unwrap());
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
        CycloneDiagnosis { child, lines }
    }

    /// Every sample received (with its `received_unix_s`), once the subscriber has ended.
    pub fn samples(mut self) -> Vec<Value> {
        let st = self.child.wait().unwrap();
        std::thread::sleep(Duration::from_millis(100));
        assert!(st.success(), "the CycloneDDS subscriber failed");
        let lines = self.lines.lock().unwrap();
        lines
            .iter()
            .filter_map(|l| serde_json::from_str::<Value>(l).ok())
            .filter(|v| v.get("sample").is_some())
            .collect()
    }

    /// The sample it received (it ends after the first, or with `{"received": 0}`).
    pub fn sample(self) -> Value {
        self.samples()
            .into_iter()
            .find_map(|v| v.get("sample").cloned())
            .unwrap_or_else(|| panic!("CycloneDDS received no /diagnosis"))
    }
}
