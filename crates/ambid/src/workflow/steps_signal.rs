//! Steps 1–3: excitation design and comparison, amplitude study, operating-point study.

use super::config::SourceKind;
use super::data::Recording;
use super::{computation, input, Ctx, Error, StepStatus};
use crate::report::format_number as fmt;
use crate::study::{
    amplitude_from_records, LevelRecord, OperatingCase, Recommendation, TwinAmplitudeStudy,
};

pub fn excitation(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    let (fs, level, unit, isat) =
        match (&ctx.twin, &ctx.ident) {
            (Some(t), _) => {
                let isat = t.twin.i_sat();
                (
                    t.twin.fs(),
                    ctx.cfg.excitation.compare_level_pct / 100.0 * isat,
                    "A",
                    Some(isat),
                )
            }
            (None, Some(r)) if r.closed_loop && r.r().is_none() => return Ok(StepStatus::Skipped(
                "the record has no excitation r (the loop ran on its own noise), so there is no \
                 excitation to describe; the comparison of candidate excitations runs on the twin \
                 and on records with an excitation"
                    .into(),
            )),
            (None, Some(r)) => (r.fs(), 1.0, "normalised", None),
            (None, None) => return Ok(StepStatus::Skipped("no data source".into())),
        };
    let identification = isat.map(|_| {
        let frac = ctx.cfg.excitation.amplitude_pct.unwrap_or(10.0) / 100.0;
        (ctx.plan(frac), ctx.cfg.excitation.kind.clone())
    });
    let stage = crate::stage::excitation_design(&crate::stage::ExcitationInput {
        fs,
        level,
        unit: unit.into(),
        i_sat: isat,
        compare_level_pct: ctx.cfg.excitation.compare_level_pct,
        seed: ctx.cfg.seed,
        identification,
        for_files: ctx.twin.is_none(),
    })?;
    ctx.typed.excitation = Some(excitation_summary(&stage));
    ctx.section(
        "excitation",
        "Excitation design and comparison",
        super::render_signal::excitation(&stage),
    );
    ctx.excitation = Some(stage);
    Ok(StepStatus::Done)
}

/// The excitation stage's part of `summary.json`.
fn excitation_summary(stage: &crate::stage::ExcitationStage) -> super::ExcitationSummary {
    let mut summary = super::ExcitationSummary::default();
    for s in &stage.comparison.signals {
        summary.compare.insert(
            s.name.to_string(),
            super::CompareFigures {
                crest_factor: s.report.crest_factor,
                f_max_hz: s.report.f_max_hz,
            },
        );
    }
    summary.identification = stage.identification.as_ref().map(|d| {
        let r = &d.report;
        super::ExcitationFigures {
            f_min_hz: r.f_min_hz,
            f_max_hz: r.f_max_hz,
            resolution_hz: r.resolution_hz,
            duration_s: r.duration_s,
            period_samples: r.period_samples as f64,
            crest_factor: r.crest_factor,
        }
    });
    summary
}

/// The amplitude stage's input on the twin (`None` on files).
pub fn amplitude_input(ctx: &Ctx<'_>) -> Option<TwinAmplitudeStudy> {
    let cfg = ctx.cfg;
    let t = ctx.twin.as_ref()?;
    Some(TwinAmplitudeStudy {
        twin: t.cfg.clone(),
        excitation: ctx.plan(0.1),
        levels: cfg
            .amplitude_study
            .levels_pct
            .iter()
            .map(|l| l / 100.0)
            .collect(),
        mode: t.mode,
        seed: ctx.seeds.amplitude,
        skip_periods: 1,
        noise: t.noise,
        band: cfg
            .frf
            .band_hz
            .map(|[a, b]| (a, b))
            .or(TwinAmplitudeStudy::default().band),
    })
}

