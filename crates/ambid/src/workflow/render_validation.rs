//! The report sections of the validation, reconstruction and ISO 14839-3 stages, drawn from
//! their typed results alone ([`crate::stage::ValidationStage`],
//! [`crate::stage::ReconstructionStage`], [`crate::stage::IsoStage`]).

use super::data::Units;
use super::figures::{envelope, figure, lin, log, series, with_spans, xy};
use crate::report::{
    format_number as fmt, Block, Marker, NoteKind, Section, Series, Span, Style, Table,
};
use crate::stage::{IsoStage, ReconstructionStage, ValidationCheck, ValidationStage};
use crate::validation::{LagChoice, WORST_WINDOW_SIGNAL_FACTOR};
use crate::workflow::config::ReconstructionSection;
use ambid_core::validate::residuals::{CorrelationTest, ResidualTest};

fn note(kind: NoteKind, text: impl Into<String>) -> Block {
    Block::Note {
        kind,
        text: text.into(),
    }
}

/// Time-series figure: a zoomed window of measured and simulated, and the error over the whole record.
fn time_figure(
    id: &str,
    title: &str,
    caption: String,
    ts: f64,
    measured: &[(&str, &[f64], &[f64], &str)],
) -> Block {
    let mut panels = Vec::new();
    for (name, meas, sim, unit) in measured {
        let n = meas.len().min(sim.len());
        let w0 = n / 2;
        let w1 = (w0 + (0.05 / ts) as usize).min(n);
        let t: Vec<f64> = (w0..w1).map(|k| k as f64 * ts).collect();
        panels.push(xy(
            &format!("{name}: 50 ms window"),
            lin("time [s]"),
            lin(&format!("{name} [{unit}]")),
            vec![
                series("measured", &t, &meas[w0..w1], Style::Line, Some(0)),
                series(
                    "model in closed loop",
                    &t,
                    &sim[w0..w1],
                    Style::Dashed,
                    Some(1),
                ),
            ],
        ));
        let tt: Vec<f64> = (0..n).map(|k| k as f64 * ts).collect();
        let e: Vec<f64> = meas[..n]
            .iter()
            .zip(&sim[..n])
            .map(|(a, b)| a - b)
            .collect();
        let (te, ee) = envelope(&tt, &e, 4000);
        panels.push(xy(
            &format!("{name}: error over the record"),
            lin("time [s]"),
            lin(&format!("error [{unit}]")),
            vec![series("measured − model", &te, &ee, Style::Line, Some(3))],
        ));
    }
    Block::Figure(figure(id, title, caption, panels, 2))
}

/// One residual test's verdict in words.
fn verdict(c: &CorrelationTest) -> String {
    format!(
        "{} (Q = {}, 95 % threshold {} of χ²({}))",
        if c.pass { "pass" } else { "fail" },
        fmt(c.statistic),
        fmt(c.threshold),
        c.dof
    )
}

