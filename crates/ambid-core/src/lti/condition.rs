//! A well-conditioned realisation for models whose near-equal poles carry large residues that
//! cancel.
//!
//! A fit in modal (pole–residue) form can put two poles a hair apart with residues that are huge
//! and nearly opposite: $R_i/(z-\lambda_i) + R_j/(z-\lambda_j)$ with $\lambda_i \approx
//! \lambda_j$ and $R_i \approx -R_j$, which is how a modal form writes a nearly double pole. Its
//! transfer function is accurate (every term is evaluated to working precision and the sum loses
//! only the cancelled digits), but its eigenvalue problems are not: the closed loop's state
//! matrix carries $B_p D_c C_p$ at the residues' size, and the eigenvalue solver's backward error
//! $\varepsilon \lVert A_{cl} \rVert$ moves the closed-loop poles by far more than the
//! model's content. On a fitted 4 × 4 machine model (linear machine rig 21, residues of 1.7
//! cancelling to $4\cdot10^{-6}$, poles $1.8\cdot10^{-9}$ apart) the closed-loop poles computed
//! from $A_{cl}$ put the loop's gain interval at 0.98…1.02, and a random similarity of the
//! same model moved it anywhere; evaluated in 50-digit arithmetic the loop is stable from 0.97
//! to 5.0.
//!
//! [`StateSpace::well_conditioned`] removes the cancellation by an exact similarity inside each
//! cluster of near-equal poles (see there).

use super::StateSpace;
use crate::linalg;
use faer::{c64, Mat};

/// Poles closer than this (relative to their modulus, at least 1) are one cluster.
const CLUSTER: f64 = 1e-4;
/// A combination is applied when it shrinks the state's input row to less than this fraction.
const SHRINK: f64 = 0.5;
/// Largest $\lVert V\rVert_F \lVert V^{-1}\rVert_F$ of the eigenvectors for which the modal
/// coordinates are formed (beyond it the matrix is (nearly) defective and is left as is).
const MAX_COND: f64 = 1e10;
/// Largest relative change of the frequency response the new realisation may show.
const TF_TOL: f64 = 1e-6;

impl StateSpace {
    /// The same model in a realisation without cancelling residues, or a copy when it has none.
    ///
    /// With the eigendecomposition $A = V \Lambda V^{-1}$ (on the balanced $A$) the model is
    /// $\hat G(\lambda) = D + \sum_k c_k b_k^{\mathsf T} / (\lambda - \lambda_k)$, $b_k^{\mathsf T}$
    /// the rows of $V^{-1}B$ and $c_k$ the columns of $CV$ (real for a real pole, one of each
    /// conjugate pair kept). Within each cluster of poles closer than $10^{-4}\max(1,
    /// |\lambda|)$, taken in order, each state $j$ is combined with each earlier state $k$ of
    /// its cluster by the similarity $T = I + t E_{jk}$,
    /// $$ t = \frac{b_k^{\mathsf H} b_j}{b_k^{\mathsf H} b_k}, \qquad
    ///    b_j \leftarrow b_j - t\, b_k, \quad c_k \leftarrow c_k + t\, c_j, \quad
    ///    A \leftarrow T^{-1} A T \;\bigl(A_{jk} \mathrel{+}= t(\lambda_j - \lambda_k)\bigr), $$
    /// when that shrinks $\lVert b_j\rVert$ below half: for residues that cancel, $b_j \approx
    /// -b_k$, and both $b_j$ and $c_k$ drop to the size of the cancelled sum, while the new
    /// coupling $t(\lambda_j - \lambda_k)$ is as small as the poles' distance. Each state is then
    /// scaled so that its row of $B$ and column of $C$ have one norm (a state whose input row
    /// the combination zeroed, so that it is reached through the coupling alone, to the mean
    /// of the others' norms), and the conjugate states
    /// are folded back into real $2\times2$ form ($\xi = x_r + j x_i$, $y = 2\operatorname{Re}
    /// C\xi$). The transfer function is unchanged in exact arithmetic; the result is checked
    /// against the original's frequency response on 200 frequencies (relative change at most
    /// $10^{-6}$).
    ///
    /// A copy of `self` is returned, bit for bit, when no cluster needed a combination, when
    /// the eigenvectors are (nearly) defective ($\lVert V\rVert_F\lVert V^{-1}\rVert_F >
    /// 10^{10}$, e.g. the repeated poles at $z = 0$ of a delay) or when the check fails.
    /// [`StateSpace::feedback_with_sign`] uses it for both of its parts, so that closed-loop
    /// poles do not depend on how a model happened to be realised.
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::StateSpace;
    /// use faer::mat;
    /// // 1/(z − 0.9) written as two poles 1e-9 apart with residues ±1e6 (+ a small remainder)
    /// let (p, e) = (0.9, 1e-9);
    /// let g = StateSpace::discrete(
    ///     mat![[p, 0.0], [0.0, p + e]],
    ///     mat![[1e3], [-1e3]],
    ///     mat![[1e3 + 1e-3, 1e3]],
    ///     mat![[0.0]],
    ///     1e-4,
    /// )
    /// .unwrap();
    /// let w = g.well_conditioned();
    /// let big = |m: faer::MatRef<'_, f64>| m.norm_max();
    /// assert!(big(w.b()) < 1.0 && big(w.c()) < 1.0);
    /// let (h0, h1) = (g.freq_response_siso(&[50.0]).unwrap(), w.freq_response_siso(&[50.0]).unwrap());
    /// assert!((h0[0] - h1[0]).norm() < 1e-6 * h0[0].norm());
    /// ```
    #[must_use]
    pub fn well_conditioned(&self) -> StateSpace {
        self.try_well_conditioned().unwrap_or_else(|| self.clone())
    }

