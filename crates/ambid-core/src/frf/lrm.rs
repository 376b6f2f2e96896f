//! The Local Rational Method (LRM): like the [LPM](super::lpm), but the local model of the FRF
//! and of the transient is a ratio of polynomials, so that a lightly damped resonance narrower
//! than the window is still captured.
//!
//! # Model
//! With the DFT of the whole record as in [`lpm`](super::lpm) ($X(k) = N^{-1/2}\sum_t x(t)
//! e^{-j2\pi kt/N}$, no window), around every line $k$ and for every output $o$ separately
//!
//! $$Y(k+r) = \frac{N_k(x)}{D_k(x)}\,U(k+r) + \frac{M_k(x)}{D_k(x)} + V(k+r),\qquad
//!   x = r/n,\ r \in \{r_0, \dots, r_0 + 2n\},$$
//!
//! with $N_k$ of degree $R_n$, $M_k$ (transient) of degree $R_m$ and the monic denominator
//! $D_k(x) = 1 + \sum_{s=1}^{R_d} d_s x^s$. Multiplying by $D_k$ gives the linear least-squares
//! problem of McKelvey & Guérin (2012),
//!
//! $$Y(k+r) = \sum_{s=0}^{R_n} n_s x^s U(k+r) + \sum_{s=0}^{R_m} m_s x^s
//!   - \sum_{s=1}^{R_d} d_s x^s Y(k+r) + e(r),\qquad e(r) = D_k(x) V(k+r),$$
//!
//! in $n_\theta = R_n + R_m + R_d + 2$ complex unknowns, and $\hat G(k) = \hat n_0$,
//! $\hat T(k) = \hat m_0$ (the value at $x = 0$, where $D_k = 1$). The window is centred except
//! at the ends of the grid, where it is shifted inside $1..\lfloor N/2\rfloor$.
//!
//! # Noise and FRF covariance
//! The fit is solved by a QR factorisation of the column-equilibrated local regressor $K$. With
//! $a^{\mathsf T}$ the first row of $K^{+} = (K^{\mathsf H}K)^{-1}K^{\mathsf H}$, $\hat G(k) =
//! a^{\mathsf T} Y_w$ and, to first order in the noise (the noise in the regressor's $Y$ columns
//! is neglected), $\delta\hat G_o = \sum_j a_{o,j} D_{o}(x_j) V_o(k+r_j)$. The noise covariance is
//! estimated from the residuals divided by the fitted denominator,
//!
//! $$\hat C_V(o_1,o_2) = \frac{1}{q}\sum_j \frac{\hat e_{o_1}(r_j)}{\hat D_{o_1}(x_j)}
//!   \overline{\left(\frac{\hat e_{o_2}(r_j)}{\hat D_{o_2}(x_j)}\right)},\qquad
//!   q = 2n + 1 - n_\theta,$$
//!
//! and $\operatorname{Cov}(\hat G_{o_1}, \hat G_{o_2}) = \hat C_V(o_1,o_2)\sum_j a_{o_1,j}
//! \hat D_{o_1}(x_j)\,\overline{a_{o_2,j}\hat D_{o_2}(x_j)}$.
//!
//! Where the response is locally polynomial (no pole near the window), the denominator columns
//! $x^s Y$ are nearly in the span of the others; a column whose part orthogonal to the previous
//! ones is below $10^{-10}$ of its norm is dropped for that line (the local denominator degree
//! falls), so smooth regions give the LPM's answer instead of an ill-conditioned one.
//!
//! # When to use it
//! The LPM's bias grows like $(w/B)^{R+1}$ with $B$ the 3 dB width of a resonance in lines; the
//! LRM models the pole itself and stays accurate when $B$ is a few lines or less, at the price
//! of a small bias of order noise/signal (the equation error $D_k V$ is correlated with the $Y$
//! columns) and a less reliable variance at low SNR. Use it on short records of lightly damped
//! systems (the twin's bending mode near 780 Hz); on long records the LPM is as good and
//! cheaper. `docs/lpm.md` compares both on the twin.
//!
//! # Reference
//! T. McKelvey, G. Guérin, "Non-parametric frequency response estimation using a local rational
//! model", *IFAC Proceedings* 45(16) (SYSID 2012), 49–54. R. Pintelon, J. Schoukens, *System
//! Identification: A Frequency Domain Approach*, 2nd ed., Wiley–IEEE Press, 2012, ch. 7.
//!
//! # Example
//! ```
//! use ambid_core::frf::lrm::{lrm, LrmOptions};
//! use rand::{RngExt, SeedableRng};
//! use rand_chacha::ChaCha8Rng;
//! // a lightly damped resonance (poles at 0.995 e^{±j0.6}), started at rest, no noise
//! let n = 4096;
//! let mut rng = ChaCha8Rng::seed_from_u64(1);
//! let u: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
//! let (a1, a2) = (-2.0 * 0.995 * 0.6f64.cos(), 0.995f64 * 0.995);
//! let mut y = vec![0.0; n];
//! for t in 0..n {
//!     let (y1, y2) = (if t > 0 { y[t - 1] } else { 0.0 }, if t > 1 { y[t - 2] } else { 0.0 });
//!     let u1 = if t > 0 { u[t - 1] } else { 0.0 };
//!     y[t] = 0.01 * u1 - a1 * y1 - a2 * y2;
//! }
//! let fs = 1.0;
//! let est = lrm(&u, &[&y], fs, (0.05, 0.15), &LrmOptions::default()).unwrap();
//! let g = est.frf(0).unwrap();
//! for (f, v) in g.f_hz().iter().zip(g.values()) {
//!     let z = ambid_core::c64::cis(-2.0 * std::f64::consts::PI * f / fs);
//!     let truth = z * 0.01 / (1.0 + z * a1 + z * z * a2);
//!     assert!((v - truth).norm() < 1e-3 * truth.norm(), "{f}: {v} vs {truth}");
//! }
//! ```

