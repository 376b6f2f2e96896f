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

pub mod config;
mod data;
pub mod figures;
mod steps_frf;
mod steps_models;
mod steps_signal;
mod steps_validate;
mod summary;

pub use self::config::{ConfigError, Step, WorkflowConfig};
use self::data::Recording;
use crate::io::output::{OutputDir, OutputError};
use crate::report::{Block, NoteKind, Report, Section};
use ambid_core::lti::{PolyModel, StateSpace};
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};
use std::time::Instant;

pub use crate::error::FailureClass;

/// The only fields of `ambid run`'s outputs that differ between two runs of the same workflow:
/// the wall-clock step timings, `summary.json`'s object `"timing"` (keys `timing.<step>_s`,
/// `timing.total_s`), which appear again as the `timing.*` rows of the summary table in
/// `report.html` and `tables/summary.csv`. Every other byte of every output is reproduced
/// exactly (docs/workflow.md, "Outputs").
pub const TIMING_KEY: &str = "timing";

/// A workflow failure: its class and the error chain.
#[derive(Debug)]
pub struct Failure {
    /// The class (exit code).
    pub class: FailureClass,
    /// What went wrong.
    pub error: anyhow::Error,
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:#}", self.error)
    }
}

impl std::error::Error for Failure {}

impl From<ConfigError> for Failure {
    fn from(e: ConfigError) -> Self {
        Failure {
            class: FailureClass::Config,
            error: e.into(),
        }
    }
}

impl From<OutputError> for Failure {
    fn from(e: OutputError) -> Self {
        Failure {
            class: FailureClass::Output,
            error: e.into(),
        }
    }
}

/// An input-data failure (exit 3): a file that is missing, unreadable or malformed.
pub fn input(e: impl Into<anyhow::Error>) -> Failure {
    Failure {
        class: FailureClass::Input,
        error: e.into(),
    }
}

/// A computation failure (exit 4).
pub fn computation(e: impl Into<anyhow::Error>) -> Failure {
    Failure {
        class: FailureClass::Computation,
        error: e.into(),
    }
}

/// A usage failure (exit 2): a command-line option value or combination that is refused.
pub fn usage(e: impl Into<anyhow::Error>) -> Failure {
    Failure {
        class: FailureClass::Config,
        error: e.into(),
    }
}

/// An output failure (exit 5): a file or directory that cannot be written.
pub fn output(e: impl Into<anyhow::Error>) -> Failure {
    Failure {
        class: FailureClass::Output,
        error: e.into(),
    }
}

/// The process exit code of a command's error: the class of the outermost classified error in
/// its chain — a [`Failure`], a [`ConfigError`] (2), a data-file error (3), an
/// [`OutputError`] (5), an invalid argument refused by `ambid_core` (2), a non-finite sample
/// found by `ambid_core` or `ambid_twin` (3), a twin configuration that does not parse (3), or
/// another `ambid_core`/`ambid_twin` error (4) — and 1 when nothing in the chain has a class.
///
/// ```
/// use ambid::workflow::{exit_code, usage};
/// let e: anyhow::Error = usage(anyhow::anyhow!("--order must be at least 1")).into();
/// assert_eq!(exit_code(&e.context("fit")), 2);
/// assert_eq!(exit_code(&anyhow::anyhow!("something else")), 1);
/// ```
pub fn exit_code(e: &anyhow::Error) -> i32 {
    for c in e.chain() {
        if let Some(ae) = c.downcast_ref::<crate::error::Error>() {
            return ae.exit_code();
        }
        if let Some(f) = c.downcast_ref::<Failure>() {
            return f.class.exit_code();
        }
        if c.is::<ConfigError>() {
            return FailureClass::Config.exit_code();
        }
        if c.is::<crate::io::table::DataFileError>() {
            return FailureClass::Input.exit_code();
        }
        if c.is::<OutputError>() {
            return FailureClass::Output.exit_code();
        }
        if let Some(ce) = c.downcast_ref::<ambid_core::Error>() {
            return match ce {
                ambid_core::Error::NonFinite { .. } => FailureClass::Input.exit_code(),
                // an argument (an option's value) the computation refuses; the message names it
                ambid_core::Error::InvalidArgument { .. } => FailureClass::Config.exit_code(),
                _ => FailureClass::Computation.exit_code(),
            };
        }
        if let Some(te) = c.downcast_ref::<ambid_twin::TwinError>() {
            return match te {
                ambid_twin::TwinError::Toml(_) | ambid_twin::TwinError::NonFinite { .. } => {
                    FailureClass::Input.exit_code()
                }
                _ => FailureClass::Computation.exit_code(),
            };
        }
    }
    1
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

/// An identified model kept for export.
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
    /// Headline numbers (written as `summary.json`; the report's first section states the answer
    /// from them and links the file).
    pub summary: Value,
    /// Models to export (JSON, `.m`, `.mat`, `.npz`).
    pub models: Vec<ModelOut>,
    /// Time per step.
    pub timings: Vec<StepTime>,
}

