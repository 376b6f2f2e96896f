//! The file workflow with its defaults on 20 random rigs of the twin (issue 16): each rig's seed
//! experiment and an independent validation record are written by `ambid simulate --rig-seed`,
//! then `ambid run`'s library entry reads them as a user's recordings (columns by name, the rig's
//! controller file, nothing else given) and runs frf → order → models → pole_zero → validation →
//! iso. Checked against each rig's exact linearised truth:
//! - the chosen model is a valid one (the supported number of unstable poles: the truth's; a
//!   stable loop with the controller) and its plant error over 10–1000 Hz (median of the
//!   relative error on a 200-point log grid, as Bode comparisons are read) is ≤ 0.5 % on every
//!   rig; the median on the FRF's own linearly spaced lines (dominated by 500–1000 Hz) and the
//!   measured FRF's own error are printed beside it;
//! - the ISO zone equals the truth's;
//! - every step ran (done), none failed or was skipped.
//!
//! No number of the nominal rig enters: bands, orders and the unstable-pole count come from the
//! data.

use crate::common::{ambid, median, s, text, tmpdir};
use ambid::workflow::{self, Progress, Verbosity, WorkflowConfig};
use ambid_core::validate::iso::IsoZones;
use ambid_twin::{random_rig, Twin};
use std::path::Path;

fn simulate(dir: &Path, rig: u64, extra: &[&str]) {
    let rig = rig.to_string();
    let mut args = vec![
        "simulate",
        "--mode",
        "linear",
        "--out",
        s(dir),
        "--rig-seed",
        &rig,
    ];
    args.extend_from_slice(extra);
    let o = ambid(&args);
    assert!(o.status.success(), "{}", text(&o));
}

