//! Exporting identified models for MATLAB and Python users: a MATLAB `.m` script that rebuilds
//! the model, a MATLAB `.mat` (Level 5, "v5"/"v6") file and a NumPy `.npz` archive (the JSON form
//! is in [`super::model`]). The files, their variables and shapes are described in
//! `docs/export.md`.
//!
//! The three writers export the same variables:
//!
//! | model | numbers | text |
//! |-------|---------|------|
//! | polynomial | `A, B, C, D, F` (row vectors, ascending powers of q⁻¹), `Ts`, `nk` | `structure`, `input_name`, `output_name`, `model_name` |
//! | state space | `A` (n×n), `B` (n×nu), `C` (ny×n), `D` (ny×nu), `K` (n×ny, if given), `Ts` | the same, `structure = "ss"` |
//!
//! `Ts = 0` marks a continuous-time state-space model (as in the JSON form). Every coefficient
//! must be finite; a NaN or infinity is an [`ExportError::NonFinite`], never a silently broken
//! file.
//!
//! The `.mat` writer is a small hand-written Level 5 encoder (the `mat5` submodule) rather than
//! the `matrw` crate (0.1.4), which writes only to a path, discards write errors and stamps the
//! creation time: this one returns bytes, reports every error, and its output is byte-for-byte
//! reproducible. Its output is checked against `scipy.io` in `tests/export.rs`.

mod mat5;
pub mod mimo;
mod npz;
mod script;
pub mod uncertain;
pub mod uncertain_matrix;

use ambid_core::lti::{PolyModel, StateSpace};

/// A model to export, with its signal names.
#[derive(Debug, Clone, Copy)]
pub enum ExportModel<'a> {
    /// A polynomial model (`A y = B/F u + C/D e`).
    Poly(&'a PolyModel),
    /// A discrete state-space model, optionally with the Kalman gain `K` of the innovations form
    /// `x⁺ = A x + B u + K e, y = C x + D u + e`. `K` is n×ny stored column by column (for the
    /// usual single-output model simply its n entries).
    StateSpace(&'a StateSpace, Option<&'a [f64]>),
}

/// Names (and the noise variance) carried into the exported files.
#[derive(Debug, Clone, Default)]
pub struct ExportNames {
    /// Variable / model name; it is passed through [`sanitize_identifier`] before use, so any
    /// text is accepted.
    pub name: String,
    /// Input signal name.
    pub input: String,
    /// Output signal name.
    pub output: String,
    /// Variance λ of the innovations e (the fit's `noise_variance`), exported as
    /// `noise_variance` of a polynomial model (`idpoly`'s `NoiseVariance`); `None` when unknown (exported
    /// as 1, MATLAB's `idpoly` default).
    pub noise_variance: Option<f64>,
}

