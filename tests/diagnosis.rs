//! Concealed-effect scenarios for the diagnosis tests (issue 6) and the SNR calibration.
//!
//! Signal-to-noise ratio of an effect in a campaign: simulate the campaign with and without the
//! effect from the same seed (identical noise), fit the rigid-body model to both, and take the
//! largest RMS over one line of the difference of the residuals, divided by the readings'
//! standard uncertainty. It is the effect's signature left in the residuals after the rigid-body
//! model has absorbed what it can, which is what any diagnosis can see.

use volcal::campaign::{prepare, Campaign, Observations};
use volcal::diagnose::{diagnose, geometry::Optics, DiagnoseOptions, Diagnosis};
use volcal::{solve, ErrorModel};
use volcal_formats::machine::Machine;
use volcal_formats::plan::sim_config;
use volcal_sim::effects::{from_specs, EffectContext};
use volcal_sim::simulate::InjectedTruth;
use volcal_sim::{simulate, Acquisition, Injection, Plan, SimConfig};

/// A concealed-effect scenario: which effect, and how its strength scales.
#[derive(Clone, Debug)]
pub struct Scenario {
    pub id: &'static str,
    /// Injection spec with `{a}` standing for the strength.
    pub spec: &'static str,
    /// Strength used to measure the SNR (the calibration scales it linearly).
    pub reference: f64,
    /// Air-temperature rate per unit strength (air refraction scales the environment).
    pub air_rate_per_unit: f64,
    /// Low-noise precision setup (interferometer periodic errors are nanometres).
    pub precision: bool,
    /// Amplitude of the air-conditioning cycle of the air temperature per unit strength, K
    /// (period 30 minutes).
    pub air_cycle_per_unit: f64,
    /// The plan measured at rest point by point ([`static_plan`]) instead of on the fly.
    pub at_rest: bool,
}

impl Scenario {
    /// A scenario on the diagnosis plan on the fly, standard machine, constant air.
    pub fn new(id: &'static str, spec: &'static str, reference: f64) -> Scenario {
        Scenario {
            id,
            spec,
            reference,
            air_rate_per_unit: 0.0,
            precision: false,
            air_cycle_per_unit: 0.0,
            at_rest: false,
        }
    }
}

/// The catalogue scenarios.
pub fn scenarios() -> Vec<Scenario> {
    let s = Scenario::new;
    vec![
        Scenario { air_rate_per_unit: 1.0, ..s("air_refraction", "air_refraction", 1.0) },
        s("material_expansion", "material_expansion:rate_k_per_h={a}", 0.5),
        s("setup_drift", "setup_drift:vx_m_per_s={a},vy_m_per_s=0,vz_m_per_s={a}", 5e-9),
        s("latency", "latency:latency_s={a}", 10e-6),
        s("reversal", "reversal:backlash_x_m={a},backlash_y_m=0,backlash_z_m=0", 1e-6),
        s("periodic_pitch", "periodic_pitch:axis=0,period_m=0.016,amplitude_m={a}", 0.3e-6),
        s("nonrigid", "nonrigid:coefficient_m={a}", 2e-6),
        Scenario { precision: true, ..s("probe_offset", "probe_offset:dx_m=0,dy_m=0,dz_m={a}", -0.03) },
        s("beam_break", "beam_break:station=1,beam=4,index=30,step_m={a}", -0.6e-6),
        Scenario { precision: true, ..s("cyclic_nonlinearity", "cyclic_nonlinearity:amplitude_m={a}", 10e-9) },
    ]
}

/// An effect outside the catalogue: a local bump of the volumetric error (a dent in a
/// guideway) centred at (0.8, 0.2, -0.15) m, radius 80 mm.
pub fn unmodelled() -> Scenario {
    Scenario::new("unmodelled_bump", "unmodelled_bump:amplitude_m={a}", 1.5e-6)
}

/// The machine of the diagnosis campaigns (`launch_configs/machines/diagnosis_cmm*.yaml`):
/// the demo CMM with 8-interval B-splines, recording the air; the precision variant has
/// nanometre noise.
pub fn machine(precision: bool) -> Machine {
    let name = if precision { "diagnosis_cmm_precision.yaml" } else { "diagnosis_cmm.yaml" };
    Machine::load(&crate::repo_root().join("launch_configs/machines").join(name)).unwrap()
}

