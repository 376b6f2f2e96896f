//! `ambid`: command-line front end. Each command parses its arguments, calls the library and
//! writes files; see `ambid --help`.

use ambid::comparison::Compared;
use ambid::experiment::{self, ExcitationKind, ExcitationPlan, Experiment};
use ambid::io::{frf_csv_bytes, time_csv_bytes, time_csv_to, FrfColumn, OutputSet};
use ambid_core::signal::{
    amplitude_spectrum, autocorrelation, ChirpSpec, Distribution, ExcitationSpec, Grid,
    MultisineSpec, NoiseSpec, Phases, PrbsSpec, Sweep,
};
use ambid_twin::{Integrator, Mode, TwinConfig};
use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};

mod cli_args;
mod cli_bla;
mod cli_fit;
mod cli_freqfit;
mod cli_frf;
mod cli_run;
mod cli_validate;

#[derive(Parser)]
#[command(
    name = "ambid",
    version,
    about = "Closed-loop black-box identification of active magnetic bearing systems",
    long_about = "Closed-loop black-box identification of active magnetic bearing (AMB) systems.\n\n\
        Design excitation signals, run the embedded AMB digital twin (or read measured files), and \
        identify the open-loop-unstable plant from closed-loop data.",
    arg_required_else_help = true
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the whole seed workflow (excitation → studies → FRF → orders → models → validation →
    /// reconstruction → ISO zone) and write the HTML report, summary.json, figure data and models.
    /// Without a workflow file it runs on the embedded twin with the defaults.
    Run(cli_run::RunArgs),
    /// Write a commented example workflow file.
    Init(cli_run::InitArgs),
    /// Design an excitation signal, write it as CSV (t, r) and print its band/duration report.
    Excite(ExciteArgs),
    /// Compare PRBS, chirp, white noise and multisine at one RMS level (the seed paper's figure 3):
    /// print their statistics, write their waveforms, spectra and autocorrelations.
    Compare(CompareArgs),
    /// Run the embedded AMB twin in closed loop and write data.csv, truth.csv, meta.json and
    /// controller.toml (the rig's controller, for `frf --controller` and `validate`).
    Simulate(SimulateArgs),
    /// Print the twin's default configuration (or a random rig's, with --rig-seed) as TOML (edit
    /// it and pass it with --config).
    Config(RigArgs),
    /// Print the twin's linearised facts: closed-loop modes, peak sensitivity, unstable plant poles.
    Info(TwinArgs),
    /// Nonparametric closed-loop FRFs from recorded data (T_ry, S, plant by the joint and, with a
    /// controller file, the indirect method, the controller from data), with standard deviations,
    /// coherences, quality measures and resonance peaks; writes the FRF CSV.
    Frf(cli_frf::FrfArgs),
    /// The seed paper's studies: excitation amplitude and operating point.
    #[command(subcommand)]
    Study(cli_frf::StudyCmd),
    /// Fit a parametric model (FIR, ARX by least squares; ARMAX, OE, BJ by the prediction-error
    /// method) to time-domain data; print parameters ± std and fits; write the model JSON.
    Fit(cli_fit::FitArgs),
    /// ARX order scan over na × nb (× nk): loss, AIC, BIC, FPE (and validation fit); writes the grid.
    Order(cli_fit::OrderArgs),
    /// Fit ARX, OE and state-space models of several orders to one FRF and compare them
    /// (frequency errors, BIC, closed-loop validation fit with the controller, unstable poles):
    /// the seed paper's table 1; writes the table as CSV.
    CompareModels(cli_freqfit::CompareModelsArgs),
    /// Validate a model on an independent record through the closed loop with the controller:
    /// fits of displacement and current, windows, residual tests, closed-loop poles, margins and
    /// the ISO 14839-3 zone; writes summary.json, timeseries.csv and residuals.csv.
    Validate(cli_validate::ValidateArgs),
    /// Robust Best Linear Approximation of the plant (M random-phase multisines × P periods) on
    /// the twin or from recorded realisations (--record PCT:PATH): noise and nonlinear variance
    /// per RMS level and the recommended level, or for one level the per-line BLA with its total,
    /// noise and nonlinear standard deviations.
    Bla(cli_bla::BlaArgs),
}

