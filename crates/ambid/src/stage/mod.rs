//! The identification pipeline as typed stages, shared by `ambid run` ([`crate::workflow`]) and
//! usable on their own from Rust.
//!
//! Each stage takes a typed input (its settings and the typed outputs of the stages it needs)
//! and returns a typed output (`serde::Serialize`, except the validation, reconstruction and ISO
//! results, which hold core types without it: `PzAnalysis`, `Frd`, complex responses) or an
//! [`crate::error::Error`]:
//!
//! | stage | input | output |
//! |---|---|---|
//! | seeds | the workflow seed | [`Seeds`] |
//! | acquisition (twin) | [`TwinSource`], [`AcquisitionPlan`] | [`Acquisition`] (identification, validation and noise records) |
//! | excitation design | [`ExcitationInput`] (sample rate, level, [`Seeds::comparison`], the identification plan) | [`ExcitationStage`] |
//! | amplitude study | [`crate::study::TwinAmplitudeStudy`] | [`AmplitudeStage`] |
//! | operating-point study | [`OperatingPointInput`] | [`crate::study::OperatingPointOutcome`] |
//! | robust BLA study | [`BlaInput`] | [`crate::bla::BlaStudy`] |
//! | nonparametric FRF | [`FrfInput`] (record, `[frf]`, noise record, controller, twin) | [`FrfStage`] |
//! | order | [`OrderInput`] (records, FRF, `[order]`, `[models]`, controller) | [`OrderStage`] |
//! | model candidates and choice | [`ModelsInput`] | [`ModelsStage`] |
//! | pole-zero check | [`PoleZeroInput`] | [`PoleZeroStage`] |
//! | validation | [`ValidationInput`] (the model as data, the validation record, the controller) | [`ValidationStage`] |
//! | closed-loop reconstruction | [`ReconstructionInput`] (the model, the controller, the chirp record) | [`ReconstructionStage`] |
//! | ISO 14839-3 zone | [`IsoInput`] (the FRF, the validation outcome, the twin) | [`IsoStage`] |
//!
//! Stages do not import each other except to read an upstream stage's output type, and none
//! depends on the report or on the workflow's state; every random number comes from a seed in
//! [`Seeds`], so stages run in any order and in parallel with identical results.
//!
//! # Example: acquisition → FRF from code
//! ```
//! use ambid::stage::{acquire_twin, frf, identification_plan, AcquisitionPlan, FrfInput, Seeds, TwinSource};
//! use ambid::experiment::ExcitationKind;
//! use ambid::workflow::config::{ExcitationSection, FrfSection};
//! let twin = TwinSource::new(ambid_twin::TwinConfig::default(), ambid_twin::Mode::Nonlinear).unwrap();
//! let seeds = Seeds::from_workflow_seed(1);
//! let exc = ExcitationSection { periods: 8, ..ExcitationSection::default() };
//! let plan = AcquisitionPlan::new(identification_plan(&exc, 0.1, &seeds), ExcitationKind::Multisine, 0.1, seeds);
//! let rec = acquire_twin(&twin, &plan).unwrap().identification;
//! let fs = FrfSection::default();
//! let st = frf(&FrfInput { record: &rec, frf: &fs, skip_periods: 1, noise: None, controller: None, twin: None }).unwrap();
//! // the measured plant against the twin's exact one at 200 Hz: within a few per cent
//! let (f, p) = (st.f_hz(), st.analysis.frf.plant.values());
//! let k = f.iter().position(|&f| f >= 200.0).unwrap();
//! let exact = twin.twin.plant_frf(&[f[k]]).unwrap()[0];
//! assert!(((p[k] - exact) / exact).norm() < 0.1);
//! ```

mod acquisition;
mod candidates;
mod excitation;
mod frf;
mod iso;
mod models;
mod order;
mod pole_zero;
mod reconstruction;
mod seeds;
mod studies;
mod validation;

