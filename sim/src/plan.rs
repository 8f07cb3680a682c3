//! Campaign plans: where the device stands, which beam directions it points, how many points
//! per beam, which probe offsets, static or on-the-fly, uni- or bidirectional; and for the
//! tracer method, the stations and the path.
//!
//! A plan expands deterministically into a list of [`BeamTask`]s (or [`PathTask`]s) for a given
//! machine travel; the offline simulator and the ROS 2 sequencer both execute that list.

use crate::instruments::{angles_from_direction, direction_from_angles};
use nalgebra::{Point3, Vector3};
use volcal::{Axis, Travel};

/// Measurement method of a plan.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Method {
    /// Fixed beams from a deflector (patent).
    #[default]
    FixedBeam,
    /// Laser tracer multilateration (paper).
    Tracer,
}

/// Acquisition mode.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(tag = "mode", rename_all = "snake_case"))]
pub enum Acquisition {
    /// The machine stops at each point; readings after `dwell_s`.
    Static { speed_mps: f64, dwell_s: f64 },
    /// The machine moves continuously at `speed_mps`; readings are triggered at equal spacing.
    OnTheFly { speed_mps: f64 },
}

impl Default for Acquisition {
    fn default() -> Self {
        Acquisition::Static { speed_mps: 0.05, dwell_s: 1.0 }
    }
}

impl Acquisition {
    pub fn speed(&self) -> f64 {
        match *self {
            Acquisition::Static { speed_mps, .. } | Acquisition::OnTheFly { speed_mps } => speed_mps,
        }
    }
}

/// Most points per beam, stations, runs of a reference line or stops of a tracer's path a plan
/// may ask for: a million, far beyond any campaign, and far below what would exhaust memory.
pub const MAX_COUNT: usize = 1_000_000;

/// A campaign plan. All fields have defaults; an empty YAML file is the patent's example.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default, deny_unknown_fields))]
pub struct Plan {
    pub method: Method,
    /// Device (or tracer) positions, metres. Empty: placed automatically.
    pub stations: Vec<[f64; 3]>,
    /// Number of automatically placed stations (3 for beams, 4 for the tracer).
    pub n_stations: Option<usize>,
    /// Beam directions per station (patent example: 25).
    pub directions_per_station: usize,
    /// Points per beam (patent example: 100).
    pub points_per_beam: usize,
    /// Minimum elevation of beam directions, degrees.
    pub min_elevation_deg: f64,
    /// Beams shorter than this fraction of the volume's largest extent are not used.
    pub min_beam_fraction: f64,
    /// Probe / reflector offsets, metres; beams cycle through them.
    pub probe_offsets: Vec<[f64; 3]>,
    pub acquisition: Acquisition,
    /// Measure every beam out and back.
    pub bidirectional: bool,
    /// Speeds cycled over the beams (or paths), m/s; empty: the acquisition speed for all.
    /// Varying speeds tell latency (proportional to speed) from reversal (not).
    pub speeds_mps: Vec<f64>,
    /// Tracer path: steps along X, Y, Z on the 12 edges of the working cuboid, metres.
    pub path_step_m: [f64; 3],
    /// Time to move the device to a new station, seconds.
    pub station_setup_s: f64,
    /// Beams along machine axes through given points, measured after the stations' beams, each
    /// from its own device position on the line's extension: the lines a per-axis compensation
    /// table (LinuxCNC, Sinumerik EEC) or an ISO 230-2 test refers to, measured directly.
    pub reference_lines: Vec<ReferenceLine>,
}

