//! The seed paper's identification procedure end to end (`ambid run`): excitation design and
//! comparison → amplitude study → robust BLA → operating-point study → identification record → nonparametric
//! FRF with quality measures → order estimation → ARX/OE/state-space fits and their comparison →
//! pole-zero check → validation on an independent record with residual tests → chirp closed-loop
//! reconstruction → ISO 14839-3 verdict.
//!
//! [`run`] computes everything in memory ([`Outcome`]: the report, `summary.json`, the figure
//! data and the models); [`Outcome::write`] writes it atomically into one directory. Every number
//! comes from the library functions the CLI commands use ([`crate::analysis`], [`crate::study`],
//! [`crate::validation`], `ambid_core::validate::compare`, …): the workflow only composes them.
//!
//! On the twin the steps run from the defaults; with a workflow file ([`config`]) they run on
//! recorded files. A step the data do not allow (closed-loop steps on open-loop data, the twin's
//! studies on files without one record per level) is skipped with a note in the report.

/// The workflow file's sections (the stages' settings), [`crate::config`].
pub use crate::config;
mod data;
pub mod figures;
pub mod machine;
pub mod machine_fit;
pub mod machine_physical;
mod machine_render;
mod outcome;
mod physical_operating;
mod render_frf;
mod render_models;
mod render_signal;
mod render_validation;
mod steps_frf;
mod steps_models;
mod steps_robust;
mod steps_signal;
mod steps_validate;
mod summary;

pub use self::config::{ConfigError, Step, WorkflowConfig};
use self::data::Recording;
pub use self::outcome::*;
use crate::io::output::OutputDir;
use crate::report::{Block, NoteKind, Report, Section};
use crate::stage::Seeds;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub use crate::error::{Error, FailureClass};

/// The only fields of `ambid run`'s outputs that differ between two runs of the same workflow:
/// the wall-clock step timings, `summary.json`'s object `"timing"` (keys `timing.<step>_s`,
/// `timing.total_s`, `timing.wall_s`), which appear again as the `timing.*` rows of the summary table in
/// `report.html` and `tables/summary.csv`. Every other byte of every output is reproduced
/// exactly (docs/workflow.md, "Outputs").
pub const TIMING_KEY: &str = "timing";

/// An input-data error (exit 3): a file that is missing, unreadable or malformed.
pub fn input(e: impl Into<Error>) -> Error {
    Error::classified(FailureClass::Input, e)
}

/// A computation error (exit 4).
pub fn computation(e: impl Into<Error>) -> Error {
    Error::classified(FailureClass::Computation, e)
}

/// A usage error (exit 2): a command-line option value or combination that is refused.
pub fn usage(e: impl Into<Error>) -> Error {
    Error::classified(FailureClass::Config, e)
}

/// An output error (exit 5): a file or directory that cannot be written.
pub fn output(e: impl Into<Error>) -> Error {
    Error::classified(FailureClass::Output, e)
}

/// A message with every over-long decimal number (more than [`MAX_MESSAGE_DIGITS`] digits,
/// e.g. a user's `1e300` printed by `{}` as 301 digits) rewritten compactly as `1.000000e300`;
/// everything else is kept. `main` prints every error through it, so no message of any command
/// grows with the size of a number in the input.
///
/// ```
/// use ambid::workflow::compact_numbers;
/// let huge = format!("got {} Hz at row 12", 1e300);
/// assert_eq!(compact_numbers(&huge), "got 1.000000e300 Hz at row 12");
/// assert_eq!(compact_numbers("fs = 20000.5 Hz, t = -0.000050"), "fs = 20000.5 Hz, t = -0.000050");
/// ```
pub fn compact_numbers(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = String::with_capacity(s.len());
    let mut i = 0;
    let mut copied = 0;
    while i < b.len() {
        // a number starts at a digit not preceded by a letter, digit, `_` or `.`
        let starts = b[i].is_ascii_digit()
            && (i == 0
                || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_' || b[i - 1] == b'.'));
        if !starts {
            i += 1;
            continue;
        }
        let mut j = i;
        while j < b.len() && b[j].is_ascii_digit() {
            j += 1;
        }
        if j + 1 < b.len() && b[j] == b'.' && b[j + 1].is_ascii_digit() {
            j += 1;
            while j < b.len() && b[j].is_ascii_digit() {
                j += 1;
            }
        }
        let digits = b[i..j].iter().filter(|c| c.is_ascii_digit()).count();
        if digits > MAX_MESSAGE_DIGITS {
            if let Ok(v) = s[i..j].parse::<f64>() {
                out.push_str(&s[copied..i]);
                out.push_str(&format!("{v:.6e}"));
                copied = j;
            }
        }
        i = j;
    }
    out.push_str(&s[copied..]);
    out
}

/// The most digits a number in a message keeps as written (see [`compact_numbers`]); 24 keeps
/// every `f64` printed with its 17 significant digits and a few leading zeros.
pub const MAX_MESSAGE_DIGITS: usize = 24;

/// How much the workflow tells on stderr.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verbosity {
    /// Errors only.
    Quiet,
    /// One line per step (and a spinner on long steps when stderr is a terminal).
    Normal,
    /// Also the step's details.
    Verbose,
}

/// Progress reporting on stderr.
pub struct Progress {
    verbosity: Verbosity,
    spinner: Option<indicatif::ProgressBar>,
    total: usize,
    done: usize,
}

