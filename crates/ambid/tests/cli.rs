//! End-to-end tests of the `ambid` binary: exit codes, messages and written files.

use crate::common::{ambid, text, tmpdir};
use std::path::PathBuf;

#[test]
fn no_arguments_prints_help_and_fails() {
    let o = ambid(&[]);
    assert!(!o.status.success());
    let t = text(&o);
    assert!(t.contains("simulate") && t.contains("excite"), "{t}");
}

#[test]
fn excite_prbs_reports_the_seed_experiment() {
    let d = tmpdir("prbs");
    let out = d.join("r.csv");
    let o = ambid(&[
        "excite",
        "prbs",
        "--order",
        "10",
        "--samples-per-bit",
        "5",
        "--periods",
        "20",
        "--amplitude",
        "0.2",
        "--json",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rep: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(rep["period_samples"], 5115);
    assert!((rep["resolution_hz"].as_f64().unwrap() - 3.9101).abs() < 1e-3);
    assert!((rep["duration_s"].as_f64().unwrap() - 5.115).abs() < 1e-9);
    let csv = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "t,r");
    assert_eq!(lines.len(), 1 + 20 * 5115);
    // two-valued ±0.2
    for l in &lines[1..200] {
        let v: f64 = l.split(',').nth(1).unwrap().parse().unwrap();
        assert!((v.abs() - 0.2).abs() < 1e-15, "{v}");
    }
}

#[test]
fn bad_inputs_exit_nonzero_with_a_message() {
    let cases: &[(&[&str], &str)] = &[
        (&["excite", "prbs", "--order", "40"], "order"),
        (&["excite", "prbs", "--order", "1"], "order"),
        (&["excite", "chirp", "--amplitude", "-1"], "amplitude"),
        (&["excite", "prbs", "--amplitude", "nan"], "amplitude"),
        (&["simulate", "--amplitude", "-0.1"], "amplitude"),
        (&["simulate", "--amplitude", "inf"], "amplitude"),
        (&["simulate", "--bias", "-1"], "bias"),
        (&["simulate", "--frobnicate"], "--frobnicate"),
        (&["simulate", "--mode", "quadratic"], "quadratic"),
        (
            &["simulate", "--config", "/nonexistent/twin.toml"],
            "cannot read",
        ),
    ];
    for (args, needle) in cases {
        let o = ambid(args);
        let t = text(&o);
        assert!(!o.status.success(), "{args:?} should fail: {t}");
        assert!(
            t.to_lowercase().contains(&needle.to_lowercase()),
            "{args:?}: message should mention `{needle}`: {t}"
        );
    }
}

#[test]
fn malformed_or_unstable_config_is_rejected() {
    let d = tmpdir("cfg");
    let bad = d.join("bad.toml");
    std::fs::write(&bad, "[rotor]\nmass = \"heavy\"\n").unwrap();
    let o = ambid(&[
        "simulate",
        "--config",
        bad.to_str().unwrap(),
        "--out",
        d.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let unknown = d.join("unknown.toml");
    std::fs::write(&unknown, "[rotor]\nmasss = 5.0\n").unwrap();
    let o = ambid(&["simulate", "--config", unknown.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(text(&o).contains("masss"), "{}", text(&o));
    // too little proportional gain: the negative magnetic stiffness wins, the loop is unstable
    let weak = d.join("weak.toml");
    std::fs::write(&weak, "[controller]\nkp = 3000.0\n").unwrap();
    for cmd in ["simulate", "info"] {
        let o = ambid(&[cmd, "--config", weak.to_str().unwrap()]);
        assert!(!o.status.success());
        assert!(text(&o).to_lowercase().contains("unstable"), "{}", text(&o));
    }
}

#[test]
fn config_round_trips_through_simulate() {
    let d = tmpdir("roundtrip");
    let o = ambid(&["config"]);
    assert!(o.status.success(), "{}", text(&o));
    let cfg = d.join("twin.toml");
    std::fs::write(&cfg, &o.stdout).unwrap();
    let o = ambid(&[
        "simulate",
        "--config",
        cfg.to_str().unwrap(),
        "--periods",
        "2",
        "--mode",
        "linear",
        "--truth-points",
        "20",
        "--out",
        d.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn simulate_with_defaults_writes_data_truth_and_meta() {
    let d = tmpdir("sim");
    let o = ambid(&["simulate", "--periods", "3", "--out", d.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let data = std::fs::read_to_string(d.join("data.csv")).unwrap();
    let mut lines = data.lines();
    assert_eq!(lines.next().unwrap(), "t,w,r,u,i,y");
    assert_eq!(lines.count(), 3 * 5115);
    let truth = std::fs::read_to_string(d.join("truth.csv")).unwrap();
    assert!(truth.lines().next().unwrap().starts_with(
        "f_hz,plant_re,plant_im,plant_std,t_ry_re,t_ry_im,t_ry_std,t_ru_re,t_ru_im,t_ru_std,controller_re"
    ));
    assert_eq!(truth.lines().count(), 401);
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("meta.json")).unwrap()).unwrap();
    assert!(meta["simulation"]["saturated_fraction"].as_f64().is_some());
}

#[test]
fn large_excitation_warns_about_saturation_or_stops_at_touchdown() {
    let d = tmpdir("sat");
    // high-frequency multisine at 90 % of i_sat: the rotor barely moves, the amplifier slews
    let o = ambid(&[
        "simulate",
        "--excitation",
        "multisine",
        "--f-min",
        "1500",
        "--f-max",
        "3000",
        "--amplitude",
        "0.9",
        "--periods",
        "2",
        "--period",
        "0.05",
        "--out",
        d.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("warning") && err.contains("saturated"),
        "{err}"
    );
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("meta.json")).unwrap()).unwrap();
    assert!(meta["simulation"]["saturated_fraction"].as_f64().unwrap() > 0.1);
    // a 90 % PRBS pushes the rotor into the magnet: a clear error, non-zero exit
    let o = ambid(&[
        "simulate",
        "--amplitude",
        "0.9",
        "--periods",
        "2",
        "--out",
        d.to_str().unwrap(),
        "--force",
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("touched down"), "{}", text(&o));
}

#[test]
fn excite_writes_spectrum_and_autocorrelation_of_one_period() {
    let d = tmpdir("analysis");
    let (s, a) = (d.join("s.csv"), d.join("a.csv"));
    let o = ambid(&[
        "excite",
        "prbs",
        "--order",
        "7",
        "--samples-per-bit",
        "1",
        "--periods",
        "3",
        "--amplitude",
        "1",
        "--spectrum",
        s.to_str().unwrap(),
        "--autocorr",
        a.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let col = |p: &PathBuf| -> Vec<f64> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
            .collect()
    };
    // Nb = 1: flat line spectrum |X_k| = sqrt(L+1)/L·2 (one-sided), DC = 1/L
    let (amp, l) = (col(&s), 127.0);
    assert_eq!(amp.len(), 64);
    assert!((amp[0] - 1.0 / l).abs() < 1e-12);
    for v in &amp[1..] {
        assert!((v - 2.0 * (l + 1.0f64).sqrt() / l).abs() < 1e-12, "{v}");
    }
    // circular autocorrelation: 1 at lag 0, −1/L elsewhere
    let rho = col(&a);
    assert!((rho[0] - 1.0).abs() < 1e-12);
    for v in &rho[1..] {
        assert!((v + 1.0 / l).abs() < 1e-12, "{v}");
    }
}

#[test]
fn compare_writes_the_four_signals_side_by_side() {
    let d = tmpdir("compare");
    // 10 % of the default i_sat = 2 A (the level is in % of i_sat since issue 18)
    let o = ambid(&["compare", "--level", "10", "--out", d.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    for f in ["waveforms.csv", "spectra.csv", "autocorr.csv"] {
        let s = std::fs::read_to_string(d.join(f)).unwrap();
        let header = s.lines().next().unwrap();
        assert!(
            header.ends_with(",prbs,chirp,noise,multisine"),
            "{f}: {header}"
        );
    }
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("comparison.json")).unwrap()).unwrap();
    assert!((rep["prbs"]["rms"].as_f64().unwrap() - 0.2).abs() < 1e-12);
    assert!((rep["prbs"]["crest_factor"].as_f64().unwrap() - 1.0).abs() < 1e-12);
    let o = ambid(&["compare", "--level", "-1"]);
    assert!(
        !o.status.success() && text(&o).contains("RMS level"),
        "{}",
        text(&o)
    );
}
