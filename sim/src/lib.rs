//! # volcal_sim: the digital twin
//!
//! A virtual Cartesian machine with known error functions ([`instruments::VirtualMachine`],
//! exact kinematic chain plus repeatability), the instruments that measure it
//! ([`instruments::Interferometer`], [`instruments::Deflector`], [`instruments::Tracer`]),
//! campaign [`plan`]s, and [`inject`]ion hooks through which physics outside the rigid-body
//! model enters the simulated world without the solver being told.
//!
//! [`simulate::simulate`] runs a whole campaign offline; the ROS 2 sim nodes drive the same
//! components step by step. Everything is deterministic for a given seed.

pub mod controller;
pub mod effects;
pub mod inject;
pub mod instruments;
pub mod line_measurement;
pub mod paper;
pub mod plan;
pub mod simulate;
pub mod truth;

pub use inject::{Injection, Sample};
pub use instruments::{BeamLine, Deflector, Interferometer, Tracer, VirtualMachine};
pub use plan::{Acquisition, Method, Plan};
pub use simulate::{simulate, EnvironmentSim, SimConfig, SimOutput, Truth};
pub use truth::{random_truth, TruthSpec};