use super::closed_loop::band_radius_factor;
use super::lpm::{
    no_power_error, prepare, split_excited, LineGrid, LocalClosedLoop, LocalFit, Prepared,
};
use crate::error::{Error, Result};
use crate::lti::Frd;
use faer::c64;

/// Degrees $(R_n, R_d, R_m)$ and half width $n$ of the local rational model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LrmOptions {
    num_degree: usize,
    den_degree: usize,
    transient_degree: usize,
    half_width: Option<usize>,
}

impl Default for LrmOptions {
    /// $R_n = R_d = R_m = 2$ and the smallest window with $q \ge 5$ degrees of freedom
    /// ($n = 6$, $w = 13$ lines).
    fn default() -> Self {
        Self {
            num_degree: 2,
            den_degree: 2,
            transient_degree: 2,
            half_width: None,
        }
    }
}

impl LrmOptions {
    /// The default options ($R_n = R_d = R_m = 2$, $n = 6$).
    pub fn new() -> Self {
        Self::default()
    }

    /// Sets the degrees of the numerator $R_n$, the denominator $R_d$ and the transient's
    /// numerator $R_m$ (the half width follows them unless set).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a degree above 6 or $R_d = 0$ (that is the LPM).
    pub fn with_degrees(mut self, num: usize, den: usize, transient: usize) -> Result<Self> {
        if num > 6 || den > 6 || transient > 6 {
            return Err(Error::invalid(
                "degrees",
                format!("the local degrees must be at most 6, got ({num}, {den}, {transient}); 2 is usual"),
            ));
        }
        if den == 0 {
            return Err(Error::invalid(
                "den_degree",
                "a local rational model needs a denominator degree ≥ 1; with 0 it is the LPM (frf::lpm)",
            ));
        }
        self.num_degree = num;
        self.den_degree = den;
        self.transient_degree = transient;
        if self.half_width.is_some() {
            self.dof()?;
        }
        Ok(self)
    }

    /// Sets the half width $n$ (window of $2n+1$ lines).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the window leaves no degree of freedom.
    pub fn with_half_width(mut self, half_width: usize) -> Result<Self> {
        self.half_width = Some(half_width);
        self.dof().map(|_| self)
    }

    /// $(R_n, R_d, R_m)$.
    pub fn degrees(&self) -> (usize, usize, usize) {
        (self.num_degree, self.den_degree, self.transient_degree)
    }

