//! A machine driven through `ros2_control`'s standard interfaces: its coordinates come from
//! `sensor_msgs/msg/JointState` (as `joint_state_broadcaster` publishes them), its motions go
//! out as `trajectory_msgs/msg/JointTrajectory` (as `joint_trajectory_controller` takes them).
//!
//! This module is the cell-independent logic, free of DDS: which joint is which axis and in
//! what unit ([`JointMap`]), the trajectory of a motion ([`trajectory`]), and when the machine
//! is in position ([`Arrival`]). The node loop is `crate::node::machine_cell`.
//!
//! Conventions (REP-103): prismatic joints report metres; `joint_scale` and `joint_sign` map a
//! cell that reports other units or directions, `axis = sign * scale * joint`.

use anyhow::{anyhow, bail, Result};
use nalgebra::{Point3, Vector3};
use volcal_msgs::builtin_interfaces::msg::Duration;
use volcal_msgs::sensor_msgs::msg::JointState;
use volcal_msgs::std_msgs::msg::Header;
use volcal_msgs::trajectory_msgs::msg::{JointTrajectory, JointTrajectoryPoint};

const AXES: [&str; 3] = ["x", "y", "z"];

/// Which joint of the cell drives each machine axis, and how its position converts to metres.
#[derive(Clone, Debug, PartialEq)]
pub struct JointMap {
    /// Joint names of X, Y, Z.
    pub names: [String; 3],
    /// `axis_m = sign * scale * joint_position` per axis.
    pub scale: [f64; 3],
    pub sign: [f64; 3],
}

/// Parses `x=A,y=B,z=C` into one value per axis; a single value without `=` applies to all
/// three. `what` names the parameter in errors.
fn per_axis(text: &str, what: &str) -> Result<[Option<String>; 3]> {
    let text = text.trim();
    if !text.is_empty() && !text.contains('=') {
        return Ok([Some(text.to_string()), Some(text.to_string()), Some(text.to_string())]);
    }
    let mut out: [Option<String>; 3] = Default::default();
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (axis, value) = item
            .split_once('=')
            .ok_or_else(|| anyhow!("parameter {what}: {item:?} is not AXIS=VALUE (x=..,y=..,z=..)"))?;
        let k = AXES
            .iter()
            .position(|a| a.eq_ignore_ascii_case(axis.trim()))
            .ok_or_else(|| anyhow!("parameter {what}: {:?} is not an axis (x, y or z)", axis.trim()))?;
        if out[k].is_some() {
            bail!("parameter {what}: axis {} given twice", AXES[k]);
        }
        out[k] = Some(value.trim().to_string());
    }
    Ok(out)
}

fn numbers(text: &str, what: &str, default: f64) -> Result<[f64; 3]> {
    let mut out = [default; 3];
    for (k, v) in per_axis(text, what)?.into_iter().enumerate() {
        if let Some(v) = v {
            let x: f64 =
                v.parse().map_err(|_| anyhow!("parameter {what}: {v:?} (axis {}) is not a number", AXES[k]))?;
            if !(x.is_finite() && x != 0.0) {
                bail!("parameter {what}: axis {} needs a finite non-zero number, got {v}", AXES[k]);
            }
            out[k] = x;
        }
    }
    Ok(out)
}

impl JointMap {
    /// From the node parameters' texts: `joint_names` (`x=NAME,y=NAME,z=NAME`, all three
    /// required), `joint_scale` and `joint_sign` (empty, one number for all axes, or per axis).
    pub fn parse(names: &str, scale: &str, sign: &str) -> Result<JointMap> {
        let n = per_axis(names, "joint_names")?;
        if n.iter().any(|v| v.as_deref().is_none_or(str::is_empty)) || !names.contains('=') {
            bail!("parameter joint_names: {names:?} must name the joint of every axis, as x=NAME,y=NAME,z=NAME");
        }
        let names: [String; 3] = n.map(Option::unwrap_or_default);
        for i in 0..3 {
            for j in i + 1..3 {
                if names[i] == names[j] {
                    bail!("parameter joint_names: joint {:?} drives both {} and {}", names[i], AXES[i], AXES[j]);
                }
            }
        }
        let sign = numbers(sign, "joint_sign", 1.0)?;
        if let Some(k) = sign.iter().position(|s| s.abs() != 1.0) {
            bail!("parameter joint_sign: axis {} must be 1 or -1, got {}", AXES[k], sign[k]);
        }
        Ok(JointMap { names, scale: numbers(scale, "joint_scale", 1.0)?, sign })
    }

