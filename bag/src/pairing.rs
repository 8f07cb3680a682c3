//! Pairing interferometer (or tracer) readings with the machine's indicated coordinates: the
//! recorder's core, free of DDS and files so that it can be tested with any arrival order.
//!
//! Two methods, as the sequencer acquires:
//!
//! - **trigger** (static points): a `POINT` trigger makes the instrument and the machine each
//!   latch one message tagged with the trigger id; the three are matched by that id, in any
//!   arrival order. `PROBE` triggers (centring) are not paired.
//! - **interpolated** (on the fly): between `SEGMENT_START` and `SEGMENT_END` of a line, every
//!   free-running reading is paired with the machine coordinates interpolated at its stamp
//!   (plus the configured clock offset) between the two bracketing machine samples: along the
//!   cubic through their positions and velocities where the machine publishes consistent
//!   velocities inside one motion, else along the straight line ([`volcal::path`]).
//!
//! Duplicated messages (same trigger id, or same stamp and line for free-running samples) are
//! counted and ignored; out-of-order messages wait until their partners arrive. Pairs come out
//! in completion order; consumers sort by stamp.
//!
//! A lost count is never lost with the reading that reported it. `beam_broken` says that the
//! instrument's count restarted before that reading, so the estimator gives what follows a new
//! origin. When the reading that says so is not recorded (a centring probe, a free-running
//! sample outside every segment), the next recorded reading of its line carries the flag. For
//! example, an interferometer restarted in the middle of a line re-establishes its count at the
//! probe before the next point; without the carry-over, every later point of the line would be
//! one step off with nothing to say so.

use nalgebra::{Point3, Vector3};
use std::collections::{BTreeMap, HashMap, HashSet};
use volcal::campaign::ObsKind;
use volcal::environment::Air;
use volcal::path::{self, PathSample};

