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
    predict_k_from(model, k_gain, y, u, k, None)
}

/// [`predict_k`] with the predictor started from $\hat x_{0|-1} = x_0$ (`None`: zero).
///
/// # Errors
/// As [`predict_k`]; [`Error::InvalidArgument`] for an `x0` that is not $n$ finite numbers.
pub fn predict_k_from(
    model: &StateSpace,
    k_gain: MatRef<'_, f64>,
    y: &[f64],
    u: &[f64],
    k: usize,
    x0: Option<&[f64]>,
) -> Result<Vec<f64>> {
    let n = model.order();
    if let Some(x) = x0 {
        if x.len() != n || x.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid(
                "x0",
                format!(
                    "the initial state must be {n} finite numbers, got {}",
                    x.len()
                ),
            ));
        }
    }
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
    xs.push(x0.map_or_else(|| vec![0.0; n], <[f64]>::to_vec));
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

/// [`predict_k`] from rest ([`InitialState::Zero`]) or from the predictor's initial state
/// that best explains the record ([`InitialState::Estimate`]); returns the prediction and the
/// state used. The prediction is affine in $x_0 = \hat x_{0|-1}$: with
/// $\Phi = A - K C$ its free part is
/// $$ \hat y^{\mathrm{free}}_{t|t-k} = \begin{cases} C A^{t} x_0, & t < k - 1,\\
///  C A^{k-1} \Phi^{\,t-k+1} x_0, & t \ge k - 1, \end{cases} $$
/// so $x_0$ is the least-squares solution of $y_t - \hat y^{(0)}_{t|t-k} = \psi_t x_0$ over the
/// record (rows $\psi_t$ computed recursively, $O(N n^2)$). An unstable predictor ($\Phi$ with
/// an eigenvalue on or outside the unit circle) starts from rest.
///
/// # Errors
/// As [`predict_k`].
pub fn predict_k_with(
    model: &StateSpace,
    k_gain: MatRef<'_, f64>,
    y: &[f64],
    u: &[f64],
    k: usize,
    ic: InitialState,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let n = model.order();
    let rest = predict_k_from(model, k_gain, y, u, k, None)?;
    let nt = y.len();
    if ic == InitialState::Zero || n == 0 || nt < n {
        return Ok((rest, vec![0.0; n]));
    }
    let (a, c) = (model.a(), model.c());
    let phi = faer::Mat::<f64>::from_fn(n, n, |i, j| a[(i, j)] - k_gain[(i, 0)] * c[(0, j)]);
    let phi_model = StateSpace::discrete(
        phi.clone(),
        faer::Mat::zeros(n, 1),
        faer::Mat::zeros(1, n),
        faer::Mat::zeros(1, 1),
        model.ts().unwrap_or(1.0),
    )?;
    if !phi_model.is_stable()? {
        return Ok((rest, vec![0.0; n]));
    }
    // ψ_t for t < k − 1: C A^t; then C A^{k−1} Φ^{t−k+1}
    let times = |row: &[f64], m: MatRef<'_, f64>| -> Vec<f64> {
        (0..n)
            .map(|j| (0..n).map(|i| row[i] * m[(i, j)]).sum())
            .collect()
    };
    let mut psi = faer::Mat::<f64>::zeros(nt, n);
    let mut row: Vec<f64> = (0..n).map(|j| c[(0, j)]).collect();
    for t in 0..nt {
        for j in 0..n {
            psi[(t, j)] = row[j];
        }
        row = if t + 1 < k {
            times(&row, a)
        } else {
            times(&row, phi.as_ref())
        };
    }
    let rhs = faer::Mat::from_fn(nt, 1, |t, _| y[t] - rest[t]);
    // minimum norm: predictor states the record cannot see stay at zero
    let x0 = match crate::linalg::lstsq_min_norm(psi.as_ref(), rhs.as_ref(), 1e-10) {
        Ok(x) if x.iter().all(|v| v.is_finite()) => x,
        _ => return Ok((rest, vec![0.0; n])),
    };
    // the prediction is affine in x0: the one from rest plus the free part, no second run
    let p = (0..nt)
        .map(|t| rest[t] + (0..n).map(|j| psi[(t, j)] * x0[j]).sum::<f64>())
        .collect();
    Ok((p, x0))
}

/// How a validation starts the model's filters (MATLAB `compare`'s `InitialCondition`).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum InitialState {
    /// From rest: every sample before $t = 0$ taken as zero.
    Zero,
    /// The initial state that best explains the record: least squares of the free response
    /// over the whole record ([`filter_with_initial_state`]). MATLAB `compare`'s default.
    #[default]
    Estimate,
}

