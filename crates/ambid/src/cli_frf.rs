//! `ambid frf` and `ambid study`: argument parsing and file output over `ambid::analysis` and
//! `ambid::study`.

use ambid::analysis::{analyze, FrfAnalysis, FrfMethod, FrfSettings, Record};
use ambid::experiment::ExcitationPlan;
use ambid::frf_stream::{analyze_csv, StreamColumns};
use ambid::io::output::write_file;
use ambid::io::{frf_csv_bytes, read_controller, read_time_csv, FrfColumn, OutputSet};
use ambid::study::{
    amplitude_from_records, amplitude_on_twin, operating_point_on_twin, seed_cases, seed_levels,
    LevelRecord, Recommendation, TwinAmplitudeStudy,
};
use ambid_core::frf::resonance::{find_resonances_reliable, order_from_peaks, ResonanceOptions};
use ambid_core::frf::window::Window;
use ambid_twin::{Mode, TwinConfig};
use anyhow::{Context, Result};
use clap::{Args, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};

pub(crate) use crate::cli_args::parse_band;

#[derive(Clone, Copy, ValueEnum)]
pub enum WindowArg {
    Rect,
    Hann,
    Hamming,
    Blackman,
    Flattop,
}

impl From<WindowArg> for Window {
    fn from(w: WindowArg) -> Window {
        match w {
            WindowArg::Rect => Window::Rectangular,
            WindowArg::Hann => Window::Hann,
            WindowArg::Hamming => Window::Hamming,
            WindowArg::Blackman => Window::Blackman,
            WindowArg::Flattop => Window::FlatTop,
        }
    }
}

#[derive(Args)]
pub struct FrfArgs {
    /// Time-data CSV (header row; optional `t` column in seconds).
    data: PathBuf,
    /// Sample rate in Hz (needed when the file has no `t` column).
    #[arg(long)]
    fs: Option<f64>,
    /// Column of the excitation r.
    #[arg(long, default_value = "r")]
    excitation: String,
    /// Column of the controller output u (including r).
    #[arg(long, default_value = "u")]
    input: String,
    /// Column of the measured output y.
    #[arg(long, default_value = "y")]
    output: String,
    /// Column of the coil current (saturation check); used when present.
    #[arg(long, default_value = "i")]
    current: String,
    /// Controller file (TOML/JSON: pid, tf or ss) for the indirect plant estimate.
    #[arg(long)]
    controller: Option<PathBuf>,
    /// Samples per excitation period: selects period-synchronous averaging (otherwise Welch);
    /// with `--method lpm|lrm`, cuts the record to whole periods.
    #[arg(long)]
    period_samples: Option<usize>,
    /// Leading periods dropped as transient (period averaging).
    #[arg(long, default_value_t = 1)]
    skip_periods: usize,
    /// Welch segment length in samples (default: 1/8 of the record, at least 256).
    #[arg(long)]
    nperseg: Option<usize>,
    /// Welch overlap in samples (default: half a segment).
    #[arg(long)]
    noverlap: Option<usize>,
    /// Welch window.
    #[arg(long, value_enum, default_value_t = WindowArg::Hann)]
    window: WindowArg,
    /// Leading samples dropped as transient (Welch).
    #[arg(long, default_value_t = 0)]
    skip_samples: usize,
    /// Band of the written FRF, Hz (f_min,f_max; default: derived from the excitation, the
    /// lines within 10 dB of its strongest; docs/frf.md).
    #[arg(long, value_parser = parse_band)]
    band: Option<(f64, f64)>,
    /// Band of the quality averages and the resonance search, Hz (default: derived from the
    /// excitation, where it is within 3 dB of its strongest line).
    #[arg(long, value_parser = parse_band)]
    quality_band: Option<(f64, f64)>,
    /// Unit of the output column (for printed magnitudes; default: not given).
    #[arg(long)]
    y_unit: Option<String>,
    /// Unit of the input column (for printed magnitudes; default: not given).
    #[arg(long)]
    u_unit: Option<String>,
    /// Saturation current of u and i in A (otherwise flat tops are looked for).
    #[arg(long)]
    i_sat: Option<f64>,
    /// Time-data CSV recorded without excitation under the same loop: output SNR.
    #[arg(long)]
    noise: Option<PathBuf>,
    /// Do not screen for NaN/Inf, spikes and stuck samples.
    #[arg(long)]
    no_screen: bool,
    /// Estimator: `auto` (period averaging with --period-samples, else Welch), `lpm` (the Local
    /// Polynomial Method on one non-periodic record: T_ry, S and the plant with their
    /// variances, leakage and transients removed; no coherence) or `lrm` (the Local Rational
    /// Method: like `lpm`, better on lightly damped modes narrower than the window).
    #[arg(long, value_enum, default_value_t = MethodArg::Auto)]
    method: MethodArg,
    /// LPM: polynomial degree R (default: R and the window chosen from the record by
    /// leave-one-out cross-validation, see docs/lpm.md; 2 when only --lpm-half-width is given).
    #[arg(long)]
    lpm_degree: Option<usize>,
    /// LRM: degrees of numerator, denominator and transient, `Rn,Rd,Rm`.
    #[arg(long, value_delimiter = ',', default_values_t = [2usize, 2, 2])]
    lrm_degrees: Vec<usize>,
    /// LPM/LRM: half width n of the local window (2n + 1 lines); default: chosen from the record
    /// (LPM, see --lpm-degree), the smallest window with 5 degrees of freedom (LRM).
    #[arg(long, alias = "half-width")]
    lpm_half_width: Option<usize>,
    /// Output FRF CSV.
    #[arg(long, default_value = "frf.csv")]
    out: PathBuf,
    /// Replace the output file if it exists.
    #[arg(long)]
    force: bool,
}

