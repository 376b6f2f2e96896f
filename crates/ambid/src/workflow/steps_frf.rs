//! Steps 4–5: the nonparametric FRF of the identification record and the order estimation.

use super::data::Recording;
use super::figures::{bode_panels, figure, lin, log, series, xy, Curve};
use super::steps_signal::plan;
use super::{computation, Ctx, Failure, StepStatus};
use crate::analysis::{analyze, FrfSettings, Record};
use crate::experiment::{ExcitationKind, ExcitationPlan};
use crate::report::{
    format_number as fmt, Block, Heatmap, NoteKind, Panel, PanelContent, Style, Table,
};
use ambid_core::estimate::order::{arx_order_scan, ArxScanSpec};
use ambid_core::frf::resonance::{find_resonances_reliable, order_from_peaks, ResonanceOptions};
use serde_json::json;

/// FRF settings for a record of `n` samples at `fs` (periodic when the period is known).
pub fn settings(ctx: &Ctx<'_>, period: Option<usize>, n: usize, fs: f64) -> FrfSettings {
    let cfg = &ctx.cfg.frf;
    let periodic = match cfg.method.as_str() {
        "welch" => None,
        _ => period.filter(|p| n / p.max(&1) >= 2),
    };
    let mut s = match periodic {
        Some(p) => FrfSettings::periodic(p, ctx.cfg.data.skip_periods.min(n / p - 1)),
        None => {
            let nper = cfg
                .nperseg
                .unwrap_or_else(|| FrfSettings::default_nperseg(n));
            FrfSettings::welch(nper.min(n))
        }
    };
    // an explicit band wins; otherwise both bands are derived from the excitation of the record
    // (ambid_core::frf::band), on the twin and on files alike
    let _ = fs;
    s.band = cfg.band_hz.map(|[a, b]| (a, b));
    s.quality_band = cfg.quality_band_hz.map(|[a, b]| (a, b));
    s.i_sat = ctx.twin.as_ref().map(|t| t.twin.i_sat());
    s
}

/// The identification record (simulated on the twin at the chosen level on first use).
pub fn ensure_ident(ctx: &mut Ctx<'_>) -> Result<(), Failure> {
    if ctx.ident.is_some() {
        return Ok(());
    }
    let frac = ctx
        .level_frac
        .or(ctx.cfg.excitation.amplitude_pct.map(|p| p / 100.0))
        .unwrap_or(0.1);
    ctx.level_frac = Some(frac);
    let p = plan(ctx, frac);
    if let Some(t) = &ctx.twin {
        let (rec, _) = t.record(p, ctx.cfg.seed + 200, "identification")?;
        ctx.put("identification.level_pct", 100.0 * frac);
        ctx.put("identification.samples", rec.len() as f64);
        if let Some(s) = rec.saturated_fraction {
            ctx.put("identification.saturated_pct", 100.0 * s);
        }
        ctx.ident = Some(rec);
    }
    Ok(())
}

/// The independent validation record (twin: a different excitation and noise realisation).
pub fn ensure_valid(ctx: &mut Ctx<'_>) -> Result<(), Failure> {
    if ctx.valid.is_some() {
        return Ok(());
    }
    let frac = ctx
        .cfg
        .validation
        .amplitude_pct
        .map(|p| p / 100.0)
        .or(ctx.level_frac)
        .unwrap_or(0.1);
    let p = ExcitationPlan {
        kind: super::data::excitation_kind(&ctx.cfg.validation.excitation),
        seed: ctx.cfg.seed + 7,
        ..plan(ctx, frac)
    };
    if let Some(t) = &ctx.twin {
        let (rec, _) = t.record(p, ctx.cfg.seed + 300, "validation")?;
        ctx.valid = Some(rec);
    }
    Ok(())
}

/// The twin record without excitation (output SNR), or the `[data] noise` file.
fn noise_record(ctx: &Ctx<'_>) -> Result<Option<Vec<f64>>, Failure> {
    if let Some(t) = &ctx.twin {
        if !t.noise {
            return Ok(None);
        }
        let p = ExcitationPlan {
            kind: ExcitationKind::None,
            ..plan(ctx, 0.0)
        };
        return Ok(Some(t.record(p, ctx.cfg.seed + 400, "noise")?.0.y));
    }
    match &ctx.cfg.data.noise {
        Some(p) => Ok(Some(
            super::data::load_file(ctx.cfg, &ctx.base, p, "noise")?.y,
        )),
        None => Ok(None),
    }
}

