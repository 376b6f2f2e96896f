//! Issue 24's first bar: the twin's seed record (`ambid simulate --out DIR`, 102 300 samples)
//! written as a MATLAB `-v7.3` MAT-file (hdf5storage: HDF5, deflate-compressed chunks) and as an
//! NI TDMS file (npTDMS: ten segments, the sample time in `wf_increment`) by
//! tests/fixtures/formats/make_seed_files.py gives the same FRF (`ambid frf`: the CSV output
//! byte for byte) and the same fitted model (`ambid fit`: the model file number for number to
//! 1e-12) as the CSV the simulation writes.
//!
//! The CSV is simulated again here with the binary under test; the fixtures must hold its
//! columns exactly, or the test says that they are stale and how to rewrite them.

use crate::common::{ambid, s, text, tmpdir};
use ambid::io::table::{read_table, ReadOptions};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/formats")
        .join(name)
}

fn ok(args: &[&str]) -> String {
    let o = ambid(args);
    assert!(
        o.status.success(),
        "ambid {}:\n{}",
        args.join(" "),
        text(&o)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Numbers equal to `tol` relative; strings equal after the file names are removed.
fn same(path: &str, a: &Value, b: &Value, tol: f64, out: &mut Vec<String>) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            for k in x.keys().chain(y.keys()) {
                match (x.get(k), y.get(k)) {
                    (Some(u), Some(v)) => same(&format!("{path}.{k}"), u, v, tol, out),
                    _ => out.push(format!("{path}.{k}: only in one")),
                }
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (k, (u, v)) in x.iter().zip(y).enumerate() {
                same(&format!("{path}[{k}]"), u, v, tol, out);
            }
        }
        (Value::Number(x), Value::Number(y)) => {
            let (u, v) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            if (u - v).abs() > tol * u.abs().max(v.abs()) {
                out.push(format!("{path}: {u:e} ≠ {v:e}"));
            }
        }
        (Value::String(_), Value::String(_)) => {}
        _ => {
            if a != b {
                out.push(format!("{path}: {a} ≠ {b}"));
            }
        }
    }
}

#[test]
fn seed_record_as_mat_v73_and_tdms_gives_the_csv_results() {
    let dir = tmpdir("seed-formats");
    ok(&["simulate", "--out", s(&dir.join("sim"))]);
    let csv = dir.join("sim/data.csv");
    let controller = dir.join("sim/controller.toml");
    let (v73, tdms) = (fixture("seed_v73.mat"), fixture("seed.tdms"));
    // the fixtures hold exactly the simulated columns
    let want = read_table(&csv, &ReadOptions::default()).unwrap();
    let mat = read_table(&v73, &ReadOptions::default()).unwrap();
    let td = read_table(&tdms, &ReadOptions::default()).unwrap();
    assert_eq!(td.ts_metadata, Some(5e-5));
    for (k, name) in want.names.iter().enumerate() {
        let stale = "stale fixture: the simulated seed record changed; rewrite the fixtures with tests/fixtures/formats/make_seed_files.py";
        let m = mat.column(&name.as_str().into()).expect(stale);
        assert!(
            m == want.columns[k].as_slice(),
            "{stale} (`{name}` in seed_v73.mat)"
        );
        if name != "t" {
            let t = td
                .column(&format!("seed/{name}").as_str().into())
                .expect(stale);
            assert!(
                t == want.columns[k].as_slice(),
                "{stale} (`{name}` in seed.tdms)"
            );
        }
    }
    // the FRF: byte for byte, also the printed report (file names removed)
    let tdms_cols = [
        "--excitation",
        "seed/r",
        "--input",
        "seed/u",
        "--output",
        "seed/y",
        "--current",
        "seed/i",
    ];
    let frf = |input: &Path, name: &str, cols: &[&str]| -> (Vec<u8>, String) {
        let out = dir.join(name);
        let mut a = vec![
            "frf",
            s(input),
            "--controller",
            s(&controller),
            "--out",
            s(&out),
        ];
        a.extend(cols);
        let printed = ok(&a).replace(s(input), "<in>").replace(s(&out), "<out>");
        (std::fs::read(&out).unwrap(), printed)
    };
    let reference = frf(&csv, "frf_csv.csv", &[]);
    assert!(reference.0.len() > 1000);
    assert!(
        reference == frf(&v73, "frf_v73.csv", &[]),
        "frf from seed_v73.mat differs"
    );
    assert!(
        reference == frf(&tdms, "frf_tdms.csv", &tdms_cols),
        "frf from seed.tdms differs"
    );
    // the fitted model to 1e-12 (`fit --structure arx --order 4`: the columns are equal bit for
    // bit above, so any deterministic estimator shows whether the same data reached it; the
    // PEM-refined `ss` fit of order 8 took 12 s per format in the debug build, 2026-12-04)
    let fit = |input: &Path, name: &str, cols: &[&str]| -> Value {
        let out = dir.join(name);
        let mut a = vec!["fit", s(input), "--structure", "arx", "--order", "4"];
        a.extend(["--out", s(&out)]);
        a.extend(
            cols.iter()
                .filter(|c| !c.contains("seed/i") && **c != "--current"),
        );
        ok(&a);
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap()
    };
    let m_csv = fit(&csv, "m_csv.json", &[]);
    for (what, m) in [
        ("seed_v73.mat", fit(&v73, "m_v73.json", &[])),
        ("seed.tdms", fit(&tdms, "m_tdms.json", &tdms_cols)),
    ] {
        let mut d = Vec::new();
        same("model", &m, &m_csv, 1e-12, &mut d);
        assert!(
            d.is_empty(),
            "the model from {what} differs:\n{}",
            d.join("\n")
        );
    }
    // a window of the TDMS log and of the CSV: the same FRF
    let win = ["--from", "1.0", "--to", "#60000"];
    let w_csv = frf(&csv, "w_csv.csv", &win);
    let mut c = tdms_cols.to_vec();
    c.extend(win);
    assert!(
        w_csv.0 == frf(&tdms, "w_tdms.csv", &c).0,
        "windowed frf differs"
    );
    assert!(w_csv.0 != reference.0, "the window was not applied");
}
