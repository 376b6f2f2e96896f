//! Closed-loop frequency responses with propagated variances.
//!
//! Conventions (injection at the controller output, `docs/conventions.md`):
//!
//! $$u = C(w - y) + r,\qquad y = P u + v,$$
//! $$T_{ry} = \frac{P}{1+PC},\quad S = T_{ru} = \frac{1}{1+PC},\quad
//!   P = \frac{T_{ry}}{T_{ru}}\ \text{(joint input–output)},\quad
//!   P = \frac{T_{ry}}{1 - C\,T_{ry}}\ \text{(indirect)},\quad C = \frac{r-u}{y}\ (w = 0).$$
//!
//! # Estimates and variances
//! **Periodic data** (from [`PeriodicSpectra`]): with the period means $\bar R, \bar U, \bar Y$ on a
//! line and the covariance of the means $\Sigma = \hat\sigma/P$ (module [`periodic`](super::periodic)),
//! every quantity $Z = \phi(\bar R, \bar U, \bar Y)$ gets the first-order variance
//!
//! $$\sigma_Z^2 = g^{\mathsf H}\Sigma\, g\ \text{ with }\ g = \nabla\phi,\qquad
//!   \text{e.g. } P = \bar Y/\bar U:\ \sigma_P^2 = \frac{\Sigma_{YY} + |P|^2\Sigma_{UU}
//!   - 2\,\mathrm{Re}\,(\bar P\,\Sigma_{YU})}{|\bar U|^2}.$$
//!
//! Noise that enters the loop shows up in both $u$ and $y$; the cross term $\Sigma_{YU}$ is what
//! makes the joint estimate's band honest.
//!
//! **Welch spectra** (from [`CrossSpectra`], $r$ as the reference): $\hat T_{ry} = S_{ry}/S_{rr}$,
//! $\hat T_{ru} = S_{ru}/S_{rr}$, $\hat P = S_{ry}/S_{ru}$, $\hat C = (S_{rr} - S_{ru})/S_{ry}$. With
//! the residual (noise) spectra $\Phi_{ab} = S_{ab} - S_{ar}S_{rb}/S_{rr}$ and $n$ effective averages,
//!
//! $$\sigma^2_{T_{ry}} = \frac{\Phi_{yy}}{n S_{rr}},\qquad
//!   \sigma^2_P = \frac{\Phi_{yy} + |P|^2\Phi_{uu} - 2\,\mathrm{Re}(P\,\Phi_{yu})}{n S_{rr} |T_{ru}|^2},$$
//!
//! the classical $(1-\gamma^2)|H|^2/(n\gamma^2)$ for $T_{ry}$ and its two-channel extension.
//!
//! **Indirect**: $P = T/(1 - CT)$ with the controller's exact response, so
//! $\sigma_P^2 = \sigma_T^2 / |1 - CT|^4$; an error $\Delta C$ in the controller model biases it by
//! $\Delta P \approx P^2 \Delta C$ (first order), which is why the joint estimate is the default.
//!
//! # The matrix algebra, written once
//! With $n_y$ outputs and $n_u$ inputs ($r$ and $u$ have $n_u$ channels), $T_{ry}$ is
//! $n_y \times n_u$ and $S = T_{ru}$ is $n_u \times n_u$; from $u = -C y + r$ and $y = P u$,
//!
//! $$T_{ry} = (I + P C)^{-1} P = P (I + C P)^{-1},\qquad S = (I + C P)^{-1},$$
//! $$P = T_{ry} S^{-1}\ \text{(joint, [`joint_plant`])},\qquad
//!   P = T_{ry} (I - C\,T_{ry})^{-1}\ \text{(indirect, [`indirect_plant`])},\qquad
//!   C = (I - S)\, T_{ry}^{-1}\ \text{(square loops, [`controller_from_loop`])},$$
//!
//! the scalar formulas above being their $1 \times 1$ case; [`ClosedLoopFrf::from_responses`] builds
//! the whole set from $T_{ry}$ and $S$ (e.g. a $4 \times 4$ MIMO estimate). The indirect estimate's
//! variance propagates $\delta P = (I - T_{ry} C)^{-1}\, \delta T_{ry}\, (I - C T_{ry})^{-1}$ (the
//! controller exact), i.e. $\sigma_T^2/|1 - CT|^4$ for SISO; the joint estimate from two separate
//! responses propagates them as independent ([`Frd::divide`]), whereas the SISO estimators below
//! use the cross-covariance of the spectra they have.
//!
//! # Confidence bands
//! For a circular complex Gaussian error, $|\hat G - G|^2/\hat\sigma^2$ follows an $F(2, 2\nu)$
//! law when $\hat\sigma^2$ has $\nu$ complex degrees of freedom ($\nu = P - 1$ periods), so the
//! radius of the level-$\alpha$ disc is $\hat\sigma\sqrt{q}$ with
//! $q = \nu\big((1-\alpha)^{-1/\nu} - 1\big)$ ([`band_radius_factor`]; $q \to -\ln(1-\alpha)$ for
//! $\nu\to\infty$).
//!
//! # Example
//! ```
//! use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
//! use ambid_core::frf::closed_loop::{from_periodic, Channels};
//! // r periodic; u = 0.5 r; y = 2 u (P = 2, static), four periods of 8 samples
//! let base = [1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 1.0, -1.0];
//! let r: Vec<f64> = (0..32).map(|k| base[k % 8]).collect();
//! let u: Vec<f64> = r.iter().map(|v| 0.5 * v).collect();
//! let y: Vec<f64> = u.iter().map(|v| 2.0 * v).collect();
//! let s = PeriodicAnalyzer::new(8).unwrap()
//!     .analyze(&[&r, &u, &y], 1000.0, &PeriodicOptions::new(8)).unwrap();
//! let lines = s.excited_lines(0, 1e-9).unwrap();
//! let frf = from_periodic(&s, Channels { r: 0, u: 1, y: 2 }, &lines, None).unwrap();
//! assert!(frf.plant.values().iter().all(|p| (p.re - 2.0).abs() < 1e-12 && p.im.abs() < 1e-12));
//! assert!(frf.t_ru.values().iter().all(|v| (v.re - 0.5).abs() < 1e-12));
//! ```

use super::periodic::PeriodicSpectra;
use super::welch::CrossSpectra;
use crate::error::{Error, Result};
use crate::lti::{Frd, StateSpace};
use faer::c64;

/// Which channel holds $r$, $u$ and $y$.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channels {
    /// Excitation $r$ (added to the controller output).
    pub r: usize,
    /// Controller output $u$ (including $r$).
    pub u: usize,
    /// Measured output $y$.
    pub y: usize,
}