/// Why a model could not be exported.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ExportError {
    /// A coefficient is NaN or infinite (`index` counts from 0, row by row for matrices).
    #[error("cannot export the model: {what}[{index}] = {value} is not finite (every coefficient must be a finite number)")]
    NonFinite {
        /// Which variable (`"A"`, `"K"`, …).
        what: &'static str,
        /// Index of the entry (0-based, row-major for matrices).
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// The Kalman gain does not have n·ny entries.
    #[error("the Kalman gain K has {got} entries, but the model has {states} states and {outputs} outputs (K must be n×ny = {} entries)", states * outputs)]
    KalmanGainLength {
        /// Entries given.
        got: usize,
        /// Model order n.
        states: usize,
        /// Number of outputs ny.
        outputs: usize,
    },
    /// A variable is too large for the file format (a MAT v5 element is limited to 4 GiB).
    #[error("{what} is too large for a MATLAB v5 file")]
    TooLarge {
        /// Which variable.
        what: String,
    },
    /// A MIMO model's channel names do not match its channels.
    #[error("{got} names given for the model's {expected} {what}: give one name per channel (e.g. u_xa, u_xb, u_ya, u_yb)")]
    ChannelNames {
        /// `inputs` or `outputs`.
        what: &'static str,
        /// Names given.
        got: usize,
        /// Channels of the model.
        expected: usize,
    },
    /// A channel name is empty or holds a comma (the files join the names with commas).
    #[error("the channel name `{name}` is empty or contains a comma; name every channel without commas, e.g. u_xa")]
    ChannelName {
        /// The name.
        name: String,
    },
    /// Two per-line vectors of an export differ in length.
    #[error("{what} has {got} entries, but the export has {expected} frequency lines: give one value per line")]
    Length {
        /// Which variable.
        what: &'static str,
        /// Entries given.
        got: usize,
        /// Lines.
        expected: usize,
    },
    /// Writing the `.npz` archive failed.
    #[error("cannot write the .npz archive: {0}")]
    Npz(#[from] std::io::Error),
}

/// Result of the export functions.
pub type Result<T> = std::result::Result<T, ExportError>;

/// A numeric or text variable of the export, in a format-neutral form.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Value {
    /// A `rows × cols` matrix, data row by row.
    Matrix {
        rows: usize,
        cols: usize,
        data: Vec<f64>,
    },
    /// A polynomial: a row vector in MATLAB, a 1-D array in NumPy.
    Vector(Vec<f64>),
    /// A scalar: 1×1 in MATLAB, a 0-d array in NumPy.
    Scalar(f64),
    /// Text: a char row vector in MATLAB, a 0-d unicode array in NumPy.
    Text(String),
}

/// A named variable of the export.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Var {
    pub(crate) name: &'static str,
    pub(crate) value: Value,
}

fn var(name: &'static str, value: Value) -> Var {
    Var { name, value }
}

fn check_finite(what: &'static str, data: &[f64]) -> Result<()> {
    match data.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(ExportError::NonFinite {
            what,
            index,
            value: data[index],
        }),
        None => Ok(()),
    }
}

fn matrix(what: &'static str, m: faer::MatRef<'_, f64>) -> Result<Value> {
    let (rows, cols) = (m.nrows(), m.ncols());
    let data: Vec<f64> = (0..rows)
        .flat_map(|i| (0..cols).map(move |j| m[(i, j)]))
        .collect();
    check_finite(what, &data)?;
    Ok(Value::Matrix { rows, cols, data })
}

