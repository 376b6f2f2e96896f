//! `ambid physical … --bias-current A --operating BIAS:GAP_UM=FILE …`: the gray box at each
//! operating point of the operating-point study and the magnet law through them — the magnet
//! constant and the effective air gap with intervals, each point's gap from its own static
//! ratio, and k_i, k_x at nominal pooled over every point; with 4×4 matrix FRFs one law per
//! axis, so each bearing's magnet gets its own constant and gap (docs/physical.md).

use super::common::frf_with_variance;
use ambid::physical::operating::{
    estimate_at_operating_points, estimate_machine_at_operating_points, MagnetLawFit, OperatingFrf,
    Predicted,
};
use ambid::physical::{Drawing, MachinePhysicalFit, PhysicalFit, PhysicalOptions, Rotation};
use ambid_core::data::AXES;
use ambid_core::lti::{Frd, StateSpace};
use anyhow::{Context, Result};
use serde_json::json;
use std::path::PathBuf;

/// One `--operating` value: bias current \[A\], gap offset \[µm\], the FRF file.
pub(crate) type OperatingFile = (f64, f64, PathBuf);

/// Parses `BIAS:GAP_UM=FILE` (e.g. `1.6:0=frf_b16.csv`, `2:-10=frf_g390.csv`).
pub(crate) fn parse_operating_file(s: &str) -> std::result::Result<OperatingFile, String> {
    const FORM: &str = "expected BIAS:GAP_UM=FILE (bias current in A, gap offset from the nominal gap in µm, positive = wider), e.g. 1.6:0=frf_b16.csv";
    let (point, file) = s.split_once('=').ok_or_else(|| format!("`{s}`: {FORM}"))?;
    let (bias, gap) = point
        .split_once(':')
        .ok_or_else(|| format!("`{s}`: {FORM}"))?;
    let bias: f64 = bias
        .trim()
        .trim_end_matches('A')
        .parse()
        .map_err(|_| format!("`{bias}` is not a bias current in A: {FORM}"))?;
    let gap: f64 = gap
        .trim()
        .trim_end_matches("um")
        .parse()
        .map_err(|_| format!("`{gap}` is not a gap offset in µm: {FORM}"))?;
    if !(bias.is_finite() && bias > 0.0) {
        return Err(format!(
            "`{s}`: the bias current must be positive, got {bias}"
        ));
    }
    if !gap.is_finite() {
        return Err(format!("`{s}`: the gap offset must be finite"));
    }
    if file.is_empty() {
        return Err(format!("`{s}`: the file is missing; {FORM}"));
    }
    Ok((bias, gap, PathBuf::from(file)))
}

/// Checks `--bias-current` and `--operating` (both or neither; not with `--also`; a positive
/// bias): usage errors naming the fix.
pub(crate) fn check_operating_args(a: &super::physical::PhysicalArgs) -> Result<()> {
    if a.bias_current.is_some() || !a.operating.is_empty() {
        if !a.also.is_empty() {
            return Err(ambid::error::Error::usage(
                "--operating and --also are not combined: estimate the operating points at one excitation level (the extrapolation to zero amplitude per operating point is not built)",
            )
            .into());
        }
        match a.bias_current {
            None => {
                return Err(ambid::error::Error::usage(
                    "--operating needs --bias-current, the bias current of FRF's operating point in A (e.g. --bias-current 2.0)",
                )
                .into())
            }
            Some(b) if !(b.is_finite() && b > 0.0) => {
                return Err(ambid::error::Error::usage(format!(
                    "--bias-current must be positive (A), got {b}"
                ))
                .into())
            }
            Some(_) if a.operating.is_empty() => {
                return Err(ambid::error::Error::usage(
                    "--bias-current is used with --operating BIAS:GAP_UM=FILE (the other operating points); without them there is nothing to fit the magnet law to",
                )
                .into())
            }
            Some(_) => {}
        }
    }
    Ok(())
}

/// The `--operating` files' set points with their FRFs (offsets from µm to m).
fn operating_frfs<'a>(files: &[OperatingFile], frds: &'a [Frd]) -> Vec<OperatingFrf<'a>> {
    files
        .iter()
        .zip(frds)
        .map(|((bias, gap_um, _), frd)| OperatingFrf {
            bias_current_a: *bias,
            gap_offset_m: gap_um * 1e-6,
            frd,
        })
        .collect()
}

