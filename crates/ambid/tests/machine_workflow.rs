//! `ambid run` with a `[machine]` section: the whole-machine procedure on the 4-axis twin
//! (short records: 2 speeds, PRBS n = 8, 4 periods, linear, default noise) against the twin's
//! exact model; the model seam with a fitter that returns the exact plant (so that the
//! model-dependent sections, the exports and their frequency response are checked end to end);
//! the refusals of bad recorded files; numpy/scipy reading the MIMO exports.

use crate::common;
use ambid::config::WorkflowConfig;
use ambid::workflow::machine::{
    run_with, ComparisonRow, MachineModelInput, MachineModelOutput, MachineModels, MeasuredOnly,
    ModePoint, SpeedModel,
};
use ambid::workflow::{Progress, Verbosity};
use ambid_core::lti::Frd;
use std::path::Path;
use std::process::Command;

const SHORT: &str = "seed = 7\n[machine]\nspeeds_rpm = [0, 30000]\nmode = \"linear\"\nprbs_order = 8\nperiods = 4\n";

/// A JSON array of numbers.
fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn cfg(text: &str) -> WorkflowConfig {
    WorkflowConfig::from_toml_str(text, Path::new("wf.toml")).unwrap()
}

/// A fitter that returns the twin's exact plant as "the model" of every speed: the seam's
/// outputs are then known exactly.
struct ExactPlant;

impl MachineModels for ExactPlant {
    fn identify(
        &self,
        input: &MachineModelInput<'_>,
    ) -> Result<MachineModelOutput, ambid::error::Error> {
        let truth = input.truth.expect("twin");
        let mut out = MachineModelOutput::default();
        for t in truth {
            out.models.push(SpeedModel {
                speed_rpm: t.speed_rpm,
                name: format!("exact_{}rpm", t.speed_rpm),
                model: t.plant.clone(),
                meta: serde_json::json!({"structure": "ss"}),
            });
            out.comparison.push(ComparisonRow {
                speed_rpm: t.speed_rpm,
                model: "exact".into(),
                order: t.plant.order(),
                unstable_poles: t
                    .plant
                    .poles()
                    .unwrap()
                    .iter()
                    .filter(|p| p.norm() > 1.0)
                    .count(),
                median_norm_error_pct: 0.0,
                max_entry_error_pct: 0.0,
                bic: None,
                fit_y_pct: None,
                chosen: true,
            });
            out.campbell_points.push(ModePoint {
                speed_rpm: t.speed_rpm,
                freq_hz: 100.0,
                damping: 0.1,
                whirl: ambid_twin::Whirl::Forward,
            });
        }
        Ok(out)
    }
}

#[test]
fn whole_machine_on_the_twin_against_the_exact_model() {
    let c = cfg(SHORT);
    let (outcome, mo) = run_with(
        &c,
        Path::new("."),
        &mut Progress::new(Verbosity::Quiet),
        &MeasuredOnly,
    )
    .unwrap();
    let s = &mo.summary;
    assert_eq!(s.speeds_rpm, vec![0.0, 30000.0]);
    assert_eq!(s.design.as_deref(), Some("orthogonal"));
    // the measured FRF against the exact plant: a few % with the default noise and 4 periods
    for e in &s.frf_error_vs_truth_pct {
        assert!(*e < 10.0, "median FRF error {e} %");
    }
    // the exact plant has no x–y coupling at standstill and more with speed (gyroscopics)
    assert!(
        s.coupling_truth[0].xy_max < 1e-9,
        "{:?}",
        s.coupling_truth[0]
    );
    assert!(
        s.coupling_truth[1].xy_median > 1e-3,
        "{:?}",
        s.coupling_truth[1]
    );
    // the A–B coupling (rigid rotor) does not depend on speed; the measured one is close to it
    let (m0, t0) = (s.coupling[0].ab_median, s.coupling_truth[0].ab_median);
    assert!(((m0 - t0) / t0).abs() < 0.05, "{m0} vs {t0}");
    // the measured per-axis ISO peak is the exact one to 2 % (lines are 78 Hz apart at n = 8,
    // so the measured peak is taken on the nearest line)
    for k in 0..2 {
        for ax in ["xa", "xb", "ya", "yb"] {
            let pick = |from: &str| {
                s.iso
                    .iter()
                    .find(|r| r.speed_rpm == s.speeds_rpm[k] && r.axis == ax && r.from == from)
                    .unwrap()
                    .peak
            };
            let (m, t) = (pick("measured"), pick("truth"));
            assert!(
                m <= t * 1.02 && m > 0.9 * t,
                "{ax}: measured {m}, exact {t}"
            );
        }
    }
    // the report: 2 Bode matrices of 16 panels each, and the model sections say there is no model
    let html = outcome.report.to_html();
    let bode = outcome
        .report
        .sections
        .iter()
        .find(|x| x.id == "machine-bode")
        .unwrap();
    let panels: usize = bode
        .blocks
        .iter()
        .map(|b| match b {
            ambid::report::Block::Figure(f) => f.panels.len(),
            _ => 0,
        })
        .sum();
    assert_eq!(panels, 32);
    assert!(html.contains("No MIMO model was identified"));
    assert!(outcome.summary["machine"]["iso"].as_array().unwrap().len() == 16);
    assert!(outcome.models.is_empty());
    // same seed, same numbers
    let (_, again) = run_with(
        &c,
        Path::new("."),
        &mut Progress::new(Verbosity::Quiet),
        &MeasuredOnly,
    )
    .unwrap();
    assert_eq!(again.summary.coupling, s.coupling);
}

