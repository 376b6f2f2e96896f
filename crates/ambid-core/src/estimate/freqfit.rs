//! Parametric models fitted to frequency-response data (an [`Frd`]): the shared data
//! preparation (band, weights), transfer-function fits (ARX in Levy's linearised form; OE by
//! Sanathanan–Koerner iterations and Levenberg–Marquardt) and, in [`freqfit_ss`](super::freqfit_ss),
//! state-space fits.
//!
//! # Criterion
//! Every fit minimises (or, for ARX and the SK start, linearises) the weighted complex error over
//! the $L$ lines $\omega_k$ of the band,
//! $$ V = \sum_{k=1}^{L} w_k \,\bigl| \hat G(e^{j\omega_k T}) - G(e^{j\omega_k T}) \bigr|^2 , $$
//! with $w_k = 1$ ([`FreqWeights::Uniform`]), $w_k = 1/\sigma_k^2$ from the FRF estimate's variance
//! ([`FreqWeights::InverseVariance`]: the maximum-likelihood criterion for Gaussian FRF errors),
//! $w_k = \gamma_k^2 / ((1 - \gamma_k^2)\,|\hat G_k|^2)$ from a coherence (proportional to the
//! inverse of the H1 estimate's variance, $\sigma^2 \approx (1-\gamma^2)|G|^2 / (2 n_d \gamma^2)$,
//! [`FreqWeights::Coherence`]) or given ([`FreqWeights::Given`]). The weights are normalised to
//! mean 1, so the cost does not depend on their overall scale.
//!
//! # Weights that follow the data's noise
//! A ratio estimate $\hat G_k = \bar Y_k/\bar U_k$ from $M$ periods has the variance
//! $v_k(G) = a_k|G|^2 + b_k - 2\operatorname{Re}(G c_k)$ ([`RatioNoise`]); what
//! [`FreqWeights::InverseVariance`] uses is $v_k(\hat G_k)$, evaluated at the *data*. In a
//! closed loop with sensor noise $v_k(G) \propto |1 + G C_k|^2$, so a line whose estimate erred
//! towards $-1/C_k$ gets a larger weight than one that erred away from it: the weight is
//! correlated with the line's own error. Each line's contribution to the fit's bias is of second
//! order, but it has the same sign on every line, so over hundreds of lines it adds up
//! coherently while the noise averages down: on random rigs of the AMB twin (a 19-period PRBS,
//! relative standard deviations of 0.06–0.2 per line at 500–1000 Hz) the order-8 fit was pulled
//! off the plant by about its own standard deviation there (rig 142, 40 noise realisations), the
//! uncertainty bound's first-order error model could not know it, and the bound missed
//! (docs/uncertainty.md, "Weights that follow the data's noise").
//! [`FreqWeights::SampleMaximumLikelihood`] evaluates the variance at the model instead,
//! $$ V(\theta) = \sum_k \frac{|\hat G_k - G_\theta(z_k)|^2}{v_k(G_\theta(z_k))}
//!   = \sum_k \frac{|\bar Y_k - G_\theta \bar U_k|^2}{\operatorname{Var}(\bar Y_k - G_\theta
//!   \bar U_k)} , $$
//! the sample maximum-likelihood (SML) cost of the errors-in-variables problem (Pintelon and
//! Schoukens, *System Identification: A Frequency Domain Approach*): the
//! sample covariances of Gaussian periods are independent of their means, so the weights no
//! longer follow the error. The refinement differentiates the denominator too
//! ([`ss_frd`](super::freqfit_ss::ss_frd)); reweighting with the variance at the previous
//! model and the denominator held fixed halved the bias on rig 142 and no more.

use crate::error::{Error, Result};
use crate::frf::closed_loop::RatioNoise;
use crate::lti::Frd;
use faer::c64;

/// Weights of the frequency lines (module docs).
#[derive(Debug, Clone, PartialEq, Default)]
pub enum FreqWeights {
    /// All lines alike.
    #[default]
    Uniform,
    /// $1/\sigma_k^2$ from the [`Frd`]'s variance (an error if it has none).
    InverseVariance,
    /// From the coherence $\gamma_k^2$ of each line (same length as the [`Frd`]).
    Coherence(Vec<f64>),
    /// Given non-negative weights (same length as the [`Frd`]).
    Given(Vec<f64>),
    /// Sample maximum likelihood: $w_k = 1/v_k(\hat P_\theta(z_k))$, the FRF's variance
    /// evaluated at the *model* ([`RatioNoise`] per line, same length as the [`Frd`]; e.g.
    /// [`ClosedLoopFrf::plant_noise`](crate::frf::closed_loop::ClosedLoopFrf::plant_noise)),
    /// not at the data (module docs, "Weights that follow the data's noise"). The state-space
    /// fit [`ss_frd`](super::freqfit_ss::ss_frd) and the output-error fit [`oe_frd`] refine
    /// with it (their Sanathanan–Koerner and subspace starts take the weights at the data);
    /// [`arx_frd`] (linear in its parameters) and [`coprime_frd`] refuse it.
    SampleMaximumLikelihood(Vec<RatioNoise>),
}

/// Options shared by the frequency-domain fits.
#[derive(Debug, Clone, PartialEq)]
pub struct FreqFitOptions {
    /// Band $[f_{\min}, f_{\max}]$ in Hz (inclusive); `None` uses every line.
    pub band_hz: Option<(f64, f64)>,
    /// Weights of the lines; default uniform.
    pub weights: FreqWeights,
    /// Iteration limit of the nonlinear refinement (Levenberg–Marquardt); default 100.
    pub max_iterations: usize,
    /// Sanathanan–Koerner iterations before the refinement; default 20.
    pub sk_iterations: usize,
    /// Reflect unstable poles into the unit circle after the fit (only when asked; default
    /// `false`: unstable plants stay unstable).
    pub enforce_stability: bool,
    /// At most this many poles on or outside the unit circle (default `None`: unconstrained).
    ///
    /// The constraint is part of the fit, not a repair: the start keeps the unstable poles that
    /// explain the data best (the others of the *start* are mirrored, $z \mapsto 1/\bar z$, and
    /// the linear parameters refitted) and the nonlinear refinement rejects every step that would
    /// leave the admissible set, so the result is the best model with at most this many
    /// unstable poles. Set it to the number of unstable poles the data support, e.g.
    /// [`crate::validate::compare::unstable_poles_from_loop`] (the Nyquist count of the
    /// measured loop).
    pub max_unstable_poles: Option<usize>,
}

impl Default for FreqFitOptions {
    fn default() -> Self {
        Self {
            band_hz: None,
            weights: FreqWeights::Uniform,
            max_iterations: 100,
            sk_iterations: 20,
            enforce_stability: false,
            max_unstable_poles: None,
        }
    }
}

/// The lines of an [`Frd`] that a fit uses: inside the band, with positive weight.
#[derive(Debug, Clone, PartialEq)]
pub struct FreqData {
    /// Frequencies \[Hz\].
    pub f_hz: Vec<f64>,
    /// Measured response $G_k$.
    pub g: Vec<c64>,
    /// Weights $w_k > 0$, mean 1.
    pub w: Vec<f64>,
    /// $z_k = e^{j 2\pi f_k T}$.
    pub z: Vec<c64>,
    /// Sample time $T$ \[s\].
    pub ts: f64,
    /// With [`FreqWeights::SampleMaximumLikelihood`], each line's [`RatioNoise`] scaled by the
    /// weights' normalisation (so that $w_k = 1/v_k(G_k)$ at the data); empty otherwise.
    pub noise: Vec<RatioNoise>,
}