impl Progress {
    /// Progress at a verbosity; spinners only when stderr is a terminal.
    pub fn new(verbosity: Verbosity) -> Self {
        Self {
            verbosity,
            spinner: None,
            total: 0,
            done: 0,
        }
    }

    fn start(&mut self, what: &str) {
        self.done += 1;
        if self.verbosity == Verbosity::Quiet {
            return;
        }
        use std::io::IsTerminal;
        if std::io::stderr().is_terminal() {
            let pb = indicatif::ProgressBar::new_spinner();
            pb.set_message(format!("[{}/{}] {what}", self.done, self.total));
            pb.enable_steady_tick(std::time::Duration::from_millis(100));
            self.spinner = Some(pb);
        }
    }

    fn finish(&mut self, what: &str, seconds: f64, status: &str) {
        if let Some(pb) = self.spinner.take() {
            pb.finish_and_clear();
        }
        if self.verbosity != Verbosity::Quiet {
            eprintln!(
                "[{}/{}] {what}: {status} ({seconds:.2} s)",
                self.done, self.total
            );
        }
    }

    fn detail(&self, text: &str) {
        if self.verbosity == Verbosity::Verbose {
            eprintln!("      {text}");
        }
    }
}

pub use crate::stage::ModelOut;

/// Time spent per step.
#[derive(Debug, Clone, serde::Serialize)]
pub struct StepTime {
    /// Step name.
    pub step: String,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// `done`, `skipped` (with the reason in the report).
    pub status: String,
}

/// Everything a workflow run produced, in memory.
pub struct Outcome {
    /// The report.
    pub report: Report,
    /// Every stage's figures, typed (what `summary.json` holds; the report's first section states
    /// the answer from them and links the file).
    pub stages: Summary,
    /// The same as JSON: `serde_json::to_value(&stages)`, written as `summary.json`.
    pub summary: Value,
    /// Models to export (JSON, `.m`, `.mat`, `.npz`).
    pub models: Vec<ModelOut>,
    /// Uncertain MIMO models to export as `models/<name>.{json,m,mat,npz}` (the whole machine's
    /// `[machine] uncertainty`, one per speed; the name is the [`MimoNames`](crate::io::export::mimo::MimoNames)'s).
    pub uncertain_models: Vec<(
        crate::io::export::mimo::MimoNames,
        crate::io::export::uncertain_matrix::UncertainMatrixModel,
    )>,
    /// Time per step.
    pub timings: Vec<StepTime>,
    /// The excitation stage's result (when the step ran).
    pub excitation: Option<crate::stage::ExcitationStage>,
    /// The operating-point study's result (when the step ran).
    pub operating_point: Option<crate::study::OperatingPointOutcome>,
    /// The robust BLA study's result (when the step ran).
    pub bla: Option<crate::bla::BlaStudy>,
    /// The models stage's typed result (candidates, choice, curves), when it ran.
    pub models_stage: Option<crate::stage::ModelsStage>,
    /// The pole-zero stage's typed result, when it ran.
    pub pole_zero_stage: Option<crate::stage::PoleZeroStage>,
    /// The validation stage's typed result (validation step).
    pub validation_stage: Option<crate::stage::ValidationStage>,
    /// The reconstruction stage's typed result (reconstruction step).
    pub reconstruction_stage: Option<crate::stage::ReconstructionStage>,
    /// The ISO 14839-3 stage's typed result (iso step).
    pub iso_stage: Option<crate::stage::IsoStage>,
    /// The nonparametric FRF stage's result (when the `frf` step ran).
    pub frf_stage: Option<crate::stage::FrfStage>,
    /// The order stage's result (when the `order` step ran).
    pub order_stage: Option<crate::stage::OrderStage>,
}

/// Stage outputs computed ahead of their step (in parallel with other stages), each with its
/// seconds; the step renders them.
#[derive(Default)]
pub(crate) struct Prefetched {
    pub amplitude: Option<(Result<crate::stage::AmplitudeStage, Error>, f64)>,
    pub bla: Option<(Result<crate::bla::BlaStudy, Error>, f64)>,
    pub noise_y: Option<Option<Vec<f64>>>,
    /// Seconds of the noise record made ahead (counted in the FRF step).
    pub noise_s: f64,
}

/// State shared by the steps.
pub(crate) struct Ctx<'a> {
    pub cfg: &'a WorkflowConfig,
    pub base: PathBuf,
    pub seeds: Seeds,
    pub sections: Vec<Section>,
    /// The step (index in the run's step list) of each section.
    pub section_step: Vec<usize>,
    pub typed: Summary,
    pub models: Vec<ModelOut>,
    /// Stage outputs computed ahead.
    pub pre: Prefetched,
    /// Seconds a step's stage spent before the step (in parallel), added to its timing.
    pub pre_seconds: f64,
    /// The twin (source = twin).
    pub twin: Option<data::TwinSource>,
    /// Identification record.
    pub ident: Option<Recording>,
    /// Validation record.
    pub valid: Option<Recording>,
    /// Chosen identification level (fraction of i_sat; twin).
    pub level_frac: Option<f64>,
    /// The seed-style amplitude study's (level %, mean relative plant variance), for the BLA step.
    pub seed_study: Option<Vec<(f64, f64)>>,
    /// The FRF stage's result.
    pub frf_stage: Option<crate::stage::FrfStage>,
    /// The order stage's result.
    pub order_stage: Option<crate::stage::OrderStage>,
    /// Controller (closed loop).
    pub controller: Option<crate::io::ControllerModel>,
    /// The excitation stage's result.
    pub excitation: Option<crate::stage::ExcitationStage>,
    /// The operating-point study's result.
    pub operating_point: Option<crate::study::OperatingPointOutcome>,
    /// The robust BLA study's result.
    pub bla: Option<crate::bla::BlaStudy>,
    /// The models stage's result.
    pub models_stage: Option<crate::stage::ModelsStage>,
    /// The pole-zero stage's result.
    pub pole_zero_stage: Option<crate::stage::PoleZeroStage>,
    /// The validation stage's result.
    pub validation_stage: Option<crate::stage::ValidationStage>,
    /// The reconstruction stage's result.
    pub reconstruction_stage: Option<crate::stage::ReconstructionStage>,
    /// The ISO 14839-3 stage's result.
    pub iso_stage: Option<crate::stage::IsoStage>,
}

