//! A misfit far beyond the stated noise, said with the lines that carry it.
//!
//! The covariance is scaled by the variance factor (Birge), so the uncertainties grow with any
//! misfit. That does not make a fit trustworthy whose residuals are many times the noise: it
//! means the readings contradict the model. The cause may be a fault in the readings (a count
//! lost without `beam_broken`: one line far above the others) or physics the model leaves out
//! (thermal drift, the air, the deflector: spread over many lines). A user must hear it, and
//! where to look first.

use crate::campaign::LineGroup;

/// Variance factor beyond which the solve warns: the residuals are 5 times the stated noise
/// (RMS). A stated noise off by a factor of two or three, the usual mistake, stays below it.
pub const GROSS_VARIANCE_FACTOR: f64 = 25.0;

/// How many lines the warning names.
const NAMED_LINES: usize = 3;

/// The warning for a fit whose variance factor `chi2 / dof` exceeds
/// [`GROSS_VARIANCE_FACTOR`], naming the lines with the largest share of the chi-square, from the
/// readings' `residuals` and standard uncertainties `sigmas` (indexed as the `groups`' ranges).
/// `None` below the threshold.
pub fn gross_misfit(chi2: f64, dof: usize, groups: &[LineGroup], residuals: &[f64], sigmas: &[f64]) -> Option<String> {
    let vf = chi2 / dof.max(1) as f64;
    if vf.is_nan() || vf <= GROSS_VARIANCE_FACTOR {
        return None;
    }
    let mut shares: Vec<(f64, &LineGroup, f64)> = groups
        .iter()
        .map(|g| {
            let r = &residuals[g.range()];
            let c: f64 = g.range().map(|i| (residuals[i] / sigmas[i]).powi(2)).sum();
            let rms = (r.iter().map(|v| v * v).sum::<f64>() / r.len().max(1) as f64).sqrt();
            (c, g, rms)
        })
        .collect();
    let total: f64 = shares.iter().map(|s| s.0).sum();
    shares.sort_by(|a, b| b.0.total_cmp(&a.0));
    let named: Vec<String> = shares
        .iter()
        .take(NAMED_LINES)
        .map(|(c, g, rms)| {
            format!(
                "station {} {} {}{} (RMS {:.1} um, {:.0} % of the chi-square)",
                g.station,
                g.kind.line_word(),
                g.line,
                if g.segment > 0 { format!(" segment {}", g.segment) } else { String::new() },
                rms * 1e6,
                100.0 * c / total.max(f64::MIN_POSITIVE)
            )
        })
        .collect();
    Some(format!(
        "the readings do not fit the model: their residuals are {:.0} times the stated noise (chi2/dof {:.3e}). The \
         uncertainties are scaled by it, but the model is not to be used until the cause is found. Most of the misfit \
         is in {}. A count lost without `beam_broken` puts one line far above the others; physics the model leaves \
         out spreads over many, and `volcal diagnose` names it.",
        vf.sqrt(),
        vf,
        named.join(", ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::campaign::ObsKind;

    fn lines(n: usize, per: usize) -> Vec<LineGroup> {
        (0..n)
            .map(|k| LineGroup {
                kind: ObsKind::Beam,
                station: 1,
                line: k as u32,
                segment: 0,
                start: k * per,
                end: (k + 1) * per,
            })
            .collect()
    }

    /// One line one step off its origin (a count re-established at its second point with
    /// nothing flagged) is named first; noise at the stated level says nothing.
    #[test]
    fn a_line_off_its_origin_is_named() {
        let g = lines(10, 20);
        let sigmas = vec![1e-7; 200];
        let mut r: Vec<f64> = (0..200).map(|i| if i % 2 == 0 { 1e-7 } else { -1e-7 }).collect();
        assert!(gross_misfit(200.0, 180, &g, &r, &sigmas).is_none());
        for (j, v) in r[80..100].iter_mut().enumerate() {
            *v += if j == 0 { -0.036 } else { 0.002 };
        }
        let chi2: f64 = r.iter().zip(&sigmas).map(|(r, s)| (r / s).powi(2)).sum();
        let w = gross_misfit(chi2, 180, &g, &r, &sigmas).unwrap();
        assert!(w.contains("Most of the misfit is in station 1 beam 4 (RMS"), "{w}");
        assert!(w.contains("100 % of the chi-square"), "{w}");
    }
}