    /// Number of complex parameters per line and output, $R_n + R_m + R_d + 2$.
    pub fn n_params(&self) -> usize {
        self.num_degree + self.transient_degree + self.den_degree + 2
    }

    /// Half width $n$: the one set, else the smallest with $q \ge 5$.
    pub fn half_width(&self) -> usize {
        self.half_width
            .unwrap_or_else(|| (self.n_params() + 4).div_ceil(2))
    }

    /// Window length $2n + 1$.
    pub fn window(&self) -> usize {
        2 * self.half_width() + 1
    }

    /// Residual degrees of freedom $q = 2n + 1 - n_\theta$.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when $q < 1$.
    pub fn dof(&self) -> Result<usize> {
        let (w, np) = (self.window(), self.n_params());
        if w <= np {
            return Err(Error::invalid(
                "half_width",
                format!(
                    "a window of {w} lines leaves no degree of freedom for {np} parameters; need 2n + 1 > {np}, \
                     i.e. n ≥ {}",
                    np / 2
                ),
            ));
        }
        Ok(w - np)
    }
}

/// The LRM fit of one input and $p$ outputs on the lines of a band; see the [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct Lrm {
    grid: LineGrid,
    options: LrmOptions,
    dof: usize,
    /// line-major, `g[l * p + o]`
    g: Vec<c64>,
    transient: Vec<c64>,
    /// `frf_cov[(l * p + o1) * p + o2]`
    frf_cov: Vec<c64>,
    /// `noise_cov[(l * p + o1) * p + o2]`
    noise_cov: Vec<c64>,
    /// lines where a denominator column was dropped (locally polynomial response), per output
    reduced: Vec<usize>,
    /// lines of the band left out: too little input power
    excluded: Vec<usize>,
}

impl Lrm {
    /// Frequencies of the estimated lines \[Hz\].
    pub fn f_hz(&self) -> &[f64] {
        &self.grid.f_hz
    }
    /// DFT line indices $k$.
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
    /// The options used.
    pub fn options(&self) -> LrmOptions {
        self.options
    }
    /// Nominal residual degrees of freedom $q$.
    pub fn dof(&self) -> usize {
        self.dof
    }
    /// Per output, the number of lines where the local denominator degree was reduced
    /// (a locally polynomial response).
    pub fn reduced_lines(&self) -> &[usize] {
        &self.reduced
    }
    /// Lines of the requested band left out because the input has too little power there (below
    /// [`EXCITED_FRACTION`](super::lpm::EXCITED_FRACTION) of its average line power over the window, as for the
    /// [LPM](super::lpm::lpm)).
    pub fn excluded_lines(&self) -> &[usize] {
        &self.excluded
    }

    /// $\hat G_o(k)$ with its variance.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an output index out of range.
    pub fn frf(&self, o: usize) -> Result<Frd> {
        let vals = self.grid.of_output(&self.g, o)?;
        let var = self
            .grid
            .of_pair(&self.frf_cov, o, o)?
            .iter()
            .map(|c| c.re.max(0.0))
            .collect();
        self.grid.frd(vals, var)
    }

    /// The estimated transient $\hat T_o(k)$.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an output index out of range.
    pub fn transient(&self, o: usize) -> Result<Vec<c64>> {
        self.grid.of_output(&self.transient, o)
    }

    /// Noise covariance $\hat C_V(k)_{o_1 o_2}$ per line.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an output index out of range.
    pub fn noise_cov(&self, o1: usize, o2: usize) -> Result<Vec<c64>> {
        self.grid.of_pair(&self.noise_cov, o1, o2)
    }

    /// Covariance $\mathrm E[\delta\hat G_{o_1}\overline{\delta\hat G_{o_2}}]$ per line.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an output index out of range.
    pub fn frf_cov(&self, o1: usize, o2: usize) -> Result<Vec<c64>> {
        self.grid.of_pair(&self.frf_cov, o1, o2)
    }

    /// Radius factor of the level-`level` confidence disc for $q$ degrees of freedom.
    ///
    /// # Errors
    /// As [`band_radius_factor`].
    pub fn band_factor(&self, level: f64) -> Result<f64> {
        band_radius_factor(level, self.dof as f64)
    }
}

