//! Validation along lines, as the paper validates its tracer result (Han et al. 2021, section
//! 3.2-3.3): the positioning error of each axis along a line (ISO 230-2 style, figures 7-9) and
//! of the four body diagonals NPP, NPN, PPN, PPP (Table 4, figure 12), predicted from an
//! identified model with uncertainty, and compared with a laser-interferometer measurement of
//! the same lines.
//!
//! A laser interferometer set up on a line from `A` (where its counter is zeroed) to `B` has its
//! beam aligned with the reflector's motion: through the reflector's actual positions `P(A)` and
//! `P(B)`, direction `n' = (P(B) - P(A)) / |P(B) - P(A)|`. At the target `X_s = A + s n` it reads
//! the displacement of the reflector along the beam, and its positioning deviation (ISO 230-2:
//! actual minus target position) is `n' . (P(X_s) - P(A)) - s`. To first order in the errors
//! that is `n . (e(X_s, p) - e(A, p))`, the model's volumetric error projected on the line and
//! referred to the start: the interferometer sees every error function that moves the reflector
//! along the line, not only the positioning error of the axis (the paper's remark on its
//! figures 7-9).
//!
//! Why the aligned beam and not the first-order projection: the deviation an interferometer
//! reads depends only on where the reflector is, not on the frame the map is drawn in, and the
//! first-order projection does not have that property beyond first order. The gauge ([`crate::gauge`])
//! puts the model in a frame turned from the machine's by the rotations no reading sees, and
//! `n . (e(B) - e(A))` changes under a turn `w` by `n . (w x (e(B) - e(A)))`: with errors of a
//! millimetre and a turn of half a milliradian, half a micrometre. Seen on the independent
//! simulator's tracer campaigns at thirty times the usual errors (300 um positioning, 240 urad
//! rotations; seeds 821-840): the body diagonals' deviations by the first-order projection were
//! up to 11.6 standard uncertainties from the truth's (38 of 1 800 targets beyond 3), quadratic
//! in the errors' size and there without noise too; by the aligned beam 3.3 (5 of 1 800), RMS of
//! z 1.19 -> 0.94. At the usual magnitudes the two differ by nanometres.

use crate::axis::{Axis, Travel};
use crate::model::ErrorModel;
use faer::Mat;
use nalgebra::{Point3, Vector3};

/// A straight measuring line in machine coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    /// Display name, e.g. `X` or `PPP`.
    pub name: String,
    /// Where the interferometer is zeroed.
    pub start: Point3<f64>,
    pub end: Point3<f64>,
}

impl Line {
    pub fn length(&self) -> f64 {
        (self.end - self.start).norm()
    }

    /// Unit direction from start to end.
    pub fn direction(&self) -> Vector3<f64> {
        (self.end - self.start) / self.length()
    }

    /// Indicated position at distance `s` from the start.
    pub fn at(&self, s: f64) -> Point3<f64> {
        self.start + self.direction() * s
    }

    /// `n >= 2` equally spaced target distances from the start to the end, both included.
    pub fn targets(&self, n: usize) -> Vec<f64> {
        let n = n.max(2);
        (0..n).map(|i| self.length() * i as f64 / (n - 1) as f64).collect()
    }
}

/// The line along `axis` through `start` (clamped into the travel), from `start` to the end of
/// the axis's travel farther from it. The paper's Table 3 gives such starts: X and Y from
/// (0, 0, -700) mm, Z from (0, -500, -700) mm.
pub fn axis_line(travel: &Travel, axis: Axis, start: &Point3<f64>) -> Line {
    let mut a = *start;
    for k in Axis::ALL {
        let [lo, hi] = travel.range(k);
        a[k.index()] = a[k.index()].clamp(lo, hi);
    }
    let [lo, hi] = travel.range(axis);
    let q = a[axis.index()];
    let mut b = a;
    b[axis.index()] = if (hi - q).abs() >= (q - lo).abs() { hi } else { lo };
    Line { name: axis.letter().to_string(), start: a, end: b }
}

/// The default start of an axis line: the lower end of the axis, the other axes at the centre
/// of their travel (where ISO 230-2 measures unless told otherwise).
pub fn default_axis_start(travel: &Travel, axis: Axis) -> Point3<f64> {
    let mut c = travel.centre();
    c[axis.index()] = travel.range(axis)[0];
    c
}

