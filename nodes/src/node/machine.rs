//! The machine node: executes motion commands from `/machine/command` and publishes the
//! indicated coordinates on `/machine/position`: at `rate_hz` while moving, at `idle_rate_hz`
//! at rest, once on reaching each target (`in_position`), and latched on each trigger
//! (`trigger_id`). With `batch` > 1, the samples go out batched on `/machine/position_batch`
//! instead (for rates above about 1 kHz; arrivals as a batch of one with `in_position`), so
//! that they stay in stamp order on one topic; latched coordinates stay on
//! `/machine/position`. The sim backend publishes
//! the actual reflector position on `/sim/truth/reflector` alongside.
//!
//! Parameters: `backend` (sim, or ros2_control: see [`super::machine_cell`]), `rate_hz` (100), `idle_rate_hz` (2), `batch` (1), and for the
//! sim backend `machine`, `seed`, `inject`, `time_scale`, `truth` (a path: the true error model
//! and the injected effects are written there; empty: none). See [`crate::backend::injected`].

use super::runtime::{check_backend, secs, TICK};
use crate::backend::sim::{SimMachine, SimWorld};
use crate::backend::{MachineBackend, MachineState, MotionCommand, Truth};
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::{anyhow, bail, Result};
use nalgebra::{Point3, Vector3};
use volcal_bag::pairing::trigger_type;
use volcal_msgs::msg::{MachineCommand, MachinePosition, MachinePositionBatch, ReflectorTruth, Trigger};
use volcal_msgs::std_msgs::msg::Header;
use volcal_msgs::topics;