impl LocalFit for Lrm {
    fn dof(&self) -> usize {
        self.dof
    }
}

/// Closed-loop FRFs by the LRM (`fit` is the [`Lrm`]).
pub type LrmClosedLoop = LocalClosedLoop<Lrm>;

/// The LRM of outputs `ys` on input `u` (equal lengths, finite), sampled at `fs` Hz, on the DFT
/// lines in `band` Hz.
///
/// # Errors
/// As [`lpm`](super::lpm::lpm): no output, bad `fs` or band, a record shorter than the window,
/// channels of different lengths, non-finite samples, a window without input power; and
/// [`Error::Numerical`] where the input part of the local regressor is rank deficient.
pub fn lrm(u: &[f64], ys: &[&[f64]], fs: f64, band: (f64, f64), opts: &LrmOptions) -> Result<Lrm> {
    lrm_named(u, ys, fs, band, opts, "u")
}

/// [`lrm`] with the input's name for the messages (`r` in closed loop).
fn lrm_named(
    u: &[f64],
    ys: &[&[f64]],
    fs: f64,
    band: (f64, f64),
    opts: &LrmOptions,
    input: &'static str,
) -> Result<Lrm> {
    let q = opts.dof()?;
    let (half, w) = (opts.half_width(), opts.window());
    let prep = prepare(u, ys, fs, band, w, input)?;
    if let Some(pp) = prep.periods {
        let ps = prep.n / pp;
        return Err(Error::invalid(
            input,
            format!(
                "the input {input} is periodic ({pp} periods of {ps} samples): it has power only on every \
                 {pp}-th DFT line, and the LRM needs a non-periodic (broadband) record; use the periodic \
                 LPM (`--method lpm`) or period averaging (`--period-samples {ps}`)"
            ),
        ));
    }
    let (lines, excluded) = split_excited(&prep, half);
    if lines.is_empty() {
        return Err(no_power_error(band, input));
    }
    let Prepared {
        uf,
        yf,
        df,
        n_lines,
        mean_power,
        n,
        ..
    } = prep;
    let p = ys.len();
    let nl = lines.len();
    let (rn, rd, rm) = opts.degrees();
    let m = opts.n_params();
    let min_power = 1e-14 * w as f64 * mean_power;
    let scale = 1.0 / half.max(1) as f64;
    let zero = c64::new(0.0, 0.0);
    let mut g = vec![zero; nl * p];
    let mut tr = vec![zero; nl * p];
    let mut frf_cov = vec![zero; nl * p * p];
    let mut noise_cov = vec![zero; nl * p * p];
    let mut reduced = vec![0usize; p];
    // workspace
    let mut k_mat = vec![zero; w * m];
    let mut ls = SmallLs::new(w, m);
    let mut ad = vec![zero; w * p]; // a_j D(x_j) per output
    let mut res = vec![zero; w * p]; // residuals e_j per output
    let mut dv = vec![zero; w * p]; // D(x_j) per output
    let mut qs = vec![zero; w * m * p]; // orthonormal basis per output, column-major
    let mut nbs = vec![0usize; p];
    let mut mab = vec![zero; m * m];
    let mut xs = vec![0.0; w];
    for (l, &k) in lines.iter().enumerate() {
        let lo = if k < 1 + half {
            1
        } else if k + half > n_lines {
            n_lines + 1 - w
        } else {
            k - half
        };
        let uw = &uf[lo..lo + w];
        if uw.iter().map(|z| z.norm_sqr()).sum::<f64>() <= min_power {
            return Err(Error::invalid(
                input,
                format!(
                    "the input {input} has no power in the window around line {k} ({:.4} Hz); restrict the band \
                     to where the excitation has power",
                    k as f64 * df
                ),
            ));
        }
        for (j, x) in xs.iter_mut().enumerate() {
            *x = (lo + j) as f64 * scale - k as f64 * scale;
        }
        for (o, yo) in yf.iter().enumerate() {
            let yw = &yo[lo..lo + w];
            // columns: U x^s (s = 0..=rn), x^s (s = 0..=rm), −Y x^s (s = 1..=rd); column-major
            for j in 0..w {
                let x = xs[j];
                let mut c = 0;
                let mut v = 1.0;
                for _ in 0..=rn {
                    k_mat[c * w + j] = uw[j] * v;
                    v *= x;
                    c += 1;
                }
                let mut v = 1.0;
                for _ in 0..=rm {
                    k_mat[c * w + j] = c64::new(v, 0.0);
                    v *= x;
                    c += 1;
                }
                let mut v = x;
                for _ in 1..=rd {
                    k_mat[c * w + j] = -yw[j] * v;
                    v *= x;
                    c += 1;
                }
            }
            let fixed = rn + rm + 2;
            let sol = ls.solve(&k_mat, yw, fixed).map_err(|_| {
                Error::numerical(
                    "LRM",
                    format!(
                        "the local regressor around line {k} ({:.4} Hz) is rank deficient: the input spectrum \
                         is locally polynomial (e.g. a single sine or a sparse multisine); use a broadband \
                         excitation or smaller degrees",
                        k as f64 * df
                    ),
                )
            })?;
            if sol.dropped > 0 {
                reduced[o] += 1;
            }
            g[l * p + o] = ls.theta[0];
            tr[l * p + o] = ls.theta[rn + 1];
            for j in 0..w {
                // D(x_j) = 1 + Σ d_s x^s
                let x = xs[j];
                let mut dval = c64::new(1.0, 0.0);
                let mut v = x;
                for s in 0..rd {
                    dval += ls.theta[fixed + s] * v;
                    v *= x;
                }
                ad[j * p + o] = ls.row0[j] * dval;
                dv[j * p + o] = dval;
                res[j * p + o] = ls.residual[j];
            }
            nbs[o] = ls.nb;
            qs[o * w * m..o * w * m + ls.nb * w].copy_from_slice(&ls.q[..ls.nb * w]);
        }
        for o1 in 0..p {
            for o2 in 0..p {
                // E Σ_j e1_j conj(e2_j) = C12 Σ_j D1_j conj(D2_j) (P2^H P1)_jj with the residual
                // projectors P = I − QQ^H: (P2^H P1)_jj = 1 − |Q1_j|² − |Q2_j|² + Q2_j M conj(Q1_j),
                // M = Q2^H Q1
                let (q1, q2) = (&qs[o1 * w * m..], &qs[o2 * w * m..]);
                let (n1, n2) = (nbs[o1], nbs[o2]);
                if o1 != o2 {
                    for a2 in 0..n2 {
                        for b1 in 0..n1 {
                            let mut v = zero;
                            for j in 0..w {
                                v += q2[a2 * w + j].conj() * q1[b1 * w + j];
                            }
                            mab[a2 * m + b1] = v;
                        }
                    }
                }
                let (mut num, mut den, mut sa) = (zero, zero, zero);
                for j in 0..w {
                    num += res[j * p + o1] * res[j * p + o2].conj();
                    sa += ad[j * p + o1] * ad[j * p + o2].conj();
                    let h1: f64 = (0..n1).map(|b| q1[b * w + j].norm_sqr()).sum();
                    let pp = if o1 == o2 {
                        c64::new(1.0 - h1, 0.0)
                    } else {
                        let h2: f64 = (0..n2).map(|b| q2[b * w + j].norm_sqr()).sum();
                        let mut x = zero;
                        for a2 in 0..n2 {
                            let mut t = zero;
                            for b1 in 0..n1 {
                                t += mab[a2 * m + b1] * q1[b1 * w + j].conj();
                            }
                            x += q2[a2 * w + j] * t;
                        }
                        c64::new(1.0 - h1 - h2, 0.0) + x
                    };
                    den += dv[j * p + o1] * dv[j * p + o2].conj() * pp;
                }
                let cv = if den.norm() > 0.0 { num / den } else { zero };
                noise_cov[(l * p + o1) * p + o2] = cv;
                frf_cov[(l * p + o1) * p + o2] = cv * sa;
            }
        }
    }
    Ok(Lrm {
        grid: LineGrid::new(lines, n, fs, p),
        options: *opts,
        dof: q,
        g,
        transient: tr,
        frf_cov,
        noise_cov,
        reduced,
        excluded,
    })
}

