//! State-space models fitted to frequency-response data: a frequency-domain subspace start
//! refined by Levenberg–Marquardt on the weighted complex error (SISO, discrete time).
//!
//! # Criterion
//! [`ss_frd`] minimises the criterion of [`freqfit`](super::freqfit),
//! $$ V = \sum_{k=1}^{L} w_k \,\bigl| \hat G(z_k) - G_k \bigr|^2, \qquad z_k = e^{j\omega_k T}, $$
//! over the $n$-th order models $\hat G(z) = C (zI - A)^{-1} B + D$ ($D = 0$ unless
//! [`SsFreqOptions::feedthrough`]). Unstable models are admitted (an AMB plant is open-loop
//! unstable); [`FreqFitOptions::max_unstable_poles`] holds the fit to at most that many poles on
//! or outside the unit circle (the number the data support), and
//! [`FreqFitOptions::enforce_stability`] asks for a stable one.
//!
//! # 1. Subspace start
//! The frequency-domain subspace method of McKelvey, Akçay and Ljung (1996). With
//! $X_k = (\zeta_k I - A)^{-1} B$ the state response, $\zeta_k X_k = A X_k + B$ and
//! $G_k = C X_k + D$ give for the powers $p = 0, \dots, q-1$
//! $$ \zeta_k^p G_k = C A^p X_k + \sum_{i<p} C A^{p-1-i} B\, \zeta_k^i + D \zeta_k^p , \qquad
//! \text{i.e.}\quad \mathbf G = \mathcal O_q \mathbf X + \Gamma_q \mathbf U , $$
//! with the $q \times L$ matrices $\mathbf G = [W_q(\zeta_k) G_k]_k$, $\mathbf U = [W_q(\zeta_k)]_k$,
//! $W_q(\zeta) = [1, \zeta, \dots, \zeta^{q-1}]^\top$, the extended observability matrix
//! $\mathcal O_q = [C; CA; \dots; CA^{q-1}]$ and a lower-triangular Toeplitz $\Gamma_q$. Each column
//! is scaled by $\sqrt{w_k}$ (this keeps the equation exact and weights the lines), real and
//! imaginary parts are stacked side by side ($q \times 2L$, which makes the realisation real), and
//! the input part is removed by the projection on the orthogonal complement of the row space
//! of $\mathbf U$: the LQ factorisation (a QR of the transpose)
//! $$ \begin{bmatrix} \mathbf U \\ \mathbf G \end{bmatrix} = \begin{bmatrix} L_{11} & 0 \\
//! L_{21} & L_{22} \end{bmatrix} \begin{bmatrix} Q_1^\top \\ Q_2^\top \end{bmatrix}, \qquad
//! \mathbf G\, \Pi_{\mathbf U}^\perp = L_{22} Q_2^\top = \mathcal O_q \mathbf X\, \Pi_{\mathbf U}^\perp . $$
//! The $n$ leading left singular vectors of $L_{22}$ span the range of $\mathcal O_q$; its shift
//! invariance $\underline{\mathcal O}\, A = \overline{\mathcal O}$ (all rows but the last, all rows
//! but the first) gives $A$ by least squares.
//!
//! **Frequency warping.** At 20 kHz sampling the band of an AMB plant (10 Hz–1 kHz) is a short
//! arc of the unit circle near $z = 1$, on which the powers $z^p$ are nearly collinear, and the
//! poles sit near $z = 1$, where $\mathcal O_q$ is badly conditioned. The subspace step therefore
//! runs in the variable of the all-pass (Möbius) map
//! $$ \zeta = \frac{z - a}{1 - a z}, \qquad a = \frac{1 - t}{1 + t}, \quad t = \tan\frac{\omega_c T}{2},
//! \qquad z = \frac{\zeta + a}{1 + a \zeta}, $$
//! which maps the unit circle onto itself, the disc onto itself (an unstable pole stays unstable)
//! and the band's geometric centre $\omega_c$ to $\zeta = j$: 10 Hz–1 kHz then covers the angles
//! $0.2$–$2.9$ rad. A rational function of degree $n$ in $z$ is one of degree $n$ in $\zeta$, so
//! the step is exact for noise-free data; its poles are mapped back to $z$. On an AMB-like plant
//! seen on 253 lines in 12–1000 Hz at 20 kHz (unit test below) the warp takes the subspace
//! poles' error from $\sim 10^{-9}$ to $10^{-16}$ on exact data, and from $\sim 10^{-2}$ to
//! $\sim 10^{-5}$ with 0.14 % noise.
//!
//! **$B$ and $D$** then follow by linear least squares of the weighted complex error (real and
//! imaginary parts stacked) with the poles fixed. This is done in the partial-fraction basis of
//! the refinement below, which spans the same models as $C(zI - A)^{-1}B + D$ with free $B$, $D$.
//! With [`FreqFitOptions::enforce_stability`] the unstable poles are first reflected,
//! $z \mapsto 1/\bar z$, and the numerators refitted. With
//! [`FreqFitOptions::max_unstable_poles`] $= m$ and more than $m$ unstable subspace poles, the start
//! keeps the unstable real poles and pairs (at most $m$ poles, as many as allowed) whose choice
//! gives the smallest cost after refitting the numerators, and mirrors the others; this moves
//! only the start of the constrained refinement below.
//!
//! # 2. Refinement
//! The model is a sum of second-order sections (a complex pair, or two real poles sorted and
//! paired; at most one first-order section) in the **delta operator** $\delta = (z - 1)/h$,
//! $$ \hat G(z) = D + \sum_b \frac{\beta_{b,1} \delta + \beta_{b,0}}{\delta^2 + \alpha_{b,1} \delta + \alpha_{b,2}}
//! \;\Bigl[+ \frac{\gamma}{\delta - \lambda}\Bigr], \qquad h = \bigl|e^{j\omega_c T} - 1\bigr| . $$
//! For poles near $z = 1$ the shift-form coefficients of $z^2 + a_1 z + a_2$ are nearly
//! collinear ($a_1 \approx -2$, $a_2 \approx 1$, sensitivities of opposite sign), the delta-form
//! ones are not (see [`ss_pem`](super::ss_pem)); $h$ makes $|\delta| \approx 1$ at the band's centre.
//! The $2n$ (plus one for $D$) parameters are locally identifiable for distinct poles, real and
//! complex poles are covered alike (a pair may move between the two) and the Jacobian is analytic:
//! $\partial \hat G / \partial \beta_{b,1} = \delta / P_b$, $\partial \hat G / \partial \beta_{b,0} = 1 / P_b$,
//! $\partial \hat G / \partial \alpha_{b,1} = -N_b \delta / P_b^2$,
//! $\partial \hat G / \partial \alpha_{b,2} = -N_b / P_b^2$. The residuals are the real and imaginary
//! parts of $\sqrt{w_k}\,(\hat G(z_k) - G_k)$; [`minimize`] runs at most
//! [`FreqFitOptions::max_iterations`] steps (0 skips the refinement; [`FreqFit::converged`] says
//! whether it met a convergence test). No constraint is imposed unless a number of unstable poles
//! is given (or a stable model asked for); then a trial with more poles on or outside the unit
//! circle than allowed (counted per section from the roots of its quadratic) is inadmissible,
//! and Levenberg–Marquardt shortens the step: the result is the best model in the admissible
//! set, never a reflected one.
//!
//! # Second start
//! With a limit on the unstable poles, the fit may refine from a second start as well and keep
//! whichever result has the lower cost $V$: the unconstrained refinement from the subspace
//! poles, as it is when it holds at most the allowed count, else its poles with the surplus
//! unstable ones mirrored (the same admissible start as above) and refined under the
//! constraint. [`SsFreqOptions::second_start`] says when: [`SecondStart::WhenPinned`] when
//! the first refinement ends with a pole pinned to the unit circle ($\bigl||z| - 1\bigr| <$
//! [`PINNED`]), the sign that the constraint, not the data, stopped it; [`SecondStart::Always`];
//! or [`SecondStart::Never`], the default.
//!
//! Why: on a narrow band the unconstrained fit of a stable structure puts unstable poles
//! outside the band to absorb the modes beyond it, the subspace start mirrors them, and the
//! constrained refinement, which rejects every step that leaves the admissible set, stalls
//! with poles pinned to the unit circle. On the F-16 ground vibration test's three FRFs
//! (periods 2–9, 2–15 Hz at 400 Hz, orders 16–32 held to 0 unstable poles) the subspace start
//! alone ends at 4.4 times the unconstrained fit's median relative misfit at the median (up to
//! 63 times: 56 % against 0.9 %); with the second start at 1.02 times (at worst 2.5); test
//! `freqfit_real` of `ambid-core`. On random twin rigs 1–40 (SML fits of orders 6–12 held to
//! the loop's one unstable pole, example `freqfit_free_start_rigs`) 30 of 280 fits end pinned;
//! the second start changes 20, all of orders 10–12, with the median error against the exact
//! plant ×0.994 (lower on 12, higher on 8), and the fit time of the 280 rises from 5.6 s to
//! 7.0 s; on the unseen nonlinear rigs 41–100, 49 of 420 end pinned, 31 change (orders 10–12),
//! the error ×0.989 (lower on 18, higher on 13), the time 11.2 s → 13.9 s.
//!
//! *What it does not do.* Either start can still end with a pole on the unit circle (the
//! admissible set is closed), and on the F-16 most do: from the subspace start 23, 15 and 21
//! of the 23 fits of orders 10–32 of its three outputs end with one ([`poles_on_unit_circle`]:
//! a real pole at $z = \pm 1$ or an undamped pair), and with the second start 23, 12 and 21,
//! more of them undamped pairs beside the band (flagged by `ambid`'s
//! `uncertainty::out_of_band_resonance` on 21, 18 and 6 fits against 8, 11 and 1). Which
//! result the second start gives depends on how far its unconstrained refinement runs (with
//! ten times the iteration limit, the BIC's model of output 1 fell from order 23 to 13 and its
//! held-out error rose from 1.8 % to 15.8 %). So it moves the stall more than it removes it
//! (example `freqfit_f16_orders` of `ambid`; docs/estimation.md).
//!
//! *Why not the default.* With `WhenPinned` as the default the twin's tests and the nominal
//! twin's summary are unchanged, but four real-data tests of `ambid` change their outcome:
//! the Silverbox's stable BLA model improves until its error is within 1.4 times the held-out
//! BLA's noise, so the held-out BLA no longer stands in for the truth there; on the F-16 the
//! BIC's model of output 3 (then order 31) held two pole–zero pairs that cancel within the
//! data (the BIC's nominal skips such fits now); SML against the inverse variance on the F-16
//! moves from 0.82–1.12 to 0.20–1.28; and `ambid uncertainty` on an FRF read back from its
//! file refits it 0.24 % away from the library's model (term (f), 1e-7 before): the
//! unconstrained refinement stops at its iteration limit and follows the file's last bits.
//! Together with the dependence above, the second start is not a fix to make the default.
//!
//! # Result
//! The returned [`StateSpace`] is the block-diagonal delta-companion realisation of the sections:
//! per second-order section
//! $$ A_b = I + h \begin{bmatrix} 0 & 1 \\ -\alpha_{b,2} & -\alpha_{b,1} \end{bmatrix}, \quad
//! B_b = \begin{bmatrix} 0 \\ h \end{bmatrix}, \quad C_b = [\beta_{b,0} \;\; \beta_{b,1}], $$
//! per first-order section $A = 1 + h\lambda$, $B = h$, $C = \gamma$.
//!
//! # Reference
//! T. McKelvey, H. Akçay, L. Ljung, "Subspace-based multivariable system identification from
//! frequency response data", *IEEE Transactions on Automatic Control* 41(7), 1996, pp. 960–979
//! (the subspace step; the all-pass warp here is a Möbius map in the spirit of the bilinear
//! transform the paper uses for continuous-time data); R. Pintelon, J. Schoukens, *System Identification: A
//! Frequency Domain Approach*, 2nd ed., Wiley, 2012 (the weighted complex criterion).
//!
//! # Example
//! ```
//! use ambid_core::estimate::freqfit::FreqFitOptions;
//! use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
//! use ambid_core::lti::{Frd, StateSpace};
//! use faer::mat;
//! // a lightly damped mode at 0.2 rad/sample, |p| = 0.99
//! let (re, im) = (0.99 * 0.2f64.cos(), 0.99 * 0.2f64.sin());
//! let truth = StateSpace::discrete(mat![[re, im], [-im, re]], mat![[1.0], [0.0]],
//!                                  mat![[0.0, 1.0]], mat![[0.0]], 1e-3).unwrap();
//! let f: Vec<f64> = (1..100).map(|k| 4.5 * k as f64).collect();
//! let frd = Frd::from_model(&truth, &f).unwrap();
//! let fit = ss_frd(&frd, 2, &FreqFitOptions::default(), &SsFreqOptions::default()).unwrap();
//! assert!(fit.errors.relative_rmse < 1e-9);
//! let p = fit.model.poles().unwrap();
//! assert!(p.iter().all(|z| (z.norm() - 0.99).abs() < 1e-9));
//! ```

