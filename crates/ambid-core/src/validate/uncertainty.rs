//! How wrong the nominal plant model can be, over frequency: an additive and a multiplicative
//! uncertainty magnitude around a SISO model, built from the data that produced it, term by term.
//!
//! With the measured plant FRF $G_k$ (variance $\sigma_k^2 = E|G_k - P_k|^2$) on the lines
//! $z_k = e^{j\omega_k T}$ and the nominal model $\hat P$, the bound at line $k$ is
//! $$ \Delta_k = q_{1-\alpha}\bigl(\delta\hat P_k + \nu_k\bigr) + b_k + s_k + a_k , \qquad
//!    \ell_k = \Delta_k / |\hat P(z_k)| , $$
//! so that $P = \hat P + \Delta_a$, $|\Delta_a(z_k)| \le \Delta_k$, and
//! $P = \hat P\,(1 + \Delta_m)$, $|\Delta_m(z_k)| \le \ell_k$. Its terms, each kept:
//!
//! * **(a) the FRF's confidence region carried through the fit**, $\delta\hat P_k$: the noise on
//!   the FRF moves the fitted model. To first order, an inverse-variance weighted
//!   frequency-domain fit of $n_\theta$ real parameters $\theta$ has $\operatorname{Cov}\theta
//!   = F^{-1}$, $F = \sum_k 2\operatorname{Re}(J_k^{\mathsf H} J_k)/\sigma_k^2$, $J_k =
//!   \partial \hat P(z_k)/\partial\theta$, and the error $\delta \hat P_k = J_k\,\delta\theta$
//!   has the $2\times 2$ real covariance of $(\operatorname{Re}, \operatorname{Im})\,J_k$ under
//!   $F^{-1}$ — an ellipse, not a circle. That covariance on the lines, $J F^{-1} J^{\mathsf
//!   T}$, is the projection onto the span of the whitened Jacobian: it depends on the *tangent
//!   space* of the model set, not on how the model is parametrised. For the models of order
//!   $n$ with $m$ poles at the origin (pure delays) and the others at the roots of $A_0$,
//!   $\hat P = D + B(z)/(z^m A_0(z))$ with $\deg B \le n - 1$, the tangent space is
//!   $$ \{\, N(z) / (z^m A_0(z)^2) : \deg N \le 2n - m - 1 \,\} \;(+\ \text{constants with a
//!   feed-through}), \qquad n_\theta = 2n - m\ (+1), $$
//!   (the variations $(A_0\,\delta B - B\,\delta A_0)/(z^m A_0^2)$ fill it when $B$ and $A_0$
//!   are coprime; it is the span of the partial fractions $1/(z-p_i)$, $1/(z-p_i)^2$ and
//!   $z^{-j}$ for distinct poles, and stays right for repeated ones). An orthonormal basis of
//!   it in the whitened real inner product comes from real Arnoldi on the multiplication by
//!   $z_k$ — an orthogonal map — started from $\sqrt{2/\sigma_k^2}/(z_k^m A_0(z_k)^2)$, with
//!   two Gram–Schmidt passes per step (the stable construction of polynomials on points, never
//!   the monomials, whose matrix has a condition number of $10^{15}$ for a 7th-order model at
//!   20 kHz on 10–1000 Hz): $J_k R$ with $R R^{\mathsf T} = F^{-1}$ is then
//!   $\sqrt{\sigma_k^2/2}\, q_k$. No eigenvector and no inverse of $F$ is formed, so models
//!   whose eigenvectors are ill-conditioned (clustered poles, companion realisations of
//!   polynomial models) get their term as well as any other.
//!   This is the uncertainty of the *model* (the fit averages the noise of all lines; the
//!   leverage $h_k = \operatorname{Re}(J_k F^{-1} J_k^{\mathsf H})/\sigma_k^2 = \lVert
//!   q_k\rVert^2/2$ sums to $n_\theta/2$), not the much wider confidence circle of each FRF
//!   line.
//! * **(b) the nominal model's error against the FRF**, $b_k$: the misfit $e_k = G_k - \hat
//!   P(z_k)$ averaged over a window of $2M + 1$ lines with weights $1/\sigma_j^2$, $\bar e_k$,
//!   kept by its excess over a significance threshold, $b_k = \sqrt{\max(0, |\bar e_k|^2 -
//!   \ln(1/\alpha_b)\, v_k)}$, $v_k$ its noise variance $\sum_j w_j^2 \sigma_j^2 (1 -
//!   h_j)/(\sum_j w_j)^2$ (under a correct model $|\bar e_k|^2/v_k$ is exponentially
//!   distributed, so $\alpha_b = 0.1\,\%$ of the lines of a correct model get a term, and a
//!   small one; where the FRF's noise is large, 1 % gave runs of lines with terms as large as
//!   the model itself on the nominal twin above 2 kHz): the smooth, systematic part of the misfit that the noise does not explain. A misfit
//!   hidden in the noise cannot be seen and is not bounded: the bound trusts the model's
//!   structure where the data cannot contradict it. $M$ comes from the model: half the half-power bandwidth
//!   $2\zeta f_n$ of its most lightly damped pole in the band, in lines, clamped to $[1, 8]$
//!   (a window never wider than a resonance). **Several scales:** a smooth misfit below the
//!   noise of $2M + 1$ lines is seen over more lines, so the test runs with the half-widths $M,
//!   2M, 4M, \dots$ (at most six, while $2M' + 1 \le L/4$), each at the level $\alpha_b/S$ for
//!   $S$ scales (so a correct model still gets a term on $\alpha_b$ of its lines), and $b_k$ is
//!   the largest excess over the scales. A misfit that changes from line to line is averaged
//!   away by any window; the line alone (half-width 0) is then one more scale, with the
//!   significant misfit's upper value in place of its excess ([`PerLineMisfit`]). By default
//!   ([`PerLineMisfit::Auto`]) it is taken when no term (c) is given and the misfit's
//!   [`misfit_roughness`] (its line-to-line part over the noise, about 1 when the model is
//!   right but for smooth errors) is at least [`ROUGH_MISFIT`] = 4. On real data from one
//!   multisine realisation without a BLA study (the F-16 ground vibration test, whose nonlinear
//!   distortion is a fixed per-line misfit far above the period-to-period noise: roughness
//!   16–92) the windows alone left the bound below a held-out measurement's error on 21–47 % of
//!   the lines (docs/uncertainty.md, "Real data: a held-out measurement", and "The line alone
//!   when the misfit is rough"). (Keeping $M$ at $\alpha_b$ and the wider ones at
//!   $\alpha_b/(S-1)$ gave a term never below the one-window one, but moved the weight of random
//!   rig 167 so that its robust margin fell below half the exact one on both twins.) With one scale, on the 4-axis twin's random rigs at
//!   10 000–27 000 rpm the MIMO model's systematic error of about 0.8 of a line's noise in the
//!   y channels was missed on 6 of 28 rigs (the model's lightly damped poles set $M = 1$). The
//!   raw misfit $|e_k|$ is reported too.
//! * **(c) nonlinear distortion**, $\nu_k$: the standard deviation $\sigma_{\mathrm{nl},k}$ of
//!   the stochastic nonlinear contributions from a robust BLA (given per line), a circular
//!   complex error added to (a) before the quantile.
//! * **(d) operating-point spread**, $s_k$: the largest distance of the plant FRFs measured at
//!   other operating points (bias current, air gap) from the nominal one, given per line.
//! * **(e) amplitude shift**, $a_k$: the systematic part of the nonlinear distortion — the best
//!   linear approximation at the experiment's excitation level moved from its extrapolation to
//!   zero amplitude (the small-signal plant a controller is designed on), given per line
//!   (`ambid::uncertainty::amplitude_term` estimates it from an amplitude study). Term (c) is the
//!   BLA's *stochastic* part and does not hold it; the model fits the BLA, so (a) and (b) do not
//!   see it.
//!
//! $q_{1-\alpha}(x)$ is the $(1-\alpha)$ quantile of $|x|$ for the Gaussian $x$ of covariance
//! $C = \operatorname{cov}(\delta \hat P_k) + \tfrac12\sigma_{\mathrm{nl},k}^2 I$, exact:
//! with $C$'s eigenvalues $\lambda_{1,2}$, $|x|^2 = R^2(\lambda_1\cos^2\phi + \lambda_2 \sin^2
//! \phi)$ with $R^2 \sim \chi^2_2$ and $\phi$ uniform, so
//! $P(|x|^2 > s) = \frac1\pi\int_0^\pi e^{-s / (2 g(\phi))}\,d\phi$ with
//! $g = \lambda_1\cos^2\phi + \lambda_2\sin^2\phi$ (a periodic integrand: the trapezoid rule
//! with 64 nodes is exact to rounding), solved for $s$ by bisection. The shown terms (a) and (c) are the same quantile of
//! each part alone.
//!
//! The default coverage $1 - \alpha$ per line is 95 %.
//!
//! # Term (e) through the model
//! A coherent shift of the BLA can lie far below each line's noise and still move the model,
//! which averages over all lines: on random machine rigs of the nonlinear twin the diagonal
//! entries' BLA sat 0.2–0.4 % below the linearisation over 10–300 Hz, 10–20 times the pooled
//! standard error, while the per-line windows of (e) found nothing above 300 Hz.
//! [`MatrixUncertainty::add_projected_shift`] projects the per-line shift estimates onto the
//! model's tangent space with the fit's weights (the first-order change of the fitted model),
//! tests the projection once per run (a Wald test against $\chi^2_{n_\theta}$) and, where
//! significant, replaces term (a) plus the line term by the quantile of $|\hat s_k + n|$
//! ([`rice_quantile`]: the projected shift $\hat s_k$ as an offset, $n$ circular with term (a)'s
//! variance plus the projection's) when that is larger. A bias and a noise of random phase do
//! not add in magnitude: the sum of the two quantiles made the weights about 1.3× looser on rigs where
//! both were present (docs/uncertainty.md, "Term (e) through the model").
//!
//! # Joint coverage
//! The errors of a fitted model are correlated over the lines (a few parameters move all of
//! them), so a run whose parameters erred by more than usual is uncovered at many lines at once:
//! a per-line 95 % band covers 95 % of the runs at each line, not 95 % of the lines in 95 % of
//! the runs. [`ErrorModel`] draws the whole error curve instead: with $R R^{\mathsf T} = F^{-1}$
//! (from the tangent basis of term (a)) and $\xi \sim N(0, I)$ (seeded
//! `ChaCha8Rng`), $\delta\hat P_k = J_k R\,\xi$, plus a circular draw of the nonlinear term per
//! line and the deterministic $b_k + s_k + a_k$ added in magnitude. For a candidate weight magnitude
//! $m_k$, each draw needs the factor $g_d$ = the $\lceil cL\rceil$-th smallest of
//! $e_{d,k}/m_k$ to be overbounded on the fraction $c$ of the $L$ lines;
//! [`ErrorModel::joint_factor`] returns the `run_coverage` quantile of $g_d$ over the draws. A
//! weight raised by it (when it exceeds 1) overbounds the model's error on $c$ of the lines in
//! that fraction of runs — as far as the first-order error model is right: an error the data do
//! not show (unmodelled dynamics below the noise) is not in it (docs/uncertainty.md gives the
//! measured coverage on random rigs).
//!
//! # Example
//! A second-order model fitted to its own exact response (the FRF's variance is known, there is
//! no misfit): the bound is the model's confidence region alone, small where the lines are many.
//! ```
//! use ambid_core::lti::{Frd, StateSpace};
//! use ambid_core::validate::uncertainty::{uncertainty, ExtraTerms, UncertaintyOptions};
//! use faer::mat;
//! let m = StateSpace::discrete(
//!     mat![[1.6, -0.8], [1.0, 0.0]], mat![[1.0], [0.0]], mat![[0.1, 0.05]], mat![[0.0]], 1e-3,
//! ).unwrap();
//! let f: Vec<f64> = (1..=200).map(|k| k as f64 * 2.0).collect();
//! let exact = Frd::from_model(&m, &f).unwrap();
//! let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr()).collect();
//! let frd = Frd::new(f.clone(), exact.values().to_vec(), Some(var.clone()), Some(1e-3)).unwrap();
//! let u = uncertainty(&m, &frd, &ExtraTerms::default(), &UncertaintyOptions::default()).unwrap();
//! assert!(u.model_error.iter().all(|&b| b == 0.0));
//! // 1 % noise per line, averaged by a 4-parameter fit over 200 lines: well below 1 %
//! let median = { let mut v = u.multiplicative.clone(); v.sort_by(f64::total_cmp); v[100] };
//! assert!(median > 1e-4 && median < 1e-2, "{median}");
//! ```

use crate::error::{Error, Result};
use crate::lti::{Frd, StateSpace};
use faer::c64;

const CTX: &str = "uncertainty";

/// Most windows term (b) tests per line (module docs): $M, 2M, \dots, 2^5 M$.
const BIAS_SCALES: usize = 6;

/// The half-widths of the windows a smooth term is tested over on `lines` lines: $M, 2M, 4M,
/// \dots$ from `m_half` $= M$, at most six of them, each wider one while $2M' + 1 \le L/4$ (the
/// first is always kept). Term (b) tests each at $\alpha_b/S$ for $S$ scales (module docs), as
/// does the amplitude term of `ambid::uncertainty::amplitude_term`.
///
/// ```
/// use ambid_core::validate::uncertainty::window_scales;
/// assert_eq!(window_scales(2, 253), vec![2, 4, 8, 16]); // 2·16 + 1 ≤ 253/4 = 63 < 2·32 + 1
/// assert_eq!(window_scales(3, 20), vec![3]);
/// assert_eq!(window_scales(1, 10_000), vec![1, 2, 4, 8, 16, 32]);
/// ```
pub fn window_scales(m_half: usize, lines: usize) -> Vec<usize> {
    let mut halves = vec![m_half];
    while halves.len() < BIAS_SCALES {
        let next = 2 * halves[halves.len() - 1];
        if 2 * next + 1 > lines / 4 {
            break;
        }
        halves.push(next);
    }
    halves
}

/// Options of [`uncertainty`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UncertaintyOptions {
    /// Coverage $1 - \alpha$ of the Gaussian part per line (default 0.95).
    pub line_coverage: f64,
    /// Level $\alpha_b$ of the significance test of the misfit (default 0.001).
    pub bias_alpha: f64,
    /// The fraction of the error model's draws in which a weight must overbound the model's
    /// error on the fraction [`Self::raise_cover`] of the band ([`ErrorModel::joint_factor`],
    /// default [`DEFAULT_RUN_COVERAGE`]).
    pub run_coverage: f64,
    /// The fraction of the lines on which the raised weight must overbound each of those draws
    /// (default [`DEFAULT_RAISE_COVER`]).
    pub raise_cover: f64,
    /// Draws of the model's error for that check (default 2 000).
    pub draws: usize,
    /// Seed of the draws (`ChaCha8Rng`, default 0).
    pub seed: u64,
    /// The family of the fitted weight (default
    /// [`WeightShape::ModeShaped`](crate::validate::weight::WeightShape::ModeShaped), which also
    /// tries the smooth family's starts and keeps the tighter weight; docs/uncertainty.md,
    /// "Mode-shaped weights" and "The mode-shaped weight as the single-axis default", gives
    /// what each holds on random rigs).
    pub weight_shape: super::weight::WeightShape,
    /// The band $[f_a, f_b]$ \[Hz\] the nominal model was fitted on, when the FRF reaches beyond
    /// it (default `None`: every line was fitted). Lines outside it are *validation* lines:
    /// the parameter covariance of term (a) comes from the fitted lines alone, a validation
    /// line's $J_k R$ is the tangent map evaluated there, and its residual's noise variance in
    /// term (b) is $\sigma_k^2(1 + h_k)$ (the model's prediction variance adds to the line's)
    /// instead of a fitted line's $\sigma_k^2(1 - h_k)$. The bound then rests on the measured
    /// misfit where the model was not fitted, not on an extrapolation (docs/uncertainty.md,
    /// "Lines beyond the fit band"). Any model goes through the joint tangent space of
    /// [`uncertainty_matrix`] then, a SISO one as its 1×1 case.
    pub fitted_band_hz: Option<[f64; 2]>,
    /// Whether term (b) also tests each line alone ([`PerLineMisfit`]; default
    /// [`PerLineMisfit::Auto`]: when the misfit is rough from line to line and no term (c) is
    /// given).
    pub per_line_misfit: PerLineMisfit,
    /// Whether terms (a) and (b) allow for noise correlated between neighbouring lines
    /// ([`CorrelatedLines`]; default [`CorrelatedLines::Auto`]: when the misfit shows it).
    pub correlated_lines: CorrelatedLines,
    /// Whether the bound adds term (f), the nominal model's distance from the FRF's own fit of
    /// its order ([`fit_distance`]; default `true`). Zero when the nominal model is that fit;
    /// for a model of another structure or estimator (an output-error polynomial, a time-domain
    /// fit) or with other weights it is what terms (a) and (b) cannot see. Only for a SISO
    /// model in its own tangent space (no [`Self::fitted_band_hz`]); the MIMO entries have no
    /// term (f).
    pub fit_distance: bool,
}

/// Noise correlated between neighbouring lines ([`UncertaintyOptions::correlated_lines`];
/// module docs, "Correlated lines").
///
/// A Welch FRF's lines are not independent: a Hann window's neighbouring DFT lines correlate
/// with $-2/3$, so the excitation's and the noise's do, and the FRF's errors on neighbouring
/// lines correlate with about $(2/3)^2 = 0.44$. Each line's variance is right, but a fit
/// averages over many lines, and the variance of an average of correlated errors is
/// $\kappa = 1 + 2\sum_l \rho_l$ times that of independent ones. On linear twin rigs 1–12 the
/// bound on a Welch FRF that took the lines as independent covered the true error on 37–95 % of
/// the 10–1000 Hz lines and its weight on ≥ 95 % in 9 of 12 runs (docs/uncertainty.md, "Welch
/// FRFs: correlated lines").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CorrelatedLines {
    /// The lines are taken as independent (the behaviour before 2026-12-06).
    Off,
    /// The factor [`LineCorrelation::factor`] of the misfit's lag correlations is applied
    /// when they show a short-range correlation ([`line_correlation`]).
    #[default]
    Auto,
}

impl CorrelatedLines {
    /// Parses `auto` or `off`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for any other name.
    pub fn from_name(s: &str) -> Result<Self> {
        match s {
            "auto" => Ok(Self::Auto),
            "off" => Ok(Self::Off),
            other => Err(Error::invalid(
                "correlated_lines",
                format!("`{other}` is not one of auto, off"),
            )),
        }
    }

    /// The name [`Self::from_name`] reads.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Off => "off",
        }
    }
}

/// The significance, in standard errors under independent lines, at which [`line_correlation`]
/// takes the misfit's lag-1 correlation as real: $\hat\rho_1 \sqrt{2L} > 3$ (one-sided level
/// 0.13 %).
pub const CORRELATED_LINES_Z: f64 = 3.0;

/// The lag correlations of an FRF's noise between neighbouring lines, as its normalised misfit
/// shows them ([`line_correlation`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineCorrelation {
    /// $\hat\rho_1$, the lag-1 correlation.
    pub rho1: f64,
    /// $\hat\rho_2$, the lag-2 correlation.
    pub rho2: f64,
    /// The lines it was estimated on (all entries).
    pub lines: usize,
    /// $\hat\rho_1\sqrt{2L}$: the lag-1 correlation in standard errors under independence.
    pub z: f64,
    /// The variance factor $\kappa \ge 1$ terms (a) and (b) were computed with:
    /// $1 + 2(\hat\rho_1 + \hat\rho_2)$ when the correlation is significant
    /// ([`CORRELATED_LINES_Z`]) and short (it has died out by lag 2: $\hat\rho_2 < \hat\rho_1 /
    /// 2$), else 1.
    pub factor: f64,
}

impl LineCorrelation {
    /// Independent lines: no correlation, factor 1.
    pub fn independent(lines: usize) -> Self {
        Self {
            rho1: 0.0,
            rho2: 0.0,
            lines,
            z: 0.0,
            factor: 1.0,
        }
    }
}

/// The lag-1 and lag-2 correlations of the normalised misfits $m_k = e_k/\sigma_k$ of one or more
/// FRF entries (each `(misfit, variance)` a sequence of lines; pooled over the entries, lags
/// within each), and the variance factor they imply:
/// $$ \hat\rho_l = \frac{\operatorname{Re} \sum_k \overline{m_k}\, m_{k+l}}{\sum_k |m_k|^2},
///    \qquad \kappa = \begin{cases} 1 + 2(\hat\rho_1 + \hat\rho_2) &
///    \hat\rho_1\sqrt{2L} > 3 \text{ and } \hat\rho_2 < \hat\rho_1/2 \\ 1 & \text{otherwise.}
///    \end{cases} $$
/// Under independent circular lines $\hat\rho_1$ has the standard error $1/\sqrt{2L}$. The
/// factor is the long-run variance of a short-range correlated sequence over its per-line
/// variance: what the variance of a fit's average over many lines is multiplied by. A
/// correlation that has not died out by lag 2 (an FRF smooth over many lines, such as a Local
/// Polynomial Method's) is not short-range; the factor stays 1 there and
/// [`misfit_roughness`] below [`SMOOTH_MISFIT`] says so. A smooth systematic misfit adds to
/// both correlations alike: where it dominates, the gate keeps the factor at 1 (the Silverbox's
/// BLA: $\hat\rho_1 = \hat\rho_2 = 0.80$, docs/uncertainty.md); where it is below the noise it
/// makes the factor larger than the noise's, the bound wider. `None` with fewer than 3 lines in
/// all or a non-positive variance.
///
/// # Example
/// Independent lines give factor 1; a moving average $x_k = a\,w_k + b\,w_{k-1}$ with $ab = 0.4$
/// gives about $1 + 2 \cdot 0.4 = 1.8$.
/// ```
/// use ambid_core::c64;
/// use ambid_core::validate::uncertainty::line_correlation;
/// use rand::{RngExt, SeedableRng};
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
/// let mut gauss = || {
///     let u: f64 = rng.random_range(1e-300..1.0);
///     let phase: f64 = rng.random_range(0.0..2.0 * std::f64::consts::PI);
///     c64::from_polar((-u.ln()).sqrt(), phase)
/// };
/// let w: Vec<c64> = (0..2001).map(|_| gauss()).collect();
/// let var = vec![1.0; 2000];
/// let c = line_correlation(&[(&w[1..], &var[..])]).unwrap();
/// assert_eq!(c.factor, 1.0);
/// let b = 0.5f64; // a² + b² = 1, ab = 0.433
/// let a = (1.0 - b * b).sqrt();
/// let ma: Vec<c64> = (1..2001).map(|k| w[k] * a + w[k - 1] * b).collect();
/// let c = line_correlation(&[(&ma[..], &var[..])]).unwrap();
/// assert!((c.rho1 - a * b).abs() < 0.06, "{}", c.rho1);
/// assert!((c.factor - (1.0 + 2.0 * a * b)).abs() < 0.2, "{}", c.factor);
/// ```
pub fn line_correlation(entries: &[(&[c64], &[f64])]) -> Option<LineCorrelation> {
    let (mut s0, mut s1, mut s2, mut lines) = (0.0, 0.0, 0.0, 0usize);
    for (misfit, var) in entries {
        if var.len() != misfit.len() || var.iter().any(|v| !(*v > 0.0 && v.is_finite())) {
            return None;
        }
        let m: Vec<c64> = misfit.iter().zip(*var).map(|(e, v)| e / v.sqrt()).collect();
        s0 += m.iter().map(|x| x.norm_sqr()).sum::<f64>();
        s1 += m.windows(2).map(|w| (w[0].conj() * w[1]).re).sum::<f64>();
        s2 += m.windows(3).map(|w| (w[0].conj() * w[2]).re).sum::<f64>();
        lines += m.len();
    }
    if lines < 3 || !(s0 > 0.0 && s0.is_finite()) {
        return None;
    }
    let (rho1, rho2) = (s1 / s0, s2 / s0);
    let z = rho1 * (2.0 * lines as f64).sqrt();
    let factor = if z > CORRELATED_LINES_Z && rho2 < rho1 / 2.0 {
        (1.0 + 2.0 * (rho1 + rho2)).max(1.0)
    } else {
        1.0
    };
    Some(LineCorrelation {
        rho1,
        rho2,
        lines,
        z,
        factor,
    })
}

/// The line correlation of `frd`'s noise as the misfit of `nominal` shows it on the lines
/// `fitted` marks (the entries pooled, [`line_correlation`]), leaving out an entry whose misfit
/// is rough ([`misfit_roughness`] ≥ [`ROUGH_MISFIT`]: a per-line systematic error, whose
/// correlation is not the noise's); independent lines when `opts.correlated_lines` is off or
/// it cannot be computed.
fn line_correlation_of(
    nominal: &StateSpace,
    frd: &Frd,
    fitted: Option<[f64; 2]>,
    opts: &UncertaintyOptions,
) -> Result<LineCorrelation> {
    let l = frd.len();
    if opts.correlated_lines == CorrelatedLines::Off {
        return Ok(LineCorrelation::independent(l));
    }
    let keep: Vec<usize> = match fitted {
        Some([a, b]) => (0..l)
            .filter(|&k| (a..=b).contains(&frd.f_hz()[k]))
            .collect(),
        None => (0..l).collect(),
    };
    let f: Vec<f64> = keep.iter().map(|&k| frd.f_hz()[k]).collect();
    let mut seqs = Vec::with_capacity(frd.ny() * frd.nu());
    for j in 0..frd.nu() {
        for i in 0..frd.ny() {
            let e = frd.entry(i, j)?;
            let Some(var) = e.variance() else {
                return Ok(LineCorrelation::independent(l));
            };
            let p = nominal.entry(i, j)?.freq_response_siso(&f)?;
            let m: Vec<c64> = keep
                .iter()
                .zip(&p)
                .map(|(&k, pk)| e.values()[k] - pk)
                .collect();
            let v: Vec<f64> = keep.iter().map(|&k| var[k]).collect();
            if noise_like(misfit_roughness(&m, &v)) {
                seqs.push((m, v));
            }
        }
    }
    let refs: Vec<(&[c64], &[f64])> = seqs.iter().map(|(m, v)| (&m[..], &v[..])).collect();
    Ok(line_correlation(&refs).unwrap_or(LineCorrelation::independent(l)))
}

