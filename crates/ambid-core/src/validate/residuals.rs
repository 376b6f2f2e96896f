//! Residual analysis: whiteness of a model's prediction errors and their independence from the
//! input, each as one portmanteau $\chi^2$ test whose 95 % level is 95 % for the true model
//! (Ljung, *System Identification*, 2nd ed., section 16.6; Box & Jenkins; Haugh 1976).
//!
//! # Which test means what
//! * **Whiteness** is a property of the *prediction errors of a model with a noise model* (ARX,
//!   ARMAX, BJ, innovations state space): for the true model they are the white innovations.
//!   The output error $y - \hat y$ of a model *without* a noise model (output error, or a plant
//!   model simulated in the closed loop with the controller) is the filtered noise — in closed
//!   loop $\varepsilon = S v$ — and is **not** white even for the true plant: use
//!   [`analyze_output_error`], which does not test it.
//! * **Independence** from the input holds for the true model's errors in every structure, as long
//!   as the "input" is a signal the noise does not reach: in open loop the input $u$, in closed
//!   loop the **excitation** $r$ (or the reference $w$), never the plant input $u$, which contains
//!   $-C v$.
//!
//! # Statistics
//! With $N$ residuals $\varepsilon$ and the input $u$, both with their means removed, and the
//! sample covariances $\hat R_\varepsilon(k) = \frac1N \sum_t \varepsilon(t)\varepsilon(t-k)$,
//! $\hat R_{\varepsilon u}(\tau) = \frac1N \sum_t \varepsilon(t) u(t-\tau)$:
//! * **Whiteness** (Ljung–Box): $r(k) = \hat R_\varepsilon(k)/\hat R_\varepsilon(0)$,
//!   $Q = N(N+2) \sum_{k=1}^{M} r(k)^2/(N-k) \sim \chi^2(M)$ for white residuals. The per-lag
//!   bound $\pm 1.96/\sqrt N$ is drawn, but the verdict is the one $\chi^2$ test (about 5 % of the
//!   lags of a white sequence lie outside the bounds, so "any lag outside" would reject far more
//!   than 5 % of true models).
//! * **Independence** (generalised portmanteau): if $\varepsilon$ and $u$ are independent, the
//!   vector $x = (\hat R_{\varepsilon u}(\tau))_{\tau=-M..M}$ is asymptotically
//!   $\mathcal N(0, \Sigma/N)$ with
//!   $$\Sigma_{ij} = \sigma(i - j), \qquad \sigma(d) = \sum_{k=-\infty}^{\infty} R_\varepsilon(k)\, R_u(k + d).$$
//!   When neither signal is white (an output-error residual $S v$ and a held PRBS or a chirp)
//!   the lags are correlated with each other and each has a variance $\sigma(0) \neq
//!   R_\varepsilon(0) R_u(0)$: the usual $\pm 1.96/\sqrt N$ bound and $N\sum_\tau x(\tau)^2 /
//!   (R_\varepsilon(0) R_u(0)) \sim \chi^2(2M+1)$ are then both wrong. The test uses
//!   $$Q = N\, x^\top \hat\Sigma^{+} x \sim \chi^2(\operatorname{rank} \hat\Sigma),$$
//!   with $\hat\sigma(d) = \sum_{|k| \le K} w(k/K)\, \hat R_\varepsilon(k)\, \hat R_u(k + d)$ and the
//!   Parzen window $w$ (its transform is non-negative, so $\hat\Sigma$ is positive semidefinite,
//!   and its bias is $O(K^{-2})$). The form is taken in the directions in which the input has
//!   power: the eigenvectors $W$ of the input's own lag covariance $(\hat R_u(i-j))_{ij}$ with
//!   eigenvalues above $4/N$ of the largest ($x \to W^\top x$, $\hat\Sigma \to W^\top
//!   \hat\Sigma W$). An input with fewer spectral lines than lags (e.g. one sine) has a singular
//!   $\Sigma$, which the biased estimates blur by end effects of relative size $O(1/N)$; the
//!   degrees of freedom are the dimension kept (51 for a PRBS or noise input with $M = 25$, 4 for
//!   one sine).
//!   **Rule for $K$**: $K = \min(\max(\lceil 4\sqrt N\,\rceil, 2M),\ \lfloor N/4 \rfloor)$ — it
//!   grows with the record (consistency needs $K \to \infty$, $K/N \to 0$), and it must exceed
//!   the lags over which $R_\varepsilon(k) R_u(k)$ is non-negligible: for a PRBS with $B$ samples
//!   per bit that is $B + 2M$ whatever the residual's colour (55 lags for $B = 5$, $M = 25$;
//!   $K = 1280$ on the 102 300-sample seed experiment, 179 on 2000 samples). Calibration: see
//!   `tests/validate_residuals.rs` (white and coloured synthetic data, 500 seeds each) and
//!   `ambid`'s `tests/residuals_rigs.rs` (true plant in closed loop on random rigs).
//!   The per-lag bound drawn is $\pm 1.96 \sqrt{\hat\sigma(0)/(\hat R_\varepsilon(0) \hat R_u(0))}/\sqrt N$.
//! * **Verdicts**: a test passes when $Q$ is below the 95 % quantile of its $\chi^2$ distribution
//!   (Wilson–Hilferty approximation, relative error below 0.5 % for the degrees of freedom used
//!   here). The lags outside the per-lag bounds are reported for diagnosis only.
//!
//! # Example
//! ```
//! use ambid_core::validate::residuals::{analyze, analyze_output_error};
//! use rand::{RngExt, SeedableRng};
//! use rand_chacha::ChaCha8Rng;
//! use rand_distr::StandardNormal;
//! let mut rng = ChaCha8Rng::seed_from_u64(2);
//! let e: Vec<f64> = (0..4000).map(|_| rng.sample(StandardNormal)).collect();
//! let u: Vec<f64> = (0..4000).map(|_| rng.sample(StandardNormal)).collect();
//! // white e independent of u (a true model) passes each test in 95 % of records, as this one
//! let t = analyze(&e, Some(&u), 25).unwrap();
//! assert!(t.whiteness.unwrap().pass && t.independence.unwrap().pass);
//! // residuals that still contain the input fail
//! let bad: Vec<f64> = e.iter().enumerate().map(|(k, v)| v + if k > 0 { 0.3 * u[k - 1] } else { 0.0 }).collect();
//! assert!(!analyze(&bad, Some(&u), 25).unwrap().independence.unwrap().pass);
//! // an output error (no noise model) is only tested for independence
//! let oe = analyze_output_error(&e, &u, 25).unwrap();
//! assert!(oe.whiteness.is_none() && oe.independence.is_some());
//! ```

