//! Variable projection for ARMAX and Box–Jenkins (the first phase of their iterations).
//!
//! For a fixed $C$ the ARMAX prediction error is linear in $A$ and $B$:
//! $$\varepsilon = \frac{A}{C}\,y - \frac{B}{C}\,u = y_C + \Phi_C\,\theta_{AB},\qquad
//!   y_C = \tfrac1C y,\; u_C = \tfrac1C u,$$
//! with the columns of $\Phi_C$ the lagged $y_C(t-i)$ ($i = 1..n_a$) and $-u_C(t-n_k-j)$
//! ($j = 0..n_b-1$), all filters from zero initial conditions (the same convention as the joint
//! predictor, so the two errors agree exactly in exact arithmetic). Eliminating
//! $\theta_{AB} = -\Phi_C^{+} y_C$ leaves a criterion in $C$ alone,
//! $$V(c) = \tfrac12 \lVert P_C^{\perp} y_C \rVert^2,$$
//! minimised by the same Levenberg–Marquardt iteration with Kaufman's Jacobian
//! $P_C^{\perp}\,\partial\varepsilon/\partial c$, $\partial\varepsilon/\partial c_i =
//! -\tfrac1C\,\varepsilon(t-i)$ (Golub & Pereyra, *Inverse Problems* 19, 2003).
//!
//! Why: on an AMB loop sampled at 20 kHz the ARMAX optimum often puts a pair of $C$ zeros next to
//! a lightly damped pair of $A$ poles (a near cancellation in the noise model $C/A$). The joint
//! iteration then follows a long curved valley in which $A$ and $C$ must move together and the
//! trust region stays small: ARMAX(4,4,4,1) of the nominal twin's $u \to y$ took 126 joint
//! iterations. With $A, B$ optimal for every $C$ the valley collapses; the joint iteration
//! that follows starts at (or next to) the optimum and only confirms it.
//!
//! Box–Jenkins ($A = 1$) is the same with $y_C = \frac DC y$, $u_C = \frac{D}{CF} u$, no lagged
//! $y_C$ columns, $B$ eliminated and $[c, d, f]$ iterated; its Kaufman Jacobian is the joint
//! gradient's $C, D, F$ columns projected onto the complement of its $B$ columns (which are the
//! columns of $\Phi$).

use super::lm::{self, LeastSquaresProblem, LmOptions, LmReport};
use super::predictor::{filter, is_stable, Polys};
use super::Orders;
use faer::Mat;

/// The reduced ARMAX criterion in $c = [c_1..c_{n_c}]$ (Box–Jenkins: in $[c, d, f]$).
pub(crate) struct Projection<'a> {
    y: &'a [f64],
    u: &'a [f64],
    o: Orders,
    /// The regression columns of $\Phi_C$ ([`columns`]).
    cols: Vec<(bool, usize, f64)>,
    /// The last evaluation, reused by the Jacobian at the same $c$.
    cache: Option<Evaluation>,
}

struct Evaluation {
    c: Vec<f64>,
    yc: Vec<f64>,
    uc: Vec<f64>,
    eps: Vec<f64>,
    gram: Gram,
    ab: Vec<f64>,
}

/// $\sum_t a(t - l_a)\,b(t - l_b)$ over the samples where both lags exist (zero before the start).
fn dot_lagged(a: &[f64], la: usize, b: &[f64], lb: usize) -> f64 {
    let n = a.len().min(b.len());
    let l = la.max(lb);
    if l >= n {
        return 0.0;
    }
    crate::estimate::subspace::hankel::dot(&a[l - la..n - la], &b[l - lb..n - lb])
}

/// The regression columns of $\Phi_C$: lag and sign on $y_C$ (first $n_a$) or $u_C$.
fn columns(o: &Orders) -> Vec<(bool, usize, f64)> {
    (0..o.na)
        .map(|i| (true, i + 1, 1.0))
        .chain((0..o.nb).map(|j| (false, o.nk + j, -1.0)))
        .collect()
}

