//! The workflow file (`workflow.toml`): which steps to run, on which data, with which settings.
//! Every key is optional; an unknown key is an error that names its line. `ambid init` writes a
//! commented example ([`EXAMPLE`]) that parses to the defaults.

use crate::io::table::ColumnRef;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The steps of the seed procedure, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize, PartialOrd, Ord)]
#[serde(rename_all = "snake_case")]
pub enum Step {
    /// Excitation design and comparison (PRBS, chirp, noise, multisine).
    Excitation,
    /// Excitation-amplitude study.
    Amplitude,
    /// Robust best linear approximation: noise and nonlinear-distortion variance against level.
    Bla,
    /// Operating-point study (bias current, air gap).
    OperatingPoint,
    /// Nonparametric FRF of the identification record, with quality measures.
    Frf,
    /// Order estimation: ARX loss/BIC over na × nb, resonance count.
    Order,
    /// ARX / OE / state-space fits of several orders and their comparison.
    Models,
    /// Pole-zero maps with near-cancellation checks.
    PoleZero,
    /// Time-domain validation on an independent record (with residual tests).
    Validation,
    /// Closed-loop reconstruction driven by a chirp position reference.
    Reconstruction,
    /// ISO 14839-3 sensitivity zone.
    Iso,
    /// The chosen model's uncertainty bound, its weight and the controller's robust stability
    /// (issue 23; not in the default list: `steps = [..., "uncertainty"]`).
    Uncertainty,
    /// Physical parameters by a gray-box fit (issue 23; not in the default list).
    Physical,
}

impl Step {
    /// The steps whose results this step reads: `frf` for `order` (its resonance count),
    /// `models` (the default frequency-domain fit of closed-loop data with r) and `iso` (the
    /// measured S); `models` for `pole_zero`, `validation` and `reconstruction`; `frf` and
    /// `models` for `physical`, and with them `amplitude` and `bla` for `uncertainty` (its
    /// terms (e) and (c)).
    pub fn prerequisites(self) -> &'static [Step] {
        match self {
            Step::Order | Step::Models | Step::Iso => &[Step::Frf],
            // the amplitude study gives the uncertainty its term (e): without it the bound
            // holds the best linear approximation at the identification level, not the
            // small-signal plant (docs/uncertainty.md, "Term (e) in the workflow")
            // and the robust BLA its term (c), the stochastic nonlinear distortion
            Step::Uncertainty => &[Step::Amplitude, Step::Bla, Step::Frf, Step::Models],
            Step::Physical => &[Step::Frf, Step::Models],
            Step::PoleZero | Step::Validation | Step::Reconstruction => &[Step::Models],
            _ => &[],
        }
    }

    /// `steps` with every prerequisite added (transitively), in the procedure's order, and the
    /// added steps each with the step that needed it.
    ///
    /// ```
    /// use ambid::workflow::config::Step;
    /// let (all, added) = Step::with_prerequisites(&[Step::Validation]);
    /// assert_eq!(all, vec![Step::Frf, Step::Models, Step::Validation]);
    /// assert_eq!(added, vec![(Step::Models, Step::Validation), (Step::Frf, Step::Models)]);
    /// ```
    pub fn with_prerequisites(steps: &[Step]) -> (Vec<Step>, Vec<(Step, Step)>) {
        let mut all: Vec<Step> = steps.to_vec();
        let mut added = Vec::new();
        let mut k = 0;
        while k < all.len() {
            for &p in all[k].prerequisites() {
                if !all.contains(&p) {
                    added.push((p, all[k]));
                    all.push(p);
                }
            }
            k += 1;
        }
        all.sort();
        all.dedup();
        (all, added)
    }

    /// The steps a workflow runs when it names none, in order (every step but the
    /// [`Step::OPTIONAL`] ones).
    pub const ALL: [Step; 11] = [
        Step::Excitation,
        Step::Amplitude,
        Step::Bla,
        Step::OperatingPoint,
        Step::Frf,
        Step::Order,
        Step::Models,
        Step::PoleZero,
        Step::Validation,
        Step::Reconstruction,
        Step::Iso,
    ];

    /// The name used in the workflow file.
    pub fn name(self) -> &'static str {
        match self {
            Step::Excitation => "excitation",
            Step::Amplitude => "amplitude",
            Step::Bla => "bla",
            Step::OperatingPoint => "operating_point",
            Step::Frf => "frf",
            Step::Order => "order",
            Step::Models => "models",
            Step::PoleZero => "pole_zero",
            Step::Validation => "validation",
            Step::Reconstruction => "reconstruction",
            Step::Iso => "iso",
            Step::Uncertainty => "uncertainty",
            Step::Physical => "physical",
        }
    }

    /// The steps that run only when named (they add seconds to the main job and need what the
    /// default steps give: the FRF and the chosen model).
    pub const OPTIONAL: [Step; 2] = [Step::Uncertainty, Step::Physical];
}

