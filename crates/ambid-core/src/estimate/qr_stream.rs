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

/// The upper-triangular $R$ ($\min(m, n) \times n$, $R^\top R = A^\top A$ up to rounding) of a
/// small tall matrix by unblocked Householder QR (LAPACK's `dgeqr2` without keeping the
/// reflectors), factored in place.
///
/// Column $c$'s reflector $H_c = I - \tau v v^\top$ with $v = x - \alpha e_1$,
/// $\alpha = -\operatorname{sign}(x_1)\lVert x\rVert$ and
/// $\tau = 2 / v^\top v = 1 / (\lVert x\rVert(\lVert x\rVert + |x_1|))$ maps the column's
/// part $x$ from row $c$ down to $\alpha e_1$, and is applied to every later column as one dot
/// product and one update. Every column gets its reflector (none is skipped as dependent, unlike
/// [`r_factor`]): a column that depends on the earlier ones leaves a diagonal entry at the
/// rounding level, and an exactly zero part leaves zeros, so the factor is upper triangular as
/// it stands and $R^\top R$ keeps the Gram matrix. Such a reflector turns an arbitrary
/// direction, though, so when a leading column is dependent the trailing block is *not* the
/// later columns projected off the leading ones (the Schur complement); where that block is
/// read, [`r_factor`] (which leaves a dependent column's row at zero) is the one to use. This
/// one is meant for factors whose whole Gram matrix is used: stacked and factored once more (the structured triangle of the MIMO frequency fit, whose
/// $506 \times 49$ blocks it factors about twice as fast as faer's blocked QR, which also forms
/// the blocked reflectors' triangular factors the $R$ alone does not need).
///
/// The dot products sum in a fixed order over eight partial sums, with the same IEEE operations
/// whether the AVX2 build of the loop runs or not, so the result is the same bits on every
/// x86-64 CPU.
pub(crate) fn r_factor_tall(w: Mat<f64>) -> Mat<f64> {
    let (m, n) = (w.nrows(), w.ncols());
    // column-major and contiguous, so that four columns can be borrowed at once
    let mut buf: Vec<f64> = Vec::with_capacity(m * n);
    for j in 0..n {
        buf.extend_from_slice(w.col_as_slice(j));
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 was detected on this CPU just above.
        unsafe { householder_avx2(&mut buf, m, n) };
        return upper(&buf, m, n);
    }
    householder_base(&mut buf, m, n);
    upper(&buf, m, n)
}

/// The upper $\min(m, n) \times n$ part of a factored column-major $m \times n$ buffer, zeros
/// below the diagonal.
fn upper(w: &[f64], m: usize, n: usize) -> Mat<f64> {
    Mat::from_fn(m.min(n), n, |i, j| if j >= i { w[j * m + i] } else { 0.0 })
}

/// [`householder_base`] compiled for AVX2, its dot products with 256-bit registers
/// ([`dot8x4_avx2`]: the same operations in the same order, no FMA, so the same bits).
///
/// # Safety
/// Only on a CPU with AVX2 (`is_x86_feature_detected!("avx2")`).
#[cfg(target_arch = "x86_64")]
#[inline(never)]
#[target_feature(enable = "avx2")]
unsafe fn householder_avx2(w: &mut [f64], m: usize, n: usize) {
    // SAFETY: this function runs only where AVX2 was detected
    householder_with(w, m, n, |v, a| unsafe { dot8x4_avx2(v, a) })
}

/// The reflections of [`r_factor_tall`] applied in place to the column-major $m \times n$
/// buffer `w` (the $R$ on and above the diagonal).
fn householder_base(w: &mut [f64], m: usize, n: usize) {
    householder_with(w, m, n, |v, a| a.map(|a| dot8(v, a)))
}

/// Reflectors per panel of [`householder_with`].
const PANEL: usize = 4;

