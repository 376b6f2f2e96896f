//! Prediction-error refinement of state-space models (typically started from [`super::subspace`]).
//!
//! # Criterion
//! For the innovation model $x_{k+1} = A x_k + B u_k + K e_k$, $y_k = C x_k + D u_k + e_k$ the
//! one-step-ahead predictor is the linear filter of the measured $u$ **and** $y$
//! $$ \hat x_{k+1} = \bar A \hat x_k + \bar B u_k + K y_k, \qquad \hat y_k = C \hat x_k + D u_k,
//! \qquad \bar A = A - K C,\; \bar B = B - K D, $$
//! and [`refine_ss`] minimises $V_N = \frac1N \sum_k \lVert y_k - \hat y_k \rVert^2$
//! ([`Focus::Prediction`], the maximum-likelihood criterion for Gaussian innovations with
//! $\Lambda \propto I$ in RMS-scaled units) over $(A, B, C, K)$ and, optionally, $D$ and the
//! initial state. [`Focus::Simulation`] fixes $K = 0$, so $\hat y$ is the simulated output and
//! the criterion is the output error (the noise model is then 1).
//!
//! # Parameterisation
//! Because the predictor is driven by measured signals only (no feedback from $\hat y$), a
//! block-diagonal $\bar A$ makes the predictor a sum of independent low-order filters, and so
//! makes the analytic gradient cheap. The start's $\bar A$ is brought to
//! $T^{-1} \bar A T = \mathrm{diag}(\bar A_1, \dots, \bar A_p)$ with $2 \times 2$ blocks (a complex
//! pair, or two real poles, sorted and paired) and at most one $1 \times 1$ block; the columns of $T$
//! for a block with characteristic polynomial $\pi_b(z)$ span the null space of $\pi_b(\bar A)$
//! (a real computation, no complex eigenvectors). Each $2 \times 2$ block is then put in the
//! **delta-operator companion form** whose output row $o_b$ (the output that sees the block most
//! strongly) is $[1\;0]$, by $x' = \mathcal O x$ with $\mathcal O = [c;\, c(\bar A_b - I)]$,
//! $c = C_{o_b}$:
//! $$ \bar A_b = I + \begin{bmatrix} 0 & 1 \\ -\alpha_2 & -\alpha_1 \end{bmatrix}, \quad
//! \det(zI - \bar A_b) = z^2 + (\alpha_1 - 2) z + (1 - \alpha_1 + \alpha_2), \quad
//! C_b = \begin{bmatrix} \vdots \\ 1 \;\; 0 \\ \vdots \end{bmatrix} \text{ (row } o_b\text{)}. $$
//! The second state is the first difference of the first, not its shifted copy: for strongly
//! oversampled data (poles near $z = 1$, as at 20 kHz) the ordinary companion form's two states
//! and the sensitivities to its two denominator coefficients are nearly collinear, the
//! delta form's are not.
//! The free parameters are, per block, $(\alpha_1, \alpha_2)$ (or the pole $\lambda$ of a $1 \times 1$
//! block), all entries of $G_b = [\bar B_b \;\; K_b]$ ($G_b = B_b$ under the simulation focus) and the
//! other rows of $C_b$; then $D$ (when estimated) and the initial state. This is locally
//! identifiable (per block $2(l + q)$ parameters for $l$ outputs and $q$ filter inputs, the
//! dimension of a McMillan-degree-2 block with given poles), covers real and complex poles alike
//! (a pair may move between the two during the iteration), and each block's companion form
//! is well conditioned because it is only of order two.
//!
//! The sensitivities $\partial \hat x / \partial\theta$ of a block parameter involve only that
//! block's two states: with $s_{k+1} = \bar A_b s_k + f_k$ and $f_k = [0; -x_{2,k}]$
//! for $\alpha_1$, $[0; -x_{1,k}]$ for $\alpha_2$, $e_r w_{c,k}$ for $G_b[r, c]$ (with $w = [u; y]$), and
//! $s_0 = e_r$, $f = 0$ for the initial state, $\partial \hat y_k / \partial \theta = C_b s_k$.
//! A Jacobian costs $O(N l\, n_\theta)$ and the Levenberg–Marquardt solver
//! ([`super::pem::lm`]) one QR of the $N l \times n_\theta$ Jacobian per iteration.
//!
//! The predictor must stay stable: a trial with a block outside the unit circle
//! ($|a_2| \ge 1$ or $|a_1| \ge 1 + a_2$ for $z^2 + a_1 z + a_2$) is inadmissible and the trust region shrinks. Nothing
//! else is constrained: $A = \bar A + K C$ may be unstable (an unstable plant identified with a
//! stable predictor) and is never stabilised.
//!
//! # Result
//! The returned model is in the block-companion coordinates (similar to the start's): $A = \bar
//! A + KC$, $B = \bar B + K D$, and $K$ (prediction focus) as [`SsPemFit::kalman_gain`]. The
//! parameter covariance is the sandwich $(J^\top J)^{-1} J^\top (\hat\Lambda \otimes I_N) J
//! (J^\top J)^{-1}$ of the final Jacobian in RMS-scaled units ($\hat\lambda (J^\top J)^{-1}$ for
//! one output); [`SsPemFit::frequency_response_std`] propagates it to the FRF of $(A, B, C, D)$.
//!
//! # Reference
//! L. Ljung, *System Identification: Theory for the User*, 2nd ed., Prentice Hall, 1999
//! (sections 4.3, 7.2 and 10.3: the innovation-form predictor, the criterion and its gradient);
//! T. McKelvey, A. Helmersson, T. Ribarits, "Data driven local coordinates for multivariable
//! linear systems and their application to system identification", *Automatica* 40, 2004
//! (why a full parameterisation needs coordinates; here the block-companion form provides them).
//!
//! # Example
//! ```
//! use ambid_core::estimate::ss_pem::{refine_ss, SsPemOptions};
//! use ambid_core::lti::StateSpace;
//! use faer::{mat, MatRef};
//! // truth: a lightly damped mode; start: the same with its poles and gain 3 % off
//! let ss = |r: f64, w: f64, g: f64| {
//!     let (re, im) = (r * w.cos(), r * w.sin());
//!     StateSpace::discrete(mat![[re, im], [-im, re]], mat![[g], [0.0]], mat![[0.0, 1.0]],
//!                          mat![[0.0]], 1.0).unwrap()
//! };
//! let truth = ss(0.97, 0.3, 1.0);
//! let u: Vec<f64> = (0..3000).map(|k| ((k * 7919 % 113) as f64 / 56.0 - 1.0)).collect();
//! let y = truth.simulate_siso(&u, None).unwrap();
//! let fit = refine_ss(MatRef::from_column_major_slice(&y, y.len(), 1),
//!                     MatRef::from_column_major_slice(&u, u.len(), 1),
//!                     &ss(0.96, 0.31, 1.03), None, &SsPemOptions::default()).unwrap();
//! let p = fit.fitted.model.poles().unwrap();
//! assert!(p.iter().all(|z| (z.norm() - 0.97).abs() < 1e-8 && (z.im.abs() - 0.97 * 0.3f64.sin()).abs() < 1e-8));
//! ```

