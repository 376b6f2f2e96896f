//! The Local Polynomial Method (LPM): frequency responses, transients and noise covariances from
//! one record — non-periodic, or periodic with whole periods (the periodic LPM, see [`lpm`]).
//!
//! # Model
//! The whole record of $N$ samples is transformed once, without a window,
//!
//! $$X(k) = \frac{1}{\sqrt N}\sum_{t=0}^{N-1} x(t)\, e^{-j 2\pi k t/N},\qquad
//!   f_k = k\,\frac{f_s}{N},\quad k = 1, \dots, \lfloor N/2 \rfloor$$
//!
//! (DC is not used). For a linear system with one input $u$ and $p$ outputs, the DFT of a finite
//! record obeys exactly $Y(k) = G(\Omega_k) U(k) + T(\Omega_k) + V(k)$, where the transient
//! $T$ (the leakage of the non-periodic signals, initial and final conditions) is as smooth in
//! $k$ as $G$. Around every line $k$ the LPM models both as complex polynomials of degree $R$ in
//! the line offset $r$,
//!
//! $$Y(k+r) = \sum_{s=0}^{R} g_s\, r^s\, U(k+r) + \sum_{s=0}^{R} t_s\, r^s + V(k+r),
//!   \qquad r \in \{r_0, \dots, r_0 + 2n\},$$
//!
//! on a window of $w = 2n+1$ consecutive lines (centred, $r_0 = -n$, except at the ends of the
//! grid, where the window is shifted so that it stays inside $1..\lfloor N/2\rfloor$; the
//! estimate is still the value at $r = 0$). Stacking the window gives $Y_w = K\theta + V_w$ with
//! the $w \times 2(R+1)$ regressor $K = [\,U \odot r^s,\ r^s\,]$, solved per line and per output by
//! least squares; $\hat G(k) = \hat g_0$ and $\hat T(k) = \hat t_0$.
//!
//! # Noise and FRF covariance
//! With the residuals $E = Y_w - K\hat\theta$ ($w \times p$) and $q = w - 2(R+1)$ degrees of
//! freedom (one input: $q = 2n + 1 - (R+1)(m+1)$ with $m = 1$),
//!
//! $$\hat C_V(k) = \frac{1}{q}\, E^{\mathsf T} \bar E \quad (p \times p),\qquad
//!   \operatorname{Cov}\big(\hat G(k)\big) = \big[(K^{\mathsf H}K)^{-1}\big]_{00}\, \hat C_V(k),$$
//!
//! the $(0,0)$ block of $(K^{\mathsf H}K)^{-1} \otimes \hat C_V$ (Pintelon et al. 2010, Part I).
//! $\hat C_V$ is the noise covariance $\mathrm E[V(k)V(k)^{\mathsf H}]$ of one DFT line in the
//! scaling above (for white noise of variance $\sigma^2$ it is $\sigma^2$; in general the
//! two-sided power spectral density times $f_s$). The variances stored in the returned [`Frd`]s are
//! $\mathrm E|\hat G - G|^2$, as everywhere in `ambid`; with $q$ complex degrees of freedom the
//! level-$\alpha$ confidence disc has the radius factor of
//! [`band_radius_factor`]`(α, q)`.
//!
//! # Closed loop
//! [`lpm_closed_loop`] takes the excitation $r$ as the input and $[y, u]$ as the two outputs
//! (conventions of [`closed_loop`](super::closed_loop): $T_{ry} = P/(1+PC)$, $S = T_{ru} =
//! 1/(1+PC)$), so the regressor is noise-free, and forms the plant $P = T_{ry}/T_{ru}$ with the
//! first-order variance including the cross covariance,
//!
//! $$\sigma_P^2 = \frac{\sigma^2_{T_{ry}} + |P|^2\sigma^2_{T_{ru}}
//!   - 2\,\mathrm{Re}\big(\bar P\, \Sigma_{T_{ry}T_{ru}}\big)}{|T_{ru}|^2}.$$
//!
//! # Algorithm and complexity
//! One real FFT per channel ($O(N\log N)$), then $O(w\,(R + p))$ work per line. The regressor's
//! powers of $r$ depend only on the window's shift, so they are tabulated once (scaled as
//! $x = r/n$ for conditioning; this changes the coefficients $g_s, t_s$ for $s \ge 1$, not
//! $\hat G$, $\hat T$, the residuals or $[(K^{\mathsf H}K)^{-1}]_{00}$). $K^{\mathsf H}K$ is
//! assembled from $4R + 2$ moments $\sum |U|^2 x^e$, $\sum \bar U x^e$ (the transient block is
//! tabulated), equilibrated to a unit diagonal and factored by a complex Cholesky
//! decomposition; residuals are formed explicitly. No allocation happens per line. On
//! $10^5$ samples (all $5\cdot 10^4$ lines) a SISO fit takes ≈ 30 ms, two outputs ≈ 40 ms
//! (≈ 0.5–0.8 µs per line; the FFTs are < 2 %); see `benches/lpm.rs` and `docs/lpm.md`.
//!
//! # Requirements
//! * the input must excite the band: lines whose window holds less than [`EXCITED_FRACTION`]
//!   of the input's average line power are left out ([`Lpm::excluded_lines`]), and a band
//!   without any excited line is an error;
//! * $G$ and $T$ must be smooth on the scale of the window, $2n+1$ lines of $f_s/N$: the
//!   polynomial approximation error (bias) grows like $(w/B)^{R+1}$ where $B$ is the 3 dB width
//!   of the sharpest resonance in lines; with lightly damped modes use long records;
//! * noise $V$ with a spectrum smooth over the window (any filtered white noise).
//!
//! # Reference
//! R. Pintelon, J. Schoukens, G. Vandersteen, K. Barbé, "Estimation of nonparametric noise and
//! FRF models for multivariable systems — Part I: Theory", *Mechanical Systems and Signal
//! Processing* 24(3), 573–595, 2010. R. Pintelon, J. Schoukens, *System Identification: A
//! Frequency Domain Approach*, 2nd ed., Wiley–IEEE Press, 2012, ch. 7.
//!
//! # Example
//! ```
//! use ambid_core::frf::lpm::{lpm, LpmOptions};
//! use rand::{RngExt, SeedableRng};
//! use rand_chacha::ChaCha8Rng;
//! // y(t) = u(t) + 0.5 u(t−1), started from u(−1) = 3 (a transient), no noise
//! let n = 4096;
//! let mut rng = ChaCha8Rng::seed_from_u64(1);
//! let u: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
//! let y: Vec<f64> = (0..n).map(|t| u[t] + 0.5 * if t == 0 { 3.0 } else { u[t - 1] }).collect();
//! let fs = 1000.0;
//! let est = lpm(&u, &[&y], fs, (10.0, 400.0), &LpmOptions::default()).unwrap();
//! let g = est.frf(0).unwrap();
//! for (f, v) in g.f_hz().iter().zip(g.values()) {
//!     let z = ambid_core::c64::cis(-2.0 * std::f64::consts::PI * f / fs);
//!     let truth = 1.0 + z * 0.5;
//!     assert!((v - truth).norm() < 1e-6 * truth.norm());
//! }
//! assert_eq!(est.dof(), 3);
//! ```

use super::closed_loop::band_radius_factor;
use crate::error::{check_finite, Error, Result};
use crate::lti::Frd;
use faer::c64;
use realfft::RealFftPlanner;

