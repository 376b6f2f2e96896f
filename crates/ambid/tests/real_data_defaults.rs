//! `ambid fit` with its defaults on the real open-loop data sets in ../shared/data/real, with
//! each README's standard split, against the README's reference numbers (numpy/SIPPY ARX
//! baselines, the best published linear figures), plus order sweeps that must write a model at
//! every order (no isolated refusal) and runs that must not abort on an unstable model.

use crate::common;
use crate::common::{ambid, s, text, tmpdir};
use std::path::{Path, PathBuf};

/// A file of the shared real data sets: `shared/data/real/<rel>` in the first ancestor of the
/// crate that has it (the workspace's sibling `../shared`, also from a git worktree).
fn real(rel: &str) -> String {
    let p = common::real_data(rel)
        .unwrap_or_else(|| panic!("shared/data/real/{rel} is needed for this check"));
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Writes `u,y` rows as a CSV.
fn write_uy(p: &Path, rows: &[(f64, f64)]) {
    let mut t = String::from("u,y\n");
    for (u, y) in rows {
        t.push_str(&format!("{u:e},{y:e}\n"));
    }
    std::fs::write(p, t).unwrap();
}

/// A DaISy file (whitespace columns `u y`) split at `split` into estimation / validation CSVs.
fn daisy(dir: &Path, rel: &str, split: usize) -> (PathBuf, PathBuf) {
    let rows: Vec<(f64, f64)> = real(rel)
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            (v[0], v[1])
        })
        .collect();
    let (e, v) = (dir.join("e.csv"), dir.join("v.csv"));
    write_uy(&e, &rows[..split]);
    write_uy(&v, &rows[split..]);
    (e, v)
}

/// Column `k` of the data rows of a nonlinearbenchmark CSV (quoted header, trailing commas,
/// constants on the first row only).
fn bench_cols(rel: &str, cols: &[usize]) -> Vec<Vec<f64>> {
    let body = real(rel);
    let mut out = vec![Vec::new(); cols.len()];
    for l in body.lines().skip(1) {
        let f: Vec<&str> = l.split(',').collect();
        if f.len() <= *cols.iter().max().unwrap() || f[cols[0]].trim().is_empty() {
            continue;
        }
        for (o, &k) in out.iter_mut().zip(cols) {
            o.push(f[k].trim().parse().unwrap());
        }
    }
    out
}

/// Runs `ambid fit` and returns the model JSON (the run must succeed and write it).
fn fit(e: &Path, v: &Path, fs: &str, args: &[&str], out: &Path) -> serde_json::Value {
    let mut a = vec![
        "fit",
        s(e),
        "--fs",
        fs,
        "--validation",
        s(v),
        "--out",
        s(out),
        "--force",
    ];
    a.extend_from_slice(args);
    let o = ambid(&a);
    assert!(o.status.success(), "{a:?}: {}", text(&o));
    assert!(out.exists(), "{a:?} wrote no model: {}", text(&o));
    serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap()
}

fn val(m: &serde_json::Value, key: &str) -> f64 {
    m["meta"]["validation"][key]
        .as_f64()
        .unwrap_or_else(|| panic!("no finite validation `{key}`: {m}"))
}

/// (file, split, fs, na, nb, nk, 1-step reference %, simulation reference %)
type Case = (
    &'static str,
    usize,
    &'static str,
    &'static str,
    &'static str,
    &'static str,
    f64,
    Option<f64>,
);

