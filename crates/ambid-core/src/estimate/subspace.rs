//! Subspace identification of state-space models (N4SID, MOESP, CVA) in bounded memory.
//!
//! # Model
//! The innovation form of a discrete linear system with $m$ inputs and $l$ outputs,
//! $$ x_{k+1} = A x_k + B u_k + K e_k, \qquad y_k = C x_k + D u_k + e_k, $$
//! with white innovations $e_k$ of covariance $\Lambda$. [`n4sid`] returns the deterministic part
//! $(A, B, C, D)$ as a [`StateSpace`] (inputs $u$ only); [`n4sid_detailed`] also returns $K$,
//! $\Lambda$, the noise covariances and the singular values that reveal the order.
//!
//! # Data equations
//! With $i$ block rows and $j = N - 2i + 1$ columns, $U_{a|b}$ is the block-Hankel matrix whose
//! column $k$ stacks $u_{k+a}, \dots, u_{k+b}$ (likewise $Y_{a|b}$); past $U_p = U_{0|i-1}$,
//! future $U_f = U_{i|2i-1}$, $W_p = [U_p; Y_p]$. Then
//! $Y_f = \Gamma_i X_f + H_i U_f + H^s_i E_f$, with the extended observability matrix
//! $\Gamma_i = [C; CA; \dots; CA^{i-1}]$ and the lower block-Toeplitz matrix $H_i$ of the Markov
//! parameters $D, CB, CAB, \dots$. The oblique projection of the future outputs along the future
//! inputs onto the past,
//! $$ \mathcal O_i = Y_f /_{U_f} W_p = \Gamma_i \hat X_i , $$
//! is the observability matrix times a (non-steady) Kalman-filter state sequence, so its column
//! space (of dimension $n$) is that of $\Gamma_i$, whatever the noise (open-loop data, $j \to
//! \infty$).
//!
//! # Algorithm
//! 1. **Data product** (module `hankel`): the LQ factorisation
//!    $[U_f; U_p; Y_p; Y_f]/\sqrt j = L Q^\top$ by a QR of the transposed block-Hankel matrix
//!    streamed in chunks, $O(N d^2)$ work and $O(d^2)$ memory with $d = 2i(m+l)$, or
//!    ([`DataProduct::Gram`]) from the Gram matrix $H H^\top$, built from lagged product sums in
//!    $O(N d (m + l))$, and its semidefinite Cholesky factor. Neither the Hankel matrices nor $Q$
//!    (nor anything $N \times N$) is formed. Every projection below is a computation on rows of
//!    $L$, because $Q$ has orthonormal columns. Each channel is first divided by its RMS (and the
//!    model scaled back at the end), so that channels in metres and amperes weigh alike.
//! 2. **Weighted SVD** $W_1 \mathcal O_i W_2 = U S V^\top$ (block rows of $L$ named
//!    $L_{21}$, $L_{22}$: $W_p$ rows against the $U_f$ and $W_p$ columns; $L_{32}$, $L_{33}$: $Y_f$
//!    rows against the $W_p$ and $Y_f$ columns):
//!    * [`Weighting::N4sid`]: $W_1 = W_2 = I$, the SVD of $L_{32} L_{22}^+ [L_{21}\;L_{22}]$;
//!    * [`Weighting::Moesp`]: $W_2 = \Pi_{U_f^\perp}$, the SVD of $L_{32}$ (PO-MOESP);
//!    * [`Weighting::Cva`]: in addition $W_1 = (L_{3\cdot} L_{3\cdot}^\top)^{-1/2}$ with
//!      $L_{3\cdot} = [L_{32}\;L_{33}]$, the covariance of $Y_f / U_f^\perp$: the singular values are
//!      the canonical correlations between future outputs and the past (given the future inputs),
//!      so they lie in $[0, 1]$.
//!
//!    The pseudo-inverse $L_{22}^+$ drops singular values below $10^{-10}$ of the largest (noise-free
//!    data make $W_p$ rank deficient); the CVA weight floors the eigenvalues of
//!    $L_{3\cdot}L_{3\cdot}^\top$ at $10^{-12}$ of the largest.
//! 3. **Order**: the given one, or the $n \le n_{\max}$ with the largest gap
//!    $\log(\sigma_n / \sigma_{n+1})$.
//! 4. $\Gamma_i = W_1^{-1} U_1 S_1^{1/2}$; $C$ is its first block row and $A$ solves the shift
//!    equation $\underline{\Gamma_i} A = \overline{\Gamma_i}$ (without the last, first block row) by
//!    least squares. No stability is forced: an unstable system gives an unstable $A$.
//! 5. **B and D** (the "robust" combined algorithm of Van Overschee and De Moor): with
//!    $Z_i = Y_f / [W_p; U_f]$ and $Z_{i+1} = Y_f^- / [W_p^+; U_f^-]$ (one block row moved from the
//!    future to the past; both are leading columns of $L$, so no inverse is needed),
//!    $$ \begin{bmatrix} \underline{\Gamma_i}^+ Z_{i+1} \\ Y_{i|i} \end{bmatrix} =
//!    \begin{bmatrix} A \\ C \end{bmatrix} \Gamma_i^+ Z_i + \mathcal K(B, D)\, U_f +
//!    \begin{bmatrix} \rho_w \\ \rho_v \end{bmatrix}, $$
//!    $$ \mathcal K = \begin{bmatrix} [B \;\; \underline{\Gamma_i}^+ H_{i-1}] - A \Gamma_i^+ H_i \\
//!    [D \;\; 0] - C \Gamma_i^+ H_i \end{bmatrix}, $$
//!    which is linear in $(B, D)$ once $A$, $C$ are known. $\mathcal K$ is fitted by least squares on
//!    $U_f$, then $(B, D)$ by least squares on $\mathrm{vec}\,\mathcal K$. This is unbiased for any
//!    $i$ in open loop (the state-sequence regression of the simpler algorithms is not, with
//!    coloured noise). With [`BdMethod::Simulation`] (the default for a stable $A$) these $(B, D)$
//!    are then replaced by the minimisers of the simulation error
//!    $\sum_k \lVert y_k - C A^k x_0 - \sum_{t<k} C A^{k-1-t} B u_t - D u_k\rVert^2$ over
//!    $(x_0, B, D)$, a linear least-squares problem whose $n(m+1) + lm$ regressors are generated
//!    recursively and factorised on the fly (streaming QR), so the record is never copied.
//! 6. **Kalman gain**: the residuals give $\begin{bmatrix} Q & S \\ S^\top & R \end{bmatrix} =
//!    \frac1j [\rho_w; \rho_v][\rho_w; \rho_v]^\top$; the filter Riccati equation
//!    ([`linalg::dare`] on $(A^\top, C^\top, Q, R, S)$) gives $P$ and
//!    $K = (A P C^\top + S)(C P C^\top + R)^{-1}$. If $R$ is numerically zero (noise-free data:
//!    its smallest eigenvalue below $10^{-20}$ in RMS-scaled units) or the equation has no
//!    stabilising solution, $K$ is `None`.
//! 7. **Fit statistics**: one pass of the one-step-ahead predictor
//!    $\hat x_{k+1} = A \hat x_k + B u_k + K \varepsilon_k$, $\varepsilon_k = y_k - C\hat x_k - D u_k$
//!    from $\hat x_0 = 0$ (the simulation when $K$ is `None`) gives the loss and $\hat\Lambda$.
//!
//! # Choices and their reasons
//! * **Block rows** $i$ (past and future horizon). The horizon must span the slow dynamics: with
//!   poles at small angles (strongly oversampled data) the extended observability matrix over a
//!   short horizon cannot tell the modes apart. On the ambid twin's seed record ($T_{ry}$ from
//!   $r$ to $y$ at 20 kHz, 102 300 samples, 0.1 µm sensor noise, modes near 100, 160 and 780 Hz,
//!   i.e. pole angles 0.03–0.25 rad) the order-8 model fitted another noise realisation of the
//!   record by 71 % with $i = 30$, 72 % with $i = 40$, 95 % with $i = 80$ and 97.93 % (the
//!   truth's own fit) with $i \ge 120$; on the 8th-order test system with pole angles
//!   0.06–1.2 rad, $i = 16$ gave 70–98 %, $i = 30$ and more 99.7–99.9 % (fit to the noise-free
//!   output, three seeds). So, unless `block_rows` is given, a **ladder** of horizons is
//!   scanned: $i_0 = \max(\lceil 2 n_{\max}/l \rceil, 30)$, then $2 i_0, 4 i_0, \dots$ up to
//!   $\min(240, i_{\max})$ with $i_{\max} = \lfloor (N+1)/(2 + 20(m+l)) \rfloor$ (at least
//!   $j \ge 10 d$ columns), so the record length sets how far it goes; every rung is identified
//!   (the scan stops early only on noise-free data, where a rung is exact). The rungs are
//!   compared by the **simulation error** [`SubspaceFit::simulation_nmse`] (the output error of
//!   $(A, C)$ with the best $B$, $D$ and initial state, a by-product of step 5) when at least half
//!   of them are stable — a stable system; otherwise (an unstable system, or
//!   [`BdMethod::Projection`]) by the one-step-ahead prediction loss. The shortest rung is kept
//!   unless a longer one lowers the criterion by at least 2 %. The parameter count does not depend
//!   on $i$, so in-sample values compare fairly. The criterion matters: at 20 kHz the one-step
//!   predictor follows $y$ so closely that its loss barely tells a good deterministic model from a
//!   poor one (the former ladder, which stopped when the prediction loss fell by less than 2 %,
//!   stayed at $i = 30$ on half of the rigs of issue 16, with validation fits 12–38 points below
//!   the truth's), while the simulation error of the same rungs falls by a factor 10–100 from
//!   $i = 30$ to $i = 120$ on those rigs. The tried horizons and criterion values are returned in
//!   [`SubspaceFit::block_rows_scan`], the criterion in [`SubspaceFit::block_rows_criterion`].
//!   Evidence (`cargo run --release -p ambid --example ss_rig_sweep -- 1 40`, 40 random rigs of
//!   the twin, seed experiment, order 8, $T_{ry}$ from $r$): the scan chose $i = 120$ or 240 on
//!   every rig; the subspace model alone came within 0.08 point of the exact $T_{ry}$'s
//!   validation fit (median 0.003), and after the refinement of `ambid fit` within 0.007.
//! * **Data product**: the streaming QR is exact to rounding and costs $O(N d^2)$; the Gram route
//!   costs $O(N d (m + l) + d^3)$ and in principle loses relative amplitudes below
//!   $\approx 3\cdot10^{-6}$ (module `hankel`); in the tests the two gave the same models to
//!   $10^{-13}$, noise-free or not. [`DataProduct::Auto`] uses the QR up to $4\cdot10^9$ flops
//!   ($N = 10^5$ SISO: up to $i = 35$).
//! * **B and D** ([`BdMethod`]): the simulation regression is the default whenever $A$ is stable.
//!   With white output noise it roughly halves the FRF error of the projection estimate at
//!   $i = 10$ (Monte Carlo, 4th-order system) and is within 10 % of it with innovation noise;
//!   it cannot be used for an unstable $A$ (the regressors grow without bound).
//! * **Feedthrough** $D$: fixed at 0 by default. A sampled physical system whose output is sampled
//!   before the input acts (zero-order hold, computation delay, anti-alias filter) has no direct
//!   term, and the AMB plant and $T_{ry}$ of the twin have none; estimating a zero $D$ only adds
//!   variance. Set `feedthrough = true` for systems with a genuine direct term.
//! * **Samples**: at least $2i - 1 + 2d$ so that $j \ge 2d$; good estimates need $j \gg d$.
//!
//! # Requirements on the data
//! Open-loop data (the excitation is uncorrelated with the noise: in closed loop identify from the
//! reference $r$, e.g. $T_{ry}$), an input that is persistently exciting of order $2i$ (white noise,
//! PRBS, multisines with enough lines), and detrended channels (no mean is removed here; see
//! [`crate::data`]). The system may be unstable.
//!
//! # Complexity
//! $O(N d^2)$ for the QR data product (e.g. $N = 10^5$, $d = 120$: $\approx 3 \cdot 10^9$
//! flops) or $O(N d (m + l))$ for the Gram one, $O(d^3)$ for the rest, $O(N (m + 1) l n^2)$ for the
//! simulation regression and $O(N n^2)$ for the predictor pass, per rung of the horizon ladder.
//! Memory $O(d^2 + d\,c)$ with QR chunks of $c = \max(8d, 256)$ rows, independent of $N$
//! (column-major data are read in place; other layouts are first copied, $O(N(m + l))$).
//!
//! # Reference
//! P. Van Overschee, B. De Moor, *Subspace Identification for Linear Systems: Theory,
//! Implementation, Applications*, Kluwer, 1996 (chapter 4: the combined deterministic-stochastic
//! algorithms, the weightings, the robust algorithm); M. Verhaegen, V. Verdult, *Filtering and
//! System Identification*, Cambridge, 2007 (PO-MOESP); W. E. Larimore, "Canonical variate analysis
//! in identification, filtering and adaptive control", *CDC* 1990.
//!
//! # Example
//! ```
//! use ambid_core::estimate::subspace::{n4sid_detailed, SubspaceOptions};
//! use ambid_core::lti::StateSpace;
//! use ambid_core::signal::{Distribution, NoiseSpec};
//! use faer::{mat, MatRef};
//! // a lightly damped mode, poles 0.95·e^{±0.5j}, sampled at 1 kHz
//! let (re, im) = (0.95 * 0.5f64.cos(), 0.95 * 0.5f64.sin());
//! let truth = StateSpace::discrete(mat![[re, im], [-im, re]], mat![[1.0], [0.0]],
//!                                  mat![[0.0, 1.0]], mat![[0.0]], 1e-3).unwrap();
//! let u = NoiseSpec { distribution: Distribution::Gaussian, rms: 1.0, n_samples: 2000,
//!                     band_hz: None, seed: 1 }.generate(1e-3).unwrap().values;
//! let y = truth.simulate_siso(&u, None).unwrap();
//! let opts = SubspaceOptions::new(1e-3); // order from the singular values
//! let fit = n4sid_detailed(MatRef::from_column_major_slice(&y, y.len(), 1),
//!                          MatRef::from_column_major_slice(&u, u.len(), 1), &opts).unwrap();
//! assert_eq!(fit.order, 2);
//! let p = fit.fitted.model.poles().unwrap();
//! assert!(p.iter().all(|z| (z.norm() - 0.95).abs() < 1e-8 && (z.im.abs() - im).abs() < 1e-8));
//! ```

