//! Smoothing: error functions whose flexibility the data choose.
//!
//! A representation fixed in advance is either too stiff for the machine (a bias no
//! uncertainty covers) or too flexible for the campaign (noise fitted as error, and directions
//! the data do not determine). Instead, each penalised function `f` carries the roughness
//! penalty `lambda_f int f'''(q)^2 dq` ([`crate::repr::Basis::roughness`], [`PENALTY_ORDER`]):
//! a Gaussian prior on its roughness, whose strength `lambda_f` is estimated from the readings
//! by restricted maximum likelihood (REML; Wahba 1985, Wood 2011). A function with detail the
//! readings resolve keeps it; one whose detail is noise becomes a parabola. The penalty never
//! acts on constants and slopes, so the gauge and the squareness are untouched.
//!
//! With the smoothing parameters estimated, the posterior covariance `(N + S_lambda)^-1` (on the
//! gauge-constrained subspace) is the uncertainty reported: it includes what the prior leaves
//! open between the readings, which is why it covers the truth where a representation error
//! would otherwise hide (Nychka 1988: across-the-function coverage of the Bayesian intervals).
//! To it is added the uncertainty of the smoothing parameters themselves
//! (`lambda_covariance`), and no function is made stiffer than [`DETAIL_FLOOR`]: both matter
//! where the readings say little about a function's smoothness.
//!
//! REML works on the quadratic model of the fit around the current estimate, in the reduced
//! (gauge-constrained, Jacobi-scaled) coordinates of the estimator: with `M_d` the data's
//! reduced normal matrix, `P_g` each penalty's, `M = M_d + sum lambda_g P_g`,
//!
//! `V(rho) = 1/2 [chi2(beta) + sum lambda_g beta' S_g beta + log|M| - sum r_g log lambda_g]`
//!
//! with `rho = log lambda` and `r_g` the rank of penalty `g` on that subspace, is minimised by
//! Newton's method with exact gradient and Hessian (Wood 2011, appendix), in a few iterations.
//! Where the penalised fit's residuals exceed the stated noise, the noise scale `phi` is
//! profiled out of `V` (`chi2 + pen` divided by `phi`, plus `(n - M_p) log phi`: `Scale`).
//! Functions the data determine only together (e.g. a straightness and a rotation through one
//! probe offset) share one smoothing parameter, since the data cannot tell their curvatures apart.
//! So do the two straightnesses of one plane (`EXY` and `EYX`) where the readings leave them open
//! alike, as beams along that plane's face diagonal do: each function's roughness is then counted
//! relative to its travel, so that the shared parameter is one prior on both
//! ([`Penalty::relative_roughness`], [`ReducedPenalty::alike_where_open`]). With two
//! parameters, each would extrapolate its own function's resolved detail to the combination the
//! readings leave open; on the independent simulator's 45-beam plan that took the map error to
//! 1.32 to 1.41 times the oracle's on two sets of twenty seeds, against 1.05 to 1.08 with one.

use crate::functions::ErrorFunction;
use crate::halves;
use crate::model::ModelLayout;
use faer::linalg::solvers::Solve;
use faer::{Mat, Side};

/// Derivative penalised: the third, `int f'''(q)^2 dq`. Its null space, the quadratics, holds
/// the constants and slopes that carry the gauge and the squareness, and the bow that machine
/// errors commonly have; measured on smooth truths outside the representation (polynomials
/// with long sinusoids, patent plan), the map error is 1.22 times that of an estimator knowing
/// the truth's own basis with this penalty and 1.69 times with the second derivative's. The
/// second derivative's penalty with the quadratics exempted (its Schur complement against them,
/// so that the bow stays free), tried for the paper's linear tables, whose kinks are rougher
/// than this penalty's prior expects, was worse there too (an experiment, not kept; dense beams,
/// seeds 1-20): the tables' map error rose from 1.33 to 1.64 um and actual / predicted from 1.12
/// to 1.46, and on smooth truths (FXYZ) the map error from 1.06 to 1.26 times the oracle's; the
/// two together (`int f''^2 + h^2 int f'''^2`, `h` the knot spacing) gave 1.48 um, 1.30 and 1.16.
/// Over a local bump (a C1 piecewise cubic, whose curvature jumps at its breakpoints, so that
/// `int f'''^2` of the truth is unbounded) the second derivative's penalty does only a little
/// better: dense FXYZ beams, seeds 1-20, 1.63 times the oracle's map error (1.65 with the
/// quadratics exempted) instead of 1.74. Nor does a prior on the jumps of the third derivative
/// between neighbouring knot intervals (differences of the rows of
/// [`crate::repr::Basis::interval_roughness_rows`]: a piecewise cubic with few breaks is then
/// smooth, a cubic free), alone or reweighted twice from the fit towards few jumps (an
/// experiment, not kept): dense FXYZ beams over a bump, seeds 1-5, 1.517 times the oracle's map
/// error became 1.566 and 1.560, where the local weights of [`PIECES`]' doc gave 1.390 (two
/// reweighted fits, floor the mean; 1.397 and 1.443 with floors 0.1 and 0.01 of it, actual /
/// predicted 0.94, 1.03, 1.15) at three to five times the solve time. The oracle told the
/// family but not where its bump and breakpoints lie is 1.243 times the oracle there
/// (`Oracle::located` in the tests; docs/representation-auto.md).
///
/// The bow stays free. A second derivative's penalty beside this one, whether with a fixed
/// share (`int f'''^2 + (pi^2 / L^2) int f''^2`) or with a smoothing parameter of its own that
/// REML estimates, puts the bow under the prior (an experiment, stop 58, not kept). On the
/// independent simulator's beams, the face diagonals' long wave, which the readings leave open,
/// was then stated as 0.84 to 0.88 um for errors of 2.26 to 2.32 um (largest |z| 12.5), where the
/// free bow states 1.75 um for 2.12 um (docs/representation-auto.md, "The bow under a penalty").
///
/// Nor a smoother prior: the fourth derivative's (the squared jumps of `f'''` between knot
/// intervals over `h`, cubics free; an experiment, stop 74) brings the independent simulator's
/// tracer at thirty times the errors from 1.59-1.75 to 1.39-1.49 times the Bayes oracle's map
/// error, but takes a tenth of the errors from 1.13-1.15 to 1.16-1.21 and the suite's sparse
/// tracer over a bump from 1.48 to 2.16; REML given both penalties takes the third's smoothing
/// parameter to zero over a bump too, so it cannot choose. Chosen per campaign by the
/// left-out stops' squared deleted residuals it keeps about half the gain (thirty times 1.42 to
/// 1.61) and leaves a tenth of the errors, long length scales and the bump as they were, but one
/// set at ten times got worse (1.42 -> 1.45), for twice the solve (docs/representation-auto.md,
/// "A smoother prior between a tracer's stops").
pub const PENALTY_ORDER: usize = 3;

/// Pieces of each function's travel with a smoothing parameter of their own. The roughness of
/// a cubic B-spline is a sum over its knot intervals
/// ([`crate::repr::Basis::interval_roughness_rows`]) and can be split into runs of consecutive
/// intervals, so that a local feature (a bump of a guideway) gets flexibility where it is. One
/// piece, because more did not pay: with 4, the map error on truths with a local bump was 1.70 to
/// 1.97 times the oracle's instead of 1.72 to 1.85 (3 seeds, dense beams, tracer and joint
/// campaigns), and REML took 3 to 4 times longer (72 smoothing parameters instead of 18).
/// Local weights of the roughness per knot interval from a pilot fit (spatially adaptive
/// smoothing, `w_i = 1 / (local int f'''^2 + floor)` scaled to geometric mean 1, iterated two or
/// three times on the refined axes) were tried too, and not kept: over 5 seeds the map error fell
/// from 1.51 to 1.39 times the oracle's with dense FXYZ beams and from 1.45 to 1.31 with the
/// joint campaign, but rose from 1.80 to 1.88 with dense FYXZ beams, whose uncertainty it then
/// under-stated (actual / predicted 1.24 instead of 1.00): weights chosen from the data make the
/// prior over-confident where the pilot missed detail. Measured again with today's estimator
/// (detail floor of three, noise scale, refinement at p < 1e-3; two reweighted fits after the
/// chosen one, floor the mean local roughness; seeds 1-20), it pays too little for its time:
/// dense beams over a bump 1.74 -> 1.57 (FXYZ) and 1.70 -> 1.60 (FYXZ) times the oracle's map
/// error, actual / predicted 1.00 -> 1.00 and 0.90 -> 0.95, but smooth truths 1.06 -> 1.09
/// (FXYZ dense beams) and each solve 1.6 to 1.75 times longer, beyond the 2x budget; stronger
/// (floor 0.1 of the mean, three fits) 1.54 and 1.61, actual / predicted 1.07 and 1.05.
/// On the refined axes only (the smooth campaigns do not refine, so they and the bench are
/// untouched; stop 53, seeds 1-20), dense beams 1.74 -> 1.57 and 1.70 -> 1.60, but sparse beams
/// over a bump under-stated (actual / predicted 0.99 -> 1.22 and 1.01 -> 1.21, the whole map
/// within its band in 12 and 13 of 20 instead of 20 and 15), and with the local roughness taken
/// as its posterior expectation half of each (docs/representation-auto.md, "What the
/// refinement test tells the prior").
/// Nor did local features found by a scan (an experiment, not kept): per smoothed function a
/// Gaussian bump one and two knot spacings wide at each knot, each tested as a one-parameter
/// extension against the fit with its smoothing held (F-test, Bonferroni at 1 % over the
/// about 900 candidates), a significant one's direction taken out of its function's penalty
/// (`S - S v v' S / v' S v`) and the campaign solved again, three rounds. Over a bump, seeds
/// 1-5, the map error moved by 1 % or less except with FYXZ beams, where it rose (dense 1.741
/// -> 1.881, sparse 1.445 -> 1.569 times the oracle's): the readings often cannot tell a
/// bump in a straightness from one in an angle of the same axis, and the scan frees the wrong
/// one (docs/representation-auto.md, the sparse joint campaign's seed 6092). Freeing the same bump in all six
/// functions of the axis at once (the data then sort out which carries it) gave dense FYXZ
/// 1.637, but sparse FYXZ 1.538 and dense FXYZ 1.547; adding bends (a truncated quadratic at
/// each knot: the curvature jumps of a piecewise cubic) to the candidates, 1.680 and 1.529
/// (1.780 and 1.514 with one function per feature), against 1.24 and 1.25 for the oracle told
/// the truth's shapes but not where they lie (`Oracle::located`).
pub const PIECES: usize = 1;

