//! The one-step predictor of the general polynomial model, its prediction errors and their
//! analytic gradient (filtered regressors), with zero initial conditions.

use super::lm::all_finite;
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

/// Samples per block of [`filter`], [`filter_dd`] and [`abs_sum_norm`]: the numerator pass and
/// the recursion of one block work on data that stays in the L1 cache.
const BLOCK: usize = 1024;

/// $y = (\text{num}/\text{den})\,x$ with zero initial conditions; `den` monic (`den[0]` is not
/// read).
///
/// Each output is summed in one fixed order, the numerator terms $\text{num}_k x_{t-k}$
/// ($k = 0, 1, \dots$, from $0.0$) and then the terms $-\text{den}_k y_{t-k}$ ($k = 1, 2, \dots$),
/// each only while $t - k \ge 0$; the numerator terms of a block of samples are added lag by lag
/// (independent samples, vectorised), the recursion then runs sample by sample.
pub(crate) fn filter(num: &[f64], den: &[f64], x: &[f64]) -> Vec<f64> {
    let n = x.len();
    let mut y = vec![0.0; n];
    let a = den.get(1..).unwrap_or(&[]);
    let mut t0 = 0;
    while t0 < n {
        let t1 = (t0 + BLOCK).min(n);
        numerator_block(num, x, &mut y, t0, t1);
        recursion(a, &mut y, t0, t1);
        t0 = t1;
    }
    y
}

/// [`filter`] of several independent signals, `jobs[i] = (num, den, x)`, each output bit for bit
/// that of `filter(num, den, x)`. The recursions of equal order run interleaved (two or three
/// at a time), so that their dependency chains overlap: one recursion alone is bound by the
/// latency of its $n_a + 1$ dependent operations per sample.
pub(crate) fn filter_many(jobs: &[(&[f64], &[f64], &[f64])]) -> Vec<Vec<f64>> {
    let n = jobs.first().map_or(0, |j| j.2.len());
    if jobs.iter().any(|j| j.2.len() != n) {
        return jobs.iter().map(|(b, a, x)| filter(b, a, x)).collect();
    }
    let order = |j: usize| jobs[j].1.len().saturating_sub(1);
    let max_group = |nd: usize| match nd {
        1..=4 => 3,
        5..=8 => 2,
        _ => 1,
    };
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for j in 0..jobs.len() {
        match groups
            .iter_mut()
            .find(|g| order(g[0]) == order(j) && g.len() < max_group(order(j)))
        {
            Some(g) => g.push(j),
            None => groups.push(vec![j]),
        }
    }
    let mut ys: Vec<Vec<f64>> = jobs.iter().map(|_| vec![0.0; n]).collect();
    let mut t0 = 0;
    while t0 < n {
        let t1 = (t0 + BLOCK).min(n);
        for ((num, _, x), y) in jobs.iter().zip(ys.iter_mut()) {
            numerator_block(num, x, y, t0, t1);
        }
        for g in &groups {
            let den = |j: usize| jobs[j].1.get(1..).unwrap_or(&[]);
            match g[..] {
                [i] => recursion(den(i), &mut ys[i], t0, t1),
                [i, j] => {
                    let (mut yi, mut yj) = (std::mem::take(&mut ys[i]), std::mem::take(&mut ys[j]));
                    recursion_group([den(i), den(j)], [&mut yi, &mut yj], t0, t1);
                    (ys[i], ys[j]) = (yi, yj);
                }
                [i, j, k] => {
                    let (mut yi, mut yj, mut yk) = (
                        std::mem::take(&mut ys[i]),
                        std::mem::take(&mut ys[j]),
                        std::mem::take(&mut ys[k]),
                    );
                    recursion_group(
                        [den(i), den(j), den(k)],
                        [&mut yi, &mut yj, &mut yk],
                        t0,
                        t1,
                    );
                    (ys[i], ys[j], ys[k]) = (yi, yj, yk);
                }
                _ => {
                    for &i in g {
                        recursion(den(i), &mut ys[i], t0, t1);
                    }
                }
            }
        }
        t0 = t1;
    }
    ys
}

