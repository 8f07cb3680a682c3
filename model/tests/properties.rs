//! Property tests of the error model (issue 2, acceptance 3).

use nalgebra::{Point3, Vector3};
use proptest::prelude::*;
use volcal::functions::{ErrorFunction, Motion, Squareness};
use volcal::{gauge, Axis, ErrorModel, ModelLayout, Representation, Topology, Travel};

fn travel() -> Travel {
    Travel::new([0.0, 1.0], [-0.5, 0.3], [-0.7, 0.0])
}

fn layout(topo: &str, repr: Representation) -> ModelLayout {
    ModelLayout::uniform(Topology::parse(topo).unwrap(), travel(), repr)
}

fn topologies() -> impl Strategy<Value = &'static str> {
    prop::sample::select(vec!["FXYZ", "FYXZ", "XFYZ", "YFXZ", "XYFZ", "FZXY"])
}

fn representations() -> impl Strategy<Value = Representation> {
    prop::sample::select(vec![
        Representation::BSpline { intervals: 6 },
        Representation::Table { nodes: 5 },
        Representation::Polynomial { degree: 4 },
        Representation::Harmonic { harmonics: 2, period_m: None },
    ])
}

/// A random model with coefficients of magnitude `scale` (metres or radians).
fn random_model(l: ModelLayout, coeffs: &[f64], scale: f64) -> ErrorModel {
    let n = l.n_params;
    ErrorModel { layout: l, u: (0..n).map(|i| scale * coeffs[i % coeffs.len()]).collect() }
}

