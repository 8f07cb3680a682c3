//! A simulated laser-interferometer measurement along a line, as the paper's validation does it
//! with a Renishaw XL-80 (Han et al. 2021, section 3.2, Table 3): the beam aligned with the
//! line, the counter zeroed at the start, the machine stepping forward and back through the
//! targets, several runs averaged.

use crate::inject::{Injection, Sample};
use crate::instruments::{Interferometer, VirtualMachine};
use nalgebra::Vector3;
use rand::Rng;
use volcal::environment::Air;
use volcal::validate::Line;

/// Mean positioning deviations at the targets of a line and their standard uncertainties.
#[derive(Clone, Debug, PartialEq)]
pub struct LineMeasurement {
    pub targets_m: Vec<f64>,
    /// Mean over all runs and both directions of (reading - target), metres.
    pub mean_deviation_m: Vec<f64>,
    /// Standard uncertainty of each mean (sample standard deviation / sqrt(count)), metres.
    pub sigma_mean_m: Vec<f64>,
    /// Number of bidirectional runs.
    pub runs: usize,
}

impl LineMeasurement {
    /// `(mean, standard uncertainty)` per target, as [`volcal::validate::compare`] takes them.
    pub fn as_pairs(&self) -> Vec<(f64, f64)> {
        self.mean_deviation_m.iter().cloned().zip(self.sigma_mean_m.iter().cloned()).collect()
    }
}

