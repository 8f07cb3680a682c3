//! Campaign readings as plain data, their validation, and their preparation into line groups
//! for the estimator.
//!
//! A campaign is the patent's acquisition table generalised: one [`Reading`] per acquired point,
//! either a fixed-beam abscissa (`kind = beam`) or a tracer range (`kind = range`). Preparation
//! turns readings into [`Observations`]: environment-compensated lengths, machine coordinates
//! normalised to 20 degC, grouped into lines that share an unknown additive origin (a beam
//! segment between beam breaks, or a tracer path).
//!
//! Failure is data here: preparation returns the observations together with warnings, and fails
//! only when the result would be wrong (non-finite values, millimetres where metres are expected,
//! nothing left to solve).

use crate::axis::{Axis, Travel};
use crate::environment::{air_index, compensation_factor, normalise_to_20c, Air, AirIndexEquation};
use nalgebra::{Point3, Vector3};
use std::collections::BTreeMap;
use std::fmt;

/// Kind of an observation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum ObsKind {
    /// Fixed-beam interferometer abscissa (patent).
    Beam,
    /// Tracking-interferometer relative range (paper).
    Range,
}

impl ObsKind {
    pub fn name(self) -> &'static str {
        match self {
            ObsKind::Beam => "beam",
            ObsKind::Range => "range",
        }
    }

    /// What a line of this kind is called in messages: a `beam` (fixed-beam) or a `path`
    /// (tracer), as in "station 1 beam 4".
    pub fn line_word(self) -> &'static str {
        match self {
            ObsKind::Beam => "beam",
            ObsKind::Range => "path",
        }
    }

    pub fn parse(s: &str) -> Option<ObsKind> {
        match s.trim() {
            "beam" => Some(ObsKind::Beam),
            "range" => Some(ObsKind::Range),
            _ => None,
        }
    }
}

/// One acquired point: a synchronised pair of interferometer reading and machine coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Reading {
    pub kind: ObsKind,
    /// Device position (deflector or tracer station).
    pub station: u32,
    /// Beam (kind = beam) or path (kind = range) id, unique within a station.
    pub line: u32,
    /// Acquisition time, seconds from campaign start.
    pub t_s: f64,
    /// Interferometer reading, metres, arbitrary origin per line.
    pub l_m: f64,
    /// Indicated machine coordinates.
    pub x: Point3<f64>,
    /// Probe / reflector offset in machine axes.
    pub p: Vector3<f64>,
    /// Air along the beam, when recorded.
    pub air: Option<Air>,
    /// Machine (scale) temperature, when recorded.
    pub machine_temp_c: Option<f64>,
    /// Machine velocity at acquisition, when recorded (on-the-fly acquisition).
    pub velocity: Option<Vector3<f64>>,
    /// The interferometer lost its count before this reading: a new segment starts here.
    pub beam_broken: bool,
    /// Where the reading came from (file line number, message index), for messages only.
    pub source_line: usize,
}

/// How the interferometer readings relate to the air.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(tag = "readings", rename_all = "snake_case"))]
pub enum Compensation {
    /// Readings are true lengths (the instrument compensated them).
    Compensated,
    /// Readings were computed with the assumed index `assumed_index` (1 = vacuum wavelength).
    Uncompensated { assumed_index: f64 },
}

/// Campaign-wide metadata.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct CampaignMeta {
    pub wavelength_vac_m: f64,
    pub compensation: Compensation,
    pub air_equation: AirIndexEquation,
}

impl Default for CampaignMeta {
    fn default() -> Self {
        CampaignMeta {
            wavelength_vac_m: 632.991_212_58e-9,
            compensation: Compensation::Compensated,
            air_equation: AirIndexEquation::Ciddor,
        }
    }
}

/// A whole campaign: metadata and readings in acquisition order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Campaign {
    pub meta: CampaignMeta,
    pub readings: Vec<Reading>,
}

