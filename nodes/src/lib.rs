//! # volcal_nodes: the imperative shell
//!
//! Everything that touches files, the network, clocks or Rerun: the `volcal` command-line tool
//! and the ROS 2 nodes. Each binary parses arguments, loads files, calls the pure core
//! ([`volcal`]) and the simulator ([`volcal_sim`]), and prints.
//!
//! - [`machine`]: the machine file (YAML).
//! - [`campaign_csv`]: the campaign interchange format.
//! - [`model_file`], [`truth_file`]: model and simulation-truth JSON.
//! - [`commands`]: the subcommands as functions.
//! - [`report`]: text summaries.
//! - [`validation`], [`paper_cmd`], [`merge`]: the tracer issue's commands (`volcal validate`,
//!   `volcal paper`, `volcal merge`).
//! - [`viz`]: Rerun visualisation (recorded and live).

pub mod bag_campaign;
pub mod campaign_csv;
pub mod commands;
pub mod machine;
pub mod merge;
pub mod model_file;
pub mod paper_cmd;
pub mod report;
pub mod truth_file;
pub mod validation;
pub mod viz;

/// `volcal <version>` for provenance records.
pub fn software_version() -> String {
    format!("volcal {}", env!("CARGO_PKG_VERSION"))
}
