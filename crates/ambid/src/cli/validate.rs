//! `ambid validate`: a model (usually of the unstable plant) checked on an independent record,
//! always through the closed loop with the real controller.

use super::args::{DataFileArgs, ExcitationColumn, InputColumn, OutputColumn};
use ambid::io::csv::read_frf_csv;
use ambid::io::model::{read_kalman_gain, read_model_json};
use ambid::io::{read_controller, time_csv_to, OutputSet};
use ambid::stage::{ModelUnderTest, Recording, Signals, ValidationCheck, ValidationInput};
use ambid::validation::{
    consistency, innovation_residuals, innovation_summary, residual_summary, MeasuredLoop,
    ValidationSettings,
};
use ambid_core::validate::fit::fit_percent;
use anyhow::Result;
use clap::Args;
use serde_json::json;
use std::path::PathBuf;

#[derive(Args)]
#[command(mut_arg("excitation", |a| a.help("Column of the excitation injected at the controller output")))]
#[command(mut_arg("output", |a| a.help("Column of the displacement")))]
#[command(mut_arg("input", |a| a.help("Column of the controller output u, the plant input (current command); `--input` in every command")))]
pub struct ValidateArgs {
    /// Model JSON written by `ambid fit` (its input is the plant input u, its output y).
    model: PathBuf,
    /// Validation record (CSV, .npy, .npz, .mat or .parquet; docs/data-files.md) with the
    /// excitation, the output and the plant input; an optional `w` column is the position
    /// reference.
    #[arg(long)]
    data: PathBuf,
    /// Controller file (TOML/JSON) of the loop.
    #[arg(long)]
    controller: PathBuf,
    #[command(flatten)]
    file: DataFileArgs,
    #[command(flatten)]
    r: ExcitationColumn,
    #[command(flatten)]
    y: OutputColumn,
    #[command(flatten)]
    u: InputColumn,
    /// Deprecated spelling of --input (`--current` names the coil current i in `frf`).
    #[arg(long, hide = true, conflicts_with = "input")]
    current: Option<String>,
    /// Samples at the start left out of the measures (initial transient).
    #[arg(long, default_value_t = 0)]
    skip: usize,
    /// Largest lag of the residual tests; default from the dynamics: 2× the peak time of the
    /// model's closed-loop impulse response with the controller, 10–150 lags (docs/validation.md).
    #[arg(long)]
    lags: Option<usize>,
    /// Time windows of the reconstruction report.
    #[arg(long, default_value_t = 20)]
    windows: usize,
    /// FRF CSV of `ambid frf`: its measured S (`t_ru`, with standard deviations) gives the
    /// ISO 14839-3 zone with a confidence interval.
    #[arg(long)]
    frf: Option<PathBuf>,
    /// Also the k-step-ahead prediction fit (needs an innovation-form model: `ambid fit
    /// --structure ss` with the prediction focus stores K); u is the recorded plant input.
    #[arg(long)]
    k_step: Option<usize>,
    /// How the simulated loop and the predictors start: from the initial state that best explains
    /// the record (the loop was running before the first sample; MATLAB `compare`'s default) or
    /// from rest.
    #[arg(long, value_enum, default_value_t = super::common::X0Arg::Estimate)]
    x0: super::common::X0Arg,
    /// Output directory (summary.json, timeseries.csv, residuals.csv).
    #[arg(long, default_value = "validation")]
    out: PathBuf,
    /// Replace those files if they exist (other files in the directory are left alone).
    #[arg(long)]
    force: bool,
}

/// The files `validate` writes into `--out`.
const VALIDATE_FILES: [&str; 3] = ["timeseries.csv", "residuals.csv", "summary.json"];