impl Ctx<'_> {
    pub fn section(&mut self, id: &str, title: &str, blocks: Vec<Block>) {
        self.sections.push(Section {
            id: id.into(),
            title: title.into(),
            blocks,
        });
    }

    pub fn note(kind: NoteKind, text: impl Into<String>) -> Block {
        Block::Note {
            kind,
            text: text.into(),
        }
    }

    pub fn is_closed_loop(&self) -> bool {
        self.ident.as_ref().is_some_and(|r| r.closed_loop)
    }

    /// The FRF analysis of the identification record (the FRF stage's, when it ran).
    pub fn frf(&self) -> Option<&crate::analysis::FrfAnalysis> {
        self.frf_stage.as_ref().map(|s| &s.analysis)
    }

    /// The chosen candidate model (the models stage's choice, when it ran and chose one).
    pub fn chosen(&self) -> Option<&crate::stage::Candidate> {
        self.models_stage.as_ref().and_then(|s| s.chosen())
    }

    /// The closed-loop validation outcome of the chosen model (the validation stage's, when it
    /// validated in closed loop).
    pub fn validation(&self) -> Option<&crate::validation::ValidationOutcome> {
        self.validation_stage.as_ref().and_then(|s| s.closed_loop())
    }

    /// The identification excitation plan of the workflow file at level `frac` of i_sat.
    pub fn plan(&self, frac: f64) -> crate::experiment::ExcitationPlan {
        crate::stage::identification_plan(&self.cfg.excitation, frac, &self.seeds)
    }

    /// FRF settings for a record of `n` samples (periodic when the period is known).
    pub fn frf_settings(&self, period: Option<usize>, n: usize) -> crate::analysis::FrfSettings {
        let mut s = crate::stage::frf_settings(
            &self.cfg.frf,
            self.cfg.data.skip_periods,
            period,
            n,
            self.twin.as_ref().map(|t| t.twin.i_sat()),
        );
        // a period found in a file's `r` (data::load_file) need not divide the record (a split
        // file): its incomplete last period is dropped
        s.incomplete_tail = self.cfg.source == crate::config::SourceKind::Files
            && self.cfg.data.period_samples.is_none();
        s
    }

    /// The identification level (fraction of i_sat): the amplitude study's choice, else the
    /// configured one, else 10 %.
    fn ident_frac(&self) -> f64 {
        self.level_frac
            .or(self.cfg.excitation.amplitude_pct.map(|p| p / 100.0))
            .unwrap_or(0.1)
    }

    /// The validation level (fraction of i_sat).
    fn valid_frac(&self) -> f64 {
        self.cfg
            .validation
            .amplitude_pct
            .map(|p| p / 100.0)
            .or(self.level_frac)
            .unwrap_or(0.1)
    }

    /// The acquisition plan on the twin at the current identification level.
    fn acquisition_plan(&self, noise_record: bool) -> crate::stage::AcquisitionPlan {
        let frac = self.ident_frac();
        crate::stage::AcquisitionPlan {
            noise_record,
            ..crate::stage::AcquisitionPlan::new(
                self.plan(frac),
                data::excitation_kind(&self.cfg.validation.excitation),
                self.valid_frac(),
                self.seeds,
            )
        }
    }

    /// The identification record (on the twin: the acquisition stage at the chosen level on
    /// first use, which also makes the validation and noise records, in parallel).
    pub fn ensure_ident(&mut self) -> Result<(), Error> {
        if self.ident.is_some() {
            return Ok(());
        }
        let frac = self.ident_frac();
        self.level_frac = Some(frac);
        if let Some(t) = &self.twin {
            // the noise record may have been made ahead, beside the studies
            let noise = self.cfg.steps().contains(&Step::Frf) && self.pre.noise_y.is_none();
            let plan = self.acquisition_plan(noise);
            let acq = crate::stage::acquire_twin(t, &plan)?;
            let rec = acq.identification;
            self.typed.identification = Some(IdentificationSummary {
                level_pct: 100.0 * frac,
                samples: rec.len() as f64,
                saturated_pct: rec.saturated_fraction.map(|s| 100.0 * s),
            });
            self.ident = Some(rec);
            if self.valid.is_none() {
                self.valid = Some(acq.validation);
            }
            if noise {
                self.pre.noise_y = Some(acq.noise_y);
            }
        }
        Ok(())
    }

    /// The independent validation record (twin: a different excitation and noise realisation).
    pub fn ensure_valid(&mut self) -> Result<(), Error> {
        if self.valid.is_some() {
            return Ok(());
        }
        if let Some(t) = &self.twin {
            let plan = self.acquisition_plan(false);
            let (rec, _) = t.record(
                plan.validation.clone(),
                plan.seeds.validation_record,
                "validation",
            )?;
            self.valid = Some(rec);
        }
        Ok(())
    }

    /// The twin's record without excitation, made ahead of the FRF step (it depends on no
    /// other stage); `None` when the twin has no noise or the simulation fails (the FRF step
    /// then makes it again and reports the error).
    fn noise_ahead(&self) -> Option<(Vec<f64>, f64)> {
        let t = self.twin.as_ref().filter(|t| t.noise)?;
        let p = crate::experiment::ExcitationPlan {
            kind: crate::experiment::ExcitationKind::None,
            ..self.plan(0.0)
        };
        let (rec, secs) = timed(|| t.record(p, self.seeds.noise_record, "noise"));
        rec.ok().map(|(r, _)| (r.y().to_vec(), secs))
    }

    /// The twin record without excitation (output SNR), or the `[data] noise` file.
    pub fn noise_record(&mut self) -> Result<Option<Vec<f64>>, Error> {
        if let Some(t) = &self.twin {
            if !t.noise {
                return Ok(None);
            }
            if let Some(y) = self.pre.noise_y.take().flatten() {
                self.pre_seconds += std::mem::take(&mut self.pre.noise_s);
                return Ok(Some(y));
            }
            let p = crate::experiment::ExcitationPlan {
                kind: crate::experiment::ExcitationKind::None,
                ..self.plan(0.0)
            };
            return Ok(Some(
                t.record(p, self.seeds.noise_record, "noise")?
                    .0
                    .y()
                    .to_vec(),
            ));
        }
        match &self.cfg.data.noise {
            Some(p) => Ok(Some(
                data::load_file(self.cfg, &self.base, p, "noise")?
                    .y()
                    .to_vec(),
            )),
            None => Ok(None),
        }
    }
}

