//! Per-reading series along the measured lines (residuals of a fit, or any other per-reading
//! quantity such as an effect's signature) and their RMS per line.
//!
//! Each line is its own series, `<root>/stations/<s>/beams/<b>`, in micrometres, on three
//! timelines: [`paths::CAMPAIGN_TIME`] (over time), [`paths::POSITION_MM`] (over the abscissa
//! along the line) and [`paths::BEAM_INDEX`] (the spread of each line at its index).

use super::colors;
use super::geometry;
use super::paths;
use crate::rerun::{RecordingStream, RecordingStreamResult, TimeColumn};
use volcal::campaign::Observations;

/// Logs `values_m` (one per reading of `obs`, metres) as one point series per line under
/// `root`, coloured by station. `what` names the quantity in the legend (e.g. "residual").
pub fn log_line_series(
    rec: &RecordingStream,
    root: &str,
    obs: &Observations,
    values_m: &[f64],
    what: &str,
) -> anyhow::Result<()> {
    anyhow::ensure!(values_m.len() == obs.len(), "{} values for {} readings", values_m.len(), obs.len());
    for (k, g) in obs.groups.iter().enumerate() {
        let path = paths::line_series(root, g);
        rec.log_static(
            path.as_str(),
            &crate::rerun::SeriesPoints::new()
                .with_colors([colors::station(g.station)])
                .with_names([format!("{what} {}", g.label())])
                .with_marker_sizes([1.5]),
        )?;
        let pos_mm: Vec<i64> = geometry::abscissa_m(obs, g).iter().map(|s| (s * 1e3).round() as i64).collect();
        let n = g.len();
        rec.send_columns(
            path.as_str(),
            [
                TimeColumn::new_duration_secs(paths::CAMPAIGN_TIME, obs.t[g.range()].iter().copied()),
                TimeColumn::new_sequence(paths::POSITION_MM, pos_mm),
                TimeColumn::new_sequence(paths::BEAM_INDEX, std::iter::repeat_n(k as i64, n)),
            ],
            crate::rerun::Scalars::new(values_m[g.range()].iter().map(|v| v * 1e6)).columns_of_unit_batches()?,
        )?;
    }
    Ok(())
}

/// Logs the RMS of `values_m` per line as bar charts `<root>/stations/<s>` (micrometres), one
/// per station in its colour, each bar at the line's [`paths::BEAM_INDEX`]. Static.
pub fn log_rms_bars(
    rec: &RecordingStream,
    root: &str,
    obs: &Observations,
    values_m: &[f64],
) -> RecordingStreamResult<()> {
    let rms = obs.rms_per_line(values_m);
    let mut stations: Vec<u32> = obs.groups.iter().map(|g| g.station).collect();
    stations.sort_unstable();
    stations.dedup();
    for s in stations {
        let (idx, val): (Vec<f64>, Vec<f64>) = obs
            .groups
            .iter()
            .enumerate()
            .filter(|(_, g)| g.station == s)
            .map(|(k, _)| (k as f64, rms[k] * 1e6))
            .unzip();
        rec.log_static(
            paths::station_series(root, s),
            &crate::rerun::BarChart::new(val).with_abscissa(idx).with_color(colors::station(s)),
        )?;
    }
    Ok(())
}
