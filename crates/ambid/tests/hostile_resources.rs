//! Issue 17, "no hang, bounded memory, controllers checked": each hostile input of the issue
//! runs the real binary on a small crafted input with a wall-clock limit enforced here (spawn,
//! poll, kill and fail past the limit), and checks the exit code (never 101, the panic code),
//! that stderr names what is wrong and the limit, and what is (not) written. Memory cases never
//! allocate gigabytes: the files only *declare* huge sizes, and the error must come before the
//! allocation (a `ulimit -v` of 1 GB makes an allocation attempt an abort, which fails the
//! test).

use crate::common;
use crate::common::{s, tmpdir};
use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Wall-clock limit of one command (test profile, shared 2-core machine; the issue's bar is
/// 10 s for a release build).
const LIMIT: Duration = Duration::from_secs(30);

struct Run {
    code: i32,
    stdout: String,
    stderr: String,
    secs: f64,
}

/// Runs `ambid args…` under `ulimit -v 1000000` (1 GB of address space) when `sh` is there,
/// kills it past [`LIMIT`].
fn run(args: &[&str]) -> Run {
    let bin = env!("CARGO_BIN_EXE_ambid");
    let mut cmd = if Path::new("/bin/sh").exists() {
        let mut c = Command::new("/bin/sh");
        c.arg("-c")
            .arg("ulimit -v 1000000 2>/dev/null; exec \"$0\" \"$@\"")
            .arg(bin)
            .args(args);
        c
    } else {
        let mut c = Command::new(bin);
        c.args(args);
        c
    };
    let t0 = Instant::now();
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the ambid binary starts");
    // drain the pipes on threads so that a chatty child cannot block
    let mut so = child.stdout.take().unwrap();
    let mut se = child.stderr.take().unwrap();
    let to = std::thread::spawn(move || {
        let mut b = String::new();
        let _ = std::io::Read::read_to_string(&mut so, &mut b);
        b
    });
    let te = std::thread::spawn(move || {
        let mut b = String::new();
        let _ = std::io::Read::read_to_string(&mut se, &mut b);
        b
    });
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        if t0.elapsed() > LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("`ambid {}` ran past {LIMIT:?}", args.join(" "));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let secs = t0.elapsed().as_secs_f64();
    let r = Run {
        code: status.code().unwrap_or(-1),
        stdout: to.join().unwrap(),
        stderr: te.join().unwrap(),
        secs,
    };
    assert_ne!(r.code, 101, "panic:\n{}", r.stderr);
    assert_ne!(
        r.code, -1,
        "killed by a signal (an allocation abort?):\n{}",
        r.stderr
    );
    r
}

/// A small closed-loop-like record `t,r,u,y` (white noise, 4096 samples at 20 kHz).
fn small_record(dir: &Path) -> std::path::PathBuf {
    let n = 4096;
    let mut x: u64 = 12345;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut text = String::from("t,r,u,y\n");
    for k in 0..n {
        let r = rnd();
        let y = 1e-6 * rnd();
        text.push_str(&format!("{},{r},{},{y}\n", k as f64 * 5e-5, r - 1e4 * y));
    }
    let p = dir.join("data.csv");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn validate_of_a_400_state_model_with_one_controllable_mode_finishes() {
    let dir = tmpdir("hr-validate400");
    let n = 400;
    let a: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| if i == j { 0.5 } else { 0.0 }).collect())
        .collect();
    let model = serde_json::json!({
        "kind": "state_space", "ts": 5e-5,
        "a": a, "b": vec![vec![1e-9]; n], "c": vec![vec![1.0; n]], "d": [[0.0]],
        "input": "u", "output": "y", "meta": {}
    });
    let mp = dir.join("model.json");
    std::fs::write(&mp, model.to_string()).unwrap();
    let data = small_record(&dir);
    let out = dir.join("val");
    let r = run(&[
        "validate",
        s(&mp),
        "--data",
        s(&data),
        "--controller",
        common::CONTROLLER,
        "--out",
        s(&out),
    ]);
    // either a validation (the model is nonsense for this record) or a clear error; never a
    // hang in the zeros of the 401×401 pencil
    assert!(
        r.code == 0 || r.stderr.contains("error"),
        "code {}:\n{}{}",
        r.code,
        r.stdout,
        r.stderr
    );
    println!(
        "validate of a 400-state model: {:.2} s, exit {}",
        r.secs, r.code
    );
}

