//! The workflow's typed outcome: [`Summary`], one typed field per stage, serialised with `serde`
//! as `summary.json` (keys sorted as `serde_json` writes a map).

use std::collections::BTreeMap;

/// `summary.json`, typed: one field per stage that ran (absent when it did not run or was
/// skipped before it had a figure), and the timings. Serialised with `serde` (keys sorted, as
/// `serde_json` writes a map).
///
/// ```
/// use ambid::workflow::{run, Progress, Step, Verbosity, WorkflowConfig};
/// let cfg = WorkflowConfig { steps: Some(vec![Step::Excitation]), ..WorkflowConfig::default() };
/// let out = run(&cfg, std::path::Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
/// let prbs = &out.stages.excitation.as_ref().unwrap().compare["prbs"];
/// assert!((prbs.crest_factor - 1.0).abs() < 1e-9); // ±A: crest factor 1
/// // summary.json is the same thing as JSON
/// assert_eq!(out.summary["excitation"]["compare"]["prbs"]["crest_factor"].as_f64(), Some(prbs.crest_factor));
/// assert!(out.stages.frf.is_none()); // the FRF step did not run
/// ```
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct Summary {
    /// The data (`data.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub data: Option<DataSummary>,
    /// The excitation comparison and the identification excitation (`excitation.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub excitation: Option<ExcitationSummary>,
    /// The nonparametric FRF (`frf.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frf: Option<FrfSummary>,
    /// The order evidence (`order.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub order: Option<OrderSummary>,
    /// The model candidates and the choice (`models.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub models: Option<ModelsSummary>,
    /// The pole-zero check of the chosen model (`pole_zero.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pole_zero: Option<PoleZeroSummary>,
    /// The validation of the chosen model (`validation.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub validation: Option<ValidationSummary>,
    /// Its residual tests (`residuals.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub residuals: Option<ResidualsSummary>,
    /// The chirp reconstruction (`reconstruction.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reconstruction: Option<ReconstructionSummary>,
    /// The ISO 14839-3 verdict (`iso.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iso: Option<IsoSummary>,
    /// The chosen model's uncertainty and robust stability (`uncertainty.*`, optional step).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<super::steps_robust::UncertaintySummary>,
    /// The gray-box physical parameters (`physical.*`, optional step).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub physical: Option<super::steps_robust::PhysicalSummary>,
    /// The amplitude study (`amplitude.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub amplitude: Option<crate::stage::AmplitudeStage>,
    /// The robust BLA study (`bla.*`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bla: Option<BlaSummary>,
    /// The operating-point study: per case, `<band>_median_dev_pct` and `error_vs_truth_pct`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub operating_point: Option<BTreeMap<String, BTreeMap<String, f64>>>,
    /// The identification record (`identification.*`, twin).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub identification: Option<IdentificationSummary>,
    /// The whole machine (`machine.*`, a workflow with a `[machine]` section).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub machine: Option<super::machine::MachineSummary>,
    /// Seconds per step (`<step>_s`), their sum (`total_s`) and the run's wall-clock time
    /// (`wall_s`; less than the sum when stages overlap).
    pub timing: BTreeMap<String, f64>,
}

/// `summary.json`'s `data`.
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct DataSummary {
    /// `twin` or `files`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// Sample rate \[Hz\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fs_hz: Option<f64>,
    /// The twin's saturation current \[A\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub i_sat_a: Option<f64>,
    /// The twin's sensor noise \[m RMS\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub noise_rms_m: Option<f64>,
    /// Closed-loop records (files).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub closed_loop: Option<bool>,
    /// Samples of the estimation record (files).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub identification_samples: Option<f64>,
    /// Samples of the validation record (files).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub validation_samples: Option<f64>,
}

/// `summary.json`'s `excitation`.
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct ExcitationSummary {
    /// Per candidate signal of the comparison.
    pub compare: BTreeMap<String, CompareFigures>,
    /// The identification excitation as designed (twin).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub identification: Option<ExcitationFigures>,
}

/// One candidate of the excitation comparison.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CompareFigures {
    /// Peak over RMS.
    pub crest_factor: f64,
    /// Upper end of the usable band \[Hz\].
    pub f_max_hz: f64,
}

/// The identification excitation as designed.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ExcitationFigures {
    /// Lower end of the usable band \[Hz\].
    pub f_min_hz: f64,
    /// Upper end of the usable band \[Hz\].
    pub f_max_hz: f64,
    /// Frequency resolution \[Hz\].
    pub resolution_hz: f64,
    /// Duration \[s\].
    pub duration_s: f64,
    /// Samples per period.
    pub period_samples: f64,
    /// Peak over RMS.
    pub crest_factor: f64,
}

