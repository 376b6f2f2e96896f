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

/// Writes a model object as pretty JSON, replacing the file atomically (commands stage
/// [`model_json_bytes`] in an [`OutputSet`](crate::io::output::OutputSet) instead).
pub fn write_model_json(path: &Path, model: &Value) -> Result<()> {
    let mut set = crate::io::output::OutputSet::new(true);
    set.write(path, &model_json_bytes(model)?)?;
    set.commit()?;
    Ok(())
}

/// The pretty JSON text of a model object.
pub fn model_json_bytes(model: &Value) -> Result<Vec<u8>> {
    Ok(serde_json::to_string_pretty(model)?.into_bytes())
}

/// Reads a model file written by `ambid fit` (`kind = "state_space"` or `"polynomial"`) as a
/// discrete state-space model of its deterministic part $G$ (input → output). Every error
/// names the file and the field, and is an input failure (exit 3).
pub fn read_model_json(path: &Path) -> Result<StateSpace> {
    read_model_inner(path).map_err(|e| crate::workflow::input(e).into())
}

/// The kinds of model file.
const KINDS: &str = "\"state_space\" or \"polynomial\"";

fn read_model_inner(path: &Path) -> Result<StateSpace> {
    use anyhow::{anyhow, bail};
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let v: Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not valid JSON", path.display()))?;
    if !v.is_object() {
        bail!(
            "model file {}: expected a JSON object with `kind` ({KINDS}), `ts` and the model's arrays, as `ambid fit` writes it; got {}",
            path.display(),
            json_kind(&v)
        );
    }
    let kind = match v.get("kind") {
        None => bail!(
            "model file {}: missing field `kind` (expected {KINDS})",
            path.display()
        ),
        Some(Value::String(k)) => k.as_str(),
        Some(other) => bail!(
            "model file {}: field `kind` must be a string, {KINDS}; got {}",
            path.display(),
            json_kind(other)
        ),
    };
    if kind != "state_space" && kind != "polynomial" {
        bail!(
            "model file {}: unknown model kind \"{kind}\" (expected {KINDS})",
            path.display()
        );
    }
    let ts = match v.get("ts") {
        None => bail!(
            "model file {}: missing field `ts` (the sample time in s of the discrete model)",
            path.display()
        ),
        Some(t) => t
            .as_f64()
            .filter(|t| t.is_finite() && *t > 0.0)
            .ok_or_else(|| {
                anyhow!(
                    "model file {}: field `ts` must be a positive sample time in s; got {}",
                    path.display(),
                    json_kind(t)
                )
            })?,
    };
    let vec_of = |key: &str| -> Result<Vec<f64>> {
        v[key]
            .as_array()
            .ok_or_else(|| {
                anyhow!(
                    "model file {}: `{key}` must be an array of numbers",
                    path.display()
                )
            })?
            .iter()
            .map(|x| {
                x.as_f64().ok_or_else(|| {
                    anyhow!("model file {}: `{key}` holds a non-number", path.display())
                })
            })
            .collect()
    };
    let mat_of = |key: &str| -> Result<faer::Mat<f64>> {
        let rows = v[key].as_array().ok_or_else(|| {
            anyhow!(
                "model file {}: `{key}` must be an array of rows",
                path.display()
            )
        })?;
        let data: Vec<Vec<f64>> = rows
            .iter()
            .map(|r| {
                r.as_array()
                    .ok_or_else(|| {
                        anyhow!(
                            "model file {}: `{key}` must be an array of rows",
                            path.display()
                        )
                    })?
                    .iter()
                    .map(|x| {
                        x.as_f64().ok_or_else(|| {
                            anyhow!("model file {}: `{key}` holds a non-number", path.display())
                        })
                    })
                    .collect::<Result<Vec<f64>>>()
            })
            .collect::<Result<_>>()?;
        let nc = data.first().map_or(0, Vec::len);
        if data.iter().any(|r| r.len() != nc) {
            bail!(
                "model file {}: the rows of `{key}` differ in length",
                path.display()
            );
        }
        Ok(faer::Mat::from_fn(data.len(), nc, |i, j| data[i][j]))
    };
    if kind == "state_space" {
        Ok(
            StateSpace::discrete(mat_of("a")?, mat_of("b")?, mat_of("c")?, mat_of("d")?, ts)
                .with_context(|| {
                    format!(
                        "model file {}: inconsistent state-space matrices",
                        path.display()
                    )
                })?,
        )
    } else {
        let m = PolyModel::general(
            vec_of("a")?,
            vec_of("b")?,
            vec_of("c")?,
            vec_of("d")?,
            vec_of("f")?,
            ts,
        )
        .with_context(|| format!("model file {}: inconsistent polynomials", path.display()))?;
        Ok(m.g()?.to_state_space()?)
    }
}

/// A short description of a JSON value for messages (`an array`, `the number -1`, …).
fn json_kind(v: &Value) -> String {
    match v {
        Value::Null => "null".into(),
        Value::Bool(b) => format!("the boolean {b}"),
        Value::Number(n) => format!(
            "the number {}",
            n.as_f64()
                .map_or_else(|| n.to_string(), |x| format!("{x:.6e}"))
        ),
        Value::String(s) if s.len() <= 40 => format!("the string \"{s}\""),
        Value::String(_) => "a string".into(),
        Value::Array(_) => "an array".into(),
        Value::Object(_) => "an object".into(),
    }
}

/// The Kalman gain $K$ of an innovation-form model file (`meta.pem.kalman_gain`, written by
/// `ambid fit --structure ss` with the prediction focus), if present.
pub fn read_kalman_gain(path: &Path) -> Result<Option<Vec<f64>>> {
    read_kalman_inner(path).map_err(|e| crate::workflow::input(e).into())
}

fn read_kalman_inner(path: &Path) -> Result<Option<Vec<f64>>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let v: Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not valid JSON", path.display()))?;
    Ok(v["meta"]["pem"]["kalman_gain"]
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_f64).collect()))
}