/// An error's message with its sources, `a: b: c` (how the error chain was always printed;
/// the Python package raises the same text).
pub fn chain_message(e: &dyn std::error::Error) -> String {
    let mut msg = e.to_string();
    let mut src = e.source();
    while let Some(s) = src {
        msg.push_str(": ");
        msg.push_str(&s.to_string());
        src = s.source();
    }
    msg
}

/// Flattens `summary` into (dotted key, formatted value) rows; numbers are formatted with
/// [`crate::report::format_number`].
pub fn flatten_summary(v: &Value) -> Vec<(String, String)> {
    fn walk(prefix: &str, v: &Value, out: &mut Vec<(String, String)>) {
        match v {
            Value::Object(m) => {
                for (k, x) in m {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    walk(&key, x, out);
                }
            }
            Value::Array(a) => {
                for (i, x) in a.iter().enumerate() {
                    walk(&format!("{prefix}[{i}]"), x, out);
                }
            }
            Value::Number(n) => out.push((
                prefix.to_string(),
                n.as_f64()
                    .map_or_else(|| n.to_string(), crate::report::format_number),
            )),
            Value::String(s) => out.push((prefix.to_string(), s.clone())),
            Value::Bool(b) => out.push((prefix.to_string(), b.to_string())),
            Value::Null => out.push((prefix.to_string(), "—".into())),
        }
    }
    let mut out = Vec::new();
    walk("", v, &mut out);
    out
}

