//! Export of MIMO state-space models (the whole machine's 4×4 plant): the same four files as a
//! single-axis model (JSON, MATLAB `.m`, `.mat`, `.npz`, docs/export.md "MIMO models") with one
//! name per input and output channel (`u_xa … u_yb`, `y_xa … y_yb`) and the speed.
//!
//! Variables: `A` (n×n), `B` (n×nu), `C` (ny×n), `D` (ny×nu), `Ts` (0: continuous time),
//! `speed_rpm` (when known; NaN is refused), and the text `structure = "ss"`, `input_name` and
//! `output_name` (the channel names joined by commas, e.g. `"u_xa,u_xb,u_ya,u_yb"`: one text
//! variable, so every reader of the single-axis files reads these too) and `model_name`. The
//! `.m` script passes the names as cell arrays, `'InputName', {'u_xa', …}`, to `idss`/`ss`.

use super::{
    check_finite, mat5, matrix, npz, sanitize_identifier, var, ExportError, Result, Value, Var,
};
use ambid_core::lti::StateSpace;
use serde_json::{json, Value as Json};
use std::fmt::Write;

/// Names of a MIMO model's channels and its operating speed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MimoNames {
    /// Model name (sanitised into a MATLAB identifier).
    pub name: String,
    /// One name per input (e.g. `u_xa`); none may contain a comma.
    pub inputs: Vec<String>,
    /// One name per output (e.g. `y_xa`); none may contain a comma.
    pub outputs: Vec<String>,
    /// The speed the model holds at \[rpm\], if any.
    pub speed_rpm: Option<f64>,
}

impl MimoNames {
    /// The whole machine's names: inputs `u_<axis>`, outputs `y_<axis>` for `axes`.
    ///
    /// ```
    /// use ambid::io::export::mimo::MimoNames;
    /// let n = MimoNames::axes("plant_15000rpm", &["xa", "xb", "ya", "yb"], Some(15000.0));
    /// assert_eq!(n.inputs, ["u_xa", "u_xb", "u_ya", "u_yb"]);
    /// assert_eq!(n.outputs[3], "y_yb");
    /// ```
    pub fn axes(name: &str, axes: &[&str], speed_rpm: Option<f64>) -> Self {
        Self {
            name: name.into(),
            inputs: axes.iter().map(|a| format!("u_{a}")).collect(),
            outputs: axes.iter().map(|a| format!("y_{a}")).collect(),
            speed_rpm,
        }
    }
}

fn check_names(m: &StateSpace, n: &MimoNames) -> Result<()> {
    for (what, names, count) in [
        ("inputs", &n.inputs, m.ninputs()),
        ("outputs", &n.outputs, m.noutputs()),
    ] {
        if names.len() != count {
            return Err(ExportError::ChannelNames {
                what,
                got: names.len(),
                expected: count,
            });
        }
        if let Some(bad) = names.iter().find(|s| s.contains(',') || s.is_empty()) {
            return Err(ExportError::ChannelName { name: bad.clone() });
        }
    }
    Ok(())
}

/// The variables of a MIMO model, in the order they are written.
pub(crate) fn mimo_variables(m: &StateSpace, n: &MimoNames) -> Result<Vec<Var>> {
    check_names(m, n)?;
    let mut vars = vec![
        var("A", matrix("A", m.a())?),
        var("B", matrix("B", m.b())?),
        var("C", matrix("C", m.c())?),
        var("D", matrix("D", m.d())?),
    ];
    let ts = m.ts().unwrap_or(0.0);
    check_finite("Ts", &[ts])?;
    vars.push(var("Ts", Value::Scalar(ts)));
    if let Some(s) = n.speed_rpm {
        check_finite("speed_rpm", &[s])?;
        vars.push(var("speed_rpm", Value::Scalar(s)));
    }
    vars.push(var("structure", Value::Text("ss".into())));
    vars.push(var("input_name", Value::Text(n.inputs.join(","))));
    vars.push(var("output_name", Value::Text(n.outputs.join(","))));
    vars.push(var("model_name", Value::Text(sanitize_identifier(&n.name))));
    Ok(vars)
}

