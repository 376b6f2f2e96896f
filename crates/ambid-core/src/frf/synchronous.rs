//! The speed-synchronous (1×) line of a record: its complex amplitude on every `u` and `y`
//! channel, with a standard deviation, reported beside the FRF and never fitted into it.
//!
//! Every record of a spinning rotor carries a line at the rotation frequency
//! $f_\mathrm{sync} = \Omega/2\pi$ (unbalance, runout). It is not a response to the
//! excitation: a periodic FRF estimator uses only the lines of the excitation period, so the
//! 1× line must be either off those lines or on an unexcited one (see *Where the 1× line falls*).
//! This module measures it so that it is reported, not absorbed.
//!
//! # Model and estimate
//! Per experiment and channel $x$, with $N$ samples per excitation period, the first
//! `skip_periods` periods dropped and $L = P N$ samples $x_t$ left ($t$ counted from the
//! **start of the experiment**, so the phase refers to its sample 0),
//!
//! $$x_t = p_{t \bmod N} + a\cos(\Omega t T_s) + b\sin(\Omega t T_s) + v_t
//!   = p_{t \bmod N} + \operatorname{Re}\!\big(A\,e^{j\Omega t T_s}\big) + v_t,
//!   \qquad A = a - j b,$$
//!
//! with $p$ the periodic response to the excitation ($N$ free values) and $v$ noise. Removing
//! the period mean, $\tilde x_t = x_t - \frac1P\sum_{q} x_{(t \bmod N) + qN}$, projects out $p$
//! (Frisch–Waugh); the same projection of the regressors $c_t = \cos\Omega tT_s$,
//! $s_t = \sin\Omega tT_s$ gives $\tilde X = [\tilde c, \tilde s]$ and the least-squares estimate
//!
//! $$\hat\theta = (\hat a, \hat b)^{\mathsf T} = G^{-1}\tilde X^{\mathsf T}\tilde x,
//!   \qquad G = \tilde X^{\mathsf T}\tilde X .$$
//!
//! Without a period length only the mean is removed ($N = L$, $P = 1$).
//!
//! # Variance
//! The noise of a closed loop is coloured, but the regressors' energy sits at $f_\mathrm{sync}$,
//! so the noise is taken as locally white with the density of the residual
//! $\varepsilon = \tilde x - \tilde X\hat\theta$ near $f_\mathrm{sync}$: with the length-$L$ DFT
//! $E(k) = \sum_t \varepsilon_t e^{-j2\pi kt/L}$,
//!
//! $$\hat\sigma^2_\mathrm{loc} = \frac{1}{L\,|\mathcal K|}\sum_{k\in\mathcal K}|E(k)|^2,\qquad
//!   \operatorname{Cov}\hat\theta = \hat\sigma^2_\mathrm{loc}\,G^{-1},\qquad
//!   \sigma_A^2 = \mathrm E|\hat A - A|^2 = \hat\sigma^2_\mathrm{loc}\,\big(G^{-1}_{11} + G^{-1}_{22}\big),$$
//!
//! where $\mathcal K$ are the [`SynchronousOptions::noise_bins`] bins nearest to
//! $f_\mathrm{sync} L T_s$ that are neither period lines ($k \equiv 0 \bmod P$, zeroed by the
//! projection) nor within 1.5 bins of $f_\mathrm{sync}$. For white noise of variance $\sigma^2$
//! and many cycles $G \approx \frac L2 I$, so $\sigma_A^2 \approx 4\sigma^2/L$. The estimate has
//! $|\mathcal K|$ complex degrees of freedom ([`SynchronousLine::dof`]).
//!
//! # Where the 1× line falls
//! Let $\delta$ be the distance of $f_\mathrm{sync}$ from the nearest line of the period grid,
//! in lines ([`SynchronousLine::grid_offset`]).
//! * **Off the grid** ($\delta \ne 0$): the regression above. The projection removes the part of
//!   the sinusoid that repeats over the periods, so $G$ shrinks as $\delta \to 0$
//!   (for $|\delta| P \lesssim 1$ the record cannot tell the 1× line from the periodic
//!   response) and the reported $\sigma_A$ grows accordingly — the estimate stays unbiased and
//!   its uncertainty honest. Conversely the 1× line leaks into the period-averaged spectrum
//!   (and so into an FRF) only through its period mean, of relative size
//!   $|\sin(\pi\delta P)/(P\sin\pi\delta)|$, which is **zero** for $\delta = \tfrac12$ and an
//!   even number of periods $P$.
//! * **On a period line** $m$ ($|\delta| \le 10^{-6}$): the sinusoid is periodic and cannot be
//!   separated from the periodic response by regression. If no excitation channel excites line
//!   $m$ (relative threshold [`SynchronousOptions::rel_threshold`], as
//!   [`MimoOptions::rel_threshold`](super::mimo::MimoOptions::rel_threshold)), the period-mean
//!   DFT at $m$ is the 1× line alone: $\hat A = 2\bar X(m)/N$ with
//!   $\sigma_A^2 = 4\,s^2_m/(P N^2)$ from the spread $s_m^2$ of the per-period DFTs
//!   ([`SynchronousMethod::PeriodLine`], $P-1$ degrees of freedom). If the line **is excited**
//!   the 1× line and the excitation response are inseparable there: a typed error says so
//!   (leave that line unexcited, e.g. an odd-line multisine with the 1× line on an even line,
//!   or change the period).
//!
//! # What the removal leaves
//! [`SynchronousLine::remove`] subtracts $\operatorname{Re}(\hat A e^{j\Omega t T_s})$; the
//! residual $\operatorname{Re}((A - \hat A) e^{j\Omega t T_s})$ stays, and its period mean
//! reaches the excited lines. Off the grid the regression uses only the part of the sinusoid
//! that does not repeat over the periods, a fraction $1 - \lambda^2$ of its energy with
//! $\lambda = |\sin(\pi\delta P)/(P\sin\pi\delta)|$, so $\sigma_A^2 \approx 4\sigma^2/(L(1 -
//! \lambda^2))$, and the residual reaches line $k$ of the period mean with the weight $\lambda
//! D_k$ ($D_k$ the Dirichlet kernel of the period at the distance $d_k$ of the line from
//! $f_\mathrm{sync}$, in lines). The residual is the same in every period, so the spread of the
//! periods, from which an FRF's variance comes, does not show it: that line's error variance is
//! $1 + \lambda^2D_k^2/(1-\lambda^2)$ times the one the spread gives
//! ([`SynchronousLine::variance_factor`]). Measured on random machine rig 28 of the 4-axis twin
//! (linear, 11 732 rpm, $\delta = 0.008$, $P = 11$): the factor is 40 at the line 0.03 Hz from
//! the 1× frequency, where the FRF's error against the exact plant was 148 times its variance
//! (the largest of the 16 entries; 3.2 is that largest-of-16's median over the lines); on rigs
//! 1, 2 and 13 ($|\delta| \ge 0.19$) no line stood out.
//!
//! # Example
//! ```
//! use ambid_core::data::IoData;
//! use ambid_core::frf::synchronous::{synchronous, SynchronousOptions};
//! use std::f64::consts::PI;
//! // a periodic "response" (period 16) plus a 1× line of amplitude 0.3∠40° at 7.3 Hz (fs = 100 Hz)
//! let (n, periods, fs, f1) = (16, 12, 100.0, 7.3);
//! let a = 0.3 * (40f64.to_radians()).cos();
//! let b = -0.3 * (40f64.to_radians()).sin();
//! let y: Vec<f64> = (0..n * periods)
//!     .map(|t| {
//!         let w = 2.0 * PI * f1 * t as f64 / fs;
//!         (2.0 * PI * (t % n) as f64 / n as f64).sin() + a * w.cos() + b * w.sin()
//!     })
//!     .collect();
//! let r: Vec<f64> = (0..n * periods).map(|t| (2.0 * PI * (t % n) as f64 / n as f64).sin()).collect();
//! let data = IoData::new(
//!     vec![("r".into(), r.clone()), ("u".into(), r), ("y".into(), y)], 1.0 / fs, Some(n),
//! ).unwrap();
//! let line = synchronous(&data, f1, &SynchronousOptions::new()).unwrap();
//! let yline = line.channels.iter().find(|c| c.name == "y").unwrap();
//! assert!((yline.amplitude.norm() - 0.3).abs() < 1e-9);
//! assert!((yline.amplitude.arg().to_degrees() - 40.0).abs() < 1e-6);
//! ```

