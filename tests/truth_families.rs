//! Truths outside every representation volcal fits, and the oracle that knows each truth's own
//! basis (issue 12).
//!
//! A truth family draws, per error function, a shape from a family of functions (Legendre
//! polynomials with long sinusoids; a C1 piecewise cubic with a local Gaussian bump; the
//! paper's linear tables) and keeps the family's basis. The simulated machine carries the
//! truth as a fine table (0.5 mm nodes: a piecewise-linear interpolant within 0.2 nm of the
//! shapes), so no solver representation contains it exactly.
//!
//! The oracle is the estimator volcal would be if it knew that basis: the model's constants and
//! slopes (a degree-1 polynomial per function, which carries the gauge), plus the family's other
//! basis functions as linear [`Effect`] parameters, each made free of the gauge's functionals
//! (zero mean and mean slope for the patent gauge, zero at both ends for the datum gauge), so
//! that the oracle's estimate lies in the same gauge as every other estimate and as the aligned
//! truth. Its map error is what the readings allow when the representation is perfect: the
//! information limit against which `representation: auto` is measured.
//!
//! That oracle is told more than the family: where each bump lies, how wide it is, where the
//! piecewise cubic's breakpoints are, a sinusoid's period. [`Oracle::located`] is told the
//! family only and must find those places from the readings: nonlinear least squares in the
//! family, linearised at the truth (the derivatives of each drawn shape with respect to its
//! features' places as further parameters), so its map error is, to first order, the least
//! that an estimator not told where the features lie can reach (the Cramer-Rao bound of the
//! family with those places unknown). It separates what `auto` loses to not knowing the
//! places, which no estimator can avoid, from what it loses to its own representation.

use nalgebra::{Point3, Vector3};
use rand::Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::sync::Arc;
use volcal::estimator::{Effect, ObsContext};
use volcal::functions::{ErrorFunction, Motion, Squareness};
use volcal::gauge::{axis_far_end, axis_origin};
use volcal::repr::gauss_legendre;
use volcal::{ErrorModel, Gauge, ModelLayout, Representation, Topology, Travel};

/// A basis function of one error function's own family, over the axis coordinate (metres).
pub type Shape = Arc<dyn Fn(f64) -> f64 + Send + Sync>;

/// The truth families of issue 12.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// Legendre polynomial of degree 3 plus one or two sinusoids of period 0.5 to 2 travels.
    PolySine,
    /// C1 piecewise cubic through 4 breakpoints (2 random inside) plus a Gaussian bump of
    /// width 3 to 6 % of the travel.
    PiecewiseBump,
    /// The paper's tables (Han et al. 2021, Table 2 ranges): 11-node linear tables.
    PaperTables,
}

impl Family {
    pub fn name(self) -> &'static str {
        match self {
            Family::PolySine => "polynomial + long sinusoids",
            Family::PiecewiseBump => "piecewise with a local bump",
            Family::PaperTables => "the paper's linear tables",
        }
    }
}

/// Amplitudes (largest excursion): volcal_sim's default truth (positioning 15 um, straightness
/// 5 um, rotations 10 urad, squareness up to 30 urad).
fn amplitude(f: ErrorFunction) -> f64 {
    match f.motion {
        Motion::Translation if f.is_positioning() => 15e-6,
        Motion::Translation => 5e-6,
        Motion::Rotation => 10e-6,
    }
}

/// A drawn truth: the simulated machine's model (a fine table) and, per function, the family
/// basis beyond constants and slopes (for the oracle).
pub struct FamilyTruth {
    pub family: Family,
    pub model: ErrorModel,
    pub basis: Vec<(ErrorFunction, Vec<Shape>)>,
    /// Per function, the derivatives of its drawn shape with respect to where its features lie
    /// (a bump's centre and width, the breakpoints of a piecewise cubic, a sinusoid's period):
    /// with them beside [`FamilyTruth::basis`], the oracle is the estimator that knows the
    /// family but must find its features from the readings, linearised at the truth
    /// ([`Oracle::located`]). An empty list per function for the paper's tables, whose nodes are
    /// the table's.
    pub located: Vec<(ErrorFunction, Vec<Shape>)>,
}

impl FamilyTruth {
    /// Whether the family has places to find ([`FamilyTruth::located`]): where it has none,
    /// the located oracle is the oracle.
    pub fn has_places(&self) -> bool {
        self.located.iter().any(|(_, m)| !m.is_empty())
    }
}

