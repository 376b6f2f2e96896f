//! The one-step predictor of the general polynomial model, its prediction errors and their
//! analytic gradient (filtered regressors), with zero initial conditions.

use super::{Focus, Orders};
use crate::lti::PolyModel;
use faer::Mat;

/// The five polynomials of a parameter vector, ascending powers of $q^{-1}$, $B$ with its delay.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Polys {
    pub a: Vec<f64>,
    pub b: Vec<f64>,
    pub c: Vec<f64>,
    pub d: Vec<f64>,
    pub f: Vec<f64>,
}

impl Polys {
    /// Unpacks $\theta = [a_{1..n_a}, b_{0..n_b-1}, c_{1..n_c}, d_{1..n_d}, f_{1..n_f}]$.
    pub fn from_theta(o: &Orders, th: &[f64]) -> Self {
        let monic = |s: &[f64]| {
            let mut p = Vec::with_capacity(s.len() + 1);
            p.push(1.0);
            p.extend_from_slice(s);
            p
        };
        let (ia, ib, ic, id) = (
            o.na,
            o.na + o.nb,
            o.na + o.nb + o.nc,
            o.na + o.nb + o.nc + o.nd,
        );
        let mut b = vec![0.0; o.nk];
        b.extend_from_slice(&th[ia..ib]);
        Self {
            a: monic(&th[..ia]),
            b,
            c: monic(&th[ib..ic]),
            d: monic(&th[ic..id]),
            f: monic(&th[id..id + o.nf]),
        }
    }

    /// The polynomials of a model, padded or checked against `o` by the caller.
    pub fn from_model(m: &PolyModel) -> Self {
        Self {
            a: m.a().to_vec(),
            b: m.b().to_vec(),
            c: m.c().to_vec(),
            d: m.d().to_vec(),
            f: m.f().to_vec(),
        }
    }

    /// Packs into $\theta$ (the inverse of [`Polys::from_theta`]; missing coefficients are 0).
    pub fn theta(&self, o: &Orders) -> Vec<f64> {
        let get = |p: &[f64], i: usize| p.get(i).copied().unwrap_or(0.0);
        let mut th = Vec::with_capacity(o.n_params());
        th.extend((1..=o.na).map(|i| get(&self.a, i)));
        th.extend((0..o.nb).map(|j| get(&self.b, o.nk + j)));
        th.extend((1..=o.nc).map(|i| get(&self.c, i)));
        th.extend((1..=o.nd).map(|i| get(&self.d, i)));
        th.extend((1..=o.nf).map(|i| get(&self.f, i)));
        th
    }
}

/// $y = (\text{num}/\text{den})\,x$ with zero initial conditions; `den` monic.
pub(crate) fn filter(num: &[f64], den: &[f64], x: &[f64]) -> Vec<f64> {
    let n = x.len();
    let mut y = vec![0.0; n];
    for t in 0..n {
        let mut s = 0.0;
        for (k, bk) in num.iter().enumerate().take(t + 1) {
            s += bk * x[t - k];
        }
        for (k, ak) in den.iter().enumerate().skip(1).take(t) {
            s -= ak * y[t - k];
        }
        y[t] = s;
    }
    y
}

/// Polynomial product.
pub(crate) fn mul(p: &[f64], q: &[f64]) -> Vec<f64> {
    let mut r = vec![0.0; p.len() + q.len() - 1];
    for (i, a) in p.iter().enumerate() {
        for (j, b) in q.iter().enumerate() {
            r[i + j] += a * b;
        }
    }
    r
}

/// Error-free sum: $a + b = s + e$ exactly (Knuth's TwoSum).
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// Error-free product $a b = p + e$ (Dekker's TwoProduct with Veltkamp's split; no FMA needed).
fn two_prod(a: f64, b: f64) -> (f64, f64) {
    const SPLIT: f64 = 134_217_729.0; // 2^27 + 1
    let split = |x: f64| {
        let c = SPLIT * x;
        let h = c - (c - x);
        (h, x - h)
    };
    let p = a * b;
    let (ah, al) = split(a);
    let (bh, bl) = split(b);
    (p, ((ah * bh - p) + ah * bl + al * bh) + al * bl)
}