impl InitialState {
    /// `zero` or `estimate`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Zero => "zero",
            Self::Estimate => "estimate",
        }
    }
}

fn conv(p: &[f64], q: &[f64]) -> Vec<f64> {
    if p.is_empty() || q.is_empty() {
        return Vec::new();
    }
    let mut r = vec![0.0; p.len() + q.len() - 1];
    for (i, a) in p.iter().enumerate() {
        for (j, b) in q.iter().enumerate() {
            r[i + j] += a * b;
        }
    }
    r
}

/// Output of the multi-input filter $\hat y_t = \sum_i \frac{N_i(q)}{D(q)} x^{(i)}_t$ (polynomials
/// in $q^{-1}$, $D$ monic), realised in observer canonical form
/// $$ s_{t+1} = A s_t + \textstyle\sum_i B_i x^{(i)}_t, \qquad \hat y_t = s_{1,t} + \sum_i n_{i,0}\, x^{(i)}_t, $$
/// $A_{j,1} = -d_j$, $A_{j,j+1} = 1$, $B_{i,j} = n_{i,j} - d_j n_{i,0}$ (order $n$ = the longest
/// polynomial's degree). With [`InitialState::Estimate`] the initial state $s_0$ is the least-squares
/// solution of $y_t - \hat y^{(0)}_t = C A^t s_0$ over the record, $\hat y^{(0)}$ the response from
/// rest and $C = e_1^\top$ (always observable); the returned output is $\hat y^{(0)}_t + C A^t s_0$,
/// the best-fitting response of the filter to the inputs over all starting states, which is what
/// MATLAB's `compare` reports. A filter with $D$ unstable (an unstable simulation model) starts
/// from rest, because its free response has no meaningful least-squares fit; its output then
/// diverges and the fit measure says so.
///
/// States that the record cannot tell apart are resolved by a ridge of $10^{-9}$ times the
/// largest column norm (their minimum-norm combination); if the solve still fails the filter
/// starts from rest. Returns the output and the initial state used. Work $O(N n (n + m))$.
///
/// # Errors
/// [`Error::DimensionMismatch`] if the signals differ in length or `nums` and `inputs` in count;
/// [`Error::InvalidArgument`] for a non-monic `den`; [`Error::NonFinite`] for a NaN sample; the
/// errors of the least-squares solve.
///
/// # Example
/// ```
/// use ambid_core::validate::predict::{filter_with_initial_state, InitialState};
/// // y = 0.9 y(t−1) + u(t−1), started from y(−1) = 5 (so the record does not start at rest)
/// let u: Vec<f64> = (0..50).map(|t| ((t * 7 % 5) as f64) - 2.0).collect();
/// let mut y = vec![0.0; 50];
/// let mut prev = (5.0, 0.0);
/// for t in 0..50 {
///     y[t] = 0.9 * prev.0 + prev.1;
///     prev = (y[t], u[t]);
/// }
/// let (yh, _) = filter_with_initial_state(&[1.0, -0.9], &[&[0.0, 1.0]], &[&u], &y, InitialState::Estimate).unwrap();
/// assert!(yh.iter().zip(&y).all(|(a, b)| (a - b).abs() < 1e-9));
/// let (y0, _) = filter_with_initial_state(&[1.0, -0.9], &[&[0.0, 1.0]], &[&u], &y, InitialState::Zero).unwrap();
/// assert!((y0[0] - y[0]).abs() > 4.0);
/// ```
pub fn filter_with_initial_state(
    den: &[f64],
    nums: &[&[f64]],
    inputs: &[&[f64]],
    y: &[f64],
    ic: InitialState,
) -> Result<(Vec<f64>, Vec<f64>)> {
    if nums.len() != inputs.len() {
        return Err(Error::DimensionMismatch {
            context: "filter_with_initial_state: numerators and inputs",
            expected: format!("{} inputs", nums.len()),
            got: format!("{}", inputs.len()),
        });
    }
    if den.first().copied() != Some(1.0) {
        return Err(Error::invalid(
            "den",
            "the denominator must be monic (d_0 = 1)",
        ));
    }
    let nt = y.len();
    for x in inputs {
        if x.len() != nt {
            return Err(Error::DimensionMismatch {
                context: "filter_with_initial_state: inputs and y",
                expected: format!("{nt} samples"),
                got: format!("{} samples", x.len()),
            });
        }
        check_finite("input", x)?;
    }
    check_finite("y", y)?;
    let n = nums
        .iter()
        .map(|p| p.len())
        .chain(std::iter::once(den.len()))
        .max()
        .unwrap_or(1)
        .saturating_sub(1);
    let at = |p: &[f64], j: usize| p.get(j).copied().unwrap_or(0.0);
    let mut out = vec![0.0; nt];
    let mut st = vec![0.0; n];
    for t in 0..nt {
        let direct: f64 = nums.iter().zip(inputs).map(|(p, x)| at(p, 0) * x[t]).sum();
        let yt = st.first().copied().unwrap_or(0.0) + direct;
        out[t] = yt;
        for j in 0..n {
            let next = if j + 1 < n { st[j + 1] } else { 0.0 };
            let drive: f64 = nums
                .iter()
                .zip(inputs)
                .map(|(p, x)| at(p, j + 1) * x[t])
                .sum();
            st[j] = next + drive - at(den, j + 1) * yt;
        }
    }
    let stable = n == 0 || crate::estimate::pem::denominator_is_stable(den);
    if ic == InitialState::Zero || n == 0 || !stable || nt < n {
        return Ok((out, vec![0.0; n]));
    }
    // observability rows C A^t, C = e1: (r A)_0 = -sum_j r_j d_{j+1}, (r A)_k = r_{k-1}
    let mut obs = faer::Mat::<f64>::zeros(nt, n);
    let mut row = vec![0.0; n];
    row[0] = 1.0;
    for t in 0..nt {
        for k in 0..n {
            obs[(t, k)] = row[k];
        }
        let first: f64 = -(0..n).map(|j| row[j] * at(den, j + 1)).sum::<f64>();
        for k in (1..n).rev() {
            row[k] = row[k - 1];
        }
        row[0] = first;
    }
    // a tiny ridge (1e-9 of the largest column norm) keeps the solve defined when states are
    // indistinguishable on this record (smooth data, nearly cancelling poles): their
    // combination is then the minimum-norm one, which leaves the response unchanged
    let cmax = (0..n)
        .map(|k| (0..nt).map(|t| obs[(t, k)].powi(2)).sum::<f64>().sqrt())
        .fold(0.0f64, f64::max);
    let ridge = 1e-9 * cmax;
    let aug = faer::Mat::from_fn(nt + n, n, |t, k| {
        if t < nt {
            obs[(t, k)]
        } else if t - nt == k {
            ridge
        } else {
            0.0
        }
    });
    let r = faer::Mat::from_fn(nt + n, 1, |t, _| if t < nt { y[t] - out[t] } else { 0.0 });
    let s0 = match crate::linalg::lstsq(aug.as_ref(), r.as_ref()) {
        Ok(s) => s,
        Err(_) => return Ok((out, vec![0.0; n])),
    };
    let s0: Vec<f64> = (0..n).map(|k| s0[(k, 0)]).collect();
    if s0.iter().any(|v| !v.is_finite()) {
        return Ok((out, vec![0.0; n]));
    }
    for (t, o) in out.iter_mut().enumerate() {
        *o += (0..n).map(|k| obs[(t, k)] * s0[k]).sum::<f64>();
    }
    Ok((out, s0))
}

