//! The polynomial prediction-error defaults (`ambid fit --structure oe|armax|bj`) on a sweep of
//! random rigs.
//!
//! For each rig seed: the seed experiment on the linear twin of `ambid_twin::random_rig(seed)`
//! (PRBS n = 10, 5 samples per bit, 20 periods, 10 % of i_sat, noise seed `1000 + seed`) is the
//! estimation record, a second run (12 % of i_sat, noise seed `2000 + seed`) the validation
//! record. OE(8,8,1), ARMAX(4,4,4,1) and BJ(4,2,2,4,1) of $T_{ry}$ (r → y, means removed as the CLI
//! does) are fitted by [`ambid_core::estimate::pem::pem`] with the default options, and their
//! validation simulation fits are compared with the fit of the exact $T_{ry}$ (the twin's closed
//! loop, simulated on the validation r from rest).
//!
//! Run: `cargo run --release -p ambid --example pem_rig_sweep -- [first_seed] [count] [samples]`
//! (`samples` truncates both records; default: the full 102 300). `PEM_LOSS_TOL=τ` replaces the
//! statistical loss tolerance by τ.
//!
//! Prints one line per rig and structure (iterations, stop reason, fit, truth's fit, gap, run
//! time) and a summary per structure.

use ambid::experiment::{run, Experiment, ExperimentOutput};
use ambid_core::estimate::arx::fit_percent;
use ambid_core::estimate::pem::{pem, Orders, PemOptions};
use ambid_core::lti::Structure;
use ambid_twin::Mode;
use anyhow::Result;
use faer::Mat;
use std::time::Instant;

fn experiment(rig: u64, noise_seed: u64, amplitude: f64) -> Result<ExperimentOutput> {
    let mut e = Experiment::seed_paper(Mode::Linear, 1e-7, noise_seed);
    e.twin = ambid_twin::random_rig(rig)?;
    e.noise = true;
    e.excitation.amplitude_frac = amplitude;
    run(&e)
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

fn main() -> Result<()> {
    let pos: Vec<u64> = std::env::args()
        .skip(1)
        .map(|a| a.parse::<u64>())
        .collect::<std::result::Result<_, _>>()?;
    let first = pos.first().copied().unwrap_or(1);
    let count = pos.get(1).copied().unwrap_or(20);
    let samples = pos.get(2).map(|&n| n as usize);
    let cases = [
        ("oe 8/8", Structure::Oe, Orders::oe(8, 8, 1)),
        ("armax 4/4/4", Structure::Armax, Orders::armax(4, 4, 4, 1)),
        ("bj 4/2/2/4", Structure::Bj, Orders::bj(4, 2, 2, 4, 1)),
    ];
    // PEM_LOSS_TOL=τ: a fixed loss tolerance instead of the statistical default
    let opts = match std::env::var("PEM_LOSS_TOL") {
        Ok(t) => PemOptions::default().with_loss_tol(t.parse()?)?,
        Err(_) => PemOptions::default(),
    };
    let mut gaps = vec![Vec::new(); cases.len()];
    let mut unconverged = vec![0; cases.len()];
    let mut times = vec![Vec::new(); cases.len()];
    for rig in first..first + count {
        let est = experiment(rig, 1000 + rig, 0.10)?;
        let val = experiment(rig, 2000 + rig, 0.12)?;
        let n = samples
            .unwrap_or(est.record.r.len())
            .min(est.record.r.len());
        let (mu, my) = (mean(&est.record.r[..n]), mean(&est.record.y[..n]));
        let u: Vec<f64> = est.record.r[..n].iter().map(|v| v - mu).collect();
        let y: Vec<f64> = est.record.y[..n].iter().map(|v| v - my).collect();
        let uv: Vec<f64> = val.record.r[..n].iter().map(|v| v - mu).collect();
        let yv: Vec<f64> = val.record.y[..n].iter().map(|v| v - my).collect();
        let cl = val.twin.closed_loop();
        let rw = Mat::from_fn(n, 2, |k, c| if c == 0 { val.record.r[k] } else { 0.0 });
        let yt = cl.simulate(rw.as_ref(), None)?;
        let yt: Vec<f64> = (0..yt.nrows()).map(|k| yt[(k, 0)]).collect();
        let f_truth = fit_percent(&val.record.y[..n], &yt)?;
        for (c, (name, s, o)) in cases.iter().enumerate() {
            let t0 = Instant::now();
            let r = pem(&y, &u, *s, o, est.twin.ts(), &opts);
            let secs = t0.elapsed().as_secs_f64();
            times[c].push(secs);
            match r {
                Ok((fit, rep)) => {
                    let ysim = fit.model.simulate(&uv, None, None)?;
                    let f_model = fit_percent(&yv, &ysim)?;
                    let gap = f_truth - f_model;
                    gaps[c].push(gap);
                    if !rep.reason().converged() {
                        unconverged[c] += 1;
                    }
                    println!(
                        "rig {rig:3} {name:12}: {:3} it {:13} | fit {f_model:7.3} % truth {f_truth:7.3} % gap {gap:7.3} | {secs:.2} s",
                        rep.iterations(),
                        format!("{:?}", rep.reason()),
                    );
                }
                Err(e) => {
                    gaps[c].push(f64::INFINITY);
                    println!("rig {rig:3} {name:12}: error {e} | {secs:.2} s");
                }
            }
        }
    }
    for (c, (name, _, _)) in cases.iter().enumerate() {
        let g = &mut gaps[c];
        g.sort_by(|a, b| a.total_cmp(b));
        let t = &mut times[c];
        t.sort_by(|a, b| a.total_cmp(b));
        println!(
            "{name}: {} rigs, gap median {:.3} max {:.3}, {} within 0.5; at the iteration limit on {}; time median {:.2} s max {:.2} s",
            g.len(),
            g[g.len() / 2],
            g[g.len() - 1],
            g.iter().filter(|v| **v <= 0.5).count(),
            unconverged[c],
            t[t.len() / 2],
            t[t.len() - 1]
        );
    }
    Ok(())
}
