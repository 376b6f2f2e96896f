//! Closed-loop simulation of an identified plant with the real controller: the time-domain
//! validation of a model of an open-loop unstable plant, which cannot be simulated alone.
//!
//! # Loop
//! The excitation $r$ is injected at the controller output, as in the experiment:
//! $$ u_k = r_k + (C * (w - y))_k, \qquad y_k = (P * u)_k, $$
//! so with $w = 0$: $y = T_{ry} r$ with $T_{ry} = (I + PC)^{-1}P$ and $u = S r$ with
//! $S = (I + CP)^{-1}$ (SISO: $P/(1 + PC)$ and $1/(1 + PC)$). The plant has $n_y$ outputs and
//! $n_u$ inputs, the controller $n_y$ inputs and $n_u$ outputs; a SISO loop is the $1 \times 1$
//! case of the same code ([`simulate_loop`] and the other SISO functions pass one channel to
//! [`simulate_loop_mimo`], [`estimate_loop_initial_state_mimo`] and [`reconstruct_mimo`], with
//! bit-identical results). The loop is simulated sample by sample from rest, or from the initial
//! state that best explains the record ([`estimate_loop_initial_state_mimo`]). A closed loop that
//! the model makes unstable is reported ([`Error::Unstable`]), not simulated (its response would
//! diverge): it means the model is wrong near the loop's crossover.
//!
//! # Example
//! ```
//! use ambid_core::lti::StateSpace;
//! use ambid_core::validate::closed_loop::{simulate_loop, simulate_loop_mimo};
//! use faer::mat;
//! // an unstable first-order plant (pole 1.01) stabilised by a proportional controller 0.5
//! let p = StateSpace::discrete(mat![[1.01]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 1e-3).unwrap();
//! let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[0.5]], 1e-3).unwrap();
//! let out = simulate_loop(&p, &c, &[1.0; 200]).unwrap();
//! // steady state: y = 1/(1 − 1.01 + 0.5) = 2.0408…, u = 1 − 0.5 y
//! assert!((out.y[199] - 1.0 / 0.49).abs() < 1e-9 && (out.u[199] - (1.0 - 0.5 / 0.49)).abs() < 1e-9);
//! // the same loop as the 1 × 1 case of the MIMO simulation: identical samples
//! let r = [1.0; 200];
//! let mimo = simulate_loop_mimo(&p, &c, None, Some(&[&r[..]]), None).unwrap();
//! assert_eq!(mimo.y[0], out.y);
//! ```

use crate::error::{Error, Result};
use crate::lti::StateSpace;
use crate::validate::fit::fit_percent;
use crate::validate::predict::InitialState;

/// Output and plant input of a simulated SISO loop.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopResponse {
    /// Plant output $y$.
    pub y: Vec<f64>,
    /// Plant input $u = r - C y$.
    pub u: Vec<f64>,
}

/// Outputs and plant inputs of a simulated loop, one vector per channel.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopResponseMimo {
    /// Plant outputs $y$ ($n_y$ channels of $N$ samples).
    pub y: Vec<Vec<f64>>,
    /// Plant inputs $u = r + C (w - y)$ ($n_u$ channels of $N$ samples).
    pub u: Vec<Vec<f64>>,
}

impl LoopResponseMimo {
    /// Channel 0 of each signal as a SISO [`LoopResponse`].
    fn into_siso(self) -> LoopResponse {
        let first = |v: Vec<Vec<f64>>| v.into_iter().next().unwrap_or_default();
        LoopResponse {
            y: first(self.y),
            u: first(self.u),
        }
    }
}

/// Simulates the loop of the module docs for the SISO `plant` and `controller` (same sample
/// time) driven by `r`, from rest: [`simulate_loop_with`] without a position reference.
///
/// # Errors
/// As [`simulate_loop_with`].
pub fn simulate_loop(
    plant: &StateSpace,
    controller: &StateSpace,
    r: &[f64],
) -> Result<LoopResponse> {
    simulate_loop_with(plant, controller, None, Some(r))
}

/// Simulates $u = C(w - y) + r$, $y = P u$ from rest, with the position reference `w` and the
/// excitation `r` (either may be absent = zero; at least one is needed, equal lengths). With
/// $r = 0$: $y = \frac{PC}{1 + PC} w$ and $u = \frac{C}{1 + PC} w$. Sample by sample with the
/// plant and controller states (an algebraic loop through $D_P D_C$ is solved exactly),
/// $O(N (n_P^2 + n_C^2))$ work and no allocation per sample. The SISO case of
/// [`simulate_loop_mimo`].
///
/// # Errors
/// * [`Error::InvalidArgument`]: a model that is not SISO, no input, inputs of different lengths,
///   $1 + D_P D_C = 0$.
/// * [`Error::Unstable`]: the closed loop has a pole on or outside the unit circle (reported
///   with the largest modulus, not simulated into overflow).
/// * the errors of [`StateSpace::feedback`] (different sample times).
/// * [`Error::NonFinite`]: a NaN or infinite input sample.
pub fn simulate_loop_with(
    plant: &StateSpace,
    controller: &StateSpace,
    w: Option<&[f64]>,
    r: Option<&[f64]>,
) -> Result<LoopResponse> {
    simulate_loop_from(plant, controller, w, r, None)
}

/// [`simulate_loop_with`] from the stacked initial state `x0` = (plant states, controller
/// states) instead of rest (`None`), e.g. the one of [`estimate_loop_initial_state`].
///
/// # Errors
/// As [`simulate_loop_with`]; [`Error::InvalidArgument`] for an `x0` whose length is not the
/// sum of the two orders.
pub fn simulate_loop_from(
    plant: &StateSpace,
    controller: &StateSpace,
    w: Option<&[f64]>,
    r: Option<&[f64]>,
    x0: Option<&[f64]>,
) -> Result<LoopResponse> {
    require_siso(plant, controller)?;
    let (w, r) = (w.map(|w| [w]), r.map(|r| [r]));
    simulate_loop_mimo(
        plant,
        controller,
        w.as_ref().map(|w| &w[..]),
        r.as_ref().map(|r| &r[..]),
        x0,
    )
    .map(LoopResponseMimo::into_siso)
}

