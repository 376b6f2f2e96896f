//! Time-domain model fitting as `ambid fit` and the workflow do it: the state-space pipeline
//! (data scaled to unit RMS, subspace identification, optional prediction-error refinement,
//! model scaled back) and the fit figures of a polynomial model.

use crate::error::{Context, Error, Result};
use ambid_core::estimate::arx::{arx, ArxOrders};
use ambid_core::estimate::pem::Focus;
use ambid_core::estimate::ss_pem::{refine_ss, SsPemOptions};
use ambid_core::estimate::subspace::{n4sid_detailed, HorizonCriterion, SubspaceOptions};
use ambid_core::estimate::Fitted;
use ambid_core::lti::{PolyModel, StateSpace};
use ambid_core::validate::predict::{fit_from, poly_one_step, poly_simulate, InitialState};
use faer::Mat;

/// The least-squares ARX(na, nb, nk) model of `u → y` as a polynomial [`Fitted`] (the FIR and
/// ARX structures of `ambid fit`, the model it writes when an ARMAX/OE/BJ estimate fails, and
/// the Python package's `fit_arx`).
///
/// # Errors
/// As [`ambid_core::estimate::arx::arx`].
///
/// # Example
/// ```
/// // y(k) = 0.5 y(k-1) + 2 u(k-1), noise free: recovered exactly
/// let u: Vec<f64> = (0..200).map(|k| ((k * 7919) % 13) as f64 - 6.0).collect();
/// let mut y = vec![0.0; 200];
/// for k in 1..200 {
///     y[k] = 0.5 * y[k - 1] + 2.0 * u[k - 1];
/// }
/// let f = ambid::fitting::arx_fitted(&y, &u, 1, 1, 1, 1.0).unwrap();
/// assert!((f.params[0] + 0.5).abs() < 1e-12 && (f.params[1] - 2.0).abs() < 1e-12);
/// ```
pub fn arx_fitted(
    y: &[f64],
    u: &[f64],
    na: usize,
    nb: usize,
    nk: usize,
    ts: f64,
) -> ambid_core::Result<Fitted<PolyModel>> {
    let f = arx(y, &[u], &ArxOrders::siso(na, nb, nk), ts)?;
    Ok(Fitted {
        model: f.model.to_poly(0)?,
        params: f.params,
        covariance: f.covariance,
        loss: f.loss,
        noise_variance: f.noise_variance,
        n_samples: f.n_samples,
    })
}

/// What the prediction-error refinement did.
#[derive(Debug, Clone)]
pub struct PemSummary {
    /// Focus.
    pub focus: Focus,
    /// Iterations.
    pub iterations: usize,
    /// Why it stopped.
    pub stop: ambid_core::estimate::pem::lm::StopReason,
    /// Loss before (in the data's units squared).
    pub start_loss: f64,
    /// Loss after.
    pub loss: f64,
    /// Kalman gain of the innovations form (prediction focus), in the data's units.
    pub kalman_gain: Option<Vec<f64>>,
    /// The optimum lies on the predictor's stability boundary.
    pub on_boundary: bool,
    /// Initial state estimated by the refinement on the estimation record (model coordinates).
    pub x0: Option<Vec<f64>>,
}

impl PemSummary {
    /// The summary of a state-space refinement run on data whose output was divided by `sy`
    /// (losses and the Kalman gain are given back in the data's units).
    pub fn of_refinement(
        p: &ambid_core::estimate::ss_pem::SsPemFit,
        focus: Focus,
        sy: f64,
    ) -> PemSummary {
        PemSummary {
            focus,
            iterations: p.report.iterations,
            stop: p.report.reason,
            start_loss: p.start_loss * sy * sy,
            loss: p.fitted.loss * sy * sy,
            kalman_gain: p
                .kalman_gain
                .as_ref()
                .map(|k| (0..k.nrows()).map(|i| k[(i, 0)] / sy).collect()),
            on_boundary: p.report.ended_on_boundary,
            x0: Some(p.x0.clone()),
        }
    }
}

/// A state-space model identified from time data.
#[derive(Debug, Clone)]
pub struct SsIdentified {
    /// The model in the data's units.
    pub model: StateSpace,
    /// Order chosen by (or given to) the subspace step.
    pub order: usize,
    /// Block rows used.
    pub block_rows: usize,
    /// The horizons the automatic choice tried, with the criterion of each (empty when the block
    /// rows were given); see [`ambid_core::estimate::subspace::SubspaceFit::block_rows_scan`].
    pub block_rows_scan: Vec<(usize, f64)>,
    /// What the automatic horizon minimised (`None` when the block rows were given).
    pub block_rows_criterion: Option<HorizonCriterion>,
    /// Singular values of the subspace step.
    pub singular_values: Vec<f64>,
    /// The refinement, when it ran.
    pub pem: Option<PemSummary>,
}