/// A double-double number $hi + lo$, $|lo| \le \mathrm{ulp}(hi)/2$.
#[derive(Debug, Clone, Copy, Default)]
struct Dd {
    hi: f64,
    lo: f64,
}

impl Dd {
    fn add(self, o: Dd) -> Dd {
        let (s, e) = two_sum(self.hi, o.hi);
        let e = e + self.lo + o.lo;
        let hi = s + e;
        Dd {
            hi,
            lo: e - (hi - s),
        }
    }
    /// $c \cdot x$ for a double $c$.
    fn scale(self, c: f64) -> Dd {
        let (p, e) = two_prod(c, self.hi);
        let e = e + c * self.lo;
        let hi = p + e;
        Dd {
            hi,
            lo: e - (hi - p),
        }
    }
}

/// `filter` in double-double arithmetic (about 32 significant digits).
fn filter_dd(num: &[f64], den: &[f64], x: &[f64]) -> Vec<Dd> {
    let n = x.len();
    let mut y = vec![Dd::default(); n];
    // the zero coefficients (B's leading delays) cost a double-double product each otherwise
    let nz: Vec<(usize, f64)> = num
        .iter()
        .enumerate()
        .filter(|(_, b)| **b != 0.0)
        .map(|(k, b)| (k, *b))
        .collect();
    for t in 0..n {
        let mut s = Dd::default();
        for &(k, bk) in nz.iter().take_while(|(k, _)| *k <= t) {
            let (p, e) = two_prod(bk, x[t - k]);
            s = s.add(Dd { hi: p, lo: e });
        }
        for (k, ak) in den.iter().enumerate().skip(1).take(t) {
            s = s.add(y[t - k].scale(-ak));
        }
        y[t] = s;
    }
    y
}

/// $\lVert h \rVert_1 = \sum_t |h_t|$ of the impulse response of the stable $1/\text{den}$ (monic),
/// summed over at most `n` samples, stopped early once the last $n_\text{den}$ samples (the
/// filter's state) are below $10^{-17}$ of the sum.
fn impulse_l1(den: &[f64], n: usize) -> f64 {
    let nd = den.len() - 1;
    if nd == 0 {
        return 1.0;
    }
    let mut h = vec![0.0; n.max(1)];
    let mut sum = 0.0;
    for t in 0..h.len() {
        let mut s = if t == 0 { 1.0 } else { 0.0 };
        for (k, dk) in den.iter().enumerate().skip(1).take(t) {
            s -= dk * h[t - k];
        }
        h[t] = s;
        sum += s.abs();
        if t >= nd && h[t + 1 - nd..=t].iter().all(|v| v.abs() <= 1e-17 * sum) {
            break;
        }
    }
    sum
}

/// $\bigl(\sum_t (\sum_k |c_k| |x_{t-k}|)^2\bigr)^{1/2}$ plus, for a recursive filter with output
/// `out`, $\sum_{k \ge 1} |\text{den}_k| |\text{out}_{t-k}|$ inside the sum: the magnitude that one
/// step's rounding error is relative to.
fn abs_sum_norm(c: &[f64], x: &[f64], den: &[f64], out: &[f64]) -> f64 {
    let mut acc = 0.0;
    for t in 0..x.len() {
        let mut s = 0.0;
        for (k, ck) in c.iter().enumerate().take(t + 1) {
            s += ck.abs() * x[t - k].abs();
        }
        for (k, dk) in den.iter().enumerate().skip(1).take(t) {
            s += dk.abs() * out[t - k].abs();
        }
        acc += s * s;
    }
    acc.sqrt()
}

/// When the iteration may use the plain double residual: see [`output_error`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Accuracy {
    /// Always double-double (the final loss and covariance; the exact-optimum mode).
    Exact,
    /// Plain double when its rounding-error bound is at most this fraction of $\lVert w\rVert$.
    RelativeBound(f64),
    /// Always plain double (the Jacobian).
    Plain,
}

