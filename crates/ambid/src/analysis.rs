//! The nonparametric FRF pipeline behind `ambid frf`: recorded channels → screening (abnormal
//! samples, saturation) → closed-loop FRFs with variances, coherences and quality measures.

use ambid_core::data::{
    check_saturation, repair_abnormal, AbnormalOptions, AbnormalReport, SaturationOptions,
    SaturationReport,
};
use ambid_core::frf::closed_loop::{from_periodic, from_welch, Channels, ClosedLoopFrf};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions, PeriodicSpectra};
use ambid_core::frf::quality::{assess, output_snr_db, Quality, DEFAULT_BAND};
use ambid_core::frf::welch::{welch_spectra, WelchOptions};
use ambid_core::frf::window::Window;
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
    /// Welch averaging of windowed, overlapping segments (any excitation).
    Welch {
        /// Samples per segment.
        nperseg: usize,
        /// Overlap in samples (default half a segment).
        noverlap: Option<usize>,
        /// Segment window.
        window: Window,
        /// Leading samples dropped as transient.
        skip_samples: usize,
    },
}

/// Settings of one FRF analysis.
#[derive(Debug, Clone)]
pub struct FrfSettings {
    /// Spectral method.
    pub method: FrfMethod,
    /// Band of the returned FRF \[Hz\].
    pub band: (f64, f64),
    /// Band of the quality averages \[Hz\] (default 10–1000 Hz).
    pub quality_band: (f64, f64),
    /// Lines whose excitation amplitude (periodic) or power (Welch) is below this fraction of
    /// the largest are not used.
    pub rel_threshold: f64,
    /// Known controller for the indirect estimate (same sample time as the data).
    pub controller: Option<StateSpace>,
    /// Saturation limit of the controller output and coil current \[A\], if known (otherwise
    /// flat-topped runs are looked for).
    pub i_sat: Option<f64>,
    /// Screen `y` and the controller part `u − r` for NaN/Inf, spikes and stuck runs, and repair
    /// isolated bad samples by interpolation (default on).
    pub screen: bool,
}

impl FrfSettings {
    /// Period averaging with `period_samples`, skipping `skip_periods`; FRF and quality over the
    /// seed band 10–1000 Hz.
    pub fn periodic(period_samples: usize, skip_periods: usize) -> Self {
        Self::with_method(FrfMethod::Periodic {
            period_samples,
            skip_periods,
        })
    }

    /// Welch with a Hann window of `nperseg` samples and 50 % overlap.
    pub fn welch(nperseg: usize) -> Self {
        Self::with_method(FrfMethod::Welch {
            nperseg,
            noverlap: None,
            window: Window::Hann,
            skip_samples: 0,
        })
    }

    fn with_method(method: FrfMethod) -> Self {
        Self {
            method,
            band: DEFAULT_BAND,
            quality_band: DEFAULT_BAND,
            rel_threshold: 1e-6,
            controller: None,
            i_sat: None,
            screen: true,
        }
    }
}

/// The result of [`analyze`].
#[derive(Debug, Clone)]
pub struct FrfAnalysis {
    /// Closed-loop FRFs with variances and coherences.
    pub frf: ClosedLoopFrf,
    /// Coherence, variance and (if given a noise record) SNR over the quality band.
    pub quality: Quality,
    /// Period spectra (periodic method).
    pub spectra: Option<PeriodicSpectra>,
    /// Abnormal-sample screening per channel (`y`, `u − r`), when enabled.
    pub abnormal: Vec<(String, AbnormalReport)>,
    /// Saturation check per channel (`u`, and `i` when given).
    pub saturation: Vec<(String, SaturationReport)>,
    /// Warnings a user must see (saturated data, repaired samples).
    pub warnings: Vec<String>,
}

/// Recorded closed-loop channels (equal lengths).
#[derive(Debug, Clone, Copy)]
pub struct Record<'a> {
    /// Excitation r.
    pub r: &'a [f64],
    /// Controller output u (including r).
    pub u: &'a [f64],
    /// Measured output y.
    pub y: &'a [f64],
    /// Coil current, if recorded (saturation check only).
    pub i: Option<&'a [f64]>,
    /// Sampling frequency \[Hz\].
    pub fs: f64,
}

