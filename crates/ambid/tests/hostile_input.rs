//! Hostile input (issue 17, workflow validation and messages): every case spawns the real
//! binary on a small crafted input in a temporary directory, with a wall-clock limit enforced
//! here, and checks the exit code of the one rule (docs/workflow.md, "Exit codes": 2 usage or
//! workflow file, 3 input data, 4 computation, 5 output; never 101), that stderr names what is
//! wrong (file, row, column, key, option) and that nothing is left on disk where a failure
//! should leave nothing.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// What a finished command gave.
struct Outcome {
    code: i32,
    stdout: String,
    stderr: String,
}

/// Runs `ambid args…` in `dir`, killing it and failing the test after `limit_s` seconds.
fn ambid(dir: &Path, args: &[&str], limit_s: u64) -> Outcome {
    let out_path = dir.join(".stdout");
    let err_path = dir.join(".stderr");
    let mut child = Command::new(env!("CARGO_BIN_EXE_ambid"))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out_path).unwrap())
        .stderr(std::fs::File::create(&err_path).unwrap())
        .spawn()
        .expect("spawn ambid");
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed() > Duration::from_secs(limit_s) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("ambid {args:?} ran longer than {limit_s} s");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let o = Outcome {
        code: status.code().unwrap_or(-1),
        stdout: std::fs::read_to_string(&out_path).unwrap(),
        stderr: std::fs::read_to_string(&err_path).unwrap(),
    };
    std::fs::remove_file(&out_path).unwrap();
    std::fs::remove_file(&err_path).unwrap();
    assert_ne!(o.code, 101, "ambid {args:?} panicked:\n{}", o.stderr);
    o
}

/// Asserts the exit code and that stderr contains every piece; returns stderr.
fn expect(o: &Outcome, code: i32, pieces: &[&str]) -> String {
    assert_eq!(
        o.code, code,
        "exit code {} instead of {code}\nstderr: {}\nstdout: {}",
        o.code, o.stderr, o.stdout
    );
    for p in pieces {
        assert!(o.stderr.contains(p), "stderr lacks {p:?}:\n{}", o.stderr);
    }
    o.stderr.clone()
}

/// A closed-loop record `t, r, u, y` of `n` samples at 1 kHz from an exactly known ARX system
/// y[k] = 0.5 y[k−1] + 0.3 u[k−1] (u = r + a deterministic ±1 sequence), written by a naive loop.
fn record(n: usize) -> Vec<[f64; 4]> {
    let mut rows = Vec::with_capacity(n);
    let mut y_prev = 0.0;
    let mut u_prev = 0.0;
    let mut state: u32 = 0x1234_5678;
    for k in 0..n {
        // xorshift: a reproducible ±1 excitation
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        let r = if state & 1 == 0 { 1.0 } else { -1.0 };
        let u = r - 0.2 * y_prev;
        let y = 0.5 * y_prev + 0.3 * u_prev;
        rows.push([k as f64 * 1e-3, r, u, y]);
        y_prev = y;
        u_prev = u;
    }
    rows
}

fn write_csv(path: &Path, header: &str, rows: &[[f64; 4]], edit: impl Fn(usize, &mut String)) {
    let mut s = format!("{header}\n");
    for (k, r) in rows.iter().enumerate() {
        let mut line = format!("{:.6},{},{},{}", r[0], r[1], r[2], r[3]);
        edit(k, &mut line);
        s.push_str(&line);
        s.push('\n');
    }
    std::fs::write(path, s).unwrap();
}

/// A fresh directory under the system's temp directory, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn tmp() -> TempDir {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let p = std::env::temp_dir().join(format!(
        "ambid-hostile-{}-{}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&p);
    std::fs::create_dir_all(&p).unwrap();
    TempDir(p)
}