/// $w = A y - (B/F) u$ (prediction) or $y - B/(AF)\,u$ (simulation); also returns $(B/F) u$ resp.
/// $B/(AF)\,u$.
///
/// [`Accuracy::Exact`]: computed in double-double and rounded once, so that it is accurate
/// relative to $|w|$ even when $y \approx G u$ cancels many digits (data with very little
/// noise). [`Accuracy::Plain`]: plain double precision (about ten times faster; enough for the
/// gradient, whose columns are filtered signals without that cancellation).
/// [`Accuracy::RelativeBound`]`(τ)`: plain double, with a rigorous first-order bound of its
/// rounding error (Higham, *Accuracy and Stability of Numerical Algorithms*, §3.1: each inner
/// product of $k$ terms errs by at most $\gamma_k = k u/(1 - k u)$ times the sum of the
/// magnitudes of its terms, and the recursion $1/F$ passes each step's error on with gain at
/// most $\lVert h_{1/F}\rVert_1$):
/// $$ \lVert \delta w\rVert_2 \le \gamma_{n_a+1}\, \bigl\lVert |A| * |y| \bigr\rVert_2 +
///    \lVert h_{1/F}\rVert_1\, \gamma_{n_b+n_f}\, \bigl\lVert |B| * |u| + |F - 1| * |v| \bigr\rVert_2 ; $$
/// when that bound exceeds $\tau \lVert w\rVert_2$ (heavy cancellation, or $F$ poles so close to
/// the unit circle that the recursion amplifies the rounding) the double-double result is
/// returned instead.
fn output_error(
    p: &Polys,
    y: &[f64],
    u: &[f64],
    focus: Focus,
    accuracy: Accuracy,
) -> (Vec<f64>, Vec<f64>) {
    let (a, den) = match focus {
        Focus::Prediction => (p.a.as_slice(), p.f.clone()),
        Focus::Simulation => (&[1.0][..], mul(&p.a, &p.f)),
    };
    if accuracy != Accuracy::Exact {
        let v = filter(&p.b, &den, u);
        let unit_a = a.len() == 1 && a[0] == 1.0;
        let ay = if unit_a {
            y.to_vec()
        } else {
            filter(a, &[1.0], y)
        };
        let w: Vec<f64> = ay.iter().zip(&v).map(|(x, z)| x - z).collect();
        let plain_ok = match accuracy {
            Accuracy::Plain => true,
            Accuracy::RelativeBound(tau) => {
                let gamma = |k: usize| {
                    let ku = k as f64 * f64::EPSILON / 2.0;
                    ku / (1.0 - ku)
                };
                let nb = p.b.iter().filter(|c| **c != 0.0).count();
                let err_a = if unit_a {
                    0.0
                } else {
                    gamma(a.len()) * abs_sum_norm(a, y, &[1.0], &[])
                };
                let wn = w.iter().map(|x| x * x).sum::<f64>().sqrt();
                let gain = impulse_l1(&den, y.len()) * gamma(nb + den.len() - 1);
                // |v_t| is at most the term magnitude of its step: a cheap lower bound first
                let vn = v.iter().map(|x| x * x).sum::<f64>().sqrt();
                let err_v = if gain * vn > tau * wn {
                    f64::INFINITY
                } else {
                    gain * abs_sum_norm(&p.b, u, &den, &v)
                };
                // the subtraction itself: one rounding of each w_t
                let bound = err_a + err_v + f64::EPSILON * wn;
                bound.is_finite() && bound <= tau * wn
            }
            Accuracy::Exact => false,
        };
        if plain_ok {
            return (w, v);
        }
    }
    let v = filter_dd(&p.b, &den, u);
    let ay = filter_dd(a, &[1.0], y);
    let w = ay
        .iter()
        .zip(&v)
        .map(|(x, z)| {
            let d = x.add(Dd {
                hi: -z.hi,
                lo: -z.lo,
            });
            d.hi + d.lo
        })
        .collect();
    (w, v.iter().map(|z| z.hi + z.lo).collect())
}

/// Schur–Cohn (step-down) test: all roots of the monic $p$ (in $z$) strictly inside the unit
/// circle. A list in ascending powers of $q^{-1}$ is the same list in descending powers of $z$.
pub(crate) fn is_stable(p: &[f64]) -> bool {
    let mut a: Vec<f64> = p.to_vec();
    while a.len() > 1 && a[a.len() - 1] == 0.0 {
        a.pop();
    }
    if a.is_empty() || a[0] == 0.0 || a.iter().any(|v| !v.is_finite()) {
        return false;
    }
    let a0 = a[0];
    for v in a.iter_mut() {
        *v /= a0;
    }
    while a.len() > 1 {
        let n = a.len() - 1;
        let k = a[n];
        if k.is_nan() || k.abs() >= 1.0 {
            return false;
        }
        let den = 1.0 - k * k;
        let next: Vec<f64> = (0..n).map(|i| (a[i] - k * a[n - i]) / den).collect();
        a = next;
    }
    true
}