pub fn frf(ctx: &mut Ctx<'_>) -> Result<StepStatus, Failure> {
    ensure_ident(ctx)?;
    let Some(rec) = ctx.ident.clone() else {
        return Ok(StepStatus::Skipped("no identification record".into()));
    };
    let noise = noise_record(ctx)?;
    let mut s = settings(ctx, rec.period, rec.len(), rec.fs());
    let has_r = rec.r.is_some();
    if has_r {
        s.controller = ctx.controller.as_ref().map(|c| c.state_space().clone());
    }
    // without a recorded excitation the input itself is the reference: the joint estimate is
    // then the H1 estimate u → y (open loop: unbiased; closed loop: the biased direct method)
    let r: &[f64] = rec.r.as_deref().unwrap_or(&rec.u);
    let record = Record {
        r,
        u: &rec.u,
        y: &rec.y,
        i: rec.i.as_deref(),
        fs: rec.fs(),
    };
    let a = analyze(&record, &s, noise.as_deref()).map_err(computation)?;
    let f = a.frf.f_hz().to_vec();
    let plant = &a.frf.plant;
    let std = plant.std();
    let truth = match &ctx.twin {
        Some(t) => Some(t.twin.plant_frf(&f).map_err(computation)?),
        None => None,
    };
    let mut curves = vec![Curve {
        name: "estimate",
        f: &f,
        g: plant.values(),
        std: std.as_deref(),
        style: Style::Line,
        color: Some(0),
    }];
    if let Some(t) = &truth {
        curves.push(Curve {
            name: "twin's exact plant",
            f: &f,
            g: t,
            std: None,
            style: Style::Dashed,
            color: Some(1),
        });
    }
    if let Some(ind) = &a.frf.plant_indirect {
        curves.push(Curve {
            name: "indirect (known controller)",
            f: &f,
            g: ind.values(),
            std: None,
            style: Style::Dashed,
            color: Some(2),
        });
    }
    let method = match &s.method {
        crate::analysis::FrfMethod::Periodic {
            period_samples,
            skip_periods,
        } => format!(
            "period-synchronous averaging ({period_samples} samples per period, {} periods averaged, {skip_periods} dropped)",
            rec.len() / period_samples - skip_periods
        ),
        crate::analysis::FrfMethod::Welch { nperseg, .. } => {
            format!("Welch averaging (Hann window, {nperseg} samples per segment, 50 % overlap)")
        }
    };
    let how = if has_r {
        "joint input-output method P = T_ry / T_ru"
    } else if rec.closed_loop {
        "direct method u → y (no excitation recorded: biased by the feedback of the noise)"
    } else {
        "H1 estimate u → y (open loop)"
    };
    let mut panels = bode_panels(
        &curves,
        &format!("|P| [dB re 1 {}]", super::data::plant_unit(ctx)),
    );
    // without a recorded r the "reference" of the analysis is u itself
    let coh_name = if has_r { "γ²_ry" } else { "γ²_uy" };
    let mut coh = vec![series(coh_name, &f, &a.frf.coh_ry, Style::Line, Some(0))];
    if has_r {
        coh.push(series("γ²_ru", &f, &a.frf.coh_ru, Style::Line, Some(3)));
    }
    panels.push(xy(
        "coherence",
        log("frequency [Hz]"),
        lin("coherence [-]"),
        coh,
    ));
    let bands = a.bands;
    ctx.put("frf.band_lo_hz", bands.band.0);
    ctx.put("frf.band_hi_hz", bands.band.1);
    ctx.put("frf.quality_band_lo_hz", bands.quality_band.0);
    ctx.put("frf.quality_band_hi_hz", bands.quality_band.1);
    ctx.put("frf.band_origin", json!(bands.band_origin));
    ctx.put("frf.quality_band_origin", json!(bands.quality_origin));
    let mut blocks = vec![
        Block::Text(format!(
            "Nonparametric plant FRF of the identification record ({} samples, {} Hz) by {method}; {how}. \
             The band is the 95 % confidence band from the propagated standard deviation.",
            rec.len(),
            fmt(rec.fs())
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
        Block::Figure(super::figures::figure(
            "plant_frf",
            "Plant FRF with 95 % band and coherence",
            format!(
                "Magnitude and phase of the estimated plant over {}–{} Hz ({} lines), its 95 % band (±1.96σ), {}and the coherence{}.",
                fmt(bands.band.0),
                fmt(bands.band.1),
                f.len(),
                if truth.is_some() { "the twin's exact linearised plant, " } else { "" },
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
    ctx.put("frf.lines", f.len() as f64);
    ctx.put("frf.mean_coh_ry", q.mean_coherence_ry);
    if has_r {
        qrows.push(vec![
            "mean coherence γ²_ru".into(),
            fmt(q.mean_coherence_ru),
        ]);
        ctx.put("frf.mean_coh_ru", q.mean_coherence_ru);
    }
    qrows.push(vec![
        "mean plant variance".into(),
        fmt(q.mean_plant_variance),
    ]);
    qrows.push(vec![
        "mean relative plant variance".into(),
        fmt(q.mean_plant_rel_variance),
    ]);
    ctx.put("frf.mean_plant_variance", q.mean_plant_variance);
    ctx.put("frf.mean_plant_rel_variance", q.mean_plant_rel_variance);
    if let Some(snr) = q.output_snr_db {
        qrows.push(vec!["output SNR [dB]".into(), fmt(snr)]);
        ctx.put("frf.output_snr_db", snr);
    }
    if let Some(t) = &truth {
        // over the quality band (derived from the excitation), and over the seed paper's
        // 10–1000 Hz where issue 3 states its bar (a check against the truth, not a default)
        let errors = |band: (f64, f64)| -> (f64, f64) {
            let mut e: Vec<f64> = plant
                .values()
                .iter()
                .zip(t)
                .zip(&f)
                .filter(|(_, f)| (band.0..=band.1).contains(*f))
                .map(|((x, t), _)| (x - t).norm() / t.norm())
                .collect();
            e.sort_by(f64::total_cmp);
            let pick = |q: f64| {
                e.get((q * e.len().saturating_sub(1) as f64).round() as usize)
                    .map_or(f64::NAN, |v| 100.0 * v)
            };
            (pick(0.5), pick(0.9))
        };
        let (med, p90) = errors(a.quality.band);
        let (med_seed, _) = errors(ambid_core::frf::quality::DEFAULT_BAND);
        qrows.push(vec![
            "median error vs exact plant, quality band [%]".into(),
            fmt(med),
        ]);
        qrows.push(vec![
            "90th percentile error vs exact plant, quality band [%]".into(),
            fmt(p90),
        ]);
        qrows.push(vec![
            "median error vs exact plant, 10–1000 Hz (the seed paper's band) [%]".into(),
            fmt(med_seed),
        ]);
        ctx.put("frf.plant_median_error_vs_truth_pct", med);
        ctx.put("frf.plant_p90_error_vs_truth_pct", p90);
        ctx.put("frf.plant_median_error_vs_truth_10_1000_pct", med_seed);
    }
    blocks.push(Block::Table(Table {
        id: "frf_quality".into(),
        caption: "Quality measures of the FRF (seed paper, section 3.3).".into(),
        header: vec!["measure".into(), "value".into()],
        rows: qrows,
        highlight: None,
    }));
    for (name, r) in &a.abnormal {
        if r.nonfinite.len() + r.spikes.len() + r.stuck_runs.len() > 0 {
            blocks.push(Ctx::note(
                NoteKind::Warning,
                format!("channel {name}: {}", r.summary()),
            ));
        }
    }
    for (name, r) in &a.saturation {
        if r.count > 0 {
            blocks.push(Ctx::note(
                NoteKind::Warning,
                format!("channel {name}: {}", r.summary()),
            ));
        }
    }
    for w in &a.warnings {
        blocks.push(Ctx::note(NoteKind::Warning, w.clone()));
    }
    ctx.section("frf", "Nonparametric FRF", blocks);
    ctx.frf = Some(a);
    Ok(StepStatus::Done)
}

pub fn order(ctx: &mut Ctx<'_>) -> Result<StepStatus, Failure> {
    ensure_ident(ctx)?;
    ensure_valid(ctx)?;
    let (Some(rec), Some(val)) = (ctx.ident.clone(), ctx.valid.clone()) else {
        return Ok(StepStatus::Skipped("no identification record".into()));
    };
    let o = &ctx.cfg.order;
    let cut = |r: &Recording| -> (Vec<f64>, Vec<f64>) {
        let n = if o.max_samples > 0 {
            o.max_samples.min(r.len())
        } else {
            r.len()
        };
        (r.y[..n].to_vec(), r.u[..n].to_vec())
    };
    let (y, u) = cut(&rec);
    let (yv, uv) = cut(&val);
    let spec = ArxScanSpec::new(1..=o.na_max.max(1), 1..=o.nb_max.max(1), vec![o.nk]);
    let scan = arx_order_scan(&y, &u, &spec, Some((&yv, &uv))).map_err(computation)?;
    let na: Vec<f64> = (1..=o.na_max.max(1)).map(|v| v as f64).collect();
    let nb: Vec<f64> = (1..=o.nb_max.max(1)).map(|v| v as f64).collect();
    let mut loss = vec![vec![f64::NAN; nb.len()]; na.len()];
    let mut bic = vec![vec![f64::NAN; nb.len()]; na.len()];
    for r in &scan.rows {
        if r.na >= 1 && r.nb >= 1 && r.na <= na.len() && r.nb <= nb.len() {
            loss[r.na - 1][r.nb - 1] = r.loss.log10();
            bic[r.na - 1][r.nb - 1] = r.bic;
        }
    }
    let best = &scan.rows[scan.best_bic];
    let hl = Some((best.nb - 1, best.na - 1));
    let heat = |title: &str, z: Vec<Vec<f64>>, label: &str| Panel {
        title: title.into(),
        x: lin("nb"),
        y: lin("na"),
        content: PanelContent::Heatmap(Heatmap {
            x: nb.clone(),
            y: na.clone(),
            z,
            z_label: label.into(),
            highlight: hl,
        }),
        spans: Vec::new(),
        equal_aspect: false,
    };
    let on_edge = best.na == na.len() || best.nb == nb.len();
    ctx.put("order.arx_best_bic.na", best.na as f64);
    ctx.put("order.arx_best_bic.nb", best.nb as f64);
    ctx.put("order.arx_best_bic.nk", best.nk as f64);
    if let Some(v) = scan.best_val {
        let r = &scan.rows[v];
        ctx.put("order.arx_best_validation.na", r.na as f64);
        ctx.put("order.arx_best_validation.nb", r.nb as f64);
        if let Some(f) = r.val_fit {
            ctx.put("order.arx_best_validation.fit_pct", f);
        }
    }
    let mut blocks = vec![Block::Figure(figure(
        "order_heatmaps",
        "ARX loss and BIC over na × nb",
        format!(
            "ARX(na, nb, nk = {}) fitted by least squares to the identification record u → y ({} samples): \
             log10 of the loss V_N (mean squared one-step error) and the BIC. Outlined: the smallest BIC, \
             na = {}, nb = {}.",
            o.nk,
            scan.n_samples,
            best.na,
            best.nb
        ),
        vec![
            heat("log10 loss", loss, "log10 V_N [log10 m²]"),
            heat("BIC", bic, "BIC [-]"),
        ],
        2,
    ))];
    if on_edge {
        blocks.push(Ctx::note(
            NoteKind::Info,
            format!(
                "The smallest BIC lies on the edge of the grid (na = {}, nb = {}): on long records the \
                 ARX loss keeps falling with order because ARX must also model the noise; the ARX orders \
                 bound the plant order from above only. Extend [order] na_max / nb_max to see the minimum.",
                best.na, best.nb
            ),
        ));
    }
    // resonance count on the plant FRF
    let closed = ctx.is_closed_loop();
    if let Some(a) = &ctx.frf {
        let plant = &a.frf.plant;
        let opts = ResonanceOptions {
            band: a.quality.band,
            ..ResonanceOptions::default()
        };
        // only lines known to 10 % (relative std) can show a mode: noise ripple is no resonance
        let (peaks, searched) = match find_resonances_reliable(plant, &opts, 0.1) {
            Ok(p) => p,
            Err(e) => {
                blocks.push(Ctx::note(
                    NoteKind::Warning,
                    format!("Resonance peaks not searched: {e}."),
                ));
                (Vec::new(), 0)
            }
        };
        let n = order_from_peaks(&peaks);
        ctx.put("order.resonances", peaks.len() as f64);
        ctx.put("order.order_from_peaks", n as f64);
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
        blocks.push(Block::Table(Table {
            id: "resonances".into(),
            caption: format!(
                "Resonance peaks of the plant FRF in the quality band {}–{} Hz ({searched} lines with \
                 relative standard deviation ≤ 10 %, prominence ≥ {} dB), with the half-power \
                 bandwidth and the damping ratio it implies. {}; {}",
                fmt(opts.band.0),
                fmt(opts.band.1),
                fmt(opts.min_prominence_db),
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
                        "in an AMB loop the rigid-body (unstable) pair adds two more, so orders near {} \
                         are the candidates (seed paper, section 3.4).",
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
        }));
    }
    ctx.section("order", "Order estimation", blocks);
    Ok(StepStatus::Done)
}