#[derive(Args)]
struct ExciteArgs {
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
    #[arg(long, global = true, allow_negative_numbers = true, value_parser = cli_args::parse_level)]
    level: Option<cli_args::Level>,
    /// Band of noise or a multisine, Hz, as `f_min:f_max` (noise: band-limited; multisine: its
    /// lowest and highest line; default 5:2000 for a multisine, white noise).
    #[arg(long, global = true, allow_negative_numbers = true, value_parser = cli_args::parse_band)]
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
enum SignalCmd {
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
enum SweepArg {
    Linear,
    Logarithmic,
}
#[derive(Clone, Copy, ValueEnum)]
enum DistArg {
    Gaussian,
    Uniform,
}
#[derive(Clone, Copy, ValueEnum)]
enum GridArg {
    Full,
    Odd,
    RandomOdd,
}
#[derive(Clone, Copy, ValueEnum)]
enum PhaseArg {
    Schroeder,
    Random,
}
#[derive(Clone, Copy, ValueEnum)]
enum IntegratorArg {
    Rk4,
    ExpRk4,
}
#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum ModeArg {
    Linear,
    Nonlinear,
}

#[derive(Args)]
struct CompareArgs {
    /// Sample rate in Hz.
    #[arg(long, default_value_t = 20_000.0, allow_negative_numbers = true)]
    fs: f64,
    /// Common RMS level in % of --i-sat (`5` or `5%`; `0.1A` for amperes). Before, this option
    /// took amperes: a bare value below 1 gets a note.
    #[arg(long, default_value = "5", allow_negative_numbers = true,
          value_parser = |s: &str| cli_args::parse_level(s).map_err(|e| format!("{e} (the common RMS level)")))]
    level: cli_args::Level,
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

#[derive(Args)]
struct RigArgs {
    /// A random rig of the twin's test family instead of the nominal one: rotor, magnets, bias
    /// and gap, amplifier and sensor bandwidths, bending mode, controller gains and noise drawn
    /// ±15–30 % from this seed, accepted only when the loop is stable with max|S| ≤ 4
    /// (`ambid_twin::rig`).
    #[arg(long)]
    rig_seed: Option<u64>,
}

#[derive(Args)]
struct TwinArgs {
    /// Twin configuration (TOML); defaults to the nominal rig (see `ambid config`).
    #[arg(long, conflicts_with = "rig_seed")]
    config: Option<PathBuf>,
    #[command(flatten)]
    rig: RigArgs,
    /// Bias current i0 in A (overrides the configuration).
    #[arg(long, allow_negative_numbers = true)]
    bias: Option<f64>,
    /// Nominal air gap g0 in m (overrides the configuration), e.g. 0.00041.
    #[arg(long, allow_negative_numbers = true)]
    gap: Option<f64>,
}

