//! Issue 17, outputs: every command writes its outputs atomically as one set, replaces an
//! existing destination only with `--force`, leaves nothing behind when it fails or is killed
//! (stale temporaries are removed by the next write), names the path and the operating
//! system's reason when the file system refuses, refuses to delete directories it must not, and
//! writes byte-identical outputs when run twice (apart from the named timing fields).
//!
//! Each case spawns the real binary on a small input crafted in a temporary directory, with a
//! wall-clock limit enforced here, and checks the exit code (never 101), stderr and what is
//! (not) on disk.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The exit code of an output failure, for every command (docs/workflow.md, "Exit codes").
const OUTPUT_EXIT: &[i32] = &[5];

/// A fresh directory under the system's temporary directory, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let p = std::env::temp_dir().join(format!("ambid-hout-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        Self(p)
    }
    fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

struct Out {
    code: i32,
    stdout: String,
    stderr: String,
    secs: f64,
}

fn spawn(args: &[&str], cwd: &Path) -> Child {
    spawn_env(args, cwd, &[])
}

fn spawn_env(args: &[&str], cwd: &Path, env: &[(&str, &Path)]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_ambid"))
        .args(args)
        .envs(env.iter().map(|(k, v)| (*k, *v)))
        .current_dir(cwd)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn ambid")
}

/// Runs `ambid args` in `cwd`, failing the test after `limit_s` seconds.
fn ambid_in(cwd: &Path, args: &[&str], limit_s: f64) -> Out {
    ambid_env(cwd, args, &[], limit_s)
}

