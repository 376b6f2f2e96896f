//! Levenberg–Marquardt for nonlinear least squares with Moré's diagonal scaling and trust-region
//! control of the damping, on faer.
//!
//! Minimises $V(x) = \tfrac12 \lVert r(x) \rVert^2$ for residuals $r: \mathbb R^n \to \mathbb R^m$
//! ($m \ge n$) with Jacobian $J = \partial r / \partial x$. Each iteration solves the trust-region
//! subproblem in the scaled variables $s = D p$,
//! $$ \min_p \lVert J p + r \rVert \quad\text{subject to}\quad \lVert D p \rVert \le \Delta, $$
//! whose solution is $p(\lambda)$ with $(J^\top J + \lambda D^2)\, p = -J^\top r$ for the $\lambda \ge 0$
//! that puts the step on the boundary (or $\lambda = 0$ when the Gauss–Newton step lies inside).
//! $D = \operatorname{diag}(d_j)$ holds the largest column norms of $J$ seen so far, which makes the
//! method invariant to the scaling of the parameters (a gain of $10^4$ next to a pole of $0.98$).
//!
//! # Algorithm
//! * The QR factorisation of $[J \;\, r] = Q \begin{bmatrix} R & z \\ 0 & \rho \end{bmatrix}$ gives
//!   $\lVert Jp + r \rVert^2 = \lVert Rp + z \rVert^2 + \rho^2$, so every later solve works on the
//!   $n \times n$ triangle $R$ and $z = Q^\top r$ without forming $J^\top J$.
//! * For a given $\lambda$ the step is the least-squares solution of the *scaled augmented* system
//!   $\left[\begin{smallmatrix} R D^{-1} \\ \sqrt\lambda\, I \end{smallmatrix}\right] s \approx
//!   \left[\begin{smallmatrix} -z \\ 0 \end{smallmatrix}\right]$, $p = D^{-1}s$,
//!   computed by a second (small, $2n \times n$) Householder QR with factor $S_\lambda$
//!   ($S_\lambda^\top S_\lambda = D^{-1}R^\top R D^{-1} + \lambda I$); the normal equations are never formed.
//! * $\lambda$ is found by Moré's safeguarded Newton iteration on
//!   $\varphi(\lambda) = \lVert s(\lambda) \rVert - \Delta$, with
//!   $\varphi'(\lambda) = -\lVert S_\lambda^{-\top} s \rVert^2 / \lVert s \rVert$, accepting
//!   $|\varphi| \le 0.1\Delta$; the bounds $[\lambda_l, \lambda_u]$ start from the Gauss–Newton step and
//!   from $\lVert D^{-1} J^\top r \rVert / \Delta$.
//! * The gain ratio $\varrho$ = actual / predicted relative reduction of $\lVert r \rVert^2$ steers the
//!   trust region: $\varrho < 1/4$ shrinks $\Delta$ (by a factor from a quadratic fit, at most
//!   $10\times$), $\varrho > 3/4$ (or a Gauss–Newton step) doubles $\lVert s\rVert$ as the new $\Delta$.
//!   A step is taken when $\varrho \ge 10^{-4}$.
//! * A trial point whose residuals are undefined (the problem returns `None`, e.g. an unstable
//!   predictor) or not finite is rejected like a failed step and shrinks $\Delta$ tenfold, so the
//!   iterates never leave the admissible set. When the iteration stops (other than on the
//!   gradient test), the full Gauss–Newton step from the final point is tried once: at an
//!   interior minimum it vanishes ($J^\top r = 0$), at a minimum pressed against the boundary it
//!   crosses it, which [`LmReport::ended_on_boundary`] reports (the last trial being
//!   inadmissible is used when $J$ is rank deficient or the iteration limit was reached).
//!
//! Stopping (the first that holds):
//! * [`StopReason::LossChange`]: the relative reduction of $\lVert r\rVert^2$, actual and
//!   predicted, is at most `loss_tol`;
//! * [`StopReason::StepSize`]: the trust region lets no parameter move by more than
//!   `step_tol` $= \tau$ relative to itself, $\Delta / d_j \le \tau\,(|x_j| + \tau)$ for every $j$
//!   (component-wise rather than MINPACK's $\Delta \le \tau\lVert Dx\rVert$, so that a weakly
//!   determined parameter next to strong ones, such as $C$ of data with tiny noise, is not
//!   declared converged while it can still move);
//! * [`StopReason::Gradient`]: the largest cosine between $r$ and a column of $J$ is at most
//!   `gradient_tol`, or $r = 0$;
//! * [`StopReason::Significance`] (only with `significance_tol` $\kappa > 0$): the Gauss–Newton
//!   step from the current point, whose predicted reduction of $\lVert r\rVert^2$ is
//!   $\lVert z\rVert^2$, is shorter than $\kappa$ standard errors in the metric of the
//!   covariance $\hat\sigma^2 (J^\top J)^{-1}$, $\hat\sigma^2 = \lVert r\rVert^2/(m - n)$:
//!   $\lVert z\rVert^2 \le \kappa^2\hat\sigma^2$ (tested before each step);
//! * [`StopReason::Stagnation`] (only with $\kappa > 0$): that step is shorter than
//!   [`STAGNATION_SIGMA`] standard errors and the last [`STAGNATION_WINDOW`] accepted steps
//!   lowered $\tfrac12\lVert r\rVert^2$ by less than $\kappa^2\hat\sigma^2/2$ in total;
//! * [`StopReason::Crawl`] (only with $\kappa > 0$ and a crawl window $w > 0$,
//!   [`LmOptions::with_crawl_window`]): the last $w$ accepted steps lowered
//!   $\tfrac12\lVert r\rVert^2$ by less than $\kappa^2\hat\sigma^2/2$ in total, however much the
//!   Gauss–Newton model still promises;
//! * [`StopReason::MaxIterations`]: `max_iterations` accepted steps.
//!
//! Complexity per iteration: one Jacobian, one $O(m n^2)$ QR, a few $O(n^3)$ small QRs.
//!
//! # Requirements on the problem
//! * $m \ge n$; residuals and Jacobian finite wherever the residuals are defined.
//! * $r$ continuously differentiable on the admissible set, which must be open and contain the start.
//! * The Jacobian must be the true derivative: a wrong Jacobian shows up as tiny or rejected steps.
//! * Only a local minimum is found; the start decides which.
//!
//! # Reference
//! J. J. Moré, "The Levenberg–Marquardt algorithm: implementation and theory", in *Numerical
//! Analysis*, Lecture Notes in Mathematics 630, Springer, 1978, pp. 105–116 (the scaling, the
//! $\lambda$ iteration and the trust-region update used here; also MINPACK's `lmder`).
//!
//! # Example
//! ```
//! use ambid_core::estimate::pem::lm::{minimize, LeastSquaresProblem, LmOptions, StopReason};
//! use faer::Mat;
//! // Rosenbrock as least squares: r = [10 (x1 - x0^2), 1 - x0], minimum at (1, 1).
//! struct Rosenbrock;
//! impl LeastSquaresProblem for Rosenbrock {
//!     fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
//!         Some(vec![10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]])
//!     }
//!     fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
//!         Some(faer::mat![[-20.0 * x[0], 10.0], [-1.0, 0.0]])
//!     }
//! }
//! let (x, report) = minimize(&mut Rosenbrock, &[-1.2, 1.0], &LmOptions::default()).unwrap();
//! assert!((x[0] - 1.0).abs() < 1e-10 && (x[1] - 1.0).abs() < 1e-10);
//! assert!(report.iterations < 50);
//! assert_ne!(report.reason, StopReason::MaxIterations);
//! ```

use crate::error::{Error, Result};
use faer::reborrow::ReborrowMut;
use faer::Mat;

