//! Steps 8–10: validation on an independent record with residual tests, the chirp closed-loop
//! reconstruction and the ISO 14839-3 sensitivity zone.

use super::figures::{envelope, figure, lin, log, series, with_spans, xy};
use super::{computation, Ctx, Error, StepStatus};
use crate::report::{format_number as fmt, Block, Marker, NoteKind, Series, Span, Style, Table};
use crate::validation::{
    chirp_frequency, residual_lags, validate_closed_loop, worst_window, LagBasis, LagChoice,
    MeasuredLoop, ValidationOutcome, ValidationSettings, WORST_WINDOW_SIGNAL_FACTOR,
};
use ambid_core::c64;
use ambid_core::lti::Frd;
use ambid_core::validate::fit::fit_percent;
use ambid_core::validate::iso::{sensitivity_zone, IsoZones};
use ambid_core::validate::residuals::{
    analyze, analyze_output_error, CorrelationTest, ResidualTest,
};

fn settings(ctx: &Ctx<'_>, n: usize) -> ValidationSettings {
    let v = &ctx.cfg.validation;
    ValidationSettings {
        skip: v.skip.min(n / 4),
        lags: v.lags.unwrap_or(crate::validation::RESIDUAL_LAGS_FALLBACK),
        windows: v.windows.min(n / 4).max(1),
        zones: zones(ctx),
        initial_state: v.x0,
        ..ValidationSettings::default()
    }
}