/// FRF estimator choice.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// Period averaging (with --period-samples) or Welch.
    Auto,
    /// Local Polynomial Method.
    Lpm,
    /// Local Rational Method.
    Lrm,
}

fn write_analysis(path: &Path, a: &FrfAnalysis, force: bool) -> Result<()> {
    let frf = &a.frf;
    let stds: Vec<Option<Vec<f64>>> = [&frf.t_ry, &frf.t_ru, &frf.plant, &frf.controller]
        .iter()
        .map(|f| f.std())
        .collect();
    let mut q = vec![
        FrfColumn {
            name: "t_ry",
            values: frf.t_ry.values(),
            std: stds[0].as_deref(),
        },
        FrfColumn {
            name: "t_ru",
            values: frf.t_ru.values(),
            std: stds[1].as_deref(),
        },
        FrfColumn {
            name: "plant",
            values: frf.plant.values(),
            std: stds[2].as_deref(),
        },
        FrfColumn {
            name: "controller",
            values: frf.controller.values(),
            std: stds[3].as_deref(),
        },
    ];
    let ind_std = frf.plant_indirect.as_ref().and_then(|p| p.std());
    if let Some(p) = &frf.plant_indirect {
        q.push(FrfColumn {
            name: "plant_indirect",
            values: p.values(),
            std: ind_std.as_deref(),
        });
    }
    // the sample rate of the data, so that fits to this FRF know their sample time
    let fs = vec![frf.t_ry.ts().map_or(f64::NAN, |t| 1.0 / t); frf.f_hz().len()];
    let bytes = frf_csv_bytes(
        frf.f_hz(),
        &q,
        &[
            ("coh_ry", &frf.coh_ry),
            ("coh_ru", &frf.coh_ru),
            ("fs_hz", &fs),
        ],
    )?;
    write_file(path, &bytes, force)?;
    Ok(())
}

