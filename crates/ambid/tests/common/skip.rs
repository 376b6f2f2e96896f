//! The one way a test skips a check: [`skip`] prints the reason loudly and records it, so the
//! test command (`bash .ci/run`, README "Tests") lists every skipped check in its last lines
//! instead of passing silently. Shared by every crate's tests (ambid-core includes this file
//! with `#[path]`).

use std::io::Write;
use std::path::PathBuf;

/// The file that collects the skipped checks: `$AMBID_SKIP_LOG` when set (`.ci/run` sets it),
/// else `<target>/ambid-skipped/skipped.txt` (beside `CARGO_TARGET_TMPDIR`).
pub fn skip_log() -> PathBuf {
    match std::env::var_os("AMBID_SKIP_LOG") {
        Some(p) => PathBuf::from(p),
        None => {
            let tmp = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
            tmp.parent()
                .unwrap_or(&tmp)
                .join("ambid-skipped")
                .join("skipped.txt")
        }
    }
}

/// Records that `check` (what was not verified, naming the test) was skipped because of
/// `reason` (what is missing and how to get it): a `SKIPPED:` line on stderr and a line
/// appended to [`skip_log`]. The caller then returns from the test.
pub fn skip(check: &str, reason: &str) {
    let line = format!("{check}: {reason}");
    eprintln!("SKIPPED: {line}");
    let path = skip_log();
    if let Some(dir) = path.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    match std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
    {
        // one write per line: appends of a short line from parallel tests do not interleave
        Ok(mut f) => {
            let _ = f.write_all(format!("{line}\n").as_bytes());
        }
        Err(e) => eprintln!("(could not record the skip in {}: {e})", path.display()),
    }
}
