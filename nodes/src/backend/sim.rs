//! Simulated backends: the components of `volcal_sim` (virtual machine, deflector,
//! interferometer, tracer, environment) driven step by step by the sim nodes.
//!
//! Every sim node builds the same [`SimWorld`] from the machine file, the plan and the seed, so
//! that they agree on the true error model and the stations without being told. What only one
//! node can know (the actual beam after the deflector's pointing error, the actual reflector
//! position including the machine's repeatability) travels on `/sim/truth/...` as [`Truth`].
//! The solver never subscribes to those topics.

use super::injected::{CampaignClock, Injected, OpticalSample, Zero};
use super::*;
use crate::ros::NodeArgs;
use anyhow::{anyhow, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;
use volcal::campaign::ObsKind;
use volcal::environment::AirIndexEquation;
use volcal::path::{self, PathSample};
use volcal_formats::machine::{Machine, DEMO_MACHINE};
use volcal_formats::plan::{load_plan, sim_config};
use volcal_sim::{BeamLine, Plan, SimConfig};

/// Below this return-signal strength the interferometer loses its count.
pub const LOSS_THRESHOLD: f64 = 0.05;

/// The simulated world shared by the sim nodes.
pub struct SimWorld {
    pub machine: Machine,
    pub plan: Plan,
    pub cfg: SimConfig,
    pub seed: u64,
    /// The laboratory's clock: air drift and every time-dependent injected effect run on it.
    pub clock: CampaignClock,
    /// Physics outside the rigid-body model ([`super::injected`]).
    pub injected: Injected,
}

impl SimWorld {
    /// From node parameters `machine` (default: the built-in demo machine), `plan` (default: the
    /// patent's example), `seed` (default 1), `inject` (effect specs, default none),
    /// `time_scale` (campaign seconds per second of the run, default 1) and `air_rate_k_per_h`
    /// (the air temperature's drift, default the machine file's). The time origin is
    /// `VOLCAL_SIM_EPOCH_NS` (set by `volcal launch` for all nodes) or now.
    pub fn from_args(args: &NodeArgs) -> Result<SimWorld> {
        let machine = match args.path("machine")? {
            Some(p) => Machine::load(&p)?,
            None => Machine::parse(DEMO_MACHINE)?,
        };
        let plan = load_plan(args.path("plan")?.as_deref())?;
        let seed: u64 = args.get_or("seed", 1)?;
        let epoch_ns =
            std::env::var("VOLCAL_SIM_EPOCH_NS").ok().and_then(|s| s.parse().ok()).unwrap_or_else(crate::ros::now_ns);
        let time_scale: f64 = args.get_or("time_scale", 1.0)?;
        if !(time_scale > 0.0 && time_scale.is_finite()) {
            return Err(anyhow!("parameter time_scale: must be a positive number, got {time_scale}"));
        }
        let mut cfg = sim_config(&machine, plan.clone(), seed);
        // (An empty value, a launch argument's default, keeps the machine file's.)
        match args.get::<serde_yaml::Value>("air_rate_k_per_h")? {
            None => {}
            Some(serde_yaml::Value::String(s)) if s.is_empty() => {}
            Some(v) => match v.as_f64().filter(|r| r.is_finite()) {
                Some(rate) => cfg.environment.air_temp_rate_k_per_h = rate,
                None => return Err(anyhow!("parameter air_rate_k_per_h: {v:?} is not a number of kelvin per hour")),
            },
        }
        let injected = Injected::parse(&args.get_or("inject", String::new())?, &cfg, machine.layout.travel)?;
        Ok(SimWorld { machine, plan, cfg, seed, clock: CampaignClock { epoch_ns, time_scale }, injected })
    }

    /// Seconds of campaign time at `ns`.
    pub fn t_s(&self, ns: i64) -> f64 {
        self.clock.t_s(ns)
    }

    /// An independent random stream for one component.
    pub fn rng(&self, component: u64) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(self.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ component)
    }

    /// Writes the truth a sim node knows of this world (the true error model and the injected
    /// effects) to a truth file, for tests; never recorded in a bag.
    pub fn write_truth(&self, path: &std::path::Path) -> Result<()> {
        let truth = volcal_sim::Truth {
            model: self.cfg.machine.truth.clone(),
            beams: vec![],
            stations: vec![],
            tracer_dead_path_m: self.cfg.tracer.dead_path_m,
            injected: self.injected.truth(),
        };
        let mut file = volcal_formats::truth_file::TruthFile::new(&truth, self.seed, self.machine.gauge);
        file.campaign_time_scale = Some(self.clock.time_scale);
        file.write(path)
    }
}

