//! The MIMO closed-loop FRF from **non-periodic** multi-input records: the multivariable Local
//! Polynomial Method (Pintelon et al. 2010) with the excitation $r$ as the input.
//!
//! Conventions as in [`mimo`](super::mimo): $u = -C y + r$, $T_{ry} = (I + PC)^{-1}P$,
//! $S = T_{ru} = (I + CP)^{-1}$, $P = T_{ry} S^{-1}$. The record holds $M \ge 1$ experiments of
//! $N$ samples each (equal lengths), with $n_r$ excitation channels, $n_u = n_r$ controller
//! outputs and $n_y$ displacements; the excitations may be random noise, chirps or any
//! broadband non-periodic signals — one experiment with $n_r$ independent noises, or a
//! sequential design (one input per experiment), or anything in between.
//!
//! # Model
//! Every channel of every experiment is transformed once without a window,
//! $X_e(k) = N^{-1/2}\sum_t x_e(t)\,e^{-j2\pi kt/N}$, and the $n_z = n_y + n_u$ responses
//! $z = (y, u)$ obey exactly $Z_e(k) = G(\Omega_k)R_e(k) + T_e(\Omega_k) + V_e(k)$ with
//! $G = [T_{ry}; S]$ ($n_z \times n_r$) and a transient $T_e$ per experiment (leakage of the
//! non-periodic signals, initial and final conditions). Around line $k$ both are polynomials of
//! degree $R$ in the scaled line offset $x = r/n$ on a window of $w = 2n+1$ lines (shifted at
//! the ends of the grid, as in [`lpm`](super::lpm)):
//!
//! $$Z_e(k+r) = \sum_{s=0}^{R}\Big(\sum_{j=1}^{n_r} g_{j,s}\,R_{j,e}(k+r) + t_{e,s}\Big)x^s
//!   + V_e(k+r),$$
//!
//! $G$ shared by the experiments, one transient per experiment. Stacking the $M$ windows gives
//! one regressor $K$ ($Mw \times n_\theta$, $n_\theta = (n_r + M)(R+1)$) for all outputs,
//! solved per line by least squares (equilibrated normal equations, Cholesky); $\hat G(k)$ are
//! the $g_{j,0}$. The residuals $E$ ($Mw \times n_z$) give the noise covariance of one DFT line,
//! $\hat C_V = E^{\mathsf T}\bar E/q$ with $q = Mw - n_\theta$ degrees of freedom, and
//!
//! $$\operatorname{E}\big[\delta G_{o_1 j}\,\overline{\delta G_{o_2 l}}\big]
//!   = \hat C_{V,o_1o_2}\,Q_{jl},\qquad Q = \big[(K^{\mathsf H}K)^{-1}\big]_{g_{\cdot,0}}.$$
//!
//! The plant $\hat P = \hat T_{ry}\hat S^{-1}$ has, to first order,
//! $\delta P_{ab} = \sum_j (S^{-1})_{jb}\, h_a^{\mathsf T}\delta G_{:,j}$ with
//! $h_a = (e_a, -P_{a,:})$ over $(y, u)$, so
//!
//! $$\sigma^2_{P_{ab}} = \big(s_b^{\mathsf T} Q\,\bar s_b\big)\big(h_a^{\mathsf T}\hat C_V\bar h_a\big),
//!   \qquad s_b = (S^{-1})_{:,b},$$
//!
//! which for $1 \times 1$ data is the plant variance of
//! [`lpm_closed_loop`](super::lpm::lpm_closed_loop) (the same fit, the same numbers).
//!
//! # Lines, coherence, condition numbers
//! A line is estimated when, for **every** input $j$, the window's power
//! $\sum_e\sum_{r}|R_{j,e}(k+r)|^2$ reaches [`EXCITED_FRACTION`] of that input's average line
//! power (over all lines and experiments) times $w$ — the SISO rule per input — and the local
//! regressor has full rank. The multiple coherence of response $z_o$ is the share of its line
//! power explained by the excitation, $\gamma_o^2 = \sum_e|\hat G_{o,:}R_e(k)|^2 /
//! \big(\sum_e|\hat G_{o,:}R_e(k)|^2 + M\hat C_{V,oo}\big)$; `cond_r` is the condition number
//! of $Q^{-1}$ (how independently the inputs are excited in the window) and `cond_u` that of
//! $\hat S$. The variances have $q$ complex degrees of freedom
//! ([`MimoClosedLoopFrf::dof`](super::mimo::MimoClosedLoopFrf::dof)).
//!
//! # Requirements
//! * the inputs must be excited **independently** within every window (independent noises, or
//!   different experiments): $n_r$ identical noises give a singular $Q$ and an error naming the
//!   line;
//! * $G$ and the transients smooth over $w$ lines (the bias grows like $(w/B)^{R+1}$ for a mode
//!   $B$ lines wide): lightly damped modes need long records;
//! * non-periodic excitation: a periodic record (every line of $r$ on multiples of some
//!   $P \ge 2$) is analysed by [`periodic`](super::mimo::periodic) instead, which is exact.
//!
//! # Example
//! ```
//! use ambid_core::data::IoData;
//! use ambid_core::frf::mimo_lpm::{local_polynomial, MimoLpmOptions};
//! use rand::{RngExt, SeedableRng};
//! use rand_chacha::ChaCha8Rng;
//! // two inputs in open loop (u = r), y = P u with a static P, one experiment of white noises
//! let mut rng = ChaCha8Rng::seed_from_u64(7);
//! let n = 2048;
//! let r0: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
//! let r1: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
//! let y0: Vec<f64> = r0.iter().zip(&r1).map(|(a, b)| a + 0.5 * b).collect();
//! let y1: Vec<f64> = r0.iter().zip(&r1).map(|(a, b)| 0.2 * a - 2.0 * b).collect();
//! let data = IoData::new(vec![
//!     ("r_xa".into(), r0.clone()), ("r_xb".into(), r1.clone()),
//!     ("u_xa".into(), r0), ("u_xb".into(), r1),
//!     ("y_xa".into(), y0), ("y_xb".into(), y1),
//! ], 1e-3, None).unwrap();
//! let frf = local_polynomial(&data, &MimoLpmOptions::new()).unwrap();
//! let p = frf.plant.at(10).unwrap();
//! assert!((p[(0, 1)].re - 0.5).abs() < 1e-9 && (p[(1, 1)].re + 2.0).abs() < 1e-9);
//! ```
//!
//! # Reference
//! R. Pintelon, J. Schoukens, G. Vandersteen, K. Barbé, "Estimation of nonparametric noise and
//! FRF models for multivariable systems — Part I: Theory", *Mechanical Systems and Signal
//! Processing* 24(3), 573–595, 2010.

