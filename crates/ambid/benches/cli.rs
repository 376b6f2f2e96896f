//! Whole-process timings of the `ambid` commands with their defaults, as a user runs them.
//!
//! `cargo bench -p ambid --bench cli` builds the release binary, simulates the seed experiment
//! (PRBS n = 10, 5 samples per bit, 20 periods = 102 300 samples at 20 kHz, 10 % of i_sat) and an
//! independent validation record (seed 2, 12 %) on the nominal rig and on random rigs of the
//! twin's test family, then times every command as a whole process (start-up, file reading,
//! computation, writing): the median of `AMBID_BENCH_REPS` runs (default 5). It prints a Markdown
//! table for docs/benchmarks.md. A command that fails is reported as failed with its message.
//!
//! Every rig also times one axis' `uncertainty` of the order-8 plant model on its FRF with the
//! loop's controller (the bound, the weight, and the three robust checks).
//!
//! On the nominal rig it also times the studies that simulate their own experiments (`study
//! amplitude`, `study operating-point`, `bla` on the twin) and the whole machine's gray box
//! (`simulate --axes 4`, the 4×4 `frf`, `physical` on it, the `[machine]` workflow's 4×4 model
//! and `uncertainty` of it on that FRF), and one axis' gray box alone and with
//! two more operating points (`physical --bias-current … --operating …`).
//!
//! Options by environment: `AMBID_BENCH_RIGS=nominal,3,7` (default `nominal,3`),
//! `AMBID_BENCH_REPS=5`, `AMBID_BENCH_FILTER=fit` (only commands whose label contains it).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const EXE: &str = env!("CARGO_BIN_EXE_ambid");

fn run(args: &[&str]) -> Result<f64, String> {
    let t = Instant::now();
    let out = Command::new(EXE)
        .args(args)
        .output()
        .map_err(|e| format!("cannot start {EXE}: {e}"))?;
    let dt = t.elapsed().as_secs_f64();
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(err.lines().take(3).collect::<Vec<_>>().join(" / "));
    }
    Ok(dt)
}

/// The placeholder for the `[machine]` workflow's model JSON in a command's arguments.
const MACHINE_MODEL: &str = "@machine-model";

/// The model JSON (not an uncertain model's) in a workflow's `models` directory.
fn machine_model(dir: &Path) -> Option<String> {
    std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| {
            p.extension().is_some_and(|x| x == "json")
                && !p
                    .file_name()
                    .is_some_and(|n| n.to_string_lossy().contains("uncertain"))
        })
        .map(|p| s(&p))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