/// Prints one magnet law (its χ², k and g₀ with intervals and the twin's values, k_i and k_x
/// pooled at the nominal point; `label` names the axis) and returns the parameter rows and the
/// pooled values.
fn law_table(
    law: &MagnetLawFit,
    nominal_bias: f64,
    truth: Option<(f64, f64)>,
    label: &str,
) -> Result<(Vec<serde_json::Value>, (Predicted, Predicted))> {
    let conf = 100.0 * law.confidence;
    println!(
        "magnet law{label} k_i = 4 k i0/g^2, k_x = 4 k i0^2/g^3 through {} operating points: chi2 {:.2} on {} dof{}",
        law.residuals.len(),
        law.chi2,
        law.dof,
        if law.variance_scale > 1.0 {
            format!(
                " (above its 95 % point: the law holds less well than the intervals say; variance x{:.2})",
                law.variance_scale
            )
        } else {
            String::new()
        }
    );
    let names = ["force_constant", "air_gap"];
    let units = ["N m^2/A^2", "m"];
    let values = [law.force_constant, law.air_gap_m];
    let mut rows = Vec::new();
    for k in 0..2 {
        let (lo, hi) = law.intervals[k];
        let twin = truth.map(|t| if k == 0 { t.0 } else { t.1 });
        println!(
            "{:>16} {:>14.6e} {:>12.3e} {:>14.6e}..{:<14.6e} {:>14} {} ({conf:.0} % interval)",
            names[k],
            values[k],
            law.std[k],
            lo,
            hi,
            twin.map_or(String::new(), |t| format!("{t:.6e}")),
            units[k]
        );
        rows.push(json!({
            "name": names[k], "unit": units[k], "estimate": values[k], "std": law.std[k],
            "interval": [lo, hi], "twin": twin,
        }));
    }
    let (ki, kx) = law.predict(nominal_bias, 0.0)?;
    println!(
        "pooled at the nominal point: k_i {:.6e} ({:.6e}..{:.6e}) N/A, k_x {:.6e} ({:.6e}..{:.6e}) N/m",
        ki.value, ki.interval.0, ki.interval.1, kx.value, kx.interval.0, kx.interval.1
    );
    Ok((rows, (ki, kx)))
}

/// The whole machine's operating-point section: the gray box at each other operating point
/// (`others`, the FRFs of `files` on the main FRF's band) and one magnet law per axis; prints
/// the four laws and returns the JSON section.
pub(crate) fn machine_operating_section(
    nominal: &MachinePhysicalFit,
    nominal_bias: f64,
    files: &[OperatingFile],
    others: &[Frd],
    (drawing, rotation, opts): (&Drawing, &Rotation, &PhysicalOptions),
    truth: Option<[(f64, f64); 4]>,
) -> Result<serde_json::Value> {
    let points = operating_frfs(files, others);
    let est = estimate_machine_at_operating_points(
        nominal,
        nominal_bias,
        &points,
        drawing,
        rotation,
        opts,
    )
    .context("the operating-point estimate")?;
    let mut axes = Vec::with_capacity(4);
    for (a, (law, name)) in est.laws.iter().zip(AXES).enumerate() {
        let (rows, (ki, kx)) = law_table(
            law,
            nominal_bias,
            truth.map(|t| t[a]),
            &format!(" of {name}"),
        )?;
        axes.push(json!({
            "axis": name,
            "parameters": rows,
            "covariance_log": law.covariance,
            "chi2": law.chi2,
            "dof": law.dof,
            "variance_scale": law.variance_scale,
            "pooled_at_nominal": {"k_i": ki, "k_x": kx},
            "gaps_from_ratio_m": law.gaps_from_ratio,
            "whitened_residuals": law.residuals,
        }));
    }
    let point_rows: Vec<serde_json::Value> =
        std::iter::once((nominal_bias, 0.0, nominal, "nominal (FRF)".to_string()))
            .chain(
                files
                    .iter()
                    .zip(&est.fits)
                    .map(|((b, g, f), fit)| (*b, *g, fit, f.display().to_string())),
            )
            .map(|(bias, gap_um, fit, file)| {
                json!({
                    "file": file,
                    "bias_current_a": bias,
                    "gap_offset_m": gap_um * 1e-6,
                    "k_i": fit.params.k_i,
                    "k_x": fit.params.k_x,
                    "bending_hz": fit.params.bending_hz,
                    "chi2": fit.chi2,
                    "dof": fit.dof,
                })
            })
            .collect();
    Ok(json!({
        "model": "per axis: k_i = 4 k i0 / g^2, k_x = 4 k i0^2 / g^3, g = g0 + offset (module docs of ambid_core::estimate::graybox::magnet)",
        "axes": axes,
        "points": point_rows,
    }))
}

