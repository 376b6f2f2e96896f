//! `ambid uncertainty` on a 4×4 matrix FRF (`P_<out>_<in>_re/_im/_std`, as `ambid frf` writes it
//! from the experiments of `ambid simulate --axes 4` or a rig): the element-wise bound of a 4×4
//! nominal model on the measured lines, raised by its joint factor; the structured relative weight
//! (one stable minimum-phase weight of order ≤ 4 per entry); the robust stability of the four
//! decentralised controllers against the bound on the lines and against the weight, with the
//! robust gain margins; the uncertain model exported for MATLAB and Python (docs/uncertainty.md,
//! "MIMO entries"; the same computation as the workflow's `[machine] uncertainty`). With
//! `--amplitude LEVEL=FRF … --level L` every entry's bound has term (e), from the 4×4 FRFs of the
//! same design at other excitation levels.

use super::common::machine_base;
use super::uncertainty::UncertaintyArgs;
use ambid::error::Error;
use ambid::io::export::mimo::MimoNames;
use ambid::io::export::uncertain_matrix::{
    uncertain_matrix_json, uncertain_matrix_mat_bytes, uncertain_matrix_matlab_script,
    uncertain_matrix_npz_bytes,
};
use ambid::io::OutputSet;
use ambid::workflow::machine::{read_machine_frf, LevelFrf};
use ambid::workflow::machine_fit::{
    fit_band, speed_uncertainty, AmplitudeStudy, MAX_VALIDATION_RELATIVE_STD,
};
use ambid_core::data::AXES;
use ambid_core::validate::uncertainty::{DEFAULT_RAISE_COVER, DEFAULT_RUN_COVERAGE};
use ambid_core::validate::weight::{WeightShape, DEFAULT_COVER, MAX_WEIGHT_ORDER};
use ambid_twin::Machine;
use anyhow::{Context, Result};
use serde_json::json;

/// The files the machine path writes into `--out`.
const FILES: [&str; 6] = [
    "uncertainty.csv",
    "summary.json",
    "uncertain.json",
    "uncertain.m",
    "uncertain.mat",
    "uncertain.npz",
];

/// The quality band of the default fit band \[Hz\] (the `[machine]` default, `quality_band_hz`).
const QUALITY_BAND_HZ: [f64; 2] = [10.0, 1000.0];

/// The single-axis options this path does not take, with whether each was given.
fn single_axis_options(a: &UncertaintyArgs) -> Vec<&'static str> {
    let mut v = Vec::new();
    let mut refuse = |given: bool, name: &'static str| {
        if given {
            v.push(name);
        }
    };
    refuse(a.controller.is_some(), "--controller (the four controllers come from the machine configuration: --config machine.toml or --rig-seed)");
    refuse(
        a.quantity != "plant",
        "--quantity (the plant is the file's P_<out>_<in> entries)",
    );
    refuse(
        a.fs.is_some(),
        "--fs (the file's fs_hz column gives the sample rate)",
    );
    refuse(!a.operating.is_empty(), "--operating");
    refuse(a.nonlinear.is_some(), "--nonlinear");
    refuse(a.line_coverage != 0.95, "--line-coverage");
    refuse(a.max_order != MAX_WEIGHT_ORDER, "--max-order");
    refuse(a.cover != DEFAULT_COVER, "--cover");
    refuse(a.run_coverage != DEFAULT_RUN_COVERAGE, "--run-coverage");
    refuse(a.raise_cover != DEFAULT_RAISE_COVER, "--raise-cover");
    refuse(a.weight_shape != WeightShape::ModeShaped, "--weight-shape");
    refuse(a.per_line_misfit.is_some(), "--per-line-misfit");
    v
}

