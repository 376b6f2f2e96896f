//! The nonparametric FRF pipeline behind `ambid frf`: recorded channels → screening (abnormal
//! samples, saturation) → closed-loop FRFs with variances, coherences and quality measures.

use crate::error::{Context, Error, Result};
use ambid_core::data::{
    check_saturation, repair_abnormal, AbnormalOptions, AbnormalReport, SaturationOptions,
    SaturationReport,
};
use ambid_core::frf::band::{excitation_bands, BandRule, ExcitationBands};
use ambid_core::frf::closed_loop::{from_periodic, from_welch, Channels, ClosedLoopFrf};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions, PeriodicSpectra};
use ambid_core::frf::quality::{assess, output_snr_db, Quality};
use ambid_core::frf::welch::{welch_spectra, CrossSpectra, WelchOptions};
use ambid_core::frf::window::Window;
use ambid_core::lti::StateSpace;

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

/// The period-averaging options of `settings`' periodic method (strict unless
/// [`FrfSettings::incomplete_tail`]).
pub(crate) fn periodic_options(
    period: usize,
    skip: usize,
    incomplete_tail: bool,
) -> PeriodicOptions {
    let o = PeriodicOptions::new(period).skip(skip);
    if incomplete_tail {
        o.lenient()
    } else {
        o
    }
}

/// Settings of one FRF analysis.
#[derive(Debug, Clone)]
pub struct FrfSettings {
    /// Spectral method.
    pub method: FrfMethod,
    /// Band of the returned FRF \[Hz\]; `None` (default): the excited band derived from the
    /// excitation ([`ambid_core::frf::band`]).
    pub band: Option<(f64, f64)>,
    /// Band of the quality averages \[Hz\]; `None` (default): the derived quality band (the
    /// excitation's half-power band) inside the FRF band.
    pub quality_band: Option<(f64, f64)>,
    /// Thresholds of the derived bands (default: the documented rule).
    pub band_rule: BandRule,
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
    /// Period averaging: ignore an incomplete last period instead of refusing the record
    /// (default off: a given period must divide the record). On when the period was found in
    /// the record ([`ambid_core::signal::PeriodScan`]), whose length need not be a multiple of
    /// it; the ignored samples are reported in the spectra's `dropped_tail`.
    pub incomplete_tail: bool,
}

impl FrfSettings {
    /// Period averaging with `period_samples`, skipping `skip_periods`; FRF and quality bands
    /// derived from the excitation.
    pub fn periodic(period_samples: usize, skip_periods: usize) -> Self {
        Self::with_method(FrfMethod::Periodic {
            period_samples,
            skip_periods,
        })
    }

    /// The default Welch segment for a record of `n` samples, the one rule of `ambid frf` and the
    /// workflow: the largest power of two $\le n/8$ (with 50 % overlap, ≈ 15 averages: the
    /// variance of each spectral estimate falls by ≈ 8 relative to one segment, while the
    /// resolution $f_s/n_\mathrm{seg}$ stays within 8–16 times the record's own), clamped to
    /// 64 … 8192 samples and never above the record. 8192 bounds the FFT work and the memory of
    /// one segment on long records (at 20 kHz: 2.4 Hz lines, 5 lines across a 1 %-damped
    /// 1 kHz mode's half-power band), and gives them more averages rather than more lines.
    ///
    /// # Example
    /// ```
    /// use ambid::analysis::FrfSettings;
    /// assert_eq!(FrfSettings::default_nperseg(102_300), 8192);
    /// assert_eq!(FrfSettings::default_nperseg(20_000), 2048);
    /// assert_eq!(FrfSettings::default_nperseg(300), 64);
    /// assert_eq!(FrfSettings::default_nperseg(40), 40);
    /// ```
    pub fn default_nperseg(n: usize) -> usize {
        let target = (n / 8).clamp(64, 8192);
        (1usize << (usize::BITS - 1 - target.leading_zeros())).min(n)
    }

