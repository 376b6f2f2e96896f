//! `ambid compare-models` (the seed's table 1).

use super::args::parse_band;
use super::args::{ExcitationColumn, FileFormatArgs, Force, OutputColumn};
use super::common::{frf_input, WeightsArg};
use ambid::io::output::write_file;
use ambid::io::read_controller;
use ambid::io::OutputSet;
use ambid::stage::{choose, frf_candidates, unstable_pole_rule, FrfCandidates, Select};
use ambid_core::lti::Structure;
use ambid_core::validate::compare::{table, ValidationRecord};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
#[command(mut_arg("excitation", |a| a.help("Column of the excitation r in the validation record (a name, or `#k`)")))]
#[command(mut_arg("output", |a| a.help("Column of the measured output y in the validation record (a name, or `#k`)")))]
pub struct CompareModelsArgs {
    /// FRF CSV (as written by `ambid frf`).
    frf: PathBuf,
    /// Quantity of the FRF file to fit.
    #[arg(long, default_value = "plant")]
    quantity: String,
    /// Sample rate of the data in Hz (default: the `fs_hz` column of the FRF file).
    #[arg(long)]
    fs: Option<f64>,
    /// Structures to compare.
    #[arg(long, value_delimiter = ',', default_value = "arx,oe,ss",
          value_parser = crate::cli::args::structure_parser(&Structure::FRF))]
    structures: Vec<Structure>,
    /// Orders to compare.
    #[arg(long, value_delimiter = ',', default_value = "6,7,8,9")]
    orders: Vec<usize>,
    /// Input delay of the ARX and OE models in samples.
    #[arg(long, default_value_t = 1)]
    nk: usize,
    /// Band `f_min:f_max` in Hz (default: derived from the file, from the first to the last run
    /// of 3 lines whose 95 % interval is within ±20 % of the value; printed).
    #[arg(long, value_parser = parse_band)]
    band: Option<(f64, f64)>,
    /// Weights of the lines.
    #[arg(long, value_enum, default_value_t = WeightsArg::Model)]
    weights: WeightsArg,
    /// Levenberg–Marquardt iteration limit of each fit (400: on 20 random rigs, 5 of the 160
    /// OE/SS fits of orders 6–9 stopped at 100 iterations, 1 at 400; a fit that stops at the
    /// limit is noted in the table).
    #[arg(long, default_value_t = 400)]
    max_iterations: usize,
    /// Independent time record (columns r, y; CSV, .npy, .npz, .mat or .parquet) for the
    /// closed-loop validation fit.
    #[arg(long, requires = "controller")]
    validation: Option<PathBuf>,
    #[command(flatten)]
    file: FileFormatArgs,
    #[command(flatten)]
    r: ExcitationColumn,
    #[command(flatten)]
    y: OutputColumn,
    /// Controller file (TOML/JSON) for the closed-loop validation.
    #[arg(long)]
    controller: Option<PathBuf>,
    /// Samples at the start of the validation record left out of the fit (transient).
    #[arg(long, default_value_t = 0)]
    skip: usize,
    /// Number of unstable plant poles to fit (default: the Nyquist count of the measured loop
    /// with --controller; unconstrained without a controller).
    #[arg(long)]
    unstable_poles: Option<usize>,
    /// Output CSV of the comparison table.
    #[arg(long, default_value = "comparison.csv")]
    out: PathBuf,
    #[command(flatten)]
    f: Force,
}

pub fn compare(a: CompareModelsArgs) -> Result<()> {
    OutputSet::check(&a.out, a.f.force)?;
    let input = frf_input(
        &a.frf,
        &a.quantity,
        a.fs,
        a.band,
        a.weights,
        a.max_iterations,
    )?;
    if a.orders.contains(&0) {
        return Err(ambid::error::Error::usage(
            "--orders: every order must be at least 1".to_string(),
        )
        .into());
    }
    let fits = FrfCandidates {
        structures: &a.structures,
        orders: &a.orders,
        nk: a.nk,
        fit: input.opts.clone(),
    };
    let ctrl = match &a.controller {
        Some(c) => {
            let ctrl = read_controller(c)?;
            let ts = input.frd.ts().unwrap_or(1.0 / ctrl.fs_hz());
            ctrl.check_ts(ts)?;
            Some(ctrl)
        }
        None => None,
    };
    let ctrl_ss = ctrl.as_ref().map(|c| c.state_space());
    let rule = unstable_pole_rule(&input.frd, ctrl_ss, input.explicit_band, a.unstable_poles);
    println!("unstable plant poles: {}", rule.how);
    let (rows, controller_desc) = match (&a.validation, &ctrl) {
        (Some(v), Some(ctrl)) => {
            let d = a.file.read(v, a.fs)?;
            let (r, y) = (d.column(&a.r.excitation)?, d.column(&a.y.output)?);
            let rec = ValidationRecord {
                r,
                y,
                controller: ctrl.state_space(),
                skip: a.skip,
            };
            (
                frf_candidates(&input.frd, &fits, &rule, ctrl_ss, Some(rec))?,
                Some(ctrl.description().to_string()),
            )
        }
        _ => (
            frf_candidates(&input.frd, &fits, &rule, ctrl_ss, None)?,
            None,
        ),
    };
    print!("{}", table(&rows));
    if let Some(d) = controller_desc {
        println!("closed-loop validation with controller: {d}");
    }
    // the models stage's choice rule (`ambid run`'s, with the default `[models] select`): among
    // the valid rows only
    let choice = choose(&rows, Select::Validation);
    match choice.index.filter(|_| choice.among_valid) {
        Some(i) => println!(
            "chosen: {} {} (the best {} among the valid rows)",
            rows[i].structure.name(),
            rows[i].order,
            if rows[i].validation_fit.is_some() {
                "validation fit"
            } else {
                "BIC"
            }
        ),
        None => println!("chosen: none (no row is valid; see the notes)"),
    }
    let mut w = ::csv::Writer::from_writer(Vec::new());
    for r in &rows {
        w.serialize(r)?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| anyhow::anyhow!("{}", e.error()))?;
    write_file(&a.out, &bytes, a.f.force)?;
    println!("written: {}", a.out.display());
    Ok(())
}
