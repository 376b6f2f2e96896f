//! The report's first section: the answer in one table (chosen model, its validation fit and
//! frequency error, the one recommended excitation level, peak |S| with its confidence interval
//! and ISO 14839-3 zone, stability margins, unstable poles) and every warning of the run.
//!
//! Everything here is read from the numbers the steps recorded (`summary.json`), the chosen
//! model and the notes of the other sections; nothing is computed twice.

use super::Ctx;
use crate::report::{format_number as fmt, Block, NoteKind, Section, Table};
use serde_json::Value;

/// The value at a dotted key of the summary.
fn get<'v>(v: &'v Value, key: &str) -> Option<&'v Value> {
    key.split('.').try_fold(v, |v, k| v.get(k))
}

fn num(v: &Value, key: &str) -> Option<f64> {
    get(v, key).and_then(Value::as_f64)
}

fn text(v: &Value, key: &str) -> Option<String> {
    get(v, key).and_then(Value::as_str).map(str::to_string)
}

/// The summary section (id `summary`), built after every step ran.
pub(crate) fn section(summary: &Value, sections: &[Section], ctx: &Ctx<'_>) -> Section {
    let mut rows: Vec<Vec<String>> = Vec::new();
    let mut blocks = Vec::new();
    let twin = ctx.twin.is_some();

    // the chosen model
    if let Some(chosen) = text(summary, "models.chosen") {
        let mut parts = Vec::new();
        if let Some(f) = num(summary, "validation.fit_y_pct")
            .or_else(|| num(summary, "models.chosen_validation_fit_pct"))
        {
            let how = match text(summary, "validation.kind") {
                Some(kind) => format!("{kind}, independent record"),
                None if ctx.is_closed_loop() => {
                    "closed loop with the controller, independent record".to_string()
                }
                None => "independent record".to_string(),
            };
            parts.push(format!("validation fit of y {} % ({how})", fmt(f)));
        }
        let row = get(summary, "models.table")
            .and_then(Value::as_array)
            .and_then(|t| {
                t.iter()
                    .find(|r| r.get("model").and_then(Value::as_str) == Some(chosen.as_str()))
            });
        if let Some(e) = row.and_then(|r| r.get("median_relative_pct")?.as_f64()) {
            parts.push(format!(
                "median error against the measured FRF {} %",
                fmt(e)
            ));
        }
        if let Some(e) = num(summary, "models.chosen_error_vs_truth_pct") {
            parts.push(format!(
                "median error against the twin's exact plant {} %",
                fmt(e)
            ));
        }
        rows.push(vec![
            "chosen model".into(),
            format!("{chosen}: {}", parts.join("; ")),
            "Parametric models, Validation".into(),
        ]);
    }

    // the reconciled order (order step)
    if let Some(n) = num(summary, "order.recommended") {
        let range = match (
            num(summary, "order.recommended_lo"),
            num(summary, "order.recommended_hi"),
        ) {
            (Some(a), Some(b)) if a < b => format!(" (range {a:.0}–{b:.0})"),
            _ => String::new(),
        };
        rows.push(vec![
            "model order".into(),
            format!(
                "recommended {n:.0}{range}{}",
                text(summary, "order.recommended_source").map_or(String::new(), |s| {
                    format!(
                        ", from {}",
                        match s.as_str() {
                            "frf_fit_error" => "the error of state-space fits to the FRF per order",
                            "time_fit_error" =>
                                "the validation error of time-domain fits per order",
                            "subspace_singular_values" => "the gap in the subspace singular values",
                            _ => "the order step",
                        }
                    )
                })
            ),
            "Order estimation".into(),
        ]);
    }

    // the one excitation level: % of i_sat, RMS (for a binary PRBS its amplitude equals its RMS)
    if let Some(level) =
        num(summary, "identification.level_pct").or_else(|| num(summary, "amplitude.chosen_pct"))
    {
        let mut why = Vec::new();
        match (
            num(summary, "amplitude.recommended_min_pct"),
            num(summary, "amplitude.recommended_max_pct"),
        ) {
            (Some(a), Some(b)) if (a - b).abs() < 1e-9 => {
                why.push(format!("the amplitude study recommends {} %", fmt(a)))
            }
            (Some(a), Some(b)) => why.push(format!(
                "the amplitude study recommends {}–{} %",
                fmt(a),
                fmt(b)
            )),
            _ => {}
        }
        let mut level_note = None;
        if let Some(bla) = num(summary, "bla.recommended_pct") {
            // an optimum at the largest level studied is only a lower bound of the true optimum
            let top = get(summary, "bla.levels")
                .and_then(Value::as_array)
                .and_then(|l| {
                    l.iter()
                        .filter_map(|r| r.get("level_pct")?.as_f64())
                        .reduce(f64::max)
                });
            why.push(format!(
                "the robust BLA's noise + nonlinear variance is smallest at {} % RMS{}",
                fmt(bla),
                if top.is_some_and(|t| (t - bla).abs() < 1e-9) {
                    " (the largest level it studied)"
                } else {
                    ""
                }
            ));
            if bla < level - 1e-9 {
                level_note = Some(format!(
                    "The robust BLA's best level ({} % RMS) is below the identification level \
                     ({} %): nonlinear distortion may bias the estimate; consider {} %.",
                    fmt(bla),
                    fmt(level),
                    fmt(bla)
                ));
            } else {
                why.push(format!(
                    "that is above the {} % used, so nonlinear distortion does not limit the level",
                    fmt(level)
                ));
            }
        }
        if let Some(s) = num(summary, "identification.saturated_pct").filter(|s| *s > 0.0) {
            why.push(format!("{} % of the samples saturated", fmt(s)));
        }
        rows.push(vec![
            "excitation level (% of i_sat, RMS; a PRBS's amplitude equals its RMS)".into(),
            format!(
                "{} %{}",
                fmt(level),
                if why.is_empty() {
                    String::new()
                } else {
                    format!(": {}", why.join("; "))
                }
            ),
            "Excitation-amplitude study, Robust BLA".into(),
        ]);
        if let Some(n) = level_note {
            blocks.push(Ctx::note(NoteKind::Warning, n));
        }
    }

    // peak |S| and the ISO zone
    if let Some(zone) = text(summary, "iso.zone") {
        let mut parts = Vec::new();
        if let Some(p) = num(summary, "iso.measured.peak") {
            let ci = match (
                num(summary, "iso.measured.peak_ci_lo"),
                num(summary, "iso.measured.peak_ci_hi"),
            ) {
                (Some(a), Some(b)) => format!(" (95 % interval {}–{})", fmt(a), fmt(b)),
                _ => String::new(),
            };
            let at = num(summary, "iso.measured.f_peak_hz")
                .map_or(String::new(), |f| format!(" at {} Hz", fmt(f)));
            parts.push(format!("measured max |S| {}{ci}{at}", fmt(p)));
        }
        if let Some(p) = num(summary, "iso.model.peak") {
            parts.push(format!("chosen model with the controller {}", fmt(p)));
        }
        if let (true, Some(p), Some(z)) = (
            twin,
            num(summary, "iso.truth.peak"),
            text(summary, "iso.truth.zone"),
        ) {
            parts.push(format!("twin's exact plant {} (zone {z})", fmt(p)));
        }
        rows.push(vec![
            "peak sensitivity and ISO 14839-3 zone".into(),
            format!("zone {zone}: {}", parts.join("; ")),
            "ISO 14839-3 stability verdict".into(),
        ]);
    }

    // margins
    let mut margins = Vec::new();
    if let Some(pm) = num(summary, "iso.model.phase_margin_deg") {
        margins.push(format!(
            "phase margin {}° (chosen model with the controller)",
            fmt(pm)
        ));
    }
    if let Some(p) = num(summary, "iso.measured.peak").filter(|p| *p > 0.0) {
        margins.push(format!(
            "modulus margin 1/max|S| = {} (measured)",
            fmt(1.0 / p)
        ));
    }
    if !margins.is_empty() {
        rows.push(vec![
            "stability margins".into(),
            margins.join("; "),
            "ISO 14839-3 stability verdict".into(),
        ]);
    }

    // unstable poles of the chosen model, in z and as s = fs ln z
    if let Some(m) = ctx
        .chosen
        .and_then(|c| ctx.candidates.get(c))
        .and_then(|c| c.model.as_ref())
    {
        let fs = num(summary, "data.fs_hz")
            .or_else(|| m.ts().map(|t| 1.0 / t))
            .unwrap_or(1.0);
        let poles = ambid_core::linalg::eigenvalues(m.a()).unwrap_or_default();
        let unstable: Vec<String> = poles
            .iter()
            .filter(|z| z.norm() > 1.0 && z.im >= 0.0)
            .map(|z| {
                let s = z.ln() * fs;
                if z.im.abs() < 1e-12 {
                    format!(
                        "z = {:.5} (real, s = +{} 1/s, time constant {} ms)",
                        z.re,
                        fmt(s.re),
                        fmt(1e3 / s.re)
                    )
                } else {
                    format!(
                        "z = {:.5} ± {:.5}j (s = {} ± {}j 1/s, {} Hz)",
                        z.re,
                        z.im,
                        fmt(s.re),
                        fmt(s.im),
                        fmt(s.im / std::f64::consts::TAU)
                    )
                }
            })
            .collect();
        let supported = num(summary, "models.unstable_poles_supported")
            .map_or(String::new(), |n| {
                format!("; the data support {n:.0} (Nyquist count of the measured loop)")
            });
        let truth = match &ctx.twin {
            Some(t) => t
                .twin
                .plant_unstable_poles()
                .ok()
                .filter(|p| !p.is_empty())
                .map_or(String::new(), |p| {
                    let list: Vec<String> = p.iter().map(|z| format!("{:.5}", z.re)).collect();
                    format!("; the twin's exact plant: z = {}", list.join(", "))
                }),
            None => String::new(),
        };
        rows.push(vec![
            "unstable poles of the chosen model".into(),
            if unstable.is_empty() {
                format!("none{supported}{truth}")
            } else {
                format!(
                    "{}: {}{supported}{truth}",
                    unstable.len(),
                    unstable.join(", ")
                )
            },
            "Pole-zero check".into(),
        ]);
    }

    // residual tests of the chosen model
    let mut tests = Vec::new();
    for (key, what) in [
        (
            "independence",
            "independence of the output error from the excitation r",
        ),
        ("whiteness", "whiteness of the prediction errors"),
    ] {
        let pass = get(summary, &format!("residuals.{key}_pass")).and_then(Value::as_bool);
        let q = num(summary, &format!("residuals.{key}_statistic"));
        let lim = num(summary, &format!("residuals.{key}_threshold"));
        if let (Some(pass), Some(q), Some(lim)) = (pass, q, lim) {
            tests.push(format!(
                "{what}: {} (Q = {}, 95 % threshold {})",
                if pass { "pass" } else { "fail" },
                fmt(q),
                fmt(lim)
            ));
        }
    }
    // on the twin: the same test on the exact plant, so a "fail" can be told from a test limit
    if let (Some(pass), Some(q), Some(lim)) = (
        get(summary, "residuals.truth_independence_pass").and_then(Value::as_bool),
        num(summary, "residuals.truth_independence_statistic"),
        num(summary, "residuals.truth_independence_threshold"),
    ) {
        tests.push(format!(
            "the twin's exact plant on the same record: {} (Q = {}, threshold {})",
            if pass { "pass" } else { "fail" },
            fmt(q),
            fmt(lim)
        ));
    }
    if let Some(l) = num(summary, "residuals.lags") {
        tests.push(format!(
            "{l:.0} lags{}",
            num(summary, "residuals.lags_ms")
                .map_or(String::new(), |ms| format!(" ({} ms)", fmt(ms)))
        ));
    }
    if !tests.is_empty() {
        rows.push(vec![
            "residual tests (95 % level)".into(),
            tests.join("; "),
            "Validation on an independent record".into(),
        ]);
    }

    // every warning and failed verdict of the run, with its section
    let mut warnings = Vec::new();
    for s in sections {
        for b in &s.blocks {
            if let Block::Note {
                kind: kind @ (NoteKind::Warning | NoteKind::Fail),
                text,
            } = b
            {
                warnings.push((*kind, format!("{}: {text}", s.title)));
            }
        }
    }
    for b in &blocks {
        if let Block::Note { kind, text } = b {
            warnings.push((*kind, format!("Summary: {text}")));
        }
    }
    rows.push(vec![
        "warnings".into(),
        if warnings.is_empty() {
            "none".into()
        } else {
            format!("{} (listed below)", warnings.len())
        },
        "this section".into(),
    ]);
    let mut out = vec![Block::Table(Table {
        id: "headline".into(),
        caption: "The answer of this run. Levels are in % of the actuator's saturation current \
                  i_sat, RMS; frequencies in Hz."
            .into(),
        header: vec!["what".into(), "result".into(), "details in".into()],
        rows,
        highlight: None,
    })];
    out.extend(
        warnings
            .into_iter()
            .map(|(kind, text)| Ctx::note(kind, text)),
    );
    out.push(Block::Text(
        "Every number of this run is in summary.json beside this page (with its key; units in \
         the key: _pct %, _hz Hz, _s s, _db dB, otherwise SI); each figure's data and each \
         table are in figures/ and tables/ as CSV."
            .into(),
    ));
    Section {
        id: "summary".into(),
        title: "Summary".into(),
        blocks: out,
    }
}
