//! The report's "Nonparametric FRF" and "Order estimation" sections, drawn from the typed
//! stage results ([`FrfStage`], [`OrderStage`]) alone.

use super::data::Units;
use super::figures::{bode_panels, figure, lin, log, series, xy, Curve};
use super::Ctx;
use crate::analysis::FrfMethod;
use crate::report::{
    format_number as fmt, Block, Heatmap, NoteKind, Panel, PanelContent, Section, Style, Table,
};
use crate::stage::{
    ErrorBasis, FrfStage, OrderRecommendation, OrderStage, PlantEstimator, ResonanceScan,
};

/// The "Nonparametric FRF" section: the method, the bands, the plant's Bode plot with its 95 %
/// band (and the twin's exact plant and the indirect estimate when there), the coherences, the
/// quality table and the data warnings.
pub(crate) fn frf_section(st: &FrfStage, units: &Units) -> Section {
    let a = &st.analysis;
    let f = st.f_hz();
    let plant = &a.frf.plant;
    let std = plant.std();
    let mut curves = vec![Curve {
        name: "estimate",
        f,
        g: plant.values(),
        std: std.as_deref(),
        style: Style::Line,
        color: Some(0),
    }];
    if let Some(t) = &st.truth {
        curves.push(Curve {
            name: "twin's exact plant",
            f,
            g: &t.plant,
            std: None,
            style: Style::Dashed,
            color: Some(1),
        });
    }
    if let Some(ind) = &a.frf.plant_indirect {
        curves.push(Curve {
            name: "indirect (known controller)",
            f,
            g: ind.values(),
            std: None,
            style: Style::Dashed,
            color: Some(2),
        });
    }
    let method = match &st.method {
        FrfMethod::Periodic {
            period_samples,
            skip_periods,
        } => format!(
            "period-synchronous averaging ({period_samples} samples per period, {} periods averaged, {skip_periods} dropped)",
            st.samples / period_samples - skip_periods
        ),
        FrfMethod::Welch { nperseg, .. } => {
            format!("Welch averaging (Hann window, {nperseg} samples per segment, 50 % overlap)")
        }
    };
    let how = match st.estimator {
        PlantEstimator::Joint => "joint input-output method P = T_ry / T_ru",
        PlantEstimator::Direct => {
            "direct method u → y (no excitation recorded: biased by the feedback of the noise)"
        }
        PlantEstimator::H1 => "H1 estimate u → y (open loop)",
    };
    let has_r = st.has_r;
    let mut panels = bode_panels(&curves, &format!("|P| [dB re 1 {}]", units.plant));
    // without a recorded r the "reference" of the analysis is u itself
    let coh_name = if has_r { "γ²_ry" } else { "γ²_uy" };
    let mut coh = vec![series(coh_name, f, &a.frf.coh_ry, Style::Line, Some(0))];
    if has_r {
        coh.push(series("γ²_ru", f, &a.frf.coh_ru, Style::Line, Some(3)));
    }
    panels.push(xy(
        "coherence",
        log("frequency [Hz]"),
        lin("coherence [-]"),
        coh,
    ));
    let bands = a.bands;
    let mut blocks = vec![
        Block::Text(format!(
            "Nonparametric plant FRF of the identification record ({} samples, {} Hz) by {method}; {how}. \
             The band is the 95 % confidence band from the propagated standard deviation.",
            st.samples,
            fmt(st.fs)
        )),
        Ctx::note(
            NoteKind::Info,
            format!(
                "Bands: {}. Rule (docs/frf.md): the FRF band spans the lines where the excitation \
                 is within 10 dB of its strongest line, the quality band those within 3 dB; a band \
                 given in [frf] band_hz / quality_band_hz wins.",
                bands.describe()
            ),
        ),
        Block::Figure(figure(
            "plant_frf",
            "Plant FRF with 95 % band and coherence",
            format!(
                "Magnitude and phase of the estimated plant over {}–{} Hz ({} lines), its 95 % band (±1.96σ), {}and the coherence{}.",
                fmt(bands.band.0),
                fmt(bands.band.1),
                f.len(),
                if st.truth.is_some() { "the twin's exact linearised plant, " } else { "" },
                if has_r { " of r with y and with u" } else { " of u with y" }
            ),
            panels,
            1,
        )),
    ];
    let q = &a.quality;
    let mut qrows = vec![
        vec![
            "quality band [Hz]".to_string(),
            format!("{}–{}", fmt(q.band.0), fmt(q.band.1)),
        ],
        vec!["lines in band".into(), q.lines.to_string()],
        vec!["mean coherence γ²_ry".into(), fmt(q.mean_coherence_ry)],
    ];
    if has_r {
        qrows.push(vec![
            "mean coherence γ²_ru".into(),
            fmt(q.mean_coherence_ru),
        ]);
    }
    qrows.push(vec![
        "mean plant variance".into(),
        fmt(q.mean_plant_variance),
    ]);
    qrows.push(vec![
        "mean relative plant variance".into(),
        fmt(q.mean_plant_rel_variance),
    ]);
    if let Some(snr) = q.output_snr_db {
        qrows.push(vec!["output SNR [dB]".into(), fmt(snr)]);
    }
    if let Some(e) = &st.errors_vs_truth {
        qrows.push(vec![
            "median error vs exact plant, quality band [%]".into(),
            fmt(e.median_pct),
        ]);
        qrows.push(vec![
            "90th percentile error vs exact plant, quality band [%]".into(),
            fmt(e.p90_pct),
        ]);
        qrows.push(vec![
            "median error vs exact plant, 10–1000 Hz (the seed paper's band) [%]".into(),
            fmt(e.median_10_1000_pct),
        ]);
    }
    blocks.push(Block::Table(Table {
        id: "frf_quality".into(),
        caption: "Quality measures of the FRF (seed paper, section 3.3).".into(),
        header: vec!["measure".into(), "value".into()],
        rows: qrows,
        highlight: None,
    }));
    for w in &st.warnings {
        blocks.push(Ctx::note(NoteKind::Warning, w.clone()));
    }
    Section {
        id: "frf".into(),
        title: "Nonparametric FRF".into(),
        blocks,
    }
}

