//! Helpers shared by the CLI tests: run the `ambid` binary, read its output, temporary
//! directories and the twin's controller file.
#![allow(dead_code)] // each test binary uses a subset

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the `ambid` binary with `args`.
pub fn ambid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ambid"))
        .args(args)
        .output()
        .expect("the ambid binary runs")
}

/// Standard output followed by standard error.
pub fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A fresh, empty temporary directory for this test process and `name`.
pub fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ambid-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The twin's default controller as a controller file.
pub const CONTROLLER: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/fixtures/twin_controller.toml"
);

/// The `p`-quantile of `v` (linear interpolation between order statistics, numpy's default).
pub fn percentile(v: &[f64], p: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let pos = p * (s.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    s[lo] + (s[hi] - s[lo]) * (pos - lo as f64)
}

/// A file of the real data sets, `shared/data/real/<rel>`, in the first ancestor of this crate
/// that has it (the workspace's sibling `../shared`, also from a git worktree). When it is absent
/// the check is skipped with a printed note, except under CI (`CI` set), where missing data is a
/// failure: CI always has `shared/` beside the clone, so a skip there would hide a broken path.
#[allow(dead_code)]
pub fn real_data(rel: &str) -> Option<PathBuf> {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    let found = here
        .ancestors()
        .map(|a| a.join("shared/data/real").join(rel))
        .find(|p| p.exists());
    if found.is_none() {
        assert!(
            std::env::var_os("CI").is_none(),
            "shared/data/real/{rel} not found above {} (CI must have ../shared)",
            here.display()
        );
        println!("skipped: shared/data/real/{rel} is not present");
    }
    found
}
