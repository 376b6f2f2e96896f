//! ARMAX, output-error (OE) and Box–Jenkins (BJ) models by the prediction-error method (PEM).
//!
//! # Predictor and criterion
//! The general SISO structure (see [`PolyModel`]) is
//! $$ A(q)\,y_t = \frac{B(q)}{F(q)}\,u_t + \frac{C(q)}{D(q)}\,e_t, $$
//! $e$ white, $A, C, D, F$ monic. Solving for the innovation gives the prediction error
//! $$ \varepsilon_t(\theta) = \frac{D}{C}\Bigl(A\,y_t - \frac BF\,u_t\Bigr) = \frac DC\, w_t,
//!    \qquad w_t = A\,y_t - v_t,\quad v_t = \frac BF\,u_t, $$
//! and the one-step predictor $\hat y_t = y_t - \varepsilon_t$. PEM minimises
//! $$ V(\theta) = \tfrac12 \sum_{t=0}^{N-1} \varepsilon_t(\theta)^2 $$
//! over $\theta = [a_1 \dots a_{n_a},\; b_0 \dots b_{n_b-1},\; c_1 \dots c_{n_c},\; d_1 \dots d_{n_d},\;
//! f_1 \dots f_{n_f}]$, where $b_j$ multiplies $q^{-(n_k+j)}$ (MATLAB's `[na nb nc nd nf nk]`).
//! This is also the order of [`Fitted::params`] and of the covariance. All filters start from
//! zero initial conditions (samples before $t = 0$ are taken as zero, MATLAB's
//! `InitialCondition = 'zero'`); records that do not start at rest should have their first
//! transient removed (`data::drop_transient`).
//!
//! The output error $w$ is computed in double-double arithmetic and rounded once, so it is
//! accurate relative to $|w|$ even when $A y$ and $\frac BF u$ cancel many digits (data with
//! very little noise, where plain double precision would leave the loss noisy at the level of
//! $10^{-16}|y|/|w|$ and the noise polynomials undetermined).
//!
//! The predictor is a stable filter of the data only if $C$ and $F$ are stable; $D$ is in the
//! numerator and $A$ acts as an FIR filter on $y$, so ARX and ARMAX predictors stay stable even
//! for an unstable $A$ (an open-loop unstable plant).
//!
//! # Analytic gradient
//! With $\partial(1/P)/\partial p_i = -q^{-i}/P^2$ for a monic $P = 1 + \sum p_i q^{-i}$, the gradient
//! $\psi_t = \partial\varepsilon_t/\partial\theta$ consists of filtered, delayed signals:
//! $$ \begin{aligned}
//! \frac{\partial\varepsilon_t}{\partial a_i} &= \frac DC\, y_{t-i}, &
//! \frac{\partial\varepsilon_t}{\partial b_j} &= -\frac{D}{CF}\, u_{t-n_k-j}, &
//! \frac{\partial\varepsilon_t}{\partial f_i} &= \frac{D\,B}{C\,F^2}\, u_{t-i} = \frac{D}{CF}\, v_{t-i}, \\
//! \frac{\partial\varepsilon_t}{\partial c_i} &= -\frac{D\,w_t}{C^2}\Big|_{q^{-i}} = -\frac1C\,\varepsilon_{t-i}, &
//! \frac{\partial\varepsilon_t}{\partial d_i} &= \frac1C\, w_{t-i}. &&
//! \end{aligned} $$
//! The signs: $a_i$ enters $w$ with $+q^{-i}y$; $b_j$ enters with $-q^{-n_k-j}u/F$; $f_i$ enters through
//! $-B/F$, whose derivative is $+Bq^{-i}/F^2$; $c_i$ enters through $1/C$ (derivative
//! $-q^{-i}/C^2$) and $d_i$ through the numerator. With zero initial conditions, filtering and
//! delaying commute exactly, so these are the exact derivatives of the finite-sample criterion
//! (tested against finite differences). The Jacobian $J = [\psi_0 \dots \psi_{N-1}]^\top$ costs about
//! five filter passes, $O(N (n_a + n_b + n_c + n_d + n_f))$.
//!
//! # Focus
//! [`Focus::Prediction`] minimises the one-step prediction errors above. [`Focus::Simulation`]
//! fits the deterministic part only, with the noise model fixed to 1: it minimises
//! $\tfrac12\sum (y_t - \frac{B}{AF} u_t)^2$ over $A, B, F$ (so $A \cdot F$ must be stable and only one
//! of $n_a, n_f$ may be positive), then, with $G$ fixed, fits $C, D$ to the output error
//! $w = A y - (B/F) u$ by the prediction criterion. Its gradient: $\partial\varepsilon/\partial a_i =
//! \frac{1}{A}\frac{B}{AF}u_{t-i}$, $\partial\varepsilon/\partial b_j = -\frac{1}{AF}u_{t-n_k-j}$,
//! $\partial\varepsilon/\partial f_i = \frac1F\frac{B}{AF}u_{t-i}$.
//!
//! # Minimisation
//! Levenberg–Marquardt with Moré's scaling and trust-region control of the damping ([`lm`]):
//! each step is the least-squares solution of the scaled augmented Jacobian by QR. A trial
//! step that makes the predictor unstable ($C$ or $F$, or $A F$ under the simulation focus) is
//! rejected and shrinks the trust region; the returned model therefore always has a stable
//! predictor. Poles are never reflected. If the iteration ends pressed against the stability
//! boundary, or the consistent instrumental-variable start already has an unstable $F$, the
//! best model has an unstable predictor and the estimator fails with [`Error::Unstable`]: an
//! OE/BJ model cannot describe an unstable plant, so identify the stable closed-loop map
//! $T_{ry}$ from the excitation $r$, or use ARX/ARMAX (stable predictor for unstable $A$).
//!
//! # Stopping
//! Besides the numerical tolerances of [`lm`] (relative loss change $10^{-12}$, relative step
//! $10^{-10}$, gradient cosine $10^{-12}$), the default options stop when the rest of the
//! iteration cannot change the estimate by an amount the data could reveal. At the current
//! point, with the QR factorisation $[J\; \varepsilon] = Q\left[\begin{smallmatrix} R & z \\ 0 & \rho
//! \end{smallmatrix}\right]$, the Gauss–Newton step $p = -R^{-1} z$ would lower $V$ by
//! $\tfrac12\lVert z\rVert^2 = \tfrac12 g^\top (J^\top J)^{-1} g$ ($g = J^\top\varepsilon$; MATLAB's
//! "expected improvement"), and its length in the metric of the asymptotic covariance
//! $P = \hat\sigma^2 (J^\top J)^{-1}$, $\hat\sigma^2 = \lVert\varepsilon\rVert^2/(N - d)$, is
//! $$ p^\top P^{-1} p = \lVert z\rVert^2 / \hat\sigma^2 . $$
//! * **Significance** ([`lm::StopReason::Significance`]): stop when
//!   $\lVert z\rVert^2 \le \kappa^2 \hat\sigma^2$, i.e. the remaining step is shorter than $\kappa$
//!   standard errors jointly (so shorter than $\kappa\sigma_i$ in every parameter), with
//!   $\kappa$ = [`DEFAULT_SIGNIFICANCE_TOL`] = 0.1: the stopped estimate's mean-square error in any
//!   direction exceeds the exact minimiser's by at most a factor $1 + \kappa^2$ = 1.01.
//!   MATLAB's relative rule ($\lVert z\rVert^2/\lVert\varepsilon\rVert^2 \le 10^{-4}$) is the same
//!   test with $\kappa^2 = 10^{-4}(N - d)$, i.e. $\kappa \approx 3$ standard errors at
//!   $N = 10^5$: looser the longer the record, which is why it is not used.
//! * **Stagnation** ([`lm::StopReason::Stagnation`]): the remaining step is shorter than half a
//!   standard error *and* the last five accepted steps together lowered $V$ by less than
//!   $\kappa^2\hat\sigma^2/2$ (the improvement the significance rule leaves). This ends the
//!   crawl of the trust region in a curved valley of the polynomial coefficients (a lightly
//!   damped $F$ at 20 kHz, where BJ(4,2,2,4,1) on the twin's loop spent 40–80 steps gaining
//!   0.2 $\hat\sigma^2$ in total); the half-standard-error condition keeps it from stopping a
//!   slow phase that is still far from the optimum (without it, one of the first six random
//!   rigs stopped 0.46 point of validation fit short).
//!
//! [`PemOptions::with_significance_tol`]`(0.0)` switches both off (iterate to the numerical
//! tolerances, for example to compare with another optimiser's minimum).
//!
//! **Residual accuracy.** With the statistical rule on, the iteration's trial residuals are
//! computed in plain double precision whenever a rigorous bound of its rounding error is below
//! $10^{-3}\kappa^2/(N - d)$ of $\lVert w\rVert$ (the loss is then known far better than the
//! smallest change the rule acts on), else in double-double (see the section above); the
//! bound is $\gamma_{n_a+1}\lVert |A| * |y|\rVert + \lVert h_{1/F}\rVert_1\,\gamma_{n_b+n_f}
//! \lVert |B| * |u| + |F - 1| * |v|\rVert$ ($\gamma_k \approx k\,2^{-53}$, $h_{1/F}$ the impulse
//! response of $1/F$). On the twin's seed record it selects plain double for ARMAX (no
//! recursion, bound $\approx 10^{-14}\lVert w\rVert$) and double-double for OE/BJ ($F$ poles at
//! $|z| \approx 0.998$, $\lVert h_{1/F}\rVert_1 \approx 10^7$). The final loss, the covariance and
//! every run with $\kappa = 0$ use double-double.
//!
//! # Open-loop data
//! That refusal is right for an AMB plant measured in closed loop, where $u \to y$ is really
//! unstable. On open-loop data an unstable *start* is usually an artefact (an integrator such as
//! EMPS's position, estimated at $|z| = 1.00003$; a lightly damped mode of the flutter data put
//! at $|z| = 1.003$ by a coloured input): with [`PemOptions::with_open_loop`] the start's roots
//! beyond $|z| = 0.99$ are moved radially onto $0.99$ (same angle), $B$ is re-estimated given
//! that $F$, and the iteration moves every pole freely; an optimum on the stability boundary is
//! returned with a warning ([`PemReport::warnings`]) instead of an error. Poles of the
//! *estimate* are never moved. Simulation-focus OE of a truly unstable system stays
//! ill-posed either way.
//!
//! # Initialisation
//! The start decides which local minimum is found, so it comes from consistent non-iterative
//! estimators (each a few least-squares problems):
//! * $B, F$ (OE, BJ, and $B/A$ under the simulation focus): ARX of matched orders by least
//!   squares; if its $F$ is unstable, a basic IV estimate with delayed inputs as instruments;
//!   then up to four iterations of the *simplified refined instrumental variable* method
//!   (SRIV): prefilter $y, u$ by $1/F$ and use the simulated noise-free output $\frac BF u$ (also
//!   prefiltered) as instruments. For OE data the prefiltered equation has white noise, so SRIV
//!   is close to the OE optimum and consistent for any noise colour in open loop. A lightly
//!   damped pole that SRIV puts just outside the unit circle (radius below 1.02) is moved
//!   radially to 0.9995 (same frequency) for the next prefilter; an ARX/IV start with poles
//!   further out is the "unstable system" error below.
//! * $A \cdot F$ of the general structure: SRIV with a denominator of order $n_a + n_f$, a
//!   Hannan–Rissanen ARMA model of the output error, and $A$ = the roots of $\widehat{AF}$
//!   closest to those of the noise denominator $\widehat{AD}$ (the factor the two share).
//! * $A, B, C$ (ARMAX; general without $F$): Hannan–Rissanen. A long ARX model (order
//!   $\max(20, 3(n_a + n_c + n_d + n_f))$, at most $N/10$) estimates the innovations $\hat e$;
//!   then $y_t - \hat e_t$ is regressed on $[-y_{t-i}, u_{t-n_k-j}, \hat e_{t-k}]$, a linear problem.
//! * $C, D$ (BJ, general, simulation focus): Hannan–Rissanen on the output error
//!   $w = A y - \frac BF u$ with a long AR model.
//! * A start $C$ or $D$ with a root beyond $|z| = 0.99$ is moved radially to $0.95$ (a start
//!   only; the estimate is never altered). For noise-free data the long model leaves no residual
//!   and $C = D = 1$ is used.
//!
//! * ARMAX$(n, n, n, n_k \ge 1)$ (prediction focus): a second start from the innovations form
//!   of an N4SID model of order $n$ ($A$ its characteristic polynomial, $B$ its numerator, $C$
//!   from the predictor's poles $\det(I - q^{-1}(\mathbf A - K\mathbf C))$). The Hannan–Rissanen
//!   long ARX (order 24) cannot represent an innovations filter $1/C$ with roots at
//!   $|z| \approx 0.99$, and the subspace Kalman gain of closed-loop data can be far off, so
//!   neither start is reliably the better one (below).
//! * BJ with $n_f \ge 2$ (prediction focus): a second start from the OE state-space start below
//!   for $B, F$ and, on its output error, Hannan–Rissanen $C, D$ refined by a few
//!   Levenberg–Marquardt steps of the ARMA criterion with $G$ fixed (cheap: no input
//!   filtering). On the twin's $T_{ry}$, BJ(4,2,2,4,1) from SRIV ended in local minima with
//!   validation fits of 5.8 % and 66 % (rigs 1, 2); from this start 87.2 % and 80.8 %.
//! * OE with $n_f \ge 2$ (and $n_k \ge 1$): a second start from a state-space model (N4SID of
//!   order $n_f$ on $u$ delayed by $n_k - 1$, refined by the state-space prediction-error method
//!   under the simulation focus — the OE criterion in a well-conditioned parameterisation —, its
//!   denominator as $F$ and its numerator as $B$ when $n_b = n_f$, otherwise $B$ by least squares
//!   given $F$); the iteration goes on from
//!   whichever start has the smaller loss, with the whole budget (the other start if that
//!   iteration fails). ARMAX and BJ instead iterate both starts 5 steps and go on from the one
//!   with the smaller loss then (the initial loss picked a start from which the iteration crawls
//!   on 7 of 40 ARMAX/BJ fits of random rigs 1–20); the 10 probe steps count against the budget.
//!   ARMAX orders its starts by the *projected* loss (each start's $C$ with $A, B$ optimal for
//!   it, [variable projection](#armax-and-boxjenkins-by-variable-projection)). Iterating only
//!   the start with the smaller projected loss converged on all 20 rigs, but on the real
//!   open-loop data sets it reached worse local minima (ARMAX(4,4,4,1) of the DaISy ball-and-beam
//!   data: loss +1.4 %; cascaded tanks ARMAX(3,3,3,1): +1.3 %) and ARMAX(2,2,2,1) of the flutter
//!   data stopped at the iteration limit; with the probe those reach the earlier optima and
//!   flutter converges in 87 iterations. The polynomial coefficients of an 8th-order $F$ with poles clustered near
//!   $z = 1$ are extremely ill-conditioned: on a lightly damped closed loop sampled at 20 kHz (the
//!   twin's $T_{ry}$, OE(8, 8, 1) on the seed record) the iteration from SRIV alone was still
//!   moving after 400 iterations (estimation fit 95.78 %; the optimum, reached from the
//!   state-space start in 4 iterations, 95.89 %).
//!
//! # ARMAX and Box–Jenkins by variable projection
//! For a fixed $C$ the ARMAX prediction error $\varepsilon = \frac AC y - \frac BC u$ is linear
//! in $A$ and $B$, so the ARMAX iteration first minimises over $C$ alone, $A$ and $B$ eliminated
//! by least squares at every $C$ (Golub–Pereyra variable projection with Kaufman's Jacobian,
//! and an extrapolated step [`LmOptions::with_extrapolation`]), then runs the joint iteration
//! from that point with the rest of the budget; the joint stopping rules decide convergence
//! (at a reduced optimum they hold at once) and the joint Jacobian gives the covariance. The
//! Box–Jenkins error $\varepsilon = \frac DC y - B\,\frac{D}{CF} u$ is linear in $B$, so BJ
//! iterates $C, D, F$ the same way (both probes and the continuation). Over random rigs 1–20
//! (BJ(4,2,2,4,1) of $r \to y$) it converged on all 20, where the joint iteration had stopped at
//! the limit on 2, with validation fits within 0.03 point of the joint iteration's. On the
//! twin's seed record the optimum of ARMAX(4,4,4,1) of $u \to y$ puts a pair of $C$ zeros
//! next to the bending mode's pair of $A$ poles (760 Hz, $|z| = 0.992$ and $0.996$): the joint
//! iteration followed that near cancellation along a curved valley for 126 iterations (100 of
//! the default budget, then stopped unconverged), the projected one needs 30 (with the probes).
//! Over random rigs 1–20 it converged on all 20 (median 14.5 iterations, at most 39), where the
//! joint iteration had stopped at the limit on 2 and needed up to 103 (the validation fits are
//! equal or better, rig 6 +0.016 point).
//!
//! A long-ARX residual was chosen over a matched-order ARX residual because it is consistent
//! for the innovations whatever the true structure; the SRIV step was chosen over plain IV
//! because its prefiltering makes it nearly efficient for OE, which shortens the iteration.
//!
//! # Uncertainty
//! At the minimum, $P = \hat\lambda (J^\top J)^{-1}$ with $\hat\lambda = 2V/(N - d)$, computed from the
//! Jacobian at the returned parameters (column-equilibrated, so that badly scaled parameters do
//! not matter). This is the asymptotic covariance when the model structure contains the true
//! system. It is omitted (`None`) when $J$ is numerically rank deficient (for example $C$ on
//! noise-free data). Under the simulation focus the estimate solves the stacked equations
//! $g(\theta) = [\Psi_G^\top \varepsilon_{\rm sim};\; J_H^\top \varepsilon] = 0$ ($\Psi_G$: simulation gradient in
//! $G$'s parameters, $J_H$: prediction gradient in $C, D$), whose covariance is the sandwich
//! $$ P = \hat\lambda\, M^{-1} X^\top X M^{-\top}, \quad
//!    M = \begin{bmatrix} \Psi_G^\top\Psi_G & 0 \\ J_H^\top J_G & J_H^\top J_H \end{bmatrix}, \quad
//!    X = [\mathcal H^\top \Psi_G,\; J_H], $$
//! where $\varepsilon_{\rm sim} = \mathcal H e$ with the lower-triangular Toeplitz matrix $\mathcal H$ of the
//! estimated $H = C/(AD)$ (so $\mathcal H^\top\Psi_G$ is an anticausal filtering). It accounts for the
//! coloured output error seen by the $G$ fit and for the $G$ error that the second stage
//! inherits; for OE it reduces to $\hat\lambda(\Psi^\top\Psi)^{-1}$. The second-stage $C, D$ also
//! inherit an $O(1/N)$ *bias* from the $G$ error, which no covariance covers (for
//! $c_1 = 0.5$: about $-0.06$ at $N = 1000$, $-0.017$ at $N = 4000$); use the prediction focus
//! when the noise model matters.
//!
//! # Threads
//! Independent parts run side by side on rayon's global pool: the two starts, the two start
//! probes, and the row parts of each step's QR factorisation of $[J\;\varepsilon]$ (one part per
//! 16 384 samples, at most 8, reduced by one QR of the stacked triangles). The cuts depend on the
//! data only, so an estimate is bit for bit the same on any number of threads
//! (`RAYON_NUM_THREADS=1` keeps it on one core).
//!
//! # Requirements on the problem
//! * Open-loop data, or closed-loop data with a noise model that contains the true one
//!   (ARMAX/BJ with the prediction focus; OE and the simulation focus are biased in closed loop).
//! * A persistently exciting input of order at least $n_b + n_f$ (or $n_a + n_b$); a constant
//!   input is an error.
//! * $N > \max$ lag $+ 2d$ samples for $d$ parameters (the long model of the start uses up to
//!   $N/10$ lags, fewer on short records).
//! * The true $C$ (and $F$ for OE/BJ) stable; otherwise see "Minimisation".
//! * Complexity: $O(N d^2)$ per iteration. Over 300 random OE/ARMAX/BJ systems (orders up to
//!   4, 40 % lightly damped, noise 1–100 % of the output, $N$ = 2000) the median was 5
//!   iterations, the 90th percentile 13; two of the 300 (4th-order, lightly damped, noise as
//!   large as the output) ended in a worse local minimum than the truth.
//!
//! # Reference
//! L. Ljung, *System Identification: Theory for the User*, 2nd ed., Prentice Hall, 1999:
//! ch. 4 (polynomial structures and their predictors), ch. 7 (the prediction-error criterion),
//! ch. 9 (asymptotic covariance), ch. 10 (iterative search, gradients, initial values).
//! E. J. Hannan and J. Rissanen, "Recursive estimation of mixed autoregressive-moving average
//! order", *Biometrika* 69(1), 1982. P. C. Young, "Some observations on instrumental variable
//! methods of time-series analysis", *Int. J. Control* 23(5), 1976
//! (SRIV). J. J. Moré, "The Levenberg–Marquardt algorithm: implementation and theory", 1978.
//!
//! # Example
//! ```
//! use ambid_core::estimate::pem::{oe, PemOptions};
//! use ambid_core::lti::PolyModel;
//! use rand::{RngExt, SeedableRng};
//! use rand_chacha::ChaCha8Rng;
//! use rand_distr::StandardNormal;
//! // y = (0.5 q^-1 + 0.2 q^-2) / (1 - 1.5 q^-1 + 0.7 q^-2) u, white input, no noise
//! let truth = PolyModel::oe(vec![0.0, 0.5, 0.2], vec![1.0, -1.5, 0.7], 1e-3).unwrap();
//! let mut rng = ChaCha8Rng::seed_from_u64(1);
//! let u: Vec<f64> = (0..1000).map(|_| rng.sample(StandardNormal)).collect();
//! let y = truth.simulate(&u, None, None).unwrap();
//! let (fit, report) = oe(&y, &u, 2, 2, 1, 1e-3, &PemOptions::default()).unwrap();
//! // θ = [b0, b1, f1, f2]
//! for (got, want) in fit.params.iter().zip([0.5, 0.2, -1.5, 0.7]) {
//!     assert!((got - want).abs() < 1e-9);
//! }
//! assert!(report.lm.reason.converged());
//! ```

