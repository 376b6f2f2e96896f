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
use ambid_core::estimate::pem::lm::LmOptions;
use ambid_core::estimate::pem::{pem, Orders, PemOptions};
use ambid_core::lti::Structure;
use ambid_core::validate::fit::fit_percent;
use ambid_core::validate::predict::{poly_one_step, InitialState};
use ambid_twin::Mode;
use anyhow::Result;
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
    let pos: Vec<u64> = std::env::args()
        .skip(1)
        .map(|a| a.parse::<u64>())
        .collect::<std::result::Result<_, _>>()?;
    let first = pos.first().copied().unwrap_or(1);
    let count = pos.get(1).copied().unwrap_or(20);
    let samples = pos.get(2).map(|&n| n as usize);
    // (name, structure, orders, input: r (else u), score by the 1-step prediction (else simulation))
    let cases = [
        ("oe 8/8", Structure::Oe, Orders::oe(8, 8, 1), true, false),
        (
            "armax 4/4/4",
            Structure::Armax,
            Orders::armax(4, 4, 4, 1),
            false,
            true,
        ),
        (
            "bj 4/2/2/4",
            Structure::Bj,
            Orders::bj(4, 2, 2, 4, 1),
            true,
            false,
        ),
    ];
    // PEM_LOSS_TOL=τ: another loss tolerance
    let mut opts = match std::env::var("PEM_LOSS_TOL") {
        Ok(t) => PemOptions::default().with_loss_tol(t.parse()?)?,
        Err(_) => PemOptions::default(),
    };
    // PEM_KAPPA=κ: another statistical tolerance (in standard errors)
    if let Ok(k) = std::env::var("PEM_KAPPA") {
        opts = opts.with_significance_tol(k.parse()?)?;
    }
    // PEM_REFERENCE=1: also run the iteration to its 100-step limit with every tolerance 0
    let reference = std::env::var("PEM_REFERENCE").is_ok();
    let full = PemOptions::default().with_lm(LmOptions::exhaustive(100)?);
    let only: Option<String> = std::env::var("PEM_ONLY").ok();
    let mut gaps = vec![Vec::new(); cases.len()];
    let mut losses = vec![Vec::new(); cases.len()];
    let mut unconverged = vec![0; cases.len()];
    let mut times = vec![Vec::new(); cases.len()];
    for rig in first..first + count {
        let est = experiment(rig, 1000 + rig, 0.10)?;
        let val = experiment(rig, 2000 + rig, 0.12)?;
        let n = samples
            .unwrap_or(est.record.r.len())
            .min(est.record.r.len());
        let cl = val.twin.closed_loop();
        let rw = Mat::from_fn(n, 2, |k, c| if c == 0 { val.record.r[k] } else { 0.0 });
        let yt = cl.simulate(rw.as_ref(), None)?;
        let yt: Vec<f64> = (0..yt.nrows()).map(|k| yt[(k, 0)]).collect();
        let f_truth = fit_percent(&val.record.y[..n], &yt)?;
        for (c, (name, s, o, from_r, one_step)) in cases.iter().enumerate() {
            if only.as_deref().is_some_and(|w| !name.starts_with(w)) {
                continue;
            }
            let (ue, uv) = if *from_r {
                (&est.record.r, &val.record.r)
            } else {
                (&est.record.u, &val.record.u)
            };
            let (mu, my) = (mean(&ue[..n]), mean(&est.record.y[..n]));
            let u: Vec<f64> = ue[..n].iter().map(|v| v - mu).collect();
            let y: Vec<f64> = est.record.y[..n].iter().map(|v| v - my).collect();
            let uv: Vec<f64> = uv[..n].iter().map(|v| v - mu).collect();
            let yv: Vec<f64> = val.record.y[..n].iter().map(|v| v - my).collect();
            let score = |m: &ambid_core::lti::PolyModel| -> Result<f64> {
                let yh = if *one_step {
                    poly_one_step(m, &yv, &uv, InitialState::Zero)?
                } else {
                    m.simulate(&uv, None, None)?
                };
                Ok(fit_percent(&yv, &yh)?)
            };
            let t0 = Instant::now();
            let r = pem(&y, &u, *s, o, est.twin.ts(), &opts);
            let secs = t0.elapsed().as_secs_f64();
            times[c].push(secs);
            let refit = if reference {
                match pem(&y, &u, *s, o, est.twin.ts(), &full) {
                    Ok((f, _)) => Some((score(&f.model)?, f.loss)),
                    Err(_) => None,
                }
            } else {
                None
            };
            match r {
                Ok((fit, rep)) => {
                    let f_model = score(&fit.model)?;
                    // against the truth (simulation) or the 100-step result (1-step)
                    let gap = match (refit, *one_step) {
                        (Some((f_ref, _)), _) => f_ref - f_model,
                        (None, false) => f_truth - f_model,
                        (None, true) => f64::NAN,
                    };
                    gaps[c].push(gap);
                    if let Some((_, l_ref)) = refit {
                        losses[c].push(fit.loss / l_ref - 1.0);
                    }
                    if !rep.reason().converged() {
                        unconverged[c] += 1;
                    }
                    if std::env::var("PEM_ROOTS").is_ok() {
                        let roots = |p: &[f64]| -> String {
                            ambid_core::linalg::roots(p)
                                .map(|r| {
                                    let mut m: Vec<String> = r
                                        .iter()
                                        .map(|z| format!("{:.5}@{:.4}", z.norm(), z.im.atan2(z.re)))
                                        .collect();
                                    m.sort();
                                    m.join(" ")
                                })
                                .unwrap_or_default()
                        };
                        let st = &rep.start;
                        println!(
                            "  start A [{}] C [{}] D [{}] F [{}]\n  final A [{}] C [{}] D [{}] F [{}]\n  rejected inadmissible {} evals {}",
                            roots(st.a()), roots(st.c()), roots(st.d()), roots(st.f()),
                            roots(fit.model.a()), roots(fit.model.c()), roots(fit.model.d()), roots(fit.model.f()),
                            rep.lm.rejected_inadmissible, rep.lm.evaluations
                        );
                    }
                    println!(
                        "rig {rig:3} {name:12}: {:3} it {:20} | fit {f_model:8.4} % {} gap {gap:7.4} | {secs:.2} s",
                        rep.iterations(),
                        format!("{:?}", rep.reason()),
                        match refit {
                            Some((f, l)) => format!("100-step {f:8.4} % (loss ratio-1 {:.1e})", fit.loss / l - 1.0),
                            None => format!("truth {f_truth:7.3} %"),
                        },
                    );
                }
                Err(e) => {
                    gaps[c].push(f64::INFINITY);
                    println!("rig {rig:3} {name:12}: error {e} | {secs:.2} s");
                }
            }
        }
    }
    for (c, (name, ..)) in cases.iter().enumerate() {
        let g = &mut gaps[c];
        if g.is_empty() {
            continue;
        }
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
