//! The MIMO closed-loop frequency response from periodic multi-input experiments.
//!
//! Conventions (`docs/conventions.md`, DESIGN.md): the excitation $r$ ($n_r$ channels) is added to
//! the controller outputs, $u = -C y + r$ ($n_u = n_r$ channels), $y = P u + v$ ($n_y$ channels),
//! so that
//!
//! $$T_{ry} = (I + P C)^{-1} P,\qquad S = T_{ru} = (I + C P)^{-1},\qquad P = T_{ry} S^{-1}.$$
//!
//! Two periodic designs are supported, both from one [`IoData`] (channels found by their roles,
//! `r_xa … r_yb`, `u_…`, `y_…`, in axis order):
//!
//! * **several experiments** ([`periodic`]; sequential, orthogonal/Hadamard or any other design
//!   with $M \ge n_r$ experiments whose excitations are independent on every line);
//! * **zippered** ([`zippered`]; one experiment, each input on its own interleaved lines).
//!
//! [`estimate`] picks the design from the record. Non-periodic records (noise, chirps; no
//! period length) go to the multivariable local polynomial method of
//! [`mimo_lpm`](super::mimo_lpm), which returns the same [`MimoClosedLoopFrf`].
//!
//! # Period averages and excited lines
//! Every experiment $e$ is cut into periods of $N$ samples (the first `skip_periods` dropped as
//! transient) and analysed by [`PeriodicAnalyzer`]: per line $k$ the period-mean DFTs
//! $\bar R_e(k), \bar U_e(k), \bar Y_e(k)$ and the per-period covariance $\hat\sigma$ of the
//! stacked vector $(U_e(k), Y_e(k))$ across the $P$ periods; the covariance of the means is
//! $\Sigma_e(k) = \hat\sigma/P$ (module [`periodic`](super::periodic)).
//!
//! **Excited lines** are decided from the DFT of $r$ alone: line $k \ge 1$ is excited by input
//! $j$ in experiment $e$ when $|\bar R_{j,e}(k)| > \rho\,\max_{e',k'}|\bar R_{j,e'}(k')|$ with
//! $\rho$ = [`MimoOptions::rel_threshold`] (default $10^{-6}$; DC is never used). The multi-
//! experiment estimate uses every line excited by some input in some experiment (within the
//! optional band); the zippered one assigns each line to the single input that excites it.
//! [`periodic`] decides them first, from the DFT of each r channel's time-averaged period (by
//! linearity its period mean), and then accumulates the period covariances only on those lines
//! and only for the pairs its formulas read (u–u, u–y and the y–y diagonal); the per-line solves
//! run in one workspace per rayon task, so the result does not depend on the thread count.
//!
//! # Several experiments
//! Per line, stack the experiments as columns: $R(k)$ ($n_r \times M$), $U(k)$, $Y(k)$. With
//! $R^+ = R^{\mathsf H}(R R^{\mathsf H})^{-1}$ (computed by an SVD),
//!
//! $$\hat T_{ry} = Y R^+,\qquad \hat S = U R^+,\qquad \hat P = \hat T_{ry}\hat S^{-1}
//!   \ \big(= Y U^{-1}\ \text{for}\ M = n_r\big).$$
//!
//! $R$ is the recorded digital excitation and taken as exact (its period spread is not
//! propagated). The experiments are independent records, so with $W = R^+ \hat S^{-1}$
//! ($M \times n_u$) the first-order errors are
//!
//! $$\delta T_{ij} = \sum_e \delta Y_{ie} R^+_{ej},\qquad
//!   \delta P_{ab} = \sum_e \big(\delta Y_{ae} - \textstyle\sum_c \hat P_{ac}\,\delta U_{ce}\big) W_{eb},$$
//!
//! $$\sigma^2_{T_{ij}} = \sum_e |R^+_{ej}|^2\, \Sigma_{e,y_iy_i},\qquad
//!   \sigma^2_{S_{ij}} = \sum_e |R^+_{ej}|^2\, \Sigma_{e,u_iu_i},\qquad
//!   \sigma^2_{P_{ab}} = \sum_e |W_{eb}|^2\; g_a^{\mathsf T}\, \Sigma_e\, \bar g_a,$$
//!
//! with $g_a = (-\hat P_{a1}, \dots, -\hat P_{a n_u}, e_a)$ over the stacked $(U, Y)$: the full
//! covariance of each experiment's $(u, y)$ DFT vector enters the plant (noise that enters the
//! loop shows in both $u$ and $y$). For $1 \times 1$ data these are exactly the formulas of
//! [`closed_loop::from_periodic`](super::closed_loop::from_periodic).
//!
//! **Multiple coherence** of output $y_i$: the share of its period power explained by the
//! excitation, $\gamma_i^2 = \sum_e |(\hat T R)_{ie}|^2 \big/ \sum_e \overline{|Y_{ie,p}|^2}$
//! (mean over the periods; $= |\bar Y|^2/\overline{|Y_p|^2}$ for SISO, the
//! [`ClosedLoopFrf::coh_ry`](super::closed_loop::ClosedLoopFrf::coh_ry) of an exact $r$),
//! likewise for $u$. **Condition numbers** $\kappa(R(k))$ and $\kappa(U(k))$ (ratio of extreme
//! singular values); a line with $\kappa > $ [`MimoOptions::max_cond`] (default $10^{12}$) is an
//! error naming its frequency (e.g. two identical experiments).
//!
//! # Zippered design
//! One experiment; input $j$ alone excites its lines $\mathcal L_j$ (a line excited by two inputs
//! is an error). On $k \in \mathcal L_j$ column $j$ is measured, $\hat T_{:,j} = \bar Y/\bar R_j$,
//! $\hat S_{:,j} = \bar U/\bar R_j$, with the covariance $\Sigma(k)/|\bar R_j|^2$ of the stacked
//! column $z_j = (T_{:,j}, S_{:,j})$ ($n_z = n_y + n_u$ entries). The **common grid** is the
//! union of all $\mathcal L_j$; column $j$ is brought to a grid line $k \notin \mathcal L_j$
//! by a weighted sum of its values on nearby own lines,
//!
//! $$\hat z_j(k) = \sum_l c_l(k)\, \hat z_j(k_l),\qquad
//!   \Sigma_{z_j}(k) = \sum_l |c_l(k)|^2\, \Sigma_{z_j}(k_l)$$
//!
//! (different lines are independent), with the weights of one of two rules
//! ([`ZipperInterpolation`], chosen by [`zippered_with`]):
//!
//! * **Local rational** (the default, [`ZipperInterpolation::Rational`]): over the 6 own lines
//!   nearest to $k$ (3 on each side inside the grid, shifted at the ends), in the local variable
//!   $s = (x - k)/h$ ($h$ half the window's span), every entry $a$ of the stacked column is
//!   modelled as $z_a(s) \approx N_a(s)/D(s)$ with degree-4 numerators and **one degree-2
//!   denominator common to the column**, $D(s) = 1 + d_1 s + d_2 s^2$ (all entries of a column of
//!   $T_{ry}$ and $S$ share the closed-loop poles, so one local denominator captures a resonance
//!   a few lines wide that no polynomial follows). $D$ comes from the Levy linearisation
//!   $\min \sum_a w_a^2 \sum_l |z_a(s_l) D(s_l) - N_a(s_l)|^2$ with the numerators eliminated
//!   (a real projector per window), then one Sanathanan–Koerner step (the same problem with the
//!   line weights $1/|D_{\text{prev}}(s_l)|$). The entry weights are
//!   $w_a = (\overline{\sigma_a^2} + 10^{-6}\,\overline{|z_a|^2})^{-1/2}$ over the window, so
//!   noisy data weigh each entry by its noise and noise-free data by its size. With $D$ fixed the
//!   value at $k$ is $N_a(0) = \sum_l c_l z_a(s_l)$, $c_l = \omega_l D(s_l)\, [(M^{\mathsf T}
//!   M)^{-1} M^{\mathsf T}]_{0l}$, $M = \operatorname{diag}(\omega) V$ ($V$ the degree-4
//!   Vandermonde matrix of the $s_l$, $\omega_l = 1/|D_{\text{prev}}(s_l)|$): linear in the data,
//!   which gives the variance above. **Approximation:** $D$ itself is estimated from the same
//!   noisy data and treated as exact (its randomness is not propagated); on the twin the
//!   resulting bands cover the truth (see below). Where the denominator's normal equations have a
//!   condition number above $10^{10}$, a weight is not finite, or the noise gain
//!   $\sum_l |c_l|^2$ exceeds 100, the line falls back to cubic Lagrange (so does every line
//!   of an input with fewer than 6 lines).
//! * **Cubic Lagrange** ([`ZipperInterpolation::Lagrange`]): the degree-3 polynomial in the line
//!   index through the 4 lines of $\mathcal L_j$ nearest to $k$ (two on each side, shifted at
//!   the ends), $c_l(k) = \prod_{m \ne l} (k - k_m)/(k_l - k_m)$.
//!
//! Then $\hat P = \hat T \hat S^{-1}$ per grid line, with
//! $\delta P_{ab} = \sum_j (S^{-1})_{jb}\,(\delta T_{aj} - \sum_c P_{ac}\,\delta S_{cj})$ and the
//! columns independent.
//!
//! **Bias.** Lagrange's error is $\frac{G^{(4)}(\xi)}{4!}\prod_m (k - k_m)$: with $n_r$
//! interleaved inputs the own lines are $n_r$ lines apart, so near a resonance of half-power
//! bandwidth $B$ lines the relative bias is of the order of $(n_r/B)^4$ — a lightly damped mode
//! only a few lines wide is smeared, and the plant, which needs all columns at once, inherits it.
//! The rational rule is exact for a column that is locally a ratio of a degree-4 numerator and
//! one quadratic (one pole pair dominating the window) and so follows a sharp mode; it is
//! biased where two or more pole pairs act within the window or where the response bends
//! sharply at the ends of the grid (extrapolation below the first own lines, e.g. the lowest
//! lines where the integral action makes $S \to 0$). On the 4-axis twin (noise off, 4.9 Hz
//! lines, own lines 19.5 Hz apart, mode at 780 Hz with $\zeta = 0.019$) the plant's error near
//! the mode falls from 0.13 (Lagrange) to $3.6\cdot10^{-5}$ (0 rpm) and $3\cdot10^{-7}$
//! (30 000 rpm), the 95th percentile over 20 Hz–2 kHz from 0.05 to $2\cdot10^{-4}$–$3\cdot10^{-3}$
//! (`crates/ambid-twin/tests/machine_zipper.rs`); neither reaches $10^{-6}$ everywhere, so only
//! the measured entries are exact. Use a finer frequency grid (longer periods) or a
//! multi-experiment design where the interpolated entries must be exact; the measured columns
//! themselves are unbiased.
//! [`MimoClosedLoopFrf::measured`] tells the measured entries from the interpolated ones. For
//! zippered data `cond_r` is 1 (one input per line) and `cond_u` is $\kappa(\hat S(k))$.
//!
//! # Confidence bands
//! Variances have $\nu = P - 1$ complex degrees of freedom per experiment ([`MimoClosedLoopFrf::dof`],
//! conservative for sums over several experiments); the level-$\alpha$ disc has the radius
//! $\hat\sigma\cdot$[`band_radius_factor`](super::closed_loop::band_radius_factor)$(\alpha, \nu)$.
//!
//! # Example
//! ```
//! use ambid_core::data::IoData;
//! use ambid_core::frf::mimo::{periodic, MimoOptions};
//! // 2 inputs, a static plant P = [[1, 0.5], [0.2, 2]] in open loop (C = 0): u = r, y = P u.
//! // Two experiments (a sequential design), 4 periods of 8 samples each.
//! let n = 8;
//! let base = [1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 1.0, -1.0];
//! let sig: Vec<f64> = (0..4 * n).map(|k| base[k % n]).collect();
//! let zero = vec![0.0; 4 * n];
//! let exp = |r1: &Vec<f64>, r2: &Vec<f64>| {
//!     let y1: Vec<f64> = r1.iter().zip(r2).map(|(a, b)| a + 0.5 * b).collect();
//!     let y2: Vec<f64> = r1.iter().zip(r2).map(|(a, b)| 0.2 * a + 2.0 * b).collect();
//!     IoData::new(vec![
//!         ("r_xa".into(), r1.clone()), ("r_xb".into(), r2.clone()),
//!         ("u_xa".into(), r1.clone()), ("u_xb".into(), r2.clone()),
//!         ("y_xa".into(), y1), ("y_xb".into(), y2),
//!     ], 1e-3, Some(n)).unwrap()
//! };
//! let data = IoData::from_experiments(vec![exp(&sig, &zero), exp(&zero, &sig)]).unwrap();
//! let frf = periodic(&data, &MimoOptions::new()).unwrap();
//! let p = frf.plant.at(0).unwrap();
//! assert!((p[(0, 1)].re - 0.5).abs() < 1e-12 && (p[(1, 0)].re - 0.2).abs() < 1e-12);
//! assert!(frf.cond_r.iter().all(|c| (c - 1.0).abs() < 1e-12));
//! ```

