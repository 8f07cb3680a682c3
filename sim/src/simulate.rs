//! Offline simulation of a whole campaign: the digital twin that predicts every reading.

use crate::inject::{Injection, Sample};
use crate::instruments::{BeamLine, Deflector, Interferometer, Tracer, VirtualMachine};
use crate::plan::{Acquisition, Method, Plan, PlanError};
use nalgebra::{Point3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use volcal::campaign::{Campaign, CampaignMeta, Compensation, ObsKind, Reading};
use volcal::environment::Air;
use volcal::{Axis, ErrorModel};

/// The environment of the simulated laboratory.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default))]
pub struct EnvironmentSim {
    /// Air at the start of the campaign.
    pub air: Air,
    /// Linear drift of the air temperature, kelvin per hour.
    pub air_temp_rate_k_per_h: f64,
    /// Amplitude of the air-conditioning cycle of the air temperature, kelvin (0: none): the
    /// air of a real laboratory swings around its set point rather than drifting one way.
    pub air_temp_cycle_k: f64,
    /// Period of that cycle, seconds.
    pub air_temp_cycle_period_s: f64,
    /// Write air temperature, pressure and humidity into the campaign.
    pub record_air: bool,
    /// Machine (scale) temperature, degC.
    pub machine_temp_c: f64,
    /// Expansion coefficients of the machine scales, 1/K (0: no thermal effect).
    pub scale_alpha_per_k: [f64; 3],
    /// Write the machine temperature into the campaign.
    pub record_machine_temp: bool,
}

impl Default for EnvironmentSim {
    fn default() -> Self {
        EnvironmentSim {
            air: Air::standard(),
            air_temp_rate_k_per_h: 0.0,
            air_temp_cycle_k: 0.0,
            air_temp_cycle_period_s: 1800.0,
            record_air: false,
            machine_temp_c: 20.0,
            scale_alpha_per_k: [0.0; 3],
            record_machine_temp: false,
        }
    }
}

impl EnvironmentSim {
    /// True air at time `t`.
    pub fn air_at(&self, t_s: f64) -> Air {
        let cycle = if self.air_temp_cycle_k == 0.0 {
            0.0
        } else {
            self.air_temp_cycle_k * (std::f64::consts::TAU * t_s / self.air_temp_cycle_period_s).sin()
        };
        Air { temp_c: self.air.temp_c + self.air_temp_rate_k_per_h * t_s / 3600.0 + cycle, ..self.air }
    }
}

/// Everything the simulator needs.
#[derive(Clone, Debug)]
pub struct SimConfig {
    pub machine: VirtualMachine,
    pub interferometer: Interferometer,
    pub deflector: Deflector,
    pub tracer: Tracer,
    pub environment: EnvironmentSim,
    pub plan: Plan,
}

/// The true beam of a task, for the truth file.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct TruthBeam {
    pub station: u32,
    pub beam: u32,
    pub line: BeamLine,
}

/// An injected effect as recorded in the truth file.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct InjectedTruth {
    pub id: String,
    pub description: String,
    pub parameters: Vec<(String, f64)>,
}

/// Simulation ground truth: never given to the solver.
#[derive(Clone, Debug)]
pub struct Truth {
    pub model: ErrorModel,
    pub beams: Vec<TruthBeam>,
    pub stations: Vec<(u32, Point3<f64>)>,
    pub tracer_dead_path_m: f64,
    pub injected: Vec<InjectedTruth>,
}

/// A simulated campaign and its truth.
#[derive(Clone, Debug)]
pub struct SimOutput {
    pub campaign: Campaign,
    pub truth: Truth,
}

