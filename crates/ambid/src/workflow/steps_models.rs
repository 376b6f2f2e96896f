//! Steps 6–7: parametric models (fitted to the FRF in closed loop, or to the time record) with
//! their comparison table and Bode overlays, and the pole-zero check. The glue between the
//! workflow's state and the stages [`crate::stage::models`] and [`crate::stage::pole_zero`]
//! (compute) and [`super::render_models`] (report).

use super::{render_models, Ctx, Error, StepStatus};
use crate::stage::{ModelsInput, ModelsStage, PoleZeroInput, PoleZeroStage};

/// `summary.json`'s `models` from the stage result.
fn summary(stage: &ModelsStage) -> super::ModelsSummary {
    let table = stage
        .candidates
        .iter()
        .map(|c| super::ModelRow {
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
        })
        .collect();
    let chosen = stage.chosen();
    super::ModelsSummary {
        domain: stage.domain.clone(),
        unstable_poles_supported: stage
            .unstable
            .as_ref()
            .map(|u| u.supported.map(|n| n as f64)),
        table,
        chosen: chosen.map(|c| c.label()),
        chosen_validation_fit_pct: chosen.and_then(|c| c.validation_fit),
        chosen_error_vs_truth_pct: chosen.and_then(|c| c.truth_median_relative.map(|e| 100.0 * e)),
    }
}

/// `summary.json`'s `pole_zero` from the stage result (absent when the chosen model has none).
fn pole_zero_summary(stage: &PoleZeroStage) -> Option<super::PoleZeroSummary> {
    stage.chosen.as_ref().map(|c| super::PoleZeroSummary {
        chosen_near_cancellations: c.near_cancellations as f64,
        chosen_unstable_poles: c.unstable_poles as f64,
    })
}

pub fn models(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    ctx.ensure_ident()?;
    ctx.ensure_valid()?;
    let recommended_orders = ctx
        .typed
        .order
        .as_ref()
        .and_then(|o| Some((o.recommended_lo? as usize, o.recommended_hi? as usize)));
    let stage = crate::stage::models(&ModelsInput {
        settings: &ctx.cfg.models,
        recommended_orders,
        identification: ctx.ident.as_ref(),
        validation: ctx.valid.as_ref(),
        validation_skip: ctx.cfg.validation.skip,
        frf: ctx.frf(),
        controller: ctx.controller.as_ref(),
        twin: ctx.twin.as_ref(),
    })?;
    if let Some(why) = &stage.skipped {
        return Ok(StepStatus::Skipped(why.clone()));
    }
    ctx.typed.models = Some(summary(&stage));
    ctx.sections.push(render_models::models_section(
        &stage,
        &ctx.cfg.models.weights,
    ));
    ctx.models.extend(stage.export.iter().cloned());
    ctx.models_stage = Some(stage);
    Ok(StepStatus::Done)
}

pub fn pole_zero(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    let Some((models, chosen)) = ctx
        .models_stage
        .as_ref()
        .and_then(|m| Some((m, m.choice.index?)))
    else {
        return Ok(StepStatus::Skipped(
            "no fitted model (run the models step)".into(),
        ));
    };
    let stage = crate::stage::pole_zero(&PoleZeroInput {
        candidates: &models.candidates,
        chosen,
        twin: ctx.twin.as_ref(),
    })?;
    if let Some(s) = pole_zero_summary(&stage) {
        ctx.typed.pole_zero = Some(s);
    }
    ctx.sections.push(render_models::pole_zero_section(&stage));
    ctx.pole_zero_stage = Some(stage);
    Ok(StepStatus::Done)
}