/// [`ambid_in`] with extra environment variables.
fn ambid_env(cwd: &Path, args: &[&str], env: &[(&str, &Path)], limit_s: f64) -> Out {
    let t0 = Instant::now();
    let mut child = spawn_env(args, cwd, env);
    loop {
        if child.try_wait().expect("try_wait").is_some() {
            break;
        }
        if t0.elapsed().as_secs_f64() > limit_s {
            let _ = child.kill();
            let _ = child.wait();
            panic!("ambid {args:?} ran past {limit_s} s");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let o = child.wait_with_output().expect("output");
    let out = Out {
        code: o.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
        secs: t0.elapsed().as_secs_f64(),
    };
    assert_ne!(out.code, 101, "panic: {}", out.stderr);
    out
}

fn ok(o: &Out) {
    assert_eq!(o.code, 0, "stdout: {}\nstderr: {}", o.stdout, o.stderr);
}

fn output_failure(o: &Out, needles: &[&str]) {
    assert!(
        OUTPUT_EXIT.contains(&o.code),
        "exit {} (want an output failure); stderr: {}",
        o.code,
        o.stderr
    );
    for n in needles {
        assert!(o.stderr.contains(n), "stderr lacks `{n}`: {}", o.stderr);
    }
}

/// Every entry of `dir` (recursively, hidden ones included), relative, sorted.
fn listing(dir: &Path) -> Vec<String> {
    fn walk(root: &Path, d: &Path, out: &mut Vec<String>) {
        if let Ok(rd) = std::fs::read_dir(d) {
            for e in rd.flatten() {
                let p = e.path();
                out.push(p.strip_prefix(root).unwrap().display().to_string());
                if p.is_dir() {
                    walk(root, &p, out);
                }
            }
        }
    }
    let mut v = Vec::new();
    walk(dir, dir, &mut v);
    v.sort();
    v
}

fn no_temps(dir: &Path) {
    let l = listing(dir);
    assert!(
        !l.iter()
            .any(|p| p.contains("ambid-tmp") || p.contains(".tmp-")),
        "temporaries left: {l:?}"
    );
}

/// A small closed-loop record (t, r, u, y at 1 kHz): first-order plant
/// y_k = 0.9 y_{k−1} + 0.5 u_{k−1}, controller u = r − 0.5 y, a ±1 pseudo-random r and a
/// little output noise, all from a fixed linear congruential generator.
fn loop_csv(n: usize) -> String {
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let mut next = || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((state >> 11) as f64) / ((1u64 << 53) as f64)
    };
    let mut s = String::from("t,r,u,y\n");
    let (mut y, mut u_prev) = (0.0f64, 0.0f64);
    for k in 0..n {
        let r = if next() < 0.5 { -1.0 } else { 1.0 };
        y = 0.9 * y + 0.5 * u_prev + 1e-3 * (next() - 0.5);
        let u = r - 0.5 * y;
        s.push_str(&format!("{:.6},{r},{u:.12},{y:.12}\n", k as f64 * 1e-3));
        u_prev = u;
    }
    s
}

#[test]
fn a_failing_second_output_leaves_no_first_output() {
    let d = TempDir::new("a_failing_second_output_");
    // the spectrum's directory cannot be created: r.csv must not be left
    let o = ambid_in(
        d.path(),
        &[
            "excite",
            "prbs",
            "--order",
            "6",
            "--periods",
            "2",
            "--out",
            "r.csv",
            "--spectrum",
            "/proc/nope/s.csv",
        ],
        10.0,
    );
    output_failure(&o, &["/proc/nope"]);
    assert_eq!(listing(d.path()), Vec::<String>::new());
    // realisations of a multisine (several files) with a failing autocorrelation output
    let o = ambid_in(
        d.path(),
        &[
            "excite",
            "multisine",
            "--period-samples",
            "200",
            "--periods",
            "1",
            "--f-min",
            "50",
            "--f-max",
            "2000",
            "--phases",
            "random",
            "--realisations",
            "3",
            "--out",
            "sub/m.csv",
            "--autocorr",
            "/proc/nope/a.csv",
        ],
        10.0,
    );
    output_failure(&o, &["/proc/nope"]);
    // not even the directory `sub` the set created is left
    assert_eq!(listing(d.path()), Vec::<String>::new());
}

#[test]
fn a_full_device_is_named_with_the_reason_and_nothing_else_is_written() {
    let d = TempDir::new("a_full_device_is_named_w");
    let prbs = ["excite", "prbs", "--order", "6", "--periods", "2"];
    let mut args = prbs.to_vec();
    args.extend(["--out", "/dev/full"]);
    let o = ambid_in(d.path(), &args, 10.0);
    output_failure(&o, &["/dev/full", "No space left on device"]);
    // the device as the second output: the first is not renamed into place
    let mut args = prbs.to_vec();
    args.extend(["--out", "r.csv", "--spectrum", "/dev/full"]);
    let o = ambid_in(d.path(), &args, 10.0);
    output_failure(&o, &["/dev/full", "No space left on device"]);
    assert_eq!(listing(d.path()), Vec::<String>::new());
    // a special file that accepts the bytes is written in place without --force
    let mut args = prbs.to_vec();
    args.extend(["--out", "r.csv", "--spectrum", "/dev/null"]);
    ok(&ambid_in(d.path(), &args, 10.0));
    assert_eq!(listing(d.path()), vec!["r.csv".to_string()]);
}

#[test]
fn an_unwritable_place_is_named_with_the_reason() {
    let d = TempDir::new("an_unwritable_place_is_n");
    let o = ambid_in(
        d.path(),
        &["excite", "prbs", "--order", "5", "--out", "/proc/rep"],
        10.0,
    );
    output_failure(
        &o,
        &["/proc/rep", "/proc is not a writable directory", "os error"],
    );
    // a directory where a file is expected
    std::fs::create_dir(d.path().join("adir")).unwrap();
    let o = ambid_in(
        d.path(),
        &["excite", "prbs", "--order", "5", "--out", "adir", "--force"],
        10.0,
    );
    output_failure(&o, &["adir", "is a directory"]);
    // the same file as two outputs of one command
    let o = ambid_in(
        d.path(),
        &[
            "excite",
            "prbs",
            "--order",
            "5",
            "--out",
            "x.csv",
            "--spectrum",
            "./x.csv",
        ],
        10.0,
    );
    output_failure(&o, &["x.csv", "two different outputs"]);
    assert_eq!(listing(d.path()), vec!["adir".to_string()]);
    // `run` into a directory under /proc: exit 5 (an output failure), path named
    let o = ambid_in(
        d.path(),
        &[
            "run",
            "--steps",
            "excitation",
            "--quiet",
            "--out",
            "/proc/rep",
        ],
        60.0,
    );
    assert_eq!(o.code, 5, "{}", o.stderr);
    assert!(
        o.stderr.contains("/proc/rep") && o.stderr.contains("not a writable directory"),
        "{}",
        o.stderr
    );
}

#[test]
fn every_writing_command_replaces_an_existing_file_only_with_force() {
    let d = TempDir::new("every_writing_command_re");
    std::fs::write(d.path().join("data.csv"), loop_csv(4000)).unwrap();
    let mine = b"my own file\n";
    let cases: [(&[&str], &str); 4] = [
        (&["frf", "data.csv", "--out", "frf.csv"], "frf.csv"),
        (
            &[
                "fit",
                "data.csv",
                "--structure",
                "arx",
                "--out",
                "model.json",
            ],
            "model.json",
        ),
        (
            &[
                "order",
                "data.csv",
                "--na-max",
                "2",
                "--nb-max",
                "2",
                "--out",
                "order.csv",
            ],
            "order.csv",
        ),
        (
            &["excite", "prbs", "--order", "5", "--out", "r.csv"],
            "r.csv",
        ),
    ];
    for (args, file) in cases {
        let path = d.path().join(file);
        std::fs::write(&path, mine).unwrap();
        let o = ambid_in(d.path(), args, 20.0);
        output_failure(&o, &[file, "--force"]);
        assert_eq!(
            std::fs::read(&path).unwrap(),
            mine,
            "{args:?} touched {file}"
        );
        let mut forced = args.to_vec();
        forced.push("--force");
        ok(&ambid_in(d.path(), &forced, 20.0));
        let new = std::fs::read(&path).unwrap();
        assert_ne!(new, mine, "{args:?} with --force did not replace {file}");
        assert!(!new.is_empty());
    }
    // `init` (exit 5, the workflow's output class)
    std::fs::write(d.path().join("workflow.toml"), mine).unwrap();
    let o = ambid_in(d.path(), &["init"], 10.0);
    assert_eq!(o.code, 5, "{}", o.stderr);
    assert!(o.stderr.contains("workflow.toml") && o.stderr.contains("--force"));
    assert_eq!(std::fs::read(d.path().join("workflow.toml")).unwrap(), mine);
    ok(&ambid_in(d.path(), &["init", "--force"], 10.0));
    no_temps(d.path());
}

#[test]
fn run_refuses_to_replace_the_current_directory_its_ancestors_and_its_inputs() {
    let d = TempDir::new("run_refuses_to_replace_t");
    let work = d.path().join("work");
    std::fs::create_dir_all(work.join("in")).unwrap();
    std::fs::write(work.join("keep.txt"), b"keep").unwrap();
    let before = listing(d.path());
    let args = |out: &str| {
        vec![
            "run".to_string(),
            "--steps".into(),
            "excitation".into(),
            "--quiet".into(),
            "--out".into(),
            out.to_string(),
            "--force".into(),
        ]
    };
    for (out, why) in [
        (".", "the current directory"),
        ("..", "an ancestor of the current directory"),
        ("/", "the root directory"),
    ] {
        let a = args(out);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let o = ambid_in(&work, &a, 20.0);
        assert_eq!(o.code, 5, "--out {out}: {}", o.stderr);
        assert!(
            o.stderr.contains("refusing to replace") && o.stderr.contains(why),
            "--out {out}: {}",
            o.stderr
        );
    }
    // the home directory (HOME pointed at a directory of this test)
    let home = d.path().join("home");
    std::fs::create_dir(&home).unwrap();
    let o = ambid_env(
        &work,
        &[
            "run",
            "--steps",
            "excitation",
            "--quiet",
            "--out",
            home.to_str().unwrap(),
            "--force",
        ],
        &[("HOME", &home)],
        20.0,
    );
    assert_eq!(o.code, 5, "{}", o.stderr);
    assert!(o.stderr.contains("the home directory"), "{}", o.stderr);
    std::fs::remove_dir(&home).unwrap();
    // a directory holding the workflow file
    ok(&ambid_in(&work, &["init", "in/wf.toml"], 10.0));
    let o = ambid_in(
        &work,
        &[
            "run",
            "in/wf.toml",
            "--steps",
            "excitation",
            "--quiet",
            "--out",
            "in",
            "--force",
        ],
        20.0,
    );
    assert_eq!(o.code, 5, "{}", o.stderr);
    assert!(o.stderr.contains("input file"), "{}", o.stderr);
    let mut after = listing(d.path());
    after.retain(|p| p != "work/in/wf.toml");
    assert_eq!(after, before, "a refused run changed the files");
}

/// The pid of a process that has ended (so that its temporaries count as stale).
fn dead_pid() -> u32 {
    let mut c = Command::new("true").spawn().unwrap();
    let pid = c.id();
    c.wait().unwrap();
    pid
}

#[test]
fn stale_temporaries_of_a_killed_run_are_removed_by_the_next_write() {
    let d = TempDir::new("stale_temporaries_of_a_k");
    let dead = dead_pid();
    assert!(!Path::new(&format!("/proc/{dead}")).exists());
    // what a run or a file command killed while writing leaves (old and legacy patterns)
    for stale in [
        format!(".rep.ambid-tmp-{dead}"),
        format!(".rep.ambid-tmp-{dead}.old"),
        format!(".rep.tmp-{dead}"),
    ] {
        std::fs::create_dir_all(d.path().join(&stale).join("figures")).unwrap();
        std::fs::write(d.path().join(&stale).join("figures/x.csv"), b"half").unwrap();
    }
    std::fs::write(d.path().join(format!(".r.csv.ambid-tmp-{dead}")), b"half").unwrap();
    // not ours or not stale: kept
    let keep = [
        ".rep.ambid-tmp-notapid".to_string(),
        format!(".other.ambid-tmp-{dead}"),
        format!(".rep.ambid-tmp-{}", std::process::id()), // a live process
        "rep.ambid-tmp-1".to_string(),
    ];
    for k in &keep {
        std::fs::write(d.path().join(k), b"mine").unwrap();
    }
    ok(&ambid_in(
        d.path(),
        &["run", "--steps", "excitation", "--quiet", "--out", "rep"],
        60.0,
    ));
    ok(&ambid_in(
        d.path(),
        &["excite", "prbs", "--order", "5", "--out", "r.csv"],
        10.0,
    ));
    let mut want: Vec<String> = keep.to_vec();
    want.extend(["r.csv".into(), "rep".into()]);
    want.sort();
    let top: Vec<String> = listing(d.path())
        .into_iter()
        .filter(|p| !p.contains('/'))
        .collect();
    assert_eq!(top, want);
}

#[test]
fn a_run_killed_at_any_time_leaves_nothing_the_next_run_does_not_clean() {
    let d = TempDir::new("a_run_killed_at_any_time");
    let args = [
        "run",
        "--steps",
        "excitation,frf,models",
        "--quiet",
        "--out",
        "rep",
        "--force",
    ];
    // kill while the temporary output directory exists (if the run gets there before it ends)
    let mut child = spawn(&args, d.path());
    let t0 = Instant::now();
    let mut killed_while_writing = false;
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if listing(d.path())
            .iter()
            .any(|p| p.starts_with(".rep.ambid-tmp-"))
        {
            child.kill().unwrap(); // SIGKILL
            killed_while_writing = true;
            break;
        }
        assert!(t0.elapsed().as_secs_f64() < 60.0, "run past 60 s");
        std::thread::sleep(Duration::from_micros(200));
    }
    let _ = child.wait();
    eprintln!("killed while writing: {killed_while_writing}");
    if killed_while_writing {
        // the temporary is left (no signal handler), the destination is absent or whole
        assert!(listing(d.path())
            .iter()
            .any(|p| p.starts_with(".rep.ambid-tmp-")));
        assert!(!d.path().join("rep").exists() || d.path().join("rep/report.html").exists());
    }
    // and killed early, during the computation
    let mut child = spawn(&args, d.path());
    std::thread::sleep(Duration::from_millis(50));
    child.kill().unwrap();
    let _ = child.wait();
    let o = ambid_in(d.path(), &args, 60.0);
    ok(&o);
    no_temps(d.path());
    assert!(d.path().join("rep/report.html").exists());
    assert!(d.path().join("rep/summary.json").exists());
}

