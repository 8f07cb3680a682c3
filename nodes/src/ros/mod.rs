//! ROS 2 plumbing on `ros2-client` (RustDDS): no ROS installation is needed, yet names, type
//! names, QoS and CDR payloads are ROS 2's, so a ROS 2 graph can join.
//!
//! - [`args`]: node command lines in ROS 2's `--ros-args -p name:=value -r from:=to` form.
//! - [`node`]: a node (participant, domain, loopback-only discovery, remaps) and its typed
//!   publishers and subscriptions.
//! - [`qos`]: the QoS profiles of the node set.
//! - [`domain`]: leasing a `ROS_DOMAIN_ID` no other process on this host uses.
//! - [`shutdown`]: SIGINT/SIGTERM as a flag the node loops poll.

pub mod args;
pub mod domain;
pub mod node;
pub mod qos;
pub mod shutdown;

pub use args::NodeArgs;
pub use node::{now_ns, Inbox, RosNode};
