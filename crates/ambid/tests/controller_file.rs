//! Controller files (`ambid::io::controller`) and `PidSpec` against the twin's controller, and
//! every error a controller file can raise.
//!
//! `AMBID_UPDATE_FIXTURES=1 cargo test -p ambid --test all controller_file::` rewrites
//! `tests/fixtures/twin_controller.toml` from `controller_toml_from_twin`.

use ambid::io::controller::{
    controller_toml_from_twin, parse_controller_str, read_controller, ControllerFormat,
    ControllerModel,
};
use ambid_core::c64;
use ambid_core::lti::{Discretisation, PidSpec};
use ambid_twin::{Twin, TwinConfig};
use std::f64::consts::PI;
use std::path::PathBuf;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn log_grid(f0: f64, f1: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| f0 * (f1 / f0).powf(k as f64 / (n - 1) as f64))
        .collect()
}

fn max_rel(got: &[c64], want: &[c64]) -> f64 {
    got.iter()
        .zip(want)
        .map(|(g, w)| (g - w).norm() / w.norm())
        .fold(0.0, f64::max)
}

/// The twin's nominal controller as a `PidSpec`.
fn twin_pid(cfg: &TwinConfig) -> PidSpec {
    let c = &cfg.controller;
    PidSpec {
        kp: c.kp,
        ki: c.ki(),
        kd: c.kd,
        derivative_cutoff_hz: Some(c.derivative_cutoff_hz),
        lowpass_hz: Some(c.lowpass_hz),
        ts: 1.0 / c.fs_hz,
        method: Discretisation::Tustin,
        delay_samples: 0,
    }
}

fn grid() -> Vec<f64> {
    log_grid(1.0, 9.9e3, 400)
}

#[test]
fn pid_spec_equals_the_twin_controller() {
    let cfg = TwinConfig::default();
    let twin = Twin::new(cfg.clone()).unwrap();
    let f = grid();
    let want = twin.controller_frf(&f).unwrap();
    let spec = twin_pid(&cfg);
    assert_eq!(spec.kp, 21_000.0);
    assert_eq!(spec.ki, 21_000.0 * 2.0 * PI * 5.0);
    assert_eq!(spec.ts, 1.0 / 20e3);
    let e = max_rel(&spec.freq_response(&f).unwrap(), &want);
    println!("PidSpec vs Twin::controller_frf, 400 points 1 Hz–9.9 kHz: max rel err {e:.2e}");
    assert!(e <= 1e-12, "PidSpec vs twin: {e:.2e}");
    let ss = spec.state_space().unwrap();
    let e = max_rel(&ss.freq_response_siso(&f).unwrap(), &want);
    assert!(e <= 1e-12, "PidSpec state space vs twin: {e:.2e}");
    let e = max_rel(
        &spec.transfer_function().unwrap().freq_response(&f).unwrap(),
        &want,
    );
    println!("PidSpec transfer function vs twin: max rel err {e:.2e}");
    assert!(e <= 1e-9, "PidSpec transfer function vs twin: {e:.2e}");
    // the same poles: z = 1, p = (α−ωd)/(α+ωd), r = (α−ωl)/(α+ωl), α = 2/Ts. Ours are exact to
    // rounding; the eigenvalues of the twin's realisation (entries up to 3e5) are good to ~1e-11.
    let alpha = 2.0 * 20e3;
    let (wd, wl) = (2.0 * PI * 4e3, 2.0 * PI * 5e3);
    let exact = [
        (alpha - wl) / (alpha + wl),
        (alpha - wd) / (alpha + wd),
        1.0,
    ];
    let mut p1: Vec<c64> = ss.poles().unwrap();
    let mut p2: Vec<c64> = twin.controller().poles().unwrap();
    for p in [&mut p1, &mut p2] {
        p.sort_by(|a, b| a.re.total_cmp(&b.re));
    }
    let mut worst = (0.0f64, 0.0f64);
    for ((a, b), z) in p1.iter().zip(&p2).zip(exact) {
        worst.0 = worst.0.max((a - z).norm());
        worst.1 = worst.1.max((b - z).norm());
    }
    println!(
        "controller poles, max abs error: PidSpec {:.1e}, twin {:.1e}",
        worst.0, worst.1
    );
    assert!(worst.0 < 1e-14 && worst.1 < 1e-10, "{worst:?}");
}

