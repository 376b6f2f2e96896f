//! The R factor of a tall matrix whose rows arrive in chunks, in $O(p\,(p + c))$ memory.
//!
//! With $R_0 = 0$ and the rows of chunk $t$ stacked in $X_t$ ($c \times p$),
//! $$ \begin{bmatrix} R_{t-1} \\ X_t \end{bmatrix} = \tilde Q_t R_t $$
//! is a Householder QR of a $(p + c) \times p$ matrix. An orthogonal factor leaves the Gram matrix
//! unchanged, $R_t^\top R_t = R_{t-1}^\top R_{t-1} + X_t^\top X_t$, so the last $R_t$ is the R factor of
//! all rows stacked (up to the signs of its rows), with the backward stability of Householder QR on
//! the data themselves (no squared condition number). Work $\approx 2 N p^2 (1 + p / c)$ flops for
//! $N$ rows.
//!
//! # Dependent columns
//! faer's Householder QR (0.24) treats a column whose part below the current row is under its
//! rank tolerance ($16\,\varepsilon$ times the rows left times the column's norm) as
//! dependent: it leaves that column's reflector out and places the *next* column's reflector on
//! the same row. The factor of a rank-deficient matrix is then in row-echelon form, not upper
//! triangular: the entries of the columns after the dependent one sit one row too high, their
//! diagonal reads zero, and a caller that reads $R$ as a triangle (a triangular solve, the
//! last column of $[J\;r]$ as the least-squares residual $\rho$) reads the wrong numbers. (On a
//! Jacobian with one dependent column, the Levenberg–Marquardt triangle read $\rho = 0$: the
//! Gauss–Newton model promised the whole cost, and the significance stop could never fire.)
//! [`StreamingQr`] and [`r_factor`] therefore move each row of such a factor down to its
//! column's row ([`retriangulate`]), so that $R$ is upper triangular with a zero diagonal
//! entry (and row) for each dependent column and $R^\top R$ is unchanged.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::factor::{
    qr_in_place, qr_in_place_scratch, recommended_block_size,
};
use faer::{Mat, MatMut, MatRef, Par};

/// Brings faer's row-echelon factor (module docs, "Dependent columns") to upper-triangular
/// form in place. `r` ($k \times n$, $k = \min(m, n)$) holds the factor's upper part (zeros
/// below the diagonal) of an $m$-row matrix, `rank` is what faer reported. The columns faer
/// skipped are found by its own rule replayed on the final factor (the head
/// $|r_{\text{row},j}|$ of column $j$ is at most $16\,\varepsilon\,(m - \text{row})$ times
/// the column's norm down to that row; the entries above a row are final once it is placed);
/// each placed row then moves down to its column's row, the rows of skipped columns are zero
/// and the skipped columns' heads (below the tolerance) are dropped. $R^\top R$ is unchanged up
/// to that tolerance. When the replay does not count `rank` placed columns, `r` is left as it
/// was.
pub(crate) fn retriangulate(mut r: MatMut<'_, f64>, m: usize, rank: usize) {
    let (k, n) = (r.nrows(), r.ncols());
    let eps = f64::EPSILON;
    // pivot column of each placed row
    let mut piv = Vec::with_capacity(k);
    let mut row = 0;
    for col in 0..n {
        if row >= k {
            break;
        }
        let head = r[(row, col)].abs();
        let above = (0..row)
            .map(|i| r[(i, col)] * r[(i, col)])
            .sum::<f64>()
            .sqrt();
        let threshold = eps * (16 * (m - row)) as f64 * head.hypot(above);
        if head > threshold {
            piv.push(col);
            row += 1;
        }
    }
    if piv.len() != rank {
        return;
    }
    // rows move down only (piv[i] >= i), so the last one first
    for i in (0..piv.len()).rev() {
        let c = piv[i];
        for j in 0..n {
            let v = if j >= c { r[(i, j)] } else { 0.0 };
            r[(i, j)] = 0.0;
            if i != c || j >= c {
                r[(c, j)] = v;
            }
        }
    }
}