/// Simulates the loop $u = r + C(w - y)$, $y = P u$ of the module docs for a plant with $n_y$
/// outputs and $n_u$ inputs and a controller with $n_y$ inputs and $n_u$ outputs (same sample
/// time), driven by the position references `w` ($n_y$ channels) and the excitations `r` ($n_u$
/// channels), either absent = zero, at least one given, every channel of one length $N$. From the
/// stacked initial state `x0` = (plant states, controller states), or from rest (`None`).
///
/// Sample by sample: $(I + D_C D_P)\,u_k = C_C x_{C,k} + D_C (w_k - C_P x_{P,k}) + r_k$ is solved
/// by an LU factorisation with partial pivoting made once (an algebraic loop through
/// $D_P D_C$ is solved exactly; for $1 \times 1$ it is one division), then
/// $y_k = C_P x_{P,k} + D_P u_k$ and both states advance. $O(N (n_P^2 + n_C^2 + n_u n_P + n_y
/// n_C))$ work.
///
/// # Errors
/// * [`Error::DimensionMismatch`]: controller and plant shapes that do not close a loop, `w`/`r`
///   with the wrong number of channels, channels of different lengths, an `x0` of the wrong
///   length.
/// * [`Error::InvalidArgument`]: neither `w` nor `r`; $I + D_C D_P$ singular (pivot below
///   $10^{-12}$).
/// * [`Error::Unstable`]: the closed loop has a pole on or outside the unit circle (reported with
///   the largest modulus, not simulated).
/// * [`Error::SampleTimeMismatch`]: plant and controller at different sample times.
/// * [`Error::NonFinite`]: a NaN or infinite input sample.
///
/// # Example
/// ```
/// use ambid_core::lti::StateSpace;
/// use ambid_core::validate::closed_loop::simulate_loop_mimo;
/// use faer::mat;
/// // two decoupled static plants y = 2 u, y = 3 u with proportional controllers 1 and 0.5:
/// // u = r − C y gives u = r/(1 + 2), u = r/(1 + 1.5)
/// let p = StateSpace::discrete(faer::Mat::zeros(0, 0), faer::Mat::zeros(0, 2),
///     faer::Mat::zeros(2, 0), mat![[2.0, 0.0], [0.0, 3.0]], 1e-3).unwrap();
/// let c = StateSpace::discrete(faer::Mat::zeros(0, 0), faer::Mat::zeros(0, 2),
///     faer::Mat::zeros(2, 0), mat![[1.0, 0.0], [0.0, 0.5]], 1e-3).unwrap();
/// let (r0, r1) = ([1.0; 3], [2.0; 3]);
/// let out = simulate_loop_mimo(&p, &c, None, Some(&[&r0[..], &r1[..]]), None).unwrap();
/// assert!((out.u[0][2] - 1.0 / 3.0).abs() < 1e-15 && (out.u[1][2] - 2.0 / 2.5).abs() < 1e-15);
/// assert!((out.y[1][0] - 3.0 * 2.0 / 2.5).abs() < 1e-15);
/// ```
pub fn simulate_loop_mimo(
    plant: &StateSpace,
    controller: &StateSpace,
    w: Option<&[&[f64]]>,
    r: Option<&[&[f64]]>,
    x0: Option<&[f64]>,
) -> Result<LoopResponseMimo> {
    let n = check_inputs(plant, controller, w, r)?;
    if let Some(x) = x0 {
        let nx = plant.order() + controller.order();
        if x.len() != nx {
            return Err(Error::invalid(
                "x0",
                format!(
                    "the loop has {nx} states ({} of the plant, {} of the controller), the initial state {}",
                    plant.order(),
                    controller.order(),
                    x.len()
                ),
            ));
        }
        crate::error::check_finite("x0", x)?;
    }
    let lp = Loop::new(plant, controller)?;
    Ok(lp.run(n, w, r, x0))
}

/// A typed error unless both models are SISO (the SISO front doors).
fn require_siso(plant: &StateSpace, controller: &StateSpace) -> Result<()> {
    for (name, m) in [("plant", plant), ("controller", controller)] {
        if m.ninputs() != 1 || m.noutputs() != 1 {
            return Err(Error::invalid(
                name,
                format!(
                    "the closed-loop simulation needs SISO models, got {} inputs × {} outputs; use simulate_loop_mimo / reconstruct_mimo for several channels",
                    m.ninputs(),
                    m.noutputs()
                ),
            ));
        }
    }
    Ok(())
}

/// Plant and controller shapes that close a loop and consistent, finite inputs; returns the
/// number of samples.
fn check_inputs(
    plant: &StateSpace,
    controller: &StateSpace,
    w: Option<&[&[f64]]>,
    r: Option<&[&[f64]]>,
) -> Result<usize> {
    let (ny, nu) = (plant.noutputs(), plant.ninputs());
    if controller.ninputs() != ny || controller.noutputs() != nu {
        return Err(Error::DimensionMismatch {
            context:
                "closed-loop simulation: the controller maps the plant's outputs to its inputs",
            expected: format!(
                "a controller with {ny} inputs and {nu} outputs (plant {ny} outputs × {nu} inputs)"
            ),
            got: format!(
                "{} inputs and {} outputs",
                controller.ninputs(),
                controller.noutputs()
            ),
        });
    }
    for (what, x, m) in [("w", w, ny), ("r", r, nu)] {
        if let Some(x) = x {
            if x.len() != m {
                return Err(Error::DimensionMismatch {
                    context: "closed-loop simulation: channels of w (one per plant output) and r (one per plant input)",
                    expected: format!("{m} channels of {what}"),
                    got: format!("{} channels", x.len()),
                });
            }
        }
    }
    let n = match (w, r) {
        (Some(w), Some(r)) if w.first().map(|c| c.len()) != r.first().map(|c| c.len()) => {
            return Err(Error::invalid(
                "w",
                format!(
                    "the reference has {} samples, the excitation {}",
                    w.first().map_or(0, |c| c.len()),
                    r.first().map_or(0, |c| c.len())
                ),
            ))
        }
        (Some(w), _) => w.first().map_or(0, |c| c.len()),
        (None, Some(r)) => r.first().map_or(0, |c| c.len()),
        (None, None) => {
            return Err(Error::invalid(
                "r",
                "give a reference w or an excitation r to drive the loop",
            ))
        }
    };
    for (what, x) in [("w", w), ("r", r)] {
        if let Some(x) = x {
            for (k, c) in x.iter().enumerate() {
                if c.len() != n {
                    return Err(Error::DimensionMismatch {
                        context: "closed-loop simulation: every channel of w and r has one length",
                        expected: format!("{n} samples"),
                        got: format!("{} samples in channel {k} of {what}", c.len()),
                    });
                }
                crate::error::check_finite(what, c)?;
            }
        }
    }
    Ok(n)
}