#[test]
fn other_twin_configurations_agree_too() {
    // other integrator corner, filter corners and rate (the twin keeps its integrator state, so
    // integral_corner_hz = 0 leaves a pole at z = 1 and the twin refuses the loop)
    let mut cfg = TwinConfig::default();
    cfg.controller.integral_corner_hz = 2.0;
    cfg.controller.fs_hz = 25e3;
    cfg.controller.derivative_cutoff_hz = 3e3;
    cfg.controller.lowpass_hz = 8e3;
    let twin = Twin::new(cfg.clone()).unwrap();
    let f = log_grid(1.0, 12.4e3, 200);
    let want = twin.controller_frf(&f).unwrap();
    let e = max_rel(&twin_pid(&cfg).freq_response(&f).unwrap(), &want);
    println!("variant (fs 25 kHz, other corners): max rel err {e:.2e}");
    assert!(e <= 1e-12, "{e:.2e}");
    let m = parse_controller_str(&controller_toml_from_twin(&cfg), ControllerFormat::Toml).unwrap();
    assert!(max_rel(&m.freq_response(&f).unwrap(), &want) <= 1e-12);
}

#[test]
fn the_twin_fixture_is_current_and_reproduces_the_twin() {
    let cfg = TwinConfig::default();
    let text = controller_toml_from_twin(&cfg);
    let path = fixture("twin_controller.toml");
    if std::env::var_os("AMBID_UPDATE_FIXTURES").is_some() {
        std::fs::write(&path, &text).unwrap();
    }
    let on_disk = std::fs::read_to_string(&path).unwrap();
    assert_eq!(
        on_disk, text,
        "fixture is stale: rerun with AMBID_UPDATE_FIXTURES=1"
    );
    let m = read_controller(&path).unwrap();
    let twin = Twin::new(cfg).unwrap();
    let f = grid();
    let e = max_rel(
        &m.freq_response(&f).unwrap(),
        &twin.controller_frf(&f).unwrap(),
    );
    println!("twin_controller.toml vs Twin::controller_frf: max rel err {e:.2e}");
    assert!(e <= 1e-12, "fixture vs twin: {e:.2e}");
    assert_eq!(m.ts(), twin.ts());
    m.check_ts(twin.ts()).unwrap();
    assert!(m.pid().is_some());
    assert_eq!(m.source(), Some(path.as_path()));
    assert!(
        m.description().contains("twin_controller.toml"),
        "{}",
        m.description()
    );
}

