//! The sequencer node: executes a campaign plan over the node graph.
//!
//! Fixed-beam plans: for each beam, point the deflector and wait until it has settled; for each
//! point, move the machine to where the reflector should meet the beam (the line through the
//! points already acquired, "the machine follows the beam"), check the return signal, centre
//! the reflector on the beam from the signal strength when it is low (the patent's
//! photoreceiver feedback, [`crate::centring`]), then trigger the acquisition: the
//! interferometer and the machine latch one reading each, tagged with the trigger id. On the
//! fly, the ends of each beam are centred and the machine runs from one to the other between
//! `SEGMENT_START` and `SEGMENT_END` triggers while the instruments sample freely.
//!
//! Tracer plans: for each station, the machine visits the path points and each is acquired
//! the same way (the tracer follows the reflector itself).
//!
//! Every request is retried when its answer does not come within `response_timeout_s`, so a
//! node restarted mid-campaign is picked up again. Required topics that have no publisher
//! after `topic_timeout_s` are reported by name. At the end the sequencer waits until the
//! recorder has paired every acquired point, and closed every on-the-fly segment (its pairs carry
//! the segment's end trigger), on `/campaign/pairs`; then it exits, which ends a
//! `volcal launch` whose sequencer has `on_exit: shutdown`.
//!
//! Parameters: `machine`, `plan` (default: the patent's example), `speed_mps` (replaces the
//! plan's speed and scales its per-line `speeds_mps` alike), `dwell_s`,
//! `station_setup_s`, `settle_timeout_s` (override the plan's timing), `response_timeout_s` (2),
//! `retries` (15), `topic_timeout_s` (10), `wait_for_recorder` (true), `finish_timeout_s` (10),
//! `probe_step_m` (0.4e-3), `recentre_below` (0.99).

use super::runtime::secs;
use crate::backend::sim::LOSS_THRESHOLD;
use crate::centring::{lateral_basis, vertex, LineFollower};
use crate::ros::Inbox;
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::{anyhow, bail, Result};
use nalgebra::{Point3, Vector3};
use ros2_client::Publisher;
use std::collections::{HashMap, HashSet};
use std::time::{Duration, Instant};
use volcal_bag::pairing::trigger_type;
use volcal_formats::machine::{Machine, DEMO_MACHINE};
use volcal_formats::plan::load_plan;
use volcal_msgs::msg::{
    Abscissa, BeamCommand, BeamState, MachineCommand, MachinePosition, MachinePositionBatch, SequencerStatus,
    SyncedPair, TracerRange, Trigger,
};
use volcal_msgs::std_msgs::msg::Header;
use volcal_msgs::topics;
use volcal_sim::plan::{task_direction, BeamTask, PathTask};
use volcal_sim::{Acquisition, Method, Plan};

/// Timing and tolerances of the run.
#[derive(Clone, Debug)]
pub struct Settings {
    pub speed_mps: f64,
    /// The plan's per-line speed cycle (`speeds_mps`) scaled by `speed_mps` over the plan's
    /// speed: line `i` runs at `line_speeds[i % len]` (empty: all at `speed_mps`).
    pub line_speeds: Vec<f64>,
    pub dwell_s: f64,
    pub station_setup_s: f64,
    pub on_the_fly: bool,
    pub response_timeout: Duration,
    pub retries: u32,
    pub probe_step_m: f64,
    pub recentre_below: f64,
}

