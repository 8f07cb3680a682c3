//! # volcal: the pure core
//!
//! Rigid-body error model of three-axis Cartesian machines (CMMs, machine tools, gantry robots)
//! and its identification from laser-interferometer data: the fixed-beam method of patent
//! EP 1 990 605 and the laser-tracer multilateration of Han et al. (2021), in one estimator.
//!
//! The crate is pure: no files, sockets, clocks or global state. The same input gives
//! bit-identical output (faer runs sequentially).
//!
//! Concepts, in the order data flows through them:
//!
//! - [`topology::Topology`] and [`axis::Travel`] describe the machine; [`model::ModelLayout`]
//!   assigns each of the 18 [`functions::ErrorFunction`]s a [`repr::Representation`] and adds the
//!   three [`functions::Squareness`] errors.
//! - [`campaign::Campaign`] holds readings; [`campaign::prepare`] validates them, applies the air
//!   index ([`environment`]) and ISO 1 normalisation, and groups them into lines.
//! - [`estimator::solve`] fits the model under [`gauge::Gauge`] constraints and returns an
//!   [`estimator::Solution`]: coefficients, covariance, residuals, and the
//!   [`identify::Identifiability`] report.
//! - [`predict`] turns a model and covariance into volumetric errors with uncertainty, maps,
//!   maxima and compensation tables.

pub mod alignment;
pub mod axis;
pub mod band;
pub mod beam;
pub mod campaign;
pub mod diagnose;
pub mod environment;
pub mod estimator;
pub mod flexibility;
pub mod functions;
pub mod gauge;
mod halves;
pub mod identify;
pub mod interpolation;
pub mod kinematics;
pub mod misfit;
pub mod model;
mod normal;
mod nullspace;
pub mod open_pairs;
pub mod path;
pub mod predict;
pub mod range;
pub mod repr;
pub mod smoothing;
pub mod station_geometry;
pub mod topology;
pub mod validate;

pub use axis::{Axis, Travel};
pub use campaign::{Campaign, ObsKind, Observations, Reading};
pub use estimator::{solve, NoiseModel, Solution, SolveOptions};
pub use functions::{ErrorFunction, Motion, Squareness};
pub use gauge::Gauge;
pub use model::{ErrorModel, ModelLayout};
pub use repr::Representation;
pub use topology::Topology;