use super::periodic::{PeriodicAnalyzer, PeriodicOptions, PeriodicSpectra};
use crate::data::{IoData, Role};
use crate::error::{Error, Result};
use crate::lti::Frd;
use faer::{c64, Mat};
use rayon::prelude::*;

const ZERO: c64 = c64 { re: 0.0, im: 0.0 };
const ONE: c64 = c64 { re: 1.0, im: 0.0 };

/// Settings of the MIMO periodic estimators.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MimoOptions {
    /// Samples per excitation period; `None` takes the record's
    /// ([`IoData::period_samples`]).
    pub period_samples: Option<usize>,
    /// Leading periods of every experiment dropped as transient.
    pub skip_periods: usize,
    /// A line is excited by an input when its $|\bar R|$ exceeds this fraction of that input's
    /// largest line amplitude (module docs); in $[0, 1)$.
    pub rel_threshold: f64,
    /// Only lines with $f_{min} \le f \le f_{max}$ \[Hz\] (`None`: all excited lines).
    pub band: Option<(f64, f64)>,
    /// Largest condition number of the input matrices accepted on a line.
    pub max_cond: f64,
}

impl Default for MimoOptions {
    fn default() -> Self {
        Self::new()
    }
}

impl MimoOptions {
    /// The record's period, no skipped period, threshold $10^{-6}$, all lines, $\kappa \le 10^{12}$.
    pub fn new() -> Self {
        Self {
            period_samples: None,
            skip_periods: 0,
            rel_threshold: 1e-6,
            band: None,
            max_cond: 1e12,
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

    /// Restricts the lines to $[f_{min}, f_{max}]$ Hz.
    pub fn band(mut self, f_min: f64, f_max: f64) -> Self {
        self.band = Some((f_min, f_max));
        self
    }
}

/// Which design the estimate came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MimoDesign {
    /// $M \ge n_r$ experiments solved per line by least squares.
    Experiments(usize),
    /// One zippered experiment, columns interpolated to the common grid.
    Zippered,
    /// Non-periodic experiments by the multivariable local polynomial method
    /// ([`mimo_lpm`](super::mimo_lpm)): degree $R$ and half width $n$ of the window.
    LocalPolynomial {
        /// Polynomial degree $R$.
        degree: usize,
        /// Half width $n$ (window of $2n+1$ lines).
        half_width: usize,
    },
}

/// The MIMO closed-loop FRF: responses with per-entry variances on the excited lines, and the
/// per-line diagnostics; see the [module docs](self) for the formulas.
///
/// Flat per-line vectors follow [`Frd::values`]: line after line, within a line column by column
/// (`coherence[line * ny + i]`, `measured[line * nu + j]`).
#[derive(Debug, Clone, PartialEq)]
pub struct MimoClosedLoopFrf {
    /// $T_{ry}$ ($n_y \times n_u$), $r \to y$.
    pub t_ry: Frd,
    /// $S = T_{ru}$ ($n_u \times n_u$), $r \to u$.
    pub s: Frd,
    /// The plant $P = T_{ry} S^{-1}$ (joint input–output), $n_y \times n_u$.
    pub plant: Frd,
    /// The indirect plant $T_{ry}(I - C T_{ry})^{-1}$, after
    /// [`with_indirect`](Self::with_indirect).
    pub plant_indirect: Option<Frd>,
    /// Multiple coherence of every output with the excitation, $n_y$ per line.
    pub coherence: Vec<f64>,
    /// Multiple coherence of every input channel $u$ with the excitation, $n_u$ per line.
    pub coherence_u: Vec<f64>,
    /// Condition number of $R(k)$ per line (1 for zippered data).
    pub cond_r: Vec<f64>,
    /// Condition number of $U(k)$ per line ($\hat S(k)$ for zippered data).
    pub cond_u: Vec<f64>,
    /// Line indices $k$ ($f = k f_s / N$).
    pub lines: Vec<usize>,
    /// Whether column $j$ of $T_{ry}$ and $S$ was measured on the line (always for several
    /// experiments) or interpolated (zippered), $n_u$ per line.
    pub measured: Vec<bool>,
    /// Periods averaged per experiment.
    pub periods: usize,
    /// Complex degrees of freedom of the variances, $P - 1$.
    pub dof: f64,
    /// The design.
    pub design: MimoDesign,
}

impl MimoClosedLoopFrf {
    /// Frequencies of the lines \[Hz\].
    pub fn f_hz(&self) -> &[f64] {
        self.plant.f_hz()
    }

    /// Radius factor of the level-`level` confidence disc for [`dof`](Self::dof).
    ///
    /// # Errors
    /// As [`band_radius_factor`](super::closed_loop::band_radius_factor) (e.g. a single period).
    pub fn band_factor(&self, level: f64) -> Result<f64> {
        super::closed_loop::band_radius_factor(level, self.dof)
    }

    /// Adds the indirect plant $P = T_{ry}(I - C T_{ry})^{-1}$ from the known controller
    /// response `controller` ($n_u \times n_y$, from $u = -C y + r$), via
    /// [`indirect_plant`](super::closed_loop::indirect_plant). The controller must hold every
    /// line of [`f_hz`](Self::f_hz) (to $10^{-9}$ relative; other frequencies are ignored), e.g.
    /// `Frd::from_model(&c, frf.f_hz())`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a missing frequency; the errors of `indirect_plant`
    /// (shape, a singular $I - C T_{ry}$ on a line).
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// use ambid_core::frf::mimo::{periodic, MimoOptions};
    /// use ambid_core::lti::Frd;
    /// // SISO (the 1×1 case): P = 2, C = 0.5, u = r − C y → u = r/2, y = r
    /// let base = [1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 1.0, -1.0];
    /// let r: Vec<f64> = (0..32).map(|k| base[k % 8]).collect();
    /// let u: Vec<f64> = r.iter().map(|v| 0.5 * v).collect();
    /// let data = IoData::new(
    ///     vec![("r".into(), r.clone()), ("u".into(), u), ("y".into(), r)], 1e-3, Some(8),
    /// ).unwrap();
    /// let frf = periodic(&data, &MimoOptions::new()).unwrap();
    /// let c = Frd::constant(frf.f_hz(), 0.5, Some(1e-3)).unwrap();
    /// let frf = frf.with_indirect(&c).unwrap();
    /// let pi = frf.plant_indirect.unwrap();
    /// assert!(pi.values().iter().all(|p| (p.re - 2.0).abs() < 1e-12 && p.im.abs() < 1e-12));
    /// ```
    pub fn with_indirect(mut self, controller: &Frd) -> Result<Self> {
        let cf = controller.f_hz();
        let per = controller.ny() * controller.nu();
        let mut vals = Vec::with_capacity(self.lines.len() * per);
        for &f in self.f_hz() {
            let tol = 1e-9 * f.abs().max(1e-300);
            let Some(i) = cf.iter().position(|g| (g - f).abs() <= tol) else {
                return Err(Error::invalid(
                    "controller",
                    format!(
                        "the controller response has no value at {f} Hz; evaluate it at the \
                         estimate's lines (MimoClosedLoopFrf::f_hz)"
                    ),
                ));
            };
            vals.extend_from_slice(&controller.values()[i * per..(i + 1) * per]);
        }
        let c = Frd::new_matrix(
            self.f_hz().to_vec(),
            controller.ny(),
            controller.nu(),
            vals,
            None,
            self.t_ry.ts(),
        )?;
        self.plant_indirect = Some(super::closed_loop::indirect_plant(&self.t_ry, &c)?);
        Ok(self)
    }
}

/// The MIMO closed-loop FRF of a record, the method chosen from it: no period length (neither
/// in `opts` nor in the record) → the local polynomial method
/// [`local_polynomial`](super::mimo_lpm::local_polynomial) (default degree and window, the
/// band of `opts`); periodic with several experiments ($M \ge n_r$) → [`periodic`]; one
/// periodic experiment with several inputs → [`zippered`]; a single input → [`periodic`] (the
/// SISO case).
///
/// # Errors
/// Those of [`periodic`], [`zippered`] and [`local_polynomial`](super::mimo_lpm::local_polynomial).
pub fn estimate(data: &IoData, opts: &MimoOptions) -> Result<MimoClosedLoopFrf> {
    let nr = data.role_count(Role::Excitation);
    if opts.period_samples.or(data.period_samples()).is_none() {
        let mut lo = super::mimo_lpm::MimoLpmOptions::new();
        lo.band = opts.band;
        return super::mimo_lpm::local_polynomial(data, &lo);
    }
    if data.n_experiments() == 1 && nr > 1 {
        zippered(data, opts)
    } else {
        periodic(data, opts)
    }
}

/// [`periodic`] on several single-experiment records (e.g. one file per experiment), joined
/// by [`IoData::from_experiments`].
///
/// # Errors
/// Records that differ in channels, roles, sample time or period; those of [`periodic`].
pub fn periodic_records(records: &[IoData], opts: &MimoOptions) -> Result<MimoClosedLoopFrf> {
    periodic(&IoData::from_experiments(records.to_vec())?, opts)
}

/// The checked layout of a record: roles, period, experiments.
struct Layout<'a> {
    /// Per experiment, the channels in the order r…, u…, y….
    chans: Vec<Vec<&'a [f64]>>,
    nr: usize,
    ny: usize,
    n: usize,
}

