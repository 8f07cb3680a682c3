//! Physics outside the rigid-body model, injected into the sim nodes: the effects of the
//! diagnosis catalogue (`volcal_sim::effects`, the same specs as `volcal simulate --inject`),
//! each applied by the node where it physically acts.
//!
//! | hook of [`Injection`] | effects | acts in |
//! |---|---|---|
//! | `probe_offset`, `actual` | probe_offset, reversal, periodic_pitch, nonrigid | the machine's actual reflector position ([`super::sim::ActualReflector`]) |
//! | `record` (coordinates) | latency, material_expansion | the coordinates the machine reports |
//! | `record` (temperature) | material_expansion | the machine temperature the environment node reports |
//! | `optical` | air_refraction, setup_drift, beam_break, cyclic_nonlinearity | the interferometer's optical length, the tracer's range |
//!
//! Nothing of this travels on a topic: every sim node parses the same `inject` parameter and
//! applies its own share, so a recording shows the effect only through what the instruments
//! and the machine report (`conceal`).
//!
//! Time-dependent effects (a drift, the air, the scale temperature) run on the campaign clock
//! ([`CampaignClock`]): the simulated launch configs compress the campaign in time, and
//! `time_scale` says how many seconds of the campaign the plan describes pass per second of the
//! run, so that a drift is as large per line as in the real campaign. A latency is a delay
//! between the recording's own stamps and is not scaled.

use nalgebra::{Point3, Vector3};
use std::sync::Arc;
use volcal::campaign::{ObsKind, Reading};
use volcal::environment::Air;
use volcal_sim::effects::{from_specs, EffectContext};
use volcal_sim::simulate::InjectedTruth;
use volcal_sim::{Injection, Sample, SimConfig};

/// The simulated laboratory's clock.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CampaignClock {
    /// Time zero, nanoseconds since the epoch (`VOLCAL_SIM_EPOCH_NS`, the same for all nodes).
    pub epoch_ns: i64,
    /// Seconds of the campaign per second of the run.
    pub time_scale: f64,
}

impl CampaignClock {
    /// Seconds of campaign time at the wall-clock instant `ns`.
    pub fn t_s(&self, ns: i64) -> f64 {
        (ns - self.epoch_ns) as f64 * 1e-9 * self.time_scale
    }
}

/// The injected effects shared by the components of one sim node.
#[derive(Clone, Default)]
pub struct Injected {
    effects: Arc<Vec<Box<dyn Injection>>>,
}

impl std::fmt::Debug for Injected {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.effects.iter().map(|e| e.id())).finish()
    }
}

/// Where a reading's counter was zeroed: what `optical` hooks measure a change from.
#[derive(Clone, Copy, Debug)]
pub struct Zero {
    pub t_s: f64,
    pub length_m: f64,
    pub air: Air,
}

/// An optical reading being simulated, for [`Injected::optical`].
#[derive(Clone, Copy, Debug)]
pub struct OpticalSample {
    pub kind: ObsKind,
    pub station: u32,
    /// Beam (fixed beams) or path (tracer).
    pub line: u32,
    /// Point index within the line: the trigger's, or the free-running samples since the zero.
    pub index: usize,
    pub t_s: f64,
    /// Beam direction, or the unit vector from the tracer to the reflector.
    pub direction: Vector3<f64>,
    pub station_position: Point3<f64>,
    pub reflector: Point3<f64>,
    pub air: Air,
    pub zero: Zero,
}

impl Injected {
    /// Parses `specs` (`id[:key=value,...]`, `+` joining several; empty: none) for the
    /// simulation `cfg` of a machine with `travel`.
    pub fn parse(specs: &str, cfg: &SimConfig, travel: volcal::Travel) -> anyhow::Result<Injected> {
        let ctx = EffectContext::new(cfg, travel);
        let effects = from_specs(specs, &ctx).map_err(|e| anyhow::anyhow!("parameter inject: {e}"))?;
        Ok(Injected { effects: Arc::new(effects) })
    }

    pub fn is_empty(&self) -> bool {
        self.effects.is_empty()
    }

    /// How much older than their stamps the machine's recorded coordinates are, nanoseconds
    /// (the injected latencies; [`volcal_sim::Injection::delay_s`]).
    pub fn delay_ns(&self) -> i64 {
        (self.effects.iter().map(|e| e.delay_s()).sum::<f64>() * 1e9).round() as i64
    }

    /// The effects as the truth file records them.
    pub fn truth(&self) -> Vec<InjectedTruth> {
        self.effects
            .iter()
            .map(|i| InjectedTruth { id: i.id().to_string(), description: i.describe(), parameters: i.parameters() })
            .collect()
    }

    /// A sample of the machine side: what the machine knows (indicated coordinates, offset,
    /// velocity, the direction of its last move, the time); the optical fields are neutral.
    fn machine_sample(
        t_s: f64,
        x: &Point3<f64>,
        p: &Vector3<f64>,
        velocity: &Vector3<f64>,
        motion: &Vector3<f64>,
    ) -> Sample {
        Sample {
            kind: ObsKind::Beam,
            station: 0,
            line: 0,
            index: 0,
            t_s,
            x: *x,
            p: *p,
            velocity: *velocity,
            direction: Vector3::zeros(),
            station_position: Point3::origin(),
            air: Air::standard(),
            motion: *motion,
            t_zero_s: t_s,
            zero_length_m: 0.0,
            air_zero: Air::standard(),
        }
    }

