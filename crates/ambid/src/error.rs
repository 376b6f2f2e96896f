//! The application library's one error type, [`Error`], and its classes ([`FailureClass`]).
//!
//! Every fallible function of the `ambid` library returns [`Result`]; the error says what is
//! wrong and what to do, and carries its class, which is the process exit code of every `ambid`
//! command (`docs/workflow.md`, "Exit codes"): 0 success, 1 an error of no class, 2 usage (the
//! workflow file or a command-line option value), 3 input data, 4 computation, 5 output.
//! A binding (the Python package) maps the classes to its exception types; the binary maps them
//! to exit codes. Only the binary (`main.rs`, `cli/`) uses `anyhow`.
//!
//! ```
//! use ambid::error::{Context, Error, FailureClass};
//! let e: Result<(), Error> = Err(Error::input("column `y` holds text at row 3"));
//! let e = e.context("reading data.csv").unwrap_err();
//! assert_eq!(e.class(), Some(FailureClass::Input));
//! assert_eq!(e.to_string(), "reading data.csv: column `y` holds text at row 3");
//! // an ambid_core error keeps its own class: a refused argument is a usage error
//! let core = ambid_core::Error::invalid("order", "must be at least 1");
//! assert_eq!(Error::from(core).class(), Some(FailureClass::Config));
//! ```

use crate::config::ConfigError;
use crate::io::output::OutputError;
use crate::io::table::DataFileError;
use std::fmt::Display;

/// Classes of failure, each with its own process exit code.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailureClass {
    /// The workflow file is unreadable or wrong, or a command-line option value (or a
    /// combination of options) is refused (exit 2, as clap's own usage errors).
    Config,
    /// A data, controller or model file is missing, unreadable, malformed, holds NaN where a
    /// number is needed, or is too short (exit 3).
    Input,
    /// A computation failed on the data (exit 4).
    Computation,
    /// The outputs could not be written, or would overwrite without `--force` (exit 5).
    Output,
}

impl FailureClass {
    /// The process exit code.
    pub fn exit_code(self) -> i32 {
        match self {
            FailureClass::Config => 2,
            FailureClass::Input => 3,
            FailureClass::Computation => 4,
            FailureClass::Output => 5,
        }
    }
}

