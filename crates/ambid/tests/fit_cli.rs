//! `ambid fit` and `ambid order` end to end on the DaISy dryer (read from ../shared/data/real).

use crate::common::{ambid, text, CONTROLLER};
use std::path::{Path, PathBuf};

/// Writes the dryer's halves as CSV (u, y) into a temporary directory.
fn dryer_halves(name: &str) -> (PathBuf, PathBuf, PathBuf) {
    let src = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/real/daisy-dryer/dryer.dat"
    );
    let body = std::fs::read_to_string(src).expect("the shared dryer data");
    let rows: Vec<&str> = body.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(rows.len(), 1000);
    let d = std::env::temp_dir().join(format!("ambid-fit-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    let write = |p: &Path, part: &[&str]| {
        let mut s = String::from("u,y\n");
        for r in part {
            let v: Vec<&str> = r.split_whitespace().collect();
            s.push_str(&format!("{},{}\n", v[0], v[1]));
        }
        std::fs::write(p, s).unwrap();
    };
    let (e, v) = (d.join("est.csv"), d.join("val.csv"));
    write(&e, &rows[..500]);
    write(&v, &rows[500..]);
    (e, v, d)
}

#[test]
fn fit_arx_on_the_dryer_writes_the_reference_model() {
    let (e, v, d) = dryer_halves("arx");
    let out = d.join("m.json");
    let o = ambid(&[
        "fit",
        e.to_str().unwrap(),
        "--fs",
        "12.5",
        "--structure",
        "arx",
        "--na",
        "2",
        "--nb",
        "2",
        "--nk",
        "3",
        "--validation",
        v.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(m["kind"], "polynomial");
    assert_eq!(m["structure"], "arx");
    let a: Vec<f64> = serde_json::from_value(m["a"].clone()).unwrap();
    let b: Vec<f64> = serde_json::from_value(m["b"].clone()).unwrap();
    // the README's numpy reference (first-half means removed, estimate on 1..500)
    let want_a = [1.0, -1.2765387524, 0.3967106056];
    let want_b = [0.0, 0.0, 0.0, 0.0651903038, 0.0451791996];
    assert!(
        a.iter().zip(&want_a).all(|(x, w)| (x - w).abs() < 1e-9),
        "{a:?}"
    );
    assert!(
        b.iter().zip(&want_b).all(|(x, w)| (x - w).abs() < 1e-9),
        "{b:?}"
    );
    assert!(m["meta"]["std"].as_array().unwrap().len() == 4);
    assert!(text(&o).contains("validation data"));
}

#[test]
fn fit_oe_and_order_scan_run_and_errors_are_clear() {
    let (e, v, d) = dryer_halves("oe");
    let o = ambid(&[
        "fit",
        e.to_str().unwrap(),
        "--fs",
        "12.5",
        "--structure",
        "oe",
        "--nb",
        "2",
        "--nf",
        "2",
        "--nk",
        "3",
        "--validation",
        v.to_str().unwrap(),
        "--out",
        d.join("oe.json").to_str().unwrap(),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("LM iterations"), "{t}");
    let grid = d.join("order.csv");
    let o = ambid(&[
        "order",
        e.to_str().unwrap(),
        "--fs",
        "12.5",
        "--na-max",
        "5",
        "--nb-max",
        "5",
        "--nk",
        "2,3",
        "--validation",
        v.to_str().unwrap(),
        "--out",
        grid.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let n = csv::Reader::from_path(&grid).unwrap().records().count();
    assert_eq!(n, 5 * 5 * 2);
    // orders the 500 samples cannot support
    let o = ambid(&[
        "fit",
        e.to_str().unwrap(),
        "--fs",
        "12.5",
        "--structure",
        "arx",
        "--na",
        "400",
        "--nb",
        "200",
        "--out",
        d.join("x.json").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(text(&o).to_lowercase().contains("sample"), "{}", text(&o));
}

#[test]
fn fit_state_space_from_twin_records() {
    let d = std::env::temp_dir().join(format!("ambid-fit-{}-ss", std::process::id()));
    for (seed, dir) in [("1", "e"), ("2", "v")] {
        let o = ambid(&[
            "simulate",
            "--mode",
            "linear",
            "--periods",
            "6",
            "--seed",
            seed,
            "--out",
            d.join(dir).to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
    }
    let out = d.join("ss.json");
    let o = ambid(&[
        "fit",
        d.join("e/data.csv").to_str().unwrap(),
        "--structure",
        "ss",
        "--order",
        "8",
        "--block-rows",
        "120",
        "--focus",
        "simulation",
        "--input",
        "r",
        "--output",
        "y",
        "--validation",
        d.join("v/data.csv").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    eprintln!("{t}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(m["kind"], "state_space");
    assert_eq!(m["a"].as_array().unwrap().len(), 8);
    let vfit = m["meta"]["validation"]["simulation_fit_pct"]
        .as_f64()
        .unwrap();
    assert!(vfit > 95.0, "{vfit} % ({t})");
    assert_eq!(m["meta"]["method"], "subspace+pem");
    assert_eq!(m["meta"]["pem"]["focus"], "simulation");
    assert!(
        m["meta"]["pem"]["loss"].as_f64().unwrap()
            <= m["meta"]["pem"]["start_loss"].as_f64().unwrap()
    );
    // the direct method: the plant u → y in closed loop, prediction focus (K estimated), then
    // validated through the loop and by k-step-ahead prediction
    let plant = d.join("plant.json");
    let o = ambid(&[
        "fit",
        d.join("e/data.csv").to_str().unwrap(),
        "--structure",
        "ss",
        "--order",
        "8",
        "--block-rows",
        "120",
        "--max-iterations",
        "40",
        "--input",
        "u",
        "--output",
        "y",
        "--out",
        plant.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let vdir = d.join("val");
    let o = ambid(&[
        "validate",
        plant.to_str().unwrap(),
        "--data",
        d.join("v/data.csv").to_str().unwrap(),
        "--controller",
        CONTROLLER,
        "--skip",
        "5115",
        "--k-step",
        "1",
        "--out",
        vdir.to_str().unwrap(),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    eprintln!("{t}");
    let sum: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(vdir.join("summary.json")).unwrap()).unwrap();
    let k1 = sum["k_step_prediction"]["fit_y_pct"].as_f64().unwrap();
    let sim = sum["fit_y_pct"].as_f64().unwrap();
    // the one-step predictor uses the measured outputs: it beats the simulation
    assert!(k1 > sim && sim > 90.0, "{k1} vs {sim}: {t}");
    // without --lags the residual lags come from the dynamics (closed-loop impulse response of
    // the model with the controller), as in the workflow: the printed M and residuals.csv agree
    let m: usize = t
        .split("residual tests: lags ±")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no lag rule printed: {t}"));
    assert!((10..=150).contains(&m) && m != 25, "M = {m}");
    let rows = std::fs::read_to_string(vdir.join("residuals.csv"))
        .unwrap()
        .lines()
        .count();
    assert_eq!(rows, 2 * m + 2, "header + lags −M…M");
}