/// Which functions are smoothed, and whether their smoothing parameters are estimated.
#[derive(Clone, Debug, PartialEq)]
pub struct Smoothing {
    /// Penalised functions (canonical order, [`ErrorFunction::index`]).
    pub penalised: [bool; 18],
    /// Smoothing parameters per function (canonical order) and piece of its travel
    /// ([`PIECES`]): fixed, or where REML starts.
    pub lambda: Option<Vec<Vec<f64>>>,
    /// Whether REML estimates the smoothing parameters.
    pub estimate: bool,
    /// Pairs of functions that an earlier fit of the same readings found open alike (a face
    /// diagonal's two straightnesses, [`ReducedPenalty::alike_where_open`]), to share one
    /// smoothing parameter here too. What a plan leaves open alike is its geometry's, and stays
    /// open on finer knots; but finer knots also leave each function's curvature between the
    /// readings' positions open, function by function, and in that larger null space the pair's
    /// likeness no longer shows (seen: the independent simulator's 45 beams over errors ten
    /// times the usual, refined to the 24 intervals their 27 positions per axis determine).
    pub open_alike: Vec<[ErrorFunction; 2]>,
}

impl Smoothing {
    /// Every function penalised, smoothing estimated by REML.
    pub fn reml() -> Smoothing {
        Smoothing { penalised: [true; 18], lambda: None, estimate: true, open_alike: Vec::new() }
    }

    /// The same penalties with the smoothing parameters fixed at those a solve estimated (so
    /// that refits of the same campaign, e.g. with diagnosis effects, compare like with like).
    pub fn fixed_from(report: &SmoothingReport) -> Smoothing {
        let mut penalised = [false; 18];
        let mut lambda = vec![Vec::new(); 18];
        for f in &report.functions {
            penalised[f.function.index()] = true;
            lambda[f.function.index()] = f.lambda.clone();
        }
        Smoothing { penalised, lambda: Some(lambda), estimate: false, open_alike: report.open_alike.clone() }
    }

    /// The same penalties, REML starting from the parameters a solve estimated (a refit on a
    /// finer layout: the roughness penalty does not depend on the knots, so neither do they).
    pub fn starting_from(report: &SmoothingReport) -> Smoothing {
        Smoothing { estimate: true, ..Smoothing::fixed_from(report) }
    }

    /// These penalties (the same functions penalised), REML starting from the parameters a
    /// solve estimated: the next fit of a layout search, on other knots.
    pub fn continued_from(&self, report: &SmoothingReport) -> Smoothing {
        Smoothing { penalised: self.penalised, ..Smoothing::starting_from(report) }
    }
}

/// How one function was smoothed.
#[derive(Clone, Debug, PartialEq)]
pub struct FunctionSmoothing {
    pub function: ErrorFunction,
    /// Smoothing parameters, one per piece of the travel ([`PIECES`]; one for a basis without
    /// intervals): the weight of `int f'''^2` over the piece against the weighted chi-square.
    pub lambda: Vec<f64>,
    /// Effective number of parameters of the function: its parabola (3) plus the detail the
    /// readings determine (0 to the basis's size minus 3).
    pub edf: f64,
    /// The basis's number of coefficients (the most `edf` could reach).
    pub n_coeffs: usize,
    /// Every smoothing parameter reached its upper bound: the readings show no detail beyond a
    /// parabola.
    pub smoothest: bool,
    /// Functions sharing this smoothing parameter (determined only in combination), names.
    pub shared_with: Vec<String>,
}

/// What the smoothing did in a solve.
#[derive(Clone, Debug, PartialEq)]
pub struct SmoothingReport {
    /// `reml` or `fixed`.
    pub method: String,
    pub functions: Vec<FunctionSmoothing>,
    /// Newton iterations of REML (0 when fixed).
    pub iterations: usize,
    /// Whether REML converged (gradient below tolerance).
    pub converged: bool,
    /// Effective number of model parameters (trace of the influence matrix), for the degrees of
    /// freedom of the residuals.
    pub edf_total: f64,
    /// The variance factor REML took the readings' noise to have, relative to the stated noise:
    /// 1, or more when the penalised fit leaves a misfit the model cannot absorb (see
    /// `Scale`).
    pub noise_scale: f64,
    /// The pairs that share a smoothing parameter because the readings leave them open alike
    /// ([`Smoothing::open_alike`]).
    pub open_alike: Vec<[ErrorFunction; 2]>,
    /// Where the stated uncertainty of what a face diagonal's pair leaves open was raised to the
    /// long waves the readings measure of the pairs' sums ([`crate::open_pairs`]).
    pub open_long_waves: Vec<crate::open_pairs::OpenLongWave>,
}

/// One piece of a penalised function: where its coefficients sit, the roughness matrix of the
/// piece and a factor of it.
#[derive(Clone, Debug)]
pub(crate) struct Block {
    pub function: ErrorFunction,
    /// Which piece of the function's travel.
    pub piece: usize,
    pub offset: usize,
    /// `int b_i''' b_j'''` (k x k).
    pub s: Mat<f64>,
    /// `R` with `R^T R = s` (rank x k).
    pub r: Mat<f64>,
    /// Index of its smoothing parameter.
    pub group: usize,
    /// `s` over the function's own `int f'''^2` (1 unless its group shares a smoothing
    /// parameter across unequal travels, [`Penalty::relative_roughness`]).
    pub weight: f64,
}

/// The penalty `sum_g lambda_g S_g` on the model coefficients.
#[derive(Clone, Debug)]
pub(crate) struct Penalty {
    pub blocks: Vec<Block>,
    /// One smoothing parameter per group.
    pub lambda: Vec<f64>,
    /// Pairs of functions open alike: told by the specification, then those the first REML round
    /// merged ([`Smoothing::open_alike`]).
    pub open_alike: Vec<[ErrorFunction; 2]>,
}

impl Penalty {
    /// Penalty blocks of `spec`'s functions, [`PIECES`] per cubic B-spline (fewer when it has
    /// fewer intervals), one group each; `None` when no penalised function has a roughness
    /// (tables).
    pub fn new(layout: &ModelLayout, spec: &Smoothing) -> Option<Penalty> {
        let mut blocks = Vec::new();
        for f in ErrorFunction::all() {
            if !spec.penalised[f.index()] {
                continue;
            }
            let basis = layout.basis(f);
            let pieces: Vec<Mat<f64>> = match basis.interval_roughness_rows() {
                Some(rows) => {
                    let k = rows.nrows();
                    let m = PIECES.min(k).max(1);
                    (0..m)
                        .map(|j| {
                            let (a, b) = (j * k / m, (j + 1) * k / m);
                            rows.subrows(a, b - a).to_owned()
                        })
                        .collect()
                }
                None => match (basis.kink_rows(), basis.roughness(PENALTY_ORDER)) {
                    (Some(rows), _) => vec![rows],
                    (None, Some(s)) => vec![factor_psd(&s, 1e-10)],
                    (None, None) => continue,
                },
            };
            for (piece, r) in pieces.into_iter().enumerate() {
                if r.nrows() == 0 {
                    continue;
                }
                let s = r.transpose() * &r;
                let group = blocks.len();
                blocks.push(Block { function: f, piece, offset: layout.offsets[f.index()], s, r, group, weight: 1.0 });
            }
        }
        if blocks.is_empty() {
            return None;
        }
        let lambda = match &spec.lambda {
            Some(l) => blocks
                .iter()
                .map(|b| l.get(b.function.index()).and_then(|v| v.get(b.piece).or(v.last())).copied().unwrap_or(0.0))
                .collect(),
            None => vec![0.0; blocks.len()],
        };
        Some(Penalty { blocks, lambda, open_alike: spec.open_alike.clone() })
    }

    pub fn n_groups(&self) -> usize {
        self.lambda.len()
    }

    /// `lambda_g` of a block.
    fn lambda_of(&self, b: &Block) -> f64 {
        self.lambda[b.group]
    }

    /// `u' S_lambda u` and, added to `grad`, `-S_lambda u` (the penalty's part of the estimator's
    /// gradient `J' W r - S u`).
    pub fn apply(&self, u: &[f64], grad: &mut [f64]) -> f64 {
        let mut cost = 0.0;
        for b in &self.blocks {
            let l = self.lambda_of(b);
            let k = b.s.nrows();
            for i in 0..k {
                let si: f64 = (0..k).map(|j| b.s[(i, j)] * u[b.offset + j]).sum();
                grad[b.offset + i] -= l * si;
                cost += l * u[b.offset + i] * si;
            }
        }
        cost
    }

    /// `u' S_g u` per group (unweighted by lambda).
    pub fn energies(&self, u: &[f64]) -> Vec<f64> {
        let mut e = vec![0.0; self.n_groups()];
        for b in &self.blocks {
            let k = b.s.nrows();
            for i in 0..k {
                for j in 0..k {
                    e[b.group] += u[b.offset + i] * b.s[(i, j)] * u[b.offset + j];
                }
            }
        }
        e
    }

    /// Adds `S_lambda`, Jacobi-scaled by `scale`, to the scaled matrix `ns` (n x n).
    pub fn add_scaled(&self, ns: &mut Mat<f64>, scale: &[f64]) {
        for b in &self.blocks {
            let l = self.lambda_of(b);
            let k = b.s.nrows();
            for i in 0..k {
                for j in 0..k {
                    let (gi, gj) = (b.offset + i, b.offset + j);
                    ns[(gi, gj)] += l * b.s[(i, j)] / (scale[gi] * scale[gj]);
                }
            }
        }
    }