fn print_quality(a: &FrfAnalysis) {
    let q = &a.quality;
    println!(
        "quality over {:.1}–{:.1} Hz ({} lines): mean coherence γ²_ry {:.4}, γ²_ru {:.4}; \
         single-period plant variance {:.3e} (relative {:.3e})",
        q.band.0,
        q.band.1,
        q.lines,
        q.mean_coherence_ry,
        q.mean_coherence_ru,
        q.mean_plant_variance,
        q.mean_plant_rel_variance
    );
    match (q.output_snr_db, &a.spectra) {
        (Some(s), _) => {
            println!("output SNR: {s:.2} dB (excited record over the noise-only record)")
        }
        (None, Some(sp)) => {
            // no noise-only record: per-line SNR of y from the period spread, averaged in dB
            let lines: Vec<usize> = a
                .frf
                .f_hz()
                .iter()
                .filter(|f| **f >= q.band.0 && **f <= q.band.1)
                .map(|f| (f / sp.resolution_hz()).round() as usize)
                .collect();
            let snr = ambid_core::frf::quality::line_snr(sp, 2, &lines);
            let db: Vec<f64> = snr
                .iter()
                .filter(|v| v.is_finite() && **v > 0.0)
                .map(|v| 10.0 * v.log10())
                .collect();
            if !db.is_empty() {
                println!(
                    "per-line output SNR from the period spread: mean {:.1} dB over {} lines \
                     (pass --noise for the seed's output SNR)",
                    db.iter().sum::<f64>() / db.len() as f64,
                    db.len()
                );
            }
        }
        _ => {}
    }
}

/// The unit of a plant magnitude from the declared units of y and u.
pub(crate) fn plant_unit(y: Option<&str>, u: Option<&str>) -> String {
    match (y, u) {
        (Some(y), Some(u)) => format!("{y}/{u}"),
        (Some(y), None) => format!("{y}/(unit of u not given)"),
        (None, Some(u)) => format!("(unit of y not given)/{u}"),
        (None, None) => "(unit not given)".into(),
    }
}

pub fn frf(a: FrfArgs) -> Result<()> {
    OutputSet::check(&a.out, a.force)?;
    let res = if a.method == MethodArg::Auto && a.noise.is_none() {
        // Welch and period averaging stream the file: memory for one block, segment or period
        let cols = StreamColumns {
            r: &a.excitation,
            u: &a.input,
            y: &a.output,
            i: Some(&a.current),
        };
        analyze_csv(&a.data, &cols, a.fs, |n, ts| frf_settings(&a, n, ts))?
    } else {
        match frf_in_memory(&a)? {
            Some(res) => res,
            None => return Ok(()),
        }
    };
    report_and_write(&a, &res)
}

/// The FRF with the whole record in memory (LPM/LRM, or a noise record for the SNR). `None`
/// when a local method wrote its output itself.
fn frf_in_memory(a: &FrfArgs) -> Result<Option<FrfAnalysis>> {
    let data = read_time_csv(&a.data, a.fs)?;
    ambid::analysis::check_fs_matches(a.fs, data.ts)?;
    // missing samples are kept for the screening; without it every sample must be a number
    let col = |name: &str| {
        if a.no_screen {
            data.column(name)
        } else {
            data.column_raw(name)
        }
    };
    let r = col(&a.excitation)?;
    let u = col(&a.input)?;
    let y = col(&a.output)?;
    let i = data.column_raw(&a.current).ok();
    let fs = 1.0 / data.ts;
    if matches!(a.method, MethodArg::Lpm | MethodArg::Lrm) {
        frf_local(a, r, u, y, fs)?;
        return Ok(None);
    }
    let settings = frf_settings(a, r.len(), data.ts)?;
    let noise = match &a.noise {
        Some(p) => {
            let d = read_time_csv(p, a.fs.or(Some(fs)))?;
            Some(d.column_raw(&a.output)?.to_vec())
        }
        None => None,
    };
    let rec = Record { r, u, y, i, fs };
    Ok(Some(
        analyze(&rec, &settings, noise.as_deref())
            .with_context(|| format!("{}", a.data.display()))?,
    ))
}