use super::pem::lm::{all_finite, minimize, LeastSquaresProblem, LmOptions, LmReport};
use super::pem::Focus;
use super::{channel_rms, check_samples, Fitted};
use crate::error::{Error, Result};
use crate::linalg;
use crate::lti::StateSpace;
use faer::{c64, Mat, MatRef};

/// Options of [`refine_ss`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SsPemOptions {
    /// Criterion: [`Focus::Prediction`] (default: $K$ is estimated) or [`Focus::Simulation`]
    /// (output error, $K = 0$).
    pub focus: Focus,
    /// Levenberg–Marquardt settings; the default has `loss_tol` $10^{-10}$, which leaves the
    /// estimate within $\sqrt{N \tau} \approx 0.003$ standard deviations of the minimiser for
    /// $N = 10^5$.
    pub lm: LmOptions,
    /// Estimate the feedthrough $D$ (`true`) or keep the start's $D$ (`false`, the default).
    pub feedthrough: bool,
    /// Estimate the initial state (default `true`); otherwise it is zero.
    pub estimate_x0: bool,
}

impl Default for SsPemOptions {
    fn default() -> Self {
        Self {
            focus: Focus::Prediction,
            lm: LmOptions::default()
                .with_loss_tol(1e-10)
                .unwrap_or_default(),
            feedthrough: false,
            estimate_x0: true,
        }
    }
}

/// What [`refine_ss`] estimates.
#[derive(Debug, Clone)]
pub struct SsPemFit {
    /// The deterministic model $(A, B, C, D)$ from $u$ to $y$. `params` is $\theta$ of the module
    /// docs (RMS-scaled units; per block: denominator, $G_b$ row by row, the free rows of $C_b$;
    /// then $D$ row by row when estimated; then $x_0$), `covariance` its covariance, `loss` the
    /// trace of $\hat\Lambda$, `noise_variance` the loss times $N / (N - n_\theta)$.
    pub fitted: Fitted<StateSpace>,
    /// $K$ ($n \times l$) under [`Focus::Prediction`], `None` under [`Focus::Simulation`].
    pub kalman_gain: Option<Mat<f64>>,
    /// $\hat\Lambda = \frac1N \sum_k \varepsilon_k \varepsilon_k^\top$ ($l \times l$).
    pub innovation_covariance: Mat<f64>,
    /// Estimated initial state (zero when not estimated), in the coordinates of the returned
    /// model; under the prediction focus, of the predictor.
    pub x0: Vec<f64>,
    /// Loss of the start on the same criterion (with its initial state estimated too).
    pub start_loss: f64,
    /// The Levenberg–Marquardt run.
    pub report: LmReport,
    layout: Layout,
    scales: (Vec<f64>, Vec<f64>),
}

/// Refines `start` (with the Kalman gain `k`, $n \times l$, if known) by the prediction-error
/// method on `y` ($N \times l$) and `u` ($N \times m$), one row per sample (module docs).
///
/// Under [`Focus::Prediction`] a missing `k` starts from $K = 0$ (which needs a stable $A$).
/// Data are used as given (no mean removal).
///
/// # Errors
/// * [`Error::DimensionMismatch`]: `y`, `u`, `start` or `k` of inconsistent sizes.
/// * [`Error::NonFinite`]: a NaN or infinite sample.
/// * [`Error::InvalidArgument`]: an identically zero channel; fewer than $2 n_\theta$ samples.
/// * [`Error::Unstable`]: the start's predictor ($A - KC$, or $A$ under the simulation focus)
///   is not stable; use the prediction focus with a stabilising $K$ (e.g. from the subspace
///   fit), or identify the stable closed loop.
/// * [`Error::Numerical`]: the start cannot be brought to block form (a mode that no output
///   sees, or nearly repeated poles in different blocks); lower the order.
///
/// # Example
/// See the module docs.
pub fn refine_ss(
    y: MatRef<'_, f64>,
    u: MatRef<'_, f64>,
    start: &StateSpace,
    k: Option<MatRef<'_, f64>>,
    opts: &SsPemOptions,
) -> Result<SsPemFit> {
    let (nn, l, m, n) = (y.nrows(), y.ncols(), u.ncols(), start.order());
    let dim = |ctx: &'static str, e: String, g: String| {
        Err(Error::DimensionMismatch {
            context: ctx,
            expected: e,
            got: g,
        })
    };
    if u.nrows() != nn {
        return dim(
            "refine_ss: samples of y and u",
            nn.to_string(),
            u.nrows().to_string(),
        );
    }
    if start.ninputs() != m || start.noutputs() != l {
        return dim(
            "refine_ss: start model inputs × outputs",
            format!("{m} × {l} (the data's)"),
            format!("{} × {}", start.ninputs(), start.noutputs()),
        );
    }
    if let Some(k) = k {
        if k.nrows() != n || k.ncols() != l {
            return dim(
                "refine_ss: Kalman gain",
                format!("{n}×{l}"),
                format!("{}×{}", k.nrows(), k.ncols()),
            );
        }
    }
    if n == 0 || l == 0 || m == 0 {
        return Err(Error::invalid(
            "start",
            "the start model needs at least one state, input and output",
        ));
    }
    check_samples("y", y)?;
    check_samples("u", u)?;
    let sy = channel_rms("y", y)?;
    let su = channel_rms("u", u)?;
    let ts = start.ts().ok_or_else(|| {
        Error::invalid(
            "start",
            "the start model is continuous-time; refine_ss needs a discrete model with the data's sample time",
        )
    })?;
    // scaled model: u = su·u_s, y = sy·y_s
    let a = start.a().to_owned();
    let b = Mat::from_fn(n, m, |r, c| start.b()[(r, c)] * su[c]);
    let c = Mat::from_fn(l, n, |r, col| start.c()[(r, col)] / sy[r]);
    let d = Mat::from_fn(l, m, |r, col| start.d()[(r, col)] * su[col] / sy[r]);
    let predict = opts.focus == Focus::Prediction;
    let kk = match (predict, k) {
        (true, Some(k)) => Mat::from_fn(n, l, |r, col| k[(r, col)] * sy[col]),
        _ => Mat::zeros(n, l),
    };
    let abar = &a - &kk * &c;
    let q = if predict { m + l } else { m };
    let g = Mat::from_fn(n, q, |r, col| {
        if col < m {
            b[(r, col)] - (0..l).map(|o| kk[(r, o)] * d[(o, col)]).sum::<f64>()
        } else {
            kk[(r, col - m)]
        }
    });
    let poles = linalg::eigenvalues(abar.as_ref())?;
    let rho = poles.iter().map(|z| z.norm()).fold(0.0, f64::max);
    if rho >= 1.0 {
        return Err(Error::Unstable {
            context: "refine_ss",
            reason: format!(
                "the start's predictor has a pole of modulus {rho:.6} (≥ 1): {}",
                if predict {
                    "A − KC must be stable; give the Kalman gain of the subspace fit, or identify the stable closed loop (r → y)"
                } else {
                    "the simulation focus needs a stable A; use the prediction focus with a Kalman gain, or identify the stable closed loop (r → y)"
                }
            ),
        });
    }
    let (layout, theta0) = to_blocks(
        abar.as_ref(),
        g.as_ref(),
        c.as_ref(),
        d.as_ref(),
        &poles,
        opts,
    )?;
    let n_theta = layout.n_params();
    if nn < 2 * n_theta {
        return Err(Error::invalid(
            "y",
            format!("too few samples: {nn} for {n_theta} parameters (at least {} needed); record longer or lower the order", 2 * n_theta),
        ));
    }
    let ys: Vec<Vec<f64>> = sy
        .iter()
        .enumerate()
        .map(|(o, &s)| scaled_channel(y, o, s))
        .collect();
    let mut w = Vec::with_capacity(q);
    for (ch, &s) in su.iter().enumerate() {
        w.push(scaled_channel(u, ch, s));
    }
    if predict {
        w.extend(ys.iter().cloned());
    }
    let mut prob = Problem {
        lay: &layout,
        w: &w,
        y: &ys,
    };
    // start from the best initial state for the start's other parameters (one linear step)
    let theta0 = if opts.estimate_x0 {
        best_x0(&mut prob, theta0)
    } else {
        theta0
    };
    let start_loss = prob
        .residuals(&theta0)
        .map_or(f64::INFINITY, |r| physical_loss(&r, nn, &sy));
    let (theta, report) = minimize(&mut prob, &theta0, &opts.lm)?;
    let res = prob.residuals(&theta).ok_or_else(|| {
        Error::numerical(
            "refine_ss",
            "the refined predictor is not admissible; this should not happen, please report it",
        )
    })?;
    let jac = prob.jacobian(&theta).ok_or_else(|| {
        Error::numerical("refine_ss", "the final Jacobian could not be evaluated")
    })?;
    // innovation covariance (scaled) and parameter covariance
    let lam_s = Mat::from_fn(l, l, |p, r| {
        (0..nn)
            .map(|t| res[p * nn + t] * res[r * nn + t])
            .sum::<f64>()
            / nn as f64
    });
    let covariance = sandwich(jac.as_ref(), lam_s.as_ref(), nn, n_theta);
    let (model, kalman_gain) = layout.model(&theta, predict, (&sy, &su), ts)?;
    let x0 = layout.matrices(&theta).4;
    let lam = Mat::from_fn(l, l, |p, r| lam_s[(p, r)] * sy[p] * sy[r]);
    let loss = (0..l).map(|o| lam[(o, o)]).sum::<f64>();
    Ok(SsPemFit {
        fitted: Fitted {
            model,
            params: theta,
            covariance,
            loss,
            noise_variance: loss * nn as f64 / (nn - n_theta) as f64,
            n_samples: nn,
        },
        kalman_gain,
        innovation_covariance: lam,
        x0,
        start_loss,
        report,
        layout,
        scales: (sy, su),
    })
}