fn info_of(i: &volcal_sim::Interferometer, instrument: &str) -> InstrumentInfo {
    InstrumentInfo {
        instrument: instrument.to_string(),
        wavelength_vac_m: i.wavelength_vac_m,
        compensated: i.assumed_index.is_none(),
        assumed_index: i.assumed_index.unwrap_or(1.0),
        air_equation: match i.air_equation {
            AirIndexEquation::Ciddor => "ciddor".into(),
            AirIndexEquation::Edlen => "edlen".into(),
        },
    }
}

/// Recent reflector truth samples, to find the one for a position or interpolate in time.
#[derive(Default)]
struct ReflectorHistory {
    samples: VecDeque<PathSample>,
}

impl ReflectorHistory {
    fn push(&mut self, t: &Truth) {
        if let Truth::Reflector { stamp_ns, position_id, settled, actual, velocity } = *t {
            // Kept in stamp order (DDS delivers one writer's samples in order; this guards
            // against anything else).
            let i = self.samples.partition_point(|s| s.stamp_ns <= stamp_ns);
            let sample = PathSample { stamp_ns, motion_id: position_id, at_rest: settled, position: actual, velocity };
            self.samples.insert(i, sample);
            // A few seconds at the machine's sampling rate: more than any reading waits.
            while self.samples.len() > 8192 {
                self.samples.pop_front();
            }
        }
    }

    /// The actual position at rest at the target of `position_id`, or (free-running) at `at_ns`,
    /// interpolated between the truth samples around it: `None` until the machine has published
    /// a sample at or after `at_ns` (the simulated instrument never reads the future).
    fn actual(&self, at_ns: i64, position_id: Option<u64>) -> Option<Point3<f64>> {
        match position_id {
            Some(id) => self.samples.iter().rev().find(|s| s.motion_id == id && s.at_rest).map(|s| s.position),
            None => {
                let i = self.samples.partition_point(|s| s.stamp_ns < at_ns);
                if i == self.samples.len() {
                    return None;
                }
                let s1 = &self.samples[i];
                if i == 0 || s1.stamp_ns == at_ns {
                    return (s1.stamp_ns == at_ns).then_some(s1.position);
                }
                // Between samples: `volcal::path`'s rule, the one the recorder pairs with.
                Some(path::between(&self.samples[i - 1], s1, at_ns).0)
            }
        }
    }
}

/// Counter state shared by the simulated interferometer and tracer.
#[derive(Default)]
struct Counter {
    zero: f64,
    valid: bool,
    /// A new beam or station: the next reading at point 0 zeroes the count normally.
    fresh: bool,
}

impl Counter {
    /// Applies the signal to the count; returns the reading relative to the count origin.
    fn count(&mut self, length: f64, signal: f64, point: Option<u32>) -> (f64, bool) {
        if signal < LOSS_THRESHOLD {
            self.valid = false;
            return (length - self.zero, true);
        }
        let mut broken = false;
        if !self.valid {
            // A fresh beam zeroed at its first point is normal; anything else re-establishes the
            // count mid-line, so the origin of what follows is new.
            broken = !(self.fresh && point.is_none_or(|p| p == 0));
            self.zero = length;
            self.valid = true;
            self.fresh = false;
        }
        (length - self.zero, broken)
    }

    fn restart(&mut self) {
        self.valid = false;
        self.fresh = true;
    }
}

/// The simulated fixed-beam interferometer.
pub struct SimInterferometer {
    world_cfg: SimConfig,
    clock: CampaignClock,
    injected: Injected,
    rng: ChaCha8Rng,
    /// Relative noise of the signal-strength reading.
    pub signal_noise: f64,
    /// The beam the deflector last reported (station, beam).
    ids: Option<(u32, u32)>,
    /// The true beams, each from the instant it settled, in time order.
    beams: Vec<(i64, u32, u32, BeamLine)>,
    /// The beam the count refers to.
    counted: Option<(i64, u32, u32)>,
    reflector: ReflectorHistory,
    counter: Counter,
    /// Where the count of the current beam started, and the readings since (free-running
    /// samples count as points for the injected effects).
    zero: Option<(Zero, usize)>,
    /// The current on-the-fly segment: its start and the samples read in it since.
    segment: Option<(i64, usize)>,
}