impl FreqData {
    /// Selects the band and computes the weights.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the [`Frd`] has no sample time (continuous), the band is
    /// empty or reversed, the weight vector has the wrong length, contains negative or non-finite
    /// values or is zero on every line of the band, or inverse-variance weights are asked for
    /// data without variance (or with a zero variance in the band).
    pub fn new(frd: &Frd, opts: &FreqFitOptions) -> Result<Self> {
        frd.require_siso("FreqData::new")?;
        let ts = frd.ts().ok_or_else(|| {
            Error::invalid(
                "frd",
                "the FRF has no sample time; frequency-domain fits are discrete-time at the data's sample time",
            )
        })?;
        let (lo, hi) = match opts.band_hz {
            Some((lo, hi)) if !(lo.is_finite() && hi.is_finite() && lo <= hi) => {
                return Err(Error::invalid(
                    "band_hz",
                    format!("the band must be finite with f_min <= f_max, got {lo}:{hi}"),
                ))
            }
            Some(b) => b,
            None => (f64::NEG_INFINITY, f64::INFINITY),
        };
        let n = frd.len();
        let per_line = |name: &'static str, v: &[f64]| -> Result<()> {
            if v.len() != n {
                return Err(Error::invalid(
                    name,
                    format!("{} weights for {n} lines", v.len()),
                ));
            }
            if let Some(i) = v.iter().position(|x| !x.is_finite() || *x < 0.0) {
                return Err(Error::invalid(
                    name,
                    format!("weight {i} is {} (must be finite and >= 0)", v[i]),
                ));
            }
            Ok(())
        };
        let raw: Vec<f64> = match &opts.weights {
            FreqWeights::Uniform => vec![1.0; n],
            FreqWeights::InverseVariance => {
                let var = frd.variance().ok_or_else(|| {
                    Error::invalid(
                        "weights",
                        "inverse-variance weights need an FRF with variances (estimate it from several periods)",
                    )
                })?;
                var.iter()
                    .map(|v| if *v > 0.0 { 1.0 / v } else { f64::INFINITY })
                    .collect()
            }
            FreqWeights::Coherence(coh) => {
                per_line("coherence", coh)?;
                coh.iter()
                    .zip(frd.values())
                    .map(|(c, g)| {
                        let c = c.min(1.0);
                        if c >= 1.0 {
                            f64::INFINITY
                        } else {
                            c / ((1.0 - c) * g.norm_sqr().max(f64::MIN_POSITIVE))
                        }
                    })
                    .collect()
            }
            FreqWeights::Given(w) => {
                per_line("weights", w)?;
                w.clone()
            }
            FreqWeights::SampleMaximumLikelihood(noise) => {
                if noise.len() != n {
                    return Err(Error::invalid(
                        "weights",
                        format!("{} noise descriptions for {n} lines", noise.len()),
                    ));
                }
                noise
                    .iter()
                    .zip(frd.values())
                    .map(|(v, g)| {
                        let v = v.variance_at(*g);
                        if v > 0.0 {
                            1.0 / v
                        } else {
                            f64::INFINITY
                        }
                    })
                    .collect()
            }
        };
        let sml = match &opts.weights {
            FreqWeights::SampleMaximumLikelihood(noise) => Some(noise),
            _ => None,
        };
        let mut data = Self {
            f_hz: Vec::new(),
            g: Vec::new(),
            w: Vec::new(),
            z: Vec::new(),
            ts,
            noise: Vec::new(),
        };
        for (k, &f) in frd.f_hz().iter().enumerate() {
            if f < lo || f > hi || raw[k] == 0.0 {
                continue;
            }
            if !raw[k].is_finite() {
                return Err(Error::invalid(
                    "weights",
                    format!("line {k} ({f} Hz) has an infinite weight (zero variance or unit coherence); give finite weights"),
                ));
            }
            data.f_hz.push(f);
            data.g.push(frd.values()[k]);
            data.w.push(raw[k]);
            if let Some(noise) = sml {
                data.noise.push(noise[k]);
            }
            data.z
                .push(c64::from_polar(1.0, 2.0 * std::f64::consts::PI * f * ts));
        }
        if data.f_hz.is_empty() {
            return Err(Error::invalid(
                "band_hz",
                "no line of the FRF lies in the band with a positive weight; widen the band or check the weights",
            ));
        }
        let mean = data.w.iter().sum::<f64>() / data.w.len() as f64;
        for w in &mut data.w {
            *w /= mean;
        }
        // w = 1/(v·mean): the noise scaled alike keeps w_k = 1/v_k(G_k)
        for v in &mut data.noise {
            v.a *= mean;
            v.b *= mean;
            v.c *= mean;
        }
        Ok(data)
    }

    /// Line `k`'s variance at the model value `p` under sample maximum likelihood, held at
    /// least $10^{-6}$ of its value at the data (a model value where the noise would vanish,
    /// $1 + \hat P C = 0$ for sensor noise alone, cannot take an unbounded weight), and whether
    /// it was held; `None` with fixed weights.
    pub(crate) fn model_variance(&self, k: usize, p: c64) -> Option<(f64, bool)> {
        let noise = self.noise.get(k)?;
        let floor = 1e-6 / self.w[k];
        let v = noise.variance_at(p);
        Some(if v > floor { (v, false) } else { (floor, true) })
    }

    /// Line `k`'s weighted residual $\sqrt{w_k}(p - G_k)$ at the model value `p`, the weight at
    /// the model under sample maximum likelihood.
    pub(crate) fn residual(&self, k: usize, p: c64) -> c64 {
        let sw = self
            .model_variance(k, p)
            .map_or(self.w[k].sqrt(), |(v, _)| 1.0 / v.sqrt());
        (p - self.g[k]) * sw
    }

    /// The derivative of [`residual`](Self::residual) along a change `dp` of the model value
    /// `p`: $\sqrt{w_k}\,\delta p$ with fixed weights; under sample maximum likelihood, with $r
    /// = (p - G)/\sqrt{v(p)}$, $\delta r = \delta p/\sqrt v - (p - G)\,\delta v/(2 v^{3/2})$.
    pub(crate) fn residual_slope(&self, k: usize, p: c64, dp: c64) -> c64 {
        match self.model_variance(k, p) {
            None => dp * self.w[k].sqrt(),
            Some((v, held)) => {
                let sw = 1.0 / v.sqrt();
                let dv = if held {
                    0.0
                } else {
                    self.noise[k].variance_slope(p, dp)
                };
                dp * sw - (p - self.g[k]) * (0.5 * dv * sw / v)
            }
        }
    }

    /// An error for a fit that holds the weights fixed when they are to follow the model
    /// ([`FreqWeights::SampleMaximumLikelihood`]): only [`ss_frd`](super::freqfit_ss::ss_frd)
    /// and [`oe_frd`] refine with them.
    pub fn require_fixed_weights(&self, fit: &'static str) -> Result<()> {
        if self.noise.is_empty() {
            Ok(())
        } else {
            Err(Error::invalid(
                "weights",
                format!(
                    "{fit} holds its weights fixed; sample maximum-likelihood weights are for the \
                     state-space and output-error fits (ss_frd, oe_frd): use inverse-variance \
                     weights here"
                ),
            ))
        }
    }

    /// The weighted cost $V = \sum_k w_k |\hat G_k - G_k|^2$ of a model's response `model` on
    /// the lines (the fits' criterion).
    pub fn weighted_cost(&self, model: impl IntoIterator<Item = c64>) -> f64 {
        model
            .into_iter()
            .zip(&self.g)
            .zip(&self.w)
            .map(|((m, g), w)| w * (m - g).norm_sqr())
            .sum()
    }

    /// Number of lines.
    pub fn len(&self) -> usize {
        self.f_hz.len()
    }

    /// Whether there is no line (never true for a constructed value).
    pub fn is_empty(&self) -> bool {
        self.f_hz.is_empty()
    }

    /// Errors unless the $2L$ real equations determine `n_params` parameters.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the numbers.
    pub fn check_params(&self, n_params: usize) -> Result<()> {
        if 2 * self.len() < n_params {
            return Err(Error::invalid(
                "band_hz",
                format!(
                    "{} lines (2 real equations each) cannot determine {n_params} parameters; widen the band or lower the order",
                    self.len()
                ),
            ));
        }
        Ok(())
    }
}