/// An error of the `ambid` library. Its [`Display`] is the whole message (context first, then
/// the cause), so it reads the same wherever it is printed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The workflow file is wrong (class [`FailureClass::Config`]).
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A data file is missing, unreadable or malformed (class [`FailureClass::Input`]).
    #[error(transparent)]
    DataFile(#[from] DataFileError),
    /// An output could not be written (class [`FailureClass::Output`]).
    #[error(transparent)]
    Output(#[from] OutputError),
    /// The core library refused or failed: a refused argument is a usage error, a non-finite
    /// sample an input error, anything else a computation error.
    #[error(transparent)]
    Core(#[from] ambid_core::Error),
    /// The twin refused or failed: a configuration that does not parse or a non-finite input
    /// is an input error, anything else a computation error.
    #[error(transparent)]
    Twin(#[from] ambid_twin::TwinError),
    /// A command-line option value or combination is refused (class [`FailureClass::Config`]).
    #[error("{0}")]
    Usage(String),
    /// Input data are wrong: too short, without excitation, inconsistent (class
    /// [`FailureClass::Input`]).
    #[error("{0}")]
    Input(String),
    /// A computation failed on the data (class [`FailureClass::Computation`]).
    #[error("{0}")]
    Computation(String),
    /// An error of no class (exit code 1).
    #[error("{0}")]
    Other(String),
    /// An error put in a class other than its own (e.g. a core error met while reading a
    /// file is an input error).
    #[error("{inner}")]
    Classified {
        /// The class it is given.
        class: FailureClass,
        /// The error.
        inner: Box<Error>,
    },
    /// An error with what was being done when it happened.
    #[error("{context}: {inner}")]
    Context {
        /// What was being done (e.g. the file read).
        context: String,
        /// The error.
        inner: Box<Error>,
    },
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// A usage error (exit 2).
    pub fn usage(msg: impl Into<String>) -> Self {
        Error::Usage(msg.into())
    }

    /// An input-data error (exit 3).
    pub fn input(msg: impl Into<String>) -> Self {
        Error::Input(msg.into())
    }

    /// A computation error (exit 4).
    pub fn computation(msg: impl Into<String>) -> Self {
        Error::Computation(msg.into())
    }

    /// An error of no class (exit 1).
    pub fn other(msg: impl Into<String>) -> Self {
        Error::Other(msg.into())
    }

    /// `e` put in class `class`, whatever its own.
    pub fn classified(class: FailureClass, e: impl Into<Error>) -> Self {
        Error::Classified {
            class,
            inner: Box::new(e.into()),
        }
    }

    /// This error with what was being done in front of its message.
    pub fn context(self, context: impl Display) -> Self {
        Error::Context {
            context: context.to_string(),
            inner: Box::new(self),
        }
    }

    /// The class: the outermost one given ([`Error::classified`]) or the error's own; `None`
    /// for an error of no class.
    pub fn class(&self) -> Option<FailureClass> {
        Some(match self {
            Error::Config(_) | Error::Usage(_) => FailureClass::Config,
            Error::DataFile(_) | Error::Input(_) => FailureClass::Input,
            Error::Output(_) => FailureClass::Output,
            Error::Computation(_) => FailureClass::Computation,
            Error::Core(ce) => core_class(ce),
            Error::Twin(te) => twin_class(te),
            Error::Other(_) => return None,
            Error::Classified { class, .. } => *class,
            Error::Context { inner, .. } => return inner.class(),
        })
    }

    /// The process exit code of this error (1 when it has no class).
    pub fn exit_code(&self) -> i32 {
        self.class().map_or(1, FailureClass::exit_code)
    }

    /// The exit code of `e` when it is one of the library's typed errors ([`Error`] or one it
    /// wraps), by the same rule as [`Error::exit_code`]; `None` for any other type. The
    /// binary walks an error chain with it.
    ///
    /// ```
    /// use ambid::error::Error;
    /// let core = ambid_core::Error::invalid("order", "must be at least 1");
    /// assert_eq!(Error::exit_code_of(&core), Some(2));
    /// assert_eq!(Error::exit_code_of(&Error::other("?")), Some(1));
    /// assert_eq!(Error::exit_code_of(&std::fmt::Error), None);
    /// ```
    pub fn exit_code_of(e: &(dyn std::error::Error + 'static)) -> Option<i32> {
        let class = if let Some(ae) = e.downcast_ref::<Error>() {
            return Some(ae.exit_code());
        } else if e.is::<ConfigError>() {
            FailureClass::Config
        } else if e.is::<DataFileError>() {
            FailureClass::Input
        } else if e.is::<OutputError>() {
            FailureClass::Output
        } else if let Some(ce) = e.downcast_ref::<ambid_core::Error>() {
            core_class(ce)
        } else if let Some(te) = e.downcast_ref::<ambid_twin::TwinError>() {
            twin_class(te)
        } else {
            return None;
        };
        Some(class.exit_code())
    }
}

/// The class of a core error: a refused argument (an option's value; the message names it) is
/// a usage error, a non-finite sample an input error, anything else a computation error.
fn core_class(e: &ambid_core::Error) -> FailureClass {
    match e {
        ambid_core::Error::NonFinite { .. } => FailureClass::Input,
        ambid_core::Error::InvalidArgument { .. } => FailureClass::Config,
        _ => FailureClass::Computation,
    }
}

/// The class of a twin error: a configuration that does not parse or a non-finite input is
/// an input error, anything else a computation error.
fn twin_class(e: &ambid_twin::TwinError) -> FailureClass {
    match e {
        ambid_twin::TwinError::Toml(_) | ambid_twin::TwinError::NonFinite { .. } => {
            FailureClass::Input
        }
        _ => FailureClass::Computation,
    }
}

/// `.context(…)` and `.with_context(…)` on any result whose error converts into [`Error`].
pub trait Context<T> {
    /// Puts `context` in front of the error's message.
    ///
    /// # Errors
    /// The error, with the context.
    fn context(self, context: impl Display) -> Result<T>;

    /// As [`Context::context`], with the context made only on error.
    ///
    /// # Errors
    /// The error, with the context.
    fn with_context<D: Display>(self, context: impl FnOnce() -> D) -> Result<T>;
}

impl<T, E: Into<Error>> Context<T> for std::result::Result<T, E> {
    fn context(self, context: impl Display) -> Result<T> {
        self.map_err(|e| e.into().context(context))
    }

    fn with_context<D: Display>(self, context: impl FnOnce() -> D) -> Result<T> {
        self.map_err(|e| e.into().context(context()))
    }
}
