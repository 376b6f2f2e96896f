//! Stepped-sine (point-by-point) frequency response: one sine at a time, a settling interval, then a
//! lock-in (single-bin DFT) over a whole number of cycles.
//!
//! The seed paper lists this "point-by-point frequency response method" first among the
//! nonparametric methods — "intuitive but time-consuming" — before it settles for PRBS and spectral
//! analysis. It is the classical reference measurement of a frequency analyser: at each frequency
//! $f_i$ a sine $r_k = A \sin(2\pi f_i k T_s)$ is injected, the loop is given time to reach its
//! periodic steady state, and the complex amplitudes of $r$, $u$ and $y$ at $f_i$ are measured.
//! Every point has the full excitation power at one frequency, so it is accurate and robust to
//! nonlinearity (the harmonics land on other frequencies), and slow: each point pays the settling
//! time of the slowest closed-loop pole.
//!
//! # Plan: integer cycles in an integer number of samples
//! [`SteppedSinePlan::new`] snaps every requested frequency $f$ to
//! $$ f_i = f_s \frac{m_i}{N_i}, \qquad m_i, N_i \in \mathbb N, \quad 0 < 2 m_i < N_i, $$
//! where $N_i$ is the measurement length in samples and $m_i$ the number of cycles it holds. $N_i$
//! is the smallest length with the best approximation among
//! $N_{\min} \le N \le N_{\min} + \lceil f_s / f \rceil$, with
//! $N_{\min} = \max(\lceil T_{\min} f_s \rceil, \lceil c_{\min} f_s / f \rceil)$ (minimum
//! measurement time and minimum number of cycles). Over that range $f N / f_s$ advances by more
//! than one in steps of $f / f_s < 1/2$, so some $N$ comes within $f/(2 f_s)$ of an integer and
//! $$ |f_i - f| \le \frac{f}{2 N_{\min}}, $$
//! a relative snap of at most $1/(2 N_{\min})$ (2.5e-4 for a 0.1 s window at 20 kHz). Before each
//! measurement window the sine runs for a settling interval ([`Settle`]) so that the transient of
//! switching it on has decayed; the plan reports each point's samples and the total time
//! $\sum_i (N^{\mathrm{settle}}_i + N_i) T_s$, the "measurement time" of the method.
//!
//! # Lock-in
//! [`lock_in`] returns the phasor
//! $$ \hat X = \frac{2}{n} \sum_{k=s}^{s+n-1} x_k\, e^{-j 2\pi f k T_s} $$
//! over the samples $[s, s+n)$, with the phase referenced to $t = k T_s$, $k$ the **absolute** sample
//! index (not the index inside the window), so that $x_k \approx \operatorname{Re}(\hat X e^{j 2\pi f k T_s})$;
//! a sine $A\sin(2\pi f k T_s)$ has $X = -jA$. If
//! $x_k = c + \operatorname{Re}(X e^{j\theta_k}) + e_k$, $\theta_k = 2\pi f k T_s$, and the window holds
//! $m$ whole cycles with $0 < 2m < n$, then $\sum_k e^{-j\theta_k} = \sum_k e^{-2j\theta_k} = 0$ and
//! $$ \hat X = X + \frac{2}{n} \sum_k e_k e^{-j\theta_k} $$
//! exactly: neither the offset $c$ nor the negative-frequency image leaks into the estimate. On a
//! window that is not a whole number of cycles both leak (a relative error of order $1/m$);
//! [`SteppedSinePlan`] exists to avoid that.
//!
//! # Variance of the phasor
//! For white noise $e_k$ of variance $\sigma^2$ the error $\delta X = \frac2n \sum_k e_k e^{-j\theta_k}$
//! has
//! $$ \mathrm E\,|\delta X|^2 = \frac{4}{n^2} \sum_k \sigma^2 = \frac{4\sigma^2}{n}, \qquad
//!    \mathrm E\,\delta X^2 = \frac{4\sigma^2}{n^2} \sum_k e^{-2j\theta_k} = 0, $$
//! so $\operatorname{Re}\delta X$ and $\operatorname{Im}\delta X$ are uncorrelated with variance
//! $2\sigma^2/n$ each, and the variance of the complex estimate in the sense of `docs/formats.md`
//! (the square of `std`, $\mathrm E|\hat X - X|^2$) is $4\sigma^2/n$. The regressors
//! $1, \cos\theta_k, \sin\theta_k$ are orthogonal over whole cycles, so the mean and $\hat X$ are
//! the least-squares sine fit and the residual $\hat e_k = x_k - \bar x - \operatorname{Re}(\hat X e^{j\theta_k})$
//! has $\mathrm E \sum_k \hat e_k^2 = (n-3)\sigma^2$. Hence
//! $$ \hat\sigma^2 = \frac{1}{n-3} \sum_k \hat e_k^2, \qquad
//!    \widehat{\operatorname{var}}\,\hat X = \frac{4 \hat\sigma^2}{n} \quad (\text{each part } 2\hat\sigma^2/n). $$
//! ([`lock_in_stats`], [`NoiseEstimate::White`].)
//!
//! **Coloured noise.** For stationary noise with autocovariance $R_\tau$ the same computation gives
//! $\mathrm E|\delta X|^2 \approx \frac4n \Phi(f)$ with $\Phi(f) = \sum_\tau R_\tau e^{-j2\pi f\tau T_s}$
//! ($=\sigma^2$ for white noise): only the noise density *at* $f$ matters, while $\hat\sigma^2$ is its
//! average over all frequencies. In closed loop the noise on $y$ and $u$ is shaped by the loop
//! (sensor noise reaches $y$ through $S$), so the white estimate can be off by the ratio of $|S(f)|^2$
//! to its mean — orders of magnitude at low frequency. [`NoiseEstimate::NeighbourBins`] instead
//! uses the DFT bins next to the excited one: with $m$ cycles in $n$ samples the sine, its offset
//! and (if excluded) its harmonics leave bins $m \pm 1, \dots, m \pm L$ untouched, and each carries
//! noise only, with $\mathrm E|X_{m\pm i}|^2 \approx \frac4n \Phi(f_{m\pm i})$. Their mean square
//! estimates $\operatorname{var}\hat X$ from the local noise density, at the price of $2K$ degrees of
//! freedom for $K$ bins (relative scatter $1/\sqrt K$). Bins $0$, $\ge n/2$ and multiples of $m$
//! (harmonics, which a nonlinear system fills with signal) are skipped.
//!
//! # Ratios in closed loop
//! With the excitation $r$ added to the controller output, $u$ the recorded controller output and
//! $y$ the measured displacement (see `docs/conventions.md`), one point gives
//! $$ \hat T_{ry} = \frac{\hat Y}{\hat R}, \qquad \hat S = \hat T_{ru} = \frac{\hat U}{\hat R}, \qquad
//!    \hat P = \frac{\hat Y}{\hat U} \;\text{(joint input–output: no controller model)}. $$
//! To first order a ratio $G = A/B$ errs by $\delta G \approx (\delta A - G\,\delta B)/B$, which keeps the
//! correlation between the errors of $A$ and $B$ (strong for $y$ and $u$ in closed loop):
//! * white: $\mathrm E|\delta A - G\delta B|^2 = \frac4n \mathrm E|e_a - G e_b|^2$, estimated with the
//!   residuals as $\frac{4}{n(n-3)} \sum_k |\hat e_{a,k} - \hat G \hat e_{b,k}|^2$;
//! * neighbour bins: $\frac1K \sum_{i} |A_{m\pm i} - \hat G B_{m\pm i}|^2$;
//!
//! and $\operatorname{var}\hat G = \mathrm E|\delta A - G\delta B|^2 / |\hat B|^2$. For a noise-free
//! reference ($B = R$) this is $\operatorname{var}\hat A / |R|^2$. The formula ignores terms of
//! order $\operatorname{var}\hat B/|B|^2$ (bias and variance of a ratio with a noisy denominator),
//! which is fine while $|\hat B|$ is well above its standard deviation.
//!
//! # Complexity
//! [`lock_in`] and [`lock_in_stats`]: $O(n)$ (one sine/cosine per sample). A [`SinePoint`] with
//! $L$ neighbour bins: $O((2L+1)\,n)$ per channel, with one table of $n$ roots of unity.
//!
//! # Example
//! ```
//! use ambid_core::frf::stepped_sine::{lock_in, NoiseEstimate, SinePoint, Settle, SteppedSinePlan};
//! let fs = 10_000.0;
//! // 3 points, 20 ms settling, at least 10 cycles and 50 ms of measurement each
//! let plan = SteppedSinePlan::new(fs, &[50.0, 333.3, 1234.5], Settle::Seconds(0.02), 10, 0.05).unwrap();
//! let p = &plan.points()[1];
//! assert_eq!(p.measure_samples as f64 * p.f_hz / fs, p.cycles as f64); // integer cycles
//! assert!((p.f_hz - 333.3).abs() <= 333.3 / (2.0 * 500.0));
//! // a "system" that scales by 0.5 and delays by 3 samples; y = 0.5 r(k-3)
//! let r = plan.excitation(1, 2.0).unwrap();
//! let y: Vec<f64> = (0..r.len()).map(|k| if k >= 3 { 0.5 * r[k - 3] } else { 0.0 }).collect();
//! let (s, n) = (p.settle_samples, p.measure_samples);
//! let rr = lock_in(&r, p.f_hz, fs, s, n).unwrap();
//! assert!((rr - ambid_core::c64::new(0.0, -2.0)).norm() < 1e-12); // sin → -j
//! let pt = SinePoint::estimate(&r, &r, &y, p.f_hz, fs, s, n, NoiseEstimate::NeighbourBins(4)).unwrap();
//! let want = ambid_core::c64::from_polar(0.5, -2.0 * std::f64::consts::PI * p.f_hz * 3.0 / fs);
//! assert!((pt.t_ry.value - want).norm() < 1e-12);
//! println!("total measurement time {:.3} s", plan.total_time_s());
//! ```

