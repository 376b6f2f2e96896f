//! `ambid simulate --axes 4`: the whole rotor ([`ambid_twin::Machine`]) in closed loop under a
//! multi-input excitation design ([`MultiInputDesign`]), written as one directory per experiment
//! plus the exact 4×4 truth (docs/formats.md, "Whole rotor").
//!
//! Layout of `--out`:
//!
//! * `exp1/data.csv`, `exp2/data.csv`, … (one per experiment of the design, 1-based): columns
//!   `t, r_xa, r_xb, r_ya, r_yb, u_xa … u_yb, y_xa … y_yb, i_xa … i_yb`;
//! * `truth.csv`: the matrix FRF file ([`matrix_frf_csv`]) of the exact $P$, $T_{ry}$ and $S$ on
//!   every DFT line $k f_s/N$ of the period ($k = 1 \dots \lfloor N/2 \rfloor$, at most
//!   [`MAX_TRUTH_LINES`], else the design's excited lines) joined with a log grid of
//!   `--truth-points` from 1 Hz to just below $f_s/2$ (standard deviations 0: exact);
//! * `meta.json`: the design report, speed, 1× frequency, unbalance, seeds, period.
//!
//! Every experiment starts in its periodic steady state: the machine runs whole periods of the
//! (cyclic) excitation before sample 0 (`MachineSimOptions::settle_samples`, [`settle_samples`]:
//! until the slowest closed-loop transient has decayed by $10^{-13}$), so
//! `ambid frf --skip-periods 0` is exact on noise-free linear data (the default
//! `--skip-periods 1` drops one more period, as for the single-axis twin).

use super::common::{level_frac, machine_base, prbs_order_arg};
use super::simulate::SimulateArgs;
use ambid::error::Error;
use ambid::io::{frf_csv_bytes, time_csv_to, FrfColumn, OutputSet};
use ambid_core::lti::Frd;
use ambid_core::signal::multi::MultiInputDesign;
use ambid_core::signal::{BaseSignal, Grid, MultisineSpec, Phases, PrbsSpec};
use ambid_twin::{
    AsymmetryConfig, Machine, MachineConfig, MachineSimOptions, Mode, UnbalanceConfig, AXES,
};
use anyhow::{Context, Result};
use clap::ValueEnum;
use num_complex::Complex64;
use std::path::{Path, PathBuf};

/// Fewest periods of the cyclic excitation simulated (and discarded) before every experiment's
/// first recorded sample; [`settle_samples`] adds more when the closed loop decays slowly.
pub const SETTLE_PERIODS: usize = 2;

/// Factor by which the slowest closed-loop transient must have decayed before the record starts
/// ($10^{-13}$: far below the $10^{-6}$ self-consistency of noise-free data).
pub const SETTLE_DECAY: f64 = 1e-13;

/// Longest pre-roll, in seconds of simulated time (a closed loop slower than that is reported).
pub const MAX_SETTLE_S: f64 = 20.0;

/// The pre-roll of every experiment in samples: whole periods, at least [`SETTLE_PERIODS`], and
/// enough for the slowest closed-loop pole $z$ to decay by [`SETTLE_DECAY`]
/// ($|z|^n \le$ `SETTLE_DECAY`), at most [`MAX_SETTLE_S`] (then a warning says the record
/// starts before steady state).
pub fn settle_samples(machine: &Machine, period: usize) -> Result<usize> {
    let rho = machine
        .closed_loop_poles()
        .context("the closed-loop poles")?
        .iter()
        .map(|z| z.norm())
        .fold(0.0f64, f64::max);
    let max = (MAX_SETTLE_S / machine.ts()).round() as usize;
    let need = if rho < 1.0 {
        (SETTLE_DECAY.ln() / rho.ln()).ceil().min(max as f64) as usize
    } else {
        max
    };
    if need >= max {
        eprintln!(
            "warning: the slowest closed-loop pole (|z| = {rho:.9}) needs more than {MAX_SETTLE_S} s \
             to settle: the records start before the periodic steady state; use --skip-periods"
        );
    }
    let periods = need.div_ceil(period.max(1)).max(SETTLE_PERIODS);
    Ok(periods * period)
}