#[test]
fn frf_with_a_5000_tap_controller_is_refused_at_once_and_256_taps_run() {
    let dir = tmpdir("hr-taps");
    let data = small_record(&dir);
    let taps = |n: usize| {
        let num: Vec<String> = (0..n)
            .map(|k| format!("{:e}", 1e4 / (1.0 + k as f64)))
            .collect();
        format!(
            "kind = \"tf\"\nts = 5e-5\nnum = [{}]\nden = [1.0]\n",
            num.join(", ")
        )
    };
    let big = dir.join("fir5000.toml");
    std::fs::write(&big, taps(5000)).unwrap();
    let out = dir.join("frf.csv");
    let r = run(&["frf", s(&data), "--controller", s(&big), "--out", s(&out)]);
    assert_ne!(r.code, 0);
    assert!(
        r.stderr.contains("fir5000.toml")
            && r.stderr.contains("MAX_CONTROLLER_ORDER = 256")
            && r.stderr.contains("4999"),
        "{}",
        r.stderr
    );
    assert!(r.secs < 10.0, "{} s", r.secs);
    assert!(!out.exists());
    // at the limit it runs, and its response (Horner's rule) is the FIR's
    let ok = dir.join("fir257.toml");
    std::fs::write(&ok, taps(257)).unwrap();
    let r = run(&[
        "frf",
        s(&data),
        "--controller",
        s(&ok),
        "--no-screen",
        "--out",
        s(&out),
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    println!("frf with a 257-tap controller: {:.2} s", r.secs);
    let c = ambid::io::read_controller(&ok).unwrap();
    let f = [100.0, 3210.0];
    let h = c.freq_response(&f).unwrap();
    for (fk, hk) in f.iter().zip(&h) {
        let want: ambid_core::c64 = (0..257)
            .map(|k| {
                ambid_core::c64::from_polar(
                    1e4 / (1.0 + k as f64),
                    -2.0 * std::f64::consts::PI * fk * 5e-5 * k as f64,
                )
            })
            .sum();
        assert!((hk - want).norm() <= 1e-12 * want.norm(), "{hk} vs {want}");
    }
}

#[test]
fn simulate_with_a_billion_truth_points_is_refused_before_anything_is_written() {
    let dir = tmpdir("hr-truth");
    let out = dir.join("sim");
    let r = run(&[
        "simulate",
        "--truth-points",
        "1000000000",
        "--mode",
        "linear",
        "--out",
        s(&out),
    ]);
    assert_ne!(r.code, 0);
    assert!(
        r.stderr.contains("--truth-points 1000000000") && r.stderr.contains("1000000"),
        "{}",
        r.stderr
    );
    assert!(r.secs < 10.0, "{} s", r.secs);
    assert!(!out.join("data.csv").exists() && !out.join("truth.csv").exists());
}

/// A designed excitation longer than a simulation may record (50 000 PRBS periods, 2.6·10⁸
/// samples, under the allocation limit of `run`) is refused from the plan, before the excitation
/// is generated: exit 2, at once, nothing written.
#[test]
fn simulate_of_a_record_too_long_to_hold_is_refused_from_the_plan() {
    let dir = tmpdir("hr-longsim");
    let out = dir.join("sim");
    let r = run(&[
        "simulate",
        "--periods",
        "50000",
        "--mode",
        "linear",
        "--out",
        s(&out),
    ]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.contains("255750000 samples") && r.stderr.contains("MAX_SIM_SAMPLES"),
        "{}",
        r.stderr
    );
    assert!(r.secs < 10.0, "{} s", r.secs);
    assert!(!out.exists());
}

/// A zip archive with one stored member `name` holding `data` but *declaring* `declared`
/// uncompressed bytes in both headers (CRC of the real data).
fn zip_declaring(name: &str, data: &[u8], declared: u32) -> Vec<u8> {
    let crc = {
        let mut c = flate2::Crc::new();
        c.update(data);
        c.sum()
    };
    let mut z = Vec::new();
    let local = |z: &mut Vec<u8>| {
        z.extend_from_slice(&0x0403_4b50u32.to_le_bytes());
        z.extend_from_slice(&[20, 0, 0, 0, 0, 0, 0, 0, 0, 0]); // version, flags, stored, time, date
        z.extend_from_slice(&crc.to_le_bytes());
        z.extend_from_slice(&(data.len() as u32).to_le_bytes());
        z.extend_from_slice(&declared.to_le_bytes());
        z.extend_from_slice(&(name.len() as u16).to_le_bytes());
        z.extend_from_slice(&0u16.to_le_bytes());
        z.extend_from_slice(name.as_bytes());
    };
    local(&mut z);
    z.extend_from_slice(data);
    let cd = z.len();
    z.extend_from_slice(&0x0201_4b50u32.to_le_bytes());
    z.extend_from_slice(&[20, 0, 20, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
    z.extend_from_slice(&crc.to_le_bytes());
    z.extend_from_slice(&(data.len() as u32).to_le_bytes());
    z.extend_from_slice(&declared.to_le_bytes());
    z.extend_from_slice(&(name.len() as u16).to_le_bytes());
    z.extend_from_slice(&[0; 12]); // extra, comment, disk, internal, external attributes
    z.extend_from_slice(&0u32.to_le_bytes()); // offset of the local header
    z.extend_from_slice(name.as_bytes());
    let cd_len = z.len() - cd;
    z.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    z.extend_from_slice(&[0, 0, 0, 0, 1, 0, 1, 0]);
    z.extend_from_slice(&(cd_len as u32).to_le_bytes());
    z.extend_from_slice(&(cd as u32).to_le_bytes());
    z.extend_from_slice(&0u16.to_le_bytes());
    z
}

#[test]
fn an_npz_member_declaring_a_gigabyte_is_refused_before_inflating() {
    let dir = tmpdir("hr-npz");
    let p = dir.join("bomb.npz");
    std::fs::write(&p, zip_declaring("y.npy", b"\x93NUMPY", 1 << 30)).unwrap();
    let out = dir.join("sim");
    let r = run(&["simulate", "--excitation-file", s(&p), "--out", s(&out)]);
    assert_ne!(r.code, 0);
    assert!(!out.exists());
    assert!(
        r.stderr.contains("bomb.npz")
            && r.stderr.contains("1024.0 MiB")
            && r.stderr.contains("512 MiB"),
        "{}",
        r.stderr
    );
}

#[test]
fn a_npy_array_declaring_more_than_the_limit_is_refused() {
    // a shape of 2^27 float64 values (1 GiB) in a file that does hold them is not read whole:
    // the header alone is checked (the data part here is short, so the older check on the file
    // size would also catch it; the message must name the limit when the file is large enough)
    let dir = tmpdir("hr-npy");
    let header = "{'descr': '<f8', 'fortran_order': False, 'shape': (134217728,), }";
    let mut h = header.to_string();
    while (10 + h.len() + 1) % 64 != 0 {
        h.push(' ');
    }
    h.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(h.len() as u16).to_le_bytes());
    bytes.extend_from_slice(h.as_bytes());
    let p = dir.join("big.npy");
    let mut f = std::fs::File::create(&p).unwrap();
    f.write_all(&bytes).unwrap();
    // a sparse file of the declared length: no disk space, no memory
    f.set_len(bytes.len() as u64 + (1 << 30)).unwrap();
    drop(f);
    let out = dir.join("sim");
    let r = run(&["simulate", "--excitation-file", s(&p), "--out", s(&out)]);
    assert_ne!(r.code, 0);
    assert!(!out.exists());
    assert!(
        r.stderr.contains("big.npy") && r.stderr.contains("512 MiB"),
        "{}",
        r.stderr
    );
    assert!(r.secs < 10.0);
}

#[test]
fn a_mat_file_whose_compressed_variable_declares_a_gigabyte_is_refused_before_inflating() {
    let dir = tmpdir("hr-mat");
    let mut header = vec![b' '; 128];
    header[..19].copy_from_slice(b"MATLAB 5.0 MAT-file");
    header[124..126].copy_from_slice(&0x0100u16.to_le_bytes());
    header[126..128].copy_from_slice(b"IM");
    // inflated: an miMATRIX tag declaring 1 GiB, then zeros (compress to almost nothing)
    let mut inner = Vec::new();
    inner.extend_from_slice(&14u32.to_le_bytes());
    inner.extend_from_slice(&(1u32 << 30).to_le_bytes());
    inner.extend_from_slice(&[0u8; 1 << 16]);
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    z.write_all(&inner).unwrap();
    let comp = z.finish().unwrap();
    let mut bytes = header;
    bytes.extend_from_slice(&15u32.to_le_bytes());
    bytes.extend_from_slice(&(comp.len() as u32).to_le_bytes());
    bytes.extend_from_slice(&comp);
    let p = dir.join("bomb.mat");
    std::fs::write(&p, bytes).unwrap();
    let out = dir.join("sim");
    let r = run(&["simulate", "--excitation-file", s(&p), "--out", s(&out)]);
    assert_ne!(r.code, 0);
    assert!(!out.exists());
    assert!(
        r.stderr.contains("bomb.mat") && r.stderr.contains("512 MiB"),
        "{}",
        r.stderr
    );
}

/// The controller check on 20 random rigs (linear twin, seed excitation at 10 % of i_sat, 6
/// periods, own noise seed each): the rig's own controller file never warns, in both the
/// periodic and the Welch path; a controller with 40 % less gain (kp and kd) always warns;
/// another rig's controller warns whenever it really differs (its exact response is more than
/// 10 % off on the median line of the quality band, from the twins' truth).
#[test]
fn the_controller_check_holds_on_20_random_rigs() {
    use ambid::analysis::{analyze, controller_mismatch, FrfSettings, Record};
    use ambid::io::controller::{
        controller_toml_from_twin, parse_controller_str, ControllerFormat,
    };
    let ctrl = |cfg: &ambid_twin::TwinConfig| {
        parse_controller_str(&controller_toml_from_twin(cfg), ControllerFormat::Toml)
            .unwrap()
            .state_space()
            .clone()
    };
    let mut worst_own: f64 = 0.0;
    let (mut other_checked, mut other_warned) = (0, 0);
    for rig in 1..=20u64 {
        let out = common::seed_record_on_rig(rig, 100 + rig, 0.1, 6);
        let cfg = ambid_twin::random_rig(rig).unwrap();
        let rec = &out.record;
        let record = Record {
            r: &rec.r,
            u: &rec.u,
            y: &rec.y,
            i: None,
            fs: 1.0 / rec.ts,
        };
        let mut settings = FrfSettings::periodic(5115, 1);
        settings.controller = Some(ctrl(&cfg));
        let res = analyze(&record, &settings, None).unwrap();
        assert!(
            !res.warnings.iter().any(|w| w.contains("does not match")),
            "rig {rig}: own controller flagged: {:?}",
            res.warnings
        );
        let band = res.quality.band;
        let stat = |c: &ambid_core::lti::StateSpace| {
            let f = res.frf.f_hz();
            let want = out.twin.controller_frf(f).unwrap();
            let got = c.freq_response_siso(f).unwrap();
            let mut d: Vec<f64> = (0..f.len())
                .filter(|&k| f[k] >= band.0 && f[k] <= band.1)
                .map(|k| ((got[k] - want[k]) / want[k]).norm())
                .collect();
            d.sort_by(f64::total_cmp);
            d[d.len() / 2]
        };
        worst_own = worst_own.max(stat(settings.controller.as_ref().unwrap()));
        let mut weak = cfg.clone();
        weak.controller.kp *= 0.6;
        weak.controller.kd *= 0.6;
        let w = controller_mismatch(&res.frf, &ctrl(&weak), band).unwrap();
        assert!(
            w.is_some(),
            "rig {rig}: a 40 % weaker controller passed (true median error {:.3})",
            stat(&ctrl(&weak))
        );
        let w = w.unwrap();
        assert!(
            w.contains("T_ry/T_ru") && w.contains("plant_indirect"),
            "{w}"
        );
        let other = ctrl(&ambid_twin::random_rig(rig + 1000).unwrap());
        if stat(&other) > 0.10 {
            other_checked += 1;
            if controller_mismatch(&res.frf, &other, band)
                .unwrap()
                .is_some()
            {
                other_warned += 1;
            }
        }
        // the Welch path runs the same check
        if rig <= 3 {
            let mut wset = FrfSettings::welch(4096);
            wset.controller = Some(ctrl(&cfg));
            let res = analyze(&record, &wset, None).unwrap();
            assert!(
                !res.warnings.iter().any(|w| w.contains("does not match")),
                "rig {rig} (Welch): {:?}",
                res.warnings
            );
            wset.controller = Some(ctrl(&weak));
            let res = analyze(&record, &wset, None).unwrap();
            assert!(
                res.warnings.iter().any(|w| w.contains("does not match")),
                "rig {rig} (Welch): a 40 % weaker controller passed"
            );
        }
    }
    println!(
        "own controller file vs twin: worst median error {worst_own:.2e}; another rig's controller \
         (> 10 % off): {other_warned}/{other_checked} flagged"
    );
    assert!(worst_own < 1e-9, "{worst_own}");
    assert_eq!(other_warned, other_checked);
}

#[test]
fn frf_with_a_controller_that_did_not_run_warns_and_names_the_estimate_to_trust() {
    let dir = tmpdir("hr-wrongctrl");
    let out = common::seed_record_on_rig(7, 3, 0.1, 4);
    let rec = &out.record;
    let data = dir.join("data.csv");
    ambid::io::write_time_csv(
        &data,
        &[("t", &rec.t), ("r", &rec.r), ("u", &rec.u), ("y", &rec.y)],
    )
    .unwrap();
    let mut cfg = ambid_twin::random_rig(7).unwrap();
    let good = dir.join("good.toml");
    std::fs::write(
        &good,
        ambid::io::controller::controller_toml_from_twin(&cfg),
    )
    .unwrap();
    cfg.controller.kp *= 0.6;
    cfg.controller.kd *= 0.6;
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, ambid::io::controller::controller_toml_from_twin(&cfg)).unwrap();
    for (file, warn) in [(&good, false), (&bad, true)] {
        let o = dir.join("frf.csv");
        let r = run(&[
            "frf",
            s(&data),
            "--period-samples",
            "5115",
            "--controller",
            s(file),
            "--out",
            s(&o),
            "--force",
        ]);
        assert_eq!(r.code, 0, "{}", r.stderr);
        assert_eq!(
            r.stderr
                .contains("does not match the controller the data were measured with"),
            warn,
            "{}",
            r.stderr
        );
        if warn {
            assert!(r.stderr.contains("trust the joint estimate P = T_ry/T_ru"));
        }
    }
}

#[test]
fn frf_of_dev_zero_stops_at_the_line_length_limit() {
    let dir = tmpdir("hr-devzero");
    let out = dir.join("z.csv");
    let r = run(&["frf", "/dev/zero", "--fs", "1000", "--out", s(&out)]);
    assert_ne!(r.code, 0);
    assert!(
        r.stderr.contains("/dev/zero") && r.stderr.contains("line 1") && r.stderr.contains("1 MiB"),
        "{}",
        r.stderr
    );
    assert!(r.secs < 10.0);
    assert!(!out.exists());
}

#[test]
fn an_excitation_file_longer_than_the_simulation_limit_is_refused_after_reading() {
    // 2^23 + 1 zeros in a deflated .npz member: 64 MiB as f64, a few hundred kB on disk
    let dir = tmpdir("hr-longexc");
    let n: usize = (1 << 23) + 1;
    let mut npy = b"\x93NUMPY\x01\x00".to_vec();
    let mut h = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({n},), }}");
    while (10 + h.len() + 1) % 64 != 0 {
        h.push(' ');
    }
    h.push('\n');
    npy.extend_from_slice(&(h.len() as u16).to_le_bytes());
    npy.extend_from_slice(h.as_bytes());
    npy.resize(npy.len() + 8 * n, 0);
    let p = dir.join("long.npz");
    let mut zw = zip::ZipWriter::new(std::fs::File::create(&p).unwrap());
    zw.start_file(
        "r.npy",
        zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated),
    )
    .unwrap();
    zw.write_all(&npy).unwrap();
    zw.finish().unwrap();
    drop(npy);
    let out = dir.join("sim");
    let r = run(&["simulate", "--excitation-file", s(&p), "--out", s(&out)]);
    assert_ne!(r.code, 0);
    assert!(
        r.stderr.contains("long.npz")
            && r.stderr.contains(&format!("{n} samples"))
            && r.stderr.contains("8388608"),
        "{}",
        r.stderr
    );
    assert!(!out.exists());
}