/// How the spectra were averaged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Averaging {
    /// Period-synchronous averaging over this many periods.
    Periods(usize),
    /// Welch averaging over this many segments (and this effective number of averages).
    Welch {
        /// Segments averaged.
        segments: usize,
        /// Effective number of independent averages (overlap-corrected).
        effective: f64,
    },
}

/// The noise of a SISO ratio estimate $\hat G = \bar Y/\bar U$ on one line as a function of the
/// plant value $G$ it is compared with:
/// $$ v(G) = \frac{\operatorname{Var}(\bar Y - G\,\bar U)}{|\bar U|^2}
///         = a\,|G|^2 + b - 2\,\operatorname{Re}(G\,c) , $$
/// with $a = \Sigma_{UU}/|\bar U|^2$, $b = \Sigma_{YY}/|\bar U|^2$ and $c = \Sigma_{UY}/|\bar
/// U|^2$ (Welch: the residual spectra over $n S_{rr} |T_{ru}|^2$; module docs). At the estimate
/// itself, $v(\hat G)$ is the variance [`from_periodic`] and [`from_welch`] report; a model fit
/// that evaluates it at the *model* instead,
/// $|\hat G_k - G_\theta|^2 / v_k(G_\theta) = |\bar Y_k - G_\theta \bar U_k|^2 /
/// \operatorname{Var}(\bar Y_k - G_\theta \bar U_k)$, minimises the sample maximum-likelihood cost of errors-in-variables data
/// ([`FreqWeights::SampleMaximumLikelihood`](crate::estimate::freqfit::FreqWeights::SampleMaximumLikelihood)):
/// weights that do not follow the line's own error (docs/uncertainty.md, "Weights that follow
/// the data's noise").
///
/// # Example
/// At the estimate the value is the reported variance; elsewhere it follows the model value.
/// ```
/// use ambid_core::frf::closed_loop::RatioNoise;
/// use faer::c64;
/// // noise on y only: v(G) = b whatever G is
/// let n = RatioNoise { a: 0.0, b: 0.25, c: c64::new(0.0, 0.0) };
/// assert_eq!(n.variance_at(c64::new(3.0, -1.0)), 0.25);
/// // noise on u only: v(G) = a |G|²
/// let n = RatioNoise { a: 0.01, b: 0.0, c: c64::new(0.0, 0.0) };
/// assert!((n.variance_at(c64::new(3.0, 4.0)) - 0.25).abs() < 1e-15);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RatioNoise {
    /// $\Sigma_{UU}/|\bar U|^2$, the input noise's part (times $|G|^2$).
    pub a: f64,
    /// $\Sigma_{YY}/|\bar U|^2$, the output noise's part.
    pub b: f64,
    /// $\Sigma_{UY}/|\bar U|^2$, their cross term.
    pub c: c64,
}

impl RatioNoise {
    /// $v(G) = a|G|^2 + b - 2\operatorname{Re}(G c)$ (type docs), never below 0.
    pub fn variance_at(&self, g: c64) -> f64 {
        (self.a * g.norm_sqr() + self.b - 2.0 * (g * self.c).re).max(0.0)
    }

    /// $\partial v / \partial G$ along a change $\delta G$: $2\operatorname{Re}(\delta G\,(a \bar G -
    /// c))$, for fits that differentiate [`variance_at`](Self::variance_at).
    pub fn variance_slope(&self, g: c64, dg: c64) -> f64 {
        2.0 * (dg * (g.conj() * self.a - self.c)).re
    }
}

/// Closed-loop FRFs on a common frequency grid, each with its variance, plus coherences.
///
/// Every response is an [`Frd`] matrix ($T_{ry}$ and $P$: $n_y \times n_u$; $S$: $n_u \times n_u$;
/// the controller $n_u \times n_y$); SISO estimates are $1 \times 1$. The coherences are stored
/// per line and entry like [`Frd::values`] (one per line for SISO data).
#[derive(Debug, Clone, PartialEq)]
pub struct ClosedLoopFrf {
    /// $T_{ry}$, $r \to y$.
    pub t_ry: Frd,
    /// $S = T_{ru}$, $r \to u$.
    pub t_ru: Frd,
    /// The plant $P$ by the joint input–output method $T_{ry}/T_{ru}$.
    pub plant: Frd,
    /// The plant by the indirect method (only with a known controller).
    pub plant_indirect: Option<Frd>,
    /// The controller estimated from data, $C = (r-u)/y$ (valid with $w = 0$).
    pub controller: Frd,
    /// Coherence $\gamma^2_{ry}$ (per line and entry of $T_{ry}$).
    pub coh_ry: Vec<f64>,
    /// Coherence $\gamma^2_{ru}$ (per line and entry of $S$).
    pub coh_ru: Vec<f64>,
    /// How the estimate was averaged.
    pub averaging: Averaging,
    /// Complex degrees of freedom $\nu$ of the variance estimates (for [`band_radius_factor`]).
    pub dof: f64,
    /// Per line, the plant estimate's variance as a function of the plant value ([`RatioNoise`];
    /// SISO estimates with variances from [`from_periodic`] and [`from_welch`], `None`
    /// otherwise): what a sample maximum-likelihood fit needs.
    pub plant_noise: Option<Vec<RatioNoise>>,
}

impl ClosedLoopFrf {
    /// Frequencies \[Hz\].
    pub fn f_hz(&self) -> &[f64] {
        self.plant.f_hz()
    }

    /// Radius factor of the level-`level` confidence disc for this estimate's degrees of freedom.
    pub fn band_factor(&self, level: f64) -> Result<f64> {
        band_radius_factor(level, self.dof)
    }

