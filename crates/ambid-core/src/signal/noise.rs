//! Seeded random noise, white or band-limited.
//!
//! # Math
//! Samples are drawn independently from a [`ChaCha8Rng`] seeded with `seed` (portable: the same seed
//! gives the same signal on every platform and version of this crate's dependencies that keep the
//! ChaCha8 stream):
//! * Gaussian: $x_k \sim \mathcal N(0, \sigma^2)$ with $\sigma$ = `rms`;
//! * uniform: $x_k \sim \mathcal U(-a, a)$ with $a = \sqrt3\,\sigma$, whose RMS is $\sigma$ and whose
//!   crest factor never exceeds $\sqrt 3$.
//!
//! White noise has the requested RMS in expectation only. With `band_hz = Some((f_lo, f_hi))` the
//! white sequence is transformed, every DFT bin $k$ with $f_k = k/(N T_s) \notin [f_lo, f_hi]$ is
//! set to zero, the result is transformed back and scaled to exactly the requested RMS. The
//! band-limited signal is then periodic with period $N$ (no energy outside the band over the whole
//! record) and, by the central limit theorem, close to Gaussian whatever the distribution.
//!
//! Noise excites every frequency, but each realisation differs: repeated experiments agree only on
//! average, and spectral estimates need windowing and averaging (leakage). Fix the seed to make an
//! experiment repeatable.
//!
//! # Example
//! ```
//! use ambid_core::signal::{NoiseSpec, Distribution, rms};
//! let spec = NoiseSpec { distribution: Distribution::Uniform, rms: 0.2, n_samples: 4096,
//!                        band_hz: Some((10.0, 200.0)), seed: 1 };
//! let x = spec.generate(1e-3).unwrap();
//! assert!((rms(&x.values).unwrap() - 0.2).abs() < 1e-12);
//! assert_eq!(x, spec.generate(1e-3).unwrap()); // same seed, same signal
//! ```

use super::analysis::{real_fft, real_ifft};
use super::{
    check_count, check_positive, check_ts, level_stats, BandReport, Excitation, MAX_SAMPLES,
};
use crate::error::{Error, Result};
use num_complex::Complex;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Amplitude distribution of white noise samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Distribution {
    /// Normal with standard deviation `rms`.
    Gaussian,
    /// Uniform on $[-\sqrt3\,\mathrm{rms}, \sqrt3\,\mathrm{rms}]$.
    Uniform,
}

/// Seeded random noise of `n_samples` samples, optionally band-limited to `band_hz`.
///
/// # Requirements
/// `rms` finite and $> 0$; $2 \le$ `n_samples` $\le$ [`MAX_SAMPLES`]; a band
/// $0 \le f_{lo} < f_{hi} \le f_s/2$ that contains at least one DFT bin $k/(N T_s)$.
///
/// # Example
/// ```
/// use ambid_core::signal::{NoiseSpec, Distribution};
/// let spec = NoiseSpec { distribution: Distribution::Gaussian, rms: 1.0, n_samples: 10_000,
///                        band_hz: None, seed: 42 };
/// let r = spec.report(1e-4).unwrap();
/// assert!((r.rms - 1.0).abs() < 0.05);
/// assert!((r.f_max_hz - 5000.0).abs() < 1e-9 && (r.resolution_hz - 1.0).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseSpec {
    /// Sample distribution (before any band limitation).
    pub distribution: Distribution,
    /// Requested RMS value $\sigma > 0$ (exact when band-limited, in expectation otherwise).
    pub rms: f64,
    /// Number of samples $N$.
    pub n_samples: usize,
    /// Optional pass band $(f_{lo}, f_{hi})$ in Hz; bins outside it are zeroed.
    pub band_hz: Option<(f64, f64)>,
    /// Seed of the [`ChaCha8Rng`].
    pub seed: u64,
}