/// A beam along one machine axis through a point, over the whole travel of that axis.
///
/// Why: a per-axis compensation corrects positioning along one line per axis, and the error
/// there is what the compensation is judged by. The stations' beams determine it only through
/// the whole model, to the model's uncertainty; a beam on the line measures it directly (as a
/// laser interferometer set up for an ISO 230-2 test does), and the estimator uses it like any
/// other beam (patent eq. 2).
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct ReferenceLine {
    /// The machine axis the beam is parallel to.
    pub axis: LineAxis,
    /// A point of the line (indicated machine position), metres; the other two coordinates must
    /// lie inside the travel.
    pub through: [f64; 3],
    /// Probe / reflector offset on this line, metres (default: none, the tool point).
    #[cfg_attr(feature = "serde", serde(default))]
    pub probe_offset: [f64; 3],
    /// Bidirectional runs, as an ISO 230-2 test measures a line (it asks for at least 5): as
    /// many beams along the line, each out and back, each pointed anew. Absent: one beam, out
    /// only unless the plan is bidirectional.
    #[cfg_attr(feature = "serde", serde(default))]
    pub runs: Option<usize>,
}

/// Machine axis of a [`ReferenceLine`] (`x`, `y` or `z` in a plan file).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "lowercase"))]
pub enum LineAxis {
    X,
    Y,
    Z,
}

impl LineAxis {
    pub fn axis(self) -> Axis {
        match self {
            LineAxis::X => Axis::X,
            LineAxis::Y => Axis::Y,
            LineAxis::Z => Axis::Z,
        }
    }
}

impl Default for Plan {
    fn default() -> Self {
        Plan {
            method: Method::FixedBeam,
            stations: Vec::new(),
            n_stations: None,
            directions_per_station: 25,
            points_per_beam: 100,
            min_elevation_deg: 20.0,
            min_beam_fraction: 0.35,
            probe_offsets: vec![[0.12, 0.0, -0.10], [0.0, 0.12, -0.10], [0.0, 0.0, -0.25]],
            acquisition: Acquisition::default(),
            bidirectional: false,
            speeds_mps: Vec::new(),
            path_step_m: [0.07, 0.05, 0.07],
            station_setup_s: 600.0,
            reference_lines: Vec::new(),
        }
    }
}

/// One beam to measure: the commanded direction and the reflector abscissae along it.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct BeamTask {
    pub station: u32,
    pub beam: u32,
    pub pivot: Point3<f64>,
    pub azimuth_rad: f64,
    pub elevation_rad: f64,
    /// Probe offset used along this beam.
    pub probe_offset: Vector3<f64>,
    /// Abscissae (distance from the pivot) of the points, in acquisition order.
    pub abscissae: Vec<f64>,
}

/// One tracer path from one station: indicated points in order.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct PathTask {
    pub station: u32,
    pub path: u32,
    pub position: Point3<f64>,
    pub probe_offset: Vector3<f64>,
    pub points: Vec<Point3<f64>>,
}

/// Problems with a plan.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("plan: {0}")]
pub struct PlanError(pub String);

impl Plan {
    /// The patent's example campaign scaled to a machine: 3 positions x 25 directions x 100
    /// points, 3 probe offsets.
    pub fn patent_example() -> Plan {
        Plan::default()
    }

    /// A small plan for quick tests: 3 positions x 12 directions x 20 points.
    pub fn short() -> Plan {
        Plan { directions_per_station: 12, points_per_beam: 20, ..Plan::default() }
    }

    /// The paper's tracer scenario: 4 stations, the 12 cuboid edges, steps 70/50/70 mm, reflector
    /// at the Z end (zero offset).
    pub fn paper_tracer() -> Plan {
        Plan {
            method: Method::Tracer,
            probe_offsets: vec![[0.0, 0.0, 0.0]],
            acquisition: Acquisition::Static { speed_mps: 0.05, dwell_s: 5.0 },
            ..Plan::default()
        }
    }

