//! Locating excess residual: per station, per line, over time, over the volume, and in the
//! spectrum along each axis.
//!
//! Every test compares the weighted residuals `r / sigma` of a region with what noise alone
//! would give there (its share of the degrees of freedom), with a Bonferroni correction over the
//! regions tested, so that clean data locate nothing.

use super::geometry::{cell, cell_label, Geometry, CELLS};
use crate::campaign::{ObsKind, Observations};
use nalgebra::Vector3;
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::f64::consts::PI;

/// Where excess residual was found.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Location {
    /// `station`, `line`, `time`, `volume` or `spectrum`.
    pub kind: String,
    /// What: "station 2", "station 1 beam 4", "t = 1200 s .. 2400 s", ...
    pub label: String,
    /// Chi-square above what noise would give there (spectrum: the periodogram power).
    pub excess_chi2: f64,
    /// Share of the campaign's total excess chi-square.
    pub share: f64,
    /// Share of the readings (regions; zero for spectra). `share / fraction` above 1 means
    /// the excess is concentrated there.
    pub fraction: f64,
    /// Probability of at least this much under noise alone (Bonferroni-corrected).
    pub p_value: f64,
    pub detail: String,
}

impl Location {
    /// Share of the excess over share of the readings (regions); zero for spectra.
    pub fn concentration(&self) -> f64 {
        if self.fraction > 0.0 {
            self.share / self.fraction
        } else {
            0.0
        }
    }
}

/// Upper-tail probability of a chi-square with `dof` degrees of freedom.
pub fn chi2_sf(x: f64, dof: f64) -> f64 {
    if dof <= 0.0 {
        return 1.0;
    }
    ChiSquared::new(dof).map(|d| d.sf(x.max(0.0))).unwrap_or(1.0)
}

/// Locates excess residual. `z[i]` is reading `i`'s residual over its standard uncertainty,
/// `dof_ratio` the solution's degrees of freedom per reading, `alpha` the family-wise level.
pub fn locate(
    obs: &Observations,
    geo: &Geometry,
    dirs: &[Vector3<f64>],
    z: &[f64],
    dof_ratio: f64,
    alpha: f64,
) -> Vec<Location> {
    let total: f64 = z.iter().map(|v| v * v).sum();
    let total_excess = (total - dof_ratio * z.len() as f64).max(1e-12);
    let mut out = Vec::new();
    // Regions: a set of readings each; tested as chi2(dof_ratio * n).
    let test = |kind: &str, label: String, members: &[usize], tests: usize, detail: String, out: &mut Vec<Location>| {
        let chi2: f64 = members.iter().map(|&i| z[i] * z[i]).sum();
        let dof = dof_ratio * members.len() as f64;
        let p = (chi2_sf(chi2, dof) * tests as f64).min(1.0);
        if p < alpha && chi2 > dof {
            out.push(Location {
                kind: kind.into(),
                label,
                excess_chi2: chi2 - dof,
                share: (chi2 - dof) / total_excess,
                fraction: members.len() as f64 / z.len().max(1) as f64,
                p_value: p,
                detail,
            });
        }
    };
    // Stations.
    for (si, (kind, id)) in geo.stations.iter().enumerate() {
        let members: Vec<usize> = (0..obs.len()).filter(|&i| geo.station_of_group[geo.group_of[i]] == si).collect();
        let what = if *kind == ObsKind::Beam { "station" } else { "tracer station" };
        test(
            "station",
            format!("{what} {id}"),
            &members,
            geo.stations.len(),
            format!("{} readings", members.len()),
            &mut out,
        );
    }
    // Lines.
    let mut lines = Vec::new();
    for (g, gr) in obs.groups.iter().enumerate() {
        let members: Vec<usize> = gr.range().collect();
        test(
            "line",
            gr.label(),
            &members,
            obs.groups.len(),
            format!("{} readings from t = {:.0} s", members.len(), obs.t[gr.start]),
            &mut lines,
        );
        let _ = g;
    }
    lines.sort_by(|a, b| b.excess_chi2.total_cmp(&a.excess_chi2));
    out.extend(lines.into_iter().take(8));
    // Time: the span of lines (in time order) where the excess accumulates (maximum-sum run).
    let mut order: Vec<usize> = (0..obs.groups.len()).collect();
    order.sort_by(|&a, &b| obs.t[obs.groups[a].start].total_cmp(&obs.t[obs.groups[b].start]));
    let excess: Vec<f64> =
        order.iter().map(|&g| obs.groups[g].range().map(|i| z[i] * z[i] - dof_ratio).sum()).collect();
    let (mut best, mut best_span, mut run, mut run_start) = (0.0, (0, 0), 0.0, 0);
    for (k, &e) in excess.iter().enumerate() {
        if run <= 0.0 {
            run = 0.0;
            run_start = k;
        }
        run += e;
        if run > best {
            best = run;
            best_span = (run_start, k);
        }
    }
    if best > 0.0 && best_span.1 + 1 - best_span.0 < order.len() {
        let members: Vec<usize> =
            order[best_span.0..=best_span.1].iter().flat_map(|&g| obs.groups[g].range()).collect();
        let (ta, tb) = (obs.t[obs.groups[order[best_span.0]].start], obs.t[obs.groups[order[best_span.1]].end - 1]);
        // The span was chosen among ~lines^2 / 2 candidates.
        let tests = (order.len() * (order.len() + 1) / 2).max(1);
        test(
            "time",
            format!("t = {ta:.0} s .. {tb:.0} s"),
            &members,
            tests,
            format!("{} of {} lines in time order", best_span.1 + 1 - best_span.0, order.len()),
            &mut out,
        );
    }
    // Volume: 3 x 3 x 3 cells of the travel.
    let mut cells: Vec<Vec<usize>> = vec![Vec::new(); CELLS];
    for i in 0..obs.len() {
        cells[cell(geo, &obs.x[i])].push(i);
    }
    let mut vol = Vec::new();
    for (c, members) in cells.iter().enumerate() {
        if members.is_empty() {
            continue;
        }
        test("volume", cell_label(c), members, CELLS, format!("{} readings", members.len()), &mut vol);
    }
    vol.sort_by(|a, b| b.excess_chi2.total_cmp(&a.excess_chi2));
    out.extend(vol.into_iter().take(3));
    // Most concentrated first: a station holding a third of the excess with a third of the
    // readings says less than a corner of the volume holding a third with a twentieth.
    out.sort_by(|a, b| b.concentration().total_cmp(&a.concentration()));
    // Spectrum along each axis: a periodogram of the weighted residuals projected on the axis.
    for a in 0..3 {
        if let Some(l) = spectrum(obs, geo, dirs, z, a, alpha) {
            out.push(l);
        }
    }
    out
}