use super::mimo::MimoClosedLoopFrf;
use super::periodic::{PeriodicAnalyzer, PeriodicOptions};
use crate::data::{IoData, Role};
use crate::error::{Error, Result};
use crate::lti::Frd;
use faer::c64;
use std::f64::consts::PI;

/// Settings of [`synchronous`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynchronousOptions {
    /// Samples per excitation period; `None` takes the record's ([`IoData::period_samples`]);
    /// without either only the mean is removed.
    pub period_samples: Option<usize>,
    /// Leading periods of every experiment dropped as transient.
    pub skip_periods: usize,
    /// Residual DFT bins near $f_\mathrm{sync}$ that estimate the local noise density (≥ 2).
    pub noise_bins: usize,
    /// A period line counts as excited when some excitation channel's $|\bar R|$ there exceeds
    /// this fraction of that channel's largest line (on-grid case only); in $[0, 1)$.
    pub rel_threshold: f64,
}

impl Default for SynchronousOptions {
    fn default() -> Self {
        Self::new()
    }
}

impl SynchronousOptions {
    /// The record's period, no skipped period, 40 noise bins, threshold $10^{-6}$.
    pub fn new() -> Self {
        Self {
            period_samples: None,
            skip_periods: 0,
            noise_bins: 40,
            rel_threshold: 1e-6,
        }
    }

