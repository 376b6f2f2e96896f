//! `ambid simulate --axes 4` and `ambid frf` on several experiment files, end to end: the
//! written files' layout, the MIMO FRF of noise-free linear records against `truth.csv` and
//! against the twin's exact `Machine` model (independent of the CLI), and the bad-input errors
//! (exit code and the message naming the fix).
//!
//! Records are short (PRBS order 7, 5 samples per bit: a period of 635 samples, 63 lines up to
//! 2 kHz; 3 periods per experiment): the bar is noise-free exactness, which needs no averaging.

use crate::common::{ambid, s, text, tmpdir};
use ambid_twin::{Machine, MachineConfig, AXES};
use num_complex::Complex64;
use std::collections::HashMap;
use std::path::Path;

/// A CSV file as its header and rows of numbers.
struct Table {
    names: Vec<String>,
    rows: Vec<Vec<f64>>,
}

impl Table {
    fn read(p: &Path) -> Table {
        let mut r = csv::Reader::from_path(p).unwrap();
        let names = r.headers().unwrap().iter().map(String::from).collect();
        let rows = r
            .records()
            .map(|rec| rec.unwrap().iter().map(|v| v.parse().unwrap()).collect())
            .collect();
        Table { names, rows }
    }
    /// The rows of a `_sync.csv` file: (channel, f_hz, abs).
    fn read_mixed(p: &Path) -> Vec<(String, f64, f64)> {
        let mut r = csv::Reader::from_path(p).unwrap();
        let h: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
        assert_eq!(
            h,
            [
                "experiment",
                "channel",
                "f_hz",
                "re",
                "im",
                "abs",
                "phase_deg",
                "std"
            ]
        );
        r.records()
            .map(|rec| {
                let rec = rec.unwrap();
                (
                    rec[1].to_string(),
                    rec[2].parse().unwrap(),
                    rec[5].parse().unwrap(),
                )
            })
            .collect()
    }
    fn col(&self, name: &str) -> usize {
        self.names
            .iter()
            .position(|n| n == name)
            .unwrap_or_else(|| panic!("no column {name} in {:?}", self.names))
    }
    fn c(&self, row: usize, q: &str, o: &str, i: &str) -> Complex64 {
        let re = self.rows[row][self.col(&format!("{q}_{o}_{i}_re"))];
        let im = self.rows[row][self.col(&format!("{q}_{o}_{i}_im"))];
        Complex64::new(re, im)
    }
}

/// The expected matrix-FRF header: f_hz, then P, T_ry, S entries out-major with re/im/std.
fn quantity_header() -> Vec<String> {
    let mut h = vec!["f_hz".to_string()];
    for q in ["P", "T_ry", "S"] {
        for o in AXES {
            for i in AXES {
                for p in ["re", "im", "std"] {
                    h.push(format!("{q}_{o}_{i}_{p}"));
                }
            }
        }
    }
    h
}

fn simulate(out: &Path, extra: &[&str]) {
    let mut args = vec![
        "simulate",
        "--axes",
        "4",
        "--mode",
        "linear",
        "--no-noise",
        "--prbs-order",
        "7",
        "--periods",
        "3",
        "--out",
        s(out),
    ];
    args.extend_from_slice(extra);
    let o = ambid(&args);
    assert!(o.status.success(), "{}", text(&o));
}

fn exp_files(dir: &Path, m: usize) -> Vec<String> {
    (1..=m)
        .map(|e| s(&dir.join(format!("exp{e}")).join("data.csv")).to_string())
        .collect()
}

fn frf(files: &[String], out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args: Vec<&str> = vec!["frf"];
    args.extend(files.iter().map(String::as_str));
    args.extend_from_slice(&["--out", s(out)]);
    args.extend_from_slice(extra);
    ambid(&args)
}

/// Row of `truth` at frequency `f` (to 1e-9 relative).
fn truth_rows(truth: &Table) -> HashMap<u64, usize> {
    // key: the frequency rounded to 1e-6 Hz
    (0..truth.rows.len())
        .map(|k| ((truth.rows[k][0] * 1e6).round() as u64, k))
        .collect()
}