    /// Removes the blocks of `functions` (and smoothing parameters left without a block).
    pub fn remove(&mut self, functions: &[ErrorFunction]) {
        if functions.is_empty() {
            return;
        }
        self.blocks.retain(|b| !functions.contains(&b.function));
        let mut used: Vec<usize> = self.blocks.iter().map(|b| b.group).collect();
        used.sort_unstable();
        used.dedup();
        self.lambda = used.iter().map(|&g| self.lambda[g]).collect();
        for b in &mut self.blocks {
            b.group = used.binary_search(&b.group).expect("a used group");
        }
    }

    /// Counts the roughness of the functions of `groups` along their travel relative to its
    /// length (`int (d^3 f / du^3)^2 du`, `u = q / L`, which is `L^5 int f'''^2 dq`), so that
    /// one smoothing parameter shared by functions of unequal travel (a face diagonal's two
    /// straightnesses, [`ReducedPenalty::alike_where_open`]) is the same prior on each: the
    /// same wave over the travel, the same amplitude. Each block is scaled by `(L / L_0)^5`,
    /// `L_0` the travel of the first of `groups`' functions, and its smoothing parameter
    /// converted, so the penalty is unchanged until the groups are merged; the report gives
    /// each function its own `int f'''^2` parameter (`lambda_g` times [`Block::weight`]).
    pub fn relative_roughness(&mut self, groups: &[usize], length: impl Fn(ErrorFunction) -> f64) {
        let Some(first) = self.blocks.iter().find(|b| groups.contains(&b.group)) else { return };
        let l0 = length(first.function);
        let mut done = vec![false; self.n_groups()];
        for b in self.blocks.iter_mut().filter(|b| groups.contains(&b.group)) {
            let w = (length(b.function) / l0).powi(5);
            b.s = &b.s * faer::Scale(w);
            b.r = &b.r * faer::Scale(w.sqrt());
            b.weight *= w;
            if !done[b.group] {
                done[b.group] = true;
                self.lambda[b.group] /= w;
            }
        }
    }

    /// Gives each set of groups connected by `pairs` one smoothing parameter (the geometric mean
    /// of theirs where they have one).
    pub fn merge(&mut self, pairs: &[(usize, usize)]) {
        let ng = self.n_groups();
        let mut parent: Vec<usize> = (0..ng).collect();
        fn root(p: &mut [usize], i: usize) -> usize {
            let mut r = i;
            while p[r] != r {
                r = p[r];
            }
            p[i] = r;
            r
        }
        for &(a, b) in pairs {
            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
            if ra != rb {
                parent[ra.max(rb)] = ra.min(rb);
            }
        }
        let roots: Vec<usize> = (0..ng).map(|g| root(&mut parent, g)).collect();
        let mut new_index = vec![usize::MAX; ng];
        let mut lambda = Vec::new();
        for g in 0..ng {
            if new_index[roots[g]] == usize::MAX {
                new_index[roots[g]] = lambda.len();
                let members: Vec<f64> = (0..ng).filter(|&h| roots[h] == roots[g]).map(|h| self.lambda[h]).collect();
                let l = if members.iter().all(|&l| l > 0.0) {
                    (members.iter().map(|l| l.ln()).sum::<f64>() / members.len() as f64).exp()
                } else {
                    0.0
                };
                lambda.push(l);
            }
        }
        for b in &mut self.blocks {
            b.group = new_index[roots[b.group]];
        }
        self.lambda = lambda;
    }

    /// `R^T / scale` of the blocks selected by `pick` as columns of an `n x rank` matrix.
    fn columns_of(&self, pick: impl Fn(&Block) -> bool, n: usize, scale: &[f64]) -> Mat<f64> {
        let blocks: Vec<&Block> = self.blocks.iter().filter(|b| pick(b)).collect();
        let cols: usize = blocks.iter().map(|b| b.r.nrows()).sum();
        let mut x = Mat::<f64>::zeros(n, cols);
        let mut c0 = 0;
        for b in blocks {
            for r in 0..b.r.nrows() {
                for j in 0..b.r.ncols() {
                    x[(b.offset + j, c0 + r)] = b.r[(r, j)] / scale[b.offset + j];
                }
            }
            c0 += b.r.nrows();
        }
        x
    }

    /// `R_g^T / scale` of every block of group `g` as columns of an `n x rank` matrix (full
    /// parameter space), so that `Z^T` of it is `B_g^T` and `P_g = B_g^T B_g`.
    fn factor_columns(&self, g: usize, n: usize, scale: &[f64]) -> Mat<f64> {
        self.columns_of(|b| b.group == g, n, scale)
    }
}

/// Each block's `Z^T (R^T / scale)` (reduced coordinates through `zt`), with its function.
pub(crate) fn block_columns(
    pen: &Penalty,
    n: usize,
    scale: &[f64],
    zt: impl Fn(&Mat<f64>) -> Mat<f64>,
) -> Vec<(ErrorFunction, Mat<f64>)> {
    (0..pen.blocks.len())
        .map(|k| (pen.blocks[k].function, zt(&pen.columns_of(|o| std::ptr::eq(o, &pen.blocks[k]), n, scale))))
        .collect()
}

/// `R` with `R^T R = s` for a positive semi-definite `s`, dropping its null space (eigenvalues
/// at or below `rel_tol` times the largest).
pub(crate) fn factor_psd(s: &Mat<f64>, rel_tol: f64) -> Mat<f64> {
    let k = s.nrows();
    let Ok(eig) = s.self_adjoint_eigen(Side::Lower) else { return Mat::zeros(0, k) };
    let lam: Vec<f64> = (0..k).map(|i| eig.S().column_vector()[i]).collect();
    let lmax = lam.iter().cloned().fold(0.0, f64::max);
    let keep: Vec<usize> = (0..k).filter(|&i| lam[i] > rel_tol * lmax).collect();
    let u = eig.U();
    Mat::from_fn(keep.len(), k, |r, j| lam[keep[r]].sqrt() * u[(j, keep[r])])
}

/// An orthonormal basis of the span of `x`'s columns (relative tolerance 1e-9 on its Gram's
/// eigenvalues).
fn orthonormal(x: &Mat<f64>) -> Mat<f64> {
    if x.ncols() == 0 {
        return x.clone();
    }
    let g = x.transpose() * x;
    let Ok(eig) = g.self_adjoint_eigen(Side::Lower) else { return Mat::zeros(x.nrows(), 0) };
    let k = g.nrows();
    let lam: Vec<f64> = (0..k).map(|i| eig.S().column_vector()[i]).collect();
    let lmax = lam.iter().cloned().fold(0.0, f64::max);
    let keep: Vec<usize> = (0..k).filter(|&i| lam[i] > 1e-9 * lmax && lam[i] > 0.0).collect();
    let v = Mat::from_fn(k, keep.len(), |i, j| eig.U()[(i, keep[j])] / lam[keep[j]].sqrt());
    x * v
}

/// Numerical rank of `x` (columns), relative tolerance 1e-9 on its Gram's eigenvalues.
fn rank_of(x: &Mat<f64>) -> usize {
    if x.ncols() == 0 {
        return 0;
    }
    let g = x.transpose() * x;
    let Ok(lam) = g.self_adjoint_eigenvalues(Side::Lower) else { return 0 };
    let lmax = lam.iter().cloned().fold(0.0, f64::max);
    lam.iter().filter(|&&l| l > 1e-9 * lmax && l > 0.0).count()
}

/// `Z^T D^-1 S_g u0` per group (all groups through `zt` at once).
fn reduced_su(pen: &Penalty, n: usize, scale: &[f64], u0: &[f64], zt: impl Fn(&Mat<f64>) -> Mat<f64>) -> Vec<Mat<f64>> {
    let ng = pen.n_groups();
    let mut su = Mat::<f64>::zeros(n, ng);
    for blk in &pen.blocks {
        let k = blk.s.nrows();
        for i in 0..k {
            let v: f64 = (0..k).map(|j| blk.s[(i, j)] * u0[blk.offset + j]).sum();
            su[(blk.offset + i, blk.group)] = v / scale[blk.offset + i];
        }
    }
    let su = zt(&su);
    (0..ng).map(|g| su.subcols(g, 1).to_owned()).collect()
}

/// The quadratic model of a fit around its current estimate `u0`, in reduced coordinates `y`
/// (the step is `D^-1 Z y`): `chi2(y) = chi2_0 - 2 y' g + y' M_d y`.
pub(crate) struct Quadratic<'a> {
    /// `Z^T D^-1 N D^-1 Z` of the data alone.
    pub m_data: &'a Mat<f64>,
    /// `Z^T D^-1 b` of the data alone (`b = J' W r`).
    pub g_data: &'a Mat<f64>,
    pub chi2: f64,
    /// Readings in the chi-square.
    pub n_obs: usize,
}

/// A symmetric matrix stored on its support: the rows (and columns) where it is not zero. A
/// penalty in reduced coordinates touches only its function's coefficients and the few the
/// gauge's reduction mixes into them (13 to 15 of 249 rows for most functions of the patent
/// example), so that adding the 18 of them to the reduced matrix at every REML evaluation need
/// not stream 18 dense matrices through memory (it took a tenth of an auto solve's time).
struct Supported {
    /// Indices of the non-zero rows, ascending.
    support: Vec<usize>,
    /// The matrix on `support x support`.
    m: Mat<f64>,
}

impl Supported {
    /// `P = B B^T` on the rows where `B` has a non-zero entry (elsewhere `P` is exactly zero,
    /// and on them its diagonal `|b_i|^2` is not), formed there alone.
    fn of_factor(b: &Mat<f64>) -> Supported {
        let support: Vec<usize> = (0..b.nrows()).filter(|&i| (0..b.ncols()).any(|j| b[(i, j)] != 0.0)).collect();
        let bs = Mat::from_fn(support.len(), b.ncols(), |a, j| b[(support[a], j)]);
        Supported { m: &bs * bs.transpose(), support }
    }