/// Largest root magnitude of a monic polynomial (for messages); 0 for a constant.
pub(crate) fn max_root(p: &[f64]) -> f64 {
    if p.len() <= 1 {
        return 0.0;
    }
    crate::linalg::roots(p)
        .map(|r| r.iter().fold(0.0f64, |m, z| m.max(z.norm())))
        .unwrap_or(f64::NAN)
}

/// Shifted copy: $x(t - k)$, zero before the start.
fn shifted(x: &[f64], k: usize, t: usize) -> f64 {
    if t >= k {
        x[t - k]
    } else {
        0.0
    }
}

/// Which denominators must be stable for the predictor of `focus`: prediction needs $C$ and
/// $F$ stable; simulation needs $A$ and $F$.
pub(crate) fn predictor_stable(p: &Polys, focus: Focus) -> bool {
    match focus {
        Focus::Prediction => is_stable(&p.c) && is_stable(&p.f),
        Focus::Simulation => is_stable(&p.a) && is_stable(&p.f),
    }
}

/// Prediction errors. Prediction: $\varepsilon = (D/C)(A y - (B/F) u)$; simulation:
/// $\varepsilon = y - B/(AF)\,u$. `None` if the predictor is unstable or the result not finite.
pub(crate) fn errors(
    p: &Polys,
    y: &[f64],
    u: &[f64],
    focus: Focus,
    accuracy: Accuracy,
) -> Option<Vec<f64>> {
    if !predictor_stable(p, focus) {
        return None;
    }
    let (w, _) = output_error(p, y, u, focus, accuracy);
    let e = match focus {
        Focus::Prediction => filter(&p.d, &p.c, &w),
        Focus::Simulation => w,
    };
    e.iter().all(|v| v.is_finite()).then_some(e)
}

/// Prediction errors and their gradient $\psi = \partial\varepsilon/\partial\theta$ ($N \times d$,
/// columns in the order of $\theta$). Columns of parameters the criterion does not depend on
/// (C and D under the simulation focus) are zero.
pub(crate) fn errors_and_gradient(
    p: &Polys,
    o: &Orders,
    y: &[f64],
    u: &[f64],
    focus: Focus,
) -> Option<(Vec<f64>, Mat<f64>)> {
    errors_and_gradient_with(p, o, y, u, focus, Accuracy::Exact)
}

/// The gradient alone ([`errors_and_gradient`] with the errors in plain double precision: the
/// Levenberg–Marquardt iteration takes its residuals from [`errors`]).
pub(crate) fn gradient(
    p: &Polys,
    o: &Orders,
    y: &[f64],
    u: &[f64],
    focus: Focus,
) -> Option<Mat<f64>> {
    errors_and_gradient_with(p, o, y, u, focus, Accuracy::Plain).map(|(_, j)| j)
}

