//! Diagnosis: when the readings disagree with the rigid-body model beyond the noise, locate the
//! mismatch, name the physics left out, model it, and show the fit improve (DESIGN.md section 7).
//!
//! 1. Fit the rigid-body model and compare every reading with its prediction.
//! 2. Locate the excess residual ([`locate`]): stations, lines, time spans, regions of the
//!    volume, periodic components along each axis.
//! 3. Test the catalogue ([`catalogue`]): each effect is a linear extension of the observation
//!    model; its nested-model (score) test gives the chi-square it would remove beyond what the
//!    rigid-body model already explains, computed exactly through the Schur complement of the
//!    fitted normal equations. Effects with hyper-parameters (the period of a periodic error,
//!    the place of a beam break) are scanned, and their tests corrected for the scan.
//! 4. Greedy selection: the candidate with the strongest evidence is accepted when its F-test is
//!    significant after a Bonferroni correction over all candidates, its information criterion
//!    (BIC) improves, it explains a substantial share of the remaining excess, and (for effects
//!    with campaign-wide parameters) it predicts held-out lines: a two-fold cross-validation
//!    across lines, where half of the lines determine the effect at all; and it stays
//!    significant without the line that holds most of the excess, if one does (a local anomaly
//!    is not campaign-wide physics). The model is refitted with it and the search repeats until
//!    nothing significant remains. Clean data raise no alarm; similar effects are told apart by the
//!    evidence once the first is modelled.
//! 5. Report each effect in plain words with its parameters and uncertainties, the residual RMS
//!    before and after, the change in the identified error map, and whatever stays unexplained.

pub mod catalogue;
pub mod geometry;
pub mod locate;

use crate::campaign::{ObsKind, Observations};
use crate::estimator::{fit, Effect, Fit, Score, Solution, SolveError, SolveOptions};
use crate::model::{ErrorModel, ModelLayout};
use crate::predict;
use geometry::{Geometry, Optics};
pub use locate::Location;
use nalgebra::Vector3;
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

/// Options of [`diagnose`].
#[derive(Clone, Debug)]
pub struct DiagnoseOptions {
    pub solve: SolveOptions,
    pub optics: Optics,
    /// Family-wise significance level of each selection round.
    pub alpha: f64,
    /// Most effects to select.
    pub max_effects: usize,
    /// Smallest share of the remaining excess chi-square an effect must explain to be named.
    pub min_share: f64,
}

impl DiagnoseOptions {
    pub fn new(solve: SolveOptions, optics: Optics) -> DiagnoseOptions {
        DiagnoseOptions { solve, optics, alpha: 1e-3, max_effects: 4, min_share: 0.3 }
    }
}

/// An effect the diagnosis found.
#[derive(Clone, Debug)]
pub struct FoundEffect {
    pub id: String,
    /// Physical parameters: name, value, standard uncertainty.
    pub parameters: Vec<(String, f64, f64)>,
    /// The raw fitted coefficients of the effect's regressors: name, value, uncertainty.
    pub coefficients: Vec<(String, f64, f64)>,
    /// Decrease of the residual RMS when the effect was added, metres.
    pub delta_rms_m: f64,
    /// Chi-square it removed.
    pub delta_chi2: f64,
    /// log10 of the Bayes factor in its favour (BIC approximation).
    pub evidence: f64,
    /// Bonferroni-corrected p-value of its F-test.
    pub p_value: f64,
    /// Parameters the data separate from the rigid-body model.
    pub rank: usize,
    /// Plain statement.
    pub statement: String,
    /// Other catalogue effects that explained the data similarly before this one was modelled.
    pub alternatives: Vec<String>,
}

/// The result of [`diagnose`].
#[derive(Debug)]
pub struct Diagnosis {
    pub rms_before_m: f64,
    pub rms_after_m: f64,
    /// RMS of the readings' standard uncertainties (the noise floor the model expects).
    pub noise_rms_m: f64,
    pub chi2_before: f64,
    pub dof_before: usize,
    pub chi2_after: f64,
    pub dof_after: usize,
    /// Found effects, in order of selection (strongest evidence first).
    pub effects: Vec<FoundEffect>,
    /// Where the rigid-body fit's excess residual is.
    pub locations: Vec<Location>,
    /// Where excess remains after the found effects are modelled.
    pub remaining: Vec<Location>,
    /// A statement when significant excess remains that the catalogue does not explain.
    pub unexplained: Option<String>,
    pub before: Solution,
    pub after: Solution,
    /// Each found effect's own signature in the readings (same order as `effects`): what it
    /// adds to every reading with its final parameters, line origins removed (see
    /// [`crate::estimator::Fit::effect_signals`]), metres.
    pub signals: Vec<Vec<f64>>,
    /// RMS and largest change of the identified volumetric error map, metres.
    pub map_change_rms_m: f64,
    pub map_change_max_m: f64,
    pub statements: Vec<String>,
    /// Every candidate tested, per selection round (the evidence behind the choices).
    pub rounds: Vec<Vec<CandidateReport>>,
}

/// One candidate's test in one round.
#[derive(Clone, Debug)]
pub struct CandidateReport {
    pub id: String,
    /// Scanned hyper-parameter (period, break position), if any.
    pub hyper: Option<f64>,
    pub delta_chi2: f64,
    pub rank: usize,
    /// Bonferroni-corrected over all candidates of the round.
    pub p_value: f64,
    pub evidence: f64,
    pub share: f64,
    pub cv_gain: Option<f64>,
    /// Corrected p-value with the line that holds most of the excess left out (when one does).
    pub without_dominant_p: Option<f64>,
    /// For the candidate chosen: the corrected p-value of the chi-square reduction that the
    /// refit with it actually achieved. Above the significance level the candidate is refuted
    /// (`accepted` false) and the round is chosen again without it.
    pub refit_p: Option<f64>,
    pub accepted: bool,
}

