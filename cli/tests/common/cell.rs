//! An independent ROS 2 cell for the tests: `tests/py/ros2_cell.py`, rclpy on Fast DDS
//! (from the Python registry: `ros-rclpy[fastrtps]`), behaving like `joint_state_broadcaster`
//! + `joint_trajectory_controller`.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The checker venv's Python when it has rclpy with Fast DDS, or `None` (skipped locally; under
/// `VOLCAL_REQUIRE_PY` a venv without rclpy is a failure).
pub fn rclpy_python() -> Option<PathBuf> {
    let py = volcal_tests::checker_python()?;
    let ok = Command::new(&py)
        .args(["-c", "import rclpy, sensor_msgs.msg, trajectory_msgs.msg"])
        .envs(ros_env(&py))
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(py);
    }
    if std::env::var_os("VOLCAL_REQUIRE_PY").is_some() {
        panic!("rclpy is missing from {} (.ci/requirements.txt installs it)", py.display());
    }
    eprintln!("skipping: no rclpy in {}", py.display());
    None
}

/// The environment of a ROS 2 Python process from the venv: its ament prefix and Fast DDS.
fn ros_env(py: &Path) -> Vec<(&'static str, String)> {
    let prefix = py.parent().and_then(Path::parent).unwrap().display().to_string();
    vec![("AMENT_PREFIX_PATH", prefix), ("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp".into())]
}

/// `py SCRIPT` from `tests/py/` as a ROS 2 process of the venv on `domain`, loopback only.
pub fn ros_python(py: &Path, script: &str, domain: u16) -> Command {
    let mut c = Command::new(py);
    c.arg(super::repo().join("tests/py").join(script))
        .envs(ros_env(py))
        .env("ROS_DOMAIN_ID", domain.to_string())
        .env("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        .env_remove("ROS_LOCALHOST_ONLY");
    c
}

/// A running cell; stopped (SIGTERM) when dropped.
pub struct Cell {
    child: Child,
    /// Every joint state it published: `stamp_ns,x_m,y_m,z_m`.
    pub log: PathBuf,
}

impl Cell {
    /// Starts the cell on `domain` (loopback only) with extra `args` for `ros2_cell.py`, and
    /// waits until its publisher and subscription exist.
    pub fn start(py: &Path, dir: &Path, domain: u16, args: &[&str]) -> Cell {
        let (log, ready) = (dir.join("cell_states.csv"), dir.join("cell.ready"));
        let _ = std::fs::remove_file(&ready);
        let child = ros_python(py, "ros2_cell.py", domain)
            .arg("--log")
            .arg(&log)
            .arg("--ready")
            .arg(&ready)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(dir.join("cell.err")).unwrap())
            .spawn()
            .expect("cannot start the rclpy cell");
        let mut cell = Cell { child, log };
        let t = Instant::now();
        while !ready.exists() {
            if let Ok(Some(st)) = cell.child.try_wait() {
                panic!(
                    "the rclpy cell ended ({st}): {}",
                    std::fs::read_to_string(dir.join("cell.err")).unwrap_or_default()
                );
            }
            assert!(t.elapsed() < Duration::from_secs(30), "the rclpy cell did not start within 30 s");
            std::thread::sleep(Duration::from_millis(50));
        }
        cell
    }

    /// Stops the cell and returns its published states, in order.
    pub fn stop(mut self) -> Vec<CellState> {
        super::signal(self.child.id() as i32, libc::SIGTERM);
        let t = Instant::now();
        while self.child.try_wait().unwrap().is_none() && t.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(50));
        }
        let text = std::fs::read_to_string(&self.log).unwrap();
        text.lines()
            .skip(1)
            .filter_map(|l| {
                let v: Vec<&str> = l.split(',').collect();
                (v.len() == 7).then(|| CellState {
                    stamp_ns: v[0].parse().unwrap(),
                    position: [1, 2, 3].map(|k| v[k].parse().unwrap()),
                    velocity: [4, 5, 6].map(|k| v[k].parse().unwrap()),
                })
            })
            .collect()
    }
}

/// One joint state the cell published (its three axis joints), as its log wrote it.
#[derive(Clone, Copy, Debug)]
pub struct CellState {
    pub stamp_ns: i64,
    pub position: [f64; 3],
    pub velocity: [f64; 3],
}

impl Drop for Cell {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            super::signal(self.child.id() as i32, libc::SIGTERM);
            std::thread::sleep(Duration::from_millis(300));
            let _ = self.child.kill();
        }
    }
}
