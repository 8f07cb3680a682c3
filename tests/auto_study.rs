//! The campaigns and measures of issue 12's acceptance suite, shared by its test and by the
//! `auto_study` example that prints the full table: truth families x (beams, tracer, joint) x
//! (dense, sparse), solved by `representation: auto` and by the oracle of the truth's own basis.

use crate::truth_families::{draw, Family, FamilyTruth, Oracle};
use nalgebra::{Point3, Vector3};
use std::time::Instant;
use volcal::campaign::{prepare, Campaign};
use volcal::flexibility::{solve_auto, Auto, AutoSolve, AxisKnots};
use volcal::interpolation::InterpolationCheck;
use volcal::predict;
use volcal::{gauge, solve, ErrorModel, Gauge, ModelLayout, Observations, SolveOptions, Topology, Travel};
use volcal_formats::machine::Machine;
use volcal_formats::plan::sim_config;
use volcal_sim::{simulate, Method, Plan};

/// How the machine is measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Measure {
    Beams,
    Tracer,
    Joint,
}

/// How densely.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Density {
    Dense,
    Sparse,
}

/// One case of the suite.
#[derive(Clone, Copy, Debug)]
pub struct Case {
    pub family: Family,
    pub topology: &'static str,
    pub measure: Measure,
    pub density: Density,
}

impl Case {
    pub fn label(&self) -> String {
        format!(
            "{} | {} | {:?} | {:?}",
            self.family.name(),
            if self.family == Family::PaperTables { "FYXZ (paper)" } else { self.topology },
            self.measure,
            self.density
        )
    }

    /// The machine: the demo CMM's travel (1.0 x 0.8 x 0.6 m) with the case's topology and the
    /// patent gauge, or the paper's CMM with its datum gauge.
    pub fn machine(&self) -> Machine {
        let text = if self.family == Family::PaperTables {
            volcal_formats::machine::PAPER_MACHINE.to_string()
        } else {
            format!("topology: {}\ntravel: {{x: [0.0, 1.0], y: [0.0, 0.8], z: [-0.6, 0.0]}}\n", self.topology)
        };
        Machine::parse(&text).expect("machine")
    }

    fn plans(&self, travel: &Travel) -> Vec<Plan> {
        let beams = match self.density {
            Density::Dense => Plan::patent_example(),
            Density::Sparse => Plan::short(),
        };
        // `AUTO_TRACER_STEPS` overrides the steps per edge (robustness sweeps of `auto_study`).
        let steps = match (std::env::var("AUTO_TRACER_STEPS").ok().and_then(|v| v.parse::<f64>().ok()), self.density) {
            (Some(s), _) => s,
            (None, Density::Dense) => 20.0,
            (None, Density::Sparse) => 10.0,
        };
        let tracer = Plan { path_step_m: volcal::Axis::ALL.map(|a| travel.length(a) / steps), ..Plan::paper_tracer() };
        match self.measure {
            Measure::Beams => vec![beams],
            Measure::Tracer => vec![tracer],
            Measure::Joint => vec![beams, tracer],
        }
    }
}

/// Every case of the acceptance suite: three families x three ways to measure x two densities,
/// beams on two topologies.
pub fn suite() -> Vec<Case> {
    let mut out = Vec::new();
    for family in [Family::PolySine, Family::PiecewiseBump, Family::PaperTables] {
        for measure in [Measure::Beams, Measure::Tracer, Measure::Joint] {
            for density in [Density::Dense, Density::Sparse] {
                let topologies: &[&'static str] = match (family, measure) {
                    (Family::PaperTables, _) => &["FYXZ"],
                    (_, Measure::Beams) => &["FXYZ", "FYXZ"],
                    _ => &["FXYZ"],
                };
                for &topology in topologies {
                    out.push(Case { family, topology, measure, density });
                }
            }
        }
    }
    out
}

/// The suite's case of `family` on `topology` measured by `measure` at `density`.
///
/// # Panics
/// When the suite has no such case (e.g. the paper's tables on FXYZ).
pub fn case(family: Family, topology: &str, measure: Measure, density: Density) -> Case {
    suite()
        .into_iter()
        .find(|c| c.family == family && c.topology == topology && c.measure == measure && c.density == density)
        .unwrap_or_else(|| panic!("no case {family:?} | {topology} | {measure:?} | {density:?} in the suite"))
}

