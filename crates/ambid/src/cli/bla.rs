//! `ambid bla`: the robust Best Linear Approximation of the plant, on the twin or from recorded
//! realisations (`--record PCT:PATH`, repeated) — an amplitude study (noise and nonlinear
//! variance per RMS level and the recommended level) or, with `--level` (twin) or a single
//! recorded level, the per-line BLA.

use super::args::{BandArg, DataFileArgs, ExcitationColumn, Force, InputColumn, OutputColumn};
use ambid::bla::{
    amplitude_study, amplitude_study_from_records, bla_of_level, figures_of, level_figures,
    run_level, BlaPlan, BlaStudy, Realisation, RecordedLevel, RecordedPlan,
};
use ambid_core::data::{check_saturation, SaturationOptions};
use ambid_core::frf::bla::Bla;
use ambid_twin::Mode;
use anyhow::{Context, Result};
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;

/// Parses `PCT:PATH` (a level in % of i_sat and a recorded realisation).
fn parse_record(s: &str) -> std::result::Result<(f64, PathBuf), String> {
    let (l, p) = s.split_once(':').ok_or_else(|| {
        format!("`{s}`: give a recorded realisation as LEVEL_PCT:PATH, e.g. 4:bla04_m1.csv")
    })?;
    let level = super::args::parse_pct(l).map_err(|e| format!("{e} (in `{s}`)"))?;
    if p.is_empty() {
        return Err(format!("`{s}`: the path is empty"));
    }
    Ok((level, PathBuf::from(p)))
}

#[derive(Args)]
#[command(mut_arg("fs", |a| a.help("Recorded data: sample rate in Hz (when the files have no `t` column)")))]
#[command(mut_arg("excitation", |a| a.help("Recorded data: column of the excitation r (closed loop); `none` for open-loop data (u is then the excitation). Names, or `#k` for the k-th column")))]
#[command(mut_arg("input", |a| a.help("Recorded data: column of the plant input u")))]
#[command(mut_arg("output", |a| a.help("Recorded data: column of the plant output y")))]
#[command(mut_arg("band", |a| a.help("Band of the study's averages, Hz (default 20–1000 on the twin, 10–1000 on files)")))]
pub struct BlaArgs {
    /// RMS levels of the study in % of i_sat (ignored with --level).
    #[arg(long, value_delimiter = ',', default_value = "2,4,8,16,32", value_parser = super::args::parse_pct)]
    levels: Vec<f64>,
    /// One RMS level in % of i_sat (`8` or `8%`): write the per-line BLA (value, std, noise
    /// std, NL std).
    #[arg(long, value_parser = super::args::parse_pct)]
    level: Option<f64>,
    /// Random-phase multisine realisations M (≥ 2).
    #[arg(long, default_value_t = 8)]
    realisations: usize,
    /// Analysed periods per realisation P (≥ 2; one more settles the transient).
    #[arg(long, default_value_t = 4)]
    periods: usize,
    /// Twin physics.
    #[arg(long, value_enum, default_value_t = super::common::ModeArg::Nonlinear)]
    mode: super::common::ModeArg,
    /// Seed of the grid, the phases and the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// A recorded realisation instead of the twin, as LEVEL_PCT:PATH (repeat it: M ≥ 2 per
    /// level, each a random-phase multisine over a whole number of periods; CSV/text, .npy,
    /// .npz or .mat). With one level the per-line BLA is written, with several the study.
    #[arg(long = "record", value_parser = parse_record, value_name = "PCT:PATH")]
    records: Vec<(f64, PathBuf)>,
    /// Recorded data: samples per multisine period.
    #[arg(long)]
    period_samples: Option<usize>,
    /// Recorded data: leading periods dropped as transient.
    #[arg(long, default_value_t = 1)]
    skip_periods: usize,
    #[command(flatten)]
    file: DataFileArgs,
    #[command(flatten)]
    r: ExcitationColumn,
    #[command(flatten)]
    u: InputColumn,
    #[command(flatten)]
    y: OutputColumn,
    /// Recorded data: saturation current in A; u (and the column `i`, if present) are checked
    /// against it and levels clipping on more than 1 % of the samples are not recommended.
    #[arg(long)]
    i_sat: Option<f64>,
    #[command(flatten)]
    b: BandArg,
    /// Output CSV.
    #[arg(long, default_value = "bla.csv")]
    out: PathBuf,
    #[command(flatten)]
    f: Force,
}