/// The Cholesky factor of the column-scaled Gram matrix $\Phi_C^\top\Phi_C$ (lower, row-major)
/// and the column scales.
struct Gram {
    l: Vec<f64>,
    scale: Vec<f64>,
}

impl Gram {
    fn new(g: &[f64], p: usize) -> Option<Self> {
        let scale: Vec<f64> = (0..p).map(|i| g[i * p + i].sqrt()).collect();
        if scale.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return None;
        }
        let mut l = vec![0.0; p * p];
        for i in 0..p {
            for j in 0..=i {
                let mut v = g[i * p + j] / (scale[i] * scale[j]);
                for k in 0..j {
                    v -= l[i * p + k] * l[j * p + k];
                }
                if i == j {
                    // the scaled diagonal is 1: a pivot below RANK_TOL² means (near) collinear columns
                    if v.is_nan() || v <= RANK_TOL * RANK_TOL {
                        return None;
                    }
                    l[i * p + i] = v.sqrt();
                } else {
                    l[i * p + j] = v / l[j * p + j];
                }
            }
        }
        Some(Self { l, scale })
    }

    /// $(\Phi^\top\Phi)^{-1} b$.
    fn solve(&self, b: &[f64]) -> Vec<f64> {
        let p = self.scale.len();
        let mut x: Vec<f64> = b.iter().zip(&self.scale).map(|(v, s)| v / s).collect();
        for i in 0..p {
            for k in 0..i {
                x[i] -= self.l[i * p + k] * x[k];
            }
            x[i] /= self.l[i * p + i];
        }
        for i in (0..p).rev() {
            for k in (i + 1)..p {
                x[i] -= self.l[k * p + i] * x[k];
            }
            x[i] /= self.l[i * p + i];
        }
        x.iter().zip(&self.scale).map(|(v, s)| v / s).collect()
    }
}

/// Smallest pivot of the unit-diagonal scaled Gram matrix's Cholesky factor (relative) below
/// which $\Phi_C$ counts as rank deficient: the elimination is then refused and the joint
/// iteration runs alone.
const RANK_TOL: f64 = 1e-7;

impl<'a> Projection<'a> {
    pub(crate) fn new(y: &'a [f64], u: &'a [f64], o: Orders) -> Self {
        Self {
            y,
            u,
            o,
            cols: columns(&o),
            cache: None,
        }
    }

    /// $C$, $D$, $F$ from the iterated parameters $[c, d, f]$ (B zero).
    fn noise_and_f(&self, x: &[f64]) -> Polys {
        let (nc, nd) = (self.o.nc, self.o.nd);
        Polys {
            a: vec![1.0],
            b: vec![0.0; self.o.nk + self.o.nb],
            c: Self::monic(&x[..nc]),
            d: Self::monic(&x[nc..nc + nd]),
            f: Self::monic(&x[nc + nd..]),
        }
    }

    fn monic(c: &[f64]) -> Vec<f64> {
        let mut p = Vec::with_capacity(c.len() + 1);
        p.push(1.0);
        p.extend_from_slice(c);
        p
    }

    /// $\Phi_C^\top x$ for a signal $x$.
    fn phi_t(&self, yc: &[f64], uc: &[f64], x: &[f64]) -> Vec<f64> {
        self.cols
            .iter()
            .map(|&(is_y, lag, sign)| sign * dot_lagged(if is_y { yc } else { uc }, lag, x, 0))
            .collect()
    }

    /// $x \leftarrow x + \Phi_C\,\theta$.
    fn add_phi(&self, yc: &[f64], uc: &[f64], theta: &[f64], x: &mut [f64]) {
        for (&(is_y, lag, sign), th) in self.cols.iter().zip(theta) {
            let src = if is_y { yc } else { uc };
            let w = sign * th;
            if lag < x.len() {
                for (xv, sv) in x[lag..].iter_mut().zip(src) {
                    *xv += w * sv;
                }
            }
        }
    }