/// Indices of the first and last abscissae and of every one where the motion reverses.
fn turning_points(abscissae: &[f64]) -> Vec<usize> {
    let mut out = vec![0];
    let mut last_sign = 0.0;
    for k in 1..abscissae.len() {
        let step = abscissae[k] - abscissae[k - 1];
        if step != 0.0 {
            if step.signum() == -last_sign {
                out.push(k - 1);
            }
            last_sign = step.signum();
        }
    }
    if abscissae.len() > 1 {
        out.push(abscissae.len() - 1);
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn turning_points_of_one_way_and_out_and_back_lines() {
        assert_eq!(super::turning_points(&[0.0, 1.0, 2.0]), vec![0, 2]);
        assert_eq!(super::turning_points(&[0.0, 1.0, 2.0, 2.0, 1.0, 0.0]), vec![0, 3, 5]);
        assert_eq!(super::turning_points(&[0.0]), vec![0]);
    }
}

/// A latched reading as the sequencer sees it.
#[derive(Clone, Copy, Debug)]
struct Latched {
    signal: f64,
}

/// The sequencer's view of the graph: publishers, subscriptions and what they brought.
struct Link<'a> {
    node: &'a mut RosNode,
    beam_cmd: Publisher<BeamCommand>,
    machine_cmd: Publisher<MachineCommand>,
    trigger: Publisher<Trigger>,
    status: Publisher<SequencerStatus>,
    states: Inbox<BeamState>,
    positions: Inbox<MachinePosition>,
    position_batches: Inbox<MachinePositionBatch>,
    abscissae: Inbox<Abscissa>,
    ranges: Inbox<TracerRange>,
    pairs: Inbox<SyncedPair>,
    beam_state: Option<BeamState>,
    reached: Option<(u64, Point3<f64>)>,
    latched_positions: HashMap<u64, Point3<f64>>,
    readings: HashMap<u64, Latched>,
    paired: HashSet<u64>,
    next_id: u64,
    settings: Settings,
    plan_name: String,
    done: u32,
    total: u32,
}

fn publish<M: volcal_msgs::RosMessage>(p: &Publisher<M>, m: M, topic: &str) -> Result<()> {
    p.publish(m).map_err(|e| anyhow!("publish {topic}: {e:?}"))
}