/// Where the data come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum SourceKind {
    /// The embedded AMB twin (default).
    #[default]
    Twin,
    /// Recorded files (`[data]`).
    Files,
}

/// A column given by name (`"y"`, `"#2"`) or 1-based position (`2`).
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum ColumnSpec {
    /// 1-based position.
    Index(usize),
    /// Name (or `#k`).
    Name(String),
}

impl ColumnSpec {
    /// The reader's column reference.
    pub fn to_ref(&self) -> ColumnRef {
        match self {
            ColumnSpec::Index(k) => ColumnRef::Index(*k),
            ColumnSpec::Name(s) => ColumnRef::parse(s),
        }
    }
}

/// A window bound in a workflow file: a number (seconds) or a string (`"2.5s"`, `"#50000"`).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum BoundSpec {
    /// Seconds after the first sample.
    Seconds(f64),
    /// `"2.5"`, `"2.5s"` or `"#50000"`.
    Text(String),
}

impl BoundSpec {
    /// The reader's bound, or what is wrong with it.
    pub fn to_bound(&self) -> Result<crate::io::time::Bound, String> {
        match self {
            BoundSpec::Seconds(v) => format!("{v}").parse(),
            BoundSpec::Text(t) => t.parse(),
        }
    }
}

/// The whole workflow file.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct WorkflowConfig {
    /// Report title.
    pub title: Option<String>,
    /// Base seed of every random choice (noise, excitation phases).
    pub seed: u64,
    /// Steps to run (default: all that the data allow).
    pub steps: Option<Vec<Step>>,
    /// Data source: `twin` or `files`.
    pub source: SourceKind,
    /// The twin (source = "twin").
    pub twin: TwinSection,
    /// Recorded files (source = "files").
    pub data: DataSection,
    /// Excitation design.
    pub excitation: ExcitationSection,
    /// Amplitude study.
    pub amplitude_study: AmplitudeSection,
    /// Robust BLA study.
    pub bla: BlaSection,
    /// Operating-point study.
    pub operating_point: OperatingSection,
    /// Nonparametric FRF.
    pub frf: FrfSection,
    /// Order estimation.
    pub order: OrderSection,
    /// Parametric models.
    pub models: ModelsSection,
    /// Validation.
    pub validation: ValidationSection,
    /// Closed-loop reconstruction.
    pub reconstruction: ReconstructionSection,
    /// ISO 14839-3 zone limits.
    pub iso: IsoSection,
    /// The whole machine (4 axes across speeds, [`MachineSection`]); with it `ambid run` runs
    /// the whole-machine procedure instead of the single-axis one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub machine: Option<MachineSection>,
    /// The drawing for the `physical` step with recorded files (on the twin its configuration
    /// gives it): `ambid_core::estimate::graybox::Drawing`'s keys, docs/physical.md.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub physical: Option<ambid_core::estimate::graybox::Drawing>,
}

impl Default for WorkflowConfig {
    fn default() -> Self {
        Self {
            title: None,
            seed: 1,
            steps: None,
            source: SourceKind::Twin,
            twin: TwinSection::default(),
            data: DataSection::default(),
            excitation: ExcitationSection::default(),
            amplitude_study: AmplitudeSection::default(),
            bla: BlaSection::default(),
            operating_point: OperatingSection::default(),
            frf: FrfSection::default(),
            order: OrderSection::default(),
            models: ModelsSection::default(),
            validation: ValidationSection::default(),
            reconstruction: ReconstructionSection::default(),
            iso: IsoSection::default(),
            machine: None,
            physical: None,
        }
    }
}

/// `[twin]`
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct TwinSection {
    /// `nonlinear` (default) or `linear` physics.
    pub mode: String,
    /// Sensor noise RMS \[µm\] (default: the twin configuration's `sensor.noise_rms_m`, 0.2 µm on the nominal rig).
    pub noise_rms_um: Option<f64>,
    /// A twin configuration file (`ambid config` writes one), relative to the workflow file.
    pub config: Option<PathBuf>,
}

impl Default for TwinSection {
    fn default() -> Self {
        Self {
            mode: "nonlinear".into(),
            noise_rms_um: None,
            config: None,
        }
    }
}