/// Largest number of DFT lines of one period on which `truth.csv` is written (every line
/// $k f_s/N$, $k = 1 \dots \lfloor N/2 \rfloor$); a longer period gets the truth on the design's
/// excited lines only (and the log grid).
pub const MAX_TRUTH_LINES: usize = 50_000;

/// The multi-input design of `ambid simulate --axes 4`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum DesignArg {
    /// One axis at a time: 4 experiments, experiment e excites axis e (PRBS).
    Sequential,
    /// Every axis at once with the signs of a 4×4 Hadamard matrix: 4 experiments (PRBS).
    Orthogonal,
    /// One experiment, a multisine in `--band` whose lines are dealt out to the axes in turn.
    Zipper,
}

/// Parses `A,B` (two finite numbers) for `--unbalance` and `--asymmetry`.
pub(crate) fn parse_pair(s: &str) -> Result<(f64, f64), String> {
    let v: Vec<&str> = s.split(',').collect();
    if v.len() != 2 {
        return Err(format!("`{s}`: give two numbers separated by a comma"));
    }
    let num = |t: &str| -> Result<f64, String> {
        let x: f64 = t
            .trim()
            .parse()
            .map_err(|_| format!("`{}` is not a number", t.trim()))?;
        if x.is_finite() {
            Ok(x)
        } else {
            Err(format!("`{}` is not finite", t.trim()))
        }
    };
    Ok((num(v[0])?, num(v[1])?))
}