    pub fn validate(&self) -> Result<(), PlanError> {
        if self.points_per_beam < 3 && self.method == Method::FixedBeam {
            return Err(PlanError(format!("points_per_beam must be at least 3, got {}", self.points_per_beam)));
        }
        if self.directions_per_station == 0 && self.method == Method::FixedBeam {
            return Err(PlanError("directions_per_station must be at least 1".into()));
        }
        if self.probe_offsets.is_empty() {
            return Err(PlanError("at least one probe offset is needed (use [0, 0, 0] for none)".into()));
        }
        if self.stations.is_empty() && self.n_stations == Some(0) && self.reference_lines.is_empty() {
            return Err(PlanError(
                "n_stations is 0 and the plan lists no stations and no reference lines: it measures nothing".into(),
            ));
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.acquisition.speed()) || !self.speeds_mps.iter().all(|&v| positive(v)) {
            return Err(PlanError("acquisition speeds must be positive numbers".into()));
        }
        if !self.path_step_m.iter().all(|&s| positive(s)) {
            return Err(PlanError("path_step_m must be positive numbers".into()));
        }
        if let Some(l) = self.reference_lines.iter().find(|l| l.runs == Some(0)) {
            return Err(PlanError(format!("reference line along {:?}: runs must be at least 1", l.axis.axis())));
        }
        // Every other number finite: a NaN or an infinity would reach the campaign file.
        let dwell = match self.acquisition {
            Acquisition::Static { dwell_s, .. } => dwell_s,
            Acquisition::OnTheFly { .. } => 0.0,
        };
        let scalars = [
            ("dwell_s", dwell),
            ("station_setup_s", self.station_setup_s),
            ("min_elevation_deg", self.min_elevation_deg),
            ("min_beam_fraction", self.min_beam_fraction),
        ];
        if let Some((name, v)) = scalars.iter().find(|(_, v)| !v.is_finite()) {
            return Err(PlanError(format!("{name} must be a finite number, got {v}")));
        }
        let points = self
            .probe_offsets
            .iter()
            .chain(&self.stations)
            .chain(self.reference_lines.iter().flat_map(|l| [&l.through, &l.probe_offset]));
        if points.flatten().any(|v| !v.is_finite()) {
            return Err(PlanError("probe offsets, stations and reference lines must be finite numbers".into()));
        }
        // Counts beyond what a campaign could hold: each would ask for more memory than a
        // machine has before a reading is simulated.
        let counts = [
            ("points_per_beam", self.points_per_beam),
            ("n_stations", self.n_stations.unwrap_or(0)),
            ("reference line runs", self.reference_lines.iter().filter_map(|l| l.runs).max().unwrap_or(0)),
        ];
        if let Some((name, n)) = counts.iter().find(|(_, n)| *n > MAX_COUNT) {
            return Err(PlanError(format!("{name} is {n}, more than the {MAX_COUNT} a campaign can hold")));
        }
        Ok(())
    }

    /// Speed of beam (or path) number `i` in acquisition order.
    pub fn speed_for(&self, i: usize) -> f64 {
        if self.speeds_mps.is_empty() {
            self.acquisition.speed()
        } else {
            self.speeds_mps[i % self.speeds_mps.len()]
        }
    }

    /// Station positions for a travel: the given ones, or automatic placement.
    pub fn station_positions(&self, travel: &Travel) -> Vec<Point3<f64>> {
        if !self.stations.is_empty() {
            return self.stations.iter().map(|s| Point3::new(s[0], s[1], s[2])).collect();
        }
        let lo = travel.min_corner();
        let len = travel.max_corner() - lo;
        let frac: &[[f64; 3]] = match self.method {
            // Below the volume, spread in X-Y, so beams rise through it.
            Method::FixedBeam => {
                &[[0.25, 0.3, -0.08], [0.75, 0.45, -0.08], [0.45, 0.8, -0.08], [0.2, 0.75, -0.08], [0.8, 0.15, -0.08]]
            }
            // Four non-coplanar tracer positions on the table and one raised.
            Method::Tracer => {
                &[[0.15, 0.2, -0.1], [0.85, 0.25, -0.1], [0.5, 0.85, -0.1], [0.5, 0.5, 0.2], [0.2, 0.8, 0.05]]
            }
        };
        let n = self.n_stations.unwrap_or(match self.method {
            Method::FixedBeam => 3,
            Method::Tracer => 4,
        });
        // Beams rise from below the lowest reflector position so that they cover the whole
        // Z travel for every probe offset.
        let lowest = self.probe_offsets.iter().map(|p| p[2]).fold(0.0, f64::min);
        (0..n)
            .map(|i| {
                let f = frac[i % frac.len()];
                let jitter = (i / frac.len()) as f64 * 0.05;
                let z = match self.method {
                    Method::FixedBeam => lo.z + lowest + f[2] * len.z,
                    Method::Tracer => lo.z + f[2] * len.z,
                };
                Point3::new(lo.x + (f[0] + jitter) * len.x, lo.y + (f[1] - jitter) * len.y, z)
            })
            .collect()
    }

