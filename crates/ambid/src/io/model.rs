//! Model files (JSON, `docs/formats.md`): one object per model, polynomial or state space, with
//! the parameter standard deviations and fit statistics in `meta`.

use ambid_core::lti::{PolyModel, StateSpace};
use anyhow::{Context, Result};
use serde_json::{json, Value};
use std::path::Path;

/// The JSON object of a polynomial model (`kind = "polynomial"`).
pub fn polynomial_json(m: &PolyModel, input: &str, output: &str, meta: Value) -> Value {
    json!({
        "kind": "polynomial",
        "structure": m.structure().name(),
        "ts": m.ts(),
        "a": m.a(), "b": m.b(), "c": m.c(), "d": m.d(), "f": m.f(),
        "input": input, "output": output,
        "meta": meta,
    })
}

fn rows(m: faer::MatRef<'_, f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
        .collect()
}

/// The JSON object of a discrete state-space model (`kind = "state_space"`).
pub fn state_space_json(m: &StateSpace, input: &str, output: &str, meta: Value) -> Value {
    json!({
        "kind": "state_space",
        "ts": m.ts().unwrap_or(0.0),
        "a": rows(m.a()), "b": rows(m.b()), "c": rows(m.c()), "d": rows(m.d()),
        "input": input, "output": output,
        "meta": meta,
    })
}

/// Writes a model object as pretty JSON.
pub fn write_model_json(path: &Path, model: &Value) -> Result<()> {
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    std::fs::write(path, serde_json::to_string_pretty(model)?)
        .with_context(|| format!("cannot write {}", path.display()))
}