/// Measures `line` on `machine` with reflector offset `p`: `runs` bidirectional runs through
/// `targets` (distances from the start), the beam aligned with the reflector's motion from the
/// line's start to its end, the counter zeroed at the start of each run. The
/// machine's repeatability and the interferometer's noise and resolution enter every reading.
/// `controller` is what the machine's controller adds to its axes' commands (a compensation,
/// [`crate::controller`]): empty for the machine as it is, the compensation's tables for the
/// machine verified after compensation (ISO 230-2 runs on the compensated axis). Forward passes
/// approach every target moving along the line, backward passes moving against it, as the
/// tables' direction columns see it.
#[allow(clippy::too_many_arguments)]
pub fn measure_line<R: Rng + ?Sized>(
    machine: &VirtualMachine,
    interferometer: &Interferometer,
    line: &Line,
    p: &Vector3<f64>,
    targets: &[f64],
    runs: usize,
    controller: &[&dyn Injection],
    rng: &mut R,
) -> LineMeasurement {
    // The beam as it is set up: aligned with the reflector's motion, through its actual
    // positions at the line's start and end (`volcal::validate`'s module doc).
    let beam = machine.exact(&line.end, p) - machine.exact(&line.start, p);
    let n = beam / beam.norm();
    let air = Air::standard();
    let runs = runs.max(1);
    let mut sums: Vec<Vec<f64>> = vec![Vec::with_capacity(2 * runs); targets.len()];
    let along = |s: f64, motion: Vector3<f64>, rng: &mut R| {
        let x = line.at(s);
        let mut actual = machine.actual(&x, p, rng);
        if !controller.is_empty() {
            let sample = Sample {
                kind: volcal::ObsKind::Beam,
                station: 0,
                line: 0,
                index: 0,
                t_s: 0.0,
                x,
                p: *p,
                velocity: Vector3::zeros(),
                direction: n,
                station_position: line.start,
                air,
                motion,
                t_zero_s: 0.0,
                zero_length_m: 0.0,
                air_zero: air,
            };
            controller.iter().for_each(|c| c.actual(&sample, &mut actual));
        }
        n.dot(&actual.coords)
    };
    for _ in 0..runs {
        let zero = along(0.0, n, rng);
        let order = (0..targets.len()).map(|k| (k, n)).chain((0..targets.len()).rev().map(|k| (k, -n)));
        for (k, motion) in order {
            let s = targets[k];
            let reading = interferometer.read(along(s, motion, rng), zero, &air, rng);
            sums[k].push(reading - s);
        }
    }
    let mean: Vec<f64> = sums.iter().map(|v| v.iter().sum::<f64>() / v.len() as f64).collect();
    let sigma = sums
        .iter()
        .zip(&mean)
        .map(|(v, m)| {
            let k = v.len() as f64;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (k - 1.0).max(1.0) / k).sqrt()
        })
        .collect();
    LineMeasurement { targets_m: targets.to_vec(), mean_deviation_m: mean, sigma_mean_m: sigma, runs }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use rand::SeedableRng;
    use volcal::validate::{axis_line, predict_positioning};

    /// Noise-free, the measurement equals the model's predicted deviation exactly (the
    /// prediction uses the same exact chain): the comparison machinery has no bias of its own.
    #[test]
    fn noise_free_measurement_equals_prediction() {
        let truth = crate::paper::truth();
        let machine = VirtualMachine { truth: truth.clone(), repeatability_m: 0.0, centring_m: 0.0 };
        let li = Interferometer { noise_m: 0.0, resolution_m: 0.0, ..Interferometer::default() };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        for line in volcal::validate::body_diagonals(&truth.layout.travel).into_iter().chain([axis_line(
            &truth.layout.travel,
            volcal::Axis::Y,
            &Point3::new(0.0, 0.0, -0.7),
        )]) {
            let t = line.targets(11);
            let m = measure_line(&machine, &li, &line, &Vector3::zeros(), &t, 5, &[], &mut rng);
            let n = truth.layout.n_params;
            let zero = faer::Mat::zeros(n, n);
            let pred = predict_positioning(
                &truth,
                &volcal::predict::Uncertainty::determined(&zero),
                &line,
                &Vector3::zeros(),
                &t,
            );
            for (p, d) in pred.iter().zip(&m.mean_deviation_m) {
                assert!((p.deviation_m - d).abs() < 1e-12, "{}: {} vs {}", line.name, p.deviation_m, d);
            }
        }
    }

    /// Under a controller whose table for the line's axis is minus the deviation the line
    /// measures (sampled at the targets, read by linear interpolation), the compensated machine
    /// measures zero at the targets; the table's direction columns are read by the direction
    /// of each pass (a reverse column of zeros leaves the backward passes uncompensated, half
    /// of the mean deviation).
    #[test]
    fn a_controller_compensation_acts_on_the_measured_line() {
        use crate::controller::{JointCompensation, JointOffsets};
        let truth = crate::paper::truth();
        let machine = VirtualMachine { truth: truth.clone(), repeatability_m: 0.0, centring_m: 0.0 };
        let li = Interferometer { noise_m: 0.0, resolution_m: 0.0, ..Interferometer::default() };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let line = axis_line(&truth.layout.travel, volcal::Axis::X, &Point3::new(0.0, -0.25, -0.35));
        let t = line.targets(21);
        let before = measure_line(&machine, &li, &line, &Vector3::zeros(), &t, 1, &[], &mut rng);
        let nominal: Vec<f64> = t.iter().map(|s| line.at(*s).x).collect();
        // The deviation is referred to the start: the table moves the start by its first entry.
        let offsets: Vec<f64> = before.mean_deviation_m.iter().map(|d| -d).collect();
        let table = |reverse: Vec<f64>| JointCompensation {
            joints: [
                Some(JointOffsets { nominal_m: nominal.clone(), forward_m: offsets.clone(), reverse_m: reverse }),
                None,
                None,
            ],
        };
        let both = table(offsets.clone());
        let after = measure_line(&machine, &li, &line, &Vector3::zeros(), &t, 1, &[&both], &mut rng);
        let range = |v: &[f64]| v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min);
        assert!(range(&before.mean_deviation_m) > 1e-6, "the paper's X line has micrometres of deviation");
        for d in &after.mean_deviation_m {
            assert!(d.abs() < 1e-12, "compensated deviation {d}");
        }
        let forward_only = table(vec![0.0; t.len()]);
        let half = measure_line(&machine, &li, &line, &Vector3::zeros(), &t, 1, &[&forward_only], &mut rng);
        for (h, b) in half.mean_deviation_m.iter().zip(&before.mean_deviation_m) {
            assert!((h - 0.5 * b).abs() < 1e-12, "{h} vs half of {b}");
        }
    }
}