/// The reflections of [`r_factor_tall`], by panels of [`PANEL`] columns: a panel's columns are
/// reduced one after the other (each reflector applied at once to the panel's later columns),
/// then the panel's reflectors are applied to the later columns, four columns at a time and
/// all the panel's reflectors in order while those columns are in the first-level cache
/// (`dot4` gives $v^\top a_t$ for four columns at once, each summed exactly as [`dot8`] sums
/// it). Every column gets the same operations in the same order as when each reflector is
/// applied to all later columns before the next is formed, so the same bits; the panels only
/// save passes over the matrix.
#[inline(always)]
fn householder_with(
    w: &mut [f64],
    m: usize,
    n: usize,
    dot4: impl Fn(&[f64], [&[f64]; 4]) -> [f64; 4],
) {
    let kmax = m.min(n);
    // the panel's reflectors: v_c (rows c..m) at vs[(c - p0) * m..][..m - c], and tau_c
    let mut vs = vec![0.0; PANEL * m];
    let mut taus = [0.0; PANEL];
    let mut p0 = 0;
    while p0 < kmax {
        let p1 = (p0 + PANEL).min(kmax);
        for c in p0..p1 {
            let (head, tail) = w.split_at_mut((c + 1) * m);
            let col = &mut head[c * m + c..];
            let norm = dot8(col, col).sqrt();
            let v = &mut vs[(c - p0) * m..][..m - c];
            if norm == 0.0 {
                // no reflection: a zero vector leaves every later column as it is
                v.fill(0.0);
                taus[c - p0] = 0.0;
                continue;
            }
            let x0 = col[0];
            let alpha = if x0 >= 0.0 { -norm } else { norm };
            v.copy_from_slice(col);
            v[0] = x0 - alpha;
            let tau = 1.0 / (norm * (norm + x0.abs()));
            taus[c - p0] = tau;
            col[0] = alpha;
            col[1..].fill(0.0);
            // the panel's later columns
            for a in tail[..(p1 - c - 1) * m].chunks_exact_mut(m) {
                reflect(&mut a[c..], v, tau);
            }
        }
        // the later columns, four at a time, every reflector of the panel in order
        let rest = &mut w[p1 * m..];
        let mut groups = rest.chunks_exact_mut(4 * m);
        for g in &mut groups {
            let (a0, g) = g.split_at_mut(m);
            let (a1, g) = g.split_at_mut(m);
            let (a2, a3) = g.split_at_mut(m);
            for c in p0..p1 {
                let tau = taus[c - p0];
                if tau == 0.0 {
                    continue;
                }
                let v = &vs[(c - p0) * m..][..m - c];
                let (b0, b1, b2, b3) = (&mut a0[c..], &mut a1[c..], &mut a2[c..], &mut a3[c..]);
                let d = dot4(v, [&*b0, &*b1, &*b2, &*b3]);
                for (a, d) in [b0, b1, b2, b3].into_iter().zip(d) {
                    let s = -tau * d;
                    for (y, x) in a.iter_mut().zip(v) {
                        *y += s * *x;
                    }
                }
            }
        }
        for a in groups.into_remainder().chunks_exact_mut(m) {
            for c in p0..p1 {
                let tau = taus[c - p0];
                if tau != 0.0 {
                    reflect(&mut a[c..], &vs[(c - p0) * m..][..m - c], tau);
                }
            }
        }
        p0 = p1;
    }
}

/// $a \mathrel{-}= \tau (v^\top a)\, v$: one reflector applied to one column's part.
#[inline(always)]
fn reflect(a: &mut [f64], v: &[f64], tau: f64) {
    let s = -tau * dot8(v, a);
    for (y, x) in a.iter_mut().zip(v) {
        *y += s * *x;
    }
}

/// $a^\top b$ over eight partial sums (partial sum $t$ takes the products $8q + t$), summed
/// as $((s_0 + s_4) + (s_1 + s_5)) + ((s_2 + s_6) + (s_3 + s_7))$, then the remainder in order.
#[inline(always)]
fn dot8(a: &[f64], b: &[f64]) -> f64 {
    let n8 = a.len().min(b.len()) / 8 * 8;
    let mut acc = [0.0f64; 8];
    for (x, y) in a[..n8].chunks_exact(8).zip(b[..n8].chunks_exact(8)) {
        for t in 0..8 {
            acc[t] += x[t] * y[t];
        }
    }
    finish8(&acc, &a[n8..], &b[n8..])
}

/// The reduction of [`dot8`]'s partial sums and its remainder.
#[inline(always)]
fn finish8(acc: &[f64; 8], a: &[f64], b: &[f64]) -> f64 {
    let mut s = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (x, y) in a.iter().zip(b) {
        s += x * y;
    }
    s
}