/// `[data]`: recorded files (paths relative to the workflow file).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct DataSection {
    /// The identification record.
    pub identification: Option<PathBuf>,
    /// An independent validation record (without it, the identification record is split).
    pub validation: Option<PathBuf>,
    /// A record without excitation under the same closed loop (output SNR).
    pub noise: Option<PathBuf>,
    /// A closed-loop record driven by a position reference (reconstruction).
    pub reconstruction: Option<PathBuf>,
    /// `.mat`/`.npz` variable to read.
    pub variable: Option<String>,
    /// Sample rate \[Hz\] (or give `time`).
    pub fs_hz: Option<f64>,
    /// Time column \[s\] (not given: a column named `t`, if the file has one and `fs_hz` is not given).
    pub time: Option<ColumnSpec>,
    /// Excitation added to the controller output (closed loop); not given: a column named `r`
    /// if the file has one, otherwise none (open-loop data).
    pub r: Option<ColumnSpec>,
    /// Plant input (controller output incl. excitation, or the open-loop input).
    pub u: ColumnSpec,
    /// Plant output (displacement).
    pub y: ColumnSpec,
    /// Coil current (optional; not given: a column named `i`, if any).
    pub i: Option<ColumnSpec>,
    /// Position reference (optional; not given: a column named `w`, if any).
    pub w: Option<ColumnSpec>,
    /// Factors that convert columns to SI units, e.g. `{ y = 1e-3 }` for mm.
    pub scale: std::collections::BTreeMap<String, f64>,
    /// Leading samples dropped (start-up, lift-off).
    pub skip_samples: usize,
    /// Start of the part of each record to use: seconds after its first sample (a number, or
    /// `"2.5s"`) or a 0-based sample index (`"#50000"`); TDMS and MAT v7.3 files read only that
    /// part (docs/data-files.md). `skip_samples` then counts from this start.
    pub from: Option<BoundSpec>,
    /// End (excluded) of the part of each record to use, as `from`.
    pub to: Option<BoundSpec>,
    /// `mean` (default), `linear` or `none`.
    pub detrend: String,
    /// Whose trend is removed: `estimation` (default: the estimation part's, from both parts),
    /// `record` (the whole identification record's, before splitting) or `each` (every record
    /// its own).
    pub detrend_scope: String,
    /// Fraction used for estimation when there is no validation file.
    pub split: f64,
    /// Samples per excitation period (periodic excitation), if known.
    pub period_samples: Option<usize>,
    /// Periods dropped at the start (transient).
    pub skip_periods: usize,
    /// The controller (TOML/JSON, see docs/formats.md); needed for the closed-loop steps.
    pub controller: Option<PathBuf>,
    /// Whether the data are closed-loop (default: true when `r` or `controller` is given).
    pub closed_loop: Option<bool>,
    /// Unit of the plant output in the report (e.g. `"m"`); not given: the report says "unit not
    /// given" (the twin's data are in m).
    pub y_unit: Option<String>,
    /// Unit of the plant input (e.g. `"A"`); not given: "unit not given" (the twin's: A).
    pub u_unit: Option<String>,
}

impl Default for DataSection {
    fn default() -> Self {
        Self {
            identification: None,
            validation: None,
            noise: None,
            reconstruction: None,
            variable: None,
            fs_hz: None,
            time: None,
            r: None,
            u: ColumnSpec::Name("u".into()),
            y: ColumnSpec::Name("y".into()),
            i: None,
            w: None,
            scale: Default::default(),
            skip_samples: 0,
            from: None,
            to: None,
            detrend: "mean".into(),
            detrend_scope: "estimation".into(),
            split: 0.5,
            period_samples: None,
            skip_periods: 1,
            controller: None,
            closed_loop: None,
            y_unit: None,
            u_unit: None,
        }
    }
}

/// `[excitation]`: the identification experiment (twin).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExcitationSection {
    /// `prbs` (default), `chirp`, `noise` or `multisine`.
    pub kind: String,
    /// PRBS register order n.
    pub prbs_order: u32,
    /// Samples per PRBS bit.
    pub samples_per_bit: usize,
    /// Periods.
    pub periods: usize,
    /// Level in % of i_sat; `None` takes the amplitude study's recommendation (10 % without it).
    pub amplitude_pct: Option<f64>,
    /// Lowest frequency of chirp/multisine \[Hz\].
    pub f_min_hz: f64,
    /// Highest frequency of chirp/multisine \[Hz\].
    pub f_max_hz: f64,
    /// Level of the four-signal comparison in % of i_sat.
    pub compare_level_pct: f64,
}

impl Default for ExcitationSection {
    fn default() -> Self {
        Self {
            kind: "prbs".into(),
            prbs_order: 10,
            samples_per_bit: 5,
            periods: 20,
            amplitude_pct: None,
            f_min_hz: 1.0,
            f_max_hz: 2000.0,
            compare_level_pct: 10.0,
        }
    }
}

/// `[amplitude_study]`
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct AmplitudeSection {
    /// Levels in % of i_sat (twin).
    pub levels_pct: Vec<f64>,
    /// Recorded files, one per level (source = "files").
    pub files: Vec<LevelFile>,
}

impl Default for AmplitudeSection {
    fn default() -> Self {
        Self {
            levels_pct: (1..=8).map(|k| 2.0 * k as f64).collect(),
            files: Vec::new(),
        }
    }
}