pub mod lm;

mod init;
mod predictor;
mod varpro;

use self::lm::{LeastSquaresProblem, LmOptions, LmReport, StopReason};
use self::predictor::{errors, errors_and_gradient, filter, max_root, mul, Accuracy, Polys};
use super::Fitted;
use crate::error::{check_finite, Error, Result};
use crate::lti::{PolyModel, Structure};
use faer::Mat;

/// What the criterion fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Focus {
    /// One-step prediction errors $\varepsilon = (D/C)(A y - (B/F) u)$: the maximum-likelihood
    /// criterion for Gaussian innovations.
    #[default]
    Prediction,
    /// Simulation errors $y - B/(AF)\,u$ for $G$ (noise model fixed to 1), then the noise
    /// model with $G$ fixed. Emphasises the fit of $G$ in open-loop simulation.
    Simulation,
}

/// Options of the prediction-error estimators; the setters validate their arguments.
///
/// # Example
/// ```
/// use ambid_core::estimate::pem::{Focus, PemOptions};
/// let o = PemOptions::default()
///     .with_focus(Focus::Simulation)
///     .with_max_iterations(50)
///     .unwrap();
/// assert_eq!(o.focus(), Focus::Simulation);
/// assert_eq!(o.lm().max_iterations(), 50);
/// assert!(PemOptions::default().with_loss_tol(-1.0).is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PemOptions {
    focus: Focus,
    lm: LmOptions,
    open_loop: bool,
}