    /// $x \leftarrow P_C^\perp x$ (least squares on $\Phi_C$ by the normal equations with one
    /// step of iterative refinement); returns the coefficients $\Phi_C^{+} x$ with a minus sign
    /// (so that $x + \Phi_C\,\theta$ is the projected vector).
    fn project(&self, yc: &[f64], uc: &[f64], gram: &Gram, x: &mut [f64]) -> Vec<f64> {
        let mut theta = vec![0.0; gram.scale.len()];
        for _ in 0..2 {
            let rhs: Vec<f64> = self.phi_t(yc, uc, x).iter().map(|v| -v).collect();
            let d = gram.solve(&rhs);
            self.add_phi(yc, uc, &d, x);
            for (t, dv) in theta.iter_mut().zip(&d) {
                *t += dv;
            }
        }
        theta
    }

    /// Errors and $\theta_{AB}$ for this $C$; `None` for an unstable $C$, a rank-deficient
    /// regression or a non-finite result.
    fn evaluate(&self, c: &[f64]) -> Option<Evaluation> {
        let (yc, uc) = if self.o.nd + self.o.nf == 0 {
            // ARMAX: y_C = y/C, u_C = u/C
            let cp = Self::monic(c);
            if !is_stable(&cp) {
                return None;
            }
            (filter(&[1.0], &cp, self.y), filter(&[1.0], &cp, self.u))
        } else {
            // Box–Jenkins (A = 1): ε = (D/C) y − B (D/(CF)) u
            let p = self.noise_and_f(c);
            if !(is_stable(&p.c) && is_stable(&p.f)) {
                return None;
            }
            let cf = super::predictor::mul(&p.c, &p.f);
            (filter(&p.d, &p.c, self.y), filter(&p.d, &cf, self.u))
        };
        let cols = &self.cols;
        let p = cols.len();
        // Σ_t a(t−l_i) b(t−l_j) depends on l_i − l_j except for the last min(l_i, l_j) samples:
        // one full lagged product per distinct lag difference, less those few end terms
        let n = yc.len();
        let mut full: Vec<((bool, bool, usize, usize), f64)> = Vec::new();
        let mut g = vec![0.0; p * p];
        for (i, &(yi, li, si)) in cols.iter().enumerate() {
            for (j, &(yj, lj, sj)) in cols.iter().enumerate().take(i + 1) {
                let (a, b) = (if yi { &yc } else { &uc }, if yj { &yc } else { &uc });
                let m = li.min(lj);
                let key = (yi, yj, li - m, lj - m);
                let whole = match full.iter().find(|(k, _)| *k == key) {
                    Some((_, v)) => *v,
                    None => {
                        let v = dot_lagged(a, li - m, b, lj - m);
                        full.push((key, v));
                        v
                    }
                };
                let tail: f64 = (n..n + m)
                    .filter(|&t| t >= li.max(lj) && t - li < n && t - lj < n)
                    .map(|t| a[t - li] * b[t - lj])
                    .sum();
                let v = si * sj * (whole - tail);
                g[i * p + j] = v;
                g[j * p + i] = v;
            }
        }
        let gram = Gram::new(&g, p)?;
        let mut eps = yc.clone();
        let ab = self.project(&yc, &uc, &gram, &mut eps);
        if eps.iter().chain(&ab).any(|v| !v.is_finite()) {
            return None;
        }
        Some(Evaluation {
            c: c.to_vec(),
            yc,
            uc,
            eps,
            gram,
            ab,
        })
    }