/// Whether a misfit of this [`misfit_roughness`] can tell the noise's correlation: a rough one
/// (≥ [`ROUGH_MISFIT`]) is a per-line systematic error (one realisation's distortion), whose
/// correlations say nothing about the noise's.
fn noise_like(roughness: Option<f64>) -> bool {
    !roughness.is_some_and(|r| r >= ROUGH_MISFIT)
}

/// [`line_correlation_of`] for one SISO channel from its misfit, variances and roughness,
/// already computed.
fn channel_correlation(
    misfit: &[c64],
    var: &[f64],
    roughness: Option<f64>,
    opts: &UncertaintyOptions,
) -> LineCorrelation {
    let independent = LineCorrelation::independent(misfit.len());
    if opts.correlated_lines == CorrelatedLines::Off || !noise_like(roughness) {
        return independent;
    }
    line_correlation(&[(misfit, var)]).unwrap_or(independent)
}

/// `frd` with every variance multiplied by `factor` (the FRF itself when it is 1).
fn with_variance_factor(frd: &Frd, factor: f64) -> Result<std::borrow::Cow<'_, Frd>> {
    if factor == 1.0 {
        return Ok(std::borrow::Cow::Borrowed(frd));
    }
    let var = positive_variances(frd)?
        .iter()
        .map(|v| v * factor)
        .collect();
    Ok(std::borrow::Cow::Owned(Frd::new_matrix(
        frd.f_hz().to_vec(),
        frd.ny(),
        frd.nu(),
        frd.values().to_vec(),
        Some(var),
        frd.ts(),
    )?))
}

/// Term (b)'s line-alone scale ([`UncertaintyOptions::per_line_misfit`]; module docs, term (b)).
///
/// With it, term (b) also tests each line alone (half-width 0) besides its windows, and a
/// significant misfit enters as its upper value at the line coverage (the Rice quantile of its
/// magnitude, [`rice_quantile`]) instead of its excess over the test's threshold. It is for an
/// FRF from one multisine realisation without a BLA study (no term (c)): that realisation's
/// nonlinear distortion is a fixed per-line misfit, far above the noise of the periods, which
/// every window averages away. On the F-16 ground vibration test the bound without it stayed
/// below a held-out measurement's error on 21–47 % of the lines, with it on at most 0.4 %
/// (docs/uncertainty.md, "Real data: a held-out measurement").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PerLineMisfit {
    /// Never (the windows alone, the behaviour before 2026-12-06).
    Off,
    /// Always.
    On,
    /// When no term (c) is given and the misfit's [`misfit_roughness`] is at least
    /// [`ROUGH_MISFIT`]: a misfit whose line-to-line part stands clearly above the noise. On
    /// 564 bounds of the twin's random rigs (single-axis and 4×4 entries, both twins) the
    /// roughness was 0.72–1.45, so it was never taken there; on the F-16 ground vibration test
    /// 16–92, where it is; on the Silverbox's BLA from ten realisations (a smooth misfit, the
    /// distortion a noise over realisations) 1.09 and 1.11, where it is not and the bound still
    /// covers a held-out BLA (docs/uncertainty.md, "The line alone when the misfit is rough",
    /// "A second real record: the Silverbox's BLA").
    #[default]
    Auto,
}

impl PerLineMisfit {
    /// `auto`, `on` or `off`.
    ///
    /// # Errors
    /// Any other name.
    pub fn from_name(s: &str) -> Result<Self> {
        match s {
            "auto" => Ok(Self::Auto),
            "on" => Ok(Self::On),
            "off" => Ok(Self::Off),
            _ => Err(Error::invalid(
                "per_line_misfit",
                format!("`{s}`: give `auto`, `on` or `off`"),
            )),
        }
    }

    /// The name [`Self::from_name`] reads.
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::On => "on",
            Self::Auto => "auto",
        }
    }
}

/// The roughness of the misfit at which [`PerLineMisfit::Auto`] turns the line-alone scale on:
/// the misfit's line-to-line part is twice the noise in amplitude at the median line. Under a
/// model that is right but for smooth errors the roughness is about 1 (with variances estimated
/// from $P$ periods it is the median of an $F(2, 2(P-1))$ variable over $\ln 2$: 1.44 for two
/// periods, 1.13 for four), so 4 is not reached by noise.
pub const ROUGH_MISFIT: f64 = 4.0;

/// The roughness below which the misfit is far smoother from line to line than the FRF's
/// variances say, as much below the noise's 1 as [`ROUGH_MISFIT`] is above it: the FRF's lines
/// are then not independent (a Local Polynomial Method's FRF is a fit over a window of lines:
/// 0.01 on the linear twin with its window of 91 lines) or its variances are too large. Terms
/// (a) and (b) take the lines as independent, so `ambid uncertainty` warns (docs/uncertainty.md,
/// "The line alone when the misfit is rough"). On the twin's periodic FRFs the roughness was
/// 0.72–1.45 (564 bounds), on the Silverbox's BLA 1.09–1.11.
pub const SMOOTH_MISFIT: f64 = 0.25;

/// How rough the misfit $e_k = G_k - \hat P(z_k)$ is from line to line, against the FRF's
/// noise: per line $k$ with three lines on each side, the residual $r_k$ of a complex quadratic
/// in the line index fitted (unweighted) to $e_{k-3}, \dots, e_{k+3}$, at the centre line,
/// $$ r_k = \sum_{j=-3}^{3} c_j\, e_{k+j}, \qquad
///    c_j = \delta_{j0} - \Bigl(\tfrac17 - \tfrac{4\,(j^2 - 4)}{84}\Bigr), $$
/// normalised by its noise variance $V_k = \sum_j c_j^2 \sigma_{k+j}^2$; the roughness is
/// $\operatorname{median}_k |r_k|^2 / V_k$ over $\ln 2$. A smooth model error (anything a
/// quadratic follows over seven lines) is removed, so under noise alone $|r_k|^2/V_k$ is
/// exponential and the roughness about 1; one multisine realisation's nonlinear distortion, a
/// fixed error that changes from line to line, makes it the distortion's power over the noise's
/// (F-16: 16–170). The median keeps a few sharp features (a resonance narrower than the window)
/// from deciding it. `None` with fewer than 7 lines or a zero variance.
///
/// # Example
/// Noise alone gives about 1; the same noise plus a fixed per-line error of five times its
/// standard deviation gives about 25 and more.
/// ```
/// use ambid_core::c64;
/// use ambid_core::validate::uncertainty::misfit_roughness;
/// use rand::{RngExt, SeedableRng};
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
/// let mut gauss = || {
///     // one circular complex normal of unit variance: exponential power, uniform phase
///     let u: f64 = rng.random_range(1e-300..1.0);
///     let phase: f64 = rng.random_range(0.0..2.0 * std::f64::consts::PI);
///     c64::from_polar((-u.ln()).sqrt(), phase)
/// };
/// let noise: Vec<c64> = (0..400).map(|_| gauss()).collect();
/// let var = vec![1.0; 400];
/// let r0 = misfit_roughness(&noise, &var).unwrap();
/// assert!((0.8..1.25).contains(&r0), "{r0}");
/// let rough: Vec<c64> = noise.iter().map(|n| n + gauss() * 5.0).collect();
/// assert!(misfit_roughness(&rough, &var).unwrap() > 15.0);
/// ```
pub fn misfit_roughness(misfit: &[c64], var: &[f64]) -> Option<f64> {
    const H: usize = 3;
    let l = misfit.len();
    if l < 2 * H + 1 || var.len() != l || var.iter().any(|v| !(*v > 0.0 && v.is_finite())) {
        return None;
    }
    // the centre row of the quadratic's hat matrix on -3..3: 1/7 + (0 - 4)(j² - 4)/84
    let c: Vec<f64> = (-(H as i64)..=H as i64)
        .map(|j| {
            let x2 = (j * j) as f64;
            f64::from(u8::from(j == 0)) - (1.0 / 7.0 - 4.0 * (x2 - 4.0) / 84.0)
        })
        .collect();
    let mut z: Vec<f64> = (H..l - H)
        .map(|k| {
            let (mut r, mut v) = (c64::new(0.0, 0.0), 0.0);
            for (i, cj) in c.iter().enumerate() {
                r += misfit[k + i - H] * *cj;
                v += cj * cj * var[k + i - H];
            }
            r.norm_sqr() / v
        })
        .collect();
    Some(crate::data::outliers::median_in_place(&mut z) / std::f64::consts::LN_2)
}

/// The default fraction of the first-order error model's draws a single-axis weight is raised
/// to overbound ([`UncertaintyOptions::run_coverage`]; module docs, "Joint coverage"). The
/// coverage bar asks for 95 % of the runs, but the draws are narrower than the true error: on
/// random rigs the true error's 95 % quantile over the lines is about 1.2× the draws' median
/// (docs/uncertainty.md, "Mode-shaped weights"; the variances the fit weighs by are estimates).
/// A weight that follows the bound (the mode-shaped default) then covers the true error in
/// fewer runs than the draws say; the 99 % quantile of the draws makes up for that
/// (docs/uncertainty.md, "The mode-shaped weight as the single-axis default", gives the sweeps).
/// The MIMO entry weights keep 0.95 (their element-wise raise was measured with it).
pub const DEFAULT_RUN_COVERAGE: f64 = 0.99;

/// The default fraction of the lines a single-axis weight is raised to overbound in each of
/// [`DEFAULT_RUN_COVERAGE`] of the error model's draws ([`UncertaintyOptions::raise_cover`]):
/// the coverage bar's 95 % of the lines. Until 2026-12-04 the raise used the weight fit's own
/// fraction, 98 % ([`DEFAULT_COVER`](super::weight::DEFAULT_COVER)), a stricter target than
/// the bar's; with 95 % the weight is 5–6 % tighter at the median on random rigs and still
/// covers the true error on ≥ 95 % of the lines in ≥ 95 % of the runs (docs/uncertainty.md,
/// "The raise at the bar's 95 % of the lines").
pub const DEFAULT_RAISE_COVER: f64 = 0.95;

impl Default for UncertaintyOptions {
    fn default() -> Self {
        Self {
            line_coverage: 0.95,
            bias_alpha: 0.001,
            run_coverage: DEFAULT_RUN_COVERAGE,
            raise_cover: DEFAULT_RAISE_COVER,
            draws: 2000,
            seed: 0,
            weight_shape: super::weight::WeightShape::ModeShaped,
            fitted_band_hz: None,
            per_line_misfit: PerLineMisfit::Auto,
            correlated_lines: CorrelatedLines::Auto,
            fit_distance: true,
        }
    }
}

/// Term (b) with its phase, for [`MatrixUncertainty::coherent_draws`]: per line the centre
/// $c_k$ and the radius $r_k$ of a disc that holds the model-set error term (b) stands for.
///
/// Term (b) is $b_k = \sqrt{(|\bar e|^2 - t v)_+}$ of the window that gave the largest value,
/// with $\bar e$ the window's weighted mean misfit, $v$ its variance and $t$ the test's
/// threshold (module docs). The misfit's noise part moves $\bar e$ by a circular error of
/// variance $v$, at most $\sqrt{t v}$ at the test's level, so the windowed systematic misfit
/// lies within the angle $\delta_k = \arcsin\rho_k$, $\rho_k = \sqrt{t v}/|\bar e|$ ($< 1$
/// where $b_k > 0$), of $\bar e$'s phase. The centre takes term (b)'s modulus at that phase,
/// $c_k = b_k\,\bar e/|\bar e|$, and the radius is the chord of that angle,
/// $r_k = 2 b_k \sin(\delta_k / 2)$. Where the chord is not shorter than $b_k$ ($\delta_k \ge
/// 60°$: a misfit just past the test's edge) the phase says nothing useful and the free phase is
/// kept: $c_k = 0$, $r_k = b_k$. The modulus is term (b)'s in both cases.
fn coherent_bias(bias: &[f64], at_max: &[(c64, f64)], thr: f64) -> (Vec<c64>, Vec<f64>) {
    bias.iter()
        .zip(at_max)
        .map(|(&b, &(mean, v))| {
            let m = mean.norm();
            if b <= 0.0 || m <= 0.0 {
                return (c64::new(0.0, 0.0), b);
            }
            let rho = ((thr * v).sqrt() / m).min(1.0);
            let chord = 2.0 * b * (0.5 * rho.asin()).sin();
            if chord < b {
                (mean * (b / m), chord)
            } else {
                (c64::new(0.0, 0.0), b)
            }
        })
        .unzip()
}

/// The terms (c), (d) and (e) of the module docs, per line of the FRF (absolute, plant units).
#[derive(Debug, Clone, Copy, Default)]
pub struct ExtraTerms<'a> {
    /// $\sigma_{\mathrm{nl},k}$: the nonlinear distortion's standard deviation (robust BLA).
    pub nonlinear_std: Option<&'a [f64]>,
    /// $s_k$: the operating-point study's largest distance from the nominal plant.
    pub operating_spread: Option<&'a [f64]>,
    /// $a_k$: the amplitude study's systematic shift of the best linear approximation at the
    /// experiment's level from its extrapolation to zero amplitude (term (e)).
    pub amplitude_shift: Option<&'a [f64]>,
    /// The FRF's noise per line as a function of the plant value (e.g. the
    /// [`plant_noise`](crate::frf::closed_loop::ClosedLoopFrf::plant_noise) of the FRF's
    /// estimate on its lines). With it, term (f)'s reference $\tilde P$ is the FRF's sample
    /// maximum-likelihood fit ([`FreqWeights::SampleMaximumLikelihood`](crate::estimate::freqfit::FreqWeights::SampleMaximumLikelihood))
    /// instead of its inverse-variance one: the fit a nominal model fitted with those weights
    /// is, so that term (f) is 0 for it and does not measure the inverse-variance fit's pull
    /// (docs/uncertainty.md, "Weights that follow the data's noise").
    pub fit_noise: Option<&'a [crate::frf::closed_loop::RatioNoise]>,
}

/// The uncertainty of a nominal model over the FRF's lines (module docs). Absolute terms are in
/// the plant's units; `multiplicative` is `additive / |nominal|`.
#[derive(Debug, Clone, PartialEq)]
pub struct UncertaintyTerms {
    /// Frequencies \[Hz\].
    pub f_hz: Vec<f64>,
    /// The nominal model $\hat P(z_k)$.
    pub nominal: Vec<c64>,
    /// The measured FRF $G_k$.
    pub measured: Vec<c64>,
    /// $|G_k - \hat P(z_k)|$, the raw misfit (shown, not part of the bound).
    pub misfit: Vec<f64>,
    /// (a) The quantile of the model's error from the FRF's noise alone.
    pub frf_confidence: Vec<f64>,
    /// (b) The significant smoothed misfit $b_k$ (0 where not significant).
    pub model_error: Vec<f64>,
    /// (c) The quantile of the nonlinear distortion alone, when given.
    pub nonlinear: Option<Vec<f64>>,
    /// (d) The operating-point spread, when given.
    pub operating: Option<Vec<f64>>,
    /// (e) The amplitude shift, when given.
    pub amplitude: Option<Vec<f64>>,
    /// (f) The nominal model's distance from the FRF's own fit of its order, $|\hat P_k -
    /// \tilde P_k|$ ([`fit_distance`]), when [`UncertaintyOptions::fit_distance`] is on and that
    /// fit succeeded.
    pub fit_distance: Option<Vec<f64>>,
    /// Why term (f) is absent although asked for (the FRF's own fit failed), if so.
    pub fit_distance_failed: Option<String>,
    /// $\Delta_k$: the additive bound.
    pub additive: Vec<f64>,
    /// $\ell_k = \Delta_k / |\hat P(z_k)|$: the multiplicative bound.
    pub multiplicative: Vec<f64>,
    /// Half-width $M$ of the misfit's window \[lines\].
    pub window_half_lines: usize,
    /// Real parameters $n_\theta$ of the model (its tangent space's dimension, module docs).
    pub n_params: usize,
    /// The coverage per line used.
    pub line_coverage: f64,
    /// The misfit's [`misfit_roughness`] (`None` with fewer than 7 lines).
    pub misfit_roughness: Option<f64>,
    /// Whether term (b) tested each line alone ([`PerLineMisfit`], resolved).
    pub per_line_misfit: bool,
    /// The correlation of the FRF's noise between neighbouring lines and the variance factor
    /// terms (a) and (b) were computed with ([`CorrelatedLines`]).
    pub line_correlation: LineCorrelation,
    /// The model's error as a random function of frequency, for coverage over the lines
    /// jointly ([`ErrorModel`]).
    pub errors: ErrorModel,
}

impl UncertaintyTerms {
    /// The median over the lines of term (d) relative to $|\hat P|$, when the term is present.
    pub fn operating_median_rel(&self) -> Option<f64> {
        self.median_rel(self.operating.as_deref()?)
    }

    /// The median over the lines of term (c) (its quantile) relative to $|\hat P|$, when the
    /// term is present.
    pub fn nonlinear_median_rel(&self) -> Option<f64> {
        self.median_rel(self.nonlinear.as_deref()?)
    }

    /// The median over the lines of term (e) relative to $|\hat P|$, when the term is present.
    pub fn amplitude_median_rel(&self) -> Option<f64> {
        self.median_rel(self.amplitude.as_deref()?)
    }

    /// The median over the lines of term (f) relative to $|\hat P|$, when the term is present.
    pub fn fit_distance_median_rel(&self) -> Option<f64> {
        self.median_rel(self.fit_distance.as_deref()?)
    }

    fn median_rel(&self, term: &[f64]) -> Option<f64> {
        let mut rel: Vec<f64> = term
            .iter()
            .zip(&self.nominal)
            .map(|(x, p)| x / p.norm().max(f64::MIN_POSITIVE))
            .collect();
        rel.sort_by(f64::total_cmp);
        rel.get(rel.len() / 2).copied()
    }
}

/// The nominal model's error over all lines at once (module docs, "Joint coverage"): to first
/// order $\delta\hat P_k = J_k R\,\xi$ with $R R^{\mathsf T} = F^{-1}$ and $\xi \sim
/// N(0, I)$, plus the nonlinear distortion (independent per line, circular, of standard deviation
/// $\sigma_{\mathrm{nl},k}$) and the deterministic terms $b_k + s_k + a_k$ added in magnitude. The
/// default has no lines (terms built by hand, e.g. for an export).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ErrorModel {
    /// Per line, the $n_\theta$ complex entries of $J_k R$.
    sens: Vec<Vec<c64>>,
    nonlinear_std: Option<Vec<f64>>,
    fixed: Vec<f64>,
    /// Term (b) at the windowed misfit's phase, $c_k$ (0 where its phase is not known;
    /// `coherent_bias`).
    bias_center: Vec<c64>,
    /// The bound $r_k$ of term (b)'s error about $c_k$ ($b_k$ where the phase is not known).
    bias_spread: Vec<f64>,
    nominal_abs: Vec<f64>,
}

impl ErrorModel {
    /// Number of lines.
    pub fn lines(&self) -> usize {
        self.sens.len()
    }

    /// One draw of the relative error $(|\delta\hat P_k + \nu_k| + b_k + s_k + a_k)/|\hat P_k|$ at every line,
    /// written to `out`.
    pub fn draw_relative<R: rand::Rng>(&self, rng: &mut R, out: &mut Vec<f64>) {
        use rand_distr::{Distribution, StandardNormal};
        let n = self.sens.first().map_or(0, Vec::len);
        let xi: Vec<f64> = (0..n).map(|_| StandardNormal.sample(rng)).collect();
        out.clear();
        for k in 0..self.sens.len() {
            out.push(self.line_error(k, &xi, rng) / self.nominal_abs[k]);
        }
    }

    /// The absolute error $|J_k R\,\xi + \nu_k| + b_k + s_k + a_k$ at line `k` for the
    /// parameter draw `xi`, with the line's nonlinear draw from `rng` (when the term is present).
    fn line_error<R: rand::Rng>(&self, k: usize, xi: &[f64], rng: &mut R) -> f64 {
        self.line_random(k, xi, rng).norm() + self.fixed[k]
    }

    /// The random part $J_k R\,\xi + \nu_k$ of the error at line `k` (complex), with the
    /// line's nonlinear draw from `rng` (when the term is present).
    fn line_random<R: rand::Rng>(&self, k: usize, xi: &[f64], rng: &mut R) -> c64 {
        use rand_distr::{Distribution, StandardNormal};
        let mut e = self.sens[k]
            .iter()
            .zip(xi)
            .fold(c64::new(0.0, 0.0), |acc, (a, x)| acc + a * *x);
        if let Some(s) = &self.nonlinear_std {
            let h = s[k] * std::f64::consts::FRAC_1_SQRT_2;
            let (re, im): (f64, f64) = (StandardNormal.sample(rng), StandardNormal.sample(rng));
            e += c64::new(h * re, h * im);
        }
        e
    }

    /// The smallest factor $g$ such that $g\,m_k$ overbounds a draw of the relative error on at
    /// least the fraction `cover` of the lines in the fraction `run_coverage` of `draws` seeded
    /// draws (module docs, "Joint coverage").
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a length that differs from the lines, a non-positive or
    /// non-finite $m_k$, fractions outside (0, 1], or no draws.
    pub fn joint_factor(
        &self,
        magnitude: &[f64],
        cover: f64,
        run_coverage: f64,
        draws: usize,
        seed: u64,
    ) -> Result<f64> {
        Ok(self.joint_factors(&[magnitude], cover, run_coverage, draws, seed)?[0])
    }

