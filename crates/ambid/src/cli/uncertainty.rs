//! `ambid uncertainty`: the uncertainty of a nominal plant model around the measured plant FRF
//! (terms (a)–(e) per line, docs/uncertainty.md), the stable minimum-phase weight of order ≤ 4
//! that overbounds it, the robust stability of the loop's controller against it, and the
//! uncertain model exported for MATLAB and Python.

use super::args::parse_band;
use super::common::{controller_for, frf_and_model, frf_with_variance};
use ambid::io::export::uncertain::{
    coherent_json, robust_json, uncertain_json, uncertain_mat_bytes, uncertain_matlab_script,
    uncertain_npz_bytes, UncertainModel, UncertainNames,
};
use ambid::io::OutputSet;
use ambid::uncertainty::{
    amplitude_term_and_shifts, bound_and_weight, nonlinear_term, operating_term, RobustChecks,
    COHERENT_DRAWS, NONLINEAR_ALPHA,
};
use ambid_core::frf::bla::BlaEstimate;
use ambid_core::validate::uncertainty::{
    CorrelatedLines, ExtraTerms, PerLineMisfit, UncertaintyOptions, DEFAULT_RAISE_COVER,
    DEFAULT_RUN_COVERAGE, ROUGH_MISFIT, SMOOTH_MISFIT,
};
use ambid_core::validate::weight::{WeightShape, DEFAULT_COVER, MAX_WEIGHT_ORDER};
use anyhow::Result;
use clap::Args;
use serde_json::json;
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct UncertaintyArgs {
    /// FRF CSV (as written by `ambid frf`) with the measured plant and its standard deviations
    /// (a single-axis FRF, or a 4×4 matrix FRF `P_<out>_<in>_re/_im/_std`).
    pub(crate) frf: PathBuf,
    /// The nominal model JSON (`ambid fit`, `compare-models`, or a workflow's models/<name>.json);
    /// its input is the plant input u, its output y; unstable poles are kept. With a 4×4 matrix
    /// FRF a 4×4 model (inputs u_xa, u_xb, u_ya, u_yb), e.g. a `[machine]` workflow's
    /// models/ssN_<speed>rpm.json.
    #[arg(long)]
    pub(crate) model: PathBuf,
    /// Controller file (TOML/JSON) of the loop, for the robust-stability check. Without it a
    /// single-axis FRF gets the bound, the weight and the uncertain model only (a plant whose
    /// controller is still to be designed, or a record without a loop): no robust.csv, and
    /// `robust`/`robust_on_lines` null in summary.json. With a 4×4 matrix FRF the four
    /// controllers come from the machine configuration (--config machine.toml, --rig-seed, or
    /// the nominal machine).
    #[arg(long)]
    pub(crate) controller: Option<PathBuf>,
    /// 4×4 matrix FRF only: the machine configuration (its four controllers, and its exact
    /// linearised plant, against which the bound's coverage and the margins are printed).
    #[command(flatten)]
    pub(crate) twin: super::common::TwinArgs,
    /// 4×4 matrix FRF only: the rotor speed the FRF was measured at, rpm (default: the
    /// configuration's).
    #[arg(long)]
    pub(crate) speed_rpm: Option<f64>,
    /// Quantity of the FRF file that is the plant.
    #[arg(long, default_value = "plant")]
    pub(crate) quantity: String,
    /// Sample rate of the data in Hz (default: the `fs_hz` column of the FRF file).
    #[arg(long)]
    pub(crate) fs: Option<f64>,
    /// Band `f_min:f_max` in Hz (default: where the file measures the plant reliably, the rule of
    /// `compare-models`; printed).
    #[arg(long, value_parser = parse_band)]
    pub(crate) band: Option<(f64, f64)>,
    /// Probability that the bound covers the error at one line (the terms' quantile).
    #[arg(long, default_value_t = 0.95)]
    pub(crate) line_coverage: f64,
    /// Highest order of the weight (0–4).
    #[arg(long, default_value_t = MAX_WEIGHT_ORDER)]
    pub(crate) max_order: usize,
    /// Fraction of the lines the weight overbounds (1: all; the default leaves out the 2 % that
    /// stand out most, the narrow peaks at the plant's anti-resonances, which are listed).
    #[arg(long, default_value_t = DEFAULT_COVER)]
    pub(crate) cover: f64,
    /// Fraction of the fitted model's error draws (2 000, seeded) in which the weight must
    /// overbound the error on `--raise-cover` of the lines; the weight's gain is raised until it
    /// does (the default 0.99 makes up for draws narrower than the true error;
    /// docs/uncertainty.md).
    #[arg(long, default_value_t = DEFAULT_RUN_COVERAGE)]
    pub(crate) run_coverage: f64,
    /// Fraction of the lines on which the raised weight must overbound each of those draws (the
    /// default is the coverage bar's 95 %; 1: every line).
    #[arg(long, default_value_t = DEFAULT_RAISE_COVER)]
    pub(crate) raise_cover: f64,
    /// The weight's family: `mode` (the default: also lightly damped pole pairs at the bound's
    /// peaks with zero pairs at its dips, and notches; the tighter of it and the smooth fit is
    /// kept) or `smooth` (every factor damped, ζ ≥ 0.2: looser, with narrower robust margins;
    /// docs/uncertainty.md, "The mode-shaped weight as the single-axis default").
    #[arg(long, default_value = "mode", value_parser = parse_shape)]
    pub(crate) weight_shape: WeightShape,
    /// Whether term (b) also tests each line alone, a significant misfit entering as its upper
    /// value: `auto` (the default) when the misfit is rough from line to line (roughness ≥ 4,
    /// printed) and no `--nonlinear` is given, as for an FRF from one multisine realisation
    /// whose nonlinear distortion shows as a per-line misfit far above the noise that the
    /// windows average away; `on`; `off` (the windows alone). docs/uncertainty.md, "The line
    /// alone when the misfit is rough". Single-axis FRFs only (a 4×4 FRF's entries use `auto`).
    #[arg(long, value_name = "auto|on|off", value_parser = parse_per_line)]
    pub(crate) per_line_misfit: Option<PerLineMisfit>,
    /// Whether terms (a) and (b) allow for noise correlated between neighbouring lines: `auto`
    /// (the default) multiplies the FRF's variances by $\kappa = 1 + 2(\rho_1 + \rho_2)$ when the
    /// misfit's lag-1 correlation is significant and short-range (a Welch FRF's lines correlate
    /// at about 0.4; printed), `off` takes the lines as independent. docs/uncertainty.md,
    /// "Welch FRFs: correlated lines".
    #[arg(long, value_name = "auto|off", value_parser = parse_correlated)]
    pub(crate) correlated_lines: Option<CorrelatedLines>,
    /// Term (f): `on` (the default) adds the model's distance from the FRF's own fit of its
    /// order (the inverse-variance state-space fit that terms (a) and (b) describe; 0 when the
    /// model is that fit), which keeps the bound a bound for a model of another structure or
    /// estimator (an output-error polynomial, a time-domain fit) or other weights; `off` leaves
    /// it out. Single-axis FRFs only. docs/uncertainty.md, "A model not fitted to the FRF".
    #[arg(long, value_name = "on|off", value_parser = parse_on_off)]
    pub(crate) fit_distance: Option<bool>,
    /// Term (d): the plant FRF CSV of the same experiment at another operating point (bias
    /// current, air gap; `ambid frf` of a record with the same excitation, so the same lines).
    /// Repeat it for each; the bound then holds the largest noise-corrected distance of them from
    /// the nominal FRF (docs/uncertainty.md).
    #[arg(long = "operating", value_name = "FRF")]
    pub(crate) operating: Vec<PathBuf>,
    /// Term (e): the plant FRF CSV of the same experiment at another excitation level, as
    /// `LEVEL=FRF` (LEVEL in the unit of `--level`, e.g. % of i_sat). Repeat it for each level;
    /// with the nominal FRF at `--level`, the bound then holds the shift of the best linear
    /// approximation at `--level` from its extrapolation to zero amplitude (docs/uncertainty.md).
    #[arg(long = "amplitude", value_name = "LEVEL=FRF", value_parser = parse_level_frf)]
    pub(crate) amplitude: Vec<(f64, PathBuf)>,
    /// The excitation level of the nominal FRF (needed with `--amplitude`, in its unit).
    #[arg(long)]
    pub(crate) level: Option<f64>,
    /// Term (c): the per-line CSV of a robust BLA measurement at the identification level
    /// (`ambid bla --level`, columns `f_hz`, `bla_re`, `bla_im`, `bla_std`, `noise_std`, `var_nl`,
    /// `realisations`, `periods`); its relative nonlinear variance, tested in groups of lines
    /// and kept where significant, is carried to the FRF's lines (docs/uncertainty.md).
    #[arg(long, value_name = "BLA")]
    pub(crate) nonlinear: Option<PathBuf>,
    /// Output directory: uncertainty.csv, robust.csv (with --controller), summary.json and the
    /// uncertain model (uncertain.m, uncertain.mat, uncertain.npz, uncertain.json).
    #[arg(long, default_value = "uncertainty")]
    pub(crate) out: PathBuf,
    /// Replace those files if they exist (other files in the directory are left alone).
    #[arg(long)]
    pub(crate) force: bool,
}

