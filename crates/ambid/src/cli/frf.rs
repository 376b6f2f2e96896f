//! `ambid frf` and `ambid study`: argument parsing and file output over `ambid::analysis` and
//! `ambid::study`.

use super::args::{
    BandArg, CurrentColumn, DataFileArgs, ExcitationColumn, Force, InputColumn, OutputColumn,
};
use super::common::plant_unit;
use ambid::analysis::{analyze, FrfAnalysis, FrfMethod, FrfSettings, Record};
use ambid::frf_stream::{analyze_csv, StreamColumns};
use ambid::io::output::write_file;
use ambid::io::table::Format;
use ambid::io::{frf_csv_bytes, read_controller, FrfColumn, OutputSet};
use ambid_core::frf::window::Window;
use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use std::path::{Path, PathBuf};

use super::args::parse_band;

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
#[command(mut_arg("band", |a| a.help("Band of the written FRF, Hz (f_min:f_max; default: derived from the excitation, the lines within 10 dB of its strongest, carried on over a design slope; docs/frf.md)")))]
#[command(mut_arg("input", |a| a.help("Column of the controller output u (including r)")))]
pub struct FrfArgs {
    /// Time-data file (CSV with a header row and an optional `t` column in seconds, or .npy,
    /// .npz, .mat, .parquet; docs/data-files.md). Several files, or one file with columns
    /// `r_xa … r_yb`, `u_…`, `y_…`: the experiments of a multi-axis (MIMO) FRF, written as a
    /// matrix FRF CSV (docs/formats.md, "Matrix FRF").
    #[arg(required = true, num_args = 1..)]
    pub(crate) files: Vec<PathBuf>,
    /// The single-axis data file (`files[0]`).
    #[arg(skip)]
    data: PathBuf,
    /// Axes of a multi-axis FRF: any N > 1 takes the MIMO path on one file (several files
    /// always do); 1 forces the single-axis path (default: from the files, see docs/frf.md).
    #[arg(long)]
    pub(crate) axes: Option<u8>,
    /// Multi-axis FRF: the rotor speed, rpm. The speed-synchronous (1×) line at speed/60 Hz is
    /// measured on every u and y channel, written beside the FRF (`<out>` with `_sync` before
    /// the extension) and taken out of u and y before the FRF is estimated, so that it is
    /// reported, not fitted (docs/frf.md).
    #[arg(long)]
    pub(crate) speed_rpm: Option<f64>,
    #[command(flatten)]
    pub(crate) file: DataFileArgs,
    #[command(flatten)]
    pub(crate) r: ExcitationColumn,
    #[command(flatten)]
    pub(crate) u: InputColumn,
    #[command(flatten)]
    pub(crate) y: OutputColumn,
    #[command(flatten)]
    pub(crate) cur: CurrentColumn,
    /// Controller file (TOML/JSON: pid, tf or ss) for the indirect plant estimate.
    #[arg(long)]
    pub(crate) controller: Option<PathBuf>,
    /// Samples per excitation period: selects period-synchronous averaging (default: found in
    /// the file, the smallest lag at which `r` repeats exactly; Welch when it does not repeat);
    /// with `--method lpm|lrm`, cuts the record to whole periods.
    #[arg(long)]
    pub(crate) period_samples: Option<usize>,
    /// Leading periods dropped as transient (period averaging).
    #[arg(long, default_value_t = 1)]
    pub(crate) skip_periods: usize,
    /// Welch segment length in samples (default: 1/8 of the record, at least 256).
    #[arg(long)]
    pub(crate) nperseg: Option<usize>,
    /// Welch overlap in samples (default: half a segment).
    #[arg(long)]
    pub(crate) noverlap: Option<usize>,
    /// Welch window (default: Hann).
    #[arg(long, value_enum)]
    pub(crate) window: Option<WindowArg>,
    /// Leading samples dropped as transient (Welch).
    #[arg(long, default_value_t = 0)]
    pub(crate) skip_samples: usize,
    #[command(flatten)]
    pub(crate) b: BandArg,
    /// Band of the quality averages and the resonance search, Hz (default: derived from the
    /// excitation, where it is within 3 dB of its strongest line).
    #[arg(long, value_parser = parse_band)]
    pub(crate) quality_band: Option<(f64, f64)>,
    /// Unit of the output column (for printed magnitudes; default: not given).
    #[arg(long)]
    pub(crate) y_unit: Option<String>,
    /// Unit of the input column (for printed magnitudes; default: not given).
    #[arg(long)]
    pub(crate) u_unit: Option<String>,
    /// Saturation current of u and i in A (otherwise flat tops are looked for).
    #[arg(long)]
    pub(crate) i_sat: Option<f64>,
    /// Time-data CSV recorded without excitation under the same loop: output SNR.
    #[arg(long)]
    pub(crate) noise: Option<PathBuf>,
    /// Do not screen for NaN/Inf, spikes and stuck samples.
    #[arg(long)]
    pub(crate) no_screen: bool,
    /// Estimator: `auto` (period averaging with --period-samples or when `r` repeats itself at
    /// least twice after --skip-periods, else Welch; any Welch option selects Welch), `welch`
    /// (Welch averaging in any case), `lpm` (the Local
    /// Polynomial Method on one non-periodic record: T_ry, S and the plant with their
    /// variances, leakage and transients removed; no coherence) or `lrm` (the Local Rational
    /// Method: like `lpm`, better on lightly damped modes narrower than the window).
    #[arg(long, value_enum, default_value_t = MethodArg::Auto)]
    pub(crate) method: MethodArg,
    /// LPM: polynomial degree R (default: R and the window chosen from the record by
    /// leave-one-out cross-validation, see docs/lpm.md; 2 when only --lpm-half-width is given).
    #[arg(long)]
    pub(crate) lpm_degree: Option<usize>,
    /// LRM: degrees of numerator, denominator and transient, `Rn,Rd,Rm`.
    #[arg(long, value_delimiter = ',', default_values_t = [2usize, 2, 2])]
    pub(crate) lrm_degrees: Vec<usize>,
    /// LPM/LRM: half width n of the local window (2n + 1 lines); default: chosen from the record
    /// (LPM, see --lpm-degree), the smallest window with 5 degrees of freedom (LRM).
    #[arg(long, alias = "half-width")]
    pub(crate) lpm_half_width: Option<usize>,
    /// Output FRF CSV.
    #[arg(long, default_value = "frf.csv")]
    pub(crate) out: PathBuf,
    #[command(flatten)]
    pub(crate) f: Force,
}