use crate::error::{Error, Result};
use crate::lti::Frd;
use crate::signal::MAX_SAMPLES;
use faer::c64;
use std::f64::consts::PI;

/// How long the sine runs before each measurement window.
///
/// The transient of switching a sine on decays with the slowest pole of the (closed-loop) system,
/// whatever the excitation frequency, so [`Settle::Seconds`] is the physically meaningful rule for a
/// feedback loop; [`Settle::Cycles`] suits systems whose slowest dynamics scale with frequency.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Settle {
    /// A fixed settling time in seconds ($\ge 0$), rounded up to whole samples.
    Seconds(f64),
    /// A number of cycles of each point's frequency ($\ge 0$), rounded up to whole samples.
    Cycles(f64),
}

/// One frequency of a [`SteppedSinePlan`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SinePlanPoint {
    /// The frequency that was asked for, Hz.
    pub f_requested_hz: f64,
    /// The snapped frequency $f_s\, m / N$ actually used, Hz.
    pub f_hz: f64,
    /// Samples of sine before the measurement window.
    pub settle_samples: usize,
    /// Samples in the measurement window, $N$.
    pub measure_samples: usize,
    /// Whole cycles in the measurement window, $m$.
    pub cycles: usize,
}

impl SinePlanPoint {
    /// Samples of this point, settling plus measurement.
    pub fn total_samples(&self) -> usize {
        self.settle_samples + self.measure_samples
    }
}

