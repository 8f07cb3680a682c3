//! What a face diagonal's two straightnesses leave open, stated no smaller than what the
//! readings measure of the same shapes.
//!
//! A beam along the diagonal of the face of axes P and Q reads `L_P EPQ + L_Q EQP` (P's error
//! while Q moves, Q's while P moves, each weighted by its component's travel). The face's two
//! diagonals together measure that sum and the even part of the difference; the odd part of
//! the difference (about the middle of the travels: a cubic, a quintic, ...) no beam of such a
//! plan sees. The smoothing states it from its roughness prior, whose strength REML takes from
//! the detail the readings resolve. For a given detail that prior fixes how large the open long
//! wave may be, and real errors need not follow it: over the independent simulator's smooth
//! machines (length scales 0.3 to 1.0 of the travel) it stated a third to a half of the open
//! cubic (docs/representation-auto.md, "Longer length scales").
//!
//! Here the two functions of a pair are taken as exchangeable (two guideways' straightness of
//! one machine): the odd long wave of their difference is as large a priori as that of their
//! sum, and as the even long waves of the difference beside it, all of which the readings
//! measure. Per odd degree `k`, the pairs' measured coefficients of that order (each sum's of
//! degree `k`, each difference's of degrees `k - 1` and `k + 1`) give one scale (their mean
//! square), and each pair's open coefficient is stated with at least the variance that scale
//! gives a direction the readings do not see (less what the readings do see of it). The
//! estimate is not moved: the open coefficient's mean is zero either way.
//!
//! Why the neighbours: three sums alone are three draws, too few to estimate a variance. Over
//! the independent simulator's machines (300 seeds per length-scale range, the truth's own
//! coefficients, seeds 5000-5299 and 9000-9299) the sums' scale left 3.4 to 7.0 % of the open
//! cubics beyond three times it; with the differences' even neighbours pooled in (nine draws,
//! and the pair's own among them), 0.3 to 2.2 % (`tests/py/open_long_wave_probe.py`;
//! docs/representation-auto.md, "Nine measured long waves").

use crate::functions::{ErrorFunction, Motion};
use crate::gauge::{self, Gauge};
use crate::model::ModelLayout;
use faer::linalg::solvers::Solve;
use faer::{Mat, MatRef};

/// The odd Legendre degrees of a pair's difference stated from the measured long waves: the
/// cubic and the quintic. The linear one is the squareness's (in the gauge); higher degrees
/// are left to the roughness prior. On the smooth machines where the prior states too little, the seventh's
/// coefficients are small (RMS over the independent simulator's machines: 4 % of the cubic's
/// with length scales 0.3 to 0.6 of the travel, 0.4 % with 0.5 to 1.0); where they are larger
/// (30 % with 0.15 to 0.4), the prior states the open long waves amply.
pub const ODD_DEGREES: [usize; 2] = [3, 5];

/// One open coefficient whose stated uncertainty was raised.
#[derive(Clone, Debug, PartialEq)]
pub struct OpenLongWave {
    /// The pair (`EPQ`, `EQP`).
    pub pair: [ErrorFunction; 2],
    /// The Legendre degree of the coefficient.
    pub degree: usize,
    /// Standard uncertainty of the coefficient of `(L_P EPQ - L_Q EQP) / 2` before, in m x m (an
    /// error weighted by a travel).
    pub before: f64,
    /// After: the measured long waves' scale (module doc), less what the readings see of it.
    pub after: f64,
}

/// Whether `pair` is a face diagonal's two straightnesses (`EPQ` and `EQP`).
fn is_face_pair([a, b]: [ErrorFunction; 2]) -> bool {
    a.motion == Motion::Translation
        && b.motion == Motion::Translation
        && a.component == b.axis
        && b.component == a.axis
        && a.axis != a.component
}

/// Legendre polynomial of degree `k` at `x`.
fn legendre(k: usize, x: f64) -> f64 {
    crate::repr::legendre(k, x).0[k]
}

/// `P_k` over `b`'s travel at `q` (the travel mapped onto -1 to 1).
fn legendre_over(b: &crate::repr::Basis, k: usize, q: f64) -> f64 {
    legendre(k, (q - 0.5 * (b.lo + b.hi)) / (0.5 * b.length()))
}

