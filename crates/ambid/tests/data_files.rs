//! Data-file readers (`ambid::io::table`): the numpy/scipy fixtures (independent oracle, written
//! by `tests/fixtures/make_data_files.py`), the real measured data sets in `shared/data/real/`
//! (skipped with a note when absent), and error messages with exact line numbers.

use crate::common;
use std::path::{Path, PathBuf};

use ambid::io::table::{read_table, ColumnRef, DataFileError, Format, ReadOptions, Table};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/data_files")
}

fn real(rel: &str) -> Option<PathBuf> {
    common::real_data(rel)
}

fn read(p: &Path) -> Table {
    read_table(p, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

fn col<'a>(t: &'a Table, name: &str) -> &'a [f64] {
    t.column(&ColumnRef::parse(name))
        .unwrap_or_else(|e| panic!("{e}"))
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

fn std(x: &[f64]) -> f64 {
    let m = mean(x);
    (x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len() as f64).sqrt()
}

/// A scratch directory removed on drop.
struct Scratch(PathBuf);

impl Scratch {
    fn new(tag: &str) -> Scratch {
        let d = std::env::temp_dir().join(format!("ambid-data-files-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        Scratch(d)
    }

    fn file(&self, name: &str, content: &[u8]) -> PathBuf {
        let p = self.0.join(name);
        std::fs::write(&p, content).unwrap();
        p
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

// ---------------------------------------------------------------- numpy / scipy oracle

#[test]
fn numpy_and_scipy_fixtures_are_reproduced_bit_for_bit() {
    let dir = fixtures();
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("expected.json")).unwrap()).unwrap();
    let cases = expected.as_object().unwrap();
    assert!(cases.len() >= 14, "expected.json has {} cases", cases.len());
    for (key, cols) in cases {
        let (file, variable) = match key.split_once("?variable=") {
            Some((f, v)) => (f, Some(v.to_string())),
            None => (key.as_str(), None),
        };
        if file.ends_with(".parquet") && !cfg!(feature = "parquet") {
            println!("note: {file} needs --features parquet; skipped");
            continue;
        }
        let opts = ReadOptions {
            variable,
            ..ReadOptions::default()
        };
        let table = read_table(&dir.join(file), &opts).unwrap_or_else(|e| panic!("{key}: {e}"));
        let cols = cols.as_array().unwrap();
        let names: Vec<&str> = cols.iter().map(|c| c["name"].as_str().unwrap()).collect();
        assert_eq!(table.names, names, "{key}: column names");
        for (c, got) in cols.iter().zip(&table.columns) {
            let want: Vec<u64> = c["bits"]
                .as_array()
                .unwrap()
                .iter()
                .map(|b| u64::from_str_radix(b.as_str().unwrap(), 16).unwrap())
                .collect();
            let got_bits: Vec<u64> = got.iter().map(|v| v.to_bits()).collect();
            assert_eq!(got_bits, want, "{key}: column {}: {got:?}", c["name"]);
        }
    }
}

#[test]
fn npz_and_mat_length_mismatch_names_the_variables() {
    for f in ["mismatch.npz", "mismatch.mat"] {
        let e = read_table(&fixtures().join(f), &ReadOptions::default()).unwrap_err();
        assert!(matches!(e, DataFileError::LengthMismatch { .. }), "{e}");
        let m = e.to_string();
        assert!(
            m.contains(f) && m.contains("a: 5") && m.contains("b: 4"),
            "{m}"
        );
        // one variable alone is fine
        let opts = ReadOptions {
            variable: Some("b".into()),
            ..ReadOptions::default()
        };
        assert_eq!(read_table(&fixtures().join(f), &opts).unwrap().len(), 4);
    }
}

#[test]
fn selecting_a_missing_or_unusable_variable_is_an_error() {
    let opts = |v: &str| ReadOptions {
        variable: Some(v.into()),
        ..ReadOptions::default()
    };
    let e = read_table(&fixtures().join("v5.mat"), &opts("y"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no variable `y`") && e.contains("`result` (6×3)"),
        "{e}"
    );
    let e = read_table(&fixtures().join("v5.mat"), &opts("note"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("`note` is text"), "{e}");
    let e = read_table(&fixtures().join("v5.mat"), &opts("Ts"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("single number"), "{e}");
    let e = read_table(&fixtures().join("vars.npz"), &opts("z"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("no variable `z`") && e.contains("`t`"), "{e}");
}

#[test]
fn format_is_detected_from_content_without_extension() {
    let s = Scratch::new("sniff");
    for f in ["block.npy", "vars.npz", "v5.mat"] {
        let bytes = std::fs::read(fixtures().join(f)).unwrap();
        let p = s.file(&f.replace('.', "_"), &bytes);
        let t = read(&p);
        assert!(!t.names.is_empty(), "{f}");
    }
    let p = s.file("plain", b"1 2\n3 4\n");
    assert_eq!(read(&p).names, ["col1", "col2"]);
    // explicit format wins over the extension
    let p = s.file("data.bin", b"a;b\n1;2\n");
    let opts = ReadOptions {
        format: Some(Format::Text),
        ..ReadOptions::default()
    };
    assert_eq!(read_table(&p, &opts).unwrap().names, ["a", "b"]);
}

// ---------------------------------------------------------------- error cases

#[test]
fn text_errors_give_file_and_line() {
    let s = Scratch::new("errors");
    let p = s.file(
        "ragged.csv",
        b"# run 3\n% setup\nt,u,y\n0,1,2\n\n0.1,1,2\n0.2,1\n0.3,1,2\n",
    );
    let e = read_table(&p, &ReadOptions::default()).unwrap_err();
    assert!(
        matches!(e, DataFileError::RaggedRow { line: 7, .. }),
        "{e:?}"
    );
    let m = e.to_string();
    assert!(
        m.contains("ragged.csv: line 7 has 2 fields, the header has 3"),
        "{m}"
    );

    let p = s.file("nan.csv", b"t,u,y\r\n0,1,2\r\n0.1,1,abc\r\n");
    let m = read_table(&p, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        m.contains("nan.csv: line 3, column `y`: cannot read `abc` as a number"),
        "{m}"
    );

    let p = s.file("noheader.dat", b"1 2 3\n4 5 x\n");
    let m = read_table(&p, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(m.contains("line 2, column `col3`: cannot read `x`"), "{m}");

    let p = s.file("empty.csv", b"");
    let e = read_table(&p, &ReadOptions::default()).unwrap_err();
    assert!(matches!(e, DataFileError::NoData { .. }), "{e:?}");
    assert!(
        e.to_string().contains("empty.csv: the file is empty"),
        "{e}"
    );

    let p = s.file("header_only.csv", b"t,u\n");
    let m = read_table(&p, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(m.contains("no data rows after the header on line 1"), "{m}");

    let m = read_table(&s.0.join("does_not_exist.csv"), &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(m.contains("does_not_exist.csv: cannot open"), "{m}");
}

#[test]
fn missing_column_lists_the_available_ones() {
    let s = Scratch::new("missing");
    let p = s.file("run.csv", b"t,u,y\n0,1,2\n");
    let t = read(&p);
    let m = t.column(&ColumnRef::parse("i_mA")).unwrap_err().to_string();
    assert!(m.contains("run.csv: no column `i_mA`"), "{m}");
    assert!(m.contains("`t` (#1), `u` (#2), `y` (#3)"), "{m}");
    let m = t.column(&ColumnRef::parse("#4")).unwrap_err().to_string();
    assert!(m.contains("no column `#4`"), "{m}");
}

#[test]
fn mat_v73_and_non_mat_files_are_explained() {
    let s = Scratch::new("v73");
    let mut v73 = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 .".to_vec();
    v73.resize(512, b' ');
    v73.extend_from_slice(b"\x89HDF\r\n\x1a\n");
    // the header of a v7.3 file and the HDF5 signature, but nothing after it: damaged
    let p = s.file("big.mat", &v73);
    let e = read_table(&p, &ReadOptions::default()).unwrap_err();
    let m = e.to_string();
    assert!(
        m.contains("big.mat") && m.contains("damaged") && m.contains("save it again"),
        "{m}"
    );

    let p = s.file("text.mat", b"1 2 3\n");
    let m = read_table(&p, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(m.contains("text.mat") && m.contains("-v7"), "{m}");

    // truncated copies of a real fixture: errors, never panics
    let good = std::fs::read(fixtures().join("v5_compressed.mat")).unwrap();
    for n in [0, 10, 127, 128, 135, 200, good.len() - 1] {
        let p = s.file("cut.mat", &good[..n]);
        assert!(
            read_table(&p, &ReadOptions::default()).is_err(),
            "cut at {n}"
        );
    }
    let good = std::fs::read(fixtures().join("vars.npz")).unwrap();
    for n in [0, 10, 100, good.len() / 2, good.len() - 1] {
        let p = s.file("cut.npz", &good[..n]);
        assert!(
            read_table(&p, &ReadOptions::default()).is_err(),
            "cut at {n}"
        );
    }
    // a header claiming absurd shapes must not allocate or overflow
    for shape in [
        "(1099511627776, 1099511627776, 1099511627776)",
        "(4611686018427387904,)",
        "(1000000,)",
    ] {
        let mut h = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}");
        while (10 + h.len() + 1) % 64 != 0 {
            h.push(' ');
        }
        h.push('\n');
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(h.len() as u16).to_le_bytes());
        b.extend_from_slice(h.as_bytes());
        b.extend_from_slice(&[0u8; 64]);
        let p = s.file("huge.npy", &b);
        let m = read_table(&p, &ReadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(m.contains("huge.npy"), "{m}");
    }
    let good = std::fs::read(fixtures().join("block.npy")).unwrap();
    for n in [0, 6, 20, 127, good.len() - 1] {
        let p = s.file("cut.npy", &good[..n]);
        assert!(
            read_table(&p, &ReadOptions::default()).is_err(),
            "cut at {n}"
        );
    }
}

#[test]
fn non_uniform_time_column_is_reported() {
    let s = Scratch::new("time");
    let p = s.file("jitter.csv", b"t,y\n0.0,1\n0.1,2\n0.2,3\n0.31,4\n0.4,5\n");
    let t = read(&p);
    let m = t
        .sample_time(Some(&ColumnRef::parse("t")), None)
        .unwrap_err()
        .to_string();
    assert!(
        m.contains("jitter.csv") && m.contains("not uniformly sampled") && m.contains("row 4"),
        "{m}"
    );
    assert_eq!(t.sample_time(None, Some(10.0)).unwrap(), 0.1);
    let m = t.sample_time(None, None).unwrap_err().to_string();
    assert!(m.contains("`fs`") && m.contains("`t`"), "{m}");
}

#[test]
fn parquet_without_the_feature_says_how_to_rebuild() {
    if cfg!(feature = "parquet") {
        return;
    }
    let s = Scratch::new("pq");
    let p = s.file("run.parquet", b"PAR1....PAR1");
    let m = read_table(&p, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        m.contains("run.parquet") && m.contains("--features parquet"),
        "{m}"
    );
}

// ---------------------------------------------------------------- real measured data

#[test]
fn real_magnetoshield_mat_v5() {
    let Some(p) = real("magnetoshield-maglev/MagnetoShield_ID_Data.mat") else {
        return;
    };
    let t = read(&p);
    assert_eq!(t.names, ["result1", "result2", "result3"]);
    assert_eq!(t.len(), 7500);
    // first samples (lift-off), as stored
    assert_eq!(&col(&t, "result1")[..3], &[15.63, 15.63, 15.62]);
    assert_eq!(&col(&t, "result2")[..3], &[7.24, 7.11, 7.1]);
    assert_eq!(&col(&t, "result3")[..3], &[44.19, 35.59, 34.19]);
    // README: values have 2 decimals
    for c in &t.columns {
        assert!(c
            .iter()
            .all(|v| ((v * 100.0).round() - v * 100.0).abs() < 1e-6));
    }
    // README, after discarding data(1:99): mean y 14.30 mm, mean u 4.60 V, mean i 21.8 mA
    let (y, u, i) = (
        &t.columns[0][99..],
        &t.columns[1][99..],
        &t.columns[2][99..],
    );
    assert!((mean(y) - 14.30).abs() < 0.005, "{}", mean(y));
    assert!((mean(u) - 4.60).abs() < 0.005, "{}", mean(u));
    assert!((mean(i) - 21.8).abs() < 0.05, "{}", mean(i));
}

#[test]
fn real_daisy_whitespace_files() {
    if let Some(p) = real("daisy-robot-arm/robot_arm.dat") {
        let t = read(&p);
        assert_eq!(t.names, ["col1", "col2"]);
        assert_eq!(t.len(), 1024);
        assert_eq!(t.columns[0][0], 2.2183165e-01);
        assert_eq!(t.columns[1][0], -1.7703630e-01);
        assert!(
            (std(&t.columns[0]) - 0.164).abs() < 0.0005,
            "{}",
            std(&t.columns[0])
        );
        assert!(
            (std(&t.columns[1]) - 0.275).abs() < 0.0005,
            "{}",
            std(&t.columns[1])
        );
    }
    if let Some(p) = real("daisy-dryer/dryer.dat") {
        let t = read(&p);
        assert_eq!(t.names, ["col1", "col2"]);
        assert_eq!(t.len(), 1000);
        assert_eq!(&t.columns[0][..2], &[6.41, 3.41]);
        assert!(t.columns[0].iter().all(|&v| v == 3.41 || v == 6.41));
        // README: first-half means u 4.994, y 4.84337228
        assert!((mean(&t.columns[0][..500]) - 4.994).abs() < 1e-9);
        assert!((mean(&t.columns[1][..500]) - 4.84337228).abs() < 1e-8);
    }
}

#[test]
fn real_nonlinearbenchmark_csvs() {
    if let Some(p) = real("silverbox/SNLS80mV.csv") {
        let t = read(&p);
        assert_eq!(t.names, ["V1", "V2"]);
        assert_eq!(t.len(), 131_072);
        assert_eq!(t.columns[0][0], 0.0057756);
        assert_eq!(t.columns[1][1], 0.012971);
        assert!(t.columns.iter().all(|c| c.iter().all(|v| v.is_finite())));
    }
    if let Some(p) = real("cascaded-tanks/dataBenchmark.csv") {
        let t = read(&p);
        assert_eq!(t.names, ["uEst", "uVal", "yEst", "yVal", "Ts"]);
        assert_eq!(t.len(), 1024);
        assert_eq!(col(&t, "Ts")[0], 4.0);
        assert!(col(&t, "Ts")[1..].iter().all(|v| v.is_nan()));
        assert_eq!(col(&t, "yVal")[0], 4.9728);
        assert!(col(&t, "uEst").iter().all(|v| v.is_finite()));
    }
    if let Some(p) = real("f16-gvt/F16Data_FullMSine_Level1.csv") {
        let t = read(&p);
        assert_eq!(
            t.names,
            [
                "Force",
                "Voltage",
                "Acceleration1",
                "Acceleration2",
                "Acceleration3",
                "Fs"
            ]
        );
        assert_eq!(t.len(), 73_728);
        assert_eq!(col(&t, "Fs")[0], 400.0);
        assert_eq!(col(&t, "Force")[0], 0.95714);
        assert_eq!(col(&t, "Acceleration3").last(), Some(&0.014724));
        let ts = t.sample_time(None, Some(col(&t, "Fs")[0])).unwrap();
        assert_eq!(ts, 0.0025);
    }
}

#[test]
fn real_emps_csv_with_time_column() {
    let Some(p) = real("emps/emps_estimation.csv") else {
        return;
    };
    let t = read(&p);
    assert_eq!(
        t.names,
        ["t_s", "qm_position_m", "qg_reference_m", "vir_control_V"]
    );
    assert_eq!(t.len(), 24_841);
    assert_eq!(col(&t, "qm_position_m")[0], 7.45e-06);
    assert_eq!(col(&t, "vir_control_V")[0], 2.5386280888756465);
    let ts = t.sample_time(None, Some(1000.0)).unwrap();
    assert_eq!(ts, 1e-3);
    // The stored time vector is float-rounded (README: steps 0.99997-1.00002 ms), about 3e-5 Ts
    // off a uniform grid: inside the 1e-3·Ts allowed, so `t` gives Ts = 1 ms (and agrees with fs).
    let from_t = t.sample_time(Some(&ColumnRef::parse("t_s")), None).unwrap();
    assert!((from_t - 1e-3).abs() < 1e-9, "{from_t}");
    let both = t
        .sample_time(Some(&ColumnRef::parse("t_s")), Some(1000.0))
        .unwrap();
    assert_eq!(both, from_t);
}

#[test]
fn real_other_files_read_with_their_documented_shapes() {
    // (file, columns, rows) from the READMEs
    let cases: [(&str, &[&str], usize); 5] = [
        (
            "silverbox/Schroeder80mV.csv",
            &["Ovld2", "Ovld1", "V1", "V2"],
            131_072,
        ),
        (
            "emps/emps_validation_pulses.csv",
            &[
                "t_s",
                "qm_position_m",
                "qg_reference_m",
                "vir_control_V",
                "pulses_N",
            ],
            24_841,
        ),
        (
            "daisy-cd-player-arm/CD_player_arm.dat",
            &["col1", "col2", "col3", "col4"],
            2048,
        ),
        ("daisy-flutter/flutter.dat", &["col1", "col2"], 1024),
        ("daisy-ballbeam/ballbeam.dat", &["col1", "col2"], 1000),
    ];
    for (rel, names, rows) in cases {
        let Some(p) = real(rel) else { continue };
        let t = read(&p);
        assert_eq!(t.names, names, "{rel}");
        assert_eq!(t.len(), rows, "{rel}");
    }
    if let Some(p) = real("silverbox/Schroeder80mV.csv") {
        let t = read(&p);
        // overload flags only on the first row
        assert_eq!(col(&t, "Ovld1")[0], 0.0);
        assert!(col(&t, "Ovld1")[1].is_nan());
        assert!(col(&t, "V2").iter().all(|v| v.is_finite()));
    }
}

#[test]
fn corrupted_fixtures_give_errors_or_tables_never_panics() {
    // Deterministic byte mutations (and truncations) of every fixture; each read must return,
    // not panic. Parquet fixtures only with the feature.
    let s = Scratch::new("mutate");
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(fixtures())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e != "json"))
        .filter(|p| cfg!(feature = "parquet") || p.extension().is_none_or(|e| e != "parquet"))
        .collect();
    files.sort();
    let text = b"# c\nt,u,y\n0,1,2\n0.1,\"1\",3\n0.2,1e-3,NaN\n".to_vec();
    let mut inputs: Vec<(String, Vec<u8>)> = files
        .iter()
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(p).unwrap())
        })
        .collect();
    inputs.push(("text.csv".into(), text));
    for (name, good) in inputs {
        for round in 0..300 {
            let mut b = good.clone();
            let flips = 1 + (next() % 4) as usize;
            for _ in 0..flips {
                let i = (next() % b.len() as u64) as usize;
                b[i] = (next() & 0xff) as u8;
            }
            if round % 5 == 0 {
                let n = (next() % b.len() as u64) as usize;
                b.truncate(n);
            }
            let p = s.file(&name, &b);
            let r = std::panic::catch_unwind(|| read_table(&p, &ReadOptions::default()));
            assert!(r.is_ok(), "{name}: round {round} panicked");
            if let Ok(Ok(t)) = r {
                assert!(!t.is_empty() && t.columns.iter().all(|c| c.len() == t.len()));
            }
        }
    }
}