/// A nonlinear least-squares problem $\min_x \tfrac12 \lVert r(x) \rVert^2$.
pub trait LeastSquaresProblem {
    /// Residuals $r(x)$, or `None` when $x$ is outside the admissible set (for example, a
    /// parameter vector whose predictor is unstable). The length must not change between calls.
    fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>>;
    /// Jacobian $\partial r_i / \partial x_j$ ($m \times n$) at an admissible $x$.
    fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>>;
    /// Whether to end the iteration now ([`StopReason::Abandoned`]), asked once per iteration
    /// with the loss $\tfrac12\lVert r\rVert^2$ and the Gauss–Newton step's predicted reduction
    /// of it, $\tfrac12\lVert z\rVert^2$ (e.g. a multi-start search that knows a better optimum
    /// than this start can reach). Never, by default.
    fn abandon(&mut self, _cost: f64, _predicted_reduction: f64) -> bool {
        false
    }
    /// The upper triangle $T$ ($(n + 1) \times (n + 1)$) of a QR factorisation of $[J\;r]$ at
    /// an admissible $x$, $T^\top T = [J\;r]^\top [J\;r]$, where `r` are the residuals last
    /// returned for $x$: all that a step uses of the Jacobian. By default from
    /// [`Self::jacobian`], its rows cut into parts of `part_rows` rows
    /// ([`LmOptions::with_triangle_part_rows`]). A problem whose Jacobian has structure (a
    /// variable projection, rows that see few columns) can form $T$ without the dense $J$; it
    /// must return the same Gram matrix.
    ///
    /// # Errors
    /// [`Error::Numerical`] when the Jacobian is undefined or not finite;
    /// [`Error::DimensionMismatch`] when it is not $m \times n$.
    fn triangle(&mut self, x: &[f64], r: &[f64], part_rows: usize) -> Result<Mat<f64>> {
        const CTX: &str = "levenberg_marquardt";
        let (m, n) = (r.len(), x.len());
        let jac = self.jacobian(x).ok_or_else(|| {
            Error::numerical(CTX, "the Jacobian is undefined at an admissible point")
        })?;
        if jac.nrows() != m || jac.ncols() != n {
            return Err(Error::DimensionMismatch {
                context: "levenberg_marquardt: Jacobian",
                expected: format!("{m}×{n}"),
                got: format!("{}×{}", jac.nrows(), jac.ncols()),
            });
        }
        for j in 0..n {
            let col = jac.col_as_slice(j);
            if !all_finite(col) {
                let i = col.iter().position(|v| !v.is_finite()).unwrap_or(0);
                return Err(Error::numerical(
                    CTX,
                    format!("Jacobian entry ({i}, {j}) is not finite"),
                ));
            }
        }
        Ok(triangle_of(&jac, r, part_rows))
    }
}

/// Why [`minimize`] stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StopReason {
    /// The actual and predicted relative reductions of the loss fell below `loss_tol`.
    LossChange,
    /// The trust region shrank below `step_tol` relative to the scaled parameter norm.
    StepSize,
    /// The residual is (numerically) orthogonal to every Jacobian column, or zero.
    Gradient,
    /// The Gauss–Newton step from the current point is statistically invisible: shorter than
    /// `significance_tol` standard errors in the metric of the parameters' covariance,
    /// $\lVert z\rVert^2 \le \kappa^2\,\lVert r\rVert^2/(m - n)$ (see the module docs).
    Significance,
    /// The Gauss–Newton step from the current point is shorter than [`STAGNATION_SIGMA`]
    /// standard errors, and the last [`STAGNATION_WINDOW`] accepted steps together lowered the
    /// loss by less than the significance rule's remaining improvement
    /// $\kappa^2\hat\sigma^2/2$ (with `significance_tol` $\kappa > 0$): the optimum is within
    /// half a standard error, and the trust region's progress towards it is too small to be
    /// seen in the data (a curved valley of the polynomial coefficients).
    Stagnation,
    /// The last [`LmOptions::with_crawl_window`] accepted steps together lowered the loss by
    /// less than the significance rule's $\kappa^2\hat\sigma^2/2$, while the Gauss–Newton model
    /// still promised more: the iterate moves along a nearly flat direction whose promised gain
    /// the steps do not deliver; as many steps again at that pace would gain less than the
    /// significance rule calls invisible.
    Crawl,
    /// The iteration limit was reached before any tolerance was met.
    MaxIterations,
    /// The problem asked to stop ([`LeastSquaresProblem::abandon`]) before convergence.
    Abandoned,
}

impl StopReason {
    /// Whether the stop means convergence (every reason except [`StopReason::MaxIterations`]
    /// and [`StopReason::Abandoned`]).
    pub fn converged(self) -> bool {
        !matches!(self, StopReason::MaxIterations | StopReason::Abandoned)
    }
}

/// Accepted steps over which [`StopReason::Stagnation`] measures the progress.
pub const STAGNATION_WINDOW: usize = 5;

/// Largest multiple of an accepted Gauss–Newton step the extrapolation moves to
/// ([`LmOptions::with_extrapolation`]).
const EXTRAPOLATION_MAX: f64 = 16.0;

/// [`StopReason::Stagnation`] applies only when the Gauss–Newton step from the current point is
/// shorter than this many standard errors (the optimum is known to lie that close).
pub const STAGNATION_SIGMA: f64 = 0.5;

/// Options of [`minimize`]; the setters validate their argument.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmOptions {
    max_iterations: usize,
    loss_tol: f64,
    step_tol: f64,
    gradient_tol: f64,
    significance_tol: f64,
    initial_radius: f64,
    extrapolate: bool,
    part_rows: usize,
    crawl_window: usize,
}

impl Default for LmOptions {
    /// 100 iterations, `loss_tol` 1e-12, `step_tol` 1e-10, `gradient_tol` 1e-12,
    /// `significance_tol` 0 (off: the numerical tolerances decide), initial radius factor 100.
    fn default() -> Self {
        Self {
            max_iterations: 100,
            loss_tol: 1e-12,
            step_tol: 1e-10,
            gradient_tol: 1e-12,
            significance_tol: 0.0,
            initial_radius: 100.0,
            extrapolate: false,
            part_rows: TRIANGLE_PART_ROWS,
            crawl_window: 0,
        }
    }
}

fn check_tol(name: &'static str, v: f64) -> Result<()> {
    if !(v.is_finite() && v >= 0.0) {
        return Err(Error::invalid(
            name,
            format!("a tolerance must be finite and non-negative, got {v}"),
        ));
    }
    Ok(())
}

