//! The one error type of `ambid-twin`.
//!
//! Every message is a complete sentence that says what is wrong and, where the user can act on it,
//! what to change.

/// Errors raised by the digital twin.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TwinError {
    /// A configuration value is out of range, non-finite or inconsistent.
    #[error("invalid twin configuration `{field}`: {reason}")]
    Config {
        /// Dotted path of the setting, e.g. `operating_point.air_gap_m`.
        field: String,
        /// What is wrong and what to do.
        reason: String,
    },
    /// The TOML text could not be parsed (syntax error, wrong type or unknown field).
    #[error("cannot read twin configuration TOML: {0}")]
    Toml(String),
    /// The configuration could not be written as TOML.
    #[error("cannot write twin configuration as TOML: {0}")]
    TomlWrite(String),
    /// The linearised closed loop (both bearings under their controllers) is unstable.
    #[error(
        "the linearised closed loop is unstable: largest closed-loop pole magnitude |z| = {max_pole_magnitude:.6} \
         (s = {s_re:.1} {s_im:+.1}j rad/s); {hint}"
    )]
    UnstableClosedLoop {
        /// Largest pole magnitude of the discrete closed loop (≥ 1).
        max_pole_magnitude: f64,
        /// Real part of that pole mapped to continuous time, s = ln(z)/Ts \[rad/s\].
        s_re: f64,
        /// Imaginary part of that pole mapped to continuous time \[rad/s\].
        s_im: f64,
        /// What to change.
        hint: String,
    },
    /// A non-finite value in an input signal.
    #[error("non-finite value (NaN or ±inf) in `{what}` at index {index} (sample {}, counted from 1); repair the signal before simulating", .index + 1)]
    NonFinite {
        /// Which signal holds the value.
        what: &'static str,
        /// Position of the first offending value.
        index: usize,
    },
    /// Two signals that must have the same length do not.
    #[error("length mismatch: `{what}` has {got} samples but {expected} are required (one per sample of `r`)")]
    LengthMismatch {
        /// Which signal has the wrong length.
        what: &'static str,
        /// Required length.
        expected: usize,
        /// Given length.
        got: usize,
    },
    /// An argument of a twin method is unusable.
    #[error("invalid argument `{name}`: {reason}")]
    InvalidArgument {
        /// Name of the argument.
        name: &'static str,
        /// What is wrong and what to do.
        reason: String,
    },
    /// The rotor reached the magnet (|x| ≥ air gap) during a simulation.
    #[error(
        "the rotor touched down at bearing {bearing} at t = {time_s:.6} s (sample {sample}): displacement \
         {displacement_m:.3e} m reached the air gap {gap_m:.3e} m; reduce the excitation amplitude \
         (or the reference w) and simulate again"
    )]
    Touchdown {
        /// `'A'` or `'B'`.
        bearing: char,
        /// Time of the event relative to the start of the record (negative during the pre-roll) \[s\].
        time_s: f64,
        /// Sample index of the control period in which it happened (relative to the record start).
        sample: i64,
        /// The displacement that reached the gap \[m\].
        displacement_m: f64,
        /// The air gap \[m\].
        gap_m: f64,
    },
    /// The simulation state became non-finite.
    #[error("the simulation diverged (non-finite state) at sample {sample}; reduce the excitation amplitude")]
    Diverged {
        /// Sample index relative to the record start.
        sample: i64,
    },
    /// An error from `ambid-core` (linear algebra, state-space models).
    #[error(transparent)]
    Core(#[from] ambid_core::Error),
}

/// Result alias of the twin.
pub type Result<T> = std::result::Result<T, TwinError>;
