//! Coverage and accuracy of the whole-rotor gray box (issue 23: $k_i$, $k_x$ per bearing and
//! direction) on machine rigs of the 4-axis twin: per run, every parameter's relative error and
//! whether its interval covers the truth; at the end the fraction covered and the worst error
//! per parameter.
//!
//! Run: `cargo run --release -p ambid --example physical_machine_rigs -- RIGS [SPEED_RPM] [linear|nonlinear] [LEVELS]`
//! (RIGS `a-b` or a list; noise seed = rig + 2000; rig 0 = the nominal symmetric machine;
//! default speed 0, linear twin, one run at the default 10 % of i_sat; LEVELS e.g. `7,10,14`
//! (% of i_sat): a run per level, noise seed + 1000 per level, and the parameters
//! extrapolated to zero amplitude are judged).
use ambid::physical::{MachineExtrapolatedRun, MachinePhysicalRun, MACHINE_PARAMETER_NAMES};
use ambid_twin::Mode;
use std::time::Instant;

fn rigs(s: &str) -> Vec<u64> {
    if let Some((a, b)) = s.split_once('-') {
        (a.parse().expect("rig")..=b.parse().expect("rig")).collect()
    } else {
        s.split(',').map(|v| v.parse().expect("rig")).collect()
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let list = rigs(args.get(1).map_or("1-5", String::as_str));
    let speed: f64 = args.get(2).map_or(0.0, |s| s.parse().expect("speed"));
    let mode = match args.get(3).map(String::as_str) {
        Some("nonlinear") => Mode::Nonlinear,
        _ => Mode::Linear,
    };
    let levels: Vec<f64> = args.get(4).map_or(Vec::new(), |s| {
        s.split(',')
            .map(|v| v.parse::<f64>().expect("level in %") / 100.0)
            .collect()
    });
    let mut covered = [0usize; 12];
    let mut worst = [0.0f64; 12];
    let mut runs = 0usize;
    for rig in list {
        let t = Instant::now();
        // (estimate, intervals, truth, a label)
        let got = if levels.is_empty() {
            MachinePhysicalRun::on_twin(rig, rig + 2000, speed, mode).map(|run| {
                (
                    run.fit.params.to_array(),
                    run.fit.intervals,
                    run.truth.to_array(),
                    format!(
                        "lines {} chi2/dof {:.2}",
                        run.lines,
                        run.fit.chi2 / run.fit.dof as f64
                    ),
                )
            })
        } else {
            MachineExtrapolatedRun::on_twin(rig, rig + 2000, speed, mode, &levels).map(|run| {
                (
                    run.zero.params.to_array(),
                    run.zero.intervals,
                    run.truth.to_array(),
                    format!("levels {}", run.at_levels.len()),
                )
            })
        };
        let (est, intervals, tru, label) = match got {
            Ok(r) => r,
            Err(e) => {
                println!("rig {rig}: {e}");
                continue;
            }
        };
        runs += 1;
        let mut line = format!("rig {rig:>3} {label} |");
        for k in 0..12 {
            let (lo, hi) = intervals[k];
            let ok = lo <= tru[k] && tru[k] <= hi;
            covered[k] += usize::from(ok);
            let err = (est[k] / tru[k] - 1.0).abs();
            worst[k] = worst[k].max(err);
            line += &format!(
                " {:+.3}%{}",
                100.0 * (est[k] / tru[k] - 1.0),
                if ok { "" } else { "*" }
            );
        }
        println!("{line} | {:.1} s", t.elapsed().as_secs_f64());
    }
    println!("runs {runs}");
    for k in 0..12 {
        println!(
            "{:>16}: covered {:.3}, worst error {:.3} %",
            MACHINE_PARAMETER_NAMES[k],
            covered[k] as f64 / runs.max(1) as f64,
            100.0 * worst[k]
        );
    }
}
