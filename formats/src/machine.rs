//! The machine file (YAML): what the machine is, how its errors are represented, how they are
//! gauged, how noisy the instruments are, and (for `volcal simulate`) how the virtual machine
//! behaves.
//!
//! ```yaml
//! topology: FXYZ                      # axis stacking, workpiece to tool
//! travel: {x: [0, 1.0], y: [0, 0.8], z: [-0.6, 0]}   # metres
//! # optional, with these defaults:
//! representation: auto                # from the data: knots the readings support, REML smoothing
//!                                     # ({kind: auto, max_intervals: 16}; tables: true also tries linear tables
//!                                     # where the readings show kinks), or e.g. {kind: bspline, intervals: 12}
//! representations: {EXX: {kind: polynomial, degree: 6}}   # per-function overrides (not smoothed)
//! gauge: patent                       # or datum
//! noise: {interferometer_m: 5.0e-8, repeatability_m: 2.0e-7, tracer_m: 1.0e-7, tracer_ppm: 0.2}
//! expansion: {x: 11.5e-6, y: 11.5e-6, z: 11.5e-6}          # ISO 1 normalisation (1/K)
//! beam_alignment: motion              # or commanded: what the fixed beams were aligned with; when
//!                                     # not stated, the uncertainty covers both (volcal::alignment)
//! simulation: {...}                   # virtual machine for `volcal simulate`
//! ```

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::collections::BTreeMap;
use std::path::Path;
use volcal::beam::BeamAlignment;
use volcal::campaign::{Observations, ScaleExpansion};
use volcal::estimator::{Solution, SolveError};
use volcal::flexibility::{solve_auto, Auto, AxisKnots};
use volcal::smoothing::Smoothing;
use volcal::{Axis, ErrorFunction, Gauge, ModelLayout, NoiseModel, Representation, SolveOptions, Topology, Travel};
use volcal_sim::{Deflector, EnvironmentSim, Interferometer, Tracer, TruthSpec};

/// Per-axis travel as written in YAML.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, expecting = "the travel per axis in metres, {x: [lo, hi], y: [lo, hi], z: [lo, hi]}")]
pub struct TravelSpec {
    pub x: [f64; 2],
    pub y: [f64; 2],
    pub z: [f64; 2],
}

/// ISO 1 expansion coefficients per axis (1/K) and scale fixed points (m).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ExpansionSpec {
    pub x: Option<f64>,
    pub y: Option<f64>,
    pub z: Option<f64>,
    #[serde(default)]
    pub fixed_point_m: Option<[f64; 3]>,
}

/// The virtual machine for `volcal simulate`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct SimulationSpec {
    /// Random truth drawn from these amplitudes (seeded by `--seed`).
    pub truth: TruthSpec,
    /// Representation of the truth functions (default: the solver's, i.e. truth inside it).
    pub truth_representation: Option<Representation>,
    /// A named truth instead of a random one: `han2021_table2`, the functions of Han et al.
    /// (2021) with the ranges of its Table 2 (needs the paper's topology and travel).
    pub truth_preset: Option<String>,
    /// Machine repeatability per axis, metres.
    pub repeatability_m: f64,
    /// Photoreceiver centring error, metres.
    pub centring_m: f64,
    pub interferometer: Interferometer,
    pub deflector: Deflector,
    pub tracer: Tracer,
    pub environment: EnvironmentSim,
}

impl Default for SimulationSpec {
    fn default() -> Self {
        SimulationSpec {
            truth: TruthSpec::default(),
            truth_representation: None,
            truth_preset: None,
            repeatability_m: 0.2e-6,
            centring_m: 1e-6,
            interferometer: Interferometer::default(),
            deflector: Deflector::default(),
            tracer: Tracer::default(),
            environment: EnvironmentSim::default(),
        }
    }
}

/// The `representation` of a machine file: chosen from the data (`auto`, the default), or given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RepresentationSpec {
    /// `auto` or `{kind: auto, max_intervals: N, tables: false}`: per axis the cubic B-spline
    /// knots the readings' positions support, each function smoothed with REML, and with
    /// `tables: true` linear tables where the readings show kinks at equally spaced nodes
    /// ([`volcal::flexibility`]).
    Auto(Auto),
    /// The same representation for every function, as written.
    Given(Representation),
}

