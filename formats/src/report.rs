//! Human-readable summaries: the error functions' ranges in the manner of the paper's Table 2,
//! the largest volumetric error and where it occurs, residuals and identifiability.

use nalgebra::Vector3;
use std::fmt::Write;
use volcal::band::{simultaneous_band, BAND_DRAWS, BAND_LEVEL};
use volcal::predict::{self, function_range, function_sigma, Extremum, Uncertainty};
use volcal::{Axis, ErrorFunction, ErrorModel, Motion, Squareness};

/// Scale and unit of a function's values for display.
pub fn display_unit(f: ErrorFunction) -> (f64, &'static str) {
    match f.motion {
        Motion::Translation => (1e6, "um"),
        Motion::Rotation => (1e6, "urad"),
    }
}

/// The Table-2 style block: for each axis its six functions' signed ranges with the largest
/// expanded uncertainty (k = 2) of the function over the travel, and the squareness errors. A
/// function (or squareness) the data do not determine is marked so instead of a number.
pub fn functions_table(model: &ErrorModel, unc: &Uncertainty<'_>) -> String {
    let mut cells: Vec<Vec<String>> = Vec::new();
    for a in Axis::ALL {
        let mut col = vec![format!("{} axis", a.letter())];
        for m in 0..6 {
            let f = ErrorFunction::from_index(a.index() * 6 + m);
            let (k, unit) = display_unit(f);
            let r = function_range(model, f, 201);
            let u = (0..=50)
                .map(|i| {
                    let [lo, hi] = model.layout.travel.range(a);
                    function_sigma(model, unc, f, lo + (hi - lo) * i as f64 / 50.0)
                })
                .fold(0.0, f64::max);
            col.push(if u.is_finite() {
                format!("{:<4}{:>9.2} {:<4} (U {:.2})", f.name(), r.signed_range * k, unit, 2.0 * u * k)
            } else {
                format!("{:<4}   not determined", f.name())
            });
        }
        cells.push(col);
    }
    let mut col = vec!["squareness".to_string()];
    let n = model.layout.n_params;
    let cov = unc.covariance;
    for s in Squareness::ALL {
        let i = model.layout.squareness_index(s);
        let sig = if cov.nrows() == n { cov[(i, i)].max(0.0).sqrt() } else { 0.0 };
        if unc.share(std::iter::once([(i, 1.0)].as_slice())) > predict::NOT_DETERMINED_ABOVE {
            col.push(format!("{:<5}   not determined", s.name()));
        } else {
            col.push(format!("{:<5}{:>9.2} urad (U {:.2})", s.name(), model.squareness(s) * 1e6, 2.0 * sig * 1e6));
        }
    }
    cells.push(col);
    let widths: Vec<usize> = cells.iter().map(|c| c.iter().map(|s| s.len()).max().unwrap_or(0)).collect();
    let mut out = String::new();
    for row in 0..7 {
        let mut line = String::new();
        for (c, w) in cells.iter().zip(&widths) {
            let cell = c.get(row).map(String::as_str).unwrap_or("");
            let _ = write!(line, "{cell:<w$}   ", w = *w);
        }
        out.push_str(line.trim_end());
        out.push('\n');
    }
    out.push_str("Ranges are max - min over the travel, signed by the larger excursion from the axis origin; U = largest expanded uncertainty (k = 2) of the function; not determined: the readings do not determine it (see the identifiability statements).\n");
    out
}

