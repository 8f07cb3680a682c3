//! Tracer (multilateration) geometry: closed-form initialisation of a station from relative
//! ranges (paper eq. 4 with unknown dead path), used to start the nonlinear estimator.

use faer::linalg::solvers::SolveLstsq;
use faer::Mat;
use nalgebra::{Point3, Vector3};

/// Station position and dead path from the closed-form solution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StationInit {
    pub position: Point3<f64>,
    pub dead_path_m: f64,
    /// RMS of `|Q - P_j| - (l_j + l0)` at the closed-form solution.
    pub rms_m: f64,
}

/// Closed-form multilateration of one station from points `P_j` (nominal positions) and
/// relative ranges `l_j` with one unknown dead path `l0`: `|Q - P_j| = l_j + l0`.
///
/// Squaring gives `-2 P_j . Q - 2 l_j l0 + w = l_j^2 - |P_j|^2` with `w = |Q|^2 - l0^2`, linear
/// in `(Q, l0, w)`; solved by least squares (faer QR). Needs at least 5 points that are not
/// coplanar. Returns `None` when the geometry is degenerate.
pub fn multilaterate(points: &[Point3<f64>], ranges: &[f64]) -> Option<StationInit> {
    let n = points.len();
    if n < 5 || ranges.len() != n {
        return None;
    }
    // Centre the coordinates for conditioning.
    let c = points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n as f64;
    let lm = ranges.iter().sum::<f64>() / n as f64;
    let a = Mat::from_fn(n, 5, |j, k| {
        let p = points[j].coords - c;
        match k {
            0..=2 => -2.0 * p[k],
            3 => -2.0 * (ranges[j] - lm),
            _ => 1.0,
        }
    });
    let mut b = Mat::from_fn(n, 1, |j, _| {
        let p = points[j].coords - c;
        (ranges[j] - lm).powi(2) - p.norm_squared()
    });
    let qr = a.col_piv_qr();
    // Degeneracy: the smallest diagonal of R relative to the largest.
    let r = qr.thin_R();
    let diag: Vec<f64> = (0..5).map(|i| r[(i, i)].abs()).collect();
    let dmax = diag.iter().cloned().fold(0.0, f64::max);
    let dmin = diag.iter().cloned().fold(f64::MAX, f64::min);
    if !(dmax > 0.0) || dmin / dmax < 1e-10 {
        return None;
    }
    qr.solve_lstsq_in_place(b.as_mut());
    let q = Point3::from(Vector3::new(b[(0, 0)], b[(1, 0)], b[(2, 0)]) + c);
    let l0 = b[(3, 0)] - lm;
    let rms =
        (points.iter().zip(ranges).map(|(p, l)| ((q - p).norm() - (l + l0)).powi(2)).sum::<f64>() / n as f64).sqrt();
    q.iter().all(|v| v.is_finite()).then_some(StationInit { position: q, dead_path_m: l0, rms_m: rms })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_station() {
        let q = Point3::new(0.3, -0.2, -0.9);
        let l0 = 0.42;
        let mut pts = Vec::new();
        for i in 0..4 {
            for j in 0..3 {
                for k in 0..3 {
                    pts.push(Point3::new(0.1 * i as f64, -0.2 * j as f64, -0.3 * k as f64));
                }
            }
        }
        let l: Vec<f64> = pts.iter().map(|p| (q - p).norm() - l0).collect();
        let s = multilaterate(&pts, &l).unwrap();
        assert!((s.position - q).norm() < 1e-9);
        assert!((s.dead_path_m - l0).abs() < 1e-9);
    }
}