/// The counts $(n_r, n_u, n_y)$ of the r, u and y channels, each present and $n_u = n_r$ (the
/// excitation is added to every controller output).
pub(super) fn channel_counts(data: &IoData) -> Result<(usize, usize, usize)> {
    let (nr, nu, ny) = (
        data.role_count(Role::Excitation),
        data.role_count(Role::Input),
        data.role_count(Role::Output),
    );
    for (role, c) in [
        (Role::Excitation, nr),
        (Role::Input, nu),
        (Role::Output, ny),
    ] {
        if c == 0 {
            return Err(data.missing_role(role));
        }
    }
    if nu != nr {
        return Err(Error::invalid(
            "channels",
            format!(
                "the record has {nr} excitation channels ({}) and {nu} input channels ({}); the \
                 excitation is added to every controller output, so give one `r_<axis>` per \
                 `u_<axis>`",
                data.role_names(Role::Excitation).join(", "),
                data.role_names(Role::Input).join(", ")
            ),
        ));
    }
    Ok((nr, nu, ny))
}

fn layout<'a>(data: &'a IoData, opts: &MimoOptions) -> Result<Layout<'a>> {
    let Some(n) = opts.period_samples.or(data.period_samples()) else {
        return Err(Error::invalid(
            "period_samples",
            "the record has no period length: the periodic MIMO closed-loop FRF needs it. Give \
             the period (`period_samples`), or for a non-periodic record (noise, chirp) use the \
             local polynomial method frf::mimo_lpm::local_polynomial (frf::mimo::estimate picks \
             it)",
        ));
    };
    if !(0.0..1.0).contains(&opts.rel_threshold) {
        return Err(Error::invalid(
            "rel_threshold",
            format!("must be in [0, 1), got {}", opts.rel_threshold),
        ));
    }
    if opts.max_cond.is_nan() || opts.max_cond < 1.0 {
        return Err(Error::invalid(
            "max_cond",
            format!(
                "a condition number limit must be at least 1, got {}",
                opts.max_cond
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
    let (nr, _, ny) = channel_counts(data)?;
    let m = data.n_experiments();
    let len0 = data.len();
    for e in 1..m {
        let le = data.experiment_len(e).unwrap_or(0);
        if le != len0 {
            return Err(Error::invalid(
                "experiments",
                format!(
                    "experiment {e} has {le} samples, experiment 0 has {len0}; record every \
                     experiment with the same length (the same number of periods) or cut them to \
                     the shortest"
                ),
            ));
        }
    }
    let mut chans = Vec::with_capacity(m);
    for e in 0..m {
        let mut c = data.signals(Role::Excitation, e)?;
        c.extend(data.signals(Role::Input, e)?);
        c.extend(data.signals(Role::Output, e)?);
        chans.push(c);
    }
    // every sample finite: a branch-free scan of all channels in parallel; on a failure
    // IoData::require_finite names the first bad channel, experiment and sample
    let all_finite = chans
        .par_iter()
        .flat_map(|c| c.par_iter())
        .all(|x| !x.iter().fold(false, |bad, v| bad | !v.is_finite()));
    if !all_finite {
        data.require_finite(&[Role::Excitation, Role::Input, Role::Output])?;
    }
    Ok(Layout { chans, nr, ny, n })
}

fn analyse(lay: &Layout<'_>, fs: f64, opts: &MimoOptions) -> Result<Vec<PeriodicSpectra>> {
    let po = PeriodicOptions::new(lay.n).skip(opts.skip_periods);
    lay.chans
        .par_iter()
        .map(|c| PeriodicAnalyzer::new(lay.n)?.analyze(c, fs, &po))
        .collect()
}

/// [`analyse`] keeping only what [`periodic`] reads: the covariances of the pairs u–u, u–y
/// and y–y on the diagonal (channels in the layout order r…, u…, y…), on the lines with
/// `lines[k]` (all if `None`).
fn analyse_for_periodic(
    lay: &Layout<'_>,
    fs: f64,
    opts: &MimoOptions,
    lines: Option<&[bool]>,
) -> Result<Vec<PeriodicSpectra>> {
    let po = PeriodicOptions::new(lay.n).skip(opts.skip_periods);
    let nr = lay.nr;
    let need = |i: usize, j: usize| i >= nr && (i < 2 * nr || i == j);
    lay.chans
        .par_iter()
        .map(|c| PeriodicAnalyzer::new(lay.n)?.analyze_selected(c, fs, &po, &need, lines))
        .collect()
}

/// The lines excited by each input: `out[j]` = sorted lines where $|\bar R_j|$ passes the
/// threshold in some experiment, within the band.
fn excited_by_input(
    specs: &[PeriodicSpectra],
    nr: usize,
    opts: &MimoOptions,
) -> Result<Vec<Vec<usize>>> {
    let means: Vec<Vec<&[c64]>> = specs
        .iter()
        .map(|s| (0..nr).map(|j| s.mean(j)).collect())
        .collect();
    excited_from_means(&means, specs[0].resolution_hz(), opts)
}

/// [`excited_by_input`] from the period-mean DFTs of the excitation channels alone,
/// `means[e][j]` (every line, DC first) of input `j` in experiment `e`, lines `df` Hz apart.
fn excited_from_means(
    means: &[Vec<&[c64]>],
    df: f64,
    opts: &MimoOptions,
) -> Result<Vec<Vec<usize>>> {
    let nr = means.first().map_or(0, |m| m.len());
    let nl = means.first().and_then(|m| m.first()).map_or(0, |m| m.len());
    let in_band = |k: usize| match opts.band {
        None => true,
        Some((lo, hi)) => {
            let f = k as f64 * df;
            f >= lo && f <= hi
        }
    };
    let mut out = Vec::with_capacity(nr);
    for j in 0..nr {
        let peak = means
            .iter()
            .flat_map(|m| m[j][1..].iter())
            .fold(0.0f64, |a, v| a.max(v.norm_sqr()));
        if peak == 0.0 {
            return Err(Error::invalid(
                "excitation",
                format!(
                    "excitation channel {j} (in axis order) has no power on any line in any \
                     experiment: every input must be excited; check the r columns"
                ),
            ));
        }
        let thr = opts.rel_threshold * opts.rel_threshold * peak;
        out.push(
            (1..nl)
                .filter(|&k| in_band(k) && means.iter().any(|m| m[j][k].norm_sqr() > thr))
                .collect::<Vec<_>>(),
        );
    }
    Ok(out)
}

/// The period-mean DFT of every excitation channel of every experiment, `[e][j]` on every
/// line, before the full analysis, so that the excited lines are known first: the DFT of the
/// channel's time-averaged period (by linearity the mean of the period DFTs; the first period
/// itself for a channel whose periods are bit-identical), two channels per complex FFT.
/// `None` when the record cannot be cut into the periods asked for (the full analysis then
/// reports why).
fn excitation_means(lay: &Layout<'_>, opts: &MimoOptions) -> Option<Vec<Vec<Vec<c64>>>> {
    let n = lay.n;
    let len = lay.chans.first()?.first()?.len();
    if n < 2 || len % n != 0 || len / n <= opts.skip_periods {
        return None;
    }
    let start = opts.skip_periods * n;
    let p_used = len / n - opts.skip_periods;
    let lines = n / 2 + 1;
    let fft = rustfft::FftPlanner::<f64>::new().plan_fft_forward(n);
    let period = |x: &[f64]| -> Vec<f64> {
        let first = &x[start..start + n];
        if (1..p_used).all(|p| &x[start + p * n..start + (p + 1) * n] == first) {
            return first.to_vec();
        }
        let mut acc = vec![0.0; n];
        for p in 0..p_used {
            for (a, v) in acc.iter_mut().zip(&x[start + p * n..start + (p + 1) * n]) {
                *a += v;
            }
        }
        let pf = p_used as f64;
        acc.iter_mut().for_each(|a| *a /= pf);
        acc
    };
    Some(
        lay.chans
            .par_iter()
            .map(|ch| {
                let mut buf = vec![ZERO; n];
                let mut scratch = vec![ZERO; fft.get_inplace_scratch_len()];
                let mut out = Vec::with_capacity(lay.nr);
                for j in (0..lay.nr).step_by(2) {
                    let a = period(ch[j]);
                    let b = (j + 1 < lay.nr).then(|| period(ch[j + 1]));
                    for (t, z) in buf.iter_mut().enumerate() {
                        *z = c64::new(a[t], b.as_ref().map_or(0.0, |b| b[t]));
                    }
                    fft.process_with_scratch(&mut buf, &mut scratch);
                    // A_k = (Z_k + conj Z_{N−k})/2, B_k = (Z_k − conj Z_{N−k})/(2j)
                    let zc = |k: usize| if k == 0 { buf[0] } else { buf[n - k] }.conj();
                    out.push((0..lines).map(|k| (buf[k] + zc(k)) * 0.5).collect());
                    if b.is_some() {
                        out.push(
                            (0..lines)
                                .map(|k| {
                                    let d = buf[k] - zc(k);
                                    c64::new(d.im * 0.5, -d.re * 0.5)
                                })
                                .collect(),
                        );
                    }
                }
                out
            })
            .collect(),
    )
}

/// One-sided (Hestenes) Jacobi SVD of a small complex matrix $A$ ($m \times n$): with
/// $B = A$ if $m \ge n$ (returns `true`) or $B = A^{\mathsf H}$ ($p \times q$, $p \ge q$),
/// rotates the columns of $W = B Z$ until they are orthogonal: on return $B = W Z^{\mathsf H}$
/// with $Z$ ($q \times q$) unitary, the columns of $W$ orthogonal and `norms[c]` $= \|W_c\|$
/// the singular values (unsorted, to high relative accuracy). `w` and `z` must be $p \times q$
/// and $q \times q$, `norms` $q$ long.
fn jacobi_svd(a: &Mat<c64>, w: &mut Mat<c64>, z: &mut Mat<c64>, norms: &mut [f64]) -> Result<bool> {
    let (m, n) = (a.nrows(), a.ncols());
    let tall = m >= n;
    let (p, q) = (w.nrows(), w.ncols());
    debug_assert!(p == m.max(n) && q == m.min(n) && z.nrows() == q && norms.len() == q);
    for r in 0..p {
        for c in 0..q {
            w[(r, c)] = if tall { a[(r, c)] } else { a[(c, r)].conj() };
        }
    }
    for r in 0..q {
        for c in 0..q {
            z[(r, c)] = if r == c { ONE } else { ZERO };
        }
    }
    let mut converged = false;
    for _ in 0..60 {
        let mut rotated = false;
        for i in 0..q {
            for j in i + 1..q {
                let (mut al, mut be, mut ga) = (0.0, 0.0, ZERO);
                for r in 0..p {
                    let (x, y) = (w[(r, i)], w[(r, j)]);
                    al += x.norm_sqr();
                    be += y.norm_sqr();
                    ga += x.conj() * y;
                }
                let g = ga.norm();
                // converged pair (or a NaN, which no rotation mends)
                if g.is_nan() || g <= 4.0 * f64::EPSILON * (al * be).sqrt() {
                    continue;
                }
                rotated = true;
                let ph = (ga / g).conj();
                let zeta = (be - al) / (2.0 * g);
                let t = if zeta == 0.0 {
                    1.0
                } else {
                    zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt())
                };
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = c * t;
                for r in 0..p {
                    let (x, y) = (w[(r, i)], w[(r, j)] * ph);
                    w[(r, i)] = x * c - y * s;
                    w[(r, j)] = x * s + y * c;
                }
                for r in 0..q {
                    let (x, y) = (z[(r, i)], z[(r, j)] * ph);
                    z[(r, i)] = x * c - y * s;
                    z[(r, j)] = x * s + y * c;
                }
            }
        }
        if !rotated {
            converged = true;
            break;
        }
    }
    if !converged {
        return Err(Error::numerical(
            "MIMO FRF",
            "the SVD of a line's matrix did not converge (non-finite entries?)",
        ));
    }
    for (j, nv) in norms.iter_mut().enumerate() {
        *nv = (0..p).map(|r| w[(r, j)].norm_sqr()).sum::<f64>().sqrt();
    }
    Ok(tall)
}

/// Thin SVD $A = U \Sigma V^{\mathsf H}$ of a small complex matrix ([`jacobi_svd`]): singular
/// values descending, $U$ ($m \times q$) and $V$ ($n \times q$), $q = \min(m, n)$.
pub(super) fn svd_small(a: &Mat<c64>) -> Result<(Vec<f64>, Mat<c64>, Mat<c64>)> {
    let (m, n) = (a.nrows(), a.ncols());
    let (p, q) = (m.max(n), m.min(n));
    let mut w = Mat::<c64>::zeros(p, q);
    let mut z = Mat::<c64>::zeros(q, q);
    let mut norms = vec![0.0; q];
    let tall = jacobi_svd(a, &mut w, &mut z, &mut norms)?;
    let mut order: Vec<usize> = (0..q).collect();
    order.sort_by(|&x, &y| norms[y].total_cmp(&norms[x]));
    let sv: Vec<f64> = order.iter().map(|&j| norms[j]).collect();
    let left = Mat::<c64>::from_fn(p, q, |r, c| {
        let j = order[c];
        if norms[j] > 0.0 {
            w[(r, j)] / norms[j]
        } else {
            ZERO
        }
    });
    let right = Mat::<c64>::from_fn(q, q, |r, c| z[(r, order[c])]);
    // B = left Σ rightᴴ; A = B (tall) or Bᴴ = right Σ leftᴴ
    Ok(if tall {
        (sv, left, right)
    } else {
        (sv, right, left)
    })
}

/// Ratio of the extreme singular values (infinite for a zero one).
pub(super) fn cond_of(sv: &[f64]) -> f64 {
    let mx = sv.iter().fold(0.0f64, |a, &v| a.max(v));
    let mn = sv.iter().fold(f64::INFINITY, |a, &v| a.min(v));
    if mn > 0.0 {
        mx / mn
    } else {
        f64::INFINITY
    }
}

/// Inverse of a small square complex matrix by Gauss–Jordan with partial pivoting (`None` if
/// singular).
pub(super) fn inv_small(a: &Mat<c64>) -> Option<Mat<c64>> {
    let n = a.nrows();
    let mut m = Mat::<c64>::zeros(n, n);
    let mut x = Mat::<c64>::zeros(n, n);
    inv_small_into(a, &mut m, &mut x).then_some(x)
}

/// [`inv_small`] into `x` with the work matrix `m` (both $n \times n$); `false` if singular.
fn inv_small_into(a: &Mat<c64>, m: &mut Mat<c64>, x: &mut Mat<c64>) -> bool {
    let n = a.nrows();
    for i in 0..n {
        for j in 0..n {
            m[(i, j)] = a[(i, j)];
            x[(i, j)] = if i == j { ONE } else { ZERO };
        }
    }
    for col in 0..n {
        let Some(piv) = (col..n).max_by(|&p, &q| m[(p, col)].norm().total_cmp(&m[(q, col)].norm()))
        else {
            return false;
        };
        if m[(piv, col)].norm() == 0.0 {
            return false;
        }
        if piv != col {
            for j in 0..n {
                let t = m[(col, j)];
                m[(col, j)] = m[(piv, j)];
                m[(piv, j)] = t;
                let t = x[(col, j)];
                x[(col, j)] = x[(piv, j)];
                x[(piv, j)] = t;
            }
        }
        let d = ONE / m[(col, col)];
        for j in 0..n {
            m[(col, j)] *= d;
            x[(col, j)] *= d;
        }
        for i in 0..n {
            if i != col {
                let f = m[(i, col)];
                if f != ZERO {
                    for j in 0..n {
                        let (mv, xv) = (m[(col, j)], x[(col, j)]);
                        m[(i, j)] -= f * mv;
                        x[(i, j)] -= f * xv;
                    }
                }
            }
        }
    }
    true
}

/// `out = a b` (shapes must agree).
fn mat_mul_into(a: &Mat<c64>, b: &Mat<c64>, out: &mut Mat<c64>) {
    for i in 0..a.nrows() {
        for j in 0..b.ncols() {
            out[(i, j)] = (0..a.ncols()).fold(ZERO, |acc, l| acc + a[(i, l)] * b[(l, j)]);
        }
    }
}

fn mat_mul(a: &Mat<c64>, b: &Mat<c64>) -> Mat<c64> {
    Mat::from_fn(a.nrows(), b.ncols(), |i, j| {
        (0..a.ncols()).fold(ZERO, |acc, l| acc + a[(i, l)] * b[(l, j)])
    })
}

/// $\sum_{il} g_i \Sigma_{il} \bar g_l$ over the indices `idx` of the stacked channels, with the
/// covariance `cov(a, b)`.
fn quad(g: &[(usize, c64)], cov: &impl Fn(usize, usize) -> c64) -> f64 {
    let mut v = 0.0;
    for (a, &(i, gi)) in g.iter().enumerate() {
        v += gi.norm_sqr() * cov(i, i).re;
        for &(l, gl) in &g[a + 1..] {
            v += 2.0 * (gi * cov(i, l) * gl.conj()).re;
        }
    }
    v.max(0.0)
}

/// The error for a condition number `cond` that is not a number or above `max` on line `k`
/// (`f` Hz), naming the matrix (`what`) and the fix (`hint`).
fn require_cond(cond: f64, max: f64, what: &str, k: usize, f: f64, hint: &str) -> Result<()> {
    if cond.is_nan() || cond > max {
        return Err(singular_line_error(what, k, f, cond, hint));
    }
    Ok(())
}

fn singular_line_error(what: &str, k: usize, f: f64, cond: f64, hint: &str) -> Error {
    Error::numerical(
        "MIMO closed-loop FRF",
        format!(
            "the {what} is singular at line {k} ({f:.6} Hz): condition number {cond:.3e}; {hint}"
        ),
    )
}

fn frd(
    f: &[f64],
    ny: usize,
    nu: usize,
    v: Vec<c64>,
    var: Vec<f64>,
    p: usize,
    ts: f64,
) -> Result<Frd> {
    let var = if p > 1 { Some(var) } else { None };
    Frd::new_matrix(f.to_vec(), ny, nu, v, var, Some(ts))
}

/// The MIMO closed-loop FRF from $M \ge n_r$ periodic experiments of one record (sequential,
/// orthogonal or any design whose input matrix $R(k)$ has full row rank on every excited line);
/// formulas in the [module docs](self). All experiments must have the same length; the period
/// comes from `opts` or the record.
///
/// # Errors
/// * [`Error::InvalidArgument`]: no period length (non-periodic data: see
///   [`mimo_lpm`](super::mimo_lpm)), a missing r, u or y
///   channel or different r and u counts (the message lists the channels), fewer experiments
///   than inputs, experiments of different lengths, a non-finite sample (channel, experiment
///   and sample named), a record that is not a whole number of periods or too short for the
///   skipped periods, an input never excited, no excited line in the band;
/// * [`Error::Numerical`]: $R(k)$ or $U(k)$ with a condition number above
///   [`MimoOptions::max_cond`] on some line (its frequency named), e.g. two identical
///   experiments.
pub fn periodic(data: &IoData, opts: &MimoOptions) -> Result<MimoClosedLoopFrf> {
    let lay = layout(data, opts)?;
    let (nr, ny) = (lay.nr, lay.ny);
    let nu = nr;
    let m = lay.chans.len();
    if m < nr {
        return Err(Error::invalid(
            "experiments",
            format!(
                "{m} experiment(s) for {nr} inputs: solving T_ry and S per line needs at least as \
                 many experiments as inputs; record {nr} (a sequential or orthogonal design) or \
                 one zippered experiment"
            ),
        ));
    }
    // the excited lines first, from r alone; then the period statistics on those lines only
    let (specs, per_in) = match excitation_means(&lay, opts) {
        Some(rm) => {
            let means: Vec<Vec<&[c64]>> = rm
                .iter()
                .map(|e| e.iter().map(|v| v.as_slice()).collect())
                .collect();
            let per_in = excited_from_means(&means, data.fs() / lay.n as f64, opts)?;
            let mut mask = vec![false; lay.n / 2 + 1];
            for &k in per_in.iter().flatten() {
                mask[k] = true;
            }
            (
                analyse_for_periodic(&lay, data.fs(), opts, Some(&mask))?,
                per_in,
            )
        }
        None => {
            let specs = analyse_for_periodic(&lay, data.fs(), opts, None)?;
            let per_in = excited_by_input(&specs, nr, opts)?;
            (specs, per_in)
        }
    };
    let mut lines: Vec<usize> = per_in.into_iter().flatten().collect();
    lines.sort_unstable();
    lines.dedup();
    if lines.is_empty() {
        return Err(Error::invalid(
            "band",
            "no excited line in the band: widen the band or check the excitation",
        ));
    }
    let p = specs[0].periods();
    let pf = p as f64;
    let ts = 1.0 / data.fs();
    let f: Vec<f64> = lines.iter().map(|&k| specs[0].line_hz(k)).collect();
    let nl = lines.len();
    let (off_u, off_y) = (nr, nr + nu);

    // per line: R, U, Y (inputs/outputs × experiments), the Jacobi SVDs, the products and the
    // inverse in one workspace per rayon task (no allocation per line but the line's output)
    let nz = nu + ny;
    struct Ws {
        r: Mat<c64>,
        u: Mat<c64>,
        y: Mat<c64>,
        w: Mat<c64>,
        z: Mat<c64>,
        norms: Vec<f64>,
        order: Vec<usize>,
        rp: Mat<c64>,
        t: Mat<c64>,
        s: Mat<c64>,
        s_inv: Mat<c64>,
        inv_work: Mat<c64>,
        pl: Mat<c64>,
        wm: Mat<c64>,
        tr: Mat<c64>,
        sr: Mat<c64>,
        cov: Vec<c64>,
        g: Vec<(usize, c64)>,
    }
    let (sp, sq) = (nr.max(m), nr.min(m));
    let new_ws = || Ws {
        r: Mat::zeros(nr, m),
        u: Mat::zeros(nu, m),
        y: Mat::zeros(ny, m),
        w: Mat::zeros(sp, sq),
        z: Mat::zeros(sq, sq),
        norms: vec![0.0; sq],
        order: (0..sq).collect(),
        rp: Mat::zeros(m, nr),
        t: Mat::zeros(ny, nu),
        s: Mat::zeros(nu, nu),
        s_inv: Mat::zeros(nu, nu),
        inv_work: Mat::zeros(nu, nu),
        pl: Mat::zeros(ny, nu),
        wm: Mat::zeros(m, nu),
        tr: Mat::zeros(ny, m),
        sr: Mat::zeros(nu, m),
        cov: vec![ZERO; nz * nz],
        g: Vec::with_capacity(nu + 1),
    };
    // per line: values t | s | p (column-major) and vt | vs | vp | coh | coh_u | cond_r | cond_u
    let (nt, ns) = (ny * nu, nu * nu);
    // the covariance rows the per-line formulas read, looked up once: per experiment, the
    // stacked (u, y) pairs a ≤ b with a < nu (u–u, u–y) or a = b (y–y diagonal), row-major
    let used: Vec<(usize, usize)> = (0..nz)
        .flat_map(|a| (a..nz).map(move |b| (a, b)))
        .filter(|&(a, b)| a < nu || a == b)
        .collect();
    let rows: Vec<Vec<&[c64]>> = specs
        .iter()
        .map(|sp| {
            used.iter()
                .map(|&(a, b)| sp.cov_slice(off_u + a, off_u + b).0)
                .collect()
        })
        .collect();
    // the period-mean second moment of channel c (PeriodicSpectra::moment_at, same operations)
    let diag: Vec<Vec<(&[c64], &[c64])>> = specs
        .iter()
        .map(|sp| {
            (0..off_u + nz)
                .map(|c| (sp.cov_slice(c, c).0, sp.mean(c)))
                .collect()
        })
        .collect();
    let moment = |e: usize, c: usize, k: usize| -> f64 {
        let (row, mean) = diag[e][c];
        let x = mean[k];
        (row[k] * ((pf - 1.0) / pf) + x * x.conj()).re
    };
    let per_line = |ws: &mut Ws, li: usize| -> Result<(Vec<c64>, Vec<f64>)> {
        let k = lines[li];
        let fk = f[li];
        for (e, sp) in specs.iter().enumerate() {
            for j in 0..nr {
                ws.r[(j, e)] = sp.mean(j)[k];
                ws.u[(j, e)] = sp.mean(off_u + j)[k];
            }
            for i in 0..ny {
                ws.y[(i, e)] = sp.mean(off_y + i)[k];
            }
        }
        let tall = jacobi_svd(&ws.r, &mut ws.w, &mut ws.z, &mut ws.norms)?;
        let cond_r = cond_of(&ws.norms);
        require_cond(
            cond_r,
            opts.max_cond,
            "excitation matrix R (inputs × experiments)",
            k,
            fk,
            "the experiments do not excite the inputs independently there (e.g. two identical \
             experiments); use a sequential or orthogonal (Hadamard) design, or restrict the band",
        )?;
        // R⁺ = V Σ⁻¹ Uᴴ (M × nr) over the singular values in descending order; with the
        // unnormalised Jacobi columns W (= left vectors · σ): R = W̃ Σ Zᴴ (tall) or Z Σ W̃ᴴ
        for (q, o) in ws.order.iter_mut().enumerate() {
            *o = q;
        }
        let norms = &ws.norms;
        ws.order.sort_by(|&x, &y| norms[y].total_cmp(&norms[x]));
        for e in 0..m {
            for j in 0..nr {
                let mut acc = ZERO;
                for &q in &ws.order {
                    let s2 = ws.norms[q] * ws.norms[q];
                    acc += if tall {
                        ws.z[(e, q)] * ws.w[(j, q)].conj() / s2
                    } else {
                        ws.w[(e, q)] * ws.z[(j, q)].conj() / s2
                    };
                }
                ws.rp[(e, j)] = acc;
            }
        }
        jacobi_svd(&ws.u, &mut ws.w, &mut ws.z, &mut ws.norms)?;
        let cond_u = cond_of(&ws.norms);
        require_cond(
            cond_u,
            opts.max_cond,
            "input matrix U (inputs × experiments)",
            k,
            fk,
            "the controller outputs are not independent across the experiments there; check the \
             excitation design and the loop",
        )?;
        mat_mul_into(&ws.y, &ws.rp, &mut ws.t);
        mat_mul_into(&ws.u, &ws.rp, &mut ws.s);
        if !inv_small_into(&ws.s, &mut ws.inv_work, &mut ws.s_inv) {
            return Err(singular_line_error(
                "sensitivity S",
                k,
                fk,
                f64::INFINITY,
                "check the data",
            ));
        }
        mat_mul_into(&ws.t, &ws.s_inv, &mut ws.pl);
        mat_mul_into(&ws.rp, &ws.s_inv, &mut ws.wm);
        let mut vals = Vec::with_capacity(2 * nt + ns);
        for a in [&ws.t, &ws.s, &ws.pl] {
            for j in 0..a.ncols() {
                for i in 0..a.nrows() {
                    vals.push(a[(i, j)]);
                }
            }
        }
        let mut fl = vec![0.0; 2 * nt + ns + ny + nu + 2];
        {
            let (vt, rest) = fl.split_at_mut(nt);
            let (vs, rest) = rest.split_at_mut(ns);
            let vp = &mut rest[..nt];
            for (e, rows) in rows.iter().enumerate() {
                // the covariance of the means of (u, y), stacked u then y: the pairs used
                for (&(a, b), row) in used.iter().zip(rows) {
                    ws.cov[a * nz + b] = row[k] / pf;
                }
                let cv = |a: usize, b: usize| ws.cov[a * nz + b];
                for j in 0..nu {
                    let w2 = ws.rp[(e, j)].norm_sqr();
                    for i in 0..ny {
                        vt[j * ny + i] += w2 * cv(nu + i, nu + i).re;
                    }
                    for i in 0..nu {
                        vs[j * nu + i] += w2 * cv(i, i).re;
                    }
                }
                for a in 0..ny {
                    ws.g.clear();
                    ws.g.extend((0..nu).map(|c| (c, -ws.pl[(a, c)])));
                    ws.g.push((nu + a, ONE));
                    let q = quad(&ws.g, &cv);
                    for b in 0..nu {
                        vp[b * ny + a] += ws.wm[(e, b)].norm_sqr() * q;
                    }
                }
            }
        }
        mat_mul_into(&ws.t, &ws.r, &mut ws.tr);
        mat_mul_into(&ws.s, &ws.r, &mut ws.sr);
        let coh_of = |fit: &Mat<c64>, off: usize, i: usize| {
            let num: f64 = (0..m).map(|e| fit[(i, e)].norm_sqr()).sum();
            let den: f64 = (0..m).map(|e| moment(e, off + i, k)).sum();
            if den > 0.0 {
                (num / den).min(1.0)
            } else {
                f64::NAN
            }
        };
        let base = 2 * nt + ns;
        for i in 0..ny {
            fl[base + i] = coh_of(&ws.tr, off_y, i);
        }
        for i in 0..nu {
            fl[base + ny + i] = coh_of(&ws.sr, off_u, i);
        }
        fl[base + ny + nu] = cond_r;
        fl[base + ny + nu + 1] = cond_u;
        Ok((vals, fl))
    };
    let outs: Vec<(Vec<c64>, Vec<f64>)> = (0..nl)
        .into_par_iter()
        .map_init(new_ws, per_line)
        .collect::<Result<_>>()?;
    let cat = |r: std::ops::Range<usize>| -> Vec<c64> {
        outs.iter()
            .flat_map(|o| o.0[r.clone()].iter().copied())
            .collect()
    };
    let catf = |r: std::ops::Range<usize>| -> Vec<f64> {
        outs.iter()
            .flat_map(|o| o.1[r.clone()].iter().copied())
            .collect()
    };
    let base = 2 * nt + ns;
    Ok(MimoClosedLoopFrf {
        t_ry: frd(&f, ny, nu, cat(0..nt), catf(0..nt), p, ts)?,
        s: frd(&f, nu, nu, cat(nt..nt + ns), catf(nt..nt + ns), p, ts)?,
        plant: frd(&f, ny, nu, cat(nt + ns..base), catf(nt + ns..base), p, ts)?,
        plant_indirect: None,
        coherence: catf(base..base + ny),
        coherence_u: catf(base + ny..base + ny + nu),
        cond_r: catf(base + ny + nu..base + ny + nu + 1),
        cond_u: catf(base + ny + nu + 1..base + ny + nu + 2),
        measured: vec![true; nl * nu],
        lines,
        periods: p,
        dof: (pf - 1.0).max(0.0),
        design: MimoDesign::Experiments(m),
    })
}

/// The 4 lines of `own` (sorted, at least 4) nearest to `k`, and the cubic Lagrange weights
/// of `k` on them.
fn lagrange4(own: &[usize], k: usize) -> ([usize; 4], [f64; 4]) {
    let pos = own.partition_point(|&x| x < k);
    let start = pos.saturating_sub(2).min(own.len() - 4);
    let xs = [own[start], own[start + 1], own[start + 2], own[start + 3]];
    let kf = k as f64;
    let mut w = [1.0; 4];
    for l in 0..4 {
        for q in 0..4 {
            if q != l {
                w[l] *= (kf - xs[q] as f64) / (xs[l] as f64 - xs[q] as f64);
            }
        }
    }
    (xs, w)
}

/// How [`zippered_with`] brings a column to the lines of the other inputs (see the
/// [module docs](self#zippered-design)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ZipperInterpolation {
    /// Cubic Lagrange polynomial in the line index through the 4 nearest own lines.
    Lagrange,
    /// Local rational fit over the 6 nearest own lines: degree-4 numerators with one degree-2
    /// denominator common to the whole stacked column, one Sanathanan–Koerner step; cubic
    /// Lagrange where the fit is ill-conditioned or the input has fewer than 6 lines. The
    /// default.
    #[default]
    Rational,
}

/// The 2q lines of `own` (sorted, at least 2q) nearest to `k`, q on each side, shifted at the
/// ends.
fn window(own: &[usize], k: usize, q: usize) -> &[usize] {
    let pos = own.partition_point(|&x| x < k);
    let start = pos.saturating_sub(q).min(own.len() - 2 * q);
    &own[start..start + 2 * q]
}

/// Solves the small real symmetric positive system `a x = b` (n ≤ 4) by Cholesky; `None` if
/// not positive definite.
fn chol_solve(a: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut v = a[i * n + j];
            for m in 0..j {
                v -= l[i * n + m] * l[j * n + m];
            }
            if i == j {
                if v <= 0.0 || !v.is_finite() {
                    return None;
                }
                l[i * n + i] = v.sqrt();
            } else {
                l[i * n + j] = v / l[j * n + j];
            }
        }
    }
    let mut y = b.to_vec();
    for i in 0..n {
        for m in 0..i {
            y[i] -= l[i * n + m] * y[m];
        }
        y[i] /= l[i * n + i];
    }
    for i in (0..n).rev() {
        for m in i + 1..n {
            y[i] -= l[m * n + i] * y[m];
        }
        y[i] /= l[i * n + i];
    }
    Some(y)
}

