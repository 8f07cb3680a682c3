//! Solving a loaded campaign for a machine file, and what is shared by every place that does
//! (the `volcal` tool, the replay node, the tests): the model file with its provenance, the
//! printed summary, the comparison with a simulation truth.

use crate::machine::Machine;
use crate::model_file::{BeamAlignmentEntry, ModelFile, Provenance, RepresentationChoice};
use crate::report;
use anyhow::Result;
use nalgebra::Vector3;
use volcal::campaign::{prepare, Campaign, Prepared};
use volcal::estimator::Solution;
use volcal::predict::{self, Uncertainty};
use volcal::{alignment, gauge, solve, ErrorModel, ObsKind, SolveOptions};

/// A solved campaign.
pub struct Solved {
    pub machine: Machine,
    pub prepared: Prepared,
    pub solution: Solution,
    pub file: ModelFile,
}

/// Prepares and solves a campaign for a machine. Input warnings go to stderr prefixed by
/// `source`.
pub fn solve_campaign(campaign: &Campaign, machine: Machine, source: &str, provenance: Provenance) -> Result<Solved> {
    let prepared = prepare_campaign(campaign, &machine, source)?;
    let setup = machine.setup_for(&prepared.obs).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
    let solution = match setup.solution {
        Some(s) => s,
        None => {
            solve(&setup.layout, &prepared.obs, &setup.options, &[]).map_err(|e| anyhow::anyhow!("{source}: {e}"))?
        }
    };
    let (solution, beam_alignment) = beam_alignment(&machine, &prepared, &setup.options, solution, source)?;
    let mut file = ModelFile::from_solution(&solution, &prepared.obs.groups, provenance);
    file.representation_choice =
        setup.knots.as_ref().map(|k| RepresentationChoice::new(k, solution.smoothing.as_ref()));
    file.beam_alignment = beam_alignment;
    Ok(Solved { machine, prepared, solution, file })
}

/// With fixed beams: the solution with its uncertainty covering the other beam alignment when
/// the machine file does not state one ([`alignment::cover`]), and what the model file records.
fn beam_alignment(
    machine: &Machine,
    prepared: &Prepared,
    options: &SolveOptions,
    solution: Solution,
    source: &str,
) -> Result<(Solution, Option<BeamAlignmentEntry>)> {
    if !prepared.obs.groups.iter().any(|g| g.kind == ObsKind::Beam) {
        return Ok((solution, None));
    }
    let aligned_with = options.beam_alignment;
    if machine.file.beam_alignment.is_some() {
        let separation = alignment::separation(&solution.model, &solution.sigmas, &prepared.obs);
        let entry = BeamAlignmentEntry { aligned_with, stated: true, separation, largest_change_m: 0.0 };
        return Ok((solution, Some(entry)));
    }
    let (solution, c) =
        alignment::cover(&prepared.obs, options, solution).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
    let entry = BeamAlignmentEntry {
        aligned_with,
        stated: false,
        separation: c.separation,
        largest_change_m: c.largest_change_m,
    };
    Ok((solution, Some(entry)))
}

/// The observations of a campaign for `machine`, its warnings printed with `source` (the file
/// or bag they came from) and errors naming it.
pub fn prepare_campaign(campaign: &Campaign, machine: &Machine, source: &str) -> Result<Prepared> {
    let prepared =
        prepare(campaign, &machine.layout.travel, &machine.expansion).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
    for w in &prepared.warnings {
        eprintln!("warning: {source}: {w}");
    }
    Ok(prepared)
}

/// Distinct probe offsets of a campaign.
pub fn probe_offsets(c: &Campaign) -> Vec<Vector3<f64>> {
    let mut v: Vec<Vector3<f64>> = Vec::new();
    for r in &c.readings {
        if !v.iter().any(|p| (p - r.p).norm() < 1e-9) {
            v.push(r.p);
        }
    }
    v
}