/// Reads the recorded realisations, grouped by level (ascending).
fn recorded_levels(a: &BlaArgs) -> Result<(Vec<RecordedLevel>, f64)> {
    let mut tagged = Vec::with_capacity(a.records.len());
    let mut fs: Option<f64> = None;
    let none = a.r.excitation.eq_ignore_ascii_case("none");
    for (level, path) in &a.records {
        let t = a.file.read(path)?;
        t.check_fs(a.file.fs)?;
        let ts = t.ts;
        match fs {
            None => fs = Some(1.0 / ts),
            Some(f) if (f * ts - 1.0).abs() > 1e-6 => return Err(ambid::error::Error::input(format!(
                "{}: sampled at {} Hz, the first realisation at {f} Hz; all realisations must share the \
                 sample rate",
                path.display(),
                1.0 / ts
            )).into()),
            Some(_) => {}
        }
        let col = |name: &str| -> Result<Vec<f64>> { Ok(t.column_raw(name)?.to_vec()) };
        let u = col(&a.u.input)?;
        let saturated_fraction = match a.i_sat {
            Some(lim) => {
                let mut frac = check_saturation(&u, Some(lim), &SaturationOptions::default())
                    .with_context(|| format!("{}: saturation check of u", path.display()))?
                    .fraction;
                if let Ok(i) = t.column_raw("i") {
                    frac = frac.max(
                        check_saturation(i, Some(lim), &SaturationOptions::default())
                            .with_context(|| format!("{}: saturation check of i", path.display()))?
                            .fraction,
                    );
                }
                Some(frac)
            }
            None => None,
        };
        let x = Realisation {
            r: if none {
                None
            } else {
                Some(col(&a.r.excitation)?)
            },
            u,
            y: col(&a.y.output)?,
            saturated_fraction,
            source: path.display().to_string(),
        };
        tagged.push((*level, x));
    }
    let fs = fs.context("no recorded realisation")?;
    Ok((RecordedLevel::group(tagged), fs))
}

pub fn bla(a: BlaArgs) -> Result<()> {
    ambid::io::OutputSet::check(&a.out, a.f.force)?;
    if !a.records.is_empty() {
        return bla_from_files(&a);
    }
    let mut plan = BlaPlan {
        mode: match a.mode {
            super::common::ModeArg::Linear => Mode::Linear,
            super::common::ModeArg::Nonlinear => Mode::Nonlinear,
        },
        realisations: a.realisations,
        periods: a.periods,
        seed: a.seed,
        ..BlaPlan::default()
    };
    if let Some(b) = a.b.band {
        plan.summary_band_hz = b;
    }
    if let Some(level) = a.level {
        let run = run_level(&plan, level / 100.0)?;
        let f = level_figures(&run, level / 100.0, plan.summary_band_hz)?;
        let csv = per_line_csv(&run.bla)?;
        print_level(&f, plan.summary_band_hz, run.bla.g.f_hz.len());
        write(&a.out, &csv, a.f.force)
    } else {
        let levels: Vec<f64> = a.levels.iter().map(|l| l / 100.0).collect();
        let s = amplitude_study(&plan, &levels)?;
        write(&a.out, &study_csv(&s)?, a.f.force)
    }
}

