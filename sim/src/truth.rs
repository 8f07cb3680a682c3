//! Random but physically plausible truth error models for simulation.

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use volcal::functions::{ErrorFunction, Motion, Squareness};
use volcal::{ErrorModel, ModelLayout};

/// Amplitudes (largest excursion over the travel) of simulated error functions.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default))]
pub struct TruthSpec {
    /// Positioning errors `EXX`, `EYY`, `EZZ`, metres.
    pub positioning_m: f64,
    /// Straightness errors, metres.
    pub straightness_m: f64,
    /// Rotation errors, radians.
    pub rotation_rad: f64,
    /// Squareness errors, radians.
    pub squareness_rad: f64,
    /// Highest Legendre degree of the random shapes (smoothness).
    pub degree: usize,
}

impl Default for TruthSpec {
    fn default() -> Self {
        TruthSpec { positioning_m: 15e-6, straightness_m: 5e-6, rotation_rad: 10e-6, squareness_rad: 30e-6, degree: 5 }
    }
}

/// Draws a random smooth truth on `layout` (its representation: the truth is then exactly
/// representable by a solver using the same layout).
pub fn random_truth<R: Rng + ?Sized>(layout: ModelLayout, spec: &TruthSpec, rng: &mut R) -> ErrorModel {
    let mut m = ErrorModel::zero(layout);
    for f in ErrorFunction::all() {
        let amp = match f.motion {
            Motion::Translation if f.is_positioning() => spec.positioning_m,
            Motion::Translation => spec.straightness_m,
            Motion::Rotation => spec.rotation_rad,
        };
        let coeffs: Vec<f64> = (1..=spec.degree.max(1))
            .map(|k| {
                let v: f64 = StandardNormal.sample(rng);
                v / k as f64
            })
            .collect();
        let [lo, hi] = m.layout.travel.range(f.axis);
        let shape = move |q: f64| {
            let s = (2.0 * q - lo - hi) / (hi - lo);
            let (mut p0, mut p1) = (1.0, s);
            let mut v = coeffs[0] * p1;
            for (k, c) in coeffs.iter().enumerate().skip(1) {
                let kf = k as f64;
                let p2 = ((2.0 * kf + 1.0) * s * p1 - kf * p0) / (kf + 1.0);
                v += c * p2;
                p0 = p1;
                p1 = p2;
            }
            v
        };
        // Normalise the largest excursion to the amplitude.
        let peak = (0..=200).map(|i| shape(lo + (hi - lo) * i as f64 / 200.0).abs()).fold(0.0, f64::max).max(1e-12);
        m.set_function(f, |q| amp * shape(q) / peak);
    }
    for s in Squareness::ALL {
        let v: f64 = StandardNormal.sample(rng);
        m.set_squareness(s, spec.squareness_rad * v.clamp(-2.0, 2.0) / 2.0);
    }
    m
}