/// The default statistical stopping tolerance $\kappa$ of the prediction-error estimators, in
/// standard errors (module docs, "Stopping").
pub const DEFAULT_SIGNIFICANCE_TOL: f64 = 0.1;

impl Default for PemOptions {
    /// Prediction focus, closed-loop (strict) data, 100 iterations, and the statistical stopping
    /// rule with $\kappa$ = [`DEFAULT_SIGNIFICANCE_TOL`] on top of the numerical tolerances of
    /// [`LmOptions::default`].
    fn default() -> Self {
        Self {
            focus: Focus::default(),
            lm: LmOptions::default()
                .with_significance_tol(DEFAULT_SIGNIFICANCE_TOL)
                .unwrap_or_default(),
            open_loop: false,
        }
    }
}

impl PemOptions {
    /// Sets the criterion (default [`Focus::Prediction`]).
    pub fn with_focus(mut self, focus: Focus) -> Self {
        self.focus = focus;
        self
    }
    /// Sets all Levenberg–Marquardt options at once.
    pub fn with_lm(mut self, lm: LmOptions) -> Self {
        self.lm = lm;
        self
    }
    /// Maximum number of Levenberg–Marquardt steps (default 100).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for 0.
    pub fn with_max_iterations(mut self, n: usize) -> Result<Self> {
        self.lm = self.lm.with_max_iterations(n)?;
        Ok(self)
    }
    /// Relative loss-change tolerance (default 1e-12). Stopping at a relative change $\tau$
    /// leaves the estimate within about $\sqrt{N\tau}$ standard deviations of the exact
    /// minimiser (5e-5 σ for N = 2000): statistically irrelevant, but set 0 (and
    /// [`Self::with_significance_tol`] 0) to iterate to machine precision when the exact optimum
    /// matters.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a negative or non-finite value.
    pub fn with_loss_tol(mut self, tol: f64) -> Result<Self> {
        self.lm = self.lm.with_loss_tol(tol)?;
        Ok(self)
    }
    /// Relative step tolerance (default 1e-10).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a negative or non-finite value.
    pub fn with_step_tol(mut self, tol: f64) -> Result<Self> {
        self.lm = self.lm.with_step_tol(tol)?;
        Ok(self)
    }
    /// Statistical stopping tolerance $\kappa$ in standard errors (default
    /// [`DEFAULT_SIGNIFICANCE_TOL`] = 0.1; 0 switches the rule off): the iteration stops when
    /// the Gauss–Newton step from the current point is shorter than $\kappa$ standard errors of
    /// the estimate (module docs, "Stopping"). Set 0 (and [`Self::with_loss_tol`] 0) to iterate
    /// to the numerical optimum, for example to compare with another optimiser's result.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a negative or non-finite value.
    pub fn with_significance_tol(mut self, kappa: f64) -> Result<Self> {
        self.lm = self.lm.with_significance_tol(kappa)?;
        Ok(self)
    }
    /// Gradient (cosine) tolerance (default 1e-12).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a negative or non-finite value.
    pub fn with_gradient_tol(mut self, tol: f64) -> Result<Self> {
        self.lm = self.lm.with_gradient_tol(tol)?;
        Ok(self)
    }
    /// Declares the data open-loop (default `false`: the strict behaviour that suits an AMB
    /// plant in closed loop, where an unstable $u \to y$ estimate is real).
    ///
    /// With `true`, a start whose denominator ($F$; $A F$ under the simulation focus) is
    /// unstable after both least squares and IV (an integrator, a lightly damped mode estimated
    /// just outside the unit circle, a coloured input) is *stabilised*: its roots beyond
    /// $|z| = 0.99$ are moved radially onto $|z| = 0.99$ and $B$ is re-estimated given that $F$.
    /// Only the start is changed; the iteration then moves every pole freely within the
    /// stability region of the predictor. An iteration that ends pressed against that boundary
    /// returns its model with a warning in [`PemReport::warnings`] instead of an error. Never use
    /// it for an open-loop unstable plant measured in closed loop: there the instability is real
    /// and an output-error model of $u \to y$ is ill-posed.
    pub fn with_open_loop(mut self, open_loop: bool) -> Self {
        self.open_loop = open_loop;
        self
    }
    /// Whether the data are declared open-loop ([`Self::with_open_loop`]).
    pub fn open_loop(&self) -> bool {
        self.open_loop
    }
    /// The criterion.
    pub fn focus(&self) -> Focus {
        self.focus
    }
    /// The Levenberg–Marquardt options.
    pub fn lm(&self) -> &LmOptions {
        &self.lm
    }
}

/// Polynomial orders in MATLAB's `[na nb nc nd nf nk]` sense: `nb` coefficients of $B$ after
/// `nk` leading zeros, `na` (etc.) free coefficients of the monic polynomials.
///
/// # Example
/// ```
/// use ambid_core::estimate::pem::Orders;
/// use ambid_core::lti::{PolyModel, Structure};
/// let m = PolyModel::oe(vec![0.0, 0.0, 1.0, 0.5], vec![1.0, -0.9], 1.0).unwrap();
/// let o = Orders::of(&m);
/// assert_eq!(o, Orders::oe(2, 1, 2));
/// assert_eq!(o.params(&m).unwrap(), vec![1.0, 0.5, -0.9]); // [b, f]
/// assert_eq!(o.model(Structure::Oe, &[1.0, 0.5, -0.9], 1.0).unwrap(), m);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Orders {
    /// Free coefficients of $A$.
    pub na: usize,
    /// Coefficients of $B$ (at least 1).
    pub nb: usize,
    /// Free coefficients of $C$.
    pub nc: usize,
    /// Free coefficients of $D$.
    pub nd: usize,
    /// Free coefficients of $F$.
    pub nf: usize,
    /// Input delay (leading zeros of $B$).
    pub nk: usize,
}

