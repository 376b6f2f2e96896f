//! The models stage: parametric candidates (every structure × order of `[models]`, fitted to the
//! plant FRF measured in closed loop or to the time record), their figures of merit, and the
//! choice of one of them; shared by `ambid run` and the `compare-models` command (the choice
//! rule, [`choose`]).

use super::candidates::Candidate;
use super::validation::SIMULATION;
use super::{Recording, TwinSource};
use crate::analysis::FrfAnalysis;
use crate::config::{parameters_of_order, ModelsSection, MAX_MODEL_ORDER};
use crate::error::{Error, FailureClass, Result};
use crate::fitting::{identify_state_space, SsFitOptions, SsFocus};
use crate::io::ControllerModel;
use crate::validation::median_relative_error as median_rel;
use ambid_core::c64;
use ambid_core::estimate::arx::{arx, ArxOrders};
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::estimate::pem::{self, Orders, PemOptions};
use ambid_core::frf::band::{fit_band, FIT_REL_HALFWIDTH};
use ambid_core::lti::{Frd, PolyModel, StateSpace, Structure};
use ambid_core::validate::compare::{
    compare_models, supported_unstable_poles, CompareRow, CompareSpec, ValidationRecord,
};
use ambid_core::validate::fit::fit_percent;
use serde_json::{json, Value};

/// A time-domain fit: the model, its polynomial form, its parameter count and its Kalman gain.
type TimeFit = (StateSpace, Option<PolyModel>, usize, Option<Vec<f64>>);

/// The structures, in the order the stage draws one Bode overlay each.
const OVERLAY_STRUCTURES: [&str; 3] = ["arx", "oe", "ss"];

fn computation(e: impl Into<Error>) -> Error {
    Error::classified(FailureClass::Computation, e)
}

/// What the models stage reads: the `[models]` settings, the order stage's recommended range,
/// the identification and validation records, the nonparametric FRF, the controller and, on the
/// twin, the exact truth.
#[derive(Clone, Copy)]
pub struct ModelsInput<'a> {
    /// `[models]` of the workflow file.
    pub settings: &'a ModelsSection,
    /// The order stage's recommended range `(lo, hi)`, added to `settings.orders` (capped by
    /// the record's parameter budget and [`MAX_MODEL_ORDER`]).
    pub recommended_orders: Option<(usize, usize)>,
    /// The identification record (`None`: the stage is skipped).
    pub identification: Option<&'a Recording>,
    /// The independent validation record.
    pub validation: Option<&'a Recording>,
    /// Samples at the start of the validation record left out of its closed-loop fit
    /// (`[validation] skip`, at most a quarter of the record).
    pub validation_skip: usize,
    /// The nonparametric FRF of the identification record.
    pub frf: Option<&'a FrfAnalysis>,
    /// The controller of the loop (closed loop).
    pub controller: Option<&'a ControllerModel>,
    /// The twin (exact truth), when the records come from it.
    pub twin: Option<&'a TwinSource>,
}

/// How the candidates are ranked (`[models] select`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Select {
    /// The best validation fit (default).
    Validation,
    /// The smallest BIC.
    Bic,
    /// The smallest relative error against the measured FRF.
    Frf,
}

impl Select {
    /// The rule of a `[models] select` value: `bic`, `frf`, anything else the validation fit.
    pub fn from_setting(s: &str) -> Self {
        match s {
            "bic" => Select::Bic,
            "frf" => Select::Frf,
            _ => Select::Validation,
        }
    }

    /// The rule in words, e.g. "the best validation fit".
    pub fn describe(self) -> &'static str {
        match self {
            Select::Bic => "the smallest BIC",
            Select::Frf => "the smallest relative FRF error",
            Select::Validation => "the best validation fit",
        }
    }
}

/// A row [`choose`] can rank: a [`Candidate`] of the workflow or a
/// [`CompareRow`] of `compare-models`.
pub trait Scored {
    /// Whether a model was fitted.
    fn fitted(&self) -> bool;
    /// Whether the row may be chosen.
    fn valid(&self) -> bool;
    /// Validation fit \[%\].
    fn validation_fit(&self) -> Option<f64>;
    /// BIC.
    fn bic(&self) -> Option<f64>;
    /// Relative RMS error against the measured FRF.
    fn relative_rmse(&self) -> Option<f64>;
}

