//! The ROS 2 nodes of the node set, one module per node; each binary in `src/bin/` is a
//! one-line `main` that calls [`run`] with the node's function. What every node loop shares
//! (start-up, parameters, timing) is in `runtime`, which the nodes use and which uses none of them.
//!
//! | node | subscribes | publishes |
//! |---|---|---|
//! | [`interferometer`] | `/sequencer/trigger`, `/deflector/state` | `/interferometer/abscissa`, `/interferometer/abscissa_batch`, `/interferometer/info` |
//! | [`tracer`] | `/sequencer/trigger` | `/tracer/range`, `/interferometer/info` |
//! | [`deflector`] | `/deflector/command` | `/deflector/state` |
//! | [`machine`] | `/machine/command`, `/sequencer/trigger` | `/machine/position`, `/machine/position_batch` |
//! | [`machine_cell`] (`backend: ros2_control`) | the above, `/joint_states` | `/machine/position`, `/joint_trajectory_controller/joint_trajectory` |
//! | [`environment`] | | `/environment` |
//! | [`sequencer`] | positions, readings, `/deflector/state`, `/campaign/pairs` | `/deflector/command`, `/machine/command`, `/sequencer/trigger`, `/sequencer/status` |
//! | [`recorder`] | everything above | `/campaign/pairs`; writes the bag |
//! | [`solver`] | (a bag) | `/error_model`, `/diagnosis` (transient-local); writes the model JSON |
//! | [`solver`] with `live: true` ([`live_diagnosis`]) | `/campaign/pairs`, `/interferometer/info`, `/sequencer/status` | `/diagnosis` (partial while the campaign runs), `/error_model` at its end |
//! | [`viz`] | `/campaign/pairs`, positions, `/deflector/*`, `/sequencer/status`, `/diagnosis` | (Rerun: live view, `.rrd`) |
//!
//! The sim backends of the instrument nodes also exchange `/sim/truth/beam` and
//! `/sim/truth/reflector`; no other node reads them.

pub mod deflector;
pub mod environment;
pub mod interferometer;
pub mod latch;
pub mod live_diagnosis;
pub mod machine;
pub mod machine_cell;
pub mod recorder;
pub mod sequencer;
pub mod solver;
pub mod tracer;
pub mod viz;

mod runtime;

pub use runtime::{backend, check_backend, run, run_with_args, secs, NodeMain, TICK};

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