/// Largest |est − truth| over the entries of quantity `q`, relative to the largest |truth|
/// entry on the line, over every line up to 2 kHz; `cols`: which input columns to compare
/// (`None`: all).
fn worst(
    est: &Table,
    truth: &Table,
    q: &str,
    cols: Option<&dyn Fn(usize, usize) -> bool>,
) -> (f64, usize) {
    let idx = truth_rows(truth);
    let mut w = 0.0f64;
    let mut n = 0;
    for (k, row) in est.rows.iter().enumerate() {
        if row[0] > 2000.0 {
            continue;
        }
        let t = *idx
            .get(&((row[0] * 1e6).round() as u64))
            .unwrap_or_else(|| panic!("truth.csv has no line {} Hz", row[0]));
        assert!((truth.rows[t][0] - row[0]).abs() <= 1e-9 * row[0]);
        let scale = AXES
            .iter()
            .flat_map(|o| AXES.iter().map(move |i| (o, i)))
            .map(|(o, i)| truth.c(t, q, o, i).norm())
            .fold(0.0f64, f64::max);
        for o in AXES {
            for (b, i) in AXES.iter().enumerate() {
                if cols.is_some_and(|c| !c(k, b)) {
                    continue;
                }
                w = w.max((est.c(k, q, o, i) - truth.c(t, q, o, i)).norm() / scale);
                n += 1;
            }
        }
    }
    (w, n)
}

/// truth.csv against the twin's own 4×4 truth at its frequencies (independent of the CLI).
fn check_truth_file(truth: &Table, speed: f64) {
    let m = Machine::new(MachineConfig {
        speed_rpm: speed,
        ..MachineConfig::default()
    })
    .unwrap();
    let f: Vec<f64> = truth.rows.iter().map(|r| r[0]).collect();
    for (q, g) in [
        ("P", m.plant_frf(&f).unwrap()),
        ("T_ry", m.t_ry_frf(&f).unwrap()),
        ("S", m.sensitivity_frf(&f).unwrap()),
    ] {
        for k in (0..f.len()).step_by(7) {
            let gm = g.at(k).unwrap();
            for (a, o) in AXES.iter().enumerate() {
                for (b, i) in AXES.iter().enumerate() {
                    let t = gm[(a, b)];
                    let d = (truth.c(k, q, o, i) - Complex64::new(t.re, t.im)).norm();
                    assert!(
                        d <= 1e-12 * t.norm().max(1e-300),
                        "{q}_{o}_{i} at {} Hz",
                        f[k]
                    );
                    let sd = truth.rows[k][truth.col(&format!("{q}_{o}_{i}_std"))];
                    assert_eq!(sd, 0.0);
                }
            }
        }
    }
    // the x–y cross terms of P: zero at standstill (no asymmetry), not at speed
    let cross = (0..f.len())
        .filter(|&k| f[k] > 10.0 && f[k] < 2000.0)
        .map(|k| truth.c(k, "P", "xa", "ya").norm() / truth.c(k, "P", "xa", "xa").norm())
        .fold(0.0f64, f64::max);
    if speed == 0.0 {
        assert!(cross < 1e-12, "{cross}");
    } else {
        assert!(cross > 1e-3, "{cross}");
    }
}

