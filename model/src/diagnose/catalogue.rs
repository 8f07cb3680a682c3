//! The catalogue of physical effects outside the rigid-body model, each as an [`Effect`]: a
//! linear extension of the observation model with its regressors and physical parameters.
//!
//! Every effect's regressors are precomputed per reading from the campaign and the fitted
//! geometry ([`Geometry`]), so that testing and fitting them is cheap. Parameter names match
//! those of the simulator's injections (`volcal_sim::effects`).

use crate::axis::Travel;
use crate::campaign::{ObsKind, Observations};
use crate::environment::{air_index, Air, AirIndexEquation};
use crate::estimator::{Effect, Fit, ObsContext};
use crate::functions::{ErrorFunction, Motion};
use nalgebra::{Matrix3, Point3, Vector3};
use std::f64::consts::PI;

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

/// Legendre polynomial `P_k`.
pub fn legendre(k: usize, s: f64) -> f64 {
    match k {
        0 => 1.0,
        1 => s,
        2 => 0.5 * (3.0 * s * s - 1.0),
        3 => 0.5 * (5.0 * s * s * s - 3.0 * s),
        _ => {
            let (mut p0, mut p1) = (1.0, s);
            for j in 1..k {
                let jf = j as f64;
                let p2 = ((2.0 * jf + 1.0) * s * p1 - jf * p0) / (jf + 1.0);
                p0 = p1;
                p1 = p2;
            }
            p1
        }
    }
}

/// An effect given by precomputed regressors: `regs[i * k + j]` is regressor `j` of reading `i`
/// (most are zero for the per-line effects, which is what keeps them cheap).
pub struct TabulatedEffect {
    pub id: &'static str,
    pub names: Vec<String>,
    pub regs: Vec<f64>,
}

impl Effect for TabulatedEffect {
    fn id(&self) -> &str {
        self.id
    }
    fn param_names(&self) -> Vec<String> {
        self.names.clone()
    }
    fn regressors(&self, ctx: &ObsContext<'_>, out: &mut [f64]) {
        let k = self.names.len();
        out.copy_from_slice(&self.regs[ctx.i * k..(ctx.i + 1) * k]);
    }
}

/// Direction along which each reading increases, from the fit (beam direction, or the unit
/// vector from the tracer station).
pub fn directions(obs: &Observations, fit: &Fit<'_>, geo: &Geometry) -> Vec<Vector3<f64>> {
    let dirs = fit.directions();
    (0..obs.len())
        .map(|i| {
            let g = geo.group_of[i];
            match obs.groups[g].kind {
                ObsKind::Beam => dirs[g],
                ObsKind::Range => (fit.actual()[i] - geo.station_position[geo.station_of_group[g]])
                    .try_normalize(1e-12)
                    .unwrap_or_else(Vector3::zeros),
            }
        })
        .collect()
}

/// Tabulates an effect's regressors, centred on each line: every line has its own eliminated
/// origin, so a constant per line changes nothing, and removing it exactly keeps a regressor
/// whose visible part is small next to its constant part (e.g. `probe_offset`, seen only
/// through the tool rotation along a fixed beam) above the estimator's resolution floor.
fn tabulate(
    id: &'static str,
    names: Vec<String>,
    obs: &Observations,
    mut f: impl FnMut(usize, &mut [f64]),
) -> TabulatedEffect {
    let k = names.len();
    let mut regs = vec![0.0; obs.len() * k];
    for i in 0..obs.len() {
        f(i, &mut regs[i * k..(i + 1) * k]);
    }
    for g in &obs.groups {
        for j in 0..k {
            let mean = g.range().map(|i| regs[i * k + j]).sum::<f64>() / g.len().max(1) as f64;
            if mean != 0.0 {
                g.range().for_each(|i| regs[i * k + j] -= mean);
            }
        }
    }
    TabulatedEffect { id, names, regs }
}

