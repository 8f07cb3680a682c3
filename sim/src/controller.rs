//! A controller's per-joint compensation acting on the simulated machine: what the controller
//! adds to each joint's command (linear interpolation between table nodes, end values held
//! outside, one column moving up and one moving down, the last one held when stopped), so that
//! the compensated machine can be measured again and identified (the closed loop of
//! `volcal simulate --compensation`).

use crate::inject::{Injection, Sample};
use nalgebra::Point3;

/// Linear interpolation in a table with ascending `x`, end values held outside: how LinuxCNC
/// (and most controllers) read a compensation table between its nodes.
pub fn interpolate(x: &[f64], y: &[f64], q: f64) -> f64 {
    if q <= x[0] {
        return y[0];
    }
    if q >= x[x.len() - 1] {
        return y[y.len() - 1];
    }
    let i = x.partition_point(|v| *v <= q) - 1;
    let s = (q - x[i]) / (x[i + 1] - x[i]);
    y[i] + s * (y[i + 1] - y[i])
}

/// One joint's table: offsets (metres) added to the command, by direction of travel.
#[derive(Clone, Debug, PartialEq)]
pub struct JointOffsets {
    pub nominal_m: Vec<f64>,
    pub forward_m: Vec<f64>,
    pub reverse_m: Vec<f64>,
}

/// Per-joint compensation of X, Y, Z (a joint without a table is not compensated).
pub struct JointCompensation {
    pub joints: [Option<JointOffsets>; 3],
}

impl Injection for JointCompensation {
    fn id(&self) -> &str {
        "controller_compensation"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        ["x", "y", "z"]
            .iter()
            .zip(&self.joints)
            .map(|(a, j)| (format!("{a}_nodes"), j.as_ref().map_or(0.0, |j| j.nominal_m.len() as f64)))
            .collect()
    }
    fn describe(&self) -> String {
        "per-joint compensation tables applied by the controller".into()
    }
    /// The joint moves by the offset: the actual position shifts along the joint's axis (the
    /// error functions' change over a few micrometres of travel is negligible).
    fn actual(&self, s: &Sample, actual: &mut Point3<f64>) {
        for (k, j) in self.joints.iter().enumerate() {
            if let Some(j) = j {
                let column = if s.motion[k] < 0.0 { &j.reverse_m } else { &j.forward_m };
                actual[k] += interpolate(&j.nominal_m, column, s.x[k]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::interpolate;

    #[test]
    fn interpolates_between_nodes_and_holds_the_ends() {
        let (x, y) = ([0.0, 1.0, 2.0], [1.0, 3.0, -1.0]);
        assert_eq!(interpolate(&x, &y, -5.0), 1.0);
        assert_eq!(interpolate(&x, &y, 0.5), 2.0);
        assert_eq!(interpolate(&x, &y, 1.5), 1.0);
        assert_eq!(interpolate(&x, &y, 9.0), -1.0);
    }
}