fn point_in_travel(f: [f64; 3]) -> Point3<f64> {
    let t = travel();
    Point3::new(
        t.ranges[0][0] + f[0] * t.length(Axis::X),
        t.ranges[1][0] + f[1] * t.length(Axis::Y),
        t.ranges[2][0] + f[2] * t.length(Axis::Z),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// The readings of a beam (the projections of the actual points on the beam direction,
    /// relative to their barycentre) do not change when the model moves along any of the 24
    /// gauge freedoms: the patent's eq. (2) cannot see them.
    #[test]
    fn beam_readings_are_invariant_under_gauge_transformations(
        topo in topologies(),
        repr in representations(),
        coeffs in prop::collection::vec(-1.0f64..1.0, 40),
        gauge_amp in prop::collection::vec(-1.0f64..1.0, 24),
        dir in prop::array::uniform3(-1.0f64..1.0),
        start in prop::array::uniform3(0.2f64..0.8),
        p in prop::array::uniform3(-0.2f64..0.2),
    ) {
        let l = layout(topo, repr);
        let m = random_model(l.clone(), &coeffs, 1e-5);
        let nb = gauge::null_basis(&l);
        let mut g = m.clone();
        for (c, a) in gauge_amp.iter().enumerate() {
            for i in 0..l.n_params {
                g.u[i] += 1e-5 * a * nb[(i, c)];
            }
        }
        let n = Vector3::from(dir).try_normalize(1e-3).unwrap_or(Vector3::z());
        let p = Vector3::from(p);
        // Points of the reflector along a line of direction n, indicated coordinates inside the travel.
        let x0 = point_in_travel(start);
        let xs: Vec<Point3<f64>> = (0..12).map(|i| x0 + n * (0.02 * i as f64 - 0.1)).collect();
        let read = |m: &ErrorModel| -> Vec<f64> {
            let r: Vec<f64> = xs.iter().map(|x| n.dot(&(x.coords + p + m.error_linear(x, &p)))).collect();
            let mean = r.iter().sum::<f64>() / r.len() as f64;
            r.iter().map(|v| v - mean).collect()
        };
        let (a, b) = (read(&m), read(&g));
        for (u, v) in a.iter().zip(&b) {
            prop_assert!((u - v).abs() < 1e-15, "{topo} {repr:?}: {u} vs {v}");
        }
    }

    /// The small-angle model equals the homogeneous-transform chain to second order: the
    /// difference scales with the square of the error magnitude.
    #[test]
    fn small_angle_model_equals_transform_chain_to_second_order(
        topo in topologies(),
        repr in representations(),
        coeffs in prop::collection::vec(-1.0f64..1.0, 40),
        x in prop::array::uniform3(0.0f64..1.0),
        p in prop::array::uniform3(-0.2f64..0.2),
    ) {
        let x = point_in_travel(x);
        let p = Vector3::from(p);
        let diff = |eps: f64| {
            let m = random_model(layout(topo, repr), &coeffs, eps);
            (m.error(&x, &p) - m.error_linear(&x, &p)).norm()
        };
        let (d1, d2) = (diff(1e-4), diff(5e-5));
        // Second order: at most (error magnitude)^2 times the reach (about 1.5 m here) times the
        // number of interacting terms; and halving the errors quarters the difference.
        prop_assert!(d1 < 200.0 * 1e-8 * 1.5, "{topo}: {d1}");
        if d1 > 1e-13 {
            let ratio = d1 / d2;
            prop_assert!((3.5..4.5).contains(&ratio), "{topo}: halving the errors divides the difference by {ratio}");
        }
    }
}

/// The patent's literal eq. (4)-(7) for FXYZ:
/// `e = t_x + t_y + t_z + r_x ^ h_x + r_y ^ h_y + r_z ^ h_z`,
/// `h_x = (0, y, z) + p`, `h_y = (0, 0, z) + p`, `h_z = p`.
#[test]
fn fxyz_matches_the_patent_literally() {
    let l = layout("FXYZ", Representation::BSpline { intervals: 7 });
    let coeffs: Vec<f64> = (0..l.n_params).map(|i| ((i * 37 % 19) as f64 - 9.0) / 9.0).collect();
    let mut m = random_model(l, &coeffs, 2e-5);
    for s in Squareness::ALL {
        m.set_squareness(s, 0.0); // the patent's model carries squareness in the straightness slopes
    }
    let vec_of = |axis: Axis, motion: Motion, q: f64| -> Vector3<f64> {
        Vector3::from_fn(|c, _| m.function_value(ErrorFunction { axis, motion, component: Axis::from_index(c) }, q))
    };
    for k in 0..50 {
        let x = point_in_travel([(k as f64 * 0.137) % 1.0, (k as f64 * 0.291) % 1.0, (k as f64 * 0.533) % 1.0]);
        let p = Vector3::new(0.1 * ((k % 3) as f64 - 1.0), 0.05 * ((k % 5) as f64 - 2.0), -0.1);
        let (tx, ty, tz) = (
            vec_of(Axis::X, Motion::Translation, x.x),
            vec_of(Axis::Y, Motion::Translation, x.y),
            vec_of(Axis::Z, Motion::Translation, x.z),
        );
        let (rx, ry, rz) = (
            vec_of(Axis::X, Motion::Rotation, x.x),
            vec_of(Axis::Y, Motion::Rotation, x.y),
            vec_of(Axis::Z, Motion::Rotation, x.z),
        );
        let hx = Vector3::new(0.0, x.y, x.z) + p;
        let hy = Vector3::new(0.0, 0.0, x.z) + p;
        let hz = p;
        let literal = tx + ty + tz + rx.cross(&hx) + ry.cross(&hy) + rz.cross(&hz);
        let ours = m.error_linear(&x, &p);
        assert!((literal - ours).norm() < 1e-18, "{literal:?} vs {ours:?}");
    }
}

/// The paper's eq. (1) for FYXZ with zero probe offset, term by term: rotations of Y act on X
/// and Z, rotations of X on Z, rotations of Z on nothing.
#[test]
fn fyxz_matches_the_paper_equation() {
    let l = layout("FYXZ", Representation::Polynomial { degree: 3 });
    let coeffs: Vec<f64> = (0..l.n_params).map(|i| ((i * 13 % 11) as f64 - 5.0) / 5.0).collect();
    let m = random_model(l, &coeffs, 1e-5);
    let f = |name: &str, q: f64| m.function_value(ErrorFunction::parse(name).unwrap(), q);
    let x = Point3::new(0.4, -0.2, -0.3);
    let (xx, yy, zz) = (x.x, x.y, x.z);
    let p = Vector3::zeros();
    let sq = |s: Squareness| m.squareness(s);
    // Paper eq. (1) with our squareness conventions (Y relative to X, Z relative to X and Y).
    let dx =
        f("EXX", xx) + f("EXY", yy) + f("EXZ", zz) + zz * (f("EBX", xx) + f("EBY", yy)) + zz * sq(Squareness::EB0Z)
            - yy * sq(Squareness::EC0Y);
    let dy = f("EYX", xx) + f("EYY", yy) + f("EYZ", zz) - zz * (f("EAX", xx) + f("EAY", yy)) + xx * f("ECY", yy)
        - zz * sq(Squareness::EA0Z);
    let dz = f("EZX", xx) + f("EZY", yy) + f("EZZ", zz) - xx * f("EBY", yy);
    let e = m.error_linear(&x, &p);
    assert!((e - Vector3::new(dx, dy, dz)).norm() < 1e-18, "{e:?} vs ({dx}, {dy}, {dz})");
}