/// Loss $\sum_o s_o^2 \frac1N \sum_k r_{oN+k}^2$ in physical units of output-major scaled
/// residuals `r` ($N$ per output, output scales `sy`).
fn physical_loss(r: &[f64], nn: usize, sy: &[f64]) -> f64 {
    sy.iter()
        .enumerate()
        .map(|(o, s)| {
            s * s * r[o * nn..(o + 1) * nn].iter().map(|v| v * v).sum::<f64>() / nn as f64
        })
        .sum()
}

impl SsPemFit {
    /// Standard deviation of the frequency response of the deterministic model at `f_hz`
    /// (entry $(o, c)$ of each matrix: output $o$, input $c$), by first-order propagation of the
    /// parameter covariance: $\sigma^2 = g^\top P g$ with $g$ the gradient of the real and
    /// imaginary parts; the returned value is $\sqrt{\sigma_{\mathrm{re}}^2 + \sigma_{\mathrm{im}}^2}$.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when no covariance is available; errors of the frequency response.
    pub fn frequency_response_std(&self, f_hz: &[f64]) -> Result<Vec<Mat<f64>>> {
        let p = self.fitted.covariance.as_ref().ok_or_else(|| {
            Error::invalid(
                "covariance",
                "the parameter covariance is not available (singular final Jacobian)",
            )
        })?;
        let ts = self.fitted.model.ts().unwrap_or(1.0);
        let theta = &self.fitted.params;
        let (sy, su) = &self.scales;
        let predict = self.kalman_gain.is_some();
        let resp = |th: &[f64]| -> Result<Vec<Mat<c64>>> {
            self.layout
                .model(th, predict, (sy, su), ts)?
                .0
                .freq_response(f_hz)
        };
        let base = resp(theta)?;
        let np = theta.len();
        let mut grads = Vec::with_capacity(np);
        for j in 0..np {
            let h = 1e-7 * theta[j].abs().max(1e-3);
            let mut tp = theta.clone();
            tp[j] += h;
            let rp = resp(&tp)?;
            tp[j] = theta[j] - h;
            let rm = resp(&tp)?;
            grads.push(
                rp.iter()
                    .zip(&rm)
                    .map(|(a, b)| {
                        Mat::from_fn(a.nrows(), a.ncols(), |r, c| {
                            (a[(r, c)] - b[(r, c)]) / (2.0 * h)
                        })
                    })
                    .collect::<Vec<_>>(),
            );
        }
        Ok(base
            .iter()
            .enumerate()
            .map(|(fi, h0)| {
                Mat::from_fn(h0.nrows(), h0.ncols(), |r, c| {
                    let mut v = 0.0;
                    for i in 0..np {
                        for j in 0..np {
                            let gi = grads[i][fi][(r, c)];
                            let gj = grads[j][fi][(r, c)];
                            v += p[(i, j)] * (gi.re * gj.re + gi.im * gj.im);
                        }
                    }
                    v.max(0.0).sqrt()
                })
            })
            .collect())
    }
}

/// Column `c` of `x` divided by `s`.
fn scaled_channel(x: MatRef<'_, f64>, c: usize, s: f64) -> Vec<f64> {
    x.col(c).iter().map(|v| v / s).collect()
}

/// One block of the block-diagonal predictor.
#[derive(Debug, Clone, Copy)]
struct Block {
    /// 1 or 2 states.
    dim: usize,
    /// First parameter of the block in θ.
    off: usize,
    /// First state of the block.
    state: usize,
    /// Output row of $C_b$ fixed at $[1\;0]$ (or 1).
    fixed_row: usize,
}

/// Where everything lives in θ.
#[derive(Debug, Clone)]
struct Layout {
    blocks: Vec<Block>,
    n: usize,
    l: usize,
    m: usize,
    q: usize,
    /// Offset of D in θ (when estimated).
    d_off: Option<usize>,
    /// The fixed D (scaled) when not estimated.
    d_fixed: Mat<f64>,
    /// Offset of x0 in θ (when estimated).
    x0_off: Option<usize>,
    n_theta: usize,
}