pub fn amplitude(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    let cfg = ctx.cfg;
    let stage = match (&ctx.twin, cfg.source) {
        (Some(_), _) => {
            let (out, secs) = match ctx.pre.amplitude.take() {
                Some(pre) => pre,
                None => match amplitude_input(ctx) {
                    Some(study) => super::timed(|| {
                        crate::stage::amplitude_twin(&study, cfg.excitation.amplitude_pct)
                    }),
                    None => return Ok(StepStatus::Skipped("no data source".into())),
                },
            };
            ctx.pre_seconds += secs;
            out?
        }
        (None, SourceKind::Files) => {
            if cfg.amplitude_study.files.len() < 2 {
                return Ok(StepStatus::Skipped(
                    "an amplitude study on recorded data needs one record per level: list them in \
                     [amplitude_study] files = [{ level_pct = 2.0, path = \"…\" }, …]"
                        .into(),
                ));
            }
            let mut records = Vec::new();
            let mut fs = f64::NAN;
            let mut period = None;
            for lf in &cfg.amplitude_study.files {
                let rec: Recording =
                    super::data::load_file(cfg, &ctx.base, &lf.path, "amplitude level")?;
                let sig = rec.signals();
                let r = sig.r.ok_or_else(|| {
                    Error::input(format!(
                        "{}: the amplitude study needs the excitation column r",
                        rec.source
                    ))
                })?;
                fs = rec.fs();
                period = rec.period();
                records.push(LevelRecord {
                    level: lf.level_pct / 100.0,
                    r,
                    u: sig.u,
                    y: sig.y,
                    i: sig.i,
                    saturated_fraction: None,
                });
            }
            let noise = match &cfg.data.noise {
                Some(p) => Some(
                    super::data::load_file(cfg, &ctx.base, p, "noise")?
                        .y()
                        .to_vec(),
                ),
                None => None,
            };
            let settings = ctx.frf_settings(period, records[0].r.len());
            crate::stage::AmplitudeStage::new(
                amplitude_from_records(
                    &records,
                    fs,
                    noise.as_deref(),
                    &settings,
                    None,
                    Recommendation::default(),
                )
                .map_err(computation)?,
                format!("{} recorded files", records.len()),
                cfg.excitation.amplitude_pct,
            )
        }
        _ => return Ok(StepStatus::Skipped("no data source".into())),
    };
    ctx.level_frac = Some(stage.chosen_pct / 100.0);
    ctx.seed_study = Some(
        stage
            .outcome
            .rows
            .iter()
            .map(|r| (r.level_pct, r.mean_plant_rel_var))
            .collect(),
    );
    let blocks = super::render_signal::amplitude(&stage, cfg.excitation.amplitude_pct.is_some());
    ctx.section("amplitude", "Excitation-amplitude study", blocks);
    ctx.typed.amplitude = Some(stage);
    Ok(StepStatus::Done)
}

/// The operating-point stage's input on the twin at the identification level (`None` on files).
pub fn operating_point_input(ctx: &Ctx<'_>) -> Option<crate::stage::OperatingPointInput> {
    let cfg = ctx.cfg;
    let t = ctx.twin.as_ref()?;
    let (i0, g0) = (
        t.cfg.operating_point.bias_current_a,
        t.cfg.operating_point.air_gap_m,
    );
    let (b, g) = (cfg.operating_point.bias_pct, cfg.operating_point.air_gap_um);
    let case = |name: String, i: f64, gap: f64| OperatingCase {
        name,
        bias_current_a: i,
        air_gap_m: gap,
    };
    let cases = vec![
        case("nominal".into(), i0, g0),
        case(format!("bias-{b}%"), i0 * (1.0 - b / 100.0), g0),
        case(format!("bias+{b}%"), i0 * (1.0 + b / 100.0), g0),
        case(format!("gap-{g}um"), i0, g0 - g * 1e-6),
        case(format!("gap+{g}um"), i0, g0 + g * 1e-6),
    ];
    let frac = ctx.level_frac.unwrap_or(0.1);
    // the FRF band of every case: [frf] band_hz if given, else the seed's 10–2000 Hz (the
    // excitation's own band reaches ≈ 3 kHz, where the twin's plant is below the sensor noise)
    let band = Some(
        cfg.frf
            .band_hz
            .map_or((10.0, 2000.0f64.min(0.45 * t.twin.fs())), |[a, b]| (a, b)),
    );
    Some(crate::stage::OperatingPointInput {
        twin: t.cfg.clone(),
        cases,
        excitation: ctx.plan(frac),
        mode: t.mode,
        seed: ctx.seeds.operating_point,
        skip_periods: 1,
        band,
    })
}

