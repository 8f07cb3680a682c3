//! The 3D scene: the machine's working volume and axes, the stations, the measured lines
//! (fitted, and commanded when known), and the indicated and actual reflector positions.
//!
//! Scene coordinates are the machine's, in metres, Z up.

use super::colors::{self, Rgba};
use super::geometry;
use super::paths;
use crate::rerun::{RecordingStream, RecordingStreamResult};
use nalgebra::{Point3, Vector3};
use volcal::campaign::{LineGroup, ObsKind, Observations};
use volcal::estimator::GroupStats;
use volcal::{Axis, ErrorModel, Travel};

pub(crate) fn f32p(p: &Point3<f64>) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}

pub(crate) fn f32v(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// Logs the working volume (a wire box labelled with its size) and the X, Y, Z axes along the
/// travel edges from the lower corner, with the Z-up view convention. Static.
pub fn log_machine(rec: &RecordingStream, travel: &Travel, name: &str) -> RecordingStreamResult<()> {
    rec.log_static("/", &crate::rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
    let lo = travel.min_corner();
    let hi = travel.max_corner();
    let c = travel.centre();
    let half = (hi - lo) / 2.0;
    let mm = |a: Axis| travel.length(a) * 1e3;
    rec.log_static(
        paths::MACHINE_VOLUME,
        &crate::rerun::Boxes3D::from_centers_and_half_sizes([f32p(&c)], [f32v(&half)])
            .with_colors([[150u8, 150, 150, 255]])
            .with_radii([crate::rerun::Radius::new_ui_points(0.75)])
            .with_labels([format!(
                "{name}: working volume X {:.0} x Y {:.0} x Z {:.0} mm",
                mm(Axis::X),
                mm(Axis::Y),
                mm(Axis::Z)
            )])
            .with_show_labels(false),
    )?;
    let axis_colors: [Rgba; 3] = [[230, 80, 70, 255], [90, 200, 90, 255], [80, 140, 240, 255]];
    rec.log_static(
        paths::MACHINE_AXES,
        &crate::rerun::Arrows3D::from_vectors(Axis::ALL.map(|a| f32v(&(a.unit() * travel.length(a)))))
            .with_origins([f32p(&lo); 3])
            .with_colors(axis_colors)
            .with_radii([crate::rerun::Radius::new_ui_points(2.0)])
            .with_labels(Axis::ALL.map(|a| format!("{} {:.0} mm", a.letter(), mm(a)))),
    )
}

/// Logs the stations as labelled points. `positions` are estimated positions (tracer) or the
/// convergence points of the beams (fixed-beam devices, see [`station_positions`]).
pub fn log_stations(rec: &RecordingStream, positions: &[(u32, Point3<f64>, &str)]) -> RecordingStreamResult<()> {
    for (s, p, what) in positions {
        rec.log_static(format!("{}/kind", paths::station(*s)), &crate::rerun::TextDocument::new(*what))?;
        rec.log_static(
            paths::station(*s),
            &crate::rerun::Points3D::new([f32p(p)])
                .with_colors([colors::station(*s)])
                .with_radii([crate::rerun::Radius::new_ui_points(7.0)])
                .with_labels([format!("station {s}")]),
        )?;
    }
    Ok(())
}

/// Station positions for the scene: tracer stations as estimated, fixed-beam devices at the
/// point their fitted beams converge to.
pub fn station_positions<'a>(
    obs: &Observations,
    stats: &[GroupStats],
    tracer: impl IntoIterator<Item = (u32, Point3<f64>)>,
) -> Vec<(u32, Point3<f64>, &'a str)> {
    let mut out: Vec<(u32, Point3<f64>, &'a str)> =
        tracer.into_iter().map(|(s, p)| (s, p, "tracer, estimated")).collect();
    for s in obs.stations(ObsKind::Beam) {
        let lines: Vec<_> = obs
            .groups_of(ObsKind::Beam)
            .filter(|(_, g)| g.station == s)
            .map(|(k, _)| (stats[k].centroid, stats[k].direction))
            .collect();
        if let Some(p) = geometry::convergence_point(&lines) {
            out.push((s, p, "device, where its beams converge"));
        }
    }
    out
}

/// Logs each fitted line (beams through the barycentre of their actual points, tracer paths
/// as polylines), and under it the indicated reflector positions `X + p` coloured by the
/// normalised residual `r / sigma` (blue -3, grey 0, red +3) and the actual positions
/// `X + p + e(X, p)` of `model`. Static.
pub fn log_lines(
    rec: &RecordingStream,
    obs: &Observations,
    stats: &[GroupStats],
    residuals: &[f64],
    sigmas: &[f64],
    model: &ErrorModel,
) -> RecordingStreamResult<()> {
    for (k, g) in obs.groups.iter().enumerate() {
        let path = paths::line(g);
        let pts = geometry::reflector_points(obs, g);
        let strip: Vec<[f32; 3]> = match g.kind {
            ObsKind::Beam => {
                geometry::line_extent(&pts, &stats[k].centroid, &stats[k].direction).map(|p| f32p(&p)).to_vec()
            }
            ObsKind::Range => pts.iter().map(f32p).collect(),
        };
        rec.log_static(
            path.as_str(),
            &crate::rerun::LineStrips3D::new([strip])
                .with_colors([colors::station(g.station)])
                .with_radii([crate::rerun::Radius::new_ui_points(1.5)])
                .with_labels([line_label(g, &stats[k])])
                .with_show_labels(false),
        )?;
        log_points(rec, &path, obs, g, residuals, sigmas, model)?;
    }
    Ok(())
}

fn line_label(g: &LineGroup, s: &GroupStats) -> String {
    format!("{}: {} points, residual RMS {:.3} um", g.label(), s.n, s.rms_m * 1e6)
}

fn log_points(
    rec: &RecordingStream,
    path: &str,
    obs: &Observations,
    g: &LineGroup,
    residuals: &[f64],
    sigmas: &[f64],
    model: &ErrorModel,
) -> RecordingStreamResult<()> {
    let pts = geometry::reflector_points(obs, g);
    let col: Vec<Rgba> = g.range().map(|i| colors::signed(residuals[i] / sigmas[i] / 3.0)).collect();
    rec.log_static(
        format!("{path}/indicated"),
        &crate::rerun::Points3D::new(pts.iter().map(f32p))
            .with_colors(col)
            .with_radii([crate::rerun::Radius::new_ui_points(1.5)]),
    )?;
    let actual = g.range().map(|i| f32p(&(obs.x[i] + obs.p[i] + model.error(&obs.x[i], &obs.p[i]))));
    rec.log_static(
        format!("{path}/actual"),
        &crate::rerun::Points3D::new(actual)
            .with_colors([[200u8, 200, 200, 255]])
            .with_radii([crate::rerun::Radius::new_ui_points(1.0)]),
    )
}

/// Logs a commanded beam (`stations/<s>/beams/<b>/commanded`) from the device pivot along the
/// commanded direction, `length_m` long, as a thin faded line, at the stream's current time.
pub fn log_commanded_beam(
    rec: &RecordingStream,
    station: u32,
    beam: u32,
    pivot: &Point3<f64>,
    direction: &Vector3<f64>,
    length_m: f64,
) -> RecordingStreamResult<()> {
    let end = pivot + direction.normalize() * length_m;
    rec.log(
        format!("{}/commanded", paths::beam(station, beam)),
        &crate::rerun::LineStrips3D::new([[f32p(pivot), f32p(&end)]])
            .with_colors([colors::faded(colors::station(station))])
            .with_radii([crate::rerun::Radius::new_ui_points(0.5)]),
    )
}