/// Runs the workflow. `base` is the directory relative paths in `cfg` are resolved against (the
/// workflow file's directory).
///
/// The stages run in the order of `cfg.steps()`, except that on the twin the studies that do
/// not feed the identification run alongside it: the amplitude and BLA studies together, the
/// operating-point study beside the FRF → order → models → validation chain (rayon). Every
/// stage draws from its own seed ([`crate::stage::Seeds`]), so the numbers do not depend on the
/// number of threads; the report's sections keep the step order.
///
/// # Example
/// ```
/// use ambid::workflow::{run, Progress, Step, Verbosity, WorkflowConfig};
/// use std::path::Path;
/// // the excitation comparison alone, on the twin (the default source)
/// let cfg = WorkflowConfig {
///     steps: Some(vec![Step::Excitation]),
///     ..WorkflowConfig::default()
/// };
/// let out = run(&cfg, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
/// let crest = out.summary["excitation"]["compare"]["prbs"]["crest_factor"].as_f64().unwrap();
/// assert!((crest - 1.0).abs() < 1e-9); // a PRBS is ±A: crest factor 1
/// assert!(out.report.to_html().contains("Excitation design and comparison"));
/// ```
///
/// # Errors
/// An [`Error`] with its class: input files missing or malformed, or a computation that failed.
pub fn run(cfg: &WorkflowConfig, base: &Path, progress: &mut Progress) -> Result<Outcome, Error> {
    if cfg.machine.is_some() {
        // the whole-machine procedure (docs/workflow.md, "Whole machine"); the models come
        // through its seam, `machine::MachineModels`: `[machine] models = "fit"` selects the
        // MIMO fitter (`"fit-all"`: every candidate order); the default stays `MeasuredOnly`
        // because the fitter takes 17–20 s for the default three speeds of the nonlinear twin on 2
        // cores (docs/benchmarks.md)
        let models = cfg.machine.as_ref().map(|m| m.models.as_str());
        return if let Some(kind @ ("fit" | "fit-all")) = models {
            machine::run_with(
                cfg,
                base,
                progress,
                &machine_fit::FrequencyFitter {
                    stop_at_noise_level: kind == "fit",
                    order_from_reference_speed: kind == "fit",
                    uncertainty: cfg.machine.as_ref().is_some_and(|m| m.uncertainty),
                    ..Default::default()
                },
            )
        } else {
            machine::run_with(cfg, base, progress, &machine::MeasuredOnly)
        }
        .map(|(o, _)| o);
    }
    let steps = cfg.steps();
    progress.total = steps.len() + 1;
    let t0 = Instant::now();
    let mut sections_prelude = Vec::new();
    progress.start("data");
    let prepared = data::prepare(cfg, base)?;
    // the values that depend on the records are checked before any step runs, too
    let mut fallback_note = None;
    if let Some(rec) = prepared.ident.as_ref() {
        if steps.contains(&Step::Frf) {
            crate::analysis::check_frf_length(rec.len(), Some(&rec.source.to_string()))
                .map_err(input)?;
        }
        cfg.check_record(Path::new("workflow file"), rec.len())?;
        if let Some(p) = cfg.data.period_samples {
            if cfg.frf.method == "auto" && rec.len() / p < 2 {
                fallback_note = Some(Ctx::note(
                    NoteKind::Warning,
                    format!(
                        "[data] period_samples = {p}, but the estimation record has {} samples, fewer than 2 periods: \
                         the FRF uses Welch averaging instead of period averaging (frf.method = \"auto\"). \
                         Correct period_samples, or set frf.method = \"welch\" to silence this warning.",
                        rec.len()
                    ),
                ));
            }
        }
    }
    let mut ctx = Ctx {
        cfg,
        base: base.to_path_buf(),
        seeds: crate::stage::Seeds::from_workflow_seed(cfg.seed),
        sections: Vec::new(),
        section_step: Vec::new(),
        typed: Summary::default(),
        models: Vec::new(),
        pre: Prefetched::default(),
        pre_seconds: 0.0,
        twin: prepared.twin,
        ident: prepared.ident,
        valid: prepared.valid,
        level_frac: None,
        seed_study: None,
        frf_stage: None,
        order_stage: None,
        controller: prepared.controller,
        excitation: None,
        operating_point: None,
        bla: None,
        models_stage: None,
        pole_zero_stage: None,
        validation_stage: None,
        reconstruction_stage: None,
        iso_stage: None,
    };
    let mut data_section = data::describe(&mut ctx);
    data_section.blocks.extend(fallback_note);
    sections_prelude.push(data_section);
    let dt = t0.elapsed().as_secs_f64();
    progress.finish("data", dt, "done");
    let mut timings: Vec<Option<StepTime>> = vec![None; steps.len()];
    let indexed: Vec<(usize, Step)> = steps.iter().copied().enumerate().collect();
    // on the twin the robust BLA study runs beside the steps and is rendered in its place
    // afterwards, before the `uncertainty` step (the only one that reads it, for its term
    // (c)) and the steps after it run; the amplitude study and the noise-only record
    // (independent experiments, each from its own seed) run together first
    let bla = ctx
        .twin
        .is_some()
        .then(|| indexed.iter().find(|(_, s)| *s == Step::Bla).copied())
        .flatten()
        .and_then(|kb| Some((kb, steps_signal::bla_input(&ctx)?)));
    let rest: Vec<(usize, Step)> = indexed
        .iter()
        .copied()
        .filter(|(k, _)| bla.as_ref().is_none_or(|(kb, _)| kb.0 != *k))
        .collect();
    let split = rest
        .iter()
        .position(|(_, s)| *s == Step::Uncertainty)
        .unwrap_or(rest.len());
    let (rest, after) = rest.split_at(split);
    // the amplitude study first (its chosen level feeds the identification chain): the BLA
    // study then runs beside the chain and the operating-point study, where the two cores have
    // room, instead of competing with the amplitude study on the critical path
    studies_ahead(&mut ctx, &steps);
    let (bla_out, result) = rayon::join(
        || {
            bla.as_ref()
                .map(|(kb, i)| (*kb, timed(|| crate::stage::bla_twin(i))))
        },
        || run_steps(&mut ctx, rest, progress, &mut timings),
    );
    // the first failure in the order of the steps
    if let Some(((kb, step), (study, secs))) = bla_out {
        if let Err((k, e)) = result {
            if k < kb || study.is_ok() {
                return Err(e);
            }
        }
        ctx.pre.bla = Some((study, secs));
        let t = Instant::now();
        progress.start(step.name());
        let n_before = ctx.sections.len();
        let status = dispatch(&mut ctx, step)?;
        let dt = t.elapsed().as_secs_f64() + std::mem::take(&mut ctx.pre_seconds);
        finish_step(
            &mut ctx,
            progress,
            &mut timings,
            (kb, step),
            n_before,
            status,
            dt,
        );
    } else {
        result.map_err(|(_, e)| e)?;
    }
    run_steps(&mut ctx, after, progress, &mut timings).map_err(|(_, e)| e)?;
    let timings: Vec<StepTime> = std::iter::once(StepTime {
        step: "data".into(),
        seconds: dt,
        status: "done".into(),
    })
    .chain(timings.into_iter().flatten())
    .collect();
    // the per-step timings are part of the summary and of the report
    let total: f64 = timings.iter().map(|t| t.seconds).sum();
    ctx.typed.timing.insert("total_s".into(), total);
    for t in &timings {
        ctx.typed.timing.insert(format!("{}_s", t.step), t.seconds);
    }
    ctx.typed
        .timing
        .insert("wall_s".into(), t0.elapsed().as_secs_f64());
    let summary = serde_json::to_value(&ctx.typed)
        .map_err(|e| Error::computation(format!("summary.json: {e}")))?;
    // the sections in the order of the steps (a stage run alongside others renders later)
    let mut tagged: Vec<(usize, Section)> = std::mem::take(&mut ctx.section_step)
        .into_iter()
        .zip(std::mem::take(&mut ctx.sections))
        .collect();
    tagged.sort_by_key(|(k, _)| *k);
    let mut sections = sections_prelude;
    sections.extend(tagged.into_iter().map(|(_, s)| s));
    // the answer first; every number stays in summary.json (linked, no longer dumped here)
    sections.insert(
        0,
        summary::section(
            &ctx.typed,
            &sections,
            ctx.models_stage.as_ref(),
            ctx.is_closed_loop(),
        ),
    );
    let title = cfg.title.clone().unwrap_or_else(|| match cfg.source {
        config::SourceKind::Twin => {
            "ambid: closed-loop identification of the embedded AMB twin".into()
        }
        config::SourceKind::Files => "ambid: closed-loop identification report".into(),
    });
    let report = Report {
        title,
        subtitle: format!(
            "ambid {} · seed {} · {} · steps: {}",
            env!("CARGO_PKG_VERSION"),
            cfg.seed,
            match cfg.source {
                config::SourceKind::Twin => "embedded twin".to_string(),
                config::SourceKind::Files => cfg
                    .data
                    .identification
                    .as_ref()
                    .map_or("files".into(), |p| p.display().to_string()),
            },
            cfg.steps()
                .iter()
                .map(|s| s.name())
                .collect::<Vec<_>>()
                .join(", ")
        ),
        sections,
    };
    Ok(Outcome {
        report,
        stages: ctx.typed,
        summary,
        models: ctx.models,
        uncertain_models: Vec::new(),
        timings,
        excitation: ctx.excitation,
        operating_point: ctx.operating_point,
        bla: ctx.bla,
        models_stage: ctx.models_stage,
        pole_zero_stage: ctx.pole_zero_stage,
        validation_stage: ctx.validation_stage,
        reconstruction_stage: ctx.reconstruction_stage,
        iso_stage: ctx.iso_stage,
        frf_stage: ctx.frf_stage,
        order_stage: ctx.order_stage,
    })
}