impl Layout {
    fn n_params(&self) -> usize {
        self.n_theta
    }
    /// Offset of $G_b[r, c]$.
    fn g_idx(&self, b: &Block, r: usize, c: usize) -> usize {
        b.off + b.dim + r * self.q + c
    }
    /// Offset of $C_b[o, r]$ for a free row `o` (`None` for the fixed row).
    fn c_idx(&self, b: &Block, o: usize, r: usize) -> Option<usize> {
        if o == b.fixed_row {
            return None;
        }
        let rank = if o < b.fixed_row { o } else { o - 1 };
        Some(b.off + b.dim + b.dim * self.q + rank * b.dim + r)
    }
    fn c_val(&self, th: &[f64], b: &Block, o: usize, r: usize) -> f64 {
        match self.c_idx(b, o, r) {
            Some(i) => th[i],
            None => {
                if r == 0 {
                    1.0
                } else {
                    0.0
                }
            }
        }
    }
    fn d_val(&self, th: &[f64], o: usize, c: usize) -> f64 {
        match self.d_off {
            Some(off) => th[off + o * self.m + c],
            None => self.d_fixed[(o, c)],
        }
    }
    fn x0_val(&self, th: &[f64], s: usize) -> f64 {
        self.x0_off.map_or(0.0, |off| th[off + s])
    }
    /// $(\bar A, G, C, D, x_0)$ of θ (scaled units).
    #[allow(clippy::type_complexity)]
    fn matrices(&self, th: &[f64]) -> (Mat<f64>, Mat<f64>, Mat<f64>, Mat<f64>, Vec<f64>) {
        let (n, l, m, q) = (self.n, self.l, self.m, self.q);
        let mut a = Mat::<f64>::zeros(n, n);
        let mut g = Mat::<f64>::zeros(n, q);
        let mut c = Mat::<f64>::zeros(l, n);
        for b in &self.blocks {
            let s = b.state;
            if b.dim == 2 {
                a[(s, s)] = 1.0;
                a[(s, s + 1)] = 1.0;
                a[(s + 1, s)] = -th[b.off + 1];
                a[(s + 1, s + 1)] = 1.0 - th[b.off];
            } else {
                a[(s, s)] = th[b.off];
            }
            for r in 0..b.dim {
                for ch in 0..q {
                    g[(s + r, ch)] = th[self.g_idx(b, r, ch)];
                }
                for o in 0..l {
                    c[(o, s + r)] = self.c_val(th, b, o, r);
                }
            }
        }
        let d = Mat::from_fn(l, m, |o, ch| self.d_val(th, o, ch));
        let x0 = (0..n).map(|s| self.x0_val(th, s)).collect();
        (a, g, c, d, x0)
    }
    /// The innovation model of θ in physical units: $(A, B, C, D)$ with $A = \bar A + KC$,
    /// $B = \bar B + KD$, scaled back by the output scales `sy` and input scales `su`, and $K$
    /// (prediction focus).
    fn model(
        &self,
        th: &[f64],
        predict: bool,
        (sy, su): (&[f64], &[f64]),
        ts: f64,
    ) -> Result<(StateSpace, Option<Mat<f64>>)> {
        let (abar, g, c, d, _) = self.matrices(th);
        let (n, m, l) = (self.n, self.m, self.l);
        let kk = if predict {
            g.subcols(m, l).to_owned()
        } else {
            Mat::zeros(n, l)
        };
        let a = &abar + &kk * &c;
        let b = &g.subcols(0, m).to_owned() + &kk * &d;
        let b = Mat::from_fn(n, m, |r, col| b[(r, col)] / su[col]);
        let c = Mat::from_fn(l, n, |r, col| c[(r, col)] * sy[r]);
        let d = Mat::from_fn(l, m, |r, col| d[(r, col)] * sy[r] / su[col]);
        let k = predict.then(|| Mat::from_fn(n, l, |r, col| kk[(r, col)] / sy[col]));
        Ok((StateSpace::discrete(a, b, c, d, ts)?, k))
    }
    fn admissible(&self, th: &[f64]) -> bool {
        th.iter().all(|v| v.is_finite())
            && self.blocks.iter().all(|b| {
                if b.dim == 2 {
                    let (a1, a2) = companion(th[b.off], th[b.off + 1]);
                    a2.abs() < 1.0 && a1.abs() < 1.0 + a2
                } else {
                    th[b.off].abs() < 1.0
                }
            })
    }
}

/// $(a_1, a_2)$ of $z^2 + a_1 z + a_2$ for the delta-companion parameters $(\alpha_1, \alpha_2)$.
fn companion(al1: f64, al2: f64) -> (f64, f64) {
    (al1 - 2.0, 1.0 - al1 + al2)
}