#[test]
fn sequential_and_orthogonal_frf_equal_the_truth_at_0_and_30000_rpm() {
    let d = tmpdir("machine-seq-orth");
    for speed in ["0", "30000"] {
        for design in ["sequential", "orthogonal"] {
            let out = d.join(format!("{design}-{speed}"));
            simulate(&out, &["--speed-rpm", speed, "--design", design]);
            // the files
            let data = Table::read(&out.join("exp1").join("data.csv"));
            let mut want = vec!["t".to_string()];
            for l in ["r", "u", "y", "i"] {
                want.extend(AXES.iter().map(|a| format!("{l}_{a}")));
            }
            assert_eq!(data.names, want);
            assert_eq!(data.rows.len(), 3 * 635);
            assert!(!out.join("exp5").exists());
            let meta: serde_json::Value =
                serde_json::from_slice(&std::fs::read(out.join("meta.json")).unwrap()).unwrap();
            assert_eq!(meta["design"]["kind"], design);
            assert_eq!(meta["design"]["experiments"], 4);
            assert_eq!(meta["period_samples"], 635);
            assert_eq!(meta["periods"], 3);
            let rpm: f64 = speed.parse().unwrap();
            assert_eq!(meta["speed_rpm"].as_f64().unwrap(), rpm);
            assert!((meta["sync_hz"].as_f64().unwrap() - rpm / 60.0).abs() < 1e-9);
            assert!((meta["design"]["condition"]["max"].as_f64().unwrap() - 1.0).abs() < 1e-9);
            let truth = Table::read(&out.join("truth.csv"));
            let mut th = quantity_header();
            th.push("fs_hz".into());
            assert_eq!(truth.names, th);
            check_truth_file(&truth, rpm);

            // the MIMO FRF from the four files (period derived from r, one period skipped)
            let est_path = out.join("frf.csv");
            let o = frf(&exp_files(&out, 4), &est_path, &[]);
            let t = text(&o);
            assert!(o.status.success(), "{t}");
            assert!(t.contains("period: 635 samples"), "{t}");
            assert!(t.contains("4 experiments"), "{t}");
            let est = Table::read(&est_path);
            let mut h = quantity_header();
            h.extend(AXES.iter().map(|a| format!("coh_{a}")));
            h.extend(["cond_r", "cond_u", "fs_hz"].map(String::from));
            assert_eq!(est.names, h);
            // every line of the PRBS's band up to 2 kHz
            assert_eq!(est.rows.iter().filter(|r| r[0] <= 2000.0).count(), 63);
            for q in ["P", "T_ry", "S"] {
                let (w, n) = worst(&est, &truth, q, None);
                println!(
                    "{design} {speed} rpm {q}: worst relative error {w:.2e} over {n} entry-lines"
                );
                assert!(w <= 1e-6, "{design} {speed} rpm {q}: {w}");
                assert_eq!(n, 63 * 16);
            }
            // exact data: no spread, full coherence, the design's conditioning
            let c = est.col("cond_r");
            assert!(est.rows.iter().all(|r| (r[c] - 1.0).abs() < 1e-9));
            let coh = est.col("coh_xa");
            assert!(est
                .rows
                .iter()
                .filter(|r| r[0] <= 2000.0)
                .all(|r| (r[coh] - 1.0).abs() < 1e-9));
            let sd = est.col("P_xa_xa_std");
            for (k, r) in est.rows.iter().enumerate().filter(|(_, r)| r[0] <= 2000.0) {
                let p = est.c(k, "P", "xa", "xa").norm();
                assert!(r[sd] <= 1e-9 * p, "{} Hz: std {} of |P| {p}", r[0], r[sd]);
            }
        }
    }
}

#[test]
fn zipper_measured_columns_equal_the_truth_at_0_and_30000_rpm() {
    let d = tmpdir("machine-zipper");
    for speed in ["0", "30000"] {
        let out = d.join(format!("zip-{speed}"));
        // 1000-sample period: 20 Hz lines, 100 lines in 1–2000 Hz, 25 per axis
        simulate(
            &out,
            &[
                "--speed-rpm",
                speed,
                "--design",
                "zipper",
                "--period",
                "0.05",
            ],
        );
        assert!(out.join("exp1").join("data.csv").exists() && !out.join("exp2").exists());
        let truth = Table::read(&out.join("truth.csv"));
        let est_path = out.join("frf.csv");
        // one file with r_<axis> columns: the MIMO path without --axes
        let o = frf(&exp_files(&out, 1), &est_path, &[]);
        let t = text(&o);
        assert!(o.status.success(), "{t}");
        assert!(t.contains("zippered"), "{t}");
        let est = Table::read(&est_path);
        assert_eq!(est.rows.len(), 100);
        let mc: Vec<usize> = AXES
            .iter()
            .map(|a| est.col(&format!("measured_{a}")))
            .collect();
        for r in &est.rows {
            // one measured column per line
            assert_eq!(mc.iter().map(|&c| r[c]).sum::<f64>(), 1.0);
        }
        let measured = |k: usize, j: usize| est.rows[k][mc[j]] == 1.0;
        for q in ["T_ry", "S"] {
            let (w, n) = worst(&est, &truth, q, Some(&measured));
            println!("zipper {speed} rpm {q} (measured entries): {w:.2e} over {n}");
            assert!(w <= 1e-6, "{q}: {w}");
            assert_eq!(n, 100 * 4);
        }
    }
}