#[derive(Args)]
struct SimulateArgs {
    #[command(flatten)]
    twin: TwinArgs,
    /// Excitation signal injected at the controller output of bearing A.
    #[arg(long, value_enum, default_value_t = ExcitationKind::Prbs)]
    signal: ExcitationKind,
    /// Deprecated spelling of --signal (`--excitation` names the column r in `frf`,
    /// `validate` and `bla`).
    #[arg(long, value_enum, hide = true, conflicts_with = "signal")]
    excitation: Option<ExcitationKind>,
    /// Excitation level in % of the saturation current i_sat (`10` or `10%`): peak for PRBS,
    /// chirp and multisine, RMS for noise.
    #[arg(long, default_value = "10", allow_negative_numbers = true, value_parser = cli_args::parse_pct)]
    level: f64,
    /// Deprecated: the level as a fraction of i_sat (0.1 = 10 %); write `--level 10`.
    #[arg(
        long,
        hide = true,
        conflicts_with = "level",
        allow_negative_numbers = true
    )]
    amplitude: Option<f64>,
    /// PRBS register order n (period 2^n − 1 bits).
    #[arg(long, default_value_t = 10)]
    prbs_order: u32,
    /// Deprecated spelling of --prbs-order (`--order` is a model order in `fit`).
    #[arg(long, hide = true, conflicts_with = "prbs_order")]
    order: Option<u32>,
    /// PRBS samples per bit.
    #[arg(long, default_value_t = 5)]
    samples_per_bit: usize,
    /// Periods (PRBS, chirp, multisine).
    #[arg(long, default_value_t = 20)]
    periods: usize,
    /// Band of the chirp, noise or multisine, Hz, as `f_min:f_max`.
    #[arg(long, default_value = "1:2000", allow_negative_numbers = true, value_parser = cli_args::parse_band)]
    band: (f64, f64),
    /// Deprecated: lowest frequency, Hz; write `--band LO:HI`.
    #[arg(long, hide = true, allow_negative_numbers = true)]
    f_min: Option<f64>,
    /// Deprecated: highest frequency, Hz; write `--band LO:HI`.
    #[arg(long, hide = true, allow_negative_numbers = true)]
    f_max: Option<f64>,
    /// Period length for chirp and multisine, s (default: one period of the seed PRBS, 5115
    /// samples). Noise and `none` records last periods × period.
    #[arg(long, default_value_t = 0.25575, allow_negative_numbers = true)]
    period: f64,
    /// Simulation mode.
    #[arg(long, value_enum, default_value_t = ModeArg::Nonlinear)]
    mode: ModeArg,
    /// Integrator of the nonlinear mode (overrides the configuration): `rk4` (10 substeps per
    /// control period, the reference) or `exp-rk4` (exact linear flow + RK4 on the nonlinear
    /// residual, ≈ 4× faster, less accurate while the amplifier slew limit switches).
    #[arg(long, value_enum)]
    integrator: Option<IntegratorArg>,
    /// Seed for sensor noise and random excitations.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Switch the sensor noise off.
    #[arg(long)]
    no_noise: bool,
    /// Also record bearing B (columns u_b, i_b, y_b).
    #[arg(long)]
    record_b: bool,
    /// Number of log-spaced truth frequencies from 1 Hz to fs/2 (at most 1000000).
    #[arg(long, default_value_t = 400)]
    truth_points: usize,
    /// A linear chirp position reference `amplitude_m,duration_s,f0_hz,f1_hz` at bearing A (the
    /// seed's closed-loop reconstruction uses 5e-6,10,1,1000); needs `--signal none`, and
    /// the record lasts the chirp's duration.
    #[arg(long)]
    reference_chirp: Option<String>,
    /// Inject the excitation read from this file (column `r`; a `t` column, if present, must
    /// match the twin's 20 kHz) instead of designing one, e.g. one realisation written by
    /// `ambid excite multisine --phases random --realisations M`.
    #[arg(long, conflicts_with_all = ["signal", "excitation", "reference_chirp"])]
    excitation_file: Option<PathBuf>,
    /// Output directory (data.csv, truth.csv, meta.json, controller.toml).
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// Replace those files if they exist (other files in the directory are left alone).
    #[arg(long)]
    force: bool,
}

fn main() {
    // `ambid … | head` closes stdout early: end quietly instead of panicking in `println!`
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let msg = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if msg.contains("Broken pipe") {
            std::process::exit(0);
        }
        default_hook(info);
    }));
    let cli = Cli::parse();
    if let Err(e) = dispatch(cli) {
        eprintln!(
            "error: {}",
            ambid::workflow::compact_numbers(&format!("{e:#}"))
        );
        // one rule for every command (docs/workflow.md, "Exit codes")
        let code = ambid::workflow::exit_code(&e);
        std::process::exit(code);
    }
}