/// The "Order estimation" section: the recommendation (or why there is none) first, the ARX
/// loss and BIC heatmaps, the resonance table and the errors per order.
pub(crate) fn order_section(st: &OrderStage) -> Section {
    let arx = &st.arx;
    let (best_na, best_nb, _) = arx.best;
    let hl = Some((best_nb - 1, best_na - 1));
    let heat = |title: &str, z: Vec<Vec<f64>>, label: &str| Panel {
        title: title.into(),
        x: lin("nb"),
        y: lin("na"),
        content: PanelContent::Heatmap(Heatmap {
            x: arx.nb.clone(),
            y: arx.na.clone(),
            z,
            z_label: label.into(),
            highlight: hl,
        }),
        spans: Vec::new(),
        equal_aspect: false,
    };
    let mut blocks = vec![Block::Figure(figure(
        "order_heatmaps",
        "ARX loss and BIC over na × nb",
        format!(
            "ARX(na, nb, nk = {}) fitted by least squares to the identification record u → y ({} samples): \
             log10 of the loss V_N (mean squared one-step error) and the BIC. Outlined: the smallest BIC, \
             na = {}, nb = {}.",
            arx.nk,
            arx.scan.n_samples,
            best_na,
            best_nb
        ),
        vec![
            heat("log10 loss", arx.log10_loss.clone(), "log10 V_N [log10 m²]"),
            heat("BIC", arx.bic.clone(), "BIC [-]"),
        ],
        2,
    ))];
    if arx.on_edge {
        blocks.push(Ctx::note(
            NoteKind::Info,
            format!(
                "The smallest BIC lies on the edge of the grid (na = {}, nb = {}): on long records the \
                 ARX loss keeps falling with order because ARX must also model the noise; the ARX orders \
                 bound the plant order from above only. Extend [order] na_max / nb_max to see the minimum.",
                best_na, best_nb
            ),
        ));
    }
    if let Some(r) = &st.resonances {
        if let Some(e) = &r.error {
            blocks.push(Ctx::note(
                NoteKind::Warning,
                format!("Resonance peaks not searched: {e}."),
            ));
        }
        blocks.push(Block::Table(resonance_table(r, st.closed_loop)));
    }
    match &st.recommendation {
        Err(why) => blocks.insert(
            0,
            Ctx::note(
                NoteKind::Warning,
                format!(
                    "No order recommendation: {why}. The models step fits [models] orders only."
                ),
            ),
        ),
        Ok(r) => {
            if let Some(t) = errors_table(r) {
                blocks.push(Block::Table(t));
            }
            blocks.insert(0, Ctx::note(NoteKind::Info, recommendation_text(st, r)));
        }
    }
    Section {
        id: "order".into(),
        title: "Order estimation".into(),
        blocks,
    }
}

