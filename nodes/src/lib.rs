//! # volcal_nodes: the imperative shell
//!
//! Everything that touches files, the network, clocks or Rerun: the `volcal` command-line tool
//! and the ROS 2 nodes. Each binary parses arguments, loads files, calls the pure core
//! ([`volcal`]) and the simulator ([`volcal_sim`]), and prints.
//!
//! - [`machine`]: the machine file (YAML).
//! - [`campaign_csv`]: the campaign interchange format.
//! - [`model_file`], [`truth_file`]: model and simulation-truth JSON.
//! - [`commands`]: the subcommands as functions; [`diagnosis`]: `volcal diagnose`.
//! - [`report`]: text summaries.
//! - The ROS 2 node set: [`ros`] (plumbing), [`node`] (the nodes), [`backend`] (instrument
//!   backends, simulated or hardware), [`pairing`], [`centring`], [`bag`] and [`bag_campaign`]
//!   (rosbag2 MCAP bags), [`convert`], [`launch`] and [`launch_cmd`] (`volcal launch`, `bag`),
//!   [`bench`] (`volcal bench`), [`demo_chain`] (the node-set half of `volcal demo`).
//! - [`validation`], [`paper_cmd`], [`merge`]: the tracer issue's commands (`volcal validate`,
//!   `volcal paper`, `volcal merge`).
//! - [`viz`]: Rerun visualisation (recorded and live).

pub mod backend;
pub mod bag;
pub mod bag_campaign;
pub mod bench;
pub mod campaign_csv;
pub mod centring;
pub mod commands;
pub mod convert;
pub mod demo_chain;
pub mod diagnosis;
pub mod launch;
pub mod launch_cmd;
pub mod machine;
pub mod merge;
pub mod model_file;
pub mod node;
pub mod pairing;
pub mod paper_cmd;
pub mod report;
pub mod ros;
pub mod truth_file;
pub mod validation;
pub mod viz;

/// `volcal <version>` for provenance records.
pub fn software_version() -> String {
    format!("volcal {}", env!("CARGO_PKG_VERSION"))
}
