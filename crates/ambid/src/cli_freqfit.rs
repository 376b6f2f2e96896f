//! `ambid fit <frf.csv> --quantity q` (parametric models fitted to FRF data) and
//! `ambid compare-models` (the seed's table 1).

use crate::cli_frf::parse_band;
use ambid::io::csv::read_frf_csv;
use ambid::io::model::{model_json_bytes, state_space_json};
use ambid::io::output::write_file;
use ambid::io::OutputSet;
use ambid::io::{read_controller, read_time_csv};
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::frf::band::{fit_band, FIT_REL_HALFWIDTH};
use ambid_core::lti::Structure as FitStructure;
use ambid_core::validate::compare::{
    choose, compare_models, supported_unstable_poles, table, CompareSpec, ValidationRecord,
};
use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use serde_json::json;
use std::path::{Path, PathBuf};

/// Weights of the FRF lines.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum WeightsArg {
    /// All lines alike.
    Uniform,
    /// Inverse variance from the file's `<q>_std` column (the default).
    Variance,
    /// From the coherence column (`coh_ry`).
    Coherence,
}

/// The FRF and the fit options common to `fit --quantity` and `compare-models`.
pub struct FrfInput {
    pub frd: ambid_core::lti::Frd,
    pub opts: FreqFitOptions,
    /// The band the user gave (`--band`), `None` when it was derived from the file.
    pub explicit_band: Option<(f64, f64)>,
}

/// Reads quantity `q` of an FRF CSV with sample rate `fs` and builds the fit options.
pub fn frf_input(
    path: &Path,
    quantity: &str,
    fs: Option<f64>,
    band: Option<(f64, f64)>,
    weights: WeightsArg,
    max_iterations: usize,
) -> Result<FrfInput> {
    let file = read_frf_csv(path)?;
    // the sample rate: --fs, else the `fs_hz` column that `ambid frf` writes
    let fs = match (fs, file.extra("fs_hz").ok().and_then(|c| c.first().copied())) {
        (Some(fs), _) => fs,
        (None, Some(fs)) => fs,
        (None, None) => return Err(ambid::workflow::usage(anyhow::anyhow!(
            "this FRF file has no `fs_hz` column: give the sample rate of the data with --fs (e.g. --fs 20000)"
        )).into()),
    };
    if !(fs.is_finite() && fs > 0.0) {
        return Err(ambid::workflow::usage(anyhow::anyhow!(
            "the sample rate must be positive and finite, got {fs:e} Hz"
        ))
        .into());
    }
    let frd = file.frd(quantity, 1.0 / fs)?;
    // the band: --band, else where the file measures the quantity reliably (band::fit_band)
    let fit_band = match band {
        Some(b) => b,
        None => {
            let d = fit_band(&frd, FIT_REL_HALFWIDTH)?;
            println!("{}", d.describe());
            d.band
        }
    };
    let weights = match weights {
        WeightsArg::Uniform => FreqWeights::Uniform,
        WeightsArg::Variance if frd.variance().is_some() => FreqWeights::InverseVariance,
        WeightsArg::Variance => {
            eprintln!("note: `{quantity}_std` is zero everywhere (exact data): uniform weights");
            FreqWeights::Uniform
        }
        WeightsArg::Coherence => FreqWeights::Coherence(
            file.extra("coh_ry")
                .context("coherence weights need the `coh_ry` column of `ambid frf`")?
                .to_vec(),
        ),
    };
    let opts = FreqFitOptions {
        band_hz: Some(fit_band),
        weights,
        max_iterations,
        ..FreqFitOptions::default()
    };
    Ok(FrfInput {
        frd,
        opts,
        explicit_band: band,
    })
}

