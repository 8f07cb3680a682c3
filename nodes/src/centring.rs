//! Keeping the reflector on the beam: the patent's photoreceiver feedback, done by the
//! sequencer from the return-signal strength, and the prediction of the next point along the
//! beam from the points already centred ("the machine follows the beam").
//!
//! The return signal of a retroreflector displaced laterally by `d` from a Gaussian beam falls
//! as `exp(-k d^2)`: its logarithm is a parabola in each lateral direction, so three readings
//! (at `-h`, `0`, `+h`) give the centre exactly for an ideal beam, and to within the signal noise
//! otherwise.

use nalgebra::{Point3, Vector3};

/// Smallest signal used in logarithms (a lost beam reads 0).
const FLOOR: f64 = 1e-9;

/// Offset of the signal maximum from the middle reading, given the signals at `-h`, `0`, `+h`:
/// the vertex of the parabola through their logarithms. `None` when the three do not bracket
/// a maximum (not concave): the caller searches wider.
pub fn vertex(s_minus: f64, s0: f64, s_plus: f64, h: f64) -> Option<f64> {
    let (fm, f0, fp) = (s_minus.max(FLOOR).ln(), s0.max(FLOOR).ln(), s_plus.max(FLOOR).ln());
    let curvature = 2.0 * f0 - fp - fm;
    if curvature <= 1e-12 {
        return None;
    }
    Some((h * (fp - fm) / (2.0 * curvature)).clamp(-2.0 * h, 2.0 * h))
}

/// Two unit vectors perpendicular to `dir` and to each other.
pub fn lateral_basis(dir: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let d = dir.normalize();
    let helper = if d.z.abs() < 0.9 { Vector3::z() } else { Vector3::x() };
    let u = d.cross(&helper).normalize();
    let v = d.cross(&u);
    (u, v)
}

/// The indicated positions of the points acquired so far along one beam, and the least-squares
/// line through them as a function of the nominal abscissa, to predict where the next point is.
#[derive(Clone, Debug)]
pub struct LineFollower {
    direction: Vector3<f64>,
    points: Vec<(f64, Point3<f64>)>,
}

impl LineFollower {
    /// `direction`: the commanded beam direction (used until two points are known).
    pub fn new(direction: Vector3<f64>) -> LineFollower {
        LineFollower { direction: direction.normalize(), points: Vec::new() }
    }

    pub fn add(&mut self, abscissa: f64, indicated: Point3<f64>) {
        self.points.push((abscissa, indicated));
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Predicted indicated position at nominal abscissa `s`; `None` before the first point.
    pub fn predict(&self, s: f64) -> Option<Point3<f64>> {
        match self.points.len() {
            0 => None,
            1 => {
                let (s0, x0) = self.points[0];
                Some(x0 + self.direction * (s - s0))
            }
            n => {
                // x(s) = a + b s by least squares, per coordinate.
                let sm = self.points.iter().map(|p| p.0).sum::<f64>() / n as f64;
                let xm = self.points.iter().fold(Vector3::zeros(), |acc, p| acc + p.1.coords) / n as f64;
                let mut sxx = 0.0;
                let mut sxy = Vector3::zeros();
                for (si, xi) in &self.points {
                    sxx += (si - sm) * (si - sm);
                    sxy += (xi.coords - xm) * (si - sm);
                }
                if sxx <= 1e-18 {
                    return Some(Point3::from(xm + self.direction * (s - sm)));
                }
                Some(Point3::from(xm + sxy / sxx * (s - sm)))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertex_finds_the_gaussian_centre() {
        let w = 2e-3;
        let signal = |d: f64| (-4.0 * d * d / (w * w)).exp();
        for centre in [-0.6e-3, -0.1e-3, 0.0, 0.05e-3, 0.7e-3] {
            let h = 0.4e-3;
            let x = vertex(signal(-h - centre), signal(-centre), signal(h - centre), h).unwrap();
            assert!((x - centre).abs() < 1e-12, "{x} vs {centre}");
        }
        // Flat or convex readings do not bracket a maximum.
        assert!(vertex(0.5, 0.5, 0.5, 1e-3).is_none());
        assert!(vertex(0.9, 0.1, 0.9, 1e-3).is_none());
    }

    #[test]
    fn basis_is_orthonormal() {
        for d in [Vector3::x(), Vector3::z(), Vector3::new(0.3, -0.2, 0.9)] {
            let (u, v) = lateral_basis(&d);
            let d = d.normalize();
            assert!(u.dot(&d).abs() < 1e-12 && v.dot(&d).abs() < 1e-12 && u.dot(&v).abs() < 1e-12);
            assert!((u.norm() - 1.0).abs() < 1e-12 && (v.norm() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn follower_extrapolates_the_fitted_line() {
        let dir = Vector3::new(0.0, 0.6, 0.8);
        let mut f = LineFollower::new(dir);
        assert!(f.predict(0.1).is_none());
        let a = Point3::new(0.1, 0.2, -0.5);
        // The actual line is tilted by 1e-4 rad from the commanded direction.
        let actual = (dir + Vector3::new(1e-4, 0.0, 0.0)).normalize();
        f.add(0.2, a);
        let p1 = f.predict(0.3).unwrap();
        assert!((p1 - (a + dir * 0.1)).norm() < 1e-15);
        f.add(0.3, a + actual * 0.1);
        f.add(0.4, a + actual * 0.2);
        let p = f.predict(0.9).unwrap();
        assert!((p - (a + actual * 0.7)).norm() < 1e-12);
    }
}