impl Default for RepresentationSpec {
    fn default() -> Self {
        RepresentationSpec::Auto(Auto::default())
    }
}

impl Serialize for RepresentationSpec {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            RepresentationSpec::Auto(a) => {
                #[derive(Serialize)]
                struct AutoOut {
                    kind: &'static str,
                    start_intervals: usize,
                    max_intervals: usize,
                    tables: bool,
                }
                AutoOut {
                    kind: "auto",
                    start_intervals: a.start_intervals,
                    max_intervals: a.max_intervals,
                    tables: a.tables,
                }
                .serialize(s)
            }
            RepresentationSpec::Given(r) => r.serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for RepresentationSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        use serde::de::Error;
        let v = serde_yaml::Value::deserialize(d)?;
        if v.as_str() == Some("auto") {
            return Ok(RepresentationSpec::Auto(Auto::default()));
        }
        if let Some(m) = v.as_mapping() {
            if m.get("kind").and_then(|k| k.as_str()) == Some("auto") {
                let mut auto = Auto::default();
                let count = |key: &str, val: &serde_yaml::Value| -> std::result::Result<usize, D::Error> {
                    val.as_u64()
                        .filter(|&n| (1..=200).contains(&n))
                        .map(|n| n as usize)
                        .ok_or_else(|| D::Error::custom(format!("{key} must be a whole number from 1 to 200")))
                };
                for (k, val) in m {
                    match k.as_str() {
                        Some("kind") => {}
                        Some("max_intervals") => auto.max_intervals = count("max_intervals", val)?,
                        Some("start_intervals") => auto.start_intervals = count("start_intervals", val)?,
                        Some("tables") => {
                            auto.tables =
                                val.as_bool().ok_or_else(|| D::Error::custom("tables must be true or false"))?
                        }
                        _ => {
                            return Err(D::Error::custom(format!(
                                "unknown key {k:?} for kind auto (expected start_intervals, max_intervals, tables)"
                            )))
                        }
                    }
                }
                auto.start_intervals = auto.start_intervals.min(auto.max_intervals);
                return Ok(RepresentationSpec::Auto(auto));
            }
        }
        serde_yaml::from_value::<Representation>(v).map(RepresentationSpec::Given).map_err(|e| {
            D::Error::custom(format!(
                "representation: expected auto, {{kind: auto, ...}} or a representation such as {{kind: bspline, intervals: 12}} ({e})"
            ))
        })
    }
}

/// A machine file.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, expecting = "a machine file: a map with at least `topology` and `travel`")]
pub struct MachineFile {
    #[serde(default)]
    pub name: Option<String>,
    pub topology: String,
    pub travel: TravelSpec,
    #[serde(default)]
    pub representation: Option<RepresentationSpec>,
    #[serde(default)]
    pub representations: BTreeMap<String, Representation>,
    #[serde(default)]
    pub gauge: Option<String>,
    #[serde(default)]
    pub noise: Option<NoiseModel>,
    #[serde(default)]
    pub expansion: Option<ExpansionSpec>,
    /// What the campaign's fixed beams were aligned with; `None`: not stated, the estimate is
    /// along the motion and its uncertainty covers the commanded line ([`volcal::alignment`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beam_alignment: Option<BeamAlignment>,
    #[serde(default)]
    pub simulation: SimulationSpec,
}

/// A validated machine description.
#[derive(Clone, Debug)]
pub struct Machine {
    pub file: MachineFile,
    /// The error-model layout: the one the file gives, or with `representation: auto` the
    /// largest that auto may choose (what [`Machine::setup_for`] fits is then the one the
    /// readings support).
    pub layout: ModelLayout,
    /// `Some` with `representation: auto`.
    pub auto: Option<Auto>,
    /// Functions with a representation of their own (`representations:`).
    pub overrides: [Option<Representation>; 18],
    pub gauge: Gauge,
    pub noise: NoiseModel,
    pub expansion: ScaleExpansion,
}

/// The built-in demo machine: a 1.0 x 0.8 x 0.6 m moving-bridge CMM (FXYZ as in the patent).
/// The range of an instrument's stated noise, metres (a picometre to a millimetre): the fit's
/// weights are its inverse square, and beyond this range they leave the floating-point range
/// of the normal equations or describe no laser instrument.
pub const NOISE_M: (f64, f64) = (1e-12, 1e-3);
/// The largest length-proportional tracer noise, ppm.
pub const MAX_NOISE_PPM: f64 = 1e3;

