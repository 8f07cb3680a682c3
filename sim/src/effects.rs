//! The catalogue of physical effects outside the rigid-body model (DESIGN.md section 7), as
//! simulator [`Injection`]s. Each effect has the stable id used by `volcal diagnose`, and its
//! truth parameters use the names under which the diagnosis reports its estimates.
//!
//! Effects are built from a spec string `id[:key=value,key=value...]`, e.g.
//! `setup_drift:vx_m_per_s=2e-9` or `beam_break:station=1,beam=4,index=50,step_m=-6.3e-7`.
//! Defaults are sized for a signal-to-noise ratio of about 3 to 5 on the demo machine's
//! campaigns (0.2 um reading noise).

use crate::inject::{Injection, Sample};
use nalgebra::{Point3, Vector3};
use std::collections::BTreeMap;
use volcal::campaign::Reading;
use volcal::environment::{air_index, Air, AirIndexEquation};

/// Ids of the catalogue, in the order the diagnosis documents them.
pub const CATALOGUE: [&str; 10] = [
    "air_refraction",
    "material_expansion",
    "setup_drift",
    "latency",
    "reversal",
    "periodic_pitch",
    "nonrigid",
    "probe_offset",
    "beam_break",
    "cyclic_nonlinearity",
];

/// Error in an effect spec.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("effect {spec:?}: {reason}")]
pub struct SpecError {
    pub spec: String,
    pub reason: String,
}

/// Parses `id[:key=value,...]` into an id and numeric parameters.
fn parse_spec(spec: &str) -> Result<(String, BTreeMap<String, f64>), SpecError> {
    let err = |reason: String| SpecError { spec: spec.to_string(), reason };
    let (id, rest) = match spec.split_once(':') {
        Some((id, rest)) => (id.trim(), rest),
        None => (spec.trim(), ""),
    };
    let mut params = BTreeMap::new();
    for kv in rest.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (k, v) = kv.split_once('=').ok_or_else(|| err(format!("{kv:?} is not key=value")))?;
        let v: f64 = v.trim().parse().map_err(|_| err(format!("{v:?} is not a number")))?;
        if !v.is_finite() {
            return Err(err(format!("{k} is not finite")));
        }
        params.insert(k.trim().to_string(), v);
    }
    Ok((id.to_string(), params))
}

/// Context an effect may need at construction: the air at the start of the campaign (the
/// reference of an interferometer compensated once) and the wavelength.
#[derive(Clone, Copy, Debug)]
pub struct EffectContext {
    pub air_start: Air,
    pub wavelength_vac_m: f64,
    pub air_equation: AirIndexEquation,
    /// The machine travel (for effects defined on normalised coordinates).
    pub travel: volcal::Travel,
}

impl EffectContext {
    /// The context of effects injected into the simulation `cfg` of a machine with `travel`:
    /// the simulation's starting air and its interferometer's wavelength and air equation.
    pub fn new(cfg: &crate::SimConfig, travel: volcal::Travel) -> EffectContext {
        EffectContext {
            air_start: cfg.environment.air,
            wavelength_vac_m: cfg.interferometer.wavelength_vac_m,
            air_equation: cfg.interferometer.air_equation,
            travel,
        }
    }
}

/// Builds the effects of a `+`-joined list of specs (blank ones ignored), e.g.
/// `setup_drift:vx_m_per_s=2e-8+air_refraction`.
pub fn from_specs(specs: &str, ctx: &EffectContext) -> Result<Vec<Box<dyn Injection>>, SpecError> {
    specs.split('+').map(str::trim).filter(|s| !s.is_empty()).map(|s| from_spec(s, ctx)).collect()
}

