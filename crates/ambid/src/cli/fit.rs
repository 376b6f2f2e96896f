//! `ambid fit` and `ambid order`: parametric models and ARX order scans from time-domain data.

use super::args::{DataFileArgs, ExcitationColumn, Force, InputColumn, OutputColumn};
use super::common::{check_model_size, mean, read_io, read_validation};
use super::common::{frf_input, WeightsArg, X0Arg};
use ambid::io::model::state_space_json;
use ambid::io::model::{model_json_bytes, polynomial_json};
use ambid::io::output::write_file;
use ambid::io::read_controller;
use ambid::io::OutputSet;
use ambid::stage::{frf_candidates, unstable_pole_rule, FrfCandidates};
use ambid_core::estimate::pem::{self, Focus, Orders, PemOptions};
use ambid_core::estimate::Fitted;
use ambid_core::lti::{PolyModel, Structure};
use ambid_core::validate::compare::table;
use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use serde_json::json;
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, ValueEnum)]
pub enum FocusArg {
    Prediction,
    Simulation,
}

/// Whether the data were measured in open or closed loop.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LoopArg {
    /// Closed if the file has the excitation column (`--excitation`, default `r`) and the input
    /// is not that column (ambid's closed-loop record `t, w, r, u, i, y`), open otherwise.
    Auto,
    /// Open-loop data: an unstable starting estimate is an artefact and is stabilised.
    Open,
    /// Closed-loop data (an AMB plant): instability of u → y is real; OE/BJ and the simulation
    /// focus refuse an unstable start.
    Closed,
}

#[derive(Args)]
#[command(mut_arg("excitation", |a| a.help("Column of the excitation r (a name, or `#k`): a record that has it is closed-loop data for `--loop auto`")))]
#[command(mut_arg("input", |a| a.help("Input column; several, comma-separated (`u1,u2`), for a MIMO state-space model (`--structure ss`)")))]
#[command(mut_arg("output", |a| a.help("Output column; several, comma-separated (`y1,y2`), for a MIMO state-space model")))]
pub struct FitArgs {
    /// Estimation data file (CSV, .npy, .npz, .mat, .parquet; docs/data-files.md), or an FRF
    /// CSV with --quantity.
    data: PathBuf,
    #[command(flatten)]
    file: DataFileArgs,
    #[command(flatten)]
    r: ExcitationColumn,
    #[command(flatten)]
    u: InputColumn,
    #[command(flatten)]
    y: OutputColumn,
    /// Model structure; `ss` is state space by subspace identification (N4SID/CVA, order from
    /// --order or automatic), then prediction-error refinement (`--focus`; `--no-pem` skips it).
    #[arg(long, value_parser = crate::cli::args::structure_parser(&Structure::TIME_DOMAIN))]
    structure: Structure,
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
    /// `--structure ss`: estimate a feed-through D (default D = 0, a strictly proper model);
    /// D is estimated by the prediction-error refinement, so not with --no-pem.
    #[arg(long)]
    feedthrough: bool,
    /// Maximum Levenberg–Marquardt iterations of the prediction-error step.
    #[arg(long, default_value_t = 100)]
    max_iterations: usize,
    /// Fit to an FRF file instead of time data: the quantity to fit (e.g. `plant`, `t_ry`);
    /// structures arx, oe, ss; the sample rate from the file's `fs_hz` column (written by `ambid
    /// frf`), else --fs.
    #[arg(long)]
    quantity: Option<String>,
    /// Band `f_min:f_max` in Hz of an FRF fit (default: derived from the file, from the first to
    /// the last run of 3 lines whose 95 % interval is within ±20 % of the value; printed).
    #[arg(long, value_parser = super::args::parse_band)]
    band: Option<(f64, f64)>,
    /// Weights of the lines of an FRF fit.
    #[arg(long, value_enum, default_value_t = super::common::WeightsArg::Model)]
    weights: super::common::WeightsArg,
    /// FRF fit: the controller of the loop the FRF was measured in (TOML/JSON): the fit is held
    /// to the plant's number of unstable poles from the measured loop's Nyquist count, and a
    /// model that does not close a stable loop with it is reported.
    #[arg(long)]
    controller: Option<PathBuf>,
    /// FRF fit: the number of unstable plant poles (instead of the Nyquist count).
    #[arg(long)]
    unstable_poles: Option<usize>,
    /// PEM criterion focus (default: prediction for the polynomial structures; for `ss`,
    /// simulation when the subspace model is stable, else prediction).
    #[arg(long, value_enum)]
    focus: Option<FocusArg>,
    /// Validation data file (same columns and format).
    #[arg(long)]
    validation: Option<PathBuf>,
    /// Do not subtract the estimation data's means (they are subtracted from both records by
    /// default).
    #[arg(long)]
    no_detrend: bool,
    /// Initial state of the fit measures (estimation and validation): `estimate` (the state
    /// that best explains each record, MATLAB `compare`'s default) or `zero`.
    #[arg(long, value_enum, default_value_t = X0Arg::Estimate)]
    x0: X0Arg,
    /// Samples at the start of each record left out of the fit measures.
    #[arg(long, default_value_t = 0)]
    skip: usize,
    /// Open- or closed-loop data (decides whether an unstable starting estimate is stabilised;
    /// see docs/estimation.md).
    #[arg(long = "loop", value_enum, default_value_t = LoopArg::Auto)]
    loop_kind: LoopArg,
    /// Several outputs with `--structure arx|fir`: `full` (each output on the past of every
    /// output, MATLAB's multi-output ARX) or `diagonal` (one MISO ARX per output).
    #[arg(long, value_enum, default_value_t = CouplingArg::Full)]
    output_coupling: CouplingArg,
    /// Output model JSON.
    #[arg(long, default_value = "model.json")]
    out: PathBuf,
    #[command(flatten)]
    f: Force,
}

/// How the outputs of a multi-output ARX enter each other's equations.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CouplingArg {
    /// Full A_k matrices.
    Full,
    /// Diagonal A_k: one MISO ARX per output.
    Diagonal,
}

