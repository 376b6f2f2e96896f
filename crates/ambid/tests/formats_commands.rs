//! One reader behind every command (issue 19): the same closed-loop twin record, written as
//! `.csv`, `.npy`, `.npz`, `.mat` and `.parquet` (tests/fixtures/formats, made by
//! `make_format_files.py` with numpy, scipy and pyarrow from `ambid simulate` output), and as a
//! MATLAB `-v7.3` MAT-file (`_v73.mat`, hdf5storage/h5py) and an NI TDMS file (`.tdms`, npTDMS,
//! three segments, sample time from `wf_increment`; issue 24, made by `make_v73_tdms_files.py`
//! from the CSV record), gives
//! IDENTICAL results in `frf`, `fit`, `order`, `validate`, `compare-models`, `bla` and `run`: the
//! CSV outputs byte for byte, the JSON outputs (which name the input file) number for number to
//! 1e-12 relative with the file names normalised. The CSV record is the reference: its text
//! path is the one each command had before the reader was unified.
//!
//! Columns are selected by name where the format has names (t, r, u, i, y) and by position
//! (`--time '#1' --excitation '#2' …`) in the `.npy` file, whose 2-D array has none: the same
//! column selection in every command and format.
//!
//! Parquet is read only with the cargo feature `parquet`; without it the Parquet checks are
//! skipped loudly (tests/common/skip.rs), the other formats still run.

use crate::common;
use crate::common::{ambid, text, tmpdir};
use serde_json::Value;
use std::path::{Path, PathBuf};

const FORMATS: [&str; 7] = ["csv", "npy", "npz", "mat", "v73", "tdms", "parquet"];

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/formats")
}

/// The file name of record `k` in format `fmt` (`v73`: the MAT v7.3 file).
fn file_name(k: usize, fmt: &str) -> String {
    match fmt {
        "v73" => format!("rec_m{k}_v73.mat"),
        _ => format!("rec_m{k}.{fmt}"),
    }
}

fn rec(k: usize, fmt: &str) -> String {
    fixtures().join(file_name(k, fmt)).display().to_string()
}

fn controller() -> String {
    fixtures().join("controller.toml").display().to_string()
}

/// The formats to check: every format, Parquet only when the binary reads it.
fn formats(what: &str) -> Vec<&'static str> {
    FORMATS
        .iter()
        .copied()
        .filter(|f| {
            let on = *f != "parquet" || cfg!(feature = "parquet");
            if !on {
                common::skip(
                    &format!("formats_commands::{what} on .parquet"),
                    "ambid is built without the cargo feature `parquet`; run `cargo test -p ambid --features parquet --test all formats_commands::`",
                );
            }
            on
        })
        .collect()
}

/// The column options of a format: none where the file names its columns t, r, u, i, y;
/// positions in the `.npy` array (columns t, r, u, i, y in that order).
fn columns(fmt: &str, which: &[&str]) -> Vec<String> {
    if fmt == "tdms" {
        // channels `group/channel`, no time channel (the sample time is wf_increment)
        let mut v = Vec::new();
        for w in which {
            let opt = match *w {
                "r" => "--excitation",
                "u" => "--input",
                "i" => "--current",
                "y" => "--output",
                _ => unreachable!(),
            };
            v.extend([opt.to_string(), format!("rec/{w}")]);
        }
        return v;
    }
    if fmt != "npy" {
        return Vec::new();
    }
    let mut v = vec!["--time".to_string(), "#1".to_string()];
    for w in which {
        let (opt, pos) = match *w {
            "r" => ("--excitation", "#2"),
            "u" => ("--input", "#3"),
            "i" => ("--current", "#4"),
            "y" => ("--output", "#5"),
            _ => unreachable!(),
        };
        v.extend([opt.to_string(), pos.to_string()]);
    }
    v
}