    /// Sets the period length in samples (overrides the record's).
    pub fn period(mut self, samples: usize) -> Self {
        self.period_samples = Some(samples);
        self
    }

    /// Sets the number of leading (transient) periods dropped in every experiment.
    pub fn skip(mut self, periods: usize) -> Self {
        self.skip_periods = periods;
        self
    }
}

/// How the 1× amplitude was obtained (module docs, *Where the 1× line falls*).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SynchronousMethod {
    /// Least-squares cos/sin fit after removing the period mean (off the period grid).
    Regression,
    /// The period-mean DFT at the unexcited period line `line` (on the grid).
    PeriodLine {
        /// The period line $m$ ($f = m f_s / N$).
        line: usize,
    },
}

/// The 1× line on one channel of one experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct SynchronousChannel {
    /// Channel name (e.g. `y_xa`).
    pub name: String,
    /// Its role ([`Role::Input`] or [`Role::Output`]).
    pub role: Role,
    /// Experiment index.
    pub experiment: usize,
    /// Complex amplitude $A$: $x_t \approx \operatorname{Re}(A e^{j\Omega t T_s})$, $t$ from the
    /// experiment's sample 0 (channel units).
    pub amplitude: c64,
    /// Standard deviation $\sigma_A = \sqrt{\mathrm E|\hat A - A|^2}$.
    pub std: f64,
}

/// The synchronous line of a record: every `u` and `y` channel of every experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct SynchronousLine {
    /// The synchronous frequency \[Hz\].
    pub f_sync_hz: f64,
    /// $f_\mathrm{sync}$ in lines of the period grid, minus the nearest line: $\delta$ in
    /// $[-\tfrac12, \tfrac12]$ (0 without a period length).
    pub grid_offset: f64,
    /// How the amplitudes were obtained.
    pub method: SynchronousMethod,
    /// Per channel: the inputs then the outputs, experiment after experiment.
    pub channels: Vec<SynchronousChannel>,
    /// Periods used per experiment (of the last one if they differ; 1 without a period length).
    pub periods: usize,
    /// Complex degrees of freedom of the variances.
    pub dof: f64,
}

impl SynchronousLine {
    /// `frd`, a period-averaged FRF of the record the line was removed from, with its variances
    /// multiplied by [`SynchronousLine::variance_factor`] on its lines (unchanged without
    /// variances).
    ///
    /// # Errors
    /// None in practice: the FRF is rebuilt from its own lines and values.
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::synchronous::{SynchronousLine, SynchronousMethod};
    /// use ambid_core::lti::Frd;
    /// let (fs, n) = (20_000.0, 5115);
    /// let df = fs / n as f64;
    /// let line = SynchronousLine {
    ///     f_sync_hz: 50.008 * df,
    ///     grid_offset: 0.008,
    ///     method: SynchronousMethod::Regression,
    ///     channels: vec![],
    ///     periods: 11,
    ///     dof: 8.0,
    /// };
    /// let frd = Frd::constant(&[49.0 * df, 50.0 * df], 2.0, Some(1.0 / fs)).unwrap();
    /// let frd = Frd::new(frd.f_hz().to_vec(), frd.values().to_vec(), Some(vec![1e-4; 2]), frd.ts()).unwrap();
    /// let w = line.widen(&frd, fs, n).unwrap();
    /// let k = line.variance_factor(frd.f_hz(), fs, n);
    /// assert_eq!(w.variance().unwrap(), &[1e-4 * k[0], 1e-4 * k[1]]);
    /// assert_eq!(w.values(), frd.values());
    /// ```
    pub fn widen(&self, frd: &Frd, fs: f64, period: usize) -> Result<Frd> {
        let Some(var) = frd.variance() else {
            return Ok(frd.clone());
        };
        let factor = self.variance_factor(frd.f_hz(), fs, period);
        let e = frd.ny() * frd.nu();
        let var: Vec<f64> = var
            .iter()
            .enumerate()
            .map(|(i, v)| v * factor[i / e])
            .collect();
        Frd::new_matrix(
            frd.f_hz().to_vec(),
            frd.ny(),
            frd.nu(),
            frd.values().to_vec(),
            Some(var),
            frd.ts(),
        )
    }

    /// [`SynchronousLine::widen`] on every FRF of a period-averaged closed-loop estimate of the
    /// record the line was removed from: the plant, $T_{ry}$, $S$ and the indirect plant.
    ///
    /// # Errors
    /// None in practice (see [`SynchronousLine::widen`]).
    pub fn widen_estimate(
        &self,
        est: &mut MimoClosedLoopFrf,
        fs: f64,
        period: usize,
    ) -> Result<()> {
        est.plant = self.widen(&est.plant, fs, period)?;
        est.t_ry = self.widen(&est.t_ry, fs, period)?;
        est.s = self.widen(&est.s, fs, period)?;
        if let Some(p) = &est.plant_indirect {
            est.plant_indirect = Some(self.widen(p, fs, period)?);
        }
        Ok(())
    }