/// Open-loop data per `--loop` (module docs of [`LoopArg`]).
fn is_open_loop(a: &FitArgs, has_r: bool) -> bool {
    match a.loop_kind {
        LoopArg::Open => true,
        LoopArg::Closed => false,
        LoopArg::Auto => !(has_r && a.u.input != a.r.excitation),
    }
}

/// Whether an estimator error is about the data's dynamics (instability, numerics), so that a
/// fallback model can still be written, rather than about bad input.
fn is_model_problem(e: &ambid_core::Error) -> bool {
    matches!(
        e,
        ambid_core::Error::Unstable { .. } | ambid_core::Error::Numerical { .. }
    )
}

fn fmt_fit(f: Option<f64>) -> String {
    f.map_or_else(
        || "— (the model output diverges: unstable model)".to_string(),
        |v| format!("{v:.2} %"),
    )
}

/// RMS of the model error from a fit % over the samples from `skip` on:
/// $\lVert y - \hat y\rVert / \sqrt{N} = (1 - \mathrm{fit}/100)\,\lVert y - \bar y\rVert / \sqrt{N}$.
fn rms_error(fit: Option<f64>, y: &[f64], skip: usize) -> Option<f64> {
    let y = y.get(skip..).filter(|y| !y.is_empty())?;
    let m = y.iter().sum::<f64>() / y.len() as f64;
    let sd = (y.iter().map(|v| (v - m).powi(2)).sum::<f64>() / y.len() as f64).sqrt();
    fit.map(|f| (1.0 - f / 100.0) * sd)
}

/// The names of a polynomial model's parameters in the order of θ, as MATLAB's `idpoly`
/// displays them: `a1 … a_na` (A), `b_nk … b_{nk+nb−1}` (B, indexed by the power of
/// $q^{-1}$), `c1 …` (C), `d1 …` (D), `f1 …` (F). `None` when `theta` is not the model's
/// coefficients in that order (the plain θ[k] is printed then).
fn param_names(m: &PolyModel, theta: &[f64]) -> Option<Vec<String>> {
    let o = Orders::of(m);
    let mut names = Vec::with_capacity(theta.len());
    let mut vals = Vec::with_capacity(theta.len());
    let mut push = |letter: char, poly: &[f64], range: std::ops::Range<usize>| {
        for j in range {
            names.push(format!("{letter}{j}"));
            vals.push(poly.get(j).copied().unwrap_or(f64::NAN));
        }
    };
    push('a', m.a(), 1..o.na + 1);
    push('b', m.b(), o.nk..o.nk + o.nb);
    push('c', m.c(), 1..o.nc + 1);
    push('d', m.d(), 1..o.nd + 1);
    push('f', m.f(), 1..o.nf + 1);
    let same = vals.len() == theta.len()
        && vals
            .iter()
            .zip(theta)
            .all(|(v, t)| (v - t).abs() <= 1e-9 * (1.0 + t.abs()));
    same.then_some(names)
}

/// One-step and simulation fit (%) of a polynomial model on a record.
use ambid::fitting::poly_fits as fits;

/// Every order option at most [`ambid::workflow::config::MAX_MODEL_ORDER`] (FIR/ARX `--nb`/`--na`
/// excepted: those are bounded by [`check_model_size`]).
fn check_orders(a: &FitArgs) -> Result<()> {
    use ambid::workflow::config::MAX_MODEL_ORDER;
    let ls = matches!(a.structure, Structure::Arx | Structure::Fir);
    let mut opts = vec![
        ("--nc", a.nc),
        ("--nd", a.nd),
        ("--nf", a.nf),
        ("--nk", a.nk),
    ];
    if !ls {
        opts.extend([("--na", a.na), ("--nb", a.nb)]);
    }
    if let Some(o) = a.order {
        opts.push(("--order", o));
    }
    if let Some(b) = a.block_rows {
        opts.push(("--block-rows", b));
    }
    for (name, v) in opts {
        let cap = if name == "--block-rows" {
            10 * MAX_MODEL_ORDER
        } else {
            MAX_MODEL_ORDER
        };
        if v > cap {
            return Err(ambid::error::Error::usage(format!(
                "{name} {v} is more than {cap}, the largest ambid fits (50 rotor modes); give a smaller value"
            ))
            .into());
        }
    }
    Ok(())
}