    /// Expands a fixed-beam plan into beam tasks for a machine travel.
    pub fn beam_tasks(&self, travel: &Travel) -> Result<Vec<BeamTask>, PlanError> {
        self.validate()?;
        let stations = self.n_stations.map_or(self.stations.len(), |n| n.max(self.stations.len())).max(1);
        let readings = stations as f64 * self.directions_per_station as f64 * self.points_per_beam as f64;
        if readings > MAX_COUNT as f64 * 10.0 {
            return Err(PlanError(format!(
                "{stations} station(s) x {} directions x {} points per beam is {readings:.3e} readings, more than the {} a campaign can hold",
                self.directions_per_station,
                self.points_per_beam,
                MAX_COUNT * 10
            )));
        }
        let extent = Axis::ALL.iter().map(|&a| travel.length(a)).fold(0.0, f64::max);
        let min_len = self.min_beam_fraction * extent;
        let mut tasks = Vec::new();
        let mut offset_index = 0;
        for (si, pivot) in self.station_positions(travel).into_iter().enumerate() {
            // Candidate directions: a Fibonacci spiral over the upper part of the sphere.
            let n_cand = 600;
            let zmin = self.min_elevation_deg.to_radians().sin();
            let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
            let mut cands: Vec<(Vector3<f64>, [f64; 2])> = Vec::new();
            for k in 0..n_cand {
                let z = zmin + (1.0 - zmin) * (k as f64 + 0.5) / n_cand as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = golden * k as f64;
                let d = Vector3::new(r * phi.cos(), r * phi.sin(), z);
                // Usable for every probe offset, so any offset can be assigned to it.
                let segs: Vec<Option<[f64; 2]>> = self
                    .probe_offsets
                    .iter()
                    .map(|po| segment_in_travel(&pivot, &d, travel, &Vector3::new(po[0], po[1], po[2])))
                    .collect();
                if segs.iter().all(|s| matches!(s, Some(s) if s[1] - s[0] >= min_len)) {
                    cands.push((d, segs[0].unwrap()));
                }
            }
            if cands.len() < self.directions_per_station {
                return Err(PlanError(format!(
                    "station {si} at ({:.3}, {:.3}, {:.3}) sees only {} usable beam directions (need {}): move it or lower min_beam_fraction",
                    pivot.x,
                    pivot.y,
                    pivot.z,
                    cands.len(),
                    self.directions_per_station
                )));
            }
            // Farthest-point sampling for a wide solid angle, starting from the vertical.
            let mut chosen: Vec<usize> =
                vec![cands.iter().enumerate().max_by(|a, b| a.1 .0.z.total_cmp(&b.1 .0.z)).unwrap().0];
            while chosen.len() < self.directions_per_station {
                let next = (0..cands.len())
                    .filter(|i| !chosen.contains(i))
                    .max_by(|&a, &b| {
                        let da = chosen.iter().map(|&c| cands[a].0.dot(&cands[c].0)).fold(f64::MIN, f64::max);
                        let db = chosen.iter().map(|&c| cands[b].0.dot(&cands[c].0)).fold(f64::MIN, f64::max);
                        db.total_cmp(&da)
                    })
                    .unwrap();
                chosen.push(next);
            }
            for (bi, &ci) in chosen.iter().enumerate() {
                let p = self.probe_offsets[offset_index % self.probe_offsets.len()];
                offset_index += 1;
                let p = Vector3::new(p[0], p[1], p[2]);
                let d = cands[ci].0;
                let seg = segment_in_travel(&pivot, &d, travel, &p)
                    .expect("candidate directions are usable for every probe offset");
                let margin = 0.01 * (seg[1] - seg[0]);
                let (a, b) = (seg[0] + margin, seg[1] - margin);
                let n = self.points_per_beam;
                let mut abscissae: Vec<f64> = (0..n).map(|i| a + (b - a) * i as f64 / (n - 1) as f64).collect();
                if self.bidirectional {
                    let back: Vec<f64> = abscissae.iter().rev().cloned().collect();
                    abscissae.extend(back);
                }
                let (az, el) = angles_from_direction(&d);
                tasks.push(BeamTask {
                    station: si as u32,
                    beam: bi as u32,
                    pivot,
                    azimuth_rad: az,
                    elevation_rad: el,
                    probe_offset: p,
                    abscissae,
                });
            }
        }
        let first_line_station = tasks.last().map_or(0, |t| t.station + 1);
        for (k, line) in self.reference_lines.iter().enumerate() {
            tasks.extend(self.reference_line_tasks(line, first_line_station + k as u32, travel)?);
        }
        Ok(tasks)
    }

