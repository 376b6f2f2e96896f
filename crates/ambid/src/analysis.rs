//! The nonparametric FRF pipeline behind `ambid frf`: recorded channels → closed-loop FRFs with
//! variances, coherences and quality measures.

use ambid_core::frf::closed_loop::{from_periodic, Channels, ClosedLoopFrf};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions, PeriodicSpectra};
use ambid_core::frf::quality::{assess, Quality, DEFAULT_BAND};
use ambid_core::lti::StateSpace;
use anyhow::{bail, Context, Result};

/// How the spectra are formed.
#[derive(Debug, Clone, PartialEq)]
pub enum FrfMethod {
    /// Period-synchronous averaging (periodic excitation, integer number of periods).
    Periodic {
        /// Samples per excitation period.
        period_samples: usize,
        /// Leading periods dropped as transient.
        skip_periods: usize,
    },
}

/// Settings of one FRF analysis.
#[derive(Debug, Clone)]
pub struct FrfSettings {
    /// Spectral method.
    pub method: FrfMethod,
    /// Band of the returned FRF and of the quality averages \[Hz\].
    pub band: (f64, f64),
    /// Lines whose excitation amplitude is below this fraction of the largest are not used.
    pub rel_threshold: f64,
    /// Known controller for the indirect estimate (same sample time as the data).
    pub controller: Option<StateSpace>,
}

impl FrfSettings {
    /// Period averaging with `period_samples`, skipping `skip_periods`, over the seed band.
    pub fn periodic(period_samples: usize, skip_periods: usize) -> Self {
        Self {
            method: FrfMethod::Periodic {
                period_samples,
                skip_periods,
            },
            band: DEFAULT_BAND,
            rel_threshold: 1e-6,
            controller: None,
        }
    }
}

/// The result of [`analyze`].
#[derive(Debug, Clone)]
pub struct FrfAnalysis {
    /// Closed-loop FRFs with variances and coherences.
    pub frf: ClosedLoopFrf,
    /// Coherence, variance and (if given a noise record) SNR over the band.
    pub quality: Quality,
    /// Period spectra (periodic method).
    pub spectra: Option<PeriodicSpectra>,
}

/// Runs the FRF analysis on the channels `r`, `u`, `y` sampled at `fs` Hz. `y_noise` (a record
/// without excitation under the same loop) enables the output SNR.
pub fn analyze(
    r: &[f64],
    u: &[f64],
    y: &[f64],
    fs: f64,
    settings: &FrfSettings,
    y_noise: Option<&[f64]>,
) -> Result<FrfAnalysis> {
    let (lo, hi) = settings.band;
    match &settings.method {
        FrfMethod::Periodic {
            period_samples,
            skip_periods,
        } => {
            let mut an = PeriodicAnalyzer::new(*period_samples)?;
            let s = an
                .analyze(
                    &[r, u, y],
                    fs,
                    &PeriodicOptions::new(*period_samples).skip(*skip_periods),
                )
                .context("period-synchronous averaging")?;
            let lines: Vec<usize> = s
                .excited_lines(0, settings.rel_threshold)?
                .into_iter()
                .filter(|&k| (lo..=hi).contains(&s.line_hz(k)))
                .collect();
            if lines.is_empty() {
                bail!(
                    "the excitation has no excited line in {lo}–{hi} Hz (resolution {:.4} Hz); widen the band \
                     or check the excitation and the period length",
                    s.resolution_hz()
                );
            }
            if s.periods() < 2 {
                bail!(
                    "only {} period is left after skipping {skip_periods}: at least 2 are needed for a \
                     variance; record more periods or pass --skip-periods 0",
                    s.periods()
                );
            }
            let frf = from_periodic(
                &s,
                Channels { r: 0, u: 1, y: 2 },
                &lines,
                settings.controller.as_ref(),
            )?;
            let snr = y_noise
                .map(|yn| ambid_core::frf::quality::output_snr_db(y, yn))
                .transpose()?;
            let quality = assess(&frf, settings.band, snr)?;
            Ok(FrfAnalysis {
                frf,
                quality,
                spectra: Some(s),
            })
        }
    }
}