    /// [`ErrorModel::joint_factor`] of several magnitudes from one set of draws (each factor
    /// equals the one a separate call with the same seed gives).
    ///
    /// # Errors
    /// As [`ErrorModel::joint_factor`], for any of the magnitudes.
    pub fn joint_factors(
        &self,
        magnitudes: &[&[f64]],
        cover: f64,
        run_coverage: f64,
        draws: usize,
        seed: u64,
    ) -> Result<Vec<f64>> {
        use rand::SeedableRng;
        let l = self.lines();
        for magnitude in magnitudes {
            if magnitude.len() != l {
                return Err(Error::invalid(
                    "magnitude",
                    format!("needs one value per line ({l}), got {}", magnitude.len()),
                ));
            }
            if magnitude.iter().any(|v| !(*v > 0.0 && v.is_finite())) {
                return Err(Error::invalid(
                    "magnitude",
                    "every magnitude must be positive and finite",
                ));
            }
        }
        for (name, v) in [("cover", cover), ("run_coverage", run_coverage)] {
            if !(v > 0.0 && v <= 1.0) {
                return Err(Error::invalid(name, format!("must lie in (0, 1], got {v}")));
            }
        }
        if draws == 0 {
            return Err(Error::invalid("draws", "needs at least one draw"));
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut e = Vec::with_capacity(l);
        let mut need: Vec<Vec<f64>> = vec![Vec::with_capacity(draws); magnitudes.len()];
        let mut ratio = vec![0.0; l];
        // the k-th smallest need ratio covers k of the l lines
        let at = ((cover * l as f64).ceil() as usize).clamp(1, l) - 1;
        for _ in 0..draws {
            self.draw_relative(&mut rng, &mut e);
            for (magnitude, need) in magnitudes.iter().zip(&mut need) {
                for k in 0..l {
                    ratio[k] = e[k] / magnitude[k];
                }
                ratio.sort_by(f64::total_cmp);
                need.push(ratio[at]);
            }
        }
        let i = ((run_coverage * draws as f64).ceil() as usize).clamp(1, draws) - 1;
        Ok(need
            .into_iter()
            .map(|mut n| {
                n.sort_by(f64::total_cmp);
                n[i]
            })
            .collect())
    }
}

/// The uncertainty of the SISO `nominal` model around the measured plant FRF `frd` (which must
/// carry variances), with the optional terms (c) and (d) (module docs).
///
/// # Errors
/// [`Error::InvalidArgument`] for a MIMO or continuous FRF, one without variances or with a
/// non-positive one, fewer lines than parameters, a model of another sample time or that is not
/// SISO, extra terms of the wrong length or with non-finite values, or coverage levels outside
/// (0, 1); [`Error::Numerical`] when the model's poles cannot be computed, a pole lies on a
/// line, or the lines do not determine $n_\theta$ independent directions.
pub fn uncertainty(
    nominal: &StateSpace,
    frd: &Frd,
    extra: &ExtraTerms<'_>,
    opts: &UncertaintyOptions,
) -> Result<UncertaintyTerms> {
    uncertainty_with(nominal, frd, extra, opts, None, None)
}

/// [`uncertainty`] of one SISO channel, with its term (a) from the given sensitivities $J_k R$
/// per line and their count $n_\theta$ (a MIMO model's joint tangent space,
/// [`uncertainty_matrix`], computed with the variances times `corr`'s factor) or, with `None`,
/// from the SISO tangent space (module docs); `corr`: the lines' correlation of the whole FRF
/// ([`line_correlation_of`]), `None` to estimate it from this channel.
fn uncertainty_with(
    nominal: &StateSpace,
    frd: &Frd,
    extra: &ExtraTerms<'_>,
    opts: &UncertaintyOptions,
    tangent: Option<Tangent>,
    corr: Option<LineCorrelation>,
) -> Result<UncertaintyTerms> {
    frd.require_siso("uncertainty")?;
    if nominal.ninputs() != 1 || nominal.noutputs() != 1 {
        return Err(Error::invalid(
            "nominal",
            "the nominal model must be SISO (one input, one output)",
        ));
    }
    for (name, v) in [
        ("line_coverage", opts.line_coverage),
        ("bias_alpha", opts.bias_alpha),
    ] {
        if !(v > 0.0 && v < 1.0) {
            return Err(Error::invalid(name, format!("must lie in (0, 1), got {v}")));
        }
    }
    let ts = match (frd.ts(), nominal.ts()) {
        (Some(a), Some(b)) if (a - b).abs() <= 1e-9 * a => a,
        (Some(a), Some(b)) => {
            return Err(Error::invalid(
                "nominal",
                format!("the model's sample time {b} s differs from the FRF's {a} s"),
            ))
        }
        _ => {
            return Err(Error::invalid(
                "frd",
                "the FRF and the model must both be discrete-time (the model's sample time)",
            ))
        }
    };
    let var_raw = positive_variances(frd)?;
    let l = frd.len();
    for (name, v) in [
        ("nonlinear_std", extra.nonlinear_std),
        ("operating_spread", extra.operating_spread),
        ("amplitude_shift", extra.amplitude_shift),
    ] {
        if let Some(v) = v {
            if v.len() != l || v.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
                return Err(Error::invalid(
                    name,
                    format!(
                        "needs one finite, non-negative value per FRF line ({l}), got {}",
                        v.len()
                    ),
                ));
            }
        }
    }
    if let Some(n) = extra.fit_noise {
        if n.len() != l {
            return Err(Error::invalid(
                "fit_noise",
                format!(
                    "needs one noise description per FRF line ({l}), got {}",
                    n.len()
                ),
            ));
        }
    }
    let f = frd.f_hz().to_vec();
    let g = frd.values().to_vec();
    let z: Vec<c64> = f
        .iter()
        .map(|&fk| c64::from_polar(1.0, 2.0 * std::f64::consts::PI * fk * ts))
        .collect();
    let poles = nominal.poles()?;
    let p_hat = nominal.freq_response_siso(&f)?;
    let misfit_c: Vec<c64> = (0..l).map(|k| g[k] - p_hat[k]).collect();
    let roughness = misfit_roughness(&misfit_c, var_raw);
    // (f): in its own tangent space, the distance from the FRF's own fit of the model's order
    let (distance, distance_failed) = match (&tangent, opts.fit_distance) {
        (None, true) => match own_fit_distance(nominal, &poles, &p_hat, frd, extra.fit_noise) {
            Ok(d) => (Some(d), None),
            Err(e) => (None, Some(e.to_string())),
        },
        _ => (None, None),
    };
    let dist = |k: usize| distance.as_ref().map_or(0.0, |d| d[k]);
    // noise correlated between neighbouring lines: every average over lines (the fit's, the
    // windows') has κ times the variance of independent lines' (module docs)
    let corr = match corr {
        Some(c) => c,
        None => channel_correlation(&misfit_c, var_raw, roughness, opts),
    };
    let var_scaled: Vec<f64> = var_raw.iter().map(|v| v * corr.factor).collect();
    let var = &var_scaled[..];
    let (sens, n_theta, fitted) = match tangent {
        Some(t) => (t.sens, t.dim, t.fitted),
        None => {
            let has_d = nominal.d()[(0, 0)] != 0.0;
            let n_theta = tangent_dim(&poles, has_d);
            if 2 * l <= n_theta {
                return Err(Error::invalid(
                    "frd",
                    format!(
                        "{l} lines give {} real equations for {n_theta} model parameters; widen the band",
                        2 * l
                    ),
                ));
            }
            // J_k R with R R^T = F^-1, from an orthonormal basis of the tangent space
            (
                tangent_sensitivities(&poles, has_d, &z, var)?,
                n_theta,
                vec![true; l],
            )
        }
    };
    // per line: 2x2 covariance of (Re, Im) δP̂ and the residual's noise variance over σ²
    let mut frf_conf = Vec::with_capacity(l);
    let mut gauss_cov = Vec::with_capacity(l);
    let mut noise_factor = Vec::with_capacity(l);
    let alpha = 1.0 - opts.line_coverage;
    for k in 0..l {
        let (mut crr, mut cii, mut cri) = (0.0, 0.0, 0.0);
        for s in &sens[k] {
            crr += s.re * s.re;
            cii += s.im * s.im;
            cri += s.re * s.im;
        }
        // a fitted line's residual has the variance σ²(1 − h), a validation line's σ²(1 + h)
        let h = ((crr + cii) / var[k]).max(0.0);
        noise_factor.push(if fitted[k] { 1.0 - h.min(1.0) } else { 1.0 + h });
        frf_conf.push(abs_quantile(crr, cii, cri, alpha));
        gauss_cov.push((crr, cii, cri));
    }
    // (b): the significant smoothed misfit
    let m_half = window_half_lines(&poles, &f, ts);
    // the windows, each tested at α_b / scales (module docs)
    // the line alone first when asked or when the misfit is rough without a term (c): a misfit
    // that changes from line to line (a single realisation's nonlinear distortion, far above
    // the noise of the periods) is averaged away by any window
    let per_line = match opts.per_line_misfit {
        PerLineMisfit::Off => false,
        PerLineMisfit::On => true,
        PerLineMisfit::Auto => {
            extra.nonlinear_std.is_none() && roughness.is_some_and(|r| r >= ROUGH_MISFIT)
        }
    };
    let halves: Vec<usize> = per_line
        .then_some(0)
        .into_iter()
        .chain(window_scales(m_half, l))
        .collect();
    let thr = (halves.len() as f64 / opts.bias_alpha).ln();
    let mut bias = vec![0.0f64; l];
    // per line, the windowed mean and its variance of the window that set b_k (for its phase)
    let mut at_max = vec![(c64::new(0.0, 0.0), 0.0f64); l];
    for &half in &halves {
        for (k, (b, best)) in bias.iter_mut().zip(&mut at_max).enumerate() {
            let (lo, hi) = (k.saturating_sub(half), (k + half).min(l - 1));
            let (mut num, mut sw, mut vv) = (c64::new(0.0, 0.0), 0.0, 0.0);
            for j in lo..=hi {
                let w = 1.0 / var[j];
                num += misfit_c[j] * w;
                sw += w;
                vv += w * w * var[j] * noise_factor[j];
            }
            let mean = num / sw;
            let v = vv / (sw * sw);
            // the excess over the test's threshold: 0 at the edge of significance, |ē| for a
            // misfit far above the noise (a noise excursion that just passes adds little)
            let excess = (mean.norm_sqr() - thr * v).max(0.0).sqrt();
            // on request a significant misfit enters at its upper value at the line coverage,
            // not its excess: the line alone has no neighbours to average its noise away
            let term = if per_line && excess > 0.0 {
                rice_quantile(mean.norm(), v, opts.line_coverage)
            } else {
                excess
            };
            if term > *b {
                *b = term;
                *best = (mean, v);
            }
        }
    }
    let (bias_center, bias_spread) = coherent_bias(&bias, &at_max, thr);
    let nonlinear = extra.nonlinear_std.map(|s| {
        s.iter()
            .map(|&x| abs_quantile(0.5 * x * x, 0.5 * x * x, 0.0, alpha))
            .collect::<Vec<f64>>()
    });
    let mut additive = Vec::with_capacity(l);
    for k in 0..l {
        let (mut crr, mut cii, cri) = gauss_cov[k];
        if let Some(s) = extra.nonlinear_std {
            crr += 0.5 * s[k] * s[k];
            cii += 0.5 * s[k] * s[k];
        }
        additive
            .push(abs_quantile(crr, cii, cri, alpha) + bias[k] + fixed_extra(extra, k) + dist(k));
    }
    let multiplicative = additive
        .iter()
        .zip(&p_hat)
        .map(|(d, p)| d / p.norm().max(f64::MIN_POSITIVE))
        .collect();
    let errors = ErrorModel {
        sens,
        nonlinear_std: extra.nonlinear_std.map(<[f64]>::to_vec),
        fixed: (0..l)
            .map(|k| bias[k] + fixed_extra(extra, k) + dist(k))
            .collect(),
        bias_center,
        bias_spread,
        nominal_abs: p_hat
            .iter()
            .map(|p| p.norm().max(f64::MIN_POSITIVE))
            .collect(),
    };
    Ok(UncertaintyTerms {
        f_hz: f,
        misfit: misfit_c.iter().map(|e| e.norm()).collect(),
        nominal: p_hat,
        measured: g,
        frf_confidence: frf_conf,
        model_error: bias,
        nonlinear,
        operating: extra.operating_spread.map(<[f64]>::to_vec),
        amplitude: extra.amplitude_shift.map(<[f64]>::to_vec),
        fit_distance: distance,
        fit_distance_failed: distance_failed,
        additive,
        multiplicative,
        window_half_lines: m_half,
        n_params: n_theta,
        line_coverage: opts.line_coverage,
        misfit_roughness: roughness,
        per_line_misfit: per_line,
        line_correlation: corr,
        errors,
    })
}

/// The uncertainty of a nominal model with $n_y$ outputs and $n_u$ inputs around its measured
/// $n_y\times n_u$ plant FRF, entry by entry ([`uncertainty_matrix`]); a SISO model is its
/// $1\times 1$ case.
///
/// Entry $(i, j)$ holds the terms of [`uncertainty`] for the channel from input $j$ to output
/// $i$: $|P_{ij}(z_k) - \hat P_{ij}(z_k)| \le L_{ij,k}$ (its `additive`). Since the spectral
/// norm is monotone on element-wise majorants ($|X_{ij}| \le L_{ij} \Rightarrow
/// \lVert X x\rVert \le \lVert L\,|x|\rVert \le \lVert L\rVert_2 \lVert x\rVert$),
/// $\bar\sigma(P - \hat P) \le \lVert L_k\rVert_2$: the unstructured additive bound
/// ([`MatrixUncertainty::norm_bound`]).
#[derive(Debug, Clone, PartialEq)]
pub struct MatrixUncertainty {
    /// Outputs $n_y$.
    pub outputs: usize,
    /// Inputs $n_u$.
    pub inputs: usize,
    /// The entries' terms, entry $(i, j)$ at index $i + j\,n_y$ (as [`Frd`] stores a matrix).
    pub entries: Vec<UncertaintyTerms>,
    /// Term (e) through the model as a distribution of the joint parameters, kept by
    /// [`add_projected_shift`](Self::add_projected_shift) for [`coherent_draws`](Self::coherent_draws).
    shift: Option<ParameterShift>,
}

/// The projected shift $\xi_s \sim N(\bar\xi_s, \Sigma_s)$ in the coordinates of the joint draws'
/// $\xi$, and what it added to each entry's deterministic part.
#[derive(Debug, Clone, PartialEq)]
struct ParameterShift {
    mean: Vec<f64>,
    /// $S$ with $S S^{\mathsf T} = \Sigma_s$ (lower triangular, row-major $n_\theta^2$).
    factor: Vec<f64>,
}

/// Draws of the model's error as whole matrices, with the part of the bound whose phase is not
/// known ([`MatrixUncertainty::coherent_draws`]).
#[derive(Debug, Clone, PartialEq)]
pub struct CoherentDraws {
    /// The lines \[Hz\].
    pub f_hz: Vec<f64>,
    /// Per draw, per line, the $n_y\times n_u$ error $D_{d,k}$.
    pub draws: Vec<Vec<faer::Mat<c64>>>,
    /// Per line, the element-wise bound $R_k$ of the rest of the error (phase unknown).
    pub remainder: Vec<faer::Mat<f64>>,
    /// Per line, the part $c_{ij,k}$ of every draw that is term (b) at its phase (0 where the
    /// phase is not known).
    pub bias_centre: Vec<faer::Mat<c64>>,
    /// Per line, the part $r_{ij,k}$ of the remainder that is term (b)'s spread about that
    /// centre ($b_{ij,k}$ where the phase is not known).
    pub bias_spread: Vec<faer::Mat<f64>>,
}

/// The outcome of [`MatrixUncertainty::add_projected_shift`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ProjectedShift {
    /// The Wald statistic $b^{\mathsf T} C_b^{-1} b$ of the projected shift.
    pub statistic: f64,
    /// Its threshold, the $1 - \alpha$ quantile of $\chi^2_{n_\theta}$.
    pub threshold: f64,
    /// Whether the projected shift entered term (e).
    pub kept: bool,
}

/// $S$ (lower triangular, row-major) with $S S^{\mathsf T} = \tfrac12(A + A^{\mathsf T})$ for a
/// positive semi-definite $A$: Cholesky with a pivot at or below $10^{-12}$ of the largest
/// diagonal taken as 0 (that column of $S$ left zero).
fn psd_factor(a: &faer::Mat<f64>) -> Vec<f64> {
    let n = a.nrows();
    let sym = |i: usize, j: usize| 0.5 * (a[(i, j)] + a[(j, i)]);
    let tol = 1e-12 * (0..n).map(|i| sym(i, i).abs()).fold(0.0, f64::max);
    let mut s = vec![0.0; n * n];
    for j in 0..n {
        let d = sym(j, j) - (0..j).map(|q| s[j * n + q] * s[j * n + q]).sum::<f64>();
        if d <= tol {
            continue;
        }
        let r = d.sqrt();
        s[j * n + j] = r;
        for i in j + 1..n {
            let v = sym(i, j) - (0..j).map(|q| s[i * n + q] * s[j * n + q]).sum::<f64>();
            s[i * n + j] = v / r;
        }
    }
    s
}

/// The quantile $r$ of $|\mu + n|$ at probability `c`, for an offset of magnitude `m` and a
/// circular complex Gaussian $n$ with $\mathrm E|n|^2$ = `var` (the Rice distribution):
/// $$ P(|\mu + n| \le r) = \int_0^r \frac{2\rho}{\sigma^2}\, e^{-(\rho^2 + m^2)/\sigma^2}\,
///    I_0\!\left(\frac{2\rho m}{\sigma^2}\right) d\rho = c , $$
/// by the trapezoid rule on 4 000 steps over $m \pm 8\sigma$ ($I_0$ scaled, Abramowitz & Stegun
/// 9.8.1–2) and linear interpolation. With $m = 0$ it is $\sigma\sqrt{\ln(1/(1 - c))}$; for
/// $m \gg \sigma$ it tends to $m + z_c\,\sigma/\sqrt 2$.
///
/// # Example
/// ```
/// use ambid_core::validate::uncertainty::rice_quantile;
/// assert!((rice_quantile(0.0, 1.0, 0.95) - 20f64.ln().sqrt()).abs() < 1e-4);
/// assert!(rice_quantile(2.0, 1.0, 0.95) > 2.0 && rice_quantile(2.0, 1.0, 0.95) < 2.0 + 20f64.ln().sqrt());
/// ```
pub fn rice_quantile(m: f64, var: f64, c: f64) -> f64 {
    let m = m.abs();
    if var.is_nan() || var <= 0.0 {
        return m;
    }
    let s2 = var;
    let sigma = s2.sqrt();
    let i0e = |x: f64| {
        let ax = x.abs();
        if ax <= 3.75 {
            let t = (ax / 3.75) * (ax / 3.75);
            (1.0 + t
                * (3.515_622_9
                    + t * (3.089_942_4
                        + t * (1.206_749_2
                            + t * (0.265_973_2 + t * (0.036_076_8 + t * 0.004_581_3))))))
                * (-ax).exp()
        } else {
            let t = 3.75 / ax;
            (0.398_942_28
                + t * (0.013_285_92
                    + t * (0.002_253_19
                        + t * (-0.001_575_65
                            + t * (0.009_162_81
                                + t * (-0.020_577_06
                                    + t * (0.026_355_37
                                        + t * (-0.016_476_33 + t * 0.003_923_77))))))))
                / ax.sqrt()
        }
    };
    let pdf = |r: f64| 2.0 * r / s2 * (-(r - m) * (r - m) / s2).exp() * i0e(2.0 * r * m / s2);
    // the density is negligible (below e^{-64} of its peak) outside m ± 8σ
    let steps = 4000;
    let (bottom, top) = ((m - 8.0 * sigma).max(0.0), m + 8.0 * sigma);
    let h = (top - bottom) / steps as f64;
    let (mut cdf, mut prev) = (0.0, pdf(bottom));
    for i in 1..=steps {
        let r = bottom + i as f64 * h;
        let cur = pdf(r);
        let next = cdf + 0.5 * h * (prev + cur);
        if next >= c {
            let frac = if next > cdf {
                (c - cdf) / (next - cdf)
            } else {
                0.0
            };
            return r - h + frac * h;
        }
        cdf = next;
        prev = cur;
    }
    top
}

/// The upper $\alpha$ quantile of $\chi^2_n$ by the Wilson–Hilferty cube
/// $n\,(1 - \tfrac{2}{9n} + z_{1-\alpha}\sqrt{2/(9n)})^3$ (relative error below 1 % for
/// $n \ge 10$ at $\alpha = 0.05$), with the normal quantile from [`normal_upper_quantile`].
///
/// # Example
/// ```
/// use ambid_core::validate::uncertainty::chi2_upper_quantile;
/// // scipy.stats.chi2.ppf(0.95, 50) = 67.5048
/// assert!((chi2_upper_quantile(50, 0.05) - 67.5048).abs() < 0.1);
/// ```
pub fn chi2_upper_quantile(n: usize, alpha: f64) -> f64 {
    let nf = n.max(1) as f64;
    let h = 2.0 / (9.0 * nf);
    nf * (1.0 - h + normal_upper_quantile(alpha) * h.sqrt()).powi(3)
}

/// The upper $\alpha$ quantile $z$ of the standard normal, $P(Z > z) = \alpha$, by bisection on
/// the complementary error function (its Chebyshev fit of fractional error below 1.2e-7,
/// Press et al., *Numerical Recipes*, §6.2).
///
/// # Example
/// ```
/// use ambid_core::validate::uncertainty::normal_upper_quantile;
/// assert!((normal_upper_quantile(0.05) - 1.644_854).abs() < 1e-5);
/// ```
pub fn normal_upper_quantile(alpha: f64) -> f64 {
    let erfc = |x: f64| {
        let z = x.abs();
        let t = 1.0 / (1.0 + 0.5 * z);
        let poly = -z * z - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87
                                        + t * (-0.822_152_23 + t * 0.170_872_77))))))));
        let r = t * poly.exp();
        if x >= 0.0 {
            r
        } else {
            2.0 - r
        }
    };
    let tail = |z: f64| 0.5 * erfc(z / std::f64::consts::SQRT_2);
    bisect_decreasing(tail, alpha, (-40.0, 40.0), 200, 0.0)
}