    /// Period averaging with the period `found` in a record of `n` samples (by
    /// [`PeriodScan`](ambid_core::signal::PeriodScan) on its `r`), skipping `skip_periods`, the
    /// incomplete last period ignored ([`Self::incomplete_tail`]); `None` when nothing was found
    /// or fewer than two whole periods remain after the skipped ones (the fewest that give a
    /// variance). The default estimator of `ambid frf`, the workflow on files and `ambid.frf`
    /// when no period and no Welch option is given; Welch otherwise (docs/frf.md, "Which
    /// estimator").
    ///
    /// # Example
    /// ```
    /// use ambid::analysis::{FrfMethod, FrfSettings};
    /// let s = FrfSettings::found_period(20 * 5115 + 7, Some(5115), 1).unwrap();
    /// assert!(s.incomplete_tail);
    /// assert!(matches!(s.method, FrfMethod::Periodic { period_samples: 5115, skip_periods: 1 }));
    /// assert!(FrfSettings::found_period(2 * 5115, Some(5115), 1).is_none()); // one period left
    /// assert!(FrfSettings::found_period(1000, None, 1).is_none());
    /// ```
    pub fn found_period(n: usize, found: Option<usize>, skip_periods: usize) -> Option<Self> {
        let p = found.filter(|&p| p > 0 && n / p >= skip_periods + 2)?;
        let mut s = Self::periodic(p, skip_periods);
        s.incomplete_tail = true;
        Some(s)
    }

    /// The estimator for a record of `n` samples whose excitation has `period` samples per
    /// period (`None`: not periodic), the one rule of the workflow's FRF step and its studies:
    /// period averaging when at least two periods are recorded, dropping `skip_periods` (at most
    /// all but one); otherwise Welch with `nperseg` samples per segment (`None`:
    /// [`Self::default_nperseg`], never above the record). A noise excitation on the twin is one
    /// "period" as long as the record, so it gets Welch, as `ambid frf` gives it.
    ///
    /// # Example
    /// ```
    /// use ambid::analysis::{FrfMethod, FrfSettings};
    /// let prbs = FrfSettings::for_record(Some(5115), 20 * 5115, 1, None);
    /// assert!(matches!(prbs.method, FrfMethod::Periodic { period_samples: 5115, skip_periods: 1 }));
    /// // two periods: one is kept
    /// let two = FrfSettings::for_record(Some(5115), 2 * 5115, 3, None);
    /// assert!(matches!(two.method, FrfMethod::Periodic { skip_periods: 1, .. }));
    /// let noise = FrfSettings::for_record(Some(102_300), 102_300, 1, None);
    /// assert!(matches!(noise.method, FrfMethod::Welch { nperseg: 8192, .. }));
    /// let short = FrfSettings::for_record(None, 40, 1, Some(64));
    /// assert!(matches!(short.method, FrfMethod::Welch { nperseg: 40, .. }));
    /// ```
    pub fn for_record(
        period: Option<usize>,
        n: usize,
        skip_periods: usize,
        nperseg: Option<usize>,
    ) -> Self {
        match period.filter(|&p| p > 0 && n / p >= 2) {
            Some(p) => Self::periodic(p, skip_periods.min(n / p - 1)),
            None => Self::welch(nperseg.unwrap_or_else(|| Self::default_nperseg(n)).min(n)),
        }
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
            band: None,
            quality_band: None,
            band_rule: BandRule::default(),
            rel_threshold: 1e-6,
            controller: None,
            i_sat: None,
            screen: true,
            incomplete_tail: false,
        }
    }
}

/// Where a band came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BandOrigin {
    /// Given by the user.
    User,
    /// Derived from the excitation by the band rule.
    Excitation,
    /// The FRF band (the derived quality band has no line inside the given FRF band).
    FrfBand,
}

