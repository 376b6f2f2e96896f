//! `ambid validate`: a model (usually of the unstable plant) checked on an independent record,
//! always through the closed loop with the real controller.

use ambid::io::csv::read_frf_csv;
use ambid::io::model::{read_kalman_gain, read_model_json};
use ambid::io::{read_controller, read_time_csv, write_time_csv};
use ambid_core::c64;
use ambid_core::estimate::arx::fit_percent;
use ambid_core::validate::closed_loop::reconstruct;
use ambid_core::validate::iso::{sensitivity_zone, IsoZones};
use ambid_core::validate::margins::margins;
use ambid_core::validate::pz::{PzAnalysis, PzOptions};
use ambid_core::validate::residuals::analyze;
use anyhow::{bail, Context, Result};
use clap::Args;
use serde_json::json;
use std::path::PathBuf;

#[derive(Args)]
pub struct ValidateArgs {
    /// Model JSON written by `ambid fit` (its input is the plant input u, its output y).
    model: PathBuf,
    /// Validation record (time CSV) with the excitation, the output and the current; an optional
    /// `w` column is the position reference.
    #[arg(long)]
    data: PathBuf,
    /// Controller file (TOML/JSON) of the loop.
    #[arg(long)]
    controller: PathBuf,
    /// Sample rate in Hz (when the file has no `t` column).
    #[arg(long)]
    fs: Option<f64>,
    /// Column of the excitation injected at the controller output.
    #[arg(long, default_value = "r")]
    excitation: String,
    /// Column of the displacement.
    #[arg(long, default_value = "y")]
    output: String,
    /// Column of the controller output (current command).
    #[arg(long, default_value = "u")]
    current: String,
    /// Samples at the start left out of the measures (initial transient).
    #[arg(long, default_value_t = 0)]
    skip: usize,
    /// Largest lag of the residual tests.
    #[arg(long, default_value_t = 25)]
    lags: usize,
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
    /// Output directory (summary.json, timeseries.csv, residuals.csv).
    #[arg(long, default_value = "validation")]
    out: PathBuf,
}

