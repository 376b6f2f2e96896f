//! Export of an uncertain plant model with several inputs and outputs (the whole machine's 4×4
//! plant, issue 23): the nominal model $\hat P$, one relative weight per entry,
//! $$ P_{ij} = \hat P_{ij}\,(1 + W_{ij}\,\delta_{ij}), \qquad |\delta_{ij}| \le 1 \text{ independent,
//! stable,} $$
//! the per-line element-wise additive bound $L_{ij,k}$ of the check on the lines (in the workflow
//! the weights overbound it relative to $|\hat P_{ij}|$ after it is scaled down to their own,
//! lower raise: `weight_raise / raise`), and the robust-stability figures on the lines and against the weights — as a
//! MATLAB script that builds the uncertain model (one `ultidyn` per entry), a MATLAB `.mat`, a
//! NumPy `.npz` and a JSON file (docs/export.md, "Uncertain MIMO plant models").
//!
//! Entry $(i, j)$ (output $i$, input $j$) is stored at index $e = i + j\,n_y$ (zero-based; MATLAB's
//! column-major linear index $e + 1$). Each weight is exported in zero–pole–gain form, as for a
//! SISO uncertain model ([`super::uncertain`]). Variables (numbers):
//!
//! | variable | meaning |
//! |---|---|
//! | `A`, `B`, `C`, `D`, `Ts`, `speed_rpm` | the nominal model $\hat P$ (as a MIMO model export) |
//! | `W_gain`, `W_order` | $n_y\times n_u$: each entry weight's gain $k_{ij}$ and order $n_{ij}$ |
//! | `W_zeros_re`, `W_zeros_im`, `W_poles_re`, `W_poles_im` | $n_yn_u\times 4$: row $e$ holds entry $e$'s zeros (poles) in its first $n_{ij}$ columns, zeros after |
//! | `f_hz` | the FRF lines of the bound \[Hz\] |
//! | `bound_additive` | lines × $n_yn_u$: column $e$ is $L_{ij,k}$ (plant units) |
//! | `lines_stability_margin`, `lines_upper_gain_margin`, `lines_lower_gain_margin` | the element-wise test on the lines |
//! | `weight_stability_margin`, `weight_upper_gain_margin`, `weight_lower_gain_margin` | the same against the weights |
//!
//! (a margin is left out when the loop is not robustly stable, or unlimited) and the text
//! variables `uncertainty = "entry_relative"`, `structure = "ss"`, `input_name`, `output_name`
//! (channel names joined by commas) and `model_name`.

use super::mimo::MimoNames;
use super::{
    check_finite, mat5, matrix, npz, sanitize_identifier, script, var, ExportError, Result, Value,
    Var,
};
use ambid_core::lti::StateSpace;
use ambid_core::validate::robust::RobustStability;
use ambid_core::validate::weight::{WeightFit, MAX_WEIGHT_ORDER};
use serde_json::{json, Value as Json};
use std::fmt::Write;

/// What an uncertain MIMO model export holds (owned: the workflow keeps it per speed).
#[derive(Debug, Clone, PartialEq)]
pub struct UncertainMatrixModel {
    /// The nominal model $\hat P$ ($n_y\times n_u$, discrete).
    pub nominal: StateSpace,
    /// The lines of the bound \[Hz\].
    pub f_hz: Vec<f64>,
    /// Per entry $e = i + j n_y$, the additive bound $L_{ij,k}$ on the lines.
    pub bounds: Vec<Vec<f64>>,
    /// Per entry, its relative weight.
    pub weights: Vec<WeightFit>,
    /// The element-wise robust test on the lines.
    pub on_lines: RobustStability,
    /// The same test against the weights.
    pub on_weights: RobustStability,
}

fn check(u: &UncertainMatrixModel) -> Result<()> {
    let entries = u.nominal.noutputs() * u.nominal.ninputs();
    for (what, got) in [("weights", u.weights.len()), ("bounds", u.bounds.len())] {
        if got != entries {
            return Err(ExportError::Length {
                what,
                got,
                expected: entries,
            });
        }
    }
    if let Some(b) = u.bounds.iter().find(|b| b.len() != u.f_hz.len()) {
        return Err(ExportError::Length {
            what: "bound_additive",
            got: b.len(),
            expected: u.f_hz.len(),
        });
    }
    if let Some(w) = u
        .weights
        .iter()
        .find(|w| w.weight.order() > MAX_WEIGHT_ORDER)
    {
        return Err(ExportError::Length {
            what: "W_order",
            got: w.weight.order(),
            expected: MAX_WEIGHT_ORDER,
        });
    }
    Ok(())
}