    /// `target += l * self`.
    fn add_scaled_to(&self, target: &mut Mat<f64>, l: f64) {
        for (b, &j) in self.support.iter().enumerate() {
            let col = target.col_as_slice_mut(j);
            for (a, &i) in self.support.iter().enumerate() {
                col[i] += l * self.m[(a, b)];
            }
        }
    }

    fn trace(&self) -> f64 {
        (0..self.support.len()).map(|a| self.m[(a, a)]).sum()
    }
}

/// The penalties in reduced coordinates, and what REML needs of them.
pub(crate) struct ReducedPenalty {
    /// `B_g^T` per group (`n_red x rank`), `P_g = B_g B_g^T`... stored as `B_g^T`.
    bt: Vec<Mat<f64>>,
    /// `P_g` per group (`n_red x n_red`, stored on its support).
    p: Vec<Supported>,
    /// `Z^T D^-1 S_g u0` per group.
    h: Vec<Mat<f64>>,
    /// `u0' S_g u0` per group.
    e0: Vec<f64>,
    /// Rank of each penalty on the reduced subspace.
    pub rank: Vec<usize>,
}

impl ReducedPenalty {
    /// `zt` maps full scaled columns to reduced ones (`Z^T`).
    pub fn new(
        pen: &Penalty,
        n: usize,
        scale: &[f64],
        u0: &[f64],
        zt: impl Fn(&Mat<f64>) -> Mat<f64>,
    ) -> ReducedPenalty {
        let ng = pen.n_groups();
        let mut bt = Vec::with_capacity(ng);
        let mut p = Vec::with_capacity(ng);
        let mut rank = Vec::with_capacity(ng);
        // Every group's columns through `zt` at once, then split.
        let groups: Vec<Mat<f64>> = (0..ng).map(|g| pen.factor_columns(g, n, scale)).collect();
        let widths: Vec<usize> = groups.iter().map(|c| c.ncols()).collect();
        let all = zt(&Mat::from_fn(n, widths.iter().sum(), |i, j| {
            let (mut g, mut j) = (0, j);
            while j >= widths[g] {
                j -= widths[g];
                g += 1;
            }
            groups[g][(i, j)]
        }));
        let mut start = 0;
        for g in 0..ng {
            let b = all.subcols(start, widths[g]).to_owned();
            start += widths[g];
            rank.push(rank_of(&b));
            p.push(Supported::of_factor(&b));
            bt.push(b);
        }
        let mut rp = ReducedPenalty { bt, p, h: Vec::new(), e0: Vec::new(), rank };
        rp.moved_to(pen, n, scale, u0, zt);
        rp
    }

    /// The same penalties about another `u0` (with the same `scale` and reduction `zt`): only
    /// `h` and `e0` depend on it, the reduced factors (most of [`ReducedPenalty::new`]'s time)
    /// do not.
    pub fn moved_to(&mut self, pen: &Penalty, n: usize, scale: &[f64], u0: &[f64], zt: impl Fn(&Mat<f64>) -> Mat<f64>) {
        debug_assert_eq!(self.bt.len(), pen.n_groups(), "reduced for other groups than `pen`'s");
        self.e0 = pen.energies(u0);
        self.h = reduced_su(pen, n, scale, u0, zt);
    }

    fn n_groups(&self) -> usize {
        self.p.len()
    }

    /// Groups whose penalised directions share a direction on the reduced subspace (a
    /// principal angle of zero between their spans): pairs to merge into one smoothing
    /// parameter, since the readings cannot tell their roughness apart.
    pub fn overlapping_pairs(&self) -> Vec<(usize, usize)> {
        let q: Vec<Mat<f64>> = self.bt.iter().map(orthonormal).collect();
        // Every pair's `Q_a^T Q_b` at once, as blocks of one Gram matrix.
        let mut start = vec![0];
        for qa in &q {
            start.push(start.last().unwrap() + qa.ncols());
        }
        let all = Mat::from_fn(q.first().map_or(0, |m| m.nrows()), *start.last().unwrap(), |i, j| {
            let g = start.partition_point(|&s| s <= j) - 1;
            q[g][(i, j - start[g])]
        });
        let gram = all.transpose() * &all;
        let mut out = Vec::new();
        for a in 0..self.n_groups() {
            for b in a + 1..self.n_groups() {
                if q[a].ncols() == 0 || q[b].ncols() == 0 {
                    continue;
                }
                let c = gram.submatrix(start[a], start[b], q[a].ncols(), q[b].ncols());
                // The largest singular value is at most the Frobenius norm: pairs clearly apart
                // need no decomposition.
                if c.squared_norm_l2() < (1.0 - 1e-8) * (1.0 - 1e-8) {
                    continue;
                }
                let cos_max = c.singular_values().ok().and_then(|s| s.first().copied()).unwrap_or(0.0);
                if cos_max > 1.0 - 1e-8 {
                    out.push((a, b));
                }
            }
        }
        out
    }

    /// Groups that the readings leave open in the same way: pairs `(a, b)` admitted by
    /// `candidate` whose penalties, seen on the data's null space `v` (reduced coordinates,
    /// orthonormal columns; the directions only the prior determines), are alike, `C_g = V' P_g V`
    /// with `tr(C_a C_b) / (|C_a| |C_b|)` above [`ALIKE_WHERE_OPEN`]. What the readings resolve
    /// of such functions tells REML little of the roughness of the combination they leave open
    /// (the odd part of a face diagonal's two straightnesses, whose sum the beams measure), so
    /// two smoothing parameters would each extrapolate their own function's detail to it; one
    /// shared parameter weighs both. Groups whose roughness lies in the null space for a
    /// negligible share of its own (`tr C_g / tr P_g` below 1e-3) are left alone.
    ///
    /// The share is each group's own, not its part of all groups' together (until stop 75):
    /// `int f'''^2 dq` scales with the travel's length to the fifth power and the open
    /// combination's amplitude with the length, so on a machine three metres long with 0.6 m
    /// of Y the long axis's straightness held 3.6e-4 of the total, below the former 1e-3, and
    /// its face diagonals' pairs, alike to 1.000, were not paired (the independent simulator,
    /// travel 3 x 0.6 x 0.4 m, seeds 1021-1030). Each of the six straightnesses there, as on
    /// the demo CMM, has 0.238 of its roughness in the null space, every other group 1e-17 or
    /// less.
    pub fn alike_where_open(&self, v: &Mat<f64>, candidate: impl Fn(usize, usize) -> bool) -> Vec<(usize, usize)> {
        let c: Vec<Mat<f64>> = self
            .bt
            .iter()
            .map(|bt| {
                let w = v.transpose() * bt;
                &w * w.transpose()
            })
            .collect();
        // `tr(A B)` of symmetric matrices is the Frobenius inner product.
        let inner = |a: &Mat<f64>, b: &Mat<f64>| (a.transpose() * b).diagonal().column_vector().sum();
        let norm: Vec<f64> = c.iter().map(|m| m.norm_l2()).collect();
        // `tr P_g = |B_g|_F^2`.
        let open_share: Vec<f64> = c
            .iter()
            .zip(&self.bt)
            .map(|(c, bt)| c.diagonal().column_vector().sum() / bt.squared_norm_l2().max(f64::MIN_POSITIVE))
            .collect();
        let mut out = Vec::new();
        for a in 0..c.len() {
            for b in a + 1..c.len() {
                if open_share[a] < 1e-3 || open_share[b] < 1e-3 || !candidate(a, b) {
                    continue;
                }
                if inner(&c[a], &c[b]) / (norm[a] * norm[b]) > ALIKE_WHERE_OPEN {
                    out.push((a, b));
                }
            }
        }
        out
    }
}

/// How alike two functions' shares of what the readings leave open must be for them to share a
/// smoothing parameter ([`ReducedPenalty::alike_where_open`]). The face diagonals' straightness
/// pairs of the independent simulator's 45-beam plan are alike to 1.000; nothing in the suite's
/// campaigns comes near the pairs it admits.
pub const ALIKE_WHERE_OPEN: f64 = 0.5;

/// Result of [`reml`].
pub(crate) struct RemlResult {
    /// Smoothing parameter per group.
    pub lambda: Vec<f64>,
    /// Reduced step from the current estimate to the penalised optimum at `lambda`.
    pub y: Mat<f64>,
    pub iterations: usize,
    pub converged: bool,
    /// Per group: the readings show no detail (held at [`DETAIL_FLOOR`]).
    pub at_upper: Vec<bool>,
    /// The noise scale at `lambda`.
    pub scale: Scale,
}

