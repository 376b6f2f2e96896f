//! Model comparison over structures and orders (the seed paper's table 1): every candidate is
//! fitted to the same FRF and scored in the frequency domain and, given an independent record
//! and the controller, in the time domain through the closed loop.
//!
//! # Scores
//! For each structure ($\mathrm{ARX}$ by Levy's form, $\mathrm{OE}$ by SK + LM, state space by
//! frequency-domain subspace + LM; see [`crate::estimate::freqfit`]) and order $n$:
//! * the unweighted complex errors on the band ([`FreqErrors`]: RMSE, relative RMSE, dB RMSE,
//!   median relative error) and the relative RMSE below `low_band_hz` (the seed compares the
//!   structures below 200 Hz);
//! * $\mathrm{BIC} = 2L \ln(V / 2L) + n_\theta \ln 2L$ with $V$ the weighted cost over the $L$
//!   lines ($2L$ real residuals); lower is better, the penalty grows with the parameter count;
//! * the closed-loop validation fit $100\,(1 - \lVert y - \hat y\rVert / \lVert y - \bar y\rVert)$
//!   of the model with the real controller driven by the record's $r$
//!   ([`super::closed_loop::simulate_loop`]); an unstable loop scores `None` with the reason;
//! * the number of unstable poles (an AMB plant has one per unstable rigid-body direction).
//!
//! Orders: ARX and OE of order $n$ have $n_b = n$, $n_f = n$ and the given delay $n_k$; the state
//! space has $n$ states (and no feedthrough).

use crate::error::Result;
use crate::estimate::arx::fit_percent;
use crate::estimate::freqfit::{arx_frd, oe_frd, FreqErrors, FreqFitOptions, TfOrders};
use crate::lti::{Frd, StateSpace, TransferFunction};
use crate::validate::closed_loop::simulate_loop;

/// Model structure of a candidate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FitStructure {
    /// ARX in Levy's linearised form.
    Arx,
    /// Output-error transfer function (SK + LM).
    Oe,
    /// State space (frequency-domain subspace + LM).
    Ss,
}

impl FitStructure {
    /// Lower-case name (`arx`, `oe`, `ss`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Arx => "arx",
            Self::Oe => "oe",
            Self::Ss => "ss",
        }
    }
}

/// What to compare.
#[derive(Debug, Clone, PartialEq)]
pub struct CompareSpec {
    /// Structures (default ARX, OE, SS).
    pub structures: Vec<FitStructure>,
    /// Orders (default 6, 7, 8, 9).
    pub orders: Vec<usize>,
    /// Input delay of the ARX and OE models in samples (default 1).
    pub nk: usize,
    /// Band, weights and iteration limits of the fits.
    pub fit: FreqFitOptions,
    /// Upper edge of the low band scored separately \[Hz\] (default 200).
    pub low_band_hz: f64,
}

impl Default for CompareSpec {
    fn default() -> Self {
        Self {
            structures: vec![FitStructure::Arx, FitStructure::Oe, FitStructure::Ss],
            orders: vec![6, 7, 8, 9],
            nk: 1,
            fit: FreqFitOptions::default(),
            low_band_hz: 200.0,
        }
    }
}

/// An independent time-domain record for the closed-loop validation.
#[derive(Debug, Clone, Copy)]
pub struct ValidationRecord<'a> {
    /// Excitation injected at the controller output.
    pub r: &'a [f64],
    /// Measured plant output.
    pub y: &'a [f64],
    /// The controller in the loop (same sample time as the models).
    pub controller: &'a StateSpace,
    /// Samples at the start left out of the fit measure (the initial transient).
    pub skip: usize,
}

/// One row of the comparison table.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CompareRow {
    /// Structure.
    pub structure: FitStructure,
    /// Order.
    pub order: usize,
    /// Real parameters.
    pub n_params: usize,
    /// Errors on the band (`None` when the fit failed).
    pub rmse: Option<f64>,
    /// Relative RMSE on the band.
    pub relative_rmse: Option<f64>,
    /// RMS dB error on the band.
    pub db_rmse: Option<f64>,
    /// Median relative error on the band.
    pub median_relative: Option<f64>,
    /// Relative RMSE below `low_band_hz`.
    pub low_band_relative_rmse: Option<f64>,
    /// BIC of the weighted frequency-domain cost.
    pub bic: Option<f64>,
    /// Closed-loop validation fit \[%\].
    pub validation_fit: Option<f64>,
    /// Unstable poles of the model.
    pub unstable_poles: Option<usize>,
    /// Why a fit or the validation failed.
    pub note: Option<String>,
    /// The fitted model as a state-space realisation (not serialised).
    #[serde(skip)]
    pub model: Option<StateSpace>,
}

/// Fits every structure × order of `spec` to `frd` and scores it (module docs). A candidate that
/// fails (rank-deficient fit, unstable closed loop) gets a row with the reason in `note`; the
/// comparison itself fails only on invalid input (a bad band or weights).
///
/// # Errors
/// The errors of [`crate::estimate::freqfit::FreqData::new`] for the band and weights.
pub fn compare_models(
    frd: &Frd,
    spec: &CompareSpec,
    validation: Option<ValidationRecord<'_>>,
) -> Result<Vec<CompareRow>> {
    // validate the band and the weights once, so that bad input is an error, not a note per row
    let data = crate::estimate::freqfit::FreqData::new(frd, &spec.fit)?;
    let mut rows = Vec::new();
    for &structure in &spec.structures {
        for &order in &spec.orders {
            rows.push(candidate(frd, &data, spec, structure, order, validation));
        }
    }
    Ok(rows)
}