/// Writes `text` to `dir/name`, returns its path.
fn put(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    s(&p).to_string()
}

/// A CSV text without column `drop`.
fn without_column(csv: &str, drop: &str) -> String {
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let k = head.iter().position(|h| *h == drop).unwrap();
    let mut out = String::new();
    for l in std::iter::once(head.join(",")).chain(lines.map(String::from)) {
        let f: Vec<&str> = l
            .split(',')
            .enumerate()
            .filter(|(j, _)| *j != k)
            .map(|x| x.1)
            .collect();
        out.push_str(&f.join(","));
        out.push('\n');
    }
    out
}

#[test]
fn bad_experiment_files_get_errors_naming_the_file_and_the_fix() {
    let d = tmpdir("machine-bad");
    let out = d.join("orth");
    simulate(&out, &["--design", "orthogonal"]);
    let f = exp_files(&out, 4);
    let est = d.join("frf.csv");
    let run = |files: &[String], extra: &[&str]| {
        let o = frf(files, &est, extra);
        assert!(!est.exists(), "nothing written on an error");
        (o.status.code().unwrap(), text(&o))
    };
    let exp2 = std::fs::read_to_string(&f[1]).unwrap();

    // different lengths
    let short: String = exp2
        .lines()
        .take(1 + 3 * 635 - 10)
        .map(|l| format!("{l}\n"))
        .collect();
    let p = put(&d, "short.csv", &short);
    let (c, t) = run(
        &[f[0].clone(), p.clone(), f[2].clone(), f[3].clone()],
        &["--period-samples", "635"],
    );
    assert_eq!(c, 3, "{t}");
    assert!(t.contains("short.csv") && t.contains("same length"), "{t}");

    // different sample rates (the t column)
    let mut slow = String::new();
    for (k, l) in exp2.lines().enumerate() {
        if k == 0 {
            slow.push_str(l);
        } else {
            let (tt, rest) = l.split_once(',').unwrap();
            slow.push_str(&format!("{:.17e},{rest}", 2.0 * tt.parse::<f64>().unwrap()));
        }
        slow.push('\n');
    }
    let p = put(&d, "slow.csv", &slow);
    let (c, t) = run(&[f[0].clone(), p, f[2].clone(), f[3].clone()], &[]);
    assert_eq!(c, 3, "{t}");
    assert!(
        t.contains("slow.csv is sampled at 10000 Hz") && t.contains("one sample rate"),
        "{t}"
    );

    // the same experiment twice: a singular input matrix
    let (c, t) = run(
        &[f[0].clone(), f[0].clone(), f[2].clone(), f[3].clone()],
        &[],
    );
    assert_ne!(c, 0, "{t}");
    assert!(
        t.contains("same excitation") && t.contains("singular"),
        "{t}"
    );
    assert!(t.contains("exp1/data.csv and"), "{t}");

    // a missing axis column
    let p = put(&d, "no_y_yb.csv", &without_column(&exp2, "y_yb"));
    let (c, t) = run(&[f[0].clone(), p, f[2].clone(), f[3].clone()], &[]);
    assert_eq!(c, 3, "{t}");
    assert!(
        t.contains("no_y_yb.csv: the column `y_yb` is missing"),
        "{t}"
    );

    // r count ≠ u count
    let p = put(
        &d,
        "no_r_yb.csv",
        &without_column(&std::fs::read_to_string(&f[0]).unwrap(), "r_yb"),
    );
    let (c, t) = run(&[p, f[1].clone(), f[2].clone(), f[3].clone()], &[]);
    assert_eq!(c, 3, "{t}");
    assert!(
        t.contains("`u_yb` has no excitation column `r_yb`")
            && t.contains("one `r_<axis>` per `u_<axis>`"),
        "{t}"
    );

    // fewer experiments than inputs
    let (c, t) = run(&f[..2], &[]);
    assert_eq!(c, 3, "{t}");
    assert!(
        t.contains("2 experiment files for 4 excited axes") && t.contains("give 4 files"),
        "{t}"
    );

    // NaN in a column
    let mut lines: Vec<String> = std::fs::read_to_string(&f[2])
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    let mut cells: Vec<String> = lines[5].split(',').map(String::from).collect();
    cells[10] = "NaN".into(); // y_xb
    lines[5] = cells.join(",");
    let p = put(&d, "nan.csv", &(lines.join("\n") + "\n"));
    let (c, t) = run(&[f[0].clone(), f[1].clone(), p, f[3].clone()], &[]);
    assert_eq!(c, 3, "{t}");
    assert!(t.contains("nan.csv") && t.contains("y_xb"), "{t}");

    // a non-periodic excitation without --period-samples
    let mut lines: Vec<String> = exp2.lines().map(String::from).collect();
    let mut x: u64 = 12345;
    for l in lines.iter_mut().skip(1) {
        let mut cells: Vec<String> = l.split(',').map(String::from).collect();
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        cells[2] = format!("{:.17e}", (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5); // r_xb
        *l = cells.join(",");
    }
    let p = put(&d, "random.csv", &(lines.join("\n") + "\n"));
    let (c, t) = run(&[f[0].clone(), p, f[2].clone(), f[3].clone()], &[]);
    assert_eq!(c, 3, "{t}");
    assert!(
        t.contains("not periodic") && t.contains("--period-samples"),
        "{t}"
    );

    // --axes 1 with several files; a single-axis option on the MIMO path
    let (c, t) = run(&f, &["--axes", "1"]);
    assert_eq!(c, 2, "{t}");
    assert!(t.contains("--axes 1 takes one data file"), "{t}");
    let (c, t) = run(&f, &["--method", "lrm"]);
    assert_eq!(c, 2, "{t}");
    assert!(
        t.contains("--method lrm is not available for a multi-axis FRF"),
        "{t}"
    );
    // the local polynomial method on a periodic record: pointed to the exact period average
    let (c, t) = run(&f, &["--method", "lpm"]);
    assert_ne!(c, 0, "{t}");
    assert!(t.contains("periodic") && t.contains("instead"), "{t}");
}

#[test]
fn simulate_axes_4_refuses_bad_options_and_never_half_writes() {
    let d = tmpdir("machine-sim-bad");
    let out = d.join("o");
    // 4-axis options without --axes 4, and single-axis options with it: usage errors
    for (args, msg) in [
        (
            vec!["simulate", "--speed-rpm", "100"],
            "--speed-rpm needs --axes 4",
        ),
        (
            vec!["simulate", "--design", "zipper"],
            "--design needs --axes 4",
        ),
        (
            vec!["simulate", "--axes", "4", "--record-b"],
            "--record-b is not available with --axes 4",
        ),
        (
            vec!["simulate", "--axes", "4", "--speed-rpm", "-5"],
            "--speed-rpm -5 must be finite and >= 0",
        ),
        (
            vec!["simulate", "--axes", "4", "--unbalance", "1e-3"],
            "two numbers",
        ),
        (
            vec!["simulate", "--axes", "4", "--asymmetry", "0.7,0"],
            "asymmetry.ki_rel",
        ),
        (vec!["simulate", "--axes", "2"], "--axes 2: give 1"),
    ] {
        let mut a = args.clone();
        a.extend_from_slice(&["--out", s(&out)]);
        let o = ambid(&a);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {t}");
        assert!(t.contains(msg), "{args:?}: {t}");
        assert!(!out.exists(), "{args:?} wrote something");
    }
    // a run that fails while simulating (touchdown at 100 % of i_sat on every axis, nonlinear)
    // leaves no file and no directory
    let o = ambid(&[
        "simulate",
        "--axes",
        "4",
        "--level",
        "100",
        "--design",
        "orthogonal",
        "--prbs-order",
        "7",
        "--periods",
        "2",
        "--out",
        s(&out),
    ]);
    assert_eq!(o.status.code(), Some(4), "{}", text(&o));
    assert!(
        text(&o).contains("touched down") && text(&o).contains("reduce"),
        "{}",
        text(&o)
    );
    assert!(!out.exists());
    // an existing output: refused before any work, nothing else written
    std::fs::create_dir_all(out.join("exp3")).unwrap();
    std::fs::write(out.join("exp3").join("data.csv"), "x\n1\n").unwrap();
    let args = [
        "simulate",
        "--axes",
        "4",
        "--mode",
        "linear",
        "--prbs-order",
        "7",
        "--periods",
        "2",
        "--out",
        s(&out),
    ];
    let o = ambid(&args);
    assert_ne!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("--force") || text(&o).contains("exists"),
        "{}",
        text(&o)
    );
    assert!(!out.join("exp1").exists() && !out.join("truth.csv").exists());
    assert_eq!(
        std::fs::read_to_string(out.join("exp3").join("data.csv")).unwrap(),
        "x\n1\n"
    );
    // with --force it is replaced, with the unbalance and asymmetry in meta.json
    let mut a = args.to_vec();
    a.extend_from_slice(&[
        "--force",
        "--unbalance",
        "2e-3,1e-3",
        "--asymmetry",
        "0.02,0.01",
        "--speed-rpm",
        "12000",
    ]);
    let o = ambid(&a);
    assert!(o.status.success(), "{}", text(&o));
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("meta.json")).unwrap()).unwrap();
    assert_eq!(meta["unbalance"]["mass_kg"].as_f64(), Some(2e-3));
    assert_eq!(meta["asymmetry"]["kx_rel"].as_f64(), Some(0.01));
    assert_eq!(meta["sync_hz"].as_f64(), Some(200.0));
    assert_eq!(
        Table::read(&out.join("exp3").join("data.csv")).rows.len(),
        2 * 635
    );
}