/// Fewest effective parameters of detail (beyond the parabola) a smoothed function keeps. Where
/// REML finds no detail in the readings it drives the smoothing to its limit, and the prior then
/// claims there is none, with no uncertainty: a detail below what the readings could reveal
/// would be reported as absent to within nanometres (seen: 108 nm of a sinusoid under a
/// standard uncertainty of 2 nm, from a tracer's 11 stops per edge). The readings can only say
/// that the detail is below their resolution; three parameters' worth of it keeps that in the
/// uncertainty: the smoothest mode alone (one parameter, the former floor) is a long wave, and a
/// local feature the readings miss (a bump of a guideway: its place, width and height) is not
/// in it. Measured with sparse beams (3 x 12 lines) over truths with a local bump, 60 seeds in
/// three sets of 20 (1-20, 1001-1020, 2001-2020): actual / predicted map error 1.24 (FXYZ) and
/// 1.09 (FYXZ) with one parameter, 1.19 and 1.01 with two, 1.05 and 0.98 with three, the map
/// error unchanged (1.13 -> 1.11 and 1.16 -> 1.14 times the oracle's). The price is on smooth
/// truths, whose uncertainty is then over-stated: 0.92 and 0.93 (1.01 and 1.03 with one), the
/// paper's tables 0.87 (1.01), and with the sparse joint campaign 0.90 and 0.89 (0.94 and 0.98,
/// seeds 1-20 and 1001-1020); the other dense, tracer and joint cases move by 3 % or less.
///
/// A floor taken from the machine instead of a count (an experiment, not kept): a function
/// whose readings show less detail than this floor given the geometric mean smoothing
/// parameter of the well-resolved functions of its kind (positioning, straightness, rotation),
/// with a floor of one parameter after it. Over-stated more, and fitted worse: sparse beams,
/// seeds 1-20, smooth truths actual / predicted 0.892 -> 0.864 (FXYZ) and 0.910 -> 0.831
/// (FYXZ), map error 0.55 -> 0.66 and 0.51 -> 0.59 times the oracle's; over a bump 0.992 ->
/// 0.772 and 1.011 -> 0.843. The paper's tables with dense beams (seeds 1-3) moved only from
/// 1.210 to 1.177: their under-statement sits in functions whose smoothing REML chose, not in
/// those held at the floor (`AUTO_DEBUG=1`: a roll 1.42 urad RMS off under a stated 0.94, at
/// the floor; a pitch 0.87 under 0.50 and a straightness 0.91 under 0.43, chosen by REML).
///
/// Nor a floor of one parameter on the axes whose readings show no detail beyond the starting
/// knots (no refinement test passed; every bump campaign refines, no smooth one with beams does;
/// stop 53, an experiment): the sparse campaigns' actual / predicted came within 10 % (0.89 ->
/// 1.05 and 0.91 -> 0.98 for polynomials, 0.83 -> 0.97 for the paper's tables), but the whole
/// map left its band in 2 to 7 more of 20 campaigns, dense ones too (docs/representation-auto.md,
/// "What the refinement test tells the prior"): the floor's count shapes the uncertainty, not
/// only its size. Nor a floor no looser than the geometric mean smoothing of the functions of
/// the same kind that REML resolved (stop 57, an experiment): the paper's tables with sparse
/// beams and linear tables came within 10 % (0.848 -> 1.033, seeds 1-20), but 586 components
/// instead of 24 lay beyond 3 sigma, over half at the start of X's travel, which the floor's
/// long waves had covered.
pub const DETAIL_FLOOR: f64 = 3.0;

/// Range of `log lambda` explored around the starting value (a factor e^25, about 7e10).
const RHO_SPAN: f64 = 25.0;
/// Newton stops when every gradient component is below this (in nats of the REML criterion).
const GRAD_TOL: f64 = 5e-2;

/// State of the criterion at one `rho`.
struct Eval {
    v: f64,
    /// Cholesky of `M`.
    llt: faer::linalg::solvers::Llt<f64>,
    y: Mat<f64>,
    /// `e_g = beta' S_g beta`.
    e: Vec<f64>,
    /// The variance factor at this point ([`Scale`]).
    scale: Scale,
}

/// The scale of the readings' noise in the criterion: the stated noise, or larger where the
/// readings say so. With the stated noise taken as exact, a misfit the model cannot absorb (a
/// feature shorter than the knots or than the readings' spacing, unmodelled physics) is read
/// by REML as detail: every smoothing parameter collapses and the functions oscillate between
/// the readings by orders of magnitude more than the truth (seen: a yaw wrong by 1.1 mrad RMS
/// where the truth is 4 urad, from sparse beams over a bump, chi2/dof 3.8). Profiling the scale
/// out when the penalised fit's variance factor `phi = D_p / (n - M_p)` exceeds 1 (REML with an
/// unknown scale, as in mgcv, bounded below by the stated noise) lets the misfit inflate the
/// noise instead, which the reported covariance then carries ([`crate::estimator`]'s Birge
/// factor).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Scale {
    /// `max(1, D_p / dof)`.
    pub phi: f64,
    /// `n - M_p`: readings less the unpenalised dimension.
    pub dof: f64,
}

impl Scale {
    fn of(d_p: f64, dof: f64) -> Scale {
        Scale { phi: (d_p / dof).max(1.0), dof }
    }

    /// Whether the scale is estimated here (above the stated noise).
    fn profiled(&self) -> bool {
        self.phi > 1.0
    }
}

/// `n - M_p` of the criterion: the readings less the dimension the penalties leave free.
fn residual_dof(q: &Quadratic<'_>, rp: &ReducedPenalty) -> f64 {
    let free = q.m_data.nrows().saturating_sub(rp.rank.iter().sum());
    (q.n_obs.saturating_sub(free)).max(1) as f64
}

fn evaluate(q: &Quadratic<'_>, rp: &ReducedPenalty, lambda: &[f64]) -> Option<Eval> {
    let mut m = q.m_data.clone();
    let mut rhs = q.g_data.clone();
    for g in 0..rp.n_groups() {
        let l = lambda[g];
        rp.p[g].add_scaled_to(&mut m, l);
        rhs.col_as_slice_mut(0).iter_mut().zip(rp.h[g].col_as_slice(0)).for_each(|(a, b)| *a -= l * b);
    }
    let llt = m.llt(Side::Lower).ok()?;
    let mut y = rhs;
    llt.solve_in_place(y.as_mut());
    let dot = |a: &Mat<f64>, b: &Mat<f64>| -> f64 {
        a.col_as_slice(0).iter().zip(b.col_as_slice(0)).map(|(x, y)| x * y).sum()
    };
    let gy = dot(&y, q.g_data);
    let ymy = dot(&y, &(q.m_data * &y));
    let chi2 = q.chi2 - 2.0 * gy + ymy;
    let mut e = Vec::with_capacity(rp.n_groups());
    let mut pen = 0.0;
    let mut logdet_prior = 0.0;
    for g in 0..rp.n_groups() {
        // `y' P_g y = |B_g y|^2`.
        let by = rp.bt[g].transpose() * &y;
        let ypy = by.squared_norm_l2();
        let eg = (rp.e0[g] + 2.0 * dot(&y, &rp.h[g]) + ypy).max(0.0);
        pen += lambda[g] * eg;
        logdet_prior += rp.rank[g] as f64 * lambda[g].ln();
        e.push(eg);
    }
    let l = llt.L();
    let logdet: f64 = (0..l.nrows()).map(|i| 2.0 * l[(i, i)].ln()).sum();
    let d_p = chi2 + pen;
    let scale = Scale::of(d_p, residual_dof(q, rp));
    let v = 0.5 * (d_p / scale.phi + scale.dof * scale.phi.ln() + logdet - logdet_prior);
    Some(Eval { v, llt, y, e, scale })
}

/// Estimates the smoothing parameters by REML from `lambda0` (one per group of `rp`), Newton's
/// method on `log lambda` with backtracking. Deterministic.
pub(crate) fn reml(q: &Quadratic<'_>, rp: &ReducedPenalty, lambda0: &[f64], max_iter: usize) -> Option<RemlResult> {
    let ng = rp.n_groups();
    let active: Vec<bool> = (0..ng).map(|g| rp.rank[g] > 0).collect();
    let rho0: Vec<f64> = lambda0.iter().map(|l| l.ln()).collect();
    let (lo, hi): (Vec<f64>, Vec<f64>) = rho0.iter().map(|r| (r - RHO_SPAN, r + RHO_SPAN)).unzip();
    let mut rho = rho0.clone();
    let lam = |rho: &[f64]| -> Vec<f64> { rho.iter().map(|r| r.exp()).collect() };
    let mut cur = evaluate(q, rp, &lam(&rho))?;
    let mut iterations = 0;
    let mut converged = false;
    let mut grad;
    // The traces at `cur`, where the iteration stops with them.
    let mut at_cur: Option<Traces> = None;
    for it in 0..max_iter {
        iterations = it + 1;
        let lambda = lam(&rho);
        let d = Derivatives::at(rp, cur.llt.L(), &cur.y);
        grad = d.traces.gradient(rp, &lambda, &cur.e, cur.scale);
        // Free components: not pinned at a bound by a gradient pushing outwards.
        let free: Vec<usize> = (0..ng)
            .filter(|&g| {
                active[g] && !((rho[g] >= hi[g] - 1e-9 && grad[g] < 0.0) || (rho[g] <= lo[g] + 1e-9 && grad[g] > 0.0))
            })
            .collect();
        let gmax = free.iter().map(|&g| grad[g].abs()).fold(0.0, f64::max);
        if gmax < GRAD_TOL {
            converged = true;
            at_cur = Some(d.traces);
            break;
        }
        let k = free.len();
        // Newton direction on a positive definite modification of the Hessian.
        let hs = d.hessian(&lambda, &cur.e, cur.scale, &free);
        let eig = hs.self_adjoint_eigen(Side::Lower).ok()?;
        let lam_h: Vec<f64> = (0..k).map(|i| eig.S().column_vector()[i]).collect();
        let lmax = lam_h.iter().map(|l| l.abs()).fold(0.0, f64::max).max(1e-12);
        let u = eig.U();
        let mut step = vec![0.0; k];
        for m in 0..k {
            let l = lam_h[m].abs().max(1e-6 * lmax);
            let proj: f64 = (0..k).map(|i| u[(i, m)] * grad[free[i]]).sum();
            for i in 0..k {
                step[i] -= u[(i, m)] * proj / l;
            }
        }
        let smax = step.iter().map(|s| s.abs()).fold(0.0, f64::max);
        if smax > 5.0 {
            step.iter_mut().for_each(|s| *s *= 5.0 / smax);
        }
        // Backtracking on the criterion.
        let mut alpha = 1.0;
        let mut accepted = false;
        for _ in 0..30 {
            let mut trial = rho.clone();
            for (i, &g) in free.iter().enumerate() {
                trial[g] = (rho[g] + alpha * step[i]).clamp(lo[g], hi[g]);
            }
            if let Some(e) = evaluate(q, rp, &lam(&trial)) {
                if e.v <= cur.v + 1e-10 * cur.v.abs().max(1.0) {
                    let moved = free.iter().map(|&g| (trial[g] - rho[g]).abs()).fold(0.0, f64::max);
                    rho = trial;
                    cur = e;
                    accepted = moved > 1e-8;
                    break;
                }
            }
            alpha *= 0.5;
        }
        if !accepted {
            // No descent along the Newton direction: at the optimum to the criterion's precision.
            converged = gmax < 1e-1;
            at_cur = Some(d.traces);
            break;
        }
    }
    // No function stiffer than DETAIL_FLOOR parameters of detail beyond its parabola: up to
    // eight rounds that raise some. A round moves a few groups' smoothing; the traces there
    // follow from those where the rounds started ([`Traces::moved`]) without factorising the
    // criterion again, and where they show nothing more to raise, the criterion is factorised
    // once and the last round is taken on its own traces. `cur` is at `from.0`.
    let mut lambda = lam(&rho);
    let mut at_upper = vec![false; ng];
    let mut from = (lambda.clone(), at_cur.unwrap_or_else(|| Traces::at(rp, cur.llt.L())));
    let mut rounds = 0;
    while rounds < 8 {
        if let Some(t) = from.1.moved(&from.0, &lambda) {
            let mut raised = false;
            for g in (0..ng).filter(|&g| active[g]) {
                let target = DETAIL_FLOOR.min(0.5 * rp.rank[g] as f64);
                let detail = rp.rank[g] as f64 - lambda[g] * t[g];
                if detail < 0.9 * target {
                    // Far from the data, detail ~ 1 / lambda.
                    at_upper[g] = true;
                    lambda[g] *= detail.max(1e-3 * target) / target;
                    raised = true;
                }
            }
            if raised {
                rounds += 1;
                continue;
            }
            if lambda == from.0 {
                break;
            }
        }
        // The identity failed, or the rounds stopped away from the factorised point: factorise
        // where they are, and take the round again on exact traces.
        cur = evaluate(q, rp, &lambda)?;
        from = (lambda.clone(), Traces::at(rp, cur.llt.L()));
    }
    if lambda != from.0 {
        cur = evaluate(q, rp, &lambda)?;
    }
    Some(RemlResult { lambda, y: cur.y, iterations, converged, at_upper, scale: cur.scale })
}

