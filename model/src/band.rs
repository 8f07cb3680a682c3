//! A simultaneous band: how many standard uncertainties the whole map lies within.
//!
//! Each value of the map carries its own standard uncertainty `u`, and at 95 % a value lies
//! within `2 u` of the truth. A map of thousands of values is not one value: about 5 % of them
//! lie beyond `2 u`, and a few beyond `3 u`, even when every `u` is right. What a user who reads
//! the map at a glance needs is the factor `k` such that, with 95 % probability, *every* value
//! lies within `k u` at once: the simultaneous band (Ruppert, Wand & Carroll 2003,
//! *Semiparametric Regression*, section 6.5; Krivobokova, Kneib & Claeskens 2010 for penalised
//! splines). It is the 95 % point of the largest `|e_i| / u_i` over the map for an error drawn
//! from the model's own covariance, found by drawing it: the values of a map are strongly
//! correlated (they share the same few coefficients), so `k` is far below the Bonferroni
//! bound, and no closed form gives it.
//!
//! Between the measured positions of an axis the covariance is scaled by the interpolation's
//! variance scale ([`crate::predict::AxisResolution`]); that scale multiplies a value's
//! variance and its draws alike, so `k` does not depend on it. The interpolation's shape there
//! ([`crate::predict::interpolation_shape_covariance`]) is a bound, not a draw: it widens each
//! value's `u` and is not in the draws, so `k` is that of the fit's own covariance and the band
//! `k u` errs wide between the positions. Values the data do not determine are not in the band.
//!
//! Deterministic: the draws come from a generator seeded by the caller, so the same model
//! gives the same `k`, bit for bit.

use crate::halves::both;
use crate::predict::{is_determined_with, propagate, PointError, Uncertainty, COVERAGE_K};
use crate::smoothing::factor_psd;
use crate::ErrorModel;
use faer::Mat;
use nalgebra::{Point3, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// Coverage of the simultaneous band that [`simultaneous_band`] gives by default.
pub const BAND_LEVEL: f64 = 0.95;

/// Draws of the model's error that [`simultaneous_band`] takes by default: the 95 % point of
/// the largest ratio from 1 000 draws has a standard error of about 0.03 (`sqrt(0.95 x 0.05 /
/// 1000)` over the largest ratio's density there, about 0.2 for a map's few hundred
/// coefficients).
pub const BAND_DRAWS: usize = 1000;

/// The simultaneous band of a map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimultaneousBand {
    /// Every value lies within `k` of its standard uncertainties at once, with probability
    /// `level`.
    pub k: f64,
    pub level: f64,
    /// Values in the band: (point, probe offset, component) with a non-zero uncertainty where
    /// the data determine the error.
    pub values: usize,
    pub draws: usize,
}

impl SimultaneousBand {
    /// The expanded uncertainty over the map as a whole of the error at `at` (e.g. the map's
    /// largest): `k` times its standard uncertainty along the least favourable direction, where
    /// [`PointError::u95`] takes the one value's 2. Infinite where the data do not determine it.
    pub fn expanded(&self, at: &PointError) -> f64 {
        at.u95() / COVERAGE_K * self.k
    }
}

/// The simultaneous band at `level` of the volumetric error at `points` for each of `offsets`
/// (every component whose standard uncertainty is not zero, where the data determine it), from
/// `draws` draws of the model's error seeded by `seed`. `None` when no value is in the band.
pub fn simultaneous_band(
    model: &ErrorModel,
    unc: &Uncertainty<'_>,
    points: &[Point3<f64>],
    offsets: &[Vector3<f64>],
    level: f64,
    draws: usize,
    seed: u64,
) -> Option<SimultaneousBand> {
    // The values: each a sparse row of the sensitivity over its (unscaled) standard uncertainty.
    let mut rows: Vec<Vec<(usize, f64)>> = Vec::new();
    for x in points {
        for p in offsets {
            let s = model.layout.sensitivity(x, p);
            if !unc.determines_everywhere() && !is_determined_with(unc, x, &s) {
                continue;
            }
            let cov = propagate(&s, unc.covariance);
            for k in 0..3 {
                // A component the gauge fixes (the datum at its origin) has no uncertainty.
                let u = cov[(k, k)].max(0.0).sqrt();
                if u > 1e-12 {
                    rows.push(s.idx.iter().zip(&s.dedu).map(|(&i, d)| (i, d[k] / u)).collect());
                }
            }
        }
    }
    let k = largest_ratio_quantile(&rows, unc.covariance, level, draws, seed)?;
    Some(SimultaneousBand { k, level, values: rows.len(), draws })
}