/// Best period of a periodic component along axis `a` (from twice the typical point spacing to
/// half the travel), and its significance: the score of a sine/cosine pair is chi-square with two
/// degrees of freedom under noise, corrected for the number of independent periods.
fn spectrum(
    obs: &Observations,
    geo: &Geometry,
    dirs: &[Vector3<f64>],
    z: &[f64],
    a: usize,
    alpha: f64,
) -> Option<Location> {
    let (periods, tests) = period_grid(obs, geo, dirs, a)?;
    let best = best_period(obs, dirs, z, a, &periods);
    let p = (chi2_sf(best.0, 2.0) * tests as f64).min(1.0);
    (p < alpha).then(|| Location {
        kind: "spectrum".into(),
        label: format!("{} axis, period {:.2} mm", ["X", "Y", "Z"][a], best.1 * 1e3),
        excess_chi2: best.0 - 2.0,
        share: 0.0,
        fraction: 0.0,
        p_value: p,
        detail: format!("periodogram of the residuals along {} over {} periods", ["X", "Y", "Z"][a], periods.len()),
    })
}

/// The period of the grid with the largest periodogram, and that periodogram.
pub fn best_period(obs: &Observations, dirs: &[Vector3<f64>], z: &[f64], a: usize, periods: &[f64]) -> (f64, f64) {
    // The grid is uniform in frequency, ascending.
    let f0 = 1.0 / periods[0];
    let df = if periods.len() > 1 { 1.0 / periods[1] - f0 } else { 0.0 };
    let scan = periodogram_scan(obs, dirs, z, a, f0, df, periods.len());
    scan.iter()
        .zip(periods)
        .map(|(&s, &p)| (s, p))
        .fold((0.0, periods[0]), |best, cur| if cur.0 > best.0 { cur } else { best })
}

/// Shortest period searched: periodic errors of drives and scales of interest here (ball-screw
/// leads, encoder interpolation of coarse scales) are millimetres long; the readings of many
/// lines together sample each axis far more densely than one line does.
pub const MIN_PERIOD_M: f64 = 2e-3;

/// Candidate periods along axis `a` and the number of independent ones.
pub fn period_grid(obs: &Observations, geo: &Geometry, dirs: &[Vector3<f64>], a: usize) -> Option<(Vec<f64>, usize)> {
    let [lo, hi] = geo.travel.ranges[a];
    let len = hi - lo;
    // The axis must be seen: enough readings on lines with a component along it.
    if (0..obs.len()).filter(|&i| dirs[i][a].abs() > 0.3).count() < 20 {
        return None;
    }
    let (pmin, pmax) = (MIN_PERIOD_M, len / 2.0);
    if pmin >= pmax {
        return None;
    }
    // Frequencies spaced by a quarter of the independent spacing 1 / len.
    let (fmin, fmax) = (1.0 / pmax, 1.0 / pmin);
    let df = 0.25 / len;
    let n = ((fmax - fmin) / df).ceil() as usize + 1;
    let periods = (0..n).map(|k| 1.0 / (fmin + k as f64 * df)).collect();
    Some((periods, ((fmax - fmin) * len).ceil().max(1.0) as usize))
}

