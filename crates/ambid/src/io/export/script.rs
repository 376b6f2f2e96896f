//! The MATLAB script writer.

use super::{format_g17, sanitize_identifier, ExportModel, ExportNames, Value, Var};
use std::fmt::Write;

/// A MATLAB expression for a text value: a quoted literal for printable ASCII (quotes doubled),
/// otherwise `char([…])` of its UTF-16 code units, so no text can break the script.
pub(super) fn matlab_string(s: &str) -> String {
    if s.chars().all(|c| c == ' ' || c.is_ascii_graphic()) {
        format!("'{}'", s.replace('\'', "''"))
    } else {
        let units: Vec<String> = s.encode_utf16().map(|u| u.to_string()).collect();
        format!("char([{}])", units.join(", "))
    }
}

fn row(data: &[f64]) -> String {
    data.iter()
        .map(|x| format_g17(*x))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A MATLAB expression for a numeric value.
pub(super) fn matlab_value(v: &Value) -> String {
    match v {
        Value::Scalar(x) => format_g17(*x),
        Value::Vector(p) if p.is_empty() => "zeros(1, 0)".to_string(),
        Value::Vector(p) => format!("[{}]", row(p)),
        Value::Matrix { rows, cols, .. } if *rows == 0 || *cols == 0 => {
            format!("zeros({rows}, {cols})")
        }
        Value::Matrix { rows: 1, data, .. } => format!("[{}]", row(data)),
        Value::Matrix { cols, data, .. } => {
            let lines: Vec<String> = data
                .chunks(*cols)
                .map(|r| format!("  {}", row(r)))
                .collect();
            format!("[\n{}\n]", lines.join(";\n"))
        }
        Value::Text(s) => matlab_string(s),
    }
}

/// Renders the script from the checked variables.
pub(super) fn render(model: ExportModel<'_>, names: &ExportNames, vars: &[Var]) -> String {
    let id = sanitize_identifier(&names.name);
    let version = env!("CARGO_PKG_VERSION");
    let io_names = format!(
        "'InputName', {}, 'OutputName', {}",
        matlab_string(&names.input),
        matlab_string(&names.output)
    );
    let mut s = String::new();
    // `write!` into a String cannot fail; the results are ignored on purpose.
    match model {
        ExportModel::Poly(m) => {
            let nk = m.delay();
            let st = m.structure().name();
            let _ = writeln!(
                s,
                "% {id}: {} polynomial model, exported by ambid {version}",
                st.to_uppercase()
            );
            let _ = writeln!(s, "%");
            let _ = writeln!(s, "%   A(q) y(k) = B(q)/F(q) u(k) + C(q)/D(q) e(k)");
            let _ = writeln!(
                s,
                "%   Polynomials in ascending powers of q^-1: A = [1, a1, ..., a_na] is 1 + a1 q^-1 + ... + a_na q^-na."
            );
            let _ = writeln!(
                s,
                "%   A, C, D, F are monic; B carries the input delay nk as leading zeros (as idpoly)."
            );
            let _ = writeln!(
                s,
                "%   structure: {st}; orders na = {}, nb = {} (after the delay), nc = {}, nd = {}, nf = {}, nk = {nk}",
                m.a().len() - 1,
                m.b().len().saturating_sub(nk),
                m.c().len() - 1,
                m.d().len() - 1,
                m.f().len() - 1,
            );
            let _ = writeln!(
                s,
                "%   input {:?}, output {:?}, sample time Ts = {} s",
                names.input,
                names.output,
                format_g17(m.ts())
            );
            let _ = writeln!(
                s,
                "%   noise_variance is the variance of e (1 when the fit did not report one)."
            );
            let _ = writeln!(s, "%");
            let _ = writeln!(
                s,
                "% Running this script defines A, B, C, D, F, Ts, nk, noise_variance and {id}: an idpoly (System"
            );
            let _ = writeln!(
                s,
                "% Identification Toolbox). Without it (e.g. in Octave, which has no idpoly) it defines the"
            );
            let _ = writeln!(
                s,
                "% deterministic part G = Gnum/Gden = B/(A F) in z^-1 as plain vectors, and {id} = tf(...) when"
            );
            let _ = writeln!(
                s,
                "% a tf function exists (Control System Toolbox, Octave's control package)."
            );
        }
        ExportModel::StateSpace(m, k) => {
            let (n, nu, ny) = (m.order(), m.ninputs(), m.noutputs());
            let time = if m.ts().is_some() {
                "discrete-time"
            } else {
                "continuous-time"
            };
            let _ = writeln!(
                s,
                "% {id}: {time} state-space model ({n} states, {nu} input(s), {ny} output(s)), exported by ambid {version}"
            );
            let _ = writeln!(s, "%");
            match (m.ts(), k) {
                (Some(_), Some(_)) => {
                    let _ = writeln!(
                        s,
                        "%   innovations form x(k+1) = A x(k) + B u(k) + K e(k), y(k) = C x(k) + D u(k) + e(k)"
                    );
                }
                (Some(_), None) => {
                    let _ = writeln!(
                        s,
                        "%   x(k+1) = A x(k) + B u(k), y(k) = C x(k) + D u(k) (no noise model: K = 0)"
                    );
                }
                (None, Some(_)) => {
                    let _ = writeln!(
                        s,
                        "%   dx/dt = A x + B u + K e, y = C x + D u + e (Ts = 0: continuous time)"
                    );
                }
                (None, None) => {
                    let _ = writeln!(
                        s,
                        "%   dx/dt = A x + B u, y = C x + D u (Ts = 0: continuous time)"
                    );
                }
            }
            let _ = writeln!(
                s,
                "%   structure: ss; order n = {n}; input {:?}, output {:?}, sample time Ts = {} s",
                names.input,
                names.output,
                format_g17(m.ts().unwrap_or(0.0))
            );
            let _ = writeln!(s, "%");
            let kv = if k.is_some() { "K, " } else { "" };
            let _ = writeln!(
                s,
                "% Running this script defines A, B, C, D, {kv}Ts and {id}: an idss (System Identification Toolbox)"
            );
            let _ = writeln!(
                s,
                "% or else an ss (Control System Toolbox); without either, only the matrices."
            );
        }
    }
    let _ = writeln!(
        s,
        "% Numbers have 17 significant digits (%.17g): they reproduce the identified values exactly."
    );
    let _ = writeln!(
        s,
        "% Conventions: docs/conventions.md and docs/export.md of ambid."
    );
    let _ = writeln!(s);
    for v in vars {
        if matches!(v.value, Value::Text(_)) {
            continue;
        }
        let _ = writeln!(s, "{} = {};", v.name, matlab_value(&v.value));
    }
    match model {
        ExportModel::Poly(_) => {
            let _ = writeln!(s, "if exist('idpoly')");
            let _ = writeln!(
                s,
                "  {id} = idpoly(A, B, C, D, F, noise_variance, Ts, {io_names});"
            );
            let _ = writeln!(s, "else");
            let _ = writeln!(
                s,
                "  % no idpoly (Octave, or MATLAB without the System Identification Toolbox)"
            );
            let _ = writeln!(s, "  Gnum = B;");
            let _ = writeln!(s, "  Gden = conv(A, F);");
            let _ = writeln!(s, "  if exist('tf')");
            let _ = writeln!(
                s,
                "    {id} = tf(Gnum, Gden, Ts, 'Variable', 'z^-1', {io_names});"
            );
            let _ = writeln!(s, "  end");
            let _ = writeln!(s, "end");
        }
        ExportModel::StateSpace(m, k) => {
            let (n, ny) = (m.order(), m.noutputs());
            let kexpr = if k.is_some() {
                "K".to_string()
            } else {
                format!("zeros({n}, {ny})")
            };
            let _ = writeln!(s, "if exist('idss')");
            let _ = writeln!(
                s,
                "  {id} = idss(A, B, C, D, {kexpr}, zeros({n}, 1), Ts, {io_names});"
            );
            let _ = writeln!(s, "elseif exist('ss')");
            let _ = writeln!(s, "  {id} = ss(A, B, C, D, Ts, {io_names});");
            let _ = writeln!(s, "end");
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strings_cannot_break_the_script() {
        assert_eq!(matlab_string("u"), "'u'");
        assert_eq!(matlab_string("it's"), "'it''s'");
        assert_eq!(matlab_string(""), "''");
        assert_eq!(matlab_string("a\nb"), "char([97, 10, 98])");
        assert_eq!(matlab_string("ü"), "char([252])");
        assert_eq!(matlab_string("😀"), "char([55357, 56832])");
    }

    #[test]
    fn matrices_print_row_by_row() {
        let m = Value::Matrix {
            rows: 2,
            cols: 2,
            data: vec![1.0, 0.5, -0.25, 0.0],
        };
        assert_eq!(matlab_value(&m), "[\n  1, 0.5;\n  -0.25, 0\n]");
        let r = Value::Matrix {
            rows: 1,
            cols: 2,
            data: vec![1.0, 2.0],
        };
        assert_eq!(matlab_value(&r), "[1, 2]");
        let e = Value::Matrix {
            rows: 0,
            cols: 1,
            data: vec![],
        };
        assert_eq!(matlab_value(&e), "zeros(0, 1)");
        assert_eq!(matlab_value(&Value::Scalar(5e-5)), "5.0000000000000002e-05");
    }
}
