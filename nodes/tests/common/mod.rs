//! Helpers for the node-set tests: run `volcal launch` as a child process, watch its output,
//! find node pids, stop it.
#![allow(dead_code)]

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