fn candidate(
    frd: &Frd,
    data: &crate::estimate::freqfit::FreqData,
    spec: &CompareSpec,
    structure: FitStructure,
    order: usize,
    validation: Option<ValidationRecord<'_>>,
) -> CompareRow {
    let mut row = CompareRow {
        structure,
        order,
        n_params: 0,
        rmse: None,
        relative_rmse: None,
        db_rmse: None,
        median_relative: None,
        low_band_relative_rmse: None,
        bic: None,
        validation_fit: None,
        unstable_poles: None,
        note: None,
        model: None,
    };
    let fitted: Result<(StateSpace, usize, f64, FreqErrors, usize)> = (|| {
        let o = TfOrders {
            nb: order,
            nf: order,
            nk: spec.nk,
        };
        let tf = |t: TransferFunction| t.to_state_space();
        match structure {
            FitStructure::Arx => {
                let f = arx_frd(frd, &o, &spec.fit)?;
                Ok((tf(f.model)?, f.n_params, f.cost, f.errors, 0))
            }
            FitStructure::Oe => {
                let f = oe_frd(frd, &o, &spec.fit)?;
                Ok((tf(f.model)?, f.n_params, f.cost, f.errors, f.iterations))
            }
            FitStructure::Ss => {
                let f = crate::estimate::freqfit_ss::ss_frd(
                    frd,
                    order,
                    &spec.fit,
                    &crate::estimate::freqfit_ss::SsFreqOptions::default(),
                )?;
                Ok((f.model, f.n_params, f.cost, f.errors, f.iterations))
            }
        }
    })();
    let (model, n_params, cost, errors, iterations) = match fitted {
        Ok(v) => v,
        Err(e) => {
            row.note = Some(format!("fit failed: {e}"));
            return row;
        }
    };
    row.n_params = n_params;
    if structure != FitStructure::Arx && iterations >= spec.fit.max_iterations {
        row.note = Some(format!(
            "the refinement stopped at its iteration limit ({iterations}): the model may not be at the optimum"
        ));
    }
    row.rmse = Some(errors.rmse);
    row.relative_rmse = Some(errors.relative_rmse);
    row.db_rmse = Some(errors.db_rmse);
    row.median_relative = Some(errors.median_relative);
    let l2 = 2.0 * data.len() as f64;
    row.bic = Some(l2 * (cost.max(f64::MIN_POSITIVE) / l2).ln() + n_params as f64 * l2.ln());
    match model.freq_response_siso(&data.f_hz) {
        Ok(resp) => {
            let low: Vec<f64> = resp
                .iter()
                .zip(&data.g)
                .zip(&data.f_hz)
                .filter(|(_, f)| **f <= spec.low_band_hz)
                .map(|((m, g), _)| (m - g).norm_sqr() / g.norm_sqr().max(f64::MIN_POSITIVE))
                .collect();
            if !low.is_empty() {
                row.low_band_relative_rmse =
                    Some((low.iter().sum::<f64>() / low.len() as f64).sqrt());
            }
        }
        Err(e) => row.note = Some(format!("frequency response failed: {e}")),
    }
    row.unstable_poles = model
        .poles()
        .ok()
        .map(|p| p.iter().filter(|z| z.norm() > 1.0).count());
    if let Some(v) = validation {
        match simulate_loop(&model, v.controller, v.r) {
            Ok(out) => {
                let n = v.y.len().min(out.y.len());
                let k0 = v.skip.min(n);
                row.validation_fit = fit_percent(&v.y[k0..n], &out.y[k0..n]).ok();
            }
            Err(e) => row.note = Some(format!("closed-loop validation failed: {e}")),
        }
    }
    row.model = Some(model);
    row
}

/// The comparison as a plain-text table (one row per candidate; `—` for missing values).
pub fn table(rows: &[CompareRow]) -> String {
    let opt = |v: Option<f64>, scale: f64, prec: usize| {
        v.map_or("—".to_string(), |x| format!("{:.*}", prec, x * scale))
    };
    let mut s = String::from(
        "structure order n_params  rel_rmse_%  low_rel_rmse_%  db_rmse  median_rel_%        bic  val_fit_%  unstable  note\n",
    );
    for r in rows {
        s.push_str(&format!(
            "{:<9} {:>5} {:>8} {:>11} {:>15} {:>8} {:>13} {:>10} {:>10} {:>9}  {}\n",
            r.structure.name(),
            r.order,
            r.n_params,
            opt(r.relative_rmse, 100.0, 3),
            opt(r.low_band_relative_rmse, 100.0, 3),
            opt(r.db_rmse, 1.0, 3),
            opt(r.median_relative, 100.0, 3),
            opt(r.bic, 1.0, 1),
            opt(r.validation_fit, 1.0, 2),
            r.unstable_poles.map_or("—".to_string(), |u| u.to_string()),
            r.note.as_deref().unwrap_or("")
        ));
    }
    s
}
