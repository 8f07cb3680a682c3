//! Live view of a running campaign: the deflector state, the current point, each line's points
//! and its running least-squares fit, the residual of every reading from that fit, and running
//! residual statistics. Fed with plain data (the `viz` node converts the campaign topics;
//! tests and benchmarks feed simulated campaigns), so it knows nothing of DDS.
//!
//! Cost is bounded per reading, whatever the rate: readings are buffered and logged in
//! batches at [`LiveViz::flush`] (the node calls it at a display rate, e.g. 20 Hz); the 3D
//! cloud of a line is decimated to at most [`DISPLAY_POINTS`] points; only the lines being
//! measured keep their raw points (for the fit), finished lines keep their statistics.
//!
//! The live residual is that of the fixed-beam method before any error model: per beam,
//! `(l - mean l) - n . (P - mean P)` with `n` the least-squares line through the reflector
//! positions `P = X + p` (patent eq. 2 with `u = 0`). It contains the machine's errors as well
//! as the noise, so it shows at once a broken beam, a drift or a bad reflector.

use super::colors;
use super::geometry;
use super::paths;
use super::scene::{f32p, f32v};
use crate::rerun::{RecordingStream, TimeColumn};
use nalgebra::{Point3, Vector3};
use std::collections::BTreeMap;
use volcal::beam::{fit_line, orient_with_readings};
use volcal::campaign::{LineGroup, ObsKind, Reading, MIN_BEAM_POINTS};
use volcal::Travel;
use volcal_sim::plan::segment_in_travel;

/// Growth of a line (ratio of its points) after which it is refitted over all its points.
pub const REFIT_GROWTH: f64 = 1.1;

/// Most points drawn per line in the 3D view (every k-th reading, k doubling as the line grows).
pub const DISPLAY_POINTS: usize = 256;

/// Lines keeping their raw points: the one being measured and the one before (a beam measured
/// out and back, or a late reading).
const ACTIVE_LINES: usize = 2;

/// Seconds between updates of the status text.
const STATUS_PERIOD_S: f64 = 0.5;

/// Root of the live residual series.
pub const LIVE_RESIDUALS: &str = "live/residuals";
/// Root of the live per-line RMS bar charts.
pub const LIVE_RESIDUAL_RMS: &str = "live/residual_rms";
/// Running RMS over the whole campaign (time series, µm).
pub const LIVE_RUNNING_RMS: &str = "live/running_rms";
pub const LIVE_CURRENT_POINT: &str = "live/current_point";
pub const LIVE_DEFLECTOR: &str = "live/deflector";
pub const LIVE_STATUS: &str = "live/status";
/// The beams a live diagnosis flags, drawn through the volume in red (3D scene).
pub const LIVE_FLAGGED: &str = "live/flagged";
/// Residual RMS of the latest live diagnosis over time: before, after the refit, the noise
/// model's (µm).
pub const DIAGNOSIS_RMS_HISTORY: &str = "diagnosis/rms_history";

/// One line of a live diagnosis (from `/diagnosis`).
#[derive(Clone, Debug, PartialEq)]
pub struct LineVerdict {
    pub station: u32,
    pub line: u32,
    pub rms_before_m: f64,
    pub rms_after_m: f64,
    /// The named effects located on this line (e.g. `beam_break`): a beam to measure again.
    pub flagged_by: Vec<String>,
}

/// A diagnosis of the campaign so far, as the solver node publishes it on `/diagnosis`.
#[derive(Clone, Debug, PartialEq)]
pub struct LiveDiagnosis {
    /// Set while the campaign runs.
    pub partial: bool,
    pub readings: usize,
    pub rms_before_m: f64,
    pub rms_after_m: f64,
    pub noise_rms_m: f64,
    /// The report's statements, strongest effect first.
    pub statements: Vec<String>,
    /// Set when an excess remains that no catalogue effect explains.
    pub unexplained: Option<String>,
    pub lines: Vec<LineVerdict>,
}

/// What the deflector does now.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeflectorState {
    pub station: u32,
    pub beam: u32,
    /// Device position (pivot), metres.
    pub origin: Point3<f64>,
    /// Unit beam direction.
    pub direction: Vector3<f64>,
    pub azimuth_rad: f64,
    pub elevation_rad: f64,
    /// Settled after the last command (false: moving).
    pub settled: bool,
}