/// Median relative error [%] over 10–1000 Hz of the period-averaged plant FRF of `dir/data.csv`
/// (`ambid frf`, as a user runs it) against the exact plant, and the FRF's lines there.
fn measured_frf_error(dir: &Path, twin: &Twin) -> (f64, Vec<f64>) {
    let out = dir.join("frf.csv");
    let o = ambid(&[
        "frf",
        s(&dir.join("data.csv")),
        "--period-samples",
        "5115",
        "--skip-periods",
        "1",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = std::fs::read_to_string(&out).unwrap();
    let mut lines = t.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |n: &str| head.iter().position(|h| *h == n).unwrap();
    let (cf, cr, ci) = (col("f_hz"), col("plant_re"), col("plant_im"));
    let mut f = Vec::new();
    let mut g = Vec::new();
    for l in lines {
        let v: Vec<f64> = l
            .split(',')
            .map(|x| x.parse().unwrap_or(f64::NAN))
            .collect();
        if (10.0..=1000.0).contains(&v[cf]) {
            f.push(v[cf]);
            g.push(ambid_core::c64::new(v[cr], v[ci]));
        }
    }
    let want = twin.plant_frf(&f).unwrap();
    let e = 100.0
        * median(
            g.iter()
                .zip(&want)
                .map(|(a, b)| (a - b).norm() / b.norm())
                .collect(),
        );
    (e, f)
}

#[test]
fn the_file_workflow_chooses_an_accurate_valid_model_on_20_random_rigs() {
    let base = tmpdir("workflow_rigs");
    let zones = IsoZones::default();
    let grid: Vec<f64> = (0..200)
        .map(|k| 10.0 * 100f64.powf(k as f64 / 199.0))
        .collect();
    let mut errors = Vec::new();
    let mut lin_errors = Vec::new();
    for rig in 1..=20u64 {
        let (id, va) = (base.join(format!("r{rig}")), base.join(format!("r{rig}v")));
        let seed = (300 + rig).to_string();
        simulate(&id, rig, &["--seed", &seed]);
        simulate(&va, rig, &["--seed", "12", "--amplitude", "0.12"]);
        let wf = format!(
            "source = \"files\"\nsteps = [\"frf\", \"order\", \"models\", \"pole_zero\", \"validation\", \"iso\"]\n\
             [data]\nidentification = \"r{rig}/data.csv\"\nvalidation = \"r{rig}v/data.csv\"\n\
             period_samples = 5115\nskip_periods = 1\ncontroller = \"r{rig}/controller.toml\"\n"
        );
        let cfg = WorkflowConfig::from_toml_str(&wf, Path::new("wf.toml")).unwrap();
        let out = workflow::run(&cfg, &base, &mut Progress::new(Verbosity::Quiet))
            .unwrap_or_else(|e| panic!("rig {rig}: workflow failed: {e}"));
        for t in &out.timings {
            assert_eq!(t.status, "done", "rig {rig}: step {} {}", t.step, t.status);
        }
        let twin = Twin::new(random_rig(rig).unwrap()).unwrap();
        let sm = &out.summary;
        // the unstable-pole count the data support is the truth's
        let n_true = twin.plant_unstable_poles().unwrap().len();
        assert_eq!(
            sm["models"]["unstable_poles_supported"].as_f64(),
            Some(n_true as f64),
            "rig {rig}: {}",
            sm["models"]
        );
        // the chosen model against the exact plant
        let chosen = out
            .models
            .iter()
            .find(|m| m.meta["chosen"] == true)
            .unwrap_or_else(|| panic!("rig {rig}: no chosen model"));
        let got = chosen.ss.freq_response_siso(&grid).unwrap();
        let want = twin.plant_frf(&grid).unwrap();
        let err = median(
            got.iter()
                .zip(&want)
                .map(|(g, w)| (g - w).norm() / w.norm())
                .collect(),
        );
        let unstable = chosen
            .ss
            .poles()
            .unwrap()
            .iter()
            .filter(|p| p.norm() > 1.0)
            .count();
        assert_eq!(unstable, n_true, "rig {rig}: {}", chosen.name);
        // the measured FRF's own error over 10–1000 Hz (what the model was fitted to), by
        // `ambid frf` with the same period averaging
        let (frf, lines) = measured_frf_error(&id, &twin);
        // the same error on the FRF's own (linearly spaced) lines, printed beside the log grid's
        let on_lines = {
            let g = chosen.ss.freq_response_siso(&lines).unwrap();
            let w = twin.plant_frf(&lines).unwrap();
            100.0
                * median(
                    g.iter()
                        .zip(&w)
                        .map(|(a, b)| (a - b).norm() / b.norm())
                        .collect(),
                )
        };
        lin_errors.push(on_lines);
        let fit = sm["models"]["chosen_validation_fit_pct"]
            .as_f64()
            .unwrap_or(f64::NAN);
        println!(
            "rig {rig:2}: chosen {} — plant error {:.3} % (on the FRF lines {on_lines:.3} %; the FRF \
             itself {frf:.3} %), validation fit {fit:.2} %, \
             ISO {} / truth {:?}",
            chosen.name,
            100.0 * err,
            sm["iso"]["measured"]["zone"],
            zones.zone(twin.peak_sensitivity().unwrap().1)
        );
        errors.push(100.0 * err);
        assert!(
            100.0 * err <= 0.5,
            "rig {rig}: chosen {} plant error {:.3} % > 0.5 %",
            chosen.name,
            100.0 * err
        );
        assert_eq!(
            sm["iso"]["measured"]["zone"],
            format!("{:?}", zones.zone(twin.peak_sensitivity().unwrap().1)).as_str(),
            "rig {rig}"
        );
    }
    let med = median(errors.clone());
    let within = errors.iter().filter(|e| **e <= 0.5).count();
    println!("chosen-model plant error: median over rigs {med:.3} %, ≤ 0.5 % on {within}/20 rigs");
    let lin_within = lin_errors.iter().filter(|e| **e <= 0.5).count();
    println!(
        "on the FRF's linear lines: median over rigs {:.3} %, ≤ 0.5 % on {lin_within}/20 rigs",
        median(lin_errors.clone())
    );
}