use super::freqfit::{
    constrained_start, count_unstable, FreqData, FreqErrors, FreqFit, FreqFitOptions,
};
use super::pem::lm::{minimize, LeastSquaresProblem, LmOptions};
use crate::error::{Error, Result};
use crate::linalg;
use crate::lti::{Frd, StateSpace};
use faer::{c64, Mat};

const CTX: &str = "ss_frd";

/// Options of [`ss_frd`] beyond the shared [`FreqFitOptions`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SsFreqOptions {
    /// Estimate a feedthrough $D$ (default `false`: $D = 0$, a strictly proper model).
    pub feedthrough: bool,
    /// Block rows $q$ of the subspace step ($n + 1 \le q \le L$); default
    /// $\min(2n + 2, L)$.
    pub horizon: Option<usize>,
    /// With a limit on the unstable poles ([`FreqFitOptions::max_unstable_poles`] or
    /// [`FreqFitOptions::enforce_stability`]), when to refine from a second start as well: the
    /// unconstrained refinement's poles with the surplus unstable ones mirrored, the lower cost
    /// kept (module docs, "Second start"). Default [`SecondStart::Never`] (module docs, "Why
    /// not the default").
    pub second_start: SecondStart,
}

/// When a fit held to a number of unstable poles refines from a second start too
/// ([`SsFreqOptions::second_start`]; module docs, "Second start").
///
/// # Example
/// A stable lightly damped mode fitted held to 0 unstable poles, with the second start where
/// the first refinement ends pinned: the fit is stable and exact.
/// ```
/// use ambid_core::estimate::freqfit::FreqFitOptions;
/// use ambid_core::estimate::freqfit_ss::{ss_frd, SecondStart, SsFreqOptions};
/// use ambid_core::lti::{Frd, StateSpace};
/// use faer::mat;
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let (re, im) = (0.995 * 0.1f64.cos(), 0.995 * 0.1f64.sin());
/// let truth = StateSpace::discrete(mat![[re, im], [-im, re]], mat![[1.0], [0.0]],
///                                  mat![[0.0, 1.0]], mat![[0.0]], 1e-3)?;
/// let f: Vec<f64> = (1..60).map(|k| 0.5 * k as f64).collect();
/// let frd = Frd::from_model(&truth, &f)?;
/// let opts = FreqFitOptions { max_unstable_poles: Some(0), ..FreqFitOptions::default() };
/// let ss = SsFreqOptions { second_start: SecondStart::WhenPinned, ..SsFreqOptions::default() };
/// let fit = ss_frd(&frd, 2, &opts, &ss)?;
/// assert!(fit.errors.relative_rmse < 1e-8);
/// assert!(fit.model.poles()?.iter().all(|z| z.norm() < 1.0));
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SecondStart {
    /// When the first refinement ends with a pole pinned to the unit circle
    /// ($\bigl||z| - 1\bigr| <$ [`PINNED`]): the constraint, not the data, stopped it.
    WhenPinned,
    /// Always (one more unconstrained and one more constrained refinement per fit).
    Always,
    /// Never: the subspace start alone (the default, and the only start before 2026-12-08).
    #[default]
    Never,
}