#[test]
fn tf_and_ss_forms_reproduce_the_pid() {
    let cfg = TwinConfig::default();
    let spec = twin_pid(&cfg);
    let tf = spec.transfer_function().unwrap();
    let ss = spec.state_space().unwrap();
    let f = grid();
    let want = spec.freq_response(&f).unwrap();
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:?}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let rows = |m: faer::MatRef<'_, f64>| {
        (0..m.nrows())
            .map(|i| {
                format!(
                    "[{}]",
                    list(&(0..m.ncols()).map(|j| m[(i, j)]).collect::<Vec<_>>())
                )
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let tf_toml = format!(
        "kind = \"tf\"\nts = {:?}\nnum = [{}]\nden = [{}]\n",
        spec.ts,
        list(tf.num()),
        list(tf.den())
    );
    let tf_json = format!(
        "{{\"kind\": \"tf\", \"fs_hz\": 20000, \"num\": [{}], \"den\": [{}], \"description\": \"twin PID as tf\"}}",
        list(tf.num()),
        list(tf.den())
    );
    let ss_toml = format!(
        "kind = \"ss\"\nfs_hz = 20000.0\na = [{}]\nb = [{}]\nc = [{}]\nd = [{}]\n",
        rows(ss.a()),
        rows(ss.b()),
        rows(ss.c()),
        rows(ss.d())
    );
    let ss_json = format!(
        "{{\"kind\": \"ss\", \"ts\": 5e-5, \"a\": [{}], \"b\": [{}], \"c\": [{}], \"d\": [{}]}}",
        rows(ss.a()),
        rows(ss.b()),
        rows(ss.c()),
        rows(ss.d())
    );
    for (text, format, tol) in [
        (&tf_toml, ControllerFormat::Toml, 1e-9),
        (&tf_json, ControllerFormat::Json, 1e-9),
        (&ss_toml, ControllerFormat::Toml, 1e-14),
        (&ss_json, ControllerFormat::Json, 1e-14),
    ] {
        let m = parse_controller_str(text, format).unwrap();
        let e = max_rel(&m.freq_response(&f).unwrap(), &want);
        println!("{format:?} {}: max rel err {e:.2e}", m.description());
        assert!(e <= tol, "{text}: {e:.2e}");
        m.check_ts(5e-5).unwrap();
        assert!(m.pid().is_none());
    }
    let m = parse_controller_str(&tf_json, ControllerFormat::Json).unwrap();
    assert_eq!(m.description(), "twin PID as tf");
}

#[test]
fn pid_keys_map_onto_pid_spec() {
    let text = r#"
        kind = "pid"
        kp = 100
        ki = 2000.0
        kd = 0.05
        derivative_cutoff_hz = 1000
        ts = 1e-4
        method = "tustin"
        prewarp_hz = 500.0
        delay_samples = 2
        description = "test rig"
    "#;
    let m = parse_controller_str(text, ControllerFormat::Toml).unwrap();
    let p = m.pid().unwrap();
    assert_eq!(
        *p,
        PidSpec::new(100.0, 2000.0, 0.05, 1e-4)
            .with_derivative_cutoff_hz(1000.0)
            .with_method(Discretisation::TustinPrewarp { f_hz: 500.0 })
            .with_delay_samples(2)
    );
    assert_eq!(m.description(), "test rig");
    assert_eq!(m.state_space().order(), 4);
    let zoh = r#"{"kind": "pid", "kp": 100, "ki": 0, "kd": 0, "fs_hz": 1e4, "method": "zoh",
                  "lowpass_hz": 2000}"#;
    let m = parse_controller_str(zoh, ControllerFormat::Json).unwrap();
    assert_eq!(m.pid().unwrap().method, Discretisation::Zoh);
    assert_eq!(m.pid().unwrap().lowpass_hz, Some(2000.0));
    assert!((m.ts() - 1e-4).abs() < 1e-20);
}

#[test]
fn check_ts_names_both_rates() {
    let m = ControllerModel::from_pid(PidSpec::new(1e4, 0.0, 0.0, 1e-4)).unwrap();
    let msg = m.check_ts(5e-5).unwrap_err().to_string();
    for part in [
        "ts = 1e-4 s",
        "fs 10 kHz",
        "5e-5 s (fs 20 kHz)",
        "rediscretise the controller at the data rate",
    ] {
        assert!(msg.contains(part), "`{msg}` lacks `{part}`");
    }
    // within 1e-9 relative is the same rate; beyond it is not
    m.check_ts(1e-4 * (1.0 + 5e-10)).unwrap();
    assert!(m.check_ts(1e-4 * (1.0 + 2e-9)).is_err());
    assert!(m.check_ts(0.0).is_err() && m.check_ts(f64::NAN).is_err());
    // from a file, the message names the file
    let m = read_controller(&fixture("twin_controller.toml")).unwrap();
    let msg = m.check_ts(1e-4).unwrap_err().to_string();
    assert!(
        msg.contains("controller file") && msg.contains("twin_controller.toml"),
        "{msg}"
    );
    assert!(msg.contains("ts = 5e-5 s (fs 20 kHz)"), "{msg}");
}

/// The full error chain of parsing `text`.
fn err(text: &str, format: ControllerFormat) -> String {
    match parse_controller_str(text, format) {
        Ok(m) => panic!("expected an error for\n{text}\ngot {m:?}"),
        Err(e) => format!("{e:#}"),
    }
}

fn assert_err(text: &str, format: ControllerFormat, parts: &[&str]) {
    let msg = err(text, format);
    for p in parts {
        assert!(
            msg.contains(p),
            "error `{msg}` lacks `{p}` (input:\n{text})"
        );
    }
}

const PID_OK: &str =
    "kind = \"pid\"\nkp = 1.0\nki = 0.0\nkd = 0.0\nts = 1e-4\nmethod = \"tustin\"\n";