impl SimInterferometer {
    pub fn new(world: &SimWorld, signal_noise: f64) -> SimInterferometer {
        SimInterferometer {
            world_cfg: world.cfg.clone(),
            clock: world.clock,
            injected: world.injected.clone(),
            rng: world.rng(0x494e_5446),
            signal_noise,
            ids: None,
            beams: Vec::new(),
            counted: None,
            reflector: ReflectorHistory::default(),
            counter: Counter::default(),
            zero: None,
            segment: None,
        }
    }

    /// The true beam for a reading at `at_ns`: for a triggered reading, the beam the deflector
    /// reports now (once its truth has arrived); for a free-running sample, which may be
    /// computed a little after its instant, the beam that was settled at that instant.
    fn beam_for(&self, at_ns: i64, triggered: bool) -> Option<(i64, u32, u32, BeamLine)> {
        if triggered {
            self.beams.last().filter(|b| Some((b.1, b.2)) == self.ids).copied()
        } else {
            self.beams.iter().rev().find(|b| b.0 <= at_ns).copied()
        }
    }
}

/// Lateral distance of `p` from a beam.
fn lateral(beam: &BeamLine, p: &Point3<f64>) -> f64 {
    let v = p - beam.origin;
    (v - beam.direction * beam.direction.dot(&v)).norm()
}

impl InterferometerBackend for SimInterferometer {
    fn info(&self) -> InstrumentInfo {
        info_of(&self.world_cfg.interferometer, "simulated laser interferometer (volcal_sim)")
    }

    fn new_beam(&mut self, station: u32, beam: u32) {
        // The count restarts with the first reading on the new true beam (see `read`).
        self.ids = Some((station, beam));
    }

    fn segment_start(&mut self, stamp_ns: i64) {
        self.segment = Some((stamp_ns, 0));
    }

    fn read(&mut self, at_ns: i64, point: Option<u32>, position_id: Option<u64>) -> Result<Option<LengthReading>> {
        // `None` until the true beam (and the reflector truth) for this reading have arrived.
        let Some((since, s, b, beam)) = self.beam_for(at_ns, position_id.is_some()) else { return Ok(None) };
        let Some(actual) = self.reflector.actual(at_ns, position_id) else { return Ok(None) };
        if self.counted != Some((since, s, b)) {
            self.counted = Some((since, s, b));
            self.counter.restart();
            self.zero = None;
        }
        let d = lateral(&beam, &actual);
        let noise: f64 = self.rng.random_range(-1.0..1.0) * self.signal_noise;
        let signal = (self.world_cfg.deflector.signal_strength(d) * (1.0 + noise)).clamp(0.0, 1.0);
        let t_s = self.clock.t_s(at_ns);
        let air = self.world_cfg.environment.air_at(t_s);
        let mut length = beam.direction.dot(&(actual - beam.origin));
        if !self.injected.is_empty() {
            let (zero, n) = *self.zero.get_or_insert((Zero { t_s, length_m: length, air }, 0));
            // A free-running sample's place in its line: its number in the on-the-fly segment.
            let index = match (point, &mut self.segment) {
                (Some(p), _) => p as usize,
                (None, Some((start, k))) if at_ns >= *start => {
                    *k += 1;
                    *k - 1
                }
                (None, _) => n,
            };
            self.injected.optical(
                &OpticalSample {
                    kind: ObsKind::Beam,
                    station: s,
                    line: b,
                    index,
                    t_s,
                    direction: beam.direction,
                    station_position: beam.origin,
                    reflector: actual,
                    air,
                    zero,
                },
                &mut length,
            );
            self.zero = Some((zero, n + 1));
        }
        let (rel, broken) = self.counter.count(length, signal, point);
        let value = self.world_cfg.interferometer.read(rel, 0.0, &air, &mut self.rng);
        Ok(Some(LengthReading { value_m: value, signal_strength: signal, beam_broken: broken }))
    }

    fn truth(&mut self, t: &Truth) {
        match t {
            Truth::Beam { stamp_ns, station, beam, origin, direction } => {
                let line = BeamLine { origin: *origin, direction: *direction };
                if !self.beams.iter().any(|x| x.0 == *stamp_ns && (x.1, x.2) == (*station, *beam)) {
                    let i = self.beams.partition_point(|x| x.0 <= *stamp_ns);
                    self.beams.insert(i, (*stamp_ns, *station, *beam, line));
                }
                if self.beams.len() > 16 {
                    self.beams.remove(0);
                }
            }
            Truth::Reflector { .. } => self.reflector.push(t),
        }
    }