/// Error measures of a model's response `model` against the data's lines (unweighted).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FreqErrors {
    /// $\sqrt{\frac1L \sum |\hat G_k - G_k|^2}$.
    pub rmse: f64,
    /// $\sqrt{\frac1L \sum |\hat G_k - G_k|^2 / |G_k|^2}$.
    pub relative_rmse: f64,
    /// RMS of $20 \log_{10} |\hat G_k / G_k|$ \[dB\].
    pub db_rmse: f64,
    /// Median of $|\hat G_k - G_k| / |G_k|$.
    pub median_relative: f64,
}

impl FreqErrors {
    /// Compares `model` (the model's response at the data's lines) with the data.
    pub fn of(model: &[c64], data: &FreqData) -> Self {
        let l = data.len().max(1) as f64;
        let mut rel: Vec<f64> = model
            .iter()
            .zip(&data.g)
            .map(|(m, g)| (m - g).norm() / g.norm().max(f64::MIN_POSITIVE))
            .collect();
        let rmse = (model
            .iter()
            .zip(&data.g)
            .map(|(m, g)| (m - g).norm_sqr())
            .sum::<f64>()
            / l)
            .sqrt();
        let relative_rmse = (rel.iter().map(|r| r * r).sum::<f64>() / l).sqrt();
        let db_rmse = (model
            .iter()
            .zip(&data.g)
            .map(|(m, g)| (20.0 * (m.norm() / g.norm().max(f64::MIN_POSITIVE)).log10()).powi(2))
            .sum::<f64>()
            / l)
            .sqrt();
        rel.sort_by(f64::total_cmp);
        let median_relative = rel.get(rel.len() / 2).copied().unwrap_or(0.0);
        Self {
            rmse,
            relative_rmse,
            db_rmse,
            median_relative,
        }
    }
}

/// A model fitted to frequency data.
#[derive(Debug, Clone)]
pub struct FreqFit<M> {
    /// The model (discrete, at the data's sample time).
    pub model: M,
    /// Number of free real parameters.
    pub n_params: usize,
    /// Weighted cost $V$ (module docs) at the result.
    pub cost: f64,
    /// Unweighted error measures on the fitted lines.
    pub errors: FreqErrors,
    /// Iterations of the nonlinear refinement (0 for linear fits).
    pub iterations: usize,
    /// Whether the refinement met a convergence test (always `true` for linear fits; `false`
    /// when it stopped at [`FreqFitOptions::max_iterations`]).
    pub converged: bool,
}

/// Number of `roots` on or outside the unit circle.
pub(crate) fn count_unstable(roots: &[c64]) -> usize {
    roots.iter().filter(|z| z.norm() >= 1.0).count()
}

/// The start of a fit constrained to at most `limit` unstable poles
/// ([`FreqFitOptions::max_unstable_poles`]): among the unstable `poles`, the real poles and
/// conjugate pairs kept unstable are the admissible choice of largest count with the smallest
/// `cost` (the weighted cost after refitting the linear parameters); the others are mirrored into
/// the unit circle, $z \mapsto 1/\bar z$ (poles on the circle are pulled just inside). This only
/// moves the *start*; the refinement that follows is constrained, not repaired. Returns `poles`
/// unchanged when they already meet the limit.
pub(crate) fn constrained_start(
    poles: &[c64],
    limit: usize,
    mut cost: impl FnMut(&[c64]) -> Option<f64>,
) -> Vec<c64> {
    if count_unstable(poles) <= limit {
        return poles.to_vec();
    }
    let mirror = |p: c64| {
        let r = p.norm();
        let mut out = if r > 1.0 { p / (r * r) } else { p };
        if out.norm() >= 1.0 - 1e-9 {
            out *= (1.0 - 1e-6) / out.norm();
        }
        out
    };
    // the unstable units: a real pole (weight 1) or the upper member of a pair (weight 2)
    let mut units: Vec<(usize, usize)> = poles
        .iter()
        .enumerate()
        .filter(|(_, p)| p.norm() >= 1.0 && p.im >= 0.0)
        .map(|(i, p)| (i, if p.im > 0.0 { 2 } else { 1 }))
        .collect();
    // enumerating subsets: keep the 10 closest to the unit circle as candidates
    units.sort_by(|a, b| poles[a.0].norm().total_cmp(&poles[b.0].norm()));
    units.truncate(10);
    let build = |mask: usize| -> Vec<c64> {
        let keep = |p: &c64| {
            units.iter().enumerate().any(|(u, &(i, _))| {
                let tol = 1e-12 * (1.0 + p.norm());
                mask & (1 << u) != 0
                    && ((poles[i] - *p).norm() <= tol || (poles[i].conj() - *p).norm() <= tol)
            })
        };
        poles
            .iter()
            .map(|p| {
                if p.norm() >= 1.0 && !keep(p) {
                    mirror(*p)
                } else {
                    *p
                }
            })
            .collect()
    };
    let mut best: Option<(usize, f64, usize)> = None;
    for mask in 0..(1usize << units.len()) {
        let count: usize = units
            .iter()
            .enumerate()
            .filter(|(u, _)| mask & (1 << u) != 0)
            .map(|(_, &(_, w))| w)
            .sum();
        if count > limit || best.is_some_and(|b| b.0 > count) {
            continue;
        }
        let Some(c) = cost(&build(mask)).filter(|c| c.is_finite()) else {
            continue;
        };
        if best.is_none_or(|b| count > b.0 || c < b.1) {
            best = Some((count, c, mask));
        }
    }
    build(best.map_or(0, |b| b.2))
}

/// Orders of a transfer-function fit $G = q^{-n_k} B(q^{-1}) / F(q^{-1})$ (MATLAB's `[nb nf nk]`):
/// `nb` coefficients of $B$ after `nk` delays, `nf` free coefficients of the monic $F$.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TfOrders {
    /// Coefficients of the numerator.
    pub nb: usize,
    /// Free coefficients of the monic denominator.
    pub nf: usize,
    /// Input delay in samples.
    pub nk: usize,
}