use crate::c64;
use crate::error::{check_finite, Error, Result};

/// One correlation test.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CorrelationTest {
    /// What is tested, in words (e.g. "residuals independent of the input").
    pub hypothesis: String,
    /// The statistic and its reference distribution, in words.
    pub method: String,
    /// Lags $\tau$.
    pub lags: Vec<i64>,
    /// Normalised correlation at each lag.
    pub values: Vec<f64>,
    /// The 95 % bound ($\pm$) on the normalised correlation at one lag (for display).
    pub bound: f64,
    /// Lags outside the bound (diagnosis only: about 5 % of the lags lie outside for a true
    /// model; the verdict is `pass`).
    pub exceeding: Vec<i64>,
    /// Portmanteau statistic $Q$.
    pub statistic: f64,
    /// Degrees of freedom of its $\chi^2$ distribution.
    pub dof: usize,
    /// 95 % quantile of that distribution.
    pub threshold: f64,
    /// `statistic < threshold`.
    pub pass: bool,
    /// Half-width $K$ of the lag window of the covariance $\hat\Sigma$ (independence; 0 for
    /// whiteness).
    pub covariance_lags: usize,
}

/// The result of [`analyze`] or [`analyze_output_error`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ResidualTest {
    /// Whiteness (Ljung–Box, lags 1..M); `None` when it does not apply (an output error of a
    /// model without a noise model, [`analyze_output_error`]).
    pub whiteness: Option<CorrelationTest>,
    /// Independence from the input (generalised portmanteau, lags −M..M), when an input is given.
    pub independence: Option<CorrelationTest>,
    /// Samples used.
    pub n_samples: usize,
}

/// Residual tests of the prediction errors `eps` of a model **with a noise model** (ARX, ARMAX,
/// BJ, innovations state space): whiteness, and independence from `input` (same length; in
/// closed loop the excitation or reference, not the plant input) over lags up to `max_lag`
/// (module docs). Means are removed first.
///
/// # Errors
/// [`Error::InvalidArgument`]: `max_lag` = 0; fewer than `max(4 max_lag, 20)` samples;
/// residuals or input identically constant. [`Error::DimensionMismatch`]: lengths differ.
/// [`Error::NonFinite`]: a NaN or infinite sample.
pub fn analyze(eps: &[f64], input: Option<&[f64]>, max_lag: usize) -> Result<ResidualTest> {
    analyze_with(eps, input, max_lag, true)
}