    /// The closed-loop set from estimated $T_{ry}$ ($n_y \times n_u$) and $S = T_{ru}$
    /// ($n_u \times n_u$) of any size: $P = T_{ry} S^{-1}$ ([`joint_plant`]), the controller
    /// $C = (I - S) T_{ry}^{-1}$ ([`controller_from_loop`], square loops), and, with the
    /// controller's known response, the indirect $P = T_{ry}(I - C T_{ry})^{-1}$
    /// ([`indirect_plant`]). `coh_ry` and `coh_ru` are per line and entry (flat, as
    /// [`Frd::values`]).
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] for inconsistent shapes or coherence lengths; singular lines
    /// (named by frequency) of $S$, $T_{ry}$ or $I - C T_{ry}$.
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::closed_loop::{Averaging, ClosedLoopFrf};
    /// use ambid_core::lti::Frd;
    /// let f = [10.0, 20.0];
    /// // P = 2, C = 0.5: T = P/(1 + PC) = 1, S = 1/(1 + CP) = 0.5
    /// let t = Frd::constant(&f, 1.0, Some(1e-3)).unwrap();
    /// let s = Frd::constant(&f, 0.5, Some(1e-3)).unwrap();
    /// let c = Frd::constant(&f, 0.5, Some(1e-3)).unwrap();
    /// let cl = ClosedLoopFrf::from_responses(t, s, Some(&c), vec![1.0; 2], vec![1.0; 2],
    ///     Averaging::Periods(4), 3.0).unwrap();
    /// assert!(cl.plant.values().iter().all(|p| (p.re - 2.0).abs() < 1e-15));
    /// assert!(cl.controller.values().iter().all(|k| (k.re - 0.5).abs() < 1e-15));
    /// assert!(cl.plant_indirect.unwrap().values().iter().all(|p| (p.re - 2.0).abs() < 1e-15));
    /// ```
    pub fn from_responses(
        t_ry: Frd,
        t_ru: Frd,
        controller: Option<&Frd>,
        coh_ry: Vec<f64>,
        coh_ru: Vec<f64>,
        averaging: Averaging,
        dof: f64,
    ) -> Result<Self> {
        for (what, got, want) in [
            ("ClosedLoopFrf coh_ry", coh_ry.len(), t_ry.values().len()),
            ("ClosedLoopFrf coh_ru", coh_ru.len(), t_ru.values().len()),
        ] {
            if got != want {
                return Err(Error::DimensionMismatch {
                    context: what,
                    expected: format!("{want} (one per line and entry)"),
                    got: got.to_string(),
                });
            }
        }
        let plant = joint_plant(&t_ry, &t_ru)?;
        let ctrl = controller_from_loop(&t_ry, &t_ru)?;
        let plant_indirect = controller.map(|c| indirect_plant(&t_ry, c)).transpose()?;
        Ok(Self {
            t_ry,
            t_ru,
            plant,
            plant_indirect,
            controller: ctrl,
            coh_ry,
            coh_ru,
            averaging,
            dof,
            plant_noise: None,
        })
    }
}

/// The joint input–output plant $P = T_{ry} S^{-1}$ (right division, any size; $T_{ry}/T_{ru}$
/// for SISO data), with the variances of [`Frd::divide`] (the two estimates taken as
/// independent).
///
/// # Errors
/// [`Error::DimensionMismatch`] unless $S$ is square with as many rows as $T_{ry}$ has columns;
/// a singular $S$ on a line (named by frequency).
pub fn joint_plant(t_ry: &Frd, t_ru: &Frd) -> Result<Frd> {
    t_ry.divide(t_ru)
}

/// The controller seen by the loop, $C = (I - S)\, T_{ry}^{-1}$ (from $u = -C y + r$:
/// $r - u = C y$), for a square loop ($n_y = n_u$); $(1 - S)/T_{ry}$ for SISO data. No variance
/// (the estimators that have the spectra give it).
///
/// # Errors
/// [`Error::DimensionMismatch`] for a non-square loop; a singular $T_{ry}$ on a line.
pub fn controller_from_loop(t_ry: &Frd, t_ru: &Frd) -> Result<Frd> {
    let strip = |g: &Frd| {
        Frd::new_matrix(
            g.f_hz().to_vec(),
            g.ny(),
            g.nu(),
            g.values().to_vec(),
            None,
            g.ts(),
        )
    };
    let eye = Frd::identity(t_ru.f_hz(), t_ru.ny(), t_ru.ts())?;
    eye.parallel(&strip(t_ru)?.scaled(-1.0))?
        .divide(&strip(t_ry)?)
}

/// The indirect plant $P = T_{ry}\,(I - C\,T_{ry})^{-1}$ from an estimated $T_{ry}$
/// ($n_y \times n_u$) and the controller's exact response $C$ ($n_u \times n_y$, its variance
/// ignored), with $\delta P = (I - T_{ry} C)^{-1}\, \delta T_{ry}\, (I - C T_{ry})^{-1}$, i.e.
/// $\sigma^2_{P_{ij}} = \sum_{kl} |A_{ik}|^2 |B_{lj}|^2 \sigma^2_{T_{kl}}$ with
/// $A = (I - T C)^{-1}$, $B = (I - C T)^{-1}$ ($\sigma_T^2/|1 - CT|^4$ for SISO data).
///
/// # Errors
/// [`Error::DimensionMismatch`] unless $C$ is $n_u \times n_y$; different grids; a singular
/// $I - C T_{ry}$ on a line.
///
/// # Example
/// ```
/// use ambid_core::frf::closed_loop::indirect_plant;
/// use ambid_core::lti::Frd;
/// use faer::c64;
/// // P = 2, C = 0.5: T = 2/(1 + 1) = 1 with variance 0.01 → P = 1/(1 − 0.5) = 2, σ² = 0.01/0.5⁴
/// let t = Frd::new(vec![5.0], vec![c64::new(1.0, 0.0)], Some(vec![0.01]), None).unwrap();
/// let c = Frd::constant(&[5.0], 0.5, None).unwrap();
/// let p = indirect_plant(&t, &c).unwrap();
/// assert!((p.values()[0].re - 2.0).abs() < 1e-15);
/// assert!((p.variance().unwrap()[0] - 0.16).abs() < 1e-15);
/// ```
pub fn indirect_plant(t_ry: &Frd, controller: &Frd) -> Result<Frd> {
    let (ny, nu) = (t_ry.ny(), t_ry.nu());
    if (controller.ny(), controller.nu()) != (nu, ny) {
        return Err(Error::DimensionMismatch {
            context: "indirect_plant: the controller maps the outputs to the inputs",
            expected: format!("{nu}×{ny}"),
            got: format!("{}×{}", controller.ny(), controller.nu()),
        });
    }
    let plain = |g: &Frd| {
        Frd::new_matrix(
            g.f_hz().to_vec(),
            g.ny(),
            g.nu(),
            g.values().to_vec(),
            None,
            g.ts(),
        )
    };
    let (t, c) = (plain(t_ry)?, plain(controller)?);
    let eye = |n: usize| Frd::identity(t.f_hz(), n, t.ts());
    // B = I − C T (nu×nu), A = I − T C (ny×ny)
    let b = eye(nu)?.parallel(&c.product(&t)?.scaled(-1.0))?;
    let p = t.divide(&b)?;
    let Some(vt) = t_ry.variance() else {
        return Ok(p);
    };
    let a_inv = eye(ny)?.parallel(&t.product(&c)?.scaled(-1.0))?.inverse()?;
    let b_inv = b.inverse()?;
    let per = ny * nu;
    let mut var = vec![0.0; p.values().len()];
    for line in 0..p.len() {
        let (ai, bi) = (a_inv.at(line)?, b_inv.at(line)?);
        for j in 0..nu {
            for i in 0..ny {
                let mut acc = 0.0;
                for k in 0..ny {
                    for l in 0..nu {
                        acc += ai[(i, k)].norm_sqr()
                            * bi[(l, j)].norm_sqr()
                            * vt[line * per + l * ny + k];
                    }
                }
                var[line * per + j * ny + i] = acc;
            }
        }
    }
    Frd::new_matrix(
        p.f_hz().to_vec(),
        ny,
        nu,
        p.values().to_vec(),
        Some(var),
        p.ts(),
    )
}