impl LmOptions {
    /// Every tolerance 0: the iteration runs until `max_iterations` accepted steps (or until
    /// no step can be taken any more, $r = 0$ or a trust region below the smallest positive
    /// number). Meant as a reference ("what the full budget gives") for tests and studies.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for `max_iterations` 0.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::pem::lm::LmOptions;
    /// let o = LmOptions::exhaustive(100).unwrap();
    /// assert_eq!((o.loss_tol(), o.step_tol(), o.significance_tol()), (0.0, 0.0, 0.0));
    /// ```
    pub fn exhaustive(max_iterations: usize) -> Result<Self> {
        Self {
            loss_tol: 0.0,
            step_tol: 0.0,
            gradient_tol: 0.0,
            significance_tol: 0.0,
            ..Self::default()
        }
        .with_max_iterations(max_iterations)
    }
    /// Maximum number of accepted steps (at least 1).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for 0.
    pub fn with_max_iterations(mut self, n: usize) -> Result<Self> {
        if n == 0 {
            return Err(Error::invalid(
                "max_iterations",
                "at least one iteration is needed",
            ));
        }
        self.max_iterations = n;
        Ok(self)
    }
    /// Tolerance on the relative reduction of the loss (actual and predicted).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a negative or non-finite value.
    pub fn with_loss_tol(mut self, tol: f64) -> Result<Self> {
        check_tol("loss_tol", tol)?;
        self.loss_tol = tol;
        Ok(self)
    }
    /// Tolerance on the trust-region radius relative to $\lVert D x\rVert$.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a negative or non-finite value.
    pub fn with_step_tol(mut self, tol: f64) -> Result<Self> {
        check_tol("step_tol", tol)?;
        self.step_tol = tol;
        Ok(self)
    }
    /// Tolerance on the largest cosine between the residual and a Jacobian column.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a negative or non-finite value.
    pub fn with_gradient_tol(mut self, tol: f64) -> Result<Self> {
        check_tol("gradient_tol", tol)?;
        self.gradient_tol = tol;
        Ok(self)
    }
    /// Statistical stopping rule ([`StopReason::Significance`]): stop when the Gauss–Newton
    /// step from the current point is shorter than $\kappa$ = `kappa` standard errors,
    /// $\lVert z\rVert^2 \le \kappa^2 \lVert r\rVert^2/(m-n)$; 0 switches it off (the default of
    /// [`LmOptions`]; the prediction-error estimators set 0.1, see
    /// [`PemOptions`](super::PemOptions)).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a negative or non-finite value.
    pub fn with_significance_tol(mut self, kappa: f64) -> Result<Self> {
        check_tol("significance_tol", kappa)?;
        self.significance_tol = kappa;
        Ok(self)
    }
    /// Initial radius $\Delta_0 = $ `factor` $\cdot \lVert D x_0 \rVert$ (MINPACK's `factor`).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] unless `factor` is positive and finite.
    pub fn with_initial_radius(mut self, factor: f64) -> Result<Self> {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(Error::invalid(
                "initial_radius",
                format!("must be positive and finite, got {factor}"),
            ));
        }
        self.initial_radius = factor;
        Ok(self)
    }
    /// Extrapolation along accepted Gauss–Newton steps: when a full (undamped) step $p$ lowered
    /// the loss by more than the linear model predicted, the loss along it is modelled as the
    /// parabola $f(\alpha) = f_0 - 2\alpha g + h\alpha^2$ through $f_0$, the model's slope
    /// ($g = \lVert J p\rVert^2$) and the actual $f(1)$, and one more point is evaluated at its
    /// minimum $\alpha^\ast = g/h$ (at most 16; 16 if $h \le 0$), kept if lower. For
    /// large-residual problems whose Gauss–Newton iteration converges only linearly because
    /// $J^\top J$ overestimates the curvature (every step too short): the variable-projection
    /// ARMAX criterion of a misspecified closed-loop model needed 100 iterations without it and
    /// 37 with it on random rig 14's record. Off by default.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::pem::lm::LmOptions;
    /// assert!(LmOptions::default().with_extrapolation(true).extrapolation());
    /// ```
    pub fn with_extrapolation(mut self, on: bool) -> Self {
        self.extrapolate = on;
        self
    }
    /// Rows per part of the QR of $[J\;r]$ (default 16 384): a tall $[J\;r]$ is cut into
    /// $\min(8, \lfloor m / \text{rows} \rfloor)$ contiguous parts whose triangles are computed
    /// side by side and reduced by one QR of the stacked triangles. The cut depends on $m$ and
    /// this option only, never on the number of threads, so the estimate is the same on any
    /// machine; a smaller value lets a problem of a few thousand residuals use several cores.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for 0.
    pub fn with_triangle_part_rows(mut self, rows: usize) -> Result<Self> {
        if rows == 0 {
            return Err(Error::invalid(
                "triangle_part_rows",
                "a part needs at least one row",
            ));
        }
        self.part_rows = rows;
        Ok(self)
    }
    /// The crawl stop ([`StopReason::Crawl`]): with `significance_tol` $\kappa > 0$, stop when
    /// the last `window` accepted steps together lowered $\tfrac12\lVert r\rVert^2$ by less
    /// than $\kappa^2\hat\sigma^2/2$, whatever the Gauss–Newton step still promises. 0 (the
    /// default) turns it off. For ill-conditioned problems whose model error is not noise (a
    /// plant the model class cannot hold): the promised gain lies along a nearly flat
    /// direction and the trust region delivers a sliver of it per step.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::pem::lm::LmOptions;
    /// assert_eq!(LmOptions::default().with_crawl_window(10).crawl_window(), 10);
    /// ```
    pub fn with_crawl_window(mut self, window: usize) -> Self {
        self.crawl_window = window;
        self
    }
    /// The crawl window (0: off).
    pub fn crawl_window(&self) -> usize {
        self.crawl_window
    }
    /// Whether [`with_extrapolation`](Self::with_extrapolation) is on.
    pub fn extrapolation(&self) -> bool {
        self.extrapolate
    }
    /// Maximum number of accepted steps.
    pub fn max_iterations(&self) -> usize {
        self.max_iterations
    }
    /// Relative loss-change tolerance.
    pub fn loss_tol(&self) -> f64 {
        self.loss_tol
    }
    /// Relative step tolerance.
    pub fn step_tol(&self) -> f64 {
        self.step_tol
    }
    /// Gradient (cosine) tolerance.
    pub fn gradient_tol(&self) -> f64 {
        self.gradient_tol
    }
    /// Statistical tolerance $\kappa$ in standard errors (0: off).
    pub fn significance_tol(&self) -> f64 {
        self.significance_tol
    }
}

/// What [`minimize`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmReport {
    /// Accepted steps.
    pub iterations: usize,
    /// Residual evaluations, including the start and rejected trials.
    pub evaluations: usize,
    /// Why the iteration stopped.
    pub reason: StopReason,
    /// $\tfrac12\lVert r\rVert^2$ at the start.
    pub initial_cost: f64,
    /// $\tfrac12\lVert r\rVert^2$ at the returned point.
    pub cost: f64,
    /// Trial points rejected because the residuals were undefined (outside the admissible set).
    pub rejected_inadmissible: usize,
    /// The returned point is a minimum on the boundary of the admissible set (for a predictor:
    /// the stability boundary): the Gauss–Newton step from it leaves the set.
    pub ended_on_boundary: bool,
}

