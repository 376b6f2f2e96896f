//! Swept sines (chirps), linear or logarithmic.
//!
//! # Math
//! Over one period of $T = N T_s$ seconds ($N$ = `duration_s / ts` rounded) the signal is
//! $x(t) = A \sin\varphi(t)$ with instantaneous frequency $f(t) = \varphi'(t)/2\pi$ going from $f_0$
//! at $t = 0$ to $f_1$ at $t = T$:
//! $$ \text{linear:}\quad f(t) = f_0 + (f_1 - f_0)\frac tT,\qquad
//!    \varphi(t) = 2\pi\Big(f_0 t + \frac{(f_1 - f_0)\,t^2}{2T}\Big), $$
//! $$ \text{logarithmic:}\quad f(t) = f_0\, \kappa^{t/T},\quad \kappa = \frac{f_1}{f_0},\qquad
//!    \varphi(t) = \frac{2\pi f_0 T}{\ln\kappa}\big(\kappa^{t/T} - 1\big). $$
//! A linear sweep spends equal time per hertz (flat power spectral density over the band), a
//! logarithmic one equal time per decade (more energy at low frequency, suited to Bode plots over
//! several decades). The signal starts at zero; the crest factor is close to $\sqrt 2$. Periods are
//! repeated verbatim; unless $\varphi(T)$ is a multiple of $2\pi$ the joins are not smooth, so analyse
//! chirp data with the input's own spectrum (e.g. an $H_1$ estimate), not assuming bin-aligned lines.
//!
//! # Example
//! ```
//! use ambid_core::signal::{ChirpSpec, Sweep};
//! // The seed paper's validation chirp: 1–1000 Hz in 10 s (amplitude here in A).
//! let spec = ChirpSpec { f0_hz: 1.0, f1_hz: 1000.0, duration_s: 10.0, amplitude: 0.05,
//!                        sweep: Sweep::Linear, periods: 1 };
//! let x = spec.generate(50e-6).unwrap();
//! assert_eq!(x.len(), 200_000);
//! assert!(x.values.iter().all(|v| v.abs() <= 0.05));
//! assert!((spec.instantaneous_frequency_hz(5.0).unwrap() - 500.5).abs() < 1e-9);
//! ```

use super::{
    check_count, check_positive, check_ts, level_stats, repeat_period, total_samples, BandReport,
    Excitation, MAX_SAMPLES,
};
use crate::error::{Error, Result};
use std::f64::consts::PI;

/// Frequency law of a chirp.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Sweep {
    /// $f(t) = f_0 + (f_1 - f_0) t / T$: equal time per hertz.
    Linear,
    /// $f(t) = f_0 (f_1/f_0)^{t/T}$: equal time per decade; needs $f_0 > 0$.
    Logarithmic,
}

/// A swept sine from `f0_hz` to `f1_hz` in `duration_s`, repeated `periods` times.
///
/// # Requirements
/// `amplitude` finite and $> 0$; `duration_s` finite with at least 2 samples per period;
/// $0 \le f_0, f_1 \le f_s/2$ with $f_0 \ne f_1$ (down-sweeps $f_0 > f_1$ are allowed);
/// logarithmic sweeps need $f_0, f_1 > 0$; `periods` $\ge 1$; at most [`MAX_SAMPLES`] samples.
///
/// # Example
/// ```
/// use ambid_core::signal::{ChirpSpec, Sweep};
/// let spec = ChirpSpec { f0_hz: 10.0, f1_hz: 100.0, duration_s: 1.0, amplitude: 2.0,
///                        sweep: Sweep::Logarithmic, periods: 2 };
/// let r = spec.report(1e-3).unwrap();
/// assert_eq!((r.f_min_hz, r.f_max_hz, r.n_samples), (10.0, 100.0, 2000));
/// assert!((r.peak - 2.0).abs() < 1e-3);
/// ```
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ChirpSpec {
    /// Start frequency $f_0$ in Hz.
    pub f0_hz: f64,
    /// End frequency $f_1$ in Hz.
    pub f1_hz: f64,
    /// Duration of one sweep (one period) $T$ in seconds.
    pub duration_s: f64,
    /// Amplitude $A > 0$ (the peak value).
    pub amplitude: f64,
    /// Frequency law.
    pub sweep: Sweep,
    /// Number of repeated sweeps $\ge 1$.
    pub periods: usize,
}