/// A workflow file on recorded data `rec.csv` (n samples) with `extra` appended to `[data]`
/// and further sections after it.
fn workflow(dir: &Path, n: usize, data_extra: &str, sections: &str) -> PathBuf {
    write_csv(&dir.join("rec.csv"), "t,r,u,y", &record(n), |_, _| {});
    let p = dir.join("wf.toml");
    std::fs::write(
        &p,
        format!(
            "source = \"files\"\nsteps = [\"frf\", \"order\", \"models\"]\n\n[data]\nidentification = \"rec.csv\"\n{data_extra}\n{sections}\n"
        ),
    )
    .unwrap();
    p
}

/// `ambid run` on a workflow that must be refused before any step ran, leaving no output.
fn refused_workflow(data_extra: &str, sections: &str, pieces: &[&str]) -> String {
    let d = tmp();
    workflow(d.path(), 2000, data_extra, sections);
    let o = ambid(d.path(), &["run", "wf.toml", "--out", "out", "--quiet"], 10);
    let e = expect(&o, 2, pieces);
    assert!(e.contains("wf") || e.contains("workflow file"), "{e}");
    // refused before any step: no step line, no output directory
    assert!(!e.contains("frf:") && !e.contains("order:"), "{e}");
    assert!(!d.path().join("out").exists(), "an output was left behind");
    e
}

#[test]
fn workflow_values_are_refused_before_any_step() {
    // the panic of issue 17: a period of 0 samples divided by zero in the FRF step (exit 101)
    refused_workflow(
        "period_samples = 0",
        "",
        &["data.period_samples = 0", "at least 2"],
    );
    refused_workflow("", "[frf]\nnperseg = 0", &["frf.nperseg = 0"]);
    refused_workflow(
        "",
        "[iso]\na = 5.0\nb = 4.0\nc = 3.0",
        &["[iso] a = 5, b = 4, c = 3", "must increase"],
    );
    refused_workflow(
        "",
        "[frf]\nband_hz = [400.0, 10.0]",
        &["frf.band_hz = [400, 10]", "increasing"],
    );
    refused_workflow(
        "",
        "[models]\norders = [1000000]",
        &["models.orders has 1000000", "100"],
    );
    // a twin workflow with no amplitude level (the levels are the twin's)
    let d = tmp();
    std::fs::write(
        d.path().join("wf.toml"),
        "steps = [\"amplitude\"]\n[amplitude_study]\nlevels_pct = []\n",
    )
    .unwrap();
    let o = ambid(d.path(), &["run", "wf.toml", "--out", "out", "--quiet"], 10);
    expect(&o, 2, &["amplitude_study.levels_pct = []"]);
    assert!(!d.path().join("out").exists());
    // … also when `--steps` asks for the step the file did not list
    std::fs::write(
        d.path().join("wf.toml"),
        "steps = [\"excitation\"]\n[amplitude_study]\nlevels_pct = []\n",
    )
    .unwrap();
    let o = ambid(
        d.path(),
        &[
            "run",
            "wf.toml",
            "--steps",
            "amplitude",
            "--out",
            "out",
            "--quiet",
        ],
        10,
    );
    expect(&o, 2, &["amplitude_study.levels_pct = []"]);
    assert!(!d.path().join("out").exists());
}

#[test]
fn workflow_values_that_need_the_record_are_refused_before_any_step() {
    // explicitly periodic with a period longer than the record: no silent Welch fallback
    let e = refused_workflow(
        "period_samples = 100000000",
        "[frf]\nmethod = \"periodic\"",
        &[
            "frf.method = \"periodic\"",
            "period_samples = 100000000",
            "1000 samples",
        ],
    );
    assert!(e.contains("welch"), "{e}");
    // an order whose parameters the estimation half (1000 samples) cannot support: 2·60 + 1
    // parameters > 1000 / 10
    refused_workflow(
        "",
        "[models]\norders = [60]",
        &["models.orders has 60", "121 parameters", "at most 100"],
    );
    refused_workflow(
        "",
        "[frf]\nnperseg = 5000",
        &["frf.nperseg = 5000", "1000 samples"],
    );
}