/// The READMEs' numpy ARX baselines (first-half means removed, half/half split, simulation and
/// prediction started from measured outputs) are matched or beaten with the default initial
/// state (estimated on each record, MATLAB `compare`'s default); ARX(8,8,1) on flutter, whose
/// 1-step fit was −503 % from a zero state, reaches the README's 99.98 %.
#[test]
fn arx_meets_the_readme_baselines_with_the_estimated_initial_state() {
    let d = tmpdir("real-arx");
    let m = d.join("m.json");
    let cases: [Case; 7] = [
        (
            "daisy-dryer/dryer.dat",
            500,
            "12.5",
            "2",
            "2",
            "3",
            95.04,
            Some(85.57),
        ),
        (
            "daisy-dryer/dryer.dat",
            500,
            "12.5",
            "4",
            "4",
            "3",
            95.22,
            Some(85.78),
        ),
        (
            "daisy-robot-arm/robot_arm.dat",
            512,
            "100",
            "4",
            "4",
            "1",
            98.12,
            Some(14.86),
        ),
        (
            "daisy-robot-arm/robot_arm.dat",
            512,
            "100",
            "8",
            "8",
            "1",
            99.91,
            Some(97.13),
        ),
        (
            "daisy-flutter/flutter.dat",
            512,
            "1",
            "2",
            "2",
            "1",
            91.32,
            Some(21.58),
        ),
        (
            "daisy-flutter/flutter.dat",
            512,
            "1",
            "8",
            "8",
            "1",
            99.98,
            None,
        ),
        (
            "daisy-ballbeam/ballbeam.dat",
            500,
            "10",
            "2",
            "2",
            "1",
            96.71,
            None,
        ),
    ];
    for (file, split, fs, na, nb, nk, one, sim) in cases {
        let (e, v) = daisy(&d, file, split);
        let j = fit(
            &e,
            &v,
            fs,
            &["--structure", "arx", "--na", na, "--nb", nb, "--nk", nk],
            &m,
        );
        let f1 = val(&j, "one_step_fit_pct");
        // the README rounds to 0.01 %
        assert!(
            f1 >= one - 0.005,
            "{file} ARX({na},{nb},{nk}): 1-step {f1} < {one}"
        );
        if let Some(r) = sim {
            let fs_ = val(&j, "simulation_fit_pct");
            assert!(
                fs_ >= r - 0.005,
                "{file} ARX({na},{nb},{nk}): sim {fs_} < {r}"
            );
        }
    }
    // the zero initial state reproduces the old figure: the estimate is what closes the gap
    let (e, v) = daisy(&d, "daisy-flutter/flutter.dat", 512);
    let j = fit(
        &e,
        &v,
        "1",
        &[
            "--structure",
            "arx",
            "--na",
            "8",
            "--nb",
            "8",
            "--x0",
            "zero",
        ],
        &m,
    );
    assert!(val(&j, "one_step_fit_pct") < 0.0, "{j}");
    // --skip 8 with the zero state: the README's protocol (k0 = 8) gives its number back
    let j = fit(
        &e,
        &v,
        "1",
        &[
            "--structure",
            "arx",
            "--na",
            "8",
            "--nb",
            "8",
            "--x0",
            "zero",
            "--skip",
            "8",
        ],
        &m,
    );
    assert!(val(&j, "one_step_fit_pct") >= 99.975, "{j}");
}

/// Cascaded tanks (estimation / test record of the benchmark): the default OE(2,2,1) simulation
/// on the test record has an RMS error below the published BLA figure 0.757 V and below the
/// README's best numpy ARX baseline (ARX(4,4,1), 0.638 V).
#[test]
fn cascaded_tanks_oe_beats_the_bla_and_the_arx_baselines() {
    let d = tmpdir("real-tanks");
    let c = bench_cols("cascaded-tanks/dataBenchmark.csv", &[0, 1, 2, 3]);
    assert_eq!(c[0].len(), 1024);
    let (e, v) = (d.join("e.csv"), d.join("v.csv"));
    let rows = |u: &[f64], y: &[f64]| u.iter().copied().zip(y.iter().copied()).collect::<Vec<_>>();
    write_uy(&e, &rows(&c[0], &c[2]));
    write_uy(&v, &rows(&c[1], &c[3]));
    let j = fit(
        &e,
        &v,
        "0.25",
        &["--structure", "oe", "--nb", "2", "--nf", "2", "--nk", "1"],
        &d.join("m.json"),
    );
    let rms = val(&j, "simulation_rms");
    // below the BLA (0.757 V) and below the best ARX baseline (0.638 V), the stricter bar
    assert!(rms < 0.638, "test RMS {rms} V");
}