/// `air_refraction` from recorded air: the readings change by
/// `f [delta(t) (l - l0) + (delta(t) - delta(t0)) d0] + m (delta(t) - delta(t0))`, with `f` the
/// uncompensated fraction and `m = f d` the instrument's internal dead-path term.
pub fn air_recorded(obs: &Observations, geo: &Geometry) -> Option<TabulatedEffect> {
    let delta = geo.delta_air.as_ref()?;
    let names = vec!["uncompensated_fraction".to_string(), "internal_dead_path_term_m".to_string()];
    let first = |g: usize| delta[obs.groups[g].start];
    Some(tabulate("air_refraction", names, obs, |i, out| {
        let g = geo.group_of[i];
        let dd = delta[i] - first(g);
        out[0] = delta[i] * (obs.l[i] - geo.l0[g]) + dd * geo.d0[g];
        out[1] = dd;
    }))
}

/// Degree of the time polynomials of the unrecorded drifts.
pub const DRIFT_DEGREE: usize = 3;

/// `air_refraction` without records: a time-correlated scale of the readings,
/// `delta(t) = sum_k c_k P_k(tau)`, same geometry as [`air_recorded`].
pub fn air_unrecorded(obs: &Observations, geo: &Geometry) -> TabulatedEffect {
    let names = (1..=DRIFT_DEGREE).map(|k| format!("scale_drift_p{k}")).collect();
    tabulate("air_refraction", names, obs, |i, out| {
        let g = geo.group_of[i];
        let (tau, tau0) = (geo.tau(obs.t[i]), geo.tau(geo.t0[g]));
        for k in 1..=DRIFT_DEGREE {
            out[k - 1] = legendre(k, tau) * (obs.l[i] - geo.l0[g]) + (legendre(k, tau) - legendre(k, tau0)) * geo.d0[g];
        }
    })
}

/// `material_expansion` from recorded machine temperatures: coordinates not normalised with
/// expansion coefficients `alpha_k`: the readings see `n_k X_k alpha_k (T - 20)`.
pub fn material_recorded(obs: &Observations, dirs: &[Vector3<f64>], geo: &Geometry) -> Option<TabulatedEffect> {
    let dt = geo.dtemp.as_ref()?;
    let names = ["alpha_x_per_k", "alpha_y_per_k", "alpha_z_per_k"].map(String::from).to_vec();
    Some(tabulate("material_expansion", names, obs, |i, out| {
        for k in 0..3 {
            out[k] = dirs[i][k] * obs.x[i][k] * dt[i];
        }
    }))
}

/// `material_expansion` without records: a time-varying scale of each axis.
pub fn material_unrecorded(obs: &Observations, dirs: &[Vector3<f64>], geo: &Geometry) -> TabulatedEffect {
    let mut names = Vec::new();
    for a in ["x", "y", "z"] {
        for k in 1..=2 {
            names.push(format!("scale_{a}_drift_p{k}"));
        }
    }
    tabulate("material_expansion", names, obs, |i, out| {
        let tau = geo.tau(obs.t[i]);
        for a in 0..3 {
            for k in 1..=2 {
                out[a * 2 + k - 1] = dirs[i][a] * obs.x[i][a] * legendre(k, tau);
            }
        }
    })
}

/// `setup_drift`: each station drifts at a constant velocity: `-n . v (t - t0)`.
pub fn setup_drift(obs: &Observations, dirs: &[Vector3<f64>], geo: &Geometry) -> TabulatedEffect {
    let mut names = Vec::new();
    for (kind, id) in &geo.stations {
        let k = if *kind == ObsKind::Beam { "station" } else { "tracer" };
        for c in ["vx", "vy", "vz"] {
            names.push(format!("{k}{id}_{c}_m_per_s"));
        }
    }
    tabulate("setup_drift", names, obs, |i, out| {
        let g = geo.group_of[i];
        let s = geo.station_of_group[g];
        for c in 0..3 {
            out[3 * s + c] = -dirs[i][c] * (obs.t[i] - geo.t0[g]);
        }
    })
}

/// `latency`: the coordinates lag the abscissae by `tau`: `n . v tau`.
pub fn latency(obs: &Observations, dirs: &[Vector3<f64>], geo: &Geometry) -> Option<TabulatedEffect> {
    geo.velocity_recorded
        .then(|| tabulate("latency", vec!["latency_s".into()], obs, |i, out| out[0] = dirs[i].dot(&geo.velocity[i])))
}