/// Kinds of candidate.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Family {
    Air,
    Material,
    Drift,
    Latency,
    Reversal,
    Periodic(usize),
    Nonrigid,
    Probe,
    BeamBreak(usize),
    Cyclic,
    /// Not a catalogue effect: a local anomaly in a cell of the volume (a competitor only).
    Local,
}

impl Family {
    /// Whether the effect has campaign-wide parameters (cross-validation across lines applies).
    fn global(self) -> bool {
        !matches!(self, Family::BeamBreak(_) | Family::Cyclic | Family::Local)
    }

    fn same_kind(self, other: Family) -> bool {
        match (self, other) {
            (Family::BeamBreak(a), Family::BeamBreak(b)) => a == b,
            (Family::Periodic(a), Family::Periodic(b)) => a == b,
            (a, b) => std::mem::discriminant(&a) == std::mem::discriminant(&b),
        }
    }
}

/// A candidate of one round.
struct Candidate {
    family: Family,
    effect: Box<dyn Effect>,
    /// Number of hypotheses it stands for (scanned hyper-parameters).
    tests: usize,
    /// Extra description of the scanned hyper-parameter.
    hyper: Option<f64>,
}

/// Evaluated candidate.
struct Evaluated {
    cand: Candidate,
    score: Score,
    p_value: f64,
    evidence: f64,
    share: f64,
    cv_gain: Option<f64>,
    /// Bonferroni-corrected p-value without the dominant line (when one holds most of the excess).
    without_dominant: Option<f64>,
}