fn main() {
    let reps: usize = std::env::var("AMBID_BENCH_REPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5)
        .max(1);
    let rigs = std::env::var("AMBID_BENCH_RIGS").unwrap_or_else(|_| "nominal,3".into());
    let filter = std::env::var("AMBID_BENCH_FILTER").unwrap_or_default();
    let root: PathBuf =
        std::env::temp_dir().join(format!("ambid-bench-cli-{}", std::process::id()));
    println!("| rig | command | median [s] | runs |");
    println!("|---|---|---|---|");
    for rig in rigs.split(',').map(str::trim).filter(|r| !r.is_empty()) {
        let dir = root.join(rig);
        let (ident, valid) = (dir.join("ident"), dir.join("valid"));
        let rig_args: Vec<String> = if rig == "nominal" {
            vec![]
        } else {
            vec!["--rig-seed".into(), rig.into()]
        };
        let rig_args: Vec<&str> = rig_args.iter().map(String::as_str).collect();
        let ident_s = s(&ident);
        let valid_s = s(&valid);
        let mut sim: Vec<&str> = vec!["simulate", "--mode", "linear", "--out", &ident_s];
        sim.extend(&rig_args);
        let mut sim_v: Vec<&str> = vec![
            "simulate",
            "--mode",
            "linear",
            "--seed",
            "2",
            "--amplitude",
            "0.12",
            "--out",
            &valid_s,
        ];
        sim_v.extend(&rig_args);
        if let Err(e) = run(&sim).and_then(|_| run(&sim_v)) {
            println!("| {rig} | simulate | failed: {e} | |");
            continue;
        }
        let data = s(&ident.join("data.csv"));
        let vdata = s(&valid.join("data.csv"));
        let ctrl = s(&ident.join("controller.toml"));
        let o = |f: &str| s(&dir.join(f));
        let (frf, frf_w, ss8, plant) = (
            o("frf.csv"),
            o("frf_welch.csv"),
            o("ss8.json"),
            o("plant.json"),
        );
        let mut cases: Vec<(&str, Vec<String>)> = vec![
            ("simulate (seed experiment, nonlinear default)", {
                let mut v: Vec<String> = ["simulate", "--out"]
                    .iter()
                    .map(|x| x.to_string())
                    .collect();
                v.push(o("sim_nl"));
                v.extend(rig_args.iter().map(|x| x.to_string()));
                v
            }),
            (
                "frf --period-samples 5115 --skip-periods 1 --controller",
                vec![
                    "frf".into(),
                    data.clone(),
                    "--period-samples".into(),
                    "5115".into(),
                    "--skip-periods".into(),
                    "1".into(),
                    "--controller".into(),
                    ctrl.clone(),
                    "--out".into(),
                    frf.clone(),
                ],
            ),
            (
                "frf (defaults: the period found in r)",
                vec!["frf".into(), data.clone(), "--out".into(), frf_w.clone()],
            ),
            (
                "frf --method welch",
                vec![
                    "frf".into(),
                    data.clone(),
                    "--method".into(),
                    "welch".into(),
                    "--out".into(),
                    frf_w.clone(),
                ],
            ),
            (
                "fit --structure ss --order 8 --input r --output y",
                vec![
                    "fit",
                    &data,
                    "--structure",
                    "ss",
                    "--order",
                    "8",
                    "--input",
                    "r",
                    "--output",
                    "y",
                    "--out",
                    &ss8,
                ]
                .into_iter()
                .map(String::from)
                .collect(),
            ),
            (
                "fit --structure arx --na 8 --nb 8",
                vec![
                    "fit",
                    &data,
                    "--structure",
                    "arx",
                    "--na",
                    "8",
                    "--nb",
                    "8",
                    "--out",
                    &o("arx.json"),
                ]
                .into_iter()
                .map(String::from)
                .collect(),
            ),
            (
                "fit --structure oe --nb 8 --nf 8 --input r --output y",
                vec![
                    "fit",
                    &data,
                    "--structure",
                    "oe",
                    "--nb",
                    "8",
                    "--nf",
                    "8",
                    "--input",
                    "r",
                    "--output",
                    "y",
                    "--out",
                    &o("oe.json"),
                ]
                .into_iter()
                .map(String::from)
                .collect(),
            ),
            (
                "fit --structure armax --na 4 --nb 4 --nc 4",
                vec![
                    "fit",
                    &data,
                    "--structure",
                    "armax",
                    "--na",
                    "4",
                    "--nb",
                    "4",
                    "--nc",
                    "4",
                    "--out",
                    &o("armax.json"),
                ]
                .into_iter()
                .map(String::from)
                .collect(),
            ),
            (
                "fit --structure bj --nb 4 --nc 2 --nd 2 --nf 4 --input r --output y",
                vec![
                    "fit",
                    &data,
                    "--structure",
                    "bj",
                    "--nb",
                    "4",
                    "--nc",
                    "2",
                    "--nd",
                    "2",
                    "--nf",
                    "4",
                    "--input",
                    "r",
                    "--output",
                    "y",
                    "--out",
                    &o("bj.json"),
                ]
                .into_iter()
                .map(String::from)
                .collect(),
            ),
            (
                "order (ARX scan, defaults)",
                vec!["order".into(), data.clone(), "--out".into(), o("order.csv")],
            ),
            (
                "fit frf.csv --quantity plant --structure ss --order 8",
                vec![
                    "fit",
                    &frf,
                    "--quantity",
                    "plant",
                    "--structure",
                    "ss",
                    "--order",
                    "8",
                    "--fs",
                    "20000",
                    "--out",
                    &plant,
                ]
                .into_iter()
                .map(String::from)
                .collect(),
            ),
            (
                "compare-models frf.csv (defaults)",
                vec![
                    "compare-models".into(),
                    frf.clone(),
                    "--fs".into(),
                    "20000".into(),
                    "--out".into(),
                    o("comparison.csv"),
                ],
            ),
            (
                "validate plant.json --data valid --controller",
                vec![
                    "validate".into(),
                    plant.clone(),
                    "--data".into(),
                    vdata.clone(),
                    "--controller".into(),
                    ctrl.clone(),
                    "--out".into(),
                    o("validation"),
                ],
            ),
            (
                "uncertainty frf.csv --model plant.json --controller (one axis: bound, weight, three robust checks)",
                vec![
                    "uncertainty".into(),
                    frf.clone(),
                    "--model".into(),
                    plant.clone(),
                    "--controller".into(),
                    ctrl.clone(),
                    "--out".into(),
                    o("unc1"),
                ],
            ),
        ];
        if rig == "nominal" {
            // the studies simulate their own experiments on the nominal twin (issue 19: their
            // levels, operating points and realisations run in parallel)
            let owned = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<String>>();
            cases.extend([
                (
                    "study amplitude (8 levels + noise record, nonlinear twin)",
                    owned(&["study", "amplitude", "--out", &o("amplitude.csv")]),
                ),
                (
                    "study operating-point (5 cases, nonlinear twin)",
                    owned(&[
                        "study",
                        "operating-point",
                        "--out",
                        &o("op.csv"),
                        "--frf-out",
                        &o("op_frf.csv"),
                    ]),
                ),
                (
                    "bla (defaults: 5 levels 2–32 %, M = 8, P = 4, twin)",
                    owned(&["bla", "--out", &o("bla.csv")]),
                ),
                // the whole machine's gray box: the 4-axis experiment (defaults: orthogonal
                // PRBS design, 4 experiments, nonlinear twin), its 4×4 FRF, and `physical` on it
                (
                    "simulate --axes 4 (defaults: 4 experiments, nonlinear)",
                    owned(&["simulate", "--axes", "4", "--out", &o("sim4")]),
                ),
                ("frf (4×4 matrix FRF of the 4 experiments)", {
                    let mut v = vec!["frf".to_string()];
                    v.extend((1..=4).map(|e| s(&dir.join(format!("sim4/exp{e}/data.csv")))));
                    v.extend(["--out".to_string(), o("frf4.csv")]);
                    v
                }),
                (
                    "physical (4×4 FRF: k_i, k_x of every axis, the bending mode)",
                    owned(&["physical", &o("frf4.csv"), "--out", &o("physical4.json")]),
                ),
                // the whole machine at two more operating points, and each axis' magnet law
                (
                    "simulate --axes 4 --bias 1.6 (operating point)",
                    owned(&["simulate", "--axes", "4", "--bias", "1.6", "--seed", "3", "--out", &o("sim4_b")]),
                ),
                (
                    "simulate --axes 4 --gap 0.00041 (operating point)",
                    owned(&["simulate", "--axes", "4", "--gap", "0.00041", "--seed", "4", "--out", &o("sim4_g")]),
                ),
                ("frf (4×4, bias 1.6 A)", {
                    let mut v = vec!["frf".to_string()];
                    v.extend((1..=4).map(|e| s(&dir.join(format!("sim4_b/exp{e}/data.csv")))));
                    v.extend(["--out".to_string(), o("frf4_b.csv")]);
                    v
                }),
                ("frf (4×4, gap 0.41 mm)", {
                    let mut v = vec!["frf".to_string()];
                    v.extend((1..=4).map(|e| s(&dir.join(format!("sim4_g/exp{e}/data.csv")))));
                    v.extend(["--out".to_string(), o("frf4_g.csv")]);
                    v
                }),
                (
                    "physical frf4.csv --bias-current 2 --operating ×2 (each axis' magnet law)",
                    owned(&[
                        "physical", &o("frf4.csv"), "--bias-current", "2",
                        "--operating", &format!("1.6:0={}", o("frf4_b.csv")),
                        "--operating", &format!("2:+10={}", o("frf4_g.csv")),
                        "--out", &o("physical4_op.json"),
                    ]),
                ),
                // the 4×4 model of the `[machine]` workflow on the nominal twin at the speed of
                // `simulate --axes 4`, and its uncertainty around the 4×4 FRF above
                (
                    "run wf_machine.toml ([machine] models = \"fit\", one speed)",
                    {
                        let wf = dir.join("wf_machine.toml");
                        let speed = ambid_twin::MachineConfig::default().speed_rpm;
                        let _ = std::fs::write(
                            &wf,
                            format!("[machine]\nspeeds_rpm = [{speed}]\nmodels = \"fit\"\n"),
                        );
                        owned(&["run", &s(&wf), "-q", "--out", &o("wf_machine")])
                    },
                ),
                (
                    "uncertainty frf4.csv --model (4×4: element-wise bound, weights, margins)",
                    owned(&["uncertainty", &o("frf4.csv"), "--model", MACHINE_MODEL, "--out", &o("unc4")]),
                ),
                // one axis' gray box, alone and with two more operating points (bias −20 %,
                // gap +10 µm; linear records, period-synchronous FRFs) for the magnet law
                (
                    "simulate --mode linear --bias 1.6 (operating point)",
                    owned(&["simulate", "--mode", "linear", "--bias", "1.6", "--seed", "3", "--out", &o("op_b")]),
                ),
                (
                    "simulate --mode linear --gap 0.00041 (operating point)",
                    owned(&["simulate", "--mode", "linear", "--gap", "0.00041", "--seed", "4", "--out", &o("op_g")]),
                ),
                (
                    "frf op_b --period-samples 5115 --controller",
                    owned(&["frf", &s(&dir.join("op_b/data.csv")), "--period-samples", "5115", "--controller", &ctrl, "--out", &o("frf_b.csv")]),
                ),
                (
                    "frf op_g --period-samples 5115 --controller",
                    owned(&["frf", &s(&dir.join("op_g/data.csv")), "--period-samples", "5115", "--controller", &ctrl, "--out", &o("frf_g.csv")]),
                ),
                (
                    "fit frf.csv --quantity plant --structure ss --order 8 --controller (gray-box starts)",
                    owned(&["fit", &frf, "--quantity", "plant", "--structure", "ss", "--order", "8", "--controller", &ctrl, "--out", &o("plant_c.json")]),
                ),
                (
                    "physical frf.csv --model --controller (one axis)",
                    owned(&["physical", &frf, "--model", &o("plant_c.json"), "--controller", &ctrl, "--out", &o("physical1.json")]),
                ),
                (
                    "physical … --bias-current 2 --operating ×2 (magnet law, 3 operating points)",
                    owned(&[
                        "physical", &frf, "--model", &o("plant_c.json"), "--controller", &ctrl,
                        "--bias-current", "2",
                        "--operating", &format!("1.6:0={}", o("frf_b.csv")),
                        "--operating", &format!("2:+10={}", o("frf_g.csv")),
                        "--out", &o("physical_op.json"),
                    ]),
                ),
            ]);
        }
        for (label, args) in cases {
            // the machine workflow's model file is named by the chosen order: found when needed
            let args: Vec<String> = args
                .into_iter()
                .map(|a| {
                    if a == MACHINE_MODEL {
                        machine_model(&dir.join("wf_machine/models")).unwrap_or(a)
                    } else {
                        a
                    }
                })
                .collect();
            // every repetition replaces the previous one's outputs
            let args: Vec<&str> = args
                .iter()
                .map(String::as_str)
                .chain(std::iter::once("--force"))
                .collect();
            if !filter.is_empty() && !label.contains(filter.as_str()) {
                // not timed, but run once: later commands read its outputs (frf.csv, plant.json)
                if let Err(e) = run(&args) {
                    println!("| {rig} | `{label}` (untimed, for later commands) | failed: {e} | |");
                }
                continue;
            }
            let mut times = Vec::with_capacity(reps);
            let mut failure = None;
            for _ in 0..reps {
                match run(&args) {
                    Ok(t) => times.push(t),
                    Err(e) => {
                        failure = Some(e);
                        break;
                    }
                }
            }
            match failure {
                Some(e) => println!("| {rig} | `{label}` | failed: {e} | |"),
                None => println!("| {rig} | `{label}` | {:.3} | {reps} |", median(times)),
            }
        }
    }
    if filter.is_empty() || filter == "run" {
        // the whole workflow on the twin (issue 19's bar: ≤ 1 s wall on the 2-core machine), with
        // the stages in parallel on every core, and on one thread for comparison
        let rep = s(&root.join("report"));
        for (threads, what) in [(None, "all cores"), (Some("1"), "RAYON_NUM_THREADS=1")] {
            let times: Result<Vec<f64>, String> = (0..reps)
                .map(|_| {
                    let t = Instant::now();
                    let mut c = Command::new(EXE);
                    c.args(["run", "--out", rep.as_str(), "--force", "-q"]);
                    if let Some(n) = threads {
                        c.env("RAYON_NUM_THREADS", n);
                    }
                    let out = c.output().map_err(|e| format!("cannot start {EXE}: {e}"))?;
                    if !out.status.success() {
                        let err = String::from_utf8_lossy(&out.stderr);
                        return Err(err.lines().take(3).collect::<Vec<_>>().join(" / "));
                    }
                    Ok(t.elapsed().as_secs_f64())
                })
                .collect();
            match times {
                Ok(t) => println!(
                    "| nominal | `run` (the whole workflow on the twin, defaults; {what}) | {:.3} | {reps} |",
                    median(t)
                ),
                Err(e) => println!("| nominal | `run` ({what}) | failed: {e} | |"),
            }
        }
    }
    let _ = std::fs::remove_dir_all(&root);
}