/// The settings of `a` for a record of `n` samples at sample time `ts` (reads the controller).
fn frf_settings(a: &FrfArgs, n: usize, ts: f64) -> Result<FrfSettings> {
    if let Some(k) = a.nperseg.filter(|&k| k > n) {
        return Err(ambid::workflow::usage(anyhow::anyhow!(
            "--nperseg {k} is longer than the record ({n} samples); give at most {n}, or leave it out to derive it from the record length"
        ))
        .into());
    }
    let method = match a.period_samples {
        Some(p) => FrfMethod::Periodic {
            period_samples: p,
            skip_periods: a.skip_periods,
        },
        None => FrfMethod::Welch {
            nperseg: a.nperseg.unwrap_or_else(|| FrfSettings::default_nperseg(n)),
            noverlap: a.noverlap,
            window: a.window.into(),
            skip_samples: a.skip_samples,
        },
    };
    let controller = match &a.controller {
        Some(p) => {
            let c = read_controller(p)?;
            c.check_ts(ts)?;
            Some(c.state_space().clone())
        }
        None => None,
    };
    Ok(FrfSettings {
        method,
        band: a.band,
        quality_band: a.quality_band,
        band_rule: Default::default(),
        rel_threshold: 1e-6,
        controller,
        i_sat: a.i_sat,
        screen: !a.no_screen,
    })
}

/// Prints the summary of `res` and writes the FRF file.
fn report_and_write(a: &FrfArgs, res: &FrfAnalysis) -> Result<()> {
    for w in &res.warnings {
        eprintln!("warning: {w}");
    }
    match &res.frf.averaging {
        ambid_core::frf::closed_loop::Averaging::Periods(p) => println!(
            "period averaging: {p} periods, {} lines in {:.1}–{:.1} Hz",
            res.frf.f_hz().len(),
            res.frf.f_hz()[0],
            res.frf.f_hz()[res.frf.f_hz().len() - 1]
        ),
        ambid_core::frf::closed_loop::Averaging::Welch {
            segments,
            effective,
        } => println!(
            "Welch: {segments} segments ({effective:.1} effective averages), {} bins",
            res.frf.f_hz().len()
        ),
    }
    println!("bands: {}", res.bands.describe());
    print_quality(res);
    // resonance peaks of the plant in the quality band, on lines whose relative standard
    // deviation is below 10 % (noise ripple must not count as a mode)
    let qb = res.quality.band;
    let opts = ResonanceOptions {
        band: qb,
        ..ResonanceOptions::default()
    };
    let unit = plant_unit(a.y_unit.as_deref(), a.u_unit.as_deref());
    match find_resonances_reliable(&res.frf.plant, &opts, 0.1) {
        Ok((peaks, n)) => {
            println!(
                "plant resonance peaks in {:.1}–{:.1} Hz (≥ 3 dB prominence, {n} lines with relative std ≤ 10 %): {} → order estimate ≥ {}",
                qb.0,
                qb.1,
                peaks.len(),
                order_from_peaks(&peaks)
            );
            for p in &peaks {
                match p.damping {
                    Some(z) => println!(
                        "  {:8.2} Hz  |P| {:.3e} {unit}  ζ ≈ {z:.3}",
                        p.f_hz, p.magnitude
                    ),
                    None => println!("  {:8.2} Hz  |P| {:.3e} {unit}", p.f_hz, p.magnitude),
                }
            }
        }
        Err(e) => println!("plant resonance peaks: not searched ({e})"),
    }
    write_analysis(&a.out, res, a.force)?;
    println!("written: {}", a.out.display());
    Ok(())
}

/// Reports the band's lines a local method left out for lack of excitation (`step` apart when
/// consecutive, `df` Hz per line).
fn print_excluded(excluded: &[usize], step: usize, df: f64) {
    if excluded.is_empty() {
        return;
    }
    let ranges = line_ranges(excluded, step);
    let shown: Vec<String> = ranges
        .iter()
        .take(6)
        .map(|(a, b)| format!("{:.1}–{:.1} Hz", *a as f64 * df, *b as f64 * df))
        .collect();
    println!(
        "left out: {} lines of the band where r has less than {} % of its average line power, in {}{}",
        excluded.len(),
        100.0 * ambid_core::frf::lpm::EXCITED_FRACTION,
        shown.join(", "),
        if ranges.len() > 6 { ", …" } else { "" }
    );
}

/// Runs of lines `step` apart as `(first, last)`, bridging gaps of up to 20 steps (so that a
/// ragged excitation edge reads as one range).
fn line_ranges(lines: &[usize], step: usize) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    for &k in lines {
        match out.last_mut() {
            Some(r) if k <= r.1 + 20 * step => r.1 = k,
            _ => out.push((k, k)),
        }
    }
    out
}