#[test]
fn a_nan_or_an_overflowing_value_is_named_by_file_row_and_column() {
    let d = tmp();
    let rows = record(1000);
    write_csv(&d.path().join("nan.csv"), "t,r,u,y", &rows, |k, l| {
        if k == 499 {
            *l = format!("{:.6},1,1,NaN", rows[k][0]);
        }
    });
    write_csv(&d.path().join("big.csv"), "t,r,u,y", &rows, |k, l| {
        if k == 499 {
            *l = format!("{:.6},1,1,1e308", rows[k][0]);
        }
    });
    for (file, what) in [("nan.csv", "NaN"), ("big.csv", "1e308")] {
        let o = ambid(
            d.path(),
            &["fit", file, "--structure", "arx", "--na", "1", "--nb", "1"],
            10,
        );
        let e = expect(&o, 3, &[file, "column `y`", "data row 500"]);
        assert!(
            !e.contains("index 0") && !e.contains("before calling"),
            "{what}: {e}"
        );
        assert!(e.len() < 600, "{what}: a {} byte message", e.len());
        assert!(!d.path().join("model.json").exists());
    }
    // `ambid frf` keeps the missing sample for its screening, repairs it and names it 1-based
    let o = ambid(d.path(), &["frf", "nan.csv", "--out", "f.csv"], 20);
    expect(&o, 0, &["1 non-finite (at sample 500)"]);
    // the workflow reader says the same
    let d = tmp();
    workflow(d.path(), 2000, "", "");
    let rows = record(2000);
    write_csv(&d.path().join("rec.csv"), "t,r,u,y", &rows, |k, l| {
        if k == 499 {
            *l = format!("{:.6},1,1,", rows[k][0]);
        }
    });
    let o = ambid(d.path(), &["run", "wf.toml", "--out", "out", "--quiet"], 10);
    expect(&o, 3, &["rec.csv", "`y`", "data row 500"]);
    assert!(!d.path().join("out").exists());
}

#[test]
fn one_text_dialect_for_every_reader() {
    let d = tmp();
    let rows = record(3000);
    write_csv(&d.path().join("plain.csv"), "t,r,u,y", &rows, |_, _| {});
    // comment and blank lines at the top and in the middle, as the workflow reader allows
    write_csv(
        &d.path().join("commented.csv"),
        "# recorded on the test rig\n% exported by hand\n\nt,r,u,y",
        &rows,
        |k, l| {
            if k == 1500 {
                l.insert_str(0, "# a note in the middle\n\n");
            }
        },
    );
    let fit = |file: &str, out: &str| {
        let o = ambid(
            d.path(),
            &[
                "fit",
                file,
                "--structure",
                "arx",
                "--na",
                "1",
                "--nb",
                "1",
                "--out",
                out,
            ],
            20,
        );
        expect(&o, 0, &[]);
        serde_json::from_str::<serde_json::Value>(
            &std::fs::read_to_string(d.path().join(out)).unwrap(),
        )
        .unwrap()
    };
    let a = fit("plain.csv", "a.json");
    let b = fit("commented.csv", "b.json");
    assert_eq!(a["a"], b["a"]);
    assert_eq!(a["b"], b["b"]);
    // and the fit finds the known system y[k] = 0.5 y[k−1] + 0.3 u[k−1] (noise-free)
    let a1 = a["a"][1].as_f64().unwrap();
    let b1 = a["b"][1].as_f64().unwrap();
    assert!((a1 + 0.5).abs() < 1e-6 && (b1 - 0.3).abs() < 1e-6, "{a}");

    // duplicate column names are an error naming the duplicate, not the first column silently
    write_csv(&d.path().join("dup.csv"), "t,r,u,y,y", &rows, |_, l| {
        l.push_str(",0")
    });
    let o = ambid(
        d.path(),
        &["fit", "dup.csv", "--structure", "arx", "--na", "1"],
        10,
    );
    expect(&o, 3, &["dup.csv", "`y` twice", "columns 4 and 5"]);
    // an empty file says so
    std::fs::write(d.path().join("empty.csv"), "").unwrap();
    let o = ambid(
        d.path(),
        &["fit", "empty.csv", "--structure", "arx", "--na", "1"],
        10,
    );
    let e = expect(&o, 3, &["empty.csv", "the file is empty"]);
    assert!(!e.contains("got []"), "{e}");
    let o = ambid(d.path(), &["frf", "empty.csv", "--fs", "1000"], 10);
    expect(&o, 3, &["empty.csv", "the file is empty"]);
    // a file without line breaks (a binary file, `/dev/zero`) is refused at the first
    // over-long line, not read whole
    std::fs::write(d.path().join("noline.csv"), vec![b'0'; (1 << 20) + 10]).unwrap();
    let o = ambid(d.path(), &["frf", "noline.csv", "--fs", "1000"], 10);
    expect(&o, 3, &["noline.csv", "line 1 is longer than 1 MiB"]);
    if Path::new("/dev/zero").exists() {
        let o = ambid(d.path(), &["frf", "/dev/zero", "--fs", "1000"], 10);
        expect(&o, 3, &["/dev/zero", "line 1 is longer than 1 MiB"]);
    }
}

