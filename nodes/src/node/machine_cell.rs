//! The machine node on a `ros2_control` cell (`backend: ros2_control`): motion commands from
//! `/machine/command` become `trajectory_msgs/JointTrajectory` on `trajectory_topic`, and every
//! `sensor_msgs/JointState` on `joint_states_topic` becomes a `/machine/position` sample stamped
//! with the joint state's time (each one while moving, at `idle_rate_hz` at rest, the arrival
//! when the axes have stayed within `position_tolerance_m` of the target for `settle_s`, and
//! the latest coordinates latched on each trigger).
//!
//! A trajectory that the cell does not start to follow (joint states fresh, no axis moved by
//! `position_tolerance_m` half a second after it went out) is taken as lost and sent again
//! from where the cell is: a controller whose subscription matched our writer late drops what
//! was written before. The time limit counts from the first sending, however often the
//! trajectory goes out again. After [`SECOND_WRITER_AFTER`] sendings that the cell has not
//! followed, a second writer is announced on the topic and every trajectory goes out on both:
//! a Fast DDS subscription has been seen (about once in a hundred campaigns under load) never to
//! discover our first writer although it discovered our other endpoints, and a new writer is a
//! new announcement. Captured on the wire (every packet of the domain, in the 4 of 903
//! campaigns under load that needed the second writer): the cell's Fast DDS participant
//! received the first writer's announcement (its SEDP `DATA(w)`, the same bytes as in a passing
//! campaign but for the ports) and acknowledged it, and still its subscription never matched
//! that writer; the second writer's announcement matched. The loss is in the receiving
//! participant's endpoint discovery, where no resending of ours can reach (the announcement
//! counts as delivered); only a new announcement does. The first writer is kept: it may be
//! the one the controller hears. A controller that hears both receives each trajectory twice,
//! a few milliseconds apart; it replaces the first by the second, the same motion from where
//! the axes are.
//!
//! The same loss strikes subscriptions: a cell whose Fast DDS never matched our joint-state
//! subscription sends it nothing. When the cell's joint-state publisher, discovered, has sent
//! no joint state for [`SECOND_READER_AFTER_NS`], a second subscription is announced, and a
//! joint state that reaches both is taken once (by its stamp). The captures showed what the
//! losses share: each announcement the cell had asked us to repair was lost when a later
//! announcement of the same participant reached it first; that order also occurs in passing
//! campaigns.
//!
//! A cell that misbehaves is named: a joint missing from the joint state or reporting NaN, or
//! a target not reached within the motion's time plus `motion_timeout_s`, stops the node with
//! the joint, the topic and the figures. Joint states that stop arriving for `topic_timeout_s`
//! pause the machine (no arrival is reported, the sequencer waits and, past its own timeout,
//! ends the campaign cleanly; the recorder keeps what was recorded); they resume the campaign
//! when they come back.
//!
//! With `dry_run: true` the node also plays the machine's errors for the simulated
//! instruments: the actual reflector position that the machine file's simulated errors give at
//! the coordinates the cell reports, on `/sim/truth/reflector`, so that a whole campaign can be
//! rehearsed on the cell before the optics are mounted; `truth` writes that simulation truth.
//!
//! Parameters: `joint_names` (`x=NAME,y=NAME,z=NAME`, required), `joint_scale`, `joint_sign`,
//! `joint_states_topic` (`/joint_states`), `trajectory_topic`
//! (`/joint_trajectory_controller/joint_trajectory`), `position_tolerance_m` (5e-6), `settle_s`
//! (0.1), `acceleration_mps2` (1.0), `idle_rate_hz` (2), `topic_timeout_s` (2), `motion_timeout_s`
//! (5), `plan` (its acquisition mode chooses the trajectories), `dry_run` (false) with `machine`,
//! `seed` and `truth` (a path; empty: none).

use super::runtime::TICK;
use crate::backend::ros2_control::{trajectory, Arrival, JointMap, MotionLimits};
use crate::backend::sim::{ActualReflector, SimWorld};
use crate::ros::{now_ns, qos, shutdown, Inbox, RosNode};
use anyhow::{anyhow, bail, Result};
use nalgebra::{Point3, Vector3};
use ros2_client::Publisher;
use volcal_bag::pairing::trigger_type;
use volcal_msgs::msg::{MachineCommand, MachinePosition, ReflectorTruth, Trigger};
use volcal_msgs::sensor_msgs::msg::JointState;
use volcal_msgs::std_msgs::msg::Header;
use volcal_msgs::topics;
use volcal_msgs::trajectory_msgs::msg::JointTrajectory;