/// The operating-point step; on the twin `pre` is the stage's output when it ran ahead.
pub fn operating_point(
    ctx: &mut Ctx<'_>,
    pre: Option<(
        crate::study::OperatingPointOutcome,
        crate::stage::OperatingPointInput,
    )>,
) -> Result<StepStatus, Error> {
    let cfg = ctx.cfg;
    if ctx.twin.is_none() {
        let files = &cfg.operating_point.files;
        if files.len() < 2 {
            return Ok(StepStatus::Skipped(
                "an operating-point study on recorded data needs one record per operating point, \
                 the nominal one first: [operating_point] files = [{ name = \"nominal\", path = \"…\" }, …]"
                    .into(),
            ));
        }
        let mut recs = Vec::new();
        for f in files {
            recs.push(super::data::load_file(cfg, &ctx.base, &f.path, &f.name)?);
        }
        let records: Vec<crate::analysis::Record<'_>> = recs
            .iter()
            .map(|r| crate::analysis::Record {
                r: r.r().unwrap_or(r.u()),
                u: r.u(),
                y: r.y(),
                i: r.i(),
                fs: r.fs(),
            })
            .collect();
        let settings = ctx.frf_settings(recs[0].period(), recs[0].len());
        let names: Vec<String> = files.iter().map(|f| f.name.clone()).collect();
        let out = crate::study::operating_point_from_records(&names, &records, &settings)
            .map_err(computation)?;
        let caption = format!(
            "Plant FRF of each recorded operating point ({}), {}.",
            names.join(", "),
            settings
                .band
                .map_or("band derived from the excitation".into(), |b| format!(
                    "{}–{} Hz",
                    fmt(b.0),
                    fmt(b.1)
                ))
        );
        return Ok(finish_operating_point(ctx, out, caption));
    }
    let (out, input) = match pre {
        Some(pre) => pre,
        None => match operating_point_input(ctx) {
            Some(input) => (crate::stage::operating_point_twin(&input)?, input),
            None => return Ok(StepStatus::Skipped("no data source".into())),
        },
    };
    let (b, g) = (cfg.operating_point.bias_pct, cfg.operating_point.air_gap_um);
    let frac = input.excitation.amplitude_frac;
    let caption = format!(
        "Period-averaged plant FRF (joint input-output) at nominal, bias current ±{b} % and air \
         gap ±{g} µm, each from its own experiment at {} % of i_sat, {}–{} Hz (band {}).",
        fmt(100.0 * frac),
        fmt(out.plants[0].f_hz().first().copied().unwrap_or(f64::NAN)),
        fmt(out.plants[0].f_hz().last().copied().unwrap_or(f64::NAN)),
        if cfg.frf.band_hz.is_some() {
            "given by [frf] band_hz"
        } else {
            "the seed's"
        }
    );
    Ok(finish_operating_point(ctx, out, caption))
}

/// Books the operating-point study's result: its summary part, its section, the typed result.
fn finish_operating_point(
    ctx: &mut Ctx<'_>,
    out: crate::study::OperatingPointOutcome,
    caption: String,
) -> StepStatus {
    ctx.typed.operating_point = Some(operating_point_summary(&out));
    ctx.section(
        "operating-point",
        "Operating-point study",
        super::render_signal::operating_point(&out, caption),
    );
    ctx.operating_point = Some(out);
    StepStatus::Done
}

/// The operating-point study's part of `summary.json`: per case, the median deviation from
/// nominal per band and the error against the twin's exact plant.
fn operating_point_summary(
    out: &crate::study::OperatingPointOutcome,
) -> std::collections::BTreeMap<String, std::collections::BTreeMap<String, f64>> {
    let mut op: std::collections::BTreeMap<String, std::collections::BTreeMap<String, f64>> =
        Default::default();
    for d in &out.deviations {
        op.entry(d.case.clone()).or_default().insert(
            format!("{}_median_dev_pct", d.band),
            100.0 * d.median_rel_dev,
        );
    }
    for (c, e) in out.cases.iter().zip(&out.truth_errors) {
        op.entry(c.name.clone())
            .or_default()
            .insert("error_vs_truth_pct".into(), 100.0 * e);
    }
    op
}

/// The robust-BLA stage's input on the twin (`None` on files).
pub fn bla_input(ctx: &Ctx<'_>) -> Option<crate::stage::BlaInput> {
    let cfg = ctx.cfg;
    let t = ctx.twin.as_ref()?;
    Some(crate::stage::BlaInput {
        plan: crate::bla::BlaPlan {
            twin: t.cfg.clone(),
            mode: t.mode,
            noise: t.noise,
            realisations: cfg.bla.realisations,
            periods: cfg.bla.periods,
            seed: ctx.seeds.bla,
            ..crate::bla::BlaPlan::default()
        },
        levels: cfg
            .amplitude_study
            .levels_pct
            .iter()
            .map(|l| l / 100.0)
            .collect(),
    })
}