/// $y_t \leftarrow y_t + \sum_k \text{num}_k x_{t-k}$ ($0 \le k \le t$, in that order of $k$) for
/// $t \in [t_0, t_1)$: lag by lag over the block.
fn numerator_block(num: &[f64], x: &[f64], y: &mut [f64], t0: usize, t1: usize) {
    for (k, &bk) in num.iter().enumerate() {
        let s = t0.max(k);
        if s >= t1 {
            break;
        }
        for (yv, xv) in y[s..t1].iter_mut().zip(&x[s - k..t1 - k]) {
            *yv += bk * xv;
        }
    }
}

/// [`recursion`] of `M` signals of one order at once (interleaved sample by sample).
fn recursion_group<const M: usize>(a: [&[f64]; M], y: [&mut [f64]; M], t0: usize, t1: usize) {
    macro_rules! fixed {
        ($($n:literal)*) => {
            match a[0].len() {
                $($n => recursion_group_fixed::<$n, M>(a, y, t0, t1),)*
                _ => {
                    for (aj, yj) in a.into_iter().zip(y) {
                        recursion(aj, yj, t0, t1);
                    }
                }
            }
        };
    }
    fixed!(1 2 3 4 5 6 7 8);
}

/// [`recursion_group`] for the order `N`: the last `N` outputs of each signal in registers.
// `t` indexes all `M` signals at once: no single iterator replaces it
#[allow(clippy::needless_range_loop)]
fn recursion_group_fixed<const N: usize, const M: usize>(
    a: [&[f64]; M],
    y: [&mut [f64]; M],
    t0: usize,
    t1: usize,
) {
    let mut c = [[0.0; N]; M];
    let warm = t1.min(N).max(t0);
    if a.iter().any(|aj| aj.len() != N) || y.iter().any(|yj| yj.len() < t1) {
        for (aj, yj) in a.into_iter().zip(y) {
            recursion(aj, yj, t0, t1);
        }
        return;
    }
    for j in 0..M {
        c[j].copy_from_slice(a[j]);
        recursion_any(a[j], y[j], t0, warm);
    }
    if warm >= t1 {
        return;
    }
    // h[j][k] = y_j[t − 1 − k]
    let mut h = [[0.0; N]; M];
    for j in 0..M {
        for k in 0..N {
            h[j][k] = y[j][warm - 1 - k];
        }
    }
    for t in warm..t1 {
        for j in 0..M {
            let mut s = y[j][t];
            for k in 0..N {
                s -= c[j][k] * h[j][k];
            }
            for k in (1..N).rev() {
                h[j][k] = h[j][k - 1];
            }
            h[j][0] = s;
            y[j][t] = s;
        }
    }
}

/// $y_t \leftarrow y_t - \sum_{k=1}^{\min(n_a, t)} a_k y_{t-k}$ for $t \in [t_0, t_1)$, in that
/// order of $k$ (`a` holds $a_1, \dots, a_{n_a}$); the outputs before $t_0$ are final.
fn recursion(a: &[f64], y: &mut [f64], t0: usize, t1: usize) {
    macro_rules! fixed {
        ($($n:literal)*) => {
            match a.len() {
                0 => {}
                $($n => recursion_fixed::<$n>(a, y, t0, t1),)*
                _ => recursion_any(a, y, t0, t1),
            }
        };
    }
    fixed!(1 2 3 4 5 6 7 8 9 10 11 12);
}

/// [`recursion`] for any order (and the first samples, with fewer than $n_a$ past outputs).
fn recursion_any(a: &[f64], y: &mut [f64], t0: usize, t1: usize) {
    for t in t0..t1 {
        let mut s = y[t];
        for (k, ak) in a.iter().enumerate().take(t) {
            s -= ak * y[t - 1 - k];
        }
        y[t] = s;
    }
}

