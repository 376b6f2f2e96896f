//! `ambid excite`: design an excitation signal, write it and print its band/duration report.

use super::common::{deprecated_band, prbs_order_arg};
use ambid::io::{time_csv_bytes, time_csv_to, OutputSet};
use ambid_core::signal::{
    amplitude_spectrum, autocorrelation, ChirpSpec, Distribution, ExcitationSpec, Grid,
    MultisineSpec, NoiseSpec, Phases, PrbsSpec, Sweep,
};
use anyhow::Result;
use clap::{Args, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct ExciteArgs {
    #[command(subcommand)]
    signal: SignalCmd,
    /// Sample rate in Hz.
    #[arg(long, default_value_t = 20_000.0, global = true)]
    fs: f64,
    /// Output CSV file (columns t, r). Without it only the report is printed.
    #[arg(long, global = true)]
    out: Option<PathBuf>,
    /// Print the report as JSON instead of text.
    #[arg(long, global = true)]
    json: bool,
    /// Excitation level in % of --i-sat (`10` or `10%`; `0.2A` for amperes): the peak of a
    /// PRBS or chirp, the RMS of noise or a multisine (default 10 % peak, 5 % RMS).
    #[arg(long, global = true, allow_negative_numbers = true, value_parser = super::args::parse_level)]
    level: Option<super::args::Level>,
    /// Band of noise or a multisine, Hz, as `f_min:f_max` (noise: band-limited; multisine: its
    /// lowest and highest line; default 5:2000 for a multisine, white noise).
    #[arg(long, global = true, allow_negative_numbers = true, value_parser = super::args::parse_band)]
    band: Option<(f64, f64)>,
    /// The amplifier's saturation current in A, to state the level as a percentage of it.
    #[arg(
        long,
        default_value_t = 2.0,
        global = true,
        allow_negative_numbers = true
    )]
    i_sat: f64,
    /// Write the one-sided amplitude spectrum of one period (columns f_hz, amplitude) to this CSV.
    #[arg(long, global = true)]
    spectrum: Option<PathBuf>,
    /// Write the normalised autocorrelation of one period (columns lag_s, r; circular for
    /// periodic signals) to this CSV.
    #[arg(long, global = true)]
    autocorr: Option<PathBuf>,
    /// Replace output files that exist (all outputs are written as one set, or none).
    #[arg(long, global = true)]
    force: bool,
}