/// Closed-loop FRFs by the LRM: $r$ as input, $[y, u]$ as outputs (each with its own local
/// denominator), and the plant $P = T_{ry}/T_{ru}$ with its first-order variance.
///
/// # Errors
/// As [`lrm`]; [`Error::Numerical`] where $\hat T_{ru} = 0$.
///
/// # Example
/// ```
/// use ambid_core::frf::lrm::{lrm_closed_loop, LrmOptions};
/// use rand::{RngExt, SeedableRng};
/// use rand_chacha::ChaCha8Rng;
/// // static loop: P = 2, C = 1.5 → S = 0.25, T_ry = 0.5
/// let mut rng = ChaCha8Rng::seed_from_u64(2);
/// let r: Vec<f64> = (0..2048).map(|_| rng.random_range(-1.0..1.0)).collect();
/// let u: Vec<f64> = r.iter().map(|r| 0.25 * r).collect();
/// let y: Vec<f64> = u.iter().map(|u| 2.0 * u).collect();
/// let cl = lrm_closed_loop(&r, &u, &y, 1000.0, (1.0, 499.0), &LrmOptions::default()).unwrap();
/// assert!(cl.plant.values().iter().all(|p| (p - 2.0).norm() < 1e-9));
/// ```
pub fn lrm_closed_loop(
    r: &[f64],
    u: &[f64],
    y: &[f64],
    fs: f64,
    band: (f64, f64),
    opts: &LrmOptions,
) -> Result<LrmClosedLoop> {
    let fit = lrm_named(r, &[y, u], fs, band, opts, "r")?;
    let (t_ry, t_ru, cov, ts) = (fit.frf(0)?, fit.frf(1)?, fit.frf_cov(0, 1)?, fit.grid.ts);
    LocalClosedLoop::assemble(fit, t_ry, t_ru, cov, ts, "LRM closed loop")
}