/// `summary.json`'s `frf`: the bands and the quality of the nonparametric FRF.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FrfSummary {
    /// Band of the estimate \[Hz\].
    pub band_lo_hz: f64,
    /// Band of the estimate \[Hz\].
    pub band_hi_hz: f64,
    /// Band of the quality averages \[Hz\].
    pub quality_band_lo_hz: f64,
    /// Band of the quality averages \[Hz\].
    pub quality_band_hi_hz: f64,
    /// Where the band came from.
    pub band_origin: crate::analysis::BandOrigin,
    /// Where the quality band came from.
    pub quality_band_origin: crate::analysis::BandOrigin,
    /// Frequency lines.
    pub lines: f64,
    /// Band average of γ²_ry (γ²_uy without r).
    pub mean_coh_ry: f64,
    /// Band average of γ²_ru (with r).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_coh_ru: Option<f64>,
    /// Band average of the plant variance.
    pub mean_plant_variance: f64,
    /// Band average of the relative plant variance.
    pub mean_plant_rel_variance: f64,
    /// Output SNR \[dB\] (with a noise record).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub output_snr_db: Option<f64>,
    /// Median relative error against the twin's exact plant over the quality band \[%\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plant_median_error_vs_truth_pct: Option<f64>,
    /// Its 90th percentile \[%\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plant_p90_error_vs_truth_pct: Option<f64>,
    /// The median over 10–1000 Hz \[%\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plant_median_error_vs_truth_10_1000_pct: Option<f64>,
}

/// `summary.json`'s `order`: the order evidence and the reconciled recommendation.
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct OrderSummary {
    /// The ARX structure of smallest BIC.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arx_best_bic: Option<ArxOrders>,
    /// The ARX structure of best validation fit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arx_best_validation: Option<ArxValidation>,
    /// Resonances found in the FRF.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub resonances: Option<f64>,
    /// The order they imply.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub order_from_peaks: Option<f64>,
    /// Recommended order.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recommended: Option<f64>,
    /// Lowest adequate order.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recommended_lo: Option<f64>,
    /// Highest adequate order.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recommended_hi: Option<f64>,
    /// Which evidence set the range.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recommended_source: Option<String>,
}

/// ARX orders.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ArxOrders {
    /// Denominator order.
    pub na: f64,
    /// Numerator order.
    pub nb: f64,
    /// Delay.
    pub nk: f64,
}

/// The ARX structure of best validation fit.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ArxValidation {
    /// Denominator order.
    pub na: f64,
    /// Numerator order.
    pub nb: f64,
    /// Validation fit \[%\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_pct: Option<f64>,
}

/// `summary.json`'s `models`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ModelsSummary {
    /// `frf` or `time`.
    pub domain: String,
    /// Unstable plant poles the data support (Nyquist count; `null`: not determined).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unstable_poles_supported: Option<Option<f64>>,
    /// One row per candidate.
    pub table: Vec<ModelRow>,
    /// The chosen candidate.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chosen: Option<String>,
    /// Its validation fit \[%\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chosen_validation_fit_pct: Option<f64>,
    /// Its median error against the twin's exact plant \[%\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chosen_error_vs_truth_pct: Option<f64>,
}

/// One model candidate in `summary.json`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ModelRow {
    /// e.g. `oe8`.
    pub model: String,
    /// Parameters.
    pub n_params: f64,
    /// Relative RMS error against the measured FRF \[%\].
    pub relative_rmse_pct: Option<f64>,
    /// Median relative error against the measured FRF \[%\].
    pub median_relative_pct: Option<f64>,
    /// RMS error in dB.
    pub db_rmse: Option<f64>,
    /// Bayesian information criterion.
    pub bic: Option<f64>,
    /// Validation fit \[%\].
    pub validation_fit_pct: Option<f64>,
    /// Unstable poles.
    pub unstable_poles: Option<f64>,
    /// Whether the candidate is admissible.
    pub valid: bool,
    /// Median relative error against the twin's exact plant \[%\].
    pub median_error_vs_truth_pct: Option<f64>,
}

/// `summary.json`'s `pole_zero`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PoleZeroSummary {
    /// Near pole-zero cancellations of the chosen model.
    pub chosen_near_cancellations: f64,
    /// Its unstable poles.
    pub chosen_unstable_poles: f64,
}

/// `summary.json`'s `residuals`: the residual tests of the chosen model (and of the twin's exact plant).
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct ResidualsSummary {
    /// `lags`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lags: Option<usize>,
    /// `lags_ms`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lags_ms: Option<f64>,
    /// `lags_rule`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lags_rule: Option<crate::validation::LagBasis>,
    /// `lags_peak_sample`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lags_peak_sample: Option<usize>,
    /// `whiteness_statistic`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub whiteness_statistic: Option<f64>,
    /// `whiteness_threshold`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub whiteness_threshold: Option<f64>,
    /// `whiteness_pass`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub whiteness_pass: Option<bool>,
    /// `independence_statistic`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub independence_statistic: Option<f64>,
    /// `independence_threshold`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub independence_threshold: Option<f64>,
    /// `independence_dof`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub independence_dof: Option<usize>,
    /// `independence_pass`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub independence_pass: Option<bool>,
    /// `truth_independence_statistic`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth_independence_statistic: Option<f64>,
    /// `truth_independence_threshold`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth_independence_threshold: Option<f64>,
    /// `truth_independence_dof`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth_independence_dof: Option<usize>,
    /// `truth_independence_pass`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth_independence_pass: Option<bool>,
}