/// A stepped-sine experiment: the snapped frequencies with their settling and measurement lengths.
///
/// # Example
/// ```
/// use ambid_core::frf::stepped_sine::{Settle, SteppedSinePlan};
/// let plan = SteppedSinePlan::new(20_000.0, &[10.0, 97.0, 1000.0], Settle::Seconds(0.1), 4, 0.05).unwrap();
/// // 10 Hz: 4 cycles need 0.4 s; 97 Hz: 0.05 s hold 4.85 cycles, snapped to 5 cycles
/// assert_eq!(plan.points()[0].measure_samples, 8000);
/// assert_eq!(plan.points()[1].cycles, 5);
/// assert_eq!(plan.points()[2].settle_samples, 2000);
/// assert!((plan.total_time_s() - (0.3 + 0.4 + 2.0 * 0.05)).abs() < 0.01);
/// ```
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SteppedSinePlan {
    fs_hz: f64,
    points: Vec<SinePlanPoint>,
}

impl SteppedSinePlan {
    /// Plans one point per requested frequency (in the given order; duplicates are allowed) at
    /// sample rate `fs_hz`: each frequency is snapped to a whole number $m \ge$ `measure_cycles` of
    /// cycles in a measurement window of $N \ge$ `min_measure_s`$\cdot f_s$ samples (see the
    /// [module documentation](self) for the rule and the bound on the snap), preceded by the
    /// settling interval `settle`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if `fs_hz` is not finite and positive, `freqs_hz` is empty or holds
    /// a frequency outside $(0, f_s/2)$ or a NaN, the settling time or cycles are negative or not
    /// finite, `measure_cycles` is 0, `min_measure_s` is negative or not finite, or a point would
    /// exceed [`MAX_SAMPLES`] samples.
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::stepped_sine::{Settle, SteppedSinePlan};
    /// assert!(SteppedSinePlan::new(1000.0, &[500.0], Settle::Cycles(10.0), 5, 0.0).is_err());
    /// let p = SteppedSinePlan::new(1000.0, &[123.4], Settle::Cycles(10.0), 5, 0.0).unwrap();
    /// let pt = p.points()[0];
    /// assert!(pt.cycles >= 5 && (pt.f_hz - 1000.0 * pt.cycles as f64 / pt.measure_samples as f64).abs() < 1e-12);
    /// ```
    pub fn new(
        fs_hz: f64,
        freqs_hz: &[f64],
        settle: Settle,
        measure_cycles: usize,
        min_measure_s: f64,
    ) -> Result<Self> {
        check_fs(fs_hz)?;
        if freqs_hz.is_empty() {
            return Err(Error::invalid(
                "freqs_hz",
                "no frequencies given; pass at least one frequency in (0, fs/2)",
            ));
        }
        match settle {
            Settle::Seconds(v) | Settle::Cycles(v) if !(v.is_finite() && v >= 0.0) => {
                return Err(Error::invalid(
                    "settle",
                    format!("the settling interval must be finite and ≥ 0, got {v}"),
                ));
            }
            _ => {}
        }
        if measure_cycles == 0 {
            return Err(Error::invalid(
                "measure_cycles",
                "at least one whole cycle must be measured; pass measure_cycles ≥ 1",
            ));
        }
        if !(min_measure_s.is_finite() && min_measure_s >= 0.0) {
            return Err(Error::invalid(
                "min_measure_s",
                format!(
                    "the minimum measurement time must be finite and ≥ 0 s, got {min_measure_s}"
                ),
            ));
        }
        let points = freqs_hz
            .iter()
            .enumerate()
            .map(|(i, &f)| plan_point(fs_hz, i, f, settle, measure_cycles, min_measure_s))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { fs_hz, points })
    }

    /// Sample rate, Hz.
    pub fn fs_hz(&self) -> f64 {
        self.fs_hz
    }

    /// The planned points, in the requested order.
    pub fn points(&self) -> &[SinePlanPoint] {
        &self.points
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// `true` if the plan has no points (never, for a plan built by [`SteppedSinePlan::new`]).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The snapped frequencies, Hz.
    pub fn f_hz(&self) -> Vec<f64> {
        self.points.iter().map(|p| p.f_hz).collect()
    }

    /// Settling samples summed over the points.
    pub fn settle_samples(&self) -> usize {
        self.points.iter().map(|p| p.settle_samples).sum()
    }

    /// Measurement samples summed over the points.
    pub fn measure_samples(&self) -> usize {
        self.points.iter().map(|p| p.measure_samples).sum()
    }

    /// Samples of the whole experiment, settling plus measurement summed over the points.
    pub fn total_samples(&self) -> usize {
        self.settle_samples() + self.measure_samples()
    }

    /// Duration of the whole experiment, $\sum_i (N^{\mathrm{settle}}_i + N_i) / f_s$, in seconds
    /// (switching between points assumed instantaneous).
    pub fn total_time_s(&self) -> f64 {
        self.total_samples() as f64 / self.fs_hz
    }

    /// The excitation of point `index`: `settle_samples + measure_samples` samples of
    /// $A \sin(2\pi f_i k T_s)$, $k = 0, 1, \dots$ (the phase advances by exactly $2\pi m/N$ per
    /// sample, computed from the integer $m k \bmod N$, so the measurement window
    /// $[N^{\mathrm{settle}}, N^{\mathrm{settle}} + N)$ holds exactly $m$ cycles). Sample 0 of the
    /// returned vector is the phase reference of [`lock_in`] when it is called on records that
    /// start with it.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if `index` is out of range or `amplitude` is not finite.
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::stepped_sine::{Settle, SteppedSinePlan};
    /// let plan = SteppedSinePlan::new(1000.0, &[250.0], Settle::Seconds(0.0), 1, 0.0).unwrap();
    /// let r = plan.excitation(0, 1.0).unwrap();
    /// assert_eq!(r.len(), 4);
    /// assert!((r[1] - 1.0).abs() < 1e-15 && r[2].abs() < 1e-15);
    /// ```
    pub fn excitation(&self, index: usize, amplitude: f64) -> Result<Vec<f64>> {
        let p = self.points.get(index).ok_or_else(|| {
            Error::invalid(
                "index",
                format!(
                    "point {index} does not exist; the plan has {} points",
                    self.points.len()
                ),
            )
        })?;
        if !amplitude.is_finite() {
            return Err(Error::invalid(
                "amplitude",
                format!("the sine amplitude must be finite, got {amplitude}"),
            ));
        }
        let table = RootTable::new(p.measure_samples);
        let (m, n) = (p.cycles, p.measure_samples);
        Ok((0..p.total_samples())
            .map(|k| amplitude * table.sin((m * (k % n)) % n))
            .collect())
    }

    /// Estimates point `index` from records `r`, `u`, `y` that start with the point's excitation
    /// (as produced by [`SteppedSinePlan::excitation`]): the measurement window is
    /// `[settle_samples, settle_samples + measure_samples)`. See [`SinePoint::estimate`].
    ///
    /// # Errors
    /// As [`SinePoint::estimate`]; [`Error::InvalidArgument`] for an index out of range.
    pub fn estimate_point(
        &self,
        index: usize,
        r: &[f64],
        u: &[f64],
        y: &[f64],
        noise: NoiseEstimate,
    ) -> Result<SinePoint> {
        let p = self.points.get(index).ok_or_else(|| {
            Error::invalid(
                "index",
                format!(
                    "point {index} does not exist; the plan has {} points",
                    self.points.len()
                ),
            )
        })?;
        SinePoint::estimate(
            r,
            u,
            y,
            p.f_hz,
            self.fs_hz,
            p.settle_samples,
            p.measure_samples,
            noise,
        )
    }
}

