//! `ambid physical`: the magnet's k_i and k_x, the bending mode's frequency, damping and mode
//! shape, with confidence intervals, from the measured plant FRF and what the drawing says (gray
//! box, docs/physical.md); the gray-box model beside the black-box one.

use super::args::parse_band;
use super::common::{frf_with_variance, model_on_frf, twin_config, ModelOnFrf, TwinArgs};
use ambid::io::model::state_space_json;
use ambid::io::OutputSet;
use ambid::physical::{
    as_array, at_levels, estimate, extrapolate_to_zero_amplitude, median_rel_error, twin_drawing,
    twin_truth, PhysicalFit, PhysicalOptions, PARAMETER_NAMES,
};
use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;
use std::path::PathBuf;

/// Whether `path` is a matrix FRF CSV (a quantity `P_<out>_<in>`), the whole-machine path.
pub(crate) fn is_matrix_frf(path: &std::path::Path) -> Result<bool> {
    let file = ambid::io::csv::read_frf_csv(path)
        .with_context(|| format!("cannot read the FRF {}", path.display()))?;
    Ok(file.quantities.iter().any(|q| q.starts_with("P_")))
}

#[derive(Args)]
pub struct PhysicalArgs {
    /// FRF CSV (as written by `ambid frf`) with the measured plant and its standard deviations.
    pub(crate) frf: PathBuf,
    /// An identified black-box plant model JSON (`ambid fit … --structure ss` with the loop's
    /// unstable pole count): its unstable pole and resonances start the fit. Required for a
    /// single-axis FRF; not used with a 4×4 matrix FRF (whose starts come from the data).
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// Controller file (TOML/JSON) of the loop; the same controller holds bearing B. Required
    /// for a single-axis FRF; not used with a 4×4 matrix FRF (all loops open).
    #[arg(long)]
    pub(crate) controller: Option<PathBuf>,
    /// 4×4 matrix FRF only: the rotor speed the FRF was measured at, rpm (default: the
    /// machine configuration's with --config, else 0). Above 0 the gyroscopic moments need
    /// the polar inertia (--polar-inertia, or the machine configuration's).
    #[arg(long)]
    pub(crate) speed_rpm: Option<f64>,
    /// 4×4 matrix FRF only: the rotor's polar moment of inertia, kg·m² (default: the machine
    /// configuration's).
    #[arg(long)]
    pub(crate) polar_inertia: Option<f64>,
    /// The drawing as TOML (mass_kg, inertia_kgm2, bearing_a_m, bearing_b_m,
    /// amplifier_bandwidth_hz, sensor_bandwidth_hz; amplifier_gain, sensor_gain, delay_samples
    /// default to 1). Without it, the drawing of the twin (nominal, --config or --rig-seed), whose
    /// true values are then printed beside the estimates.
    #[arg(long)]
    pub(crate) drawing: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) twin: TwinArgs,
    /// Quantity of the FRF file that is the plant.
    #[arg(long, default_value = "plant")]
    pub(crate) quantity: String,
    /// Sample rate of the data in Hz (default: the `fs_hz` column of the FRF file).
    #[arg(long)]
    pub(crate) fs: Option<f64>,
    /// Band `f_min:f_max` in Hz (default: where the file measures the plant reliably; printed).
    /// The bending mode must lie inside it.
    #[arg(long, value_parser = parse_band)]
    pub(crate) band: Option<(f64, f64)>,
    /// Two-sided confidence level of the intervals.
    #[arg(long, default_value_t = 0.95)]
    pub(crate) confidence: f64,
    /// The excitation level of FRF (any unit proportional to the amplitude, e.g. % of i_sat);
    /// needed with --also.
    #[arg(long)]
    pub(crate) level: Option<f64>,
    /// Another FRF of the same axis (or, with a 4×4 matrix FRF, of the same machine) at another
    /// excitation level, `LEVEL=FILE` (repeat for more levels): the parameters are estimated at
    /// every level and extrapolated to zero amplitude (the small-signal k_i, k_x of a nonlinear
    /// magnet; docs/physical.md). Read on FRF's band.
    #[arg(long, value_parser = parse_level_file)]
    pub(crate) also: Vec<(f64, PathBuf)>,
    /// The bias current of FRF's operating point, A; needed with --operating.
    #[arg(long)]
    pub(crate) bias_current: Option<f64>,
    /// An FRF of the same axis at another operating point of the operating-point study,
    /// `BIAS:GAP_UM=FILE`: its bias current in A and its air-gap offset from FRF's gap in µm
    /// (positive = wider), e.g. `1.6:0=frf_b16.csv` (repeat per operating point). The gray box
    /// runs at each point and the magnet law k_i = 4k i0/g², k_x = 4k i0²/g³ through all of
    /// them gives the magnet constant k and the effective air gap with intervals
    /// (docs/physical.md). Read on FRF's band. With a 4×4 matrix FRF the other files are 4×4
    /// too, and each axis gets its own law. Not with --also.
    #[arg(long, value_parser = super::physical_operating::parse_operating_file)]
    pub(crate) operating: Vec<super::physical_operating::OperatingFile>,
    /// Output JSON: estimates, standard deviations, intervals, the ratio k_i/k_x, the gray-box
    /// model and its comparison with the black-box model.
    #[arg(long, default_value = "physical.json")]
    pub(crate) out: PathBuf,
    /// Replace the output file if it exists.
    #[arg(long)]
    pub(crate) force: bool,
}