impl NoiseSpec {
    fn validate(&self, ts: f64) -> Result<()> {
        check_ts(ts)?;
        check_positive("rms", self.rms)?;
        check_count("n_samples", self.n_samples, 2)?;
        if self.n_samples > MAX_SAMPLES {
            return Err(Error::invalid(
                "n_samples",
                format!(
                    "{} exceeds the limit of {MAX_SAMPLES} samples; generate shorter records",
                    self.n_samples
                ),
            ));
        }
        if let Some((lo, hi)) = self.band_hz {
            let nyq = 0.5 / ts;
            if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo < hi && hi <= nyq) {
                return Err(Error::invalid(
                    "band_hz",
                    format!("must satisfy 0 <= f_lo < f_hi <= fs/2 = {nyq} Hz, got ({lo}, {hi})"),
                ));
            }
            let (k_lo, k_hi) = self.band_bins(ts, lo, hi);
            if k_lo > k_hi {
                return Err(Error::invalid(
                    "band_hz",
                    format!(
                        "({lo}, {hi}) Hz contains no frequency line k/(N ts) (spacing {} Hz); \
                         widen the band or use more samples",
                        1.0 / (self.n_samples as f64 * ts)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// First and last DFT bin inside `[lo, hi]`.
    fn band_bins(&self, ts: f64, lo: f64, hi: f64) -> (usize, usize) {
        let df = 1.0 / (self.n_samples as f64 * ts);
        let half = self.n_samples / 2;
        // Tolerate rounding so that band edges given exactly on a line include it.
        let eps = 1e-9;
        let k_lo = (lo / df - eps).ceil().max(0.0) as usize;
        let k_hi = ((hi / df + eps).floor() as usize).min(half);
        (k_lo, k_hi)
    }

    /// Generates the noise at sample time `ts` (one "period" of `n_samples`).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for any field outside its range (see the type's requirements).
    pub fn generate(&self, ts: f64) -> Result<Excitation> {
        self.validate(ts)?;
        let n = self.n_samples;
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut x: Vec<f64> = match self.distribution {
            Distribution::Gaussian => (0..n)
                .map(|_| self.rms * rng.sample::<f64, _>(StandardNormal))
                .collect(),
            Distribution::Uniform => {
                let a = 3f64.sqrt() * self.rms;
                (0..n).map(|_| rng.random_range(-a..a)).collect()
            }
        };
        if let Some((lo, hi)) = self.band_hz {
            let (k_lo, k_hi) = self.band_bins(ts, lo, hi);
            let mut spec = real_fft(&x)?;
            for (k, c) in spec.iter_mut().enumerate() {
                if k < k_lo || k > k_hi {
                    *c = Complex::new(0.0, 0.0);
                }
            }
            x = real_ifft(&spec, n)?;
            let (r, _, _) = level_stats(&x);
            if r == 0.0 || !r.is_finite() {
                return Err(Error::numerical(
                    "band-limited noise",
                    "the filtered signal vanished; widen the band or change the seed",
                ));
            }
            let g = self.rms / r;
            x.iter_mut().for_each(|v| *v *= g);
        }
        Ok(Excitation {
            values: x,
            ts,
            period_samples: n,
            periods: 1,
        })
    }

    /// Band (the pass band, or $[1/(N T_s), f_s/2]$ for white noise), resolution $1/(N T_s)$,
    /// duration, and the level of the generated realisation.
    ///
    /// # Errors
    /// As [`NoiseSpec::generate`].
    pub fn report(&self, ts: f64) -> Result<BandReport> {
        let x = self.generate(ts)?;
        let n = self.n_samples;
        let df = 1.0 / (n as f64 * ts);
        let (f_min, f_max) = match self.band_hz {
            Some((lo, hi)) => (lo.max(df), hi),
            None => (df, 0.5 / ts),
        };
        let (rms, peak, crest) = level_stats(&x.values);
        Ok(BandReport {
            f_min_hz: f_min,
            f_max_hz: f_max,
            resolution_hz: df,
            duration_s: n as f64 * ts,
            n_samples: n,
            period_samples: n,
            periods: 1,
            rms,
            peak,
            crest_factor: crest,
        })
    }
}