/// The campaign plan (`launch_configs/plans/diagnosis.yaml`): 3 positions x 16 beams x 30
/// points, out and back on the fly at three speeds, so that latency (proportional to speed)
/// and reversal (not) can be told apart.
pub fn plan() -> Plan {
    volcal_formats::plan::load_plan(Some(&crate::repo_root().join("launch_configs/plans/diagnosis.yaml"))).unwrap()
}

/// The diagnosis plan measured at rest: the machine stops at every point (1 s dwell), out and
/// back, so that a reversal shows and a latency cannot (nothing moves while it reads).
pub fn static_plan() -> Plan {
    Plan { acquisition: Acquisition::Static { speed_mps: 0.05, dwell_s: 1.0 }, ..plan() }
}

/// A simulated campaign of a scenario at strength `a` (0: the clean campaign of the same seed).
pub fn campaign(sc: &Scenario, a: f64, seed: u64) -> (Machine, SimConfig, Campaign, Vec<InjectedTruth>) {
    let m = machine(sc.precision);
    let mut cfg = sim_config(&m, if sc.at_rest { static_plan() } else { plan() }, 1000 + seed);
    cfg.environment.air_temp_rate_k_per_h = sc.air_rate_per_unit * a;
    cfg.environment.air_temp_cycle_k = sc.air_cycle_per_unit * a;
    let injections = if a == 0.0 {
        Vec::new()
    } else {
        from_specs(&sc.spec.replace("{a}", &a.to_string()), &EffectContext::new(&cfg, m.layout.travel)).unwrap()
    };
    let refs: Vec<&dyn Injection> = injections.iter().map(|b| b.as_ref()).collect();
    let out = simulate(&cfg, &refs, 2000 + seed).unwrap();
    (m, cfg, out.campaign, out.truth.injected)
}

/// Prepared observations of a campaign.
pub fn observations(m: &Machine, c: &Campaign) -> Observations {
    prepare(c, &m.layout.travel, &m.expansion).unwrap().obs
}

/// SNR of a scenario at strength `a` (see the module documentation).
pub fn snr(sc: &Scenario, a: f64, seed: u64) -> f64 {
    let (m, _, with, _) = campaign(sc, a, seed);
    let (_, _, without, _) = campaign(sc, 0.0, seed);
    let (ow, oo) = (observations(&m, &with), observations(&m, &without));
    let sw = solve(&m.layout, &ow, &m.solve_options(), &[]).unwrap();
    let so = solve(&m.layout, &oo, &m.solve_options(), &[]).unwrap();
    let sigma = sw.sigmas[0];
    ow.groups
        .iter()
        .map(|g| {
            let r2: f64 = g.range().map(|i| (sw.residuals[i] - so.residuals[i]).powi(2)).sum();
            (r2 / g.len() as f64).sqrt() / sigma
        })
        .fold(0.0, f64::max)
}

