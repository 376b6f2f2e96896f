//! Export of an uncertain plant model for robust-control design (issue 23): the nominal model
//! $\hat P$, the multiplicative weight $W$ of
//! $P = \hat P\,(1 + W\Delta)$, $\lVert\Delta\rVert_\infty \le 1$, the per-line bounds it
//! overbounds, and the robust-stability figures — as a MATLAB script that builds the uncertain
//! model (`ultidyn` × weight, the form `ucover` returns), a MATLAB `.mat`, a NumPy `.npz` and a
//! JSON file (docs/export.md, "Uncertain plant models").
//!
//! The weight is exported in its exact form, zeros, poles and gain
//! ($W(z) = k \prod_i (z - z_i) / \prod_i (z - p_i)$, MATLAB's `zpk(z, p, k, Ts)`), not as
//! polynomials: with corners far below the sample rate the polynomial coefficients lose digits
//! near $z = 1$ (relative $5\cdot 10^{-8}$ for a fourth-order weight with a corner at
//! $\omega T = 10^{-4}$), while the product form evaluates to $\approx 10^{-13}$.
//!
//! Variables (numbers):
//!
//! | variable | meaning |
//! |---|---|
//! | `A`, `B`, `C`, `D`, `Ts` | the nominal model $\hat P$ (discrete state space, as a model export) |
//! | `W_gain` | $k$ |
//! | `W_zeros_re`, `W_zeros_im` | the zeros $z_i$ (row vectors; inside the unit circle) |
//! | `W_poles_re`, `W_poles_im` | the poles $p_i$ (inside the unit circle) |
//! | `f_hz` | the FRF lines the bound is given on \[Hz\] |
//! | `bound_multiplicative`, `bound_additive` | $\ell_k$ and $\Delta_k = \ell_k\lvert\hat P_k\rvert$ |
//! | `term_frf_confidence`, `term_model_error`, `term_nonlinear`, `term_operating`, `term_amplitude` | the terms (a)–(e) (the last three only when given) |
//! | `stability_margin`, `mu_peak`, `mu_peak_hz` | $1/\max\mu$, $\max\lvert WT\rvert$ and where |
//! | `upper_gain_margin`, `lower_gain_margin` | the robust gain margins, when finite |
//!
//! and the text variables `uncertainty = "multiplicative"`, `structure = "ss"`, `input_name`,
//! `output_name`, `model_name`.

use super::{
    check_finite, mat5, matrix, npz, sanitize_identifier, script, var, ExportError, Result, Value,
    Var,
};
use ambid_core::lti::StateSpace;
use ambid_core::validate::robust::{DrawnRobustStability, RobustStability};
use ambid_core::validate::uncertainty::UncertaintyTerms;
use ambid_core::validate::weight::WeightFit;
use serde_json::{json, Value as Json};
use std::fmt::Write;

/// What an uncertain-model export holds.
#[derive(Debug, Clone, Copy)]
pub struct UncertainModel<'a> {
    /// The nominal model $\hat P$ (SISO, discrete).
    pub nominal: &'a StateSpace,
    /// The fitted weight.
    pub weight: &'a WeightFit,
    /// The per-line terms and bounds.
    pub terms: &'a UncertaintyTerms,
    /// The robust-stability analysis, when made.
    pub robust: Option<&'a RobustStability>,
}

/// Names carried into the files.
#[derive(Debug, Clone, Default)]
pub struct UncertainNames {
    /// Model name (sanitised into a MATLAB identifier).
    pub name: String,
    /// Input signal name (the plant input u).
    pub input: String,
    /// Output signal name (the displacement y).
    pub output: String,
}

fn vector(what: &'static str, v: &[f64]) -> Result<Var> {
    check_finite(what, v)?;
    Ok(var(what, Value::Vector(v.to_vec())))
}

fn check(u: &UncertainModel<'_>) -> Result<()> {
    let m = u.nominal;
    if m.ninputs() != 1 || m.noutputs() != 1 {
        return Err(ExportError::ChannelNames {
            what: "inputs and outputs (an uncertain-model export is SISO)",
            got: m.ninputs().max(m.noutputs()),
            expected: 1,
        });
    }
    let n = u.terms.f_hz.len();
    for (what, len) in [
        ("bound_multiplicative", u.terms.multiplicative.len()),
        ("bound_additive", u.terms.additive.len()),
        ("term_frf_confidence", u.terms.frf_confidence.len()),
        ("term_model_error", u.terms.model_error.len()),
    ] {
        if len != n {
            return Err(ExportError::Length {
                what,
                got: len,
                expected: n,
            });
        }
    }
    Ok(())
}