    /// The machine coordinates in a joint state (joints in any order, extra joints ignored),
    /// and the axis velocities when the message carries them. `topic` names the source in errors.
    pub fn axes(&self, js: &JointState, topic: &str) -> Result<(Point3<f64>, Option<Vector3<f64>>)> {
        if js.position.len() != js.name.len() {
            bail!(
                "{topic}: a joint state with {} names and {} positions (they must pair up)",
                js.name.len(),
                js.position.len()
            );
        }
        let with_velocity = js.velocity.len() == js.name.len();
        let (mut p, mut v) = (Point3::origin(), Vector3::zeros());
        for k in 0..3 {
            let i = js.name.iter().position(|n| *n == self.names[k]).ok_or_else(|| {
                anyhow!(
                    "{topic}: joint {:?} (axis {}) is missing from the joint state, which has [{}]",
                    self.names[k],
                    AXES[k],
                    js.name.join(", ")
                )
            })?;
            let f = self.sign[k] * self.scale[k];
            let q = js.position[i];
            if !q.is_finite() {
                bail!("{topic}: joint {:?} (axis {}) reports position {q}", self.names[k], AXES[k]);
            }
            p[k] = f * q;
            if with_velocity {
                v[k] = f * js.velocity[i];
            }
        }
        Ok((p, (with_velocity && v.iter().all(|x| x.is_finite())).then_some(v)))
    }

    /// Joint positions (in the cell's units) that put the axes at `p`.
    pub fn joints(&self, p: &Vector3<f64>) -> Vec<f64> {
        (0..3).map(|k| p[k] / (self.sign[k] * self.scale[k])).collect()
    }
}

/// How a motion is executed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionLimits {
    /// Path speed, m/s.
    pub speed_mps: f64,
    /// Path acceleration, m/s^2.
    pub acceleration_mps2: f64,
}

fn duration(s: f64) -> Duration {
    let ns = (s.max(0.0) * 1e9).round() as i64;
    Duration { sec: (ns / 1_000_000_000) as i32, nanosec: (ns % 1_000_000_000) as u32 }
}

/// Seconds that a straight motion of `length` takes at these limits with a trapezoidal speed
/// profile (triangular when the length is too short to reach the speed).
pub fn motion_time(length: f64, l: &MotionLimits) -> f64 {
    let (v, a) = (l.speed_mps, l.acceleration_mps2);
    if length <= v * v / a {
        2.0 * (length / a).sqrt()
    } else {
        length / v + v / a
    }
}

/// The trajectory of a straight motion from `from` to `to`, to be started on receipt (header
/// stamp zero, as `joint_trajectory_controller` reads it).
///
/// `constant_speed` (an on-the-fly line): the points of a trapezoidal profile with their
/// velocities (end of the acceleration, start of the deceleration, the target at rest), so
/// that the machine crosses the line at the commanded speed. Otherwise (a static target) one
/// point at rest whose time from start is [`motion_time`]: the controller's spline through it
/// sets the profile, with peak acceleration below `6 L / t^2`.
pub fn trajectory(
    map: &JointMap,
    from: &Point3<f64>,
    to: &Point3<f64>,
    limits: &MotionLimits,
    constant_speed: bool,
) -> JointTrajectory {
    let d = to - from;
    let length = d.norm();
    let dir = if length > 0.0 { d / length } else { Vector3::zeros() };
    let point = |s: f64, speed: f64, t: f64| JointTrajectoryPoint {
        positions: map.joints(&(from.coords + dir * s)),
        velocities: map.joints(&(dir * speed)),
        time_from_start: duration(t),
        ..Default::default()
    };
    let (v, a) = (limits.speed_mps, limits.acceleration_mps2);
    let ramp = v * v / (2.0 * a);
    let points = if constant_speed && length > 2.0 * ramp {
        let t_ramp = v / a;
        let t_end = motion_time(length, limits);
        vec![point(ramp, v, t_ramp), point(length - ramp, v, t_end - t_ramp), point(length, 0.0, t_end)]
    } else {
        // At least the time the acceleration allows for the controller's cubic through a
        // single point at rest (peak acceleration 6 L / t^2).
        let t = motion_time(length, limits).max((6.0 * length / a).sqrt()).max(1e-3);
        vec![point(length, 0.0, t)]
    };
    JointTrajectory { header: Header::default(), joint_names: map.names.to_vec(), points }
}

/// Decides from the joint states when a motion has arrived: every axis within `tolerance_m`
/// of the target, continuously for `settle_s`.
#[derive(Clone, Debug)]
pub struct Arrival {
    pub target: Point3<f64>,
    pub tolerance_m: f64,
    pub settle_ns: i64,
    /// Stamp since which the axes have stayed within tolerance.
    within_since: Option<i64>,
}

impl Arrival {
    pub fn new(target: Point3<f64>, tolerance_m: f64, settle_s: f64) -> Arrival {
        Arrival { target, tolerance_m, settle_ns: (settle_s.max(0.0) * 1e9) as i64, within_since: None }
    }

    /// Feeds the coordinates stamped `t_ns`; whether the machine is in position now.
    pub fn update(&mut self, t_ns: i64, p: &Point3<f64>) -> bool {
        if self.offsets(p).iter().all(|o| o.abs() <= self.tolerance_m) {
            let since = *self.within_since.get_or_insert(t_ns);
            t_ns - since >= self.settle_ns
        } else {
            self.within_since = None;
            false
        }
    }