/// A pole with $\bigl||z| - 1\bigr|$ below this is pinned to the unit circle by the constraint
/// ([`SecondStart::WhenPinned`]). A physical mode's $1 - |z| = \zeta\omega T$ is far above it
/// (at 20 kHz a 100 Hz mode would need $\zeta < 3\cdot10^{-8}$); the stalled fits of the
/// module docs end within $10^{-11}$ of the circle.
pub const PINNED: f64 = 1e-9;

/// The poles of `model` within [`PINNED`] of the unit circle, $\bigl||z| - 1\bigr| <$
/// [`PINNED`]: of a fit held to a number of unstable poles, the ones its constraint holds there
/// (module docs, "Second start"). The data want them outside; the fit stopped on the
/// constraint, not at the data's optimum, and the model has an undamped mode there. One pole
/// per mode: of a complex pair the one in the upper half-plane. Empty for a fit whose
/// constraint is inactive.
///
/// # Errors
/// When the model's poles cannot be computed.
///
/// # Example
/// ```
/// use ambid_core::estimate::freqfit_ss::poles_on_unit_circle;
/// use ambid_core::lti::StateSpace;
/// use faer::mat;
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// // an integrator (z = 1) and a damped pole (z = 0.5)
/// let m = StateSpace::discrete(mat![[1.0, 0.0], [0.0, 0.5]], mat![[1.0], [1.0]],
///                              mat![[1.0, 1.0]], mat![[0.0]], 1e-3)?;
/// let on = poles_on_unit_circle(&m)?;
/// assert_eq!(on.len(), 1);
/// assert!((on[0].re - 1.0).abs() < 1e-12);
/// # Ok(())
/// # }
/// ```
pub fn poles_on_unit_circle(model: &StateSpace) -> Result<Vec<c64>> {
    Ok(model
        .poles()?
        .into_iter()
        .filter(|p| p.im >= 0.0 && on_unit_circle(p))
        .collect())
}

/// Whether the pole `p` lies within [`PINNED`] of the unit circle.
fn on_unit_circle(p: &c64) -> bool {
    (p.norm() - 1.0).abs() < PINNED
}

