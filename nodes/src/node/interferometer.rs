//! The interferometer node: latches a reading on each beam trigger from the sequencer
//! (`/interferometer/abscissa`, tagged with the trigger id) and, when `rate_hz` > 0, samples
//! freely for on-the-fly acquisition (batched on `/interferometer/abscissa_batch` when
//! `batch` > 1).
//!
//! Parameters: `backend` (sim, or line: `device`, `reply_timeout_s`, see
//! [`crate::backend::line`]), `rate_hz` (0: triggered only), `batch` (1), `latch_timeout_s`
//! (1.0), and for the sim backend `machine`, `plan`, `seed`, `signal_noise` (0.001).

use super::latch::PendingTriggers;
use super::runtime::{backend, secs, TICK};
use crate::backend::sim::{SimInterferometer, SimWorld};
use crate::backend::{InterferometerBackend, LengthReading};
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::{bail, Result};
use volcal_bag::convert::{self, info_to_msg};
use volcal_msgs::msg::{Abscissa, AbscissaBatch, BeamState, InterferometerInfo, ReflectorTruth, Trigger};
use volcal_msgs::std_msgs::msg::Header;
use volcal_msgs::topics;

pub fn run(node: &mut RosNode) -> Result<()> {
    if backend(node, &["sim", "line"])? == "line" {
        let link = crate::backend::line::open_from_args(&node.args)?;
        return run_with(node, crate::backend::line::LineInterferometer::new(link)?);
    }
    let world = SimWorld::from_args(&node.args)?;
    let noise = node.args.get_or("signal_noise", 0.001)?;
    let backend = SimInterferometer::new(&world, noise);
    run_with(node, backend)
}