/// `reversal`: backlash `b_k`: the position lags half of it behind each axis's last move:
/// `-n_k b_k sign(m_k) / 2`.
pub fn reversal(obs: &Observations, dirs: &[Vector3<f64>], geo: &Geometry) -> TabulatedEffect {
    let names = ["backlash_x_m", "backlash_y_m", "backlash_z_m"].map(String::from).to_vec();
    tabulate("reversal", names, obs, |i, out| {
        for k in 0..3 {
            let m = geo.motion[i][k];
            out[k] = if m.abs() > 1e-6 { -0.5 * dirs[i][k] * m.signum() } else { 0.0 };
        }
    })
}

/// `periodic_pitch` of an axis with period `period`: `n_a (s sin + c cos)(2 pi q_a / period)`.
pub fn periodic(obs: &Observations, dirs: &[Vector3<f64>], axis: usize, period: f64) -> TabulatedEffect {
    tabulate("periodic_pitch", vec!["sin_m".into(), "cos_m".into()], obs, |i, out| {
        let (sn, cs) = (2.0 * PI * obs.x[i][axis] / period).sin_cos();
        out[0] = dirs[i][axis] * sn;
        out[1] = dirs[i][axis] * cs;
    })
}

/// `nonrigid`: products of Legendre polynomials of two axes in each error component, the
/// position-dependent coupling a rigid-body model cannot express (the parts it can are
/// recognised by the score test as aliasing and dropped).
pub fn nonrigid(obs: &Observations, dirs: &[Vector3<f64>], geo: &Geometry) -> TabulatedEffect {
    let axes = ["x", "y", "z"];
    let mut terms: Vec<(usize, usize, usize, usize, usize)> = Vec::new();
    for c in 0..3 {
        for a in 0..3 {
            for b in a + 1..3 {
                for (oa, ob) in [(1, 2), (2, 1), (2, 2)] {
                    terms.push((c, a, oa, b, ob));
                }
            }
        }
    }
    let names =
        terms.iter().map(|&(c, a, oa, b, ob)| format!("e{}:P{oa}({})P{ob}({})", axes[c], axes[a], axes[b])).collect();
    tabulate("nonrigid", names, obs, |i, out| {
        let x = &obs.x[i];
        for (j, &(c, a, oa, b, ob)) in terms.iter().enumerate() {
            out[j] = dirs[i][c] * legendre(oa, geo.unit(a, x[a])) * legendre(ob, geo.unit(b, x[b]));
        }
    })
}

/// `probe_offset`: the reflector of each probe but the reference sits `dp` from its declared
/// offset: the readings see `n . (R dp)`, with `R` the tool rotation of the fitted model.
pub fn probe_offset(obs: &Observations, dirs: &[Vector3<f64>], geo: &Geometry) -> Option<TabulatedEffect> {
    if geo.probes.len() < 2 {
        return None;
    }
    let others: Vec<usize> = (0..geo.probes.len()).filter(|&k| k != geo.reference_probe).collect();
    let mut names = Vec::new();
    for &k in &others {
        for c in ["dx_m", "dy_m", "dz_m"] {
            names.push(format!("probe{k}_{c}"));
        }
    }
    Some(tabulate("probe_offset", names, obs, |i, out| {
        if let Some(slot) = others.iter().position(|&k| k == geo.probe_of[i]) {
            // n . (I + [r]x) e_c = n_c + (n x r)_c.
            let v = dirs[i] + dirs[i].cross(&geo.rot_sum[i]);
            for c in 0..3 {
                out[3 * slot + c] = v[c];
            }
        }
    }))
}

/// Not a catalogue effect: a local anomaly in one cell of the volume, an error vector linear
/// in the coordinates inside the cell (12 parameters). It competes with the catalogue so that
/// an excess confined to one place is not forced into a campaign-wide name.
pub fn local_anomaly(obs: &Observations, dirs: &[Vector3<f64>], geo: &Geometry, cell: usize) -> TabulatedEffect {
    let axes = ["x", "y", "z"];
    let names = (0..3).flat_map(|c| ["1", "x", "y", "z"].map(move |t| format!("e{}:{t}", axes[c]))).collect();
    tabulate("local_anomaly", names, obs, |i, out| {
        if super::locate::cell(geo, &obs.x[i]) == cell {
            let u = [1.0, geo.unit(0, obs.x[i].x), geo.unit(1, obs.x[i].y), geo.unit(2, obs.x[i].z)];
            for c in 0..3 {
                for (t, ut) in u.iter().enumerate() {
                    out[4 * c + t] = dirs[i][c] * ut;
                }
            }
        }
    })
}

