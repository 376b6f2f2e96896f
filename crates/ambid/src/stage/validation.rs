//! The validation stage: the chosen model checked on an independent record — through the closed
//! loop with the real controller when there is one ([`crate::validation::validate_closed_loop`],
//! beside the twin's exact plant through the same check), else like open-loop data (simulation
//! or one-step prediction) — with the residual tests and their number of lags.

use super::{Recording, TwinSource};
use crate::config::ValidationSection;
use crate::error::Result;
use crate::io::ControllerModel;
use crate::validation::{
    residual_lags, validate_closed_loop, LagBasis, LagChoice, MeasuredLoop, ValidationOutcome,
    ValidationSettings, RESIDUAL_LAGS_FALLBACK,
};
use ambid_core::lti::{PolyModel, StateSpace, Structure};
use ambid_core::validate::fit::fit_percent;
use ambid_core::validate::iso::IsoZones;
use ambid_core::validate::residuals::{analyze, analyze_output_error, ResidualTest};

/// How a model without a controller is compared with a record: simulated from the
/// least-squares initial state (stable models, MATLAB `compare`'s default).
pub const SIMULATION: &str = "simulation from the least-squares initial state";
/// How an unstable model with a predictor is compared with a record: its one-step prediction.
pub const ONE_STEP: &str = "1-step prediction";

/// The model under test, as data: its state-space form, its name in the report, and — when it
/// has them — its polynomial form (an ARX model's one-step predictor) and the Kalman gain of its
/// innovations form (a state-space model's predictor).
#[derive(Debug, Clone, Copy)]
pub struct ModelUnderTest<'a> {
    /// Name in the report and `summary.json` (e.g. `OE 8`).
    pub name: &'a str,
    /// The model, from the plant input u to the output y.
    pub model: &'a StateSpace,
    /// Its polynomial form, when it was fitted as one.
    pub poly: Option<&'a PolyModel>,
    /// Kalman gain $K$ of the innovations form $x_{k+1} = A x_k + B u_k + K e_k$, when it has one.
    pub kalman: Option<&'a [f64]>,
}

/// The validation stage's input.
pub struct ValidationInput<'a> {
    /// The model to validate.
    pub model: ModelUnderTest<'a>,
    /// The independent validation record.
    pub record: &'a Recording,
    /// The loop's controller (closed-loop validation), if known.
    pub controller: Option<&'a ControllerModel>,
    /// The twin (its exact plant is validated the same way, as the reference).
    pub twin: Option<&'a TwinSource>,
    /// Start-up samples left out, windows, zone limits, frequency grid and initial state of the
    /// check ([`validation_settings`] from a workflow's `[validation]`); its `lags` is replaced
    /// by the lag choice of `lags`.
    pub settings: ValidationSettings,
    /// The residual tests' number of lags; `None`: the rule of [`residual_lags`]
    /// ([`lag_choice`]).
    pub lags: Option<usize>,
}

/// The settings of [`validate_closed_loop`] for a record of `n` samples: `[validation]`'s skip
/// (at most `n/4`), lags (or [`RESIDUAL_LAGS_FALLBACK`]), windows (1 to `n/4`) and initial state,
/// with the zone limits `zones`.
///
/// ```
/// use ambid::stage::validation_settings;
/// use ambid::workflow::config::ValidationSection;
/// let v = ValidationSection { skip: 5000, windows: 20, ..ValidationSection::default() };
/// let s = validation_settings(&v, Default::default(), 1000);
/// assert_eq!((s.skip, s.windows), (250, 20));
/// ```
pub fn validation_settings(v: &ValidationSection, zones: IsoZones, n: usize) -> ValidationSettings {
    ValidationSettings {
        skip: v.skip.min(n / 4),
        lags: v.lags.unwrap_or(RESIDUAL_LAGS_FALLBACK),
        windows: v.windows.min(n / 4).max(1),
        zones,
        initial_state: v.x0,
        ..ValidationSettings::default()
    }
}

/// The residual tests' number of lags: `given` when set, else the rule of [`residual_lags`] on
/// `model` (closed with `controller` when there is one) over the `n` tested samples. The one
/// rule of `ambid validate` and `ambid run`.
///
/// ```
/// use ambid::stage::lag_choice;
/// use ambid::validation::LagBasis;
/// let m = ambid_core::lti::StateSpace::new(
///     faer::mat![[0.5]], faer::mat![[1.0]], faer::mat![[1.0]], faer::mat![[0.0]], Some(1e-3),
/// ).unwrap();
/// let given = lag_choice(Some(40), &m, None, 10_000);
/// assert_eq!((given.lags, given.basis), (40, LagBasis::Given));
/// let rule = lag_choice(None, &m, None, 10_000);
/// assert!((10..=150).contains(&rule.lags));
/// ```
pub fn lag_choice(
    given: Option<usize>,
    model: &StateSpace,
    controller: Option<&StateSpace>,
    n: usize,
) -> LagChoice {
    match given {
        Some(l) => LagChoice {
            lags: l,
            peak_sample: None,
            basis: LagBasis::Given,
        },
        None => residual_lags(model, controller, n),
    }
}