    fn try_well_conditioned(&self) -> Option<StateSpace> {
        let n = self.order();
        if n < 2 {
            return None;
        }
        let (bal, d) = linalg::balance_with_scaling(self.a());
        let eig = bal.eigen().ok()?;
        let (u, s) = (eig.U(), eig.S());
        // V = D U, each real pole's eigenvector turned real (its largest entry real)
        let lam: Vec<c64> = (0..n).map(|k| s[k]).collect();
        let scale = lam.iter().map(|l| l.norm()).fold(1.0f64, f64::max);
        let is_real = |l: c64| l.im.abs() <= 1e-10 * scale;
        // the common case, no two poles in one cluster: nothing to combine, so no modal form
        let clustered = (0..n).any(|j| (0..j).any(|q| near(lam[j], lam[q])));
        if !clustered {
            return None;
        }
        let mut v = Mat::<c64>::from_fn(n, n, |i, k| u[(i, k)] * d[i]);
        for k in 0..n {
            if is_real(lam[k]) {
                let big = (0..n)
                    .map(|i| v[(i, k)])
                    .max_by(|a, b| a.norm().total_cmp(&b.norm()))?;
                let ph = big / big.norm();
                for i in 0..n {
                    v[(i, k)] /= ph;
                }
            }
        }
        let vi = linalg_inverse(&v)?;
        let cond = v.norm_l2() * vi.norm_l2();
        if !cond.is_finite() || cond > MAX_COND {
            return None;
        }
        let (m, p) = (self.ninputs(), self.noutputs());
        let bc = Mat::<c64>::from_fn(n, m, |i, j| c64::new(self.b()[(i, j)], 0.0));
        let cc = Mat::<c64>::from_fn(p, n, |i, j| c64::new(self.c()[(i, j)], 0.0));
        let bm = &vi * &bc;
        let cm = &cc * &v;
        let real: Vec<usize> = (0..n).filter(|&k| is_real(lam[k])).collect();
        let upper: Vec<usize> = (0..n)
            .filter(|&k| !is_real(lam[k]) && lam[k].im > 0.0)
            .collect();
        if 2 * upper.len() + real.len() != n {
            return None;
        }
        let mut parts = [
            Part::new(&real, &lam, &bm, &cm),
            Part::new(&upper, &lam, &bm, &cm),
        ];
        // both parts are combined (no short circuit)
        let done: Vec<bool> = parts.iter_mut().map(Part::combine).collect();
        let combined = done.contains(&true);
        if !combined {
            return None;
        }
        // assemble: real states, then each conjugate state as (re, im)
        let (nr, nh) = (parts[0].len(), parts[1].len());
        let mut a = Mat::<f64>::zeros(n, n);
        let mut b = Mat::<f64>::zeros(n, m);
        let mut c = Mat::<f64>::zeros(p, n);
        let r = &parts[0];
        for i in 0..nr {
            for k in 0..nr {
                a[(i, k)] = r.a[(i, k)].re;
            }
            for j in 0..m {
                b[(i, j)] = r.b[(i, j)].re;
            }
            for o in 0..p {
                c[(o, i)] = r.c[(o, i)].re;
            }
        }
        let h = &parts[1];
        for i in 0..nh {
            let (ri, ii) = (nr + i, nr + nh + i);
            for k in 0..nh {
                let (rk, ik) = (nr + k, nr + nh + k);
                let x = h.a[(i, k)];
                a[(ri, rk)] = x.re;
                a[(ri, ik)] = -x.im;
                a[(ii, rk)] = x.im;
                a[(ii, ik)] = x.re;
            }
            for j in 0..m {
                b[(ri, j)] = h.b[(i, j)].re;
                b[(ii, j)] = h.b[(i, j)].im;
            }
            for o in 0..p {
                c[(o, ri)] = 2.0 * h.c[(o, i)].re;
                c[(o, ii)] = -2.0 * h.c[(o, i)].im;
            }
        }
        let out = StateSpace::new(a, b, c, self.d().to_owned(), self.ts()).ok()?;
        self.same_response(&out).then_some(out)
    }

