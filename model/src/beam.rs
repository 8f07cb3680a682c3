//! Per-beam geometry of the fixed-beam method: barycentre and least-squares line of the points
//! (patent claim 1 and eq. 2).

use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};

/// What a fixed beam is aligned with, which the readings themselves cannot tell: the two differ
/// only by the cosine of the angle between the commanded line and the reflector's actual motion
/// (second order in the machine's errors), as a beam scale that the model's own positioning
/// errors absorb (`crate::alignment`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum BeamAlignment {
    /// Along the reflector's actual motion: the patent's procedure (the machine moves the
    /// reflector along the beam), or an operator who aligned the beam with the line's motion.
    /// The beam is the least-squares line of the actual reflector points.
    #[default]
    Motion,
    /// Along the commanded line: the machine runs its commanded straight line and the beam was
    /// pointed along it (e.g. by a deflector set from the machine's coordinates), so the
    /// reflector drifts across the beam with the machine's errors. The beam is the
    /// least-squares line of the commanded reflector points.
    ///
    /// Commanded in the model's frame, which the gauge fixes ([`crate::gauge`]; with the
    /// patent's, X along X's mean motion and Y in the plane of X's and Y's mean motions, the
    /// squareness errors explicit). Beams set along the axes of some other reference (a
    /// granite's edges, a frame the errors were drawn in) are neither this nor `Motion`: each
    /// beam's cosine error then depends on that reference's turn from the model's frame, which
    /// no reading of the beams sees, and at large errors a tracer in the same campaign
    /// contradicts the beams' scale (README, "On data we did not simulate").
    Commanded,
}

impl BeamAlignment {
    /// Its name in machine files and reports.
    pub fn name(self) -> &'static str {
        match self {
            BeamAlignment::Motion => "motion",
            BeamAlignment::Commanded => "commanded",
        }
    }
}

/// Least-squares line through a set of points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineFit {
    /// Barycentre of the points.
    pub centroid: Point3<f64>,
    /// Unit direction (principal axis of the scatter), sign arbitrary.
    pub direction: Vector3<f64>,
    /// RMS distance of the points from the line.
    pub lateral_rms: f64,
}

/// The points of a line's segments, each segment about its own barycentre: readings of
/// different segments have different origins, so only their spread fixes the line's direction.
pub fn centred_segments(segments: &[Vec<Point3<f64>>]) -> Vec<Point3<f64>> {
    segments
        .iter()
        .flat_map(|s| {
            let c = s.iter().map(|q| q.coords).sum::<Vector3<f64>>() / s.len().max(1) as f64;
            s.iter().map(move |q| Point3::from(q.coords - c))
        })
        .collect()
}

/// Fits a line to points by the principal axis of their scatter matrix.
pub fn fit_line(points: &[Point3<f64>]) -> LineFit {
    let n = points.len().max(1) as f64;
    let centroid = Point3::from(points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n);
    let mut s = Matrix3::zeros();
    for p in points {
        let d = p - centroid;
        s += d * d.transpose();
    }
    let eig = SymmetricEigen::new(s);
    let (imax, _) = eig.eigenvalues.argmax();
    let direction = eig.eigenvectors.column(imax).into_owned().normalize();
    // Computed directly, not as a difference of eigenvalues, which would cancel.
    let lateral: f64 = points
        .iter()
        .map(|p| {
            let d = p - centroid;
            (d - direction * d.dot(&direction)).norm_squared()
        })
        .sum();
    LineFit { centroid, direction, lateral_rms: (lateral / n).sqrt() }
}

/// Orients `direction` so that the readings `l` increase along it for the points `points`.
pub fn orient_with_readings(direction: Vector3<f64>, points: &[Point3<f64>], l: &[f64]) -> Vector3<f64> {
    let n = points.len().max(1) as f64;
    let c = points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n;
    let lm = l.iter().sum::<f64>() / n;
    let cov: f64 = points.iter().zip(l).map(|(p, li)| (p.coords - c).dot(&direction) * (li - lm)).sum();
    if cov < 0.0 {
        -direction
    } else {
        direction
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_a_line() {
        let d = Vector3::new(1.0, 2.0, -0.5).normalize();
        let pts: Vec<Point3<f64>> = (0..10).map(|i| Point3::new(0.1, 0.2, 0.3) + d * (i as f64 * 0.05)).collect();
        let f = fit_line(&pts);
        assert!((f.direction.dot(&d).abs() - 1.0).abs() < 1e-12);
        assert!(f.lateral_rms < 1e-9);
        let l: Vec<f64> = (0..10).map(|i| -(i as f64)).collect();
        assert!(orient_with_readings(d, &pts, &l).dot(&d) < 0.0);
    }
}