/// Block decomposition of the start (module docs): the layout and θ₀ (x0 = 0).
fn to_blocks(
    abar: MatRef<'_, f64>,
    g: MatRef<'_, f64>,
    c: MatRef<'_, f64>,
    d: MatRef<'_, f64>,
    poles: &[c64],
    opts: &SsPemOptions,
) -> Result<(Layout, Vec<f64>)> {
    let (n, q, l, m) = (abar.nrows(), g.ncols(), c.nrows(), d.ncols());
    // groups of poles: (a1, a2) of z² + a1 z + a2, or (−λ) of z − λ
    let mut complex: Vec<c64> = poles.iter().copied().filter(|z| z.im > 0.0).collect();
    complex.sort_by(|x, y| x.im.total_cmp(&y.im));
    let n_complex_neg = poles.iter().filter(|z| z.im < 0.0).count();
    let mut real: Vec<f64> = poles.iter().filter(|z| z.im == 0.0).map(|z| z.re).collect();
    if n_complex_neg != complex.len() {
        return Err(Error::numerical(
            "refine_ss",
            "the eigenvalues of the predictor do not come in conjugate pairs",
        ));
    }
    real.sort_by(f64::total_cmp);
    let mut polys: Vec<Vec<f64>> = complex
        .iter()
        .map(|z| vec![-2.0 * z.re, z.norm_sqr()])
        .collect();
    for pair in real.chunks(2) {
        if pair.len() == 2 {
            polys.push(vec![-(pair[0] + pair[1]), pair[0] * pair[1]]);
        } else {
            polys.push(vec![-pair[0]]);
        }
    }
    // invariant subspaces: null space of π(Ā)
    let eye = Mat::<f64>::identity(n, n);
    let a2 = abar * abar;
    let mut t = Mat::<f64>::zeros(n, n);
    let mut col = 0;
    for p in &polys {
        let pm = if p.len() == 2 {
            &a2 + abar * p[0] + &eye * p[1]
        } else {
            abar.to_owned() + &eye * p[0]
        };
        let svd = pm
            .svd()
            .map_err(|e| Error::numerical("refine_ss", format!("SVD failed: {e:?}")))?;
        let s = svd.S().column_vector();
        let mut idx: Vec<usize> = (0..n).collect();
        idx.sort_by(|&x, &y| s[x].total_cmp(&s[y]));
        for &k in idx.iter().take(p.len()) {
            for r in 0..n {
                t[(r, col)] = svd.V()[(r, k)];
            }
            col += 1;
        }
    }
    let sv = linalg::singular_values(t.as_ref())?;
    if sv.last().copied().unwrap_or(0.0) <= 1e-10 * sv[0] {
        return Err(Error::numerical(
            "refine_ss",
            "the start model has (nearly) repeated poles in different blocks, so it cannot be put in block form; lower the order",
        ));
    }
    let tinv = linalg::solve(t.as_ref(), eye.as_ref())?;
    let ab = &tinv * abar * &t;
    let gb = &tinv * g;
    let cb = c * &t;
    // per block: companion form with C_b[o_b] = [1 0]
    let mut blocks = Vec::new();
    let mut theta = Vec::new();
    let mut state = 0;
    for p in &polys {
        let dim = p.len();
        let ad = ab.submatrix(state, state, dim, dim);
        let cbk = cb.subcols(state, dim);
        let fixed_row = (0..l)
            .max_by(|&x, &y| {
                let nx: f64 = (0..dim).map(|r| cbk[(x, r)].powi(2)).sum();
                let ny: f64 = (0..dim).map(|r| cbk[(y, r)].powi(2)).sum();
                nx.total_cmp(&ny)
            })
            .unwrap_or(0);
        // x' = O x
        let o = if dim == 2 {
            let c0 = [cbk[(fixed_row, 0)], cbk[(fixed_row, 1)]];
            // c (A_b − I): the delta-operator companion form (module docs)
            let c1 = [
                c0[0] * (ad[(0, 0)] - 1.0) + c0[1] * ad[(1, 0)],
                c0[0] * ad[(0, 1)] + c0[1] * (ad[(1, 1)] - 1.0),
            ];
            faer::mat![[c0[0], c0[1]], [c1[0], c1[1]]]
        } else {
            faer::mat![[cbk[(fixed_row, 0)]]]
        };
        let osv = linalg::singular_values(o.as_ref())?;
        let scale_c: f64 = (0..dim)
            .map(|r| cbk[(fixed_row, r)].powi(2))
            .sum::<f64>()
            .sqrt();
        if osv.last().copied().unwrap_or(0.0) <= 1e-9 * osv[0].max(f64::MIN_POSITIVE)
            || scale_c == 0.0
        {
            return Err(Error::numerical(
                "refine_ss",
                "a mode of the start model is (nearly) unobservable from every output; lower the order",
            ));
        }
        let oinv = linalg::solve(o.as_ref(), Mat::<f64>::identity(dim, dim).as_ref())?;
        let off = theta.len();
        if dim == 2 {
            // z² + a1 z + a2 = det(zI − A_b), α1 = a1 + 2, α2 = a2 − 1 + α1
            let a1 = -(ad[(0, 0)] + ad[(1, 1)]);
            let a2 = ad[(0, 0)] * ad[(1, 1)] - ad[(0, 1)] * ad[(1, 0)];
            theta.push(a1 + 2.0);
            theta.push(a2 + a1 + 1.0);
        } else {
            theta.push(ad[(0, 0)]);
        }
        let gnew = &o * gb.subrows(state, dim);
        for r in 0..dim {
            for ch in 0..q {
                theta.push(gnew[(r, ch)]);
            }
        }
        let cnew = cbk * &oinv;
        for oo in 0..l {
            if oo != fixed_row {
                for r in 0..dim {
                    theta.push(cnew[(oo, r)]);
                }
            }
        }
        blocks.push(Block {
            dim,
            off,
            state,
            fixed_row,
        });
        state += dim;
    }
    let d_off = if opts.feedthrough {
        let off = theta.len();
        for o in 0..l {
            for ch in 0..m {
                theta.push(d[(o, ch)]);
            }
        }
        Some(off)
    } else {
        None
    };
    let x0_off = if opts.estimate_x0 {
        let off = theta.len();
        theta.extend(std::iter::repeat_n(0.0, n));
        Some(off)
    } else {
        None
    };
    let layout = Layout {
        blocks,
        n,
        l,
        m,
        q,
        d_off,
        d_fixed: d.to_owned(),
        x0_off,
        n_theta: theta.len(),
    };
    Ok((layout, theta))
}

/// The predictor criterion on scaled data: residuals output-major, $r_{oN + k} = y_{o,k} - \hat y_{o,k}$.
struct Problem<'a> {
    lay: &'a Layout,
    /// Filter inputs $w$ ($q$ channels).
    w: &'a [Vec<f64>],
    /// Outputs ($l$ channels).
    y: &'a [Vec<f64>],
}

impl Problem<'_> {
    fn len(&self) -> usize {
        self.y.first().map_or(0, |v| v.len())
    }
    /// Runs block `b`'s dynamics $s_{k+1} = \bar A_b s_k + f_k$ from `s0` (the forcing `f(r, k)`
    /// for state `r`; the second state is unused for a $1 \times 1$ block) and hands each
    /// $(k, s_k)$ to `sink`.
    fn run_block(
        &self,
        th: &[f64],
        b: &Block,
        s0: [f64; 2],
        f: impl Fn(usize, usize) -> f64,
        mut sink: impl FnMut(usize, f64, f64),
    ) {
        let (mut s1, mut s2) = (s0[0], s0[1]);
        if b.dim == 2 {
            let (al1, al2) = (th[b.off], th[b.off + 1]);
            for k in 0..self.len() {
                sink(k, s1, s2);
                let n1 = s1 + s2 + f(0, k);
                let n2 = -al2 * s1 + (1.0 - al1) * s2 + f(1, k);
                s1 = n1;
                s2 = n2;
            }
        } else {
            let lam = th[b.off];
            for k in 0..self.len() {
                sink(k, s1, 0.0);
                s1 = lam * s1 + f(0, k);
            }
        }
    }
    /// State trajectory of block `b` (`dim` rows of length N) driven by $G_b w$ from its
    /// initial state.
    fn states(&self, th: &[f64], b: &Block) -> Vec<Vec<f64>> {
        let nn = self.len();
        let lay = self.lay;
        let gcoef: Vec<Vec<f64>> = (0..b.dim)
            .map(|r| (0..lay.q).map(|c| th[lay.g_idx(b, r, c)]).collect())
            .collect();
        let drive = |r: usize, k: usize| -> f64 {
            gcoef[r]
                .iter()
                .zip(self.w)
                .map(|(g, w)| g * w[k])
                .sum::<f64>()
        };
        let s0 = [lay.x0_val(th, b.state), lay.x0_val(th, b.state + b.dim - 1)];
        let mut x = vec![vec![0.0; nn]; b.dim];
        self.run_block(th, b, s0, drive, |k, s1, s2| {
            x[0][k] = s1;
            if let Some(x2) = x.get_mut(1) {
                x2[k] = s2;
            }
        });
        x
    }
    /// Runs block `b`'s dynamics from `s0` with the forcing `f(r, k)` and writes
    /// $-C_b s_k$ into column `col` of `jac` (rows $oN + k$), without storing $s$.
    fn sensitivity_into(
        &self,
        th: &[f64],
        b: &Block,
        s0: [f64; 2],
        f: impl Fn(usize, usize) -> f64,
        jac: &mut Mat<f64>,
        col: usize,
    ) {
        let nn = self.len();
        let cr: Vec<[f64; 2]> = (0..self.lay.l)
            .map(|o| {
                let mut c = [0.0; 2];
                for (r, cv) in c.iter_mut().enumerate().take(b.dim) {
                    *cv = self.lay.c_val(th, b, o, r);
                }
                c
            })
            .collect();
        let mut out = jac.col_mut(col);
        self.run_block(th, b, s0, f, |k, s1, s2| {
            for (o, c) in cr.iter().enumerate() {
                out[o * nn + k] = -(c[0] * s1 + c[1] * s2);
            }
        });
    }
}