impl TfOrders {
    /// Number of real parameters $n_b + n_f$.
    pub fn n_params(&self) -> usize {
        self.nb + self.nf
    }
    fn check(&self) -> Result<()> {
        if self.nb == 0 {
            return Err(Error::invalid(
                "nb",
                "the numerator needs at least one coefficient (nb >= 1)",
            ));
        }
        Ok(())
    }
}

/// Powers $\zeta_k^p$, $\zeta_k = z_k^{-1}$, for $p = 0..=p_{\max}$ (row `p`).
fn zeta_powers(data: &FreqData, pmax: usize) -> Vec<Vec<c64>> {
    let mut out: Vec<Vec<c64>> = vec![vec![c64::new(1.0, 0.0); data.len()]];
    for p in 1..=pmax {
        let next: Vec<c64> = out[p - 1].iter().zip(&data.z).map(|(v, z)| v / z).collect();
        out.push(next);
    }
    out
}

/// Least squares of a complex linear model: `cols[j][k]` is the coefficient of parameter `j`
/// on line `k`, `rhs[k]` the right-hand side; line `k` weighted by `wt[k]` (multiplying both).
/// Real and imaginary parts are stacked.
fn complex_lstsq(cols: &[Vec<c64>], rhs: &[c64], wt: &[f64]) -> Result<Vec<f64>> {
    let l = rhs.len();
    let n = cols.len();
    let a = faer::Mat::from_fn(2 * l, n, |r, j| {
        let (k, im) = (r / 2, r % 2 == 1);
        let v = cols[j][k] * wt[k];
        if im {
            v.im
        } else {
            v.re
        }
    });
    let b = faer::Mat::from_fn(2 * l, 1, |r, _| {
        let (k, im) = (r / 2, r % 2 == 1);
        let v = rhs[k] * wt[k];
        if im {
            v.im
        } else {
            v.re
        }
    });
    // columns scaled to unit norm, then a truncated SVD: polynomial coefficients of strongly
    // oversampled data (poles near z = 1) are nearly collinear, and the minimum-norm solution
    // over the numerically determined directions still gives the best response on the lines
    let scale: Vec<f64> = (0..n)
        .map(|j| {
            let c = a.col(j).norm_l2();
            if c > 0.0 {
                c
            } else {
                1.0
            }
        })
        .collect();
    let an = faer::Mat::from_fn(2 * l, n, |r, j| a[(r, j)] / scale[j]);
    let svd = an.thin_svd().map_err(|e| {
        Error::numerical(
            "freqfit",
            format!("SVD of the frequency-domain problem failed: {e:?}"),
        )
    })?;
    let sv = svd.S().column_vector();
    let smax = (0..sv.nrows()).map(|k| sv[k]).fold(0.0, f64::max);
    if !(smax > 0.0 && smax.is_finite()) {
        return Err(Error::numerical(
            "freqfit",
            "the frequency-domain least-squares problem is degenerate (all-zero regressors); check the data and the band",
        ));
    }
    let utb = svd.U().transpose() * &b;
    let mut y = vec![0.0; n];
    for k in 0..sv.nrows() {
        if sv[k] > LSTSQ_RCOND * smax {
            let c = utb[(k, 0)] / sv[k];
            for (j, yj) in y.iter_mut().enumerate() {
                *yj += svd.V()[(j, k)] * c;
            }
        }
    }
    let x: Vec<f64> = y.iter().zip(&scale).map(|(v, s)| v / s).collect();
    if x.iter().any(|v| !v.is_finite()) {
        return Err(Error::numerical(
            "freqfit",
            "the frequency-domain least-squares solution is not finite; lower the orders or narrow the band",
        ));
    }
    Ok(x)
}

/// Relative singular-value cut-off of the linear frequency-domain least squares.
const LSTSQ_RCOND: f64 = 1e-14;

/// $\sum_p c_p \zeta^p$ at every line, with the coefficient list starting at power `p0`.
fn poly_at(coef: &[f64], p0: usize, zp: &[Vec<c64>], k: usize) -> c64 {
    coef.iter()
        .enumerate()
        .map(|(i, c)| zp[p0 + i][k] * *c)
        .sum()
}

fn tf_model(b: &[f64], f: &[f64], o: &TfOrders, ts: f64) -> Result<crate::lti::TransferFunction> {
    let mut num = vec![0.0; o.nk];
    num.extend_from_slice(b);
    let mut den = vec![1.0];
    den.extend_from_slice(f);
    crate::lti::TransferFunction::new(num, den, ts)
}

/// Solves the linearised problem $\min \sum_k v_k |F(\zeta_k) G_k - \zeta_k^{n_k} B(\zeta_k)|^2$
/// for $(b, f)$ with line weights $v_k$ (squared inside).
fn levy_step(
    data: &FreqData,
    o: &TfOrders,
    zp: &[Vec<c64>],
    v: &[f64],
) -> Result<(Vec<f64>, Vec<f64>)> {
    let l = data.len();
    let mut cols: Vec<Vec<c64>> = Vec::with_capacity(o.n_params());
    for j in 0..o.nb {
        cols.push((0..l).map(|k| zp[o.nk + j][k]).collect());
    }
    for zi in &zp[1..=o.nf] {
        cols.push(zi.iter().zip(&data.g).map(|(z, g)| -z * g).collect());
    }
    let wt: Vec<f64> = v.iter().map(|x| x.sqrt()).collect();
    let x = complex_lstsq(&cols, &data.g, &wt)?;
    Ok((x[..o.nb].to_vec(), x[o.nb..].to_vec()))
}

/// ARX model fitted to frequency data in Levy's linearised form (linear least squares):
/// minimises $\sum_k w_k |A(\zeta_k) G_k - \zeta_k^{n_k} B(\zeta_k)|^2$ with $A$ monic of degree
/// `o.nf` (the ARX $A$), $\zeta = z^{-1}$. The criterion weights the error by $|A|^2$, which
/// over-weights high frequencies; [`oe_frd`] removes that bias.
///
/// # Errors
/// [`FreqData::new`]'s errors; `nb = 0`; fewer real equations than parameters; a rank-deficient
/// problem.
///
/// # Example
/// ```
/// use ambid_core::estimate::freqfit::{arx_frd, FreqFitOptions, TfOrders};
/// use ambid_core::lti::{Frd, TransferFunction};
/// let g = TransferFunction::new(vec![0.0, 0.5, 0.2], vec![1.0, -1.2, 0.5], 1e-3).unwrap();
/// let f: Vec<f64> = (1..100).map(|k| 4.0 * k as f64).collect();
/// let frd = Frd::new(f.clone(), g.freq_response(&f).unwrap(), None, Some(1e-3)).unwrap();
/// let fit = arx_frd(&frd, &TfOrders { nb: 2, nf: 2, nk: 1 }, &FreqFitOptions::default()).unwrap();
/// assert!((fit.model.den()[1] + 1.2).abs() < 1e-10 && (fit.model.num()[2] - 0.2).abs() < 1e-10);
/// ```
pub fn arx_frd(
    frd: &Frd,
    o: &TfOrders,
    opts: &FreqFitOptions,
) -> Result<FreqFit<crate::lti::TransferFunction>> {
    frd.require_siso("freqfit::arx_frd")?;
    o.check()?;
    let data = FreqData::new(frd, opts)?;
    data.require_fixed_weights("arx_frd")?;
    data.check_params(o.n_params())?;
    let zp = zeta_powers(&data, (o.nk + o.nb).max(o.nf + 1));
    let (b, f) = levy_step(&data, o, &zp, &data.w)?;
    let limit = unstable_limit(opts);
    match limit {
        Some(lim) if unstable_roots_of(&f)? > lim => {
            // the constrained equation-error problem: start from the admissible denominator
            // that explains the data best, then Levenberg–Marquardt on Levy's residuals with
            // every step that leaves the admissible set rejected
            let f0 = admissible_denominator(&data, o, &zp, &f, lim)?;
            let b0 = refit_numerator(&data, o, &zp, &f0)?;
            let mut x0 = b0;
            x0.extend_from_slice(&f0);
            let mut prob = LevyProblem {
                data: &data,
                o: *o,
                zp: &zp,
                limit: lim,
            };
            let lm = super::pem::lm::LmOptions::default()
                .with_max_iterations(opts.max_iterations.max(1))?
                .with_loss_tol(1e-14)?;
            let (x, report) = super::pem::lm::minimize(&mut prob, &x0, &lm)?;
            let (b, f) = (x[..o.nb].to_vec(), x[o.nb..].to_vec());
            finish_tf(
                &data,
                o,
                &zp,
                b,
                f,
                (report.iterations, report.reason.converged()),
            )
        }
        _ => finish_tf(&data, o, &zp, b, f, (0, true)),
    }
}

