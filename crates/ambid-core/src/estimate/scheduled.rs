//! Speed-scheduled state-space models: one plant model for every speed between the measured
//! ones, built from per-speed models and their frequency-response data.
//!
//! # Model
//! $$ x_{k+1} = A(\Omega)\, x_k + B u_k, \qquad y_k = C x_k + D u_k, \qquad
//! A(\Omega) = \sum_{p=0}^{d} A_p\, \xi^p, \quad \xi = \frac{\Omega - \Omega_c}{\Omega_h}, $$
//! with the speed $\Omega$ in rpm, $\Omega_c$ the centre and $\Omega_h$ the half width of the
//! measured range (so $\xi \in [-1, 1]$, which keeps the polynomial well conditioned). Only $A$
//! depends on the speed: the magnets, amplifiers and sensors (in $B$, $C$, $D$) do not; the
//! gyroscopic coupling of a spinning rotor is a term of $A$ that is linear in $\Omega$ in
//! continuous time and nearly so after a zero-order-hold discretisation (the quadratic and higher
//! terms of $e^{(A_0 + \Omega A_1) T}$ are of relative size $(\Omega T \lVert A_1\rVert)^2$,
//! below $10^{-5}$ for an AMB rotor at 20 kHz). The degree $d$ is 2 by default (at most the number
//! of speeds minus one); the $A_p$ are fitted entrywise by least squares over the speeds.
//!
//! # The common basis
//! The per-speed models come in unrelated state bases. One speed is the **reference** (the one
//! nearest the middle of the range, the lower one on a tie). Its model is brought to its
//! **band-balanced** realisation, and the $(B, C, D)$ of that realisation become the common ones;
//! every speed is then described by an $A_s$ with $C (zI - A_s)^{-1} B + D$ equal to its plant.
//!
//! *Why balance.* A plant assembled from physical units (m, m/s, A, with gains of $10^3$ next
//! to $10^{-13}$), or such a plant in an arbitrary basis, makes every step below badly
//! conditioned: on the 4-axis twin the gauge tangent below has a condition number of
//! $10^{11}$–$10^{12}$ in the physical or a random basis, $6 \cdot 10^{-6}$ after diagonal
//! (Parlett–Reinsch) balancing and $0.026$ after band balancing. The band gramians exist for an
//! unstable plant because they are sums over the data's lines, not integrals over the whole
//! circle:
//! $$ W_c = \operatorname{Re} \sum_k H_k H_k^{\mathsf H}, \quad W_o = \operatorname{Re} \sum_k
//! F_k^{\mathsf H} F_k, \qquad H_k = (z_k I - A)^{-1} B, \quad F_k = C (z_k I - A)^{-1}, $$
//! each regularised by $\varepsilon\,\operatorname{tr}(W)/n \cdot I$ with $\varepsilon = 10^{-12}$
//! (the twin's plant has states that the 10–1000 Hz band sees $10^{-10}$ times less than others,
//! and a random basis of it carries rounding at that level). By the square-root method,
//! $W_c = R_c^\top R_c$, $W_o = R_o^\top R_o$ from QR factorisations of the stacked real and
//! imaginary parts, $R_o R_c^\top = U \Sigma V^\top$, and the realisation
//! $(T^{-1} A T, T^{-1} B, C T)$ with $T = R_c^\top V \Sigma^{-1/2}$,
//! $T^{-1} = \Sigma^{-1/2} U^\top R_o$ has $T^{-1} W_c T^{-\top} = T^\top W_o T = \Sigma$. It does
//! not depend on the basis the model came in (up to the signs of the states).
//!
//! # The gauge
//! Fixing $B$ and $C$ does **not** fix the basis when the order $n$ exceeds the number of inputs
//! $m$ or outputs $p$: every $T = I + E$ with $E B = 0$ and $C E = 0$ keeps $B$ and $C$ and maps a
//! solution $A_s$ to another one, $T^{-1} A_s T$. These $E = N_C X N_B^\top$ ($N_C$ a basis of the
//! null space of $C$, $N_B$ of that of $B^\top$, $X$ free) form an
//! $r = (n - \operatorname{rank} C)(n - \operatorname{rank} B)$ dimensional family: for the 4-axis
//! AMB plant ($n = 24$, $m = p = 4$) $r = 400$ of the $n^2 = 576$ entries of $A$ are not
//! determined by the plant. For a controllable model the family acts freely (if $[A, E] = 0$ and
//! $EB = 0$ then $E A^k B = A^k E B = 0$ for all $k$, so $E = 0$), so $A_s$ is determined up to
//! these $r$ directions and no further, and entrywise interpolation of the $A_s$ is only
//! meaningful once every speed is put into the *same* member of its family: a **gauge** has to be
//! chosen.
//!
//! The gauge is a linear **slice** through the reference: the tangent of the family at the
//! reference's $A_\mathrm{ref}$ is the range of
//! $$ M(A) = N_B \otimes (A N_C) - (A^\top N_B) \otimes N_C \in \mathbb R^{n^2 \times r},
//! \qquad \operatorname{vec}\,[A, N_C X N_B^\top] = M(A) \operatorname{vec} X, $$
//! and a QR factorisation with column pivoting of $M(A_\mathrm{ref})^\top$ picks the $r$ entries of
//! $A$ on which the family acts most independently (the pivots). Those $r$ entries are held at
//! their reference values for every speed; the other $q = n^2 - r$ entries $\theta$ are the free
//! parameters. Every speed's $A_s$ lies in this one affine subspace, which crosses each family
//! transversally near $A_\mathrm{ref}$, so $A_s$ is unique there and a smooth (analytic) function of
//! the speed: its entries can be interpolated. (With $n \le \max(m, p)$ there is no gauge, $r = 0$
//! and all of $A$ is free.) A slice of *entries* rather than the orthogonal complement of the
//! tangent keeps the Jacobian below sparse: one product $F_{:,a} H_{b,:}$ per free entry.
//!
//! # Algorithm
//! For every speed $s$, the reference first:
//! 1. **Similarity start.** The speed's own model is band-balanced on its own lines, then the
//!    map $T$ from the reference basis into that basis
//!    ($\hat A_s T \approx T A_\mathrm{ref}$, $T B = \hat B_s$, $\hat C_s T = C$) follows from two
//!    nested least-squares problems: first the $B$, $C$ conditions,
//!    $T_0 = \hat B_s B^+ + \hat C_s^+ C - \hat C_s^+ \hat C_s \hat B_s B^+$ (exact when
//!    $\hat C_s \hat B_s = C B$), then, over their null space $T = T_0 + N_{\hat C} X N_B^\top$,
//!    $\min_X \lVert \hat A_s T - T A_\mathrm{ref} \rVert_F$; then $A_s = T^{-1} \hat A_s T$ with
//!    $(B, C, D)$ replaced by the reference's. For exact models of one family this is exact.
//! 2. **Into the slice.** Newton's method on the $r$ slice conditions over the gauge
//!    $T = I + N_C X N_B^\top$ (a square $r \times r$ system with the rows of $M(A)$ of the held
//!    entries, with step halving), $A_s \leftarrow T^{-1} A_s T$ after each step; this keeps the
//!    transfer function exactly. If the similarity or the Newton iteration fails, or its model
//!    fits the data worse than the (refined) $A_\mathrm{ref}$, $A_\mathrm{ref}$ is the start.
//! 3. **Refinement** of the $q$ free entries by Levenberg–Marquardt ([`minimize`]) on the weighted
//!    complex error of that speed's data,
//!    $$ V_s(\theta) = \sum_{k} \sum_{i,j} w_{kij}\,\bigl| \hat G_{ij}(z_k) - G_{ij,k} \bigr|^2
//!    \;+\; \mu \lVert \theta - \theta_0 \rVert^2,
//!    \qquad \hat G(z) = C (zI - A)^{-1} B + D, \quad z_k = e^{j 2\pi f_k T}, $$
//!    with $w_{kij} = 1/\sigma^2_{kij}$ when the data carry variances and otherwise
//!    $w_{kij} = n_y n_u / \lVert G_k \rVert_F^2$ (every line counts by its *relative* error,
//!    which is the plant bar's measure; a per-entry scaling would give infinite weight to the
//!    x–y cross terms of a rotor at standstill, which are zero). The small **ridge** toward the
//!    start $\theta_0$, $\sqrt\mu = 10^{-4} \max_j \lVert J_{:,j} \rVert$ (the largest column
//!    norm of the data's Jacobian at the start), holds the directions that the band barely sees:
//!    without it, Levenberg–Marquardt moved the entries of the twin's weakly seen states by
//!    $10^5$ at no cost on the data, and the interpolated model at an unused speed got spurious
//!    poles at $-3\cdot 10^5$. The data part is reported ([`SpeedFit::cost`]). The Jacobian is
//!    analytic:
//!    $$ \frac{\partial \hat G}{\partial A_{ab}} = C (zI - A)^{-1} e_a e_b^\top (zI - A)^{-1} B
//!    = F_{:,a}\, H_{b,:}, \qquad F = C (zI - A)^{-1}, \; H = (zI - A)^{-1} B, $$
//!    one LU factorisation of $zI - A$ per line. Nothing is constrained: $A_s$ may be (and for
//!    an AMB is) unstable and is never stabilised.
//!
//! Then the free entries of the $A_s$ are fitted by least squares with the Vandermonde matrix
//! of the $\xi_s$ (one fit shared by all entries). [`SpeedScheduledModel::at`] evaluates the
//! polynomial; it refuses speeds outside the measured range (no extrapolation: a polynomial in
//! the speed is not a physical model beyond the data, and the error is typed, not a warning).
//!
//! # Accuracy
//! Without a gauge ($n \le \max(m, p)$) an $A$ that is a polynomial of degree $\le d$ in the
//! speed is recovered exactly. With a gauge the slice makes $A_s$ an analytic but not a
//! polynomial function of the speed even when the physical $A$ is affine, so between the build
//! speeds the schedule has the error of polynomial interpolation, $O(\delta^{d+1})$ for a
//! variation of $A$ of relative size $\delta$ over the range (unit test, $A_0 + \delta\lambda A_1$
//! with $\lVert A_1 \rVert \approx 2 \lVert A_0 \rVert$, $\lambda \in [0, 3]$, $d = 3$:
//! $3.5 \cdot 10^{-4}$, $2.9 \cdot 10^{-7}$, $1.6\cdot 10^{-8}$, $2.4 \cdot 10^{-11}$ for
//! $\delta = 2 \cdot 10^{-2}$, $4 \cdot 10^{-3}$, $2 \cdot 10^{-3}$, $4 \cdot 10^{-4}$); at the
//! build speeds it is exact when $d = S - 1$. The gyroscopic coupling of an AMB rotor is a small variation: on the
//! 4-axis twin built from exact models at 0, 7 500, 22 500 and 30 000 rpm ($d = 2$), the plant
//! at the unused 15 000 rpm is right to a median relative error (spectral norm, 10–1000 Hz) of
//! $9 \cdot 10^{-11}$; with 0.3 % errors in the models' dynamics and 0.5 % noise on the data,
//! $6.5 \cdot 10^{-4}$ (tests in `ambid-twin/tests/machine_scheduled.rs`).
//!
//! The reference is fitted first; the other speeds, which need only its refined $A$, are then
//! fitted side by side (each on its own data, so the result does not depend on the number of
//! threads). Each refinement stops by the MIMO fitter's rules
//! ([`freqfit_mimo`](super::freqfit_mimo), "Stopping"): when the Gauss–Newton step could
//! still gain less than $\kappa^2\hat\sigma^2$ with $\kappa^2 = \sqrt{q/2}$, or when the last
//! ten steps gained less than half that; until 2026-11-29 only the numerical tolerances
//! stopped it, and on the default `[machine] models = "fit"` workflow (three speeds, order
//! 24, $q = 176$) the schedule took about 10 s of the workflow's 31 s.
//!
//! Complexity: the gauge set-up and each similarity are $O(n^6)$ (QR factorisations of
//! $n^2 \times r$ matrices), each Newton step $O(n^6)$ (an $r \times r$ LU), each
//! Levenberg–Marquardt iteration $O(L n^3 + L n_y n_u q^2)$ for $L$ lines; the method is meant for
//! orders up to a few tens. The 4-axis twin ($n = 24$, 253 lines, four speeds) takes about 4 s
//! in the debug profile (opt-level 1).
//!
//! # Requirements on the problem
//! * At least two speeds, strictly increasing; models discrete, of one order, shape and sample
//!   time; each speed's data of the model's shape, on lines where no model has a pole.
//! * The **reference model minimal** (else part of its $A$ does not show in the plant, and the
//!   gauge may not act freely), also as seen by the band (nonsingular band gramians); checked
//!   with [`StateSpace::minimal_part`], by the balancing and by the rank of
//!   $M(A_\mathrm{ref})$, each reported as an error. The other speeds' models only give the
//!   start: a poor one costs iterations, not accuracy.
//! * The plants must have a realisation with speed-independent $B$, $C$, $D$ in one basis
//!   (physically: only the rotor dynamics change with speed). What does not fit that structure
//!   shows up as a per-speed fit error ([`SpeedFit`]).
//! * The variation of the plant over the range small enough for the slice to stay transversal
//!   (always so for the gyroscopic coupling of an AMB rotor); speeds spaced so that a
//!   polynomial of degree $d$ follows the $A_s$; the error of the schedule at the build speeds
//!   ([`SpeedFit::schedule_median_relative_error`]) measures how well it does, a speed that was
//!   not used to build the model measures the interpolation.
//! * Each speed needs at least $q / (2 n_y n_u)$ lines; $B$, $C$, $D$ come from the reference
//!   speed's model alone (band-balanced), so its errors in $B$, $C$, $D$ are shared by every
//!   speed (its $A$ is refined on its data like every other speed's).
//! * Entries that the band does not see are held near the start by the ridge, not estimated:
//!   the schedule is a model of the plant *in the band*.
//!
//! # Reference
//! The interpolation of local models in a common state basis follows J. De Caigny, J. F. Camino,
//! J. Swevers, "Interpolation-based modeling of MIMO LPV systems", *IEEE Transactions on Control
//! Systems Technology* 19(1), 2011, pp. 46–63 (local models brought to a consistent basis, then
//! interpolated); the gauge family and its slice are those of T. McKelvey, A. Helmersson,
//! T. Ribarits, "Data driven local coordinates for multivariable linear systems and their
//! application to system identification", *Automatica* 40, 2004, pp. 1629–1635 (there with $B$ and
//! $C$ free; here they are fixed and the family is the one that keeps them). The criterion is the
//! weighted complex error of R. Pintelon, J. Schoukens, *System Identification: A Frequency
//! Domain Approach*, 2nd ed., Wiley, 2012.
//!
//! # Example
//! ```
//! use ambid_core::estimate::scheduled::{fit_scheduled, ScheduleOptions, SpeedData};
//! use ambid_core::lti::{Frd, StateSpace};
//! use faer::{mat, Mat};
//! // a lightly damped mode whose frequency rises with the speed (rpm); B, C do not change
//! let truth = |rpm: f64| {
//!     let w = 0.1 + 5e-6 * rpm;
//!     StateSpace::discrete(mat![[0.95, w], [-w, 0.95]], mat![[0.0], [1.0]],
//!                          mat![[1.0, 0.0]], mat![[0.0]], 1e-3).unwrap()
//! };
//! // "identified" models: the truth in a different state basis at each speed
//! let in_basis = |p: &StateSpace, t: Mat<f64>| {
//!     let ti = ambid_core::linalg::solve(t.as_ref(), Mat::<f64>::identity(2, 2).as_ref()).unwrap();
//!     StateSpace::discrete(&ti * p.a() * &t, &ti * p.b(), p.c() * &t, p.d().to_owned(), 1e-3)
//!         .unwrap()
//! };
//! let speeds = [0.0, 1000.0, 2000.0];
//! let f: Vec<f64> = (1..60).map(|k| 2.0 * k as f64).collect();
//! let models: Vec<StateSpace> = speeds.iter().enumerate()
//!     .map(|(i, &s)| in_basis(&truth(s), mat![[1.0, 0.2 * i as f64], [-0.3, 1.0 + 0.1 * i as f64]]))
//!     .collect();
//! let frds: Vec<Frd> = speeds.iter().map(|&s| Frd::from_model(&truth(s), &f).unwrap()).collect();
//! let data: Vec<SpeedData> = (0..3)
//!     .map(|i| SpeedData { speed_rpm: speeds[i], model: &models[i], frd: &frds[i] })
//!     .collect();
//! let sched = fit_scheduled(&data, &ScheduleOptions::default()).unwrap();
//! assert_eq!(sched.degree(), 2);
//! // at a speed that was not used: the plant of the truth
//! let p = sched.at(1500.0).unwrap();
//! let (g, g0) = (p.freq_response_siso(&f).unwrap(), truth(1500.0).freq_response_siso(&f).unwrap());
//! let err = g.iter().zip(&g0).map(|(a, b)| (a - b).norm() / b.norm()).fold(0.0, f64::max);
//! assert!(err < 1e-5, "{err}");
//! // no extrapolation
//! assert!(sched.at(2500.0).is_err());
//! ```