/// The point where the decreasing function `f` crosses `target` in `bracket`, by bisection:
/// at most `iterations` halvings, stopping early once the interval is within `rel_tol` of its
/// upper end; the interval's midpoint.
fn bisect_decreasing(
    f: impl Fn(f64) -> f64,
    target: f64,
    bracket: (f64, f64),
    iterations: usize,
    rel_tol: f64,
) -> f64 {
    let (mut lo, mut hi) = bracket;
    for _ in 0..iterations {
        let mid = 0.5 * (lo + hi);
        if f(mid) > target {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= rel_tol * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

impl MatrixUncertainty {
    /// The lines \[Hz\].
    pub fn f_hz(&self) -> &[f64] {
        self.entries.first().map_or(&[], |e| e.f_hz.as_slice())
    }

    /// The terms of entry $(i, j)$ (output $i$, input $j$), `None` outside the matrix.
    pub fn entry(&self, i: usize, j: usize) -> Option<&UncertaintyTerms> {
        (i < self.outputs && j < self.inputs)
            .then(|| self.entries.get(i + j * self.outputs))
            .flatten()
    }

    /// The element-wise additive bound $L_k$ at line `k` ($n_y\times n_u$; zeros past the
    /// last line).
    pub fn bound_at(&self, k: usize) -> faer::Mat<f64> {
        faer::Mat::from_fn(self.outputs, self.inputs, |i, j| {
            self.entries[i + j * self.outputs]
                .additive
                .get(k)
                .copied()
                .unwrap_or(0.0)
        })
    }

    /// The nominal model $\hat P(z_k)$ at line `k` (zeros past the last line).
    pub fn nominal_at(&self, k: usize) -> faer::Mat<c64> {
        faer::Mat::from_fn(self.outputs, self.inputs, |i, j| {
            self.entries[i + j * self.outputs]
                .nominal
                .get(k)
                .copied()
                .unwrap_or_default()
        })
    }

    /// The element-wise bounds $L_k$ on every line.
    pub fn bounds(&self) -> Vec<faer::Mat<f64>> {
        (0..self.f_hz().len()).map(|k| self.bound_at(k)).collect()
    }

    /// The factor $g$ by which the element-wise bound must be raised so that $g L_{ij,k}$
    /// overbounds a draw of the model's error $|\delta\hat P_{ij,k}|$ on at least the fraction
    /// `cover` of the (line, entry) pairs in the fraction `run_coverage` of `draws` seeded draws
    /// (`ChaCha8Rng`): the module docs' "Joint coverage" over all entries at once. One draw
    /// $\xi \sim N(0, I)$ of the joint parameters moves every entry, $\delta\hat P_{ij,k} =
    /// J_{ij,k} R\,\xi$ (the entries share the tangent basis of [`uncertainty_matrix`]), plus each
    /// entry's nonlinear draw and its deterministic terms in magnitude. The factor may be below 1
    /// (the bound is then wider than needed); callers raise with $\max(g, 1)$.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for fractions outside (0, 1], no draws, or a bound that is not
    /// positive on some pair.
    pub fn joint_raise(
        &self,
        cover: f64,
        run_coverage: f64,
        draws: usize,
        seed: u64,
    ) -> Result<f64> {
        Ok(self.joint_raises(&[cover], run_coverage, draws, seed)?[0])
    }

    /// [`joint_raise`](Self::joint_raise) for several fractions `covers` of the pairs on the
    /// same draws: element $m$ equals `joint_raise(covers[m], run_coverage, draws, seed)`, the
    /// draws made once. The machine's bound uses two: 98 % of the pairs for the bound on the
    /// lines and 95 % for the bound its entry weights are fitted to (docs/uncertainty.md, "Two
    /// raises for the machine").
    ///
    /// # Errors
    /// As [`joint_raise`](Self::joint_raise), and for an empty `covers`.
    pub fn joint_raises(
        &self,
        covers: &[f64],
        run_coverage: f64,
        draws: usize,
        seed: u64,
    ) -> Result<Vec<f64>> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        if covers.is_empty() {
            return Err(Error::invalid("covers", "needs at least one fraction"));
        }
        for v in covers {
            if !(*v > 0.0 && *v <= 1.0) {
                return Err(Error::invalid(
                    "cover",
                    format!("must lie in (0, 1], got {v}"),
                ));
            }
        }
        if !(run_coverage > 0.0 && run_coverage <= 1.0) {
            return Err(Error::invalid(
                "run_coverage",
                format!("must lie in (0, 1], got {run_coverage}"),
            ));
        }
        if draws == 0 {
            return Err(Error::invalid("draws", "needs at least one draw"));
        }
        if self
            .entries
            .iter()
            .any(|e| e.additive.iter().any(|b| !(*b > 0.0 && b.is_finite())))
        {
            return Err(Error::invalid(
                "bound",
                "every entry's bound must be positive and finite on every line",
            ));
        }
        let dim = self.tangent_dim();
        let pairs: usize = self.entries.iter().map(|e| e.additive.len()).sum();
        if pairs == 0 {
            return Err(Error::invalid("bound", "has no line"));
        }
        let at: Vec<usize> = covers
            .iter()
            .map(|c| ((c * pairs as f64).ceil() as usize).clamp(1, pairs) - 1)
            .collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut need = vec![Vec::with_capacity(draws); covers.len()];
        let mut ratio = Vec::with_capacity(pairs);
        for _ in 0..draws {
            let xi: Vec<f64> = (0..dim).map(|_| StandardNormal.sample(&mut rng)).collect();
            ratio.clear();
            for e in &self.entries {
                for k in 0..e.errors.sens.len() {
                    ratio.push(e.errors.line_error(k, &xi, &mut rng) / e.additive[k]);
                }
            }
            // each selection only reorders the same values
            for (n, a) in need.iter_mut().zip(&at) {
                ratio.select_nth_unstable_by(*a, f64::total_cmp);
                n.push(ratio[*a]);
            }
        }
        let i = ((run_coverage * draws as f64).ceil() as usize).clamp(1, draws) - 1;
        Ok(need
            .into_iter()
            .map(|mut n| {
                n.select_nth_unstable_by(i, f64::total_cmp);
                n[i]
            })
            .collect())
    }

    /// The bound raised by a factor $g$ (a raise of [`joint_raises`](Self::joint_raises)):
    /// every entry's additive bound $\Delta_{ij,k}$ becomes $g\,\Delta_{ij,k}$ and its relative
    /// bound $\ell_{ij,k} = \Delta_{ij,k}/\lvert\hat P_{ij,k}\rvert$ with it; the terms it was
    /// built from, (a)–(e), are kept as they are, so the table of terms still shows what was
    /// estimated and the bound shows what is claimed.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a factor that is not finite and positive.
    ///
    /// # Example
    /// A diagonal 2×2 model's bound raised by 1.3: every entry's bound, absolute and relative.
    /// ```
    /// use ambid_core::lti::{Frd, StateSpace};
    /// use ambid_core::validate::uncertainty::{uncertainty_matrix, UncertaintyOptions};
    /// use faer::mat;
    /// let m = StateSpace::discrete(
    ///     mat![[0.9, 0.0], [0.0, 0.5]], mat![[1.0, 0.0], [0.0, 1.0]], mat![[0.1, 0.0], [0.0, 0.2]],
    ///     mat![[0.0, 0.0], [0.0, 0.0]], 1e-3,
    /// ).unwrap();
    /// let f: Vec<f64> = (1..=100).map(|k| k as f64 * 4.0).collect();
    /// let exact = Frd::from_model(&m, &f).unwrap();
    /// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr().max(1e-6)).collect();
    /// let frd = Frd::new_matrix(f.clone(), 2, 2, exact.values().to_vec(), Some(var), Some(1e-3)).unwrap();
    /// let u = uncertainty_matrix(&m, &frd, &[], &UncertaintyOptions::default()).unwrap();
    /// let r = u.scaled(1.3).unwrap();
    /// let (a, b) = (u.entry(1, 1).unwrap(), r.entry(1, 1).unwrap());
    /// assert!((b.additive[7] - 1.3 * a.additive[7]).abs() <= 1e-12 * b.additive[7]);
    /// assert!((b.multiplicative[7] - 1.3 * a.multiplicative[7]).abs() <= 1e-12 * b.multiplicative[7]);
    /// assert_eq!(b.frf_confidence, a.frf_confidence);
    /// assert!(u.scaled(f64::NAN).is_err());
    /// ```
    pub fn scaled(&self, g: f64) -> Result<Self> {
        if !(g.is_finite() && g > 0.0) {
            return Err(Error::invalid(
                "g",
                format!("the raise must be finite and positive, got {g}"),
            ));
        }
        let mut u = self.clone();
        for e in &mut u.entries {
            for b in e.additive.iter_mut().chain(e.multiplicative.iter_mut()) {
                *b *= g;
            }
        }
        Ok(u)
    }

    /// Draws of the model's error as whole $n_y\times n_u$ matrices, for a robust check that
    /// keeps the error's coherence between the entries
    /// ([`robust_stability_matrix_drawn`](super::robust::robust_stability_matrix_drawn);
    /// docs/uncertainty.md, "Coherent draws for the machine"). Draw $d$ (seeded `ChaCha8Rng`)
    /// takes one $\xi \sim N(0, I)$ of the joint parameters (term (a), as
    /// [`joint_raises`](Self::joint_raises)) and, when term (e) through the model was kept
    /// ([`add_projected_shift`](Self::add_projected_shift)), one $\xi_s \sim N(\bar\xi_s,
    /// \Sigma_s)$ of the projected shift, and moves every entry with them:
    /// $$ D_{d,ij,k} = J_{ij,k} R\,(\xi - \xi_s) + c_{ij,k} + \nu_{d,ij,k} , $$
    /// with the nonlinear term (c) drawn per line and entry (circular) and $c_{ij,k}$ term (b)
    /// at the windowed misfit's phase where that phase is known: $c_{ij,k} = b_k\,\bar e/|\bar e|$
    /// with $\bar e$ the mean misfit of the window that set $b_k$, and the spread
    /// $r_k = 2 b_k \sin(\tfrac12\arcsin(\sqrt{t v}/|\bar e|))$ of that phase's error at the
    /// test's level ($t$ the threshold, $v$ the mean's variance); where $r_k \ge b_k$ the phase
    /// is not known, $c_{ij,k} = 0$ and $r_k = b_k$. The misfit $G - \hat P$ holds the model
    /// set's error $+\beta$, so its phase is the error's.
    /// The rest of the bound has no known phase — term (b)'s spread $r_k$ about $c_k$ ($b_k$
    /// where the phase is not known) and the operating spread (d) — and is returned as the
    /// element-wise `remainder` $R_{ij,k} = r_k + d_k$, plus the per-line amplitude term $a_k$
    /// when no projected shift was kept. The bound's raises are not applied: the draws carry
    /// the random part themselves. Term (b) at its phase dates from 2026-12-05 (eleventh
    /// session; before, all of $b_k$ was in the remainder: on one nonlinear machine rig it set
    /// the coherent margin at a free phase on the cross entries, docs/uncertainty.md, "Term (b)
    /// at the misfit's phase").
    ///
    /// *Why the amplitude term leaves the remainder when the projection is kept.* The model is
    /// fitted to the BLA $G = P_0 + s + n$ (small-signal plant $P_0$, amplitude shift $s$,
    /// noise $n$). To first order it is $\hat P = P_{\theta_0} + \Pi(s) + \Pi(n)$, with $\Pi$ the
    /// fit's weighted projection onto the model's tangent space and $P_{\theta_0}$ the model
    /// set's best approximation of $P_0$. Its error against the small-signal plant is
    /// $P_0 - \hat P = \beta - \Pi(s) - \Pi(n)$, $\beta = P_0 - P_{\theta_0}$: the shift
    /// enters only through $-\Pi(s)$, which the draws carry ($-J R\,\xi_s$; the model moved
    /// *with* the shift, so its error against $P_0$ is the shift's negative — until
    /// 2026-12-05, eleventh session, the draws added $+J R\,\xi_s$ and stood $2\Pi(s)$ from
    /// the truth), and $\Pi(n)$ is term (a). The projected shift's noise and term (a) share the
    /// identification FRF's noise (the amplitude study's regression includes that FRF), a
    /// correlation the draws leave out: they draw the two independently. The rest of the
    /// shift, $s - \Pi(s)$, is no error of the model against $P_0$; it lies in the misfit
    /// $G - \hat P = \beta + (s - \Pi(s)) + (n - \Pi(n))$, which term (b) bounds. Adding
    /// $a_k \approx |s_k|$ at a free phase as well counted the shift twice; on nonlinear
    /// machine rigs it set the coherent margin at the bending modes
    /// (docs/uncertainty.md, "The amplitude term in the coherent draws"). What this assumes:
    /// term (b) bounds $\beta$ only where $s - \Pi(s)$ does not cancel part of it at a line
    /// (both lie outside the tangent space); the per-line shift estimates are too noisy to
    /// bound $s - \Pi(s)$ by themselves, so that case is not covered, and the rig sweeps are
    /// the evidence that it does not decide a margin. The element-wise bound (`additive`, the
    /// weights, the check on the lines) keeps $\max(a_k, \cdot)$, a worst case over the phase.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for no draws or a bound without lines.
    ///
    /// # Example
    /// A diagonal 2×2 model fitted to its exact response: the error is the parameters' alone,
    /// so the remainder is zero and every draw moves both diagonal entries, never the zero
    /// cross entries.
    /// ```
    /// use ambid_core::lti::{Frd, StateSpace};
    /// use ambid_core::validate::uncertainty::{uncertainty_matrix, UncertaintyOptions};
    /// use faer::mat;
    /// let m = StateSpace::discrete(
    ///     mat![[0.9, 0.0], [0.0, 0.5]], mat![[1.0, 0.0], [0.0, 1.0]], mat![[0.1, 0.0], [0.0, 0.2]],
    ///     mat![[0.0, 0.0], [0.0, 0.0]], 1e-3,
    /// ).unwrap();
    /// let f: Vec<f64> = (1..=100).map(|k| k as f64 * 4.0).collect();
    /// let exact = Frd::from_model(&m, &f).unwrap();
    /// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr().max(1e-6)).collect();
    /// let frd = Frd::new_matrix(f.clone(), 2, 2, exact.values().to_vec(), Some(var), Some(1e-3)).unwrap();
    /// let u = uncertainty_matrix(&m, &frd, &[], &UncertaintyOptions::default()).unwrap();
    /// let d = u.coherent_draws(20, 7).unwrap();
    /// assert_eq!((d.draws.len(), d.draws[0].len(), d.remainder.len()), (20, 100, 100));
    /// assert!(d.remainder.iter().all(|r| (0..2).all(|i| (0..2).all(|j| r[(i, j)] == 0.0))));
    /// assert!(d.draws[3][10][(0, 0)].norm() > 0.0 && d.draws[3][10][(1, 1)].norm() > 0.0);
    /// assert!(u.coherent_draws(0, 7).is_err());
    /// ```
    pub fn coherent_draws(&self, draws: usize, seed: u64) -> Result<CoherentDraws> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        if draws == 0 {
            return Err(Error::invalid("draws", "needs at least one draw"));
        }
        let l = self.f_hz().len();
        if l == 0 || self.entries.is_empty() {
            return Err(Error::invalid("bound", "has no line"));
        }
        let (ny, nu) = (self.outputs, self.inputs);
        let dim = self.tangent_dim();
        // with the projected shift kept, the draws carry the shift's effect on the model and
        // the per-line amplitude term leaves the remainder (doc above); without it, it stays
        let remainder: Vec<faer::Mat<f64>> = (0..l)
            .map(|k| {
                faer::Mat::from_fn(ny, nu, |i, j| {
                    let t = &self.entries[i + j * ny];
                    let amp = match (&self.shift, &t.amplitude) {
                        (Some(_), Some(a)) => a[k],
                        _ => 0.0,
                    };
                    // term (b) is carried at its phase where that is known (its centre in
                    // every draw) and only its spread about it stays here
                    let b = t.model_error[k];
                    (t.errors.fixed[k] - amp - b).max(0.0) + t.errors.bias_spread[k]
                })
            })
            .collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut out = Vec::with_capacity(draws);
        for _ in 0..draws {
            let mut xi: Vec<f64> = (0..dim).map(|_| StandardNormal.sample(&mut rng)).collect();
            if let Some(s) = &self.shift {
                let z: Vec<f64> = (0..dim).map(|_| StandardNormal.sample(&mut rng)).collect();
                for (m, x) in xi.iter_mut().enumerate() {
                    let row = &s.factor[m * dim..(m + 1) * dim];
                    // the model moved by +Π(s) with the shift, so its error against the
                    // small-signal plant holds −Π(s) (doc above)
                    *x -= s.mean[m] + row.iter().zip(&z).map(|(a, b)| a * b).sum::<f64>();
                }
            }
            let mut lines = vec![faer::Mat::<c64>::zeros(ny, nu); l];
            // entry by entry, as the joint raise draws them
            for (e, terms) in self.entries.iter().enumerate() {
                for (k, line) in lines.iter_mut().enumerate() {
                    line[(e % ny, e / ny)] =
                        terms.errors.line_random(k, &xi, &mut rng) + terms.errors.bias_center[k];
                }
            }
            out.push(lines);
        }
        let at = |i: usize, j: usize| &self.entries[i + j * ny].errors;
        Ok(CoherentDraws {
            f_hz: self.f_hz().to_vec(),
            draws: out,
            remainder,
            bias_centre: (0..l)
                .map(|k| faer::Mat::from_fn(ny, nu, |i, j| at(i, j).bias_center[k]))
                .collect(),
            bias_spread: (0..l)
                .map(|k| faer::Mat::from_fn(ny, nu, |i, j| at(i, j).bias_spread[k]))
                .collect(),
        })
    }

    /// Term (e) through the model (module docs, "Term (e) through the model"): the amplitude
    /// shift's per-line estimates `shift` (complex, absolute: $s_{ij,k} = c_{ij,k} a_e^2$, entry
    /// $(i, j)$ at index $i + j\,n_y$) with their variances `var` (of a circular complex error),
    /// on the lines of `frd` (the FRF the bound was computed on, whose variances weight the fit),
    /// projected onto the model's tangent space with the fit's weights $w = 1/\sigma^2$:
    /// $$ \xi_s = G^{-1} b, \quad G = \operatorname{Re}\sum_{ij,k} w\,s^{\mathsf H}_{\theta} s_\theta,
    ///    \quad b = \operatorname{Re}\sum_{ij,k} w\, s_\theta^{\mathsf H} s_{ij,k},
    ///    \qquad \hat s_{ij,k} = (J_{ij,k} R)\,\xi_s , $$
    /// with $s_\theta = J_{ij,k}R$ the entry's sensitivity at the line (the rows term (a) and the
    /// draws use). The model fitted to an FRF whose BLA is shifted by a smooth $s$ moves by
    /// $\hat s$ to first order, so the shift reaches the model even where each line's estimate
    /// is far below its noise and [`ExtraTerms::amplitude_shift`]'s windows see nothing. Kept
    /// when the Wald statistic $b^{\mathsf T} C_b^{-1} b$, $C_b = \sum \tfrac{v}{2} w^2
    /// \operatorname{Re}(\bar s_\theta s_\theta^{\mathsf T})$, exceeds the $1 - \alpha$ quantile of
    /// $\chi^2_{n_\theta}$ (one test per run); then each entry's term (e) becomes
    /// $\max(e_k, |\hat s_k| + \sqrt{\ln(1/(1-c))\,\mathrm E|\hat s_k - \mathrm E\hat s_k|^2})$
    /// ($c$ the bound's line coverage) and the bound, the draws' fixed part and the
    /// multiplicative bound grow by the difference. Returns the statistic and its threshold.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for shapes that differ from the bound's entries and lines, an
    /// FRF on other lines or without positive variances, a non-finite shift or variance, or
    /// $\alpha$ outside (0, 1); [`Error::Numerical`] when $G$ or $C_b$ is singular.
    ///
    /// # Example
    /// A 1 % shift of a diagonal 2×2 model's every entry, known per line to 1 %: it enters the
    /// bound, which then covers it.
    /// ```
    /// use ambid_core::lti::{Frd, StateSpace};
    /// use ambid_core::validate::uncertainty::{uncertainty_matrix, UncertaintyOptions};
    /// use faer::mat;
    /// let m = StateSpace::discrete(
    ///     mat![[0.9, 0.0], [0.0, 0.5]], mat![[1.0, 0.0], [0.0, 1.0]], mat![[0.1, 0.0], [0.0, 0.2]],
    ///     mat![[0.0, 0.0], [0.0, 0.0]], 1e-3,
    /// ).unwrap();
    /// let f: Vec<f64> = (1..=200).map(|k| k as f64 * 2.0).collect();
    /// let exact = Frd::from_model(&m, &f).unwrap();
    /// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr().max(1e-6)).collect();
    /// let frd = Frd::new_matrix(f.clone(), 2, 2, exact.values().to_vec(), Some(var), Some(1e-3)).unwrap();
    /// let mut u = uncertainty_matrix(&m, &frd, &[], &UncertaintyOptions::default()).unwrap();
    /// let shift: Vec<Vec<_>> = (0..4).map(|e| (0..f.len()).map(|k| exact.values()[k * 4 + e] * 0.01).collect()).collect();
    /// let var: Vec<Vec<f64>> = shift.iter().map(|s| s.iter().map(|x| 1e-4 * x.norm_sqr() + 1e-30).collect()).collect();
    /// let r = u.add_projected_shift(&frd, &shift, &var, 0.05).unwrap();
    /// assert!(r.kept && r.statistic > r.threshold);
    /// assert!(u.entry(0, 0).unwrap().additive[50] >= shift[0][50].norm());
    /// ```
    pub fn add_projected_shift(
        &mut self,
        frd: &Frd,
        shift: &[Vec<c64>],
        var: &[Vec<f64>],
        alpha: f64,
    ) -> Result<ProjectedShift> {
        let n_entries = self.entries.len();
        if shift.len() != n_entries || var.len() != n_entries {
            return Err(Error::invalid(
                "shift",
                format!(
                    "needs one shift and one variance per entry ({n_entries}), got {} and {}",
                    shift.len(),
                    var.len()
                ),
            ));
        }
        if !(alpha > 0.0 && alpha < 1.0) {
            return Err(Error::invalid(
                "alpha",
                format!("must lie in (0, 1), got {alpha}"),
            ));
        }
        if frd.ny() != self.outputs || frd.nu() != self.inputs || frd.f_hz() != self.f_hz() {
            return Err(Error::invalid(
                "frd",
                "must be the FRF the bound was computed on (same entries and lines)",
            ));
        }
        let l = self.f_hz().len();
        let fvar = frd.variance().ok_or_else(|| {
            Error::invalid("frd", "has no variances: the projection weighs by them")
        })?;
        let n = self.tangent_dim();
        if n == 0 {
            return Err(Error::invalid(
                "bound",
                "has no tangent space to project on",
            ));
        }
        let (mut g, mut cb) = (faer::Mat::<f64>::zeros(n, n), faer::Mat::<f64>::zeros(n, n));
        let mut b = faer::Mat::<f64>::zeros(n, 1);
        for (e, terms) in self.entries.iter().enumerate() {
            let (i, j) = (e % self.outputs, e / self.outputs);
            if shift[e].len() != l || var[e].len() != l || terms.errors.sens.len() != l {
                return Err(Error::invalid(
                    "shift",
                    format!("entry ({i}, {j}): needs one value per line ({l})"),
                ));
            }
            for k in 0..l {
                let w = 1.0 / fvar[k * n_entries + e];
                let (s, v) = (shift[e][k], var[e][k]);
                if !(w.is_finite()
                    && w > 0.0
                    && s.re.is_finite()
                    && s.im.is_finite()
                    && v.is_finite()
                    && v >= 0.0)
                {
                    return Err(Error::invalid(
                        "shift",
                        format!(
                            "entry ({i}, {j}) at {} Hz: the FRF's variance must be positive and the shift and its variance finite",
                            self.f_hz()[k]
                        ),
                    ));
                }
                let a = &terms.errors.sens[k];
                for (m, am) in a.iter().enumerate() {
                    b[(m, 0)] += w * (am.conj() * s).re;
                    for (q, aq) in a.iter().enumerate() {
                        let re = (am.conj() * aq).re;
                        g[(m, q)] += w * re;
                        cb[(m, q)] += 0.5 * v * w * w * re;
                    }
                }
            }
        }
        let y = crate::linalg::solve(cb.as_ref(), b.as_ref())
            .map_err(|_| Error::numerical(CTX, "the projected shift's covariance is singular"))?;
        let statistic = (0..n).map(|m| b[(m, 0)] * y[(m, 0)]).sum::<f64>();
        let threshold = chi2_upper_quantile(n, alpha);
        let kept = statistic > threshold;
        if kept {
            let xi = crate::linalg::solve(g.as_ref(), b.as_ref()).map_err(|_| {
                Error::numerical(CTX, "the tangent space's Gram matrix is singular")
            })?;
            // Cov ξ = G⁻¹ C_b G⁻¹
            let gi_cb = crate::linalg::solve(g.as_ref(), cb.as_ref())?;
            let cov = crate::linalg::solve(g.as_ref(), gi_cb.transpose())?;
            let coverage = self.line_coverage();
            let q = (1.0 / (1.0 - coverage)).ln();
            for terms in &mut self.entries {
                let mut amp = terms.amplitude.clone().unwrap_or_else(|| vec![0.0; l]);
                #[allow(clippy::needless_range_loop)] // k indexes six per-line vectors
                for k in 0..l {
                    let a = &terms.errors.sens[k];
                    let mean = a
                        .iter()
                        .enumerate()
                        .fold(c64::new(0.0, 0.0), |acc, (m, am)| acc + am * xi[(m, 0)]);
                    // E|a·η|² = Σ Re(a_m ā_q) Cov_mq
                    let mut v = 0.0;
                    for (m, am) in a.iter().enumerate() {
                        for (q2, aq) in a.iter().enumerate() {
                            v += (am * aq.conj()).re * cov[(m, q2)];
                        }
                    }
                    // the model's error at the line is δ_a + s: the quantile of |ŝ + n| with
                    // n of the variance of term (a) (its quantile read as a circular one's)
                    // plus the projection's, in place of term (a) plus the shift in magnitude
                    let qa = terms.frf_confidence[k];
                    let joint = rice_quantile(mean.norm(), qa * qa / q + v.max(0.0), coverage);
                    let proj = joint - qa;
                    if proj > amp[k] {
                        let d = proj - amp[k];
                        amp[k] = proj;
                        terms.additive[k] += d;
                        terms.errors.fixed[k] += d;
                        terms.multiplicative[k] = terms.additive[k] / terms.nominal[k].norm();
                    }
                }
                terms.amplitude = Some(amp);
            }
            self.shift = Some(ParameterShift {
                mean: (0..n).map(|m| xi[(m, 0)]).collect(),
                factor: psd_factor(&cov),
            });
        }
        Ok(ProjectedShift {
            statistic,
            threshold,
            kept,
        })
    }

    /// The dimension of the joint tangent space the entries' draws share (0 without one).
    fn tangent_dim(&self) -> usize {
        self.entries
            .iter()
            .flat_map(|e| e.errors.sens.iter().map(Vec::len))
            .max()
            .unwrap_or(0)
    }

    /// The line coverage the entries' bounds were computed with.
    fn line_coverage(&self) -> f64 {
        self.entries.first().map_or(0.95, |e| e.line_coverage)
    }

    /// The relative bound of entry $(i, j)$ per line, $L_{ij,k}/|\hat P_{ij}(z_k)|$ (the current
    /// `additive`, so after any raise; the `multiplicative` field is the one before it).
    ///
    /// # Errors
    /// [`Error::Numerical`] where the model's entry is zero or the ratio is not finite.
    pub fn entry_relative(&self, i: usize, j: usize) -> Result<Vec<f64>> {
        let e = self
            .entry(i, j)
            .ok_or_else(|| Error::invalid("entry", format!("({i}, {j}) is outside the matrix")))?;
        e.additive
            .iter()
            .zip(&e.nominal)
            .zip(&e.f_hz)
            .map(|((a, p), f)| {
                let r = a / p.norm();
                if r.is_finite() && r > 0.0 {
                    Ok(r)
                } else {
                    Err(Error::numerical(
                        CTX,
                        format!(
                            "entry ({i}, {j}) of the model is zero at {f} Hz: no relative bound there"
                        ),
                    ))
                }
            })
            .collect()
    }

    /// A structured weight for robust-control design: per entry, the stable minimum-phase
    /// weight of order at most `max_order` that overbounds the entry's relative bound
    /// ([`MatrixUncertainty::entry_relative`]) on the fraction `cover` of its lines
    /// ([`fit_weight`](super::weight::fit_weight)), entry $(i, j)$ at index $i + j\,n_y$. Together
    /// they describe $P_{ij} = \hat P_{ij}(1 + W_{ij}\delta_{ij})$, $|\delta_{ij}| \le 1$
    /// independent, the set
    /// [`robust_stability_matrix_weight`](super::robust::robust_stability_matrix_weight) checks
    /// with [`MatrixWeight::EntryRelative`](super::robust::MatrixWeight::EntryRelative). Relative
    /// per entry, not additive: outside the band the weight is extrapolated, and a relative one
    /// rolls off with the model's entry. The entries are fitted side by side.
    ///
    /// # Errors
    /// As [`MatrixUncertainty::entry_relative`] and [`fit_weight`](super::weight::fit_weight),
    /// naming the entry.
    pub fn entry_weights(
        &self,
        ts: f64,
        max_order: usize,
        cover: f64,
        form: EntryForm,
    ) -> Result<Vec<super::weight::WeightFit>> {
        self.entry_weights_shaped(
            ts,
            max_order,
            cover,
            form,
            super::weight::WeightShape::Smooth,
        )
    }

    /// [`Self::entry_weights`] with the weight family `shape`
    /// ([`fit_weight_shaped`](super::weight::fit_weight_shaped)); `Smooth` is
    /// [`Self::entry_weights`].
    ///
    /// # Errors
    /// Those of [`Self::entry_weights`].
    pub fn entry_weights_shaped(
        &self,
        ts: f64,
        max_order: usize,
        cover: f64,
        form: EntryForm,
        shape: super::weight::WeightShape,
    ) -> Result<Vec<super::weight::WeightFit>> {
        use rayon::prelude::*;
        let f = self.f_hz().to_vec();
        (0..self.outputs * self.inputs)
            .into_par_iter()
            .map(|e| {
                let (i, j) = (e % self.outputs, e / self.outputs);
                let bound = match form {
                    EntryForm::Relative => self.entry_relative(i, j)?,
                    EntryForm::Additive => self.entries[e].additive.clone(),
                };
                super::weight::fit_weight_shaped(&f, &bound, ts, max_order, cover, shape).map_err(
                    |err| Error::numerical(CTX, format!("the weight of entry ({i}, {j}): {err}")),
                )
            })
            .collect()
    }

    /// $\lVert L_k\rVert_2$ per line: a bound on $\bar\sigma(P - \hat P)$ (type docs), in the
    /// plant's units; for a SISO model the additive bound itself.
    pub fn norm_bound(&self) -> Vec<f64> {
        (0..self.f_hz().len())
            .map(|k| spectral_norm(&self.bound_at(k)))
            .collect()
    }
}

impl MatrixUncertainty {
    /// The input-multiplicative bound per line, $P = \hat P(I + \Delta_I)$ with
    /// $\bar\sigma(\Delta_I) \le \lVert\,|\hat P_k^{-1}|\,L_k\rVert_2$: $\Delta_I = \hat
    /// P^{-1}\Delta_A$ and $|\hat P^{-1}\Delta_A| \le |\hat P^{-1}|\,L$ element-wise (a square
    /// plant; for a SISO one the multiplicative bound $\ell_k$).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a plant that is not square; [`Error::Numerical`] where
    /// $\hat P(z_k)$ is singular.
    pub fn input_multiplicative_bound(&self) -> Result<Vec<f64>> {
        if self.outputs != self.inputs {
            return Err(Error::invalid(
                "nominal",
                format!(
                    "an input-multiplicative bound needs a square plant, this one is {}×{}",
                    self.outputs, self.inputs
                ),
            ));
        }
        let n = self.inputs;
        (0..self.f_hz().len())
            .map(|k| {
                let inv = crate::linalg::solve_c64(
                    self.nominal_at(k).as_ref(),
                    faer::Mat::<c64>::identity(n, n).as_ref(),
                )?;
                if (0..n).any(|i| (0..n).any(|j| !inv[(i, j)].norm().is_finite())) {
                    return Err(Error::numerical(
                        CTX,
                        format!("the model is singular at {} Hz", self.f_hz()[k]),
                    ));
                }
                let abs_inv = faer::Mat::from_fn(n, n, |i, j| inv[(i, j)].norm());
                Ok(spectral_norm(&(&abs_inv * &self.bound_at(k))))
            })
            .collect()
    }
}

/// What the per-entry weights of [`MatrixUncertainty::entry_weights`] overbound.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum EntryForm {
    /// $L_{ij}/|\hat P_{ij}|$: $P_{ij} = \hat P_{ij}(1 + W_{ij}\delta_{ij})$.
    Relative,
    /// $L_{ij}$ in the plant's units: $P_{ij} = \hat P_{ij} + W_{ij}\delta_{ij}$.
    Additive,
}

/// $\lVert L\rVert_2$ of a real matrix (its largest singular value; 0 when it cannot be
/// computed, which the finite, non-negative bounds never cause).
fn spectral_norm(l: &faer::Mat<f64>) -> f64 {
    crate::linalg::singular_values(l.as_ref())
        .ok()
        .and_then(|s| s.into_iter().reduce(f64::max))
        .unwrap_or(0.0)
}