/// The JSON object of a MIMO state-space model: `kind = "state_space"` as a single-axis model,
/// with `inputs`/`outputs` (arrays of names) beside `input`/`output` (the names joined by
/// commas) and `speed_rpm`.
///
/// ```
/// use ambid::io::export::mimo::{mimo_json, MimoNames};
/// use ambid_core::lti::StateSpace;
/// use faer::Mat;
/// let m = StateSpace::new(Mat::identity(1, 1), Mat::zeros(1, 2), Mat::zeros(2, 1), Mat::zeros(2, 2), Some(1e-3)).unwrap();
/// let names = MimoNames { name: "g".into(), inputs: vec!["u_xa".into(), "u_xb".into()],
///     outputs: vec!["y_xa".into(), "y_xb".into()], speed_rpm: Some(0.0) };
/// let j = mimo_json(&m, &names, serde_json::json!({})).unwrap();
/// assert_eq!(j["inputs"][1], "u_xb");
/// assert_eq!(j["input"], "u_xa,u_xb");
/// assert_eq!(j["b"].as_array().unwrap().len(), 1); // n rows of nu
/// ```
///
/// # Errors
/// [`ExportError::ChannelNames`] when the names do not match the model's channels.
pub fn mimo_json(m: &StateSpace, n: &MimoNames, meta: Json) -> Result<Json> {
    check_names(m, n)?;
    let rows = |x: faer::MatRef<'_, f64>| -> Vec<Vec<f64>> {
        (0..x.nrows())
            .map(|i| (0..x.ncols()).map(|j| x[(i, j)]).collect())
            .collect()
    };
    Ok(json!({
        "kind": "state_space",
        "ts": m.ts().unwrap_or(0.0),
        "a": rows(m.a()), "b": rows(m.b()), "c": rows(m.c()), "d": rows(m.d()),
        "input": n.inputs.join(","), "output": n.outputs.join(","),
        "inputs": n.inputs, "outputs": n.outputs,
        "speed_rpm": n.speed_rpm,
        "meta": meta,
    }))
}

fn cell(names: &[String]) -> String {
    let q: Vec<String> = names
        .iter()
        .map(|s| super::script::matlab_string(s))
        .collect();
    format!("{{{}}}", q.join(", "))
}