/// Builds an effect from its spec.
pub fn from_spec(spec: &str, ctx: &EffectContext) -> Result<Box<dyn Injection>, SpecError> {
    let (id, mut p) = parse_spec(spec)?;
    let mut take = |k: &str, default: f64| p.remove(k).unwrap_or(default);
    let effect: Box<dyn Injection> = match id.as_str() {
        "air_refraction" => Box::new(AirRefraction {
            reference: ctx.air_start,
            dead_path_m: take("dead_path_m", 0.15),
            fraction: take("uncompensated_fraction", 1.0),
            wavelength_vac_m: ctx.wavelength_vac_m,
            equation: ctx.air_equation,
        }),
        "material_expansion" => Box::new(MaterialExpansion {
            alpha_per_k: [
                take("alpha_x_per_k", 11.5e-6),
                take("alpha_y_per_k", 11.5e-6),
                take("alpha_z_per_k", 11.5e-6),
            ],
            temp_start_c: take("temp_start_c", 20.5),
            rate_k_per_h: take("rate_k_per_h", 0.6),
            record: take("record", 1.0) != 0.0,
        }),
        "setup_drift" => Box::new(SetupDrift {
            velocity_mps: Vector3::new(take("vx_m_per_s", 5e-9), take("vy_m_per_s", -3e-9), take("vz_m_per_s", 4e-9)),
        }),
        "latency" => Box::new(Latency { tau_s: take("latency_s", 20e-6) }),
        "reversal" => Box::new(Reversal {
            backlash_m: [take("backlash_x_m", 1.5e-6), take("backlash_y_m", -1.2e-6), take("backlash_z_m", 1.0e-6)],
        }),
        "periodic_pitch" => Box::new(PeriodicPitch {
            axis: take("axis", 0.0) as usize,
            amplitude_m: take("amplitude_m", 0.6e-6),
            period_m: take("period_m", 0.016),
            phase_rad: take("phase_rad", 0.7),
        }),
        "nonrigid" => Box::new(Nonrigid { coefficient_m: take("coefficient_m", 1.0e-6), travel: ctx.travel.ranges }),
        "probe_offset" => Box::new(ProbeOffset {
            declared: Vector3::new(take("declared_x_m", 0.0), take("declared_y_m", 0.12), take("declared_z_m", -0.10)),
            delta: Vector3::new(take("dx_m", 0.0), take("dy_m", 0.0), take("dz_m", -0.08)),
        }),
        "beam_break" => Box::new(BeamBreak {
            station: take("station", 1.0) as u32,
            beam: take("beam", 4.0) as u32,
            index: take("index", 50.0) as usize,
            step_m: take("step_m", -6.33e-7),
        }),
        "cyclic_nonlinearity" => Box::new(CyclicNonlinearity {
            amplitude_m: take("amplitude_m", 20e-9),
            phase_rad: take("phase_rad", 0.3),
            dead_path_m: take("dead_path_m", 0.15),
            wavelength_vac_m: ctx.wavelength_vac_m,
            equation: ctx.air_equation,
        }),
        "unmodelled_bump" => Box::new(UnmodelledBump {
            centre: Point3::new(take("x_m", 0.8), take("y_m", 0.2), take("z_m", -0.15)),
            radius_m: take("radius_m", 0.08),
            amplitude_m: take("amplitude_m", 1.5e-6),
        }),
        other => {
            return Err(SpecError {
                spec: spec.into(),
                reason: format!("unknown effect {other:?} (known: {}, unmodelled_bump)", CATALOGUE.join(", ")),
            })
        }
    };
    if let Some(k) = p.keys().next() {
        return Err(SpecError { spec: spec.into(), reason: format!("unknown parameter {k:?} for {id}") });
    }
    Ok(effect)
}

/// `air_refraction`: the interferometer was compensated with the air of the start of the
/// campaign and never updated, while the air changed. Its reading of a geometric length `L` from
/// a zero taken at `L0` is `(n(t) (d + L) - n(t0) (d + L0)) / n_ref` with `d` the instrument's
/// internal dead path: relative to the truth, `delta(t) (d + L) - delta(t0) (d + L0)` with
/// `delta = n / n_ref - 1`.
pub struct AirRefraction {
    pub reference: Air,
    pub dead_path_m: f64,
    /// Fraction of the index change left uncompensated (1: none of it compensated).
    pub fraction: f64,
    pub wavelength_vac_m: f64,
    pub equation: AirIndexEquation,
}

impl AirRefraction {
    fn delta(&self, air: &Air) -> f64 {
        self.fraction
            * (air_index(self.equation, self.wavelength_vac_m, air)
                / air_index(self.equation, self.wavelength_vac_m, &self.reference)
                - 1.0)
    }
}

