//! `ambid physical`: the magnet's k_i and k_x, the bending mode's frequency, damping and mode
//! shape, with confidence intervals, from the measured plant FRF and what the drawing says (gray
//! box, docs/physical.md); the gray-box model beside the black-box one.

use super::args::parse_band;
use super::common::{model_on_frf, twin_config, ModelOnFrf, TwinArgs};
use ambid::io::model::state_space_json;
use ambid::io::OutputSet;
use ambid::physical::{
    as_array, estimate, median_rel_error, twin_drawing, twin_truth, Drawing, PhysicalOptions,
    PARAMETER_NAMES,
};
use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;
use std::path::PathBuf;

#[derive(Args)]
pub struct PhysicalArgs {
    /// FRF CSV (as written by `ambid frf`) with the measured plant and its standard deviations.
    frf: PathBuf,
    /// An identified black-box plant model JSON (`ambid fit … --structure ss` with the loop's
    /// unstable pole count): its unstable pole and resonances start the fit.
    #[arg(long)]
    model: PathBuf,
    /// Controller file (TOML/JSON) of the loop; the same controller holds bearing B.
    #[arg(long)]
    controller: PathBuf,
    /// The drawing as TOML (mass_kg, inertia_kgm2, bearing_a_m, bearing_b_m,
    /// amplifier_bandwidth_hz, sensor_bandwidth_hz; amplifier_gain, sensor_gain, delay_samples
    /// default to 1). Without it, the drawing of the twin (nominal, --config or --rig-seed), whose
    /// true values are then printed beside the estimates.
    #[arg(long)]
    drawing: Option<PathBuf>,
    #[command(flatten)]
    twin: TwinArgs,
    /// Quantity of the FRF file that is the plant.
    #[arg(long, default_value = "plant")]
    quantity: String,
    /// Sample rate of the data in Hz (default: the `fs_hz` column of the FRF file).
    #[arg(long)]
    fs: Option<f64>,
    /// Band `f_min:f_max` in Hz (default: where the file measures the plant reliably; printed).
    /// The bending mode must lie inside it.
    #[arg(long, value_parser = parse_band)]
    band: Option<(f64, f64)>,
    /// Two-sided confidence level of the intervals.
    #[arg(long, default_value_t = 0.95)]
    confidence: f64,
    /// Output JSON: estimates, standard deviations, intervals, the ratio k_i/k_x, the gray-box
    /// model and its comparison with the black-box model.
    #[arg(long, default_value = "physical.json")]
    out: PathBuf,
    /// Replace the output file if it exists.
    #[arg(long)]
    force: bool,
}

const UNITS: [&str; 6] = ["N/A", "N/m", "Hz", "-", "kg^-1/2", "kg^-1/2"];

pub fn physical(a: PhysicalArgs) -> Result<()> {
    OutputSet::check(&a.out, a.force)?;
    if !(a.confidence > 0.0 && a.confidence < 1.0) {
        return Err(ambid::error::Error::usage(format!(
            "--confidence must lie in (0, 1), e.g. 0.95; got {}",
            a.confidence
        ))
        .into());
    }
    let (drawing, truth) = match &a.drawing {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read the drawing {}", p.display()))?;
            let d: Drawing = toml::from_str(&text).map_err(|e| {
                ambid::error::Error::input(format!(
                    "{}: {e}; a drawing has mass_kg, inertia_kgm2, bearing_a_m, bearing_b_m, amplifier_bandwidth_hz, sensor_bandwidth_hz (and optionally amplifier_gain, sensor_gain, delay_samples); docs/physical.md",
                    p.display()
                ))
            })?;
            (d, None)
        }
        None => {
            let twin = ambid_twin::Twin::new(twin_config(&a.twin)?)?;
            (
                twin_drawing(twin.config()),
                Some(as_array(&twin_truth(&twin))),
            )
        }
    };
    let ModelOnFrf {
        frd,
        band,
        model,
        controller: ctrl,
    } = model_on_frf(
        &a.frf,
        &a.quantity,
        a.fs,
        a.band,
        &a.model,
        &a.controller,
        "the gray-box fit weights the lines by the FRF's standard deviations",
    )?;
    let fit = estimate(
        &frd,
        &model,
        &drawing,
        ctrl.state_space(),
        &PhysicalOptions {
            confidence: a.confidence,
            ..PhysicalOptions::default()
        },
    )?;
    let est = as_array(&fit.params);
    let pct = 100.0 * a.confidence;
    println!(
        "gray-box fit over {} lines in {:.1}–{:.1} Hz: chi2/dof {:.3} ({} iterations, {:?})",
        frd.len(),
        band.0,
        band.1,
        fit.chi2 / fit.dof as f64,
        fit.iterations,
        fit.stop
    );
    println!(
        "{:>16} {:>14} {:>12} {:>30} {:>14}",
        "parameter",
        "estimate",
        "std",
        format!("{pct:.0} % interval"),
        if truth.is_some() { "twin" } else { "" }
    );
    let mut rows = Vec::new();
    for k in 0..6 {
        let (lo, hi) = fit.intervals[k];
        println!(
            "{:>16} {:>14.6e} {:>12.3e} {:>14.6e}..{:<14.6e} {:>14} {}",
            PARAMETER_NAMES[k],
            est[k],
            fit.std[k],
            lo,
            hi,
            truth.map_or(String::new(), |t| format!("{:.6e}", t[k])),
            UNITS[k]
        );
        rows.push(json!({
            "name": PARAMETER_NAMES[k],
            "unit": UNITS[k],
            "estimate": est[k],
            "std": fit.std[k],
            "interval": [lo, hi],
            "twin": truth.map(|t| t[k]),
        }));
    }
    let (ratio, (rlo, rhi)) = fit.ratio();
    println!(
        "identifiable without the drawing: k_i/k_x = {ratio:.6e} m/A ({rlo:.6e}..{rhi:.6e}), unstable pole {:.2} rad/s",
        fit.unstable_pole_rad_s
    );
    let e_gray = median_rel_error(&fit.model, &frd)?;
    let e_black = median_rel_error(&model, &frd)?;
    println!(
        "median relative error against the FRF: gray box ({} states, 6 parameters) {:.3} %, black box ({} states) {:.3} %",
        fit.model.order(),
        100.0 * e_gray,
        model.order(),
        100.0 * e_black
    );
    let summary = json!({
        "frf": a.frf.display().to_string(),
        "model": a.model.display().to_string(),
        "controller": a.controller.display().to_string(),
        "drawing": drawing,
        "band_hz": [band.0, band.1],
        "lines": frd.len(),
        "confidence": a.confidence,
        "parameters": rows,
        "covariance_log_theta": fit.covariance,
        "chi2": fit.chi2,
        "dof": fit.dof,
        "variance_scale": fit.variance_scale,
        "iterations": fit.iterations,
        "stop": format!("{:?}", fit.stop),
        "ratio_ki_kx": {"estimate": ratio, "interval": [rlo, rhi], "unit": "m/A"},
        "unstable_pole_rad_s": fit.unstable_pole_rad_s,
        "comparison": {
            "graybox_median_rel_error": e_gray,
            "blackbox_median_rel_error": e_black,
            "graybox_states": fit.model.order(),
            "blackbox_states": model.order(),
        },
        "graybox_model": state_space_json(&fit.model, "u", "y", json!({"kind": "graybox"})),
    });
    let mut set = OutputSet::new(a.force);
    set.write(&a.out, serde_json::to_string_pretty(&summary)?.as_bytes())?;
    set.commit()?;
    println!("written: {}", a.out.display());
    Ok(())
}