/// [`Scored`] for a row type with the fields `model`, `valid`, `validation_fit`, `bic` and
/// `relative_rmse`.
macro_rules! scored_by_fields {
    ($t:ty) => {
        impl Scored for $t {
            fn fitted(&self) -> bool {
                self.model.is_some()
            }
            fn valid(&self) -> bool {
                self.valid
            }
            fn validation_fit(&self) -> Option<f64> {
                self.validation_fit
            }
            fn bic(&self) -> Option<f64> {
                self.bic
            }
            fn relative_rmse(&self) -> Option<f64> {
                self.relative_rmse
            }
        }
    };
}

scored_by_fields!(Candidate);
scored_by_fields!(CompareRow);

/// The chosen row and whether it was chosen among the valid ones.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Choice {
    /// Index of the chosen row (`None`: no row has a model).
    pub index: Option<usize>,
    /// `true` when the chosen row is valid; `false` when no row is valid and `index` is the
    /// best of the invalid ones (reported as such).
    pub among_valid: bool,
}

/// The choice rule: the best fitted valid row by the `select` key (finite values only), else
/// the valid row with the smallest BIC; only when no row is valid, the best of the others by
/// the key, else the first fitted row. With [`Select::Validation`] on valid rows this is
/// `ambid_core::validate::compare::choose`.
///
/// ```
/// use ambid::stage::{choose, Candidate, Select};
/// let m = ambid_core::lti::StateSpace::discrete(
///     faer::Mat::from_fn(1, 1, |_, _| 0.5),
///     faer::Mat::from_fn(1, 1, |_, _| 1.0),
///     faer::Mat::from_fn(1, 1, |_, _| 1.0),
///     faer::Mat::zeros(1, 1),
///     1e-3,
/// )
/// .unwrap();
/// let cand = |fit: f64, bic: f64, valid: bool| Candidate {
///     model: Some(m.clone()),
///     validation_fit: Some(fit),
///     bic: Some(bic),
///     valid,
///     ..Candidate::time_fit("oe", 2, None, 4, None)
/// };
/// let rows = [cand(80.0, -10.0, true), cand(90.0, -5.0, true), cand(99.0, -50.0, false)];
/// assert_eq!(choose(&rows, Select::Validation).index, Some(1)); // best valid fit
/// assert_eq!(choose(&rows, Select::Bic).index, Some(0)); // smallest valid BIC
/// let invalid = [cand(80.0, -10.0, false), cand(90.0, -5.0, false)];
/// let c = choose(&invalid, Select::Validation);
/// assert_eq!((c.index, c.among_valid), (Some(1), false));
/// ```
pub fn choose<T: Scored>(rows: &[T], select: Select) -> Choice {
    let key = |c: &T| -> Option<f64> {
        match select {
            Select::Bic => c.bic(),
            Select::Frf => c.relative_rmse(),
            Select::Validation => c.validation_fit().map(|f| -f),
        }
    };
    let best = |only_valid: bool, key: &dyn Fn(&T) -> Option<f64>| {
        rows.iter()
            .enumerate()
            .filter(|(_, c)| c.fitted() && (c.valid() || !only_valid))
            .filter_map(|(i, c)| key(c).filter(|v| v.is_finite()).map(|v| (i, v)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    };
    let chosen_valid = best(true, &key).or_else(|| best(true, &|c: &T| c.bic()));
    let index = chosen_valid
        .or_else(|| best(false, &key))
        .or_else(|| rows.iter().position(|c| c.fitted()));
    Choice {
        index,
        among_valid: chosen_valid.is_some(),
    }
}

/// The fit band of an FRF fit and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct BandChoice {
    /// The band \[Hz\].
    pub band_hz: (f64, f64),
    /// Where it came from, in words (for the report).
    pub how: String,
}

/// The number of unstable plant poles the FRF fits are held to, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct UnstableChoice {
    /// The supported number (`None`: not determined, unconstrained).
    pub supported: Option<usize>,
    /// How it was determined, in words.
    pub how: String,
}

