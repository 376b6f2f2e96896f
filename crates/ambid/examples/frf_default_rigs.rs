//! What `ambid frf`'s default estimator does to the physical parameters on rigs of the twin:
//! per rig the seed experiment's record (a periodic PRBS) analysed as `ambid frf` analyses a
//! file without options, once with the period found in `r` (`PeriodScan`, the default since
//! 2026-12-01) and once with Welch (the default before, now `--method welch`), each FRF then
//! through the gray box (`estimate_with_starts_from_data`); the relative errors of $k_i$ and
//! $k_x$ against the twin's linearisation and whether their 95 % intervals cover it.
//!
//! `cargo run --release -p ambid --example frf_default_rigs -- RIGS [linear|nonlinear]`
//! (e.g. `1-50`); each rig runs with its own noise seed (2000 + rig). The FRFs use the whole
//! band the CLI derives from the excitation (`FrfSettings`' defaults), and the found period
//! must equal the design's on every rig.

use ambid::analysis::{analyze, FrfSettings, Record};
use ambid::experiment::{run, ExcitationPlan, Experiment};
use ambid::physical::{estimate_with_starts_from_data, twin_drawing, twin_truth, PhysicalOptions};
use ambid_core::signal::PeriodScan;
use ambid_twin::{random_rig, Mode, TwinConfig};

mod common;
use common::range;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs = range(args.get(1).map_or("1-5", String::as_str));
    let mode = match args.get(2).map(String::as_str) {
        Some("nonlinear") => Mode::Nonlinear,
        _ => Mode::Linear,
    };
    // per estimator: covered k_i, covered k_x, runs, Σ z², worst |error| of k_x
    let mut tally = [[0.0f64; 5]; 2];
    let mut errs: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    println!("rig | period found/design | k_i err % (z) k_x err % (z): period ; welch");
    for &rig in &rigs {
        let twin = if rig == 0 {
            TwinConfig::default()
        } else {
            random_rig(rig).expect("rig")
        };
        let exp = Experiment {
            twin,
            excitation: ExcitationPlan::default(),
            mode,
            seed: 2000 + rig,
            noise: true,
            record_b: false,
        };
        let out = match run(&exp) {
            Ok(o) => o,
            Err(e) => {
                println!("{rig}: {e}");
                continue;
            }
        };
        let rec = &out.record;
        let design = out.excitation.period_samples;
        let found = PeriodScan::of(&rec.r);
        let record = Record {
            r: &rec.r,
            u: &rec.u,
            y: &rec.y,
            i: None,
            fs: 1.0 / rec.ts,
        };
        let n = rec.r.len();
        let settings = [
            found.map(|p| FrfSettings::periodic(p, 1)),
            Some(FrfSettings::welch(FrfSettings::default_nperseg(n))),
        ];
        let truth = twin_truth(&out.twin);
        let drawing = twin_drawing(out.twin.config());
        let mut line = format!("{rig:3} | {found:?}/{design} |");
        for (m, s) in settings.iter().enumerate() {
            let Some(s) = s else {
                line += " (no period) ;";
                continue;
            };
            let res = analyze(&record, s, None)
                .map_err(|e| e.to_string())
                .and_then(|a| {
                    estimate_with_starts_from_data(
                        &a.frf.plant,
                        &drawing,
                        out.twin.controller(),
                        &PhysicalOptions::default(),
                    )
                    .map_err(|e| e.to_string())
                });
            match res {
                Ok(fit) => {
                    let ei = fit.params.k_i / truth.k_i - 1.0;
                    let ex = fit.params.k_x / truth.k_x - 1.0;
                    let zi = (fit.params.k_i - truth.k_i) / fit.std[0];
                    let zx = (fit.params.k_x - truth.k_x) / fit.std[1];
                    let t = &mut tally[m];
                    t[0] += (zi.abs() <= 1.96) as u8 as f64;
                    t[1] += (zx.abs() <= 1.96) as u8 as f64;
                    t[2] += 1.0;
                    t[3] += zx * zx;
                    t[4] = t[4].max(ex.abs());
                    errs[m].push(ex);
                    line += &format!(
                        " {:+.3} ({:+.2}) {:+.3} ({:+.2}) ;",
                        100.0 * ei,
                        zi,
                        100.0 * ex,
                        zx
                    );
                }
                Err(e) => line += &format!(" failed: {e} ;"),
            }
        }
        println!("{line}");
    }
    for (m, name) in ["period (default)", "welch (former default)"]
        .iter()
        .enumerate()
    {
        let t = tally[m];
        let mut e = errs[m].clone();
        e.sort_by(f64::total_cmp);
        let med = e.get(e.len() / 2).copied().unwrap_or(f64::NAN);
        println!(
            "{name}: runs {}, k_i covered {}, k_x covered {}, k_x rms z {:.2}, k_x median error {:+.3} %, worst {:.3} %",
            t[2],
            t[0],
            t[1],
            (t[3] / t[2].max(1.0)).sqrt(),
            100.0 * med,
            100.0 * t[4]
        );
    }
}
