//! Residual analysis: whiteness of the residuals and their independence from the input, with
//! the 95 % bounds of Ljung (*System Identification*, 2nd ed., section 16.6) and a numeric verdict.
//!
//! # Statistics
//! With $N$ residuals $\varepsilon$ and the input (in closed loop: the reference) $u$, both with
//! their means removed, and the sample covariances
//! $\hat R_\varepsilon(\tau) = \frac1N \sum_t \varepsilon(t)\varepsilon(t-\tau)$,
//! $\hat R_{\varepsilon u}(\tau) = \frac1N \sum_t \varepsilon(t) u(t-\tau)$:
//! * **Whiteness**: $r(\tau) = \hat R_\varepsilon(\tau) / \hat R_\varepsilon(0)$, $\tau = 1..M$. For
//!   white residuals $\sqrt N r(\tau)$ is asymptotically $\mathcal N(0, 1)$: bounds
//!   $\pm 1.96/\sqrt N$, and the portmanteau statistic $\zeta = N \sum_{\tau=1}^M r(\tau)^2$ is
//!   $\chi^2(M)$.
//! * **Independence from the input**: $x(\tau) = \hat R_{\varepsilon u}(\tau) /
//!   \sqrt{\hat R_\varepsilon(0) \hat R_u(0)}$, $\tau = -M..M$. If $\varepsilon$ and $u$ are
//!   independent, $\sqrt N \hat R_{\varepsilon u}(\tau)$ is asymptotically $\mathcal N(0, P)$ with
//!   $P = \sum_{k=-\infty}^{\infty} R_\varepsilon(k) R_u(k)$. For white residuals this is
//!   $R_\varepsilon(0) R_u(0)$ (the usual $\pm 1.96/\sqrt N$); when both are coloured (an
//!   output-error model leaves coloured residuals; the input of an AMB experiment is rarely
//!   white) the **coloured-input correction** $\hat P = \sum_{|k| \le M} \hat R_\varepsilon(k)
//!   \hat R_u(k)$ gives the bound $\pm 1.96 \sqrt{\hat P / (\hat R_\varepsilon(0) \hat R_u(0))} /
//!   \sqrt N$, and $N \sum_\tau x(\tau)^2 \hat R_\varepsilon(0)\hat R_u(0)/\hat P$ is approximately
//!   $\chi^2(2M + 1)$.
//! * **Verdicts**: a test passes when its portmanteau statistic is below the 95 % quantile of its
//!   $\chi^2$ distribution (Wilson–Hilferty approximation, relative error below 0.5 % for the
//!   degrees of freedom used here). Under the null hypothesis about 5 % of the lags fall outside
//!   the bounds; the count and the lags are reported.
//!
//! # Example
//! ```
//! use ambid_core::validate::residuals::analyze;
//! use rand::{RngExt, SeedableRng};
//! use rand_chacha::ChaCha8Rng;
//! use rand_distr::StandardNormal;
//! let mut rng = ChaCha8Rng::seed_from_u64(1);
//! let e: Vec<f64> = (0..4000).map(|_| rng.sample(StandardNormal)).collect();
//! let u: Vec<f64> = (0..4000).map(|_| rng.sample(StandardNormal)).collect();
//! let t = analyze(&e, Some(&u), 25).unwrap();
//! assert!(t.whiteness.pass && t.independence.unwrap().pass);
//! // residuals that still contain the input fail
//! let bad: Vec<f64> = e.iter().enumerate().map(|(k, v)| v + if k > 0 { 0.3 * u[k - 1] } else { 0.0 }).collect();
//! assert!(!analyze(&bad, Some(&u), 25).unwrap().independence.unwrap().pass);
//! ```

use crate::error::{check_finite, Error, Result};