/// What one campaign gave.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// Map error (RMS over the grid and the campaign's probe offsets, where the model is
    /// determined) of `auto` and of the oracle; the RMS of `auto`'s predicted standard
    /// uncertainty (sqrt of the mean trace) there.
    pub auto_rms_m: f64,
    pub oracle_rms_m: f64,
    pub predicted_rms_m: f64,
    /// Map error of the oracle that knows the family but must find where its features lie
    /// ([`Oracle::located`]), at the same points.
    pub located_rms_m: f64,
    /// The same two at the points where the readings resolve the map (not interpolated
    /// between measured positions; all points where no axis is bounded by its positions).
    pub auto_rms_resolved_m: f64,
    pub predicted_rms_resolved_m: f64,
    /// Largest |error component| / its standard uncertainty, and how many (point, offset,
    /// component) values exceed 3, at points where the readings resolve the map.
    pub max_z: f64,
    pub over_3: usize,
    pub values: usize,
    /// The same at points between measured positions (interpolated).
    pub max_z_interpolated: f64,
    pub over_3_interpolated: usize,
    pub values_interpolated: usize,
    /// Grid points (x offsets) reported as not determined, of all.
    pub undetermined: usize,
    pub points: usize,
    pub knots: [AxisKnots; 3],
    /// The interpolation checks of the axes bounded by their positions.
    pub interpolation: Vec<InterpolationCheck>,
    pub edf: f64,
    /// The noise variance factor REML took (1: the stated noise).
    pub noise_scale: f64,
    pub auto_s: f64,
    /// The map's 95 % simultaneous band ([`volcal::band`]): its factor `k`, and whether every
    /// error component where the model gives a number lies within `k` standard uncertainties.
    pub band_k: f64,
    pub within_band: bool,
}

/// The case's campaign for `seed` (its plans on one machine carrying the truth), and the truth.
pub fn campaign(case: &Case, seed: u64) -> (Campaign, FamilyTruth) {
    let machine = case.machine();
    let truth: FamilyTruth = draw(case.family, &machine.layout.topology, machine.layout.travel, seed);
    let mut campaign: Option<Campaign> = None;
    for (k, plan) in case.plans(&machine.layout.travel).into_iter().enumerate() {
        let mut cfg = sim_config(&machine, plan, seed);
        cfg.machine.truth = truth.model.clone();
        let out = simulate(&cfg, &[], seed * 7 + k as u64).expect("simulate");
        match campaign.as_mut() {
            None => campaign = Some(out.campaign),
            Some(c) => c.readings.extend(out.campaign.readings),
        }
    }
    (campaign.unwrap(), truth)
}

/// Simulates the case for `seed`, solves it both ways and measures both maps.
pub fn run(case: &Case, seed: u64, auto: &Auto) -> Outcome {
    let (campaign, truth) = self::campaign(case, seed);
    run_on(case, &campaign, &truth, auto)
}