    fn simulated(&self) -> bool {
        true
    }
}

/// The simulated laser tracer: stations from the plan, ranges to the actual reflector.
pub struct SimTracer {
    world_cfg: SimConfig,
    clock: CampaignClock,
    injected: Injected,
    /// Where the current station's count started, and the readings since.
    zero: Option<(Zero, usize)>,
    rng: ChaCha8Rng,
    stations: Vec<Point3<f64>>,
    station: Option<u32>,
    reflector: ReflectorHistory,
    counter: Counter,
    /// Extra dead path after a lost count (the tracer re-establishes it at an unknown value).
    extra_dead_path: f64,
}

impl SimTracer {
    pub fn new(world: &SimWorld) -> Result<SimTracer> {
        let travel = world.machine.layout.travel;
        let stations = world.plan.path_tasks(&travel).map_err(|e| anyhow!("{e}"))?.iter().map(|t| t.position).collect();
        Ok(SimTracer {
            world_cfg: world.cfg.clone(),
            clock: world.clock,
            injected: world.injected.clone(),
            zero: None,
            rng: world.rng(0x5452_4143),
            stations,
            station: None,
            reflector: ReflectorHistory::default(),
            counter: Counter::default(),
            extra_dead_path: 0.0,
        })
    }
}

impl TracerBackend for SimTracer {
    fn info(&self) -> InstrumentInfo {
        info_of(&self.world_cfg.interferometer, "simulated laser tracer (volcal_sim)")
    }

    fn new_station(&mut self, station: u32) {
        if self.station != Some(station) {
            self.station = Some(station);
            self.counter.restart();
            self.zero = None;
        }
    }

    fn read(&mut self, at_ns: i64, point: Option<u32>, position_id: Option<u64>) -> Result<Option<LengthReading>> {
        let Some(station) = self.station else { return Ok(None) };
        let q = *self
            .stations
            .get(station as usize)
            .ok_or_else(|| anyhow!("tracer station {station} is not in the plan ({} stations)", self.stations.len()))?;
        let Some(actual) = self.reflector.actual(at_ns, position_id) else { return Ok(None) };
        let mut range = (actual - q).norm();
        if !self.injected.is_empty() {
            let t_s = self.clock.t_s(at_ns);
            let air = self.world_cfg.environment.air_at(t_s);
            let (zero, n) = *self.zero.get_or_insert((Zero { t_s, length_m: range, air }, 0));
            self.injected.optical(
                &OpticalSample {
                    kind: ObsKind::Range,
                    station,
                    line: 0,
                    index: point.map_or(n, |p| p as usize),
                    t_s,
                    direction: (actual - q) / range,
                    station_position: q,
                    reflector: actual,
                    air,
                    zero,
                },
                &mut range,
            );
            self.zero = Some((zero, n + 1));
        }
        let range = self.world_cfg.tracer.read_range(range, &mut self.rng);
        // The tracer keeps its count unless the reflector leaves its view; the counter models
        // re-establishment with a new dead path.
        let (_, broken) = self.counter.count(0.0, 1.0, point);
        if broken {
            self.extra_dead_path = self.rng.random_range(0.0..1e-3);
        }
        Ok(Some(LengthReading { value_m: range - self.extra_dead_path, signal_strength: 1.0, beam_broken: broken }))
    }

    fn truth(&mut self, t: &Truth) {
        self.reflector.push(t);
    }

    fn simulated(&self) -> bool {
        true
    }
}

/// The simulated beam deflector.
pub struct SimDeflector {
    deflector: volcal_sim::Deflector,
    rng: ChaCha8Rng,
    /// Settling time after a command, seconds (machine file value unless overridden).
    pub settle_s: f64,
    state: Option<(f64, f64, Point3<f64>, BeamLine, i64)>,
}

impl SimDeflector {
    pub fn new(world: &SimWorld, settle_s: Option<f64>) -> SimDeflector {
        SimDeflector {
            deflector: world.cfg.deflector.clone(),
            rng: world.rng(0x4445_464c),
            settle_s: settle_s.unwrap_or(world.cfg.deflector.settle_s),
            state: None,
        }
    }
}