/// The unstable-pole limit of the options: 0 with `enforce_stability`, else
/// `max_unstable_poles`.
fn unstable_limit(opts: &FreqFitOptions) -> Option<usize> {
    if opts.enforce_stability {
        Some(0)
    } else {
        opts.max_unstable_poles
    }
}

/// Number of roots of $1 + f_1 \zeta + \dots$ (a denominator in $\zeta = z^{-1}$) on or
/// outside the unit circle in $z$.
fn unstable_roots_of(f: &[f64]) -> Result<usize> {
    if f.iter().all(|v| *v == 0.0) {
        return Ok(0);
    }
    let mut den = vec![1.0];
    den.extend_from_slice(f);
    Ok(count_unstable(&crate::linalg::roots(&den)?))
}

/// $B$ by weighted linear least squares of the output error with the denominator $F$ fixed.
fn refit_numerator(data: &FreqData, o: &TfOrders, zp: &[Vec<c64>], f: &[f64]) -> Result<Vec<f64>> {
    let l = data.len();
    let cols: Vec<Vec<c64>> = (0..o.nb)
        .map(|j| {
            (0..l)
                .map(|k| zp[o.nk + j][k] / (c64::new(1.0, 0.0) + poly_at(f, 1, zp, k)))
                .collect()
        })
        .collect();
    let wt: Vec<f64> = data.w.iter().map(|x| x.sqrt()).collect();
    complex_lstsq(&cols, &data.g, &wt)
}

/// The weighted output-error cost of $(B, F)$.
fn oe_cost(data: &FreqData, o: &TfOrders, zp: &[Vec<c64>], b: &[f64], f: &[f64]) -> f64 {
    (0..data.len())
        .map(|k| {
            let fk = c64::new(1.0, 0.0) + poly_at(f, 1, zp, k);
            data.w[k] * (poly_at(b, o.nk, zp, k) / fk - data.g[k]).norm_sqr()
        })
        .sum()
}

/// The start denominator with at most `limit` unstable roots ([`constrained_start`], scored by
/// the output-error cost with $B$ refitted).
fn admissible_denominator(
    data: &FreqData,
    o: &TfOrders,
    zp: &[Vec<c64>],
    f: &[f64],
    limit: usize,
) -> Result<Vec<f64>> {
    let mut den = vec![1.0];
    den.extend_from_slice(f);
    let roots = crate::linalg::roots(&den)?;
    let to_f = |r: &[c64]| crate::linalg::poly_from_roots(r)[1..].to_vec();
    let start = constrained_start(&roots, limit, |r| {
        let f = to_f(r);
        let b = refit_numerator(data, o, zp, &f).ok()?;
        Some(oe_cost(data, o, zp, &b, &f))
    });
    Ok(to_f(&start))
}

/// Levy's equation-error residuals $\sqrt{w_k}\,(F(\zeta_k) G_k - \zeta_k^{n_k} B(\zeta_k))$
/// (re, im) with the denominator constrained to at most `limit` unstable roots.
struct LevyProblem<'a> {
    data: &'a FreqData,
    o: TfOrders,
    zp: &'a [Vec<c64>],
    limit: usize,
}

impl super::pem::lm::LeastSquaresProblem for LevyProblem<'_> {
    fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
        let (b, f) = x.split_at(self.o.nb);
        if unstable_roots_of(f).ok()? > self.limit {
            return None;
        }
        let mut r = Vec::with_capacity(2 * self.data.len());
        for k in 0..self.data.len() {
            let fk = c64::new(1.0, 0.0) + poly_at(f, 1, self.zp, k);
            let e =
                (fk * self.data.g[k] - poly_at(b, self.o.nk, self.zp, k)) * self.data.w[k].sqrt();
            r.push(e.re);
            r.push(e.im);
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    }
    fn jacobian(&mut self, x: &[f64]) -> Option<faer::Mat<f64>> {
        let (nb, nk) = (self.o.nb, self.o.nk);
        let l = self.data.len();
        let mut j = faer::Mat::<f64>::zeros(2 * l, x.len());
        for k in 0..l {
            let sw = self.data.w[k].sqrt();
            for p in 0..nb {
                let d = -self.zp[nk + p][k] * sw;
                j[(2 * k, p)] = d.re;
                j[(2 * k + 1, p)] = d.im;
            }
            for i in 1..=self.o.nf {
                let d = self.zp[i][k] * self.data.g[k] * sw;
                j[(2 * k, nb + i - 1)] = d.re;
                j[(2 * k + 1, nb + i - 1)] = d.im;
            }
        }
        Some(j)
    }
}

fn finish_tf(
    data: &FreqData,
    o: &TfOrders,
    zp: &[Vec<c64>],
    b: Vec<f64>,
    f: Vec<f64>,
    (iterations, converged): (usize, bool),
) -> Result<FreqFit<crate::lti::TransferFunction>> {
    let model = tf_model(&b, &f, o, data.ts)?;
    let resp: Vec<c64> = (0..data.len())
        .map(|k| {
            let fk = c64::new(1.0, 0.0) + poly_at(&f, 1, zp, k);
            poly_at(&b, o.nk, zp, k) / fk
        })
        .collect();
    if resp.iter().any(|v| !(v.re.is_finite() && v.im.is_finite())) {
        return Err(Error::numerical(
            "freqfit",
            "the fitted model has a pole on a data line (infinite response); lower the order or narrow the band",
        ));
    }
    let cost = data.weighted_cost(resp.iter().copied());
    Ok(FreqFit {
        errors: FreqErrors::of(&resp, data),
        model,
        n_params: o.n_params(),
        cost,
        iterations,
        converged,
    })
}

