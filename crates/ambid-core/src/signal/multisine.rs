//! Periodic multisines on DFT bins (Schroeder or random phases; full, odd or random-odd grids).
//!
//! # Math
//! With period $N$ samples and the excited bin set $\mathcal K \subset \{1, \dots, \lceil N/2 \rceil - 1\}$
//! ($F = |\mathcal K|$ lines),
//! $$ x_n = A \sum_{i=1}^{F} \cos\!\Big(\frac{2\pi k_i n}{N} + \varphi_i\Big), \qquad
//!    A = \mathrm{rms}\sqrt{2/F}, $$
//! so every line has the same amplitude $A$ (flat amplitude spectrum) and the RMS over a period is
//! exactly `rms`. Lines sit exactly on the DFT bins $f_k = k f_s / N$, so the DFT of any whole number
//! of periods has energy only on $\mathcal K$: no leakage, no window needed. The signal is computed
//! by one inverse real FFT.
//!
//! Phases:
//! * Schroeder: $\varphi_i = -\pi\, i (i-1) / F$ — a deterministic low crest factor for a flat
//!   spectrum of many lines: about 1.45–1.65 when the band starts at the first bin, about 1.8–1.9
//!   for a band away from DC, versus about 3–4 for random phases;
//! * random: $\varphi_i \sim \mathcal U[0, 2\pi)$ from a seeded [`ChaCha8Rng`].
//!
//! Grids (which bins in $[f_{\min}, f_{\max}]$ are excited):
//! * full: every bin;
//! * odd: odd bins only, so even-order nonlinear distortion lands on the unexcited even bins;
//! * random-odd: odd bins, and in each complete group of [`RANDOM_ODD_GROUP`] consecutive odd lines one
//!   line chosen at random (seeded) is left out, so odd-order distortion shows on those detection lines
//!   (Pintelon & Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed., 2012,
//!   Sec. 3.4 and 4.3).
//!
//! The Nyquist bin $N/2$ is never excited (its phase is not free), even when `f_max_hz` $= f_s/2$.
//!
//! # Example
//! ```
//! use ambid_core::signal::{MultisineSpec, Grid, Phases, crest_factor};
//! let spec = MultisineSpec { f_min_hz: 10.0, f_max_hz: 1000.0, period_samples: 4000, periods: 2,
//!                            rms: 0.1, grid: Grid::Full, phases: Phases::Schroeder, seed: 0 };
//! let ts = 2.5e-4; // fs = 4 kHz, 1 Hz spacing
//! assert_eq!(spec.lines(ts).unwrap().len(), 991);
//! let x = spec.generate(ts).unwrap();
//! assert!(crest_factor(&x.values).unwrap() < 1.9);
//! ```

use super::analysis::real_ifft;
use super::{
    check_count, check_positive, check_ts, level_stats, repeat_period, total_samples, BandReport,
    Excitation, MAX_SAMPLES,
};
use crate::error::{Error, Result};
use num_complex::Complex;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// Number of consecutive odd lines per group of the random-odd grid (one is left out per group).
pub const RANDOM_ODD_GROUP: usize = 3;

/// Which DFT bins inside the band are excited.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Grid {
    /// Every bin.
    Full,
    /// Odd bins only.
    Odd,
    /// Odd bins with one random line left out of each group of [`RANDOM_ODD_GROUP`].
    RandomOdd,
}

/// Phase choice of the lines.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phases {
    /// Schroeder phases $-\pi i(i-1)/F$: low crest factor, deterministic.
    Schroeder,
    /// Independent uniform phases from the seeded generator.
    Random,
}

