//! Steps 8–10: validation on an independent record with residual tests, the chirp closed-loop
//! reconstruction and the ISO 14839-3 sensitivity zone. Each step builds its stage's input from
//! the run's state, calls the stage ([`crate::stage::validation`],
//! [`crate::stage::reconstruction`], [`crate::stage::iso`]), fills its part of `summary.json`
//! from the typed result and pushes the sections [`super::render_validation`] draws from it.

use super::data::Units;
use super::render_validation as render;
use super::{Ctx, Error, StepStatus};
use super::{
    IsoMeasured, IsoModel, IsoSummary, IsoTruth, ReconstructionSummary, ResidualsSummary,
    ValidationSummary,
};
use crate::stage::{
    IsoInput, IsoStage, ModelUnderTest, ReconstructionInput, ReconstructionSource,
    ReconstructionStage, ValidationCheck, ValidationInput, ValidationStage,
};
use crate::validation::LagChoice;
use ambid_core::validate::iso::IsoZones;
use ambid_core::validate::residuals::ResidualTest;

fn zones(ctx: &Ctx<'_>) -> IsoZones {
    IsoZones {
        a: ctx.cfg.iso.a,
        b: ctx.cfg.iso.b,
        c: ctx.cfg.iso.c,
    }
}

/// `summary.json`'s `residuals` of one residual test with its lags (and the truth's test).
fn residuals_summary(
    res: &ResidualTest,
    truth: Option<&ResidualTest>,
    lags: &LagChoice,
    ts: f64,
) -> ResidualsSummary {
    let mut r = ResidualsSummary {
        lags: Some(lags.lags),
        lags_ms: Some(lags.lags as f64 * ts * 1e3),
        lags_rule: Some(lags.basis),
        lags_peak_sample: lags.peak_sample,
        ..Default::default()
    };
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
    if let Some(c) = truth.and_then(|t| t.independence.as_ref()) {
        r.truth_independence_statistic = Some(c.statistic);
        r.truth_independence_threshold = Some(c.threshold);
        r.truth_independence_dof = Some(c.dof);
        r.truth_independence_pass = Some(c.pass);
    }
    r
}

/// `summary.json`'s `validation` and `residuals` of a validation stage (`None` when it did not
/// validate; no `residuals` when there was no residual test).
fn validation_summary(
    st: &ValidationStage,
) -> Option<(ValidationSummary, Option<ResidualsSummary>)> {
    match &st.check {
        ValidationCheck::NotDone(_) => None,
        ValidationCheck::ClosedLoop(c) => {
            let v = &c.outcome;
            let exact = c.exact_plant.as_ref();
            Some((
                ValidationSummary {
                    model: Some(st.model.clone()),
                    fit_y_pct: Some(v.fit_y),
                    fit_u_pct: Some(v.fit_u),
                    rmse_y: Some(v.rmse_y),
                    max_error_y: Some(v.max_error_y),
                    exact_plant_fit_y_pct: exact.map(|t| t.fit_y),
                    ..Default::default()
                },
                Some(residuals_summary(
                    &v.residuals,
                    exact.map(|t| &t.residuals),
                    &c.lags,
                    st.ts,
                )),
            ))
        }
        ValidationCheck::OpenLoop(o) => Some((
            ValidationSummary {
                model: Some(st.model.clone()),
                fit_y_pct: Some(o.fit_y),
                kind: Some(o.kind.to_string()),
                ..Default::default()
            },
            o.residuals
                .as_ref()
                .ok()
                .map(|r| residuals_summary(&r.test, None, &o.lags, st.ts)),
        )),
    }
}

pub fn validation(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    ctx.ensure_valid()?;
    let Some(c) = ctx.chosen() else {
        return Ok(StepStatus::Skipped(
            "no fitted model (run the models step)".into(),
        ));
    };
    let Some(model) = c.model.as_ref() else {
        return Ok(StepStatus::Skipped("the chosen model failed".into()));
    };
    let label = c.label();
    let Some(val) = ctx.valid.as_ref() else {
        return Ok(StepStatus::Skipped("no validation record".into()));
    };
    let st = crate::stage::validation(&ValidationInput {
        model: ModelUnderTest {
            name: &label,
            model,
            poly: c.poly.as_ref(),
            kalman: c.kalman.as_deref(),
        },
        record: val,
        controller: ctx.controller.as_ref(),
        twin: ctx.twin.as_ref(),
        settings: crate::stage::validation_settings(&ctx.cfg.validation, zones(ctx), val.len()),
        lags: ctx.cfg.validation.lags,
    })
    .map_err(super::computation)?;
    // the validation stage and the models step name the open-loop comparison alike
    if let ValidationCheck::NotDone(why) = &st.check {
        return Ok(StepStatus::Skipped(why.clone()));
    }
    if let Some((v, r)) = validation_summary(&st) {
        ctx.typed.validation = Some(v);
        ctx.typed.residuals = r;
    }
    if let Some(s) = render::validation_section(&st, &Units::of(ctx)) {
        ctx.sections.push(s);
    }
    ctx.validation_stage = Some(st);
    Ok(StepStatus::Done)
}