/// The variables of a model, in the order they are written, after checking every number.
pub(crate) fn variables(model: ExportModel<'_>, names: &ExportNames) -> Result<Vec<Var>> {
    let mut vars = Vec::new();
    let structure = match model {
        ExportModel::Poly(m) => {
            let polys: [(&'static str, &[f64]); 5] = [
                ("A", m.a()),
                ("B", m.b()),
                ("C", m.c()),
                ("D", m.d()),
                ("F", m.f()),
            ];
            for (name, p) in polys {
                check_finite(name, p)?;
                vars.push(var(name, Value::Vector(p.to_vec())));
            }
            check_finite("Ts", &[m.ts()])?;
            vars.push(var("Ts", Value::Scalar(m.ts())));
            vars.push(var("nk", Value::Scalar(m.delay() as f64)));
            let lambda = names.noise_variance.unwrap_or(1.0);
            check_finite("noise_variance", &[lambda])?;
            vars.push(var("noise_variance", Value::Scalar(lambda)));
            m.structure().name()
        }
        ExportModel::StateSpace(m, k) => {
            vars.push(var("A", matrix("A", m.a())?));
            vars.push(var("B", matrix("B", m.b())?));
            vars.push(var("C", matrix("C", m.c())?));
            vars.push(var("D", matrix("D", m.d())?));
            if let Some(k) = k {
                let (n, ny) = (m.order(), m.noutputs());
                if k.len() != n * ny {
                    return Err(ExportError::KalmanGainLength {
                        got: k.len(),
                        states: n,
                        outputs: ny,
                    });
                }
                // column-major input → row-major storage
                let data: Vec<f64> = (0..n)
                    .flat_map(|i| (0..ny).map(move |j| k[i + j * n]))
                    .collect();
                check_finite("K", &data)?;
                vars.push(var(
                    "K",
                    Value::Matrix {
                        rows: n,
                        cols: ny,
                        data,
                    },
                ));
            }
            let ts = m.ts().unwrap_or(0.0);
            check_finite("Ts", &[ts])?;
            vars.push(var("Ts", Value::Scalar(ts)));
            "ss"
        }
    };
    vars.push(var("structure", Value::Text(structure.to_string())));
    vars.push(var("input_name", Value::Text(names.input.clone())));
    vars.push(var("output_name", Value::Text(names.output.clone())));
    vars.push(var(
        "model_name",
        Value::Text(sanitize_identifier(&names.name)),
    ));
    Ok(vars)
}

/// The polynomial form of a SISO discrete transfer-function model that is held as a state-space
/// realisation (the frequency-domain ARX and OE fits of the workflow are fitted as
/// $G = B/A$ resp. $B/F$ and kept in companion form): `structure` `"arx"` gives
/// $A = \mathrm{den}$, $B = \mathrm{num}$ (`A y = B u + e`), `"oe"` gives $F = \mathrm{den}$,
/// $B = \mathrm{num}$ (`y = B/F u + e`). A model in the companion form of
/// [`ambid_core::lti::TransferFunction::to_state_space`] gives its coefficients back exactly;
/// any other realisation goes through [`StateSpace::tf_coefficients`] (monic denominator from
/// the eigenvalues, numerator from the Markov parameters, the delay as exact leading zeros of
/// $B$). `None` for any other structure, a
/// MIMO or continuous model, or when the conversion fails: the model is then exported as state
/// space. The poles are not touched (an unstable plant stays unstable).
///
/// ```
/// use ambid::io::export::polynomial_form;
/// use ambid_core::lti::TransferFunction;
/// // G = 0.5 q^-1 / (1 - 1.02 q^-1): unstable, as an AMB plant
/// let ss = TransferFunction::new(vec![0.0, 0.5], vec![1.0, -1.02], 5e-5).unwrap().to_state_space().unwrap();
/// let p = polynomial_form("oe", &ss).unwrap();
/// assert_eq!(p.b(), &[0.0, 0.5]);
/// assert_eq!(p.f(), &[1.0, -1.02]); // read back from the companion form, bit for bit
/// assert!(polynomial_form("ss", &ss).is_none());
/// ```
pub fn polynomial_form(structure: &str, ss: &StateSpace) -> Option<PolyModel> {
    if ss.ninputs() != 1 || ss.noutputs() != 1 {
        return None;
    }
    let ts = ss.ts()?;
    let (num, den) = companion_coefficients(ss).or_else(|| ss.tf_coefficients().ok())?;
    let a0 = *den.first()?;
    if a0 == 0.0 {
        return None;
    }
    let num: Vec<f64> = num.iter().map(|x| x / a0).collect();
    let den: Vec<f64> = den.iter().map(|x| x / a0).collect();
    match structure {
        "arx" => PolyModel::arx(den, num, ts).ok(),
        "oe" => PolyModel::oe(num, den, ts).ok(),
        _ => None,
    }
}

/// The exact `(num, den)` of a SISO model in the controllable canonical form of
/// [`ambid_core::lti::TransferFunction::to_state_space`] (first row of `A` = −den₁…, ones on the
/// subdiagonal, `B = e₁`, `C_j = num_{j+1} − num₀ den_{j+1}`, `D = num₀`), trailing zero
/// coefficients removed; `None` for any other realisation. Reading the coefficients back
/// instead of recomputing them from the eigenvalues keeps them bit for bit: at 20 kHz, where all
/// poles sit near z = 1, a relative change of 1e-11 in the denominator moves the low-frequency
/// response by per cent.
fn companion_coefficients(ss: &StateSpace) -> Option<(Vec<f64>, Vec<f64>)> {
    let (a, b, c, d) = (ss.a(), ss.b(), ss.c(), ss.d());
    let n = a.nrows();
    if n == 0 {
        return None;
    }
    for i in 0..n {
        if b[(i, 0)] != if i == 0 { 1.0 } else { 0.0 } {
            return None;
        }
        if i > 0 && (0..n).any(|j| a[(i, j)] != if i == j + 1 { 1.0 } else { 0.0 }) {
            return None;
        }
    }
    let b0 = d[(0, 0)];
    let mut den: Vec<f64> = std::iter::once(1.0)
        .chain((0..n).map(|j| -a[(0, j)]))
        .collect();
    let mut num: Vec<f64> = std::iter::once(b0)
        .chain((0..n).map(|j| c[(0, j)] + b0 * den[j + 1]))
        .collect();
    for p in [&mut num, &mut den] {
        while p.len() > 1 && p.last() == Some(&0.0) {
            p.pop();
        }
    }
    Some((num, den))
}

/// Maximum identifier length in MATLAB (`namelengthmax`).
const MAX_IDENTIFIER: usize = 63;

/// Words a model name must not be: MATLAB and Python keywords, and the variables and functions
/// the generated MATLAB script uses itself.
const RESERVED: &[&str] = &[
    // MATLAB keywords
    "break",
    "case",
    "catch",
    "classdef",
    "continue",
    "else",
    "elseif",
    "end",
    "for",
    "function",
    "global",
    "if",
    "otherwise",
    "parfor",
    "persistent",
    "return",
    "spmd",
    "switch",
    "try",
    "while",
    // Python keywords (those not above)
    "False",
    "None",
    "True",
    "and",
    "as",
    "assert",
    "async",
    "await",
    "class",
    "def",
    "del",
    "elif",
    "except",
    "finally",
    "from",
    "import",
    "in",
    "is",
    "lambda",
    "nonlocal",
    "not",
    "or",
    "pass",
    "raise",
    "with",
    "yield",
    // names used by the generated script
    "A",
    "B",
    "C",
    "D",
    "F",
    "K",
    "Ts",
    "nk",
    "noise_variance",
    "Gnum",
    "Gden",
    "conv",
    "exist",
    "idpoly",
    "idss",
    "ss",
    "tf",
    "zeros",
    "char",
];

/// Turns any text into a valid MATLAB and Python identifier: characters other than ASCII
/// letters, digits and `_` become `_`, a name not starting with a letter gets an `m` in front,
/// an empty name becomes `model`, names are cut to MATLAB's 63 characters, and a keyword or a
/// name the generated script uses itself (`A`, `Ts`, `idpoly`, …) gets a `_` appended.
///
/// ```
/// use ambid::io::export::sanitize_identifier;
/// assert_eq!(sanitize_identifier("bearing A/x-axis"), "bearing_A_x_axis");
/// assert_eq!(sanitize_identifier("2nd model"), "m2nd_model");
/// assert_eq!(sanitize_identifier(""), "model");
/// assert_eq!(sanitize_identifier("end"), "end_");
/// ```
pub fn sanitize_identifier(text: &str) -> String {
    let mut s: String = text
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() {
        return "model".to_string();
    }
    if !s.starts_with(|c: char| c.is_ascii_alphabetic()) {
        s.insert(0, 'm');
    }
    // all characters are ASCII now, so byte truncation is safe
    s.truncate(MAX_IDENTIFIER);
    if RESERVED.contains(&s.as_str()) {
        if s.len() == MAX_IDENTIFIER {
            s.pop();
        }
        s.push('_');
    }
    s
}

/// A MATLAB script (`.m`) that rebuilds the model.
///
/// Running the script defines the coefficient variables (`A, B, C, D, F, Ts, nk` for a
/// polynomial model, `A, B, C, D, (K), Ts` for state space) and, when the System Identification
/// Toolbox is available, the model itself as `idpoly` / `idss` in a variable named after
/// [`ExportNames::name`] (sanitised by [`sanitize_identifier`]); without it, the Control System
/// Toolbox's `tf` (deterministic part `G = B/(A F)` in `z^-1`) / `ss`; without either only the
/// coefficients. Every number is printed with 17 significant digits (`%.17g`), so it is read
/// back bit for bit.
///
/// # Errors
/// [`ExportError::NonFinite`] for a NaN or infinite coefficient, [`ExportError::KalmanGainLength`]
/// for a `K` that is not n·ny long.
///
/// # Example
/// ```
/// use ambid::io::export::{matlab_script, ExportModel, ExportNames};
/// use ambid_core::lti::PolyModel;
/// // OE: y = 0.2 q^-1 / (1 - 0.8 q^-1) u + e
/// let m = PolyModel::oe(vec![0.0, 0.2], vec![1.0, -0.8], 1e-3).unwrap();
/// let names = ExportNames { name: "plant".into(), input: "u".into(), output: "y".into(), noise_variance: None };
/// let names = ExportNames { noise_variance: Some(1e-3), ..names };
/// let text = matlab_script(ExportModel::Poly(&m), &names).unwrap();
/// assert!(text.contains("B = [0, 0.20000000000000001];"));
/// assert!(text.contains("F = [1, -0.80000000000000004];"));
/// assert!(text.contains("noise_variance = 0.001;"));
/// assert!(text.contains("plant = idpoly(A, B, C, D, F, noise_variance, Ts, 'InputName', 'u', 'OutputName', 'y');"));
/// ```
pub fn matlab_script(model: ExportModel<'_>, names: &ExportNames) -> Result<String> {
    let vars = variables(model, names)?;
    Ok(script::render(model, names, &vars))
}

/// The model as a MATLAB Level 5 (`-v6`, uncompressed) `.mat` file: doubles for the numbers
/// (polynomials as 1×n row vectors, scalars as 1×1) and char row vectors for the text, readable
/// by MATLAB's `load`, Octave and `scipy.io.loadmat`.
///
/// # Errors
/// [`ExportError::NonFinite`] for a NaN or infinite coefficient, [`ExportError::KalmanGainLength`]
/// for a `K` that is not n·ny long, [`ExportError::TooLarge`] for a variable beyond the format's 4 GiB.
///
/// ```
/// use ambid::io::export::{mat_bytes, ExportModel, ExportNames};
/// use ambid_core::lti::PolyModel;
/// let m = PolyModel::arx(vec![1.0, -0.5], vec![0.0, 1.0], 1e-3).unwrap();
/// let names = ExportNames { name: "g".into(), input: "u".into(), output: "y".into(), noise_variance: None };
/// let bytes = mat_bytes(ExportModel::Poly(&m), &names).unwrap();
/// assert!(bytes.starts_with(b"MATLAB 5.0 MAT-file"));
/// assert_eq!(&bytes[126..128], b"IM"); // little-endian
/// ```
pub fn mat_bytes(model: ExportModel<'_>, names: &ExportNames) -> Result<Vec<u8>> {
    let vars = variables(model, names)?;
    mat5::encode(&header_text(), &vars)
}

/// The model as a NumPy `.npz` archive: float64 arrays (2-D matrices, 1-D polynomials, 0-d
/// scalars) and 0-d unicode (`<U`) arrays for the text, readable by `numpy.load` without
/// `allow_pickle`.
///
/// # Errors
/// [`ExportError::NonFinite`] for a NaN or infinite coefficient, [`ExportError::KalmanGainLength`]
/// for a `K` that is not n·ny long, [`ExportError::Npz`] when the archive cannot be written.
///
/// ```
/// use ambid::io::export::{npz_bytes, ExportModel, ExportNames};
/// use ambid_core::lti::PolyModel;
/// let m = PolyModel::fir(vec![0.0, 0.5, 0.25], 1e-3).unwrap();
/// let names = ExportNames { name: "g".into(), input: "u".into(), output: "y".into(), noise_variance: None };
/// let bytes = npz_bytes(ExportModel::Poly(&m), &names).unwrap();
/// assert!(bytes.starts_with(b"PK\x03\x04")); // a zip archive
/// ```
pub fn npz_bytes(model: ExportModel<'_>, names: &ExportNames) -> Result<Vec<u8>> {
    let vars = variables(model, names)?;
    npz::encode(&vars)
}

fn header_text() -> String {
    format!(
        "MATLAB 5.0 MAT-file, Platform: any, Created by: ambid {} model export",
        env!("CARGO_PKG_VERSION")
    )
}

/// `x` as C's `printf("%.17g", x)`: 17 significant digits, exponent form when the decimal
/// exponent is below −4 or at least 17, trailing zeros removed. Finite `x` only (the callers
/// check).
pub(crate) fn format_g17(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return if x.is_sign_negative() { "-0" } else { "0" }.to_string();
    }
    // Rust's `{:e}` rounds correctly, like glibc's printf.
    let sci = format!("{:.16e}", x.abs());
    let (mantissa, exp) = match sci.split_once('e') {
        Some((m, e)) => match e.parse::<i32>() {
            Ok(e) => (m, e),
            Err(_) => return format!("{x:e}"),
        },
        None => return format!("{x:e}"),
    };
    let digits: String = mantissa.chars().filter(char::is_ascii_digit).collect();
    let sign = if x < 0.0 { "-" } else { "" };
    let body = if !(-4..17).contains(&exp) {
        let m = if mantissa.contains('.') {
            mantissa.trim_end_matches('0').trim_end_matches('.')
        } else {
            mantissa
        };
        let es = if exp < 0 { '-' } else { '+' };
        format!("{m}e{es}{:02}", exp.unsigned_abs())
    } else if exp >= 0 {
        let split = (exp as usize + 1).min(digits.len());
        let (int, frac) = digits.split_at(split);
        let frac = frac.trim_end_matches('0');
        if frac.is_empty() {
            int.to_string()
        } else {
            format!("{int}.{frac}")
        }
    } else {
        let zeros = "0".repeat((-exp - 1) as usize);
        format!("0.{zeros}{}", digits.trim_end_matches('0'))
    };
    format!("{sign}{body}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::mat;

    fn names() -> ExportNames {
        ExportNames {
            name: "plant".into(),
            input: "u".into(),
            output: "y".into(),
            noise_variance: None,
        }
    }

    #[test]
    fn identifiers_are_sanitised() {
        assert_eq!(sanitize_identifier("plant"), "plant");
        assert_eq!(sanitize_identifier("bearing A/x"), "bearing_A_x");
        assert_eq!(sanitize_identifier("_x"), "m_x");
        assert_eq!(sanitize_identifier("9"), "m9");
        assert_eq!(sanitize_identifier("Ünïcode"), "m_n_code");
        assert_eq!(sanitize_identifier(""), "model");
        assert_eq!(sanitize_identifier("end"), "end_");
        assert_eq!(sanitize_identifier("lambda"), "lambda_");
        assert_eq!(sanitize_identifier("A"), "A_");
        assert_eq!(sanitize_identifier("Ts"), "Ts_");
        assert_eq!(sanitize_identifier("idpoly"), "idpoly_");
        let long = "x".repeat(100);
        assert_eq!(sanitize_identifier(&long), "x".repeat(63));
        for s in ["", "1", "a b", "ärger", "\n", "end", &long, "😀"] {
            let id = sanitize_identifier(s);
            assert!(id.len() <= 63, "{id}");
            assert!(id.starts_with(|c: char| c.is_ascii_alphabetic()), "{id}");
            assert!(id.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'));
            assert!(!RESERVED.contains(&id.as_str()));
        }
    }

    #[test]
    fn g17_matches_printf() {
        // expected strings from Python's '%.17g' % x (C printf semantics)
        let cases: &[(f64, &str)] = &[
            (0.2, "0.20000000000000001"),
            (-0.8, "-0.80000000000000004"),
            (1.0, "1"),
            (0.0, "0"),
            (-0.0, "-0"),
            (1e-3, "0.001"),
            (5e-5, "5.0000000000000002e-05"),
            (1.5e-7, "1.4999999999999999e-07"),
            (123456.0, "123456"),
            (1e16, "10000000000000000"),
            (1e17, "1e+17"),
            (1.2345e20, "1.2345e+20"),
            (std::f64::consts::PI, "3.1415926535897931"),
            (0.0001, "0.0001"),
            (0.00012, "0.00012"),
            (f64::MAX, "1.7976931348623157e+308"),
            (f64::MIN_POSITIVE, "2.2250738585072014e-308"),
            (5e-324, "4.9406564584124654e-324"),
        ];
        for (x, want) in cases {
            assert_eq!(&format_g17(*x), want, "{x:e}");
        }
    }

    #[test]
    fn g17_round_trips() {
        let mut x = 0.123_456_789_f64;
        for _ in 0..2000 {
            for y in [x, -x, 1.0 / x, x * 1e-9, x * 1e12] {
                let s = format_g17(y);
                assert_eq!(s.parse::<f64>().unwrap().to_bits(), y.to_bits(), "{s}");
            }
            x = (x * 3.7 + 0.1).fract() + 1e-3;
        }
    }

    #[test]
    fn empty_polynomials_are_one() {
        let m = PolyModel::fir(vec![0.0, 0.5], 1e-3).unwrap();
        let vars = variables(ExportModel::Poly(&m), &names()).unwrap();
        for p in ["A", "C", "D", "F"] {
            let v = vars.iter().find(|v| v.name == p).unwrap();
            assert_eq!(v.value, Value::Vector(vec![1.0]), "{p}");
        }
        let nk = vars.iter().find(|v| v.name == "nk").unwrap();
        assert_eq!(nk.value, Value::Scalar(1.0));
        let text = matlab_script(ExportModel::Poly(&m), &names()).unwrap();
        for p in ["A", "C", "D", "F"] {
            assert!(text.contains(&format!("\n{p} = [1];\n")), "{p}: {text}");
        }
        assert!(text.contains("structure: fir"));
    }

    #[test]
    fn kalman_gain_is_checked() {
        let ss = StateSpace::discrete(
            mat![[0.5, 0.1], [0.0, 0.3]],
            mat![[1.0], [0.0]],
            mat![[1.0, 0.0]],
            mat![[0.0]],
            1e-3,
        )
        .unwrap();
        let k = [0.1, f64::NAN];
        let err = mat_bytes(ExportModel::StateSpace(&ss, Some(&k)), &names()).unwrap_err();
        assert!(matches!(
            err,
            ExportError::NonFinite {
                what: "K",
                index: 1,
                ..
            }
        ));
        assert!(
            err.to_string().contains("K[1] = NaN is not finite"),
            "{err}"
        );
        let k = [0.1, 0.2, 0.3];
        let err = npz_bytes(ExportModel::StateSpace(&ss, Some(&k)), &names()).unwrap_err();
        assert!(matches!(
            err,
            ExportError::KalmanGainLength {
                got: 3,
                states: 2,
                outputs: 1
            }
        ));
        let err = matlab_script(
            ExportModel::StateSpace(&ss, Some(&[f64::INFINITY, 0.0])),
            &names(),
        )
        .unwrap_err();
        assert!(err.to_string().contains("inf"), "{err}");
        // a valid gain
        let vars = variables(ExportModel::StateSpace(&ss, Some(&[0.1, 0.2])), &names()).unwrap();
        let k = vars.iter().find(|v| v.name == "K").unwrap();
        assert_eq!(
            k.value,
            Value::Matrix {
                rows: 2,
                cols: 1,
                data: vec![0.1, 0.2]
            }
        );
    }

    #[test]
    fn continuous_state_space_has_zero_ts() {
        let ss =
            StateSpace::continuous(mat![[-1.0]], mat![[1.0]], mat![[1.0]], mat![[0.0]]).unwrap();
        let vars = variables(ExportModel::StateSpace(&ss, None), &names()).unwrap();
        assert!(vars.iter().all(|v| v.name != "K"));
        let ts = vars.iter().find(|v| v.name == "Ts").unwrap();
        assert_eq!(ts.value, Value::Scalar(0.0));
    }
}