/// On the twin: the amplitude study and the noise-only record, side by side, ahead of their steps.
fn studies_ahead(ctx: &mut Ctx<'_>, steps: &[Step]) {
    if ctx.twin.is_none() {
        return;
    }
    let amp = steps
        .contains(&Step::Amplitude)
        .then(|| steps_signal::amplitude_input(ctx))
        .flatten();
    let configured = ctx.cfg.excitation.amplitude_pct;
    let want_noise = steps.contains(&Step::Frf);
    let shared = &*ctx;
    let (a, n) = rayon::join(
        || amp.map(|i| timed(|| crate::stage::amplitude_twin(&i, configured))),
        || want_noise.then(|| shared.noise_ahead()).flatten(),
    );
    ctx.pre.amplitude = a;
    if let Some((y, secs)) = n {
        ctx.pre.noise_y = Some(Some(y));
        ctx.pre.noise_s = secs;
    }
}

/// `f`'s result and its wall-clock seconds.
fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let t = Instant::now();
    let out = f();
    (out, t.elapsed().as_secs_f64())
}

/// Runs one step on the context.
fn dispatch(ctx: &mut Ctx<'_>, step: Step) -> Result<StepStatus, Error> {
    match step {
        Step::Excitation => steps_signal::excitation(ctx),
        Step::Amplitude => steps_signal::amplitude(ctx),
        Step::Bla => steps_signal::bla(ctx),
        Step::OperatingPoint => steps_signal::operating_point(ctx, None),
        Step::Frf => steps_frf::frf(ctx),
        Step::Order => steps_frf::order(ctx),
        Step::Models => steps_models::models(ctx),
        Step::PoleZero => steps_models::pole_zero(ctx),
        Step::Validation => steps_validate::validation(ctx),
        Step::Reconstruction => steps_validate::reconstruction(ctx),
        Step::Iso => steps_validate::iso(ctx),
        Step::Uncertainty => steps_robust::uncertainty(ctx),
        Step::Physical => steps_robust::physical(ctx),
    }
}

/// Books a finished step: tags its new sections, adds the skipped note, reports progress and
/// keeps its time.
fn finish_step(
    ctx: &mut Ctx<'_>,
    progress: &mut Progress,
    timings: &mut [Option<StepTime>],
    (k, step): (usize, Step),
    n_before: usize,
    status: StepStatus,
    dt: f64,
) {
    let status = match status {
        StepStatus::Done => "done".to_string(),
        StepStatus::Skipped(why) => {
            if ctx.sections.len() == n_before {
                ctx.section(
                    step.name(),
                    &format!("{} (skipped)", step.name().replace('_', " ")),
                    vec![Ctx::note(NoteKind::Warning, format!("Skipped: {why}"))],
                );
            }
            progress.detail(&why);
            "skipped".to_string()
        }
    };
    let n = ctx.sections.len() - ctx.section_step.len();
    ctx.section_step.extend(std::iter::repeat_n(k, n));
    progress.finish(step.name(), dt, &status);
    timings[k] = Some(StepTime {
        step: step.name().into(),
        seconds: dt,
        status,
    });
}