/// Runs the diagnosis.
pub fn diagnose(layout: &ModelLayout, obs: &Observations, opts: &DiagnoseOptions) -> Result<Diagnosis, SolveError> {
    let base = fit(layout, obs, &opts.solve, &[])?;
    let geo = Geometry::new(obs, &base, opts.optics);
    let dirs = catalogue::directions(obs, &base, &geo);
    let before = base.solution().clone();
    let locations = locate::locate(obs, &geo, &dirs, &standardised(&before), dof_ratio(&before, obs.len()), opts.alpha);
    drop(base);
    // The readings as the refits see them: `probe_offset` moves the declared probe offsets.
    let mut work = obs.clone();
    let mut probe_shift = vec![Vector3::zeros(); geo.probes.len()];
    let mut hypers = Vec::new();

    let mut selected: Vec<(Family, Box<dyn Effect>)> = Vec::new();
    let mut found: Vec<FoundEffect> = Vec::new();
    let mut current = before.clone();
    let mut signals: Vec<Vec<f64>> = Vec::new();
    let mut rounds: Vec<Vec<CandidateReport>> = Vec::new();
    let mut local: Option<String> = None;
    // Candidates whose refit did not deliver the reduction their score promised.
    let mut refuted: Vec<(Family, Option<f64>)> = Vec::new();
    loop {
        if found.len() >= opts.max_effects || refuted.len() > MAX_REFUTED {
            break;
        }
        let refs: Vec<&dyn Effect> = selected.iter().map(|(_, e)| e.as_ref()).collect();
        let f = fit(layout, &work, &opts.solve, &refs)?;
        let candidates = propose(&work, &geo, &dirs, &f, &selected);
        let mut evaluated: Vec<Evaluated> = candidates.into_iter().map(|c| evaluate(&work, &f, c)).collect();
        evaluated.sort_by(|a, b| b.evidence.total_cmp(&a.evidence));
        let total_tests: usize = evaluated.iter().map(|e| e.cand.tests).sum::<usize>().max(1);
        // A p-value corrected for the `tests` hypotheses of its candidate, re-corrected for all
        // the hypotheses of the round (Bonferroni).
        let corrected = |p: f64, tests: usize| p * total_tests as f64 / tests as f64;
        let accept = |e: &Evaluated| {
            corrected(e.p_value, e.cand.tests) <= opts.alpha && e.evidence > 0.0 && e.share >= opts.min_share
        };
        // Cross-validation across lines for the campaign-wide effects that pass the other
        // criteria: the model and the effect are fitted on every other line and the effect's
        // parameters from each half must reduce the chi-square of the other half.
        let mut folds: Option<(Fit<'_>, Fit<'_>)> = None;
        let masks: [Vec<bool>; 2] =
            [(0..obs.groups.len()).map(|g| g % 2 == 0).collect(), (0..obs.groups.len()).map(|g| g % 2 == 1).collect()];
        // A line holding most of the excess: campaign-wide effects must stay significant
        // without it, or they are a local anomaly (a dent crossed by one beam) dressed up.
        let dominant = dominant_line(&work, f.solution());
        let mut without: Option<(Fit<'_>, Vec<bool>)> = None;
        let mut chosen = None;
        for (k, e) in evaluated.iter_mut().enumerate() {
            if !accept(e) || refuted.contains(&(e.cand.family, e.cand.hyper)) {
                continue;
            }
            if let (true, Some(g)) = (e.cand.family.global() && e.score.rank > 0, dominant) {
                if without.is_none() {
                    let sol = f.solution();
                    let mask: Vec<bool> = (0..work.groups.len()).map(|h| h != g).collect();
                    let o = SolveOptions {
                        group_mask: Some(mask.clone()),
                        initial_model: Some(sol.model.u.clone()),
                        initial_stations: sol.stations.iter().map(|s| (s.station, s.position)).collect(),
                        ..opts.solve.clone()
                    };
                    without = Some((fit(layout, &work, &o, &refs)?, mask));
                }
                let (fw, mask) = without.as_ref().unwrap();
                let sw = fw.score_masked(e.cand.effect.as_ref(), Some(mask));
                let stats = &fw.solution().stats;
                let p = f_test(sw.delta_chi2, sw.rank, stats.chi2, stats.dof as f64, e.cand.tests);
                e.without_dominant = Some(corrected(p, e.cand.tests));
                if corrected(p, e.cand.tests) > opts.alpha {
                    continue;
                }
            }
            if e.cand.family.global() && e.score.rank > 0 {
                if folds.is_none() {
                    // Started from the fit on all lines: each half is a weaker campaign.
                    let sol = f.solution();
                    let warm = SolveOptions {
                        group_mask: None,
                        initial_model: Some(sol.model.u.clone()),
                        initial_stations: sol.stations.iter().map(|s| (s.station, s.position)).collect(),
                        ..opts.solve.clone()
                    };
                    let fold = |m: &Vec<bool>| {
                        fit(layout, &work, &SolveOptions { group_mask: Some(m.clone()), ..warm.clone() }, &refs)
                    };
                    folds = Some((fold(&masks[0])?, fold(&masks[1])?));
                }
                let (fa, fb) = folds.as_ref().unwrap();
                let sa = fa.score_masked(e.cand.effect.as_ref(), Some(&masks[0]));
                let sb = fb.score_masked(e.cand.effect.as_ref(), Some(&masks[1]));
                // Half of the lines should determine the parameters with about twice the
                // variance of all lines. Effects that only the crossing of all lines separates
                // from the rigid-body model (e.g. nonrigid couplings: half the lines absorb
                // them) cannot be cross-validated this way; they rest on the other criteria.
                if determines(&e.score, &sa) && determines(&e.score, &sb) {
                    let gain = sb.gain(&sa.estimate) + sa.gain(&sb.estimate);
                    e.cv_gain = Some(gain);
                    if gain <= 0.0 {
                        continue;
                    }
                }
            }
            chosen = Some(k);
            break;
        }
        drop(folds);
        drop(without);
        rounds.push(
            evaluated
                .iter()
                .enumerate()
                .map(|(k, e)| CandidateReport {
                    id: e.cand.effect.id().to_string(),
                    hyper: e.cand.hyper,
                    delta_chi2: e.score.delta_chi2,
                    rank: e.score.rank,
                    p_value: corrected(e.p_value, e.cand.tests).min(1.0),
                    evidence: e.evidence,
                    share: e.share,
                    cv_gain: e.cv_gain,
                    without_dominant_p: e.without_dominant,
                    refit_p: None,
                    accepted: Some(k) == chosen,
                })
                .collect(),
        );
        let Some(pos) = chosen else { break };
        if evaluated[pos].cand.family == Family::Local {
            // Confined to one place better than any catalogue effect explains it: reported as
            // unexplained, where it is.
            local = evaluated[pos].cand.hyper.map(|c| geometry::cell_label(c as usize));
            break;
        }
        let best = evaluated.swap_remove(pos);
        let alternatives: Vec<String> = evaluated
            .iter()
            .filter(|e| e.score.delta_chi2 >= 0.5 * best.score.delta_chi2 && e.cand.family != best.cand.family)
            .map(|e| {
                format!(
                    "{} would explain {:.0} % as much",
                    e.cand.effect.id(),
                    100.0 * e.score.delta_chi2 / best.score.delta_chi2.max(1e-300)
                )
            })
            .collect();
        let p_value = corrected(best.p_value, best.cand.tests).min(1.0);
        drop(f);
        let (family, hyper, rank) = (best.cand.family, best.cand.hyper, best.score.rank);
        selected.push((family, best.cand.effect));
        let (work_before, shift_before) = (work.clone(), probe_shift.clone());
        let (sol, sig) = refit(layout, &mut work, opts, &selected, &geo, &mut probe_shift)?;
        // The score is the linearised reduction at the current fit; the refit is what the
        // effect explains. Where the two disagree (an extension nearly inside the model, whose
        // Schur complement is ill-conditioned: a nonrigid coupling that the splines almost
        // express, on a clean campaign at the noise floor), the effect explains nothing and is
        // not named.
        let realised = current.stats.chi2 - sol.stats.chi2;
        let tests = best.cand.tests;
        let refit_p =
            corrected(f_test(realised, rank, current.stats.chi2, current.stats.dof as f64, tests), tests).min(1.0);
        if let Some(c) = rounds.last_mut().and_then(|r| r.iter_mut().find(|c| c.accepted)) {
            c.refit_p = Some(refit_p);
        }
        if refit_p > opts.alpha {
            if let Some(c) = rounds.last_mut().and_then(|r| r.iter_mut().find(|c| c.accepted)) {
                c.accepted = false;
            }
            selected.pop();
            work = work_before;
            probe_shift = shift_before;
            refuted.push((family, hyper));
            continue;
        }
        hypers.push(hyper);
        signals = sig;
        let (id, coeffs) = sol.effects.last().cloned().expect("the new effect is fitted");
        found.push(FoundEffect {
            id,
            parameters: Vec::new(),
            coefficients: coeffs,
            delta_rms_m: current.stats.rms_m - sol.stats.rms_m,
            delta_chi2: current.stats.chi2 - sol.stats.chi2,
            evidence: best.evidence,
            p_value,
            rank: best.score.rank,
            statement: String::new(),
            alternatives,
        });
        current = sol;
    }
    // Every effect as the final refit (with all of them) estimates it.
    for (k, e) in found.iter_mut().enumerate() {
        let coeffs = current.effects[k].1.clone();
        let (parameters, statement) = describe(selected[k].0, &coeffs, obs, &geo, hypers[k]);
        e.parameters = parameters;
        e.statement = statement;
        e.coefficients = coeffs;
    }
    let after = current;
    let remaining = locate::locate(&work, &geo, &dirs, &standardised(&after), dof_ratio(&after, obs.len()), opts.alpha);
    let excess_p = locate::chi2_sf(after.stats.chi2, after.stats.dof as f64);
    let unexplained = (excess_p < opts.alpha).then(|| {
        let mut s = format!(
            "An excess residual remains that no catalogue effect explains: chi2/dof {:.2} (RMS {:.3} um against {:.3} um expected)",
            after.stats.variance_factor,
            after.stats.rms_m * 1e6,
            noise_rms(&after) * 1e6
        );
        let top: Vec<String> = remaining
            .iter()
            .filter(|l| l.kind == "spectrum" || l.share > 0.1)
            .take(4)
            .map(|l| match l.kind.as_str() {
                "spectrum" => format!("{} (spectrum)", l.label),
                _ => format!("{} ({}, {:.0} % of the excess in {:.0} % of the readings)", l.label, l.kind, 100.0 * l.share, 100.0 * l.fraction),
            })
            .collect();
        if top.is_empty() {
            s.push_str("; it is spread over the whole campaign (or the noise model underestimates the noise).");
        } else {
            s.push_str(&format!("; it is concentrated in: {}.", top.join("; ")));
        }
        if let Some(cell) = &local {
            s.push_str(&format!(" A local anomaly in the cell {cell} of the volume explains it better than any catalogue effect (a dent, a collision, a local deformation?)."));
        }
        s
    });
    let (map_change_rms_m, map_change_max_m) = map_change(&before.model, &after.model, obs);
    let mut statements = Vec::new();
    if found.is_empty() && unexplained.is_none() {
        statements.push(format!(
            "No effect found: the residual RMS {:.3} um is what the noise model expects (chi2/dof {:.2}).",
            before.stats.rms_m * 1e6,
            before.stats.variance_factor
        ));
    }
    for e in &found {
        statements.push(e.statement.clone());
    }
    if !found.is_empty() {
        statements.push(format!(
            "Residual RMS {:.3} um before, {:.3} um after (noise floor {:.3} um); the identified error map changed by {:.3} um RMS, {:.3} um at most.",
            before.stats.rms_m * 1e6,
            after.stats.rms_m * 1e6,
            noise_rms(&after) * 1e6,
            map_change_rms_m * 1e6,
            map_change_max_m * 1e6
        ));
    }
    if let Some(u) = &unexplained {
        statements.push(u.clone());
    }
    Ok(Diagnosis {
        rms_before_m: before.stats.rms_m,
        rms_after_m: after.stats.rms_m,
        noise_rms_m: noise_rms(&after),
        chi2_before: before.stats.chi2,
        dof_before: before.stats.dof,
        chi2_after: after.stats.chi2,
        dof_after: after.stats.dof,
        effects: found,
        locations,
        remaining,
        unexplained,
        before,
        after,
        map_change_rms_m,
        map_change_max_m,
        statements,
        rounds,
        signals,
    })
}

/// RMS of the readings' standard uncertainties scaled by the residual degrees of freedom: the
/// residual RMS a correct model gives.
fn noise_rms(s: &Solution) -> f64 {
    let n = s.sigmas.len().max(1) as f64;
    (s.sigmas.iter().map(|v| v * v).sum::<f64>() / n * s.stats.dof as f64 / n).sqrt()
}

/// Candidates of one round, given the current fit.
fn propose(
    obs: &Observations,
    geo: &Geometry,
    dirs: &[Vector3<f64>],
    f: &Fit<'_>,
    selected: &[(Family, Box<dyn Effect>)],
) -> Vec<Candidate> {
    let taken = |fam: Family| selected.iter().any(|(s, _)| s.same_kind(fam));
    let mut out: Vec<Candidate> = Vec::new();
    let push = |family: Family, effect: Box<dyn Effect>, tests: usize, hyper: Option<f64>, out: &mut Vec<Candidate>| {
        if !taken(family) {
            out.push(Candidate { family, effect, tests, hyper });
        }
    };
    let has_beams = obs.groups.iter().any(|g| g.kind == ObsKind::Beam);
    match catalogue::air_recorded(obs, geo) {
        Some(e) => push(Family::Air, Box::new(e), 1, None, &mut out),
        None => push(Family::Air, Box::new(catalogue::air_unrecorded(obs, geo)), 1, None, &mut out),
    }
    match catalogue::material_recorded(obs, dirs, geo) {
        Some(e) => push(Family::Material, Box::new(e), 1, None, &mut out),
        None => push(Family::Material, Box::new(catalogue::material_unrecorded(obs, dirs, geo)), 1, None, &mut out),
    }
    push(Family::Drift, Box::new(catalogue::setup_drift(obs, dirs, geo)), 1, None, &mut out);
    if let Some(e) = catalogue::latency(obs, dirs, geo) {
        push(Family::Latency, Box::new(e), 1, None, &mut out);
    }
    push(Family::Reversal, Box::new(catalogue::reversal(obs, dirs, geo)), 1, None, &mut out);
    push(Family::Nonrigid, Box::new(catalogue::nonrigid(obs, dirs, geo)), 1, None, &mut out);
    if let Some(e) = catalogue::probe_offset(obs, dirs, geo) {
        push(Family::Probe, Box::new(e), 1, None, &mut out);
    }
    if has_beams {
        push(Family::Cyclic, Box::new(catalogue::cyclic(obs, geo)), 1, None, &mut out);
    }
    // Scans on the current residuals.
    let sol = f.solution();
    let z = standardised(sol);
    for a in 0..3 {
        if taken(Family::Periodic(a)) {
            continue;
        }
        if let Some((periods, tests)) = locate::period_grid(obs, geo, dirs, a) {
            let (_, p) = locate::best_period(obs, dirs, &z, a, &periods);
            let p = refine_period(obs, geo, dirs, &z, a, p);
            push(Family::Periodic(a), Box::new(catalogue::periodic(obs, dirs, a, p)), tests, Some(p), &mut out);
        }
    }
    // Beam breaks: the best step position in each line from the residuals alone, with at
    // least STEP_SIDE readings on either side; the strongest few lines are then scored exactly.
    let mut steps: Vec<(f64, usize, usize)> = Vec::new();
    let mut positions = 0usize;
    for (g, gr) in obs.groups.iter().enumerate() {
        if taken(Family::BeamBreak(g)) || gr.len() < 2 * STEP_SIDE {
            continue;
        }
        let (mut best, mut at) = (0.0, 0);
        let n = gr.len() as f64;
        let total: f64 = gr.range().map(|i| z[i]).sum();
        let mut cum = 0.0;
        for (k, i) in gr.range().enumerate().skip(1) {
            cum += z[i - 1];
            // A step with fewer than STEP_SIDE readings on one side is one or two bad readings
            // (the line's origin is eliminated): at a turn of an on-the-fly run, the first
            // reading of a segment carries whatever the model gets wrong at the turn, and
            // calling that a lost count would name physics that is not there.
            if k < STEP_SIDE || gr.len() - k < STEP_SIDE {
                continue;
            }
            let m = k as f64;
            // Score of a step after point k-1 on the centred residuals (unit weights).
            let after = total - cum;
            let stat = (after - (n - m) / n * total).powi(2) / ((n - m) * m / n);
            if stat > best {
                best = stat;
                at = k;
            }
        }
        positions += gr.len() + 1 - 2 * STEP_SIDE;
        steps.push((best, g, at));
    }
    // The local competitor: the cell of the volume with the largest excess.
    let dof_ratio = dof_ratio(sol, obs.len());
    let mut cell_excess = vec![0.0; geometry::CELLS];
    for i in 0..obs.len() {
        cell_excess[geometry::cell(geo, &obs.x[i])] += z[i] * z[i] - dof_ratio;
    }
    if let Some((c, _)) = cell_excess.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) {
        push(
            Family::Local,
            Box::new(catalogue::local_anomaly(obs, dirs, geo, c)),
            geometry::CELLS,
            Some(c as f64),
            &mut out,
        );
    }
    steps.sort_by(|a, b| b.0.total_cmp(&a.0));
    for &(_, g, at) in steps.iter().take(3) {
        push(
            Family::BeamBreak(g),
            Box::new(catalogue::beam_break(obs, geo, g, at)),
            positions.max(1),
            Some(at as f64),
            &mut out,
        );
    }
    out
}

