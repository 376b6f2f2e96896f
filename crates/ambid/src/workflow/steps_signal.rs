//! Steps 1–3: excitation design and comparison, amplitude study, operating-point study.

use super::config::SourceKind;
use super::data::Recording;
use super::figures::{bode_panels, figure, lin, log, series, with_spans, xy, Curve};
use super::{computation, input, Ctx, Error, StepStatus};
use crate::report::{format_number as fmt, Block, NoteKind, Span, Style, Table};
use crate::study::{
    amplitude_from_records, AmplitudeOutcome, LevelRecord, OperatingCase, Recommendation,
    TwinAmplitudeStudy,
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
    let for_files = if ctx.twin.is_none() {
        "Candidates for a new experiment at this record's sample rate (not the recorded signal). "
    } else {
        ""
    };
    let cmp = crate::comparison::compare(fs, level, ctx.cfg.seed, 400).map_err(computation)?;
    let mut blocks = vec![Block::Text(format!(
        "{for_files}The four candidate excitations of the seed paper, each one PRBS period long ({} samples at \
         {} Hz) and scaled to the same RMS level ({} {unit}{}): PRBS (order 10, 5 samples per bit), \
         a linear chirp, Gaussian white noise and a Schroeder-phased multisine over the PRBS band.",
        cmp.signals.first().map_or(0, |s| s.values.len()),
        fmt(fs),
        fmt(level),
        isat.map_or(String::new(), |i| format!(
            ", {} % of i_sat = {} A",
            fmt(ctx.cfg.excitation.compare_level_pct),
            fmt(i)
        )),
    ))];
    let ms = 20.0;
    let nwin = ((ms * 1e-3 * fs) as usize).max(10);
    let mut wave = Vec::new();
    let mut spec = Vec::new();
    let mut acf = Vec::new();
    let mut rows = Vec::new();
    let mut summary = super::ExcitationSummary::default();
    for (k, s) in cmp.signals.iter().enumerate() {
        let n = s.values.len().min(nwin);
        let t: Vec<f64> = (0..n).map(|j| 1e3 * j as f64 * cmp.ts).collect();
        wave.push(xy(
            s.name,
            lin("time [ms]"),
            lin(&format!("r [{unit}]")),
            vec![series(s.name, &t, &s.values[..n], Style::Line, Some(k))],
        ));
        let (f, a): (Vec<f64>, Vec<f64>) = cmp
            .f_hz
            .iter()
            .zip(&s.spectrum)
            .skip(1)
            .map(|(f, a)| (*f, *a))
            .unzip();
        spec.push(series(s.name, &f, &a, Style::Line, Some(k)));
        let lags: Vec<f64> = (0..s.autocorr.len())
            .map(|j| 1e3 * j as f64 * cmp.ts)
            .collect();
        acf.push(series(s.name, &lags, &s.autocorr, Style::Line, Some(k)));
        let r = &s.report;
        rows.push(vec![
            s.name.to_string(),
            fmt(r.f_min_hz),
            fmt(r.f_max_hz),
            spectrum_3db_hz(&cmp.f_hz, &s.spectrum, r.f_min_hz, r.f_max_hz).map_or("—".into(), fmt),
            fmt(r.resolution_hz),
            fmt(r.duration_s),
            fmt(r.rms),
            fmt(r.peak),
            fmt(r.crest_factor),
        ]);
        summary.compare.insert(
            s.name.to_string(),
            super::CompareFigures {
                crest_factor: r.crest_factor,
                f_max_hz: r.f_max_hz,
            },
        );
    }
    // overlaid panels: the PRBS (the seed paper's choice, first in the list) is drawn last, on top
    spec.reverse();
    acf.reverse();
    blocks.push(Block::Figure(figure(
        "excitation_waveforms",
        "Excitation waveforms",
        format!("First {ms} ms of each signal at the common RMS level."),
        wave,
        2,
    )));
    blocks.push(Block::Figure(figure(
        "excitation_spectra",
        "Amplitude spectra",
        "One-sided amplitude spectrum of one period of each signal (DFT of the whole period, no window)."
            .into(),
        {
            // the multisine and the PRBS have (numerically) empty lines: show four decades
            let top = spec
                .iter()
                .flat_map(|s| s.y.iter().copied())
                .fold(0.0f64, f64::max);
            let mut p = xy(
                "",
                log("frequency [Hz]"),
                log(&format!("amplitude [{unit}]")),
                spec,
            );
            if top > 0.0 {
                p.y.range = Some((top * 1e-4, top * 2.0));
            }
            vec![p]
        },
        1,
    )));
    blocks.push(Block::Figure(figure(
        "excitation_autocorrelation",
        "Autocorrelation",
        "Normalised autocorrelation of each signal (circular for the periodic PRBS and multisine) over the first 400 lags."
            .into(),
        vec![xy("", lin("lag [ms]"), lin("normalised autocorrelation [-]"), acf)],
        1,
    )));
    blocks.push(Block::Table(Table {
        id: "excitation_comparison".into(),
        caption:
            "Usable band, resolution, duration and crest factor of the four signals (one period): \
             f_max is each design's nominal upper frequency (the PRBS's 1/(2 N_b T_s), the seed \
             paper's rule), −3 dB the frequency where the signal's own amplitude spectrum (averaged \
             over 1 % of the lines) has fallen by 3 dB from its mean below f_max/10."
                .into(),
        header: vec![
            "signal".into(),
            "f_min [Hz]".into(),
            "f_max [Hz]".into(),
            "−3 dB [Hz]".into(),
            "resolution [Hz]".into(),
            "duration [s]".into(),
            format!("RMS [{unit}]"),
            format!("peak [{unit}]"),
            "crest factor [-]".into(),
        ],
        rows,
        highlight: Some(0),
    }));
    // the identification PRBS as designed
    if let Some(isat) = isat {
        let frac = ctx.cfg.excitation.amplitude_pct.unwrap_or(10.0) / 100.0;
        let p = ctx.plan(frac);
        let ts = 1.0 / fs;
        if let Some(spec) = p.spec(isat, ts).map_err(input)? {
            let r = spec.report(ts).map_err(computation)?;
            summary.identification = Some(super::ExcitationFigures {
                f_min_hz: r.f_min_hz,
                f_max_hz: r.f_max_hz,
                resolution_hz: r.resolution_hz,
                duration_s: r.duration_s,
                period_samples: r.period_samples as f64,
                crest_factor: r.crest_factor,
            });
            blocks.push(Block::Table(Table {
                id: "excitation_identification".into(),
                caption: format!(
                    "The identification excitation ({}{}): usable band (f_min = resolution = fs/period; \
                     f_max = 1/(2 N_b T_s), the seed paper's rule for a PRBS of N_b samples per bit; \
                     −3 dB where its spectrum |sin(π f N_b T_s) / (N_b sin(π f T_s))| has fallen by 3 dB), \
                     resolution and duration.",
                    ctx.cfg.excitation.kind,
                    if ctx.cfg.excitation.kind == "prbs" {
                        format!(
                            ", maximum-length sequence of order {}, {} samples per bit, {} periods",
                            p.prbs_order, p.samples_per_bit, p.periods
                        )
                    } else {
                        String::new()
                    }
                ),
                header: vec![
                    "f_min [Hz]".into(),
                    "f_max [Hz]".into(),
                    "−3 dB [Hz]".into(),
                    "resolution [Hz]".into(),
                    "period [samples]".into(),
                    "periods".into(),
                    "duration [s]".into(),
                    "crest factor [-]".into(),
                ],
                rows: vec![vec![
                    fmt(r.f_min_hz),
                    fmt(r.f_max_hz),
                    if ctx.cfg.excitation.kind == "prbs" {
                        fmt(hold_3db_hz(p.samples_per_bit, ts))
                    } else {
                        "—".into()
                    },
                    fmt(r.resolution_hz),
                    r.period_samples.to_string(),
                    r.periods.to_string(),
                    fmt(r.duration_s),
                    fmt(r.crest_factor),
                ]],
                highlight: None,
            }));
        }
    }
    ctx.section("excitation", "Excitation design and comparison", blocks);
    ctx.typed.excitation = Some(summary);
    Ok(StepStatus::Done)
}