/// The residual figure and the verdict table: `error` names the residual, `no_white` says why
/// whiteness is not tested when it is not; `truth` is the same test of the twin's exact plant on
/// the same record and lags (the reference: a fail of both is the test's, not the model's).
#[allow(clippy::too_many_arguments)]
fn residual_blocks(
    res: &ResidualTest,
    truth: Option<&ResidualTest>,
    label: &str,
    input: &str,
    error: &str,
    no_white: &str,
    ts: f64,
    lags: &LagChoice,
    nonlinear_twin: bool,
) -> Vec<Block> {
    let bound = |x: &[f64], b: f64| {
        vec![
            series("+95 % bound", x, &vec![b; x.len()], Style::Dashed, Some(7)),
            series("−95 % bound", x, &vec![-b; x.len()], Style::Dashed, Some(7)),
        ]
    };
    let ms = |l: &[i64]| -> Vec<f64> { l.iter().map(|l| *l as f64 * ts * 1e3).collect() };
    let mut panels = Vec::new();
    if let Some(w) = &res.whiteness {
        let x = ms(&w.lags);
        let mut s1 = vec![series(
            "autocorrelation",
            &x,
            &w.values,
            Style::Stems,
            Some(0),
        )];
        s1.extend(bound(&x, w.bound));
        panels.push(xy(
            "whiteness",
            lin("lag [ms]"),
            lin("normalised correlation [-]"),
            s1,
        ));
    }
    if let Some(c) = &res.independence {
        let x = ms(&c.lags);
        let mut s2 = Vec::new();
        // the truth first, so the chosen model's stems are drawn on top
        if let Some(tc) = truth.and_then(|t| t.independence.as_ref()) {
            s2.push(series(
                "twin's exact plant",
                &ms(&tc.lags),
                &tc.values,
                Style::Line,
                Some(2),
            ));
        }
        s2.push(series(
            &format!("{label}: cross-correlation with {input}"),
            &x,
            &c.values,
            Style::Stems,
            Some(1),
        ));
        s2.extend(bound(&x, c.bound));
        panels.push(xy(
            &format!("{error} independent of {input}"),
            lin("lag [ms]"),
            lin("normalised correlation [-]"),
            s2,
        ));
    }
    let ind = res.independence.as_ref().map_or_else(
        || {
            format!(
                "Independence of the {error} is not tested: no recorded signal is independent of \
                 the noise (in closed loop u carries the noise back; an excitation r would be)."
            )
        },
        |c| {
            format!(
                "Cross-correlation of the {error} with the {input} over {} (sample time {} ms), \
                 with the per-lag 95 % bound of coloured signals ±1.96·√(σ̂(0)/(R̂ε(0)R̂r(0)))/√N \
                 (N = {}); the verdict is one portmanteau test N xᵀΣ̂⁺x of all lags together, Σ̂ from \
                 the error's and the {input}'s autocovariances (Parzen window, K = {} lags): {}.",
                lags.describe(ts),
                fmt(ts * 1e3),
                res.n_samples,
                c.covariance_lags,
                verdict(c)
            )
        },
    );
    let truth_text = match truth.and_then(|t| t.independence.as_ref()) {
        Some(tc) => format!(
            " Reference: the twin's exact linear plant, closed with the same controller on the \
             same record and lags: {} — {}.",
            verdict(tc),
            match (res.independence.as_ref().map(|c| c.pass), tc.pass) {
                (Some(false), true) => "the truth passes where the model fails: the test resolves a real model error (with 10⁵ samples it sees errors far below 1 % of the output)",
                (_, false) if nonlinear_twin => "the twin runs its nonlinear physics here, and its exact linearised plant leaves the nonlinear distortion in the error, which the test resolves: a fail says the record is not linear enough for the test, not that a linear model could do better",
                (Some(false), false) => "the truth fails too: this record is one of the 5 % where the test rejects the true model, so the model's fail is not evidence against it",
                (Some(true), false) => "the truth fails where the model passes: one of the 5 % of records where the test rejects the true model",
                _ => "both pass",
            }
        ),
        None => String::new(),
    };
    let white = res.whiteness.as_ref().map_or_else(
        || format!("Whiteness is not tested: {no_white}."),
        |w| format!("Whiteness: {}.", verdict(w)),
    );
    let mut blocks = vec![Block::Figure(figure(
        "residuals",
        "Residual tests",
        format!("{ind} The true model passes each test in 95 % of records.{truth_text} {white}"),
        panels,
        2,
    ))];
    let row = |name: &str, r: &ResidualTest| -> Vec<Vec<String>> {
        let mut rows = Vec::new();
        for (test, c) in [
            (format!("independent of {input}"), r.independence.as_ref()),
            ("whiteness".to_string(), r.whiteness.as_ref()),
        ] {
            if let Some(c) = c {
                rows.push(vec![
                    name.to_string(),
                    test,
                    fmt(c.statistic),
                    fmt(c.threshold),
                    c.dof.to_string(),
                    if c.pass { "pass" } else { "fail" }.into(),
                ]);
            }
        }
        rows
    };
    let mut rows = row(label, res);
    if let Some(t) = truth {
        rows.extend(row("twin's exact linear plant (reference)", t));
    }
    if !rows.is_empty() {
        blocks.push(Block::Table(Table {
            id: "residual_tests".into(),
            caption: format!(
                "Residual tests of the {error}: portmanteau statistic Q against the 95 % quantile of χ²(dof), {}.",
                lags.describe(ts)
            ),
            header: vec![
                "model".into(),
                "test".into(),
                "Q".into(),
                "95 % threshold".into(),
                "dof".into(),
                "verdict".into(),
            ],
            rows,
            highlight: Some(0),
        }));
    }
    blocks
}