/// Every file under `dir`, relative path → bytes, with the timing fields named by
/// [`ambid::workflow::TIMING_KEY`] masked (summary.json's object, and the rows of the summary
/// table in report.html and tables/summary.csv).
fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let key = ambid::workflow::TIMING_KEY;
    let mut v = Vec::new();
    for rel in listing(dir) {
        let p = dir.join(&rel);
        if p.is_dir() {
            continue;
        }
        let bytes = std::fs::read(&p).unwrap();
        let masked = if rel == "rep/summary.json" {
            let mut j: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
            let t = j.as_object_mut().unwrap().remove(key);
            assert!(
                t.is_some_and(|t| t.is_object()),
                "summary.json has no `{key}`"
            );
            serde_json::to_vec(&j).unwrap()
        } else if rel.ends_with(".html") || rel.ends_with(".csv") {
            let text = String::from_utf8(bytes).unwrap();
            text.lines()
                .filter(|l| !l.contains(&format!("{key}.")))
                .collect::<Vec<_>>()
                .join("\n")
                .into_bytes()
        } else {
            bytes
        };
        v.push((rel, masked));
    }
    v
}

fn same_outputs(a: &Path, b: &Path, what: &str) {
    let (sa, sb) = (snapshot(a), snapshot(b));
    assert!(!sa.is_empty(), "{what}: no outputs");
    assert_eq!(
        sa.iter().map(|x| &x.0).collect::<Vec<_>>(),
        sb.iter().map(|x| &x.0).collect::<Vec<_>>(),
        "{what}: different files"
    );
    for ((name, x), (_, y)) in sa.iter().zip(&sb) {
        if x != y {
            let k = x.iter().zip(y).take_while(|(a, b)| a == b).count();
            let show = |v: &[u8]| {
                String::from_utf8_lossy(&v[k.saturating_sub(80)..(k + 80).min(v.len())])
                    .into_owned()
            };
            panic!(
                "{what}: {name} differs between two runs at byte {k}:\n{}\n---\n{}",
                show(x),
                show(y)
            );
        }
    }
}