/// LU factorisation with partial pivoting of a small dense row-major matrix: `(lu, perm)`, or
/// `None` when a pivot is below `1e-12` in magnitude. For $1 \times 1$ the solve is one division.
fn lu_factor(mut a: Vec<f64>, n: usize) -> Option<(Vec<f64>, Vec<usize>)> {
    let mut perm: Vec<usize> = (0..n).collect();
    for k in 0..n {
        let p = (k..n).max_by(|&i, &j| a[i * n + k].abs().total_cmp(&a[j * n + k].abs()))?;
        if a[p * n + k].abs() < 1e-12 {
            return None;
        }
        if p != k {
            for j in 0..n {
                a.swap(k * n + j, p * n + j);
            }
            perm.swap(k, p);
        }
        for i in k + 1..n {
            let l = a[i * n + k] / a[k * n + k];
            a[i * n + k] = l;
            for j in k + 1..n {
                a[i * n + j] -= l * a[k * n + j];
            }
        }
    }
    Some((a, perm))
}

/// Solves $A x = b$ in place with the factors of [`lu_factor`] (`tmp`: scratch of length $n$).
fn lu_solve(lu: &[f64], perm: &[usize], b: &mut [f64], tmp: &mut [f64]) {
    let n = perm.len();
    for (t, &p) in tmp.iter_mut().zip(perm) {
        *t = b[p];
    }
    for i in 0..n {
        for j in 0..i {
            tmp[i] -= lu[i * n + j] * tmp[j];
        }
    }
    for i in (0..n).rev() {
        for j in i + 1..n {
            tmp[i] -= lu[i * n + j] * tmp[j];
        }
        tmp[i] /= lu[i * n + i];
    }
    b.copy_from_slice(tmp);
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The loop of [`simulate_loop_mimo`] checked and prepared once: row-major matrices, the
/// factors of the algebraic-loop matrix $I + D_C D_P$ and the closed loop's spectral radius.
struct Loop {
    np: usize,
    nc: usize,
    ny: usize,
    nu: usize,
    ap: Vec<f64>,
    bp: Vec<f64>,
    cp: Vec<f64>,
    dp: Vec<f64>,
    ac: Vec<f64>,
    bc: Vec<f64>,
    cc: Vec<f64>,
    dc: Vec<f64>,
    /// LU factors of $I + D_C D_P$ ($n_u \times n_u$, row-major) and the row permutation.
    lu: Vec<f64>,
    perm: Vec<usize>,
    rho: f64,
}

impl Loop {
    fn new(plant: &StateSpace, controller: &StateSpace) -> Result<Self> {
        let t_ry = plant.feedback(controller)?;
        let rho = t_ry.poles()?.iter().map(|p| p.norm()).fold(0.0, f64::max);
        if rho >= 1.0 {
            return Err(Error::Unstable {
                context: "closed-loop simulation",
                reason: format!(
                    "the model with this controller gives an unstable closed loop (largest |pole| {rho:.6}); the model is wrong near the loop's crossover, or the controller does not match the data"
                ),
            });
        }
        let rows = crate::linalg::row_major;
        let (ny, nu) = (plant.noutputs(), plant.ninputs());
        let (dp, dc) = (rows(plant.d()), rows(controller.d()));
        // I + D_C D_P (n_u × n_u)
        let m: Vec<f64> = (0..nu * nu)
            .map(|ij| {
                let (i, j) = (ij / nu, ij % nu);
                let s: f64 = (0..ny).map(|l| dc[i * ny + l] * dp[l * nu + j]).sum();
                if i == j {
                    1.0 + s
                } else {
                    s
                }
            })
            .collect();
        let Some((lu, perm)) = lu_factor(m, nu) else {
            return Err(Error::invalid(
                "controller",
                "I + D_C D_P is singular (1 + D_P D_C = 0 for SISO): the loop has an algebraic loop without a solution",
            ));
        };
        Ok(Self {
            np: plant.order(),
            nc: controller.order(),
            ny,
            nu,
            ap: rows(plant.a()),
            bp: rows(plant.b()),
            cp: rows(plant.c()),
            dp,
            ac: rows(controller.a()),
            bc: rows(controller.b()),
            cc: rows(controller.c()),
            dc,
            lu,
            perm,
            rho,
        })
    }

    /// The loop without inputs as $x_{t+1} = A_{cl} x_t$, $y_t = \Psi_y x_t$, $u_t = \Psi_u x_t$
    /// ($x$ = plant states, then controller states): $A_{cl}$ and the output rows, row-major.
    fn free_dynamics(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (np, nc, ny, nu) = (self.np, self.nc, self.ny, self.nu);
        let nx = np + nc;
        // (I + Dc Dp) u = Cc xc − Dc Cp xp, y = Cp xp + Dp u, e = −y
        let mut ku = vec![0.0; nu * nx];
        let (mut col, mut tmp) = (vec![0.0; nu], vec![0.0; nu]);
        for j in 0..nx {
            for (i, v) in col.iter_mut().enumerate() {
                *v = if j < np {
                    (0..ny)
                        .map(|l| -self.dc[i * ny + l] * self.cp[l * np + j])
                        .sum()
                } else {
                    self.cc[i * nc + j - np]
                };
            }
            lu_solve(&self.lu, &self.perm, &mut col, &mut tmp);
            for i in 0..nu {
                ku[i * nx + j] = col[i];
            }
        }
        let mut ky = vec![0.0; ny * nx];
        for l in 0..ny {
            for j in 0..nx {
                let dk: f64 = (0..nu).map(|i| self.dp[l * nu + i] * ku[i * nx + j]).sum();
                ky[l * nx + j] = if j < np { self.cp[l * np + j] + dk } else { dk };
            }
        }
        let mut a = vec![0.0; nx * nx];
        for i in 0..np {
            for j in 0..np {
                a[i * nx + j] = self.ap[i * np + j];
            }
            for j in 0..nx {
                a[i * nx + j] += (0..nu)
                    .map(|k| self.bp[i * nu + k] * ku[k * nx + j])
                    .sum::<f64>();
            }
        }
        for i in 0..nc {
            for j in 0..nc {
                a[(np + i) * nx + np + j] = self.ac[i * nc + j];
            }
            for j in 0..nx {
                a[(np + i) * nx + j] -= (0..ny)
                    .map(|l| self.bc[i * ny + l] * ky[l * nx + j])
                    .sum::<f64>();
            }
        }
        (a, ky, ku)
    }

    /// `n` samples from the stacked initial state `x0` = (plant states, controller states), or
    /// from rest.
    fn run(
        &self,
        n: usize,
        w: Option<&[&[f64]]>,
        r: Option<&[&[f64]]>,
        x0: Option<&[f64]>,
    ) -> LoopResponseMimo {
        let (np, nc, ny, nu) = (self.np, self.nc, self.ny, self.nu);
        let (ap, bp, cp, dp) = (&self.ap, &self.bp, &self.cp, &self.dp);
        let (ac, bc, cc, dc) = (&self.ac, &self.bc, &self.cc, &self.dc);
        let (mut xp, mut xc) = match x0 {
            Some(x) => (x[..np].to_vec(), x[np..np + nc].to_vec()),
            None => (vec![0.0; np], vec![0.0; nc]),
        };
        let (mut xpn, mut xcn) = (vec![0.0; np], vec![0.0; nc]);
        let mut yv: Vec<Vec<f64>> = (0..ny).map(|_| Vec::with_capacity(n)).collect();
        let mut uv: Vec<Vec<f64>> = (0..nu).map(|_| Vec::with_capacity(n)).collect();
        let (mut ypart, mut ek) = (vec![0.0; ny], vec![0.0; ny]);
        let (mut u, mut tmp, mut y) = (vec![0.0; nu], vec![0.0; nu], vec![0.0; ny]);
        for k in 0..n {
            // (I + Dc Dp) u = Cc xc + Dc (w − Cp xp) + r
            for l in 0..ny {
                ypart[l] = dot(&cp[l * np..(l + 1) * np], &xp);
                let wk = w.map_or(0.0, |w| w[l][k]);
                ek[l] = wk - ypart[l];
            }
            for (i, ui) in u.iter_mut().enumerate() {
                let rk = r.map_or(0.0, |r| r[i][k]);
                *ui =
                    dot(&cc[i * nc..(i + 1) * nc], &xc) + dot(&dc[i * ny..(i + 1) * ny], &ek) + rk;
            }
            lu_solve(&self.lu, &self.perm, &mut u, &mut tmp);
            for l in 0..ny {
                y[l] = ypart[l] + dot(&dp[l * nu..(l + 1) * nu], &u);
                let wk = w.map_or(0.0, |w| w[l][k]);
                ek[l] = wk - y[l];
            }
            for i in 0..np {
                xpn[i] = dot(&ap[i * np..(i + 1) * np], &xp) + dot(&bp[i * nu..(i + 1) * nu], &u);
            }
            for i in 0..nc {
                xcn[i] = dot(&ac[i * nc..(i + 1) * nc], &xc) + dot(&bc[i * ny..(i + 1) * ny], &ek);
            }
            std::mem::swap(&mut xp, &mut xpn);
            std::mem::swap(&mut xc, &mut xcn);
            for (v, yk) in yv.iter_mut().zip(&y) {
                v.push(*yk);
            }
            for (v, uk) in uv.iter_mut().zip(&u) {
                v.push(*uk);
            }
        }
        LoopResponseMimo { y: yv, u: uv }
    }
}

/// The largest loop (plant plus controller states) whose initial state
/// [`estimate_loop_initial_state`] estimates; a larger one starts from rest. The work is
/// $O(H n_x^2)$ for the free responses and $O(H n_x^2)$ for the least squares; identified plant
/// models have a few tens of states, and a model of hundreds is refused by this bound instead of
/// taking minutes.
pub const MAX_X0_LOOP_STATES: usize = 64;

/// The initial state of the SISO loop (plant states, then controller states) that best explains
/// the measured `y_meas` and `u_meas`: [`estimate_loop_initial_state_mimo`] with one channel
/// each (same numbers).
///
/// # Errors
/// As [`simulate_loop_with`]; [`Error::DimensionMismatch`] for measured signals of another length.
pub fn estimate_loop_initial_state(
    plant: &StateSpace,
    controller: &StateSpace,
    w: Option<&[f64]>,
    r: Option<&[f64]>,
    y_meas: &[f64],
    u_meas: &[f64],
) -> Result<Vec<f64>> {
    require_siso(plant, controller)?;
    let (w, r) = (w.map(|w| [w]), r.map(|r| [r]));
    estimate_loop_initial_state_mimo(
        plant,
        controller,
        w.as_ref().map(|w| &w[..]),
        r.as_ref().map(|r| &r[..]),
        &[y_meas],
        &[u_meas],
    )
}

/// The initial state of the loop (plant states, then controller states) that best explains the
/// measured outputs `y_meas` ($n_y$ channels) and plant inputs `u_meas` ($n_u$ channels): the
/// loop's response is affine in its initial state $x_0$, $\hat y = y^{(0)} + \Psi_y x_0$,
/// $\hat u = u^{(0)} + \Psi_u x_0$, where $y^{(0)}, u^{(0)}$ are the responses from rest and
/// the columns of $\Psi$ the free responses to unit initial states. $x_0$ minimises
/// $$ \sum_{l=1}^{n_y} \frac{\lVert y_l - y^{(0)}_l - \Psi_{y,l} x_0 \rVert^2}{\lVert y_l \rVert^2} + \sum_{i=1}^{n_u} \frac{\lVert u_i - u^{(0)}_i - \Psi_{u,i} x_0 \rVert^2}{\lVert u_i \rVert^2}, $$
/// every channel weighted by its own energy (they have different units and sizes). The free
/// responses decay with the closed loop's spectral radius $\rho < 1$; they are computed over
/// $H = \min(N, \lceil \ln 10^{-12} / \ln \rho \rceil)$ samples, beyond which they are below
/// $10^{-12}$ of their start. This is MATLAB `compare`'s default (`InitialCondition` =
/// `'e'`) applied to the closed loop, which is what a record taken in steady operation needs:
/// the loop was running before the first sample. The minimum-norm solution leaves states the
/// record cannot see at zero. Loops of more than [`MAX_X0_LOOP_STATES`] states start from rest
/// (zeros are returned).
///
/// # Errors
/// As [`simulate_loop_mimo`]; [`Error::DimensionMismatch`] for measured signals with another
/// number of channels or samples.
///
/// # Example
/// ```
/// use ambid_core::lti::StateSpace;
/// use ambid_core::validate::closed_loop::{estimate_loop_initial_state_mimo, simulate_loop_mimo};
/// use faer::mat;
/// // two first-order plants (one unstable) under proportional control, started at x0
/// let p = StateSpace::discrete(mat![[1.02, 0.0], [0.1, 0.8]], mat![[1.0, 0.0], [0.0, 1.0]],
///     mat![[1.0, 0.0], [0.0, 1.0]], mat![[0.0, 0.0], [0.0, 0.0]], 1e-3).unwrap();
/// let c = StateSpace::discrete(faer::Mat::zeros(0, 0), faer::Mat::zeros(0, 2),
///     faer::Mat::zeros(2, 0), mat![[0.5, 0.0], [0.0, 0.3]], 1e-3).unwrap();
/// let r0: Vec<f64> = (0..300).map(|k| ((k * 7 % 5) as f64 - 2.0)).collect();
/// let r1: Vec<f64> = (0..300).map(|k| ((k * 3 % 7) as f64 - 3.0)).collect();
/// let r = [&r0[..], &r1[..]];
/// let rec = simulate_loop_mimo(&p, &c, None, Some(&r), Some(&[0.4, -0.7])).unwrap();
/// let (y, u) = ([&rec.y[0][..], &rec.y[1][..]], [&rec.u[0][..], &rec.u[1][..]]);
/// let x0 = estimate_loop_initial_state_mimo(&p, &c, None, Some(&r), &y, &u).unwrap();
/// assert!((x0[0] - 0.4).abs() < 1e-9 && (x0[1] + 0.7).abs() < 1e-9);
/// ```
pub fn estimate_loop_initial_state_mimo(
    plant: &StateSpace,
    controller: &StateSpace,
    w: Option<&[&[f64]]>,
    r: Option<&[&[f64]]>,
    y_meas: &[&[f64]],
    u_meas: &[&[f64]],
) -> Result<Vec<f64>> {
    let n = check_inputs(plant, controller, w, r)?;
    check_measured(plant, n, y_meas, u_meas)?;
    let lp = Loop::new(plant, controller)?;
    let (ny, nu) = (lp.ny, lp.nu);
    let nx = lp.np + lp.nc;
    if nx == 0 || n < nx || nx > MAX_X0_LOOP_STATES {
        return Ok(vec![0.0; nx]);
    }
    let horizon = if lp.rho > 0.0 {
        ((1e-12f64).ln() / lp.rho.ln()).ceil().max(nx as f64)
    } else {
        nx as f64
    };
    let h = n.min(horizon as usize);
    let rest = lp.run(n, w, r, None);
    let energy = |x: &[f64]| {
        x.iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt()
            .max(f64::MIN_POSITIVE)
    };
    let sy: Vec<f64> = y_meas.iter().map(|y| 1.0 / energy(y)).collect();
    let su: Vec<f64> = u_meas.iter().map(|u| 1.0 / energy(u)).collect();
    // free responses as rows: y_t = Ψ_y A_cl^t x0, u_t = Ψ_u A_cl^t x0, propagated by
    // Ψ ← Ψ A_cl (O(n_x²) per sample and channel, not O(n_x³) for n_x unit simulations)
    let (a_cl, mut rows_y, mut rows_u) = lp.free_dynamics();
    let per = ny + nu;
    let mut psi = faer::Mat::<f64>::zeros(per * h, nx);
    let mut next = vec![0.0; nx];
    // row ← row A_cl as a sum of A_cl's rows (contiguous, independent sums: this loop is the
    // estimate's main cost on long records)
    let times = |row: &[f64], out: &mut Vec<f64>| {
        out.iter_mut().for_each(|o| *o = 0.0);
        for (i, &ri) in row.iter().enumerate() {
            for (o, &a) in out.iter_mut().zip(&a_cl[i * nx..(i + 1) * nx]) {
                *o += ri * a;
            }
        }
    };
    for t in 0..h {
        for l in 0..ny {
            for j in 0..nx {
                psi[(per * t + l, j)] = sy[l] * rows_y[l * nx + j];
            }
        }
        for i in 0..nu {
            for j in 0..nx {
                psi[(per * t + ny + i, j)] = su[i] * rows_u[i * nx + j];
            }
        }
        for rows in [&mut rows_y, &mut rows_u] {
            for row in rows.chunks_mut(nx) {
                times(row, &mut next);
                row.copy_from_slice(&next);
            }
        }
    }
    let rhs = faer::Mat::from_fn(per * h, 1, |i, _| {
        let (t, c) = (i / per, i % per);
        if c < ny {
            sy[c] * (y_meas[c][t] - rest.y[c][t])
        } else {
            su[c - ny] * (u_meas[c - ny][t] - rest.u[c - ny][t])
        }
    });
    // minimum norm: states the record cannot see (uncontrollable and unobservable modes of the
    // loop, e.g. a plant model's decoupled states) stay at zero
    let x0 = crate::linalg::lstsq_min_norm(psi.as_ref(), rhs.as_ref(), 1e-10)?;
    if x0.iter().all(|v| v.is_finite()) {
        Ok(x0)
    } else {
        Ok(vec![0.0; nx])
    }
}

/// Measured signals with one channel per plant output / input, `n` finite samples each.
fn check_measured(
    plant: &StateSpace,
    n: usize,
    y_meas: &[&[f64]],
    u_meas: &[&[f64]],
) -> Result<()> {
    for (what, x, m) in [
        ("y_meas", y_meas, plant.noutputs()),
        ("u_meas", u_meas, plant.ninputs()),
    ] {
        if x.len() != m {
            return Err(Error::DimensionMismatch {
                context: "closed loop: measured outputs (one per plant output) and inputs (one per plant input)",
                expected: format!("{m} channels of {what}"),
                got: format!("{} channels", x.len()),
            });
        }
        for c in x {
            if c.len() != n {
                return Err(Error::DimensionMismatch {
                    context: "closed loop: measured signals and loop inputs",
                    expected: format!("{n} samples"),
                    got: format!("{} samples in {what}", c.len()),
                });
            }
            crate::error::check_finite(what, c)?;
        }
    }
    Ok(())
}

/// Fit of a simulated signal to a measured one in one time window.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WindowFit {
    /// Window start and end \[s\].
    pub t_s: (f64, f64),
    /// Fit of the displacement \[%\].
    pub fit_y: f64,
    /// Fit of the current (controller output) \[%\].
    pub fit_u: f64,
    /// RMS of the displacement error in the window.
    pub rms_error_y: f64,
}

