//! Default layouts, so that the first screen answers the engineer's questions: do the beams
//! cover the volume, is the fit good, where are the residuals, how large are the errors. The
//! views are building blocks that other commands (diagnosis) combine with their own roots.

use super::error_functions::plot_title;
use super::layout::{Container, Layout, Node, View};
use super::paths;
use crate::rerun::blueprint::components::PanelState;
use crate::rerun::external::re_sdk_types::blueprint::archetypes as bp;
use volcal::{Axis, Motion, Travel};

/// The 3D scene: volume, stations, beams and points, the volumetric map, live state, looked
/// at from the front left, above, from `distance` times the default distance. Entities in `hide` (e.g. the actual points, which coincide
/// with the indicated ones at this scale) stay in the recording but out of the view.
pub fn scene_view(title: &str, travel: Option<&Travel>, distance: f64, hide: impl IntoIterator<Item = String>) -> View {
    let mut q: Vec<String> =
        [paths::MACHINE, paths::STATIONS, "map", paths::LIVE].iter().map(|r| format!("+ /{r}/**")).collect();
    q.extend(hide.into_iter().map(|p| format!("- /{p}")));
    // The viewer's grid lies in z = 0, which is the top of a typical CMM travel; the box of
    // the working volume is the reference instead.
    let view = View::spatial3d(title, q).property("LineGrid3D", &bp::LineGrid3D::new().with_visible(false));
    let Some(travel) = travel else { return view };
    let c = travel.centre();
    let d = (travel.max_corner() - travel.min_corner()).norm();
    let eye = c + nalgebra::Vector3::new(-0.35, -0.8, 0.55) * (d * distance);
    view.property(
        "EyeControls3D",
        &bp::EyeControls3D::new()
            .with_position([eye.x as f32, eye.y as f32, eye.z as f32])
            .with_look_target([c.x as f32, c.y as f32, c.z as f32])
            .with_eye_up([0.0f32, 0.0, 1.0]),
    )
}

/// Per-reading series under `root` (residuals, or a diagnosis root), without legend (one
/// series per line; the colour is the station's).
pub fn series_view(title: &str, root: &str) -> View {
    View::time_series(title, [format!("+ /{root}/**")]).without_legend()
}

/// Per-line RMS bar charts under `root`.
pub fn rms_view(title: &str, root: &str) -> View {
    View::bar_chart(title, [format!("+ /{root}/**")]).without_legend()
}

/// One plot per axis and kind: translations (µm) and rotations with squareness (µrad); the
/// title names the colours, the faded lines are the U (k=2) band.
pub fn function_views() -> Container {
    let mut cells: Vec<Node> = Vec::new();
    for motion in [Motion::Translation, Motion::Rotation] {
        for a in Axis::ALL {
            let root = paths::function_group(a, motion == Motion::Rotation);
            cells.push(View::time_series(plot_title(a, motion), [format!("+ /{root}/**")]).without_legend().into());
        }
    }
    Container::grid(3, cells).named("Error functions with U (k=2) bands")
}

/// Text summary.
pub fn summary_view() -> View {
    View::text_document("Summary", [format!("+ /{}", paths::SUMMARY)])
}

/// Views maximised: side panels collapsed, the timeline bar kept small with `timeline` selected.
pub fn first_screen(root: Container, timeline: &str) -> Layout {
    Layout {
        root,
        timeline: timeline.to_string(),
        side_panels: PanelState::Collapsed,
        time_panel: PanelState::Collapsed,
    }
}

/// Layout of `volcal solve --rerun`. Top: the summary (the verdict) and the RMS per beam, the
/// scene, the residuals; bottom: the error functions. The selected timeline is
/// [`paths::POSITION_MM`], on which residuals run over the abscissa and functions over axis
/// position. (The summary sits where a headless viewer's pointer rests, a quarter of the way
/// in from the top left, so that screenshots show no hover tooltip; the residual plot is wide
/// enough at 1920 px for its abscissa to be labelled every 100 mm.)
pub fn solve(travel: &Travel, hide: impl IntoIterator<Item = String>) -> Layout {
    let left = Container::vertical([
        summary_view().into(),
        rms_view("Residual RMS per line (µm)", paths::RESIDUAL_RMS).into(),
    ])
    .shares([1.2, 1.0]);
    let top = Container::horizontal([
        left.into(),
        scene_view("Volume: beams, stations, volumetric error", Some(travel), 1.0, hide).into(),
        series_view("Residuals (µm) over the abscissa along each line (mm)", paths::RESIDUALS).into(),
    ])
    .shares([0.85, 1.1, 1.3]);
    first_screen(Container::vertical([top.into(), function_views().into()]).shares([1.4, 1.0]), paths::POSITION_MM)
}