/// The motion in progress (or last reached).
struct Motion {
    id: u64,
    arrival: Arrival,
    probe: Vector3<f64>,
    speed_mps: f64,
    /// When the trajectory first went out, and the time it should take.
    sent_ns: i64,
    planned_s: f64,
    arrived: bool,
    /// Where the cell was when the trajectory went out, when it last went out, and how often.
    from: Point3<f64>,
    resent_ns: i64,
    sendings: u32,
}

/// How long the cell may stay exactly where it was after a trajectory went out before the
/// trajectory is taken as lost and sent again. A `joint_trajectory_controller` starts on its
/// next update (1-10 ms); but a reader that matches our writer only after the sample was
/// written drops it (volatile durability): the writer seeing the subscription does not mean
/// that the subscription sees the writer.
const RESEND_NS: i64 = 500_000_000;

impl Motion {
    /// Whether the cell at `position` is still where it was when the trajectory first went out:
    /// then it has received (or accepted) none of the sendings.
    fn unmoved(&self, position: &Point3<f64>, tolerance_m: f64) -> bool {
        (position - self.from).amax() <= tolerance_m
    }
}

/// How many sendings of one motion the cell may leave unfollowed (one second of
/// [`RESEND_NS`]) before a second trajectory writer is announced: early enough that the new
/// writer is discovered within the shortest time limits (a motion's time plus
/// `motion_timeout_s`).
const SECOND_WRITER_AFTER: u32 = 2;

/// How long the cell's joint-state publisher may stay silent, once our participant has
/// discovered it and before any joint state has arrived, before a second joint-state
/// subscription is announced: the same loss as the trajectory writer's, in the other direction
/// (the cell's Fast DDS acknowledged our reader's announcement and never matched it, so it
/// never sent to it; seen in 1 of 328 campaigns under load).
const SECOND_READER_AFTER_NS: i64 = 1_000_000_000;

/// One coordinate sample of the cell.
#[derive(Clone, Copy)]
struct Sample {
    stamp_ns: i64,
    position: Point3<f64>,
    velocity: Vector3<f64>,
    /// When it was received (for the staleness of the stream).
    received_ns: i64,
}

/// The machine's errors played for the simulated instruments (`dry_run`).
fn dry_run(node: &RosNode) -> Result<Option<ActualReflector>> {
    if !node.args.get_or("dry_run", false)? {
        return Ok(None);
    }
    let world = SimWorld::from_args(&node.args)?;
    if let Some(path) = node.args.path("truth")? {
        world.write_truth(&path)?;
        log::info!("dry run: wrote the simulated machine's truth to {}", path.display());
    }
    Ok(Some(ActualReflector::new(&world)))
}

fn position_msg(s: &Sample, m: Option<&Motion>, in_position: bool, trigger_id: u64) -> MachinePosition {
    MachinePosition {
        header: Header::at(s.stamp_ns, "machine"),
        x_m: s.position.x,
        y_m: s.position.y,
        z_m: s.position.z,
        probe_offset_m: m.map_or(Vector3::zeros(), |m| m.probe).into(),
        velocity_mps: s.velocity.into(),
        in_position,
        position_id: m.map_or(0, |m| m.id),
        trigger_id,
    }
}

