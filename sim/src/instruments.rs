//! Virtual instruments: the machine itself, the interferometer, the two-axis beam deflector and
//! the laser tracer. Each is a small deterministic component driven by an explicit RNG, so the
//! offline simulator and the ROS 2 sim nodes share exactly the same physics.

use nalgebra::{Point3, Rotation3, Unit, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use volcal::environment::{air_index, Air, AirIndexEquation};
use volcal::ErrorModel;

fn gauss<R: Rng + ?Sized>(rng: &mut R, sigma: f64) -> f64 {
    if sigma > 0.0 {
        Normal::new(0.0, sigma).unwrap().sample(rng)
    } else {
        0.0
    }
}

fn gauss3<R: Rng + ?Sized>(rng: &mut R, sigma: f64) -> Vector3<f64> {
    Vector3::new(gauss(rng, sigma), gauss(rng, sigma), gauss(rng, sigma))
}

/// A straight laser beam in machine coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct BeamLine {
    /// Point where the beam leaves the deflector mirror.
    pub origin: Point3<f64>,
    /// Unit direction of propagation.
    pub direction: Vector3<f64>,
}

impl BeamLine {
    /// Point at abscissa `s` along the beam.
    pub fn at(&self, s: f64) -> Point3<f64> {
        self.origin + self.direction * s
    }
}

/// Unit vector of azimuth `az` (about Z from +X) and elevation `el` (from the XY plane).
pub fn direction_from_angles(az: f64, el: f64) -> Vector3<f64> {
    Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
}

/// Azimuth and elevation of a direction.
pub fn angles_from_direction(d: &Vector3<f64>) -> (f64, f64) {
    let d = d.normalize();
    (d.y.atan2(d.x), d.z.clamp(-1.0, 1.0).asin())
}

/// The machine: true error model (exact kinematic chain) plus random repeatability.
#[derive(Clone, Debug)]
pub struct VirtualMachine {
    pub truth: ErrorModel,
    /// Standard deviation of the random positioning error per axis, metres.
    pub repeatability_m: f64,
    /// Lateral centring error of the photoreceiver feedback, metres.
    pub centring_m: f64,
}

impl VirtualMachine {
    /// Actual reflector position for indicated coordinates `x` and offset `p`, without noise.
    pub fn exact(&self, x: &Point3<f64>, p: &Vector3<f64>) -> Point3<f64> {
        self.truth.exact_position(x, p)
    }

    /// Actual reflector position including the random repeatability.
    pub fn actual<R: Rng + ?Sized>(&self, x: &Point3<f64>, p: &Vector3<f64>, rng: &mut R) -> Point3<f64> {
        self.exact(x, p) + gauss3(rng, self.repeatability_m)
    }

    /// Indicated coordinates that put the reflector (offset `p`) at `target`: the controller's
    /// motion along the beam under photoreceiver feedback (patent: the machine follows the beam).
    pub fn indicated_for<R: Rng + ?Sized>(
        &self,
        target: &Point3<f64>,
        p: &Vector3<f64>,
        beam_dir: &Vector3<f64>,
        rng: &mut R,
    ) -> Point3<f64> {
        // Centring error, perpendicular to the beam.
        let mut lateral = gauss3(rng, self.centring_m);
        lateral -= beam_dir * beam_dir.dot(&lateral);
        let goal = target + lateral;
        let mut x = goal - p;
        for _ in 0..20 {
            let d = goal - self.exact(&x, p);
            x += d;
            if d.norm() < 1e-15 {
                break;
            }
        }
        x
    }
}

/// Interferometer readings: compensated lengths or raw counts with an assumed air index.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default))]
pub struct Interferometer {
    /// White noise per reading, metres.
    pub noise_m: f64,
    /// Display resolution (quantisation), metres.
    pub resolution_m: f64,
    pub wavelength_vac_m: f64,
    /// `None`: the instrument compensates with the true air index. `Some(n0)`: it reports
    /// lengths computed with the fixed index `n0` (uncompensated).
    pub assumed_index: Option<f64>,
    pub air_equation: AirIndexEquation,
}

impl Default for Interferometer {
    fn default() -> Self {
        Interferometer {
            noise_m: 0.05e-6,
            resolution_m: 1e-9,
            wavelength_vac_m: 632.991_212_58e-9,
            assumed_index: None,
            air_equation: AirIndexEquation::Ciddor,
        }
    }
}