/// Thermal properties of the machine scales (ISO 1 normalisation), per axis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ScaleExpansion {
    /// Expansion coefficient per axis, 1/K (`None`: not normalised).
    pub alpha_per_k: [Option<f64>; 3],
    /// Fixed point of each scale, metres.
    pub fixed_point_m: [f64; 3],
}

/// A problem found in the input.
#[derive(Clone, Debug, PartialEq)]
pub struct InputIssue {
    /// Source line of the offending reading (0 when not tied to one reading).
    pub source_line: usize,
    /// Field (column) concerned, if any.
    pub field: Option<&'static str>,
    pub message: String,
}

impl fmt::Display for InputIssue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.source_line > 0 {
            write!(f, "line {}: ", self.source_line)?;
        }
        if let Some(field) = self.field {
            write!(f, "field {field}: ")?;
        }
        f.write_str(&self.message)
    }
}

/// A group of observations sharing one unknown additive origin.
#[derive(Clone, Debug, PartialEq)]
pub struct LineGroup {
    pub kind: ObsKind,
    pub station: u32,
    pub line: u32,
    /// Segment index within the line (beam breaks start new segments).
    pub segment: u32,
    /// Observations `start..end` in [`Observations`].
    pub start: usize,
    pub end: usize,
}

impl LineGroup {
    pub fn len(&self) -> usize {
        self.end - self.start
    }

    pub fn is_empty(&self) -> bool {
        self.end == self.start
    }

    pub fn range(&self) -> std::ops::Range<usize> {
        self.start..self.end
    }

    /// `station/line[/segment]` label for messages.
    pub fn label(&self) -> String {
        let what = match self.kind {
            ObsKind::Beam => "beam",
            ObsKind::Range => "path",
        };
        if self.segment == 0 {
            format!("station {} {what} {}", self.station, self.line)
        } else {
            format!("station {} {what} {} segment {}", self.station, self.line, self.segment)
        }
    }
}

/// Prepared observations, stored contiguously per line group.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Observations {
    pub x: Vec<Point3<f64>>,
    pub p: Vec<Vector3<f64>>,
    /// Compensated length readings.
    pub l: Vec<f64>,
    pub t: Vec<f64>,
    pub velocity: Vec<Option<Vector3<f64>>>,
    pub air: Vec<Option<Air>>,
    /// Recorded machine (scale) temperature.
    pub machine_temp: Vec<Option<f64>>,
    /// Index of the originating reading in the campaign.
    pub reading: Vec<usize>,
    pub groups: Vec<LineGroup>,
}

impl Observations {
    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// RMS of `values_m` (one per observation) over each line group, in group order: the
    /// per-line residual a diagnosis reports and a viewer draws as bars.
    pub fn rms_per_line(&self, values_m: &[f64]) -> Vec<f64> {
        self.groups
            .iter()
            .map(|g| {
                let v = &values_m[g.range()];
                (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
            })
            .collect()
    }

    /// Groups of one kind.
    pub fn groups_of(&self, kind: ObsKind) -> impl Iterator<Item = (usize, &LineGroup)> {
        self.groups.iter().enumerate().filter(move |(_, g)| g.kind == kind)
    }

    /// For each group, the index of the first group of the same line (kind, station and line
    /// id): the segments of one beam, which a beam break splits, share its direction.
    pub fn line_owners(&self) -> Vec<usize> {
        (0..self.groups.len())
            .map(|k| {
                let g = &self.groups[k];
                (0..=k)
                    .find(|&j| {
                        let h = &self.groups[j];
                        h.kind == g.kind && h.station == g.station && h.line == g.line
                    })
                    .unwrap_or(k)
            })
            .collect()
    }

    /// Distinct stations of one kind, in increasing order.
    pub fn stations(&self, kind: ObsKind) -> Vec<u32> {
        let mut s: Vec<u32> = self.groups_of(kind).map(|(_, g)| g.station).collect();
        s.sort_unstable();
        s.dedup();
        s
    }
}

/// Result of preparation: observations plus the warnings raised on the way.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Prepared {
    pub obs: Observations,
    pub warnings: Vec<InputIssue>,
}