pub fn run(node: &mut RosNode) -> Result<()> {
    let map = JointMap::parse(
        &node.args.require::<String>("joint_names")?,
        &node.args.get_or("joint_scale", String::new())?,
        &node.args.get_or("joint_sign", String::new())?,
    )?;
    let js_topic: String = node.args.get_or("joint_states_topic", "/joint_states".to_string())?;
    let traj_topic: String =
        node.args.get_or("trajectory_topic", "/joint_trajectory_controller/joint_trajectory".to_string())?;
    let tolerance: f64 = node.args.get_or("position_tolerance_m", 5e-6)?;
    let settle_s: f64 = node.args.get_or("settle_s", 0.1)?;
    let acceleration: f64 = node.args.get_or("acceleration_mps2", 1.0)?;
    let idle_rate: f64 = node.args.get_or("idle_rate_hz", 2.0)?;
    let topic_timeout: f64 = node.args.get_or("topic_timeout_s", 2.0)?;
    let motion_timeout: f64 = node.args.get_or("motion_timeout_s", 5.0)?;
    for (name, v) in [
        ("position_tolerance_m", tolerance),
        ("acceleration_mps2", acceleration),
        ("idle_rate_hz", idle_rate),
        ("topic_timeout_s", topic_timeout),
        ("motion_timeout_s", motion_timeout),
    ] {
        if !(v > 0.0 && v.is_finite()) {
            bail!("parameter {name}: must be a positive number, got {v}");
        }
    }
    if !(settle_s >= 0.0) {
        bail!("parameter settle_s: must not be negative, got {settle_s}");
    }
    // Free-running samples are taken on lines at constant speed (an on-the-fly plan); a static
    // target is approached with the controller's own profile through one point.
    let on_the_fly = matches!(
        volcal_formats::plan::load_plan(node.args.path("plan")?.as_deref())?.acquisition,
        volcal_sim::Acquisition::OnTheFly { .. }
    );
    let mut dry = dry_run(node)?;
    node.warn_unused_parameters();

    let mut states = vec![node.subscription::<JointState>(&js_topic, qos::data())?];
    let mut commands = node.subscription::<MachineCommand>(topics::MACHINE_COMMAND, qos::commands())?;
    let mut triggers = node.subscription::<Trigger>(topics::TRIGGER, qos::commands())?;
    let out = node.publisher::<MachinePosition>(topics::MACHINE_POSITION, qos::data())?;
    let mut writers = vec![node.publisher::<JointTrajectory>(&traj_topic, qos::commands())?];
    let truth = match dry {
        Some(_) => Some(node.publisher::<ReflectorTruth>(topics::TRUTH_REFLECTOR, qos::truth())?),
        None => None,
    };
    let (js_param, js_topic) = (js_topic.clone(), node.resolve(&js_topic));
    let (traj_param, traj_topic) = (traj_topic.clone(), node.resolve(&traj_topic));
    log::info!(
        "ros2_control cell: joints {} (x, y, z) from {js_topic}, trajectories to {traj_topic}{}",
        map.names.join(", "),
        if dry.is_some() { "; dry run: simulated instruments follow the cell" } else { "" }
    );
    let publish =
        |m: MachinePosition| out.publish(m).map_err(|e| anyhow!("publish {}: {e:?}", topics::MACHINE_POSITION));
    // Sends the trajectory from `from` to `to` on every trajectory writer; the time it should take.
    let send =
        |writers: &[Publisher<JointTrajectory>], from: &Point3<f64>, to: &Point3<f64>, speed_mps: f64| -> Result<f64> {
            let limits = MotionLimits { speed_mps, acceleration_mps2: acceleration };
            let t = trajectory(&map, from, to, &limits, on_the_fly);
            let planned_s =
                t.points.last().map_or(0.0, |p| p.time_from_start.sec as f64 + p.time_from_start.nanosec as f64 * 1e-9);
            for w in writers {
                w.publish(t.clone()).map_err(|e| anyhow!("publish {traj_topic}: {e:?}"))?;
            }
            Ok(planned_s)
        };

    let idle_ns = (1e9 / idle_rate) as i64;
    let mut last: Option<Sample> = None;
    let mut motion: Option<Motion> = None;
    let mut pending: Option<MachineCommand> = None;
    let mut next_idle = 0i64;
    let mut stalled = false;
    let started = now_ns();
    let mut waiting_reported = false;
    // When our participant first saw the cell's joint-state publisher while none had arrived.
    let mut publisher_seen_ns: Option<i64> = None;
    let mut deaf_reported = false;
    while !shutdown::requested() {
        node.wait(TICK);
        while let Some(c) = commands.next() {
            pending = Some(c);
        }
        // A command is executed from where the cell says it is, once the cell's controller
        // listens: a trajectory written before its subscription is matched is lost.
        // (Asked only with a command waiting: it reads the participant's discovery tables.)
        let listening = pending.is_some() && node.remote_subscription_count(&traj_topic) > 0;
        if pending.is_some() && !listening && !deaf_reported && now_ns() - started > (topic_timeout * 1e9) as i64 {
            log::warn!("no subscription on {traj_topic} yet: waiting for the cell (is its joint_trajectory_controller running?)");
            deaf_reported = true;
        }
        if let (Some(c), Some(s), true) = (&pending, &last, listening) {
            let target = Point3::new(c.x_m, c.y_m, c.z_m);
            if !(c.speed_mps > 0.0 && c.speed_mps.is_finite()) {
                bail!("motion {}: speed {} m/s is not a positive number", c.position_id, c.speed_mps);
            }
            let repeated = motion.as_ref().is_some_and(|m| m.id == c.position_id && m.arrival.target == target);
            if let Some(m) = motion.as_mut().filter(|_| repeated) {
                if m.arrived {
                    // The sequencer retries: it missed the arrival, report it again.
                    publish(position_msg(s, Some(m), true, 0))?;
                } else {
                    // A retry of a motion that has not arrived (the trajectory may have been
                    // lost): the controller replaces its trajectory by this one. The time
                    // limit still counts from the first sending, so that a cell that does not
                    // follow is named, however often the sequencer asks.
                    send(&writers, &s.position, &target, c.speed_mps)?;
                    log::info!("motion {}: the sequencer asks again; trajectory sent again", c.position_id);
                    m.resent_ns = now_ns();
                    m.sendings += 1;
                }
            } else {
                // A new motion.
                let planned_s = send(&writers, &s.position, &target, c.speed_mps)?;
                let sent_ns = now_ns();
                motion = Some(Motion {
                    id: c.position_id,
                    arrival: Arrival::new(target, tolerance, settle_s),
                    probe: Vector3::from(c.probe_offset_m),
                    speed_mps: c.speed_mps,
                    sent_ns,
                    planned_s,
                    arrived: false,
                    from: s.position,
                    resent_ns: sent_ns,
                    sendings: 1,
                });
            }
            pending = None;
        }
        for js in joint_states(&mut states, last.map(|l| l.stamp_ns)) {
            let (position, velocity) = map.axes(&js, &js_topic)?;
            let received = now_ns();
            let stamp = match js.header.stamp.to_nanos() {
                0 => received,
                t => t,
            };
            let velocity = velocity.unwrap_or_else(|| match &last {
                Some(l) if stamp > l.stamp_ns => (position - l.position) / ((stamp - l.stamp_ns) as f64 * 1e-9),
                _ => Vector3::zeros(),
            });
            let sample = Sample { stamp_ns: stamp, position, velocity, received_ns: received };
            if stalled {
                log::info!("{js_topic}: joint states arrive again; the machine resumes");
                stalled = false;
                // The time to reach the target counts from the resumption.
                if let Some(m) = motion.as_mut().filter(|m| !m.arrived) {
                    m.sent_ns = received;
                }
            }
            let (in_position, corner) = match &mut motion {
                Some(m) => {
                    let now_in = m.arrival.update(stamp, &position);
                    let corner = now_in && !m.arrived;
                    m.arrived |= now_in;
                    (m.arrived && now_in, corner)
                }
                None => (true, last.is_none()),
            };
            if let (Some(d), Some(t)) = (&mut dry, &truth) {
                let (id, probe) = motion.as_ref().map_or((0, Vector3::zeros()), |m| (m.id, m.probe));
                let actual = d.at(stamp, id, in_position, &position, &probe, &velocity);
                let actual_velocity =
                    if in_position { Vector3::zeros() } else { d.velocity(stamp, &position, &probe, &velocity) };
                t.publish(ReflectorTruth {
                    header: Header::at(stamp, "machine"),
                    position_id: id,
                    settled: in_position,
                    actual_m: actual.coords.into(),
                    velocity_mps: actual_velocity.into(),
                })
                .map_err(|e| anyhow!("publish {}: {e:?}", topics::TRUTH_REFLECTOR))?;
            }
            if !in_position || corner || stamp >= next_idle {
                publish(position_msg(&sample, motion.as_ref(), in_position, 0))?;
                if in_position {
                    next_idle = stamp + idle_ns;
                }
            }
            last = Some(sample);
        }
        let now = now_ns();
        // A cell that has not moved at all, with fresh joint states, has not received the
        // trajectory: send it again from where the cell is (the time limit still counts from
        // the first sending).
        if let (Some(m), Some(s)) = (&mut motion, &last) {
            if !m.arrived && !stalled && m.unmoved(&s.position, tolerance) && s.received_ns > m.resent_ns + RESEND_NS {
                if writers.len() == 1 && m.sendings >= SECOND_WRITER_AFTER {
                    writers.push(node.publisher::<JointTrajectory>(&traj_param, qos::commands())?);
                    log::warn!(
                        "motion {}: the cell has not followed {} sendings of the trajectory on {traj_topic}: a second writer is announced there, and trajectories go out on both (a subscription that has not discovered our first writer discovers the new one)",
                        m.id,
                        m.sendings
                    );
                }
                send(&writers, &s.position, &m.arrival.target, m.speed_mps)?;
                log::info!(
                    "motion {}: the cell has not moved {:.1} s after the trajectory went out on {traj_topic}; trajectory sent again (a controller that matched late drops what was written before)",
                    m.id,
                    (now - m.resent_ns) as f64 * 1e-9
                );
                m.resent_ns = now;
                m.sendings += 1;
            }
        }
        if last.is_none() && states.len() == 1 && node.publisher_count(&js_param) > 0 {
            let seen = *publisher_seen_ns.get_or_insert(now);
            if now - seen > SECOND_READER_AFTER_NS {
                states.push(node.subscription::<JointState>(&js_param, qos::data())?);
                log::warn!(
                    "{js_topic}: the cell's publisher is discovered but has sent no joint state in {:.1} s: a second subscription is announced there (a publisher that has not discovered our first subscription discovers the new one)",
                    (now - seen) as f64 * 1e-9
                );
            }
        }
        match &last {
            None if !waiting_reported && now - started > (topic_timeout * 1e9) as i64 => {
                log::warn!(
                    "no joint state on {js_topic} yet: waiting for the cell (is its joint_state_broadcaster running?)"
                );
                waiting_reported = true;
            }
            Some(s) if !stalled && now - s.received_ns > (topic_timeout * 1e9) as i64 => {
                log::warn!(
                    "{js_topic}: no joint state for {:.1} s (topic_timeout_s {topic_timeout}): the machine's coordinates are unknown, the campaign waits",
                    (now - s.received_ns) as f64 * 1e-9
                );
                stalled = true;
            }
            _ => {}
        }
        if let (Some(m), Some(s)) = (&motion, &last) {
            let limit = m.sent_ns + ((m.planned_s + motion_timeout) * 1e9) as i64;
            if !m.arrived && !stalled && now > limit {
                let off = m.arrival.offsets(&s.position);
                let worst = (0..3).max_by(|&a, &b| off[a].abs().total_cmp(&off[b].abs())).unwrap_or(0);
                // A cell that never moved did not receive (or did not accept) any of the
                // trajectories: say so, it is a different fault from an axis that stops.
                let unmoved = if m.unmoved(&s.position, tolerance) {
                    format!(
                        "; the cell has not moved since the first of the {} trajectories sent: its controller did not receive or did not accept them (does its subscription to {traj_topic} match our writer, and does it accept the joint names?)",
                        m.sendings
                    )
                } else {
                    String::new()
                };
                bail!(
                    "motion {} not reached: joint {:?} (axis {}) is at {:.6} m, {:.1} um from its target {:.6} m, {:.1} s after the trajectory went out on {traj_topic} (planned {:.1} s at {} m/s, position_tolerance_m {tolerance}){unmoved}",
                    m.id,
                    map.names[worst],
                    ["x", "y", "z"][worst],
                    s.position[worst],
                    off[worst].abs() * 1e6,
                    m.arrival.target[worst],
                    (now - m.sent_ns) as f64 * 1e-9,
                    m.planned_s,
                    m.speed_mps
                );
            }
        }
        while let Some(t) = triggers.next() {
            if t.trigger_type != trigger_type::POINT && t.trigger_type != trigger_type::PROBE {
                continue;
            }
            match &last {
                // The cell's latest coordinates are those at the trigger: a trigger is sent at rest.
                Some(s) => {
                    publish(position_msg(s, motion.as_ref(), motion.as_ref().is_none_or(|m| m.arrived), t.trigger_id))?
                }
                None => log::warn!("trigger {}: no joint state from {js_topic} yet, nothing to latch", t.trigger_id),
            }
        }
    }
    Ok(())
}

/// The joint states waiting on `states`, in stamp order. With a second subscription the cell
/// may send each joint state to both: a state stamped no later than the one before it
/// (`after`, or the previous one taken) is a copy and is dropped. A state without a stamp (0)
/// is always taken.
fn joint_states(states: &mut [Inbox<JointState>], after: Option<i64>) -> Vec<JointState> {
    let mut all: Vec<JointState> = states.iter_mut().flat_map(|s| std::iter::from_fn(move || s.next())).collect();
    if states.len() > 1 {
        all.sort_by_key(|js| js.header.stamp.to_nanos());
        let mut newest = after.unwrap_or(i64::MIN);
        all.retain(|js| {
            let t = js.header.stamp.to_nanos();
            let fresh = t == 0 || t > newest;
            newest = newest.max(t);
            fresh
        });
    }
    all
}