impl DeflectorBackend for SimDeflector {
    fn command(&mut self, pivot: Point3<f64>, az: f64, el: f64, now_ns: i64) -> Result<()> {
        let beam = self.deflector.point(&pivot, az, el, &mut self.rng);
        self.state = Some((az, el, pivot, beam, now_ns + (self.settle_s * 1e9) as i64));
        Ok(())
    }

    fn readback(&mut self, now_ns: i64) -> DeflectorReadback {
        match self.state {
            None => DeflectorReadback { azimuth_rad: 0.0, elevation_rad: 0.0, settled: false, geometry: None },
            Some((az, el, pivot, _, until)) => DeflectorReadback {
                azimuth_rad: az,
                elevation_rad: el,
                settled: now_ns >= until,
                geometry: Some((pivot, volcal_sim::instruments::direction_from_angles(az, el))),
            },
        }
    }

    fn next_change_ns(&self) -> Option<i64> {
        self.state.map(|s| s.4)
    }

    fn truth_beam(&mut self, now_ns: i64) -> Option<(Point3<f64>, Vector3<f64>)> {
        self.state.filter(|s| now_ns >= s.4).map(|s| (s.3.origin, s.3.direction))
    }
}

/// The actual reflector position of a simulated machine: at rest, with the repeatability drawn
/// once per arrival (the same position for as long as the machine stays), and the path leaving
/// it offset alike;
/// the injected machine-side effects on top ([`super::injected`]). The simulated machine and a
/// cell's dry run (`machine_cell`) both play the machine this way.
pub struct ActualReflector {
    vm: volcal_sim::VirtualMachine,
    rng: ChaCha8Rng,
    injected: Injected,
    clock: CampaignClock,
    at_rest: Option<(u64, Point3<f64>)>,
    /// Unit direction of the last move (backlash acts against it), zero before the first.
    motion: Vector3<f64>,
    /// The repeatability drawn at the last rest (actual minus exact position): it holds until
    /// the machine settles again, so the path leaving a rest is continuous with it.
    scatter: Vector3<f64>,
    /// Inside an on-the-fly run: the scatter of its start holds at its turns and end too (a
    /// continuous run does not settle anew; a fresh draw at a turn would put a step into the
    /// readings that no machine makes).
    continuous: bool,
}

impl ActualReflector {
    pub fn new(world: &SimWorld) -> ActualReflector {
        ActualReflector {
            vm: world.cfg.machine.clone(),
            rng: world.rng(0x4d41_4348),
            injected: world.injected.clone(),
            clock: world.clock,
            at_rest: None,
            motion: Vector3::zeros(),
            scatter: Vector3::zeros(),
            continuous: false,
        }
    }

    /// An on-the-fly run starts (`true`) or ends.
    pub fn set_continuous(&mut self, on: bool) {
        self.continuous = on;
    }

    /// The actual position at `now_ns` for indicated coordinates `x`, declared offset `p` and
    /// velocity `v`, during motion `id`.
    pub fn at(
        &mut self,
        now_ns: i64,
        id: u64,
        settled: bool,
        x: &Point3<f64>,
        p: &Vector3<f64>,
        v: &Vector3<f64>,
    ) -> Point3<f64> {
        let speed = v.norm();
        if speed > 0.0 {
            self.motion = v / speed;
        }
        if settled {
            if let Some((i, a)) = self.at_rest {
                if i == id {
                    return a;
                }
            }
        }
        let t_s = self.clock.t_s(now_ns);
        let a = if settled && !self.continuous {
            let p_actual = self.injected.probe_offset(t_s, x, p, &self.motion);
            let exact = self.vm.exact(x, &p_actual);
            let drawn = self.vm.actual(x, &p_actual, &mut self.rng);
            self.scatter = drawn - exact;
            let mut a = drawn;
            self.injected.actual(t_s, x, p, v, &self.motion, &mut a);
            a
        } else {
            self.path(t_s, x, p, v)
        };
        if settled {
            self.at_rest = Some((id, a));
        }
        a
    }