impl Injection for AirRefraction {
    fn id(&self) -> &str {
        "air_refraction"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![("uncompensated_fraction".into(), self.fraction), ("dead_path_m".into(), self.dead_path_m)]
    }
    fn describe(&self) -> String {
        format!("readings compensated with the air at the start ({:.2} degC) and never updated", self.reference.temp_c)
    }
    fn optical(&self, s: &Sample, length: &mut f64) {
        let d = self.dead_path_m;
        *length += self.delta(&s.air) * (d + *length) - self.delta(&s.air_zero) * (d + s.zero_length_m);
    }
}

/// `material_expansion`: the scales are at `T(t) = T0 + rate t` and the coordinates are not
/// normalised to 20 degC: a scale reads `q / (1 + alpha (T - 20))` (fixed point at 0).
pub struct MaterialExpansion {
    pub alpha_per_k: [f64; 3],
    pub temp_start_c: f64,
    pub rate_k_per_h: f64,
    /// Write the machine temperature into the campaign.
    pub record: bool,
}

impl MaterialExpansion {
    pub fn temp_at(&self, t_s: f64) -> f64 {
        self.temp_start_c + self.rate_k_per_h * t_s / 3600.0
    }
}

impl Injection for MaterialExpansion {
    fn id(&self) -> &str {
        "material_expansion"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![
            ("alpha_x_per_k".into(), self.alpha_per_k[0]),
            ("alpha_y_per_k".into(), self.alpha_per_k[1]),
            ("alpha_z_per_k".into(), self.alpha_per_k[2]),
            ("temp_start_c".into(), self.temp_start_c),
            ("rate_k_per_h".into(), self.rate_k_per_h),
        ]
    }
    fn describe(&self) -> String {
        format!(
            "scales at {:.2} degC rising {:.2} K/h, not normalised to 20 degC",
            self.temp_start_c, self.rate_k_per_h
        )
    }
    fn record(&self, s: &Sample, r: &mut Reading) {
        let dt = self.temp_at(s.t_s) - 20.0;
        for k in 0..3 {
            r.x[k] /= 1.0 + self.alpha_per_k[k] * dt;
        }
        if self.record {
            r.machine_temp_c = Some(self.temp_at(s.t_s));
        }
    }
}

/// `setup_drift`: the deflector (or tracer) drifts at a constant velocity: a reading taken `dt`
/// after the counter was zeroed is shorter by `n . v dt`.
pub struct SetupDrift {
    pub velocity_mps: Vector3<f64>,
}

impl Injection for SetupDrift {
    fn id(&self) -> &str {
        "setup_drift"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![
            ("vx_m_per_s".into(), self.velocity_mps.x),
            ("vy_m_per_s".into(), self.velocity_mps.y),
            ("vz_m_per_s".into(), self.velocity_mps.z),
        ]
    }
    fn describe(&self) -> String {
        format!("the device drifts at {:.2} um/h", self.velocity_mps.norm() * 3.6e9)
    }
    fn optical(&self, s: &Sample, length: &mut f64) {
        *length -= s.direction.dot(&self.velocity_mps) * (s.t_s - s.t_zero_s);
    }
}

/// `latency`: the machine coordinates are those of `tau` seconds earlier than the abscissa
/// (on-the-fly acquisition).
pub struct Latency {
    pub tau_s: f64,
}

impl Injection for Latency {
    fn id(&self) -> &str {
        "latency"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![("latency_s".into(), self.tau_s)]
    }
    fn describe(&self) -> String {
        format!("machine coordinates {:.1} us older than the abscissae", self.tau_s * 1e6)
    }
    fn record(&self, s: &Sample, r: &mut Reading) {
        r.x -= s.velocity * self.tau_s;
    }
    fn delay_s(&self) -> f64 {
        self.tau_s
    }
}

/// `reversal`: backlash of each axis: the actual position lags by half the backlash behind the
/// direction of the last move of that axis.
pub struct Reversal {
    pub backlash_m: [f64; 3],
}