use super::freqfit_mimo::{significance_kappa2, CRAWL_WINDOW};
use super::pem::lm::{minimize, LeastSquaresProblem, LmOptions, StopReason};
use crate::error::{Error, Result};
use crate::linalg;
use crate::lti::{Frd, StateSpace};
use faer::linalg::solvers::{Solve, SolveLstsq};
use faer::{c64, Mat, MatRef};
use rayon::prelude::*;

const CTX: &str = "fit_scheduled";

/// Relative tolerance (of the measured range) within which [`SpeedScheduledModel::at`] accepts a
/// speed outside the range (rounding of the speeds, not extrapolation).
pub const RANGE_TOLERANCE: f64 = 1e-9;

/// Relative regularisation $\varepsilon$ of the band gramians (module docs): directions of the
/// state space that the band sees less than this (relative to the mean) are scaled as if they
/// were seen this much, which bounds the condition number of the balancing transformation.
const GRAMIAN_REGULARISATION: f64 = 1e-12;

/// Weight $\kappa$ of the ridge toward the start, relative to the largest Jacobian column norm
/// (module docs).
const RIDGE: f64 = 1e-4;

/// Largest condition number accepted for the similarity of the start (step 1 of the module docs).
const MAX_SIMILARITY_COND: f64 = 1e12;

/// One measured speed: the speed, the model identified there (in its own state basis) and the
/// frequency-response data it was fitted on.
#[derive(Debug, Clone, Copy)]
pub struct SpeedData<'a> {
    /// Rotor speed in rpm (any sign, finite; the speeds must increase strictly).
    pub speed_rpm: f64,
    /// The identified discrete-time plant at this speed, of the common order, shape and sample
    /// time.
    pub model: &'a StateSpace,
    /// The measured $n_y \times n_u$ frequency response (with entry variances when available)
    /// at this speed.
    pub frd: &'a Frd,
}

