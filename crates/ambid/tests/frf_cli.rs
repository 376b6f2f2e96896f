//! `ambid frf` and `ambid study` end to end: files written, numbers against the twin's truth,
//! and the bad-input messages issue 3 asks for.

use crate::common::{ambid, s, text, tmpdir, CONTROLLER};
use std::path::Path;

/// Simulates the linear seed experiment into `dir` (data.csv, truth.csv).
fn simulate(dir: &Path) {
    let o = ambid(&["simulate", "--mode", "linear", "--out", s(dir)]);
    assert!(o.status.success(), "{}", text(&o));
}

fn read_csv(p: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let mut r = csv::Reader::from_path(p).unwrap();
    let h: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    let rows = r
        .records()
        .map(|rec| rec.unwrap().iter().map(|v| v.parse().unwrap()).collect())
        .collect();
    (h, rows)
}

#[test]
fn frf_writes_the_closed_loop_frfs_and_they_match_the_twin() {
    let d = tmpdir("ok");
    simulate(&d);
    let out = d.join("frf.csv");
    let o = ambid(&[
        "frf",
        s(&d.join("data.csv")),
        "--period-samples",
        "5115",
        "--controller",
        CONTROLLER,
        "--i-sat",
        "2.0",
        "--band",
        "10,1000",
        "--out",
        s(&out),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("19 periods") && t.contains("mean coherence"),
        "{t}"
    );
    assert!(!t.contains("warning"), "{t}");
    let (h, rows) = read_csv(&out);
    for col in [
        "f_hz",
        "t_ry_re",
        "t_ry_std",
        "t_ru_re",
        "plant_re",
        "plant_im",
        "plant_std",
        "controller_re",
        "plant_indirect_re",
        "coh_ry",
        "coh_ru",
    ] {
        assert!(h.iter().any(|c| c == col), "missing {col} in {h:?}");
    }
    assert_eq!(rows.len(), 253);
    // the plant against the twin's own truth (library call, same default configuration)
    let twin = ambid_twin::Twin::new(ambid_twin::TwinConfig::default()).unwrap();
    let f: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    let truth = twin.plant_frf(&f).unwrap();
    let col = |name: &str| h.iter().position(|c| c == name).unwrap();
    let (pr, pi, ps) = (col("plant_re"), col("plant_im"), col("plant_std"));
    let mut inside = 0;
    for (row, t) in rows.iter().zip(&truth) {
        let e = ((row[pr] - t.re).powi(2) + (row[pi] - t.im).powi(2)).sqrt();
        if e <= 1.81 * row[ps] {
            inside += 1;
        }
    }
    let frac = inside as f64 / rows.len() as f64;
    assert!(frac > 0.88, "{frac} of the lines inside the 95 % disc");
}

#[test]
fn frf_bad_inputs_name_the_fix() {
    let d = tmpdir("bad");
    simulate(&d);
    let data = d.join("data.csv");
    let out = d.join("x.csv");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["--period-samples", "5000"],
            "not an integer number of periods",
        ),
        (
            vec!["--period-samples", "5115", "--skip-periods", "19"],
            "at least 2",
        ),
        (
            vec!["--period-samples", "5115", "--excitation", "w"],
            "no power",
        ),
        (
            vec!["--period-samples", "5115", "--excitation", "nope"],
            "unknown column `nope`",
        ),
        (vec!["--nperseg", "200000"], "nperseg"),
        (
            vec!["--period-samples", "5115", "--band", "10"],
            "f_min,f_max",
        ),
    ];
    for (extra, expect) in cases {
        let mut args = vec!["frf", s(&data), "--out", s(&out)];
        args.extend(extra.iter().copied());
        let o = ambid(&args);
        let t = text(&o);
        assert!(!o.status.success(), "{extra:?} should fail");
        assert!(t.contains(expect), "{extra:?}: {t}");
    }
    // a controller sampled at another rate than the data
    let ctrl = d.join("ctrl.toml");
    let body = std::fs::read_to_string(CONTROLLER)
        .unwrap()
        .replace("fs_hz = 20000.0", "fs_hz = 10000.0")
        .replace("lowpass_hz = 5000.0", "lowpass_hz = 4500.0");
    std::fs::write(&ctrl, body).unwrap();
    let o = ambid(&[
        "frf",
        s(&data),
        "--period-samples",
        "5115",
        "--controller",
        s(&ctrl),
        "--out",
        s(&out),
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("rediscretise"), "{}", text(&o));
}