/// `summary.json`'s `reconstruction` of a reconstruction stage.
fn reconstruction_summary(st: &ReconstructionStage) -> ReconstructionSummary {
    let r = &st.outcome.reconstruction;
    let mut summary = ReconstructionSummary {
        fit_y_pct: Some(r.fit_y),
        fit_u_pct: Some(r.fit_u),
        max_error_y: Some(r.max_error_y),
        ..Default::default()
    };
    if let (Some(ww), Some(wf)) = (&st.worst, st.worst_fit()) {
        summary.worst_window_fit_y_pct = Some(wf.fit_y);
        summary.worst_window_start_s = Some(wf.t_s.0);
        summary.worst_window_end_s = Some(wf.t_s.1);
        summary.worst_window_record_fit_pct = Some(ww.record_fit_pct);
        summary.worst_window_rms_error_y = Some(wf.rms_error_y);
        summary.worst_window_signal_rms_y = Some(ww.signal_rms);
        summary.error_floor_y = Some(ww.error_floor);
        summary.windows_judged = Some(ww.judged);
        if let Some((f0, f1)) = st.window_frequency(wf) {
            summary.worst_window_f_lo_hz = Some(f0);
            summary.worst_window_f_hi_hz = Some(f1);
        }
    }
    summary
}

pub fn reconstruction(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    let Some(c) = ctx.chosen() else {
        return Ok(StepStatus::Skipped(
            "no fitted model (run the models step)".into(),
        ));
    };
    let Some(model) = c.model.as_ref() else {
        return Ok(StepStatus::Skipped("the chosen model failed".into()));
    };
    let Some(controller) = ctx.controller.as_ref() else {
        return Ok(StepStatus::Skipped(
            "the closed-loop reconstruction needs the controller (open-loop data, or no [data] controller)".into(),
        ));
    };
    let file;
    let source = if let Some(t) = &ctx.twin {
        ReconstructionSource::Twin {
            twin: t,
            seed: crate::stage::reconstruction_seed(&ctx.seeds),
        }
    } else if let Some(p) = &ctx.cfg.data.reconstruction {
        file = super::data::load_file(ctx.cfg, &ctx.base, p, "reconstruction")?;
        ReconstructionSource::Record(&file)
    } else {
        return Ok(StepStatus::Skipped(
            "no chirp-reference record ([data] reconstruction = \"chirp.csv\" with a w column)"
                .into(),
        ));
    };
    let label = c.label();
    let st = crate::stage::reconstruction(&ReconstructionInput {
        name: &label,
        model,
        controller,
        chirp: &ctx.cfg.reconstruction,
        settings: &ctx.cfg.validation,
        zones: zones(ctx),
        source,
    })?;
    ctx.typed.reconstruction = Some(reconstruction_summary(&st));
    let section = render::reconstruction_section(&st, &ctx.cfg.reconstruction, &Units::of(ctx));
    ctx.sections.push(section);
    ctx.reconstruction_stage = Some(st);
    Ok(StepStatus::Done)
}

/// `summary.json`'s `iso` of an ISO stage.
fn iso_summary(st: &IsoStage) -> IsoSummary {
    IsoSummary {
        measured: st.measured.as_ref().map(|m| {
            let v = &m.search.verdict;
            IsoMeasured {
                peak: Some(v.peak),
                f_peak_hz: Some(v.f_peak_hz),
                zone: Some(format!("{:?}", v.zone)),
                peak_ci_lo: v.interval.map(|i| i.0),
                peak_ci_hi: v.interval.map(|i| i.1),
                search_lo_hz: Some(m.search.band.0),
                search_hi_hz: Some(m.search.band.1),
                search_lines: Some(m.search.lines as f64),
            }
        }),
        model: st.model.as_ref().map(|m| IsoModel {
            peak: Some(m.verdict.peak),
            f_peak_hz: Some(m.verdict.f_peak_hz),
            zone: Some(format!("{:?}", m.verdict.zone)),
            phase_margin_deg: st.model_phase_margin_deg,
        }),
        truth: st.truth.as_ref().map(|t| IsoTruth {
            peak: Some(t.verdict.peak),
            zone: Some(format!("{:?}", t.verdict.zone)),
        }),
        zone: st.verdict().map(|v| format!("{v:?}")),
    }
}

pub fn iso(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    let st = crate::stage::iso(&IsoInput {
        zones: zones(ctx),
        frf: ctx.frf(),
        identification: ctx.ident.as_ref(),
        validation: ctx.validation(),
        twin: ctx.twin.as_ref(),
    })?;
    if let Some(why) = st.not_done() {
        return Ok(StepStatus::Skipped(why));
    }
    ctx.typed.iso = Some(iso_summary(&st));
    if let Some(s) = render::iso_section(&st) {
        ctx.sections.push(s);
    }
    ctx.iso_stage = Some(st);
    Ok(StepStatus::Done)
}