/// Minimum points in a beam segment for it to carry information beyond its origin and
/// direction.
pub const MIN_BEAM_POINTS: usize = 3;
/// Minimum points in a tracer path.
pub const MIN_RANGE_POINTS: usize = 4;

/// Validates a campaign against a machine travel and prepares it for the estimator.
pub fn prepare(campaign: &Campaign, travel: &Travel, expansion: &ScaleExpansion) -> Result<Prepared, InputIssue> {
    let mut warnings = Vec::new();
    if campaign.readings.is_empty() {
        return Err(InputIssue { source_line: 0, field: None, message: "the campaign has no readings".into() });
    }
    check_finite(campaign)?;
    check_units(campaign, travel)?;

    // Environment: uncompensated readings are converted with the recorded air.
    let mut air_factor = vec![1.0; campaign.readings.len()];
    if let Compensation::Uncompensated { assumed_index } = campaign.meta.compensation {
        let mut missing = 0usize;
        for (i, r) in campaign.readings.iter().enumerate() {
            match r.air {
                Some(air) => {
                    air.validate().map_err(|m| InputIssue {
                        source_line: r.source_line,
                        field: Some("air_temp_c/air_pressure_pa/air_rh_pct"),
                        message: m,
                    })?;
                    let n = air_index(campaign.meta.air_equation, campaign.meta.wavelength_vac_m, &air);
                    air_factor[i] = compensation_factor(assumed_index, n);
                }
                None => missing += 1,
            }
        }
        if missing > 0 {
            warnings.push(InputIssue {
                source_line: 0,
                field: Some("air_temp_c"),
                message: format!(
                    "readings are declared uncompensated but {missing} of {} carry no air temperature, pressure and humidity: those are used as recorded (assumed index {assumed_index})",
                    campaign.readings.len()
                ),
            });
        }
    }

    // Group by (kind, station, line), keeping acquisition order; split at beam breaks.
    let mut by_line: BTreeMap<(ObsKind, u32, u32), Vec<usize>> = BTreeMap::new();
    for (i, r) in campaign.readings.iter().enumerate() {
        by_line.entry((r.kind, r.station, r.line)).or_default().push(i);
    }
    let mut obs = Observations::default();
    let mut outside = 0usize;
    let mut normalised = false;
    for ((kind, station, line), idx) in by_line {
        let mut segments: Vec<Vec<usize>> = vec![Vec::new()];
        for &i in &idx {
            if campaign.readings[i].beam_broken && !segments.last().unwrap().is_empty() {
                segments.push(Vec::new());
            }
            segments.last_mut().unwrap().push(i);
        }
        let min = match kind {
            ObsKind::Beam => MIN_BEAM_POINTS,
            ObsKind::Range => MIN_RANGE_POINTS,
        };
        for (s, seg) in segments.into_iter().enumerate() {
            let label = LineGroup { kind, station, line, segment: s as u32, start: 0, end: 0 }.label();
            if seg.len() < min {
                let first = seg.first().map(|&i| campaign.readings[i].source_line).unwrap_or(0);
                warnings.push(InputIssue {
                    source_line: first,
                    field: None,
                    message: format!(
                        "{label} has {} point(s), fewer than {min}: it carries no information and is skipped",
                        seg.len()
                    ),
                });
                continue;
            }
            let start = obs.len();
            for &i in &seg {
                let r = &campaign.readings[i];
                let mut x = r.x;
                if let Some(tc) = r.machine_temp_c {
                    for a in Axis::ALL {
                        if let Some(alpha) = expansion.alpha_per_k[a.index()] {
                            x[a.index()] =
                                normalise_to_20c(x[a.index()], alpha, tc, expansion.fixed_point_m[a.index()]);
                            normalised = true;
                        }
                    }
                }
                if !travel.contains(&r.x, 0.02 * max_length(travel)) {
                    outside += 1;
                }
                obs.x.push(x);
                obs.p.push(r.p);
                obs.l.push(r.l_m * air_factor[i]);
                obs.t.push(r.t_s);
                obs.velocity.push(r.velocity);
                obs.air.push(r.air);
                obs.machine_temp.push(r.machine_temp_c);
                obs.reading.push(i);
            }
            let g = LineGroup { kind, station, line, segment: s as u32, start, end: obs.len() };
            if kind == ObsKind::Beam {
                if let Some(w) = check_beam_alignment(&obs, &g) {
                    warnings.push(w);
                }
            }
            obs.groups.push(g);
        }
    }
    let has_temp = campaign.readings.iter().any(|r| r.machine_temp_c.is_some());
    if has_temp && !normalised && expansion.alpha_per_k.iter().any(|a| a.is_none()) {
        warnings.push(InputIssue {
            source_line: 0,
            field: Some("machine_temp_c"),
            message: "the campaign records machine temperatures but the machine file gives no expansion coefficients: coordinates are not normalised to 20 degC".into(),
        });
    }
    if outside > 0 {
        warnings.push(InputIssue {
            source_line: 0,
            field: Some("x_m/y_m/z_m"),
            message: format!(
                "{outside} reading(s) lie outside the machine travel; error functions are held constant beyond it"
            ),
        });
    }
    if obs.groups.is_empty() {
        return Err(InputIssue {
            source_line: 0,
            field: None,
            message: "no beam or path has enough points to solve".into(),
        });
    }
    Ok(Prepared { obs, warnings })
}