/// The node loop over any backend.
pub fn run_with<B: InterferometerBackend>(node: &mut RosNode, mut backend: B) -> Result<()> {
    let rate_hz: f64 = node.args.get_or("rate_hz", 0.0)?;
    let batch: usize = node.args.get_or("batch", 1)?;
    let latch_timeout = (node.args.get_or("latch_timeout_s", 1.0)? * 1e9) as i64;
    let max_lag_ns = (node.args.get_or("max_lag_s", 0.5)? * 1e9) as i64;
    if !(rate_hz >= 0.0 && rate_hz.is_finite()) || batch == 0 {
        bail!("parameters rate_hz ({rate_hz}) and batch ({batch}) must be non-negative and positive");
    }
    node.warn_unused_parameters();
    let mut triggers = node.subscription::<Trigger>(topics::TRIGGER, qos::commands())?;
    let mut states = node.subscription::<BeamState>(topics::DEFLECTOR_STATE, qos::latched())?;
    let mut truth = if backend.simulated() {
        Some((
            node.subscription::<BeamState>(topics::TRUTH_BEAM, qos::latched())?,
            node.subscription::<ReflectorTruth>(topics::TRUTH_REFLECTOR, qos::truth())?,
        ))
    } else {
        None
    };
    let out = node.publisher::<Abscissa>(topics::ABSCISSA, qos::data())?;
    let out_batch =
        if batch > 1 { Some(node.publisher::<AbscissaBatch>(topics::ABSCISSA_BATCH, qos::data())?) } else { None };
    let info = node.publisher::<InterferometerInfo>(topics::INTERFEROMETER_INFO, qos::latched())?;
    info.publish(info_to_msg(&backend.info(), now_ns())).map_err(|e| anyhow::anyhow!("{e:?}"))?;

    // The beam ids reported by the deflector, in time: a free-running sample is tagged with the
    // beam of its instant, even if it is computed after the deflector moved on.
    let mut ids_history: Vec<(i64, (u32, u32))> = Vec::new();
    let ids_at =
        |h: &Vec<(i64, (u32, u32))>, t: i64| h.iter().rev().find(|x| x.0 <= t).or(h.first()).map_or((0, 0), |x| x.1);
    let mut pending = PendingTriggers::new(Trigger::KIND_BEAM, latch_timeout);
    let period_ns = if rate_hz > 0.0 { (1e9 / rate_hz) as i64 } else { 0 };
    let mut next_sample = now_ns();
    let mut acc = AbscissaBatch::default();
    let mut published = 0u64;
    let mut skipped = 0u64;
    while !shutdown::requested() {
        let wait = if period_ns > 0 { secs((next_sample - now_ns()) as f64 * 1e-9).min(TICK) } else { TICK };
        node.wait(wait);
        while let Some(s) = states.next() {
            let t = s.header.stamp.to_nanos();
            if ids_history.last().is_none_or(|l| l.1 != (s.station, s.beam)) {
                ids_history.push((t, (s.station, s.beam)));
                if ids_history.len() > 16 {
                    ids_history.remove(0);
                }
            }
            backend.new_beam(s.station, s.beam);
        }
        if let Some((beam, refl)) = &mut truth {
            while let Some(b) = beam.next() {
                backend.truth(&convert::beam_truth(&b));
            }
            while let Some(r) = refl.next() {
                backend.truth(&convert::reflector_truth(&r));
            }
        }
        let now = now_ns();
        for start in pending.take_from(&mut triggers, now) {
            backend.segment_start(start);
        }
        pending.service(now, |t| {
            let Some(r) = backend.read(now, Some(t.point), Some(t.position_id))? else { return Ok(false) };
            out.publish(abscissa(now, ids_at(&ids_history, i64::MAX), &r, t.trigger_id))
                .map_err(|e| anyhow::anyhow!("publish {}: {e:?}", topics::ABSCISSA))?;
            published += 1;
            Ok(true)
        })?;
        if period_ns > 0 {
            while next_sample <= now_ns() {
                let r = backend.read(next_sample, None, None)?;
                let ids = ids_at(&ids_history, next_sample);
                // Not readable yet (the simulated instrument waits for the truth of this instant):
                // retry later; samples more than `max_lag` old are given up.
                let gap = r.is_none() && now_ns() - next_sample > max_lag_ns;
                if r.is_none() && !gap {
                    break;
                }
                // A batch holds consecutive samples of one beam: close it before a gap or a new beam.
                if let Some(pb) = &out_batch {
                    if !acc.abscissa_m.is_empty() && (gap || (acc.station, acc.beam) != ids) {
                        pb.publish(std::mem::take(&mut acc)).map_err(|e| anyhow::anyhow!("publish batch: {e:?}"))?;
                    }
                }
                let Some(r) = r else {
                    skipped += 1;
                    next_sample += period_ns;
                    continue;
                };
                if let Some(pb) = &out_batch {
                    if acc.abscissa_m.is_empty() {
                        acc.header = Header::at(next_sample, &format!("deflector/{}", ids.0));
                        acc.station = ids.0;
                        acc.beam = ids.1;
                        acc.sample_period_s = period_ns as f64 * 1e-9;
                    }
                    acc.abscissa_m.push(r.value_m);
                    acc.signal_strength.push(r.signal_strength as f32);
                    acc.beam_broken.push(r.beam_broken);
                    if acc.abscissa_m.len() >= batch {
                        pb.publish(std::mem::take(&mut acc)).map_err(|e| anyhow::anyhow!("publish batch: {e:?}"))?;
                    }
                } else {
                    out.publish(abscissa(next_sample, ids, &r, 0))
                        .map_err(|e| anyhow::anyhow!("publish {}: {e:?}", topics::ABSCISSA))?;
                }
                published += 1;
                next_sample += period_ns;
            }
        }
    }
    log::info!("published {published} readings");
    if skipped > 0 {
        log::warn!(
            "{skipped} free-running samples were not readable within {} s (no beam, or no reflector position, yet for their instant)",
            max_lag_ns as f64 * 1e-9
        );
    }
    Ok(())
}

fn abscissa(stamp_ns: i64, ids: (u32, u32), r: &LengthReading, trigger_id: u64) -> Abscissa {
    Abscissa {
        header: Header::at(stamp_ns, &format!("deflector/{}", ids.0)),
        station: ids.0,
        beam: ids.1,
        abscissa_m: r.value_m,
        signal_strength: r.signal_strength,
        beam_broken: r.beam_broken,
        trigger_id,
    }
}