/// The largest volumetric error over the travel for each probe offset, as text: among the
/// points where the data determine it, with how much of the volume that is; then the map's
/// simultaneous band over the same grid ([`volcal::band`]), which is what a largest error found
/// by searching the map is known to: its expanded uncertainty beside the one value's U95.
pub fn max_error_lines(model: &ErrorModel, unc: &Uncertainty<'_>, offsets: &[Vector3<f64>]) -> (String, Vec<Extremum>) {
    let step = volcal::Axis::ALL.iter().map(|&a| model.layout.travel.length(a)).fold(0.0, f64::max) / 20.0;
    let grid = predict::grid(&model.layout.travel, step);
    let band = simultaneous_band(model, unc, &grid, offsets, BAND_LEVEL, BAND_DRAWS, 0);
    let mut out = String::new();
    let mut ext = Vec::new();
    for p in offsets {
        let e = predict::max_error(model, unc, p, step);
        let x = e.at.x;
        if e.undetermined_points == e.grid_points {
            let _ = writeln!(
                out,
                "Volumetric error not determined by the data anywhere for probe offset ({:.3}, {:.3}, {:.3}) m: {}",
                p.x,
                p.y,
                p.z,
                what_to_measure(model, unc, p)
            );
        } else {
            let over_map = band
                .map(|b| format!("; {:.2} um over the map as a whole", b.expanded(&e.at) * 1e6))
                .unwrap_or_default();
            let _ = writeln!(
                out,
                "Max volumetric error {:.2} um (U95 {:.2} um{over_map}) at ({:.3}, {:.3}, {:.3}) m, probe offset ({:.3}, {:.3}, {:.3}) m",
                e.magnitude_m * 1e6,
                e.at.u95() * 1e6,
                x.x,
                x.y,
                x.z,
                p.x,
                p.y,
                p.z
            );
            if e.undetermined_points > 0 {
                let _ = writeln!(
                    out,
                    "  (the data determine the error at {} of {} grid points for this offset; elsewhere it is not determined: {})",
                    e.grid_points - e.undetermined_points,
                    e.grid_points,
                    what_to_measure(model, unc, p)
                );
            }
        }
        ext.push(e);
    }
    if let Some(b) = band {
        let _ = writeln!(
            out,
            "The map as a whole: with {:.0} % probability every error component of it ({} values on a {:.0} mm grid where the data determine them) lies within {:.2} standard uncertainties of the truth at once (its simultaneous band, from {} draws of the model's error), where one value read alone lies within {:.2}. A largest error found by searching the map is known to the band, not to one value's U95.",
            b.level * 100.0,
            b.values,
            step * 1e3,
            b.k,
            b.draws,
            predict::COVERAGE_K
        );
    }
    (out, ext)
}

/// Where the map is interpolated between the measured positions of an axis, and where the
/// readings contradict that interpolation, in words (empty when the readings resolve every axis
/// everywhere).
pub fn interpolation_line(unc: &Uncertainty<'_>) -> String {
    let (mut borne, mut contradicted, mut scaled) = (Vec::new(), Vec::new(), Vec::new());
    for a in Axis::ALL {
        let r = &unc.resolution[a.index()];
        if let Some(said) = positions_of(a, r) {
            if r.is_contradicted() {
                contradicted.push(said)
            } else {
                borne.push(said);
                if let predict::AxisResolution::AtPositions { interpolation_scale: s, .. } = r {
                    if *s != 1.0 {
                        scaled.push((a.letter(), *s));
                    }
                }
            }
        }
    }
    let mut out = String::new();
    if !borne.is_empty() {
        let _ = writeln!(
            out,
            "Between the measured positions along {} the map is interpolated: the readings do not resolve a feature shorter than their step there (map column interpolated = 1). Nor do they tell the fit's curve from a straight run between two positions: the uncertainty there holds the difference as a bound (variance d^2 / 3).",
            borne.join(", ")
        );
    }
    if let Some(&(_, first)) = scaled.first() {
        // One factor pooled over the checked axes (a solve since the pooled factor); files
        // written before it keep one per axis.
        let factors = if scaled.iter().all(|&(_, s)| s == first) {
            let axes: Vec<String> = scaled.iter().map(|(a, _)| a.to_string()).collect();
            format!("{first:.2} along {}", axes.join(", "))
        } else {
            scaled.iter().map(|(a, s)| format!("{a} {s:.2}")).collect::<Vec<_>>().join(", ")
        };
        let _ = writeln!(
            out,
            "There its uncertainty is widened to what leaving each position out showed: the interpolation's variance times {factors} (the left-out readings' prediction error beyond what the fit stated for it, put on the interpolation and pooled over the axes checked).",
        );
    }
    if !contradicted.is_empty() {
        let _ = writeln!(
            out,
            "Between the measured positions along {} the readings contradict the interpolation: the error there is not determined by the data (map column determined = 0), only at the positions.",
            contradicted.join(", ")
        );
    }
    out
}

/// "X (11 positions, about 100 mm apart)" for an axis resolved at its positions.
fn positions_of(a: Axis, r: &predict::AxisResolution) -> Option<String> {
    match r {
        predict::AxisResolution::AtPositions { positions, .. } => Some(format!(
            "{} ({} positions, about {:.0} mm apart)",
            a.letter(),
            positions.len(),
            predict::median_spacing(positions) * 1e3
        )),
        predict::AxisResolution::Everywhere => None,
    }
}

