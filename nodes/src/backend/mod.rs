//! The instruments and the machine behind the ROS 2 nodes.
//!
//! Each node (interferometer, tracer, deflector, machine, environment) is a thin loop that
//! turns DDS messages into calls on a backend and backend results into DDS messages. The
//! backend is either the simulation ([`sim`], driven by `volcal_sim`: the same components as
//! `volcal simulate`) or real hardware, which implements the traits below.
//!
//! # Writing a hardware backend
//!
//! A backend talks to one device through its driver (serial, USB, a fieldbus, a vendor SDK).
//! Its methods are called from the node's single thread; they should return quickly (the node
//! polls again) rather than block for long. Times are wall-clock nanoseconds since the Unix
//! epoch, the stamps of the messages; a device with its own clock must convert, and if it cannot,
//! the recorder's `clock_offset_s` parameter corrects the machine stamps and is recorded with
//! every pair. Units are SI. Errors are reported with `anyhow` and name the device.
//!
//! - [`InterferometerBackend`]: a laser interferometer (e.g. a Renishaw XL-80 or Keysight 5530
//!   with a trigger input). `read` latches the fringe count; the node tags it with the trigger.
//! - [`TracerBackend`]: a tracking interferometer (Etalon LaserTRACER) giving relative ranges.
//! - [`DeflectorBackend`]: the two-axis beam deflector (motorised indexing head with a mirror).
//! - [`MachineBackend`]: the machine controller: motion commands, indicated coordinates (the
//!   scales, latched on a trigger input where the controller has one), in-position status.
//! - [`EnvironmentBackend`]: air and material temperature sensors (e.g. the XC-80 station).
//!
//! An instrument needs no Rust either when a few lines of any language bridge its SDK to the
//! text protocol of [`line`] (TCP or a serial port; the interferometer, tracer and environment
//! nodes' `backend: line`). A machine that speaks ROS 2's standard interfaces needs no Rust: [`ros2_control`] reads its
//! `sensor_msgs/JointState` and sends it `trajectory_msgs/JointTrajectory` (the machine node's
//! `backend: ros2_control`).
//!
//! The simulated backends additionally receive the simulation truth ([`Truth`]) that the sim
//! nodes exchange on `/sim/truth/...`; hardware backends ignore it (the default method), and
//! the nodes subscribe to those topics only when [`InterferometerBackend::simulated`] (etc.) says
//! so.

pub mod injected;
pub mod line;
pub mod ros2_control;
pub mod sim;

pub use volcal_formats::instrument::{InstrumentInfo, LengthReading, Truth};

use anyhow::Result;
use nalgebra::{Point3, Vector3};

/// A fixed-beam laser interferometer.
pub trait InterferometerBackend {
    /// Wavelength and compensation of the readings (published latched on
    /// `/interferometer/info`).
    fn info(&self) -> InstrumentInfo;
    /// The deflector points a new beam: the counter will be zeroed at the next reading
    /// (the patent zeroes it at the first point of each beam).
    fn new_beam(&mut self, station: u32, beam: u32);
    /// Latches a reading valid at `at_ns`. `point` is the point index within the beam for a
    /// triggered reading (`None` for free-running samples). `Ok(None)`: no reading possible
    /// yet (e.g. the reflector is still moving); the node retries shortly.
    fn read(&mut self, at_ns: i64, point: Option<u32>, position_id: Option<u64>) -> Result<Option<LengthReading>>;
    /// An on-the-fly segment started at `stamp_ns` (the sequencer's `SEGMENT_START`).
    fn segment_start(&mut self, _stamp_ns: i64) {}
    /// Simulation truth (only simulated backends use it).
    fn truth(&mut self, _t: &Truth) {}
    /// Whether the node must subscribe to the simulation truth topics.
    fn simulated(&self) -> bool {
        false
    }
}