#[test]
fn frf_reports_repaired_samples_and_saturation() {
    let d = tmpdir("dirty");
    let o = ambid(&[
        "simulate",
        "--mode",
        "nonlinear",
        "--amplitude",
        "0.6",
        "--out",
        s(&d),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    // knock out one sample of y and add a spike
    let p = d.join("data.csv");
    let body = std::fs::read_to_string(&p).unwrap();
    let mut lines: Vec<String> = body.lines().map(String::from).collect();
    for (row, how) in [(30_001usize, "nan"), (40_001, "spike")] {
        let mut f: Vec<String> = lines[row].split(',').map(String::from).collect();
        let y: f64 = f[5].parse().unwrap();
        f[5] = if how == "nan" {
            "NaN".into()
        } else {
            format!("{:e}", y + 1e-3)
        };
        lines[row] = f.join(",");
    }
    std::fs::write(&p, lines.join("\n")).unwrap();
    let o = ambid(&[
        "frf",
        s(&p),
        "--period-samples",
        "5115",
        "--i-sat",
        "2.0",
        "--out",
        s(&d.join("f.csv")),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("warning") && t.contains("saturated"), "{t}");
    assert!(
        t.contains("1 non-finite") || t.contains("non-finite"),
        "{t}"
    );
    assert!(t.contains("spike"), "{t}");
    // the clamp plateaus of u are reported as saturation, not "repaired" as spikes
    assert!(!t.contains("u - r:"), "{t}");
}

#[test]
fn studies_write_their_figures() {
    let d = tmpdir("study");
    let out = d.join("amp.csv");
    let o = ambid(&[
        "study",
        "amplitude",
        "--levels",
        "4,10",
        "--periods",
        "4",
        "--mode",
        "linear",
        "--out",
        s(&out),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let (h, rows) = {
        let mut r = csv::Reader::from_path(&out).unwrap();
        let h: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
        (h, r.records().count())
    };
    assert_eq!(rows, 2);
    assert!(h.contains(&"mean_coh_ry".to_string()) && h.contains(&"snr_db".to_string()));
    let dev = d.join("op.csv");
    let frf = d.join("opf.csv");
    let o = ambid(&[
        "study",
        "operating-point",
        "--mode",
        "linear",
        "--out",
        s(&dev),
        "--frf-out",
        s(&frf),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let n = csv::Reader::from_path(&dev).unwrap().records().count();
    assert_eq!(n, 4 * 3, "four off-nominal cases × three bands");
    let o = ambid(&["study", "amplitude", "--levels", "4,200"]);
    assert!(!o.status.success() && text(&o).contains("(0, 100]"));
}

/// `ambid frf --method lpm` on one non-periodic record (white-noise excitation): the plant
/// against the twin's exact plant, and a window that leaves no degrees of freedom is refused.
#[test]
fn frf_by_the_local_polynomial_method_matches_the_twin() {
    let d = tmpdir("frf-lpm");
    let o = ambid(&[
        "simulate",
        "--mode",
        "linear",
        "--excitation",
        "noise",
        "--out",
        s(&d),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let data = d.join("data.csv");
    let out = d.join("frf.csv");
    let o = ambid(&[
        "frf",
        s(&data),
        "--method",
        "lpm",
        "--band",
        "10,1000",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let frf = ambid::io::csv::read_frf_csv(&out).unwrap();
    let est = frf.frd("plant", 5e-5).unwrap();
    let twin = ambid_twin::Twin::new(ambid_twin::TwinConfig::default()).unwrap();
    let truth = twin.plant_frf(est.f_hz()).unwrap();
    let med = ambid::validation::median_relative_error(est.values(), &truth);
    println!(
        "LPM plant: median error {:.3} % over {} lines",
        100.0 * med,
        est.f_hz().len()
    );
    // default twin noise (0.2 µm): the error is what the written standard deviations say
    assert!(med < 0.05, "{med}");
    let sd = est.std().unwrap();
    let inside = est
        .values()
        .iter()
        .zip(&truth)
        .zip(&sd)
        .filter(|((e, t), s)| (*e - *t).norm() <= 2.0 * **s)
        .count() as f64
        / sd.len() as f64;
    println!("truth inside ±2σ on {:.1} % of the lines", 100.0 * inside);
    assert!((0.9..0.99).contains(&inside), "{inside}");
    assert_eq!(frf.extra("fs_hz").unwrap()[0], 20_000.0);
    // degree 4 needs (R + 1)(m + 1) = 10 parameters: a 7-line window leaves none
    let o = ambid(&[
        "frf",
        s(&data),
        "--method",
        "lpm",
        "--lpm-degree",
        "4",
        "--lpm-half-width",
        "3",
        "--out",
        s(&d.join("bad.csv")),
    ]);
    assert!(!o.status.success());
    println!("{}", text(&o));
    assert!(!d.join("bad.csv").exists());
    // the Local Rational Method on the same record
    let out_lrm = d.join("frf_lrm.csv");
    let o = ambid(&[
        "frf",
        s(&data),
        "--method",
        "lrm",
        "--band",
        "10,1000",
        "--out",
        s(&out_lrm),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    println!("{}", text(&o));
    assert!(text(&o).contains("LRM: degrees (Rn, Rd, Rm) = (2, 2, 2)"));
    let frf = ambid::io::csv::read_frf_csv(&out_lrm).unwrap();
    let est = frf.frd("plant", 5e-5).unwrap();
    let truth = twin.plant_frf(est.f_hz()).unwrap();
    let med_lrm = ambid::validation::median_relative_error(est.values(), &truth);
    println!("LRM plant: median error {:.3} %", 100.0 * med_lrm);
    assert!(med_lrm < 0.05, "{med_lrm}");
    let o = ambid(&[
        "frf",
        s(&data),
        "--method",
        "lrm",
        "--lrm-degrees",
        "2,0,2",
        "--out",
        s(&d.join("bad.csv")),
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("denominator degree"), "{}", text(&o));
    let _ = std::fs::remove_dir_all(&d);
}

/// `ambid frf` without options on a periodic record finds the period in `r` and averages
/// periods (the default since 2026-12-01): on random rig 47 with a PRBS and a multisine, the
/// found period is the design's (meta.json), the output equals `--period-samples N`'s byte for
/// byte, and the plant FRF's error against the twin's exact plant (truth.csv) is the noise its
/// standard deviations state. A noise record keeps Welch; `--method welch` forces it; a
/// record with fewer than two periods after `--skip-periods` falls back to Welch; conflicting
/// options are refused with nothing written.
#[test]
fn frf_finds_the_period_of_a_periodic_record() {
    let d = tmpdir("period-found");
    for signal in ["prbs", "multisine"] {
        let sim = d.join(signal);
        let o = ambid(&[
            "simulate",
            "--rig-seed",
            "47",
            "--mode",
            "linear",
            "--signal",
            signal,
            "--seed",
            "3",
            "--out",
            s(&sim),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        let meta: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(sim.join("meta.json")).unwrap()).unwrap();
        let p = meta["period_samples"].as_u64().unwrap();
        let data = sim.join("data.csv");
        let auto = d.join(format!("{signal}_auto.csv"));
        let t = text(&ambid(&["frf", s(&data), "--out", s(&auto)]));
        assert!(
            t.contains(&format!("repeats every {p} samples")) && t.contains("period averaging"),
            "{signal}: {t}"
        );
        // the leakage note is Welch's alone
        assert!(
            !t.contains("not the leakage bias at lightly"),
            "{signal}: {t}"
        );
        let given = d.join(format!("{signal}_given.csv"));
        let ps = p.to_string();
        let o = ambid(&["frf", s(&data), "--period-samples", &ps, "--out", s(&given)]);
        assert!(o.status.success(), "{}", text(&o));
        assert_eq!(
            std::fs::read(&auto).unwrap(),
            std::fs::read(&given).unwrap(),
            "{signal}: the found period's FRF is the given period's"
        );
        // against the exact plant on the lines of 10–1000 Hz: mean |G − P|²/σ² near 1
        let (h, rows) = read_csv(&auto);
        let c = |n: &str| h.iter().position(|x| x == n).unwrap();
        let (f, re, im, sd) = (c("f_hz"), c("plant_re"), c("plant_im"), c("plant_std"));
        let rows: Vec<&Vec<f64>> = rows
            .iter()
            .filter(|r| (10.0..=1000.0).contains(&r[f]))
            .collect();
        let fl: Vec<f64> = rows.iter().map(|r| r[f]).collect();
        let twin = ambid_twin::Twin::new(ambid_twin::random_rig(47).unwrap()).unwrap();
        let truth = twin.plant_frf(&fl).unwrap();
        let z2: Vec<f64> = rows
            .iter()
            .zip(&truth)
            .map(|(r, t)| ((r[re] - t.re).powi(2) + (r[im] - t.im).powi(2)) / (r[sd] * r[sd]))
            .collect();
        let m = crate::common::mean(&z2);
        println!(
            "{signal}: period {p}, {} lines, mean |G - P|²/σ² {m:.3}",
            z2.len()
        );
        assert!(z2.len() > 50 && (0.6..1.6).contains(&m), "{signal}: {m}");
        // --method welch: Welch whatever the record
        let w = d.join(format!("{signal}_welch.csv"));
        let t = text(&ambid(&[
            "frf",
            s(&data),
            "--method",
            "welch",
            "--out",
            s(&w),
        ]));
        assert!(t.contains("Welch:") && !t.contains("repeats"), "{t}");
        assert!(t.contains("not the leakage bias at lightly"), "{t}");
    }
    let data = d.join("prbs").join("data.csv");
    // a record cut to 8.5 periods (rows 1–43 478): the found period, the tail ignored
    let cut = d.join("cut.csv");
    let t = text(&ambid(&[
        "frf",
        s(&data),
        "--to",
        "#43478",
        "--out",
        s(&cut),
    ]));
    assert!(
        t.contains("repeats every 5115 samples (8 periods") && t.contains("incomplete period"),
        "{t}"
    );
    // 20 periods, 19 dropped: one left, Welch
    let few = d.join("few.csv");
    let t = text(&ambid(&[
        "frf",
        s(&data),
        "--skip-periods",
        "19",
        "--out",
        s(&few),
    ]));
    assert!(t.contains("fewer than 2") && t.contains("Welch:"), "{t}");
    // a noise excitation does not repeat: Welch, no period claimed
    let sim = d.join("noise");
    let o = ambid(&[
        "simulate",
        "--rig-seed",
        "47",
        "--mode",
        "linear",
        "--signal",
        "noise",
        "--out",
        s(&sim),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&ambid(&[
        "frf",
        s(&sim.join("data.csv")),
        "--out",
        s(&d.join("noise.csv")),
    ]));
    assert!(t.contains("Welch:") && !t.contains("repeats"), "{t}");
    // conflicting options: refused, nothing written
    for args in [
        &["--method", "welch", "--period-samples", "5115"][..],
        &["--period-samples", "5115", "--nperseg", "1024"][..],
        &["--period-samples", "5115", "--window", "rect"][..],
    ] {
        let out = d.join("refused.csv");
        let mut a = vec!["frf", s(&data), "--out", s(&out)];
        a.extend_from_slice(args);
        let o = ambid(&a);
        let t = text(&o);
        assert!(
            !o.status.success() && t.contains("--period-samples"),
            "{args:?}: {t}"
        );
        assert!(!out.exists(), "{args:?}");
    }
}

/// An FRF file is read only when every field is a finite number, every `_std` non-negative and
/// `f_hz` strictly increasing; each refusal names the column and the data row. A negative
/// standard deviation was read before as its square, a variance, unnoticed (found on
/// 2026-12-05: `ambid uncertainty` wrote its files from such an FRF).
#[test]
fn frf_files_with_bad_fields_are_refused_with_the_row_named() {
    let d = tmpdir("frf-bad-fields");
    let good = "f_hz,plant_re,plant_im,plant_std\n1,1,0,0.1\n2,0.5,-0.5,0.1\n3,0.2,-0.4,0.1\n";
    let p = d.join("good.csv");
    std::fs::write(&p, good).unwrap();
    let f = ambid::io::csv::read_frf_csv(&p).unwrap();
    let frd = f.frd("plant", 1e-3).unwrap();
    let var = frd.variance().unwrap();
    assert!(
        var.len() == 3 && var.iter().all(|v| (v - 0.01).abs() < 1e-15),
        "{var:?}"
    );
    let cases = [
        (
            "2,0.5,-0.5,-0.1",
            "column `plant_std`, data row 2",
            "negative",
        ),
        (
            "2,NaN,-0.5,0.1",
            "column `plant_re`, data row 2",
            "not finite",
        ),
        (
            "1,0.5,-0.5,0.1",
            "f_hz must increase strictly",
            "data row 2",
        ),
    ];
    for (row, what, why) in cases {
        let text_in = good.replace("2,0.5,-0.5,0.1", row);
        let p = d.join("bad.csv");
        std::fs::write(&p, &text_in).unwrap();
        let e = ambid::io::csv::read_frf_csv(&p).unwrap_err().to_string();
        assert!(e.contains(what) && e.contains(why), "{row}: {e}");
        // and through a command: refused, nothing written
        let out = d.join("model.json");
        let o = ambid(&[
            "fit",
            s(&p),
            "--quantity",
            "plant",
            "--structure",
            "ss",
            "--order",
            "1",
            "--fs",
            "1000",
            "--out",
            s(&out),
        ]);
        // exit code 3: input data (docs/workflow.md, "Exit codes")
        assert_eq!(o.status.code(), Some(3), "{row}: {}", text(&o));
        assert!(text(&o).contains(what), "{row}: {}", text(&o));
        assert!(!out.exists(), "{row}: a model was written");
    }
}
