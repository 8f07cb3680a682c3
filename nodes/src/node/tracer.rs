//! The laser-tracer node: latches a relative range on each range trigger from the sequencer
//! (`/tracer/range`, tagged with the trigger id), like the interferometer node does abscissae.
//! The station comes with the trigger: the sequencer knows where the operator set the tracer.
//!
//! Parameters: `backend` (sim, or line: `device`, `reply_timeout_s`, see
//! [`crate::backend::line`]), `latch_timeout_s` (1.0), and for the sim backend `machine`,
//! `plan` (a tracer plan: its stations are the tracer's positions), `seed`.

use super::latch::PendingTriggers;
use super::runtime::{backend, TICK};
use crate::backend::sim::{SimTracer, SimWorld};
use crate::backend::TracerBackend;
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::Result;
use volcal_bag::convert::{self, info_to_msg};
use volcal_msgs::msg::{InterferometerInfo, ReflectorTruth, TracerRange, Trigger};
use volcal_msgs::std_msgs::msg::Header;
use volcal_msgs::topics;

pub fn run(node: &mut RosNode) -> Result<()> {
    if backend(node, &["sim", "line"])? == "line" {
        let link = crate::backend::line::open_from_args(&node.args)?;
        return run_with(node, crate::backend::line::LineTracer::new(link)?);
    }
    let world = SimWorld::from_args(&node.args)?;
    let backend = SimTracer::new(&world)?;
    run_with(node, backend)
}

/// The node loop over any backend.
pub fn run_with<B: TracerBackend>(node: &mut RosNode, mut backend: B) -> Result<()> {
    let latch_timeout = (node.args.get_or("latch_timeout_s", 1.0)? * 1e9) as i64;
    node.warn_unused_parameters();
    let mut triggers = node.subscription::<Trigger>(topics::TRIGGER, qos::commands())?;
    let mut truth = if backend.simulated() {
        Some(node.subscription::<ReflectorTruth>(topics::TRUTH_REFLECTOR, qos::truth())?)
    } else {
        None
    };
    let out = node.publisher::<TracerRange>(topics::TRACER_RANGE, qos::data())?;
    let info = node.publisher::<InterferometerInfo>(topics::INTERFEROMETER_INFO, qos::latched())?;
    info.publish(info_to_msg(&backend.info(), now_ns())).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut pending = PendingTriggers::new(Trigger::KIND_RANGE, latch_timeout);
    let mut published = 0u64;
    while !shutdown::requested() {
        node.wait(TICK);
        if let Some(refl) = &mut truth {
            while let Some(r) = refl.next() {
                backend.truth(&convert::reflector_truth(&r));
            }
        }
        let now = now_ns();
        pending.take_from(&mut triggers, now);
        pending.service(now, |t| {
            backend.new_station(t.station);
            let Some(r) = backend.read(now, Some(t.point), Some(t.position_id))? else { return Ok(false) };
            out.publish(TracerRange {
                header: Header::at(now, &format!("tracer/{}", t.station)),
                station: t.station,
                path: t.line,
                range_m: r.value_m,
                signal_strength: r.signal_strength,
                beam_broken: r.beam_broken,
                trigger_id: t.trigger_id,
            })
            .map_err(|e| anyhow::anyhow!("publish {}: {e:?}", topics::TRACER_RANGE))?;
            published += 1;
            Ok(true)
        })?;
    }
    log::info!("published {published} ranges");
    Ok(())
}