/// Residual test of the output error `eps` $= y - \hat y$ of a model **without a noise model**
/// (output error; a plant model simulated in closed loop with the controller): only its
/// independence from `input` (in closed loop the excitation $r$ or the reference $w$) — its
/// whiteness is not tested, since the true model leaves the coloured noise ($S v$ in closed
/// loop). Same errors as [`analyze`].
pub fn analyze_output_error(eps: &[f64], input: &[f64], max_lag: usize) -> Result<ResidualTest> {
    analyze_with(eps, Some(input), max_lag, false)
}

fn analyze_with(
    eps: &[f64],
    input: Option<&[f64]>,
    max_lag: usize,
    whiteness: bool,
) -> Result<ResidualTest> {
    if max_lag == 0 {
        return Err(Error::invalid("max_lag", "at least one lag is needed"));
    }
    let n = eps.len();
    let need = (4 * max_lag).max(20);
    if n < need {
        return Err(Error::invalid(
            "eps",
            format!("{n} residuals are too few for lags up to {max_lag} (at least {need}); use a longer record or fewer lags"),
        ));
    }
    check_finite("residuals", eps)?;
    let e = centred("residuals", eps)?;
    let nf = n as f64;
    let kw = covariance_lags(n, max_lag);
    let re = autocov(&e, if input.is_some() { kw } else { max_lag });
    let whiteness = whiteness.then(|| {
        let values: Vec<f64> = (1..=max_lag).map(|k| re[k] / re[0]).collect();
        let statistic = nf
            * (nf + 2.0)
            * values
                .iter()
                .enumerate()
                .map(|(i, v)| v * v / (nf - (i + 1) as f64))
                .sum::<f64>();
        test(
            "residuals white (uncorrelated with their own past)".into(),
            format!("Ljung–Box Q = N(N+2) Σ r(k)²/(N−k), k = 1..{max_lag}, against χ²({max_lag})"),
            (1..=max_lag as i64).collect(),
            values,
            Z95 / nf.sqrt(),
            statistic,
            max_lag,
            0,
        )
    });
    let independence = match input {
        None => None,
        Some(u) => {
            if u.len() != n {
                return Err(Error::DimensionMismatch {
                    context: "residual test: residuals and input",
                    expected: format!("{n} samples"),
                    got: format!("{} samples", u.len()),
                });
            }
            check_finite("input", u)?;
            let u = centred("input", u)?;
            let m2 = 2 * max_lag;
            let ru = autocov(&u, kw + m2);
            // σ̂(d) = Σ_{|k| ≤ K} w(k/K) R̂ε(k) R̂u(k + d), d = 0..2M (both autocovariances even)
            let sigma: Vec<f64> = (0..=m2)
                .map(|d| {
                    (-(kw as i64)..=kw as i64)
                        .map(|k| {
                            parzen(k as f64 / kw as f64)
                                * re[k.unsigned_abs() as usize]
                                * ru[(k + d as i64).unsigned_abs() as usize]
                        })
                        .sum::<f64>()
                })
                .collect();
            let lags: Vec<i64> = (-(max_lag as i64)..=max_lag as i64).collect();
            let x: Vec<f64> = lags.iter().map(|&tau| crosscov(&e, &u, tau)).collect();
            let scale = (re[0] * ru[0]).sqrt();
            let p = x.len();
            let cov: Vec<f64> = (0..p * p)
                .map(|ij| sigma[(ij / p).abs_diff(ij % p)])
                .collect();
            // the directions in which the input has power: eigenvectors of its own lag covariance
            // (end effects of the biased estimates blur a singular one by O(1/N))
            let tu: Vec<f64> = (0..p * p).map(|ij| ru[(ij / p).abs_diff(ij % p)]).collect();
            let (w, r) = dominant_subspace(&tu, p, 4.0 / nf);
            let (statistic, rank) = restricted_form(&cov, &x, &w, p, r);
            let statistic = nf * statistic;
            let ratio = if sigma[0] > 0.0 {
                sigma[0] / (scale * scale)
            } else {
                1.0
            };
            Some(test(
                "residuals independent of the input".into(),
                format!(
                    "generalised portmanteau Q = N xᵀ Σ̂⁺ x over the cross-covariances x at lags −{max_lag}..{max_lag}, \
                     Σ̂ from the residual and input autocovariances (Parzen window, K = {kw} lags), against χ²({rank})"
                ),
                lags,
                x.iter().map(|v| v / scale).collect(),
                Z95 * ratio.sqrt() / nf.sqrt(),
                statistic,
                rank.max(1),
                kw,
            ))
        }
    };
    Ok(ResidualTest {
        whiteness,
        independence,
        n_samples: n,
    })
}