/// Criterion of the prediction-error step of [`identify_state_space`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SsFocus {
    /// [`Focus::Simulation`] when the subspace model is stable, [`Focus::Prediction`] otherwise
    /// (the default; see [`identify_state_space`] for why).
    #[default]
    Auto,
    /// One-step-ahead prediction errors: $(A, B, C, K)$ are estimated.
    Prediction,
    /// Simulation (output) errors: $K = 0$, the noise model is 1.
    Simulation,
    /// No refinement: the subspace model is the result.
    None,
}

/// Settings of [`identify_state_space`] (what `ambid fit --structure ss` exposes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SsFitOptions {
    /// Model order; `None` chooses it from the singular values (up to 10).
    pub order: Option<usize>,
    /// Block rows of the subspace step; `None` for the automatic horizon
    /// ([`ambid_core::estimate::subspace`], "Choices and their reasons").
    pub block_rows: Option<usize>,
    /// Criterion of the refinement.
    pub focus: SsFocus,
    /// Iteration budget of the refinement (Levenberg–Marquardt steps).
    pub max_iterations: usize,
    /// Estimate a feed-through $D$ in the refinement (default `false`: $D = 0$).
    pub feedthrough: bool,
}

impl Default for SsFitOptions {
    /// Automatic order and horizon, [`SsFocus::Auto`], 100 iterations.
    fn default() -> Self {
        Self {
            order: None,
            block_rows: None,
            focus: SsFocus::Auto,
            max_iterations: 100,
            feedthrough: false,
        }
    }
}

/// The state-space pipeline of `ambid fit --structure ss`: subspace identification of `u → y`
/// (means already removed) with the automatic horizon unless `block_rows` is given, then the
/// prediction-error refinement under `opts.focus` ([`SsFocus::None`]: none).
///
/// **Focus default** ([`SsFocus::Auto`]): the simulation focus (output error) when the subspace
/// model is stable, the prediction focus otherwise. Output error is consistent whenever the
/// input is uncorrelated with the noise — the condition the subspace step needs anyway (open-loop
/// data, or the reference $r$ of a closed loop) — whatever the noise colour; it minimises what
/// the simulation fit measures; and it converges in a few iterations. The prediction focus on
/// closed-loop $r \to y$ data has its optimum on the predictor's stability boundary (the noise
/// $S\,n$ has zeros at the plant's unstable poles and the controller's integrator, which the
/// predictor $A - KC$ would have to reproduce), so it approaches that boundary slowly: on the
/// first 5 rigs of the sweep in `docs/estimation.md` it used 98–100 of its 100 iterations (about
/// 20 times the time) for the same validation fits, where the simulation focus needed 2–12.
/// An unstable subspace model (an unstable plant from $u$, the direct method in closed loop,
/// where only a noise model makes the estimate consistent) cannot be simulated, so it gets the
/// prediction focus with the subspace Kalman gain. Closed-loop $u \to y$ data should be fitted with
/// [`SsFocus::Prediction`] explicitly: output error from a feedback signal is biased.
///
/// # Errors
/// A constant input or output, and the errors of the estimators.
///
/// # Example
/// ```
/// use ambid::fitting::{identify_state_space, SsFitOptions, SsFocus};
/// // y_k = 0.9 y_{k-1} + u_{k-1} + small noise, u a random binary signal
/// let mut s = 1u64;
/// let mut draw = || {
///     s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
///     (s >> 11) as f64 / (1u64 << 53) as f64
/// };
/// let u: Vec<f64> = (0..4000).map(|_| if draw() < 0.5 { -1.0 } else { 1.0 }).collect();
/// let mut y = vec![0.0; u.len()];
/// for k in 1..u.len() {
///     y[k] = 0.9 * y[k - 1] + u[k - 1] + 1e-3 * (draw() - 0.5);
/// }
/// let o = SsFitOptions { order: Some(1), ..SsFitOptions::default() };
/// let fit = identify_state_space(&u, &y, 1.0, &o).unwrap();
/// let p = fit.pem.as_ref().unwrap();
/// assert_eq!(p.focus, ambid_core::estimate::pem::Focus::Simulation);
/// assert!((fit.model.a()[(0, 0)] - 0.9).abs() < 1e-3);
/// ```
pub fn identify_state_space(
    u: &[f64],
    y: &[f64],
    ts: f64,
    opts: &SsFitOptions,
) -> Result<SsIdentified> {
    let lm = SsPemOptions::default()
        .lm
        .with_max_iterations(opts.max_iterations)?;
    let pem = |focus| SsPemOptions {
        focus,
        lm,
        feedthrough: opts.feedthrough,
        ..SsPemOptions::default()
    };
    let (pem, auto) = match opts.focus {
        SsFocus::None => (None, false),
        SsFocus::Prediction => (Some(pem(Focus::Prediction)), false),
        SsFocus::Simulation => (Some(pem(Focus::Simulation)), false),
        SsFocus::Auto => (Some(pem(Focus::Simulation)), true),
    };
    fit_scaled(u, y, ts, opts.order, opts.block_rows, pem, auto)
}