/// The files `uncertainty` writes into `--out`.
const FILES: [&str; 7] = [
    "uncertainty.csv",
    "robust.csv",
    "summary.json",
    "uncertain.m",
    "uncertain.mat",
    "uncertain.npz",
    "uncertain.json",
];

fn csv_bytes(header: &[String], columns: &[&[f64]]) -> Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(header)?;
    let n = columns.first().map_or(0, |c| c.len());
    for k in 0..n {
        w.write_record(columns.iter().map(|c| format!("{:.17e}", c[k])))?;
    }
    w.into_inner().map_err(|e| anyhow::anyhow!("{}", e.error()))
}

fn path_in(dir: &Path, f: &str) -> PathBuf {
    dir.join(f)
}

pub fn uncertainty(a: UncertaintyArgs) -> Result<()> {
    if super::physical::is_matrix_frf(&a.frf)? {
        return super::uncertainty_machine::uncertainty_machine(&a);
    }
    for f in FILES {
        OutputSet::check(&path_in(&a.out, f), a.force)?;
    }
    if !(a.line_coverage > 0.0 && a.line_coverage < 1.0) {
        return Err(ambid::error::Error::usage(format!(
            "--line-coverage must lie in (0, 1), e.g. 0.95; got {}",
            a.line_coverage
        ))
        .into());
    }
    // the fractions in (0, 1]
    for (name, value, example) in [
        ("--cover", a.cover, "0.98 or 1 (every line)"),
        ("--raise-cover", a.raise_cover, "0.95 or 1 (every line)"),
        ("--run-coverage", a.run_coverage, "0.95"),
    ] {
        if !(value > 0.0 && value <= 1.0) {
            return Err(ambid::error::Error::usage(format!(
                "{name} must lie in (0, 1], e.g. {example}; got {value}"
            ))
            .into());
        }
    }
    if a.max_order > MAX_WEIGHT_ORDER {
        return Err(ambid::error::Error::usage(format!(
            "--max-order is at most {MAX_WEIGHT_ORDER} (a low-order weight for controller design); got {}",
            a.max_order
        ))
        .into());
    }
    let twin_given = a.twin.config.is_some()
        || a.twin.rig.rig_seed.is_some()
        || a.twin.bias.is_some()
        || a.twin.gap.is_some();
    if twin_given || a.speed_rpm.is_some() {
        return Err(ambid::error::Error::usage(
            "--config, --rig-seed, --bias, --gap and --speed-rpm belong to a 4×4 matrix FRF (P_xa_xa_re, …); this file is a single-axis FRF: its loop's controller, for the robust-stability check, is --controller",
        )
        .into());
    }
    let robust_csv_path = path_in(&a.out, "robust.csv");
    if a.controller.is_none() && robust_csv_path.is_file() {
        // --force replaces files; it would leave this one beside a summary without a check
        return Err(ambid::error::Error::usage(format!(
            "{} holds a robust-stability check of an earlier run, and without --controller none is made: remove it, give --controller, or choose another --out",
            robust_csv_path.display()
        ))
        .into());
    }
    let (frd, band, model, fit_noise) = frf_and_model(
        &a.frf,
        &a.quantity,
        a.fs,
        a.band,
        &a.model,
        "the uncertainty needs the FRF's standard deviations (an FRF of `ambid frf` from several periods or realisations)",
    )?;
    // with the plant's noise as a function of its value (`plant_noise_*`, `ambid frf`): each
    // line's variance at the model (the variance at the data follows the line's own error) and
    // term (f)'s reference fit under the same criterion, as the workflow's step
    // (docs/uncertainty.md, "Weights that follow the data's noise")
    let frd = match &fit_noise {
        Some(n) => {
            println!(
                "variances: at the model (the file's `{}_noise_*` columns)",
                a.quantity
            );
            ambid::uncertainty::variances_at_model(&frd, n, &model)?
        }
        None => frd,
    };
    let per_line_setting = a.per_line_misfit.unwrap_or_default();
    let corr_setting = a.correlated_lines.unwrap_or_default();
    let ctrl = match &a.controller {
        Some(p) => Some(controller_for(p, &frd)?),
        None => None,
    };
    // term (d) from the other operating points' FRFs, on the nominal FRF's lines
    let spread = if a.operating.is_empty() {
        None
    } else {
        let mut plants = vec![frd.clone()];
        for path in &a.operating {
            let (other, _, _) = frf_with_variance(
                path,
                &a.quantity,
                a.fs,
                Some(band),
                "term (d) needs each operating point's standard deviations, like the nominal FRF's",
            )?;
            plants.push(other);
        }
        Some(operating_term(&plants, frd.f_hz(), &model).map_err(|e| {
            ambid::error::Error::input(format!(
                "--operating: {e}; record every operating point with the nominal experiment's excitation and sample rate"
            ))
        })?)
    };
    // term (e) from the other excitation levels' FRFs, with the nominal FRF at --level
    let amplitude = match (a.amplitude.is_empty(), a.level) {
        (true, None) => None,
        (true, Some(_)) => {
            return Err(ambid::error::Error::usage(
                "--level without --amplitude: give the other levels' FRFs as --amplitude LEVEL=FRF, or leave out --level",
            )
            .into())
        }
        (false, None) => {
            return Err(ambid::error::Error::usage(
                "--amplitude needs --level, the nominal FRF's excitation level in the same unit",
            )
            .into())
        }
        (false, Some(level)) => {
            let mut levels = vec![(level, frd.clone())];
            for (l, path) in &a.amplitude {
                let (other, _, _) = frf_with_variance(
                    path,
                    &a.quantity,
                    a.fs,
                    Some(band),
                    "term (e) needs each level's standard deviations, like the nominal FRF's",
                )?;
                levels.push((*l, other));
            }
            let refs: Vec<(f64, &ambid_core::lti::Frd)> =
                levels.iter().map(|(l, g)| (*l, g)).collect();
            let input = |e: ambid::error::Error| ambid::error::Error::input(format!("--amplitude: {e}"));
            // the line term, and the per-line shifts for term (e) through the model
            Some(
                amplitude_term_and_shifts(&refs, level, frd.f_hz(), &model, a.line_coverage)
                    .map_err(input)?,
            )
        }
    };
    // term (c) from a robust BLA's nonlinear variance, tested in groups of lines
    let nonlinear = match &a.nonlinear {
        None => None,
        Some(path) => {
            let bla = read_bla(path)?;
            Some(
                nonlinear_term(&bla, 1.0, frd.f_hz(), &model, NONLINEAR_ALPHA).map_err(|e| {
                    ambid::error::Error::input(format!("--nonlinear {}: {e}", path.display()))
                })?,
            )
        }
    };
    if let Some(n) = &nonlinear {
        println!(
            "term (c): the BLA's nonlinear variance is significant in {} of {} groups of lines",
            n.significant_groups(),
            n.groups.len()
        );
    }
    let extra = ExtraTerms {
        // no significant group: no term (a zero term would still change the joint draws)
        nonlinear_std: nonlinear
            .as_ref()
            .filter(|n| n.significant_groups() > 0)
            .map(|n| n.std.as_slice()),
        operating_spread: spread.as_deref(),
        amplitude_shift: amplitude.as_ref().map(|a| a.term.as_slice()),
        fit_noise: fit_noise.as_deref(),
    };
    let analysis = bound_and_weight(
        &model,
        &frd,
        &extra,
        amplitude.as_ref().map(|a| a.shift_lines()),
        &UncertaintyOptions {
            line_coverage: a.line_coverage,
            run_coverage: a.run_coverage,
            raise_cover: a.raise_cover,
            weight_shape: a.weight_shape,
            per_line_misfit: per_line_setting,
            correlated_lines: corr_setting,
            fit_distance: a.fit_distance.unwrap_or(true),
            ..UncertaintyOptions::default()
        },
        a.max_order,
        a.cover,
    )?;
    let checks = match &ctrl {
        Some(c) => Some(analysis.robust_checks(&model, c.state_space())?),
        None => None,
    };
    match &analysis.amplitude_projected {
        Some(Ok(p)) => println!(
            "term (e) through the model: Wald statistic {:.1} against {:.1} (χ², 5 %): {}",
            p.statistic,
            p.threshold,
            if p.kept { "kept" } else { "not significant" }
        ),
        Some(Err(e)) => println!("term (e) through the model left out (the line term stays): {e}"),
        None => {}
    }
    let t = &analysis.terms;
    let w = &analysis.weight;
    println!(
        "term (b): the misfit's roughness {} (line to line against the noise; ≥ {ROUGH_MISFIT} is rough); each line alone also tested: {} ({})",
        t.misfit_roughness
            .map_or_else(|| "-".to_string(), |r| format!("{r:.2}")),
        if t.per_line_misfit { "yes" } else { "no" },
        per_line_setting.name(),
    );
    let lc = &t.line_correlation;
    if lc.factor > 1.0 {
        println!(
            "terms (a) and (b): the FRF's neighbouring lines are correlated (ρ₁ {:.2}, ρ₂ {:.2}: \
             {:.1} standard errors; a windowed (Welch) FRF?), so its variances are taken × {:.2} \
             for every average over lines ({})",
            lc.rho1,
            lc.rho2,
            lc.z,
            lc.factor,
            corr_setting.name()
        );
    }
    match (&t.fit_distance, &t.fit_distance_failed) {
        (Some(_), _) => println!(
            "term (f): the model's distance from the FRF's own fit of its order, median {:.3} % of |P̂| (0 when the model is that fit)",
            100.0 * t.fit_distance_median_rel().unwrap_or(0.0)
        ),
        (None, Some(e)) => println!(
            "warning: term (f) left out, the FRF's own fit failed ({e}); the bound then holds for a model fitted to this FRF with inverse-variance weights only"
        ),
        (None, None) => {}
    }
    if let Some(r) = t.misfit_roughness.filter(|r| *r < SMOOTH_MISFIT) {
        println!(
            "warning: the misfit is far smoother from line to line than the FRF's variances say \
             (roughness {r:.2} < {SMOOTH_MISFIT}): its lines are not independent (a local \
             polynomial or smoothed FRF?) or its variances are too large. Terms (a) and (b) take \
             the lines as independent, so the bound's calibration is not known for this FRF; an \
             FRF from period averaging (`ambid frf --period-samples N`) has independent lines"
        );
    }

    // the per-line table
    let wmag = w.weight.magnitude(&t.f_hz);
    let cols: Vec<Vec<f64>> = vec![
        t.f_hz.clone(),
        t.nominal.iter().map(|x| x.re).collect(),
        t.nominal.iter().map(|x| x.im).collect(),
        t.measured.iter().map(|x| x.re).collect(),
        t.measured.iter().map(|x| x.im).collect(),
        t.misfit.clone(),
        t.frf_confidence.clone(),
        t.model_error.clone(),
        t.additive.clone(),
        t.multiplicative.clone(),
        wmag.clone(),
    ];
    let header: Vec<String> = [
        "f_hz",
        "nominal_re",
        "nominal_im",
        "measured_re",
        "measured_im",
        "misfit",
        "term_frf_confidence",
        "term_model_error",
        "bound_additive",
        "bound_multiplicative",
        "weight_mag",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let (mut cols, mut header) = (cols, header);
    if let Some(o) = &t.nonlinear {
        cols.push(o.clone());
        header.push("term_nonlinear".into());
    }
    if let Some(o) = &t.operating {
        cols.push(o.clone());
        header.push("term_operating".into());
    }
    if let Some(e) = &t.amplitude {
        cols.push(e.clone());
        header.push("term_amplitude".into());
    }
    if let Some(d) = &t.fit_distance {
        cols.push(d.clone());
        header.push("term_fit_distance".into());
    }
    let refs: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
    let table = csv_bytes(&header, &refs)?;
    let robust_csv = match &checks {
        Some(c) => Some(csv_bytes(
            &["f_hz".into(), "mu".into()],
            &[&c.weight.f_hz, &c.weight.mu],
        )?),
        None => None,
    };

    let names = UncertainNames {
        name: "uncertain_plant".into(),
        input: "u".into(),
        output: "y".into(),
    };
    let u = UncertainModel {
        nominal: &model,
        weight: w,
        terms: t,
        robust: checks.as_ref().map(|c| &c.weight),
    };
    let covered = wmag
        .iter()
        .zip(&t.multiplicative)
        .filter(|(m, l)| *m >= *l)
        .count();
    let summary = json!({
        "frf": a.frf.display().to_string(),
        "model": a.model.display().to_string(),
        "controller": a.controller.as_ref().map(|p| p.display().to_string()),
        "band_hz": [band.0, band.1],
        "band_from_file": a.band.is_none(),
        "lines": t.f_hz.len(),
        "line_coverage": t.line_coverage,
        "window_half_lines": t.window_half_lines,
        "per_line_misfit": t.per_line_misfit,
        "per_line_misfit_setting": per_line_setting.name(),
        "misfit_roughness": t.misfit_roughness,
        "line_correlation": {
            "setting": corr_setting.name(),
            "rho1": lc.rho1,
            "rho2": lc.rho2,
            "z": lc.z,
            "variance_factor": lc.factor,
        },
        "variances": if fit_noise.is_some() { "at the model (plant_noise_* columns)" } else { "at the data (<q>_std)" },
        "fit_distance": {
            "setting": if a.fit_distance.unwrap_or(true) { "on" } else { "off" },
            "median_rel": t.fit_distance_median_rel(),
            "failed": t.fit_distance_failed,
        },
        "lines_raise": analysis.lines_raise,
        "weight": {
            "order": w.weight.order(),
            "looseness": w.looseness,
            "per_order": w.per_order,
            "cover": a.cover,
            "run_coverage": a.run_coverage,
            "raise_cover": a.raise_cover,
            "shape": a.weight_shape.name(),
            "joint_raise": analysis.joint_raise,
            "lines_covered": covered,
            "uncovered_hz": w.uncovered_hz,
        },
        "operating": t.operating_median_rel().map(|m| json!({
            "files": a.operating.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
            "spread_median_rel": m,
        })),
        "nonlinear": a.nonlinear.as_ref().zip(nonlinear.as_ref()).map(|(p, n)| json!({
            "file": p.display().to_string(),
            "groups": n.groups,
            "significant_groups": n.significant_groups(),
        })),
        "amplitude": t.amplitude_median_rel().map(|m| json!({
            "level": a.level,
            "levels": a.amplitude.iter().map(|(l, p)| json!({"level": l, "file": p.display().to_string()})).collect::<Vec<_>>(),
            "shift_median_rel": m,
            "projected": match &analysis.amplitude_projected {
                Some(Ok(p)) => json!(p),
                Some(Err(e)) => json!({ "error": e }),
                None => serde_json::Value::Null,
            },
        })),
        "robust": checks.as_ref().map(|c| robust_json(&c.weight)),
        "robust_on_lines": checks.as_ref().map(|c| json!({
            "raise": analysis.lines_raise,
            "check": robust_json(&c.on_lines),
        })),
        "robust_coherent": checks.as_ref().map(|c| coherent_json(&c.coherent)),
    });

    let mut set = OutputSet::new(a.force);
    set.write(&path_in(&a.out, "uncertainty.csv"), &table)?;
    if let Some(bytes) = &robust_csv {
        set.write(&robust_csv_path, bytes)?;
    }
    set.write(
        &path_in(&a.out, "summary.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    set.write(
        &path_in(&a.out, "uncertain.m"),
        uncertain_matlab_script(&u, &names)?.as_bytes(),
    )?;
    set.write(
        &path_in(&a.out, "uncertain.mat"),
        &uncertain_mat_bytes(&u, &names)?,
    )?;
    set.write(
        &path_in(&a.out, "uncertain.npz"),
        &uncertain_npz_bytes(&u, &names)?,
    )?;
    set.write(
        &path_in(&a.out, "uncertain.json"),
        serde_json::to_string_pretty(&uncertain_json(&u, &names)?)?.as_bytes(),
    )?;

    println!(
        "uncertainty over {} lines in {:.4}–{:.4} Hz (line coverage {:.0} %, misfit window ±{} lines)",
        t.f_hz.len(),
        band.0,
        band.1,
        100.0 * t.line_coverage,
        t.window_half_lines
    );
    println!(
        "weight: order {}, looseness {:.2} (median |W|/bound; gain raised ×{:.3} to cover {:.0} % of the lines in {:.0} % of the model's error draws), covers {} of {} lines{}",
        w.weight.order(),
        w.looseness,
        analysis.joint_raise,
        100.0 * a.raise_cover,
        100.0 * a.run_coverage,
        covered,
        t.f_hz.len(),
        if w.uncovered_hz.is_empty() {
            String::new()
        } else {
            format!(
                " (above it: {})",
                w.uncovered_hz
                    .iter()
                    .map(|f| format!("{f:.1} Hz"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        }
    );
    let margin = |x: Option<f64>| match x {
        Some(g) if g.is_infinite() => "unlimited".to_string(),
        Some(g) => format!("{g:.3}"),
        None => "-".to_string(),
    };
    match &checks {
        Some(RobustChecks {
            weight: r,
            on_lines: ol,
            coherent: co,
        }) => {
            println!(
                "against {COHERENT_DRAWS} coherent draws of the model's error (whole curves; the misfit of unknown phase around each; up to an octave outside the lines the weight, gains {}): {:.1} % of the draws stable, robust gain margins at {:.0} % of the draws: down to {}, up to {} (the reported margins, docs/uncertainty.md)",
                co.outside_gain_interval
                    .map_or("-".to_string(), |[lo, hi]| format!("{} … {}", margin(Some(lo)), margin(Some(hi)))),
                100.0 * co.stable_fraction,
                100.0 * co.confidence,
                margin(co.lower_gain_margin),
                margin(co.upper_gain_margin),
            );
            println!(
                "robust stability: {} (max |W T| = {:.3} at {:.1} Hz, margin {:.3}); robust gain margins: down to {}, up to {}",
                if r.robustly_stable {
                    "yes"
                } else if r.nominal_stable {
                    "NO (the nominal loop is stable, the uncertain set is not)"
                } else {
                    "NO (the nominal loop is unstable)"
                },
                r.mu_peak,
                r.mu_peak_hz,
                r.stability_margin,
                margin(r.lower_gain_margin),
                margin(r.upper_gain_margin),
            );
            println!(
                "on the lines (the bound itself ×{:.3}, no weight fit; the band only): {} (max ℓ|T| = {:.3} at {:.1} Hz); robust gain margins: down to {}, up to {}",
                analysis.lines_raise,
                if ol.robustly_stable { "robustly stable" } else { "NOT robustly stable" },
                ol.mu_peak,
                ol.mu_peak_hz,
                margin(ol.lower_gain_margin),
                margin(ol.upper_gain_margin),
            );
        }
        None => println!(
            "robust stability: not checked (no --controller); the bound on the lines would be raised ×{:.3} for its check",
            analysis.lines_raise
        ),
    }
    let written = set.commit()?;
    println!("written: {}", written.len());
    for p in written {
        println!("  {}", p.display());
    }
    Ok(())
}

/// `LEVEL=FRF` of `--amplitude`.
fn parse_level_frf(s: &str) -> Result<(f64, PathBuf), String> {
    let (l, p) = s.split_once('=').ok_or_else(|| {
        format!("`{s}`: give a level and its FRF as LEVEL=FRF, e.g. 16=frf_16pct.csv")
    })?;
    let level: f64 = l
        .trim()
        .parse()
        .map_err(|_| format!("`{l}` in `{s}` is not a number: give the level as LEVEL=FRF"))?;
    if !(level.is_finite() && level > 0.0) {
        return Err(format!(
            "the level {level} in `{s}` must be a positive number"
        ));
    }
    if p.is_empty() {
        return Err(format!("`{s}`: the FRF file after `=` is missing"));
    }
    Ok((level, PathBuf::from(p)))
}

/// The per-line CSV of `ambid bla --level` as the plant's [`BlaEstimate`]: lines, BLA, the
/// BLA's total and noise standard deviations, one realisation's nonlinear variance and the
/// realisation and period counts (read by the data-file reader; the values are checked by
/// `nonlinear_term`). The DFT line numbers are not in the file: `lines` holds the rows' indices.
fn read_bla(path: &Path) -> Result<BlaEstimate> {
    use ambid::io::table::{read_table, ColumnRef, ReadOptions};
    let bad = |e: String| {
        ambid::error::Error::input(format!(
            "--nonlinear {}: {e}; give the per-line CSV of `ambid bla --level` (f_hz, bla_re, bla_im, bla_std, noise_std, var_nl, realisations, periods; files written before 2026-12-02 lack the last two: write it again)",
            path.display()
        ))
    };
    let t = read_table(path, &ReadOptions::default()).map_err(|e| bad(e.to_string()))?;
    let col = |name: &str| {
        t.column(&ColumnRef::parse(name))
            .map(<[f64]>::to_vec)
            .map_err(|e| bad(e.to_string()))
    };
    let (f, re, im) = (col("f_hz")?, col("bla_re")?, col("bla_im")?);
    let (st, sn, vnl) = (col("bla_std")?, col("noise_std")?, col("var_nl")?);
    // standard deviations are squared below: a negative one would pass for a variance
    for (name, c) in [("bla_std", &st), ("noise_std", &sn)] {
        if let Some(k) = c.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(bad(format!(
                "the column `{name}`, data row {}, holds {}: a standard deviation is a finite number ≥ 0",
                k + 1,
                c[k]
            ))
            .into());
        }
    }
    let count = |name: &str| -> Result<usize> {
        let c = col(name)?;
        let v = c.first().copied().unwrap_or(f64::NAN);
        if !(v.is_finite() && v >= 2.0 && v.fract() == 0.0 && c.iter().all(|x| *x == v)) {
            return Err(bad(format!(
                "the column `{name}` must hold one whole number ≥ 2 on every row"
            ))
            .into());
        }
        Ok(v as usize)
    };
    let (m, p) = (count("realisations")?, count("periods")?);
    Ok(BlaEstimate {
        lines: (0..f.len()).collect(),
        values: re
            .iter()
            .zip(&im)
            .map(|(r, i)| ambid_core::c64::new(*r, *i))
            .collect(),
        var_total: st.iter().map(|s| s * s).collect(),
        var_noise: sn.iter().map(|s| s * s).collect(),
        var_nl: vnl,
        f_hz: f,
        realisations: m,
        periods: p,
    })
}

/// `--correlated-lines`: [`CorrelatedLines::from_name`].
fn parse_correlated(s: &str) -> std::result::Result<CorrelatedLines, String> {
    CorrelatedLines::from_name(s).map_err(|e| e.to_string())
}

/// `--fit-distance`: `on` or `off`.
fn parse_on_off(s: &str) -> std::result::Result<bool, String> {
    match s {
        "on" => Ok(true),
        "off" => Ok(false),
        _ => Err(format!("`{s}`: use on or off")),
    }
}

/// `--per-line-misfit`: [`PerLineMisfit::from_name`].
fn parse_per_line(s: &str) -> std::result::Result<PerLineMisfit, String> {
    PerLineMisfit::from_name(s).map_err(|e| e.to_string())
}

/// `--weight-shape`: [`WeightShape::from_name`].
fn parse_shape(s: &str) -> std::result::Result<WeightShape, String> {
    WeightShape::from_name(s).map_err(|e| e.to_string())
}
