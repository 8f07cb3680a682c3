//! What the instruments report, independent of how it travels (DDS messages, bags): the
//! backends of the nodes produce these, and the message conversions read them.

use nalgebra::{Point3, Vector3};

/// How a length instrument's readings relate to the air.
#[derive(Clone, Debug, PartialEq)]
pub struct InstrumentInfo {
    pub instrument: String,
    pub wavelength_vac_m: f64,
    /// Readings are compensated for the air index (the instrument has a weather station).
    pub compensated: bool,
    /// Index used for uncompensated readings.
    pub assumed_index: f64,
    /// `ciddor` or `edlen`.
    pub air_equation: String,
}

/// One latched length reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LengthReading {
    /// Abscissa (interferometer) or relative range (tracer), metres.
    pub value_m: f64,
    /// Return-signal strength, 0..1.
    pub signal_strength: f64,
    /// The count was lost before this reading: its origin is new.
    pub beam_broken: bool,
}

/// What the sim nodes tell each other about the simulated world (never the solver).
#[derive(Clone, Debug, PartialEq)]
pub enum Truth {
    /// The actual beam, from `stamp_ns` (when the deflector settled) on.
    Beam { stamp_ns: i64, station: u32, beam: u32, origin: Point3<f64>, direction: Vector3<f64> },
    /// The actual reflector position at `stamp_ns`.
    Reflector { stamp_ns: i64, position_id: u64, settled: bool, actual: Point3<f64>, velocity: Vector3<f64> },
}
