//! The triangular factor of the block-Hankel data matrix, computed in bounded memory.
//!
//! With $j = N - 2i + 1$ columns, the stacked data matrix
//! $$ H = \begin{bmatrix} U_{i|2i-1} \\ U_{0|i-1} \\ Y_{0|2i-1} \end{bmatrix}
//!    \in \mathbb R^{d \times j}, \qquad d = 2i(m + l), $$
//! has as its column $k$ the vector $[u_{k+i}; \dots; u_{k+2i-1}; u_k; \dots; u_{k+i-1};
//! y_k; \dots; y_{k+2i-1}]$. Its LQ factorisation $H / \sqrt j = L\,Q^\top$ ($L$ lower triangular,
//! $Q^\top Q = I$) is the QR factorisation $H^\top = Q R$, $L = R^\top / \sqrt j$. The rows of
//! $H^\top$ are streamed in chunks of `c` rows: with $R_0 = 0$,
//! $$ \begin{bmatrix} R_{t-1} \\ H_t^\top \end{bmatrix} = \tilde Q_t R_t, $$
//! which is a Householder QR of a $(d + c) \times d$ matrix. Because an orthogonal factor does not
//! change the Gram matrix, $R_t^\top R_t = R_{t-1}^\top R_{t-1} + H_t H_t^\top$, so the final $R$ is
//! the R factor of the whole $H^\top$ (up to the signs of its rows). Work $\approx 2 j d^2 (1 +
//! d/c)$ flops, memory $O(d (d + c))$, independent of $N$: neither $H$ nor $Q$ is ever formed.
//!
//! Householder QR is backward stable on $H^\top$ itself, so the small singular values of $H$ (the
//! noise floor, or the rank deficiency of noise-free data) are resolved down to
//! $\approx \varepsilon \lVert H \rVert$. Accumulating the Gram matrix $H H^\top$ and taking its
//! Cholesky factor would cost the same order of work (a Toeplitz recursion even brings it to
//! $O(N d (m + l))$) but squares the condition number: directions below
//! $\sqrt\varepsilon \lVert H \rVert \approx 10^{-8} \lVert H \rVert$ would be lost, which is why
//! the chunked QR ([`lq_factor`]) is the accurate choice.
//!
//! The QR costs $O(N d^2)$, which grows with the square of the horizon: for strongly oversampled
//! data (a horizon of $i \approx 100$–$200$ samples) it takes seconds. [`gram_factor`] is the fast
//! alternative. Every entry of $H H^\top$ is a lagged product sum of two channels,
//! $S_{ab}(o_1, o_2) = \sum_{k=0}^{j-1} x_a[k + o_1]\, x_b[k + o_2]$, and along a diagonal
//! $$ S_{ab}(o_1 + 1, o_2 + 1) = S_{ab}(o_1, o_2) + x_a[j + o_1] x_b[j + o_2] - x_a[o_1] x_b[o_2], $$
//! so only the first row and column of each $2i \times 2i$ block need full sums: $O(N d (m + l))$
//! work instead of $O(N d^2)$. A Cholesky factorisation without pivoting (to keep the row order
//! that the projections rely on) then gives $L$; a pivot below $10^{-11}$ of the row's own
//! variance marks the row as linearly dependent on the rows above it and its column of $L$ is set
//! to zero, which is what the QR produces for rank-deficient (noise-free) data. The price is the
//! squared condition number: relative amplitudes below $\approx 3 \cdot 10^{-6}$ (the square
//! root of that threshold) are treated as exactly dependent, immaterial for measured data whose
//! noise is far above that level.

use crate::error::{Error, Result};
use crate::estimate::qr_stream::StreamingQr;
use faer::reborrow::ReborrowMut;
use faer::{Mat, MatRef};
use std::borrow::Cow;

/// Rows of $H^\top$ factorised per step, as a multiple of $d$ (and at least 256).
const CHUNK_PER_DIM: usize = 8;

/// Data layout of the block-Hankel rows: $i$ block rows, $m$ inputs, $l$ outputs.
#[derive(Debug, Clone, Copy)]
pub(super) struct Layout {
    pub i: usize,
    pub m: usize,
    pub l: usize,
}