/// The streamed FRF equals the in-memory one bit for bit on the twin's record (periodic and
/// Welch, with the controller's indirect estimate).
#[test]
fn streamed_frf_equals_the_in_memory_frf_on_a_twin_record() {
    use ambid::analysis::{analyze, FrfSettings, Record};
    use ambid::frf_stream::{analyze_csv, StreamColumns};
    let dir = tmpdir("hr-stream-eq");
    let out = common::seed_record_on_rig(5, 11, 0.1, 6);
    let rec = &out.record;
    let data = dir.join("data.csv");
    ambid::io::write_time_csv(
        &data,
        &[
            ("t", &rec.t),
            ("r", &rec.r),
            ("u", &rec.u),
            ("i", &rec.i),
            ("y", &rec.y),
        ],
    )
    .unwrap();
    let mem = ambid::io::read_time(&data, &ambid::io::TimeOptions::default()).unwrap();
    let cfg = ambid_twin::random_rig(5).unwrap();
    let ctrl = ambid::io::controller::parse_controller_str(
        &ambid::io::controller::controller_toml_from_twin(&cfg),
        ambid::io::controller::ControllerFormat::Toml,
    )
    .unwrap()
    .state_space()
    .clone();
    let record = Record {
        r: mem.column("r").unwrap(),
        u: mem.column("u").unwrap(),
        y: mem.column("y").unwrap(),
        i: Some(mem.column("i").unwrap()),
        fs: 1.0 / mem.ts,
    };
    let cols = StreamColumns {
        r: "r",
        u: "u",
        y: "y",
        i: Some("i"),
    };
    for mut settings in [FrfSettings::periodic(5115, 1), FrfSettings::welch(4096)] {
        settings.controller = Some(ctrl.clone());
        let a = analyze(&record, &settings, None).unwrap();
        let b = analyze_csv(&data, &cols, None, false, |n, ts, _| {
            assert_eq!((n, ts), (rec.r.len(), mem.ts));
            Ok(settings.clone())
        })
        .unwrap();
        assert_eq!(a.frf, b.frf);
        assert_eq!(a.spectra, b.spectra);
        assert_eq!(a.saturation, b.saturation);
        assert_eq!(a.abnormal, b.abnormal);
        assert_eq!(a.warnings, b.warnings);
        assert_eq!(a.quality, b.quality);
    }
}