impl Orders {
    /// ARMAX orders.
    pub fn armax(na: usize, nb: usize, nc: usize, nk: usize) -> Self {
        Self {
            na,
            nb,
            nc,
            nk,
            ..Self::default()
        }
    }
    /// OE orders.
    pub fn oe(nb: usize, nf: usize, nk: usize) -> Self {
        Self {
            nb,
            nf,
            nk,
            ..Self::default()
        }
    }
    /// BJ orders.
    pub fn bj(nb: usize, nc: usize, nd: usize, nf: usize, nk: usize) -> Self {
        Self {
            nb,
            nc,
            nd,
            nf,
            nk,
            ..Self::default()
        }
    }
    /// The orders of a model: lengths of its polynomials, $n_k$ = leading zeros of $B$.
    pub fn of(model: &PolyModel) -> Self {
        let nk = model.delay().min(model.b().len().saturating_sub(1));
        Self {
            na: model.a().len() - 1,
            nb: model.b().len() - nk,
            nc: model.c().len() - 1,
            nd: model.d().len() - 1,
            nf: model.f().len() - 1,
            nk,
        }
    }
    /// Number of parameters $d = n_a + n_b + n_c + n_d + n_f$.
    pub fn n_params(&self) -> usize {
        self.na + self.nb + self.nc + self.nd + self.nf
    }
    /// Longest lag of any regressor: $\max(n_a, n_k + n_b - 1, n_c, n_d, n_f)$.
    pub fn max_lag(&self) -> usize {
        self.na
            .max((self.nk + self.nb).saturating_sub(1))
            .max(self.nc)
            .max(self.nd)
            .max(self.nf)
    }
    /// The parameter vector $\theta$ of `model` in the order documented in the module docs.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if the model's polynomials do not have these orders.
    pub fn params(&self, model: &PolyModel) -> Result<Vec<f64>> {
        if Orders::of(model) != *self {
            return Err(Error::invalid(
                "orders",
                format!(
                    "the model has orders {:?}, not {:?}",
                    Orders::of(model),
                    self
                ),
            ));
        }
        Ok(Polys::from_model(model).theta(self))
    }
    /// The model with parameters `theta` (order as in the module docs).
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] for a wrong length; the errors of [`PolyModel::new`].
    pub fn model(&self, structure: Structure, theta: &[f64], ts: f64) -> Result<PolyModel> {
        if theta.len() != self.n_params() {
            return Err(Error::DimensionMismatch {
                context: "Orders::model: parameter vector",
                expected: self.n_params().to_string(),
                got: theta.len().to_string(),
            });
        }
        let p = Polys::from_theta(self, theta);
        PolyModel::new(structure, p.a, p.b, p.c, p.d, p.f, ts)
    }
}

/// What the prediction-error iteration did.
#[derive(Debug, Clone, PartialEq)]
pub struct PemReport {
    /// The starting model of the last Levenberg–Marquardt run (ARX / IV / Hannan–Rissanen, the
    /// OE probe's model or subspace start, or the one given to [`refine`]).
    pub start: PolyModel,
    /// The Levenberg–Marquardt run (under [`Focus::Simulation`]: the fit of $G$).
    pub lm: LmReport,
    /// Under [`Focus::Simulation`] with noise polynomials: the second run that fits $C, D$.
    pub noise_lm: Option<LmReport>,
    /// Open-loop data only ([`PemOptions::with_open_loop`]): the largest root radius of the
    /// unstable least-squares/IV denominator whose roots were moved onto $|z| = 0.99$ for the
    /// start; `None` when the start needed no stabilisation.
    pub stabilised_start: Option<f64>,
    /// Problems of the returned model that did not stop the estimate (open-loop data): for
    /// example an optimum on the predictor's stability boundary.
    pub warnings: Vec<String>,
}

impl PemReport {
    /// Accepted Levenberg–Marquardt steps over all runs.
    pub fn iterations(&self) -> usize {
        self.lm.iterations + self.noise_lm.map_or(0, |r| r.iterations)
    }
    /// Why the (main) iteration stopped.
    pub fn reason(&self) -> StopReason {
        self.lm.reason
    }
}

/// ARMAX model $A y = B u + C e$ by the prediction-error method.
///
/// `na`, `nc`: free coefficients of $A$, $C$; `nb` coefficients of $B$ after `nk` delays;
/// `ts` the sample time of the returned model. $\theta = [a_1..a_{n_a}, b_0..b_{n_b-1}, c_1..c_{n_c}]$.
///
/// # Errors
/// See [`pem`].
///
/// # Example
/// ```
/// use ambid_core::estimate::pem::{armax, PemOptions};
/// use ambid_core::lti::PolyModel;
/// use rand::{RngExt, SeedableRng};
/// use rand_chacha::ChaCha8Rng;
/// use rand_distr::StandardNormal;
/// let truth = PolyModel::armax(vec![1.0, -1.5, 0.7], vec![0.0, 1.0, 0.5], vec![1.0, -0.5], 1.0).unwrap();
/// let mut rng = ChaCha8Rng::seed_from_u64(3);
/// let u: Vec<f64> = (0..2000).map(|_| rng.sample(StandardNormal)).collect();
/// let e: Vec<f64> = (0..2000).map(|_| 0.1 * rng.sample::<f64, _>(StandardNormal)).collect();
/// let y = truth.simulate(&u, Some(&e), None).unwrap();
/// let (fit, _) = armax(&y, &u, 2, 2, 1, 1, 1.0, &PemOptions::default()).unwrap();
/// let sd = fit.std().unwrap();
/// for (k, want) in [-1.5, 0.7, 1.0, 0.5, -0.5].into_iter().enumerate() {
///     assert!((fit.params[k] - want).abs() < 5.0 * sd[k]);
/// }
/// ```
#[allow(clippy::too_many_arguments)]
pub fn armax(
    y: &[f64],
    u: &[f64],
    na: usize,
    nb: usize,
    nc: usize,
    nk: usize,
    ts: f64,
    opts: &PemOptions,
) -> Result<(Fitted<PolyModel>, PemReport)> {
    pem(
        y,
        u,
        Structure::Armax,
        &Orders::armax(na, nb, nc, nk),
        ts,
        opts,
    )
}

/// Output-error model $y = (B/F) u + e$ by the prediction-error method.
///
/// $\theta = [b_0..b_{n_b-1}, f_1..f_{n_f}]$. The predictor needs a stable $F$: an unstable plant
/// gives [`Error::Unstable`] (see the module docs for the closed-loop route).
///
/// # Errors
/// See [`pem`].
///
/// # Example
/// ```
/// use ambid_core::estimate::pem::{oe, PemOptions};
/// use ambid_core::lti::PolyModel;
/// use rand::{RngExt, SeedableRng};
/// use rand_chacha::ChaCha8Rng;
/// use rand_distr::StandardNormal;
/// // a lightly damped mode, poles 0.98 e^{±0.3j}, with 10 % output noise
/// let truth = PolyModel::oe(vec![0.0, 0.1, 0.08], vec![1.0, -1.8724, 0.9604], 1.0).unwrap();
/// let mut rng = ChaCha8Rng::seed_from_u64(7);
/// let u: Vec<f64> = (0..2000).map(|_| rng.sample(StandardNormal)).collect();
/// let e: Vec<f64> = (0..2000).map(|_| 0.1 * rng.sample::<f64, _>(StandardNormal)).collect();
/// let y = truth.simulate(&u, Some(&e), None).unwrap();
/// let (fit, report) = oe(&y, &u, 2, 2, 1, 1.0, &PemOptions::default()).unwrap();
/// let sd = fit.std().unwrap();
/// for (k, want) in [0.1, 0.08, -1.8724, 0.9604].into_iter().enumerate() {
///     assert!((fit.params[k] - want).abs() < 5.0 * sd[k]);
/// }
/// assert!(report.reason().converged());
/// ```
pub fn oe(
    y: &[f64],
    u: &[f64],
    nb: usize,
    nf: usize,
    nk: usize,
    ts: f64,
    opts: &PemOptions,
) -> Result<(Fitted<PolyModel>, PemReport)> {
    pem(y, u, Structure::Oe, &Orders::oe(nb, nf, nk), ts, opts)
}

/// Box–Jenkins model $y = (B/F) u + (C/D) e$ by the prediction-error method.
///
/// $\theta = [b_0..b_{n_b-1}, c_1..c_{n_c}, d_1..d_{n_d}, f_1..f_{n_f}]$.
///
/// # Errors
/// See [`pem`].
///
/// # Example
/// ```
/// use ambid_core::estimate::pem::{bj, PemOptions};
/// use ambid_core::lti::PolyModel;
/// use rand::{RngExt, SeedableRng};
/// use rand_chacha::ChaCha8Rng;
/// use rand_distr::StandardNormal;
/// let truth = PolyModel::bj(vec![0.0, 0.4], vec![1.0, 0.5], vec![1.0, -0.8],
///                           vec![1.0, -0.7], 1.0).unwrap();
/// let mut rng = ChaCha8Rng::seed_from_u64(5);
/// let u: Vec<f64> = (0..2000).map(|_| rng.sample(StandardNormal)).collect();
/// let e: Vec<f64> = (0..2000).map(|_| 0.1 * rng.sample::<f64, _>(StandardNormal)).collect();
/// let y = truth.simulate(&u, Some(&e), None).unwrap();
/// let (fit, _) = bj(&y, &u, 1, 1, 1, 1, 1, 1.0, &PemOptions::default()).unwrap();
/// assert!((fit.model.f()[1] + 0.7).abs() < 0.02);
/// assert!((fit.model.d()[1] + 0.8).abs() < 0.1);
/// ```
#[allow(clippy::too_many_arguments)]
pub fn bj(
    y: &[f64],
    u: &[f64],
    nb: usize,
    nc: usize,
    nd: usize,
    nf: usize,
    nk: usize,
    ts: f64,
    opts: &PemOptions,
) -> Result<(Fitted<PolyModel>, PemReport)> {
    pem(
        y,
        u,
        Structure::Bj,
        &Orders::bj(nb, nc, nd, nf, nk),
        ts,
        opts,
    )
}

