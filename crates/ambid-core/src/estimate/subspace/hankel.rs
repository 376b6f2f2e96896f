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
//! the chunked QR is used.

use super::qr_stream::StreamingQr;
use crate::error::{Error, Result};
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

#[cfg(test)]
mod tests {
    use super::*;

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