/// A model exported with the run (`models/<name>.{json,m,mat,npz}`).
#[derive(Debug, Clone)]
pub struct ModelOut {
    /// File stem, e.g. `oe8`.
    pub name: String,
    /// The state-space form (always).
    pub ss: StateSpace,
    /// The polynomial form, when the model was fitted as one.
    pub poly: Option<PolyModel>,
    /// Kalman gain of the innovations form, when the model has one (exported with it).
    pub kalman: Option<Vec<f64>>,
    /// Metadata for the JSON (structure, order, fit figures).
    pub meta: Value,
}

/// One candidate's frequency response on the FRF grid and its relative error per line,
/// $|\hat G(f_k) - \hat P(f_k)| / |\hat P(f_k)|$ against the measured plant.
#[derive(Debug, Clone)]
pub struct FitCurve {
    /// The candidate's label, e.g. `OE 8`.
    pub label: String,
    /// $\hat G(f_k)$.
    pub response: Vec<c64>,
    /// The relative error per line.
    pub relative_error: Vec<f64>,
}

/// The candidates of one structure against the measured plant FRF (a Bode overlay).
#[derive(Debug, Clone)]
pub struct Overlay {
    /// `arx`, `oe` or `ss`.
    pub structure: &'static str,
    /// Its candidates that have a response, in table order.
    pub fits: Vec<FitCurve>,
}

/// The measured plant FRF the overlays are drawn against.
#[derive(Debug, Clone)]
pub struct MeasuredPlant {
    /// Frequencies \[Hz\].
    pub f_hz: Vec<f64>,
    /// $\hat P(f_k)$.
    pub plant: Vec<c64>,
}

/// Everything the models stage found: the candidates with their figures, the choice and the
/// rule that made it, the band and unstable-pole decisions, the curves of the report and the
/// models to export.
#[derive(Debug, Clone)]
pub struct ModelsStage {
    /// Why the stage did not run (`None`: it ran).
    pub skipped: Option<String>,
    /// `frf` (fits to the plant FRF) or `time` (fits to the identification record).
    pub domain: String,
    /// The orders fitted (`[models] orders` with the recommended range).
    pub orders: Vec<usize>,
    /// `[models] orders` as configured.
    pub configured_orders: Vec<usize>,
    /// The FRF fits' band (domain `frf`).
    pub band: Option<BandChoice>,
    /// The unstable-pole rule (domain `frf`).
    pub unstable: Option<UnstableChoice>,
    /// How the validation fit was computed, in words.
    pub validation_kind: String,
    /// The candidates, structure-major in the order of `[models] structures` × `orders`.
    pub candidates: Vec<Candidate>,
    /// The choice among them.
    pub choice: Choice,
    /// The rule of the choice.
    pub select: Select,
    /// The measured plant FRF (when the FRF stage ran).
    pub measured: Option<MeasuredPlant>,
    /// One Bode overlay per structure that has responses (ARX, OE, SS order).
    pub overlays: Vec<Overlay>,
    /// The models to export (every fitted candidate).
    pub export: Vec<ModelOut>,
    /// On the twin: the exact plant's unstable poles (empty when it has none or they could not
    /// be computed); `None` off the twin.
    pub truth_unstable_poles: Option<Vec<c64>>,
    /// The chosen model's unstable eigenvalues with $\operatorname{Im} z \ge 0$ (one per
    /// complex pair).
    pub chosen_unstable: Vec<c64>,
}

impl ModelsStage {
    /// A stage that did not run, with the reason.
    pub fn skip(why: impl Into<String>) -> Self {
        ModelsStage {
            skipped: Some(why.into()),
            domain: String::new(),
            orders: Vec::new(),
            configured_orders: Vec::new(),
            band: None,
            unstable: None,
            validation_kind: String::new(),
            candidates: Vec::new(),
            choice: Choice {
                index: None,
                among_valid: false,
            },
            select: Select::Validation,
            measured: None,
            overlays: Vec::new(),
            export: Vec::new(),
            truth_unstable_poles: None,
            chosen_unstable: Vec::new(),
        }
    }

    /// The chosen candidate.
    pub fn chosen(&self) -> Option<&Candidate> {
        self.choice.index.and_then(|i| self.candidates.get(i))
    }
}