    /// Position minus target per axis.
    pub fn offsets(&self, p: &Point3<f64>) -> Vector3<f64> {
        p - self.target
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn js(names: &[&str], pos: &[f64]) -> JointState {
        JointState { name: names.iter().map(|s| s.to_string()).collect(), position: pos.to_vec(), ..Default::default() }
    }

    #[test]
    fn joints_in_any_order_extra_ignored_units_and_signs() {
        let m = JointMap::parse("x=gantry_x, y=gantry_y ,z=quill", "x=0.001,y=0.001,z=0.001", "z=-1").unwrap();
        let (p, v) =
            m.axes(&js(&["quill", "spindle", "gantry_y", "gantry_x"], &[250.0, 3.0, 100.0, 40.0]), "/js").unwrap();
        assert_eq!(p, Point3::new(0.04, 0.1, -0.25));
        assert!(v.is_none());
        // Back to joints: the inverse.
        let q = m.joints(&p.coords);
        assert!((q[0] - 40.0).abs() < 1e-12 && (q[1] - 100.0).abs() < 1e-12 && (q[2] - 250.0).abs() < 1e-12);
    }

    #[test]
    fn bad_cells_are_named() {
        let m = JointMap::parse("x=a,y=b,z=c", "", "").unwrap();
        let e = m.axes(&js(&["a", "c"], &[0.0, 0.0]), "/joint_states").unwrap_err().to_string();
        assert!(e.contains("/joint_states") && e.contains("\"b\"") && e.contains("axis y"), "{e}");
        let e = m.axes(&js(&["a", "b", "c"], &[0.0, f64::NAN, 0.0]), "/joint_states").unwrap_err().to_string();
        assert!(e.contains("\"b\"") && e.contains("NaN"), "{e}");
        assert!(JointMap::parse("x=a,y=b", "", "").is_err());
        assert!(JointMap::parse("x=a,y=a,z=c", "", "").unwrap_err().to_string().contains("both x and y"));
        assert!(JointMap::parse("x=a,y=b,z=c", "", "y=2").is_err());
        assert!(JointMap::parse("x=a,y=b,z=c", "x=0", "").is_err());
        assert!(JointMap::parse("x=a,y=b,w=c", "", "").is_err());
    }

    #[test]
    fn static_and_on_the_fly_trajectories() {
        let m = JointMap::parse("x=a,y=b,z=c", "", "").unwrap();
        let l = MotionLimits { speed_mps: 0.5, acceleration_mps2: 2.0 };
        let (from, to) = (Point3::new(0.0, 0.0, 0.0), Point3::new(0.6, 0.8, 0.0));
        let t = trajectory(&m, &from, &to, &l, false);
        assert_eq!(t.joint_names, ["a", "b", "c"]);
        assert_eq!(t.points.len(), 1);
        assert_eq!(t.points[0].positions, vec![0.6, 0.8, 0.0]);
        assert_eq!(t.points[0].velocities, vec![0.0, 0.0, 0.0]);
        // 1 m at 0.5 m/s with 2 m/s^2: 2 s + 0.25 s; the cubic needs sqrt(3) s only.
        assert_eq!(t.points[0].time_from_start, Duration { sec: 2, nanosec: 250_000_000 });
        let t = trajectory(&m, &from, &to, &l, true);
        assert_eq!(t.points.len(), 3);
        // Ramp 0.0625 m in 0.25 s, cruise at 0.5 m/s along the line.
        assert!((t.points[0].positions[0] - 0.0375).abs() < 1e-12);
        assert!((t.points[0].velocities[0] - 0.3).abs() < 1e-12 && (t.points[1].velocities[1] - 0.4).abs() < 1e-12);
        assert_eq!(t.points[1].time_from_start, Duration { sec: 2, nanosec: 0 });
        assert_eq!(t.points[2].positions, vec![0.6, 0.8, 0.0]);
    }

    #[test]
    fn arrival_needs_the_tolerance_for_the_settling_time() {
        let mut a = Arrival::new(Point3::new(1.0, 0.0, 0.0), 1e-6, 0.1);
        assert!(!a.update(0, &Point3::new(0.9, 0.0, 0.0)));
        assert!(!a.update(10_000_000, &Point3::new(1.0, 0.0, 0.0)));
        assert!(!a.update(60_000_000, &Point3::new(1.0 + 5e-7, 0.0, 0.0)));
        assert!(a.update(110_000_000, &Point3::new(1.0, 0.0, 0.0)));
        // An excursion restarts the settling.
        assert!(!a.update(120_000_000, &Point3::new(1.0 + 2e-6, 0.0, 0.0)));
        assert!(!a.update(130_000_000, &Point3::new(1.0, 0.0, 0.0)));
    }
}