    /// Whether `other` has this model's frequency response to [`TF_TOL`] on 200 frequencies
    /// (log-spaced up to the Nyquist frequency, or over the poles' range in continuous time).
    fn same_response(&self, other: &StateSpace) -> bool {
        let (lo, hi) = match self.ts() {
            Some(ts) => (1e-5 / ts, 0.4999 / ts),
            None => {
                let mags: Vec<f64> = self
                    .poles()
                    .map(|v| v.iter().map(|z| z.norm()).filter(|x| *x > 0.0).collect())
                    .unwrap_or_default();
                let lo = mags.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = mags.iter().copied().fold(0.0f64, f64::max);
                if !(lo.is_finite() && hi > 0.0) {
                    (1e-3, 1e6)
                } else {
                    (
                        1e-3 * lo / std::f64::consts::TAU,
                        1e3 * hi / std::f64::consts::TAU,
                    )
                }
            }
        };
        let f: Vec<f64> = (0..200)
            .map(|k| lo * (hi / lo).powf(f64::from(k) / 199.0))
            .collect();
        let (Ok(g0), Ok(g1)) = (self.freq_response(&f), other.freq_response(&f)) else {
            return false;
        };
        g0.iter().zip(&g1).all(|(x, y)| {
            let diff = (x - y).norm_l2();
            diff.is_finite() && diff <= TF_TOL * x.norm_l2()
        })
    }
}

/// The states of one kind (real poles, or one of each conjugate pair) in modal coordinates.
struct Part {
    lam: Vec<c64>,
    a: Mat<c64>,
    b: Mat<c64>,
    c: Mat<c64>,
}

impl Part {
    /// The states `idx` of the modal form, ordered by their pole (so a cluster is contiguous).
    fn new(idx: &[usize], lam: &[c64], bm: &Mat<c64>, cm: &Mat<c64>) -> Self {
        let mut idx = idx.to_vec();
        idx.sort_by(|&x, &y| {
            lam[x]
                .re
                .total_cmp(&lam[y].re)
                .then(lam[x].im.total_cmp(&lam[y].im))
        });
        let k = idx.len();
        Part {
            lam: idx.iter().map(|&i| lam[i]).collect(),
            a: Mat::from_fn(k, k, |i, j| {
                if i == j {
                    lam[idx[i]]
                } else {
                    c64::new(0.0, 0.0)
                }
            }),
            b: Mat::from_fn(k, bm.ncols(), |i, j| bm[(idx[i], j)]),
            c: Mat::from_fn(cm.nrows(), k, |o, i| cm[(o, idx[i])]),
        }
    }

    fn len(&self) -> usize {
        self.lam.len()
    }