/// The traces of the REML criterion at one point: `G_g = L^-1 B_g^T` and `t_g = tr(M^-1
/// P_g)`, what its gradient needs and the detail floor checks ([`reml`]), and from which the
/// traces after a move of a few groups' smoothing follow ([`Traces::moved`]).
struct Traces {
    /// Columns of each group in `g`.
    cols: Vec<std::ops::Range<usize>>,
    /// `G = L^-1 [B_1^T .. B_n^T]`. Its Gram matrix, which only the Hessian needs, is formed
    /// there, over the groups the Hessian is of ([`Traces::pair_traces`]).
    g: Mat<f64>,
    t: Vec<f64>,
}

/// What the gradient and Hessian of the REML criterion need at one point: its [`Traces`] and
/// `w_g = L^-1 Z^T D^-1 S_g beta` (the reduced `S_g beta`), which only the Hessian and the
/// smoothing parameters' share of the covariance use.
struct Derivatives {
    traces: Traces,
    /// `L^-1 [w_1 .. w_n]`.
    w: Mat<f64>,
}

impl Derivatives {
    /// At the estimate `y` (reduced step from `u0`), with `l` the Cholesky factor there.
    fn at(rp: &ReducedPenalty, l: faer::MatRef<'_, f64>, y: &Mat<f64>) -> Derivatives {
        let mut w = Mat::<f64>::zeros(l.nrows(), rp.n_groups());
        for k in 0..rp.n_groups() {
            let v = &rp.bt[k] * (rp.bt[k].transpose() * y) + &rp.h[k];
            w.col_mut(k).copy_from(v.col(0));
        }
        let traces = Traces::solving(rp, l, w.as_mut());
        Derivatives { traces, w }
    }
}

impl Traces {
    /// With `l` the Cholesky factor of the criterion.
    fn at(rp: &ReducedPenalty, l: faer::MatRef<'_, f64>) -> Traces {
        Traces::solving(rp, l, Mat::<f64>::zeros(l.nrows(), 0).as_mut())
    }

    /// [`Traces::at`], solving `also` with `l` alongside.
    fn solving(rp: &ReducedPenalty, l: faer::MatRef<'_, f64>, also: faer::MatMut<'_, f64>) -> Traces {
        let mut cols = Vec::with_capacity(rp.n_groups());
        let mut start = 0;
        for b in &rp.bt {
            cols.push(start..start + b.ncols());
            start += b.ncols();
        }
        // One triangular solve and one product for all groups.
        let mut g = Mat::<f64>::zeros(l.nrows(), start);
        for (b, c) in rp.bt.iter().zip(&cols) {
            g.subcols_mut(c.start, c.len()).copy_from(b);
        }
        // The columns in two halves side by side ([`crate::halves`]).
        let half = start / 2;
        let solve = |m: faer::MatMut<'_, f64>| {
            faer::linalg::triangular_solve::solve_lower_triangular_in_place(l, m, faer::Par::Seq)
        };
        let (left, right) = g.as_mut().split_at_col_mut(half);
        halves::both(true, || (solve(left), solve(also)), || solve(right));
        let t = cols.iter().map(|c| g.subcols(c.start, c.len()).squared_norm_l2()).collect();
        Traces { cols, g, t }
    }

    /// `t_g` where the smoothing parameters are `lambda` instead of `base` (this point's), a
    /// few groups moved: with `U` the columns of `G` of the groups that moved and `D` their moves
    /// (`lambda_g - base_g` on each of the group's columns), `M' = M + B_U D B_U^T`, and by
    /// Woodbury's identity `t'_h = t_h - tr(X_h^T K^-1 X_h)` with `X = U^T G` and `K = D^-1 +
    /// U^T U`: a product of `G` with a few of its columns instead of a factorisation and a
    /// triangular solve of all of them. `None` where the result is not a trace (negative or
    /// not finite: `K` too ill-conditioned); the caller then factorises.
    fn moved(&self, base: &[f64], lambda: &[f64]) -> Option<Vec<f64>> {
        let moved: Vec<usize> = (0..base.len()).filter(|&g| lambda[g] != base[g]).collect();
        if moved.is_empty() {
            return Some(self.t.clone());
        }
        let (u, at) = self.columns_of(&moved);
        let m = u.ncols();
        let x = u.transpose() * &self.g;
        let mut k = u.transpose() * &u;
        for (a, &g) in moved.iter().enumerate() {
            for c in at[a]..at[a + 1] {
                k[(c, c)] += 1.0 / (lambda[g] - base[g]);
            }
        }
        let y = k.partial_piv_lu().solve(&x);
        let t: Vec<f64> = self
            .cols
            .iter()
            .zip(&self.t)
            .map(|(c, &t)| t - c.clone().map(|j| (0..m).map(|i| x[(i, j)] * y[(i, j)]).sum::<f64>()).sum::<f64>())
            .collect();
        t.iter().all(|v| v.is_finite() && *v >= 0.0).then_some(t)
    }

    /// The columns of `G` of `groups`, side by side, and where each group's columns begin
    /// there (and, last, where they end).
    fn columns_of(&self, groups: &[usize]) -> (Mat<f64>, Vec<usize>) {
        let mut at = vec![0];
        for &g in groups {
            at.push(at.last().unwrap() + self.cols[g].len());
        }
        let mut out = Mat::<f64>::zeros(self.g.nrows(), at[groups.len()]);
        for (a, &g) in groups.iter().enumerate() {
            out.subcols_mut(at[a], at[a + 1] - at[a]).copy_from(self.g.subcols(self.cols[g].start, self.cols[g].len()));
        }
        (out, at)
    }

    /// `tr(M^-1 P_g M^-1 P_h) = |G_g^T G_h|_F^2` for the pairs of `free` (`k x k`, symmetric):
    /// the Gram matrix of `G` on the free groups' columns, its upper blocks only (half the
    /// product, and none at all where the Newton iteration stops on the gradient alone). The
    /// block rows in two halves of about equal work ([`crate::halves`]).
    fn pair_traces(&self, free: &[usize]) -> Mat<f64> {
        let k = free.len();
        let (gf, at) = self.columns_of(free);
        let width = at[k];
        // Block row `a`: `G_a^T [G_a .. G_k]`, its blocks' squared norms.
        let row = |a: usize| -> Vec<f64> {
            let p = gf.subcols(at[a], at[a + 1] - at[a]).transpose() * gf.subcols(at[a], width - at[a]);
            (a..k).map(|b| p.subcols(at[b] - at[a], at[b + 1] - at[b]).squared_norm_l2()).collect()
        };
        let work = (0..k).map(|a| (at[a + 1] - at[a]) * (width - at[a]));
        let cut = halves::first_half(work);
        let (first, second) =
            halves::both(true, || (0..cut).map(row).collect::<Vec<_>>(), || (cut..k).map(row).collect::<Vec<_>>());
        let mut out = Mat::<f64>::zeros(k, k);
        for (a, r) in first.into_iter().chain(second).enumerate() {
            for (b, v) in (a..k).zip(r) {
                out[(a, b)] = v;
                out[(b, a)] = v;
            }
        }
        out
    }

    /// Gradient of `V` with respect to `log lambda` (Wood 2011):
    /// `(lambda_g e_g / phi + lambda_g t_g - r_g) / 2`, zero for a group of rank zero.
    fn gradient(&self, rp: &ReducedPenalty, lambda: &[f64], e: &[f64], scale: Scale) -> Vec<f64> {
        (0..rp.n_groups())
            .map(|g| {
                if rp.rank[g] == 0 {
                    return 0.0;
                }
                0.5 * (lambda[g] * e[g] / scale.phi + lambda[g] * self.t[g] - rp.rank[g] as f64)
            })
            .collect()
    }
}