/// [`recursion`] for the order `N`: the last `N` outputs stay in registers.
fn recursion_fixed<const N: usize>(a: &[f64], y: &mut [f64], t0: usize, t1: usize) {
    let Ok(a) = <&[f64; N]>::try_from(a) else {
        return recursion_any(a, y, t0, t1);
    };
    let warm = t1.min(N).max(t0);
    recursion_any(a, y, t0, warm);
    if warm >= t1 {
        return;
    }
    // h[k] = y[t − 1 − k]
    let mut h = [0.0; N];
    for (k, hk) in h.iter_mut().enumerate() {
        *hk = y[warm - 1 - k];
    }
    for v in &mut y[warm..t1] {
        let mut s = *v;
        for k in 0..N {
            s -= a[k] * h[k];
        }
        // a shift of constant indices (not `rotate_right`, a memory move): h stays in registers
        for k in (1..N).rev() {
            h[k] = h[k - 1];
        }
        h[0] = s;
        *v = s;
    }
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

/// `filter` in double-double arithmetic (about 32 significant digits), in the same order of
/// terms as [`filter`] (the zero numerator coefficients skipped).
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
    let a = den.get(1..).unwrap_or(&[]);
    let mut t0 = 0;
    while t0 < n {
        let t1 = (t0 + BLOCK).min(n);
        for &(k, bk) in &nz {
            let s = t0.max(k);
            if s >= t1 {
                break;
            }
            for (yv, xv) in y[s..t1].iter_mut().zip(&x[s - k..t1 - k]) {
                let (p, e) = two_prod(bk, *xv);
                *yv = yv.add(Dd { hi: p, lo: e });
            }
        }
        recursion_dd(a, &mut y, t0, t1);
        t0 = t1;
    }
    y
}

/// [`recursion`] in double-double arithmetic: $y_t \leftarrow y_t + \sum_k (-a_k)\,y_{t-k}$.
fn recursion_dd(a: &[f64], y: &mut [Dd], t0: usize, t1: usize) {
    macro_rules! fixed {
        ($($n:literal)*) => {
            match a.len() {
                0 => {}
                $($n => recursion_dd_fixed::<$n>(a, y, t0, t1),)*
                _ => recursion_dd_any(a, y, t0, t1),
            }
        };
    }
    fixed!(1 2 3 4 5 6 7 8 9 10 11 12);
}

fn recursion_dd_any(a: &[f64], y: &mut [Dd], t0: usize, t1: usize) {
    for t in t0..t1 {
        let mut s = y[t];
        for (k, ak) in a.iter().enumerate().take(t) {
            s = s.add(y[t - 1 - k].scale(-ak));
        }
        y[t] = s;
    }
}