fn check_orders(structure: Structure, o: &Orders, focus: Focus) -> Result<()> {
    if o.nb == 0 {
        return Err(Error::invalid(
            "nb",
            "B needs at least one coefficient (nb ≥ 1); for a pure noise model use a time-series method",
        ));
    }
    let fixed: &[(&'static str, usize)] = match structure {
        Structure::Fir => &[("na", o.na), ("nc", o.nc), ("nd", o.nd), ("nf", o.nf)],
        Structure::Arx => &[("nc", o.nc), ("nd", o.nd), ("nf", o.nf)],
        Structure::Armax => &[("nd", o.nd), ("nf", o.nf)],
        Structure::Oe => &[("na", o.na), ("nc", o.nc), ("nd", o.nd)],
        Structure::Bj => &[("na", o.na)],
        Structure::General => &[],
        Structure::Ss => {
            return Err(Error::invalid(
                "structure",
                "the polynomial prediction-error method does not fit a state-space structure (`ss`); use estimate::ss_pem (or estimate::subspace) instead",
            ))
        }
    };
    for (name, v) in fixed {
        if *v != 0 {
            return Err(Error::invalid(
                name,
                format!(
                    "a {} model fixes this polynomial to 1, so its order must be 0 (got {v}); use Structure::General for a free one",
                    structure.name()
                ),
            ));
        }
    }
    if focus == Focus::Simulation && o.na > 0 && o.nf > 0 {
        return Err(Error::invalid(
            "focus",
            "the simulation criterion sees only the product A·F, so A and F cannot both be estimated; set na = 0 or nf = 0",
        ));
    }
    Ok(())
}

fn check_data(y: &[f64], u: &[f64], o: &Orders, ts: f64) -> Result<()> {
    if !(ts.is_finite() && ts > 0.0) {
        return Err(Error::invalid(
            "ts",
            format!("sample time must be positive and finite, got {ts}"),
        ));
    }
    if y.len() != u.len() {
        return Err(Error::DimensionMismatch {
            context: "pem: output y and input u",
            expected: format!("{} samples", y.len()),
            got: format!("{} samples", u.len()),
        });
    }
    check_finite("y", y)?;
    check_finite("u", u)?;
    let n = y.len();
    let d = o.n_params();
    let need = o.max_lag() + 2 * d + 1;
    if n < need {
        return Err(Error::invalid(
            "y",
            format!(
                "{n} samples cannot support {d} parameters with lags up to {}: at least {need} are needed; collect more data or lower the orders",
                o.max_lag()
            ),
        ));
    }
    let (lo, hi) = u
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    if hi - lo <= 0.0 {
        return Err(Error::invalid(
            "u",
            format!(
                "the input is constant ({lo}), so it does not excite the system; apply a persistently exciting input (PRBS, multisine or noise)"
            ),
        ));
    }
    Ok(())
}

/// The front door on an [`crate::data::IoData`]: [`pem`] of the output on the input channel
/// (roles) of a single-experiment SISO record.
///
/// # Errors
/// [`Error::InvalidArgument`] for several experiments (not joined yet), a record that is not
/// SISO (the message gives the role counts), a missing role or a non-finite sample; the errors
/// of [`pem`].
pub fn pem_iodata(
    data: &crate::data::IoData,
    structure: Structure,
    orders: &Orders,
    opts: &PemOptions,
) -> Result<(Fitted<PolyModel>, PemReport)> {
    let (y, u) = crate::data::iodata::siso_pair(data, "pem")?;
    pem(y, u, structure, orders, data.ts(), opts)
}

/// Prediction-error estimate of a polynomial model of the given structure and orders.
///
/// The general entry point behind [`armax`], [`oe`] and [`bj`]: also FIR, ARX (one
/// Gauss–Newton step from the least-squares start) and the general structure (start: see the
/// module docs; $A$ and $F$ are told apart only through the noise model, so local minima
/// with their roots swapped exist). Returns the model with sample time `ts`, its
/// parameters, covariance and losses ([`Fitted::loss`] is $\frac1N\sum\varepsilon_t^2$ of the
/// prediction errors of the returned model, [`Fitted::noise_variance`] $= \sum\varepsilon_t^2/(N-d)$)
/// and a [`PemReport`].
///
/// # Errors
/// * [`Error::DimensionMismatch`] if `y` and `u` differ in length; [`Error::NonFinite`] for a NaN
///   or infinite sample.
/// * [`Error::InvalidArgument`] for `nb = 0`, an order that the structure fixes to 0, too few
///   samples for the orders, a constant input, `ts` not positive, or both `na`, `nf` under
///   [`Focus::Simulation`].
/// * [`Error::Numerical`] if the start regression is rank deficient (an input that does not
///   excite all parameters) or the iteration fails numerically.
/// * [`Error::Unstable`] if the best model's predictor is unstable ($F$ of an OE/BJ model, $A F$
///   under the simulation focus, or $C$ with a zero on the unit circle); the message suggests
///   the closed-loop route.
///
/// # Example
/// ```
/// use ambid_core::estimate::pem::{pem, Orders, PemOptions};
/// use ambid_core::lti::{PolyModel, Structure};
/// use rand::{RngExt, SeedableRng};
/// use rand_chacha::ChaCha8Rng;
/// use rand_distr::StandardNormal;
/// let truth = PolyModel::arx(vec![1.0, -0.9], vec![0.0, 1.0], 1.0).unwrap();
/// let mut rng = ChaCha8Rng::seed_from_u64(2);
/// let u: Vec<f64> = (0..500).map(|_| rng.sample(StandardNormal)).collect();
/// let y = truth.simulate(&u, None, None).unwrap();
/// let o = Orders { na: 1, nb: 1, nk: 1, ..Orders::default() };
/// let (fit, _) = pem(&y, &u, Structure::Arx, &o, 1.0, &PemOptions::default()).unwrap();
/// assert!((fit.params[0] + 0.9).abs() < 1e-10 && (fit.params[1] - 1.0).abs() < 1e-10);
/// ```
pub fn pem(
    y: &[f64],
    u: &[f64],
    structure: Structure,
    orders: &Orders,
    ts: f64,
    opts: &PemOptions,
) -> Result<(Fitted<PolyModel>, PemReport)> {
    check_orders(structure, orders, opts.focus)?;
    check_data(y, u, orders, ts)?;
    // the two starts are independent jobs: computed side by side (same result on one thread)
    let (first, alt) = rayon::join(
        || init::start(y, u, orders, opts.focus, opts.open_loop),
        || match (structure, opts.focus) {
            (Structure::Oe, _) if orders.nf >= 2 => {
                init::subspace_oe_start(y, u, orders.nb, orders.nf, orders.nk, ts)
                    .and_then(|(b, f)| PolyModel::oe(b, f, ts).ok())
                    .map(|m| Polys::from_model(&m))
            }
            (Structure::Bj, Focus::Prediction) => {
                init::subspace_bj_start(y, u, orders, ts, &opts.lm)
            }
            (Structure::Armax, Focus::Prediction) => init::subspace_armax_start(y, u, orders, ts),
            _ => None,
        },
    );
    let (start, stabilised) = first?;
    let (fit, mut rep) = match alt {
        Some(alt) => with_second_start(y, u, structure, orders, ts, opts, start, alt)?,
        None => run(y, u, structure, orders, ts, opts, start, true)?,
    };
    if let Some(r) = stabilised {
        rep.stabilised_start = Some(r);
        rep.warnings.insert(
            0,
            format!(
                "the least-squares and IV starts had a pole outside the unit circle (largest |z| = {r:.6}); it was moved onto |z| = {} for the start only (open-loop data), then the iteration moved the poles freely",
                init::STABILISED_RADIUS
            ),
        );
    }
    Ok((fit, rep))
}

/// The iteration from the better of two starts: the least-squares / IV / Hannan–Rissanen start
/// and a state-space start (OE with $n_f \ge 2$: [`init::subspace_oe_start`]; BJ:
/// [`init::subspace_bj_start`]; ARMAX$(n, n, n, n_k)$: [`init::subspace_armax_start`]); the one
/// with the smaller loss of the criterion of the focus goes on with the whole iteration budget.
/// If its iteration fails (an error) the other start is tried. Lightly damped closed loops
/// sampled fast (an AMB loop at 20 kHz) make the polynomial iteration from the classical starts
/// crawl for tens to hundreds of iterations, while the state-space start is close to the
/// optimum.
#[allow(clippy::too_many_arguments)]
fn with_second_start(
    y: &[f64],
    u: &[f64],
    structure: Structure,
    o: &Orders,
    ts: f64,
    opts: &PemOptions,
    start: Polys,
    alt: Polys,
) -> Result<(Fitted<PolyModel>, PemReport)> {
    // ARMAX iterates C by variable projection, so its starts compete on the projected loss
    // (A, B re-estimated for each start's C); the plain loss when either cannot be projected
    let loss = |p: &Polys| {
        predictor::errors(p, y, u, opts.focus, Accuracy::Exact)
            .map_or(f64::INFINITY, |e| e.iter().map(|v| v * v).sum::<f64>())
    };
    let projected = |p: &Polys| {
        (structure == Structure::Armax)
            .then(|| varpro::projected_loss(y, u, o, p))
            .flatten()
    };
    let alt_first = match (projected(&alt), projected(&start)) {
        (Some(a), Some(s)) => a < s,
        _ => loss(&alt) < loss(&start),
    };
    let (first, second) = if alt_first {
        (alt, start)
    } else {
        (start, alt)
    };
    if structure != Structure::Oe && opts.lm.max_iterations() > 2 * PROBE_ITERATIONS {
        if let Some(r) = probe_both(y, u, structure, o, ts, opts, &first, &second) {
            return Ok(r);
        }
    }
    match run(y, u, structure, o, ts, opts, first, true) {
        Ok(r) => Ok(r),
        Err(e) => run(y, u, structure, o, ts, opts, second, true).map_err(|_| e),
    }
}

/// Iterations each start of ARMAX/BJ gets before the better one is chosen ([`probe_both`]).
const PROBE_ITERATIONS: usize = 5;

/// ARMAX and BJ: both starts iterate [`PROBE_ITERATIONS`] steps; the one with the smaller
/// loss then goes on with the rest of the budget (a probe that has already converged is
/// returned as it is). The initial loss alone picked the wrong start on 7 of 40 ARMAX/BJ fits of
/// random rigs 1–20: a start with the smaller loss from which the iteration crawls. `None` if
/// either probe fails (the caller falls back to the single-start rule).
#[allow(clippy::too_many_arguments)]
fn probe_both(
    y: &[f64],
    u: &[f64],
    structure: Structure,
    o: &Orders,
    ts: f64,
    opts: &PemOptions,
    first: &Polys,
    second: &Polys,
) -> Option<(Fitted<PolyModel>, PemReport)> {
    let probe_opts = opts.with_max_iterations(PROBE_ITERATIONS).ok()?;
    let (a, b) = rayon::join(
        || run(y, u, structure, o, ts, &probe_opts, first.clone(), false),
        || run(y, u, structure, o, ts, &probe_opts, second.clone(), false),
    );
    let (a, b) = (a.ok()?, b.ok()?);
    let ((fit, rep), other) = if b.0.loss < a.0.loss { (b, a) } else { (a, b) };
    let probe_cost = other.1.iterations();
    if rep.reason().converged() {
        // the probes skip the covariance (the loser's is never used): the winner's now
        let mut fit = fit;
        fit.covariance = prediction_covariance(&Polys::from_theta(o, &fit.params), o, y, u)
            .ok()?
            .1;
        let mut rep = rep;
        rep.lm.iterations += probe_cost;
        return Some((fit, rep));
    }
    let rest = opts
        .with_max_iterations(opts.lm.max_iterations() - 2 * PROBE_ITERATIONS)
        .ok()?;
    let (fit2, mut rep2) = run(
        y,
        u,
        structure,
        o,
        ts,
        &rest,
        Polys::from_model(&fit.model),
        true,
    )
    .ok()?;
    rep2.start = rep.start;
    rep2.lm.iterations += rep.lm.iterations + probe_cost;
    rep2.lm.initial_cost = rep.lm.initial_cost;
    rep2.warnings.splice(0..0, rep.warnings);
    Some((fit2, rep2))
}

/// Prediction-error refinement of a given model (for example from a subspace method or an
/// earlier fit): the same iteration as [`pem`], started from `start`, with its structure, its
/// orders ([`Orders::of`]) and its sample time.
///
/// # Errors
/// As [`pem`]; [`Error::Unstable`] if the start's predictor is unstable ($C$ or $F$, or $A F$
/// under the simulation focus).
///
/// # Example
/// ```
/// use ambid_core::estimate::pem::{refine, PemOptions};
/// use ambid_core::lti::PolyModel;
/// use rand::{RngExt, SeedableRng};
/// use rand_chacha::ChaCha8Rng;
/// use rand_distr::StandardNormal;
/// let truth = PolyModel::oe(vec![0.0, 1.0], vec![1.0, -0.9], 1.0).unwrap();
/// let mut rng = ChaCha8Rng::seed_from_u64(4);
/// let u: Vec<f64> = (0..500).map(|_| rng.sample(StandardNormal)).collect();
/// let y = truth.simulate(&u, None, None).unwrap();
/// let guess = PolyModel::oe(vec![0.0, 0.5], vec![1.0, -0.5], 1.0).unwrap();
/// let (fit, _) = refine(&y, &u, &guess, &PemOptions::default()).unwrap();
/// assert!((fit.model.f()[1] + 0.9).abs() < 1e-9);
/// ```
pub fn refine(
    y: &[f64],
    u: &[f64],
    start: &PolyModel,
    opts: &PemOptions,
) -> Result<(Fitted<PolyModel>, PemReport)> {
    let o = Orders::of(start);
    check_orders(start.structure(), &o, opts.focus)?;
    check_data(y, u, &o, start.ts())?;
    let p = Polys::from_model(start);
    run(y, u, start.structure(), &o, start.ts(), opts, p, true)
}

/// Prediction errors of `model` on the data and their analytic gradient
/// $\psi = \partial\varepsilon/\partial\theta$ ($N \times d$, columns in the order of $\theta$ for
/// `Orders::of(model)`), with zero initial conditions. Under [`Focus::Simulation`] the errors
/// are $y - B/(AF)\,u$ and the columns of $C, D$ are zero.
///
/// # Errors
/// [`Error::DimensionMismatch`] / [`Error::NonFinite`] for bad data; [`Error::Unstable`] if the
/// predictor is unstable ($C$ or $F$; $A$ or $F$ under the simulation focus).
///
/// # Example
/// ```
/// use ambid_core::estimate::pem::{prediction_errors, Focus};
/// use ambid_core::lti::PolyModel;
/// let m = PolyModel::oe(vec![0.0, 1.0], vec![1.0, -0.5], 1.0).unwrap();
/// let u = [1.0, 0.0, 0.0, 0.0];
/// let y = m.simulate(&u, None, None).unwrap();
/// let (e, psi) = prediction_errors(&m, &y, &u, Focus::Prediction).unwrap();
/// assert!(e.iter().all(|v| v.abs() < 1e-15));
/// // ∂ε/∂b0 = −u(t−1)/F: −[0, 1, 0.5, 0.25]
/// assert!((psi[(2, 0)] + 0.5).abs() < 1e-15);
/// ```
pub fn prediction_errors(
    model: &PolyModel,
    y: &[f64],
    u: &[f64],
    focus: Focus,
) -> Result<(Vec<f64>, Mat<f64>)> {
    if y.len() != u.len() {
        return Err(Error::DimensionMismatch {
            context: "prediction_errors: output y and input u",
            expected: format!("{} samples", y.len()),
            got: format!("{} samples", u.len()),
        });
    }
    check_finite("y", y)?;
    check_finite("u", u)?;
    let o = Orders::of(model);
    let p = Polys::from_model(model);
    errors_and_gradient(&p, &o, y, u, focus).ok_or_else(|| Error::Unstable {
        context: "prediction_errors",
        reason: format!(
            "the predictor is unstable or overflows (largest |root| of C: {:.6}, of F: {:.6}, of A: {:.6}); the {} focus needs stable {}",
            max_root(&p.c),
            max_root(&p.f),
            max_root(&p.a),
            if focus == Focus::Prediction { "prediction" } else { "simulation" },
            if focus == Focus::Prediction { "C and F" } else { "A and F" },
        ),
    })
}

/// Moves every root of the monic polynomial `p` (ascending powers of $q^{-1}$) that lies beyond
/// $|z| = 0.99$ radially onto $|z| = 0.99$, keeping its angle; the other roots stay. Meant for
/// *starting values* on open-loop data ([`PemOptions::with_open_loop`]), never for an estimate.
/// `None` if the roots cannot be computed.
///
/// # Example
/// ```
/// use ambid_core::estimate::pem::stabilise_start_polynomial;
/// // (1 − 1.01 q⁻¹)(1 − 0.5 q⁻¹): the root at 1.01 moves to 0.99, the one at 0.5 stays
/// let p = stabilise_start_polynomial(&[1.0, -1.51, 0.505]).unwrap();
/// assert!((p[1] + 1.49).abs() < 1e-12 && (p[2] - 0.495).abs() < 1e-12);
/// ```
pub fn stabilise_start_polynomial(p: &[f64]) -> Option<Vec<f64>> {
    init::stabilise(p)
}

/// Whether every root of the monic polynomial `p` (ascending powers of $q^{-1}$) lies strictly
/// inside the unit circle (Schur–Cohn test).
pub(crate) fn denominator_is_stable(p: &[f64]) -> bool {
    predictor::is_stable(p)
}

/// The criterion restricted to the free parameters `free` of $\theta$.
struct Criterion<'a> {
    y: &'a [f64],
    u: &'a [f64],
    o: Orders,
    focus: Focus,
    theta: Vec<f64>,
    free: Vec<usize>,
    accuracy: Accuracy,
}

