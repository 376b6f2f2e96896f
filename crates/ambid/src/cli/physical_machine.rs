//! `ambid physical` on a 4×4 matrix FRF (`P_<out>_<in>_re/_im/_std`, as `ambid frf` writes it
//! from the experiments of `ambid simulate --axes 4` or a rig): $k_i$ and $k_x$ of every axis'
//! magnet, the bending mode and its shape, with confidence intervals, from the plant with all
//! loops open (docs/physical.md, "The whole machine").

use super::common::machine_base;
use super::physical::{parameter_table, zero_amplitude_table, PhysicalArgs, ZeroTable};
use ambid::error::Error;
use ambid::io::model::state_space_json;
use ambid::io::OutputSet;
use ambid::physical::{
    extrapolate_machine_to_zero_amplitude, fit_machine_physical, machine_drawing, machine_truth,
    MachineAtLevel, MachinePhysicalFit, PhysicalOptions, Rotation, MACHINE_AXES,
    MACHINE_PARAMETER_NAMES,
};
use ambid::workflow::machine::read_machine_frf;
use ambid_core::lti::Frd;
use ambid_core::lti::StateSpace;
use ambid_twin::{Machine, MachineConfig};
use anyhow::{Context, Result};
use serde_json::json;

const UNITS: [&str; 12] = [
    "N/A", "N/A", "N/A", "N/A", "N/m", "N/m", "N/m", "N/m", "Hz", "-", "kg^-1/2", "kg^-1/2",
];

/// The median over the lines and the four diagonal entries of $|M_{jj} - G_{jj}|/|G_{jj}|$.
fn median_diag_error(model: &StateSpace, frd: &Frd) -> Result<f64> {
    let r = model.freq_response(frd.f_hz())?;
    let mut e = Vec::with_capacity(4 * r.len());
    for (k, m) in r.iter().enumerate() {
        let g = frd.at(k)?;
        for j in 0..4 {
            e.push((m[(j, j)] - g[(j, j)]).norm() / g[(j, j)].norm());
        }
    }
    e.sort_by(f64::total_cmp);
    Ok(e.get(e.len() / 2).copied().unwrap_or(f64::NAN))
}