fn zones(ctx: &Ctx<'_>) -> IsoZones {
    IsoZones {
        a: ctx.cfg.iso.a,
        b: ctx.cfg.iso.b,
        c: ctx.cfg.iso.c,
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

/// The residual tests' number of lags: `[validation] lags` when set, else the rule of
/// [`residual_lags`] on the chosen model (with the controller when there is one) over the `n`
/// tested samples.
fn lag_choice(
    ctx: &Ctx<'_>,
    model: &ambid_core::lti::StateSpace,
    controller: Option<&ambid_core::lti::StateSpace>,
    n: usize,
) -> LagChoice {
    match ctx.cfg.validation.lags {
        Some(l) => LagChoice {
            lags: l,
            peak_sample: None,
            basis: LagBasis::Given,
        },
        None => residual_lags(model, controller, n),
    }
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

fn put_residuals(ctx: &mut Ctx<'_>, res: &ResidualTest, lags: &LagChoice, ts: f64) {
    let r = ctx.typed.residuals.get_or_insert_with(Default::default);
    r.lags = Some(lags.lags);
    r.lags_ms = Some(lags.lags as f64 * ts * 1e3);
    r.lags_rule = Some(lags.basis);
    if let Some(k) = lags.peak_sample {
        r.lags_peak_sample = Some(k);
    }
    if let Some(w) = &res.whiteness {
        r.whiteness_statistic = Some(w.statistic);
        r.whiteness_threshold = Some(w.threshold);
        r.whiteness_pass = Some(w.pass);
    }
    if let Some(c) = &res.independence {
        r.independence_statistic = Some(c.statistic);
        r.independence_threshold = Some(c.threshold);
        r.independence_dof = Some(c.dof);
        r.independence_pass = Some(c.pass);
    }
}

fn put_truth_residuals(ctx: &mut Ctx<'_>, res: &ResidualTest) {
    if let Some(c) = &res.independence {
        let r = ctx.typed.residuals.get_or_insert_with(Default::default);
        r.truth_independence_statistic = Some(c.statistic);
        r.truth_independence_threshold = Some(c.threshold);
        r.truth_independence_dof = Some(c.dof);
        r.truth_independence_pass = Some(c.pass);
    }
}

pub fn validation(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    ctx.ensure_valid()?;
    let Some(ch) = ctx.chosen else {
        return Ok(StepStatus::Skipped(
            "no fitted model (run the models step)".into(),
        ));
    };
    let Some(model) = ctx.candidates[ch].model.clone() else {
        return Ok(StepStatus::Skipped("the chosen model failed".into()));
    };
    let label = ctx.candidates[ch].label();
    let Some(val) = ctx.valid.clone() else {
        return Ok(StepStatus::Skipped("no validation record".into()));
    };
    let mut blocks = Vec::new();
    let controller = ctx.controller.clone();
    match (&controller, val.closed_loop) {
        (Some(_), true)
            if !val
                .r()
                .as_ref()
                .is_some_and(|r| r.iter().any(|v| *v != 0.0))
                && !val
                    .w()
                    .as_ref()
                    .is_some_and(|w| w.iter().any(|v| *v != 0.0)) =>
        {
            // a record without excitation is a failure of this step, not of the whole report
            return Ok(StepStatus::Skipped(format!(
                "the validation record {} has neither an excitation r nor a position reference w \
                 (or they are zero): nothing drives the loop. Name the columns in [data] r / w.",
                val.source
            )));
        }
        (Some(c), true) => {
            let zeros = vec![0.0; val.len()];
            let w = val.w().unwrap_or(&zeros);
            let mut s = settings(ctx, val.len());
            let lags = lag_choice(ctx, &model, Some(c.state_space()), val.len() - s.skip);
            s.lags = lags.lags;
            let rec = MeasuredLoop {
                w,
                r: val.r(),
                y: val.y(),
                u: val.u(),
                ts: val.ts(),
            };
            // the chosen model and (twin) the exact plant through the same validation, side by side
            let (v, exact) = rayon::join(
                || validate_closed_loop(&model, c.state_space(), &rec, &s),
                || {
                    ctx.twin
                        .as_ref()
                        .map(|t| validate_closed_loop(t.twin.plant(), c.state_space(), &rec, &s))
                },
            );
            let v = v.map_err(computation)?;
            let vs = ctx.typed.validation.get_or_insert_with(Default::default);
            vs.model = Some(label.clone());
            vs.fit_y_pct = Some(v.fit_y);
            vs.fit_u_pct = Some(v.fit_u);
            vs.rmse_y = Some(v.rmse_y);
            vs.max_error_y = Some(v.max_error_y);
            let mut rows = vec![vec![
                label.clone(),
                fmt(v.fit_y),
                fmt(v.fit_u),
                fmt(v.rmse_y),
                fmt(v.max_error_y),
            ]];
            // the twin's exact plant through the same validation (same record, same lags): the
            // best any model can do, and the residual tests' reference
            let mut truth_res = None;
            if ctx.twin.is_some() {
                if let Some(Ok(vt)) = exact {
                    ctx.typed
                        .validation
                        .get_or_insert_with(Default::default)
                        .exact_plant_fit_y_pct = Some(vt.fit_y);
                    truth_res = Some(vt.residuals.clone());
                    rows.push(vec![
                        "twin's exact linear plant".into(),
                        fmt(vt.fit_y),
                        fmt(vt.fit_u),
                        fmt(vt.rmse_y),
                        fmt(vt.max_error_y),
                    ]);
                }
            }
            blocks.push(Block::Text(format!(
                "The chosen model {label} closed with the controller ({}) and driven by the independent \
                 record's excitation ({} samples, first {} excluded); the simulated displacement and \
                 controller output are compared with the measured ones.",
                c.description(),
                val.len(),
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
                val.ts(),
                &[
                    ("y", val.y(), &v.reconstruction.simulated.y, &super::data::y_unit(ctx)),
                    ("u", val.u(), &v.reconstruction.simulated.u, &super::data::u_unit(ctx)),
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
            put_residuals(ctx, &v.residuals, &lags, val.ts());
            if let Some(t) = &truth_res {
                put_truth_residuals(ctx, t);
            }
            blocks.extend(residual_blocks(
                &v.residuals,
                truth_res.as_ref(),
                &label,
                if v.residual_input == "r" {
                    "excitation r"
                } else {
                    "reference w"
                },
                "closed-loop output error y − ŷ",
                "the output error of the model simulated in closed loop is the sensor noise through the loop, S·v, coloured even for the true plant (and correlated with u, so u is not the test signal)",
                val.ts(),
                &lags,
                ctx.twin
                    .as_ref()
                    .is_some_and(|t| t.mode == ambid_twin::Mode::Nonlinear),
            ));
            ctx.validation = Some(v);
        }
        (_, closed) => {
            if closed {
                blocks.push(Ctx::note(
                    NoteKind::Warning,
                    "Closed-loop data without a controller file: the model cannot be validated through \
                     the closed loop, so it is validated like open-loop data (one-step prediction when \
                     it is unstable). Give [data] controller = \"controller.toml\" for the closed-loop \
                     validation.",
                ));
            }
            // open loop: simulate (stable) or predict one step (unstable) on the validation record
            let c = &ctx.candidates[ch];
            let Some((yhat, kind)) =
                super::steps_models::open_loop_response(c, &model, val.y(), val.u())
            else {
                return Ok(StepStatus::Skipped(format!(
                    "{label} is unstable and has no predictor: it cannot be validated in open loop"
                )));
            };
            let fit = fit_percent(val.y(), &yhat).map_err(computation)?;
            let vs = ctx.typed.validation.get_or_insert_with(Default::default);
            vs.model = Some(label.clone());
            vs.fit_y_pct = Some(fit);
            vs.kind = Some(kind.to_string());
            let eps: Vec<f64> = val.y().iter().zip(&yhat).map(|(a, b)| a - b).collect();
            // the quantity that should be white / independent (docs/validation.md): a one-step
            // prediction error of a model with a noise model is white and independent of the
            // input; a simulation error (no noise model) is only independent of it. In closed loop
            // the test signal is the excitation r (or reference w), never u (it contains −C v).
            let test_signal: Option<(&[f64], &str)> = if closed {
                match (val.r(), val.w()) {
                    (Some(r), _) if r.iter().any(|v| *v != 0.0) => Some((r, "excitation r")),
                    (_, Some(w)) if w.iter().any(|v| *v != 0.0) => Some((w, "reference w")),
                    _ => None,
                }
            } else {
                Some((val.u(), "input u"))
            };
            let lag_rule = lag_choice(ctx, &model, None, val.len());
            let lags = lag_rule.lags;
            let one_step = kind == super::steps_models::ONE_STEP;
            let res = match (one_step, test_signal) {
                (true, t) => Some((analyze(&eps, t.map(|t| t.0), lags), t.map_or("—", |t| t.1))),
                (false, Some((x, name))) => Some((analyze_output_error(&eps, x, lags), name)),
                (false, None) => None,
            };
            blocks.push(Block::Text(format!(
                "The chosen model {label} on the validation record ({} samples): {kind} fit {} %.",
                val.len(),
                fmt(fit)
            )));
            let empty: Vec<f64> = Vec::new();
            let _ = &empty;
            blocks.push(time_figure(
                "validation_time",
                "Time-domain validation",
                format!(
                    "Measured output and the model's {kind} on the validation record; fit {} %.",
                    fmt(fit)
                ),
                val.ts(),
                &[("y", val.y(), &yhat, &super::data::y_unit(ctx))],
            ));
            match res {
                Some((res, signal)) => {
                    let res = res.map_err(computation)?;
                    put_residuals(ctx, &res, &lag_rule, val.ts());
                    blocks.extend(residual_blocks(
                        &res,
                        None,
                        &label,
                        signal,
                        if one_step { "1-step prediction error" } else { "simulation error" },
                        "the simulation error of a model is the noise as it reaches the output, coloured unless the noise is white, whatever the model",
                        val.ts(),
                        &lag_rule,
                        false,
                    ));
                }
                None => blocks.push(Ctx::note(
                    NoteKind::Warning,
                    "No residual test: the simulation error of closed-loop data can only be tested against \
                     an excitation r or a reference w (not u, which contains the fed-back noise), and the \
                     record has neither.",
                )),
            }
        }
    }
    ctx.section("validation", "Validation on an independent record", blocks);
    Ok(StepStatus::Done)
}

pub fn reconstruction(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    let Some(ch) = ctx.chosen else {
        return Ok(StepStatus::Skipped(
            "no fitted model (run the models step)".into(),
        ));
    };
    let Some(model) = ctx.candidates[ch].model.clone() else {
        return Ok(StepStatus::Skipped("the chosen model failed".into()));
    };
    let Some(c) = ctx.controller.clone() else {
        return Ok(StepStatus::Skipped(
            "the closed-loop reconstruction needs the controller (open-loop data, or no [data] controller)".into(),
        ));
    };
    let rc = &ctx.cfg.reconstruction;
    let (w, y, u, ts, source) = if let Some(t) = &ctx.twin {
        let w = ambid_core::signal::ChirpSpec {
            amplitude: rc.amplitude_um * 1e-6,
            duration_s: rc.duration_s,
            f0_hz: rc.f0_hz,
            f1_hz: rc.f1_hz,
            sweep: ambid_core::signal::Sweep::Linear,
            periods: 1,
        }
        .generate(t.twin.ts())
        .map_err(super::input)?
        .values;
        let opts = ambid_twin::SimOptions {
            mode: t.mode,
            seed: ctx.cfg.seed + 500,
            noise: t.noise,
            w: Some(w.clone()),
            ..ambid_twin::SimOptions::default()
        };
        let rec = t
            .twin
            .simulate(&vec![0.0; w.len()], &opts)
            .map_err(computation)?;
        (w, rec.y, rec.u, rec.ts, "the twin".to_string())
    } else if let Some(p) = ctx.cfg.data.reconstruction.clone() {
        let r = super::data::load_file(ctx.cfg, &ctx.base, &p, "reconstruction")?;
        let Some(w) = r.w().map(<[f64]>::to_vec) else {
            return Err(Error::input(format!(
                "{}: the reconstruction record needs the position reference column ([data] w = \"…\")",
                r.source
            )));
        };
        (w, r.y().to_vec(), r.u().to_vec(), r.ts(), r.source)
    } else {
        return Ok(StepStatus::Skipped(
            "no chirp-reference record ([data] reconstruction = \"chirp.csv\" with a w column)"
                .into(),
        ));
    };
    let s = settings(ctx, y.len());
    let s = ValidationSettings { skip: 0, ..s };
    let v: ValidationOutcome = validate_closed_loop(
        &model,
        c.state_space(),
        &MeasuredLoop {
            w: &w,
            r: None,
            y: &y,
            u: &u,
            ts,
        },
        &s,
    )
    .map_err(computation)?;
    let label = ctx.candidates[ch].label();
    let mut summary = super::ReconstructionSummary {
        fit_y_pct: Some(v.reconstruction.fit_y),
        fit_u_pct: Some(v.reconstruction.fit_u),
        max_error_y: Some(v.reconstruction.max_error_y),
        ..Default::default()
    };
    let wins = &v.reconstruction.windows;
    let worst = worst_window(wins, &y, ts);
    // the chirp's instantaneous frequency, from the reference's zero crossings
    let freq = chirp_frequency(&w, ts);
    let n = y.len();
    let idx = |t: f64| ((t / ts).round().max(0.0) as usize).min(n.saturating_sub(1));
    let win_f = |wf: &ambid_core::validate::closed_loop::WindowFit| {
        freq.as_ref().map(|f| (f[idx(wf.t_s.0)], f[idx(wf.t_s.1)]))
    };
    if let Some(ww) = &worst {
        let wf = &wins[ww.index];
        summary.worst_window_fit_y_pct = Some(wf.fit_y);
        summary.worst_window_start_s = Some(wf.t_s.0);
        summary.worst_window_end_s = Some(wf.t_s.1);
        summary.worst_window_record_fit_pct = Some(ww.record_fit_pct);
        summary.worst_window_rms_error_y = Some(wf.rms_error_y);
        summary.worst_window_signal_rms_y = Some(ww.signal_rms);
        summary.error_floor_y = Some(ww.error_floor);
        summary.windows_judged = Some(ww.judged);
        if let Some((f0, f1)) = win_f(wf) {
            summary.worst_window_f_lo_hz = Some(f0);
            summary.worst_window_f_hi_hz = Some(f1);
        }
    }
    ctx.typed.reconstruction = Some(summary);
    // measured vs reconstructed over the whole sweep (min/max envelopes) against the chirp's
    // instantaneous frequency (time when the reference is not a rising sweep)
    let t: Vec<f64> = (0..n).map(|k| k as f64 * ts).collect();
    type XOf<'a> = Box<dyn Fn(f64) -> f64 + 'a>;
    let (x, x_axis, x_of): (&[f64], &str, XOf<'_>) = match &freq {
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
        ("displacement y", &y, &sim.y, super::data::y_unit(ctx)),
        ("controller output u", &u, &sim.u, super::data::u_unit(ctx)),
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
    let yu = super::data::y_unit(ctx);
    let mid: Vec<f64> = wins
        .iter()
        .map(|wf| x_of(0.5 * (wf.t_s.0 + wf.t_s.1)))
        .collect();
    let sig_rms: Vec<f64> = wins
        .iter()
        .map(|wf| {
            let (i0, i1) = (idx(wf.t_s.0), idx(wf.t_s.1).max(idx(wf.t_s.0) + 1).min(n));
            let seg = &y[i0..i1];
            let m = seg.iter().sum::<f64>() / seg.len() as f64;
            (seg.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / seg.len() as f64).sqrt()
        })
        .collect();
    let err: Vec<f64> = wins.iter().map(|wf| wf.rms_error_y).collect();
    let mut ws = vec![
        series(
            "measured signal RMS",
            &mid,
            &sig_rms,
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
    if let Some(ww) = &worst {
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
    if err.iter().chain(&sig_rms).all(|v| *v > 0.0) {
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
    ctx.section("reconstruction", "Closed-loop reconstruction", blocks);
    Ok(StepStatus::Done)
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

pub fn iso(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    let z = zones(ctx);
    let mut curves = Vec::new();
    let mut rows = Vec::new();
    let mut verdicts = Vec::new();
    let mut iso_notes: Vec<String> = Vec::new();
    // drawn in this order: zone shading, the measured 95 % band, model and truth, measured |S|
    let mut bands = Vec::new();
    let mut measured = None;
    let mut search_span = None;
    let db1 = |m: f64| 20.0 * m.max(1e-300).log10();
    // measured S = T_ru from the FRF (closed loop with an excitation)
    if let (Some(a), true) = (
        &ctx.frf,
        ctx.ident
            .as_ref()
            .is_some_and(|r| r.r().is_some() && r.closed_loop),
    ) {
        let s = &a.frf.t_ru;
        // the peak over the lines of the FRF band where S is known to ±10 % (docs/validation.md)
        let search = ambid_core::frf::band::iso_search(
            s,
            a.bands.band,
            &ambid_core::frf::band::BandRule::default(),
            &z,
        )
        .map_err(computation)?;
        let v = search.verdict.clone();
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
        let ms = ctx
            .typed
            .iso
            .get_or_insert_with(Default::default)
            .measured
            .get_or_insert_with(Default::default);
        ms.peak = Some(v.peak);
        ms.f_peak_hz = Some(v.f_peak_hz);
        ms.zone = Some(format!("{:?}", v.zone));
        if let Some((lo, hi)) = v.interval {
            let ms = ctx
                .typed
                .iso
                .get_or_insert_with(Default::default)
                .measured
                .get_or_insert_with(Default::default);
            ms.peak_ci_lo = Some(lo);
            ms.peak_ci_hi = Some(hi);
        }
        let ms = ctx
            .typed
            .iso
            .get_or_insert_with(Default::default)
            .measured
            .get_or_insert_with(Default::default);
        ms.search_lo_hz = Some(search.band.0);
        ms.search_hi_hz = Some(search.band.1);
        ms.search_lines = Some(search.lines as f64);
        iso_notes.push(format!("Measured: {}.", search.describe()));
        rows.push(iso_row("measured S (FRF)", &v));
        verdicts.push(v.zone);
    }
    let model_s = ctx.validation.as_ref().map(|v| {
        (
            series(
                "model S = 1/(1+PC)",
                &v.grid_hz,
                &v.s_model.iter().map(|x| db1(x.norm())).collect::<Vec<_>>(),
                Style::Dashed,
                Some(6),
            ),
            v.iso_model.clone(),
            v.margins.phase_margin(),
        )
    });
    if let Some((curve, m, pm)) = model_s {
        curves.push(curve);
        let m = &m;
        let ms = ctx
            .typed
            .iso
            .get_or_insert_with(Default::default)
            .model
            .get_or_insert_with(Default::default);
        ms.peak = Some(m.peak);
        ms.f_peak_hz = Some(m.f_peak_hz);
        ms.zone = Some(format!("{:?}", m.zone));
        if let Some(p) = pm {
            ctx.typed
                .iso
                .get_or_insert_with(Default::default)
                .model
                .get_or_insert_with(Default::default)
                .phase_margin_deg = Some(p);
        }
        rows.push(iso_row("chosen model with the controller", m));
        verdicts.push(m.zone);
    }
    if let Some(t) = &ctx.twin {
        let f: Vec<f64> = (0..2000)
            .map(|k| 1.0 * (0.49 * t.twin.fs()).powf(k as f64 / 1999.0))
            .collect();
        let s: Vec<c64> = t.twin.sensitivity_frf(&f).map_err(computation)?;
        let frd = Frd::new(f.clone(), s.clone(), None, Some(t.twin.ts())).map_err(computation)?;
        let v = sensitivity_zone(&frd, &z).map_err(computation)?;
        curves.push(series(
            "twin's exact S",
            &f,
            &s.iter().map(|x| db1(x.norm())).collect::<Vec<_>>(),
            Style::Dashed,
            Some(7),
        ));
        let ts = ctx
            .typed
            .iso
            .get_or_insert_with(Default::default)
            .truth
            .get_or_insert_with(Default::default);
        ts.peak = Some(v.peak);
        ts.zone = Some(format!("{:?}", v.zone));
        rows.push(iso_row("twin's exact plant", &v));
    }
    if curves.is_empty() && measured.is_none() {
        return Ok(StepStatus::Skipped(
            "the ISO 14839-3 zone needs the measured sensitivity (closed-loop data with an excitation) or a model validated with the controller".into(),
        ));
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
    let verdict = verdicts.first().copied();
    if let Some(v) = verdict {
        ctx.typed.iso.get_or_insert_with(Default::default).zone = Some(format!("{v:?}"));
    }
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
        Ctx::note(
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
        blocks.push(Ctx::note(NoteKind::Info, n));
    }
    ctx.section("iso", "ISO 14839-3 stability verdict", blocks);
    Ok(StepStatus::Done)
}