/// Degree $R$ and half width $n$ of the local polynomial model, fixed or chosen from the data.
///
/// [`LpmOptions::default`] is the fixed smallest window ($R = 2$, $n = 4$, $q = 3$), meant for
/// short records and sharp features. [`LpmOptions::auto`] chooses $(R, n)$ from the record (its
/// length, its signal-to-noise ratio and how fast the response changes): the rule is in
/// [`lpm`]'s docs and `docs/lpm.md`. `ambid frf --method lpm` uses `auto` unless a degree or half
/// width is given.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LpmOptions {
    degree: usize,
    half_width: Option<usize>,
    auto: bool,
}

impl Default for LpmOptions {
    /// $R = 2$ and the smallest window with $q \ge 3$ degrees of freedom ($n = R + 2 = 4$,
    /// $w = 9$ lines).
    fn default() -> Self {
        Self {
            degree: 2,
            half_width: None,
            auto: false,
        }
    }
}

/// Candidate degrees and half widths of [`LpmOptions::auto`]: $R \in \{1, 2\}$ and
/// $n \in \{R + 2, 6, 8, 11, 16, 22, 32, 45, 64\}$ (windows of $2R + 5$ to 129 lines, geometric
/// steps of ≈ 1.4).
pub const AUTO_CANDIDATES: [(usize, usize); 18] = [
    (1, 3),
    (1, 6),
    (1, 8),
    (1, 11),
    (1, 16),
    (1, 22),
    (1, 32),
    (1, 45),
    (1, 64),
    (2, 4),
    (2, 6),
    (2, 8),
    (2, 11),
    (2, 16),
    (2, 22),
    (2, 32),
    (2, 45),
    (2, 64),
];

impl LpmOptions {
    /// The default options ($R = 2$, $n = 4$).
    pub fn new() -> Self {
        Self::default()
    }

    /// A window chosen from the data: among [`AUTO_CANDIDATES`] the $(R, n)$ with the smallest
    /// leave-one-out error (see [`lpm`]). For a periodic record the transient window is set by
    /// the number of periods (see [`lpm`]) with $R = 2$.
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::lpm::{lpm, LpmOptions};
    /// use rand::{RngExt, SeedableRng};
    /// use rand_chacha::ChaCha8Rng;
    /// let mut rng = ChaCha8Rng::seed_from_u64(3);
    /// let fs = 1000.0;
    /// let truth = |f: f64| 1.0 + ambid_core::c64::cis(-2.0 * std::f64::consts::PI * f / fs) * 0.5;
    /// // y(t) = u(t) + 0.5 u(t−1), started from rest
    /// let fir = |u: &[f64]| -> Vec<f64> {
    ///     (0..u.len()).map(|t| u[t] + 0.5 * if t > 0 { u[t - 1] } else { 0.0 }).collect()
    /// };
    /// // a non-periodic record: the window is chosen from the data
    /// let u: Vec<f64> = (0..8192).map(|_| rng.random_range(-1.0..1.0)).collect();
    /// let est = lpm(&u, &[&fir(&u)], fs, (5.0, 450.0), &LpmOptions::auto()).unwrap();
    /// assert!(est.window_chosen() && est.periods().is_none());
    /// let g = est.frf(0).unwrap();
    /// assert!(g.f_hz().iter().zip(g.values()).all(|(f, v)| (v - truth(*f)).norm() < 1e-6));
    /// // 4 periods of 1024 samples: the periodic LPM on every 4th line
    /// let one: Vec<f64> = (0..1024).map(|_| rng.random_range(-1.0..1.0)).collect();
    /// let u: Vec<f64> = (0..4096).map(|t| one[t % 1024]).collect();
    /// let est = lpm(&u, &[&fir(&u)], fs, (5.0, 450.0), &LpmOptions::auto()).unwrap();
    /// assert_eq!(est.periods(), Some(4));
    /// assert!(est.lines().iter().all(|k| k % 4 == 0));
    /// ```
    pub fn auto() -> Self {
        Self {
            degree: 2,
            half_width: None,
            auto: true,
        }
    }

    /// Whether the window is chosen from the data ([`LpmOptions::auto`]).
    pub fn is_auto(&self) -> bool {
        self.auto
    }

    /// Sets the polynomial degree $R$ of $G$ and $T$ (the half width follows it unless set); the
    /// window is then fixed (not [`auto`](Self::auto)).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for $R > 8$ (the local fit would need windows of ≥ 21 lines and
    /// becomes ill-conditioned; use a longer record instead).
    pub fn with_degree(mut self, degree: usize) -> Result<Self> {
        if degree > 8 {
            return Err(Error::invalid(
                "degree",
                format!("the local polynomial degree must be at most 8, got {degree}; 2 is usual"),
            ));
        }
        self.degree = degree;
        self.auto = false;
        Ok(self)
    }

    /// Sets the half width $n$ (window of $2n+1$ lines); the window is then fixed (not
    /// [`auto`](Self::auto)).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the window leaves no degree of freedom,
    /// $q = 2n + 1 - 2(R+1) < 1$ (set the degree first).
    pub fn with_half_width(mut self, half_width: usize) -> Result<Self> {
        self.half_width = Some(half_width);
        self.auto = false;
        self.dof().map(|_| self)
    }

    /// Polynomial degree $R$.
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Half width $n$: the one set, else the smallest with $q \ge 3$, i.e. $R + 2$.
    pub fn half_width(&self) -> usize {
        self.half_width.unwrap_or(self.degree + 2)
    }

    /// Window length $2n + 1$.
    pub fn window(&self) -> usize {
        2 * self.half_width() + 1
    }

    /// Degrees of freedom $q = 2n + 1 - 2(R + 1)$ of the residuals (one input).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when $q < 1$.
    pub fn dof(&self) -> Result<usize> {
        let (w, np) = (self.window(), 2 * (self.degree + 1));
        if w <= np {
            return Err(Error::invalid(
                "half_width",
                format!(
                    "a window of {w} lines leaves no degree of freedom for {np} parameters (degree {}); \
                     need 2n + 1 > 2(R + 1), i.e. n ≥ {}",
                    self.degree,
                    self.degree + 1
                ),
            ));
        }
        Ok(w - np)
    }
}

/// The estimated lines of a local fit (LPM or LRM) and access to its line-major per-output
/// storage (`v[l * p + o]` per output, `v[(l * p + o1) * p + o2]` per pair of outputs).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct LineGrid {
    pub f_hz: Vec<f64>,
    pub lines: Vec<usize>,
    pub record_len: usize,
    pub ts: f64,
    pub n_out: usize,
}

impl LineGrid {
    /// The lines `lines` of a record of `record_len` samples at `fs` Hz, with `n_out` outputs.
    pub fn new(lines: Vec<usize>, record_len: usize, fs: f64, n_out: usize) -> Self {
        let df = fs / record_len as f64;
        Self {
            f_hz: lines.iter().map(|&k| k as f64 * df).collect(),
            lines,
            record_len,
            ts: 1.0 / fs,
            n_out,
        }
    }

    pub fn check_output(&self, o: usize) -> Result<()> {
        if o >= self.n_out {
            return Err(Error::invalid(
                "output",
                format!(
                    "output {o} requested but the fit has {} output(s)",
                    self.n_out
                ),
            ));
        }
        Ok(())
    }

    /// `v[l * p + o]` for every line.
    pub fn of_output<T: Copy>(&self, v: &[T], o: usize) -> Result<Vec<T>> {
        self.check_output(o)?;
        let p = self.n_out;
        Ok((0..self.lines.len()).map(|l| v[l * p + o]).collect())
    }

