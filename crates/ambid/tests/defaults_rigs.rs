//! Defaults that must hold on rigs and data ambid was not tuned on (issue 16, "bands from the
//! data"): the file workflow's FRF band, quality band and ISO 14839-3 search derived from the
//! excitation, checked on 20 random rigs of the twin against each rig's exact sensitivity, on the
//! nominal twin, and on the real F-16 and Silverbox records.

use crate::common;
use crate::common::{ambid, s, text, tmpdir};
use ambid::workflow::{self, Outcome, Progress, Verbosity, WorkflowConfig};
use ambid_core::validate::iso::IsoZones;
use ambid_twin::{random_rig, Twin};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn num(v: &Value, path: &str) -> f64 {
    let mut x = v;
    for k in path.split('.') {
        x = &x[k];
    }
    x.as_f64()
        .unwrap_or_else(|| panic!("summary has no number at {path}: {x}"))
}

fn run(text: &str, base: &Path) -> Outcome {
    let cfg = WorkflowConfig::from_toml_str(text, Path::new("test.toml")).unwrap();
    let mut progress = Progress::new(Verbosity::Quiet);
    workflow::run(&cfg, base, &mut progress).unwrap_or_else(|e| panic!("workflow failed: {e}"))
}

/// A file of ../shared/data/real (see `common::real_data`).
fn real(rel: &str) -> Option<PathBuf> {
    common::real_data(rel)
}

