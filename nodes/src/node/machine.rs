//! The machine node: executes motion commands from `/machine/command` and publishes the
//! indicated coordinates on `/machine/position`: at `rate_hz` while moving, at `idle_rate_hz`
//! at rest, once on reaching each target (`in_position`), and latched on each trigger
//! (`trigger_id`). With `batch` > 1, the samples while moving go out batched on
//! `/machine/position_batch` instead (for rates above about 1 kHz). The sim backend publishes
//! the actual reflector position on `/sim/truth/reflector` alongside.
//!
//! Parameters: `backend` (sim), `rate_hz` (100), `idle_rate_hz` (2), `batch` (1), and for the
//! sim backend `machine`, `seed`.

use super::{check_backend, secs, TICK};
use crate::backend::sim::{SimMachine, SimWorld};
use crate::backend::{MachineBackend, MachineState, MotionCommand, Truth};
use crate::pairing::trigger_type;
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::{anyhow, bail, Result};
use nalgebra::{Point3, Vector3};
use volcal_msgs::msg::{MachineCommand, MachinePosition, MachinePositionBatch, ReflectorTruth, Trigger};
use volcal_msgs::std_msgs::msg::Header;
use volcal_msgs::topics;

pub fn run(node: &mut RosNode) -> Result<()> {
    check_backend(node)?;
    let world = SimWorld::from_args(&node.args)?;
    run_with(node, SimMachine::new(&world, now_ns()), true)
}

fn position_msg(stamp: i64, s: &MachineState, trigger_id: u64) -> MachinePosition {
    MachinePosition {
        header: Header::at(stamp, "machine"),
        x_m: s.position.x,
        y_m: s.position.y,
        z_m: s.position.z,
        probe_offset_m: s.probe_offset.into(),
        velocity_mps: s.velocity.into(),
        in_position: s.in_position,
        position_id: s.position_id,
        trigger_id,
    }
}

/// The node loop over any backend; `simulated` publishes the reflector truth.
pub fn run_with<B: MachineBackend>(node: &mut RosNode, mut backend: B, simulated: bool) -> Result<()> {
    let rate: f64 = node.args.get_or("rate_hz", 100.0)?;
    let idle_rate: f64 = node.args.get_or("idle_rate_hz", 2.0)?;
    let batch: usize = node.args.get_or("batch", 1)?;
    if !(rate > 0.0 && idle_rate > 0.0) || batch == 0 {
        bail!("parameters rate_hz ({rate}), idle_rate_hz ({idle_rate}) and batch ({batch}) must be positive");
    }
    node.warn_unused_parameters();
    let commands = node.subscription::<MachineCommand>(topics::MACHINE_COMMAND, qos::commands())?;
    let triggers = node.subscription::<Trigger>(topics::TRIGGER, qos::commands())?;
    let out = node.publisher::<MachinePosition>(topics::MACHINE_POSITION, qos::data())?;
    let out_batch = if batch > 1 {
        Some(node.publisher::<MachinePositionBatch>(topics::MACHINE_POSITION_BATCH, qos::data())?)
    } else {
        None
    };
    let truth =
        if simulated { Some(node.publisher::<ReflectorTruth>(topics::TRUTH_REFLECTOR, qos::data())?) } else { None };
    let publish_truth = |backend: &mut B, now: i64| -> Result<()> {
        if let (Some(t), Some(Truth::Reflector { stamp_ns, position_id, settled, actual, velocity })) =
            (&truth, backend.truth(now))
        {
            t.publish(ReflectorTruth {
                header: Header::at(stamp_ns, "machine"),
                position_id,
                settled,
                actual_m: actual.coords.into(),
                velocity_mps: velocity.into(),
            })
            .map_err(|e| anyhow!("publish {}: {e:?}", topics::TRUTH_REFLECTOR))?;
        }
        Ok(())
    };
    let moving_ns = (1e9 / rate) as i64;
    let idle_ns = (1e9 / idle_rate) as i64;
    let mut next_idle = now_ns();
    let mut next_sample = now_ns();
    let mut last: Option<MachineState> = None;
    let mut acc = MachinePositionBatch::default();
    let flush = |acc: &mut MachinePositionBatch| -> Result<()> {
        if let Some(pb) = &out_batch {
            if !acc.x_m.is_empty() {
                pb.publish(std::mem::take(acc)).map_err(|e| anyhow!("publish batch: {e:?}"))?;
            }
        }
        Ok(())
    };
    while !shutdown::requested() {
        let moving = last.is_some_and(|l| !l.in_position);
        let mut due = if moving { next_sample } else { next_idle };
        if let Some(t) = backend.next_change_ns().filter(|t| *t > now_ns() - 1_000_000) {
            due = due.min(t);
        }
        node.wait(secs((due - now_ns()) as f64 * 1e-9).min(TICK));
        while let Ok(Some((c, _))) = commands.take() {
            let target = Point3::new(c.x_m, c.y_m, c.z_m);
            let now = now_ns();
            if let Some(l) = &last {
                if l.position_id == c.position_id && l.position == target && l.in_position {
                    // A repeated command for where the machine already is: report again.
                    last = None;
                    continue;
                }
            }
            backend.move_to(
                &MotionCommand {
                    position_id: c.position_id,
                    target,
                    probe_offset: Vector3::from(c.probe_offset_m),
                    speed_mps: c.speed_mps,
                },
                now,
            )?;
            next_sample = now;
        }
        let now = now_ns();
        let s = backend.state(now);
        let arrived = s.in_position && last.is_none_or(|l| !l.in_position || l.position_id != s.position_id);
        if !s.in_position {
            // Samples at the fixed rate, stamped at their sampling instants.
            if next_sample < now - 100 * moving_ns {
                next_sample = now;
            }
            while next_sample <= now {
                let sk = backend.state(next_sample);
                if out_batch.is_some() {
                    if acc.x_m.is_empty() {
                        acc.header = Header::at(next_sample, "machine");
                        acc.sample_period_s = moving_ns as f64 * 1e-9;
                        acc.probe_offset_m = sk.probe_offset.into();
                        acc.position_id = sk.position_id;
                    }
                    acc.x_m.push(sk.position.x);
                    acc.y_m.push(sk.position.y);
                    acc.z_m.push(sk.position.z);
                    if acc.x_m.len() >= batch {
                        flush(&mut acc)?;
                    }
                } else {
                    out.publish(position_msg(next_sample, &sk, 0))
                        .map_err(|e| anyhow!("publish {}: {e:?}", topics::MACHINE_POSITION))?;
                }
                next_sample += moving_ns;
            }
            publish_truth(&mut backend, now)?;
            last = Some(s);
        } else if arrived || now >= next_idle {
            flush(&mut acc)?;
            // Truth first, so that the simulated instruments know where the reflector is when
            // the sequencer reacts to the in-position message.
            publish_truth(&mut backend, now)?;
            out.publish(position_msg(now, &s, 0))
                .map_err(|e| anyhow!("publish {}: {e:?}", topics::MACHINE_POSITION))?;
            next_idle = now + idle_ns;
            last = Some(s);
        }
        while let Ok(Some((t, _))) = triggers.take() {
            if t.trigger_type != trigger_type::POINT && t.trigger_type != trigger_type::PROBE {
                continue;
            }
            // Latch the coordinates at the trigger.
            let now = now_ns();
            let s = backend.state(now);
            out.publish(position_msg(now, &s, t.trigger_id))
                .map_err(|e| anyhow!("publish {}: {e:?}", topics::MACHINE_POSITION))?;
        }
    }
    Ok(())
}
