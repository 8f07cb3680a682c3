//! The 18 error functions and the 3 squareness errors over axis position, each with its
//! expanded uncertainty band (k = 2), in micrometres and microradians, on the
//! [`paths::POSITION_MM`] timeline.
//!
//! One plot per axis and kind (`functions/X/translation`: EXX, EYX, EZX; `functions/X/rotation`:
//! EAX, EBX, ECX; squareness joins the rotations of the axis it belongs to, flat over its
//! travel). The band is drawn as two thin faded lines, series 1 and 2 of the function's entity.

use super::colors;
use super::paths;
use crate::rerun::{RecordingStream, TimeColumn};
use volcal::predict::{self, Uncertainty, COVERAGE_K};
use volcal::{Axis, ErrorFunction, ErrorModel, Motion, Squareness};

/// Positions at which each function is sampled for display.
pub const SAMPLES: usize = 61;

/// Display unit of a function: micrometres for translations, microradians for rotations.
pub fn display_unit(motion: Motion) -> &'static str {
    match motion {
        Motion::Translation => "µm",
        Motion::Rotation => "µrad",
    }
}

/// Logs every function of `model` with its band from `unc` (the coefficient covariance); where
/// the data do not determine a function it is drawn without a band, and named so.
pub fn log_error_functions(rec: &RecordingStream, model: &ErrorModel, unc: &Uncertainty<'_>) -> anyhow::Result<()> {
    let cov = unc.covariance;
    for f in ErrorFunction::all() {
        let [lo, hi] = model.layout.travel.range(f.axis);
        let q: Vec<f64> = (0..SAMPLES).map(|i| lo + (hi - lo) * i as f64 / (SAMPLES - 1) as f64).collect();
        let v: Vec<f64> = q.iter().map(|&q| model.function_value(f, q)).collect();
        let u: Vec<f64> = q.iter().map(|&q| COVERAGE_K * predict::function_sigma(model, unc, f, q)).collect();
        // Where the data do not determine the function the band is NaN: the viewer draws none
        // there (a band of zero width would read as a value known exactly).
        let open = u.iter().filter(|u| !u.is_finite()).count();
        let said = match open {
            0 => "",
            n if n == u.len() => ", not determined by the data",
            _ => ", not determined by the data where it has no band",
        };
        let u: Vec<f64> = u.into_iter().map(|u| if u.is_finite() { u } else { f64::NAN }).collect();
        let name = format!("{} ({}){said}", f.name(), f.describe());
        let color = colors::component(f.component.index());
        log_with_band(rec, &paths::function(f), &name, color, &q, &v, &u)?;
    }
    for s in Squareness::ALL {
        let [lo, hi] = model.layout.travel.range(s.axis());
        let k = model.layout.squareness_index(s);
        let u = COVERAGE_K * cov[(k, k)].max(0.0).sqrt();
        let v = model.squareness(s);
        let color = squareness_color(s);
        log_with_band(
            rec,
            &paths::squareness(s),
            &format!("{} ({})", s.name(), s.describe()),
            color,
            &[lo, hi],
            &[v, v],
            &[u, u],
        )?;
    }
    Ok(())
}

/// Colour of a squareness line (distinct from the three rotations it is plotted with, and
/// from the other squareness of the same axis) and its name in plot titles.
fn squareness_color(s: Squareness) -> colors::Rgba {
    match s {
        Squareness::EA0Z => colors::component(4),
        _ => colors::component(3),
    }
}

fn squareness_color_name(s: Squareness) -> &'static str {
    match s {
        Squareness::EA0Z => "magenta",
        _ => "yellow",
    }
}

/// One function `v(q)` with band `v +- u` (SI units; scaled to µm/µrad for display): one
/// entity with three series (value, upper and lower bound of the band), which keeps the
/// recording small.
fn log_with_band(
    rec: &RecordingStream,
    path: &str,
    name: &str,
    color: colors::Rgba,
    q_m: &[f64],
    v: &[f64],
    u: &[f64],
) -> anyhow::Result<()> {
    let short = name.split(' ').next().unwrap_or(name);
    rec.log_static(
        path,
        &crate::rerun::SeriesLines::new()
            .with_colors([color, colors::faded(color), colors::faded(color)])
            .with_names([name.to_string(), format!("{short} + U (k=2)"), format!("{short} - U (k=2)")])
            .with_widths([2.0, 1.0, 1.0]),
    )?;
    let pos: Vec<i64> = q_m.iter().map(|q| (q * 1e3).round() as i64).collect();
    let values = v.iter().zip(u).flat_map(|(v, u)| [v * 1e6, (v + u) * 1e6, (v - u) * 1e6]);
    rec.send_columns(
        path,
        [TimeColumn::new_sequence(paths::POSITION_MM, pos)],
        crate::rerun::Scalars::new(values).columns(std::iter::repeat_n(3, q_m.len()))?,
    )?;
    Ok(())
}

/// Title of the plot of `axis`'s translations or rotations, with the unit.
/// Title of the plot of `axis`'s translations or rotations: the functions with their colours
/// (the plots have no legend), the unit, and the abscissa.
pub fn plot_title(axis: Axis, motion: Motion) -> String {
    let names: Vec<String> = Axis::ALL
        .iter()
        .map(|&c| ErrorFunction { axis, motion, component: c }.name())
        .zip(["red", "green", "blue"])
        .map(|(n, c)| format!("{n} {c}"))
        .collect();
    let sq: Vec<String> = Squareness::ALL
        .iter()
        .filter(|s| motion == Motion::Rotation && s.axis() == axis)
        .map(|s| format!("{} {}", s.name(), squareness_color_name(*s)))
        .collect();
    let all = names.into_iter().chain(sq).collect::<Vec<_>>().join(", ");
    format!("{all} ({}) over {} (mm)", display_unit(motion), axis.letter())
}
