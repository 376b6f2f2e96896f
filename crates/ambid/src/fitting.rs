//! Time-domain model fitting as `ambid fit` and the workflow do it: the state-space pipeline
//! (data scaled to unit RMS, subspace identification, optional prediction-error refinement,
//! model scaled back) and the fit figures of a polynomial model.

use ambid_core::estimate::pem::Focus;
use ambid_core::estimate::ss_pem::{refine_ss, SsPemOptions};
use ambid_core::estimate::subspace::{n4sid_detailed, SubspaceOptions};
use ambid_core::lti::{PolyModel, StateSpace};
use ambid_core::validate::predict::{fit_from, poly_one_step, poly_simulate, InitialState};
use anyhow::{bail, Context, Result};
use faer::Mat;

/// What the prediction-error refinement did.
#[derive(Debug, Clone)]
pub struct PemSummary {
    /// Focus.
    pub focus: Focus,
    /// Iterations.
    pub iterations: usize,
    /// Why it stopped.
    pub stop: String,
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

/// A state-space model identified from time data.
#[derive(Debug, Clone)]
pub struct SsIdentified {
    /// The model in the data's units.
    pub model: StateSpace,
    /// Order chosen by (or given to) the subspace step.
    pub order: usize,
    /// Block rows used.
    pub block_rows: usize,
    /// Singular values of the subspace step.
    pub singular_values: Vec<f64>,
    /// The refinement, when it ran.
    pub pem: Option<PemSummary>,
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
    let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt();
    let (su, sy) = (rms(u), rms(y));
    if su == 0.0 || sy == 0.0 {
        bail!("the input or the output is constant after removing its mean: nothing to identify");
    }
    let um = Mat::from_fn(u.len(), 1, |k, _| u[k] / su);
    let ym = Mat::from_fn(y.len(), 1, |k, _| y[k] / sy);
    let mut opts = SubspaceOptions::new(ts);
    opts.order = order;
    opts.block_rows = block_rows;
    let fit = n4sid_detailed(ym.as_ref(), um.as_ref(), &opts).context("subspace identification")?;
    let mut scaled = fit.fitted.model.clone();
    let mut summary = None;
    if let Some(o) = pem {
        let k = fit.kalman_gain.as_ref().map(|k| k.as_ref());
        let p = refine_ss(ym.as_ref(), um.as_ref(), &scaled, k, &o)
            .context("prediction-error refinement of the subspace model")?;
        summary = Some(PemSummary {
            focus: o.focus,
            iterations: p.report.iterations,
            stop: format!("{:?}", p.report.reason),
            start_loss: p.start_loss * sy * sy,
            loss: p.fitted.loss * sy * sy,
            kalman_gain: p
                .kalman_gain
                .as_ref()
                .map(|k| (0..k.nrows()).map(|i| k[(i, 0)] / sy).collect()),
            on_boundary: p.report.ended_on_boundary,
            x0: Some(p.x0.clone()),
        });
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