/// Whether every entry is finite: a branch-free test per 16 entries (the plain
/// `iter().all(..)` tests and branches on each entry of a Jacobian of $10^6$ entries).
pub(crate) fn all_finite(v: &[f64]) -> bool {
    let mut chunks = v.chunks_exact(16);
    chunks
        .by_ref()
        .all(|c| c.iter().fold(true, |ok, x| ok & x.is_finite()))
        && chunks.remainder().iter().all(|x| x.is_finite())
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Solves the upper-triangular system $U x = b$ (back substitution).
fn solve_upper(u: &Mat<f64>, b: &[f64]) -> Vec<f64> {
    let n = b.len();
    let mut x = b.to_vec();
    for i in (0..n).rev() {
        let mut s = x[i];
        for j in i + 1..n {
            s -= u[(i, j)] * x[j];
        }
        x[i] = s / u[(i, i)];
    }
    x
}

/// Solves $U^\top x = b$ for upper-triangular $U$ (forward substitution).
fn solve_upper_transposed(u: &Mat<f64>, b: &[f64]) -> Vec<f64> {
    let n = b.len();
    let mut x = b.to_vec();
    for i in 0..n {
        let mut s = x[i];
        for j in 0..i {
            s -= u[(j, i)] * x[j];
        }
        x[i] = s / u[(i, i)];
    }
    x
}

/// Whether the triangle is numerically nonsingular.
fn full_rank(u: &Mat<f64>) -> bool {
    let n = u.nrows();
    let dmax = (0..n).map(|i| u[(i, i)].abs()).fold(0.0, f64::max);
    dmax > 0.0 && (0..n).all(|i| u[(i, i)].abs() > dmax * 1e-14 * n as f64)
}

/// The $(n+1) \times (n+1)$ triangle $\begin{bmatrix} R & z \\ 0 & \rho \end{bmatrix}$ of the QR
/// factorisation of $[J \;\, r]$ ($m \times (n+1)$), computed in row chunks
/// ([`StreamingQr`](crate::estimate::qr_stream::StreamingQr)) so that $[J\;r]$ is never copied
/// whole; with fewer than $n + 1$ rows the missing rows of the triangle are zero.
///
/// Tall problems are cut into [`triangle_parts`] contiguous row ranges, whose triangles are
/// computed side by side and then reduced by one QR of the stacked triangles (the Gram matrix
/// $[J\;r]^\top[J\;r]$ is the sum over the parts, so the result is the same triangle up to
/// rounding and row signs). The cut depends on $m$ only, never on the number of threads, so an
/// estimate is the same on any machine.
fn triangle_of(jac: &Mat<f64>, r: &[f64], part_rows: usize) -> Mat<f64> {
    use rayon::prelude::*;
    let (m, n) = (jac.nrows(), jac.ncols());
    let parts = triangle_parts(m, part_rows);
    if parts < 2 {
        return triangle_rows(jac, r, 0, m);
    }
    let p = n + 1;
    let tris: Vec<Mat<f64>> = (0..parts)
        .into_par_iter()
        .map(|k| triangle_rows(jac, r, k * m / parts, (k + 1) * m / parts))
        .collect();
    let stacked = Mat::from_fn(parts * p, p, |i, j| tris[i / p][(i % p, j)]);
    qr_triangle(&stacked)
}

/// Row ranges of [`triangle_of`]: one per `part_rows` rows (default [`TRIANGLE_PART_ROWS`]),
/// at most 8.
fn triangle_parts(m: usize, part_rows: usize) -> usize {
    (m / part_rows.max(1)).clamp(1, 8)
}

/// Rows per part of [`triangle_of`] (small problems stay in one part).
const TRIANGLE_PART_ROWS: usize = 16_384;

/// [`triangle_of`] for the rows `k_start..k_end` of $[J\;r]$.
fn triangle_rows(jac: &Mat<f64>, r: &[f64], k_start: usize, k_end: usize) -> Mat<f64> {
    let n = jac.ncols();
    let m = k_end - k_start;
    let p = n + 1;
    let mut qr = crate::estimate::qr_stream::StreamingQr::new(p, (8 * p).max(256).min(m.max(1)));
    let c = qr.chunk_rows();
    let mut k0 = k_start;
    while k0 < k_end {
        let cc = c.min(k_end - k0);
        let mut w = qr.chunk_mut(cc);
        for j in 0..n {
            for (dst, src) in w
                .rb_mut()
                .col_mut(j)
                .iter_mut()
                .zip(jac.col(j).subrows(k0, cc).iter())
            {
                *dst = *src;
            }
        }
        for (dst, src) in w.rb_mut().col_mut(n).iter_mut().zip(&r[k0..k0 + cc]) {
            *dst = *src;
        }
        qr.absorb(cc);
        k0 += cc;
    }
    let t = qr.finish();
    Mat::from_fn(p, p, |i, j| if j >= i { t[(i, j)] } else { 0.0 })
}

/// The $n \times n$ upper triangle $R$ of the QR factorisation of `a` ($m \ge n$ rows),
/// triangular also when columns are dependent ([`r_factor`](crate::estimate::qr_stream::r_factor)).
fn qr_triangle(a: &Mat<f64>) -> Mat<f64> {
    crate::estimate::qr_stream::r_factor(a.as_ref())
}

/// Step in scaled variables for damping `par`: least squares of
/// $[\tilde R; \sqrt{par} I] s \approx [-z; 0]$; returns $s$ and the triangle $S$.
fn damped_step(rt: &Mat<f64>, z: &[f64], par: f64) -> (Vec<f64>, Mat<f64>) {
    let n = z.len();
    let sp = par.sqrt();
    let aug = Mat::from_fn(2 * n, n + 1, |i, j| {
        if j == n {
            if i < n {
                -z[i]
            } else {
                0.0
            }
        } else if i < n {
            rt[(i, j)]
        } else if i - n == j {
            sp
        } else {
            0.0
        }
    });
    let t = qr_triangle(&aug);
    let s_mat = Mat::from_fn(n, n, |i, j| t[(i, j)]);
    let rhs: Vec<f64> = (0..n).map(|i| t[(i, n)]).collect();
    (solve_upper(&s_mat, &rhs), s_mat)
}

/// Moré's λ iteration: the scaled step $s$ with $\lVert s \rVert \approx \Delta$ (or the
/// Gauss–Newton step when it is shorter), and the damping $\lambda$.
fn lm_parameter(rt: &Mat<f64>, z: &[f64], delta: f64, par0: f64) -> (Vec<f64>, f64) {
    let n = z.len();
    let mut parl = 0.0;
    let mut fp = f64::INFINITY;
    let mut gn_norm = f64::NAN;
    if full_rank(rt) {
        let s0: Vec<f64> = solve_upper(rt, z).iter().map(|v| -v).collect();
        let dxnorm = norm(&s0);
        if dxnorm.is_finite() {
            fp = dxnorm - delta;
            if fp <= 0.1 * delta {
                return (s0, 0.0);
            }
            gn_norm = dxnorm;
            let w: Vec<f64> = s0.iter().map(|v| v / dxnorm).collect();
            let v = solve_upper_transposed(rt, &w);
            let vn = norm(&v);
            if vn.is_finite() && vn > 0.0 {
                parl = fp / (delta * vn * vn);
            }
        }
    }
    // upper bound from the gradient g = R̃ᵀ z
    let g: Vec<f64> = (0..n)
        .map(|j| (0..=j).map(|i| rt[(i, j)] * z[i]).sum::<f64>())
        .collect();
    let gnorm = norm(&g);
    let mut paru = gnorm / delta;
    if paru == 0.0 {
        paru = f64::MIN_POSITIVE / delta.min(0.1);
    }
    let mut par = par0.max(parl).min(paru);
    if par == 0.0 {
        par = if gn_norm.is_finite() && gn_norm > 0.0 {
            gnorm / gn_norm
        } else {
            0.001 * paru
        };
    }
    let mut s = vec![0.0; n];
    for iter in 1..=10 {
        if par == 0.0 {
            par = f64::MIN_POSITIVE.max(0.001 * paru);
        }
        let (step, smat) = damped_step(rt, z, par);
        s = step;
        let dxnorm = norm(&s);
        let prev = fp;
        fp = dxnorm - delta;
        if fp.abs() <= 0.1 * delta || (parl == 0.0 && fp <= prev && prev < 0.0) || iter == 10 {
            break;
        }
        if dxnorm == 0.0 || !dxnorm.is_finite() {
            break;
        }
        let w: Vec<f64> = s.iter().map(|v| v / dxnorm).collect();
        let v = solve_upper_transposed(&smat, &w);
        let vn2 = v.iter().map(|x| x * x).sum::<f64>();
        let parc = fp / (delta * vn2);
        if fp > 0.0 {
            parl = parl.max(par);
        }
        if fp < 0.0 {
            paru = paru.min(par);
        }
        par = parl.max(par + parc);
        if !par.is_finite() {
            par = paru;
        }
    }
    // a (nearly) rank-deficient R̃ can drive the damping to underflow and the step to overflow:
    // then the steepest-descent step to the trust-region boundary (damping at its upper bound)
    if !s.iter().all(|v| v.is_finite()) && gnorm > 0.0 && gnorm.is_finite() {
        return (
            g.iter().map(|v| -v * delta / gnorm).collect(),
            gnorm / delta,
        );
    }
    (s, par)
}

fn finite_residuals<P: LeastSquaresProblem + ?Sized>(
    p: &mut P,
    x: &[f64],
    m: usize,
) -> Option<Vec<f64>> {
    let r = p.residuals(x)?;
    (r.len() == m && r.iter().all(|v| v.is_finite())).then_some(r)
}

/// Minimises $\tfrac12\lVert r(x)\rVert^2$ from `x0` by Levenberg–Marquardt (see the module docs).
///
/// Returns the final point and a report. Reaching `max_iterations` is not an error: the report
/// says so, and the point is the best one found.
///
/// # Errors
/// [`Error::Numerical`] if the residuals at `x0` are undefined or not finite, or a Jacobian is
/// missing, of the wrong size or not finite; [`Error::InvalidArgument`] if there are fewer
/// residuals than unknowns.
///
/// # Example
/// ```
/// use ambid_core::estimate::pem::lm::{minimize, LeastSquaresProblem, LmOptions};
/// use faer::Mat;
/// // fit y = a e^{b t} to exact data from a = 2, b = -0.5
/// struct Exp(Vec<f64>, Vec<f64>);
/// impl LeastSquaresProblem for Exp {
///     fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
///         Some(self.0.iter().zip(&self.1).map(|(t, y)| x[0] * (x[1] * t).exp() - y).collect())
///     }
///     fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
///         let t = &self.0;
///         Some(Mat::from_fn(t.len(), 2, |i, j| {
///             let e = (x[1] * t[i]).exp();
///             if j == 0 { e } else { x[0] * t[i] * e }
///         }))
///     }
/// }
/// let t: Vec<f64> = (0..20).map(|k| k as f64 * 0.25).collect();
/// let y: Vec<f64> = t.iter().map(|t| 2.0 * (-0.5 * t).exp()).collect();
/// let (x, _) = minimize(&mut Exp(t, y), &[1.0, 0.0], &LmOptions::default()).unwrap();
/// assert!((x[0] - 2.0).abs() < 1e-10 && (x[1] + 0.5).abs() < 1e-10);
/// ```
pub fn minimize<P: LeastSquaresProblem + ?Sized>(
    problem: &mut P,
    x0: &[f64],
    opts: &LmOptions,
) -> Result<(Vec<f64>, LmReport)> {
    minimize_resumed(problem, x0, opts, None).map(|(x, report, _)| (x, report))
}

/// The trust-region state of a [`minimize_resumed`] run where it stopped: the radius
/// $\Delta$, the damping $\lambda$ and the scaling $D$.
#[derive(Debug, Clone, PartialEq)]
pub struct LmState {
    delta: f64,
    par: f64,
    diag: Vec<f64>,
}

/// [`minimize`], continued from the trust-region state of an earlier run on the same problem
/// (`resume`), and returning its own final state. A run stopped at its iteration limit and
/// resumed from its last point with its state takes the same steps the uninterrupted run would
/// have; started afresh, the radius would begin at `initial_radius` again and the first steps
/// would be spent shrinking it. A `resume` of another dimension is ignored.
///
/// # Errors
/// As [`minimize`].
pub fn minimize_resumed<P: LeastSquaresProblem + ?Sized>(
    problem: &mut P,
    x0: &[f64],
    opts: &LmOptions,
    resume: Option<LmState>,
) -> Result<(Vec<f64>, LmReport, LmState)> {
    const CTX: &str = "levenberg_marquardt";
    let n = x0.len();
    let mut x = x0.to_vec();
    let mut r = problem
        .residuals(&x)
        .filter(|r| r.iter().all(|v| v.is_finite()))
        .ok_or_else(|| {
            Error::numerical(
                CTX,
                "the residuals at the starting point are undefined or not finite; start from an admissible point",
            )
        })?;
    let m = r.len();
    let mut fnorm = norm(&r);
    let mut report = LmReport {
        iterations: 0,
        evaluations: 1,
        reason: StopReason::Gradient,
        initial_cost: 0.5 * fnorm * fnorm,
        cost: 0.5 * fnorm * fnorm,
        rejected_inadmissible: 0,
        ended_on_boundary: false,
    };
    if n == 0 {
        let state = LmState {
            delta: 0.0,
            par: 0.0,
            diag: Vec::new(),
        };
        return Ok((x, report, state));
    }
    if m < n {
        return Err(Error::invalid(
            "residuals",
            format!(
                "{m} residuals cannot determine {n} unknowns; supply more data or fewer parameters"
            ),
        ));
    }
    let max_evals = 20 * (opts.max_iterations + 1);
    let mut diag = vec![0.0; n];
    let mut delta = 0.0;
    let mut par = 0.0;
    let mut first = true;
    if let Some(st) = resume.filter(|st| st.diag.len() == n && st.delta > 0.0) {
        diag = st.diag;
        delta = st.delta;
        par = st.par;
        first = false;
    }
    // ½‖r‖² after each accepted step (index = iterations), for the stagnation test
    let mut costs = vec![0.5 * fnorm * fnorm];
    let reason = 'outer: loop {
        let t = problem.triangle(&x, &r, opts.part_rows)?;
        if t.nrows() != n + 1 || t.ncols() != n + 1 {
            return Err(Error::DimensionMismatch {
                context: "levenberg_marquardt: triangle of [J r]",
                expected: format!("{}×{}", n + 1, n + 1),
                got: format!("{}×{}", t.nrows(), t.ncols()),
            });
        }
        if !(0..=n).all(|j| all_finite(t.col_as_slice(j))) {
            return Err(Error::numerical(CTX, "the Jacobian is not finite"));
        }
        if fnorm == 0.0 {
            break StopReason::Gradient;
        }
        let rmat = Mat::from_fn(n, n, |i, j| t[(i, j)]);
        let z: Vec<f64> = (0..n).map(|i| t[(i, n)]).collect();
        let colnorm: Vec<f64> = (0..n)
            .map(|j| (0..=j).map(|i| rmat[(i, j)].powi(2)).sum::<f64>().sqrt())
            .collect();
        if first {
            for j in 0..n {
                diag[j] = if colnorm[j] == 0.0 { 1.0 } else { colnorm[j] };
            }
            let xnorm = norm(&x.iter().zip(&diag).map(|(a, b)| a * b).collect::<Vec<_>>());
            delta = opts.initial_radius * xnorm;
            if delta == 0.0 {
                delta = opts.initial_radius;
            }
        }
        // gradient test: cosine between r and each column of J (Jᵀr = Rᵀz)
        let mut gnorm: f64 = 0.0;
        for j in 0..n {
            if colnorm[j] > 0.0 {
                let gj: f64 = (0..=j).map(|i| rmat[(i, j)] * z[i]).sum();
                gnorm = gnorm.max((gj / (fnorm * colnorm[j])).abs());
            }
        }
        if gnorm <= opts.gradient_tol {
            break StopReason::Gradient;
        }
        // statistical test: the whole remaining Gauss–Newton reduction ‖z‖² is below κ² σ̂²
        if opts.significance_tol > 0.0 && m > n {
            let zz: f64 = z.iter().map(|v| v * v).sum();
            let sigma2 = fnorm * fnorm / (m - n) as f64;
            let k2 = opts.significance_tol.powi(2);
            if zz <= k2 * sigma2 {
                break StopReason::Significance;
            }
            let it = report.iterations;
            if it >= STAGNATION_WINDOW
                && zz <= STAGNATION_SIGMA * STAGNATION_SIGMA * sigma2
                && costs[it - STAGNATION_WINDOW] - costs[it] <= 0.5 * k2 * sigma2
            {
                break StopReason::Stagnation;
            }
            let w = opts.crawl_window;
            if w > 0 && it >= w && costs[it - w] - costs[it] <= 0.5 * k2 * sigma2 {
                break StopReason::Crawl;
            }
        }
        if problem.abandon(
            0.5 * fnorm * fnorm,
            0.5 * z.iter().map(|v| v * v).sum::<f64>(),
        ) {
            break StopReason::Abandoned;
        }
        for j in 0..n {
            diag[j] = diag[j].max(colnorm[j]);
        }
        let rt = Mat::from_fn(n, n, |i, j| rmat[(i, j)] / diag[j]);
        loop {
            let (s, p) = lm_parameter(&rt, &z, delta, par);
            par = p;
            let step: Vec<f64> = s.iter().zip(&diag).map(|(s, d)| s / d).collect();
            let pnorm = norm(&s);
            if first {
                delta = delta.min(pnorm);
            }
            let xt: Vec<f64> = x.iter().zip(&step).map(|(a, b)| a + b).collect();
            let fnorm_prev = fnorm;
            report.evaluations += 1;
            let trial = finite_residuals(problem, &xt, m);
            let admissible = trial.is_some();
            let fnorm1 = trial.as_deref().map_or(f64::INFINITY, norm);
            let actred = if admissible && 0.1 * fnorm1 < fnorm {
                1.0 - (fnorm1 / fnorm).powi(2)
            } else {
                -1.0
            };
            if !admissible {
                report.rejected_inadmissible += 1;
            }
            // predicted reduction from the linear model
            let jp: Vec<f64> = (0..n)
                .map(|i| (i..n).map(|j| rt[(i, j)] * s[j]).sum::<f64>())
                .collect();
            let temp1 = norm(&jp) / fnorm;
            let temp2 = par.sqrt() * pnorm / fnorm;
            let prered = temp1 * temp1 + 2.0 * temp2 * temp2;
            let dirder = -(temp1 * temp1 + temp2 * temp2);
            let ratio = if prered != 0.0 { actred / prered } else { 0.0 };
            if ratio <= 0.25 {
                let mut temp = if actred >= 0.0 {
                    0.5
                } else {
                    0.5 * dirder / (dirder + 0.5 * actred)
                };
                if !admissible || 0.1 * fnorm1 >= fnorm || temp.is_nan() || temp < 0.1 {
                    temp = 0.1;
                }
                delta = temp * delta.min(pnorm / 0.1);
                par /= temp;
            } else if par == 0.0 || ratio >= 0.75 {
                delta = pnorm / 0.5;
                par *= 0.5;
            }
            let accepted = admissible && ratio >= 1e-4;
            if accepted {
                if let Some(rn) = trial {
                    x = xt;
                    r = rn;
                }
                fnorm = fnorm1;
                if opts.extrapolate && par == 0.0 && ratio > 1.0 && report.evaluations < max_evals {
                    // the Gauss–Newton step fell short of the decrease it predicted: along the
                    // step the loss is f(α) ≈ f₀ − 2αg + hα² with g = ‖J p‖² (the linear model's
                    // slope) and h from the actual f(1); one more evaluation at its minimum α*
                    let f0 = fnorm_prev * fnorm_prev;
                    let g = (temp1 * fnorm_prev).powi(2);
                    let h = fnorm * fnorm - f0 + 2.0 * g;
                    let alpha = if h > 0.0 {
                        (g / h).min(EXTRAPOLATION_MAX)
                    } else {
                        EXTRAPOLATION_MAX
                    };
                    if alpha > 1.0 {
                        let xe: Vec<f64> = x
                            .iter()
                            .zip(&step)
                            .map(|(a, b)| a + (alpha - 1.0) * b)
                            .collect();
                        report.evaluations += 1;
                        if let Some(re) = finite_residuals(problem, &xe, m) {
                            let fe = norm(&re);
                            if fe < fnorm {
                                fnorm = fe;
                                x = xe;
                                r = re;
                                delta = delta.max(2.0 * alpha * pnorm);
                            }
                        }
                    }
                }
                report.iterations += 1;
                costs.push(0.5 * fnorm * fnorm);
                first = false;
            }
            report.ended_on_boundary = !admissible;
            let eps = f64::EPSILON;
            if actred.abs() <= opts.loss_tol.max(eps)
                && prered <= opts.loss_tol.max(eps)
                && 0.5 * ratio <= 1.0
            {
                break 'outer StopReason::LossChange;
            }
            // every parameter's largest possible move Δ/d_j is below step_tol relative to it
            let xtol = opts.step_tol.max(eps);
            let step_small = (0..n).all(|j| delta <= xtol * diag[j] * (x[j].abs() + xtol));
            if step_small || delta <= f64::MIN_POSITIVE {
                break 'outer StopReason::StepSize;
            }
            if report.iterations >= opts.max_iterations || report.evaluations >= max_evals {
                break 'outer StopReason::MaxIterations;
            }
            if accepted {
                break;
            }
        }
    };
    report.reason = reason;
    report.cost = 0.5 * fnorm * fnorm;
    let state = LmState {
        delta,
        par,
        diag: diag.clone(),
    };
    report.ended_on_boundary = match reason {
        StopReason::Gradient => false,
        // not at a minimum: the Gauss–Newton step says nothing, keep the last trial's verdict
        StopReason::MaxIterations | StopReason::Abandoned | StopReason::Crawl => {
            report.ended_on_boundary
        }
        StopReason::LossChange
        | StopReason::StepSize
        | StopReason::Significance
        | StopReason::Stagnation => match gauss_newton_leaves(problem, &x, &r, m) {
            Some(leaves) => {
                report.evaluations += 1;
                leaves
            }
            None => report.ended_on_boundary,
        },
    };
    Ok((x, report, state))
}

