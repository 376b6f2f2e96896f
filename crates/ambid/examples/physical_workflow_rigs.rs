//! The workflow's `physical` step after its `amplitude` step (issue 23: the parameters
//! extrapolated to zero amplitude) on random rigs of the twin: per rig the workflow with
//! `steps = amplitude, physical` (and their prerequisites) on `random_rig(rig)` with noise seed
//! `rig`, the estimate of the identification record and the one at zero amplitude against the
//! twin's linearisation (k_i, k_x) and rotor (f_b), whether each 95 % interval covers it; at the
//! end the coverage per parameter and the levels used.
//!
//! `cargo run --release -p ambid --example physical_workflow_rigs -- RIGS [linear|nonlinear]`
//! (e.g. `61-80`).

mod common;

use ambid::physical::{as_array, twin_truth, PARAMETER_NAMES};
use ambid::workflow::Step;
use ambid_twin::Twin;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs = common::range(args.get(1).map_or("61-70", String::as_str));
    let mode = args.get(2).cloned().unwrap_or_else(|| "nonlinear".into());
    let dir = std::env::temp_dir().join(format!("ambid-physical-wf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (all, _) = Step::with_prerequisites(&[Step::Amplitude, Step::Physical]);
    let mut cov = [[0usize; 6]; 2];
    let mut worst = [[0.0f64; 6]; 2];
    let mut runs = 0;
    println!(
        "rig | levels | one record: rel. error % k_i k_x f_b (covered) | zero amplitude: the same"
    );
    for rig in rigs {
        let (cfg, out) = common::workflow_on_rig(rig, &mode, &all, &dir);
        let truth = as_array(&twin_truth(&Twin::new(cfg).unwrap()));
        let out = match out {
            Ok(o) => o,
            Err(e) => {
                println!("{rig}: {e}");
                continue;
            }
        };
        let ph = &out.summary["physical"];
        let z = &ph["zero_amplitude"];
        if z.is_null() {
            println!("{rig}: no zero-amplitude estimate ({})", ph);
            continue;
        }
        runs += 1;
        let mut line = format!("{rig} | {} |", z["levels_pct"]);
        for (s, sec) in [&ph["parameters"], &z["parameters"]].iter().enumerate() {
            for k in 0..6 {
                let e = sec[k]["estimate"].as_f64().unwrap();
                let (lo, hi) = (
                    sec[k]["interval"][0].as_f64().unwrap(),
                    sec[k]["interval"][1].as_f64().unwrap(),
                );
                let c = lo <= truth[k] && truth[k] <= hi;
                cov[s][k] += usize::from(c);
                let r = (e - truth[k]) / truth[k];
                worst[s][k] = worst[s][k].max(r.abs());
                if k < 3 {
                    line += &format!(" {:+.3}{}", 100.0 * r, if c { "" } else { "*" });
                }
            }
            line += " |";
        }
        println!("{line}");
    }
    println!("runs {runs}");
    for (s, what) in ["one record", "zero amplitude"].iter().enumerate() {
        for k in 0..6 {
            println!(
                "{what:>15} {:>16}: coverage {:.3}, worst |rel. error| {:.3} %",
                PARAMETER_NAMES[k],
                cov[s][k] as f64 / runs.max(1) as f64,
                100.0 * worst[s][k]
            );
        }
    }
}