/// Runs `steps` in order; on the twin the operating-point study runs beside the steps after it
/// up to the `uncertainty` or `physical` step, which use it (it depends only on the identification level,
/// which the amplitude step fixed before). An error comes with the index of its step.
fn run_steps(
    ctx: &mut Ctx<'_>,
    steps: &[(usize, Step)],
    progress: &mut Progress,
    timings: &mut [Option<StepTime>],
) -> Result<(), (usize, Error)> {
    let mut rest = steps;
    while let Some((&(k, step), tail)) = rest.split_first() {
        if step == Step::OperatingPoint && !tail.is_empty() {
            if let Some(input) = steps_signal::operating_point_input(ctx) {
                progress.start(step.name());
                // the uncertainty step uses the study (term (d)): the steps before it run beside
                // the study, the rest after it
                let split = tail
                    .iter()
                    .position(|(_, s)| matches!(s, Step::Uncertainty | Step::Physical))
                    .unwrap_or(tail.len());
                let (beside, after) = tail.split_at(split);
                let ((op, op_s), chain) = rayon::join(
                    || timed(|| crate::stage::operating_point_twin(&input)),
                    || run_steps(ctx, beside, progress, timings),
                );
                let t = Instant::now();
                let n_before = ctx.sections.len();
                let op = op.map_err(|e| (k, e))?;
                let status =
                    steps_signal::operating_point(ctx, Some((op, input))).map_err(|e| (k, e))?;
                let dt = op_s + t.elapsed().as_secs_f64();
                finish_step(ctx, progress, timings, (k, step), n_before, status, dt);
                chain?;
                return run_steps(ctx, after, progress, timings);
            }
        }
        let t = Instant::now();
        progress.start(step.name());
        let n_before = ctx.sections.len();
        let status = dispatch(ctx, step).map_err(|e| (k, e))?;
        let dt = t.elapsed().as_secs_f64() + std::mem::take(&mut ctx.pre_seconds);
        finish_step(ctx, progress, timings, (k, step), n_before, status, dt);
        rest = tail;
    }
    Ok(())
}

/// A single-input single-output model's JSON, as `models/<name>.json` holds it.
fn siso_model_json(m: &ModelOut) -> Value {
    use crate::io::model::{polynomial_json, state_space_json};
    match &m.poly {
        Some(p) => polynomial_json(p, "u", "y", m.meta.clone()),
        None => state_space_json(&m.ss, "u", "y", m.meta.clone()),
    }
}

/// A MIMO model's channel names and speed from its `meta` (`inputs`, `outputs`, `speed_rpm`;
/// `u1…`, `y1…` when absent).
fn mimo_names(m: &ModelOut) -> crate::io::export::mimo::MimoNames {
    let list = |key: &str, prefix: &str, n: usize| -> Vec<String> {
        m.meta[key]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|v| v.as_str().unwrap_or_default().to_string())
                    .collect()
            })
            .unwrap_or_else(|| (1..=n).map(|k| format!("{prefix}{k}")).collect())
    };
    crate::io::export::mimo::MimoNames {
        name: m.name.clone(),
        inputs: list("inputs", "u", m.ss.ninputs()),
        outputs: list("outputs", "y", m.ss.noutputs()),
        speed_rpm: m.meta["speed_rpm"].as_f64(),
    }
}

/// The four files of a MIMO model (the whole machine's): channel names and speed from its
/// `meta` (`inputs`, `outputs`, `speed_rpm`; `u1…`, `y1…` when absent).
fn mimo_files(m: &ModelOut) -> Result<[(String, Vec<u8>); 4], crate::io::export::ExportError> {
    use crate::io::export::mimo::{mimo_json, mimo_mat_bytes, mimo_matlab_script, mimo_npz_bytes};
    let names = mimo_names(m);
    let json = mimo_json(&m.ss, &names, m.meta.clone())?;
    let text = serde_json::to_string_pretty(&json).unwrap_or_default();
    Ok([
        (format!("models/{}.json", m.name), text.into_bytes()),
        (
            format!("models/{}.m", m.name),
            mimo_matlab_script(&m.ss, &names)?.into_bytes(),
        ),
        (
            format!("models/{}.mat", m.name),
            mimo_mat_bytes(&m.ss, &names)?,
        ),
        (
            format!("models/{}.npz", m.name),
            mimo_npz_bytes(&m.ss, &names)?,
        ),
    ])
}