pub(crate) mod hankel;

use super::qr_stream::StreamingQr;
use super::{channel_rms, check_samples};
use crate::error::{Error, Result};
use crate::estimate::Fitted;
use crate::linalg;
use crate::lti::StateSpace;
use faer::{Mat, MatRef, Side};
use hankel::Layout;
use rayon::prelude::*;

/// Weighting of the oblique projection before the SVD (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Weighting {
    /// $W_1 = W_2 = I$ (Van Overschee and De Moor's N4SID).
    N4sid,
    /// $W_2 = \Pi_{U_f^\perp}$ (PO-MOESP, Verhaegen).
    Moesp,
    /// Canonical variate analysis (Larimore): singular values are canonical correlations. The
    /// default, because its singular values (in $[0, 1]$) make the order selection independent of
    /// the signal levels; on the SISO and 2×2 test systems the three weightings gave the same
    /// models to within a few per cent.
    #[default]
    Cva,
}

/// How $B$ and $D$ are estimated once $A$ and $C$ are known (step 5 of the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BdMethod {
    /// [`Simulation`](Self::Simulation) when the estimated $A$ is stable, otherwise
    /// [`Projection`](Self::Projection). The default.
    #[default]
    Auto,
    /// The subspace relation on $Z_i$, $Z_{i+1}$ (Van Overschee and De Moor's robust algorithm);
    /// valid for unstable systems.
    Projection,
    /// Least squares of the simulation error over the whole record, with the initial state as
    /// extra unknowns (SLICOT's `IB01CD` approach); needs a stable $A$.
    Simulation,
}