/// The four body diagonals of the working volume as in the paper's Table 4, whose travel is
/// X [0, 700], Y [-500, 0], Z [-700, 0] mm: NPP from (700, -500, -700) to (0, 0, 0), NPN from
/// (0, 0, -700) to (700, -500, 0), PPN from (700, 0, -700) to (0, -500, 0), PPP from
/// (0, -500, -700) to (700, 0, 0). Each starts at the bottom of Z and ends at the opposite
/// corner; for another travel the same corners (lower or upper end of each axis) are taken.
pub fn body_diagonals(travel: &Travel) -> [Line; 4] {
    // Start corner per diagonal: false = lower end, true = upper end of X, Y, Z.
    const STARTS: [(&str, [bool; 3]); 4] = [
        ("NPP", [true, false, false]),
        ("NPN", [false, true, false]),
        ("PPN", [true, true, false]),
        ("PPP", [false, false, false]),
    ];
    STARTS.map(|(name, hi)| {
        let corner = |flags: [bool; 3]| Point3::from(Vector3::from_fn(|k, _| travel.ranges[k][usize::from(flags[k])]));
        Line { name: name.to_string(), start: corner(hi), end: corner(hi.map(|h| !h)) }
    })
}

/// Predicted positioning deviation at one target of a line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositioningPoint {
    /// Target distance from the start, metres.
    pub s_m: f64,
    /// Indicated position of the target.
    pub x: Point3<f64>,
    /// `n' . (P(X_s) - P(A)) - s` with the beam `n'` through `P(A)` and `P(B)` (the module's
    /// doc), to first order `n . (e(X_s, p) - e(A, p))`, metres.
    pub deviation_m: f64,
    /// Standard uncertainty of the deviation (from the model covariance), metres; infinite
    /// where the data do not determine the deviation.
    pub sigma_m: f64,
    /// The target or the line's start lies between the measured positions of an axis the
    /// readings resolve only there (a tracer's stops): the deviation is interpolated, under the
    /// smoothness the readings showed elsewhere ([`crate::predict::PointError::interpolated`]).
    pub interpolated: bool,
}

/// Predicts the positioning deviations of `line` at the `targets` (distances from the start)
/// for probe offset `p`, as an interferometer aligned with the reflector's motion reads them
/// (the module's doc): exact kinematic chain for the value, small-angle sensitivity for the
/// uncertainty (`g^T C g` with `g = n'^T (G(X_s) - G(A)) + w_s^T (G(B) - G(A))`, where
/// `w_s = (I - n' n'^T) (P(X_s) - P(A)) / |P(B) - P(A)|` is how the beam's alignment moves the
/// reading), infinite where `g` depends on the directions the data leave undetermined or the
/// target or the start lies where the readings contradict the interpolation between measured
/// positions.
pub fn predict_positioning(
    model: &ErrorModel,
    unc: &crate::predict::Uncertainty<'_>,
    line: &Line,
    p: &Vector3<f64>,
    targets: &[f64],
) -> Vec<PositioningPoint> {
    let n = line.direction();
    let actual = |y: &Point3<f64>| model.exact_position(y, p);
    let (p_start, p_end) = (actual(&line.start), actual(&line.end));
    let beam = p_end - p_start;
    let n_beam = beam / beam.norm();
    let sens_start = model.layout.sensitivity(&line.start, p);
    let sens_end = model.layout.sensitivity(&line.end, p);
    let n_params = model.layout.n_params;
    let cov = unc.covariance;
    let with_cov = cov.nrows() == n_params && cov.ncols() == n_params;
    let start_open = unc.leaves_open_at(&line.start);
    let start_scale = unc.interpolation_scale_at(&line.start);
    // The share of a touched start's own readings (`crate::predict::with_own_readings`).
    let start_share = unc.touched_share_at(&line.start);
    // The interpolation's shape along the line at a point
    // ([`crate::predict::interpolation_shape_covariance`]) as the standard uncertainty of its
    // bound. At the target and at the start the two bounds are not independent (the same
    // curve, perhaps the same interval): the deviation's bound is their sum, `(a + b)^2` in
    // variance, which holds whatever their signs.
    let shape = |y: &Point3<f64>| {
        crate::predict::interpolation_shape_variance_along(model, unc.resolution, y, p, &n).max(0.0).sqrt()
    };
    let start_shape = if with_cov && !start_open { shape(&line.start) } else { 0.0 };
    targets
        .iter()
        .map(|&s| {
            let x = line.at(s);
            let scale_at = unc.interpolation_scale_at(&x);
            let along = actual(&x) - p_start;
            let dev = n_beam.dot(&along) - s;
            // The beam's turn with the line's end: what the reading at `x` is across the beam.
            let w = (along - n_beam * n_beam.dot(&along)) / beam.norm();
            let mut g: Vec<(usize, f64)> = model.layout.sensitivity(&x, p).project(&n_beam).collect();
            g.extend(sens_start.project(&(n_beam + w)).map(|(k, v)| (k, -v)));
            g.extend(sens_end.project(&w));
            let determined = unc.share(std::iter::once(g.as_slice())) <= crate::predict::NOT_DETERMINED_ABOVE
                && !start_open
                && !unc.leaves_open_at(&x);
            let sigma_m = match (determined, with_cov) {
                (false, _) => f64::INFINITY,
                (true, false) => 0.0,
                (true, true) => {
                    let scale = start_scale.unwrap_or(1.0).max(scale_at.unwrap_or(1.0));
                    let (base, bound) = (quadratic_form(cov, &g) * scale, (shape(&x) + start_shape).powi(2));
                    // The smaller of the target's and the start's, where either is touched; none
                    // (share 0) elsewhere.
                    let share = [unc.touched_share_at(&x), start_share].into_iter().flatten().reduce(f64::min);
                    crate::predict::with_own_readings(base, bound, share.unwrap_or(0.0)).max(0.0).sqrt()
                }
            };
            PositioningPoint { s_m: s, x, deviation_m: dev, sigma_m, interpolated: start_scale.or(scale_at).is_some() }
        })
        .collect()
}

