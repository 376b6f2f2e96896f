//! Recordings as the rigs write them (issue 24): MATLAB `-v7.3` MAT-files (HDF5) in the layouts
//! MATLAB, Simulink and dSPACE ControlDesk produce, and NI TDMS files with several groups,
//! segments, scaled integer channels and string channels, written by third-party writers
//! (hdf5storage/h5py and npTDMS; tests/fixtures/rig_formats/make_rig_format_files.py), read
//! back value for value against `expected.json`, which the same script wrote from the arrays it
//! gave the writers (for the scaled channel: the values npTDMS itself reads back). Then windows
//! and column subsets, and every malformed file with its error.

use ambid::io::table::{read_table, ColumnRef, DataFileError, Format, ReadOptions};
use ambid::io::time::{Bound, Window};
use ambid::io::{read_time, TimeOptions};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/rig_formats")
}

fn expected() -> Value {
    let t = std::fs::read_to_string(dir().join("expected.json")).unwrap();
    serde_json::from_str(&t).unwrap()
}

fn values(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// Every good file gives exactly the columns (names, order, values) its writer was given.
#[test]
fn rig_layouts_read_back_exactly() {
    let exp = expected();
    for file in [
        "struct_v73.mat",
        "simulink_v73.mat",
        "dspace_v73.mat",
        "multi.tdms",
        "float32_i32.tdms",
    ] {
        let e = &exp[file];
        let cols = e["columns"].as_object().unwrap();
        let names: Vec<&str> = cols.keys().map(String::as_str).collect();
        let opts = ReadOptions {
            columns: Some(names.iter().map(|n| ColumnRef::parse(n)).collect()),
            ..ReadOptions::default()
        };
        let t = read_table(&dir().join(file), &opts).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_eq!(t.names, names, "{file}");
        for (name, col) in t.names.iter().zip(&t.columns) {
            assert_eq!(*col, values(&cols[name.as_str()]), "{file}: {name}");
        }
        if file.ends_with(".tdms") {
            assert_eq!(t.ts_metadata, e["ts"].as_f64(), "{file}: wf_increment");
        }
    }
}

/// Without a column list a file gives every numeric signal: the MAT files their struct fields
/// (the scalar `fs` and the text `note` are not signals), a TDMS group its numeric channels.
#[test]
fn whole_files_list_their_signals() {
    let exp = expected();
    let t = read_table(&dir().join("struct_v73.mat"), &ReadOptions::default()).unwrap();
    let mut want: Vec<String> = exp["struct_v73.mat"]["columns"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect();
    let mut got = t.names.clone();
    got.sort();
    want.sort();
    assert_eq!(got, want);
    // a TDMS group by `variable` (the groups may differ in length; one group is one record)
    let g = read_table(
        &dir().join("multi.tdms"),
        &ReadOptions {
            variable: Some("exp2".into()),
            ..ReadOptions::default()
        },
    )
    .unwrap();
    assert_eq!(g.names, ["exp2/r_xa", "exp2/u_xa", "exp2/y_xa"]);
    assert_eq!(g.ts_metadata, Some(5e-5));
    // a MAT variable by `variable`
    let v = read_table(
        &dir().join("simulink_v73.mat"),
        &ReadOptions {
            variable: Some("sim".into()),
            ..ReadOptions::default()
        },
    )
    .unwrap();
    assert!(
        v.names.iter().all(|n| n.starts_with("sim.")),
        "{:?}",
        v.names
    );
    // the format from the first bytes when the extension says nothing
    let tmp = std::env::temp_dir().join(format!("ambid-rigfmt-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let p = tmp.join("log.bin");
    std::fs::copy(dir().join("float32_i32.tdms"), &p).unwrap();
    assert_eq!(Format::of_file(&p, None).unwrap(), Format::Tdms);
    assert_eq!(
        read_table(&p, &ReadOptions::default()).unwrap().names,
        ["g/a", "g/b"]
    );
}

/// A window in samples or seconds and a column subset read exactly those rows of those
/// columns; the sample time comes from the time column or from `wf_increment`.
#[test]
fn windows_and_column_subsets() {
    let exp = expected();
    let cases: [(&str, &str, Option<&str>); 3] = [
        ("multi.tdms", "exp1/y_raw", None),
        ("struct_v73.mat", "rec.uv2", Some("rec.t")),
        ("simulink_v73.mat", "sim.signals.r1", Some("sim.time")),
    ];
    for (file, col, time) in cases {
        let all = values(&exp[file]["columns"][col]);
        for (from, to, lo, hi) in [
            (Bound::Sample(100), Bound::Sample(600), 100, 600),
            // 0.01 s = sample 200 at 20 kHz, 0.0301 s: the first sample at or after it, 602
            (Bound::Seconds(0.01), Bound::Seconds(0.0301), 200, 602),
            (Bound::Sample(950), Bound::Sample(5000), 950, 1000),
        ] {
            let opts = TimeOptions {
                time: time.map(ColumnRef::parse),
                window: Some(Window {
                    from: Some(from),
                    to: Some(to),
                }),
                columns: Some(vec![col.to_string()]),
                ..TimeOptions::default()
            };
            let d = read_time(&dir().join(file), &opts).unwrap_or_else(|e| panic!("{file}: {e}"));
            assert_eq!(
                d.column(col).unwrap(),
                &all[lo..hi],
                "{file} {col} {from:?}"
            );
            assert!((d.ts - 5e-5).abs() < 1e-15, "{file}: {}", d.ts);
            assert_eq!(d.first_row, lo);
            // only the column asked for (and the time column) was read
            assert!(d.names.len() == 1, "{file}: {:?}", d.names);
        }
    }
    // a window outside the record is an error, not an empty record
    let opts = TimeOptions {
        window: Some(Window {
            from: Some(Bound::Seconds(5.0)),
            to: None,
        }),
        columns: Some(vec!["g/a".into()]),
        ..TimeOptions::default()
    };
    let e = read_time(&dir().join("float32_i32.tdms"), &opts)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("float32_i32.tdms") && e.contains("no samples"),
        "{e}"
    );
    // --fs that contradicts wf_increment
    let opts = TimeOptions {
        fs_hz: Some(500.0),
        columns: Some(vec!["g/a".into()]),
        ..TimeOptions::default()
    };
    let e = read_time(&dir().join("float32_i32.tdms"), &opts)
        .unwrap_err()
        .to_string();
    assert!(e.contains("wf_increment") && e.contains("--fs"), "{e}");
}

fn err(file: &str, opts: &ReadOptions) -> DataFileError {
    read_table(&dir().join(file), opts).unwrap_err()
}

/// Damaged files and wrong selections: a typed error naming the file and the object.
#[test]
fn malformed_files_and_wrong_selections_are_explained() {
    let none = ReadOptions::default();
    let col = |c: &str| ReadOptions {
        columns: Some(vec![ColumnRef::parse(c)]),
        ..ReadOptions::default()
    };
    let m = err("truncated_v73.mat", &none).to_string();
    assert!(
        m.contains("truncated_v73.mat") && m.contains("damaged or truncated"),
        "{m}"
    );
    let m = err("not_hdf5_v73.mat", &none).to_string();
    assert!(
        m.contains("not_hdf5_v73.mat") && m.contains("no HDF5"),
        "{m}"
    );
    let m = err("bad_leadin.tdms", &none).to_string();
    assert!(m.contains("bad_leadin.tdms") && m.contains("TDSm"), "{m}");
    let e = err("truncated.tdms", &none);
    assert!(matches!(e, DataFileError::Invalid { .. }), "{e:?}");
    let m = e.to_string();
    assert!(
        m.contains("truncated.tdms") && m.contains("segment 2") && m.contains("truncated"),
        "{m}"
    );
    // a channel of strings
    let m = err("multi.tdms", &col("exp1/comment")).to_string();
    assert!(m.contains("`exp1/comment` holds strings"), "{m}");
    // a struct without the named field: the error lists what there is
    let e = err("struct_v73.mat", &col("rec.x"));
    assert!(matches!(e, DataFileError::MissingColumn { .. }), "{e:?}");
    let m = e.to_string();
    assert!(
        m.contains("no column `rec.x`") && m.contains("rec.meta.gain"),
        "{m}"
    );
    // text and single numbers are not signals
    let m = err("struct_v73.mat", &col("note")).to_string();
    assert!(m.contains("`note` is text"), "{m}");
    let m = err("struct_v73.mat", &col("fs")).to_string();
    assert!(m.contains("`fs` is a single number"), "{m}");
    // groups of different lengths cannot be one table without a choice
    let tmp = std::env::temp_dir().join(format!("ambid-rigfmt-e-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let e = read_table(
        &dir().join("multi.tdms"),
        &ReadOptions {
            columns: Some(vec![ColumnRef::parse("exp1/r_xa"), ColumnRef::parse("#99")]),
            ..ReadOptions::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, DataFileError::MissingColumn { .. }), "{e:?}");
}