fn check_fs(fs_hz: f64) -> Result<()> {
    if fs_hz.is_finite() && fs_hz > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            "fs_hz",
            format!("the sample rate must be a finite number of Hz > 0, got {fs_hz}"),
        ))
    }
}

fn check_frequency(name: &'static str, f: f64, fs_hz: f64) -> Result<()> {
    if f.is_finite() && f > 0.0 && f < 0.5 * fs_hz {
        Ok(())
    } else {
        Err(Error::invalid(
            name,
            format!(
                "{f} Hz is outside (0, fs/2) = (0, {} Hz); a lock-in needs a frequency strictly \
                 between DC and the Nyquist frequency",
                0.5 * fs_hz
            ),
        ))
    }
}

fn samples_from(name: &'static str, x: f64, hint: &str) -> Result<usize> {
    // tolerate the rounding of products such as 0.05 s × 20 kHz
    let v = (x - 1e-9 * x.abs().max(1.0)).ceil().max(0.0);
    if v > MAX_SAMPLES as f64 {
        return Err(Error::invalid(
            name,
            format!("{v} samples exceed the limit of {MAX_SAMPLES} samples per point; {hint}"),
        ));
    }
    Ok(v as usize)
}

fn plan_point(
    fs: f64,
    i: usize,
    f: f64,
    settle: Settle,
    measure_cycles: usize,
    min_measure_s: f64,
) -> Result<SinePlanPoint> {
    check_frequency("freqs_hz", f, fs).map_err(|e| match e {
        Error::InvalidArgument { name, reason } => Error::InvalidArgument {
            name,
            reason: format!("freqs_hz[{i}]: {reason}"),
        },
        other => other,
    })?;
    let hint = "shorten the measurement or raise the lowest frequency";
    let n_min = samples_from("min_measure_s", min_measure_s * fs, hint)?
        .max(samples_from(
            "measure_cycles",
            measure_cycles as f64 * fs / f,
            hint,
        )?)
        .max(3);
    let span = (fs / f).ceil() as usize;
    let mut best: Option<(f64, usize, usize)> = None;
    for n in n_min..=n_min + span {
        let m = (f * n as f64 / fs).round() as usize;
        if m < measure_cycles || 2 * m >= n {
            continue;
        }
        let err = (fs * m as f64 / n as f64 - f).abs();
        // strictly better by more than rounding: ties go to the shorter window
        if best.is_none_or(|(e, _, _)| err < e - 1e-12 * f) {
            best = Some((err, n, m));
            if err <= 1e-12 * f {
                break;
            }
        }
    }
    let (_, n, m) = best.ok_or_else(|| {
        Error::numerical(
            "SteppedSinePlan",
            format!("no whole-cycle window found for {f} Hz; this is a bug, please report it"),
        )
    })?;
    if n > MAX_SAMPLES {
        return Err(Error::invalid(
            "min_measure_s",
            format!("{n} samples exceed the limit of {MAX_SAMPLES}; {hint}"),
        ));
    }
    let f_hz = fs * m as f64 / n as f64;
    let settle_samples = match settle {
        Settle::Seconds(s) => samples_from("settle", s * fs, "shorten the settling interval")?,
        Settle::Cycles(c) => samples_from("settle", c * fs / f_hz, "use fewer settling cycles")?,
    };
    Ok(SinePlanPoint {
        f_requested_hz: f,
        f_hz,
        settle_samples,
        measure_samples: n,
        cycles: m,
    })
}

/// $\cos$ and $\sin$ of $2\pi i / n$, $i = 0, \dots, n-1$: exact periodicity for whole-cycle windows.
struct RootTable {
    cos: Vec<f64>,
    sin: Vec<f64>,
}

impl RootTable {
    fn new(n: usize) -> Self {
        let (sin, cos) = (0..n)
            .map(|i| (2.0 * PI * i as f64 / n as f64).sin_cos())
            .unzip();
        Self { cos, sin }
    }

    fn sin(&self, i: usize) -> f64 {
        self.sin[i]
    }