/// One-step-ahead prediction $\hat y_{t|t-1} = \bigl(1 - \frac{D A}{C}\bigr) y_t + \frac{D B}{C F} u_t$
/// of a polynomial model (common denominator $C F$), from rest or from the estimated initial
/// state ([`filter_with_initial_state`]). With the estimate an ARX(8, 8, 1) predictor no longer
/// pays for the 8 unknown past samples (flutter validation: −503 % from rest, 99.98 % with
/// the estimated state).
///
/// # Errors
/// As [`filter_with_initial_state`]; `y`, `u` of different lengths.
pub fn poly_one_step(
    m: &crate::lti::PolyModel,
    y: &[f64],
    u: &[f64],
    ic: InitialState,
) -> Result<Vec<f64>> {
    let cf = conv(m.c(), m.f());
    let daf = conv(&conv(m.d(), m.a()), m.f());
    let len = cf.len().max(daf.len());
    let num_y: Vec<f64> = (0..len)
        .map(|j| cf.get(j).copied().unwrap_or(0.0) - daf.get(j).copied().unwrap_or(0.0))
        .collect();
    let num_u = conv(m.d(), m.b());
    Ok(filter_with_initial_state(&cf, &[&num_y, &num_u], &[y, u], y, ic)?.0)
}

/// Simulation $\hat y = \frac{B}{A F} u$ of a polynomial model, from rest or from the estimated
/// initial state ([`filter_with_initial_state`]; an unstable $A F$ starts from rest and diverges).
///
/// # Errors
/// As [`filter_with_initial_state`].
pub fn poly_simulate(
    m: &crate::lti::PolyModel,
    y: &[f64],
    u: &[f64],
    ic: InitialState,
) -> Result<Vec<f64>> {
    let af = conv(m.a(), m.f());
    Ok(filter_with_initial_state(&af, &[m.b()], &[u], y, ic)?.0)
}

