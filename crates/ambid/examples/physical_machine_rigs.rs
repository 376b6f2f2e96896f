//! Coverage and accuracy of the whole-rotor gray box (issue 23: $k_i$, $k_x$ per bearing and
//! direction) on machine rigs of the 4-axis twin: per run, every parameter's relative error and
//! whether its interval covers the truth; at the end the fraction covered and the worst error
//! per parameter.
//!
//! Run: `cargo run --release -p ambid --example physical_machine_rigs -- RIGS [SPEED_RPM] [linear|nonlinear] [LEVELS]`
//! (RIGS `a-b` or a list; noise seed = rig + 2000; rig 0 = the nominal symmetric machine;
//! default speed 0, linear twin, one run at the default 10 % of i_sat; LEVELS e.g. `7,10,14`
//! (% of i_sat): a run per level, noise seed + 1000 per level, and the parameters
//! extrapolated to zero amplitude are judged). SPEED_RPM `spread`: rig k at
//! (7 919 k) mod 30 000 rpm.
//!
//! `WORKFLOW=1`: the `[machine] physical = true` workflow's own path instead, at its defaults
//! (the experiment and the default amplitude study, `workflow::machine::acquire_twin_config`
//! with noise seed rig + 2000, then `workflow::machine_physical::machine_physical`): both its
//! estimates are judged, the identification level's (`id`) and the one at zero amplitude
//! (`zero`); LEVELS is then the study's levels (`[machine] amplitude_levels_pct`, `none` for
//! none).
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

/// One judged estimate: its name, the estimate, its intervals and the truth.
type Judged = (&'static str, [f64; 12], [(f64, f64); 12], [f64; 12]);

/// The workflow's path on machine rig `rig` (module docs).
fn workflow_run(
    rig: u64,
    speed: f64,
    mode: Mode,
    levels: Option<Vec<f64>>,
) -> ambid::error::Result<(Vec<Judged>, String)> {
    use ambid::config::MachineSection;
    let base = if rig == 0 {
        ambid_twin::MachineConfig::default()
    } else {
        ambid_twin::random_machine_rig(rig)?
    };
    let section = MachineSection {
        speeds_rpm: Some(vec![speed]),
        mode: match mode {
            Mode::Linear => "linear".into(),
            Mode::Nonlinear => "nonlinear".into(),
        },
        physical: true,
        amplitude_levels_pct: levels,
        ..Default::default()
    };
    let data = ambid::workflow::machine::acquire_twin_config(base, &section, rig + 2000)?;
    let rows = ambid::workflow::machine_physical::machine_physical(
        &section,
        std::path::Path::new("."),
        &data,
    )?;
    let row = rows
        .first()
        .ok_or_else(|| ambid::error::Error::other("no speed"))?;
    if let Some(e) = &row.error {
        return Err(ambid::error::Error::other(e.clone()));
    }
    let arrays = |p: &[ambid::workflow::machine_physical::PhysicalParameterRow]| {
        let est: [f64; 12] = std::array::from_fn(|k| p[k].estimate);
        let iv: [(f64, f64); 12] = std::array::from_fn(|k| (p[k].interval[0], p[k].interval[1]));
        let tru: [f64; 12] = std::array::from_fn(|k| p[k].twin.unwrap_or(f64::NAN));
        (est, iv, tru)
    };
    let (e, i, t) = arrays(&row.parameters);
    let mut out = vec![("id", e, i, t)];
    let mut label = format!(
        "{speed:>5.0} rpm sat {:.1e}",
        data.speeds[0].saturated_fraction.unwrap_or(0.0)
    );
    if let Some(z) = &row.zero_amplitude {
        let (e, i, t) = arrays(&z.parameters);
        out.push(("zero", e, i, t));
        label += &format!(" levels {:?}", z.levels_pct);
    }
    if let Some(n) = &row.zero_amplitude_note {
        label += &format!(" ({n})");
    }
    Ok((out, label))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let list = rigs(args.get(1).map_or("1-5", String::as_str));
    let spread = args.get(2).map(String::as_str) == Some("spread");
    let speed: f64 = match args.get(2).map(String::as_str) {
        None | Some("spread") => 0.0,
        Some(s) => s.parse().expect("speed"),
    };
    let workflow = std::env::var("WORKFLOW").is_ok_and(|v| v == "1");
    let mode = match args.get(3).map(String::as_str) {
        Some("nonlinear") => Mode::Nonlinear,
        _ => Mode::Linear,
    };
    let levels: Vec<f64> = args
        .get(4)
        .filter(|s| *s != "none")
        .map_or(Vec::new(), |s| {
            s.split(',')
                .map(|v| v.parse::<f64>().expect("level in %") / 100.0)
                .collect()
        });
    // per estimate name: runs, covered and worst error per parameter
    let mut tally: Vec<(&str, usize, [usize; 12], [f64; 12])> = Vec::new();
    for rig in list {
        let t = Instant::now();
        let speed = if spread {
            (7919 * rig % 30_000) as f64
        } else {
            speed
        };
        let got: ambid::error::Result<(Vec<Judged>, String)> = if workflow {
            let study = match args.get(4).map(String::as_str) {
                None => None,
                Some("none") => Some(Vec::new()),
                Some(_) => Some(levels.iter().map(|l| 100.0 * l).collect()),
            };
            workflow_run(rig, speed, mode, study)
        } else if levels.is_empty() {
            MachinePhysicalRun::on_twin(rig, rig + 2000, speed, mode).map(|run| {
                (
                    vec![(
                        "id",
                        run.fit.params.to_array(),
                        run.fit.intervals,
                        run.truth.to_array(),
                    )],
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
                    vec![(
                        "zero",
                        run.zero.params.to_array(),
                        run.zero.intervals,
                        run.truth.to_array(),
                    )],
                    format!("levels {}", run.at_levels.len()),
                )
            })
        };
        let (judged, label) = match got {
            Ok(r) => r,
            Err(e) => {
                println!("rig {rig}: {e}");
                continue;
            }
        };
        let mut line = format!("rig {rig:>3} {label}");
        for (name, est, intervals, tru) in judged {
            let at = match tally.iter().position(|t| t.0 == name) {
                Some(i) => i,
                None => {
                    tally.push((name, 0, [0; 12], [0.0; 12]));
                    tally.len() - 1
                }
            };
            let t = &mut tally[at];
            t.1 += 1;
            line += &format!(" | {name}");
            for k in 0..12 {
                let (lo, hi) = intervals[k];
                let ok = lo <= tru[k] && tru[k] <= hi;
                t.2[k] += usize::from(ok);
                let err = (est[k] / tru[k] - 1.0).abs();
                t.3[k] = t.3[k].max(err);
                line += &format!(
                    " {:+.3}%{}",
                    100.0 * (est[k] / tru[k] - 1.0),
                    if ok { "" } else { "*" }
                );
            }
        }
        println!("{line} | {:.1} s", t.elapsed().as_secs_f64());
    }
    for (name, runs, covered, worst) in &tally {
        println!("{name}: runs {runs}");
        for k in 0..12 {
            println!(
                "{:>16}: covered {:.3}, worst error {:.3} %",
                MACHINE_PARAMETER_NAMES[k],
                covered[k] as f64 / (*runs).max(1) as f64,
                100.0 * worst[k]
            );
        }
    }
}
