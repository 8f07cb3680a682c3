//! What `volcal solve --rerun` records: the scene, the residuals, the error functions, the
//! volumetric map and a summary, with the [`blueprint::solve`] layout.

use super::{blueprint, error_functions, paths, residuals, scene, volumetric, RerunArgs};
use crate::rerun::RecordingStream;
use anyhow::Result;
use nalgebra::Vector3;
use volcal::campaign::{ObsKind, Observations};
use volcal::estimator::Solution;

/// Entities logged but kept out of the default 3D view: the actual points (they coincide with
/// the indicated ones at the scale of the volume; add them from the tree to inspect them).
pub fn hidden_in_scene(obs: &Observations) -> Vec<String> {
    obs.groups.iter().map(|g| format!("{}/actual", paths::line(g))).collect()
}

/// Opens the recording(s) asked for by `args` and logs the solved campaign. Does nothing when
/// no `--rerun*` flag was given.
pub fn record(args: &RerunArgs, name: &str, obs: &Observations, solution: &Solution) -> Result<()> {
    let layout = blueprint::solve(&solution.model.layout.travel, hidden_in_scene(obs));
    let Some(rec) = args.open(name, &layout)? else { return Ok(()) };
    log_solution(&rec, name, obs, solution)?;
    rec.flush_blocking()?;
    Ok(())
}

/// Logs everything about a solved campaign into `rec`.
pub fn log_solution(
    rec: &RecordingStream,
    name: &str,
    obs: &Observations,
    solution: &Solution,
) -> Result<volumetric::MapInfo> {
    let model = &solution.model;
    let stats = &solution.stats.per_group;
    scene::log_machine(rec, &model.layout.travel, name)?;
    let tracers = solution.stations.iter().map(|s| (s.station, s.position));
    scene::log_stations(rec, &scene::station_positions(obs, stats, tracers))?;
    scene::log_lines(rec, obs, stats, &solution.residuals, &solution.sigmas, model)?;
    residuals::log_line_series(rec, paths::RESIDUALS, obs, &solution.residuals, "residual")?;
    residuals::log_rms_bars(rec, paths::RESIDUAL_RMS, obs, &solution.residuals)?;
    error_functions::log_error_functions(rec, model, &solution.uncertainty())?;
    let map = volumetric::log_volumetric_map(rec, model, &solution.uncertainty(), &Vector3::zeros())?;
    rec.log_static(paths::SUMMARY, &crate::rerun::TextDocument::from_markdown(summary_markdown(obs, solution, &map)))?;
    Ok(map)
}

/// The summary shown next to the scene: fit statistics, the largest error, how to read the
/// colours and timelines.
pub fn summary_markdown(obs: &Observations, solution: &Solution, map: &volumetric::MapInfo) -> String {
    let st = &solution.stats;
    let n_beams = obs.groups_of(ObsKind::Beam).count();
    let n_paths = obs.groups_of(ObsKind::Range).count();
    let stations = obs.stations(ObsKind::Beam).len() + obs.stations(ObsKind::Range).len();
    let worst = obs
        .groups
        .iter()
        .zip(&st.per_group)
        .max_by(|a, b| a.1.rms_m.total_cmp(&b.1.rms_m))
        .map(|(g, s)| format!("{}, RMS {:.3} µm", g.label(), s.rms_m * 1e6))
        .unwrap_or_default();
    let lines = match (n_beams, n_paths) {
        (b, 0) => format!("{b} beams"),
        (0, p) => format!("{p} tracer paths"),
        (b, p) => format!("{b} beams, {p} tracer paths"),
    };
    let m = &map.max;
    let fit = format!(
        "**Fit**: {} readings, {lines} from {stations} stations; residual RMS **{:.3} µm**, chi²/dof {:.2}{}.\n\n\
         Worst line: {worst}.",
        st.n_obs,
        st.rms_m * 1e6,
        st.variance_factor,
        if solution.converged { "" } else { " — **not converged**" },
    );
    // What a maximum found by searching the map is known to: the map's simultaneous band.
    let over_map = map
        .band
        .map(|b| {
            format!(
                "; {:.1} µm over the map as a whole: with {:.0} % probability every value of the map (on a {:.0} mm grid) lies within {:.2} σ of the truth at once",
                b.expanded(&m.at) * 1e6,
                b.level * 100.0,
                map.search_step_m * 1e3,
                b.k
            )
        })
        .unwrap_or_default();
    let largest = format!(
        "**Largest volumetric error** (probe offset {:.0}, {:.0}, {:.0} mm): **{:.1} µm** (U {:.1} µm, k=2{over_map}) \
         at X {:.0} Y {:.0} Z {:.0} mm.",
        map.probe.x * 1e3,
        map.probe.y * 1e3,
        map.probe.z * 1e3,
        m.magnitude_m * 1e6,
        m.at.u95() * 1e6,
        m.at.x.x * 1e3,
        m.at.x.y * 1e3,
        m.at.x.z * 1e3,
    );
    let scene = format!(
        "**Scene**: lines in their station's colour; beam devices where their beams converge, tracer \
         stations as estimated; points by residual/σ (blue −3, grey 0, red +3); arrows: volumetric error ×{}, coloured by |e| (blue 0 to red \
         {:.1} µm); scale bar {} µm.",
        map.scale,
        m.magnitude_m * 1e6,
        map.scale_bar_m * 1e6,
    );
    let timelines = "**Timelines**: `position_mm` (abscissa along each line; axis position of the functions), \
         `campaign_time` (residuals over time), `beam_index` (spread of each line).";
    let open = if m.undetermined_points > 0 {
        format!(
            "\n\n**Not determined** by the data at {} of {} grid points (grey points, no arrow; functions without a band there): the report says what to measure.",
            m.undetermined_points, m.grid_points
        )
    } else {
        String::new()
    };
    format!("{fit}\n\n{largest}{open}\n\n{scene}\n\n{timelines}")
}
