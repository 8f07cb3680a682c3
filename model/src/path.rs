//! A machine's path between two of its samples.
//!
//! Machines publish their coordinates at a few hundred hertz to a few kilohertz; an
//! on-the-fly reading falls between two samples. A straight line between them is off by
//! `a h² / 8` where the machine accelerates (`a`, sample interval `h`): 62 um for 20 m/s² at
//! 200 Hz, where a ros2_control cell accelerates into a line. When both samples carry the
//! machine's own velocity (a `sensor_msgs/JointState` has it), the cubic Hermite curve through
//! positions and velocities is exact for constant acceleration and keeps a 16 mm periodic error
//! sampled every millimetre to 1e-4 of its amplitude.
//!
//! The velocities are used only where they are worth it: both samples of one motion, neither at
//! rest (a start or an arrival may be a kink), and velocities that agree with the positions to
//! second order (their mean equals the chord velocity for any constant acceleration; a backward
//! difference, as a driver without velocities would publish, is off by half the velocity change
//! and is not used). Otherwise the line is straight. The recorder pairs readings with this rule and
//! the simulated instruments read their truth with it, so a dry run is consistent by construction.

use nalgebra::{Point3, Vector3};

/// One sample of a machine's path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathSample {
    /// Stamp, nanoseconds.
    pub stamp_ns: i64,
    /// The motion command in progress (or last reached).
    pub motion_id: u64,
    /// At rest at the motion's target.
    pub at_rest: bool,
    /// Position, metres.
    pub position: Point3<f64>,
    /// Velocity at `stamp_ns`, metres per second; zero where the source gives none.
    pub velocity: Vector3<f64>,
}

/// Below this disagreement (m/s times the interval) the velocities' contribution is under a
/// nanometre either way.
const NEGLIGIBLE_M: f64 = 3e-9;

/// Whether the Hermite curve is used between `s0` and `s1` (see the module documentation).
pub fn smooth_between(s0: &PathSample, s1: &PathSample) -> bool {
    let h_s = (s1.stamp_ns - s0.stamp_ns) as f64 * 1e-9;
    if h_s <= 0.0 || s0.motion_id != s1.motion_id || s0.at_rest || s1.at_rest {
        return false;
    }
    let chord = (s1.position - s0.position) / h_s;
    let mismatch = ((s0.velocity + s1.velocity) * 0.5 - chord).norm();
    mismatch <= 0.1 * (s1.velocity - s0.velocity).norm() + NEGLIGIBLE_M / h_s
}

/// Position and velocity at `at_ns` (between the two stamps) on the path from `s0` to `s1`.
pub fn between(s0: &PathSample, s1: &PathSample, at_ns: i64) -> (Point3<f64>, Vector3<f64>) {
    let h_ns = s1.stamp_ns - s0.stamp_ns;
    if h_ns <= 0 {
        return (s0.position, s0.velocity);
    }
    let h_s = h_ns as f64 * 1e-9;
    let f = (at_ns - s0.stamp_ns) as f64 / h_ns as f64;
    let chord = (s1.position - s0.position) / h_s;
    if !smooth_between(s0, s1) {
        return (s0.position + (s1.position - s0.position) * f, chord);
    }
    // The Hermite curve as the line plus the velocities' departures from the chord: the form
    // that keeps full precision where the curve is nearly straight.
    let (d0, d1) = (s0.velocity - chord, s1.velocity - chord);
    let (f2, f3) = (f * f, f * f * f);
    let x = s0.position + (s1.position - s0.position) * f + (d0 * (f3 - 2.0 * f2 + f) + d1 * (f3 - f2)) * h_s;
    let v = chord + d0 * (3.0 * f2 - 4.0 * f + 1.0) + d1 * (3.0 * f2 - 2.0 * f);
    (x, v)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_ns: i64, x: f64, v: f64) -> PathSample {
        PathSample {
            stamp_ns: t_ns,
            motion_id: 1,
            at_rest: false,
            position: Point3::new(x, 0.0, 0.0),
            velocity: Vector3::new(v, 0.0, 0.0),
        }
    }

    #[test]
    fn constant_acceleration_is_exact_with_velocities() {
        // 20 m/s² at 200 Hz: a straight line would be 62 um off mid-interval.
        let (a, v0, h) = (20.0, 0.1, 5_000_000i64);
        let at = |t: f64| (v0 * t + 0.5 * a * t * t, v0 + a * t);
        let (x0, w0) = at(0.0);
        let (x1, w1) = at(h as f64 * 1e-9);
        let (s0, s1) = (sample(0, x0, w0), sample(h, x1, w1));
        for j in 0..=10 {
            let t = h * j / 10;
            let (x, v) = between(&s0, &s1, t);
            let (xt, vt) = at(t as f64 * 1e-9);
            assert!((x.x - xt).abs() < 1e-15, "{} vs {xt}", x.x);
            assert!((v.x - vt).abs() < 1e-12);
        }
    }

    #[test]
    fn backward_differences_and_rests_give_a_straight_line() {
        let (a, h) = (20.0, 5_000_000i64);
        let x = |t: f64| 0.5 * a * t * t;
        let (t1, t2) = (h as f64 * 1e-9, 2.0 * h as f64 * 1e-9);
        // Velocities as a driver without them would publish: backward differences.
        let s1 = sample(h, x(t1), (x(t1) - 0.0) / t1);
        let s2 = sample(2 * h, x(t2), (x(t2) - x(t1)) / t1);
        assert!(!smooth_between(&s1, &s2));
        let (mid, _) = between(&s1, &s2, h + h / 2);
        assert_eq!(mid.x, 0.5 * (x(t1) + x(t2)));
        // A start: the sample at rest bounds a straight line whatever the velocities say.
        let rest = PathSample { at_rest: true, ..sample(0, 0.0, 0.0) };
        assert!(!smooth_between(&rest, &sample(h, 0.001, 0.4)));
        // Another motion.
        let other = PathSample { motion_id: 2, ..sample(2 * h, 0.002, 0.4) };
        assert!(!smooth_between(&sample(h, 0.001, 0.4), &other));
    }

    #[test]
    fn a_short_period_keeps_its_amplitude() {
        // A 16 mm periodic error of 1 um on X at 2 m/s, sampled at 2 kHz (every mm).
        let (a, period, speed) = (1e-6, 0.016, 2.0);
        let k = 2.0 * std::f64::consts::PI / period;
        let at = |t_ns: i64| {
            let x = speed * t_ns as f64 * 1e-9;
            sample(t_ns, x + a * (k * x).sin(), speed * (1.0 + a * k * (k * x).cos()))
        };
        let mut worst: f64 = 0.0;
        for i in 0..32 {
            let (t0, t1) = (i * 500_000, (i + 1) * 500_000);
            for j in 0..=10 {
                let t = t0 + j * 50_000;
                worst = worst.max((between(&at(t0), &at(t1), t).0 - at(t).position).norm());
            }
        }
        // A straight line would flatten it by 2 %.
        assert!(worst < 1e-4 * a, "off by {worst:e} m");
    }
}