/// The `level` quantile, over `draws` draws of `e ~ N(0, covariance)` seeded by `seed`, of
/// `max_r |row_r . e|`: each sparse row `(index, coefficient)` already divided by its value's
/// standard uncertainty. `None` without rows, draws or covariance.
fn largest_ratio_quantile(
    rows: &[Vec<(usize, f64)>],
    covariance: &Mat<f64>,
    level: f64,
    draws: usize,
    seed: u64,
) -> Option<f64> {
    if rows.is_empty() || draws == 0 {
        return None;
    }
    // R with R^T R = covariance, its null space (the gauge's, at rounding level) dropped.
    let root = factor_psd(covariance, 1e-14);
    if root.nrows() == 0 {
        return None;
    }
    // Draws of the coefficients' error, one row per draw: Z R.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let z: Mat<f64> = Mat::from_fn(draws, root.nrows(), |_, _| StandardNormal.sample(&mut rng));
    let e = z * &root;
    // Each coefficient's column over the draws as a slice: the inner loop below vectorises.
    let cols: Vec<&[f64]> = (0..e.ncols())
        .map(|i| e.col(i).try_as_col_major().expect("an owned matrix is column-major").as_slice())
        .collect();
    // Row by row, the values of every draw at once, the rows in two halves on two cores (the
    // largest over the draws is the same whichever half finds it: bit-identical either way).
    let half = rows.len() / 2;
    let (a, b) = both(
        rows.len() >= 2 * PARALLEL_ROWS,
        || largest_over(&rows[..half], &cols, draws),
        || largest_over(&rows[half..], &cols, draws),
    );
    let mut largest: Vec<f64> = a.iter().zip(&b).map(|(x, y)| x.max(*y)).collect();
    largest.sort_by(f64::total_cmp);
    let at = ((level * draws as f64).ceil() as usize).clamp(1, draws) - 1;
    Some(largest[at])
}

/// Rows from which the two halves run side by side (a thread costs more than it saves below).
const PARALLEL_ROWS: usize = 1_000;

/// Per draw, the largest `|row . e|` over `rows`, with `cols[i]` coefficient `i`'s error over
/// the draws. The inner loop runs with the instruction set available at run time (`pulp`).
fn largest_over(rows: &[Vec<(usize, f64)>], cols: &[&[f64]], draws: usize) -> Vec<f64> {
    struct Largest<'a> {
        rows: &'a [Vec<(usize, f64)>],
        cols: &'a [&'a [f64]],
        draws: usize,
    }
    impl pulp::WithSimd for Largest<'_> {
        type Output = Vec<f64>;
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) -> Vec<f64> {
            let mut largest = vec![0.0f64; self.draws];
            let mut acc = vec![0.0f64; self.draws];
            for row in self.rows {
                acc.iter_mut().for_each(|a| *a = 0.0);
                for &(i, g) in row {
                    for (a, v) in acc.iter_mut().zip(self.cols[i]) {
                        *a += g * v;
                    }
                }
                for (m, a) in largest.iter_mut().zip(&acc) {
                    *m = m.max(a.abs());
                }
            }
            largest
        }
    }
    pulp::Arch::new().dispatch(Largest { rows, cols, draws })
}

#[cfg(test)]
mod tests {
    use super::*;
    use statrs::distribution::{ContinuousCDF, Normal};

    fn unit_rows(m: usize) -> Vec<Vec<(usize, f64)>> {
        (0..m).map(|i| vec![(i, 1.0)]).collect()
    }

    /// One value: the band is the pointwise 95 % factor, 1.96. Values that are one and the same
    /// (fully correlated): the same. Independent values: Sidak's `Phi^-1((1 + 0.95^(1/m)) / 2)`.
    /// The draws find each to within what 20 000 of them resolve.
    #[test]
    fn the_band_is_pointwise_for_one_value_and_sidak_for_independent_ones() {
        let n = Normal::standard();
        let draws = 20_000;
        let one = largest_ratio_quantile(&unit_rows(1), &Mat::identity(1, 1), 0.95, draws, 1).unwrap();
        assert!((one - 1.959_964).abs() < 0.04, "{one}");

        let same: Vec<Vec<(usize, f64)>> = (0..50).map(|_| vec![(0, 1.0)]).collect();
        let k = largest_ratio_quantile(&same, &Mat::identity(3, 3), 0.95, draws, 2).unwrap();
        assert!((k - 1.959_964).abs() < 0.04, "{k}");

        for m in [10, 100] {
            let sidak = n.inverse_cdf((1.0 + 0.95f64.powf(1.0 / m as f64)) / 2.0);
            let k = largest_ratio_quantile(&unit_rows(m), &Mat::identity(m, m), 0.95, draws, 3).unwrap();
            assert!((k - sidak).abs() < 0.04, "m {m}: {k} against {sidak}");
        }
        // A covariance's scale is in the rows (each divided by its own standard uncertainty).
        let c = Mat::from_fn(2, 2, |i, j| if i == j { 4e-12 } else { 0.0 });
        let rows = vec![vec![(0, 1.0 / 2e-6)], vec![(1, 1.0 / 2e-6)]];
        let k = largest_ratio_quantile(&rows, &c, 0.95, draws, 4).unwrap();
        let sidak = n.inverse_cdf((1.0 + 0.95f64.sqrt()) / 2.0);
        assert!((k - sidak).abs() < 0.04, "{k} against {sidak}");
    }

    /// The same draws give the same band, bit for bit; no rows, no band.
    #[test]
    fn the_band_is_deterministic() {
        let rows = unit_rows(5);
        let c = Mat::identity(5, 5);
        let a = largest_ratio_quantile(&rows, &c, 0.95, 500, 7).unwrap();
        assert_eq!(a.to_bits(), largest_ratio_quantile(&rows, &c, 0.95, 500, 7).unwrap().to_bits());
        assert!(largest_ratio_quantile(&[], &c, 0.95, 500, 7).is_none());
    }
}