pub fn run(node: &mut RosNode) -> Result<()> {
    // A ros2_control cell has its own loop: its coordinates arrive, they are not polled.
    if node.args.get_or("backend", String::new())? == "ros2_control" {
        return super::machine_cell::run(node);
    }
    check_backend(node)?;
    let world = SimWorld::from_args(&node.args)?;
    if let Some(path) = node.args.path("truth")? {
        world.write_truth(&path)?;
        log::info!("wrote the simulated machine's truth to {}", path.display());
    }
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
    let mut commands = node.subscription::<MachineCommand>(topics::MACHINE_COMMAND, qos::commands())?;
    let mut triggers = node.subscription::<Trigger>(topics::TRIGGER, qos::commands())?;
    let out = node.publisher::<MachinePosition>(topics::MACHINE_POSITION, qos::data())?;
    let out_batch = if batch > 1 {
        Some(node.publisher::<MachinePositionBatch>(topics::MACHINE_POSITION_BATCH, qos::data())?)
    } else {
        None
    };
    let truth =
        if simulated { Some(node.publisher::<ReflectorTruth>(topics::TRUTH_REFLECTOR, qos::truth())?) } else { None };
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
    // The simulated instruments interpolate the reflector truth in time: it is published on a
    // grid at `rate_hz` whether or not the machine moves, and at the corners of each motion.
    let mut truth_grid = TruthGrid { next_ns: if simulated { now_ns() } else { i64::MAX }, period_ns: moving_ns };
    let publish_truth_grid = |backend: &mut B, grid: &mut TruthGrid, until_ns: i64| -> Result<()> {
        grid.due(until_ns).into_iter().try_for_each(|t| publish_truth(backend, t))
    };
    let idle_ns = (1e9 / idle_rate) as i64;
    let mut next_idle = now_ns();
    let mut next_sample = now_ns();
    let mut motion_end: Option<i64> = None;
    let mut last: Option<MachineState> = None;
    let mut acc = MachinePositionBatch::default();
    // Sends a sample: batched samples and single ones must travel on one topic to stay in
    // stamp order, so with batching on, a corner sample is a batch of one.
    let emit = |stamp: i64, s: &MachineState, acc: &mut MachinePositionBatch, single: bool| -> Result<()> {
        match &out_batch {
            None => out
                .publish(position_msg(stamp, s, 0))
                .map_err(|e| anyhow!("publish {}: {e:?}", topics::MACHINE_POSITION)),
            Some(pb) => {
                // A batch's samples are stamped `header + i * sample_period`: a sample that
                // does not fall on that grid (the node fell behind and skipped ahead, or a
                // corner) starts a new batch, or its coordinates would carry a wrong stamp.
                let on_grid = acc.header.stamp.to_nanos() + acc.x_m.len() as i64 * moving_ns == stamp;
                if (single || !on_grid) && !acc.x_m.is_empty() {
                    pb.publish(std::mem::take(acc)).map_err(|e| anyhow!("publish batch: {e:?}"))?;
                }
                if acc.x_m.is_empty() {
                    acc.header = Header::at(stamp, "machine");
                    acc.sample_period_s = moving_ns as f64 * 1e-9;
                    acc.probe_offset_m = s.probe_offset.into();
                    acc.position_id = s.position_id;
                }
                acc.x_m.push(s.position.x);
                acc.y_m.push(s.position.y);
                acc.z_m.push(s.position.z);
                if single || acc.x_m.len() >= batch {
                    acc.in_position = s.in_position;
                    pb.publish(std::mem::take(acc)).map_err(|e| anyhow!("publish batch: {e:?}"))?;
                }
                Ok(())
            }
        }
    };
    while !shutdown::requested() {
        let moving = last.is_some_and(|l| !l.in_position);
        let mut due = (if moving { next_sample } else { next_idle }).min(truth_grid.next_ns);
        if let Some(t) = motion_end.filter(|t| *t > now_ns() - 1_000_000) {
            due = due.min(t);
        }
        node.wait(secs((due - now_ns()) as f64 * 1e-9).min(TICK));
        // Segment triggers before commands: the sequencer starts a segment before its run.
        let mut latch = Vec::new();
        while let Some(t) = triggers.next() {
            if t.trigger_type == trigger_type::SEGMENT_START || t.trigger_type == trigger_type::SEGMENT_END {
                backend.on_the_fly(t.trigger_type == trigger_type::SEGMENT_START);
            } else if t.trigger_type == trigger_type::POINT || t.trigger_type == trigger_type::PROBE {
                latch.push(t);
            }
        }
        while let Some(c) = commands.next() {
            let target = Point3::new(c.x_m, c.y_m, c.z_m);
            let now = now_ns();
            if let Some(l) = &last {
                if l.position_id == c.position_id && l.position == target && l.in_position {
                    // A repeated command for where the machine already is: report again.
                    last = None;
                    continue;
                }
            }
            if simulated {
                // The truth up to this corner (short of an arrival not yet reported), while the
                // backend still plays the motion before it.
                let pending_arrival = motion_end.filter(|t| *t <= now && last.is_some_and(|l| !l.in_position));
                publish_truth_grid(&mut backend, &mut truth_grid, pending_arrival.unwrap_or(now) - 1)?;
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
            // The motion starts now: a sample at this corner (where the reported coordinates
            // start), then samples at the fixed rate.
            let corner = backend.start_corner_ns(now);
            let s0 = backend.state(corner);
            if simulated {
                publish_truth(&mut backend, now)?;
                // The grid resumes after this corner: the truth goes out in stamp order.
                truth_grid.resume_after(now);
            }
            if !s0.in_position {
                // (A motion of zero length has only its arrival corner.)
                emit(corner, &s0, &mut acc, true)?;
            }
            next_sample = now + moving_ns;
            motion_end = backend.next_change_ns();
            last = Some(MachineState { in_position: false, ..s0 });
        }
        let now = now_ns();
        let s = backend.state(now);
        let was_moving = last.is_some_and(|l| !l.in_position);
        let arrived = s.in_position && last.is_none_or(|l| !l.in_position || l.position_id != s.position_id);
        // The instant the target was reached (the controller knows it; the sim computes it).
        let arrival = motion_end.filter(|t| *t <= now).unwrap_or(now);
        if was_moving {
            if next_sample < now - 100 * moving_ns {
                next_sample = now;
            }
            let until = if arrived { arrival - 1 } else { now };
            while next_sample <= until {
                let sk = backend.state(next_sample);
                emit(next_sample, &sk, &mut acc, false)?;
                next_sample += moving_ns;
            }
        }
        if arrived {
            // The arrival corner, stamped when it happened; truth first, so that the simulated
            // instruments know where the reflector is when the sequencer reacts to it.
            let sa = backend.state(arrival);
            if simulated {
                publish_truth_grid(&mut backend, &mut truth_grid, arrival - 1)?;
                publish_truth(&mut backend, arrival)?;
            }
            emit(arrival, &sa, &mut acc, true)?;
            next_idle = now + idle_ns;
            last = Some(sa);
        } else if s.in_position && now >= next_idle {
            emit(now, &s, &mut acc, true)?;
            next_idle = now + idle_ns;
            last = Some(s);
        } else if !s.in_position {
            last = Some(s);
        }
        if simulated {
            publish_truth_grid(&mut backend, &mut truth_grid, now)?;
        }
        for t in latch {
            // Latch the coordinates at the trigger.
            let now = now_ns();
            let s = backend.state(now);
            out.publish(position_msg(now, &s, t.trigger_id))
                .map_err(|e| anyhow!("publish {}: {e:?}", topics::MACHINE_POSITION))?;
        }
    }
    Ok(())
}

/// The stamps at which the simulated machine publishes its reflector truth: a fixed grid,
/// published retroactively when the loop was late. The simulated instruments interpolate
/// between consecutive truth samples; a sample published only where the loop woke would leave
/// them a chord across the stall (49 ms at 2 m/s is 98 mm of path, whose curvature the readings
/// then carry as a false step of a few tenths of a micrometre at the next stop).
struct TruthGrid {
    next_ns: i64,
    period_ns: i64,
}

impl TruthGrid {
    /// After a stall of more than this many periods the grid restarts where the loop is.
    const MAX_CATCH_UP: i64 = 1000;

    /// The grid stamps up to `until_ns`, in order; the grid then waits for the next one.
    fn due(&mut self, until_ns: i64) -> Vec<i64> {
        if self.next_ns < until_ns - Self::MAX_CATCH_UP * self.period_ns {
            self.next_ns = until_ns;
        }
        let mut stamps = Vec::new();
        while self.next_ns <= until_ns {
            stamps.push(self.next_ns);
            self.next_ns += self.period_ns;
        }
        stamps
    }

    /// A corner was published at `corner_ns`: the grid resumes a period after it, so that the
    /// truth goes out in stamp order.
    fn resume_after(&mut self, corner_ns: i64) {
        self.next_ns = self.next_ns.max(corner_ns + self.period_ns);
    }
}

#[cfg(test)]
mod tests {
    use super::TruthGrid;

    #[test]
    fn a_late_loop_publishes_the_truth_grid_it_missed() {
        let mut g = TruthGrid { next_ns: 0, period_ns: 500_000 };
        assert_eq!(g.due(1_200_000), vec![0, 500_000, 1_000_000]);
        // A stall of 49 ms: every grid stamp in it, none twice, none ahead of the loop.
        let late = g.due(50_200_000);
        assert_eq!(late.len(), 98);
        assert_eq!(late.first(), Some(&1_500_000));
        assert!(late.windows(2).all(|w| w[1] - w[0] == 500_000));
        assert!(g.due(50_400_000).is_empty());
        // A corner between grid stamps: nothing stamped before it goes out after it.
        g.resume_after(50_700_000);
        assert_eq!(g.due(51_200_000), vec![51_200_000]);
        // Beyond the catch-up limit the grid restarts where the loop is.
        let long = g.due(51_200_000 + 2_000 * 500_000);
        assert_eq!(long, vec![51_200_000 + 2_000 * 500_000]);
    }
}
