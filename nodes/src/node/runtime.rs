//! What every node loop shares: start-up (logging, signals, arguments), the `backend`
//! parameter, and loop timing.

use crate::ros::node::init_logging;
use crate::ros::{shutdown, NodeArgs, RosNode};
use anyhow::{bail, Result};
use std::process::ExitCode;

/// A node's entry point.
pub type NodeMain = fn(&mut RosNode) -> Result<()>;

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
    backend(node, &["sim"]).map(drop)
}

/// The `backend` parameter (default `sim`), one of `available`.
pub fn backend(node: &RosNode, available: &[&str]) -> Result<String> {
    let b: String = node.args.get_or("backend", "sim".to_string())?;
    if !available.contains(&b.as_str()) {
        bail!(
            "parameter backend: {b:?} is not available in this build for this node (only {}); a hardware backend implements the traits in crate::backend",
            available.iter().map(|a| format!("{a:?}")).collect::<Vec<_>>().join(", ")
        );
    }
    Ok(b)
}

/// Sleep granularity of node loops when nothing arrives.
pub const TICK: std::time::Duration = std::time::Duration::from_millis(5);

/// Seconds as a duration, from a parameter value.
pub fn secs(s: f64) -> std::time::Duration {
    std::time::Duration::from_secs_f64(s.max(0.0))
}
