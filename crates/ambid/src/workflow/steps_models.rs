//! Steps 6–7: parametric models (fitted to the FRF in closed loop, or to the time record) with
//! their comparison table and Bode overlays, and the pole-zero check.

pub use super::candidates::{open_loop_response, Candidate, ONE_STEP, SIMULATION};
use super::figures::{bode_panels, figure, lin, log, pz_panel, series, xy, Curve};
use super::{computation, Ctx, Error, ModelOut, StepStatus};
use crate::fitting::{identify_state_space, SsFitOptions, SsFocus};
use crate::report::{format_number as fmt, Block, Marker, NoteKind, Style, Table};
use ambid_core::c64;
use ambid_core::estimate::arx::{arx, ArxOrders};
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::estimate::pem::{self, Orders, PemOptions};
use ambid_core::frf::band::{fit_band, FIT_REL_HALFWIDTH};
use ambid_core::lti::{PolyModel, StateSpace, Structure};
use ambid_core::validate::compare::{
    compare_models, supported_unstable_poles, CompareSpec, ValidationRecord,
};
use ambid_core::validate::fit::fit_percent;
use ambid_core::validate::pz::{PzAnalysis, PzOptions};
use serde_json::json;

/// A time-domain fit: the model, its polynomial form, its parameter count and its Kalman gain.
type TimeFit = (StateSpace, Option<PolyModel>, usize, Option<Vec<f64>>);

use crate::validation::median_relative_error as median_rel;

/// `[models] orders` with the order step's recommended range (`order.recommended_lo` …
/// `order.recommended_hi`) added, sorted, each order capped by the record's parameter budget
/// ([`super::config::SAMPLES_PER_PARAMETER`] samples per parameter) and
/// [`super::config::MAX_MODEL_ORDER`].
fn orders_with_recommendation(
    given: &[usize],
    order: Option<&super::OrderSummary>,
    rec: Option<&super::data::Recording>,
) -> Vec<usize> {
    let mut out = given.to_vec();
    if let Some((lo, hi)) =
        order.and_then(|o| Some((o.recommended_lo? as usize, o.recommended_hi? as usize)))
    {
        let cap = rec.map_or(usize::MAX, |r| {
            r.len() / super::config::SAMPLES_PER_PARAMETER
        });
        out.extend((lo.max(1)..=hi).filter(|&o| {
            o <= super::config::MAX_MODEL_ORDER && super::config::parameters_of_order(o) <= cap
        }));
    }
    out.sort_unstable();
    out.dedup();
    out
}