pub const DEMO_MACHINE: &str = include_str!("../../launch_configs/machines/demo_cmm.yaml");

impl Machine {
    /// Reads and validates a machine file.
    pub fn load(path: &Path) -> Result<Machine> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("cannot read machine file {}", path.display()))?;
        Machine::parse(&text).with_context(|| format!("machine file {}", path.display()))
    }

    /// Parses and validates machine YAML.
    pub fn parse(text: &str) -> Result<Machine> {
        let file: MachineFile = serde_yaml::from_str(text).map_err(|e| {
            let at = e.location().map(|l| format!("line {}, column {}: ", l.line(), l.column())).unwrap_or_default();
            anyhow::anyhow!("{at}{e}")
        })?;
        Machine::from_file(file)
    }

    pub fn from_file(file: MachineFile) -> Result<Machine> {
        let topology = Topology::parse(&file.topology).map_err(|e| anyhow::anyhow!("field topology: {e}"))?;
        let t = &file.travel;
        let travel = Travel::new(t.x, t.y, t.z);
        travel.validate().map_err(|e| anyhow::anyhow!("field travel: {e}"))?;
        for (a, r) in [('x', t.x), ('y', t.y), ('z', t.z)] {
            if r[1] - r[0] > 50.0 {
                bail!(
                    "field travel.{a}: [{}, {}] spans more than 50 m; the machine file is in metres (millimetres?)",
                    r[0],
                    r[1]
                );
            }
        }
        let spec = file.representation.unwrap_or_default();
        let (auto, base) = match spec {
            RepresentationSpec::Auto(a) => (Some(a), Representation::BSpline { intervals: a.max_intervals }),
            RepresentationSpec::Given(r) => (None, r),
        };
        check_representation(&base, &travel, "representation")?;
        let mut reprs = [base; 18];
        let mut overrides = [None; 18];
        for (name, r) in &file.representations {
            let f = ErrorFunction::parse(name).ok_or_else(|| {
                anyhow::anyhow!(
                    "field representations: unknown error function {name:?} (expected ISO names such as EXX, EYZ, ECY)"
                )
            })?;
            check_representation(r, &travel, &format!("representations.{name}"))?;
            reprs[f.index()] = *r;
            overrides[f.index()] = Some(*r);
        }
        let gauge = match &file.gauge {
            None => Gauge::Patent,
            Some(g) => Gauge::parse(g)
                .ok_or_else(|| anyhow::anyhow!("field gauge: unknown gauge {g:?} (expected patent or datum)"))?,
        };
        let noise = file.noise.unwrap_or_default();
        let lengths = [
            ("interferometer_m", noise.interferometer_m),
            ("repeatability_m", noise.repeatability_m),
            ("tracer_m", noise.tracer_m),
        ];
        for (name, v) in lengths.into_iter().chain([("tracer_ppm", noise.tracer_ppm)]) {
            if !(v.is_finite() && v >= 0.0) {
                bail!("field noise.{name}: must be a non-negative number, got {v}");
            }
        }
        // The weights of the fit are 1 / noise^2: a noise of 1e-300 m made them overflow and
        // the solve end, 40 s later, in a singular-matrix error that named the readings.
        for (name, v) in lengths {
            if v != 0.0 && !(NOISE_M.0..=NOISE_M.1).contains(&v) {
                bail!(
                    "field noise.{name}: {v:e} m is no instrument's noise (expected {:e} to {:e} m, or 0)",
                    NOISE_M.0,
                    NOISE_M.1
                );
            }
        }
        if noise.tracer_ppm > MAX_NOISE_PPM {
            bail!(
                "field noise.tracer_ppm: {} ppm is no instrument's noise (expected at most {MAX_NOISE_PPM})",
                noise.tracer_ppm
            );
        }
        if noise.interferometer_m == 0.0 && noise.repeatability_m == 0.0 {
            bail!("field noise: interferometer_m and repeatability_m cannot both be zero (they weight the readings)");
        }
        check_simulation(&file.simulation)?;
        if let Some(r) = &file.simulation.truth_representation {
            check_representation(r, &travel, "simulation.truth_representation")?;
        }
        let expansion = match &file.expansion {
            None => ScaleExpansion::default(),
            Some(e) => {
                ScaleExpansion { alpha_per_k: [e.x, e.y, e.z], fixed_point_m: e.fixed_point_m.unwrap_or([0.0; 3]) }
            }
        };
        if let Some(v) = expansion.alpha_per_k.iter().flatten().chain(&expansion.fixed_point_m).find(|v| !v.is_finite())
        {
            bail!("field expansion: every coefficient and the fixed point must be finite numbers, got {v}");
        }
        if let Some(p) = &file.simulation.truth_preset {
            check_truth_preset(p, &topology, &travel)?;
        }
        let layout = ModelLayout::new(topology, travel, reprs);
        Ok(Machine { file, layout, auto, overrides, gauge, noise, expansion })
    }

    /// Solver options implied by the machine file, for its own layout (without smoothing: use
    /// [`Machine::setup_for`] to fit a campaign).
    pub fn solve_options(&self) -> SolveOptions {
        SolveOptions {
            gauge: self.gauge,
            noise: self.noise,
            beam_alignment: self.file.beam_alignment.unwrap_or_default(),
            ..SolveOptions::default()
        }
    }

    /// The layout and solver options to fit `obs` with: the file's representation, or with
    /// `representation: auto` what [`solve_auto`] chose for these readings (knots per axis,
    /// smoothing held at the REML estimate), with that solution.
    pub fn setup_for(&self, obs: &Observations) -> std::result::Result<Setup, SolveError> {
        let Some(auto) = &self.auto else {
            return Ok(Setup {
                layout: self.layout.clone(),
                options: self.solve_options(),
                knots: None,
                solution: None,
            });
        };
        let s =
            solve_auto(&self.layout.topology, self.layout.travel, obs, &self.solve_options(), auto, &self.overrides)?;
        let options = SolveOptions {
            smoothing: s.solution.smoothing.as_ref().map(Smoothing::fixed_from),
            ..self.solve_options()
        };
        Ok(Setup { layout: s.solution.model.layout.clone(), options, knots: Some(s.knots), solution: Some(s.solution) })
    }

    /// Layout used for the simulated truth: `simulation.truth_representation`, else the file's
    /// representation (a cubic B-spline of 12 intervals with `auto`).
    pub fn truth_layout(&self) -> ModelLayout {
        match (self.file.simulation.truth_representation, &self.auto) {
            (Some(r), _) => ModelLayout::uniform(self.layout.topology.clone(), self.layout.travel, r),
            (None, Some(_)) => {
                let reprs: [Representation; 18] = std::array::from_fn(|i| self.overrides[i].unwrap_or_default());
                ModelLayout::new(self.layout.topology.clone(), self.layout.travel, reprs)
            }
            (None, None) => self.layout.clone(),
        }
    }

    /// Display name.
    pub fn name(&self) -> String {
        self.file.name.clone().unwrap_or_else(|| format!("{} machine", self.layout.topology))
    }
}