/// One run of a block's dynamics for [`Problem::sensitivities_into`]: start state, forcing of
/// each state row (`None`: 0.0) and the column of the Jacobian it fills.
struct Run<'s> {
    s0: [f64; 2],
    f: [Option<&'s [f64]>; 2],
    col: usize,
}

impl Problem<'_> {
    /// [`Problem::sensitivity_into`] for several runs of block `b` at once, interleaved sample by
    /// sample (each run alone is bound by the latency of its recursion); every entry is computed
    /// by the same operations in the same order as one `sensitivity_into` per run. The columns
    /// of `runs` must be distinct.
    fn sensitivities_into(&self, th: &[f64], b: &Block, runs: &[Run<'_>], jac: &mut Mat<f64>) {
        let nn = self.len();
        let cr: Vec<[f64; 2]> = (0..self.lay.l)
            .map(|o| {
                let mut c = [0.0; 2];
                for (r, cv) in c.iter_mut().enumerate().take(b.dim) {
                    *cv = self.lay.c_val(th, b, o, r);
                }
                c
            })
            .collect();
        let mut cols: Vec<Option<&mut [f64]>> = jac
            .col_iter_mut()
            .map(|c| c.try_as_col_major_mut().map(|c| c.as_slice_mut()))
            .collect();
        let outs: Option<Vec<&mut [f64]>> = runs
            .iter()
            .map(|r| cols.get_mut(r.col).and_then(Option::take))
            .collect();
        let Some(mut outs) = outs.filter(|o| o.iter().all(|c| c.len() >= nn * cr.len())) else {
            drop(cols);
            for r in runs {
                let f = |rr: usize, k: usize| r.f[rr].map_or(0.0, |v| v[k]);
                self.sensitivity_into(th, b, r.s0, f, jac, r.col);
            }
            return;
        };
        // no forcing: +0.0, read like any other forcing (the same value as the literal)
        let zeros = vec![0.0; nn];
        let dynamics = if b.dim == 2 {
            Dynamics::Pair(th[b.off], th[b.off + 1])
        } else {
            Dynamics::Single(th[b.off])
        };
        for (rs, os) in runs.chunks(4).zip(outs.chunks_mut(4)) {
            let f = |i: usize| -> [&[f64]; 2] {
                let g = |r: usize| rs[i].f[r].unwrap_or(&zeros[..]);
                [g(0), g(1)]
            };
            let s0 = |i: usize| rs[i].s0;
            match os {
                [a] => run_chunk(dynamics, &cr, [s0(0)], [f(0)], [a], nn),
                [a, b] => run_chunk(dynamics, &cr, [s0(0), s0(1)], [f(0), f(1)], [a, b], nn),
                [a, b, c] => run_chunk(
                    dynamics,
                    &cr,
                    [s0(0), s0(1), s0(2)],
                    [f(0), f(1), f(2)],
                    [a, b, c],
                    nn,
                ),
                [a, b, c, d] => run_chunk(
                    dynamics,
                    &cr,
                    [s0(0), s0(1), s0(2), s0(3)],
                    [f(0), f(1), f(2), f(3)],
                    [a, b, c, d],
                    nn,
                ),
                _ => {}
            }
        }
    }
}

/// A block's state update: $(\alpha_1, \alpha_2)$ of a $2 \times 2$ block, or $\lambda$ of a
/// $1 \times 1$ block.
#[derive(Debug, Clone, Copy)]
enum Dynamics {
    Pair(f64, f64),
    Single(f64),
}

/// `R` runs of one block interleaved: [`Problem::run_block`] with the sink of
/// [`Problem::sensitivity_into`] (outputs `cr`, $N$ = `nn` samples each), per run.
fn run_chunk<const R: usize>(
    dynamics: Dynamics,
    cr: &[[f64; 2]],
    s0: [[f64; 2]; R],
    f: [[&[f64]; 2]; R],
    outs: [&mut &mut [f64]; R],
    nn: usize,
) {
    let mut s1: [f64; R] = std::array::from_fn(|i| s0[i][0]);
    let mut s2: [f64; R] = std::array::from_fn(|i| s0[i][1]);
    match dynamics {
        Dynamics::Pair(al1, al2) => {
            for k in 0..nn {
                for i in 0..R {
                    let (a, c) = (s1[i], s2[i]);
                    for (o, cc) in cr.iter().enumerate() {
                        outs[i][o * nn + k] = -(cc[0] * a + cc[1] * c);
                    }
                    s1[i] = a + c + f[i][0][k];
                    s2[i] = -al2 * a + (1.0 - al1) * c + f[i][1][k];
                }
            }
        }
        Dynamics::Single(lam) => {
            for k in 0..nn {
                for i in 0..R {
                    let a = s1[i];
                    for (o, cc) in cr.iter().enumerate() {
                        outs[i][o * nn + k] = -(cc[0] * a + cc[1] * 0.0);
                    }
                    s1[i] = lam * a + f[i][0][k];
                }
            }
        }
    }
}