/// How the triangular factor $L$ of the block-Hankel data is computed (step 1 of the module
/// docs). Both need memory independent of $N$.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DataProduct {
    /// [`Qr`](Self::Qr) when it costs at most $2 j d^2 \le 4 \cdot 10^9$ flops (a few tenths of a
    /// second), otherwise [`Gram`](Self::Gram). The default.
    #[default]
    Auto,
    /// Streaming Householder QR of the Hankel data: backward stable, $O(N d^2)$.
    Qr,
    /// Gram matrix by lagged product sums and a semidefinite Cholesky factorisation:
    /// $O(N d (m + l) + d^3)$, but relative amplitudes below $\approx 3 \cdot 10^{-6}$ are lost
    /// (the squared condition number).
    Gram,
}

/// Options of [`n4sid`].
#[derive(Debug, Clone, PartialEq)]
pub struct SubspaceOptions {
    /// Sample time of the data and the model \[s\].
    pub ts: f64,
    /// Model order; `None` chooses it from the singular values (largest gap up to `max_order`).
    pub order: Option<usize>,
    /// Largest order considered when `order` is `None`; default 10.
    pub max_order: usize,
    /// Block rows $i$ (past and future horizon); `None` chooses them from the data by the
    /// horizon ladder of the module docs.
    pub block_rows: Option<usize>,
    /// Weighting of the SVD; default [`Weighting::Cva`].
    pub weighting: Weighting,
    /// Estimate the feedthrough $D$ (`true`) or fix it at 0 (`false`, the default).
    pub feedthrough: bool,
    /// Estimator of $B$ and $D$; default [`BdMethod::Auto`].
    pub bd_method: BdMethod,
    /// Computation of the data product; default [`DataProduct::Auto`].
    pub data_product: DataProduct,
    /// Criterion of the automatic horizon (when `block_rows` is `None`): `None` (the default)
    /// decides from the rungs' stability as in the module docs; `Some(c)` forces `c`
    /// ([`HorizonCriterion::Prediction`] reproduces the choice of the former ladder on data
    /// where the prediction loss stops falling).
    pub horizon_criterion: Option<HorizonCriterion>,
}

impl SubspaceOptions {
    /// Defaults for data sampled every `ts` seconds: automatic order up to 10, automatic block
    /// rows, CVA weighting, $D = 0$.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::subspace::{SubspaceOptions, Weighting};
    /// let o = SubspaceOptions { order: Some(8), weighting: Weighting::Moesp,
    ///                           ..SubspaceOptions::new(5e-5) };
    /// assert!(o.validate().is_ok());
    /// assert!(SubspaceOptions { order: Some(0), ..o }.validate().is_err());
    /// ```
    pub fn new(ts: f64) -> Self {
        Self {
            ts,
            order: None,
            max_order: 10,
            block_rows: None,
            weighting: Weighting::default(),
            feedthrough: false,
            bd_method: BdMethod::default(),
            data_product: DataProduct::default(),
            horizon_criterion: None,
        }
    }

    /// Checks the settings on their own: `ts` finite and $> 0$, `order` (if given) and `max_order`
    /// $\ge 1$, `block_rows` (if given) $\ge 2$. What depends on the data is checked by [`n4sid`].
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the offending field.
    pub fn validate(&self) -> Result<()> {
        crate::signal::check_ts(self.ts)?;
        if self.order == Some(0) {
            return Err(Error::invalid(
                "order",
                "the model order must be at least 1; leave it unset (`ambid fit`: omit --order) to choose it from the singular values",
            ));
        }
        if self.max_order == 0 {
            return Err(Error::invalid(
                "max_order",
                "the largest order searched must be at least 1",
            ));
        }
        if let Some(i) = self.block_rows {
            if i < 2 {
                return Err(Error::invalid(
                    "block_rows",
                    format!("at least 2 block rows are needed (past and future horizon), got {i}; leave them unset (`ambid fit`: omit --block-rows) for the automatic horizon"),
                ));
            }
        }
        Ok(())
    }
}