/// Radius of the level-$\alpha$ confidence disc in units of the estimated standard deviation,
/// $\sqrt{\nu((1-\alpha)^{-1/\nu}-1)}$ ($\nu$ complex degrees of freedom; `f64::INFINITY` gives the
/// known-variance value $\sqrt{-\ln(1-\alpha)}$).
///
/// # Errors
/// [`Error::InvalidArgument`] unless $0 < \alpha < 1$ and $\nu > 0$.
///
/// # Example
/// ```
/// use ambid_core::frf::closed_loop::band_radius_factor;
/// let inf = band_radius_factor(0.95, f64::INFINITY).unwrap();
/// assert!((inf - 20f64.ln().sqrt()).abs() < 1e-12);
/// assert!(band_radius_factor(0.95, 19.0).unwrap() > inf);
/// ```
pub fn band_radius_factor(level: f64, dof: f64) -> Result<f64> {
    if !(level > 0.0 && level < 1.0) {
        return Err(Error::invalid(
            "level",
            format!("a confidence level must be in (0, 1), got {level}"),
        ));
    }
    if dof.is_nan() || dof <= 0.0 {
        return Err(Error::invalid(
            "dof",
            format!("degrees of freedom must be positive, got {dof}; at least 2 periods or segments are needed"),
        ));
    }
    let q = if dof.is_infinite() {
        -(1.0 - level).ln()
    } else {
        dof * ((1.0 - level).powf(-1.0 / dof) - 1.0)
    };
    Ok(q.sqrt())
}

/// Variance $g^{\mathsf H} \Sigma g$ of a linear combination $\sum_i g_i\,\delta X_i$ with
/// $\Sigma_{ij} = \mathrm E[\delta X_i \overline{\delta X_j}]$.
fn quad_form(g: &[c64; 3], cov: impl Fn(usize, usize) -> c64) -> f64 {
    // Hermitian: diagonal terms plus twice the real part of the upper triangle
    let mut v = 0.0;
    for i in 0..3 {
        v += g[i].norm_sqr() * cov(i, i).re;
        for j in i + 1..3 {
            v += 2.0 * (g[i] * cov(i, j) * g[j].conj()).re;
        }
    }
    v.max(0.0)
}

/// $|a|^2 s_{aa} + |b|^2 s_{bb} + 2\,\mathrm{Re}(a\, s_{ab}\, \bar b)$: [`quad_form`] for two
/// non-zero coefficients.
#[inline]
fn quad_form2(a: c64, b: c64, saa: f64, sbb: f64, sab: c64) -> f64 {
    (a.norm_sqr() * saa + b.norm_sqr() * sbb + 2.0 * (a * sab * b.conj()).re).max(0.0)
}

fn controller_response(ctrl: &StateSpace, f_hz: &[f64], ts_data: f64) -> Result<Frd> {
    match ctrl.ts() {
        None => Err(Error::TimeDomain(
            "the controller for the indirect method is continuous-time; discretise it at the data's \
             sample time first"
                .into(),
        )),
        Some(ts) if ((ts - ts_data) / ts_data).abs() > 1e-9 => Err(Error::SampleTimeMismatch {
            left: ts,
            right: ts_data,
        }),
        Some(_) => Frd::from_model(ctrl, f_hz),
    }
}

/// Closed-loop FRFs from period-synchronous averages on the given `lines` (e.g.
/// [`PeriodicSpectra::excited_lines`] restricted to a band); `controller` enables the indirect
/// estimate.
///
/// # Errors
/// * [`Error::InvalidArgument`]: a channel index out of range, no line, a line beyond Nyquist or
///   where $\bar R$, $\bar U$ or $\bar Y$ vanishes (not excited);
/// * [`Error::SampleTimeMismatch`] / [`Error::TimeDomain`]: a controller whose sample time is not
///   the data's.
pub fn from_periodic(
    s: &PeriodicSpectra,
    ch: Channels,
    lines: &[usize],
    controller: Option<&StateSpace>,
) -> Result<ClosedLoopFrf> {
    let nc = s.n_channels();
    for (name, c) in [("r", ch.r), ("u", ch.u), ("y", ch.y)] {
        if c >= nc {
            return Err(Error::invalid(
                "channels",
                format!("channel `{name}` has index {c} but only {nc} channels were analysed"),
            ));
        }
    }
    if lines.is_empty() {
        return Err(Error::invalid(
            "lines",
            "no frequency line selected: the excitation has no power in the requested band; widen \
             the band or check the excitation",
        ));
    }
    if let Some(&k) = lines.iter().find(|&&k| k == 0 || k >= s.n_lines()) {
        return Err(Error::invalid(
            "lines",
            format!(
                "line {k} is outside 1..{} (DC is not used; lines stop at Nyquist)",
                s.n_lines()
            ),
        ));
    }
    let p = s.periods() as f64;
    let idx = [ch.r, ch.u, ch.y];
    let ts = 1.0 / s.fs();
    let f: Vec<f64> = lines.iter().map(|&k| s.line_hz(k)).collect();
    let n = lines.len();
    let (mut t, mut sv, mut pl, mut c) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    let (mut vt, mut vs, mut vp, mut vc) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    let (mut coh_ry, mut coh_ru) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut noise = Vec::with_capacity(n);
    let covs: Vec<Vec<(&[c64], bool)>> = idx
        .iter()
        .map(|&i| idx.iter().map(|&j| s.cov_slice(i, j)).collect())
        .collect();
    let (mr, mu, my) = (s.mean(ch.r), s.mean(ch.u), s.mean(ch.y));
    for &k in lines {
        let (rr, uu, yy) = (mr[k], mu[k], my[k]);
        for (name, v) in [("r", rr), ("u", uu), ("y", yy)] {
            if v.norm_sqr() == 0.0 {
                return Err(Error::invalid(
                    "lines",
                    format!(
                        "channel `{name}` has no power on line {k} ({:.3} Hz); select excited lines only",
                        s.line_hz(k)
                    ),
                ));
            }
        }
        // covariance of the means of (R, U, Y) on this line
        let mut sig = [[c64::new(0.0, 0.0); 3]; 3];
        for (i, row) in covs.iter().enumerate() {
            for (j, (slice, conj)) in row.iter().enumerate() {
                let v = slice[k] / p;
                sig[i][j] = if *conj { v.conj() } else { v };
            }
        }
        let cov = |i: usize, j: usize| sig[i][j];
        let one = c64::new(1.0, 0.0);
        let (ir, iu, iy) = (one / rr, one / uu, one / yy);
        let tk = yy * ir;
        let sk = uu * ir;
        let pk = yy * iu;
        let ck = (rr - uu) * iy;
        vt.push(quad_form2(
            -tk * ir,
            ir,
            sig[0][0].re,
            sig[2][2].re,
            sig[0][2],
        ));
        vs.push(quad_form2(
            -sk * ir,
            ir,
            sig[0][0].re,
            sig[1][1].re,
            sig[0][1],
        ));
        vp.push(quad_form2(
            -pk * iu,
            iu,
            sig[1][1].re,
            sig[2][2].re,
            sig[1][2],
        ));
        vc.push(quad_form(&[iy, -iy, -ck * iy], cov));
        let u2 = uu.norm_sqr();
        noise.push(RatioNoise {
            a: sig[1][1].re / u2,
            b: sig[2][2].re / u2,
            c: sig[1][2] / u2,
        });
        t.push(tk);
        sv.push(sk);
        pl.push(pk);
        c.push(ck);
        // coherences from the period moments M_ab = (P − 1) Σ_ab + X̄_a X̄_b*
        let m = [rr, uu, yy];
        let mom = |a: usize, b: usize| sig[a][b] * (p - 1.0) + m[a] * m[b].conj();
        let (m_rr, m_uu, m_yy) = (mom(0, 0).re, mom(1, 1).re, mom(2, 2).re);
        coh_ry.push((mom(0, 2).norm_sqr() / (m_rr * m_yy)).min(1.0));
        coh_ru.push((mom(0, 1).norm_sqr() / (m_rr * m_uu)).min(1.0));
    }
    let has_var = s.periods() > 1;
    let var = |v: Vec<f64>| if has_var { Some(v) } else { None };
    let t_ry = Frd::new(f.clone(), t, var(vt), Some(ts))?;
    let plant_indirect = controller
        .map(|ctrl| indirect(&t_ry, ctrl, ts))
        .transpose()?;
    Ok(ClosedLoopFrf {
        t_ry,
        t_ru: Frd::new(f.clone(), sv, var(vs), Some(ts))?,
        plant: Frd::new(f.clone(), pl, var(vp), Some(ts))?,
        plant_indirect,
        controller: Frd::new(f, c, var(vc), Some(ts))?,
        coh_ry,
        coh_ru,
        averaging: Averaging::Periods(s.periods()),
        dof: (s.periods() as f64 - 1.0).max(0.0),
        plant_noise: has_var.then_some(noise),
    })
}

