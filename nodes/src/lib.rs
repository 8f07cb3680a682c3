//! # volcal_nodes: the ROS 2 node set
//!
//! The ROS 2 runtime and the node loops with their instrument backends. Each node binary
//! (`volcal_interferometer`, `volcal_machine`, ...) is a one-line `main` around [`node`]; the
//! `volcal` tool runs the same loops as `volcal node NAME` and launches them with [`launch`].
//!
//! - [`ros`]: ROS 2 plumbing on `ros2-client` (participant, arguments, QoS, domains, shutdown).
//! - [`node`]: one module per node, and [`node::by_name`], the table `volcal node` and
//!   [`launch`] use.
//! - [`backend`]: the hardware-backend traits of the instrument nodes and their simulated
//!   implementations.
//! - [`centring`]: centring the reflector on the beam, used by the sequencer.
//! - [`launch`]: the ROS 2 YAML launch subset: parsing, processes, respawn, clean stop.
//!
//! Files other than bags come from `volcal_formats`, bags and pairing from `volcal_bag`, the
//! live view from `volcal_viz`. Nothing here is called back by those crates.

pub mod backend;
pub mod centring;
pub mod launch;
pub mod node;
pub mod ros;
