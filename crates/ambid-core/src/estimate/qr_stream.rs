//! The R factor of a tall matrix whose rows arrive in chunks, in $O(p\,(p + c))$ memory.
//!
//! With $R_0 = 0$ and the rows of chunk $t$ stacked in $X_t$ ($c \times p$),
//! $$ \begin{bmatrix} R_{t-1} \\ X_t \end{bmatrix} = \tilde Q_t R_t $$
//! is a Householder QR of a $(p + c) \times p$ matrix. An orthogonal factor leaves the Gram matrix
//! unchanged, $R_t^\top R_t = R_{t-1}^\top R_{t-1} + X_t^\top X_t$, so the last $R_t$ is the R factor of
//! all rows stacked (up to the signs of its rows), with the backward stability of Householder QR on
//! the data themselves (no squared condition number). Work $\approx 2 N p^2 (1 + p / c)$ flops for
//! $N$ rows.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::factor::{
    qr_in_place, qr_in_place_scratch, recommended_block_size,
};
use faer::{Mat, MatMut, MatRef, Par};

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
        qr_in_place(
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