/// What to measure so that the data determine the volumetric error at probe offset `p`: the
/// functions the undetermined directions involve, when the error at `p` depends on them, and the
/// axes along which the readings contradict the interpolation between their positions.
pub fn what_to_measure(model: &ErrorModel, unc: &Uncertainty<'_>, p: &Vector3<f64>) -> String {
    // Whether the error at `p` sees the undetermined directions (a tracer's single offset does
    // not see the rolls its lever arm is zero for), on a coarse grid: 5 points along the longest
    // axis.
    let travel = model.layout.travel;
    let step = Axis::ALL.iter().map(|&a| travel.length(a)).fold(0.0, f64::max) / 4.0;
    let sees = unc.has_undetermined()
        && predict::grid(&travel, step)
            .iter()
            .any(|x| predict::predict(model, unc, x, p).undetermined > predict::NOT_DETERMINED_ABOVE);
    what_to_measure_with(model, unc, sees)
}

/// What to measure so that the data determine every error function over its travel (the
/// tables of an ISG or SINUMERIK export): the functions the undetermined directions involve, and
/// the axes along which the readings contradict the interpolation.
pub fn what_to_measure_functions(model: &ErrorModel, unc: &Uncertainty<'_>) -> String {
    what_to_measure_with(model, unc, true)
}

/// The statements of [`what_to_measure`], the undetermined functions among them when
/// `functions` (or when nothing else explains what is missing).
fn what_to_measure_with(model: &ErrorModel, unc: &Uncertainty<'_>, functions: bool) -> String {
    let involved = undetermined_functions(model, unc);
    let functions_said = (!involved.is_empty()).then(|| {
        format!(
            "the readings leave {} undetermined; measure with other probe offsets or along lines that move those axes where they are missing",
            involved.join(", ")
        )
    });
    let mut said: Vec<String> = Vec::new();
    if functions {
        said.extend(functions_said.clone());
    }
    for a in Axis::ALL {
        let r = &unc.resolution[a.index()];
        if let Some(at) = r.is_contradicted().then(|| positions_of(a, r)).flatten() {
            said.push(format!(
                "between the measured positions along {at} the readings contradict the interpolation; measure at more positions along {} (e.g. halve the step)",
                a.letter()
            ));
        }
    }
    if said.is_empty() {
        said.extend(functions_said);
    }
    if said.is_empty() {
        return "measure along more lines".into();
    }
    said.join("; ")
}

/// The functions and squareness errors the undetermined directions involve.
fn undetermined_functions(model: &ErrorModel, unc: &Uncertainty<'_>) -> Vec<String> {
    let weight = |i: usize| -> f64 { (0..unc.undetermined.ncols()).map(|j| unc.undetermined[(i, j)].powi(2)).sum() };
    let mut involved: Vec<String> = ErrorFunction::all()
        .into_iter()
        .filter(|&f| model.layout.range(f).map(weight).sum::<f64>() > 1e-3)
        .map(|f| f.name())
        .collect();
    involved.extend(
        Squareness::ALL
            .iter()
            .filter(|&&s| weight(model.layout.squareness_index(s)) > 1e-3)
            .map(|s| s.name().to_string()),
    );
    involved
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;
    use predict::AxisResolution;

    fn stated(resolution: &[AxisResolution; 3]) -> String {
        let covariance = Mat::<f64>::zeros(0, 0);
        let undetermined = Mat::<f64>::zeros(0, 0);
        interpolation_line(&Uncertainty::new(&covariance, &undetermined).with_resolution(resolution))
    }

    #[test]
    fn a_factor_pooled_over_the_axes_is_stated_once() {
        let at = |s: f64| AxisResolution::at(vec![0.0, 0.1, 0.2]).with_interpolation_scale(s);
        let pooled = stated(&[AxisResolution::Everywhere, at(1.4512), at(1.4512)]);
        assert!(pooled.contains("variance times 1.45 along Y, Z ("), "{pooled}");
        // A file written before the pooled factor keeps one ratio per axis.
        let per_axis = stated(&[AxisResolution::Everywhere, at(1.12), at(1.24)]);
        assert!(per_axis.contains("variance times Y 1.12, Z 1.24 ("), "{per_axis}");
        assert!(!stated(&[AxisResolution::Everywhere, at(1.0), at(1.0)]).contains("widened"));
    }
}
