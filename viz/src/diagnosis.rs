//! What `volcal diagnose --rerun` records: the solved campaign as `volcal solve --rerun` shows
//! it (with the effects modelled), and beside it the evidence of the diagnosis: the residuals
//! of the rigid-body fit before, each named effect's own signature, the residuals after, their
//! RMS per line before and after, and the report.
//!
//! Comparing the three series plots is the point: the signature of a named effect has the
//! shape of the excess in the residuals before (a ramp over time for a drift, a sine along an
//! axis for a periodic error, a step inside one beam for a lost count), and the residuals
//! after are flat at the noise.

use super::layout::{Container, Layout, View};
use super::paths::{
    self, effect_signature, DIAGNOSIS_REPORT as REPORT, RESIDUALS_AFTER, RESIDUALS_BEFORE, RMS_AFTER, RMS_BEFORE,
};
use super::{blueprint, residuals, solve, RerunArgs};
use crate::rerun::RecordingStream;
use anyhow::Result;
use volcal::campaign::Observations;
use volcal::diagnose::Diagnosis;

/// The timeline on which an effect shows best: time for the effects that grow with time,
/// the position along the line for the others.
fn timeline_of(id: &str) -> &'static str {
    match id {
        "air_refraction" | "material_expansion" | "setup_drift" => paths::CAMPAIGN_TIME,
        _ => paths::POSITION_MM,
    }
}

/// Default layout: the report and the RMS per line before and after on the left, the scene
/// in the middle, on the right the residuals before, the signature of each named effect and
/// the residuals after, one above the other on the same timeline.
pub fn layout(d: &Diagnosis, obs: &Observations) -> Layout {
    let travel = &d.after.model.layout.travel;
    let left = Container::vertical([
        View::text_document("Diagnosis", [format!("+ /{REPORT}")]).into(),
        blueprint::rms_view("Residual RMS per line before (µm)", RMS_BEFORE).into(),
        blueprint::rms_view("Residual RMS per line after (µm)", RMS_AFTER).into(),
    ])
    .shares([1.6, 1.0, 1.0]);
    let timeline = d.effects.first().map_or(paths::POSITION_MM, |e| timeline_of(&e.id));
    // On campaign time, the whole campaign (with a margin); on positions the default fits.
    let (t0, t1) = obs.t.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| (a.min(t), b.max(t)));
    let margin = 0.02 * (t1 - t0).max(1.0);
    let series = |title: &str, root: &str| {
        let v = blueprint::series_view(title, root);
        if timeline == paths::CAMPAIGN_TIME && t0.is_finite() {
            blueprint::campaign_time_span(v, t0 - margin, t1 + margin).into()
        } else {
            v.into()
        }
    };
    let mut right = vec![series("Residuals before: rigid-body model only (µm)", RESIDUALS_BEFORE)];
    for e in &d.effects {
        right.push(series(&format!("Signature of {} (µm)", e.id), &effect_signature(&e.id)));
    }
    let after_title = if d.effects.is_empty() {
        "Residuals after: no effect named (µm)".to_string()
    } else {
        "Residuals after: with the named effects (µm)".to_string()
    };
    right.push(series(&after_title, RESIDUALS_AFTER));
    let root = Container::horizontal([
        left.into(),
        blueprint::scene_view(
            "Volume: beams, stations, volumetric error (with the effects)",
            Some(travel),
            1.35,
            solve::hidden_in_scene(obs),
        )
        .into(),
        Container::vertical(right).into(),
    ])
    .shares([0.9, 1.1, 1.3]);
    blueprint::first_screen(root, timeline)
}

/// Opens the recording(s) asked for by `args` and logs the diagnosis of `obs` with the
/// report text `report`. Does nothing when no `--rerun*` flag was given.
pub fn record(args: &RerunArgs, name: &str, obs: &Observations, d: &Diagnosis, report: &str) -> Result<()> {
    let Some(rec) = args.open(name, &layout(d, obs))? else { return Ok(()) };
    log_diagnosis(&rec, name, obs, d, report)?;
    rec.flush_blocking()?;
    Ok(())
}

/// Logs the diagnosis into `rec`: the solved campaign (the refit with the effects, as
/// [`solve::log_solution`] logs it), then the diagnosis entities.
pub fn log_diagnosis(rec: &RecordingStream, name: &str, obs: &Observations, d: &Diagnosis, report: &str) -> Result<()> {
    solve::log_solution(rec, name, obs, &d.after)?;
    residuals::log_line_series(rec, RESIDUALS_BEFORE, obs, &d.before.residuals, "residual before")?;
    residuals::log_line_series(rec, RESIDUALS_AFTER, obs, &d.after.residuals, "residual after")?;
    residuals::log_rms_bars(rec, RMS_BEFORE, obs, &d.before.residuals)?;
    residuals::log_rms_bars(rec, RMS_AFTER, obs, &d.after.residuals)?;
    for (e, signal) in d.effects.iter().zip(&d.signals) {
        residuals::log_line_series(rec, &effect_signature(&e.id), obs, signal, &e.id)?;
    }
    rec.log_static(REPORT, &crate::rerun::TextDocument::new(report.to_string()))?;
    Ok(())
}