/// Options of [`fit_scheduled`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScheduleOptions {
    /// Only the lines with $f_{\min} \le f \le f_{\max}$ (Hz) are used; `None` uses every line.
    pub band_hz: Option<(f64, f64)>,
    /// Degree $d$ of $A(\Omega)$; `None` is $\min(2, S - 1)$ for $S$ speeds; at most $S - 1$.
    pub degree: Option<usize>,
    /// Levenberg–Marquardt steps per speed (0 keeps the start of steps 1–2 of the module docs).
    pub max_iterations: usize,
}

impl Default for ScheduleOptions {
    /// Every line, degree $\min(2, S - 1)$, at most 50 refinement steps per speed.
    fn default() -> Self {
        Self {
            band_hz: None,
            degree: None,
            max_iterations: 50,
        }
    }
}

/// Where a speed's refinement started (module docs, steps 1–2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ScheduleStart {
    /// The reference speed: its own model (band-balanced).
    Reference,
    /// The similarity transform of the speed's own model, moved into the slice.
    Similarity,
    /// The reference's $A$ (the similarity failed or fitted the data worse).
    ReferenceA,
}

/// How one speed was fitted, and how well the schedule reproduces its data.
///
/// The relative errors are per line, $\lVert \hat G_k - G_k \rVert_F / \lVert G_k \rVert_F$, on
/// the lines used; the median and the maximum over the lines are given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedFit {
    /// The speed in rpm.
    pub speed_rpm: f64,
    /// Lines used.
    pub lines: usize,
    /// Start of the refinement.
    pub start: ScheduleStart,
    /// $V_s$ at the start.
    pub initial_cost: f64,
    /// $V_s$ at the refined common-basis model.
    pub cost: f64,
    /// Accepted Levenberg–Marquardt steps.
    pub iterations: usize,
    /// Why the refinement stopped (`None` when it did not run).
    pub stop: Option<StopReason>,
    /// Median relative error of the refined common-basis model at this speed.
    pub median_relative_error: f64,
    /// Largest relative error of the refined common-basis model at this speed.
    pub max_relative_error: f64,
    /// Median relative error of the schedule ([`SpeedScheduledModel::at`]) at this speed.
    pub schedule_median_relative_error: f64,
    /// Largest relative error of the schedule at this speed.
    pub schedule_max_relative_error: f64,
}

/// A discrete-time plant model whose state matrix is a polynomial in the rotor speed (module
/// docs); built by [`fit_scheduled`].
#[derive(Debug, Clone)]
pub struct SpeedScheduledModel {
    coefficients: Vec<Mat<f64>>,
    local: Vec<Mat<f64>>,
    b: Mat<f64>,
    c: Mat<f64>,
    d: Mat<f64>,
    ts: f64,
    speeds: Vec<f64>,
    reference: usize,
    free: Vec<(usize, usize)>,
    fits: Vec<SpeedFit>,
}

impl SpeedScheduledModel {
    /// The plant at `speed_rpm`: $A(\Omega)$ with the common $B$, $C$, $D$.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a speed that is not finite or lies outside the measured
    /// range (beyond [`RANGE_TOLERANCE`] of its width): the schedule is not extrapolated;
    /// measure at that speed and add it to the data.
    pub fn at(&self, speed_rpm: f64) -> Result<StateSpace> {
        let (lo, hi) = self.range_rpm();
        let tol = RANGE_TOLERANCE * (hi - lo);
        if !speed_rpm.is_finite() || speed_rpm < lo - tol || speed_rpm > hi + tol {
            return Err(Error::invalid(
                "speed_rpm",
                format!(
                    "{speed_rpm} rpm lies outside the measured range [{lo}, {hi}] rpm; the schedule is not \
                     extrapolated: measure at that speed and add it to the data"
                ),
            ));
        }
        StateSpace::discrete(
            self.a_at(self.xi(speed_rpm)),
            self.b.clone(),
            self.c.clone(),
            self.d.clone(),
            self.ts,
        )
    }

    fn xi(&self, speed_rpm: f64) -> f64 {
        let (c, h) = self.normalisation();
        (speed_rpm - c) / h
    }

    fn a_at(&self, xi: f64) -> Mat<f64> {
        let n = self.b.nrows();
        let mut a = Mat::<f64>::zeros(n, n);
        let mut pw = 1.0;
        for ap in &self.coefficients {
            a += ap * faer::Scale(pw);
            pw *= xi;
        }
        a
    }

    /// The coefficients $A_0, \dots, A_d$ of $A(\Omega) = \sum_p A_p \xi^p$ in the normalised
    /// speed $\xi = (\Omega - \Omega_c)/\Omega_h$ ([`SpeedScheduledModel::normalisation`]).
    /// The entries held by the gauge slice are constant (zero in $A_1, \dots, A_d$).
    pub fn coefficients(&self) -> &[Mat<f64>] {
        &self.coefficients
    }

    /// $(\Omega_c, \Omega_h)$ in rpm: the centre and the half width of the measured range.
    pub fn normalisation(&self) -> (f64, f64) {
        let (lo, hi) = self.range_rpm();
        (0.5 * (lo + hi), 0.5 * (hi - lo))
    }

    /// The lowest and the highest measured speed (rpm).
    pub fn range_rpm(&self) -> (f64, f64) {
        (
            self.speeds.first().copied().unwrap_or(0.0),
            self.speeds.last().copied().unwrap_or(0.0),
        )
    }

    /// Degree $d$ of the polynomial.
    pub fn degree(&self) -> usize {
        self.coefficients.len().saturating_sub(1)
    }

    /// The speeds used to build the schedule (rpm, increasing).
    pub fn speeds_rpm(&self) -> &[f64] {
        &self.speeds
    }

    /// The reference speed (rpm), whose $(B, C, D)$ are the common ones.
    pub fn reference_speed_rpm(&self) -> f64 {
        self.speeds[self.reference]
    }

    /// The common input matrix $B$.
    pub fn b(&self) -> MatRef<'_, f64> {
        self.b.as_ref()
    }

    /// The common output matrix $C$.
    pub fn c(&self) -> MatRef<'_, f64> {
        self.c.as_ref()
    }

    /// The common feedthrough $D$.
    pub fn d(&self) -> MatRef<'_, f64> {
        self.d.as_ref()
    }

    /// Sample time in seconds.
    pub fn ts(&self) -> f64 {
        self.ts
    }

    /// The entries $(i, j)$ of $A$ that vary with the speed (the free entries of the gauge
    /// slice, module docs), row-major order.
    pub fn free_entries(&self) -> &[(usize, usize)] {
        &self.free
    }

    /// How each speed was fitted (same order as [`SpeedScheduledModel::speeds_rpm`]).
    pub fn fits(&self) -> &[SpeedFit] {
        &self.fits
    }

    /// The refined common-basis model of build speed `index` (before the polynomial fit).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an index outside the speeds.
    pub fn local_model(&self, index: usize) -> Result<StateSpace> {
        let a = self.local.get(index).ok_or_else(|| {
            Error::invalid(
                "index",
                format!(
                    "speed index {index} is outside the {} build speeds",
                    self.local.len()
                ),
            )
        })?;
        StateSpace::discrete(
            a.clone(),
            self.b.clone(),
            self.c.clone(),
            self.d.clone(),
            self.ts,
        )
    }
}