/// EMPS (u = vir, y = qm; DATA_EMPS for estimation, DATA_EMPS_PULSES for the test): OE of every
/// order 1..6 writes a model (the integrator's least-squares start at |z| = 1.00003 is
/// stabilised for the start only), none falls back, and OE(2,2,2), the command that was
/// refused, simulates the test record with a relative error
/// ‖y − ŷ‖/‖y‖ ≤ ‖y − ŷ‖/‖y − ȳ‖ = 1 − fit/100 far below the black-box 74.6 %.
#[test]
fn emps_oe_orders_are_never_refused_and_beat_the_black_box_figure() {
    let d = tmpdir("real-emps");
    let read = |name: &str| {
        let body = real(&format!("emps/{name}"));
        let mut lines = body.lines();
        let h: Vec<&str> = lines.next().unwrap().split(',').collect();
        let iu = h.iter().position(|c| *c == "vir_control_V").unwrap();
        let iy = h.iter().position(|c| *c == "qm_position_m").unwrap();
        lines
            .filter(|l| !l.trim().is_empty())
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                (f[iu].parse().unwrap(), f[iy].parse().unwrap())
            })
            .collect::<Vec<(f64, f64)>>()
    };
    let (e, v) = (d.join("e.csv"), d.join("v.csv"));
    write_uy(&e, &read("emps_estimation.csv"));
    write_uy(&v, &read("emps_validation_pulses.csv"));
    let m = d.join("m.json");
    let j = fit(
        &e,
        &v,
        "1000",
        &["--structure", "oe", "--nb", "2", "--nf", "2", "--nk", "2"],
        &m,
    );
    let f = val(&j, "simulation_fit_pct");
    assert!(1.0 - f / 100.0 < 0.746, "fit {f} %");
    assert!(f > 75.0, "fit {f} %");
    assert_eq!(j["meta"]["loop"], "open");
    assert_eq!(j["meta"]["fallback"], false);
    // declared closed-loop, the same unstable start is refused as before (the AMB rule), the
    // ARX model of the same orders is written instead with the closed-loop advice
    let j = fit(
        &e,
        &v,
        "1000",
        &[
            "--structure",
            "oe",
            "--nb",
            "2",
            "--nf",
            "2",
            "--nk",
            "2",
            "--loop",
            "closed",
        ],
        &m,
    );
    assert_eq!(j["meta"]["loop"], "closed");
    assert_eq!(j["meta"]["fallback"], true);
    assert!(j["meta"]["problems"].to_string().contains("T_ry"), "{j}");
    for n in 1..=6 {
        let n = n.to_string();
        let j = fit(
            &e,
            &v,
            "1000",
            &["--structure", "oe", "--nb", &n, "--nf", &n, "--nk", "1"],
            &m,
        );
        assert_eq!(j["meta"]["fallback"], false, "OE({n},{n},1): {j}");
        let f = val(&j, "simulation_fit_pct");
        assert!(f > 40.0, "OE({n},{n},1): {f}");
    }
}

/// Flutter (512/512): OE of every order 1..6 and simulation-focus SS of every order 1..10 are
/// estimated (not refused, no fallback) and simulate the validation half finitely; OE(5,5,1)
/// and SS(5) were refused before (unstable starts at |z| = 1.003 and 1.05).
#[test]
fn flutter_order_sweeps_have_no_refusal() {
    let d = tmpdir("real-flutter");
    let (e, v) = daisy(&d, "daisy-flutter/flutter.dat", 512);
    let m = d.join("m.json");
    for n in 1..=6 {
        let n = n.to_string();
        let j = fit(
            &e,
            &v,
            "1",
            &["--structure", "oe", "--nb", &n, "--nf", &n, "--nk", "1"],
            &m,
        );
        assert_eq!(j["meta"]["fallback"], false, "OE({n},{n},1): {j}");
        assert!(val(&j, "simulation_fit_pct") > 15.0, "OE({n}): {j}");
    }
    for n in 1..=10 {
        let n = n.to_string();
        let j = fit(
            &e,
            &v,
            "1",
            &["--structure", "ss", "--order", &n, "--focus", "simulation"],
            &m,
        );
        let method = j["meta"]["method"].as_str().unwrap();
        assert!(method.ends_with("pem"), "SS({n}): {method}");
        assert!(val(&j, "simulation_fit_pct").is_finite());
        // the refinement's initial state is stored with the model
        assert_eq!(j["x0"].as_array().map(Vec::len), Some(n.parse().unwrap()));
    }
}