/// `ambid frf --method lpm|lrm`: the Local Polynomial or Rational Method on the whole record.
fn frf_local(a: &FrfArgs, r: &[f64], u: &[f64], y: &[f64], fs: f64) -> Result<()> {
    use ambid_core::frf::lpm::{lpm_closed_loop, LpmOptions};
    use ambid_core::frf::lrm::{lrm_closed_loop, LrmOptions};
    let band = a.band.unwrap_or((1.0, 0.5 * fs));
    // with --period-samples: whole periods only (the LPM detects periodic inputs from the line
    // pattern, which needs a whole number of periods)
    let (r, u, y) = match a.period_samples {
        Some(p) if p > 0 => {
            let m = r.len() / p * p;
            if m < 2 * p {
                return Err(ambid::workflow::usage(anyhow::anyhow!(
                    "--period-samples {p}: the record of {} samples holds fewer than two periods",
                    r.len()
                ))
                .into());
            }
            if m < r.len() {
                println!(
                    "--period-samples {p}: using the first {} whole periods ({m} of {} samples)",
                    m / p,
                    r.len()
                );
            }
            (&r[..m], &u[..m], &y[..m])
        }
        _ => (r, u, y),
    };
    // the three FRFs of either local method, and a description
    let (t_ry, t_ru, plant, what) = if a.method == MethodArg::Lrm {
        let [rn, rd, rm] = <[usize; 3]>::try_from(a.lrm_degrees.as_slice()).map_err(|_| {
            anyhow::anyhow!("--lrm-degrees takes three degrees Rn,Rd,Rm, e.g. 2,2,2")
        })?;
        let mut opts = LrmOptions::default().with_degrees(rn, rd, rm)?;
        if let Some(n) = a.lpm_half_width {
            opts = opts.with_half_width(n)?;
        }
        let c = lrm_closed_loop(r, u, y, fs, band, &opts)?;
        let what = format!(
            "LRM: degrees (Rn, Rd, Rm) = ({rn}, {rd}, {rm}), window {} lines, {} degrees of freedom",
            opts.window(),
            c.dof()
        );
        print_excluded(c.fit.excluded_lines(), 1, fs / c.fit.record_len() as f64);
        (c.t_ry, c.t_ru, c.plant, what)
    } else {
        let opts = match (a.lpm_degree, a.lpm_half_width) {
            (None, None) => LpmOptions::auto(),
            (deg, half) => {
                let mut o = LpmOptions::default().with_degree(deg.unwrap_or(2))?;
                if let Some(n) = half {
                    o = o.with_half_width(n)?;
                }
                o
            }
        };
        let c = lpm_closed_loop(r, u, y, fs, band, &opts)?;
        let fit = &c.fit;
        if let Some(p) = a.period_samples.filter(|&p| p > 0) {
            if fit.periods() != Some(r.len() / p) {
                eprintln!(
                    "warning: --period-samples {p} given, but r is not periodic with that period over \
                     the record's {} whole periods (line pattern: {}); the LPM for non-periodic data \
                     was used",
                    r.len() / p,
                    fit.periods()
                        .map_or("no period".to_string(), |q| format!("{q} periods"))
                );
            }
        }
        let what = match fit.periods() {
            Some(p) => format!(
                "LPM for periodic data: r holds {p} periods of {} samples; FRFs on the excited lines \
                 (every {p}-th), transient and noise from the non-excited lines (degree {}, {} lines, \
                 {} degrees of freedom)",
                fit.record_len() / p,
                fit.degree(),
                fit.dof() + fit.degree() + 1,
                fit.dof()
            ),
            None => format!(
                "LPM: degree {}, window {} lines{}, {} degrees of freedom",
                fit.degree(),
                2 * fit.half_width() + 1,
                if fit.window_chosen() {
                    " (chosen from the record by leave-one-out cross-validation)"
                } else {
                    ""
                },
                fit.dof()
            ),
        };
        print_excluded(
            fit.excluded_lines(),
            fit.periods().unwrap_or(1),
            fs / fit.record_len() as f64,
        );
        (c.t_ry, c.t_ru, c.plant, what)
    };
    let f = plant.f_hz().to_vec();
    let qb = a.quality_band.unwrap_or(band);
    println!(
        "{what}, {} lines in {:.1}–{:.1} Hz",
        f.len(),
        f.first().copied().unwrap_or(f64::NAN),
        f.last().copied().unwrap_or(f64::NAN)
    );
    let q: Vec<(f64, f64)> = f
        .iter()
        .zip(plant.values())
        .zip(plant.std().unwrap_or_default())
        .filter(|((f, _), _)| **f >= qb.0 && **f <= qb.1)
        .map(|((_, p), s)| (s / p.norm(), s))
        .collect();
    if !q.is_empty() {
        let mut rel: Vec<f64> = q.iter().map(|x| x.0).collect();
        rel.sort_by(f64::total_cmp);
        println!(
            "plant relative standard deviation over {}–{} Hz: median {:.3e} ({} lines)",
            qb.0,
            qb.1,
            rel[rel.len() / 2],
            rel.len()
        );
    }
    let stds: Vec<Option<Vec<f64>>> = [&t_ry, &t_ru, &plant].iter().map(|x| x.std()).collect();
    let fs_col = vec![fs; f.len()];
    let bytes = frf_csv_bytes(
        &f,
        &[
            FrfColumn {
                name: "t_ry",
                values: t_ry.values(),
                std: stds[0].as_deref(),
            },
            FrfColumn {
                name: "t_ru",
                values: t_ru.values(),
                std: stds[1].as_deref(),
            },
            FrfColumn {
                name: "plant",
                values: plant.values(),
                std: stds[2].as_deref(),
            },
        ],
        &[("fs_hz", &fs_col)],
    )?;
    write_file(&a.out, &bytes, a.force)?;
    println!("written: {}", a.out.display());
    Ok(())
}