/// Simulation of a SISO state-space model from rest or from the initial state estimated on
/// the record ([`StateSpace::estimate_initial_state`], stable models only; an unstable model
/// starts from rest). Returns the output and the state used.
///
/// # Errors
/// The errors of the simulation and of the estimate.
pub fn ss_simulate(
    m: &StateSpace,
    y: &[f64],
    u: &[f64],
    ic: InitialState,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let n = m.order();
    let stable = m.is_stable()?;
    let x0 = if ic == InitialState::Estimate && stable && y.len() >= n {
        m.estimate_initial_state(u, y)
            .ok()
            .filter(|x| x.iter().all(|v| v.is_finite()))
            .unwrap_or_else(|| vec![0.0; n])
    } else {
        vec![0.0; n]
    };
    Ok((m.simulate_siso(u, Some(&x0))?, x0))
}

/// Simulation of a (MIMO) state-space model on `u` ($N \times m$) from rest or from the initial
/// state that best explains `y` ($N \times l$): the least-squares solution of
/// $y_t - y^{(0)}_t = C A^t x_0$ stacked over every output and sample, of minimum norm (stable
/// models only; an unstable model starts from rest). Returns the $N \times l$ output and the state used.
///
/// # Errors
/// [`Error::DimensionMismatch`] for records of different lengths or widths; the errors of the
/// simulation.
pub fn ss_simulate_mimo(
    m: &StateSpace,
    y: MatRef<'_, f64>,
    u: MatRef<'_, f64>,
    ic: InitialState,
) -> Result<(faer::Mat<f64>, Vec<f64>)> {
    let (nt, l, n) = (u.nrows(), m.noutputs(), m.order());
    if y.nrows() != nt || y.ncols() != l {
        return Err(Error::DimensionMismatch {
            context: "ss_simulate_mimo: y",
            expected: format!("{nt} × {l}"),
            got: format!("{} × {}", y.nrows(), y.ncols()),
        });
    }
    let y0 = m.simulate(u, None)?;
    if ic == InitialState::Zero || n == 0 || !m.is_stable()? || nt * l < n {
        return Ok((y0, vec![0.0; n]));
    }
    let a = m.a();
    let c = m.c();
    let mut obs = faer::Mat::<f64>::zeros(nt * l, n);
    let mut ca = c.to_owned();
    for t in 0..nt {
        for j in 0..l {
            for k in 0..n {
                obs[(t * l + j, k)] = ca[(j, k)];
            }
        }
        ca = &ca * a;
    }
    let r = faer::Mat::from_fn(nt * l, 1, |i, _| y[(i / l, i % l)] - y0[(i / l, i % l)]);
    // minimum norm: a non-minimal realisation (e.g. a multi-output ARX's shift register) has
    // states the record cannot tell apart
    let x0 = match crate::linalg::lstsq_min_norm(obs.as_ref(), r.as_ref(), 1e-10) {
        Ok(x) if x.iter().all(|v| v.is_finite()) => x,
        _ => vec![0.0; n],
    };
    Ok((m.simulate(u, Some(&x0))?, x0))
}

