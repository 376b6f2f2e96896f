//! `ambid study`: the seed paper's amplitude and operating-point studies.

use ambid::analysis::FrfSettings;
use ambid::experiment::ExcitationPlan;
use ambid::io::output::write_file;
use ambid::io::OutputSet;
use ambid::study::{
    amplitude_from_records, amplitude_on_twin, operating_point_on_twin, seed_cases, seed_levels,
    LevelRecord, Recommendation, TwinAmplitudeStudy,
};
use ambid_twin::{Mode, TwinConfig};
use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;

use super::args::parse_band;

#[derive(Subcommand)]
pub enum StudyCmd {
    /// Excitation-amplitude study (the seed's figure 6): coherence, FRF variance and output SNR
    /// per level, and a recommended range.
    Amplitude(Box<AmplitudeArgs>),
    /// Operating-point study (the seed's figure 7): plant FRFs at nominal, bias ±20 % and air gap
    /// ±10 µm, with the deviation from nominal per band.
    OperatingPoint(OperatingPointArgs),
}

#[derive(Args)]
pub struct AmplitudeArgs {
    /// PRBS levels in % of i_sat, peak (= RMS for a PRBS), comma-separated (`2,4,8` or
    /// `2%,4%,8%`).
    #[arg(long, value_delimiter = ',', value_parser = super::args::parse_pct,
          default_values_t = seed_levels().iter().map(|l| super::args::clean(100.0 * l)).collect::<Vec<f64>>())]
    levels: Vec<f64>,
    /// Recorded files instead of the twin, one per level (same order as --levels), with the
    /// columns r, u, y (and i when present) named by --excitation, --input, --output, --current;
    /// any format of docs/data-files.md.
    #[arg(long, value_delimiter = ',')]
    files: Vec<PathBuf>,
    #[command(flatten)]
    r: super::args::ExcitationColumn,
    #[command(flatten)]
    u: super::args::InputColumn,
    #[command(flatten)]
    y: super::args::OutputColumn,
    #[command(flatten)]
    i: super::args::CurrentColumn,
    /// Noise-only file (files mode) for the output SNR.
    #[arg(long)]
    noise: Option<PathBuf>,
    #[command(flatten)]
    file: super::args::DataFileArgs,
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
    #[arg(long, value_enum, default_value_t = super::common::ModeArg::Nonlinear)]
    mode: super::common::ModeArg,
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
    #[arg(long, value_enum, default_value_t = super::common::ModeArg::Nonlinear)]
    mode: super::common::ModeArg,
    /// Twin configuration (TOML) of the nominal point.
    #[arg(long)]
    config: Option<PathBuf>,
    /// PRBS level in % of i_sat, peak (`10` or `10%`).
    #[arg(long, value_parser = super::args::parse_pct, default_value = "10")]
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
        StudyCmd::Amplitude(a) => amplitude(*a),
        StudyCmd::OperatingPoint(a) => operating_point(a),
    }
}

fn mode(m: super::common::ModeArg) -> Mode {
    match m {
        super::common::ModeArg::Linear => Mode::Linear,
        super::common::ModeArg::Nonlinear => Mode::Nonlinear,
    }
}

fn amplitude(a: AmplitudeArgs) -> Result<()> {
    OutputSet::check(&a.out, a.force)?;
    if let Some(l) = a
        .levels
        .iter()
        .find(|l| !(l.is_finite() && **l > 0.0 && **l <= 100.0))
    {
        return Err(ambid::error::Error::usage(format!(
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
            return Err(ambid::error::Error::usage(format!(
                "{} files for {} levels: pass one file per level, in the order of --levels",
                a.files.len(),
                a.levels.len()
            ))
            .into());
        }
        let mut records = Vec::new();
        let mut fs = None;
        for (p, l) in a.files.iter().zip(&a.levels) {
            let d = a.file.read(p)?;
            fs = Some(1.0 / d.ts);
            records.push(LevelRecord {
                level: l / 100.0,
                r: d.column(&a.r.excitation)?.to_vec(),
                u: d.column(&a.u.input)?.to_vec(),
                y: d.column(&a.y.output)?.to_vec(),
                i: d.optional_column(&a.i.current)?.map(<[f64]>::to_vec),
                saturated_fraction: None,
            });
        }
        let fs = fs.context("no file")?;
        let noise = match &a.noise {
            Some(p) => Some(a.file.file.read(p, Some(fs))?.column(&a.y.output)?.to_vec()),
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
            let (lo, hi) = (super::args::clean(lo), super::args::clean(hi));
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
            amplitude_frac: super::common::level_frac(a.level, a.amplitude)?,
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