/// The indirect plant estimate $T (I - C T)^{-1}$ ($T/(1 - CT)$ for SISO data) from an
/// estimated $T_{ry}$ and a known discrete controller (same sample time), with the variance of
/// [`indirect_plant`] ($\sigma_P^2 = \sigma_T^2/|1 - CT|^4$ for SISO data).
///
/// # Errors
/// Sample-time or time-domain mismatch of the controller; a controller whose size does not
/// match $T_{ry}$ ($n_u \times n_y$).
pub fn indirect(t_ry: &Frd, controller: &StateSpace, ts: f64) -> Result<Frd> {
    let cf = controller_response(controller, t_ry.f_hz(), ts)?;
    let cf = Frd::new_matrix(
        cf.f_hz().to_vec(),
        cf.ny(),
        cf.nu(),
        cf.values().to_vec(),
        None,
        Some(ts),
    )?;
    let t = Frd::new_matrix(
        t_ry.f_hz().to_vec(),
        t_ry.ny(),
        t_ry.nu(),
        t_ry.values().to_vec(),
        t_ry.variance().map(<[f64]>::to_vec),
        Some(ts),
    )?;
    indirect_plant(&t, &cf)
}

/// The three SISO channels $(r, u, y)$ of a single-experiment record, by role.
fn ruy(data: &crate::data::IoData, what: &str) -> Result<[Vec<f64>; 3]> {
    use crate::data::Role;
    let (y, u) = crate::data::iodata::siso_pair(data, what)?;
    let nr = data.role_count(Role::Excitation);
    if nr != 1 {
        return Err(match nr {
            0 => data.missing_role(Role::Excitation),
            _ => Error::invalid(
                "channels",
                format!("{what} is SISO-only, and the record has {nr} excitation channels"),
            ),
        });
    }
    data.require_finite(&[Role::Excitation])?;
    Ok([
        data.signals(Role::Excitation, 0)?[0].to_vec(),
        u.to_vec(),
        y.to_vec(),
    ])
}

/// The front door on an [`crate::data::IoData`] for Welch estimates: [`from_welch`] on the
/// excitation, input and output channels (roles) of a single-experiment SISO record, with
/// `opts.fs` the record's sample rate.
///
/// # Errors
/// [`Error::InvalidArgument`] for several experiments, a record that is not SISO (role counts
/// named), a missing role, a non-finite sample, or `opts.fs` different from the record's; the
/// errors of [`crate::frf::welch::welch_spectra`] and [`from_welch`].
pub fn from_welch_iodata(
    data: &crate::data::IoData,
    opts: &crate::frf::welch::WelchOptions,
    band: (f64, f64),
    rel_threshold: f64,
    controller: Option<&StateSpace>,
) -> Result<ClosedLoopFrf> {
    if ((opts.fs - data.fs()) / data.fs()).abs() > 1e-9 {
        return Err(Error::invalid(
            "fs",
            format!(
                "the Welch options are for {} Hz but the record is sampled at {} Hz",
                opts.fs,
                data.fs()
            ),
        ));
    }
    let ch = ruy(data, "from_welch")?;
    let spectra = crate::frf::welch::welch_spectra(&ch, opts)?;
    from_welch(
        &spectra,
        Channels { r: 0, u: 1, y: 2 },
        band,
        rel_threshold,
        controller,
    )
}