    /// The factor by which [`SynchronousLine::remove`] leaves the noise variance of the
    /// period-averaged spectrum raised at each of the lines `f_hz` (module docs, "What the
    /// removal leaves"), for a record of `fs` Hz with `period` samples per period: $1 + r_k$,
    /// $$ r_k = \frac{\lambda^2 D_k^2}{1 - \lambda^2}, \qquad
    ///    \lambda = \left|\frac{\sin \pi\delta P}{P \sin \pi\delta}\right|, \qquad
    ///    D_k = \left|\frac{\sin \pi d_k}{N \sin(\pi d_k / N)}\right|, \quad
    ///    d_k = (f_\mathrm{sync} - f_k)\,N / f_s $$
    /// ($D_k = 1$ at $d_k = 0$). The estimate $\hat A$ has the variance $4\sigma^2/(L(1 -
    /// \lambda^2))$ (the regression sees only the part of the sinusoid that does not repeat
    /// over the periods), and the residual $A - \hat A$ left in the record reaches line $k$ of
    /// the period mean with the weight $\lambda D_k$, against the line's own noise variance
    /// $4\sigma^2/L$ (the noise taken as locally white, as for [`SynchronousChannel::std`]).
    /// The residual is the same in every period, so the spread of the periods that an FRF's
    /// variance comes from does not show it: multiply the FRF's variances by this factor. It
    /// matters only at the line nearest the 1× frequency when $|\delta| P \lesssim 1$ (at
    /// $\delta = 0.008$, $P = 11$: 40). Without a period length, or with the 1× line on an
    /// unexcited period line ([`SynchronousMethod::PeriodLine`], removed exactly), every factor
    /// is 1.
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::synchronous::{SynchronousLine, SynchronousMethod};
    /// // 1× at 0.008 lines above line 50 of a 5115-sample period at 20 kHz, 11 periods
    /// let (fs, n) = (20_000.0, 5115);
    /// let df = fs / n as f64;
    /// let line = SynchronousLine {
    ///     f_sync_hz: (50.0 + 0.008) * df,
    ///     grid_offset: 0.008,
    ///     method: SynchronousMethod::Regression,
    ///     channels: vec![],
    ///     periods: 11,
    ///     dof: 8.0,
    /// };
    /// let k = line.variance_factor(&[49.0 * df, 50.0 * df, 51.0 * df], fs, n);
    /// assert!(k[1] > 35.0 && k[1] < 45.0); // the line beside the 1× frequency
    /// assert!(k[0] < 1.01 && k[2] < 1.01); // its neighbours
    /// ```
    pub fn variance_factor(&self, f_hz: &[f64], fs: f64, period: usize) -> Vec<f64> {
        use std::f64::consts::PI;
        let p = self.periods as f64;
        let delta = self.grid_offset;
        if self.method != SynchronousMethod::Regression
            || self.periods < 2
            || period == 0
            || delta == 0.0
        {
            return vec![1.0; f_hz.len()];
        }
        let lam = ((PI * delta * p).sin() / (p * (PI * delta).sin())).abs();
        let g = (1.0 - lam * lam).max(1e-12);
        let n = period as f64;
        f_hz.iter()
            .map(|&f| {
                let d = (self.f_sync_hz - f) * n / fs;
                let dk = if d.abs() < 1e-12 {
                    1.0
                } else {
                    ((PI * d).sin() / (n * (PI * d / n).sin())).abs()
                };
                1.0 + lam * lam * dk * dk / g
            })
            .collect()
    }