/// `[bla]`: the robust BLA study, on the twin at the amplitude study's levels (RMS, % of i_sat),
/// or from recorded realisations.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct BlaSection {
    /// Random-phase multisine realisations M (twin).
    pub realisations: usize,
    /// Periods P per realisation after one settling period (twin).
    pub periods: usize,
    /// Recorded realisations (source = "files"): one entry per record, several per level; each
    /// a whole number of periods of `[data] period_samples`, the first `[data] skip_periods`
    /// dropped.
    pub files: Vec<LevelFile>,
}

impl Default for BlaSection {
    fn default() -> Self {
        Self {
            realisations: 8,
            periods: 4,
            files: Vec::new(),
        }
    }
}

/// One recorded level of an amplitude study.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LevelFile {
    /// Level in % of i_sat.
    pub level_pct: f64,
    /// The record (same columns as `[data]`).
    pub path: PathBuf,
}

/// `[operating_point]`
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct OperatingSection {
    /// Bias-current change ± \[%\] (twin).
    pub bias_pct: f64,
    /// Air-gap change ± \[µm\] (twin).
    pub air_gap_um: f64,
    /// Recorded files, one per operating point, the nominal one first (source = "files").
    pub files: Vec<CaseFile>,
}

impl Default for OperatingSection {
    fn default() -> Self {
        Self {
            bias_pct: 20.0,
            air_gap_um: 10.0,
            files: Vec::new(),
        }
    }
}

/// One recorded operating point.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CaseFile {
    /// Label, e.g. `"bias-20%"`.
    pub name: String,
    /// The record (same columns as `[data]`).
    pub path: PathBuf,
    /// Its bias current \[A\] (for the `physical` step's magnet law; optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bias_current_a: Option<f64>,
    /// Its air-gap offset from the nominal record's gap \[µm\], positive = wider (for the
    /// `physical` step's magnet law; optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gap_offset_um: Option<f64>,
}

/// `[frf]`
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct FrfSection {
    /// Band of the estimate \[Hz\].
    pub band_hz: Option<[f64; 2]>,
    /// Band of the quality averages \[Hz\] (seed: 10–1000 Hz).
    pub quality_band_hz: Option<[f64; 2]>,
    /// `auto` (periodic when the period is known, else Welch), `periodic` or `welch`.
    pub method: String,
    /// Welch segment length.
    pub nperseg: Option<usize>,
}

impl Default for FrfSection {
    fn default() -> Self {
        Self {
            band_hz: None,
            quality_band_hz: None,
            method: "auto".into(),
            nperseg: None,
        }
    }
}

/// `[order]`
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct OrderSection {
    /// Largest na of the ARX scan.
    pub na_max: usize,
    /// Largest nb of the ARX scan.
    pub nb_max: usize,
    /// Input delay of the scan.
    pub nk: usize,
    /// Samples of the identification record used for the scan (0: all).
    pub max_samples: usize,
}

impl Default for OrderSection {
    fn default() -> Self {
        Self {
            na_max: 12,
            nb_max: 12,
            nk: 1,
            max_samples: 0,
        }
    }
}

/// `[models]`
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelsSection {
    /// Structures: `arx`, `oe`, `ss`.
    pub structures: Vec<ambid_core::lti::Structure>,
    /// Orders.
    pub orders: Vec<usize>,
    /// Input delay (polynomial models).
    pub nk: usize,
    /// Fit band \[Hz\] (FRF fits; default: the FRF band).
    pub band_hz: Option<[f64; 2]>,
    /// `frf` (fit to the FRF; default in closed loop with an excitation) or `time` (fit to the
    /// time record; default otherwise).
    pub domain: Option<String>,
    /// FRF weights: `model` (default: the variance at the model, sample maximum likelihood;
    /// [`frf_weights`](crate::stage::frf_weights)), `variance` (at the data),
    /// `coherence` or `uniform`.
    pub weights: String,
    /// Maximum iterations of the iterative fits.
    pub max_iterations: usize,
    /// Criterion of the time-domain state-space fits: `auto` (default: as `ambid fit
    /// --structure ss`, the simulation focus for a stable subspace model, else prediction; on
    /// closed-loop records, whose time-domain fits go from u to y, always prediction, since output
    /// error from a feedback signal is biased), `prediction` or `simulation`. The polynomial OE
    /// fits use the prediction criterion unless `simulation` is given.
    pub focus: String,
    /// How the model is chosen: `validation` (best validation fit), `bic` or `frf` (smallest
    /// relative FRF error).
    pub select: String,
    /// Number of unstable plant poles of FRF fits (default: the Nyquist count of the measured
    /// loop with the controller; unconstrained without a controller).
    pub unstable_poles: Option<usize>,
}