/// F-16 GVT level 1 (Force → Acceleration1; period 2 for estimation, period 6 for validation):
/// the simulation-focus SS fits of orders 13..16, whose subspace starts are unstable at the high
/// orders, are refined from a stabilised start and simulate the validation period; and the
/// unrefined subspace model of order 16, unstable, no longer aborts the run ("non-finite value
/// in yhat"): it is written with the divergence named.
#[test]
fn f16_high_order_state_space_is_always_written() {
    let d = tmpdir("real-f16");
    let c = bench_cols("f16-gvt/F16Data_FullMSine_Level1.csv", &[0, 2]);
    assert_eq!(c[0].len(), 73728);
    let rows = |k: usize| -> Vec<(f64, f64)> {
        (k * 8192..(k + 1) * 8192)
            .map(|i| (c[0][i], c[1][i]))
            .collect()
    };
    let (e, v) = (d.join("e.csv"), d.join("v.csv"));
    write_uy(&e, &rows(1));
    write_uy(&v, &rows(5));
    let m = d.join("m.json");
    for n in 13..=16 {
        let n = n.to_string();
        let j = fit(
            &e,
            &v,
            "400",
            &["--structure", "ss", "--order", &n, "--focus", "simulation"],
            &m,
        );
        let method = j["meta"]["method"].as_str().unwrap();
        assert!(method.ends_with("pem"), "SS({n}): {method}");
        assert!(val(&j, "simulation_fit_pct") > 70.0, "SS({n}): {j}");
    }
    let o = ambid(&[
        "fit",
        s(&e),
        "--fs",
        "400",
        "--structure",
        "ss",
        "--order",
        "16",
        "--no-pem",
        "--validation",
        s(&v),
        "--out",
        s(&m),
        "--force",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let j: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&m).unwrap()).unwrap();
    assert_eq!(j["kind"], "state_space");
    assert!(j["meta"]["problems"].is_array(), "{j}");
    let fit = &j["meta"]["validation"]["simulation_fit_pct"];
    // a diverging simulation is reported (null or a finite figure), never an abort
    assert!(
        fit.is_null() || fit.as_f64().is_some_and(f64::is_finite),
        "{j}"
    );
}

/// `--feedthrough`: the robot arm's output is an acceleration, which responds to the torque
/// within the sample, so D ≠ 0 is estimated and the simulation fit does not get worse; the
/// default keeps D = 0.
#[test]
fn feedthrough_is_estimated_on_request() {
    let d = tmpdir("real-d");
    let (e, v) = daisy(&d, "daisy-robot-arm/robot_arm.dat", 512);
    let m = d.join("m.json");
    let j0 = fit(&e, &v, "100", &["--structure", "ss", "--order", "6"], &m);
    assert_eq!(j0["d"][0][0].as_f64(), Some(0.0));
    let j1 = fit(
        &e,
        &v,
        "100",
        &["--structure", "ss", "--order", "6", "--feedthrough"],
        &m,
    );
    assert!(j1["d"][0][0].as_f64().unwrap().abs() > 0.0, "{j1}");
    assert!(
        val(&j1, "simulation_fit_pct") >= val(&j0, "simulation_fit_pct") - 0.5,
        "{j0} {j1}"
    );
    let o = ambid(&[
        "fit",
        s(&e),
        "--fs",
        "100",
        "--structure",
        "ss",
        "--order",
        "6",
        "--no-pem",
        "--feedthrough",
        "--out",
        s(&m),
        "--force",
    ]);
    assert!(!o.status.success() && text(&o).contains("--feedthrough"));
}