/// Everything [`n4sid_detailed`] estimates.
#[derive(Debug, Clone)]
pub struct SubspaceFit {
    /// The deterministic model $(A, B, C, D)$ from $u$ to $y$ with its fit statistics.
    /// `params` holds $\mathrm{vec}\,A, \mathrm{vec}\,B, \mathrm{vec}\,C$ and, when the
    /// feedthrough is estimated, $\mathrm{vec}\,D$ (column-major each); `covariance` is `None`;
    /// `loss` is $\frac1N \sum_k \varepsilon_k^\top \varepsilon_k$ of the one-step-ahead
    /// prediction errors (the trace of $\hat\Lambda$); `noise_variance` is the loss times
    /// $N/(N - n_\theta)$ with $n_\theta = n(m + 2l) + lm_D$ identifiable parameters
    /// ($n(m + l) + lm_D$ without $K$; $m_D = m$ when $D$ is estimated, else 0).
    pub fitted: Fitted<StateSpace>,
    /// Kalman gain $K$ ($n \times l$) of the innovation form; `None` for noise-free data or when the
    /// Riccati equation has no stabilising solution.
    pub kalman_gain: Option<Mat<f64>>,
    /// Sample covariance $\hat\Lambda$ ($l \times l$) of the one-step-ahead prediction errors on the
    /// estimation data.
    pub innovation_covariance: Mat<f64>,
    /// $\begin{bmatrix} Q & S \\ S^\top & R \end{bmatrix}$ ($(n + l) \times (n + l)$): covariance of the
    /// process and measurement noise of $x_{k+1} = Ax_k + Bu_k + w_k$, $y_k = Cx_k + Du_k + v_k$,
    /// from the residuals of step 6.
    pub noise_covariance: Mat<f64>,
    /// Singular values of the weighted projection, largest first (of the RMS-scaled data).
    pub singular_values: Vec<f64>,
    /// Chosen order $n$.
    pub order: usize,
    /// Block rows $i$ used.
    pub block_rows: usize,
    /// How the data product was computed ([`DataProduct::Qr`] or [`DataProduct::Gram`]).
    pub data_product: DataProduct,
    /// The horizons tried by the automatic choice of block rows with the value of
    /// [`block_rows_criterion`](Self::block_rows_criterion) for each (empty when `block_rows` was
    /// given).
    pub block_rows_scan: Vec<(usize, f64)>,
    /// What the automatic horizon minimised (`None` when `block_rows` was given).
    pub block_rows_criterion: Option<HorizonCriterion>,
    /// Normalised simulation error of the model:
    /// $\frac1N \sum_k \sum_o (y_{o,k} - \hat y_{o,k})^2 / s_o^2$ with $\hat y$ simulated from the
    /// best initial state and $s_o$ the RMS of output $o$ (for one output and zero-mean data,
    /// $(1 - \text{fit}/100)^2$ up to the initial state's effect). Available when $B$ and $D$
    /// came from the simulation regression (a stable $A$ and [`BdMethod::Auto`] or
    /// [`BdMethod::Simulation`]), otherwise `None`.
    pub simulation_nmse: Option<f64>,
}

/// The criterion the automatic horizon minimises over the ladder of block rows (module docs,
/// "Choices and their reasons").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum HorizonCriterion {
    /// [`SubspaceFit::simulation_nmse`]: the deterministic model's output error; used when at
    /// least half of the horizons tried give a stable model (whose $B$, $D$ came from the
    /// simulation regression).
    Simulation,
    /// The one-step-ahead prediction loss relative to the output power; used otherwise (an
    /// unstable system, or [`BdMethod::Projection`]).
    Prediction,
}

/// Identifies a state-space model from `y` ($N \times l$) and `u` ($N \times m$), one row per
/// sample: [`n4sid_detailed`] without the details.
///
/// # Errors
/// As [`n4sid_detailed`].
///
/// # Example
/// ```
/// use ambid_core::estimate::subspace::{n4sid, SubspaceOptions};
/// use faer::Mat;
/// // y_k = 0.5 y_{k-1} + u_{k-1}
/// let u = Mat::from_fn(400, 1, |k, _| ((k * 7919) % 97) as f64 / 48.0 - 1.0);
/// let mut y = Mat::<f64>::zeros(400, 1);
/// for k in 1..400 { y[(k, 0)] = 0.5 * y[(k - 1, 0)] + u[(k - 1, 0)]; }
/// let opts = SubspaceOptions { order: Some(1), block_rows: Some(4), ..SubspaceOptions::new(0.01) };
/// let g = n4sid(y.as_ref(), u.as_ref(), &opts).unwrap().model;
/// assert!((g.a()[(0, 0)] - 0.5).abs() < 1e-9);
/// ```
pub fn n4sid(
    y: MatRef<'_, f64>,
    u: MatRef<'_, f64>,
    opts: &SubspaceOptions,
) -> Result<Fitted<StateSpace>> {
    Ok(n4sid_detailed(y, u, opts)?.fitted)
}

/// The front door on an [`crate::data::IoData`]: [`n4sid`] with $Y$ and $U$ the output and input
/// channels (roles, in axis order) of a single-experiment record (MIMO allowed).
///
/// # Errors
/// [`Error::InvalidArgument`] for several experiments (not joined yet), a missing role or a
/// non-finite sample; the errors of [`n4sid`].
pub fn n4sid_iodata(
    data: &crate::data::IoData,
    opts: &SubspaceOptions,
) -> Result<Fitted<StateSpace>> {
    use crate::data::Role;
    data.require_single_experiment("n4sid")?;
    data.require_finite(&[Role::Output, Role::Input])?;
    let (y, u) = (data.y_matrix(0)?, data.u_matrix(0)?);
    n4sid(y.as_ref(), u.as_ref(), opts)
}

/// Identifies the innovation model $x_{k+1} = Ax_k + Bu_k + Ke_k$, $y_k = Cx_k + Du_k + e_k$ from
/// `y` ($N \times l$) and `u` ($N \times m$), one row per sample, by the algorithm of the module
/// docs.
///
/// # Errors
/// * [`Error::InvalidArgument`]: invalid options; no input or output channel; fewer than
///   $2i - 1 + 4i(m + l)$ samples; an order with $(i - 1)\,l < n$ (more states than the block
///   rows can observe); a channel that is identically zero.
/// * [`Error::DimensionMismatch`]: `y` and `u` of different lengths.
/// * [`Error::NonFinite`]: a NaN or infinite sample (`index` is the sample number).
/// * [`Error::Numerical`]: an input that is not persistently exciting, or a degenerate projection.
/// * [`Error::Unstable`]: [`BdMethod::Simulation`] requested for an estimated $A$ that is not
///   stable.
///
/// # Example
/// See the module docs.
pub fn n4sid_detailed(
    y: MatRef<'_, f64>,
    u: MatRef<'_, f64>,
    opts: &SubspaceOptions,
) -> Result<SubspaceFit> {
    opts.validate()?;
    let (nn, l, m) = (y.nrows(), y.ncols(), u.ncols());
    if u.nrows() != nn {
        return Err(Error::DimensionMismatch {
            context: "n4sid: samples of y and u",
            expected: nn.to_string(),
            got: u.nrows().to_string(),
        });
    }
    if l == 0 || m == 0 {
        return Err(Error::invalid(
            if l == 0 { "y" } else { "u" },
            "n4sid needs at least one output and one input column (time-series models without an input are not supported)",
        ));
    }
    check_samples("y", y)?;
    check_samples("u", u)?;
    let sy = channel_rms("y", y)?;
    let su = channel_rms("u", u)?;
    let n_max = opts.order.unwrap_or(opts.max_order);
    if let Some(i) = opts.block_rows {
        return identify_with_rows(y, u, opts, i, &sy, &su);
    }
    // the horizon ladder (module docs, "Choices and their reasons")
    let i0 = (2 * n_max).div_ceil(l).max(MIN_AUTO_BLOCK_ROWS);
    let cap = ((nn + 1) / (2 + 20 * (m + l))).min(MAX_AUTO_BLOCK_ROWS);
    let power: f64 = sy.iter().map(|s| s * s).sum();
    let exact = |f: &SubspaceFit| {
        f.simulation_nmse.is_some_and(|e| e <= 1e-20) || f.fitted.loss <= 1e-20 * power
    };
    // the rungs i0, 2 i0, 4 i0, … ≤ cap are independent jobs, identified side by side; the
    // ladder then reads them in order as a sequential scan would: it stops after the first
    // exact rung and before the first failing one past i0 (a failing i0 is the error)
    let mut horizons = vec![i0];
    while let Some(&i) = horizons.last().filter(|&&i| 2 * i <= cap) {
        horizons.push(2 * i);
    }
    // (longest horizon first: the costliest rung starts at once, the short ones share the other
    // thread)
    let mut fits: Vec<Result<SubspaceFit>> = horizons
        .par_iter()
        .rev()
        .map(|&i| identify_with_rows(y, u, opts, i, &sy, &su))
        .collect();
    fits.reverse();
    let mut rungs: Vec<SubspaceFit> = Vec::with_capacity(fits.len());
    for fit in fits {
        match fit {
            Ok(f) => {
                let stop = exact(&f);
                rungs.push(f);
                if stop {
                    break;
                }
            }
            Err(e) if rungs.is_empty() => return Err(e),
            Err(_) => break,
        }
    }
    // a stable system: most rungs stable (and simulated); then their output error decides
    let simulated = rungs.iter().filter(|f| f.simulation_nmse.is_some()).count();
    let criterion = match opts.horizon_criterion {
        Some(c) => c,
        None if 2 * simulated >= rungs.len() => HorizonCriterion::Simulation,
        None => HorizonCriterion::Prediction,
    };
    let value = |f: &SubspaceFit| match criterion {
        HorizonCriterion::Simulation => f.simulation_nmse.unwrap_or(f64::INFINITY),
        HorizonCriterion::Prediction => f.fitted.loss / power,
    };
    let scan: Vec<(usize, f64)> = rungs.iter().map(|f| (f.block_rows, value(f))).collect();
    // the shortest horizon unless a longer one lowers the criterion by LADDER_GAIN
    let mut best = 0;
    for (k, &(_, v)) in scan.iter().enumerate().skip(1) {
        if v < (1.0 - LADDER_GAIN) * scan[best].1 {
            best = k;
        }
    }
    let mut best = rungs.swap_remove(best);
    best.block_rows_scan = scan;
    best.block_rows_criterion = Some(criterion);
    Ok(best)
}