impl LeastSquaresProblem for Problem<'_> {
    fn residuals(&mut self, th: &[f64]) -> Option<Vec<f64>> {
        let lay = self.lay;
        if !lay.admissible(th) {
            return None;
        }
        let nn = self.len();
        let mut r: Vec<f64> = self.y.iter().flat_map(|v| v.iter().copied()).collect();
        for b in &lay.blocks {
            let x = self.states(th, b);
            for o in 0..lay.l {
                for (rr, xr) in x.iter().enumerate() {
                    let cv = lay.c_val(th, b, o, rr);
                    if cv != 0.0 {
                        for (res, xv) in r[o * nn..(o + 1) * nn].iter_mut().zip(xr) {
                            *res -= cv * xv;
                        }
                    }
                }
            }
        }
        for o in 0..lay.l {
            for ch in 0..lay.m {
                let dv = lay.d_val(th, o, ch);
                if dv != 0.0 {
                    for (res, uv) in r[o * nn..(o + 1) * nn].iter_mut().zip(&self.w[ch]) {
                        *res -= dv * uv;
                    }
                }
            }
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    fn jacobian(&mut self, th: &[f64]) -> Option<Mat<f64>> {
        let lay = self.lay;
        if !lay.admissible(th) {
            return None;
        }
        let nn = self.len();
        let mut jac = Mat::<f64>::zeros(nn * lay.l, lay.n_theta);
        for b in &lay.blocks {
            let x = self.states(th, b);
            let neg: Vec<Vec<f64>> = if b.dim == 2 {
                x.iter().map(|v| v.iter().map(|a| -a).collect()).collect()
            } else {
                Vec::new()
            };
            let mut runs = Vec::new();
            // denominator
            if let [n1, n2] = &neg[..] {
                runs.push(Run {
                    s0: [0.0; 2],
                    f: [None, Some(n2)],
                    col: b.off,
                });
                runs.push(Run {
                    s0: [0.0; 2],
                    f: [None, Some(n1)],
                    col: b.off + 1,
                });
            } else {
                runs.push(Run {
                    s0: [0.0; 2],
                    f: [Some(&x[0]), None],
                    col: b.off,
                });
            }
            // G
            for r in 0..b.dim {
                for ch in 0..lay.q {
                    let mut f = [None, None];
                    f[r] = Some(&self.w[ch][..]);
                    runs.push(Run {
                        s0: [0.0; 2],
                        f,
                        col: lay.g_idx(b, r, ch),
                    });
                }
            }
            // initial state
            if let Some(off) = lay.x0_off {
                for r in 0..b.dim {
                    let mut s0 = [0.0; 2];
                    s0[r] = 1.0;
                    runs.push(Run {
                        s0,
                        f: [None, None],
                        col: off + b.state + r,
                    });
                }
            }
            self.sensitivities_into(th, b, &runs, &mut jac);
            // free rows of C
            for o in 0..lay.l {
                for (r, xr) in x.iter().enumerate() {
                    if let Some(idx) = lay.c_idx(b, o, r) {
                        let mut out = jac.col_mut(idx);
                        for (k, v) in xr.iter().enumerate() {
                            out[o * nn + k] = -v;
                        }
                    }
                }
            }
        }
        if let Some(off) = lay.d_off {
            for o in 0..lay.l {
                for ch in 0..lay.m {
                    let mut out = jac.col_mut(off + o * lay.m + ch);
                    for (k, v) in self.w[ch].iter().enumerate() {
                        out[o * nn + k] = -v;
                    }
                }
            }
        }
        let finite = (0..jac.ncols()).all(|j| all_finite(jac.col_as_slice(j)));
        finite.then_some(jac)
    }
}

/// θ with the initial state replaced by its least-squares value for the other parameters
/// (the residuals are affine in $x_0$).
fn best_x0(prob: &mut Problem<'_>, theta: Vec<f64>) -> Vec<f64> {
    let Some(off) = prob.lay.x0_off else {
        return theta;
    };
    let n = prob.lay.n;
    let Some(r) = prob.residuals(&theta) else {
        return theta;
    };
    // only the n columns of the initial state
    let mut jx = Mat::<f64>::zeros(r.len(), n);
    for b in &prob.lay.blocks {
        let runs: Vec<Run<'_>> = (0..b.dim)
            .map(|k| {
                let mut s0 = [0.0; 2];
                s0[k] = 1.0;
                Run {
                    s0,
                    f: [None, None],
                    col: b.state + k,
                }
            })
            .collect();
        prob.sensitivities_into(&theta, b, &runs, &mut jx);
    }
    let rhs = Mat::from_fn(r.len(), 1, |k, _| r[k]);
    match linalg::lstsq(jx.as_ref(), rhs.as_ref()) {
        Ok(dx) => {
            let mut th = theta;
            for s in 0..n {
                th[off + s] -= dx[(s, 0)];
            }
            th
        }
        Err(_) => theta,
    }
}

/// $(J^\top J)^{-1} J^\top (\Lambda \otimes I) J (J^\top J)^{-1}$, `None` when $J^\top J$ is singular.
fn sandwich(j: MatRef<'_, f64>, lam: MatRef<'_, f64>, nn: usize, np: usize) -> Option<Mat<f64>> {
    let l = lam.nrows();
    let jtj = j.transpose() * j;
    let sv = linalg::singular_values(jtj.as_ref()).ok()?;
    if sv.last().copied().unwrap_or(0.0) <= 1e-14 * sv.first().copied().unwrap_or(0.0) {
        return None;
    }
    let inv = linalg::solve(jtj.as_ref(), Mat::<f64>::identity(np, np).as_ref()).ok()?;
    let mut mid = Mat::<f64>::zeros(np, np);
    for p in 0..l {
        for r in 0..l {
            let jp = j.subrows(p * nn, nn);
            let jr = j.subrows(r * nn, nn);
            mid += (jp.transpose() * jr) * lam[(p, r)];
        }
    }
    Some(&inv * &mid * &inv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    /// Analytic Jacobian against central differences of the residuals, MIMO with a real pole
    /// pair, a complex pair and a single real pole, D and x0 estimated, prediction focus.
    #[test]
    fn jacobian_matches_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (n, m, l, nn) = (5, 2, 2, 300);
        let a = faer::mat![
            [0.5, 0.3, 0.0, 0.0, 0.0],
            [-0.3, 0.5, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.8, 0.1, 0.0],
            [0.0, 0.0, 0.0, 0.6, 0.0],
            [0.0, 0.0, 0.0, 0.0, -0.4]
        ];
        let b = Mat::from_fn(n, m, |_, _| rng.sample::<f64, _>(StandardNormal));
        let c = Mat::from_fn(l, n, |_, _| rng.sample::<f64, _>(StandardNormal));
        let d = Mat::from_fn(l, m, |_, _| rng.sample::<f64, _>(StandardNormal));
        let k = Mat::from_fn(n, l, |_, _| 0.05 * rng.sample::<f64, _>(StandardNormal));
        let opts = SsPemOptions {
            feedthrough: true,
            ..SsPemOptions::default()
        };
        let abar = &a - &k * &c;
        let g = Mat::from_fn(n, m + l, |r, col| {
            if col < m {
                b[(r, col)] - (0..l).map(|o| k[(r, o)] * d[(o, col)]).sum::<f64>()
            } else {
                k[(r, col - m)]
            }
        });
        let poles = linalg::eigenvalues(abar.as_ref()).unwrap();
        let (lay, mut th) = to_blocks(
            abar.as_ref(),
            g.as_ref(),
            c.as_ref(),
            d.as_ref(),
            &poles,
            &opts,
        )
        .unwrap();
        for (i, v) in th.iter_mut().enumerate().skip(lay.x0_off.unwrap()) {
            *v = 0.1 * (i as f64).sin();
        }
        let w: Vec<Vec<f64>> = (0..m + l)
            .map(|_| (0..nn).map(|_| rng.sample(StandardNormal)).collect())
            .collect();
        let y: Vec<Vec<f64>> = (0..l)
            .map(|_| (0..nn).map(|_| rng.sample(StandardNormal)).collect())
            .collect();
        let mut p = Problem {
            lay: &lay,
            w: &w,
            y: &y,
        };
        let j = p.jacobian(&th).unwrap();
        let mut worst: f64 = 0.0;
        for col in 0..th.len() {
            let h = 1e-6;
            let mut tp = th.clone();
            tp[col] += h;
            let rp = p.residuals(&tp).unwrap();
            tp[col] -= 2.0 * h;
            let rm = p.residuals(&tp).unwrap();
            let scale = (0..j.nrows())
                .map(|r| j[(r, col)].abs())
                .fold(1e-3, f64::max);
            for r in 0..j.nrows() {
                let fd = (rp[r] - rm[r]) / (2.0 * h);
                worst = worst.max((fd - j[(r, col)]).abs() / scale);
            }
        }
        assert!(worst < 1e-6, "worst relative Jacobian error {worst:e}");
        // the block form reproduces the start's predictor: residuals equal a direct simulation
        let (ab, gb, cb, db, x0) = lay.matrices(&th);
        let mut x = x0.clone();
        let r = p.residuals(&th).unwrap();
        let mut worst = 0.0f64;
        for t in 0..nn {
            for o in 0..l {
                let mut yh = 0.0;
                for s in 0..n {
                    yh += cb[(o, s)] * x[s];
                }
                for ch in 0..m {
                    yh += db[(o, ch)] * w[ch][t];
                }
                worst = worst.max((y[o][t] - yh - r[o * nn + t]).abs());
            }
            let xn: Vec<f64> = (0..n)
                .map(|s| {
                    (0..n).map(|q| ab[(s, q)] * x[q]).sum::<f64>()
                        + (0..m + l).map(|ch| gb[(s, ch)] * w[ch][t]).sum::<f64>()
                })
                .collect();
            x = xn;
        }
        assert!(worst < 1e-10, "{worst:e}");
        // and the block form has the start's transfer function (zero initial state)
        let poles_b = linalg::eigenvalues(ab.as_ref()).unwrap();
        for z in &poles {
            assert!(poles_b.iter().any(|p| (p - z).norm() < 1e-10), "{z:?}");
        }
    }

    /// The Jacobian as computed before the interleaved runs (one `sensitivity_into` per
    /// column): the oracle of `interleaved_jacobian_is_bit_identical`.
    fn old_jacobian(this: &Problem<'_>, th: &[f64]) -> Option<Mat<f64>> {
        let s = this;
        let lay = s.lay;
        if !lay.admissible(th) {
            return None;
        }
        let nn = s.len();
        let mut jac = Mat::<f64>::zeros(nn * lay.l, lay.n_theta);
        for b in &lay.blocks {
            let x = s.states(th, b);
            // denominator
            if b.dim == 2 {
                let (x1, x2) = (&x[0], &x[1]);
                s.sensitivity_into(
                    th,
                    b,
                    [0.0; 2],
                    |r, k| if r == 1 { -x2[k] } else { 0.0 },
                    &mut jac,
                    b.off,
                );
                s.sensitivity_into(
                    th,
                    b,
                    [0.0; 2],
                    |r, k| if r == 1 { -x1[k] } else { 0.0 },
                    &mut jac,
                    b.off + 1,
                );
            } else {
                let x1 = &x[0];
                s.sensitivity_into(th, b, [0.0; 2], |_, k| x1[k], &mut jac, b.off);
            }
            // G
            for r in 0..b.dim {
                for ch in 0..lay.q {
                    let w = &s.w[ch];
                    let col = lay.g_idx(b, r, ch);
                    s.sensitivity_into(
                        th,
                        b,
                        [0.0; 2],
                        |rr, k| if rr == r { w[k] } else { 0.0 },
                        &mut jac,
                        col,
                    );
                }
            }
            // free rows of C
            for o in 0..lay.l {
                for (r, xr) in x.iter().enumerate() {
                    if let Some(idx) = lay.c_idx(b, o, r) {
                        let mut out = jac.col_mut(idx);
                        for (k, v) in xr.iter().enumerate() {
                            out[o * nn + k] = -v;
                        }
                    }
                }
            }
            // initial state
            if let Some(off) = lay.x0_off {
                for r in 0..b.dim {
                    let mut s0 = [0.0; 2];
                    s0[r] = 1.0;
                    s.sensitivity_into(th, b, s0, |_, _| 0.0, &mut jac, off + b.state + r);
                }
            }
        }
        if let Some(off) = lay.d_off {
            for o in 0..lay.l {
                for ch in 0..lay.m {
                    let mut out = jac.col_mut(off + o * lay.m + ch);
                    for (k, v) in s.w[ch].iter().enumerate() {
                        out[o * nn + k] = -v;
                    }
                }
            }
        }
        let finite = jac.col_iter().all(|c| c.iter().all(|v| v.is_finite()));
        finite.then_some(jac)
    }

    #[test]
    fn interleaved_jacobian_is_bit_identical() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for (feedthrough, estimate_x0, l, nn) in [(true, true, 2, 1500), (false, false, 1, 777)] {
            let (n, m) = (5, 2);
            let a = faer::mat![
                [0.5, 0.3, 0.0, 0.0, 0.0],
                [-0.3, 0.5, 0.0, 0.0, 0.0],
                [0.0, 0.0, 0.8, 0.1, 0.0],
                [0.0, 0.0, 0.0, 0.6, 0.0],
                [0.0, 0.0, 0.0, 0.0, -0.4]
            ];
            let g = Mat::from_fn(n, m + l, |_, _| rng.sample::<f64, _>(StandardNormal));
            let c = Mat::from_fn(l, n, |_, _| rng.sample::<f64, _>(StandardNormal));
            let d = Mat::from_fn(l, m, |_, _| rng.sample::<f64, _>(StandardNormal));
            let opts = SsPemOptions {
                feedthrough,
                estimate_x0,
                ..SsPemOptions::default()
            };
            let poles = linalg::eigenvalues(a.as_ref()).unwrap();
            let (lay, mut th) = to_blocks(
                a.as_ref(),
                g.as_ref(),
                c.as_ref(),
                d.as_ref(),
                &poles,
                &opts,
            )
            .unwrap();
            if let Some(off) = lay.x0_off {
                for (i, v) in th.iter_mut().enumerate().skip(off) {
                    *v = 0.1 * (i as f64).sin();
                }
            }
            let w: Vec<Vec<f64>> = (0..m + l)
                .map(|_| (0..nn).map(|_| rng.sample(StandardNormal)).collect())
                .collect();
            let y: Vec<Vec<f64>> = (0..l)
                .map(|_| (0..nn).map(|_| rng.sample(StandardNormal)).collect())
                .collect();
            let mut p = Problem {
                lay: &lay,
                w: &w,
                y: &y,
            };
            let new = p.jacobian(&th).unwrap();
            let old = old_jacobian(&p, &th).unwrap();
            assert_eq!((new.nrows(), new.ncols()), (old.nrows(), old.ncols()));
            for col in 0..new.ncols() {
                let bits = |j: &Mat<f64>| -> Vec<u64> {
                    j.col_as_slice(col).iter().map(|v| v.to_bits()).collect()
                };
                assert_eq!(bits(&new), bits(&old), "column {col}");
            }
        }
    }
}