/// Node count of the fine truth tables: 0.5 mm spacing.
fn fine_nodes(lo: f64, hi: f64) -> usize {
    ((hi - lo) / 0.5e-3).round() as usize + 1
}

/// Legendre polynomial `P_k` on `[lo, hi]`.
fn legendre(k: usize, lo: f64, hi: f64) -> Shape {
    Arc::new(move |q| {
        let s = (2.0 * q - lo - hi) / (hi - lo);
        let (mut p0, mut p1) = (1.0, s);
        if k == 0 {
            return 1.0;
        }
        for j in 1..k {
            let jf = j as f64;
            let p2 = ((2.0 * jf + 1.0) * s * p1 - jf * p0) / (jf + 1.0);
            p0 = p1;
            p1 = p2;
        }
        p1
    })
}

/// Cubic Hermite basis on breakpoints `b` (sorted, ends included): value and slope at each.
fn hermite_basis(b: &[f64]) -> Vec<Shape> {
    let mut out: Vec<Shape> = Vec::new();
    for i in 0..b.len() {
        for slope in [false, true] {
            let b = b.to_vec();
            out.push(Arc::new(move |q| {
                // The piece containing q, and which end of it node i is.
                let k = b.windows(2).position(|w| q <= w[1]).unwrap_or(b.len() - 2);
                let (a, c) = (b[k], b[k + 1]);
                let h = c - a;
                let t = ((q - a) / h).clamp(0.0, 1.0);
                let (h00, h10, h01, h11) = (
                    2.0 * t.powi(3) - 3.0 * t * t + 1.0,
                    t.powi(3) - 2.0 * t * t + t,
                    -2.0 * t.powi(3) + 3.0 * t * t,
                    t.powi(3) - t * t,
                );
                match (i == k, i == k + 1, slope) {
                    (true, _, false) => h00,
                    (true, _, true) => h10 * h,
                    (_, true, false) => h01,
                    (_, true, true) => h11 * h,
                    _ => 0.0,
                }
            }));
        }
    }
    out
}

/// Hat function of node `i` of an `n`-node table on `[lo, hi]`.
fn hat(i: usize, n: usize, lo: f64, hi: f64) -> Shape {
    let h = (hi - lo) / (n - 1) as f64;
    let c = lo + i as f64 * h;
    Arc::new(move |q| (1.0 - ((q - c) / h).abs()).max(0.0))
}