/// Chi-square reduction of a sine/cosine pair of period `lam` along axis `a`, fitted to the
/// residuals alone (line origins eliminated), in units of the noise.
pub fn periodogram(obs: &Observations, geo: &Geometry, dirs: &[Vector3<f64>], z: &[f64], a: usize, lam: f64) -> f64 {
    let (mut g, mut c) = ([[0.0f64; 2]; 2], [0.0f64; 2]);
    for gr in &obs.groups {
        let mut rows: Vec<[f64; 2]> = Vec::with_capacity(gr.len());
        for i in gr.range() {
            let (sn, cs) = (2.0 * PI * obs.x[i][a] / lam).sin_cos();
            rows.push([dirs[i][a] * sn, dirs[i][a] * cs]);
        }
        let n = rows.len() as f64;
        let mean = [rows.iter().map(|r| r[0]).sum::<f64>() / n, rows.iter().map(|r| r[1]).sum::<f64>() / n];
        for (k, i) in gr.range().enumerate() {
            let r = [rows[k][0] - mean[0], rows[k][1] - mean[1]];
            for u in 0..2 {
                c[u] += r[u] * z[i];
                for v in 0..2 {
                    g[u][v] += r[u] * r[v];
                }
            }
        }
    }
    let det = g[0][0] * g[1][1] - g[0][1] * g[1][0];
    if det <= 1e-300 {
        return 0.0;
    }
    let inv = [[g[1][1] / det, -g[0][1] / det], [-g[1][0] / det, g[0][0] / det]];
    let _ = geo;
    c[0] * (inv[0][0] * c[0] + inv[0][1] * c[1]) + c[1] * (inv[1][0] * c[0] + inv[1][1] * c[1])
}

/// [`periodogram`] for a whole grid of frequencies `f0 + k df` (k < n) at once: the sine and
/// cosine of each reading are advanced by an angle-addition recurrence instead of being evaluated
/// for every frequency.
pub fn periodogram_scan(
    obs: &Observations,
    dirs: &[Vector3<f64>],
    z: &[f64],
    a: usize,
    f0: f64,
    df: f64,
    n: usize,
) -> Vec<f64> {
    // Per frequency: G (3 values), c (2 values).
    let (mut g00, mut g01, mut g11) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let (mut c0, mut c1) = (vec![0.0; n], vec![0.0; n]);
    // Per frequency, sums over the current group: s, c, s z, c z and the products.
    let mut acc = vec![[0.0f64; 7]; n];
    for gr in &obs.groups {
        for v in acc.iter_mut() {
            *v = [0.0; 7];
        }
        let m = gr.len() as f64;
        for i in gr.range() {
            let w = dirs[i][a];
            if w == 0.0 {
                continue;
            }
            let x = obs.x[i][a];
            let (mut sn, mut cs) = (2.0 * PI * x * f0).sin_cos();
            let (ds, dc) = (2.0 * PI * x * df).sin_cos();
            for v in acc.iter_mut() {
                let (rs, rc) = (w * sn, w * cs);
                v[0] += rs;
                v[1] += rc;
                v[2] += rs * z[i];
                v[3] += rc * z[i];
                v[4] += rs * rs;
                v[5] += rs * rc;
                v[6] += rc * rc;
                let s2 = sn * dc + cs * ds;
                cs = cs * dc - sn * ds;
                sn = s2;
            }
        }
        // Centre within the group (its origin is free): subtract the means' contributions.
        let zm: f64 = gr.range().map(|i| z[i]).sum::<f64>() / m;
        for k in 0..n {
            let v = &acc[k];
            let (ms, mc) = (v[0] / m, v[1] / m);
            g00[k] += v[4] - m * ms * ms;
            g01[k] += v[5] - m * ms * mc;
            g11[k] += v[6] - m * mc * mc;
            c0[k] += v[2] - m * ms * zm;
            c1[k] += v[3] - m * mc * zm;
        }
    }
    (0..n)
        .map(|k| {
            let det = g00[k] * g11[k] - g01[k] * g01[k];
            if det <= 1e-300 {
                return 0.0;
            }
            (c0[k] * (g11[k] * c0[k] - g01[k] * c1[k]) + c1[k] * (g00[k] * c1[k] - g01[k] * c0[k])) / det
        })
        .collect()
}
