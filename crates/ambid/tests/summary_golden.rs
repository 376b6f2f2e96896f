//! Behaviour kept through refactoring (issue 19): the workflow's `summary.json` on the default
//! twin and on the two real-data example workflows equals the summary committed before the
//! pipeline refactor (`tests/fixtures/summary/*.json`, made by this test with `AMBID_BLESS=1` at
//! commit ae03c3b), every number to 1e-12 relative, every string and key exactly. The wall-clock
//! `timing` object is the only part left out: it differs between any two runs.
//!
//! A change that legitimately moves a number must be named (with its reason) in the issue note
//! and the fixture re-made with `AMBID_BLESS=1 cargo test -p ambid --test all summary_golden::`,
//! which writes the fixtures and then fails, so a blessing run never passes silently.

use crate::common;
use ambid::workflow::{self, Progress, Verbosity, WorkflowConfig};
use serde_json::Value;
use std::path::{Path, PathBuf};

const REL: f64 = 1e-12;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/summary")
        .join(format!("{name}.json"))
}

/// Every difference between `got` and `want` (numbers to [`REL`] relative), as `path: detail`.
fn diff(path: &str, got: &Value, want: &Value, out: &mut Vec<String>) {
    match (got, want) {
        (Value::Object(g), Value::Object(w)) => {
            for k in w.keys().filter(|k| !g.contains_key(*k)) {
                out.push(format!("{path}.{k}: missing"));
            }
            for k in g.keys().filter(|k| !w.contains_key(*k)) {
                out.push(format!("{path}.{k}: new key"));
            }
            for (k, wv) in w {
                if let Some(gv) = g.get(k) {
                    diff(&format!("{path}.{k}"), gv, wv, out);
                }
            }
        }
        (Value::Array(g), Value::Array(w)) => {
            if g.len() != w.len() {
                out.push(format!("{path}: length {} ≠ {}", g.len(), w.len()));
            }
            for (i, (gv, wv)) in g.iter().zip(w).enumerate() {
                diff(&format!("{path}[{i}]"), gv, wv, out);
            }
        }
        (Value::Number(g), Value::Number(w)) => {
            let (a, b) = (
                g.as_f64().unwrap_or(f64::NAN),
                w.as_f64().unwrap_or(f64::NAN),
            );
            let scale = a.abs().max(b.abs());
            if (a - b).abs() > REL * scale || a.is_nan() != b.is_nan() {
                out.push(format!("{path}: {a:e} ≠ {b:e}"));
            }
        }
        _ => {
            if got != want {
                out.push(format!("{path}: {got} ≠ {want}"));
            }
        }
    }
}

fn check(name: &str, cfg: &WorkflowConfig, base: &Path) {
    let mut progress = Progress::new(Verbosity::Quiet);
    let out = workflow::run(cfg, base, &mut progress)
        .unwrap_or_else(|e| panic!("{name}: workflow failed: {e}"));
    let mut got = out.summary.clone();
    if let Value::Object(m) = &mut got {
        m.remove(workflow::TIMING_KEY);
    }
    let path = fixture(name);
    if std::env::var_os("AMBID_BLESS").is_some() {
        let text = serde_json::to_string_pretty(&got).unwrap();
        std::fs::write(&path, text + "\n").unwrap();
        panic!(
            "AMBID_BLESS: wrote {}; rerun without AMBID_BLESS to check",
            path.display()
        );
    }
    let want: Value = serde_json::from_str(
        &std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap();
    let mut d = Vec::new();
    diff("summary", &got, &want, &mut d);
    assert!(
        d.is_empty(),
        "{name}: {} differences from the committed summary, first ones:\n{}",
        d.len(),
        d.iter().take(40).cloned().collect::<Vec<_>>().join("\n")
    );
}

fn example(name: &str) -> Option<(WorkflowConfig, PathBuf)> {
    let p = root().join("examples/workflows").join(name);
    let cfg = WorkflowConfig::from_path(&p).unwrap();
    Some((cfg, p.parent()?.to_path_buf()))
}

#[test]
fn the_default_twin_summary_equals_the_committed_one() {
    check("twin_default", &WorkflowConfig::default(), Path::new("."));
}

#[test]
fn the_robot_arm_summary_equals_the_committed_one() {
    if common::real_data("daisy-robot-arm/robot_arm.dat").is_none() {
        return;
    }
    let (cfg, base) = example("robot-arm.toml").unwrap();
    check("robot_arm", &cfg, &base);
}

#[test]
fn the_maglev_summary_equals_the_committed_one() {
    if common::real_data("magnetoshield-maglev/MagnetoShield_ID_Data.mat").is_none() {
        return;
    }
    let (cfg, base) = example("maglev.toml").unwrap();
    check("maglev", &cfg, &base);
}