    /// `v[(l * p + o1) * p + o2]` for every line.
    pub fn of_pair<T: Copy>(&self, v: &[T], o1: usize, o2: usize) -> Result<Vec<T>> {
        self.check_output(o1)?;
        self.check_output(o2)?;
        let p = self.n_out;
        Ok((0..self.lines.len())
            .map(|l| v[(l * p + o1) * p + o2])
            .collect())
    }

    /// An [`Frd`] on these lines.
    pub fn frd(&self, values: Vec<c64>, variance: Vec<f64>) -> Result<Frd> {
        Frd::new(self.f_hz.clone(), values, Some(variance), Some(self.ts))
    }
}

/// The LPM fit of one input and $p$ outputs on the lines of a band; see the [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct Lpm {
    grid: LineGrid,
    degree: usize,
    half_width: usize,
    dof: usize,
    /// line-major, `g[l * p + o]`
    g: Vec<c64>,
    transient: Vec<c64>,
    /// `noise_cov[(l * p + o1) * p + o2]` = Ĉ_V(o1, o2)
    noise_cov: Vec<c64>,
    /// $[(K^H K)^{-1}]_{00}$ per line
    c00: Vec<f64>,
    /// lines of the band left out: too little input power
    excluded: Vec<usize>,
    /// number of periods of a periodic input (periodic LPM), else `None`
    periods: Option<usize>,
    /// the window was chosen from the data
    auto: bool,
}

impl Lpm {
    /// Frequencies of the estimated lines \[Hz\].
    pub fn f_hz(&self) -> &[f64] {
        &self.grid.f_hz
    }
    /// DFT line indices $k$ of the estimates ($f_k = k f_s/N$).
    pub fn lines(&self) -> &[usize] {
        &self.grid.lines
    }
    /// Record length $N$.
    pub fn record_len(&self) -> usize {
        self.grid.record_len
    }
    /// Number of outputs $p$.
    pub fn n_outputs(&self) -> usize {
        self.grid.n_out
    }
    /// Polynomial degree $R$ used.
    pub fn degree(&self) -> usize {
        self.degree
    }
    /// Half width $n$ used.
    pub fn half_width(&self) -> usize {
        self.half_width
    }
    /// Residual degrees of freedom $q$ (complex) of the noise covariance estimates.
    pub fn dof(&self) -> usize {
        self.dof
    }
    /// Lines of the requested band that were left out because the input has too little power
    /// there (below [`EXCITED_FRACTION`] of its average; see [`lpm`]). For a periodic input this
    /// includes only the band's multiples of the number of periods that carry no power, not the
    /// non-excited lines between them.
    pub fn excluded_lines(&self) -> &[usize] {
        &self.excluded
    }
    /// `Some(P)` when the input was found periodic with $P$ periods in the record and the
    /// periodic LPM was used (estimates on the excited lines $k = P, 2P, \dots$ only).
    pub fn periods(&self) -> Option<usize> {
        self.periods
    }
    /// Whether $(R, n)$ were chosen from the data ([`LpmOptions::auto`]).
    pub fn window_chosen(&self) -> bool {
        self.auto
    }

    /// $\hat G_o(k)$ with its variance $[(K^{\mathsf H}K)^{-1}]_{00}\,\hat C_{V,oo}$.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an output index out of range.
    pub fn frf(&self, o: usize) -> Result<Frd> {
        let vals = self.grid.of_output(&self.g, o)?;
        let var = self
            .grid
            .of_pair(&self.noise_cov, o, o)?
            .iter()
            .zip(&self.c00)
            .map(|(c, k)| k * c.re)
            .collect();
        self.grid.frd(vals, var)
    }

    /// The estimated transient $\hat T_o(k)$ (DFT scaling of the [module docs](self)).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an output index out of range.
    pub fn transient(&self, o: usize) -> Result<Vec<c64>> {
        self.grid.of_output(&self.transient, o)
    }

    /// Noise covariance $\hat C_V(k)_{o_1 o_2} = \mathrm E[V_{o_1}(k)\overline{V_{o_2}(k)}]$ per line.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an output index out of range.
    pub fn noise_cov(&self, o1: usize, o2: usize) -> Result<Vec<c64>> {
        self.grid.of_pair(&self.noise_cov, o1, o2)
    }

    /// Covariance $\mathrm E[\delta\hat G_{o_1}(k)\,\overline{\delta\hat G_{o_2}(k)}]$ per line.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an output index out of range.
    pub fn frf_cov(&self, o1: usize, o2: usize) -> Result<Vec<c64>> {
        let v = self.noise_cov(o1, o2)?;
        Ok(v.iter().zip(&self.c00).map(|(c, k)| c * *k).collect())
    }

    /// Radius factor of the level-`level` confidence disc for $q$ degrees of freedom.
    ///
    /// # Errors
    /// As [`band_radius_factor`].
    pub fn band_factor(&self, level: f64) -> Result<f64> {
        band_radius_factor(level, self.dof as f64)
    }
}

/// A local fit (LPM or LRM) with residual degrees of freedom.
pub trait LocalFit {
    /// Residual degrees of freedom $q$ of the noise covariance estimates.
    fn dof(&self) -> usize;
}

impl LocalFit for Lpm {
    fn dof(&self) -> usize {
        self.dof
    }
}

/// Closed-loop FRFs by a local method (the LPM here, the [LRM](super::lrm) too) with $r$ as the
/// input and $[y, u]$ as outputs.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalClosedLoop<F> {
    /// $T_{ry}$ with its variance.
    pub t_ry: Frd,
    /// $S = T_{ru}$ with its variance.
    pub t_ru: Frd,
    /// The plant $P = T_{ry}/T_{ru}$ with the first-order variance (cross covariance included).
    pub plant: Frd,
    /// $\mathrm E[\delta T_{ry}\,\overline{\delta T_{ru}}]$ per line.
    pub cov_ry_ru: Vec<c64>,
    /// The underlying SIMO fit (output 0 is $y$, output 1 is $u$): transients, noise covariances.
    pub fit: F,
}

/// Closed-loop FRFs by the LPM.
pub type LpmClosedLoop = LocalClosedLoop<Lpm>;

impl<F: LocalFit> LocalClosedLoop<F> {
    /// Frequencies \[Hz\].
    pub fn f_hz(&self) -> &[f64] {
        self.plant.f_hz()
    }
    /// Residual degrees of freedom $q$.
    pub fn dof(&self) -> usize {
        self.fit.dof()
    }
    /// Radius factor of the level-`level` confidence disc.
    ///
    /// # Errors
    /// As [`band_radius_factor`].
    pub fn band_factor(&self, level: f64) -> Result<f64> {
        band_radius_factor(level, self.fit.dof() as f64)
    }

    /// Assembles the closed-loop result from the SIMO fit's $T_{ry}$, $T_{ru}$ and their cross
    /// covariance (plant by [`ratio_plant`]).
    pub(super) fn assemble(
        fit: F,
        t_ry: Frd,
        t_ru: Frd,
        cov: Vec<c64>,
        ts: f64,
        what: &'static str,
    ) -> Result<Self> {
        let plant = ratio_plant(&t_ry, &t_ru, &cov, ts, what)?;
        Ok(Self {
            t_ry,
            t_ru,
            plant,
            cov_ry_ru: cov,
            fit,
        })
    }
}