/// State shared by the steps.
pub(crate) struct Ctx<'a> {
    pub cfg: &'a WorkflowConfig,
    pub base: PathBuf,
    pub sections: Vec<Section>,
    pub summary: Map<String, Value>,
    pub models: Vec<ModelOut>,
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
    /// FRF analysis of the identification record.
    pub frf: Option<crate::analysis::FrfAnalysis>,
    /// Controller (closed loop).
    pub controller: Option<crate::io::ControllerModel>,
    /// Candidate models.
    pub candidates: Vec<steps_models::Candidate>,
    /// Index of the chosen candidate.
    pub chosen: Option<usize>,
    /// Validation outcome of the chosen model.
    pub validation: Option<crate::validation::ValidationOutcome>,
}

impl Ctx<'_> {
    /// Records a headline number (also shown in the report's summary table).
    pub fn put(&mut self, key: &str, v: impl Into<Value>) {
        insert_path(&mut self.summary, key, v.into());
    }

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
}

fn insert_path(map: &mut Map<String, Value>, key: &str, v: Value) {
    match key.split_once('.') {
        Some((head, rest)) => {
            let e = map
                .entry(head.to_string())
                .or_insert_with(|| Value::Object(Map::new()));
            if !e.is_object() {
                *e = Value::Object(Map::new());
            }
            if let Value::Object(m) = e {
                insert_path(m, rest, v);
            }
        }
        None => {
            map.insert(key.to_string(), v);
        }
    }
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
/// A [`Failure`] with its class: input files missing or malformed, or a computation that failed.
pub fn run(cfg: &WorkflowConfig, base: &Path, progress: &mut Progress) -> Result<Outcome, Failure> {
    let steps = cfg.steps();
    progress.total = steps.len() + 1;
    let mut timings = Vec::new();
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
        sections: Vec::new(),
        summary: Map::new(),
        models: Vec::new(),
        twin: prepared.twin,
        ident: prepared.ident,
        valid: prepared.valid,
        level_frac: None,
        seed_study: None,
        frf: None,
        controller: prepared.controller,
        candidates: Vec::new(),
        chosen: None,
        validation: None,
    };
    let mut data_section = data::describe(&mut ctx);
    data_section.blocks.extend(fallback_note);
    sections_prelude.push(data_section);
    let dt = t0.elapsed().as_secs_f64();
    progress.finish("data", dt, "done");
    timings.push(StepTime {
        step: "data".into(),
        seconds: dt,
        status: "done".into(),
    });
    for step in steps {
        let t = Instant::now();
        progress.start(step.name());
        let n_before = ctx.sections.len();
        let status = match step {
            Step::Excitation => steps_signal::excitation(&mut ctx),
            Step::Amplitude => steps_signal::amplitude(&mut ctx),
            Step::Bla => steps_signal::bla(&mut ctx),
            Step::OperatingPoint => steps_signal::operating_point(&mut ctx),
            Step::Frf => steps_frf::frf(&mut ctx),
            Step::Order => steps_frf::order(&mut ctx),
            Step::Models => steps_models::models(&mut ctx),
            Step::PoleZero => steps_models::pole_zero(&mut ctx),
            Step::Validation => steps_validate::validation(&mut ctx),
            Step::Reconstruction => steps_validate::reconstruction(&mut ctx),
            Step::Iso => steps_validate::iso(&mut ctx),
        }?;
        let dt = t.elapsed().as_secs_f64();
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
        progress.finish(step.name(), dt, &status);
        timings.push(StepTime {
            step: step.name().into(),
            seconds: dt,
            status,
        });
    }
    // the per-step timings are part of the summary and of the report
    let total: f64 = timings.iter().map(|t| t.seconds).sum();
    ctx.put(&format!("{TIMING_KEY}.total_s"), total);
    for t in &timings {
        ctx.put(&format!("{TIMING_KEY}.{}_s", t.step), t.seconds);
    }
    let summary = Value::Object(ctx.summary.clone());
    let mut sections = sections_prelude;
    sections.append(&mut ctx.sections);
    // the answer first; every number stays in summary.json (linked, no longer dumped here)
    sections.insert(0, summary::section(&summary, &sections, &ctx));
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
        summary,
        models: ctx.models,
        timings,
    })
}

