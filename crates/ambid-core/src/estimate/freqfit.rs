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

use crate::error::{Error, Result};
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
}

impl Default for FreqFitOptions {
    fn default() -> Self {
        Self {
            band_hz: None,
            weights: FreqWeights::Uniform,
            max_iterations: 100,
            sk_iterations: 20,
            enforce_stability: false,
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
        };
        let mut data = Self {
            f_hz: Vec::new(),
            g: Vec::new(),
            w: Vec::new(),
            z: Vec::new(),
            ts,
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
        Ok(data)
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
}