/// Fraction of the average input line power below which a line counts as not excited (−20 dB).
///
/// Non-periodic input: a line is estimated when the mean $|U|^2$ over its window is at least
/// this fraction of the mean $|U(k)|^2$ over all lines $1..\lfloor N/2\rfloor$. Periodic input
/// with $P$ periods: an excited line $k = lP$ is estimated when $|U(k)|^2$ is at least this
/// fraction of the mean over all multiples of $P$. Lines below it are left out and reported
/// ([`Lpm::excluded_lines`]); at −20 dB the FRF error there would be ten times the record's
/// typical one (e.g. the nulls of a PRBS at multiples of $f_s/N_b$, or above a chirp's end).
pub const EXCITED_FRACTION: f64 = 1e-2;

/// The LPM of outputs `ys` on input `u` (equal lengths, finite), sampled at `fs` Hz, on the DFT
/// lines in `band` = $[f_{\min}, f_{\max}]$ Hz.
///
/// # Lines, periodic inputs and the window
/// * **Excited lines only**: lines of the band where the input has less than
///   [`EXCITED_FRACTION`] of its average line power are left out and listed in
///   [`Lpm::excluded_lines`] (not an error unless no line is left).
/// * **Periodic input** (detected: every DFT line with more than $10^{-10}$ of the largest line
///   power is a multiple of some $P \ge 2$, i.e. the record holds $P$ whole periods; or, for a
///   measured input with noise, $P$ is the largest divisor of $N$ with less than
///   [`PERIODIC_OFF_FRACTION`] = $10^{-3}$ of the input power off the multiples of $P$): the
///   non-excited lines carry only transient and noise, so the *periodic LPM* is used
///   (Pintelon et al. 2011, "Part II"): around each excited line $k$ a polynomial of degree $R$
///   (2 in [`LpmOptions::auto`]) is fitted to the $m = \max(2(P-1),\, 2(R+1)+6)$ nearest
///   non-excited lines of every output; its value at $k$ is the transient $\hat T(k)$ and its
///   residuals give $\hat C_V$ with $q = m - (R + 1)$; then
///   $\hat G(k) = (Y(k) - \hat T(k))/U(k)$ with
///   $\operatorname{Cov}\hat G = (1 + [(A^{\mathsf T}A)^{-1}]_{00})\,\hat C_V/|U(k)|^2$.
///   Only the excited lines in the band are returned ([`Lpm::periods`] is `Some(P)`).
/// * **Automatic window** ([`LpmOptions::auto`], non-periodic input): every $(R, n)$ of
///   [`AUTO_CANDIDATES`] is fitted on up to 1500 lines spread over the excited band, and the
///   one with the smallest mean of $\ln\big([(K^{\mathsf H}K)^{-1}]_{00}\hat C_{V,oo}\big) -
///   (\psi(q) - \ln q)$ over lines and outputs is used ($\psi$ the digamma function; the term
///   removes the bias of the log of a $q$-degree-of-freedom variance estimate). This is the
///   estimated variance of $\hat G$: it falls with the window length (more lines, less noise)
///   until the polynomial no longer follows $G$ and $T$, when the residuals — and so
///   $\hat C_V$ — grow with the model error. The choice therefore follows the record length
///   (lines per hertz), the SNR and the sharpness of the response.
///
/// # Errors
/// * [`Error::InvalidArgument`]: no output, `fs` not positive and finite, options with $q < 1$,
///   fewer lines in the record than the window needs, a band without a DFT line in
///   $1..\lfloor N/2\rfloor$, or no excited line in the band;
/// * [`Error::DimensionMismatch`]: channels of different lengths;
/// * [`Error::NonFinite`]: a NaN or infinite sample;
/// * [`Error::Numerical`]: every local regressor of the band is rank deficient (the input is
///   locally a polynomial in the line index, e.g. a single sine).
pub fn lpm(u: &[f64], ys: &[&[f64]], fs: f64, band: (f64, f64), opts: &LpmOptions) -> Result<Lpm> {
    lpm_named(u, ys, fs, band, opts, "u")
}

/// [`lpm`] with the input's name for the error messages (`r` in closed loop).
fn lpm_named(
    u: &[f64],
    ys: &[&[f64]],
    fs: f64,
    band: (f64, f64),
    opts: &LpmOptions,
    input: &'static str,
) -> Result<Lpm> {
    opts.dof()?;
    let min_w = if opts.is_auto() {
        AUTO_CANDIDATES
            .iter()
            .map(|c| 2 * c.1 + 1)
            .min()
            .unwrap_or(7)
    } else {
        opts.window()
    };
    let prep = prepare(u, ys, fs, band, min_w, input)?;
    let p = ys.len();
    if let Some(periods) = prep.periods {
        return lpm_periodic(
            &prep,
            p,
            opts.degree(),
            periods,
            band,
            input,
            opts.is_auto(),
        );
    }
    let (degree, half) = if opts.is_auto() {
        choose_window(&prep, p)?
    } else {
        (opts.degree(), opts.half_width())
    };
    let w = 2 * half + 1;
    let q = w - 2 * (degree + 1);
    let (kept, mut excluded) = split_excited(&prep, half);
    if kept.is_empty() {
        return Err(no_power_error(band, input));
    }
    let yref: Vec<&[c64]> = prep.yf.iter().map(|v| v.as_slice()).collect();
    let mut fit = Fitter::new(degree, half, p, 1e-14 * w as f64 * prep.mean_power);
    let nl = kept.len();
    let mut lines = Vec::with_capacity(nl);
    let mut g = Vec::with_capacity(nl * p);
    let mut tr = Vec::with_capacity(nl * p);
    let mut cv = Vec::with_capacity(nl * p * p);
    let mut c00 = Vec::with_capacity(nl);
    let mut first_rank_deficient = None;
    for &k in &kept {
        match fit.fit_line(&prep.uf, &yref, k, prep.n_lines) {
            Ok(c) => {
                lines.push(k);
                c00.push(c);
                g.extend_from_slice(&fit.g_out);
                tr.extend_from_slice(&fit.t_out);
                cv.extend_from_slice(&fit.cov_out);
            }
            Err(_) => {
                first_rank_deficient.get_or_insert(k);
                excluded.push(k);
            }
        }
    }
    if lines.is_empty() {
        let k = first_rank_deficient.unwrap_or(kept[0]);
        return Err(Error::numerical(
            "LPM",
            format!(
                "the local regressor is rank deficient on every line of the band (first at line {k}, \
                 {:.4} Hz): the input {input} is locally a polynomial in the line index (e.g. a single \
                 sine or a sparse multisine); use a broadband excitation or a smaller degree",
                k as f64 * prep.df
            ),
        ));
    }
    excluded.sort_unstable();
    Ok(Lpm {
        grid: LineGrid::new(lines, prep.n, fs, p),
        degree,
        half_width: half,
        dof: q,
        g,
        transient: tr,
        noise_cov: cv,
        c00,
        excluded,
        periods: None,
        auto: opts.is_auto(),
    })
}

/// The error for a band without an excited line (non-periodic input).
pub(super) fn no_power_error(band: (f64, f64), input: &'static str) -> Error {
    Error::invalid(
        input,
        format!(
            "the input {input} has no power in {}–{} Hz: on every line there its local power is below \
             {} % of its average line power; set the band to where {input} is excited",
            band.0,
            band.1,
            100.0 * EXCITED_FRACTION
        ),
    )
}

/// First line of the window of `w = 2 half + 1` lines around `k`, inside `1..=n_lines`.
pub(super) fn window_lo(k: usize, half: usize, n_lines: usize) -> usize {
    let w = 2 * half + 1;
    if k < 1 + half {
        1
    } else if k + half > n_lines {
        n_lines + 1 - w
    } else {
        k - half
    }
}