    /// `data` with the measured 1× line taken out of every `u` and `y` channel it was measured
    /// on: $x_t \leftarrow x_t - \operatorname{Re}(\hat A e^{j\Omega t T_s})$ for every sample
    /// $t$ of each experiment (skipped periods included; $t$ from the experiment's sample 0, as
    /// the amplitudes are defined). `r` (and other roles) are left alone.
    ///
    /// This is how the 1× line is *reported, not fitted*: an off-grid 1× line leaks into the
    /// period means with the weight $|\sin(\pi\delta P)/(P\sin\pi\delta)|$ and so biases
    /// every excited line near it; after `remove` the periodic estimators see only the
    /// excitation's response and the noise (the regression is exact for a steady sinusoid, by
    /// Frisch–Waugh). The standard deviation of $\hat A$ stays in the record as a sinusoid of that
    /// size, far below the noise on every other line.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `data` is not the record the line was measured on (a
    /// channel or experiment missing).
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// use ambid_core::frf::synchronous::{synchronous, SynchronousOptions};
    /// use std::f64::consts::PI;
    /// // a periodic response (period 16) plus a 1× line at 7.3 Hz (fs = 100 Hz)
    /// let (n, periods, fs, f1) = (16, 12, 100.0, 7.3);
    /// let periodic = |t: usize| (2.0 * PI * (t % n) as f64 / n as f64).sin();
    /// let y: Vec<f64> = (0..n * periods)
    ///     .map(|t| periodic(t) + 0.3 * (2.0 * PI * f1 * t as f64 / fs + 0.5).cos())
    ///     .collect();
    /// let data = IoData::new(
    ///     vec![("u".into(), y.clone()), ("y".into(), y)], 1.0 / fs, Some(n),
    /// ).unwrap();
    /// let line = synchronous(&data, f1, &SynchronousOptions::new()).unwrap();
    /// let clean = line.remove(&data).unwrap();
    /// let y = clean.channel("y").unwrap();
    /// assert!((0..n * periods).all(|t| (y[t] - periodic(t)).abs() < 1e-10));
    /// ```
    pub fn remove(&self, data: &IoData) -> Result<IoData> {
        let w = 2.0 * PI * self.f_sync_hz * data.ts();
        let mut exps = Vec::with_capacity(data.n_experiments());
        for e in 0..data.n_experiments() {
            let mut exp = data.experiment(e)?;
            // the phase's cosine and sine once per experiment, shared by its channels
            let mut cs: Vec<(f64, f64)> = Vec::new();
            for ch in self.channels.iter().filter(|c| c.experiment == e) {
                let (a, b) = (ch.amplitude.re, -ch.amplitude.im);
                let v = exp.channel(&ch.name)?;
                if cs.len() != v.len() {
                    cs = (0..v.len())
                        .map(|t| {
                            let ph = w * t as f64;
                            (ph.cos(), ph.sin())
                        })
                        .collect();
                }
                let x: Vec<f64> = v
                    .iter()
                    .zip(&cs)
                    .map(|(v, &(c, s))| v - a * c - b * s)
                    .collect();
                exp = exp.with_channel(ch.name.clone(), x)?;
            }
            exps.push(exp);
        }
        if self.channels.iter().any(|c| c.experiment >= exps.len()) {
            return Err(Error::invalid(
                "data",
                format!(
                    "the synchronous line was measured on more experiments than the record has                      ({}); remove it from the record it was measured on",
                    exps.len()
                ),
            ));
        }
        IoData::from_experiments(exps)
    }
}