fn errors_and_gradient_with(
    p: &Polys,
    o: &Orders,
    y: &[f64],
    u: &[f64],
    focus: Focus,
    accuracy: Accuracy,
) -> Option<(Vec<f64>, Mat<f64>)> {
    if !predictor_stable(p, focus) {
        return None;
    }
    let n = y.len();
    let (ia, ib, ic, id) = (
        o.na,
        o.na + o.nb,
        o.na + o.nb + o.nc,
        o.na + o.nb + o.nc + o.nd,
    );
    let mut jac = Mat::<f64>::zeros(n, o.n_params());
    let eps;
    match focus {
        Focus::Prediction => {
            let (w, v) = output_error(p, y, u, focus, accuracy); // A y − (B/F) u and (B/F) u
            eps = filter(&p.d, &p.c, &w);
            let cf = mul(&p.c, &p.f);
            // ∂ε/∂a_i = (D/C) y(t−i)
            if o.na > 0 {
                let yt = filter(&p.d, &p.c, y);
                for i in 0..o.na {
                    for t in 0..n {
                        jac[(t, i)] = shifted(&yt, i + 1, t);
                    }
                }
            }
            // ∂ε/∂b_j = −(D/(CF)) u(t−nk−j)
            let ut = filter(&p.d, &cf, u);
            for j in 0..o.nb {
                for t in 0..n {
                    jac[(t, ia + j)] = -shifted(&ut, o.nk + j, t);
                }
            }
            // ∂ε/∂c_i = −(1/C) ε(t−i)
            if o.nc > 0 {
                let et = filter(&[1.0], &p.c, &eps);
                for i in 0..o.nc {
                    for t in 0..n {
                        jac[(t, ib + i)] = -shifted(&et, i + 1, t);
                    }
                }
            }
            // ∂ε/∂d_i = (1/C) w(t−i)
            if o.nd > 0 {
                let wt = filter(&[1.0], &p.c, &w);
                for i in 0..o.nd {
                    for t in 0..n {
                        jac[(t, ic + i)] = shifted(&wt, i + 1, t);
                    }
                }
            }
            // ∂ε/∂f_i = (D B/(C F²)) u(t−i) = (D/(CF)) v(t−i)
            if o.nf > 0 {
                let vt = filter(&p.d, &cf, &v);
                for i in 0..o.nf {
                    for t in 0..n {
                        jac[(t, id + i)] = shifted(&vt, i + 1, t);
                    }
                }
            }
        }
        Focus::Simulation => {
            let af = mul(&p.a, &p.f);
            let (w, g) = output_error(p, y, u, focus, accuracy); // y − B/(AF) u and B/(AF) u
            eps = w;
            // ∂ε/∂a_i = (B/(A²F)) u(t−i) = (1/A) g(t−i)
            if o.na > 0 {
                let ga = filter(&[1.0], &p.a, &g);
                for i in 0..o.na {
                    for t in 0..n {
                        jac[(t, i)] = shifted(&ga, i + 1, t);
                    }
                }
            }
            // ∂ε/∂b_j = −(1/(AF)) u(t−nk−j)
            let ut = filter(&[1.0], &af, u);
            for j in 0..o.nb {
                for t in 0..n {
                    jac[(t, ia + j)] = -shifted(&ut, o.nk + j, t);
                }
            }
            // ∂ε/∂f_i = (1/F) g(t−i)
            if o.nf > 0 {
                let gf = filter(&[1.0], &p.f, &g);
                for i in 0..o.nf {
                    for t in 0..n {
                        jac[(t, id + i)] = shifted(&gf, i + 1, t);
                    }
                }
            }
        }
    }
    let finite = eps.iter().all(|v| v.is_finite())
        && (0..jac.ncols()).all(|j| jac.col(j).iter().all(|v| v.is_finite()));
    finite.then_some((eps, jac))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schur_cohn_agrees_with_roots() {
        let cases: [(&[f64], bool); 7] = [
            (&[1.0], true),
            (&[1.0, -0.5], true),
            (&[1.0, -1.0], false),
            (&[1.0, -1.5, 0.7], true),
            (&[1.0, -2.0 * 0.98 * 0.3f64.cos(), 0.9604], true),
            (&[1.0, -2.1, 1.1], false),
            (&[1.0, 0.0, 0.0, 1.01], false),
        ];
        for (p, want) in cases {
            assert_eq!(is_stable(p), want, "{p:?}");
            assert_eq!(max_root(p) < 1.0, want, "{p:?}");
        }
    }

    #[test]
    fn output_error_is_accurate_under_cancellation() {
        // y = B/F u + 1e-12 · e: w must be 1e-12 · e to ~1e-15 relative, where plain double
        // arithmetic leaves an error of ~1e-16 · |y|, i.e. 1e-4 relative
        let u: Vec<f64> = (0..400)
            .map(|k| ((k * 37 % 101) as f64 - 50.0) / 7.0)
            .collect();
        let e: Vec<f64> = (0..400)
            .map(|k| ((k * 53 % 97) as f64 - 48.0) / 9.0)
            .collect();
        let p = Polys {
            a: vec![1.0],
            b: vec![0.0, 0.3, 0.2],
            c: vec![1.0],
            d: vec![1.0],
            f: vec![1.0, -1.9, 0.95],
        };
        let v = filter_dd(&p.b, &p.f, &u);
        let y: Vec<f64> = v
            .iter()
            .zip(&e)
            .map(|(v, e)| (v.hi + v.lo) + 1e-12 * e)
            .collect();
        let (w, _) = output_error(&p, &y, &u, Focus::Prediction, Accuracy::Exact);
        // the bound sees the cancellation and falls back to double-double
        let (wb, _) = output_error(
            &p,
            &y,
            &u,
            Focus::Prediction,
            Accuracy::RelativeBound(1e-10),
        );
        assert_eq!(w, wb);
        for t in 0..400 {
            // y[t] itself is rounded: |y| · 2^-53 is the best possible
            assert!(
                (w[t] - 1e-12 * e[t]).abs() <= 2.0 * f64::EPSILON * y[t].abs(),
                "{t}"
            );
        }
        let (a, b) = two_prod(1.0 + f64::EPSILON, 1.0 - f64::EPSILON);
        assert_eq!(a, 1.0);
        assert_eq!(b, -f64::EPSILON * f64::EPSILON);
    }

    #[test]
    fn plain_residual_is_used_only_within_its_bound() {
        // ARMAX-like (F = 1, no recursion) with noise of 1 % of the output: the bound allows
        // plain double, and the plain result agrees with double-double to the bound's level
        let u: Vec<f64> = (0..2000)
            .map(|k| ((k * 37 % 101) as f64 - 50.0) / 7.0)
            .collect();
        let e: Vec<f64> = (0..2000)
            .map(|k| ((k * 53 % 97) as f64 - 48.0) / 9.0)
            .collect();
        let p = Polys {
            a: vec![1.0, -1.5, 0.7],
            b: vec![0.0, 1.0, 0.5],
            c: vec![1.0],
            d: vec![1.0],
            f: vec![1.0],
        };
        let g = filter(&p.b, &p.a, &u);
        let y: Vec<f64> = g.iter().zip(&e).map(|(g, e)| g + 0.01 * e).collect();
        let tau = 1e-10;
        let (exact, _) = output_error(&p, &y, &u, Focus::Prediction, Accuracy::Exact);
        let (bounded, _) =
            output_error(&p, &y, &u, Focus::Prediction, Accuracy::RelativeBound(tau));
        let (plain, _) = output_error(&p, &y, &u, Focus::Prediction, Accuracy::Plain);
        assert_eq!(bounded, plain, "the bound should allow plain double here");
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let diff: Vec<f64> = plain.iter().zip(&exact).map(|(a, b)| a - b).collect();
        assert!(
            norm(&diff) <= tau * norm(&exact),
            "{}",
            norm(&diff) / norm(&exact)
        );
        // a lightly damped F (‖h‖₁ ≈ 10³) with the same noise: double-double is chosen
        let q = Polys {
            a: vec![1.0],
            b: vec![0.0, 0.3, 0.2],
            c: vec![1.0],
            d: vec![1.0],
            f: vec![1.0, -2.0 * 0.999 * 0.05f64.cos(), 0.998001],
        };
        let v = filter(&q.b, &q.f, &u);
        let y: Vec<f64> = v.iter().zip(&e).map(|(v, e)| v + 1e-6 * e).collect();
        let (exact, _) = output_error(&q, &y, &u, Focus::Prediction, Accuracy::Exact);
        let (bounded, _) =
            output_error(&q, &y, &u, Focus::Prediction, Accuracy::RelativeBound(tau));
        assert_eq!(bounded, exact);
        assert!(impulse_l1(&q.f, 20_000) > 100.0);
    }

    #[test]
    fn filter_is_the_difference_equation() {
        // y = (1 + 0.5 q^-1)/(1 - 0.8 q^-1) x for an impulse
        let y = filter(&[1.0, 0.5], &[1.0, -0.8], &[1.0, 0.0, 0.0, 0.0]);
        let want = [1.0, 1.3, 1.04, 0.832];
        for (a, b) in y.iter().zip(want) {
            assert!((a - b).abs() < 1e-15);
        }
    }
}