/// The band's lines whose window mean input power reaches [`EXCITED_FRACTION`] of the average
/// line power, and the others.
pub(super) fn split_excited(prep: &Prepared, half: usize) -> (Vec<usize>, Vec<usize>) {
    let w = 2 * half + 1;
    let thr = EXCITED_FRACTION * prep.mean_power * w as f64;
    // prefix sums of |U|² for the window sums
    let mut cum = vec![0.0; prep.n_lines + 2];
    for k in 1..=prep.n_lines {
        cum[k + 1] = cum[k] + prep.uf[k].norm_sqr();
    }
    prep.lines.iter().partition(|&&k| {
        let lo = window_lo(k, half, prep.n_lines);
        cum[lo + w] - cum[lo] >= thr
    })
}

/// The automatic $(R, n)$ of [`lpm`] (non-periodic input): the smallest mean log leave-one-out
/// error of the line itself.
fn choose_window(prep: &Prepared, p: usize) -> Result<(usize, usize)> {
    let (kept, _) = split_excited(prep, 4.min(prep.n_lines.saturating_sub(1) / 2));
    if kept.is_empty() {
        return Ok((2, 4));
    }
    let stride = kept.len().div_ceil(AUTO_LINES).max(1);
    let yref: Vec<&[c64]> = prep.yf.iter().map(|v| v.as_slice()).collect();
    let mut best: Option<(f64, usize, usize)> = None;
    for &(r, n) in AUTO_CANDIDATES.iter() {
        let w = 2 * n + 1;
        if w > prep.n_lines {
            continue;
        }
        let mut fit = Fitter::new(r, n, p, 1e-14 * w as f64 * prep.mean_power);
        let (mut sum, mut cnt) = (0.0, 0usize);
        for &k in kept.iter().step_by(stride) {
            if fit.fit_line(&prep.uf, &yref, k, prep.n_lines).is_err() {
                continue;
            }
            let j = k - window_lo(k, n, prep.n_lines);
            let h = fit.center_leverage(prep.uf[k]);
            if h.is_nan() || h >= 1.0 - 1e-9 {
                continue;
            }
            for o in 0..p {
                let e = fit.res[j * p + o].norm_sqr() / ((1.0 - h) * (1.0 - h));
                if e > 0.0 && e.is_finite() {
                    sum += e.ln();
                    cnt += 1;
                }
            }
        }
        if cnt == 0 {
            continue;
        }
        let j = sum / cnt as f64;
        if best.is_none_or(|b| j < b.0) {
            best = Some((j, r, n));
        }
    }
    Ok(best.map_or((2, 4), |b| (b.1, b.2)))
}

/// Lines scored per candidate window by [`LpmOptions::auto`] (spread evenly over the excited
/// band).
const AUTO_LINES: usize = 4000;

/// The periodic LPM of [`lpm`] on the excited lines (multiples of `periods`) of the band.
fn lpm_periodic(
    prep: &Prepared,
    p: usize,
    degree: usize,
    periods: usize,
    band: (f64, f64),
    input: &'static str,
    auto: bool,
) -> Result<Lpm> {
    let pp = periods;
    let n_lines = prep.n_lines;
    let candidates: Vec<usize> = prep.lines.iter().copied().filter(|k| k % pp == 0).collect();
    let mults = n_lines / pp;
    let ref_power =
        (1..=mults).map(|l| prep.uf[l * pp].norm_sqr()).sum::<f64>() / mults.max(1) as f64;
    let (kept, excluded): (Vec<usize>, Vec<usize>) = candidates
        .iter()
        .partition(|&&k| prep.uf[k].norm_sqr() >= EXCITED_FRACTION * ref_power);
    let period_samples = prep.n / pp;
    if kept.is_empty() {
        return Err(Error::invalid(
            input,
            format!(
                "the input {input} is periodic ({pp} periods of {period_samples} samples): it is excited \
                 only on every {pp}-th DFT line ({:.4} Hz apart) and none of those in {}–{} Hz has power; \
                 widen the band, or use period averaging (`--period-samples {period_samples}`)",
                pp as f64 * prep.df,
                band.0,
                band.1
            ),
        ));
    }
    let r1 = degree + 1;
    let m = (2 * (pp - 1)).max(2 * r1 + 6);
    if n_lines - mults < m {
        return Err(Error::invalid(
            input,
            format!(
                "the input {input} is periodic ({pp} periods of {period_samples} samples), but the record \
                 has only {} non-excited lines, fewer than the {m} the periodic LPM needs for the noise; \
                 use period averaging (`--period-samples {period_samples}`)",
                n_lines - mults
            ),
        ));
    }
    let q = m - r1;
    let zero = c64::new(0.0, 0.0);
    let nl = kept.len();
    let (mut g, mut tr, mut cv, mut c00) = (
        Vec::with_capacity(nl * p),
        Vec::with_capacity(nl * p),
        Vec::with_capacity(nl * p * p),
        Vec::with_capacity(nl),
    );
    let mut offs: Vec<isize> = Vec::with_capacity(m + 1);
    let mut xs = vec![0.0; m];
    let mut mat = vec![0.0; r1 * r1];
    let mut theta = vec![zero; r1];
    let mut res = vec![zero; m * p];
    for &k in &kept {
        // the m nearest non-excited lines inside 1..=n_lines
        offs.clear();
        let mut d = 1usize;
        while offs.len() < m && d <= n_lines {
            if d % pp != 0 {
                if k > d {
                    offs.push(-(d as isize));
                }
                if k + d <= n_lines && offs.len() < m {
                    offs.push(d as isize);
                }
            }
            d += 1;
        }
        let dmax = offs.iter().map(|o| o.unsigned_abs()).max().unwrap_or(1) as f64;
        for (x, o) in xs.iter_mut().zip(&offs) {
            *x = *o as f64 / dmax;
        }
        // normal matrix A^T A of the powers x^s, s = 0..R, and its inverse
        for a in 0..r1 {
            for b in 0..r1 {
                mat[a * r1 + b] = xs.iter().map(|x| x.powi((a + b) as i32)).sum();
            }
        }
        let inv = small_spd_inverse(&mat, r1).ok_or_else(|| {
            Error::numerical(
                "periodic LPM",
                format!("the transient fit around line {k} is singular; use a smaller degree"),
            )
        })?;
        let ct = inv[0];
        let uk = prep.uf[k];
        for (o, yo) in prep.yf.iter().enumerate() {
            for (a, t) in theta.iter_mut().enumerate() {
                *t = (0..r1)
                    .map(|b| {
                        let rb: c64 = offs
                            .iter()
                            .zip(&xs)
                            .map(|(off, x)| yo[(k as isize + off) as usize] * x.powi(b as i32))
                            .sum();
                        rb * inv[a * r1 + b]
                    })
                    .sum();
            }
            for (j, (off, x)) in offs.iter().zip(&xs).enumerate() {
                let fitted: c64 = (0..r1).map(|a| theta[a] * x.powi(a as i32)).sum();
                res[j * p + o] = yo[(k as isize + off) as usize] - fitted;
            }
            tr.push(theta[0]);
            g.push((yo[k] - theta[0]) / uk);
        }
        for o1 in 0..p {
            for o2 in 0..p {
                let s: c64 = (0..m)
                    .map(|j| res[j * p + o1] * res[j * p + o2].conj())
                    .sum();
                cv.push(s / q as f64);
            }
        }
        c00.push((1.0 + ct) / uk.norm_sqr());
    }
    Ok(Lpm {
        grid: LineGrid::new(kept, prep.n, prep.fs, p),
        degree,
        half_width: m / 2,
        dof: q,
        g,
        transient: tr,
        noise_cov: cv,
        c00,
        excluded,
        periods: Some(pp),
        auto,
    })
}