pub fn bla(ctx: &mut Ctx<'_>) -> Result<StepStatus, Error> {
    let cfg = ctx.cfg;
    let (study, intro) = match (&ctx.twin, cfg.source) {
        (Some(_), _) => {
            let Some(input) = bla_input(ctx) else {
                return Ok(StepStatus::Skipped("no data source".into()));
            };
            let (study, secs) = match ctx.pre.bla.take() {
                Some(pre) => pre,
                None => super::timed(|| crate::stage::bla_twin(&input)),
            };
            ctx.pre_seconds += secs;
            let study = study?;
            let plan = &input.plan;
            let intro = format!(
                "Robust best linear approximation (Pintelon & Schoukens) on the twin: at each RMS level, \
                 {} random-phase random-odd multisines of {} periods (one more period settles the loop), \
                 20–2000 Hz; the plant's BLA referenced to r, its noise variance from the period spread and \
                 the stochastic nonlinear-distortion variance from the spread over realisations, both \
                 relative to |G|² and averaged over {}–{} Hz; and the power at the non-excited (detection) \
                 lines over the noise floor. This answers directly what the seed-style study (coherence, FRF \
                 variance, SNR) infers.",
                plan.realisations,
                plan.periods,
                fmt(plan.summary_band_hz.0),
                fmt(plan.summary_band_hz.1)
            );
            (study, intro)
        }
        (None, SourceKind::Files) => {
            if cfg.bla.files.is_empty() {
                return Ok(StepStatus::Skipped(
                    "the robust BLA on recorded data needs M ≥ 2 random-phase multisine records per level \
                     (whole periods, the same period length): list them in [bla] files = \
                     [{ level_pct = 4.0, path = \"…\" }, …] (several entries per level); the period \
                     is found in the records unless [data] period_samples gives it"
                        .into(),
                ));
            }
            let mut tagged = Vec::with_capacity(cfg.bla.files.len());
            let mut fs = f64::NAN;
            for lf in &cfg.bla.files {
                let rec: Recording =
                    super::data::load_file(cfg, &ctx.base, &lf.path, "BLA realisation")?;
                if fs.is_nan() {
                    fs = rec.fs();
                } else if (rec.fs() - fs).abs() > 1e-9 * fs {
                    return Err(Error::input(format!(
                        "{}: sampled at {} Hz, the first BLA file at {} Hz; all realisations must share \
                         the sample rate",
                        rec.source,
                        rec.fs(),
                        fs
                    )));
                }
                let sig = rec.signals();
                let x = crate::bla::Realisation {
                    r: sig.r,
                    u: sig.u,
                    y: sig.y,
                    saturated_fraction: rec.saturated_fraction,
                    source: rec.source,
                };
                tagged.push((lf.level_pct, x));
            }
            let levels = crate::bla::RecordedLevel::group(tagged);
            // [data] period_samples, else the period every realisation's excitation repeats with
            let n = match cfg.data.period_samples {
                Some(n) => n,
                None => crate::bla::common_period(&levels).map_err(|e| {
                    Error::input(format!(
                        "[bla] files are given but the multisine period is not, and it is not found \
                         in the records ({e}): set [data] period_samples"
                    ))
                })?,
            };
            let band = cfg.frf.quality_band_hz.unwrap_or([10.0, 1000.0]);
            let plan = crate::bla::RecordedPlan {
                fs,
                period_samples: n,
                skip_periods: cfg.data.skip_periods,
                summary_band_hz: (band[0], band[1]),
            };
            let study = crate::bla::amplitude_study_from_records(&levels, &plan).map_err(input)?;
            let m: Vec<String> = levels
                .iter()
                .map(|l| format!("{} at {} %", l.realisations.len(), fmt(l.level_pct)))
                .collect();
            let intro = format!(
                "Robust best linear approximation (Pintelon & Schoukens) from {} recorded random-phase \
                 multisine realisations ({}), periods of {n} samples, {} leading period(s) dropped: the \
                 plant's BLA{}, its noise variance from the period spread and the stochastic \
                 nonlinear-distortion variance from the spread over realisations, both relative to |G|² \
                 and averaged over {}–{} Hz; and the power at the non-excited (detection) lines over the \
                 noise floor. The current limit is not known for recorded data, so clipping is not \
                 checked here.",
                cfg.bla.files.len(),
                m.join(", "),
                cfg.data.skip_periods,
                if levels[0].realisations[0].r.is_some() {
                    " referenced to r"
                } else {
                    " (open loop, u → y)"
                },
                fmt(band[0]),
                fmt(band[1])
            );
            (study, intro)
        }
        _ => return Ok(StepStatus::Skipped("no data source".into())),
    };
    ctx.typed.bla = Some(bla_summary(&study));
    let blocks = super::render_signal::bla(&study, intro, ctx.seed_study.as_deref());
    ctx.section("bla", "Robust best linear approximation", blocks);
    ctx.bla = Some(study);
    Ok(StepStatus::Done)
}

/// The robust BLA study's part of `summary.json`.
fn bla_summary(study: &crate::bla::BlaStudy) -> super::BlaSummary {
    super::BlaSummary {
        levels: study
            .rows
            .iter()
            .map(|r| super::BlaLevel {
                level_pct: r.level_pct,
                noise_rel: r.noise_rel,
                nl_rel: r.nl_rel,
                nl_rel_se: r.nl_rel_se,
                even_db: r.even_db,
                odd_db: r.odd_db,
                bla_vs_linear_pct: r.bla_vs_linear_rel.map(|e| 100.0 * e),
                saturated_pct: 100.0 * r.saturated_fraction,
            })
            .collect(),
        recommended_pct: study.recommended_pct,
    }
}