#[test]
fn malformed_files_are_reported() {
    use ControllerFormat::{Json, Toml};
    assert_err(
        "kind = \"pid\"\nkp = = 1\n",
        Toml,
        &["malformed TOML", "line 2"],
    );
    assert_err(
        "{\"kind\": \"pid\", \"kp\": }",
        Json,
        &["malformed JSON", "line 1"],
    );
    assert_err("[1, 2]", Json, &["one object"]);
    assert_err(
        "kp = 1.0\n",
        Toml,
        &["missing key `kind`", "\"pid\", \"tf\" or \"ss\""],
    );
    assert_err("{\"kp\": 1}", Json, &["missing key `kind`"]);
    assert_err("kind = 3\n", Toml, &["`kind` must be a string"]);
    assert_err(
        "kind = \"lqg\"\n",
        Toml,
        &["unknown controller kind `lqg`", "\"pid\", \"tf\" or \"ss\""],
    );
    assert_err(
        "{\"kind\": \"PID\"}",
        Json,
        &["unknown controller kind `PID`"],
    );
    // JSON cannot spell a non-finite number
    assert_err(
        "{\"kind\": \"tf\", \"ts\": 1e-4, \"num\": [1e999], \"den\": [1]}",
        Json,
        &["malformed JSON"],
    );
}

#[test]
fn unknown_and_missing_keys_are_named() {
    use ControllerFormat::{Json, Toml};
    assert_err(
        &format!("{PID_OK}kpp = 2.0\n"),
        Toml,
        &["unknown field `kpp`", "line 7"],
    );
    assert_err(
        "{\"kind\": \"tf\", \"ts\": 1e-4, \"num\": [1], \"den\": [1], \"gain\": 2}",
        Json,
        &["unknown field `gain`"],
    );
    assert_err(
        "kind = \"ss\"\nts = 1e-4\na = [[0.5]]\nb = [[1]]\nc = [[1]]\nd = [[0]]\ne = [[1]]\n",
        Toml,
        &["unknown field `e`"],
    );
    assert_err(
        &PID_OK.replace("kd = 0.0\n", ""),
        Toml,
        &["missing field `kd`"],
    );
    assert_err(
        &PID_OK.replace("method = \"tustin\"\n", ""),
        Toml,
        &["missing field `method`"],
    );
    assert_err(
        &PID_OK.replace("tustin", "euler"),
        Toml,
        &["unknown variant `euler`", "tustin", "zoh"],
    );
    assert_err(
        &PID_OK.replace("ki = 0.0\n", ""),
        Toml,
        &["ki", "integral_corner_hz"],
    );
    assert_err(
        &format!("{PID_OK}integral_corner_hz = 5.0\n"),
        Toml,
        &["not both"],
    );
    assert_err(
        &PID_OK.replace("ts = 1e-4\n", ""),
        Toml,
        &["missing sample time"],
    );
    assert_err(
        &format!("{PID_OK}fs_hz = 1e4\n"),
        Toml,
        &["`ts`", "`fs_hz`", "not both"],
    );
    assert_err(
        &format!("{}prewarp_hz = 100.0\n", PID_OK.replace("tustin", "zoh")),
        Toml,
        &["prewarp_hz", "tustin"],
    );
    assert_err(
        "kind = \"tf\"\nts = 1e-4\nnum = [1.0]\n",
        Toml,
        &["missing field `den`"],
    );
    assert_err(
        &format!("{PID_OK}delay_samples = -1\n"),
        Toml,
        &["delay_samples", "-1"],
    );
    assert_err(
        &PID_OK.replace("kp = 1.0", "kp = \"big\""),
        Toml,
        &["kp", "invalid type"],
    );
}