#[test]
fn random_rigs_lifted_to_the_whole_rotor_keep_the_frf_exact() {
    // the defaults (pre-roll, period detection, line matching) on rigs they were not tuned on
    let d = tmpdir("machine-rigs");
    for (seed, design) in [("3", "orthogonal"), ("11", "sequential")] {
        let out = d.join(format!("rig{seed}"));
        simulate(
            &out,
            &[
                "--rig-seed",
                seed,
                "--speed-rpm",
                "30000",
                "--design",
                design,
            ],
        );
        let est_path = out.join("frf.csv");
        let o = frf(&exp_files(&out, 4), &est_path, &["--skip-periods", "0"]);
        assert!(o.status.success(), "{}", text(&o));
        let (est, truth) = (Table::read(&est_path), Table::read(&out.join("truth.csv")));
        for q in ["P", "T_ry", "S"] {
            let (w, n) = worst(&est, &truth, q, None);
            println!("rig {seed} {design} {q}: {w:.2e} over {n}");
            assert!(w <= 1e-6, "rig {seed} {q}: {w}");
        }
    }
}

#[test]
fn experiment_files_in_another_dialect_without_time_column_give_the_same_frf() {
    // the one reader of every command: semicolon-delimited, a comment line, no `t` (--fs)
    let d = tmpdir("machine-dialect");
    let out = d.join("o");
    simulate(&out, &["--design", "orthogonal", "--speed-rpm", "20000"]);
    let files = exp_files(&out, 4);
    let mut other = Vec::new();
    for (k, f) in files.iter().enumerate() {
        let txt = std::fs::read_to_string(f).unwrap();
        let mut o = String::from("# experiment without a time column\n");
        for l in txt.lines() {
            o.push_str(&l.split(',').skip(1).collect::<Vec<_>>().join(";"));
            o.push('\n');
        }
        other.push(put(&d, &format!("e{k}.txt"), &o));
    }
    let (a, b) = (d.join("a.csv"), d.join("b.csv"));
    let o = frf(&files, &a, &[]);
    assert!(o.status.success(), "{}", text(&o));
    let o = frf(&other, &b, &["--fs", "20000", "--format", "csv"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("band: derived from the excitation"),
        "{}",
        text(&o)
    );
    let (ta, tb) = (Table::read(&a), Table::read(&b));
    assert_eq!(ta.names, tb.names);
    assert_eq!(ta.rows.len(), tb.rows.len());
    for (ra, rb) in ta.rows.iter().zip(&tb.rows) {
        for (x, y) in ra.iter().zip(rb) {
            assert!((x - y).abs() <= 1e-12 * x.abs().max(1e-300), "{x} vs {y}");
        }
    }
}

#[test]
fn an_unbalance_on_a_line_of_the_period_biases_that_line_only() {
    // PRBS order 7: 635 samples per period, lines 31.496 Hz apart; line 16 = 503.937 Hz
    let d = tmpdir("machine-unbalance");
    let df = 20_000.0 / 635.0;
    // between two lines: a warning naming the speeds that put the 1x line on a line
    let out = d.join("off");
    let mut a = vec![
        "simulate",
        "--axes",
        "4",
        "--mode",
        "linear",
        "--no-noise",
        "--prbs-order",
        "7",
    ];
    a.extend_from_slice(&[
        "--periods",
        "3",
        "--unbalance",
        "1e-3,1e-3",
        "--speed-rpm",
        "30000",
    ]);
    a.extend_from_slice(&["--design", "orthogonal", "--out", s(&out)]);
    let o = ambid(&a);
    assert!(o.status.success(), "{}", text(&o));
    let want = "(line 15) or 30236.22";
    assert!(
        text(&o).contains("falls between the lines") && text(&o).contains(want),
        "{}",
        text(&o)
    );
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("meta.json")).unwrap()).unwrap();
    assert!(meta["sync_line"].is_null());
    // on line 16: the FRF equals the truth on every other line, and is off on line 16
    let out = d.join("on");
    let speed = format!("{}", 16.0 * df * 60.0);
    simulate(
        &out,
        &[
            "--unbalance",
            "1e-3,1e-3",
            "--speed-rpm",
            &speed,
            "--design",
            "orthogonal",
        ],
    );
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("meta.json")).unwrap()).unwrap();
    assert_eq!(meta["sync_line"], 16);
    let est_path = out.join("frf.csv");
    let o = frf(&exp_files(&out, 4), &est_path, &[]);
    assert!(o.status.success(), "{}", text(&o));
    let (est, truth) = (Table::read(&est_path), Table::read(&out.join("truth.csv")));
    let sync = 16.0 * df;
    let k_sync = est
        .rows
        .iter()
        .position(|r| (r[0] - sync).abs() < 1e-6)
        .unwrap();
    let not_sync = |k: usize, _: usize| k != k_sync;
    for q in ["P", "T_ry", "S"] {
        let (w, n) = worst(&est, &truth, q, Some(&not_sync));
        println!("unbalance on line 16, {q} on the other lines: {w:.2e} over {n}");
        assert!(w <= 1e-6, "{q}: {w}");
        let only = |k: usize, _: usize| k == k_sync;
        let (w, _) = worst(&est, &truth, q, Some(&only));
        assert!(w > 1e-3, "{q} on the 1x line: {w}");
    }
}

