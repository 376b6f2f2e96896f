//! Controller files: the controller $C$ of $u = C(q)(w - y) + r$ for the indirect method and for
//! reconstructing the loop (see `docs/formats.md`, "Controllers").
//!
//! A file is TOML (`.toml`) or JSON (`.json`) and holds one of three forms, chosen by `kind`:
//!
//! ```toml
//! kind = "pid"   # a continuous filtered PID and how it is discretised (ambid_core::lti::PidSpec)
//! kp = 21000.0                 # A/m
//! integral_corner_hz = 5.0     # or ki = 659734.457… (A/(m·s)); Ki = Kp·2π·f_i; 0: no integrator
//! kd = 14.0                    # A·s/m; 0: no derivative
//! derivative_cutoff_hz = 4000.0  # required when kd ≠ 0, below fs/2
//! lowpass_hz = 5000.0          # optional output low-pass, below fs/2
//! fs_hz = 20000.0              # or ts = 5e-5 (s)
//! method = "tustin"            # or "zoh"
//! prewarp_hz = 1000.0          # optional, tustin only
//! delay_samples = 0            # optional computation delay q^-d (default 0: ambid puts it in the plant)
//! ```
//! ```toml
//! kind = "tf"    # discrete transfer function, ascending powers of q^-1
//! ts = 5e-5      # or fs_hz
//! num = [1.0, -0.5]
//! den = [1.0, -0.9]
//! ```
//! ```toml
//! kind = "ss"    # discrete state space x+ = A x + B e, u = C x + D e (SISO)
//! ts = 5e-5      # or fs_hz
//! a = [[0.9]]
//! b = [[1.0]]
//! c = [[0.1]]
//! d = [[2.0]]
//! ```
//! Every form accepts an optional `description` string. Unknown keys, a missing key, a
//! non-finite number, a non-SISO model and inconsistent sizes are errors that name the key.
//!
//! # Example
//! ```
//! use ambid::io::controller::{controller_toml_from_twin, parse_controller_str, ControllerFormat};
//! use ambid_twin::{Twin, TwinConfig};
//! let cfg = TwinConfig::default();
//! let text = controller_toml_from_twin(&cfg);
//! let c = parse_controller_str(&text, ControllerFormat::Toml).unwrap();
//! let twin = Twin::new(cfg).unwrap();
//! let (f, want) = (1234.0, twin.controller_frf(&[1234.0]).unwrap()[0]);
//! let got = c.freq_response(&[f]).unwrap()[0];
//! assert!((got - want).norm() < 1e-12 * want.norm());
//! c.check_ts(twin.ts()).unwrap();
//! assert!(c.check_ts(1e-4).unwrap_err().to_string().contains("rediscretise"));
//! ```

use crate::error::FailureClass;
use crate::error::{Context, Error, Result};
use ambid_core::c64;
use ambid_core::lti::{Discretisation, PidSpec, StateSpace, TransferFunction};
use ambid_twin::TwinConfig;
use faer::Mat;
use serde::de::DeserializeOwned;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The syntax of a controller file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerFormat {
    /// TOML (`.toml`).
    Toml,
    /// JSON (`.json`).
    Json,
}

impl ControllerFormat {
    /// The format from the file extension (`.toml` or `.json`, case-insensitive).
    ///
    /// # Errors
    /// Any other or no extension.
    ///
    /// # Example
    /// ```
    /// use ambid::io::controller::ControllerFormat;
    /// use std::path::Path;
    /// assert_eq!(ControllerFormat::from_path(Path::new("c.JSON")).unwrap(), ControllerFormat::Json);
    /// assert!(ControllerFormat::from_path(Path::new("c.yaml")).is_err());
    /// ```
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("toml") => Ok(ControllerFormat::Toml),
            Some("json") => Ok(ControllerFormat::Json),
            Some(other) => Err(Error::other(format!(
                "unsupported controller file extension `.{other}` in {}: use a .toml or .json file",
                path.display()
            ))),
            None => Err(Error::other(format!(
                "controller file {} has no extension: name it *.toml or *.json",
                path.display()
            ))),
        }
    }
}