/// What a step did.
pub(crate) enum StepStatus {
    Done,
    Skipped(String),
}

impl Outcome {
    /// Writes `report.html`, `summary.json`, `figures/<id>.csv`, `tables/<id>.csv` and
    /// `models/<name>.{json,m,mat,npz}` into `dir`, atomically: everything goes to a temporary
    /// directory beside `dir` that is renamed into place at the end, so a failure leaves nothing
    /// half-written. An existing `dir` is replaced only with `force`.
    ///
    /// # Errors
    /// [`FailureClass::Output`] failures.
    pub fn write(&self, dir: &Path, force: bool) -> Result<Vec<PathBuf>, Failure> {
        use crate::io::export::{mat_bytes, matlab_script, npz_bytes, ExportModel, ExportNames};
        use crate::io::model::{polynomial_json, state_space_json};
        let out = OutputDir::create(dir, force)?;
        let output = |e: anyhow::Error| Failure {
            class: FailureClass::Output,
            error: e,
        };
        out.write("report.html", self.report.to_html().as_bytes())?;
        out.write(
            "summary.json",
            serde_json::to_string_pretty(&self.summary)
                .map_err(|e| output(e.into()))?
                .as_bytes(),
        )?;
        for s in &self.report.sections {
            for b in &s.blocks {
                match b {
                    Block::Figure(f) => {
                        out.write(&format!("figures/{}.csv", f.id), f.to_csv().as_bytes())?
                    }
                    Block::Table(t) => {
                        out.write(&format!("tables/{}.csv", t.id), t.to_csv().as_bytes())?
                    }
                    _ => {}
                }
            }
        }
        for m in &self.models {
            let names = ExportNames {
                name: m.name.clone(),
                input: "u".into(),
                output: "y".into(),
                noise_variance: m.meta["noise_variance"].as_f64(),
            };
            let (json, em) = match &m.poly {
                Some(p) => (
                    polynomial_json(p, "u", "y", m.meta.clone()),
                    ExportModel::Poly(p),
                ),
                None => (
                    state_space_json(&m.ss, "u", "y", m.meta.clone()),
                    ExportModel::StateSpace(&m.ss, m.kalman.as_deref()),
                ),
            };
            let text = serde_json::to_string_pretty(&json).map_err(|e| output(e.into()))?;
            out.write(&format!("models/{}.json", m.name), text.as_bytes())?;
            out.write(
                &format!("models/{}.m", m.name),
                matlab_script(em, &names)
                    .map_err(|e| output(e.into()))?
                    .as_bytes(),
            )?;
            out.write(
                &format!("models/{}.mat", m.name),
                &mat_bytes(em, &names).map_err(|e| output(e.into()))?,
            )?;
            out.write(
                &format!("models/{}.npz", m.name),
                &npz_bytes(em, &names).map_err(|e| output(e.into()))?,
            )?;
        }
        Ok(out.commit()?)
    }
}
