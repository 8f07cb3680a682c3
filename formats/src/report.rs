//! Human-readable summaries: the error functions' ranges in the manner of the paper's Table 2,
//! the largest volumetric error and where it occurs, residuals and identifiability.

use faer::Mat;
use nalgebra::Vector3;
use std::fmt::Write;
use volcal::predict::{self, function_range, function_sigma, Extremum};
use volcal::{Axis, ErrorFunction, ErrorModel, Motion, Squareness};

/// Scale and unit of a function's values for display.
pub fn display_unit(f: ErrorFunction) -> (f64, &'static str) {
    match f.motion {
        Motion::Translation => (1e6, "um"),
        Motion::Rotation => (1e6, "urad"),
    }
}

/// The Table-2 style block: for each axis its six functions' signed ranges with the largest
/// expanded uncertainty (k = 2) of the function over the travel, and the squareness errors.
pub fn functions_table(model: &ErrorModel, cov: &Mat<f64>) -> String {
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
                    function_sigma(model, cov, f, lo + (hi - lo) * i as f64 / 50.0)
                })
                .fold(0.0, f64::max);
            col.push(format!("{:<4}{:>9.2} {:<4} (U {:.2})", f.name(), r.signed_range * k, unit, 2.0 * u * k));
        }
        cells.push(col);
    }
    let mut col = vec!["squareness".to_string()];
    let n = model.layout.n_params;
    for s in Squareness::ALL {
        let i = model.layout.squareness_index(s);
        let sig = if cov.nrows() == n { cov[(i, i)].max(0.0).sqrt() } else { 0.0 };
        col.push(format!("{:<5}{:>9.2} urad (U {:.2})", s.name(), model.squareness(s) * 1e6, 2.0 * sig * 1e6));
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
    out.push_str("Ranges are max - min over the travel, signed by the larger excursion from the axis origin; U = largest expanded uncertainty (k = 2) of the function.\n");
    out
}

/// The largest volumetric error over the travel for each probe offset, as text.
pub fn max_error_lines(model: &ErrorModel, cov: &Mat<f64>, offsets: &[Vector3<f64>]) -> (String, Vec<Extremum>) {
    let step = volcal::Axis::ALL.iter().map(|&a| model.layout.travel.length(a)).fold(0.0, f64::max) / 20.0;
    let mut out = String::new();
    let mut ext = Vec::new();
    for p in offsets {
        let e = predict::max_error(model, cov, p, step);
        let x = e.at.x;
        let _ = writeln!(
            out,
            "Max volumetric error {:.2} um (U95 {:.2} um) at ({:.3}, {:.3}, {:.3}) m, probe offset ({:.3}, {:.3}, {:.3}) m",
            e.magnitude_m * 1e6,
            e.at.u95() * 1e6,
            x.x,
            x.y,
            x.z,
            p.x,
            p.y,
            p.z
        );
        ext.push(e);
    }
    (out, ext)
}
