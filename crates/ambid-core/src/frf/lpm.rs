//! The Local Polynomial Method (LPM): frequency responses, transients and noise covariances from
//! one non-periodic record.
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
//! * the input must excite every window (a window where $\sum |U|^2 = 0$ is an error);
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

/// Degree $R$ and half width $n$ of the local polynomial model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LpmOptions {
    degree: usize,
    half_width: Option<usize>,
}

impl Default for LpmOptions {
    /// $R = 2$ and the smallest window with $q \ge 3$ degrees of freedom ($n = R + 2 = 4$,
    /// $w = 9$ lines).
    fn default() -> Self {
        Self {
            degree: 2,
            half_width: None,
        }
    }
}

impl LpmOptions {
    /// The default options ($R = 2$, $n = 4$).
    pub fn new() -> Self {
        Self::default()
    }

    /// Sets the polynomial degree $R$ of $G$ and $T$ (the half width follows it unless set).
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
        Ok(self)
    }

    /// Sets the half width $n$ (window of $2n+1$ lines).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the window leaves no degree of freedom,
    /// $q = 2n + 1 - 2(R+1) < 1$ (set the degree first).
    pub fn with_half_width(mut self, half_width: usize) -> Result<Self> {
        self.half_width = Some(half_width);
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

/// The LPM of outputs `ys` on input `u` (equal lengths, finite), sampled at `fs` Hz, on the DFT
/// lines in `band` = $[f_{\min}, f_{\max}]$ Hz.
///
/// # Errors
/// * [`Error::InvalidArgument`]: no output, `fs` not positive and finite, options with $q < 1$,
///   fewer lines in the record than the window needs, a band without a DFT line in
///   $1..\lfloor N/2\rfloor$, or an input without power in some window of the band;
/// * [`Error::DimensionMismatch`]: channels of different lengths;
/// * [`Error::NonFinite`]: a NaN or infinite sample;
/// * [`Error::Numerical`]: a rank-deficient local regressor (the input is locally a polynomial in
///   the line index, e.g. a single sine).
pub fn lpm(u: &[f64], ys: &[&[f64]], fs: f64, band: (f64, f64), opts: &LpmOptions) -> Result<Lpm> {
    let q = opts.dof()?;
    let (half, w) = (opts.half_width(), opts.window());
    let Prepared {
        uf,
        yf,
        lines,
        df,
        n_lines,
        mean_power,
        n,
    } = prepare(u, ys, fs, band, w)?;
    let yref: Vec<&[c64]> = yf.iter().map(|v| v.as_slice()).collect();
    // a window whose input power is below 1e-14 of an average window's (−140 dB) holds only
    // leakage and round-off: not excited
    let mut fit = Fitter::new(opts.degree(), half, ys.len(), 1e-14 * w as f64 * mean_power);
    let p = ys.len();
    let nl = lines.len();
    let mut g = vec![c64::new(0.0, 0.0); nl * p];
    let mut tr = vec![c64::new(0.0, 0.0); nl * p];
    let mut cv = vec![c64::new(0.0, 0.0); nl * p * p];
    let mut c00 = vec![0.0; nl];
    for (l, &k) in lines.iter().enumerate() {
        let res = fit.fit_line(&uf, &yref, k, n_lines);
        match res {
            Ok(c) => c00[l] = c,
            Err(LineFailure::NoPower) => {
                return Err(Error::invalid(
                    "u",
                    format!(
                        "the input has no power in the window around line {k} ({:.4} Hz); restrict the band \
                         to where the excitation has power",
                        k as f64 * df
                    ),
                ))
            }
            Err(LineFailure::RankDeficient) => {
                return Err(Error::numerical(
                    "LPM",
                    format!(
                        "the local regressor around line {k} ({:.4} Hz) is rank deficient: the input spectrum \
                         is locally polynomial (e.g. a single sine or a sparse multisine); use a broadband \
                         excitation or a smaller degree",
                        k as f64 * df
                    ),
                ))
            }
        }
        g[l * p..(l + 1) * p].copy_from_slice(&fit.g_out);
        tr[l * p..(l + 1) * p].copy_from_slice(&fit.t_out);
        cv[l * p * p..(l + 1) * p * p].copy_from_slice(&fit.cov_out);
    }
    Ok(Lpm {
        grid: LineGrid::new(lines, n, fs, p),
        degree: opts.degree(),
        half_width: half,
        dof: q,
        g,
        transient: tr,
        noise_cov: cv,
        c00,
    })
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
    let fit = lpm(r, &[y, u], fs, band, opts)?;
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
}

/// Checks the channels, the band and the window length `w`, and transforms the record.
pub(super) fn prepare(
    u: &[f64],
    ys: &[&[f64]],
    fs: f64,
    band: (f64, f64),
    w: usize,
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
    check_finite("u", u)?;
    for y in ys {
        check_finite("y", y)?;
    }
    let n_lines = n / 2;
    if n_lines < w {
        return Err(Error::invalid(
            "u",
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
            "u",
            "the input is identically zero: there is no excitation power",
        ));
    }
    let uf = dft(u)?;
    let yf: Vec<Vec<c64>> = ys.iter().map(|y| dft(y)).collect::<Result<_>>()?;
    let mean_power = uf.iter().skip(1).map(|z| z.norm_sqr()).sum::<f64>() / n_lines as f64;
    Ok(Prepared {
        uf,
        yf,
        lines,
        df,
        n_lines,
        mean_power,
        n,
    })
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
    }
}