/// Solves the case's `campaign` both ways and measures both maps against `truth`.
pub fn run_on(case: &Case, campaign: &Campaign, truth: &FamilyTruth, auto: &Auto) -> Outcome {
    let machine = case.machine();
    let topology: Topology = machine.layout.topology.clone();
    let travel = machine.layout.travel;
    let prep = prepare(campaign, &travel, &machine.expansion).expect("prepare");
    let obs = &prep.obs;
    let g: Gauge = machine.gauge;
    let plain = SolveOptions { gauge: g, noise: machine.noise, ..SolveOptions::default() };

    let t0 = Instant::now();
    let AutoSolve { solution: sol, knots, interpolation } =
        solve_auto(&topology, travel, obs, &plain, auto, &[None; 18]).expect("auto solve");
    let auto_s = t0.elapsed().as_secs_f64();
    if std::env::var_os("AUTO_EDF").is_some() {
        if let Some(r) = &sol.smoothing {
            let v: Vec<String> =
                r.functions.iter().map(|f| format!("{}:{:.1}/{}", f.function.name(), f.edf, f.n_coeffs)).collect();
            eprintln!("  edf {}", v.join(" "));
        }
    }

    let oracle_layout = Oracle::layout(topology.clone(), travel);
    let oracle = solve_oracle(Oracle::new(truth, g, &oracle_layout), &oracle_layout, obs, &plain);
    // Where the family has no places to find (the paper's tables) the located oracle is the
    // oracle, and not solved again.
    let located = truth
        .has_places()
        .then(|| solve_oracle(Oracle::located(truth, g, &oracle_layout), &oracle_layout, obs, &plain));

    let aligned =
        ErrorModel { layout: truth.model.layout.clone(), u: gauge::align(&truth.model.layout, g, &truth.model.u) };
    let offsets: Vec<Vector3<f64>> = {
        let mut v: Vec<Vector3<f64>> = Vec::new();
        for p in &obs.p {
            if !v.iter().any(|o| (o - p).norm() < 1e-9) {
                v.push(*p);
            }
        }
        v
    };
    let unc = sol.uncertainty();
    let (mut a2, mut o2, mut l2, mut p2, mut n) = (0.0, 0.0, 0.0, 0.0, 0usize);
    let (mut a2r, mut p2r, mut nr) = (0.0, 0.0, 0usize);
    let (mut max_z, mut over_3, mut values, mut undetermined, mut points) = (0.0f64, 0, 0, 0, 0);
    let (mut max_zi, mut over_3i, mut values_i) = (0.0f64, 0, 0);
    let grid = predict::grid(&travel, 0.1);
    let band = volcal::band::simultaneous_band(
        &sol.model,
        &unc,
        &grid,
        &offsets,
        volcal::band::BAND_LEVEL,
        volcal::band::BAND_DRAWS,
        0,
    );
    let band_k = band.map_or(f64::NAN, |b| b.k);
    for &x in &grid {
        for p in &offsets {
            points += 1;
            let pe = predict::predict(&sol.model, &unc, &x, p);
            if !pe.is_determined() {
                undetermined += 1;
                continue;
            }
            let t = aligned.error(&x, p);
            let d = sol.model.error(&x, p) - t;
            let d_o = oracle.error(&x, p) - t;
            let d_l = located.as_ref().map_or(d_o, |l| l.error(&x, p) - t);
            for k in 0..3 {
                // A component fixed by the gauge (the datum at its origin) has no variance and
                // no error: it is not a test of the uncertainty.
                let sigma = pe.cov[(k, k)].max(0.0).sqrt();
                if sigma < 1e-12 && d[k].abs() < 1e-9 {
                    continue;
                }
                let z = d[k].abs() / sigma;
                if pe.interpolated {
                    max_zi = max_zi.max(z);
                    over_3i += (z > 3.0) as usize;
                    values_i += 1;
                } else {
                    max_z = max_z.max(z);
                    over_3 += (z > 3.0) as usize;
                    values += 1;
                }
            }
            a2 += d.norm_squared();
            o2 += d_o.norm_squared();
            l2 += d_l.norm_squared();
            p2 += pe.cov.trace();
            n += 1;
            if !pe.interpolated {
                a2r += d.norm_squared();
                p2r += pe.cov.trace();
                nr += 1;
            }
        }
    }
    if std::env::var_os("AUTO_DEBUG").is_some() {
        let st = &sol.stats;
        eprintln!("  chi2 {:.1} dof {} vf {:.3}", st.chi2, st.dof, st.variance_factor);
        // Per instrument: where a misfit lies when one noise scale serves both.
        for kind in [volcal::campaign::ObsKind::Beam, volcal::campaign::ObsKind::Range] {
            let z2: Vec<f64> = obs
                .groups_of(kind)
                .flat_map(|(_, g)| g.range())
                .map(|i| (sol.residuals[i] / sol.sigmas[i]).powi(2))
                .collect();
            if !z2.is_empty() {
                eprintln!(
                    "    {kind:?}: {} readings, chi2 / n {:.3}",
                    z2.len(),
                    z2.iter().sum::<f64>() / z2.len() as f64
                );
            }
        }
        let lam: std::collections::HashMap<String, (f64, f64)> = sol
            .smoothing
            .as_ref()
            .map(|r| r.functions.iter().map(|f| (f.function.name(), (f.lambda[0], f.edf))).collect())
            .unwrap_or_default();
        for f in volcal::ErrorFunction::all() {
            let [lo, hi] = travel.range(f.axis);
            let (mut e2, mut t2, mut m, mut s2) = (0.0, 0.0, 0.0f64, 0.0);
            for i in 0..=200 {
                let q = lo + (hi - lo) * i as f64 / 200.0;
                let t = aligned.function_value(f, q);
                let d = sol.model.function_value(f, q) - t;
                s2 += predict::function_sigma(&sol.model, &unc, f, q).powi(2);
                e2 += d * d;
                t2 += t * t;
                m = m.max(d.abs());
            }
            // `AUTO_PROFILE=NAME`: that function along its axis (where an outlier lies).
            if std::env::var("AUTO_PROFILE").ok().as_deref() == Some(f.name().as_str()) {
                for i in 0..=40 {
                    let q = lo + (hi - lo) * i as f64 / 40.0;
                    let t = aligned.function_value(f, q);
                    let e = sol.model.function_value(f, q);
                    let s = predict::function_sigma(&sol.model, &unc, f, q);
                    eprintln!(
                        "      q {:.3} truth {:.3e} est {:.3e} err {:.3e} sigma {:.3e} z {:.2}",
                        q,
                        t,
                        e,
                        e - t,
                        s,
                        (e - t) / s
                    );
                }
            }
            let (l, edf) = lam.get(&f.name()).copied().unwrap_or((0.0, 0.0));
            eprintln!(
                "   {:>4}: err rms {:.3e} (sigma rms {:.3e}) max {:.3e} truth rms {:.3e} lambda {:.2e} edf {:.1}",
                f.name(),
                (e2 / 201.0).sqrt(),
                (s2 / 201.0).sqrt(),
                m,
                (t2 / 201.0).sqrt(),
                l,
                edf
            );
        }
    }
    let n = n.max(1) as f64;
    let nr = nr.max(1) as f64;
    Outcome {
        auto_rms_m: (a2 / n).sqrt(),
        oracle_rms_m: (o2 / n).sqrt(),
        located_rms_m: (l2 / n).sqrt(),
        predicted_rms_m: (p2 / n).sqrt(),
        auto_rms_resolved_m: (a2r / nr).sqrt(),
        predicted_rms_resolved_m: (p2r / nr).sqrt(),
        max_z,
        over_3,
        values,
        max_z_interpolated: max_zi,
        over_3_interpolated: over_3i,
        values_interpolated: values_i,
        undetermined,
        points,
        knots,
        interpolation,
        edf: sol.smoothing.as_ref().map_or(0.0, |s| s.edf_total),
        noise_scale: sol.smoothing.as_ref().map_or(1.0, |s| s.noise_scale),
        auto_s,
        band_k,
        within_band: max_z.max(max_zi) <= band_k,
    }
}