/// Smallest horizon of the automatic ladder.
const MIN_AUTO_BLOCK_ROWS: usize = 30;
/// Largest horizon of the automatic ladder.
const MAX_AUTO_BLOCK_ROWS: usize = 240;
/// Relative decrease of the criterion that makes a longer horizon preferred.
const LADDER_GAIN: f64 = 0.02;

/// Steps 1–7 for a given number of block rows.
fn identify_with_rows(
    y: MatRef<'_, f64>,
    u: MatRef<'_, f64>,
    opts: &SubspaceOptions,
    i: usize,
    sy: &[f64],
    su: &[f64],
) -> Result<SubspaceFit> {
    let (nn, l, m) = (y.nrows(), y.ncols(), u.ncols());
    let n_max = opts.order.unwrap_or(opts.max_order);
    if (i - 1) * l < n_max {
        let what = if opts.order.is_some() {
            "order"
        } else {
            "max_order"
        };
        return Err(Error::invalid(
            what,
            format!(
                "{what} {n_max} exceeds what {i} block rows of {l} output(s) can observe ((i − 1)·l = {}); raise block_rows to at least {} or lower the order",
                (i - 1) * l,
                n_max.div_ceil(l) + 1
            ),
        ));
    }
    let lay = Layout { i, m, l };
    let d = lay.dim();
    let need = 2 * i - 1 + 2 * d;
    if nn < need {
        return Err(Error::invalid(
            "y",
            format!(
                "too few samples: {nn}, but {i} block rows with {m} input(s) and {l} output(s) need at least {need} (2i − 1 + 4i(m + l)); record longer or lower block_rows / the order"
            ),
        ));
    }
    let j = nn + 1 - 2 * i;
    let product = match opts.data_product {
        DataProduct::Auto if 2.0 * j as f64 * (d * d) as f64 <= 4e9 => DataProduct::Qr,
        DataProduct::Auto => DataProduct::Gram,
        p => p,
    };
    let lq = match product {
        DataProduct::Gram => hankel::gram_factor(y, u, lay, sy, su)?,
        _ => hankel::lq_factor(y, u, lay, sy, su)?,
    };
    let mut core = identify_scaled(lq.as_ref(), lay, opts)?;
    let mut simulation_nmse = None;
    let stable = || -> Result<bool> {
        Ok(linalg::eigenvalues(core.a.as_ref())?
            .iter()
            .all(|z| z.norm() < 1.0))
    };
    match opts.bd_method {
        BdMethod::Projection => {}
        BdMethod::Auto => {
            if stable()? {
                // a rank-deficient regression keeps the projection estimate
                if let Ok((b, d, e)) = bd_by_simulation(&core, y, u, sy, su, opts.feedthrough) {
                    core.b = b;
                    core.d = d;
                    simulation_nmse = Some(e);
                }
            }
        }
        BdMethod::Simulation => {
            if !stable()? {
                return Err(Error::Unstable {
                    context: "n4sid (BdMethod::Simulation)",
                    reason: "the estimated A has a pole on or outside the unit circle, so the simulation regression for B and D diverges; use BdMethod::Projection or Auto".into(),
                });
            }
            let (b, d, e) = bd_by_simulation(&core, y, u, sy, su, opts.feedthrough)?;
            core.b = b;
            core.d = d;
            simulation_nmse = Some(e);
        }
    }
    let mut fit = finish(core, y, u, (sy, su), opts, (i, product))?;
    fit.simulation_nmse = simulation_nmse;
    Ok(fit)
}

/// The model in RMS-scaled units with what step 6 estimates.
struct ScaledModel {
    a: Mat<f64>,
    b: Mat<f64>,
    c: Mat<f64>,
    d: Mat<f64>,
    k: Option<Mat<f64>>,
    sigma: Mat<f64>,
    singular_values: Vec<f64>,
}