impl DeflectorState {
    /// `station 1 beam 14: az 12.30°, el 45.60°, settled`.
    pub fn describe(&self) -> String {
        format!(
            "station {} beam {}: az {:.2}°, el {:.2}°, {}",
            self.station,
            self.beam,
            self.azimuth_rad.to_degrees(),
            self.elevation_rad.to_degrees(),
            if self.settled { "settled" } else { "moving" }
        )
    }
}

/// Counters of one flush, for the node's own load report.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FlushStats {
    /// Residuals logged.
    pub residuals: usize,
    /// Lines refitted.
    pub lines: usize,
}

struct LineState {
    group: LineGroup,
    /// Running index of the line in the campaign ([`paths::BEAM_INDEX`]).
    index: usize,
    /// Raw data of an active line (empty once retired).
    points: Vec<Point3<f64>>,
    l: Vec<f64>,
    t: Vec<f64>,
    /// Readings whose residual has been logged.
    logged: usize,
    n: usize,
    display: Vec<[f32; 3]>,
    stride: usize,
    display_dirty: bool,
    sum_r2: f64,
    rms_m: Option<f64>,
    /// The last full fit: centroid, oriented direction, mean reading, and the number of points
    /// it was made from. Readings that arrive before the line has grown by [`REFIT_GROWTH`] are
    /// referred to it, so the cost of a long line stays proportional to its readings.
    fit: Option<(Point3<f64>, Vector3<f64>, f64, usize)>,
    /// No longer among the active lines: raw data dropped; later readings start a new segment.
    retired: bool,
}

impl LineState {
    fn push(&mut self, pair: &Reading) {
        let pt = pair.x + pair.p;
        if self.n % self.stride == 0 {
            self.display.push(f32p(&pt));
            if self.display.len() > DISPLAY_POINTS {
                self.display = self.display.iter().step_by(2).copied().collect();
                self.stride *= 2;
            }
            self.display_dirty = true;
        }
        self.points.push(pt);
        self.l.push(pair.l_m);
        self.t.push(pair.t_s);
        self.n += 1;
    }
}

/// The live view of one campaign.
pub struct LiveViz {
    rec: RecordingStream,
    travel: Option<Travel>,
    lines: Vec<LineState>,
    /// (kind, station, line) -> index of its current segment in `lines`.
    current: BTreeMap<(u8, u32, u32), usize>,
    /// Most recently fed lines, newest last.
    active: Vec<usize>,
    /// Lines that left `active` since the last flush: refitted once more, then their raw data go.
    retiring: Vec<usize>,
    t_s: f64,
    pairs: usize,
    rate_hz: f64,
    last_rate: (f64, usize),
    position: Option<(f64, Point3<f64>, Vector3<f64>)>,
    position_dirty: bool,
    deflector: Option<DeflectorState>,
    deflector_dirty: bool,
    dirty_stations: Vec<u32>,
    last_status_t: f64,
    /// Extra status line from the caller (sequencer progress, the node's own lag).
    note: String,
    /// Commanded beams: (station, beam) -> pivot, direction, length through the volume.
    commanded: BTreeMap<(u32, u32), (Point3<f64>, Vector3<f64>, f64)>,
}

fn kind_key(k: ObsKind) -> u8 {
    match k {
        ObsKind::Beam => 0,
        ObsKind::Range => 1,
    }
}