/// Fits an `order`-th order discrete-time SISO state-space model to `frd` (module docs):
/// frequency-domain subspace start, then Levenberg–Marquardt on the weighted complex error.
///
/// The model has the data's sample time; `cost` is $V$ at the result, `n_params` is $2n$ (plus 1
/// with a feedthrough), `iterations` the accepted refinement steps and `errors` the unweighted
/// error measures on the lines used.
///
/// # Errors
/// * [`Error::InvalidArgument`] for order 0, a continuous [`Frd`], a bad band or weights (see
///   [`FreqData::new`]), fewer real equations ($2L$) than parameters ([`FreqData::check_params`]),
///   or a horizon outside $[n + 1, L]$;
/// * [`Error::Numerical`] when the subspace step is degenerate (too few lines for the horizon, a
///   rank-deficient shift equation or numerator regression, a pole at infinity) or the
///   refinement fails; the message says what may help.
pub fn ss_frd(
    frd: &Frd,
    order: usize,
    opts: &FreqFitOptions,
    ss_opts: &SsFreqOptions,
) -> Result<FreqFit<StateSpace>> {
    ss_frd_started(frd, order, opts, ss_opts, None)
}

/// [`ss_frd`] with the refinement started from the poles `start` (in $z$, `order` of them in
/// conjugate pairs) instead of the subspace step's; `None` is [`ss_frd`]. The numerators are
/// fitted to the start's poles as for the subspace start, and the same admissibility rule
/// (unstable pole count) applies. Term (f) of the uncertainty bound starts the FRF's own fit
/// from the nominal model's poles too (`validate::uncertainty::fit_distance`).
pub(crate) fn ss_frd_started(
    frd: &Frd,
    order: usize,
    opts: &FreqFitOptions,
    ss_opts: &SsFreqOptions,
    start: Option<&[c64]>,
) -> Result<FreqFit<StateSpace>> {
    frd.require_siso("freqfit_ss::ss_frd")?;
    if start.is_some_and(|p| p.len() != order) {
        return Err(Error::invalid(
            "start",
            format!("the start needs {order} poles, one per state"),
        ));
    }
    if order == 0 {
        return Err(Error::invalid(
            "order",
            "the model order must be at least 1",
        ));
    }
    let data = FreqData::new(frd, opts)?;
    let n_params = 2 * order + usize::from(ss_opts.feedthrough);
    data.check_params(n_params)?;
    let l = data.len();
    let q = match ss_opts.horizon {
        Some(q) if q < order + 1 || q > l => {
            return Err(Error::invalid(
                "horizon",
                format!(
                    "the horizon must lie in [order + 1, lines] = [{}, {l}], got {q}",
                    order + 1
                ),
            ))
        }
        Some(q) => q,
        None => {
            if l < order + 1 {
                return Err(Error::numerical(
                    CTX,
                    format!(
                        "the subspace step needs at least order + 1 = {} lines, the band has {l}; widen the band or lower the order",
                        order + 1
                    ),
                ));
            }
            (2 * order + 2).min(l)
        }
    };
    let warp = Warp::new(&data)?;

    // 1. subspace poles, mapped back to z; blocks in delta form
    let mut poles = match start {
        Some(p) => p.to_vec(),
        None => subspace_poles(&data, &warp, order, q)?,
    };
    let limit = if opts.enforce_stability {
        for p in &mut poles {
            *p = reflect(*p);
        }
        Some(0)
    } else {
        opts.max_unstable_poles
    };
    let refine = |poles: &[c64], limit: Option<usize>| {
        refine_from(
            &data,
            &warp,
            poles,
            ss_opts.feedthrough,
            limit,
            opts.max_iterations,
        )
    };
    let mut best = refine(&poles, limit)?;
    // 2'. with a limit, a second start (module docs, "Second start"): the unconstrained
    // refinement's poles, the surplus unstable ones mirrored
    let try_second = match ss_opts.second_start {
        SecondStart::Never => false,
        SecondStart::Always => true,
        SecondStart::WhenPinned => best.poles.iter().any(on_unit_circle),
    };
    if let (Some(lim), None, true) = (limit, start, try_second && opts.max_iterations > 0) {
        let second = refine(&poles, None).and_then(|free| {
            if count_unstable(&free.poles) <= lim {
                Ok(free)
            } else {
                refine(&free.poles, limit)
            }
        });
        if let Ok(second) = second {
            if second.cost < best.cost {
                best = second;
            }
        }
    }
    let response = best.model.freq_response_siso(&data.f_hz)?;
    let errors = FreqErrors::of(&response, &data);
    Ok(FreqFit {
        model: best.model,
        n_params,
        cost: best.cost,
        errors,
        iterations: best.iterations,
        converged: best.converged,
    })
}

/// A refined model of [`refine_from`] with its cost and poles.
struct Refined {
    model: StateSpace,
    cost: f64,
    iterations: usize,
    converged: bool,
    poles: Vec<c64>,
}

/// The numerators fitted to `poles` (the admissible start of `limit` first, module docs) and
/// the Levenberg–Marquardt refinement of at most `max_iterations` steps.
fn refine_from(
    data: &FreqData,
    warp: &Warp,
    poles: &[c64],
    feedthrough: bool,
    limit: Option<usize>,
    max_iterations: usize,
) -> Result<Refined> {
    let mut poles = poles.to_vec();
    let mut prob = Problem::new(data, warp, &poles, feedthrough, limit)?;
    if let Some(lim) = limit {
        // an admissible start: the unstable subspace poles that explain the data best are kept
        poles = constrained_start(&poles, lim, |p| {
            let mut th = prob.denominators_from_poles(p);
            prob.fit_numerators(&mut th).ok()?;
            let r = prob.residuals(&th)?;
            Some(r.iter().map(|x| x * x).sum())
        });
    }
    let mut theta = prob.denominators_from_poles(&poles);
    prob.fit_numerators(&mut theta)?;

    // 2. refinement
    let (mut iterations, mut converged) = (0, true);
    if max_iterations > 0 {
        let lm = LmOptions::default().with_max_iterations(max_iterations)?;
        let (th, report) = minimize(&mut prob, &theta, &lm)?;
        theta = th;
        iterations = report.iterations;
        converged = report.reason.converged();
    }
    if theta.iter().any(|v| !v.is_finite()) {
        return Err(Error::numerical(
            CTX,
            "the refinement produced non-finite parameters; lower the order or narrow the band",
        ));
    }
    let r = prob.residuals(&theta).ok_or_else(|| {
        Error::numerical(
            CTX,
            "the fitted model's response is not finite on the data's lines (a pole on a line); lower the order",
        )
    })?;
    let cost = r.iter().map(|x| x * x).sum::<f64>();
    let model = prob.realise(&theta, data.ts)?;
    Ok(Refined {
        model,
        cost,
        iterations,
        converged,
        poles: prob.poles(&theta),
    })
}