/// What the operating-point section needs from the main estimate.
pub(crate) struct OperatingInput<'a> {
    pub nominal: &'a PhysicalFit,
    pub nominal_bias: f64,
    pub files: &'a [OperatingFile],
    pub band: (f64, f64),
    pub quantity: &'a str,
    pub fs: Option<f64>,
    pub drawing: &'a Drawing,
    pub controller: &'a StateSpace,
    pub controller_ts: f64,
    pub opts: &'a PhysicalOptions,
    /// The twin's magnet constant and nominal gap, when the drawing is the twin's.
    pub truth: Option<(f64, f64)>,
    pub needs: &'a str,
}

/// Reads the files on the main FRF's band, estimates, prints the tables and returns the JSON
/// section (nothing is written here).
pub(crate) fn operating_section(x: &OperatingInput<'_>) -> Result<serde_json::Value> {
    let mut frds: Vec<Frd> = Vec::with_capacity(x.files.len());
    for (_, _, file) in x.files {
        let (frd, _, _) = frf_with_variance(file, x.quantity, x.fs, Some(x.band), x.needs)?;
        match frd.ts() {
            Some(ts) if (ts - x.controller_ts).abs() <= 1e-9 * ts => {}
            _ => {
                return Err(ambid::error::Error::input(format!(
                    "{}: its sample time differs from the controller's ({} s); every operating point must be measured with the same controller",
                    file.display(),
                    x.controller_ts
                ))
                .into())
            }
        }
        frds.push(frd);
    }
    let others = operating_frfs(x.files, &frds);
    let est = estimate_at_operating_points(
        x.nominal,
        x.nominal_bias,
        &others,
        x.drawing,
        x.controller,
        x.opts,
    )
    .context("the operating-point estimate")?;
    let law = &est.law;
    let (rows, (ki, kx)) = law_table(law, x.nominal_bias, x.truth, "")?;
    println!(
        "{:>10} {:>10} {:>14} {:>14} {:>14} {:>22}",
        "bias A", "gap um", "k_i N/A", "k_x N/m", "gap from ratio", "whitened residual"
    );
    let all: Vec<(f64, f64, &PhysicalFit, String)> =
        std::iter::once((x.nominal_bias, 0.0, x.nominal, "nominal (FRF)".to_string()))
            .chain(
                x.files
                    .iter()
                    .zip(&est.fits)
                    .map(|((b, g, f), fit)| (*b, *g, fit, f.display().to_string())),
            )
            .collect();
    let mut points = Vec::new();
    for (n, (bias, gap_um, fit, file)) in all.iter().enumerate() {
        let (g, (glo, ghi)) = law.gaps_from_ratio[n];
        let r = law.residuals[n];
        println!(
            "{bias:>10.4} {gap_um:>+10.2} {:>14.6e} {:>14.6e} {:>14.6e} {:>+10.2} {:>+10.2}",
            fit.params.k_i, fit.params.k_x, g, r[0], r[1]
        );
        points.push(json!({
            "file": file,
            "bias_current_a": bias,
            "gap_offset_m": gap_um * 1e-6,
            "k_i": fit.params.k_i, "k_i_std": fit.std[0],
            "k_x": fit.params.k_x, "k_x_std": fit.std[1],
            "bending_hz": fit.params.bending_hz,
            "chi2": fit.chi2, "dof": fit.dof,
            "gap_from_ratio_m": {"estimate": g, "interval": [glo, ghi]},
            "whitened_residuals": r,
        }));
    }
    Ok(json!({
        "model": "k_i = 4 k i0 / g^2, k_x = 4 k i0^2 / g^3, g = g0 + offset (module docs of ambid_core::estimate::graybox::magnet)",
        "parameters": rows,
        "covariance_log": law.covariance,
        "chi2": law.chi2,
        "dof": law.dof,
        "variance_scale": law.variance_scale,
        "pooled_at_nominal": {"k_i": ki, "k_x": kx},
        "points": points,
    }))
}