    /// The actual velocity at `now_ns` of a reflector moving with indicated velocity `v`
    /// through `x`: what the error functions and the injected effects make of `v` (a periodic
    /// pitch error, for one, speeds the reflector up and slows it down along its period). Zero
    /// at rest. The simulated instruments interpolate the truth samples with it (cubic
    /// Hermite); a linear interpolation of samples 1 mm apart flattens a 16 mm period by 2 %.
    pub fn velocity(&self, now_ns: i64, x: &Point3<f64>, p: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
        if v.norm() == 0.0 {
            return Vector3::zeros();
        }
        // A central difference over ±10 us along the path: at 2 m/s, ±20 um, whose truncation
        // error on a 16 mm period is below 1e-6 of the velocity.
        const H_S: f64 = 1e-5;
        let t_s = self.clock.t_s(now_ns);
        let dt = H_S * self.clock.time_scale;
        let ahead = self.path(t_s + dt, &(x + v * H_S), p, v);
        let behind = self.path(t_s - dt, &(x - v * H_S), p, v);
        (ahead - behind) / (2.0 * H_S)
    }

    /// The actual position along a path leaving the last rest (its scatter carried along), at
    /// campaign time `t_s`: no draw, no state changed.
    fn path(&self, t_s: f64, x: &Point3<f64>, p: &Vector3<f64>, v: &Vector3<f64>) -> Point3<f64> {
        let p_actual = self.injected.probe_offset(t_s, x, p, &self.motion);
        let mut a = self.vm.exact(x, &p_actual) + self.scatter;
        self.injected.actual(t_s, x, p, v, &self.motion, &mut a);
        a
    }
}

/// The simulated machine: straight-line motion at the commanded speed; the actual reflector
/// position from the true error model ([`ActualReflector`]); the coordinates it reports as the
/// injected recording-side effects (a latency, warm scales) leave them.
pub struct SimMachine {
    reflector: ActualReflector,
    injected: Injected,
    clock: CampaignClock,
    from: Point3<f64>,
    cmd: MotionCommand,
    t0_ns: i64,
    /// The injected latency: the state reported at `t` is the machine's at `t - delay_ns`.
    delay_ns: i64,
}

impl SimMachine {
    pub fn new(world: &SimWorld, now_ns: i64) -> SimMachine {
        let home = world.machine.layout.travel.centre();
        SimMachine {
            reflector: ActualReflector::new(world),
            injected: world.injected.clone(),
            clock: world.clock,
            from: home,
            cmd: MotionCommand { position_id: 0, target: home, probe_offset: Vector3::zeros(), speed_mps: 1.0 },
            t0_ns: now_ns,
            delay_ns: world.injected.delay_ns(),
        }
    }

    fn arrival_ns(&self) -> i64 {
        let d = (self.cmd.target - self.from).norm();
        self.t0_ns + (d / self.cmd.speed_mps * 1e9) as i64
    }

    /// Where the machine is by its scales (the coordinates of the true error model).
    fn kinematic(&self, now_ns: i64) -> MachineState {
        let arrive = self.arrival_ns();
        let (position, velocity, in_position) = if now_ns >= arrive {
            (self.cmd.target, Vector3::zeros(), true)
        } else {
            let d = self.cmd.target - self.from;
            let dir = d / d.norm();
            let s = (now_ns - self.t0_ns).max(0) as f64 * 1e-9 * self.cmd.speed_mps;
            (self.from + dir * s, dir * self.cmd.speed_mps, false)
        };
        MachineState {
            position,
            velocity,
            probe_offset: self.cmd.probe_offset,
            in_position,
            position_id: self.cmd.position_id,
        }
    }
}

impl MachineBackend for SimMachine {
    fn move_to(&mut self, cmd: &MotionCommand, now_ns: i64) -> Result<()> {
        if !(cmd.speed_mps > 0.0 && cmd.speed_mps.is_finite()) {
            anyhow::bail!("motion {}: speed {} m/s is not a positive number", cmd.position_id, cmd.speed_mps);
        }
        let here = self.kinematic(now_ns).position;
        self.from = here;
        self.cmd = *cmd;
        self.t0_ns = now_ns;
        Ok(())
    }

    fn state(&mut self, now_ns: i64) -> MachineState {
        // A latency delays the whole state: where the machine was, its velocity and whether it
        // had arrived. Applied as `x - v tau` (the recording-side hook, given the velocity) it
        // would be wrong near a corner, and the node's corner samples would stand at the
        // undelayed corners: the reported path, interpolated between them, is then off by up to
        // `v tau` for a sample interval after each start, which the diagnosis read as small
        // beam breaks. The hook is given no velocity, so that the delay is not applied twice.
        let at = now_ns - self.delay_ns;
        let s = self.kinematic(at);
        let (position, _) =
            self.injected.record(self.clock.t_s(at), &s.position, &s.probe_offset, &Vector3::zeros(), None);
        MachineState { position, ..s }
    }