fn max_length(travel: &Travel) -> f64 {
    Axis::ALL.iter().map(|&a| travel.length(a)).fold(0.0, f64::max)
}

/// Largest length or coordinate a reading may carry, metres.
const MAX_LENGTH_M: f64 = 1e4;

fn check_finite(c: &Campaign) -> Result<(), InputIssue> {
    for r in &c.readings {
        let bad = |field: &'static str| InputIssue {
            source_line: r.source_line,
            field: Some(field),
            message: "value is not a finite number".into(),
        };
        let fields: [(&'static str, f64); 8] = [
            ("t_s", r.t_s),
            ("l_m", r.l_m),
            ("x_m", r.x.x),
            ("y_m", r.x.y),
            ("z_m", r.x.z),
            ("px_m", r.p.x),
            ("py_m", r.p.y),
            ("pz_m", r.p.z),
        ];
        for (name, v) in fields {
            if !v.is_finite() {
                return Err(bad(name));
            }
            // A length or a coordinate of more than 10 km is no reading of a machine: squared and
            // summed it overflows (a diagnosis printed NaN for a reading of 1e300 m).
            if name != "t_s" && v.abs() > MAX_LENGTH_M {
                return Err(InputIssue {
                    source_line: r.source_line,
                    field: Some(name),
                    message: format!("value {v:e} m is beyond {MAX_LENGTH_M:e} m: no reading of a machine's travel"),
                });
            }
        }
        if let Some(t) = r.machine_temp_c {
            if !t.is_finite() {
                return Err(bad("machine_temp_c"));
            }
        }
        if let Some(v) = r.velocity {
            if !v.iter().all(|x| x.is_finite()) {
                return Err(bad("vx_mps/vy_mps/vz_mps"));
            }
        }
        if let Some(a) = r.air {
            if !(a.temp_c.is_finite() && a.pressure_pa.is_finite() && a.humidity_pct.is_finite()) {
                return Err(bad("air_temp_c/air_pressure_pa/air_rh_pct"));
            }
        }
    }
    Ok(())
}