    /// $\sum_{i<n} x_i e^{-j 2\pi k i / n}$ for the window `x` (local index $i$).
    fn bin(&self, x: &[f64], k: usize) -> c64 {
        let n = self.cos.len();
        let (mut re, mut im) = (0.0, 0.0);
        let mut idx = 0usize;
        for v in x {
            re += v * self.cos[idx];
            im -= v * self.sin[idx];
            idx += k;
            if idx >= n {
                idx -= n;
            }
        }
        c64::new(re, im)
    }
}

/// Checks the window `[start, start + n)` of `x` and returns it.
fn window<'a>(what: &'static str, x: &'a [f64], start: usize, n: usize) -> Result<&'a [f64]> {
    if n == 0 {
        return Err(Error::invalid(
            "n",
            "the lock-in window is empty; pass n ≥ 1 samples (a whole number of cycles)",
        ));
    }
    let end = start
        .checked_add(n)
        .filter(|&e| e <= x.len())
        .ok_or_else(|| {
            Error::invalid(
                "start",
                format!(
                    "the window [{start}, {start} + {n}) ends after the {} samples of `{what}`; \
                 record longer or move the window",
                    x.len()
                ),
            )
        })?;
    let w = &x[start..end];
    if let Some(i) = w.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFinite {
            what,
            index: start + i,
        });
    }
    Ok(w)
}

fn check_lock_in_args(f_hz: f64, fs_hz: f64) -> Result<()> {
    check_fs(fs_hz)?;
    check_frequency("f_hz", f_hz, fs_hz)
}

/// $\hat X$ of the window `w` that starts at absolute index `start`.
fn phasor(w: &[f64], f_hz: f64, fs_hz: f64, start: usize) -> c64 {
    let c = f_hz / fs_hz;
    let (mut re, mut im) = (0.0, 0.0);
    for (i, v) in w.iter().enumerate() {
        // reduce the phase to one cycle before the trigonometry
        let cyc = (c * (start + i) as f64).rem_euclid(1.0);
        let (s, co) = (2.0 * PI * cyc).sin_cos();
        re += v * co;
        im -= v * s;
    }
    c64::new(re, im) * (2.0 / w.len() as f64)
}

/// The lock-in phasor $\hat X = \frac2n \sum_{k=s}^{s+n-1} x_k e^{-j2\pi f k T_s}$ of `x` at `f_hz` over
/// the samples `[start, start + n)`, phase referenced to the absolute sample index $k$
/// ($t = k T_s$, $T_s = 1/f_s$), so that $x_k \approx \operatorname{Re}(\hat X e^{j 2\pi f k T_s})$.
///
/// Exact (to rounding) for a sine plus offset when the window holds a whole number of cycles; see
/// the [module documentation](self).
///
/// # Errors
/// [`Error::InvalidArgument`] if `fs_hz` is not finite and positive, `f_hz` is not in
/// $(0, f_s/2)$, `n == 0` or the window does not fit in `x`; [`Error::NonFinite`] for a NaN or
/// infinite sample inside the window (with its absolute index).
///
/// # Example
/// ```
/// use ambid_core::frf::stepped_sine::lock_in;
/// let fs = 1000.0;
/// // 3 cos(2π 50 t + 0.4): 20 samples per cycle
/// let x: Vec<f64> = (0..400).map(|k| 3.0 * (2.0 * std::f64::consts::PI * 50.0 * k as f64 / fs + 0.4).cos()).collect();
/// let z = lock_in(&x, 50.0, fs, 100, 200).unwrap();
/// assert!((z.norm() - 3.0).abs() < 1e-12 && (z.arg() - 0.4).abs() < 1e-12);
/// assert!(lock_in(&x, 500.0, fs, 0, 200).is_err());
/// ```
pub fn lock_in(x: &[f64], f_hz: f64, fs_hz: f64, start: usize, n: usize) -> Result<c64> {
    check_lock_in_args(f_hz, fs_hz)?;
    let w = window("x", x, start, n)?;
    Ok(phasor(w, f_hz, fs_hz, start))
}

/// A lock-in phasor with the statistics of its residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LockIn {
    /// The phasor $\hat X$ (see [`lock_in`]).
    pub phasor: c64,
    /// Mean of the window, $\bar x$.
    pub mean: f64,
    /// Residual variance $\hat\sigma^2 = \frac{1}{n-3}\sum_k \hat e_k^2$,
    /// $\hat e_k = x_k - \bar x - \operatorname{Re}(\hat X e^{j\theta_k})$.
    pub residual_variance: f64,
    /// Variance of the complex phasor under the white-noise assumption,
    /// $\mathrm E|\hat X - X|^2 \approx 4\hat\sigma^2/n$ (each of the real and imaginary parts has half of it).
    pub variance: f64,
}

impl LockIn {
    /// Standard deviation of the complex phasor, $\sqrt{\mathrm E|\hat X - X|^2}$.
    pub fn std(&self) -> f64 {
        self.variance.sqrt()
    }
}

/// [`lock_in`] plus the window mean, the residual variance and the white-noise variance of the
/// phasor $4\hat\sigma^2/n$ (derived in the [module documentation](self); valid for a whole number
/// of cycles and white noise — for noise coloured by a feedback loop use
/// [`NoiseEstimate::NeighbourBins`] through [`phasor_ratio`] or [`SinePoint::estimate`]).
///
/// # Errors
/// As [`lock_in`]; also [`Error::InvalidArgument`] for `n < 4` (three parameters are fitted).
///
/// # Example
/// ```
/// use ambid_core::frf::stepped_sine::lock_in_stats;
/// // 1 + sin at a quarter of the sample rate plus ±0.1 alternating "noise" (at fs/2, orthogonal)
/// let x: Vec<f64> = (0..400).map(|k| 1.0 + [0.0, 1.0, 0.0, -1.0][k % 4] + if k % 2 == 0 { 0.1 } else { -0.1 }).collect();
/// let s = lock_in_stats(&x, 250.0, 1000.0, 0, 400).unwrap();
/// assert!((s.phasor.im + 1.0).abs() < 1e-12 && (s.mean - 1.0).abs() < 1e-12);
/// assert!((s.residual_variance - 0.01 * 400.0 / 397.0).abs() < 1e-12);
/// assert!((s.variance - 4.0 * s.residual_variance / 400.0).abs() < 1e-15);
/// ```
pub fn lock_in_stats(x: &[f64], f_hz: f64, fs_hz: f64, start: usize, n: usize) -> Result<LockIn> {
    check_lock_in_args(f_hz, fs_hz)?;
    let w = window("x", x, start, n)?;
    check_fit_length(n)?;
    let z = phasor(w, f_hz, fs_hz, start);
    let mean = w.iter().sum::<f64>() / n as f64;
    let res = residual(w, z, mean, f_hz, fs_hz, start);
    let residual_variance = res.iter().map(|e| e * e).sum::<f64>() / (n - 3) as f64;
    Ok(LockIn {
        phasor: z,
        mean,
        residual_variance,
        variance: 4.0 * residual_variance / n as f64,
    })
}