/// The result of [`reconstruct`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Reconstruction {
    /// Simulated displacement and current.
    #[serde(skip)]
    pub simulated: LoopResponse,
    /// Fit of the displacement over the record \[%\].
    pub fit_y: f64,
    /// Fit of the current over the record \[%\].
    pub fit_u: f64,
    /// Largest absolute displacement error.
    pub max_error_y: f64,
    /// Fits per window.
    pub windows: Vec<WindowFit>,
    /// The loop's initial state the simulation started from (plant states, then controller
    /// states): zeros from rest, or [`estimate_loop_initial_state`]'s.
    pub initial_state: Vec<f64>,
}

impl Reconstruction {
    /// The window with the lowest displacement fit (where the model is worst).
    pub fn worst_window(&self) -> Option<&WindowFit> {
        self.windows
            .iter()
            .min_by(|a, b| a.fit_y.total_cmp(&b.fit_y))
    }
}

/// The result of [`reconstruct_mimo`]: per axis $k$ (output $y_k$ and plant input $u_k$).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ReconstructionMimo {
    /// Simulated outputs and plant inputs.
    #[serde(skip)]
    pub simulated: LoopResponseMimo,
    /// Fit of each output over the record \[%\] (NaN for a constant measured channel).
    pub fit_y: Vec<f64>,
    /// Fit of each plant input (controller output) over the record \[%\].
    pub fit_u: Vec<f64>,
    /// Largest absolute error of each output.
    pub max_error_y: Vec<f64>,
    /// Fits per window, per axis (`windows[k][j]`: axis `k`, window `j`).
    pub windows: Vec<Vec<WindowFit>>,
    /// The loop's initial state the simulation started from (plant states, then controller
    /// states): zeros from rest, or [`estimate_loop_initial_state_mimo`]'s.
    pub initial_state: Vec<f64>,
}