/// One row of the ISO table: peak |S| (linear and dB), where, and the zone.
fn iso_row(source: &str, v: &ambid_core::validate::iso::IsoVerdict) -> Vec<String> {
    vec![
        source.to_string(),
        fmt(v.peak),
        fmt(20.0 * v.peak.log10()),
        fmt(v.f_peak_hz),
        format!("{:?}", v.zone),
    ]
}

/// The validation section (`validation`); `None` when the stage did not validate (the step is
/// then skipped with the stage's reason).
pub(crate) fn validation_section(st: &ValidationStage, units: &Units) -> Option<Section> {
    let label = &st.model;
    let mut blocks = Vec::new();
    match &st.check {
        ValidationCheck::NotDone(_) => return None,
        ValidationCheck::ClosedLoop(c) => {
            let v = &c.outcome;
            let mut rows = vec![vec![
                label.clone(),
                fmt(v.fit_y),
                fmt(v.fit_u),
                fmt(v.rmse_y),
                fmt(v.max_error_y),
            ]];
            // the twin's exact plant through the same validation (same record, same lags): the
            // best any model can do, and the residual tests' reference
            if let Some(vt) = &c.exact_plant {
                rows.push(vec![
                    "twin's exact linear plant".into(),
                    fmt(vt.fit_y),
                    fmt(vt.fit_u),
                    fmt(vt.rmse_y),
                    fmt(vt.max_error_y),
                ]);
            }
            blocks.push(Block::Text(format!(
                "The chosen model {label} closed with the controller ({}) and driven by the independent \
                 record's excitation ({} samples, first {} excluded); the simulated displacement and \
                 controller output are compared with the measured ones.",
                c.controller,
                st.samples,
                v.skip
            )));
            blocks.push(time_figure(
                "validation_time",
                "Time-domain validation",
                format!(
                    "Measured and simulated displacement y and controller output u on the validation record \
                     (50 ms window in the middle, and the error over the whole record, min/max per block). \
                     Fit y {} %, fit u {} %.",
                    fmt(v.fit_y),
                    fmt(v.fit_u)
                ),
                st.ts,
                &[
                    ("y", &st.y, &v.reconstruction.simulated.y, &units.y),
                    ("u", &st.u, &v.reconstruction.simulated.u, &units.u),
                ],
            ));
            blocks.push(Block::Table(Table {
                id: "validation".into(),
                caption: "Closed-loop validation figures (after the excluded start-up).".into(),
                header: vec![
                    "model".into(),
                    "fit y [%]".into(),
                    "fit u [%]".into(),
                    "RMSE y".into(),
                    "max |error y|".into(),
                ],
                rows,
                highlight: Some(0),
            }));
            blocks.extend(residual_blocks(
                &v.residuals,
                c.exact_plant.as_ref().map(|t| &t.residuals),
                label,
                if v.residual_input == "r" {
                    "excitation r"
                } else {
                    "reference w"
                },
                "closed-loop output error y − ŷ",
                "the output error of the model simulated in closed loop is the sensor noise through the loop, S·v, coloured even for the true plant (and correlated with u, so u is not the test signal)",
                st.ts,
                &c.lags,
                c.nonlinear_twin,
            ));
        }
        ValidationCheck::OpenLoop(o) => {
            if let Some(w) = &o.without_controller {
                blocks.push(note(NoteKind::Warning, w.clone()));
            }
            let kind = o.kind;
            let fit = o.fit_y;
            blocks.push(Block::Text(format!(
                "The chosen model {label} on the validation record ({} samples): {kind} fit {} %.",
                st.samples,
                fmt(fit)
            )));
            blocks.push(time_figure(
                "validation_time",
                "Time-domain validation",
                format!(
                    "Measured output and the model's {kind} on the validation record; fit {} %.",
                    fmt(fit)
                ),
                st.ts,
                &[("y", &st.y, &o.yhat, &units.y)],
            ));
            match &o.residuals {
                Ok(r) => blocks.extend(residual_blocks(
                    &r.test,
                    None,
                    label,
                    r.signal,
                    if o.one_step() { "1-step prediction error" } else { "simulation error" },
                    "the simulation error of a model is the noise as it reaches the output, coloured unless the noise is white, whatever the model",
                    st.ts,
                    &o.lags,
                    false,
                )),
                Err(why) => blocks.push(note(NoteKind::Warning, why.clone())),
            }
        }
    }
    Some(Section {
        id: "validation".into(),
        title: "Validation on an independent record".into(),
        blocks,
    })
}