    /// Box–Jenkins: the joint gradient's $C, D, F$ columns at $(B^\ast, C, D, F)$, projected
    /// onto the complement of the $B$ columns (Kaufman).
    fn bj_jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
        let p = self.polys(x)?;
        let full =
            super::predictor::gradient(&p, &self.o, self.y, self.u, super::Focus::Prediction)?;
        let ev = self.cache.as_ref()?;
        let nb = self.o.nb;
        Some(self.projected(ev, x.len(), |i| full.col(nb + i).iter().copied().collect()))
    }

    /// The Kaufman Jacobian: `k` columns of $\partial\varepsilon$ at fixed $\theta_{AB}$, each
    /// projected onto the complement of $\Phi_C$'s range by one normal-equations step (the
    /// Jacobian only steers the step; the refined trial residuals decide its acceptance).
    fn projected(&self, ev: &Evaluation, k: usize, column: impl Fn(usize) -> Vec<f64>) -> Mat<f64> {
        let mut jac = Mat::<f64>::zeros(ev.eps.len(), k);
        for i in 0..k {
            let mut col = column(i);
            let rhs: Vec<f64> = self
                .phi_t(&ev.yc, &ev.uc, &col)
                .iter()
                .map(|v| -v)
                .collect();
            let d = ev.gram.solve(&rhs);
            self.add_phi(&ev.yc, &ev.uc, &d, &mut col);
            for (dst, v) in jac.col_mut(i).iter_mut().zip(&col) {
                *dst = *v;
            }
        }
        jac
    }

    fn cached(&mut self, c: &[f64]) -> Option<&Evaluation> {
        if self.cache.as_ref().is_none_or(|e| e.c != c) {
            self.cache = Some(self.evaluate(c)?);
        }
        self.cache.as_ref()
    }

    /// The full ARMAX polynomials at $c$ ($A, B$ from the elimination).
    pub(crate) fn polys(&mut self, c: &[f64]) -> Option<Polys> {
        let (na, nk) = (self.o.na, self.o.nk);
        let mut p = if self.o.nd + self.o.nf == 0 {
            Polys {
                a: vec![1.0],
                b: vec![],
                c: Self::monic(c),
                d: vec![1.0],
                f: vec![1.0],
            }
        } else {
            self.noise_and_f(c)
        };
        let ev = self.cached(c)?;
        p.a.extend_from_slice(&ev.ab[..na]);
        p.b = vec![0.0; nk];
        p.b.extend_from_slice(&ev.ab[na..]);
        Some(p)
    }
}

impl LeastSquaresProblem for Projection<'_> {
    fn residuals(&mut self, c: &[f64]) -> Option<Vec<f64>> {
        self.cached(c).map(|e| e.eps.clone())
    }

    fn jacobian(&mut self, c: &[f64]) -> Option<Mat<f64>> {
        if self.o.nd + self.o.nf > 0 {
            return self.bj_jacobian(c);
        }
        let nc = self.o.nc;
        let cp = Self::monic(c);
        self.cached(c)?;
        let ev = self.cache.as_ref()?;
        let n = ev.eps.len();
        // ∂ε/∂c_i = −(1/C) ε(t−i), then projected onto the complement of Φ_C's range
        let et = filter(&[1.0], &cp, &ev.eps);
        Some(self.projected(ev, nc, |i| {
            (0..n)
                .map(|t| if t > i { -et[t - i - 1] } else { 0.0 })
                .collect()
        }))
    }
}

/// Statistical tolerance of the projected phase when the caller's options have none
/// ([`LmOptions::exhaustive`]): its criterion is evaluated in double precision by normal
/// equations, so tolerances of 0 cannot be met; the joint phase then goes on to the caller's
/// tolerances.
const PHASE_KAPPA: f64 = 0.01;

/// The projected phase's options: the caller's budget and statistical rule (or
/// [`PHASE_KAPPA`]), with extrapolation.
fn phase_options(opts: &LmOptions) -> Option<LmOptions> {
    let kappa = if opts.significance_tol() > 0.0 {
        opts.significance_tol()
    } else {
        PHASE_KAPPA
    };
    Some(
        opts.with_significance_tol(kappa)
            .ok()?
            .with_extrapolation(true),
    )
}

