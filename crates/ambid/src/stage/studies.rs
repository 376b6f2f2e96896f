//! The study stages on the twin: excitation amplitude (seed-style), operating point and robust
//! BLA. Each runs its own experiments from its own seed ([`super::Seeds`]), so the studies are
//! independent of each other and of the identification records and can run in parallel.

use crate::bla::{BlaPlan, BlaStudy};
use crate::error::{Context, Error, FailureClass, Result};
use crate::experiment::ExcitationPlan;
use crate::study::{
    operating_point_on_twin, AmplitudeOutcome, OperatingCase, OperatingPointOutcome,
    TwinAmplitudeStudy,
};
use ambid_twin::{Mode, TwinConfig};
use serde::Serialize;

/// One level of the amplitude study as `summary.json` gives it (`amplitude.levels[k]`).
#[derive(Debug, Clone, Serialize)]
pub struct AmplitudeLevel {
    /// Level \[% of i_sat\].
    pub level_pct: f64,
    /// Band average of γ²_ry.
    pub mean_coh_ry: f64,
    /// Band average of γ²_ru.
    pub mean_coh_ru: f64,
    /// Band average of the relative single-period plant variance.
    pub mean_plant_rel_var: f64,
    /// Output SNR \[dB\].
    pub snr_db: Option<f64>,
    /// Saturated samples \[%\].
    pub saturated_pct: f64,
    /// Median relative error of the plant against the twin's exact one \[%\].
    pub plant_median_rel_err_pct: Option<f64>,
}

/// The amplitude stage's output: the study, the level chosen for identification and the
/// figures `summary.json` keeps (key `amplitude`).
#[derive(Debug, Clone, Serialize)]
pub struct AmplitudeStage {
    /// The whole study (figures, plants).
    #[serde(skip)]
    pub outcome: AmplitudeOutcome,
    /// Where the records came from (for the report).
    #[serde(skip)]
    pub source: String,
    /// Per level.
    pub levels: Vec<AmplitudeLevel>,
    /// Lowest recommended level \[% of i_sat\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recommended_min_pct: Option<f64>,
    /// Highest recommended level \[% of i_sat\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recommended_max_pct: Option<f64>,
    /// The identification level \[% of i_sat\] ([`choose_level_pct`]).
    pub chosen_pct: f64,
}

impl AmplitudeStage {
    /// The stage output of a study `outcome`, with the identification level chosen by
    /// [`choose_level_pct`] from `configured_pct` (the workflow file's level, if any).
    pub fn new(outcome: AmplitudeOutcome, source: String, configured_pct: Option<f64>) -> Self {
        let chosen_pct = choose_level_pct(configured_pct, &outcome);
        let levels = outcome
            .rows
            .iter()
            .map(|r| AmplitudeLevel {
                level_pct: r.level_pct,
                mean_coh_ry: r.mean_coh_ry,
                mean_coh_ru: r.mean_coh_ru,
                mean_plant_rel_var: r.mean_plant_rel_var,
                snr_db: r.snr_db,
                saturated_pct: 100.0 * r.saturated_fraction,
                plant_median_rel_err_pct: r.plant_median_rel_err.map(|e| 100.0 * e),
            })
            .collect();
        Self {
            recommended_min_pct: outcome.recommended_pct.map(|r| r.0),
            recommended_max_pct: outcome.recommended_pct.map(|r| r.1),
            levels,
            chosen_pct,
            source,
            outcome,
        }
    }
}

/// The identification level \[% of i_sat\]: the configured one, else the studied level nearest
/// the middle of the recommended range, else 10 %.
///
/// ```
/// use ambid::stage::choose_level_pct;
/// use ambid::study::AmplitudeOutcome;
/// let none = AmplitudeOutcome { rows: vec![], plants: vec![], recommended_pct: None, reasoning: String::new() };
/// assert_eq!(choose_level_pct(Some(4.0), &none), 4.0);
/// assert_eq!(choose_level_pct(None, &none), 10.0);
/// ```
pub fn choose_level_pct(configured_pct: Option<f64>, out: &AmplitudeOutcome) -> f64 {
    match (configured_pct, out.recommended_pct) {
        (Some(p), _) => p,
        (None, Some((a, b))) => {
            let mid = 0.5 * (a + b);
            out.rows
                .iter()
                .map(|r| r.level_pct)
                .filter(|l| (a..=b).contains(l))
                .min_by(|x, y| (x - mid).abs().total_cmp(&(y - mid).abs()))
                .unwrap_or(mid)
        }
        (None, None) => 10.0,
    }
}

/// The amplitude stage on the twin: one experiment per level of `study` (level `j` with seed
/// `study.seed + j`) plus one without excitation (seed `study.seed + 1000`), all simulated in
/// parallel, then the study of [`crate::study::amplitude_from_records`]; the identification
/// level chosen from `configured_pct` or the recommendation. The numbers are those of
/// [`crate::study::amplitude_on_twin`] (the same experiments and analysis), whatever the number
/// of threads.
///
/// # Errors
/// A computation error when a simulation or an estimate fails.
pub fn amplitude_twin(
    study: &TwinAmplitudeStudy,
    configured_pct: Option<f64>,
) -> Result<AmplitudeStage> {
    // the level experiments and the noise-only record run in parallel inside the study
    let out = crate::study::amplitude_on_twin(study)
        .map_err(|e| Error::classified(FailureClass::Computation, e))?;
    Ok(AmplitudeStage::new(
        out,
        "the twin (one experiment per level plus one without excitation)".to_string(),
        configured_pct,
    ))
}

/// The operating-point study's input on the twin.
#[derive(Debug, Clone)]
pub struct OperatingPointInput {
    /// The nominal twin.
    pub twin: TwinConfig,
    /// The cases, nominal first.
    pub cases: Vec<OperatingCase>,
    /// The excitation of every case.
    pub excitation: ExcitationPlan,
    /// Linear or nonlinear physics.
    pub mode: Mode,
    /// The study's seed ([`super::Seeds::operating_point`]).
    pub seed: u64,
    /// Leading periods dropped.
    pub skip_periods: usize,
    /// FRF band \[Hz\].
    pub band: Option<(f64, f64)>,
}

/// The operating-point stage on the twin: one experiment per case.
///
/// # Errors
/// A computation error when a simulation or an estimate fails.
pub fn operating_point_twin(input: &OperatingPointInput) -> Result<OperatingPointOutcome> {
    operating_point_on_twin(
        &input.twin,
        &input.cases,
        &input.excitation,
        input.mode,
        input.seed,
        input.skip_periods,
        input.band,
    )
    .context("operating-point study")
    .map_err(|e| Error::classified(FailureClass::Computation, e))
}

/// The robust BLA study's input on the twin.
#[derive(Debug, Clone)]
pub struct BlaInput {
    /// The plan (its `seed` is [`super::Seeds::bla`]).
    pub plan: BlaPlan,
    /// Levels as fractions of i_sat.
    pub levels: Vec<f64>,
}

/// The robust-BLA stage on the twin: M random-phase multisine realisations per level.
///
/// # Errors
/// A computation error when a simulation or an estimate fails.
pub fn bla_twin(input: &BlaInput) -> Result<BlaStudy> {
    crate::bla::amplitude_study(&input.plan, &input.levels)
        .map_err(|e| Error::classified(FailureClass::Computation, e))
}