#[test]
fn the_seam_renders_models_and_exports_them() {
    let c = cfg(SHORT);
    let (outcome, mo) = run_with(
        &c,
        Path::new("."),
        &mut Progress::new(Verbosity::Quiet),
        &ExactPlant,
    )
    .unwrap();
    assert_eq!(outcome.models.len(), 2);
    assert_eq!(mo.summary.comparison[0].unstable_poles, 4);
    let html = outcome.report.to_html();
    assert!(html.contains("identified model") && !html.contains("No MIMO model was identified"));
    assert!(html.contains("identified models, forward whirl"));
    let dir = common::tmpdir("machine-export");
    let out = dir.join("report");
    let files = outcome.write(&out, true).unwrap();
    for ext in ["json", "m", "mat", "npz"] {
        assert!(
            files
                .iter()
                .any(|f| f.ends_with(format!("models/exact_30000rpm.{ext}"))),
            "{ext}: {files:?}"
        );
    }
    let m = std::fs::read_to_string(out.join("models/exact_30000rpm.m")).unwrap();
    assert!(m.contains("'InputName', {'u_xa', 'u_xb', 'u_ya', 'u_yb'}, 'OutputName', {'y_xa', 'y_xb', 'y_ya', 'y_yb'}"));
    assert!(m.contains("speed_rpm = 30000;"));
    let j: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("models/exact_30000rpm.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(j["outputs"][2], "y_ya");
    assert_eq!(j["speed_rpm"], 30000.0);
    // our frequency response of the exported model, for numpy to compare with
    let plant = &mo.data.truth.as_ref().unwrap()[1].plant;
    let f = [1.0, 37.5, 150.0, 999.0, 4000.0];
    let g = Frd::from_model(plant, &f).unwrap();
    let vals: Vec<[f64; 2]> = g.values().iter().map(|v| [v.re, v.im]).collect();
    std::fs::write(
        dir.join("ours.json"),
        serde_json::to_string(&serde_json::json!({"f": f, "g": vals})).unwrap(),
    )
    .unwrap();
    if !Command::new("python3")
        .args(["-c", "import scipy, numpy"])
        .output()
        .is_ok_and(|o| o.status.success())
    {
        common::skip(
            "machine_workflow: scipy/numpy read the MIMO .mat/.npz and evaluate their frequency response",
            "python3 with numpy and scipy not available (bash .ci/run installs them)",
        );
        return;
    }
    let script = r#"
import json, sys, numpy as np, scipy.io
d = sys.argv[1]
ours = json.load(open(d + "/ours.json"))
f = np.array(ours["f"]); g = np.array(ours["g"])
g = (g[:, 0] + 1j * g[:, 1]).reshape(len(f), 4, 4).transpose(0, 2, 1)  # stored column by column
for kind in ("npz", "mat"):
    p = d + "/report/models/exact_30000rpm." + kind
    if kind == "npz":
        z = np.load(p)
        get = lambda k: z[k]
        txt = lambda k: str(z[k])
    else:
        z = scipy.io.loadmat(p)
        get = lambda k: z[k]
        txt = lambda k: str(z[k][0])
    A, B, C, D = (np.atleast_2d(get(k)).astype(float) for k in "ABCD")
    Ts = float(np.squeeze(get("Ts"))); sp = float(np.squeeze(get("speed_rpm")))
    assert A.shape == (24, 24) and B.shape == (24, 4) and C.shape == (4, 24) and D.shape == (4, 4), A.shape
    assert sp == 30000.0, sp
    assert txt("input_name") == "u_xa,u_xb,u_ya,u_yb", txt("input_name")
    assert txt("output_name") == "y_xa,y_xb,y_ya,y_yb", txt("output_name")
    worst = 0.0
    for k, fk in enumerate(f):
        z1 = np.exp(2j * np.pi * fk * Ts)
        H = C @ np.linalg.solve(z1 * np.eye(A.shape[0]) - A, B) + D
        worst = max(worst, np.max(np.abs(H - g[k])) / np.max(np.abs(g[k])))
    assert worst < 1e-12, (kind, worst)
    print(kind, "max relative difference", worst)
print("machine export: OK")
"#;
    let o = Command::new("python3")
        .args(["-c", script])
        .arg(&dir)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    println!("{text}");
    assert!(
        o.status.success() && text.contains("machine export: OK"),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_recorded_files_are_refused_with_the_fix() {
    let dir = common::tmpdir("machine-files");
    // an FRF file with only one entry of the 4×4 plant
    std::fs::write(
        dir.join("frf.csv"),
        "f_hz,P_xa_xa_re,P_xa_xa_im,P_xa_xa_std,fs_hz\n10,1,0,0,20000\n20,1,0,0,20000\n",
    )
    .unwrap();
    // a directory whose meta.json says another speed
    std::fs::create_dir_all(dir.join("run").join("exp1")).unwrap();
    std::fs::write(
        dir.join("run").join("meta.json"),
        "{\"speed_rpm\": 15000.0, \"period_samples\": 255}",
    )
    .unwrap();
    let run = |toml: &str| {
        let c = WorkflowConfig::from_toml_str(toml, &dir.join("wf.toml")).unwrap();
        match run_with(
            &c,
            &dir,
            &mut Progress::new(Verbosity::Quiet),
            &MeasuredOnly,
        ) {
            Ok(_) => panic!("accepted"),
            Err(e) => (e.to_string(), e.exit_code()),
        }
    };
    let (e, code) = run("[machine]\n[[machine.files]]\nspeed_rpm = 0\npath = \"frf.csv\"\n");
    assert!(
        e.contains("15 missing entries") && e.contains("P_xb_xa") && e.contains("ambid frf"),
        "{e}"
    );
    assert_eq!(code, 3);
    let (e, code) = run("[machine]\n[[machine.files]]\nspeed_rpm = 12000\npath = \"run\"\n");
    assert!(
        e.contains("speed_rpm = 15000") && e.contains("speed_rpm = 12000"),
        "{e}"
    );
    assert_eq!(code, 3);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The section's defaults (orthogonal PRBS design, n = 10, 12 periods, nonlinear twin at 10 %
/// of i_sat, the 1× line removal, the ISO peak on lines with σ/|S| ≤ 0.1, the 10–1000 Hz band)
/// on random rigs of the twin's test family lifted to the machine (`MachineConfig::from_twin`):
/// without noise at standstill the measured FRF is the exact plant's to 1 % (what is left is the
/// nonlinearity at 10 % of i_sat); with the default noise at 30 000 rpm the measured
/// per-axis ISO peak is the exact one to 3 % and in the same zone, and the FRF's median error
/// (noise-limited, printed) stays below 15 %.
#[test]
fn defaults_hold_on_random_rigs() {
    let dir = common::tmpdir("machine-rigs");
    for seed in [3u64, 11, 29] {
        let rig = ambid_twin::random_rig(seed).unwrap();
        let mc = ambid_twin::MachineConfig::from_twin(&rig);
        std::fs::write(dir.join("machine.toml"), mc.to_toml_string().unwrap()).unwrap();
        let run = |extra: &str| {
            let c = WorkflowConfig::from_toml_str(
                &format!("[machine]\nconfig = \"machine.toml\"\n{extra}"),
                &dir.join("wf.toml"),
            )
            .unwrap();
            run_with(
                &c,
                &dir,
                &mut Progress::new(Verbosity::Quiet),
                &MeasuredOnly,
            )
            .unwrap_or_else(|e| panic!("rig {seed}: {e}"))
            .1
        };
        let clean = run("speeds_rpm = [0]\nnoise = false\n");
        let e = clean.summary.frf_error_vs_truth_pct[0];
        println!("rig {seed}: noise-free FRF error vs exact at 0 rpm {e:.3} %");
        assert!(e < 1.0, "rig {seed}: noise-free FRF error {e} %");
        let mo = run("speeds_rpm = [30000]\n");
        let s = &mo.summary;
        println!(
            "rig {seed}: FRF error vs exact (noise) {:?} %",
            s.frf_error_vs_truth_pct
        );
        for e in &s.frf_error_vs_truth_pct {
            assert!(*e < 15.0, "rig {seed}: median FRF error {e} %");
        }
        for k in 0..1 {
            for ax in ["xa", "xb", "ya", "yb"] {
                let pick = |from: &str| {
                    s.iso
                        .iter()
                        .find(|r| r.speed_rpm == s.speeds_rpm[k] && r.axis == ax && r.from == from)
                        .unwrap()
                };
                let (m, t) = (pick("measured"), pick("truth"));
                let rel = (m.peak - t.peak) / t.peak;
                println!(
                    "rig {seed} {} rpm {ax}: peak |S| measured {:.4} at {:.1} Hz, exact {:.4} at {:.1} Hz ({:+.2} %)",
                    s.speeds_rpm[k], m.peak, m.f_hz, t.peak, t.f_hz, 100.0 * rel
                );
                assert!(
                    rel.abs() < 0.03,
                    "rig {seed} {ax}: measured {} exact {}",
                    m.peak,
                    t.peak
                );
                assert_eq!(m.zone, t.zone, "rig {seed} {ax}");
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Recorded experiments: the directory `ambid simulate --axes 4` writes and the matrix FRF CSV
/// `ambid frf --speed-rpm` writes from it give the same 4×4 plant on every line of the CSV (the
/// same period average after the same 1× removal), as whole processes; `ambid run` refuses
/// unsorted speeds (exit 2) naming the order to write.
#[test]
fn recorded_directories_and_frf_files_give_the_same_plant() {
    let dir = common::tmpdir("machine-recorded");
    let exe = env!("CARGO_BIN_EXE_ambid");
    let sim = dir.join("sim");
    let o = Command::new(exe)
        .args([
            "simulate",
            "--axes",
            "4",
            "--design",
            "orthogonal",
            "--prbs-order",
            "8",
        ])
        .args([
            "--periods",
            "4",
            "--mode",
            "linear",
            "--speed-rpm",
            "30000",
            "--out",
        ])
        .arg(&sim)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut frf = Command::new(exe);
    frf.arg("frf");
    for e in 1..=4 {
        frf.arg(sim.join(format!("exp{e}")).join("data.csv"));
    }
    let o = frf
        .args(["--speed-rpm", "30000", "--out"])
        .arg(dir.join("frf.csv"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run = |path: &str| {
        let c = WorkflowConfig::from_toml_str(
            &format!("[machine]\n[[machine.files]]\nspeed_rpm = 30000\npath = \"{path}\"\n"),
            &dir.join("wf.toml"),
        )
        .unwrap();
        run_with(
            &c,
            &dir,
            &mut Progress::new(Verbosity::Quiet),
            &MeasuredOnly,
        )
        .unwrap_or_else(|e| panic!("{path}: {e}"))
        .1
    };
    let from_dir = run("sim");
    let from_csv = run("frf.csv");
    assert_eq!(from_dir.summary.source, "files");
    assert_eq!(from_dir.data.speeds[0].records.len(), 4);
    assert_eq!(from_dir.data.speeds[0].sync_removed_hz, Some(500.0));
    let (pd, pc) = (
        &from_dir.data.speeds[0].frf.plant,
        &from_csv.data.speeds[0].frf.plant,
    );
    assert!(pc.len() > 100, "{} lines", pc.len());
    let mut worst = 0.0f64;
    for (k, f) in pc.f_hz().iter().enumerate() {
        let kd = pd
            .f_hz()
            .iter()
            .position(|g| (g - f).abs() < 1e-9 * f)
            .unwrap_or_else(|| panic!("{f} Hz not in the directory's FRF"));
        for e in 0..16 {
            let (a, b) = (pc.values()[k * 16 + e], pd.values()[kd * 16 + e]);
            worst = worst.max((a - b).norm() / b.norm());
        }
    }
    assert!(worst < 1e-9, "largest relative difference {worst}");
    // both have S, so both have the per-axis ISO rows (no truth on recorded data)
    assert_eq!(from_csv.summary.iso.len(), 4);
    assert!(from_csv.summary.iso.iter().all(|r| r.from == "measured"));
    // as a process: unsorted speeds are a configuration error (exit 2) with the order to write
    let wf = dir.join("bad.toml");
    std::fs::write(&wf, "[machine]\nspeeds_rpm = [30000, 15000]\n").unwrap();
    let o = Command::new(exe)
        .arg("run")
        .arg(&wf)
        .arg("--out")
        .arg(dir.join("out"))
        .arg("-q")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("write [15000, 30000]"), "{err}");
    assert!(!dir.join("out").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `[machine] models = "fit"` runs the MIMO fitter inside `ambid run` (short records, one
/// speed): the comparison table has the default orders fitted in turn up to the first
/// admissible one at the noise level (a note names the orders left out), one chosen model with its
/// closed-loop validation on every axis and its closed-loop modes, the report renders the
/// model sections. Its accuracy is `tests/machine_models.rs`'s subject; an unknown value of the
/// key is refused with the accepted ones.
#[test]
fn models_fit_runs_the_mimo_fitter_in_the_workflow() {
    let c = cfg("seed = 7\n[machine]\nspeeds_rpm = [15000]\nmode = \"linear\"\nprbs_order = 8\nperiods = 6\nmodels = \"fit\"\n");
    let out =
        ambid::workflow::run(&c, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
    let m = &out.summary["machine"];
    let rows = m["comparison"].as_array().unwrap();
    let orders: Vec<u64> = rows.iter().map(|r| r["order"].as_u64().unwrap()).collect();
    assert!(
        !orders.is_empty() && [16, 20, 24].starts_with(&orders),
        "{rows:?}"
    );
    let chosen: Vec<_> = rows.iter().filter(|r| r["chosen"] == true).collect();
    assert_eq!(chosen.len(), 1, "{rows:?}");
    let html = out.report.to_html();
    if orders.len() < 3 {
        // the scan stopped at a model at the noise level, and the report's note says which
        // orders were left out; BIC still chooses among the fitted ones (on this short record
        // order 20 is at the noise level and 16, just above it, has the lower BIC)
        assert!(
            html.contains("at the noise level"),
            "no note on the orders left out"
        );
    }
    assert_eq!(m["models"].as_array().unwrap().len(), 1);
    let val = m["validation"].as_array().unwrap();
    assert_eq!(val.len(), 4, "{val:?}");
    for r in val {
        // the model's fit beside the exact plant's on the same independent record
        let (fit, truth) = (
            r["fit_y_pct"].as_f64().unwrap(),
            r["truth_fit_y_pct"].as_f64().unwrap(),
        );
        assert!(
            fit.is_finite() && truth.is_finite() && fit <= truth + 5.0,
            "{r}"
        );
    }
    assert!(!m["campbell_points"].as_array().unwrap().is_empty());
    assert!(html.contains("MIMO model comparison"));

    let bad =
        WorkflowConfig::from_toml_str("[machine]\nmodels = \"exact\"\n", Path::new("wf.toml"))
            .unwrap_err()
            .to_string();
    assert!(
        bad.contains("\"none\"") && bad.contains("\"fit\"") && bad.contains("\"fit-all\""),
        "{bad}"
    );
    // every order fitted on request
    WorkflowConfig::from_toml_str("[machine]\nmodels = \"fit-all\"\n", Path::new("wf.toml"))
        .unwrap();
}

/// `[machine] models = "fit"` on two speeds runs its independent parts side by side (the
/// reference speed's validation beside the other speed's fit, that speed's validation beside
/// the speed-scheduled model, a model's and the true plant's closed-loop simulations together):
/// every number of the machine summary is the same on one thread and on three (its JSON values
/// compared exactly), and the parts all ran (both speeds validated against the true plant, the
/// speed-scheduled model built).
#[test]
fn the_fitted_workflow_is_independent_of_the_threads() {
    let c = cfg(&format!("{SHORT}models = \"fit\"\n"));
    let run_on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let out =
                    ambid::workflow::run(&c, Path::new("."), &mut Progress::new(Verbosity::Quiet))
                        .unwrap();
                let html = out.report.to_html();
                (
                    out.summary["machine"].clone(),
                    html.contains("Speed-scheduled model: order"),
                )
            })
    };
    let (one, scheduled) = run_on(1);
    let (three, _) = run_on(3);
    assert!(
        one == three,
        "the fitted workflow depends on the number of threads:\n{one}\n{three}"
    );
    let val = one["validation"].as_array().unwrap();
    assert_eq!(val.len(), 8, "{val:?}");
    assert!(
        val.iter()
            .all(|r| r["truth_fit_y_pct"].as_f64().is_some_and(f64::is_finite)),
        "{val:?}"
    );
    assert_eq!(one["models"].as_array().unwrap().len(), 2);
    assert!(scheduled, "no speed-scheduled model");
}

/// `[machine] uncertainty = true` (with `models = "fit"`) adds the chosen model's uncertainty
/// per speed (short records, one speed, linear): a row in `summary.json` and the report's table;
/// the raise is at least 1 and the weights' lower one between 1 and it, the robust gain margins lie inside the exact loop's interval (the
/// pole oracle: a robust margin is one for every plant of the set, the exact plant among them
/// when the bound covers it) and the exact loop is stable at 90 % of each; the bound covers
/// σ̄(P − P̂) on ≥ 95 % of the 10–1000 Hz lines. Asking for it without a model is refused with
/// the fix.
#[test]
fn the_workflow_bounds_the_chosen_models_uncertainty_on_request() {
    let c = cfg("seed = 7\n[machine]\nspeeds_rpm = [15000]\nmode = \"linear\"\nprbs_order = 8\nperiods = 6\nmodels = \"fit\"\nuncertainty = true\n");
    let out =
        ambid::workflow::run(&c, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
    let rows = out.summary["machine"]["uncertainty"].as_array().unwrap();
    assert_eq!(rows.len(), 1, "{rows:?}");
    let r = &rows[0];
    eprintln!("{r}");
    assert!(r["raise"].as_f64().unwrap() >= 1.0);
    // the weights' raise (95 % of the pairs) on the same draws: never above the lines' (98 %)
    let wr = r["weight_raise"].as_f64().unwrap();
    assert!((1.0..=r["raise"].as_f64().unwrap()).contains(&wr), "{r}");
    assert_eq!(r["robustly_stable"], true, "{r}");
    let g = floats(&r["gain_margins"]);
    let e = floats(&r["exact_gain_margins"]);
    assert!(g[0] < 1.0 && g[1] > 1.0, "{r}");
    assert!(
        g[0] >= e[0] * (1.0 - 1e-3) && g[1] <= e[1] * (1.0 + 1e-3),
        "{r}"
    );
    assert!(r["truth_coverage"].as_f64().unwrap() >= 0.95, "{r}");
    let med = r["median_rel_pct"].as_f64().unwrap();
    assert!(med > 0.0 && med < 10.0, "{r}");
    // the bound's lines: the fit band and the validation lines above it, up to an octave
    let (fit, bound) = (floats(&r["band_hz"]), floats(&r["bound_band_hz"]));
    assert!(
        bound[0] == fit[0] && bound[1] >= fit[1] && bound[1] <= 2.0 * fit[1],
        "{r}"
    );
    assert!(out
        .report
        .to_html()
        .contains("Uncertainty and robust stability"));
    // the structured weight: 16 relative weights of order ≤ 4; covering the exact error as the
    // line bound does, robustly stable, its margins inside the exact ones and no wider than
    // the line test's by more than the grids differ
    assert!(r["weight_max_order"].as_u64().unwrap() <= 4, "{r}");
    assert!(r["weight_truth_coverage"].as_f64().unwrap() >= 0.95, "{r}");
    assert_eq!(r["weight_robustly_stable"], true, "{r}");
    let gw = floats(&r["weight_gain_margins"]);
    assert!(gw[0] < 1.0 && gw[1] > 1.0, "{r}");
    assert!(
        gw[0] >= e[0] * (1.0 - 1e-3) && gw[1] <= e[1] * (1.0 + 1e-3),
        "{r}"
    );
    // the coherent draws (docs/uncertainty.md, "Coherent draws for the machine"): the margins
    // of 95 % of 200 draws meet both margin bars against the exact loop's gain interval (which
    // is one interval around 1, so a gain inside it is stable)
    assert_eq!(r["coherent_draws"], 200, "{r}");
    assert!(
        r["coherent_stable_fraction"].as_f64().unwrap() >= 0.95,
        "{r}"
    );
    let gc = floats(&r["coherent_gain_margins"]);
    assert!(
        1.0 + 0.9 * (gc[1] - 1.0) < e[1] && 1.0 - 0.9 * (1.0 - gc[0]) > e[0],
        "{r}"
    );
    assert!(
        gc[1] - 1.0 >= 0.5 * (e[1] - 1.0) && 1.0 - gc[0] >= 0.5 * (1.0 - e[0]),
        "{r}"
    );
    // outside the lines the entry weights cap them: the interval they allow holds the margins
    let go = floats(&r["coherent_outside_gain_interval"]);
    assert!(go[0] <= gc[0] && go[1] >= gc[1], "{r}");
    assert!(out
        .report
        .to_html()
        .contains("machine-uncertainty-coherent"));
    // the uncertain model's files, beside the model's
    let dir = common::tmpdir("machine-uncertain-files");
    let written = out.write(&dir.join("o"), false).unwrap();
    let name = out.models[0].name.clone();
    let base = dir.join("o/models").join(format!("{name}_uncertain"));
    for ext in ["json", "m", "mat", "npz"] {
        let p = base.with_extension(ext);
        assert!(written.contains(&p) || p.is_file(), "{}", p.display());
    }
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(base.with_extension("json")).unwrap())
            .unwrap();
    assert_eq!(j["kind"], "uncertain_plant_matrix");
    let entries = j["entries"].as_array().unwrap();
    assert_eq!(entries.len(), 16);
    assert_eq!(entries[1]["output"], "y_xb");
    assert_eq!(entries[1]["input"], "u_xa");
    assert_eq!(
        j["robust"]["weights"]["upper_gain_margin"].as_f64(),
        Some(gw[1]),
        "{}",
        j["robust"]
    );
    let bad =
        WorkflowConfig::from_toml_str("[machine]\nuncertainty = true\n", Path::new("wf.toml"))
            .unwrap_err()
            .to_string();
    assert!(bad.contains("models = \"fit\""), "{bad}");
}

/// The asymmetric machine of the physical tests: its `[machine]` line and its twin at a speed.
const ASYMMETRY: &str =
    "asymmetry = { ki_rel = 0.03, kx_rel = -0.04, ki_rel_b = -0.06, kx_rel_b = 0.05 }\n";

fn asymmetric_machine(speed_rpm: f64) -> ambid_twin::Machine {
    ambid_twin::Machine::new(ambid_twin::MachineConfig {
        speed_rpm,
        asymmetry: ambid_twin::AsymmetryConfig {
            ki_rel: 0.03,
            kx_rel: -0.04,
            ki_rel_b: -0.06,
            kx_rel_b: 0.05,
        },
        ..Default::default()
    })
    .unwrap()
}

/// `[machine] physical = true` on an asymmetric linear twin (every axis its own magnet) at 0
/// and 20 000 rpm with the default experiment: the gray box per speed in `summary.json` and the
/// report; every $k_i$, $k_x$ within 0.5 % of the machine's linearisation
/// (`Machine::axis_magnets`, computed here), $f_b$ within 0.1 %; the options' refusals.
#[test]
fn the_workflow_estimates_every_axis_magnet_on_request() {
    // no amplitude study here (the next test runs it): no zero-amplitude table
    let c = cfg(&format!("seed = 11\n[machine]\nspeeds_rpm = [0, 20000]\nmode = \"linear\"\nphysical = true\namplitude_levels_pct = []\n{ASYMMETRY}"));
    let out =
        ambid::workflow::run(&c, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
    let rows = out.summary["machine"]["physical"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{rows:?}");
    for (r, speed) in rows.iter().zip([0.0, 20000.0]) {
        assert_eq!(r["speed_rpm"].as_f64(), Some(speed));
        assert!(r["error"].is_null(), "{r}");
        let m = asymmetric_machine(speed);
        let (ki, kx) = m.axis_magnets();
        let p = r["parameters"].as_array().unwrap();
        let get = |name: &str| p.iter().find(|q| q["name"] == name).unwrap();
        for (a, ax) in ["xa", "xb", "ya", "yb"].iter().enumerate() {
            for (name, truth) in [(format!("k_i_{ax}"), ki[a]), (format!("k_x_{ax}"), kx[a])] {
                let q = get(&name);
                let e = q["estimate"].as_f64().unwrap();
                assert!(
                    ((e - truth) / truth).abs() < 0.005,
                    "{speed} rpm {name}: {e} vs {truth}"
                );
                assert!((q["twin"].as_f64().unwrap() / truth - 1.0).abs() < 1e-12);
            }
        }
        let fb = get("bending_hz")["estimate"].as_f64().unwrap();
        assert!(
            (fb / m.config().rotor.bending_freq_hz - 1.0).abs() < 0.001,
            "{fb}"
        );
        let chi = r["chi2_per_dof"].as_f64().unwrap();
        assert!(chi < 1.5, "{chi}");
        assert!(r["zero_amplitude"].is_null(), "{r}");
        assert!(r.get("zero_amplitude_note").is_none(), "{r}");
    }
    assert!(out
        .report
        .sections
        .iter()
        .any(|s| s.id == "machine-physical" && !s.blocks.is_empty()));
    assert!(out.summary["timing"]["machine_physical_s"]
        .as_f64()
        .is_some());
    // refusals: files without a drawing; a drawing on the twin
    let e = WorkflowConfig::from_toml_str(
        "[machine]\nphysical = true\n[[machine.files]]\nspeed_rpm = 0\npath = \"frf.csv\"\n",
        Path::new("wf.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("machine.drawing"), "{e}");
    let e =
        WorkflowConfig::from_toml_str("[machine]\ndrawing = \"d.toml\"\n", Path::new("wf.toml"))
            .unwrap_err()
            .to_string();
    assert!(e.contains("machine.drawing"), "{e}");
    let e = WorkflowConfig::from_toml_str(
        "[machine]\nphysical = true\ndrawing = \"d.toml\"\n[[machine.files]]\nspeed_rpm = 9000\npath = \"frf.csv\"\n",
        Path::new("wf.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("polar_inertia_kgm2"), "{e}");
}

/// `[machine] physical = true` on an asymmetric *nonlinear* twin at 12 000 rpm (short records):
/// the default amplitude study (5 and 16 % beside the identification level's 10 %) gives the
/// parameters at zero amplitude. At 10 % every axis' $k_x$ is the best linear approximation's,
/// more than 3σ above the small-signal value (the linearisation, `Machine::axis_magnets`,
/// computed here); at zero amplitude each $k_i$, $k_x$ lies within 3σ and 0.3 % of it and
/// $f_b$ within 0.5 %. The report has the table; the key is refused without `physical` or
/// `uncertainty`.
#[test]
fn the_machine_physical_parameters_at_zero_amplitude_are_the_small_signal_ones() {
    let c = cfg(&format!(
        "seed = 5\n[machine]\nspeeds_rpm = [12000]\nmode = \"nonlinear\"\nprbs_order = 8\nperiods = 6\nphysical = true\n{ASYMMETRY}"
    ));
    let out =
        ambid::workflow::run(&c, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
    let r = &out.summary["machine"]["physical"][0];
    assert!(r["error"].is_null(), "{r}");
    let z = &r["zero_amplitude"];
    let levels: Vec<f64> = z["levels_pct"]
        .as_array()
        .unwrap_or_else(|| panic!("no zero amplitude: {r}"))
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(levels, vec![5.0, 10.0, 16.0], "{r}");
    let m = asymmetric_machine(12000.0);
    let (ki, kx) = m.axis_magnets();
    let get = |rows: &serde_json::Value, name: &str| -> (f64, f64) {
        let q = rows
            .as_array()
            .unwrap()
            .iter()
            .find(|q| q["name"] == name)
            .unwrap();
        (q["estimate"].as_f64().unwrap(), q["std"].as_f64().unwrap())
    };
    for (a, ax) in ["xa", "xb", "ya", "yb"].iter().enumerate() {
        let name = format!("k_x_{ax}");
        let (e10, s10) = get(&r["parameters"], &name);
        assert!(
            e10 - kx[a] > 3.0 * s10,
            "{name} at 10 %: {e10} ± {s10} vs {}",
            kx[a]
        );
        for (name, truth) in [(format!("k_i_{ax}"), ki[a]), (name, kx[a])] {
            let (e0, s0) = get(&z["parameters"], &name);
            assert!(
                (e0 - truth).abs() < 3.0 * s0 && (e0 / truth - 1.0).abs() < 0.003,
                "{name} at zero amplitude: {e0} ± {s0} vs {truth}"
            );
        }
    }
    let (fb, _) = get(&z["parameters"], "bending_hz");
    assert!(
        (fb / m.config().rotor.bending_freq_hz - 1.0).abs() < 0.005,
        "{fb}"
    );
    assert!(out
        .report
        .to_html()
        .contains("machine-physical-zero-12000rpm"));
    let bad = WorkflowConfig::from_toml_str(
        "[machine]\namplitude_levels_pct = [5, 16]\n",
        Path::new("wf.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(bad.contains("machine.physical = true"), "{bad}");
}

/// `[machine] physical = true` with a recorded matrix FRF file: the drawing from
/// `machine.drawing`, the polar inertia from `machine.polar_inertia_kgm2` (the FRF at
/// 12 000 rpm of `simulate --axes 4` with x/y and A/B asymmetry, linear physics): every $k_i$,
/// $k_x$ within 0.5 % of the machine's linearisation (computed here), no twin column.
#[test]
fn the_workflow_estimates_every_axis_magnet_from_files() {
    let dir = common::tmpdir("machine-physical-files");
    let exe = env!("CARGO_BIN_EXE_ambid");
    let toml = "speed_rpm = 12000.0\n[asymmetry]\nki_rel = -0.05\nkx_rel = 0.04\nki_rel_b = 0.06\nkx_rel_b = -0.07\n";
    std::fs::write(dir.join("machine.toml"), toml).unwrap();
    let sim = dir.join("sim");
    let o = Command::new(exe)
        .args([
            "simulate", "--axes", "4", "--mode", "linear", "--seed", "23", "--config",
        ])
        .arg(dir.join("machine.toml"))
        .arg("--out")
        .arg(&sim)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut frf = Command::new(exe);
    frf.arg("frf");
    for e in 1..=4 {
        frf.arg(sim.join(format!("exp{e}")).join("data.csv"));
    }
    let o = frf
        .args(["--speed-rpm", "12000", "--out"])
        .arg(dir.join("frf.csv"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cfg = ambid_twin::MachineConfig::from_toml_str(toml).unwrap();
    let (drawing, rot) = ambid::physical::machine_drawing(&cfg);
    std::fs::write(dir.join("drawing.toml"), toml::to_string(&drawing).unwrap()).unwrap();
    let c = WorkflowConfig::from_toml_str(
        &format!(
            "[machine]\nphysical = true\ndrawing = \"drawing.toml\"\npolar_inertia_kgm2 = {}\n[[machine.files]]\nspeed_rpm = 12000\npath = \"frf.csv\"\n",
            rot.polar_inertia_kgm2
        ),
        &dir.join("wf.toml"),
    )
    .unwrap();
    let out = ambid::workflow::run(&c, &dir, &mut Progress::new(Verbosity::Quiet)).unwrap();
    let rows = out.summary["machine"]["physical"].as_array().unwrap();
    assert_eq!(rows.len(), 1);
    let r = &rows[0];
    assert!(r["error"].is_null(), "{r}");
    let (ki, kx) = ambid_twin::Machine::new(cfg).unwrap().axis_magnets();
    let p = r["parameters"].as_array().unwrap();
    for (a, ax) in ["xa", "xb", "ya", "yb"].iter().enumerate() {
        for (name, truth) in [(format!("k_i_{ax}"), ki[a]), (format!("k_x_{ax}"), kx[a])] {
            let q = p.iter().find(|q| q["name"] == name.as_str()).unwrap();
            let e = q["estimate"].as_f64().unwrap();
            assert!(
                ((e - truth) / truth).abs() < 0.005,
                "{name}: {e} vs {truth}"
            );
            assert!(q["twin"].is_null());
        }
    }
    // a drawing that is not one: refused with the keys named
    std::fs::write(dir.join("bad.toml"), "mass = 3\n").unwrap();
    let c = WorkflowConfig::from_toml_str(
        &format!(
            "[machine]\nphysical = true\ndrawing = \"bad.toml\"\npolar_inertia_kgm2 = {}\n[[machine.files]]\nspeed_rpm = 12000\npath = \"frf.csv\"\n",
            rot.polar_inertia_kgm2
        ),
        &dir.join("wf.toml"),
    )
    .unwrap();
    let e = match ambid::workflow::run(&c, &dir, &mut Progress::new(Verbosity::Quiet)) {
        Ok(_) => panic!("a bad drawing was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("mass_kg") && e.contains("bad.toml"), "{e}");
}

/// Issue 23, term (e) for the machine: on the nominal *nonlinear* twin at 15 000 rpm (seed 7,
/// short records) the bound without an amplitude study holds the best linear approximation at
/// the identification level, and its norm covers the twin's exact linearisation on fewer than
/// 95 % of the 10–1000 Hz lines (92.1 % measured); with the default study (5 and 16 % of i_sat
/// beside the identification level's 10 %) every entry has term (e) and the bound and the
/// structured weight cover it on ≥ 95 % (100 % measured), and the robust margins stay within
/// the exact loop's; the summary gives the projection's Wald test. The report names the levels.
#[test]
fn the_machine_amplitude_study_bounds_the_small_signal_plant() {
    let run = |levels: &str| {
        let c = cfg(&format!(
            "seed = 7\n[machine]\nspeeds_rpm = [15000]\nmode = \"nonlinear\"\nprbs_order = 8\nperiods = 6\nmodels = \"fit\"\nuncertainty = true\n{levels}"
        ));
        ambid::workflow::run(&c, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap()
    };
    let (bare, with) = (run("amplitude_levels_pct = []\n"), run(""));
    let row = |o: &ambid::workflow::Outcome| o.summary["machine"]["uncertainty"][0].clone();
    let (b, w) = (row(&bare), row(&with));
    eprintln!("without: {b}\nwith: {w}");
    assert!(b.get("amplitude_levels_pct").is_none(), "{b}");
    assert!(b["truth_coverage"].as_f64().unwrap() < 0.95, "{b}");
    assert!(bare
        .report
        .to_html()
        .contains("No amplitude study at 15000 rpm"));
    let floats = |v: &serde_json::Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    assert_eq!(
        floats(&w["amplitude_levels_pct"]),
        vec![5.0, 10.0, 16.0],
        "{w}"
    );
    assert!(w["truth_coverage"].as_f64().unwrap() >= 0.95, "{w}");
    assert!(w["weight_truth_coverage"].as_f64().unwrap() >= 0.95, "{w}");
    // term (e) through the model: its Wald test against χ² of the tangent space's dimension
    let p = &w["amplitude_projected"];
    let (stat, thr) = (
        p["statistic"].as_f64().unwrap(),
        p["threshold"].as_f64().unwrap(),
    );
    assert!(stat >= 0.0 && thr > 100.0, "{w}");
    assert_eq!(p["kept"].as_bool().unwrap(), stat > thr, "{w}");
    assert!(b.get("amplitude_projected").is_none(), "{b}");
    // conservative margins: inside the exact loop's gain interval
    let e = floats(&w["exact_gain_margins"]);
    for key in ["gain_margins", "weight_gain_margins"] {
        let g = floats(&w[key]);
        assert!(
            g[0] >= e[0] * (1.0 - 1e-3) && g[1] <= e[1] * (1.0 + 1e-3) && g[0] < 1.0 && g[1] > 1.0,
            "{key}: {w}"
        );
    }
    assert!(with.report.to_html().contains("5, 10, 16: "));
    // levels on recorded files, or repeating the identification level, are refused with the
    // reason
    for (tail, says) in [
        (
            "amplitude_levels_pct = [5, 16]\n[[machine.files]]\nspeed_rpm = 0\npath = \"a\"\n",
            "not read yet",
        ),
        (
            "amplitude_levels_pct = [5, 10]\n",
            "identification level level_pct = 10",
        ),
    ] {
        let bad = WorkflowConfig::from_toml_str(
            &format!("[machine]\nmodels = \"fit\"\nuncertainty = true\n{tail}"),
            Path::new("wf.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(bad.contains(says), "{bad}");
    }
}