/// Measures the synchronous (1×) line at `f_sync_hz` on every `u` and `y` channel of every
/// experiment of `data`; see the [module docs](self) for the method and its variance.
///
/// # Errors
/// [`Error::InvalidArgument`]: `f_sync_hz` not in $(0, f_s/2)$; no `u` or `y` channel; bad
/// options; a record shorter than the skipped periods plus two periods (or, without a period,
/// too short for the noise bins); non-finite samples; on a period line: the line excited by
/// some `r` channel (inseparable; the message names the line and the fix) or a single period.
/// [`Error::Numerical`]: a singular regression (a degenerate record).
pub fn synchronous(
    data: &IoData,
    f_sync_hz: f64,
    opts: &SynchronousOptions,
) -> Result<SynchronousLine> {
    let fs = data.fs();
    if !(f_sync_hz.is_finite() && f_sync_hz > 0.0 && f_sync_hz < fs / 2.0) {
        return Err(Error::invalid(
            "f_sync_hz",
            format!(
                "the synchronous frequency must be in (0, fs/2) = (0, {}) Hz, got {f_sync_hz}; \
                 give the rotation frequency speed_rpm / 60",
                fs / 2.0
            ),
        ));
    }
    if opts.noise_bins < 2 {
        return Err(Error::invalid(
            "noise_bins",
            format!("at least 2 noise bins are needed, got {}", opts.noise_bins),
        ));
    }
    if !(0.0..1.0).contains(&opts.rel_threshold) {
        return Err(Error::invalid(
            "rel_threshold",
            format!("must be in [0, 1), got {}", opts.rel_threshold),
        ));
    }
    for role in [Role::Input, Role::Output] {
        if data.role_names(role).is_empty() {
            return Err(data.missing_role(role));
        }
    }
    data.require_finite(&[Role::Input, Role::Output])?;
    let names: Vec<(String, Role)> = [Role::Input, Role::Output]
        .iter()
        .flat_map(|&role| {
            data.role_names(role)
                .into_iter()
                .map(move |n| (n.to_string(), role))
        })
        .collect();
    let period = opts.period_samples.or(data.period_samples());
    let ts = 1.0 / fs;
    let mut channels = Vec::new();
    let mut out_method = SynchronousMethod::Regression;
    let mut out_periods = 1;
    let mut out_dof = 0.0;
    let mut grid_offset = 0.0;
    for e in 0..data.n_experiments() {
        let len = data.experiment_len(e).unwrap_or(0);
        let (n, skip, p) = match period {
            Some(n) => {
                if n < 2 {
                    return Err(Error::invalid(
                        "period_samples",
                        format!("a period needs at least 2 samples, got {n}"),
                    ));
                }
                let p = (len / n).saturating_sub(opts.skip_periods);
                if p < 2 {
                    return Err(Error::invalid(
                        "data",
                        format!(
                            "experiment {e} has {len} samples = {} whole periods of {n}; after \
                             skipping {} there must be at least 2: record more periods or skip \
                             fewer",
                            len / n,
                            opts.skip_periods
                        ),
                    ));
                }
                (n, opts.skip_periods * n, p)
            }
            None => {
                if opts.skip_periods > 0 {
                    return Err(Error::invalid(
                        "skip_periods",
                        "periods can be skipped only with a period length (period_samples)",
                    ));
                }
                (len, 0, 1)
            }
        };
        let l = n * p;
        // position of f_sync on the period grid (lines) and on the record's DFT grid (bins)
        let pos_line = f_sync_hz * n as f64 * ts;
        let m = pos_line.round();
        grid_offset = if period.is_some() { pos_line - m } else { 0.0 };
        let on_grid = period.is_some() && grid_offset.abs() <= 1e-6;
        let ins = data.signals(Role::Input, e)?;
        let outs = data.signals(Role::Output, e)?;
        let sigs: Vec<&[f64]> = ins.iter().chain(outs.iter()).copied().collect();
        if on_grid {
            let line = m as usize;
            if line == 0 || 2 * line >= n {
                return Err(Error::invalid(
                    "f_sync_hz",
                    format!(
                        "the synchronous frequency {f_sync_hz} Hz falls on period line {line} \
                         of {n}, which has no complex amplitude (DC or Nyquist)"
                    ),
                ));
            }
            let mut an = PeriodicAnalyzer::new(n)?;
            let po = PeriodicOptions::new(n).skip(opts.skip_periods);
            // the line must not be excited by any r channel
            if data.role_count(Role::Excitation) > 0 {
                let rs = data.signals(Role::Excitation, e)?;
                let spec = an.analyze(&rs, fs, &po)?;
                for (j, name) in data.role_names(Role::Excitation).iter().enumerate() {
                    let mean = spec.mean(j);
                    let peak = mean[1..].iter().fold(0.0f64, |a, v| a.max(v.norm()));
                    if peak > 0.0 && mean[line].norm() > opts.rel_threshold * peak {
                        return Err(Error::invalid(
                            "f_sync_hz",
                            format!(
                                "the synchronous frequency {f_sync_hz} Hz falls on period line \
                                 {line}, which the excitation `{name}` excites (experiment {e}): \
                                 the 1× line and the excitation response cannot be separated \
                                 there. Leave that line unexcited (e.g. an odd-line multisine \
                                 with the 1× line on an even line), or change the period so that \
                                 the 1× line falls between lines"
                            ),
                        ));
                    }
                }
            }
            let spec = an.analyze(&sigs, fs, &po)?;
            let nf = n as f64;
            for (c, (name, role)) in names.iter().enumerate() {
                let amp = spec.mean(c)[line] * (2.0 / nf);
                let var = spec.cov_at(c, c, line).re / p as f64 * 4.0 / (nf * nf);
                channels.push(SynchronousChannel {
                    name: name.clone(),
                    role: *role,
                    experiment: e,
                    amplitude: amp,
                    std: var.max(0.0).sqrt(),
                });
            }
            out_method = SynchronousMethod::PeriodLine { line };
            out_dof = (p - 1) as f64;
        } else {
            let w = 2.0 * PI * f_sync_hz * ts;
            let proj = |x: &[f64]| -> Vec<f64> {
                let mut mean = vec![0.0; n];
                for q in 0..p {
                    for (a, v) in mean.iter_mut().zip(&x[q * n..(q + 1) * n]) {
                        *a += v;
                    }
                }
                mean.iter_mut().for_each(|a| *a /= p as f64);
                x.iter().enumerate().map(|(t, v)| v - mean[t % n]).collect()
            };
            let cr: Vec<f64> = (0..l).map(|t| (w * (skip + t) as f64).cos()).collect();
            let sr: Vec<f64> = (0..l).map(|t| (w * (skip + t) as f64).sin()).collect();
            let (ct, st) = (proj(&cr), proj(&sr));
            let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
            let (g11, g12, g22) = (dot(&ct, &ct), dot(&ct, &st), dot(&st, &st));
            let det = g11 * g22 - g12 * g12;
            if det.is_nan() || det <= 1e-12 * (g11 * g22).max(f64::MIN_POSITIVE) {
                return Err(Error::numerical(
                    "synchronous line",
                    format!(
                        "the cos/sin regressors at {f_sync_hz} Hz are degenerate after removing \
                         the period mean (grid offset {grid_offset:.3e} lines); record more \
                         periods or move the period grid"
                    ),
                ));
            }
            let (i11, i12, i22) = (g22 / det, -g12 / det, g11 / det);
            let bins = noise_bins(l, p, f_sync_hz * l as f64 * ts, opts.noise_bins);
            if bins.len() < 2 {
                return Err(Error::invalid(
                    "data",
                    format!(
                        "experiment {e}: only {} residual DFT bins near {f_sync_hz} Hz to \
                         estimate the noise; record a longer experiment",
                        bins.len()
                    ),
                ));
            }
            // twiddles e^{-j2π t/L}
            let tw: Vec<c64> = (0..l)
                .map(|t| c64::from_polar(1.0, -2.0 * PI * t as f64 / l as f64))
                .collect();
            for (c, (name, role)) in names.iter().enumerate() {
                let xt = proj(&sigs[c][skip..skip + l]);
                let (r1, r2) = (dot(&ct, &xt), dot(&st, &xt));
                let a = i11 * r1 + i12 * r2;
                let b = i12 * r1 + i22 * r2;
                let res: Vec<f64> = (0..l).map(|t| xt[t] - a * ct[t] - b * st[t]).collect();
                let mut pow = 0.0;
                for &k in &bins {
                    let mut acc = c64::new(0.0, 0.0);
                    // the twiddle index k·t mod L, stepped (no division per sample)
                    let step = k % l;
                    let mut at = 0;
                    for v in &res {
                        acc += tw[at] * *v;
                        at += step;
                        if at >= l {
                            at -= l;
                        }
                    }
                    pow += acc.norm_sqr();
                }
                let s2 = pow / (l as f64 * bins.len() as f64);
                channels.push(SynchronousChannel {
                    name: name.clone(),
                    role: *role,
                    experiment: e,
                    amplitude: c64::new(a, -b),
                    std: (s2 * (i11 + i22)).max(0.0).sqrt(),
                });
            }
            out_method = SynchronousMethod::Regression;
            out_dof = bins.len() as f64;
        }
        out_periods = p;
    }
    Ok(SynchronousLine {
        f_sync_hz,
        grid_offset,
        method: out_method,
        channels,
        periods: out_periods,
        dof: out_dof,
    })
}

