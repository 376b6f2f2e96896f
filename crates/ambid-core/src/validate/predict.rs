//! $k$-step-ahead prediction with an innovation-form state-space model.
//!
//! For $x_{t+1} = A x_t + B u_t + K e_t$, $y_t = C x_t + D u_t + e_t$ the one-step predictor
//! $\hat x_{t+1|t} = A \hat x_{t|t-1} + B u_t + K (y_t - C \hat x_{t|t-1} - D u_t)$ uses the
//! measured outputs up to $t$; the $k$-step prediction continues it without outputs:
//! $$ \hat x_{t|t-k} = A^{k-1} \hat x_{t-k+1|t-k} + \sum_{j=1}^{k-1} A^{k-1-j} B u_{t-k+j},
//! \qquad \hat y_{t|t-k} = C \hat x_{t|t-k} + D u_t . $$
//! $k = 1$ is the one-step predictor; as $k \to \infty$ (stable $A$) it becomes the simulation;
//! with $K = 0$ it is the simulation for every $k$. The predictor starts from $\hat x_{0|-1} = 0$.
//! In closed loop $u$ is the measured plant input (the direct method's view). Work $O(N k n^2)$.
//!
//! # Example
//! ```
//! use ambid_core::validate::predict::predict_k;
//! use ambid_core::lti::StateSpace;
//! use faer::mat;
//! // AR(1) y_t = 0.8 y_{t-1} + e_t in innovation form: A = 0.8, C = 1, K = 0.8 (no input)
//! let m = StateSpace::discrete(mat![[0.8]], mat![[0.0]], mat![[1.0]], mat![[0.0]], 1.0).unwrap();
//! let y = [1.0, -0.5, 2.0, 0.3, 1.1];
//! let u = [0.0; 5];
//! let p = predict_k(&m, mat![[0.8]].as_ref(), &y, &u, 2).unwrap();
//! // ŷ(t|t−2) = 0.8² y(t−2)
//! assert!((p[4] - 0.64 * 2.0).abs() < 1e-12);
//! ```

use crate::error::{check_finite, Error, Result};
use crate::lti::StateSpace;
use faer::MatRef;

/// $\hat y_{t|t-k}$ for every $t$ (module docs) for a SISO `model` with Kalman gain `k_gain`
/// ($n \times 1$; zeros give the simulation).
///
/// # Errors
/// [`Error::InvalidArgument`] for a non-SISO model, `k` = 0 or a gain of the wrong size;
/// [`Error::DimensionMismatch`] for `y`, `u` of different lengths; [`Error::NonFinite`] for a NaN
/// sample.
pub fn predict_k(
    model: &StateSpace,
    k_gain: MatRef<'_, f64>,
    y: &[f64],
    u: &[f64],
    k: usize,
) -> Result<Vec<f64>> {
    let n = model.order();
    if model.ninputs() != 1 || model.noutputs() != 1 {
        return Err(Error::invalid(
            "model",
            "k-step prediction is implemented for SISO models",
        ));
    }
    if k == 0 {
        return Err(Error::invalid(
            "k",
            "the prediction horizon must be at least 1 sample",
        ));
    }
    if k_gain.nrows() != n || k_gain.ncols() != 1 {
        return Err(Error::invalid(
            "k_gain",
            format!(
                "the Kalman gain must be {n}×1, got {}×{}",
                k_gain.nrows(),
                k_gain.ncols()
            ),
        ));
    }
    if y.len() != u.len() {
        return Err(Error::DimensionMismatch {
            context: "predict_k: y and u",
            expected: format!("{} samples", y.len()),
            got: format!("{} samples", u.len()),
        });
    }
    check_finite("y", y)?;
    check_finite("u", u)?;
    let (a, b, c, d) = (model.a(), model.b(), model.c(), model.d()[(0, 0)]);
    let step = |x: &[f64], uv: f64, out: &mut Vec<f64>| {
        out.clear();
        out.extend((0..n).map(|i| (0..n).map(|j| a[(i, j)] * x[j]).sum::<f64>() + b[(i, 0)] * uv));
    };
    let cx = |x: &[f64]| (0..n).map(|j| c[(0, j)] * x[j]).sum::<f64>();
    // one-step predictor states x̂(t|t−1), t = 0..N
    let mut xs: Vec<Vec<f64>> = Vec::with_capacity(y.len() + 1);
    xs.push(vec![0.0; n]);
    let mut tmp = Vec::with_capacity(n);
    for t in 0..y.len() {
        let x = &xs[t];
        let e = y[t] - cx(x) - d * u[t];
        step(x, u[t], &mut tmp);
        let next: Vec<f64> = (0..n).map(|i| tmp[i] + k_gain[(i, 0)] * e).collect();
        xs.push(next);
    }
    let mut out = Vec::with_capacity(y.len());
    let mut z = vec![0.0; n];
    for t in 0..y.len() {
        // start from x̂(s|s−1) with s = t − k + 1 (or from rest), propagate with u only
        let s = (t + 1).saturating_sub(k);
        z.clear();
        z.extend_from_slice(&xs[s]);
        for &uj in &u[s..t] {
            step(&z, uj, &mut tmp);
            std::mem::swap(&mut z, &mut tmp);
        }
        out.push(cx(&z) + d * u[t]);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::mat;

    /// k = 1 is the one-step predictor; K = 0 is the simulation for every k; a large k of a stable
    /// model approaches the simulation.
    #[test]
    fn limits() {
        let m = StateSpace::discrete(
            mat![[0.9, 0.2], [-0.2, 0.9]],
            mat![[1.0], [0.5]],
            mat![[1.0, 0.3]],
            mat![[0.1]],
            1.0,
        )
        .unwrap();
        let kg = mat![[0.4], [-0.1]];
        let u: Vec<f64> = (0..200)
            .map(|t| ((t * 37 % 13) as f64 - 6.0) / 6.0)
            .collect();
        let y: Vec<f64> = (0..200).map(|t| (0.1 * t as f64).sin()).collect();
        // one-step predictor by hand
        let mut x = [0.0, 0.0];
        let p1 = predict_k(&m, kg.as_ref(), &y, &u, 1).unwrap();
        for t in 0..y.len() {
            let yh = x[0] + 0.3 * x[1] + 0.1 * u[t];
            assert!((yh - p1[t]).abs() < 1e-12, "t = {t}");
            let e = y[t] - yh;
            x = [
                0.9 * x[0] + 0.2 * x[1] + u[t] + 0.4 * e,
                -0.2 * x[0] + 0.9 * x[1] + 0.5 * u[t] - 0.1 * e,
            ];
        }
        let sim = m.simulate_siso(&u, None).unwrap();
        let p5 = predict_k(&m, mat![[0.0], [0.0]].as_ref(), &y, &u, 5).unwrap();
        assert!(sim.iter().zip(&p5).all(|(a, b)| (a - b).abs() < 1e-12));
        let p200 = predict_k(&m, kg.as_ref(), &y, &u, 200).unwrap();
        assert!(sim.iter().zip(&p200).all(|(a, b)| (a - b).abs() < 1e-12));
        assert!(predict_k(&m, kg.as_ref(), &y, &u, 0).is_err());
    }
}