/// Half-width $K$ of the lag window of the independence test's covariance for `n` samples and
/// lags up to `max_lag`: $\min(\max(\lceil 4\sqrt N\rceil, 2M), \lfloor N/4 \rfloor)$ (module docs).
pub fn covariance_lags(n: usize, max_lag: usize) -> usize {
    let k = (4.0 * (n as f64).sqrt()).ceil() as usize;
    k.max(2 * max_lag).min(n / 4).max(1)
}

/// Parzen lag window on $|x| \le 1$.
fn parzen(x: f64) -> f64 {
    let a = x.abs();
    if a <= 0.5 {
        1.0 - 6.0 * a * a + 6.0 * a * a * a
    } else if a <= 1.0 {
        2.0 * (1.0 - a).powi(3)
    } else {
        0.0
    }
}

/// Eigendecomposition of the symmetric `p`×`p` matrix `a` (row-major) by cyclic Jacobi
/// rotations: the eigenvalues and the eigenvectors (`v[k * p + i]` is component `k` of vector `i`).
fn jacobi_eigen(a: &[f64], p: usize) -> (Vec<f64>, Vec<f64>) {
    let mut m = a.to_vec();
    let mut v = vec![0.0; p * p];
    for i in 0..p {
        v[i * p + i] = 1.0;
    }
    for _sweep in 0..60 {
        let mut off = 0.0;
        let mut diag = 0.0;
        for i in 0..p {
            for j in 0..p {
                let x = m[i * p + j] * m[i * p + j];
                if i == j {
                    diag += x;
                } else {
                    off += x;
                }
            }
        }
        if off <= 1e-30 * diag || off == 0.0 {
            break;
        }
        for i in 0..p {
            for j in i + 1..p {
                let aij = m[i * p + j];
                if aij == 0.0 {
                    continue;
                }
                let theta = (m[j * p + j] - m[i * p + i]) / (2.0 * aij);
                let t = if theta == 0.0 {
                    1.0
                } else {
                    theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
                };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..p {
                    let (mki, mkj) = (m[k * p + i], m[k * p + j]);
                    m[k * p + i] = c * mki - s * mkj;
                    m[k * p + j] = s * mki + c * mkj;
                }
                for k in 0..p {
                    let (mik, mjk) = (m[i * p + k], m[j * p + k]);
                    m[i * p + k] = c * mik - s * mjk;
                    m[j * p + k] = s * mik + c * mjk;
                }
                for k in 0..p {
                    let (vki, vkj) = (v[k * p + i], v[k * p + j]);
                    v[k * p + i] = c * vki - s * vkj;
                    v[k * p + j] = s * vki + c * vkj;
                }
            }
        }
    }
    ((0..p).map(|i| m[i * p + i]).collect(), v)
}

/// The eigenvectors of the symmetric `p`×`p` matrix `a` whose eigenvalues exceed `rtol` times
/// the largest, as the columns of a `p`×`r` row-major matrix, and `r`.
fn dominant_subspace(a: &[f64], p: usize, rtol: f64) -> (Vec<f64>, usize) {
    let (l, v) = jacobi_eigen(a, p);
    let lmax = l.iter().copied().fold(0.0, f64::max);
    let keep: Vec<usize> = (0..p)
        .filter(|&i| l[i] > rtol * lmax && l[i] > 0.0)
        .collect();
    let r = keep.len();
    let mut w = vec![0.0; p * r];
    for (c, &i) in keep.iter().enumerate() {
        for k in 0..p {
            w[k * r + c] = v[k * p + i];
        }
    }
    (w, r)
}

/// $x^\top A^{+} x$ for a symmetric positive semidefinite `a` (`p`×`p`, row-major); eigenvalues
/// below `rtol` times the largest are dropped. Returns the form and the rank kept.
fn quadratic_pinv(a: &[f64], x: &[f64], p: usize, rtol: f64) -> (f64, usize) {
    let (l, v) = jacobi_eigen(a, p);
    let lmax = l.iter().copied().fold(0.0, f64::max);
    let mut q = 0.0;
    let mut rank = 0;
    for (i, &li) in l.iter().enumerate() {
        if li > rtol * lmax && li > 0.0 {
            let proj: f64 = (0..p).map(|k| v[k * p + i] * x[k]).sum();
            q += proj * proj / li;
            rank += 1;
        }
    }
    (q, rank)
}