#[derive(Subcommand)]
pub enum SignalCmd {
    /// Maximum-length pseudo-random binary sequence.
    Prbs {
        /// PRBS register (LFSR) order n (2..=31); period 2^n − 1 bits.
        #[arg(long, default_value_t = 10)]
        prbs_order: u32,
        /// Deprecated spelling of --prbs-order (`--order` is a model order in `fit`).
        #[arg(long, hide = true, conflicts_with = "prbs_order")]
        order: Option<u32>,
        /// Samples per bit Nb.
        #[arg(long, default_value_t = 5)]
        samples_per_bit: usize,
        /// Number of periods Np.
        #[arg(long, default_value_t = 20)]
        periods: usize,
        /// Deprecated: amplitude in A (values ±amplitude + offset); write `--level PCT`.
        #[arg(long, hide = true, allow_negative_numbers = true)]
        amplitude: Option<f64>,
        /// Mean offset in A.
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        offset: f64,
    },
    /// Swept sine.
    Chirp {
        /// Start frequency, Hz.
        #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
        f0: f64,
        /// End frequency, Hz.
        #[arg(long, default_value_t = 1000.0, allow_negative_numbers = true)]
        f1: f64,
        /// Duration of one sweep, s.
        #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
        duration: f64,
        /// Deprecated: amplitude in A; write `--level PCT`.
        #[arg(long, hide = true, allow_negative_numbers = true)]
        amplitude: Option<f64>,
        /// Sweep law.
        #[arg(long, value_enum, default_value_t = SweepArg::Linear)]
        sweep: SweepArg,
        /// Number of sweeps.
        #[arg(long, default_value_t = 1)]
        periods: usize,
    },
    /// White noise, Gaussian or uniform, optionally band-limited.
    Noise {
        /// Deprecated: RMS value in A; write `--level PCT`.
        #[arg(long, hide = true, allow_negative_numbers = true)]
        rms: Option<f64>,
        /// Number of samples.
        #[arg(long, default_value_t = 102_300)]
        samples: usize,
        /// Distribution.
        #[arg(long, value_enum, default_value_t = DistArg::Gaussian)]
        distribution: DistArg,
        /// Deprecated: lower band edge, Hz; write `--band LO:HI`.
        #[arg(long, hide = true, requires = "band_hi", allow_negative_numbers = true)]
        band_lo: Option<f64>,
        /// Deprecated: upper band edge, Hz; write `--band LO:HI`.
        #[arg(long, hide = true, requires = "band_lo", allow_negative_numbers = true)]
        band_hi: Option<f64>,
        /// Random seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Periodic multisine with bin-aligned lines.
    Multisine {
        /// Deprecated: lowest line, Hz; write `--band LO:HI`.
        #[arg(long, hide = true, allow_negative_numbers = true)]
        f_min: Option<f64>,
        /// Deprecated: highest line, Hz; write `--band LO:HI`.
        #[arg(long, hide = true, allow_negative_numbers = true)]
        f_max: Option<f64>,
        /// Samples per period.
        #[arg(long, default_value_t = 5115)]
        period_samples: usize,
        /// Number of periods.
        #[arg(long, default_value_t = 20)]
        periods: usize,
        /// Deprecated: RMS value in A; write `--level PCT`.
        #[arg(long, hide = true, allow_negative_numbers = true)]
        rms: Option<f64>,
        /// Frequency grid.
        #[arg(long, value_enum, default_value_t = GridArg::Odd)]
        grid: GridArg,
        /// Phases.
        #[arg(long, value_enum, default_value_t = PhaseArg::Schroeder)]
        phases: PhaseArg,
        /// Random seed (random phases, random-odd grid).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Write M random-phase realisations for the robust BLA (`ambid bla --record`): the
        /// same grid (from --seed), phases from seed + 1 … seed + M, as `<out>_m1.csv` …
        /// `<out>_mM.csv`. Needs --phases random and --out.
        #[arg(long)]
        realisations: Option<usize>,
    },
}

#[derive(Clone, Copy, ValueEnum)]
pub enum SweepArg {
    Linear,
    Logarithmic,
}
#[derive(Clone, Copy, ValueEnum)]
pub enum DistArg {
    Gaussian,
    Uniform,
}
#[derive(Clone, Copy, ValueEnum)]
pub enum GridArg {
    Full,
    Odd,
    RandomOdd,
}
#[derive(Clone, Copy, ValueEnum)]
pub enum PhaseArg {
    Schroeder,
    Random,
}

pub fn excite(a: ExciteArgs) -> Result<()> {
    if !(a.fs.is_finite() && a.fs > 0.0) {
        return Err(ambid::error::Error::usage(format!(
            "--fs must be a positive sample rate in Hz, got {:e}",
            a.fs
        ))
        .into());
    }
    if !(a.i_sat.is_finite() && a.i_sat > 0.0) {
        return Err(ambid::error::Error::usage(format!(
            "--i-sat must be a positive current in A, got {:e}",
            a.i_sat
        ))
        .into());
    }
    let ts = 1.0 / a.fs;
    let prbs_order = match &a.signal {
        SignalCmd::Prbs {
            prbs_order, order, ..
        } => Some(prbs_order_arg(*prbs_order, *order)),
        _ => None,
    };
    let prbs_bits = prbs_order
        .filter(|o| (2..=31).contains(o))
        .map(|o| (1u64 << o) - 1);
    let realisations = match &a.signal {
        SignalCmd::Multisine { realisations, .. } => *realisations,
        _ => None,
    };
    // the level: --level (% of --i-sat, or A), else the deprecated amperes, else the default
    let i_sat = a.i_sat;
    let level = |old: Option<f64>, old_name: &str, default_pct: f64| -> Result<f64> {
        match (a.level, old) {
            (Some(_), Some(_)) => Err(ambid::error::Error::usage(format!(
                "give the level once: --level, or the deprecated {old_name}, not both"
            ))
            .into()),
            (Some(l), None) => Ok(l.amps(i_sat)),
            (None, Some(v)) => {
                super::args::deprecated(
                    &format!("{old_name} {v} (A)"),
                    &format!(
                        "--level {}% (of --i-sat {i_sat} A) or --level {v}A",
                        super::args::clean(100.0 * v / i_sat)
                    ),
                );
                Ok(v)
            }
            (None, None) => Ok(default_pct / 100.0 * i_sat),
        }
    };
    let band = a.band;
    if band.is_some() && matches!(a.signal, SignalCmd::Prbs { .. } | SignalCmd::Chirp { .. }) {
        return Err(ambid::error::Error::usage(
            "--band applies to noise and multisine (a PRBS has no band parameter; a chirp sweeps \
             from --f0 to --f1)"
                .to_string(),
        )
        .into());
    }
    let spec =
        match a.signal {
            SignalCmd::Prbs {
                samples_per_bit,
                periods,
                amplitude,
                offset,
                ..
            } => ExcitationSpec::Prbs(PrbsSpec {
                order: prbs_order.unwrap_or(10),
                samples_per_bit,
                periods,
                amplitude: level(amplitude, "--amplitude", 10.0)?,
                offset,
            }),
            SignalCmd::Chirp {
                f0,
                f1,
                duration,
                amplitude,
                sweep,
                periods,
            } => ExcitationSpec::Chirp(ChirpSpec {
                f0_hz: f0,
                f1_hz: f1,
                duration_s: duration,
                amplitude: level(amplitude, "--amplitude", 10.0)?,
                sweep: match sweep {
                    SweepArg::Linear => Sweep::Linear,
                    SweepArg::Logarithmic => Sweep::Logarithmic,
                },
                periods,
            }),
            SignalCmd::Noise {
                rms,
                samples,
                distribution,
                band_lo,
                band_hi,
                seed,
            } => ExcitationSpec::Noise(NoiseSpec {
                distribution: match distribution {
                    DistArg::Gaussian => Distribution::Gaussian,
                    DistArg::Uniform => Distribution::Uniform,
                },
                rms: level(rms, "--rms", 5.0)?,
                n_samples: samples,
                band_hz: match (band, band_lo.zip(band_hi)) {
                    (Some(_), Some(_)) => return Err(ambid::error::Error::usage(
                        "give the band once: --band LO:HI, or the deprecated --band-lo/--band-hi"
                            .to_string(),
                    )
                    .into()),
                    (Some(b), None) => Some(b),
                    (None, Some((lo, hi))) => {
                        super::args::deprecated(
                            &format!("--band-lo {lo} --band-hi {hi}"),
                            &format!("--band {lo}:{hi}"),
                        );
                        Some((lo, hi))
                    }
                    (None, None) => None,
                },
                seed,
            }),
            SignalCmd::Multisine {
                f_min,
                f_max,
                period_samples,
                periods,
                rms,
                grid,
                phases,
                seed,
                realisations: _,
            } => {
                let (f_min, f_max) = match band {
                    Some(b) if f_min.is_some() || f_max.is_some() => {
                        return Err(ambid::error::Error::usage(format!(
                            "give the band once: --band {}:{}, or the deprecated --f-min/--f-max",
                            b.0, b.1
                        ))
                        .into())
                    }
                    Some(b) => b,
                    None => deprecated_band((5.0, 2000.0), f_min, f_max, ("--f-min", "--f-max"))?,
                };
                ExcitationSpec::Multisine(MultisineSpec {
                    f_min_hz: f_min,
                    f_max_hz: f_max,
                    period_samples,
                    periods,
                    rms: level(rms, "--rms", 5.0)?,
                    grid: match grid {
                        GridArg::Full => Grid::Full,
                        GridArg::Odd => Grid::Odd,
                        GridArg::RandomOdd => Grid::RandomOdd,
                    },
                    phases: match phases {
                        PhaseArg::Schroeder => Phases::Schroeder,
                        PhaseArg::Random => Phases::Random,
                    },
                    seed,
                })
            }
        };
    let report = spec.report(ts)?;
    // refuse to overwrite before any work
    for p in [&a.out, &a.spectrum, &a.autocorr].into_iter().flatten() {
        OutputSet::check(p, a.force)?;
    }
    let mut set = OutputSet::new(a.force);
    let mut realisation_files = Vec::new();
    if a.out.is_some() || a.spectrum.is_some() || a.autocorr.is_some() {
        let e = spec.generate(ts)?;
        match (&a.out, realisations) {
            (Some(out), Some(m)) => {
                realisation_files = write_realisations(&mut set, &spec, ts, m, out)?;
            }
            (Some(out), None) => {
                let t = e.times();
                set.write_with(out, |w| time_csv_to(w, &[("t", &t), ("r", &e.values)]))?;
            }
            _ => {}
        }
        // one period of a periodic signal (the whole record otherwise)
        let period = e.period(0).unwrap_or(&e.values);
        if let Some(path) = &a.spectrum {
            let (f, amp) = amplitude_spectrum(period, ts)?;
            set.write(path, &time_csv_bytes(&[("f_hz", &f), ("amplitude", &amp)])?)?;
        }
        if let Some(path) = &a.autocorr {
            let max_lag = (period.len() - 1).min(MAX_AUTOCORR_LAG);
            let circular = e.periods > 1 || e.period_samples < e.values.len();
            let rho = autocorrelation(period, max_lag, circular)?;
            let lag: Vec<f64> = (0..rho.len()).map(|k| k as f64 * ts).collect();
            set.write(path, &time_csv_bytes(&[("lag_s", &lag), ("r", &rho)])?)?;
        }
    }
    set.commit()?;
    for p in &realisation_files {
        println!("written: {}", p.display());
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        if let Some(l) = prbs_bits {
            println!("period        L = 2^n - 1 = {l} bits");
        }
        println!("{report}");
        println!(
            "level         peak {:.3} % / rms {:.3} % of i_sat = {} A",
            100.0 * report.peak / a.i_sat,
            100.0 * report.rms / a.i_sat,
            a.i_sat
        );
        if let (Some(out), None) = (&a.out, realisations) {
            println!("written: {}", out.display());
        }
    }
    Ok(())
}

/// Writes `m` random-phase realisations of a multisine (same grid, phases from seed + 1 …
/// seed + m, the convention of `ambid::bla::run_level`) next to `out` as `<stem>_m<k>.<ext>`,
/// staged in `set`; returns their paths.
fn write_realisations(
    set: &mut OutputSet,
    spec: &ExcitationSpec,
    ts: f64,
    m: usize,
    out: &Path,
) -> Result<Vec<PathBuf>> {
    let ExcitationSpec::Multisine(ms) = spec else {
        return Err(ambid::error::Error::usage(
            "--realisations applies to a multisine".to_string(),
        )
        .into());
    };
    if ms.phases != Phases::Random {
        return Err(ambid::error::Error::usage(
            "--realisations needs --phases random (Schroeder phases are the same every time)"
                .to_string(),
        )
        .into());
    }
    if m < 2 {
        return Err(ambid::error::Error::usage(format!(
            "--realisations must be at least 2 (the robust BLA needs M ≥ 2), got {m}"
        ))
        .into());
    }
    let bins = ms.bins(ts)?;
    let n = ms.period_samples;
    let stem = out.file_stem().map_or_else(
        || "realisation".into(),
        |s| s.to_string_lossy().into_owned(),
    );
    let ext = out
        .extension()
        .map_or_else(|| "csv".into(), |s| s.to_string_lossy().into_owned());
    let mut paths = Vec::with_capacity(m);
    for k in 0..m {
        let period = ambid_core::frf::bla::random_phase_period(
            &bins,
            n,
            ms.rms,
            ms.seed.wrapping_add(1 + k as u64),
        )?;
        let r: Vec<f64> = (0..ms.periods * n).map(|t| period[t % n]).collect();
        let t: Vec<f64> = (0..r.len()).map(|j| j as f64 * ts).collect();
        let path = out.with_file_name(format!("{stem}_m{}.{ext}", k + 1));
        set.write_with(&path, |w| time_csv_to(w, &[("t", &t), ("r", &r)]))?;
        paths.push(path);
    }
    Ok(paths)
}

/// Longest autocorrelation lag written by `excite --autocorr` (samples).
const MAX_AUTOCORR_LAG: usize = 20_000;