fn check_fit_length(n: usize) -> Result<()> {
    if n < 4 {
        return Err(Error::invalid(
            "n",
            format!(
                "a residual variance needs n ≥ 4 samples (mean and phasor are fitted), got {n}"
            ),
        ));
    }
    Ok(())
}

fn residual(w: &[f64], z: c64, mean: f64, f_hz: f64, fs_hz: f64, start: usize) -> Vec<f64> {
    let c = f_hz / fs_hz;
    w.iter()
        .enumerate()
        .map(|(i, v)| {
            let cyc = (c * (start + i) as f64).rem_euclid(1.0);
            let (s, co) = (2.0 * PI * cyc).sin_cos();
            v - mean - (z.re * co - z.im * s)
        })
        .collect()
}

/// How the noise variance of a phasor (and of a ratio of phasors) is estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseEstimate {
    /// From the residual of the sine fit, assuming white noise: $4\hat\sigma^2/n$. Fast and fine
    /// for open-loop data with white measurement noise; wrong by the noise colour otherwise.
    White,
    /// From the $L$ DFT bins on each side of the excited bin (skipping DC, bins at or above
    /// $n/2$, and harmonics of the excitation): the local noise density at $f$. Needs a whole
    /// number of cycles in the window. The default for closed-loop data.
    NeighbourBins(usize),
}

impl Default for NoiseEstimate {
    /// Eight bins on each side: up to 16 bins, a variance estimate with a relative scatter of
    /// about 25 %.
    fn default() -> Self {
        NoiseEstimate::NeighbourBins(8)
    }
}

/// A complex ratio estimate with its first-order variance $\mathrm E|\hat G - G|^2$.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ratio {
    /// The estimate $\hat G$.
    pub value: c64,
    /// $\mathrm E|\hat G - G|^2$ to first order.
    pub variance: f64,
}

impl Ratio {
    /// Standard deviation $\sqrt{\mathrm E|\hat G - G|^2}$.
    pub fn std(&self) -> f64 {
        self.variance.sqrt()
    }
}

/// What one channel contributes to ratios: its phasor and the noise information.
struct Channel {
    phasor: c64,
    /// Neighbour bins (scaled like the phasor, $\frac2n\sum$), for [`NoiseEstimate::NeighbourBins`].
    bins: Vec<c64>,
    /// Residual series, for [`NoiseEstimate::White`].
    residual: Vec<f64>,
}

/// The shared window geometry of the channels of one point.
struct Geometry {
    f_hz: f64,
    fs_hz: f64,
    start: usize,
    n: usize,
    noise: NoiseEstimate,
    /// Bins used for the noise, when neighbour bins are asked for.
    bins: Vec<usize>,
    table: Option<RootTable>,
}

impl Geometry {
    fn new(f_hz: f64, fs_hz: f64, start: usize, n: usize, noise: NoiseEstimate) -> Result<Self> {
        check_lock_in_args(f_hz, fs_hz)?;
        if n == 0 {
            return Err(Error::invalid(
                "n",
                "the lock-in window is empty; pass n ≥ 1 samples (a whole number of cycles)",
            ));
        }
        let (bins, table) = match noise {
            NoiseEstimate::White => {
                check_fit_length(n)?;
                (Vec::new(), None)
            }
            NoiseEstimate::NeighbourBins(l) => {
                if l == 0 {
                    return Err(Error::invalid(
                        "noise",
                        "NeighbourBins(0) uses no bins; pass at least 1 (8 is a good default)",
                    ));
                }
                let cycles = f_hz * n as f64 / fs_hz;
                let m = cycles.round();
                if (cycles - m).abs() > 1e-6 {
                    return Err(Error::invalid(
                        "f_hz",
                        format!(
                            "the window of {n} samples holds {cycles} cycles of {f_hz} Hz; \
                             neighbour-bin noise estimates need a whole number of cycles \
                             (plan the frequencies with SteppedSinePlan) or use NoiseEstimate::White"
                        ),
                    ));
                }
                let m = m as usize;
                if m == 0 || 2 * m >= n {
                    return Err(Error::invalid(
                        "f_hz",
                        format!(
                            "the window of {n} samples holds {m} cycles of {f_hz} Hz; neighbour-bin \
                             noise estimates need between 1 and n/2 cycles"
                        ),
                    ));
                }
                let bins: Vec<usize> = (1..=l)
                    .flat_map(|i| [m.checked_sub(i), Some(m + i)])
                    .flatten()
                    .filter(|&k| k > 0 && 2 * k < n && k % m != 0)
                    .collect();
                if bins.is_empty() {
                    return Err(Error::invalid(
                        "noise",
                        format!(
                            "no usable neighbour bins around bin {m} of a {n}-sample window (DC, \
                             Nyquist and harmonics are skipped); measure more cycles or use \
                             NoiseEstimate::White"
                        ),
                    ));
                }
                (bins, Some(RootTable::new(n)))
            }
        };
        Ok(Self {
            f_hz,
            fs_hz,
            start,
            n,
            noise,
            bins,
            table,
        })
    }

