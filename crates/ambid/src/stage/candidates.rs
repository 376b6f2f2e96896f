//! A model candidate of the models stage and how it answers on a record: the types the order,
//! models, pole-zero and validation steps share (no step imports another step for them).

use ambid_core::lti::{PolyModel, StateSpace};

/// One fitted candidate.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// `arx`, `oe` or `ss`.
    pub structure: &'static str,
    /// Model order.
    pub order: usize,
    /// The fitted model (`None`: the fit failed, the reason is in `note`).
    pub model: Option<StateSpace>,
    /// Its polynomial form, when fitted as one (time-domain ARX/OE).
    pub poly: Option<PolyModel>,
    /// Real parameters.
    pub n_params: usize,
    /// Relative RMS error against the measured plant FRF.
    pub relative_rmse: Option<f64>,
    /// Median relative error against the measured plant FRF.
    pub median_relative: Option<f64>,
    /// RMS error in dB against the measured plant FRF (FRF fits).
    pub db_rmse: Option<f64>,
    /// Bayesian information criterion (FRF fits).
    pub bic: Option<f64>,
    /// Validation fit on the independent record \[%\].
    pub validation_fit: Option<f64>,
    /// Unstable poles of the model.
    pub unstable_poles: Option<usize>,
    /// On the twin: median relative error against the exact plant.
    pub truth_median_relative: Option<f64>,
    /// May be chosen (FRF fits: the supported number of unstable poles and a stable loop with
    /// the controller, see [`ambid_core::validate::compare`]; time fits: fitted).
    pub valid: bool,
    /// Why the fit failed, why it is not valid, or how it was validated.
    pub note: Option<String>,
    /// Kalman gain of the innovations form (time-domain state-space fits).
    pub kalman: Option<Vec<f64>>,
}

impl Candidate {
    /// A time-domain fit that succeeded: chosen by its validation fit, with no FRF figures yet.
    pub fn time_fit(
        structure: &'static str,
        order: usize,
        poly: Option<PolyModel>,
        n_params: usize,
        kalman: Option<Vec<f64>>,
    ) -> Self {
        Candidate {
            structure,
            order,
            model: None,
            poly,
            n_params,
            relative_rmse: None,
            median_relative: None,
            db_rmse: None,
            bic: None,
            validation_fit: None,
            unstable_poles: None,
            truth_median_relative: None,
            valid: true,
            note: None,
            kalman,
        }
    }

    /// The label of the report and `summary.json`, e.g. `OE 8`.
    pub fn label(&self) -> String {
        format!("{} {}", self.structure.to_uppercase(), self.order)
    }
}

/// Open-loop simulation of a stable model from the initial state that best explains the
/// record (least squares, as MATLAB's `compare` does by default).
pub fn simulate_from_estimated_state(
    m: &StateSpace,
    u: &[f64],
    y: &[f64],
) -> ambid_core::Result<Vec<f64>> {
    let x0 = m.estimate_initial_state(u, y)?;
    m.simulate_siso(u, Some(&x0))
}

/// How a model is compared with an open-loop (or controller-less) record.
pub const SIMULATION: &str = "simulation from the least-squares initial state";
/// The fallback for unstable models that have a predictor.
pub const ONE_STEP: &str = "1-step prediction";

/// The model's response on a record: the simulation from the least-squares initial state when
/// the model is stable (MATLAB `compare`'s default), else the one-step prediction where a
/// predictor exists (ARX's, or the innovations form with its Kalman gain); `None` otherwise.
pub fn open_loop_response(
    c: &Candidate,
    m: &StateSpace,
    y: &[f64],
    u: &[f64],
) -> Option<(Vec<f64>, &'static str)> {
    let stable = m
        .poles()
        .map(|p| p.iter().all(|z| z.norm() < 1.0))
        .unwrap_or(false);
    if stable {
        if let Ok(ys) = simulate_from_estimated_state(m, u, y) {
            return Some((ys, SIMULATION));
        }
    }
    match (c.structure, &c.poly, &c.kalman) {
        ("arx", Some(p), _) => {
            let (eps, _) = ambid_core::estimate::pem::prediction_errors(
                p,
                y,
                u,
                ambid_core::estimate::pem::Focus::Prediction,
            )
            .ok()?;
            Some((y.iter().zip(&eps).map(|(y, e)| y - e).collect(), ONE_STEP))
        }
        (_, _, Some(k)) => {
            let km = faer::Mat::from_fn(k.len(), 1, |i, _| k[i]);
            ambid_core::validate::predict::predict_k(m, km.as_ref(), y, u, 1)
                .ok()
                .map(|p| (p, ONE_STEP))
        }
        _ => None,
    }
}