#[derive(Subcommand)]
pub enum StudyCmd {
    /// Excitation-amplitude study (the seed's figure 6): coherence, FRF variance and output SNR
    /// per level, and a recommended range.
    Amplitude(AmplitudeArgs),
    /// Operating-point study (the seed's figure 7): plant FRFs at nominal, bias ±20 % and air gap
    /// ±10 µm, with the deviation from nominal per band.
    OperatingPoint(OperatingPointArgs),
}

#[derive(Args)]
pub struct AmplitudeArgs {
    /// PRBS levels in % of i_sat, peak (= RMS for a PRBS), comma-separated (`2,4,8` or
    /// `2%,4%,8%`).
    #[arg(long, value_delimiter = ',', value_parser = crate::cli_args::parse_pct,
          default_values_t = seed_levels().iter().map(|l| crate::cli_args::clean(100.0 * l)).collect::<Vec<f64>>())]
    levels: Vec<f64>,
    /// Recorded files instead of the twin, one per level (same order as --levels), with columns
    /// r, u, y.
    #[arg(long, value_delimiter = ',')]
    files: Vec<PathBuf>,
    /// Noise-only file (files mode) for the output SNR.
    #[arg(long)]
    noise: Option<PathBuf>,
    /// Sample rate for files without a `t` column.
    #[arg(long)]
    fs: Option<f64>,
    /// Samples per excitation period (files mode; the twin uses its PRBS period).
    #[arg(long, default_value_t = 5115)]
    period_samples: usize,
    /// PRBS periods per level (twin mode; the seed used 50).
    #[arg(long, default_value_t = 20)]
    periods: usize,
    /// Leading periods dropped.
    #[arg(long, default_value_t = 1)]
    skip_periods: usize,
    /// Twin mode.
    #[arg(long, value_enum, default_value_t = crate::ModeArg::Nonlinear)]
    mode: crate::ModeArg,
    /// Twin configuration (TOML).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Noise seed (twin mode).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Band of the FRFs and of the averages, Hz (default: on the twin the seed paper's 10–1000
    /// Hz; with --files derived from the excitation, the lines within 10 dB of its strongest for
    /// the FRF and 3 dB for the averages; docs/frf.md).
    #[arg(long, value_parser = parse_band)]
    band: Option<(f64, f64)>,
    /// Output CSV of the figures.
    #[arg(long, default_value = "amplitude_study.csv")]
    out: PathBuf,
    /// Replace the output file if it exists.
    #[arg(long)]
    force: bool,
}