/// Coefficient weights `g` with `g . c` = the Legendre coefficient of degree `k` of `f`'s
/// function over its travel (`(2k + 1) / 2 int P_k(x) f dx`, `x` from -1 to 1).
fn legendre_functional(layout: &ModelLayout, f: ErrorFunction, k: usize) -> Vec<f64> {
    let b = layout.basis(f);
    let mut g = vec![0.0; b.n_coeffs()];
    for (q, w) in b.quadrature() {
        let p = legendre_over(b, k, q) * (2 * k + 1) as f64 / b.length();
        for (i, v) in b.eval(q) {
            g[i] += w * p * v;
        }
    }
    g
}

/// Raises the stated uncertainty of what the readings leave open of each face diagonal's pair
/// in `pairs` (module doc) in `cov` (the model's parameters, unscaled), from the estimate `u`
/// and the readings' normal matrix `n_data` over the model's parameters. Returns what it
/// raised; pairs that are not a face's straightnesses are left alone.
pub fn state_open_long_waves(
    layout: &ModelLayout,
    gauge_kind: Gauge,
    pairs: &[[ErrorFunction; 2]],
    u: &[f64],
    n_data: MatRef<'_, f64>,
    cov: &mut Mat<f64>,
) -> Vec<OpenLongWave> {
    let pairs: Vec<[ErrorFunction; 2]> = pairs.iter().copied().filter(|&p| is_face_pair(p)).collect();
    if pairs.is_empty() {
        return Vec::new();
    }
    let n = layout.n_params;
    // The gauge: a direction moved along its freedoms until it meets the constraints predicts
    // every observable quantity as before (`d - G (C G)^-1 C d`).
    let g = gauge::null_basis(layout);
    let c = gauge::constraints(layout, gauge_kind);
    let cg_lu = (&c * &g).partial_piv_lu();
    let in_gauge = |d: Mat<f64>| -> Mat<f64> {
        let alpha = cg_lu.solve(&c * &d);
        &d - &g * alpha
    };
    let weight = |f: ErrorFunction| layout.travel.length(f.component);
    let mut raised = Vec::new();
    for k in ODD_DEGREES {
        // Per pair: the functional of the difference's coefficient, the direction that moves it
        // by one, and the measured coefficients of that order (module doc) as estimated.
        let mut per_pair = Vec::new();
        let mut measured = Vec::new();
        for &[a, b] in &pairs {
            let (wa, wb) = (weight(a), weight(b));
            // The estimate's coefficient of the pair's lever-weighted sum (`sign` 1) or
            // difference (-1), given the two functions' functionals of one degree.
            let estimated = |la: &[f64], lb: &[f64], sign: f64| {
                let of_a = layout.range(a).zip(la).map(|(r, l)| l * u[r]).sum::<f64>();
                let of_b = layout.range(b).zip(lb).map(|(r, l)| l * u[r]).sum::<f64>();
                0.5 * (wa * of_a + sign * wb * of_b)
            };
            let (la, lb) = (legendre_functional(layout, a, k), legendre_functional(layout, b, k));
            measured.push(estimated(&la, &lb, 1.0));
            for j in [k - 1, k + 1] {
                measured.push(estimated(&legendre_functional(layout, a, j), &legendre_functional(layout, b, j), -1.0));
            }
            let shape = |f: ErrorFunction| {
                let basis = layout.basis(f);
                basis.fit(|q| legendre_over(basis, k, q))
            };
            let (sa, sb) = (shape(a), shape(b));
            let mut f = Mat::<f64>::zeros(n, 1);
            let mut d = Mat::<f64>::zeros(n, 1);
            for (i, r) in layout.range(a).enumerate() {
                f[(r, 0)] = 0.5 * wa * la[i];
                d[(r, 0)] = sa[i] / wa;
            }
            for (i, r) in layout.range(b).enumerate() {
                f[(r, 0)] = -0.5 * wb * lb[i];
                d[(r, 0)] = -sb[i] / wb;
            }
            // A quintic is not quite a cubic spline: scale the direction to move the
            // coefficient by exactly one.
            let moved = (f.transpose() * &d)[(0, 0)];
            if moved.abs() < 1e-6 {
                continue;
            }
            let d = in_gauge(d * faer::Scale(1.0 / moved));
            per_pair.push(([a, b], f, d));
        }
        if per_pair.is_empty() {
            continue;
        }
        let scale2 = measured.iter().map(|c| c * c).sum::<f64>() / measured.len() as f64;
        if !(scale2 > 0.0) {
            continue;
        }
        for (pair, f, d) in per_pair {
            let before = (f.transpose() * &*cov * &f)[(0, 0)].max(0.0);
            let seen = (d.transpose() * n_data * &d)[(0, 0)].max(0.0);
            let target = 1.0 / (seen + 1.0 / scale2);
            if target > before {
                let add = &d * d.transpose() * faer::Scale(target - before);
                *cov += add;
                raised.push(OpenLongWave { pair, degree: k, before: before.sqrt(), after: target.sqrt() });
            }
        }
    }
    // Symmetric to the bit, as the solve leaves it (untouched where nothing was raised).
    for i in (0..n).filter(|_| !raised.is_empty()) {
        for j in i + 1..n {
            let v = cov[(i, j)];
            cov[(j, i)] = v;
        }
    }
    raised
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legendre_polynomials_and_their_coefficients() {
        assert!((legendre(3, 0.5) - (2.5 * 0.125 - 1.5 * 0.5)).abs() < 1e-15);
        assert!((legendre(5, 1.0) - 1.0).abs() < 1e-15);
        let layout = ModelLayout::uniform(
            crate::topology::Topology::parse("FXYZ").unwrap(),
            crate::axis::Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]),
            crate::repr::Representation::BSpline { intervals: 12 },
        );
        let f =
            ErrorFunction { axis: crate::axis::Axis::Y, motion: Motion::Translation, component: crate::axis::Axis::X };
        let b = layout.basis(f);
        // 2 P3 + P1 on Y's travel: its cubic coefficient is 2, its linear one 1.
        let c = b.fit(|q| {
            let x = (q - 0.4) / 0.4;
            2.0 * legendre(3, x) + x
        });
        let dot = |g: &[f64]| g.iter().zip(&c).map(|(a, b)| a * b).sum::<f64>();
        assert!((dot(&legendre_functional(&layout, f, 3)) - 2.0).abs() < 1e-9);
        assert!((dot(&legendre_functional(&layout, f, 1)) - 1.0).abs() < 1e-9);
        assert!(dot(&legendre_functional(&layout, f, 5)).abs() < 1e-9);
    }

    /// A pair whose measured long waves are of known size, nothing seen by the readings: the
    /// open cubic of the difference is stated with the mean square of the sum's cubic and the
    /// difference's quadratic and quartic, the quintic with that of the sum's quintic (none)
    /// and the difference's quartic and sextic, in the gauge (the constraints hold for every
    /// draw of the added covariance).
    #[test]
    fn the_open_cubic_is_stated_as_large_as_the_measured_one() {
        use crate::axis::Axis;
        let layout = ModelLayout::uniform(
            crate::topology::Topology::parse("FXYZ").unwrap(),
            crate::axis::Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]),
            crate::repr::Representation::BSpline { intervals: 12 },
        );
        let t = |axis, component| ErrorFunction { axis, motion: Motion::Translation, component };
        let (exy, eyx) = (t(Axis::Y, Axis::X), t(Axis::X, Axis::Y));
        // EXY = 2 um (P2 + P3 + P4) over Y's travel: the sum (L_X EXY + L_Y EYX) / 2 has the
        // cubic 1 um, the difference the quadratic and the quartic 1 um.
        let mut u = vec![0.0; layout.n_params];
        let b = layout.basis(exy);
        let c = b.fit(|q| {
            let x = (q - 0.4) / 0.4;
            2e-6 * (legendre(2, x) + legendre(3, x) + legendre(4, x))
        });
        for (r, v) in layout.range(exy).zip(&c) {
            u[r] = *v;
        }
        let n = layout.n_params;
        let mut cov = Mat::<f64>::zeros(n, n);
        let raised = state_open_long_waves(
            &layout,
            Gauge::Patent,
            &[[eyx, exy]],
            &u,
            Mat::<f64>::zeros(n, n).as_ref(),
            &mut cov,
        );
        assert_eq!(raised.len(), 2, "{raised:?}");
        assert_eq!((raised[0].degree, raised[1].degree), (3, 5));
        assert!((raised[0].after - 1e-6).abs() < 1e-11, "{}", raised[0].after);
        assert!((raised[1].after - 1e-6 / 3f64.sqrt()).abs() < 1e-11, "{}", raised[1].after);
        let cons = gauge::constraints(&layout, Gauge::Patent);
        let moved = &cons * &cov;
        let largest = (0..moved.nrows()).flat_map(|i| (0..n).map(move |j| (i, j))).map(|(i, j)| moved[(i, j)].abs());
        assert!(largest.fold(0.0, f64::max) < 1e-24);
    }
}
