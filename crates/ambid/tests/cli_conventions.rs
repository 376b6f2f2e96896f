//! One set of command-line conventions across every command (issue 18, docs/conventions.md,
//! "Command line"): the excitation level in % of i_sat, the band as `f_min:f_max`, one meaning
//! per column option. For every command that takes one of them, the new and the deprecated
//! spellings give the same files, the deprecated one prints a `note:` naming the new spelling,
//! and a malformed value exits with code 2 and a message naming the option. The levels are also
//! checked against an independent value: the twin's i_sat (2 A, `ambid config`) times the level.

use crate::common::{ambid, s, text, tmpdir, CONTROLLER};
use std::path::{Path, PathBuf};
use std::process::Output;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Runs `args`, asserts success and returns the output.
fn ok(args: &[&str]) -> Output {
    let o = ambid(args);
    assert!(o.status.success(), "{args:?}: {}", text(&o));
    o
}

/// Asserts that `args` exits with code 2 and a message naming `option`.
fn usage_error(args: &[&str], option: &str) {
    let o = ambid(args);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o));
    assert!(stderr(&o).contains(option), "{args:?}: {}", text(&o));
}

/// Asserts the deprecation note for `old` naming `new`, and none for the new spelling.
fn noted(old: &Output, new: &Output, naming: &str) {
    let e = stderr(old);
    assert!(
        e.contains("note:") && e.contains("deprecated") && e.contains(naming),
        "{e}"
    );
    assert!(!stderr(new).contains("deprecated"), "{}", stderr(new));
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Column `name` of a CSV file.
fn column(p: &Path, name: &str) -> Vec<f64> {
    let mut r = csv::Reader::from_path(p).unwrap();
    let k = r.headers().unwrap().iter().position(|h| h == name).unwrap();
    r.records()
        .map(|rec| rec.unwrap()[k].parse().unwrap())
        .collect()
}

/// The twin's saturation current, from `ambid config` (the independent reference of a level).
fn twin_i_sat() -> f64 {
    let o = ok(&["config"]);
    let cfg: toml::Value = toml::from_str(&String::from_utf8_lossy(&o.stdout)).unwrap();
    cfg["magnet"]["i_sat_a"].as_float().unwrap()
}

/// A short linear twin record (PRBS n = 8, 3 periods of 1275 samples) at `level_args`.
fn simulate(dir: &Path, level_args: &[&str]) -> Output {
    let mut args = vec![
        "simulate",
        "--mode",
        "linear",
        "--prbs-order",
        "8",
        "--periods",
        "3",
        "--out",
        s(dir),
    ];
    args.extend_from_slice(level_args);
    ok(&args)
}

#[test]
fn simulate_level_in_percent_of_i_sat() {
    let d = tmpdir("conv-sim");
    let new = simulate(&d.join("new"), &["--level", "12"]);
    let _pct = simulate(&d.join("pct"), &["--level", "12%"]);
    let old = simulate(&d.join("old"), &["--amplitude", "0.12"]);
    noted(&old, &new, "--level 12");
    let data = read(&d.join("new/data.csv"));
    assert_eq!(data, read(&d.join("pct/data.csv")));
    assert_eq!(data, read(&d.join("old/data.csv")));
    // the PRBS is ±12 % of i_sat
    let r = column(&d.join("new/data.csv"), "r");
    let want = 0.12 * twin_i_sat();
    assert!(r.iter().all(|v| (v.abs() - want).abs() < 1e-12), "{want}");
    let out = String::from_utf8_lossy(&new.stdout).into_owned();
    assert!(
        out.contains("peak 12.000 % / RMS 12.000 % of i_sat"),
        "{out}"
    );
    // the band: new and old spellings (a noise record, where the band shapes r)
    let band = |dir: &str, extra: &[&str]| {
        let mut a = vec!["--signal", "noise"];
        a.extend_from_slice(extra);
        simulate(&d.join(dir), &a)
    };
    let bn = band("bn", &["--band", "20:800"]);
    let bo = band("bo", &["--f-min", "20", "--f-max", "800"]);
    let bc = band("bc", &["--band", "20,800"]);
    noted(&bo, &bn, "--band 20:800");
    noted(&bc, &bn, "`20:800`");
    let data = read(&d.join("bn/data.csv"));
    assert_eq!(data, read(&d.join("bo/data.csv")));
    assert_eq!(data, read(&d.join("bc/data.csv")));
    for bad in ["abc", "0", "120", "-5"] {
        usage_error(
            &["simulate", "--level", bad, "--out", s(&d.join("x"))],
            "--level",
        );
    }
    usage_error(
        &["simulate", "--band", "800:20", "--out", s(&d.join("x"))],
        "--band",
    );
    usage_error(
        &["simulate", "--band", "20-800", "--out", s(&d.join("x"))],
        "--band",
    );
    assert!(!d.join("x").exists());
}

#[test]
fn excite_level_and_band() {
    let d = tmpdir("conv-excite");
    let i_sat = twin_i_sat();
    let run = |name: &str, args: &[&str]| -> (Output, PathBuf) {
        let p = d.join(format!("{name}.csv"));
        let mut a = vec!["excite"];
        a.extend_from_slice(args);
        a.extend_from_slice(&["--out", s(&p)]);
        (ok(&a), p)
    };
    // PRBS: peak level
    let (n, pn) = run(
        "prbs_new",
        &[
            "prbs",
            "--prbs-order",
            "8",
            "--periods",
            "1",
            "--level",
            "10",
        ],
    );
    let (_, pa) = run(
        "prbs_amps",
        &[
            "prbs",
            "--prbs-order",
            "8",
            "--periods",
            "1",
            "--level",
            "0.2A",
        ],
    );
    let (o, po) = run(
        "prbs_old",
        &[
            "prbs",
            "--order",
            "8",
            "--periods",
            "1",
            "--amplitude",
            "0.2",
        ],
    );
    noted(&o, &n, "--level 10%");
    assert_eq!(read(&pn), read(&pa));
    assert_eq!(read(&pn), read(&po));
    let r = column(&pn, "r");
    assert!(r.iter().all(|v| (v.abs() - 0.1 * i_sat).abs() < 1e-12));
    // noise: RMS level and the band
    let noise = ["noise", "--samples", "4096"];
    let (n, p1) = run(
        "noise_new",
        &[&noise[..], &["--level", "5", "--band", "10:1000"]].concat(),
    );
    let (o2, p2) = run(
        "noise_old",
        &[
            &noise[..],
            &["--rms", "0.1", "--band-lo", "10", "--band-hi", "1000"],
        ]
        .concat(),
    );
    let (o3, p3) = run(
        "noise_comma",
        &[&noise[..], &["--level", "5%", "--band", "10,1000"]].concat(),
    );
    noted(&o2, &n, "--band 10:1000");
    noted(&o2, &n, "--level 5%");
    noted(&o3, &n, "`10:1000`");
    assert_eq!(read(&p1), read(&p2));
    assert_eq!(read(&p1), read(&p3));
    let r = column(&p1, "r");
    let rms = (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt();
    assert!((rms - 0.05 * i_sat).abs() < 1e-9 * i_sat, "rms {rms}");
    // multisine: RMS level and the band of its lines
    let ms = ["multisine", "--period-samples", "2000", "--periods", "1"];
    let (n, m1) = run(
        "ms_new",
        &[&ms[..], &["--band", "50:500", "--level", "5"]].concat(),
    );
    let (o, m2) = run(
        "ms_old",
        &[
            &ms[..],
            &["--f-min", "50", "--f-max", "500", "--rms", "0.1"],
        ]
        .concat(),
    );
    noted(&o, &n, "--band 50:500");
    assert_eq!(read(&m1), read(&m2));
    // malformed values name the option; a band on a PRBS is refused
    usage_error(&["excite", "prbs", "--level", "ten"], "--level");
    usage_error(&["excite", "noise", "--band", "1000:10"], "--band");
    usage_error(&["excite", "prbs", "--band", "10:1000"], "--band");
    usage_error(
        &["excite", "prbs", "--level", "10", "--amplitude", "0.2"],
        "--level",
    );
}

#[test]
fn compare_level_in_percent_of_i_sat() {
    let d = tmpdir("conv-compare");
    let i_sat = twin_i_sat();
    let a = d.join("a");
    let b = d.join("b");
    let na = ok(&["compare", "--level", "5", "--max-lag", "10", "--out", s(&a)]);
    ok(&[
        "compare",
        "--level",
        "0.1A",
        "--max-lag",
        "10",
        "--out",
        s(&b),
    ]);
    assert!(!stderr(&na).contains("note"), "{}", stderr(&na));
    assert_eq!(
        read(&a.join("comparison.json")),
        read(&b.join("comparison.json"))
    );
    let rep: serde_json::Value = serde_json::from_str(&read(&a.join("comparison.json"))).unwrap();
    for sig in ["prbs", "chirp", "noise", "multisine"] {
        let rms = rep[sig]["rms"].as_f64().unwrap();
        assert!((rms - 0.05 * i_sat).abs() < 1e-3 * i_sat, "{sig}: {rms}");
    }
    // a bare value below 1 (amperes before) is read as % with a note
    let c = d.join("c");
    let o = ok(&[
        "compare",
        "--level",
        "0.5",
        "--max-lag",
        "10",
        "--out",
        s(&c),
    ]);
    assert!(stderr(&o).contains("0.5A"), "{}", stderr(&o));
    usage_error(
        &["compare", "--level", "5x", "--out", s(&d.join("x"))],
        "--level",
    );
}

#[test]
fn study_and_bla_levels_and_bands() {
    let d = tmpdir("conv-study");
    // the default levels print without binary noise
    let h = String::from_utf8_lossy(&ok(&["study", "amplitude", "--help"]).stdout).into_owned();
    assert!(h.contains("14") && !h.contains("000000000"), "{h}");
    let study = |name: &str, extra: &[&str]| -> (Output, String) {
        let out = d.join(format!("{name}.csv"));
        let mut a = vec![
            "study",
            "amplitude",
            "--mode",
            "linear",
            "--periods",
            "3",
            "--out",
            s(&out),
        ];
        a.extend_from_slice(extra);
        let o = ok(&a);
        (o, read(&out))
    };
    let (n, c1) = study("new", &["--levels", "4,8", "--band", "10:1000"]);
    let (o, c2) = study("old", &["--levels", "4%,8%", "--band", "10,1000"]);
    noted(&o, &n, "`10:1000`");
    assert_eq!(c1, c2);
    let out = String::from_utf8_lossy(&n.stdout).into_owned();
    assert!(!out.contains("000000000"), "{out}");
    usage_error(&["study", "amplitude", "--levels", "4,x"], "--levels");
    usage_error(&["study", "amplitude", "--band", "10"], "--band");
    // operating point: --level (%) against the deprecated --amplitude (fraction)
    let op = |name: &str, level: &[&str]| -> (Output, String) {
        let out = d.join(format!("op_{name}.csv"));
        let frf = d.join(format!("opf_{name}.csv"));
        let mut a = vec![
            "study",
            "operating-point",
            "--mode",
            "linear",
            "--band",
            "10:1000",
            "--out",
            s(&out),
            "--frf-out",
            s(&frf),
        ];
        a.extend_from_slice(level);
        let o = ok(&a);
        (o, read(&out) + &read(&frf))
    };
    let (n, p1) = op("new", &["--level", "12%"]);
    let (o, p2) = op("old", &["--amplitude", "0.12"]);
    noted(&o, &n, "--level 12");
    assert_eq!(p1, p2);
    usage_error(&["study", "operating-point", "--level", "200"], "--level");
    // BLA: the band of the averages
    let bla = |name: &str, band: &str| -> (Output, String) {
        let out = d.join(format!("bla_{name}.csv"));
        let o = ok(&[
            "bla",
            "--levels",
            "4,8",
            "--realisations",
            "2",
            "--periods",
            "2",
            "--mode",
            "linear",
            "--band",
            band,
            "--out",
            s(&out),
        ]);
        (o, read(&out))
    };
    let (n, b1) = bla("new", "20:1000");
    let (o, b2) = bla("old", "20,1000");
    noted(&o, &n, "`20:1000`");
    assert_eq!(b1, b2);
    usage_error(&["bla", "--level", "0"], "--level");
    usage_error(&["bla", "--band", "x:1000"], "--band");
}

#[test]
fn frf_fit_compare_models_and_validate_options() {
    let d = tmpdir("conv-frf");
    simulate(&d.join("id"), &[]);
    simulate(&d.join("va"), &["--seed", "2", "--level", "12"]);
    let data = d.join("id/data.csv");
    let frf = |name: &str, extra: &[&str]| -> (Output, PathBuf) {
        let out = d.join(format!("{name}.csv"));
        let mut a = vec![
            "frf",
            s(&data),
            "--period-samples",
            "1275",
            "--current",
            "i",
            "--out",
            s(&out),
        ];
        a.extend_from_slice(extra);
        (ok(&a), out)
    };
    let (n, f1) = frf(
        "frf_new",
        &["--band", "10:1000", "--quality-band", "20:800"],
    );
    let (o, f2) = frf(
        "frf_old",
        &["--band", "10,1000", "--quality-band", "20,800"],
    );
    noted(&o, &n, "`10:1000`");
    noted(&o, &n, "`20:800`");
    assert_eq!(read(&f1), read(&f2));
    let f = column(&f1, "f_hz");
    assert!(f[0] >= 10.0 && *f.last().unwrap() <= 1000.0, "{f:?}");
    usage_error(&["frf", s(&data), "--band", "10"], "--band");
    usage_error(
        &["frf", s(&data), "--quality-band", "1:x"],
        "--quality-band",
    );
    // fit to the FRF and compare-models: the band
    let fit = |name: &str, band: &str| -> (Output, String) {
        let out = d.join(format!("{name}.json"));
        let o = ok(&[
            "fit",
            s(&f1),
            "--quantity",
            "plant",
            "--structure",
            "arx",
            "--order",
            "4",
            "--band",
            band,
            "--out",
            s(&out),
        ]);
        (o, read(&out))
    };
    let (n, m1) = fit("fit_new", "20:800");
    let (o, m2) = fit("fit_old", "20,800");
    noted(&o, &n, "`20:800`");
    assert_eq!(m1, m2);
    let cm = |name: &str, band: &str| -> (Output, String) {
        let out = d.join(format!("{name}.csv"));
        let o = ok(&[
            "compare-models",
            s(&f1),
            "--structures",
            "arx",
            "--orders",
            "4",
            "--band",
            band,
            "--out",
            s(&out),
        ]);
        (o, read(&out))
    };
    let (n, c1) = cm("cm_new", "20:800");
    let (o, c2) = cm("cm_old", "20,800");
    noted(&o, &n, "`20:800`");
    assert_eq!(c1, c2);
    usage_error(&["compare-models", s(&f1), "--band", "800:20"], "--band");
    // validate: --input names the controller output u (as in frf and fit); --current was its
    // old name there
    let model = d.join("arx.json");
    ok(&[
        "fit",
        s(&data),
        "--structure",
        "arx",
        "--na",
        "4",
        "--nb",
        "4",
        "--out",
        s(&model),
    ]);
    let va = d.join("va/data.csv");
    let val = |name: &str, col: &[&str]| -> (Output, String) {
        let out = d.join(name);
        let mut a = vec![
            "validate",
            s(&model),
            "--data",
            s(&va),
            "--controller",
            CONTROLLER,
            "--out",
            s(&out),
        ];
        a.extend_from_slice(col);
        let o = ok(&a);
        (o, read(&out.join("timeseries.csv")))
    };
    let (n, v1) = val("val_new", &["--input", "u"]);
    let (o, v2) = val("val_old", &["--current", "u"]);
    let (_, v3) = val("val_default", &[]);
    noted(&o, &n, "--input u");
    assert_eq!(v1, v2);
    assert_eq!(v1, v3);
}

#[test]
fn fit_prints_named_parameters_and_iteration_limits() {
    let d = tmpdir("conv-fit");
    simulate(&d.join("id"), &[]);
    let data = d.join("id/data.csv");
    let out = d.join("oe.json");
    let o = ok(&[
        "fit",
        s(&data),
        "--structure",
        "oe",
        "--nb",
        "2",
        "--nf",
        "2",
        "--nk",
        "1",
        "--max-iterations",
        "1",
        "--loop",
        "open",
        "--out",
        s(&out),
    ]);
    let t = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(!t.contains("θ["), "{t}");
    // the printed b1, b2, f1, f2 are the written model's B and F coefficients
    let m: serde_json::Value = serde_json::from_str(&read(&out)).unwrap();
    let coef = |k: &str, j: usize| m[k][j].as_f64().unwrap();
    for (name, want) in [
        ("b1", coef("b", 1)),
        ("b2", coef("b", 2)),
        ("f1", coef("f", 1)),
        ("f2", coef("f", 2)),
    ] {
        let line = t
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{name} ")))
            .unwrap_or_else(|| panic!("no {name} in {t}"));
        let v: f64 = line
            .split('=')
            .nth(1)
            .unwrap()
            .split('±')
            .next()
            .unwrap()
            .trim()
            .parse()
            .unwrap();
        assert!(
            (v - want).abs() <= 1e-6 * want.abs().max(1e-300),
            "{name}: {v} vs {want}"
        );
        assert!(line.contains('±'), "{line}");
    }
    assert_eq!(
        m["meta"]["param_names"],
        serde_json::json!(["b1", "b2", "f1", "f2"])
    );
    // one iteration does not converge: a warning naming the option that raises the budget
    assert!(
        t.contains("warning:") && t.contains("raise --max-iterations"),
        "{t}"
    );
}

/// `run --steps models` runs the `frf` step it reads (and says so), so the models are fitted to
/// the FRF as in the full run — the issue measured 94.5 s for the silent time-domain fallback —
/// and the chosen model is close to the twin's exact plant.
#[test]
fn run_steps_pull_in_their_prerequisites() {
    let d = tmpdir("conv-run");
    let out = d.join("rep");
    let o = ok(&["run", "--steps", "models", "--out", s(&out)]);
    assert!(
        stderr(&o).contains("also running `frf` (`models` uses its results)"),
        "{}",
        stderr(&o)
    );
    let sum: serde_json::Value = serde_json::from_str(&read(&out.join("summary.json"))).unwrap();
    assert_eq!(sum["models"]["domain"], "frf", "{}", sum["models"]);
    assert!(sum["frf"].is_object(), "the frf step ran");
    let err = sum["models"]["chosen_error_vs_truth_pct"].as_f64().unwrap();
    assert!(err < 10.0, "chosen model {err} % from the truth");
    // an unknown step is still a usage error naming --steps
    usage_error(
        &["run", "--steps", "modles", "--out", s(&d.join("x"))],
        "--steps",
    );
}

/// The level is relative to each rig's own i_sat: on 20 random rigs (`--rig-seed 1…20`, noise
/// seeds 101…120, whose i_sat is drawn at 80–100 % of the bias current) `simulate --level 10`
/// injects a PRBS of ±10 % of that rig's `magnet.i_sat_a` (read back with `ambid config
/// --rig-seed N`), and says so.
#[test]
fn simulate_level_follows_each_rigs_i_sat() {
    let d = tmpdir("conv-rigs");
    let mut seen = Vec::new();
    for rig in 1..=20u64 {
        let (rs, ns) = (rig.to_string(), (100 + rig).to_string());
        let cfg = ok(&["config", "--rig-seed", &rs]);
        let cfg: toml::Value = toml::from_str(&String::from_utf8_lossy(&cfg.stdout)).unwrap();
        let i_sat = cfg["magnet"]["i_sat_a"].as_float().unwrap();
        let dir = d.join(format!("rig{rig}"));
        let o = ok(&[
            "simulate",
            "--rig-seed",
            &rs,
            "--seed",
            &ns,
            "--mode",
            "linear",
            "--prbs-order",
            "6",
            "--periods",
            "2",
            "--level",
            "10",
            "--out",
            s(&dir),
        ]);
        let r = column(&dir.join("data.csv"), "r");
        assert!(
            r.iter()
                .all(|v| (v.abs() - 0.1 * i_sat).abs() < 1e-12 * i_sat),
            "rig {rig}: i_sat {i_sat}"
        );
        assert!(
            String::from_utf8_lossy(&o.stdout).contains("peak 10.000 % / RMS 10.000 % of i_sat"),
            "rig {rig}: {}",
            text(&o)
        );
        seen.push(i_sat);
    }
    // the rigs do differ in i_sat (else the test would not tell % of i_sat from a fixed 0.2 A)
    let (lo, hi) = seen
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, h), v| (l.min(*v), h.max(*v)));
    assert!(hi / lo > 1.1, "i_sat {lo} … {hi}");
}