/// Draws a truth of `family` for `topology`/`travel` from `seed` (the paper's tables ignore
/// both: they are the paper's machine).
pub fn draw(family: Family, topology: &Topology, travel: Travel, seed: u64) -> FamilyTruth {
    if family == Family::PaperTables {
        let model = volcal_sim::paper::truth();
        let n = volcal_sim::paper::TABLE_NODES;
        let basis = ErrorFunction::all()
            .iter()
            .map(|&f| {
                let [lo, hi] = model.layout.travel.range(f.axis);
                (f, (0..n).map(|i| hat(i, n, lo, hi)).collect())
            })
            .collect();
        let located = ErrorFunction::all().iter().map(|&f| (f, Vec::new())).collect();
        return FamilyTruth { family, model, basis, located };
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4641_4d49_4c59);
    let reprs: [Representation; 18] = std::array::from_fn(|i| {
        let [lo, hi] = travel.range(ErrorFunction::from_index(i).axis);
        Representation::Table { nodes: fine_nodes(lo, hi) }
    });
    let mut model = ErrorModel::zero(ModelLayout::new(topology.clone(), travel, reprs));
    let mut basis = Vec::new();
    let mut located = Vec::new();
    for f in ErrorFunction::all() {
        let [lo, hi] = travel.range(f.axis);
        let len = hi - lo;
        let mut shapes: Vec<Shape> = Vec::new();
        let mut coeffs: Vec<f64> = Vec::new();
        let mut moves: Vec<Shape> = Vec::new();
        let normal = |rng: &mut ChaCha8Rng| -> f64 { StandardNormal.sample(rng) };
        match family {
            Family::PolySine => {
                for k in 1..=3 {
                    shapes.push(legendre(k, lo, hi));
                    coeffs.push(normal(&mut rng) / k as f64);
                }
                let n_sines = 1 + rng.random::<bool>() as usize;
                for _ in 0..n_sines {
                    let period = len * (0.5 + 1.5 * rng.random::<f64>());
                    let w = 2.0 * std::f64::consts::PI / period;
                    shapes.push(Arc::new(move |q| (w * (q - lo)).sin()));
                    shapes.push(Arc::new(move |q| (w * (q - lo)).cos()));
                    let (a, b) = (0.5 * normal(&mut rng), 0.5 * normal(&mut rng));
                    coeffs.push(a);
                    coeffs.push(b);
                    // d/dw of a sin(w (q - lo)) + b cos(w (q - lo)): the period.
                    moves.push(Arc::new(move |q| (q - lo) * (a * (w * (q - lo)).cos() - b * (w * (q - lo)).sin())));
                }
            }
            Family::PiecewiseBump => {
                let b = [
                    lo,
                    lo + len * (0.25 + 0.2 * rng.random::<f64>()),
                    lo + len * (0.55 + 0.2 * rng.random::<f64>()),
                    hi,
                ];
                shapes.extend(hermite_basis(&b));
                for _ in 0..b.len() {
                    // Value, then slope (about one amplitude over the travel).
                    coeffs.push(normal(&mut rng));
                    coeffs.push(1.5 * normal(&mut rng) / len);
                }
                let centre = lo + len * (0.15 + 0.7 * rng.random::<f64>());
                let width = len * (0.03 + 0.03 * rng.random::<f64>());
                let gauss = move |q: f64| (-0.5 * ((q - centre) / width).powi(2)).exp();
                shapes.push(Arc::new(gauss));
                let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
                coeffs.push(sign * 0.6);
                // The bump's centre and width, and the two inner breakpoints with the values
                // and slopes there held (central differences of the Hermite interpolant).
                moves.push(Arc::new(move |q| gauss(q) * (q - centre) / (width * width)));
                moves.push(Arc::new(move |q| gauss(q) * (q - centre).powi(2) / width.powi(3)));
                let hermite: Vec<f64> = coeffs[..2 * b.len()].to_vec();
                let d = 1e-6 * len;
                for k in 1..b.len() - 1 {
                    let (mut up, mut down) = (b, b);
                    up[k] += d;
                    down[k] -= d;
                    let (hu, hd) = (hermite_basis(&up), hermite_basis(&down));
                    let c = hermite.clone();
                    moves.push(Arc::new(move |q| {
                        hu.iter().zip(hd.iter()).zip(&c).map(|((u, v), c)| c * (u(q) - v(q))).sum::<f64>() / (2.0 * d)
                    }));
                }
            }
            Family::PaperTables => unreachable!(),
        }
        let shape = |q: f64| shapes.iter().zip(&coeffs).map(|(s, c)| c * s(q)).sum::<f64>();
        // Scale the largest excursion from the mean to the function's amplitude.
        let samples: Vec<f64> = (0..=400).map(|i| shape(lo + len * i as f64 / 400.0)).collect();
        let mean = samples.iter().sum::<f64>() / samples.len() as f64;
        let peak = samples.iter().map(|v| (v - mean).abs()).fold(0.0, f64::max).max(1e-12);
        let scale = amplitude(f) / peak;
        let nodes = model.layout.basis(f).n_coeffs();
        let c = model.coeffs_mut(f);
        for (i, ci) in c.iter_mut().enumerate() {
            *ci = scale * shape(lo + len * i as f64 / (nodes - 1) as f64);
        }
        basis.push((f, shapes));
        located.push((f, moves));
    }
    for s in Squareness::ALL {
        let v: f64 = StandardNormal.sample(&mut rng);
        model.set_squareness(s, 30e-6 * v.clamp(-2.0, 2.0) / 2.0);
    }
    FamilyTruth { family, model, basis, located }
}

/// `phi` minus the straight line that makes it invisible to `gauge`'s functionals on
/// `[lo, hi]`: zero mean and least-squares slope (patent), zero at the axis origin and far end
/// (datum). The span of the line and `phi` is unchanged.
fn gauge_free(phi: &Shape, gauge: Gauge, lo: f64, hi: f64, origin: f64, far: f64) -> Shape {
    let phi = phi.clone();
    let (a, b) = match gauge {
        Gauge::Patent => {
            let (x, w) = gauss_legendre(64);
            let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo));
            let (mut m0, mut m1, mut s2) = (0.0, 0.0, 0.0);
            for (xi, wi) in x.iter().zip(&w) {
                let q = mid + half * xi;
                let v = phi(q) * wi * half;
                m0 += v;
                m1 += v * (q - mid);
                s2 += wi * half * (q - mid).powi(2);
            }
            let b = m1 / s2;
            (m0 / (hi - lo) - b * mid, b)
        }
        Gauge::Datum => {
            let (po, pf) = (phi(origin), phi(far));
            let b = (pf - po) / (far - origin);
            (po - b * origin, b)
        }
    };
    Arc::new(move |q| phi(q) - a - b * q)
}