/// `summary.json`'s `validation`: the chosen model on the independent record.
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct ValidationSummary {
    /// `model`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// `kind`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kind: Option<String>,
    /// `fit_y_pct`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_y_pct: Option<f64>,
    /// `fit_u_pct`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_u_pct: Option<f64>,
    /// `rmse_y`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rmse_y: Option<f64>,
    /// `max_error_y`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_error_y: Option<f64>,
    /// `exact_plant_fit_y_pct`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exact_plant_fit_y_pct: Option<f64>,
}

/// `summary.json`'s `reconstruction`: the chirp closed-loop reconstruction.
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct ReconstructionSummary {
    /// `fit_y_pct`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_y_pct: Option<f64>,
    /// `fit_u_pct`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_u_pct: Option<f64>,
    /// `max_error_y`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_error_y: Option<f64>,
    /// `worst_window_fit_y_pct`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst_window_fit_y_pct: Option<f64>,
    /// `worst_window_start_s`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst_window_start_s: Option<f64>,
    /// `worst_window_end_s`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst_window_end_s: Option<f64>,
    /// `worst_window_record_fit_pct`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst_window_record_fit_pct: Option<f64>,
    /// `worst_window_rms_error_y`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst_window_rms_error_y: Option<f64>,
    /// `worst_window_signal_rms_y`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst_window_signal_rms_y: Option<f64>,
    /// `error_floor_y`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_floor_y: Option<f64>,
    /// `windows_judged`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub windows_judged: Option<usize>,
    /// `worst_window_f_lo_hz`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst_window_f_lo_hz: Option<f64>,
    /// `worst_window_f_hi_hz`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst_window_f_hi_hz: Option<f64>,
}

/// The ISO 14839-3 figures of the measured sensitivity.
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct IsoMeasured {
    /// `peak`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak: Option<f64>,
    /// `f_peak_hz`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub f_peak_hz: Option<f64>,
    /// `zone`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zone: Option<String>,
    /// `peak_ci_lo`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak_ci_lo: Option<f64>,
    /// `peak_ci_hi`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak_ci_hi: Option<f64>,
    /// `search_lo_hz`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub search_lo_hz: Option<f64>,
    /// `search_hi_hz`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub search_hi_hz: Option<f64>,
    /// `search_lines`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub search_lines: Option<f64>,
}

/// The ISO 14839-3 figures of the chosen model with the controller.
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct IsoModel {
    /// `peak`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak: Option<f64>,
    /// `f_peak_hz`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub f_peak_hz: Option<f64>,
    /// `zone`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zone: Option<String>,
    /// `phase_margin_deg`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub phase_margin_deg: Option<f64>,
}

/// The ISO 14839-3 figures of the twin's exact plant.
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct IsoTruth {
    /// `peak`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak: Option<f64>,
    /// `zone`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zone: Option<String>,
}

/// `summary.json`'s `iso`: the ISO 14839-3 zone of the measured sensitivity, of the chosen
/// model with the controller and of the twin's exact plant, and the verdict (`zone`).
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct IsoSummary {
    /// From the measured S.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measured: Option<IsoMeasured>,
    /// From the chosen model.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<IsoModel>,
    /// From the twin's exact plant.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth: Option<IsoTruth>,
    /// The verdict.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zone: Option<String>,
}

/// `summary.json`'s `bla`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct BlaSummary {
    /// Per level.
    pub levels: Vec<BlaLevel>,
    /// The level with the smallest noise + nonlinear variance \[% of i_sat, RMS\].
    pub recommended_pct: f64,
}

/// One level of the robust BLA study in `summary.json`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct BlaLevel {
    /// Level \[% of i_sat, RMS\].
    pub level_pct: f64,
    /// Relative noise variance.
    pub noise_rel: f64,
    /// Relative nonlinear variance.
    pub nl_rel: f64,
    /// Its standard error.
    pub nl_rel_se: f64,
    /// Even detection lines over the noise floor \[dB\].
    pub even_db: f64,
    /// Odd detection lines over the noise floor \[dB\].
    pub odd_db: f64,
    /// RMS relative difference of the BLA from the twin's linearised plant \[%\].
    pub bla_vs_linear_pct: Option<f64>,
    /// Clipped samples \[%\].
    pub saturated_pct: f64,
}

/// `summary.json`'s `identification` (twin).
#[derive(Debug, Clone, serde::Serialize)]
pub struct IdentificationSummary {
    /// Level \[% of i_sat\].
    pub level_pct: f64,
    /// Samples of the record.
    pub samples: f64,
    /// Saturated samples \[%\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub saturated_pct: Option<f64>,
}