impl Default for ModelsSection {
    fn default() -> Self {
        Self {
            structures: ambid_core::lti::Structure::FRF.to_vec(),
            orders: vec![6, 7, 8, 9],
            nk: 1,
            band_hz: None,
            domain: None,
            weights: "model".into(),
            max_iterations: 100,
            focus: "auto".into(),
            select: "validation".into(),
            unstable_poles: None,
        }
    }
}

/// `[validation]`
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct ValidationSection {
    /// Excitation of the independent twin record: `noise` (default), `prbs`, `chirp`, `multisine`.
    pub excitation: String,
    /// Its level in % of i_sat (default: the identification level).
    pub amplitude_pct: Option<f64>,
    /// Leading samples excluded.
    pub skip: usize,
    /// Largest lag of the residual tests; unset (default): from the chosen model's dynamics
    /// (`validation::residual_lags`, docs/validation.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lags: Option<usize>,
    /// Windows of the windowed fit.
    pub windows: usize,
    /// How the simulated loop starts: `"estimate"` (default; the initial state that best explains
    /// the record) or `"zero"` (from rest).
    pub x0: ambid_core::validate::predict::InitialState,
}

impl Default for ValidationSection {
    fn default() -> Self {
        Self {
            excitation: "noise".into(),
            amplitude_pct: None,
            skip: 2000,
            lags: None,
            windows: 20,
            x0: ambid_core::validate::predict::InitialState::Estimate,
        }
    }
}

/// `[reconstruction]`: the chirp position reference (twin).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReconstructionSection {
    /// Amplitude \[µm\].
    pub amplitude_um: f64,
    /// Duration \[s\].
    pub duration_s: f64,
    /// Start frequency \[Hz\].
    pub f0_hz: f64,
    /// End frequency \[Hz\].
    pub f1_hz: f64,
}

impl Default for ReconstructionSection {
    fn default() -> Self {
        Self {
            amplitude_um: 5.0,
            duration_s: 2.0,
            f0_hz: 1.0,
            f1_hz: 1000.0,
        }
    }
}

/// `[iso]`: zone limits on the peak sensitivity.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct IsoSection {
    /// A/B limit (ISO 14839-3: 3, i.e. 9.5 dB).
    pub a: f64,
    /// B/C limit (4, 12 dB).
    pub b: f64,
    /// C/D limit (5, 14 dB).
    pub c: f64,
}

impl Default for IsoSection {
    fn default() -> Self {
        let z = ambid_core::validate::iso::IsoZones::default();
        Self {
            a: z.a,
            b: z.b,
            c: z.c,
        }
    }
}

pub use crate::config_machine::{
    MachineFile, MachineSection, DEFAULT_MACHINE_AMPLITUDE_LEVELS_PCT,
};

/// A workflow file that could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// Cannot read the file.
    #[error("{path}: cannot read the workflow file ({reason})")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// TOML syntax, an unknown key or a wrong type (the message has the line).
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message with line and column.
        message: String,
    },
    /// A value that is not allowed.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong and what to do.
        message: String,
    },
}