/// Readings a lost count needs on each side of its step to be told from a bad reading.
const STEP_SIDE: usize = 3;

/// How many chosen candidates a diagnosis may refute (their refit explains nothing) before it
/// stops looking.
const MAX_REFUTED: usize = 8;

/// Refines a period by golden-section search on the periodogram around `p`.
fn refine_period(obs: &Observations, geo: &Geometry, dirs: &[Vector3<f64>], z: &[f64], a: usize, p: f64) -> f64 {
    let len = geo.travel.ranges[a][1] - geo.travel.ranges[a][0];
    // The grid spacing in frequency was 0.25 / len.
    let f0 = 1.0 / p;
    let (mut lo, mut hi) = (f0 - 0.25 / len, f0 + 0.25 / len);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let score = |f: f64| locate::periodogram(obs, geo, dirs, z, a, 1.0 / f);
    for _ in 0..30 {
        let (m1, m2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if score(m1) > score(m2) {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    2.0 / (lo + hi)
}

/// Scores a candidate: F-test, evidence, share of the excess, cross-validation.
fn evaluate(obs: &Observations, f: &Fit<'_>, cand: Candidate) -> Evaluated {
    let sol = f.solution();
    let score = f.score(cand.effect.as_ref());
    let n = obs.len() as f64;
    let (chi2, dof) = (sol.stats.chi2, sol.stats.dof as f64);
    let k = score.rank as f64;
    let (p_value, evidence) = if score.rank == 0 || dof - k < 1.0 || !consistent(score.delta_chi2, chi2) {
        (1.0, f64::NEG_INFINITY)
    } else {
        let s2 = alternative_variance(score.delta_chi2, score.rank, chi2, dof);
        let p = f_test(score.delta_chi2, score.rank, chi2, dof, cand.tests);
        // BIC with the noise scale estimated under the alternative; the scanned hyper-parameter
        // counts as a parameter.
        let extra = if cand.hyper.is_some() { 1.0 } else { 0.0 };
        let bic_gain = score.delta_chi2 / s2 - (k + extra) * n.ln();
        (p, bic_gain / 2.0 / std::f64::consts::LN_10)
    };
    let excess = chi2 - dof;
    let share = if excess > 3.0 * (2.0 * dof).sqrt() { score.delta_chi2 / excess } else { 1.0 };
    Evaluated { cand, score, p_value, evidence, share, cv_gain: None, without_dominant: None }
}

/// P-value of the nested-model F-test of a chi-square reduction `delta_chi2` by `rank` new
/// parameters against a fit with `chi2` on `dof` degrees of freedom, corrected for `tests`
/// scanned hypotheses.
fn f_test(delta_chi2: f64, rank: usize, chi2: f64, dof: f64, tests: usize) -> f64 {
    let k = rank as f64;
    if rank == 0 || dof - k < 1.0 || !consistent(delta_chi2, chi2) {
        return 1.0;
    }
    let s2 = alternative_variance(delta_chi2, rank, chi2, dof);
    let fstat = (delta_chi2 / k) / s2;
    (f_sf(k, dof - k, fstat) * tests as f64).min(1.0)
}

/// Whether a score can be a property of the data: the linearised extension cannot remove more
/// than the whole chi-square of the fit (its residual sum of squares is not negative). A score
/// beyond that comes from a numerically singular Schur complement, an effect the campaign does
/// not separate whatever rank was counted (a few lines of one station, for a probe offset or a
/// nonrigid coupling): it is untestable, like an effect the model already expresses.
fn consistent(delta_chi2: f64, chi2: f64) -> bool {
    delta_chi2 <= chi2 * (1.0 + 1e-6)
}

/// Survival function of the F distribution with `d1`, `d2` degrees of freedom at `fstat`.
/// When the effect explains the residual almost entirely the statistic runs past 1e300
/// (`alternative_variance` floors at 1e-300) and statrs' `sf` forms `inf / inf` and panics in
/// the incomplete beta function; there the probability, `I_x(d2/2, d1/2)` with
/// `x = d2 / (d2 + d1 fstat)` below 1e-300, is zero in double precision.
fn f_sf(d1: f64, d2: f64, fstat: f64) -> f64 {
    if fstat.is_nan() {
        return 1.0;
    }
    if !(d1 * fstat + d2).is_finite() {
        return 0.0;
    }
    FisherSnedecor::new(d1, d2).map(|d| d.sf(fstat)).unwrap_or(1.0)
}

/// Variance of unit weight under the alternative (the fit extended by the effect).
fn alternative_variance(delta_chi2: f64, rank: usize, chi2: f64, dof: f64) -> f64 {
    (chi2 - delta_chi2).max(1e-300) / (dof - rank as f64)
}

/// Standardised residuals `r / sigma` of every reading of a fit.
fn standardised(s: &Solution) -> Vec<f64> {
    s.residuals.iter().zip(&s.sigmas).map(|(r, sigma)| r / sigma).collect()
}

/// Residual degrees of freedom per reading: the `z^2` a reading contributes on average under
/// noise alone.
fn dof_ratio(s: &Solution, n: usize) -> f64 {
    s.stats.dof as f64 / n.max(1) as f64
}

/// The line holding at least a third of the excess chi-square of a fit, if any.
fn dominant_line(obs: &Observations, sol: &Solution) -> Option<usize> {
    let (z, dof_ratio) = (standardised(sol), dof_ratio(sol, obs.len()));
    let excess: Vec<f64> =
        obs.groups.iter().map(|g| g.range().map(|i| z[i] * z[i]).sum::<f64>() - dof_ratio * g.len() as f64).collect();
    let total = sol.stats.chi2 - sol.stats.dof as f64;
    if total <= 3.0 * (2.0 * sol.stats.dof as f64).sqrt() {
        return None;
    }
    let (g, e) = excess.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
    (*e >= total / 3.0).then_some(g)
}

/// The SI unit of a found effect's parameter, from its name (the names `describe` and the
/// catalogue give carry their unit as a suffix): `m`, `s`, `rad`, `m/s`, `1/K`, `ppm`, `index`
/// (a station, beam, point or axis number) or `1` (dimensionless: a fraction, a relative scale).
/// Nonrigid coupling terms (`eX:P1(x)P1(y)`) are lengths.
pub fn parameter_unit(name: &str) -> &'static str {
    if name.ends_with("_m_per_s") {
        "m/s"
    } else if name.ends_with("_per_k") {
        "1/K"
    } else if name.contains("_ppm") {
        "ppm"
    } else if name.ends_with("_rad") {
        "rad"
    } else if name.ends_with("_s") {
        "s"
    } else if name.ends_with("_m") || (name.starts_with('e') && name.contains(":P")) {
        "m"
    } else if matches!(name, "axis" | "station" | "beam" | "index") {
        "index"
    } else {
        "1"
    }
}

/// Physical parameters and a plain statement for a found effect.
fn describe(
    family: Family,
    coeffs: &[(String, f64, f64)],
    obs: &Observations,
    geo: &Geometry,
    hyper: Option<f64>,
) -> (Vec<(String, f64, f64)>, String) {
    let get = |name: &str| coeffs.iter().find(|c| c.0 == name).map(|c| (c.1, c.2)).unwrap_or((0.0, 0.0));
    let um = |v: f64| v * 1e6;
    match family {
        Family::Air => {
            if geo.delta_air.is_some() {
                let (f, sf) = get("uncompensated_fraction");
                let delta = geo.delta_air.as_ref().unwrap();
                let (i_first, i_last) = time_extremes(obs);
                let d_end = delta[i_last] - delta[i_first];
                let air = |i: usize| obs.air[i].unwrap();
                let dt = air(i_last).temp_c - air(i_first).temp_c;
                let dp = air(i_last).pressure_pa - air(i_first).pressure_pa;
                (
                    vec![("uncompensated_fraction".into(), f, sf), ("index_change_ppm_end".into(), f * d_end * 1e6, sf * d_end.abs() * 1e6)],
                    format!(
                        "air_refraction: the air temperature changed by {dt:+.2} K (pressure {dp:+.0} Pa) during the campaign and the readings were not compensated for it (fraction {f:.3} +- {sf:.3}): {:+.2} ppm at the end.",
                        f * d_end * 1e6
                    ),
                )
            } else {
                let c: Vec<(String, f64, f64)> = coeffs.to_vec();
                let peak = (0..=20)
                    .map(|k| {
                        let tau = -1.0 + 0.1 * k as f64;
                        c.iter().enumerate().map(|(j, cc)| cc.1 * catalogue::legendre(j + 1, tau)).sum::<f64>().abs()
                    })
                    .fold(0.0, f64::max);
                (
                    vec![("scale_drift_ppm_peak".into(), peak * 1e6, c.iter().map(|cc| cc.2).fold(0.0, f64::max) * 1e6)],
                    format!("air_refraction: the readings' scale drifted by up to {:.2} ppm during the campaign, with no environment records to compensate it (air index; a uniform thermal expansion of the machine would look the same).", peak * 1e6),
                )
            }
        }
        Family::Material => {
            if let Some(dt) = &geo.dtemp {
                let (i_first, i_last) = time_extremes(obs);
                let p: Vec<(String, f64, f64)> = ["alpha_x_per_k", "alpha_y_per_k", "alpha_z_per_k"]
                    .iter()
                    .map(|n| (n.to_string(), get(n).0, get(n).1))
                    .collect();
                let s = format!(
                    "material_expansion: the machine scales went from {:.2} to {:.2} degC and the coordinates were not normalised to 20 degC; expansion coefficients X {:.2} +- {:.2}, Y {:.2} +- {:.2}, Z {:.2} +- {:.2} ppm/K.",
                    dt[i_first] + 20.0,
                    dt[i_last] + 20.0,
                    p[0].1 * 1e6,
                    p[0].2 * 1e6,
                    p[1].1 * 1e6,
                    p[1].2 * 1e6,
                    p[2].1 * 1e6,
                    p[2].2 * 1e6
                );
                (p, s)
            } else {
                (coeffs.to_vec(), "material_expansion: the scale of the machine axes drifted during the campaign (no machine temperatures recorded).".into())
            }
        }
        Family::Drift => {
            let mut parts = Vec::new();
            for (kind, sid) in &geo.stations {
                let k = if *kind == ObsKind::Beam { "station" } else { "tracer" };
                let v: Vec<(f64, f64)> =
                    ["vx", "vy", "vz"].iter().map(|c| get(&format!("{k}{sid}_{c}_m_per_s"))).collect();
                let speed = (v[0].0.powi(2) + v[1].0.powi(2) + v[2].0.powi(2)).sqrt();
                parts.push(format!(
                    "{k} {sid} {:.2} um/h ({:+.2}, {:+.2}, {:+.2})",
                    speed * 3.6e9,
                    v[0].0 * 3.6e9,
                    v[1].0 * 3.6e9,
                    v[2].0 * 3.6e9
                ));
            }
            (coeffs.to_vec(), format!("setup_drift: the device drifted during each line: {}.", parts.join("; ")))
        }
        Family::Latency => {
            let (t, st) = get("latency_s");
            (coeffs.to_vec(), format!("latency: the machine coordinates are {:.1} +- {:.1} us older than the abscissae (on-the-fly acquisition).", t * 1e6, st * 1e6))
        }
        Family::Reversal => {
            let b: Vec<(f64, f64)> = ["backlash_x_m", "backlash_y_m", "backlash_z_m"].iter().map(|n| get(n)).collect();
            (
                coeffs.to_vec(),
                format!(
                    "reversal: backlash X {:.2} +- {:.2} um, Y {:.2} +- {:.2} um, Z {:.2} +- {:.2} um.",
                    um(b[0].0),
                    um(b[0].1),
                    um(b[1].0),
                    um(b[1].1),
                    um(b[2].0),
                    um(b[2].1)
                ),
            )
        }
        Family::Periodic(a) => {
            let (s, ss) = get("sin_m");
            let (c, sc) = get("cos_m");
            let amp = (s * s + c * c).sqrt();
            let sa = ((s * ss).powi(2) + (c * sc).powi(2)).sqrt() / amp.max(1e-300);
            let phase = c.atan2(s);
            let period = hyper.unwrap_or(0.0);
            (
                vec![
                    ("axis".into(), a as f64, 0.0),
                    ("amplitude_m".into(), amp, sa),
                    ("period_m".into(), period, 0.0),
                    ("phase_rad".into(), phase, sa / amp.max(1e-300)),
                ],
                format!(
                    "periodic_pitch: a periodic error of {} of {:.3} +- {:.3} um with period {:.2} mm.",
                    ["X", "Y", "Z"][a],
                    um(amp),
                    um(sa),
                    period * 1e3
                ),
            )
        }
        Family::Nonrigid => {
            let biggest =
                coeffs.iter().max_by(|a, b| (a.1.abs() / a.2.max(1e-300)).total_cmp(&(b.1.abs() / b.2.max(1e-300))));
            let s = match biggest {
                Some(b) => format!("nonrigid: the errors depend on two coordinates at once, outside the rigid-body model; the strongest term is {} = {:.3} +- {:.3} um.", b.0, um(b.1), um(b.2)),
                None => "nonrigid: the errors depend on two coordinates at once.".into(),
            };
            (coeffs.to_vec(), s)
        }
        Family::Probe => {
            let mut parts = Vec::new();
            for (k, p) in geo.probes.iter().enumerate() {
                if k == geo.reference_probe {
                    continue;
                }
                let d: Vec<(f64, f64)> =
                    ["dx_m", "dy_m", "dz_m"].iter().map(|c| get(&format!("probe{k}_{c}"))).collect();
                parts.push(format!(
                    "probe {k} declared at ({:.3}, {:.3}, {:.3}) m: ({:+.1}, {:+.1}, {:+.1}) mm +- ({:.1}, {:.1}, {:.1})",
                    p.x,
                    p.y,
                    p.z,
                    d[0].0 * 1e3,
                    d[1].0 * 1e3,
                    d[2].0 * 1e3,
                    d[0].1 * 1e3,
                    d[1].1 * 1e3,
                    d[2].1 * 1e3
                ));
            }
            let r = geo.probes[geo.reference_probe];
            (
                coeffs.to_vec(),
                format!(
                    "probe_offset: relative to probe {} at ({:.3}, {:.3}, {:.3}) m, {}.",
                    geo.reference_probe,
                    r.x,
                    r.y,
                    r.z,
                    parts.join("; ")
                ),
            )
        }
        Family::BeamBreak(g) => {
            let gr = &obs.groups[g];
            let at = hyper.unwrap_or(0.0) as usize;
            let (step, s) = get("step_m");
            let i = gr.start + at;
            (
                vec![("station".into(), gr.station as f64, 0.0), ("beam".into(), gr.line as f64, 0.0), ("index".into(), at as f64, 0.0), ("step_m".into(), step, s)],
                format!(
                    "beam_break: {} lost its count between points {} and {} (t = {:.1} s): a step of {:.3} +- {:.3} um ({:.1} half wavelengths).",
                    gr.label(),
                    at.saturating_sub(1),
                    at,
                    obs.t[i],
                    um(step),
                    um(s),
                    step / 316.5e-9
                ),
            )
        }
        Family::Local => (coeffs.to_vec(), "local_anomaly: an error confined to one cell of the volume.".into()),
        Family::Cyclic => {
            let (amp, sa) = catalogue::cyclic_amplitude(coeffs);
            let note = if geo.fringes_from_records {
                ""
            } else {
                " (fringe count computed with standard air: no air records)"
            };
            (vec![("amplitude_m".into(), amp, sa)], format!("cyclic_nonlinearity: the interferometer has a periodic error of {:.1} +- {:.1} nm, one period per fringe{note}.", amp * 1e9, sa * 1e9))
        }
    }
}

/// Fits the model with the selected effects. Probe offsets enter the kinematics nonlinearly
/// (through the tool rotation, which the linear `probe_offset` regressor takes from the first
/// fit): once that effect is selected, the declared offsets in `work` are moved by its estimate
/// and the model refitted until the correction is below a hundredth of its uncertainty; the
/// reported offsets are the total moves (`shift`) plus the last correction.
fn refit(
    layout: &ModelLayout,
    work: &mut Observations,
    opts: &DiagnoseOptions,
    selected: &[(Family, Box<dyn Effect>)],
    geo: &Geometry,
    shift: &mut [Vector3<f64>],
) -> Result<(Solution, Vec<Vec<f64>>), SolveError> {
    let refs: Vec<&dyn Effect> = selected.iter().map(|(_, e)| e.as_ref()).collect();
    let probe_param = |name: &str| -> Option<(usize, usize)> {
        let rest = name.strip_prefix("probe")?;
        let (k, c) = rest.split_once('_')?;
        Some((k.parse().ok()?, ["dx_m", "dy_m", "dz_m"].iter().position(|n| *n == c)?))
    };
    let slot = selected.iter().position(|(f, _)| *f == Family::Probe);
    let mut f = fit(layout, work, &opts.solve, &refs)?;
    for _ in 0..8 {
        let Some(slot) = slot else { break };
        let mut step = vec![Vector3::zeros(); shift.len()];
        let mut worst = 0.0f64;
        for (name, value, sigma) in &f.solution().effects[slot].1 {
            if let Some((k, c)) = probe_param(name) {
                step[k][c] = *value;
                worst = worst.max(value.abs() / sigma.max(1e-300));
            }
        }
        if worst < 0.01 {
            break;
        }
        drop(f);
        for (i, p) in work.p.iter_mut().enumerate() {
            *p += step[geo.probe_of[i]];
        }
        for (s, d) in shift.iter_mut().zip(&step) {
            *s += d;
        }
        f = fit(layout, work, &opts.solve, &refs)?;
    }
    let mut effects = f.solution().effects.clone();
    if let Some(slot) = slot {
        for (name, value, _) in &mut effects[slot].1 {
            if let Some((k, c)) = probe_param(name) {
                *value += shift[k][c];
            }
        }
    }
    // The probe offset's signal is that of its whole move (to first order), not of the last
    // correction only.
    let params: Vec<Vec<f64>> = effects.iter().map(|(_, c)| c.iter().map(|v| v.1).collect()).collect();
    let signals = f.effect_signals(&params);
    let mut sol = f.into_solution();
    sol.effects = effects;
    Ok((sol, signals))
}

/// Whether a fold's score determines an effect's parameters nearly as well as expected from
/// half of the data: the median ratio of the full to the fold variance is at least 0.1 (about
/// 0.5 expected).
fn determines(full: &Score, fold: &Score) -> bool {
    let var = |s: &Score, j: usize| s.covariance[(j, j)];
    let mut ratios: Vec<f64> = (0..full.estimate.len().min(fold.estimate.len()))
        .filter(|&j| var(full, j) > 0.0 && var(fold, j) > 0.0 && var(fold, j).is_finite())
        .map(|j| var(full, j) / var(fold, j))
        .collect();
    if ratios.is_empty() {
        return false;
    }
    ratios.sort_by(f64::total_cmp);
    ratios[ratios.len() / 2] >= 0.1
}

/// Readings with the earliest and the latest time.
fn time_extremes(obs: &Observations) -> (usize, usize) {
    let first = (0..obs.len()).min_by(|&a, &b| obs.t[a].total_cmp(&obs.t[b])).unwrap_or(0);
    let last = (0..obs.len()).max_by(|&a, &b| obs.t[a].total_cmp(&obs.t[b])).unwrap_or(0);
    (first, last)
}

/// RMS and largest change of the volumetric error between two models over a grid and the
/// campaign's probe offsets.
fn map_change(a: &ErrorModel, b: &ErrorModel, obs: &Observations) -> (f64, f64) {
    let mut offsets: Vec<Vector3<f64>> = Vec::new();
    for p in &obs.p {
        if !offsets.iter().any(|q| (q - p).norm() < 1e-9) {
            offsets.push(*p);
        }
    }
    let step = crate::axis::Axis::ALL.iter().map(|&ax| a.layout.travel.length(ax)).fold(0.0, f64::max) / 8.0;
    let (mut s2, mut m, mut n) = (0.0f64, 0.0f64, 0.0f64);
    for x in predict::grid(&a.layout.travel, step) {
        for p in &offsets {
            let d = (a.error(&x, p) - b.error(&x, p)).norm();
            s2 += d * d;
            m = m.max(d);
            n += 1.0;
        }
    }
    ((s2 / n.max(1.0)).sqrt(), m)
}

#[cfg(test)]
mod unit_tests {
    use super::{f_sf, parameter_unit};

    #[test]
    fn f_test_survives_statistics_past_any_double() {
        // What a degenerate campaign (a few lines of one station) gives for probe_offset: the
        // score removes more than the fit's chi-square, the statistic is about 5e307.
        assert_eq!(f_sf(5.0, 210.0, 5.2e307), 0.0);
        assert_eq!(f_sf(22.0, 193.0, f64::INFINITY), 0.0);
        assert_eq!(f_sf(3.0, 100.0, f64::NAN), 1.0);
        // Ordinary statistics are statrs' own.
        let p = f_sf(3.0, 100.0, 2.0);
        assert!(p > 0.1 && p < 0.15, "{p}");
    }

    #[test]
    fn units_follow_the_parameter_names() {
        for (name, unit) in [
            ("uncompensated_fraction", "1"),
            ("index_change_ppm_end", "ppm"),
            ("scale_drift_ppm_peak", "ppm"),
            ("scale_drift_p1", "1"),
            ("alpha_x_per_k", "1/K"),
            ("station2_vx_m_per_s", "m/s"),
            ("latency_s", "s"),
            ("backlash_x_m", "m"),
            ("phase_rad", "rad"),
            ("period_m", "m"),
            ("probe1_dz_m", "m"),
            ("ex:P1(y)P2(z)", "m"),
            ("station", "index"),
            ("index", "index"),
            ("step_m", "m"),
        ] {
            assert_eq!(parameter_unit(name), unit, "{name}");
        }
    }
}