/// Largest controller order (states of its realisation; taps − 1 of a `tf` file) that
/// [`ControllerModel`] accepts. A `tf` controller's frequency response is evaluated by
/// Horner's rule, linear in its taps, but the closed-loop simulation of `validate`/`fit`
/// costs $O(n^2)$ per sample and the closed-loop poles $O(n^3)$, so a 5000-tap filter would
/// run for minutes. Real AMB controllers (PID with notches and low-passes) have at most a few
/// dozen states; 256 keeps every loop computation on the seed record under a few seconds.
pub const MAX_CONTROLLER_ORDER: usize = 256;

/// A discrete SISO controller read from a file: $u = C(q)\,e$, $e = w - y$ \[m\], $u$ \[A\].
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerModel {
    ss: StateSpace,
    /// The transfer function of a `kind = "tf"` file, evaluated by Horner's rule.
    tf: Option<TransferFunction>,
    ts: f64,
    description: String,
    pid: Option<PidSpec>,
    source: Option<PathBuf>,
}

/// Rounds to 9 significant digits for messages (`1.0/5e-5` prints as `20000`).
fn short(x: f64) -> f64 {
    format!("{x:.8e}").parse().unwrap_or(x)
}

fn fs_text(ts: f64) -> String {
    let fs = short(1.0 / ts);
    if fs >= 1e3 {
        format!("{} kHz", short(fs / 1e3))
    } else {
        format!("{fs} Hz")
    }
}

impl ControllerModel {
    /// Wraps a discrete SISO state-space model.
    ///
    /// # Errors
    /// A continuous model, or one that is not single-input single-output.
    ///
    /// # Example
    /// ```
    /// use ambid::io::controller::ControllerModel;
    /// use ambid_core::lti::TransferFunction;
    /// let ss = TransferFunction::new(vec![2.0], vec![1.0], 5e-5).unwrap().to_state_space().unwrap();
    /// let c = ControllerModel::new(ss, "static gain 2 A/m").unwrap();
    /// assert_eq!(c.ts(), 5e-5);
    /// ```
    pub fn new(ss: StateSpace, description: impl Into<String>) -> Result<Self> {
        let ts = ss.ts().ok_or_else(|| {
            Error::other(
                "a controller model must be discrete (have a sample time); discretise it first"
                    .to_string(),
            )
        })?;
        if ss.ninputs() != 1 || ss.noutputs() != 1 {
            return Err(Error::other(format!(
                "the controller must be SISO (one input e = w - y, one output u), but the model \
                 has {} outputs × {} inputs",
                ss.noutputs(),
                ss.ninputs()
            )));
        }
        if ss.order() > MAX_CONTROLLER_ORDER {
            return Err(Error::other(format!(
                "the controller has {} states, more than the limit MAX_CONTROLLER_ORDER = \
                 {MAX_CONTROLLER_ORDER}: the loop computations with it (frequency response, \
                 closed-loop simulation and poles) grow as the square or cube of its order; \
                 reduce it (balanced truncation, fewer FIR taps or a lower sampling rate of the \
                 filter design)",
                ss.order()
            )));
        }
        Ok(Self {
            ss,
            tf: None,
            ts,
            description: description.into(),
            pid: None,
            source: None,
        })
    }

    /// The discrete equivalent of a PID description ([`PidSpec::state_space`]); the
    /// description is [`PidSpec`]'s `Display`.
    ///
    /// # Errors
    /// An invalid specification (see [`PidSpec::validate`]).
    ///
    /// # Example
    /// ```
    /// use ambid::io::controller::ControllerModel;
    /// use ambid_core::lti::PidSpec;
    /// let c = ControllerModel::from_pid(PidSpec::new(1e4, 0.0, 0.0, 5e-5)).unwrap();
    /// assert!(c.description().starts_with("PID"));
    /// ```
    pub fn from_pid(pid: PidSpec) -> Result<Self> {
        let ss = pid.state_space()?;
        let mut m = Self::new(ss, pid.to_string())?;
        m.pid = Some(pid);
        Ok(m)
    }