#[test]
fn repeated_runs_give_byte_identical_outputs_apart_from_the_timings() {
    let d = TempDir::new("repeated_runs_give_byte_");
    std::fs::write(d.path().join("data.csv"), loop_csv(4000)).unwrap();
    let t0 = Instant::now();
    for k in ["1", "2"] {
        let dir = format!("run{k}");
        std::fs::create_dir(d.path().join(&dir)).unwrap();
        let o = ambid_in(
            d.path(),
            &[
                "run",
                "--steps",
                "excitation,frf,models",
                "--quiet",
                "--out",
                &format!("{dir}/rep"),
            ],
            60.0,
        );
        ok(&o);
        let sub = |f: &str| format!("{dir}/{f}");
        for args in [
            vec!["frf", "data.csv", "--out", &sub("frf.csv")],
            vec![
                "fit",
                "data.csv",
                "--structure",
                "oe",
                "--nb",
                "1",
                "--nf",
                "1",
                "--out",
                &sub("model.json"),
            ],
            vec![
                "excite",
                "multisine",
                "--period-samples",
                "400",
                "--periods",
                "2",
                "--phases",
                "random",
                "--out",
                &sub("ms.csv"),
                "--spectrum",
                &sub("ms_spec.csv"),
            ],
            vec![
                "simulate",
                "--mode",
                "linear",
                "--order",
                "6",
                "--periods",
                "2",
                "--truth-points",
                "50",
                "--out",
                &sub("sim"),
            ],
        ] {
            let o = ambid_in(d.path(), &args, 60.0);
            ok(&o);
        }
    }
    same_outputs(&d.path().join("run1"), &d.path().join("run2"), "outputs");
    // the summary names the timing fields, and they are the only masked lines
    let s = std::fs::read_to_string(d.path().join("run1/rep/summary.json")).unwrap();
    assert!(s.contains(&format!("\"{}\"", ambid::workflow::TIMING_KEY)));
    no_temps(d.path());
    eprintln!("determinism runs: {:.1} s", t0.elapsed().as_secs_f64());
}

#[test]
fn a_failed_simulate_leaves_no_file_and_no_directory() {
    let d = TempDir::new("a_failed_simulate_leaves");
    // truth.csv exists: refused before any work, data.csv not written
    std::fs::create_dir(d.path().join("sim")).unwrap();
    std::fs::write(d.path().join("sim/truth.csv"), b"mine").unwrap();
    let o = ambid_in(
        d.path(),
        &[
            "simulate",
            "--mode",
            "linear",
            "--order",
            "5",
            "--periods",
            "1",
            "--out",
            "sim",
        ],
        30.0,
    );
    output_failure(&o, &["truth.csv", "--force"]);
    assert!(o.secs < 10.0);
    assert_eq!(
        listing(d.path()),
        vec!["sim".to_string(), "sim/truth.csv".to_string()]
    );
    // an output directory that cannot be created: named, nothing left
    let o = ambid_in(
        d.path(),
        &[
            "simulate",
            "--mode",
            "linear",
            "--order",
            "5",
            "--periods",
            "1",
            "--out",
            "/proc/sim",
        ],
        30.0,
    );
    output_failure(&o, &["/proc/sim"]);
}
