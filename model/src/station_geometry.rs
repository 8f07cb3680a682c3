//! Geometry of the tracer stations, for the identifiability report.
//!
//! Multilateration locates a point from its ranges to several stations whose positions and dead
//! paths are themselves unknown (paper eq. 4-5). The paper asks for m >= 4 stations that are not
//! coplanar: with fewer, each point is not located with redundancy; with coplanar stations,
//! every station sees a point in their common plane from within that plane, so no range depends
//! (to first order) on the point's error normal to the plane. The rigid-body error model ties
//! the points together, so such geometry weakens the estimate rather than always breaking it;
//! whether it breaks it is decided by the identifiability analysis from the data. This module
//! only names the geometry so that the report can say why.

use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};

/// Minimum number of stations of the tracer method.
pub const MIN_STATIONS: usize = 4;
/// Stations count as coplanar when their largest distance from the best-fit plane is below
/// this fraction of their largest in-plane extent.
pub const COPLANAR_FRACTION: f64 = 0.01;
/// A reading lies "in the stations' plane" when it is closer to it than this fraction of the
/// stations' extent.
pub const IN_PLANE_FRACTION: f64 = 1e-3;

/// The tracer stations' geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct StationGeometry {
    pub n_stations: usize,
    /// Largest distance of a station from the best-fit plane through all of them, metres.
    pub out_of_plane_m: f64,
    /// Largest distance between two stations, metres.
    pub extent_m: f64,
    /// Normal of the best-fit plane (meaningful with 3 or more stations).
    pub normal: Vector3<f64>,
    pub coplanar: bool,
    /// Readings closer to the stations' plane than [`IN_PLANE_FRACTION`] of the extent.
    pub readings_in_plane: usize,
    pub n_readings: usize,
}

impl StationGeometry {
    /// Plain statements for the report (empty when the geometry is as the method requires).
    pub fn statements(&self) -> Vec<String> {
        let mut st = Vec::new();
        if self.n_stations == 0 {
            return st;
        }
        if self.n_stations < MIN_STATIONS {
            st.push(format!(
                "Only {} tracer station(s): the tracer method needs at least {MIN_STATIONS}, not coplanar (Han et al. 2021, section 2), to locate every point of the path with redundancy while solving for the stations' positions and dead paths. Only the rigid-body error model ties the points together here; the statements above say what these data still determine, the predicted uncertainty how well.",
                self.n_stations
            ));
        } else if self.coplanar {
            let n = self.normal;
            let mut s = format!(
                "The {} tracer stations are coplanar (largest distance from their common plane {:.1} mm over an extent of {:.0} mm; plane normal ({:.2}, {:.2}, {:.2})): the tracer method needs stations that are not coplanar (Han et al. 2021, section 2).",
                self.n_stations,
                self.out_of_plane_m * 1e3,
                self.extent_m * 1e3,
                n.x,
                n.y,
                n.z
            );
            if self.readings_in_plane > 0 {
                s.push_str(&format!(
                    " {} of {} readings lie in that plane, where no range sees the error component normal to it: errors there are determined only through the rigid-body model, if at all.",
                    self.readings_in_plane, self.n_readings
                ));
            } else {
                s.push_str(" No reading lies in that plane, so every point is still seen from out of plane; the estimate is weaker, not undetermined, as the analysis above shows.");
            }
            st.push(s);
        }
        st
    }
}

/// Assesses the stations (current positions) and the reflector points they measured.
pub fn assess(stations: &[Point3<f64>], points: &[Point3<f64>]) -> StationGeometry {
    let n = stations.len();
    let mut g = StationGeometry {
        n_stations: n,
        out_of_plane_m: 0.0,
        extent_m: 0.0,
        normal: Vector3::z(),
        coplanar: n < MIN_STATIONS,
        readings_in_plane: 0,
        n_readings: points.len(),
    };
    if n == 0 {
        return g;
    }
    for a in stations {
        for b in stations {
            g.extent_m = g.extent_m.max((a - b).norm());
        }
    }
    if n < 3 {
        return g;
    }
    let c = Point3::from(stations.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n as f64);
    let mut m = Matrix3::zeros();
    for p in stations {
        let d = p - c;
        m += d * d.transpose();
    }
    let eig = SymmetricEigen::new(m);
    let k = eig.eigenvalues.imin();
    g.normal = eig.eigenvectors.column(k).into_owned().normalize();
    if g.normal.iter().map(|v| v.abs()).enumerate().max_by(|a, b| a.1.total_cmp(&b.1)).map(|(i, _)| g.normal[i] < 0.0)
        == Some(true)
    {
        g.normal = -g.normal;
    }
    g.out_of_plane_m = stations.iter().map(|p| (p - c).dot(&g.normal).abs()).fold(0.0, f64::max);
    g.coplanar = n < MIN_STATIONS || g.out_of_plane_m < COPLANAR_FRACTION * g.extent_m;
    if g.coplanar {
        let tol = IN_PLANE_FRACTION * g.extent_m;
        g.readings_in_plane = points.iter().filter(|p| (*p - c).dot(&g.normal).abs() < tol).count();
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recognises_coplanar_stations_and_readings_in_their_plane() {
        let flat = [
            Point3::new(0.0, 0.0, -0.8),
            Point3::new(0.8, 0.0, -0.8),
            Point3::new(0.8, 0.6, -0.8),
            Point3::new(0.0, 0.6, -0.8),
        ];
        let pts = [Point3::new(0.2, 0.2, -0.8), Point3::new(0.2, 0.2, -0.1)];
        let g = assess(&flat, &pts);
        assert!(g.coplanar && g.out_of_plane_m < 1e-12);
        assert!((g.normal - Vector3::z()).norm() < 1e-9);
        assert_eq!(g.readings_in_plane, 1);
        assert!(g.statements()[0].contains("coplanar"));
        let mut raised = flat;
        raised[3].z = -0.6;
        let g = assess(&raised, &pts);
        assert!(!g.coplanar && g.statements().is_empty());
        let g = assess(&raised[..3], &pts);
        assert!(g.statements()[0].starts_with("Only 3 tracer station(s)"));
    }
}