/// The −3 dB frequency of a signal held for `nb` samples of `ts` (a PRBS of `nb` samples per
/// bit): the root of $|\sin(\pi f N_b T_s) / (N_b \sin(\pi f T_s))|^2 = 1/2$ below the first null
/// $1/(N_b T_s)$, by bisection (the ratio falls monotonically there); for `nb` = 1 the Nyquist
/// frequency.
pub(crate) fn hold_3db_hz(nb: usize, ts: f64) -> f64 {
    if nb <= 1 {
        return 0.5 / ts;
    }
    let n = nb as f64;
    let gain = |f: f64| {
        let x = std::f64::consts::PI * f * ts;
        ((n * x).sin() / (n * x.sin())).powi(2)
    };
    let (mut lo, mut hi) = (1e-12 / ts, 1.0 / (n * ts));
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if gain(mid) > 0.5 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The −3 dB point of a measured amplitude spectrum: the first frequency above `f_max`/10 where
/// the power, averaged over 1 % of the lines, falls below half its mean over the lines in
/// [`f_min`, `f_max`/10]; `None` when there is no such reference or no such fall.
fn spectrum_3db_hz(f: &[f64], amp: &[f64], f_min: f64, f_max: f64) -> Option<f64> {
    let pw: Vec<f64> = amp.iter().map(|a| a * a).collect();
    let refs: Vec<f64> = f
        .iter()
        .zip(&pw)
        .filter(|(fk, _)| **fk >= f_min && **fk <= 0.1 * f_max)
        .map(|(_, p)| *p)
        .collect();
    if refs.is_empty() {
        return None;
    }
    let reference = refs.iter().sum::<f64>() / refs.len() as f64;
    let half = (pw.len() / 200).max(1);
    (0..pw.len()).find_map(|k| {
        if f[k] <= 0.1 * f_max {
            return None;
        }
        let (a, b) = (k.saturating_sub(half), (k + half + 1).min(pw.len()));
        let mean = pw[a..b].iter().sum::<f64>() / (b - a) as f64;
        (mean < 0.5 * reference).then_some(f[k])
    })
}

fn amplitude_figure(out: &AmplitudeOutcome) -> Block {
    let lv: Vec<f64> = out.rows.iter().map(|r| r.level_pct).collect();
    let spans = out
        .recommended_pct
        .map(|(a, b)| {
            vec![Span {
                label: "recommended".into(),
                x0: a - 0.5,
                x1: b + 0.5,
            }]
        })
        .unwrap_or_default();
    let coh = with_spans(
        xy(
            "coherence",
            lin("excitation level [% of i_sat]"),
            lin("mean coherence [-]"),
            vec![
                series(
                    "γ²_ry",
                    &lv,
                    &out.rows.iter().map(|r| r.mean_coh_ry).collect::<Vec<_>>(),
                    Style::LineMarkers(crate::report::Marker::Dot),
                    Some(0),
                ),
                series(
                    "γ²_ru",
                    &lv,
                    &out.rows.iter().map(|r| r.mean_coh_ru).collect::<Vec<_>>(),
                    Style::LineMarkers(crate::report::Marker::Square),
                    Some(1),
                ),
            ],
        ),
        spans.clone(),
    );
    let var = with_spans(
        xy(
            "FRF variance",
            lin("excitation level [% of i_sat]"),
            log("mean relative plant variance [-]"),
            vec![series(
                "var(P̂)/|P̂|²",
                &lv,
                &out.rows
                    .iter()
                    .map(|r| r.mean_plant_rel_var)
                    .collect::<Vec<_>>(),
                Style::LineMarkers(crate::report::Marker::Dot),
                Some(2),
            )],
        ),
        spans.clone(),
    );
    let snr: Vec<f64> = out
        .rows
        .iter()
        .map(|r| r.snr_db.unwrap_or(f64::NAN))
        .collect();
    let snr = with_spans(
        xy(
            "output SNR",
            lin("excitation level [% of i_sat]"),
            lin("output SNR [dB]"),
            vec![series(
                "SNR",
                &lv,
                &snr,
                Style::LineMarkers(crate::report::Marker::Dot),
                Some(3),
            )],
        ),
        spans,
    );
    Block::Figure(figure(
        "amplitude_study",
        "Excitation-amplitude study",
        format!(
            "Quality of the plant FRF against the excitation level (seed paper, figure 6): average \
             coherence γ²_ry and γ²_ru, average relative FRF variance from the period-to-period spread, \
             and the output SNR (output power with excitation over the output power of a record without \
             excitation) over the quality band. Shaded: the recommended range. {}",
            out.reasoning
        ),
        vec![coh, var, snr],
        3,
    ))
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
    let chosen_pct = stage.chosen_pct;
    let out = &stage.outcome;
    let source = &stage.source;
    ctx.level_frac = Some(chosen_pct / 100.0);
    ctx.seed_study = Some(
        out.rows
            .iter()
            .map(|r| (r.level_pct, r.mean_plant_rel_var))
            .collect(),
    );
    let mut rows = Vec::new();
    for r in &out.rows {
        rows.push(vec![
            fmt(r.level_pct),
            fmt(r.mean_coh_ry),
            fmt(r.mean_coh_ru),
            fmt(r.mean_plant_rel_var),
            r.snr_db.map_or("—".into(), fmt),
            fmt(100.0 * r.saturated_fraction),
            r.plant_median_rel_err
                .map_or("—".into(), |e| fmt(100.0 * e)),
        ]);
    }
    let highlight = out
        .rows
        .iter()
        .position(|r| (r.level_pct - chosen_pct).abs() < 1e-9);
    let mut blocks = vec![
        Block::Text(format!("Amplitude study on {source}.")),
        amplitude_figure(out),
        Block::Table(Table {
            id: "amplitude_study".into(),
            caption: "Quality measures per level (quality band averages). The last column is the \
                      median relative error of the plant FRF against the twin's exact linearised \
                      plant (twin only)."
                .into(),
            header: vec![
                "level [% i_sat]".into(),
                "mean γ²_ry".into(),
                "mean γ²_ru".into(),
                "mean rel. variance".into(),
                "SNR [dB]".into(),
                "saturated [%]".into(),
                "median error vs truth [%]".into(),
            ],
            rows,
            highlight,
        }),
    ];
    blocks.push(Ctx::note(
        if out.recommended_pct.is_some() {
            NoteKind::Pass
        } else {
            NoteKind::Warning
        },
        format!(
            "{} Identification level used below: {} % of i_sat{}.",
            out.reasoning,
            fmt(chosen_pct),
            if cfg.excitation.amplitude_pct.is_some() {
                " (set in the workflow file)"
            } else {
                ""
            }
        ),
    ));
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
        let blocks = operating_point_blocks(ctx, &out, caption);
        ctx.section("operating-point", "Operating-point study", blocks);
        return Ok(StepStatus::Done);
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
    let blocks = operating_point_blocks(ctx, &out, caption);
    ctx.section("operating-point", "Operating-point study", blocks);
    Ok(StepStatus::Done)
}

fn operating_point_blocks(
    ctx: &mut Ctx<'_>,
    out: &crate::study::OperatingPointOutcome,
    caption: String,
) -> Vec<Block> {
    let curves: Vec<Curve<'_>> = out
        .cases
        .iter()
        .zip(&out.plants)
        .enumerate()
        .map(|(k, (c, p))| Curve {
            name: &c.name,
            f: p.f_hz(),
            g: p.values(),
            std: None,
            style: if k == 0 { Style::Line } else { Style::Dashed },
            color: Some(k),
        })
        .collect();
    let fig = figure(
        "operating_point_frf",
        "Plant FRF at five operating points",
        caption,
        bode_panels(&curves, "|P| [dB re 1 m/A]"),
        1,
    );
    let mut rows = Vec::new();
    let mut op: std::collections::BTreeMap<String, std::collections::BTreeMap<String, f64>> =
        Default::default();
    for d in &out.deviations {
        rows.push(vec![
            d.case.clone(),
            d.band.clone(),
            format!("{}–{}", fmt(d.f_min_hz), fmt(d.f_max_hz)),
            fmt(100.0 * d.median_rel_dev),
            fmt(d.max_abs_db_dev),
            fmt(d.max_abs_phase_dev_deg),
            d.truth_median_rel_dev
                .map_or("—".into(), |v| fmt(100.0 * v)),
        ]);
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
    ctx.typed.operating_point = Some(op);
    vec![
        Block::Figure(fig),
        Block::Table(Table {
            id: "operating_point".into(),
            caption:
                "Deviation of each operating point's plant FRF from nominal, per band: median \
                      relative deviation, largest magnitude (dB) and phase deviation, and the same \
                      median for the twin's exact plants (what the estimate should show)."
                    .into(),
            header: vec![
                "case".into(),
                "band".into(),
                "range [Hz]".into(),
                "median deviation [%]".into(),
                "max |Δ| [dB]".into(),
                "max |Δφ| [deg]".into(),
                "true median deviation [%]".into(),
            ],
            rows,
            highlight: None,
        }),
    ]
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
                     [{ level_pct = 4.0, path = \"…\" }, …] (several entries per level) and give \
                     [data] period_samples"
                        .into(),
                ));
            }
            let Some(n) = cfg.data.period_samples else {
                return Err(Error::input("[bla] files are given but the multisine period is not: set [data] period_samples"));
            };
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
    let lv: Vec<f64> = study.rows.iter().map(|r| r.level_pct).collect();
    let col = |f: fn(&crate::bla::LevelBla) -> f64| study.rows.iter().map(f).collect::<Vec<f64>>();
    let spans = vec![Span {
        label: "recommended (BLA)".into(),
        x0: study.recommended_pct - 0.5,
        x1: study.recommended_pct + 0.5,
    }];
    let mut series_v = vec![
        series(
            "noise variance (BLA)",
            &lv,
            &col(|r| r.noise_rel),
            Style::LineMarkers(crate::report::Marker::Dot),
            Some(0),
        ),
        series(
            "nonlinear variance (BLA)",
            &lv,
            &col(|r| r.nl_rel),
            Style::LineMarkers(crate::report::Marker::Square),
            Some(1),
        ),
        series("sum", &lv, &col(|r| r.sum_rel), Style::Dashed, Some(2)),
    ];
    if let Some(seed) = &ctx.seed_study {
        let (x, y): (Vec<f64>, Vec<f64>) = seed.iter().copied().unzip();
        series_v.push(series(
            "seed-style FRF variance (amplitude study)",
            &x,
            &y,
            Style::LineMarkers(crate::report::Marker::Cross),
            Some(3),
        ));
    }
    let var_panel = with_spans(
        xy(
            "variances",
            lin("excitation level [% of i_sat, RMS]"),
            log("relative variance [-]"),
            series_v,
        ),
        spans.clone(),
    );
    let det_panel = with_spans(
        xy(
            "detection lines",
            lin("excitation level [% of i_sat, RMS]"),
            lin("power over the noise floor [dB]"),
            vec![
                series(
                    "even non-excited lines",
                    &lv,
                    &col(|r| r.even_db),
                    Style::LineMarkers(crate::report::Marker::Dot),
                    Some(4),
                ),
                series(
                    "odd non-excited lines",
                    &lv,
                    &col(|r| r.odd_db),
                    Style::LineMarkers(crate::report::Marker::Square),
                    Some(5),
                ),
            ],
        ),
        spans,
    );
    let mut rows = Vec::new();
    let mut jrows = Vec::new();
    for r in &study.rows {
        rows.push(vec![
            fmt(r.level_pct),
            fmt(r.noise_rel),
            if r.nl_rel > 3.0 * r.nl_rel_se {
                format!("{} ± {}", fmt(r.nl_rel), fmt(r.nl_rel_se))
            } else {
                // a variance estimate within 3 standard errors of zero (possibly negative)
                format!("< {} (not significant)", fmt(3.0 * r.nl_rel_se))
            },
            fmt(r.sum_rel),
            fmt(r.even_db),
            fmt(r.odd_db),
            r.bla_vs_linear_rel.map_or("—".into(), |e| fmt(100.0 * e)),
            fmt(100.0 * r.saturated_fraction),
        ]);
        jrows.push(super::BlaLevel {
            level_pct: r.level_pct,
            noise_rel: r.noise_rel,
            nl_rel: r.nl_rel,
            nl_rel_se: r.nl_rel_se,
            even_db: r.even_db,
            odd_db: r.odd_db,
            bla_vs_linear_pct: r.bla_vs_linear_rel.map(|e| 100.0 * e),
            saturated_pct: 100.0 * r.saturated_fraction,
        });
    }
    ctx.typed.bla = Some(super::BlaSummary {
        levels: jrows,
        recommended_pct: study.recommended_pct,
    });
    let highlight = study
        .rows
        .iter()
        .position(|r| (r.level_pct - study.recommended_pct).abs() < 1e-9);
    let blocks = vec![
        Block::Text(intro),
        Block::Figure(figure(
            "bla_study",
            "Noise and nonlinear distortion against level (robust BLA)",
            format!(
                "Band-averaged relative noise variance and nonlinear variance of one experiment, their sum, \
                 and the seed-style relative FRF variance of the amplitude study for comparison (log axis: \
                 non-positive nonlinear variances, i.e. statistically zero, are not drawn); detection-line \
                 power over the noise floor. Shaded: the BLA's recommended level. {}",
                study.reasoning
            ),
            vec![var_panel, det_panel],
            2,
        )),
        Block::Table(Table {
            id: "bla_study".into(),
            caption: "Robust BLA per level: relative noise and nonlinear variance (± standard error), their \
                      sum, detection-line power over the noise floor, the BLA's RMS relative difference from \
                      the twin's linearised plant (twin only) and the fraction of clipped samples (twin \
                      only)."
                .into(),
            header: vec![
                "level [% i_sat RMS]".into(),
                "noise var. [-]".into(),
                "NL var. [-]".into(),
                "sum [-]".into(),
                "even lines [dB]".into(),
                "odd lines [dB]".into(),
                "BLA vs linear [%]".into(),
                "clipped [%]".into(),
            ],
            rows,
            highlight,
        }),
        Ctx::note(NoteKind::Info, study.reasoning.clone()),
    ];
    ctx.section("bla", "Robust best linear approximation", blocks);
    Ok(StepStatus::Done)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hold's −3 dB point against a naive DFT of the hold kernel (a box of N_b ones):
    /// |Σ_k e^{−j2πf k T_s}| / N_b = 1/√2 there; for 5 samples per bit at 20 kHz 1803.2 Hz (the
    /// issue read ≈ 1806 Hz off a measured spectrum; the seed paper's rule says 2000 Hz).
    #[test]
    fn hold_3db_point_matches_the_dft_of_the_hold_kernel() {
        let kernel = |nb: usize, ts: f64, f: f64| {
            let (mut re, mut im) = (0.0, 0.0);
            for k in 0..nb {
                let ph = -std::f64::consts::TAU * f * k as f64 * ts;
                re += ph.cos();
                im += ph.sin();
            }
            (re * re + im * im).sqrt() / nb as f64
        };
        for (nb, fs) in [(2, 1000.0), (5, 20_000.0), (7, 10_000.0), (20, 48_000.0)] {
            let ts = 1.0 / fs;
            let f3 = hold_3db_hz(nb, ts);
            assert!((kernel(nb, ts, f3) - 0.5f64.sqrt()).abs() < 1e-9, "nb {nb}");
            // at or below the rule (equal for 2 samples per bit: f_s/4)
            assert!(f3 <= 1.0 / (2.0 * nb as f64 * ts) * (1.0 + 1e-9));
        }
        let f = hold_3db_hz(5, 5e-5);
        assert!((f - 1803.17).abs() < 0.01, "{f}");
        assert_eq!(hold_3db_hz(1, 1e-3), 500.0);
    }

    /// A first-order low-pass spectrum |1/(1 + j f/fc)| falls by 3 dB at fc.
    #[test]
    fn spectrum_3db_point_of_a_first_order_low_pass() {
        let fc = 1000.0;
        let f: Vec<f64> = (0..20_000).map(|k| k as f64 * 0.5).collect();
        let a: Vec<f64> = f
            .iter()
            .map(|f| 1.0 / (1.0 + (f / fc).powi(2)).sqrt())
            .collect();
        // reference over [1, 100] Hz, where the power is 1 to within 1 %
        let got = spectrum_3db_hz(&f, &a, 1.0, 1000.0).unwrap();
        assert!((got - fc).abs() < 0.03 * fc, "{got}");
        assert!(spectrum_3db_hz(&f, &a, 1e6, 2e6).is_none());
    }
}