/// A MATLAB script that rebuilds the model as an `idss` (System Identification Toolbox), else
/// an `ss` (Control System Toolbox), with `InputName`/`OutputName` per channel; without either
/// only the matrices. Numbers with 17 significant digits.
///
/// ```
/// use ambid::io::export::mimo::{mimo_matlab_script, MimoNames};
/// use ambid_core::lti::StateSpace;
/// use faer::Mat;
/// let m = StateSpace::new(Mat::identity(1, 1), Mat::zeros(1, 2), Mat::zeros(2, 1), Mat::zeros(2, 2), Some(1e-3)).unwrap();
/// let names = MimoNames { name: "g".into(), inputs: vec!["u_xa".into(), "u_xb".into()],
///     outputs: vec!["y_xa".into(), "y_xb".into()], speed_rpm: Some(15000.0) };
/// let s = mimo_matlab_script(&m, &names).unwrap();
/// assert!(s.contains("g = idss(A, B, C, D, zeros(1, 2), zeros(1, 1), Ts, 'InputName', {'u_xa', 'u_xb'}, 'OutputName', {'y_xa', 'y_xb'});"));
/// assert!(s.contains("speed_rpm = 15000;"));
/// ```
///
/// # Errors
/// [`ExportError::NonFinite`], [`ExportError::ChannelNames`], [`ExportError::ChannelName`].
pub fn mimo_matlab_script(m: &StateSpace, n: &MimoNames) -> Result<String> {
    let vars = mimo_variables(m, n)?;
    let id = sanitize_identifier(&n.name);
    let (nx, nu, ny) = (m.order(), m.ninputs(), m.noutputs());
    let io = format!(
        "'InputName', {}, 'OutputName', {}",
        cell(&n.inputs),
        cell(&n.outputs)
    );
    let mut s = String::new();
    let time = if m.ts().is_some() {
        "discrete-time"
    } else {
        "continuous-time"
    };
    // `write!` into a String cannot fail
    let _ = writeln!(
        s,
        "% {id}: {time} MIMO state-space model ({nx} states, {nu} inputs, {ny} outputs), exported by ambid {}",
        env!("CARGO_PKG_VERSION")
    );
    let _ = writeln!(s, "%");
    let _ = writeln!(
        s,
        "%   x(k+1) = A x(k) + B u(k), y(k) = C x(k) + D u(k) (Ts = 0: continuous time, dx/dt)"
    );
    let _ = writeln!(s, "%   inputs:  {}", n.inputs.join(", "));
    let _ = writeln!(s, "%   outputs: {}", n.outputs.join(", "));
    if let Some(sp) = n.speed_rpm {
        let _ = writeln!(
            s,
            "%   speed: {} rpm (the plant at this speed)",
            super::format_g17(sp)
        );
    }
    let _ = writeln!(
        s,
        "% Running this script defines A, B, C, D, Ts{} and {id}: an idss (System Identification",
        if n.speed_rpm.is_some() {
            ", speed_rpm"
        } else {
            ""
        }
    );
    let _ = writeln!(
        s,
        "% Toolbox) or else an ss (Control System Toolbox); without either, only the matrices."
    );
    let _ = writeln!(
        s,
        "% Numbers have 17 significant digits (%.17g). Conventions: docs/conventions.md, docs/export.md."
    );
    let _ = writeln!(s);
    for v in &vars {
        if matches!(v.value, Value::Text(_)) {
            continue;
        }
        let _ = writeln!(s, "{} = {};", v.name, super::script::matlab_value(&v.value));
    }
    let _ = writeln!(s, "if exist('idss')");
    let _ = writeln!(
        s,
        "  {id} = idss(A, B, C, D, zeros({nx}, {ny}), zeros({nx}, 1), Ts, {io});"
    );
    let _ = writeln!(s, "elseif exist('ss')");
    let _ = writeln!(s, "  {id} = ss(A, B, C, D, Ts, {io});");
    let _ = writeln!(s, "end");
    Ok(s)
}

/// The model as a MATLAB Level 5 `.mat` file (variables in the module docs).
///
/// # Errors
/// As [`mimo_matlab_script`], and [`ExportError::TooLarge`].
pub fn mimo_mat_bytes(m: &StateSpace, n: &MimoNames) -> Result<Vec<u8>> {
    mat5::encode(&super::header_text(), &mimo_variables(m, n)?)
}

/// The model as a NumPy `.npz` archive (variables in the module docs).
///
/// # Errors
/// As [`mimo_matlab_script`], and [`ExportError::Npz`].
pub fn mimo_npz_bytes(m: &StateSpace, n: &MimoNames) -> Result<Vec<u8>> {
    npz::encode(&mimo_variables(m, n)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;

    #[test]
    fn names_must_match_the_channels() {
        let m = StateSpace::new(
            Mat::identity(2, 2),
            Mat::zeros(2, 4),
            Mat::zeros(4, 2),
            Mat::zeros(4, 4),
            Some(5e-5),
        )
        .unwrap();
        let mut n = MimoNames::axes("p", &["xa", "xb", "ya", "yb"], Some(0.0));
        assert!(mimo_variables(&m, &n).is_ok());
        n.inputs.pop();
        let e = mimo_mat_bytes(&m, &n).unwrap_err().to_string();
        assert!(e.contains("3 names given for the model's 4 inputs"), "{e}");
        let mut n = MimoNames::axes("p", &["xa", "xb", "ya", "yb"], Some(f64::NAN));
        assert!(mimo_npz_bytes(&m, &n)
            .unwrap_err()
            .to_string()
            .contains("speed_rpm"));
        n.speed_rpm = None;
        n.outputs[0] = "y,xa".into();
        assert!(mimo_matlab_script(&m, &n)
            .unwrap_err()
            .to_string()
            .contains("y,xa"));
    }
}