/// Outcome of one small least-squares solve.
struct Solved {
    /// columns dropped as dependent
    dropped: usize,
}

/// Least squares $\min\|K\theta - y\|$ for a small complex $w \times m$ matrix by classical
/// Gram–Schmidt with reorthogonalisation on equilibrated columns; columns from `fixed` on may
/// be dropped when dependent. Gives $\theta$, the residual and the first row of $K^+$.
struct SmallLs {
    w: usize,
    m: usize,
    q: Vec<c64>,
    r: Vec<c64>,
    scale: Vec<f64>,
    kept: Vec<bool>,
    qty: Vec<c64>,
    z: Vec<c64>,
    theta: Vec<c64>,
    residual: Vec<c64>,
    row0: Vec<c64>,
    /// basis size of the last solve
    nb: usize,
    coeffs: Vec<c64>,
    ts: Vec<c64>,
    basis: Vec<usize>,
}

impl SmallLs {
    fn new(w: usize, m: usize) -> Self {
        let zero = c64::new(0.0, 0.0);
        Self {
            w,
            m,
            q: vec![zero; w * m],
            r: vec![zero; m * m],
            scale: vec![0.0; m],
            kept: vec![false; m],
            qty: vec![zero; m],
            z: vec![zero; m],
            theta: vec![zero; m],
            residual: vec![zero; w],
            row0: vec![zero; w],
            nb: 0,
            coeffs: vec![zero; m],
            ts: vec![zero; m],
            basis: Vec::with_capacity(m),
        }
    }