/// An oracle's estimate: its degree-1 model and its terms' coefficients.
struct OracleFit {
    oracle: Oracle,
    model: ErrorModel,
    coeffs: Vec<f64>,
}

impl OracleFit {
    /// Its volumetric error at `x` with probe offset `p`.
    fn error(&self, x: &Point3<f64>, p: &Vector3<f64>) -> Vector3<f64> {
        self.oracle.error(&self.model, &self.coeffs, x, p)
    }
}

/// Solves `oracle` (its terms as an effect beside the degree-1 `layout`) on `obs`.
fn solve_oracle(oracle: Oracle, layout: &ModelLayout, obs: &Observations, opts: &SolveOptions) -> OracleFit {
    let refs: [&dyn volcal::estimator::Effect; 1] = [&oracle];
    let s = solve(layout, obs, opts, &refs).expect("oracle solve");
    let coeffs = s.effects[0].1.iter().map(|(_, v, _)| *v).collect();
    OracleFit { oracle, model: s.model, coeffs }
}

/// A case over seeds.
#[derive(Clone, Debug)]
pub struct Summary {
    pub seeds: usize,
    /// RMS over seeds of `auto`'s map error divided by the oracle's.
    pub oracle_ratio: f64,
    /// The same divided by the located oracle's ([`Outcome::located_rms_m`]), and the located
    /// oracle's divided by the oracle's: what not knowing where the features lie costs at best.
    pub located_ratio: f64,
    pub located_over_oracle: f64,
    /// RMS over seeds of the actual map error divided by that of the predicted uncertainty.
    pub mc_ratio: f64,
    /// 95 % interval of `mc_ratio` from the seeds alone (percentile bootstrap over the seeds,
    /// 2 000 resamples): the scale on which the figure strays with this many seeds, since one
    /// campaign's map error is dominated by a few long-wavelength components. Approximate: with
    /// 20 seeds of such a skewed quantity it is too narrow (docs/representation-auto.md).
    pub mc_ratio_95: (f64, f64),
    /// `mc_ratio` at the points where the readings resolve the map ([`Outcome`]).
    pub mc_ratio_resolved: f64,
    pub auto_rms_m: f64,
    pub oracle_rms_m: f64,
    pub max_z: f64,
    pub over_3: usize,
    pub values: usize,
    pub max_z_interpolated: f64,
    pub over_3_interpolated: usize,
    pub values_interpolated: usize,
    pub undetermined: usize,
    pub points: usize,
    pub mean_s: f64,
}