/// Detects coordinates or abscissae given in millimetres (or micrometres) instead of metres.
fn check_units(c: &Campaign, travel: &Travel) -> Result<(), InputIssue> {
    let big = max_length(travel);
    let reach = Axis::ALL.iter().map(|&a| travel.range(a)[0].abs().max(travel.range(a)[1].abs())).fold(0.0, f64::max);
    let n = c.readings.len();
    let far: Vec<&Reading> = c.readings.iter().filter(|r| r.x.coords.amax() > 20.0 * reach.max(big)).collect();
    if far.len() * 2 > n {
        let r = far[0];
        let scaled_ok =
            c.readings.iter().filter(|r| travel.contains(&Point3::from(r.x.coords / 1000.0), 0.05 * big)).count();
        let hint = if scaled_ok * 2 > n {
            "they look like millimetres: convert to metres"
        } else {
            "check the units (metres expected)"
        };
        return Err(InputIssue {
            source_line: r.source_line,
            field: Some("x_m/y_m/z_m"),
            message: format!(
                "machine coordinates ({:.4}, {:.4}, {:.4}) are far outside the travel (largest extent {big} m); {hint}",
                r.x.x, r.x.y, r.x.z
            ),
        });
    }
    if let Some(r) = c.readings.iter().find(|r| r.p.amax() > 10.0 * big.max(1.0)) {
        return Err(InputIssue {
            source_line: r.source_line,
            field: Some("px_m/py_m/pz_m"),
            message: format!(
                "probe offset ({}, {}, {}) is larger than the machine; probe offsets are in metres",
                r.p.x, r.p.y, r.p.z
            ),
        });
    }
    // Abscissae: compare the span of l with the span of machine motion along each line.
    let mut by_line: BTreeMap<(ObsKind, u32, u32), (f64, f64, Point3<f64>, Point3<f64>, usize)> = BTreeMap::new();
    for r in &c.readings {
        let e = by_line.entry((r.kind, r.station, r.line)).or_insert((f64::MAX, f64::MIN, r.x, r.x, r.source_line));
        e.0 = e.0.min(r.l_m);
        e.1 = e.1.max(r.l_m);
        e.2 = Point3::from(e.2.coords.inf(&r.x.coords));
        e.3 = Point3::from(e.3.coords.sup(&r.x.coords));
    }
    let mut ratios: Vec<(f64, usize)> = by_line
        .values()
        .filter_map(|&(lo, hi, a, b, line)| {
            let motion = (b - a).norm();
            (motion > 1e-3 * big && hi > lo).then(|| ((hi - lo) / motion, line))
        })
        .collect();
    if !ratios.is_empty() {
        ratios.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (median, line) = ratios[ratios.len() / 2];
        let unit = if (300.0..3000.0).contains(&median) {
            Some("millimetres")
        } else if (3e5..3e6).contains(&median) {
            Some("micrometres")
        } else {
            None
        };
        if let Some(unit) = unit {
            return Err(InputIssue {
                source_line: line,
                field: Some("l_m"),
                message: format!("interferometer readings span {median:.0} times the machine motion along their lines: they look like {unit}; l_m must be in metres"),
            });
        }
    }
    Ok(())
}

/// Warns when the machine points of a beam segment do not lie on a line (a wrong beam id,
/// or a beam that was not followed).
fn check_beam_alignment(obs: &Observations, g: &LineGroup) -> Option<InputIssue> {
    let pts: Vec<Point3<f64>> = g.range().map(|i| obs.x[i] + obs.p[i]).collect();
    let fit = crate::beam::fit_line(&pts);
    let length = pts
        .iter()
        .map(|p| (p - fit.centroid).dot(&fit.direction))
        .fold((f64::MAX, f64::MIN), |(a, b), s| (a.min(s), b.max(s)));
    let length = length.1 - length.0;
    if length <= 0.0 {
        return Some(InputIssue {
            source_line: 0,
            field: Some("x_m/y_m/z_m"),
            message: format!("{}: the machine did not move along the beam", g.label()),
        });
    }
    (fit.lateral_rms > 0.005 * length.max(1e-3)).then(|| InputIssue {
        source_line: 0,
        field: Some("x_m/y_m/z_m"),
        message: format!(
            "{}: machine points deviate {:.3} mm RMS from a straight line over {:.3} m; is the beam id right?",
            g.label(),
            fit.lateral_rms * 1e3,
            length
        ),
    })
}