/// Degree of the local denominator of the rational interpolation.
const RAT_DEG: usize = 2;
/// Degree of the local numerators of the rational interpolation.
const RAT_NUM_DEG: usize = 4;
/// Own lines on each side of the target line in the rational interpolation.
const RAT_HALF_WIDTH: usize = 3;
/// Largest condition number of the denominator's normal equations accepted.
const RAT_MAX_COND: f64 = 1e10;
/// Largest noise gain $\sum_l |c_l|^2$ of the rational weights accepted.
const RAT_MAX_GAIN: f64 = 1e2;

/// The rational interpolation weights of the stacked column at line `k` from its values `z`
/// (`xs.len()` lines × `nz` entries, line-major) on the own lines `xs`, with entry weights
/// `ew` (nz): complex $c_l$ with $\hat z(k) = \sum_l c_l z(x_l)$, or `None` where the fit is
/// ill-conditioned (the caller falls back to Lagrange).
fn rational_weights(xs: &[usize], k: usize, z: &[c64], nz: usize, ew: &[f64]) -> Option<Vec<c64>> {
    let nl = xs.len();
    let (x0, x1) = (xs[0] as f64, xs[nl - 1] as f64);
    let h = ((x1 - x0) / 2.0).max(1.0);
    // local variable s = (x - k) / h, so that the target is s = 0 and D(0) = 1
    let sv: Vec<f64> = xs.iter().map(|&x| (x as f64 - k as f64) / h).collect();
    let np = RAT_NUM_DEG + 1;
    let vand = |l: usize, p: usize| sv[l].powi(p as i32);
    let mut omega = vec![1.0; nl];
    let mut d = [ZERO; RAT_DEG]; // d_1 .. d_deg
    for _iter in 0..2 {
        // M = diag(ω) V; the projector Q = I − M (MᵀM)⁻¹ Mᵀ (real)
        let mut g = vec![0.0; np * np];
        for a in 0..np {
            for b in 0..np {
                g[a * np + b] = (0..nl)
                    .map(|l| omega[l] * omega[l] * vand(l, a) * vand(l, b))
                    .sum();
            }
        }
        let mut q = vec![0.0; nl * nl];
        for c in 0..nl {
            let rhs: Vec<f64> = (0..np).map(|a| omega[c] * vand(c, a)).collect();
            let sol = chol_solve(&g, &rhs, np)?;
            for l in 0..nl {
                let m_l: f64 = (0..np).map(|a| omega[l] * vand(l, a) * sol[a]).sum();
                q[l * nl + c] = if l == c { 1.0 } else { 0.0 } - m_l;
            }
        }
        // normal equations of the denominator: Σ_a ew_a² ‖Q ω z_a (1 + Σ d_p s^p)‖² → min
        let nd = RAT_DEG;
        let mut a_mat = vec![ZERO; nd * nd];
        let mut b_vec = vec![ZERO; nd];
        let mut col = vec![ZERO; nl * (nd + 1)];
        for (ent, &w) in ew.iter().enumerate() {
            if w == 0.0 {
                continue;
            }
            // columns: Q diag(ω z) s^p for p = 0..=nd
            for p in 0..=nd {
                for l in 0..nl {
                    let mut acc = ZERO;
                    for c in 0..nl {
                        let qv = q[l * nl + c];
                        if qv != 0.0 {
                            acc += z[c * nz + ent] * (qv * omega[c] * sv[c].powi(p as i32));
                        }
                    }
                    col[p * nl + l] = acc * w;
                }
            }
            for p in 0..nd {
                for r in 0..nd {
                    a_mat[p * nd + r] += (0..nl)
                        .map(|l| col[(p + 1) * nl + l].conj() * col[(r + 1) * nl + l])
                        .sum::<c64>();
                }
                b_vec[p] -= (0..nl)
                    .map(|l| col[(p + 1) * nl + l].conj() * col[l])
                    .sum::<c64>();
            }
        }
        let am = Mat::<c64>::from_fn(nd, nd, |i, j| a_mat[i * nd + j]);
        let (svs, _, _) = svd_small(&am).ok()?;
        let cond = cond_of(&svs);
        if cond.is_nan() || cond > RAT_MAX_COND {
            return None;
        }
        let ai = inv_small(&am)?;
        for p in 0..nd {
            d[p] = (0..nd).fold(ZERO, |acc, r| acc + ai[(p, r)] * b_vec[r]);
        }
        for l in 0..nl {
            let dl = (0..nd).fold(ONE, |acc, p| acc + d[p] * sv[l].powi(p as i32 + 1));
            let m = dl.norm();
            if !(m.is_finite() && m > 0.0) {
                return None;
            }
            omega[l] = 1.0 / m;
        }
    }
    // numerator at s = 0 for the final D, the last iteration's ω: row 0 of (MᵀM)⁻¹Mᵀ diag(ω)
    let mut g = vec![0.0; np * np];
    for a in 0..np {
        for b in 0..np {
            g[a * np + b] = (0..nl)
                .map(|l| omega[l] * omega[l] * vand(l, a) * vand(l, b))
                .sum();
        }
    }
    let mut e0 = vec![0.0; np];
    e0[0] = 1.0;
    let row = chol_solve(&g, &e0, np)?;
    let c: Vec<c64> = (0..nl)
        .map(|l| {
            let p: f64 = (0..np).map(|a| row[a] * vand(l, a)).sum::<f64>() * omega[l] * omega[l];
            let dl = (0..RAT_DEG).fold(ONE, |acc, q| acc + d[q] * sv[l].powi(q as i32 + 1));
            dl * p
        })
        .collect();
    let gain: f64 = c.iter().map(|v| v.norm_sqr()).sum();
    if !(gain.is_finite() && gain <= RAT_MAX_GAIN) {
        return None;
    }
    Some(c)
}