/// The summary printed by `volcal solve` and `volcal report`.
pub fn summary(model: &ErrorModel, unc: &Uncertainty<'_>, file: &ModelFile, offsets: &[Vector3<f64>]) -> String {
    let mut out = String::new();
    out.push_str(&format!(
        "Machine {}, travel X [{}, {}] Y [{}, {}] Z [{}, {}] m, gauge {}\n",
        file.topology,
        file.travel[0][0],
        file.travel[0][1],
        file.travel[1][0],
        file.travel[1][1],
        file.travel[2][0],
        file.travel[2][1],
        file.gauge.name()
    ));
    out.push_str(&format!("Representation: {}\n", model.layout.describe()));
    if let Some(c) = &file.representation_choice {
        out.push_str("Chosen from the data (representation: auto):\n");
        for s in &c.statements {
            out.push_str(&format!("  {s}\n"));
        }
    }
    out.push('\n');
    out.push_str(&report::functions_table(model, unc));
    out.push('\n');
    let offsets = if offsets.is_empty() { vec![Vector3::zeros()] } else { offsets.to_vec() };
    out.push_str(&report::max_error_lines(model, unc, &offsets).0);
    out.push_str(&report::interpolation_line(unc));
    if let Some(r) = &file.residuals {
        let worst = r.lines.iter().max_by(|a, b| a.rms_m.total_cmp(&b.rms_m));
        out.push_str(&format!(
            "\nResiduals: {} readings, RMS {:.4} um, chi2/dof {:.3} ({} dof){}\n",
            r.n_obs,
            r.rms_m * 1e6,
            r.variance_factor,
            r.dof,
            worst
                .map(|w| format!(
                    "; worst line: station {} {} {} RMS {:.4} um",
                    w.station,
                    volcal::ObsKind::parse(&w.kind).unwrap_or(volcal::ObsKind::Range).line_word(),
                    w.line,
                    w.rms_m * 1e6
                ))
                .unwrap_or_default()
        ));
    }
    if !file.stations.is_empty() {
        for s in &file.stations {
            out.push_str(&format!(
                "Station {}: ({:.6}, {:.6}, {:.6}) m +- ({:.1}, {:.1}, {:.1}) um\n",
                s.station,
                s.position_m[0],
                s.position_m[1],
                s.position_m[2],
                s.sigma_m[0] * 1e6,
                s.sigma_m[1] * 1e6,
                s.sigma_m[2] * 1e6
            ));
        }
    }
    out.push_str("\nIdentifiability:\n");
    for s in &file.identifiability.statements {
        out.push_str(&format!("  {s}\n"));
    }
    for w in &file.warnings {
        out.push_str(&format!("warning: {w}\n"));
    }
    out
}

/// Gauge-aligned comparison of an estimate with simulation truth.
pub struct TruthComparison {
    pub rms_m: f64,
    pub max_m: f64,
    /// RMS of the predicted standard uncertainty (sqrt of the mean trace of the covariance).
    pub predicted_rms_m: f64,
    /// Grid points (x offsets) where the estimate is not determined, left out of the figures.
    pub undetermined_points: usize,
}

/// Compares an estimate with truth over a grid and the given probe offsets, after moving the
/// truth along the gauge freedoms onto the estimate's gauge (the gauge's functionals evaluated on
/// the truth's own functions, so that whatever the estimate's representation misses counts as
/// error). Points where the estimate is not determined by the data are left out and counted.
pub fn compare_with_truth(
    est: &ErrorModel,
    unc: &Uncertainty<'_>,
    truth: &ErrorModel,
    g: volcal::Gauge,
    offsets: &[Vector3<f64>],
    step: f64,
) -> TruthComparison {
    let aligned = ErrorModel { layout: truth.layout.clone(), u: gauge::align(&truth.layout, g, &truth.u) };
    let (mut s2, mut m, mut v2, mut n, mut undetermined) = (0.0, 0.0f64, 0.0, 0usize, 0usize);
    for x in predict::grid(&est.layout.travel, step) {
        for p in offsets {
            let pe = predict::predict(est, unc, &x, p);
            if !pe.is_determined() {
                undetermined += 1;
                continue;
            }
            let d = (est.error(&x, p) - aligned.error(&x, p)).norm();
            s2 += d * d;
            m = m.max(d);
            v2 += pe.cov.trace();
            n += 1;
        }
    }
    let k = n.max(1) as f64;
    TruthComparison {
        rms_m: (s2 / k).sqrt(),
        max_m: m,
        predicted_rms_m: (v2 / k).sqrt(),
        undetermined_points: undetermined,
    }
}
