//! Steps 4–5: the nonparametric FRF of the identification record and the order estimation.
//! The stages ([`crate::stage::frf`], [`crate::stage::order`]) compute; [`super::render_frf`]
//! draws; these steps connect them to the run's state and fill `summary.json`.

use super::config::Step;
use super::data::Units;
use super::{render_frf, Ctx, Error, StepStatus};
use crate::stage::{FrfInput, FrfStage, OrderInput, OrderStage};

pub fn frf(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    ctx.ensure_ident()?;
    let Some(rec) = ctx.ident.clone() else {
        return Ok(StepStatus::Skipped("no identification record".into()));
    };
    let noise = ctx.noise_record()?;
    let st = crate::stage::frf(&FrfInput {
        record: &rec,
        frf: &ctx.cfg.frf,
        skip_periods: ctx.cfg.data.skip_periods,
        noise: noise.as_deref(),
        controller: ctx.controller.as_ref(),
        twin: ctx.twin.as_ref(),
    })?;
    ctx.typed.frf = Some(frf_summary(&st));
    let units = Units::of(ctx);
    ctx.sections.push(render_frf::frf_section(&st, &units));
    ctx.frf_stage = Some(st);
    Ok(StepStatus::Done)
}

/// `summary.json`'s `frf` from the stage.
fn frf_summary(st: &FrfStage) -> super::FrfSummary {
    let a = &st.analysis;
    let (bands, q) = (&a.bands, &a.quality);
    let truth = st.errors_vs_truth;
    super::FrfSummary {
        band_lo_hz: bands.band.0,
        band_hi_hz: bands.band.1,
        quality_band_lo_hz: bands.quality_band.0,
        quality_band_hi_hz: bands.quality_band.1,
        band_origin: bands.band_origin,
        quality_band_origin: bands.quality_origin,
        lines: st.f_hz().len() as f64,
        mean_coh_ry: q.mean_coherence_ry,
        mean_coh_ru: st.has_r.then_some(q.mean_coherence_ru),
        mean_plant_variance: q.mean_plant_variance,
        mean_plant_rel_variance: q.mean_plant_rel_variance,
        output_snr_db: q.output_snr_db,
        plant_median_error_vs_truth_pct: truth.map(|e| e.median_pct),
        plant_p90_error_vs_truth_pct: truth.map(|e| e.p90_pct),
        plant_median_error_vs_truth_10_1000_pct: truth.map(|e| e.median_10_1000_pct),
    }
}

pub fn order(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    ctx.ensure_ident()?;
    ctx.ensure_valid()?;
    let (Some(rec), Some(val)) = (ctx.ident.as_ref(), ctx.valid.as_ref()) else {
        return Ok(StepStatus::Skipped("no identification record".into()));
    };
    let st = crate::stage::order(&OrderInput {
        identification: rec,
        validation: val,
        frf: ctx.frf(),
        order: &ctx.cfg.order,
        models: &ctx.cfg.models,
        models_run: ctx.cfg.steps().contains(&Step::Models),
        controller: ctx.controller.as_ref(),
    })?;
    ctx.typed.order = Some(order_summary(&st));
    ctx.sections.push(render_frf::order_section(&st));
    ctx.order_stage = Some(st);
    Ok(StepStatus::Done)
}

/// `summary.json`'s `order` from the stage.
fn order_summary(st: &OrderStage) -> super::OrderSummary {
    let scan = &st.arx.scan;
    let best = &scan.rows[scan.best_bic];
    let rec = st.recommendation.as_ref().ok();
    super::OrderSummary {
        arx_best_bic: Some(super::ArxOrders {
            na: best.na as f64,
            nb: best.nb as f64,
            nk: best.nk as f64,
        }),
        arx_best_validation: scan.best_val.map(|v| {
            let r = &scan.rows[v];
            super::ArxValidation {
                na: r.na as f64,
                nb: r.nb as f64,
                fit_pct: r.val_fit,
            }
        }),
        resonances: st.resonances.as_ref().map(|r| r.peaks.len() as f64),
        order_from_peaks: st.resonances.as_ref().map(|r| r.order as f64),
        recommended: rec.map(|r| r.n as f64),
        recommended_lo: rec.map(|r| r.lo as f64),
        recommended_hi: rec.map(|r| r.hi as f64),
        recommended_source: rec.map(|r| r.source.to_string()),
    }
}
