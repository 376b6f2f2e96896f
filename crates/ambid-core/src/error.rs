//! The one error type of `ambid-core`.
//!
//! Every fallible public function returns [`Result`]. Each variant says *what* is wrong and, where a
//! user can act on it, *what to do*; messages are complete sentences meant to be shown to a user
//! as they are.

/// Result alias used throughout `ambid-core`.
pub type Result<T> = std::result::Result<T, Error>;

/// Errors raised by `ambid-core`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An argument is outside its valid range or otherwise unusable.
    #[error("invalid argument `{name}`: {reason}")]
    InvalidArgument {
        /// Name of the argument or setting.
        name: &'static str,
        /// What is wrong and what to do.
        reason: String,
    },
    /// Two things that must agree in size do not.
    #[error("dimension mismatch in {context}: expected {expected}, got {got}")]
    DimensionMismatch {
        /// Where the mismatch was found.
        context: &'static str,
        /// The size that was required.
        expected: String,
        /// The size that was given.
        got: String,
    },
    /// A NaN or infinite value was found where finite data are required.
    #[error("non-finite value (NaN or ±inf) in `{what}` at sample {} (1-based); repair the sample or cut the record there", .index + 1)]
    NonFinite {
        /// Which input holds the value.
        what: &'static str,
        /// Position of the first offending value.
        index: usize,
    },
    /// Two models or data sets with different sample times were combined.
    #[error(
        "sample time mismatch: {left} s vs {right} s; resample or rediscretise one of them first"
    )]
    SampleTimeMismatch {
        /// Sample time of the left operand (0 for continuous time).
        left: f64,
        /// Sample time of the right operand (0 for continuous time).
        right: f64,
    },
    /// The operation needs a discrete-time model and got a continuous one (or vice versa).
    #[error("time domain mismatch: {0}")]
    TimeDomain(String),
    /// A numerical algorithm failed (no convergence, singular matrix, ...).
    #[error("numerical failure in {context}: {reason}")]
    Numerical {
        /// The algorithm that failed.
        context: &'static str,
        /// Why it failed and what may help.
        reason: String,
    },
    /// A system that must be stable is not.
    #[error("unstable system in {context}: {reason}")]
    Unstable {
        /// Where stability was required.
        context: &'static str,
        /// Details (e.g. the largest pole magnitude).
        reason: String,
    },
}

impl Error {
    /// Shorthand for [`Error::InvalidArgument`].
    pub fn invalid(name: &'static str, reason: impl Into<String>) -> Self {
        Error::InvalidArgument {
            name,
            reason: reason.into(),
        }
    }

    /// Shorthand for [`Error::Numerical`].
    pub fn numerical(context: &'static str, reason: impl Into<String>) -> Self {
        Error::Numerical {
            context,
            reason: reason.into(),
        }
    }
}

/// Returns an error naming the first non-finite element of `x`.
pub fn check_finite(what: &'static str, x: &[f64]) -> Result<()> {
    match x.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(Error::NonFinite { what, index }),
        None => Ok(()),
    }
}