impl WorkflowConfig {
    /// Parses a workflow file's text; `path` is used in messages.
    ///
    /// # Errors
    /// [`ConfigError::Parse`] with the line of the offending key or value.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let cfg: WorkflowConfig = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| {
                text.as_bytes()[..s.start.min(text.len())]
                    .iter()
                    .filter(|b| **b == b'\n')
                    .count()
                    + 1
            });
            let msg = e.message().trim().to_string();
            ConfigError::Parse {
                path: path.to_path_buf(),
                message: match line {
                    Some(l) => format!("line {l}: {msg}"),
                    None => msg,
                },
            }
        })?;
        cfg.check(path)?;
        Ok(cfg)
    }

    /// Reads a workflow file.
    ///
    /// # Errors
    /// As [`WorkflowConfig::from_toml_str`], and [`ConfigError::Read`].
    pub fn from_path(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError::Read {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        Self::from_toml_str(&text, path)
    }

    /// Checks every value of the file on its own (the values that need the records:
    /// [`WorkflowConfig::check_record`]); [`WorkflowConfig::from_toml_str`] calls it, and
    /// `ambid run` again after `--steps` replaced the file's steps.
    ///
    /// # Errors
    /// [`ConfigError::Invalid`] naming the key and what to write instead.
    pub fn check(&self, path: &Path) -> Result<(), ConfigError> {
        let bad = |message: String| ConfigError::Invalid {
            path: path.to_path_buf(),
            message,
        };
        let one_of = |what: &str, v: &str, allowed: &[&str]| {
            if allowed.contains(&v) {
                Ok(())
            } else {
                Err(bad(format!(
                    "{what} = \"{v}\" is not one of {}",
                    allowed
                        .iter()
                        .map(|a| format!("\"{a}\""))
                        .collect::<Vec<_>>()
                        .join(", ")
                )))
            }
        };
        one_of("twin.mode", &self.twin.mode, &["linear", "nonlinear"])?;
        one_of(
            "excitation.kind",
            &self.excitation.kind,
            &["prbs", "chirp", "noise", "multisine"],
        )?;
        one_of(
            "validation.excitation",
            &self.validation.excitation,
            &["prbs", "chirp", "noise", "multisine"],
        )?;
        one_of(
            "frf.method",
            &self.frf.method,
            &["auto", "periodic", "welch"],
        )?;
        one_of(
            "data.detrend",
            &self.data.detrend,
            &["mean", "linear", "none"],
        )?;
        one_of(
            "data.detrend_scope",
            &self.data.detrend_scope,
            &["estimation", "record", "each"],
        )?;
        one_of(
            "models.weights",
            &self.models.weights,
            &["model", "variance", "coherence", "uniform"],
        )?;
        one_of(
            "models.select",
            &self.models.select,
            &["validation", "bic", "frf"],
        )?;
        one_of(
            "models.focus",
            &self.models.focus,
            &["auto", "prediction", "simulation"],
        )?;
        if let Some(d) = &self.models.domain {
            one_of("models.domain", d, &["frf", "time"])?;
        }
        if let Some(s) = self.models.structures.iter().find(|s| !s.fits_frf()) {
            return Err(bad(format!(
                "models.structures = \"{s}\" is not available; use \"arx\", \"oe\" or \"ss\""
            )));
        }
        if self.bla.realisations < 2 || self.bla.periods < 2 {
            return Err(bad(format!(
                "bla.realisations = {} and bla.periods = {} must both be at least 2 (the noise and the \
                 nonlinear variance need a spread over periods and over realisations)",
                self.bla.realisations, self.bla.periods
            )));
        }
        if self.models.orders.is_empty() || self.models.orders.contains(&0) {
            return Err(bad(
                "models.orders must list orders ≥ 1, e.g. [6, 7, 8, 9]".into()
            ));
        }
        if self.models.structures.is_empty() {
            return Err(bad(
                "models.structures must list at least one of \"arx\", \"oe\", \"ss\"".into(),
            ));
        }
        if !(self.data.split > 0.0 && self.data.split < 1.0) {
            return Err(bad(format!(
                "data.split = {} must be between 0 and 1 (the estimation fraction, e.g. 0.5)",
                fmt_num(self.data.split)
            )));
        }
        for (k, v) in &self.data.scale {
            if !(v.is_finite() && *v != 0.0) {
                return Err(bad(format!(
                    "data.scale.{k} = {} must be a finite, non-zero factor",
                    fmt_num(*v)
                )));
            }
        }
        for (what, b) in [
            ("frf.band_hz", self.frf.band_hz),
            ("frf.quality_band_hz", self.frf.quality_band_hz),
            ("models.band_hz", self.models.band_hz),
        ] {
            if let Some([a, b]) = b {
                if !(a.is_finite() && b.is_finite() && 0.0 <= a && a < b) {
                    return Err(bad(format!(
                        "{what} = [{a}, {b}] must be an increasing pair of frequencies in Hz"
                    )));
                }
            }
        }
        if let Some(l) = self
            .amplitude_study
            .levels_pct
            .iter()
            .find(|l| !(l.is_finite() && **l > 0.0 && **l <= 100.0))
        {
            return Err(bad(format!(
                "amplitude_study.levels_pct has {}, but every level must be in (0, 100] % of i_sat, e.g. levels_pct = [2, 4, 6, 8]",
                fmt_num(*l)
            )));
        }
        if self.amplitude_study.levels_pct.is_empty()
            && self.source == SourceKind::Twin
            && self
                .steps()
                .iter()
                .any(|s| matches!(s, Step::Amplitude | Step::Bla))
        {
            return Err(bad(
                "amplitude_study.levels_pct = [] lists no level; give at least one level in % of i_sat (e.g. levels_pct = [2, 4, 6, 8]), or remove the key for the default 2 … 16 %, or leave \"amplitude\" out of `steps`".into(),
            ));
        }
        self.check_values(path)?;
        if let Some(m) = &self.machine {
            return m.check(path, self.steps.is_some());
        }
        if self.source == SourceKind::Files && self.data.identification.is_none() {
            return Err(bad(
                "source = \"files\" needs [data] identification = \"path/to/record.csv\"".into(),
            ));
        }
        Ok(())
    }

    /// The checks of numeric values that [`WorkflowConfig::check`] does not cover: every value a
    /// step would later refuse (or divide by) is refused here, before any step runs, with the key
    /// and what to write instead.
    fn check_values(&self, path: &Path) -> Result<(), ConfigError> {
        let bad = |message: String| ConfigError::Invalid {
            path: path.to_path_buf(),
            message,
        };
        if let Some(p) = self.data.period_samples {
            if p < 2 {
                return Err(bad(format!(
                    "data.period_samples = {p} must be at least 2 (the samples per excitation period, e.g. 5115 for the seed PRBS with n = 10 and 5 samples per bit); remove the key if the excitation is not periodic"
                )));
            }
        }
        if let Some(n) = self.frf.nperseg {
            if n < MIN_NPERSEG {
                return Err(bad(format!(
                    "frf.nperseg = {n} is too short: a Welch segment needs at least {MIN_NPERSEG} samples; give e.g. nperseg = 4096, or remove the key to derive it from the record length"
                )));
            }
        }
        let iso = &self.iso;
        if !(iso.a.is_finite()
            && iso.b.is_finite()
            && iso.c.is_finite()
            && 1.0 < iso.a
            && iso.a < iso.b
            && iso.b < iso.c)
        {
            return Err(bad(format!(
                "[iso] a = {}, b = {}, c = {} must increase above 1 (peak-sensitivity limits A/B < B/C < C/D; ISO 14839-3: a = 3, b = 4, c = 5)",
                fmt_num(iso.a),
                fmt_num(iso.b),
                fmt_num(iso.c)
            )));
        }
        if let Some(&o) = self.models.orders.iter().find(|&&o| o > MAX_MODEL_ORDER) {
            return Err(bad(format!(
                "models.orders has {o}, above the largest order ambid fits, {MAX_MODEL_ORDER}; give orders such as [6, 7, 8, 9] (two states per rotor mode in the band)"
            )));
        }
        for (key, v) in [
            ("order.na_max", self.order.na_max),
            ("order.nb_max", self.order.nb_max),
        ] {
            if v == 0 || v > MAX_MODEL_ORDER {
                return Err(bad(format!(
                    "{key} = {v} must be between 1 and {MAX_MODEL_ORDER}, e.g. 12"
                )));
            }
        }
        let ex = &self.excitation;
        if !(ex.f_min_hz.is_finite()
            && ex.f_max_hz.is_finite()
            && 0.0 < ex.f_min_hz
            && ex.f_min_hz < ex.f_max_hz)
        {
            return Err(bad(format!(
                "excitation.f_min_hz = {} and f_max_hz = {} must be an increasing pair of positive frequencies in Hz, e.g. 1 and 2000",
                fmt_num(ex.f_min_hz),
                fmt_num(ex.f_max_hz)
            )));
        }
        if !(2..=MAX_PRBS_ORDER).contains(&ex.prbs_order) {
            return Err(bad(format!(
                "excitation.prbs_order = {} must be between 2 and {MAX_PRBS_ORDER} (period 2^n − 1 bits), e.g. 10",
                ex.prbs_order
            )));
        }
        for (key, v) in [
            ("excitation.samples_per_bit", ex.samples_per_bit),
            ("excitation.periods", ex.periods),
            ("validation.windows", self.validation.windows),
            ("validation.lags", self.validation.lags.unwrap_or(1)),
        ] {
            if v == 0 {
                return Err(bad(format!("{key} = 0 must be at least 1")));
            }
        }
        for (key, v) in [
            ("excitation.amplitude_pct", ex.amplitude_pct),
            ("validation.amplitude_pct", self.validation.amplitude_pct),
            ("excitation.compare_level_pct", Some(ex.compare_level_pct)),
        ] {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0 && v <= 100.0) {
                    return Err(bad(format!(
                        "{key} = {} must be in (0, 100] % of i_sat, e.g. 10",
                        fmt_num(v)
                    )));
                }
            }
        }
        let rc = &self.reconstruction;
        if !(rc.f0_hz.is_finite() && rc.f1_hz.is_finite() && 0.0 < rc.f0_hz && rc.f0_hz < rc.f1_hz)
        {
            return Err(bad(format!(
                "reconstruction.f0_hz = {} and f1_hz = {} must be an increasing pair of positive frequencies in Hz, e.g. 1 and 1000",
                fmt_num(rc.f0_hz),
                fmt_num(rc.f1_hz)
            )));
        }
        for (key, v) in [
            ("reconstruction.duration_s", rc.duration_s),
            ("reconstruction.amplitude_um", rc.amplitude_um),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(format!(
                    "{key} = {} must be a positive number",
                    fmt_num(v)
                )));
            }
        }
        if let Some(v) = self.data.fs_hz {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(format!(
                    "data.fs_hz = {} must be a positive sample rate in Hz, e.g. 20000, or remove it and give a time column",
                    fmt_num(v)
                )));
            }
        }
        for (l, f) in self
            .amplitude_study
            .files
            .iter()
            .map(|f| (f.level_pct, "amplitude_study.files"))
            .chain(self.bla.files.iter().map(|f| (f.level_pct, "bla.files")))
        {
            if !(l.is_finite() && l > 0.0 && l <= 100.0) {
                return Err(bad(format!(
                    "{f}: level_pct = {} must be in (0, 100] % of i_sat",
                    fmt_num(l)
                )));
            }
        }
        Ok(())
    }

    /// Checks against the records once they are read, before any step runs: an explicitly
    /// periodic FRF needs at least two periods of `[data] period_samples` in the estimation
    /// record, `frf.nperseg` must fit in it, and (when the models step runs) every model order
    /// must leave at least
    /// [`SAMPLES_PER_PARAMETER`] samples per parameter. `n` is the estimation record's length.
    ///
    /// # Errors
    /// [`ConfigError::Invalid`] naming the key and the value to write instead.
    pub fn check_record(&self, path: &Path, n: usize) -> Result<(), ConfigError> {
        let bad = |message: String| ConfigError::Invalid {
            path: path.to_path_buf(),
            message,
        };
        if let Some(p) = self.data.period_samples {
            let need = p.saturating_mul(2);
            if self.frf.method == "periodic" && n < need {
                return Err(bad(format!(
                    "frf.method = \"periodic\" with data.period_samples = {p} needs at least 2 periods ({need} samples), but the estimation record has {n} samples; correct period_samples, or set frf.method = \"welch\""
                )));
            }
        }
        if let Some(k) = self.frf.nperseg {
            if k > n {
                return Err(bad(format!(
                    "frf.nperseg = {k} is longer than the estimation record ({n} samples); give at most {n}, or remove the key to derive it from the record length"
                )));
            }
        }
        let cap = n / SAMPLES_PER_PARAMETER;
        let fits = self.steps().contains(&Step::Models);
        if let Some(&o) = self
            .models
            .orders
            .iter()
            .find(|&&o| fits && parameters_of_order(o) > cap)
        {
            return Err(bad(format!(
                "models.orders has {o}: a model of order {o} has about {} parameters, but the estimation record ({n} samples) supports at most {cap} ({SAMPLES_PER_PARAMETER} samples per parameter); give smaller orders or a longer record",
                parameters_of_order(o)
            )));
        }
        Ok(())
    }

    /// The steps to run, in order.
    pub fn steps(&self) -> Vec<Step> {
        let mut s = self.steps.clone().unwrap_or_else(|| Step::ALL.to_vec());
        s.sort();
        s.dedup();
        s
    }
}