#[derive(Args)]
pub struct OperatingPointArgs {
    /// Twin mode.
    #[arg(long, value_enum, default_value_t = crate::ModeArg::Nonlinear)]
    mode: crate::ModeArg,
    /// Twin configuration (TOML) of the nominal point.
    #[arg(long)]
    config: Option<PathBuf>,
    /// PRBS level in % of i_sat, peak (`10` or `10%`).
    #[arg(long, value_parser = crate::cli_args::parse_pct, default_value = "10")]
    level: f64,
    /// Deprecated: the level as a fraction of i_sat (0.1 = 10 %); write `--level 10`.
    #[arg(
        long,
        hide = true,
        conflicts_with = "level",
        allow_negative_numbers = true
    )]
    amplitude: Option<f64>,
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Band of the FRFs, Hz (default 10–2000 Hz, the seed's: the excitation's own band reaches
    /// ≈ 3 kHz, where the twin's plant is below the sensor noise).
    #[arg(long, value_parser = parse_band)]
    band: Option<(f64, f64)>,
    /// Output CSV of the deviations per case and band.
    #[arg(long, default_value = "operating_point_study.csv")]
    out: PathBuf,
    /// Output CSV of the plant FRF magnitudes of all cases (f_hz, then |P| and phase per case).
    #[arg(long, default_value = "operating_point_frf.csv")]
    frf_out: PathBuf,
    /// Replace the output files if they exist.
    #[arg(long)]
    force: bool,
}

fn load_config(p: &Option<PathBuf>) -> Result<TwinConfig> {
    match p {
        Some(p) => {
            let s = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            Ok(TwinConfig::from_toml_str(&s).with_context(|| format!("in {}", p.display()))?)
        }
        None => Ok(TwinConfig::default()),
    }
}

fn rows_csv<T: serde::Serialize>(rows: &[T]) -> Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in rows {
        w.serialize(r)?;
    }
    w.into_inner().map_err(|e| anyhow::anyhow!("{}", e.error()))
}

pub fn study(cmd: StudyCmd) -> Result<()> {
    match cmd {
        StudyCmd::Amplitude(a) => amplitude(a),
        StudyCmd::OperatingPoint(a) => operating_point(a),
    }
}

fn mode(m: crate::ModeArg) -> Mode {
    match m {
        crate::ModeArg::Linear => Mode::Linear,
        crate::ModeArg::Nonlinear => Mode::Nonlinear,
    }
}