/// Output-error transfer function fitted to frequency data: Sanathanan–Koerner iterations
/// (Levy's problem reweighted by $1/|F_{i-1}(\zeta_k)|^2$, `opts.sk_iterations` of them, starting
/// from [`arx_frd`]) give the start, then Levenberg–Marquardt ([`super::pem::lm`]) minimises the
/// weighted complex error $\sum_k w_k |\zeta_k^{n_k} B(\zeta_k)/F(\zeta_k) - G_k|^2$ with the
/// analytic Jacobian $\partial/\partial b_j = \zeta^{n_k + j}/F$,
/// $\partial/\partial f_i = -\zeta^{n_k + i} B / F^2$. Unstable $F$ is allowed (no
/// stability constraint in the frequency domain); with `opts.enforce_stability` the unstable roots
/// of $F$ are reflected into the unit circle and $B$ is refitted.
///
/// # Errors
/// As [`arx_frd`]; [`Error::Numerical`] if the refinement fails.
///
/// # Example
/// ```
/// use ambid_core::estimate::freqfit::{oe_frd, FreqFitOptions, TfOrders};
/// use ambid_core::lti::{Frd, TransferFunction};
/// // an unstable pole at 1.02 and a lightly damped pair
/// let den = [1.0, -2.9, 2.8676, -0.9588]; // (1 - 1.02 q^-1)(1 - 1.88 q^-1 + 0.94 q^-2)
/// let g = TransferFunction::new(vec![0.0, 0.1, 0.05], den.to_vec(), 1e-3).unwrap();
/// let f: Vec<f64> = (1..150).map(|k| 3.0 * k as f64).collect();
/// let frd = Frd::new(f.clone(), g.freq_response(&f).unwrap(), None, Some(1e-3)).unwrap();
/// let fit = oe_frd(&frd, &TfOrders { nb: 2, nf: 3, nk: 1 }, &FreqFitOptions::default()).unwrap();
/// assert!(fit.errors.relative_rmse < 1e-9);
/// assert!(fit.model.poles().unwrap().iter().any(|p| p.norm() > 1.0));
/// ```
pub fn oe_frd(
    frd: &Frd,
    o: &TfOrders,
    opts: &FreqFitOptions,
) -> Result<FreqFit<crate::lti::TransferFunction>> {
    frd.require_siso("freqfit::oe_frd")?;
    o.check()?;
    let data = FreqData::new(frd, opts)?;
    data.check_params(o.n_params())?;
    let zp = zeta_powers(&data, (o.nk + o.nb).max(o.nf + 1) + o.nf);
    let (mut b, mut f) = levy_step(&data, o, &zp, &data.w)?;
    for _ in 0..opts.sk_iterations {
        let v: Vec<f64> = (0..data.len())
            .map(|k| {
                let fk = c64::new(1.0, 0.0) + poly_at(&f, 1, &zp, k);
                data.w[k] / fk.norm_sqr().max(f64::MIN_POSITIVE)
            })
            .collect();
        match levy_step(&data, o, &zp, &v) {
            Ok((nb, nf)) => {
                b = nb;
                f = nf;
            }
            Err(_) => break,
        }
    }
    // with a limit on the unstable poles (not the explicit reflection of `enforce_stability`):
    // an admissible start and a constrained refinement
    let limit = opts.max_unstable_poles.filter(|_| !opts.enforce_stability);
    if let Some(lim) = limit {
        if unstable_roots_of(&f)? > lim {
            f = admissible_denominator(&data, o, &zp, &f, lim)?;
            b = refit_numerator(&data, o, &zp, &f)?;
        }
    }
    let mut prob = TfProblem {
        data: &data,
        o: *o,
        zp: &zp,
        limit,
    };
    let mut x0 = b.clone();
    x0.extend_from_slice(&f);
    let lm = super::pem::lm::LmOptions::default()
        .with_max_iterations(opts.max_iterations.max(1))?
        .with_loss_tol(1e-14)?;
    let (x, report) = super::pem::lm::minimize(&mut prob, &x0, &lm)?;
    let (mut b, mut f) = (x[..o.nb].to_vec(), x[o.nb..].to_vec());
    if opts.enforce_stability && o.nf > 0 {
        let mut den = vec![1.0];
        den.extend_from_slice(&f);
        // roots of z^nf + f1 z^(nf-1) + ... (descending powers of z)
        let roots = crate::linalg::roots(&den)?;
        if roots.iter().any(|r| r.norm() > 1.0) {
            let reflected: Vec<c64> = roots
                .iter()
                .map(|r| {
                    if r.norm() > 1.0 {
                        c64::new(1.0, 0.0) / r.conj()
                    } else {
                        *r
                    }
                })
                .collect();
            let p = crate::linalg::poly_from_roots(&reflected);
            f = p[1..].to_vec();
            // refit B for the reflected F (linear)
            let l = data.len();
            let cols: Vec<Vec<c64>> = (0..o.nb)
                .map(|j| {
                    (0..l)
                        .map(|k| zp[o.nk + j][k] / (c64::new(1.0, 0.0) + poly_at(&f, 1, &zp, k)))
                        .collect()
                })
                .collect();
            let wt: Vec<f64> = data.w.iter().map(|x| x.sqrt()).collect();
            b = complex_lstsq(&cols, &data.g, &wt)?;
        }
    }
    finish_tf(
        &data,
        o,
        &zp,
        b,
        f,
        (report.iterations, report.reason.converged()),
    )
}

/// The OE criterion for the Levenberg–Marquardt solver: residuals (re, im) of
/// $\sqrt{w_k}(\zeta^{n_k}B/F - G_k)$ ([`FreqData::residual`]: the weight at the model under
/// sample maximum likelihood).
struct TfProblem<'a> {
    data: &'a FreqData,
    o: TfOrders,
    zp: &'a [Vec<c64>],
    /// At most this many unstable roots of $F$ (steps beyond are inadmissible).
    limit: Option<usize>,
}

impl super::pem::lm::LeastSquaresProblem for TfProblem<'_> {
    fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
        let (b, f) = x.split_at(self.o.nb);
        if let Some(lim) = self.limit {
            if unstable_roots_of(f).ok()? > lim {
                return None;
            }
        }
        let mut r = Vec::with_capacity(2 * self.data.len());
        for k in 0..self.data.len() {
            let fk = c64::new(1.0, 0.0) + poly_at(f, 1, self.zp, k);
            let e = self
                .data
                .residual(k, poly_at(b, self.o.nk, self.zp, k) / fk);
            r.push(e.re);
            r.push(e.im);
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    }
    fn jacobian(&mut self, x: &[f64]) -> Option<faer::Mat<f64>> {
        let (b, f) = x.split_at(self.o.nb);
        let (nb, nk) = (self.o.nb, self.o.nk);
        let l = self.data.len();
        let mut j = faer::Mat::<f64>::zeros(2 * l, x.len());
        for k in 0..l {
            let fk = c64::new(1.0, 0.0) + poly_at(f, 1, self.zp, k);
            let bk = poly_at(b, nk, self.zp, k);
            let pk = bk / fk;
            for (p, _) in b.iter().enumerate() {
                let d = self.data.residual_slope(k, pk, self.zp[nk + p][k] / fk);
                j[(2 * k, p)] = d.re;
                j[(2 * k + 1, p)] = d.im;
            }
            for i in 1..=f.len() {
                let d = self
                    .data
                    .residual_slope(k, pk, -(self.zp[i][k] * bk) / (fk * fk));
                j[(2 * k, nb + i - 1)] = d.re;
                j[(2 * k + 1, nb + i - 1)] = d.im;
            }
        }
        let finite = j.col_iter().all(|c| c.iter().all(|v| v.is_finite()));
        finite.then_some(j)
    }
}

