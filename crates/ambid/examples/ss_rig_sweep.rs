//! The state-space defaults of `ambid fit --structure ss` on a sweep of random rigs.
//!
//! For each rig seed: the seed experiment on the linear twin of `ambid_twin::random_rig(seed)`
//! (PRBS n = 10, 5 samples per bit, 20 periods, 10 % of i_sat, noise seed `1000 + seed`) is the
//! estimation record, a second run (12 % of i_sat, noise seed `2000 + seed`) the validation
//! record. The order-8 model of $T_{ry}$ (r → y, means removed as the CLI does) is identified by
//! [`ambid::fitting::fit_state_space`] — the function `ambid fit` calls — and its validation
//! simulation fit is compared with the fit of the exact $T_{ry}$ (the twin's closed loop,
//! simulated on the validation r from rest).
//!
//! Run: `cargo run --release -p ambid --example ss_rig_sweep -- [first_seed] [count]
//! [--block-rows i] [--focus auto|prediction|simulation|none]`
//!
//! Prints one line per rig (chosen horizon, the horizon scan, PEM iterations and stop, the
//! model's and the truth's validation fits and their gap, the run time) and a summary.

use ambid::experiment::{run, Experiment, ExperimentOutput};
use ambid::fitting::{identify_state_space, SsFitOptions, SsFocus};
use ambid_core::validate::fit::fit_percent;
use ambid_twin::Mode;
use anyhow::{Context, Result};
use faer::Mat;
use std::time::Instant;

fn experiment(rig: u64, noise_seed: u64, amplitude: f64) -> Result<ExperimentOutput> {
    let mut e = Experiment::seed_paper(Mode::Linear, 1e-7, noise_seed);
    e.twin = ambid_twin::random_rig(rig)?;
    e.noise = true;
    e.excitation.amplitude_frac = amplitude;
    Ok(run(&e)?)
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut pos = Vec::new();
    let mut block_rows = None;
    let mut focus = SsFocus::Auto;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--block-rows" => block_rows = Some(it.next().context("value")?.parse()?),
            "--focus" => {
                focus = match it.next().context("value")?.as_str() {
                    "auto" => SsFocus::Auto,
                    "prediction" => SsFocus::Prediction,
                    "simulation" => SsFocus::Simulation,
                    "none" => SsFocus::None,
                    f => anyhow::bail!("unknown focus {f}"),
                }
            }
            p => pos.push(p.parse::<u64>()?),
        }
    }
    let first = pos.first().copied().unwrap_or(1);
    let count = pos.get(1).copied().unwrap_or(20);
    let mut gaps = Vec::new();
    let mut unconverged = 0;
    for rig in first..first + count {
        let est = experiment(rig, 1000 + rig, 0.10)?;
        let val = experiment(rig, 2000 + rig, 0.12)?;
        let (mu, my) = (mean(&est.record.r), mean(&est.record.y));
        let u: Vec<f64> = est.record.r.iter().map(|v| v - mu).collect();
        let y: Vec<f64> = est.record.y.iter().map(|v| v - my).collect();
        let uv: Vec<f64> = val.record.r.iter().map(|v| v - mu).collect();
        let yv: Vec<f64> = val.record.y.iter().map(|v| v - my).collect();
        let t0 = Instant::now();
        let o = SsFitOptions {
            order: Some(8),
            block_rows,
            focus,
            ..SsFitOptions::default()
        };
        let fit = identify_state_space(&u, &y, est.twin.ts(), &o)?;
        let secs = t0.elapsed().as_secs_f64();
        let ysim = fit.model.simulate_siso(&uv, None)?;
        let f_model = fit_percent(&yv, &ysim)?;
        // the truth: the closed loop (inputs r, w; outputs y, u) from rest, w = 0
        let cl = val.twin.closed_loop();
        let rw = Mat::from_fn(val.record.r.len(), 2, |k, c| {
            if c == 0 {
                val.record.r[k]
            } else {
                0.0
            }
        });
        let yt = cl.simulate(rw.as_ref(), None)?;
        let yt: Vec<f64> = (0..yt.nrows()).map(|k| yt[(k, 0)]).collect();
        let f_truth = fit_percent(&val.record.y, &yt)?;
        let (iters, stop) = fit.pem.as_ref().map_or((0, "-".to_string()), |p| {
            (p.iterations, format!("{:?}", p.stop))
        });
        if stop == "MaxIterations" {
            unconverged += 1;
        }
        let gap = f_truth - f_model;
        gaps.push(gap);
        println!(
            "rig {rig:3}: i = {:3} scan {:?} | pem {:?} {iters:3} it {stop:13} | fit {f_model:7.3} % truth {f_truth:7.3} % gap {gap:7.3} | {secs:.2} s",
            fit.block_rows,
            fit.block_rows_scan
                .iter()
                .map(|(i, l)| format!("{i}:{l:.4e}"))
                .collect::<Vec<_>>(),
            fit.pem.as_ref().map(|p| p.focus),
        );
    }
    gaps.sort_by(|a, b| a.total_cmp(b));
    println!(
        "{} rigs: gap (truth − model, points) median {:.3}, max {:.3}; {} within 0.5; PEM at its iteration limit on {}",
        gaps.len(),
        gaps[gaps.len() / 2],
        gaps[gaps.len() - 1],
        gaps.iter().filter(|g| **g <= 0.5).count(),
        unconverged
    );
    Ok(())
}
