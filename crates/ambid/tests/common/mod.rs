//! Helpers shared by the CLI tests: run the `ambid` binary, read its output, temporary
//! directories and the twin's controller file.
#![allow(dead_code)] // each test binary uses a subset

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod skip;
pub use skip::skip;

/// Runs the `ambid` binary with `args`.
pub fn ambid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ambid"))
        .args(args)
        .output()
        .expect("the ambid binary runs")
}

/// Standard output followed by standard error.
pub fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Runs `ambid args`, asserts that it succeeded (the output in the message otherwise) and
/// returns its output text.
pub fn ok(args: &[&str]) -> String {
    let o = ambid(args);
    let t = text(&o);
    assert!(o.status.success(), "ambid {args:?}: {t}");
    t
}

/// A fresh, empty temporary directory for this test process and `name`, removed with
/// everything in it when the returned guard is dropped (also when the test panics): the rig
/// sweeps write hundreds of MB of records, and a test run used to leave about 1.8 GB in the
/// temporary directory every time.
pub fn tmpdir(name: &str) -> TmpDir {
    let d = std::env::temp_dir().join(format!("ambid-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    TmpDir(d)
}

/// See [`tmpdir`]; derefs to its path.
#[derive(Debug)]
pub struct TmpDir(PathBuf);

impl std::ops::Deref for TmpDir {
    type Target = PathBuf;
    fn deref(&self) -> &PathBuf {
        &self.0
    }
}

impl AsRef<Path> for TmpDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TmpDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TmpDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The twin's default controller as a controller file.
pub const CONTROLLER: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/fixtures/twin_controller.toml"
);

/// The `p`-quantile of `v` (linear interpolation between order statistics, numpy's default).
pub fn percentile(v: &[f64], p: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let pos = p * (s.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    s[lo] + (s[hi] - s[lo]) * (pos - lo as f64)
}

/// A file of the real data sets, `shared/data/real/<rel>`, in the first ancestor of this crate
/// that has it (the workspace's sibling `../shared`, also from a git worktree). When it is absent
/// the check is skipped with a printed note, except under CI (`CI` set), where missing data is a
/// failure: CI always has `shared/` beside the clone, so a skip there would hide a broken path.
#[allow(dead_code)]
pub fn real_data(rel: &str) -> Option<PathBuf> {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    let found = here
        .ancestors()
        .map(|a| a.join("shared/data/real").join(rel))
        .find(|p| p.exists());
    if found.is_none() {
        assert!(
            std::env::var_os("CI").is_none(),
            "shared/data/real/{rel} not found above {} (CI must have ../shared)",
            here.display()
        );
        skip(
            &format!("real data set shared/data/real/{rel}"),
            "not present next to the repository (put the shared/ folder beside the clone)",
        );
    }
    found
}

/// The upper median (`v[n/2]` of the sorted values), as the rig sweeps report it.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Arithmetic mean.
pub fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// The seed experiment (default excitation plan at `amplitude` of i_sat) on the linear twin of
/// random rig `rig`, sensor noise on with seed `seed`.
pub fn rig_experiment(rig: u64, seed: u64, amplitude: f64) -> ambid::experiment::Experiment {
    ambid::experiment::Experiment {
        twin: ambid_twin::random_rig(rig).unwrap(),
        excitation: ambid::experiment::ExcitationPlan {
            amplitude_frac: amplitude,
            ..ambid::experiment::ExcitationPlan::default()
        },
        mode: ambid_twin::Mode::Linear,
        seed,
        noise: true,
        record_b: false,
    }
}

/// The seed paper's experiment on the linear twin of random rig `rig` (noise seed `noise_seed`,
/// `amplitude` of i_sat, `periods` PRBS periods), simulated.
pub fn seed_record_on_rig(
    rig: u64,
    noise_seed: u64,
    amplitude: f64,
    periods: usize,
) -> ambid::experiment::ExperimentOutput {
    let mut e =
        ambid::experiment::Experiment::seed_paper(ambid_twin::Mode::Linear, 1e-7, noise_seed);
    e.twin = ambid_twin::random_rig(rig).unwrap();
    e.noise = true;
    e.excitation.amplitude_frac = amplitude;
    e.excitation.periods = periods;
    ambid::experiment::run(&e).unwrap()
}

/// Fit % of the exact closed loop of `twin` (inputs r and w = 0, from rest) on `(r, y)`: the
/// ceiling a model of r → y can reach on that record.
pub fn exact_loop_fit(twin: &ambid_twin::Twin, r: &[f64], y: &[f64]) -> f64 {
    let rw = faer::Mat::from_fn(r.len(), 2, |k, c| if c == 0 { r[k] } else { 0.0 });
    let yt = twin.closed_loop().simulate(rw.as_ref(), None).unwrap();
    let yt: Vec<f64> = (0..yt.nrows()).map(|k| yt[(k, 0)]).collect();
    ambid_core::validate::fit::fit_percent(y, &yt).unwrap()
}

/// The `[machine]` section of random rig `seed` (`ambid_twin::random_rig(seed)` lifted to four
/// axes, its config written into `dir`) at `(7919·seed) mod 30 000` rpm, linear, every other
/// setting at its default.
pub fn random_machine_rig(dir: &Path, seed: u64) -> ambid::config::MachineSection {
    let path = dir.join(format!("rig{seed}.toml"));
    std::fs::write(
        &path,
        ambid_twin::random_rig(seed)
            .unwrap()
            .to_toml_string()
            .unwrap(),
    )
    .unwrap();
    ambid::config::MachineSection {
        speeds_rpm: Some(vec![((seed * 7919) % 30_000) as f64]),
        mode: "linear".into(),
        config: Some(path),
        ..Default::default()
    }
}

/// The single-axis chain on the twin in `dir`: `ambid simulate <simulate_args> --out sim`, `ambid
/// frf` with the rig's controller, and a state-space fit of order 8 to the plant FRF with the
/// loop's unstable pole count: `sim/`, `frf.csv`, `model.json` (the inputs of `uncertainty` and
/// `physical`).
pub fn identify_on_twin(dir: &Path, simulate_args: &[&str]) {
    let d = |f: &str| dir.join(f).to_str().unwrap().to_string();
    let run = |args: &[&str]| {
        let o = ambid(args);
        assert!(o.status.success(), "ambid {args:?}: {}", text(&o));
    };
    let sim = d("sim");
    let mut args = vec!["simulate"];
    args.extend_from_slice(simulate_args);
    args.extend_from_slice(&["--out", &sim]);
    run(&args);
    let (data, ctrl, frf, model) = (
        d("sim/data.csv"),
        d("sim/controller.toml"),
        d("frf.csv"),
        d("model.json"),
    );
    run(&["frf", &data, "--controller", &ctrl, "--out", &frf]);
    let o = fit_plant_ss(&frf, "8", &model, &["--controller", &ctrl]);
    assert!(o.status.success(), "ambid fit: {}", text(&o));
}

/// `ambid fit FRF --quantity plant --structure ss --order ORDER` with `extra` arguments, writing
/// `out`: the command's output.
pub fn fit_plant_ss(frf: &str, order: &str, out: &str, extra: &[&str]) -> std::process::Output {
    let mut args = vec![
        "fit",
        frf,
        "--quantity",
        "plant",
        "--structure",
        "ss",
        "--order",
        order,
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", out]);
    ambid(&args)
}

/// Issue 23's two margin bars for robust gain margins `lo..hi` against the true loop's
/// `t_lo..t_hi` (its exact gain interval): the true loop is stable with the gain moved 90 % of
/// the way to either, and each is at least half the true one. `what` names the case in the
/// messages.
pub fn assert_margin_bars(
    plant: &ambid_core::lti::StateSpace,
    ctrl: &ambid_core::lti::StateSpace,
    (lo, hi): (f64, f64),
    (t_lo, t_hi): (f64, f64),
    what: &str,
) {
    use ambid::uncertainty::loop_stable;
    for g in [1.0 - 0.9 * (1.0 - lo), 1.0 + 0.9 * (hi - 1.0)] {
        assert!(
            loop_stable(plant, ctrl, g).unwrap(),
            "{what}: the true loop at gain {g} (margins {lo} … {hi})"
        );
    }
    assert!(
        hi - 1.0 >= 0.5 * (t_hi - 1.0),
        "{what}: upper {hi} vs true {t_hi}"
    );
    assert!(
        1.0 - lo >= 0.5 * (1.0 - t_lo),
        "{what}: lower {lo} vs true {t_lo}"
    );
}

/// The oracle of `ambid fit`'s `meta.poles_on_unit_circle`: the written model's poles (upper
/// half-plane and real) with $\bigl||z| - 1\bigr| < 10^{-9}$, as frequencies $|\arg z| / 2\pi T$
/// in Hz, computed here from the model file; checked against the meta's list and the warning.
/// Returns those frequencies.
pub fn check_poles_on_unit_circle(model_path: &Path, printed: &str) -> Vec<f64> {
    let m = ambid::io::model::read_model_json(model_path).unwrap();
    let ts = m.ts().unwrap();
    let oracle: Vec<f64> = m
        .poles()
        .unwrap()
        .iter()
        .filter(|z| z.im >= 0.0 && (z.norm() - 1.0).abs() < 1e-9)
        .map(|z| z.arg().abs() / (2.0 * std::f64::consts::PI * ts))
        .collect();
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(model_path).unwrap()).unwrap();
    let listed: Vec<f64> = j["meta"]["poles_on_unit_circle"]
        .as_array()
        .expect("meta.poles_on_unit_circle")
        .iter()
        .map(|p| p["f_hz"].as_f64().unwrap())
        .collect();
    assert_eq!(listed.len(), oracle.len(), "{listed:?} against {oracle:?}");
    for f in &oracle {
        assert!(
            listed.iter().any(|g| (g - f).abs() <= 1e-9 * (1.0 + f)),
            "{f} not in {listed:?}"
        );
    }
    assert_eq!(
        printed.contains("poles on the unit circle"),
        !oracle.is_empty(),
        "{printed}"
    );
    oracle
}