/// Fit \[%\] $100\,(1 - \lVert y - \hat y\rVert / \lVert y - \bar y\rVert)$ over the samples from
/// `skip` on (the mean over the same samples); `None` if the model output is not finite there
/// (a diverging simulation), the range is empty or $y$ is constant on it.
///
/// # Example
/// ```
/// use ambid_core::validate::predict::fit_from;
/// let y = [9.0, 1.0, 2.0, 3.0];
/// assert_eq!(fit_from(&y, &[0.0, 1.0, 2.0, 3.0], 1), Some(100.0));
/// assert_eq!(fit_from(&y, &[0.0, 1.0, f64::INFINITY, 3.0], 1), None);
/// ```
pub fn fit_from(y: &[f64], yhat: &[f64], skip: usize) -> Option<f64> {
    let n = y.len().min(yhat.len());
    if skip >= n {
        return None;
    }
    let (y, yh) = (&y[skip..n], &yhat[skip..n]);
    if yh.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let spread = y.iter().map(|v| (v - mean).powi(2)).sum::<f64>().sqrt();
    let err = y
        .iter()
        .zip(yh)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    (spread > 0.0 && err.is_finite()).then(|| 100.0 * (1.0 - err / spread))
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

    /// Estimated initial state against an in-test oracle: an ARX(2,2,1) record started from a
    /// non-zero past; the one-step predictor and the simulation from the estimated state match
    /// the record exactly (noise-free), from rest they do not.
    #[test]
    fn estimated_initial_state_removes_the_start_transient() {
        use crate::lti::PolyModel;
        let m = PolyModel::arx(vec![1.0, -1.5, 0.7], vec![0.0, 1.0, 0.5], 1.0).unwrap();
        let u: Vec<f64> = (0..300)
            .map(|t| ((t * 37 % 11) as f64 - 5.0) / 5.0)
            .collect();
        // y(t) = 1.5 y(t−1) − 0.7 y(t−2) + u(t−1) + 0.5 u(t−2) with y(−1) = 3, y(−2) = −2, u(−1) = 1
        let (mut y1, mut y2, mut u1, mut u2) = (3.0, -2.0, 1.0, 0.0);
        let mut y = Vec::new();
        for &ut in &u {
            let v = 1.5 * y1 - 0.7 * y2 + u1 + 0.5 * u2;
            y.push(v);
            (y2, y1, u2, u1) = (y1, v, u1, ut);
        }
        let p = poly_one_step(&m, &y, &u, InitialState::Estimate).unwrap();
        assert!(p.iter().zip(&y).all(|(a, b)| (a - b).abs() < 1e-9));
        let s = poly_simulate(&m, &y, &u, InitialState::Estimate).unwrap();
        assert!(s.iter().zip(&y).all(|(a, b)| (a - b).abs() < 1e-8));
        let p0 = poly_one_step(&m, &y, &u, InitialState::Zero).unwrap();
        assert!((p0[0] - y[0]).abs() > 1.0);
        assert!(p0
            .iter()
            .zip(&y)
            .skip(2)
            .all(|(a, b)| (a - b).abs() < 1e-12));
        assert_eq!(fit_from(&y, &p, 0).map(|f| f > 99.999), Some(true));
        // SS from the same model: the estimated state reproduces the record
        // observer canonical form of B/A: A = [[1.5, 1], [−0.7, 0]], B = [1, 0.5]ᵀ, C = [1, 0]
        let ss = StateSpace::discrete(
            mat![[1.5, 1.0], [-0.7, 0.0]],
            mat![[1.0], [0.5]],
            mat![[1.0, 0.0]],
            mat![[0.0]],
            1.0,
        )
        .unwrap();
        let (ys, x0) = ss_simulate(&ss, &y, &u, InitialState::Estimate).unwrap();
        assert!(
            ys.iter().zip(&y).all(|(a, b)| (a - b).abs() < 1e-7),
            "{x0:?}"
        );
    }

    /// Data of the innovation model with e = 0 started from x0 ≠ 0: the predictor from x0 is exact
    /// for every k; the estimate recovers x0 (so the fit is 100 %) while the predictor from rest
    /// is not exact at the start.
    #[test]
    fn k_step_initial_state_is_recovered() {
        let m = StateSpace::discrete(
            mat![[0.95, 0.2, 0.0], [-0.2, 0.95, 0.1], [0.0, 0.0, 0.7]],
            mat![[1.0], [0.5], [0.3]],
            mat![[1.0, 0.3, -0.4]],
            mat![[0.0]],
            1e-3,
        )
        .unwrap();
        let kg = mat![[0.3], [0.1], [0.05]];
        let u: Vec<f64> = (0..300)
            .map(|k| ((k * 13 % 7) as f64 - 3.0) / 3.0)
            .collect();
        let truth = [1.5, -0.8, 2.0];
        let y = m.simulate_siso(&u, Some(&truth)).unwrap();
        for k in [1, 3, 10] {
            let exact = predict_k_from(&m, kg.as_ref(), &y, &u, k, Some(&truth)).unwrap();
            assert!(
                exact.iter().zip(&y).all(|(a, b)| (a - b).abs() < 1e-9),
                "k = {k}"
            );
            let (p, x0) =
                predict_k_with(&m, kg.as_ref(), &y, &u, k, InitialState::Estimate).unwrap();
            for (a, b) in x0.iter().zip(&truth) {
                assert!((a - b).abs() < 1e-7, "k = {k}: {x0:?}");
            }
            assert!(fit_from(&y, &p, 0).unwrap() > 100.0 - 1e-6, "k = {k}");
            let (p0, z) = predict_k_with(&m, kg.as_ref(), &y, &u, k, InitialState::Zero).unwrap();
            assert_eq!(z, vec![0.0; 3]);
            assert!(fit_from(&y, &p0, 0).unwrap() < 99.0, "k = {k}");
        }
    }
}