/// The upper-triangular $R$ ($\min(m, n) \times n$) of a QR factorisation of `a`
/// ($m \times n$), $R^\top R = A^\top A$ up to rounding, also when columns of `a` are
/// (numerically) dependent (module docs, "Dependent columns"; `a.qr().thin_R()` then returns
/// a row-echelon factor).
pub(crate) fn r_factor(a: MatRef<'_, f64>) -> Mat<f64> {
    r_factor_in_place(a.to_owned())
}

/// [`r_factor`] of an owned matrix, factored in place (no copy).
pub(crate) fn r_factor_in_place(mut w: Mat<f64>) -> Mat<f64> {
    let (m, n) = (w.nrows(), w.ncols());
    let k = m.min(n);
    if k == 0 {
        return Mat::zeros(k, n);
    }
    let bs = recommended_block_size::<f64>(m, n).max(1);
    let mut q_coeff = Mat::<f64>::zeros(bs, k);
    let mut mem = MemBuffer::new(qr_in_place_scratch::<f64>(
        m,
        n,
        bs,
        Par::Seq,
        Default::default(),
    ));
    let info = qr_in_place(
        w.as_mut(),
        q_coeff.as_mut(),
        Par::Seq,
        MemStack::new(&mut mem),
        Default::default(),
    );
    let mut r = Mat::from_fn(k, n, |i, j| if j >= i { w[(i, j)] } else { 0.0 });
    if info.rank < k {
        retriangulate(r.as_mut(), m, info.rank);
    }
    r
}

/// Streaming QR: push rows (or fill whole chunks), read the upper-triangular $R$.
pub(crate) struct StreamingQr {
    p: usize,
    c: usize,
    /// Top $p$ rows: $R$ (upper triangle, zeros below); next $c$ rows: the pending chunk.
    w: Mat<f64>,
    q_coeff: Mat<f64>,
    mem: MemBuffer,
    pending: usize,
}

impl StreamingQr {
    /// An empty factorisation of rows of width `p`, absorbed `c` rows at a time ($c \ge 1$).
    pub fn new(p: usize, c: usize) -> Self {
        let c = c.max(1);
        let bs = recommended_block_size::<f64>(p + c, p).max(1);
        Self {
            p,
            c,
            w: Mat::zeros(p + c, p),
            q_coeff: Mat::zeros(bs, p),
            mem: MemBuffer::new(qr_in_place_scratch::<f64>(
                p + c,
                p,
                bs,
                Par::Seq,
                Default::default(),
            )),
            pending: 0,
        }
    }

    /// Rows absorbed per QR step.
    pub fn chunk_rows(&self) -> usize {
        self.c
    }