/// The variables, in the order they are written, after checking every number.
pub(crate) fn uncertain_variables(
    u: &UncertainModel<'_>,
    names: &UncertainNames,
) -> Result<Vec<Var>> {
    check(u)?;
    let m = u.nominal;
    let w = &u.weight.weight;
    let mut vars = vec![
        var("A", matrix("A", m.a())?),
        var("B", matrix("B", m.b())?),
        var("C", matrix("C", m.c())?),
        var("D", matrix("D", m.d())?),
    ];
    let ts = m.ts().unwrap_or(0.0);
    check_finite("Ts", &[ts])?;
    vars.push(var("Ts", Value::Scalar(ts)));
    check_finite("W_gain", &[w.gain])?;
    vars.push(var("W_gain", Value::Scalar(w.gain)));
    let (zeros, poles) = (w.zeros(), w.poles());
    let re = |v: &[ambid_core::c64]| v.iter().map(|x| x.re).collect::<Vec<_>>();
    let im = |v: &[ambid_core::c64]| v.iter().map(|x| x.im).collect::<Vec<_>>();
    vars.push(vector("W_zeros_re", &re(&zeros))?);
    vars.push(vector("W_zeros_im", &im(&zeros))?);
    vars.push(vector("W_poles_re", &re(&poles))?);
    vars.push(vector("W_poles_im", &im(&poles))?);
    let t = u.terms;
    vars.push(vector("f_hz", &t.f_hz)?);
    vars.push(vector("bound_multiplicative", &t.multiplicative)?);
    vars.push(vector("bound_additive", &t.additive)?);
    vars.push(vector("term_frf_confidence", &t.frf_confidence)?);
    vars.push(vector("term_model_error", &t.model_error)?);
    for (what, v) in [
        ("term_nonlinear", &t.nonlinear),
        ("term_operating", &t.operating),
        ("term_amplitude", &t.amplitude),
    ] {
        if let Some(v) = v {
            if v.len() != t.f_hz.len() {
                return Err(ExportError::Length {
                    what,
                    got: v.len(),
                    expected: t.f_hz.len(),
                });
            }
            vars.push(vector(what, v)?);
        }
    }
    if let Some(r) = u.robust {
        for (what, x) in [
            ("stability_margin", Some(r.stability_margin)),
            ("mu_peak", Some(r.mu_peak)),
            ("mu_peak_hz", Some(r.mu_peak_hz)),
            ("upper_gain_margin", r.upper_gain_margin),
            ("lower_gain_margin", r.lower_gain_margin),
        ] {
            // an infinite margin (nothing limits it) or none is left out, never written as NaN
            if let Some(x) = x.filter(|x| x.is_finite()) {
                vars.push(var(what, Value::Scalar(x)));
            }
        }
    }
    vars.push(var("uncertainty", Value::Text("multiplicative".into())));
    vars.push(var("structure", Value::Text("ss".into())));
    vars.push(var("input_name", Value::Text(names.input.clone())));
    vars.push(var("output_name", Value::Text(names.output.clone())));
    vars.push(var(
        "model_name",
        Value::Text(sanitize_identifier(&names.name)),
    ));
    Ok(vars)
}