/// The inverse of a small symmetric positive definite matrix (Gauss–Jordan with partial
/// pivoting), or `None` when it is singular.
fn small_spd_inverse(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut m = a.to_vec();
    let mut inv = vec![0.0; n * n];
    for i in 0..n {
        inv[i * n + i] = 1.0;
    }
    let scale = (0..n).map(|i| a[i * n + i].abs()).fold(0.0, f64::max);
    for c in 0..n {
        let piv = (c..n).max_by(|&i, &j| m[i * n + c].abs().total_cmp(&m[j * n + c].abs()))?;
        if m[piv * n + c].abs() <= 1e-13 * scale {
            return None;
        }
        for j in 0..n {
            m.swap(c * n + j, piv * n + j);
            inv.swap(c * n + j, piv * n + j);
        }
        let d = m[c * n + c];
        for j in 0..n {
            m[c * n + j] /= d;
            inv[c * n + j] /= d;
        }
        for i in 0..n {
            if i != c {
                let f = m[i * n + c];
                if f != 0.0 {
                    for j in 0..n {
                        m[i * n + j] -= f * m[c * n + j];
                        inv[i * n + j] -= f * inv[c * n + j];
                    }
                }
            }
        }
    }
    Some(inv)
}

/// Closed-loop FRFs by the LPM: $r$ (the excitation) as input, $[y, u]$ as outputs; see the
/// [module docs](self).
///
/// # Errors
/// As [`lpm`]; [`Error::Numerical`] where $\hat T_{ru} = 0$.
///
/// # Example
/// ```
/// use ambid_core::frf::lpm::{lpm_closed_loop, LpmOptions};
/// use rand::{RngExt, SeedableRng};
/// use rand_chacha::ChaCha8Rng;
/// // static loop: P = 2, C = 1.5 → S = 1/(1 + 3) = 0.25, T_ry = 0.5
/// let mut rng = ChaCha8Rng::seed_from_u64(2);
/// let r: Vec<f64> = (0..2048).map(|_| rng.random_range(-1.0..1.0)).collect();
/// let u: Vec<f64> = r.iter().map(|r| 0.25 * r).collect();
/// let y: Vec<f64> = u.iter().map(|u| 2.0 * u).collect();
/// let cl = lpm_closed_loop(&r, &u, &y, 1000.0, (1.0, 499.0), &LpmOptions::default()).unwrap();
/// assert!(cl.plant.values().iter().all(|p| (p - 2.0).norm() < 1e-10));
/// assert!(cl.t_ru.values().iter().all(|s| (s - 0.25).norm() < 1e-10));
/// ```
pub fn lpm_closed_loop(
    r: &[f64],
    u: &[f64],
    y: &[f64],
    fs: f64,
    band: (f64, f64),
    opts: &LpmOptions,
) -> Result<LpmClosedLoop> {
    let fit = lpm_named(r, &[y, u], fs, band, opts, "r")?;
    let (t_ry, t_ru, cov, ts) = (fit.frf(0)?, fit.frf(1)?, fit.frf_cov(0, 1)?, fit.grid.ts);
    LocalClosedLoop::assemble(fit, t_ry, t_ru, cov, ts, "LPM closed loop")
}

/// The plant $P = T_{ry}/T_{ru}$ with the first-order variance including the cross covariance
/// `cov` $=\mathrm E[\delta T_{ry}\overline{\delta T_{ru}}]$ (see the [module docs](self)).
pub(super) fn ratio_plant(
    t_ry: &Frd,
    t_ru: &Frd,
    cov: &[c64],
    ts: f64,
    what: &'static str,
) -> Result<Frd> {
    let f_hz = t_ry.f_hz();
    let (vy, vu) = (
        t_ry.variance().unwrap_or(&[]),
        t_ru.variance().unwrap_or(&[]),
    );
    let mut pv = Vec::with_capacity(f_hz.len());
    let mut pvar = Vec::with_capacity(f_hz.len());
    for (l, (&ty, &tu)) in t_ry.values().iter().zip(t_ru.values()).enumerate() {
        if tu.norm_sqr() == 0.0 {
            return Err(Error::numerical(
                what,
                format!("T_ru = 0 at {} Hz; the plant is undefined there", f_hz[l]),
            ));
        }
        let a = c64::new(1.0, 0.0) / tu;
        let pk = ty * a;
        let b = -pk * a;
        let (syy, suu) = (
            vy.get(l).copied().unwrap_or(0.0),
            vu.get(l).copied().unwrap_or(0.0),
        );
        let syu = cov.get(l).copied().unwrap_or(c64::new(0.0, 0.0));
        let v = a.norm_sqr() * syy + b.norm_sqr() * suu + 2.0 * (a * syu * b.conj()).re;
        pv.push(pk);
        pvar.push(v.max(0.0));
    }
    Frd::new(f_hz.to_vec(), pv, Some(pvar), Some(ts))
}

/// Checked inputs of a local (polynomial or rational) method: the DFTs and the band's lines.
pub(super) struct Prepared {
    pub uf: Vec<c64>,
    pub yf: Vec<Vec<c64>>,
    pub lines: Vec<usize>,
    pub df: f64,
    pub n_lines: usize,
    /// mean $|U(k)|^2$ over lines $1..=\lfloor N/2\rfloor$
    pub mean_power: f64,
    /// record length $N$
    pub n: usize,
    /// sampling frequency \[Hz\]
    pub fs: f64,
    /// `Some(P)` when the input holds $P \ge 2$ whole periods (see [`detect_periods`])
    pub periods: Option<usize>,
}

/// Checks the channels, the band and the window length `w`, and transforms the record; `input`
/// names the input in the messages.
pub(super) fn prepare(
    u: &[f64],
    ys: &[&[f64]],
    fs: f64,
    band: (f64, f64),
    w: usize,
    input: &'static str,
) -> Result<Prepared> {
    if ys.is_empty() {
        return Err(Error::invalid("ys", "no output channel given"));
    }
    if !(fs.is_finite() && fs > 0.0) {
        return Err(Error::invalid(
            "fs",
            format!("the sampling frequency must be positive and finite, got {fs}"),
        ));
    }
    let n = u.len();
    for (o, y) in ys.iter().enumerate() {
        if y.len() != n {
            return Err(Error::DimensionMismatch {
                context: "LPM/LRM: output length vs input length",
                expected: n.to_string(),
                got: format!("{} (output {o})", y.len()),
            });
        }
    }
    check_finite(input, u)?;
    for y in ys {
        check_finite("y", y)?;
    }
    let n_lines = n / 2;
    if n_lines < w {
        return Err(Error::invalid(
            input,
            format!(
                "the record of {n} samples has {n_lines} DFT lines, fewer than the window of {w} lines; \
                 record longer or use a smaller degree/half width"
            ),
        ));
    }
    if !(band.0.is_finite() && band.1.is_finite() && band.0 <= band.1) {
        return Err(Error::invalid(
            "band",
            format!("need finite f_min ≤ f_max, got [{}, {}]", band.0, band.1),
        ));
    }
    let df = fs / n as f64;
    let lines: Vec<usize> = (1..=n_lines)
        .filter(|&k| {
            let f = k as f64 * df;
            f >= band.0 && f <= band.1
        })
        .collect();
    if lines.is_empty() {
        return Err(Error::invalid(
            "band",
            format!(
                "no DFT line in {}–{} Hz: the lines are {df} Hz apart from {df} Hz to {} Hz",
                band.0,
                band.1,
                n_lines as f64 * df
            ),
        ));
    }
    if u.iter().all(|v| *v == 0.0) {
        return Err(Error::invalid(
            input,
            format!("the input {input} is identically zero: there is no excitation power"),
        ));
    }
    let uf = dft(u)?;
    let yf: Vec<Vec<c64>> = ys.iter().map(|y| dft(y)).collect::<Result<_>>()?;
    let mean_power = uf.iter().skip(1).map(|z| z.norm_sqr()).sum::<f64>() / n_lines as f64;
    let periods = detect_periods(&uf, n_lines, n);
    Ok(Prepared {
        uf,
        yf,
        lines,
        df,
        n_lines,
        mean_power,
        n,
        fs,
        periods,
    })
}