    /// The next `rows` pending rows ($\le$ [`chunk_rows`](Self::chunk_rows)) to be filled
    /// completely by the caller and then committed with [`absorb`](Self::absorb). Only valid when
    /// nothing is pending from [`push_row`](Self::push_row).
    pub fn chunk_mut(&mut self, rows: usize) -> MatMut<'_, f64> {
        debug_assert!(self.pending == 0 && rows <= self.c);
        self.w.as_mut().subrows_mut(self.p, rows)
    }

    /// Folds the first `rows` pending rows into $R$.
    pub fn absorb(&mut self, rows: usize) {
        if rows == 0 || self.p == 0 {
            self.pending = 0;
            return;
        }
        let p = self.p;
        let info = qr_in_place(
            self.w.as_mut().subrows_mut(0, p + rows),
            self.q_coeff.as_mut(),
            Par::Seq,
            MemStack::new(&mut self.mem),
            Default::default(),
        );
        // keep R in the upper triangle of the top p rows; clear the Householder vectors
        for col in 0..p {
            for row in col + 1..p {
                self.w[(row, col)] = 0.0;
            }
        }
        if info.rank < p {
            retriangulate(self.w.as_mut().subrows_mut(0, p), p + rows, info.rank);
        }
        self.pending = 0;
    }

    /// Appends one row (length $p$).
    pub fn push_row(&mut self, row: &[f64]) {
        let r = self.p + self.pending;
        for (col, v) in row.iter().enumerate().take(self.p) {
            self.w[(r, col)] = *v;
        }
        self.pending += 1;
        if self.pending == self.c {
            self.absorb(self.c);
        }
    }

    /// Absorbs the pending rows and returns $R$ ($p \times p$, upper triangular).
    pub fn finish(&mut self) -> MatRef<'_, f64> {
        let rows = self.pending;
        self.absorb(rows);
        self.w.as_ref().subrows(0, self.p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tall matrix whose column 3 is 2·col 0 − col 2 (exactly dependent) and whose other
    /// columns are independent.
    fn dependent(m: usize, n: usize) -> Mat<f64> {
        let mut a = Mat::from_fn(m, n, |i, j| {
            ((i * 31 + j * 17) as f64 * 0.173).sin() * (1.0 + j as f64)
                + 0.3 * ((i * j) as f64 * 0.011).cos()
        });
        for i in 0..m {
            a[(i, 3)] = 2.0 * a[(i, 0)] - a[(i, 2)];
        }
        a
    }

    /// `r` is upper triangular, its Gram matrix is `a`'s, and its last diagonal entry is the
    /// least-squares residual of the last column on the others (the oracle: the normal
    /// equations of the independent columns, solved directly).
    fn check_triangle(a: &Mat<f64>, r: MatRef<'_, f64>) {
        let n = a.ncols();
        for i in 0..r.nrows() {
            for j in 0..i.min(n) {
                assert_eq!(r[(i, j)], 0.0, "entry ({i}, {j}) below the diagonal");
            }
        }
        let g = a.transpose() * a;
        let g2 = r.transpose() * r;
        assert!((&g - &g2).norm_max() < 1e-11 * g.norm_max());
        // the residual of the last column on the independent others (column 3 left out)
        let keep: Vec<usize> = (0..n - 1).filter(|&j| j != 3).collect();
        let x = Mat::from_fn(a.nrows(), keep.len(), |i, c| a[(i, keep[c])]);
        let y = Mat::from_fn(a.nrows(), 1, |i, _| a[(i, n - 1)]);
        let xtx = x.transpose() * &x;
        let coef = faer::prelude::Solve::solve(&xtx.partial_piv_lu(), x.transpose() * &y);
        let res = &y - &x * &coef;
        let rho = res.norm_l2();
        assert!(
            (r[(n - 1, n - 1)].abs() - rho).abs() < 1e-9 * rho,
            "rho {} against {rho}",
            r[(n - 1, n - 1)]
        );
        // the dependent column's diagonal is (numerically) zero, the others are not
        assert!(r[(3, 3)].abs() < 1e-10 * g[(3, 3)].sqrt());
        for j in (0..n).filter(|&j| j != 3) {
            assert!(r[(j, j)].abs() > 1e-3, "diagonal {j}: {}", r[(j, j)]);
        }
    }

    #[test]
    fn a_dependent_column_leaves_the_factor_triangular() {
        let (m, n) = (700, 12);
        let a = dependent(m, n);
        // faer's own factor is in row-echelon form here (the premise of the repair)
        let echelon = a.qr().thin_R().to_owned();
        assert_eq!(echelon[(n - 1, n - 1)], 0.0);
        check_triangle(&a, r_factor(a.as_ref()).as_ref());
        let mut s = StreamingQr::new(n, 64);
        for i in 0..m {
            let row: Vec<f64> = (0..n).map(|j| a[(i, j)]).collect();
            s.push_row(&row);
        }
        let r = s.finish().to_owned();
        check_triangle(&a, r.as_ref());
    }

    #[test]
    fn gram_of_pushed_rows() {
        let (n, p) = (1000, 5);
        let x = Mat::from_fn(n, p, |i, j| {
            ((i * 31 + j * 17) as f64 * 0.173).sin() + j as f64
        });
        let mut s = StreamingQr::new(p, 64);
        for i in 0..n {
            let row: Vec<f64> = (0..p).map(|j| x[(i, j)]).collect();
            s.push_row(&row);
        }
        let r = s.finish().to_owned();
        let g = x.transpose() * &x;
        let g2 = r.transpose() * &r;
        assert!((&g - &g2).norm_max() < 1e-12 * g.norm_max());
    }
}