/// Fits one structure and order to the FRF and writes the model JSON.
#[allow(clippy::too_many_arguments)]
pub fn fit_frf(
    path: &Path,
    quantity: &str,
    structure: FitStructure,
    order: usize,
    nk: usize,
    fs: Option<f64>,
    band: Option<(f64, f64)>,
    weights: WeightsArg,
    max_iterations: usize,
    (controller, unstable_poles): (Option<&Path>, Option<usize>),
    (out, force): (&Path, bool),
) -> Result<()> {
    OutputSet::check(out, force)?;
    let input = frf_input(path, quantity, fs, band, weights, max_iterations)?;
    if order == 0 {
        return Err(ambid::workflow::usage(anyhow::anyhow!(
            "--order must be at least 1 for a fit to FRF data"
        ))
        .into());
    }
    let ctrl = match controller {
        Some(c) => {
            let ctrl = read_controller(c)?;
            ctrl.check_ts(input.frd.ts().unwrap_or(1.0 / ctrl.fs_hz()))?;
            Some(ctrl)
        }
        None => None,
    };
    let (n_u, how) = supported_unstable_poles(
        &input.frd,
        ctrl.as_ref().map(|c| c.state_space()),
        input.explicit_band,
        unstable_poles,
    );
    println!("unstable plant poles: {how}");
    let spec = CompareSpec {
        structures: vec![structure],
        orders: vec![order],
        nk,
        fit: input.opts.clone(),
        unstable_poles: n_u,
        controller: ctrl.as_ref().map(|c| c.state_space().clone()),
        ..CompareSpec::default()
    };
    let rows = compare_models(&input.frd, &spec, None)?;
    let row = &rows[0];
    let Some(model) = &row.model else {
        return Err(ambid::workflow::computation(anyhow::anyhow!(
            "{} fit of order {order} failed: {}",
            structure.name(),
            row.note.as_deref().unwrap_or("unknown reason")
        ))
        .into());
    };
    print!("{}", table(&rows));
    if row.converged == Some(false) {
        eprintln!(
            "warning: the {} fit of order {order} stopped at its iteration limit ({max_iterations} \
             iterations) before converging: raise --max-iterations",
            structure.name()
        );
    }
    if !row.valid {
        eprintln!(
            "warning: the model is written but is not valid: {}",
            row.note.as_deref().unwrap_or("see the table")
        );
    }
    let pz = ambid_core::validate::pz::PzAnalysis::from_state_space(
        model,
        &ambid_core::validate::pz::PzOptions::default(),
    )?;
    print!("{}", pz.table());
    let meta = json!({
        "method": format!("{}_frd", structure.name()),
        "quantity": quantity,
        "order": order,
        "n_params": row.n_params,
        "band_hz": input.opts.band_hz,
        "band_origin": if input.explicit_band.is_some() { "given (--band)" } else { "derived from the FRF's standard deviations (ambid_core::frf::band::fit_band)" },
        "relative_rmse": row.relative_rmse,
        "median_relative": row.median_relative,
        "db_rmse": row.db_rmse,
        "bic": row.bic,
        "unstable_poles": row.unstable_poles,
        "unstable_poles_supported": n_u,
        "valid": row.valid,
        "converged": row.converged,
        "source": path.display().to_string(),
    });
    write_file(
        out,
        &model_json_bytes(&state_space_json(model, "u", quantity, meta))?,
        force,
    )?;
    println!("written: {}", out.display());
    Ok(())
}

#[derive(Args)]
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
    #[arg(long, value_delimiter = ',', default_value = "arx,oe,ss")]
    structures: Vec<StructureName>,
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
    #[arg(long, value_enum, default_value_t = WeightsArg::Variance)]
    weights: WeightsArg,
    /// Levenberg–Marquardt iteration limit of each fit (400: on 20 random rigs, 5 of the 160
    /// OE/SS fits of orders 6–9 stopped at 100 iterations, 1 at 400; a fit that stops at the
    /// limit is noted in the table).
    #[arg(long, default_value_t = 400)]
    max_iterations: usize,
    /// Independent time record (columns r, y) for the closed-loop validation fit.
    #[arg(long, requires = "controller")]
    validation: Option<PathBuf>,
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
    /// Replace the output file if it exists.
    #[arg(long)]
    force: bool,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StructureName {
    Arx,
    Oe,
    Ss,
}

impl From<StructureName> for FitStructure {
    fn from(s: StructureName) -> Self {
        match s {
            StructureName::Arx => FitStructure::Arx,
            StructureName::Oe => FitStructure::Oe,
            StructureName::Ss => FitStructure::Ss,
        }
    }
}

pub fn compare(a: CompareModelsArgs) -> Result<()> {
    OutputSet::check(&a.out, a.force)?;
    let input = frf_input(
        &a.frf,
        &a.quantity,
        a.fs,
        a.band,
        a.weights,
        a.max_iterations,
    )?;
    let mut spec = CompareSpec {
        structures: a.structures.iter().map(|s| (*s).into()).collect(),
        orders: a.orders.clone(),
        nk: a.nk,
        fit: input.opts.clone(),
        ..CompareSpec::default()
    };
    if spec.orders.contains(&0) {
        return Err(ambid::workflow::usage(anyhow::anyhow!(
            "--orders: every order must be at least 1"
        ))
        .into());
    }
    let ctrl = match &a.controller {
        Some(c) => {
            let ctrl = read_controller(c)?;
            let ts = input.frd.ts().unwrap_or(1.0 / ctrl.fs_hz());
            ctrl.check_ts(ts)?;
            Some(ctrl)
        }
        None => None,
    };
    let (n_u, how) = supported_unstable_poles(
        &input.frd,
        ctrl.as_ref().map(|c| c.state_space()),
        input.explicit_band,
        a.unstable_poles,
    );
    println!("unstable plant poles: {how}");
    spec.unstable_poles = n_u;
    spec.controller = ctrl.as_ref().map(|c| c.state_space().clone());
    let (rows, controller_desc) = match (&a.validation, &ctrl) {
        (Some(v), Some(ctrl)) => {
            let d = read_time_csv(v, a.fs)?;
            let (r, y) = (d.column("r")?, d.column("y")?);
            let rec = ValidationRecord {
                r,
                y,
                controller: ctrl.state_space(),
                skip: a.skip,
            };
            (
                compare_models(&input.frd, &spec, Some(rec))?,
                Some(ctrl.description().to_string()),
            )
        }
        _ => (compare_models(&input.frd, &spec, None)?, None),
    };
    print!("{}", table(&rows));
    if let Some(d) = controller_desc {
        println!("closed-loop validation with controller: {d}");
    }
    match choose(&rows) {
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
    write_file(&a.out, &bytes, a.force)?;
    println!("written: {}", a.out.display());
    Ok(())
}