    fn channel(&self, what: &'static str, x: &[f64]) -> Result<Channel> {
        let w = window(what, x, self.start, self.n)?;
        let z = phasor(w, self.f_hz, self.fs_hz, self.start);
        let scale = 2.0 / self.n as f64;
        Ok(match (&self.noise, &self.table) {
            (NoiseEstimate::NeighbourBins(_), Some(t)) => Channel {
                phasor: z,
                bins: self.bins.iter().map(|&k| t.bin(w, k) * scale).collect(),
                residual: Vec::new(),
            },
            _ => {
                let mean = w.iter().sum::<f64>() / self.n as f64;
                Channel {
                    phasor: z,
                    bins: Vec::new(),
                    residual: residual(w, z, mean, self.f_hz, self.fs_hz, self.start),
                }
            }
        })
    }

    /// $A/B$ with the first-order variance of the module documentation.
    fn ratio(&self, what: &'static str, a: &Channel, b: &Channel) -> Result<Ratio> {
        let bn = b.phasor.norm_sqr();
        if !(bn > 0.0 && bn.is_finite()) {
            return Err(Error::numerical(
                "stepped-sine ratio",
                format!(
                    "the denominator phasor of {what} is zero at {} Hz; the channel carries no \
                     excitation at this frequency (check the excitation and the wiring)",
                    self.f_hz
                ),
            ));
        }
        let g = a.phasor / b.phasor;
        let num_var = match self.noise {
            NoiseEstimate::NeighbourBins(_) => {
                a.bins
                    .iter()
                    .zip(&b.bins)
                    .map(|(x, y)| (x - g * y).norm_sqr())
                    .sum::<f64>()
                    / a.bins.len() as f64
            }
            NoiseEstimate::White => {
                let s: f64 = a
                    .residual
                    .iter()
                    .zip(&b.residual)
                    .map(|(ea, eb)| (c64::new(*ea, 0.0) - g * eb).norm_sqr())
                    .sum();
                4.0 * s / (self.n as f64 * (self.n - 3) as f64)
            }
        };
        Ok(Ratio {
            value: g,
            variance: num_var / bn,
        })
    }
}

/// The ratio of the phasors of `num` and `den` at `f_hz` over `[start, start + n)`, with its
/// first-order variance (correlated errors of numerator and denominator included), e.g. an
/// open-loop FRF `y/u` or one closed-loop ratio.
///
/// # Errors
/// As [`lock_in`]; [`Error::InvalidArgument`] if the noise estimate cannot be formed (see
/// [`NoiseEstimate`]: `n < 4` for white, a window that is not a whole number of cycles or has no
/// usable neighbour bins); [`Error::Numerical`] if the denominator phasor is zero.
///
/// # Example
/// ```
/// use ambid_core::frf::stepped_sine::{phasor_ratio, NoiseEstimate};
/// let u: Vec<f64> = (0..1000).map(|k| (2.0 * std::f64::consts::PI * 0.01 * k as f64).sin()).collect();
/// let y: Vec<f64> = u.iter().map(|v| -2.0 * v).collect();
/// let g = phasor_ratio(&y, &u, 10.0, 1000.0, 0, 1000, NoiseEstimate::NeighbourBins(3)).unwrap();
/// assert!((g.value.re + 2.0).abs() < 1e-12 && g.std() < 1e-12);
/// ```
pub fn phasor_ratio(
    num: &[f64],
    den: &[f64],
    f_hz: f64,
    fs_hz: f64,
    start: usize,
    n: usize,
    noise: NoiseEstimate,
) -> Result<Ratio> {
    let g = Geometry::new(f_hz, fs_hz, start, n, noise)?;
    let a = g.channel("num", num)?;
    let b = g.channel("den", den)?;
    g.ratio("num/den", &a, &b)
}

/// One stepped-sine point in closed loop: the phasors of $r$, $u$, $y$ and the three ratios.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SinePoint {
    /// Frequency, Hz.
    pub f_hz: f64,
    /// Phasor of the excitation $r$.
    pub r: c64,
    /// Phasor of the recorded controller output $u$.
    pub u: c64,
    /// Phasor of the measured output $y$.
    pub y: c64,
    /// Process sensitivity $T_{ry} = Y/R$.
    pub t_ry: Ratio,
    /// Sensitivity $S = T_{ru} = U/R$.
    pub t_ru: Ratio,
    /// Plant $P = Y/U$ (joint input–output).
    pub plant: Ratio,
}

impl SinePoint {
    /// Locks in on `r`, `u`, `y` at `f_hz` over `[start, start + n)` and forms
    /// $T_{ry} = Y/R$, $T_{ru} = U/R$ and $P = Y/U$ with their first-order variances (see the
    /// [module documentation](self)).
    ///
    /// # Errors
    /// As [`phasor_ratio`] for each channel (the error names the channel: `r`, `u` or `y`).
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::stepped_sine::{NoiseEstimate, SinePoint};
    /// let fs = 1000.0;
    /// let r: Vec<f64> = (0..2000).map(|k| (2.0 * std::f64::consts::PI * 0.05 * k as f64).sin()).collect();
    /// let u: Vec<f64> = r.iter().map(|v| 0.5 * v).collect();   // S = 0.5
    /// let y: Vec<f64> = r.iter().map(|v| -0.1 * v).collect();  // T_ry = -0.1
    /// let p = SinePoint::estimate(&r, &u, &y, 50.0, fs, 1000, 1000, NoiseEstimate::White).unwrap();
    /// assert!((p.plant.value.re + 0.2).abs() < 1e-12);
    /// ```
    #[allow(clippy::too_many_arguments)]
    pub fn estimate(
        r: &[f64],
        u: &[f64],
        y: &[f64],
        f_hz: f64,
        fs_hz: f64,
        start: usize,
        n: usize,
        noise: NoiseEstimate,
    ) -> Result<SinePoint> {
        let g = Geometry::new(f_hz, fs_hz, start, n, noise)?;
        let cr = g.channel("r", r)?;
        let cu = g.channel("u", u)?;
        let cy = g.channel("y", y)?;
        Ok(SinePoint {
            f_hz,
            r: cr.phasor,
            u: cu.phasor,
            y: cy.phasor,
            t_ry: g.ratio("T_ry = y/r", &cy, &cr)?,
            t_ru: g.ratio("T_ru = u/r", &cu, &cr)?,
            plant: g.ratio("P = y/u", &cy, &cu)?,
        })
    }
}

