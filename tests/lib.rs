//! Shared helpers for the workspace-level integration tests.

use std::path::PathBuf;

/// Root of the repository.
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// The Python interpreter of the pinned checker venv (`.venv`, made by `.ci/run`), or `None`
/// with a message. Under `VOLCAL_REQUIRE_PY` (set by CI) a missing venv is a test failure.
pub fn checker_python() -> Option<PathBuf> {
    let py = repo_root().join(".venv/bin/python");
    if py.exists() {
        return Some(py);
    }
    if std::env::var_os("VOLCAL_REQUIRE_PY").is_some() {
        panic!("the Python checker venv {} is missing (run .ci/run, or python3 -m venv .venv && .venv/bin/pip install -r .ci/requirements.txt)", py.display());
    }
    eprintln!("skipping: no Python checker venv at {} (create it with .ci/run)", py.display());
    None
}

/// A fresh scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volcal-test-{}-{}", name, std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

use faer::linalg::solvers::Solve;
use nalgebra::{Point3, Vector3};
use volcal::{gauge, predict, ErrorModel, Gauge};

/// Distance between an estimate and the truth after removing the gauge freedom: the truth is
/// moved along the 24 gauge freedoms (first onto the estimate's gauge, then by Gauss-Newton
/// with exact kinematics) to minimise the volumetric difference over a grid and the probe
/// offsets. Returns `(max, rms)` of the remaining difference in metres.
pub fn gauge_distance(
    est: &ErrorModel,
    truth: &ErrorModel,
    g: Gauge,
    offsets: &[Vector3<f64>],
    step: f64,
) -> (f64, f64) {
    let layout = &est.layout;
    let nb = gauge::null_basis(layout);
    let k = nb.ncols();
    let mut u = gauge::align(layout, g, &truth.u);
    let pts: Vec<Point3<f64>> = predict::grid(&layout.travel, step);
    let diff = |u: &[f64]| -> Vec<f64> {
        let m = ErrorModel { layout: layout.clone(), u: u.to_vec() };
        let mut d = Vec::with_capacity(pts.len() * offsets.len() * 3);
        for x in &pts {
            for p in offsets {
                let e = est.error(x, p) - m.error(x, p);
                d.extend_from_slice(e.as_slice());
            }
        }
        d
    };
    for _ in 0..4 {
        // Jacobian of the model's volumetric error along each gauge freedom (small-angle).
        let mut jt_j = faer::Mat::<f64>::zeros(k, k);
        let mut jt_r = faer::Mat::<f64>::zeros(k, 1);
        let r = diff(&u);
        let mut row = 0;
        for x in &pts {
            for p in offsets {
                let s = layout.sensitivity(x, p);
                let cols: Vec<Vector3<f64>> =
                    (0..k).map(|c| s.idx.iter().zip(&s.dedu).map(|(&i, d)| d * nb[(i, c)]).sum()).collect();
                for a in 0..k {
                    for b in 0..k {
                        jt_j[(a, b)] += cols[a].dot(&cols[b]);
                    }
                    jt_r[(a, 0)] += cols[a].dot(&Vector3::new(r[row], r[row + 1], r[row + 2]));
                }
                row += 3;
            }
        }
        // Some freedoms are invisible in volumetric errors too (e.g. constant rotation errors
        // with zero probe offset): a tiny ridge keeps the normal matrix invertible.
        let ridge = (0..k).map(|i| jt_j[(i, i)]).fold(0.0, f64::max) * 1e-12;
        for i in 0..k {
            jt_j[(i, i)] += ridge;
        }
        jt_j.partial_piv_lu().solve_in_place(jt_r.as_mut());
        for c in 0..k {
            for i in 0..u.len() {
                u[i] += nb[(i, c)] * jt_r[(c, 0)];
            }
        }
    }
    let d = diff(&u);
    let n = d.len() / 3;
    let mut max: f64 = 0.0;
    let mut s2 = 0.0;
    for c in d.chunks(3) {
        let v = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        max = max.max(v);
        s2 += v * v;
    }
    (max, (s2 / n as f64).sqrt())
}
pub mod auto_study;
pub mod diagnosis;
pub mod truth_families;

/// `y` less its least-squares straight line in `s` (how ISO 230-1 evaluates a straightness).
pub fn detrended(s: &[f64], y: &[f64]) -> Vec<f64> {
    let n = s.len().max(1) as f64;
    let (ms, my) = (s.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxx: f64 = s.iter().map(|v| (v - ms).powi(2)).sum();
    let sxy: f64 = s.iter().zip(y).map(|(a, b)| (a - ms) * (b - my)).sum();
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    s.iter().zip(y).map(|(a, b)| b - my - slope * (a - ms)).collect()
}

/// A volumetric error field after removing the best-fitting rigid-body motion `t + w x X`: what
/// remains of it in the machine's own frame, where a rigid motion of the whole volume is not an
/// error (it is the gauge freedom of the identification seen at one tool point). Returns
/// `(max, rms)` of the remaining vectors' lengths, metres.
pub fn rigid_aligned(points: &[Point3<f64>], errors: &[Vector3<f64>]) -> (f64, f64) {
    // Least squares in (t, w): e ~ t + w x X = t - [X]x w, rows of 3 per point.
    let c = points.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / points.len().max(1) as f64;
    let a = nalgebra::DMatrix::<f64>::from_fn(3 * points.len(), 6, |r, k| {
        let x = points[r / 3].coords - c;
        let i = r % 3;
        if k < 3 {
            return if i == k { 1.0 } else { 0.0 };
        }
        // Column k-3 of -[x]x: the derivative of (w x x)_i by w_(k-3).
        let mut w = Vector3::zeros();
        w[k - 3] = 1.0;
        w.cross(&x)[i]
    });
    let b = nalgebra::DVector::<f64>::from_iterator(3 * errors.len(), errors.iter().flat_map(|e| [e.x, e.y, e.z]));
    let sol = a.clone().svd(true, true).solve(&b, 1e-15).expect("SVD with both factors");
    let r = b - a * sol;
    let lengths: Vec<f64> = r.as_slice().chunks(3).map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()).collect();
    let max = lengths.iter().cloned().fold(0.0, f64::max);
    (max, (lengths.iter().map(|v| v * v).sum::<f64>() / lengths.len().max(1) as f64).sqrt())
}