/// Variable-projection iteration over $C$ from the start's $C$; returns the ARMAX polynomials at
/// the reduced optimum and the iteration's report. `None` when the elimination is not possible
/// (no $C$ to iterate, the start's $C$ unstable, or a rank-deficient regression), so the caller
/// runs the joint iteration alone.
pub(crate) fn armax(
    y: &[f64],
    u: &[f64],
    o: &Orders,
    start: &Polys,
    opts: &LmOptions,
) -> Option<(Polys, LmReport)> {
    if o.nc == 0 || o.nd != 0 || o.nf != 0 || start.c.len() != o.nc + 1 {
        return None;
    }
    let mut problem = Projection::new(y, u, *o);
    let c0 = start.c[1..].to_vec();
    let (c, rep) = lm::minimize(&mut problem, &c0, &phase_options(opts)?).ok()?;
    let p = problem.polys(&c)?;
    Some((p, rep))
}

/// Box–Jenkins by variable projection over $[c, d, f]$ ($B$ eliminated by least squares for
/// each $C, D, F$) from the start's $C, D, F$; as [`armax`] otherwise.
pub(crate) fn bj(
    y: &[f64],
    u: &[f64],
    o: &Orders,
    start: &Polys,
    opts: &LmOptions,
) -> Option<(Polys, LmReport)> {
    if o.na != 0 || o.nf == 0 {
        return None;
    }
    let mut problem = Projection::new(y, u, *o);
    let mut x0 = start.c[1..].to_vec();
    x0.extend_from_slice(&start.d[1..]);
    x0.extend_from_slice(&start.f[1..]);
    if x0.len() != o.nc + o.nd + o.nf {
        return None;
    }
    let (x, rep) = lm::minimize(&mut problem, &x0, &phase_options(opts)?).ok()?;
    let p = problem.polys(&x)?;
    Some((p, rep))
}