/// Closed-loop reconstruction: simulates the loop with the identified `plant` and the real
/// `controller` driven by the reference `w` (and the excitation `r`, if any) and compares the
/// displacement and the current with the measured `y_meas`, `u_meas`, over the whole record and in
/// `n_windows` equal windows (for a chirp reference a window is a frequency band, so a local
/// mismatch such as an unmodelled mode is located in time and frequency). Fit $= 100\,(1 -
/// \lVert x - \hat x\rVert / \lVert x - \bar x\rVert)$. The SISO case of [`reconstruct_mimo`].
///
/// # Errors
/// As [`simulate_loop_with`]; [`Error::DimensionMismatch`] when the measured signals differ in
/// length from the reference; [`Error::InvalidArgument`] for `n_windows` = 0 or more windows than
/// samples / 2.
#[allow(clippy::too_many_arguments)]
pub fn reconstruct(
    plant: &StateSpace,
    controller: &StateSpace,
    w: &[f64],
    r: Option<&[f64]>,
    y_meas: &[f64],
    u_meas: &[f64],
    n_windows: usize,
    ts: f64,
) -> Result<Reconstruction> {
    reconstruct_with(
        plant,
        controller,
        w,
        r,
        y_meas,
        u_meas,
        n_windows,
        ts,
        InitialState::Zero,
    )
}