/// Which closed-loop ratio.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// $T_{ry} = y/r$.
    TRy,
    /// $S = T_{ru} = u/r$.
    TRu,
    /// $P = y/u$.
    Plant,
}

/// A stepped-sine frequency response: the frequencies and, per quantity, the ratios with variances.
#[derive(Debug, Clone, PartialEq)]
pub struct SteppedSineResult {
    /// Frequencies, Hz (in the order of the points).
    pub f_hz: Vec<f64>,
    /// $T_{ry}$ per point.
    pub t_ry: Vec<Ratio>,
    /// $S = T_{ru}$ per point.
    pub t_ru: Vec<Ratio>,
    /// $P$ per point.
    pub plant: Vec<Ratio>,
}

impl SteppedSineResult {
    /// Collects points.
    pub fn from_points(points: &[SinePoint]) -> Self {
        Self {
            f_hz: points.iter().map(|p| p.f_hz).collect(),
            t_ry: points.iter().map(|p| p.t_ry).collect(),
            t_ru: points.iter().map(|p| p.t_ru).collect(),
            plant: points.iter().map(|p| p.plant).collect(),
        }
    }

    /// The ratios of one quantity.
    pub fn ratios(&self, q: Quantity) -> &[Ratio] {
        match q {
            Quantity::TRy => &self.t_ry,
            Quantity::TRu => &self.t_ru,
            Quantity::Plant => &self.plant,
        }
    }

    /// One quantity as frequency-response data with variance (sample time `ts`, `None` for
    /// unspecified).
    ///
    /// # Errors
    /// As [`Frd::new`]: in particular the frequencies must be strictly increasing, so plan them
    /// sorted and without duplicates.
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::stepped_sine::{Quantity, Ratio, SteppedSineResult};
    /// use ambid_core::c64;
    /// let one = Ratio { value: c64::new(1.0, 0.0), variance: 0.01 };
    /// let res = SteppedSineResult { f_hz: vec![1.0, 2.0], t_ry: vec![one; 2], t_ru: vec![one; 2], plant: vec![one; 2] };
    /// let frd = res.to_frd(Quantity::Plant, Some(1e-3)).unwrap();
    /// assert_eq!(frd.std().unwrap(), vec![0.1, 0.1]);
    /// ```
    pub fn to_frd(&self, q: Quantity, ts: Option<f64>) -> Result<Frd> {
        let r = self.ratios(q);
        Frd::new(
            self.f_hz.clone(),
            r.iter().map(|x| x.value).collect(),
            Some(r.iter().map(|x| x.variance).collect()),
            ts,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snap_bound_holds_and_windows_are_whole_cycles() {
        let fs = 20_000.0;
        let freqs: Vec<f64> = (0..200)
            .map(|i| 10.0 * 1.035f64.powi(i))
            .filter(|f| *f < 9_999.0)
            .collect();
        let plan = SteppedSinePlan::new(fs, &freqs, Settle::Cycles(3.0), 3, 0.02).unwrap();
        for p in plan.points() {
            let n_min = (0.02 * fs).max(3.0 * fs / p.f_requested_hz).ceil();
            assert!(p.measure_samples as f64 >= n_min - 1e-9, "{p:?}");
            assert!(p.cycles >= 3 && 2 * p.cycles < p.measure_samples);
            assert!(
                (p.f_hz - p.f_requested_hz).abs() <= p.f_requested_hz / (2.0 * n_min) + 1e-9,
                "{p:?}"
            );
            assert_eq!(p.f_hz, fs * p.cycles as f64 / p.measure_samples as f64);
            assert!(p.settle_samples as f64 >= 3.0 * fs / p.f_hz - 1e-9);
        }
    }

    #[test]
    fn near_nyquist_snaps_below_it() {
        let p = SteppedSinePlan::new(1000.0, &[499.999], Settle::Seconds(0.0), 1, 0.0).unwrap();
        let pt = p.points()[0];
        assert!(
            pt.f_hz < 500.0 && 2 * pt.cycles < pt.measure_samples,
            "{pt:?}"
        );
    }

    #[test]
    fn bins_match_a_direct_dft() {
        let n = 37;
        let t = RootTable::new(n);
        let x: Vec<f64> = (0..n).map(|i| ((i * i) % 11) as f64 - 3.0).collect();
        for k in [1, 5, 18] {
            let want: c64 = x
                .iter()
                .enumerate()
                .map(|(i, v)| c64::from_polar(*v, -2.0 * PI * (k * i) as f64 / n as f64))
                .sum();
            assert!((t.bin(&x, k) - want).norm() < 1e-12);
        }
    }

    #[test]
    fn harmonics_are_not_noise_bins() {
        let g = Geometry::new(100.0, 1000.0, 0, 100, NoiseEstimate::NeighbourBins(20)).unwrap();
        // m = 10: bins 20, 30, 40 skipped, 0 skipped, nothing ≥ 50
        assert!(g.bins.iter().all(|k| k % 10 != 0 && *k > 0 && *k < 50));
        assert_eq!(g.bins.len(), 9 + 18);
    }
}