    /// The beam tasks of a reference line, one per run: the device on the line's extension, 5 %
    /// of the axis travel below its lower end, pointing along the axis; the points span the
    /// travel with the stations' 1 % margins.
    fn reference_line_tasks(
        &self,
        line: &ReferenceLine,
        station: u32,
        travel: &Travel,
    ) -> Result<Vec<BeamTask>, PlanError> {
        let a = line.axis.axis();
        let p = Vector3::from(line.probe_offset);
        let mut d = Vector3::zeros();
        d[a.index()] = 1.0;
        let mut pivot = Point3::from(Vector3::from(line.through) + p);
        pivot[a.index()] = travel.range(a)[0] - 0.05 * travel.length(a) + p[a.index()];
        let seg = segment_in_travel(&pivot, &d, travel, &p).ok_or_else(|| {
            PlanError(format!(
                "reference line along {a:?} through ({:.3}, {:.3}, {:.3}) m with probe offset ({:.3}, {:.3}, {:.3}) m leaves the travel",
                line.through[0], line.through[1], line.through[2], p.x, p.y, p.z
            ))
        })?;
        let margin = 0.01 * (seg[1] - seg[0]);
        let (s0, s1) = (seg[0] + margin, seg[1] - margin);
        let n = self.points_per_beam;
        let mut abscissae: Vec<f64> = (0..n).map(|i| s0 + (s1 - s0) * i as f64 / (n - 1) as f64).collect();
        if self.bidirectional || line.runs.is_some() {
            let back: Vec<f64> = abscissae.iter().rev().cloned().collect();
            abscissae.extend(back);
        }
        let (azimuth_rad, elevation_rad) = angles_from_direction(&d);
        Ok((0..line.runs.unwrap_or(1) as u32)
            .map(|beam| BeamTask {
                station,
                beam,
                pivot,
                azimuth_rad,
                elevation_rad,
                probe_offset: p,
                abscissae: abscissae.clone(),
            })
            .collect())
    }