pub use self::acquisition::{
    acquire_twin, excitation_kind, Acquisition, AcquisitionPlan, Recording, Signals, TwinSource,
};
pub use self::candidates::Candidate;
pub use self::excitation::{
    excitation_design, hold_3db_hz, spectrum_3db_hz, ExcitationInput, ExcitationStage,
    IdentificationDesign,
};
pub use self::frf::{frf, FrfInput, FrfStage, PlantEstimator, TruthErrors, TwinTruth};
pub use self::iso::{iso, GridSensitivity, IsoInput, IsoStage, MeasuredSensitivity};
pub use self::models::{
    choose, frf_candidates, frf_weights, models, unstable_pole_rule, BandChoice, Choice, FitCurve,
    FrfCandidates, MeasuredPlant, ModelOut, ModelsInput, ModelsStage, Overlay, Scored, Select,
    UnstableChoice,
};
pub use self::order::{
    order, order_error_tolerance, resonance_scan, ArxGrid, ErrorBasis, OrderError, OrderErrors,
    OrderInput, OrderRecommendation, OrderStage, ResonanceScan, SubspaceEvidence,
    ORDER_RANGE_ABOVE, ORDER_SCAN_MAX, RESONANCE_MAX_REL_STD,
};
pub use self::pole_zero::{
    pole_zero, ChosenPz, PoleHz, PoleZeroInput, PoleZeroStage, PzRow, SPlane,
};
pub use self::reconstruction::{
    reconstruction, reconstruction_seed, ReconstructionInput, ReconstructionSource,
    ReconstructionStage, RECONSTRUCTION_SEED_OFFSET,
};
pub use self::seeds::Seeds;
pub use self::studies::{
    amplitude_twin, bla_twin, choose_level_pct, operating_point_twin, AmplitudeStage, BlaInput,
    OperatingPointInput,
};
pub use self::validation::{
    drives_loop, lag_choice, open_loop_response, validation, validation_settings, ClosedLoopCheck,
    ModelUnderTest, OpenLoopCheck, OpenLoopResiduals, ValidationCheck, ValidationInput,
    ValidationStage, ONE_STEP, SIMULATION,
};

use crate::analysis::FrfSettings;
use crate::config::{ExcitationSection, FrfSection};
use crate::experiment::ExcitationPlan;

/// The identification excitation of an `[excitation]` section at level `frac` of i_sat, with
/// the identification excitation seed.
pub fn identification_plan(e: &ExcitationSection, frac: f64, seeds: &Seeds) -> ExcitationPlan {
    ExcitationPlan {
        kind: excitation_kind(&e.kind),
        amplitude_frac: frac,
        prbs_order: e.prbs_order,
        samples_per_bit: e.samples_per_bit,
        periods: e.periods,
        f_min_hz: e.f_min_hz,
        f_max_hz: e.f_max_hz,
        seed: seeds.identification_excitation,
        ..ExcitationPlan::default()
    }
}

/// The nonparametric FRF's settings for a record of `n` samples: period averaging when the
/// period is known and at least two periods are recorded (dropping `skip_periods`, at most all
/// but one), Welch averaging otherwise or with `method = "welch"`; the bands of `frf` (derived
/// from the excitation when not given) and the saturation current `i_sat` when known.
///
/// ```
/// use ambid::stage::frf_settings;
/// use ambid::workflow::config::FrfSection;
/// let s = frf_settings(&FrfSection::default(), 1, Some(5115), 20 * 5115, Some(1.5));
/// assert!(matches!(s.method, ambid::analysis::FrfMethod::Periodic { period_samples: 5115, skip_periods: 1 }));
/// assert_eq!(s.i_sat, Some(1.5));
/// ```
pub fn frf_settings(
    frf: &FrfSection,
    skip_periods: usize,
    period: Option<usize>,
    n: usize,
    i_sat: Option<f64>,
) -> FrfSettings {
    let period = match frf.method.as_str() {
        "welch" => None,
        _ => period,
    };
    let mut s = FrfSettings::for_record(period, n, skip_periods, frf.nperseg);
    // an explicit band wins; otherwise both bands are derived from the excitation of the record
    // (ambid_core::frf::band), on the twin and on files alike
    s.band = frf.band_hz.map(|[a, b]| (a, b));
    s.quality_band = frf.quality_band_hz.map(|[a, b]| (a, b));
    s.i_sat = i_sat;
    s
}