/// One correlation test.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CorrelationTest {
    /// Lags $\tau$.
    pub lags: Vec<i64>,
    /// Normalised correlation at each lag.
    pub values: Vec<f64>,
    /// The 95 % bound ($\pm$) on the normalised correlation.
    pub bound: f64,
    /// Lags outside the bound.
    pub exceeding: Vec<i64>,
    /// Portmanteau statistic.
    pub statistic: f64,
    /// Degrees of freedom of its $\chi^2$ distribution.
    pub dof: usize,
    /// 95 % quantile of that distribution.
    pub threshold: f64,
    /// `statistic < threshold`.
    pub pass: bool,
}

/// The result of [`analyze`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ResidualTest {
    /// Autocorrelation of the residuals, lags 1..M.
    pub whiteness: CorrelationTest,
    /// Cross-correlation of the residuals with the input, lags −M..M (when an input is given).
    pub independence: Option<CorrelationTest>,
    /// Samples used.
    pub n_samples: usize,
}

/// Residual tests of `eps` (and against `input`, same length) over lags up to `max_lag`
/// (module docs). Means are removed first.
///
/// # Errors
/// [`Error::InvalidArgument`]: `max_lag` = 0; fewer than `max(4 max_lag, 20)` samples;
/// residuals or input identically constant. [`Error::DimensionMismatch`]: lengths differ.
/// [`Error::NonFinite`]: a NaN or infinite sample.
pub fn analyze(eps: &[f64], input: Option<&[f64]>, max_lag: usize) -> Result<ResidualTest> {
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
    let re = autocov(&e, max_lag);
    let sqrt_n = (n as f64).sqrt();
    let values: Vec<f64> = (1..=max_lag).map(|k| re[k] / re[0]).collect();
    let bound = Z95 / sqrt_n;
    let statistic = n as f64 * values.iter().map(|v| v * v).sum::<f64>();
    let whiteness = test(
        (1..=max_lag as i64).collect(),
        values,
        bound,
        statistic,
        max_lag,
    );
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
            let ru = autocov(&u, max_lag);
            // P̂ = Σ_{|k| ≤ M} R̂_ε(k) R̂_u(k) (both even), normalised by R̂_ε(0) R̂_u(0)
            let p: f64 = re[0] * ru[0] + 2.0 * (1..=max_lag).map(|k| re[k] * ru[k]).sum::<f64>();
            let scale = re[0] * ru[0];
            // a non-positive estimate (possible for short records) falls back to the white case
            let ratio = if p > 0.0 { p / scale } else { 1.0 };
            let lags: Vec<i64> = (-(max_lag as i64)..=max_lag as i64).collect();
            let values: Vec<f64> = lags
                .iter()
                .map(|&tau| crosscov(&e, &u, tau) / scale.sqrt())
                .collect();
            let statistic = n as f64 * values.iter().map(|v| v * v).sum::<f64>() / ratio;
            Some(test(
                lags,
                values,
                Z95 * ratio.sqrt() / sqrt_n,
                statistic,
                2 * max_lag + 1,
            ))
        }
    };
    Ok(ResidualTest {
        whiteness,
        independence,
        n_samples: n,
    })
}

/// Two-sided 95 % quantile of the standard normal distribution.
const Z95: f64 = 1.959_963_984_540_054;

fn test(
    lags: Vec<i64>,
    values: Vec<f64>,
    bound: f64,
    statistic: f64,
    dof: usize,
) -> CorrelationTest {
    let exceeding = lags
        .iter()
        .zip(&values)
        .filter(|(_, v)| v.abs() > bound)
        .map(|(l, _)| *l)
        .collect();
    let threshold = chi2_95(dof);
    CorrelationTest {
        lags,
        values,
        bound,
        exceeding,
        statistic,
        dof,
        threshold,
        pass: statistic < threshold,
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

/// $\hat R_x(k)$ for $k = 0..=m$ (divided by $N$).
fn autocov(x: &[f64], m: usize) -> Vec<f64> {
    let n = x.len() as f64;
    (0..=m)
        .map(|k| x[k..].iter().zip(x).map(|(a, b)| a * b).sum::<f64>() / n)
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
}
