//! `ambid fit` and `ambid order`: parametric models and ARX order scans from time-domain data.

use ambid::io::model::{polynomial_json, write_model_json};
use ambid::io::read_time_csv;
use ambid_core::estimate::arx::{arx, fit_percent, ArxOrders};
use ambid_core::estimate::order::{arx_order_scan, ArxScanSpec};
use ambid_core::estimate::pem::{self, Focus, Orders, PemOptions};
use ambid_core::estimate::Fitted;
use ambid_core::lti::PolyModel;
use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use serde_json::json;
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StructureArg {
    Fir,
    Arx,
    Armax,
    Oe,
    Bj,
    /// State space by subspace identification (N4SID/CVA, order from --order or automatic),
    /// then prediction-error refinement (`--focus`; `--no-pem` skips it).
    Ss,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum FocusArg {
    Prediction,
    Simulation,
}

#[derive(Args)]
pub struct FitArgs {
    /// Estimation data CSV.
    data: PathBuf,
    /// Sample rate in Hz (when the file has no `t` column).
    #[arg(long)]
    fs: Option<f64>,
    /// Input column.
    #[arg(long, default_value = "u")]
    input: String,
    /// Output column.
    #[arg(long, default_value = "y")]
    output: String,
    /// Model structure.
    #[arg(long, value_enum)]
    structure: StructureArg,
    /// Order of A.
    #[arg(long, default_value_t = 0)]
    na: usize,
    /// Number of B coefficients.
    #[arg(long, default_value_t = 1)]
    nb: usize,
    /// Order of C.
    #[arg(long, default_value_t = 0)]
    nc: usize,
    /// Order of D.
    #[arg(long, default_value_t = 0)]
    nd: usize,
    /// Order of F.
    #[arg(long, default_value_t = 0)]
    nf: usize,
    /// Input delay in samples.
    #[arg(long, default_value_t = 1)]
    nk: usize,
    /// State-space order (`--structure ss`; automatic from the singular values when absent).
    #[arg(long)]
    order: Option<usize>,
    /// Block rows (past/future horizon) of the subspace step (`--structure ss`; automatic
    /// horizon ladder when absent).
    #[arg(long)]
    block_rows: Option<usize>,
    /// `--structure ss`: keep the subspace model, without the prediction-error refinement.
    #[arg(long)]
    no_pem: bool,
    /// Maximum Levenberg–Marquardt iterations of the prediction-error step.
    #[arg(long, default_value_t = 100)]
    max_iterations: usize,
    /// Fit to an FRF file instead of time data: the quantity to fit (e.g. `plant`, `t_ry`);
    /// structures arx, oe, ss; needs --fs.
    #[arg(long)]
    quantity: Option<String>,
    /// Band `f_min:f_max` in Hz of an FRF fit (default: every line).
    #[arg(long, value_parser = crate::cli_frf::parse_band)]
    band: Option<(f64, f64)>,
    /// Weights of the lines of an FRF fit.
    #[arg(long, value_enum, default_value_t = crate::cli_freqfit::WeightsArg::Variance)]
    weights: crate::cli_freqfit::WeightsArg,
    /// FRF fit: the controller of the loop the FRF was measured in (TOML/JSON): the fit is held
    /// to the plant's number of unstable poles from the measured loop's Nyquist count, and a
    /// model that does not close a stable loop with it is reported.
    #[arg(long)]
    controller: Option<PathBuf>,
    /// FRF fit: the number of unstable plant poles (instead of the Nyquist count).
    #[arg(long)]
    unstable_poles: Option<usize>,
    /// PEM criterion focus.
    #[arg(long, value_enum, default_value_t = FocusArg::Prediction)]
    focus: FocusArg,
    /// Validation data CSV (same columns).
    #[arg(long)]
    validation: Option<PathBuf>,
    /// Do not subtract the estimation data's means (they are subtracted from both records by
    /// default).
    #[arg(long)]
    no_detrend: bool,
    /// Output model JSON.
    #[arg(long, default_value = "model.json")]
    out: PathBuf,
}

fn read_io(
    p: &Path,
    fs: Option<f64>,
    input: &str,
    output: &str,
) -> Result<(Vec<f64>, Vec<f64>, f64)> {
    let d = read_time_csv(p, fs)?;
    let u = d.column(input)?.to_vec();
    let y = d.column(output)?.to_vec();
    Ok((u, y, d.ts))
}

/// Reads a validation record, checks its sample time against the estimation data's and removes
/// the estimation data's means (`mu` from u, `my` from y).
fn read_validation(
    p: &Path,
    fs: Option<f64>,
    input: &str,
    output: &str,
    ts: f64,
    mu: f64,
    my: f64,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let (mut u, mut y, tsv) = read_io(p, fs, input, output)?;
    if ((tsv - ts) / ts).abs() > 1e-9 {
        bail!(
            "the validation data are sampled at {} Hz, the estimation data at {} Hz",
            1.0 / tsv,
            1.0 / ts
        );
    }
    u.iter_mut().for_each(|v| *v -= mu);
    y.iter_mut().for_each(|v| *v -= my);
    Ok((u, y))
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// One-step and simulation fit (%) of a polynomial model on a record.
use ambid::fitting::poly_fits as fits;

pub fn fit(a: FitArgs) -> Result<()> {
    if let Some(q) = &a.quantity {
        use ambid_core::validate::compare::FitStructure;
        let (structure, order) = match a.structure {
            StructureArg::Arx => (FitStructure::Arx, a.order.unwrap_or(a.na)),
            StructureArg::Oe => (FitStructure::Oe, a.order.unwrap_or(a.nf)),
            StructureArg::Ss => match a.order {
                Some(n) => (FitStructure::Ss, n),
                None => bail!("a state-space fit to FRF data needs --order"),
            },
            _ => bail!("fits to FRF data support --structure arx, oe or ss (ARX/OE of order n: n numerator and n denominator coefficients after --nk delays)"),
        };
        return crate::cli_freqfit::fit_frf(
            &a.data,
            q,
            structure,
            order,
            a.nk,
            a.fs,
            a.band,
            a.weights,
            a.max_iterations,
            (a.controller.as_deref(), a.unstable_poles),
            &a.out,
        );
    }
    let (mut u, mut y, ts) = read_io(&a.data, a.fs, &a.input, &a.output)?;
    let (mu, my) = if a.no_detrend {
        (0.0, 0.0)
    } else {
        (mean(&u), mean(&y))
    };
    u.iter_mut().for_each(|v| *v -= mu);
    y.iter_mut().for_each(|v| *v -= my);
    let focus = match a.focus {
        FocusArg::Prediction => Focus::Prediction,
        FocusArg::Simulation => Focus::Simulation,
    };
    let (fitted, iterations): (Fitted<PolyModel>, Option<usize>) = match a.structure {
        StructureArg::Fir | StructureArg::Arx => {
            let na = if a.structure == StructureArg::Fir {
                0
            } else {
                a.na
            };
            let f = arx(&y, &[&u], &ArxOrders::siso(na, a.nb, a.nk), ts)?;
            let model = f.model.to_poly(0)?;
            (
                Fitted {
                    model,
                    params: f.params,
                    covariance: f.covariance,
                    loss: f.loss,
                    noise_variance: f.noise_variance,
                    n_samples: f.n_samples,
                },
                None,
            )
        }
        StructureArg::Ss => return fit_ss(&a, &u, &y, ts, mu, my),
        s => {
            let orders = match s {
                StructureArg::Armax => Orders::armax(a.na, a.nb, a.nc, a.nk),
                StructureArg::Oe => Orders::oe(a.nb, a.nf, a.nk),
                _ => Orders::bj(a.nb, a.nc, a.nd, a.nf, a.nk),
            };
            let structure = match s {
                StructureArg::Armax => ambid_core::lti::Structure::Armax,
                StructureArg::Oe => ambid_core::lti::Structure::Oe,
                _ => ambid_core::lti::Structure::Bj,
            };
            let opts = PemOptions::default()
                .with_focus(focus)
                .with_max_iterations(a.max_iterations)?;
            let (f, rep) = pem::pem(&y, &u, structure, &orders, ts, &opts)
                .context("prediction-error estimation")?;
            (f, Some(rep.iterations()))
        }
    };
    let m = &fitted.model;
    let std = fitted.std();
    println!(
        "{} model, {} parameters, {} samples{}",
        m.structure().name(),
        fitted.params.len(),
        fitted.n_samples,
        iterations.map_or(String::new(), |i| format!(", {i} LM iterations"))
    );
    for (k, p) in fitted.params.iter().enumerate() {
        match &std {
            Some(s) => println!("  θ[{k}] = {p:+.6e} ± {:.2e}", s[k]),
            None => println!("  θ[{k}] = {p:+.6e}"),
        }
    }
    println!(
        "loss V_N = {:.4e}, noise variance {:.4e}",
        fitted.loss, fitted.noise_variance
    );
    let poles = m.poles()?;
    let unstable = poles.iter().filter(|p| p.norm() >= 1.0).count();
    if unstable > 0 {
        println!("note: {unstable} pole(s) on or outside the unit circle (an unstable model; simulation fits diverge)");
    }
    let (f1, fs_est) = fits(m, &y, &u)?;
    println!("estimation data: 1-step fit {f1:.2} %, simulation fit {fs_est:.2} %");
    let mut val = json!(null);
    if let Some(p) = &a.validation {
        let (uv, yv) = read_validation(p, a.fs, &a.input, &a.output, ts, mu, my)?;
        let (v1, vs) = fits(m, &yv, &uv)?;
        println!("validation data: 1-step fit {v1:.2} %, simulation fit {vs:.2} %");
        val = json!({"one_step_fit_pct": v1, "simulation_fit_pct": vs});
    }
    let meta = json!({
        "params": fitted.params,
        "std": std,
        "loss": fitted.loss,
        "noise_variance": fitted.noise_variance,
        "n_samples": fitted.n_samples,
        "detrend": {"u_mean": mu, "y_mean": my},
        "estimation_fit_pct": {"one_step": f1, "simulation": fs_est},
        "validation": val,
        "source": a.data.display().to_string(),
    });
    write_model_json(&a.out, &polynomial_json(m, &a.input, &a.output, meta))?;
    println!("written: {}", a.out.display());
    Ok(())
}

#[derive(Args)]
pub struct OrderArgs {
    /// Estimation data CSV.
    data: PathBuf,
    /// Sample rate in Hz (when the file has no `t` column).
    #[arg(long)]
    fs: Option<f64>,
    /// Input column.
    #[arg(long, default_value = "u")]
    input: String,
    /// Output column.
    #[arg(long, default_value = "y")]
    output: String,
    /// Largest na (the scan runs na = 1..=na-max).
    #[arg(long, default_value_t = 10)]
    na_max: usize,
    /// Largest nb (nb = 1..=nb-max).
    #[arg(long, default_value_t = 10)]
    nb_max: usize,
    /// Delays to try (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = vec![1usize])]
    nk: Vec<usize>,
    /// Validation data CSV.
    #[arg(long)]
    validation: Option<PathBuf>,
    /// Output CSV of the grid (one row per model).
    #[arg(long, default_value = "order.csv")]
    out: PathBuf,
}

pub fn order(a: OrderArgs) -> Result<()> {
    if a.na_max == 0 || a.nb_max == 0 {
        bail!("--na-max and --nb-max must be at least 1");
    }
    let (mut u, mut y, ts) = read_io(&a.data, a.fs, &a.input, &a.output)?;
    let (mu, my) = (mean(&u), mean(&y));
    u.iter_mut().for_each(|v| *v -= mu);
    y.iter_mut().for_each(|v| *v -= my);
    let val = match &a.validation {
        Some(p) => {
            let (uv, yv) = read_validation(p, a.fs, &a.input, &a.output, ts, mu, my)?;
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
    if let Some(d) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    let mut w = csv::Writer::from_path(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    for r in &scan.rows {
        w.serialize(r)?;
    }
    w.flush()?;
    println!("written: {}", a.out.display());
    Ok(())
}

/// Subspace state-space fit: data scaled to unit RMS for the algorithm, model scaled back.
fn fit_ss(a: &FitArgs, u: &[f64], y: &[f64], ts: f64, mu: f64, my: f64) -> Result<()> {
    use ambid::io::model::state_space_json;
    use ambid_core::estimate::ss_pem::SsPemOptions;
    let pem = if a.no_pem {
        None
    } else {
        let focus = match a.focus {
            FocusArg::Prediction => Focus::Prediction,
            FocusArg::Simulation => Focus::Simulation,
        };
        Some(SsPemOptions {
            focus,
            lm: SsPemOptions::default()
                .lm
                .with_max_iterations(a.max_iterations)?,
            ..SsPemOptions::default()
        })
    };
    let fit =
        ambid::fitting::fit_state_space(u, y, ts, a.order, a.block_rows, pem).map_err(|e| {
            if a.no_pem {
                e
            } else {
                e.context("(use --no-pem to skip the refinement)")
            }
        })?;
    let mut pem_meta = json!(null);
    if let Some(p) = &fit.pem {
        println!(
            "prediction-error refinement ({:?} focus): loss {:.4e} -> {:.4e} after {} iterations ({}){}",
            p.focus,
            p.start_loss,
            p.loss,
            p.iterations,
            p.stop,
            if p.on_boundary { "; the optimum lies on the predictor's stability boundary" } else { "" }
        );
        pem_meta = json!({
            "focus": format!("{:?}", p.focus).to_lowercase(),
            "iterations": p.iterations,
            "stop": p.stop,
            "start_loss": p.start_loss,
            "loss": p.loss,
            "kalman_gain": p.kalman_gain,
        });
    }
    let model = fit.model.clone();
    println!(
        "state-space model of order {} (block rows {}), singular values: {}",
        fit.order,
        fit.block_rows,
        fit.singular_values
            .iter()
            .take(12)
            .map(|v| format!("{v:.3e}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    let unstable = model.poles()?.iter().filter(|p| p.norm() >= 1.0).count();
    if unstable > 0 {
        println!("note: {unstable} pole(s) on or outside the unit circle (not stabilised)");
    }
    let fit_on = |u: &[f64], y: &[f64]| -> Result<f64> {
        let ys = model.simulate_siso(u, None)?;
        Ok(fit_percent(y, &ys)?)
    };
    let f_est = fit_on(u, y)?;
    println!("estimation data: simulation fit {f_est:.2} %");
    let mut val = json!(null);
    if let Some(p) = &a.validation {
        let (uv, yv) = read_validation(p, a.fs, &a.input, &a.output, ts, mu, my)?;
        let fv = fit_on(&uv, &yv)?;
        println!("validation data: simulation fit {fv:.2} %");
        val = json!({"simulation_fit_pct": fv});
    }
    let meta = json!({
        "method": if a.no_pem { "subspace" } else { "subspace+pem" },
        "pem": pem_meta,
        "order": fit.order,
        "block_rows": fit.block_rows,
        "singular_values": fit.singular_values,
        "detrend": {"u_mean": mu, "y_mean": my},
        "estimation_fit_pct": {"simulation": f_est},
        "validation": val,
        "source": a.data.display().to_string(),
    });
    write_model_json(&a.out, &state_space_json(&model, &a.input, &a.output, meta))?;
    println!("written: {}", a.out.display());
    Ok(())
}