impl Injection for Reversal {
    fn id(&self) -> &str {
        "reversal"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![
            ("backlash_x_m".into(), self.backlash_m[0]),
            ("backlash_y_m".into(), self.backlash_m[1]),
            ("backlash_z_m".into(), self.backlash_m[2]),
        ]
    }
    fn describe(&self) -> String {
        format!(
            "backlash X {:.2} um, Y {:.2} um, Z {:.2} um",
            self.backlash_m[0] * 1e6,
            self.backlash_m[1] * 1e6,
            self.backlash_m[2] * 1e6
        )
    }
    fn actual(&self, s: &Sample, actual: &mut Point3<f64>) {
        for k in 0..3 {
            if s.motion[k].abs() > 1e-9 {
                actual[k] -= 0.5 * self.backlash_m[k] * s.motion[k].signum();
            }
        }
    }
}

/// `periodic_pitch`: a periodic positioning error of one axis (ball screw, scale).
pub struct PeriodicPitch {
    pub axis: usize,
    pub amplitude_m: f64,
    pub period_m: f64,
    pub phase_rad: f64,
}

impl Injection for PeriodicPitch {
    fn id(&self) -> &str {
        "periodic_pitch"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![
            ("axis".into(), self.axis as f64),
            ("amplitude_m".into(), self.amplitude_m),
            ("period_m".into(), self.period_m),
            ("phase_rad".into(), self.phase_rad),
        ]
    }
    fn describe(&self) -> String {
        format!(
            "periodic error of {} of {:.2} um, period {:.1} mm",
            ["X", "Y", "Z"][self.axis.min(2)],
            self.amplitude_m * 1e6,
            self.period_m * 1e3
        )
    }
    fn actual(&self, s: &Sample, actual: &mut Point3<f64>) {
        let a = self.axis.min(2);
        actual[a] += self.amplitude_m * (2.0 * std::f64::consts::PI * s.x[a] / self.period_m + self.phase_rad).sin();
    }
}

/// `nonrigid`: an error outside the rigid-body class: the Z displacement grows with X times the
/// square of the Y position, `c P1(x) P2(y)` (Legendre, normalised travel), as a bridge that
/// sags more the further the carriage is out.
pub struct Nonrigid {
    pub coefficient_m: f64,
    /// Travel over which the Legendre polynomials are normalised.
    pub travel: [[f64; 2]; 3],
}

fn legendre_unit(q: f64, range: [f64; 2], order: usize) -> f64 {
    let s = 2.0 * (q - range[0]) / (range[1] - range[0]) - 1.0;
    match order {
        1 => s,
        2 => 0.5 * (3.0 * s * s - 1.0),
        _ => 1.0,
    }
}

impl Injection for Nonrigid {
    fn id(&self) -> &str {
        "nonrigid"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![("ez:P1(x)P2(y)".into(), self.coefficient_m)]
    }
    fn describe(&self) -> String {
        format!("Z error {:.2} um P1(x) P2(y): a sag that grows with the carriage position", self.coefficient_m * 1e6)
    }
    fn actual(&self, s: &Sample, actual: &mut Point3<f64>) {
        actual.z +=
            self.coefficient_m * legendre_unit(s.x.x, self.travel[0], 1) * legendre_unit(s.x.y, self.travel[1], 2);
    }
}

/// `probe_offset`: the reflector mounted for one declared offset sits elsewhere.
pub struct ProbeOffset {
    pub declared: Vector3<f64>,
    pub delta: Vector3<f64>,
}

impl Injection for ProbeOffset {
    fn id(&self) -> &str {
        "probe_offset"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![("dx_m".into(), self.delta.x), ("dy_m".into(), self.delta.y), ("dz_m".into(), self.delta.z)]
    }
    fn describe(&self) -> String {
        format!(
            "the reflector declared at ({:.3}, {:.3}, {:.3}) m is displaced by ({:.1}, {:.1}, {:.1}) mm",
            self.declared.x,
            self.declared.y,
            self.declared.z,
            self.delta.x * 1e3,
            self.delta.y * 1e3,
            self.delta.z * 1e3
        )
    }
    fn probe_offset(&self, s: &Sample, p: &mut Vector3<f64>) {
        if (s.p - self.declared).norm() < 1e-9 {
            *p += self.delta;
        }
    }
}