/// `ambid simulate --rig-seed` for the seed experiment (linear twin) into `dir`.
fn simulate(dir: &Path, rig: u64, extra: &[&str]) {
    let mut args = vec![
        "simulate",
        "--mode",
        "linear",
        "--out",
        s(dir),
        "--rig-seed",
    ];
    let rig = rig.to_string();
    args.push(&rig);
    args.extend_from_slice(extra);
    let o = ambid(&args);
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn the_file_workflow_gives_every_random_rig_its_true_iso_zone_in_a_band_from_the_excitation() {
    let zones = IsoZones::default();
    let base = tmpdir("rigs");
    let mut worst_dev: f64 = 0.0;
    let mut cli_inside: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    for rig in 1..=20u64 {
        let (id, va) = (base.join(format!("r{rig}")), base.join(format!("r{rig}v")));
        // a different noise realisation per rig; the validation record as a user would record it
        let seed = (100 + rig).to_string();
        simulate(&id, rig, &["--seed", &seed]);
        simulate(&va, rig, &["--seed", "11", "--amplitude", "0.12"]);
        // a twin-style file needs no column names: r, u, y, i, w, t are taken by name
        let wf = format!(
            "source = \"files\"\nsteps = [\"frf\", \"iso\"]\n[data]\nidentification = \"r{rig}/data.csv\"\n\
             validation = \"r{rig}v/data.csv\"\nperiod_samples = 5115\nskip_periods = 1\n\
             controller = \"r{rig}/controller.toml\"\n"
        );
        let out = run(&wf, &base);
        let sm = &out.summary;
        for t in &out.timings {
            assert_eq!(t.status, "done", "rig {rig}: step {} {}", t.step, t.status);
        }
        let twin = Twin::new(random_rig(rig).unwrap()).unwrap();
        let (f_true, peak_true) = twin.peak_sensitivity().unwrap();
        let zone_true = format!("{:?}", zones.zone(peak_true));
        let (lo, hi) = (num(sm, "frf.band_lo_hz"), num(sm, "frf.band_hi_hz"));
        let (qlo, qhi) = (
            num(sm, "frf.quality_band_lo_hz"),
            num(sm, "frf.quality_band_hi_hz"),
        );
        let (peak, f_peak) = (
            num(sm, "iso.measured.peak"),
            num(sm, "iso.measured.f_peak_hz"),
        );
        let (ci_lo, ci_hi) = (
            num(sm, "iso.measured.peak_ci_lo"),
            num(sm, "iso.measured.peak_ci_hi"),
        );
        // the truth on the measured line grid (the estimate cannot see between lines): the
        // largest |S| over the lines within ±1 line of the measured peak
        let df = 20_000.0 / 5115.0;
        let grid: Vec<f64> = (-1..=1).map(|k| f_peak + k as f64 * df).collect();
        let on_lines = twin
            .sensitivity_frf(&grid)
            .unwrap()
            .iter()
            .map(|v| v.norm())
            .fold(0.0, f64::max);
        println!(
            "rig {rig:2}: band {lo:.1}–{hi:.0} Hz, quality {qlo:.1}–{qhi:.0} Hz; max|S| {peak:.3} \
             [{ci_lo:.3}, {ci_hi:.3}] at {f_peak:.1} Hz (truth {peak_true:.3} at {f_true:.1} Hz, \
             {on_lines:.3} on the lines) zone {} / truth {zone_true}",
            sm["iso"]["measured"]["zone"]
        );
        assert_eq!(sm["frf"]["band_origin"], "excitation");
        assert_eq!(
            sm["iso"]["measured"]["zone"],
            zone_true.as_str(),
            "rig {rig}"
        );
        // the band from the excitation: the PRBS main lobe (no side lobe past fs/Nb = 4 kHz) and
        // the true peak inside both bands
        assert!(lo > 0.0 && hi < 4000.0, "rig {rig}: band {lo}–{hi}");
        assert!(
            lo <= f_true && f_true <= hi,
            "rig {rig}: f_peak {f_true} outside {lo}–{hi}"
        );
        assert!(
            qlo <= f_true && f_true <= qhi,
            "rig {rig}: f_peak {f_true} outside {qlo}–{qhi}"
        );
        assert!(
            (f_peak - f_true).abs() <= df,
            "rig {rig}: {f_peak} vs {f_true}"
        );
        // the measured peak within its stated 95 % interval of the truth on the lines (with
        // 1 % for the upward bias of a maximum over noisy lines)
        let dev = (on_lines - peak).abs() / (ci_hi - ci_lo).max(1e-12) * 2.0;
        worst_dev = worst_dev.max(dev);
        assert!(
            on_lines >= ci_lo - 0.01 * peak && on_lines <= ci_hi + 0.01 * peak,
            "rig {rig}: truth on the lines {on_lines} outside [{ci_lo}, {ci_hi}]"
        );
        // a user who does not know the period: the period is found in r (the same FRF, so the
        // same verdict to the last digit), and with `[frf] method = "welch"` Welch with the same
        // band rule on the PSD of r
        let found = wf.replace("period_samples = 5115\n", "");
        let out = run(&found, &base);
        assert!(
            out.report.to_html().contains("repeats every 5115 samples"),
            "rig {rig}: no note of the found period"
        );
        assert_eq!(
            num(&out.summary, "iso.measured.peak"),
            peak,
            "rig {rig}: the found period's verdict"
        );
        let welch = found.replace("[data]", "[frf]\nmethod = \"welch\"\n[data]");
        let out = run(&welch, &base);
        let sm = &out.summary;
        let (lo, hi) = (num(sm, "frf.band_lo_hz"), num(sm, "frf.band_hi_hz"));
        println!(
            "        Welch: band {lo:.1}–{hi:.0} Hz, max|S| {:.3} [{:.3}, {:.3}] at {:.1} Hz",
            num(sm, "iso.measured.peak"),
            num(sm, "iso.measured.peak_ci_lo"),
            num(sm, "iso.measured.peak_ci_hi"),
            num(sm, "iso.measured.f_peak_hz")
        );
        assert_eq!(
            sm["iso"]["measured"]["zone"],
            zone_true.as_str(),
            "rig {rig} (Welch)"
        );
        assert!(
            lo <= f_true && f_true <= hi && hi < 4000.0,
            "rig {rig} (Welch): {lo}–{hi}"
        );
        // `ambid frf` with every default (the period found in r, the band from the excitation)
        // and with `--method welch` (its default segment): the plant against the rig's truth on
        // the lines it writes
        for (k, extra) in [&[][..], &["--method", "welch"][..]]
            .into_iter()
            .enumerate()
        {
            let what = ["defaults", "Welch"][k];
            let wcsv = base.join(format!("r{rig}-{k}.csv"));
            let data = id.join("data.csv");
            let mut args = vec!["frf", s(&data), "--out", s(&wcsv)];
            args.extend_from_slice(extra);
            let o = ambid(&args);
            assert!(o.status.success(), "{}", text(&o));
            let body = std::fs::read_to_string(&wcsv).unwrap();
            let mut lines = body.lines();
            let head: Vec<&str> = lines.next().unwrap().split(',').collect();
            let col = |n: &str| head.iter().position(|c| *c == n).unwrap();
            let (cf, cr, ci, cs) = (
                col("f_hz"),
                col("plant_re"),
                col("plant_im"),
                col("plant_std"),
            );
            let rows: Vec<Vec<f64>> = lines
                .map(|l| {
                    l.split(',')
                        .map(|x| x.parse().unwrap_or(f64::NAN))
                        .collect()
                })
                .collect();
            let f: Vec<f64> = rows.iter().map(|r| r[cf]).collect();
            let truth = twin.plant_frf(&f).unwrap();
            // the stated uncertainty holds: the truth inside the 95 % circle (radius √5.99 σ of
            // a circular complex Gaussian) on ≈ 95 % of the lines
            let inside = rows
                .iter()
                .zip(&truth)
                .filter(|(r, t)| {
                    ((r[cr] - t.re).powi(2) + (r[ci] - t.im).powi(2)).sqrt()
                        <= 5.99f64.sqrt() * r[cs]
                })
                .count() as f64
                / rows.len() as f64;
            // and the lines known to ±10 % (σ ≤ 5 % of |P|) are accurate
            let mut rel: Vec<f64> = rows
                .iter()
                .zip(&truth)
                .filter(|(r, t)| r[cs] <= 0.05 * t.norm())
                .map(|(r, t)| ((r[cr] - t.re).powi(2) + (r[ci] - t.im).powi(2)).sqrt() / t.norm())
                .collect();
            rel.sort_by(f64::total_cmp);
            let med = rel[rel.len() / 2];
            cli_inside[k].push(inside);
            println!(
                "        frf ({what}): {} lines {:.1}–{:.0} Hz, truth inside the 95 % interval on {:.1} %; {} lines known to ±10 %: median plant error {:.3} %",
                rows.len(),
                f[0],
                f[f.len() - 1],
                100.0 * inside,
                rel.len(),
                100.0 * med
            );
            let least = [0.90, 0.85][k];
            assert!(inside > least, "rig {rig}: CLI {what} coverage {inside}");
            assert!(med < 0.03, "rig {rig}: CLI {what} plant error {med}");
        }
    }
    println!("largest |truth − peak| in half-widths: {worst_dev:.2}");
    for (k, what) in ["defaults (period found)", "Welch"].iter().enumerate() {
        let v = &mut cli_inside[k];
        v.sort_by(f64::total_cmp);
        println!(
            "CLI {what}: truth inside the 95 % interval on {:.1} % (worst rig) … {:.1} % (median rig) of the lines",
            100.0 * v[0],
            100.0 * v[v.len() / 2]
        );
    }
}

#[test]
fn the_nominal_twin_path_uses_the_same_rule() {
    let out = run(
        "steps = [\"frf\", \"iso\"]\n[twin]\nmode = \"linear\"\n",
        Path::new("."),
    );
    let sm = &out.summary;
    let twin = Twin::new(ambid_twin::TwinConfig::default()).unwrap();
    let (f_true, peak_true) = twin.peak_sensitivity().unwrap();
    assert_eq!(sm["frf"]["band_origin"], "excitation");
    assert_eq!(sm["frf"]["quality_band_origin"], "excitation");
    let (lo, hi) = (num(sm, "frf.band_lo_hz"), num(sm, "frf.band_hi_hz"));
    let (qlo, qhi) = (
        num(sm, "frf.quality_band_lo_hz"),
        num(sm, "frf.quality_band_hi_hz"),
    );
    // PRBS Nb = 5 at 20 kHz, bits held for 5 samples: |sin(πf Nb/fs)/(Nb sin(πf/fs))|², 10 dB
    // down at 0.7465 fs/Nb = 2986 Hz, 3 dB at 0.4501 fs/Nb = 1800 Hz (lines 3.91 Hz apart)
    let df = 20_000.0 / 5115.0;
    assert!(
        (lo - df).abs() < 1e-9 && (qlo - df).abs() < 1e-9,
        "{lo} {qlo}"
    );
    assert!(hi <= 2986.2 && hi > 2986.2 - df, "{hi}");
    assert!(qhi <= 1800.4 && qhi > 1800.4 - df, "{qhi}");
    assert!(lo <= f_true && f_true <= qhi);
    let zone_true = format!("{:?}", IsoZones::default().zone(peak_true));
    assert_eq!(sm["iso"]["measured"]["zone"], zone_true.as_str());
    assert_eq!(sm["iso"]["truth"]["zone"], zone_true.as_str());
    let peak = num(sm, "iso.measured.peak");
    assert!(
        (peak - peak_true).abs() < 0.02 * peak_true,
        "{peak} vs {peak_true}"
    );
    // the twin's units
    assert!(out.report.to_html().contains("m/A"));
}

#[test]
fn f16_resonances_are_its_modes_in_the_multisine_band() {
    let Some(p) = real("f16-gvt/F16Data_FullMSine_Level1.csv") else {
        return;
    };
    // Force → Acceleration1, 8192-sample periods, the first period dropped (README); the FRF
    // and order steps use the identification record only
    let f = p.display().to_string();
    let wf = format!(
        "steps = [\"frf\", \"order\"]\nsource = \"files\"\n[order]\nna_max = 2\nnb_max = 2\n\
         [data]\nidentification = \"{f}\"\nvalidation = \"{f}\"\nfs_hz = 400\nu = \"Force\"\n\
         y = \"Acceleration1\"\nperiod_samples = 8192\nskip_periods = 1\n"
    );
    let out = run(&wf, Path::new("."));
    let sm = &out.summary;
    // the multisine's design band 2–15 Hz, not 0–200 Hz
    let (lo, hi) = (num(sm, "frf.band_lo_hz"), num(sm, "frf.band_hi_hz"));
    assert!(
        (lo - 2.0).abs() < 0.05 && (hi - 15.0).abs() < 0.05,
        "{lo}–{hi}"
    );
    let n = num(sm, "order.resonances");
    assert!((3.0..=10.0).contains(&n), "{n} resonances");
    // every peak a mode of the README's reference FRF (3.5–9.2 Hz), the dominant 7.3 Hz among them
    let html = out.report.to_html();
    assert!(!html.contains("m/A"), "the F-16's units are not m/A");
    let tab = out
        .report
        .sections
        .iter()
        .flat_map(|s| &s.blocks)
        .find_map(|b| match b {
            ambid::report::Block::Table(t) if t.id == "resonances" => Some(t),
            _ => None,
        })
        .expect("a resonance table");
    let fr: Vec<f64> = tab.rows.iter().map(|r| r[0].parse().unwrap()).collect();
    println!("F-16 resonances: {fr:?} Hz");
    assert!(fr.iter().all(|f| (3.0..=10.0).contains(f)), "{fr:?}");
    assert!(fr.iter().any(|f| (f - 7.324).abs() < 0.1), "{fr:?}");
}

#[test]
fn silverbox_gives_a_handful_of_resonances_not_seventy() {
    let Some(p) = real("silverbox/Schroeder80mV.csv") else {
        return;
    };
    // as a new user runs it: V1 → V2 at fs = 10^7/2^14 Hz, no period given (Welch), the record
    // split in halves
    let wf = format!(
        "steps = [\"frf\", \"order\"]\nsource = \"files\"\n[order]\nna_max = 2\nnb_max = 2\n\
         [data]\nidentification = \"{}\"\nfs_hz = 610.3515625\nu = \"V1\"\ny = \"V2\"\n",
        p.display()
    );
    let out = run(&wf, Path::new("."));
    let sm = &out.summary;
    // the Schroeder multisine excites odd bins up to 199.7 Hz (README)
    let hi = num(sm, "frf.band_hi_hz");
    assert!((hi - 199.7).abs() < 1.0, "{hi}");
    let n = num(sm, "order.order_from_peaks");
    println!("Silverbox: order from peaks {n}");
    assert!((2.0..=8.0).contains(&n), "order from peaks {n}");
    let html = out.report.to_html();
    assert!(html.contains("unit not given"));
}