impl<'a> Link<'a> {
    fn new(node: &'a mut RosNode, settings: Settings, plan_name: String, total: u32) -> Result<Link<'a>> {
        Ok(Link {
            beam_cmd: node.publisher(topics::DEFLECTOR_COMMAND, qos::commands())?,
            machine_cmd: node.publisher(topics::MACHINE_COMMAND, qos::commands())?,
            trigger: node.publisher(topics::TRIGGER, qos::commands())?,
            status: node.publisher(topics::SEQUENCER_STATUS, qos::latched())?,
            states: node.subscription(topics::DEFLECTOR_STATE, qos::latched())?,
            positions: node.subscription(topics::MACHINE_POSITION, qos::data())?,
            position_batches: node.subscription(topics::MACHINE_POSITION_BATCH, qos::data())?,
            abscissae: node.subscription(topics::ABSCISSA, qos::data())?,
            ranges: node.subscription(topics::TRACER_RANGE, qos::data())?,
            pairs: node.subscription(topics::PAIRS, qos::data())?,
            node,
            beam_state: None,
            reached: None,
            latched_positions: HashMap::new(),
            readings: HashMap::new(),
            paired: HashSet::new(),
            // Unique across restarts of the sequencer: ids start at the current time.
            next_id: now_ns().max(1) as u64,
            settings,
            plan_name,
            done: 0,
            total,
        })
    }

    fn id(&mut self) -> u64 {
        self.next_id += 1;
        self.next_id
    }

    /// Waits briefly for traffic and takes everything that arrived.
    fn pump(&mut self, wait: Duration) -> Result<()> {
        if shutdown::requested() {
            bail!("stopped by a signal after {} of {} points", self.done, self.total);
        }
        self.node.wait(wait);
        while let Some(s) = self.states.next() {
            self.beam_state = Some(s);
        }
        while let Some(p) = self.positions.next() {
            let x = Point3::new(p.x_m, p.y_m, p.z_m);
            if p.trigger_id != 0 {
                self.latched_positions.insert(p.trigger_id, x);
            } else if p.in_position {
                self.reached = Some((p.position_id, x));
            }
        }
        while let Some(b) = self.position_batches.next() {
            if b.in_position {
                if let (Some(x), Some(y), Some(z)) = (b.x_m.last(), b.y_m.last(), b.z_m.last()) {
                    self.reached = Some((b.position_id, Point3::new(*x, *y, *z)));
                }
            }
        }
        while let Some(a) = self.abscissae.next() {
            if a.trigger_id != 0 {
                self.readings.insert(a.trigger_id, Latched { signal: a.signal_strength });
            }
        }
        while let Some(r) = self.ranges.next() {
            if r.trigger_id != 0 {
                self.readings.insert(r.trigger_id, Latched { signal: r.signal_strength });
            }
        }
        while let Some(p) = self.pairs.next() {
            self.paired.insert(p.trigger_id);
        }
        Ok(())
    }

    /// Sends a request (again on each timeout) until `answered` holds.
    fn request(
        &mut self,
        what: &str,
        topic: &str,
        extra_wait: Duration,
        mut send: impl FnMut(&mut Self) -> Result<()>,
        mut answered: impl FnMut(&Self) -> bool,
    ) -> Result<()> {
        let retries = self.settings.retries;
        for attempt in 0..=retries {
            send(self)?;
            let start = Instant::now();
            let limit = self.settings.response_timeout + extra_wait;
            while start.elapsed() < limit {
                self.pump(Duration::from_millis(2))?;
                if answered(self) {
                    return Ok(());
                }
            }
            if attempt < retries {
                log::warn!(
                    "{what}: no answer on {topic} within {:.1} s; retrying ({}/{retries})",
                    limit.as_secs_f64(),
                    attempt + 1
                );
            }
        }
        bail!("{what}: no answer on {topic} after {} attempts", retries + 1)
    }

    fn point_beam(&mut self, task: &BeamTask) -> Result<()> {
        let cmd = BeamCommand {
            header: Header::at(now_ns(), "machine"),
            station: task.station,
            beam: task.beam,
            device_position_m: task.pivot.coords.into(),
            azimuth_rad: task.azimuth_rad,
            elevation_rad: task.elevation_rad,
        };
        let (station, beam) = (task.station, task.beam);
        self.request(
            &format!("station {station} beam {beam}: pointing the deflector"),
            topics::DEFLECTOR_STATE,
            Duration::from_secs_f64(30.0),
            |l| publish(&l.beam_cmd, cmd.clone(), topics::DEFLECTOR_COMMAND),
            |l| l.beam_state.as_ref().is_some_and(|s| s.station == station && s.beam == beam && s.settled),
        )
    }

    /// Moves the machine and waits until it reports the target reached; returns the motion id.
    fn move_to(&mut self, target: Point3<f64>, probe: &Vector3<f64>, speed: f64) -> Result<u64> {
        let id = self.id();
        let cmd = MachineCommand {
            header: Header::at(now_ns(), "machine"),
            position_id: id,
            x_m: target.x,
            y_m: target.y,
            z_m: target.z,
            probe_offset_m: (*probe).into(),
            speed_mps: speed,
        };
        let from = self.reached.map(|r| r.1).unwrap_or(target);
        let travel_time = Duration::from_secs_f64(((target - from).norm() / speed).min(3600.0));
        self.request(
            &format!("motion {id}"),
            topics::MACHINE_POSITION,
            travel_time,
            |l| publish(&l.machine_cmd, cmd.clone(), topics::MACHINE_COMMAND),
            |l| l.reached.is_some_and(|r| r.0 == id),
        )?;
        Ok(id)
    }

    fn send_trigger(&mut self, ty: u8, kind: u8, station: u32, line: u32, point: u32, position_id: u64) -> Result<u64> {
        let id = self.id();
        publish(
            &self.trigger,
            Trigger {
                header: Header::at(now_ns(), "machine"),
                trigger_id: id,
                trigger_type: ty,
                kind,
                station,
                line,
                point,
                position_id,
            },
            topics::TRIGGER,
        )?;
        Ok(id)
    }

    /// A triggered reading: a probe (signal only) or an acquired point (reading and latched
    /// coordinates). Retries with a new trigger id until both answers arrive.
    fn trigger_reading(
        &mut self,
        ty: u8,
        kind: u8,
        station: u32,
        line: u32,
        point: u32,
        pos: u64,
    ) -> Result<(u64, f64)> {
        let topic = if kind == Trigger::KIND_BEAM { topics::ABSCISSA } else { topics::TRACER_RANGE };
        let last = std::cell::Cell::new(0u64);
        let what = format!(
            "station {station} line {line} point {point}: {}",
            if ty == trigger_type::POINT { "acquisition" } else { "signal probe" }
        );
        self.request(
            &what,
            topic,
            Duration::ZERO,
            |l| {
                last.set(l.send_trigger(ty, kind, station, line, point, pos)?);
                Ok(())
            },
            |l| {
                let id = last.get();
                l.readings.contains_key(&id) && (ty != trigger_type::POINT || l.latched_positions.contains_key(&id))
            },
        )?;
        let id = last.get();
        let r = self.readings.remove(&id).unwrap();
        self.latched_positions.remove(&id);
        Ok((id, r.signal))
    }

    fn probe_at(&mut self, x: Point3<f64>, probe: &Vector3<f64>, task: &BeamTask, point: u32) -> Result<f64> {
        let pos = self.move_to(x, probe, self.settings.speed_mps)?;
        self.dwell()?;
        Ok(self.trigger_reading(trigger_type::PROBE, Trigger::KIND_BEAM, task.station, task.beam, point, pos)?.1)
    }

    fn dwell(&mut self) -> Result<()> {
        let until = Instant::now() + secs(self.settings.dwell_s);
        while Instant::now() < until {
            self.pump(Duration::from_millis(1))?;
        }
        Ok(())
    }

    /// Centres the reflector on the beam near `x` by the return-signal strength.
    fn centre(&mut self, x: Point3<f64>, probe: &Vector3<f64>, task: &BeamTask, point: u32) -> Result<Point3<f64>> {
        let dir = task_direction(task);
        let (u, v) = lateral_basis(&dir);
        let h = self.settings.probe_step_m;
        let mut c = x;
        for _ in 0..4 {
            let mut s0 = self.probe_at(c, probe, task, point)?;
            if s0 < LOSS_THRESHOLD {
                c = self.search(c, probe, task, point, &u, &v)?;
                s0 = self.probe_at(c, probe, task, point)?;
            }
            let mut shift = 0.0f64;
            for axis in [u, v] {
                let sp = self.probe_at(c + axis * h, probe, task, point)?;
                let sm = self.probe_at(c - axis * h, probe, task, point)?;
                let dx = vertex(sm, s0, sp, h).unwrap_or(if sp > sm { h } else { -h });
                c += axis * dx;
                shift = shift.max(dx.abs());
            }
            if shift < 0.05 * h {
                break;
            }
        }
        Ok(c)
    }

    /// Looks for the beam around `x` on widening rings when it is lost there.
    fn search(
        &mut self,
        x: Point3<f64>,
        probe: &Vector3<f64>,
        task: &BeamTask,
        point: u32,
        u: &Vector3<f64>,
        v: &Vector3<f64>,
    ) -> Result<Point3<f64>> {
        let h = self.settings.probe_step_m;
        for ring in 1..=6 {
            let r = ring as f64 * 2.0 * h;
            for k in 0..8 {
                let a = k as f64 * std::f64::consts::FRAC_PI_4;
                let y = x + (u * a.cos() + v * a.sin()) * r;
                if self.probe_at(y, probe, task, point)? >= LOSS_THRESHOLD {
                    return Ok(y);
                }
            }
        }
        bail!(
            "station {} beam {} point {point}: the beam is not found within {:.1} mm of its nominal position",
            task.station,
            task.beam,
            12.0 * h * 1e3
        )
    }

    fn status(&mut self, state: u8, station: u32, line: u32, message: &str) -> Result<()> {
        publish(
            &self.status,
            SequencerStatus {
                header: Header::at(now_ns(), ""),
                state,
                plan: self.plan_name.clone(),
                points_done: self.done,
                points_total: self.total,
                station,
                line,
                message: message.to_string(),
            },
            topics::SEQUENCER_STATUS,
        )
    }

    fn station_setup(&mut self, station: u32, line: u32) -> Result<()> {
        let s = self.settings.station_setup_s;
        if s > 0.0 {
            log::info!("station {station}: waiting {s:.1} s for the device to be set up");
            self.status(SequencerStatus::RUNNING, station, line, "setting up the station")?;
            let until = Instant::now() + secs(s);
            while Instant::now() < until {
                self.pump(Duration::from_millis(20))?;
            }
        }
        Ok(())
    }

    /// The speed of the measuring moves of line `i` (the plan's speed cycle, scaled).
    fn line_speed(&self, i: usize) -> f64 {
        let v = &self.settings.line_speeds;
        if v.is_empty() {
            self.settings.speed_mps
        } else {
            v[i % v.len()]
        }
    }

    fn run_beam(&mut self, i: usize, task: &BeamTask, acquired: &mut Vec<u64>) -> Result<()> {
        self.point_beam(task)?;
        let dir = task_direction(task);
        let p = task.probe_offset;
        let mut follower = LineFollower::new(dir);
        let mut last_signal = 0.0;
        let nominal = |s: f64| task.pivot + dir * s - p;
        if self.settings.on_the_fly {
            // The machine runs through the turning points of the abscissae (out and back for a
            // bidirectional beam), each centred on the beam first, the far ones first so that
            // the run starts where the centring ends.
            let turns = turning_points(&task.abscissae);
            let mut centred = Vec::with_capacity(turns.len());
            for &k in turns.iter().rev() {
                let c = match centred
                    .iter()
                    .find(|(kk, _): &&(usize, Point3<f64>)| task.abscissae[*kk] == task.abscissae[k])
                {
                    Some((_, c)) => *c,
                    None => self.centre(nominal(task.abscissae[k]), &p, task, k as u32)?,
                };
                centred.push((k, c));
            }
            centred.reverse();
            let pos = self.move_to(centred[0].1, &p, self.settings.speed_mps)?;
            let kind = Trigger::KIND_BEAM;
            self.send_trigger(trigger_type::SEGMENT_START, kind, task.station, task.beam, 0, pos)?;
            let mut pos = pos;
            for (_, c) in &centred[1..] {
                pos = self.move_to(*c, &p, self.line_speed(i))?;
            }
            // The recorder's pairs of this segment carry this id: the campaign waits for them
            // as it waits for the static points' pairs.
            let end = self.send_trigger(trigger_type::SEGMENT_END, kind, task.station, task.beam, 0, pos)?;
            acquired.push(end);
            self.done += task.abscissae.len() as u32;
            return Ok(());
        }
        for (k, &s) in task.abscissae.iter().enumerate() {
            let k32 = k as u32;
            let mut target = follower.predict(s).unwrap_or_else(|| nominal(s));
            if k == 0 {
                target = self.centre(target, &p, task, k32)?;
            }
            let mut pos = self.move_to(target, &p, self.line_speed(i))?;
            self.dwell()?;
            if k == 1 || (k > 1 && last_signal < self.settings.recentre_below) {
                let (_, sig) =
                    self.trigger_reading(trigger_type::PROBE, Trigger::KIND_BEAM, task.station, task.beam, k32, pos)?;
                if sig < self.settings.recentre_below {
                    target = self.centre(target, &p, task, k32)?;
                    pos = self.move_to(target, &p, self.settings.speed_mps)?;
                    self.dwell()?;
                }
            }
            let (id, sig) =
                self.trigger_reading(trigger_type::POINT, Trigger::KIND_BEAM, task.station, task.beam, k32, pos)?;
            acquired.push(id);
            last_signal = sig;
            follower.add(s, target);
            self.done += 1;
        }
        Ok(())
    }

    fn run_path(&mut self, i: usize, task: &PathTask, acquired: &mut Vec<u64>) -> Result<()> {
        for (k, x) in task.points.iter().enumerate() {
            let pos = self.move_to(*x, &task.probe_offset, self.line_speed(i))?;
            self.dwell()?;
            let (id, _) =
                self.trigger_reading(trigger_type::POINT, Trigger::KIND_RANGE, task.station, task.path, k as u32, pos)?;
            acquired.push(id);
            self.done += 1;
            if self.done.is_multiple_of(50) {
                self.status(SequencerStatus::RUNNING, task.station, task.path, "")?;
            }
        }
        Ok(())
    }
}

/// Topics that must have a publisher before the campaign starts.
pub fn required_topics(method: Method, wait_for_recorder: bool) -> Vec<&'static str> {
    let mut v = vec![topics::MACHINE_POSITION];
    match method {
        Method::FixedBeam => v.extend([topics::DEFLECTOR_STATE, topics::ABSCISSA]),
        Method::Tracer => v.push(topics::TRACER_RANGE),
    }
    if wait_for_recorder {
        v.push(topics::PAIRS);
    }
    v
}