impl Layout {
    /// Rows $d = 2i(m + l)$.
    pub fn dim(&self) -> usize {
        2 * self.i * (self.m + self.l)
    }
}

/// Channel `ch` as a slice: borrowed when the column is contiguous (column-major data), copied
/// otherwise.
fn channel(x: MatRef<'_, f64>, ch: usize) -> Cow<'_, [f64]> {
    match x.col(ch).try_as_col_major() {
        Some(c) => Cow::Borrowed(c.as_slice()),
        None => Cow::Owned(x.col(ch).iter().copied().collect()),
    }
}

/// $L$ ($d \times d$, lower triangular) with $H/\sqrt j = L Q^\top$ for the row order of the
/// module docs; every input channel `c` is divided by `su[c]`, every output by `sy[c]`.
///
/// `y` is $N \times l$, `u` is $N \times m$, with $N \ge 2i$ (checked by the caller).
pub(super) fn lq_factor(
    y: MatRef<'_, f64>,
    u: MatRef<'_, f64>,
    lay: Layout,
    sy: &[f64],
    su: &[f64],
) -> Result<Mat<f64>> {
    let Layout { i, m, l } = lay;
    let d = lay.dim();
    let n = y.nrows();
    let j = n + 1 - 2 * i;
    let mut qr = StreamingQr::new(d, (CHUNK_PER_DIM * d).max(256).min(j));
    let c = qr.chunk_rows();
    let yc: Vec<Cow<'_, [f64]>> = (0..l).map(|ch| channel(y, ch)).collect();
    let uc: Vec<Cow<'_, [f64]>> = (0..m).map(|ch| channel(u, ch)).collect();
    let mut k0 = 0;
    while k0 < j {
        let cc = c.min(j - k0);
        let mut w = qr.chunk_mut(cc);
        // column r of the chunk of H^T is a contiguous slice of one channel
        let mut fill = |r: usize, src: &[f64], offset: usize, scale: f64| {
            let start = k0 + offset;
            for (dst, s) in w
                .rb_mut()
                .col_mut(r)
                .iter_mut()
                .zip(&src[start..start + cc])
            {
                *dst = s / scale;
            }
        };
        for t in 0..i {
            for ch in 0..m {
                fill(t * m + ch, &uc[ch], i + t, su[ch]);
                fill(i * m + t * m + ch, &uc[ch], t, su[ch]);
            }
        }
        for t in 0..2 * i {
            for ch in 0..l {
                fill(2 * i * m + t * l + ch, &yc[ch], t, sy[ch]);
            }
        }
        qr.absorb(cc);
        k0 += cc;
    }
    let r = qr.finish();
    let scale = 1.0 / (j as f64).sqrt();
    let lmat = Mat::from_fn(d, d, |row, col| {
        if col <= row {
            r[(col, row)] * scale
        } else {
            0.0
        }
    });
    for col in 0..d {
        for row in col..d {
            if !lmat[(row, col)].is_finite() {
                return Err(Error::numerical(
                    "n4sid",
                    "the QR factorisation of the data produced non-finite values; rescale the data",
                ));
            }
        }
    }
    Ok(lmat)
}

/// The same $L$ as [`lq_factor`] (up to rounding and the signs of its columns) from the Gram
/// matrix and a semidefinite Cholesky factorisation (module docs).
pub(super) fn gram_factor(
    y: MatRef<'_, f64>,
    u: MatRef<'_, f64>,
    lay: Layout,
    sy: &[f64],
    su: &[f64],
) -> Result<Mat<f64>> {
    let Layout { i, m, l } = lay;
    let d = lay.dim();
    let n = y.nrows();
    let j = n + 1 - 2 * i;
    let w = 2 * i;
    // channels (inputs first, then outputs), read in place when column-major, and their scales
    let x: Vec<Cow<'_, [f64]>> = (0..m)
        .map(|c| channel(u, c))
        .chain((0..l).map(|c| channel(y, c)))
        .collect();
    let scale: Vec<f64> = su.iter().chain(sy).copied().collect();
    let ns = m + l;
    // first rows: lags[(a, b)][o] = S_ab(0, o)
    let lags: Vec<Vec<f64>> = (0..ns * ns)
        .map(|ab| lagged_sums(&x[ab / ns], &x[ab % ns], j, w))
        .collect();
    // s[(a, b)][o1 * w + o2] = S_ab(o1, o2)
    let mut s = vec![vec![0.0; w * w]; ns * ns];
    for a in 0..ns {
        for b in 0..ns {
            let t = &mut s[a * ns + b];
            let (xa, xb) = (&x[a], &x[b]);
            for o in 0..w {
                t[o] = lags[a * ns + b][o];
                // S_ab(o, 0) = S_ba(0, o)
                t[o * w] = lags[b * ns + a][o];
            }
            for o1 in 0..w - 1 {
                for o2 in 0..w - 1 {
                    t[(o1 + 1) * w + o2 + 1] =
                        t[o1 * w + o2] + xa[j + o1] * xb[j + o2] - xa[o1] * xb[o2];
                }
            }
        }
    }
    // row r of H: (channel, offset)
    let row = |r: usize| -> (usize, usize) {
        if r < i * m {
            (r % m, i + r / m)
        } else if r < 2 * i * m {
            ((r - i * m) % m, (r - i * m) / m)
        } else {
            (m + (r - 2 * i * m) % l, (r - 2 * i * m) / l)
        }
    };
    let jf = j as f64;
    let g = Mat::from_fn(d, d, |r, q| {
        let ((a, o1), (b, o2)) = (row(r), row(q));
        s[a * ns + b][o1 * w + o2] / (jf * scale[a] * scale[b])
    });
    // semidefinite Cholesky without pivoting, computed as the upper factor U = Lᵀ stored by
    // columns, so that every inner product runs over contiguous memory
    let mut uf = vec![0.0; d * d];
    for k in 0..d {
        let gkk = g[(k, k)];
        let colk = &mut uf[k * d..(k + 1) * d];
        let p = gkk - dot(&colk[..k], &colk[..k]);
        if !p.is_finite() {
            return Err(Error::numerical(
                "n4sid",
                "the Gram matrix of the data is not finite; rescale the data",
            ));
        }
        if gkk <= 0.0 || p <= GRAM_PIVOT_TOL * gkk {
            // the row depends on the rows above: its column of L stays zero
            continue;
        }
        let piv = p.sqrt();
        colk[k] = piv;
        // U[k, r] for r > k: (G[k, r] − U[:k, k]·U[:k, r]) / piv
        for r in k + 1..d {
            let (left, right) = uf.split_at_mut(r * d);
            let ck = &left[k * d..k * d + k];
            let cr = &mut right[..d];
            cr[k] = (g[(r, k)] - dot(ck, &cr[..k])) / piv;
        }
    }
    Ok(Mat::from_fn(
        d,
        d,
        |r, c| if c <= r { uf[r * d + c] } else { 0.0 },
    ))
}

/// $\sum_{k<j} a_k b_{k+o}$ for $o = 0, \dots, w-1$, as one axpy per $k$ (contiguous in $o$, so it
/// vectorises).
fn lagged_sums(a: &[f64], b: &[f64], j: usize, w: usize) -> Vec<f64> {
    let mut acc = vec![0.0; w];
    for (k, &ak) in a[..j].iter().enumerate() {
        for (s, &bv) in acc.iter_mut().zip(&b[k..k + w]) {
            *s += ak * bv;
        }
    }
    acc
}

/// Inner product with four partial sums (vectorisable).
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut s = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for t in 0..4 {
            s[t] += x[t] * y[t];
        }
    }
    let tail: f64 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