/// Trigger types (the `Trigger.msg` constants).
pub mod trigger_type {
    pub const POINT: u8 = 0;
    pub const PROBE: u8 = 1;
    pub const SEGMENT_START: u8 = 2;
    pub const SEGMENT_END: u8 = 3;
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriggerEvent {
    pub id: u64,
    pub trigger_type: u8,
    pub kind: ObsKind,
    pub station: u32,
    pub line: u32,
    pub point: u32,
    pub stamp_ns: i64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReadingEvent {
    pub kind: ObsKind,
    pub station: u32,
    pub line: u32,
    pub value_m: f64,
    pub signal_strength: f64,
    pub beam_broken: bool,
    /// 0 for free-running samples.
    pub trigger_id: u64,
    pub stamp_ns: i64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionEvent {
    pub x: [f64; 3],
    pub probe_offset: [f64; 3],
    /// The machine's own velocity at `stamp_ns` (zero where its source has none).
    pub velocity: [f64; 3],
    /// The motion in progress (or last reached) and whether the machine rests at its target:
    /// [`volcal::path`] interpolates with the velocities only inside one motion.
    pub position_id: u64,
    pub in_position: bool,
    /// 0 unless latched by a trigger.
    pub trigger_id: u64,
    pub stamp_ns: i64,
}

impl PositionEvent {
    fn path_sample(&self) -> PathSample {
        PathSample {
            stamp_ns: self.stamp_ns,
            motion_id: self.position_id,
            at_rest: self.in_position,
            position: Point3::from(self.x),
            velocity: Vector3::from(self.velocity),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnvironmentEvent {
    pub air: Option<Air>,
    pub machine_temp_c: Option<f64>,
    pub stamp_ns: i64,
}

/// How a pair was formed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    Trigger,
    Interpolated,
}

/// A synchronised pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pair {
    pub kind: ObsKind,
    pub station: u32,
    pub line: u32,
    pub point: u32,
    /// The reading's stamp.
    pub stamp_ns: i64,
    pub l_m: f64,
    pub x: [f64; 3],
    pub probe_offset: [f64; 3],
    pub velocity: [f64; 3],
    pub beam_broken: bool,
    pub method: Method,
    /// Trigger: |reading stamp - machine stamp|; interpolation: the bracketing interval. Seconds.
    pub gap_s: f64,
    /// Trigger pairing: the point's trigger; interpolation: the trigger that ended the segment.
    pub trigger_id: u64,
    pub environment: Option<EnvironmentEvent>,
}

/// Pairing parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairingConfig {
    /// Machine clock minus instrument clock, nanoseconds: added to a reading's stamp to find
    /// the machine samples of the same instant.
    pub clock_offset_ns: i64,
    /// Largest interval between the two machine samples bracketing a reading, nanoseconds.
    pub max_gap_ns: i64,
    /// How long (in stamp time) an incomplete pair waits for its partners, nanoseconds.
    pub horizon_ns: i64,
}

impl Default for PairingConfig {
    fn default() -> Self {
        PairingConfig { clock_offset_ns: 0, max_gap_ns: 50_000_000, horizon_ns: 10_000_000_000 }
    }
}

/// What the pairing saw besides pairs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PairingStats {
    pub trigger_pairs: u64,
    pub interpolated_pairs: u64,
    /// Messages received twice (ignored).
    pub duplicates: u64,
    /// Messages contradicting an earlier one with the same id or stamp (the first is kept).
    pub conflicts: u64,
    /// Point triggers whose reading or machine coordinates never arrived.
    pub incomplete_points: u64,
    /// Free-running readings outside every on-the-fly segment (e.g. while moving between beams).
    pub outside_segments: u64,
    /// Free-running readings in a segment without machine samples close enough on both sides.
    pub unbracketed: u64,
    /// Count losses reported by readings that are not recorded (centring probes, free-running
    /// samples outside segments), carried over to the next recorded reading of their line.
    pub carried_breaks: u64,
    /// Of those, the ones that arrived after a later reading of their line had been paired:
    /// that reading went out without the flag, so its line is suspect there.
    pub late_breaks: u64,
}

#[derive(Clone, Copy, Debug)]
struct Segment {
    kind: ObsKind,
    station: u32,
    line: u32,
    start_ns: i64,
    end_ns: Option<i64>,
    /// The id of the SEGMENT_END trigger; the segment's pairs carry it, so that the sequencer
    /// learns from the first of them that the recorder has closed the segment.
    end_trigger: u64,
    next_point: u32,
}

type FreeKey = (i64, ObsKind, u32, u32);

/// A line: instrument kind, station, beam or path.
type LineKey = (ObsKind, u32, u32);

/// The pairing state machine.
#[derive(Default)]
pub struct Pairer {
    cfg: PairingConfig,
    // Static points.
    triggers: HashMap<u64, TriggerEvent>,
    readings: HashMap<u64, ReadingEvent>,
    positions: HashMap<u64, PositionEvent>,
    closed: HashSet<u64>,
    /// Centring probes, with their line.
    probes: HashMap<u64, LineKey>,
    /// Duplicates seen for ids whose trigger has not arrived yet (a probe's are not counted).
    pending_duplicates: HashMap<u64, u64>,
    // On the fly.
    segment_ids: HashSet<u64>,
    segments: Vec<Segment>,
    orphan_ends: Vec<TriggerEvent>,
    waiting_segment: BTreeMap<FreeKey, ReadingEvent>,
    waiting_position: BTreeMap<FreeKey, ReadingEvent>,
    paired_free: BTreeMap<FreeKey, ()>,
    track: BTreeMap<i64, PositionEvent>,
    environment: BTreeMap<i64, EnvironmentEvent>,
    // Count losses.
    /// Per line, the stamp of the earliest count loss reported by a reading that is not
    /// recorded and not yet carried over to a recorded one.
    unrecorded_breaks: HashMap<LineKey, i64>,
    /// Per line, the latest reading stamp among the pairs that went out.
    last_pair_ns: HashMap<LineKey, i64>,
    latest_ns: i64,
    expired_at_ns: i64,
    stats: PairingStats,
}

fn free_key(r: &ReadingEvent) -> FreeKey {
    (r.stamp_ns, r.kind, r.station, r.line)
}

impl Pairer {
    pub fn new(cfg: PairingConfig) -> Pairer {
        Pairer { cfg, latest_ns: i64::MIN, expired_at_ns: i64::MIN, ..Pairer::default() }
    }

    pub fn stats(&self) -> PairingStats {
        self.stats
    }

    fn see(&mut self, stamp_ns: i64) {
        self.latest_ns = self.latest_ns.max(stamp_ns);
    }

    /// A trigger from the sequencer.
    pub fn trigger(&mut self, t: TriggerEvent, out: &mut Vec<Pair>) {
        self.see(t.stamp_ns);
        match t.trigger_type {
            trigger_type::POINT => {
                if self.closed.contains(&t.id) {
                    self.stats.duplicates += 1;
                    return;
                }
                match self.triggers.get(&t.id) {
                    Some(old) if *old == t => self.duplicate_of(t.id),
                    Some(_) => self.stats.conflicts += 1,
                    None => {
                        self.triggers.insert(t.id, t);
                        self.try_point(t.id, out);
                    }
                }
            }
            trigger_type::PROBE => {
                // Centring probes are not paired; their messages are neither pairs nor duplicates.
                let line = (t.kind, t.station, t.line);
                self.probes.insert(t.id, line);
                if let Some(r) = self.readings.remove(&t.id) {
                    self.not_recorded(line, &r);
                }
                self.positions.remove(&t.id);
                if let Some(n) = self.pending_duplicates.remove(&t.id) {
                    self.stats.duplicates -= n;
                }
            }
            trigger_type::SEGMENT_START | trigger_type::SEGMENT_END => {
                if !self.segment_ids.insert(t.id) {
                    self.stats.duplicates += 1;
                    return;
                }
                if t.trigger_type == trigger_type::SEGMENT_START {
                    let mut seg = Segment {
                        kind: t.kind,
                        station: t.station,
                        line: t.line,
                        start_ns: t.stamp_ns,
                        end_ns: None,
                        end_trigger: 0,
                        next_point: 0,
                    };
                    // An end that overtook its start.
                    if let Some(i) = self.orphan_ends.iter().position(|e| {
                        (e.kind, e.station, e.line) == (t.kind, t.station, t.line) && e.stamp_ns >= t.stamp_ns
                    }) {
                        let end = self.orphan_ends.remove(i);
                        seg.end_ns = Some(end.stamp_ns);
                        seg.end_trigger = end.id;
                    }
                    self.segments.push(seg);
                } else if let Some(seg) = self.segments.iter_mut().rev().find(|s| {
                    (s.kind, s.station, s.line) == (t.kind, t.station, t.line)
                        && s.end_ns.is_none()
                        && s.start_ns <= t.stamp_ns
                }) {
                    seg.end_ns = Some(t.stamp_ns);
                    seg.end_trigger = t.id;
                } else {
                    self.orphan_ends.push(t);
                }
                // Readings that were waiting for this segment.
                let keys: Vec<FreeKey> = self.waiting_segment.keys().cloned().collect();
                for k in keys {
                    if self.segment_of(k).is_some() {
                        let r = self.waiting_segment.remove(&k).unwrap();
                        self.waiting_position.insert(k, r);
                    }
                }
                self.pair_free(out);
            }
            _ => self.stats.conflicts += 1,
        }
        self.expire();
    }

    fn duplicate_of(&mut self, id: u64) {
        self.stats.duplicates += 1;
        if !self.closed.contains(&id) {
            *self.pending_duplicates.entry(id).or_insert(0) += 1;
        }
    }

    /// An instrument reading (triggered or free-running).
    pub fn reading(&mut self, r: ReadingEvent, out: &mut Vec<Pair>) {
        self.see(r.stamp_ns);
        if r.trigger_id != 0 {
            if let Some(&line) = self.probes.get(&r.trigger_id) {
                self.not_recorded(line, &r);
                return;
            }
            if self.closed.contains(&r.trigger_id) {
                self.stats.duplicates += 1;
                return;
            }
            match self.readings.get(&r.trigger_id) {
                Some(old) if *old == r => self.duplicate_of(r.trigger_id),
                Some(_) => self.stats.conflicts += 1,
                None => {
                    self.readings.insert(r.trigger_id, r);
                    self.try_point(r.trigger_id, out);
                }
            }
        } else {
            let k = free_key(&r);
            if self.paired_free.contains_key(&k) {
                self.stats.duplicates += 1;
                return;
            }
            let existing = self.waiting_segment.get(&k).or_else(|| self.waiting_position.get(&k));
            match existing {
                Some(old) if *old == r => self.stats.duplicates += 1,
                Some(_) => self.stats.conflicts += 1,
                None => {
                    if self.segment_of(k).is_some() {
                        self.waiting_position.insert(k, r);
                        self.pair_free(out);
                    } else {
                        self.waiting_segment.insert(k, r);
                    }
                }
            }
        }
        self.expire();
    }

    /// Machine coordinates (latched by a trigger, or sampled while moving). Latched ones are
    /// for trigger pairing only: they may travel on another topic than the sampled track and
    /// arrive out of order with it, so they do not enter the interpolation track.
    pub fn position(&mut self, p: PositionEvent, out: &mut Vec<Pair>) {
        self.see(p.stamp_ns);
        let seen = p.trigger_id == 0
            && match self.track.get(&p.stamp_ns) {
                Some(old) => {
                    if old.x != p.x {
                        self.stats.conflicts += 1;
                    }
                    true
                }
                None => {
                    self.track.insert(p.stamp_ns, p);
                    false
                }
            };
        // (`seen` is false for latched positions, which are not tracked.)
        if p.trigger_id != 0 {
            if self.probes.contains_key(&p.trigger_id) {
                return;
            }
            if self.closed.contains(&p.trigger_id) {
                self.stats.duplicates += 1;
                return;
            }
            match self.positions.get(&p.trigger_id) {
                Some(old) if *old == p => self.duplicate_of(p.trigger_id),
                Some(_) => self.stats.conflicts += 1,
                None => {
                    self.positions.insert(p.trigger_id, p);
                    self.try_point(p.trigger_id, out);
                }
            }
        } else if seen {
            self.stats.duplicates += 1;
            return;
        }
        self.pair_free(out);
        self.expire();
    }

    /// An environment sample (attached to the pairs that follow it in time).
    pub fn environment(&mut self, e: EnvironmentEvent) {
        self.environment.insert(e.stamp_ns, e);
    }

    /// Pairs everything still possible and counts what stays incomplete.
    pub fn finish(&mut self, out: &mut Vec<Pair>) -> PairingStats {
        self.pair_free(out);
        let ids: HashSet<u64> = self.triggers.keys().cloned().collect();
        self.stats.incomplete_points += ids.len() as u64;
        self.triggers.clear();
        self.stats.outside_segments += self.waiting_segment.len() as u64;
        self.stats.unbracketed += self.waiting_position.len() as u64;
        self.waiting_segment.clear();
        self.waiting_position.clear();
        self.stats
    }

    fn environment_at(&self, stamp_ns: i64) -> Option<EnvironmentEvent> {
        self.environment.range(..=stamp_ns).next_back().or_else(|| self.environment.iter().next()).map(|(_, e)| *e)
    }

    fn try_point(&mut self, id: u64, out: &mut Vec<Pair>) {
        if !(self.triggers.contains_key(&id) && self.readings.contains_key(&id) && self.positions.contains_key(&id)) {
            return;
        }
        let t = self.triggers.remove(&id).unwrap();
        let r = self.readings.remove(&id).unwrap();
        let p = self.positions.remove(&id).unwrap();
        self.closed.insert(id);
        self.pending_duplicates.remove(&id);
        self.stats.trigger_pairs += 1;
        let machine_ns = p.stamp_ns - self.cfg.clock_offset_ns;
        let beam_broken = self.recorded((t.kind, t.station, t.line), &r);
        out.push(Pair {
            kind: t.kind,
            station: t.station,
            line: t.line,
            point: t.point,
            stamp_ns: r.stamp_ns,
            l_m: r.value_m,
            x: p.x,
            probe_offset: p.probe_offset,
            velocity: p.velocity,
            beam_broken,
            method: Method::Trigger,
            gap_s: (r.stamp_ns - machine_ns).abs() as f64 * 1e-9,
            trigger_id: id,
            environment: self.environment_at(r.stamp_ns),
        });
    }

    /// A reading of `line` that will not be recorded: a count loss it reports goes to the next
    /// recorded reading of the line.
    fn not_recorded(&mut self, line: LineKey, r: &ReadingEvent) {
        if !r.beam_broken {
            return;
        }
        if self.last_pair_ns.get(&line).is_some_and(|&s| s > r.stamp_ns) {
            // A later reading of the line went out without the flag. The next one still gets
            // it, so that the rest of the line keeps its own origin.
            self.stats.late_breaks += 1;
        }
        let b = self.unrecorded_breaks.entry(line).or_insert(r.stamp_ns);
        *b = (*b).min(r.stamp_ns);
    }

    /// Whether a reading about to be recorded on `line` starts a new count: its own flag, or a
    /// count loss that an unrecorded reading of the line reported before it. A loss before the
    /// line's first recorded reading separates nothing (e.g. the beam not yet met on the way to
    /// an on-the-fly line's start) and is dropped.
    fn recorded(&mut self, line: LineKey, r: &ReadingEvent) -> bool {
        let before = self.last_pair_ns.get(&line).copied();
        self.last_pair_ns.insert(line, before.map_or(r.stamp_ns, |last| last.max(r.stamp_ns)));
        match self.unrecorded_breaks.get(&line) {
            Some(&b) if b <= r.stamp_ns => {
                self.unrecorded_breaks.remove(&line);
                if before.is_none() {
                    return r.beam_broken;
                }
                self.stats.carried_breaks += 1;
                true
            }
            _ => r.beam_broken,
        }
    }

    /// The closed segment containing a free-running reading. Readings of a segment still open
    /// wait for its end, which fixes which of them belong to it.
    fn segment_of(&self, k: FreeKey) -> Option<usize> {
        let (t, kind, station, line) = k;
        self.segments.iter().rposition(|s| {
            (s.kind, s.station, s.line) == (kind, station, line) && s.start_ns <= t && s.end_ns.is_some_and(|e| t <= e)
        })
    }

    /// A segment of this line is open since before the reading: it may still claim it.
    fn in_open_segment(&self, k: FreeKey) -> bool {
        let (t, kind, station, line) = k;
        self.segments
            .iter()
            .any(|s| (s.kind, s.station, s.line) == (kind, station, line) && s.start_ns <= t && s.end_ns.is_none())
    }

    fn pair_free(&mut self, out: &mut Vec<Pair>) {
        let Some((&last_pos_ns, _)) = self.track.iter().next_back() else { return };
        while let Some((&k, &r)) = self.waiting_position.iter().next() {
            let t = r.stamp_ns + self.cfg.clock_offset_ns;
            if t > last_pos_ns {
                // The machine samples after this reading have not arrived yet.
                break;
            }
            self.waiting_position.remove(&k);
            let before = self.track.range(..=t).next_back().map(|(_, p)| *p);
            let after = self.track.range(t..).next().map(|(_, p)| *p);
            let (Some(p0), Some(p1)) = (before, after) else {
                self.stats.unbracketed += 1;
                self.not_recorded((r.kind, r.station, r.line), &r);
                continue;
            };
            let gap = p1.stamp_ns - p0.stamp_ns;
            if gap > self.cfg.max_gap_ns {
                self.stats.unbracketed += 1;
                self.not_recorded((r.kind, r.station, r.line), &r);
                continue;
            }
            let Some(si) = self.segment_of(k) else {
                self.stats.outside_segments += 1;
                self.not_recorded((r.kind, r.station, r.line), &r);
                continue;
            };
            let (x, v) = if gap > 0 {
                let (x, v) = path::between(&p0.path_sample(), &p1.path_sample(), t);
                (x.coords.into(), v.into())
            } else {
                (p0.x, p0.velocity)
            };
            let seg = &mut self.segments[si];
            let point = seg.next_point;
            let segment_end = seg.end_trigger;
            seg.next_point += 1;
            self.paired_free.insert(k, ());
            self.stats.interpolated_pairs += 1;
            let beam_broken = self.recorded((r.kind, r.station, r.line), &r);
            out.push(Pair {
                kind: r.kind,
                station: r.station,
                line: r.line,
                point,
                stamp_ns: r.stamp_ns,
                l_m: r.value_m,
                x,
                probe_offset: p0.probe_offset,
                velocity: v,
                beam_broken,
                method: Method::Interpolated,
                gap_s: gap as f64 * 1e-9,
                trigger_id: segment_end,
                environment: self.environment_at(r.stamp_ns),
            });
        }
    }

    /// Forgets what is older than the horizon: free-running readings that no segment claimed,
    /// and the machine track and bookkeeping behind them.
    fn expire(&mut self) {
        // At most every 100 ms of stamp time: the scans below are linear.
        if self.latest_ns < self.expired_at_ns.saturating_add(100_000_000) {
            return;
        }
        self.expired_at_ns = self.latest_ns;
        let limit = self.latest_ns.saturating_sub(self.cfg.horizon_ns);
        if self.waiting_segment.keys().next().is_some_and(|k| k.0 < limit) {
            let old: Vec<FreeKey> =
                self.waiting_segment.range(..(limit, ObsKind::Beam, 0, 0)).map(|(k, _)| *k).collect();
            for k in old {
                if !self.in_open_segment(k) {
                    if let Some(r) = self.waiting_segment.remove(&k) {
                        self.not_recorded((r.kind, r.station, r.line), &r);
                    }
                    self.stats.outside_segments += 1;
                }
            }
        }
        // Keep machine samples that pending readings may still need.
        let oldest_wait = [self.waiting_position.keys().next(), self.waiting_segment.keys().next()]
            .into_iter()
            .flatten()
            .map(|k| k.0 + self.cfg.clock_offset_ns)
            .min();
        let keep_from = oldest_wait.unwrap_or(limit);
        let cut = limit.min(keep_from) - self.cfg.max_gap_ns;
        if self.track.len() > 1024 {
            while let Some((&s, _)) = self.track.iter().next() {
                if s >= cut || self.track.len() <= 2 {
                    break;
                }
                self.track.remove(&s);
            }
        }
        while let Some((&k, _)) = self.paired_free.iter().next() {
            if k.0 >= limit {
                break;
            }
            self.paired_free.remove(&k);
        }
        if self.environment.len() > 64 {
            while self.environment.len() > 2 {
                let (&s, _) = self.environment.iter().next().unwrap();
                let second = *self.environment.keys().nth(1).unwrap();
                if second > limit {
                    break;
                }
                self.environment.remove(&s);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::seq::SliceRandom;
    use rand::SeedableRng;

    enum Ev {
        T(TriggerEvent),
        R(ReadingEvent),
        P(PositionEvent),
    }

    fn feed(p: &mut Pairer, evs: &[Ev]) -> Vec<Pair> {
        let mut out = Vec::new();
        for e in evs {
            match e {
                Ev::T(t) => p.trigger(*t, &mut out),
                Ev::R(r) => p.reading(*r, &mut out),
                Ev::P(x) => p.position(*x, &mut out),
            }
        }
        p.finish(&mut out);
        out.sort_by_key(|q| (q.stamp_ns, q.trigger_id));
        out
    }

    /// A static campaign: per point a probe and a point trigger.
    fn static_events(n: u64) -> Vec<Ev> {
        let mut v = Vec::new();
        for i in 0..n {
            let t = 1_000_000_000 + i as i64 * 10_000_000;
            for (id, ty) in [(2 * i + 1, trigger_type::PROBE), (2 * i + 2, trigger_type::POINT)] {
                let stamp = t + if ty == trigger_type::POINT { 1_000_000 } else { 0 };
                v.push(Ev::T(TriggerEvent {
                    id,
                    trigger_type: ty,
                    kind: ObsKind::Beam,
                    station: 0,
                    line: (i / 10) as u32,
                    point: (i % 10) as u32,
                    stamp_ns: stamp,
                }));
                v.push(Ev::R(ReadingEvent {
                    kind: ObsKind::Beam,
                    station: 0,
                    line: (i / 10) as u32,
                    value_m: i as f64 * 1e-3 + if ty == trigger_type::PROBE { 0.5 } else { 0.0 },
                    signal_strength: 1.0,
                    beam_broken: false,
                    trigger_id: id,
                    stamp_ns: stamp + 100_000,
                }));
                v.push(Ev::P(PositionEvent {
                    x: [i as f64, 0.0, 0.0],
                    probe_offset: [0.0; 3],
                    velocity: [0.0; 3],
                    position_id: 0,
                    in_position: true,
                    trigger_id: id,
                    stamp_ns: stamp + 200_000,
                }));
            }
        }
        v
    }

    #[test]
    fn static_points_pair_by_trigger_in_any_order_with_duplicates() {
        let reference = feed(&mut Pairer::new(PairingConfig::default()), &static_events(50));
        assert_eq!(reference.len(), 50);
        for (i, p) in reference.iter().enumerate() {
            assert_eq!(p.x[0], i as f64);
            assert!((p.l_m - i as f64 * 1e-3).abs() < 1e-15, "a probe reading was paired");
            assert_eq!(p.method, Method::Trigger);
            assert!((p.gap_s - 1e-4).abs() < 1e-12);
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for round in 0..20 {
            let mut evs = static_events(50);
            // Duplicate a third of the messages, then shuffle everything.
            let dups: Vec<Ev> = evs
                .iter()
                .step_by(3)
                .map(|e| match e {
                    Ev::T(t) => Ev::T(*t),
                    Ev::R(r) => Ev::R(*r),
                    Ev::P(p) => Ev::P(*p),
                })
                .collect();
            // Messages of probe triggers are ignored, not counted.
            let n_dups = dups
                .iter()
                .filter(|e| match e {
                    Ev::T(t) => t.trigger_type == trigger_type::POINT,
                    Ev::R(r) => r.trigger_id % 2 == 0,
                    Ev::P(p) => p.trigger_id % 2 == 0,
                })
                .count() as u64;
            evs.extend(dups);
            evs.shuffle(&mut rng);
            let mut pairer = Pairer::new(PairingConfig::default());
            let got = feed(&mut pairer, &evs);
            assert_eq!(got, reference, "round {round}");
            let s = pairer.stats();
            assert_eq!(s.duplicates, n_dups, "round {round}");
            assert_eq!((s.conflicts, s.incomplete_points), (0, 0));
        }
    }

    /// The static events with the probe reading before point `k` reporting a lost count.
    fn probe_breaks_before(k: u64) -> Vec<Ev> {
        let mut evs = static_events(20);
        for e in evs.iter_mut() {
            if let Ev::R(r) = e {
                if r.trigger_id == 2 * k + 1 {
                    r.beam_broken = true;
                }
            }
        }
        evs
    }

    fn broken_points(pairs: &[Pair]) -> Vec<(u32, u32)> {
        pairs.iter().filter(|p| p.beam_broken).map(|p| (p.line, p.point)).collect()
    }

    /// An instrument restarted in the middle of a line re-establishes its count at the probe
    /// before the next point: that probe is not recorded, so the point must say it.
    #[test]
    fn a_count_lost_at_a_probe_is_carried_to_the_next_point() {
        let mut pairer = Pairer::new(PairingConfig::default());
        let got = feed(&mut pairer, &probe_breaks_before(4));
        assert_eq!(got.len(), 20);
        assert_eq!(broken_points(&got), vec![(0, 4)]);
        assert_eq!((pairer.stats().carried_breaks, pairer.stats().late_breaks), (1, 0));

        // The probe's reading before its trigger: kept until the trigger says it is a probe.
        let mut evs = probe_breaks_before(4);
        let r = evs.iter().position(|e| matches!(e, Ev::R(r) if r.trigger_id == 9)).unwrap();
        let t = evs.iter().position(|e| matches!(e, Ev::T(t) if t.id == 9)).unwrap();
        evs.swap(r, t);
        assert_eq!(broken_points(&feed(&mut Pairer::new(PairingConfig::default()), &evs)), vec![(0, 4)]);

        // The probe's reading after point 4 went out: counted as late, and point 5 still
        // starts a new count, so that the rest of the line keeps its own origin.
        let mut evs = probe_breaks_before(4);
        let r = evs.iter().position(|e| matches!(e, Ev::R(r) if r.trigger_id == 9)).unwrap();
        let late = evs.remove(r);
        let p5 = evs.iter().position(|e| matches!(e, Ev::T(t) if t.id == 11)).unwrap();
        evs.insert(p5, late);
        let mut pairer = Pairer::new(PairingConfig::default());
        assert_eq!(broken_points(&feed(&mut pairer, &evs)), vec![(0, 5)]);
        assert_eq!(pairer.stats().late_breaks, 1);

        // A loss before a line's first recorded point separates nothing.
        let mut pairer = Pairer::new(PairingConfig::default());
        assert!(broken_points(&feed(&mut pairer, &probe_breaks_before(10))).is_empty());
        assert_eq!(pairer.stats().carried_breaks, 0);
    }

    #[test]
    fn missing_partner_is_counted_not_invented() {
        let mut evs = static_events(5);
        // Drop the machine coordinates of the third point trigger (id 6).
        evs.retain(|e| !matches!(e, Ev::P(p) if p.trigger_id == 6));
        let mut pairer = Pairer::new(PairingConfig::default());
        let got = feed(&mut pairer, &evs);
        assert_eq!(got.len(), 4);
        assert!(got.iter().all(|p| p.trigger_id != 6));
        assert_eq!(pairer.stats().incomplete_points, 1);
    }

    fn otf_events() -> (Vec<Ev>, usize) {
        // The machine moves along X at 0.1 m/s, sampled at 1 kHz with stamps offset by 0.3 ms
        // from the interferometer's 1 kHz samples. Segment from 0.1 s to 0.9 s.
        let mut v = Vec::new();
        let t0 = 5_000_000_000i64;
        let seg = |id, ty, at| {
            Ev::T(TriggerEvent {
                id,
                trigger_type: ty,
                kind: ObsKind::Beam,
                station: 1,
                line: 2,
                point: 0,
                stamp_ns: at,
            })
        };
        v.push(seg(1, trigger_type::SEGMENT_START, t0 + 100_000_000));
        let mut inside = 0;
        for k in 0..1000i64 {
            let tm = t0 + k * 1_000_000 + 300_000;
            v.push(Ev::P(PositionEvent {
                x: [0.1 * (tm - t0) as f64 * 1e-9, 0.2, 0.3],
                probe_offset: [0.0, 0.0, -0.1],
                velocity: [0.1, 0.0, 0.0],
                position_id: 1,
                in_position: false,
                trigger_id: 0,
                stamp_ns: tm,
            }));
            let ti = t0 + k * 1_000_000;
            if (100_000_000..=900_000_000).contains(&(ti - t0)) {
                inside += 1;
            }
            v.push(Ev::R(ReadingEvent {
                kind: ObsKind::Beam,
                station: 1,
                line: 2,
                value_m: 0.1 * (ti - t0) as f64 * 1e-9,
                signal_strength: 1.0,
                beam_broken: false,
                trigger_id: 0,
                stamp_ns: ti,
            }));
        }
        v.push(seg(2, trigger_type::SEGMENT_END, t0 + 900_000_000));
        (v, inside)
    }

    #[test]
    fn on_the_fly_interpolates_inside_segments_in_any_order() {
        let (evs, inside) = otf_events();
        let reference = feed(&mut Pairer::new(PairingConfig::default()), &evs);
        assert_eq!(reference.len(), inside);
        for p in &reference {
            // Linear motion: the interpolated X equals the abscissa exactly.
            assert!((p.x[0] - p.l_m).abs() < 1e-12, "{p:?}");
            assert!((p.velocity[0] - 0.1).abs() < 1e-9);
            assert_eq!(p.method, Method::Interpolated);
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let (mut evs, _) = otf_events();
        // Shuffle within windows of 200 messages (DDS reorders locally, not across seconds),
        // and duplicate every fifth message.
        for w in evs.chunks_mut(200) {
            w.shuffle(&mut rng);
        }
        let mut with_dups = Vec::new();
        for (i, e) in evs.into_iter().enumerate() {
            let copy = match &e {
                Ev::T(t) => Ev::T(*t),
                Ev::R(r) => Ev::R(*r),
                Ev::P(p) => Ev::P(*p),
            };
            with_dups.push(e);
            if i % 5 == 0 {
                with_dups.push(copy);
            }
        }
        let mut pairer = Pairer::new(PairingConfig::default());
        let got = feed(&mut pairer, &with_dups);
        assert_eq!(got.len(), reference.len());
        for (a, b) in got.iter().zip(&reference) {
            assert_eq!((a.stamp_ns, a.l_m, a.x), (b.stamp_ns, b.l_m, b.x));
        }
        assert!(pairer.stats().duplicates > 0);
    }

    #[test]
    fn clock_offset_shifts_the_machine_track() {
        let (evs, _) = otf_events();
        // Declaring the machine clock 0.3 ms ahead pairs each reading with the sample stamped
        // 0.3 ms later: X then leads the abscissa by 0.1 m/s * 0.3 ms.
        let cfg = PairingConfig { clock_offset_ns: 300_000, ..PairingConfig::default() };
        let got = feed(&mut Pairer::new(cfg), &evs);
        for p in &got {
            assert!((p.x[0] - p.l_m - 0.1 * 0.3e-3).abs() < 1e-12);
            assert!(p.gap_s < 1e-12);
        }
    }
}