/// Steps 2–6 on the LQ factor of the scaled data.
fn identify_scaled(
    lq: MatRef<'_, f64>,
    lay: Layout,
    opts: &SubspaceOptions,
) -> Result<ScaledModel> {
    let Layout { i, m, l } = lay;
    let d = lay.dim();
    let (im, il, p) = (i * m, i * l, i * (m + l));
    let wp = im; // first column/row of W_p = [U_p; Y_p]
    let yf = im + p; // first row of Y_f (= Y_{i|i})
    let l32 = lq.submatrix(yf, wp, il, p);

    // step 2: weighted SVD
    let (sv, u1, w1_inv) = match opts.weighting {
        Weighting::N4sid => {
            let l22 = lq.submatrix(wp, wp, p, p);
            let l21 = lq.submatrix(wp, 0, p, im);
            let x = times_pinv(l32, l22, 1e-10)?;
            let mut o = Mat::<f64>::zeros(il, im + p);
            o.as_mut().subcols_mut(0, im).copy_from(&x * l21);
            o.as_mut().subcols_mut(im, p).copy_from(&x * l22);
            let (s, uu) = left_svd(o.as_ref())?;
            (s, uu, None)
        }
        Weighting::Moesp => {
            let (s, uu) = left_svd(l32)?;
            (s, uu, None)
        }
        Weighting::Cva => {
            let l3 = lq.submatrix(yf, wp, il, d - wp);
            let cov = l3 * l3.transpose();
            let (w, w_inv) = inv_sqrt_psd(cov.as_ref(), 1e-12)?;
            let (s, uu) = left_svd((&w * l32).as_ref())?;
            (s, uu, Some(w_inv))
        }
    };

    // step 3: order
    let n = match opts.order {
        Some(n) => n,
        None => select_order(&sv, opts.max_order),
    };
    if sv.len() < n || sv[n - 1] <= 0.0 {
        return Err(Error::numerical(
            "n4sid",
            format!("the weighted projection has rank below the order {n}; the input does not excite {n} states, lower the order"),
        ));
    }

    // step 4: Γ, A, C
    let mut gamma = Mat::from_fn(il, n, |r, c| u1[(r, c)] * sv[c].sqrt());
    if let Some(wi) = &w1_inv {
        gamma = wi * &gamma;
    }
    let g_up = gamma.subrows(0, il - l);
    let g_dn = gamma.subrows(l, il - l);
    let a = linalg::lstsq(g_up, g_dn).map_err(|_| rank_error(n))?;
    let c = gamma.subrows(0, l).to_owned();
    let gp = linalg::lstsq(gamma.as_ref(), Mat::<f64>::identity(il, il).as_ref())
        .map_err(|_| rank_error(n))?;
    let gup_p = linalg::lstsq(g_up, Mat::<f64>::identity(il - l, il - l).as_ref())
        .map_err(|_| rank_error(n))?;

    // step 5: T = [Γ̲⁺ Z_{i+1}; Y_{i|i}] − [A; C] Γ⁺ Z_i in coordinates of the rows of Qᵀ
    let zi = Mat::from_fn(
        il,
        d,
        |r, col| if col < yf { lq[(yf + r, col)] } else { 0.0 },
    );
    let zi1 = Mat::from_fn(il - l, d, |r, col| {
        if col < yf + l {
            lq[(yf + l + r, col)]
        } else {
            0.0
        }
    });
    let gz = &gp * &zi;
    let top = &gup_p * &zi1 - &a * &gz;
    let bot = lq.subrows(yf, l) - &c * &gz;
    let mut t = Mat::<f64>::zeros(n + l, d);
    t.as_mut().subrows_mut(0, n).copy_from(&top);
    t.as_mut().subrows_mut(n, l).copy_from(&bot);
    // K̂ L11 = T(:, U_f columns): least squares of T on the row space of U_f
    let l11 = lq.submatrix(0, 0, im, im);
    let t_uf = t.subcols(0, im).to_owned();
    let k_free = linalg::solve(l11.transpose(), t_uf.transpose())
        .map_err(|_| {
            Error::numerical(
                "n4sid",
                format!("the future inputs are linearly dependent: the input is not persistently exciting of order {} (use white noise, a PRBS or a multisine with more lines, or fewer block rows)", 2 * i),
            )
        })?
        .transpose()
        .to_owned();
    let markov = MarkovMap::new(a.as_ref(), c.as_ref(), gp.as_ref(), gup_p.as_ref(), i);
    let n_b = n * m;
    let n_theta = n_b + if opts.feedthrough { l * m } else { 0 };
    let mut mm = Mat::<f64>::zeros((n + l) * im, n_theta);
    for q in 0..n_theta {
        let mut bq = Mat::<f64>::zeros(n, m);
        let mut dq = Mat::<f64>::zeros(l, m);
        if q < n_b {
            bq[(q % n, q / n)] = 1.0;
        } else {
            let r = q - n_b;
            dq[(r % l, r / l)] = 1.0;
        }
        let kq = markov.k_of(bq.as_ref(), dq.as_ref());
        for col in 0..im {
            for row in 0..n + l {
                mm[(col * (n + l) + row, q)] = kq[(row, col)];
            }
        }
    }
    let rhs = Mat::from_fn((n + l) * im, 1, |r, _| k_free[(r % (n + l), r / (n + l))]);
    let theta = linalg::lstsq(mm.as_ref(), rhs.as_ref()).map_err(|_| {
        Error::numerical(
            "n4sid",
            "B and D are not determined by the data (singular least-squares problem); check that the input excites the system",
        )
    })?;
    let b = Mat::from_fn(n, m, |r, col| theta[(col * n + r, 0)]);
    let dmat = if opts.feedthrough {
        Mat::from_fn(l, m, |r, col| theta[(n_b + col * l + r, 0)])
    } else {
        Mat::zeros(l, m)
    };
    let k_fit = markov.k_of(b.as_ref(), dmat.as_ref());
    // residuals ρ = T − K(B, D) [L11 0]
    let mut rho = t;
    let kl = &k_fit * l11;
    for col in 0..im {
        for row in 0..n + l {
            rho[(row, col)] -= kl[(row, col)];
        }
    }
    let sigma = symmetric(&(&rho * rho.transpose()));

    // step 6: Kalman gain from the filter Riccati equation
    let k = kalman_gain(a.as_ref(), c.as_ref(), sigma.as_ref(), n, l);
    Ok(ScaledModel {
        a,
        b,
        c,
        d: dmat,
        k,
        sigma,
        singular_values: sv,
    })
}