/// $z \mapsto 1/\bar z$ for $|z| > 1$; a pole on the unit circle is pulled just inside.
fn reflect(p: c64) -> c64 {
    let r = p.norm();
    let mut out = if r > 1.0 { p / (r * r) } else { p };
    if out.norm() >= 1.0 - 1e-9 {
        out *= (1.0 - 1e-6) / out.norm();
    }
    out
}

/// The all-pass warp of the subspace step and the delta scale of the refinement (module docs).
struct Warp {
    /// $a$ of $\zeta = (z - a)/(1 - a z)$.
    a: f64,
    /// $h$ of $\delta = (z - 1)/h$.
    h: f64,
}

impl Warp {
    fn new(data: &FreqData) -> Result<Self> {
        let f_hi = data.f_hz.iter().copied().fold(0.0, f64::max);
        if f_hi <= 0.0 {
            return Err(Error::invalid(
                "band_hz",
                "every line of the band is at 0 Hz; a dynamic model needs lines at positive frequencies",
            ));
        }
        let f_lo = data
            .f_hz
            .iter()
            .copied()
            .filter(|&f| f > 0.0)
            .fold(f_hi, f64::min)
            .max(1e-3 * f_hi);
        let pi = std::f64::consts::PI;
        let theta_c = (2.0 * pi * (f_lo * f_hi).sqrt() * data.ts).min(0.9 * pi);
        let t = (theta_c / 2.0).tan();
        Ok(Self {
            a: (1.0 - t) / (1.0 + t),
            h: 2.0 * (theta_c / 2.0).sin(),
        })
    }
    fn warp(&self, z: c64) -> c64 {
        (z - self.a) / (c64::new(1.0, 0.0) - z * self.a)
    }
    fn unwarp(&self, zeta: c64) -> Option<c64> {
        let den = c64::new(1.0, 0.0) + zeta * self.a;
        if den.norm() <= 1e-12 * (1.0 + zeta.norm()) {
            return None;
        }
        Some((zeta + self.a) / den)
    }
    fn delta(&self, z: c64) -> c64 {
        (z - 1.0) / self.h
    }
}

/// The poles (in $z$) of the subspace step (module docs).
fn subspace_poles(data: &FreqData, warp: &Warp, n: usize, q: usize) -> Result<Vec<c64>> {
    let l = data.len();
    let zeta: Vec<c64> = data.z.iter().map(|&z| warp.warp(z)).collect();
    let sw: Vec<f64> = data.w.iter().map(|w| w.sqrt()).collect();
    let g_rms = (data
        .g
        .iter()
        .zip(&sw)
        .map(|(g, s)| (g * s).norm_sqr())
        .sum::<f64>()
        / l as f64)
        .sqrt();
    if !(g_rms > 0.0 && g_rms.is_finite()) {
        return Err(Error::numerical(
            CTX,
            "the response is zero (or not finite) on every line of the band; there is nothing to fit",
        ));
    }
    // [U; G]ᵀ: one row per real equation (Re of line k, then Im), U's q powers then G's q powers
    let mut mt = Mat::<f64>::zeros(2 * l, 2 * q);
    for k in 0..l {
        let gk = data.g[k] / g_rms;
        let mut pw = c64::new(sw[k], 0.0);
        for p in 0..q {
            let u = pw;
            let y = pw * gk;
            mt[(k, p)] = u.re;
            mt[(l + k, p)] = u.im;
            mt[(k, q + p)] = y.re;
            mt[(l + k, q + p)] = y.im;
            pw *= zeta[k];
        }
    }
    let r = crate::estimate::qr_stream::r_factor(mt.as_ref());
    // G Π⊥ = L22 Q2ᵀ with L22 = R22ᵀ
    let l22 = Mat::from_fn(q, q, |i, j| if i >= j { r[(q + j, q + i)] } else { 0.0 });
    let svd = l22.thin_svd().map_err(|e| {
        Error::numerical(
            CTX,
            format!("the SVD of the projected data failed ({e:?}); check the data"),
        )
    })?;
    let s = svd.S().column_vector();
    let s0 = s[0];
    if !(s0 > 0.0 && s0.is_finite()) {
        return Err(Error::numerical(
            CTX,
            "the projected data vanish: the response is a constant (or polynomial) on the band's lines; no dynamics to fit",
        ));
    }
    let o = svd.U().subcols(0, n);
    let o_up = o.subrows(0, q - 1).to_owned();
    let o_dn = o.subrows(1, q - 1).to_owned();
    let a = linalg::lstsq(o_up.as_ref(), o_dn.as_ref()).map_err(|e| {
        Error::numerical(
            CTX,
            format!("the shift equation of the subspace step is degenerate ({e}); lower the order or raise the horizon"),
        )
    })?;
    let pz = linalg::eigenvalues(a.as_ref())?;
    let mut out = Vec::with_capacity(n);
    for p in pz {
        let z = warp.unwarp(p).ok_or_else(|| {
            Error::numerical(
                CTX,
                "the subspace step placed a pole at infinity; lower the order or narrow the band",
            )
        })?;
        if !(z.re.is_finite() && z.im.is_finite()) {
            return Err(Error::numerical(
                CTX,
                "the subspace step produced a non-finite pole; lower the order",
            ));
        }
        out.push(z);
    }
    Ok(out)
}