/// The MIMO closed-loop FRF from one zippered periodic experiment: input $j$ alone on its lines
/// $\mathcal L_j$; columns measured there and interpolated (the local rational rule,
/// [`ZipperInterpolation::Rational`]) to the union of the lines, then $P = T_{ry} S^{-1}$ per
/// line. [`MimoClosedLoopFrf::measured`]`[line * nu + j]` is `true` where column $j$ was
/// measured and `false` where it was interpolated. See the [module docs](self#zippered-design)
/// for the formulas and the bias near sharp resonances; [`zippered_with`] chooses the rule.
///
/// # Example
/// ```
/// use ambid_core::data::IoData;
/// use ambid_core::frf::mimo::{zippered, MimoOptions};
/// use std::f64::consts::PI;
/// // 2 inputs in open loop (u = r), a static plant y = P u with P = [[1, 0.5], [0.2, 2]];
/// // input 0 on the odd lines 1..7, input 1 on the even lines 2..8, 3 periods of 32 samples
/// let n = 32;
/// let tone = |lines: &[usize], t: usize| -> f64 {
///     lines.iter().map(|&k| (2.0 * PI * (k * t % n) as f64 / n as f64 + k as f64).cos()).sum()
/// };
/// let r0: Vec<f64> = (0..3 * n).map(|t| tone(&[1, 3, 5, 7], t)).collect();
/// let r1: Vec<f64> = (0..3 * n).map(|t| tone(&[2, 4, 6, 8], t)).collect();
/// let y0: Vec<f64> = r0.iter().zip(&r1).map(|(a, b)| a + 0.5 * b).collect();
/// let y1: Vec<f64> = r0.iter().zip(&r1).map(|(a, b)| 0.2 * a + 2.0 * b).collect();
/// let data = IoData::new(vec![
///     ("r_xa".into(), r0.clone()), ("r_xb".into(), r1.clone()),
///     ("u_xa".into(), r0), ("u_xb".into(), r1),
///     ("y_xa".into(), y0), ("y_xb".into(), y1),
/// ], 1e-3, Some(n)).unwrap();
/// let frf = zippered(&data, &MimoOptions::new()).unwrap();
/// assert_eq!(frf.lines, (1..=8).collect::<Vec<_>>());
/// // line 1: column 0 measured, column 1 interpolated (exactly, the plant is static)
/// assert_eq!(&frf.measured[..2], &[true, false]);
/// let p = frf.plant.at(0).unwrap();
/// assert!((p[(0, 1)].re - 0.5).abs() < 1e-12 && (p[(1, 0)].re - 0.2).abs() < 1e-12);
/// ```
///
/// # Errors
/// As [`periodic`] for the record; and [`Error::InvalidArgument`] for several experiments, a
/// line excited by two inputs (not a zippered design), or an input with fewer than 4 lines;
/// [`Error::Numerical`] for a singular $\hat S$ on a line.
pub fn zippered(data: &IoData, opts: &MimoOptions) -> Result<MimoClosedLoopFrf> {
    zippered_with(data, opts, ZipperInterpolation::default())
}