/// A periodic, bin-aligned multisine with a flat amplitude spectrum.
///
/// # Requirements
/// `period_samples` $\ge 4$; `periods` $\ge 1$; `rms` finite and $> 0$;
/// $0 < f_{\min} \le f_{\max} \le f_s/2$ with at least one line of the grid in the band; at most
/// [`MAX_SAMPLES`] samples.
///
/// # Example
/// ```
/// use ambid_core::signal::{MultisineSpec, Grid, Phases};
/// let spec = MultisineSpec { f_min_hz: 1.0, f_max_hz: 10.0, period_samples: 100, periods: 1,
///                            rms: 1.0, grid: Grid::Odd, phases: Phases::Random, seed: 3 };
/// let ts = 0.01; // 1 Hz bins
/// assert_eq!(spec.bins(ts).unwrap(), vec![1, 3, 5, 7, 9]);
/// let r = spec.report(ts).unwrap();
/// assert!((r.rms - 1.0).abs() < 1e-12);
/// assert_eq!((r.f_min_hz, r.f_max_hz), (1.0, 9.0));
/// ```
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MultisineSpec {
    /// Lowest frequency of the band in Hz ($> 0$).
    pub f_min_hz: f64,
    /// Highest frequency of the band in Hz ($\le f_s/2$).
    pub f_max_hz: f64,
    /// Samples per period $N$; the line spacing is $f_s/N$.
    pub period_samples: usize,
    /// Number of periods.
    pub periods: usize,
    /// RMS value over a period.
    pub rms: f64,
    /// Which bins are excited.
    pub grid: Grid,
    /// Phase choice.
    pub phases: Phases,
    /// Seed for random phases and the random-odd grid.
    pub seed: u64,
}

impl MultisineSpec {
    fn validate(&self, ts: f64) -> Result<()> {
        check_ts(ts)?;
        check_count("period_samples", self.period_samples, 4)?;
        check_count("periods", self.periods, 1)?;
        check_positive("rms", self.rms)?;
        if self.period_samples > MAX_SAMPLES {
            return Err(Error::invalid(
                "period_samples",
                format!(
                    "{} exceeds the limit of {MAX_SAMPLES} samples",
                    self.period_samples
                ),
            ));
        }
        let nyq = 0.5 / ts;
        let (lo, hi) = (self.f_min_hz, self.f_max_hz);
        if !(lo.is_finite() && lo > 0.0 && lo <= nyq) {
            return Err(Error::invalid(
                "f_min_hz",
                format!("must lie in (0, fs/2] = (0, {nyq}] Hz, got {lo}"),
            ));
        }
        if !(hi.is_finite() && hi >= lo && hi <= nyq) {
            return Err(Error::invalid(
                "f_max_hz",
                format!("must lie in [f_min_hz, fs/2] = [{lo}, {nyq}] Hz, got {hi}"),
            ));
        }
        Ok(())
    }