/// The least-squares problem of the refinement: sections in delta form (module docs).
///
/// Parameters: per 2nd-order section $(\alpha_1, \alpha_2, \beta_1, \beta_0)$, per 1st-order
/// section $(\lambda, \gamma)$, then $D$.
struct Problem<'a> {
    delta: Vec<c64>,
    g: &'a [c64],
    sw: Vec<f64>,
    /// The lines and weights (the residual and its slope, [`FreqData::residual`]).
    data: &'a FreqData,
    /// Section orders (2 or 1).
    sections: Vec<usize>,
    feedthrough: bool,
    /// At most this many poles on or outside the unit circle (`None`: unconstrained).
    limit: Option<usize>,
    h: f64,
}

impl<'a> Problem<'a> {
    fn new(
        data: &'a FreqData,
        warp: &Warp,
        poles: &[c64],
        feedthrough: bool,
        limit: Option<usize>,
    ) -> Result<Self> {
        let n_pairs = poles.iter().filter(|p| p.im > 0.0).count();
        let n_real = poles.iter().filter(|p| p.im == 0.0).count();
        if 2 * n_pairs + n_real != poles.len() {
            return Err(Error::numerical(
                CTX,
                "the poles of the subspace step do not come in conjugate pairs",
            ));
        }
        let mut sections = vec![2; n_pairs + n_real / 2];
        if n_real % 2 == 1 {
            sections.push(1);
        }
        Ok(Self {
            delta: data.z.iter().map(|&z| warp.delta(z)).collect(),
            g: &data.g,
            sw: data.w.iter().map(|w| w.sqrt()).collect(),
            data,
            sections,
            feedthrough,
            limit,
            h: warp.h,
        })
    }

    fn n_params(&self) -> usize {
        self.sections.iter().map(|&d| 2 * d).sum::<usize>() + usize::from(self.feedthrough)
    }

    /// θ with the denominators of `poles` (numerators and D zero), in the section order of `new`.
    fn denominators_from_poles(&self, poles: &[c64]) -> Vec<f64> {
        let lam = |p: c64| (p - 1.0) / self.h;
        let mut pairs: Vec<c64> = poles.iter().copied().filter(|p| p.im > 0.0).collect();
        pairs.sort_by(|x, y| x.im.total_cmp(&y.im));
        let mut real: Vec<f64> = poles
            .iter()
            .filter(|p| p.im == 0.0)
            .map(|p| lam(*p).re)
            .collect();
        real.sort_by(f64::total_cmp);
        let mut th = Vec::with_capacity(self.n_params());
        for p in pairs {
            let l = lam(p);
            th.extend_from_slice(&[-2.0 * l.re, l.norm_sqr(), 0.0, 0.0]);
        }
        for pr in real.chunks(2) {
            if pr.len() == 2 {
                th.extend_from_slice(&[-(pr[0] + pr[1]), pr[0] * pr[1], 0.0, 0.0]);
            } else {
                th.extend_from_slice(&[pr[0], 0.0]);
            }
        }
        if self.feedthrough {
            th.push(0.0);
        }
        th
    }

    /// Basis responses at line `k`: for every parameter that enters linearly, its column.
    /// Returns the model response and, when `jac` is given, fills the derivative row.
    fn eval_line(&self, th: &[f64], k: usize, mut jac: Option<&mut [c64]>) -> c64 {
        let d = self.delta[k];
        let mut g = c64::new(0.0, 0.0);
        let mut i = 0;
        for &s in &self.sections {
            if s == 2 {
                let (a1, a2, b1, b0) = (th[i], th[i + 1], th[i + 2], th[i + 3]);
                let p = d * d + d * a1 + a2;
                let pinv = p.inv();
                let num = d * b1 + b0;
                g += num * pinv;
                if let Some(j) = jac.as_deref_mut() {
                    let np2 = num * pinv * pinv;
                    j[i] = -np2 * d;
                    j[i + 1] = -np2;
                    j[i + 2] = d * pinv;
                    j[i + 3] = pinv;
                }
                i += 4;
            } else {
                let (lam, gam) = (th[i], th[i + 1]);
                let pinv = (d - lam).inv();
                g += pinv * gam;
                if let Some(j) = jac.as_deref_mut() {
                    j[i] = pinv * pinv * gam;
                    j[i + 1] = pinv;
                }
                i += 2;
            }
        }
        if self.feedthrough {
            g += th[i];
            if let Some(j) = jac {
                j[i] = c64::new(1.0, 0.0);
            }
        }
        g
    }

    /// The poles in $z$ of the sections of `th` ($z = 1 + h\lambda$ for each root $\lambda$ of a
    /// section's denominator), complex ones as exact conjugate pairs.
    fn poles(&self, th: &[f64]) -> Vec<c64> {
        let h = self.h;
        let mut out = Vec::with_capacity(self.sections.iter().sum());
        let mut i = 0;
        for &s in &self.sections {
            if s == 2 {
                // λ² + α1 λ + α2
                let (a1, a2) = (th[i], th[i + 1]);
                let disc = a1 * a1 - 4.0 * a2;
                if disc < 0.0 {
                    let z = c64::new(1.0 - h * a1 / 2.0, h * (-disc).sqrt() / 2.0);
                    out.extend_from_slice(&[z, z.conj()]);
                } else {
                    let sq = disc.sqrt();
                    for l in [(-a1 + sq) / 2.0, (-a1 - sq) / 2.0] {
                        out.push(c64::new(1.0 + h * l, 0.0));
                    }
                }
                i += 4;
            } else {
                out.push(c64::new(1.0 + h * th[i], 0.0));
                i += 2;
            }
        }
        out
    }

    /// Whether the sections have at most `limit` poles on or outside the unit circle (always
    /// `true` without a limit).
    fn admissible(&self, th: &[f64]) -> bool {
        let Some(limit) = self.limit else {
            return true;
        };
        let h = self.h;
        let mut i = 0;
        let mut count = 0;
        for &s in &self.sections {
            if s == 2 {
                // z² + a1 z + a2 with a1 = hα1 − 2, a2 = 1 − hα1 + h²α2
                let a1 = h * th[i] - 2.0;
                let a2 = 1.0 - h * th[i] + h * h * th[i + 1];
                let disc = a1 * a1 - 4.0 * a2;
                if disc < 0.0 {
                    // a complex pair, |z|² = a2
                    if a2 >= 1.0 {
                        count += 2;
                    }
                } else {
                    let sq = disc.sqrt();
                    count += usize::from((-a1 + sq).abs() >= 2.0);
                    count += usize::from((-a1 - sq).abs() >= 2.0);
                }
                i += 4;
            } else {
                count += usize::from((1.0 + h * th[i]).abs() >= 1.0);
                i += 2;
            }
        }
        count <= limit
    }

