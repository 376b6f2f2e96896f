//! The whole-machine workflow as a whole process (issue 21's bar: the 4-axis workflow on the
//! twin at three speeds ≤ 10 s on the project machine): `ambid run wf.toml` with a `[machine]`
//! section, defaults otherwise (0, 15 000, 30 000 rpm, the orthogonal PRBS design, n = 10, 5
//! samples per bit, 12 periods per experiment, nonlinear twin with noise), and the same with
//! `mode = "linear"`, with the MIMO fitter (`models = "fit"`), and with the fitter and the
//! uncertainty bound with its structured weight (`uncertainty = true`, issue 23; its default
//! amplitude study at 5 and 16 % of i_sat, and without it, `amplitude_levels_pct = []`), and the
//! whole-machine gray box (`physical = true`, with the same default study and without it). Median of
//! `AMBID_BENCH_REPS` runs (default 5); `AMBID_BENCH_ONLY=<text>` runs only the workflows whose
//! label contains the text. Prints a Markdown table for docs/benchmarks.md.
//!
//! Run: `cargo bench -p ambid --bench machine_workflow`.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

const EXE: &str = env!("CARGO_BIN_EXE_ambid");

fn run(wf: &Path, out: &Path) -> Result<f64, String> {
    let t = Instant::now();
    let o = Command::new(EXE)
        .arg("run")
        .arg(wf)
        .arg("--out")
        .arg(out)
        .args(["--force", "--quiet"])
        .output()
        .map_err(|e| format!("cannot start {EXE}: {e}"))?;
    let dt = t.elapsed().as_secs_f64();
    if !o.status.success() {
        return Err(String::from_utf8_lossy(&o.stderr).lines().take(3).collect());
    }
    Ok(dt)
}

fn main() {
    let reps: usize = std::env::var("AMBID_BENCH_REPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5)
        .max(1);
    let root = std::env::temp_dir().join(format!("ambid-bench-machine-{}", std::process::id()));
    if let Err(e) = std::fs::create_dir_all(&root) {
        eprintln!("cannot create {}: {e}", root.display());
        return;
    }
    println!("| workflow | median [s] | runs |");
    println!("|---|---|---|");
    for (label, toml) in [
        ("[machine] defaults (3 speeds, nonlinear)", "[machine]\n"),
        (
            "[machine] mode = \"linear\" (3 speeds)",
            "[machine]\nmode = \"linear\"\n",
        ),
        (
            "[machine] models = \"fit\" (3 speeds, nonlinear)",
            "[machine]\nmodels = \"fit\"\n",
        ),
        (
            "[machine] models = \"fit\", uncertainty = true (3 speeds, nonlinear)",
            "[machine]\nmodels = \"fit\"\nuncertainty = true\n",
        ),
        (
            "[machine] models = \"fit\", uncertainty = true, amplitude_levels_pct = [] (3 speeds, nonlinear)",
            "[machine]\nmodels = \"fit\"\nuncertainty = true\namplitude_levels_pct = []\n",
        ),
        (
            "[machine] physical = true (3 speeds, nonlinear; the default study, parameters at zero amplitude)",
            "[machine]\nphysical = true\n",
        ),
        (
            "[machine] physical = true, amplitude_levels_pct = [] (3 speeds, nonlinear)",
            "[machine]\nphysical = true\namplitude_levels_pct = []\n",
        ),
    ] {
        if let Ok(only) = std::env::var("AMBID_BENCH_ONLY") {
            if !label.contains(&only) {
                continue;
            }
        }
        let wf = root.join("wf.toml");
        if let Err(e) = std::fs::write(&wf, toml) {
            eprintln!("cannot write {}: {e}", wf.display());
            return;
        }
        let out = root.join("out");
        let mut t = Vec::new();
        let mut failed = None;
        for _ in 0..reps {
            match run(&wf, &out) {
                Ok(s) => t.push(s),
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        match failed {
            Some(e) => println!("| {label} | failed: {e} | |"),
            None => {
                t.sort_by(f64::total_cmp);
                println!("| {label} | {:.2} | {} |", t[t.len() / 2], t.len());
            }
        }
    }
    let _ = std::fs::remove_dir_all(&root);
}