/// Builds the speed-scheduled model from per-speed models and data (module docs).
///
/// # Errors
/// * [`Error::InvalidArgument`] for fewer than two speeds, speeds that are not strictly
///   increasing, a degree above the number of speeds minus one, a bad band, a band with too few
///   lines for the free parameters, a zero line (without variances) or a non-positive variance;
/// * [`Error::NonFinite`] for a speed that is NaN or infinite;
/// * [`Error::TimeDomain`] for a continuous-time model;
/// * [`Error::DimensionMismatch`] for models of different order or shape, or data whose shape
///   differs from the models'; [`Error::SampleTimeMismatch`] for different sample times;
/// * [`Error::Numerical`] for a reference model that is not minimal, a model with a pole on a
///   data line, or a failed refinement.
pub fn fit_scheduled(
    data: &[SpeedData<'_>],
    opts: &ScheduleOptions,
) -> Result<SpeedScheduledModel> {
    let (ts, n, nu, ny) = check_data(data)?;
    let ns = data.len();
    let degree = match opts.degree {
        Some(d) if d + 1 > ns => {
            return Err(Error::invalid(
                "degree",
                format!(
                    "a polynomial of degree {d} needs at least {} speeds, got {ns}; lower the degree or measure at more speeds",
                    d + 1
                ),
            ))
        }
        Some(d) => d,
        None => 2.min(ns - 1),
    };
    let lines = data
        .iter()
        .map(|s| Lines::new(s, opts.band_hz, ts))
        .collect::<Result<Vec<_>>>()?;

    // reference: the speed nearest the middle of the range (the lower one on a tie)
    let mid = 0.5 * (data[0].speed_rpm + data[ns - 1].speed_rpm);
    let reference = (0..ns)
        .min_by(|&i, &j| {
            (data[i].speed_rpm - mid)
                .abs()
                .total_cmp(&(data[j].speed_rpm - mid).abs())
        })
        .unwrap_or(0);
    let rm = data[reference].model;
    let minimal = rm.minimal_part()?.order();
    if minimal < n {
        return Err(Error::numerical(
            CTX,
            format!(
                "the reference model (at {} rpm) is not minimal: {} of its {n} states are controllable and \
                 observable; its A is then not determined by the plant; reduce it (StateSpace::minimal_part) \
                 or identify every speed at order {minimal}",
                data[reference].speed_rpm, minimal
            ),
        ));
    }
    // free entries: n² less the gauge's (n − rank C)(n − rank B), basis-invariant
    let q = n * n - null_space(rm.c())?.ncols() * null_space(rm.b().transpose())?.ncols();
    for (s, l) in lines.iter().enumerate() {
        let m = 2 * l.len() * ny * nu;
        if m < q {
            return Err(Error::invalid(
                "band_hz",
                format!(
                    "speed {} rpm has {} lines in the band, {m} real equations for {q} free entries of A; \
                     widen the band or measure more lines (at least {})",
                    data[s].speed_rpm,
                    l.len(),
                    q.div_ceil(2 * ny * nu)
                ),
            ));
        }
    }
    let rm = band_balanced(rm, &lines[reference].z).ok_or_else(|| {
        Error::numerical(
            CTX,
            format!(
                "the reference model (at {} rpm) is not minimal as seen on the lines of its band (a band \
                 gramian is singular) or has a pole on a line; widen the band or lower the order",
                data[reference].speed_rpm
            ),
        )
    })?;
    let common = Common::new(&rm)?;
    let gauge = Gauge::new(rm.a(), common.b.as_ref(), common.c.as_ref())?;
    if gauge.free.len() != q {
        return Err(Error::numerical(
            CTX,
            "the rank of B or C changed in the balancing; the reference model is too badly conditioned",
        ));
    }
    // the significance rule of the MIMO fitter with κ² = √(q/2), and its crawl stop: the
    // refinement ends when what it could still gain is statistically invisible (module docs,
    // "Algorithm", step 3)
    let lm_opts = if opts.max_iterations > 0 {
        Some(
            LmOptions::default()
                .with_max_iterations(opts.max_iterations)?
                .with_significance_tol(significance_kappa2(q).sqrt())?
                .with_crawl_window(CRAWL_WINDOW),
        )
    } else {
        None
    };

    let base = rm.a().to_owned();
    // one speed's refinement from the (refined) reference's A
    let fit_speed = |s: usize, a_ref: &Mat<f64>| -> Result<LocalFit> {
        let mut prob = SliceProblem {
            base: &base,
            free: &gauge.free,
            common: &common,
            lines: &lines[s],
            prior: Vec::new(),
            ridge: 0.0,
        };
        let theta_ref = gauge.theta(a_ref.as_ref());
        let cost_ref = prob.cost(&theta_ref);
        let (start, theta0) = if s == reference {
            (ScheduleStart::Reference, theta_ref)
        } else {
            let own = band_balanced(data[s].model, &lines[s].z);
            let candidate = similarity(
                own.as_ref().unwrap_or(data[s].model),
                a_ref.as_ref(),
                &common,
            )
            .and_then(|a| gauge.move_into_slice(a, base.as_ref()));
            match candidate {
                Some(a) => {
                    let th = gauge.theta(a.as_ref());
                    match (prob.cost(&th), cost_ref) {
                        (Some(c), Some(cr)) if c > cr => (ScheduleStart::ReferenceA, theta_ref),
                        (Some(_), _) => (ScheduleStart::Similarity, th),
                        (None, _) => (ScheduleStart::ReferenceA, theta_ref),
                    }
                }
                None => (ScheduleStart::ReferenceA, theta_ref),
            }
        };
        let initial_cost = prob.cost(&theta0).ok_or_else(|| {
            Error::numerical(
                CTX,
                format!(
                    "the start at {} rpm has a pole on a data line (or a non-finite response); \
                     drop that line with the band or check the model",
                    data[s].speed_rpm
                ),
            )
        })?;
        let (theta, iterations, stop) = match &lm_opts {
            Some(o) => {
                prob.set_ridge(&theta0).ok_or_else(|| {
                    Error::numerical(CTX, "the Jacobian at the start is not finite")
                })?;
                let (th, rep) = minimize(&mut prob, &theta0, o)?;
                (th, rep.iterations, Some(rep.reason))
            }
            None => (theta0, 0, None),
        };
        let cost = prob.cost(&theta).ok_or_else(|| {
            Error::numerical(
                CTX,
                format!(
                    "the refined model at {} rpm has a non-finite response on the data's lines",
                    data[s].speed_rpm
                ),
            )
        })?;
        let a = prob.a_of(&theta);
        let (med, max) = lines[s].relative_errors(a.as_ref(), &common)?;
        Ok((
            a,
            SpeedFit {
                speed_rpm: data[s].speed_rpm,
                lines: lines[s].len(),
                start,
                initial_cost,
                cost,
                iterations,
                stop,
                median_relative_error: med,
                max_relative_error: max,
                schedule_median_relative_error: f64::NAN,
                schedule_max_relative_error: f64::NAN,
            },
        ))
    };
    // the reference first; the other speeds start from its refined A, each on its own (in
    // parallel: they share nothing, so the result does not depend on the number of threads)
    let (a_ref, fit_ref) = fit_speed(reference, &base)?;
    let others: Vec<(usize, Result<LocalFit>)> = (0..ns)
        .into_par_iter()
        .filter(|&s| s != reference)
        .map(|s| (s, fit_speed(s, &a_ref)))
        .collect();
    let mut local: Vec<Option<Mat<f64>>> = vec![None; ns];
    let mut fits: Vec<Option<SpeedFit>> = vec![None; ns];
    local[reference] = Some(a_ref);
    fits[reference] = Some(fit_ref);
    for (s, r) in others {
        let (a, f) = r?;
        local[s] = Some(a);
        fits[s] = Some(f);
    }
    let local: Vec<Mat<f64>> = local.into_iter().flatten().collect();
    let mut fits: Vec<SpeedFit> = fits.into_iter().flatten().collect();
    if local.len() != ns || fits.len() != ns {
        return Err(Error::numerical(
            CTX,
            "a speed was not fitted (internal error)",
        ));
    }

    // polynomial in ξ, least squares over the speeds, the same fit for every free entry
    let speeds: Vec<f64> = data.iter().map(|s| s.speed_rpm).collect();
    let (lo, hi) = (speeds[0], speeds[ns - 1]);
    let (centre, half) = (0.5 * (lo + hi), 0.5 * (hi - lo));
    let vander = Mat::<f64>::from_fn(ns, degree + 1, |s, p| {
        ((speeds[s] - centre) / half).powi(p as i32)
    });
    let thetas = Mat::<f64>::from_fn(ns, q, |s, k| {
        let (i, j) = gauge.free[k];
        local[s][(i, j)]
    });
    let coef = linalg::lstsq(vander.as_ref(), thetas.as_ref())?;
    let mut coefficients = vec![Mat::<f64>::zeros(n, n); degree + 1];
    coefficients[0] = base.clone();
    for (p, cp) in coefficients.iter_mut().enumerate() {
        for (k, &(i, j)) in gauge.free.iter().enumerate() {
            cp[(i, j)] = coef[(p, k)];
        }
    }
    let model = SpeedScheduledModel {
        coefficients,
        local,
        b: common.b.clone(),
        c: common.c.clone(),
        d: common.d.clone(),
        ts,
        speeds,
        reference,
        free: gauge.free.clone(),
        fits: Vec::new(),
    };
    for (s, fit) in fits.iter_mut().enumerate() {
        let a = model.a_at(model.xi(model.speeds[s]));
        let (med, max) = lines[s].relative_errors(a.as_ref(), &common)?;
        fit.schedule_median_relative_error = med;
        fit.schedule_max_relative_error = max;
    }
    Ok(SpeedScheduledModel { fits, ..model })
}

/// One speed's refined $A_s$ and its fit report.
type LocalFit = (Mat<f64>, SpeedFit);

/// Checks the speeds, models and data; returns $(T, n, n_u, n_y)$.
fn check_data(data: &[SpeedData<'_>]) -> Result<(f64, usize, usize, usize)> {
    if data.len() < 2 {
        return Err(Error::invalid(
            "data",
            format!(
                "a speed schedule needs models at two or more speeds, got {}; identify the plant at more speeds",
                data.len()
            ),
        ));
    }
    for (s, d) in data.iter().enumerate() {
        if !d.speed_rpm.is_finite() {
            return Err(Error::NonFinite {
                what: "speed_rpm",
                index: s,
            });
        }
        if s > 0 && d.speed_rpm <= data[s - 1].speed_rpm {
            return Err(Error::invalid(
                "speed_rpm",
                format!(
                    "the speeds must increase strictly, but {} rpm (entry {}) follows {} rpm; sort the data by speed \
                     and merge repeated speeds into one",
                    d.speed_rpm,
                    s + 1,
                    data[s - 1].speed_rpm
                ),
            ));
        }
    }
    let m0 = data[0].model;
    let ts = m0.ts().ok_or_else(|| {
        Error::TimeDomain(
            "fit_scheduled needs discrete-time models; discretise them (c2d_zoh) at the data's sample time"
                .into(),
        )
    })?;
    let (n, nu, ny) = (m0.order(), m0.ninputs(), m0.noutputs());
    if n == 0 {
        return Err(Error::invalid(
            "model",
            "the models have no states; a speed schedule varies the state matrix",
        ));
    }
    for d in data {
        let m = d.model;
        let t = m.ts().ok_or_else(|| {
            Error::TimeDomain(format!(
                "the model at {} rpm is continuous-time; discretise it (c2d_zoh) at {ts} s",
                d.speed_rpm
            ))
        })?;
        if t != ts {
            return Err(Error::SampleTimeMismatch { left: ts, right: t });
        }
        if (m.order(), m.ninputs(), m.noutputs()) != (n, nu, ny) {
            return Err(Error::DimensionMismatch {
                context: "fit_scheduled models (order, inputs, outputs)",
                expected: format!("({n}, {nu}, {ny}) as at {} rpm", data[0].speed_rpm),
                got: format!(
                    "({}, {}, {}) at {} rpm",
                    m.order(),
                    m.ninputs(),
                    m.noutputs(),
                    d.speed_rpm
                ),
            });
        }
        if (d.frd.ny(), d.frd.nu()) != (ny, nu) {
            return Err(Error::DimensionMismatch {
                context: "fit_scheduled data (outputs × inputs)",
                expected: format!("{ny}×{nu} as the models"),
                got: format!("{}×{} at {} rpm", d.frd.ny(), d.frd.nu(), d.speed_rpm),
            });
        }
        if let Some(tf) = d.frd.ts() {
            if tf != ts {
                return Err(Error::SampleTimeMismatch {
                    left: ts,
                    right: tf,
                });
            }
        }
    }
    Ok((ts, n, nu, ny))
}

/// The common $(B, C, D)$, also as complex $B$ and $C^\top$ for the solves.
struct Common {
    b: Mat<f64>,
    c: Mat<f64>,
    d: Mat<f64>,
    bc: Mat<c64>,
    ctc: Mat<c64>,
}

impl Common {
    fn new(m: &StateSpace) -> Result<Self> {
        let (b, c) = (m.b(), m.c());
        Ok(Self {
            b: b.to_owned(),
            c: c.to_owned(),
            d: m.d().to_owned(),
            bc: Mat::from_fn(b.nrows(), b.ncols(), |i, j| c64::new(b[(i, j)], 0.0)),
            ctc: Mat::from_fn(c.ncols(), c.nrows(), |i, j| c64::new(c[(j, i)], 0.0)),
        })
    }

    /// $F = C (zI - A)^{-1}$ (as $F^\top$, $n \times n_y$) and $H = (zI - A)^{-1} B$; `None` if
    /// $zI - A$ is singular.
    fn resolvents(&self, a: MatRef<'_, f64>, z: c64) -> Option<(Mat<c64>, Mat<c64>)> {
        let n = a.nrows();
        let zia = Mat::<c64>::from_fn(n, n, |i, j| {
            let d = if i == j { z } else { c64::new(0.0, 0.0) };
            d - c64::new(a[(i, j)], 0.0)
        });
        let lu = zia.partial_piv_lu();
        let h = lu.solve(&self.bc);
        let ft = lu.solve_transpose(&self.ctc);
        let finite = |m: &Mat<c64>| {
            m.col_iter()
                .all(|c| c.iter().all(|v| v.re.is_finite() && v.im.is_finite()))
        };
        (finite(&h) && finite(&ft)).then_some((ft, h))
    }

    /// $\hat G(z) = C H + D$ from $H$.
    fn response(&self, h: &Mat<c64>) -> Mat<c64> {
        let (ny, nu, n) = (self.c.nrows(), self.b.ncols(), self.b.nrows());
        Mat::from_fn(ny, nu, |i, j| {
            let mut acc = c64::new(self.d[(i, j)], 0.0);
            for k in 0..n {
                acc += h[(k, j)] * self.c[(i, k)];
            }
            acc
        })
    }
}

/// One speed's lines in the band: $z_k$, the data and $\sqrt{w}$ (module docs), flat with the
/// layout of [`Frd`] (line after line, each column by column).
struct Lines {
    z: Vec<c64>,
    g: Vec<c64>,
    sw: Vec<f64>,
    ny: usize,
    nu: usize,
}

impl Lines {
    fn new(s: &SpeedData<'_>, band: Option<(f64, f64)>, ts: f64) -> Result<Self> {
        let frd = match band {
            Some((lo, hi)) => s.frd.band(lo, hi)?,
            None => s.frd.clone(),
        };
        let (ny, nu) = (frd.ny(), frd.nu());
        let e = ny * nu;
        if frd.is_empty() {
            return Err(Error::invalid(
                "band_hz",
                format!(
                    "the data at {} rpm have no line in the band; widen the band",
                    s.speed_rpm
                ),
            ));
        }
        let g = frd.values().to_vec();
        let sw = match frd.variance() {
            Some(v) => {
                if let Some(k) = v.iter().position(|&x| !(x > 0.0 && x.is_finite())) {
                    return Err(Error::invalid(
                        "frd",
                        format!(
                            "the variance of entry {} of the line at {} Hz ({} rpm) is {}, not positive; \
                             repair it or pass the data without variances (then the lines are weighted by their norm)",
                            k % e,
                            frd.f_hz()[k / e],
                            s.speed_rpm,
                            v[k]
                        ),
                    ));
                }
                v.iter().map(|x| 1.0 / x.sqrt()).collect()
            }
            None => {
                let mut sw = Vec::with_capacity(g.len());
                for (k, line) in g.chunks_exact(e).enumerate() {
                    let ms = line.iter().map(|v| v.norm_sqr()).sum::<f64>() / e as f64;
                    if !(ms > 0.0 && ms.is_finite()) {
                        return Err(Error::invalid(
                            "frd",
                            format!(
                                "the response at {} Hz ({} rpm) is zero; a zero line has no relative error: \
                                 drop it with the band or give the data variances",
                                frd.f_hz()[k],
                                s.speed_rpm
                            ),
                        ));
                    }
                    sw.extend(std::iter::repeat_n(1.0 / ms.sqrt(), e));
                }
                sw
            }
        };
        let z = frd
            .f_hz()
            .iter()
            .map(|f| c64::from_polar(1.0, 2.0 * std::f64::consts::PI * f * ts))
            .collect();
        Ok(Self { z, g, sw, ny, nu })
    }

    fn len(&self) -> usize {
        self.z.len()
    }

    /// Median and maximum over the lines of $\lVert \hat G_k - G_k\rVert_F / \lVert G_k\rVert_F$.
    fn relative_errors(&self, a: MatRef<'_, f64>, common: &Common) -> Result<(f64, f64)> {
        let e = self.ny * self.nu;
        let mut rel = Vec::with_capacity(self.len());
        for (k, &z) in self.z.iter().enumerate() {
            let (_, h) = common.resolvents(a, z).ok_or_else(|| {
                Error::numerical(
                    CTX,
                    "a model has a pole on a data line; drop that line with the band",
                )
            })?;
            let gh = common.response(&h);
            let (mut num, mut den) = (0.0, 0.0);
            for j in 0..self.nu {
                for i in 0..self.ny {
                    let g = self.g[k * e + j * self.ny + i];
                    num += (gh[(i, j)] - g).norm_sqr();
                    den += g.norm_sqr();
                }
            }
            rel.push(if den > 0.0 {
                (num / den).sqrt()
            } else {
                num.sqrt()
            });
        }
        rel.sort_by(f64::total_cmp);
        let l = rel.len();
        let med = if l % 2 == 1 {
            rel[l / 2]
        } else {
            0.5 * (rel[l / 2 - 1] + rel[l / 2])
        };
        Ok((med, rel[l - 1]))
    }
}

/// The gauge family of the reference (module docs): null spaces of $C$ and $B^\top$, the pivoted
/// (held) entries and the free ones.
struct Gauge {
    nc: Mat<f64>,
    nb: Mat<f64>,
    /// Entries held at the reference's values ($r$).
    held: Vec<(usize, usize)>,
    /// Free entries ($q = n^2 - r$), row-major order.
    free: Vec<(usize, usize)>,
}

impl Gauge {
    fn new(a: MatRef<'_, f64>, b: MatRef<'_, f64>, c: MatRef<'_, f64>) -> Result<Self> {
        let n = a.nrows();
        let nc = null_space(c)?;
        let nb = null_space(b.transpose())?;
        let r = nc.ncols() * nb.ncols();
        let mut held = Vec::with_capacity(r);
        if r > 0 {
            let m = gauge_tangent(a, a, nc.as_ref(), nb.as_ref());
            let mt = m.transpose().to_owned();
            let qr = mt.col_piv_qr();
            let rr = qr.R();
            let d0 = rr[(0, 0)].abs();
            let dr = rr[(r - 1, r - 1)].abs();
            if !(d0 > 0.0 && dr > 1e-10 * d0) {
                return Err(Error::numerical(
                    CTX,
                    format!(
                        "the reference model is not minimal (or nearly so; gauge conditioning {:.1e}): B and C do \
                         not fix its state basis; reduce it (StateSpace::minimal_part) or identify a lower order",
                        if d0 > 0.0 { dr / d0 } else { 0.0 }
                    ),
                ));
            }
            let (fwd, _) = qr.P().arrays();
            held.extend(fwd[..r].iter().map(|&k| (k % n, k / n)));
        }
        let mut is_held = vec![false; n * n];
        for &(i, j) in &held {
            is_held[i * n + j] = true;
        }
        let free = (0..n * n)
            .filter(|&k| !is_held[k])
            .map(|k| (k / n, k % n))
            .collect();
        Ok(Self { nc, nb, held, free })
    }

    fn theta(&self, a: MatRef<'_, f64>) -> Vec<f64> {
        self.free.iter().map(|&(i, j)| a[(i, j)]).collect()
    }

    /// Newton's method over $T = I + N_C X N_B^\top$ until the held entries of $T^{-1} A T$ equal
    /// those of `base` (module docs, step 2); `None` if it does not converge.
    fn move_into_slice(&self, a: Mat<f64>, base: MatRef<'_, f64>) -> Option<Mat<f64>> {
        let n = a.nrows();
        let r = self.held.len();
        if r == 0 {
            return Some(a);
        }
        let resid = |a: &Mat<f64>| -> Vec<f64> {
            self.held
                .iter()
                .map(|&(i, j)| a[(i, j)] - base[(i, j)])
                .collect()
        };
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let scale = base.norm_l2().max(f64::MIN_POSITIVE);
        let mut a = a;
        let mut res = resid(&a);
        let mut rn = norm(&res);
        for _ in 0..50 {
            if rn <= 1e-14 * scale {
                return Some(a);
            }
            let m = gauge_tangent(a.as_ref(), a.as_ref(), self.nc.as_ref(), self.nb.as_ref());
            let jac = Mat::<f64>::from_fn(r, r, |row, col| {
                let (i, j) = self.held[row];
                m[(i + j * n, col)]
            });
            let rhs = Mat::<f64>::from_fn(r, 1, |i, _| -res[i]);
            let x = jac.partial_piv_lu().solve(&rhs);
            if !x.col(0).iter().all(|v| v.is_finite()) {
                return None;
            }
            let kc = self.nc.ncols();
            let xm = Mat::<f64>::from_fn(kc, self.nb.ncols(), |u, v| x[(u + v * kc, 0)]);
            let e = &self.nc * &xm * self.nb.transpose();
            // backtracking: the full step, then halves, while the slice residual does not drop
            let mut step = 1.0;
            let mut accepted = false;
            for _ in 0..30 {
                let t = Mat::<f64>::identity(n, n) + &e * faer::Scale(step);
                let at = &a * &t;
                let cand = t.partial_piv_lu().solve(&at);
                if finite(cand.as_ref()) {
                    let rc = resid(&cand);
                    let rcn = norm(&rc);
                    if rcn < rn {
                        a = cand;
                        res = rc;
                        rn = rcn;
                        accepted = true;
                        break;
                    }
                }
                step *= 0.5;
            }
            if !accepted {
                return (rn <= 1e-10 * scale).then_some(a);
            }
        }
        (rn <= 1e-10 * scale).then_some(a)
    }
}

/// The band-balanced realisation of `m` on the lines `z` (module docs): the basis in which the
/// band gramians $W_c = \operatorname{Re}\sum_k H_k H_k^{\mathsf H}$ and
/// $W_o = \operatorname{Re}\sum_k F_k^{\mathsf H} F_k$ are equal and diagonal, by the square-root
/// method (triangular factors from QR factorisations of the stacked real and imaginary parts).
/// `None` if a gramian is singular to working precision or a line sits on a pole.
pub(crate) fn band_balanced(m: &StateSpace, z: &[c64]) -> Option<StateSpace> {
    let (a, b, c) = (m.a(), m.b(), m.c());
    let (n, ny, nu) = (a.nrows(), c.nrows(), b.ncols());
    let l = z.len();
    if 2 * l * nu < n || 2 * l * ny < n {
        return None;
    }
    let common = Common::new(m).ok()?;
    let mut zc = Mat::<f64>::zeros(2 * l * nu, n);
    let mut zo = Mat::<f64>::zeros(2 * l * ny, n);
    for (k, &zk) in z.iter().enumerate() {
        let (ft, h) = common.resolvents(a, zk)?;
        for j in 0..nu {
            for i in 0..n {
                zc[(2 * (k * nu + j), i)] = h[(i, j)].re;
                zc[(2 * (k * nu + j) + 1, i)] = h[(i, j)].im;
            }
        }
        for j in 0..ny {
            for i in 0..n {
                zo[(2 * (k * ny + j), i)] = ft[(i, j)].re;
                zo[(2 * (k * ny + j) + 1, i)] = ft[(i, j)].im;
            }
        }
    }
    // regularised gramians W + ε (‖Z‖²_F / n) I: n rows √ε ‖Z‖_F/√n I appended
    for z in [&mut zc, &mut zo] {
        let rows = z.nrows();
        let reg = GRAMIAN_REGULARISATION.sqrt() * z.norm_l2() / (n as f64).sqrt();
        let mut ext = Mat::<f64>::zeros(rows + n, n);
        ext.as_mut().get_mut(..rows, ..).copy_from(z.as_ref());
        for i in 0..n {
            ext[(rows + i, i)] = reg;
        }
        *z = ext;
    }
    // W_c = R_cᵀ R_c, W_o = R_oᵀ R_o; R_o R_cᵀ = U Σ Vᵀ; T = R_cᵀ V Σ^{-1/2}, T⁻¹ = Σ^{-1/2} Uᵀ R_o
    let rc = crate::estimate::qr_stream::r_factor(zc.as_ref());
    let ro = crate::estimate::qr_stream::r_factor(zo.as_ref());
    let x = &ro * rc.transpose();
    let svd = x.svd().ok()?;
    let sv = svd.S().column_vector();
    let s1 = sv[0];
    if !(s1 > 0.0 && s1.is_finite() && sv[n - 1] > n as f64 * f64::EPSILON * s1) {
        return None;
    }
    let t = Mat::<f64>::from_fn(n, n, |i, j| {
        (0..n).map(|k| rc[(k, i)] * svd.V()[(k, j)]).sum::<f64>() / sv[j].sqrt()
    });
    let ti = Mat::<f64>::from_fn(n, n, |i, j| {
        (0..n).map(|k| svd.U()[(k, i)] * ro[(k, j)]).sum::<f64>() / sv[i].sqrt()
    });
    let (ab, bb, cb) = (&ti * a * &t, &ti * b, c * &t);
    (finite(ab.as_ref()) && finite(bb.as_ref()) && finite(cb.as_ref())).then_some(())?;
    StateSpace::new(ab, bb, cb, m.d().to_owned(), m.ts()).ok()
}

/// Orthonormal basis (columns) of the null space of `m` ($k \times n$): the right singular
/// vectors of the singular values below $\max(k, n)\,\varepsilon\,\sigma_1$.
fn null_space(m: MatRef<'_, f64>) -> Result<Mat<f64>> {
    let (k, n) = (m.nrows(), m.ncols());
    if k == 0 || m.norm_max() == 0.0 {
        return Ok(Mat::identity(n, n));
    }
    // SVD of the tall transpose: null(m) is the part of its left singular basis beyond the rank
    let svd = m
        .transpose()
        .to_owned()
        .svd()
        .map_err(|e| Error::numerical(CTX, format!("SVD failed: {e:?}")))?;
    let s = svd.S().column_vector();
    let smax = (0..s.nrows()).map(|i| s[i]).fold(0.0, f64::max);
    let tol = k.max(n) as f64 * f64::EPSILON * smax;
    let rank = (0..s.nrows()).filter(|&i| s[i] > tol).count();
    Ok(svd.U().get(.., rank..).to_owned())
}

/// Moore–Penrose pseudo-inverse by the thin SVD (singular values below
/// $\max(k, n)\,\varepsilon\,\sigma_1$ dropped).
fn pinv(m: MatRef<'_, f64>) -> Option<Mat<f64>> {
    let (k, n) = (m.nrows(), m.ncols());
    let svd = m.thin_svd().ok()?;
    let s = svd.S().column_vector();
    let smax = (0..s.nrows()).map(|i| s[i]).fold(0.0, f64::max);
    let tol = k.max(n) as f64 * f64::EPSILON * smax;
    let (u, v) = (svd.U(), svd.V());
    Some(Mat::from_fn(n, k, |i, j| {
        (0..s.nrows())
            .filter(|&l| s[l] > tol)
            .map(|l| v[(i, l)] * u[(j, l)] / s[l])
            .sum()
    }))
}

/// $M = N_B \otimes (A_l N_C) - (A_r^\top N_B) \otimes N_C$ ($n^2 \times k_c k_b$):
/// $\operatorname{vec}(A_l E - E A_r) = M \operatorname{vec} X$ for $E = N_C X N_B^\top$
/// (column-major vec; with $A_l = A_r = A$ the tangent of the gauge family, module docs).
fn gauge_tangent(
    al: MatRef<'_, f64>,
    ar: MatRef<'_, f64>,
    nc: MatRef<'_, f64>,
    nb: MatRef<'_, f64>,
) -> Mat<f64> {
    let n = al.nrows();
    let (kc, kb) = (nc.ncols(), nb.ncols());
    let anc = al * nc;
    let atnb = ar.transpose() * nb;
    let mut m = Mat::<f64>::zeros(n * n, kc * kb);
    for v in 0..kb {
        for u in 0..kc {
            let col = u + v * kc;
            for j in 0..n {
                let (nbj, atj) = (nb[(j, v)], atnb[(j, v)]);
                for i in 0..n {
                    m[(i + j * n, col)] = anc[(i, u)] * nbj - nc[(i, u)] * atj;
                }
            }
        }
    }
    m
}

/// Step 1 of the module docs: $T^{-1} \hat A_s T$ for the similarity $T$ from the reference basis
/// into the model's; `None` if $T$ is singular or badly conditioned.
fn similarity(model: &StateSpace, a_ref: MatRef<'_, f64>, common: &Common) -> Option<Mat<f64>> {
    let n = a_ref.nrows();
    let (ah, bh, ch) = (model.a(), model.b(), model.c());
    let (b, c) = (common.b.as_ref(), common.c.as_ref());
    let bp = pinv(b)?;
    let chp = pinv(ch)?;
    let bhbp = bh * &bp;
    let t0 = &bhbp + &chp * c - &chp * (ch * &bhbp);
    let nch = null_space(ch).ok()?;
    let nb = null_space(b.transpose()).ok()?;
    let (kc, kb) = (nch.ncols(), nb.ncols());
    let t = if kc * kb > 0 {
        let m = gauge_tangent(ah, a_ref, nch.as_ref(), nb.as_ref());
        let r0 = ah * &t0 - &t0 * a_ref;
        let rhs = Mat::<f64>::from_fn(n * n, 1, |k, _| -r0[(k % n, k / n)]);
        let x = m.qr().solve_lstsq(&rhs);
        let xm = Mat::<f64>::from_fn(kc, kb, |u, v| x[(u + v * kc, 0)]);
        &t0 + &nch * &xm * nb.transpose()
    } else {
        t0
    };
    let ti = t.partial_piv_lu().solve(Mat::<f64>::identity(n, n));
    let cond = linalg::norm1(t.as_ref()) * linalg::norm1(ti.as_ref());
    if !(cond.is_finite() && cond < MAX_SIMILARITY_COND) {
        return None;
    }
    let a = &ti * ah * &t;
    finite(a.as_ref()).then_some(a)
}

/// Whether every entry of `m` is finite.
fn finite(m: MatRef<'_, f64>) -> bool {
    (0..m.ncols()).all(|j| (0..m.nrows()).all(|i| m[(i, j)].is_finite()))
}

/// The refinement of one speed (module docs, step 3): the free entries of $A$ in the slice,
/// with $B$, $C$, $D$ fixed.
struct SliceProblem<'a> {
    base: &'a Mat<f64>,
    free: &'a [(usize, usize)],
    common: &'a Common,
    lines: &'a Lines,
    /// The ridge's centre (the start) and weight $\sqrt\mu$ (0: no ridge).
    prior: Vec<f64>,
    ridge: f64,
}

impl SliceProblem<'_> {
    fn a_of(&self, theta: &[f64]) -> Mat<f64> {
        let mut a = self.base.clone();
        for (&(i, j), &t) in self.free.iter().zip(theta) {
            a[(i, j)] = t;
        }
        a
    }

    /// $V_s$ at `theta` (the data's part, without the ridge), `None` if the response is not
    /// finite.
    fn cost(&self, theta: &[f64]) -> Option<f64> {
        self.data_residuals(theta)
            .map(|r| r.iter().map(|x| x * x).sum::<f64>())
            .filter(|c| c.is_finite())
    }

    /// Sets the ridge: centre `prior`, weight $\kappa$ times the largest column norm of the
    /// data's Jacobian at `prior`.
    fn set_ridge(&mut self, prior: &[f64]) -> Option<()> {
        self.ridge = 0.0;
        let j = self.data_jacobian(prior)?;
        let cmax = (0..j.ncols())
            .map(|c| j.col(c).norm_l2())
            .fold(0.0, f64::max);
        self.prior = prior.to_vec();
        self.ridge = RIDGE * cmax;
        Some(())
    }

    fn data_residuals(&self, theta: &[f64]) -> Option<Vec<f64>> {
        let a = self.a_of(theta);
        let l = self.lines;
        let (ny, nu) = (l.ny, l.nu);
        let e = ny * nu;
        let mut r = Vec::with_capacity(2 * l.g.len());
        for (k, &z) in l.z.iter().enumerate() {
            let (_, h) = self.common.resolvents(a.as_ref(), z)?;
            let gh = self.common.response(&h);
            for j in 0..nu {
                for i in 0..ny {
                    let idx = k * e + j * ny + i;
                    let d = (gh[(i, j)] - l.g[idx]) * l.sw[idx];
                    r.push(d.re);
                    r.push(d.im);
                }
            }
        }
        Some(r)
    }

    fn data_jacobian(&self, theta: &[f64]) -> Option<Mat<f64>> {
        let a = self.a_of(theta);
        let l = self.lines;
        let (ny, nu) = (l.ny, l.nu);
        let e = ny * nu;
        let mut jac = Mat::<f64>::zeros(2 * l.g.len(), self.free.len());
        for (k, &z) in l.z.iter().enumerate() {
            let (ft, h) = self.common.resolvents(a.as_ref(), z)?;
            for (col, &(ia, ib)) in self.free.iter().enumerate() {
                for j in 0..nu {
                    let hb = h[(ib, j)];
                    for i in 0..ny {
                        let idx = k * e + j * ny + i;
                        let d = ft[(ia, i)] * hb * l.sw[idx];
                        jac[(2 * idx, col)] = d.re;
                        jac[(2 * idx + 1, col)] = d.im;
                    }
                }
            }
        }
        Some(jac)
    }
}

