//! Diagnostic sweep of the MIMO frequency-domain fitter on the 4-axis twin: per rig (0 = the
//! nominal twin, k > 0 = `random_rig(k)` at `(7919 k) mod 30 000` rpm, the nominal one at
//! 15 000 rpm), linear, default noise, seed 1: the fitted band, and per order the wall time, the
//! iterations, the weighted cost and the median plant error against the exact plant.
//!
//! The fits are `ss_frd_mimo_in_loop` with the workflow's band rule (`machine_fit::fit_band`)
//! and default options; `ITERS=n` sets the iteration limit per stage (default 100);
//! `FEEDTHROUGH=1` fits a feed-through term; `MODE=nonlinear` simulates the nonlinear twin (the workflow's default) instead of the linear
//! one (the plant error is then against the linearised plant, which the BLA differs from).
//!
//! Run: `cargo run --release -p ambid --example mimo_fit_sweep -- 0,1,2 16,20,24`.
use ambid::config::MachineSection;
use ambid::workflow::machine::acquire_twin;
use ambid::workflow::machine_fit::fit_band;
use ambid_core::estimate::freqfit_mimo::{ss_frd_mimo_in_loop, MimoFreqOptions};
use ambid_core::lti::{Frd, StateSpace};
use faer::{c64, Mat};
use std::path::Path;
use std::time::Instant;

fn norm2(m: &Mat<c64>) -> f64 {
    m.singular_values()
        .map(|s| s.iter().fold(0.0f64, |a, v| a.max(*v)))
        .unwrap_or(f64::NAN)
}

fn median_plant_error(model: &StateSpace, truth: &StateSpace, f: &[f64]) -> f64 {
    let t = Frd::from_model(truth, f).expect("truth");
    let r = model.freq_response(f).expect("model");
    let mut e: Vec<f64> = (0..f.len())
        .map(|k| {
            let tk = t.at(k).expect("line");
            let d = Mat::from_fn(4, 4, |i, j| r[k][(i, j)] - tk[(i, j)]);
            norm2(&d) / norm2(&tk)
        })
        .collect();
    e.sort_by(f64::total_cmp);
    e[e.len() / 2]
}

/// A comma-separated argument (or its default) as numbers; unparsable items are skipped.
fn list<T: std::str::FromStr>(arg: Option<&String>, default: &str) -> Vec<T> {
    arg.map_or(default, String::as_str)
        .split(',')
        .filter_map(|x| x.parse().ok())
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs: Vec<u64> = list(args.get(1), "0");
    let orders: Vec<usize> = list(args.get(2), "16,20,24");
    let mode = std::env::var("MODE").unwrap_or_else(|_| "linear".into());
    let dir = std::env::temp_dir().join(format!("ambid-mimo-sweep-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp dir");
    for rig in rigs {
        let m = if rig == 0 {
            MachineSection {
                speeds_rpm: Some(vec![15_000.0]),
                mode: mode.clone(),
                ..Default::default()
            }
        } else {
            let path = dir.join(format!("rig{rig}.toml"));
            std::fs::write(
                &path,
                ambid_twin::random_rig(rig)
                    .expect("rig")
                    .to_toml_string()
                    .expect("toml"),
            )
            .expect("write rig");
            MachineSection {
                speeds_rpm: Some(vec![((rig * 7919) % 30_000) as f64]),
                mode: mode.clone(),
                config: Some(path),
                ..Default::default()
            }
        };
        let data = acquire_twin(&m, Path::new("."), 1).expect("twin");
        let truth = &data.truth.as_ref().expect("truth")[0];
        let plant = &data.speeds[0].frf.plant;
        let Some(band) = fit_band(plant, m.quality_band_hz).expect("band") else {
            println!("rig {rig}: no band");
            continue;
        };
        let f: Vec<f64> = plant
            .f_hz()
            .iter()
            .copied()
            .filter(|f| (10.0..=1000.0).contains(f))
            .collect();
        let lines = plant
            .f_hz()
            .iter()
            .filter(|&&x| x >= band.0 && x <= band.1)
            .count();
        let mut tp: Vec<c64> = truth.plant.poles().expect("poles");
        tp.sort_by(|a, b| a.norm().total_cmp(&b.norm()));
        println!(
            "rig {rig}: band {:.1}-{:.1} Hz ({lines} lines), raw plant error {:.3} %",
            band.0,
            band.1,
            100.0 * {
                let mut e: Vec<f64> = (0..plant.len())
                    .filter(|&k| (10.0..=1000.0).contains(&plant.f_hz()[k]))
                    .map(|k| {
                        let pk = plant.at(k).expect("line");
                        let tk = Frd::from_model(&truth.plant, &[plant.f_hz()[k]])
                            .expect("t")
                            .at(0)
                            .expect("t");
                        let d = Mat::from_fn(4, 4, |i, j| pk[(i, j)] - tk[(i, j)]);
                        norm2(&d) / norm2(&tk)
                    })
                    .collect();
                e.sort_by(f64::total_cmp);
                e[e.len() / 2]
            }
        );
        let ts = data.ts;
        let show = |p: &[c64]| -> String {
            p.iter()
                .map(|z| {
                    let s = z.ln() / ts;
                    format!(
                        "{:.0}{:+.0}j",
                        s.re / (2.0 * std::f64::consts::PI),
                        s.im / (2.0 * std::f64::consts::PI)
                    )
                })
                .collect::<Vec<_>>()
                .join(" ")
        };
        println!("  truth poles [Hz]: {}", show(&tp));
        for &order in &orders {
            let opts = MimoFreqOptions {
                band_hz: Some(band),
                max_iterations: std::env::var("ITERS")
                    .ok()
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(100),
                feedthrough: std::env::var("FEEDTHROUGH").is_ok(),
                ..Default::default()
            };
            let t = Instant::now();
            let r = ss_frd_mimo_in_loop(plant, order, &opts, &truth.controller);
            let dt = t.elapsed().as_secs_f64();
            match r {
                Ok(fit) => {
                    let mut p = fit.model.poles().expect("poles");
                    p.sort_by(|a, b| a.norm().total_cmp(&b.norm()));
                    println!(
                        "  order {order}: {dt:.2} s, {} iterations (converged {}), cost {:.0}, plant error {:.3} %, unstable {}",
                        fit.iterations,
                        fit.converged,
                        fit.cost,
                        100.0 * median_plant_error(&fit.model, &truth.plant, &f),
                        fit.unstable_poles().unwrap_or(99)
                    );
                    println!("    poles [Hz]: {}", show(&p));
                }
                Err(e) => println!("  order {order}: {dt:.2} s, failed: {e}"),
            }
        }
    }
}
