//! What the catalogue's effects and the locator need to know about a campaign beyond its
//! readings: the geometry gathered from a first rigid-body fit (stations, velocities, motion
//! directions, probes, air and material records, fringe counts) and the cells of the volume.
//!
//! Both [`super::catalogue`] and [`super::locate`] read it; it reads neither of them.

use crate::axis::Travel;
use crate::campaign::{ObsKind, Observations};
use crate::environment::{air_index, Air, AirIndexEquation};
use crate::estimator::Fit;
use crate::functions::{ErrorFunction, Motion};
use nalgebra::{Matrix3, Point3, Vector3};

/// What the effects need to know about the campaign beyond the readings.
pub struct Geometry {
    pub travel: Travel,
    /// Group of each reading.
    pub group_of: Vec<usize>,
    /// Index of each reading within its group.
    pub index_in_group: Vec<usize>,
    /// Per group: time, reading and distance from the station of its first point.
    pub t0: Vec<f64>,
    pub l0: Vec<f64>,
    pub d0: Vec<f64>,
    /// Per group: index into `stations`.
    pub station_of_group: Vec<usize>,
    /// Station ids with their kind, and the estimated station positions.
    pub stations: Vec<(ObsKind, u32)>,
    pub station_position: Vec<Point3<f64>>,
    /// Campaign time span.
    pub t_min: f64,
    pub t_max: f64,
    /// Per reading: machine velocity (recorded, or estimated from neighbouring readings).
    pub velocity: Vec<Vector3<f64>>,
    pub velocity_recorded: bool,
    /// Per reading: unit direction of the last move into the point.
    pub motion: Vec<Vector3<f64>>,
    /// Distinct probe offsets, the probe of each reading, and the reference probe.
    pub probes: Vec<Vector3<f64>>,
    pub probe_of: Vec<usize>,
    pub reference_probe: usize,
    /// Per reading: sum of the fitted rotation error vectors of the three axes (tool rotation).
    pub rot_sum: Vec<Vector3<f64>>,
    /// Per reading: relative air-index change since the first reading (from records).
    pub delta_air: Option<Vec<f64>>,
    /// Per reading: machine temperature minus 20 degC (from records).
    pub dtemp: Option<Vec<f64>>,
    /// Per reading: fringe count `2 n l / lambda_vac` of the fitted length `l` (air from
    /// records, else standard air).
    pub fringes: Vec<f64>,
    pub fringes_from_records: bool,
}

/// The wavelength and air equation of the campaign.
#[derive(Clone, Copy, Debug)]
pub struct Optics {
    pub wavelength_vac_m: f64,
    pub air_equation: AirIndexEquation,
}