pub fn physical_machine(a: &PhysicalArgs) -> Result<()> {
    let refuse = |what: &str| -> Result<()> {
        Err(Error::usage(format!(
            "{what} does not apply to a 4×4 matrix FRF (the whole-machine gray box, docs/physical.md)"
        ))
        .into())
    };
    let level = match (a.level, a.also.is_empty()) {
        (Some(l), _) if !(l.is_finite() && l > 0.0) => {
            return Err(Error::usage(format!("--level must be positive, got {l}")).into())
        }
        (None, false) => {
            return Err(Error::usage(
                "--also needs --level, the excitation level of FRF (e.g. --level 10 for 10 % of i_sat), to extrapolate to zero amplitude",
            )
            .into())
        }
        (l, _) => l,
    };
    super::physical_operating::check_operating_args(a)?;
    if a.model.is_some() || a.controller.is_some() {
        return refuse(
            "--model/--controller (the starts come from the data, and all loops are open)",
        );
    }
    if a.quantity != "plant" {
        return refuse("--quantity (the plant is the file's P_<out>_<in> entries)");
    }
    if a.fs.is_some() {
        return refuse("--fs (the file's fs_hz column gives the sample rate)");
    }
    // the drawing: the file's, else the twin machine's (whose true values are printed beside)
    let twin_cfg: Option<MachineConfig> = if a.drawing.is_none() {
        Some(machine_base(&a.twin)?)
    } else {
        None
    };
    let drawing = match &a.drawing {
        Some(p) => ambid::physical::read_drawing(p)?,
        None => twin_cfg
            .as_ref()
            .map(|c| machine_drawing(c).0)
            .ok_or_else(|| Error::other("no drawing"))?,
    };
    let speed_rpm = a
        .speed_rpm
        .or(twin_cfg.as_ref().map(|c| c.speed_rpm))
        .unwrap_or(0.0);
    if !(speed_rpm.is_finite() && speed_rpm >= 0.0) {
        return Err(Error::usage(format!(
            "--speed-rpm {speed_rpm} must be finite and >= 0 (the speed the FRF was measured at)"
        ))
        .into());
    }
    let polar = a
        .polar_inertia
        .or(twin_cfg.as_ref().map(MachineConfig::polar_inertia));
    let rotation = match polar {
        Some(j) if j.is_finite() && j > 0.0 => Rotation {
            speed_rpm,
            polar_inertia_kgm2: j,
        },
        Some(j) => {
            return Err(Error::usage(format!(
                "--polar-inertia {j} must be positive and finite, kg·m²"
            ))
            .into())
        }
        None if speed_rpm > 0.0 => {
            return Err(Error::usage(format!(
                "at {speed_rpm} rpm the gyroscopic moments need the rotor's polar inertia: give --polar-inertia in kg·m² (a solid cylinder: m r²/2)"
            ))
            .into())
        }
        None => Rotation::STANDSTILL,
    };
    let full = read_machine_frf(&a.frf, speed_rpm)?.frf.plant;
    let frd = match a.band {
        Some((lo, hi)) => full.band(lo, hi).map_err(|e| {
            Error::usage(format!(
                "--band {lo}:{hi}: {e}; the file has lines in {:.2}–{:.2} Hz",
                full.f_hz().first().copied().unwrap_or(f64::NAN),
                full.f_hz().last().copied().unwrap_or(f64::NAN)
            ))
        })?,
        None => full,
    };
    let band = (frd.f_hz()[0], frd.f_hz()[frd.len() - 1]);
    let opts = PhysicalOptions {
        confidence: a.confidence,
        ..PhysicalOptions::default()
    };
    let fit = fit_machine_physical(&frd, &drawing, &rotation, &[], &opts)
        .context("the whole-machine gray-box fit")?;
    // the other levels on the same band (everything is estimated before anything is written)
    let mut levels: Vec<(f64, MachinePhysicalFit)> = Vec::new();
    if let Some(l) = level {
        levels.push((l, fit.clone()));
    }
    for (l, file) in &a.also {
        let other = read_machine_frf(file, speed_rpm)?
            .frf
            .plant
            .band(band.0, band.1)?;
        let f = fit_machine_physical(&other, &drawing, &rotation, &[], &opts)
            .with_context(|| format!("the estimate at level {l} ({})", file.display()))?;
        levels.push((*l, f));
    }
    let zero = if levels.len() > 1 {
        let points: Vec<MachineAtLevel> = levels
            .iter()
            .map(|(l, f)| MachineAtLevel {
                level: *l,
                params: f.params,
                std: f.std,
            })
            .collect();
        Some(extrapolate_machine_to_zero_amplitude(
            &points,
            a.confidence,
        )?)
    } else {
        None
    };
    let truth = match &twin_cfg {
        Some(c) => Some(
            machine_truth(&Machine::new(MachineConfig {
                speed_rpm,
                ..c.clone()
            })?)
            .to_array(),
        ),
        None => None,
    };
    let est = fit.params.to_array();
    println!(
        "whole-machine gray-box fit over {} lines × 16 entries in {:.1}–{:.1} Hz at {speed_rpm} rpm: chi2/dof {:.3} ({} iterations, {:?})",
        frd.len(),
        band.0,
        band.1,
        fit.chi2 / fit.dof as f64,
        fit.iterations,
        fit.stop
    );
    let rows = parameter_table(
        &MACHINE_PARAMETER_NAMES,
        &UNITS,
        &est,
        &fit.std,
        &fit.intervals,
        truth.as_ref().map(|t| t.as_slice()),
        a.confidence,
    );
    let ratios: Vec<_> = fit
        .ratios()
        .iter()
        .zip(MACHINE_AXES)
        .map(|((r, (lo, hi)), ax)| {
            println!(
                "identifiable without the drawing: k_i/k_x of {ax} = {r:.6e} m/A ({lo:.6e}..{hi:.6e})"
            );
            json!({"axis": ax, "estimate": r, "interval": [lo, hi], "unit": "m/A"})
        })
        .collect();
    let e_gray = median_diag_error(&fit.model, &frd)?;
    println!(
        "median relative difference of the gray box ({} states, 12 parameters) from the measured FRF on the diagonal entries (the FRF's noise included): {:.3} %",
        fit.model.order(),
        100.0 * e_gray
    );
    let operating_json = match a.bias_current {
        Some(nominal_bias) if !a.operating.is_empty() => {
            let magnet_truth = match &twin_cfg {
                Some(c) => Some(ambid::physical::operating::machine_magnet_truth(
                    &Machine::new(MachineConfig {
                        speed_rpm,
                        ..c.clone()
                    })?,
                )),
                None => None,
            };
            let mut others = Vec::with_capacity(a.operating.len());
            for (_, _, file) in &a.operating {
                others.push(
                    read_machine_frf(file, speed_rpm)?
                        .frf
                        .plant
                        .band(band.0, band.1)?,
                );
            }
            Some(super::physical_operating::machine_operating_section(
                &fit,
                nominal_bias,
                &a.operating,
                &others,
                (&drawing, &rotation, &opts),
                magnet_truth,
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
                    names: &MACHINE_PARAMETER_NAMES,
                    units: &UNITS,
                    est: &z.params.to_array(),
                    std: &z.std,
                    intervals: &z.intervals,
                    slope: &z.slope,
                    chi2: &z.chi2,
                    variance_scale: &z.variance_scale,
                    change: &z.change_at(top),
                    dof: z.dof,
                    levels: levels
                        .iter()
                        .map(|(l, f)| {
                            (
                                *l,
                                f.params.to_array().to_vec(),
                                f.std.to_vec(),
                                f.chi2,
                                f.dof,
                            )
                        })
                        .collect(),
                    files,
                },
                truth.as_ref().map(|t| t.as_slice()),
                "a line in level² per parameter",
            )
        }
    };
    let summary = json!({
        "frf": a.frf.display().to_string(),
        "axes": MACHINE_AXES,
        "drawing": drawing,
        "rotation": rotation,
        "band_hz": [band.0, band.1],
        "lines": frd.len(),
        "confidence": a.confidence,
        "parameters": rows,
        "parameter_order": MACHINE_PARAMETER_NAMES,
        "covariance_log_theta": fit.covariance,
        "chi2": fit.chi2,
        "dof": fit.dof,
        "variance_scale": fit.variance_scale,
        "iterations": fit.iterations,
        "stop": format!("{:?}", fit.stop),
        "ratios_ki_kx": ratios,
        "graybox_median_rel_error_diagonal": e_gray,
        "graybox_model": state_space_json(&fit.model, "u", "y", json!({"kind": "graybox_machine", "axes": MACHINE_AXES})),
        "zero_amplitude": zero_json,
        "operating_points": operating_json,
    });
    let mut set = OutputSet::new(a.force);
    set.write(&a.out, serde_json::to_string_pretty(&summary)?.as_bytes())?;
    set.commit()?;
    println!("written: {}", a.out.display());
    Ok(())
}
