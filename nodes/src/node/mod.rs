//! The ROS 2 nodes of the node set, one module per node; each binary in `src/bin/` is a
//! one-line `main` that calls [`run`] with the node's function.
//!
//! | node | subscribes | publishes |
//! |---|---|---|
//! | [`interferometer`] | `/sequencer/trigger`, `/deflector/state` | `/interferometer/abscissa`, `/interferometer/abscissa_batch`, `/interferometer/info` |
//! | [`tracer`] | `/sequencer/trigger` | `/tracer/range`, `/interferometer/info` |
//! | [`deflector`] | `/deflector/command` | `/deflector/state` |
//! | [`machine`] | `/machine/command`, `/sequencer/trigger` | `/machine/position`, `/machine/position_batch` |
//! | [`environment`] | | `/environment` |
//! | [`sequencer`] | positions, readings, `/deflector/state`, `/campaign/pairs` | `/deflector/command`, `/machine/command`, `/sequencer/trigger`, `/sequencer/status` |
//! | [`recorder`] | everything above | `/campaign/pairs`; writes the bag |
//! | [`solver`] | (a bag) | `/error_model` (transient-local); writes the model JSON |
//! | [`viz`] | `/campaign/pairs`, positions, `/deflector/*`, `/sequencer/status` | (Rerun: live view, `.rrd`) |
//!
//! The sim backends of the instrument nodes also exchange `/sim/truth/beam` and
//! `/sim/truth/reflector`; no other node reads them.

pub mod deflector;
pub mod environment;
pub mod interferometer;
pub mod latch;
pub mod machine;
pub mod recorder;
pub mod sequencer;
pub mod solver;
pub mod tracer;
pub mod viz;

use crate::ros::node::init_logging;
use crate::ros::{shutdown, NodeArgs, RosNode};
use anyhow::{bail, Result};
use std::process::ExitCode;

/// A node's entry point.
pub type NodeMain = fn(&mut RosNode) -> Result<()>;

/// The nodes by executable name (`volcal_interferometer`) or node name (`interferometer`):
/// `(default node name, entry point)`. `volcal node NAME` runs them from the `volcal` binary,
/// which `volcal launch` falls back to when the node binaries were not built.
pub fn by_name(name: &str) -> Option<(&'static str, NodeMain)> {
    let table: [(&'static str, NodeMain); 9] = [
        ("interferometer", interferometer::run),
        ("tracer", tracer::run),
        ("deflector", deflector::run),
        ("machine", machine::run),
        ("environment", environment::run),
        ("sequencer", sequencer::run),
        ("recorder", recorder::run),
        ("solver", solver::run),
        ("viz", viz::run),
    ];
    let short = name.strip_prefix("volcal_").unwrap_or(name);
    table.into_iter().find(|(n, _)| *n == short)
}

/// Runs a node with the process arguments (a node binary's `main`).
pub fn run(default_name: &str, body: NodeMain) -> ExitCode {
    run_with_args(default_name, body, std::env::args().skip(1).collect())
}

/// Runs a node: logging, signal handling, arguments, the node itself; errors end the process
/// with a message and exit status 1.
pub fn run_with_args(default_name: &str, body: NodeMain, args: Vec<String>) -> ExitCode {
    init_logging();
    shutdown::install();
    let r = NodeArgs::parse(&args).and_then(|a| RosNode::new(a, default_name)).and_then(|mut n| {
        log::info!(
            "node {} on ROS_DOMAIN_ID {}{}",
            n.name,
            n.dds.domain_id,
            if n.dds.localhost_only { " (localhost only)" } else { "" }
        );
        body(&mut n)
    });
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            log::error!("{e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The `backend` parameter: only `sim` is built in; hardware backends implement the traits of
/// [`crate::backend`].
pub fn check_backend(node: &RosNode) -> Result<()> {
    let b: String = node.args.get_or("backend", "sim".to_string())?;
    if b != "sim" {
        bail!(
            "parameter backend: {b:?} is not available in this build (only \"sim\"); a hardware backend implements the traits in volcal_nodes::backend"
        );
    }
    Ok(())
}

/// Sleep granularity of node loops when nothing arrives.
pub const TICK: std::time::Duration = std::time::Duration::from_millis(5);

/// Seconds as a duration, from a parameter value.
pub fn secs(s: f64) -> std::time::Duration {
    std::time::Duration::from_secs_f64(s.max(0.0))
}