/// The bands an analysis used, and the ones derived from the excitation.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct UsedBands {
    /// Band of the FRF \[Hz\].
    pub band: (f64, f64),
    /// Where it came from.
    pub band_origin: BandOrigin,
    /// Band of the quality averages \[Hz\].
    pub quality_band: (f64, f64),
    /// Where it came from.
    pub quality_origin: BandOrigin,
    /// The bands derived from the excitation (always computed).
    pub derived: ExcitationBands,
}

impl UsedBands {
    /// One line for reports and CLI output: which bands were used and why.
    pub fn describe(&self) -> String {
        let why = |o: BandOrigin| match o {
            BandOrigin::User => "given",
            BandOrigin::Excitation => "derived from the excitation",
            BandOrigin::FrfBand => "the given FRF band",
        };
        format!(
            "FRF band {:.4}–{:.4} Hz ({}), quality band {:.4}–{:.4} Hz ({}); the excitation has {} lines within {} dB of its strongest{} in {:.4}–{:.4} Hz and is within {} dB of it{} in {:.4}–{:.4} Hz",
            self.band.0,
            self.band.1,
            why(self.band_origin),
            self.quality_band.0,
            self.quality_band.1,
            why(self.quality_origin),
            self.derived.excited_lines,
            self.derived.thresholds_db.0,
            self.derived.carried(),
            self.derived.excited.0,
            self.derived.excited.1,
            self.derived.thresholds_db.1,
            if self.derived.carried_lines > 0 {
                " (or on its design slope)"
            } else {
                ""
            },
            self.derived.quality.0,
            self.derived.quality.1,
        )
    }
}

/// The result of [`analyze`].
#[derive(Debug, Clone)]
pub struct FrfAnalysis {
    /// Closed-loop FRFs with variances and coherences.
    pub frf: ClosedLoopFrf,
    /// Coherence, variance and (if given a noise record) SNR over the quality band.
    pub quality: Quality,
    /// The bands used and the ones derived from the excitation.
    pub bands: UsedBands,
    /// Period spectra (periodic method).
    pub spectra: Option<PeriodicSpectra>,
    /// Abnormal-sample screening per channel (`y`, `u − r`), when enabled.
    pub abnormal: Vec<(String, AbnormalReport)>,
    /// Saturation check per channel (`u`, and `i` when given).
    pub saturation: Vec<(String, SaturationReport)>,
    /// Warnings a user must see (saturated data, repaired samples).
    pub warnings: Vec<String>,
}

