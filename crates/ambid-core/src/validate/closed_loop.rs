//! Closed-loop simulation of an identified plant with the real controller: the time-domain
//! validation of a model of an open-loop unstable plant, which cannot be simulated alone.
//!
//! # Loop
//! The excitation $r$ is injected at the controller output, as in the experiment:
//! $$ u_k = r_k - (C * y)_k, \qquad y_k = (P * u)_k, $$
//! so $y = T_{ry} r$ with $T_{ry} = P/(1 + PC)$ and $u = S r$ with $S = 1/(1 + PC)$. The closed
//! loop is formed as a state-space model ([`StateSpace::feedback`]) and simulated from rest, or
//! from the initial state that best explains the record ([`estimate_loop_initial_state`]); $u$
//! follows from $u = r - C y$. A closed loop that the model makes unstable is reported, not
//! simulated (its response would diverge): it means the model is wrong near the loop's crossover.
//!
//! # Example
//! ```
//! use ambid_core::lti::StateSpace;
//! use ambid_core::validate::closed_loop::simulate_loop;
//! use faer::mat;
//! // an unstable first-order plant (pole 1.01) stabilised by a proportional controller 0.5
//! let p = StateSpace::discrete(mat![[1.01]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 1e-3).unwrap();
//! let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[0.5]], 1e-3).unwrap();
//! let out = simulate_loop(&p, &c, &[1.0; 200]).unwrap();
//! // steady state: y = 1/(1 − 1.01 + 0.5) = 2.0408…, u = 1 − 0.5 y
//! assert!((out.y[199] - 1.0 / 0.49).abs() < 1e-9 && (out.u[199] - (1.0 - 0.5 / 0.49)).abs() < 1e-9);
//! ```

use crate::error::{Error, Result};
use crate::lti::StateSpace;
use crate::validate::fit::fit_percent;
use crate::validate::predict::InitialState;

/// Output and plant input of the simulated loop.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopResponse {
    /// Plant output $y$.
    pub y: Vec<f64>,
    /// Plant input $u = r - C y$.
    pub u: Vec<f64>,
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
/// $O(N (n_P^2 + n_C^2))$ work and no allocation per sample.
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

/// SISO models and consistent, finite inputs; returns the number of samples.
fn check_inputs(
    plant: &StateSpace,
    controller: &StateSpace,
    w: Option<&[f64]>,
    r: Option<&[f64]>,
) -> Result<usize> {
    for (name, m) in [("plant", plant), ("controller", controller)] {
        if m.ninputs() != 1 || m.noutputs() != 1 {
            return Err(Error::invalid(
                name,
                format!(
                    "the closed-loop simulation needs SISO models, got {} inputs × {} outputs",
                    m.ninputs(),
                    m.noutputs()
                ),
            ));
        }
    }
    let n = match (w, r) {
        (Some(w), Some(r)) if w.len() != r.len() => {
            return Err(Error::invalid(
                "w",
                format!(
                    "the reference has {} samples, the excitation {}",
                    w.len(),
                    r.len()
                ),
            ))
        }
        (Some(w), _) => w.len(),
        (None, Some(r)) => r.len(),
        (None, None) => {
            return Err(Error::invalid(
                "r",
                "give a reference w or an excitation r to drive the loop",
            ))
        }
    };
    for (what, x) in [("w", w), ("r", r)] {
        if let Some(x) = x {
            crate::error::check_finite(what, x)?;
        }
    }
    Ok(n)
}