/// The model's response on a record without a controller: the simulation from the
/// least-squares initial state when the model is stable ([`SIMULATION`]), else the one-step
/// prediction where a predictor exists ([`ONE_STEP`]: an ARX polynomial form's, or the
/// innovations form's with its Kalman gain); `None` otherwise.
///
/// ```
/// use ambid::stage::{open_loop_response, ModelUnderTest, SIMULATION};
/// // y_k = 0.5 y_{k-1} + u_{k-1}, from rest: the simulation reproduces the record exactly
/// let m = ambid_core::lti::StateSpace::new(
///     faer::mat![[0.5]], faer::mat![[1.0]], faer::mat![[1.0]], faer::mat![[0.0]], Some(1e-3),
/// ).unwrap();
/// let u = [1.0, 0.0, 0.0, 1.0, 0.0, 0.0];
/// let y = m.simulate_siso(&u, None).unwrap();
/// let mut_ = ModelUnderTest { name: "ss 1", model: &m, poly: None, kalman: None };
/// let (yhat, kind) = open_loop_response(&mut_, &y, &u).unwrap();
/// assert_eq!(kind, SIMULATION);
/// assert!(yhat.iter().zip(&y).all(|(a, b)| (a - b).abs() < 1e-9));
/// ```
pub fn open_loop_response(
    m: &ModelUnderTest<'_>,
    y: &[f64],
    u: &[f64],
) -> Option<(Vec<f64>, &'static str)> {
    let stable = m
        .model
        .poles()
        .map(|p| p.iter().all(|z| z.norm() < 1.0))
        .unwrap_or(false);
    if stable {
        let sim = m
            .model
            .estimate_initial_state(u, y)
            .and_then(|x0| m.model.simulate_siso(u, Some(&x0)));
        if let Ok(ys) = sim {
            return Some((ys, SIMULATION));
        }
    }
    match (m.poly.filter(|p| p.structure() == Structure::Arx), m.kalman) {
        (Some(p), _) => {
            let (eps, _) = ambid_core::estimate::pem::prediction_errors(
                p,
                y,
                u,
                ambid_core::estimate::pem::Focus::Prediction,
            )
            .ok()?;
            Some((y.iter().zip(&eps).map(|(y, e)| y - e).collect(), ONE_STEP))
        }
        (None, Some(k)) => {
            let km = faer::Mat::from_fn(k.len(), 1, |i, _| k[i]);
            ambid_core::validate::predict::predict_k(m.model, km.as_ref(), y, u, 1)
                .ok()
                .map(|p| (p, ONE_STEP))
        }
        _ => None,
    }
}

/// The closed-loop validation of the chosen model (and of the twin's exact plant).
#[derive(Debug, Clone)]
pub struct ClosedLoopCheck {
    /// The controller's description.
    pub controller: String,
    /// The chosen model closed with the controller and driven by the record's excitation.
    pub outcome: ValidationOutcome,
    /// The twin's exact linear plant through the same check (same record and lags): the best
    /// any model can do and the residual tests' reference; `None` off the twin (or when it
    /// failed).
    pub exact_plant: Option<ValidationOutcome>,
    /// The residual tests' number of lags and its rule.
    pub lags: LagChoice,
    /// The twin runs its nonlinear physics (its exact linearised plant then leaves the
    /// nonlinear distortion in the error).
    pub nonlinear_twin: bool,
}

/// A residual test of an open-loop validation.
#[derive(Debug, Clone)]
pub struct OpenLoopResiduals {
    /// The tests (whiteness for a one-step prediction error; independence from `signal`).
    pub test: ResidualTest,
    /// The signal the error is tested against, in words (`input u`, `excitation r`,
    /// `reference w`, `—` for none).
    pub signal: &'static str,
}