/// Result of [`coprime_frd`].
#[derive(Debug, Clone)]
pub struct CoprimeFit {
    /// $\hat T_{ry} = q^{-n_k} B_t / F$.
    pub t_ry: crate::lti::TransferFunction,
    /// $\hat S = B_s / F$.
    pub s: crate::lti::TransferFunction,
    /// $\hat P = \hat T_{ry} / \hat S = q^{-n_k} B_t / B_s$: its poles are the zeros of $\hat S$.
    pub plant: crate::lti::TransferFunction,
    /// Errors of $\hat T_{ry}$ and of $\hat S$ on their lines.
    pub errors: (FreqErrors, FreqErrors),
    /// Weighted cost over both FRFs.
    pub cost: f64,
    /// Levenberg–Marquardt iterations.
    pub iterations: usize,
}

/// The **coprime route** to an unstable plant: $T_{ry}$ and $S$ (both stable closed-loop maps,
/// measured from $r$) fitted jointly with a common monic denominator $F$ of degree `n`,
/// $\hat T_{ry} = q^{-n_k} B_t(q^{-1})/F$ ($n$ coefficients of $B_t$), $\hat S = B_s(q^{-1})/F$
/// ($n + 1$ coefficients of $B_s$), then $\hat P = \hat T_{ry}/\hat S = q^{-n_k} B_t / B_s$. No
/// controller model is needed, every fit is of a stable map, and the plant's unstable poles appear
/// as zeros of $\hat S$. `n` is the closed-loop order (plant plus controller states). The
/// criterion is the sum of the two weighted complex errors (each with the weights of `opts` on its
/// own FRF), minimised as [`oe_frd`] does: Levy's linear problem, Sanathanan–Koerner iterations,
/// then Levenberg–Marquardt.
///
/// # Errors
/// As [`oe_frd`]; [`Error::InvalidArgument`] when the two FRFs have different frequencies or
/// sample times, or `n = 0`.
///
/// # Example
/// ```
/// use ambid_core::estimate::freqfit::{coprime_frd, FreqFitOptions};
/// use ambid_core::lti::{Frd, TransferFunction};
/// // unstable plant P = 0.1 q^-1 / (1 - 1.05 q^-1), proportional controller 2: closed loop
/// // 1 + PC has the root 1.05 - 0.2 = 0.85
/// let (ts, f): (f64, Vec<f64>) = (1e-3, (1..120).map(|k| 4.0 * k as f64).collect());
/// let t = TransferFunction::new(vec![0.0, 0.1], vec![1.0, -0.85], ts).unwrap();
/// let s = TransferFunction::new(vec![1.0, -1.05], vec![1.0, -0.85], ts).unwrap();
/// let frd = |g: &TransferFunction| Frd::new(f.clone(), g.freq_response(&f).unwrap(), None, Some(ts)).unwrap();
/// let fit = coprime_frd(&frd(&t), &frd(&s), 1, 1, &FreqFitOptions::default()).unwrap();
/// let p = fit.plant.poles().unwrap();
/// assert!((p[0].re - 1.05).abs() < 1e-9);
/// ```
pub fn coprime_frd(
    t_ry: &Frd,
    s: &Frd,
    n: usize,
    nk: usize,
    opts: &FreqFitOptions,
) -> Result<CoprimeFit> {
    t_ry.require_siso("freqfit::coprime_frd")?;
    s.require_siso("freqfit::coprime_frd")?;
    if n == 0 {
        return Err(Error::invalid(
            "n",
            "the closed-loop order must be at least 1",
        ));
    }
    let dt = FreqData::new(t_ry, opts)?;
    let ds = FreqData::new(s, opts)?;
    dt.require_fixed_weights("coprime_frd")?;
    if dt.f_hz != ds.f_hz || dt.ts != ds.ts {
        return Err(Error::invalid(
            "s",
            "T_ry and S must be given on the same lines (same band, same weights' zero pattern) and at the same sample time",
        ));
    }
    let (nbt, nbs) = (n, n + 1);
    let np = nbt + nbs + n;
    if 4 * dt.len() < np {
        return Err(Error::invalid(
            "band_hz",
            format!("{} lines of two FRFs cannot determine {np} parameters; widen the band or lower the order", dt.len()),
        ));
    }
    let zp = zeta_powers(&dt, (nk + nbt).max(nbs).max(n + 1));
    let l = dt.len();
    // Levy / SK: unknowns [b_t, b_s, f]; equations F T − ζ^nk B_t and F S − B_s
    let solve = |v: &[f64]| -> Result<Vec<f64>> {
        let mut cols: Vec<Vec<c64>> = Vec::with_capacity(np);
        let zero = c64::new(0.0, 0.0);
        for j in 0..nbt {
            cols.push(
                (0..2 * l)
                    .map(|k| if k < l { zp[nk + j][k] } else { zero })
                    .collect(),
            );
        }
        for zj in &zp[..nbs] {
            cols.push(
                (0..2 * l)
                    .map(|k| if k < l { zero } else { zj[k - l] })
                    .collect(),
            );
        }
        for zi in &zp[1..=n] {
            cols.push(
                (0..2 * l)
                    .map(|k| {
                        if k < l {
                            -zi[k] * dt.g[k]
                        } else {
                            -zi[k - l] * ds.g[k - l]
                        }
                    })
                    .collect(),
            );
        }
        let rhs: Vec<c64> = dt.g.iter().chain(&ds.g).copied().collect();
        let wt: Vec<f64> = (0..2 * l)
            .map(|k| {
                if k < l {
                    dt.w[k] * v[k]
                } else {
                    ds.w[k - l] * v[k - l]
                }
                .sqrt()
            })
            .collect();
        complex_lstsq(&cols, &rhs, &wt)
    };
    let mut x = solve(&vec![1.0; l])?;
    for _ in 0..opts.sk_iterations {
        let f = &x[nbt + nbs..];
        let v: Vec<f64> = (0..l)
            .map(|k| {
                1.0 / (c64::new(1.0, 0.0) + poly_at(f, 1, &zp, k))
                    .norm_sqr()
                    .max(f64::MIN_POSITIVE)
            })
            .collect();
        match solve(&v) {
            Ok(nx) => x = nx,
            Err(_) => break,
        }
    }
    let mut prob = CoprimeProblem {
        dt: &dt,
        ds: &ds,
        zp: &zp,
        nbt,
        nbs,
        nk,
    };
    let lm = super::pem::lm::LmOptions::default()
        .with_max_iterations(opts.max_iterations.max(1))?
        .with_loss_tol(1e-14)?;
    let (x, report) = super::pem::lm::minimize(&mut prob, &x, &lm)?;
    let (bt, rest) = x.split_at(nbt);
    let (bs, f) = rest.split_at(nbs);
    let mut den = vec![1.0];
    den.extend_from_slice(f);
    let mut num_t = vec![0.0; nk];
    num_t.extend_from_slice(bt);
    let t_model = crate::lti::TransferFunction::new(num_t.clone(), den.clone(), dt.ts)?;
    let s_model = crate::lti::TransferFunction::new(bs.to_vec(), den, dt.ts)?;
    if bs[0] == 0.0 {
        return Err(Error::numerical(
            "coprime_frd",
            "the fitted S has no direct term, so P = T_ry/S is improper; check that S is the map from r to u",
        ));
    }
    let plant = crate::lti::TransferFunction::new(num_t, bs.to_vec(), dt.ts)?;
    let rt = t_model.freq_response(&dt.f_hz)?;
    let rs = s_model.freq_response(&ds.f_hz)?;
    Ok(CoprimeFit {
        errors: (FreqErrors::of(&rt, &dt), FreqErrors::of(&rs, &ds)),
        t_ry: t_model,
        s: s_model,
        plant,
        cost: report.cost * 2.0,
        iterations: report.iterations,
    })
}