/// `beam_break`: a step of the readings of group `g` from its `index`-th point on.
pub fn beam_break(obs: &Observations, geo: &Geometry, group: usize, index: usize) -> TabulatedEffect {
    tabulate("beam_break", vec!["step_m".into()], obs, |i, out| {
        out[0] = if geo.group_of[i] == group && geo.index_in_group[i] >= index { 1.0 } else { 0.0 };
    })
}

/// `cyclic_nonlinearity`: per beam, a sine and a cosine of the fringe phase (one period per
/// fringe; the phase at each beam's zero is unknown). Regressors are computed on the fly: two
/// non-zero values per reading.
pub struct CyclicEffect {
    names: Vec<String>,
    slot_of_group: Vec<Option<usize>>,
    group_of: Vec<usize>,
    fringes: Vec<f64>,
}

impl Effect for CyclicEffect {
    fn id(&self) -> &str {
        "cyclic_nonlinearity"
    }
    fn param_names(&self) -> Vec<String> {
        self.names.clone()
    }
    fn regressors(&self, ctx: &ObsContext<'_>, out: &mut [f64]) {
        if let Some(slot) = self.slot_of_group[self.group_of[ctx.i]] {
            let (sn, cs) = (2.0 * PI * self.fringes[ctx.i]).sin_cos();
            out[2 * slot] = sn;
            out[2 * slot + 1] = cs;
        }
    }
}

/// Builds [`CyclicEffect`] for the beams of a campaign.
pub fn cyclic(obs: &Observations, geo: &Geometry) -> CyclicEffect {
    let mut names = Vec::new();
    let mut slot_of_group = vec![None; obs.groups.len()];
    for (g, gr) in obs.groups.iter().enumerate().filter(|(_, gr)| gr.kind == ObsKind::Beam) {
        slot_of_group[g] = Some(names.len() / 2);
        names.push(format!("s{}b{}_sin_m", gr.station, gr.line));
        names.push(format!("s{}b{}_cos_m", gr.station, gr.line));
    }
    CyclicEffect { names, slot_of_group, group_of: geo.group_of.clone(), fringes: geo.fringes.clone() }
}

/// Amplitude of the cyclic error and its standard uncertainty from the per-beam sine and cosine
/// coefficients (name, value, uncertainty): the mean over beams of `s^2 + c^2` debiased by
/// their noise. The uncertainty comes from the scatter of the beams' values (it includes what
/// the coefficients' own uncertainties miss, such as the phase jitter of the machine's
/// repeatability), and is never below the propagated one.
pub fn cyclic_amplitude(coeffs: &[(String, f64, f64)]) -> (f64, f64) {
    let per_beam: Vec<(f64, f64)> = coeffs
        .chunks(2)
        .filter(|p| p.len() == 2)
        .map(|p| {
            (p[0].1.powi(2) + p[1].1.powi(2) - p[0].2.powi(2) - p[1].2.powi(2), (p[0].2.powi(2) + p[1].2.powi(2)) / 2.0)
        })
        .collect();
    let nb = per_beam.len().max(1) as f64;
    let a2 = per_beam.iter().map(|b| b.0).sum::<f64>() / nb;
    let amp = a2.max(0.0).sqrt();
    let var_coeff = per_beam.iter().map(|b| b.1).sum::<f64>() / nb;
    let propagated = (var_coeff * (1.0 + var_coeff / amp.powi(2).max(1e-300)) / nb).sqrt();
    let scatter = if per_beam.len() > 1 {
        let var_a2 = per_beam.iter().map(|b| (b.0 - a2).powi(2)).sum::<f64>() / (nb - 1.0);
        (var_a2 / nb).sqrt() / (2.0 * amp.max(1e-300))
    } else {
        0.0
    };
    (amp, propagated.max(scatter))
}
