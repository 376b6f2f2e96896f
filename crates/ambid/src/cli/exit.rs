//! The exit code of a failed command: one rule for every command (docs/workflow.md, "Exit
//! codes").

use ambid::error::FailureClass;
use ambid::io::OutputError;
use ambid::workflow::{ConfigError, Failure};

/// The exit code of an error: the class of the first typed error found walking the `anyhow`
/// chain from the outside in ([`ambid::error::Error::exit_code`] for the library's error; the
/// other typed errors by their kind), else 1.
///
/// | class | code |
/// |---|---|
/// | usage / configuration | 2 |
/// | input data | 3 |
/// | computation | 4 |
/// | output | 5 |
pub fn exit_code(e: &anyhow::Error) -> i32 {
    for c in e.chain() {
        if let Some(ae) = c.downcast_ref::<ambid::error::Error>() {
            return ae.exit_code();
        }
        if let Some(f) = c.downcast_ref::<Failure>() {
            return f.class.exit_code();
        }
        if c.is::<ConfigError>() {
            return FailureClass::Config.exit_code();
        }
        if c.is::<ambid::io::table::DataFileError>() {
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
