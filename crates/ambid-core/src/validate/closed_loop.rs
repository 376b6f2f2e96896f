//! Closed-loop simulation of an identified plant with the real controller: the time-domain
//! validation of a model of an open-loop unstable plant, which cannot be simulated alone.
//!
//! # Loop
//! The excitation $r$ is injected at the controller output, as in the experiment:
//! $$ u_k = r_k - (C * y)_k, \qquad y_k = (P * u)_k, $$
//! so $y = T_{ry} r$ with $T_{ry} = P/(1 + PC)$ and $u = S r$ with $S = 1/(1 + PC)$. The closed
//! loop is formed as a state-space model ([`StateSpace::feedback`]) and simulated from rest; $u$
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

/// Output and plant input of the simulated loop.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopResponse {
    /// Plant output $y$.
    pub y: Vec<f64>,
    /// Plant input $u = r - C y$.
    pub u: Vec<f64>,
}

/// Simulates the loop of the module docs for the SISO `plant` and `controller` (same sample
/// time) driven by `r`, from rest.
///
/// # Errors
/// * [`Error::InvalidArgument`]: a model that is not SISO.
/// * the errors of [`StateSpace::feedback`] (different sample times, an algebraic loop without a
///   solution) and of the simulation (non-finite `r`);
/// * [`Error::Unstable`]: the closed loop has a pole on or outside the unit circle.
pub fn simulate_loop(
    plant: &StateSpace,
    controller: &StateSpace,
    r: &[f64],
) -> Result<LoopResponse> {
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
    let y = t_ry.simulate_siso(r, None)?;
    let cy = controller.simulate_siso(&y, None)?;
    let u = r.iter().zip(&cy).map(|(r, c)| r - c).collect();
    Ok(LoopResponse { y, u })
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::mat;

    /// The loop simulated sample by sample with explicit plant and controller states (a naive
    /// oracle) agrees with the state-space closed loop.
    #[test]
    fn matches_a_sample_by_sample_loop() {
        let ts = 1e-3;
        // plant: unstable real pole and a lightly damped pair, strictly proper
        let p = StateSpace::discrete(
            mat![[1.02, 0.0, 0.0], [0.0, 0.9, 0.3], [0.0, -0.3, 0.9]],
            mat![[1.0], [0.0], [0.5]],
            mat![[0.4, 1.0, 0.2]],
            mat![[0.0]],
            ts,
        )
        .unwrap();
        // PD-like controller with feedthrough
        let c =
            StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[0.1]], mat![[0.3]], ts).unwrap();
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
        // an unstable loop is refused with a typed error
        let weak =
            StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[0.001]], ts).unwrap();
        assert!(matches!(
            simulate_loop(&p, &weak, &r),
            Err(Error::Unstable { .. })
        ));
    }
}