/// The topics that the recorder needs from the start of the campaign to pair its points: what
/// the sequencer sends and what the instruments answer.
fn recorded_topics(method: Method) -> Vec<&'static str> {
    let mut v = vec![topics::TRIGGER, topics::MACHINE_COMMAND, topics::MACHINE_POSITION];
    match method {
        Method::FixedBeam => v.extend([topics::DEFLECTOR_COMMAND, topics::ABSCISSA]),
        Method::Tracer => v.push(topics::TRACER_RANGE),
    }
    v
}

pub fn run(node: &mut RosNode) -> Result<()> {
    let args = &node.args;
    let machine = match args.path("machine")? {
        Some(p) => Machine::load(&p)?,
        None => Machine::parse(DEMO_MACHINE)?,
    };
    let plan_path = args.path("plan")?;
    let mut plan: Plan = load_plan(plan_path.as_deref())?;
    let plan_name = plan_path.map(|p| p.display().to_string()).unwrap_or_else(|| "patent example".into());
    let on_the_fly = matches!(plan.acquisition, Acquisition::OnTheFly { .. });
    let (plan_speed, plan_dwell) = match plan.acquisition {
        Acquisition::Static { speed_mps, dwell_s } => (speed_mps, dwell_s),
        Acquisition::OnTheFly { speed_mps } => (speed_mps, 0.0),
    };
    let speed_mps: f64 = args.get_or("speed_mps", plan_speed)?;
    let settings = Settings {
        speed_mps,
        line_speeds: plan.speeds_mps.iter().map(|v| v * speed_mps / plan_speed).collect(),
        dwell_s: args.get_or("dwell_s", plan_dwell)?,
        station_setup_s: args.get_or("station_setup_s", plan.station_setup_s)?,
        on_the_fly,
        response_timeout: secs(args.get_or("response_timeout_s", 2.0)?),
        retries: args.get_or("retries", 15)?,
        probe_step_m: args.get_or("probe_step_m", 0.4e-3)?,
        recentre_below: args.get_or("recentre_below", 0.99)?,
    };
    if !(settings.speed_mps > 0.0) || settings.line_speeds.iter().any(|v| !(*v > 0.0 && v.is_finite())) {
        bail!(
            "parameter speed_mps ({}) and the plan's speed ({plan_speed}) and speeds_mps ({:?}) must be positive",
            settings.speed_mps,
            plan.speeds_mps
        );
    }
    let topic_timeout = secs(args.get_or("topic_timeout_s", 10.0)?);
    let finish_timeout = secs(args.get_or("finish_timeout_s", 10.0)?);
    let wait_for_recorder: bool = args.get_or("wait_for_recorder", true)?;
    node.warn_unused_parameters();
    plan.station_setup_s = settings.station_setup_s;
    let travel = machine.layout.travel;
    let (beams, paths) = match plan.method {
        Method::FixedBeam => (plan.beam_tasks(&travel).map_err(|e| anyhow!("{e}"))?, Vec::new()),
        Method::Tracer => {
            if on_the_fly {
                bail!("plan: on-the-fly acquisition is implemented for fixed-beam plans only; use static for tracer plans");
            }
            (Vec::new(), plan.path_tasks(&travel).map_err(|e| anyhow!("{e}"))?)
        }
    };
    let total: u32 = beams.iter().map(|t| t.abscissae.len() as u32).sum::<u32>()
        + paths.iter().map(|t| t.points.len() as u32).sum::<u32>();
    let required = required_topics(plan.method, wait_for_recorder);
    let mut link = Link::new(node, settings, plan_name.clone(), total)?;
    link.status(SequencerStatus::WAITING, 0, 0, "waiting for the nodes")?;
    if let Err(e) = link.node.wait_for_publishers(&required, topic_timeout) {
        let _ = link.status(SequencerStatus::FAILED, 0, 0, &format!("{e}"));
        return Err(e);
    }
    if wait_for_recorder {
        // The recorder must hear the first trigger and command as well as the last.
        let recorded = recorded_topics(plan.method);
        if let Err(e) = link.node.wait_for_readers(&recorded, topics::PAIRS, topic_timeout) {
            let _ = link.status(SequencerStatus::FAILED, 0, 0, &format!("{e}"));
            return Err(e);
        }
    }
    log::info!(
        "plan {plan_name}: {} {}, {total} points, {}",
        if beams.is_empty() { paths.len() } else { beams.len() },
        if beams.is_empty() { "tracer paths" } else { "beams" },
        if on_the_fly { "on the fly" } else { "static" }
    );
    let started = Instant::now();
    let mut acquired = Vec::new();
    let result = (|| -> Result<()> {
        let mut station = u32::MAX;
        for (i, task) in beams.iter().enumerate() {
            if task.station != station {
                if station != u32::MAX {
                    link.station_setup(task.station, task.beam)?;
                }
                station = task.station;
            }
            link.status(SequencerStatus::RUNNING, task.station, task.beam, "")?;
            link.run_beam(i, task, &mut acquired)?;
        }
        for (i, task) in paths.iter().enumerate() {
            if i > 0 {
                link.station_setup(task.station, task.path)?;
            }
            link.status(SequencerStatus::RUNNING, task.station, task.path, "")?;
            link.run_path(i, task, &mut acquired)?;
        }
        Ok(())
    })();
    if let Err(e) = result {
        let _ = link.status(SequencerStatus::FAILED, 0, 0, &format!("{e:#}"));
        return Err(e);
    }
    log::info!("acquired {} points in {:.1} s", link.done, started.elapsed().as_secs_f64());
    link.status(SequencerStatus::DONE, 0, 0, "campaign complete")?;
    if wait_for_recorder && !acquired.is_empty() {
        let until = Instant::now() + finish_timeout;
        let missing = |l: &Link| acquired.iter().filter(|id| !l.paired.contains(id)).count();
        while missing(&link) > 0 && Instant::now() < until {
            link.pump(Duration::from_millis(10))?;
        }
        let m = missing(&link);
        let what = if on_the_fly { "on-the-fly segments" } else { "acquired points" };
        if m > 0 {
            log::warn!("the recorder has not confirmed {m} of {} {what}", acquired.len());
        } else {
            log::info!("the recorder confirmed all {} {what}", acquired.len());
        }
    }
    Ok(())
}