/// The loop of [`simulate_loop_with`] checked and prepared once: row-major matrices, the
/// algebraic-loop denominator and the closed loop's spectral radius.
struct Loop {
    np: usize,
    nc: usize,
    ap: Vec<f64>,
    bp: Vec<f64>,
    cp: Vec<f64>,
    dp: f64,
    ac: Vec<f64>,
    bc: Vec<f64>,
    cc: Vec<f64>,
    dc: f64,
    den: f64,
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
        let dp = plant.d()[(0, 0)];
        let dc = controller.d()[(0, 0)];
        let den = 1.0 + dp * dc;
        if den.abs() < 1e-12 {
            return Err(Error::invalid(
                "controller",
                "1 + D_P D_C = 0: the loop has an algebraic loop without a solution",
            ));
        }
        let rows = crate::linalg::row_major;
        Ok(Self {
            np: plant.order(),
            nc: controller.order(),
            ap: rows(plant.a()),
            bp: rows(plant.b()),
            cp: rows(plant.c()),
            dp,
            ac: rows(controller.a()),
            bc: rows(controller.b()),
            cc: rows(controller.c()),
            dc,
            den,
            rho,
        })
    }

    /// The loop without inputs as $x_{t+1} = A_{cl} x_t$, $y_t = \psi_y x_t$, $u_t = \psi_u x_t$
    /// ($x$ = plant states, then controller states): $A_{cl}$ row-major and the two output rows.
    fn free_dynamics(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (np, nc) = (self.np, self.nc);
        let nx = np + nc;
        // u = (Cc xc − Dc Cp xp) / den, y = Cp xp + Dp u, e = −y
        let ku: Vec<f64> = self
            .cp
            .iter()
            .map(|c| -self.dc * c / self.den)
            .chain(self.cc.iter().map(|c| c / self.den))
            .collect();
        let mut ky: Vec<f64> = ku.iter().map(|v| self.dp * v).collect();
        for (k, c) in ky.iter_mut().zip(&self.cp) {
            *k += c;
        }
        let mut a = vec![0.0; nx * nx];
        for i in 0..np {
            for j in 0..np {
                a[i * nx + j] = self.ap[i * np + j];
            }
            for j in 0..nx {
                a[i * nx + j] += self.bp[i] * ku[j];
            }
        }
        for i in 0..nc {
            for j in 0..nc {
                a[(np + i) * nx + np + j] = self.ac[i * nc + j];
            }
            for j in 0..nx {
                a[(np + i) * nx + j] -= self.bc[i] * ky[j];
            }
        }
        (a, ky, ku)
    }

    /// `n` samples from the stacked initial state `x0` = (plant states, controller states), or
    /// from rest.
    fn run(
        &self,
        n: usize,
        w: Option<&[f64]>,
        r: Option<&[f64]>,
        x0: Option<&[f64]>,
    ) -> LoopResponse {
        let (np, nc) = (self.np, self.nc);
        let (ap, bp, cp, dp) = (&self.ap, &self.bp, &self.cp, self.dp);
        let (ac, bc, cc, dc) = (&self.ac, &self.bc, &self.cc, self.dc);
        let den = self.den;
        let dot = |a: &[f64], b: &[f64]| -> f64 { a.iter().zip(b).map(|(x, y)| x * y).sum() };
        let (mut xp, mut xc) = match x0 {
            Some(x) => (x[..np].to_vec(), x[np..np + nc].to_vec()),
            None => (vec![0.0; np], vec![0.0; nc]),
        };
        let (mut xpn, mut xcn) = (vec![0.0; np], vec![0.0; nc]);
        let (mut yv, mut uv) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for k in 0..n {
            let wk = w.map_or(0.0, |w| w[k]);
            let rk = r.map_or(0.0, |r| r[k]);
            // u = Cc xc + Dc (w − Cp xp − Dp u) + r
            let ypart = dot(cp, &xp);
            let u = (dot(cc, &xc) + dc * (wk - ypart) + rk) / den;
            let y = ypart + dp * u;
            let e = wk - y;
            for i in 0..np {
                xpn[i] = dot(&ap[i * np..(i + 1) * np], &xp) + bp[i] * u;
            }
            for i in 0..nc {
                xcn[i] = dot(&ac[i * nc..(i + 1) * nc], &xc) + bc[i] * e;
            }
            std::mem::swap(&mut xp, &mut xpn);
            std::mem::swap(&mut xc, &mut xcn);
            yv.push(y);
            uv.push(u);
        }
        LoopResponse { y: yv, u: uv }
    }
}

/// The largest loop (plant plus controller states) whose initial state
/// [`estimate_loop_initial_state`] estimates; a larger one starts from rest. The work is
/// $O(H n_x^2)$ for the free responses and $O(H n_x^2)$ for the least squares; identified plant
/// models have a few tens of states, and a model of hundreds is refused by this bound instead of
/// taking minutes.
pub const MAX_X0_LOOP_STATES: usize = 64;