impl Criterion<'_> {
    fn polys(&self, x: &[f64]) -> Polys {
        let mut th = self.theta.clone();
        for (k, &i) in self.free.iter().enumerate() {
            th[i] = x[k];
        }
        Polys::from_theta(&self.o, &th)
    }
    fn full(&self, x: &[f64]) -> Vec<f64> {
        let mut th = self.theta.clone();
        for (k, &i) in self.free.iter().enumerate() {
            th[i] = x[k];
        }
        th
    }
}

impl LeastSquaresProblem for Criterion<'_> {
    fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
        errors(&self.polys(x), self.y, self.u, self.focus, self.accuracy)
    }
    fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
        let j = predictor::gradient(&self.polys(x), &self.o, self.y, self.u, self.focus)?;
        if self.free.len() == j.ncols() && self.free.iter().enumerate().all(|(k, &i)| k == i) {
            return Some(j);
        }
        Some(Mat::from_fn(j.nrows(), self.free.len(), |t, k| {
            j[(t, self.free[k])]
        }))
    }
}

/// How accurately the iteration's trial residuals are computed (module docs, "Stopping"): with
/// the statistical rule on, plain double precision whenever its rounding-error bound is below
/// $10^{-3}\kappa^2/(N-d)$ of $\lVert w\rVert$ (so the loss is known to far better than the
/// smallest reduction the rule still acts on); otherwise (exact-optimum mode, $\kappa = 0$)
/// always double-double.
fn residual_accuracy(lm: &LmOptions, n: usize, d: usize) -> Accuracy {
    let kappa = lm.significance_tol();
    if kappa > 0.0 && n > d {
        Accuracy::RelativeBound(1e-3 * kappa * kappa / (n - d) as f64)
    } else {
        Accuracy::Exact
    }
}

/// Index ranges of the polynomial blocks in $\theta$.
fn blocks(o: &Orders) -> [std::ops::Range<usize>; 5] {
    let ia = o.na;
    let ib = ia + o.nb;
    let ic = ib + o.nc;
    let id = ic + o.nd;
    [0..ia, ia..ib, ib..ic, ic..id, id..id + o.nf]
}

/// $(J^\top J)^{-1}$ over the columns `cols` of `j`, with column equilibration; `None` if the
/// equilibrated matrix is numerically rank deficient.
fn inverse_gram(j: &Mat<f64>, cols: &[usize]) -> Option<Mat<f64>> {
    let d = cols.len();
    let n = j.nrows();
    let s: Vec<f64> = cols
        .iter()
        .map(|&c| (0..n).map(|t| j[(t, c)].powi(2)).sum::<f64>().sqrt())
        .collect();
    if s.iter().any(|v| !(*v > 0.0 && v.is_finite())) {
        return None;
    }
    let js = Mat::from_fn(n, d, |t, k| j[(t, cols[k])] / s[k]);
    let sv = crate::linalg::singular_values(js.as_ref()).ok()?;
    let (smax, smin) = (*sv.first()?, *sv.last()?);
    if smin <= smax * 1e-10 {
        return None;
    }
    let g = js.transpose() * &js;
    let inv = crate::linalg::solve(g.as_ref(), Mat::<f64>::identity(d, d).as_ref()).ok()?;
    Some(Mat::from_fn(d, d, |a, b| {
        0.5 * (inv[(a, b)] + inv[(b, a)]) / (s[a] * s[b])
    }))
}