fn bla_from_files(a: &BlaArgs) -> Result<()> {
    let (levels, fs) = recorded_levels(a)?;
    let n = match a.period_samples {
        Some(n) => n,
        None => {
            let n = ambid::bla::common_period(&levels).map_err(|e| {
                ambid::error::Error::usage(format!(
                    "recorded BLA realisations need the multisine period, and it is not found in \
                     the records ({e}): pass --period-samples N"
                ))
            })?;
            println!(
                "period: {n} samples (every realisation's excitation repeats every {n} samples; \
                 give --period-samples to override)"
            );
            n
        }
    };
    let plan = RecordedPlan {
        fs,
        period_samples: n,
        skip_periods: a.skip_periods,
        summary_band_hz: a.b.band.unwrap_or((10.0, 1000.0)),
    };
    if let [level] = levels.as_slice() {
        let bla = bla_of_level(level, &plan)?;
        let sat = level
            .realisations
            .iter()
            .filter_map(|x| x.saturated_fraction)
            .fold(0.0, f64::max);
        let f = figures_of(&bla, level.level_pct, plan.summary_band_hz, sat, None)?;
        print_level(&f, plan.summary_band_hz, bla.g.f_hz.len());
        write(&a.out, &per_line_csv(&bla)?, a.f.force)
    } else {
        let s = amplitude_study_from_records(&levels, &plan)?;
        write(&a.out, &study_csv(&s)?, a.f.force)
    }
}

fn write(path: &std::path::Path, csv: &str, force: bool) -> Result<()> {
    ambid::io::output::write_file(path, csv.as_bytes(), force)?;
    println!("wrote {}", path.display());
    Ok(())
}

fn per_line_csv(bla: &Bla) -> Result<String> {
    let g = &bla.g;
    let mut csv =
        String::from("f_hz,bla_re,bla_im,bla_std,noise_std,nl_std,var_nl,realisations,periods\n");
    let (st, sn, snl) = (g.std_total(), g.std_noise(), g.std_nl());
    for i in 0..g.f_hz.len() {
        writeln!(
            csv,
            "{},{:e},{:e},{:e},{:e},{:e},{:e},{},{}",
            g.f_hz[i],
            g.values[i].re,
            g.values[i].im,
            st[i],
            sn[i],
            snl[i],
            g.var_nl[i],
            g.realisations,
            g.periods
        )?;
    }
    Ok(csv)
}

fn print_level(f: &ambid::bla::LevelBla, band: (f64, f64), lines: usize) {
    println!(
        "BLA at {} % of i_sat RMS, M = {}, P = {}: {lines} lines; over {}–{} Hz noise {:.2e}, NL {:.2e} ± {:.1e} \
         (relative, one realisation); detection lines: even {:.1} dB, odd {:.1} dB over noise; limits active on {:.2} % of samples",
        f.level_pct,
        f.realisations,
        f.periods,
        ambid::report::format_number(band.0),
        ambid::report::format_number(band.1),
        f.noise_rel,
        f.nl_rel,
        f.nl_rel_se,
        f.even_db,
        f.odd_db,
        100.0 * f.saturated_fraction
    );
}

fn study_csv(s: &BlaStudy) -> Result<String> {
    let mut csv = String::from(
        "level_pct,realisations,periods,lines,noise_rel,nl_rel,nl_rel_se,sum_rel,even_db,odd_db,bla_vs_linear_rel,saturated_fraction,recommended\n",
    );
    for r in &s.rows {
        writeln!(
            csv,
            "{},{},{},{},{:e},{:e},{:e},{:e},{:.2},{:.2},{},{:e},{}",
            r.level_pct,
            r.realisations,
            r.periods,
            r.lines,
            r.noise_rel,
            r.nl_rel,
            r.nl_rel_se,
            r.sum_rel,
            r.even_db,
            r.odd_db,
            r.bla_vs_linear_rel
                .map_or(String::new(), |e| format!("{e:e}")),
            r.saturated_fraction,
            u8::from(r.level_pct == s.recommended_pct)
        )?;
        println!(
            "{:5.1} %: noise {:.2e}, NL {:.2e} ± {:.1e}, sum {:.2e}, even {:.1} dB, odd {:.1} dB",
            r.level_pct, r.noise_rel, r.nl_rel, r.nl_rel_se, r.sum_rel, r.even_db, r.odd_db
        );
    }
    println!("recommended {:.1} %: {}", s.recommended_pct, s.reasoning);
    Ok(csv)
}