    /// The discrete SISO model $e \to u$.
    pub fn state_space(&self) -> &StateSpace {
        &self.ss
    }
    /// Sample time \[s\].
    pub fn ts(&self) -> f64 {
        self.ts
    }
    /// Sampling frequency \[Hz\].
    pub fn fs_hz(&self) -> f64 {
        1.0 / self.ts
    }
    /// What the controller is (and where it came from, for a file).
    pub fn description(&self) -> &str {
        &self.description
    }
    /// The PID description, for a `kind = "pid"` file or [`from_pid`](Self::from_pid).
    pub fn pid(&self) -> Option<&PidSpec> {
        self.pid.as_ref()
    }
    /// The file it was read from, if any.
    pub fn source(&self) -> Option<&Path> {
        self.source.as_deref()
    }

    /// The controller's frequency response $C(e^{j2\pi f T_s})$ at each frequency (Hz): for a
    /// `tf` file by Horner's rule in $q^{-1}$ on its coefficients ($O(\text{taps})$ per
    /// frequency), otherwise from the state-space model.
    ///
    /// # Errors
    /// A non-finite frequency, or a frequency on a pole (DC for a controller with an
    /// integrator).
    pub fn freq_response(&self, f_hz: &[f64]) -> Result<Vec<c64>> {
        match &self.tf {
            // Horner's rule in q^-1: O(taps) per frequency
            Some(tf) => Ok(tf.freq_response(f_hz)?),
            None => Ok(self.ss.freq_response_siso(f_hz)?),
        }
    }

    /// Checks that the controller runs at the data's sample time `data_ts` (s): they may
    /// differ by at most 1e-9 relative.
    ///
    /// # Errors
    /// A larger difference, with both rates and what to do; a `data_ts` that is not positive
    /// and finite.
    ///
    /// # Example
    /// ```
    /// use ambid::io::controller::ControllerModel;
    /// use ambid_core::lti::PidSpec;
    /// let c = ControllerModel::from_pid(PidSpec::new(1e4, 0.0, 0.0, 1e-4)).unwrap();
    /// let msg = c.check_ts(5e-5).unwrap_err().to_string();
    /// assert!(msg.contains("ts = 1e-4 s") && msg.contains("5e-5 s (fs 20 kHz)"), "{msg}");
    /// ```
    pub fn check_ts(&self, data_ts: f64) -> Result<()> {
        self.check_ts_inner(data_ts)
            .map_err(|e| Error::classified(FailureClass::Input, e))
    }

    fn check_ts_inner(&self, data_ts: f64) -> Result<()> {
        if !(data_ts.is_finite() && data_ts > 0.0) {
            return Err(Error::other(format!(
                "the data's sample time must be positive and finite, got {data_ts}"
            )));
        }
        let tc = self.ts;
        if (tc - data_ts).abs() > 1e-9 * tc.max(data_ts) {
            let who = match &self.source {
                Some(p) => format!("controller file {}", p.display()),
                None => format!("controller ({})", self.description),
            };
            return Err(Error::other(format!(
                "{who} has ts = {:e} s (fs {}) but the data are sampled at {:e} s (fs {}): \
                 rediscretise the controller at the data rate (for a `pid` file, set fs_hz or \
                 ts to the data's rate)",
                short(tc),
                fs_text(tc),
                short(data_ts),
                fs_text(data_ts)
            )));
        }
        Ok(())
    }
}

/// Reads a controller file; the format follows the extension (`.toml` or `.json`).
///
/// # Errors
/// An unreadable file, an unsupported extension, and everything
/// [`parse_controller_str`] rejects; the message names the file.
///
/// # Example
/// ```no_run
/// use ambid::io::controller::read_controller;
/// let c = read_controller(std::path::Path::new("controller.toml")).unwrap();
/// c.check_ts(5e-5).unwrap();
/// ```
pub fn read_controller(path: &Path) -> Result<ControllerModel> {
    read_controller_inner(path).map_err(|e| Error::classified(FailureClass::Input, e))
}

