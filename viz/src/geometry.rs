//! Small geometric reductions for display: where a device station stands (the point its
//! beams converge to), how far a fitted line extends, and the abscissa along a line.
//! Display only: nothing here feeds the estimator.

use nalgebra::{Matrix3, Point3, Vector3};
use volcal::campaign::{LineGroup, Observations};

/// Least-squares point closest to a set of lines (point, unit direction): the device
/// position of a fixed-beam station, which the campaign file does not record. `None` when the
/// lines are (nearly) parallel.
pub fn convergence_point(lines: &[(Point3<f64>, Vector3<f64>)]) -> Option<Point3<f64>> {
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for (c, d) in lines {
        let n = d.try_normalize(0.0)?;
        let proj = Matrix3::identity() - n * n.transpose();
        a += proj;
        b += proj * c.coords;
    }
    let eig = a.symmetric_eigen();
    if lines.len() < 2 || eig.eigenvalues.min() < 1e-6 * eig.eigenvalues.max().max(1e-300) {
        return None;
    }
    a.lu().solve(&b).map(Point3::from)
}

/// End points of a fitted line through `centroid` along `direction`, spanning the projections
/// of `points`.
pub fn line_extent(points: &[Point3<f64>], centroid: &Point3<f64>, direction: &Vector3<f64>) -> [Point3<f64>; 2] {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in points {
        let s = direction.dot(&(p - centroid));
        lo = lo.min(s);
        hi = hi.max(s);
    }
    if !lo.is_finite() {
        return [*centroid, *centroid];
    }
    [centroid + direction * lo, centroid + direction * hi]
}

/// Indicated reflector positions `X + p` of a group's readings.
pub fn reflector_points(obs: &Observations, g: &LineGroup) -> Vec<Point3<f64>> {
    g.range().map(|i| obs.x[i] + obs.p[i]).collect()
}

/// Abscissa of each reading of a group, metres from the line's start: the interferometer (or
/// tracer) reading minus its smallest value along the line, so that beams and tracer paths
/// share one axis (a tracer path's residuals then show any dependence on range).
pub fn abscissa_m(obs: &Observations, g: &LineGroup) -> Vec<f64> {
    let l = &obs.l[g.range()];
    let lo = l.iter().copied().fold(f64::INFINITY, f64::min);
    l.iter().map(|v| v - lo).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beams_from_one_pivot_converge_on_it() {
        let pivot = Point3::new(0.3, -0.2, 0.1);
        let dirs = [Vector3::new(1.0, 0.0, 0.2), Vector3::new(0.1, 1.0, 0.3), Vector3::new(-0.4, 0.5, 1.0)];
        let lines: Vec<_> = dirs
            .iter()
            .enumerate()
            .map(|(k, d)| {
                let d = d.normalize();
                (pivot + d * (0.2 + 0.3 * k as f64), d)
            })
            .collect();
        let p = convergence_point(&lines).unwrap();
        assert!((p - pivot).norm() < 1e-12, "{p}");
        assert!(convergence_point(&lines[..1]).is_none(), "one line has no convergence point");
        let parallel = [(Point3::origin(), Vector3::x()), (Point3::new(0.0, 1.0, 0.0), Vector3::x())];
        assert!(convergence_point(&parallel).is_none());
    }

    #[test]
    fn extent_spans_the_projected_points() {
        let pts = [Point3::new(1.0, 0.1, 0.0), Point3::new(3.0, -0.1, 0.0), Point3::new(2.0, 0.0, 0.0)];
        let [a, b] = line_extent(&pts, &Point3::new(2.0, 0.0, 0.0), &Vector3::x());
        assert_eq!((a.x, b.x), (1.0, 3.0));
    }
}