/// The advice at the end of an "unstable system" message: the closed-loop route for
/// closed-loop data (the default), the integrator / ARX route for data declared open-loop.
pub(crate) fn unstable_advice(open_loop: bool) -> &'static str {
    if open_loop {
        "On open-loop data this usually means an integrator or a pole on the unit circle: fit ARX/ARMAX (prediction focus), or a model of the differenced output; if the data were in fact measured in closed loop around an unstable plant, declare them so (--loop closed) and identify the stable closed-loop map T_ry from the excitation r"
    } else {
        "Identify the stable closed-loop map T_ry from the excitation r (then P = T_ry / (1 - C T_ry)), or fit ARX/ARMAX with the prediction focus, whose predictor stays stable for an unstable A"
    }
}

fn boundary_error(p: &Polys, focus: Focus, context: &'static str, open_loop: bool) -> Error {
    let rc = max_root(&p.c);
    let rf = max_root(&p.f);
    let ra = max_root(&p.a);
    let (den_name, rden) = match focus {
        Focus::Prediction => ("F", rf),
        Focus::Simulation => ("A·F", ra.max(rf)),
    };
    if focus == Focus::Prediction && rc >= rden {
        Error::Unstable {
            context,
            reason: format!(
                "the best fit pushes a zero of the noise polynomial C onto the unit circle (largest |z| = {rc:.6}), where the predictor (D/C)(A y - (B/F) u) becomes unstable: the noise spectrum seems to vanish at some frequency (filtered or over-differenced data). Lower nc, or fit an OE model"
            ),
        }
    } else {
        Error::Unstable {
            context,
            reason: format!(
                "the best fit pushes a pole of {den_name} onto the unit circle (largest |z| = {rden:.6}) and the output-error predictor needs it stable: the system from u to y looks unstable, which an OE/BJ model (or the simulation focus) cannot describe. {}",
                unstable_advice(open_loop)
            ),
        }
    }
}