/// Fraction of a measured input's power (lines $1..\lfloor N/2\rfloor$) that may lie off the
/// multiples of $P$ for the record to count as $P$ periods of a periodic input with measurement
/// noise (−30 dB); see [`lpm`].
pub const PERIODIC_OFF_FRACTION: f64 = 1e-3;

/// `Some(P)` when the record of `n` samples holds $P \ge 2$ periods of a periodic input: every
/// line $1..\lfloor N/2\rfloor$ of `uf` with more than $10^{-10}$ of the largest line power is a
/// multiple of $P$ (a generated signal: the lines in between carry only round-off), or else,
/// for a measured (noisy) input, $P$ is the largest divisor of $N$ for which the lines that are
/// not multiples of $P$ hold less than [`PERIODIC_OFF_FRACTION`] of the power.
pub(super) fn detect_periods(uf: &[c64], n_lines: usize, n: usize) -> Option<usize> {
    let pw: Vec<f64> = (0..=n_lines).map(|k| uf[k].norm_sqr()).collect();
    let pmax = pw[1..].iter().copied().fold(0.0, f64::max);
    if pmax.is_nan() || pmax <= 0.0 {
        return None;
    }
    let mut g = 0usize;
    for (k, &v) in pw.iter().enumerate().skip(1) {
        if v > 1e-10 * pmax {
            g = gcd(g, k);
            if g == 1 {
                break;
            }
        }
    }
    if g >= 2 {
        return Some(g);
    }
    let total: f64 = pw[1..].iter().sum();
    (2..=n_lines / 2).rev().filter(|p| n % p == 0).find(|&p| {
        let off: f64 = pw
            .iter()
            .enumerate()
            .skip(1)
            .filter(|(k, _)| k % p != 0)
            .map(|(_, v)| v)
            .sum();
        off < PERIODIC_OFF_FRACTION * total
    })
}