/// [`reconstruct`] starting from rest ([`InitialState::Zero`]) or from the loop's initial
/// state that best explains the record ([`InitialState::Estimate`],
/// [`estimate_loop_initial_state`]), for records taken while the loop was already running.
///
/// # Errors
/// As [`reconstruct`] and [`estimate_loop_initial_state`].
#[allow(clippy::too_many_arguments)]
pub fn reconstruct_with(
    plant: &StateSpace,
    controller: &StateSpace,
    w: &[f64],
    r: Option<&[f64]>,
    y_meas: &[f64],
    u_meas: &[f64],
    n_windows: usize,
    ts: f64,
    ic: InitialState,
) -> Result<Reconstruction> {
    let n = w.len();
    for (what, x) in [("y_meas", y_meas), ("u_meas", u_meas)] {
        if x.len() != n {
            return Err(Error::DimensionMismatch {
                context: "reconstruct: measured signal and reference",
                expected: format!("{n} samples ({what})"),
                got: format!("{} samples", x.len()),
            });
        }
    }
    check_windows(n_windows, n)?;
    require_siso(plant, controller)?;
    let r = r.map(|r| [r]);
    let m = reconstruct_mimo(
        plant,
        controller,
        Some(&[w]),
        r.as_ref().map(|r| &r[..]),
        &[y_meas],
        &[u_meas],
        n_windows,
        ts,
        ic,
    )?;
    let first = |v: Vec<f64>| v.first().copied().unwrap_or(f64::NAN);
    Ok(Reconstruction {
        fit_y: first(m.fit_y),
        fit_u: first(m.fit_u),
        max_error_y: first(m.max_error_y),
        windows: m.windows.into_iter().next().unwrap_or_default(),
        simulated: m.simulated.into_siso(),
        initial_state: m.initial_state,
    })
}

fn check_windows(n_windows: usize, n: usize) -> Result<()> {
    if n_windows == 0 || 2 * n_windows > n {
        return Err(Error::invalid(
            "n_windows",
            format!(
                "need 1 ≤ n_windows ≤ samples/2 = {}, got {n_windows}",
                n / 2
            ),
        ));
    }
    Ok(())
}