pub fn validate(a: ValidateArgs) -> Result<()> {
    for f in VALIDATE_FILES {
        OutputSet::check(&a.out.join(f), a.force)?;
    }
    let model = read_model_json(&a.model)?;
    let ctrl = read_controller(&a.controller)?;
    let d = a.file.read(&a.data)?;
    let ts = d.ts;
    ctrl.check_ts(ts)?;
    let y = d.column(&a.y.output)?;
    let u_col = match &a.current {
        Some(c) => {
            super::args::deprecated(
                &format!("validate --current {c}"),
                &format!("--input {c} (the controller output u)"),
            );
            c
        }
        None => &a.u.input,
    };
    let u = d.column(u_col)?;
    let r = d
        .optional_column(&a.r.excitation)?
        .filter(|r| r.iter().any(|v| *v != 0.0));
    let zeros = vec![0.0; y.len()];
    let w = d.optional_column("w")?.unwrap_or(&zeros);
    if !ambid::stage::drives_loop(r, Some(w)) {
        return Err(ambid::error::Error::input(format!("the record has neither an excitation column `{}` nor a reference `w`: nothing drives the loop", a.r.excitation)).into());
    }
    // the residual lags: given, or from the dynamics, by the validation stage's rule
    let choice = ambid::stage::lag_choice(
        a.lags,
        &model,
        Some(ctrl.state_space()),
        y.len().saturating_sub(a.skip),
    );
    if a.lags.is_none() {
        println!("residual tests: {}", choice.describe(ts));
    }
    let lags = choice.lags;
    let settings = ValidationSettings {
        skip: a.skip,
        lags,
        windows: a.windows,
        initial_state: a.x0.core(),
        ..ValidationSettings::default()
    };
    let k0 = a.skip;
    let c = ctrl.state_space();
    // the workflow's validation stage, on the record as the core's data contract
    let record = Recording::from_signals(
        ts,
        None,
        Signals {
            r: r.map(<[f64]>::to_vec),
            u: u.to_vec(),
            y: y.to_vec(),
            i: None,
            w: Some(w.to_vec()),
        },
        true,
        a.data.display().to_string(),
    )?;
    let name = a.model.display().to_string();
    let stage = ambid::stage::validation(&ValidationInput {
        model: ModelUnderTest {
            name: &name,
            model: &model,
            poly: None,
            kalman: None,
        },
        record: &record,
        controller: Some(&ctrl),
        twin: None,
        settings: settings.clone(),
        lags: Some(lags),
    })
    .map_err(|e| {
        if a.skip + 4 * lags.max(5) >= y.len() {
            e.context("use a smaller --skip or fewer --lags")
        } else {
            e
        }
    })?;
    let v = match stage.check {
        ValidationCheck::ClosedLoop(c) => c.outcome,
        ValidationCheck::NotDone(why) => return Err(ambid::error::Error::input(why).into()),
        ValidationCheck::OpenLoop(_) => {
            return Err(ambid::error::Error::other(
                "the record was not validated through the closed loop",
            )
            .into())
        }
    };
    let full = &v.reconstruction;
    let sim = &full.simulated;
    let res = &v.residuals;
    let (fit_y, fit_u, rmse, max_err) = (v.fit_y, v.fit_u, v.rmse_y, v.max_error_y);
    let mg = &v.margins;
    let iso_model = &v.iso_model;
    let pz_cl = &v.closed_loop;
    let (iso_measured, iso_how, consistency) = match &a.frf {
        Some(p) => {
            let file = read_frf_csv(p)?;
            let cns = consistency(
                &model,
                c,
                &file.frd("t_ru", ts)?,
                &file.frd("t_ry", ts)?,
                &settings.zones,
            )?;
            (
                Some(cns.iso_measured.clone()),
                Some(cns.iso_search.describe()),
                Some(json!({
                    "s_median_relative_error": cns.s_median_relative_error,
                    "t_ry_median_relative_error": cns.t_ry_median_relative_error,
                    "lines": cns.lines,
                })),
            )
        }
        None => (None, None, None),
    };
    // an innovation-form model has a noise model: its 1-step prediction errors are tested for
    // whiteness and independence (validation::innovation_residuals)
    let kalman_gain = read_kalman_gain(&a.model)?;
    let innovations = match &kalman_gain {
        Some(kg) => Some(innovation_residuals(
            &model,
            kg,
            &MeasuredLoop { w, r, y, u, ts },
            &settings,
        )?),
        None => None,
    };
    let k_step = match a.k_step {
        Some(k) => {
            let Some(kg) = &kalman_gain else {
                return Err(ambid::error::Error::usage("--k-step needs an innovation-form model with a Kalman gain (`ambid fit --structure ss` with --focus prediction)".to_string()).into());
            };
            if kg.len() != model.order() {
                return Err(ambid::error::Error::input(format!(
                    "the model's Kalman gain has {} entries for {} states",
                    kg.len(),
                    model.order()
                ))
                .into());
            }
            let kmat = faer::Mat::from_fn(kg.len(), 1, |i, _| kg[i]);
            let (p, _) = ambid_core::validate::predict::predict_k_with(
                &model,
                kmat.as_ref(),
                y,
                u,
                k,
                settings.initial_state,
            )?;
            Some((k, fit_percent(&y[k0..], &p[k0..])?))
        }
        None => None,
    };
    let mut set = OutputSet::new(a.force);
    let t: Vec<f64> = (0..y.len()).map(|k| k as f64 * ts).collect();
    let e_full: Vec<f64> = y.iter().zip(&sim.y).map(|(a, b)| a - b).collect();
    set.write_with(&a.out.join(VALIDATE_FILES[0]), |w| {
        time_csv_to(
            w,
            &[
                ("t", &t),
                ("y", y),
                ("y_sim", &sim.y),
                ("error", &e_full),
                ("u", u),
                ("u_sim", &sim.u),
            ],
        )
    })?;
    let ind = res.independence.as_ref();
    let mut wtr = ::csv::Writer::from_writer(Vec::new());
    wtr.write_record([
        "lag",
        "autocorrelation",
        "auto_bound",
        "cross_correlation",
        "cross_bound",
    ])?;
    for (i, lag) in (-(lags as i64)..=lags as i64).enumerate() {
        // the closed-loop output error has no whiteness test (validation module docs): empty
        let white = res.whiteness.as_ref();
        let auto = match white {
            Some(w) if lag >= 1 => w.values[(lag - 1) as usize].to_string(),
            _ => String::new(),
        };
        let cross = ind.map_or(String::new(), |c| c.values[i].to_string());
        wtr.write_record([
            lag.to_string(),
            auto,
            white.map_or(String::new(), |w| w.bound.to_string()),
            cross,
            ind.map_or(String::new(), |c| c.bound.to_string()),
        ])?;
    }
    let residuals = wtr
        .into_inner()
        .map_err(|e| anyhow::anyhow!("{}", e.error()))?;
    set.write(&a.out.join(VALIDATE_FILES[1]), &residuals)?;
    let worst = full.worst_window();
    let summary = json!({
        "model": a.model.display().to_string(),
        "data": a.data.display().to_string(),
        "controller": ctrl.description(),
        "samples_measured": y.len() - k0,
        "initial_state": settings.initial_state.name(),
        "initial_state_values": full.initial_state,
        "fit_y_pct": fit_y, "fit_u_pct": fit_u, "rmse_y": rmse, "max_error_y": max_err,
        "windows": full.windows,
        "worst_window": worst,
        "residuals": res,
        "closed_loop_poles": pz_cl.poles.iter().map(|p| json!({"re": p.z.re, "im": p.z.im, "abs": p.z.norm(), "f_hz": p.f_hz, "damping": p.damping})).collect::<Vec<_>>(),
        "margins": mg,
        "iso_model": iso_model,
        "iso_measured": iso_measured,
        "iso_measured_search": iso_how,
        "consistency": consistency,
        "k_step_prediction": k_step.map(|(k, f)| json!({"k": k, "fit_y_pct": f})),
        "innovation_residuals": innovations.as_ref().map(|(t, input)| json!({"tested_against": input, "tests": t})),
        "residuals_tested_against": v.residual_input,
    });
    set.write(
        &a.out.join(VALIDATE_FILES[2]),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    set.commit()?;
    println!("closed-loop validation on {} samples (first {k0} skipped, loop started from the {} initial state): fit y {fit_y:.2} %, fit u {fit_u:.2} %, RMSE y {rmse:.3e}, max |error| {max_err:.3e}", y.len() - k0, if settings.initial_state == ambid_core::validate::predict::InitialState::Estimate { "estimated" } else { "zero" });
    let nx = model.order() + c.order();
    if settings.initial_state == ambid_core::validate::predict::InitialState::Estimate
        && nx > ambid_core::validate::closed_loop::MAX_X0_LOOP_STATES
    {
        println!(
            "note: the loop has {nx} states, more than the {} whose initial state is estimated: it started from rest (use --skip to leave out the start)",
            ambid_core::validate::closed_loop::MAX_X0_LOOP_STATES
        );
    }
    if let Some(wf) = worst {
        println!(
            "worst window {:.3}–{:.3} s: fit y {:.1} %",
            wf.t_s.0, wf.t_s.1, wf.fit_y
        );
    }
    println!("{}", residual_summary(res, v.residual_input));
    println!(
        "margins: phase {} deg, gain {} (upper) / {} (lower); max|S| {:.3} at {:.1} Hz → ISO 14839-3 zone {:?} (model){}",
        mg.phase_margin().map_or("—".into(), |v| format!("{v:.1}")),
        mg.upper_gain_margin().map_or("—".into(), |v| format!("{v:.3}")),
        mg.lower_gain_margin().map_or("—".into(), |v| format!("{v:.3}")),
        iso_model.peak,
        iso_model.f_peak_hz,
        iso_model.zone,
        iso_measured.as_ref().map_or(String::new(), |m| {
            let ci = m.interval.map_or(String::new(), |(lo, hi)| format!(" (95 % interval {lo:.3}–{hi:.3})"));
            format!(", measured max|S| {:.3}{ci} at {:.1} Hz → zone {:?}", m.peak, m.f_peak_hz, m.zone)
        })
    );
    if let Some(h) = &iso_how {
        println!("measured sensitivity: {h}");
    }
    if let Some((t, input)) = &innovations {
        println!("{}", innovation_summary(t, input));
    }
    if let Some((k, f)) = k_step {
        println!("{k}-step-ahead prediction fit of y: {f:.2} %");
    }
    if let Some(cns) = &consistency {
        println!(
            "closed-loop consistency: model S vs measured S median {:.3} %, T_ry {:.3} % over {} lines",
            100.0 * cns["s_median_relative_error"].as_f64().unwrap_or(f64::NAN),
            100.0 * cns["t_ry_median_relative_error"].as_f64().unwrap_or(f64::NAN),
            cns["lines"]
        );
    }
    println!("written: {}", a.out.display());
    Ok(())
}
