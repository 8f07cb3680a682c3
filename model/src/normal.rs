//! Assembly of normal equations from sparse rows.
//!
//! A reading's row touches each error function through a run of consecutive coefficients (4 for
//! a cubic B-spline, 2 for a table), so a row is stored as runs and `w a a^T` is accumulated run
//! against run. The runs of length 4 use a fixed-width kernel, compiled for the best instruction
//! set available at run time (AVX2/FMA or AVX-512 through `pulp`'s dispatch, scalar otherwise),
//! so the binary stays portable. Everything after assembly (the origin elimination, the
//! factorisations) is faer's.

/// One run of a row: `len` consecutive columns from `col`, values at `vals[at..at + len]`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Run {
    pub col: usize,
    pub len: usize,
    pub at: usize,
}

/// Splits a sorted sparse row into runs of consecutive columns.
pub(crate) fn runs_of(idx: &[usize], runs: &mut Vec<Run>) {
    runs.clear();
    let mut k = 0;
    while k < idx.len() {
        let mut e = k + 1;
        while e < idx.len() && idx[e] == idx[e - 1] + 1 {
            e += 1;
        }
        runs.push(Run { col: idx[k], len: e - k, at: k });
        k = e;
    }
}

/// `dst[r.col..][..r.len] += w * vals[r.at..][..r.len]`, with a fixed-width kernel for a run of
/// 4 (a cubic B-spline's span) that the caller's SIMD dispatch vectorises.
#[inline(always)]
fn add_run(dst: &mut [f64], w: f64, r: &Run, vals: &[f64]) {
    if r.len == 4 {
        let d: &mut [f64; 4] = (&mut dst[r.col..r.col + 4]).try_into().unwrap();
        let v: &[f64; 4] = (&vals[r.at..r.at + 4]).try_into().unwrap();
        d[0] += w * v[0];
        d[1] += w * v[1];
        d[2] += w * v[2];
        d[3] += w * v[3];
    } else {
        for (d, v) in dst[r.col..r.col + r.len].iter_mut().zip(&vals[r.at..r.at + r.len]) {
            *d += w * v;
        }
    }
}

/// Adds `w_j a` to row `j` of the row-major `k x n` matrix `bt` for every `(j, w_j)` of
/// `(cols, weights)`: the cross products `G^T W A` of an extension's sparse row (already
/// weighted) against a model row `a` given by `runs` over `vals` ([`add_run`]).
pub(crate) fn add_cross(bt: &mut [f64], n: usize, cols: &[usize], weights: &[f64], runs: &[Run], vals: &[f64]) {
    struct Cross<'a> {
        bt: &'a mut [f64],
        n: usize,
        cols: &'a [usize],
        weights: &'a [f64],
        runs: &'a [Run],
        vals: &'a [f64],
    }
    impl pulp::WithSimd for Cross<'_> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) {
            let n = self.n;
            for (&j, &wj) in self.cols.iter().zip(self.weights) {
                let dst = &mut self.bt[j * n..(j + 1) * n];
                for r in self.runs {
                    add_run(dst, wj, r, self.vals);
                }
            }
        }
    }
    pulp::Arch::new().dispatch(Cross { bt, n, cols, weights, runs, vals });
}

/// The six functions of one axis in a row: function `f` touches columns
/// `col[f] .. col[f] + b.len()` with values `d[f] * b`.
#[derive(Clone, Debug)]
pub(crate) struct AxisSegment<'a> {
    pub col: [usize; 6],
    pub d: [f64; 6],
    pub b: &'a [f64],
}

/// One structured row with its weight.
#[derive(Clone, Debug)]
pub(crate) struct StructuredRow<'a> {
    pub w: f64,
    pub axes: [AxisSegment<'a>; 3],
    pub extras: Vec<(usize, f64)>,
}

/// Upper triangle of a symmetric `n x n` matrix, row-major, accumulated row by row.
pub(crate) struct Upper {
    pub n: usize,
    pub data: Vec<f64>,
}

impl Upper {
    pub fn new(n: usize) -> Upper {
        Upper { n, data: vec![0.0; n * n] }
    }