/// The front door on an [`crate::data::IoData`] for periodic excitations: period-synchronous
/// averages of the $(r, u, y)$ channels (roles) of a single-experiment SISO record with its
/// [`IoData::period_samples`](crate::data::IoData::period_samples), on the lines where $r$
/// exceeds `rel_threshold` of its largest line within `band` (Hz), then [`from_periodic`].
///
/// # Errors
/// [`Error::InvalidArgument`] for a record without a period, several experiments, a record that
/// is not SISO, a missing role or a non-finite sample; the errors of
/// [`crate::frf::periodic::PeriodicAnalyzer::analyze`] and [`from_periodic`].
///
/// # Example
/// ```
/// use ambid_core::data::IoData;
/// use ambid_core::frf::closed_loop::from_periodic_iodata;
/// let base = [1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 1.0, -1.0];
/// let r: Vec<f64> = (0..32).map(|k| base[k % 8]).collect();
/// let u: Vec<f64> = r.iter().map(|v| 0.5 * v).collect();
/// let y: Vec<f64> = u.iter().map(|v| 2.0 * v).collect();
/// let d = IoData::new(vec![("r".into(), r), ("u".into(), u), ("y".into(), y)], 1e-3, Some(8)).unwrap();
/// let frf = from_periodic_iodata(&d, (0.0, 500.0), 1e-9, None).unwrap();
/// assert!(frf.plant.values().iter().all(|p| (p.re - 2.0).abs() < 1e-12));
/// ```
pub fn from_periodic_iodata(
    data: &crate::data::IoData,
    band: (f64, f64),
    rel_threshold: f64,
    controller: Option<&StateSpace>,
) -> Result<ClosedLoopFrf> {
    use crate::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
    let Some(p) = data.period_samples() else {
        return Err(Error::invalid(
            "period_samples",
            "the record has no period; set IoData::with_period_samples (a periodic excitation's period in samples) or use from_welch_iodata",
        ));
    };
    let ch = ruy(data, "from_periodic")?;
    let refs: Vec<&[f64]> = ch.iter().map(|v| v.as_slice()).collect();
    let s = PeriodicAnalyzer::new(p)?.analyze(&refs, data.fs(), &PeriodicOptions::new(p))?;
    let lines: Vec<usize> = s
        .excited_lines(0, rel_threshold)?
        .into_iter()
        .filter(|&k| {
            let f = s.line_hz(k);
            f >= band.0 && f <= band.1
        })
        .collect();
    from_periodic(&s, Channels { r: 0, u: 1, y: 2 }, &lines, controller)
}

/// The plant FRF's deviation in each period, to first order: with the period DFTs $U_p(k)$,
/// $Y_p(k)$ and their means $\bar U(k)$, $\bar Y(k)$ over the $P$ analysed periods (the
/// estimate $\hat P_k = \bar Y(k)/\bar U(k)$ of [`from_periodic`]),
/// $$ d_{p,k} = \frac{Y_p(k) - \hat P_k\, U_p(k)}{\bar U(k)}, \qquad \sum_p d_{p,k} = 0, $$
/// indexed `[period][line]` on `lines`. The error of $\hat P_k$ is the mean of the periods'
/// errors, $\delta\hat P_k \approx \frac1P\sum_p (Y_p - P_k U_p)/\bar U$, so
/// $\frac{1}{P(P-1)}\sum_p |d_{p,k}|^2$ is the variance [`from_periodic`] gives the plant FRF
/// (the same linearisation), and $\frac{1}{P(P-1)}\sum_p d_{p,k}\,\overline{d_{p,j}}$ its
/// covariance *between* lines, which the per-line variances do not hold: the sample
/// covariance across periods of any linear functional of the FRF (e.g. a whole-band sum, or a
/// fitted model's parameters to first order) is taken from them. docs/uncertainty.md uses them
/// to test whether the FRF's error is correlated over the band.
///
/// # Errors
/// Those of [`PeriodicAnalyzer::analyze`](super::periodic::PeriodicAnalyzer::analyze) and
/// [`PeriodicAnalyzer::period_lines`](super::periodic::PeriodicAnalyzer::period_lines);
/// [`Error::InvalidArgument`] for a channel index out of range, no line, line 0, fewer than 2
/// analysed periods, or a line where $\bar U$ vanishes (not excited).
///
/// # Example
/// A plant of gain 2 whose output carries a disturbance that changes from period to period:
/// the deviations' sample variance is the one [`from_periodic`] reports.
/// ```
/// use ambid_core::frf::closed_loop::{from_periodic, plant_period_deviations, Channels};
/// use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
/// let n = 16;
/// let u: Vec<f64> = (0..6 * n).map(|k| (2.0 * std::f64::consts::PI * 3.0 * k as f64 / n as f64).cos()).collect();
/// let y: Vec<f64> = u.iter().enumerate().map(|(k, v)| 2.0 * v + 0.01 * ((k * k) % 7) as f64).collect();
/// let (ch, opts) = (Channels { r: 0, u: 0, y: 1 }, PeriodicOptions::new(n));
/// let d = plant_period_deviations(&[&u, &y], 1.0, ch, &opts, &[3]).unwrap();
/// let p = d.len() as f64;
/// let var = d.iter().map(|dp| dp[0].norm_sqr()).sum::<f64>() / (p * (p - 1.0));
/// let s = PeriodicAnalyzer::new(n).unwrap().analyze(&[&u, &y], 1.0, &opts).unwrap();
/// let frf = from_periodic(&s, ch, &[3], None).unwrap();
/// let reported = frf.plant.variance().unwrap()[0];
/// assert!((var - reported).abs() <= 1e-9 * reported, "{var} {reported}");
/// ```
pub fn plant_period_deviations(
    channels: &[&[f64]],
    fs: f64,
    ch: Channels,
    opts: &super::periodic::PeriodicOptions,
    lines: &[usize],
) -> Result<Vec<Vec<c64>>> {
    let nc = channels.len();
    for (name, c) in [("r", ch.r), ("u", ch.u), ("y", ch.y)] {
        if c >= nc {
            return Err(Error::invalid(
                "channels",
                format!("channel `{name}` has index {c} but only {nc} channels were given"),
            ));
        }
    }
    if lines.is_empty() || lines.contains(&0) {
        return Err(Error::invalid(
            "lines",
            "needs at least one line, and not line 0 (DC is not used)",
        ));
    }
    let per = super::periodic::PeriodicAnalyzer::new(opts.period_samples)?.period_lines(
        &[channels[ch.u], channels[ch.y]],
        fs,
        opts,
        lines,
    )?;
    let p = per.len();
    if p < 2 {
        return Err(Error::invalid(
            "periods",
            format!("{p} analysed period: deviations across periods need at least 2"),
        ));
    }
    let mean = |c: usize, i: usize| per.iter().map(|x| x[c][i]).sum::<c64>() / p as f64;
    let mut ratio = Vec::with_capacity(lines.len());
    for (i, &k) in lines.iter().enumerate() {
        let (ub, yb) = (mean(0, i), mean(1, i));
        if ub.norm_sqr() == 0.0 {
            return Err(Error::invalid(
                "lines",
                format!("`u` has no power on line {k}; select excited lines only"),
            ));
        }
        ratio.push((yb / ub, c64::new(1.0, 0.0) / ub));
    }
    Ok(per
        .iter()
        .map(|x| {
            ratio
                .iter()
                .enumerate()
                .map(|(i, (ph, iu))| (x[1][i] - ph * x[0][i]) * iu)
                .collect()
        })
        .collect())
}