/// The quadratic form of `x` with the covariance
/// `cov` restricted to the columns of `w` (`p`×`r`): $y = W^\top x$, $B = W^\top \Sigma W$,
/// $y^\top B^{+} y$ (eigenvalues of $B$ below $10^{-12}$ of the largest dropped). Returns the form
/// and the rank.
fn restricted_form(cov: &[f64], x: &[f64], w: &[f64], p: usize, r: usize) -> (f64, usize) {
    let y: Vec<f64> = (0..r)
        .map(|c| (0..p).map(|k| w[k * r + c] * x[k]).sum())
        .collect();
    // S W (p×r), then B = Wᵀ S W (r×r)
    let sw: Vec<f64> = (0..p * r)
        .map(|ic| {
            let (i, c) = (ic / r, ic % r);
            (0..p).map(|j| cov[i * p + j] * w[j * r + c]).sum()
        })
        .collect();
    let b: Vec<f64> = (0..r * r)
        .map(|cd| {
            let (c, d) = (cd / r, cd % r);
            (0..p).map(|i| w[i * r + c] * sw[i * r + d]).sum()
        })
        .collect();
    quadratic_pinv(&b, &y, r, 1e-12)
}

/// Two-sided 95 % quantile of the standard normal distribution.
const Z95: f64 = 1.959_963_984_540_054;

#[allow(clippy::too_many_arguments)]
fn test(
    hypothesis: String,
    method: String,
    lags: Vec<i64>,
    values: Vec<f64>,
    bound: f64,
    statistic: f64,
    dof: usize,
    covariance_lags: usize,
) -> CorrelationTest {
    let exceeding = lags
        .iter()
        .zip(&values)
        .filter(|(_, v)| v.abs() > bound)
        .map(|(l, _)| *l)
        .collect();
    let threshold = chi2_95(dof);
    CorrelationTest {
        hypothesis,
        method,
        lags,
        values,
        bound,
        exceeding,
        statistic,
        dof,
        threshold,
        pass: statistic < threshold,
        covariance_lags,
    }
}

/// 95 % quantile of $\chi^2(k)$ by the Wilson–Hilferty approximation
/// $k\,(1 - \tfrac{2}{9k} + z_{0.95}\sqrt{2/(9k)})^3$, $z_{0.95} = 1.6449$.
pub fn chi2_95(k: usize) -> f64 {
    let k = k as f64;
    let z = 1.644_853_626_951_472_2;
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).powi(3)
}

fn centred(what: &'static str, x: &[f64]) -> Result<Vec<f64>> {
    let m = x.iter().sum::<f64>() / x.len() as f64;
    let c: Vec<f64> = x.iter().map(|v| v - m).collect();
    if c.iter().all(|v| *v == 0.0) {
        return Err(Error::invalid(
            what,
            "the signal is constant: its correlations are undefined (no excitation or a perfect fit)",
        ));
    }
    Ok(c)
}

/// $\hat R_x(k)$ for $k = 0..=m$ (divided by $N$; 0 beyond the record). Direct sums for few
/// lags, an FFT of the zero-padded record (length $\ge N + m$, no wrap-around) for many.
fn autocov(x: &[f64], m: usize) -> Vec<f64> {
    let n = x.len();
    let nf = n as f64;
    if m <= 64 {
        return (0..=m)
            .map(|k| {
                if k >= n {
                    0.0
                } else {
                    x[k..].iter().zip(x).map(|(a, b)| a * b).sum::<f64>() / nf
                }
            })
            .collect();
    }
    let len = (n + m + 1).next_power_of_two();
    let mut planner = rustfft::FftPlanner::new();
    let (fwd, inv) = (planner.plan_fft_forward(len), planner.plan_fft_inverse(len));
    let mut buf: Vec<c64> = x
        .iter()
        .map(|v| c64::new(*v, 0.0))
        .chain(std::iter::repeat(c64::new(0.0, 0.0)))
        .take(len)
        .collect();
    fwd.process(&mut buf);
    for v in buf.iter_mut() {
        *v = c64::new(v.norm_sqr(), 0.0);
    }
    inv.process(&mut buf);
    (0..=m)
        .map(|k| {
            if k >= n {
                0.0
            } else {
                buf[k].re / (len as f64 * nf)
            }
        })
        .collect()
}

