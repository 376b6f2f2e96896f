//! `ambid`: command-line front end. `main` only parses the command line (clap) and dispatches to
//! one file per command under `cli/` (see `ambid --help`); the exit code of an error follows one
//! rule for every command (`cli::exit::exit_code`, docs/workflow.md "Exit codes").

use anyhow::Result;
use clap::{Parser, Subcommand};

mod cli;

use cli::*;

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
    Run(run::RunArgs),
    /// Write a commented example workflow file.
    Init(init::InitArgs),
    /// Design an excitation signal, write it as CSV (t, r) and print its band/duration report.
    Excite(excite::ExciteArgs),
    /// Compare PRBS, chirp, white noise and multisine at one RMS level (the seed paper's figure 3):
    /// print their statistics, write their waveforms, spectra and autocorrelations.
    Compare(compare::CompareArgs),
    /// Run the embedded AMB twin in closed loop and write data.csv, truth.csv, meta.json and
    /// controller.toml (the rig's controller, for `frf --controller` and `validate`); with
    /// `--axes 4` the whole rotor under a multi-axis design: exp1/data.csv …, the 4×4 truth.csv
    /// and meta.json.
    Simulate(simulate::SimulateArgs),
    /// Print the twin's default configuration (or a random rig's, with --rig-seed) as TOML (edit
    /// it and pass it with --config).
    Config(common::RigArgs),
    /// Print the twin's linearised facts: closed-loop modes, peak sensitivity, unstable plant poles
    /// (with `--axes 4` the whole rotor's: inertias, modes with whirl, peak |S| per axis, 1×).
    Info(info::InfoArgs),
    /// Nonparametric closed-loop FRFs from recorded data (T_ry, S, plant by the joint and, with a
    /// controller file, the indirect method, the controller from data), with standard deviations,
    /// coherences, quality measures and resonance peaks; writes the FRF CSV. Several experiment
    /// files (or `r_<axis>` columns): the 4×4 MIMO FRF as a matrix FRF CSV.
    Frf(frf::FrfArgs),
    /// The seed paper's studies: excitation amplitude and operating point.
    #[command(subcommand)]
    Study(study::StudyCmd),
    /// Fit a parametric model (FIR, ARX by least squares; ARMAX, OE, BJ by the prediction-error
    /// method) to time-domain data; print parameters ± std and fits; write the model JSON.
    Fit(fit::FitArgs),
    /// ARX order scan over na × nb (× nk): loss, AIC, BIC, FPE (and validation fit); writes the grid.
    Order(order::OrderArgs),
    /// Fit ARX, OE and state-space models of several orders to one FRF and compare them
    /// (frequency errors, BIC, closed-loop validation fit with the controller, unstable poles):
    /// the seed paper's table 1; writes the table as CSV.
    CompareModels(compare_models::CompareModelsArgs),
    /// Validate a model on an independent record through the closed loop with the controller:
    /// fits of displacement and current, windows, residual tests, closed-loop poles, margins and
    /// the ISO 14839-3 zone; writes summary.json, timeseries.csv and residuals.csv.
    Validate(validate::ValidateArgs),
    /// Robust Best Linear Approximation of the plant (M random-phase multisines × P periods) on
    /// the twin or from recorded realisations (--record PCT:PATH): noise and nonlinear variance
    /// per RMS level and the recommended level, or for one level the per-line BLA with its total,
    /// noise and nonlinear standard deviations.
    Bla(bla::BlaArgs),
    /// Campbell diagram of the 4-axis twin: the true closed-loop modes (frequency, damping,
    /// forward/backward whirl) against rotor speed, with the 1× line; writes the CSV.
    Campbell(campbell::CampbellArgs),
    /// The uncertainty of a nominal plant model over frequency (FRF confidence carried through
    /// the fit, significant model error), the stable minimum-phase weight W of order <= 4 that
    /// overbounds it, the robust stability of the controller against P = Pnom (1 + W Delta), and
    /// the uncertain model for MATLAB (ultidyn x W) and Python; writes uncertainty.csv,
    /// robust.csv, summary.json and uncertain.{m,mat,npz,json}.
    Uncertainty(uncertainty::UncertaintyArgs),
    /// Physical parameters from the measured plant (gray box): k_i and k_x, the bending mode's
    /// frequency, damping and mode shape with confidence intervals, from the FRF, an identified
    /// black-box model (for the starts), the controller and the drawing (rotor mass, inertia,
    /// bearing positions, amplifier and sensor); writes physical.json.
    Physical(physical::PhysicalArgs),
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
        std::process::exit(exit::exit_code(&e));
    }
}

fn dispatch(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Run(a) => run::run(a),
        Command::Init(a) => init::init(a),
        Command::Excite(a) => excite::excite(a),
        Command::Compare(a) => compare::compare(a),
        Command::Simulate(a) => simulate::simulate(a),
        Command::Config(a) => config::config(a),
        Command::Info(a) => info::info(a),
        Command::Frf(a) => frf::frf(a),
        Command::Study(c) => study::study(c),
        Command::Fit(a) => fit::fit(a),
        Command::Order(a) => order::order(a),
        Command::CompareModels(a) => compare_models::compare(a),
        Command::Validate(a) => validate::validate(a),
        Command::Bla(a) => bla::bla(a),
        Command::Campbell(a) => campbell::campbell(a),
        Command::Uncertainty(a) => uncertainty::uncertainty(a),
        Command::Physical(a) => physical::physical(a),
    }
}