/// `--speed-rpm` on an off-grid 1× line: the line is measured, written to `<out>_sync.csv`
/// (every u and y channel of every experiment) and taken out of u and y, and the FRF is then
/// exact on every line; without it the 1× line leaks into the period means. On an excited
/// period line the 1× line cannot be separated: a clear error.
#[test]
fn speed_rpm_reports_the_synchronous_line_and_keeps_the_frf_exact() {
    let d = tmpdir("machine-sync");
    let out = d.join("off");
    simulate(
        &out,
        &[
            "--unbalance",
            "1e-3,1e-3",
            "--speed-rpm",
            "30000",
            "--design",
            "orthogonal",
        ],
    );
    let truth = Table::read(&out.join("truth.csv"));
    let raw = out.join("raw.csv");
    let o = frf(&exp_files(&out, 4), &raw, &[]);
    assert!(o.status.success(), "{}", text(&o));
    let (w_raw, _) = worst(&Table::read(&raw), &truth, "P", None);
    let est_path = out.join("frf.csv");
    let o = frf(&exp_files(&out, 4), &est_path, &["--speed-rpm", "30000"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("removed from u and y"), "{}", text(&o));
    let est = Table::read(&est_path);
    let (w, n) = worst(&est, &truth, "P", None);
    println!("off-grid 1x line: P error {w_raw:.2e} as recorded, {w:.2e} after --speed-rpm ({n} entries)");
    assert!(w <= 1e-6, "{w}");
    assert!(w_raw > 1e-3, "{w_raw}");
    let sync = Table::read_mixed(&out.join("frf_sync.csv"));
    assert_eq!(sync.len(), 4 * 8);
    assert!(sync.iter().all(|r| (r.1 - 500.0).abs() < 1e-9 && r.2 > 0.0));
    // on an excited line (line 16 of the PRBS period): refused, nothing written
    let df = 20_000.0 / 635.0;
    let speed = format!("{}", 16.0 * df * 60.0);
    let on = d.join("on");
    simulate(&on, &["--unbalance", "1e-3,1e-3", "--speed-rpm", &speed]);
    let p = on.join("frf.csv");
    let o = frf(&exp_files(&on, 4), &p, &["--speed-rpm", &speed]);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("cannot be separated"), "{}", text(&o));
    assert!(!p.exists() && !on.join("frf_sync.csv").exists());
}