use super::lpm::{gcd, window_lo, EXCITED_FRACTION};
use super::mimo::{cond_of, inv_small, svd_small, MimoClosedLoopFrf, MimoDesign};
use crate::data::{IoData, Role};
use crate::error::{Error, Result};
use crate::lti::Frd;
use faer::{c64, Mat};
use rayon::prelude::*;
use realfft::RealFftPlanner;

const ZERO: c64 = c64 { re: 0.0, im: 0.0 };

/// Degree, window and band of [`local_polynomial`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MimoLpmOptions {
    /// Polynomial degree $R$ of $G$ and of the transients (default 2).
    pub degree: usize,
    /// Half width $n$ of the window of $2n+1$ lines (`None`: the smallest with $q \ge 3$ degrees
    /// of freedom, see [`MimoLpmOptions::half_width_for`]).
    pub half_width: Option<usize>,
    /// Only lines with $f_{min} \le f \le f_{max}$ \[Hz\] (`None`: lines $1..\lfloor N/2\rfloor$).
    pub band: Option<(f64, f64)>,
}

impl Default for MimoLpmOptions {
    fn default() -> Self {
        Self::new()
    }
}

impl MimoLpmOptions {
    /// $R = 2$, the smallest window with $q \ge 3$, all lines.
    pub fn new() -> Self {
        Self {
            degree: 2,
            half_width: None,
            band: None,
        }
    }

    /// Restricts the lines to $[f_{min}, f_{max}]$ Hz.
    pub fn band(mut self, f_min: f64, f_max: f64) -> Self {
        self.band = Some((f_min, f_max));
        self
    }

    /// The half width used for $n_r$ inputs and $M$ experiments: the one set, else the smallest
    /// $n$ with $q = M(2n+1) - (n_r + M)(R+1) \ge 3$ (for $1 \times 1$ data $n = R + 2$, the
    /// default of [`LpmOptions`](super::lpm::LpmOptions)).
    pub fn half_width_for(&self, n_inputs: usize, n_experiments: usize) -> usize {
        if let Some(h) = self.half_width {
            return h;
        }
        let np = (n_inputs + n_experiments) * (self.degree + 1);
        let m = n_experiments.max(1);
        // M(2n+1) ≥ np + 3
        let need = (np + 3).div_ceil(m);
        need.saturating_sub(1).div_ceil(2).max(1)
    }
}