/// CD-player arm, 2 × 2 (first half estimation, second half validation, first-half means
/// removed): `fit --input u1,u2 --output y1,y2 --structure ss` identifies one MIMO model; with
/// the simulation focus its validation simulation fits beat the README's ARX(2,2,1) baselines
/// (y1 66.72 %, y2 76.88 %) at orders 4 and 6; `--structure arx` fits the 2 × 2 ARX (the README's
/// MISO-per-output protocol with `--output-coupling diagonal`); OE refuses several columns with a
/// clear message.
#[test]
fn cd_player_two_by_two_state_space() {
    let d = tmpdir("real-cd");
    let rows: Vec<Vec<f64>> = real("daisy-cd-player-arm/CD_player_arm.dat")
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 2048);
    let write = |p: &Path, part: &[Vec<f64>]| {
        let mut t = String::from("u1,u2,y1,y2\n");
        for r in part {
            t.push_str(&format!("{:e},{:e},{:e},{:e}\n", r[0], r[1], r[2], r[3]));
        }
        std::fs::write(p, t).unwrap();
    };
    let (e, v) = (d.join("e.csv"), d.join("v.csv"));
    write(&e, &rows[..1024]);
    write(&v, &rows[1024..]);
    let m = d.join("m.json");
    for n in ["4", "6"] {
        let j = fit(
            &e,
            &v,
            "1",
            &[
                "--input",
                "u1,u2",
                "--output",
                "y1,y2",
                "--structure",
                "ss",
                "--order",
                n,
                "--focus",
                "simulation",
            ],
            &m,
        );
        assert_eq!(j["b"][0].as_array().map(Vec::len), Some(2), "{j}");
        assert_eq!(j["c"].as_array().map(Vec::len), Some(2), "{j}");
        let f = j["meta"]["validation"]["simulation_fit_pct"]
            .as_array()
            .unwrap();
        let (f1, f2) = (f[0].as_f64().unwrap(), f[1].as_f64().unwrap());
        assert!(f1 >= 66.72 && f2 >= 76.88, "order {n}: {f1} / {f2}");
    }
    // polynomial MIMO: the README's protocol (MISO ARX per output = diagonal coupling,
    // na = nb = 2, nk = 1) reproduces its numpy 1-step fits (83.10 %, 77.04 %) and, from the
    // estimated initial state, beats its simulation fits (66.72 %, 76.88 %)
    // one 2 × 2 ARX(2,2,1) fit, extra options `more`: its validation figure `key` per output
    let arx = |name: &str, more: &[&str]| -> serde_json::Value {
        let mut args = vec![
            "--input",
            "u1,u2",
            "--output",
            "y1,y2",
            "--structure",
            "arx",
            "--na",
            "2",
            "--nb",
            "2",
        ];
        args.extend_from_slice(more);
        fit(&e, &v, "1", &args, &d.join(name))
    };
    let vals = |j: &serde_json::Value, key: &str| -> Vec<f64> {
        j["meta"]["validation"][key]
            .as_array()
            .unwrap_or_else(|| panic!("{key}: {j}"))
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let j = arx("arx-diagonal.json", &["--output-coupling", "diagonal"]);
    let (p1, sim) = (vals(&j, "one_step_fit_pct"), vals(&j, "simulation_fit_pct"));
    println!("CD player ARX(2,2,1) diagonal: 1-step {p1:?}, simulation {sim:?}");
    assert!(
        (p1[0] - 83.10).abs() < 0.1 && (p1[1] - 77.04).abs() < 0.1,
        "{p1:?}"
    );
    assert!(sim[0] >= 66.72 && sim[1] >= 76.88, "{sim:?}");
    // full coupling (MATLAB's multi-output ARX) has more parameters: a better 1-step fit
    let pf = vals(&arx("arx-full.json", &[]), "one_step_fit_pct");
    println!("CD player ARX(2,2,1) full: 1-step {pf:?}");
    assert!(pf[0] > 80.0 && pf[1] > 75.0, "{pf:?}");
    // OE has no multi-output path here: a clear refusal naming the structures that do
    let o = ambid(&[
        "fit",
        s(&e),
        "--fs",
        "1",
        "--input",
        "u1,u2",
        "--output",
        "y1",
        "--structure",
        "oe",
        "--nb",
        "2",
        "--nf",
        "2",
        "--out",
        s(&d.join("oe.json")),
        "--force",
    ]);
    assert!(
        !o.status.success() && text(&o).contains("--structure ss, arx or fir"),
        "{}",
        text(&o)
    );
}