/// `g^T C g` for a sparse `g` given as (index, value) pairs (indices may repeat).
fn quadratic_form(cov: &Mat<f64>, g: &[(usize, f64)]) -> f64 {
    let mut v = 0.0;
    for &(i, gi) in g {
        for &(j, gj) in g {
            v += gi * gj * cov[(i, j)];
        }
    }
    v
}

/// One target of a prediction-versus-measurement comparison.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ComparedPoint {
    pub s_m: f64,
    pub predicted_m: f64,
    /// Infinite where the data do not determine the prediction ([`PositioningPoint::sigma_m`]).
    pub predicted_sigma_m: f64,
    pub measured_m: f64,
    pub measured_sigma_m: f64,
    /// Predicted minus measured.
    pub difference_m: f64,
    /// Normalised error `|difference| / (k sqrt(u_pred^2 + u_meas^2))` with k = 2: at most 1
    /// when the two agree within their expanded uncertainties. `None` where the data do not
    /// determine the prediction: an infinite uncertainty would make any difference look like
    /// agreement.
    pub en: Option<f64>,
}

impl ComparedPoint {
    /// Whether the data determine the prediction at this target, so that its difference from
    /// the measurement is a test of the model.
    pub fn is_determined(&self) -> bool {
        self.predicted_sigma_m.is_finite()
    }
}

/// Prediction versus measurement along one line.
#[derive(Clone, Debug, PartialEq)]
pub struct LineComparison {
    pub line: Line,
    pub points: Vec<ComparedPoint>,
    /// Targets where the data determine the prediction ([`ComparedPoint::is_determined`]); the
    /// predicted figures below are over those alone.
    pub determined: usize,
    /// Largest |predicted - measured|, metres (the paper's "maximum difference"); `None` when
    /// no target is determined.
    pub max_abs_difference_m: Option<f64>,
    /// ISO 230-2 positioning error of the line (range of the mean deviations), predicted; over
    /// the determined targets, `None` when fewer than two are.
    pub predicted_range_m: Option<f64>,
    /// The same from the measurement, over every target.
    pub measured_range_m: f64,
    /// Largest normalised error over the determined targets.
    pub max_en: Option<f64>,
}

/// Range (max - min) of `v`; `None` with fewer than two values, which span no range (the
/// start alone, where the interferometer is zeroed, says nothing of a line's positioning).
pub fn range(v: impl Iterator<Item = f64>) -> Option<f64> {
    let (n, lo, hi) =
        v.fold((0usize, f64::INFINITY, f64::NEG_INFINITY), |(n, lo, hi), x| (n + 1, lo.min(x), hi.max(x)));
    (n >= 2).then_some(hi - lo)
}