    /// The reflector offset actually mounted when `p` is declared.
    pub fn probe_offset(&self, t_s: f64, x: &Point3<f64>, p: &Vector3<f64>, motion: &Vector3<f64>) -> Vector3<f64> {
        let s = Self::machine_sample(t_s, x, p, &Vector3::zeros(), motion);
        let mut actual = *p;
        for e in self.effects.iter() {
            e.probe_offset(&s, &mut actual);
        }
        actual
    }

    /// Machine-side physics on the actual reflector position.
    pub fn actual(
        &self,
        t_s: f64,
        x: &Point3<f64>,
        p: &Vector3<f64>,
        velocity: &Vector3<f64>,
        motion: &Vector3<f64>,
        actual: &mut Point3<f64>,
    ) {
        let s = Self::machine_sample(t_s, x, p, velocity, motion);
        for e in self.effects.iter() {
            e.actual(&s, actual);
        }
    }

    /// What the controller reports: the indicated coordinates `x` (and the machine temperature
    /// `temp_c`, when measured) as the recording-side effects leave them.
    pub fn record(
        &self,
        t_s: f64,
        x: &Point3<f64>,
        p: &Vector3<f64>,
        velocity: &Vector3<f64>,
        temp_c: Option<f64>,
    ) -> (Point3<f64>, Option<f64>) {
        if self.effects.is_empty() {
            return (*x, temp_c);
        }
        let s = Self::machine_sample(t_s, x, p, velocity, &Vector3::zeros());
        let mut r = Reading {
            kind: ObsKind::Beam,
            station: 0,
            line: 0,
            t_s,
            l_m: 0.0,
            x: *x,
            p: *p,
            air: None,
            machine_temp_c: temp_c,
            velocity: Some(*velocity),
            beam_broken: false,
            source_line: 0,
        };
        for e in self.effects.iter() {
            e.record(&s, &mut r);
        }
        (r.x, r.machine_temp_c)
    }

    /// Instrument-side physics on an optical length (beam) or range (tracer), metres.
    pub fn optical(&self, o: &OpticalSample, length_m: &mut f64) {
        if self.effects.is_empty() {
            return;
        }
        let s = Sample {
            kind: o.kind,
            station: o.station,
            line: o.line,
            index: o.index,
            t_s: o.t_s,
            x: o.reflector,
            p: Vector3::zeros(),
            velocity: Vector3::zeros(),
            direction: o.direction,
            station_position: o.station_position,
            air: o.air,
            motion: Vector3::zeros(),
            t_zero_s: o.zero.t_s,
            zero_length_m: o.zero.length_m,
            air_zero: o.zero.air,
        };
        for e in self.effects.iter() {
            e.optical(&s, length_m);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volcal_formats::machine::{Machine, DEMO_MACHINE};
    use volcal_formats::plan::{load_plan, sim_config};

    fn world() -> (SimConfig, volcal::Travel) {
        let m = Machine::parse(DEMO_MACHINE).unwrap();
        (sim_config(&m, load_plan(None).unwrap(), 1), m.layout.travel)
    }

    #[test]
    fn each_hook_reaches_its_effect() {
        let (cfg, travel) = world();
        let x = Point3::new(0.5, 0.4, -0.3);
        let p = Vector3::new(0.0, 0.12, -0.10);
        // probe_offset: only the declared offset moves.
        let e = Injected::parse("probe_offset:dz_m=-0.001", &cfg, travel).unwrap();
        assert_eq!(e.probe_offset(0.0, &x, &p, &Vector3::x()), p + Vector3::new(0.0, 0.0, -0.001));
        assert_eq!(e.probe_offset(0.0, &x, &Vector3::zeros(), &Vector3::x()), Vector3::zeros());
        // reversal: half the backlash against the last move.
        let e = Injected::parse("reversal:backlash_x_m=2e-6,backlash_y_m=0,backlash_z_m=0", &cfg, travel).unwrap();
        let mut a = x;
        e.actual(0.0, &x, &p, &Vector3::zeros(), &Vector3::x(), &mut a);
        assert!((a.x - x.x + 1e-6).abs() < 1e-15);
        // latency: coordinates of tau earlier; material: the recorded temperature.
        let e = Injected::parse("latency:latency_s=1e-3+material_expansion:rate_k_per_h=3600", &cfg, travel).unwrap();
        let (xr, t) = e.record(2.0, &x, &p, &Vector3::new(0.5, 0.0, 0.0), Some(20.0));
        assert!((t.unwrap() - (20.5 + 2.0)).abs() < 1e-12);
        assert!(xr.x < x.x - 4e-4);
        // setup drift: shorter by n.v (t - t0).
        let e = Injected::parse("setup_drift:vx_m_per_s=1e-6,vy_m_per_s=0,vz_m_per_s=0", &cfg, travel).unwrap();
        let zero = Zero { t_s: 10.0, length_m: 0.3, air: Air::standard() };
        let o = OpticalSample {
            kind: ObsKind::Beam,
            station: 0,
            line: 0,
            index: 3,
            t_s: 12.0,
            direction: Vector3::x(),
            station_position: Point3::origin(),
            reflector: x,
            air: Air::standard(),
            zero,
        };
        let mut l = 0.5;
        e.optical(&o, &mut l);
        assert!((l - (0.5 - 2e-6)).abs() < 1e-15);
    }

    #[test]
    fn the_campaign_clock_scales_time() {
        let c = CampaignClock { epoch_ns: 1_000_000_000, time_scale: 240.0 };
        assert_eq!(c.t_s(1_500_000_000), 120.0);
    }
}