/// The reconstruction section (`reconstruction`): the text, the figure of measured and
/// reconstructed signals against the chirp's frequency with the error per window, and the table
/// of the windows; `chirp` labels the reference.
pub(crate) fn reconstruction_section(
    st: &ReconstructionStage,
    chirp: &ReconstructionSection,
    units: &Units,
) -> Section {
    let rc = chirp;
    let (label, source) = (&st.model, &st.source);
    let v = &st.outcome;
    let wins = st.windows();
    let worst = &st.worst;
    let freq = &st.frequency;
    let (y, u, ts) = (&st.y, &st.u, st.ts);
    let n = y.len();
    let idx = |t: f64| st.sample_at(t);
    let win_f = |wf: &ambid_core::validate::closed_loop::WindowFit| st.window_frequency(wf);
    // measured vs reconstructed over the whole sweep (min/max envelopes) against the chirp's
    // instantaneous frequency (time when the reference is not a rising sweep)
    let t: Vec<f64> = (0..n).map(|k| k as f64 * ts).collect();
    type XOf<'a> = Box<dyn Fn(f64) -> f64 + 'a>;
    let (x, x_axis, x_of): (&[f64], &str, XOf<'_>) = match freq {
        Some(f) => (
            f,
            "chirp instantaneous frequency [Hz]",
            Box::new(move |tt: f64| f[idx(tt)]),
        ),
        None => (&t, "time [s]", Box::new(|tt: f64| tt)),
    };
    let sim = &v.reconstruction.simulated;
    let spans = |label: &str| -> Vec<Span> {
        worst
            .as_ref()
            .map(|ww| {
                let wf = &wins[ww.index];
                vec![Span {
                    label: label.to_string(),
                    x0: x_of(wf.t_s.0),
                    x1: x_of(wf.t_s.1),
                }]
            })
            .unwrap_or_default()
    };
    let mut panels = Vec::new();
    for (name, meas, rec, unit) in [
        ("displacement y", y, &sim.y, &units.y),
        ("controller output u", u, &sim.u, &units.u),
    ] {
        let (tm, m) = envelope(x, meas, 3000);
        let (tr, r) = envelope(x, rec, 3000);
        panels.push(with_spans(
            xy(
                name,
                lin(x_axis),
                lin(&format!("{name} [{unit}]")),
                vec![
                    series("measured", &tm, &m, Style::Line, Some(0)),
                    series("reconstructed", &tr, &r, Style::Dashed, Some(1)),
                ],
            ),
            spans("worst window"),
        ));
    }
    // error per window against frequency, with the window's signal and the judging threshold
    let yu = &units.y;
    let mid: Vec<f64> = wins
        .iter()
        .map(|wf| x_of(0.5 * (wf.t_s.0 + wf.t_s.1)))
        .collect();
    let sig_rms = &st.window_signal_rms;
    let err: Vec<f64> = wins.iter().map(|wf| wf.rms_error_y).collect();
    let mut ws = vec![
        series(
            "measured signal RMS",
            &mid,
            sig_rms,
            Style::LineMarkers(Marker::Square),
            Some(0),
        ),
        series(
            "error RMS (measured − reconstructed)",
            &mid,
            &err,
            Style::LineMarkers(Marker::Dot),
            Some(3),
        ),
    ];
    if let Some(ww) = worst {
        let thr = WORST_WINDOW_SIGNAL_FACTOR * ww.error_floor;
        ws.push(series(
            &format!(
                "{}× error floor (windows below: not judged)",
                fmt(WORST_WINDOW_SIGNAL_FACTOR)
            ),
            &mid,
            &vec![thr; mid.len()],
            Style::Dashed,
            Some(7),
        ));
    }
    if err.iter().chain(sig_rms).all(|v| *v > 0.0) {
        panels.push(with_spans(
            xy(
                "displacement error per window",
                lin(x_axis),
                log(&format!("RMS [{yu}]")),
                ws,
            ),
            spans("worst window"),
        ));
    }
    let win: Vec<Vec<String>> = wins
        .iter()
        .enumerate()
        .map(|(k, wf)| {
            vec![
                format!("{}–{}", fmt(wf.t_s.0), fmt(wf.t_s.1)),
                win_f(wf).map_or("—".into(), |(a, b)| format!("{}–{}", fmt(a), fmt(b))),
                fmt(wf.fit_y),
                fmt(wf.fit_u),
                fmt(wf.rms_error_y),
                fmt(sig_rms[k]),
            ]
        })
        .collect();
    let rule = format!(
        "Worst window: the largest displacement error RMS among the windows whose measured signal RMS is at least {}× the error floor (the smallest window error RMS, the sensor noise every window carries); its error is {} of the whole record's signal RMS{}.{} A window's own fit (error against its own signal) is not the judge: where the displacement is small it only measures the noise.",
        fmt(WORST_WINDOW_SIGNAL_FACTOR),
        worst.as_ref().map_or("—".into(), |ww| format!("{} %", fmt(100.0 - ww.record_fit_pct))),
        worst.as_ref().map_or(String::new(), |ww| {
            let wf = &wins[ww.index];
            format!(
                " ({}–{} s{}, signal RMS {} against the floor {}; {} of {} windows judged)",
                fmt(wf.t_s.0),
                fmt(wf.t_s.1),
                win_f(wf).map_or(String::new(), |(a, b)| format!(", {}–{} Hz", fmt(a), fmt(b))),
                fmt(ww.signal_rms),
                fmt(ww.error_floor),
                ww.judged,
                wins.len()
            )
        }),
        worst.as_ref().map_or(String::new(), |ww| {
            if wins[ww.index].rms_error_y <= 1.5 * ww.error_floor {
                " Its error is within 1.5× the floor: no window stands out from the noise.".into()
            } else {
                String::new()
            }
        })
    );
    let blocks = vec![
        Block::Text(format!(
            "Closed-loop reconstruction (seed paper, section 4): {source} driven by a linear chirp position \
             reference ({} µm, {}–{} Hz over {} s); the chosen model {label} closed with the real controller \
             and driven by the same reference. Fit of the displacement {} %, of the controller output {} %.",
            fmt(rc.amplitude_um),
            fmt(rc.f0_hz),
            fmt(rc.f1_hz),
            fmt(rc.duration_s),
            fmt(v.reconstruction.fit_y),
            fmt(v.reconstruction.fit_u)
        )),
        Block::Figure(figure(
            "reconstruction",
            "Closed-loop reconstruction: displacement and current",
            format!(
                "Measured and reconstructed displacement and controller output (current reference) during \
                 the chirp (min/max per block of the {n}-sample record), against {}; last panel: the \
                 displacement error RMS and the measured signal RMS per window (log scale). Shaded: the worst window. {rule}",
                if freq.is_some() {
                    "the chirp's instantaneous frequency (from the reference's zero crossings)"
                } else {
                    "time (the reference is not a rising sweep)"
                }
            ),
            panels,
            1,
        )),
        Block::Table(Table {
            id: "reconstruction_windows".into(),
            caption: format!("Fit per time window of the sweep, with the chirp's frequency range in the window; highlighted: the worst window. {rule}"),
            header: vec![
                "window [s]".into(),
                "frequency [Hz]".into(),
                "fit y [%]".into(),
                "fit u [%]".into(),
                format!("RMS error y [{yu}]"),
                format!("signal RMS y [{yu}]"),
            ],
            rows: win,
            highlight: worst.as_ref().map(|ww| ww.index),
        }),
    ];
    Section {
        id: "reconstruction".into(),
        title: "Closed-loop reconstruction".into(),
        blocks,
    }
}