    fn solve(&mut self, k: &[c64], y: &[c64], fixed: usize) -> std::result::Result<Solved, ()> {
        let (w, m) = (self.w, self.m);
        let zero = c64::new(0.0, 0.0);
        self.r.iter_mut().for_each(|v| *v = zero);
        let mut dropped = 0;
        // orthonormal columns are stored compactly: basis index b for kept columns
        self.basis.clear();
        for c in 0..m {
            let col = &k[c * w..(c + 1) * w];
            let norm = col.iter().map(|v| v.norm_sqr()).sum::<f64>().sqrt();
            self.kept[c] = false;
            if norm == 0.0 || !norm.is_finite() {
                if c < fixed {
                    return Err(());
                }
                dropped += 1;
                continue;
            }
            self.scale[c] = 1.0 / norm;
            let b = self.basis.len();
            let (done, rest) = self.q.split_at_mut(b * w);
            let v = &mut rest[..w];
            for j in 0..w {
                v[j] = col[j] * self.scale[c];
            }
            let coeffs = &mut self.coeffs[..b];
            coeffs.iter_mut().for_each(|v| *v = zero);
            for _pass in 0..2 {
                for (bi, cf) in coeffs.iter_mut().enumerate() {
                    let qb = &done[bi * w..(bi + 1) * w];
                    let mut h = zero;
                    for j in 0..w {
                        h += qb[j].conj() * v[j];
                    }
                    for j in 0..w {
                        v[j] -= qb[j] * h;
                    }
                    *cf += h;
                }
            }
            let rn = v.iter().map(|x| x.norm_sqr()).sum::<f64>().sqrt();
            if rn <= 1e-10 {
                if c < fixed {
                    return Err(());
                }
                dropped += 1;
                continue;
            }
            for x in v.iter_mut() {
                *x /= rn;
            }
            // R is stored over basis indices: r[bi * m + b]
            for (bi, cf) in coeffs.iter().enumerate() {
                self.r[bi * m + b] = *cf;
            }
            self.r[b * m + b] = c64::new(rn, 0.0);
            self.kept[c] = true;
            self.basis.push(c);
        }
        let nb = self.basis.len();
        // Q^H y
        for bi in 0..nb {
            let qb = &self.q[bi * w..(bi + 1) * w];
            let mut h = zero;
            for j in 0..w {
                h += qb[j].conj() * y[j];
            }
            self.qty[bi] = h;
        }
        // back substitution R θs = Q^H y
        let ts = &mut self.ts[..nb];
        for i in (0..nb).rev() {
            let mut v = self.qty[i];
            for (kk, t) in ts.iter().enumerate().skip(i + 1) {
                v -= self.r[i * m + kk] * *t;
            }
            ts[i] = v / self.r[i * m + i].re;
        }
        self.theta.iter_mut().for_each(|v| *v = zero);
        for (bi, &c) in self.basis.iter().enumerate() {
            self.theta[c] = ts[bi] * self.scale[c];
        }
        // residual y − Q Q^H y
        for (j, (res, yj)) in self.residual.iter_mut().zip(y).enumerate() {
            let mut v = *yj;
            for bi in 0..nb {
                v -= self.q[bi * w + j] * self.qty[bi];
            }
            *res = v;
        }
        // first row of K^+ (column 0 is always kept: it is a fixed column): z = R^{-H} e0,
        // a_j = conj(Σ_i z_i Q_ji) · scale_0
        for i in 0..nb {
            let mut v = if i == 0 { c64::new(1.0, 0.0) } else { zero };
            for kk in 0..i {
                v -= self.r[kk * m + i].conj() * self.z[kk];
            }
            self.z[i] = v / self.r[i * m + i].re;
        }
        for j in 0..w {
            let mut v = zero;
            for bi in 0..nb {
                v += self.z[bi] * self.q[bi * w + j];
            }
            self.row0[j] = v.conj() * self.scale[0];
        }
        self.nb = nb;
        Ok(Solved { dropped })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_defaults_and_errors() {
        let o = LrmOptions::default();
        assert_eq!(o.degrees(), (2, 2, 2));
        assert_eq!(o.n_params(), 8);
        assert_eq!((o.half_width(), o.window()), (6, 13));
        assert_eq!(o.dof().unwrap(), 5);
        assert!(LrmOptions::new().with_half_width(3).is_err());
        assert!(LrmOptions::new().with_degrees(2, 0, 2).is_err());
        assert!(LrmOptions::new().with_degrees(7, 2, 2).is_err());
        assert_eq!(
            LrmOptions::new()
                .with_degrees(1, 1, 1)
                .unwrap()
                .with_half_width(3)
                .unwrap()
                .dof()
                .unwrap(),
            2
        );
    }
}