/// The noise seed of experiment `e` (0-based) of a run with `--seed seed`: SplitMix64 of
/// `seed + (e + 1)·0x9E3779B97F4A7C15` (independent noise in every experiment, and no experiment
/// shares its noise with an experiment of a run with a neighbouring seed).
pub fn experiment_seed(seed: u64, e: usize) -> u64 {
    let mut z = seed.wrapping_add((e as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The machine of `simulate --axes 4`: `--config` as a `MachineConfig` TOML (as `info --axes 4`
/// and `campbell` read it) or a single-plane `TwinConfig` TOML lifted by
/// [`MachineConfig::from_twin`]; else `--rig-seed` or the nominal rig lifted; then `--bias`,
/// `--gap`, `--speed-rpm`, `--unbalance`, `--asymmetry`.
fn machine_config(a: &SimulateArgs) -> Result<MachineConfig> {
    let mut cfg = machine_base(&a.twin)?;
    if let Some(v) = a.speed_rpm {
        if !(v.is_finite() && v >= 0.0) {
            return Err(Error::usage(format!(
                "--speed-rpm {v} must be finite and >= 0 (e.g. --speed-rpm 30000)"
            ))
            .into());
        }
        cfg.speed_rpm = v;
    }
    if let Some((m, e)) = a.unbalance {
        if !(m > 0.0 && e > 0.0) {
            return Err(Error::usage(format!(
                "--unbalance {m},{e}: give the unbalance mass in kg and its eccentricity in m, \
                 both positive, e.g. --unbalance 1e-3,1e-3 (1 g at 1 mm)"
            ))
            .into());
        }
        cfg.unbalance = Some(UnbalanceConfig {
            mass_kg: m,
            eccentricity_m: e,
            ..UnbalanceConfig::default()
        });
    }
    if let Some((ki, kx)) = a.asymmetry {
        cfg.asymmetry = AsymmetryConfig {
            ki_rel: ki,
            kx_rel: kx,
            ..AsymmetryConfig::default()
        };
    }
    cfg.validate()
        .map_err(|e| Error::usage(format!("the 4-axis machine: {e}")))?;
    Ok(cfg)
}

/// Refuses the single-axis options that mean nothing for the whole rotor.
fn refuse_siso_options(a: &SimulateArgs) -> Result<()> {
    let bad: &[(bool, &str, &str)] = &[
        (
            a.excitation_file.is_some(),
            "--excitation-file",
            "the 4-axis excitation is designed by --design",
        ),
        (
            a.reference_chirp.is_some(),
            "--reference-chirp",
            "position references are not available for the whole rotor",
        ),
        (
            a.record_b,
            "--record-b",
            "every axis (bearings A and B, x and y) is recorded",
        ),
        (
            a.integrator.is_some(),
            "--integrator",
            "the whole rotor's nonlinear mode integrates by RK4 (simulation.substeps)",
        ),
        (
            a.excitation.is_some() || a.signal != ambid::experiment::ExcitationKind::Prbs,
            "--signal",
            "the signal follows from --design (PRBS for sequential/orthogonal, multisine for zipper)",
        ),
    ];
    if let Some((_, opt, why)) = bad.iter().find(|b| b.0) {
        return Err(Error::usage(format!(
            "{opt} is not available with --axes 4: {why}; leave it out"
        ))
        .into());
    }
    Ok(())
}

/// The multi-input design of the arguments for sample time `ts` and saturation current `i_sat`:
/// PRBS (`--prbs-order`, `--samples-per-bit`, peak = `--level` % of i_sat per axis) for the
/// sequential and orthogonal designs; a full-grid Schroeder multisine in `--band` with period
/// `--period` for the zipper, scaled so that its largest peak over the axes is the level (the
/// single-axis multisine's peak rule).
fn design(a: &SimulateArgs, ts: f64, i_sat: f64) -> Result<MultiInputDesign> {
    let amp = level_frac(a.level, a.amplitude)? * i_sat;
    if a.periods == 0 {
        return Err(Error::usage("--periods must be at least 1").into());
    }
    let band = super::common::deprecated_band(a.band, a.f_min, a.f_max, ("--f-min", "--f-max"))?;
    let kind = a.design.unwrap_or(DesignArg::Sequential);
    let d = match kind {
        DesignArg::Sequential | DesignArg::Orthogonal => {
            let prbs = PrbsSpec {
                order: prbs_order_arg(a.prbs_order, a.order),
                samples_per_bit: a.samples_per_bit,
                periods: a.periods,
                amplitude: amp,
                offset: 0.0,
            };
            if kind == DesignArg::Sequential {
                MultiInputDesign::sequential(4, BaseSignal::Prbs(prbs))
            } else {
                MultiInputDesign::orthogonal(4, BaseSignal::Prbs(prbs))
            }
        }
        DesignArg::Zipper => {
            if !(a.period.is_finite() && a.period > 0.0) {
                return Err(Error::usage(format!(
                    "--period {} must be a positive duration in s (e.g. --period 0.25575)",
                    a.period
                ))
                .into());
            }
            let ms = |rms: f64| MultisineSpec {
                f_min_hz: band.0,
                f_max_hz: band.1,
                period_samples: (a.period / ts).round() as usize,
                periods: a.periods,
                rms,
                grid: Grid::Full,
                phases: Phases::Schroeder,
                seed: a.seed,
            };
            // the signal is linear in the level: scale so that the largest peak is `amp`
            let unit = MultiInputDesign::zipper(4, ms(1.0))
                .generate(ts)
                .context("designing the zippered multisine")?;
            let peak = unit
                .samples()
                .iter()
                .flatten()
                .flatten()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            if peak.is_nan() || peak <= 0.0 {
                return Err(Error::usage(
                    "the zippered multisine has no lines: widen --band or lengthen --period",
                )
                .into());
            }
            MultiInputDesign::zipper(4, ms(amp / peak))
        }
    };
    d.validate(ts).context("the excitation design")?;
    Ok(d)
}

/// `f` sorted, frequencies closer than 1e-9 relative merged into one.
fn union_grid(mut f: Vec<f64>) -> Vec<f64> {
    f.sort_by(f64::total_cmp);
    let mut out: Vec<f64> = Vec::with_capacity(f.len());
    for v in f {
        match out.last() {
            Some(&l) if (v - l).abs() <= 1e-9 * v.abs().max(1e-300) => {}
            _ => out.push(v),
        }
    }
    out
}

/// The column names and complex columns of a 4×4 response: `<q>_<out>_<in>` in axis order, out
/// major (`P_xa_xa, P_xa_xb, …, P_yb_yb`); `axes` names rows and columns (an index beyond it
/// is named by its 1-based number).
pub fn entries(q: &str, axes: &[&str], g: &Frd) -> Vec<(String, Vec<Complex64>, Option<Vec<f64>>)> {
    let (ny, nu) = (g.ny(), g.nu());
    let per = ny * nu;
    let mut out = Vec::with_capacity(per);
    for i in 0..ny {
        for j in 0..nu {
            let idx = i + j * ny;
            let v: Vec<Complex64> = (0..g.len())
                .map(|k| {
                    let c = g.values()[k * per + idx];
                    Complex64::new(c.re, c.im)
                })
                .collect();
            let s = g
                .variance()
                .map(|var| (0..g.len()).map(|k| var[k * per + idx].sqrt()).collect());
            let name = |k: usize| {
                axes.get(k)
                    .map_or_else(|| format!("{}", k + 1), |a| a.to_string())
            };
            out.push((format!("{q}_{}_{}", name(i), name(j)), v, s));
        }
    }
    out
}

/// The bytes of a matrix FRF CSV (docs/formats.md, "Matrix FRF"): `f_hz`, then for each
/// quantity `(name, response)` every entry `<name>_<out>_<in>_re, _im, _std` (out major, axis
/// order; `_std` the standard deviation of the complex entry, 0 where the response has no
/// variance), then the real `extras`.
pub fn matrix_frf_csv(
    f_hz: &[f64],
    axes: &[&str],
    q: &[(&str, &Frd)],
    extras: &[(&str, &[f64])],
) -> Result<Vec<u8>> {
    let cols: Vec<(String, Vec<Complex64>, Option<Vec<f64>>)> =
        q.iter().flat_map(|(n, g)| entries(n, axes, g)).collect();
    let fc: Vec<FrfColumn> = cols
        .iter()
        .map(|(n, v, s)| FrfColumn {
            name: n,
            values: v,
            std: s.as_deref(),
        })
        .collect();
    Ok(frf_csv_bytes(f_hz, &fc, extras)?)
}

/// The directory of experiment `e` (0-based): `exp1`, `exp2`, ….
pub fn experiment_dir(out: &Path, e: usize) -> PathBuf {
    out.join(format!("exp{}", e + 1))
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

/// Where the unbalance's 1× line falls on the period's DFT grid ($f_k = k f_s/N$): `Some(k)`
/// when it is line $k$ (to $10^{-6}$ of a line spacing; only that line of the FRF carries the
/// unbalance response), `None` without an unbalance force or between lines (its leakage then
/// reaches every line; a warning names the nearest speeds that put it on a line).
pub fn sync_line(sync_hz: f64, period: usize, fs: f64) -> Option<usize> {
    let x = sync_hz * period as f64 / fs;
    let k = x.round();
    (k >= 1.0 && (x - k).abs() <= 1e-6).then_some(k as usize)
}

/// [`sync_line`] for the configured machine, with the note or warning it deserves on stderr.
fn sync_line_note(cfg: &MachineConfig, sync_hz: f64, period: usize, fs: f64) -> Option<usize> {
    let unb = cfg.unbalance.as_ref()?;
    if unb.mass_kg * unb.eccentricity_m == 0.0 || sync_hz <= 0.0 {
        return None;
    }
    let df = fs / period as f64;
    match sync_line(sync_hz, period, fs) {
        Some(k) => {
            eprintln!(
                "note: the unbalance's 1x line ({sync_hz:.4} Hz) is line {k} of the period: the \
                 FRF on that line carries the unbalance response, every other line is free of it"
            );
            Some(k)
        }
        None => {
            let x = sync_hz / df;
            let (lo, hi) = (x.floor().max(1.0), x.ceil().max(1.0));
            eprintln!(
                "warning: the unbalance's 1x line ({sync_hz:.4} Hz) falls between the lines of the \
                 period ({period} samples, {df:.4} Hz apart): its leakage biases the FRF on every \
                 line, most near {sync_hz:.1} Hz. Put it on a line with --speed-rpm {} (line {lo}) \
                 or {} (line {hi}), or choose a period whose line spacing divides the 1x frequency",
                lo * df * 60.0,
                hi * df * 60.0
            );
            None
        }
    }
}

/// Runs `ambid simulate --axes 4`.
pub fn simulate4(a: &SimulateArgs) -> Result<()> {
    refuse_siso_options(a)?;
    if !(2..=super::simulate::MAX_TRUTH_POINTS).contains(&a.truth_points) {
        return Err(Error::usage(format!(
            "--truth-points {} must be in 2..={}",
            a.truth_points,
            super::simulate::MAX_TRUTH_POINTS
        ))
        .into());
    }
    let cfg = machine_config(a)?;
    let machine = Machine::new(cfg.clone()).context("building the 4-axis machine")?;
    let (ts, fs) = (machine.ts(), machine.fs());
    let d = design(a, ts, machine.i_sat())?;
    let m = d.n_experiments()?;
    let period = d.base.period_samples()?;
    let n = period.saturating_mul(a.periods);
    if n > ambid::experiment::MAX_SIM_SAMPLES {
        return Err(Error::usage(format!(
            "each experiment would record {n} samples, more than the limit of {} a simulation \
             may record; use fewer --periods or a shorter period",
            ambid::experiment::MAX_SIM_SAMPLES
        ))
        .into());
    }
    // every output is checked before any work
    let meta_path = a.out.join("meta.json");
    let truth_path = a.out.join("truth.csv");
    let data_paths: Vec<PathBuf> = (0..m)
        .map(|e| experiment_dir(&a.out, e).join("data.csv"))
        .collect();
    for p in data_paths.iter().chain([&truth_path, &meta_path]) {
        OutputSet::check(p, a.force)?;
    }
    let exc = d.generate(ts).context("generating the excitation design")?;
    let report = exc.report().context("the design report")?;
    let mode = match a.mode {
        super::common::ModeArg::Linear => Mode::Linear,
        super::common::ModeArg::Nonlinear => Mode::Nonlinear,
    };
    let sync_line = sync_line_note(&cfg, machine.sync_hz(), period, fs);
    let settle = settle_samples(&machine, period)?;
    let mut set = OutputSet::new(a.force);
    let mut runs = Vec::with_capacity(m);
    for (e, r) in exc.samples().iter().enumerate() {
        let seed = experiment_seed(a.seed, e);
        let opts = MachineSimOptions {
            mode,
            seed,
            noise: !a.no_noise,
            w: None,
            settle_samples: settle,
        };
        let rec = machine
            .simulate([&r[0], &r[1], &r[2], &r[3]], &opts)
            .with_context(|| format!("simulating experiment {} of {m}", e + 1))?;
        let mut cols: Vec<(String, &[f64])> = vec![("t".into(), &rec.t[..])];
        for (letter, sig) in [("r", &rec.r), ("u", &rec.u), ("y", &rec.y), ("i", &rec.i)] {
            for (k, ax) in AXES.iter().enumerate() {
                cols.push((format!("{letter}_{ax}"), &sig[k][..]));
            }
        }
        let named: Vec<(&str, &[f64])> = cols.iter().map(|(n, c)| (n.as_str(), *c)).collect();
        set.write_with(&data_paths[e], |w| time_csv_to(w, &named))?;
        runs.push(serde_json::json!({
            "dir": format!("exp{}", e + 1),
            "noise_seed": seed,
            "samples": rec.t.len(),
            "saturated_fraction": rec.meta.saturated_fraction,
            "max_abs_displacement_m": rec.meta.max_abs_displacement_m,
            "noise_rms_m": rec.meta.noise_rms_m,
        }));
        let sat = rec
            .meta
            .saturated_fraction
            .iter()
            .fold(0.0f64, |a, b| a.max(*b));
        if sat > 0.0 {
            eprintln!(
                "warning: experiment {}: a controller output saturated in {:.3} % of the samples; \
                 the data are not from a linear operating regime — reduce --level",
                e + 1,
                100.0 * sat
            );
        }
    }
    // truth on every DFT line of the period up to fs/2 (a superset of the lines any estimate
    // from these records has), or only on the design's lines for very long periods, and a log
    // grid
    let mut f: Vec<f64> = if period / 2 <= MAX_TRUTH_LINES {
        (1..=period / 2)
            .map(|k| k as f64 * fs / period as f64)
            .collect()
    } else {
        report
            .axes
            .iter()
            .flat_map(|x| x.lines_hz.iter().copied())
            .collect()
    };
    let n_lines = f.len();
    f.extend(ambid::experiment::log_grid(
        1.0,
        0.5 * fs * 0.999,
        a.truth_points,
    ));
    let f = union_grid(f);
    let p = machine.plant_frf(&f)?;
    let t = machine.t_ry_frf(&f)?;
    let s = machine.sensitivity_frf(&f)?;
    let fs_col = vec![fs; f.len()];
    let truth = matrix_frf_csv(
        &f,
        &AXES,
        &[("P", &p), ("T_ry", &t), ("S", &s)],
        &[("fs_hz", &fs_col)],
    )?;
    set.write(&truth_path, &truth)?;
    let mut conds: Vec<f64> = report.condition.iter().map(|c| c.cond).collect();
    let cond_summary = serde_json::json!({
        "lines": conds.len(),
        "min": conds.iter().copied().fold(f64::INFINITY, f64::min),
        "median": median(&mut conds),
        "max": report.max_condition,
    });
    let lines: Vec<serde_json::Value> = AXES
        .iter()
        .zip(&report.axes)
        .map(|(ax, l)| {
            serde_json::json!({
                "axis": ax,
                "lines": l.bins.len(),
                "f_min_hz": l.lines_hz.first(),
                "f_max_hz": l.lines_hz.last(),
                "rms": l.rms,
                "peak": l.peak,
                "crest_factor": l.crest_factor,
            })
        })
        .collect();
    let meta = serde_json::json!({
        "axes": AXES,
        "design": {
            "kind": report.kind,
            "inputs": report.n_inputs,
            "experiments": report.experiments,
            "base": d.base,
            "level_pct_of_i_sat": 100.0 * level_frac(a.level, a.amplitude)?,
            "period_samples": report.period_samples,
            "periods": report.periods,
            "settle_samples": settle,
            "samples_per_experiment": report.samples_per_experiment,
            "total_duration_s": report.total_duration_s,
            "resolution_hz": report.resolution_hz,
            "lines_per_axis": lines,
            "condition": cond_summary,
        },
        "experiments": runs,
        "period_samples": period,
        "periods": a.periods,
        "fs_hz": fs,
        "speed_rpm": cfg.speed_rpm,
        "sync_hz": machine.sync_hz(),
        "sync_line": sync_line,
        "unbalance": cfg.unbalance,
        "asymmetry": cfg.asymmetry,
        "mode": mode,
        "noise": !a.no_noise,
        "seed": a.seed,
        "truth": { "points": f.len(), "period_lines": n_lines, "log_points": a.truth_points },
        "machine": cfg,
    });
    set.write(&meta_path, serde_json::to_string_pretty(&meta)?.as_bytes())?;
    set.commit()?;
    println!(
        "simulated the whole rotor at {} rpm (1x {:.2} Hz): {} design, {m} experiment(s) of {n} \
         samples ({:.3} s each at {fs} Hz), {} mode{}",
        cfg.speed_rpm,
        machine.sync_hz(),
        report.kind,
        n as f64 * ts,
        format!("{mode:?}").to_lowercase(),
        if cfg.unbalance.is_some() {
            ", with unbalance"
        } else {
            ""
        }
    );
    println!(
        "period {period} samples, {} lines per axis, input condition number max {:.3}",
        report.axes.first().map_or(0, |l| l.bins.len()),
        report.max_condition
    );
    for p in data_paths.iter().chain([&truth_path, &meta_path]) {
        println!("written: {}", p.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_parse_two_finite_numbers() {
        assert_eq!(parse_pair("1e-3,2e-3"), Ok((1e-3, 2e-3)));
        assert_eq!(parse_pair(" -0.02 , 0.01"), Ok((-0.02, 0.01)));
        assert!(parse_pair("1e-3").is_err());
        assert!(parse_pair("1,2,3").is_err());
        assert!(parse_pair("a,1").is_err());
        assert!(parse_pair("inf,1").is_err());
    }

    #[test]
    fn experiment_seeds_differ_across_experiments_and_neighbouring_seeds() {
        let mut seen = std::collections::HashSet::new();
        for seed in 0..64u64 {
            for e in 0..8 {
                assert!(
                    seen.insert(experiment_seed(seed, e)),
                    "seed {seed} experiment {e}"
                );
            }
        }
        assert_eq!(experiment_seed(7, 2), experiment_seed(7, 2));
    }

    #[test]
    fn the_truth_grid_is_sorted_without_duplicates() {
        let g = union_grid(vec![3.0, 1.0, 2.0, 1.0 + 1e-12, 2.5, 3.0]);
        assert_eq!(g, vec![1.0, 2.0, 2.5, 3.0]);
    }
}