fn start_error(p: &Polys, focus: Focus) -> Error {
    let rc = max_root(&p.c);
    let (name, r) = match focus {
        Focus::Prediction => ("F", max_root(&p.f)),
        Focus::Simulation => ("A·F", max_root(&mul(&p.a, &p.f))),
    };
    if r >= 1.0 {
        Error::Unstable {
            context: "pem start",
            reason: format!(
                "the starting model's {name} has a pole on or outside the unit circle (largest |z| = {r:.6}), so its output-error predictor is unstable; an OE/BJ model (or the simulation focus) cannot describe an unstable system. Identify the stable closed-loop map T_ry from the excitation r (then P = T_ry / (1 - C T_ry)), or fit ARX/ARMAX with the prediction focus"
            ),
        }
    } else {
        Error::Unstable {
            context: "pem start",
            reason: format!(
                "the starting C has a zero on or outside the unit circle (largest |z| = {rc:.6}), so the predictor (D/C)(A y - (B/F) u) is unstable; start from a minimum-phase C"
            ),
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn run(
    y: &[f64],
    u: &[f64],
    structure: Structure,
    o: &Orders,
    ts: f64,
    opts: &PemOptions,
    start: Polys,
    with_covariance: bool,
) -> Result<(Fitted<PolyModel>, PemReport)> {
    const CTX: &str = "pem";
    let focus = opts.focus;
    let n = y.len();
    let mut warnings = Vec::new();
    let mut start = start;
    if !predictor::predictor_stable(&start, focus) && opts.open_loop {
        // open-loop data: stabilise the start only (module docs), then iterate freely
        let r = max_root(&start.f).max(max_root(&start.a));
        if let Some(f) = init::stabilise(&start.f) {
            start.f = f;
        }
        if focus == Focus::Simulation {
            if let Some(a) = init::stabilise(&start.a) {
                start.a = a;
            }
        }
        if predictor::predictor_stable(&start, focus) {
            warnings.push(format!(
                "the starting model had a pole outside the unit circle (largest |z| = {r:.6}); it was moved onto |z| = {} for the start only (open-loop data)",
                init::STABILISED_RADIUS
            ));
        }
    }
    if !predictor::predictor_stable(&start, focus) {
        return Err(start_error(&start, focus));
    }
    let theta0 = start.theta(o);
    let start_model = PolyModel::new(
        structure,
        start.a.clone(),
        start.b.clone(),
        start.c.clone(),
        start.d.clone(),
        start.f.clone(),
        ts,
    )?;
    let [ra, rb, rc, rd, rf] = blocks(o);
    let accuracy = residual_accuracy(&opts.lm, n, o.n_params());
    let (theta, lm_main, noise_lm, cov) = match focus {
        Focus::Prediction => {
            // ARMAX, BJ: variable projection first (module varpro), then the joint iteration
            let projected = match structure {
                Structure::Armax => varpro::armax(y, u, o, &start, &opts.lm),
                Structure::Bj => varpro::bj(y, u, o, &start, &opts.lm),
                _ => None,
            };
            let (theta1, lm_opts, pre) = match projected {
                Some((p, rep)) => {
                    let rest = opts
                        .lm
                        .max_iterations()
                        .saturating_sub(rep.iterations)
                        .max(1);
                    (p.theta(o), opts.lm.with_max_iterations(rest)?, Some(rep))
                }
                None => (theta0.clone(), opts.lm, None),
            };
            let free: Vec<usize> = (0..o.n_params()).collect();
            let mut crit = Criterion {
                y,
                u,
                o: *o,
                focus,
                theta: theta1.clone(),
                free,
                accuracy,
            };
            let (x, mut rep) = lm::minimize(&mut crit, &theta1, &lm_opts)?;
            if let Some(pre) = pre {
                rep.iterations += pre.iterations;
                rep.evaluations += pre.evaluations;
                rep.initial_cost = pre.initial_cost;
            }
            let th = crit.full(&x);
            if rep.ended_on_boundary {
                let e = boundary_error(&Polys::from_theta(o, &th), focus, CTX, opts.open_loop);
                if !opts.open_loop {
                    return Err(e);
                }
                warnings.push(e.to_string());
            }
            (th, rep, None, None)
        }
        Focus::Simulation => {
            let g_free: Vec<usize> = ra.clone().chain(rb.clone()).chain(rf.clone()).collect();
            let mut crit = Criterion {
                y,
                u,
                o: *o,
                focus: Focus::Simulation,
                theta: theta0.clone(),
                free: g_free.clone(),
                accuracy,
            };
            let x0: Vec<f64> = g_free.iter().map(|&i| theta0[i]).collect();
            let (x, rep) = lm::minimize(&mut crit, &x0, &opts.lm)?;
            let mut th = crit.full(&x);
            if rep.ended_on_boundary {
                let e = boundary_error(&Polys::from_theta(o, &th), focus, CTX, opts.open_loop);
                if !opts.open_loop {
                    return Err(e);
                }
                warnings.push(e.to_string());
            }
            // the G block of the covariance is formed after the noise model is known
            let (_, psi) =
                errors_and_gradient(&Polys::from_theta(o, &th), o, y, u, Focus::Simulation)
                    .ok_or_else(|| {
                        Error::numerical(CTX, "the simulation gradient overflowed at the estimate")
                    })?;
            let h_free: Vec<usize> = rc.clone().chain(rd.clone()).collect();
            let mut noise_rep = None;
            if !h_free.is_empty() {
                let p = Polys::from_theta(o, &th);
                let ay = filter(&p.a, &[1.0], y);
                let v = filter(&p.b, &p.f, u);
                let w: Vec<f64> = ay.iter().zip(&v).map(|(a, b)| a - b).collect();
                let (c, d) = init::arma_start(&w, o.nc, o.nd, init::noise_order(n, o));
                th[rc.clone()].copy_from_slice(&c[1..]);
                th[rd.clone()].copy_from_slice(&d[1..]);
                let mut crit = Criterion {
                    y,
                    u,
                    o: *o,
                    focus: Focus::Prediction,
                    theta: th.clone(),
                    free: h_free.clone(),
                    accuracy,
                };
                let x0: Vec<f64> = h_free.iter().map(|&i| th[i]).collect();
                let (x, rep2) = lm::minimize(&mut crit, &x0, &opts.lm)?;
                th = crit.full(&x);
                if rep2.ended_on_boundary {
                    let e = boundary_error(
                        &Polys::from_theta(o, &th),
                        Focus::Prediction,
                        CTX,
                        opts.open_loop,
                    );
                    if !opts.open_loop {
                        return Err(e);
                    }
                    warnings.push(e.to_string());
                }
                noise_rep = Some(rep2);
            }
            (th, rep, noise_rep, Some((psi, g_free, h_free)))
        }
    };
    let p = Polys::from_theta(o, &theta);
    let d = o.n_params();
    let (sse, covariance) = match cov {
        None if with_covariance => prediction_covariance(&p, o, y, u)?,
        None => {
            // the errors alone, the same values as those of the covariance's pass
            let eps = errors(&p, y, u, Focus::Prediction, Accuracy::Exact)
                .ok_or_else(|| Error::numerical(CTX, OVERFLOW_AT_ESTIMATE))?;
            (eps.iter().map(|e| e * e).sum(), None)
        }
        Some((psi, g_free, h_free)) => {
            let (sse, lambda, jac) = at_estimate(&p, o, y, u)?;
            let cov = sim_covariance(&p, &psi, &jac, &g_free, &h_free, lambda, d);
            (sse, cov)
        }
    };
    let lambda = sse / (n - d) as f64;
    let model = PolyModel::new(structure, p.a, p.b, p.c, p.d, p.f, ts)?;
    Ok((
        Fitted {
            model,
            params: theta,
            covariance,
            loss: sse / n as f64,
            noise_variance: lambda,
            n_samples: n,
        },
        PemReport {
            start: start_model,
            lm: lm_main,
            noise_lm,
            stabilised_start: None,
            warnings,
        },
    ))
}

const OVERFLOW_AT_ESTIMATE: &str =
    "the prediction errors overflow at the estimate; check the data scaling";

/// The sum of squared prediction errors at `p` and the covariance
/// $\hat\lambda\,(\Psi^\top\Psi)^{-1}$ of the prediction-focus estimate ($\Psi$ the gradient of the
/// errors, $\hat\lambda = \sum\varepsilon^2 / (N - d)$); `None` for a singular $\Psi^\top\Psi$.
fn prediction_covariance(
    p: &Polys,
    o: &Orders,
    y: &[f64],
    u: &[f64],
) -> Result<(f64, Option<Mat<f64>>)> {
    let (sse, lambda, jac) = at_estimate(p, o, y, u)?;
    let d = o.n_params();
    let cov = inverse_gram(&jac, &(0..d).collect::<Vec<_>>())
        .map(|m| Mat::from_fn(d, d, |i, j| lambda * m[(i, j)]));
    Ok((sse, cov))
}

/// The sum of squared prediction errors at `p`, $\hat\lambda = \sum\varepsilon^2 / (N - d)$
/// and the gradient $\Psi$ of the errors (prediction focus), for the covariances.
fn at_estimate(p: &Polys, o: &Orders, y: &[f64], u: &[f64]) -> Result<(f64, f64, Mat<f64>)> {
    let (eps, jac) = errors_and_gradient(p, o, y, u, Focus::Prediction)
        .ok_or_else(|| Error::numerical("pem", OVERFLOW_AT_ESTIMATE))?;
    let sse: f64 = eps.iter().map(|e| e * e).sum();
    Ok((sse, sse / (y.len() - o.n_params()) as f64, jac))
}

/// Covariance of the two-stage estimate under the simulation focus (see the module docs): the
/// sandwich $\hat\lambda M^{-1} X^\top X M^{-\top}$ of the stacked estimating equations.
fn sim_covariance(
    p: &Polys,
    psi: &Mat<f64>,
    jac: &Mat<f64>,
    g_free: &[usize],
    h_free: &[usize],
    lambda: f64,
    d: usize,
) -> Option<Mat<f64>> {
    let n = psi.nrows();
    let (dg, dh) = (g_free.len(), h_free.len());
    let k = dg + dh;
    // X = [Φ, J_H] with Φ = Hᵀ Ψ_G: anticausal filtering by H = C/(A D)
    let ad = mul(&p.a, &p.d);
    let mut x = Mat::<f64>::zeros(n, k);
    for (c, &i) in g_free.iter().enumerate() {
        let rev: Vec<f64> = (0..n).rev().map(|t| psi[(t, i)]).collect();
        let f = filter(&p.c, &ad, &rev);
        for t in 0..n {
            x[(t, c)] = f[n - 1 - t];
        }
    }
    for (c, &i) in h_free.iter().enumerate() {
        for t in 0..n {
            x[(t, dg + c)] = jac[(t, i)];
        }
    }
    // column scales from the Jacobians that define M
    let col = |m: &Mat<f64>, i: usize| (0..n).map(|t| m[(t, i)].powi(2)).sum::<f64>().sqrt();
    let s: Vec<f64> = g_free
        .iter()
        .map(|&i| col(psi, i))
        .chain(h_free.iter().map(|&i| col(jac, i)))
        .collect();
    if s.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return None;
    }
    // M = [[Ψ_Gᵀ Ψ_G, 0], [J_Hᵀ J_G, J_Hᵀ J_H]], scaled: D⁻¹ M D⁻¹
    let left = |r: usize, t: usize| {
        if r < dg {
            psi[(t, g_free[r])]
        } else {
            jac[(t, h_free[r - dg])]
        }
    };
    let right = |c: usize, t: usize, r: usize| {
        if r < dg {
            psi[(t, g_free[c])]
        } else if c < dg {
            jac[(t, g_free[c])]
        } else {
            jac[(t, h_free[c - dg])]
        }
    };
    let m = Mat::from_fn(k, k, |r, c| {
        if r < dg && c >= dg {
            0.0
        } else {
            (0..n).map(|t| left(r, t) * right(c, t, r)).sum::<f64>() / (s[r] * s[c])
        }
    });
    let xt = Mat::from_fn(k, n, |r, t| x[(t, r)] / s[r]);
    let sv = crate::linalg::singular_values(m.as_ref()).ok()?;
    if *sv.last()? <= sv[0] * 1e-12 {
        return None;
    }
    let b = crate::linalg::solve(m.as_ref(), xt.as_ref()).ok()?; // M̃⁻¹ X̃ᵀ
    let pk = &b * b.transpose();
    let order: Vec<usize> = g_free.iter().chain(h_free).copied().collect();
    let mut out = Mat::<f64>::zeros(d, d);
    for (a, &i) in order.iter().enumerate() {
        for (c, &j) in order.iter().enumerate() {
            out[(i, j)] = lambda * 0.5 * (pk[(a, c)] + pk[(c, a)]) / (s[a] * s[c]);
        }
    }
    (0..d).all(|i| out[(i, i)].is_finite()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn theta_round_trip() {
        let o = Orders {
            na: 2,
            nb: 2,
            nc: 1,
            nd: 1,
            nf: 2,
            nk: 3,
        };
        let th: Vec<f64> = (1..=o.n_params()).map(|k| k as f64 * 0.25).collect();
        let m = o.model(Structure::General, &th, 1.0).unwrap();
        assert_eq!(m.b(), &[0.0, 0.0, 0.0, 0.75, 1.0]);
        assert_eq!(Orders::of(&m), o);
        assert_eq!(o.params(&m).unwrap(), th);
        assert_eq!(o.max_lag(), 4);
    }

    /// A fit that converges within the start probes (which skip the covariance) still carries
    /// the covariance of its estimate: the reported standard errors of ARMAX(1,1,1,1) match the
    /// spread of the estimates over 40 noise realisations (the independent truth) to within the
    /// sampling error of 40 draws.
    #[test]
    fn a_fit_converged_in_the_probes_reports_a_calibrated_covariance() {
        use rand::{RngExt, SeedableRng};
        use rand_chacha::ChaCha8Rng;
        use rand_distr::StandardNormal;
        let (n, runs) = (3000, 40);
        let truth = PolyModel::new(
            Structure::Armax,
            vec![1.0, -0.7],
            vec![0.0, 1.0],
            vec![1.0, 0.5],
            vec![1.0],
            vec![1.0],
            1.0,
        )
        .unwrap();
        let o = Orders::armax(1, 1, 1, 1);
        let mut est: Vec<Vec<f64>> = Vec::new();
        let mut reported: Vec<Vec<f64>> = Vec::new();
        for seed in 0..runs {
            let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
            let u: Vec<f64> = (0..n).map(|_| rng.sample(StandardNormal)).collect();
            let e: Vec<f64> = (0..n)
                .map(|_| 0.5 * rng.sample::<f64, _>(StandardNormal))
                .collect();
            let y = truth.simulate(&u, Some(&e), None).unwrap();
            let (fit, rep) =
                pem(&y, &u, Structure::Armax, &o, 1.0, &PemOptions::default()).unwrap();
            assert!(
                rep.reason().converged() && rep.iterations() < 2 * PROBE_ITERATIONS,
                "{rep:?}"
            );
            let cov = fit.covariance.as_ref().expect("a covariance");
            reported.push((0..3).map(|k| cov[(k, k)].sqrt()).collect());
            est.push(fit.params.clone());
        }
        for k in 0..3 {
            let mean = est.iter().map(|p| p[k]).sum::<f64>() / runs as f64;
            let sd =
                (est.iter().map(|p| (p[k] - mean).powi(2)).sum::<f64>() / (runs - 1) as f64).sqrt();
            let rep = reported.iter().map(|s| s[k]).sum::<f64>() / runs as f64;
            // the sample SD of 40 draws is within ±35 % of the true SD with > 99 % probability
            assert!(
                (sd / rep - 1.0).abs() < 0.35,
                "parameter {k}: spread {sd}, reported {rep}"
            );
        }
    }

    /// The parallel parts (the two starts, the two probes, the parts of the QR of the Jacobian,
    /// the N4SID horizons) are cut by the data, never by the number of threads: an ARMAX and a
    /// BJ estimate are bit for bit the same on 1 and on 3 threads.
    #[test]
    fn estimates_do_not_depend_on_the_number_of_threads() {
        use rand::{RngExt, SeedableRng};
        use rand_chacha::ChaCha8Rng;
        use rand_distr::StandardNormal;
        let n = 40_000; // two parts of the Jacobian's QR
        let mut rng = ChaCha8Rng::seed_from_u64(23);
        let u: Vec<f64> = (0..n).map(|_| rng.sample(StandardNormal)).collect();
        let e: Vec<f64> = (0..n)
            .map(|_| 0.1 * rng.sample::<f64, _>(StandardNormal))
            .collect();
        let g = PolyModel::oe(vec![0.0, 0.5, 0.3], vec![1.0, -1.5, 0.7], 1.0).unwrap();
        let h = PolyModel::oe(vec![1.0, 0.4], vec![1.0, -0.8], 1.0).unwrap();
        let yg = g.simulate(&u, None, None).unwrap();
        let yh = h.simulate(&e, None, None).unwrap();
        let y: Vec<f64> = yg.iter().zip(&yh).map(|(a, b)| a + b).collect();
        let fits = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let o_bj = Orders::bj(2, 1, 1, 2, 1);
                let o_ax = Orders::armax(2, 2, 2, 1);
                let opts = PemOptions::default();
                let bj = pem(&y, &u, Structure::Bj, &o_bj, 1.0, &opts).unwrap().0;
                let ax = pem(&y, &u, Structure::Armax, &o_ax, 1.0, &opts).unwrap().0;
                [bj.params, ax.params]
            })
        };
        let bits =
            |v: &[Vec<f64>; 2]| -> Vec<u64> { v.iter().flatten().map(|x| x.to_bits()).collect() };
        let (one, three) = (fits(1), fits(3));
        assert_eq!(bits(&one), bits(&three));
        // and they are estimates of the system, not a degenerate constant
        // θ_BJ = [b1, b2, c1, d1, f1, f2]
        let truth = [0.5, 0.3, 0.4, -0.8, -1.5, 0.7];
        for (est, tru) in one[0].iter().zip(truth) {
            assert!((est - tru).abs() < 0.03, "{:?}", one[0]);
        }
    }
}