    /// Numerators and D by weighted linear least squares with the denominators of `th` fixed.
    fn fit_numerators(&self, th: &mut [f64]) -> Result<()> {
        let l = self.delta.len();
        let np = self.n_params();
        // the linear parameters: β1, β0 of each 2nd-order section, γ, D
        let mut lin = Vec::new();
        let mut i = 0;
        for &s in &self.sections {
            if s == 2 {
                lin.extend_from_slice(&[i + 2, i + 3]);
                i += 4;
            } else {
                lin.push(i + 1);
                i += 2;
            }
        }
        if self.feedthrough {
            lin.push(i);
        }
        let mut phi = Mat::<f64>::zeros(2 * l, lin.len());
        let mut rhs = Mat::<f64>::zeros(2 * l, 1);
        let mut row = vec![c64::new(0.0, 0.0); np];
        for k in 0..l {
            self.eval_line(th, k, Some(&mut row));
            for (c, &p) in lin.iter().enumerate() {
                phi[(k, c)] = self.sw[k] * row[p].re;
                phi[(l + k, c)] = self.sw[k] * row[p].im;
            }
            rhs[(k, 0)] = self.sw[k] * self.g[k].re;
            rhs[(l + k, 0)] = self.sw[k] * self.g[k].im;
        }
        let x = linalg::lstsq(phi.as_ref(), rhs.as_ref()).map_err(|e| {
            Error::numerical(
                CTX,
                format!("the numerator regression of the subspace poles is degenerate ({e}); lower the order or widen the band"),
            )
        })?;
        for (c, &p) in lin.iter().enumerate() {
            th[p] = x[(c, 0)];
        }
        Ok(())
    }

    /// The block-diagonal delta-companion realisation (module docs).
    fn realise(&self, th: &[f64], ts: f64) -> Result<StateSpace> {
        let n: usize = self.sections.iter().sum();
        let h = self.h;
        let mut a = Mat::<f64>::zeros(n, n);
        let mut b = Mat::<f64>::zeros(n, 1);
        let mut c = Mat::<f64>::zeros(1, n);
        let (mut i, mut s0) = (0, 0);
        for &s in &self.sections {
            if s == 2 {
                a[(s0, s0)] = 1.0;
                a[(s0, s0 + 1)] = h;
                a[(s0 + 1, s0)] = -h * th[i + 1];
                a[(s0 + 1, s0 + 1)] = 1.0 - h * th[i];
                b[(s0 + 1, 0)] = h;
                c[(0, s0)] = th[i + 3];
                c[(0, s0 + 1)] = th[i + 2];
                i += 4;
            } else {
                a[(s0, s0)] = 1.0 + h * th[i];
                b[(s0, 0)] = h;
                c[(0, s0)] = th[i + 1];
                i += 2;
            }
            s0 += s;
        }
        let d = if self.feedthrough { th[i] } else { 0.0 };
        StateSpace::discrete(a, b, c, faer::mat![[d]], ts)
    }
}