/// Closed-loop reconstruction of a loop with one actuator per sensor (plant $n \times n$,
/// axis $k$ = output $k$ and input $k$): simulates the loop with the identified `plant` and the
/// real `controller` driven by the references `w` and the excitations `r` (either may be absent,
/// not both), from rest or from [`estimate_loop_initial_state_mimo`] (`ic`), and compares every
/// output and plant input with the measured `y_meas`, `u_meas` over the whole record and in
/// `n_windows` equal windows per axis (module docs of [`reconstruct`]). The fit of each channel
/// is [`fit_percent`] (NaN for a constant measured channel).
///
/// # Errors
/// As [`simulate_loop_mimo`] and [`estimate_loop_initial_state_mimo`]; [`Error::DimensionMismatch`]
/// for a plant that is not square or measured signals with the wrong number of channels or
/// samples; [`Error::InvalidArgument`] for `n_windows` = 0 or more windows than samples / 2.
///
/// # Example
/// ```
/// use ambid_core::lti::StateSpace;
/// use ambid_core::validate::closed_loop::{reconstruct_mimo, simulate_loop_mimo};
/// use ambid_core::validate::predict::InitialState;
/// use faer::mat;
/// let p = StateSpace::discrete(mat![[1.02, 0.0], [0.1, 0.8]], mat![[1.0, 0.0], [0.0, 1.0]],
///     mat![[1.0, 0.0], [0.0, 1.0]], mat![[0.0, 0.0], [0.0, 0.0]], 1e-3).unwrap();
/// let c = StateSpace::discrete(faer::Mat::zeros(0, 0), faer::Mat::zeros(0, 2),
///     faer::Mat::zeros(2, 0), mat![[0.5, 0.0], [0.0, 0.3]], 1e-3).unwrap();
/// let r0: Vec<f64> = (0..300).map(|k| ((k * 7 % 5) as f64 - 2.0)).collect();
/// let r1: Vec<f64> = (0..300).map(|k| ((k * 3 % 7) as f64 - 3.0)).collect();
/// let r = [&r0[..], &r1[..]];
/// let rec = simulate_loop_mimo(&p, &c, None, Some(&r), None).unwrap();
/// let (y, u) = ([&rec.y[0][..], &rec.y[1][..]], [&rec.u[0][..], &rec.u[1][..]]);
/// // the plant itself reproduces the record: 100 % on every axis
/// let rc = reconstruct_mimo(&p, &c, None, Some(&r), &y, &u, 3, 1e-3, InitialState::Zero).unwrap();
/// assert!(rc.fit_y.iter().chain(&rc.fit_u).all(|f| (f - 100.0).abs() < 1e-9));
/// assert_eq!(rc.windows[1].len(), 3);
/// ```
#[allow(clippy::too_many_arguments)]
pub fn reconstruct_mimo(
    plant: &StateSpace,
    controller: &StateSpace,
    w: Option<&[&[f64]]>,
    r: Option<&[&[f64]]>,
    y_meas: &[&[f64]],
    u_meas: &[&[f64]],
    n_windows: usize,
    ts: f64,
    ic: InitialState,
) -> Result<ReconstructionMimo> {
    if plant.noutputs() != plant.ninputs() {
        return Err(Error::DimensionMismatch {
            context: "reconstruct_mimo: one actuator per sensor (a square plant)",
            expected: format!("{0} outputs × {0} inputs", plant.noutputs()),
            got: format!("{} outputs × {} inputs", plant.noutputs(), plant.ninputs()),
        });
    }
    let n = check_inputs(plant, controller, w, r)?;
    check_measured(plant, n, y_meas, u_meas)?;
    check_windows(n_windows, n)?;
    let x0 = match ic {
        InitialState::Zero => vec![0.0; plant.order() + controller.order()],
        InitialState::Estimate => {
            estimate_loop_initial_state_mimo(plant, controller, w, r, y_meas, u_meas)?
        }
    };
    let sim = simulate_loop_mimo(plant, controller, w, r, Some(&x0))?;
    // NaN for a constant window (the fit is undefined there)
    let fit = |x: &[f64], xh: &[f64]| fit_percent(x, xh).unwrap_or(f64::NAN);
    let len = n / n_windows;
    let windows = (0..plant.noutputs())
        .map(|c| {
            let (ym, um, ys, us) = (y_meas[c], u_meas[c], &sim.y[c], &sim.u[c]);
            (0..n_windows)
                .map(|k| {
                    let (a, b) = (k * len, if k + 1 == n_windows { n } else { (k + 1) * len });
                    let e2: f64 = ym[a..b]
                        .iter()
                        .zip(&ys[a..b])
                        .map(|(p, q)| (p - q).powi(2))
                        .sum();
                    WindowFit {
                        t_s: (a as f64 * ts, b as f64 * ts),
                        fit_y: fit(&ym[a..b], &ys[a..b]),
                        fit_u: fit(&um[a..b], &us[a..b]),
                        rms_error_y: (e2 / (b - a) as f64).sqrt(),
                    }
                })
                .collect()
        })
        .collect();
    Ok(ReconstructionMimo {
        fit_y: y_meas.iter().zip(&sim.y).map(|(m, s)| fit(m, s)).collect(),
        fit_u: u_meas.iter().zip(&sim.u).map(|(m, s)| fit(m, s)).collect(),
        max_error_y: y_meas
            .iter()
            .zip(&sim.y)
            .map(|(m, s)| {
                m.iter()
                    .zip(s)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max)
            })
            .collect(),
        windows,
        simulated: sim,
        initial_state: x0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::mat;

    /// Plant with an unstable real pole and a lightly damped pair (strictly proper) and a PD-like
    /// controller with feedthrough, at 1 kHz.
    fn test_loop() -> (StateSpace, StateSpace, f64) {
        let ts = 1e-3;
        let p = StateSpace::discrete(
            mat![[1.02, 0.0, 0.0], [0.0, 0.9, 0.3], [0.0, -0.3, 0.9]],
            mat![[1.0], [0.0], [0.5]],
            mat![[0.4, 1.0, 0.2]],
            mat![[0.0]],
            ts,
        )
        .unwrap();
        let c =
            StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[0.1]], mat![[0.3]], ts).unwrap();
        (p, c, ts)
    }

    /// The loop simulated sample by sample with explicit plant and controller states (a naive
    /// oracle) agrees with the state-space closed loop.
    #[test]
    fn matches_a_sample_by_sample_loop() {
        let (p, c, ts) = test_loop();
        let r: Vec<f64> = (0..300)
            .map(|k| ((k * 37 % 11) as f64 - 5.0) / 5.0)
            .collect();
        let out = simulate_loop(&p, &c, &r).unwrap();
        let (mut xp, mut xc) = (vec![0.0; 3], 0.0);
        for (k, rk) in r.iter().enumerate() {
            let y: f64 = (0..3).map(|i| p.c()[(0, i)] * xp[i]).sum();
            let u = rk - (c.c()[(0, 0)] * xc + c.d()[(0, 0)] * y);
            assert!((y - out.y[k]).abs() < 1e-10 * (1.0 + y.abs()), "y at {k}");
            assert!((u - out.u[k]).abs() < 1e-10 * (1.0 + u.abs()), "u at {k}");
            let xn: Vec<f64> = (0..3)
                .map(|i| (0..3).map(|j| p.a()[(i, j)] * xp[j]).sum::<f64>() + p.b()[(i, 0)] * u)
                .collect();
            xc = c.a()[(0, 0)] * xc + c.b()[(0, 0)] * y;
            xp = xn;
        }
        // with a position reference: y = PC/(1 + PC) w, from the interconnection functions
        let w: Vec<f64> = (0..300).map(|k| (0.05 * k as f64).sin()).collect();
        let out = simulate_loop_with(&p, &c, Some(&w), None).unwrap();
        let one =
            StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[1.0]], ts).unwrap();
        let t_wy = c.series(&p).unwrap().feedback(&one).unwrap();
        let y = t_wy.simulate_siso(&w, None).unwrap();
        for (k, (a, b)) in y.iter().zip(&out.y).enumerate() {
            assert!((a - b).abs() < 1e-10 * (1.0 + a.abs()), "w → y at {k}");
        }
        // an unstable loop is refused with a typed error
        let weak =
            StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[0.001]], ts).unwrap();
        assert!(matches!(
            simulate_loop(&p, &weak, &r),
            Err(Error::Unstable { .. })
        ));
    }

    /// A record that starts while the loop is running (a nonzero initial state of plant and
    /// controller, from a naive sample-by-sample loop): the estimate recovers the state to
    /// rounding, the reconstruction from it is exact, and the one from rest is not.
    #[test]
    fn initial_state_of_a_running_loop_is_recovered() {
        let (p, c, ts) = test_loop();
        let r: Vec<f64> = (0..400)
            .map(|k| ((k * 37 % 11) as f64 - 5.0) / 5.0)
            .collect();
        let truth = [0.7, -1.3, 0.4, 2.0];
        // naive oracle: the loop by hand from the initial state
        let (mut xp, mut xc) = (truth[..3].to_vec(), truth[3]);
        let (mut y, mut u) = (Vec::new(), Vec::new());
        for rk in &r {
            let yk: f64 = (0..3).map(|i| p.c()[(0, i)] * xp[i]).sum();
            let uk = rk - (c.c()[(0, 0)] * xc + c.d()[(0, 0)] * yk);
            xp = (0..3)
                .map(|i| (0..3).map(|j| p.a()[(i, j)] * xp[j]).sum::<f64>() + p.b()[(i, 0)] * uk)
                .collect();
            xc = c.a()[(0, 0)] * xc + c.b()[(0, 0)] * yk;
            y.push(yk);
            u.push(uk);
        }
        let x0 = estimate_loop_initial_state(&p, &c, None, Some(&r), &y, &u).unwrap();
        // the loop's controller is driven by e = w − y, the oracle's by y: its state has the
        // opposite sign
        let expected = [truth[0], truth[1], truth[2], -truth[3]];
        for (a, b) in x0.iter().zip(&expected) {
            assert!((a - b).abs() < 1e-8, "x0 {x0:?} vs {expected:?}");
        }
        let zeros = vec![0.0; r.len()];
        let est = reconstruct_with(
            &p,
            &c,
            &zeros,
            Some(&r),
            &y,
            &u,
            4,
            ts,
            InitialState::Estimate,
        )
        .unwrap();
        assert!(
            est.fit_y > 100.0 - 1e-6,
            "fit from the estimate {}",
            est.fit_y
        );
        let rest = reconstruct(&p, &c, &zeros, Some(&r), &y, &u, 4, ts).unwrap();
        assert!(rest.fit_y < 99.0, "fit from rest {}", rest.fit_y);
        assert_eq!(rest.initial_state, vec![0.0; 4]);
        // a wrong-length state is refused
        assert!(simulate_loop_from(&p, &c, None, Some(&r), Some(&[1.0])).is_err());
    }

    /// A 2 × 2 loop with feedthrough in plant and controller (an algebraic loop through
    /// D_C D_P, coupled channels) against a naive oracle that solves the loop equations with
    /// faer at every sample; the response from rest to a reference and an excitation, and the
    /// initial state of a running loop recovered by the MIMO estimate.
    #[test]
    fn mimo_loop_matches_a_naive_oracle() {
        let ts = 1e-3;
        let p = StateSpace::discrete(
            mat![[1.03, 0.1, 0.0], [0.0, 0.7, 0.2], [0.05, 0.0, 0.5]],
            mat![[1.0, 0.2], [0.0, 1.0], [0.3, 0.0]],
            mat![[1.0, 0.0, 0.4], [0.2, 1.0, 0.0]],
            mat![[0.1, 0.02], [0.0, 0.05]],
            ts,
        )
        .unwrap();
        let c = StateSpace::discrete(
            mat![[0.6, 0.0], [0.1, 0.4]],
            mat![[1.0, 0.0], [0.0, 1.0]],
            mat![[0.2, 0.0], [0.0, 0.1]],
            mat![[0.5, 0.05], [0.0, 0.4]],
            ts,
        )
        .unwrap();
        let n = 300;
        let sig = |a: usize, b: usize| -> Vec<f64> {
            (0..n)
                .map(|k| ((k * a % b) as f64 - b as f64 / 2.0) / b as f64)
                .collect()
        };
        let (w0, w1, r0, r1) = (sig(7, 11), sig(5, 13), sig(3, 17), sig(11, 7));
        let (w, r) = ([&w0[..], &w1[..]], [&r0[..], &r1[..]]);
        let x0 = [0.3, -0.2, 0.5, 0.1, -0.4];
        let out = simulate_loop_mimo(&p, &c, Some(&w), Some(&r), Some(&x0)).unwrap();
        // oracle: (I + Dc Dp) u = Cc xc + Dc (w − Cp xp) + r, y = Cp xp + Dp u, e = w − y
        let mut xp = faer::Mat::from_fn(3, 1, |i, _| x0[i]);
        let mut xc = faer::Mat::from_fn(2, 1, |i, _| x0[3 + i]);
        let m = faer::Mat::<f64>::identity(2, 2) + c.d() * p.d();
        for k in 0..n {
            let wk = faer::Mat::from_fn(2, 1, |i, _| [w0[k], w1[k]][i]);
            let rk = faer::Mat::from_fn(2, 1, |i, _| [r0[k], r1[k]][i]);
            let rhs = c.c() * &xc + c.d() * (&wk - p.c() * &xp) + &rk;
            let u = crate::linalg::solve(m.as_ref(), rhs.as_ref()).unwrap();
            let y = p.c() * &xp + p.d() * &u;
            let e = &wk - &y;
            for i in 0..2 {
                assert!(
                    (out.u[i][k] - u[(i, 0)]).abs() < 1e-10 * (1.0 + u[(i, 0)].abs()),
                    "u{i} at {k}"
                );
                assert!(
                    (out.y[i][k] - y[(i, 0)]).abs() < 1e-10 * (1.0 + y[(i, 0)].abs()),
                    "y{i} at {k}"
                );
            }
            xp = p.a() * &xp + p.b() * &u;
            xc = c.a() * &xc + c.b() * &e;
        }
        // the state of the running loop is recovered from its record
        let (y, u) = (
            [&out.y[0][..], &out.y[1][..]],
            [&out.u[0][..], &out.u[1][..]],
        );
        let est = estimate_loop_initial_state_mimo(&p, &c, Some(&w), Some(&r), &y, &u).unwrap();
        for (a, b) in est.iter().zip(&x0) {
            assert!((a - b).abs() < 1e-8, "{est:?} vs {x0:?}");
        }
        // a controller of the wrong shape is refused
        let c1 =
            StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[0.5]], ts).unwrap();
        assert!(matches!(
            simulate_loop_mimo(&p, &c1, None, Some(&r), None),
            Err(Error::DimensionMismatch { .. })
        ));
    }
}
