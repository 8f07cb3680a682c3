//! The subspace allowed by equality constraints `C d = 0`, kept implicitly as the Householder QR
//! of `C^T` (faer). With `C^T = Q R`, the last `n - c` columns of `Q` span the null space `Z`;
//! products with `Z` are applied as block reflectors in `O(n^2 c)` instead of forming `Z`, which
//! matters because `c` (the gauge, 24 rows) is much smaller than `n`.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::householder as hh;
use faer::{Conj, Mat, MatMut, Par};

pub(crate) struct NullSpace {
    basis: Mat<f64>,
    factor: Mat<f64>,
    n: usize,
    c: usize,
}

impl NullSpace {
    /// Null space of the rows of `c` (full row rank), each column `j` divided by `scale[j]`.
    pub fn new(c: &Mat<f64>, scale: &[f64]) -> NullSpace {
        let n = c.ncols();
        let m = c.nrows();
        let ct = Mat::from_fn(n, m, |i, j| c[(j, i)] / scale[i]);
        let qr = ct.qr();
        NullSpace { basis: qr.Q_basis().to_owned(), factor: qr.Q_coeff().to_owned(), n, c: m }
    }

    /// Dimension of the null space.
    pub fn dim(&self) -> usize {
        self.n - self.c
    }

    fn scratch(&self, ncols: usize) -> MemBuffer {
        let bs = self.factor.nrows();
        let req = hh::apply_block_householder_sequence_on_the_left_in_place_scratch::<f64>(self.n, bs, ncols)
            .or(hh::apply_block_householder_sequence_transpose_on_the_left_in_place_scratch::<f64>(self.n, bs, ncols))
            .or(hh::apply_block_householder_sequence_on_the_right_in_place_scratch::<f64>(self.n, bs, ncols))
            .or(hh::apply_block_householder_sequence_transpose_on_the_right_in_place_scratch::<f64>(self.n, bs, ncols));
        MemBuffer::new(req)
    }

    fn q_left(&self, m: MatMut<'_, f64>) {
        let mut buf = self.scratch(m.ncols());
        hh::apply_block_householder_sequence_on_the_left_in_place_with_conj(
            self.basis.as_ref(),
            self.factor.as_ref(),
            Conj::No,
            m,
            Par::Seq,
            MemStack::new(&mut buf),
        );
    }

    fn qt_left(&self, m: MatMut<'_, f64>) {
        let mut buf = self.scratch(m.ncols());
        hh::apply_block_householder_sequence_transpose_on_the_left_in_place_with_conj(
            self.basis.as_ref(),
            self.factor.as_ref(),
            Conj::No,
            m,
            Par::Seq,
            MemStack::new(&mut buf),
        );
    }

    fn q_right(&self, m: MatMut<'_, f64>) {
        let mut buf = self.scratch(m.nrows());
        hh::apply_block_householder_sequence_on_the_right_in_place_with_conj(
            self.basis.as_ref(),
            self.factor.as_ref(),
            Conj::No,
            m,
            Par::Seq,
            MemStack::new(&mut buf),
        );
    }

    fn qt_right(&self, m: MatMut<'_, f64>) {
        let mut buf = self.scratch(m.nrows());
        hh::apply_block_householder_sequence_transpose_on_the_right_in_place_with_conj(
            self.basis.as_ref(),
            self.factor.as_ref(),
            Conj::No,
            m,
            Par::Seq,
            MemStack::new(&mut buf),
        );
    }

    /// `Z^T A Z` for a symmetric `n x n` matrix `a`.
    pub fn project(&self, a: &Mat<f64>) -> Mat<f64> {
        let mut t = a.clone();
        self.qt_left(t.as_mut());
        self.q_right(t.as_mut());
        let k = self.dim();
        let mut m = t.submatrix(self.c, self.c, k, k).to_owned();
        for j in 0..k {
            for i in 0..j {
                let v = 0.5 * (m[(i, j)] + m[(j, i)]);
                m[(i, j)] = v;
                m[(j, i)] = v;
            }
        }
        m
    }

    /// `Z^T x` for columns `x` (n rows).
    pub fn zt(&self, x: &Mat<f64>) -> Mat<f64> {
        let mut t = x.clone();
        self.qt_left(t.as_mut());
        t.subrows(self.c, self.dim()).to_owned()
    }

    /// `Z y` for columns `y` (n - c rows).
    pub fn z(&self, y: &Mat<f64>) -> Mat<f64> {
        let mut t = Mat::<f64>::zeros(self.n, y.ncols());
        t.subrows_mut(self.c, self.dim()).copy_from(y);
        self.q_left(t.as_mut());
        t
    }

    /// `Z B Z^T` for a symmetric `(n - c) x (n - c)` matrix `b`.
    pub fn embed(&self, b: &Mat<f64>) -> Mat<f64> {
        let mut t = Mat::<f64>::zeros(self.n, self.n);
        t.submatrix_mut(self.c, self.c, self.dim(), self.dim()).copy_from(b);
        self.q_left(t.as_mut());
        self.qt_right(t.as_mut());
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_explicit_basis() {
        for (n, m) in [(9, 3), (147, 24), (273, 24), (400, 60)] {
            check(n, m);
        }
    }

    fn check(n: usize, nc: usize) {
        let c = Mat::from_fn(nc, n, |i, j| {
            ((i * 7 + j * 3) % 5) as f64 - 1.5 + if i == j { 2.0 } else { 0.0 } + if j % nc == i { 1.0 } else { 0.0 }
        });
        let scale: Vec<f64> = (0..n).map(|j| 1.0 + j as f64 * 0.1).collect();
        let ns = NullSpace::new(&c, &scale);
        let ct = Mat::from_fn(n, nc, |i, j| c[(j, i)] / scale[i]);
        // Z has orthonormal columns orthogonal to the scaled constraint rows.
        let eye = Mat::<f64>::identity(ns.dim(), ns.dim());
        let z = ns.z(&eye);
        let ztz = z.transpose() * &z;
        let cz = ct.transpose() * &z;
        for i in 0..ns.dim() {
            for j in 0..ns.dim() {
                assert!((ztz[(i, j)] - if i == j { 1.0 } else { 0.0 }).abs() < 1e-10, "n {n}: Z^T Z ({i}, {j})");
            }
            for k in 0..nc {
                assert!(cz[(k, i)].abs() < 1e-10, "n {n}: constraint {k} on column {i}: {}", cz[(k, i)]);
            }
        }
        let a = Mat::from_fn(n, n, |i, j| 1.0 / (1.0 + i as f64 + j as f64));
        let m = ns.project(&a);
        let m2 = z.transpose() * &a * &z;
        let b = Mat::from_fn(ns.dim(), ns.dim(), |i, j| if i == j { 2.0 } else { 0.1 });
        let e = ns.embed(&b);
        let e2 = &z * &b * z.transpose();
        for i in 0..ns.dim() {
            for j in 0..ns.dim() {
                assert!(
                    (m[(i, j)] - m2[(i, j)]).abs() < 1e-10,
                    "n {n}: project ({i}, {j}) {} vs {}",
                    m[(i, j)],
                    m2[(i, j)]
                );
            }
        }
        for i in 0..n {
            for j in 0..n {
                assert!((e[(i, j)] - e2[(i, j)]).abs() < 1e-10, "n {n}: embed ({i}, {j})");
            }
        }
    }
}