/// Shows `[from_s, to_s]` of [`paths::CAMPAIGN_TIME`] in a plot, wherever the time cursor is
/// (a plot of a long campaign otherwise opens on a short window around the cursor).
pub fn campaign_time_span(view: View, from_s: f64, to_s: f64) -> View {
    use crate::rerun::external::re_sdk_types::datatypes::{TimeInt, TimeRange, TimeRangeBoundary};
    let at = |s: f64| TimeRangeBoundary::Absolute(TimeInt((s * 1e9) as i64));
    let span = TimeRange { start: at(from_s), end: at(to_s) };
    view.property(
        "TimeAxis",
        &bp::TimeAxis::new().with_view_range(crate::rerun::blueprint::components::TimeRange(span)),
    )
}

/// Shows only the last `seconds` of [`paths::CAMPAIGN_TIME`] before the time cursor.
pub fn last_seconds(view: View, seconds: f64) -> View {
    use crate::rerun::external::re_sdk_types::datatypes::{TimeInt, TimeRange, TimeRangeBoundary, VisibleTimeRange};
    let range = VisibleTimeRange {
        timeline: paths::CAMPAIGN_TIME.into(),
        range: TimeRange {
            start: TimeRangeBoundary::CursorRelative(TimeInt((-seconds * 1e9) as i64)),
            end: TimeRangeBoundary::AT_CURSOR,
        },
    };
    view.property("VisibleTimeRanges", &bp::VisibleTimeRanges::new([range]))
}

/// Layout of the live `viz` node: the status (what is measured now, rates, running RMS), the
/// latest live diagnosis (its verdict, the beams to measure again) and the RMS per line of the
/// running line fits on the left; the scene in the middle (stations, commanded beams, points,
/// running line fits, the current point and the beam, flagged beams in red); on the right the
/// residuals of the last 30 s, the running RMS, and the diagnosis: RMS per line before and
/// after its refit, and its overall RMS over time. The cursor follows [`paths::CAMPAIGN_TIME`].
pub fn live(travel: Option<&Travel>) -> Layout {
    use super::live::{DIAGNOSIS_RMS_HISTORY, LIVE_RESIDUALS, LIVE_RESIDUAL_RMS, LIVE_RUNNING_RMS, LIVE_STATUS};
    let left = Container::vertical([
        View::text_document("Campaign status", [format!("+ /{LIVE_STATUS}")]).into(),
        View::text_document("Live diagnosis", [format!("+ /{}", paths::DIAGNOSIS_REPORT)]).into(),
        rms_view("Residual RMS per line (µm), line fits", LIVE_RESIDUAL_RMS).into(),
    ])
    .shares([0.8, 1.0, 0.8]);
    let right = Container::vertical([
        last_seconds(series_view("Residuals from the running line fits (µm), last 30 s", LIVE_RESIDUALS), 30.0).into(),
        View::time_series("Running residual RMS of the campaign (µm)", [format!("+ /{LIVE_RUNNING_RMS}")])
            .without_legend()
            .into(),
        rms_view("Diagnosis: residual RMS per beam, rigid-body fit (µm)", paths::RMS_BEFORE).into(),
        rms_view("Diagnosis: residual RMS per beam, refit with the named effects (µm)", paths::RMS_AFTER).into(),
        View::time_series(
            "Diagnosis: residual RMS before / after / noise (µm)",
            [format!("+ /{DIAGNOSIS_RMS_HISTORY}/**")],
        )
        .into(),
    ])
    .shares([1.2, 0.7, 0.8, 0.8, 0.8]);
    let root = Container::horizontal([
        left.into(),
        scene_view("Volume: stations, beams, points, current position; flagged beams red", travel, 1.35, []).into(),
        right.into(),
    ])
    .shares([0.85, 1.4, 1.2]);
    first_screen(root, paths::CAMPAIGN_TIME)
}