/// $B$ and $D$ (RMS-scaled units) minimising the simulation error
/// $\sum_k \lVert y_k - C A^k x_0 - \sum_{t<k} C A^{k-1-t} B u_t - D u_k \rVert^2$ for the given
/// $A$, $C$, with $x_0$ a nuisance unknown. The regressors follow from
/// $\Phi_{k+1} = \Phi_k A$, $\Phi_0 = C$ (for $x_0$) and $Z^{(c)}_{k+1} = Z^{(c)}_k A + u_{c,k} C$,
/// $Z^{(c)}_0 = 0$ (the regressor of column $c$ of $B$), $O(N (m + 1) l n^2)$ work; the rows go
/// through a [`StreamingQr`], so memory does not grow with $N$.
fn bd_by_simulation(
    core: &ScaledModel,
    y: MatRef<'_, f64>,
    u: MatRef<'_, f64>,
    sy: &[f64],
    su: &[f64],
    feedthrough: bool,
) -> Result<(Mat<f64>, Mat<f64>, f64)> {
    let (n, l, m, nn) = (core.a.nrows(), y.ncols(), u.ncols(), y.nrows());
    let nd = if feedthrough { l * m } else { 0 };
    let p = n + n * m + nd + 1;
    let mut qr = StreamingQr::new(p, 1024);
    // row-major copies: A (n × n), Φ and every Z^(c) (l × n)
    let a: Vec<f64> = (0..n * n).map(|k| core.a[(k / n, k % n)]).collect();
    let cm: Vec<f64> = (0..l * n).map(|k| core.c[(k / n, k % n)]).collect();
    let mut phi = cm.clone();
    let mut z = vec![0.0; m * l * n];
    let mut tmp = vec![0.0; l * n];
    let mut row = vec![0.0; p];
    let times_a = |x: &mut [f64], tmp: &mut [f64]| {
        for r in 0..l {
            for col in 0..n {
                tmp[r * n + col] = (0..n).map(|q| x[r * n + q] * a[q * n + col]).sum();
            }
        }
        x.copy_from_slice(tmp);
    };
    for k in 0..nn {
        for r in 0..l {
            row[..n].copy_from_slice(&phi[r * n..(r + 1) * n]);
            for ch in 0..m {
                let zc = &z[ch * l * n..(ch + 1) * l * n];
                row[n + ch * n..n + (ch + 1) * n].copy_from_slice(&zc[r * n..(r + 1) * n]);
            }
            if feedthrough {
                for ch in 0..m {
                    for r2 in 0..l {
                        row[n + n * m + ch * l + r2] =
                            if r2 == r { u[(k, ch)] / su[ch] } else { 0.0 };
                    }
                }
            }
            row[p - 1] = y[(k, r)] / sy[r];
            qr.push_row(&row);
        }
        times_a(&mut phi, &mut tmp);
        for ch in 0..m {
            let zc = &mut z[ch * l * n..(ch + 1) * l * n];
            times_a(zc, &mut tmp);
            let uk = u[(k, ch)] / su[ch];
            for (zv, cv) in zc.iter_mut().zip(&cm) {
                *zv += uk * cv;
            }
        }
    }
    let r = qr.finish();
    let r11 = r.submatrix(0, 0, p - 1, p - 1);
    let r12 = r.submatrix(0, p - 1, p - 1, 1);
    let theta = linalg::lstsq(r11, r12).map_err(|_| {
        Error::numerical(
            "n4sid (BdMethod::Simulation)",
            "the simulation regression for B and D is rank deficient: the input does not excite every state; use BdMethod::Projection",
        )
    })?;
    let b = Mat::from_fn(n, m, |row, col| theta[(n + col * n + row, 0)]);
    let d = if feedthrough {
        Mat::from_fn(l, m, |row, col| theta[(n + n * m + col * l + row, 0)])
    } else {
        Mat::zeros(l, m)
    };
    // the last diagonal entry of R of [X y] is the residual norm of the least-squares fit
    let rss = r[(p - 1, p - 1)].powi(2);
    Ok((b, d, rss / nn as f64))
}

fn rank_error(n: usize) -> Error {
    Error::numerical(
        "n4sid",
        format!("the estimated observability matrix is rank deficient at order {n}; lower the order or raise block_rows"),
    )
}

/// $K$ from $\Sigma = [Q, S; S^\top, R]$, or `None` (see step 6).
fn kalman_gain(
    a: MatRef<'_, f64>,
    c: MatRef<'_, f64>,
    sigma: MatRef<'_, f64>,
    n: usize,
    l: usize,
) -> Option<Mat<f64>> {
    let q = sigma.submatrix(0, 0, n, n);
    let s = sigma.submatrix(0, n, n, l);
    let r = sigma.submatrix(n, n, l, l);
    let r_min = r
        .self_adjoint_eigenvalues(Side::Lower)
        .ok()?
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    if r_min.is_nan() || r_min <= 1e-20 {
        return None;
    }
    let p = linalg::dare(a.transpose(), c.transpose(), q, r, Some(s)).ok()?;
    let apc = a * &p * c.transpose() + s;
    let cpc = c * &p * c.transpose() + r;
    let kt = linalg::solve(cpc.transpose(), apc.transpose()).ok()?;
    Some(kt.transpose().to_owned())
}

/// The linear map $(B, D) \mapsto \mathcal K$ of step 5 for fixed $A$, $C$, $\Gamma_i^+$,
/// $\underline{\Gamma_i}^+$.
struct MarkovMap<'a> {
    a: MatRef<'a, f64>,
    c: MatRef<'a, f64>,
    gp: MatRef<'a, f64>,
    gup_p: MatRef<'a, f64>,
    /// $C A^k$, $k = 0, \dots, i - 2$.
    ca: Vec<Mat<f64>>,
    i: usize,
}

impl<'a> MarkovMap<'a> {
    fn new(
        a: MatRef<'a, f64>,
        c: MatRef<'a, f64>,
        gp: MatRef<'a, f64>,
        gup_p: MatRef<'a, f64>,
        i: usize,
    ) -> Self {
        let mut ca = Vec::with_capacity(i.saturating_sub(1));
        let mut cur = c.to_owned();
        for _ in 0..i.saturating_sub(1) {
            let next = &cur * a;
            ca.push(cur);
            cur = next;
        }
        Self {
            a,
            c,
            gp,
            gup_p,
            ca,
            i,
        }
    }

    fn k_of(&self, b: MatRef<'_, f64>, d: MatRef<'_, f64>) -> Mat<f64> {
        let (n, m, l, i) = (self.a.nrows(), b.ncols(), self.c.nrows(), self.i);
        let mut h = Mat::<f64>::zeros(i * l, i * m);
        let markov: Vec<Mat<f64>> = std::iter::once(d.to_owned())
            .chain(self.ca.iter().map(|ca| ca * b))
            .collect();
        for r in 0..i {
            for cb in 0..=r {
                h.as_mut()
                    .submatrix_mut(r * l, cb * m, l, m)
                    .copy_from(&markov[r - cb]);
            }
        }
        let gh = self.gp * &h;
        let mut k = Mat::<f64>::zeros(n + l, i * m);
        let agh = self.a * &gh;
        let cgh = self.c * &gh;
        let h1 = h.submatrix(0, 0, (i - 1) * l, (i - 1) * m);
        let gh1 = self.gup_p * h1;
        for col in 0..i * m {
            for r in 0..n {
                let first = if col < m {
                    b[(r, col)]
                } else {
                    gh1[(r, col - m)]
                };
                k[(r, col)] = first - agh[(r, col)];
            }
            for r in 0..l {
                let first = if col < m { d[(r, col)] } else { 0.0 };
                k[(n + r, col)] = first - cgh[(r, col)];
            }
        }
        k
    }
}