/// Whether the full Gauss–Newton step from the final point leaves the admissible set. At an
/// interior (local) minimum $J^\top r = 0$ and the step vanishes; at a minimum on the boundary
/// the gradient points outwards and the step crosses it. `None` if $J$ is rank deficient.
fn gauss_newton_leaves<P: LeastSquaresProblem + ?Sized>(
    problem: &mut P,
    x: &[f64],
    r: &[f64],
    m: usize,
) -> Option<bool> {
    let n = x.len();
    let t = problem.triangle(x, r, TRIANGLE_PART_ROWS).ok()?;
    if r.len() != m || t.nrows() != n + 1 || t.ncols() != n + 1 {
        return None;
    }
    let rmat = Mat::from_fn(n, n, |i, j| t[(i, j)]);
    if !full_rank(&rmat) {
        return None;
    }
    let z: Vec<f64> = (0..n).map(|i| t[(i, n)]).collect();
    let step = solve_upper(&rmat, &z);
    let xt: Vec<f64> = x.iter().zip(&step).map(|(a, s)| a - s).collect();
    if xt.iter().any(|v| !v.is_finite()) {
        return None;
    }
    Some(finite_residuals(problem, &xt, m).is_none())
}

/// Test support: a problem's Jacobian at `th` against central differences of its residuals, to the
/// relative tolerance `tol`; returned for further checks.
#[cfg(test)]
pub(crate) fn jacobian_against_differences(
    prob: &mut impl LeastSquaresProblem,
    th: &[f64],
    tol: f64,
) -> std::result::Result<Mat<f64>, Box<dyn std::error::Error>> {
    let j = prob.jacobian(th).ok_or("no Jacobian")?;
    for p in 0..th.len() {
        let eps = 1e-6 * (1.0 + th[p].abs());
        let mut tp = th.to_vec();
        tp[p] += eps;
        let mut tm = th.to_vec();
        tm[p] -= eps;
        let (rp, rm) = (
            prob.residuals(&tp).ok_or("no residuals")?,
            prob.residuals(&tm).ok_or("no residuals")?,
        );
        for i in 0..rp.len() {
            let fd = (rp[i] - rm[i]) / (2.0 * eps);
            assert!(
                (fd - j[(i, p)]).abs() <= tol * (1.0 + fd.abs()),
                "param {p} row {i}: {fd} vs {}",
                j[(i, p)]
            );
        }
    }
    Ok(j)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The triangle of a tall $[J\;r]$ cut into parts equals the one of the whole (one streaming
    /// QR) up to rounding, as Gram matrices $T^\top T$ (row signs may differ), and is upper
    /// triangular.
    #[test]
    fn triangle_in_parts_matches_the_one_part_triangle() {
        use rand::{RngExt, SeedableRng};
        use rand_chacha::ChaCha8Rng;
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        for &(m, n) in &[(40_000, 3), (100_003, 9), (3 * TRIANGLE_PART_ROWS + 1, 14)] {
            assert!(triangle_parts(m, TRIANGLE_PART_ROWS) >= 2);
            // badly scaled columns, as Jacobians of polynomial coefficients are
            let jac = Mat::from_fn(m, n, |_, j| {
                rng.random_range(-1.0..1.0) * 10f64.powi(j as i32 - 3)
            });
            let r: Vec<f64> = (0..m).map(|_| rng.random_range(-1.0..1.0)).collect();
            let parts = triangle_of(&jac, &r, TRIANGLE_PART_ROWS);
            let whole = triangle_rows(&jac, &r, 0, m);
            let gram = |t: &Mat<f64>| t.transpose() * t;
            let (gp, gw) = (gram(&parts), gram(&whole));
            for i in 0..=n {
                for j in 0..=n {
                    let scale = (gw[(i, i)] * gw[(j, j)]).sqrt();
                    assert!(
                        (gp[(i, j)] - gw[(i, j)]).abs() <= 1e-13 * scale,
                        "m {m}, n {n}: Gram ({i}, {j}) {} vs {}",
                        gp[(i, j)],
                        gw[(i, j)]
                    );
                    if i > j {
                        assert_eq!(parts[(i, j)], 0.0);
                    }
                }
            }
        }
        assert_eq!(
            triangle_parts(TRIANGLE_PART_ROWS * 2 - 1, TRIANGLE_PART_ROWS),
            1
        );
        assert_eq!(triangle_parts(usize::MAX / 2, TRIANGLE_PART_ROWS), 8);
        // a smaller part size cuts a problem of a few thousand rows (the MIMO frequency fit's
        // 8 096 residuals into four parts of one input column each)
        assert_eq!(triangle_parts(8096, 2024), 4);
        assert_eq!(triangle_parts(8096, 1), 8);
    }

    /// A Jacobian with an exactly dependent column (a flat direction, e.g. two blocks of equal
    /// poles): the triangle of $[J\;r]$ is upper triangular in one part and in parts, and its
    /// $\lVert z\rVert^2$ is what the Gauss–Newton step can gain, $\lVert P_J r\rVert^2$
    /// (oracle: the normal equations of the independent columns). faer's own factor is in
    /// row-echelon form here and read $\rho = 0$, $\lVert z\rVert^2 = \lVert r\rVert^2$.
    #[test]
    fn a_dependent_jacobian_column_leaves_the_gauss_newton_gain_right() {
        use rand::{RngExt, SeedableRng};
        use rand_chacha::ChaCha8Rng;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (m, n) = (8096, 10);
        let mut jac = Mat::from_fn(m, n, |_, _| rng.random_range(-1.0..1.0));
        for i in 0..m {
            jac[(i, 4)] = 0.5 * jac[(i, 1)] - 2.0 * jac[(i, 7)];
        }
        let r: Vec<f64> = (0..m).map(|_| rng.random_range(-1.0..1.0)).collect();
        let keep: Vec<usize> = (0..n).filter(|&j| j != 4).collect();
        let x = Mat::from_fn(m, keep.len(), |i, c| jac[(i, keep[c])]);
        let y = Mat::from_fn(m, 1, |i, _| r[i]);
        let coef =
            faer::prelude::Solve::solve(&(x.transpose() * &x).partial_piv_lu(), x.transpose() * &y);
        let fitted = &x * &coef;
        let gain: f64 = (0..m).map(|i| fitted[(i, 0)] * y[(i, 0)]).sum();
        let rr: f64 = r.iter().map(|v| v * v).sum();
        for t in [triangle_rows(&jac, &r, 0, m), triangle_of(&jac, &r, m / 4)] {
            for i in 0..=n {
                for j in 0..i {
                    assert_eq!(t[(i, j)], 0.0);
                }
            }
            let zz: f64 = (0..n).map(|i| t[(i, n)] * t[(i, n)]).sum();
            assert!((zz - gain).abs() < 1e-9 * rr, "‖z‖² {zz} against {gain}");
            assert!((t[(n, n)].powi(2) - (rr - gain)).abs() < 1e-9 * rr);
            // column 7 is the one in the span of those before it
            assert!(t[(7, 7)].abs() < 1e-9 * t[(0, 0)].abs());
        }
    }

    /// Dennis & Schnabel's large-residual example: $r = [x + 1,\; \lambda x^2 + x - 1]$, minimum
    /// at $x = 0$ with $r = [1, -1]$; the true curvature $2 - 2\lambda$ is below
    /// $J^\top J = 2$, so Gauss–Newton converges only linearly (rate $\lambda$).
    struct LargeResidual(f64);
    impl LeastSquaresProblem for LargeResidual {
        fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
            Some(vec![x[0] + 1.0, self.0 * x[0] * x[0] + x[0] - 1.0])
        }
        fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
            let lam = self.0;
            Some(Mat::from_fn(2, 1, |i, _| {
                if i == 0 {
                    1.0
                } else {
                    2.0 * lam * x[0] + 1.0
                }
            }))
        }
    }

    /// Two exactly opposite Jacobian columns at the start (as C = D = 1 gives for Box–Jenkins):
    /// the damped step must stay finite and the iteration reach the minimum.
    struct Opposite;
    impl LeastSquaresProblem for Opposite {
        fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
            Some(
                (0..50)
                    .map(|i| {
                        let s = (i as f64 * 0.1).sin();
                        s * (1.0 + x[0] - x[1]) + x[2] - 0.3 + 0.01 * x[0] * x[0]
                    })
                    .collect(),
            )
        }
        fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
            Some(Mat::from_fn(50, 3, |i, j| {
                let s = (i as f64 * 0.1).sin();
                match j {
                    0 => s + 0.02 * x[0],
                    1 => -s,
                    _ => 1.0,
                }
            }))
        }
    }

    #[test]
    fn rank_deficient_start_gives_a_finite_step_and_converges() {
        let (x, rep) = minimize(&mut Opposite, &[0.0, 0.0, 0.0], &LmOptions::default()).unwrap();
        assert_eq!(rep.rejected_inadmissible, 0, "{rep:?}");
        assert!(rep.reason.converged(), "{rep:?}");
        // the minimum: 1 + x0 − x1 + 0.01 x0² = 0 (the sine term vanishes) and x2 = 0.3
        let r = Opposite.residuals(&x).unwrap();
        assert!(r.iter().all(|v| v.abs() < 1e-8), "{x:?}: {r:?}");
    }

    #[test]
    fn extrapolation_shortens_a_linearly_converging_gauss_newton_iteration() {
        let opts = LmOptions::default();
        let (x0, r0) = minimize(&mut LargeResidual(0.5), &[0.2], &opts).unwrap();
        let (x1, r1) = minimize(
            &mut LargeResidual(0.5),
            &[0.2],
            &opts.with_extrapolation(true),
        )
        .unwrap();
        // both at the analytic minimum x = 0
        assert!(x0[0].abs() < 1e-6 && x1[0].abs() < 1e-6, "{x0:?} {x1:?}");
        assert!(r0.reason.converged() && r1.reason.converged());
        // the parabola along the step finds the 1-D minimum of this quartic-in-x loss
        // (nearly) at once; without it the error halves per step
        assert!(
            r1.iterations * 3 <= r0.iterations,
            "with extrapolation {} iterations, without {}",
            r1.iterations,
            r0.iterations
        );
    }

    /// Linear least squares: one Gauss–Newton step is exact.
    struct Linear {
        a: Mat<f64>,
        b: Vec<f64>,
    }
    impl LeastSquaresProblem for Linear {
        fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
            Some(
                (0..self.a.nrows())
                    .map(|i| (0..x.len()).map(|j| self.a[(i, j)] * x[j]).sum::<f64>() - self.b[i])
                    .collect(),
            )
        }
        fn jacobian(&mut self, _x: &[f64]) -> Option<Mat<f64>> {
            Some(self.a.clone())
        }
    }

    #[test]
    fn a_problem_that_abandons_stops_unconverged_where_it_asked() {
        // Rosenbrock from the classic start, abandoned at its fourth iteration
        struct Quits(usize);
        impl LeastSquaresProblem for Quits {
            fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
                Some(vec![10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]])
            }
            fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
                Some(faer::mat![[-20.0 * x[0], 10.0], [-1.0, 0.0]])
            }
            fn abandon(&mut self, cost: f64, predicted: f64) -> bool {
                assert!(cost > 0.0 && predicted >= 0.0 && predicted <= cost * (1.0 + 1e-12));
                self.0 += 1;
                self.0 > 3
            }
        }
        let mut p = Quits(0);
        let (x, rep) = minimize(&mut p, &[-1.2, 1.0], &LmOptions::default()).unwrap();
        assert_eq!(rep.reason, StopReason::Abandoned);
        assert!(!rep.reason.converged());
        assert_eq!(rep.iterations, 3);
        assert!((x[0] - 1.0).abs() > 1e-3, "stopped before the minimum");
    }

    #[test]
    fn linear_problem_matches_lstsq() {
        let a = Mat::from_fn(30, 3, |i, j| {
            ((i * 7 + j * 3) % 11) as f64 - 5.0 + if j == 2 { 1e3 } else { 0.0 }
        });
        let b: Vec<f64> = (0..30).map(|i| (i as f64).sin()).collect();
        let bm = Mat::from_fn(30, 1, |i, _| b[i]);
        let want = crate::linalg::lstsq(a.as_ref(), bm.as_ref()).unwrap();
        let (x, rep) = minimize(&mut Linear { a, b }, &[0.0; 3], &LmOptions::default()).unwrap();
        for j in 0..3 {
            assert!(
                (x[j] - want[(j, 0)]).abs() < 1e-10 * want[(j, 0)].abs().max(1e-3),
                "{j}"
            );
        }
        assert!(rep.iterations <= 3, "{rep:?}");
    }

    /// Powell's badly scaled function: residuals 1e4 x0 x1 - 1, e^-x0 + e^-x1 - 1.0001.
    struct Powell;
    impl LeastSquaresProblem for Powell {
        fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
            Some(vec![
                1e4 * x[0] * x[1] - 1.0,
                (-x[0]).exp() + (-x[1]).exp() - 1.0001,
            ])
        }
        fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
            Some(faer::mat![
                [1e4 * x[1], 1e4 * x[0]],
                [-(-x[0]).exp(), -(-x[1]).exp()]
            ])
        }
    }

    #[test]
    fn a_resumed_run_takes_the_steps_of_the_uninterrupted_one() {
        let opts = |n: usize| LmOptions::exhaustive(n).unwrap();
        let (whole, rep) = minimize(&mut Powell, &[0.0, 1.0], &opts(12)).unwrap();
        assert_eq!(rep.iterations, 12, "{rep:?}");
        let (x5, rep5, state) = minimize_resumed(&mut Powell, &[0.0, 1.0], &opts(5), None).unwrap();
        assert_eq!(rep5.reason, StopReason::MaxIterations);
        let (resumed, rep7, _) = minimize_resumed(&mut Powell, &x5, &opts(7), Some(state)).unwrap();
        assert_eq!(rep7.iterations, 7);
        assert_eq!(resumed, whole, "the same steps, bit for bit");
        // started afresh from the same point, the radius begins at the initial one again and
        // the path differs (the reason to resume)
        let (fresh, _) = minimize(&mut Powell, &x5, &opts(7)).unwrap();
        assert_ne!(fresh, whole);
        // a state of another dimension is ignored: the run is the fresh one
        let other = LmState {
            delta: 1.0,
            par: 0.0,
            diag: vec![1.0; 3],
        };
        let (ignored, _, _) = minimize_resumed(&mut Powell, &x5, &opts(7), Some(other)).unwrap();
        assert_eq!(ignored, fresh);
    }

    #[test]
    fn badly_scaled_powell() {
        let (x, rep) = minimize(&mut Powell, &[0.0, 1.0], &LmOptions::default()).unwrap();
        let r = Powell.residuals(&x).unwrap();
        assert!(norm(&r) < 1e-12, "{x:?} {rep:?}");
        assert!(rep.reason.converged());
    }

    /// Minimum of (x - 2)² restricted to x < 1: the method stops at the boundary.
    struct Boundary;
    impl LeastSquaresProblem for Boundary {
        fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
            (x[0] < 1.0).then(|| vec![x[0] - 2.0, 0.0])
        }
        fn jacobian(&mut self, _x: &[f64]) -> Option<Mat<f64>> {
            Some(faer::mat![[1.0], [0.0]])
        }
    }

    #[test]
    fn inadmissible_region_is_never_entered_and_boundary_is_reported() {
        let (x, rep) = minimize(&mut Boundary, &[0.0], &LmOptions::default()).unwrap();
        assert!(x[0] < 1.0 && x[0] > 0.999, "{x:?}");
        assert!(rep.ended_on_boundary, "{rep:?}");
        assert!(rep.rejected_inadmissible > 0);
    }

    /// y = a e^{b t} + noise: the statistical rule stops within κ standard errors of the
    /// exact minimiser (distance in the metric of σ̂²(JᵀJ)⁻¹ at that minimiser), and earlier.
    struct NoisyExp(Vec<f64>, Vec<f64>);
    impl LeastSquaresProblem for NoisyExp {
        fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
            Some(
                self.0
                    .iter()
                    .zip(&self.1)
                    .map(|(t, y)| x[0] * (x[1] * t).exp() - y)
                    .collect(),
            )
        }
        fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
            let t = &self.0;
            Some(Mat::from_fn(t.len(), 2, |i, j| {
                let e = (x[1] * t[i]).exp();
                if j == 0 {
                    e
                } else {
                    x[0] * t[i] * e
                }
            }))
        }
    }

    #[test]
    fn significance_rule_stops_within_kappa_standard_errors_of_the_minimiser() {
        let t: Vec<f64> = (0..400).map(|k| k as f64 * 0.01).collect();
        // deterministic "noise" of RMS ≈ 0.05
        let y: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(k, t)| {
                2.0 * (-0.5 * t).exp() + 0.05 * ((k * 7919 % 997) as f64 / 498.5 - 1.0) * 1.7
            })
            .collect();
        let mut p = NoisyExp(t, y);
        let exact = LmOptions::exhaustive(200).unwrap();
        let (xe, re) = minimize(&mut p, &[1.0, 0.3], &exact).unwrap();
        for kappa in [0.1, 1.0] {
            let o = LmOptions::default().with_significance_tol(kappa).unwrap();
            let (xs, rs) = minimize(&mut p, &[1.0, 0.3], &o).unwrap();
            assert_eq!(rs.reason, StopReason::Significance, "{rs:?}");
            assert!(rs.iterations < re.iterations, "{rs:?} vs {re:?}");
            // Mahalanobis distance with P = σ̂² (JᵀJ)⁻¹ at the exact minimiser
            let j = p.jacobian(&xe).unwrap();
            let r = p.residuals(&xe).unwrap();
            let s2 = r.iter().map(|v| v * v).sum::<f64>() / (r.len() - 2) as f64;
            let g = j.transpose() * &j;
            let d = [xs[0] - xe[0], xs[1] - xe[1]];
            let q = (0..2)
                .map(|a| (0..2).map(|b| d[a] * g[(a, b)] * d[b]).sum::<f64>())
                .sum::<f64>()
                / s2;
            assert!(q.sqrt() <= kappa * 1.05, "κ = {kappa}: {} σ", q.sqrt());
        }
    }

    #[test]
    fn bad_start_and_options_are_errors() {
        assert!(minimize(&mut Boundary, &[3.0], &LmOptions::default()).is_err());
        assert!(LmOptions::default().with_loss_tol(-1.0).is_err());
        assert!(LmOptions::default().with_max_iterations(0).is_err());
        assert!(LmOptions::default().with_initial_radius(f64::NAN).is_err());
        assert!(LmOptions::default().with_significance_tol(-0.1).is_err());
    }
}