#[test]
fn short_records_and_option_values_name_what_the_user_can_set() {
    let d = tmp();
    write_csv(
        &d.path().join("short.csv"),
        "t,r,u,y",
        &record(10),
        |_, _| {},
    );
    let o = ambid(d.path(), &["frf", "short.csv"], 10);
    let e = expect(&o, 3, &["10 samples", "at least 64"]);
    assert!(
        !e.contains("half-window") && !e.contains("half_window"),
        "{e}"
    );
    assert!(!d.path().join("frf.csv").exists());
    // the workflow says the same before any step runs (with a validation file, no split)
    std::fs::write(
        d.path().join("wf.toml"),
        "source = \"files\"\nsteps = [\"frf\"]\n[data]\nidentification = \"short.csv\"\nvalidation = \"short.csv\"\n",
    )
    .unwrap();
    let o = ambid(d.path(), &["run", "wf.toml", "--out", "out", "--quiet"], 10);
    expect(&o, 3, &["short.csv", "10 samples are too few for an FRF"]);
    assert!(!d.path().join("out").exists());
    // no Rust-isms: an order of 0 names the option to leave out
    write_csv(
        &d.path().join("rec.csv"),
        "t,r,u,y",
        &record(2000),
        |_, _| {},
    );
    let o = ambid(
        d.path(),
        &["fit", "rec.csv", "--structure", "ss", "--order", "0"],
        10,
    );
    let e = expect(&o, 2, &["--order"]);
    assert!(!e.contains("None"), "{e}");
    // a huge option value is printed compactly
    let o = ambid(d.path(), &["frf", "rec.csv", "--fs", "1e300"], 10);
    let e = expect(&o, 2, &["--fs 1e300"]);
    assert!(e.len() < 400, "a {} byte message: {e}", e.len());
    let o = ambid(d.path(), &["excite", "prbs", "--fs", "0"], 10);
    expect(&o, 2, &["--fs must be a positive sample rate"]);
    // a library message that prints a huge value with `{}` is compacted too (it was 301 digits)
    let o = ambid(d.path(), &["excite", "chirp", "--f0", "1e300"], 10);
    let e = expect(&o, 2, &["f0_hz", "1.000000e300"]);
    assert!(e.len() < 300, "a {} byte message: {e}", e.len());
    let o = ambid(
        d.path(),
        &["simulate", "--amplitude", "1e300", "--out", "sim"],
        10,
    );
    let e = expect(&o, 2, &["excitation amplitude 1.000000e300 exceeds i_sat"]);
    assert!(e.len() < 300, "a {} byte message: {e}", e.len());
    assert!(!d.path().join("sim").exists());
    // a Welch segment longer than the record is refused before anything is allocated for it
    let o = ambid(
        d.path(),
        &["frf", "rec.csv", "--nperseg", "100000000000000"],
        10,
    );
    expect(
        &o,
        2,
        &["--nperseg 100000000000000 is longer than the record (2000 samples)"],
    );
}

