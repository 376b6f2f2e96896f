//! The report sections of the excitation design and the studies (amplitude, operating point,
//! robust BLA), drawn from the stages' typed results alone.

use super::figures::{bode_panels, figure, lin, log, series, with_spans, xy, Curve};
use crate::bla::BlaStudy;
use crate::report::{format_number as fmt, Block, NoteKind, Span, Style, Table};
use crate::stage::{AmplitudeStage, ExcitationStage};
use crate::study::{AmplitudeOutcome, OperatingPointOutcome};

fn note(kind: NoteKind, text: impl Into<String>) -> Block {
    Block::Note {
        kind,
        text: text.into(),
    }
}

/// The excitation section's blocks: the four candidates' waveforms, spectra and
/// autocorrelations, their comparison table and the identification excitation's design.
pub(crate) fn excitation(stage: &ExcitationStage) -> Vec<Block> {
    let inp = &stage.input;
    let (fs, level, unit, isat) = (inp.fs, inp.level, inp.unit.as_str(), inp.i_sat);
    let cmp = &stage.comparison;
    let for_files = if inp.for_files {
        "Candidates for a new experiment at this record's sample rate (not the recorded signal). "
    } else {
        ""
    };
    let mut blocks = vec![Block::Text(format!(
        "{for_files}The four candidate excitations of the seed paper, each one PRBS period long ({} samples at \
         {} Hz) and scaled to the same RMS level ({} {unit}{}): PRBS (order 10, 5 samples per bit), \
         a linear chirp, Gaussian white noise and a Schroeder-phased multisine over the PRBS band.",
        cmp.signals.first().map_or(0, |s| s.values.len()),
        fmt(fs),
        fmt(level),
        isat.map_or(String::new(), |i| format!(
            ", {} % of i_sat = {} A",
            fmt(inp.compare_level_pct),
            fmt(i)
        )),
    ))];
    let ms = 20.0;
    let nwin = ((ms * 1e-3 * fs) as usize).max(10);
    let mut wave = Vec::new();
    let mut spec = Vec::new();
    let mut acf = Vec::new();
    let mut rows = Vec::new();
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
            stage.minus_3db_hz[k].map_or("—".into(), fmt),
            fmt(r.resolution_hz),
            fmt(r.duration_s),
            fmt(r.rms),
            fmt(r.peak),
            fmt(r.crest_factor),
        ]);
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
    {
        if let Some(d) = &stage.identification {
            let (p, r) = (&d.plan, &d.report);
            blocks.push(Block::Table(Table {
                id: "excitation_identification".into(),
                caption: format!(
                    "The identification excitation ({}{}): usable band (f_min = resolution = fs/period; \
                     f_max = 1/(2 N_b T_s), the seed paper's rule for a PRBS of N_b samples per bit; \
                     −3 dB where its spectrum |sin(π f N_b T_s) / (N_b sin(π f T_s))| has fallen by 3 dB), \
                     resolution and duration.",
                    d.kind,
                    if d.kind == "prbs" {
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
                    if d.kind == "prbs" {
                        d.hold_3db_hz.map_or("—".into(), fmt)
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
    blocks
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

/// The amplitude study's blocks; `configured` when the workflow file fixed the level.
pub(crate) fn amplitude(stage: &AmplitudeStage, configured: bool) -> Vec<Block> {
    let chosen_pct = stage.chosen_pct;
    let out = &stage.outcome;
    let source = &stage.source;
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
    blocks.push(note(
        if out.recommended_pct.is_some() {
            NoteKind::Pass
        } else {
            NoteKind::Warning
        },
        format!(
            "{} Identification level used below: {} % of i_sat{}.",
            out.reasoning,
            fmt(chosen_pct),
            if configured {
                " (set in the workflow file)"
            } else {
                ""
            }
        ),
    ));
    blocks
}

/// The operating-point study's blocks: the plant FRF of every case and the deviations table.
pub(crate) fn operating_point(out: &OperatingPointOutcome, caption: String) -> Vec<Block> {
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
    }
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

/// The robust BLA section's blocks; `seed_study` is the amplitude study's (level %, mean
/// relative plant variance), drawn for comparison when it ran.
pub(crate) fn bla(
    study: &BlaStudy,
    intro: String,
    seed_study: Option<&[(f64, f64)]>,
) -> Vec<Block> {
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
    if let Some(seed) = seed_study {
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
    }
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
        note(NoteKind::Info, study.reasoning.clone()),
    ];
    blocks
}
