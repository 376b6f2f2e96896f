//! The report's first section: the answer in one table (chosen model, its validation fit and
//! frequency error, the one recommended excitation level, peak |S| with its confidence interval
//! and ISO 14839-3 zone, stability margins, unstable poles) and every warning of the run.
//!
//! Everything here is read from the run's typed outcome ([`super::Summary`], what
//! `summary.json` holds), the models stage's typed result ([`ModelsStage`]: the chosen model,
//! its unstable poles and, on the twin, the exact plant's) and the notes of the other sections;
//! nothing is computed here.

use super::Summary;
use crate::report::{format_number as fmt, Block, NoteKind, Section, Table};
use crate::stage::ModelsStage;

fn note(kind: NoteKind, text: String) -> Block {
    Block::Note { kind, text }
}

/// A number as `summary.json` keeps it: `None` when absent or not finite (written as `null`).
fn fin(x: Option<f64>) -> Option<f64> {
    x.filter(|v| v.is_finite())
}

/// The summary section (id `summary`), built after every step ran from the typed `summary`, the
/// other `sections` (their warnings), the models stage's result `stage` and whether the
/// identification record is `closed_loop`.
pub(crate) fn section(
    summary: &Summary,
    sections: &[Section],
    stage: Option<&ModelsStage>,
    closed_loop: bool,
) -> Section {
    let s = summary;
    let models = s.models.as_ref();
    let validation = s.validation.as_ref();
    let order = s.order.as_ref();
    let amplitude = s.amplitude.as_ref();
    let iso = s.iso.as_ref();
    let residuals = s.residuals.as_ref();
    let mut rows: Vec<Vec<String>> = Vec::new();
    let mut blocks = Vec::new();
    let twin = s.data.as_ref().and_then(|d| d.source.as_deref()) == Some("twin");

    // the chosen model
    if let Some(chosen) = models.and_then(|m| m.chosen.clone()) {
        let mut parts = Vec::new();
        if let Some(f) = fin(validation.and_then(|v| v.fit_y_pct))
            .or_else(|| fin(models.and_then(|m| m.chosen_validation_fit_pct)))
        {
            let how = match validation.and_then(|v| v.kind.clone()) {
                Some(kind) => format!("{kind}, independent record"),
                None if closed_loop => {
                    "closed loop with the controller, independent record".to_string()
                }
                None => "independent record".to_string(),
            };
            parts.push(format!("validation fit of y {} % ({how})", fmt(f)));
        }
        let row = models.and_then(|m| m.table.iter().find(|r| r.model == chosen));
        if let Some(e) = fin(row.and_then(|r| r.median_relative_pct)) {
            parts.push(format!(
                "median error against the measured FRF {} %",
                fmt(e)
            ));
        }
        if let Some(e) = fin(models.and_then(|m| m.chosen_error_vs_truth_pct)) {
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
    if let Some(n) = fin(order.and_then(|o| o.recommended)) {
        let range = match (
            fin(order.and_then(|o| o.recommended_lo)),
            fin(order.and_then(|o| o.recommended_hi)),
        ) {
            (Some(a), Some(b)) if a < b => format!(" (range {a:.0}–{b:.0})"),
            _ => String::new(),
        };
        rows.push(vec![
            "model order".into(),
            format!(
                "recommended {n:.0}{range}{}",
                order
                    .and_then(|o| o.recommended_source.clone())
                    .map_or(String::new(), |s| {
                        format!(
                            ", from {}",
                            match s.as_str() {
                                "frf_fit_error" =>
                                    "the error of state-space fits to the FRF per order",
                                "time_fit_error" =>
                                    "the validation error of time-domain fits per order",
                                "subspace_singular_values" =>
                                    "the gap in the subspace singular values",
                                _ => "the order step",
                            }
                        )
                    })
            ),
            "Order estimation".into(),
        ]);
    }

    // the one excitation level: % of i_sat, RMS (for a binary PRBS its amplitude equals its RMS)
    if let Some(level) = fin(s.identification.as_ref().map(|i| i.level_pct))
        .or_else(|| fin(amplitude.map(|a| a.chosen_pct)))
    {
        let mut why = Vec::new();
        match (
            fin(amplitude.and_then(|a| a.recommended_min_pct)),
            fin(amplitude.and_then(|a| a.recommended_max_pct)),
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
        if let Some(bla) = fin(s.bla.as_ref().map(|b| b.recommended_pct)) {
            // an optimum at the largest level studied is only a lower bound of the true optimum
            let top = s.bla.as_ref().and_then(|b| {
                b.levels
                    .iter()
                    .filter_map(|r| fin(Some(r.level_pct)))
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
        if let Some(s) =
            fin(s.identification.as_ref().and_then(|i| i.saturated_pct)).filter(|s| *s > 0.0)
        {
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
            blocks.push(note(NoteKind::Warning, n));
        }
    }

    // peak |S| and the ISO zone
    let measured = iso.and_then(|i| i.measured.as_ref());
    let model = iso.and_then(|i| i.model.as_ref());
    if let Some(zone) = iso.and_then(|i| i.zone.clone()) {
        let mut parts = Vec::new();
        if let Some(p) = fin(measured.and_then(|m| m.peak)) {
            let ci = match (
                fin(measured.and_then(|m| m.peak_ci_lo)),
                fin(measured.and_then(|m| m.peak_ci_hi)),
            ) {
                (Some(a), Some(b)) => format!(" (95 % interval {}–{})", fmt(a), fmt(b)),
                _ => String::new(),
            };
            let at = fin(measured.and_then(|m| m.f_peak_hz))
                .map_or(String::new(), |f| format!(" at {} Hz", fmt(f)));
            parts.push(format!("measured max |S| {}{ci}{at}", fmt(p)));
        }
        if let Some(p) = fin(model.and_then(|m| m.peak)) {
            parts.push(format!("chosen model with the controller {}", fmt(p)));
        }
        if let (true, Some(p), Some(z)) = (
            twin,
            fin(iso.and_then(|i| i.truth.as_ref()).and_then(|t| t.peak)),
            iso.and_then(|i| i.truth.as_ref())
                .and_then(|t| t.zone.clone()),
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
    if let Some(pm) = fin(model.and_then(|m| m.phase_margin_deg)) {
        margins.push(format!(
            "phase margin {}° (chosen model with the controller)",
            fmt(pm)
        ));
    }
    if let Some(p) = fin(measured.and_then(|m| m.peak)).filter(|p| *p > 0.0) {
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
    if let Some((stage, m)) =
        stage.and_then(|st| Some((st, st.chosen().and_then(|c| c.model.as_ref())?)))
    {
        let fs = fin(s.data.as_ref().and_then(|d| d.fs_hz))
            .or_else(|| m.ts().map(|t| 1.0 / t))
            .unwrap_or(1.0);
        let unstable: Vec<String> = stage
            .chosen_unstable
            .iter()
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
        let supported = fin(models.and_then(|m| m.unstable_poles_supported.flatten()))
            .map_or(String::new(), |n| {
                format!("; the data support {n:.0} (Nyquist count of the measured loop)")
            });
        let truth = stage
            .truth_unstable_poles
            .as_ref()
            .filter(|p| !p.is_empty())
            .map_or(String::new(), |p| {
                let list: Vec<String> = p.iter().map(|z| format!("{:.5}", z.re)).collect();
                format!("; the twin's exact plant: z = {}", list.join(", "))
            });
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
    for (test, what) in [
        (
            residuals.map(|r| {
                (
                    r.independence_pass,
                    r.independence_statistic,
                    r.independence_threshold,
                )
            }),
            "independence of the output error from the excitation r",
        ),
        (
            residuals.map(|r| {
                (
                    r.whiteness_pass,
                    r.whiteness_statistic,
                    r.whiteness_threshold,
                )
            }),
            "whiteness of the prediction errors",
        ),
    ] {
        let (pass, q, lim) = test.unwrap_or((None, None, None));
        let (q, lim) = (fin(q), fin(lim));
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
        residuals.and_then(|r| r.truth_independence_pass),
        fin(residuals.and_then(|r| r.truth_independence_statistic)),
        fin(residuals.and_then(|r| r.truth_independence_threshold)),
    ) {
        tests.push(format!(
            "the twin's exact plant on the same record: {} (Q = {}, threshold {})",
            if pass { "pass" } else { "fail" },
            fmt(q),
            fmt(lim)
        ));
    }
    if let Some(l) = residuals.and_then(|r| r.lags).map(|l| l as f64) {
        tests.push(format!(
            "{l:.0} lags{}",
            fin(residuals.and_then(|r| r.lags_ms))
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
    out.extend(warnings.into_iter().map(|(kind, text)| note(kind, text)));
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