impl LeastSquaresProblem for Problem<'_> {
    fn residuals(&mut self, th: &[f64]) -> Option<Vec<f64>> {
        if !self.admissible(th) {
            return None;
        }
        let l = self.delta.len();
        let mut r = vec![0.0; 2 * l];
        for k in 0..l {
            let e = self.data.residual(k, self.eval_line(th, k, None));
            r[k] = e.re;
            r[l + k] = e.im;
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    fn jacobian(&mut self, th: &[f64]) -> Option<Mat<f64>> {
        let l = self.delta.len();
        let np = self.n_params();
        let mut j = Mat::<f64>::zeros(2 * l, np);
        let mut row = vec![c64::new(0.0, 0.0); np];
        for k in 0..l {
            let p = self.eval_line(th, k, Some(&mut row));
            for (q, dp) in row.iter().enumerate() {
                let d = self.data.residual_slope(k, p, *dp);
                j[(k, q)] = d.re;
                j[(l + k, q)] = d.im;
            }
        }
        Some(j)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::pem::lm::jacobian_against_differences;
    use crate::frf::closed_loop::RatioNoise;

    /// A pair, an unstable real pole and two stable ones: the Jacobian tests' sections.
    const TEST_POLES: [c64; 5] = [
        c64::new(0.9, 0.2),
        c64::new(0.9, -0.2),
        c64::new(1.01, 0.0),
        c64::new(0.5, 0.0),
        c64::new(0.7, 0.0),
    ];

    #[test]
    fn jacobian_matches_finite_differences() -> std::result::Result<(), Box<dyn std::error::Error>>
    {
        let f: Vec<f64> = (1..60).map(|k| 7.0 * k as f64).collect();
        let vals: Vec<c64> = f
            .iter()
            .map(|x| c64::new(1.0 / (1.0 + x / 50.0), -0.01 * x))
            .collect();
        let frd = Frd::new(f, vals, None, Some(1e-3))?;
        let data = FreqData::new(&frd, &FreqFitOptions::default())?;
        let warp = Warp::new(&data)?;
        let poles = TEST_POLES;
        let mut prob = Problem::new(&data, &warp, &poles, true, None)?;
        let mut th = prob.denominators_from_poles(&poles);
        prob.fit_numerators(&mut th)?;
        jacobian_against_differences(&mut prob, &th, 1e-6)?;
        // the realisation has the section poles and the same response
        let model = prob.realise(&th, 1e-3)?;
        let resp = model.freq_response_siso(&data.f_hz)?;
        for (k, rk) in resp.iter().enumerate() {
            let pf = prob.eval_line(&th, k, None);
            assert!((rk - pf).norm() <= 1e-10 * (1.0 + pf.norm()));
        }
        let mut mp = model.poles()?;
        mp.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
        for p in poles {
            assert!(mp.iter().any(|m| (m - p).norm() < 1e-12), "{p} in {mp:?}");
        }
        Ok(())
    }

    /// With sample maximum-likelihood weights the residual $(P_\theta - G)/\sqrt{v(P_\theta)}$
    /// has the variance's slope in its Jacobian: checked against central differences.
    #[test]
    fn sml_jacobian_matches_finite_differences(
    ) -> std::result::Result<(), Box<dyn std::error::Error>> {
        let f: Vec<f64> = (1..60).map(|k| 7.0 * k as f64).collect();
        let vals: Vec<c64> = f
            .iter()
            .map(|x| c64::new(1.0 / (1.0 + x / 50.0), -0.01 * x))
            .collect();
        let noise: Vec<RatioNoise> = f
            .iter()
            .map(|x| RatioNoise {
                a: 1e-3 * (1.0 + x / 400.0),
                b: 2e-3,
                c: c64::new(3e-4, -1e-4 * x / 400.0),
            })
            .collect();
        let frd = Frd::new(f, vals, None, Some(1e-3))?;
        let opts = FreqFitOptions {
            weights: super::super::freqfit::FreqWeights::SampleMaximumLikelihood(noise),
            ..FreqFitOptions::default()
        };
        let data = FreqData::new(&frd, &opts)?;
        let warp = Warp::new(&data)?;
        let poles = TEST_POLES;
        let mut prob = Problem::new(&data, &warp, &poles, true, None)?;
        let mut th = prob.denominators_from_poles(&poles);
        prob.fit_numerators(&mut th)?;
        // off the numerators' optimum, so that the residual's weight term matters
        for v in th.iter_mut() {
            *v *= 1.05;
        }
        let j = jacobian_against_differences(&mut prob, &th, 1e-5)?;
        let mut weight_term = 0.0f64;
        // the slope term matters: the Jacobian without it (∂P/√v alone) is off by more than
        // the differences' tolerance
        let l = data.len();
        let mut row = vec![c64::new(0.0, 0.0); th.len()];
        for k in 0..l {
            let pk = prob.eval_line(&th, k, Some(&mut row));
            let sw = 1.0
                / prob
                    .data
                    .model_variance(k, pk)
                    .ok_or("fixed weights")?
                    .0
                    .sqrt();
            for (q, dp) in row.iter().enumerate() {
                let d = *dp * sw;
                weight_term = weight_term
                    .max((d.re - j[(k, q)]).abs() / (1.0 + d.re.abs()))
                    .max((d.im - j[(l + k, q)]).abs() / (1.0 + d.im.abs()));
            }
        }
        assert!(weight_term > 1e-3, "{weight_term}");
        Ok(())
    }

    /// An AMB-like plant (unstable and stable real poles at 1.0206 and 0.9795, pairs at 125 Hz
    /// ζ = 0.2 and 754 Hz ζ = 0.016, a real pole at 1868 Hz) at 20 kHz, seen on 253 lines in
    /// 12–1000 Hz: the warped subspace step is far more accurate than the unwarped one ($a = 0$).
    #[test]
    fn warping_makes_the_subspace_step_accurate_on_a_short_arc() {
        let ts = 5e-5;
        let pi = std::f64::consts::PI;
        let pair = |f: f64, z: f64| {
            let s = c64::new(-z * 2.0 * pi * f, 2.0 * pi * f * (1.0 - z * z).sqrt());
            (s * ts).exp()
        };
        let (p1, p2) = (pair(125.0, 0.2), pair(754.0, 0.016));
        let n = 7;
        let mut a = Mat::<f64>::zeros(n, n);
        for (o, p) in [(0, p1), (2, p2)] {
            a[(o, o)] = p.re;
            a[(o, o + 1)] = p.im;
            a[(o + 1, o)] = -p.im;
            a[(o + 1, o + 1)] = p.re;
        }
        a[(4, 4)] = 1.0206;
        a[(5, 5)] = 0.9795;
        a[(6, 6)] = 0.55;
        let b = Mat::from_fn(n, 1, |i, _| [1.0, 0.0, 1.0, 0.0, 1.0, 1.0, 1.0][i]);
        let c = Mat::from_fn(1, n, |_, j| [0.02, 0.01, 0.1, -0.05, 0.01, -0.01, 0.3][j]);
        let truth = StateSpace::discrete(a, b, c, faer::mat![[0.0]], ts).unwrap();
        // the in-band poles (the one at 1868 Hz is weakly determined by 12–1000 Hz data)
        let in_band = [p1, p2, c64::new(1.0206, 0.0), c64::new(0.9795, 0.0)];
        let f: Vec<f64> = (3..256).map(|k| 3.91 * k as f64).collect();
        let g0 = truth.freq_response_siso(&f).unwrap();
        let pole_error = |noise: f64, warped: bool, q: usize| -> f64 {
            let mut seed = 12345u64;
            let mut rnd = || {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            };
            let vals: Vec<c64> = g0
                .iter()
                .map(|g| g * (1.0 + c64::new(rnd(), rnd()) * noise * 3.4))
                .collect();
            let frd = Frd::new(f.clone(), vals, None, Some(ts)).unwrap();
            let data = FreqData::new(&frd, &FreqFitOptions::default()).unwrap();
            let mut w = Warp::new(&data).unwrap();
            if !warped {
                w.a = 0.0;
            }
            let p = subspace_poles(&data, &w, n, q).unwrap();
            in_band
                .iter()
                .map(|t| p.iter().map(|x| (x - t).norm()).fold(f64::MAX, f64::min))
                .fold(0.0, f64::max)
        };
        // exact data: rounding level warped, ~1e-9 unwarped
        let (ew, eu) = (pole_error(0.0, true, 9), pole_error(0.0, false, 9));
        assert!(
            ew < 1e-13 && eu > 1e-11,
            "exact: warped {ew:e}, unwarped {eu:e}"
        );
        // relative noise of 0.14 % RMS: ~1e-5 warped, ~1e-2 unwarped
        for q in [9, 16] {
            let (ew, eu) = (pole_error(1e-3, true, q), pole_error(1e-3, false, q));
            assert!(
                ew < 1e-4 && eu > 100.0 * ew,
                "q = {q}: warped {ew:e}, unwarped {eu:e}"
            );
        }
    }
}
