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

impl Candidate {
    /// The candidate's response on a record without a controller, by the validation stage's
    /// rule ([`crate::stage::open_loop_response`]): `m` is its model (state space), its
    /// polynomial form and Kalman gain come from the candidate.
    pub fn open_loop_response(
        &self,
        m: &StateSpace,
        y: &[f64],
        u: &[f64],
    ) -> Option<(Vec<f64>, &'static str)> {
        super::validation::open_loop_response(
            &super::validation::ModelUnderTest {
                name: self.structure,
                model: m,
                poly: self.poly.as_ref(),
                kalman: self.kalman.as_deref(),
            },
            y,
            u,
        )
    }
}
