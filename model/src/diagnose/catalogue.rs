//! The catalogue of physical effects outside the rigid-body model, each as an [`Effect`]: a
//! linear extension of the observation model with its regressors and physical parameters.
//!
//! Every effect's regressors are precomputed per reading from the campaign and the fitted
//! geometry ([`Geometry`]), so that testing and fitting them is cheap. Parameter names match
//! those of the simulator's injections (`volcal_sim::effects`).

use super::geometry::Geometry;
use crate::campaign::{ObsKind, Observations};
use crate::estimator::{Effect, Fit, ObsContext};
use nalgebra::Vector3;
use std::f64::consts::PI;

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
        if super::geometry::cell(geo, &obs.x[i]) == cell {
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