impl Interferometer {
    /// Reading for a true geometric length `length_m` from the beam origin, relative to the
    /// origin length `zero_m` (the counter was zeroed there).
    pub fn read<R: Rng + ?Sized>(&self, length_m: f64, zero_m: f64, air: &Air, rng: &mut R) -> f64 {
        let optical = match self.assumed_index {
            None => length_m - zero_m,
            Some(n0) => {
                let n = air_index(self.air_equation, self.wavelength_vac_m, air);
                (length_m - zero_m) * n / n0
            }
        };
        let v = optical + gauss(rng, self.noise_m);
        quantise(v, self.resolution_m)
    }
}

fn quantise(v: f64, res: f64) -> f64 {
    if res > 0.0 {
        (v / res).round() * res
    } else {
        v
    }
}

/// Two-axis beam deflector (indexing head with a mirror).
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default))]
pub struct Deflector {
    /// Random pointing error of each axis, radians.
    pub pointing_noise_rad: f64,
    /// Offset of the mirror surface from the intersection of the two rotation axes, metres:
    /// the beam origin moves with the direction.
    pub pivot_offset_m: f64,
    /// Time to settle after a new command, seconds.
    pub settle_s: f64,
    /// 1/e^2 radius of the beam profile, metres (photoreceiver signal vs lateral offset).
    pub beam_radius_m: f64,
}

impl Default for Deflector {
    fn default() -> Self {
        Deflector { pointing_noise_rad: 20e-6, pivot_offset_m: 0.5e-3, settle_s: 2.0, beam_radius_m: 2.0e-3 }
    }
}

impl Deflector {
    /// The actual beam for a commanded azimuth/elevation from a device at `pivot`.
    pub fn point<R: Rng + ?Sized>(&self, pivot: &Point3<f64>, az: f64, el: f64, rng: &mut R) -> BeamLine {
        let az = az + gauss(rng, self.pointing_noise_rad);
        let el = el + gauss(rng, self.pointing_noise_rad);
        let direction = direction_from_angles(az, el);
        // The mirror normal bisects the incoming (vertical) and outgoing beams; its surface sits
        // `pivot_offset_m` from the pivot along that normal.
        let incoming = Vector3::z();
        let normal = (direction - incoming).try_normalize(1e-12).unwrap_or(Vector3::x());
        BeamLine { origin: pivot + normal * self.pivot_offset_m, direction }
    }

    /// Relative return-signal strength (0..1) for a reflector at lateral distance `d` from the
    /// beam axis: a retroreflector displaced by `d` returns the beam displaced by `2 d`, and the
    /// photoreceiver sees the overlap of two Gaussian profiles.
    pub fn signal_strength(&self, lateral_m: f64) -> f64 {
        let w = self.beam_radius_m;
        (-(2.0 * lateral_m).powi(2) / (w * w)).exp()
    }
}

/// Laser tracer (tracking interferometer) relative ranges.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default))]
pub struct Tracer {
    pub noise_m: f64,
    pub noise_ppm: f64,
    /// Dead path: the range at which the relative count is zero, metres.
    pub dead_path_m: f64,
    pub resolution_m: f64,
}

impl Default for Tracer {
    fn default() -> Self {
        Tracer { noise_m: 0.1e-6, noise_ppm: 0.2, dead_path_m: 0.25, resolution_m: 1e-9 }
    }
}

impl Tracer {
    /// Relative range reading from station `q` to the actual reflector position.
    pub fn read<R: Rng + ?Sized>(&self, q: &Point3<f64>, actual: &Point3<f64>, rng: &mut R) -> f64 {
        self.read_range((actual - q).norm(), rng)
    }

    /// Relative range reading for a geometric (optical) range `r`.
    pub fn read_range<R: Rng + ?Sized>(&self, r: f64, rng: &mut R) -> f64 {
        let sigma = (self.noise_m.powi(2) + (self.noise_ppm * 1e-6 * r).powi(2)).sqrt();
        quantise(r - self.dead_path_m + gauss(rng, sigma), self.resolution_m)
    }
}

/// Rotation that takes +X to `d` (for drawing and for building lateral bases).
pub fn frame_along(d: &Vector3<f64>) -> Rotation3<f64> {
    Rotation3::rotation_between(&Vector3::x(), d)
        .unwrap_or_else(|| Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::z()), std::f64::consts::PI))
}