/// The oracle's extra parameters: each family basis function that is not a constant or a
/// slope, made gauge-free, as a linear effect on the readings.
pub struct Oracle {
    topology: Topology,
    terms: Vec<(ErrorFunction, Shape)>,
}

impl Oracle {
    /// The oracle for `truth` in `gauge` on `layout`'s travel.
    pub fn new(truth: &FamilyTruth, gauge: Gauge, layout: &ModelLayout) -> Oracle {
        Oracle::of(&truth.basis, gauge, layout)
    }

    /// The oracle that knows the truth's family but not where its features lie: the family's
    /// basis and the derivatives of the drawn shapes with respect to their features' places
    /// ([`FamilyTruth::located`]), i.e. nonlinear least squares in the family linearised at
    /// the truth. Its error is the information limit (to first order, the Cramer-Rao bound) of an
    /// estimator that is told the shape of the truth but must find its bump and breakpoints.
    pub fn located(truth: &FamilyTruth, gauge: Gauge, layout: &ModelLayout) -> Oracle {
        let both: Vec<(ErrorFunction, Vec<Shape>)> = truth
            .basis
            .iter()
            .zip(&truth.located)
            .map(|((f, s), (_, m))| (*f, s.iter().chain(m).cloned().collect()))
            .collect();
        Oracle::of(&both, gauge, layout)
    }

    fn of(basis: &[(ErrorFunction, Vec<Shape>)], gauge: Gauge, layout: &ModelLayout) -> Oracle {
        let mut terms = Vec::new();
        for (f, shapes) in basis {
            let [lo, hi] = layout.travel.range(f.axis);
            let (origin, far) = (axis_origin(layout, *f), axis_far_end(layout, *f));
            for s in shapes {
                let g = gauge_free(s, gauge, lo, hi, origin, far);
                // Shapes that are lines (Legendre P1, slope-like Hermite combinations) leave
                // nothing once the line is removed: they live in the model's own slopes.
                let norm = (0..=200).map(|i| g(lo + (hi - lo) * i as f64 / 200.0).abs()).fold(0.0, f64::max);
                if norm > 1e-9 * (0..=200).map(|i| s(lo + (hi - lo) * i as f64 / 200.0).abs()).fold(0.0, f64::max) {
                    terms.push((*f, g));
                }
            }
        }
        Oracle { topology: layout.topology.clone(), terms }
    }

    /// The layout the oracle fits beside its terms: constants and slopes (degree 1).
    pub fn layout(topology: Topology, travel: Travel) -> ModelLayout {
        ModelLayout::uniform(topology, travel, Representation::Polynomial { degree: 1 })
    }

    /// Direction in which function `f`'s unit value moves the reflector at `(x, p)`.
    fn direction(&self, f: ErrorFunction, x: &Point3<f64>, p: &Vector3<f64>) -> Vector3<f64> {
        match f.motion {
            Motion::Translation => f.component.unit(),
            Motion::Rotation => f.component.unit().cross(&self.topology.lever_arm(f.axis, x, p)),
        }
    }

    /// The oracle's volumetric error: its degree-1 model's exact error plus its terms.
    pub fn error(&self, model: &ErrorModel, coeffs: &[f64], x: &Point3<f64>, p: &Vector3<f64>) -> Vector3<f64> {
        let mut e = model.error(x, p);
        for ((f, g), c) in self.terms.iter().zip(coeffs) {
            e += self.direction(*f, x, p) * (c * g(f.axis.coord(x)));
        }
        e
    }
}

impl Effect for Oracle {
    fn id(&self) -> &str {
        "oracle"
    }

    fn param_names(&self) -> Vec<String> {
        self.terms.iter().enumerate().map(|(k, (f, _))| format!("{}_{k}", f.name())).collect()
    }

    fn regressors(&self, ctx: &ObsContext<'_>, out: &mut [f64]) {
        let (x, p) = (ctx.obs.x[ctx.i], ctx.obs.p[ctx.i]);
        for (k, (f, g)) in self.terms.iter().enumerate() {
            out[k] = ctx.direction.dot(&self.direction(*f, &x, &p)) * g(f.axis.coord(&x));
        }
    }
}