impl FrfAnalysis {
    /// The plant's noise per line as a function of the plant value, for fits weighted by the
    /// variance at the model (sample maximum likelihood): the estimate's
    /// [`plant_noise`](ambid_core::frf::closed_loop::ClosedLoopFrf::plant_noise) when it
    /// averaged periods, `None` for a Welch estimate.
    ///
    /// The period means and the periods' sample covariances are independent for Gaussian
    /// noise, so weights from the covariances at the model do not follow the error. A Welch
    /// estimate's noise description comes from the same overlapping, windowed segments as its
    /// value: on random twin rigs 1–100 with a noise excitation the SML fits covered the true
    /// error on 95 (linear) and 99 (nonlinear) runs against 98 and 99 with the variance at the
    /// data (docs/uncertainty.md, "Sample maximum likelihood as the default").
    ///
    /// # Example
    /// The seed experiment's record averaged over periods has it, and at the estimate it gives
    /// the reported variance; the same record by Welch's method has none.
    /// ```
    /// use ambid::analysis::{analyze, FrfSettings, Record};
    /// use ambid::experiment::{run, Experiment};
    /// # fn main() -> Result<(), Box<dyn std::error::Error>> {
    /// let mut exp = Experiment::seed_paper(ambid_twin::Mode::Linear, 1e-7, 1);
    /// exp.excitation.periods = 4;
    /// let rec = run(&exp)?.record;
    /// let r = Record { r: &rec.r, u: &rec.u, y: &rec.y, i: None, fs: 1.0 / rec.ts };
    /// let periodic = analyze(&r, &FrfSettings::periodic(5115, 1), None)?;
    /// let noise = periodic.model_weight_noise().ok_or("a periodic estimate has it")?;
    /// let var = periodic.frf.plant.variance().ok_or("variances")?;
    /// for ((n, g), v) in noise.iter().zip(periodic.frf.plant.values()).zip(var) {
    ///     assert!((n.variance_at(*g) - v).abs() <= 1e-9 * v);
    /// }
    /// let welch = analyze(&r, &FrfSettings::welch(4096), None)?;
    /// assert!(welch.model_weight_noise().is_none());
    /// # Ok(())
    /// # }
    /// ```
    pub fn model_weight_noise(&self) -> Option<&[ambid_core::frf::closed_loop::RatioNoise]> {
        self.spectra.as_ref()?;
        self.frf.plant_noise.as_deref()
    }
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

/// The shortest record [`analyze`] accepts: the shortest Welch segment of the workflow's
/// default segment rule (`n/8` clamped to 64 … 8192 samples).
pub const MIN_FRF_SAMPLES: usize = 64;

/// Refuses a record of fewer than [`MIN_FRF_SAMPLES`] samples (an input-data error naming
/// `source`, the file, when known): one check and one message for the in-memory FRF, the
/// streamed one and the workflow.
///
/// # Errors
/// The record is too short.
pub fn check_frf_length(n: usize, source: Option<&str>) -> Result<()> {
    if n < MIN_FRF_SAMPLES {
        let prefix = source.map_or(String::new(), |s| format!("{s}: "));
        return Err(Error::input(format!(
            "{prefix}{n} samples are too few for an FRF: at least {MIN_FRF_SAMPLES} are needed (the shortest Welch segment the defaults use); give a longer record"
        )));
    }
    Ok(())
}

/// Refuses a sample rate given with `--fs` that disagrees (beyond 10⁻⁶ relative) with the one
/// of the file's `t` column (sample time `ts`): a usage error.
///
/// # Errors
/// The two rates disagree.
pub fn check_fs_matches(fs: Option<f64>, ts: f64) -> Result<()> {
    if let Some(fs) = fs {
        let file_fs = 1.0 / ts;
        if ((file_fs - fs) / fs).abs() > 1e-6 {
            return Err(Error::usage(format!(
                "--fs {fs:e} Hz disagrees with the file's `t` column ({file_fs:e} Hz)"
            )));
        }
    }
    Ok(())
}

/// The Welch options of a [`FrfMethod::Welch`] `method` for a record of `n` samples at `fs` Hz
/// (the in-memory and the streamed analysis alike).
///
/// # Errors
/// A `skip_samples` that drops the whole record; another method.
pub(crate) fn welch_options(method: &FrfMethod, fs: f64, n: usize) -> Result<WelchOptions> {
    let FrfMethod::Welch {
        nperseg,
        noverlap,
        window,
        skip_samples,
    } = method
    else {
        return Err(Error::other(
            "Welch options asked for a period-averaging analysis",
        ));
    };
    if *skip_samples >= n {
        return Err(Error::other(format!(
            "--skip-samples {skip_samples} drops the whole record of {n} samples"
        )));
    }
    let mut opts = WelchOptions::new(fs, *nperseg);
    opts.window = *window;
    if let Some(o) = noverlap {
        opts.noverlap = *o;
    }
    Ok(opts)
}

/// Screens `y` and the controller part `u − r` of a block (module docs of the screening: `u − r`
/// is smooth, `r` a designed signal) and returns the repaired `u`, `y` and the two reports
/// (`u − r`, `y`). With `u_saturated` (a clamped `u` makes `u − r` flat-topped with jumps) only
/// non-finite samples of `u − r` are screened; the clamp is the saturation check's to report.
///
/// # Errors
/// The screening's errors, naming the channel.
pub(crate) fn screen_channels(
    r: &[f64],
    u: &[f64],
    y: &[f64],
    u_saturated: bool,
) -> Result<(Vec<f64>, Vec<f64>, AbnormalReport, AbnormalReport)> {
    let opts = AbnormalOptions::default();
    let c: Vec<f64> = u.iter().zip(r).map(|(u, r)| u - r).collect();
    let copts = if u_saturated {
        AbnormalOptions {
            hampel: None,
            stuck_min_run: None,
            ..AbnormalOptions::default()
        }
    } else {
        opts
    };
    // the two channels are screened independently (the Hampel filter is most of an analysis's
    // time): in parallel; the errors are reported in the same order (y first)
    let (y_screened, c_screened) =
        rayon::join(|| repair_abnormal(y, &opts), || repair_abnormal(&c, &copts));
    let (y2, ry) = y_screened.context("screening y")?;
    let (c2, rc) = c_screened.context("screening u − r")?;
    let u2: Vec<f64> = c2.iter().zip(r).map(|(c, r)| c + r).collect();
    Ok((u2, y2, rc, ry))
}

/// Runs the FRF analysis. `y_noise` (a record without excitation under the same loop) enables
/// the output SNR.
pub fn analyze(
    rec: &Record<'_>,
    settings: &FrfSettings,
    y_noise: Option<&[f64]>,
) -> Result<FrfAnalysis> {
    let n = rec.r.len();
    check_frf_length(n, None)?;
    for (name, x) in [("u", rec.u), ("y", rec.y)]
        .into_iter()
        .chain(rec.i.map(|i| ("i", i)))
    {
        if x.len() != n {
            return Err(Error::input(format!(
                "channel `{name}` has {} samples but the excitation has {n}; all channels must be \
                 recorded together",
                x.len()
            )));
        }
    }
    if !(rec.fs.is_finite() && rec.fs > 0.0) {
        return Err(Error::other(format!(
            "the sampling frequency must be positive, got {}",
            rec.fs
        )));
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
        let u_saturated = saturation.iter().any(|(n, r)| n == "u" && r.count > 0);
        let (u2, y2, rc, ry) = screen_channels(rec.r, rec.u, rec.y, u_saturated)?;
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

    let spectra = match &settings.method {
        FrfMethod::Periodic {
            period_samples,
            skip_periods,
        } => {
            let mut an = PeriodicAnalyzer::new(*period_samples)?;
            let s = an
                .analyze(
                    &[rec.r, &u, &y],
                    rec.fs,
                    &periodic_options(*period_samples, *skip_periods, settings.incomplete_tail),
                )
                .context("period-synchronous averaging")?;
            Spectra::Periodic(s)
        }
        FrfMethod::Welch { skip_samples, .. } => {
            let opts = welch_options(&settings.method, rec.fs, n)?;
            let k0 = *skip_samples;
            let cs = welch_spectra(&[&rec.r[k0..], &u[k0..], &y[k0..]], &opts)
                .context("Welch spectra")?;
            Spectra::Welch(cs)
        }
    };
    let snr = y_noise.map(|yn| output_snr_db(&y, yn)).transpose()?;
    analyze_spectra(
        spectra,
        settings,
        Checks {
            snr,
            abnormal,
            saturation,
            warnings,
        },
    )
}

/// Spectra of the record `(r, u, y)` (channels 0, 1, 2), computed by [`analyze`] or by a caller
/// that streams the record (`ambid frf`).
#[derive(Debug, Clone)]
pub enum Spectra {
    /// Period-synchronous averages ([`FrfMethod::Periodic`]).
    Periodic(PeriodicSpectra),
    /// Welch cross spectra ([`FrfMethod::Welch`]).
    Welch(CrossSpectra),
}

/// What the checks of the samples found, for [`analyze_spectra`].
#[derive(Debug, Clone, Default)]
pub struct Checks {
    /// Output SNR \[dB\] from a noise record, if one was given.
    pub snr: Option<f64>,
    /// Abnormal-sample screening per channel.
    pub abnormal: Vec<(String, AbnormalReport)>,
    /// Saturation check per channel.
    pub saturation: Vec<(String, SaturationReport)>,
    /// Warnings so far.
    pub warnings: Vec<String>,
}

/// The second half of [`analyze`]: bands, closed-loop FRFs (with the indirect estimate and the
/// controller check when `settings.controller` is given) and quality from the spectra of
/// `(r, u, y)` as channels 0, 1, 2 (the method in `settings` must be the one the spectra were
/// computed by).
///
/// # Errors
/// Fewer than 2 periods or Welch segments; no excited line in the band; the errors of the
/// FRF and quality computations.
pub fn analyze_spectra(
    spectra: Spectra,
    settings: &FrfSettings,
    checks: Checks,
) -> Result<FrfAnalysis> {
    let Checks {
        snr,
        abnormal,
        saturation,
        mut warnings,
    } = checks;
    let ch = Channels { r: 0, u: 1, y: 2 };
    let pick = |derived: ExcitationBands| -> (f64, f64, BandOrigin) {
        match settings.band {
            Some((a, b)) => (a, b, BandOrigin::User),
            None => (derived.excited.0, derived.excited.1, BandOrigin::Excitation),
        }
    };
    let (frf, spectra, derived, band_origin) = match spectra {
        Spectra::Periodic(s) => {
            let skip_periods = s.skipped_periods();
            let f_lines: Vec<f64> = (0..s.n_lines()).map(|k| s.line_hz(k)).collect();
            let power: Vec<f64> = s.mean(0).iter().map(|v| v.norm_sqr()).collect();
            let derived = excitation_bands(&f_lines, &power, 1, &settings.band_rule)
                .context("the band of the excitation")?;
            let (lo, hi, origin) = pick(derived);
            if s.periods() < 2 {
                return Err(Error::other(format!(
                    "only {} period is left after skipping {skip_periods}: at least 2 are needed for a \
                     variance; record more periods or skip fewer",
                    s.periods()
                )));
            }
            let lines: Vec<usize> = s
                .excited_lines(0, settings.rel_threshold)?
                .into_iter()
                .filter(|&k| (lo..=hi).contains(&s.line_hz(k)))
                .collect();
            if lines.is_empty() {
                return Err(Error::other(format!(
                    "the excitation has no excited line in {lo}–{hi} Hz (resolution {:.4} Hz); widen \
                     the band or check the excitation and the period length",
                    s.resolution_hz()
                )));
            }
            let frf = from_periodic(&s, ch, &lines, settings.controller.as_ref())?;
            (frf, Some(s), derived, origin)
        }
        Spectra::Welch(cs) => {
            if cs.n_segments() < 2 {
                return Err(Error::other(format!(
                    "only {} Welch segment fits in the record; at least 2 are needed for a variance: \
                     lower --nperseg",
                    cs.n_segments()
                )));
            }
            let derived = excitation_bands(
                cs.f_hz(),
                &cs.psd(0)?,
                2.min(cs.f_hz().len() - 1),
                &settings.band_rule,
            )
            .context("the band of the excitation")?;
            let (lo, hi, origin) = pick(derived);
            let frf = from_welch(
                &cs,
                ch,
                (lo, hi),
                settings.rel_threshold,
                settings.controller.as_ref(),
            )?;
            (frf, None, derived, origin)
        }
    };
    let f = frf.f_hz();
    let band = match settings.band {
        Some(b) => b,
        None => derived.excited,
    };
    let (quality_band, quality_origin) = match settings.quality_band {
        Some(q) => (q, BandOrigin::User),
        None => {
            // the derived quality band inside the FRF band, on the FRF's lines
            let (a, b) = (derived.quality.0.max(band.0), derived.quality.1.min(band.1));
            if a < b && f.iter().any(|x| (a..=b).contains(x)) {
                ((a, b), BandOrigin::Excitation)
            } else {
                (band, BandOrigin::FrfBand)
            }
        }
    };
    if let Some(c) = &settings.controller {
        if let Some(w) = controller_mismatch(&frf, c, quality_band)? {
            warnings.push(w);
        }
    }
    let quality = assess(&frf, quality_band, snr).context(
        "quality measures (the quality band must overlap the FRF band; see --quality-band)",
    )?;
    Ok(FrfAnalysis {
        frf,
        quality,
        bands: UsedBands {
            band,
            band_origin,
            quality_band,
            quality_origin,
            derived,
        },
        spectra,
        abnormal,
        saturation,
        warnings,
    })
}

/// Relative controller mismatch above which [`controller_mismatch`] warns (on top of three
/// times the noise of the data's controller estimate).
pub const CONTROLLER_MISMATCH_TOL: f64 = 0.05;

/// Checks that a given controller `c` is the one the data were measured with, before its
/// indirect estimate is trusted. On the lines of `band`, compares the file's
/// $C(e^{j\omega T_s})$ with the controller measured in the loop,
/// $\hat C = (r - u)/y$ ([`ClosedLoopFrf::controller`], valid with $w = 0$):
/// $d_k = |C_k - \hat C_k| / |\hat C_k|$ and its noise $\sigma_k / |\hat C_k|$. The
/// controller does not match when the median of $d_k$ exceeds three times the median relative
/// noise plus [`CONTROLLER_MISMATCH_TOL`] (5 %: a 5 % controller error already biases the
/// indirect plant by about as much near crossover). A controller that does not match was not
/// running when the data were measured, so nothing says it stabilises the measured plant; the
/// joint estimate $P = T_{ry}/T_{ru}$ needs no controller model and is the one to trust.
/// Returns the warning, or `None` when the controller matches (or no line of `band` has a
/// usable estimate).
///
/// # Errors
/// The controller's frequency response (a frequency on one of its poles).
pub fn controller_mismatch(
    frf: &ClosedLoopFrf,
    c: &StateSpace,
    band: (f64, f64),
) -> Result<Option<String>> {
    let f = frf.f_hz();
    let idx: Vec<usize> = (0..f.len())
        .filter(|&k| f[k] >= band.0 && f[k] <= band.1)
        .collect();
    let fk: Vec<f64> = idx.iter().map(|&k| f[k]).collect();
    let cf = c.freq_response_siso(&fk)?;
    let data = frf.controller.values();
    let var = frf.controller.variance();
    let mut d = Vec::new();
    let mut s = Vec::new();
    for (j, &k) in idx.iter().enumerate() {
        let m = data[k].norm();
        let dk = (cf[j] - data[k]).norm() / m;
        if m > 0.0 && dk.is_finite() {
            d.push(dk);
            s.push(var.map_or(0.0, |v| v[k].max(0.0).sqrt() / m));
        }
    }
    if d.is_empty() {
        return Ok(None);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (md, ms) = (median(&mut d), median(&mut s));
    let limit = 3.0 * ms + CONTROLLER_MISMATCH_TOL;
    if md <= limit {
        return Ok(None);
    }
    Ok(Some(format!(
        "the controller given does not match the controller the data were measured with: \
         |C - C_data|/|C_data| has median {:.1} % on {} lines in {:.1}-{:.1} Hz (noise allows \
         {:.1} %), where C_data = (r - u)/y from the record. Its indirect estimate \
         (plant_indirect) is biased and this controller may not even stabilise the measured \
         plant: trust the joint estimate P = T_ry/T_ru (column plant), which needs no \
         controller model, or give the controller that ran during the measurement",
        100.0 * md,
        d.len(),
        band.0,
        band.1,
        100.0 * limit
    )))
}