pub fn summarise(outcomes: &[Outcome]) -> Summary {
    let ms = |f: &dyn Fn(&Outcome) -> f64| {
        (outcomes.iter().map(|o| f(o).powi(2)).sum::<f64>() / outcomes.len() as f64).sqrt()
    };
    let (a, o, p) = (ms(&|o| o.auto_rms_m), ms(&|o| o.oracle_rms_m), ms(&|o| o.predicted_rms_m));
    Summary {
        seeds: outcomes.len(),
        oracle_ratio: a / o,
        located_ratio: a / ms(&|o| o.located_rms_m),
        located_over_oracle: ms(&|o| o.located_rms_m) / o,
        mc_ratio: a / p,
        mc_ratio_95: bootstrap_95(outcomes, |o| (o.auto_rms_m.powi(2), o.predicted_rms_m.powi(2))),
        mc_ratio_resolved: ms(&|o| o.auto_rms_resolved_m) / ms(&|o| o.predicted_rms_resolved_m),
        auto_rms_m: a,
        oracle_rms_m: o,
        max_z: outcomes.iter().map(|o| o.max_z).fold(0.0, f64::max),
        over_3: outcomes.iter().map(|o| o.over_3).sum(),
        values: outcomes.iter().map(|o| o.values).sum(),
        max_z_interpolated: outcomes.iter().map(|o| o.max_z_interpolated).fold(0.0, f64::max),
        over_3_interpolated: outcomes.iter().map(|o| o.over_3_interpolated).sum(),
        values_interpolated: outcomes.iter().map(|o| o.values_interpolated).sum(),
        undetermined: outcomes.iter().map(|o| o.undetermined).sum(),
        points: outcomes.iter().map(|o| o.points).sum(),
        mean_s: outcomes.iter().map(|o| o.auto_s).sum::<f64>() / outcomes.len() as f64,
    }
}

/// Percentile bootstrap (2 000 resamples of the seeds, a fixed generator) of
/// `sqrt(sum num / sum den)` over `outcomes`, with `parts(o) = (num, den)`: its 2.5 % and
/// 97.5 % points.
fn bootstrap_95(outcomes: &[Outcome], parts: impl Fn(&Outcome) -> (f64, f64)) -> (f64, f64) {
    use rand::{Rng, SeedableRng};
    let v: Vec<(f64, f64)> = outcomes.iter().map(parts).collect();
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(95);
    let mut r: Vec<f64> = (0..2000)
        .map(|_| {
            let (mut num, mut den) = (0.0, 0.0);
            for _ in 0..v.len() {
                let (a, b) = v[rng.random_range(0..v.len())];
                num += a;
                den += b;
            }
            (num / den).sqrt()
        })
        .collect();
    r.sort_by(f64::total_cmp);
    (r[50], r[1949])
}

/// Whether a plan measures by tracer (for labels).
pub fn is_tracer(plan: &Plan) -> bool {
    plan.method == Method::Tracer
}