pub fn fit(a: FitArgs) -> Result<()> {
    OutputSet::check(&a.out, a.f.force)?;
    check_orders(&a)?;
    if let Some(q) = &a.quantity {
        let (structure, order) = match a.structure {
            Structure::Arx => (Structure::Arx, a.order.unwrap_or(a.na)),
            Structure::Oe => (Structure::Oe, a.order.unwrap_or(a.nf)),
            Structure::Ss => match a.order {
                Some(n) => (Structure::Ss, n),
                None => return Err(ambid::error::Error::usage("a state-space fit to FRF data needs --order".to_string()).into()),
            },
            _ => return Err(ambid::error::Error::usage("fits to FRF data support --structure arx, oe or ss (ARX/OE of order n: n numerator and n denominator coefficients after --nk delays)".to_string()).into()),
        };
        return fit_frf(
            &a.data,
            q,
            structure,
            order,
            a.nk,
            a.file.fs,
            a.band,
            a.weights,
            a.max_iterations,
            (a.controller.as_deref(), a.unstable_poles),
            (&a.out, a.f.force),
        );
    }
    let split = |s: &str| -> Vec<String> { s.split(',').map(|c| c.trim().to_string()).collect() };
    let (ins, outs) = (split(&a.u.input), split(&a.y.output));
    if ins.len() > 1 || outs.len() > 1 {
        return match a.structure {
            Structure::Ss => fit_ss_mimo(&a, &ins, &outs),
            Structure::Arx | Structure::Fir => fit_arx_mimo(&a, &ins, &outs),
            _ => Err(ambid::error::Error::usage(format!(
                "several inputs or outputs ({} → {}) need --structure ss, arx or fir (the multi-input multi-output paths); armax, oe and bj are single-input single-output here: fit one output (and input) at a time",
                a.u.input,
                a.y.output
            ))
            .into()),
        };
    }
    let rec = read_io(&a.data, &a.file, (&a.u.input, &a.y.output), &a.r.excitation)?;
    let (mut u, mut y, ts, has_r) = (
        rec.u().to_vec(),
        rec.y().to_vec(),
        rec.ts(),
        rec.r().is_some(),
    );
    let open_loop = is_open_loop(&a, has_r);
    let params = match a.structure {
        Structure::Ss => a.order.unwrap_or(0),
        Structure::Fir => a.nb,
        _ => a.na + a.nb + a.nc + a.nd + a.nf,
    };
    check_model_size(y.len(), params, "the model")?;
    let (mu, my) = if a.no_detrend {
        (0.0, 0.0)
    } else {
        (mean(&u), mean(&y))
    };
    u.iter_mut().for_each(|v| *v -= mu);
    y.iter_mut().for_each(|v| *v -= my);
    let focus = match a.focus {
        None | Some(FocusArg::Prediction) => Focus::Prediction,
        Some(FocusArg::Simulation) => Focus::Simulation,
    };
    let mut problems: Vec<String> = Vec::new();
    let mut fallback = false;
    let mut stop: Option<String> = None;
    let (fitted, iterations): (Fitted<PolyModel>, Option<usize>) = match a.structure {
        Structure::Fir | Structure::Arx => {
            let na = if a.structure == Structure::Fir {
                0
            } else {
                a.na
            };
            (
                ambid::fitting::arx_fitted(&y, &u, na, a.nb, a.nk, ts)?,
                None,
            )
        }
        Structure::Ss => return fit_ss(&a, &u, &y, ts, (mu, my), open_loop),
        s => {
            let orders = match s {
                Structure::Armax => Orders::armax(a.na, a.nb, a.nc, a.nk),
                Structure::Oe => Orders::oe(a.nb, a.nf, a.nk),
                _ => Orders::bj(a.nb, a.nc, a.nd, a.nf, a.nk),
            };
            let structure = match s {
                Structure::Armax => Structure::Armax,
                Structure::Oe => Structure::Oe,
                _ => Structure::Bj,
            };
            let opts = PemOptions::default()
                .with_focus(focus)
                .with_max_iterations(a.max_iterations)?
                .with_open_loop(open_loop);
            match pem::pem(&y, &u, structure, &orders, ts, &opts) {
                Ok((f, rep)) => {
                    problems.extend(rep.warnings.iter().cloned());
                    if !rep.reason().converged() {
                        problems.push(format!(
                            "the iteration stopped at its limit ({} iterations, {}): raise --max-iterations",
                            rep.iterations(),
                            stop_reason_text(rep.reason())
                        ));
                    }
                    stop = Some(stop_reason_text(rep.reason()).to_string());
                    (f, Some(rep.iterations()))
                }
                Err(e) if is_model_problem(&e) => {
                    // a model is always written: the ARX model of the same orders, with the
                    // problem named (closed-loop advice only for closed-loop data)
                    let na = orders.na + orders.nf;
                    problems.push(format!("{} estimation failed: {e}", structure.name()));
                    problems.push(format!(
                        "written instead: the least-squares ARX({na}, {}, {}) model",
                        a.nb, a.nk
                    ));
                    if open_loop {
                        problems.push("the data were taken as open-loop (--loop); for data measured around an unstable plant in closed loop use --loop closed".to_string());
                    }
                    fallback = true;
                    (
                        ambid::fitting::arx_fitted(&y, &u, na, a.nb, a.nk, ts)?,
                        None,
                    )
                }
                Err(e) => return Err(anyhow::Error::new(e).context("prediction-error estimation")),
            }
        }
    };
    let m = &fitted.model;
    let std = fitted.std();
    println!(
        "{} model, {} parameters, {} samples{}",
        m.structure().name(),
        fitted.params.len(),
        fitted.n_samples,
        iterations.map_or(String::new(), |i| format!(
            ", {i} LM iterations{}",
            stop.as_deref()
                .map_or(String::new(), |s| format!(" (stopped: {s})"))
        ))
    );
    let names = param_names(m, &fitted.params);
    for (k, p) in fitted.params.iter().enumerate() {
        let name = names
            .as_ref()
            .map_or_else(|| format!("θ[{k}]"), |n| n[k].clone());
        match &std {
            Some(s) => println!("  {name:<4} = {p:+.6e} ± {:.2e}", s[k]),
            None => println!("  {name:<4} = {p:+.6e}"),
        }
    }
    println!(
        "loss V_N = {:.4e}, noise variance {:.4e}",
        fitted.loss, fitted.noise_variance
    );
    let poles = m.poles()?;
    let unstable = poles.iter().filter(|p| p.norm() >= 1.0).count();
    if unstable > 0 {
        problems.push(format!("{unstable} pole(s) on or outside the unit circle (an unstable model: its simulation diverges; judge it by the 1-step fit)"));
    }
    let (x0, skip) = (a.x0.core(), a.skip);
    let (f1, fs_est) = fits(m, &y, &u, x0, skip)?;
    println!(
        "estimation data: 1-step fit {}, simulation fit {} (initial state: {}{})",
        fmt_fit(f1),
        fmt_fit(fs_est),
        x0.name(),
        if skip > 0 {
            format!(", first {skip} samples skipped")
        } else {
            String::new()
        }
    );
    let mut val = json!(null);
    if let Some(p) = &a.validation {
        let (uv, yv) = read_validation(p, &a.file, &a.u.input, &a.y.output, ts, mu, my)?;
        let (v1, vs) = fits(m, &yv, &uv, x0, skip)?;
        println!(
            "validation data: 1-step fit {}, simulation fit {}",
            fmt_fit(v1),
            fmt_fit(vs)
        );
        val = json!({
            "one_step_fit_pct": v1,
            "simulation_fit_pct": vs,
            "one_step_rms": rms_error(v1, &yv, skip),
            "simulation_rms": rms_error(vs, &yv, skip),
        });
    }
    for p in &problems {
        println!("warning: {p}");
    }
    let meta = json!({
        "params": fitted.params,
        "param_names": names,
        "std": std,
        "loss": fitted.loss,
        "noise_variance": fitted.noise_variance,
        "n_samples": fitted.n_samples,
        "detrend": {"u_mean": mu, "y_mean": my},
        "estimation_fit_pct": {"one_step": f1, "simulation": fs_est},
        "validation": val,
        "initial_state": x0.name(),
        "skip": skip,
        "fallback": fallback,
        "iterations": iterations,
        "stop": stop,
        "loop": if open_loop { "open" } else { "closed" },
        "problems": problems,
        "source": a.data.display().to_string(),
    });
    write_file(
        &a.out,
        &model_json_bytes(&polynomial_json(m, &a.u.input, &a.y.output, meta))?,
        a.f.force,
    )?;
    println!("written: {}", a.out.display());
    Ok(())
}