    /// Expands a tracer plan into path tasks: each station runs the 12 edges of the cuboid.
    pub fn path_tasks(&self, travel: &Travel) -> Result<Vec<PathTask>, PlanError> {
        self.validate()?;
        let lo = travel.min_corner();
        let hi = travel.max_corner();
        let corner = |i: usize, j: usize, k: usize| Point3::new([lo.x, hi.x][i], [lo.y, hi.y][j], [lo.z, hi.z][k]);
        let mut edges: Vec<(Point3<f64>, Point3<f64>, usize)> = Vec::new();
        for j in 0..2 {
            for k in 0..2 {
                edges.push((corner(0, j, k), corner(1, j, k), 0));
            }
        }
        for i in 0..2 {
            for k in 0..2 {
                edges.push((corner(i, 0, k), corner(i, 1, k), 1));
            }
        }
        for i in 0..2 {
            for j in 0..2 {
                edges.push((corner(i, j, 0), corner(i, j, 1), 2));
            }
        }
        let steps =
            |a: &Point3<f64>, b: &Point3<f64>, ax: usize| ((b - a).norm() / self.path_step_m[ax]).round().max(1.0);
        let total: f64 = edges.iter().map(|(a, b, ax)| steps(a, b, *ax) + 1.0).sum();
        if total > MAX_COUNT as f64 {
            return Err(PlanError(format!(
                "path_step_m {:?} gives {total:.3e} stops along the edges, more than the {MAX_COUNT} a campaign can hold",
                self.path_step_m
            )));
        }
        let mut points = Vec::new();
        for (a, b, ax) in edges {
            let n = steps(&a, &b, ax) as usize;
            for s in 0..=n {
                points.push(a + (b - a) * (s as f64 / n as f64));
            }
        }
        let p = self.probe_offsets[0];
        let p = Vector3::new(p[0], p[1], p[2]);
        Ok(self
            .station_positions(travel)
            .into_iter()
            .enumerate()
            .map(|(si, q)| PathTask {
                station: si as u32,
                path: 0,
                position: q,
                probe_offset: p,
                points: points.clone(),
            })
            .collect())
    }
}

/// Abscissa interval `[s0, s1]` of the ray `pivot + s d` (s > 0) over which the indicated
/// position `pivot + s d - p` stays inside the travel.
pub fn segment_in_travel(pivot: &Point3<f64>, d: &Vector3<f64>, travel: &Travel, p: &Vector3<f64>) -> Option<[f64; 2]> {
    let mut s0 = 0.02f64;
    let mut s1 = f64::INFINITY;
    for a in Axis::ALL {
        let [lo, hi] = travel.range(a);
        let o = pivot[a.index()] - p[a.index()];
        let v = d[a.index()];
        if v.abs() < 1e-12 {
            if o < lo || o > hi {
                return None;
            }
        } else {
            let (t0, t1) = ((lo - o) / v, (hi - o) / v);
            s0 = s0.max(t0.min(t1));
            s1 = s1.min(t0.max(t1));
        }
    }
    (s1 > s0).then_some([s0, s1])
}