#[test]
fn invalid_pid_values_are_named() {
    use ControllerFormat::Toml;
    assert_err(
        &PID_OK.replace("kd = 0.0", "kd = 0.01"),
        Toml,
        &["derivative_cutoff_hz", "improper"],
    );
    assert_err(
        &format!(
            "{}derivative_cutoff_hz = 6000\n",
            PID_OK.replace("kd = 0.0", "kd = 0.01")
        ),
        Toml,
        &["derivative_cutoff_hz", "Nyquist frequency fs/2 = 5000 Hz"],
    );
    assert_err(
        &format!("{PID_OK}lowpass_hz = 5000\n"),
        Toml,
        &["lowpass_hz", "Nyquist"],
    );
    assert_err(
        &PID_OK.replace("kp = 1.0", "kp = -1.0"),
        Toml,
        &["kp", "w - y"],
    );
    assert_err(
        &PID_OK.replace("ts = 1e-4", "ts = -1e-4"),
        Toml,
        &["`ts` must be positive"],
    );
    assert_err(
        &PID_OK.replace("ts = 1e-4", "fs_hz = 0"),
        Toml,
        &["`fs_hz` must be positive"],
    );
    assert_err(
        &format!("{PID_OK}delay_samples = 1000\n"),
        Toml,
        &["delay_samples"],
    );
    assert_err(
        &PID_OK.replace("ki = 0.0", "integral_corner_hz = -5.0"),
        Toml,
        &["integral_corner_hz", ">= 0"],
    );
}

#[test]
fn non_finite_numbers_are_named() {
    use ControllerFormat::Toml;
    assert_err(
        &PID_OK.replace("kp = 1.0", "kp = nan"),
        Toml,
        &["`kp`", "finite"],
    );
    assert_err(
        &PID_OK.replace("ki = 0.0", "ki = inf"),
        Toml,
        &["`ki`", "finite"],
    );
    assert_err(
        &PID_OK.replace("kd = 0.0", "kd = -inf"),
        Toml,
        &["kd", "finite"],
    );
    assert_err(
        &PID_OK.replace("ts = 1e-4", "ts = nan"),
        Toml,
        &["`ts`", "finite"],
    );
    assert_err(
        &PID_OK.replace("ts = 1e-4", "fs_hz = inf"),
        Toml,
        &["`fs_hz`", "finite"],
    );
    assert_err(
        &PID_OK.replace("ki = 0.0", "integral_corner_hz = nan"),
        Toml,
        &["`integral_corner_hz`", "finite"],
    );
    assert_err(
        &format!(
            "{}derivative_cutoff_hz = nan\n",
            PID_OK.replace("kd = 0.0", "kd = 0.01")
        ),
        Toml,
        &["derivative_cutoff_hz"],
    );
    assert_err(
        &format!("{PID_OK}prewarp_hz = inf\n"),
        Toml,
        &["prewarp_hz", "finite"],
    );
    assert_err(
        "kind = \"tf\"\nts = 1e-4\nnum = [1.0, nan]\nden = [1.0]\n",
        Toml,
        &["`num[1]`", "finite"],
    );
    assert_err(
        "kind = \"tf\"\nts = 1e-4\nnum = [1.0]\nden = [1.0, -inf]\n",
        Toml,
        &["`den[1]`", "finite"],
    );
    assert_err(
        "kind = \"ss\"\nts = 1e-4\na = [[0.5, 0], [0, inf]]\nb = [[1], [1]]\nc = [[1, 1]]\nd = [[0]]\n",
        Toml,
        &["`a[1][1]`", "finite"],
    );
    assert_err(
        "kind = \"ss\"\nts = 1e-4\na = [[0.5]]\nb = [[1]]\nc = [[1]]\nd = [[nan]]\n",
        Toml,
        &["`d[0][0]`", "finite"],
    );
}

#[test]
fn transfer_function_errors() {
    use ControllerFormat::{Json, Toml};
    assert_err(
        "kind = \"tf\"\nts = 1e-4\nnum = [1.0]\nden = [0.0, 1.0]\n",
        Toml,
        &["`den[0]`", "causal"],
    );
    assert_err(
        "{\"kind\": \"tf\", \"ts\": 1e-4, \"num\": [1], \"den\": []}",
        Json,
        &["`den[0]`"],
    );
    assert_err(
        "{\"kind\": \"tf\", \"ts\": 1e-4, \"num\": [0, 0], \"den\": [1]}",
        Json,
        &["C = 0"],
    );
    assert_err(
        "{\"kind\": \"tf\", \"ts\": 1e-4, \"num\": [], \"den\": [1]}",
        Json,
        &["`num`"],
    );
}