fn read_controller_inner(path: &Path) -> Result<ControllerModel> {
    let format = ControllerFormat::from_path(path)?;
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::other(e.to_string()))
        .with_context(|| format!("cannot read controller file {}", path.display()))?;
    let mut model = parse_controller_str(&text, format)
        .with_context(|| format!("invalid controller file {}", path.display()))?;
    model.description = format!("{} (from {})", model.description, path.display());
    model.source = Some(path.to_path_buf());
    Ok(model)
}

#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum Method {
    Tustin,
    Zoh,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PidFile {
    #[allow(dead_code)]
    kind: String,
    kp: f64,
    ki: Option<f64>,
    integral_corner_hz: Option<f64>,
    kd: f64,
    derivative_cutoff_hz: Option<f64>,
    lowpass_hz: Option<f64>,
    fs_hz: Option<f64>,
    ts: Option<f64>,
    method: Method,
    prewarp_hz: Option<f64>,
    delay_samples: Option<usize>,
    description: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TfFile {
    #[allow(dead_code)]
    kind: String,
    fs_hz: Option<f64>,
    ts: Option<f64>,
    num: Vec<f64>,
    den: Vec<f64>,
    description: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SsFile {
    #[allow(dead_code)]
    kind: String,
    fs_hz: Option<f64>,
    ts: Option<f64>,
    a: Vec<Vec<f64>>,
    b: Vec<Vec<f64>>,
    c: Vec<Vec<f64>>,
    d: Vec<Vec<f64>>,
    description: Option<String>,
}

/// Parses the text of a controller file (see the [module docs](self) and `docs/formats.md`).
///
/// # Errors
/// Malformed TOML/JSON; a missing or unknown `kind`; unknown or missing keys (named); a
/// non-finite number; both or neither of `ts`/`fs_hz` (and of `ki`/`integral_corner_hz` for a
/// PID); an invalid PID ([`PidSpec::validate`]); `den[0] = 0`; a non-SISO or inconsistently
/// sized state space.
///
/// # Example
/// ```
/// use ambid::io::controller::{parse_controller_str, ControllerFormat};
/// let c = parse_controller_str(
///     r#"{"kind": "tf", "ts": 5e-5, "num": [2.0, -1.8], "den": [1.0, -1.0]}"#,
///     ControllerFormat::Json,
/// ).unwrap();
/// assert_eq!(c.state_space().order(), 1);
/// let err = parse_controller_str("kind = \"tf\"\nts = 5e-5\nnum = [1.0]\nden = [1.0]\ngain = 2.0\n",
///     ControllerFormat::Toml).unwrap_err();
/// assert!(format!("{err:#}").contains("unknown field `gain`"));
/// ```
pub fn parse_controller_str(s: &str, format: ControllerFormat) -> Result<ControllerModel> {
    let kind = read_kind(s, format)?;
    match kind.as_str() {
        "pid" => pid_model(decode(s, format)?),
        "tf" => tf_model(decode(s, format)?),
        "ss" => ss_model(decode(s, format)?),
        other => Err(Error::other(format!(
            "unknown controller kind `{other}`: use \"pid\", \"tf\" or \"ss\""
        ))),
    }
}

fn read_kind(s: &str, format: ControllerFormat) -> Result<String> {
    let missing =
        || Error::other("missing key `kind`: give kind = \"pid\", \"tf\" or \"ss\"".to_string());
    let not_string =
        || Error::other("`kind` must be a string: \"pid\", \"tf\" or \"ss\"".to_string());
    match format {
        ControllerFormat::Toml => {
            let t: toml::Table =
                toml::from_str(s).map_err(|e| Error::other(format!("malformed TOML: {e}")))?;
            match t.get("kind") {
                None => Err(missing()),
                Some(toml::Value::String(k)) => Ok(k.clone()),
                Some(_) => Err(not_string()),
            }
        }
        ControllerFormat::Json => {
            let v: serde_json::Value = serde_json::from_str(s)
                .map_err(|e| Error::other(format!("malformed JSON: {e}")))?;
            let obj = v.as_object().ok_or_else(|| {
                Error::other(
                    "a JSON controller file must hold one object {\"kind\": …, …}".to_string(),
                )
            })?;
            match obj.get("kind") {
                None => Err(missing()),
                Some(serde_json::Value::String(k)) => Ok(k.clone()),
                Some(_) => Err(not_string()),
            }
        }
    }
}

fn decode<T: DeserializeOwned>(s: &str, format: ControllerFormat) -> Result<T> {
    match format {
        ControllerFormat::Toml => toml::from_str(s).map_err(|e| Error::other(format!("{e}"))),
        ControllerFormat::Json => serde_json::from_str(s).map_err(|e| Error::other(format!("{e}"))),
    }
}

fn finite(key: &str, v: f64) -> Result<f64> {
    if !v.is_finite() {
        return Err(Error::other(format!(
            "`{key}` must be a finite number, got {v}"
        )));
    }
    Ok(v)
}

fn sample_time(ts: Option<f64>, fs_hz: Option<f64>) -> Result<f64> {
    let t = match (ts, fs_hz) {
        (Some(_), Some(_)) => {
            return Err(Error::other(
                "give either `ts` (s) or `fs_hz` (Hz), not both".to_string(),
            ))
        }
        (None, None) => {
            return Err(Error::other(
                "missing sample time: give `ts` (s) or `fs_hz` (Hz)".to_string(),
            ))
        }
        (Some(t), None) => {
            finite("ts", t)?;
            t
        }
        (None, Some(f)) => {
            if finite("fs_hz", f)? <= 0.0 {
                return Err(Error::other(format!("`fs_hz` must be positive, got {f}")));
            }
            1.0 / f
        }
    };
    if t <= 0.0 {
        return Err(Error::other(format!("`ts` must be positive, got {t}")));
    }
    Ok(t)
}

fn pid_model(p: PidFile) -> Result<ControllerModel> {
    let ts = sample_time(p.ts, p.fs_hz)?;
    finite("kp", p.kp)?;
    let ki = match (p.ki, p.integral_corner_hz) {
        (Some(_), Some(_)) => {
            return Err(Error::other(
                "give either `ki` (A/(m·s)) or `integral_corner_hz` (Hz), not both".to_string(),
            ))
        }
        (None, None) => {
            return Err(Error::other(
                "missing integral action: give `ki` (A/(m·s)) or `integral_corner_hz` (Hz, \
             Ki = Kp·2π·f_i); 0 means no integrator"
                    .to_string(),
            ))
        }
        (Some(ki), None) => finite("ki", ki)?,
        (None, Some(fi)) => {
            finite("integral_corner_hz", fi)?;
            if fi < 0.0 {
                return Err(Error::other(format!(
                    "`integral_corner_hz` must be >= 0 (0: no integrator), got {fi}"
                )));
            }
            // the twin's expression, so a twin file reproduces its Ki bit for bit
            p.kp * 2.0 * std::f64::consts::PI * fi
        }
    };
    let method = match (p.method, p.prewarp_hz) {
        (Method::Tustin, None) => Discretisation::Tustin,
        (Method::Tustin, Some(f)) => Discretisation::TustinPrewarp { f_hz: f },
        (Method::Zoh, None) => Discretisation::Zoh,
        (Method::Zoh, Some(_)) => {
            return Err(Error::other(
                "`prewarp_hz` applies to method = \"tustin\" only; remove it for \"zoh\""
                    .to_string(),
            ))
        }
    };
    let spec = PidSpec {
        kp: p.kp,
        ki,
        kd: p.kd,
        derivative_cutoff_hz: p.derivative_cutoff_hz,
        lowpass_hz: p.lowpass_hz,
        ts,
        method,
        delay_samples: p.delay_samples.unwrap_or(0),
    };
    let mut m = ControllerModel::from_pid(spec)?;
    if let Some(d) = p.description {
        m.description = d;
    }
    Ok(m)
}

fn tf_model(t: TfFile) -> Result<ControllerModel> {
    let ts = sample_time(t.ts, t.fs_hz)?;
    for (key, p) in [("num", &t.num), ("den", &t.den)] {
        if let Some(i) = p.iter().position(|x| !x.is_finite()) {
            return Err(Error::other(format!(
                "`{key}[{i}]` must be a finite number, got {:e}",
                p[i]
            )));
        }
    }
    if t.num.iter().all(|b| *b == 0.0) {
        return Err(Error::other(
            "`num` is empty or all zero, so the controller would be C = 0".to_string(),
        ));
    }
    if t.den.first().is_none_or(|a0| *a0 == 0.0) {
        return Err(Error::other(
            "`den[0]` (the coefficient of q^0) must be non-zero: with den[0] = 0 the controller \
             is not causal; list den in ascending powers of q^-1, den = [1, a1, a2, …]"
                .to_string(),
        ));
    }
    let n = t.num.len().max(t.den.len()).saturating_sub(1);
    if n > MAX_CONTROLLER_ORDER {
        return Err(Error::other(format!(
            "`num`/`den` have {} coefficients, a controller of order {n}: more than the limit \
             MAX_CONTROLLER_ORDER = {MAX_CONTROLLER_ORDER}; reduce it (balanced truncation, \
             fewer FIR taps or a lower sampling rate of the filter design)",
            n + 1
        )));
    }
    let tf = TransferFunction::new(t.num, t.den, ts)?;
    let n = tf.num().len().max(tf.den().len()) - 1;
    let ss = tf.to_state_space()?;
    let desc = t.description.unwrap_or_else(|| {
        format!(
            "discrete transfer function of order {n}, fs = {} Hz",
            short(1.0 / ts)
        )
    });
    let mut m = ControllerModel::new(ss, desc)?;
    m.tf = Some(tf);
    Ok(m)
}

/// Rows and columns of a matrix given as rows; errors on ragged rows.
fn shape(key: &str, m: &[Vec<f64>]) -> Result<(usize, Option<usize>)> {
    let cols = m.first().map(Vec::len);
    for (i, row) in m.iter().enumerate() {
        if Some(row.len()) != cols {
            return Err(Error::other(format!(
                "`{key}` row {i} has {} entries but row 0 has {}: every row needs the same length",
                row.len(),
                cols.unwrap_or(0)
            )));
        }
        if let Some(j) = row.iter().position(|x| !x.is_finite()) {
            return Err(Error::other(format!(
                "`{key}[{i}][{j}]` must be a finite number, got {:e}",
                row[j]
            )));
        }
    }
    Ok((m.len(), cols))
}

fn ss_model(f: SsFile) -> Result<ControllerModel> {
    let ts = sample_time(f.ts, f.fs_hz)?;
    let (na, ca) = shape("a", &f.a)?;
    let (nb, mb) = shape("b", &f.b)?;
    let (pc, nc) = shape("c", &f.c)?;
    let (pd, md) = shape("d", &f.d)?;
    let siso = |what: String| {
        Error::other(format!(
            "the controller must be SISO (one input e = w - y, one output u), but {what}; \
             give one controller per file"
        ))
    };
    match (pd, md) {
        (1, Some(1)) => {}
        (0, _) => {
            return Err(Error::other(
                "`d` is empty: give the 1×1 feed-through as d = [[d0]]".to_string(),
            ))
        }
        (p, m) => return Err(siso(format!("d is {p}×{}", m.unwrap_or(0)))),
    }
    if pc != 1 {
        return Err(siso(format!("c has {pc} rows (outputs)")));
    }
    if let Some(m) = mb.filter(|m| *m != 1) {
        return Err(siso(format!("b has {m} columns (inputs)")));
    }
    let n = na;
    if n > MAX_CONTROLLER_ORDER {
        return Err(Error::other(format!(
            "`a` has {n} rows, a controller of order {n}: more than the limit \
             MAX_CONTROLLER_ORDER = {MAX_CONTROLLER_ORDER}; reduce it (balanced truncation)"
        )));
    }
    if ca.is_some_and(|c| c != n) {
        return Err(Error::other(format!(
            "`a` must be square (n×n): it has {n} rows of {} entries",
            ca.unwrap_or(0)
        )));
    }
    if nb != n {
        return Err(Error::other(format!(
            "`b` must have one row per state: a is {n}×{n} but b has {nb} rows"
        )));
    }
    if nc.unwrap_or(0) != n {
        return Err(Error::other(format!(
            "`c` must have one column per state: a is {n}×{n} but c has {} columns{}",
            nc.unwrap_or(0),
            if n == 0 {
                " (a static gain is a = [], b = [], c = [[]], d = [[k]])"
            } else {
                ""
            }
        )));
    }
    let a = Mat::from_fn(n, n, |i, j| f.a[i][j]);
    let b = Mat::from_fn(n, 1, |i, _| f.b[i][0]);
    let c = Mat::from_fn(1, n, |_, j| f.c[0][j]);
    let d = Mat::from_fn(1, 1, |_, _| f.d[0][0]);
    let ss = StateSpace::discrete(a, b, c, d, ts)?;
    let desc = f.description.unwrap_or_else(|| {
        format!(
            "discrete state space of order {n}, fs = {} Hz",
            short(1.0 / ts)
        )
    });
    ControllerModel::new(ss, desc)
}

/// A TOML number that reads back to exactly `x` (`nan`/`inf` spelled as TOML does).
fn toml_number(x: f64) -> String {
    if x.is_nan() {
        "nan".into()
    } else if x.is_infinite() {
        if x > 0.0 { "inf" } else { "-inf" }.into()
    } else {
        format!("{x:?}")
    }
}

/// The twin's controller (`cfg.controller`) as a `kind = "pid"` TOML controller file.
///
/// Numbers are written so that they read back exactly; reading the result with
/// [`parse_controller_str`] gives the frequency response of `Twin::controller_frf`. The twin's
/// output clamp and anti-windup are not part of a linear controller model and are not written.
/// The configuration is written as it is (not validated).
///
/// # Example
/// ```
/// use ambid::io::controller::controller_toml_from_twin;
/// let text = controller_toml_from_twin(&ambid_twin::TwinConfig::default());
/// assert!(text.contains("kind = \"pid\"") && text.contains("kp = 21000.0"));
/// ```
pub fn controller_toml_from_twin(cfg: &TwinConfig) -> String {
    let c = &cfg.controller;
    let mut s = String::new();
    s.push_str(
        "# Controller of the ambid twin, C(s) = [Kp + Ki/s + Kd s/(1 + s/wd)] / (1 + s/wl) acting\n\
         # on e = w - y (m -> A), Ki = kp 2 pi integral_corner_hz, Tustin at fs_hz. No computation\n\
         # delay: in ambid's convention it belongs to the plant. The twin's output clamp (+-i_sat)\n\
         # and anti-windup are not part of this linear model.\n",
    );
    s.push_str("kind = \"pid\"\n");
    for (key, v) in [
        ("kp", c.kp),
        ("integral_corner_hz", c.integral_corner_hz),
        ("kd", c.kd),
        ("derivative_cutoff_hz", c.derivative_cutoff_hz),
        ("lowpass_hz", c.lowpass_hz),
        ("fs_hz", c.fs_hz),
    ] {
        s.push_str(&format!("{key} = {}\n", toml_number(v)));
    }
    s.push_str("method = \"tustin\"\ndelay_samples = 0\n");
    s
}
