//! Model files (JSON, `docs/formats.md`): one object per model, polynomial or state space, with
//! the parameter standard deviations and fit statistics in `meta`.

use crate::error::FailureClass;
use crate::error::{Context, Error, Result};
use ambid_core::lti::{PolyModel, StateSpace};
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
    Ok(serde_json::to_string_pretty(model)
        .map_err(|e| Error::other(e.to_string()))?
        .into_bytes())
}

/// Reads a model file written by `ambid fit` (`kind = "state_space"` or `"polynomial"`) as a
/// discrete state-space model of its deterministic part $G$ (input → output). Every error
/// names the file and the field, and is an input failure (exit 3).
pub fn read_model_json(path: &Path) -> Result<StateSpace> {
    read_model_inner(path).map_err(|e| Error::classified(FailureClass::Input, e))
}

/// The kinds of model file.
const KINDS: &str = "\"state_space\" or \"polynomial\"";

fn read_model_inner(path: &Path) -> Result<StateSpace> {
    match read_model_value(path)?.0 {
        Parsed::StateSpace(ss) => Ok(ss),
        Parsed::Poly(m) => Ok(m.g()?.to_state_space()?),
    }
}

/// A model file parsed in its own form.
#[derive(Debug, Clone)]
pub enum Parsed {
    /// A polynomial model (`kind = "polynomial"`, with its `structure`: `oe` stays `oe`).
    Poly(PolyModel),
    /// A discrete state-space model (`kind = "state_space"`).
    StateSpace(StateSpace),
}

/// A model file read back for export: its polynomial or state-space form, the Kalman gain
/// (`meta.pem.kalman_gain`), the signal names and the noise variance (`meta.noise_variance`).
#[derive(Debug, Clone)]
pub struct ModelFile {
    /// The model in the form the file holds.
    pub model: Parsed,
    /// Kalman gain of an innovations-form state-space model.
    pub kalman: Option<Vec<f64>>,
    /// Model name (the file stem), signal names and noise variance for the export.
    pub names: crate::io::export::ExportNames,
}

impl ModelFile {
    /// The model as [`crate::io::export`] takes it.
    pub fn export_model(&self) -> crate::io::export::ExportModel<'_> {
        use crate::io::export::ExportModel;
        match &self.model {
            Parsed::Poly(p) => ExportModel::Poly(p),
            Parsed::StateSpace(ss) => ExportModel::StateSpace(ss, self.kalman.as_deref()),
        }
    }
}

/// Reads a model file written by `ambid fit`, `ambid freqfit` or `ambid run` (`models/*.json`)
/// in its own form, for [`write_model_exports`]. Errors name the file and the field (exit 3).
pub fn read_model_file(path: &Path) -> Result<ModelFile> {
    (|| -> Result<ModelFile> {
        let (parsed, v) = read_model_value(path)?;
        let text = |k: &str, d: &str| v[k].as_str().unwrap_or(d).to_string();
        let names = crate::io::export::ExportNames {
            name: path
                .file_stem()
                .map_or("model".into(), |s| s.to_string_lossy().into_owned()),
            input: text("input", "u"),
            output: text("output", "y"),
            noise_variance: v["meta"]["noise_variance"]
                .as_f64()
                .filter(|x| x.is_finite() && *x >= 0.0),
        };
        let kalman = v["meta"]["pem"]["kalman_gain"]
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_f64).collect());
        let kalman = match parsed {
            Parsed::StateSpace(_) => kalman,
            Parsed::Poly(_) => None,
        };
        Ok(ModelFile {
            model: parsed,
            kalman,
            names,
        })
    })()
    .map_err(|e| Error::classified(FailureClass::Input, e))
}

/// Writes the MATLAB script, `.mat` and `.npz` exports (`docs/export.md`) of the model file
/// `json` as `<stem>.m`, `<stem>.mat`, `<stem>.npz` beside it; returns the paths written. A
/// polynomial model file (ARX, OE, BJ, …) is exported as polynomials (`idpoly`), a state-space
/// one as matrices (`idss`).
pub fn write_model_exports(json: &Path) -> Result<Vec<std::path::PathBuf>> {
    use crate::io::export::{mat_bytes, matlab_script, npz_bytes};
    let m = read_model_file(json)?;
    let em = m.export_model();
    let files: [(&str, Vec<u8>); 3] = [
        (
            "m",
            matlab_script(em, &m.names)
                .map_err(export_error)?
                .into_bytes(),
        ),
        ("mat", mat_bytes(em, &m.names).map_err(export_error)?),
        ("npz", npz_bytes(em, &m.names).map_err(export_error)?),
    ];
    let mut set = crate::io::output::OutputSet::new(true);
    let mut out = Vec::new();
    for (ext, bytes) in files {
        let p = json.with_extension(ext);
        set.write(&p, &bytes)?;
        out.push(p);
    }
    set.commit()?;
    Ok(out)
}

/// An export error as an error of no class (its message kept, as before).
fn export_error(e: crate::io::export::ExportError) -> Error {
    Error::other(e.to_string())
}