/// Scales the model back to the units of the data, runs the predictor (step 7) and assembles the
/// result.
fn finish(
    s: ScaledModel,
    y: MatRef<'_, f64>,
    u: MatRef<'_, f64>,
    (sy, su): (&[f64], &[f64]),
    opts: &SubspaceOptions,
    (i, data_product): (usize, DataProduct),
) -> Result<SubspaceFit> {
    let n = s.a.nrows();
    let (nn, l, m) = (y.nrows(), y.ncols(), u.ncols());
    // y = S_y y_s, u_s = S_u⁻¹ u, e = S_y e_s
    let b = Mat::from_fn(n, m, |r, c| s.b[(r, c)] / su[c]);
    let c = Mat::from_fn(l, n, |r, col| s.c[(r, col)] * sy[r]);
    let d = Mat::from_fn(l, m, |r, col| s.d[(r, col)] * sy[r] / su[col]);
    let k =
        s.k.as_ref()
            .map(|k| Mat::from_fn(n, l, |r, col| k[(r, col)] / sy[col]));
    let sig_scale = |r: usize| if r < n { 1.0 } else { sy[r - n] };
    let sigma = Mat::from_fn(n + l, n + l, |r, col| {
        s.sigma[(r, col)] * sig_scale(r) * sig_scale(col)
    });
    let a = s.a;

    // step 7: one-step-ahead predictor from x = 0
    let mut x = vec![0.0; n];
    let mut xn = vec![0.0; n];
    let mut e = vec![0.0; l];
    let mut lam = Mat::<f64>::zeros(l, l);
    for kk in 0..nn {
        for r in 0..l {
            let mut v = y[(kk, r)];
            for (col, xc) in x.iter().enumerate() {
                v -= c[(r, col)] * xc;
            }
            for col in 0..m {
                v -= d[(r, col)] * u[(kk, col)];
            }
            e[r] = v;
        }
        for r in 0..l {
            for col in 0..l {
                lam[(r, col)] += e[r] * e[col];
            }
        }
        for (r, xr) in xn.iter_mut().enumerate() {
            let mut v = 0.0;
            for (col, xc) in x.iter().enumerate() {
                v += a[(r, col)] * xc;
            }
            for col in 0..m {
                v += b[(r, col)] * u[(kk, col)];
            }
            if let Some(k) = &k {
                for (col, ec) in e.iter().enumerate() {
                    v += k[(r, col)] * ec;
                }
            }
            *xr = v;
        }
        std::mem::swap(&mut x, &mut xn);
    }
    let lam = Mat::from_fn(l, l, |r, col| lam[(r, col)] / nn as f64);
    let loss = (0..l).map(|r| lam[(r, r)]).sum::<f64>();
    let n_dpar = if opts.feedthrough { l * m } else { 0 };
    let n_par = n * (m + l) + n_dpar + if k.is_some() { n * l } else { 0 };
    let noise_variance = if nn > n_par {
        loss * nn as f64 / (nn - n_par) as f64
    } else {
        loss
    };
    let mut params = Vec::with_capacity(n * n + n * m + l * n + n_dpar);
    params.extend(
        a.col_iter()
            .flat_map(|col| col.iter().copied().collect::<Vec<_>>()),
    );
    params.extend(
        b.col_iter()
            .flat_map(|col| col.iter().copied().collect::<Vec<_>>()),
    );
    params.extend(
        c.col_iter()
            .flat_map(|col| col.iter().copied().collect::<Vec<_>>()),
    );
    if opts.feedthrough {
        params.extend(
            d.col_iter()
                .flat_map(|col| col.iter().copied().collect::<Vec<_>>()),
        );
    }
    let model = StateSpace::discrete(a, b, c, d, opts.ts)?;
    Ok(SubspaceFit {
        fitted: Fitted {
            model,
            params,
            covariance: None,
            loss,
            noise_variance,
            n_samples: nn,
        },
        kalman_gain: k,
        innovation_covariance: lam,
        noise_covariance: sigma,
        singular_values: s.singular_values,
        order: n,
        block_rows: i,
        data_product,
        block_rows_scan: Vec::new(),
        block_rows_criterion: None,
        simulation_nmse: None,
    })
}

/// The order $n \in [1, n_{\max}]$ with the largest $\log(\sigma_n / \sigma_{n+1})$, singular
/// values floored at $10^{-20}\sigma_1$.
fn select_order(sv: &[f64], n_max: usize) -> usize {
    let floor = sv.first().copied().unwrap_or(0.0) * 1e-20;
    let mut best = (1, f64::NEG_INFINITY);
    for n in 1..=n_max.min(sv.len().saturating_sub(1)) {
        let gap = sv[n - 1].max(floor).ln() - sv[n].max(floor).ln();
        if gap > best.1 {
            best = (n, gap);
        }
    }
    best.0
}

/// Singular values (largest first) and left singular vectors of `x`.
fn left_svd(x: MatRef<'_, f64>) -> Result<(Vec<f64>, Mat<f64>)> {
    let svd = x
        .thin_svd()
        .map_err(|e| Error::numerical("n4sid", format!("SVD of the projection failed: {e:?}")))?;
    let s = svd.S().column_vector();
    let sv: Vec<f64> = (0..s.nrows()).map(|k| s[k]).collect();
    Ok((sv, svd.U().to_owned()))
}

/// $X A^+$ with singular values of $A$ below `rtol` times the largest dropped.
fn times_pinv(x: MatRef<'_, f64>, a: MatRef<'_, f64>, rtol: f64) -> Result<Mat<f64>> {
    let svd = a
        .thin_svd()
        .map_err(|e| Error::numerical("n4sid", format!("SVD of the past data failed: {e:?}")))?;
    let s = svd.S().column_vector();
    let smax = if s.nrows() > 0 { s[0] } else { 0.0 };
    let keep = (0..s.nrows()).filter(|&k| s[k] > rtol * smax).count();
    let v = svd.V().subcols(0, keep);
    let uu = svd.U().subcols(0, keep);
    let xv = x * v;
    let scaled = Mat::from_fn(xv.nrows(), keep, |r, c| xv[(r, c)] / s[c]);
    Ok(&scaled * uu.transpose())
}

/// $(M^{-1/2}, M^{1/2})$ of a symmetric positive semidefinite $M$, eigenvalues floored at `rtol`
/// times the largest.
fn inv_sqrt_psd(mat: MatRef<'_, f64>, rtol: f64) -> Result<(Mat<f64>, Mat<f64>)> {
    let evd = mat
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| Error::numerical("n4sid", format!("CVA weighting failed: {e:?}")))?;
    let lam = evd.S().column_vector();
    let v = evd.U();
    let n = lam.nrows();
    let lmax = (0..n).map(|k| lam[k]).fold(0.0, f64::max);
    if lmax <= 0.0 || !lmax.is_finite() {
        return Err(Error::numerical(
            "n4sid",
            "the future outputs carry no variance after removing the future inputs; CVA needs output data that are not a function of the input alone",
        ));
    }
    let fl: Vec<f64> = (0..n).map(|k| lam[k].max(rtol * lmax)).collect();
    let vi = Mat::from_fn(n, n, |r, c| v[(r, c)] / fl[c].sqrt());
    let vs = Mat::from_fn(n, n, |r, c| v[(r, c)] * fl[c].sqrt());
    Ok((&vi * v.transpose(), &vs * v.transpose()))
}

fn symmetric(m: &Mat<f64>) -> Mat<f64> {
    Mat::from_fn(m.nrows(), m.ncols(), |i, j| 0.5 * (m[(i, j)] + m[(j, i)]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_from_the_largest_gap() {
        assert_eq!(select_order(&[1.0, 0.9, 1e-3, 9e-4, 8e-4], 4), 2);
        assert_eq!(select_order(&[1.0, 0.5, 0.4, 0.3, 0.0], 4), 4);
        assert_eq!(select_order(&[1.0, 0.1, 0.09, 1e-9], 1), 1);
    }

    #[test]
    fn pinv_drops_tiny_directions() {
        let a = faer::mat![[2.0, 0.0], [0.0, 1e-14]];
        let x = faer::mat![[1.0, 1.0]];
        let got = times_pinv(x.as_ref(), a.as_ref(), 1e-10).unwrap();
        assert!((got[(0, 0)] - 0.5).abs() < 1e-15 && got[(0, 1)].abs() < 1e-15);
    }
}