/// Simulates a whole campaign with the given injections and seed.
pub fn simulate(cfg: &SimConfig, injections: &[&dyn Injection], seed: u64) -> Result<SimOutput, PlanError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let travel = cfg.machine.truth.layout.travel;
    let env = &cfg.environment;
    let meta = CampaignMeta {
        wavelength_vac_m: cfg.interferometer.wavelength_vac_m,
        compensation: match cfg.interferometer.assumed_index {
            None => Compensation::Compensated,
            Some(n0) => Compensation::Uncompensated { assumed_index: n0 },
        },
        air_equation: cfg.interferometer.air_equation,
    };
    let mut readings = Vec::new();
    let mut beams = Vec::new();
    let mut stations = Vec::new();
    let mut t = 0.0;
    let on_the_fly = matches!(cfg.plan.acquisition, Acquisition::OnTheFly { .. });
    let dwell = match cfg.plan.acquisition {
        Acquisition::Static { dwell_s, .. } => dwell_s,
        Acquisition::OnTheFly { .. } => 0.0,
    };
    // Indicated coordinates as the warm scales report them.
    let thermal = |x: Point3<f64>| -> Point3<f64> {
        let mut y = x;
        for a in Axis::ALL {
            let alpha = env.scale_alpha_per_k[a.index()];
            if alpha != 0.0 {
                y[a.index()] = x[a.index()] / (1.0 + alpha * (env.machine_temp_c - 20.0));
            }
        }
        y
    };
    let mut record =
        |kind, station, line, t_s: f64, l_m, x: Point3<f64>, p, velocity: Vector3<f64>, sample: &Sample| {
            let air = env.air_at(t_s);
            let mut r = Reading {
                kind,
                station,
                line,
                t_s,
                l_m,
                x: thermal(x),
                p,
                air: env.record_air.then_some(air),
                machine_temp_c: env.record_machine_temp.then_some(env.machine_temp_c),
                velocity: on_the_fly.then_some(velocity),
                beam_broken: false,
                source_line: 0,
            };
            for inj in injections {
                inj.record(sample, &mut r);
            }
            readings.push(r);
        };

    match cfg.plan.method {
        Method::FixedBeam => {
            let tasks = cfg.plan.beam_tasks(&travel)?;
            let mut last_station = u32::MAX;
            for (bi, task) in tasks.iter().enumerate() {
                if task.station != last_station {
                    if last_station != u32::MAX {
                        t += cfg.plan.station_setup_s;
                    }
                    stations.push((task.station, task.pivot));
                    last_station = task.station;
                }
                let speed = cfg.plan.speed_for(bi);
                let beam = cfg.deflector.point(&task.pivot, task.azimuth_rad, task.elevation_rad, &mut rng);
                t += cfg.deflector.settle_s;
                beams.push(TruthBeam { station: task.station, beam: task.beam, line: beam });
                let zero = task.abscissae[0];
                let t_zero = t;
                let air_zero = env.air_at(t);
                let mut prev_s = task.abscissae[0];
                let mut motion = beam.direction;
                for (k, &s) in task.abscissae.iter().enumerate() {
                    let ds = s - prev_s;
                    t += ds.abs() / speed + if k > 0 { dwell } else { 0.0 };
                    if ds != 0.0 {
                        motion = beam.direction * ds.signum();
                    }
                    let vel = if on_the_fly { motion * speed } else { Vector3::zeros() };
                    prev_s = s;
                    let mut sample = Sample {
                        kind: ObsKind::Beam,
                        station: task.station,
                        line: task.beam,
                        index: k,
                        t_s: t,
                        x: Point3::origin(),
                        p: task.probe_offset,
                        velocity: vel,
                        direction: beam.direction,
                        station_position: task.pivot,
                        air: env.air_at(t),
                        motion,
                        t_zero_s: t_zero,
                        zero_length_m: zero,
                        air_zero,
                    };
                    let mut p_actual = task.probe_offset;
                    for inj in injections {
                        inj.probe_offset(&sample, &mut p_actual);
                    }
                    let x = cfg.machine.indicated_for(&beam.at(s), &task.probe_offset, &beam.direction, &mut rng);
                    sample.x = x;
                    let mut actual = cfg.machine.actual(&x, &p_actual, &mut rng);
                    for inj in injections {
                        inj.actual(&sample, &mut actual);
                    }
                    let mut length = beam.direction.dot(&(actual - beam.origin));
                    for inj in injections {
                        inj.optical(&sample, &mut length);
                    }
                    let l = cfg.interferometer.read(length, zero, &env.air_at(t), &mut rng);
                    record(ObsKind::Beam, task.station, task.beam, t, l, x, task.probe_offset, vel, &sample);
                }
            }
        }
        Method::Tracer => {
            let tasks = cfg.plan.path_tasks(&travel)?;
            for (ti, task) in tasks.iter().enumerate() {
                if ti > 0 {
                    t += cfg.plan.station_setup_s;
                }
                stations.push((task.station, task.position));
                let speed = cfg.plan.speed_for(ti);
                let mut prev = task.points[0];
                let t_zero = t;
                let air_zero = env.air_at(t);
                let zero_length = (task.points[0] + task.probe_offset - task.position).norm();
                let mut motion = Vector3::zeros();
                for (k, x) in task.points.iter().enumerate() {
                    let step = (x - prev).norm();
                    t += step / speed + dwell;
                    if step > 0.0 {
                        motion = (x - prev) / step;
                    }
                    let vel = if on_the_fly { motion * speed } else { Vector3::zeros() };
                    prev = *x;
                    let mut sample = Sample {
                        kind: ObsKind::Range,
                        station: task.station,
                        line: task.path,
                        index: k,
                        t_s: t,
                        x: *x,
                        p: task.probe_offset,
                        velocity: vel,
                        direction: (x + task.probe_offset - task.position).normalize(),
                        station_position: task.position,
                        air: env.air_at(t),
                        motion,
                        t_zero_s: t_zero,
                        zero_length_m: zero_length,
                        air_zero,
                    };
                    let mut p_actual = task.probe_offset;
                    for inj in injections {
                        inj.probe_offset(&sample, &mut p_actual);
                    }
                    let mut actual = cfg.machine.actual(x, &p_actual, &mut rng);
                    sample.direction = (actual - task.position).normalize();
                    for inj in injections {
                        inj.actual(&sample, &mut actual);
                    }
                    let mut range = (actual - task.position).norm();
                    for inj in injections {
                        inj.optical(&sample, &mut range);
                    }
                    let l = cfg.tracer.read_range(range, &mut rng);
                    record(ObsKind::Range, task.station, task.path, t, l, *x, task.probe_offset, vel, &sample);
                }
            }
        }
    }
    // A truth or a time beyond what floating point holds (errors of 1e300 m, a dwell of 1e308
    // s) overflows into infinities and NaN: refused rather than written to a campaign file.
    if let Some((k, r)) = readings.iter().enumerate().find(|(_, r)| {
        ![r.t_s, r.l_m, r.x.x, r.x.y, r.x.z].iter().all(|v| v.is_finite())
            || r.air.is_some_and(|a| !(a.temp_c.is_finite() && a.pressure_pa.is_finite() && a.humidity_pct.is_finite()))
    }) {
        return Err(PlanError(format!(
            "reading {k} came out non-finite (t {} s, length {} m, at {:?}): the machine's truth magnitudes or the plan's times are beyond what the simulation can represent",
            r.t_s, r.l_m, r.x
        )));
    }
    let injected = injections
        .iter()
        .map(|i| InjectedTruth { id: i.id().to_string(), description: i.describe(), parameters: i.parameters() })
        .collect();
    Ok(SimOutput {
        campaign: Campaign { meta, readings },
        truth: Truth {
            model: cfg.machine.truth.clone(),
            beams,
            stations,
            tracer_dead_path_m: cfg.tracer.dead_path_m,
            injected,
        },
    })
}