    /// The combinations within clusters and the final scaling (see
    /// [`StateSpace::well_conditioned`]); whether any combination was made.
    fn combine(&mut self) -> bool {
        let k = self.len();
        let m = self.b.ncols();
        let row_norm =
            |b: &Mat<c64>, i: usize| (0..m).map(|j| b[(i, j)].norm_sqr()).sum::<f64>().sqrt();
        let mut any = false;
        for j in 1..k {
            for q in 0..j {
                let (lj, lq) = (self.lam[j], self.lam[q]);
                if !near(lj, lq) {
                    continue;
                }
                let nq: f64 = (0..m).map(|i| self.b[(q, i)].norm_sqr()).sum();
                if nq <= 0.0 || !nq.is_finite() {
                    continue;
                }
                let dot: c64 = (0..m).map(|i| self.b[(q, i)].conj() * self.b[(j, i)]).sum();
                let t = dot / nq;
                let before = row_norm(&self.b, j);
                let after = (0..m)
                    .map(|i| (self.b[(j, i)] - t * self.b[(q, i)]).norm_sqr())
                    .sum::<f64>()
                    .sqrt();
                if after.is_nan() || after >= SHRINK * before {
                    continue;
                }
                // T = I + t E_jq: T⁻¹ A T, T⁻¹ B, C T
                for col in 0..k {
                    let x = self.a[(q, col)];
                    self.a[(j, col)] -= t * x;
                }
                for row in 0..k {
                    let x = self.a[(row, j)];
                    self.a[(row, q)] += t * x;
                }
                for i in 0..m {
                    let x = self.b[(q, i)];
                    self.b[(j, i)] -= t * x;
                }
                for o in 0..self.c.nrows() {
                    let x = self.c[(o, j)];
                    self.c[(o, q)] += t * x;
                }
                any = true;
            }
        }
        if any {
            let col_norm = |c: &Mat<c64>, i: usize| {
                (0..c.nrows())
                    .map(|o| c[(o, i)].norm_sqr())
                    .sum::<f64>()
                    .sqrt()
            };
            let norms: Vec<(f64, f64)> = (0..k)
                .map(|i| (row_norm(&self.b, i), col_norm(&self.c, i)))
                .collect();
            // a state seen from both sides gets |b| = |c| = √(|b||c|); one seen from one side
            // only (a combination can zero its input row) gets the mean of those
            let both: Vec<f64> = norms
                .iter()
                .filter(|(nb, nc)| *nb > 0.0 && *nc > 0.0)
                .map(|(nb, nc)| (nb * nc).sqrt())
                .collect();
            let target = if both.is_empty() {
                1.0
            } else {
                both.iter().sum::<f64>() / both.len() as f64
            };
            for (i, &(nb, nc)) in norms.iter().enumerate() {
                let s = match (nb > 0.0, nc > 0.0) {
                    (true, true) => (nb / nc).sqrt(),
                    (true, false) => nb / target,
                    (false, true) => target / nc,
                    (false, false) => 1.0,
                };
                if !(s.is_finite() && s > 0.0) {
                    continue;
                }
                for col in 0..k {
                    if col != i {
                        self.a[(i, col)] /= s;
                        self.a[(col, i)] *= s;
                    }
                }
                for j in 0..m {
                    self.b[(i, j)] /= s;
                }
                for o in 0..self.c.nrows() {
                    self.c[(o, i)] *= s;
                }
            }
        }
        any
    }
}

/// Whether two poles are in one cluster: closer than [`CLUSTER`] relative to their modulus (at
/// least 1).
fn near(a: c64, b: c64) -> bool {
    (a - b).norm() <= CLUSTER * a.norm().max(b.norm()).max(1.0)
}