/// Residuals of both FRFs for [`coprime_frd`].
struct CoprimeProblem<'a> {
    dt: &'a FreqData,
    ds: &'a FreqData,
    zp: &'a [Vec<c64>],
    nbt: usize,
    nbs: usize,
    nk: usize,
}

impl super::pem::lm::LeastSquaresProblem for CoprimeProblem<'_> {
    fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
        let (bt, rest) = x.split_at(self.nbt);
        let (bs, f) = rest.split_at(self.nbs);
        let mut r = Vec::with_capacity(4 * self.dt.len());
        for k in 0..self.dt.len() {
            let fk = c64::new(1.0, 0.0) + poly_at(f, 1, self.zp, k);
            let et = (poly_at(bt, self.nk, self.zp, k) / fk - self.dt.g[k]) * self.dt.w[k].sqrt();
            let es = (poly_at(bs, 0, self.zp, k) / fk - self.ds.g[k]) * self.ds.w[k].sqrt();
            r.extend_from_slice(&[et.re, et.im, es.re, es.im]);
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    }
    fn jacobian(&mut self, x: &[f64]) -> Option<faer::Mat<f64>> {
        let (bt, rest) = x.split_at(self.nbt);
        let (bs, f) = rest.split_at(self.nbs);
        let (nbt, nbs) = (self.nbt, self.nbs);
        let mut j = faer::Mat::<f64>::zeros(4 * self.dt.len(), x.len());
        for k in 0..self.dt.len() {
            let (swt, sws) = (self.dt.w[k].sqrt(), self.ds.w[k].sqrt());
            let fk = c64::new(1.0, 0.0) + poly_at(f, 1, self.zp, k);
            let tk = poly_at(bt, self.nk, self.zp, k) / fk;
            let sk = poly_at(bs, 0, self.zp, k) / fk;
            let row = 4 * k;
            for p in 0..nbt {
                let d = self.zp[self.nk + p][k] / fk * swt;
                j[(row, p)] = d.re;
                j[(row + 1, p)] = d.im;
            }
            for p in 0..nbs {
                let d = self.zp[p][k] / fk * sws;
                j[(row + 2, nbt + p)] = d.re;
                j[(row + 3, nbt + p)] = d.im;
            }
            for i in 1..=f.len() {
                let col = nbt + nbs + i - 1;
                let dt = -(self.zp[i][k] * tk) / fk * swt;
                let ds = -(self.zp[i][k] * sk) / fk * sws;
                j[(row, col)] = dt.re;
                j[(row + 1, col)] = dt.im;
                j[(row + 2, col)] = ds.re;
                j[(row + 3, col)] = ds.im;
            }
        }
        let finite = j.col_iter().all(|c| c.iter().all(|v| v.is_finite()));
        finite.then_some(j)
    }
}

/// The input delay of an OE model estimated from frequency data: [`oe_frd`] for every
/// $n_k = 0, \dots,$ `max_nk` with the same $n_b$, $n_f$ (so the same parameter count), keeping the
/// lowest weighted cost. Returns the delay and its fit.
///
/// # Errors
/// As [`oe_frd`] when no delay gives a fit.
///
/// # Example
/// ```
/// use ambid_core::estimate::freqfit::{estimate_delay, FreqFitOptions};
/// use ambid_core::lti::{Frd, TransferFunction};
/// let g = TransferFunction::new(vec![0.0, 0.0, 0.0, 0.3, 0.2], vec![1.0, -0.6], 1e-3).unwrap();
/// let f: Vec<f64> = (1..100).map(|k| 4.0 * k as f64).collect();
/// let frd = Frd::new(f.clone(), g.freq_response(&f).unwrap(), None, Some(1e-3)).unwrap();
/// let (nk, fit) = estimate_delay(&frd, 2, 1, 6, &FreqFitOptions::default()).unwrap();
/// assert_eq!(nk, 3);
/// assert!(fit.errors.relative_rmse < 1e-9);
/// ```
pub fn estimate_delay(
    frd: &Frd,
    nb: usize,
    nf: usize,
    max_nk: usize,
    opts: &FreqFitOptions,
) -> Result<(usize, FreqFit<crate::lti::TransferFunction>)> {
    frd.require_siso("freqfit::estimate_delay")?;
    let mut best: Option<(usize, FreqFit<crate::lti::TransferFunction>)> = None;
    let mut last_err = None;
    for nk in 0..=max_nk {
        match oe_frd(frd, &TfOrders { nb, nf, nk }, opts) {
            Ok(fit) => {
                if best.as_ref().is_none_or(|(_, b)| fit.cost < b.cost) {
                    best = Some((nk, fit));
                }
            }
            Err(e) => last_err = Some(e),
        }
    }
    match (best, last_err) {
        (Some(b), _) => Ok(b),
        (None, Some(e)) => Err(e),
        (None, None) => Err(Error::invalid("max_nk", "no delay was tried")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::pem::lm::jacobian_against_differences;

    /// The output-error criterion's Jacobian against central differences, with weights fixed
    /// and with sample maximum-likelihood weights (the variance's slope in the residual).
    #[test]
    fn oe_jacobian_matches_finite_differences(
    ) -> std::result::Result<(), Box<dyn std::error::Error>> {
        let f: Vec<f64> = (1..50).map(|k| 9.0 * k as f64).collect();
        let vals: Vec<c64> = f
            .iter()
            .map(|x| c64::new(1.0 / (1.0 + x / 60.0), -0.02 * x / 60.0))
            .collect();
        let noise: Vec<RatioNoise> = f
            .iter()
            .map(|x| RatioNoise {
                a: 2e-3 * (1.0 + x / 300.0),
                b: 1e-3,
                c: c64::new(4e-4, 1e-4),
            })
            .collect();
        let frd = Frd::new(f, vals, None, Some(1e-3))?;
        let o = TfOrders {
            nb: 2,
            nf: 2,
            nk: 1,
        };
        for weights in [
            FreqWeights::Uniform,
            FreqWeights::SampleMaximumLikelihood(noise),
        ] {
            let opts = FreqFitOptions {
                weights,
                ..FreqFitOptions::default()
            };
            let data = FreqData::new(&frd, &opts)?;
            let zp = zeta_powers(&data, 4);
            let mut prob = TfProblem {
                data: &data,
                o,
                zp: &zp,
                limit: None,
            };
            let x = [0.3, -0.1, -1.2, 0.5];
            jacobian_against_differences(&mut prob, &x, 1e-5)?;
        }
        Ok(())
    }
}