/// $\lVert P_C^\perp y_C\rVert^2$ at the start's $C$: the ARMAX loss with $A$, $B$ optimal for
/// that $C$ (how the ARMAX starts compete). `None` when the elimination is not possible.
pub(crate) fn projected_loss(y: &[f64], u: &[f64], o: &Orders, start: &Polys) -> Option<f64> {
    if o.nc == 0 || start.c.len() != o.nc + 1 {
        return None;
    }
    let ev = Projection::new(y, u, *o).evaluate(&start.c[1..])?;
    Some(ev.eps.iter().map(|v| v * v).sum())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::pem::predictor::{errors, Accuracy};
    use crate::estimate::pem::Focus;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    /// $\lVert a - b\rVert / \lVert b\rVert$.
    fn relative_difference(a: &[f64], b: &[f64]) -> f64 {
        let diff: f64 = a.iter().zip(b).map(|(p, q)| (p - q).powi(2)).sum();
        (diff / b.iter().map(|v| v * v).sum::<f64>()).sqrt()
    }

    /// ARMAX(2, 2, 2, 1) data: A = 1 − 1.5q⁻¹ + 0.7q⁻², B = q⁻¹ + 0.5q⁻², C = 1 − 0.6q⁻¹ + 0.2q⁻².
    fn data(n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let u: Vec<f64> = (0..n).map(|_| rng.sample(StandardNormal)).collect();
        let e: Vec<f64> = (0..n)
            .map(|_| 0.3 * rng.sample::<f64, _>(StandardNormal))
            .collect();
        let bu = filter(&[0.0, 1.0, 0.5], &[1.0, -1.5, 0.7], &u);
        let ce = filter(&[1.0, -0.6, 0.2], &[1.0, -1.5, 0.7], &e);
        (bu.iter().zip(&ce).map(|(a, b)| a + b).collect(), u)
    }

    #[test]
    fn projected_errors_are_the_joint_predictors_at_the_least_squares_a_b() {
        let (y, u) = data(3000, 1);
        let o = Orders::armax(2, 2, 2, 1);
        let mut pr = Projection::new(&y, &u, o);
        for c in [[-0.6, 0.2], [0.3, -0.1], [-1.2, 0.5]] {
            let p = pr.polys(&c).unwrap();
            let eps = pr.residuals(&c).unwrap();
            // the joint predictor (double-double) at (A, B, C) gives the same errors
            let joint = errors(&p, &y, &u, Focus::Prediction, Accuracy::Exact).unwrap();
            let rel = relative_difference(&eps, &joint);
            assert!(rel < 1e-10, "c = {c:?}: relative difference {rel:e}");
            // and (A, B) is the least-squares optimum: an explicit regression solved by QR
            let cp = [1.0, c[0], c[1]];
            let (yc, uc) = (filter(&[1.0], &cp, &y), filter(&[1.0], &cp, &u));
            let lag = |x: &[f64], k: usize, t: usize| if t >= k { x[t - k] } else { 0.0 };
            let phi = Mat::from_fn(y.len(), 4, |t, k| match k {
                0 | 1 => lag(&yc, k + 1, t),
                _ => -lag(&uc, k - 1, t),
            });
            let rhs = Mat::from_fn(y.len(), 1, |t, _| -yc[t]);
            let want = crate::linalg::lstsq(phi.as_ref(), rhs.as_ref()).unwrap();
            let got = [p.a[1], p.a[2], p.b[1], p.b[2]];
            for k in 0..4 {
                assert!(
                    (got[k] - want[(k, 0)]).abs() < 1e-9 * (1.0 + want[(k, 0)].abs()),
                    "c = {c:?}, θ[{k}]: {} vs {}",
                    got[k],
                    want[(k, 0)]
                );
            }
        }
    }

    #[test]
    fn kaufman_jacobian_gives_the_exact_gradient_of_the_projected_loss() {
        // Jᵀε with the projected Jacobian is the gradient of ½‖P⊥ y_C‖² (the dropped term is
        // orthogonal to ε); checked against central differences of the loss
        let (y, u) = data(2000, 2);
        let o = Orders::armax(2, 2, 2, 1);
        let mut pr = Projection::new(&y, &u, o);
        let c = [-0.4, 0.1];
        let eps = pr.residuals(&c).unwrap();
        let jac = pr.jacobian(&c).unwrap();
        let loss = |pr: &mut Projection, c: &[f64]| {
            0.5 * pr.residuals(c).unwrap().iter().map(|v| v * v).sum::<f64>()
        };
        for i in 0..2 {
            let g: f64 = (0..eps.len()).map(|t| jac[(t, i)] * eps[t]).sum();
            let h = 1e-6;
            let (mut cp, mut cm) = (c, c);
            cp[i] += h;
            cm[i] -= h;
            let fd = (loss(&mut pr, &cp) - loss(&mut pr, &cm)) / (2.0 * h);
            assert!(
                (g - fd).abs() < 1e-5 * fd.abs().max(1e-3),
                "∂V/∂c_{}: {g} vs {fd}",
                i + 1
            );
        }
    }

    #[test]
    fn projection_reaches_the_joint_optimum_and_refuses_an_unstable_c() {
        let (y, u) = data(4000, 3);
        let o = Orders::armax(2, 2, 2, 1);
        let start = Polys {
            a: vec![1.0, -1.0, 0.3],
            b: vec![0.0, 0.8, 0.2],
            c: vec![1.0, 0.0, 0.0],
            d: vec![1.0],
            f: vec![1.0],
        };
        let exhaustive = LmOptions::exhaustive(200).unwrap();
        let (p, rep) = armax(&y, &u, &o, &start, &exhaustive).unwrap();
        assert!(rep.reason.converged(), "{:?}", rep.reason);
        // the joint criterion's exact optimum from that point: nothing left to gain
        let joint = crate::estimate::pem::refine(
            &y,
            &u,
            &crate::lti::PolyModel::armax(p.a.clone(), p.b.clone(), p.c.clone(), 1.0).unwrap(),
            &crate::estimate::pem::PemOptions::default().with_lm(exhaustive),
        )
        .unwrap()
        .0;
        // the projected phase stops within 0.01 standard errors (its statistical rule)
        let theta = p.theta(&o);
        let sd = joint.std().unwrap();
        for (k, (a, b)) in theta.iter().zip(&joint.params).enumerate() {
            assert!(
                (a - b).abs() < 0.02 * sd[k],
                "θ[{k}]: projected {a}, joint {b}"
            );
        }
        // and near the truth (5 standard errors)
        for (k, want) in [-1.5, 0.7, 1.0, 0.5, -0.6, 0.2].into_iter().enumerate() {
            assert!(
                (theta[k] - want).abs() < 5.0 * sd[k],
                "θ[{k}] = {}",
                theta[k]
            );
        }
        // an unstable start C cannot be projected: the caller runs the joint iteration
        let bad = Polys {
            c: vec![1.0, -2.5, 1.2],
            ..start
        };
        assert!(armax(&y, &u, &o, &bad, &exhaustive).is_none());
        assert!(projected_loss(&y, &u, &o, &bad).is_none());
    }

    #[test]
    fn box_jenkins_projection_matches_the_joint_criterion_and_its_optimum() {
        // BJ(2, 1, 1, 2, 1): B = q⁻¹ + 0.5q⁻², C = 1 − 0.5q⁻¹, D = 1 − 0.8q⁻¹,
        // F = 1 − 1.5q⁻¹ + 0.7q⁻²
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let n = 4000;
        let u: Vec<f64> = (0..n).map(|_| rng.sample(StandardNormal)).collect();
        let e: Vec<f64> = (0..n)
            .map(|_| 0.3 * rng.sample::<f64, _>(StandardNormal))
            .collect();
        let g = filter(&[0.0, 1.0, 0.5], &[1.0, -1.5, 0.7], &u);
        let h = filter(&[1.0, -0.5], &[1.0, -0.8], &e);
        let y: Vec<f64> = g.iter().zip(&h).map(|(a, b)| a + b).collect();
        let o = Orders::bj(2, 1, 1, 2, 1);
        let mut pr = Projection::new(&y, &u, o);
        let x = [-0.3, -0.6, -1.4, 0.6];
        let p = pr.polys(&x).unwrap();
        assert_eq!(
            (p.c.clone(), p.d.clone()),
            (vec![1.0, -0.3], vec![1.0, -0.6])
        );
        assert_eq!(p.f, vec![1.0, -1.4, 0.6]);
        let eps = pr.residuals(&x).unwrap();
        let joint = errors(&p, &y, &u, Focus::Prediction, Accuracy::Exact).unwrap();
        let rel = relative_difference(&eps, &joint);
        assert!(rel < 1e-10, "relative difference {rel:e}");
        // from a rough start, the projected optimum is the joint one
        let start = Polys {
            a: vec![1.0],
            b: vec![0.0, 0.9, 0.4],
            // (C = D = 1 would make the C and D columns of the Jacobian opposite)
            c: vec![1.0, -0.2],
            d: vec![1.0, -0.5],
            f: vec![1.0, -1.3, 0.5],
        };
        let exhaustive = LmOptions::exhaustive(200).unwrap();
        let (q, rep) = bj(&y, &u, &o, &start, &exhaustive).unwrap();
        assert!(rep.reason.converged(), "{:?}", rep.reason);
        let model =
            crate::lti::PolyModel::bj(q.b.clone(), q.c.clone(), q.d.clone(), q.f.clone(), 1.0)
                .unwrap();
        let joint = crate::estimate::pem::refine(
            &y,
            &u,
            &model,
            &crate::estimate::pem::PemOptions::default().with_lm(exhaustive),
        )
        .unwrap()
        .0;
        let theta = q.theta(&o);
        let sd = joint.std().unwrap();
        for (k, (a, b)) in theta.iter().zip(&joint.params).enumerate() {
            assert!(
                (a - b).abs() < 0.02 * sd[k],
                "θ[{k}]: projected {a}, joint {b}"
            );
        }
        for (k, want) in [1.0, 0.5, -0.5, -0.8, -1.5, 0.7].into_iter().enumerate() {
            assert!(
                (theta[k] - want).abs() < 5.0 * sd[k],
                "θ[{k}] = {}",
                theta[k]
            );
        }
    }
}