/// What the FRF's standard deviations are needed for (the error when they are all zero).
const NEEDS: &str = "the gray-box fit weights the lines by the FRF's standard deviations";

const UNITS: [&str; 6] = ["N/A", "N/m", "Hz", "-", "kg^-1/2", "kg^-1/2"];

/// `LEVEL=FILE` of `--also`.
fn parse_level_file(s: &str) -> std::result::Result<(f64, PathBuf), String> {
    let (l, f) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}`: expected LEVEL=FILE, e.g. 14=frf14.csv"))?;
    let level: f64 =
        l.trim().trim_end_matches('%').parse().map_err(|_| {
            format!("`{l}` is not a number: expected LEVEL=FILE, e.g. 14=frf14.csv")
        })?;
    if !(level.is_finite() && level > 0.0) {
        return Err(format!("the level must be positive, got {level}"));
    }
    if f.is_empty() {
        return Err(format!("`{s}`: the file is missing; expected LEVEL=FILE"));
    }
    Ok((level, PathBuf::from(f)))
}

/// Prints the table of estimates (heading with the confidence level, then one row per
/// parameter with its unit, standard deviation, interval and the twin's value when known) and
/// returns the rows for the JSON output.
pub(crate) fn parameter_table(
    names: &[&str],
    units: &[&str],
    est: &[f64],
    std: &[f64],
    intervals: &[(f64, f64)],
    truth: Option<&[f64]>,
    confidence: f64,
) -> Vec<serde_json::Value> {
    println!(
        "{:>16} {:>14} {:>12} {:>30} {:>14}",
        "parameter",
        "estimate",
        "std",
        format!("{:.0} % interval", 100.0 * confidence),
        if truth.is_some() { "twin" } else { "" }
    );
    let mut rows = Vec::with_capacity(names.len());
    for k in 0..names.len() {
        let (lo, hi) = intervals[k];
        println!(
            "{:>16} {:>14.6e} {:>12.3e} {:>14.6e}..{:<14.6e} {:>14} {}",
            names[k],
            est[k],
            std[k],
            lo,
            hi,
            truth.map_or(String::new(), |t| format!("{:.6e}", t[k])),
            units[k]
        );
        rows.push(json!({
            "name": names[k],
            "unit": units[k],
            "estimate": est[k],
            "std": std[k],
            "interval": [lo, hi],
            "twin": truth.map(|t| t[k]),
        }));
    }
    rows
}

/// One level's estimate in the zero-amplitude section: the level, the estimate, its standard
/// deviations, χ² and degrees of freedom.
pub(crate) type LevelRow = (f64, Vec<f64>, Vec<f64>, f64, usize);

/// One zero-amplitude extrapolation as the CLI prints and writes it.
pub(crate) struct ZeroTable<'a> {
    pub names: &'a [&'a str],
    pub units: &'a [&'a str],
    pub est: &'a [f64],
    pub std: &'a [f64],
    pub intervals: &'a [(f64, f64)],
    pub slope: &'a [f64],
    pub chi2: &'a [f64],
    pub variance_scale: &'a [f64],
    /// The relative change from zero amplitude to the top level.
    pub change: &'a [f64],
    pub dof: usize,
    /// Per level ([`LevelRow`]).
    pub levels: Vec<LevelRow>,
    /// The FRF files in the order of the levels.
    pub files: Vec<String>,
}

/// Prints the zero-amplitude table (`heading` names the rule) and returns its JSON section.
pub(crate) fn zero_amplitude_table(
    z: &ZeroTable<'_>,
    truth: Option<&[f64]>,
    heading: &str,
) -> serde_json::Value {
    let top = z.levels.iter().map(|l| l.0).fold(0.0f64, f64::max);
    println!(
        "extrapolated to zero amplitude from {} levels ({}; {heading}):",
        z.levels.len(),
        z.levels
            .iter()
            .map(|l| format!("{}", l.0))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let mut rows = Vec::with_capacity(z.names.len());
    for k in 0..z.names.len() {
        let (lo, hi) = z.intervals[k];
        println!(
            "{:>16} {:>14.6e} {:>12.3e} {:>14.6e}..{:<14.6e} {:>14} {} (change at level {top}: {:+.3} %)",
            z.names[k],
            z.est[k],
            z.std[k],
            lo,
            hi,
            truth.map_or(String::new(), |t| format!("{:.6e}", t[k])),
            z.units[k],
            100.0 * z.change[k]
        );
        rows.push(json!({
            "name": z.names[k],
            "unit": z.units[k],
            "estimate": z.est[k],
            "std": z.std[k],
            "interval": [lo, hi],
            "slope_per_level_squared": z.slope[k],
            "relative_change_at_top_level": z.change[k],
            "chi2": z.chi2[k],
            "variance_scale": z.variance_scale[k],
            "twin": truth.map(|t| t[k]),
        }));
    }
    json!({
        "levels": z.levels.iter().map(|(l, e, s, c, d)| json!({
            "level": l,
            "estimate": e,
            "std": s,
            "chi2": c,
            "dof": d,
        })).collect::<Vec<_>>(),
        "files": z.files,
        "parameter_order": z.names,
        "dof": z.dof,
        "parameters": rows,
    })
}

pub fn physical(a: PhysicalArgs) -> Result<()> {
    OutputSet::check(&a.out, a.force)?;
    if !(a.confidence > 0.0 && a.confidence < 1.0) {
        return Err(ambid::error::Error::usage(format!(
            "--confidence must lie in (0, 1), e.g. 0.95; got {}",
            a.confidence
        ))
        .into());
    }
    if is_matrix_frf(&a.frf)? {
        return super::physical_machine::physical_machine(&a);
    }
    super::physical_operating::check_operating_args(&a)?;
    if a.speed_rpm.is_some() || a.polar_inertia.is_some() {
        return Err(ambid::error::Error::usage(
            "--speed-rpm and --polar-inertia belong to a 4×4 matrix FRF (P_xa_xa_re, …); this file is a single-axis FRF",
        )
        .into());
    }
    let (Some(model_path), Some(controller_path)) = (&a.model, &a.controller) else {
        return Err(ambid::error::Error::usage(
            "a single-axis FRF needs --model (the black-box plant model JSON whose unstable pole and resonances start the fit) and --controller (the loop's controller, which holds bearing B)",
        )
        .into());
    };
    let level = match (a.level, a.also.is_empty()) {
        (Some(l), _) if !(l.is_finite() && l > 0.0) => {
            return Err(
                ambid::error::Error::usage(format!("--level must be positive, got {l}")).into(),
            )
        }
        (None, false) => {
            return Err(ambid::error::Error::usage(
                "--also needs --level, the excitation level of FRF (e.g. --level 10 for 10 % of i_sat), to extrapolate to zero amplitude",
            )
            .into())
        }
        (l, _) => l,
    };
    let (drawing, truth, magnet_truth) = match &a.drawing {
        Some(p) => (ambid::physical::read_drawing(p)?, None, None),
        None => {
            let twin = ambid_twin::Twin::new(twin_config(&a.twin)?)?;
            (
                twin_drawing(twin.config()),
                Some(as_array(&twin_truth(&twin))),
                Some(ambid::physical::operating::twin_magnet_truth(&twin)),
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
        model_path,
        controller_path,
        NEEDS,
    )?;
    let popts = PhysicalOptions {
        confidence: a.confidence,
        ..PhysicalOptions::default()
    };
    let fit = estimate(&frd, &model, &drawing, ctrl.state_space(), &popts)?;
    // the other levels, on the same band (everything is estimated before anything is written)
    let mut levels: Vec<(f64, PhysicalFit)> = Vec::new();
    if let Some(l) = level {
        levels.push((l, fit.clone()));
    }
    for (l, file) in &a.also {
        let (other, _, _) = frf_with_variance(file, &a.quantity, a.fs, Some(band), NEEDS)?;
        ctrl.check_ts(other.ts().unwrap_or(1.0 / ctrl.fs_hz()))?;
        let f = estimate(&other, &model, &drawing, ctrl.state_space(), &popts)
            .with_context(|| format!("the estimate at level {l} ({})", file.display()))?;
        levels.push((*l, f));
    }
    let zero = if levels.len() > 1 {
        Some(extrapolate_to_zero_amplitude(
            &at_levels(&levels),
            a.confidence,
        )?)
    } else {
        None
    };
    let est = as_array(&fit.params);
    println!(
        "gray-box fit over {} lines in {:.1}–{:.1} Hz: chi2/dof {:.3} ({} iterations, {:?})",
        frd.len(),
        band.0,
        band.1,
        fit.chi2 / fit.dof as f64,
        fit.iterations,
        fit.stop
    );
    let rows = parameter_table(
        &PARAMETER_NAMES,
        &UNITS,
        &est,
        &fit.std,
        &fit.intervals,
        truth.as_ref().map(|t| t.as_slice()),
        a.confidence,
    );
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
    let operating_json = match a.bias_current {
        Some(nominal_bias) if !a.operating.is_empty() => {
            Some(super::physical_operating::operating_section(
                &super::physical_operating::OperatingInput {
                    nominal: &fit,
                    nominal_bias,
                    files: &a.operating,
                    band,
                    quantity: &a.quantity,
                    fs: a.fs,
                    drawing: &drawing,
                    controller: ctrl.state_space(),
                    controller_ts: 1.0 / ctrl.fs_hz(),
                    opts: &popts,
                    truth: magnet_truth,
                    needs: NEEDS,
                },
            )?)
        }
        _ => None,
    };
    let files: Vec<String> = std::iter::once(a.frf.display().to_string())
        .chain(a.also.iter().map(|(_, f)| f.display().to_string()))
        .collect();
    let zero_json = match &zero {
        None => serde_json::Value::Null,
        Some(z) => {
            let top = levels.iter().map(|(l, _)| *l).fold(0.0f64, f64::max);
            zero_amplitude_table(
                &ZeroTable {
                    names: &PARAMETER_NAMES,
                    units: &UNITS,
                    est: &z.params_array(),
                    std: &z.std,
                    intervals: &z.intervals,
                    slope: &z.slope,
                    chi2: &z.chi2,
                    variance_scale: &z.variance_scale,
                    change: &z.change_at(top),
                    dof: z.dof,
                    levels: levels
                        .iter()
                        .map(|(l, f)| (*l, as_array(&f.params).to_vec(), f.std.to_vec(), f.chi2, f.dof))
                        .collect(),
                    files,
                },
                truth.as_ref().map(|t| t.as_slice()),
                "the line in level² per parameter, module docs of ambid_core::estimate::graybox::amplitude",
            )
        }
    };
    let summary = json!({
        "frf": a.frf.display().to_string(),
        "model": model_path.display().to_string(),
        "controller": controller_path.display().to_string(),
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
        "zero_amplitude": zero_json,
        "operating_points": operating_json,
    });
    let mut set = OutputSet::new(a.force);
    set.write(&a.out, serde_json::to_string_pretty(&summary)?.as_bytes())?;
    set.commit()?;
    println!("written: {}", a.out.display());
    Ok(())
}