/// A laser tracer (tracking interferometer) measuring relative ranges.
pub trait TracerBackend {
    fn info(&self) -> InstrumentInfo;
    /// The tracer stands at a new station (the operator moved it): the count restarts.
    fn new_station(&mut self, station: u32);
    /// Latches a relative range valid at `at_ns`; see [`InterferometerBackend::read`].
    fn read(&mut self, at_ns: i64, point: Option<u32>, position_id: Option<u64>) -> Result<Option<LengthReading>>;
    fn truth(&mut self, _t: &Truth) {}
    fn simulated(&self) -> bool {
        false
    }
}

/// What the deflector reports about its beam.
#[derive(Clone, Debug, PartialEq)]
pub struct DeflectorReadback {
    pub azimuth_rad: f64,
    pub elevation_rad: f64,
    pub settled: bool,
    /// Nominal beam origin and direction, when the device's geometry is calibrated.
    pub geometry: Option<(Point3<f64>, Vector3<f64>)>,
}

/// A two-axis beam deflector.
pub trait DeflectorBackend {
    /// Starts pointing the beam; `device_position` is where the device stands.
    fn command(
        &mut self,
        device_position: Point3<f64>,
        azimuth_rad: f64,
        elevation_rad: f64,
        now_ns: i64,
    ) -> Result<()>;
    /// Current state.
    fn readback(&mut self, now_ns: i64) -> DeflectorReadback;
    /// When the state is next expected to change by itself (settled); `None` if unknown.
    fn next_change_ns(&self) -> Option<i64> {
        None
    }
    /// Simulated backends: the actual beam once settled (published on `/sim/truth/beam`).
    fn truth_beam(&mut self, _now_ns: i64) -> Option<(Point3<f64>, Vector3<f64>)> {
        None
    }
}

/// A motion command.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionCommand {
    pub position_id: u64,
    /// Target indicated coordinates, metres.
    pub target: Point3<f64>,
    /// Probe / reflector offset mounted, metres.
    pub probe_offset: Vector3<f64>,
    pub speed_mps: f64,
}

/// The machine's state as its controller reports it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MachineState {
    /// Indicated coordinates (scales), metres.
    pub position: Point3<f64>,
    pub velocity: Vector3<f64>,
    pub probe_offset: Vector3<f64>,
    /// At rest at the target of `position_id`.
    pub in_position: bool,
    pub position_id: u64,
}

/// The machine controller.
pub trait MachineBackend {
    /// Starts a motion (replacing any motion in progress).
    fn move_to(&mut self, cmd: &MotionCommand, now_ns: i64) -> Result<()>;
    /// The state at `now_ns` (for a trigger: the latched coordinates).
    fn state(&mut self, now_ns: i64) -> MachineState;
    /// When the state is next expected to change by itself (the end of a motion), so that the
    /// node reports it without delay; `None` if unknown (the node polls).
    fn next_change_ns(&self) -> Option<i64> {
        None
    }
    /// Where the reported coordinates of a motion commanded at `now_ns` leave their start
    /// (later than `now_ns` by their latency): the node's start sample is stamped there, so
    /// that the samples stand at the reported path's corners.
    fn start_corner_ns(&self, now_ns: i64) -> i64 {
        now_ns
    }
    /// An on-the-fly segment starts (`true`, the sequencer's `SEGMENT_START`) or ends.
    fn on_the_fly(&mut self, _running: bool) {}
    /// Simulated backends: the actual reflector position at `now_ns` (`/sim/truth/reflector`).
    fn truth(&mut self, _now_ns: i64) -> Option<Truth> {
        None
    }
}

/// One environment sample.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct EnvironmentSample {
    /// Air temperature (degC), pressure (Pa), humidity (%), CO2 (ppm), when measured.
    pub air: Option<volcal::environment::Air>,
    /// Scale temperature, degC, when measured.
    pub machine_temp_c: Option<f64>,
    /// Further material sensors, degC.
    pub materials: Vec<(String, f64)>,
}

/// Environment sensors.
pub trait EnvironmentBackend {
    fn read(&mut self, now_ns: i64) -> Result<EnvironmentSample>;
}