/// The initial state of the loop (plant states, then controller states) that best explains the
/// measured `y_meas` and `u_meas`: the loop's response is affine in its initial state $x_0$,
/// $\hat y = y^{(0)} + \Psi_y x_0$, $\hat u = u^{(0)} + \Psi_u x_0$, where $y^{(0)}, u^{(0)}$
/// are the responses from rest and the columns of $\Psi$ the free responses to unit initial
/// states. $x_0$ minimises
/// $$ \frac{\lVert y - y^{(0)} - \Psi_y x_0 \rVert^2}{\lVert y \rVert^2} + \frac{\lVert u - u^{(0)} - \Psi_u x_0 \rVert^2}{\lVert u \rVert^2}, $$
/// both signals weighted by their own energy (they have different units). The free responses
/// decay with the closed loop's spectral radius $\rho < 1$; they are computed over
/// $H = \min(N, \lceil \ln 10^{-12} / \ln \rho \rceil)$ samples, beyond which they are below
/// $10^{-12}$ of their start. This is MATLAB `compare`'s default (`InitialCondition` =
/// `'e'`) applied to the closed loop, which is what a record taken in steady operation needs:
/// the loop was running before the first sample. Loops of more than [`MAX_X0_LOOP_STATES`]
/// states start from rest (zeros are returned).
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
    let n = check_inputs(plant, controller, w, r)?;
    if y_meas.len() != n || u_meas.len() != n {
        return Err(Error::DimensionMismatch {
            context: "estimate_loop_initial_state: measured signals and loop inputs",
            expected: format!("{n} samples"),
            got: format!("y_meas {}, u_meas {} samples", y_meas.len(), u_meas.len()),
        });
    }
    crate::error::check_finite("y_meas", y_meas)?;
    crate::error::check_finite("u_meas", u_meas)?;
    let lp = Loop::new(plant, controller)?;
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
    let (sy, su) = (1.0 / energy(y_meas), 1.0 / energy(u_meas));
    // free responses as rows: y_t = ψ_y A_cl^t x0, u_t = ψ_u A_cl^t x0, propagated by
    // ψ ← ψ A_cl (O(n_x²) per sample and output, not O(n_x³) for n_x unit simulations)
    let (a_cl, mut row_y, mut row_u) = lp.free_dynamics();
    let mut psi = faer::Mat::<f64>::zeros(2 * h, nx);
    let mut next = vec![0.0; nx];
    let times = |row: &[f64], out: &mut Vec<f64>| {
        for (j, o) in out.iter_mut().enumerate() {
            *o = (0..nx).map(|i| row[i] * a_cl[i * nx + j]).sum();
        }
    };
    for t in 0..h {
        for j in 0..nx {
            psi[(2 * t, j)] = sy * row_y[j];
            psi[(2 * t + 1, j)] = su * row_u[j];
        }
        times(&row_y, &mut next);
        std::mem::swap(&mut row_y, &mut next);
        times(&row_u, &mut next);
        std::mem::swap(&mut row_u, &mut next);
    }
    let rhs = faer::Mat::from_fn(2 * h, 1, |i, _| {
        let t = i / 2;
        if i % 2 == 0 {
            sy * (y_meas[t] - rest.y[t])
        } else {
            su * (u_meas[t] - rest.u[t])
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

/// Closed-loop reconstruction: simulates the loop with the identified `plant` and the real
/// `controller` driven by the reference `w` (and the excitation `r`, if any) and compares the
/// displacement and the current with the measured `y_meas`, `u_meas`, over the whole record and in
/// `n_windows` equal windows (for a chirp reference a window is a frequency band, so a local
/// mismatch such as an unmodelled mode is located in time and frequency). Fit $= 100\,(1 -
/// \lVert x - \hat x\rVert / \lVert x - \bar x\rVert)$.
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
    if n_windows == 0 || 2 * n_windows > n {
        return Err(Error::invalid(
            "n_windows",
            format!(
                "need 1 ≤ n_windows ≤ samples/2 = {}, got {n_windows}",
                n / 2
            ),
        ));
    }
    let x0 = match ic {
        InitialState::Zero => vec![0.0; plant.order() + controller.order()],
        InitialState::Estimate => {
            estimate_loop_initial_state(plant, controller, Some(w), r, y_meas, u_meas)?
        }
    };
    let sim = simulate_loop_from(plant, controller, Some(w), r, Some(&x0))?;
    // NaN for a constant window (the fit is undefined there)
    let fit = |x: &[f64], xh: &[f64]| fit_percent(x, xh).unwrap_or(f64::NAN);
    let len = n / n_windows;
    let windows = (0..n_windows)
        .map(|k| {
            let (a, b) = (k * len, if k + 1 == n_windows { n } else { (k + 1) * len });
            let e2: f64 = y_meas[a..b]
                .iter()
                .zip(&sim.y[a..b])
                .map(|(p, q)| (p - q).powi(2))
                .sum();
            WindowFit {
                t_s: (a as f64 * ts, b as f64 * ts),
                fit_y: fit(&y_meas[a..b], &sim.y[a..b]),
                fit_u: fit(&u_meas[a..b], &sim.u[a..b]),
                rms_error_y: (e2 / (b - a) as f64).sqrt(),
            }
        })
        .collect();
    Ok(Reconstruction {
        fit_y: fit(y_meas, &sim.y),
        fit_u: fit(u_meas, &sim.u),
        max_error_y: y_meas
            .iter()
            .zip(&sim.y)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max),
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
}