impl LeastSquaresProblem for SliceProblem<'_> {
    fn residuals(&mut self, theta: &[f64]) -> Option<Vec<f64>> {
        let mut r = self.data_residuals(theta)?;
        if self.ridge > 0.0 {
            r.extend(
                theta
                    .iter()
                    .zip(&self.prior)
                    .map(|(t, p)| self.ridge * (t - p)),
            );
        }
        Some(r)
    }

    fn jacobian(&mut self, theta: &[f64]) -> Option<Mat<f64>> {
        let j = self.data_jacobian(theta)?;
        if self.ridge <= 0.0 {
            return Some(j);
        }
        let (m, q) = (j.nrows(), j.ncols());
        let mut out = Mat::<f64>::zeros(m + q, q);
        out.as_mut().get_mut(..m, ..).copy_from(j.as_ref());
        for k in 0..q {
            out[(m + k, k)] = self.ridge;
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    fn randn(rng: &mut ChaCha8Rng) -> f64 {
        StandardNormal.sample(rng)
    }

    fn rand_mat(rng: &mut ChaCha8Rng, r: usize, c: usize, s: f64) -> Mat<f64> {
        Mat::from_fn(r, c, |_, _| s * randn(rng))
    }

    /// The model in a random basis $T$ ($T^{-1} A T$, $T^{-1} B$, $C T$).
    fn in_basis(p: &StateSpace, rng: &mut ChaCha8Rng) -> StateSpace {
        let n = p.order();
        let t = Mat::<f64>::from_fn(n, n, |i, j| {
            let g = randn(rng);
            if i == j {
                1.0 + 0.3 * g
            } else {
                0.3 * g / (n as f64).sqrt()
            }
        });
        let ti = t.partial_piv_lu().solve(Mat::<f64>::identity(n, n));
        StateSpace::discrete(
            &ti * p.a() * &t,
            &ti * p.b(),
            p.c() * &t,
            p.d().to_owned(),
            p.ts().unwrap_or(1.0),
        )
        .unwrap()
    }

    /// A stable random $A_0$ (spectral radius 0.8) plus `lambda` times a fixed $A_1$ (entries of
    /// standard deviation $1/\sqrt n$, like $A_0$'s before scaling).
    struct Family {
        a0: Mat<f64>,
        a1: Mat<f64>,
        b: Mat<f64>,
        c: Mat<f64>,
    }

    impl Family {
        fn new(n: usize, m: usize, p: usize, seed: u64) -> Self {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let a0 = rand_mat(&mut rng, n, n, 1.0 / (n as f64).sqrt());
            let rho = linalg::eigenvalues(a0.as_ref())
                .unwrap()
                .iter()
                .map(|z| z.norm())
                .fold(0.0, f64::max);
            let a0 = &a0 * faer::Scale(0.8 / rho);
            let a1 = rand_mat(&mut rng, n, n, 1.0 / (n as f64).sqrt());
            let b = rand_mat(&mut rng, n, m, 1.0);
            let c = rand_mat(&mut rng, p, n, 1.0);
            Self { a0, a1, b, c }
        }

        fn at(&self, lambda: f64) -> StateSpace {
            let (p, m) = (self.c.nrows(), self.b.ncols());
            StateSpace::discrete(
                &self.a0 + &self.a1 * faer::Scale(lambda),
                self.b.clone(),
                self.c.clone(),
                Mat::zeros(p, m),
                1e-3,
            )
            .unwrap()
        }
    }

    fn grid() -> Vec<f64> {
        (1..=40).map(|k| 12.0 * k as f64).collect()
    }

    fn rel_err(a: &StateSpace, b: &StateSpace, f: &[f64]) -> f64 {
        let (ga, gb) = (a.freq_response(f).unwrap(), b.freq_response(f).unwrap());
        ga.iter()
            .zip(&gb)
            .map(|(x, y)| (x - y).norm_l2() / y.norm_l2())
            .fold(0.0, f64::max)
    }

    /// The analytic Jacobian equals central differences of the residuals.
    #[test]
    fn scheduled_jacobian_matches_finite_differences() {
        let fam = Family::new(5, 2, 2, 11);
        let truth = fam.at(0.0);
        let f = grid();
        let frd = Frd::from_model(&fam.at(1.0), &f).unwrap();
        let sd = SpeedData {
            speed_rpm: 0.0,
            model: &truth,
            frd: &frd,
        };
        let lines = Lines::new(&sd, None, 1e-3).unwrap();
        let common = Common::new(&truth).unwrap();
        let gauge = Gauge::new(truth.a(), truth.b(), truth.c()).unwrap();
        assert_eq!(gauge.free.len(), 25 - 9);
        let base = truth.a().to_owned();
        let mut prob = SliceProblem {
            base: &base,
            free: &gauge.free,
            common: &common,
            lines: &lines,
            prior: Vec::new(),
            ridge: 0.0,
        };
        let theta = gauge.theta(base.as_ref());
        // with the ridge centred away from the point, so that its rows are tested too
        let prior: Vec<f64> = theta.iter().map(|t| t + 0.1).collect();
        prob.set_ridge(&prior).unwrap();
        assert!(prob.ridge > 0.0);
        let jac = prob.jacobian(&theta).unwrap();
        assert_eq!(jac.nrows(), 2 * 40 * 4 + theta.len());
        let h = 1e-6;
        let mut worst: f64 = 0.0;
        for k in 0..theta.len() {
            let (mut tp, mut tm) = (theta.clone(), theta.clone());
            tp[k] += h;
            tm[k] -= h;
            let (rp, rm) = (prob.residuals(&tp).unwrap(), prob.residuals(&tm).unwrap());
            let col_norm = (0..jac.nrows())
                .map(|i| jac[(i, k)] * jac[(i, k)])
                .sum::<f64>()
                .sqrt();
            for i in 0..rp.len() {
                let fd = (rp[i] - rm[i]) / (2.0 * h);
                worst = worst.max((fd - jac[(i, k)]).abs() / col_norm);
            }
        }
        assert!(worst < 1e-7, "worst relative Jacobian error {worst:e}");
    }

    /// With as many inputs as states there is no gauge: an $A$ affine in the speed, seen through
    /// exact models in random bases, is recovered exactly by degree 1, also at unused speeds.
    #[test]
    fn scheduled_exact_recovery_without_gauge() {
        let fam = Family::new(3, 3, 2, 5);
        let f = grid();
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let speeds = [0.0, 1000.0, 3000.0];
        let models: Vec<StateSpace> = speeds
            .iter()
            .map(|&s| in_basis(&fam.at(s / 1000.0), &mut rng))
            .collect();
        let frds: Vec<Frd> = speeds
            .iter()
            .map(|&s| Frd::from_model(&fam.at(s / 1000.0), &f).unwrap())
            .collect();
        let data: Vec<SpeedData> = (0..3)
            .map(|i| SpeedData {
                speed_rpm: speeds[i],
                model: &models[i],
                frd: &frds[i],
            })
            .collect();
        let opts = ScheduleOptions {
            degree: Some(1),
            ..Default::default()
        };
        let s = fit_scheduled(&data, &opts).unwrap();
        assert_eq!(s.free_entries().len(), 9);
        for x in [0.0, 500.0, 1700.0, 2999.0, 3000.0] {
            let e = rel_err(&s.at(x).unwrap(), &fam.at(x / 1000.0), &f);
            assert!(e < 1e-10, "{x} rpm: {e:e}");
        }
    }

    /// With a gauge ($n = 6$ states, 2 inputs, 2 outputs: 16 of the 36 entries of $A$ are fixed
    /// by the slice): exact models in random bases of $A_0 + \delta\,\lambda A_1$,
    /// $\lambda \in \{0, 1, 2, 3\}$, degree 3. Returns the largest relative error at the unused
    /// $\lambda = 0.5, 1.5, 2.5$ after checking that the common-basis models and the schedule
    /// are exact at the build speeds.
    fn gauge_case(delta: f64) -> f64 {
        let fam = Family::new(6, 2, 2, 21);
        let at = |rpm: f64| fam.at(delta * rpm / 1000.0);
        let f = grid();
        let mut rng = ChaCha8Rng::seed_from_u64(22);
        let speeds = [0.0, 1000.0, 2000.0, 3000.0];
        let models: Vec<StateSpace> = speeds.iter().map(|&s| in_basis(&at(s), &mut rng)).collect();
        let frds: Vec<Frd> = speeds
            .iter()
            .map(|&s| Frd::from_model(&at(s), &f).unwrap())
            .collect();
        let data: Vec<SpeedData> = (0..4)
            .map(|i| SpeedData {
                speed_rpm: speeds[i],
                model: &models[i],
                frd: &frds[i],
            })
            .collect();
        let opts = ScheduleOptions {
            degree: Some(3),
            ..Default::default()
        };
        let s = fit_scheduled(&data, &opts).unwrap();
        assert_eq!(s.free_entries().len(), 36 - 16);
        assert_eq!(s.reference_speed_rpm(), 1000.0);
        for (i, fit) in s.fits().iter().enumerate() {
            assert!(fit.max_relative_error < 1e-10, "{fit:?}");
            assert!(fit.schedule_max_relative_error < 1e-9, "{fit:?}");
            if i != 1 {
                assert_eq!(fit.start, ScheduleStart::Similarity, "{fit:?}");
            }
            let e = rel_err(&s.local_model(i).unwrap(), &at(speeds[i]), &f);
            assert!(e < 1e-10, "{e:e}");
        }
        [500.0, 1500.0, 2500.0]
            .iter()
            .map(|&x| rel_err(&s.at(x).unwrap(), &at(x), &f))
            .fold(0.0, f64::max)
    }

    /// With a gauge the slice makes each speed's $A_s$ an analytic but not affine function of
    /// the speed even when the truth is affine, so the schedule between the build speeds has the
    /// error of polynomial interpolation, $O(\delta^{d+1})$: measured 2.9e-7 at
    /// $\delta = 4 \cdot 10^{-3}$ and 2.4e-11 at $4 \cdot 10^{-4}$ (a factor $10^{4.1}$ for
    /// $d = 3$).
    #[test]
    fn scheduled_exact_recovery_with_gauge() {
        let (e1, e2) = (gauge_case(4e-3), gauge_case(4e-4));
        eprintln!("gauge case: {e1:.2e} at δ = 4e-3, {e2:.2e} at δ = 4e-4");
        assert!(e1 < 1e-6, "{e1:e}");
        assert!(e2 < 1e-3 * e1 || e2 < 1e-11, "{e1:e} {e2:e}");
    }

    #[test]
    fn scheduled_typed_errors() {
        let fam = Family::new(4, 1, 1, 3);
        let f = grid();
        let m0 = fam.at(0.0);
        let m1 = fam.at(1.0);
        let frd = Frd::from_model(&m0, &f).unwrap();
        let sd = |s: f64, m| SpeedData {
            speed_rpm: s,
            model: m,
            frd: &frd,
        };
        let o = ScheduleOptions::default();
        assert!(matches!(
            fit_scheduled(&[sd(0.0, &m0)], &o),
            Err(Error::InvalidArgument { name: "data", .. })
        ));
        assert!(matches!(
            fit_scheduled(&[sd(1.0, &m0), sd(1.0, &m1)], &o),
            Err(Error::InvalidArgument {
                name: "speed_rpm",
                ..
            })
        ));
        assert!(matches!(
            fit_scheduled(&[sd(2.0, &m0), sd(1.0, &m1)], &o),
            Err(Error::InvalidArgument {
                name: "speed_rpm",
                ..
            })
        ));
        assert!(matches!(
            fit_scheduled(&[sd(f64::NAN, &m0), sd(1.0, &m1)], &o),
            Err(Error::NonFinite { .. })
        ));
        let small = Family::new(3, 1, 1, 3).at(0.0);
        assert!(matches!(
            fit_scheduled(&[sd(0.0, &m0), sd(1.0, &small)], &o),
            Err(Error::DimensionMismatch { .. })
        ));
        let other_ts = StateSpace::discrete(
            m1.a().to_owned(),
            m1.b().to_owned(),
            m1.c().to_owned(),
            m1.d().to_owned(),
            2e-3,
        )
        .unwrap();
        assert!(matches!(
            fit_scheduled(&[sd(0.0, &m0), sd(1.0, &other_ts)], &o),
            Err(Error::SampleTimeMismatch { .. })
        ));
        let cont = StateSpace::continuous(
            m1.a().to_owned(),
            m1.b().to_owned(),
            m1.c().to_owned(),
            m1.d().to_owned(),
        )
        .unwrap();
        assert!(matches!(
            fit_scheduled(&[sd(0.0, &m0), sd(1.0, &cont)], &o),
            Err(Error::TimeDomain(_))
        ));
        let two = Family::new(4, 2, 1, 3).at(0.0);
        let frd2 = Frd::from_model(&two, &f).unwrap();
        let bad = [
            sd(0.0, &m0),
            SpeedData {
                speed_rpm: 1.0,
                model: &m1,
                frd: &frd2,
            },
        ];
        assert!(matches!(
            fit_scheduled(&bad, &o),
            Err(Error::DimensionMismatch { .. })
        ));
        let deg = ScheduleOptions {
            degree: Some(2),
            ..Default::default()
        };
        assert!(matches!(
            fit_scheduled(&[sd(0.0, &m0), sd(1.0, &m1)], &deg),
            Err(Error::InvalidArgument { name: "degree", .. })
        ));
        let narrow = ScheduleOptions {
            band_hz: Some((12.0, 13.0)),
            ..Default::default()
        };
        assert!(matches!(
            fit_scheduled(&[sd(0.0, &m0), sd(1.0, &m1)], &narrow),
            Err(Error::InvalidArgument {
                name: "band_hz",
                ..
            })
        ));
        // a non-minimal reference: a state that no input reaches
        let mut a = Mat::<f64>::zeros(4, 4);
        a[(3, 3)] = 0.5;
        for i in 0..3 {
            for j in 0..3 {
                a[(i, j)] = m0.a()[(i, j)];
            }
        }
        let mut b = m0.b().to_owned();
        b[(3, 0)] = 0.0;
        let nm = StateSpace::discrete(a, b, m0.c().to_owned(), m0.d().to_owned(), 1e-3).unwrap();
        assert!(matches!(
            fit_scheduled(&[sd(0.0, &nm), sd(1.0, &nm)], &o),
            Err(Error::Numerical { .. })
        ));
        // the schedule refuses to extrapolate
        let ok = fit_scheduled(&[sd(0.0, &m0), sd(1.0, &m0)], &o).unwrap();
        assert!(ok.at(0.5).is_ok());
        assert!(matches!(
            ok.at(1.5),
            Err(Error::InvalidArgument {
                name: "speed_rpm",
                ..
            })
        ));
        assert!(ok.at(f64::NAN).is_err());
    }
}
