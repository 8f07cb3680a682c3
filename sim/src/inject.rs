//! Hooks through which physics outside the rigid-body model is injected into a simulation,
//! without the solver knowing: the diagnosis catalogue's effects implement [`Injection`].

use nalgebra::{Point3, Vector3};
use volcal::campaign::{ObsKind, Reading};
use volcal::environment::Air;

/// What an injection sees of the sample being simulated.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub kind: ObsKind,
    pub station: u32,
    pub line: u32,
    /// Index of the point within its line.
    pub index: usize,
    pub t_s: f64,
    /// Indicated machine coordinates (as commanded, before the injection acts).
    pub x: Point3<f64>,
    /// Declared probe offset.
    pub p: Vector3<f64>,
    /// Machine velocity (zero for static acquisition).
    pub velocity: Vector3<f64>,
    /// Beam direction, or unit vector from the tracer station to the reflector.
    pub direction: Vector3<f64>,
    /// Deflector pivot or tracer position.
    pub station_position: Point3<f64>,
    /// True air along the beam.
    pub air: Air,
    /// Unit direction of the machine's last move into this point (also for static
    /// acquisition: the approach direction), zero before the first move of a line.
    pub motion: Vector3<f64>,
    /// Time at which the interferometer counter was zeroed (start of the line).
    pub t_zero_s: f64,
    /// Geometric distance from the beam origin (or tracer) to the reflector at zeroing.
    pub zero_length_m: f64,
    /// True air at zeroing.
    pub air_zero: Air,
}

/// A physical effect added to the simulated world. Every hook defaults to "no change".
pub trait Injection: Send + Sync {
    /// Stable id of the effect (the diagnosis catalogue's spelling).
    fn id(&self) -> &str;
    /// Parameters for the truth file.
    fn parameters(&self) -> Vec<(String, f64)>;
    /// Plain description for the truth file.
    fn describe(&self) -> String {
        self.id().to_string()
    }
    /// The probe offset actually mounted (declared offset in, actual out).
    fn probe_offset(&self, _s: &Sample, _p: &mut Vector3<f64>) {}
    /// Machine-side physics: perturbs the actual reflector position.
    fn actual(&self, _s: &Sample, _actual: &mut Point3<f64>) {}
    /// Instrument-side physics: perturbs the optical length (beam) or range (tracer) in metres.
    fn optical(&self, _s: &Sample, _length_m: &mut f64) {}
    /// Recording-side effects: perturbs the reading as written (e.g. delayed coordinates).
    fn record(&self, _s: &Sample, _r: &mut Reading) {}
    /// How much older than their stamps the recorded coordinates are, seconds (a latency).
    /// [`Injection::record`] applies it to one reading through its velocity (`x - v tau`);
    /// a node that samples the machine's motion applies it to the whole state instead, since a
    /// motion's corners are where `x - v tau` and the delayed motion part.
    fn delay_s(&self) -> f64 {
        0.0
    }
}