impl LiveViz {
    /// Starts the live view in `rec`; the working volume is drawn when `travel` is known.
    pub fn new(rec: RecordingStream, travel: Option<Travel>, machine_name: &str) -> anyhow::Result<LiveViz> {
        if let Some(t) = &travel {
            super::scene::log_machine(&rec, t, machine_name)?;
        } else {
            rec.log_static("/", &crate::rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
        }
        Ok(LiveViz {
            rec,
            travel,
            lines: Vec::new(),
            current: BTreeMap::new(),
            active: Vec::new(),
            retiring: Vec::new(),
            t_s: 0.0,
            pairs: 0,
            rate_hz: 0.0,
            last_rate: (0.0, 0),
            position: None,
            position_dirty: false,
            deflector: None,
            deflector_dirty: false,
            dirty_stations: Vec::new(),
            last_status_t: f64::NEG_INFINITY,
            note: String::new(),
            commanded: BTreeMap::new(),
        })
    }

    /// The recording stream (e.g. to flush it on exit).
    pub fn recording(&self) -> &RecordingStream {
        &self.rec
    }

    /// Readings received so far.
    pub fn pairs(&self) -> usize {
        self.pairs
    }

    /// A new beam was commanded: the device position and the commanded line (to the edge of
    /// the working volume when it is known).
    pub fn beam_command(&mut self, t_s: f64, state: DeflectorState) -> anyhow::Result<()> {
        self.t_s = self.t_s.max(t_s);
        self.rec.set_duration_secs(paths::CAMPAIGN_TIME, self.t_s);
        self.rec.log(
            paths::station(state.station),
            &crate::rerun::Points3D::new([f32p(&state.origin)])
                .with_colors([colors::station(state.station)])
                .with_radii([crate::rerun::Radius::new_ui_points(7.0)])
                .with_labels([format!("station {}", state.station)]),
        )?;
        let length = self.beam_length(&state);
        self.commanded.insert((state.station, state.beam), (state.origin, state.direction, length));
        super::scene::log_commanded_beam(
            &self.rec,
            state.station,
            state.beam,
            &state.origin,
            &state.direction,
            length,
        )?;
        self.deflector_state(t_s, state);
        Ok(())
    }

    /// Whether the beam `(station, beam)` has been drawn as commanded: a viewer that joined
    /// after a command went out (`/deflector/command` is volatile) draws it from the first
    /// settled `/deflector/state` instead.
    pub fn is_commanded(&self, station: u32, beam: u32) -> bool {
        self.commanded.contains_key(&(station, beam))
    }

    /// Length of a beam from the device to where it leaves the working volume (1 m when the
    /// volume is not known or the beam misses it).
    fn beam_length(&self, state: &DeflectorState) -> f64 {
        self.travel
            .and_then(|t| segment_in_travel(&state.origin, &state.direction, &t, &Vector3::zeros()))
            .map_or(1.0, |[_, end]| end)
    }

    /// The deflector's reported state (logged at the next flush).
    pub fn deflector_state(&mut self, t_s: f64, state: DeflectorState) {
        self.t_s = self.t_s.max(t_s);
        self.deflector = Some(state);
        self.deflector_dirty = true;
    }

    /// A line of the caller's shown in the status text (e.g. the sequencer's progress).
    pub fn note(&mut self, text: String) {
        self.note = text;
    }

    /// The machine's indicated position (the latest one is drawn at the next flush).
    pub fn machine_position(&mut self, t_s: f64, x: Point3<f64>, p: Vector3<f64>) {
        self.t_s = self.t_s.max(t_s);
        self.position = Some((t_s, x, p));
        self.position_dirty = true;
    }

    /// A synchronised pair as recorded (`/campaign/pairs`), as a campaign reading (logged at the
    /// next flush).
    pub fn pair(&mut self, pair: &Reading) {
        self.t_s = self.t_s.max(pair.t_s);
        self.pairs += 1;
        let key = (kind_key(pair.kind), pair.station, pair.line);
        let k = match self.current.get(&key) {
            Some(&k) if (!pair.beam_broken || self.lines[k].n == 0) && !self.lines[k].retired => k,
            prev => {
                let segment = prev.map(|&k| self.lines[k].group.segment + 1).unwrap_or(0);
                let group =
                    LineGroup { kind: pair.kind, station: pair.station, line: pair.line, segment, start: 0, end: 0 };
                self.lines.push(LineState {
                    group,
                    index: self.lines.len(),
                    points: Vec::new(),
                    l: Vec::new(),
                    t: Vec::new(),
                    logged: 0,
                    n: 0,
                    display: Vec::new(),
                    stride: 1,
                    display_dirty: false,
                    sum_r2: 0.0,
                    rms_m: None,
                    fit: None,
                    retired: false,
                });
                self.current.insert(key, self.lines.len() - 1);
                self.lines.len() - 1
            }
        };
        self.lines[k].push(pair);
        if self.active.last() != Some(&k) {
            self.active.retain(|&a| a != k);
            self.active.push(k);
            while self.active.len() > ACTIVE_LINES {
                let old = self.active.remove(0);
                // Readings arriving later start a new segment.
                self.lines[old].retired = true;
                self.retiring.push(old);
            }
        }
    }

    /// A diagnosis of the campaign so far (the solver node's `/diagnosis`), at campaign time
    /// `t_s`: the beams it flags drawn in red through the volume and labelled with the effect,
    /// the residual RMS per line before and after its refit (bar charts per station, replacing
    /// the previous diagnosis's), the overall RMS before and after over time against the noise
    /// model's, and its report.
    pub fn diagnosis(&mut self, t_s: f64, d: &LiveDiagnosis) -> anyhow::Result<()> {
        self.t_s = self.t_s.max(t_s);
        self.rec.set_duration_secs(paths::CAMPAIGN_TIME, self.t_s);
        let flagged: Vec<&LineVerdict> = d.lines.iter().filter(|l| !l.flagged_by.is_empty()).collect();
        let mut strips = Vec::new();
        let mut labels = Vec::new();
        for l in &flagged {
            if let Some((o, dir, len)) = self.commanded.get(&(l.station, l.line)) {
                strips.push([f32p(o), f32p(&(o + dir * *len))]);
                labels.push(format!(
                    "station {} beam {}: {} (RMS {:.2} → {:.2} µm)",
                    l.station,
                    l.line,
                    l.flagged_by.join(", "),
                    l.rms_before_m * 1e6,
                    l.rms_after_m * 1e6
                ));
            }
        }
        self.rec.log(
            LIVE_FLAGGED,
            &crate::rerun::LineStrips3D::new(strips)
                .with_colors([colors::FLAGGED])
                .with_radii([crate::rerun::Radius::new_ui_points(4.0)])
                .with_labels(labels),
        )?;
        let mut stations: Vec<u32> = d.lines.iter().map(|l| l.station).collect();
        stations.sort_unstable();
        stations.dedup();
        // Stations side by side: station k's beams from k * (beams + 2).
        let stride = d.lines.iter().map(|l| l.line).max().unwrap_or(0) as f64 + 3.0;
        for (k, s) in stations.into_iter().enumerate() {
            for (root, rms) in [
                (paths::RMS_BEFORE, (|l: &LineVerdict| l.rms_before_m) as fn(&LineVerdict) -> f64),
                (paths::RMS_AFTER, |l: &LineVerdict| l.rms_after_m),
            ] {
                let (idx, val): (Vec<f64>, Vec<f64>) = d
                    .lines
                    .iter()
                    .filter(|l| l.station == s)
                    .map(|l| (k as f64 * stride + l.line as f64, rms(l) * 1e6))
                    .unzip();
                self.rec.log(
                    paths::station_series(root, s),
                    &crate::rerun::BarChart::new(val).with_abscissa(idx).with_color(colors::station(s)),
                )?;
            }
        }
        for (name, v, color) in [
            ("before", d.rms_before_m, [0xe0, 0x5a, 0x4a, 255]),
            ("after", d.rms_after_m, [0x5c, 0xc8, 0x6b, 255]),
            ("noise", d.noise_rms_m, [0x9a, 0x9a, 0x9a, 255]),
        ] {
            let path = format!("{DIAGNOSIS_RMS_HISTORY}/{name}");
            self.rec.log_static(
                path.as_str(),
                &crate::rerun::SeriesLines::new().with_colors([color]).with_names([match name {
                    "before" => "rigid-body fit",
                    "after" => "refit with the named effects",
                    _ => "noise model",
                }]),
            )?;
            self.rec.log(path.as_str(), &crate::rerun::Scalars::new([v * 1e6]))?;
        }
        let mut text = format!(
            "**{} diagnosis** at {:.1} s of {} readings: residual RMS {:.3} µm before, {:.3} µm after \
             (noise model {:.3} µm)\n\n",
            if d.partial { "Live" } else { "Final" },
            self.t_s,
            d.readings,
            d.rms_before_m * 1e6,
            d.rms_after_m * 1e6,
            d.noise_rms_m * 1e6
        );
        if flagged.is_empty() {
            text += "No beam flagged.\n\n";
        } else {
            text += &format!(
                "**Measure again**: {}\n\n",
                flagged.iter().map(|l| format!("station {} beam {}", l.station, l.line)).collect::<Vec<_>>().join(", ")
            );
        }
        if d.statements.is_empty() && d.unexplained.is_none() {
            text += "Nothing named: the residual is what the noise model expects.\n";
        }
        for st in &d.statements {
            text += &format!("- {st}\n");
        }
        if let Some(u) = &d.unexplained {
            text += &format!("\n{u}\n");
        }
        self.rec.log(paths::DIAGNOSIS_REPORT, &crate::rerun::TextDocument::from_markdown(text))?;
        Ok(())
    }

    /// Logs everything received and the status, at the end of the campaign (or of watching).
    pub fn finish(&mut self) -> anyhow::Result<FlushStats> {
        let s = self.flush()?;
        self.log_status()?;
        self.rec.flush_blocking()?;
        Ok(s)
    }

    /// Logs everything received since the last flush.
    pub fn flush(&mut self) -> anyhow::Result<FlushStats> {
        let mut stats = FlushStats::default();
        self.rec.set_duration_secs(paths::CAMPAIGN_TIME, self.t_s);
        let retiring = std::mem::take(&mut self.retiring);
        for &k in retiring.iter().chain(&self.active.clone()) {
            stats.residuals += self.refit(k, retiring.contains(&k))?;
            stats.lines += 1;
        }
        for k in retiring {
            // Statistics stay, raw data go.
            let l = &mut self.lines[k];
            (l.points, l.l, l.t) = (Vec::new(), Vec::new(), Vec::new());
        }
        if self.position_dirty {
            if let Some((_, x, p)) = self.position {
                let r = x + p;
                self.rec.log(
                    LIVE_CURRENT_POINT,
                    &crate::rerun::Points3D::new([f32p(&r)])
                        .with_colors([[255u8, 255, 255, 255]])
                        .with_radii([crate::rerun::Radius::new_ui_points(8.0)])
                        .with_labels([format!("X {:.1} Y {:.1} Z {:.1} mm", x.x * 1e3, x.y * 1e3, x.z * 1e3)]),
                )?;
            }
            self.position_dirty = false;
        }
        if self.deflector_dirty {
            if let Some(d) = self.deflector {
                // Drawn through the volume like the beam itself, so that it stands out among the
                // measured lines from any viewpoint.
                let len = self.beam_length(&d);
                let color = colors::deflector(d.settled);
                self.rec.log(
                    LIVE_DEFLECTOR,
                    &crate::rerun::Arrows3D::from_vectors([f32v(&(d.direction * len))])
                        .with_origins([f32p(&d.origin)])
                        .with_colors([color])
                        .with_radii([crate::rerun::Radius::new_ui_points(3.5)])
                        .with_labels([d.describe()]),
                )?;
            }
            self.deflector_dirty = false;
        }
        self.log_bars()?;
        if self.t_s - self.last_status_t >= STATUS_PERIOD_S {
            self.log_status()?;
        }
        Ok(stats)
    }

    /// Refits an active line over all its points, logs the residuals of the new readings, the
    /// fitted line and the decimated cloud. Returns the residuals logged.
    /// `last`: the line is retiring; its final fit is over all its points.
    fn refit(&mut self, k: usize, last: bool) -> anyhow::Result<usize> {
        let rec = &self.rec;
        let line = &mut self.lines[k];
        let path = paths::line(&line.group);
        if line.display_dirty {
            rec.log(
                format!("{path}/indicated"),
                &crate::rerun::Points3D::new(line.display.iter().copied())
                    .with_colors([colors::station(line.group.station)])
                    .with_radii([crate::rerun::Radius::new_ui_points(1.5)]),
            )?;
            line.display_dirty = false;
        }
        let fitted = line.fit.map_or(0, |f| f.3);
        if line.group.kind != ObsKind::Beam
            || line.points.len() < MIN_BEAM_POINTS
            || (line.logged == line.points.len() && !(last && fitted < line.points.len()))
        {
            return Ok(0);
        }
        // A full refit when the line has grown by REFIT_GROWTH since the last one (amortised
        // O(1) per reading) or is retiring; otherwise the new readings are referred to the last
        // fit.
        let full = fitted == 0 || last || line.points.len() as f64 >= REFIT_GROWTH * fitted as f64;
        let first = if full { 0 } else { line.logged };
        if full {
            let fit = fit_line(&line.points);
            let n = orient_with_readings(fit.direction, &line.points, &line.l);
            let lm = line.l.iter().sum::<f64>() / line.l.len() as f64;
            line.fit = Some((fit.centroid, n, lm, line.points.len()));
            line.sum_r2 = 0.0;
        }
        let (c, n, lm, _) = line.fit.expect("fitted above");
        let r: Vec<f64> = (first..line.points.len()).map(|i| (line.l[i] - lm) - n.dot(&(line.points[i] - c))).collect();
        line.sum_r2 += r.iter().map(|v| v * v).sum::<f64>();
        line.rms_m = Some((line.sum_r2 / line.points.len() as f64).sqrt());
        let r = &r[line.logged - first..];
        let new = line.logged..line.points.len();
        let count = new.len();
        rec.send_columns(
            paths::line_series(LIVE_RESIDUALS, &line.group).as_str(),
            [
                TimeColumn::new_duration_secs(paths::CAMPAIGN_TIME, line.t[new.clone()].iter().copied()),
                TimeColumn::new_sequence(paths::BEAM_INDEX, std::iter::repeat_n(line.index as i64, count)),
            ],
            crate::rerun::Scalars::new(r.iter().map(|v| v * 1e6)).columns_of_unit_batches()?,
        )?;
        if line.logged == 0 {
            rec.log_static(
                paths::line_series(LIVE_RESIDUALS, &line.group).as_str(),
                &crate::rerun::SeriesPoints::new()
                    .with_colors([colors::station(line.group.station)])
                    .with_names([format!("residual {}", line.group.label())])
                    .with_marker_sizes([1.5]),
            )?;
        }
        line.logged = line.points.len();
        if !self.dirty_stations.contains(&line.group.station) {
            self.dirty_stations.push(line.group.station);
        }
        if !full {
            return Ok(count);
        }
        let ends = geometry::line_extent(&line.points, &c, &n);
        rec.log(
            path.as_str(),
            &crate::rerun::LineStrips3D::new([ends.map(|p| f32p(&p))])
                .with_colors([colors::station(line.group.station)])
                .with_radii([crate::rerun::Radius::new_ui_points(1.5)])
                .with_labels([format!(
                    "{}: {} points, RMS {:.3} µm",
                    line.group.label(),
                    line.n,
                    line.rms_m.unwrap_or(0.0) * 1e6
                )])
                .with_show_labels(false),
        )?;
        Ok(count)
    }

    /// RMS per line of the stations whose lines changed; the campaign's running RMS.
    fn log_bars(&mut self) -> anyhow::Result<()> {
        if self.dirty_stations.is_empty() {
            return Ok(());
        }
        for s in std::mem::take(&mut self.dirty_stations) {
            let (idx, val): (Vec<f64>, Vec<f64>) = self
                .lines
                .iter()
                .filter(|l| l.group.station == s)
                .filter_map(|l| l.rms_m.map(|r| (l.index as f64, r * 1e6)))
                .unzip();
            self.rec.log(
                paths::station_series(LIVE_RESIDUAL_RMS, s),
                &crate::rerun::BarChart::new(val).with_abscissa(idx).with_color(colors::station(s)),
            )?;
        }
        if let Some(rms) = self.running_rms_m() {
            self.rec.log(LIVE_RUNNING_RMS, &crate::rerun::Scalars::new([rms * 1e6]))?;
        }
        Ok(())
    }

    /// RMS of the live residuals over all fitted lines so far.
    pub fn running_rms_m(&self) -> Option<f64> {
        let (s, n) =
            self.lines.iter().filter(|l| l.rms_m.is_some()).fold((0.0, 0usize), |(s, n), l| (s + l.sum_r2, n + l.n));
        (n > 0).then(|| (s / n as f64).sqrt())
    }

    fn log_status(&mut self) -> anyhow::Result<()> {
        let dt = self.t_s - self.last_rate.0;
        if dt > 0.0 {
            self.rate_hz = (self.pairs - self.last_rate.1) as f64 / dt;
        }
        self.last_rate = (self.t_s, self.pairs);
        self.last_status_t = self.t_s;
        let current = self
            .active
            .last()
            .map(|&k| {
                let l = &self.lines[k];
                format!(
                    "**Measuring**: {}, {} points{}",
                    l.group.label(),
                    l.n,
                    l.rms_m.map(|r| format!(", residual RMS {:.3} µm", r * 1e6)).unwrap_or_default()
                )
            })
            .unwrap_or_else(|| "**Waiting** for the first reading".into());
        let deflector =
            format!("**Deflector**: {}", self.deflector.map(|d| d.describe()).unwrap_or_else(|| "no state yet".into()));
        let text = format!(
            "**Campaign time** {:.1} s · **{}** readings ({:.0} Hz) on {} lines\n\n{current}\n\n{deflector}\n\n{}\
             **Running residual RMS** (line fits, before calibration): {}\n\n\
             Points in their station's colour, the white point is the reflector now, the arrow the beam \
             (yellow settled, red moving); faded lines are the commanded beams.",
            self.t_s,
            self.pairs,
            self.rate_hz,
            self.lines.len(),
            if self.note.is_empty() { String::new() } else { format!("{}\n\n", self.note) },
            self.running_rms_m().map(|r| format!("{:.3} µm", r * 1e6)).unwrap_or_else(|| "-".into()),
        );
        self.rec.log(LIVE_STATUS, &crate::rerun::TextDocument::from_markdown(text))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A straight beam from `o` along `d` read with white noise of `sigma`.
    fn beam(
        station: u32,
        line: u32,
        o: Point3<f64>,
        d: Vector3<f64>,
        n: usize,
        t0: f64,
        sigma: f64,
        rng: &mut impl Rng,
    ) -> Vec<Reading> {
        (0..n)
            .map(|i| {
                let s = 0.1 + 0.8 * i as f64 / n as f64;
                let noise: f64 = rng.random_range(-1.0..1.0) * sigma * 3f64.sqrt();
                Reading {
                    t_s: t0 + i as f64 * 1e-3,
                    kind: ObsKind::Beam,
                    station,
                    line,
                    l_m: 5.0 + s + noise,
                    x: o + d * s,
                    p: Vector3::zeros(),
                    air: None,
                    machine_temp_c: None,
                    velocity: None,
                    beam_broken: false,
                    source_line: i,
                }
            })
            .collect()
    }

    #[test]
    fn live_fit_finds_the_noise_and_bounds_what_it_draws() {
        let (rec, storage) = crate::rerun::RecordingStreamBuilder::new("volcal").memory().unwrap();
        let travel = Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]);
        let mut viz = LiveViz::new(rec, Some(travel), "test").unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let sigma = 0.2e-6;
        let dirs = [Vector3::new(1.0, 0.3, 0.2), Vector3::new(0.2, 1.0, -0.3), Vector3::new(-0.5, 0.5, -0.7)];
        let mut logged = 0;
        for (b, d) in dirs.iter().enumerate() {
            let pairs =
                beam(1, b as u32, Point3::new(0.1, 0.1, -0.5), d.normalize(), 5000, b as f64 * 10.0, sigma, &mut rng);
            for (i, p) in pairs.iter().enumerate() {
                viz.pair(p);
                if i % 50 == 49 {
                    logged += viz.flush().unwrap().residuals;
                }
            }
        }
        logged += viz.flush().unwrap().residuals;
        assert_eq!(logged, 15000, "one residual per reading");
        let rms = viz.running_rms_m().unwrap();
        assert!((rms - sigma).abs() < 0.05 * sigma, "running RMS {rms} for noise {sigma}");
        assert!(viz.lines.iter().all(|l| l.display.len() <= DISPLAY_POINTS && l.display.len() > DISPLAY_POINTS / 4));
        assert!(viz.lines[0].points.is_empty() && viz.lines[0].retired, "the oldest line is retired");
        // A reading of a retired line, or after a beam break, starts a new segment.
        let late =
            Reading { beam_broken: false, ..beam(1, 0, Point3::origin(), Vector3::x(), 1, 40.0, 0.0, &mut rng)[0] };
        viz.pair(&late);
        viz.pair(&Reading { beam_broken: true, t_s: 40.1, ..late });
        assert_eq!(viz.lines.len(), 5);
        assert_eq!((viz.lines[3].group.segment, viz.lines[4].group.segment), (1, 2));
        viz.flush().unwrap();
        drop(viz);
        let paths: std::collections::BTreeSet<String> = storage
            .take()
            .iter()
            .filter_map(|m| match m {
                crate::rerun::log::LogMsg::ArrowMsg(_, a) => {
                    crate::rerun::log::Chunk::from_arrow_msg(a).ok().map(|c| c.entity_path().to_string())
                }
                _ => None,
            })
            .collect();
        for p in [
            "/live/residuals/stations/1/beams/2",
            "/stations/1/beams/2",
            "/stations/1/beams/2/indicated",
            "/live/status",
            "/live/residual_rms/stations/1",
            "/live/running_rms",
            "/machine/volume",
        ] {
            assert!(paths.contains(p), "{p} missing from {paths:?}");
        }
    }
}
