//! `ambid compare`: PRBS, chirp, white noise and multisine at one RMS level (the seed paper's figure 3).

use ambid::comparison::Compared;
use ambid::io::{time_csv_bytes, OutputSet};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct CompareArgs {
    /// Sample rate in Hz.
    #[arg(long, default_value_t = 20_000.0, allow_negative_numbers = true)]
    fs: f64,
    /// Common RMS level in % of --i-sat (`5` or `5%`; `0.1A` for amperes). Before, this option
    /// took amperes: a bare value below 1 gets a note.
    #[arg(long, default_value = "5", allow_negative_numbers = true,
          value_parser = |s: &str| super::args::parse_level(s).map_err(|e| format!("{e} (the common RMS level)")))]
    level: super::args::Level,
    /// The amplifier's saturation current in A (the reference of --level).
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    i_sat: f64,
    /// Seed of the noise signal.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Longest autocorrelation lag written, samples.
    #[arg(long, default_value_t = 1000)]
    max_lag: usize,
    /// Output directory for waveforms.csv, spectra.csv, autocorr.csv and comparison.json.
    #[arg(long, default_value = "out/excitation")]
    out: PathBuf,
    /// Replace those files if they exist (other files in the directory are left alone).
    #[arg(long)]
    force: bool,
}

pub fn compare(a: CompareArgs) -> Result<()> {
    let names = [
        "waveforms.csv",
        "spectra.csv",
        "autocorr.csv",
        "comparison.json",
    ];
    for n in names {
        OutputSet::check(&a.out.join(n), a.force)?;
    }
    if !(a.i_sat.is_finite() && a.i_sat > 0.0) {
        return Err(ambid::error::Error::usage(format!(
            "--i-sat must be a positive current in A, got {:e}",
            a.i_sat
        ))
        .into());
    }
    if let super::args::Level::Pct(p) = a.level {
        if p < 1.0 {
            eprintln!(
                "note: --level {p} is {p} % of i_sat = {} A RMS (compare read amperes before; \
                 write {p}A for {p} A)",
                super::args::clean(a.level.amps(a.i_sat))
            );
        }
    }
    let c = ambid::comparison::compare(a.fs, a.level.amps(a.i_sat), a.seed, a.max_lag)?;
    let mut set = OutputSet::new(a.force);
    let t: Vec<f64> = (0..c.signals[0].values.len())
        .map(|k| k as f64 * c.ts)
        .collect();
    let lag: Vec<f64> = (0..c.signals[0].autocorr.len())
        .map(|k| k as f64 * c.ts)
        .collect();
    let mut write = |file: &str, first: (&str, &[f64]), pick: fn(&Compared) -> &[f64]| {
        let mut cols: Vec<(&str, &[f64])> = vec![first];
        cols.extend(c.signals.iter().map(|s| (s.name, pick(s))));
        set.write(&a.out.join(file), &time_csv_bytes(&cols)?)
            .map_err(anyhow::Error::from)
    };
    write(names[0], ("t", &t), |s| &s.values)?;
    write(names[1], ("f_hz", &c.f_hz), |s| &s.spectrum)?;
    write(names[2], ("lag_s", &lag), |s| &s.autocorr)?;
    let table: serde_json::Map<String, serde_json::Value> = c
        .signals
        .iter()
        .map(|s| Ok((s.name.to_string(), serde_json::to_value(&s.report)?)))
        .collect::<Result<_>>()?;
    set.write(
        &a.out.join(names[3]),
        serde_json::to_string_pretty(&table)?.as_bytes(),
    )?;
    set.commit()?;
    println!(
        "{:<10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>7}",
        "signal", "f_min Hz", "f_max Hz", "Δf Hz", "rms A", "peak A", "crest"
    );
    for s in &c.signals {
        let r = &s.report;
        println!(
            "{:<10} {:>10.3} {:>10.1} {:>10.3} {:>10.4} {:>10.4} {:>7.3}",
            s.name, r.f_min_hz, r.f_max_hz, r.resolution_hz, r.rms, r.peak, r.crest_factor
        );
    }
    println!(
        "written: {}/{{waveforms,spectra,autocorr}}.csv, comparison.json",
        a.out.display()
    );
    Ok(())
}