/// What a campaign is fitted with ([`Machine::setup_for`]).
#[derive(Clone, Debug)]
pub struct Setup {
    pub layout: ModelLayout,
    pub options: SolveOptions,
    /// With `representation: auto`: the knots chosen per axis and why.
    pub knots: Option<[AxisKnots; 3]>,
    /// With `representation: auto`: the solution it was chosen with.
    pub solution: Option<Solution>,
}

/// Name of the truth preset of the paper's Table 2.
pub const PRESET_HAN2021: &str = "han2021_table2";

/// A truth preset exists and fits the machine.
fn check_truth_preset(name: &str, topology: &Topology, travel: &Travel) -> Result<()> {
    if name != PRESET_HAN2021 {
        bail!("field simulation.truth_preset: unknown preset {name:?} (known: {PRESET_HAN2021})");
    }
    let paper = volcal_sim::paper::travel();
    if topology.to_string() != volcal_sim::paper::TOPOLOGY || travel.ranges != paper.ranges {
        bail!(
            "field simulation.truth_preset: {PRESET_HAN2021} is the paper's machine: it needs topology {} and travel x {:?}, y {:?}, z {:?} m",
            volcal_sim::paper::TOPOLOGY,
            paper.ranges[0],
            paper.ranges[1],
            paper.ranges[2]
        );
    }
    Ok(())
}