pub fn validate(a: ValidateArgs) -> Result<()> {
    let model = read_model_json(&a.model)?;
    let ctrl = read_controller(&a.controller)?;
    let d = read_time_csv(&a.data, a.fs)?;
    let ts = d.ts;
    let mts = model.ts().unwrap_or(0.0);
    if (mts - ts).abs() > 1e-9 * ts {
        bail!(
            "the model's sample time {mts} s differs from the data's {ts} s: identify the model at the data's rate (or resample the data)"
        );
    }
    ctrl.check_ts(ts)?;
    let y = d.column(&a.output)?;
    let u = d.column(&a.current)?;
    // an all-zero excitation column (a reference-driven record) counts as absent
    let r = d
        .column(&a.excitation)
        .ok()
        .filter(|r| r.iter().any(|v| *v != 0.0));
    let zeros = vec![0.0; y.len()];
    let w = d.column("w").unwrap_or(&zeros);
    if r.is_none() && w.iter().all(|v| *v == 0.0) {
        bail!("the record has neither an excitation column `{}` nor a reference `w`: nothing drives the loop", a.excitation);
    }
    if a.skip + 4 * a.lags.max(5) >= y.len() {
        bail!(
            "--skip {} leaves too few samples ({}) for the residual tests with {} lags",
            a.skip,
            y.len().saturating_sub(a.skip),
            a.lags
        );
    }
    let k0 = a.skip;
    let c = ctrl.state_space();
    // closed-loop poles first: an unstable loop is reported with its poles
    let cl = model.feedback(c)?;
    let pz_cl = PzAnalysis::from_state_space(&cl, &PzOptions::default())?;
    let unstable_cl: Vec<String> = pz_cl
        .poles
        .iter()
        .filter(|p| p.z.norm() >= 1.0)
        .map(|p| format!("{:.6}{:+.6}j (|z| = {:.6})", p.z.re, p.z.im, p.z.norm()))
        .collect();
    if !unstable_cl.is_empty() {
        bail!(
            "the model does not give a stable closed loop with this controller; unstable closed-loop poles: {}. The model is wrong near crossover or the controller does not match the data",
            unstable_cl.join(", ")
        );
    }
    // simulate from the start of the record (the model starts from rest like the plant did) and
    // measure after the skip
    let full = reconstruct(&model, c, w, r, y, u, a.windows, ts)?;
    let sim = &full.simulated;
    let eps: Vec<f64> = y[k0..]
        .iter()
        .zip(&sim.y[k0..])
        .map(|(a, b)| a - b)
        .collect();
    let input = r.map_or(&w[k0..], |r| &r[k0..]);
    let res = analyze(&eps, Some(input), a.lags)?;
    let rmse = (eps.iter().map(|e| e * e).sum::<f64>() / eps.len() as f64).sqrt();
    let max_err = eps.iter().map(|e| e.abs()).fold(0.0, f64::max);
    let fit = |x: &[f64], xh: &[f64]| fit_percent(x, xh);
    let (fit_y, fit_u) = (fit(&y[k0..], &sim.y[k0..])?, fit(&u[k0..], &sim.u[k0..])?);
    // margins and ISO zone of the model's loop on a log grid up to Nyquist
    let fny = 0.5 / ts;
    let grid: Vec<f64> = (0..4000)
        .map(|k| 0.5 * (0.98 * fny / 0.5f64).powf(k as f64 / 3999.0))
        .collect();
    let gp = model.freq_response_siso(&grid)?;
    let gc = c.freq_response_siso(&grid)?;
    let l: Vec<c64> = gp.iter().zip(&gc).map(|(p, c)| p * c).collect();
    let mg = margins(&grid, &l)?;
    let s_model: Vec<c64> = l.iter().map(|v| (c64::new(1.0, 0.0) + v).inv()).collect();
    let s_frd = ambid_core::lti::Frd::new(grid.clone(), s_model, None, Some(ts))?;
    let iso_model = sensitivity_zone(&s_frd, &IsoZones::default())?;
    // closed-loop consistency: the model's S and T_ry in the loop against the measured ones
    let (iso_measured, consistency) = match &a.frf {
        Some(p) => {
            let file = read_frf_csv(p)?;
            let s_meas = file.frd("t_ru", ts)?;
            let t_meas = file.frd("t_ry", ts)?;
            let f = s_meas.f_hz().to_vec();
            let (gp, gc) = (model.freq_response_siso(&f)?, c.freq_response_siso(&f)?);
            let med = |pred: &[c64], meas: &[c64]| {
                let mut r: Vec<f64> = pred
                    .iter()
                    .zip(meas)
                    .map(|(a, b)| (a - b).norm() / b.norm())
                    .collect();
                r.sort_by(f64::total_cmp);
                r[r.len() / 2]
            };
            let s_pred: Vec<c64> = gp
                .iter()
                .zip(&gc)
                .map(|(p, c)| (c64::new(1.0, 0.0) + p * c).inv())
                .collect();
            let t_pred: Vec<c64> = gp.iter().zip(&s_pred).map(|(p, s)| p * s).collect();
            (
                Some(sensitivity_zone(&s_meas, &IsoZones::default())?),
                Some(json!({
                    "s_median_relative_error": med(&s_pred, s_meas.values()),
                    "t_ry_median_relative_error": med(&t_pred, t_meas.values()),
                    "lines": f.len(),
                })),
            )
        }
        None => (None, None),
    };
    let k_step = match a.k_step {
        Some(k) => {
            let Some(kg) = read_kalman_gain(&a.model)? else {
                bail!("--k-step needs an innovation-form model with a Kalman gain (`ambid fit --structure ss` with --focus prediction)");
            };
            if kg.len() != model.order() {
                bail!(
                    "the model's Kalman gain has {} entries for {} states",
                    kg.len(),
                    model.order()
                );
            }
            let kmat = faer::Mat::from_fn(kg.len(), 1, |i, _| kg[i]);
            let p = ambid_core::validate::predict::predict_k(&model, kmat.as_ref(), y, u, k)?;
            Some((k, fit(&y[k0..], &p[k0..])?))
        }
        None => None,
    };
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let t: Vec<f64> = (0..y.len()).map(|k| k as f64 * ts).collect();
    let e_full: Vec<f64> = y.iter().zip(&sim.y).map(|(a, b)| a - b).collect();
    write_time_csv(
        &a.out.join("timeseries.csv"),
        &[
            ("t", &t),
            ("y", y),
            ("y_sim", &sim.y),
            ("error", &e_full),
            ("u", u),
            ("u_sim", &sim.u),
        ],
    )?;
    let ind = res.independence.as_ref();
    let mut wtr = ::csv::Writer::from_path(a.out.join("residuals.csv"))?;
    wtr.write_record([
        "lag",
        "autocorrelation",
        "auto_bound",
        "cross_correlation",
        "cross_bound",
    ])?;
    for (i, lag) in (-(a.lags as i64)..=a.lags as i64).enumerate() {
        let auto = if lag >= 1 {
            res.whiteness.values[(lag - 1) as usize].to_string()
        } else {
            String::new()
        };
        let cross = ind.map_or(String::new(), |c| c.values[i].to_string());
        wtr.write_record([
            lag.to_string(),
            auto,
            res.whiteness.bound.to_string(),
            cross,
            ind.map_or(String::new(), |c| c.bound.to_string()),
        ])?;
    }
    wtr.flush()?;
    let worst = full.worst_window();
    let summary = json!({
        "model": a.model.display().to_string(),
        "data": a.data.display().to_string(),
        "controller": ctrl.description(),
        "samples_measured": y.len() - k0,
        "fit_y_pct": fit_y, "fit_u_pct": fit_u, "rmse_y": rmse, "max_error_y": max_err,
        "windows": full.windows,
        "worst_window": worst,
        "residuals": res,
        "closed_loop_poles": pz_cl.poles.iter().map(|p| json!({"re": p.z.re, "im": p.z.im, "abs": p.z.norm(), "f_hz": p.f_hz, "damping": p.damping})).collect::<Vec<_>>(),
        "margins": mg,
        "iso_model": iso_model,
        "iso_measured": iso_measured,
        "consistency": consistency,
        "k_step_prediction": k_step.map(|(k, f)| json!({"k": k, "fit_y_pct": f})),
    });
    std::fs::write(
        a.out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    println!("closed-loop validation on {} samples (first {k0} skipped): fit y {fit_y:.2} %, fit u {fit_u:.2} %, RMSE y {rmse:.3e}, max |error| {max_err:.3e}", y.len() - k0);
    if let Some(wf) = worst {
        println!(
            "worst window {:.3}–{:.3} s: fit y {:.1} %",
            wf.t_s.0, wf.t_s.1, wf.fit_y
        );
    }
    println!(
        "residuals: whiteness {} (statistic {:.1}, 95 % threshold {:.1}, {} of {} lags outside); independence from the {} {}",
        if res.whiteness.pass { "pass" } else { "FAIL" },
        res.whiteness.statistic,
        res.whiteness.threshold,
        res.whiteness.exceeding.len(),
        res.whiteness.lags.len(),
        if r.is_some() { "excitation" } else { "reference" },
        ind.map_or("—".to_string(), |c| format!("{} (statistic {:.1}, threshold {:.1}, {} of {} lags outside)", if c.pass { "pass" } else { "FAIL" }, c.statistic, c.threshold, c.exceeding.len(), c.lags.len()))
    );
    println!(
        "margins: phase {} deg, gain {} (upper) / {} (lower); max|S| {:.3} at {:.1} Hz → ISO 14839-3 zone {:?} (model){}",
        mg.phase_margin().map_or("—".into(), |v| format!("{v:.1}")),
        mg.upper_gain_margin().map_or("—".into(), |v| format!("{v:.3}")),
        mg.lower_gain_margin().map_or("—".into(), |v| format!("{v:.3}")),
        iso_model.peak,
        iso_model.f_peak_hz,
        iso_model.zone,
        iso_measured.as_ref().map_or(String::new(), |m| format!(", measured max|S| {:.3} ({:?}) → zone {:?}", m.peak, m.interval, m.zone))
    );
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