    /// Adds `w_k a_k a_k^T` for a batch of rows: `rows[k] = (w_k, runs, values)` where the runs
    /// index into `runs_buf` and the values into `vals_buf`.
    pub fn add_batch(&mut self, rows: &[(f64, std::ops::Range<usize>)], runs_buf: &[Run], vals_buf: &[f64]) {
        struct Batch<'a> {
            upper: &'a mut Upper,
            rows: &'a [(f64, std::ops::Range<usize>)],
            runs: &'a [Run],
            vals: &'a [f64],
        }
        impl pulp::WithSimd for Batch<'_> {
            type Output = ();
            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, _simd: S) {
                for (w, r) in self.rows {
                    self.upper.add(*w, &self.runs[r.clone()], self.vals);
                }
            }
        }
        pulp::Arch::new().dispatch(Batch { upper: self, rows, runs: runs_buf, vals: vals_buf });
    }

    /// Adds `w a a^T` for the row `a` given by `runs` over `vals` (run offsets index `vals`).
    #[inline(always)]
    pub fn add(&mut self, w: f64, runs: &[Run], vals: &[f64]) {
        let n = self.n;
        for (ra, r) in runs.iter().enumerate() {
            for i in 0..r.len {
                let row = r.col + i;
                let wa = w * vals[r.at + i];
                let dst = &mut self.data[row * n..(row + 1) * n];
                // Same run: columns row..end of the run.
                for j in i..r.len {
                    dst[r.col + j] += wa * vals[r.at + j];
                }
                for s in &runs[ra + 1..] {
                    add_run(dst, wa, s, vals);
                }
            }
        }
    }

    /// Adds `w a a^T` for a structured row (see [`AxisSegment`]): per axis, six functions
    /// sharing one basis, plus a few extra columns above all of them (squareness, stations,
    /// effects), given in increasing column order.
    #[inline(always)]
    pub fn add_structured<S: pulp::Simd>(
        &mut self,
        simd: S,
        w: f64,
        axes: &[AxisSegment<'_>; 3],
        extras: &[(usize, f64)],
    ) {
        let n = self.n;
        debug_assert!(axes.iter().all(|a| a.col.iter().all(|&c| c + a.b.len() <= n)));
        let base = self.data.as_mut_ptr();
        for a in 0..3 {
            let sa = &axes[a];
            for c in a..3 {
                let sc = &axes[c];
                let kc = sc.b.len();
                let v4: [f64; 4] = if kc == 4 { [sc.b[0], sc.b[1], sc.b[2], sc.b[3]] } else { [0.0; 4] };
                // One SIMD register holds a 4-coefficient run when the ISA has 4 f64 lanes.
                let wide = kc == 4 && S::F64_LANES == 4;
                let vv: S::f64s =
                    if wide { pulp::bytemuck::cast_slice::<f64, S::f64s>(&v4)[0] } else { simd.splat_f64s(0.0) };
                for f in 0..6 {
                    let wf = w * sa.d[f];
                    let g0 = if a == c { f } else { 0 };
                    for g in g0..6 {
                        let k = wf * sc.d[g];
                        let col = sc.col[g];
                        for (i, &ba) in sa.b.iter().enumerate() {
                            let kb = k * ba;
                            let at = (sa.col[f] + i) * n + col;
                            if wide {
                                // SAFETY: as below; `S::f64s` is exactly four f64 here.
                                unsafe {
                                    let d = base.add(at) as *mut S::f64s;
                                    d.write_unaligned(simd.mul_add_f64s(simd.splat_f64s(kb), vv, d.read_unaligned()));
                                }
                            } else if kc == 4 {
                                // SAFETY: `sa.col[f] + i < n` and `col + 4 <= n` (checked above in
                                // debug builds; guaranteed by the layout: every function's
                                // coefficients lie inside `0..n_params` and a basis span starts
                                // at most `n_coeffs - k`), so `at + 4 <= n * n = data.len()`.
                                unsafe {
                                    let d = base.add(at) as *mut [f64; 4];
                                    let mut t = d.read_unaligned();
                                    t[0] += kb * v4[0];
                                    t[1] += kb * v4[1];
                                    t[2] += kb * v4[2];
                                    t[3] += kb * v4[3];
                                    d.write_unaligned(t);
                                }
                            } else {
                                for (d, v) in self.data[at..at + kc].iter_mut().zip(sc.b) {
                                    *d += kb * v;
                                }
                            }
                        }
                    }
                }
            }
        }
        // Axis coefficients against the extra columns, and the extras among themselves.
        for sa in axes {
            for f in 0..6 {
                let wf = w * sa.d[f];
                if wf == 0.0 {
                    continue;
                }
                for (i, &b) in sa.b.iter().enumerate() {
                    let row = sa.col[f] + i;
                    let wv = wf * b;
                    for &(col, v) in extras {
                        self.data[row * n + col] += wv * v;
                    }
                }
            }
        }
        for (e, &(row, v)) in extras.iter().enumerate() {
            let wv = w * v;
            for &(col, u) in &extras[e..] {
                self.data[row * n + col] += wv * u;
            }
        }
    }

    /// [`Upper::add_structured`] for a batch of rows, compiled for the best available SIMD.
    pub fn add_structured_batch(&mut self, rows: &[StructuredRow<'_>]) {
        struct Batch<'a, 'b> {
            upper: &'a mut Upper,
            rows: &'a [StructuredRow<'b>],
        }
        impl pulp::WithSimd for Batch<'_, '_> {
            type Output = ();
            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, simd: S) {
                for r in self.rows {
                    self.upper.add_structured(simd, r.w, &r.axes, &r.extras);
                }
            }
        }
        pulp::Arch::new().dispatch(Batch { upper: self, rows });
    }

    /// The full symmetric matrix as a faer matrix.
    pub fn to_mat(&self) -> faer::Mat<f64> {
        let n = self.n;
        faer::Mat::from_fn(n, n, |i, j| if i <= j { self.data[i * n + j] } else { self.data[j * n + i] })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_dense_outer_product() {
        let n = 12;
        let idx = vec![0, 1, 2, 3, 5, 7, 8, 9, 10, 11];
        let vals: Vec<f64> = (0..idx.len()).map(|k| 0.3 + k as f64).collect();
        let mut runs = Vec::new();
        runs_of(&idx, &mut runs);
        let mut u = Upper::new(n);
        u.add(2.0, &runs, &vals);
        let m = u.to_mat();
        for (a, &i) in idx.iter().enumerate() {
            for (b, &j) in idx.iter().enumerate() {
                assert!((m[(i, j)] - 2.0 * vals[a] * vals[b]).abs() < 1e-12);
            }
        }
        assert_eq!(m[(4, 4)], 0.0);
    }

    #[test]
    fn cross_products_match_dense() {
        let n = 12;
        let idx = vec![0, 1, 2, 3, 5, 7, 8, 9, 10];
        let vals: Vec<f64> = (0..idx.len()).map(|k| 0.3 + k as f64).collect();
        let mut runs = Vec::new();
        runs_of(&idx, &mut runs);
        let (cols, weights) = (vec![1, 4], vec![2.0, -0.5]);
        let k = 5;
        let mut bt = vec![0.0; k * n];
        add_cross(&mut bt, n, &cols, &weights, &runs, &vals);
        for j in 0..k {
            for i in 0..n {
                let w = cols.iter().position(|&c| c == j).map_or(0.0, |p| weights[p]);
                let a = idx.iter().position(|&c| c == i).map_or(0.0, |p| vals[p]);
                assert_eq!(bt[j * n + i], w * a, "({j}, {i})");
            }
        }
    }

    #[test]
    fn structured_matches_generic() {
        let b = [[0.1, 0.5, 0.3, 0.1], [0.2, 0.3, 0.4, 0.1], [0.6, 0.4, 0.0, 0.0]];
        let bs: [&[f64]; 3] = [&b[0], &b[1], &b[2][..2]];
        let axes: [AxisSegment<'_>; 3] = std::array::from_fn(|a| AxisSegment {
            col: std::array::from_fn(|f| a * 60 + f * 10 + a + 1),
            d: std::array::from_fn(|f| (a * 6 + f) as f64 * 0.1 - 0.7),
            b: bs[a],
        });
        let extras = vec![(180, 0.25), (182, -1.5)];
        let n = 190;
        let mut s = Upper::new(n);
        s.add_structured(pulp::Scalar, 1.7, &axes, &extras);
        let mut s2 = Upper::new(n);
        s2.add_structured_batch(&[StructuredRow { w: 1.7, axes: axes.clone(), extras: extras.clone() }]);
        let mut idx = Vec::new();
        let mut vals = Vec::new();
        for ax in &axes {
            for f in 0..6 {
                for (i, b) in ax.b.iter().enumerate() {
                    idx.push(ax.col[f] + i);
                    vals.push(ax.d[f] * b);
                }
            }
        }
        for &(c, v) in &extras {
            idx.push(c);
            vals.push(v);
        }
        let mut runs = Vec::new();
        runs_of(&idx, &mut runs);
        let mut g = Upper::new(n);
        g.add(1.7, &runs, &vals);
        let (ms, mg, m2) = (s.to_mat(), g.to_mat(), s2.to_mat());
        for i in 0..n {
            for j in 0..n {
                assert!((ms[(i, j)] - mg[(i, j)]).abs() < 1e-12, "({i}, {j}): {} vs {}", ms[(i, j)], mg[(i, j)]);
                assert!((m2[(i, j)] - mg[(i, j)]).abs() < 1e-12, "simd ({i}, {j}): {} vs {}", m2[(i, j)], mg[(i, j)]);
            }
        }
    }
}