/// Commanded direction of a task.
pub fn task_direction(t: &BeamTask) -> Vector3<f64> {
    direction_from_angles(t.azimuth_rad, t.elevation_rad)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn travel() -> Travel {
        Travel::new([0.0, 0.8], [0.0, 0.5], [-0.5, 0.0])
    }

    #[test]
    fn a_reference_line_is_one_beam_along_its_axis_over_the_travel() {
        let through = [0.4, 0.25, -0.25];
        let lines = [LineAxis::X, LineAxis::Y, LineAxis::Z].map(|axis| ReferenceLine {
            axis,
            through,
            probe_offset: [0.0; 3],
            runs: None,
        });
        let plan = Plan { reference_lines: lines.to_vec(), ..Plan::short() };
        let tasks = plan.beam_tasks(&travel()).unwrap();
        let stations = plan.station_positions(&travel()).len() as u32;
        assert_eq!(tasks.len(), 3 * 12 + 3);
        for (k, t) in tasks[36..].iter().enumerate() {
            let a = Axis::ALL[k];
            assert_eq!((t.station, t.beam), (stations + k as u32, 0), "each line from its own device position");
            let d = task_direction(t);
            assert!((d - Vector3::from_fn(|i, _| if i == a.index() { 1.0 } else { 0.0 })).norm() < 1e-12);
            let [lo, hi] = travel().range(a);
            let first = t.pivot + d * t.abscissae[0] - t.probe_offset;
            let last = t.pivot + d * *t.abscissae.last().unwrap() - t.probe_offset;
            for i in 0..3 {
                if i != a.index() {
                    assert!((first[i] - through[i]).abs() < 1e-12 && (last[i] - through[i]).abs() < 1e-12);
                }
            }
            // The stations' 1 % margins at both ends.
            assert!((first[a.index()] - (lo + 0.01 * (hi - lo))).abs() < 1e-12, "{first}");
            assert!((last[a.index()] - (hi - 0.01 * (hi - lo))).abs() < 1e-12, "{last}");
            assert_eq!(t.abscissae.len(), plan.points_per_beam);
        }
    }

    /// Numbers a plan file could hold that no campaign can: NaN or infinite speeds and times,
    /// and counts that would exhaust memory before a reading is simulated (found by fuzzing:
    /// they wrote NaN into the campaign, panicked or aborted).
    #[test]
    fn plans_beyond_a_campaign_are_refused() {
        let travel = Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]);
        let bad = [
            Plan { acquisition: Acquisition::Static { speed_mps: f64::NAN, dwell_s: 1.0 }, ..Plan::short() },
            Plan { acquisition: Acquisition::OnTheFly { speed_mps: f64::INFINITY }, ..Plan::short() },
            Plan { acquisition: Acquisition::Static { speed_mps: 0.05, dwell_s: f64::NAN }, ..Plan::short() },
            Plan { min_elevation_deg: f64::NAN, ..Plan::short() },
            Plan { probe_offsets: vec![[f64::NAN, 0.0, 0.0]], ..Plan::short() },
            Plan { station_setup_s: f64::INFINITY, ..Plan::short() },
            Plan { points_per_beam: usize::MAX, ..Plan::short() },
            Plan { n_stations: Some(1_000_000), ..Plan::short() },
            Plan { n_stations: Some(0), ..Plan::short() },
        ];
        for p in bad {
            assert!(p.beam_tasks(&travel).is_err(), "{p:?}");
        }
        let tiny = Plan { path_step_m: [1e-7; 3], ..Plan::paper_tracer() };
        let e = tiny.path_tasks(&travel).unwrap_err();
        assert!(e.0.contains("stops along the edges"), "{e:?}");
        assert!(Plan::short().beam_tasks(&travel).is_ok() && Plan::paper_tracer().path_tasks(&travel).is_ok());
        let nothing = Plan { n_stations: Some(0), ..Plan::short() }.validate().unwrap_err();
        assert!(nothing.0.contains("it measures nothing"), "{nothing:?}");
        let lines_only = Plan {
            n_stations: Some(0),
            reference_lines: vec![ReferenceLine {
                axis: LineAxis::X,
                through: [0.5, 0.4, -0.3],
                probe_offset: [0.0; 3],
                runs: Some(5),
            }],
            ..Plan::short()
        };
        assert!(lines_only.beam_tasks(&travel).is_ok_and(|t| t.len() == 5));
    }

    #[test]
    fn a_reference_line_outside_the_travel_is_refused_with_where() {
        let line = ReferenceLine { axis: LineAxis::Y, through: [0.9, 0.25, -0.25], probe_offset: [0.0; 3], runs: None };
        let plan = Plan { reference_lines: vec![line], ..Plan::short() };
        let err = plan.beam_tasks(&travel()).unwrap_err().to_string();
        assert!(err.contains("reference line along Y through (0.900, 0.250, -0.250)"), "{err}");
    }

    #[test]
    fn runs_are_beams_out_and_back_along_the_line() {
        let line =
            ReferenceLine { axis: LineAxis::Y, through: [0.4, 0.25, -0.25], probe_offset: [0.0; 3], runs: Some(5) };
        let plan = Plan { reference_lines: vec![line], ..Plan::short() };
        let tasks = plan.beam_tasks(&travel()).unwrap();
        let runs = &tasks[36..];
        assert_eq!(runs.len(), 5);
        for (k, t) in runs.iter().enumerate() {
            assert_eq!((t.station, t.beam), (runs[0].station, k as u32));
            let n = plan.points_per_beam;
            assert_eq!(t.abscissae.len(), 2 * n);
            assert!((0..n).all(|i| t.abscissae[i] == t.abscissae[2 * n - 1 - i]), "out and back over the same targets");
        }
        let zero = ReferenceLine { runs: Some(0), ..plan.reference_lines[0].clone() };
        let err = Plan { reference_lines: vec![zero], ..Plan::short() }.beam_tasks(&travel()).unwrap_err();
        assert!(err.to_string().contains("runs must be at least 1"), "{err}");
    }
}