    /// Random generator shared by the grid and the phases, in that order.
    fn rng(&self) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(self.seed)
    }

    fn bins_with(&self, ts: f64, rng: &mut ChaCha8Rng) -> Result<Vec<usize>> {
        self.validate(ts)?;
        let n = self.period_samples;
        let per_bin = n as f64 * ts; // bins per Hz
        let eps = 1e-9;
        let k_lo = ((self.f_min_hz * per_bin - eps).ceil() as usize).max(1);
        // Highest bin strictly below Nyquist.
        let k_top = (n - 1) / 2;
        let k_hi = ((self.f_max_hz * per_bin + eps).floor() as usize).min(k_top);
        let band: Vec<usize> = if k_lo > k_hi {
            Vec::new()
        } else {
            match self.grid {
                Grid::Full => (k_lo..=k_hi).collect(),
                Grid::Odd | Grid::RandomOdd => (k_lo..=k_hi).filter(|k| k % 2 == 1).collect(),
            }
        };
        let lines = if self.grid == Grid::RandomOdd {
            let mut kept = Vec::with_capacity(band.len());
            for group in band.chunks(RANDOM_ODD_GROUP) {
                if group.len() == RANDOM_ODD_GROUP {
                    let drop = rng.random_range(0..RANDOM_ODD_GROUP);
                    kept.extend(
                        group
                            .iter()
                            .enumerate()
                            .filter(|&(i, _)| i != drop)
                            .map(|(_, &k)| k),
                    );
                } else {
                    kept.extend_from_slice(group);
                }
            }
            kept
        } else {
            band
        };
        if lines.is_empty() {
            return Err(Error::invalid(
                "f_min_hz",
                format!(
                    "the band [{}, {}] Hz holds no line of the chosen grid (line spacing fs/N = {} Hz, \
                     Nyquist excluded); widen the band or increase period_samples",
                    self.f_min_hz,
                    self.f_max_hz,
                    1.0 / (n as f64 * ts)
                ),
            ));
        }
        Ok(lines)
    }

    /// The excited DFT bins $k$ (line $k$ is at $k f_s / N$ Hz), ascending.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for any field outside its range or a band without lines.
    pub fn bins(&self, ts: f64) -> Result<Vec<usize>> {
        self.bins_with(ts, &mut self.rng())
    }

    /// The excited frequencies $k f_s / N$ in Hz, ascending.
    ///
    /// # Errors
    /// As [`MultisineSpec::bins`].
    pub fn lines(&self, ts: f64) -> Result<Vec<f64>> {
        let per_bin = self.period_samples as f64 * ts;
        Ok(self
            .bins(ts)?
            .into_iter()
            .map(|k| k as f64 / per_bin)
            .collect())
    }

    fn one_period(&self, ts: f64) -> Result<Vec<f64>> {
        let mut rng = self.rng();
        let bins = self.bins_with(ts, &mut rng)?;
        let n = self.period_samples;
        let f = bins.len();
        let amp = self.rms * (2.0 / f as f64).sqrt();
        let mag = amp * n as f64 / 2.0;
        let mut half = vec![Complex::new(0.0, 0.0); n / 2 + 1];
        for (i, &k) in bins.iter().enumerate() {
            let phi = match self.phases {
                Phases::Schroeder => {
                    let i1 = (i + 1) as f64;
                    -PI * i1 * (i1 - 1.0) / f as f64
                }
                Phases::Random => rng.random_range(0.0..2.0 * PI),
            };
            half[k] = Complex::from_polar(mag, phi);
        }
        real_ifft(&half, n)
    }

    /// Generates `periods` periods of `period_samples` samples at sample time `ts`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for any field outside its range, a band without lines, or more
    /// than [`MAX_SAMPLES`] samples.
    pub fn generate(&self, ts: f64) -> Result<Excitation> {
        self.validate(ts)?;
        total_samples(
            self.period_samples,
            self.periods,
            "use fewer periods or a shorter period",
        )?;
        let period = self.one_period(ts)?;
        Ok(Excitation {
            values: repeat_period(&period, self.periods),
            ts,
            period_samples: self.period_samples,
            periods: self.periods,
        })
    }

    /// Band (first and last excited line), resolution $f_s/N$, duration, and the level of one
    /// period (RMS equals `rms`; the crest factor depends on phases and grid).
    ///
    /// # Errors
    /// As [`MultisineSpec::generate`].
    pub fn report(&self, ts: f64) -> Result<BandReport> {
        self.validate(ts)?;
        let n_samples = total_samples(
            self.period_samples,
            self.periods,
            "use fewer periods or a shorter period",
        )?;
        let lines = self.lines(ts)?;
        let (rms, peak, crest) = level_stats(&self.one_period(ts)?);
        let first = lines.first().copied().unwrap_or(0.0);
        let last = lines.last().copied().unwrap_or(0.0);
        Ok(BandReport {
            f_min_hz: first,
            f_max_hz: last,
            resolution_hz: 1.0 / (self.period_samples as f64 * ts),
            duration_s: n_samples as f64 * ts,
            n_samples,
            period_samples: self.period_samples,
            periods: self.periods,
            rms,
            peak,
            crest_factor: crest,
        })
    }
}
