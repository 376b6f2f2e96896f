//! `ambid simulate`: run the embedded twin in closed loop and write its record and truth.

use super::common::{deprecated_band, level_frac, prbs_order_arg, twin_config, ModeArg, TwinArgs};
use ambid::experiment::{self, ExcitationKind, ExcitationPlan, Experiment};
use ambid::io::{frf_csv_bytes, time_csv_to, FrfColumn, OutputSet};
use ambid_twin::{Integrator, Mode};
use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use std::path::PathBuf;

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum IntegratorArg {
    Rk4,
    ExpRk4,
}

#[derive(Args)]
pub struct SimulateArgs {
    #[command(flatten)]
    pub(crate) twin: TwinArgs,
    /// Excitation signal injected at the controller output of bearing A.
    #[arg(long, value_enum, default_value_t = ExcitationKind::Prbs)]
    pub(crate) signal: ExcitationKind,
    /// Deprecated spelling of --signal (`--excitation` names the column r in `frf`,
    /// `validate` and `bla`).
    #[arg(long, value_enum, hide = true, conflicts_with = "signal")]
    pub(crate) excitation: Option<ExcitationKind>,
    /// Excitation level in % of the saturation current i_sat (`10` or `10%`): peak for PRBS,
    /// chirp and multisine, RMS for noise.
    #[arg(long, default_value = "10", allow_negative_numbers = true, value_parser = super::args::parse_pct)]
    pub(crate) level: f64,
    /// Deprecated: the level as a fraction of i_sat (0.1 = 10 %); write `--level 10`.
    #[arg(
        long,
        hide = true,
        conflicts_with = "level",
        allow_negative_numbers = true
    )]
    pub(crate) amplitude: Option<f64>,
    /// PRBS register order n (period 2^n − 1 bits).
    #[arg(long, default_value_t = 10)]
    pub(crate) prbs_order: u32,
    /// Deprecated spelling of --prbs-order (`--order` is a model order in `fit`).
    #[arg(long, hide = true, conflicts_with = "prbs_order")]
    pub(crate) order: Option<u32>,
    /// PRBS samples per bit.
    #[arg(long, default_value_t = 5)]
    pub(crate) samples_per_bit: usize,
    /// Periods (PRBS, chirp, multisine).
    #[arg(long, default_value_t = 20)]
    pub(crate) periods: usize,
    /// Band of the chirp, noise or multisine, Hz, as `f_min:f_max`.
    #[arg(long, default_value = "1:2000", allow_negative_numbers = true, value_parser = super::args::parse_band)]
    pub(crate) band: (f64, f64),
    /// Deprecated: lowest frequency, Hz; write `--band LO:HI`.
    #[arg(long, hide = true, allow_negative_numbers = true)]
    pub(crate) f_min: Option<f64>,
    /// Deprecated: highest frequency, Hz; write `--band LO:HI`.
    #[arg(long, hide = true, allow_negative_numbers = true)]
    pub(crate) f_max: Option<f64>,
    /// Period length for chirp and multisine, s (default: one period of the seed PRBS, 5115
    /// samples). Noise and `none` records last periods × period.
    #[arg(long, default_value_t = 0.25575, allow_negative_numbers = true)]
    pub(crate) period: f64,
    /// Simulation mode.
    #[arg(long, value_enum, default_value_t = ModeArg::Nonlinear)]
    pub(crate) mode: ModeArg,
    /// Integrator of the nonlinear mode (overrides the configuration): `rk4` (10 substeps per
    /// control period, the reference) or `exp-rk4` (exact linear flow + RK4 on the nonlinear
    /// residual, ≈ 4× faster, less accurate while the amplifier slew limit switches).
    #[arg(long, value_enum)]
    pub(crate) integrator: Option<IntegratorArg>,
    /// Seed for sensor noise and random excitations.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Switch the sensor noise off.
    #[arg(long)]
    pub(crate) no_noise: bool,
    /// Also record bearing B (columns u_b, i_b, y_b).
    #[arg(long)]
    pub(crate) record_b: bool,
    /// Number of log-spaced truth frequencies from 1 Hz to fs/2 (at most 1000000).
    #[arg(long, default_value_t = 400)]
    pub(crate) truth_points: usize,
    /// A linear chirp position reference `amplitude_m,duration_s,f0_hz,f1_hz` at bearing A (the
    /// seed's closed-loop reconstruction uses 5e-6,10,1,1000); needs `--signal none`, and
    /// the record lasts the chirp's duration.
    #[arg(long)]
    pub(crate) reference_chirp: Option<String>,
    /// Inject the excitation read from this file (column `r`; a `t` column, if present, must
    /// match the twin's 20 kHz) instead of designing one, e.g. one realisation written by
    /// `ambid excite multisine --phases random --realisations M`.
    #[arg(long, conflicts_with_all = ["signal", "excitation", "reference_chirp"])]
    pub(crate) excitation_file: Option<PathBuf>,
    /// Output directory (data.csv, truth.csv, meta.json, controller.toml).
    #[arg(long, default_value = "out")]
    pub(crate) out: PathBuf,
    /// Replace those files if they exist (other files in the directory are left alone).
    #[arg(long)]
    pub(crate) force: bool,
    /// 1: the single-plane twin (default); 4: the whole rotor (`ambid_twin::Machine`, both
    /// planes, gyroscopic coupling at speed), excited by `--design`; writes `exp1/data.csv`,
    /// `exp2/data.csv`, … (one per experiment), `truth.csv` (the 4×4 P, T_ry, S) and `meta.json`
    /// (docs/formats.md, "Whole rotor"). `--config` may then be a machine configuration.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=4))]
    pub(crate) axes: u8,
    /// Rotor speed in rpm (with `--axes 4`; overrides the configuration's `speed_rpm`).
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) speed_rpm: Option<f64>,
    /// Multi-axis excitation design (with `--axes 4`; default sequential): `sequential` and
    /// `orthogonal` (Hadamard signs) use the PRBS of `--prbs-order`, `--samples-per-bit` at
    /// `--level` (peak) on every axis, 4 experiments; `zipper` one experiment, a multisine in
    /// `--band` with period `--period`, its lines dealt out to the axes, peak = `--level`.
    #[arg(long, value_enum)]
    pub(crate) design: Option<super::simulate4::DesignArg>,
    /// Unbalance `MASS_KG,ECC_M` (with `--axes 4`), e.g. `1e-3,1e-3` (1 g at 1 mm): a force at
    /// 1× the rotation frequency at the centre of mass.
    #[arg(long, value_parser = super::simulate4::parse_pair, allow_negative_numbers = true)]
    pub(crate) unbalance: Option<(f64, f64)>,
    /// x/y asymmetry of the magnets `KI_REL,KX_REL` (with `--axes 4`): the y magnets' k_i and
    /// k_x are (1 + KI_REL)·k_i and (1 + KX_REL)·k_x, each |·| < 0.5, e.g. `0.02,0.02`.
    #[arg(long, value_parser = super::simulate4::parse_pair, allow_negative_numbers = true)]
    pub(crate) asymmetry: Option<(f64, f64)>,
}