/// `--order` is a model order (`fit`), `--excitation` a column (r): the PRBS register order is
/// `--prbs-order` and the twin's signal `--signal`; the old spellings in `simulate` and
/// `excite prbs` still work, with a note, and give the same files.
#[test]
fn prbs_order_and_signal_names() {
    let d = tmpdir("conv-names");
    let new = ok(&[
        "simulate",
        "--mode",
        "linear",
        "--signal",
        "prbs",
        "--prbs-order",
        "7",
        "--periods",
        "2",
        "--out",
        s(&d.join("new")),
    ]);
    let old = ok(&[
        "simulate",
        "--mode",
        "linear",
        "--excitation",
        "prbs",
        "--order",
        "7",
        "--periods",
        "2",
        "--out",
        s(&d.join("old")),
    ]);
    noted(&old, &new, "--prbs-order 7");
    noted(&old, &new, "--signal prbs");
    let data = read(&d.join("new/data.csv"));
    assert_eq!(data, read(&d.join("old/data.csv")));
    // 2 periods of 2^7 − 1 = 127 bits × 5 samples
    assert_eq!(data.lines().count(), 1 + 2 * 127 * 5);
    let (pn, po) = (d.join("pn.csv"), d.join("po.csv"));
    let n = ok(&[
        "excite",
        "prbs",
        "--prbs-order",
        "6",
        "--periods",
        "1",
        "--out",
        s(&pn),
    ]);
    let o = ok(&[
        "excite",
        "prbs",
        "--order",
        "6",
        "--periods",
        "1",
        "--out",
        s(&po),
    ]);
    noted(&o, &n, "--prbs-order 6");
    assert_eq!(read(&pn), read(&po));
    assert_eq!(read(&pn).lines().count(), 1 + 63 * 5);
    usage_error(
        &["simulate", "--prbs-order", "x", "--out", s(&d.join("x"))],
        "--prbs-order",
    );
    usage_error(
        &["simulate", "--signal", "sine", "--out", s(&d.join("x"))],
        "--signal",
    );
}