impl ChirpSpec {
    fn check_duration(&self) -> Result<()> {
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            return Err(Error::invalid(
                "duration_s",
                format!(
                    "must be a finite number of seconds > 0, got {}",
                    self.duration_s
                ),
            ));
        }
        Ok(())
    }

    /// Validates against `ts` and returns the samples per period.
    fn validate(&self, ts: f64) -> Result<usize> {
        check_ts(ts)?;
        check_positive("amplitude", self.amplitude)?;
        check_count("periods", self.periods, 1)?;
        self.check_duration()?;
        let n = (self.duration_s / ts).round();
        if n < 2.0 {
            return Err(Error::invalid(
                "duration_s",
                format!(
                    "{} s is less than two samples of {ts} s; make the sweep longer",
                    self.duration_s
                ),
            ));
        }
        if n > MAX_SAMPLES as f64 {
            return Err(Error::invalid(
                "duration_s",
                format!(
                    "{} s at {ts} s per sample exceeds {MAX_SAMPLES} samples; shorten the sweep \
                     or use a larger sample time",
                    self.duration_s
                ),
            ));
        }
        let nyq = 0.5 / ts;
        for (name, f) in [("f0_hz", self.f0_hz), ("f1_hz", self.f1_hz)] {
            if !(f.is_finite() && (0.0..=nyq).contains(&f)) {
                return Err(Error::invalid(
                    name,
                    format!("must lie in [0, fs/2] = [0, {nyq}] Hz, got {f}"),
                ));
            }
            if self.sweep == Sweep::Logarithmic && f <= 0.0 {
                return Err(Error::invalid(
                    name,
                    "a logarithmic sweep needs frequencies > 0; start at a small positive \
                     frequency or use Sweep::Linear",
                ));
            }
        }
        if self.f0_hz == self.f1_hz {
            return Err(Error::invalid(
                "f1_hz",
                format!(
                    "equals f0_hz = {} Hz, so nothing is swept; choose a different end frequency \
                     or use a MultisineSpec for a single tone",
                    self.f0_hz
                ),
            ));
        }
        Ok(n as usize)
    }

    /// Instantaneous frequency $f(t)$ in Hz at time `t` seconds into a sweep of the nominal
    /// duration `duration_s` (the analytic law; `generate` uses the rounded period $N T_s$).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if `t` is not finite or the spec's frequencies or duration are
    /// unusable (not finite, duration $\le 0$, or a logarithmic sweep through 0 Hz).
    pub fn instantaneous_frequency_hz(&self, t: f64) -> Result<f64> {
        if !t.is_finite() {
            return Err(Error::invalid("t", format!("must be finite, got {t}")));
        }
        self.check_duration()?;
        if !(self.f0_hz.is_finite() && self.f1_hz.is_finite()) {
            return Err(Error::invalid("f0_hz", "frequencies must be finite"));
        }
        let f = instantaneous(self.sweep, self.f0_hz, self.f1_hz, self.duration_s, t);
        if f.is_finite() {
            Ok(f)
        } else {
            Err(Error::invalid(
                "f0_hz",
                "a logarithmic sweep needs frequencies > 0",
            ))
        }
    }

    /// Generates `periods` sweeps of $N = \mathrm{round}(T/T_s)$ samples each at sample time `ts`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for any field outside its range (see the type's requirements).
    pub fn generate(&self, ts: f64) -> Result<Excitation> {
        let n = self.validate(ts)?;
        total_samples(n, self.periods, "shorten the sweep or use fewer periods")?;
        let period = self.one_period(n, ts);
        Ok(Excitation {
            values: repeat_period(&period, self.periods),
            ts,
            period_samples: n,
            periods: self.periods,
        })
    }

    fn one_period(&self, n: usize, ts: f64) -> Vec<f64> {
        let t_per = n as f64 * ts;
        let (f0, f1) = (self.f0_hz, self.f1_hz);
        (0..n)
            .map(|k| {
                let t = k as f64 * ts;
                let phase = match self.sweep {
                    Sweep::Linear => 2.0 * PI * (f0 * t + (f1 - f0) * t * t / (2.0 * t_per)),
                    Sweep::Logarithmic => {
                        let ln_k = (f1 / f0).ln();
                        2.0 * PI * f0 * t_per / ln_k * ((t / t_per * ln_k).exp() - 1.0)
                    }
                };
                self.amplitude * phase.sin()
            })
            .collect()
    }

    /// Band $[\min(f_0,f_1), \max(f_0,f_1)]$, resolution $1/T$ (the line spacing of one period),
    /// duration, and the level of the generated samples.
    ///
    /// # Errors
    /// As [`ChirpSpec::generate`].
    pub fn report(&self, ts: f64) -> Result<BandReport> {
        let n = self.validate(ts)?;
        let n_samples = total_samples(n, self.periods, "shorten the sweep or use fewer periods")?;
        let (rms, peak, crest) = level_stats(&self.one_period(n, ts));
        Ok(BandReport {
            f_min_hz: self.f0_hz.min(self.f1_hz),
            f_max_hz: self.f0_hz.max(self.f1_hz),
            resolution_hz: 1.0 / (n as f64 * ts),
            duration_s: n_samples as f64 * ts,
            n_samples,
            period_samples: n,
            periods: self.periods,
            rms,
            peak,
            crest_factor: crest,
        })
    }
}

fn instantaneous(sweep: Sweep, f0: f64, f1: f64, t_per: f64, t: f64) -> f64 {
    match sweep {
        Sweep::Linear => f0 + (f1 - f0) * t / t_per,
        Sweep::Logarithmic => {
            if f0 > 0.0 && f1 > 0.0 {
                f0 * (f1 / f0).powf(t / t_per)
            } else {
                f64::NAN
            }
        }
    }
}