/// `excitation: peak … % / RMS … % of i_sat (… A)` of the injected excitation, or `None`
/// without one.
fn excitation_level(r: &[f64], i_sat: f64) -> Option<String> {
    if r.is_empty() || !(i_sat.is_finite() && i_sat > 0.0) {
        return None;
    }
    let peak = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let rms = (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt();
    (peak > 0.0).then(|| {
        format!(
            "excitation: peak {:.3} % / RMS {:.3} % of i_sat = {i_sat} A",
            100.0 * peak / i_sat,
            100.0 * rms / i_sat
        )
    })
}

/// Largest `simulate --truth-points`: checked before anything is simulated or written (each
/// point costs a few hundred bytes in memory and a row of truth.csv; 10⁹ points aborted
/// allocating 8 GB after data.csv was written).
pub(crate) const MAX_TRUTH_POINTS: usize = 1_000_000;

pub fn simulate(a: SimulateArgs) -> Result<()> {
    match a.axes {
        4 => return super::simulate4::simulate4(&a),
        1 => {}
        n => {
            return Err(ambid::error::Error::usage(format!(
                "--axes {n}: give 1 (the single-plane twin) or 4 (the whole rotor)"
            ))
            .into())
        }
    }
    for (given, opt) in [
        (a.speed_rpm.is_some(), "--speed-rpm"),
        (a.design.is_some(), "--design"),
        (a.unbalance.is_some(), "--unbalance"),
        (a.asymmetry.is_some(), "--asymmetry"),
    ] {
        if given {
            return Err(ambid::error::Error::usage(format!(
                "{opt} needs --axes 4 (the whole rotor; the single-plane twin does not rotate)"
            ))
            .into());
        }
    }
    let data_path = a.out.join("data.csv");
    let truth_path = a.out.join("truth.csv");
    let meta_path = a.out.join("meta.json");
    let ctrl_path = a.out.join("controller.toml");
    // refuse to overwrite before any work
    for p in [&data_path, &truth_path, &meta_path, &ctrl_path] {
        OutputSet::check(p, a.force)?;
    }
    let band = deprecated_band(a.band, a.f_min, a.f_max, ("--f-min", "--f-max"))?;
    let mut cfg = twin_config(&a.twin)?;
    if let Some(integ) = a.integrator {
        cfg.simulation.integrator = match integ {
            IntegratorArg::Rk4 => Integrator::Rk4,
            IntegratorArg::ExpRk4 => Integrator::ExpRk4,
        };
    }
    let exp = Experiment {
        twin: cfg,
        excitation: ExcitationPlan {
            kind: match a.excitation {
                Some(k) => {
                    let name = k
                        .to_possible_value()
                        .map_or_else(String::new, |v| v.get_name().to_string());
                    super::args::deprecated(
                        &format!("simulate --excitation {name}"),
                        &format!("--signal {name}"),
                    );
                    k
                }
                None => a.signal,
            },
            amplitude_frac: level_frac(a.level, a.amplitude)?,
            prbs_order: prbs_order_arg(a.prbs_order, a.order),
            samples_per_bit: a.samples_per_bit,
            periods: a.periods,
            f_min_hz: band.0,
            f_max_hz: band.1,
            period_s: a.period,
            seed: a.seed,
        },
        mode: match a.mode {
            ModeArg::Linear => Mode::Linear,
            ModeArg::Nonlinear => Mode::Nonlinear,
        },
        seed: a.seed,
        noise: !a.no_noise,
        record_b: a.record_b,
    };
    if a.truth_points < 2 {
        bail!("--truth-points must be at least 2");
    }
    if a.truth_points > MAX_TRUTH_POINTS {
        bail!(
            "--truth-points {} is more than the limit {MAX_TRUTH_POINTS}: truth.csv would hold \
             {} rows of exact FRFs (a log grid of 10^4 points already resolves every mode of \
             the twin); give at most {MAX_TRUTH_POINTS}",
            a.truth_points,
            a.truth_points
        );
    }
    let mut out = match &a.excitation_file {
        Some(p) => {
            let t = ambid::io::table::read_table(p, &Default::default())?;
            let r = t.column(&"r".into())?.to_vec();
            let ts = if t.names.iter().any(|n| n == "t") {
                Some(t.sample_time(Some(&"t".into()), None)?)
            } else {
                None
            };
            experiment::run_with_excitation(&exp, r, ts)
                .with_context(|| format!("--excitation-file {}", p.display()))?
        }
        None => experiment::run(&exp)?,
    };
    if let Some(spec) = &a.reference_chirp {
        let c: Vec<f64> = spec
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .ok()
            .filter(|v: &Vec<f64>| v.len() == 4)
            .with_context(|| {
                format!("--reference-chirp `{spec}`: give amplitude_m,duration_s,f0_hz,f1_hz, e.g. 5e-6,10,1,1000")
            })?;
        if exp.excitation.kind != ExcitationKind::None {
            bail!("--reference-chirp drives the loop by its position reference: use it with --signal none");
        }
        let w = ambid_core::signal::ChirpSpec {
            amplitude: c[0],
            duration_s: c[1],
            f0_hz: c[2],
            f1_hz: c[3],
            sweep: ambid_core::signal::Sweep::Linear,
            periods: 1,
        }
        .generate(out.twin.ts())
        .context("--reference-chirp amplitude_m,duration_s,f0_hz,f1_hz")?
        .values;
        let opts = ambid_twin::SimOptions {
            mode: exp.mode,
            seed: exp.seed,
            noise: exp.noise,
            record_b: exp.record_b,
            w: Some(w.clone()),
            ..ambid_twin::SimOptions::default()
        };
        out.record = out
            .twin
            .simulate(&vec![0.0; w.len()], &opts)
            .context("simulating the closed loop with the reference")?;
    }
    let rec = &out.record;
    let mut cols: Vec<(&str, &[f64])> = vec![
        ("t", &rec.t),
        ("w", &rec.w),
        ("r", &rec.r),
        ("u", &rec.u),
        ("i", &rec.i),
        ("y", &rec.y),
    ];
    if let Some(b) = &rec.b {
        cols.extend([("u_b", &b.u[..]), ("i_b", &b.i[..]), ("y_b", &b.y[..])]);
    }
    let mut set = OutputSet::new(a.force);
    set.write_with(&data_path, |w| time_csv_to(w, &cols))?;
    let grid = experiment::log_grid(1.0, 0.5 * out.twin.fs() * 0.999, a.truth_points);
    let truth = experiment::truth(&out.twin, &grid)?;
    let truth_bytes = frf_csv_bytes(
        &truth.f_hz,
        &[
            FrfColumn {
                name: "plant",
                values: &truth.plant,
                std: None,
            },
            FrfColumn {
                name: "t_ry",
                values: &truth.t_ry,
                std: None,
            },
            FrfColumn {
                name: "t_ru",
                values: &truth.t_ru,
                std: None,
            },
            FrfColumn {
                name: "controller",
                values: &truth.controller,
                std: None,
            },
        ],
        &[],
    )?;
    set.write(&truth_path, &truth_bytes)?;
    let meta = serde_json::json!({
        "excitation": match &a.excitation_file {
            Some(p) => serde_json::json!({ "file": p.display().to_string() }),
            None => serde_json::json!(exp.excitation),
        },
        "excitation_samples": out.excitation.values.len(),
        "period_samples": out.excitation.period_samples,
        "periods": out.excitation.periods,
        "simulation": rec.meta,
        "twin": exp.twin,
    });
    set.write(&meta_path, serde_json::to_string_pretty(&meta)?.as_bytes())?;
    set.write(
        &ctrl_path,
        ambid::io::controller::controller_toml_from_twin(&exp.twin).as_bytes(),
    )?;
    set.commit()?;
    println!(
        "simulated {} samples ({:.3} s at {} Hz), {} mode",
        rec.t.len(),
        rec.t.len() as f64 * rec.ts,
        out.twin.fs(),
        format!("{:?}", exp.mode).to_lowercase()
    );
    if let Some(l) = excitation_level(&out.excitation.values, exp.twin.magnet.i_sat_a) {
        println!("{l}");
    }
    let sat = rec.meta.saturated_fraction;
    if sat > 0.0 {
        eprintln!(
            "warning: the amplifier or controller output saturated in {:.3} % of the samples; \
             the data are not from a linear operating regime — reduce --level",
            100.0 * sat
        );
    }
    for p in [&data_path, &truth_path, &meta_path, &ctrl_path] {
        println!("written: {}", p.display());
    }
    Ok(())
}
