//! Assembly of normal equations from sparse rows.
//!
//! A reading's row touches each error function through a run of consecutive coefficients (4 for
//! a cubic B-spline, 2 for a table), so a row is stored as runs and `w a a^T` is accumulated run
//! against run. The runs of length 4 use a fixed-width kernel, compiled for the best instruction
//! set available at run time (AVX2/FMA or AVX-512 through `pulp`'s dispatch, scalar otherwise),
//! so the binary stays portable. Everything after assembly (the origin elimination, the
//! factorisations) is faer's. The extension tests' cross products (`G^T W A`, `G^T W G`) are
//! summed per batch of readings of the same shape ([`CrossBatch`]).

/// One run of a row: `len` consecutive columns from `col`, values at `vals[at..at + len]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
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

/// The cross products of consecutive readings whose extension rows touch the same columns and
/// whose model rows have the same runs (a line's readings within one knot span): `sum w g a^T`
/// and, within each segment of the extension's columns, `sum w g g^T` over the batch, dense and
/// small enough for the first-level cache, added to the large `k x n` sums once per batch
/// instead of once per reading. Scattering each reading into the large sums costs a cache miss
/// per run; here a reading costs contiguous SIMD rows.
#[derive(Default)]
pub(crate) struct CrossBatch {
    /// The extension's columns (rows of the cross products).
    cols: Vec<usize>,
    /// The model row's columns, and their runs ([`runs_of`]); its values are `width` long.
    idx: Vec<usize>,
    runs: Vec<Run>,
    width: usize,
    /// Ranges of `cols` whose products among themselves are summed.
    segments: Vec<std::ops::Range<usize>>,
    /// `cols.len() x width`, row-major.
    cross: Vec<f64>,
    /// Each segment's square block, row-major, one after the other.
    gram: Vec<f64>,
    readings: usize,
}

impl CrossBatch {
    /// Whether a reading with extension columns `cols` and model row columns `idx` (sorted)
    /// joins the batch.
    pub fn holds(&self, cols: &[usize], idx: &[usize]) -> bool {
        self.readings > 0 && self.cols == cols && self.idx == idx
    }

    /// Starts an empty batch for readings of this shape (extension columns `cols`, model row
    /// columns `idx`, sorted); `segments` (ranges of `cols`) are the columns whose products
    /// among themselves are wanted. The model row's runs are split here, once per batch.
    pub fn start(&mut self, cols: &[usize], idx: &[usize], segments: &[std::ops::Range<usize>]) {
        self.cols.clear();
        self.cols.extend_from_slice(cols);
        self.idx.clear();
        self.idx.extend_from_slice(idx);
        runs_of(idx, &mut self.runs);
        self.width = idx.len();
        self.segments.clear();
        self.segments.extend_from_slice(segments);
        self.cross.clear();
        self.cross.resize(cols.len() * idx.len(), 0.0);
        self.gram.clear();
        self.gram.resize(segments.iter().map(|r| r.len() * r.len()).sum(), 0.0);
        self.readings = 0;
    }