/// Runs the FRF analysis. `y_noise` (a record without excitation under the same loop) enables
/// the output SNR.
pub fn analyze(
    rec: &Record<'_>,
    settings: &FrfSettings,
    y_noise: Option<&[f64]>,
) -> Result<FrfAnalysis> {
    let n = rec.r.len();
    for (name, x) in [("u", rec.u), ("y", rec.y)]
        .into_iter()
        .chain(rec.i.map(|i| ("i", i)))
    {
        if x.len() != n {
            bail!(
                "channel `{name}` has {} samples but the excitation has {n}; all channels must be \
                 recorded together",
                x.len()
            );
        }
    }
    if !(rec.fs.is_finite() && rec.fs > 0.0) {
        bail!("the sampling frequency must be positive, got {}", rec.fs);
    }
    ambid_core::error::check_finite("r (excitation)", rec.r)?;
    let mut warnings = Vec::new();

    // saturation of the controller output and the coil current
    let mut saturation = Vec::new();
    for (name, x) in [("u", Some(rec.u)), ("i", rec.i)] {
        let Some(x) = x else { continue };
        let rep = check_saturation(x, settings.i_sat, &SaturationOptions::default())
            .with_context(|| format!("saturation check of `{name}`"))?;
        if rep.count > 0 {
            warnings.push(format!(
                "the FRF was computed from saturated data: `{name}` {}",
                rep.summary()
            ));
        }
        saturation.push((name.to_string(), rep));
    }

    // screening: y and the controller part of u (u − r is smooth; r itself is a designed signal)
    let mut abnormal = Vec::new();
    let (u, y) = if settings.screen {
        let opts = AbnormalOptions::default();
        let (y2, ry) = repair_abnormal(rec.y, &opts).context("screening y")?;
        let c: Vec<f64> = rec.u.iter().zip(rec.r).map(|(u, r)| u - r).collect();
        // a clamped u makes u − r flat-topped with jumps: there only non-finite samples are
        // screened, the clamp is reported by the saturation check instead
        let u_saturated = saturation.iter().any(|(n, r)| n == "u" && r.count > 0);
        let copts = if u_saturated {
            AbnormalOptions {
                hampel: None,
                stuck_min_run: None,
                ..AbnormalOptions::default()
            }
        } else {
            opts
        };
        let (c2, rc) = repair_abnormal(&c, &copts).context("screening u − r")?;
        let u2: Vec<f64> = c2.iter().zip(rec.r).map(|(c, r)| c + r).collect();
        for (name, rep) in [("y", &ry), ("u - r", &rc)] {
            if !rep.is_clean() {
                warnings.push(format!("{name}: {}", rep.summary()));
            }
        }
        abnormal.push(("y".to_string(), ry));
        abnormal.push(("u - r".to_string(), rc));
        (u2, y2)
    } else {
        (rec.u.to_vec(), rec.y.to_vec())
    };

    let ch = Channels { r: 0, u: 1, y: 2 };
    let (lo, hi) = settings.band;
    let (frf, spectra) = match &settings.method {
        FrfMethod::Periodic {
            period_samples,
            skip_periods,
        } => {
            let mut an = PeriodicAnalyzer::new(*period_samples)?;
            let s = an
                .analyze(
                    &[rec.r, &u, &y],
                    rec.fs,
                    &PeriodicOptions::new(*period_samples).skip(*skip_periods),
                )
                .context("period-synchronous averaging")?;
            if s.periods() < 2 {
                bail!(
                    "only {} period is left after skipping {skip_periods}: at least 2 are needed for a \
                     variance; record more periods or skip fewer",
                    s.periods()
                );
            }
            let lines: Vec<usize> = s
                .excited_lines(0, settings.rel_threshold)?
                .into_iter()
                .filter(|&k| (lo..=hi).contains(&s.line_hz(k)))
                .collect();
            if lines.is_empty() {
                bail!(
                    "the excitation has no excited line in {lo}–{hi} Hz (resolution {:.4} Hz); widen \
                     the band or check the excitation and the period length",
                    s.resolution_hz()
                );
            }
            let frf = from_periodic(&s, ch, &lines, settings.controller.as_ref())?;
            (frf, Some(s))
        }
        FrfMethod::Welch {
            nperseg,
            noverlap,
            window,
            skip_samples,
        } => {
            if *skip_samples >= n {
                bail!("--skip-samples {skip_samples} drops the whole record of {n} samples");
            }
            let mut opts = WelchOptions::new(rec.fs, *nperseg);
            opts.window = *window;
            if let Some(o) = noverlap {
                opts.noverlap = *o;
            }
            let k0 = *skip_samples;
            let cs = welch_spectra(&[&rec.r[k0..], &u[k0..], &y[k0..]], &opts)
                .context("Welch spectra")?;
            if cs.n_segments() < 2 {
                bail!(
                    "only {} Welch segment fits in the record; at least 2 are needed for a variance: \
                     lower --nperseg",
                    cs.n_segments()
                );
            }
            let frf = from_welch(
                &cs,
                ch,
                settings.band,
                settings.rel_threshold,
                settings.controller.as_ref(),
            )?;
            (frf, None)
        }
    };
    let snr = y_noise.map(|yn| output_snr_db(&y, yn)).transpose()?;
    let quality = assess(&frf, settings.quality_band, snr).context(
        "quality measures (the quality band must overlap the FRF band; see --quality-band)",
    )?;
    Ok(FrfAnalysis {
        frf,
        quality,
        spectra,
        abnormal,
        saturation,
        warnings,
    })
}