/// `beam_break`: the interferometer lost its count inside a beam; readings from `index` on
/// are offset by `step_m` (an integer number of half wavelengths, or an arbitrary jump).
pub struct BeamBreak {
    pub station: u32,
    pub beam: u32,
    pub index: usize,
    pub step_m: f64,
}

impl Injection for BeamBreak {
    fn id(&self) -> &str {
        "beam_break"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![
            ("station".into(), self.station as f64),
            ("beam".into(), self.beam as f64),
            ("index".into(), self.index as f64),
            ("step_m".into(), self.step_m),
        ]
    }
    fn describe(&self) -> String {
        format!(
            "count lost in station {} beam {} at point {}: step {:.3} um",
            self.station,
            self.beam,
            self.index,
            self.step_m * 1e6
        )
    }
    fn optical(&self, s: &Sample, length: &mut f64) {
        if s.station == self.station && s.line == self.beam && s.index >= self.index {
            *length += self.step_m;
        }
    }
}

/// `cyclic_nonlinearity`: the interferometer's periodic error, one period per fringe, i.e. per
/// `lambda_air / 2` of geometric path (internal dead path `d` plus the distance to the
/// reflector): a function of the fringe count `2 n (d + L) / lambda_vac`.
pub struct CyclicNonlinearity {
    pub amplitude_m: f64,
    pub phase_rad: f64,
    pub dead_path_m: f64,
    pub wavelength_vac_m: f64,
    pub equation: AirIndexEquation,
}

impl Injection for CyclicNonlinearity {
    fn id(&self) -> &str {
        "cyclic_nonlinearity"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![("amplitude_m".into(), self.amplitude_m)]
    }
    fn describe(&self) -> String {
        format!("interferometer periodic error {:.1} nm, period lambda/2", self.amplitude_m * 1e9)
    }
    fn optical(&self, s: &Sample, length: &mut f64) {
        let n = air_index(self.equation, self.wavelength_vac_m, &s.air);
        let fringes = 2.0 * n * (self.dead_path_m + *length) / self.wavelength_vac_m;
        *length += self.amplitude_m * (2.0 * std::f64::consts::PI * fringes + self.phase_rad).sin();
    }
}

/// Not in the catalogue: a local bump of the volumetric error (a dent in a guideway), used to
/// check that the diagnosis does not force an unknown effect into a catalogue name.
pub struct UnmodelledBump {
    pub centre: Point3<f64>,
    pub radius_m: f64,
    pub amplitude_m: f64,
}

impl Injection for UnmodelledBump {
    fn id(&self) -> &str {
        "unmodelled_bump"
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        vec![
            ("x_m".into(), self.centre.x),
            ("y_m".into(), self.centre.y),
            ("z_m".into(), self.centre.z),
            ("radius_m".into(), self.radius_m),
            ("amplitude_m".into(), self.amplitude_m),
        ]
    }
    fn describe(&self) -> String {
        format!(
            "local {:.1} um bump of radius {:.0} mm at ({:.2}, {:.2}, {:.2}) m",
            self.amplitude_m * 1e6,
            self.radius_m * 1e3,
            self.centre.x,
            self.centre.y,
            self.centre.z
        )
    }
    fn actual(&self, s: &Sample, actual: &mut Point3<f64>) {
        let d2 = (s.x - self.centre).norm_squared();
        let g = self.amplitude_m * (-d2 / (2.0 * self.radius_m * self.radius_m)).exp();
        actual.x += g * 0.6;
        actual.z += g * 0.8;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_and_reject() {
        let ctx = EffectContext {
            air_start: Air::standard(),
            wavelength_vac_m: 633e-9,
            air_equation: AirIndexEquation::Ciddor,
            travel: volcal::Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]),
        };
        for id in CATALOGUE {
            assert_eq!(from_spec(id, &ctx).unwrap().id(), id);
        }
        assert!(from_spec("latency:latency_s=1e-5", &ctx).is_ok());
        assert!(from_spec("latency:tau=1", &ctx).err().unwrap().to_string().contains("unknown parameter"));
        assert!(from_spec("gremlins", &ctx).err().unwrap().to_string().contains("unknown effect"));
        assert!(from_spec("latency:latency_s=x", &ctx).is_err());
    }
}