/// A MATLAB script that defines the variables (module docs) and builds, with the Robust Control
/// Toolbox, the uncertain model `<name> = Pnom * (1 + W * Delta)` with
/// `Delta = ultidyn('Delta', [1 1])` and `W = zpk(W_zeros, W_poles, W_gain, Ts)` — the
/// structure `ucover(Parray, Pnom, ord)` returns for `'InputMult'` (`usys = Pnom*(I + W1*Delta*W2)`,
/// here with `W1 = W`, `W2 = 1`; `<name>_info.W1` holds `W`). With only the Control System
/// Toolbox it builds `Pnom` and `W`; without it (Octave) only the numbers. Numbers with 17
/// significant digits (`%.17g`: read back bit for bit).
///
/// ```
/// use ambid::io::export::uncertain::{uncertain_matlab_script, UncertainModel, UncertainNames};
/// use ambid::uncertainty::analyse;
/// use ambid_core::lti::{Frd, StateSpace};
/// use ambid_core::validate::uncertainty::{ExtraTerms, UncertaintyOptions};
/// use faer::mat;
/// let ts = 1e-3;
/// let p = StateSpace::discrete(mat![[0.9]], mat![[1.0]], mat![[0.1]], mat![[0.0]], ts).unwrap();
/// let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[2.0]], ts).unwrap();
/// let f: Vec<f64> = (1..=100).map(|k| 4.0 * k as f64).collect();
/// let exact = Frd::from_model(&p, &f).unwrap();
/// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr()).collect();
/// let frd = Frd::new(f, exact.values().to_vec(), Some(var), Some(ts)).unwrap();
/// let a = analyse(&p, &frd, &c, &ExtraTerms::default(), &UncertaintyOptions::default(), 4, 1.0)
///     .unwrap();
/// let u = UncertainModel { nominal: &p, weight: &a.weight, terms: &a.terms, robust: Some(&a.robust) };
/// let names = UncertainNames { name: "bearing A".into(), input: "u".into(), output: "y".into() };
/// let s = uncertain_matlab_script(&u, &names).unwrap();
/// assert!(s.contains("W = zpk(W_zeros, W_poles, W_gain, Ts);"));
/// assert!(s.contains("bearing_A = Pnom * (1 + W * Delta);"));
/// assert!(s.contains("stability_margin = "));
/// ```
///
/// # Errors
/// [`ExportError::NonFinite`] for a NaN or infinite number, [`ExportError::ChannelNames`] for a
/// nominal model that is not SISO, [`ExportError::Length`] for terms of the wrong length.
pub fn uncertain_matlab_script(u: &UncertainModel<'_>, names: &UncertainNames) -> Result<String> {
    let vars = uncertain_variables(u, names)?;
    let id = sanitize_identifier(&names.name);
    let io = format!(
        "'InputName', {}, 'OutputName', {}",
        script::matlab_string(&names.input),
        script::matlab_string(&names.output)
    );
    let w = &u.weight.weight;
    let mut s = String::new();
    // `write!` into a String cannot fail; the results are ignored on purpose.
    let _ = writeln!(
        s,
        "% {id}: uncertain plant P = Pnom (1 + W Delta), ||Delta||_inf <= 1, exported by ambid {}",
        env!("CARGO_PKG_VERSION")
    );
    let _ = writeln!(s, "%");
    let _ = writeln!(
        s,
        "%   Pnom: the nominal model ({} states; x(k+1) = A x(k) + B u(k), y(k) = C x(k) + D u(k)), unstable poles kept",
        u.nominal.order()
    );
    let _ = writeln!(
        s,
        "%   W:    the multiplicative weight, order {}, stable and minimum phase, in zero-pole-gain form",
        w.order()
    );
    let _ = writeln!(
        s,
        "%         W(z) = W_gain prod(z - W_zeros) / prod(z - W_poles) (keep it as zpk: tf(W) loses digits"
    );
    let _ = writeln!(
        s,
        "%         when its corners lie far below the sample rate)"
    );
    let _ = writeln!(
        s,
        "%   f_hz, bound_multiplicative: the per-line bound W overbounds ({} of {} lines above |W|),",
        u.weight.uncovered_hz.len(),
        u.terms.f_hz.len()
    );
    let _ = writeln!(
        s,
        "%         bound_additive and the terms (a) FRF confidence, (b) model error, (c)-(e) when given"
    );
    let _ = writeln!(
        s,
        "% With the Robust Control Toolbox: {id} (uss) and {id}_info.W1 = W, the form ucover returns"
    );
    let _ = writeln!(
        s,
        "% for 'InputMult' (usys = Pnom*(I + W1*Delta*W2), W2 = 1). Conventions: docs/export.md."
    );
    let _ = writeln!(s);
    for v in &vars {
        if matches!(v.value, Value::Text(_)) {
            continue;
        }
        let _ = writeln!(s, "{} = {};", v.name, script::matlab_value(&v.value));
    }
    let _ = writeln!(s, "W_zeros = complex(W_zeros_re, W_zeros_im);");
    let _ = writeln!(s, "W_poles = complex(W_poles_re, W_poles_im);");
    let _ = writeln!(s, "if exist('ultidyn')");
    let _ = writeln!(s, "  Pnom = ss(A, B, C, D, Ts, {io});");
    let _ = writeln!(s, "  W = zpk(W_zeros, W_poles, W_gain, Ts);");
    let _ = writeln!(s, "  Delta = ultidyn('Delta', [1 1]);");
    let _ = writeln!(s, "  {id} = Pnom * (1 + W * Delta);");
    let _ = writeln!(s, "  {id}_info = struct('W1', W, 'W2', 1);");
    let _ = writeln!(s, "elseif exist('zpk')");
    let _ = writeln!(s, "  Pnom = ss(A, B, C, D, Ts, {io});");
    let _ = writeln!(s, "  W = zpk(W_zeros, W_poles, W_gain, Ts);");
    let _ = writeln!(s, "end");
    Ok(s)
}

/// The variables (module docs) as a MATLAB Level 5 `.mat` file.
///
/// # Errors
/// As [`uncertain_matlab_script`], and [`ExportError::TooLarge`].
pub fn uncertain_mat_bytes(u: &UncertainModel<'_>, names: &UncertainNames) -> Result<Vec<u8>> {
    mat5::encode(&super::header_text(), &uncertain_variables(u, names)?)
}