/// Across several screening blocks, a clean synthetic record (periodic excitation through a
/// resonant loop, noise) gives the in-memory result bit for bit.
#[test]
fn streamed_frf_equals_the_in_memory_frf_across_blocks() {
    use ambid::analysis::{analyze, FrfSettings, Record};
    use ambid::frf_stream::{analyze_csv, StreamColumns, STREAM_BLOCK};
    let dir = tmpdir("hr-stream-blocks");
    let np = 1024;
    let n = (STREAM_BLOCK / np + 8) * np;
    let mut x: u64 = 99;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let base: Vec<f64> = (0..np)
        .map(|_| if rnd() > 0.0 { 1.0 } else { -1.0 })
        .collect();
    let (mut y1, mut y2) = (0.0, 0.0);
    let mut cols: [Vec<f64>; 4] = Default::default();
    for k in 0..n {
        let r = base[k % np];
        let u = r - 0.5 * y1;
        let y = 1.6 * y1 - 0.8 * y2 + 0.1 * u + 1e-3 * rnd();
        (y2, y1) = (y1, y);
        cols[0].push(k as f64 * 1e-3);
        cols[1].push(r);
        cols[2].push(u);
        cols[3].push(y);
    }
    let data = dir.join("long.csv");
    ambid::io::write_time_csv(
        &data,
        &[
            ("t", &cols[0]),
            ("r", &cols[1]),
            ("u", &cols[2]),
            ("y", &cols[3]),
        ],
    )
    .unwrap();
    let mem = ambid::io::read_time(&data, &ambid::io::TimeOptions::default()).unwrap();
    let record = Record {
        r: mem.column("r").unwrap(),
        u: mem.column("u").unwrap(),
        y: mem.column("y").unwrap(),
        i: None,
        fs: 1.0 / mem.ts,
    };
    let sc = StreamColumns {
        r: "r",
        u: "u",
        y: "y",
        i: Some("i"),
    };
    for settings in [FrfSettings::periodic(np, 2), FrfSettings::welch(8192)] {
        let a = analyze(&record, &settings, None).unwrap();
        let b = analyze_csv(&data, &sc, None, false, |_, _, _| Ok(settings.clone())).unwrap();
        assert!(
            a.abnormal.iter().all(|(_, r)| r.is_clean()),
            "{:?}",
            a.warnings
        );
        assert_eq!(a.frf, b.frf);
        assert_eq!(a.spectra, b.spectra);
        assert_eq!(a.saturation, b.saturation);
        assert_eq!(a.abnormal, b.abnormal);
        assert_eq!(a.warnings, b.warnings);
    }
}