/// The `count` bins of a length-`l` DFT nearest to the fractional bin `pos`, excluding the
/// period lines (multiples of `p`, zeroed by the projection), DC and bins from $l/2$, and those
/// within 1.5 bins of `pos`.
fn noise_bins(l: usize, p: usize, pos: f64, count: usize) -> Vec<usize> {
    let ok = |k: usize| k >= 1 && 2 * k < l && k % p != 0 && (k as f64 - pos).abs() > 1.5;
    let centre = pos.round().max(0.0) as usize;
    let mut out = Vec::with_capacity(count);
    let mut d = 0usize;
    while out.len() < count && (d <= centre || centre + d < l / 2) {
        if ok(centre + d) {
            out.push(centre + d);
        }
        if d > 0 && d <= centre && ok(centre - d) && out.len() < count {
            out.push(centre - d);
        }
        d += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// `p` periods of `n` samples at `fs` Hz of one channel `y`: a cosine on period line
    /// `line`, the 1× line $\operatorname{Re}(A e^{j 2\pi f_1 t / f_s})$ and white noise σ
    /// (seeded); `u` is zero.
    fn record(
        (n, p, fs): (usize, usize, f64),
        line: usize,
        f1: f64,
        amp: c64,
        sigma: f64,
        seed: u64,
    ) -> IoData {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let y: Vec<f64> = (0..n * p)
            .map(|t| {
                let per = (2.0 * PI * line as f64 * (t % n) as f64 / n as f64).cos();
                let ph = c64::from_polar(1.0, 2.0 * PI * f1 * t as f64 / fs);
                let v: f64 = StandardNormal.sample(&mut rng);
                per + (amp * ph).re + sigma * v
            })
            .collect();
        IoData::new(
            vec![("u".into(), vec![0.0; n * p]), ("y".into(), y)],
            1.0 / fs,
            Some(n),
        )
        .unwrap()
    }

    /// A periodic part, a 1× line and white noise σ; the estimate's error against the truth,
    /// normalised by the reported σ_A, pooled over seeds: E|δ|²/σ_A² ≈ 1 (white noise:
    /// σ_A² ≈ 4σ²/L).
    #[test]
    fn regression_is_unbiased_and_its_std_is_right_for_white_noise() {
        let (n, p, fs, f1, sigma) = (64usize, 16usize, 1000.0, 123.4567, 0.05);
        let amp = c64::new(0.02, -0.01);
        let mut z2 = 0.0;
        let mut ratio = 0.0;
        let seeds = 200;
        for seed in 0..seeds {
            let data = record((n, p, fs), 3, f1, amp, sigma, seed);
            let line = synchronous(&data, f1, &SynchronousOptions::new()).unwrap();
            assert_eq!(line.method, SynchronousMethod::Regression);
            let c = &line.channels[1];
            z2 += (c.amplitude - amp).norm_sqr() / (c.std * c.std);
            ratio += c.std * c.std / (4.0 * sigma * sigma / (n * p) as f64);
        }
        let (z2, ratio) = (z2 / seeds as f64, ratio / seeds as f64);
        assert!((0.8..1.25).contains(&z2), "E|δ|²/σ² = {z2}");
        assert!((0.9..1.12).contains(&ratio), "σ_A² / (4σ²/L) = {ratio}");
    }

    /// [`SynchronousLine::variance_factor`] against a Monte Carlo oracle: a periodic
    /// response on line 8 of a 64-sample period, a 1× line 0.01 lines above it ($\delta P =
    /// 0.11$ with 11 periods) and white noise; after `remove`, the error of the period-mean
    /// spectrum's amplitude at line 8 (against the periodic response's) and at line 10
    /// (nothing there), pooled over 400 seeds, in units of the line's own noise variance
    /// $4\sigma^2/L$: at line 8 the factor (about 25), at line 10 about 1.
    #[test]
    fn the_variance_the_removal_leaves_is_the_factor_times_the_lines_noise() {
        let (n, p, fs, sigma) = (64usize, 11usize, 1000.0, 0.05);
        let df = fs / n as f64;
        let f1 = (8.0 + 0.01) * df;
        let amp = c64::new(0.3, 0.2);
        let l = (n * p) as f64;
        let seeds = 400;
        let (mut e8, mut e10) = (0.0, 0.0);
        let mut factor = Vec::new();
        for seed in 0..seeds {
            let data = record((n, p, fs), 8, f1, amp, sigma, seed);
            let line = synchronous(&data, f1, &SynchronousOptions::new().period(n)).unwrap();
            assert_eq!(line.method, SynchronousMethod::Regression);
            assert!((line.grid_offset - 0.01).abs() < 1e-9);
            if factor.is_empty() {
                factor = line.variance_factor(&[8.0 * df, 10.0 * df], fs, n);
            }
            let clean = line.remove(&data).unwrap();
            let y = clean.channel("y").unwrap();
            // the period mean's amplitude at line k: (2/N) Σ_n ȳ_n e^{-j2πkn/N}
            let at = |k: f64| {
                let mut acc = c64::new(0.0, 0.0);
                for (t, v) in y.iter().enumerate() {
                    acc += c64::from_polar(*v, -2.0 * PI * k * (t % n) as f64 / n as f64);
                }
                acc * (2.0 / l)
            };
            e8 += (at(8.0) - 1.0).norm_sqr();
            e10 += at(10.0).norm_sqr();
        }
        let unit = 4.0 * sigma * sigma / l * seeds as f64;
        let (r8, r10) = (e8 / unit, e10 / unit);
        eprintln!(
            "line 8: {r8:.2} against the factor {:.2}; line 10: {r10:.3} against {:.4}",
            factor[0], factor[1]
        );
        assert!(factor[0] > 20.0 && factor[1] < 1.01, "{factor:?}");
        assert!(
            (r8 / factor[0] - 1.0).abs() < 0.2,
            "{r8} against {}",
            factor[0]
        );
        assert!(
            (r10 / factor[1] - 1.0).abs() < 0.2,
            "{r10} against {}",
            factor[1]
        );
    }

    #[test]
    fn on_an_excited_line_is_an_error_and_on_an_unexcited_line_the_period_dft() {
        let (n, p, fs) = (32usize, 4usize, 320.0); // lines every 10 Hz
        let r: Vec<f64> = (0..n * p)
            .map(|t| (2.0 * PI * 3.0 * (t % n) as f64 / n as f64).sin())
            .collect();
        let y: Vec<f64> = (0..n * p)
            .map(|t| {
                r[t] + 0.5 * (2.0 * PI * 50.0 * t as f64 / fs + 0.3).cos()
                    + 1e-3 * ((t * 7919) % 13) as f64
            })
            .collect();
        let data = IoData::new(
            vec![("r".into(), r.clone()), ("u".into(), r), ("y".into(), y)],
            1.0 / fs,
            Some(n),
        )
        .unwrap();
        let err = synchronous(&data, 30.0, &SynchronousOptions::new()).unwrap_err();
        assert!(err.to_string().contains("excites"), "{err}");
        let line = synchronous(&data, 50.0, &SynchronousOptions::new()).unwrap();
        assert_eq!(line.method, SynchronousMethod::PeriodLine { line: 5 });
        let a = line.channels[1].amplitude;
        assert!((a - c64::from_polar(0.5, 0.3)).norm() < 1e-2, "{a}");
        assert!(synchronous(&data, 200.0, &SynchronousOptions::new()).is_err());
        assert!(synchronous(&data, f64::NAN, &SynchronousOptions::new()).is_err());
    }
}