/// FRF estimator choice.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// Period averaging (with --period-samples, or the period found in `r`) or Welch.
    Auto,
    /// Welch averaging, even of a periodic record.
    Welch,
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
    let mut extra: Vec<(&str, &[f64])> = vec![("coh_ry", &frf.coh_ry), ("coh_ru", &frf.coh_ru)];
    // the plant's noise as a function of the plant value, for fits weighted by the variance at
    // the model (`ambid fit --weights model`, `ambid uncertainty`): periodic estimates only
    // (`FrfAnalysis::model_weight_noise`)
    let noise: Option<[Vec<f64>; 4]> = a.model_weight_noise().map(|n| {
        [
            n.iter().map(|x| x.a).collect(),
            n.iter().map(|x| x.b).collect(),
            n.iter().map(|x| x.c.re).collect(),
            n.iter().map(|x| x.c.im).collect(),
        ]
    });
    if let Some([a, b, cr, ci]) = &noise {
        extra.extend([
            ("plant_noise_a", a.as_slice()),
            ("plant_noise_b", b.as_slice()),
            ("plant_noise_c_re", cr.as_slice()),
            ("plant_noise_c_im", ci.as_slice()),
        ]);
    }
    extra.push(("fs_hz", &fs));
    let bytes = frf_csv_bytes(frf.f_hz(), &q, &extra)?;
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