/// The robust figures of one test as the scalars `names` (stability margin, upper and lower
/// gain margin; finite ones only).
fn robust_vars(names: [&'static str; 3], r: &RobustStability, vars: &mut Vec<Var>) {
    for (name, x) in names.into_iter().zip([
        Some(r.stability_margin),
        r.upper_gain_margin,
        r.lower_gain_margin,
    ]) {
        if let Some(x) = x.filter(|x| x.is_finite()) {
            vars.push(var(name, Value::Scalar(x)));
        }
    }
}

/// The variables (module docs), in the order they are written, after checking every number.
pub(crate) fn uncertain_matrix_variables(
    u: &UncertainMatrixModel,
    names: &MimoNames,
) -> Result<Vec<Var>> {
    check(u)?;
    let mut vars = super::mimo::mimo_variables(&u.nominal, names)?;
    // the text variables go last, after the numbers
    let texts: Vec<Var> = vars
        .iter()
        .filter(|v| matches!(v.value, Value::Text(_)))
        .cloned()
        .collect();
    vars.retain(|v| !matches!(v.value, Value::Text(_)));
    let (ny, nu) = (u.nominal.noutputs(), u.nominal.ninputs());
    let n = ny * nu;
    let gain = faer::Mat::from_fn(ny, nu, |i, j| u.weights[i + j * ny].weight.gain);
    let order = faer::Mat::from_fn(ny, nu, |i, j| u.weights[i + j * ny].weight.order() as f64);
    vars.push(var("W_gain", matrix("W_gain", gain.as_ref())?));
    vars.push(var("W_order", matrix("W_order", order.as_ref())?));
    let roots = |poles: bool, imag: bool| {
        faer::Mat::from_fn(n, MAX_WEIGHT_ORDER, |e, c| {
            let w = &u.weights[e].weight;
            let r = if poles { w.poles() } else { w.zeros() };
            r.get(c).map_or(0.0, |z| if imag { z.im } else { z.re })
        })
    };
    for (name, poles, imag) in [
        ("W_zeros_re", false, false),
        ("W_zeros_im", false, true),
        ("W_poles_re", true, false),
        ("W_poles_im", true, true),
    ] {
        vars.push(var(name, matrix(name, roots(poles, imag).as_ref())?));
    }
    check_finite("f_hz", &u.f_hz)?;
    vars.push(var("f_hz", Value::Vector(u.f_hz.clone())));
    let bounds = faer::Mat::from_fn(u.f_hz.len(), n, |k, e| u.bounds[e][k]);
    vars.push(var(
        "bound_additive",
        matrix("bound_additive", bounds.as_ref())?,
    ));
    robust_vars(
        [
            "lines_stability_margin",
            "lines_upper_gain_margin",
            "lines_lower_gain_margin",
        ],
        &u.on_lines,
        &mut vars,
    );
    robust_vars(
        [
            "weight_stability_margin",
            "weight_upper_gain_margin",
            "weight_lower_gain_margin",
        ],
        &u.on_weights,
        &mut vars,
    );
    vars.push(var("uncertainty", Value::Text("entry_relative".into())));
    vars.extend(texts);
    Ok(vars)
}

/// A MATLAB script that defines the variables (module docs) and builds, with the Robust Control
/// Toolbox, the uncertain model `<name> = Pnom + Σ e_i (Pnom(i,j) W_ij Delta_ij) e_jᵀ` with one
/// `Delta_ij = ultidyn('D_<output>_<input>', [1 1])` per entry and `W_ij =
/// zpk(zeros, poles, gain, Ts)` (the cell array `W`); with only the Control System Toolbox it
/// builds `Pnom` and `W`; without it (Octave) only the numbers. The uncertain model carries the
/// nominal model's states once per entry: apply `minreal`/`simplify` as the design needs.
///
/// ```
/// use ambid::io::export::mimo::MimoNames;
/// use ambid::io::export::uncertain_matrix::{uncertain_matrix_matlab_script, UncertainMatrixModel};
/// use ambid_core::lti::StateSpace;
/// use ambid_core::validate::robust::{robust_stability_matrix_on_lines, robust_stability_matrix_weight, LineBound, MatrixWeight};
/// use ambid_core::validate::weight::{fit_weight, WeightFit};
/// use faer::{mat, Mat};
/// let ts = 1e-3;
/// let p = StateSpace::discrete(mat![[0.9, 0.0], [0.0, 0.5]], mat![[1.0, 0.0], [0.0, 1.0]],
///     mat![[0.1, 0.0], [0.0, 0.1]], mat![[0.0, 0.01], [0.01, 0.0]], ts).unwrap();
/// let c = StateSpace::discrete(Mat::zeros(0, 0), Mat::zeros(0, 2), Mat::zeros(2, 0),
///     mat![[2.0, 0.0], [0.0, 2.0]], ts).unwrap();
/// let f: Vec<f64> = (1..=50).map(|k| 8.0 * k as f64).collect();
/// let rel = vec![0.05; f.len()];
/// let weights: Vec<WeightFit> = (0..4).map(|_| fit_weight(&f, &rel, ts, 1, 1.0).unwrap()).collect();
/// let resp = p.freq_response(&f).unwrap();
/// let bounds: Vec<Vec<f64>> = (0..4)
///     .map(|e| resp.iter().map(|m| 0.05 * m[(e % 2, e / 2)].norm()).collect())
///     .collect();
/// let lines: Vec<Mat<f64>> = (0..f.len()).map(|k| Mat::from_fn(2, 2, |i, j| bounds[i + 2 * j][k])).collect();
/// let ws: Vec<_> = weights.iter().map(|w| w.weight.clone()).collect();
/// let u = UncertainMatrixModel {
///     on_lines: robust_stability_matrix_on_lines(&p, &c, &f, LineBound::Elementwise(&lines)).unwrap(),
///     on_weights: robust_stability_matrix_weight(&p, &c, MatrixWeight::EntryRelative(&ws)).unwrap(),
///     nominal: p, f_hz: f, bounds, weights,
/// };
/// let names = MimoNames::axes("plant A", &["xa", "xb"], Some(15000.0));
/// let s = uncertain_matrix_matlab_script(&u, &names).unwrap();
/// assert!(s.contains("ultidyn(sprintf('D_%s_%s', outs{i}, ins{j}), [1 1])"));
/// assert!(s.contains("W_order = ") && s.contains("bound_additive = "));
/// ```
///
/// # Errors
/// [`ExportError::NonFinite`], [`ExportError::ChannelNames`]/[`ExportError::ChannelName`] for
/// names that do not match the model, [`ExportError::Length`] for weights or bounds of the wrong
/// number or length.
pub fn uncertain_matrix_matlab_script(
    u: &UncertainMatrixModel,
    names: &MimoNames,
) -> Result<String> {
    let vars = uncertain_matrix_variables(u, names)?;
    let id = sanitize_identifier(&names.name);
    let cell = |v: &[String]| {
        let q: Vec<String> = v.iter().map(|s| script::matlab_string(s)).collect();
        format!("{{{}}}", q.join(", "))
    };
    let (ins, outs) = (cell(&names.inputs), cell(&names.outputs));
    let (ny, nu) = (u.nominal.noutputs(), u.nominal.ninputs());
    let mut s = String::new();
    // `write!` into a String cannot fail; the results are ignored on purpose.
    let _ = writeln!(
        s,
        "% {id}: uncertain plant P(i,j) = Pnom(i,j) (1 + W{{i,j}} Delta_ij), |Delta_ij| <= 1, exported by ambid {}",
        env!("CARGO_PKG_VERSION")
    );
    let _ = writeln!(s, "%");
    let _ = writeln!(
        s,
        "%   Pnom: the nominal model ({} states, {ny} outputs, {nu} inputs), unstable poles kept",
        u.nominal.order()
    );
    let _ = writeln!(
        s,
        "%   W{{i,j}}: one relative weight per entry (order <= {MAX_WEIGHT_ORDER}, stable, minimum phase), zero-pole-gain:"
    );
    let _ = writeln!(
        s,
        "%         entry e = i + (j-1)*{ny}: W_gain(i,j) prod(z - zeros) / prod(z - poles), the first W_order(i,j)"
    );
    let _ = writeln!(
        s,
        "%         columns of row e of W_zeros_* / W_poles_* (keep it as zpk: tf loses digits)"
    );
    let _ = writeln!(
        s,
        "%   f_hz, bound_additive: the per-line element-wise bound |P - Pnom|(i,j) <= L (column e)"
    );
    let _ = writeln!(
        s,
        "% With the Robust Control Toolbox: {id} (uss), one ultidyn D_<output>_<input> per entry."
    );
    let _ = writeln!(s, "% Conventions: docs/export.md.");
    let _ = writeln!(s);
    for v in &vars {
        if matches!(v.value, Value::Text(_)) {
            continue;
        }
        let _ = writeln!(s, "{} = {};", v.name, script::matlab_value(&v.value));
    }
    let _ = writeln!(s, "ins = {ins};");
    let _ = writeln!(s, "outs = {outs};");
    let _ = writeln!(s, "W_zeros = complex(W_zeros_re, W_zeros_im);");
    let _ = writeln!(s, "W_poles = complex(W_poles_re, W_poles_im);");
    let _ = writeln!(s, "if exist('zpk')");
    let _ = writeln!(
        s,
        "  Pnom = ss(A, B, C, D, Ts, 'InputName', ins, 'OutputName', outs);"
    );
    let _ = writeln!(s, "  W = cell({ny}, {nu});");
    let _ = writeln!(s, "  for j = 1:{nu}");
    let _ = writeln!(s, "    for i = 1:{ny}");
    let _ = writeln!(s, "      e = i + (j - 1) * {ny}; n = W_order(i, j);");
    let _ = writeln!(
        s,
        "      W{{i, j}} = zpk(W_zeros(e, 1:n), W_poles(e, 1:n), W_gain(i, j), Ts);"
    );
    let _ = writeln!(s, "    end");
    let _ = writeln!(s, "  end");
    let _ = writeln!(s, "end");
    let _ = writeln!(s, "if exist('ultidyn')");
    let _ = writeln!(s, "  {id} = Pnom;");
    let _ = writeln!(s, "  for j = 1:{nu}");
    let _ = writeln!(s, "    for i = 1:{ny}");
    let _ = writeln!(
        s,
        "      Dij = ultidyn(sprintf('D_%s_%s', outs{{i}}, ins{{j}}), [1 1]);"
    );
    let _ = writeln!(
        s,
        "      ei = zeros({ny}, 1); ei(i) = 1; ej = zeros(1, {nu}); ej(j) = 1;"
    );
    let _ = writeln!(
        s,
        "      {id} = {id} + ei * (Pnom(i, j) * W{{i, j}} * Dij) * ej;"
    );
    let _ = writeln!(s, "    end");
    let _ = writeln!(s, "  end");
    let _ = writeln!(s, "end");
    Ok(s)
}

/// The variables (module docs) as a MATLAB Level 5 `.mat` file.
///
/// # Errors
/// As [`uncertain_matrix_matlab_script`], and [`ExportError::TooLarge`].
pub fn uncertain_matrix_mat_bytes(u: &UncertainMatrixModel, names: &MimoNames) -> Result<Vec<u8>> {
    mat5::encode(
        &super::header_text(),
        &uncertain_matrix_variables(u, names)?,
    )
}

/// The variables (module docs) as a NumPy `.npz` archive.
///
/// # Errors
/// As [`uncertain_matrix_matlab_script`], and [`ExportError::Npz`].
pub fn uncertain_matrix_npz_bytes(u: &UncertainMatrixModel, names: &MimoNames) -> Result<Vec<u8>> {
    npz::encode(&uncertain_matrix_variables(u, names)?)
}

/// The JSON form: `kind = "uncertain_plant_matrix"`, the nominal model as a MIMO model object
/// (`nominal`), `entries` (one object per entry in the order $e = i + j n_y$: `output`, `input`,
/// the weight as in the SISO export, `bound_additive`), `f_hz`, and `robust` with `lines` and
/// `weights` (as [`super::uncertain::robust_json`]).
///
/// # Errors
/// As [`uncertain_matrix_matlab_script`].
pub fn uncertain_matrix_json(u: &UncertainMatrixModel, names: &MimoNames) -> Result<Json> {
    uncertain_matrix_variables(u, names)?;
    let ny = u.nominal.noutputs();
    let pairs = |v: Vec<ambid_core::c64>| v.iter().map(|x| [x.re, x.im]).collect::<Vec<_>>();
    let entries: Vec<Json> = u
        .weights
        .iter()
        .enumerate()
        .map(|(e, w)| {
            let (i, j) = (e % ny, e / ny);
            json!({
                "output": names.outputs[i],
                "input": names.inputs[j],
                "weight": {
                    "ts": w.weight.ts,
                    "order": w.weight.order(),
                    "gain": w.weight.gain,
                    "zeros": pairs(w.weight.zeros()),
                    "poles": pairs(w.weight.poles()),
                    "factors": {"numerator": w.weight.numerator, "denominator": w.weight.denominator},
                    "looseness": w.looseness,
                    "uncovered_hz": w.uncovered_hz,
                },
                "bound_additive": u.bounds[e],
            })
        })
        .collect();
    Ok(json!({
        "kind": "uncertain_plant_matrix",
        "uncertainty": "entry_relative",
        "form": "P_ij = P_nom,ij (1 + W_ij delta_ij), delta_ij stable and independent, |delta_ij| <= 1",
        "name": sanitize_identifier(&names.name),
        "nominal": super::mimo::mimo_json(&u.nominal, names, json!({}))?,
        "f_hz": u.f_hz,
        "entries": entries,
        "robust": {
            "lines": super::uncertain::robust_json(&u.on_lines),
            "weights": super::uncertain::robust_json(&u.on_weights),
        },
    }))
}
