//! Entity paths and timeline names: the one place where the tree a user sees in the Rerun
//! viewer is spelled. Tests and the default blueprints refer to these, so renaming an entity
//! here renames it everywhere.
//!
//! ```text
//! machine/volume                      working volume (box) and travel
//! machine/axes                        X, Y, Z axis arrows at the travel origin
//! stations/<s>                        device or tracer station (estimated position)
//! stations/<s>/beams/<b>              fitted beam line; children: indicated, actual, commanded
//! stations/<s>/paths/<p>              tracer path (indicated points)
//! fit/residuals/stations/<s>/beams/<b>  residual of every reading (um)
//! fit/residual_rms/stations/<s>       RMS residual per beam (bar chart, um)
//! fit/summary                         text: fit statistics, largest error, how to read colours
//! functions/<axis>/translation/<EXX>  error functions over axis position (um), with bands
//! functions/<axis>/rotation/<EAX>     rotation errors and squareness (urad), with bands
//! map/volumetric                      volumetric error arrows, scaled, coloured by magnitude
//! map/volumetric/max                  the largest error, marked and labelled
//! map/volumetric/scale                scale bar arrow with its length in um in the label
//! live/...                            state of a running campaign (viz node)
//! diagnosis/residuals_before/...      residuals of the rigid-body fit (volcal diagnose)
//! diagnosis/effects/<id>/...          a named effect's own signature in the readings
//! diagnosis/residuals_after/...       residuals of the refit with the named effects
//! diagnosis/residual_rms_{before,after}/stations/<s>   RMS per line before and after
//! diagnosis/report                    the diagnosis report
//! ```

use volcal::campaign::{LineGroup, ObsKind};
use volcal::{Axis, ErrorFunction, Motion, Squareness};

/// Timeline: seconds from the start of the campaign (the `t_s` column / message stamps).
pub const CAMPAIGN_TIME: &str = "campaign_time";
/// Timeline: running index of the measured line (beam or tracer path) in campaign order.
pub const BEAM_INDEX: &str = "beam_index";
/// Timeline: position in millimetres. For residuals, the abscissa along the line (the reading
/// minus its smallest value on the line); for error functions, the axis position. Rerun plots a time series against the selected timeline only, so sharing one
/// position timeline lets residuals over the abscissa and error functions over axis position
/// appear on the same screen.
pub const POSITION_MM: &str = "position_mm";

pub const MACHINE: &str = "machine";
pub const MACHINE_VOLUME: &str = "machine/volume";
pub const MACHINE_AXES: &str = "machine/axes";
pub const STATIONS: &str = "stations";
pub const FIT: &str = "fit";
/// Root of the per-reading residuals of the fit.
pub const RESIDUALS: &str = "fit/residuals";
/// Root of the per-beam RMS bar charts of the fit.
pub const RESIDUAL_RMS: &str = "fit/residual_rms";
pub const SUMMARY: &str = "fit/summary";
pub const FUNCTIONS: &str = "functions";
pub const MAP_VOLUMETRIC: &str = "map/volumetric";
pub const MAP_MAX: &str = "map/volumetric/max";
pub const MAP_SCALE: &str = "map/volumetric/scale";
/// Grid points where the data do not determine the volumetric error (grey, no arrow).
pub const MAP_UNDETERMINED: &str = "map/volumetric/not_determined";
pub const LIVE: &str = "live";

/// Root of everything the diagnosis adds.
pub const DIAGNOSIS: &str = "diagnosis";
/// Residuals of the rigid-body fit, before any effect is modelled.
pub const RESIDUALS_BEFORE: &str = "diagnosis/residuals_before";
/// Residuals of the refit with the named effects.
pub const RESIDUALS_AFTER: &str = "diagnosis/residuals_after";
/// Per-line RMS before and after.
pub const RMS_BEFORE: &str = "diagnosis/residual_rms_before";
pub const RMS_AFTER: &str = "diagnosis/residual_rms_after";
/// The report text.
pub const DIAGNOSIS_REPORT: &str = "diagnosis/report";

/// `diagnosis/effects/<id>`: the signature of a named effect.
pub fn effect_signature(id: &str) -> String {
    format!("{DIAGNOSIS}/effects/{id}")
}

/// `stations/<s>`.
pub fn station(s: u32) -> String {
    format!("{STATIONS}/{s}")
}

/// The line of a group relative to a station: `beams/<b>` or `paths/<p>`, with
/// `/segment_<k>` for the pieces after a beam break.
fn line_suffix(g: &LineGroup) -> String {
    let kind = match g.kind {
        ObsKind::Beam => "beams",
        ObsKind::Range => "paths",
    };
    if g.segment == 0 {
        format!("{}/{kind}/{}", g.station, g.line)
    } else {
        format!("{}/{kind}/{}/segment_{}", g.station, g.line, g.segment)
    }
}

/// `stations/<s>/beams/<b>` (or `.../paths/<p>`): the line itself in the 3D scene.
pub fn line(g: &LineGroup) -> String {
    format!("{STATIONS}/{}", line_suffix(g))
}

/// `stations/<s>/beams/<b>` for a beam known by its ids (live campaigns, before grouping).
pub fn beam(station: u32, beam: u32) -> String {
    format!("{STATIONS}/{station}/beams/{beam}")
}

/// `<root>/stations/<s>/beams/<b>`: a per-reading series of one line under `root`
/// (e.g. [`RESIDUALS`], or a diagnosis root such as `diagnosis/before`).
pub fn line_series(root: &str, g: &LineGroup) -> String {
    format!("{root}/{STATIONS}/{}", line_suffix(g))
}

/// `<root>/stations/<s>`: the per-station bar chart under `root`.
pub fn station_series(root: &str, s: u32) -> String {
    format!("{root}/{STATIONS}/{s}")
}

/// `functions/<axis>/translation` or `functions/<axis>/rotation`.
pub fn function_group(axis: Axis, rotation: bool) -> String {
    format!("{FUNCTIONS}/{}/{}", axis.letter(), if rotation { "rotation" } else { "translation" })
}

/// `functions/<axis>/<translation|rotation>/<ISO name>`.
pub fn function(f: ErrorFunction) -> String {
    format!("{}/{}", function_group(f.axis, f.motion == Motion::Rotation), f.name())
}

/// `functions/<axis>/rotation/<EC0Y|EB0Z|EA0Z>`: squareness, with the rotations of the axis it
/// belongs to (same unit, drawn flat over that axis's travel).
pub fn squareness(s: Squareness) -> String {
    format!("{}/{}", function_group(s.axis(), true), s.name())
}
