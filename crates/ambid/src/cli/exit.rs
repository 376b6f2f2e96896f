//! The exit code of a failed command: one rule for every command (docs/workflow.md, "Exit
//! codes").

/// The exit code of an error: that of the first typed error found walking the `anyhow` chain
/// from the outside in ([`ambid::error::Error::exit_code_of`], the library's one rule), else 1.
///
/// | class | code |
/// |---|---|
/// | usage / configuration | 2 |
/// | input data | 3 |
/// | computation | 4 |
/// | output | 5 |
pub fn exit_code(e: &anyhow::Error) -> i32 {
    e.chain()
        .find_map(ambid::error::Error::exit_code_of)
        .unwrap_or(1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ambid::error::Error;
    use ambid::error::FailureClass;

    #[test]
    fn typed_errors_give_their_class_code_through_any_context() {
        let usage = anyhow::Error::from(Error::usage("--na-max must be at least 1"));
        assert_eq!(exit_code(&usage), 2);
        assert_eq!(exit_code(&usage.context("fit")), 2);
        let data = anyhow::Error::from(Error::from(ambid::io::table::DataFileError::NoData {
            path: "x.csv".into(),
            message: "needs at least 2 data rows, found 1".into(),
        }));
        assert_eq!(exit_code(&data), 3);
        // the library's error wrapping a data-file error in a context keeps the input class
        let ctx = anyhow::Error::from(Error::input("short").context("reading x.csv"));
        assert_eq!(exit_code(&ctx), 3);
        assert_eq!(
            exit_code(&anyhow::Error::from(Error::computation("no fit"))),
            4
        );
        assert_eq!(exit_code(&anyhow::Error::from(Error::other("?"))), 1);
        // a typed error put in another class keeps the class given
        let cls = Error::classified(FailureClass::Input, Error::other("bad controller file"));
        assert_eq!(exit_code(&anyhow::Error::from(cls)), 3);
        let out = Error::classified(FailureClass::Output, Error::other("disk full"));
        assert_eq!(exit_code(&anyhow::Error::from(out).context("writing")), 5);
        // the other typed errors met in the chain keep their class
        let core = ambid_core::Error::invalid("order", "must be at least 1");
        assert_eq!(exit_code(&anyhow::Error::from(core)), 2);
        assert_eq!(exit_code(&anyhow::anyhow!("plain")), 1);
    }
}