/// The shortest Welch segment `frf.nperseg` accepts: a segment of fewer samples resolves
/// fewer than 4 frequency lines.
pub const MIN_NPERSEG: usize = 8;

/// The largest model order (`models.orders`, `order.na_max`, `order.nb_max`) a workflow accepts:
/// an AMB rotor needs two states per mode in the band, and 100 states is 50 modes, far more than
/// any measured band holds; above it the fits and the pole-zero analysis grow as order³.
pub const MAX_MODEL_ORDER: usize = 100;

/// The largest PRBS register order of the twin's excitation (a period of 2²⁰ − 1 bits).
pub const MAX_PRBS_ORDER: u32 = 20;

/// Samples the estimation record must hold per model parameter (rule of thumb of system
/// identification: the parameter variance is ∝ parameters / samples, and with fewer than ten
/// samples per parameter the estimate is dominated by noise).
pub const SAMPLES_PER_PARAMETER: usize = 10;

/// The parameter count of a model of order `n` as the workflow fits it: `na = nb = n`
/// polynomial coefficients (ARX, OE), and for a state-space model of order `n` the
/// observable canonical form's `2n + 1`.
pub fn parameters_of_order(n: usize) -> usize {
    n.saturating_mul(2).saturating_add(1)
}

/// A number in a message, compact whatever its size: up to 6 decimals without trailing zeros
/// for magnitudes in [1e-4, 1e6) (`0.5`, `20000`), else `{:.6e}` (`1.000000e300`).
pub(crate) fn fmt_num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let a = v.abs();
    if (1e-4..1e6).contains(&a) {
        let s = format!("{v:.6}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    } else {
        format!("{v:.6e}")
    }
}

/// The commented example written by `ambid init` (it parses to the defaults).
pub const EXAMPLE: &str = include_str!("workflow/example.toml");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_structures_are_the_one_structure_type() {
        let p = Path::new("wf.toml");
        let cfg =
            WorkflowConfig::from_toml_str("[models]\nstructures = [\"oe\", \"ss\"]\n", p).unwrap();
        assert_eq!(
            cfg.models.structures,
            [
                ambid_core::lti::Structure::Oe,
                ambid_core::lti::Structure::Ss
            ]
        );
        // a structure the FRF fits do not take is refused by name
        let e = WorkflowConfig::from_toml_str("[models]\nstructures = [\"armax\"]\n", p)
            .and_then(|c| c.check(p).map(|()| c))
            .unwrap_err();
        assert!(e.to_string().contains("armax"), "{e}");
        // an unknown name is refused at parsing, naming it
        let e =
            WorkflowConfig::from_toml_str("[models]\nstructures = [\"narx\"]\n", p).unwrap_err();
        assert!(e.to_string().contains("narx"), "{e}");
    }
}