fn dispatch(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Run(a) => cli_run::run(a),
        Command::Init(a) => cli_run::init(a),
        Command::Excite(a) => excite(a),
        Command::Compare(a) => compare(a),
        Command::Simulate(a) => simulate(a),
        Command::Config(a) => {
            let cfg = match a.rig_seed {
                Some(seed) => ambid_twin::random_rig(seed)?,
                None => TwinConfig::default(),
            };
            print!("{}", cfg.to_toml_string()?);
            Ok(())
        }
        Command::Info(a) => info(a),
        Command::Frf(a) => cli_frf::frf(a),
        Command::Study(c) => cli_frf::study(c),
        Command::Fit(a) => cli_fit::fit(a),
        Command::Order(a) => cli_fit::order(a),
        Command::CompareModels(a) => cli_freqfit::compare(a),
        Command::Validate(a) => cli_validate::validate(a),
        Command::Bla(a) => cli_bla::bla(a),
    }
}

fn excite(a: ExciteArgs) -> Result<()> {
    if !(a.fs.is_finite() && a.fs > 0.0) {
        return Err(ambid::workflow::usage(anyhow::anyhow!(
            "--fs must be a positive sample rate in Hz, got {:e}",
            a.fs
        ))
        .into());
    }
    if !(a.i_sat.is_finite() && a.i_sat > 0.0) {
        return Err(ambid::workflow::usage(anyhow::anyhow!(
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
            (Some(_), Some(_)) => Err(ambid::workflow::usage(anyhow::anyhow!(
                "give the level once: --level, or the deprecated {old_name}, not both"
            ))
            .into()),
            (Some(l), None) => Ok(l.amps(i_sat)),
            (None, Some(v)) => {
                cli_args::deprecated(
                    &format!("{old_name} {v} (A)"),
                    &format!(
                        "--level {}% (of --i-sat {i_sat} A) or --level {v}A",
                        cli_args::clean(100.0 * v / i_sat)
                    ),
                );
                Ok(v)
            }
            (None, None) => Ok(default_pct / 100.0 * i_sat),
        }
    };
    let band = a.band;
    if band.is_some() && matches!(a.signal, SignalCmd::Prbs { .. } | SignalCmd::Chirp { .. }) {
        return Err(ambid::workflow::usage(anyhow::anyhow!(
            "--band applies to noise and multisine (a PRBS has no band parameter; a chirp sweeps \
             from --f0 to --f1)"
        ))
        .into());
    }
    let spec = match a.signal {
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
                (Some(_), Some(_)) => {
                    return Err(ambid::workflow::usage(anyhow::anyhow!(
                        "give the band once: --band LO:HI, or the deprecated --band-lo/--band-hi"
                    ))
                    .into())
                }
                (Some(b), None) => Some(b),
                (None, Some((lo, hi))) => {
                    cli_args::deprecated(
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
                    return Err(ambid::workflow::usage(anyhow::anyhow!(
                        "give the band once: --band {}:{}, or the deprecated --f-min/--f-max",
                        b.0,
                        b.1
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
        return Err(ambid::workflow::usage(anyhow::anyhow!(
            "--realisations applies to a multisine"
        ))
        .into());
    };
    if ms.phases != Phases::Random {
        return Err(ambid::workflow::usage(anyhow::anyhow!(
            "--realisations needs --phases random (Schroeder phases are the same every time)"
        ))
        .into());
    }
    if m < 2 {
        return Err(ambid::workflow::usage(anyhow::anyhow!(
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

/// The PRBS order from `--prbs-order`, or from the deprecated `--order` (with its note).
fn prbs_order_arg(prbs_order: u32, deprecated_order: Option<u32>) -> u32 {
    match deprecated_order {
        Some(o) => {
            cli_args::deprecated(
                &format!("--order {o} (the PRBS order)"),
                &format!("--prbs-order {o}"),
            );
            o
        }
        None => prbs_order,
    }
}

/// The level in % of i_sat as a fraction: `level_pct`, or the deprecated `--amplitude` fraction
/// (with its note).
pub(crate) fn level_frac(level_pct: f64, deprecated_frac: Option<f64>) -> Result<f64> {
    match deprecated_frac {
        Some(f) => {
            cli_args::deprecated(
                &format!("--amplitude {f} (a fraction of i_sat)"),
                &format!("--level {}", cli_args::clean(100.0 * f)),
            );
            Ok(f)
        }
        None => Ok(level_pct / 100.0),
    }
}

/// The band from `--band` (or its default `band`), or from the deprecated separate edges
/// (`names`, with a note); an edge given alone replaces that edge of `band`.
pub(crate) fn deprecated_band(
    band: (f64, f64),
    lo: Option<f64>,
    hi: Option<f64>,
    names: (&str, &str),
) -> Result<(f64, f64)> {
    if lo.is_none() && hi.is_none() {
        return Ok(band);
    }
    let (l, h) = (lo.unwrap_or(band.0), hi.unwrap_or(band.1));
    let old: Vec<String> = [(names.0, lo), (names.1, hi)]
        .iter()
        .filter_map(|(n, v)| v.map(|v| format!("{n} {v}")))
        .collect();
    cli_args::deprecated(&old.join(" "), &format!("--band {l}:{h}"));
    Ok((l, h))
}

/// `excitation: peak … % / RMS … % of i_sat (… A)` of the injected excitation, or `None`
/// without one.
fn excitation_level(r: &[f64], i_sat: f64) -> Option<String> {
    if r.is_empty() || !(i_sat.is_finite() && i_sat > 0.0) {
        return None;
    }
    let peak = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let rms = (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt();
    (peak > 0.0).then(|| {
        format!(
            "excitation: peak {:.3} % / RMS {:.3} % of i_sat = {i_sat} A",
            100.0 * peak / i_sat,
            100.0 * rms / i_sat
        )
    })
}

/// Longest autocorrelation lag written by `excite --autocorr` (samples).
const MAX_AUTOCORR_LAG: usize = 20_000;

fn compare(a: CompareArgs) -> Result<()> {
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
        return Err(ambid::workflow::usage(anyhow::anyhow!(
            "--i-sat must be a positive current in A, got {:e}",
            a.i_sat
        ))
        .into());
    }
    if let cli_args::Level::Pct(p) = a.level {
        if p < 1.0 {
            eprintln!(
                "note: --level {p} is {p} % of i_sat = {} A RMS (compare read amperes before; \
                 write {p}A for {p} A)",
                cli_args::clean(a.level.amps(a.i_sat))
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

fn twin_config(a: &TwinArgs) -> Result<TwinConfig> {
    let mut cfg = match &a.config {
        Some(p) => {
            let s = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            TwinConfig::from_toml_str(&s).with_context(|| format!("in {}", p.display()))?
        }
        None => match a.rig.rig_seed {
            Some(seed) => ambid_twin::random_rig(seed)?,
            None => TwinConfig::default(),
        },
    };
    if let Some(b) = a.bias {
        cfg.operating_point.bias_current_a = b;
    }
    if let Some(g) = a.gap {
        cfg.operating_point.air_gap_m = g;
    }
    cfg.validate()?;
    Ok(cfg)
}

fn info(a: TwinArgs) -> Result<()> {
    let twin = ambid_twin::Twin::new(twin_config(&a)?)?;
    let lp = twin.linear_params();
    println!(
        "linearised magnet: k_i = {:.2} N/A, k_x = {:.4e} N/m",
        lp.k_i, lp.k_x
    );
    println!("closed-loop modes (lightly damped pole pairs):");
    for m in twin.closed_loop_modes() {
        println!("  {:8.1} Hz   damping {:.3}", m.freq_hz, m.damping);
    }
    let (f, s) = twin.peak_sensitivity()?;
    println!("peak sensitivity |S| = {s:.3} at {f:.1} Hz");
    println!("unstable poles of the assembled plant P (z; s = ln z / Ts):");
    for z in twin.plant_unstable_poles()? {
        let s = twin.pole_to_s(z);
        println!(
            "  z = {:.6}{:+.6}j   s = {:.2}{:+.2}j rad/s",
            z.re, z.im, s.re, s.im
        );
    }
    let pred = twin.predicted_unstable_pole();
    println!(
        "physics prediction ({} unstable pole): rigid rotor with loop B as a spring k_B = {:.4e} N/m: \
         s = +{:.2} rad/s; rotor pinned at B (lower bound): s = +{:.2} rad/s",
        pred.count, pred.bearing_b_stiffness_n_per_m, pred.rigid_spring_b_rad_s, pred.pinned_at_b_rad_s
    );
    Ok(())
}

/// Largest `simulate --truth-points`: checked before anything is simulated or written (each
/// point costs a few hundred bytes in memory and a row of truth.csv; 10⁹ points aborted
/// allocating 8 GB after data.csv was written).
const MAX_TRUTH_POINTS: usize = 1_000_000;

fn simulate(a: SimulateArgs) -> Result<()> {
    let data_path = a.out.join("data.csv");
    let truth_path = a.out.join("truth.csv");
    let meta_path = a.out.join("meta.json");
    let ctrl_path = a.out.join("controller.toml");
    // refuse to overwrite before any work
    for p in [&data_path, &truth_path, &meta_path, &ctrl_path] {
        OutputSet::check(p, a.force)?;
    }
    let band = deprecated_band(a.band, a.f_min, a.f_max, ("--f-min", "--f-max"))?;
    let mut cfg = twin_config(&a.twin)?;
    if let Some(integ) = a.integrator {
        cfg.simulation.integrator = match integ {
            IntegratorArg::Rk4 => Integrator::Rk4,
            IntegratorArg::ExpRk4 => Integrator::ExpRk4,
        };
    }
    let exp = Experiment {
        twin: cfg,
        excitation: ExcitationPlan {
            kind: match a.excitation {
                Some(k) => {
                    let name = k
                        .to_possible_value()
                        .map_or_else(String::new, |v| v.get_name().to_string());
                    cli_args::deprecated(
                        &format!("simulate --excitation {name}"),
                        &format!("--signal {name}"),
                    );
                    k
                }
                None => a.signal,
            },
            amplitude_frac: level_frac(a.level, a.amplitude)?,
            prbs_order: prbs_order_arg(a.prbs_order, a.order),
            samples_per_bit: a.samples_per_bit,
            periods: a.periods,
            f_min_hz: band.0,
            f_max_hz: band.1,
            period_s: a.period,
            seed: a.seed,
        },
        mode: match a.mode {
            ModeArg::Linear => Mode::Linear,
            ModeArg::Nonlinear => Mode::Nonlinear,
        },
        seed: a.seed,
        noise: !a.no_noise,
        record_b: a.record_b,
    };
    if a.truth_points < 2 {
        bail!("--truth-points must be at least 2");
    }
    if a.truth_points > MAX_TRUTH_POINTS {
        bail!(
            "--truth-points {} is more than the limit {MAX_TRUTH_POINTS}: truth.csv would hold \
             {} rows of exact FRFs (a log grid of 10^4 points already resolves every mode of \
             the twin); give at most {MAX_TRUTH_POINTS}",
            a.truth_points,
            a.truth_points
        );
    }
    let mut out = match &a.excitation_file {
        Some(p) => {
            let t = ambid::io::table::read_table(p, &Default::default())?;
            let r = t.column(&"r".into())?.to_vec();
            let ts = if t.names.iter().any(|n| n == "t") {
                Some(t.sample_time(Some(&"t".into()), None)?)
            } else {
                None
            };
            experiment::run_with_excitation(&exp, r, ts)
                .with_context(|| format!("--excitation-file {}", p.display()))?
        }
        None => experiment::run(&exp)?,
    };
    if let Some(spec) = &a.reference_chirp {
        let c: Vec<f64> = spec
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .ok()
            .filter(|v: &Vec<f64>| v.len() == 4)
            .with_context(|| {
                format!("--reference-chirp `{spec}`: give amplitude_m,duration_s,f0_hz,f1_hz, e.g. 5e-6,10,1,1000")
            })?;
        if exp.excitation.kind != ExcitationKind::None {
            bail!("--reference-chirp drives the loop by its position reference: use it with --signal none");
        }
        let w = ambid_core::signal::ChirpSpec {
            amplitude: c[0],
            duration_s: c[1],
            f0_hz: c[2],
            f1_hz: c[3],
            sweep: ambid_core::signal::Sweep::Linear,
            periods: 1,
        }
        .generate(out.twin.ts())
        .context("--reference-chirp amplitude_m,duration_s,f0_hz,f1_hz")?
        .values;
        let opts = ambid_twin::SimOptions {
            mode: exp.mode,
            seed: exp.seed,
            noise: exp.noise,
            record_b: exp.record_b,
            w: Some(w.clone()),
            ..ambid_twin::SimOptions::default()
        };
        out.record = out
            .twin
            .simulate(&vec![0.0; w.len()], &opts)
            .context("simulating the closed loop with the reference")?;
    }
    let rec = &out.record;
    let mut cols: Vec<(&str, &[f64])> = vec![
        ("t", &rec.t),
        ("w", &rec.w),
        ("r", &rec.r),
        ("u", &rec.u),
        ("i", &rec.i),
        ("y", &rec.y),
    ];
    if let Some(b) = &rec.b {
        cols.extend([("u_b", &b.u[..]), ("i_b", &b.i[..]), ("y_b", &b.y[..])]);
    }
    let mut set = OutputSet::new(a.force);
    set.write_with(&data_path, |w| time_csv_to(w, &cols))?;
    let grid = experiment::log_grid(1.0, 0.5 * out.twin.fs() * 0.999, a.truth_points);
    let truth = experiment::truth(&out.twin, &grid)?;
    let truth_bytes = frf_csv_bytes(
        &truth.f_hz,
        &[
            FrfColumn {
                name: "plant",
                values: &truth.plant,
                std: None,
            },
            FrfColumn {
                name: "t_ry",
                values: &truth.t_ry,
                std: None,
            },
            FrfColumn {
                name: "t_ru",
                values: &truth.t_ru,
                std: None,
            },
            FrfColumn {
                name: "controller",
                values: &truth.controller,
                std: None,
            },
        ],
        &[],
    )?;
    set.write(&truth_path, &truth_bytes)?;
    let meta = serde_json::json!({
        "excitation": match &a.excitation_file {
            Some(p) => serde_json::json!({ "file": p.display().to_string() }),
            None => serde_json::json!(exp.excitation),
        },
        "excitation_samples": out.excitation.values.len(),
        "period_samples": out.excitation.period_samples,
        "periods": out.excitation.periods,
        "simulation": rec.meta,
        "twin": exp.twin,
    });
    set.write(&meta_path, serde_json::to_string_pretty(&meta)?.as_bytes())?;
    set.write(
        &ctrl_path,
        ambid::io::controller::controller_toml_from_twin(&exp.twin).as_bytes(),
    )?;
    set.commit()?;
    println!(
        "simulated {} samples ({:.3} s at {} Hz), {} mode",
        rec.t.len(),
        rec.t.len() as f64 * rec.ts,
        out.twin.fs(),
        format!("{:?}", exp.mode).to_lowercase()
    );
    if let Some(l) = excitation_level(&out.excitation.values, exp.twin.magnet.i_sat_a) {
        println!("{l}");
    }
    let sat = rec.meta.saturated_fraction;
    if sat > 0.0 {
        eprintln!(
            "warning: the amplifier or controller output saturated in {:.3} % of the samples; \
             the data are not from a linear operating regime — reduce --level",
            100.0 * sat
        );
    }
    for p in [&data_path, &truth_path, &meta_path, &ctrl_path] {
        println!("written: {}", p.display());
    }
    Ok(())
}
