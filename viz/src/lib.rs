//! # volcal_viz: Rerun visualisation
//!
//! What a calibration engineer looks at: the working volume with the stations and beams, the
//! residuals of the fit (where, how large, per beam), the 18 error functions and squareness
//! with their uncertainty, and the volumetric error map. Offline (`volcal solve --rerun`) or
//! live (the `viz` node), saved to `.rrd`, streamed to a running viewer, or to a spawned one.
//!
//! The API is a set of functions taking plain data (observations, per-reading values, an
//! error model and covariance) and an entity root, so that other commands add their views by
//! calling them with their own data; e.g. a diagnosis logs the residuals before and after an
//! effect and the effect's signature with [`residuals::log_line_series`] under its own roots,
//! and places them with the building blocks of [`blueprint`].
//!
//! - [`paths`]: entity paths and timeline names (the tree the user sees).
//! - [`scene`]: machine volume and axes, stations, beam lines, indicated and actual points.
//! - [`residuals`]: per-reading series per line, per-line RMS bar charts.
//! - [`error_functions`]: the 18 functions and squareness over axis position with bands.
//! - [`volumetric`]: the volumetric error map as scaled, coloured arrows, the maximum marked.
//! - [`solve`]: everything `volcal solve --rerun` logs, and its summary text.
//! - [`diagnosis`]: what `volcal diagnose --rerun` adds: residuals before and after, each
//!   named effect's signature, the report.
//! - [`live`]: the live view of a running campaign (the `viz` node), fed with plain data.
//! - [`blueprint`]: default layouts, so that the first screen is useful; [`layout`]: the
//!   blueprint builder they use.
//! - [`colors`], [`geometry`]: colour scales; display-only geometric reductions.
//! - [`rerun`]: the part of the Rerun SDK these use.

pub mod blueprint;
pub mod colors;
pub mod diagnosis;
pub mod error_functions;
pub mod geometry;
pub mod layout;
pub mod live;
pub mod paths;
pub mod rerun;
pub mod residuals;
pub mod scene;
pub mod solve;
pub mod volumetric;

use anyhow::{bail, Context, Result};
use std::path::PathBuf;

pub use crate::rerun::RecordingStream;

/// Rerun application id of everything volcal logs (the viewer groups recordings by it).
pub const APP_ID: &str = "volcal";

/// Default gRPC address of a Rerun viewer (`rerun` listens there by default).
pub const DEFAULT_CONNECT_ADDR: &str = "rerun+http://127.0.0.1:9876/proxy";

/// Where to send a recording: the `--rerun*` flags shared by `volcal solve`, `volcal diagnose`
/// and the `viz` node. Several may be given at once (e.g. watch live and save).
#[derive(clap::Args, Clone, Debug, Default, PartialEq)]
pub struct RerunArgs {
    /// Save a Rerun recording to this file (.rrd).
    #[arg(long = "rerun", value_name = "FILE.rrd")]
    pub save: Option<PathBuf>,
    /// Stream to a running Rerun viewer over gRPC [default address: rerun+http://127.0.0.1:9876/proxy].
    #[arg(long = "rerun-connect", value_name = "ADDR", num_args = 0..=1, default_missing_value = DEFAULT_CONNECT_ADDR)]
    pub connect: Option<String>,
    /// Start a Rerun viewer (the `rerun` executable on PATH) and stream to it.
    #[arg(long = "rerun-spawn")]
    pub spawn: bool,
}

impl RerunArgs {
    /// Whether any Rerun output was asked for.
    pub fn enabled(&self) -> bool {
        self.save.is_some() || self.connect.is_some() || self.spawn
    }

    /// Checks the flags without opening anything (the file name, the address), so that a
    /// command can refuse bad flags before doing its work.
    pub fn validate(&self) -> Result<()> {
        if let Some(path) = &self.save {
            if path.extension().and_then(|e| e.to_str()) != Some("rrd") {
                bail!("--rerun {}: the recording file must end in .rrd", path.display());
            }
        }
        if let Some(addr) = &self.connect {
            grpc_sink(addr).with_context(|| format!("--rerun-connect {addr}"))?;
        }
        Ok(())
    }

    /// Opens a recording named `name` with the default layout `layout`, or `None` when no
    /// Rerun output was asked for. Errors say which flag failed.
    pub fn open(&self, name: &str, layout: &layout::Layout) -> Result<Option<RecordingStream>> {
        if !self.enabled() {
            return Ok(None);
        }
        self.validate()?;
        let mut sinks: Vec<Box<dyn crate::rerun::sink::LogSink>> = Vec::new();
        if let Some(path) = &self.save {
            let sink = crate::rerun::sink::FileSink::new(path)
                .with_context(|| format!("--rerun {}: cannot create the recording file", path.display()))?;
            sinks.push(Box::new(sink));
        }
        if let Some(addr) = &self.connect {
            sinks.push(Box::new(grpc_sink(addr).with_context(|| format!("--rerun-connect {addr}"))?));
        }
        if self.spawn {
            let info = crate::rerun::spawn(&crate::rerun::SpawnOptions::default()).context(
                "--rerun-spawn: cannot start the Rerun viewer (is `rerun` on PATH? `pip install rerun-sdk==0.36.3`)",
            )?;
            sinks.push(Box::new(grpc_sink(&format!("rerun+http://127.0.0.1:{}/proxy", info.port))?));
        }
        let rec = crate::rerun::RecordingStreamBuilder::new(APP_ID)
            .recording_name(name)
            .set_sinks(sinks)
            .context("cannot open the Rerun recording")?;
        layout.send(&rec, APP_ID).context("cannot send the Rerun layout")?;
        Ok(Some(rec))
    }
}

/// A gRPC sink towards `addr`, accepting `host:port` as a shorthand for the proxy URL.
fn grpc_sink(addr: &str) -> Result<crate::rerun::sink::GrpcSink> {
    let url = if addr.contains("://") { addr.to_string() } else { format!("rerun+http://{addr}/proxy") };
    let uri = url.parse().map_err(|e| {
        anyhow::anyhow!(
            "{url:?} is not a Rerun gRPC address ({e}); expected e.g. {DEFAULT_CONNECT_ADDR} or 127.0.0.1:9876"
        )
    })?;
    Ok(crate::rerun::sink::GrpcSink::new(uri))
}