    fn next_change_ns(&self) -> Option<i64> {
        Some(self.arrival_ns() + self.delay_ns)
    }

    fn start_corner_ns(&self, now_ns: i64) -> i64 {
        now_ns + self.delay_ns
    }

    fn on_the_fly(&mut self, running: bool) {
        self.reflector.set_continuous(running);
    }

    fn truth(&mut self, now_ns: i64) -> Option<Truth> {
        let s = self.kinematic(now_ns);
        let actual = self.reflector.at(now_ns, s.position_id, s.in_position, &s.position, &s.probe_offset, &s.velocity);
        Some(Truth::Reflector {
            stamp_ns: now_ns,
            position_id: s.position_id,
            settled: s.in_position,
            actual,
            velocity: self.reflector.velocity(now_ns, &s.position, &s.probe_offset, &s.velocity),
        })
    }
}

/// Simulated environment sensors (`EnvironmentSim` of the machine file), on the campaign clock;
/// the machine temperature as the injected effects leave it (warm scales).
pub struct SimEnvironment {
    env: volcal_sim::EnvironmentSim,
    clock: CampaignClock,
    injected: Injected,
}

impl SimEnvironment {
    pub fn new(world: &SimWorld) -> SimEnvironment {
        SimEnvironment { env: world.cfg.environment.clone(), clock: world.clock, injected: world.injected.clone() }
    }
}

impl EnvironmentBackend for SimEnvironment {
    fn read(&mut self, now_ns: i64) -> Result<EnvironmentSample> {
        let t = self.clock.t_s(now_ns);
        let temp = self.env.record_machine_temp.then_some(self.env.machine_temp_c);
        let (_, machine_temp_c) =
            self.injected.record(t, &Point3::origin(), &Vector3::zeros(), &Vector3::zeros(), temp);
        Ok(EnvironmentSample {
            air: self.env.record_air.then(|| self.env.air_at(t)),
            machine_temp_c,
            materials: Vec::new(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn world(inject: &str) -> SimWorld {
        let args = ["--ros-args", "-p", &format!("inject:={inject}")].map(String::from);
        SimWorld::from_args(&NodeArgs::parse(&args).unwrap()).unwrap()
    }

    #[test]
    fn a_latency_delays_the_whole_state_corners_included() {
        let tau = 175;
        let (plain, late) = (world(""), world(&format!("latency:latency_s={tau}e-9")));
        let (mut a, mut b) = (SimMachine::new(&plain, 0), SimMachine::new(&late, 0));
        let target = plain.machine.layout.travel.centre() + Vector3::new(0.01, 0.0, 0.0);
        let cmd = MotionCommand { position_id: 1, target, probe_offset: Vector3::zeros(), speed_mps: 2.0 };
        a.move_to(&cmd, 1_000_000).unwrap();
        b.move_to(&cmd, 1_000_000).unwrap();
        // The motion leaves where the delayed coordinates leave, and arrives a latency late.
        assert_eq!(b.start_corner_ns(1_000_000), 1_000_000 + tau);
        assert_eq!(b.next_change_ns(), a.next_change_ns().map(|t| t + tau));
        // Around the start (at rest, then moving), mid-motion and around the arrival.
        for t in
            [999_000, 1_000_000, 1_000_100, 1_000_175, 1_000_300, 3_000_000, 5_999_900, 6_000_000, 6_000_100, 6_000_200]
        {
            let (sa, sb) = (a.state(t), b.state(t + tau));
            assert_eq!((sb.position, sb.velocity, sb.in_position), (sa.position, sa.velocity, sa.in_position), "{t}");
        }
    }

    #[test]
    fn counter_flags_mid_line_restarts_only() {
        let mut c = Counter::default();
        c.restart();
        assert_eq!(c.count(1.0, 1.0, Some(0)), (0.0, false));
        assert_eq!(c.count(1.5, 1.0, Some(1)), (0.5, false));
        // Lost, then re-established mid-beam: a new origin, flagged.
        assert!(c.count(1.6, 0.01, Some(2)).1);
        assert_eq!(c.count(1.7, 1.0, Some(3)), (0.0, true));
        // A node restarted mid-beam (fresh, but first reading at point 7) is flagged too.
        let mut c = Counter::default();
        c.restart();
        assert!(c.count(2.0, 1.0, Some(7)).1);
    }
}