/// The unstable-pole rule of the FRF fits: `given` (`[models] unstable_poles`,
/// `--unstable-poles`) when set, else the Nyquist count of the measured loop with the
/// controller, $n_u(P) = W - n_u(C)$, over `explicit_band` (all lines when `None`);
/// unconstrained without a controller (`ambid_core::validate::compare::supported_unstable_poles`).
/// `ambid run`, `ambid fit` on an FRF file and `compare-models` all apply it.
pub fn unstable_pole_rule(
    plant: &Frd,
    controller: Option<&StateSpace>,
    explicit_band: Option<(f64, f64)>,
    given: Option<usize>,
) -> UnstableChoice {
    let (supported, how) = supported_unstable_poles(plant, controller, explicit_band, given);
    UnstableChoice { supported, how }
}

/// The FRF fits of a comparison: structures × orders with their input delay and fit options.
#[derive(Debug, Clone)]
pub struct FrfCandidates<'a> {
    /// Structures (ARX, OE, SS).
    pub structures: &'a [Structure],
    /// Orders.
    pub orders: &'a [usize],
    /// Input delay of the ARX and OE models in samples.
    pub nk: usize,
    /// Band, weights and iteration limit.
    pub fit: FreqFitOptions,
}

/// Fits every structure × order of `fits` to the measured plant FRF and scores it
/// (`ambid_core::validate::compare::compare_models`): each fit held to the unstable-pole count
/// of `unstable` ([`unstable_pole_rule`]), a row valid only with that count, a stable loop
/// with `controller` and no pole–zero pair that cancels within the data
/// (`ambid_core::validate::compare::cancelling_pairs`), the closed-loop validation fit on
/// `validation` when given. The comparison
/// of `ambid run`'s models stage, `compare-models` and `ambid fit` on an FRF file.
///
/// # Errors
/// Invalid input to the comparison (a bad band or weights, a structure an FRF fit does not
/// take); a candidate that fails is a row with the reason in its note.
pub fn frf_candidates(
    plant: &Frd,
    fits: &FrfCandidates<'_>,
    unstable: &UnstableChoice,
    controller: Option<&StateSpace>,
    validation: Option<ValidationRecord<'_>>,
) -> ambid_core::Result<Vec<CompareRow>> {
    let spec = CompareSpec {
        structures: fits.structures.to_vec(),
        orders: fits.orders.to_vec(),
        nk: fits.nk,
        fit: fits.fit.clone(),
        unstable_poles: unstable.supported,
        controller: controller.cloned(),
        ..CompareSpec::default()
    };
    compare_models(plant, &spec, validation)
}

/// The weights of the FRF fits for `[models] weights` (`setting`) on the closed-loop analysis
/// `a`:
/// - `model` (default): each line's variance evaluated at the model, the sample
///   maximum-likelihood weights ([`FreqWeights::SampleMaximumLikelihood`] with
///   [`FrfAnalysis::model_weight_noise`]); the state-space and output-error fits refine with
///   them, ARX (linear in its parameters) keeps the variance at the data. Without that noise
///   description (a Welch estimate), as `variance`.
/// - `variance`: $1/\sigma_k^2$ with the variance at the data ([`FreqWeights::InverseVariance`]);
///   uniform without variances.
/// - `coherence`, `uniform`.
///
/// The variance at the data follows each line's own error (in a loop with sensor noise it is
/// $\propto |1 + \hat G_k C_k|^2$), which pulls the fit off the plant by about its own standard
/// deviation at 300–1000 Hz on random twin rigs (docs/uncertainty.md, "Weights that follow the
/// data's noise").
///
/// # Example
/// ```
/// use ambid::analysis::{analyze, FrfSettings, Record};
/// use ambid::experiment::{run, Experiment};
/// use ambid::stage::frf_weights;
/// use ambid_core::estimate::freqfit::FreqWeights;
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let mut exp = Experiment::seed_paper(ambid_twin::Mode::Linear, 1e-7, 1);
/// exp.excitation.periods = 4;
/// let rec = run(&exp)?.record;
/// let r = Record { r: &rec.r, u: &rec.u, y: &rec.y, i: None, fs: 1.0 / rec.ts };
/// let periodic = analyze(&r, &FrfSettings::periodic(5115, 1), None)?;
/// let welch = analyze(&r, &FrfSettings::welch(4096), None)?;
/// assert!(matches!(frf_weights("model", &periodic), FreqWeights::SampleMaximumLikelihood(_)));
/// assert_eq!(frf_weights("model", &welch), FreqWeights::InverseVariance);
/// assert_eq!(frf_weights("variance", &periodic), FreqWeights::InverseVariance);
/// # Ok(())
/// # }
/// ```
pub fn frf_weights(setting: &str, a: &FrfAnalysis) -> FreqWeights {
    let has_variance = a.frf.plant.variance().is_some();
    match (setting, a.model_weight_noise()) {
        ("uniform", _) => FreqWeights::Uniform,
        ("coherence", _) => FreqWeights::Coherence(a.frf.coh_ry.clone()),
        ("model", Some(noise)) if has_variance => {
            FreqWeights::SampleMaximumLikelihood(noise.to_vec())
        }
        _ if has_variance => FreqWeights::InverseVariance,
        _ => FreqWeights::Uniform,
    }
}

