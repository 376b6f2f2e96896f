//! The report sections of the models and pole-zero stages, built from their typed results alone
//! ([`ModelsStage`], [`PoleZeroStage`]).

use super::figures::{bode_panels, figure, lin, log, pz_panel, series, xy, Curve};
use crate::report::{format_number as fmt, Block, Marker, NoteKind, Section, Style, Table};
use crate::stage::{ModelsStage, PoleZeroStage};

fn note(kind: NoteKind, text: impl Into<String>) -> Block {
    Block::Note {
        kind,
        text: text.into(),
    }
}

/// The models section (id `models`): what was fitted and how, the comparison table, the choice
/// and one Bode overlay with error curves per structure. `weights` is `[models] weights` (a
/// label).
pub(crate) fn models_section(stage: &ModelsStage, weights: &str) -> Section {
    let cands = &stage.candidates;
    let chosen = stage.choice.index;
    let frf_domain = stage.domain == "frf";
    let opt = |v: Option<f64>, scale: f64| v.map_or("—".to_string(), |v| fmt(scale * v));
    let rows: Vec<Vec<String>> = cands
        .iter()
        .map(|c| {
            vec![
                c.label(),
                c.n_params.to_string(),
                opt(c.relative_rmse, 100.0),
                opt(c.median_relative, 100.0),
                opt(c.db_rmse, 1.0),
                opt(c.bic, 1.0),
                opt(c.validation_fit, 1.0),
                c.unstable_poles.map_or("—".into(), |u| u.to_string()),
                opt(c.truth_median_relative, 100.0),
                c.note.clone().unwrap_or_default(),
            ]
        })
        .collect();
    let mut blocks = vec![Block::Text(format!(
        "{} at orders {:?} ([models] orders {:?} plus the order step's recommended range); {}. Validation fit: {}. Chosen by {} among the valid models{}.",
        if frf_domain {
            "ARX (Levy), OE (Sanathanan–Koerner + Levenberg–Marquardt) and state-space (frequency-domain subspace + LM) models fitted to the plant FRF"
        } else {
            "ARX (least squares), OE (prediction-error method) and state-space (N4SID + prediction-error refinement) models fitted to the identification record"
        },
        stage.orders,
        stage.configured_orders,
        if frf_domain {
            format!(
                "weights {}; {}",
                weights,
                stage.band.as_ref().map_or("every line", |b| b.how.as_str())
            )
        } else {
            "validation fit on the independent record (simulation from the least-squares initial state for stable models, as MATLAB compare does; else the one-step prediction)".into()
        },
        stage.validation_kind,
        stage.select.describe(),
        stage.unstable.as_ref().map_or(String::new(), |u| format!(
            " (right number of unstable poles and a stable loop with the controller; unstable plant poles: {})",
            u.how
        ))
    ))];
    blocks.push(Block::Table(Table {
        id: "model_comparison".into(),
        caption: "Model comparison (seed paper, table 1): parameters, errors against the measured FRF \
                  (relative RMSE, median relative, RMS dB), BIC, validation fit, unstable poles and, on \
                  the twin, the median relative error against the exact plant. Highlighted: the chosen model."
            .into(),
        header: vec![
            "model".into(),
            "parameters".into(),
            "rel. RMSE [%]".into(),
            "median rel. [%]".into(),
            "RMS error [dB]".into(),
            "BIC".into(),
            "validation fit [%]".into(),
            "unstable poles".into(),
            "error vs truth [%]".into(),
            "note".into(),
        ],
        rows,
        highlight: chosen,
    }));
    if let (Some(i), false) = (chosen, stage.choice.among_valid) {
        blocks.push(note(
            NoteKind::Fail,
            format!(
                "No candidate is valid (see the notes in the table); {} is shown as the best of the invalid ones.",
                cands[i].label()
            ),
        ));
    }
    if let Some(c) = stage.chosen() {
        blocks.push(note(
            NoteKind::Pass,
            format!(
                "Chosen model: {} ({} parameters{}).",
                c.label(),
                c.n_params,
                c.validation_fit
                    .map_or(String::new(), |f| format!(", validation fit {} %", fmt(f)))
            ),
        ));
    } else {
        blocks.push(note(
            NoteKind::Fail,
            "No candidate could be fitted; see the notes in the table.",
        ));
    }
    // Bode overlays and error curves, one figure per structure
    if let Some(m) = &stage.measured {
        let f = &m.f_hz;
        for o in &stage.overlays {
            let s = o.structure;
            let mut curves = vec![Curve {
                name: "measured FRF",
                f,
                g: &m.plant,
                std: None,
                style: Style::Line,
                color: Some(7),
            }];
            for (k, c) in o.fits.iter().enumerate() {
                curves.push(Curve {
                    name: &c.label,
                    f,
                    g: &c.response,
                    std: None,
                    style: Style::Dashed,
                    color: Some(k),
                });
            }
            let mut panels = bode_panels(&curves, "|P| [dB]");
            let err: Vec<_> = o
                .fits
                .iter()
                .enumerate()
                .map(|(k, c)| series(&c.label, f, &c.relative_error, Style::Line, Some(k)))
                .collect();
            panels.push(xy(
                "relative error against the measured FRF",
                log("frequency [Hz]"),
                log("|Ĝ − P̂| / |P̂| [-]"),
                err,
            ));
            blocks.push(Block::Figure(figure(
                &format!("bode_{s}"),
                &format!("{} fits: Bode overlay and error curves", s.to_uppercase()),
                format!(
                    "The {} models of orders {:?} against the measured plant FRF, and their relative error per line.",
                    s.to_uppercase(),
                    stage.orders
                ),
                panels,
                1,
            )));
        }
    }
    Section {
        id: "models".into(),
        title: "Parametric models".into(),
        blocks,
    }
}