fn read_model_value(path: &Path) -> Result<(Parsed, Value)> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::other(e.to_string()))
        .with_context(|| format!("cannot read {}", path.display()))?;
    let v: Value = serde_json::from_str(&text)
        .map_err(|e| Error::other(e.to_string()))
        .with_context(|| format!("{}: not valid JSON", path.display()))?;
    if !v.is_object() {
        return Err(Error::other(format!(
            "model file {}: expected a JSON object with `kind` ({KINDS}), `ts` and the model's arrays, as `ambid fit` writes it; got {}",
            path.display(),
            json_kind(&v)
        )));
    }
    let kind = match v.get("kind") {
        None => {
            return Err(Error::other(format!(
                "model file {}: missing field `kind` (expected {KINDS})",
                path.display()
            )))
        }
        Some(Value::String(k)) => k.as_str(),
        Some(other) => {
            return Err(Error::other(format!(
                "model file {}: field `kind` must be a string, {KINDS}; got {}",
                path.display(),
                json_kind(other)
            )))
        }
    };
    if kind != "state_space" && kind != "polynomial" {
        return Err(Error::other(format!(
            "model file {}: unknown model kind \"{kind}\" (expected {KINDS})",
            path.display()
        )));
    }
    let ts = match v.get("ts") {
        None => {
            return Err(Error::other(format!(
                "model file {}: missing field `ts` (the sample time in s of the discrete model)",
                path.display()
            )))
        }
        Some(t) => t
            .as_f64()
            .filter(|t| t.is_finite() && *t > 0.0)
            .ok_or_else(|| {
                Error::other(format!(
                    "model file {}: field `ts` must be a positive sample time in s; got {}",
                    path.display(),
                    json_kind(t)
                ))
            })?,
    };
    let vec_of = |key: &str| -> Result<Vec<f64>> {
        v[key]
            .as_array()
            .ok_or_else(|| {
                Error::other(format!(
                    "model file {}: `{key}` must be an array of numbers",
                    path.display()
                ))
            })?
            .iter()
            .map(|x| {
                x.as_f64().ok_or_else(|| {
                    Error::other(format!(
                        "model file {}: `{key}` holds a non-number",
                        path.display()
                    ))
                })
            })
            .collect()
    };
    let mat_of = |key: &str| -> Result<faer::Mat<f64>> {
        let rows = v[key].as_array().ok_or_else(|| {
            Error::other(format!(
                "model file {}: `{key}` must be an array of rows",
                path.display()
            ))
        })?;
        let data: Vec<Vec<f64>> = rows
            .iter()
            .map(|r| {
                r.as_array()
                    .ok_or_else(|| {
                        Error::other(format!(
                            "model file {}: `{key}` must be an array of rows",
                            path.display()
                        ))
                    })?
                    .iter()
                    .map(|x| {
                        x.as_f64().ok_or_else(|| {
                            Error::other(format!(
                                "model file {}: `{key}` holds a non-number",
                                path.display()
                            ))
                        })
                    })
                    .collect::<Result<Vec<f64>>>()
            })
            .collect::<Result<_>>()?;
        let nc = data.first().map_or(0, Vec::len);
        if data.iter().any(|r| r.len() != nc) {
            return Err(Error::other(format!(
                "model file {}: the rows of `{key}` differ in length",
                path.display()
            )));
        }
        Ok(faer::Mat::from_fn(data.len(), nc, |i, j| data[i][j]))
    };
    if kind == "state_space" {
        let ss = StateSpace::discrete(mat_of("a")?, mat_of("b")?, mat_of("c")?, mat_of("d")?, ts)
            .with_context(|| {
            format!(
                "model file {}: inconsistent state-space matrices",
                path.display()
            )
        })?;
        Ok((Parsed::StateSpace(ss), v))
    } else {
        use ambid_core::lti::Structure;
        let structure = [
            Structure::Fir,
            Structure::Arx,
            Structure::Armax,
            Structure::Oe,
            Structure::Bj,
        ]
        .into_iter()
        .find(|s| v["structure"].as_str() == Some(s.name()))
        .unwrap_or(Structure::General);
        let (a, b, c, d, f) = (
            vec_of("a")?,
            vec_of("b")?,
            vec_of("c")?,
            vec_of("d")?,
            vec_of("f")?,
        );
        // the file's structure tag when its polynomials fit it, else the general structure
        let m = PolyModel::new(
            structure,
            a.clone(),
            b.clone(),
            c.clone(),
            d.clone(),
            f.clone(),
            ts,
        )
        .or_else(|_| PolyModel::general(a, b, c, d, f, ts))
        .with_context(|| format!("model file {}: inconsistent polynomials", path.display()))?;
        Ok((Parsed::Poly(m), v))
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
    read_kalman_inner(path).map_err(|e| Error::classified(FailureClass::Input, e))
}

fn read_kalman_inner(path: &Path) -> Result<Option<Vec<f64>>> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::other(e.to_string()))
        .with_context(|| format!("cannot read {}", path.display()))?;
    let v: Value = serde_json::from_str(&text)
        .map_err(|e| Error::other(e.to_string()))
        .with_context(|| format!("{}: not valid JSON", path.display()))?;
    Ok(v["meta"]["pem"]["kalman_gain"]
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_f64).collect()))
}
