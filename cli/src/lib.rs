//! # volcal_cli: the `volcal` command-line tool
//!
//! Each subcommand is a function here that takes argument values, calls the libraries below and
//! prints or writes files; `main.rs` only parses the command line. Nothing below calls back into
//! this crate.
//!
//! - [`commands`]: `simulate`, `solve`, `predict`, `map`, `report`, `demo` (the offline half).
//! - [`diagnosis`]: `volcal diagnose` (reads the campaign; the diagnosis, its JSON and report are
//!   `volcal_formats::diagnosing` and `diagnosis_file`, shared with the replay node).
//! - [`export_cmd`]: `volcal export` (compensation files a controller loads).
//! - [`iso230_2_cmd`]: `volcal iso230-2` (a positioning test evaluated to ISO 230-2), drawn by
//!   [`iso230_2_plot`] on a [`raster`].
//! - [`validation`], [`paper_cmd`]: `volcal validate` and `volcal paper` (Han et al. 2021).
//! - [`launch_cmd`]: `volcal launch`, `volcal bag info`, `volcal report BAG`.
//! - [`bench`]: `volcal bench` (throughput of the recording chain).
//! - [`demo_chain`]: the node-set half of `volcal demo`.

pub mod bench;
pub mod commands;
pub mod demo_chain;
pub mod diagnosis;
pub mod export_cmd;
pub mod iso230_2_cmd;
pub mod iso230_2_plot;
pub mod launch_cmd;
pub mod paper_cmd;
pub mod raster;
pub mod validation;