/// SNR of the raw signal: the largest RMS over one line of the effect's change of the
/// residuals under the model fitted to the clean campaign (not refitted, so nothing is absorbed
/// beyond each line's origin and direction), over the readings' standard uncertainty. This is
/// the effect's size in the readings, the definition the diagnosis tests use.
pub fn snr_raw(sc: &Scenario, a: f64, seed: u64) -> f64 {
    let (m, _, with, _) = campaign(sc, a, seed);
    let (_, _, without, _) = campaign(sc, 0.0, seed);
    let (ow, oo) = (observations(&m, &with), observations(&m, &without));
    let clean = solve(&m.layout, &oo, &m.solve_options(), &[]).unwrap();
    let at_clean = volcal::SolveOptions {
        initial_model: Some(clean.model.u.clone()),
        initial_stations: clean.stations.iter().map(|s| (s.station, s.position)).collect(),
        max_iterations: 0,
        ..m.solve_options()
    };
    let rw = solve(&m.layout, &ow, &at_clean, &[]).unwrap();
    let ro = solve(&m.layout, &oo, &at_clean, &[]).unwrap();
    ow.groups
        .iter()
        .map(|g| {
            let d: Vec<f64> = g.range().map(|i| rw.residuals[i] - ro.residuals[i]).collect();
            let mean = d.iter().sum::<f64>() / d.len() as f64;
            (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt() / rw.sigmas[g.start]
        })
        .fold(0.0, f64::max)
}

/// The smallest strength that gives an SNR of at least 3 in every seed of `seeds`, and the
/// smallest SNR it gives (at the seed where it is smallest). The signatures are nearly linear in
/// the strength; a few corrections at the worst seed take care of the rest.
pub fn strength_for_snr3(sc: &Scenario, seeds: std::ops::Range<u64>) -> (f64, f64) {
    let (worst, min) =
        seeds.map(|s| (s, snr(sc, sc.reference, s))).min_by(|a, b| a.1.total_cmp(&b.1)).expect("at least one seed");
    let mut a = sc.reference * 3.0 / min;
    let mut at = snr(sc, a, worst);
    for _ in 0..4 {
        if at >= 3.0 {
            break;
        }
        a *= 3.0 / at * 1.001;
        at = snr(sc, a, worst);
    }
    (a, at)
}

/// Diagnosis options for a campaign made with `cfg`.
pub fn options(m: &Machine, cfg: &SimConfig) -> DiagnoseOptions {
    DiagnoseOptions::new(
        m.solve_options(),
        Optics { wavelength_vac_m: cfg.interferometer.wavelength_vac_m, air_equation: cfg.interferometer.air_equation },
    )
}

/// RMS volumetric difference between a model and the truth after removing the gauge freedom
/// ([`crate::gauge_distance`]), over a grid and the campaign's probe offsets.
pub fn map_error(model: &ErrorModel, truth: &ErrorModel, g: volcal::Gauge, obs: &Observations) -> f64 {
    crate::gauge_distance(model, truth, g, &distinct_probes(obs), 0.2).1
}

/// One diagnosis run of a scenario at strength `a`.
pub struct Run {
    pub diagnosis: Diagnosis,
    pub truth: Vec<InjectedTruth>,
    pub truth_model: ErrorModel,
    pub rms_clean_m: f64,
    pub map_error_before: f64,
    pub map_error_after: f64,
    pub gauge: volcal::Gauge,
    /// Distinct probe offsets in order of first appearance (the diagnosis's probe numbering).
    pub probes: Vec<nalgebra::Vector3<f64>>,
}

pub fn run(sc: &Scenario, a: f64, seed: u64) -> Run {
    let (m, cfg, c, truth) = campaign(sc, a, seed);
    let obs = observations(&m, &c);
    let d = diagnose(&m.layout, &obs, &options(&m, &cfg)).unwrap();
    let (_, _, clean, _) = campaign(sc, 0.0, seed);
    let clean_obs = observations(&m, &clean);
    let rms_clean_m = solve(&m.layout, &clean_obs, &m.solve_options(), &[]).unwrap().stats.rms_m;
    let truth_model = cfg.machine.truth.clone();
    let probes = distinct_probes(&obs);
    Run {
        map_error_before: map_error(&d.before.model, &truth_model, m.gauge, &obs),
        map_error_after: map_error(&d.after.model, &truth_model, m.gauge, &obs),
        diagnosis: d,
        truth,
        truth_model,
        rms_clean_m,
        gauge: m.gauge,
        probes,
    }
}

/// How a run compares with its truth.
#[derive(Debug)]
pub struct Check {
    /// The scenario's effect is the first (strongest) one reported.
    pub named_first: bool,
    /// Standardised errors `(estimate - truth) / uncertainty` of the effect's primary
    /// parameters (those the injection made non-zero); empty when the effect was not found.
    pub z: Vec<f64>,
    /// Hyper-parameters found from the data (period, break location) equal the truth.
    pub located: bool,
    /// Residual RMS after the refit within 10 % of the clean campaign's.
    pub rms_at_floor: bool,
    /// The identified error map is closer to the truth after the refit than before.
    pub map_closer: bool,
}

fn truth_param(t: &[InjectedTruth], id: &str, name: &str) -> f64 {
    t.iter()
        .find(|e| e.id == id)
        .and_then(|e| e.parameters.iter().find(|p| p.0 == name))
        .map(|p| p.1)
        .unwrap_or_else(|| panic!("no truth {id}.{name}"))
}

/// The primary parameters of an injected effect as the diagnosis names them, with their true
/// values: those the injection made non-zero. `found` are the names the diagnosis reported
/// (setup drift is per station), `probes` the distinct probe offsets in order of first
/// appearance in the prepared readings (the diagnosis's probe numbering).
pub fn primary_parameters(
    id: &str,
    truth: &[InjectedTruth],
    found: &[String],
    probes: &[nalgebra::Vector3<f64>],
) -> Vec<(String, f64)> {
    let t = |name: &str| truth_param(truth, id, name);
    match id {
        "air_refraction" => vec![("uncompensated_fraction".into(), t("uncompensated_fraction"))],
        "material_expansion" => {
            ["alpha_x_per_k", "alpha_y_per_k", "alpha_z_per_k"].iter().map(|n| (n.to_string(), t(n))).collect()
        }
        "setup_drift" => found
            .iter()
            .filter_map(|n| {
                let c = ["vx", "vy", "vz"].iter().position(|c| n.ends_with(&format!("_{c}_m_per_s")))?;
                let v = t(["vx_m_per_s", "vy_m_per_s", "vz_m_per_s"][c]);
                (v != 0.0).then(|| (n.clone(), v))
            })
            .collect(),
        "latency" => vec![("latency_s".into(), t("latency_s"))],
        "reversal" => vec![("backlash_x_m".into(), t("backlash_x_m"))],
        "periodic_pitch" | "cyclic_nonlinearity" => vec![("amplitude_m".into(), t("amplitude_m"))],
        "nonrigid" => vec![("ez:P1(x)P2(y)".into(), t("ez:P1(x)P2(y)"))],
        "probe_offset" => {
            let declared = nalgebra::Vector3::new(0.0, 0.12, -0.10);
            let k =
                probes.iter().position(|p| (p - declared).norm() < 1e-9).expect("the displaced probe is in the plan");
            vec![(format!("probe{k}_dz_m"), t("dz_m"))]
        }
        "beam_break" => vec![("step_m".into(), t("step_m"))],
        other => panic!("no primary parameters for {other}"),
    }
}

/// Distinct probe offsets in order of first appearance.
pub fn distinct_probes(obs: &Observations) -> Vec<nalgebra::Vector3<f64>> {
    let mut probes: Vec<nalgebra::Vector3<f64>> = Vec::new();
    for p in &obs.p {
        if !probes.iter().any(|q| (q - p).norm() < 1e-9) {
            probes.push(*p);
        }
    }
    probes
}

/// Compares a run of scenario `sc` with its truth.
pub fn check(sc: &Scenario, r: &Run) -> Check {
    let d = &r.diagnosis;
    let found = d.effects.iter().find(|e| e.id == sc.id);
    let truth = |name: &str| truth_param(&r.truth, sc.id, name);
    let names: Vec<String> = found.map(|f| f.parameters.iter().map(|p| p.0.clone()).collect()).unwrap_or_default();
    let primary = primary_parameters(sc.id, &r.truth, &names, &r.probes);
    let z = match found {
        Some(f) => primary
            .iter()
            .map(|(n, t)| {
                let p = f.parameters.iter().find(|p| &p.0 == n).unwrap_or_else(|| panic!("{} reports no {n}", sc.id));
                (p.1 - t) / p.2
            })
            .collect(),
        None => Vec::new(),
    };
    let get = |n: &str| found.and_then(|f| f.parameters.iter().find(|p| p.0 == n)).map(|p| p.1);
    let located = match sc.id {
        "periodic_pitch" => {
            get("period_m").is_some_and(|p| (p / truth("period_m") - 1.0).abs() < 0.01)
                && get("axis") == Some(truth("axis"))
        }
        "beam_break" => ["station", "beam", "index"].iter().all(|n| get(n) == Some(truth(n))),
        _ => found.is_some(),
    };
    Check {
        named_first: d.effects.first().is_some_and(|e| e.id == sc.id),
        z,
        located,
        rms_at_floor: d.rms_after_m <= 1.1 * r.rms_clean_m,
        map_closer: r.map_error_after < r.map_error_before,
    }
}