/// Subspace identification (N4SID) of `u → y` (means already removed), then, with `pem`, the
/// prediction-error refinement; the data are scaled to unit RMS for the algorithms and the model
/// is scaled back.
///
/// # Errors
/// A constant input or output, and the errors of the estimators.
pub fn fit_state_space(
    u: &[f64],
    y: &[f64],
    ts: f64,
    order: Option<usize>,
    block_rows: Option<usize>,
    pem: Option<SsPemOptions>,
) -> Result<SsIdentified> {
    fit_scaled(u, y, ts, order, block_rows, pem, false)
}

/// [`fit_state_space`]; with `auto_focus` the focus of `pem` is replaced by the simulation
/// focus for a stable subspace model and the prediction focus otherwise.
fn fit_scaled(
    u: &[f64],
    y: &[f64],
    ts: f64,
    order: Option<usize>,
    block_rows: Option<usize>,
    pem: Option<SsPemOptions>,
    auto_focus: bool,
) -> Result<SsIdentified> {
    let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt();
    let (su, sy) = (rms(u), rms(y));
    if su == 0.0 || sy == 0.0 {
        return Err(Error::other(
            "the input or the output is constant after removing its mean: nothing to identify",
        ));
    }
    let um = Mat::from_fn(u.len(), 1, |k, _| u[k] / su);
    let ym = Mat::from_fn(y.len(), 1, |k, _| y[k] / sy);
    let mut opts = SubspaceOptions::new(ts);
    opts.order = order;
    opts.block_rows = block_rows;
    let fit = n4sid_detailed(ym.as_ref(), um.as_ref(), &opts).context("subspace identification")?;
    let mut scaled = fit.fitted.model.clone();
    let mut summary = None;
    if let Some(mut o) = pem {
        if auto_focus {
            o.focus = if scaled.is_stable()? {
                Focus::Simulation
            } else {
                Focus::Prediction
            };
        }
        let k = fit.kalman_gain.as_ref().map(|k| k.as_ref());
        let p = refine_ss(ym.as_ref(), um.as_ref(), &scaled, k, &o)
            .context("prediction-error refinement of the subspace model")?;
        summary = Some(PemSummary::of_refinement(&p, o.focus, sy));
        scaled = p.fitted.model;
    }
    let m = &scaled;
    let model = StateSpace::discrete(
        m.a().to_owned(),
        m.b() * faer::Scale(1.0 / su),
        m.c() * faer::Scale(sy),
        m.d() * faer::Scale(sy / su),
        ts,
    )?;
    Ok(SsIdentified {
        model,
        order: fit.order,
        block_rows: fit.block_rows,
        block_rows_scan: fit.block_rows_scan,
        block_rows_criterion: fit.block_rows_criterion,
        singular_values: fit.singular_values,
        pem: summary,
    })
}

/// One-step-ahead prediction fit % and simulation fit % of a polynomial model on `(y, u)`,
/// both from the initial state `x0` (estimated on the record by default, MATLAB `compare`'s
/// convention; see [`ambid_core::validate::predict`]) and scored from sample `skip` on. `None`
/// for a fit whose model output diverges (an unstable predictor or simulation).
///
/// # Errors
/// The errors of the predictor and the simulation on bad data.
pub fn poly_fits(
    m: &PolyModel,
    y: &[f64],
    u: &[f64],
    x0: InitialState,
    skip: usize,
) -> Result<(Option<f64>, Option<f64>)> {
    let yhat = poly_one_step(m, y, u, x0)?;
    let ysim = poly_simulate(m, y, u, x0)?;
    Ok((fit_from(y, &yhat, skip), fit_from(y, &ysim, skip)))
}