#[test]
fn state_space_errors() {
    use ControllerFormat::{Json, Toml};
    let ss = |a: &str, b: &str, c: &str, d: &str| {
        format!(
            "{{\"kind\": \"ss\", \"ts\": 1e-4, \"a\": {a}, \"b\": {b}, \"c\": {c}, \"d\": {d}}}"
        )
    };
    // non-SISO
    assert_err(
        &ss("[[0.5]]", "[[1, 0]]", "[[1]]", "[[0, 0]]"),
        Json,
        &["SISO", "d is 1×2"],
    );
    assert_err(
        &ss("[[0.5]]", "[[1]]", "[[1], [2]]", "[[0], [0]]"),
        Json,
        &["SISO", "d is 2×1"],
    );
    assert_err(
        &ss("[[0.5]]", "[[1, 0]]", "[[1]]", "[[0]]"),
        Json,
        &["SISO", "b has 2 columns"],
    );
    assert_err(
        &ss("[[0.5]]", "[[1]]", "[[1], [2]]", "[[0]]"),
        Json,
        &["SISO", "c has 2 rows"],
    );
    // wrong sizes
    assert_err(
        &ss("[[0.5, 0]]", "[[1]]", "[[1]]", "[[0]]"),
        Json,
        &["`a` must be square"],
    );
    assert_err(
        &ss("[[0.5, 0], [0]]", "[[1], [1]]", "[[1, 1]]", "[[0]]"),
        Json,
        &["`a` row 1 has 1 entries"],
    );
    assert_err(
        &ss("[[0.5]]", "[[1], [1]]", "[[1]]", "[[0]]"),
        Json,
        &["`b` must have one row per state"],
    );
    assert_err(
        &ss("[[0.5]]", "[[1]]", "[[1, 2]]", "[[0]]"),
        Json,
        &["`c` must have one column per state"],
    );
    assert_err(
        &ss("[]", "[]", "[]", "[[1]]"),
        Json,
        &["SISO", "c has 0 rows"],
    );
    assert_err(&ss("[]", "[]", "[[1]]", "[[1]]"), Json, &["c = [[]]"]);
    assert_err(
        &ss("[[0.5]]", "[[1]]", "[[1]]", "[]"),
        Json,
        &["`d` is empty"],
    );
    // a static gain is fine
    let m = parse_controller_str(&ss("[]", "[]", "[[]]", "[[3]]"), Json).unwrap();
    assert_eq!(m.freq_response(&[100.0]).unwrap()[0], c64::new(3.0, 0.0));
    // TOML too
    assert_err(
        "kind = \"ss\"\nts = 1e-4\na = [[0.5]]\nb = [[1]]\nc = [[1]]\nd = [[0, 1]]\n",
        Toml,
        &["SISO"],
    );
}

#[test]
fn file_level_errors() {
    let dir = std::env::temp_dir().join(format!("ambid-controller-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let yaml = dir.join("c.yaml");
    std::fs::write(&yaml, "kind: pid\n").unwrap();
    let msg = format!("{:#}", read_controller(&yaml).unwrap_err());
    assert!(
        msg.contains("`.yaml`") && msg.contains(".toml or .json"),
        "{msg}"
    );
    let none = dir.join("controller");
    std::fs::write(&none, PID_OK).unwrap();
    assert!(format!("{:#}", read_controller(&none).unwrap_err()).contains("no extension"));
    let missing = dir.join("missing.toml");
    let msg = format!("{:#}", read_controller(&missing).unwrap_err());
    assert!(
        msg.contains("cannot read controller file") && msg.contains("missing.toml"),
        "{msg}"
    );
    let bad = dir.join("bad.json");
    std::fs::write(
        &bad,
        "{\"kind\": \"tf\", \"ts\": 1e-4, \"num\": [1], \"den\": [0]}",
    )
    .unwrap();
    let msg = format!("{:#}", read_controller(&bad).unwrap_err());
    assert!(msg.contains("bad.json") && msg.contains("den[0]"), "{msg}");
    let good = dir.join("good.TOML");
    std::fs::write(&good, PID_OK).unwrap();
    assert!(read_controller(&good).is_ok());
    std::fs::remove_dir_all(&dir).unwrap();
}