pub fn uncertainty_machine(a: &UncertaintyArgs) -> Result<()> {
    for f in FILES {
        OutputSet::check(&a.out.join(f), a.force)?;
    }
    let refused = single_axis_options(a);
    if !refused.is_empty() {
        return Err(Error::usage(format!(
            "{} do(es) not apply to a 4×4 matrix FRF: the MIMO bound takes terms (a), (b) and with --amplitude (e), with the defaults (line coverage 0.95, weights of order ≤ {MAX_WEIGHT_ORDER} over {} of each entry's lines; the bound raised to cover 98 % of the (line, entry) pairs, the weights' to cover 95 %, in 95 % of the error draws; docs/uncertainty.md, \"MIMO entries\")",
            refused.join(", "),
            DEFAULT_COVER
        ))
        .into());
    }
    let mut cfg = machine_base(&a.twin)?;
    if let Some(s) = a.speed_rpm {
        if !(s.is_finite() && s >= 0.0) {
            return Err(Error::usage(format!("--speed-rpm must be ≥ 0, got {s}")).into());
        }
        cfg.speed_rpm = s;
    }
    let speed = cfg.speed_rpm;
    let machine = Machine::new(cfg).context("the machine configuration")?;
    let meas = read_machine_frf(&a.frf, speed)?;
    let plant = &meas.frf.plant;
    let model = ambid::io::model::read_model_json(&a.model)?;
    if model.ninputs() != 4 || model.noutputs() != 4 {
        return Err(Error::input(format!(
            "{}: the model is {}×{}; a 4×4 matrix FRF needs a 4×4 plant model (inputs u_xa, u_xb, u_ya, u_yb; outputs y_*), e.g. the models/ssN_<speed>rpm.json of `ambid run` with a [machine] section",
            a.model.display(),
            model.noutputs(),
            model.ninputs()
        ))
        .into());
    }
    match (model.ts(), plant.ts()) {
        (Some(m), Some(p)) if (m - p).abs() <= 1e-9 * p => {}
        (m, p) => {
            return Err(Error::input(format!(
                "{}: the model's sample time {m:?} s differs from the FRF's {p:?} s",
                a.model.display()
            ))
            .into())
        }
    }
    let controller = machine.controller();
    match controller.ts() {
        Some(c) if (c - plant.ts().unwrap_or(c)).abs() <= 1e-9 * c => {}
        c => {
            return Err(Error::input(format!(
                "the machine configuration's controllers run at a sample time of {c:?} s, the FRF's is {:?} s: give the configuration of the machine that was measured (--config)",
                plant.ts()
            ))
            .into())
        }
    }
    let band = match a.band {
        Some(b) => b,
        None => fit_band(plant, QUALITY_BAND_HZ)?.ok_or_else(|| {
            Error::input(format!(
                "{}: no run of three lines in {}–{} Hz measures the plant precisely enough (relative standard deviation); give --band",
                a.frf.display(),
                QUALITY_BAND_HZ[0],
                QUALITY_BAND_HZ[1]
            ))
        })?,
    };
    println!(
        "band {:.1}–{:.1} Hz{}",
        band.0,
        band.1,
        if a.band.is_some() {
            " (given)"
        } else {
            " (the precise lines of the plant in 10–1000 Hz, as the [machine] fit's)"
        }
    );
    // term (e): the other levels' 4×4 FRFs, with the nominal FRF at --level (the level's unit
    // cancels: only the ratios of the squared levels enter)
    let levels = match (a.amplitude.is_empty(), a.level) {
        (true, None) => Vec::new(),
        (true, Some(_)) => {
            return Err(Error::usage(
                "--level without --amplitude: give the other levels' 4×4 FRFs as --amplitude LEVEL=FRF, or leave out --level",
            )
            .into())
        }
        (false, None) => {
            return Err(Error::usage(
                "--amplitude needs --level, the nominal FRF's excitation level in the same unit",
            )
            .into())
        }
        (false, Some(_)) => a
            .amplitude
            .iter()
            .map(|(l, path)| {
                let m = read_machine_frf(path, speed)?;
                Ok(LevelFrf {
                    level_pct: *l,
                    plant: m.frf.plant,
                    // a file does not say whether its record saturated: the user's to check
                    saturated_fraction: 0.0,
                })
            })
            .collect::<Result<Vec<_>>>()?,
    };
    let study = a.level.map(|level_pct| AmplitudeStudy {
        level_pct,
        levels: &levels,
    });
    let row = speed_uncertainty(
        speed,
        plant,
        band,
        &model,
        controller,
        Some(machine.plant()),
        study.as_ref(),
    )
    .map_err(|e| Error::computation(format!("the MIMO uncertainty: {e}")))?;
    if let Some(n) = &row.amplitude_note {
        return Err(Error::input(format!("--amplitude: {n}")).into());
    }
    if let (Some(l), Some(m)) = (&row.amplitude_levels_pct, row.amplitude_median_rel_pct) {
        println!(
            "term (e) from the levels {}: median σ̄(E)/σ̄(P̂) {m:.2} %",
            l.iter()
                .map(|v| format!("{v}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let export = row
        .export
        .as_ref()
        .ok_or_else(|| Error::computation("the MIMO uncertainty has no export"))?;
    if !export.on_lines.nominal_stable {
        eprintln!(
            "warning: the model with the configuration's four controllers gives an unstable loop, so no robust margin exists: its unstable poles disagree with the loop's (fit the model knowing the controllers, e.g. `ambid run` with a [machine] section on the twin), or the configuration is not the measured machine's"
        );
    }
    let margins = |m: Option<[f64; 2]>| {
        m.map_or("none (not robustly stable)".to_string(), |[lo, hi]| {
            format!("{lo:.3}…{hi:.3}")
        })
    };
    println!(
        "{} lines at {speed} rpm ({:.1}–{:.1} Hz: the fit band{}); the element-wise bound raised ×{:.3} (98 % of the pairs in 95 % of the error draws); ‖L‖/σ̄(P̂) median {:.2} %, max {:.2} %",
        row.lines,
        row.bound_band_hz[0],
        row.bound_band_hz[1],
        if row.bound_band_hz[1] > row.band_hz[1] {
            format!(" and the validation lines above it, where the FRF's relative std stays ≤ {MAX_VALIDATION_RELATIVE_STD}")
        } else {
            String::new()
        },
        row.raise,
        row.median_rel_pct,
        row.max_rel_pct
    );
    println!(
        "against the bound on the lines: robustly stable {} (max μ {:.3} at {:.1} Hz), robust gain margins {}",
        row.robustly_stable,
        row.mu_peak,
        row.mu_peak_hz,
        margins(row.gain_margins)
    );
    println!(
        "against {} coherent draws of the model's error (whole matrices; the misfit element-wise around each; up to an octave outside the lines the entry weights, gains {}{}): {:.1} % of the draws stable, robust gain margins at {:.0} % of the draws {}",
        row.coherent_draws,
        margins(row.coherent_outside_gain_interval),
        row.coherent_outside_critical_hz[1]
            .map_or(String::new(), |f| format!(", ended above at {f:.1} Hz")),
        100.0 * row.coherent_stable_fraction,
        100.0 * row.coherent_confidence,
        margins(row.coherent_gain_margins)
    );
    println!(
        "against the structured weight (order ≤ {}, over the bound raised ×{:.3} for 95 % of the pairs; median looseness {:.2}): robustly stable {} (max μ {:.3} at {:.1} Hz), robust gain margins {}",
        row.weight_max_order,
        row.weight_raise,
        row.weight_looseness,
        row.weight_robustly_stable,
        row.weight_mu_peak,
        row.weight_mu_peak_hz,
        margins(row.weight_gain_margins)
    );
    if let Some([lo, hi]) = row.exact_gain_margins {
        println!(
            "the configuration's exact plant: gain margins {lo:.3}…{hi:.3}; the bound covers σ̄(P − P̂) on {:.1} % of the lines in 10–1000 Hz, the weight on {:.1} %",
            100.0 * row.truth_coverage.unwrap_or(f64::NAN),
            100.0 * row.weight_truth_coverage.unwrap_or(f64::NAN)
        );
    }
    // per line: the bound and the weight's magnitude per entry (column-major: out, in)
    let mut header = vec!["f_hz".to_string()];
    for inp in AXES.iter() {
        for out in AXES.iter() {
            header.push(format!("bound_{out}_{inp}"));
        }
    }
    for inp in AXES.iter() {
        for out in AXES.iter() {
            header.push(format!("weight_{out}_{inp}"));
        }
    }
    let mags: Vec<Vec<f64>> = export
        .weights
        .iter()
        .map(|w| w.weight.magnitude(&export.f_hz))
        .collect();
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(&header)?;
    for (k, f) in export.f_hz.iter().enumerate() {
        let mut rec = vec![format!("{f:.17e}")];
        rec.extend(export.bounds.iter().map(|b| format!("{:.17e}", b[k])));
        rec.extend(mags.iter().map(|m| format!("{:.17e}", m[k])));
        w.write_record(&rec)?;
    }
    let table = w
        .into_inner()
        .map_err(|e| anyhow::anyhow!("{}", e.error()))?;
    let stem = a
        .model
        .file_stem()
        .map_or("plant".into(), |s| s.to_string_lossy().into_owned());
    let names = MimoNames::axes(&format!("{stem}_uncertain"), &AXES, Some(speed));
    let summary = json!({
        "frf": a.frf.display().to_string(),
        "model": a.model.display().to_string(),
        "speed_rpm": speed,
        "nominal_loop_stable": export.on_lines.nominal_stable,
        "uncertainty": row,
        "files": FILES,
    });
    let json_model = uncertain_matrix_json(export, &names)?;
    let mut set = OutputSet::new(a.force);
    set.write(&a.out.join("uncertainty.csv"), &table)?;
    set.write(
        &a.out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    set.write(
        &a.out.join("uncertain.json"),
        serde_json::to_string_pretty(&json_model)?.as_bytes(),
    )?;
    set.write(
        &a.out.join("uncertain.m"),
        uncertain_matrix_matlab_script(export, &names)?.as_bytes(),
    )?;
    set.write(
        &a.out.join("uncertain.mat"),
        &uncertain_matrix_mat_bytes(export, &names)?,
    )?;
    set.write(
        &a.out.join("uncertain.npz"),
        &uncertain_matrix_npz_bytes(export, &names)?,
    )?;
    set.commit()?;
    println!("written: {} ({})", a.out.display(), FILES.join(", "));
    Ok(())
}