impl Derivatives {
    /// Hessian of `V` with respect to `log lambda` over the groups `free` (Wood 2011):
    /// `H_gh = delta_gh lambda_g (e_g / phi + t_g) / 2 - lambda_g lambda_h (w_g . w_h) / phi
    ///  - lambda_g lambda_h tr(M^-1 P_g M^-1 P_h) / 2`, the trace being the squared norm of
    /// the `(g, h)` block of `G^T G`; with the scale profiled ([`Scale`]), less
    /// `lambda_g e_g lambda_h e_h / (2 dof phi^2)`.
    fn hessian(&self, lambda: &[f64], e: &[f64], scale: Scale, free: &[usize]) -> Mat<f64> {
        let phi = scale.phi;
        let profiled = scale.profiled();
        let k = free.len();
        let ww = self.w.transpose() * &self.w;
        let pair = self.traces.pair_traces(free);
        let mut h = Mat::<f64>::zeros(k, k);
        for (a, &g) in free.iter().enumerate() {
            for (b, &hh) in free.iter().enumerate().skip(a) {
                let tgh = pair[(a, b)];
                let mut v = -lambda[g] * lambda[hh] * ww[(g, hh)] / phi - 0.5 * lambda[g] * lambda[hh] * tgh;
                if profiled {
                    v -= lambda[g] * e[g] * lambda[hh] * e[hh] / (2.0 * scale.dof * phi * phi);
                }
                if a == b {
                    v += 0.5 * lambda[g] * (e[g] / phi + self.traces.t[g]);
                }
                h[(a, b)] = v;
                h[(b, a)] = v;
            }
        }
        h
    }
}

/// The part of the estimate's covariance (reduced coordinates) that comes from the smoothing
/// parameters being estimated rather than known: `J V_rho J^T`, with `V_rho` the inverse of the
/// REML criterion's Hessian in `log lambda` and `J_g = d y / d log lambda_g = -lambda_g M^-1
/// Z^T D^-1 S_g beta` (Wood, Pya & Saefken 2016, section 2.1). It matters where the readings
/// say little about a function's smoothness (few readings, sparse campaigns) and vanishes
/// otherwise. `l` is the Cholesky factor of the penalised reduced matrix at the estimate
/// (`y = 0` relative to the `u0` of `rp`); groups at their upper bound are left out (the
/// estimate does not move with them).
///
/// What it carries where the truth is rougher than the prior (the paper's linear tables, a kink
/// every tenth of the travel; dense beams, seeds 1-8, actual / predicted map RMS): 1.314
/// without this term, 1.241 with it, and 1.080 with it taken four times, while smooth truths
/// (FXYZ dense beams) went 0.839, 0.828 and 0.799. The kinks make REML's criterion flatter
/// towards less smoothing than its curvature at the optimum says, which a first-order term
/// does not follow; scaling it is no remedy (nothing in the readings says by how much), and
/// taking in the groups held at the detail floor (their curvature there) moved the tables only
/// to 1.218 (experiments, not kept). Nor does the paper's second-order term, the smoothing
/// parameters' effect on the posterior covariance itself (mgcv's `Vc2`: `sum_kl V_rho,kl D_k
/// D_l^T` with `D_k` the derivative in `log lambda_k` of the posterior's square root `L^-T`;
/// an experiment, not kept): its trace is 1.2 to 1.7 % of the posterior's and a tenth to a
/// sixth of the first-order term's (the tables' fits of seeds 1-2), and on seeds 1-8 the tables
/// went 1.241 -> 1.234 (1.214 taken four times), smooth truths 0.828 -> 0.825, at 1.6 to 1.7
/// times the solve time (two `n^3` products per direction of `V_rho`).
pub(crate) fn lambda_covariance(
    rp: &ReducedPenalty,
    lambda: &[f64],
    l: faer::MatRef<'_, f64>,
    at_upper: &[bool],
    scale: Scale,
) -> Option<Mat<f64>> {
    let ng = rp.n_groups();
    let nr = l.nrows();
    let y = Mat::<f64>::zeros(nr, 1);
    let e = rp.e0.clone();
    let d = Derivatives::at(rp, l, &y);
    let free: Vec<usize> = (0..ng).filter(|&g| rp.rank[g] > 0 && !at_upper.get(g).copied().unwrap_or(false)).collect();
    if free.is_empty() {
        return None;
    }
    let h = d.hessian(lambda, &e, scale, &free);
    let eig = h.self_adjoint_eigen(Side::Lower).ok()?;
    let k = free.len();
    let lam_h: Vec<f64> = (0..k).map(|i| eig.S().column_vector()[i]).collect();
    let lmax = lam_h.iter().cloned().fold(0.0, f64::max);
    // J, n_red x k: J_g = -lambda_g L^-T w_g.
    let mut j = Mat::<f64>::zeros(nr, k);
    for (c, &g) in free.iter().enumerate() {
        let mut x = d.w.col(g).as_mat().to_owned();
        faer::linalg::triangular_solve::solve_upper_triangular_in_place(l.transpose(), x.as_mut(), faer::Par::Seq);
        for i in 0..nr {
            j[(i, c)] = -lambda[g] * x[(i, 0)];
        }
    }
    // J V_rho J^T on the positive part of H (a direction of zero curvature has no estimate).
    let kept: Vec<usize> = (0..k).filter(|&m| lam_h[m] > 1e-9 * lmax).collect();
    let u = eig.U();
    let ju = &j * Mat::from_fn(k, kept.len(), |i, c| u[(i, kept[c])]);
    let jus = Mat::from_fn(nr, kept.len(), |i, c| ju[(i, c)] / lam_h[kept[c]]);
    Some(jus * ju.transpose())
}

/// Starting smoothing parameters: the penalty at 1e-3 of the data's information, per group
/// (mean diagonals of `P_g` and `M_d` on the reduced subspace).
pub(crate) fn initial_lambda(q: &Quadratic<'_>, rp: &ReducedPenalty) -> Vec<f64> {
    let n = q.m_data.nrows().max(1);
    let md = (0..n).map(|i| q.m_data[(i, i)]).sum::<f64>() / n as f64;
    rp.p.iter()
        .map(|p| {
            let pd = p.trace() / n as f64;
            if pd > 0.0 {
                1e-3 * md / pd
            } else {
                1.0
            }
        })
        .collect()
}