/// The ISO 14839-3 section (`iso`): $|S|$ in dB over the zones (measured with its 95 % band,
/// the model's and the truth's), the table of peaks and zones, the verdict and how the measured
/// peak was searched; `None` when the stage had nothing to judge.
pub(crate) fn iso_section(st: &IsoStage) -> Option<Section> {
    if st.not_done().is_some() {
        return None;
    }
    let z = st.zones;
    let db1 = |m: f64| 20.0 * m.max(1e-300).log10();
    let mut curves = Vec::new();
    let mut rows = Vec::new();
    let mut iso_notes: Vec<String> = Vec::new();
    // drawn in this order: zone shading, the measured 95 % band, model and truth, measured |S|
    let mut bands = Vec::new();
    let mut measured = None;
    let mut search_span = None;
    if let Some(m) = &st.measured {
        let s = &m.s;
        let search = &m.search;
        let mag: Vec<f64> = s.values().iter().map(|x| x.norm()).collect();
        if let Some(sd) = s.std() {
            // the 95 % band of |S| (±1.96 σ of the complex estimate, floored at a tenth of |S|)
            let up: Vec<f64> = mag
                .iter()
                .zip(&sd)
                .map(|(m, d)| db1(m + 1.96 * d))
                .collect();
            let lo: Vec<f64> = mag
                .iter()
                .zip(&sd)
                .map(|(m, d)| db1((m - 1.96 * d).max(0.1 * m)))
                .collect();
            bands.push(series(
                "measured |S|, 95 % band",
                s.f_hz(),
                &up,
                Style::Band { lower: lo },
                Some(0),
            ));
        }
        measured = Some(series(
            "measured S = T_ru",
            s.f_hz(),
            &mag.iter().map(|m| db1(*m)).collect::<Vec<_>>(),
            Style::Line,
            Some(0),
        ));
        search_span = Some(Span {
            label: "ISO search band".into(),
            x0: search.band.0,
            x1: search.band.1,
        });
        iso_notes.push(format!("Measured: {}.", search.describe()));
        rows.push(iso_row("measured S (FRF)", &search.verdict));
    }
    if let Some(m) = &st.model {
        curves.push(series(
            "model S = 1/(1+PC)",
            &m.f_hz,
            &m.s.iter().map(|x| db1(x.norm())).collect::<Vec<_>>(),
            Style::Dashed,
            Some(6),
        ));
        rows.push(iso_row("chosen model with the controller", &m.verdict));
    }
    if let Some(t) = &st.truth {
        curves.push(series(
            "twin's exact S",
            &t.f_hz,
            &t.s.iter().map(|x| db1(x.norm())).collect::<Vec<_>>(),
            Style::Dashed,
            Some(7),
        ));
        rows.push(iso_row("twin's exact plant", &t.verdict));
    }
    let all: Vec<&Series> = curves.iter().chain(measured.iter()).collect();
    let fx: Vec<f64> = all
        .iter()
        .flat_map(|s| s.x.iter().copied())
        .filter(|f| *f > 0.0)
        .collect();
    let (f0, f1) = (
        fx.iter().copied().fold(f64::INFINITY, f64::min),
        fx.iter().copied().fold(0.0, f64::max),
    );
    // zone shading from the lowest drawn |S| (at most 60 dB below the A/B limit) to 6 dB above C/D
    let y_min = all
        .iter()
        .flat_map(|s| s.y.iter().copied())
        .filter(|v| v.is_finite())
        .fold(f64::INFINITY, f64::min)
        .max(db1(z.a) - 60.0)
        .min(db1(z.a) - 6.0);
    let edges = [y_min, db1(z.a), db1(z.b), db1(z.c), db1(z.c) + 6.0];
    let mut shading = Vec::new();
    for (k, name) in ["zone A", "zone B", "zone C", "zone D"].iter().enumerate() {
        shading.push(series(
            &format!(
                "{name} ({})",
                match k {
                    0 => format!("|S| < {}", fmt(z.a)),
                    1 => format!("{}–{}", fmt(z.a), fmt(z.b)),
                    2 => format!("{}–{}", fmt(z.b), fmt(z.c)),
                    _ => format!("|S| > {}", fmt(z.c)),
                }
            ),
            &[f0, f1],
            &[edges[k + 1]; 2],
            Style::Band {
                lower: vec![edges[k]; 2],
            },
            // green, amber, vermillion, purple (palette of report::svg)
            Some([2, 3, 1, 4][k]),
        ));
    }
    let curves: Vec<Series> = shading
        .into_iter()
        .chain(bands)
        .chain(curves)
        .chain(measured)
        .collect();
    let verdict = st.verdict();
    let blocks = vec![
        Block::Figure(figure(
            "iso_sensitivity",
            "Sensitivity and ISO 14839-3 zones",
            format!(
                "|S| = |T_ru| in dB against frequency over the zones of ISO 14839-3 (limits A/B {}, B/C {}, \
                 C/D {}, i.e. {} / {} / {} dB); the measured |S| with its 95 % band is drawn on top, the \
                 shaded span is the band where the measured peak is searched.",
                fmt(z.a),
                fmt(z.b),
                fmt(z.c),
                fmt(db1(z.a)),
                fmt(db1(z.b)),
                fmt(db1(z.c))
            ),
            vec![with_spans(
                xy("", log("frequency [Hz]"), lin("|S| [dB]"), curves),
                search_span.into_iter().collect(),
            )],
            1,
        )),
        Block::Table(Table {
            id: "iso".into(),
            caption: "Peak sensitivity and ISO 14839-3 zone.".into(),
            header: vec![
                "source".into(),
                "max |S|".into(),
                "max |S| [dB]".into(),
                "at [Hz]".into(),
                "zone".into(),
            ],
            rows,
            highlight: Some(0),
        }),
        note(
            match verdict {
                Some(ambid_core::validate::iso::Zone::A) | Some(ambid_core::validate::iso::Zone::B) => {
                    NoteKind::Pass
                }
                _ => NoteKind::Fail,
            },
            format!(
                "ISO 14839-3 verdict: zone {}.",
                verdict.map_or("—".into(), |v| format!("{v:?}"))
            ),
        ),
    ];

    let mut blocks = blocks;
    for n in iso_notes {
        blocks.push(note(NoteKind::Info, n));
    }
    Some(Section {
        id: "iso".into(),
        title: "ISO 14839-3 stability verdict".into(),
        blocks,
    })
}