pub fn models(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    ctx.ensure_ident()?;
    ctx.ensure_valid()?;
    let cfg_orig = &ctx.cfg.models;
    let cfg = &super::config::ModelsSection {
        orders: orders_with_recommendation(
            &cfg_orig.orders,
            ctx.typed.order.as_ref(),
            ctx.ident.as_ref(),
        ),
        ..cfg_orig.clone()
    };
    let Some(rec) = ctx.ident.clone() else {
        return Ok(StepStatus::Skipped("no identification record".into()));
    };
    let has_r = rec.r().is_some();
    let domain = cfg.domain.clone().unwrap_or_else(|| {
        if has_r && rec.closed_loop && ctx.frf.is_some() {
            "frf".into()
        } else {
            "time".into()
        }
    });
    if domain == "frf" && ctx.frf.is_none() {
        return Ok(StepStatus::Skipped(
            "models.domain = \"frf\" needs the frf step".into(),
        ));
    }
    let ts = rec.ts();
    let mut cands: Vec<Candidate> = Vec::new();
    let truth_f = ctx.frf.as_ref().map(|a| a.frf.f_hz().to_vec());
    let truth = match (&ctx.twin, &truth_f) {
        (Some(t), Some(f)) => Some(t.twin.plant_frf(f).map_err(computation)?),
        _ => None,
    };
    let validation_kind: String;
    let mut unstable_how: Option<(Option<usize>, String)> = None;
    let mut band_how: Option<String> = None;
    if domain == "frf" {
        let Some(a) = &ctx.frf else {
            return Ok(StepStatus::Skipped("no FRF".into()));
        };
        let frd = &a.frf.plant;
        // the fit band: [models] band_hz, else where the plant FRF is measured reliably (the
        // rule of `ambid fit frf.csv` and `compare-models`, ambid_core::frf::band::fit_band)
        let explicit_band = cfg.band_hz.map(|[a, b]| (a, b));
        let fit_band_hz = match explicit_band {
            Some(b) => {
                band_how = Some(format!(
                    "band {:.1}–{:.1} Hz from [models] band_hz",
                    b.0, b.1
                ));
                b
            }
            None => {
                let d = fit_band(frd, FIT_REL_HALFWIDTH).map_err(computation)?;
                band_how = Some(d.describe().replace("give --band", "set [models] band_hz"));
                d.band
            }
        };
        let weights = match cfg.weights.as_str() {
            "uniform" => FreqWeights::Uniform,
            "coherence" => FreqWeights::Coherence(a.frf.coh_ry.clone()),
            _ if frd.variance().is_some() => FreqWeights::InverseVariance,
            _ => FreqWeights::Uniform,
        };
        let spec = CompareSpec {
            structures: cfg.structures.to_vec(),
            orders: cfg.orders.clone(),
            nk: cfg.nk,
            fit: FreqFitOptions {
                band_hz: Some(fit_band_hz),
                weights,
                max_iterations: cfg.max_iterations,
                ..FreqFitOptions::default()
            },
            ..CompareSpec::default()
        };
        let ctrl = ctx.controller.as_ref().map(|c| c.state_space());
        let (n_u, how) = supported_unstable_poles(frd, ctrl, explicit_band, cfg.unstable_poles);
        unstable_how = Some((n_u, how));
        let spec = CompareSpec {
            unstable_poles: n_u,
            controller: ctrl.cloned(),
            ..spec
        };
        let val = ctx.valid.as_ref();
        let vrec = match (val, &ctx.controller) {
            (Some(v), Some(c)) if v.r().is_some() && v.closed_loop => Some(ValidationRecord {
                r: v.r().unwrap_or(&[]),
                y: v.y(),
                controller: c.state_space(),
                skip: ctx.cfg.validation.skip.min(v.len() / 4),
            }),
            _ => None,
        };
        validation_kind = if vrec.is_some() {
            "closed-loop simulation with the controller".into()
        } else {
            "none (no controller or no validation record with r)".into()
        };
        let rows = compare_models(frd, &spec, vrec).map_err(computation)?;
        for r in rows {
            let truth_med = match (&r.model, &truth, &truth_f) {
                (Some(m), Some(t), Some(f)) => {
                    m.freq_response_siso(f).ok().map(|g| median_rel(&g, t))
                }
                _ => None,
            };
            cands.push(Candidate {
                structure: r.structure.name(),
                order: r.order,
                model: r.model,
                poly: None,
                n_params: r.n_params,
                relative_rmse: r.relative_rmse,
                median_relative: r.median_relative,
                db_rmse: r.db_rmse,
                bic: r.bic,
                validation_fit: r.validation_fit,
                unstable_poles: r.unstable_poles,
                truth_median_relative: truth_med,
                valid: r.valid,
                note: r.note,
                kalman: None,
            });
        }
    } else {
        let Some(val) = ctx.valid.clone() else {
            return Ok(StepStatus::Skipped("no validation record".into()));
        };
        let mut kinds = Vec::new();
        let focus = if cfg.focus == "simulation" {
            ambid_core::estimate::pem::Focus::Simulation
        } else {
            ambid_core::estimate::pem::Focus::Prediction
        };
        // state space: `auto` is `ambid fit`'s rule on open-loop records; a closed-loop record's
        // time-domain fit goes from u to y (direct method), where only the prediction criterion
        // (a noise model) is consistent
        let ss_focus = match cfg.focus.as_str() {
            "simulation" => SsFocus::Simulation,
            "prediction" => SsFocus::Prediction,
            _ if rec.closed_loop => SsFocus::Prediction,
            _ => SsFocus::Auto,
        };
        for s in &cfg.structures {
            for &n in &cfg.orders {
                let fitted: crate::error::Result<TimeFit> = (|| match s {
                    Structure::Arx => {
                        let f = arx(rec.y(), &[rec.u()], &ArxOrders::siso(n, n, cfg.nk), ts)?;
                        let p = f.model.to_poly(0)?;
                        Ok((p.g()?.to_state_space()?, Some(p), f.params.len(), None))
                    }
                    Structure::Oe => {
                        // open-loop records (no excitation r): an unstable start is an
                        // artefact and is stabilised; closed-loop ones keep the strict rule
                        let opts = PemOptions::default()
                            .with_max_iterations(cfg.max_iterations)?
                            .with_focus(focus)
                            .with_open_loop(!(has_r && rec.closed_loop));
                        let (f, _) = pem::pem(
                            rec.y(),
                            rec.u(),
                            Structure::Oe,
                            &Orders::oe(n, n, cfg.nk),
                            ts,
                            &opts,
                        )?;
                        let p = f.model;
                        Ok((p.g()?.to_state_space()?, Some(p), f.params.len(), None))
                    }
                    _ => {
                        let o = SsFitOptions {
                            order: Some(n),
                            focus: ss_focus,
                            max_iterations: cfg.max_iterations,
                            ..SsFitOptions::default()
                        };
                        let f = identify_state_space(rec.u(), rec.y(), ts, &o)?;
                        let np = n * n + 2 * n;
                        let k = f.pem.and_then(|p| p.kalman_gain);
                        Ok((f.model, None, np, k))
                    }
                })();
                let sname: &'static str = s.name();
                match fitted {
                    Ok((m, poly, np, k)) => {
                        let mut c = Candidate::time_fit(sname, n, poly, np, k);
                        let (fit, kind) = match open_loop_response(&c, &m, val.y(), val.u()) {
                            Some((yhat, kind)) => (fit_percent(val.y(), &yhat).ok(), kind),
                            None => (None, "unstable without a predictor: no fit"),
                        };
                        kinds.push(kind);
                        let unstable = m
                            .poles()
                            .ok()
                            .map(|p| p.iter().filter(|z| z.norm() >= 1.0).count());
                        let frf_err = match (
                            &ctx.frf,
                            m.freq_response_siso(truth_f.as_deref().unwrap_or(&[])),
                        ) {
                            (Some(a), Ok(g)) if !g.is_empty() => {
                                let p = a.frf.plant.values();
                                let num: f64 =
                                    g.iter().zip(p).map(|(a, b)| (a - b).norm_sqr()).sum();
                                let den: f64 = p.iter().map(|b| b.norm_sqr()).sum();
                                (Some((num / den).sqrt()), Some(median_rel(&g, p)))
                            }
                            _ => (None, None),
                        };
                        c.truth_median_relative = truth.as_ref().and_then(|t| {
                            m.freq_response_siso(truth_f.as_deref()?)
                                .ok()
                                .map(|g| median_rel(&g, t))
                        });
                        c.model = Some(m);
                        c.relative_rmse = frf_err.0;
                        c.median_relative = frf_err.1;
                        c.validation_fit = fit;
                        c.unstable_poles = unstable;
                        c.note = (kind != SIMULATION).then(|| format!("validation fit: {kind}"));
                        cands.push(c);
                    }
                    Err(e) => {
                        cands.push(Candidate {
                            valid: false,
                            note: Some(format!("{e:#}")),
                            ..Candidate::time_fit(sname, n, None, 0, None)
                        });
                    }
                }
            }
        }
        kinds.sort();
        kinds.dedup();
        validation_kind = format!("on the validation record: {}", kinds.join(" / "));
    }
    // choose
    let key = |c: &Candidate| -> Option<f64> {
        match ctx.cfg.models.select.as_str() {
            "bic" => c.bic,
            "frf" => c.relative_rmse,
            _ => c.validation_fit.map(|f| -f),
        }
    };
    // the best valid candidate by the configured key (BIC when no valid candidate has the key,
    // e.g. no validation fit); only when none is valid, the best of the others, reported as such
    let best = |only_valid: bool, key: &dyn Fn(&Candidate) -> Option<f64>| {
        cands
            .iter()
            .enumerate()
            .filter(|(_, c)| c.model.is_some() && (c.valid || !only_valid))
            .filter_map(|(i, c)| key(c).filter(|v| v.is_finite()).map(|v| (i, v)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    };
    let chosen_valid = best(true, &key).or_else(|| best(true, &|c: &Candidate| c.bic));
    let chosen = chosen_valid
        .or_else(|| best(false, &key))
        .or_else(|| cands.iter().position(|c| c.model.is_some()));
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
    let mut jrows = Vec::new();
    for c in &cands {
        jrows.push(super::ModelRow {
            model: c.label(),
            n_params: c.n_params as f64,
            relative_rmse_pct: c.relative_rmse.map(|v| 100.0 * v),
            median_relative_pct: c.median_relative.map(|v| 100.0 * v),
            db_rmse: c.db_rmse,
            bic: c.bic,
            validation_fit_pct: c.validation_fit,
            unstable_poles: c.unstable_poles.map(|u| u as f64),
            valid: c.valid,
            median_error_vs_truth_pct: c.truth_median_relative.map(|v| 100.0 * v),
        });
    }
    let mut summary = super::ModelsSummary {
        domain: domain.clone(),
        unstable_poles_supported: unstable_how.as_ref().map(|(n_u, _)| n_u.map(|n| n as f64)),
        table: jrows,
        chosen: None,
        chosen_validation_fit_pct: None,
        chosen_error_vs_truth_pct: None,
    };
    let mut blocks = vec![Block::Text(format!(
        "{} at orders {:?} ([models] orders {:?} plus the order step's recommended range); {}. Validation fit: {validation_kind}. Chosen by {} among the valid models{}.",
        if domain == "frf" {
            "ARX (Levy), OE (Sanathanan–Koerner + Levenberg–Marquardt) and state-space (frequency-domain subspace + LM) models fitted to the plant FRF"
        } else {
            "ARX (least squares), OE (prediction-error method) and state-space (N4SID + prediction-error refinement) models fitted to the identification record"
        },
        cfg.orders,
        cfg_orig.orders,
        if domain == "frf" {
            format!(
                "weights {}; {}",
                cfg.weights,
                band_how.as_deref().unwrap_or("every line")
            )
        } else {
            "validation fit on the independent record (simulation from the least-squares initial state for stable models, as MATLAB compare does; else the one-step prediction)".into()
        },
        match ctx.cfg.models.select.as_str() {
            "bic" => "the smallest BIC",
            "frf" => "the smallest relative FRF error",
            _ => "the best validation fit",
        },
        unstable_how.as_ref().map_or(String::new(), |(_, h)| format!(
            " (right number of unstable poles and a stable loop with the controller; unstable plant poles: {h})"
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
    if let (Some(i), None) = (chosen, chosen_valid) {
        blocks.push(Ctx::note(
            NoteKind::Fail,
            format!(
                "No candidate is valid (see the notes in the table); {} is shown as the best of the invalid ones.",
                cands[i].label()
            ),
        ));
    }
    if let Some(i) = chosen {
        let c = &cands[i];
        summary.chosen = Some(c.label());
        summary.chosen_validation_fit_pct = c.validation_fit;
        summary.chosen_error_vs_truth_pct = c.truth_median_relative.map(|e| 100.0 * e);
        blocks.push(Ctx::note(
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
        blocks.push(Ctx::note(
            NoteKind::Fail,
            "No candidate could be fitted; see the notes in the table.",
        ));
    }
    // Bode overlays and error curves, one figure per structure
    if let Some(a) = &ctx.frf {
        let f = a.frf.f_hz().to_vec();
        let meas = a.frf.plant.values().to_vec();
        for s in ["arx", "oe", "ss"] {
            let fits: Vec<(String, Vec<c64>)> = cands
                .iter()
                .filter(|c| c.structure == s)
                .filter_map(|c| {
                    let g = c.model.as_ref()?.freq_response_siso(&f).ok()?;
                    Some((c.label(), g))
                })
                .collect();
            if fits.is_empty() {
                continue;
            }
            let mut curves = vec![Curve {
                name: "measured FRF",
                f: &f,
                g: &meas,
                std: None,
                style: Style::Line,
                color: Some(7),
            }];
            for (k, (name, g)) in fits.iter().enumerate() {
                curves.push(Curve {
                    name,
                    f: &f,
                    g,
                    std: None,
                    style: Style::Dashed,
                    color: Some(k),
                });
            }
            let mut panels = bode_panels(&curves, "|P| [dB]");
            let err: Vec<_> = fits
                .iter()
                .enumerate()
                .map(|(k, (name, g))| {
                    let e: Vec<f64> = g
                        .iter()
                        .zip(&meas)
                        .map(|(a, b)| (a - b).norm() / b.norm())
                        .collect();
                    series(name, &f, &e, Style::Line, Some(k))
                })
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
                    cfg.orders
                ),
                panels,
                1,
            )));
        }
    }
    // export every candidate
    for c in &cands {
        let k = &c.kalman;
        if let Some(m) = &c.model {
            ctx.models.push(ModelOut {
                name: format!("{}{}", c.structure, c.order),
                ss: m.clone(),
                // an FRF-fitted ARX/OE is held in companion form: export its polynomials
                poly: c
                    .poly
                    .clone()
                    .or_else(|| crate::io::export::polynomial_form(c.structure, m)),
                kalman: c.kalman.clone(),
                meta: json!({
                    "structure": c.structure,
                    "order": c.order,
                    "domain": domain,
                    "n_params": c.n_params,
                    "relative_rmse": c.relative_rmse,
                    "bic": c.bic,
                    "validation_fit_pct": c.validation_fit,
                    "unstable_poles": c.unstable_poles,
                    "pem": {"kalman_gain": k},
                    "chosen": chosen.is_some_and(|i| cands[i].label() == c.label()),
                }),
            });
        }
    }
    ctx.section("models", "Parametric models", blocks);
    ctx.candidates = cands;
    ctx.chosen = chosen;
    ctx.typed.models = Some(summary);
    Ok(StepStatus::Done)
}

/// The chosen model's label, poles, zeros and sample time (for its zoomed views and table).
type ChosenPz = (String, Vec<c64>, Vec<c64>, Option<f64>);

pub fn pole_zero(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    let Some(ch) = ctx.chosen else {
        return Ok(StepStatus::Skipped(
            "no fitted model (run the models step)".into(),
        ));
    };
    let structure = ctx.candidates[ch].structure;
    let mut panels = Vec::new();
    let mut rows = Vec::new();
    let truth_unstable: Vec<c64> = match &ctx.twin {
        Some(t) => t.twin.plant_unstable_poles().unwrap_or_default(),
        None => Vec::new(),
    };
    let opts = PzOptions::default();
    let mut chosen_pz = None;
    let mut chosen_poles: Option<ChosenPz> = None;
    for (i, c) in ctx.candidates.iter().enumerate() {
        if c.structure != structure {
            continue;
        }
        let Some(m) = &c.model else { continue };
        let pz = PzAnalysis::from_state_space(m, &opts).map_err(computation)?;
        let poles: Vec<c64> = pz.poles.iter().map(|r| r.z).collect();
        let zeros: Vec<c64> = pz.zeros.iter().map(|r| r.z).collect();
        panels.push(pz_panel(&c.label(), &poles, &zeros, None));
        let unstable: Vec<String> = pz
            .poles
            .iter()
            .filter(|r| r.unstable)
            .map(|r| format!("{:.5}{:+.5}j", r.z.re, r.z.im))
            .collect();
        let min_d = pz
            .cancellations
            .iter()
            .map(|x| x.distance)
            .fold(f64::INFINITY, f64::min);
        rows.push(vec![
            c.label(),
            pz.poles.len().to_string(),
            pz.zeros.len().to_string(),
            if unstable.is_empty() {
                "none".into()
            } else {
                unstable.join(", ")
            },
            pz.cancellations.len().to_string(),
            if min_d.is_finite() {
                fmt(min_d)
            } else {
                "—".into()
            },
        ]);
        if i == ch {
            chosen_pz = Some((pz.cancellations.len(), unstable.len()));
            chosen_poles = Some((c.label(), poles.clone(), zeros.clone(), m.ts()));
        }
    }
    // the chosen model at a glance: its map zoomed onto the poles near z = 1 (at a high sample
    // rate every mode sits there), the s-plane in Hz and a table of the poles in Hz and damping
    let mut ct_rows = Vec::new();
    let mut ct_note = None;
    if let Some((label, poles, zeros, ts)) = &chosen_poles {
        // the poles that matter for the loop: natural frequency below f_s/15 (rigid-body and
        // bending modes; actuator, sensor and delay poles lie beyond)
        let fs_model = ts.filter(|t| *t > 0.0).map_or(1.0, |t| 1.0 / t);
        let slow = |z: &c64| {
            z.norm() > 1e-9 && (z.ln() * fs_model).norm() / std::f64::consts::TAU < fs_model / 15.0
        };
        let near: Vec<f64> = poles
            .iter()
            .filter(|z| slow(z))
            .map(|z| (c64::new(1.0, 0.0) - z).norm())
            .collect();
        let excess = poles.iter().map(|z| z.norm() - 1.0).fold(0.0_f64, f64::max);
        let r = (1.5 * near.iter().copied().fold(0.0, f64::max))
            .max(2.5 * excess)
            .clamp(1e-4, 0.6);
        let outside = poles.len() - near.len();
        panels.push(pz_panel(
            &format!("{label}, zoomed near z = 1"),
            poles,
            zeros,
            Some(r),
        ));
        if outside > 0 {
            ct_note = Some(format!(
                "{outside} pole{} of {label} with a natural frequency above f_s/15 lie{} outside the \
                 zoomed views.",
                if outside == 1 { "" } else { "s" },
                if outside == 1 { "s" } else { "" }
            ));
        }
        if let Some(ts) = ts.filter(|t| *t > 0.0) {
            let fs = 1.0 / ts;
            let to_hz = |z: &c64| -> Option<c64> {
                (z.norm() > 1e-9).then(|| z.ln() * fs / std::f64::consts::TAU)
            };
            let sp: Vec<c64> = poles.iter().filter_map(to_hz).collect();
            let sz: Vec<c64> = zeros
                .iter()
                .filter(|z| z.norm() < 10.0)
                .filter_map(to_hz)
                .collect();
            let mut p = xy(
                &format!("{label}, s-plane (s = f_s ln z, in Hz)"),
                lin("real part σ/2π [Hz]"),
                lin("imaginary part ω/2π [Hz]"),
                vec![
                    series(
                        "poles",
                        &sp.iter().map(|v| v.re).collect::<Vec<_>>(),
                        &sp.iter().map(|v| v.im).collect::<Vec<_>>(),
                        Style::Markers(Marker::Cross),
                        Some(0),
                    ),
                    series(
                        "zeros",
                        &sz.iter().map(|v| v.re).collect::<Vec<_>>(),
                        &sz.iter().map(|v| v.im).collect::<Vec<_>>(),
                        Style::Markers(Marker::Circle),
                        Some(1),
                    ),
                ],
            );
            p.equal_aspect = false;
            // zoomed onto the slow poles (with the origin)
            let slow_s: Vec<c64> = poles.iter().filter(|z| slow(z)).filter_map(to_hz).collect();
            if !slow_s.is_empty() {
                let xr = slow_s
                    .iter()
                    .map(|v| v.re.abs())
                    .fold(0.0, f64::max)
                    .max(1.0);
                let yr = slow_s
                    .iter()
                    .map(|v| v.im.abs())
                    .fold(0.0, f64::max)
                    .max(xr);
                p.x.range = Some((-1.2 * xr, 1.2 * xr));
                p.y.range = Some((-1.2 * yr, 1.2 * yr));
            }
            panels.push(p);
            let mut sorted: Vec<(&c64, c64)> = poles
                .iter()
                .filter(|z| z.im >= 0.0)
                .filter_map(|z| to_hz(z).map(|s| (z, s)))
                .collect();
            sorted.sort_by(|a, b| a.1.norm().total_cmp(&b.1.norm()));
            for (z, s) in sorted {
                let fnat = s.norm();
                let zeta = if fnat > 0.0 { -s.re / fnat } else { 0.0 };
                ct_rows.push(vec![
                    if z.im.abs() < 1e-12 {
                        format!("{:.6}", z.re)
                    } else {
                        format!("{:.6} ± {:.6}j", z.re, z.im)
                    },
                    fmt(z.norm()),
                    fmt(fnat),
                    if z.im.abs() < 1e-12 {
                        "— (real)".into()
                    } else {
                        fmt(zeta)
                    },
                    if z.norm() > 1.0 {
                        format!(
                            "unstable (time constant {} ms)",
                            fmt(1e3 / (s.re * std::f64::consts::TAU))
                        )
                    } else if z.im.abs() < 1e-12 {
                        format!(
                            "stable (time constant {} ms)",
                            fmt(-1e3 / (s.re * std::f64::consts::TAU))
                        )
                    } else {
                        "stable".into()
                    },
                ]);
            }
        }
    }
    if let Some((nc, nu)) = chosen_pz {
        ctx.typed.pole_zero = Some(super::PoleZeroSummary {
            chosen_near_cancellations: nc as f64,
            chosen_unstable_poles: nu as f64,
        });
    }
    let mut blocks = vec![Block::Figure(figure(
        "pole_zero",
        &format!("Pole-zero maps of the {} candidates", structure.to_uppercase()),
        format!(
            "Poles (×) and zeros (○) in the z-plane with the unit circle, for every order of the chosen \
             structure; the last two panels show the chosen model zoomed onto the poles near z = 1 (at \
             a high sample rate every mode of the plant sits there) and in the s-plane in Hz \
             (s = f_s ln z). An AMB plant must keep its unstable real pole outside the unit circle{}.",
            if truth_unstable.is_empty() {
                String::new()
            } else {
                format!(
                    " (the twin's exact plant: {})",
                    truth_unstable
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
            fmt(opts.cancellation_tol)
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
        let label = chosen_poles.as_ref().map_or(String::new(), |c| c.0.clone());
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
        blocks.push(Ctx::note(NoteKind::Info, n));
    }
    let _ = log;
    ctx.section("pole-zero", "Pole-zero check", blocks);
    Ok(StepStatus::Done)
}