/// $\hat R_{\varepsilon u}(\tau) = \frac1N \sum_t \varepsilon(t) u(t - \tau)$.
fn crosscov(e: &[f64], u: &[f64], tau: i64) -> f64 {
    let n = e.len();
    let s: f64 = if tau >= 0 {
        let t = tau as usize;
        e[t..].iter().zip(&u[..n - t]).map(|(a, b)| a * b).sum()
    } else {
        let t = (-tau) as usize;
        e[..n - t].iter().zip(&u[t..]).map(|(a, b)| a * b).sum()
    };
    s / n as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Wilson–Hilferty against `scipy.stats.chi2.ppf(0.95, k)` (printed by scipy 1.x).
    #[test]
    fn chi2_quantiles() {
        for (k, want) in [
            (10, 18.307038),
            (25, 37.652484),
            (51, 68.669293),
            (101, 125.458419),
        ] {
            let got = chi2_95(k);
            assert!((got / want - 1.0).abs() < 5e-3, "{k}: {got} vs {want}");
        }
    }

    /// The pseudo-inverse quadratic form against a hand-computed inverse, and the rank of a
    /// singular matrix.
    #[test]
    fn quadratic_form_and_rank() {
        // [[2, 1], [1, 2]]⁻¹ = [[2, −1], [−1, 2]]/3: x = (1, 2) → (2 − 4 + 8)/3 = 2
        let (q, r) = quadratic_pinv(&[2.0, 1.0, 1.0, 2.0], &[1.0, 2.0], 2, 1e-10);
        assert!((q - 2.0).abs() < 1e-12 && r == 2, "{q} {r}");
        // rank 1: [[1, 1], [1, 1]] = 2 vvᵀ, v = (1, 1)/√2; x = (1, 1): (√2)²/2 = 1
        let (q, r) = quadratic_pinv(&[1.0, 1.0, 1.0, 1.0], &[1.0, 1.0], 2, 1e-10);
        assert!((q - 1.0).abs() < 1e-12 && r == 1, "{q} {r}");
        // a 3×3 Toeplitz matrix against Gaussian elimination done by hand (Cramer)
        let a = [4.0, 1.0, 0.5, 1.0, 4.0, 1.0, 0.5, 1.0, 4.0];
        let x = [1.0, -1.0, 2.0];
        let (q, r) = quadratic_pinv(&a, &x, 3, 1e-10);
        let det = |m: &[f64; 9]| {
            m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6])
                + m[2] * (m[3] * m[7] - m[4] * m[6])
        };
        let d = det(&a);
        let mut y = [0.0; 3];
        for (c, yc) in y.iter_mut().enumerate() {
            let mut m = a;
            for rr in 0..3 {
                m[rr * 3 + c] = x[rr];
            }
            *yc = det(&m) / d;
        }
        let want: f64 = x.iter().zip(&y).map(|(a, b)| a * b).sum();
        assert!((q - want).abs() < 1e-12 * want && r == 3, "{q} {want}");
    }

    #[test]
    fn parzen_window_and_lag_rule() {
        assert_eq!(parzen(0.0), 1.0);
        assert!((parzen(0.5) - 0.25).abs() < 1e-15 && (parzen(-0.5) - 0.25).abs() < 1e-15);
        assert_eq!(parzen(1.0), 0.0);
        assert_eq!(covariance_lags(102_300, 25), 1280);
        assert_eq!(covariance_lags(2000, 25), 179);
        assert_eq!(covariance_lags(100, 25), 25);
    }

    /// The FFT autocovariance equals the direct sums.
    #[test]
    fn fft_autocovariance_matches_the_sums() {
        let x: Vec<f64> = (0..1000)
            .map(|k| ((k * k) % 17) as f64 - 8.0 + (0.1 * k as f64).sin())
            .collect();
        let fast = autocov(&x, 300);
        for (k, f) in fast.iter().enumerate() {
            let direct = x[k..].iter().zip(&x).map(|(a, b)| a * b).sum::<f64>() / 1000.0;
            assert!(
                (f - direct).abs() < 1e-10 * (1.0 + direct.abs()),
                "{k}: {f} {direct}"
            );
        }
        assert_eq!(autocov(&x[..10], 70)[50], 0.0);
    }
}