/// The validation of a model without a controller (open-loop data, or closed-loop data without
/// a controller file).
#[derive(Debug, Clone)]
pub struct OpenLoopCheck {
    /// Closed-loop data validated like open-loop data for want of a controller: the warning to
    /// give.
    pub without_controller: Option<String>,
    /// How the model was compared ([`SIMULATION`] or [`ONE_STEP`]).
    pub kind: &'static str,
    /// The model's response $\hat y$ on the record.
    pub yhat: Vec<f64>,
    /// Fit % of $\hat y$ ([`fit_percent`]).
    pub fit_y: f64,
    /// The residual tests' number of lags and its rule.
    pub lags: LagChoice,
    /// The residual tests, or why there are none.
    pub residuals: std::result::Result<OpenLoopResiduals, String>,
}

impl OpenLoopCheck {
    /// Whether $\hat y$ is a one-step prediction (else a simulation).
    pub fn one_step(&self) -> bool {
        self.kind == ONE_STEP
    }
}

/// What the validation did.
#[derive(Debug, Clone)]
pub enum ValidationCheck {
    /// Through the closed loop with the controller.
    ClosedLoop(Box<ClosedLoopCheck>),
    /// Like open-loop data.
    OpenLoop(Box<OpenLoopCheck>),
    /// Not done, and why (the step is skipped with this reason).
    NotDone(String),
}

/// The validation stage's output: everything the report, `summary.json` and the later stages
/// need.
#[derive(Debug, Clone)]
pub struct ValidationStage {
    /// The model's name.
    pub model: String,
    /// Where the record came from.
    pub source: String,
    /// Samples of the record.
    pub samples: usize,
    /// Sample time \[s\].
    pub ts: f64,
    /// The measured output y (for the figures).
    pub y: Vec<f64>,
    /// The measured plant input u (for the figures).
    pub u: Vec<f64>,
    /// What was done.
    pub check: ValidationCheck,
}

impl ValidationStage {
    /// The closed-loop outcome of the chosen model, when it was validated through the loop.
    pub fn closed_loop(&self) -> Option<&ValidationOutcome> {
        match &self.check {
            ValidationCheck::ClosedLoop(c) => Some(&c.outcome),
            _ => None,
        }
    }
}

/// Whether a closed-loop record has something that drives the loop: a nonzero excitation `r`
/// or a nonzero position reference `w`.
pub fn drives_loop(r: Option<&[f64]>, w: Option<&[f64]>) -> bool {
    let nonzero = |x: Option<&[f64]>| x.is_some_and(|x| x.iter().any(|v| *v != 0.0));
    nonzero(r) || nonzero(w)
}

/// The validation stage. With a controller and closed-loop data: the model closed with the
/// controller and driven by the record's excitation (and reference), its fits of y and u, and
/// the output error $\varepsilon = y - \hat y$ tested for independence of the excitation (the
/// portmanteau statistic $Q = N x^\top \hat\Sigma^{+} x$ against the 95 % quantile of
/// $\chi^2$), beside the twin's exact plant through the same check (in parallel). Otherwise the
/// model's open-loop response ([`open_loop_response`]) with its fit and residual tests.
///
/// ```
/// use ambid::experiment::ExcitationPlan;
/// use ambid::stage::{validation, validation_settings, ModelUnderTest, ValidationCheck, ValidationInput, TwinSource};
/// use ambid::workflow::config::ValidationSection;
/// use ambid_twin::{Mode, TwinConfig};
/// let twin = TwinSource::new(TwinConfig::default(), Mode::Linear).unwrap();
/// // a short closed-loop record of the twin (PRBS excitation, noisy sensor)
/// let plan = ExcitationPlan { periods: 2, ..ExcitationPlan::default() };
/// let (rec, _) = twin.record(plan, 3, "validation").unwrap();
/// let ctrl = ambid::io::ControllerModel::new(twin.twin.controller().clone(), "the twin's PID").unwrap();
/// let plant = twin.twin.plant().clone();
/// let stage = validation(&ValidationInput {
///     model: ModelUnderTest { name: "exact", model: &plant, poly: None, kalman: None },
///     record: &rec,
///     controller: Some(&ctrl),
///     twin: None,
///     settings: validation_settings(&ValidationSection::default(), Default::default(), rec.len()),
///     lags: None,
/// }).unwrap();
/// let ValidationCheck::ClosedLoop(c) = &stage.check else { panic!() };
/// // the exact plant reproduces the noisy record to the sensor noise
/// assert!(c.outcome.fit_y > 80.0, "{}", c.outcome.fit_y);
/// ```
///
/// # Errors
/// The errors of [`validate_closed_loop`] (an unstable loop with the model, a sample time that
/// differs from the record's, too few samples after the start-up) and of the residual tests, as
/// they come (`ambid run` classes them as computation errors, `ambid validate` keeps them).
pub fn validation(input: &ValidationInput<'_>) -> Result<ValidationStage> {
    let val = input.record;
    let m = &input.model;
    let mut stage = ValidationStage {
        model: m.name.to_string(),
        source: val.source.clone(),
        samples: val.len(),
        ts: val.ts(),
        y: val.y().to_vec(),
        u: val.u().to_vec(),
        check: ValidationCheck::NotDone(String::new()),
    };
    stage.check = match (input.controller, val.closed_loop) {
        (Some(_), true) if !drives_loop(val.r(), val.w()) => ValidationCheck::NotDone(format!(
            "the validation record {} has neither an excitation r nor a position reference w \
             (or they are zero): nothing drives the loop. Name the columns in [data] r / w.",
            val.source
        )),
        (Some(c), true) => {
            let zeros = vec![0.0; val.len()];
            let w = val.w().unwrap_or(&zeros);
            let mut s = input.settings.clone();
            let lags = lag_choice(
                input.lags,
                m.model,
                Some(c.state_space()),
                val.len().saturating_sub(s.skip),
            );
            s.lags = lags.lags;
            let rec = MeasuredLoop {
                w,
                r: val.r(),
                y: val.y(),
                u: val.u(),
                ts: val.ts(),
            };
            // the chosen model and (twin) the exact plant through the same validation
            let (v, exact) = rayon::join(
                || validate_closed_loop(m.model, c.state_space(), &rec, &s),
                || {
                    input
                        .twin
                        .map(|t| validate_closed_loop(t.twin.plant(), c.state_space(), &rec, &s))
                },
            );
            ValidationCheck::ClosedLoop(Box::new(ClosedLoopCheck {
                controller: c.description().to_string(),
                outcome: v?,
                exact_plant: exact.and_then(|e| e.ok()),
                lags,
                nonlinear_twin: input
                    .twin
                    .is_some_and(|t| t.mode == ambid_twin::Mode::Nonlinear),
            }))
        }
        (_, closed) => open_loop(input, closed)?,
    };
    Ok(stage)
}