/// The uncertainty of the nominal model `nominal` ($n_y$ outputs, $n_u$ inputs) around the
/// measured plant FRF `frd` ($n_y\times n_u$, with a variance per entry), entry by entry: the
/// terms of [`uncertainty`] for every channel $(i, j)$, with the model's channel
/// [`StateSpace::entry`] (all its states, so its poles) against the FRF's entry
/// [`Frd::entry`]. `extra` is empty or holds the terms (c)–(e) of each entry, in the order of
/// [`MatrixUncertainty::entries`]. A SISO model gives one entry, equal to [`uncertainty`]'s
/// result.
///
/// Term (a) comes from the fit of all entries together: the tangent space of the state-space
/// model set at $\hat P$ (the span of $\partial\hat P/\partial(A, B, C, D)$, of dimension
/// $n(n_y + n_u)$, and $n_y n_u$ more with a feed-through, whitened by every entry's variance), so one draw of
/// the parameters moves all entries at once ([`MatrixUncertainty::joint_raise`]). Per-entry SISO
/// tangent spaces of the same order ($2n$ parameters for each of the $n_y n_u$ entries) would
/// count 4× the parameters of a 4×4 model of order 16 and gave bounds 10× the true error on the
/// 4-axis twin. Terms (b)–(e) are per entry, as for a SISO model (term (b)'s noise variance uses
/// the joint leverage).
///
/// # Errors
/// As [`uncertainty`], naming the entry; [`Error::InvalidArgument`] also when the model's inputs
/// and outputs differ from the FRF's, or `extra` has neither 0 nor $n_y n_u$ items.
///
/// # Example
/// A diagonal 2×2 model against its own exact response with 1 % noise variance: each diagonal
/// entry's bound is small, and $\lVert L_k\rVert_2$ is the larger diagonal entry.
/// ```
/// use ambid_core::lti::{Frd, StateSpace};
/// use ambid_core::validate::uncertainty::{uncertainty_matrix, UncertaintyOptions};
/// use faer::mat;
/// let m = StateSpace::discrete(
///     mat![[0.9, 0.0], [0.0, 0.5]], mat![[1.0, 0.0], [0.0, 1.0]], mat![[0.1, 0.0], [0.0, 0.2]],
///     mat![[0.0, 0.0], [0.0, 0.0]], 1e-3,
/// ).unwrap();
/// let f: Vec<f64> = (1..=200).map(|k| k as f64 * 2.0).collect();
/// let exact = Frd::from_model(&m, &f).unwrap();
/// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr().max(1e-6)).collect();
/// let frd = Frd::new_matrix(f.clone(), 2, 2, exact.values().to_vec(), Some(var), Some(1e-3)).unwrap();
/// let u = uncertainty_matrix(&m, &frd, &[], &UncertaintyOptions::default()).unwrap();
/// assert_eq!(u.entries.len(), 4);
/// let (l, s) = (u.bound_at(10), u.norm_bound()[10]);
/// assert!(s >= l[(0, 0)].max(l[(1, 1)]) && s > 0.0);
/// assert!(u.entry(0, 0).unwrap().multiplicative[10] < 1e-2);
/// ```
pub fn uncertainty_matrix(
    nominal: &StateSpace,
    frd: &Frd,
    extra: &[ExtraTerms<'_>],
    opts: &UncertaintyOptions,
) -> Result<MatrixUncertainty> {
    let (ny, nu) = (frd.ny(), frd.nu());
    if nominal.noutputs() != ny || nominal.ninputs() != nu {
        return Err(Error::invalid(
            "nominal",
            format!(
                "the model has {} outputs and {} inputs, the FRF is {ny}×{nu}: use the model fitted to this FRF",
                nominal.noutputs(),
                nominal.ninputs()
            ),
        ));
    }
    if !(extra.is_empty() || extra.len() == ny * nu) {
        return Err(Error::invalid(
            "extra",
            format!(
                "needs no extra terms or one set per entry ({}), got {}",
                ny * nu,
                extra.len()
            ),
        ));
    }
    // a SISO model fitted on every line: the SISO tangent space; else the joint one, split
    // per entry
    // one line correlation for the whole FRF, its variances scaled for the joint tangent space
    let corr = line_correlation_of(nominal, frd, opts.fitted_band_hz, opts)?;
    let mut joint = if ny * nu > 1 || opts.fitted_band_hz.is_some() {
        joint_tangent_sensitivities(
            nominal,
            &*with_variance_factor(frd, corr.factor)?,
            opts.fitted_band_hz,
        )?
        .into_iter()
        .map(Some)
        .collect()
    } else {
        vec![None]
    };
    let mut entries = Vec::with_capacity(ny * nu);
    for j in 0..nu {
        for i in 0..ny {
            let e = extra.get(i + j * ny).copied().unwrap_or_default();
            let tangent = joint[i + j * ny].take();
            let terms = uncertainty_with(
                &nominal.entry(i, j)?,
                &frd.entry(i, j)?,
                &e,
                opts,
                tangent,
                Some(corr),
            )
            .map_err(|err| in_entry(err, i, j, ny * nu > 1))?;
            entries.push(terms);
        }
    }
    Ok(MatrixUncertainty {
        outputs: ny,
        inputs: nu,
        entries,
        shift: None,
    })
}

/// `err` with the entry $(i, j)$ named in its reason (when there are several entries).
fn in_entry(err: Error, i: usize, j: usize, several: bool) -> Error {
    if !several {
        return err;
    }
    match err {
        Error::InvalidArgument { name, reason } => Error::InvalidArgument {
            name,
            reason: format!("entry (output {i}, input {j}): {reason}"),
        },
        Error::Numerical { context, reason } => Error::Numerical {
            context,
            reason: format!("entry (output {i}, input {j}): {reason}"),
        },
        other => other,
    }
}

/// Term (f) of the module docs: per line of `frd`, $|\hat P(z_k) - \tilde P(z_k)|$, the
/// distance of the SISO `nominal` model from $\tilde P$, the inverse-variance state-space fit
/// to `frd` of the nominal's order with at most its number of unstable poles
/// ([`ss_frd`](crate::estimate::freqfit_ss::ss_frd), default options).
///
/// When the nominal model is the subspace-started fit (within $10^{-6}$ of $|\hat P|$ at the
/// median: the models step's own state-space fit, or one read back from a file), the term is
/// that distance (0 for the fit itself). Otherwise the fit is also refined from the nominal
/// model's own poles, and the one of lower cost is $\tilde P$ (the nominal's start when its
/// cost is lower by more than one part in $10^6$). A fit is a local optimum, and the subspace
/// start can end in a poor one: on random rig 531 of the nonlinear twin with a multisine excitation the order-7 fit from
/// the subspace start erred by 10.4 % of $|P|$ at the median, the chosen OE 7 by 0.51 %, and the
/// term was 15.6 % of $|\hat P|$, the weight 33 times the true error and its upper gain margin
/// short of half the true one. Started from the OE model's poles the fit's cost is 9 times
/// lower and the term $2 \times 10^{-7}$ (docs/uncertainty.md, "Term (f) from the nominal's
/// poles").
///
/// Term (a) is the error of *that* fit from the FRF's noise, and term (b) its misfit where the
/// data show one. A model of another structure or estimator (an output-error polynomial fitted
/// by its own iteration, a time-domain fit) or with other weights has its own error, which can
/// be larger than the fit's where the FRF is too noisy for its misfit to be significant. Since
/// $\hat P - P = (\hat P - \tilde P) + (\tilde P - P)$ exactly, the known distance
/// $|\hat P - \tilde P|$ added to the bound keeps it a bound for such a model; it is zero when
/// the nominal model is $\tilde P$. On the twin's workflow with a noise excitation (Welch FRF;
/// output-error polynomial models chosen on most rigs) the weight covered the true error on 89
/// of 100 linear rigs without it (docs/uncertainty.md, "A model not fitted to the FRF").
///
/// # Errors
/// A model that is not SISO or not discrete-time, or the fit failing (too few lines, a
/// numerical failure).
///
/// # Example
/// The FRF's own fit is at distance 0; a model 1 % off in gain is at 1 % of $|\hat P|$.
/// ```
/// use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
/// use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
/// use ambid_core::lti::{Frd, StateSpace};
/// use ambid_core::validate::uncertainty::fit_distance;
/// use faer::mat;
/// let ts = 1e-3;
/// let p = StateSpace::discrete(
///     mat![[1.6, -0.8], [1.0, 0.0]], mat![[1.0], [0.0]], mat![[0.1, 0.05]], mat![[0.0]], ts,
/// ).unwrap();
/// let f: Vec<f64> = (1..=200).map(|k| 2.0 * k as f64).collect();
/// let exact = Frd::from_model(&p, &f).unwrap();
/// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr()).collect();
/// let frd = Frd::new(f.clone(), exact.values().to_vec(), Some(var), Some(ts)).unwrap();
/// let opts = FreqFitOptions { weights: FreqWeights::InverseVariance, max_unstable_poles: Some(0), ..FreqFitOptions::default() };
/// let own = ss_frd(&frd, 2, &opts, &SsFreqOptions::default()).unwrap().model;
/// let d = fit_distance(&own, &frd).unwrap();
/// assert!(d.iter().zip(exact.values()).all(|(d, g)| *d <= 1e-9 * g.norm()));
/// let off = StateSpace::discrete(
///     mat![[1.6, -0.8], [1.0, 0.0]], mat![[1.0], [0.0]], mat![[0.101, 0.0505]], mat![[0.0]], ts,
/// ).unwrap();
/// let d = fit_distance(&off, &frd).unwrap();
/// let p_off = off.freq_response_siso(&f).unwrap();
/// assert!(d.iter().zip(&p_off).all(|(d, p)| (d / p.norm() - 0.01 / 1.01).abs() < 1e-6));
/// ```
pub fn fit_distance(nominal: &StateSpace, frd: &Frd) -> Result<Vec<f64>> {
    if nominal.ninputs() != 1 || nominal.noutputs() != 1 {
        return Err(Error::invalid("nominal", "term (f) needs a SISO model"));
    }
    let p_hat = nominal.freq_response_siso(frd.f_hz())?;
    own_fit_distance(nominal, &nominal.poles()?, &p_hat, frd, None)
}

/// [`fit_distance`] with the nominal model's `poles` and response `p_hat` on `frd`'s lines,
/// already computed; with `noise` ([`ExtraTerms::fit_noise`]) the reference fit is the sample
/// maximum-likelihood one.
fn own_fit_distance(
    nominal: &StateSpace,
    poles: &[c64],
    p_hat: &[c64],
    frd: &Frd,
    noise: Option<&[crate::frf::closed_loop::RatioNoise]>,
) -> Result<Vec<f64>> {
    use crate::estimate::freqfit::{FreqFitOptions, FreqWeights};
    use crate::estimate::freqfit_ss::{ss_frd_started, SsFreqOptions};
    let unstable = poles.iter().filter(|p| p.norm() > 1.0).count();
    let opts = FreqFitOptions {
        weights: noise.map_or(FreqWeights::InverseVariance, |n| {
            FreqWeights::SampleMaximumLikelihood(n.to_vec())
        }),
        max_unstable_poles: Some(unstable),
        ..FreqFitOptions::default()
    };
    let order = nominal.order().max(1);
    let fit =
        |start: Option<&[c64]>| ss_frd_started(frd, order, &opts, &SsFreqOptions::default(), start);
    let distance = |own: &StateSpace| -> Result<Vec<f64>> {
        let b = own.freq_response_siso(frd.f_hz())?;
        Ok(p_hat.iter().zip(&b).map(|(x, y)| (x - y).norm()).collect())
    };
    let subspace = fit(None);
    // the nominal is the subspace-started fit itself: the term is that distance ([`fit_distance`])
    if let Ok(s) = &subspace {
        let d = distance(&s.model)?;
        let mut rel: Vec<f64> = d.iter().zip(p_hat).map(|(d, p)| d / p.norm()).collect();
        rel.sort_by(f64::total_cmp);
        if rel
            .get(rel.len() / 2)
            .is_some_and(|m| *m <= FIT_DISTANCE_SAME_FIT)
        {
            return Ok(d);
        }
    }
    // both starts; the nominal's own poles' fit where it is the better one ([`fit_distance`])
    let warm = conjugate_poles(poles).and_then(|p| fit(Some(&p)).ok());
    let own = match (subspace, warm) {
        (Ok(s), Some(w)) if w.cost < s.cost * (1.0 - FIT_DISTANCE_START_MARGIN) => w,
        (Ok(s), _) => s,
        (Err(_), Some(w)) => w,
        (Err(e), None) => {
            return Err(Error::numerical(
                "the FRF's own fit for term (f)",
                format!(
                    "order {}: {e}; bound the model without term (f) (`fit_distance` off)",
                    nominal.order()
                ),
            ))
        }
    }
    .model;
    distance(&own)
}

/// How much lower (relative) the cost of term (f)'s fit started from the nominal model's poles
/// must be than the subspace-started fit's for it to be taken ([`fit_distance`]): rounding
/// apart.
const FIT_DISTANCE_START_MARGIN: f64 = 1e-6;

/// The median distance, relative to $|\hat P|$, within which the nominal model *is* the
/// subspace-started fit ([`fit_distance`]): a model written to a file and read back, or the
/// models step's own fit. Term (f) is then that distance, and the second start is not tried.
const FIT_DISTANCE_SAME_FIT: f64 = 1e-6;

/// `poles` as exact conjugate pairs and real poles (an imaginary part within $10^{-10}(1 + |p|)$
/// of 0 taken as real), or `None` when they do not pair up.
fn conjugate_poles(poles: &[c64]) -> Option<Vec<c64>> {
    let snap = |p: &c64| {
        if p.im.abs() <= 1e-10 * (1.0 + p.norm()) {
            c64::new(p.re, 0.0)
        } else {
            *p
        }
    };
    let clean: Vec<c64> = poles.iter().map(snap).collect();
    let mut out: Vec<c64> = clean.iter().filter(|p| p.im == 0.0).copied().collect();
    for p in clean.iter().filter(|p| p.im > 0.0) {
        out.extend([*p, p.conj()]);
    }
    // `out` has real + 2 × upper poles: all of them exactly when as many lie below the real
    // axis as above it
    (out.len() == poles.len()).then_some(out)
}

/// The deterministic terms (d) and (e) at line `k`, added in magnitude.
fn fixed_extra(extra: &ExtraTerms<'_>, k: usize) -> f64 {
    extra.operating_spread.map_or(0.0, |s| s[k]) + extra.amplitude_shift.map_or(0.0, |s| s[k])
}

/// The half-width $M$ of term (b)'s window, in lines of `f_hz`, for the model `model` (module
/// docs: half the half-power bandwidth of its most lightly damped pole in the band, clamped to
/// $[1, 8]$ lines; 8 when no pole lies in the band). Other smoothed terms use it so that no
/// window is wider than a resonance.
///
/// # Errors
/// A continuous-time model, or one whose poles cannot be computed.
///
/// # Example
/// ```
/// use ambid_core::lti::StateSpace;
/// use ambid_core::validate::uncertainty::window_half_lines_for;
/// use faer::mat;
/// // poles 0.9 ± 0.3j at 1 kHz sampling: ζ ≈ 0.16 at 52 Hz, a half-power band of ≈ 17 Hz
/// let m = StateSpace::discrete(
///     mat![[1.8, -0.9], [1.0, 0.0]], mat![[1.0], [0.0]], mat![[1.0, 0.0]], mat![[0.0]], 1e-3,
/// ).unwrap();
/// let f: Vec<f64> = (1..=200).map(|k| k as f64).collect();
/// assert_eq!(window_half_lines_for(&m, &f).unwrap(), 8); // 17 Hz / 2 on 1 Hz lines, clamped
/// ```
pub fn window_half_lines_for(model: &StateSpace, f_hz: &[f64]) -> Result<usize> {
    let ts = model
        .ts()
        .ok_or_else(|| Error::invalid("model", "needs a discrete-time model"))?;
    Ok(window_half_lines(&model.poles()?, f_hz, ts))
}

/// $M$ of the misfit window (module docs): half the half-power bandwidth of the most lightly
/// damped pole of the model with its natural frequency in the band, in lines, in $[1, 8]$.
fn window_half_lines(poles: &[c64], f: &[f64], ts: f64) -> usize {
    let l = f.len();
    if l < 3 {
        return 1;
    }
    let mut gaps: Vec<f64> = f.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    gaps.sort_by(f64::total_cmp);
    let df = gaps[gaps.len() / 2].max(f64::MIN_POSITIVE);
    let (flo, fhi) = (f[0].min(f[l - 1]), f[0].max(f[l - 1]));
    let mut bw_min = f64::INFINITY;
    for &p in poles {
        if p.norm() <= ORIGIN_POLE || p.im < 0.0 {
            continue;
        }
        let s = p.ln() / ts;
        let fn_hz = s.norm() / (2.0 * std::f64::consts::PI);
        if fn_hz < flo || fn_hz > fhi || s.im.abs() < 1e-12 {
            continue;
        }
        let zeta = (-s.re / s.norm()).abs();
        bw_min = bw_min.min(2.0 * zeta * fn_hz);
    }
    if !bw_min.is_finite() {
        return 8;
    }
    ((bw_min / (2.0 * df)).floor() as usize).clamp(1, 8)
}

/// The $(1-\alpha)$ quantile of $|x|$, $x = (x_r, x_i)$ Gaussian of covariance
/// $\begin{bmatrix} c_{rr} & c_{ri} \\ c_{ri} & c_{ii}\end{bmatrix}$ (module docs).
pub fn abs_quantile(crr: f64, cii: f64, cri: f64, alpha: f64) -> f64 {
    let tr = crr + cii;
    if tr <= 0.0 || !tr.is_finite() {
        return 0.0;
    }
    let disc = (0.25 * (crr - cii).powi(2) + cri * cri).sqrt();
    let l1 = 0.5 * tr + disc;
    let l2 = (0.5 * tr - disc).max(0.0);
    const NODES: usize = 64;
    let exceed = |s: f64| -> f64 {
        let mut acc = 0.0;
        for i in 0..NODES {
            let phi = std::f64::consts::PI * (i as f64 + 0.5) / NODES as f64;
            let gphi = l1 * phi.cos().powi(2) + l2 * phi.sin().powi(2);
            if gphi > 0.0 {
                acc += (-s / (2.0 * gphi)).exp();
            }
        }
        acc / NODES as f64
    };
    // P(|x|² > s) ≤ exp(-s / (2 λ1)): s_hi = 2 λ1 ln(1/α) exceeds with at most α
    bisect_decreasing(
        exceed,
        alpha,
        (0.0, 2.0 * l1 * (1.0 / alpha).ln()),
        80,
        1e-12,
    )
    .sqrt()
}

/// Eigenvalues of $A$ at most this magnitude are poles at the origin (delays; a Jordan block at
/// 0 is perturbed by rounding to about $\varepsilon^{1/m}$, $10^{-5}$ for $m = 3$).
const ORIGIN_POLE: f64 = 1e-4;

/// $n_\theta$ of a model with the poles `poles` (module docs): $2n - m$, $+1$ with a feed-through.
/// $J_{ij,k} R$ of a state-space model with several inputs and outputs, per entry (index $i +
/// j n_y$) and line, with $R R^{\mathsf T} = F^{-1}$ for the inverse-variance weighted fit of all
/// entries together ([`uncertainty_matrix`]): the model set's tangent space is the span of
/// $\partial\hat P/\partial\theta$ over $\theta = (A, B, C, D)$ entry by entry,
/// $$ \frac{\partial \hat P_{ij}}{\partial A_{rs}} = Y_{ir} X_{sj}, \quad
///    \frac{\partial \hat P_{ij}}{\partial B_{rj}} = Y_{ir}, \quad
///    \frac{\partial \hat P_{ij}}{\partial C_{is}} = X_{sj}, \quad
///    \frac{\partial \hat P_{ij}}{\partial D_{ij}} = 1 , $$
/// $X = (zI - A)^{-1}B$, $Y = C(zI - A)^{-1}$ (the $D$ columns when the model has a
/// feed-through). Its $n^2$ similarity directions are null, so the span has dimension $n(n_y +
/// n_u)\ (+ n_y n_u)$ at most: the orthonormal basis is the leading left singular vectors of the
/// whitened Jacobian (rows $\sqrt{2/\sigma^2_{ij,k}}\,(\operatorname{Re}, \operatorname{Im})$,
/// columns scaled to unit norm), as many as exceed $10^{-9}$ of the largest, capped at that
/// dimension. Returns per entry the sensitivities, the dimension $n_\theta$ and which lines lie
/// in `fitted_band_hz` (all without one): the SVD is of the fitted lines' rows alone, and every
/// line's sensitivity is its whitened row times $V\Sigma^{-1}$ (on a fitted line the left
/// singular vector's row).
fn joint_tangent_sensitivities(
    model: &StateSpace,
    frd: &Frd,
    fitted_band_hz: Option<[f64; 2]>,
) -> Result<Vec<Tangent>> {
    let (n, ny, nu) = (model.order(), model.noutputs(), model.ninputs());
    let e = ny * nu;
    let l = frd.len();
    let ts = model
        .ts()
        .ok_or_else(|| Error::invalid("nominal", "needs a discrete-time model"))?;
    let var = positive_variances(frd)?;
    let fitted: Vec<bool> = match fitted_band_hz {
        None => vec![true; l],
        Some([a, b]) if a.is_finite() && b.is_finite() && a <= b => {
            let tol = 1e-9 * b.abs().max(1.0);
            frd.f_hz()
                .iter()
                .map(|f| *f >= a - tol && *f <= b + tol)
                .collect()
        }
        Some(band) => {
            return Err(Error::invalid(
                "fitted_band_hz",
                format!("must be a finite band [low, high] with low ≤ high, got {band:?}"),
            ))
        }
    };
    let fit_lines: Vec<usize> = (0..l).filter(|k| fitted[*k]).collect();
    let has_d = (0..ny).any(|i| (0..nu).any(|j| model.d()[(i, j)] != 0.0));
    let n_cols = n * n + n * nu + ny * n + if has_d { e } else { 0 };
    let dim = (n * (ny + nu) + if has_d { e } else { 0 }).min(n_cols);
    let rows_fit = 2 * fit_lines.len() * e;
    if rows_fit <= dim {
        return Err(Error::invalid(
            "frd",
            format!(
                "{} fitted lines of {e} entries give {rows_fit} real equations for {dim} model parameters; widen the band{}",
                fit_lines.len(),
                if fitted_band_hz.is_some() { " (or the fitted band)" } else { "" }
            ),
        ));
    }
    let rows = 2 * l * e;
    let mut jac = faer::Mat::<f64>::zeros(rows, n_cols);
    let a = model.a();
    for k in 0..l {
        let z = c64::from_polar(1.0, 2.0 * std::f64::consts::PI * frd.f_hz()[k] * ts);
        let zi_a = faer::Mat::from_fn(n, n, |r, c| {
            let d = if r == c { z } else { c64::new(0.0, 0.0) };
            d - c64::new(a[(r, c)], 0.0)
        });
        let b = faer::Mat::from_fn(n, nu, |r, c| c64::new(model.b()[(r, c)], 0.0));
        let ct = faer::Mat::from_fn(n, ny, |r, c| c64::new(model.c()[(c, r)], 0.0));
        let on_pole = |_| {
            Error::numerical(
                CTX,
                format!(
                    "a pole of the model lies on the line at {} Hz",
                    frd.f_hz()[k]
                ),
            )
        };
        let x = crate::linalg::solve_c64(zi_a.as_ref(), b.as_ref()).map_err(on_pole)?;
        let yt = crate::linalg::solve_c64(zi_a.transpose().to_owned().as_ref(), ct.as_ref())
            .map_err(on_pole)?;
        for j in 0..nu {
            for i in 0..ny {
                let w = (2.0 / var[k * e + j * ny + i]).sqrt();
                let row = 2 * (k * e + j * ny + i);
                let mut put = |col: usize, v: c64| {
                    jac[(row, col)] = w * v.re;
                    jac[(row + 1, col)] = w * v.im;
                };
                for r in 0..n {
                    for s2 in 0..n {
                        put(r * n + s2, yt[(r, i)] * x[(s2, j)]);
                    }
                    put(n * n + r * nu + j, yt[(r, i)]);
                }
                for s2 in 0..n {
                    put(n * n + n * nu + i * n + s2, x[(s2, j)]);
                }
                if has_d {
                    put(n * n + n * nu + ny * n + j * ny + i, c64::new(1.0, 0.0));
                }
            }
        }
    }
    // the rows of the fitted lines: the fit's whitened Jacobian (every row when all lines were
    // fitted); its columns scaled to unit norm over those rows, every line's row with them
    let all_fitted = fit_lines.len() == l;
    let fit_row = |r: usize| 2 * fit_lines[r / (2 * e)] * e + r % (2 * e);
    for c in 0..n_cols {
        let norm = (0..rows_fit)
            .map(|r| jac[(fit_row(r), c)].powi(2))
            .sum::<f64>()
            .sqrt();
        if norm > 0.0 && norm.is_finite() {
            for r in 0..rows {
                jac[(r, c)] /= norm;
            }
        }
    }
    let svd = if all_fitted {
        jac.thin_svd()
    } else {
        faer::Mat::<f64>::from_fn(rows_fit, n_cols, |r, c| jac[(fit_row(r), c)]).thin_svd()
    }
    .map_err(|err| {
        Error::numerical(
            CTX,
            format!("the SVD of the model's Jacobian failed ({err:?})"),
        )
    })?;
    let sv: Vec<f64> = svd.S().column_vector().iter().copied().collect();
    let top = sv.first().copied().unwrap_or(0.0);
    if !(top > 0.0 && top.is_finite()) {
        return Err(Error::numerical(
            CTX,
            "the model's Jacobian on the lines vanishes",
        ));
    }
    let rank = sv.iter().filter(|v| **v > 1e-9 * top).count().min(dim);
    // every line's whitened row mapped into the fit's orthonormal basis, Ĵ V Σ⁻¹: on a fitted
    // line the left singular vector's row itself, on a validation line the tangent map there
    let basis: faer::Mat<f64> = if all_fitted {
        svd.U().subcols(0, rank).to_owned()
    } else {
        let v = svd.V();
        let vs = faer::Mat::<f64>::from_fn(n_cols, rank, |r, c| v[(r, c)] / sv[c]);
        &jac * &vs
    };
    Ok((0..e)
        .map(|ent| {
            let sens = (0..l)
                .map(|k| {
                    let row = 2 * (k * e + ent);
                    let h = (0.5 * var[k * e + ent]).sqrt();
                    (0..rank)
                        .map(|c| c64::new(h * basis[(row, c)], h * basis[(row + 1, c)]))
                        .collect()
                })
                .collect();
            Tangent {
                sens,
                dim: rank,
                fitted: fitted.clone(),
            }
        })
        .collect())
}

/// A tangent space handed to [`uncertainty_with`]: $J_k R$ per line, its dimension and which
/// lines were fitted ([`UncertaintyOptions::fitted_band_hz`]).
struct Tangent {
    sens: Vec<Vec<c64>>,
    dim: usize,
    fitted: Vec<bool>,
}

/// The FRF's variances, every one positive and finite.
fn positive_variances(frd: &Frd) -> Result<&[f64]> {
    let var = frd.variance().ok_or_else(|| {
        Error::invalid(
            "frd",
            "the FRF has no variances: estimate it from at least two periods (or realisations) so that its confidence region is known",
        )
    })?;
    if var.iter().any(|v| !(*v > 0.0 && v.is_finite())) {
        return Err(Error::invalid(
            "frd",
            "every line's variance (of every entry) must be positive and finite",
        ));
    }
    Ok(var)
}

fn tangent_dim(poles: &[c64], has_d: bool) -> usize {
    let m = poles.iter().filter(|p| p.norm() <= ORIGIN_POLE).count();
    2 * poles.len() - m + usize::from(has_d)
}

/// $J_k R$ with $R R^{\mathsf T} = F^{-1}$ (module docs): per line $k$, $\sqrt{\sigma_k^2/2}\,
/// q_{k,c}$ for an orthonormal basis $q_{\cdot,c}$ of the whitened tangent space
/// $\{\sqrt{2/\sigma_k^2}\,N(z_k)/(z_k^m A_0(z_k)^2)\}$ in the real inner product
/// $\operatorname{Re}\sum_k \bar a_k b_k$. The basis comes from real Arnoldi on the
/// multiplication by $z_k$ (an orthogonal map), with two passes of Gram–Schmidt: a stable
/// construction of the polynomials $N$ on the lines, never the ill-conditioned monomials.
fn tangent_sensitivities(
    poles: &[c64],
    has_d: bool,
    z: &[c64],
    var: &[f64],
) -> Result<Vec<Vec<c64>>> {
    let l = z.len();
    let dim = tangent_dim(poles, has_d);
    let m = poles.iter().filter(|p| p.norm() <= ORIGIN_POLE).count();
    let inner = |a: &[c64], b: &[c64]| -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| x.re * y.re + x.im * y.im)
            .sum()
    };
    let norm = |a: &[c64]| inner(a, a).sqrt();
    let mut v: Vec<c64> = z
        .iter()
        .zip(var)
        .map(|(&zk, &vk)| c64::new((2.0 / vk).sqrt(), 0.0) * zk.powi(-(m as i32)))
        .collect();
    // 1/A_0(z)^2 factor by factor, rescaled as it goes (the span does not see the scale)
    for &p in poles.iter().filter(|p| p.norm() > ORIGIN_POLE) {
        for (vk, &zk) in v.iter_mut().zip(z) {
            let d = zk - p;
            *vk /= d * d;
        }
        let s = v.iter().map(|x| x.norm()).fold(0.0f64, f64::max);
        if !(s > 0.0 && s.is_finite()) {
            return Err(Error::numerical(
                CTX,
                "the model has a pole on a line of the FRF (its response is infinite there); remove that line or refit the model",
            ));
        }
        v.iter_mut().for_each(|x| *x /= s);
    }
    let mut q: Vec<Vec<c64>> = Vec::with_capacity(dim);
    for j in 0..dim {
        let mut w: Vec<c64> = if j == 0 {
            v.clone()
        } else {
            q[j - 1].iter().zip(z).map(|(a, zk)| a * zk).collect()
        };
        let before = norm(&w);
        for _ in 0..2 {
            for qi in &q {
                let h = inner(qi, &w);
                w.iter_mut().zip(qi).for_each(|(x, y)| *x -= y * h);
            }
        }
        let after = norm(&w);
        if !(after > 1e-10 * before && after.is_finite()) {
            return Err(Error::numerical(
                CTX,
                format!(
                    "the lines do not determine the model's {dim} parameters (only {j} independent directions); use a lower order or a wider band"
                ),
            ));
        }
        w.iter_mut().for_each(|x| *x /= after);
        q.push(w);
    }
    Ok((0..l)
        .map(|k| {
            let s = (0.5 * var[k]).sqrt();
            q.iter().map(|qc| qc[k] * s).collect()
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Term (f)'s second start takes the nominal's poles as exact conjugate pairs: a real pole
    /// with a rounding-sized imaginary part becomes real, a pair becomes exact conjugates, and
    /// poles that do not pair up give no start.
    #[test]
    fn the_nominals_poles_are_paired_for_term_fs_start() {
        let c = |re: f64, im: f64| c64::new(re, im);
        let got = conjugate_poles(&[
            c(0.5, 1e-17),
            c(0.9, 0.1),
            c(0.9, -0.1 - 1e-15),
            c(-0.2, 0.0),
        ]);
        assert_eq!(
            got,
            Some(vec![c(0.5, 0.0), c(-0.2, 0.0), c(0.9, 0.1), c(0.9, -0.1)])
        );
        assert_eq!(conjugate_poles(&[c(0.9, 0.1), c(0.5, 0.0)]), None);
        assert_eq!(conjugate_poles(&[c(0.9, 0.1), c(0.8, 0.2)]), None);
        assert_eq!(conjugate_poles(&[]), Some(vec![]));
    }
    use faer::{mat, Mat};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The quantile of a circular complex Gaussian of variance σ² is σ √ln(1/α); of a real one
    /// (a degenerate ellipse) the two-sided normal quantile.
    #[test]
    fn abs_quantile_matches_the_circular_and_the_real_case() {
        let q = abs_quantile(0.5, 0.5, 0.0, 0.05);
        assert!((q - (20f64).ln().sqrt()).abs() < 1e-9, "{q}");
        let q = abs_quantile(1.0, 0.0, 0.0, 0.05);
        assert!((q - 1.959_963_984_540_054).abs() < 1e-6, "{q}");
        // rotation invariance
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        let (l1, l2) = (2.0, 0.5);
        let q1 = abs_quantile(
            l1 * c * c + l2 * s * s,
            l1 * s * s + l2 * c * c,
            (l1 - l2) * c * s,
            0.01,
        );
        let q2 = abs_quantile(l1, l2, 0.0, 0.01);
        assert!((q1 - q2).abs() < 1e-9 * q2);
    }

    /// The same quantile against a naive Monte Carlo oracle on an ellipse.
    #[test]
    fn abs_quantile_matches_monte_carlo() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (l1, l2) = (3.0, 0.2);
        let mut v: Vec<f64> = (0..200_000)
            .map(|_| {
                let (a, b) = gauss_pair(&mut rng);
                (l1 * a * a + l2 * b * b).sqrt()
            })
            .collect();
        v.sort_by(f64::total_cmp);
        let mc = v[(0.99 * v.len() as f64) as usize];
        let q = abs_quantile(l1, l2, 0.0, 0.01);
        assert!((q - mc).abs() < 0.01 * q, "{q} vs {mc}");
    }

    fn gauss_pair(rng: &mut ChaCha8Rng) -> (f64, f64) {
        let u1: f64 = rng.random_range(f64::EPSILON..1.0);
        let u2: f64 = rng.random_range(0.0..1.0);
        let r = (-2.0 * u1.ln()).sqrt();
        let t = 2.0 * std::f64::consts::PI * u2;
        (r * t.cos(), r * t.sin())
    }

    /// `exact`'s lines and values with the variances `var`, at sample time `ts`.
    fn with_var(exact: &Frd, var: Option<Vec<f64>>, ts: f64) -> Frd {
        Frd::new(
            exact.f_hz().to_vec(),
            exact.values().to_vec(),
            var,
            Some(ts),
        )
        .unwrap()
    }

    /// [`model`] on 150 lines with 1e-3 relative variances: the model, the lines, the FRF and
    /// its variances.
    fn model_on_lines() -> (StateSpace, Vec<f64>, Frd, Vec<f64>) {
        let m = model();
        let f: Vec<f64> = (1..=150).map(|k| k as f64 * 1.5).collect();
        let exact = Frd::from_model(&m, &f).unwrap();
        let var: Vec<f64> = exact.values().iter().map(|g| 1e-3 * g.norm_sqr()).collect();
        let frd = with_var(&exact, Some(var.clone()), 1e-3);
        (m, f, frd, var)
    }

    fn default_terms(m: &StateSpace, frd: &Frd) -> UncertaintyTerms {
        uncertainty(
            m,
            frd,
            &ExtraTerms::default(),
            &UncertaintyOptions::default(),
        )
        .unwrap()
    }

    fn model() -> StateSpace {
        model_with_gain(1.0)
    }

    /// [`model`] with its output matrix times `g`.
    fn model_with_gain(g: f64) -> StateSpace {
        // an unstable real pole and a lightly damped pair
        let (r, w) = (0.995f64, 0.2f64);
        StateSpace::discrete(
            mat![
                [1.004, 0.0, 0.0],
                [0.0, r * w.cos(), r * w.sin()],
                [0.0, -r * w.sin(), r * w.cos()]
            ],
            mat![[1.0], [0.3], [1.0]],
            mat![[0.02 * g, 0.01 * g, 0.004 * g]],
            mat![[0.0]],
            1e-3,
        )
        .unwrap()
    }

    /// Term (f): on the exact response (noise-free values, 3 % standard deviation per line)
    /// the model itself is the FRF's own fit, at distance ≈ 0, and the bound is the one without
    /// term (f). A model 2 % off in gain is at $0.02\,|P|$ from that fit, i.e. $0.02/1.02$ of
    /// its own $|\hat P|$ (analytic), its additive bound is the one without term (f) plus
    /// exactly that distance, and the term is what makes it cover the model's true error on
    /// every line. Terms (a) and (b) alone cover it on 4 of the 150: term (a) describes the
    /// fit, not this model, and term (b) keeps only the misfit's excess over its significance
    /// threshold (2 % against 3.2 % noise per line).
    #[test]
    fn fit_distance_is_the_distance_from_the_frfs_own_fit() {
        let (m, f, frd, _) = model_on_lines();
        let off_opts = UncertaintyOptions {
            fit_distance: false,
            ..UncertaintyOptions::default()
        };
        let on = default_terms(&m, &frd);
        let off = uncertainty(&m, &frd, &ExtraTerms::default(), &off_opts).unwrap();
        let d = on.fit_distance.as_ref().expect("term (f)");
        assert!(on.fit_distance_failed.is_none() && off.fit_distance.is_none());
        for (k, dk) in d.iter().enumerate() {
            let p = on.nominal[k].norm();
            assert!(*dk <= 1e-6 * p, "line {k}: {}", dk / p);
            assert!((on.additive[k] - off.additive[k] - dk).abs() <= 1e-12 * on.additive[k]);
        }
        let biased = model_with_gain(1.02);
        let on = default_terms(&biased, &frd);
        let off = uncertainty(&biased, &frd, &ExtraTerms::default(), &off_opts).unwrap();
        let d = on.fit_distance.as_ref().expect("term (f)");
        let truth = frd.values();
        let (mut covered_on, mut covered_off) = (0, 0);
        for k in 0..f.len() {
            let p = on.nominal[k].norm();
            assert!(
                (d[k] / p - 0.02 / 1.02).abs() < 1e-6,
                "line {k}: {}",
                d[k] / p
            );
            assert!((on.additive[k] - off.additive[k] - d[k]).abs() <= 1e-12 * on.additive[k]);
            let err = (on.nominal[k] - truth[k]).norm();
            covered_on += usize::from(on.additive[k] >= err);
            covered_off += usize::from(off.additive[k] >= err);
        }
        assert_eq!(covered_on, f.len());
        assert!(covered_off < f.len() / 2, "{covered_off}");
    }

    /// The projector $\tilde J \tilde J^{+}$ onto the span of the whitened real Jacobian
    /// columns `cols` (each one complex value per line) and its singular values: the oracle's
    /// side of the tangent-space tests, from an SVD of the columns themselves.
    /// The columns whitened: rows $\sqrt{2/\sigma_k^2}\,(\operatorname{Re}, \operatorname{Im})$.
    fn whitened(cols: &[Vec<c64>], var: &[f64]) -> Mat<f64> {
        Mat::<f64>::from_fn(2 * var.len(), cols.len(), |r, c| {
            let v = cols[c][r / 2] * (2.0 / var[r / 2]).sqrt();
            if r % 2 == 0 {
                v.re
            } else {
                v.im
            }
        })
    }

    fn span_projector(cols: &[Vec<c64>], var: &[f64], rank: usize) -> (Mat<f64>, Vec<f64>) {
        let l = var.len();
        let svd = whitened(cols, var).thin_svd().unwrap();
        let s: Vec<f64> = (0..cols.len()).map(|i| svd.S()[i]).collect();
        let u = svd.U();
        let p = Mat::<f64>::from_fn(2 * l, 2 * l, |a, b| {
            (0..rank).map(|c| u[(a, c)] * u[(b, c)]).sum()
        });
        (p, s)
    }

    /// The projector $Q Q^{\mathsf T}$ of [`tangent_sensitivities`] (whitened back).
    fn tangent_projector(sens: &[Vec<c64>], var: &[f64]) -> Mat<f64> {
        let l = var.len();
        let q = |r: usize, c: usize| {
            let v = sens[r / 2][c] * (2.0 / var[r / 2]).sqrt();
            if r % 2 == 0 {
                v.re
            } else {
                v.im
            }
        };
        let n = sens[0].len();
        Mat::<f64>::from_fn(2 * l, 2 * l, |a, b| (0..n).map(|c| q(a, c) * q(b, c)).sum())
    }

    fn max_abs_diff(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
        let mut m = 0.0f64;
        for i in 0..a.nrows() {
            for j in 0..a.ncols() {
                m = m.max((a[(i, j)] - b[(i, j)]).abs());
            }
        }
        m
    }

    /// $\lVert (I - QQ^{\mathsf T})\,\tilde c\rVert / \lVert\tilde c\rVert$ of the whitened
    /// column `col` against the basis of `sens`.
    fn outside_fraction(sens: &[Vec<c64>], var: &[f64], col: &[c64]) -> f64 {
        let l = var.len();
        let w: Vec<c64> = (0..l).map(|k| col[k] * (2.0 / var[k]).sqrt()).collect();
        let q = |k: usize, c: usize| sens[k][c] * (2.0 / var[k]).sqrt();
        let mut r = w.clone();
        for c in 0..sens[0].len() {
            let h: f64 = (0..l)
                .map(|k| q(k, c).re * w[k].re + q(k, c).im * w[k].im)
                .sum();
            for (k, rk) in r.iter_mut().enumerate() {
                *rk -= q(k, c) * h;
            }
        }
        let n = |v: &[c64]| v.iter().map(|x| x.norm_sqr()).sum::<f64>().sqrt();
        n(&r) / n(&w)
    }

    /// The real-parameter partial-fraction columns of distinct poles away from the origin:
    /// $1/(z-p)$ and $1/(z-p)^2$, by real and imaginary parts for a pair.
    fn partial_fraction_columns(poles: &[c64], z: &[c64]) -> Vec<Vec<c64>> {
        let one = c64::new(1.0, 0.0);
        let j = c64::new(0.0, 1.0);
        let mut cols: Vec<Vec<c64>> = Vec::new();
        for &p in poles
            .iter()
            .filter(|p| p.im >= 0.0 && p.norm() > ORIGIN_POLE)
        {
            let a1: Vec<c64> = z.iter().map(|zk| one / (zk - p)).collect();
            if p.im > 1e-12 {
                let b1: Vec<c64> = z.iter().map(|zk| one / (zk - p.conj())).collect();
                for pw in [1, 2] {
                    cols.push(
                        a1.iter()
                            .zip(&b1)
                            .map(|(x, y)| x.powi(pw) + y.powi(pw))
                            .collect(),
                    );
                    cols.push(
                        a1.iter()
                            .zip(&b1)
                            .map(|(x, y)| j * x.powi(pw) - j * y.powi(pw))
                            .collect(),
                    );
                }
            } else {
                let a1: Vec<c64> = z.iter().map(|zk| one / (zk - p.re)).collect();
                cols.push(a1.clone());
                cols.push(a1.iter().map(|x| x * x).collect());
            }
        }
        cols
    }

    /// Central finite differences of the model's response on the lines over every entry of
    /// $A$, $B$, $C$ (and $D$ with `with_d`): columns that span the tangent space of the
    /// order-$n$ models (and many more columns than its dimension).
    fn fd_state_space_columns(m: &StateSpace, f: &[f64], with_d: bool) -> Vec<Vec<c64>> {
        let (n, ts) = (m.order(), m.ts().unwrap());
        let mut cols = Vec::new();
        let mut entries: Vec<(usize, usize, usize)> = Vec::new();
        for i in 0..n {
            for j in 0..n {
                entries.push((0, i, j));
            }
            entries.push((1, i, 0));
            entries.push((2, 0, i));
        }
        if with_d {
            entries.push((3, 0, 0));
        }
        for (which, i, j) in entries {
            let eval = |h: f64| {
                let (mut a, mut b, mut c, mut d) = (
                    m.a().to_owned(),
                    m.b().to_owned(),
                    m.c().to_owned(),
                    m.d().to_owned(),
                );
                match which {
                    0 => a[(i, j)] += h,
                    1 => b[(i, j)] += h,
                    2 => c[(i, j)] += h,
                    _ => d[(i, j)] += h,
                }
                StateSpace::discrete(a, b, c, d, ts)
                    .unwrap()
                    .freq_response_siso(f)
                    .unwrap()
            };
            let h = 1e-6;
            let (p, q) = (eval(h), eval(-h));
            cols.push(p.iter().zip(&q).map(|(x, y)| (x - y) / (2.0 * h)).collect());
        }
        cols
    }

    fn lines_z(f: &[f64], ts: f64) -> Vec<c64> {
        f.iter()
            .map(|fk| c64::from_polar(1.0, 2.0 * std::f64::consts::PI * fk * ts))
            .collect()
    }

    /// The tangent basis spans what the model's state-space entries move, by finite differences
    /// (an independent oracle: 15 columns of rank 6, or 16 of rank 7 with a feed-through),
    /// and is orthonormal, so the leverages sum to $n_\theta/2$.
    #[test]
    fn the_tangent_basis_spans_the_state_space_jacobian() {
        let (m0, f, _, var) = model_on_lines();
        for with_d in [false, true] {
            let m = if with_d {
                StateSpace::discrete(
                    m0.a().to_owned(),
                    m0.b().to_owned(),
                    m0.c().to_owned(),
                    mat![[0.05]],
                    1e-3,
                )
                .unwrap()
            } else {
                m0.clone()
            };
            let dim = 6 + usize::from(with_d);
            let poles = m.poles().unwrap();
            assert_eq!(tangent_dim(&poles, with_d), dim);
            let sens = tangent_sensitivities(&poles, with_d, &lines_z(&f, 1e-3), &var).unwrap();
            assert_eq!(sens[0].len(), dim);
            let (oracle, s) = span_projector(&fd_state_space_columns(&m, &f, with_d), &var, dim);
            // the finite differences have rank dim: a clear gap after it
            assert!(s[dim - 1] > 1e-5 * s[0], "{s:?}");
            assert!(s[dim] < 1e-8 * s[0], "{s:?}");
            let mine = tangent_projector(&sens, &var);
            let diff = max_abs_diff(&mine, &oracle);
            assert!(diff < 1e-6, "with_d {with_d}: projector differs by {diff}");
            let lever: f64 = (0..f.len())
                .map(|k| sens[k].iter().map(|x| x.norm_sqr()).sum::<f64>() / var[k])
                .sum();
            assert!((lever - dim as f64 / 2.0).abs() < 1e-9, "{lever}");
            let u = default_terms(
                &m,
                &with_var(&Frd::from_model(&m, &f).unwrap(), Some(var.clone()), 1e-3),
            );
            assert_eq!(u.n_params, dim);
            assert!(u.model_error.iter().all(|&b| b == 0.0));
        }
    }

    /// Lines beyond the fitted band ([`UncertaintyOptions::fitted_band_hz`]): every line's
    /// $J_k R$ gives the covariance $J_k F^{+} J_k^{\mathsf T}$ of the model at that line, with
    /// the information $F$ of the fitted lines alone. The oracle is computed here from finite
    /// differences of the state-space entries (rank 6 of 15 columns), the lines 1–100 fitted,
    /// 101–150 validation lines. A SISO model
    /// goes through the joint tangent space as its 1×1 case.
    #[test]
    fn validation_lines_carry_the_fitted_lines_covariance() {
        let (m, f, frd, var) = model_on_lines();
        let fitted = [f[0], f[99]];
        let opts = UncertaintyOptions {
            fitted_band_hz: Some(fitted),
            ..UncertaintyOptions::default()
        };
        let u = uncertainty_matrix(&m, &frd, &[], &opts).unwrap();
        let e = &u.entries[0];
        assert_eq!(e.n_params, 6);
        let cols = fd_state_space_columns(&m, &f, false);
        // whitened Jacobian of the fitted lines, its pseudo-inverse information of rank 6
        let jw = Mat::<f64>::from_fn(200, cols.len(), |r, c| {
            let v = cols[c][r / 2] * (2.0 / var[r / 2]).sqrt();
            if r % 2 == 0 {
                v.re
            } else {
                v.im
            }
        });
        let svd = jw.thin_svd().unwrap();
        let v = svd.V();
        let sv: Vec<f64> = (0..cols.len()).map(|i| svd.S()[i]).collect();
        assert!(sv[5] > 1e-5 * sv[0] && sv[6] < 1e-8 * sv[0], "{sv:?}");
        let mut worst = 0.0f64;
        for k in 0..f.len() {
            // t_c = r_k · v_c / s_c for the real and imaginary rows
            let t: Vec<c64> = (0..6)
                .map(|c| {
                    let x: c64 = (0..cols.len()).map(|q| cols[q][k] * v[(q, c)]).sum();
                    x / sv[c]
                })
                .collect();
            let oracle = [
                t.iter().map(|x| x.re * x.re).sum::<f64>(),
                t.iter().map(|x| x.im * x.im).sum::<f64>(),
                t.iter().map(|x| x.re * x.im).sum::<f64>(),
            ];
            let sk = &e.errors.sens[k];
            let mine = [
                sk.iter().map(|x| x.re * x.re).sum::<f64>(),
                sk.iter().map(|x| x.im * x.im).sum::<f64>(),
                sk.iter().map(|x| x.re * x.im).sum::<f64>(),
            ];
            let scale = oracle[0] + oracle[1];
            assert!(scale > 0.0, "line {k}");
            for q in 0..3 {
                worst = worst.max((mine[q] - oracle[q]).abs() / scale);
            }
        }
        assert!(worst < 1e-6, "covariance differs by {worst} of its trace");
        // on the fitted lines it is the bound of the FRF cut to them
        let cut = frd.band(fitted[0], fitted[1]).unwrap();
        let alone = uncertainty_matrix(&m, &cut, &[], &UncertaintyOptions::default()).unwrap();
        for k in 0..100 {
            let (a, b) = (e.frf_confidence[k], alone.entries[0].frf_confidence[k]);
            assert!((a - b).abs() < 1e-6 * b, "line {k}: {a} vs {b}");
        }
    }

    /// A misfit above the fitted band, where the model was never fitted: term (b) measures it
    /// on the validation lines (0.1 |P̂| of a model 10 % below the FRF there) and stays 0 on
    /// the fitted lines away from the edge; bad fitted bands are refused.
    #[test]
    fn term_b_measures_a_misfit_on_the_validation_lines() {
        let (m, f, frd, var) = model_on_lines();
        let g: Vec<c64> = frd
            .values()
            .iter()
            .zip(&f)
            .map(|(g, fk)| if *fk > f[99] { g * 1.1 } else { *g })
            .collect();
        let var: Vec<f64> = var.iter().map(|v| v * 0.1).collect();
        let frd = Frd::new(f.clone(), g, Some(var), Some(1e-3)).unwrap();
        let opts = UncertaintyOptions {
            fitted_band_hz: Some([f[0], f[99]]),
            ..UncertaintyOptions::default()
        };
        let u = uncertainty_matrix(&m, &frd, &[], &opts).unwrap();
        let e = &u.entries[0];
        for k in 0..f.len() {
            let rel = e.model_error[k] / e.nominal[k].norm();
            if k >= 110 {
                assert!((rel - 0.1).abs() < 0.02, "line {k}: term (b) {rel}");
                assert!(e.additive[k] >= (frd.values()[k] - e.nominal[k]).norm());
            } else if k < 80 {
                assert_eq!(e.model_error[k], 0.0, "line {k}");
            }
        }
        for bad in [[f64::NAN, 10.0], [50.0, 10.0]] {
            let opts = UncertaintyOptions {
                fitted_band_hz: Some(bad),
                ..UncertaintyOptions::default()
            };
            let err = uncertainty_matrix(&m, &frd, &[], &opts).unwrap_err();
            assert!(err.to_string().contains("fitted_band_hz"), "{err}");
        }
        let opts = UncertaintyOptions {
            fitted_band_hz: Some([f[0], f[1]]),
            ..UncertaintyOptions::default()
        };
        let err = uncertainty_matrix(&m, &frd, &[], &opts).unwrap_err();
        assert!(err.to_string().contains("fitted lines"), "{err}");
    }

    /// A model with two delay poles at the origin (a Jordan block: no eigenvector basis) has
    /// the tangent space of its other poles' partial fractions plus $c_1 z^{-1} + c_2 z^{-2}$:
    /// the projector matches the one of that explicit basis ($1/(z-p)$ and $1/(z-p)^2$ by real
    /// and imaginary parts, and $z^{-1}, z^{-2}$), $n_\theta = 8$.
    #[test]
    fn a_model_with_delay_poles_gets_its_delay_terms() {
        let m0 = model();
        let n0 = m0.order();
        let n = n0 + 2;
        // u → x_d1 → x_d2 → the base model's input
        let a = Mat::<f64>::from_fn(n, n, |i, j| match (i < n0, j < n0) {
            (true, true) => m0.a()[(i, j)],
            (true, false) if j == n0 + 1 => m0.b()[(i, 0)],
            (false, false) => f64::from(i == n0 + 1 && j == n0),
            _ => 0.0,
        });
        let b = Mat::<f64>::from_fn(n, 1, |i, _| f64::from(i == n0));
        let c = Mat::<f64>::from_fn(1, n, |_, j| if j < n0 { m0.c()[(0, j)] } else { 0.0 });
        let m = StateSpace::discrete(a, b, c, mat![[0.0]], 1e-3).unwrap();
        let f: Vec<f64> = (1..=150).map(|k| k as f64 * 1.5).collect();
        let exact = m.freq_response_siso(&f).unwrap();
        let base = m0.freq_response_siso(&f).unwrap();
        let z = lines_z(&f, 1e-3);
        for k in 0..f.len() {
            // the delayed model is the base one times z^-2
            assert!((exact[k] - base[k] * z[k].powi(-2)).norm() < 1e-12 * base[k].norm());
        }
        let var: Vec<f64> = exact.iter().map(|g| 1e-3 * g.norm_sqr()).collect();
        let poles = m.poles().unwrap();
        assert_eq!(tangent_dim(&poles, false), 8);
        let sens = tangent_sensitivities(&poles, false, &z, &var).unwrap();
        // the explicit partial-fraction columns
        let mut cols = partial_fraction_columns(&m0.poles().unwrap(), &z);
        for d in 1..=2 {
            cols.push(z.iter().map(|zk| zk.powi(-d)).collect());
        }
        assert_eq!(cols.len(), 8);
        let (oracle, s) = span_projector(&cols, &var, 8);
        assert!(s[7] > 1e-8 * s[0], "{s:?}");
        let diff = max_abs_diff(&tangent_projector(&sens, &var), &oracle);
        assert!(diff < 1e-7, "projector differs by {diff}");
        let frd = Frd::new(f, exact, Some(var), Some(1e-3)).unwrap();
        let u = default_terms(&m, &frd);
        assert_eq!(u.n_params, 8);
        assert!(u.frf_confidence.iter().all(|q| q.is_finite() && *q > 0.0));
    }

    /// The chosen model of random rig 65 (an OE 7 at 20 kHz, one unstable pole, poles from
    /// 63 Hz to 2 kHz) in the companion realisation its polynomials give: the pole–residue form
    /// this module used before did not reproduce it (eigenvectors too ill-conditioned), so
    /// the workflow skipped the step. The tangent basis matches the finite-difference
    /// projector of that realisation on 10–1000 Hz.
    #[test]
    fn an_oe_model_of_an_unseen_rig_gets_its_bound() {
        let ts = 5e-5;
        let b = vec![
            0.0,
            2.3907137349706874e-8,
            -1.6176411226823583e-7,
            5.212797497960586e-7,
            -9.422020759667078e-7,
            9.600638067194606e-7,
            -5.132304137514163e-7,
            1.1194818787030255e-7,
        ];
        let fp = vec![
            1.0,
            -6.453702571323267,
            17.799301958868277,
            -27.169276205806693,
            24.75856962383618,
            -13.447514314652128,
            4.022130028670141,
            -0.5095085301704295,
        ];
        let m = crate::lti::PolyModel::oe(b.clone(), fp.clone(), ts)
            .unwrap()
            .g()
            .unwrap()
            .to_state_space()
            .unwrap();
        assert_eq!(m.order(), 7);
        let f: Vec<f64> = (1..=100).map(|k| k as f64 * 10.0).collect();
        let exact = m.freq_response_siso(&f).unwrap();
        let var: Vec<f64> = exact.iter().map(|g| 1e-4 * g.norm_sqr()).collect();
        let z = lines_z(&f, ts);
        let poles = m.poles().unwrap();
        let has_d = m.d()[(0, 0)] != 0.0;
        assert!(!has_d);
        let dim = tangent_dim(&poles, has_d);
        assert_eq!(dim, 14);
        let sens = tangent_sensitivities(&poles, has_d, &z, &var).unwrap();
        // the oracle: the OE model's own Jacobian, analytic, ∂P/∂b_i = z^-i / F and
        // ∂P/∂f_i = -B z^-i / F^2 (q = z^-1)
        let poly = |c: &[f64], q: c64| {
            c.iter()
                .rev()
                .fold(c64::new(0.0, 0.0), |acc, x| acc * q + x)
        };
        let mut cols: Vec<Vec<c64>> = Vec::new();
        for i in 1..=7 {
            cols.push(
                z.iter()
                    .map(|zk| zk.powi(-i) / poly(&fp, zk.inv()))
                    .collect(),
            );
        }
        for i in 1..=7 {
            cols.push(
                z.iter()
                    .map(|zk| {
                        let (bq, fq) = (poly(&b, zk.inv()), poly(&fp, zk.inv()));
                        -bq * zk.powi(-i) / (fq * fq)
                    })
                    .collect(),
            );
        }
        for (k, zk) in z.iter().enumerate() {
            let p = poly(&b, zk.inv()) / poly(&fp, zk.inv());
            assert!((p - exact[k]).norm() < 1e-6 * exact[k].norm());
        }
        // every column lies in the basis's span (a residual check, no inversion: these 14
        // columns have a condition number near 1e15)
        for c in &cols {
            let out = outside_fraction(&sens, &var, c);
            // 1e-6: F evaluated by Horner is about 1e-8 on the low lines against coefficients
            // summing to 95, so the oracle itself carries ~1e-6 relative rounding there
            assert!(
                out < 1e-6,
                "an OE Jacobian column is {out} outside the span"
            );
        }
        // and so do the partial fractions of the distinct poles, which have full rank 14: the
        // spans are equal
        let pf = partial_fraction_columns(&poles, &z);
        assert_eq!(pf.len(), dim);
        let (oracle, s) = span_projector(&pf, &var, dim);
        assert!(s[dim - 1] > 1e-10 * s[0], "{s:?}");
        let diff = max_abs_diff(&tangent_projector(&sens, &var), &oracle);
        assert!(diff < 1e-5, "projector differs by {diff}");
        let frd = Frd::new(f, exact, Some(var), Some(ts)).unwrap();
        let u = default_terms(&m, &frd);
        assert_eq!(u.n_params, dim);
        assert!(u.multiplicative.iter().all(|x| x.is_finite() && *x > 0.0));
    }

    /// The draws of the model's error reproduce the exact per-line quantile of term (a) at every
    /// line, and the joint factor is that quantile where one line holds the band, larger for
    /// all lines at once, smaller for half of them, and reproducible from its seed.
    #[test]
    fn the_error_draws_reproduce_the_per_line_quantile() {
        use rand::SeedableRng;
        let (m, f, frd, _) = model_on_lines();
        let u = default_terms(&m, &frd);
        let q: Vec<f64> = (0..f.len())
            .map(|k| u.frf_confidence[k] / u.nominal[k].norm())
            .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (draws, mut inside, mut e) = (4000, vec![0usize; f.len()], Vec::new());
        for _ in 0..draws {
            u.errors.draw_relative(&mut rng, &mut e);
            for k in 0..f.len() {
                inside[k] += usize::from(e[k] <= q[k]);
            }
        }
        for (k, n) in inside.iter().enumerate() {
            let frac = *n as f64 / draws as f64;
            assert!((frac - 0.95).abs() < 0.015, "line {k}: {frac}");
        }
        let g = |m: &[f64], cover: f64, seed: u64| {
            u.errors.joint_factor(m, cover, 0.95, 4000, seed).unwrap()
        };
        // every other line far above its error: line 40 alone decides, its 95 % point is q
        let mut one: Vec<f64> = q.iter().map(|v| v * 1e6).collect();
        one[40] = q[40];
        let g_one = g(&one, 1.0, 1);
        assert!((g_one - 1.0).abs() < 0.03, "{g_one}");
        let (g_all, g_half) = (g(&q, 1.0, 1), g(&q, 0.5, 1));
        assert!(g_all > 1.05 && g_half < 1.0, "{g_all} {g_half}");
        assert_eq!(g(&q, 0.95, 3), g(&q, 0.95, 3));
        // several magnitudes from one set of draws: each as a call of its own
        let both = u
            .errors
            .joint_factors(&[&one, &q], 1.0, 0.95, 4000, 1)
            .unwrap();
        assert_eq!(both, vec![g_one, g_all]);
        assert!(u.errors.joint_factor(&q[1..], 0.95, 0.95, 10, 0).is_err());
        assert!(u.errors.joint_factor(&q, 0.95, 1.5, 10, 0).is_err());
        assert!(u.errors.joint_factor(&q, 0.95, 0.95, 0, 0).is_err());
    }

    /// A misfit that the noise does not explain becomes term (b); the operating spread is
    /// added as given; the nonlinear term widens the Gaussian part.
    #[test]
    fn a_systematic_misfit_and_the_extra_terms_enter_the_bound() {
        let m = model();
        let f: Vec<f64> = (1..=150).map(|k| k as f64 * 1.5).collect();
        let exact = Frd::from_model(&m, &f).unwrap();
        // a 5 % smooth misfit, noise 1 %
        let g: Vec<c64> = exact.values().iter().map(|v| v * 1.05).collect();
        let var: Vec<f64> = exact.values().iter().map(|v| 1e-4 * v.norm_sqr()).collect();
        let frd = Frd::new(f.clone(), g, Some(var.clone()), Some(1e-3)).unwrap();
        let base = uncertainty(
            &m,
            &frd,
            &ExtraTerms::default(),
            &UncertaintyOptions::default(),
        )
        .unwrap();
        let mut rel: Vec<f64> = base
            .model_error
            .iter()
            .zip(&base.nominal)
            .map(|(b, p)| b / p.norm())
            .collect();
        rel.sort_by(f64::total_cmp);
        assert!((rel[75] - 0.05).abs() < 0.01, "{}", rel[75]);
        let spread = vec![1e-3; f.len()];
        let shift = vec![2e-3; f.len()];
        let nl: Vec<f64> = exact.values().iter().map(|v| 0.05 * v.norm()).collect();
        let ext = ExtraTerms {
            nonlinear_std: Some(&nl),
            operating_spread: Some(&spread),
            amplitude_shift: Some(&shift),
            fit_noise: None,
        };
        let more = uncertainty(&m, &frd, &ext, &UncertaintyOptions::default()).unwrap();
        assert_eq!(more.amplitude.as_deref(), Some(shift.as_slice()));
        for k in 0..f.len() {
            assert!(more.additive[k] >= base.additive[k] + 3e-3 * (1.0 - 1e-12));
            let q = more.nonlinear.as_ref().unwrap()[k];
            assert!((q - 0.05 * exact.values()[k].norm() * 20f64.ln().sqrt()).abs() < 1e-9 * q);
        }
    }

    /// `misfit_roughness` against a naive oracle: per line the complex quadratic in the line
    /// index fitted by solving its 3×3 normal equations over the seven lines, its residual at
    /// the centre over that residual's variance (from the same solve, line by line), the median
    /// over ln 2. A quadratic misfit (what a smooth model error looks like over seven lines) has
    /// roughness 0; fewer than seven lines or a zero variance give none.
    #[test]
    fn misfit_roughness_matches_a_naive_quadratic_fit() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let l = 60;
        let e: Vec<c64> = (0..l)
            .map(|_| c64::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)))
            .collect();
        let var: Vec<f64> = (0..l).map(|_| rng.random_range(0.5..2.0)).collect();
        // the centre value of the least-squares quadratic through (x, y), x = -3..3, as the
        // weights it puts on y: solve the normal equations for each unit vector
        let centre_weights = || -> Vec<f64> {
            let xs: Vec<f64> = (-3..=3).map(f64::from).collect();
            let mut a = [[0.0f64; 3]; 3];
            for x in &xs {
                let row = [1.0, *x, x * x];
                for i in 0..3 {
                    for j in 0..3 {
                        a[i][j] += row[i] * row[j];
                    }
                }
            }
            (0..7)
                .map(|unit| {
                    // A c = X^T e_unit by Gauss elimination; the centre value is c_0
                    let (mut m, mut r) = (a, [1.0, xs[unit], xs[unit] * xs[unit]]);
                    for p in 0..3 {
                        for q in p + 1..3 {
                            let f = m[q][p] / m[p][p];
                            let pivot = m[p];
                            for (mc, pc) in m[q].iter_mut().zip(pivot).skip(p) {
                                *mc -= f * pc;
                            }
                            r[q] -= f * r[p];
                        }
                    }
                    let mut c = [0.0f64; 3];
                    for p in (0..3).rev() {
                        let s: f64 = (p + 1..3).map(|c2| m[p][c2] * c[c2]).sum();
                        c[p] = (r[p] - s) / m[p][p];
                    }
                    c[0]
                })
                .collect()
        };
        let h = centre_weights();
        let mut z: Vec<f64> = (3..l - 3)
            .map(|k| {
                let mut r = e[k];
                let mut v = 0.0;
                for j in 0..7 {
                    let c = f64::from(u8::from(j == 3)) - h[j];
                    r -= e[k + j - 3] * h[j];
                    v += c * c * var[k + j - 3];
                }
                r.norm_sqr() / v
            })
            .collect();
        z.sort_by(f64::total_cmp);
        let oracle = 0.5 * (z[z.len() / 2 - 1] + z[z.len() / 2]) / std::f64::consts::LN_2;
        let got = misfit_roughness(&e, &var).unwrap();
        assert!((got - oracle).abs() <= 1e-12 * oracle, "{got} vs {oracle}");
        // a quadratic misfit is smooth: nothing is left
        let q: Vec<c64> = (0..l)
            .map(|k| {
                let x = k as f64;
                c64::new(0.3 + 0.01 * x - 2e-4 * x * x, -0.1 + 3e-4 * x * x)
            })
            .collect();
        assert!(misfit_roughness(&q, &var).unwrap() < 1e-16);
        assert_eq!(misfit_roughness(&e[..6], &var[..6]), None);
        let mut zero = var.clone();
        zero[10] = 0.0;
        assert_eq!(misfit_roughness(&e, &zero), None);
    }

    /// A fixed misfit that is white over the lines, 5 σ on every line (one multisine
    /// realisation's nonlinear distortion, shared by any second measurement of it): the windows
    /// average it to about 5 σ/√3 and below, so the windows alone stay under it on most lines;
    /// with the line alone ([`PerLineMisfit::On`]) it carries the misfit, as its upper value,
    /// and the bound covers it on ≥ 95 % of the lines. The default ([`PerLineMisfit::Auto`])
    /// sees the roughness and does the same, but not when a term (c) is given. A smooth 5 %
    /// misfit gets a term with the line alone at least the windows', above the misfit on every
    /// line, and at most 5 σ above the larger of the two; the default keeps the windows there.
    #[test]
    fn the_line_alone_bounds_a_misfit_that_changes_from_line_to_line() {
        let m = model();
        let f: Vec<f64> = (1..=300).map(|k| k as f64 * 0.75).collect();
        let exact = Frd::from_model(&m, &f).unwrap();
        let var: Vec<f64> = exact.values().iter().map(|v| 1e-6 * v.norm_sqr()).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let d: Vec<c64> = exact
            .values()
            .iter()
            .zip(&var)
            .map(|(_, v)| {
                let phi = rng.random_range(0.0..std::f64::consts::TAU);
                c64::from_polar(5.0 * v.sqrt(), phi)
            })
            .collect();
        let g: Vec<c64> = exact.values().iter().zip(&d).map(|(a, b)| a + b).collect();
        let frd = Frd::new(f.clone(), g, Some(var.clone()), Some(1e-3)).unwrap();
        let covered = |opts: &UncertaintyOptions| {
            let u = uncertainty(&m, &frd, &ExtraTerms::default(), opts).unwrap();
            (0..f.len())
                .filter(|&k| u.additive[k] >= d[k].norm())
                .count() as f64
                / f.len() as f64
        };
        let with = |per_line_misfit| UncertaintyOptions {
            per_line_misfit,
            ..UncertaintyOptions::default()
        };
        let windows = covered(&with(PerLineMisfit::Off));
        let alone = covered(&with(PerLineMisfit::On));
        assert!(windows < 0.5, "the windows cover {windows}");
        assert!(alone >= 0.95, "the line alone covers {alone}");
        // the default sees the misfit's roughness and takes the line alone, unless a term (c)
        // is given
        let auto =
            uncertainty(&m, &frd, &ExtraTerms::default(), &with(PerLineMisfit::Auto)).unwrap();
        let rough = auto.misfit_roughness.unwrap();
        assert!(rough >= ROUGH_MISFIT && auto.per_line_misfit, "{rough}");
        assert_eq!(covered(&UncertaintyOptions::default()), alone);
        let nl = vec![1e-9; f.len()];
        let given_c = ExtraTerms {
            nonlinear_std: Some(&nl),
            ..ExtraTerms::default()
        };
        let u = uncertainty(&m, &frd, &given_c, &with(PerLineMisfit::Auto)).unwrap();
        assert!(!u.per_line_misfit);
        // a smooth misfit: the windows already see it
        let g: Vec<c64> = exact.values().iter().map(|v| v * 1.05).collect();
        let frd = Frd::new(f.clone(), g, Some(var.clone()), Some(1e-3)).unwrap();
        let b = |opts: &UncertaintyOptions| {
            uncertainty(&m, &frd, &ExtraTerms::default(), opts)
                .unwrap()
                .model_error
        };
        let (w, a) = (b(&with(PerLineMisfit::Off)), b(&with(PerLineMisfit::On)));
        // smooth: the default keeps the windows alone
        let auto = uncertainty(
            &m,
            &frd,
            &ExtraTerms::default(),
            &UncertaintyOptions::default(),
        )
        .unwrap();
        assert!(!auto.per_line_misfit, "{:?}", auto.misfit_roughness);
        assert!(auto.misfit_roughness.unwrap() < 1.0);
        assert_eq!(auto.model_error, w);
        for k in 0..f.len() {
            let (sd, e) = (var[k].sqrt(), 0.05 * exact.values()[k].norm());
            assert!(w[k] > 10.0 * sd, "line {k}: the smooth misfit is seen");
            // where |P| changes fast (the unstable pole's low lines) the windows' weighted
            // means fall below the line's own misfit; the line alone does not
            assert!(
                a[k] >= w[k] && a[k] >= e,
                "line {k}: {} vs {} and {e}",
                a[k],
                w[k]
            );
            assert!(a[k] <= w[k].max(e) + 5.0 * sd, "line {k}: {} vs {e}", a[k]);
        }
    }

    #[test]
    fn bad_input_is_refused() {
        let m = model();
        let f: Vec<f64> = (1..=50).map(|k| k as f64).collect();
        let exact = Frd::from_model(&m, &f).unwrap();
        let plain = with_var(&exact, None, 1e-3);
        let e = uncertainty(
            &m,
            &plain,
            &ExtraTerms::default(),
            &UncertaintyOptions::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("no variances"), "{e}");
        let var = vec![1e-6; 50];
        let frd = with_var(&exact, Some(var.clone()), 1e-3);
        let short = vec![0.0; 3];
        let ext = ExtraTerms {
            nonlinear_std: Some(&short),
            ..ExtraTerms::default()
        };
        assert!(uncertainty(&m, &frd, &ext, &UncertaintyOptions::default()).is_err());
        let negative = vec![-1e-3; 50];
        let ext = ExtraTerms {
            amplitude_shift: Some(&negative),
            ..ExtraTerms::default()
        };
        let e = uncertainty(&m, &frd, &ext, &UncertaintyOptions::default()).unwrap_err();
        assert!(e.to_string().contains("amplitude_shift"), "{e}");
        let opts = UncertaintyOptions {
            line_coverage: 1.0,
            ..Default::default()
        };
        assert!(uncertainty(&m, &frd, &ExtraTerms::default(), &opts).is_err());
        let other_ts = with_var(&exact, Some(var.clone()), 2e-3);
        assert!(uncertainty(
            &m,
            &other_ts,
            &ExtraTerms::default(),
            &UncertaintyOptions::default()
        )
        .is_err());
    }

    /// Noise correlated between neighbouring lines (a moving average with lag-1 correlation
    /// 0.44, a Hann-windowed Welch FRF's): term (a) with the misfit's factor matches the
    /// per-line 95 % quantile of the fitted error by Monte Carlo (an oracle that projects each
    /// noise draw onto the span of the model's partial fractions, another basis of the tangent
    /// space), and taking the lines as independent falls short of it by about
    /// $1/\sqrt{1 + 2\rho}$. Independent noise gives factor 1 and the same bound as `Off`.
    #[test]
    fn correlated_lines_widen_term_a_to_the_fitted_errors_quantile() {
        use rand_distr::{Distribution, StandardNormal};
        let (m, f, exact, var) = model_on_lines();
        let l = f.len();
        let z = lines_z(&f, 1e-3);
        let poles = m.poles().unwrap();
        let cols = partial_fraction_columns(&poles, &z);
        let dim = tangent_dim(&poles, false);
        // the oracle's basis: leading left singular vectors of the whitened columns
        let svd = whitened(&cols, &var).thin_svd().unwrap();
        let u = svd.U();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut gauss = || {
            let re: f64 = StandardNormal.sample(&mut rng);
            let im: f64 = StandardNormal.sample(&mut rng);
            c64::new(re, im) * std::f64::consts::FRAC_1_SQRT_2
        };
        // x_k = a w_k + b w_{k-1}: unit variance, lag-1 correlation ab = 0.44
        let b = ((1.0 - (1.0 - 4.0 * 0.44f64 * 0.44).sqrt()) / 2.0).sqrt();
        let a = (1.0 - b * b).sqrt();
        assert!((a * b - 0.44).abs() < 1e-12);
        let mut ma = |corr: bool| -> Vec<c64> {
            let w: Vec<c64> = (0..=l).map(|_| gauss()).collect();
            (0..l)
                .map(|k| {
                    if corr {
                        w[k + 1] * a + w[k] * b
                    } else {
                        w[k + 1]
                    }
                })
                .collect()
        };
        let draws = 2000;
        let mut mags: Vec<Vec<f64>> = vec![Vec::with_capacity(draws); l];
        for _ in 0..draws {
            let x = ma(true);
            // whitened noise: (Re, Im) of x_k with variance 1/2 each, times sqrt(2)
            let e: Vec<f64> = (0..2 * l)
                .map(|r| {
                    let v = x[r / 2] * std::f64::consts::SQRT_2;
                    if r % 2 == 0 {
                        v.re
                    } else {
                        v.im
                    }
                })
                .collect();
            let coef: Vec<f64> = (0..dim)
                .map(|c| (0..2 * l).map(|r| u[(r, c)] * e[r]).sum())
                .collect();
            for (k, mk) in mags.iter_mut().enumerate() {
                let (mut re, mut im) = (0.0, 0.0);
                for (c, co) in coef.iter().enumerate() {
                    re += u[(2 * k, c)] * co;
                    im += u[(2 * k + 1, c)] * co;
                }
                // back from whitened units: δP̂_k = (re + j im) σ_k / sqrt(2)
                mk.push(c64::new(re, im).norm() * (var[k] / 2.0).sqrt());
            }
        }
        let q95: Vec<f64> = mags
            .into_iter()
            .map(|mut v| {
                v.sort_by(f64::total_cmp);
                v[(0.95 * draws as f64) as usize]
            })
            .collect();
        let mut bound = |corr: bool, setting: CorrelatedLines| {
            let noise = ma(corr);
            let g: Vec<c64> = exact
                .values()
                .iter()
                .zip(&noise)
                .zip(&var)
                .map(|((p, n), v)| p + n * v.sqrt())
                .collect();
            let frd = Frd::new(f.clone(), g, Some(var.clone()), Some(1e-3)).unwrap();
            let opts = UncertaintyOptions {
                correlated_lines: setting,
                ..UncertaintyOptions::default()
            };
            uncertainty(&m, &frd, &ExtraTerms::default(), &opts).unwrap()
        };
        let median_ratio = |t: &UncertaintyTerms| {
            let mut r: Vec<f64> = (0..l).map(|k| t.frf_confidence[k] / q95[k]).collect();
            r.sort_by(f64::total_cmp);
            r[l / 2]
        };
        let auto = bound(true, CorrelatedLines::Auto);
        let c = auto.line_correlation;
        assert!(
            (c.rho1 - 0.44).abs() < 0.1 && c.z > CORRELATED_LINES_Z,
            "{c:?}"
        );
        assert!((c.factor - 1.88).abs() < 0.3, "{c:?}");
        let ra = median_ratio(&auto);
        assert!((0.88..1.15).contains(&ra), "term (a) with the factor: {ra}");
        let off = bound(true, CorrelatedLines::Off);
        assert_eq!(off.line_correlation.factor, 1.0);
        let ro = median_ratio(&off);
        assert!(ro < 0.85, "term (a) taking the lines as independent: {ro}");
        assert!((ra / ro - c.factor.sqrt()).abs() < 0.05, "{ra} {ro} {c:?}");
        // independent noise: no factor, the same bound as Off
        let ind = bound(false, CorrelatedLines::Auto);
        assert_eq!(
            ind.line_correlation.factor, 1.0,
            "{:?}",
            ind.line_correlation
        );
        assert!(ind.line_correlation.z.abs() < CORRELATED_LINES_Z);
    }

    /// The joint tangent space of [`uncertainty_matrix`] (SVD of the whitened state-space
    /// Jacobian) for a SISO model is the SISO tangent space (Arnoldi on the partial-fraction
    /// space), with and without a feed-through: the two projectors agree.
    #[test]
    fn the_joint_tangent_of_a_siso_model_is_its_siso_tangent() {
        let (m0, f, _, var) = model_on_lines();
        for with_d in [false, true] {
            let m = StateSpace::discrete(
                m0.a().to_owned(),
                m0.b().to_owned(),
                m0.c().to_owned(),
                mat![[if with_d { 0.05 } else { 0.0 }]],
                1e-3,
            )
            .unwrap();
            let frd = with_var(&Frd::from_model(&m, &f).unwrap(), Some(var.clone()), 1e-3);
            let t = joint_tangent_sensitivities(&m, &frd, None).unwrap();
            let (joint, dim) = (vec![t[0].sens.clone()], t[0].dim);
            assert_eq!(dim, 6 + usize::from(with_d));
            let poles = m.poles().unwrap();
            let siso = tangent_sensitivities(&poles, with_d, &lines_z(&f, 1e-3), &var).unwrap();
            let diff = max_abs_diff(
                &tangent_projector(&joint[0], &var),
                &tangent_projector(&siso, &var),
            );
            assert!(diff < 1e-6, "with_d {with_d}: projectors differ by {diff}");
        }
    }

    /// The coupled 2×2 model of order 3 of the matrix tests, its 150 lines (1.5 Hz apart), its
    /// exact response and an FRF of it with the variance `rel_var` |P|² per entry.
    fn coupled_2x2(rel_var: f64) -> (StateSpace, Vec<f64>, Frd, Frd) {
        let m1 = model();
        let m = StateSpace::discrete(
            m1.a().to_owned(),
            mat![[1.0, 0.5], [0.3, -0.2], [1.0, 0.7]],
            mat![[0.02, 0.01, 0.004], [0.01, -0.02, 0.006]],
            mat![[0.0, 0.0], [0.0, 0.0]],
            1e-3,
        )
        .unwrap();
        let f: Vec<f64> = (1..=150).map(|k| k as f64 * 1.5).collect();
        let exact = Frd::from_model(&m, &f).unwrap();
        let var: Vec<f64> = exact
            .values()
            .iter()
            .map(|g| rel_var * g.norm_sqr())
            .collect();
        let frd = Frd::new_matrix(
            f.clone(),
            2,
            2,
            exact.values().to_vec(),
            Some(var),
            Some(1e-3),
        )
        .unwrap();
        (m, f, exact, frd)
    }

    /// A coupled 2×2 model of order 3 against its exact response: the joint tangent space has
    /// $n(n_y + n_u) = 12$ dimensions, its leverages over all entries and lines sum to 6; the
    /// element-wise, norm and input-multiplicative bounds relate as their definitions say; a
    /// 1×1 model gives exactly [`uncertainty`]'s terms and its joint raise is
    /// [`ErrorModel::joint_factor`]'s; bad input is refused with the entry named.
    #[test]
    fn a_matrix_bound_is_built_from_its_entries() {
        let (m, f, exact, frd) = coupled_2x2(1e-3);
        let var = frd.variance().unwrap().to_vec();
        let u = uncertainty_matrix(&m, &frd, &[], &UncertaintyOptions::default()).unwrap();
        assert_eq!((u.outputs, u.inputs, u.entries.len()), (2, 2, 4));
        assert!(u.entries.iter().all(|e| e.n_params == 12));
        let lever: f64 = u
            .entries
            .iter()
            .enumerate()
            .map(|(e, t)| {
                (0..f.len())
                    .map(|k| {
                        t.errors.sens[k].iter().map(|x| x.norm_sqr()).sum::<f64>() / var[k * 4 + e]
                    })
                    .sum::<f64>()
            })
            .sum();
        assert!((lever - 6.0).abs() < 1e-9, "{lever}");
        // entry (1, 0) is the FRF's entry (1, 0) and the model's channel from input 0 to output 1
        let e10 = u.entry(1, 0).unwrap();
        let g10 = frd.entry(1, 0).unwrap();
        assert_eq!(e10.measured, g10.values().to_vec());
        assert!(u.entry(2, 0).is_none());
        let norm = u.norm_bound();
        let rel = u.input_multiplicative_bound().unwrap();
        for k in 0..f.len() {
            let l = u.bound_at(k);
            let (mx, fro) = (0..2)
                .flat_map(|i| (0..2).map(move |j| (i, j)))
                .fold((0.0f64, 0.0f64), |(a, b), (i, j)| {
                    (a.max(l[(i, j)]), b + l[(i, j)] * l[(i, j)])
                });
            assert!(norm[k] >= mx * (1.0 - 1e-12) && norm[k] <= fro.sqrt() * (1.0 + 1e-12));
            // σ̄(P̂⁻¹) ‖L‖ bounds |P̂⁻¹| L from above
            let p = u.nominal_at(k);
            let inv_sv = p
                .singular_values()
                .unwrap()
                .iter()
                .fold(f64::INFINITY, |a, v| a.min(*v));
            assert!(rel[k] > 0.0 && rel[k] <= norm[k] / inv_sv * (1.0 + 1e-9) * 2.0);
        }
        // the 1×1 case is the SISO function itself
        let siso = frd.entry(0, 0).unwrap();
        let ch = m.entry(0, 0).unwrap();
        let one = uncertainty_matrix(&ch, &siso, &[], &UncertaintyOptions::default()).unwrap();
        let direct = default_terms(&ch, &siso);
        assert_eq!(one.entries[0], direct);
        for (a, b) in one
            .input_multiplicative_bound()
            .unwrap()
            .iter()
            .zip(&direct.multiplicative)
            .chain(one.norm_bound().iter().zip(&direct.additive))
        {
            assert!((a - b).abs() <= 1e-12 * b, "{a} {b}");
        }
        let raise = one.joint_raise(0.9, 0.95, 300, 7).unwrap();
        let factor = direct
            .errors
            .joint_factor(&direct.multiplicative, 0.9, 0.95, 300, 7)
            .unwrap();
        assert!((raise - factor).abs() < 1e-9 * factor, "{raise} {factor}");
        // the structured weight: per entry the weight of the entry's relative (or additive)
        // bound, each covering 98 % of its lines; the 1×1 relative one is the SISO weight of
        // the multiplicative bound
        let ts = 1e-3;
        for form in [EntryForm::Relative, EntryForm::Additive] {
            let ws = u.entry_weights(ts, 2, 0.98, form).unwrap();
            assert_eq!(ws.len(), 4);
            for (e, w) in ws.iter().enumerate() {
                let (i, j) = (e % 2, e / 2);
                let bound = match form {
                    EntryForm::Relative => u.entry_relative(i, j).unwrap(),
                    EntryForm::Additive => u.entries[e].additive.clone(),
                };
                let direct = crate::validate::weight::fit_weight(&f, &bound, ts, 2, 0.98).unwrap();
                assert_eq!(*w, direct);
                let m = w.weight.magnitude(&f);
                let below = m
                    .iter()
                    .zip(&bound)
                    .filter(|(w, b)| **w < **b * (1.0 - 1e-12));
                assert!(below.count() <= f.len() / 50, "entry ({i}, {j})");
            }
        }
        // the mode-shaped family per entry: each entry's fit_weight_shaped
        let shaped = crate::validate::weight::WeightShape::ModeShaped;
        let ws = u
            .entry_weights_shaped(ts, 4, 0.98, EntryForm::Relative, shaped)
            .unwrap();
        for (e, w) in ws.iter().enumerate() {
            let bound = u.entry_relative(e % 2, e / 2).unwrap();
            let direct =
                crate::validate::weight::fit_weight_shaped(&f, &bound, ts, 4, 0.98, shaped)
                    .unwrap();
            assert_eq!(*w, direct);
        }
        let w1 = one.entry_weights(ts, 2, 0.98, EntryForm::Relative).unwrap();
        let direct =
            crate::validate::weight::fit_weight(&f, &direct.multiplicative, ts, 2, 0.98).unwrap();
        assert_eq!(w1[0].weight, direct.weight);
        assert!(u.entry_relative(2, 0).is_err());
        // the joint draws of the 2×2 bound: a factor near 1 (the bound is a per-pair 95 % quantile)
        let g = u.joint_raise(0.98, 0.95, 500, 1).unwrap();
        assert!(g > 0.3 && g < 3.0, "{g}");
        // several fractions on the same draws: each the single call's factor, smaller for
        // fewer pairs
        let gs = u.joint_raises(&[0.98, 0.95, 0.5], 0.95, 500, 1).unwrap();
        assert_eq!(gs[0], g);
        assert_eq!(gs[1], u.joint_raise(0.95, 0.95, 500, 1).unwrap());
        assert_eq!(gs[2], u.joint_raise(0.5, 0.95, 500, 1).unwrap());
        assert!(gs[2] < gs[1] && gs[1] < gs[0], "{gs:?}");
        assert!(u.joint_raises(&[], 0.95, 10, 0).is_err());
        assert!(u.joint_raises(&[0.9, 1.1], 0.95, 10, 0).is_err());
        // bad input
        let err = uncertainty_matrix(&ch, &frd, &[], &UncertaintyOptions::default()).unwrap_err();
        assert!(err.to_string().contains("2×2"), "{err}");
        let extra = [ExtraTerms::default(); 3];
        assert!(uncertainty_matrix(&m, &frd, &extra, &UncertaintyOptions::default()).is_err());
        let mut bad = var.clone();
        bad[4 * 7 + 3] = 0.0;
        let frd_bad = Frd::new_matrix(
            f.clone(),
            2,
            2,
            exact.values().to_vec(),
            Some(bad),
            Some(1e-3),
        )
        .unwrap();
        let err =
            uncertainty_matrix(&m, &frd_bad, &[], &UncertaintyOptions::default()).unwrap_err();
        assert!(err.to_string().contains("variance"), "{err}");
        for (c, r) in [(0.0, 0.95), (0.9, 1.5)] {
            assert!(u.joint_raise(c, r, 10, 0).is_err());
        }
        assert!(u.joint_raise(0.9, 0.9, 0, 0).is_err());
    }

    /// The coherent draws carry the error model's moments: zero mean, each entry's variance
    /// $\sum_m |s_{ij,k,m}|^2$ and the covariance between two entries $\sum_m s_{00,k,m}
    /// \overline{s_{11,k,m}}$ (4 000 draws, 5 standard errors), with the deterministic part as
    /// the remainder; with the per-line amplitude term $a_k = |\varepsilon\hat P_k|$ given, the
    /// remainder holds it until a projected shift is kept; after the noise-free projected shift
    /// $\varepsilon\hat P$ every draw is the model's error it implies, $-\varepsilon\hat P$
    /// (the model moved with the shift), and the remainder holds none of it (it held $a_k$
    /// again before 2026-12-05: the shift counted twice).
    #[test]
    fn coherent_draws_carry_the_error_models_moments() {
        let (m, f, exact, frd) = coupled_2x2(1e-3);
        let u = uncertainty_matrix(&m, &frd, &[], &UncertaintyOptions::default()).unwrap();
        let n = 4000;
        let d = u.coherent_draws(n, 3).unwrap();
        assert_eq!(d.f_hz, f);
        let mut strongest = 0.0f64;
        for k in [5usize, 60, 140] {
            let sens = |e: usize| &u.entries[e].errors.sens[k];
            let var = |e: usize| sens(e).iter().map(|a| a.norm_sqr()).sum::<f64>();
            let at = |x: &Vec<faer::Mat<c64>>, e: usize| x[k][(e % 2, e / 2)];
            for e in 0..4 {
                let v = var(e);
                let mean: c64 = d.draws.iter().map(|x| at(x, e)).sum::<c64>() / n as f64;
                let ms: f64 = d.draws.iter().map(|x| at(x, e).norm_sqr()).sum::<f64>() / n as f64;
                let se = (v / n as f64).sqrt();
                assert!(
                    mean.norm() < 5.0 * se,
                    "line {k} entry {e}: mean {mean} se {se}"
                );
                let tol = 5.0 * (2.0 / n as f64).sqrt();
                assert!((ms / v - 1.0).abs() < tol, "line {k} entry {e}: {ms} {v}");
                for q in e + 1..4 {
                    let c: c64 = sens(e).iter().zip(sens(q)).map(|(a, b)| a * b.conj()).sum();
                    let got: c64 = d
                        .draws
                        .iter()
                        .map(|x| at(x, e) * at(x, q).conj())
                        .sum::<c64>()
                        / n as f64;
                    let se_c = (v * var(q) / n as f64).sqrt();
                    assert!(
                        (got - c).norm() < 5.0 * se_c,
                        "line {k} ({e}, {q}): {got} {c}"
                    );
                    strongest = strongest.max(c.norm() / (v * var(q)).sqrt());
                }
            }
            for e in 0..4 {
                let r = d.remainder[k][(e % 2, e / 2)];
                assert_eq!(r, u.entries[e].errors.fixed[k]);
            }
        }
        // some entries are correlated (0.1 is 6 standard errors): the test above is not vacuous
        assert!(strongest > 0.1, "{strongest}");
        // a noise-free shift ε P̂ projected through an exact model on a precise FRF, with the
        // per-line amplitude term a_k = |s_k| that the amplitude study's windows would give
        let (_, _, _, precise) = coupled_2x2(1e-13);
        let eps = 0.01;
        let truth: Vec<Vec<c64>> = (0..4)
            .map(|e| {
                (0..f.len())
                    .map(|k| exact.values()[k * 4 + e] * eps)
                    .collect()
            })
            .collect();
        let per_line: Vec<Vec<f64>> = truth
            .iter()
            .map(|s| s.iter().map(|x| x.norm()).collect())
            .collect();
        let extra: Vec<ExtraTerms> = per_line
            .iter()
            .map(|a| ExtraTerms {
                amplitude_shift: Some(a),
                ..ExtraTerms::default()
            })
            .collect();
        let mut u =
            uncertainty_matrix(&m, &precise, &extra, &UncertaintyOptions::default()).unwrap();
        // not projected: the draws do not carry the shift, so the remainder holds a_k
        let d = u.coherent_draws(5, 4).unwrap();
        for k in [5usize, 60, 140] {
            for (e, a) in per_line.iter().enumerate() {
                let r = d.remainder[k][(e % 2, e / 2)];
                assert!((r - a[k]).abs() <= 1e-9 * a[k], "{r}");
            }
        }
        let tiny: Vec<Vec<f64>> = truth
            .iter()
            .map(|s| s.iter().map(|x| 1e-20 * x.norm_sqr()).collect())
            .collect();
        assert!(
            u.add_projected_shift(&precise, &truth, &tiny, 0.05)
                .unwrap()
                .kept
        );
        // projected: the draws carry it, and it is not counted again at a free phase. The
        // shift is the BLA's departure from the small-signal plant, G = P0 + s; the model fitted
        // to G moved by +s, so its error P0 − P̂ is −s (the draws held +s before 2026-12-05,
        // eleventh session)
        let d = u.coherent_draws(50, 4).unwrap();
        for x in &d.draws {
            for k in [5usize, 60, 140] {
                for e in 0..4 {
                    let (got, want) = (x[k][(e % 2, e / 2)], -truth[e][k]);
                    assert!(
                        (got - want).norm() < 1e-3 * want.norm(),
                        "line {k} entry {e}: {got} {want}"
                    );
                    // the bound holds the shift (term (e)); the remainder does not
                    assert!(u.entries[e].additive[k] >= want.norm());
                    assert!(d.remainder[k][(e % 2, e / 2)] < 1e-3 * want.norm());
                }
            }
        }
        assert!(u.coherent_draws(0, 1).is_err());
    }

    /// Term (b) at its phase in the coherent draws: an exact 2×2 model against an FRF with a
    /// known systematic misfit $\beta_k = 0.15\,(k/L)^2 e^{0.7i} P_{00,k}$ on entry (0, 0)
    /// only, in 0.5 % noise. Where the misfit is far above the noise the draws' mean is $\beta$
    /// (the truth, analytic) to within the spread, which is then a small part of $b_k$; the
    /// disc (centre, spread) holds $\beta_k$ on ≥ 95 % of those lines; where the misfit is
    /// just past the test's edge the phase is left free (centre 0, spread $b_k$); the entries
    /// without misfit carry nothing. The free phase alone (the build before) would put all of
    /// $b_k$ in the remainder.
    #[test]
    fn term_b_enters_the_coherent_draws_at_the_misfits_phase() {
        let (m, f, exact, _) = coupled_2x2(1e-3);
        let l = f.len();
        let phase = c64::from_polar(1.0, 0.7);
        let beta: Vec<c64> = (0..l)
            .map(|k| exact.values()[k * 4] * phase * (0.15 * ((k + 1) as f64 / l as f64).powi(2)))
            .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let rel = 0.005f64;
        let (mut g, mut var) = (Vec::with_capacity(4 * l), Vec::with_capacity(4 * l));
        for (k, bk) in beta.iter().enumerate() {
            for e in 0..4 {
                let p = exact.values()[k * 4 + e];
                let v = rel * rel * p.norm_sqr();
                let (a, b) = gauss_pair(&mut rng);
                let noise = c64::new(a, b) * (v / 2.0).sqrt();
                g.push(p + noise + if e == 0 { *bk } else { c64::new(0.0, 0.0) });
                var.push(v);
            }
        }
        let frd = Frd::new_matrix(f.clone(), 2, 2, g, Some(var), Some(1e-3)).unwrap();
        let u = uncertainty_matrix(&m, &frd, &[], &UncertaintyOptions::default()).unwrap();
        let n = 400;
        let d = u.coherent_draws(n, 2).unwrap();
        let b = &u.entries[0].model_error;
        let (mut strong, mut held, mut free_edge) = (0, 0, 0);
        for k in 0..l {
            let (c, r) = (d.bias_centre[k][(0, 0)], d.bias_spread[k][(0, 0)]);
            if b[k] == 0.0 {
                assert!(c.norm() == 0.0 && r == 0.0, "line {k}: {c} {r}");
                continue;
            }
            // the modulus is term (b)'s; the spread is below it where a phase is kept
            assert!(c.norm() == 0.0 || ((c.norm() - b[k]).abs() <= 1e-9 * b[k] && r < b[k]));
            if c.norm() == 0.0 {
                assert_eq!(r, b[k]);
                free_edge += 1;
                continue;
            }
            // the remainder holds the spread, not b_k
            assert!((d.remainder[k][(0, 0)] - r).abs() <= 1e-12 * b[k]);
            let sd = (rel * exact.values()[k * 4].norm()) / (2.0f64).sqrt();
            if beta[k].norm() > 20.0 * sd {
                strong += 1;
                let mean: c64 = d.draws.iter().map(|x| x[k][(0, 0)]).sum::<c64>() / n as f64;
                // the draws' mean is the centre (term (a) averages out over the draws)
                let sa = u.entries[0].errors.sens[k]
                    .iter()
                    .map(|a| a.norm_sqr())
                    .sum::<f64>();
                assert!((mean - c).norm() < 5.0 * (sa / n as f64).sqrt() + 1e-12);
                held += usize::from((c - beta[k]).norm() <= r);
                assert!(r < 0.5 * b[k], "line {k}: spread {r} of b {}", b[k]);
            }
        }
        assert!(strong > 30, "{strong}");
        assert!(held as f64 >= 0.95 * strong as f64, "{held} of {strong}");
        assert!(free_edge > 0, "no line at the test's edge");
        // the entries without misfit: term (b) (hence its centre) is 0 on ≥ 95 % of the lines
        for e in 1..4 {
            let (i, j) = (e % 2, e / 2);
            let b = &u.entries[e].model_error;
            let quiet = (0..l)
                .filter(|&k| b[k] == 0.0 && d.bias_centre[k][(i, j)].norm() == 0.0)
                .count();
            assert!(quiet as f64 >= 0.95 * l as f64, "entry {e}: {quiet}");
        }
    }

    /// Term (e) through the model ([`MatrixUncertainty::add_projected_shift`]) on the coupled
    /// 2×2 model of order 3 (12 tangent dimensions). The shift $\varepsilon\hat P$ ($B$ scaled by
    /// $1 + \varepsilon$: inside the tangent space) is recovered exactly from noise-free lines;
    /// observed at a third of each line's noise it is still found (the Wald test over all
    /// lines) and the bound covers it on ≥ 95 % of the (entry, line) pairs within 3× of it at
    /// the median, growing by what the term grew; pure noise is kept in about α of
    /// the runs and its statistic has the $\chi^2_{12}$ mean; bad input is refused.
    #[test]
    fn a_coherent_shift_below_each_lines_noise_reaches_the_bound_through_the_model() {
        assert!((normal_upper_quantile(0.05) - 1.644_853_626_951_472).abs() < 1e-6);
        assert!((normal_upper_quantile(0.025) - 1.959_963_984_540_054).abs() < 1e-6);
        // scipy.stats.chi2.ppf(0.95, n) for n = 12, 100: 21.026, 124.342 (Wilson–Hilferty < 1 %)
        assert!((chi2_upper_quantile(12, 0.05) / 21.026_069_817_483_08 - 1.0).abs() < 0.01);
        assert!((chi2_upper_quantile(100, 0.05) / 124.342_113_404_089_3 - 1.0).abs() < 0.002);
        let (m, f, exact, frd) = coupled_2x2(1e-3);
        let u0 = uncertainty_matrix(&m, &frd, &[], &UncertaintyOptions::default()).unwrap();
        // an FRF 10⁵ times more precise: term (a) is negligible beside the shift
        let (_, _, _, precise) = coupled_2x2(1e-13);
        let u_precise =
            uncertainty_matrix(&m, &precise, &[], &UncertaintyOptions::default()).unwrap();
        let l = f.len();
        let eps = 0.01;
        // the exact shift per entry and line: ε P̂
        let truth: Vec<Vec<c64>> = (0..4)
            .map(|e| (0..l).map(|k| exact.values()[k * 4 + e] * eps).collect())
            .collect();
        // noise-free: the projection returns the shift itself
        let tiny: Vec<Vec<f64>> = truth
            .iter()
            .map(|s| s.iter().map(|x| 1e-20 * x.norm_sqr()).collect())
            .collect();
        let mut u = u_precise.clone();
        let r = u
            .add_projected_shift(&precise, &truth, &tiny, 0.05)
            .unwrap();
        assert!(r.kept, "{r:?}");
        for (e, t) in u.entries.iter().enumerate() {
            let a = t.amplitude.as_ref().unwrap();
            for k in 0..l {
                let s = truth[e][k].norm();
                assert!(
                    (a[k] - s).abs() < 1e-4 * s,
                    "entry {e} line {k}: {} {s}",
                    a[k]
                );
            }
        }
        // each line's estimate at three times the shift's size in noise
        let noisy_vars: Vec<Vec<f64>> = truth
            .iter()
            .map(|s| s.iter().map(|x| 9.0 * x.norm_sqr()).collect())
            .collect();
        let draw = |rng: &mut ChaCha8Rng, mean: &[Vec<c64>]| -> Vec<Vec<c64>> {
            mean.iter()
                .zip(&noisy_vars)
                .map(|(s, v)| {
                    s.iter()
                        .zip(v)
                        .map(|(x, v)| {
                            let h = (v / 2.0).sqrt();
                            let (a, b): (f64, f64) = (
                                rand_distr::Distribution::sample(&rand_distr::StandardNormal, rng),
                                rand_distr::Distribution::sample(&rand_distr::StandardNormal, rng),
                            );
                            x + c64::new(h * a, h * b)
                        })
                        .collect()
                })
                .collect()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let observed = draw(&mut rng, &truth);
        let mut u = u0.clone();
        let r = u
            .add_projected_shift(&frd, &observed, &noisy_vars, 0.05)
            .unwrap();
        assert!(r.kept && r.statistic > r.threshold, "{r:?}");
        let (mut covered, mut pairs, mut ratios) = (0, 0, Vec::new());
        for (e, (t, t0)) in u.entries.iter().zip(&u0.entries).enumerate() {
            let a = t.amplitude.as_ref().unwrap();
            for k in 0..l {
                let s = truth[e][k].norm();
                // the model is exact but for the shift: the bound must cover |s|
                pairs += 1;
                covered += usize::from(t.additive[k] >= s);
                ratios.push(t.additive[k] / s);
                // the term is the joint quantile of |ŝ + n| less term (a): below the sum
                assert!(a[k] <= t0.additive[k] + s * 3.0);
                // the bound grew by the term, the draws' fixed part too
                assert!((t.additive[k] - t0.additive[k] - a[k]).abs() <= 1e-12 * t.additive[k]);
                assert!(
                    (t.errors.fixed[k] - t0.errors.fixed[k] - a[k]).abs() <= 1e-12 * t.additive[k]
                );
                let rel = t.additive[k] / t.nominal[k].norm();
                assert!((t.multiplicative[k] - rel).abs() <= 1e-12 * rel);
            }
        }
        ratios.sort_by(f64::total_cmp);
        let med = ratios[ratios.len() / 2];
        assert!(
            covered as f64 >= 0.95 * pairs as f64,
            "{covered} of {pairs}"
        );
        // term (a) alone does not cover the shift
        let before = u0
            .entries
            .iter()
            .enumerate()
            .map(|(e, t)| {
                (0..l)
                    .filter(|&k| t.additive[k] >= truth[e][k].norm())
                    .count()
            })
            .sum::<usize>();
        assert!(before * 2 < pairs, "{before} of {pairs} before");
        assert!(med < 3.0, "median bound / shift {med}");
        // no shift: kept in about 5 % of the runs, the statistic's mean is n = 12
        let zero: Vec<Vec<c64>> = truth
            .iter()
            .map(|s| vec![c64::new(0.0, 0.0); s.len()])
            .collect();
        let (mut kept, mut stat) = (0, 0.0);
        let runs = 80;
        for seed in 0..runs {
            let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
            let mut u = u0.clone();
            let r = u
                .add_projected_shift(&frd, &draw(&mut rng, &zero), &noisy_vars, 0.05)
                .unwrap();
            kept += usize::from(r.kept);
            stat += r.statistic / runs as f64;
            if !r.kept {
                assert_eq!(u, u0);
            }
        }
        eprintln!("coherent shift: covered {covered} of {pairs} ({before} before), median {med:.2}, statistic {:.1} > {:.1}; null: kept {kept} of {runs}, mean statistic {stat:.2}", r.statistic, r.threshold);
        assert!(kept <= 10, "{kept} of {runs}");
        assert!((stat / 12.0 - 1.0).abs() < 0.15, "mean statistic {stat}");
        // bad input
        let mut u = u0.clone();
        assert!(u
            .add_projected_shift(&frd, &truth[..3], &tiny, 0.05)
            .is_err());
        assert!(u.add_projected_shift(&frd, &truth, &tiny, 1.0).is_err());
        let mut short = truth.clone();
        short[2].pop();
        assert!(u.add_projected_shift(&frd, &short, &tiny, 0.05).is_err());
        let mut nan = tiny.clone();
        nan[1][3] = f64::NAN;
        let err = u.add_projected_shift(&frd, &truth, &nan, 0.05).unwrap_err();
        assert!(err.to_string().contains("entry (1, 0)"), "{err}");
        let other = frd.band(3.0, 200.0).unwrap();
        assert!(u.add_projected_shift(&other, &truth, &tiny, 0.05).is_err());
        assert_eq!(u, u0);
    }

    /// The Rice quantile against its two closed-form limits and a Monte Carlo oracle.
    #[test]
    fn the_rice_quantile_matches_its_limits_and_a_monte_carlo_oracle() {
        let q0 = rice_quantile(0.0, 4.0, 0.95);
        assert!((q0 - 2.0 * 20f64.ln().sqrt()).abs() < 1e-4, "{q0}");
        // far from the origin: the radial part is a real Gaussian of variance σ²/2
        let far = rice_quantile(40.0, 1.0, 0.95);
        let z = normal_upper_quantile(0.05);
        assert!((far - (40.0 + z / 2f64.sqrt())).abs() < 2e-2, "{far}");
        assert_eq!(rice_quantile(3.0, 0.0, 0.95), 3.0);
        // a narrow density far out (σ = 1e-6 m) is still resolved
        let narrow = rice_quantile(1.0, 1e-12, 0.95);
        assert!(
            (narrow - (1.0 + z * 1e-6 / 2f64.sqrt())).abs() < 1e-8,
            "{narrow}"
        );
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for m in [0.5, 1.5, 3.0] {
            let h = 0.5f64.sqrt();
            let mut v: Vec<f64> = (0..200_000)
                .map(|_| {
                    let (a, b): (f64, f64) = (
                        rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng),
                        rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng),
                    );
                    c64::new(m + h * a, h * b).norm()
                })
                .collect();
            v.sort_by(f64::total_cmp);
            let emp = v[(0.95 * v.len() as f64) as usize];
            let q = rice_quantile(m, 1.0, 0.95);
            assert!((q / emp - 1.0).abs() < 0.01, "m {m}: {q} against {emp}");
        }
    }
}