/// The paper's CMM (Han et al. 2021), shipped as an example machine file.
pub const PAPER_MACHINE: &str = include_str!("../../launch_configs/machines/paper_cmm.yaml");

/// Checks the representation in `field` ([`Representation::validate`]) and, against the
/// travel, a harmonic period: at more than ten times the longest axis its sines and cosines are
/// nearly straight lines over the travel, which the basis cannot tell apart from each other (a
/// period of 1e300 m made its Gram matrix singular, a panic).
fn check_representation(r: &Representation, travel: &Travel, field: &str) -> Result<()> {
    r.validate().map_err(|e| anyhow::anyhow!("field {field}: {e}"))?;
    let longest = Axis::ALL.iter().map(|&a| travel.length(a)).fold(0.0, f64::max);
    if let Representation::Harmonic { period_m: Some(p), .. } = *r {
        if p > 10.0 * longest {
            bail!("field {field}: a harmonic period of {p:e} m is more than ten times the longest travel ({longest} m): over the travel its harmonics are nearly straight lines");
        }
    }
    Ok(())
}

/// The virtual machine's figures of `volcal simulate`: every standard deviation finite and not
/// negative, the environment's period positive. A random draw with an infinite or NaN standard
/// deviation has no meaning (it panicked in the simulator), and a NaN one was taken as zero.
fn check_simulation(s: &SimulationSpec) -> Result<()> {
    let e = &s.environment;
    for (name, v) in [
        ("repeatability_m", s.repeatability_m),
        ("centring_m", s.centring_m),
        ("interferometer.noise_m", s.interferometer.noise_m),
        ("interferometer.resolution_m", s.interferometer.resolution_m),
        ("deflector.pointing_noise_rad", s.deflector.pointing_noise_rad),
        ("tracer.noise_m", s.tracer.noise_m),
        ("tracer.noise_ppm", s.tracer.noise_ppm),
        ("tracer.resolution_m", s.tracer.resolution_m),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            bail!("field simulation.{name}: must be a non-negative number, got {v}");
        }
    }
    for (name, v) in [
        ("environment.air_temp_rate_k_per_h", e.air_temp_rate_k_per_h),
        ("environment.air_temp_cycle_k", e.air_temp_cycle_k),
        ("environment.machine_temp_c", e.machine_temp_c),
        ("tracer.dead_path_m", s.tracer.dead_path_m),
        ("deflector.pivot_offset_m", s.deflector.pivot_offset_m),
    ] {
        if !v.is_finite() {
            bail!("field simulation.{name}: must be a finite number, got {v}");
        }
    }
    if !(e.air_temp_cycle_period_s.is_finite() && e.air_temp_cycle_period_s > 0.0) {
        bail!(
            "field simulation.environment.air_temp_cycle_period_s: must be a positive number of seconds, got {}",
            e.air_temp_cycle_period_s
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demo_machine_parses() {
        let m = Machine::parse(DEMO_MACHINE).unwrap();
        assert_eq!(m.layout.topology.to_string(), "FXYZ");
    }

    #[test]
    fn paper_machine_parses_and_the_preset_checks_the_machine() {
        let m = Machine::parse(PAPER_MACHINE).unwrap();
        assert_eq!(m.gauge, Gauge::Datum);
        assert_eq!(m.file.simulation.truth_preset.as_deref(), Some(PRESET_HAN2021));
        let other = PAPER_MACHINE.replace("x: [0.0, 0.7]", "x: [0.0, 0.8]");
        let e = Machine::parse(&other).unwrap_err();
        assert!(format!("{e:#}").contains("truth_preset"), "{e:#}");
        let unknown = PAPER_MACHINE.replace("han2021_table2", "nonesuch");
        assert!(format!("{:#}", Machine::parse(&unknown).unwrap_err()).contains("unknown preset"));
    }

    #[test]
    fn minimal_file_and_errors() {
        let m = Machine::parse("topology: FYXZ\ntravel: {x: [0, 0.7], y: [-0.5, 0], z: [-0.7, 0]}\n").unwrap();
        assert_eq!(m.gauge, Gauge::Patent);
        assert_eq!(m.auto, Some(Auto::default()), "auto is the default representation");
        let head = "topology: FXYZ\ntravel: {x: [0, 1], y: [0, 1], z: [0, 1]}\n";
        let m = Machine::parse(&format!("{head}representation: {{kind: auto, max_intervals: 9}}\n")).unwrap();
        assert_eq!(m.auto, Some(Auto { start_intervals: 9, max_intervals: 9, tables: false }));
        let m = Machine::parse(&format!("{head}representation: {{kind: auto, tables: true}}\n")).unwrap();
        assert!(m.auto.unwrap().tables);
        let m = Machine::parse(&format!("{head}representation: {{kind: bspline, intervals: 12}}\n")).unwrap();
        assert_eq!(m.auto, None);
        let e = Machine::parse(&format!("{head}representation: {{kind: auto, knots: 9}}\n")).unwrap_err();
        assert!(format!("{e:#}").contains("knots"), "{e:#}");
        let e = Machine::parse(&format!("{head}representation: automatic\n")).unwrap_err();
        assert!(format!("{e:#}").contains("representation"), "{e:#}");
        let e = Machine::parse("topology: FXQZ\ntravel: {x: [0, 1], y: [0, 1], z: [0, 1]}\n").unwrap_err();
        assert!(format!("{e:#}").contains("topology"), "{e:#}");
        let e = Machine::parse("topology: FXYZ\ntravel: {x: [0, 1000], y: [0, 800], z: [0, 600]}\n").unwrap_err();
        assert!(format!("{e:#}").contains("millimetres"), "{e:#}");
        let e = Machine::parse("topology: FXYZ\ntravel: {x: [0, 1], y: [0, 1], z: [0, 1]}\nrepresentations: {EQX: {kind: table, nodes: 3}}\n").unwrap_err();
        assert!(format!("{e:#}").contains("EQX"), "{e:#}");
        let e = Machine::parse("topology: FXYZ\ntravel: {x: [0, 1], y: [0, 1]\n").unwrap_err();
        assert!(format!("{e:#}").contains("line"), "{e:#}");
    }

    /// Values a user could type that the solver or the simulator cannot use are refused with
    /// the field named (found by fuzzing: each panicked, aborted or wrote NaN before).
    #[test]
    fn values_beyond_use_are_refused_with_the_field() {
        let head = "topology: FXYZ\ntravel: {x: [0, 1], y: [0, 0.8], z: [-0.6, 0]}\n";
        for (extra, field) in [
            ("representation: {kind: bspline, intervals: 100000}", "representation"),
            ("representation: {kind: table, nodes: 10000}", "representation"),
            ("representations: {EXX: {kind: harmonic, harmonics: 10000}}", "representations.EXX"),
            ("representation: {kind: harmonic, harmonics: 3, period_m: 1e300}", "representation"),
            (
                "simulation: {truth_representation: {kind: bspline, intervals: 100000}}",
                "simulation.truth_representation",
            ),
            ("simulation: {repeatability_m: .inf}", "simulation.repeatability_m"),
            ("simulation: {centring_m: .nan}", "simulation.centring_m"),
            (
                "simulation: {environment: {air_temp_cycle_period_s: 0}}",
                "simulation.environment.air_temp_cycle_period_s",
            ),
            ("expansion: {x: .nan, y: 0, z: 0}", "expansion"),
            ("noise: {interferometer_m: 1.0e-300, repeatability_m: 2.0e-7}", "noise.interferometer_m"),
            ("noise: {interferometer_m: 5.0e-8, repeatability_m: 1.0e300}", "noise.repeatability_m"),
            ("noise: {interferometer_m: 5.0e-8, repeatability_m: 2.0e-7, tracer_m: 0.5}", "noise.tracer_m"),
            ("noise: {interferometer_m: 5.0e-8, repeatability_m: 2.0e-7, tracer_ppm: 1.0e9}", "noise.tracer_ppm"),
        ] {
            let e = Machine::parse(&format!("{head}{extra}\n")).unwrap_err();
            assert!(format!("{e:#}").contains(&format!("field {field}")), "{extra}: {e:#}");
        }
        assert!(
            Machine::parse(&format!("{head}representation: {{kind: harmonic, harmonics: 3, period_m: 2}}\n")).is_ok()
        );
    }
}