/// The four files of an uncertain MIMO model, `models/<name>.{json,m,mat,npz}`.
fn uncertain_matrix_files(
    u: &crate::io::export::uncertain_matrix::UncertainMatrixModel,
    names: &crate::io::export::mimo::MimoNames,
) -> Result<[(String, Vec<u8>); 4], crate::io::export::ExportError> {
    use crate::io::export::uncertain_matrix::{
        uncertain_matrix_json, uncertain_matrix_mat_bytes, uncertain_matrix_matlab_script,
        uncertain_matrix_npz_bytes,
    };
    let json = uncertain_matrix_json(u, names)?;
    let text = serde_json::to_string_pretty(&json).unwrap_or_default();
    let base = format!("models/{}", names.name);
    Ok([
        (format!("{base}.json"), text.into_bytes()),
        (
            format!("{base}.m"),
            uncertain_matrix_matlab_script(u, names)?.into_bytes(),
        ),
        (format!("{base}.mat"), uncertain_matrix_mat_bytes(u, names)?),
        (format!("{base}.npz"), uncertain_matrix_npz_bytes(u, names)?),
    ])
}

/// What a step did.
pub(crate) enum StepStatus {
    Done,
    Skipped(String),
}

impl Outcome {
    /// Every model's JSON as [`Outcome::write`] writes it to `models/<name>.json`, by name.
    ///
    /// # Errors
    /// A MIMO model whose JSON cannot be formed (an [`FailureClass::Output`] error, as in
    /// [`Outcome::write`]).
    pub fn model_jsons(&self) -> Result<Vec<(String, Value)>, Error> {
        self.models
            .iter()
            .map(|m| {
                let v = if m.ss.ninputs() > 1 || m.ss.noutputs() > 1 {
                    crate::io::export::mimo::mimo_json(&m.ss, &mimo_names(m), m.meta.clone())
                        .map_err(|e| output(Error::other(chain_message(&e))))?
                } else {
                    siso_model_json(m)
                };
                Ok((m.name.clone(), v))
            })
            .collect()
    }

    /// Writes `report.html`, `summary.json`, `figures/<id>.csv`, `tables/<id>.csv` and
    /// `models/<name>.{json,m,mat,npz}` into `dir`, atomically: everything goes to a temporary
    /// directory beside `dir` that is renamed into place at the end, so a failure leaves nothing
    /// half-written. An existing `dir` is replaced only with `force`.
    ///
    /// # Errors
    /// [`FailureClass::Output`] errors.
    pub fn write(&self, dir: &Path, force: bool) -> Result<Vec<PathBuf>, Error> {
        use crate::io::export::{mat_bytes, matlab_script, npz_bytes, ExportModel, ExportNames};
        use rayon::prelude::*;
        let out = OutputDir::create(dir, force)?;
        let json_error = |e: serde_json::Error| output(Error::other(chain_message(&e)));
        let export_error =
            |e: crate::io::export::ExportError| output(Error::other(chain_message(&e)));
        // every file's bytes are made in parallel (they are independent), then written in the
        // order below, so the output and the first error are those of a sequential write
        let blocks: Vec<&Block> = self
            .report
            .sections
            .iter()
            .flat_map(|s| &s.blocks)
            .filter(|b| matches!(b, Block::Figure(_) | Block::Table(_)))
            .collect();
        let ((html, summary), (tables, models)) = rayon::join(
            || {
                rayon::join(
                    || self.report.to_html(),
                    || serde_json::to_string_pretty(&self.summary),
                )
            },
            || {
                rayon::join(
                    || {
                        blocks
                            .par_iter()
                            .map(|b| match b {
                                Block::Figure(f) => (format!("figures/{}.csv", f.id), f.to_csv()),
                                Block::Table(t) => (format!("tables/{}.csv", t.id), t.to_csv()),
                                _ => (String::new(), String::new()),
                            })
                            .collect::<Vec<_>>()
                    },
                    || {
                        self.models
                            .par_iter()
                            .map(|m| -> Result<[(String, Vec<u8>); 4], Error> {
                                if m.ss.ninputs() > 1 || m.ss.noutputs() > 1 {
                                    return mimo_files(m).map_err(export_error);
                                }
                                let names = ExportNames {
                                    name: m.name.clone(),
                                    input: "u".into(),
                                    output: "y".into(),
                                    noise_variance: m.meta["noise_variance"].as_f64(),
                                };
                                let json = siso_model_json(m);
                                let em = match &m.poly {
                                    Some(p) => ExportModel::Poly(p),
                                    None => ExportModel::StateSpace(&m.ss, m.kalman.as_deref()),
                                };
                                let text =
                                    serde_json::to_string_pretty(&json).map_err(json_error)?;
                                Ok([
                                    (format!("models/{}.json", m.name), text.into_bytes()),
                                    (
                                        format!("models/{}.m", m.name),
                                        matlab_script(em, &names)
                                            .map_err(export_error)?
                                            .into_bytes(),
                                    ),
                                    (
                                        format!("models/{}.mat", m.name),
                                        mat_bytes(em, &names).map_err(export_error)?,
                                    ),
                                    (
                                        format!("models/{}.npz", m.name),
                                        npz_bytes(em, &names).map_err(export_error)?,
                                    ),
                                ])
                            })
                            .collect::<Vec<_>>()
                    },
                )
            },
        );
        out.write("report.html", html.as_bytes())?;
        out.write("summary.json", summary.map_err(json_error)?.as_bytes())?;
        for (name, text) in &tables {
            out.write(name, text.as_bytes())?;
        }
        for files in models {
            for (name, bytes) in files? {
                out.write(&name, &bytes)?;
            }
        }
        for (names, u) in &self.uncertain_models {
            for (name, bytes) in uncertain_matrix_files(u, names).map_err(export_error)? {
                out.write(&name, &bytes)?;
            }
        }
        Ok(out.commit()?)
    }
}
