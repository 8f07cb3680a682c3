//! The beam deflector node: points the beam on `/deflector/command` and reports on
//! `/deflector/state` (transient-local, so a node that starts late knows the current beam),
//! first unsettled, then settled. The sim backend also publishes the actual beam on
//! `/sim/truth/beam` (for the simulated interferometer only).
//!
//! Parameters: `backend` (sim), and for the sim backend `machine`, `seed`, `settle_s` (default:
//! the machine file's deflector settling time).

use super::runtime::{check_backend, TICK};
use crate::backend::sim::{SimDeflector, SimWorld};
use crate::backend::DeflectorBackend;
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::{anyhow, Result};
use nalgebra::Point3;
use volcal_msgs::msg::{BeamCommand, BeamState};
use volcal_msgs::std_msgs::msg::Header;
use volcal_msgs::topics;

pub fn run(node: &mut RosNode) -> Result<()> {
    check_backend(node)?;
    let world = SimWorld::from_args(&node.args)?;
    let settle: Option<f64> = node.args.get("settle_s")?;
    run_with(node, SimDeflector::new(&world, settle), true)
}

/// The node loop over any backend; `simulated` publishes the truth beam.
pub fn run_with<B: DeflectorBackend>(node: &mut RosNode, mut backend: B, simulated: bool) -> Result<()> {
    node.warn_unused_parameters();
    let mut commands = node.subscription::<BeamCommand>(topics::DEFLECTOR_COMMAND, qos::commands())?;
    let state = node.publisher::<BeamState>(topics::DEFLECTOR_STATE, qos::latched())?;
    let truth = if simulated { Some(node.publisher::<BeamState>(topics::TRUTH_BEAM, qos::latched())?) } else { None };
    let mut current: Option<BeamCommand> = None;
    let mut reported_settled = false;
    while !shutdown::requested() {
        let until_change = backend.next_change_ns().map(|t| t - now_ns()).filter(|d| *d > 0);
        node.wait(until_change.map_or(TICK, |d| TICK.min(std::time::Duration::from_nanos(d as u64))));
        while let Some(c) = commands.next() {
            let same = current.as_ref().is_some_and(|o| {
                (o.station, o.beam, o.azimuth_rad, o.elevation_rad)
                    == (c.station, c.beam, c.azimuth_rad, c.elevation_rad)
            });
            if same {
                // A repeated command (the sequencer retrying): keep the beam, report it again.
                reported_settled = false;
                continue;
            }
            backend.command(Point3::from(c.device_position_m), c.azimuth_rad, c.elevation_rad, now_ns())?;
            log::debug!(
                "station {} beam {}: azimuth {:.4} rad, elevation {:.4} rad",
                c.station,
                c.beam,
                c.azimuth_rad,
                c.elevation_rad
            );
            current = Some(c);
            reported_settled = false;
            publish_state(&state, &mut backend, current.as_ref().unwrap())?;
        }
        if let Some(c) = &current {
            let now = now_ns();
            if !reported_settled && backend.readback(now).settled {
                if let (Some(t), Some((o, d))) = (&truth, backend.truth_beam(now)) {
                    t.publish(BeamState {
                        header: Header::at(now, "machine"),
                        station: c.station,
                        beam: c.beam,
                        azimuth_rad: c.azimuth_rad,
                        elevation_rad: c.elevation_rad,
                        settled: true,
                        geometry_known: true,
                        origin_m: o.coords.into(),
                        direction: d.into(),
                    })
                    .map_err(|e| anyhow!("publish {}: {e:?}", topics::TRUTH_BEAM))?;
                }
                publish_state(&state, &mut backend, c)?;
                reported_settled = true;
            }
        }
    }
    Ok(())
}

fn publish_state<B: DeflectorBackend>(
    pub_: &ros2_client::Publisher<BeamState>,
    backend: &mut B,
    c: &BeamCommand,
) -> Result<()> {
    let now = now_ns();
    let r = backend.readback(now);
    let (origin, dir) = r.geometry.map(|(o, d)| (o.coords.into(), d.into())).unwrap_or(([0.0; 3], [0.0; 3]));
    pub_.publish(BeamState {
        header: Header::at(now, "machine"),
        station: c.station,
        beam: c.beam,
        azimuth_rad: r.azimuth_rad,
        elevation_rad: r.elevation_rad,
        settled: r.settled,
        geometry_known: r.geometry.is_some(),
        origin_m: origin,
        direction: dir,
    })
    .map_err(|e| anyhow!("publish {}: {e:?}", topics::DEFLECTOR_STATE))
}