pub(super) fn gcd(a: usize, b: usize) -> usize {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

/// DFT lines $0..=\lfloor N/2 \rfloor$ of a real record, scaled by $1/\sqrt N$.
fn dft(x: &[f64]) -> Result<Vec<c64>> {
    let n = x.len();
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(n);
    let mut input = x.to_vec();
    let mut out = fft.make_output_vec();
    fft.process(&mut input, &mut out)
        .map_err(|e| Error::numerical("LPM DFT", e.to_string()))?;
    let s = 1.0 / (n as f64).sqrt();
    Ok(out.iter().map(|z| c64::new(z.re * s, z.im * s)).collect())
}

enum LineFailure {
    NoPower,
    RankDeficient,
}

/// Precomputed tables and per-line workspace of the local fits (no allocation per line).
struct Fitter {
    /// windows with less input power ($\sum |U|^2$) than this count as not excited
    min_power: f64,
    r1: usize,
    half: usize,
    w: usize,
    np: usize,
    p: usize,
    /// `pow[(shift * w + j) * (2R + 1) + e]` = x_j^e for a window shifted by `shift`
    pow: Vec<f64>,
    ne: usize,
    // workspace
    h: Vec<c64>,
    d: Vec<f64>,
    rhs: Vec<c64>,
    theta: Vec<c64>,
    z0: Vec<c64>,
    ma: Vec<f64>,
    mb: Vec<c64>,
    res: Vec<c64>,
    g_out: Vec<c64>,
    t_out: Vec<c64>,
    cov_out: Vec<c64>,
}

impl Fitter {
    fn new(degree: usize, half: usize, p: usize, min_power: f64) -> Self {
        let r1 = degree + 1;
        let w = 2 * half + 1;
        let ne = 2 * degree + 1;
        let np = 2 * r1;
        let scale = 1.0 / half.max(1) as f64;
        let mut pow = vec![0.0; w * w * ne];
        for shift in 0..w {
            for j in 0..w {
                let x = (j as f64 - shift as f64) * scale;
                let mut v = 1.0;
                for e in 0..ne {
                    pow[(shift * w + j) * ne + e] = v;
                    v *= x;
                }
            }
        }
        let z = c64::new(0.0, 0.0);
        Self {
            min_power,
            r1,
            half,
            w,
            np,
            p,
            pow,
            ne,
            h: vec![z; np * np],
            d: vec![0.0; np],
            rhs: vec![z; np * p],
            theta: vec![z; np * p],
            z0: vec![z; np],
            ma: vec![0.0; ne],
            mb: vec![z; ne],
            res: vec![z; w * p],
            g_out: vec![z; p],
            t_out: vec![z; p],
            cov_out: vec![z; p * p],
        }
    }

    /// Fits the window around line `k` (1-based grid 1..=n_lines); results in `g_out`,
    /// `t_out`, `cov_out`; returns $[(K^H K)^{-1}]_{00}$.
    fn fit_line(
        &mut self,
        uf: &[c64],
        yf: &[&[c64]],
        k: usize,
        n_lines: usize,
    ) -> std::result::Result<f64, LineFailure> {
        let (w, half, r1, np, ne, p) = (self.w, self.half, self.r1, self.np, self.ne, self.p);
        // window lo..lo+w inside 1..=n_lines
        let lo = if k < 1 + half {
            1
        } else if k + half > n_lines {
            n_lines + 1 - w
        } else {
            k - half
        };
        let shift = k - lo;
        let pw = &self.pow[shift * w * ne..(shift + 1) * w * ne];
        let uw = &uf[lo..lo + w];
        // moments
        self.ma.iter_mut().for_each(|v| *v = 0.0);
        self.mb.iter_mut().for_each(|v| *v = c64::new(0.0, 0.0));
        let mut m0 = [0.0f64; 17];
        for (j, uj) in uw.iter().enumerate() {
            let a = uj.norm_sqr();
            let b = uj.conj();
            let pj = &pw[j * ne..(j + 1) * ne];
            for e in 0..ne {
                self.ma[e] += a * pj[e];
                self.mb[e] += b * pj[e];
                m0[e] += pj[e];
            }
        }
        if self.ma[0].is_nan() || self.ma[0] <= self.min_power {
            return Err(LineFailure::NoPower);
        }
        // Gram matrix, row-major np × np
        for a in 0..r1 {
            for b in 0..r1 {
                self.h[a * np + b] = c64::new(self.ma[a + b], 0.0);
                self.h[a * np + r1 + b] = self.mb[a + b];
                self.h[(r1 + a) * np + b] = self.mb[a + b].conj();
                self.h[(r1 + a) * np + r1 + b] = c64::new(m0[a + b], 0.0);
            }
        }
        // right-hand sides K^H Y
        self.rhs.iter_mut().for_each(|v| *v = c64::new(0.0, 0.0));
        for (o, y) in yf.iter().enumerate() {
            let yw = &y[lo..lo + w];
            for j in 0..w {
                let yj = yw[j];
                let cy = uw[j].conj() * yj;
                let pj = &pw[j * ne..j * ne + r1];
                for (a, &x) in pj.iter().enumerate() {
                    self.rhs[a * p + o] += cy * x;
                    self.rhs[(r1 + a) * p + o] += yj * x;
                }
            }
        }
        // equilibrate
        for a in 0..np {
            self.d[a] = 1.0 / self.h[a * np + a].re.sqrt();
        }
        for a in 0..np {
            for b in 0..np {
                self.h[a * np + b] *= self.d[a] * self.d[b];
            }
        }
        // Cholesky, lower triangle in place
        for j in 0..np {
            let mut s = self.h[j * np + j].re;
            for kk in 0..j {
                s -= self.h[j * np + kk].norm_sqr();
            }
            if s.is_nan() || s <= 1e-13 {
                return Err(LineFailure::RankDeficient);
            }
            let ljj = s.sqrt();
            self.h[j * np + j] = c64::new(ljj, 0.0);
            for i in j + 1..np {
                let mut v = self.h[i * np + j];
                for kk in 0..j {
                    v -= self.h[i * np + kk] * self.h[j * np + kk].conj();
                }
                self.h[i * np + j] = v / ljj;
            }
        }
        // solve for every output: L z = D rhs, L^H θs = z, θ = D θs
        for o in 0..p {
            for i in 0..np {
                let mut v = self.rhs[i * p + o] * self.d[i];
                for kk in 0..i {
                    v -= self.h[i * np + kk] * self.theta[kk * p + o];
                }
                self.theta[i * p + o] = v / self.h[i * np + i].re;
            }
            for i in (0..np).rev() {
                let mut v = self.theta[i * p + o];
                for kk in i + 1..np {
                    v -= self.h[kk * np + i].conj() * self.theta[kk * p + o];
                }
                self.theta[i * p + o] = v / self.h[i * np + i].re;
            }
            for i in 0..np {
                self.theta[i * p + o] *= self.d[i];
            }
            self.g_out[o] = self.theta[o];
            self.t_out[o] = self.theta[r1 * p + o];
        }
        // [(K^H K)^{-1}]_00 = d0² ‖L^{-1} e0‖²
        let mut c = 0.0;
        for i in 0..np {
            let mut v = if i == 0 {
                c64::new(1.0, 0.0)
            } else {
                c64::new(0.0, 0.0)
            };
            for kk in 0..i {
                v -= self.h[i * np + kk] * self.z0[kk];
            }
            self.z0[i] = v / self.h[i * np + i].re;
            c += self.z0[i].norm_sqr();
        }
        let c00 = c * self.d[0] * self.d[0];
        // residuals
        for (o, y) in yf.iter().enumerate() {
            let yw = &y[lo..lo + w];
            for j in 0..w {
                let pj = &pw[j * ne..j * ne + r1];
                let (mut gp, mut tp) = (c64::new(0.0, 0.0), c64::new(0.0, 0.0));
                for (a, &x) in pj.iter().enumerate() {
                    gp += self.theta[a * p + o] * x;
                    tp += self.theta[(r1 + a) * p + o] * x;
                }
                self.res[j * p + o] = yw[j] - uw[j] * gp - tp;
            }
        }
        let qf = (w - np) as f64;
        for o1 in 0..p {
            for o2 in 0..p {
                let mut s = c64::new(0.0, 0.0);
                for j in 0..w {
                    s += self.res[j * p + o1] * self.res[j * p + o2].conj();
                }
                self.cov_out[o1 * p + o2] = s / qf;
            }
        }
        Ok(c00)
    }

    /// Leverage $h = K_0 (K^{\mathsf H}K)^{-1} K_0^{\mathsf H}$ of the window row at the line
    /// itself ($x = 0$, input `uk`) in the last successful [`fit_line`](Self::fit_line).
    fn center_leverage(&mut self, uk: c64) -> f64 {
        let (np, r1) = (self.np, self.r1);
        let mut h = 0.0;
        for i in 0..np {
            let mut v = if i == 0 {
                uk.conj() * self.d[0]
            } else if i == r1 {
                c64::new(self.d[r1], 0.0)
            } else {
                c64::new(0.0, 0.0)
            };
            for kk in 0..i {
                v -= self.h[i * np + kk] * self.z0[kk];
            }
            self.z0[i] = v / self.h[i * np + i].re;
            h += self.z0[i].norm_sqr();
        }
        h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_defaults_and_errors() {
        let o = LpmOptions::default();
        assert_eq!((o.degree(), o.half_width(), o.window()), (2, 4, 9));
        assert_eq!(o.dof().unwrap(), 3);
        assert!(LpmOptions::new().with_half_width(2).is_err());
        assert_eq!(
            LpmOptions::new()
                .with_degree(1)
                .unwrap()
                .with_half_width(2)
                .unwrap()
                .dof()
                .unwrap(),
            1
        );
        assert!(LpmOptions::new().with_degree(9).is_err());
        let a = LpmOptions::auto();
        assert!(a.is_auto() && !LpmOptions::default().is_auto());
        assert!(!a.with_degree(1).unwrap().is_auto());
        assert!(!a.with_half_width(10).unwrap().is_auto());
    }

    #[test]
    fn periods_are_detected_from_the_line_pattern() {
        let z = c64::new(0.0, 0.0);
        let mut uf = vec![z; 65];
        for k in (6..=64).step_by(6) {
            uf[k] = c64::new(1.0, -0.5);
        }
        assert_eq!(detect_periods(&uf, 64, 128), Some(6));
        // round-off on the other lines does not count
        uf[7] = c64::new(1e-7, 0.0);
        assert_eq!(detect_periods(&uf, 64, 128), Some(6));
        // noise below −30 dB: periodic with the largest divisor of N = 120 that fits (6)
        uf[7] = c64::new(1e-2, 0.0);
        assert_eq!(detect_periods(&uf, 60, 120), Some(6));
        // with N = 128 (6 does not divide it) the largest fit is 2 periods of 64 samples: all
        // the power but the noise is on even lines
        assert_eq!(detect_periods(&uf, 64, 128), Some(2));
        // more power off the multiples: not periodic
        uf[7] = c64::new(0.5, 0.0);
        assert_eq!(detect_periods(&uf, 60, 120), None);
        assert_eq!(detect_periods(&vec![z; 65], 64, 128), None);
        // white noise is not periodic
        let mut rng = 1u64;
        let noise: Vec<c64> = (0..=512)
            .map(|_| {
                rng = rng
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                c64::new((rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5, 0.1)
            })
            .collect();
        assert_eq!(detect_periods(&noise, 512, 1024), None);
    }

    #[test]
    fn small_inverse_matches_the_identity() {
        let a = [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0];
        let inv = small_spd_inverse(&a, 3).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let v: f64 = (0..3).map(|k| a[i * 3 + k] * inv[k * 3 + j]).sum();
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-14);
            }
        }
        assert!(small_spd_inverse(&[1.0, 1.0, 1.0, 1.0], 2).is_none());
    }
}