/// The variables (module docs) as a NumPy `.npz` archive.
///
/// # Errors
/// As [`uncertain_matlab_script`], and [`ExportError::Npz`].
pub fn uncertain_npz_bytes(u: &UncertainModel<'_>, names: &UncertainNames) -> Result<Vec<u8>> {
    npz::encode(&uncertain_variables(u, names)?)
}

/// The JSON form: `kind = "uncertain_plant"`, the nominal model as a state-space model object
/// (`nominal`), the weight (`weight`: `ts`, `gain`, `zeros`/`poles` as `[re, im]` pairs, the
/// continuous prototype `factors`, `looseness`, `uncovered_hz`), the per-line bounds and terms
/// (`lines`), and `robust` (margins; an unlimited gain margin is `null`).
///
/// # Errors
/// As [`uncertain_matlab_script`].
pub fn uncertain_json(u: &UncertainModel<'_>, names: &UncertainNames) -> Result<Json> {
    // the same checks as the binary forms: a JSON file never holds what they refuse
    uncertain_variables(u, names)?;
    let w = &u.weight.weight;
    let pairs = |v: Vec<ambid_core::c64>| v.iter().map(|x| [x.re, x.im]).collect::<Vec<_>>();
    let t = u.terms;
    let robust = u.robust.map(robust_json);
    Ok(json!({
        "kind": "uncertain_plant",
        "uncertainty": "multiplicative",
        "form": "P = P_nom (1 + W Delta), Delta stable, ||Delta||_inf <= 1",
        "name": sanitize_identifier(&names.name),
        "nominal": crate::io::model::state_space_json(u.nominal, &names.input, &names.output, json!({})),
        "weight": {
            "ts": w.ts,
            "order": w.order(),
            "gain": w.gain,
            "zeros": pairs(w.zeros()),
            "poles": pairs(w.poles()),
            "factors": {"numerator": w.numerator, "denominator": w.denominator},
            "looseness": u.weight.looseness,
            "uncovered_hz": u.weight.uncovered_hz,
        },
        "lines": {
            "f_hz": t.f_hz,
            "bound_multiplicative": t.multiplicative,
            "bound_additive": t.additive,
            "term_frf_confidence": t.frf_confidence,
            "term_model_error": t.model_error,
            "term_nonlinear": t.nonlinear,
            "term_operating": t.operating,
            "term_amplitude": t.amplitude,
            "line_coverage": t.line_coverage,
        },
        "robust": robust,
    }))
}

/// The robust-stability figures as JSON (`summary.json` of `ambid uncertainty` and the `robust`
/// object of [`uncertain_json`]): an unlimited gain margin is `null` with
/// `upper_gain_margin_unlimited: true`.
pub fn robust_json(r: &RobustStability) -> Json {
    let fin = |x: Option<f64>| x.filter(|x| x.is_finite());
    json!({
        "nominal_stable": r.nominal_stable,
        "robustly_stable": r.robustly_stable,
        "stability_margin": r.stability_margin,
        "mu_peak": r.mu_peak,
        "mu_peak_hz": r.mu_peak_hz,
        "upper_gain_margin": fin(r.upper_gain_margin),
        "upper_gain_margin_unlimited": r.upper_gain_margin == Some(f64::INFINITY),
        "lower_gain_margin": fin(r.lower_gain_margin),
    })
}

/// The coherent robust-stability check
/// ([`RobustChecks::coherent`](crate::uncertainty::RobustChecks::coherent)) as JSON: `draws`,
/// `confidence`, `nominal_stable`, `stable_fraction`, `robustly_stable`, the margins
/// (`lower_gain_margin`, `upper_gain_margin`, null when not robustly stable or unlimited, with
/// `upper_gain_margin_unlimited`), and the weight's test outside the lines
/// (`outside_gain_interval`, `outside_critical_hz`).
pub fn coherent_json(r: &DrawnRobustStability) -> Json {
    let fin = |x: Option<f64>| x.filter(|x| x.is_finite());
    json!({
        "draws": r.per_draw.len(),
        "confidence": r.confidence,
        "nominal_stable": r.nominal_stable,
        "stable_fraction": r.stable_fraction,
        "robustly_stable": r.robustly_stable,
        "upper_gain_margin": fin(r.upper_gain_margin),
        "upper_gain_margin_unlimited": r.upper_gain_margin == Some(f64::INFINITY),
        "lower_gain_margin": fin(r.lower_gain_margin),
        "outside_gain_interval": r.outside_gain_interval,
        "outside_critical_hz": r.outside_critical_hz,
    })
}