/// The open-loop branch of [`validation`].
fn open_loop(input: &ValidationInput<'_>, closed: bool) -> Result<ValidationCheck> {
    let val = input.record;
    let m = &input.model;
    let without_controller = closed.then(|| {
        "Closed-loop data without a controller file: the model cannot be validated through \
         the closed loop, so it is validated like open-loop data (one-step prediction when \
         it is unstable). Give [data] controller = \"controller.toml\" for the closed-loop \
         validation."
            .to_string()
    });
    // open loop: simulate (stable) or predict one step (unstable) on the validation record
    let Some((yhat, kind)) = open_loop_response(m, val.y(), val.u()) else {
        return Ok(ValidationCheck::NotDone(format!(
            "{} is unstable and has no predictor: it cannot be validated in open loop",
            m.name
        )));
    };
    let fit_y = fit_percent(val.y(), &yhat)?;
    let eps: Vec<f64> = val.y().iter().zip(&yhat).map(|(a, b)| a - b).collect();
    // the quantity that should be white / independent (docs/validation.md): a one-step
    // prediction error of a model with a noise model is white and independent of the input; a
    // simulation error (no noise model) is only independent of it. In closed loop the test
    // signal is the excitation r (or reference w), never u (it contains −C v).
    let test_signal: Option<(&[f64], &'static str)> = if closed {
        match (val.r(), val.w()) {
            (Some(r), _) if r.iter().any(|v| *v != 0.0) => Some((r, "excitation r")),
            (_, Some(w)) if w.iter().any(|v| *v != 0.0) => Some((w, "reference w")),
            _ => None,
        }
    } else {
        Some((val.u(), "input u"))
    };
    let lags = lag_choice(input.lags, m.model, None, val.len());
    let one_step = kind == ONE_STEP;
    let residuals = match (one_step, test_signal) {
        (true, t) => Ok(OpenLoopResiduals {
            test: analyze(&eps, t.map(|t| t.0), lags.lags)?,
            signal: t.map_or("—", |t| t.1),
        }),
        (false, Some((x, signal))) => Ok(OpenLoopResiduals {
            test: analyze_output_error(&eps, x, lags.lags)?,
            signal,
        }),
        (false, None) => Err(
            "No residual test: the simulation error of closed-loop data can only be tested against \
             an excitation r or a reference w (not u, which contains the fed-back noise), and the \
             record has neither."
                .to_string(),
        ),
    };
    Ok(ValidationCheck::OpenLoop(Box::new(OpenLoopCheck {
        without_controller,
        kind,
        yhat,
        fit_y,
        lags,
        residuals,
    })))
}