/// Relative pivot below which [`gram_factor`] treats a row as dependent.
const GRAM_PIVOT_TOL: f64 = 1e-11;

#[cfg(test)]
mod tests {
    use super::*;

    /// Pseudo-random numbers in [-1, 1) from a 64-bit LCG.
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (*state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// On well-conditioned data both factors give the same L up to column signs.
    #[test]
    fn gram_factor_matches_the_qr_factor() {
        let n = 900;
        let (i, m, l) = (4, 1, 2);
        let mut st = 7u64;
        let u = Mat::from_fn(n, m, |_, _| lcg(&mut st));
        let mut y = Mat::<f64>::zeros(n, l);
        for k in 1..n {
            y[(k, 0)] = 0.8 * y[(k - 1, 0)] + u[(k - 1, 0)] + 0.1 * lcg(&mut st);
            y[(k, 1)] = -0.5 * y[(k - 1, 1)] + y[(k - 1, 0)] + 0.1 * lcg(&mut st);
        }
        let lay = Layout { i, m, l };
        let (sy, su) = ([1.5, 0.7], [0.6]);
        let a = lq_factor(y.as_ref(), u.as_ref(), lay, &sy, &su).unwrap();
        let b = gram_factor(y.as_ref(), u.as_ref(), lay, &sy, &su).unwrap();
        let d = lay.dim();
        let scale = a.norm_max();
        for c in 0..d {
            let sign = if a[(c, c)] * b[(c, c)] < 0.0 {
                -1.0
            } else {
                1.0
            };
            for r in c..d {
                assert!(
                    (a[(r, c)] - sign * b[(r, c)]).abs() < 1e-11 * scale,
                    "({r}, {c}): {} vs {}",
                    a[(r, c)],
                    b[(r, c)]
                );
            }
        }
    }

    /// On noise-free data (exactly dependent rows) the Gram route drops the dependent rows and
    /// still reproduces the Gram matrix.
    #[test]
    fn gram_factor_of_rank_deficient_data() {
        let n = 600;
        let (i, m, l) = (5, 1, 1);
        let mut st = 11u64;
        let u = Mat::from_fn(n, m, |_, _| lcg(&mut st));
        let mut y = Mat::<f64>::zeros(n, l);
        for k in 2..n {
            y[(k, 0)] = 1.2 * y[(k - 1, 0)] - 0.5 * y[(k - 2, 0)] + u[(k - 1, 0)];
        }
        let lay = Layout { i, m, l };
        let b = gram_factor(y.as_ref(), u.as_ref(), lay, &[1.0], &[1.0]).unwrap();
        let a = lq_factor(y.as_ref(), u.as_ref(), lay, &[1.0], &[1.0]).unwrap();
        let (ga, gb) = (&a * a.transpose(), &b * b.transpose());
        assert!((&ga - &gb).norm_max() < 1e-12 * ga.norm_max());
        // 2i inputs and n = 2 states span the rows: the rest are dependent
        let rank = (0..lay.dim()).filter(|&k| b[(k, k)] != 0.0).count();
        assert_eq!(rank, 2 * i * m + 2);
    }

    /// The factor reproduces the Gram matrix of the explicitly built Hankel matrix.
    #[test]
    fn gram_matches_explicit_hankel() {
        let n = 700;
        let (i, m, l) = (3, 2, 1);
        let u = Mat::from_fn(n, m, |k, c| ((k * 7 + c * 3) as f64 * 0.37).sin());
        let y = Mat::from_fn(n, l, |k, _| ((k * k) as f64 * 0.011).cos() + 0.1);
        let lay = Layout { i, m, l };
        let d = lay.dim();
        let su = [2.0, 0.5];
        let sy = [3.0];
        let lm = lq_factor(y.as_ref(), u.as_ref(), lay, &sy, &su).unwrap();
        let j = n + 1 - 2 * i;
        let h = Mat::from_fn(d, j, |r, k| {
            if r < i * m {
                let (t, c) = (r / m, r % m);
                u[(k + i + t, c)] / su[c]
            } else if r < 2 * i * m {
                let (t, c) = ((r - i * m) / m, (r - i * m) % m);
                u[(k + t, c)] / su[c]
            } else {
                let (t, c) = ((r - 2 * i * m) / l, (r - 2 * i * m) % l);
                y[(k + t, c)] / sy[c]
            }
        });
        let g = &h * h.transpose();
        let g2 = &lm * lm.transpose();
        let jf = j as f64;
        let scale = g.norm_max() / jf;
        for a in 0..d {
            for b in 0..d {
                assert!((g[(a, b)] / jf - g2[(a, b)]).abs() < 1e-13 * scale);
            }
        }
    }
}