fn recursion_dd_fixed<const N: usize>(a: &[f64], y: &mut [Dd], t0: usize, t1: usize) {
    let Ok(a) = <&[f64; N]>::try_from(a) else {
        return recursion_dd_any(a, y, t0, t1);
    };
    let warm = t1.min(N).max(t0);
    recursion_dd_any(a, y, t0, warm);
    if warm >= t1 {
        return;
    }
    // h[k] = y[t − 1 − k]
    let mut h = [Dd::default(); N];
    for (k, hk) in h.iter_mut().enumerate() {
        *hk = y[warm - 1 - k];
    }
    for v in &mut y[warm..t1] {
        let mut s = *v;
        for k in 0..N {
            s = s.add(h[k].scale(-a[k]));
        }
        // a shift of constant indices (not `rotate_right`, a memory move): h stays in registers
        for k in (1..N).rev() {
            h[k] = h[k - 1];
        }
        h[0] = s;
        *v = s;
    }
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
    let n = x.len();
    let d = den.get(1..).unwrap_or(&[]);
    let mut buf = vec![0.0; BLOCK.min(n)];
    let mut acc = 0.0;
    let mut t0 = 0;
    while t0 < n {
        let t1 = (t0 + BLOCK).min(n);
        let s = &mut buf[..t1 - t0];
        s.fill(0.0);
        for (k, ck) in c.iter().enumerate() {
            let st = t0.max(k);
            if st >= t1 {
                break;
            }
            let ca = ck.abs();
            for (sv, xv) in s[st - t0..].iter_mut().zip(&x[st - k..t1 - k]) {
                *sv += ca * xv.abs();
            }
        }
        for (j, dk) in d.iter().enumerate() {
            let k = j + 1;
            let st = t0.max(k);
            if st >= t1 {
                break;
            }
            let da = dk.abs();
            for (sv, ov) in s[st - t0..].iter_mut().zip(&out[st - k..t1 - k]) {
                *sv += da * ov.abs();
            }
        }
        for v in s.iter() {
            acc += v * v;
        }
        t0 = t1;
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

/// Column `col` of `jac` $\leftarrow \pm x(t - k)$, $\pm 0$ before the start (`negate` for the
/// minus sign).
pub(crate) fn fill_shifted(jac: &mut Mat<f64>, col: usize, x: &[f64], k: usize, negate: bool) {
    let c = jac.col_as_slice_mut(col);
    let (head, tail) = c.split_at_mut(k.min(c.len()));
    if negate {
        head.fill(-0.0);
        for (d, v) in tail.iter_mut().zip(x) {
            *d = -v;
        }
    } else {
        head.fill(0.0);
        for (d, v) in tail.iter_mut().zip(x) {
            *d = *v;
        }
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
    all_finite(&e).then_some(e)
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
            let cf = mul(&p.c, &p.f);
            let one = [1.0];
            // the independent filters at once: ε = (D/C) w, (D/C) y, (D/(CF)) u, (1/C) w,
            // (D/(CF)) v
            let mut jobs: Vec<(&[f64], &[f64], &[f64])> = vec![(&p.d, &p.c, &w), (&p.d, &cf, u)];
            let mut slot = |on: bool, job| {
                on.then(|| {
                    jobs.push(job);
                    jobs.len() - 1
                })
            };
            let iy = slot(o.na > 0, (&p.d, &p.c, y));
            let iw = slot(o.nd > 0, (&one, &p.c, &w));
            let iv = slot(o.nf > 0, (&p.d, &cf, &v));
            let mut out = filter_many(&jobs);
            let take = |out: &mut Vec<Vec<f64>>, i: usize| std::mem::take(&mut out[i]);
            eps = take(&mut out, 0);
            // ∂ε/∂a_i = (D/C) y(t−i)
            if let Some(k) = iy {
                let yt = take(&mut out, k);
                for i in 0..o.na {
                    fill_shifted(&mut jac, i, &yt, i + 1, false);
                }
            }
            // ∂ε/∂b_j = −(D/(CF)) u(t−nk−j)
            let ut = take(&mut out, 1);
            for j in 0..o.nb {
                fill_shifted(&mut jac, ia + j, &ut, o.nk + j, true);
            }
            // ∂ε/∂c_i = −(1/C) ε(t−i)
            if o.nc > 0 {
                let et = filter(&one, &p.c, &eps);
                for i in 0..o.nc {
                    fill_shifted(&mut jac, ib + i, &et, i + 1, true);
                }
            }
            // ∂ε/∂d_i = (1/C) w(t−i)
            if let Some(k) = iw {
                let wt = take(&mut out, k);
                for i in 0..o.nd {
                    fill_shifted(&mut jac, ic + i, &wt, i + 1, false);
                }
            }
            // ∂ε/∂f_i = (D B/(C F²)) u(t−i) = (D/(CF)) v(t−i)
            if let Some(k) = iv {
                let vt = take(&mut out, k);
                for i in 0..o.nf {
                    fill_shifted(&mut jac, id + i, &vt, i + 1, false);
                }
            }
        }
        Focus::Simulation => {
            let af = mul(&p.a, &p.f);
            let (w, g) = output_error(p, y, u, focus, accuracy); // y − B/(AF) u and B/(AF) u
            eps = w;
            let one = [1.0];
            // the independent filters at once: (1/(AF)) u, (1/A) g, (1/F) g
            let mut jobs: Vec<(&[f64], &[f64], &[f64])> = vec![(&one, &af, u)];
            let mut slot = |on: bool, job| {
                on.then(|| {
                    jobs.push(job);
                    jobs.len() - 1
                })
            };
            let ia_job = slot(o.na > 0, (&one, &p.a, &g));
            let if_job = slot(o.nf > 0, (&one, &p.f, &g));
            let mut out = filter_many(&jobs);
            // ∂ε/∂a_i = (B/(A²F)) u(t−i) = (1/A) g(t−i)
            if let Some(k) = ia_job {
                for i in 0..o.na {
                    fill_shifted(&mut jac, i, &out[k], i + 1, false);
                }
            }
            // ∂ε/∂b_j = −(1/(AF)) u(t−nk−j)
            let ut = std::mem::take(&mut out[0]);
            for j in 0..o.nb {
                fill_shifted(&mut jac, ia + j, &ut, o.nk + j, true);
            }
            // ∂ε/∂f_i = (1/F) g(t−i)
            if let Some(k) = if_job {
                for i in 0..o.nf {
                    fill_shifted(&mut jac, id + i, &out[k], i + 1, false);
                }
            }
        }
    }
    let finite = all_finite(&eps) && (0..jac.ncols()).all(|j| all_finite(jac.col_as_slice(j)));
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

    /// The implementations before the block-wise rewrite (issue 16), kept as the oracle of
    /// `new_filters_are_bit_identical_to_the_old_ones`.
    mod oracle {
        use super::super::*;

        pub(super) fn old_filter(num: &[f64], den: &[f64], x: &[f64]) -> Vec<f64> {
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

        pub(super) fn old_filter_dd(num: &[f64], den: &[f64], x: &[f64]) -> Vec<Dd> {
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

        pub(super) fn old_abs_sum_norm(c: &[f64], x: &[f64], den: &[f64], out: &[f64]) -> f64 {
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

        pub(super) fn old_output_error(
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
                let v = old_filter(&p.b, &den, u);
                let unit_a = a.len() == 1 && a[0] == 1.0;
                let ay = if unit_a {
                    y.to_vec()
                } else {
                    old_filter(a, &[1.0], y)
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
                            gamma(a.len()) * old_abs_sum_norm(a, y, &[1.0], &[])
                        };
                        let wn = w.iter().map(|x| x * x).sum::<f64>().sqrt();
                        let gain = impulse_l1(&den, y.len()) * gamma(nb + den.len() - 1);
                        // |v_t| is at most the term magnitude of its step: a cheap lower bound first
                        let vn = v.iter().map(|x| x * x).sum::<f64>().sqrt();
                        let err_v = if gain * vn > tau * wn {
                            f64::INFINITY
                        } else {
                            gain * old_abs_sum_norm(&p.b, u, &den, &v)
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
            let v = old_filter_dd(&p.b, &den, u);
            let ay = old_filter_dd(a, &[1.0], y);
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

        fn old_shifted(x: &[f64], k: usize, t: usize) -> f64 {
            if t >= k {
                x[t - k]
            } else {
                0.0
            }
        }

        pub(super) fn old_errors_and_gradient_with(
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
                    let (w, v) = old_output_error(p, y, u, focus, accuracy); // A y − (B/F) u and (B/F) u
                    eps = old_filter(&p.d, &p.c, &w);
                    let cf = mul(&p.c, &p.f);
                    // ∂ε/∂a_i = (D/C) y(t−i)
                    if o.na > 0 {
                        let yt = old_filter(&p.d, &p.c, y);
                        for i in 0..o.na {
                            for t in 0..n {
                                jac[(t, i)] = old_shifted(&yt, i + 1, t);
                            }
                        }
                    }
                    // ∂ε/∂b_j = −(D/(CF)) u(t−nk−j)
                    let ut = old_filter(&p.d, &cf, u);
                    for j in 0..o.nb {
                        for t in 0..n {
                            jac[(t, ia + j)] = -old_shifted(&ut, o.nk + j, t);
                        }
                    }
                    // ∂ε/∂c_i = −(1/C) ε(t−i)
                    if o.nc > 0 {
                        let et = old_filter(&[1.0], &p.c, &eps);
                        for i in 0..o.nc {
                            for t in 0..n {
                                jac[(t, ib + i)] = -old_shifted(&et, i + 1, t);
                            }
                        }
                    }
                    // ∂ε/∂d_i = (1/C) w(t−i)
                    if o.nd > 0 {
                        let wt = old_filter(&[1.0], &p.c, &w);
                        for i in 0..o.nd {
                            for t in 0..n {
                                jac[(t, ic + i)] = old_shifted(&wt, i + 1, t);
                            }
                        }
                    }
                    // ∂ε/∂f_i = (D B/(C F²)) u(t−i) = (D/(CF)) v(t−i)
                    if o.nf > 0 {
                        let vt = old_filter(&p.d, &cf, &v);
                        for i in 0..o.nf {
                            for t in 0..n {
                                jac[(t, id + i)] = old_shifted(&vt, i + 1, t);
                            }
                        }
                    }
                }
                Focus::Simulation => {
                    let af = mul(&p.a, &p.f);
                    let (w, g) = old_output_error(p, y, u, focus, accuracy); // y − B/(AF) u and B/(AF) u
                    eps = w;
                    // ∂ε/∂a_i = (B/(A²F)) u(t−i) = (1/A) g(t−i)
                    if o.na > 0 {
                        let ga = old_filter(&[1.0], &p.a, &g);
                        for i in 0..o.na {
                            for t in 0..n {
                                jac[(t, i)] = old_shifted(&ga, i + 1, t);
                            }
                        }
                    }
                    // ∂ε/∂b_j = −(1/(AF)) u(t−nk−j)
                    let ut = old_filter(&[1.0], &af, u);
                    for j in 0..o.nb {
                        for t in 0..n {
                            jac[(t, ia + j)] = -old_shifted(&ut, o.nk + j, t);
                        }
                    }
                    // ∂ε/∂f_i = (1/F) g(t−i)
                    if o.nf > 0 {
                        let gf = old_filter(&[1.0], &p.f, &g);
                        for i in 0..o.nf {
                            for t in 0..n {
                                jac[(t, id + i)] = old_shifted(&gf, i + 1, t);
                            }
                        }
                    }
                }
            }
            let finite = eps.iter().all(|v| v.is_finite())
                && (0..jac.ncols()).all(|j| jac.col(j).iter().all(|v| v.is_finite()));
            finite.then_some((eps, jac))
        }
    }

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    fn bits_dd(v: &[Dd]) -> Vec<(u64, u64)> {
        v.iter().map(|x| (x.hi.to_bits(), x.lo.to_bits())).collect()
    }

    /// A monic polynomial with `n` roots of magnitude below 0.995 (real or in conjugate pairs).
    fn stable_poly(rng: &mut rand_chacha::ChaCha8Rng, n: usize) -> Vec<f64> {
        use rand::RngExt;
        let mut p = vec![1.0];
        let mut left = n;
        while left > 0 {
            let r: f64 = rng.random_range(0.0..0.995);
            if left >= 2 && rng.random_range(0..2) == 0 {
                let w: f64 = rng.random_range(0.0..std::f64::consts::PI);
                p = mul(&p, &[1.0, -2.0 * r * w.cos(), r * r]);
                left -= 2;
            } else {
                let sign = if rng.random_range(0..2) == 0 {
                    -1.0
                } else {
                    1.0
                };
                p = mul(&p, &[1.0, sign * r]);
                left -= 1;
            }
        }
        p
    }

    fn random_vec(rng: &mut rand_chacha::ChaCha8Rng, n: usize) -> Vec<f64> {
        use rand::RngExt;
        (0..n)
            .map(|k| match k % 17 {
                3 => 0.0,
                11 => -0.0,
                _ => rng.random_range(-3.0..3.0),
            })
            .collect()
    }

    #[test]
    fn new_filters_are_bit_identical_to_the_old_ones() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(16);
        let lengths = [0, 1, 2, 3, 7, 15, 1023, 1024, 1025, 2049, 3000];
        for case in 0..400 {
            let n = lengths[case % lengths.len()];
            let x = random_vec(&mut rng, n);
            let out = random_vec(&mut rng, n);
            // numerators of 0..=15 coefficients, some with leading (and inner) zeros
            let nb = rng.random_range(0..16);
            let mut num = random_vec(&mut rng, nb);
            let lead = rng.random_range(0..4).min(nb);
            for v in num.iter_mut().take(lead) {
                *v = 0.0;
            }
            // denominators of order 0..=14 (the fixed orders 1..=12 and the general loop),
            // also the empty list and a den of length 1
            let nd = case % 15;
            let den = match case % 23 {
                0 => vec![],
                1 => vec![1.0],
                _ => stable_poly(&mut rng, nd),
            };
            let msg = format!("case {case}: n {n}, num {num:?}, den {den:?}");
            assert_eq!(
                bits(&filter(&num, &den, &x)),
                bits(&oracle::old_filter(&num, &den, &x)),
                "filter, {msg}"
            );
            assert_eq!(
                bits_dd(&filter_dd(&num, &den, &x)),
                bits_dd(&oracle::old_filter_dd(&num, &den, &x)),
                "filter_dd, {msg}"
            );
            assert_eq!(
                abs_sum_norm(&num, &x, &den, &out).to_bits(),
                oracle::old_abs_sum_norm(&num, &x, &den, &out).to_bits(),
                "abs_sum_norm, {msg}"
            );
        }
    }

    #[test]
    fn new_errors_and_gradient_are_bit_identical_to_the_old_ones() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let lengths = [40, 1023, 1025, 2600];
        for case in 0..60 {
            let n = lengths[case % lengths.len()];
            let o = Orders {
                na: rng.random_range(0..5),
                nb: rng.random_range(1..5),
                nc: rng.random_range(0..5),
                nd: rng.random_range(0..4),
                nf: rng.random_range(0..5),
                nk: rng.random_range(0..3),
            };
            let mut b = vec![0.0; o.nk];
            b.extend(random_vec(&mut rng, o.nb).iter().map(|v| 0.3 * v));
            let p = Polys {
                a: stable_poly(&mut rng, o.na),
                b,
                c: stable_poly(&mut rng, o.nc),
                d: stable_poly(&mut rng, o.nd),
                f: stable_poly(&mut rng, o.nf),
            };
            let u = random_vec(&mut rng, n);
            // y = B/(AF) u + noise: realistic cancellation in w for the bound
            let g = filter(&p.b, &mul(&p.a, &p.f), &u);
            let scale = [1.0, 1e-3, 1e-9][case % 3];
            let e = random_vec(&mut rng, n);
            let y: Vec<f64> = g.iter().zip(&e).map(|(g, e)| g + scale * e).collect();
            for focus in [Focus::Prediction, Focus::Simulation] {
                for acc in [
                    Accuracy::Exact,
                    Accuracy::Plain,
                    Accuracy::RelativeBound(1e-6),
                    Accuracy::RelativeBound(1e-12),
                ] {
                    let msg = format!("case {case}: {o:?} {focus:?} {acc:?}");
                    let (w1, v1) = output_error(&p, &y, &u, focus, acc);
                    let (w0, v0) = oracle::old_output_error(&p, &y, &u, focus, acc);
                    assert_eq!(bits(&w1), bits(&w0), "w, {msg}");
                    assert_eq!(bits(&v1), bits(&v0), "v, {msg}");
                    let new = errors_and_gradient_with(&p, &o, &y, &u, focus, acc);
                    let old = oracle::old_errors_and_gradient_with(&p, &o, &y, &u, focus, acc);
                    let (Some((e1, j1)), Some((e0, j0))) = (new, old) else {
                        panic!("both must be defined, {msg}");
                    };
                    assert_eq!(bits(&e1), bits(&e0), "errors, {msg}");
                    assert_eq!(j1.ncols(), j0.ncols());
                    for c in 0..j1.ncols() {
                        assert_eq!(
                            bits(j1.col_as_slice(c)),
                            bits(j0.col_as_slice(c)),
                            "column {c}, {msg}"
                        );
                    }
                }
            }
        }
    }
}