/// Closed-loop FRFs from Welch spectra (channel indices into `spectra`), $r$ as the reference;
/// frequencies restricted to `[f_min, f_max]` and to bins where $S_{rr}$ exceeds `rel_threshold`
/// times its maximum.
///
/// # Errors
/// * [`Error::InvalidArgument`]: a channel out of range, or no bin with excitation power in the
///   band (names the band);
/// * controller errors as in [`from_periodic`].
pub fn from_welch(
    spectra: &CrossSpectra,
    ch: Channels,
    band: (f64, f64),
    rel_threshold: f64,
    controller: Option<&StateSpace>,
) -> Result<ClosedLoopFrf> {
    let nc = spectra.n_channels();
    for (name, c) in [("r", ch.r), ("u", ch.u), ("y", ch.y)] {
        if c >= nc {
            return Err(Error::invalid(
                "channels",
                format!("channel `{name}` has index {c} but the spectra hold {nc} channels"),
            ));
        }
    }
    let f_all = spectra.f_hz();
    let srr = spectra.get(ch.r, ch.r)?;
    let peak = srr.iter().skip(1).fold(0.0f64, |m, v| m.max(v.re));
    let bins: Vec<usize> = (1..f_all.len())
        .filter(|&k| f_all[k] >= band.0 && f_all[k] <= band.1 && srr[k].re > rel_threshold * peak)
        .collect();
    if bins.is_empty() || peak == 0.0 {
        return Err(Error::invalid(
            "band",
            format!(
                "the excitation has no power in {}–{} Hz; widen the band or check the excitation channel",
                band.0, band.1
            ),
        ));
    }
    let ts = 1.0 / spectra.options().fs;
    let n_eff = spectra.effective_averages();
    let (sru, sry) = (spectra.get(ch.r, ch.u)?, spectra.get(ch.r, ch.y)?);
    let (suu, syy, syu) = (
        spectra.get(ch.u, ch.u)?,
        spectra.get(ch.y, ch.y)?,
        spectra.get(ch.y, ch.u)?,
    );
    let (sur, syr) = (spectra.get(ch.u, ch.r)?, spectra.get(ch.y, ch.r)?);
    let m = bins.len();
    let mut f = Vec::with_capacity(m);
    let (mut t, mut sv, mut pl, mut c) = (vec![], vec![], vec![], vec![]);
    let (mut vt, mut vs, mut vp, mut vc) = (vec![], vec![], vec![], vec![]);
    let (mut coh_ry, mut coh_ru) = (vec![], vec![]);
    let mut noise = Vec::with_capacity(bins.len());
    for &k in &bins {
        f.push(f_all[k]);
        let rr = srr[k].re;
        // residual spectra Φ_ab = S_ab − S_ar S_rb / S_rr  (S_ab = E[conj(a) b])
        let phi_yy = (syy[k].re - syr[k].norm_sqr() / rr).max(0.0);
        let phi_uu = (suu[k].re - sur[k].norm_sqr() / rr).max(0.0);
        let phi_yu = syu[k] - syr[k] * sru[k] / rr;
        let tk = sry[k] / rr;
        let sk = sru[k] / rr;
        let pk = sry[k] / sru[k];
        let ck = (c64::new(rr, 0.0) - sru[k]) / sry[k];
        let nr = n_eff * rr;
        vt.push(phi_yy / nr);
        vs.push(phi_uu / nr);
        let den = nr * sk.norm_sqr();
        vp.push(((phi_yy + pk.norm_sqr() * phi_uu - 2.0 * (pk * phi_yu).re).max(0.0)) / den);
        noise.push(RatioNoise {
            a: phi_uu / den,
            b: phi_yy / den,
            c: phi_yu / den,
        });
        vc.push(
            ((phi_uu + ck.norm_sqr() * phi_yy + 2.0 * (ck * phi_yu.conj()).re).max(0.0))
                / (nr * tk.norm_sqr()),
        );
        t.push(tk);
        sv.push(sk);
        pl.push(pk);
        c.push(ck);
        coh_ry.push((sry[k].norm_sqr() / (rr * syy[k].re)).min(1.0));
        coh_ru.push((sru[k].norm_sqr() / (rr * suu[k].re)).min(1.0));
    }
    let t_ry = Frd::new(f.clone(), t, Some(vt), Some(ts))?;
    let plant_indirect = controller
        .map(|ctrl| indirect(&t_ry, ctrl, ts))
        .transpose()?;
    Ok(ClosedLoopFrf {
        t_ry,
        t_ru: Frd::new(f.clone(), sv, Some(vs), Some(ts))?,
        plant: Frd::new(f.clone(), pl, Some(vp), Some(ts))?,
        plant_indirect,
        controller: Frd::new(f, c, Some(vc), Some(ts))?,
        coh_ry,
        coh_ru,
        averaging: Averaging::Welch {
            segments: spectra.n_segments(),
            effective: n_eff,
        },
        dof: (n_eff - 1.0).max(1.0),
        plant_noise: Some(noise),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// $u = r - 0.4 y$, $y_k = 0.8 y_{k-1} + 0.5 u_{k-1} + 0.05 e_k$: a noisy loop with memory
    /// (sensor-like noise $e$ that the controller feeds back).
    fn loop_with_memory(r: &[f64], rng: &mut rand_chacha::ChaCha8Rng) -> (Vec<f64>, Vec<f64>) {
        use rand_distr::{Distribution, StandardNormal};
        let len = r.len();
        let (mut u, mut y) = (vec![0.0; len], vec![0.0; len]);
        for k in 0..len {
            let (yp, up) = if k > 0 {
                (y[k - 1], u[k - 1])
            } else {
                (0.0, 0.0)
            };
            let e: f64 = StandardNormal.sample(rng);
            y[k] = 0.8 * yp + 0.5 * up + 0.05 * e;
            u[k] = r[k] - 0.4 * y[k];
        }
        (u, y)
    }

    #[test]
    fn band_factor_matches_f_distribution_quantile() {
        // F(2, 2ν) CDF: 1 − (1 + x/ν)^(−ν); check the quantile inverts it.
        for &nu in &[1.0, 4.0, 19.0, 200.0] {
            let q = band_radius_factor(0.95, nu).unwrap().powi(2);
            let cdf = 1.0 - (1.0 + q / nu).powf(-nu);
            assert!((cdf - 0.95).abs() < 1e-12, "ν = {nu}");
        }
        assert!(band_radius_factor(1.0, 3.0).is_err());
        assert!(band_radius_factor(0.9, 0.0).is_err());
    }

    /// A noisy closed loop on a periodic record: the periods' deviations reproduce the plant
    /// variance [`from_periodic`] computes from the accumulated covariances (another code path,
    /// the delta method on the 3×3 covariance), sum to zero over the periods, and reconstruct
    /// the period DFTs a naive in-test DFT gives.
    #[test]
    fn period_deviations_reproduce_the_plant_variance_and_a_naive_dft() {
        use crate::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let (n, periods) = (64usize, 7usize);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let base: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut rng)).collect();
        let len = n * periods;
        let r: Vec<f64> = (0..len).map(|k| base[k % n]).collect();
        let (u, y) = loop_with_memory(&r, &mut rng);
        let opts = PeriodicOptions::new(n).skip(1);
        let ch = Channels { r: 0, u: 1, y: 2 };
        let lines: Vec<usize> = (1..n / 2).collect();
        let d = plant_period_deviations(&[&r, &u, &y], 1.0, ch, &opts, &lines).unwrap();
        assert_eq!(d.len(), periods - 1);
        let s = PeriodicAnalyzer::new(n)
            .unwrap()
            .analyze(&[&r, &u, &y], 1.0, &opts)
            .unwrap();
        let frf = from_periodic(&s, ch, &lines, None).unwrap();
        let var = frf.plant.variance().unwrap();
        let p = d.len() as f64;
        for (i, _) in lines.iter().enumerate() {
            let v = d.iter().map(|dp| dp[i].norm_sqr()).sum::<f64>() / (p * (p - 1.0));
            assert!(
                (v - var[i]).abs() <= 1e-9 * var[i],
                "line {i}: {v} {}",
                var[i]
            );
            let sum: c64 = d.iter().map(|dp| dp[i]).sum();
            assert!(sum.norm() <= 1e-12 * var[i].sqrt() * p, "line {i}: {sum}");
        }
        // the period DFTs against a naive DFT of period 3 (the fourth of the record), line 5
        let per = PeriodicAnalyzer::new(n)
            .unwrap()
            .period_lines(&[&u], 1.0, &opts, &[5])
            .unwrap();
        let naive: c64 = (0..n)
            .map(|j| {
                let ph = -2.0 * std::f64::consts::PI * 5.0 * j as f64 / n as f64;
                c64::new(ph.cos(), ph.sin()) * u[3 * n + j]
            })
            .sum();
        assert!((per[2][0][0] - naive).norm() < 1e-10 * naive.norm());
        // the plant's noise as a function of the plant value (`plant_noise`): at the estimate
        // it is the reported variance; at another value G it is the periods' sample variance
        // of Y_p − G U_p over P (the mean's) and |Ū|², computed here from the period DFTs
        let (Some(noise), Ok(mut an)) = (frf.plant_noise.as_ref(), PeriodicAnalyzer::new(n)) else {
            panic!("a periodic estimate with variances has its plant noise");
        };
        let per = an
            .period_lines(&[&u, &y], 1.0, &opts, &lines)
            .map_err(|e| e.to_string());
        let Ok(per) = per else { panic!("{per:?}") };
        let m = per.len() as f64;
        for (i, _) in lines.iter().enumerate() {
            let ph = frf.plant.values()[i];
            assert!((noise[i].variance_at(ph) - var[i]).abs() <= 1e-9 * var[i]);
            let g = ph * c64::new(1.3, 0.2);
            let ub = per.iter().map(|x| x[0][i]).sum::<c64>() / m;
            let e: Vec<c64> = per.iter().map(|x| x[1][i] - g * x[0][i]).collect();
            let eb = e.iter().sum::<c64>() / m;
            let naive = e.iter().map(|x| (x - eb).norm_sqr()).sum::<f64>()
                / ((m - 1.0) * m)
                / ub.norm_sqr();
            let v = noise[i].variance_at(g);
            assert!((v - naive).abs() <= 1e-9 * naive, "line {i}: {v} {naive}");
        }
    }

    /// A noisy loop under Welch averaging: `plant_noise` evaluated at the estimate is the plant
    /// variance [`from_welch`] reports, and it grows with |1 + G C| away from it (sensor noise
    /// through the controller: $v(G) \propto |1 + G C|^2$ with $C = 0.4$ here).
    #[test]
    fn welch_plant_noise_is_the_reported_variance_at_the_estimate(
    ) -> std::result::Result<(), Box<dyn std::error::Error>> {
        use crate::frf::welch::{welch_spectra, WelchOptions};
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let len = 8192;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let r: Vec<f64> = (0..len).map(|_| StandardNormal.sample(&mut rng)).collect();
        let (u, y) = loop_with_memory(&r, &mut rng);
        let sp = welch_spectra(&[&r, &u, &y], &WelchOptions::new(1.0, 128))?;
        let frf = from_welch(&sp, Channels { r: 0, u: 1, y: 2 }, (0.01, 0.45), 1e-6, None)?;
        let noise = frf.plant_noise.as_ref().ok_or("no plant noise")?;
        let var = frf.plant.variance().ok_or("no variance")?;
        assert_eq!(noise.len(), var.len());
        for (i, g) in frf.plant.values().iter().enumerate() {
            let v = noise[i].variance_at(*g);
            assert!(
                (v - var[i]).abs() <= 1e-9 * var[i],
                "line {i}: {v} {}",
                var[i]
            );
            // the output-noise part dominates: at G = -1/C the noise would vanish
            let at_pole = noise[i].variance_at(c64::new(-1.0 / 0.4, 0.0));
            assert!(at_pole < 0.05 * v, "line {i}: {at_pole} {v}");
        }
        Ok(())
    }

    #[test]
    fn period_deviations_refuse_bad_input() {
        use crate::frf::periodic::PeriodicOptions;
        let x: Vec<f64> = (0..64).map(|k| ((k * 7) % 5) as f64).collect();
        let ch = Channels { r: 0, u: 0, y: 1 };
        let opts = PeriodicOptions::new(16);
        let bad = |e: Result<Vec<Vec<c64>>>| matches!(e, Err(Error::InvalidArgument { .. }));
        assert!(bad(plant_period_deviations(
            &[&x, &x],
            1.0,
            Channels { r: 0, u: 2, y: 1 },
            &opts,
            &[1]
        )));
        assert!(bad(plant_period_deviations(
            &[&x, &x],
            1.0,
            ch,
            &opts,
            &[0]
        )));
        assert!(bad(plant_period_deviations(&[&x, &x], 1.0, ch, &opts, &[])));
        assert!(bad(plant_period_deviations(
            &[&x, &x],
            1.0,
            ch,
            &opts,
            &[9]
        )));
        // one analysed period
        assert!(bad(plant_period_deviations(
            &[&x, &x],
            1.0,
            ch,
            &opts.skip(3),
            &[1]
        )));
        // a record that is not a whole number of periods
        assert!(bad(plant_period_deviations(
            &[&x[..60], &x[..60]],
            1.0,
            ch,
            &opts,
            &[1]
        )));
        let mut nan = x.clone();
        nan[20] = f64::NAN;
        assert!(matches!(
            plant_period_deviations(&[&x, &nan], 1.0, ch, &opts, &[1]),
            Err(Error::NonFinite { index: 20, .. })
        ));
    }
}