/// The inverse of a complex square matrix by LU with full pivoting; `None` when it is not
/// finite.
fn linalg_inverse(v: &Mat<c64>) -> Option<Mat<c64>> {
    use faer::linalg::solvers::DenseSolveCore;
    let inv = v.full_piv_lu().inverse();
    let finite = (0..inv.nrows()).all(|i| (0..inv.ncols()).all(|j| inv[(i, j)].is_finite()));
    finite.then_some(inv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validate::robust::nominal_gain_interval;
    use faer::mat;

    const TS: f64 = 1e-4;

    /// An unstable plant $1/(s^2 - 400^2)$ (ZOH) plus a stable, nearly double pole at
    /// $z = 0.99$ in chain form $\xi_1^+ = p\,\xi_1 + u$, $\xi_2^+ = \kappa\xi_1 + (p +
    /// \varepsilon)\xi_2$, $y \mathrel{+}= \gamma(\xi_1 + \xi_2)$ (a well-conditioned
    /// realisation), and a lead controller $k(1 + s/\omega_d)/(1 + s/(10\omega_d))$ (Tustin).
    /// Returns the plant in that realisation, the same plant in the modal form of the chain
    /// (residues $\approx \pm\gamma\kappa/\varepsilon$ that cancel), and the controller.
    fn loop_with_a_near_double_pole() -> (StateSpace, StateSpace, StateSpace) {
        let pc = StateSpace::continuous(
            mat![[0.0, 1.0], [160_000.0, 0.0]],
            mat![[0.0], [1.0]],
            mat![[1.0, 0.0]],
            mat![[0.0]],
        )
        .unwrap()
        .c2d_zoh(TS)
        .unwrap();
        let (p, eps, kappa, gamma) = (0.99, 1e-11, 1e-2, 1e-9);
        let chain = |modal: bool| {
            // the chain's eigenvectors: v1 = (1, κ/(p − (p + ε))) = (1, −κ/ε), v2 = (0, 1)
            let r = -kappa / eps;
            let (a2, b2, c2) = if modal {
                // V⁻¹ A V = diag(p, p + ε), V⁻¹ b = (1, −r), c V = γ(1 + r, 1)
                (
                    mat![[p, 0.0], [0.0, p + eps]],
                    mat![[1.0], [-r]],
                    mat![[gamma * (1.0 + r), gamma]],
                )
            } else {
                (
                    mat![[p, 0.0], [kappa, p + eps]],
                    mat![[1.0], [0.0]],
                    mat![[gamma, gamma]],
                )
            };
            let n = 4;
            let mut a = Mat::<f64>::zeros(n, n);
            let mut b = Mat::<f64>::zeros(n, 1);
            let mut c = Mat::<f64>::zeros(1, n);
            for i in 0..2 {
                for j in 0..2 {
                    a[(i, j)] = pc.a()[(i, j)];
                    a[(2 + i, 2 + j)] = a2[(i, j)];
                }
                b[(i, 0)] = pc.b()[(i, 0)];
                b[(2 + i, 0)] = b2[(i, 0)];
                c[(0, i)] = pc.c()[(0, i)];
                c[(0, 2 + i)] = c2[(0, i)];
            }
            StateSpace::discrete(a, b, c, mat![[0.0]], TS).unwrap()
        };
        let (k, wd) = (4.0e5, 300.0);
        let ctrl = StateSpace::continuous(
            mat![[-10.0 * wd]],
            mat![[1.0]],
            mat![[k * 10.0 * wd * (1.0 - 10.0)]],
            mat![[k * 10.0]],
        )
        .unwrap()
        .c2d_tustin(TS, None)
        .unwrap();
        (chain(false), chain(true), ctrl)
    }

    /// The closed loop's largest pole modulus with the controller's gain scaled by `g`, from
    /// $A_{cl}$ formed by hand from the given realisations (no conditioning): the naive oracle.
    fn naive_max_pole(p: &StateSpace, c: &StateSpace, g: f64) -> f64 {
        let (n1, n2) = (p.order(), c.order());
        // D_p = 0: u = −g(C_c x_c + D_c C_p x_p), x_c⁺ = A_c x_c + B_c C_p x_p
        let bdc = p.b() * c.d() * p.c() * g;
        let bcc = p.b() * c.c() * g;
        let bcp = c.b() * p.c();
        let a = Mat::<f64>::from_fn(n1 + n2, n1 + n2, |i, j| match (i < n1, j < n1) {
            (true, true) => p.a()[(i, j)] - bdc[(i, j)],
            (true, false) => -bcc[(i, j - n1)],
            (false, true) => bcp[(i - n1, j)],
            (false, false) => c.a()[(i - n1, j - n1)],
        });
        linalg::eigenvalues(a.as_ref())
            .unwrap()
            .iter()
            .map(|z| z.norm())
            .fold(0.0, f64::max)
    }

    /// The modal form with cancelling residues gets back a realisation of the same response
    /// with small B and C, and its closed-loop poles are those of the well-conditioned chain
    /// (the oracle), where the modal form's own state matrix gives other ones.
    #[test]
    fn cancelling_residues_are_removed_without_changing_the_model() {
        let (good, modal, ctrl) = loop_with_a_near_double_pole();
        let w = modal.well_conditioned();
        assert_eq!(w.order(), 4);
        let f: Vec<f64> = (1..=60).map(|k| 5.0 * 1.12f64.powi(k)).collect();
        let (g0, g1) = (
            good.freq_response_siso(&f).unwrap(),
            w.freq_response_siso(&f).unwrap(),
        );
        for (x, y) in g0.iter().zip(&g1) {
            assert!((x - y).norm() <= 1e-7 * x.norm(), "{x} vs {y}");
        }
        let big = |m: faer::MatRef<'_, f64>| m.norm_max();
        assert!(big(modal.b()) > 1e6, "the modal form is not ill-scaled");
        assert!(
            big(w.b()) < 10.0 && big(w.c()) < 10.0,
            "{:?} {:?}",
            w.b(),
            w.c()
        );
        let mut naive_off = 0.0f64;
        for g in [0.6, 1.0, 1.5, 2.0] {
            let truth = naive_max_pole(&good, &ctrl, g);
            let fixed = naive_max_pole(&w, &ctrl, g);
            assert!((fixed - truth).abs() < 1e-7, "g {g}: {fixed} vs {truth}");
            naive_off = naive_off.max((naive_max_pole(&modal, &ctrl, g) - truth).abs());
        }
        // the problem is real: the modal form's own closed loop is off
        assert!(
            naive_off > 1e-5,
            "the modal form's naive poles are off by only {naive_off}"
        );
        // and the gain interval through feedback (which conditions) is the chain's (through the
        // modal form's own state matrix it was 0.864…1.300 against 0.413…16.9)
        let (lo_g, hi_g) = nominal_gain_interval(&good, &ctrl).unwrap();
        let (lo_m, hi_m) = nominal_gain_interval(&modal, &ctrl).unwrap();
        assert!(lo_g < 0.9 && hi_g > 1.1, "the chain's loop: {lo_g}…{hi_g}");
        assert!(
            (lo_g - lo_m).abs() < 1e-5 * lo_g && (hi_g - hi_m).abs() < 1e-5 * hi_g,
            "{lo_g}…{hi_g} against {lo_m}…{hi_m}"
        );
    }

    /// A model without cancelling residues (distinct poles, or repeated poles with orthogonal
    /// input rows as in two identical planes) comes back bit for bit.
    #[test]
    fn a_well_conditioned_model_is_returned_unchanged() {
        let (good, _, ctrl) = loop_with_a_near_double_pole();
        assert_eq!(ctrl.well_conditioned(), ctrl);
        // two identical planes: diag(p, p) with orthogonal inputs
        let planes = StateSpace::discrete(
            mat![[0.98, 0.0], [0.0, 0.98]],
            mat![[1.0, 0.0], [0.0, 2.0]],
            mat![[3.0, 0.0], [0.0, 4.0]],
            mat![[0.0, 0.0], [0.0, 0.0]],
            TS,
        )
        .unwrap();
        assert_eq!(planes.well_conditioned(), planes);
        // a chain with a defective pair (a Jordan block) is left as is
        let jordan = StateSpace::discrete(
            mat![[0.9, 1.0], [0.0, 0.9]],
            mat![[0.0], [1.0]],
            mat![[1.0, 0.0]],
            mat![[0.0]],
            TS,
        )
        .unwrap();
        assert_eq!(jordan.well_conditioned(), jordan);
        // the well-conditioned chain itself has a near-defective pair: whatever is returned has
        // its response
        let w = good.well_conditioned();
        let f = [10.0, 100.0, 1000.0];
        let (g0, g1) = (
            good.freq_response_siso(&f).unwrap(),
            w.freq_response_siso(&f).unwrap(),
        );
        for (x, y) in g0.iter().zip(&g1) {
            assert!((x - y).norm() <= 1e-7 * x.norm());
        }
    }
}