/// `orders` with the recommended range `(lo, hi)` added, sorted, each added order capped by
/// the record's parameter budget (`n / SAMPLES_PER_PARAMETER` samples per parameter) and
/// [`MAX_MODEL_ORDER`].
fn orders_with_recommendation(
    given: &[usize],
    recommended: Option<(usize, usize)>,
    rec: Option<&Recording>,
) -> Vec<usize> {
    let mut out = given.to_vec();
    if let Some((lo, hi)) = recommended {
        let cap = rec.map_or(usize::MAX, |r| {
            r.len() / crate::config::SAMPLES_PER_PARAMETER
        });
        out.extend(
            (lo.max(1)..=hi).filter(|&o| o <= MAX_MODEL_ORDER && parameters_of_order(o) <= cap),
        );
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// Fits every structure × order of `[models]` and chooses one.
///
/// Domain `frf` (the default with a closed-loop record with excitation r and an FRF): ARX
/// (Levy), OE (Sanathanan–Koerner + Levenberg–Marquardt) and state-space models are fitted to
/// the measured plant $\hat P = \hat T_{ry} \hat S^{-1}$ in the band of
/// `ambid_core::frf::band::fit_band` (or `[models] band_hz`); each is held to the number of
/// unstable poles the measured loop supports (the Nyquist count
/// $n_u(P) = W - n_u(C)$), must close a stable loop with the controller and may hold no
/// pole–zero pair that cancels within the data (`ambid_core::validate::compare`). Domain `time`: ARX (least squares), OE (prediction-error
/// method) and state-space (N4SID + PEM) fits to the identification record, scored on the
/// validation record. The choice is [`choose`] with `[models] select`.
///
/// Nothing is stabilised: an unstable fit keeps its unstable poles.
///
/// # Example
/// ```
/// use ambid::stage::{models, ModelsInput, Recording, Select, Signals};
/// use ambid::workflow::config::ModelsSection;
/// use ambid_core::lti::{StateSpace, Structure};
/// // y = G u with G(z) = 0.5 / (z − 0.8), open loop, noise-free: the ARX 1 fit is exact
/// let one = |v: f64| faer::Mat::from_fn(1, 1, |_, _| v);
/// let g = StateSpace::discrete(one(0.8), one(1.0), one(0.5), one(0.0), 1e-3).unwrap();
/// let rec = |seed: u64| {
///     // a deterministic broadband input
///     let u: Vec<f64> = (0..2000u64)
///         .map(|k| ((k * 2654435761 + seed * 40503) % 1000) as f64 / 500.0 - 1.0)
///         .collect();
///     let y = g.simulate_siso(&u, None).unwrap();
///     let s = Signals { u, y, ..Signals::default() };
///     Recording::from_signals(1e-3, None, s, false, "demo").unwrap()
/// };
/// let (ident, valid) = (rec(1), rec(2));
/// let settings = ModelsSection {
///     structures: vec![Structure::Arx],
///     orders: vec![1],
///     ..ModelsSection::default()
/// };
/// let stage = models(&ModelsInput {
///     settings: &settings,
///     recommended_orders: None,
///     identification: Some(&ident),
///     validation: Some(&valid),
///     validation_skip: 0,
///     frf: None,
///     controller: None,
///     twin: None,
/// })
/// .unwrap();
/// assert_eq!(stage.domain, "time");
/// assert_eq!(stage.select, Select::Validation);
/// let chosen = stage.chosen().unwrap();
/// assert!(chosen.validation_fit.unwrap() > 99.9, "{:?}", chosen.validation_fit);
/// assert_eq!(stage.export.len(), 1);
/// ```
///
/// # Errors
/// A computation error when the twin's truth, the fit band or the FRF comparison cannot be
/// computed; a candidate that fails is kept with the reason in its note instead.
pub fn models(input: &ModelsInput<'_>) -> Result<ModelsStage> {
    let cfg_orig = input.settings;
    let cfg = &ModelsSection {
        orders: orders_with_recommendation(
            &cfg_orig.orders,
            input.recommended_orders,
            input.identification,
        ),
        ..cfg_orig.clone()
    };
    let Some(rec) = input.identification else {
        return Ok(ModelsStage::skip("no identification record"));
    };
    let frf = input.frf;
    let has_r = rec.r().is_some();
    let domain = cfg.domain.clone().unwrap_or_else(|| {
        if has_r && rec.closed_loop && frf.is_some() {
            "frf".into()
        } else {
            "time".into()
        }
    });
    if domain == "frf" && frf.is_none() {
        return Ok(ModelsStage::skip(
            "models.domain = \"frf\" needs the frf step",
        ));
    }
    let ts = rec.ts();
    let mut cands: Vec<Candidate> = Vec::new();
    let truth_f = frf.map(|a| a.frf.f_hz().to_vec());
    let truth = match (input.twin, &truth_f) {
        (Some(t), Some(f)) => Some(t.twin.plant_frf(f).map_err(computation)?),
        _ => None,
    };
    let validation_kind: String;
    let mut unstable: Option<UnstableChoice> = None;
    let mut band: Option<BandChoice> = None;
    if domain == "frf" {
        let Some(a) = frf else {
            return Ok(ModelsStage::skip("no FRF"));
        };
        let frd = &a.frf.plant;
        // the fit band: [models] band_hz, else where the plant FRF is measured reliably (the
        // rule of `ambid fit frf.csv` and `compare-models`, ambid_core::frf::band::fit_band)
        let explicit_band = cfg.band_hz.map(|[a, b]| (a, b));
        let b = match explicit_band {
            Some(b) => BandChoice {
                band_hz: b,
                how: format!("band {:.1}–{:.1} Hz from [models] band_hz", b.0, b.1),
            },
            None => {
                let d = fit_band(frd, FIT_REL_HALFWIDTH).map_err(computation)?;
                BandChoice {
                    band_hz: d.band,
                    how: d.describe().replace("give --band", "set [models] band_hz"),
                }
            }
        };
        let fit_band_hz = b.band_hz;
        band = Some(b);
        let weights = frf_weights(&cfg.weights, a);
        let fits = FrfCandidates {
            structures: &cfg.structures,
            orders: &cfg.orders,
            nk: cfg.nk,
            fit: FreqFitOptions {
                band_hz: Some(fit_band_hz),
                weights,
                max_iterations: cfg.max_iterations,
                ..FreqFitOptions::default()
            },
        };
        let ctrl = input.controller.map(|c| c.state_space());
        let rule = unstable_pole_rule(frd, ctrl, explicit_band, cfg.unstable_poles);
        let vrec = match (input.validation, input.controller) {
            (Some(v), Some(c)) if v.r().is_some() && v.closed_loop => Some(ValidationRecord {
                r: v.r().unwrap_or(&[]),
                y: v.y(),
                controller: c.state_space(),
                skip: input.validation_skip.min(v.len() / 4),
            }),
            _ => None,
        };
        validation_kind = if vrec.is_some() {
            "closed-loop simulation with the controller".into()
        } else {
            "none (no controller or no validation record with r)".into()
        };
        let rows = frf_candidates(frd, &fits, &rule, ctrl, vrec).map_err(computation)?;
        unstable = Some(rule);
        for r in rows {
            let truth_med = match (&r.model, &truth, &truth_f) {
                (Some(m), Some(t), Some(f)) => {
                    m.freq_response_siso(f).ok().map(|g| median_rel(&g, t))
                }
                _ => None,
            };
            cands.push(Candidate {
                structure: r.structure.name(),
                order: r.order,
                model: r.model,
                poly: None,
                n_params: r.n_params,
                relative_rmse: r.relative_rmse,
                median_relative: r.median_relative,
                db_rmse: r.db_rmse,
                bic: r.bic,
                validation_fit: r.validation_fit,
                unstable_poles: r.unstable_poles,
                truth_median_relative: truth_med,
                valid: r.valid,
                note: r.note,
                kalman: None,
            });
        }
    } else {
        let Some(val) = input.validation else {
            return Ok(ModelsStage::skip("no validation record"));
        };
        let mut kinds = Vec::new();
        let focus = if cfg.focus == "simulation" {
            ambid_core::estimate::pem::Focus::Simulation
        } else {
            ambid_core::estimate::pem::Focus::Prediction
        };
        // state space: `auto` is `ambid fit`'s rule on open-loop records; a closed-loop record's
        // time-domain fit goes from u to y (direct method), where only the prediction criterion
        // (a noise model) is consistent
        let ss_focus = match cfg.focus.as_str() {
            "simulation" => SsFocus::Simulation,
            "prediction" => SsFocus::Prediction,
            _ if rec.closed_loop => SsFocus::Prediction,
            _ => SsFocus::Auto,
        };
        for s in &cfg.structures {
            for &n in &cfg.orders {
                let fitted: Result<TimeFit> = (|| match s {
                    Structure::Arx => {
                        let f = arx(rec.y(), &[rec.u()], &ArxOrders::siso(n, n, cfg.nk), ts)?;
                        let p = f.model.to_poly(0)?;
                        Ok((p.g()?.to_state_space()?, Some(p), f.params.len(), None))
                    }
                    Structure::Oe => {
                        // open-loop records (no excitation r): an unstable start is an
                        // artefact and is stabilised; closed-loop ones keep the strict rule
                        let opts = PemOptions::default()
                            .with_max_iterations(cfg.max_iterations)?
                            .with_focus(focus)
                            .with_open_loop(!(has_r && rec.closed_loop));
                        let (f, _) = pem::pem(
                            rec.y(),
                            rec.u(),
                            Structure::Oe,
                            &Orders::oe(n, n, cfg.nk),
                            ts,
                            &opts,
                        )?;
                        let p = f.model;
                        Ok((p.g()?.to_state_space()?, Some(p), f.params.len(), None))
                    }
                    _ => {
                        let o = SsFitOptions {
                            order: Some(n),
                            focus: ss_focus,
                            max_iterations: cfg.max_iterations,
                            ..SsFitOptions::default()
                        };
                        let f = identify_state_space(rec.u(), rec.y(), ts, &o)?;
                        let np = n * n + 2 * n;
                        let k = f.pem.and_then(|p| p.kalman_gain);
                        Ok((f.model, None, np, k))
                    }
                })();
                let sname: &'static str = s.name();
                match fitted {
                    Ok((m, poly, np, k)) => {
                        let mut c = Candidate::time_fit(sname, n, poly, np, k);
                        let (fit, kind) = match c.open_loop_response(&m, val.y(), val.u()) {
                            Some((yhat, kind)) => (fit_percent(val.y(), &yhat).ok(), kind),
                            None => (None, "unstable without a predictor: no fit"),
                        };
                        kinds.push(kind);
                        let unstable = m
                            .poles()
                            .ok()
                            .map(|p| p.iter().filter(|z| z.norm() >= 1.0).count());
                        let frf_err =
                            match (frf, m.freq_response_siso(truth_f.as_deref().unwrap_or(&[]))) {
                                (Some(a), Ok(g)) if !g.is_empty() => {
                                    let p = a.frf.plant.values();
                                    let num: f64 =
                                        g.iter().zip(p).map(|(a, b)| (a - b).norm_sqr()).sum();
                                    let den: f64 = p.iter().map(|b| b.norm_sqr()).sum();
                                    (Some((num / den).sqrt()), Some(median_rel(&g, p)))
                                }
                                _ => (None, None),
                            };
                        c.truth_median_relative = truth.as_ref().and_then(|t| {
                            m.freq_response_siso(truth_f.as_deref()?)
                                .ok()
                                .map(|g| median_rel(&g, t))
                        });
                        c.model = Some(m);
                        c.relative_rmse = frf_err.0;
                        c.median_relative = frf_err.1;
                        c.validation_fit = fit;
                        c.unstable_poles = unstable;
                        c.note = (kind != SIMULATION).then(|| format!("validation fit: {kind}"));
                        cands.push(c);
                    }
                    Err(e) => {
                        cands.push(Candidate {
                            valid: false,
                            note: Some(format!("{e:#}")),
                            ..Candidate::time_fit(sname, n, None, 0, None)
                        });
                    }
                }
            }
        }
        kinds.sort();
        kinds.dedup();
        validation_kind = format!("on the validation record: {}", kinds.join(" / "));
    }
    let select = Select::from_setting(&cfg.select);
    let choice = choose(&cands, select);
    // the Bode overlays and error curves, one per structure
    let measured = frf.map(|a| MeasuredPlant {
        f_hz: a.frf.f_hz().to_vec(),
        plant: a.frf.plant.values().to_vec(),
    });
    let overlays = measured
        .as_ref()
        .map_or_else(Vec::new, |m| overlays(&cands, m));
    let export = export(&cands, choice.index, &domain);
    let truth_unstable_poles = input
        .twin
        .map(|t| t.twin.plant_unstable_poles().unwrap_or_default());
    let chosen_unstable = choice
        .index
        .and_then(|i| cands[i].model.as_ref())
        .map(|m| {
            ambid_core::linalg::eigenvalues(m.a())
                .unwrap_or_default()
                .into_iter()
                .filter(|z| z.norm() > 1.0 && z.im >= 0.0)
                .collect()
        })
        .unwrap_or_default();
    Ok(ModelsStage {
        skipped: None,
        domain,
        orders: cfg.orders.clone(),
        configured_orders: cfg_orig.orders.clone(),
        band,
        unstable,
        validation_kind,
        candidates: cands,
        choice,
        select,
        measured,
        overlays,
        export,
        truth_unstable_poles,
        chosen_unstable,
    })
}

/// One overlay per structure with at least one response on the measured grid.
fn overlays(cands: &[Candidate], m: &MeasuredPlant) -> Vec<Overlay> {
    let f = &m.f_hz;
    let meas = &m.plant;
    OVERLAY_STRUCTURES
        .iter()
        .filter_map(|&s| {
            let fits: Vec<FitCurve> = cands
                .iter()
                .filter(|c| c.structure == s)
                .filter_map(|c| {
                    let g = c.model.as_ref()?.freq_response_siso(f).ok()?;
                    let e: Vec<f64> = g
                        .iter()
                        .zip(meas)
                        .map(|(a, b)| (a - b).norm() / b.norm())
                        .collect();
                    Some(FitCurve {
                        label: c.label(),
                        response: g,
                        relative_error: e,
                    })
                })
                .collect();
            (!fits.is_empty()).then_some(Overlay { structure: s, fits })
        })
        .collect()
}

/// Every fitted candidate as a model to export, with its metadata.
fn export(cands: &[Candidate], chosen: Option<usize>, domain: &str) -> Vec<ModelOut> {
    let mut out = Vec::new();
    for c in cands {
        let k = &c.kalman;
        if let Some(m) = &c.model {
            out.push(ModelOut {
                name: format!("{}{}", c.structure, c.order),
                ss: m.clone(),
                // an FRF-fitted ARX/OE is held in companion form: export its polynomials
                poly: c
                    .poly
                    .clone()
                    .or_else(|| crate::io::export::polynomial_form(c.structure, m)),
                kalman: c.kalman.clone(),
                meta: json!({
                    "structure": c.structure,
                    "order": c.order,
                    "domain": domain,
                    "n_params": c.n_params,
                    "relative_rmse": c.relative_rmse,
                    "bic": c.bic,
                    "validation_fit_pct": c.validation_fit,
                    "unstable_poles": c.unstable_poles,
                    "pem": {"kalman_gain": k},
                    "chosen": chosen.is_some_and(|i| cands[i].label() == c.label()),
                }),
            });
        }
    }
    out
}