/// The table of resonance peaks with the order they imply.
fn resonance_table(r: &ResonanceScan, closed: bool) -> Table {
    let (peaks, searched, n) = (&r.peaks, r.searched, r.order);
    let rows = peaks
        .iter()
        .map(|p| {
            vec![
                fmt(p.f_hz),
                fmt(20.0 * p.magnitude.log10()),
                fmt(p.prominence_db),
                p.bandwidth_hz().map_or("—".into(), fmt),
                p.damping.map_or("—".into(), fmt),
            ]
        })
        .collect();
    Table {
        id: "resonances".into(),
        caption: format!(
            "Resonance peaks of the plant FRF in the quality band {}–{} Hz ({searched} lines with \
             relative standard deviation ≤ 10 %, prominence ≥ {} dB), with the half-power \
             bandwidth and the damping ratio it implies. {}; {}",
            fmt(r.band.0),
            fmt(r.band.1),
            fmt(r.min_prominence_db),
            if peaks.is_empty() {
                "No resonance peak in the band, so no state comes from peaks".to_string()
            } else {
                format!(
                    "Two states per lightly damped mode give {n} states for the {} peak{}",
                    peaks.len(),
                    if peaks.len() == 1 { "" } else { "s" }
                )
            },
            if closed {
                format!(
                    "in an AMB loop the rigid-body (unstable) pair adds two more, so at least {} \
                     states (a lower bound: modes outside the band and actuator, sensor and delay \
                     poles show no peak; see the recommendation above).",
                    n + 2
                )
            } else {
                "actuator, sensor and delay dynamics may add one or two more.".to_string()
            }
        ),
        header: vec![
            "f [Hz]".into(),
            "|P| [dB]".into(),
            "prominence [dB]".into(),
            "bandwidth [Hz]".into(),
            "damping [-]".into(),
        ],
        rows,
        highlight: None,
    }
}

/// The table of errors per order the recommendation rests on.
fn errors_table(r: &OrderRecommendation) -> Option<Table> {
    let e = r.errors.as_ref()?;
    let (caption, header, missing) = match e.basis {
        ErrorBasis::Frf { band } => (
            format!(
                "State-space fits of orders 1–{} to the plant FRF over {}–{} Hz (the models \
                 step's band, weights and unstable-pole count): relative RMSE per order. Adequate: \
                 valid and within {} % of the smallest error ({} %).",
                e.scan_max,
                fmt(band.0),
                fmt(band.1),
                fmt(100.0 * (e.tolerance - 1.0)),
                fmt(100.0 * e.best)
            ),
            "relative RMSE [%]",
            "— (not valid)",
        ),
        ErrorBasis::TimeValidation => (
            format!(
                "State-space fits of orders 1–{} to the identification record \
                 (the models step's criterion): validation error 100 % − fit per order (simulation for a \
                 stable model, else one-step prediction). \
                 Adequate: within {} % of the smallest error ({} %).",
                e.scan_max,
                fmt(100.0 * (e.tolerance - 1.0)),
                fmt(e.best)
            ),
            "validation error [%]",
            "— (no fit)",
        ),
    };
    let scale = match e.basis {
        ErrorBasis::Frf { .. } => 100.0,
        ErrorBasis::TimeValidation => 1.0,
    };
    Some(Table {
        id: "order_fit_errors".into(),
        caption,
        header: vec!["order".into(), header.into(), "adequate".into()],
        rows: e
            .rows
            .iter()
            .map(|row| {
                vec![
                    row.order.to_string(),
                    row.error.map_or(missing.into(), |v| fmt(scale * v)),
                    if row.adequate { "yes" } else { "no" }.into(),
                ]
            })
            .collect(),
        highlight: None,
    })
}