/// Compares predicted deviations with measured mean deviations and their standard
/// uncertainties (same targets, same order). Targets whose prediction the data do not
/// determine are kept with their measurement but left out of the predicted figures: their
/// value is the minimum-norm one, no prediction.
pub fn compare(line: &Line, predicted: &[PositioningPoint], measured: &[(f64, f64)]) -> LineComparison {
    assert_eq!(predicted.len(), measured.len(), "prediction and measurement must have the same targets");
    let points: Vec<ComparedPoint> = predicted
        .iter()
        .zip(measured)
        .map(|(p, &(m, um))| {
            let d = p.deviation_m - m;
            let u = (p.sigma_m.powi(2) + um.powi(2)).sqrt();
            let en = p.sigma_m.is_finite().then(|| {
                if u > 0.0 {
                    d.abs() / (crate::predict::COVERAGE_K * u)
                } else {
                    f64::INFINITY
                }
            });
            ComparedPoint {
                s_m: p.s_m,
                predicted_m: p.deviation_m,
                predicted_sigma_m: p.sigma_m,
                measured_m: m,
                measured_sigma_m: um,
                difference_m: d,
                en,
            }
        })
        .collect();
    let determined = || points.iter().filter(|c| c.is_determined());
    LineComparison {
        line: line.clone(),
        determined: determined().count(),
        max_abs_difference_m: determined().map(|c| c.difference_m.abs()).reduce(f64::max),
        predicted_range_m: range(determined().map(|c| c.predicted_m)),
        measured_range_m: range(points.iter().map(|c| c.measured_m)).unwrap_or(0.0),
        max_en: determined().filter_map(|c| c.en).reduce(f64::max),
        points,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::functions::ErrorFunction;
    use crate::model::ModelLayout;
    use crate::repr::Representation;
    use crate::topology::Topology;

    fn paper_travel() -> Travel {
        Travel::new([0.0, 0.7], [-0.5, 0.0], [-0.7, 0.0])
    }

    #[test]
    fn diagonals_are_those_of_table_4() {
        let d = body_diagonals(&paper_travel());
        let mm = |p: Point3<f64>| (p * 1e3).map(|v| v.round() as i64);
        let expect = [
            ("NPP", [700, -500, -700], [0, 0, 0]),
            ("NPN", [0, 0, -700], [700, -500, 0]),
            ("PPN", [700, 0, -700], [0, -500, 0]),
            ("PPP", [0, -500, -700], [700, 0, 0]),
        ];
        for (line, (name, a, b)) in d.iter().zip(expect) {
            assert_eq!(line.name, name);
            assert_eq!(mm(line.start), Point3::from(a), "{name}");
            assert_eq!(mm(line.end), Point3::from(b), "{name}");
        }
    }

    #[test]
    fn axis_lines_of_table_3_run_over_the_whole_travel() {
        let t = paper_travel();
        let x = axis_line(&t, Axis::X, &Point3::new(0.0, 0.0, -0.7));
        assert_eq!((x.start, x.end), (Point3::new(0.0, 0.0, -0.7), Point3::new(0.7, 0.0, -0.7)));
        let y = axis_line(&t, Axis::Y, &Point3::new(0.0, 0.0, -0.7));
        assert_eq!(y.end, Point3::new(0.0, -0.5, -0.7));
        let z = axis_line(&t, Axis::Z, &Point3::new(0.0, -0.5, -0.7));
        assert_eq!(z.end, Point3::new(0.0, -0.5, 0.0));
        assert_eq!(x.targets(11).len(), 11);
        assert!((x.targets(11)[10] - 0.7).abs() < 1e-15);
    }

    /// Along an X line at y = z = 0 with zero probe offset, only EXX moves the reflector along
    /// X (the lever arm of X's rotations is (0, 0, z) = 0): the predicted deviation is EXX(x) -
    /// EXX(0), and its variance is that of this difference. The straightness EYX, a slope of 5
    /// urad, turns the reflector's path and the beam aligned with it alike: it adds only the
    /// cosine term `(5 urad)^2 x / 2`, as it would to an interferometer's reading.
    #[test]
    fn deviation_along_x_is_the_positioning_error() {
        let layout = ModelLayout::uniform(
            Topology::parse("FYXZ").unwrap(),
            paper_travel(),
            Representation::Polynomial { degree: 3 },
        );
        let mut m = ErrorModel::zero(layout.clone());
        let exx = ErrorFunction::parse("EXX").unwrap();
        m.set_function(exx, |x| 20e-6 * x * x);
        m.set_function(ErrorFunction::parse("EYX").unwrap(), |x| 5e-6 * x);
        let n = layout.n_params;
        let cov = Mat::<f64>::from_fn(n, n, |i, j| if i == j { 1e-14 } else { 0.0 });
        let line = axis_line(&layout.travel, Axis::X, &Point3::new(0.0, 0.0, 0.0));
        let pts = predict_positioning(
            &m,
            &crate::predict::Uncertainty::determined(&cov),
            &line,
            &Vector3::zeros(),
            &line.targets(8),
        );
        let b = layout.basis(exx);
        let r = layout.range(exx);
        for p in &pts {
            let x = p.x.x;
            assert!((p.deviation_m - (20e-6 * x * x + 0.5 * 25e-12 * x)).abs() < 1e-15, "{}", p.deviation_m);
            let g: Vec<f64> = (0..b.n_coeffs())
                .map(|k| {
                    let at = |q: f64| b.eval(q).iter().filter(|(i, _)| *i == k).map(|(_, v)| v).sum::<f64>();
                    at(x) - at(0.0)
                })
                .collect();
            let var: f64 = g.iter().map(|v| v * v * cov[(r.start, r.start)]).sum();
            assert!((p.sigma_m - var.sqrt()).abs() < 1e-15, "{} vs {}", p.sigma_m, var.sqrt());
        }
        let c = compare(&line, &pts, &pts.iter().map(|p| (p.deviation_m + 1e-6, 0.0)).collect::<Vec<_>>());
        assert!((c.max_abs_difference_m.unwrap() - 1e-6).abs() < 1e-15);
        assert!((c.predicted_range_m.unwrap() - (20e-6 * 0.49 + 0.5 * 25e-12 * 0.7)).abs() < 1e-15);
        assert_eq!(c.determined, pts.len());
    }

    /// A target whose prediction the data do not determine keeps its measurement but gives no
    /// difference, normalised error or predicted range: its minimum-norm value is no prediction,
    /// and its infinite uncertainty would pass any difference as agreement (En near 0).
    #[test]
    fn undetermined_targets_are_left_out_of_the_predicted_figures() {
        let line = Line { name: "X".into(), start: Point3::origin(), end: Point3::new(0.3, 0.0, 0.0) };
        let at = |s_m: f64, deviation_m: f64, sigma_m: f64| PositioningPoint {
            s_m,
            x: Point3::new(s_m, 0.0, 0.0),
            deviation_m,
            sigma_m,
            interpolated: false,
        };
        let pts = [at(0.0, 0.0, 0.0), at(0.1, 2e-6, 1e-7), at(0.2, 5e-3, f64::INFINITY), at(0.3, -1e-6, 1e-7)];
        let measured = [(0.0, 1e-8), (2.1e-6, 1e-8), (3e-6, 1e-8), (-1e-6, 1e-8)];
        let c = compare(&line, &pts, &measured);
        assert_eq!(c.determined, 3);
        assert_eq!(c.points[2].en, None);
        assert!(!c.points[2].is_determined());
        assert!((c.predicted_range_m.unwrap() - 3e-6).abs() < 1e-15, "{:?}", c.predicted_range_m);
        assert!((c.max_abs_difference_m.unwrap() - 1e-7).abs() < 1e-15, "{:?}", c.max_abs_difference_m);
        assert!((c.measured_range_m - 4e-6).abs() < 1e-15);
        assert!(c.max_en.unwrap() > 0.0 && c.max_en.unwrap().is_finite());

        let none = [at(0.0, 1.0, f64::INFINITY), at(0.3, -1.0, f64::INFINITY)];
        let c = compare(&line, &none, &measured[..2]);
        assert_eq!((c.determined, c.predicted_range_m, c.max_abs_difference_m, c.max_en), (0, None, None, None));
        // The start alone spans no range.
        let c = compare(&line, &[at(0.0, 0.0, 0.0), at(0.3, -1.0, f64::INFINITY)], &measured[..2]);
        assert_eq!((c.determined, c.predicted_range_m), (1, None));
    }
}
