//! The volumetric error map: at grid points over the travel, an arrow along the error vector
//! `e(X, p)`, scaled so that the largest arrow is a visible fraction of the volume (the scale
//! is in the labels and drawn as a scale bar), coloured by magnitude; the largest error
//! marked with its value, uncertainty and position.

use super::colors;
use super::paths;
use super::scene::{f32p, f32v};
use crate::rerun::{RecordingStream, RecordingStreamResult};
use nalgebra::{Point3, Vector3};
use volcal::band::{simultaneous_band, SimultaneousBand, BAND_DRAWS, BAND_LEVEL};
use volcal::predict::{self, Extremum, Uncertainty};
use volcal::{Axis, ErrorModel};

/// Grid points per axis along the longest travel (shorter axes get proportionally fewer).
pub const POINTS_ALONG_LONGEST: f64 = 7.0;

/// Largest arrow as a fraction of the shortest travel.
const ARROW_FRACTION: f64 = 0.45;

/// What the map shows, for the summary.
#[derive(Clone, Copy, Debug)]
pub struct MapInfo {
    pub max: Extremum,
    /// Display scale: arrow length per error length.
    pub scale: f64,
    /// Length of the scale bar, as an error, metres.
    pub scale_bar_m: f64,
    pub probe: Vector3<f64>,
    /// Spacing of the grid the maximum was searched on and the band drawn over, metres: the
    /// report's grid (50 mm) is finer, so its band factor is a little larger.
    pub search_step_m: f64,
    /// The map's 95 % simultaneous band over the grid its maximum was searched on
    /// ([`volcal::band`]): what that maximum is known to.
    pub band: Option<SimultaneousBand>,
}

/// 1, 2 or 5 times a power of ten, at most `x` (x > 0).
pub fn round_down_125(x: f64) -> f64 {
    let p = 10f64.powf(x.log10().floor());
    [5.0, 2.0, 1.0].into_iter().map(|m| m * p).find(|v| *v <= x * (1.0 + 1e-12)).unwrap_or(p)
}

/// Logs the map for probe offset `probe`.
pub fn log_volumetric_map(
    rec: &RecordingStream,
    model: &ErrorModel,
    unc: &Uncertainty<'_>,
    probe: &Vector3<f64>,
) -> RecordingStreamResult<MapInfo> {
    let travel = model.layout.travel;
    let longest = Axis::ALL.iter().map(|&a| travel.length(a)).fold(0.0, f64::max);
    let shortest = Axis::ALL.iter().map(|&a| travel.length(a)).fold(f64::INFINITY, f64::min);
    let step = longest / (POINTS_ALONG_LONGEST - 1.0);
    let all = predict::grid(&travel, step);
    // Arrows where the data determine the error; grey points where they do not.
    let (grid, open): (Vec<Point3<f64>>, Vec<Point3<f64>>) =
        all.into_iter().partition(|x| unc.determines_everywhere() || predict::is_determined_at(model, unc, x, probe));
    if !open.is_empty() {
        rec.log_static(
            paths::MAP_UNDETERMINED,
            &crate::rerun::Points3D::new(open.iter().map(|x| f32p(&(x + probe))))
                .with_colors([[110u8, 110, 110, 255]])
                .with_radii([crate::rerun::Radius::new_ui_points(3.0)]),
        )?;
    }
    let search_step_m = step / 2.0;
    let max = predict::max_error(model, unc, probe, search_step_m);
    let band = simultaneous_band(
        model,
        unc,
        &predict::grid(&travel, search_step_m),
        std::slice::from_ref(probe),
        BAND_LEVEL,
        BAND_DRAWS,
        0,
    );
    let emax = max.magnitude_m.max(1e-12);
    let scale = round_down_125(ARROW_FRACTION * shortest / emax);
    let scale_bar_m = round_down_125(emax / 2.0);
    let errors: Vec<Vector3<f64>> = grid.iter().map(|x| model.error(x, probe)).collect();
    let origin = |x: &Point3<f64>| f32p(&(x + probe));
    rec.log_static(
        paths::MAP_VOLUMETRIC,
        &crate::rerun::Arrows3D::from_vectors(errors.iter().map(|e| f32v(&(e * scale))))
            .with_origins(grid.iter().map(origin))
            .with_colors(errors.iter().map(|e| colors::magnitude(e.norm() / emax)))
            .with_radii([crate::rerun::Radius::new_ui_points(2.5)]),
    )?;
    let at = max.at.x;
    rec.log_static(
        paths::MAP_MAX,
        &crate::rerun::Arrows3D::from_vectors([f32v(&(max.at.e * scale))])
            .with_origins([origin(&at)])
            .with_colors([[255u8, 255, 255, 255]])
            .with_radii([crate::rerun::Radius::new_ui_points(4.0)])
            .with_labels([format!("max {:.1} µm", max.magnitude_m * 1e6)]),
    )?;
    // Scale bar above the front top edge of the volume, along X, clear of the map's arrows.
    let (lo, hi) = (travel.min_corner(), travel.max_corner());
    let bar_origin = Point3::new(lo.x, lo.y, hi.z + 0.15 * travel.length(Axis::Z));
    rec.log_static(
        paths::MAP_SCALE,
        &crate::rerun::Arrows3D::from_vectors([f32v(&(Vector3::x() * scale_bar_m * scale))])
            .with_origins([f32p(&bar_origin)])
            .with_colors([[220u8, 220, 220, 255]])
            .with_radii([crate::rerun::Radius::new_ui_points(3.0)])
            .with_labels([format!("scale: {} µm (arrows ×{})", fmt_um(scale_bar_m), scale)]),
    )?;
    Ok(MapInfo { max, scale, scale_bar_m, probe: *probe, search_step_m, band })
}

fn fmt_um(m: f64) -> String {
    let um = m * 1e6;
    if um >= 1.0 {
        format!("{um:.0}")
    } else {
        format!("{um}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_rounds_down_to_1_2_5() {
        assert_eq!(round_down_125(7300.0), 5000.0);
        assert_eq!(round_down_125(2000.0), 2000.0);
        assert_eq!(round_down_125(1.9e-5), 1e-5);
        assert!((round_down_125(0.3) - 0.2).abs() < 1e-15);
    }
}
