//! `ambid order`: ARX order scan.

use super::args::{DataFileArgs, Force, InputColumn, OutputColumn};
use super::common::{check_model_size, mean, read_io, read_validation};
use ambid::io::output::write_file;
use ambid::io::OutputSet;
use ambid_core::estimate::order::{arx_order_scan, ArxScanSpec};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct OrderArgs {
    /// Estimation data file (CSV, .npy, .npz, .mat, .parquet; docs/data-files.md).
    data: PathBuf,
    #[command(flatten)]
    file: DataFileArgs,
    #[command(flatten)]
    u: InputColumn,
    #[command(flatten)]
    y: OutputColumn,
    /// Largest na (the scan runs na = 1..=na-max).
    #[arg(long, default_value_t = 10)]
    na_max: usize,
    /// Largest nb (nb = 1..=nb-max).
    #[arg(long, default_value_t = 10)]
    nb_max: usize,
    /// Delays to try (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = vec![1usize])]
    nk: Vec<usize>,
    /// Validation data file (same columns and format).
    #[arg(long)]
    validation: Option<PathBuf>,
    /// Output CSV of the grid (one row per model).
    #[arg(long, default_value = "order.csv")]
    out: PathBuf,
    #[command(flatten)]
    f: Force,
}

pub fn order(a: OrderArgs) -> Result<()> {
    OutputSet::check(&a.out, a.f.force)?;
    if a.na_max == 0 || a.nb_max == 0 {
        return Err(ambid::error::Error::usage(
            "--na-max and --nb-max must be at least 1".to_string(),
        )
        .into());
    }
    if a.na_max > ambid::workflow::config::MAX_MODEL_ORDER
        || a.nb_max > ambid::workflow::config::MAX_MODEL_ORDER
    {
        return Err(ambid::error::Error::usage(format!(
            "--na-max {} / --nb-max {}: at most {} each (the scan fits every pair)",
            a.na_max,
            a.nb_max,
            ambid::workflow::config::MAX_MODEL_ORDER
        ))
        .into());
    }
    let rec = read_io(&a.data, &a.file, (&a.u.input, &a.y.output), "r")?;
    let (mut u, mut y, ts) = (rec.u().to_vec(), rec.y().to_vec(), rec.ts());
    check_model_size(
        y.len(),
        a.na_max + a.nb_max,
        "the largest model of the scan",
    )?;
    let (mu, my) = (mean(&u), mean(&y));
    u.iter_mut().for_each(|v| *v -= mu);
    y.iter_mut().for_each(|v| *v -= my);
    let val = match &a.validation {
        Some(p) => {
            let (uv, yv) = read_validation(p, &a.file, &a.u.input, &a.y.output, ts, mu, my)?;
            Some((yv, uv))
        }
        None => None,
    };
    let spec = ArxScanSpec::new(1..=a.na_max, 1..=a.nb_max, a.nk.clone());
    let scan = arx_order_scan(
        &y,
        &u,
        &spec,
        val.as_ref().map(|(y, u)| (y.as_slice(), u.as_slice())),
    )?;
    let show = |label: &str, i: usize| {
        let r = &scan.rows[i];
        println!(
            "{label}: ARX(na {}, nb {}, nk {}), loss {:.4e}, BIC {:.2}{}",
            r.na,
            r.nb,
            r.nk,
            r.loss,
            r.bic,
            r.val_fit.map_or(String::new(), |f| format!(
                ", validation 1-step fit {f:.2} %"
            ))
        )
    };
    println!("{} models, {} samples", scan.rows.len(), scan.n_samples);
    show("best BIC", scan.best_bic);
    show("best AIC", scan.best_aic);
    show("most parsimonious within BIC tolerance", scan.parsimonious);
    if let Some(k) = scan.knee {
        show("knee of the loss", k);
    }
    if let Some(b) = scan.best_val {
        show("best on validation", b);
    }
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in &scan.rows {
        w.serialize(r)?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| anyhow::anyhow!("{}", e.error()))?;
    write_file(&a.out, &bytes, a.f.force)?;
    println!("written: {}", a.out.display());
    Ok(())
}