/// The recommendation's paragraph: the order and range, why, and how the resonance count and
/// the ARX BIC minimum compare with it.
fn recommendation_text(st: &OrderStage, r: &OrderRecommendation) -> String {
    let (n, lo, hi) = (r.n, r.lo, r.hi);
    let sv_text = r.subspace.as_ref().map(|s| {
        let sv: Vec<String> = s.singular_values.iter().map(|v| fmt(*v)).collect();
        format!(
            "the subspace (CVA) singular values of u → y ({}) have their largest gap after {}",
            sv.join(", "),
            s.order
        )
    });
    let how = match (&r.errors, &sv_text) {
        (Some(e), _) if matches!(e.basis, ErrorBasis::Frf { .. }) => format!(
            "the state-space fits to the plant FRF stop improving there: orders from {} on fit within \
             {} % of the smallest relative error ({} %) (the range adds up to one more pole pair), order {} does not",
            lo,
            fmt(100.0 * (e.tolerance - 1.0)),
            fmt(100.0 * e.best),
            r.below
        ),
        (Some(e), Some(sv_text)) => {
            let agree = if r.subspace.as_ref().is_some_and(|s| (lo..=hi).contains(&s.order)) {
                "agrees"
            } else {
                "disagrees; the fits decide, since the gap of measured singular values is \
                 blurred by noise and feedback"
            };
            format!(
                "the state-space fits' validation error stops improving there: \
                 orders from {lo} on are within {} % of the smallest error ({} %) (the range \
                 adds up to one more pole pair), order {} is not; {sv_text}, which {agree}",
                fmt(100.0 * (e.tolerance - 1.0)),
                fmt(e.best),
                r.below
            )
        }
        (_, sv_text) => sv_text.clone().unwrap_or_default(),
    };
    let mut text = format!(
        "Recommended order {n} (range {lo}–{hi}) because {how}. The models step fits these orders \
         besides [models] orders."
    );
    let closed = st.closed_loop;
    if let Some(p) = st.significant_peaks {
        let lower = 2 * p + usize::from(closed) * 2;
        if lower > hi {
            text.push_str(&format!(
                " The resonance count disagrees: {p} significant peak(s) ask for at least {lower} \
                 states, more than the range; check the peaks below against the FRF's noise."
            ));
        } else if p == 0 {
            text.push_str(if closed {
                " No resonance peak is significant against the FRF's noise, so the peaks set no \
                 lower bound beyond the rigid-body pair (2 states)."
            } else {
                " No resonance peak is significant against the FRF's noise, so the peaks set no \
                 lower bound."
            });
        } else {
            text.push_str(&format!(
                " The {p} significant resonance peak(s) give at least {lower} states, consistent \
                 (actuator, sensor and delay poles make no peak)."
            ));
        }
    }
    let (na, nb, _) = st.arx.best;
    if st.arx.on_edge {
        text.push_str(&format!(
            " The ARX BIC minimum lies on the grid's edge (na = {na}, nb = {nb}), so it is no \
             estimate: ARX also models the noise and needs high orders."
        ));
    } else if na < lo {
        text.push_str(&format!(
            " The ARX BIC minimum na = {na} is below the range (an ARX model with a short noise \
             model may merge modes); the range rests on the fits above."
        ));
    } else {
        text.push_str(&format!(
            " The ARX BIC minimum na = {na} is consistent (an upper bound: ARX needs extra poles \
             for the noise model)."
        ));
    }
    text
}