/// The pole-zero section (id `pole-zero`): the maps of the chosen structure's candidates, the
/// chosen model zoomed and in the s-plane, and the tables of poles.
pub(crate) fn pole_zero_section(stage: &PoleZeroStage) -> Section {
    let mut panels = Vec::new();
    let rows: Vec<Vec<String>> = stage
        .rows
        .iter()
        .map(|r| {
            panels.push(pz_panel(&r.label, &r.poles, &r.zeros, None));
            let unstable: Vec<String> = r
                .unstable
                .iter()
                .map(|z| format!("{:.5}{:+.5}j", z.re, z.im))
                .collect();
            vec![
                r.label.clone(),
                r.poles.len().to_string(),
                r.zeros.len().to_string(),
                if unstable.is_empty() {
                    "none".into()
                } else {
                    unstable.join(", ")
                },
                r.cancellations.to_string(),
                r.closest.map_or("—".into(), fmt),
            ]
        })
        .collect();
    let mut ct_rows = Vec::new();
    let mut ct_note = None;
    if let Some(ch) = &stage.chosen {
        let label = &ch.label;
        panels.push(pz_panel(
            &format!("{label}, zoomed near z = 1"),
            &ch.poles,
            &ch.zeros,
            Some(ch.zoom_radius),
        ));
        let outside = ch.outside;
        if outside > 0 {
            ct_note = Some(format!(
                "{outside} pole{} of {label} with a natural frequency above f_s/15 lie{} outside the \
                 zoomed views.",
                if outside == 1 { "" } else { "s" },
                if outside == 1 { "s" } else { "" }
            ));
        }
        if let Some(sp) = &ch.s_plane {
            let mut p = xy(
                &format!("{label}, s-plane (s = f_s ln z, in Hz)"),
                lin("real part σ/2π [Hz]"),
                lin("imaginary part ω/2π [Hz]"),
                vec![
                    series(
                        "poles",
                        &sp.poles_hz.iter().map(|v| v.re).collect::<Vec<_>>(),
                        &sp.poles_hz.iter().map(|v| v.im).collect::<Vec<_>>(),
                        Style::Markers(Marker::Cross),
                        Some(0),
                    ),
                    series(
                        "zeros",
                        &sp.zeros_hz.iter().map(|v| v.re).collect::<Vec<_>>(),
                        &sp.zeros_hz.iter().map(|v| v.im).collect::<Vec<_>>(),
                        Style::Markers(Marker::Circle),
                        Some(1),
                    ),
                ],
            );
            p.equal_aspect = false;
            if let Some((xr, yr)) = sp.range {
                p.x.range = Some(xr);
                p.y.range = Some(yr);
            }
            panels.push(p);
            for ph in &sp.table {
                let z = ph.z;
                ct_rows.push(vec![
                    if ph.real {
                        format!("{:.6}", z.re)
                    } else {
                        format!("{:.6} ± {:.6}j", z.re, z.im)
                    },
                    fmt(z.norm()),
                    fmt(ph.natural_hz),
                    if ph.real {
                        "— (real)".into()
                    } else {
                        fmt(ph.damping)
                    },
                    match ph.time_constant_ms {
                        Some(t) if z.norm() > 1.0 => {
                            format!("unstable (time constant {} ms)", fmt(t))
                        }
                        Some(t) => format!("stable (time constant {} ms)", fmt(t)),
                        None => "stable".into(),
                    },
                ]);
            }
        }
    }
    let truth = &stage.truth_unstable_poles;
    let mut blocks = vec![Block::Figure(figure(
        "pole_zero",
        &format!(
            "Pole-zero maps of the {} candidates",
            stage.structure.to_uppercase()
        ),
        format!(
            "Poles (×) and zeros (○) in the z-plane with the unit circle, for every order of the chosen \
             structure; the last two panels show the chosen model zoomed onto the poles near z = 1 (at \
             a high sample rate every mode of the plant sits there) and in the s-plane in Hz \
             (s = f_s ln z). An AMB plant must keep its unstable real pole outside the unit circle{}.",
            if truth.is_empty() {
                String::new()
            } else {
                format!(
                    " (the twin's exact plant: {})",
                    truth
                        .iter()
                        .map(|z| format!("z = {:.5}", z.re))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        ),
        panels,
        2,
    ))];
    blocks.push(Block::Table(Table {
        id: "pole_zero".into(),
        caption: format!(
            "Poles, zeros, unstable poles and near pole-zero cancellations (a pole and a zero closer \
             than {} in the z-plane); a near cancellation means the order is higher than the data \
             support.",
            fmt(stage.cancellation_tol)
        ),
        header: vec![
            "model".into(),
            "poles".into(),
            "zeros".into(),
            "unstable poles".into(),
            "near cancellations".into(),
            "closest pair".into(),
        ],
        rows,
        highlight: None,
    }));
    if !ct_rows.is_empty() {
        let label = stage
            .chosen
            .as_ref()
            .map_or(String::new(), |c| c.label.clone());
        blocks.push(Block::Table(Table {
            id: "poles_hz".into(),
            caption: format!(
                "Poles of the chosen model {label} in continuous time, s = f_s ln z: natural frequency \
                 |s|/2π and damping ratio −Re s/|s| (one row per complex pair), slowest first."
            ),
            header: vec![
                "z".into(),
                "|z|".into(),
                "natural frequency [Hz]".into(),
                "damping [-]".into(),
                "stability".into(),
            ],
            rows: ct_rows,
            highlight: None,
        }));
    }
    if let Some(n) = ct_note {
        blocks.push(note(NoteKind::Info, n));
    }
    Section {
        id: "pole-zero".into(),
        title: "Pole-zero check".into(),
        blocks,
    }
}