/// One real FFT of every channel, lines $0..=\lfloor N/2\rfloor$, scaled by $N^{-1/2}$.
fn spectra(x: &[&[f64]]) -> Result<Vec<Vec<c64>>> {
    let n = x.first().map_or(0, |c| c.len());
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(n);
    let s = 1.0 / (n as f64).sqrt();
    x.par_iter()
        .map(|c| {
            let mut input = c.to_vec();
            let mut out = fft.make_output_vec();
            fft.process(&mut input, &mut out)
                .map_err(|e| Error::numerical("MIMO LPM DFT", e.to_string()))?;
            Ok(out.iter().map(|z| c64::new(z.re * s, z.im * s)).collect())
        })
        .collect()
}

/// Whether every line of $r$ lies on multiples of some $P \ge 2$ (a periodic excitation).
fn is_periodic<'a>(rf: impl Iterator<Item = &'a Vec<c64>>, n_lines: usize) -> Option<usize> {
    let mut g = 0usize;
    for spec in rf {
        let pmax = spec[1..=n_lines]
            .iter()
            .fold(0.0f64, |a, z| a.max(z.norm_sqr()));
        if pmax <= 0.0 {
            continue;
        }
        for (k, z) in spec.iter().enumerate().take(n_lines + 1).skip(1) {
            if z.norm_sqr() > 1e-10 * pmax {
                g = gcd(g, k);
                if g == 1 {
                    return None;
                }
            }
        }
    }
    (g >= 2).then_some(g)
}

/// Hermitian positive definite solve by Cholesky of an equilibrated matrix (row-major `h`,
/// `n × n`); `None` when a pivot falls below $10^{-13}$ (rank deficient).
fn cholesky(h: &mut [c64], n: usize) -> Option<()> {
    for j in 0..n {
        let mut s = h[j * n + j].re;
        for k in 0..j {
            s -= h[j * n + k].norm_sqr();
        }
        if s.is_nan() || s <= 1e-13 {
            return None;
        }
        let l = s.sqrt();
        h[j * n + j] = c64::new(l, 0.0);
        for i in j + 1..n {
            let mut v = h[i * n + j];
            for k in 0..j {
                v -= h[i * n + k] * h[j * n + k].conj();
            }
            h[i * n + j] = v / l;
        }
    }
    Some(())
}

/// Solves $L L^{\mathsf H} x = b$ in place with the factor from [`cholesky`].
fn chol_solve(l: &[c64], n: usize, b: &mut [c64]) {
    for i in 0..n {
        let mut v = b[i];
        for k in 0..i {
            v -= l[i * n + k] * b[k];
        }
        b[i] = v / l[i * n + i].re;
    }
    for i in (0..n).rev() {
        let mut v = b[i];
        for k in i + 1..n {
            v -= l[k * n + i].conj() * b[k];
        }
        b[i] = v / l[i * n + i].re;
    }
}

/// One estimated line.
struct LineFit {
    /// $G = [T_{ry}; S]$, column-major $n_z \times n_r$.
    g: Vec<c64>,
    /// $Q$, row-major $n_r \times n_r$.
    q: Vec<c64>,
    /// $\hat C_V$, row-major $n_z \times n_z$.
    cv: Vec<c64>,
    /// $\sum_e |\hat G_{o,:} R_e(k)|^2$ per response.
    explained: Vec<f64>,
}