#[test]
fn model_files_name_the_missing_field() {
    let d = tmp();
    std::fs::write(
        d.path().join("nokind.json"),
        r#"{"ts": 0.001, "a": [[0.5]]}"#,
    )
    .unwrap();
    std::fs::write(d.path().join("array.json"), "[1, 2, 3]").unwrap();
    std::fs::write(
        d.path().join("badts.json"),
        r#"{"kind": "state_space", "ts": -1}"#,
    )
    .unwrap();
    for (file, piece) in [
        (
            "nokind.json",
            "missing field `kind` (expected \"state_space\" or \"polynomial\")",
        ),
        ("array.json", "expected a JSON object"),
        ("badts.json", "field `ts` must be a positive sample time"),
    ] {
        let o = ambid(
            d.path(),
            &[
                "validate",
                file,
                "--data",
                "x.csv",
                "--controller",
                "c.toml",
            ],
            10,
        );
        let e = expect(&o, 3, &[file, piece]);
        assert!(!e.contains("None"), "{e}");
    }
}

#[test]
fn every_command_follows_one_exit_code_rule() {
    let d = tmp();
    write_csv(
        &d.path().join("rec.csv"),
        "t,r,u,y",
        &record(2000),
        |_, _| {},
    );
    // 3: a missing input file, for several commands alike
    for args in [
        &["fit", "missing.csv", "--structure", "arx", "--na", "1"][..],
        &["frf", "missing.csv"][..],
        &["order", "missing.csv"][..],
    ] {
        let o = ambid(d.path(), args, 10);
        expect(&o, 3, &["missing.csv", "cannot open"]);
    }
    // 2: clap's own usage errors and refused option values
    let o = ambid(d.path(), &["fit", "rec.csv", "--structure", "nonsense"], 10);
    assert_eq!(o.code, 2, "{}", o.stderr);
    // 5: an output that cannot be written
    let o = ambid(
        d.path(),
        &[
            "fit",
            "rec.csv",
            "--structure",
            "arx",
            "--na",
            "1",
            "--out",
            "/proc/nope/m.json",
        ],
        20,
    );
    expect(&o, 5, &["/proc/nope"]);
}

/// Model sizes a record cannot support are refused before any work (a hostile ARX 5000/5000 on
/// 20 000 samples ran > 60 s at 3.9 GB; a state space of order 500 took 7 s to fail): exit 2,
/// within a second, naming the options and the limit; a large but supported FIR still fits.
#[test]
fn oversized_models_are_refused_before_any_work() {
    let d = tmp();
    write_csv(
        &d.path().join("rec.csv"),
        "t,r,u,y",
        &record(20_000),
        |_, _| {},
    );
    let o = ambid(
        d.path(),
        &[
            "fit",
            "rec.csv",
            "--structure",
            "arx",
            "--na",
            "5000",
            "--nb",
            "5000",
        ],
        5,
    );
    expect(&o, 2, &["10000 parameters", "1000", "20000 samples"]);
    let o = ambid(
        d.path(),
        &["fit", "rec.csv", "--structure", "ss", "--order", "500"],
        5,
    );
    expect(&o, 2, &["--order 500", "100"]);
    let o = ambid(
        d.path(),
        &[
            "fit",
            "rec.csv",
            "--structure",
            "oe",
            "--nb",
            "200",
            "--nf",
            "200",
        ],
        5,
    );
    expect(&o, 2, &["--nf 200", "100"]);
    let o = ambid(
        d.path(),
        &["order", "rec.csv", "--na-max", "500", "--nb-max", "5"],
        5,
    );
    expect(&o, 2, &["--na-max 500"]);
    assert!(!d.path().join("model.json").exists() && !d.path().join("order.csv").exists());
    let o = ambid(
        d.path(),
        &[
            "fit",
            "rec.csv",
            "--structure",
            "fir",
            "--nb",
            "60",
            "--out",
            "fir.json",
        ],
        30,
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(d.path().join("fir.json").exists());
}