    /// Adds one reading: its weighted extension row `wg`, the same unweighted `g`, and its
    /// model row's values `a` (in the order of the runs).
    pub fn add(&mut self, wg: &[f64], g: &[f64], a: &[f64]) {
        struct Add<'a> {
            batch: &'a mut CrossBatch,
            wg: &'a [f64],
            g: &'a [f64],
            a: &'a [f64],
        }
        impl pulp::WithSimd for Add<'_> {
            type Output = ();
            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, _simd: S) {
                let b = self.batch;
                let (m, w) = (b.cols.len(), b.width);
                assert!(self.wg.len() == m && self.g.len() == m && self.a.len() == w);
                for (row, &wr) in b.cross.chunks_exact_mut(w).zip(self.wg) {
                    for (d, &v) in row.iter_mut().zip(self.a) {
                        *d += wr * v;
                    }
                }
                let mut at = 0;
                for seg in &b.segments {
                    let len = seg.len();
                    let g = &self.g[seg.clone()];
                    for (row, &wr) in b.gram[at..at + len * len].chunks_exact_mut(len).zip(&self.wg[seg.clone()]) {
                        for (d, &v) in row.iter_mut().zip(g) {
                            *d += wr * v;
                        }
                    }
                    at += len * len;
                }
            }
        }
        pulp::Arch::new().dispatch(Add { batch: self, wg, g, a });
        self.readings += 1;
    }

    /// Adds the batch's sums to `bt` (row-major `k x n`, rows indexed by the extension's
    /// columns) and hands each segment's `g g^T` block to `gram` with the segment's columns;
    /// then empties the batch.
    pub fn flush(&mut self, bt: &mut [f64], n: usize, gram: &mut impl FnMut(&[usize], &[f64])) {
        if self.readings == 0 {
            return;
        }
        let w = self.width;
        for (&j, src) in self.cols.iter().zip(self.cross.chunks_exact(w)) {
            let dst = &mut bt[j * n..(j + 1) * n];
            for run in &self.runs {
                for (d, v) in dst[run.col..run.col + run.len].iter_mut().zip(&src[run.at..run.at + run.len]) {
                    *d += v;
                }
            }
        }
        let mut at = 0;
        for seg in &self.segments {
            let len = seg.len();
            gram(&self.cols[seg.clone()], &self.gram[at..at + len * len]);
            at += len * len;
        }
        self.readings = 0;
    }
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
    fn batched_cross_products_match_dense() {
        // Readings of two shapes, the first shape twice in a row: the sums over all of them
        // against dense outer products, for `G^T W A` and within each segment `G^T W G`.
        let n = 12;
        let k = 6;
        let shapes: [(Vec<usize>, Vec<usize>); 2] =
            [(vec![0, 1, 2, 3, 5, 7, 8, 9, 10], vec![1, 2, 4]), (vec![2, 3, 4, 5, 11], vec![0, 3, 4, 5])];
        let segments = |cols: &[usize]| -> Vec<std::ops::Range<usize>> {
            // Columns below 3 and from 3 on are two parts.
            let split = cols.iter().position(|&c| c >= 3).unwrap_or(cols.len());
            [0..split, split..cols.len()].into_iter().filter(|r| !r.is_empty()).collect()
        };
        // A segment's block into the full `k x k` products.
        let into = |gram: &mut [f64], cs: &[usize], sums: &[f64]| {
            for (a, &j) in cs.iter().enumerate() {
                for (b, &l) in cs.iter().enumerate() {
                    gram[j * k + l] += sums[a * cs.len() + b];
                }
            }
        };
        let readings: Vec<(f64, usize)> = vec![(2.0, 0), (0.5, 0), (1.5, 1), (3.0, 0)];
        let (mut bt, mut gram) = (vec![0.0; k * n], vec![0.0; k * k]);
        let (mut want_bt, mut want_gram) = (vec![0.0; k * n], vec![0.0; k * k]);
        let mut batch = CrossBatch::default();
        for (r, &(w, s)) in readings.iter().enumerate() {
            let (idx, cols) = &shapes[s];
            let vals: Vec<f64> = (0..idx.len()).map(|a| 0.3 + a as f64 + r as f64).collect();
            let g: Vec<f64> = (0..cols.len()).map(|a| 1.0 - 0.25 * a as f64 + r as f64).collect();
            let wg: Vec<f64> = g.iter().map(|v| w * v).collect();
            if !batch.holds(cols, idx) {
                batch.flush(&mut bt, n, &mut |cs: &[usize], sums: &[f64]| into(&mut gram, cs, sums));
                batch.start(cols, idx, &segments(cols));
            }
            batch.add(&wg, &g, &vals);
            for (a, &j) in cols.iter().enumerate() {
                for (b, &i) in idx.iter().enumerate() {
                    want_bt[j * n + i] += wg[a] * vals[b];
                }
                for (b, &l) in cols.iter().enumerate() {
                    if (j < 3) == (l < 3) {
                        want_gram[j * k + l] += wg[a] * g[b];
                    }
                }
            }
        }
        batch.flush(&mut bt, n, &mut |cs: &[usize], sums: &[f64]| into(&mut gram, cs, sums));
        for (i, (got, want)) in bt.iter().zip(&want_bt).enumerate() {
            assert!((got - want).abs() <= 1e-12 * want.abs().max(1.0), "bt[{i}]: {got} vs {want}");
        }
        for (i, (got, want)) in gram.iter().zip(&want_gram).enumerate() {
            assert!((got - want).abs() <= 1e-12 * want.abs().max(1.0), "gram[{i}]: {got} vs {want}");
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