/// [`dot8`] of `v` with four columns at once, each column's eight partial sums in two 256-bit
/// registers (the same products and sums as [`dot8`], so the same bits).
///
/// # Safety
/// Only inlined into a function compiled with AVX2 ([`householder_avx2`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn dot8x4_avx2(v: &[f64], a: [&[f64]; 4]) -> [f64; 4] {
    use std::arch::x86_64::{
        __m256d, _mm256_add_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_setzero_pd, _mm256_storeu_pd,
    };
    let len = a.iter().fold(v.len(), |l, c| l.min(c.len()));
    let n8 = len / 8 * 8;
    let pv = v.as_ptr();
    let pa = a.map(|c| c.as_ptr());
    let mut out = [0.0f64; 4];
    // SAFETY: every load reads v[i..i + 8] and a[t][i..i + 8] with i + 8 <= n8 <= every length
    unsafe {
        let mut lo: [__m256d; 4] = [_mm256_setzero_pd(); 4];
        let mut hi: [__m256d; 4] = [_mm256_setzero_pd(); 4];
        let mut i = 0;
        while i < n8 {
            let (x0, x1) = (_mm256_loadu_pd(pv.add(i)), _mm256_loadu_pd(pv.add(i + 4)));
            for t in 0..4 {
                let y0 = _mm256_mul_pd(x0, _mm256_loadu_pd(pa[t].add(i)));
                let y1 = _mm256_mul_pd(x1, _mm256_loadu_pd(pa[t].add(i + 4)));
                lo[t] = _mm256_add_pd(lo[t], y0);
                hi[t] = _mm256_add_pd(hi[t], y1);
            }
            i += 8;
        }
        for t in 0..4 {
            let mut acc = [0.0f64; 8];
            _mm256_storeu_pd(acc.as_mut_ptr(), lo[t]);
            _mm256_storeu_pd(acc.as_mut_ptr().add(4), hi[t]);
            out[t] = finish8(&acc, &v[n8..len], &a[t][n8..len]);
        }
    }
    out
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

    #[test]
    fn the_unblocked_factor_keeps_the_gram_matrix_and_is_the_same_bits_without_avx2() {
        // tall with one exactly dependent column, one zero column, wide, and empty shapes
        let mut cases = vec![dependent(506, 49), dependent(37, 9), dependent(6, 11)];
        let mut z = dependent(40, 7);
        for i in 0..40 {
            z[(i, 5)] = 0.0;
        }
        cases.push(z);
        cases.push(Mat::zeros(0, 4));
        for a in cases {
            let r = r_factor_tall(a.clone());
            let k = a.nrows().min(a.ncols());
            assert_eq!((r.nrows(), r.ncols()), (k, a.ncols()));
            for i in 0..k {
                for j in 0..i {
                    assert_eq!(r[(i, j)], 0.0, "below the diagonal at ({i}, {j})");
                }
            }
            // the naive Gram matrix as the oracle
            let g = a.transpose() * &a;
            let gr = r.transpose() * &r;
            let scale = g.norm_max().max(1.0);
            let err = (&g - &gr).norm_max() / scale;
            assert!(
                err < 1e-13,
                "{}x{}: Gram error {err:e}",
                a.nrows(),
                a.ncols()
            );
            // the portable loop gives the same bits as the dispatched one, and both the same
            // bits as the reflections applied one column at a time (an in-test oracle)
            let (m, n) = (a.nrows(), a.ncols());
            let mut b: Vec<f64> = (0..n).flat_map(|j| a.col_as_slice(j).to_vec()).collect();
            householder_base(&mut b, m, n);
            assert_eq!(upper(&b, m, n), r);
            assert_eq!(one_column_at_a_time(&a), r);
        }
        // a dependent column leaves its diagonal at the rounding level, as faer's factor does
        // after `retriangulate`
        let a = dependent(506, 49);
        let (r, rf) = (r_factor_tall(a.clone()), r_factor(a.as_ref()));
        assert!(r[(3, 3)].abs() < 1e-12 * r[(0, 0)].abs());
        assert!(rf[(3, 3)].abs() < 1e-12 * rf[(0, 0)].abs());
    }

    /// The unblocked Householder factor with every later column updated on its own (a dot
    /// product and an update per column, [`dot8`] as the sum): the reference for the bits of
    /// [`r_factor_tall`], which takes the columns four at a time.
    fn one_column_at_a_time(a: &Mat<f64>) -> Mat<f64> {
        let (m, n) = (a.nrows(), a.ncols());
        let mut w = a.clone();
        for c in 0..m.min(n) {
            let col: Vec<f64> = w.col_as_slice(c)[c..].to_vec();
            let norm = dot8(&col, &col).sqrt();
            if norm == 0.0 {
                continue;
            }
            let alpha = if col[0] >= 0.0 { -norm } else { norm };
            let mut v = col.clone();
            v[0] = col[0] - alpha;
            let tau = 1.0 / (norm * (norm + col[0].abs()));
            w[(c, c)] = alpha;
            for i in c + 1..m {
                w[(i, c)] = 0.0;
            }
            for j in c + 1..n {
                let cj = &mut w.col_as_slice_mut(j)[c..];
                let s = -tau * dot8(&v, cj);
                for (y, x) in cj.iter_mut().zip(&v) {
                    *y += s * *x;
                }
            }
        }
        Mat::from_fn(m.min(n), n, |i, j| if j >= i { w[(i, j)] } else { 0.0 })
    }

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