/// Subspace state-space fit: data scaled to unit RMS for the algorithm, model scaled back.
/// A refinement that fails (an unstable start under the simulation focus) is retried, for
/// open-loop data, from the subspace model with its poles beyond |z| = 0.99 moved onto 0.99
/// ([`stabilised_refine`]); if that fails too, the subspace model is written with the problem
/// named. A model file is always written.
fn fit_ss(
    a: &FitArgs,
    u: &[f64],
    y: &[f64],
    ts: f64,
    (mu, my): (f64, f64),
    open_loop: bool,
) -> Result<()> {
    use ambid::fitting::{SsFitOptions, SsFocus};
    use ambid::io::model::state_space_json;
    use ambid_core::estimate::ss_pem::SsPemOptions;
    use ambid_core::estimate::subspace::HorizonCriterion;
    if a.no_pem && a.feedthrough {
        return Err(ambid::error::Error::usage(
            "--feedthrough needs the prediction-error refinement (it estimates D); drop --no-pem"
                .to_string(),
        )
        .into());
    }
    let opts = SsFitOptions {
        order: a.order,
        block_rows: a.block_rows,
        focus: match (a.no_pem, a.focus) {
            (true, _) => SsFocus::None,
            (false, None) => SsFocus::Auto,
            (false, Some(FocusArg::Prediction)) => SsFocus::Prediction,
            (false, Some(FocusArg::Simulation)) => SsFocus::Simulation,
        },
        max_iterations: a.max_iterations,
        feedthrough: a.feedthrough,
    };
    let mut problems: Vec<String> = Vec::new();
    let mut method = if a.no_pem { "subspace" } else { "subspace+pem" };
    let fit = match ambid::fitting::identify_state_space(u, y, ts, &opts) {
        Ok(f) => f,
        Err(e) if a.no_pem => return Err(e.into()),
        Err(e) => {
            // the refinement failed: a model is still written
            let first = format!("{e:#}");
            let sub_opts = SsFitOptions {
                focus: SsFocus::None,
                ..opts
            };
            let sub = ambid::fitting::identify_state_space(u, y, ts, &sub_opts)
                .map_err(|_| e.context("(use --no-pem to skip the refinement)"))?;
            let retry = if open_loop {
                // from a stabilised start the model can be simulated: the simulation focus unless
                // the prediction focus was asked for
                let focus = match opts.focus {
                    SsFocus::Prediction => Focus::Prediction,
                    _ => Focus::Simulation,
                };
                let pem = SsPemOptions {
                    focus,
                    lm: SsPemOptions::default()
                        .lm
                        .with_max_iterations(a.max_iterations)?,
                    feedthrough: a.feedthrough,
                    ..SsPemOptions::default()
                };
                Some(stabilised_refine(u, y, ts, &sub.model, &pem))
            } else {
                None
            };
            match retry {
                Some(Ok((model, summary))) => {
                    problems.push(format!(
                        "the refinement from the subspace model failed ({first}); it was restarted from the subspace model with its poles beyond |z| = 0.99 moved onto 0.99 (open-loop data; the start only)"
                    ));
                    method = "subspace+stabilised start+pem";
                    ambid::fitting::SsIdentified {
                        model,
                        pem: Some(summary),
                        ..sub
                    }
                }
                other => {
                    problems.push(format!("the prediction-error refinement failed: {first}"));
                    if let Some(Err(e2)) = other {
                        problems.push(format!("from a stabilised start it failed too: {e2:#}"));
                    } else {
                        problems.push("closed-loop data (--loop): an unstable u → y start is taken as real; the simulation focus cannot fit an unstable system, use the prediction focus".to_string());
                    }
                    problems
                        .push("written instead: the subspace model without refinement".to_string());
                    method = "subspace (refinement failed)";
                    sub
                }
            }
        }
    };
    let mut pem_meta = json!(null);
    if let Some(p) = &fit.pem {
        println!(
            "prediction-error refinement ({} focus): loss {:.4e} -> {:.4e} after {} iterations ({}){}",
            format!("{:?}", p.focus).to_lowercase(),
            p.start_loss,
            p.loss,
            p.iterations,
            stop_reason_text(p.stop),
            if p.on_boundary { "; the optimum lies on the predictor's stability boundary" } else { "" }
        );
        if p.stop == ambid_core::estimate::pem::lm::StopReason::MaxIterations {
            problems.push(format!(
                "the prediction-error refinement stopped at its limit ({} iterations) before converging: raise --max-iterations",
                p.iterations
            ));
        }
        pem_meta = json!({
            "focus": format!("{:?}", p.focus).to_lowercase(),
            "iterations": p.iterations,
            "stop": format!("{:?}", p.stop),
            "start_loss": p.start_loss,
            "loss": p.loss,
            "kalman_gain": p.kalman_gain,
            "x0": p.x0,
        });
    }
    let model = fit.model.clone();
    let criterion = fit.block_rows_criterion.map(|c| match c {
        HorizonCriterion::Simulation => "simulation error",
        HorizonCriterion::Prediction => "one-step prediction error",
    });
    let horizon = match criterion {
        Some(c) => format!(
            "block rows {}, chosen by the {c} of {}",
            fit.block_rows,
            fit.block_rows_scan
                .iter()
                .map(|(i, v)| format!("{i}: {v:.3e}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        None => format!("block rows {}", fit.block_rows),
    };
    println!(
        "state-space model of order {} ({horizon}), singular values: {}",
        fit.order,
        fit.singular_values
            .iter()
            .take(12)
            .map(|v| format!("{v:.3e}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    let unstable = model.poles()?.iter().filter(|p| p.norm() >= 1.0).count();
    if unstable > 0 {
        problems.push(format!("{unstable} pole(s) on or outside the unit circle (not stabilised): the simulation diverges"));
    }
    let (x0, skip) = (a.x0.core(), a.skip);
    let fit_on = |u: &[f64], y: &[f64]| -> Result<Option<f64>> {
        let (ys, _) = ambid_core::validate::predict::ss_simulate(&model, y, u, x0)?;
        Ok(ambid_core::validate::predict::fit_from(y, &ys, skip))
    };
    let f_est = fit_on(u, y)?;
    println!(
        "estimation data: simulation fit {} (initial state: {})",
        fmt_fit(f_est),
        x0.name()
    );
    let mut val = json!(null);
    if let Some(p) = &a.validation {
        let (uv, yv) = read_validation(p, &a.file, &a.u.input, &a.y.output, ts, mu, my)?;
        let fv = fit_on(&uv, &yv)?;
        println!("validation data: simulation fit {}", fmt_fit(fv));
        val = json!({"simulation_fit_pct": fv, "simulation_rms": rms_error(fv, &yv, skip)});
    }
    for p in &problems {
        println!("warning: {p}");
    }
    let meta = json!({
        "method": method,
        "loop": if open_loop { "open" } else { "closed" },
        "pem": pem_meta,
        "order": fit.order,
        "block_rows": fit.block_rows,
        "block_rows_scan": fit.block_rows_scan,
        "block_rows_criterion": criterion,
        "singular_values": fit.singular_values,
        "detrend": {"u_mean": mu, "y_mean": my},
        "estimation_fit_pct": {"simulation": f_est},
        "validation": val,
        "initial_state": x0.name(),
        "skip": skip,
        "problems": problems,
        "source": a.data.display().to_string(),
    });
    let mut j = state_space_json(&model, &a.u.input, &a.y.output, meta);
    if let Some(x) = fit.pem.as_ref().and_then(|p| p.x0.clone()) {
        // the initial state the refinement estimated on the estimation record
        j["x0"] = json!(x);
    }
    write_file(&a.out, &model_json_bytes(&j)?, a.f.force)?;
    println!("written: {}", a.out.display());
    Ok(())
}

/// Prediction-error refinement of the subspace model `sub` (data units) from a stabilised
/// start: on unit-RMS data, the start's poles beyond $|z| = 0.99$ are moved radially onto 0.99
/// ([`ambid_core::estimate::pem::stabilise_start_polynomial`] on its denominator); if that
/// refinement fails (a companion form of high order is ill-conditioned), $A$ is scaled by
/// $0.99 / \max|\lambda|$. The refinement then moves every pole freely. SISO; open-loop data only.
fn stabilised_refine(
    u: &[f64],
    y: &[f64],
    ts: f64,
    sub: &ambid_core::lti::StateSpace,
    opts: &ambid_core::estimate::ss_pem::SsPemOptions,
) -> Result<(ambid_core::lti::StateSpace, ambid::fitting::PemSummary)> {
    use ambid_core::lti::{StateSpace, TransferFunction};
    use faer::{Mat, Scale};
    let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt();
    let (su, sy) = (rms(u), rms(y));
    let scaled = StateSpace::discrete(
        sub.a().to_owned(),
        sub.b() * Scale(su),
        sub.c() * Scale(1.0 / sy),
        sub.d() * Scale(su / sy),
        ts,
    )?;
    let um = Mat::from_fn(u.len(), 1, |k, _| u[k] / su);
    let ym = Mat::from_fn(y.len(), 1, |k, _| y[k] / sy);
    let refine = |start: &StateSpace| {
        ambid_core::estimate::ss_pem::refine_ss(ym.as_ref(), um.as_ref(), start, None, opts)
    };
    // first: only the poles beyond 0.99 moved (transfer-function route; fine for low orders)
    let per_pole = (|| -> Result<_> {
        let tf = TransferFunction::from_state_space(&scaled)?;
        let d0 = tf.den()[0];
        let den: Vec<f64> = tf.den().iter().map(|c| c / d0).collect();
        let num: Vec<f64> = tf.num().iter().map(|c| c / d0).collect();
        let den = ambid_core::estimate::pem::stabilise_start_polynomial(&den)
            .context("cannot stabilise the start: its poles could not be computed")?;
        let start = TransferFunction::new(num, den, ts)?.to_state_space()?;
        Ok(refine(&start)?)
    })();
    let p = match per_pole {
        Ok(p) => p,
        Err(_) => {
            // then: A scaled by 0.99 / max|λ| (every pole moved radially by the same factor;
            // no companion form, so it also works at high orders)
            let r = scaled.poles()?.iter().fold(0.0f64, |m, z| m.max(z.norm()));
            let rho = if r > 0.99 { 0.99 / r } else { 1.0 };
            let start = StateSpace::discrete(
                scaled.a() * Scale(rho),
                scaled.b().to_owned(),
                scaled.c().to_owned(),
                scaled.d().to_owned(),
                ts,
            )?;
            refine(&start)?
        }
    };
    let m = &p.fitted.model;
    let model = StateSpace::discrete(
        m.a().to_owned(),
        m.b() * Scale(1.0 / su),
        m.c() * Scale(sy),
        m.d() * Scale(sy / su),
        ts,
    )?;
    let summary = ambid::fitting::PemSummary::of_refinement(&p, opts.focus, sy);
    Ok((model, summary))
}

/// The named columns of a time-data file, each with the estimation means `means` removed
/// (`None`: its own means, returned).
fn columns(
    p: &Path,
    file: &DataFileArgs,
    names: &[String],
    means: Option<&[f64]>,
    detrend: bool,
) -> Result<(Vec<Vec<f64>>, Vec<f64>, f64)> {
    let d = file.read(p)?;
    let mut cols: Vec<Vec<f64>> = names
        .iter()
        .map(|n| Ok(d.column(n)?.to_vec()))
        .collect::<Result<_>>()?;
    let m: Vec<f64> = match means {
        Some(m) => m.to_vec(),
        None if detrend => cols.iter().map(|c| mean(c)).collect(),
        None => vec![0.0; cols.len()],
    };
    for (c, mv) in cols.iter_mut().zip(&m) {
        c.iter_mut().for_each(|v| *v -= mv);
    }
    Ok((cols, m, d.ts))
}

/// Multi-input multi-output state space (`--input u1,u2 --output y1,y2 --structure ss`): every
/// column scaled to unit RMS, subspace identification, the prediction-error refinement (a
/// refinement that fails leaves the subspace model, with the problem named), model scaled back;
/// simulation fit per output from the estimated initial state.
fn fit_ss_mimo(a: &FitArgs, ins: &[String], outs: &[String]) -> Result<()> {
    use ambid_core::estimate::ss_pem::{refine_ss, SsPemOptions};
    use ambid_core::estimate::subspace::{n4sid_detailed, SubspaceOptions};
    use ambid_core::lti::StateSpace;
    use faer::Mat;
    let (u, mu, ts) = columns(&a.data, &a.file, ins, None, !a.no_detrend)?;
    let (y, my, _) = columns(&a.data, &a.file, outs, None, !a.no_detrend)?;
    let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt();
    let su: Vec<f64> = u.iter().map(|c| rms(c)).collect();
    let sy: Vec<f64> = y.iter().map(|c| rms(c)).collect();
    if su.iter().chain(&sy).any(|v| *v == 0.0) {
        return Err(ambid::error::Error::input(
            "an input or output column is constant after removing its mean: nothing to identify"
                .to_string(),
        )
        .into());
    }
    let nt = u[0].len();
    let (m, l) = (u.len(), y.len());
    let um = Mat::from_fn(nt, m, |k, i| u[i][k] / su[i]);
    let ym = Mat::from_fn(nt, l, |k, j| y[j][k] / sy[j]);
    let mut opts = SubspaceOptions::new(ts);
    opts.order = a.order;
    opts.block_rows = a.block_rows;
    let sub = n4sid_detailed(ym.as_ref(), um.as_ref(), &opts).context("subspace identification")?;
    let mut scaled = sub.fitted.model.clone();
    let mut problems: Vec<String> = Vec::new();
    let mut method = "subspace";
    let mut pem_meta = json!(null);
    let mut x0_est: Option<Vec<f64>> = None;
    if a.feedthrough && a.no_pem {
        return Err(ambid::error::Error::usage(
            "--feedthrough needs the prediction-error refinement (it estimates D); drop --no-pem"
                .to_string(),
        )
        .into());
    }
    if !a.no_pem {
        let o = SsPemOptions {
            // the single-output rule (`SsFocus::Auto`): simulation for a stable subspace model
            focus: match a.focus {
                Some(FocusArg::Prediction) => Focus::Prediction,
                Some(FocusArg::Simulation) => Focus::Simulation,
                None if scaled.is_stable()? => Focus::Simulation,
                None => Focus::Prediction,
            },
            lm: SsPemOptions::default()
                .lm
                .with_max_iterations(a.max_iterations)?,
            feedthrough: a.feedthrough,
            ..SsPemOptions::default()
        };
        let k = match o.focus {
            Focus::Prediction => sub.kalman_gain.as_ref().map(|k| k.as_ref()),
            Focus::Simulation => None,
        };
        match refine_ss(ym.as_ref(), um.as_ref(), &scaled, k, &o) {
            Ok(p) => {
                pem_meta = json!({
                    "focus": format!("{:?}", o.focus).to_lowercase(),
                    "iterations": p.report.iterations,
                    "stop": format!("{:?}", p.report.reason),
                    "x0": p.x0,
                });
                x0_est = Some(p.x0.clone());
                scaled = p.fitted.model;
                method = "subspace+pem";
            }
            Err(e) => {
                problems.push(format!("the prediction-error refinement failed: {e}"));
                problems.push("written instead: the subspace model without refinement".into());
                method = "subspace (refinement failed)";
            }
        }
    }
    let sm = &scaled;
    let n = sm.order();
    let model = StateSpace::discrete(
        Mat::from_fn(n, n, |i, j| sm.a()[(i, j)]),
        Mat::from_fn(n, m, |i, k| sm.b()[(i, k)] / su[k]),
        Mat::from_fn(l, n, |j, i| sm.c()[(j, i)] * sy[j]),
        Mat::from_fn(l, m, |j, k| sm.d()[(j, k)] * sy[j] / su[k]),
        ts,
    )?;
    let head = format!(
        "state-space model of order {} ({} inputs, {} outputs; block rows {}), {method}",
        n, m, l, sub.block_rows
    );
    let meta = json!({
        "method": method,
        "pem": pem_meta,
        "order": n,
        "block_rows": sub.block_rows,
        "singular_values": sub.singular_values,
    });
    finish_mimo(
        a,
        ins,
        outs,
        MimoFit {
            model,
            means: (mu, my),
            ts,
            head,
            meta,
            problems,
            x0_est,
            one_step: None,
            model_lag: 0,
            data: (u, y),
        },
    )
}

/// Multi-input multi-output ARX/FIR (`--input u1,u2 --output y1,y2 --structure arx|fir`):
/// [`ambid_core::estimate::arx_mimo`] with common orders, full output coupling by default,
/// realised in state space for the simulation fits and the model file.
fn fit_arx_mimo(a: &FitArgs, ins: &[String], outs: &[String]) -> Result<()> {
    use ambid_core::estimate::arx_mimo::{arx_mimo, OutputCoupling};
    let (u, mu, ts) = columns(&a.data, &a.file, ins, None, !a.no_detrend)?;
    let (y, my, _) = columns(&a.data, &a.file, outs, None, !a.no_detrend)?;
    let na = if a.structure == Structure::Fir {
        0
    } else {
        a.na
    };
    let coupling = match a.output_coupling {
        CouplingArg::Full => OutputCoupling::Full,
        CouplingArg::Diagonal => OutputCoupling::Diagonal,
    };
    let yr: Vec<&[f64]> = y.iter().map(Vec::as_slice).collect();
    let ur: Vec<&[f64]> = u.iter().map(Vec::as_slice).collect();
    let m = arx_mimo(&yr, &ur, na, a.nb, a.nk, coupling, ts).context("multi-output ARX")?;
    let model = m.to_state_space()?;
    let lag = na.max(a.nk + a.nb - 1);
    let head = format!(
        "{} {} × {} (na {na}, nb {}, nk {}, output coupling {}), realised in state space of order {}",
        if na == 0 { "FIR" } else { "ARX" },
        outs.len(),
        ins.len(),
        a.nb,
        a.nk,
        match coupling {
            OutputCoupling::Full => "full",
            OutputCoupling::Diagonal => "diagonal",
        },
        model.order()
    );
    let meta = json!({
        "method": if na == 0 { "fir" } else { "arx" },
        "orders": {"na": na, "nb": a.nb, "nk": a.nk},
        "output_coupling": match coupling { OutputCoupling::Full => "full", OutputCoupling::Diagonal => "diagonal" },
        "loss": m.loss,
        "samples": m.n_samples,
    });
    let one_step: OneStep = Box::new(move |y: &[Vec<f64>], u: &[Vec<f64>]| {
        let yr: Vec<&[f64]> = y.iter().map(Vec::as_slice).collect();
        let ur: Vec<&[f64]> = u.iter().map(Vec::as_slice).collect();
        Ok(m.predict(&yr, &ur)?)
    });
    finish_mimo(
        a,
        ins,
        outs,
        MimoFit {
            model,
            means: (mu, my),
            ts,
            head,
            meta,
            problems: Vec::new(),
            x0_est: None,
            one_step: Some(one_step),
            model_lag: lag,
            data: (u, y),
        },
    )
}

/// One-step predictor of a MIMO model: outputs from the measured outputs and inputs.
type OneStep = Box<dyn Fn(&[Vec<f64>], &[Vec<f64>]) -> Result<Vec<Vec<f64>>>>;

/// A multi-input multi-output model ready for its fit measures and the model file.
struct MimoFit {
    /// The model in the data's units.
    model: ambid_core::lti::StateSpace,
    /// Input and output means removed from the estimation data.
    means: (Vec<f64>, Vec<f64>),
    ts: f64,
    /// First line printed.
    head: String,
    /// Method-specific metadata (merged into the model file's `meta`).
    meta: serde_json::Value,
    problems: Vec<String>,
    /// The initial state the estimator found, stored in the model file.
    x0_est: Option<Vec<f64>>,
    /// One-step predictor `(y, u) → ŷ`, for the structures with one, and the samples its
    /// start-up needs (left out of its fit).
    one_step: Option<OneStep>,
    model_lag: usize,
    /// The estimation record (inputs, outputs), means removed.
    data: (Vec<Vec<f64>>, Vec<Vec<f64>>),
}

/// Fit measures of a MIMO model on the estimation and validation records (simulation from the
/// `--x0` initial state, and the one-step prediction where the structure has one), printed and
/// written with the model.
fn finish_mimo(a: &FitArgs, ins: &[String], outs: &[String], f: MimoFit) -> Result<()> {
    use ambid::io::model::state_space_json;
    use ambid_core::validate::predict::{fit_from, ss_simulate_mimo};
    use faer::Mat;
    let MimoFit {
        model,
        means: (mu, my),
        ts,
        head,
        meta: extra,
        mut problems,
        x0_est,
        one_step,
        model_lag,
        data,
    } = f;
    let (u, y) = (&data.0, &data.1);
    let unstable = model.poles()?.iter().filter(|p| p.norm() >= 1.0).count();
    if unstable > 0 {
        problems.push(format!("{unstable} pole(s) on or outside the unit circle (not stabilised): the simulation diverges"));
    }
    let (x0, skip) = (a.x0.core(), a.skip);
    let fits_on = |u: &[Vec<f64>], y: &[Vec<f64>]| -> Result<Vec<Option<f64>>> {
        let n = u[0].len();
        let um = Mat::from_fn(n, u.len(), |k, i| u[i][k]);
        let ymat = Mat::from_fn(n, y.len(), |k, j| y[j][k]);
        let (ys, _) = ss_simulate_mimo(&model, ymat.as_ref(), um.as_ref(), x0)?;
        Ok((0..y.len())
            .map(|j| {
                let yh: Vec<f64> = (0..n).map(|k| ys[(k, j)]).collect();
                fit_from(&y[j], &yh, skip)
            })
            .collect())
    };
    let predict_on = |u: &[Vec<f64>], y: &[Vec<f64>]| -> Result<Option<Vec<Option<f64>>>> {
        let Some(p) = &one_step else { return Ok(None) };
        let yh = p(y, u)?;
        Ok(Some(
            y.iter()
                .zip(&yh)
                .map(|(yj, hj)| fit_from(yj, hj, skip.max(model_lag)))
                .collect(),
        ))
    };
    let show = |f: &[Option<f64>]| {
        outs.iter()
            .zip(f)
            .map(|(o, v)| format!("{o} {}", fmt_fit(*v)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!("{head}");
    let f_est = fits_on(u, y)?;
    let p_est = predict_on(u, y)?;
    println!(
        "estimation data: simulation fit {} (initial state: {}){}",
        show(&f_est),
        x0.name(),
        p_est.as_ref().map_or(String::new(), |p| format!(
            "; 1-step prediction fit {}",
            show(p)
        ))
    );
    let mut val = json!(null);
    if let Some(p) = &a.validation {
        let (uv, _, tsv) = columns(p, &a.file, ins, Some(&mu), true)?;
        let (yv, _, _) = columns(p, &a.file, outs, Some(&my), true)?;
        if ((tsv - ts) / ts).abs() > 1e-9 {
            return Err(ambid::error::Error::input(format!(
                "the validation data are sampled at {} Hz, the estimation data at {} Hz",
                1.0 / tsv,
                1.0 / ts
            ))
            .into());
        }
        let fv = fits_on(&uv, &yv)?;
        let pv = predict_on(&uv, &yv)?;
        println!(
            "validation data: simulation fit {}{}",
            show(&fv),
            pv.as_ref().map_or(String::new(), |p| format!(
                "; 1-step prediction fit {}",
                show(p)
            ))
        );
        val = json!({"simulation_fit_pct": fv, "one_step_fit_pct": pv});
    }
    for p in &problems {
        println!("warning: {p}");
    }
    let meta = json!({
        "detrend": {"u_mean": mu, "y_mean": my},
        "estimation_fit_pct": {"simulation": f_est, "one_step": p_est},
        "validation": val,
        "initial_state": x0.name(),
        "skip": skip,
        "problems": problems,
        "source": a.data.display().to_string(),
    });
    let mut j = state_space_json(&model, &ins.join(","), &outs.join(","), meta);
    if let Some(x) = x0_est {
        j["x0"] = json!(x);
    }
    if let (Some(m), Some(e)) = (j["meta"].as_object_mut(), extra.as_object()) {
        for (k, v) in e {
            m.insert(k.clone(), v.clone());
        }
    }
    write_file(&a.out, &model_json_bytes(&j)?, a.f.force)?;
    println!("written: {}", a.out.display());
    Ok(())
}

/// What stopped the prediction-error iteration, for the summary (see
/// [`ambid_core::estimate::pem::lm::StopReason`]).
fn stop_reason_text(r: ambid_core::estimate::pem::lm::StopReason) -> &'static str {
    use ambid_core::estimate::pem::lm::StopReason;
    match r {
        StopReason::Significance => {
            "converged: the remaining Gauss-Newton step is below 0.1 standard errors"
        }
        StopReason::Stagnation => {
            "converged: within 0.5 standard errors of the optimum and no visible progress"
        }
        StopReason::Crawl => {
            "converged: the last steps gained less than the significance rule's threshold"
        }
        StopReason::LossChange => "converged: loss change below the numerical tolerance",
        StopReason::StepSize => "converged: step below the numerical tolerance",
        StopReason::Gradient => "converged: gradient zero",
        StopReason::MaxIterations => "iteration limit reached",
        StopReason::Abandoned => "abandoned: a better optimum was known",
    }
}

/// Fits one structure and order to the FRF and writes the model JSON.
#[allow(clippy::too_many_arguments)]
pub fn fit_frf(
    path: &Path,
    quantity: &str,
    structure: Structure,
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
        return Err(ambid::error::Error::usage(
            "--order must be at least 1 for a fit to FRF data".to_string(),
        )
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
    let ctrl_ss = ctrl.as_ref().map(|c| c.state_space());
    let rule = unstable_pole_rule(&input.frd, ctrl_ss, input.explicit_band, unstable_poles);
    println!("unstable plant poles: {}", rule.how);
    let fits = FrfCandidates {
        structures: &[structure],
        orders: &[order],
        nk,
        fit: input.opts.clone(),
    };
    let rows = frf_candidates(&input.frd, &fits, &rule, ctrl_ss, None)?;
    let n_u = rule.supported;
    let row = &rows[0];
    let Some(model) = &row.model else {
        return Err(ambid::error::Error::computation(format!(
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
    // a stable resonance the FRF's lines see only by its tail (docs/uncertainty.md, "A
    // resonance beyond the band is not a nominal model")
    let lines = input.frd.f_hz();
    let fitted = input
        .opts
        .band_hz
        .unwrap_or((lines[0], lines[lines.len() - 1]));
    let beyond = ambid::uncertainty::out_of_band_resonance(model, fitted)?;
    if let Some((f_n, zeta)) = beyond {
        eprintln!(
            "warning: the model has a stable resonance at {f_n:.1} Hz (damping {zeta:.2e}) outside the fitted band {:.1}–{:.1} Hz by more than its half-power bandwidth: the FRF sees only its tail, so neither its frequency nor its damping is identified, and a loop built on the model may show a peak the machine does not have; a lower order (or a band that holds the resonance) avoids it (docs/uncertainty.md)",
            fitted.0, fitted.1
        );
    }
    // poles the unstable-pole limit holds on the unit circle: the fit stopped on the constraint
    // (ambid_core::estimate::freqfit_ss, "Second start")
    let ts = input.frd.ts().unwrap_or(1.0);
    let on_circle: Vec<serde_json::Value> = match n_u {
        Some(_) => ambid_core::estimate::freqfit_ss::poles_on_unit_circle(model)?
            .iter()
            .map(|z| {
                json!({
                    "f_hz": z.arg().abs() / (2.0 * std::f64::consts::PI * ts),
                    "abs_z": z.norm(),
                })
            })
            .collect(),
        None => Vec::new(),
    };
    if let (Some(lim), false) = (n_u, on_circle.is_empty()) {
        let at: Vec<String> = on_circle
            .iter()
            .map(|p| format!("{:.2} Hz", p["f_hz"].as_f64().unwrap_or(f64::NAN)))
            .collect();
        eprintln!(
            "warning: the model has poles on the unit circle (within {:.0e}) at {}: the limit of {lim} unstable pole(s) holds them there, so the fit stopped on that constraint, not at the data's optimum, and the model has an undamped mode at each; at this order and band the data ask for more unstable poles than the limit allows. Check the unstable-pole count, or try another order or a wider band (docs/estimation.md, \"A second start for constrained fits\")",
            ambid_core::estimate::freqfit_ss::PINNED,
            at.join(", ")
        );
    }
    let meta = json!({
        "method": format!("{}_frd", structure.name()),
        "out_of_band_resonance": beyond.map(|(f, z)| json!({"f_hz": f, "damping": z})),
        "poles_on_unit_circle": on_circle,
        "quantity": quantity,
        "order": order,
        "n_params": row.n_params,
        "band_hz": input.opts.band_hz,
        "weights": super::common::weights_name(&input.opts.weights),
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