fn amplitude(a: AmplitudeArgs) -> Result<()> {
    OutputSet::check(&a.out, a.force)?;
    if let Some(l) = a
        .levels
        .iter()
        .find(|l| !(l.is_finite() && **l > 0.0 && **l <= 100.0))
    {
        return Err(ambid::workflow::usage(anyhow::anyhow!(
            "--levels must be in (0, 100] % of i_sat, got {l:e}"
        ))
        .into());
    }
    let out = if a.files.is_empty() {
        let study = TwinAmplitudeStudy {
            twin: load_config(&a.config)?,
            excitation: ExcitationPlan {
                periods: a.periods,
                ..ExcitationPlan::default()
            },
            levels: a.levels.iter().map(|l| l / 100.0).collect(),
            mode: mode(a.mode),
            seed: a.seed,
            skip_periods: a.skip_periods,
            band: a.band.or(Some(ambid_core::frf::quality::DEFAULT_BAND)),
            noise: true,
        };
        amplitude_on_twin(&study)?
    } else {
        if a.files.len() != a.levels.len() {
            return Err(ambid::workflow::usage(anyhow::anyhow!(
                "{} files for {} levels: pass one file per level, in the order of --levels",
                a.files.len(),
                a.levels.len()
            ))
            .into());
        }
        let mut records = Vec::new();
        let mut fs = None;
        for (p, l) in a.files.iter().zip(&a.levels) {
            let d = read_time_csv(p, a.fs)?;
            fs = Some(1.0 / d.ts);
            records.push(LevelRecord {
                level: l / 100.0,
                r: d.column("r")?.to_vec(),
                u: d.column("u")?.to_vec(),
                y: d.column("y")?.to_vec(),
                i: d.optional_column("i")?.map(<[f64]>::to_vec),
                saturated_fraction: None,
            });
        }
        let fs = fs.context("no file")?;
        let noise = match &a.noise {
            Some(p) => Some(read_time_csv(p, Some(fs))?.column("y")?.to_vec()),
            None => None,
        };
        let mut settings = FrfSettings::periodic(a.period_samples, a.skip_periods);
        settings.band = a.band;
        settings.quality_band = a.band;
        amplitude_from_records(
            &records,
            fs,
            noise.as_deref(),
            &settings,
            None,
            Recommendation::default(),
        )?
    };
    println!(
        "{:>7} {:>9} {:>9} {:>12} {:>12} {:>9} {:>9}",
        "level %", "coh_ry", "coh_ru", "FRF var", "rel var", "SNR dB", "sat %"
    );
    for r in &out.rows {
        println!(
            "{:7.1} {:9.4} {:9.4} {:12.4e} {:12.4e} {:>9} {:9.3}",
            r.level_pct,
            r.mean_coh_ry,
            r.mean_coh_ru,
            r.mean_plant_var,
            r.mean_plant_rel_var,
            r.snr_db.map_or("-".into(), |s| format!("{s:.2}")),
            100.0 * r.saturated_fraction
        );
    }
    match out.recommended_pct {
        Some((lo, hi)) => {
            let (lo, hi) = (crate::cli_args::clean(lo), crate::cli_args::clean(hi));
            if lo == hi {
                println!("recommended excitation: {lo} % of i_sat (peak)");
            } else {
                println!("recommended excitation: {lo}–{hi} % of i_sat (peak)");
            }
        }
        None => println!("no level recommended"),
    }
    println!("({})", out.reasoning);
    write_file(&a.out, &rows_csv(&out.rows)?, a.force)?;
    println!("written: {}", a.out.display());
    Ok(())
}

fn operating_point(a: OperatingPointArgs) -> Result<()> {
    OutputSet::check(&a.out, a.force)?;
    OutputSet::check(&a.frf_out, a.force)?;
    let nominal = load_config(&a.config)?;
    let cases = seed_cases(&nominal);
    let out = operating_point_on_twin(
        &nominal,
        &cases,
        &ExcitationPlan {
            amplitude_frac: crate::level_frac(a.level, a.amplitude)?,
            ..ExcitationPlan::default()
        },
        mode(a.mode),
        a.seed,
        1,
        Some(a.band.unwrap_or((10.0, 2000.0))),
    )?;
    println!(
        "{:>10} {:>10} {:>14} {:>14} {:>10}",
        "case", "band", "median dev %", "true dev %", "max dB"
    );
    for d in &out.deviations {
        println!(
            "{:>10} {:>10} {:14.2} {:>14} {:10.2}",
            d.case,
            d.band,
            100.0 * d.median_rel_dev,
            d.truth_median_rel_dev
                .map_or("-".into(), |t| format!("{:.2}", 100.0 * t)),
            d.max_abs_db_dev
        );
    }
    let mut set = OutputSet::new(a.force);
    set.write(&a.out, &rows_csv(&out.deviations)?)?;
    // overlay file
    let mut w = csv::Writer::from_writer(Vec::new());
    let mut header = vec!["f_hz".to_string()];
    for c in &out.cases {
        header.push(format!("{}_mag", c.name));
        header.push(format!("{}_phase_deg", c.name));
    }
    w.write_record(&header)?;
    let f = out.plants[0].f_hz();
    for (k, fk) in f.iter().enumerate() {
        let mut row = vec![format!("{fk:.17e}")];
        for p in &out.plants {
            row.push(format!("{:.17e}", p.values()[k].norm()));
            row.push(format!("{:.17e}", p.values()[k].arg().to_degrees()));
        }
        w.write_record(&row)?;
    }
    let overlay = w
        .into_inner()
        .map_err(|e| anyhow::anyhow!("{}", e.error()))?;
    set.write(&a.frf_out, &overlay)?;
    set.commit()?;
    println!("written: {}, {}", a.out.display(), a.frf_out.display());
    Ok(())
}