/// The MIMO closed-loop FRF of a non-periodic record by the multivariable local polynomial
/// method; see the [module docs](self). All experiments must have the same length; $T_{ry}$,
/// $S$ and $P$ come with their first-order variances.
///
/// # Errors
/// * [`Error::InvalidArgument`]: a missing r, u or y channel or different r and u counts,
///   experiments of different lengths, a non-finite sample, an input without power, a
///   periodic excitation (use [`periodic`](super::mimo::periodic)), a record shorter than the
///   window, a band without an excited line;
/// * [`Error::Numerical`]: the local regressor rank deficient on every line (e.g. two inputs
///   driven by the same signal), or $\hat S$ singular on a line.
pub fn local_polynomial(data: &IoData, opts: &MimoLpmOptions) -> Result<MimoClosedLoopFrf> {
    let (nr, nu, ny) = super::mimo::channel_counts(data)?;
    if opts.degree > 8 {
        return Err(Error::invalid(
            "degree",
            format!(
                "the local polynomial degree must be at most 8, got {}; 2 is usual",
                opts.degree
            ),
        ));
    }
    let m = data.n_experiments();
    let n = data.len();
    for e in 1..m {
        let le = data.experiment_len(e).unwrap_or(0);
        if le != n {
            return Err(Error::invalid(
                "experiments",
                format!(
                    "experiment {e} has {le} samples, experiment 0 has {n}; the local polynomial \
                     method needs one frequency grid: cut the experiments to the same length"
                ),
            ));
        }
    }
    data.require_finite(&[Role::Excitation, Role::Input, Role::Output])?;
    let nz = ny + nu;
    let r1 = opts.degree + 1;
    let np = (nr + m) * r1;
    let half = opts.half_width_for(nr, m);
    let w = 2 * half + 1;
    if m * w <= np {
        return Err(Error::invalid(
            "half_width",
            format!(
                "a window of {w} lines in {m} experiment(s) leaves no degree of freedom for {np} \
                 parameters; use a larger half width (or the default)"
            ),
        ));
    }
    let q = m * w - np;
    let n_lines = n / 2;
    if n_lines < w {
        return Err(Error::invalid(
            "r",
            format!(
                "the record of {n} samples has {n_lines} DFT lines, fewer than the window of {w} \
                 lines; record longer or use a smaller degree/half width"
            ),
        ));
    }
    if let Some((lo, hi)) = opts.band {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(Error::invalid(
                "band",
                format!("the band must be finite with f_min ≤ f_max, got ({lo}, {hi})"),
            ));
        }
    }
    // spectra: rf[e][j], zf[e][o] with z = (y, u)
    let mut rf = Vec::with_capacity(m);
    let mut zf = Vec::with_capacity(m);
    for e in 0..m {
        rf.push(spectra(&data.signals(Role::Excitation, e)?)?);
        let mut z = data.signals(Role::Output, e)?;
        z.extend(data.signals(Role::Input, e)?);
        zf.push(spectra(&z)?);
    }
    // every input excited; the SISO power rule per input
    let mut thr = vec![0.0; nr];
    let mut cum = vec![vec![0.0; n_lines + 2]; nr];
    for j in 0..nr {
        let mut total = 0.0;
        for k in 1..=n_lines {
            let p: f64 = (0..m).map(|e| rf[e][j][k].norm_sqr()).sum();
            cum[j][k + 1] = cum[j][k] + p;
            total += p;
        }
        if total.is_nan() || total <= 0.0 {
            return Err(Error::invalid(
                "excitation",
                format!(
                    "excitation channel {} has no power in any experiment: every input must be \
                     excited; check the r columns",
                    data.role_names(Role::Excitation)[j]
                ),
            ));
        }
        thr[j] = EXCITED_FRACTION * total / n_lines as f64 * w as f64;
    }
    if let Some(p) = is_periodic(rf.iter().flatten(), n_lines) {
        return Err(Error::invalid(
            "excitation",
            format!(
                "the excitation is periodic ({p} periods: its lines are multiples of {p}); use the \
                 exact periodic estimate frf::mimo::periodic (give the period length) instead of \
                 the local polynomial method"
            ),
        ));
    }
    let df = data.fs() / n as f64;
    let in_band = |k: usize| match opts.band {
        None => true,
        Some((lo, hi)) => {
            let f = k as f64 * df;
            f >= lo && f <= hi
        }
    };
    let candidates: Vec<usize> = (1..=n_lines)
        .filter(|&k| {
            in_band(k) && {
                let lo = window_lo(k, half, n_lines);
                (0..nr).all(|j| cum[j][lo + w] - cum[j][lo] >= thr[j])
            }
        })
        .collect();
    if candidates.is_empty() {
        return Err(Error::invalid(
            "band",
            format!(
                "no line in the band where every input reaches {} % of its average line power \
                 over the window: set the band to where all r channels are excited",
                100.0 * EXCITED_FRACTION
            ),
        ));
    }
    // scaled powers x^s, x = (i - shift)/half, per window shift
    let scale = 1.0 / half.max(1) as f64;
    let pw = |shift: usize, i: usize, s: usize| ((i as f64 - shift as f64) * scale).powi(s as i32);
    let fit_line = |k: usize| -> Option<LineFit> {
        let lo = window_lo(k, half, n_lines);
        let shift = k - lo;
        let rows = m * w;
        // K: rows × np, column order g_{j,s} (j-major), then t_{e,s}
        let mut kmat = vec![ZERO; rows * np];
        for e in 0..m {
            for i in 0..w {
                let row = e * w + i;
                for s in 0..r1 {
                    let x = pw(shift, i, s);
                    for j in 0..nr {
                        kmat[row * np + j * r1 + s] = rf[e][j][lo + i] * x;
                    }
                    kmat[row * np + (nr + e) * r1 + s] = c64::new(x, 0.0);
                }
            }
        }
        // equilibrated Gram matrix
        let mut h = vec![ZERO; np * np];
        for a in 0..np {
            for b in a..np {
                let mut v = ZERO;
                for row in 0..rows {
                    v += kmat[row * np + a].conj() * kmat[row * np + b];
                }
                h[a * np + b] = v;
                h[b * np + a] = v.conj();
            }
        }
        let d: Vec<f64> = (0..np).map(|a| 1.0 / h[a * np + a].re.sqrt()).collect();
        if d.iter().any(|v| !v.is_finite()) {
            return None;
        }
        for a in 0..np {
            for b in 0..np {
                h[a * np + b] *= d[a] * d[b];
            }
        }
        cholesky(&mut h, np)?;
        // θ per response, residuals
        let mut g = vec![ZERO; nz * nr];
        let mut res = vec![ZERO; rows * nz];
        let mut b = vec![ZERO; np];
        for o in 0..nz {
            for (a, ba) in b.iter_mut().enumerate() {
                let mut v = ZERO;
                for e in 0..m {
                    for i in 0..w {
                        v += kmat[(e * w + i) * np + a].conj() * zf[e][o][lo + i];
                    }
                }
                *ba = v * d[a];
            }
            chol_solve(&h, np, &mut b);
            for (a, ba) in b.iter_mut().enumerate() {
                *ba *= d[a];
            }
            for (e, ze) in zf.iter().enumerate() {
                for i in 0..w {
                    let row = e * w + i;
                    let fit = (0..np).fold(ZERO, |acc, a| acc + kmat[row * np + a] * b[a]);
                    res[row * nz + o] = ze[o][lo + i] - fit;
                }
            }
            for j in 0..nr {
                g[j * nz + o] = b[j * r1];
            }
        }
        let mut cv = vec![ZERO; nz * nz];
        for a in 0..nz {
            for c in 0..nz {
                let mut v = ZERO;
                for row in 0..rows {
                    v += res[row * nz + a] * res[row * nz + c].conj();
                }
                cv[a * nz + c] = v / q as f64;
            }
        }
        // Q = [(KᴴK)⁻¹] on the g_{j,0}: columns of the inverse for unit vectors
        let mut qm = vec![ZERO; nr * nr];
        for l in 0..nr {
            b.iter_mut().for_each(|v| *v = ZERO);
            b[l * r1] = c64::new(d[l * r1], 0.0);
            chol_solve(&h, np, &mut b);
            for j in 0..nr {
                qm[j * nr + l] = b[j * r1] * d[j * r1];
            }
        }
        let explained = (0..nz)
            .map(|o| {
                (0..m)
                    .map(|e| {
                        (0..nr)
                            .fold(ZERO, |acc, j| acc + g[j * nz + o] * rf[e][j][k])
                            .norm_sqr()
                    })
                    .sum()
            })
            .collect();
        Some(LineFit {
            g,
            q: qm,
            cv,
            explained,
        })
    };
    let fits: Vec<Option<LineFit>> = candidates.par_iter().map(|&k| fit_line(k)).collect();
    let mut lines = Vec::new();
    let mut kept = Vec::new();
    for (k, f) in candidates.iter().zip(fits) {
        if let Some(f) = f {
            lines.push(*k);
            kept.push(f);
        }
    }
    if lines.is_empty() {
        let k = candidates[0];
        return Err(Error::numerical(
            "MIMO LPM",
            format!(
                "the local regressor is rank deficient on every line of the band (first at {:.4} \
                 Hz): the inputs are not excited independently (e.g. the same signal on two \
                 axes) or are locally polynomial in the line index; excite every axis with its \
                 own broadband signal, or record one experiment per axis",
                k as f64 * df
            ),
        ));
    }
    let nl = lines.len();
    let f: Vec<f64> = lines.iter().map(|&k| k as f64 * df).collect();
    let (mut t, mut s, mut p) = (
        Vec::with_capacity(nl * ny * nu),
        Vec::with_capacity(nl * nu * nu),
        Vec::with_capacity(nl * ny * nu),
    );
    let (mut vt, mut vs, mut vp) = (
        Vec::with_capacity(nl * ny * nu),
        Vec::with_capacity(nl * nu * nu),
        Vec::with_capacity(nl * ny * nu),
    );
    let mut coherence = Vec::with_capacity(nl * ny);
    let mut coherence_u = Vec::with_capacity(nl * nu);
    let mut cond_r = Vec::with_capacity(nl);
    let mut cond_u = Vec::with_capacity(nl);
    for (li, fit) in kept.iter().enumerate() {
        for j in 0..nr {
            for i in 0..ny {
                t.push(fit.g[j * nz + i]);
                vt.push((fit.cv[i * nz + i].re * fit.q[j * nr + j].re).max(0.0));
            }
            for i in 0..nu {
                s.push(fit.g[j * nz + ny + i]);
                vs.push((fit.cv[(ny + i) * nz + ny + i].re * fit.q[j * nr + j].re).max(0.0));
            }
        }
        let sm = Mat::<c64>::from_fn(nu, nu, |i, j| fit.g[j * nz + ny + i]);
        let singular = || {
            Error::numerical(
                "MIMO LPM",
                format!(
                    "the estimated sensitivity S is singular at {:.6} Hz; restrict the band",
                    f[li]
                ),
            )
        };
        let cu = cond_of(&svd_small(&sm)?.0);
        if !cu.is_finite() {
            return Err(singular());
        }
        let s_inv = inv_small(&sm).ok_or_else(singular)?;
        let tm = Mat::<c64>::from_fn(ny, nu, |i, j| fit.g[j * nz + i]);
        let pm = &tm * &s_inv;
        for bcol in 0..nu {
            // s_bᵀ Q s̄_b
            let mut sq = 0.0;
            for j in 0..nr {
                for l in 0..nr {
                    sq += (s_inv[(j, bcol)] * fit.q[j * nr + l] * s_inv[(l, bcol)].conj()).re;
                }
            }
            for a in 0..ny {
                p.push(pm[(a, bcol)]);
                // h_a = (e_a over y, −P_{a,:} over u)
                let h = |o: usize| -> c64 {
                    if o < ny {
                        if o == a {
                            c64::new(1.0, 0.0)
                        } else {
                            ZERO
                        }
                    } else {
                        -pm[(a, o - ny)]
                    }
                };
                let mut hc = 0.0;
                for o1 in 0..nz {
                    let h1 = h(o1);
                    if h1 == ZERO {
                        continue;
                    }
                    for o2 in 0..nz {
                        let h2 = h(o2);
                        if h2 != ZERO {
                            hc += (h1 * fit.cv[o1 * nz + o2] * h2.conj()).re;
                        }
                    }
                }
                vp.push((sq * hc).max(0.0));
            }
        }
        let coh = |o: usize| {
            let ex = fit.explained[o];
            let den = ex + m as f64 * fit.cv[o * nz + o].re.max(0.0);
            if den > 0.0 {
                ex / den
            } else {
                f64::NAN
            }
        };
        coherence.extend((0..ny).map(coh));
        coherence_u.extend((ny..nz).map(coh));
        let qinfo = Mat::<c64>::from_fn(nr, nr, |j, l| fit.q[j * nr + l]);
        cond_r.push(cond_of(&svd_small(&qinfo)?.0));
        cond_u.push(cu);
    }
    let ts = 1.0 / data.fs();
    let mk = |rows: usize, v: Vec<c64>, var: Vec<f64>| {
        Frd::new_matrix(f.clone(), rows, nu, v, Some(var), Some(ts))
    };
    Ok(MimoClosedLoopFrf {
        t_ry: mk(ny, t, vt)?,
        s: mk(nu, s, vs)?,
        plant: mk(ny, p, vp)?,
        plant_indirect: None,
        coherence,
        coherence_u,
        cond_r,
        cond_u,
        measured: vec![true; nl * nu],
        lines,
        periods: 1,
        dof: q as f64,
        design: MimoDesign::LocalPolynomial {
            degree: opts.degree,
            half_width: half,
        },
    })
}