/// A non-periodic record (four independent white noises at the controller outputs, one
/// experiment) through `ambid frf --method lpm`: the multivariable local polynomial method,
/// against the twin's exact plant (independent of the CLI). Noise off, so the error is the
/// local polynomial's bias.
#[test]
fn lpm_on_a_non_periodic_record_follows_the_exact_plant() {
    let m = Machine::new(MachineConfig {
        speed_rpm: 15_000.0,
        ..MachineConfig::default()
    })
    .unwrap();
    let len = 16_384;
    // a seeded 64-bit LCG's top 53 bits: uniform in [-1, 1)
    let mut x: u64 = 9;
    let mut uniform = || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        2.0 * ((x >> 11) as f64 / (1u64 << 53) as f64) - 1.0
    };
    let amp = 0.02 * m.i_sat();
    let r: Vec<Vec<f64>> = (0..4)
        .map(|_| (0..len).map(|_| amp * uniform()).collect())
        .collect();
    let rec = m
        .simulate(
            [&r[0], &r[1], &r[2], &r[3]],
            &ambid_twin::MachineSimOptions {
                mode: ambid_twin::Mode::Linear,
                noise: false,
                ..ambid_twin::MachineSimOptions::default()
            },
        )
        .unwrap()
        .to_iodata(None)
        .unwrap();
    let d = tmpdir("machine-lpm");
    let names: Vec<String> = ["r", "u", "y"]
        .iter()
        .flat_map(|q| AXES.iter().map(move |a| format!("{q}_{a}")))
        .collect();
    let cols: Vec<&[f64]> = names.iter().map(|n| rec.channel(n).unwrap()).collect();
    let mut csv = format!("t,{}\n", names.join(","));
    for t in 0..len {
        csv.push_str(&format!("{:e}", t as f64 * m.ts()));
        for c in &cols {
            csv.push_str(&format!(",{:e}", c[t]));
        }
        csv.push('\n');
    }
    let data = put(&d, "noise.csv", &csv);
    // without --method lpm the non-periodic record is refused, pointing to it
    let p = d.join("frf.csv");
    let o = frf(std::slice::from_ref(&data), &p, &[]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    assert!(text(&o).contains("--method lpm"), "{}", text(&o));
    let o = frf(&[data], &p, &["--method", "lpm", "--band", "20:1000"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("local polynomial method"), "{}", text(&o));
    let est = Table::read(&p);
    let f: Vec<f64> = est.rows.iter().map(|r| r[0]).collect();
    assert!(f.len() > 700 && f[0] >= 20.0 && *f.last().unwrap() <= 1000.0);
    let truth = m.plant_frf(&f).unwrap();
    let mut errs = Vec::new();
    for (k, _) in f.iter().enumerate() {
        let t = truth.at(k).unwrap();
        let scale = (0..4)
            .flat_map(|i| (0..4).map(move |j| (i, j)))
            .fold(0.0f64, |acc, (i, j)| acc.max(t[(i, j)].norm()));
        for (a, o) in AXES.iter().enumerate() {
            for (b, i) in AXES.iter().enumerate() {
                let e = est.c(k, "P", o, i);
                let tv = Complex64::new(t[(a, b)].re, t[(a, b)].im);
                errs.push((e - tv).norm() / scale);
            }
        }
    }
    errs.sort_by(f64::total_cmp);
    let (med, p95) = (errs[errs.len() / 2], errs[errs.len() * 95 / 100]);
    println!("LPM, noise-free, 20-1000 Hz: P error median {med:.2e}, 95th percentile {p95:.2e}");
    assert!(med < 1e-4 && p95 < 1e-2, "{med} {p95}");
}