/// Runs ambid with `args`; panics with its output unless it succeeds. Returns stdout.
fn ok(args: &[String]) -> String {
    let a: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = ambid(&a);
    assert!(o.status.success(), "ambid {}:\n{}", a.join(" "), text(&o));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn s(v: &[&str]) -> Vec<String> {
    v.iter().map(|x| x.to_string()).collect()
}

/// `text` with the format's file names and the output directory written format-free.
fn normalise(text: &str, fmt: &str, dir: &Path) -> String {
    text.replace(&dir.display().to_string(), "<out>")
        .replace(&file_name(1, fmt), "rec_m1.<fmt>")
        .replace(&file_name(2, fmt), "rec_m2.<fmt>")
}

fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Differences of two JSON values: numbers to 1e-12 relative, strings after [`normalise`].
fn json_diff(path: &str, got: &Value, want: &Value, out: &mut Vec<String>) {
    match (got, want) {
        (Value::Object(g), Value::Object(w)) => {
            if g.keys().ne(w.keys()) {
                out.push(format!(
                    "{path}: keys {:?} ≠ {:?}",
                    g.keys().collect::<Vec<_>>(),
                    w.keys().collect::<Vec<_>>()
                ));
            }
            for (k, wv) in w {
                if let Some(gv) = g.get(k) {
                    json_diff(&format!("{path}.{k}"), gv, wv, out);
                }
            }
        }
        (Value::Array(g), Value::Array(w)) => {
            if g.len() != w.len() {
                out.push(format!("{path}: length {} ≠ {}", g.len(), w.len()));
            }
            for (i, (gv, wv)) in g.iter().zip(w).enumerate() {
                json_diff(&format!("{path}[{i}]"), gv, wv, out);
            }
        }
        (Value::Number(g), Value::Number(w)) => {
            let (a, b) = (g.as_f64().unwrap(), w.as_f64().unwrap());
            if (a - b).abs() > 1e-12 * a.abs().max(b.abs()) {
                out.push(format!("{path}: {a:e} ≠ {b:e}"));
            }
        }
        _ => {
            if got != want {
                out.push(format!("{path}: {got} ≠ {want}"));
            }
        }
    }
}

/// The JSON file `p` (written from format `fmt` into `dir`) with its strings normalised; a
/// model file names its signals as they were selected, `#3`/`#5` in the `.npy` array and
/// `rec/u`/`rec/y` in the TDMS file: written `u`/`y` here.
fn json(p: &Path, fmt: &str, dir: &Path) -> Value {
    let t = String::from_utf8(read(p)).unwrap();
    let mut v: Value = serde_json::from_str(&normalise(&t, fmt, dir)).unwrap();
    let sel = match fmt {
        "npy" => [("input", "#3", "u"), ("output", "#5", "y")],
        "tdms" => [("input", "rec/u", "u"), ("output", "rec/y", "y")],
        _ => return v,
    };
    for (k, col, name) in sel {
        if v.get(k).and_then(Value::as_str) == Some(col) {
            v[k] = Value::from(name);
        }
    }
    v
}

fn assert_json_equal(what: &str, fmt: &str, got: &Value, want: &Value) {
    let mut d = Vec::new();
    json_diff(what, got, want, &mut d);
    assert!(
        d.is_empty(),
        "{what}: .{fmt} differs from .csv in {} places:\n{}",
        d.len(),
        d.iter().take(20).cloned().collect::<Vec<_>>().join("\n")
    );
}

/// One command on every format: `args(fmt, dir)` are its arguments writing into `dir`; the
/// files `csv_outputs` must be byte-equal to the CSV record's, `json_outputs` equal as JSON
/// (numbers to 1e-12), and the printed report equal with the file names normalised.
fn same_on_every_format(
    what: &str,
    args: impl Fn(&str, &Path) -> Vec<String>,
    csv_outputs: &[&str],
    json_outputs: &[&str],
) {
    let root = tmpdir(&format!("formats-{what}"));
    let mut reference: Option<(PathBuf, String)> = None;
    for fmt in formats(what) {
        let dir = root.join(fmt);
        std::fs::create_dir_all(&dir).unwrap();
        let stdout = normalise(&ok(&args(fmt, &dir)), fmt, &dir);
        let Some((ref_dir, ref_stdout)) = &reference else {
            // the reference (CSV) run wrote every output, and something
            for f in csv_outputs.iter().chain(json_outputs) {
                assert!(
                    !read(&dir.join(f)).is_empty(),
                    "{what}: {f} is empty on the CSV record"
                );
            }
            reference = Some((dir.clone(), stdout));
            continue;
        };
        for f in csv_outputs {
            let (got, want) = (read(&dir.join(f)), read(&ref_dir.join(f)));
            assert!(
                got == want,
                "{what}: {f} from .{fmt} is not byte-equal to the one from .csv"
            );
        }
        for f in json_outputs {
            assert_json_equal(
                &format!("{what} {f}"),
                fmt,
                &json(&dir.join(f), fmt, &dir),
                &json(&ref_dir.join(f), "csv", ref_dir),
            );
        }
        assert_eq!(
            &stdout, ref_stdout,
            "{what}: the printed report from .{fmt} differs from the one from .csv"
        );
    }
}

#[test]
fn frf_reads_every_format_alike() {
    same_on_every_format(
        "frf",
        |fmt, dir| {
            let mut a = s(&["frf", &rec(1, fmt), "--period-samples", "400"]);
            a.extend(s(&["--controller", &controller(), "--out"]));
            a.push(dir.join("frf.csv").display().to_string());
            a.extend(columns(fmt, &["r", "u", "i", "y"]));
            a
        },
        &["frf.csv"],
        &[],
    );
}

#[test]
fn frf_local_polynomial_method_reads_every_format_alike() {
    // the in-memory path of `frf` (LPM) on every format, CSV included
    same_on_every_format(
        "frf-lpm",
        |fmt, dir| {
            let mut a = s(&["frf", &rec(1, fmt), "--method", "lpm", "--out"]);
            a.push(dir.join("frf.csv").display().to_string());
            a.extend(columns(fmt, &["r", "u", "i", "y"]));
            a
        },
        &["frf.csv"],
        &[],
    );
}

#[test]
fn fit_reads_every_format_alike() {
    same_on_every_format(
        "fit",
        |fmt, dir| {
            let mut a = s(&["fit", &rec(1, fmt), "--structure", "arx", "--na", "4"]);
            a.extend(s(&["--nb", "4", "--validation", &rec(2, fmt), "--out"]));
            a.push(dir.join("model.json").display().to_string());
            a.extend(columns(fmt, &["r", "u", "y"]));
            a
        },
        &[],
        &["model.json"],
    );
}

#[test]
fn order_reads_every_format_alike() {
    same_on_every_format(
        "order",
        |fmt, dir| {
            let mut a = s(&["order", &rec(1, fmt), "--na-max", "4", "--nb-max", "4"]);
            a.extend(s(&["--validation", &rec(2, fmt), "--out"]));
            a.push(dir.join("order.csv").display().to_string());
            a.extend(columns(fmt, &["u", "y"]));
            a
        },
        &["order.csv"],
        &[],
    );
}

/// A model of the plant fitted on the CSV record (the model file is not what is compared).
fn model(dir: &Path) -> String {
    let p = dir.join("model.json");
    let mut a = s(&[
        "fit",
        &rec(1, "csv"),
        "--structure",
        "arx",
        "--na",
        "8",
        "--nb",
        "8",
    ]);
    a.extend(s(&["--out", &p.display().to_string()]));
    ok(&a);
    p.display().to_string()
}

#[test]
fn validate_reads_every_format_alike() {
    let m = tmpdir("formats-validate-model");
    let model = model(&m);
    same_on_every_format(
        "validate",
        |fmt, dir| {
            let mut a = s(&["validate", &model, "--data", &rec(2, fmt)]);
            a.extend(s(&["--controller", &controller(), "--out"]));
            a.push(dir.join("val").display().to_string());
            a.extend(columns(fmt, &["r", "u", "y"]));
            a
        },
        &["val/timeseries.csv", "val/residuals.csv"],
        &["val/summary.json"],
    );
}

#[test]
fn compare_models_reads_every_format_alike() {
    // the FRF from the CSV record; the validation record in every format
    let f = tmpdir("formats-compare-frf");
    let frf = f.join("frf.csv").display().to_string();
    ok(&s(&[
        "frf",
        &rec(1, "csv"),
        "--period-samples",
        "400",
        "--controller",
        &controller(),
        "--out",
        &frf,
    ]));
    same_on_every_format(
        "compare-models",
        |fmt, dir| {
            let mut a = s(&["compare-models", &frf, "--structures", "arx,oe"]);
            a.extend(s(&["--orders", "4", "--validation", &rec(2, fmt)]));
            a.extend(s(&["--controller", &controller(), "--out"]));
            a.push(dir.join("comparison.csv").display().to_string());
            a.extend(columns(fmt, &["r", "y"]));
            a
        },
        &["comparison.csv"],
        &[],
    );
}

#[test]
fn bla_reads_every_format_alike() {
    same_on_every_format(
        "bla",
        |fmt, dir| {
            let mut a = s(&["bla", "--record"]);
            a.push(format!("5:{}", rec(1, fmt)));
            a.push("--record".into());
            a.push(format!("5:{}", rec(2, fmt)));
            a.extend(s(&["--period-samples", "400", "--out"]));
            a.push(dir.join("bla.csv").display().to_string());
            a.extend(columns(fmt, &["r", "u", "y"]));
            a
        },
        &["bla.csv"],
        &[],
    );
}

/// The workflow file of `run` on the records in format `fmt`.
fn workflow(fmt: &str, dir: &Path) -> PathBuf {
    workflow_with(fmt, dir, "")
}

/// [`workflow`] with `extra` lines in `[data]`.
fn workflow_with(fmt: &str, dir: &Path, extra: &str) -> PathBuf {
    let cols = match fmt {
        "npy" => "time = \"#1\"\nr = \"#2\"\nu = \"#3\"\ni = \"#4\"\ny = \"#5\"\n",
        "tdms" => "r = \"rec/r\"\nu = \"rec/u\"\ni = \"rec/i\"\ny = \"rec/y\"\n",
        _ => "",
    };
    let text = format!(
        "title = \"formats\"\nsource = \"files\"\nsteps = [\"frf\", \"order\", \"models\", \"validation\"]\n\n\
         [data]\nidentification = \"{}\"\nvalidation = \"{}\"\ncontroller = \"{}\"\n\
         period_samples = 400\n{cols}{extra}\n\
         [order]\nna_max = 4\nnb_max = 4\n\n\
         [models]\nstructures = [\"arx\", \"ss\"]\norders = [4]\n",
        rec(1, fmt),
        rec(2, fmt),
        controller()
    );
    let p = dir.join("workflow.toml");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn run_reads_every_format_alike() {
    let root = tmpdir("formats-run");
    let mut reference: Option<Value> = None;
    for fmt in formats("run") {
        let dir = root.join(fmt);
        std::fs::create_dir_all(&dir).unwrap();
        let wf = workflow(fmt, &dir);
        let out = dir.join("report");
        ok(&s(&[
            "run",
            &wf.display().to_string(),
            "--out",
            &out.display().to_string(),
            "--quiet",
        ]));
        let mut summary = json(&out.join("summary.json"), fmt, &dir);
        if let Value::Object(m) = &mut summary {
            m.remove(ambid::workflow::TIMING_KEY);
        }
        match &reference {
            None => reference = Some(summary),
            Some(want) => assert_json_equal("run summary.json", fmt, &summary, want),
        }
    }
}

/// `[data] from`/`to` cut the same window from every format (TDMS and MAT v7.3 read only it):
/// 4 of the 5 periods, from sample 400 to 0.1 s.
#[test]
fn run_reads_the_same_window_of_every_format() {
    let root = tmpdir("formats-run-window");
    let mut reference: Option<Value> = None;
    let mut whole: Option<Value> = None;
    for fmt in formats("run-window") {
        let dir = root.join(fmt);
        std::fs::create_dir_all(&dir).unwrap();
        let run = |wf: PathBuf, name: &str| {
            let out = dir.join(name);
            ok(&s(&[
                "run",
                &wf.display().to_string(),
                "--out",
                &out.display().to_string(),
                "--quiet",
            ]));
            let mut v = json(&out.join("summary.json"), fmt, &dir);
            if let Value::Object(m) = &mut v {
                m.remove(ambid::workflow::TIMING_KEY);
            }
            v
        };
        let summary = run(
            workflow_with(fmt, &dir, "from = \"#400\"\nto = 0.1\n"),
            "window",
        );
        match &reference {
            None => {
                // the window changes the result (it is applied), against the whole record
                let w = run(workflow(fmt, &dir), "whole");
                let mut d = Vec::new();
                json_diff("window vs whole", &summary, &w, &mut d);
                assert!(!d.is_empty(), "the window did not change the summary");
                whole = Some(w);
                reference = Some(summary);
            }
            Some(want) => assert_json_equal("run window summary.json", fmt, &summary, want),
        }
    }
    assert!(whole.is_some());
}

/// The positions `#k` count the file's columns, the time column included, in every format.
#[test]
fn positions_select_the_same_columns_as_names() {
    use ambid::io::{read_time, TimeOptions};
    let by_name = read_time(Path::new(&rec(1, "csv")), &TimeOptions::default()).unwrap();
    assert_eq!(by_name.names, ["r", "u", "i", "y"]);
    assert_eq!(by_name.time_column, Some(0));
    for (name, pos) in [("r", "#2"), ("u", "#3"), ("i", "#4"), ("y", "#5")] {
        assert_eq!(by_name.column(name).unwrap(), by_name.column(pos).unwrap());
    }
    assert!(by_name.column_raw("#1").is_err(), "#1 is the time column");
    assert!(by_name.column_raw("#6").is_err());
    let opts = TimeOptions {
        time: Some(ambid::io::table::ColumnRef::parse("#1")),
        ..TimeOptions::default()
    };
    let npy = read_time(Path::new(&rec(1, "npy")), &opts).unwrap();
    assert_eq!(npy.ts, by_name.ts);
    for pos in ["#2", "#3", "#4", "#5"] {
        assert_eq!(npy.column(pos).unwrap(), by_name.column(pos).unwrap());
    }
    // the record is the twin's at 20 kHz: Ts = 50 µs from the time column
    assert!((by_name.ts - 5e-5).abs() < 1e-15);
}