pub fn frf(mut a: FrfArgs) -> Result<()> {
    if super::frf4::is_mimo(&a)? {
        return super::frf4::frf4(&a);
    }
    a.data = a.files[0].clone();
    OutputSet::check(&a.out, a.f.force)?;
    // one reader for every format; a text record with Welch or period averaging is streamed
    // (the same arithmetic in bounded memory, frf_stream), everything else is read whole
    let streamable = Format::of_file(&a.data, a.file.file.format)? == Format::Text
        && a.file.file.time.is_none()
        && a.file.file.from.is_none()
        && a.file.file.to.is_none()
        && [&a.r.excitation, &a.u.input, &a.y.output, &a.cur.current]
            .iter()
            .all(|c| !c.starts_with('#'));
    let res = if matches!(a.method, MethodArg::Auto | MethodArg::Welch)
        && a.noise.is_none()
        && streamable
    {
        // Welch and period averaging stream the file: memory for one block, segment or period
        let cols = StreamColumns {
            r: &a.r.excitation,
            u: &a.u.input,
            y: &a.y.output,
            i: Some(&a.cur.current),
        };
        analyze_csv(
            &a.data,
            &cols,
            a.file.fs,
            looks_for_period(&a),
            |n, ts, period| frf_settings(&a, n, ts, period),
        )?
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
    // only the four columns (TDMS and MAT v7.3 files read nothing else)
    let data = a.file.file.read_columns(
        &a.data,
        a.file.fs,
        &[&a.r.excitation, &a.u.input, &a.y.output, &a.cur.current],
    )?;
    ambid::analysis::check_fs_matches(a.file.fs, data.ts)?;
    // missing samples are kept for the screening; without it every sample must be a number
    let col = |name: &str| {
        if a.no_screen {
            data.column(name)
        } else {
            data.column_raw(name)
        }
    };
    let r = col(&a.r.excitation)?;
    let u = col(&a.u.input)?;
    let y = col(&a.y.output)?;
    let i = data.column_raw(&a.cur.current).ok();
    let fs = 1.0 / data.ts;
    if matches!(a.method, MethodArg::Lpm | MethodArg::Lrm) {
        frf_local(a, r, u, y, fs)?;
        return Ok(None);
    }
    let found = looks_for_period(a)
        .then(|| ambid_core::signal::PeriodScan::of(r))
        .flatten();
    let settings = frf_settings(a, r.len(), data.ts, found)?;
    let noise = match &a.noise {
        Some(p) => {
            let d = a.file.file.read(p, a.file.fs.or(Some(fs)))?;
            Some(d.column_raw(&a.y.output)?.to_vec())
        }
        None => None,
    };
    let rec = Record { r, u, y, i, fs };
    Ok(Some(
        analyze(&rec, &settings, noise.as_deref())
            .with_context(|| format!("{}", a.data.display()))?,
    ))
}

/// A Welch option of `a` (`--nperseg`, `--noverlap`, `--window`, `--skip-samples`).
pub(crate) fn welch_options(a: &FrfArgs) -> bool {
    a.nperseg.is_some() || a.noverlap.is_some() || a.window.is_some() || a.skip_samples != 0
}

/// Whether the estimator of `a` depends on the period of `r`: `--method auto` with neither
/// `--period-samples` nor a Welch option.
fn looks_for_period(a: &FrfArgs) -> bool {
    a.method == MethodArg::Auto && a.period_samples.is_none() && !welch_options(a)
}

/// The settings of `a` for a record of `n` samples at sample time `ts` whose `r` repeats every
/// `found` samples (reads the controller). The estimator of `--method auto`: period averaging
/// with `--period-samples`; else Welch when a Welch option is given; else period averaging
/// with the found period when at least two periods remain after `--skip-periods`; else Welch.
fn frf_settings(
    a: &FrfArgs,
    n: usize,
    ts: f64,
    found: Option<usize>,
) -> ambid::error::Result<FrfSettings> {
    if let Some(k) = a.nperseg.filter(|&k| k > n) {
        return Err(ambid::error::Error::usage(format!(
            "--nperseg {k} is longer than the record ({n} samples); give at most {n}, or leave it out to derive it from the record length"
        )));
    }
    if a.method == MethodArg::Welch && a.period_samples.is_some() {
        return Err(ambid::error::Error::usage(
            "--method welch and --period-samples exclude each other: leave out --period-samples \
             for Welch averaging, or --method welch for period averaging",
        ));
    }
    if a.period_samples.is_some() && welch_options(a) {
        return Err(ambid::error::Error::usage(
            "--nperseg/--noverlap/--window/--skip-samples set Welch averaging, --period-samples \
             period averaging: give one of them",
        ));
    }
    let detected = match found.filter(|_| looks_for_period(a)) {
        Some(p) => {
            let periods = n / p;
            let chosen = FrfSettings::found_period(n, Some(p), a.skip_periods);
            if chosen.is_some() {
                let tail = match n % p {
                    0 => String::new(),
                    t => format!(", the last {t} samples, an incomplete period, ignored"),
                };
                println!(
                    "period averaging: the excitation repeats every {p} samples ({periods} \
                     periods, {} dropped as transient{tail}); give --method welch for Welch \
                     averaging",
                    a.skip_periods
                );
            } else {
                println!(
                    "the excitation repeats every {p} samples, but {periods} periods leave fewer \
                     than 2 after --skip-periods {}: Welch averaging",
                    a.skip_periods
                );
            }
            chosen.map(|_| p)
        }
        None => None,
    };
    let method = match a.period_samples.or(detected) {
        Some(p) => FrfMethod::Periodic {
            period_samples: p,
            skip_periods: a.skip_periods,
        },
        None => FrfMethod::Welch {
            nperseg: a.nperseg.unwrap_or_else(|| FrfSettings::default_nperseg(n)),
            noverlap: a.noverlap,
            window: a.window.unwrap_or(WindowArg::Hann).into(),
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
        band: a.b.band,
        quality_band: a.quality_band,
        band_rule: Default::default(),
        rel_threshold: 1e-6,
        controller,
        i_sat: a.i_sat,
        screen: !a.no_screen,
        // a found period need not divide the record (a cut or split file): the tail is dropped
        incomplete_tail: detected.is_some(),
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
        } => {
            println!(
                "Welch: {segments} segments ({effective:.1} effective averages), {} bins",
                res.frf.f_hz().len()
            );
            println!(
                "Welch: the standard deviations hold the noise, not the leakage bias at lightly \
                 damped modes nor the correlation of neighbouring lines (about 0.4 with Hann); \
                 `ambid uncertainty` allows for the correlation, and its weight on Welch FRFs \
                 covered the truth on 96 of 100 unseen rigs of each twin, at the 95 % of runs \
                 issue 23 asks and not above (docs/uncertainty.md, \"Welch FRFs on unseen \
                 rigs\"); periodic excitation avoids both"
            );
        }
    }
    println!("bands: {}", res.bands.describe());
    print_quality(res);
    // resonance peaks of the plant in the quality band, on lines whose relative standard
    // deviation is below 10 % (noise ripple must not count as a mode): the order stage's search
    let scan = ambid::stage::resonance_scan(res);
    let qb = scan.band;
    let unit = plant_unit(a.y_unit.as_deref(), a.u_unit.as_deref());
    match &scan.error {
        None => {
            println!(
                "plant resonance peaks in {:.1}–{:.1} Hz (≥ 3 dB prominence, {} lines with relative std ≤ 10 %): {} → order estimate ≥ {}",
                qb.0,
                qb.1,
                scan.searched,
                scan.peaks.len(),
                scan.order
            );
            for p in &scan.peaks {
                match p.damping {
                    Some(z) => println!(
                        "  {:8.2} Hz  |P| {:.3e} {unit}  ζ ≈ {z:.3}",
                        p.f_hz, p.magnitude
                    ),
                    None => println!("  {:8.2} Hz  |P| {:.3e} {unit}", p.f_hz, p.magnitude),
                }
            }
        }
        Some(e) => println!("plant resonance peaks: not searched ({e})"),
    }
    write_analysis(&a.out, res, a.f.force)?;
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
    let band = a.b.band.unwrap_or((1.0, 0.5 * fs));
    // with --period-samples: whole periods only (the LPM detects periodic inputs from the line
    // pattern, which needs a whole number of periods)
    let (r, u, y) = match a.period_samples {
        Some(p) if p > 0 => {
            let m = r.len() / p * p;
            if m < 2 * p {
                return Err(ambid::error::Error::usage(format!(
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
    write_file(&a.out, &bytes, a.f.force)?;
    println!("written: {}", a.out.display());
    Ok(())
}