impl Geometry {
    /// Gathers the geometry from the readings and a fit of the rigid-body model.
    pub fn new(obs: &Observations, fit: &Fit<'_>, optics: Optics) -> Geometry {
        let sol = fit.solution();
        let n = obs.len();
        let mut group_of = vec![0; n];
        let mut index_in_group = vec![0; n];
        for (gi, g) in obs.groups.iter().enumerate() {
            for (k, i) in g.range().enumerate() {
                group_of[i] = gi;
                index_in_group[i] = k;
            }
        }
        // Stations: the tracer stations come with the fit; beam stations are where their beam
        // lines meet (least squares).
        let mut stations: Vec<(ObsKind, u32)> = obs.groups.iter().map(|g| (g.kind, g.station)).collect();
        stations.sort_unstable();
        stations.dedup();
        let station_of_group: Vec<usize> =
            obs.groups.iter().map(|g| stations.iter().position(|s| *s == (g.kind, g.station)).unwrap()).collect();
        let station_position: Vec<Point3<f64>> = stations
            .iter()
            .enumerate()
            .map(|(si, (kind, id))| match kind {
                ObsKind::Range => {
                    sol.stations.iter().find(|s| s.station == *id).map(|s| s.position).unwrap_or_else(Point3::origin)
                }
                ObsKind::Beam => {
                    let mut a = Matrix3::zeros();
                    let mut b = Vector3::zeros();
                    for (gi, st) in sol.stats.per_group.iter().enumerate() {
                        if station_of_group[gi] != si {
                            continue;
                        }
                        let m = Matrix3::identity() - st.direction * st.direction.transpose();
                        a += m;
                        b += m * st.centroid.coords;
                    }
                    a.try_inverse().map(|ai| Point3::from(ai * b)).unwrap_or_else(Point3::origin)
                }
            })
            .collect();
        let actual = fit.actual();
        let t0: Vec<f64> = obs.groups.iter().map(|g| obs.t[g.start]).collect();
        let l0: Vec<f64> = obs.groups.iter().map(|g| obs.l[g.start]).collect();
        let d0: Vec<f64> = obs
            .groups
            .iter()
            .enumerate()
            .map(|(gi, g)| (actual[g.start] - station_position[station_of_group[gi]]).norm())
            .collect();
        let t_min = obs.t.iter().cloned().fold(f64::INFINITY, f64::min);
        let t_max = obs.t.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        // Velocities and motion directions.
        let velocity_recorded = obs.velocity.iter().any(|v| v.is_some_and(|v| v.norm() > 0.0));
        let mut velocity = vec![Vector3::zeros(); n];
        let mut motion = vec![Vector3::zeros(); n];
        for g in &obs.groups {
            let r = g.range();
            for i in r.clone() {
                let prev = if i > r.start { Some(i - 1) } else { None };
                let next = if i + 1 < r.end { Some(i + 1) } else { None };
                velocity[i] = match obs.velocity[i] {
                    Some(v) if velocity_recorded => v,
                    _ => {
                        let (a, b) = (prev.unwrap_or(i), next.unwrap_or(i));
                        let dt = obs.t[b] - obs.t[a];
                        if dt > 0.0 && velocity_recorded {
                            (obs.x[b] - obs.x[a]) / dt
                        } else {
                            Vector3::zeros()
                        }
                    }
                };
                let step = match prev {
                    Some(a) => obs.x[i] - obs.x[a],
                    None => next.map(|b| obs.x[b] - obs.x[i]).unwrap_or_else(Vector3::zeros),
                };
                let v = if velocity[i].norm() > 0.0 { velocity[i] } else { step };
                motion[i] = v.try_normalize(1e-12).unwrap_or_else(Vector3::zeros);
            }
        }
        // Probes.
        let mut probes: Vec<Vector3<f64>> = Vec::new();
        let mut counts: Vec<usize> = Vec::new();
        let probe_of: Vec<usize> = obs
            .p
            .iter()
            .map(|p| match probes.iter().position(|q| (q - p).norm() < 1e-9) {
                Some(k) => {
                    counts[k] += 1;
                    k
                }
                None => {
                    probes.push(*p);
                    counts.push(1);
                    probes.len() - 1
                }
            })
            .collect();
        let reference_probe = 0;
        // Tool rotation of the fitted model at each reading.
        let m = &sol.model;
        let rot_sum: Vec<Vector3<f64>> = obs
            .x
            .iter()
            .map(|x| {
                let mut r = Vector3::zeros();
                for f in ErrorFunction::all().into_iter().filter(|f| f.motion == Motion::Rotation) {
                    r[f.component.index()] += m.function_value(f, f.axis.coord(x));
                }
                r
            })
            .collect();
        // Environment records.
        let has_air = !obs.air.is_empty() && obs.air.iter().all(|a| a.is_some());
        let index = |a: &Air| air_index(optics.air_equation, optics.wavelength_vac_m, a);
        let first = (0..n).min_by(|&a, &b| obs.t[a].total_cmp(&obs.t[b]));
        let delta_air = match (has_air, first) {
            (true, Some(f)) => {
                let n0 = index(&obs.air[f].unwrap());
                Some(obs.air.iter().map(|a| index(&a.unwrap()) / n0 - 1.0).collect())
            }
            _ => None,
        };
        let has_temp = !obs.machine_temp.is_empty() && obs.machine_temp.iter().all(|t| t.is_some());
        let dtemp = has_temp.then(|| obs.machine_temp.iter().map(|t| t.unwrap() - 20.0).collect());
        let standard = index(&Air::standard());
        // The phase of the cyclic error is that of the true length. The reading carries the
        // error itself (20 nm is a fifth of a radian) and the instrument's noise, which would
        // correlate the regressors with the noise of the very readings they fit: the phase is
        // taken from the fitted length instead (air from the records, else standard air).
        let fringes: Vec<f64> = (0..n)
            .map(|i| {
                let length = obs.l[i] - sol.residuals[i];
                2.0 * obs.air[i].map(|a| index(&a)).unwrap_or(standard) * length / optics.wavelength_vac_m
            })
            .collect();
        let _ = counts;
        Geometry {
            travel: m.layout.travel,
            group_of,
            index_in_group,
            t0,
            l0,
            d0,
            station_of_group,
            stations,
            station_position,
            t_min,
            t_max,
            velocity,
            velocity_recorded,
            motion,
            probes,
            probe_of,
            reference_probe,
            rot_sum,
            delta_air,
            dtemp,
            fringes,
            fringes_from_records: has_air,
        }
    }

    /// Campaign time mapped to `[-1, 1]`.
    pub fn tau(&self, t: f64) -> f64 {
        if self.t_max > self.t_min {
            2.0 * (t - self.t_min) / (self.t_max - self.t_min) - 1.0
        } else {
            0.0
        }
    }

    /// Axis coordinate mapped to `[-1, 1]` over the travel.
    pub fn unit(&self, axis: usize, q: f64) -> f64 {
        let [lo, hi] = self.travel.ranges[axis];
        2.0 * (q - lo) / (hi - lo) - 1.0
    }
}

/// Number of cells of the volume (thirds of each axis's travel).
pub const CELLS: usize = 27;

/// Cell of the volume holding machine coordinates `x`.
pub fn cell(geo: &Geometry, x: &Point3<f64>) -> usize {
    let mut c = 0;
    for a in 0..3 {
        let u = ((geo.unit(a, x[a]) + 1.0) / 2.0 * 3.0).floor().clamp(0.0, 2.0) as usize;
        c = c * 3 + u;
    }
    c
}

/// "X high third, Y low third, Z middle third".
pub fn cell_label(c: usize) -> String {
    let names = ["low", "middle", "high"];
    format!("X {} third, Y {} third, Z {} third", names[c / 9], names[(c / 3) % 3], names[c % 3])
}