/// The report of a solve's smoothing at its final factor `l` (Cholesky factor of the reduced,
/// penalised matrix): per function the share of its curvature that the prior rather than the
/// data determines, `lambda tr(M^-1 P_f)`, hence its effective number of parameters; the total
/// over the `n_free` free directions. `reml` carries (iterations, converged, at upper bound per
/// group, noise scale) when the parameters were estimated.
pub(crate) fn report(
    pen: &Penalty,
    l: faer::MatRef<'_, f64>,
    n: usize,
    scale: &[f64],
    zt: impl Fn(&Mat<f64>) -> Mat<f64>,
    n_free: usize,
    reml: Option<(usize, bool, &[bool], f64)>,
) -> SmoothingReport {
    let mut functions: Vec<FunctionSmoothing> = Vec::new();
    let mut prior_total = 0.0;
    for (k, b) in pen.blocks.iter().enumerate() {
        let mut x = zt(&pen.columns_of(|o| std::ptr::eq(o, &pen.blocks[k]), n, scale));
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(l, x.as_mut(), faer::Par::Seq);
        let share = pen.lambda[b.group] * x.squared_norm_l2();
        prior_total += share;
        let at_upper = reml.is_some_and(|(_, _, up, _)| up.get(b.group).copied().unwrap_or(false));
        match functions.iter_mut().find(|f| f.function == b.function) {
            Some(f) => {
                f.lambda.push(pen.lambda[b.group] * b.weight);
                f.edf -= share;
                f.smoothest &= at_upper;
            }
            None => {
                let mut shared_with: Vec<String> = pen
                    .blocks
                    .iter()
                    .filter(|o| o.group == b.group && o.function != b.function)
                    .map(|o| o.function.name())
                    .collect();
                shared_with.dedup();
                functions.push(FunctionSmoothing {
                    function: b.function,
                    lambda: vec![pen.lambda[b.group] * b.weight],
                    edf: b.s.nrows() as f64 - share,
                    n_coeffs: b.s.nrows(),
                    smoothest: at_upper,
                    shared_with,
                });
            }
        }
    }
    for f in &mut functions {
        f.edf = f.edf.max(0.0);
    }
    let (method, iterations, converged, noise_scale) = match reml {
        Some((it, c, _, phi)) => ("reml", it, c, phi),
        None => ("fixed", 0, true, 1.0),
    };
    SmoothingReport {
        method: method.into(),
        functions,
        iterations,
        converged,
        edf_total: (n_free as f64 - prior_total).max(0.0),
        noise_scale,
        open_alike: pen.open_alike.clone(),
        open_long_waves: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::axis::Travel;
    use crate::topology::Topology;

    #[test]
    fn the_penalty_never_acts_on_a_gauge_freedom() {
        for topo in ["FXYZ", "FYXZ", "XFYZ"] {
            for travel in
                [Travel::new([0.0, 0.7], [-0.5, 0.0], [-0.7, 0.0]), Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0])]
            {
                let layout = ModelLayout::uniform(
                    Topology::parse(topo).unwrap(),
                    travel,
                    crate::repr::Representation::BSpline { intervals: 8 },
                );
                let mut pen = Penalty::new(&layout, &Smoothing::reml()).unwrap();
                pen.lambda.iter_mut().for_each(|l| *l = 1.0);
                let g = crate::gauge::null_basis(&layout);
                for c in 0..g.ncols() {
                    let u: Vec<f64> = (0..layout.n_params).map(|i| g[(i, c)]).collect();
                    let mut grad = vec![0.0; layout.n_params];
                    let cost = pen.apply(&u, &mut grad);
                    let scale = pen
                        .blocks
                        .iter()
                        .map(|b| (0..b.s.nrows()).map(|i| b.s[(i, i)]).fold(0.0, f64::max))
                        .fold(0.0, f64::max);
                    assert!(cost.abs() < 1e-9 * scale, "{topo} {travel:?}: gauge freedom {c} costs {cost:e}");
                }
            }
        }
    }

    /// Counting two functions' roughness relative to their travels changes neither penalty
    /// until they share a parameter: the cost of every estimate and each function's own
    /// `int f'''^2` parameter are unchanged, and the weights are the travels' ratio to the fifth.
    #[test]
    fn relative_roughness_changes_no_penalty_before_a_merge() {
        let travel = Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]);
        let layout = ModelLayout::uniform(
            Topology::parse("FXYZ").unwrap(),
            travel,
            crate::repr::Representation::BSpline { intervals: 8 },
        );
        let mut pen = Penalty::new(&layout, &Smoothing::reml()).unwrap();
        pen.lambda.iter_mut().enumerate().for_each(|(g, l)| *l = 1.0 + g as f64);
        let u: Vec<f64> = (0..layout.n_params).map(|i| ((i * 7919) % 101) as f64 / 101.0 - 0.5).collect();
        let cost = |pen: &Penalty| pen.apply(&u, &mut vec![0.0; layout.n_params]);
        let own = |pen: &Penalty| -> Vec<f64> { pen.blocks.iter().map(|b| pen.lambda[b.group] * b.weight).collect() };
        let (cost0, own0) = (cost(&pen), own(&pen));
        let block = |pen: &Penalty, name: &str| pen.blocks.iter().find(|b| b.function.name() == name).unwrap().clone();
        let groups = [block(&pen, "EYX").group, block(&pen, "EXY").group];
        pen.relative_roughness(&groups, |f| layout.basis(f).length());
        assert!((cost(&pen) - cost0).abs() <= 1e-12 * cost0.abs(), "{} against {cost0}", cost(&pen));
        for (now, was) in own(&pen).iter().zip(&own0) {
            assert!((now - was).abs() <= 1e-12 * was, "{now} against {was}");
        }
        let ratio = block(&pen, "EXY").weight / block(&pen, "EYX").weight;
        assert!((ratio - 0.8f64.powi(5)).abs() < 1e-12, "weight ratio {ratio}");
        // Merged, the two have one parameter of relative roughness: their own parameters keep
        // the travels' ratio.
        pen.merge(&[(groups[0], groups[1])]);
        let (a, b) = (block(&pen, "EYX"), block(&pen, "EXY"));
        assert_eq!(a.group, b.group);
        let own_ratio = (pen.lambda[b.group] * b.weight) / (pen.lambda[a.group] * a.weight);
        assert!((own_ratio - 0.8f64.powi(5)).abs() < 1e-12, "own parameters' ratio {own_ratio}");
    }

    /// Groups whose penalties meet what the readings leave open in the same combination are
    /// paired; one that meets it elsewhere is not, nor a pair the caller does not admit.
    #[test]
    fn groups_open_alike_are_paired() {
        let n = 12;
        // Three groups on disjoint coordinates, as functions are: 0..4, 4..8, 8..12.
        let bt: Vec<Mat<f64>> =
            (0..3).map(|g| Mat::from_fn(n, 4, |r, c| if r == 4 * g + c { 1.0 } else { 0.0 })).collect();
        let rp = ReducedPenalty { bt, p: Vec::new(), h: Vec::new(), e0: Vec::new(), rank: vec![4; 3] };
        // Open: the difference of groups 0 and 1 in their first coordinates, their sum in the
        // second, and one coordinate of group 2 alone.
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let v = Mat::from_fn(n, 3, |r, c| match (r, c) {
            (0, 0) | (1, 1) | (5, 1) => s,
            (4, 0) => -s,
            (10, 2) => 1.0,
            _ => 0.0,
        });
        assert_eq!(rp.alike_where_open(&v, |_, _| true), vec![(0, 1)]);
        assert!(rp.alike_where_open(&v, |a, b| (a, b) != (0, 1)).is_empty());
        // Whatever the scale of a penalty (the roughness of a function along a travel five times
        // as long is 5^-3 of its partner's in the same open combination): each group's share is
        // its own.
        let mut rp = rp;
        rp.bt[0] = &rp.bt[0] * faer::Scale(1e-3);
        assert_eq!(rp.alike_where_open(&v, |_, _| true), vec![(0, 1)]);
    }

    /// A reduced problem of `n` coordinates, three penalties of rank 5 and `n_obs` readings
    /// whose chi-square at the start is `chi2`.
    fn random_problem(
        n: usize,
        n_obs: usize,
        chi2: f64,
        seed: u64,
    ) -> (Mat<f64>, Mat<f64>, f64, usize, ReducedPenalty) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let a = Mat::from_fn(n + 10, n, |_, _| rng.random_range(-1.0..1.0));
        let m_data = a.transpose() * &a;
        let g_data = Mat::from_fn(n, 1, |_, _| rng.random_range(-3.0..3.0));
        let u0 = Mat::from_fn(n, 1, |_, _| rng.random_range(-3.0..3.0));
        let (mut bt, mut p, mut h, mut e0, mut rank) = (vec![], vec![], vec![], vec![], vec![]);
        for _ in 0..3 {
            let b = Mat::from_fn(n, 5, |_, _| rng.random_range(-1.0..1.0));
            let pg = &b * b.transpose();
            h.push(&pg * &u0);
            e0.push((u0.transpose() * &pg * &u0)[(0, 0)]);
            rank.push(5);
            p.push(Supported::of_factor(&b));
            bt.push(b);
        }
        (m_data, g_data, chi2, n_obs, ReducedPenalty { bt, p, h, e0, rank })
    }

    /// The traces where a few groups' smoothing moved, from Woodbury's identity, are those of
    /// the criterion factorised there, whether the smoothing moves up or down, by a little or
    /// by orders of magnitude.
    #[test]
    fn traces_after_a_move_match_a_new_factorisation() {
        let (m_data, g_data, chi2, n_obs, rp) = random_problem(16, 300, 40.0, 5);
        let q = Quadratic { m_data: &m_data, g_data: &g_data, chi2, n_obs };
        let base = [2.0, 0.5, 30.0];
        let e = evaluate(&q, &rp, &base).unwrap();
        let d = Traces::at(&rp, e.llt.L());
        for moved in [[2.0, 0.5, 30.0], [2e-3, 0.5, 30.0], [2.0, 5e2, 0.03], [1.9, 0.55, 3e4], [2e3, 5e-4, 30.0]] {
            let t = d.moved(&base, &moved).unwrap();
            let e2 = evaluate(&q, &rp, &moved).unwrap();
            let exact = Traces::at(&rp, e2.llt.L()).t;
            for g in 0..3 {
                assert!(
                    (t[g] - exact[g]).abs() <= 1e-9 * exact[g],
                    "{moved:?} group {g}: {} against {}",
                    t[g],
                    exact[g]
                );
            }
        }
    }

    /// Readings that show no detail at all drive REML to its stiffest smoothing; the floor then
    /// gives every function [`DETAIL_FLOOR`] parameters of detail back, to within a tenth (the
    /// floor tolerates 0.9 of it; more than 1.1 would be a step past it), in the rounds it has.
    #[test]
    fn readings_without_detail_leave_the_floor_s_detail() {
        for seed in [3, 11, 12] {
            let (m_data, _, _, n_obs, mut rp) = random_problem(16, 300, 0.0, seed);
            // No signal: the start is the penalised optimum and its roughness is zero.
            let g_data = Mat::<f64>::zeros(16, 1);
            rp.h.iter_mut().for_each(|h| h.fill(0.0));
            rp.e0.iter_mut().for_each(|e| *e = 0.0);
            let q = Quadratic { m_data: &m_data, g_data: &g_data, chi2: n_obs as f64, n_obs };
            let res = reml(&q, &rp, &[1.0; 3], 60).unwrap();
            let e = evaluate(&q, &rp, &res.lambda).unwrap();
            let t = Traces::at(&rp, e.llt.L()).t;
            for g in 0..3 {
                let target = DETAIL_FLOOR.min(0.5 * rp.rank[g] as f64);
                let detail = rp.rank[g] as f64 - res.lambda[g] * t[g];
                assert!(res.at_upper[g], "seed {seed} group {g}: not at the floor, detail {detail}");
                assert!(
                    (0.9 * target..=1.1 * target).contains(&detail),
                    "seed {seed} group {g}: detail {detail} for a floor of {target}"
                );
            }
        }
    }

    /// The gradient and Hessian the Newton iteration uses are those of the criterion it
    /// minimises, with the stated noise and with the scale profiled out (a misfit).
    #[test]
    fn reml_derivatives_match_finite_differences() {
        for (chi2, n_obs, profiled) in [(40.0, 400, false), (400.0, 30, true)] {
            let (m_data, g_data, chi2, n_obs, rp) = random_problem(12, n_obs, chi2, 7);
            let q = Quadratic { m_data: &m_data, g_data: &g_data, chi2, n_obs };
            let rho = [0.3, -1.2, 0.8];
            let lam = |r: &[f64]| -> Vec<f64> { r.iter().map(|x| x.exp()).collect() };
            let at = |r: &[f64]| {
                let e = evaluate(&q, &rp, &lam(r)).unwrap();
                let d = Derivatives::at(&rp, e.llt.L(), &e.y);
                (
                    e.v,
                    d.traces.gradient(&rp, &lam(r), &e.e, e.scale),
                    d.hessian(&lam(r), &e.e, e.scale, &[0, 1, 2]),
                    e.scale,
                )
            };
            let (_, grad, hess, scale) = at(&rho);
            assert_eq!(scale.profiled(), profiled, "phi {}", scale.phi);
            let eps = 1e-5;
            for k in 0..3 {
                let mut up = rho;
                up[k] += eps;
                let mut dn = rho;
                dn[k] -= eps;
                let (vu, gu, _, _) = at(&up);
                let (vd, gd, _, _) = at(&dn);
                let fd = (vu - vd) / (2.0 * eps);
                assert!(
                    (fd - grad[k]).abs() < 1e-5 * (1.0 + fd.abs()),
                    "chi2 {chi2}: gradient {k}: {fd} vs {}",
                    grad[k]
                );
                for j in 0..3 {
                    let fd = (gu[j] - gd[j]) / (2.0 * eps);
                    assert!(
                        (fd - hess[(j, k)]).abs() < 1e-5 * (1.0 + fd.abs()),
                        "chi2 {chi2}: hessian ({j}, {k}): {fd} vs {}",
                        hess[(j, k)]
                    );
                }
            }
        }
    }
}