/// [`zippered`] with the interpolation of the columns chosen by `interp` (see the
/// [module docs](self#zippered-design)).
///
/// # Example
/// ```
/// use ambid_core::data::IoData;
/// use ambid_core::frf::mimo::{zippered_with, MimoOptions, ZipperInterpolation};
/// use std::f64::consts::PI;
/// // 2 inputs in open loop (u = r); y = P u with a static P = [[1, 0.5], [0.2, 2]];
/// // input 0 on the odd lines 1..15, input 1 on the even lines 2..16, 3 periods of 64 samples
/// let n = 64;
/// let tone = |lines: &[usize], t: usize| -> f64 {
///     lines.iter().map(|&k| (2.0 * PI * (k * t % n) as f64 / n as f64 + k as f64).cos()).sum()
/// };
/// let odd: Vec<usize> = (1..16).step_by(2).collect();
/// let even: Vec<usize> = (2..=16).step_by(2).collect();
/// let r0: Vec<f64> = (0..3 * n).map(|t| tone(&odd, t)).collect();
/// let r1: Vec<f64> = (0..3 * n).map(|t| tone(&even, t)).collect();
/// let y0: Vec<f64> = r0.iter().zip(&r1).map(|(a, b)| a + 0.5 * b).collect();
/// let y1: Vec<f64> = r0.iter().zip(&r1).map(|(a, b)| 0.2 * a + 2.0 * b).collect();
/// let data = IoData::new(vec![
///     ("r_xa".into(), r0.clone()), ("r_xb".into(), r1.clone()),
///     ("u_xa".into(), r0), ("u_xb".into(), r1),
///     ("y_xa".into(), y0), ("y_xb".into(), y1),
/// ], 1e-3, Some(n)).unwrap();
/// for how in [ZipperInterpolation::Rational, ZipperInterpolation::Lagrange] {
///     let frf = zippered_with(&data, &MimoOptions::new(), how).unwrap();
///     assert_eq!(frf.lines, (1..=16).collect::<Vec<_>>());
///     let p = frf.plant.at(4).unwrap();
///     assert!((p[(0, 1)].re - 0.5).abs() < 1e-9 && (p[(1, 0)].re - 0.2).abs() < 1e-9);
/// }
/// ```
///
/// # Errors
/// As [`zippered`].
pub fn zippered_with(
    data: &IoData,
    opts: &MimoOptions,
    interp: ZipperInterpolation,
) -> Result<MimoClosedLoopFrf> {
    data.require_single_experiment("the zippered MIMO FRF")?;
    let lay = layout(data, opts)?;
    let (nr, ny) = (lay.nr, lay.ny);
    let nu = nr;
    let specs = analyse(&lay, data.fs(), opts)?;
    let sp = &specs[0];
    let own = excited_by_input(&specs, nr, opts)?;
    let nlines = sp.n_lines();
    let mut owner = vec![usize::MAX; nlines];
    for (j, l) in own.iter().enumerate() {
        if l.len() < 4 {
            return Err(Error::invalid(
                "excitation",
                format!(
                    "input {j} (in axis order) excites {} line(s) in the band; the zippered \
                     estimate interpolates each column through 4 of its own lines: excite more \
                     lines or widen the band",
                    l.len()
                ),
            ));
        }
        for &k in l {
            if owner[k] != usize::MAX {
                return Err(Error::invalid(
                    "excitation",
                    format!(
                        "line {k} ({:.6} Hz) is excited by inputs {} and {j}: this is not a \
                         zippered design (each input on its own lines); record one experiment per \
                         input (sequential or orthogonal design) and use frf::mimo::periodic",
                        sp.line_hz(k),
                        owner[k]
                    ),
                ));
            }
            owner[k] = j;
        }
    }
    let lines: Vec<usize> = (1..nlines).filter(|&k| owner[k] != usize::MAX).collect();
    let p = sp.periods();
    let pf = p as f64;
    let ts = 1.0 / data.fs();
    let (off_u, off_y) = (nr, nr + nu);
    let nz = ny + nu; // stacked column z = (T[:, j], S[:, j])
                      // the measured column on an own line: values and covariance (nz × nz, row-major)
    let measured_col = |j: usize, k: usize| -> (Vec<c64>, Vec<c64>) {
        let rj = sp.mean(j)[k];
        let ir = ONE / rj;
        let ch = |a: usize| if a < ny { off_y + a } else { off_u + a - ny };
        let z: Vec<c64> = (0..nz).map(|a| sp.mean(ch(a))[k] * ir).collect();
        let s2 = rj.norm_sqr() * pf;
        let mut cov = vec![ZERO; nz * nz];
        for a in 0..nz {
            for b in 0..nz {
                cov[a * nz + b] = sp.cov_at(ch(a), ch(b), k) / s2;
            }
        }
        (z, cov)
    };
    let f: Vec<f64> = lines.iter().map(|&k| sp.line_hz(k)).collect();
    let nl = lines.len();
    let mut t = vec![ZERO; nl * ny * nu];
    let mut s = vec![ZERO; nl * nu * nu];
    let mut pv = vec![ZERO; nl * ny * nu];
    let (mut vt, mut vs, mut vp) = (
        vec![0.0; nl * ny * nu],
        vec![0.0; nl * nu * nu],
        vec![0.0; nl * ny * nu],
    );
    let mut measured = vec![false; nl * nu];
    let mut cond_u = vec![0.0; nl];
    let mut coherence = vec![0.0; nl * ny];
    let mut coherence_u = vec![0.0; nl * nu];
    let mut covs: Vec<Vec<c64>> = vec![vec![ZERO; nz * nz]; nu];
    for (li, &k) in lines.iter().enumerate() {
        for j in 0..nu {
            let (z, cov) = if owner[k] == j {
                measured[li * nu + j] = true;
                measured_col(j, k)
            } else {
                let (xs, w): (Vec<usize>, Vec<c64>) = match interp {
                    ZipperInterpolation::Rational if own[j].len() >= 2 * RAT_HALF_WIDTH => {
                        let xs = window(&own[j], k, RAT_HALF_WIDTH);
                        let cols: Vec<(Vec<c64>, Vec<c64>)> =
                            xs.iter().map(|&x| measured_col(j, x)).collect();
                        let zs: Vec<c64> = cols.iter().flat_map(|c| c.0.iter().copied()).collect();
                        // entry weights: 1/sqrt(mean σ² + (1e-3 rms)²), the noise-free case
                        // weighting every entry by its size
                        let ew: Vec<f64> = (0..nz)
                            .map(|a| {
                                let n = xs.len() as f64;
                                let ms = cols.iter().map(|c| c.0[a].norm_sqr()).sum::<f64>() / n;
                                let var = cols.iter().map(|c| c.1[a * nz + a].re).sum::<f64>() / n;
                                let den = (var.max(0.0) + 1e-6 * ms).sqrt();
                                if den > 0.0 && den.is_finite() {
                                    1.0 / den
                                } else {
                                    0.0
                                }
                            })
                            .collect();
                        match rational_weights(xs, k, &zs, nz, &ew) {
                            Some(c) => (xs.to_vec(), c),
                            None => {
                                let (xs, w) = lagrange4(&own[j], k);
                                (xs.to_vec(), w.iter().map(|&v| c64::new(v, 0.0)).collect())
                            }
                        }
                    }
                    _ => {
                        let (xs, w) = lagrange4(&own[j], k);
                        (xs.to_vec(), w.iter().map(|&v| c64::new(v, 0.0)).collect())
                    }
                };
                let mut z = vec![ZERO; nz];
                let mut cov = vec![ZERO; nz * nz];
                for (x, wl) in xs.iter().zip(w) {
                    let (zl, cl) = measured_col(j, *x);
                    let w2 = wl.norm_sqr();
                    for a in 0..nz {
                        z[a] += zl[a] * wl;
                    }
                    for (c, v) in cov.iter_mut().zip(cl) {
                        *c += v * w2;
                    }
                }
                (z, cov)
            };
            for i in 0..ny {
                t[li * ny * nu + j * ny + i] = z[i];
                vt[li * ny * nu + j * ny + i] = cov[i * nz + i].re.max(0.0);
            }
            for i in 0..nu {
                s[li * nu * nu + j * nu + i] = z[ny + i];
                vs[li * nu * nu + j * nu + i] = cov[(ny + i) * nz + ny + i].re.max(0.0);
            }
            covs[j] = cov;
        }
        let tm = Mat::<c64>::from_fn(ny, nu, |i, j| t[li * ny * nu + j * ny + i]);
        let sm = Mat::<c64>::from_fn(nu, nu, |i, j| s[li * nu * nu + j * nu + i]);
        let (svs, _, _) = svd_small(&sm)?;
        cond_u[li] = cond_of(&svs);
        require_cond(
            cond_u[li],
            opts.max_cond,
            "estimated sensitivity S",
            k,
            f[li],
            "the loop's input response cannot be inverted there; restrict the band",
        )?;
        let s_inv = inv_small(&sm).ok_or_else(|| {
            singular_line_error(
                "estimated sensitivity S",
                k,
                f[li],
                f64::INFINITY,
                "restrict the band",
            )
        })?;
        let pm = mat_mul(&tm, &s_inv);
        let mut g: Vec<(usize, c64)> = Vec::with_capacity(nu + 1);
        for a in 0..ny {
            for b in 0..nu {
                pv[li * ny * nu + b * ny + a] = pm[(a, b)];
                let mut acc = 0.0;
                for (j, cov) in covs.iter().enumerate() {
                    g.clear();
                    g.push((a, ONE));
                    g.extend((0..nu).map(|c| (ny + c, -pm[(a, c)])));
                    let cv = |x: usize, y: usize| cov[x * nz + y];
                    acc += s_inv[(j, b)].norm_sqr() * quad(&g, &cv);
                }
                vp[li * ny * nu + b * ny + a] = acc;
            }
        }
        for i in 0..ny {
            let mo = sp.moment_at(off_y + i, off_y + i, k).re;
            coherence[li * ny + i] = if mo > 0.0 {
                (sp.mean(off_y + i)[k].norm_sqr() / mo).min(1.0)
            } else {
                f64::NAN
            };
        }
        for i in 0..nu {
            let mo = sp.moment_at(off_u + i, off_u + i, k).re;
            coherence_u[li * nu + i] = if mo > 0.0 {
                (sp.mean(off_u + i)[k].norm_sqr() / mo).min(1.0)
            } else {
                f64::NAN
            };
        }
    }
    Ok(MimoClosedLoopFrf {
        t_ry: frd(&f, ny, nu, t, vt, p, ts)?,
        s: frd(&f, nu, nu, s, vs, p, ts)?,
        plant: frd(&f, ny, nu, pv, vp, p, ts)?,
        plant_indirect: None,
        coherence,
        coherence_u,
        cond_r: vec![1.0; nl],
        cond_u,
        lines,
        measured,
        periods: p,
        dof: (pf - 1.0).max(0.0),
        design: MimoDesign::Zippered,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lagrange_weights_reproduce_cubics_and_pick_the_nearest_lines() {
        let own = [2usize, 6, 10, 14, 18, 22];
        let cubic = |x: f64| 0.5 - 1.5 * x + 0.25 * x * x - 0.01 * x * x * x;
        for k in [1usize, 3, 7, 12, 17, 21, 25] {
            let (xs, w) = lagrange4(&own, k);
            let v: f64 = xs.iter().zip(w).map(|(&x, w)| w * cubic(x as f64)).sum();
            assert!((v - cubic(k as f64)).abs() < 1e-12, "k = {k}: {v}");
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
        assert_eq!(lagrange4(&own, 12).0, [6, 10, 14, 18]);
        assert_eq!(lagrange4(&own, 1).0, [2, 6, 10, 14]);
        assert_eq!(lagrange4(&own, 25).0, [10, 14, 18, 22]);
    }

    /// The Jacobi SVD against faer's singular values (an independent algorithm) and by
    /// reconstruction, for tall, wide and square matrices, one of them rank-deficient.
    #[test]
    fn jacobi_svd_reconstructs_and_matches_faer() {
        let el = |i: usize, j: usize, s: f64| {
            c64::new(
                ((i * 7 + j * 3) as f64 * 0.37 + s).sin(),
                ((i * 5 + j * 11) as f64 * 0.23 - s).cos(),
            )
        };
        let mut cases: Vec<Mat<c64>> = vec![
            Mat::from_fn(4, 4, |i, j| el(i, j, 0.1)),
            Mat::from_fn(3, 6, |i, j| el(i, j, 0.2)),
            Mat::from_fn(6, 3, |i, j| el(i, j, 0.3)),
            Mat::from_fn(1, 1, |_, _| c64::new(-2.0, 0.5)),
        ];
        // rank 1: σ₂ = 0 (to rounding) → κ huge
        cases.push(Mat::from_fn(3, 3, |i, j| el(i, 0, 0.4) * el(0, j, 0.5)));
        for a in &cases {
            let (m, n) = (a.nrows(), a.ncols());
            let (sv, u, v) = svd_small(a).unwrap();
            let q = m.min(n);
            assert_eq!(
                (sv.len(), u.nrows(), u.ncols(), v.nrows(), v.ncols()),
                (q, m, q, n, q)
            );
            let want = a.singular_values().unwrap();
            let scale = sv[0];
            for (x, y) in sv.iter().zip(&want) {
                assert!((x - y).abs() <= 1e-13 * scale, "{sv:?} vs {want:?}");
            }
            assert!(sv.windows(2).all(|w| w[0] >= w[1]));
            for i in 0..m {
                for j in 0..n {
                    let r: c64 = (0..q).map(|l| u[(i, l)] * v[(j, l)].conj() * sv[l]).sum();
                    assert!((r - a[(i, j)]).norm() < 1e-13 * scale);
                }
            }
            for (x, rows) in [(&v, n), (&u, m)] {
                for c in 0..q {
                    if sv[c] < 1e-12 * scale && std::ptr::eq(x, &u) {
                        continue; // no left vector for a zero singular value
                    }
                    for d in 0..q {
                        if sv[d] < 1e-12 * scale && std::ptr::eq(x, &u) {
                            continue;
                        }
                        let g: c64 = (0..rows).map(|i| x[(i, c)].conj() * x[(i, d)]).sum();
                        let want = if c == d { ONE } else { ZERO };
                        assert!((g - want).norm() < 1e-13);
                    }
                }
            }
        }
        let (sv, _, _) = svd_small(&cases[4]).unwrap();
        assert!(cond_of(&sv) > 1e14);
    }

    #[test]
    fn rational_weights_reproduce_one_pole_pair_and_polynomials() {
        // own lines every 4th line; the target line between them
        let own: Vec<usize> = (0..12).map(|i| 3 + 4 * i).collect();
        let k = 22usize;
        let xs = window(&own, k, RAT_HALF_WIDTH);
        assert_eq!(xs, &[11, 15, 19, 23, 27, 31]);
        // three entries sharing one sharp pole pair (a resonance 0.8 lines wide at line 21.3),
        // each with its own numerator, plus an entry without the pole
        let pole = c64::new(21.3, 0.8);
        let f = |a: usize, x: f64| -> c64 {
            let xc = c64::new(x, 0.0);
            let d = (xc - pole) * (xc - pole.conj() - c64::new(2.0, 0.0));
            let n =
                c64::new(1.0 + a as f64, 0.3 * a as f64) + xc * c64::new(0.05, -0.02 * a as f64);
            if a == 3 {
                c64::new(0.5, 0.1) + xc * 0.01
            } else {
                n / d
            }
        };
        let nz = 4;
        let z: Vec<c64> = xs
            .iter()
            .flat_map(|&x| (0..nz).map(move |a| f(a, x as f64)))
            .collect();
        let ew = vec![1.0; nz];
        let c = rational_weights(xs, k, &z, nz, &ew).unwrap();
        for a in 0..nz {
            let v: c64 = (0..xs.len()).map(|l| c[l] * z[l * nz + a]).sum();
            let want = f(a, k as f64);
            assert!(
                (v - want).norm() < 1e-9 * want.norm(),
                "entry {a}: {v} vs {want}"
            );
        }
        // the cubic Lagrange through the 4 nearest lines misses the resonance by far
        let (lx, lw) = lagrange4(&own, k);
        let lv: c64 = lx.iter().zip(lw).map(|(&x, w)| f(0, x as f64) * w).sum();
        assert!((lv - f(0, k as f64)).norm() > 1e-2 * f(0, k as f64).norm());
        // degree-4 polynomials (no pole) are reproduced as well; with one entry the 6 lines
        // leave one equation for the two denominator coefficients: refused (Lagrange then)
        let poly = |a: usize, x: f64| {
            c64::new(
                0.3 - 0.1 * x + 0.002 * a as f64 * x * x * x,
                1e-5 * x.powi(4 - a as i32),
            )
        };
        let z: Vec<c64> = xs
            .iter()
            .flat_map(|&x| (0..3).map(move |a| poly(a, x as f64)))
            .collect();
        let c = rational_weights(xs, k, &z, 3, &[1.0; 3]).unwrap();
        for a in 0..3 {
            let v: c64 = (0..xs.len()).map(|l| c[l] * z[l * 3 + a]).sum();
            let want = poly(a, k as f64);
            assert!((v - want).norm() < 1e-9 * want.norm(), "{a}: {v} vs {want}");
        }
        let z1: Vec<c64> = xs.iter().map(|&x| poly(0, x as f64)).collect();
        assert!(rational_weights(xs, k, &z1, 1, &[1.0]).is_none());
        // all-zero data cannot define a denominator: refused (the caller falls back)
        assert!(rational_weights(xs, k, &[ZERO; 6], 1, &[1.0]).is_none());
    }

    #[test]
    fn small_inverse_and_condition_number() {
        let a = Mat::<c64>::from_fn(3, 3, |i, j| {
            c64::new(
                if i == j {
                    2.0
                } else {
                    0.3 * (i + 2 * j) as f64
                },
                0.1 * i as f64 - 0.2 * j as f64,
            )
        });
        let ai = inv_small(&a).unwrap();
        let e = mat_mul(&a, &ai);
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { ONE } else { ZERO };
                assert!((e[(i, j)] - want).norm() < 1e-14);
            }
        }
        assert!(inv_small(&Mat::<c64>::zeros(2, 2)).is_none());
        // diag(3, 1e-3) rotated: κ = 3000
        let d = Mat::<c64>::from_fn(2, 2, |i, j| match (i, j) {
            (0, 0) => c64::new(3.0, 0.0),
            (1, 1) => c64::new(0.0, 1e-3),
            _ => ZERO,
        });
        let (sv, _, _) = svd_small(&d).unwrap();
        assert!((cond_of(&sv) - 3000.0).abs() < 1e-9);
        // g^T Σ ḡ of a 2-vector against the expanded form
        let sig = [
            [c64::new(2.0, 0.0), c64::new(0.3, -0.4)],
            [c64::new(0.3, 0.4), c64::new(1.0, 0.0)],
        ];
        let g = [(0usize, c64::new(1.0, 2.0)), (1usize, c64::new(-0.5, 0.25))];
        let direct: c64 = (0..2)
            .flat_map(|i| (0..2).map(move |l| (i, l)))
            .map(|(i, l)| g[i].1 * sig[i][l] * g[l].1.conj())
            .sum();
        assert!((quad(&g, &|a, b| sig[a][b]) - direct.re).abs() < 1e-14 && direct.im.abs() < 1e-14);
    }
}