/// `--loop auto` takes ambid's own closed-loop record (t, w, r, u, i, y) with input u as closed
/// loop, and the same file with input r (T_ry, stable) as open loop.
#[test]
fn loop_auto_detects_the_closed_loop_record() {
    let d = tmpdir("real-loop");
    let o = ambid(&[
        "simulate",
        "--rig-seed",
        "3",
        "--periods",
        "2",
        "--mode",
        "linear",
        "--out",
        s(&d),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let data = d.join("data.csv");
    for (input, want) in [("u", "closed"), ("r", "open")] {
        let m = d.join(format!("m-{input}.json"));
        let o = ambid(&[
            "fit",
            s(&data),
            "--structure",
            "oe",
            "--nb",
            "2",
            "--nf",
            "2",
            "--input",
            input,
            "--out",
            s(&m),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&m).unwrap()).unwrap();
        assert_eq!(j["meta"]["loop"], want, "input {input}");
    }
}

/// ARMAX on real open-loop data (half/half splits) must not settle in a worse local minimum than
/// the joint iteration did before variable projection (commit 779b697: ball-and-beam
/// ARMAX(4,4,4,1) loss 4.6137e-6, cascaded tanks ARMAX(3,3,3,1) 2.1784e-3), and flutter
/// ARMAX(2,2,2,1) must converge within the default budget. Iterating only the start with the
/// smaller projected loss failed all three (4.6761e-6, 2.2077e-3, iteration limit); the probe of
/// both starts (docs/estimation.md) passes. A regression guard on measured optima, not a truth.
#[test]
fn armax_on_real_data_keeps_the_joint_iterations_optima_and_converges() {
    let d = tmpdir("real-armax");
    let m = d.join("m.json");
    let loss = |j: &serde_json::Value| j["meta"]["loss"].as_f64().unwrap();
    let armax = |n: &'static str| ["--structure", "armax", "--na", n, "--nb", n, "--nc", n];
    let (e, v) = daisy(&d, "daisy-ballbeam/ballbeam.dat", 500);
    let j = fit(&e, &v, "10", &armax("4"), &m);
    assert!(
        loss(&j) <= 4.6137e-6 * 1.0005,
        "ball-and-beam ARMAX(4,4,4,1): {}",
        loss(&j)
    );
    let c = bench_cols("cascaded-tanks/dataBenchmark.csv", &[0, 1, 2, 3]);
    let (e, v) = (d.join("te.csv"), d.join("tv.csv"));
    let rows = |u: &[f64], y: &[f64]| u.iter().copied().zip(y.iter().copied()).collect::<Vec<_>>();
    write_uy(&e, &rows(&c[0], &c[2]));
    write_uy(&v, &rows(&c[1], &c[3]));
    let j = fit(&e, &v, "0.25", &armax("3"), &m);
    assert!(
        loss(&j) <= 2.1784e-3 * 1.0005,
        "tanks ARMAX(3,3,3,1): {}",
        loss(&j)
    );
    let (e, v) = daisy(&d, "daisy-flutter/flutter.dat", 512);
    let j = fit(&e, &v, "1", &armax("2"), &m);
    let stop = j["meta"]["stop"].as_str().unwrap_or_default();
    assert!(
        stop.starts_with("converged"),
        "flutter ARMAX(2,2,2,1): {stop}"
    );
}
