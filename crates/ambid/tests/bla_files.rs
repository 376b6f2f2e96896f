//! The robust BLA from recorded files, end to end through the CLI as an engineer would run it on
//! a rig: `ambid excite multisine --phases random --realisations M` writes the excitations,
//! `ambid simulate --excitation-file` records each on the twin (standing in for the rig), and
//! `ambid bla --record PCT:PATH …` (or the workflow's `[bla] files`) estimates the BLA. The
//! estimates are checked against the twin's exact linearised plant.

use crate::common::{ambid, s, text, tmpdir};
use ambid::workflow::{self, Progress, Verbosity, WorkflowConfig};
use std::path::{Path, PathBuf};

/// Samples per multisine period (20 Hz lines at 20 kHz).
const N: usize = 1000;
/// Periods per record: one transient period, then P = 4.
const PERIODS: usize = 5;
/// Realisations per level (linear twin).
const M: usize = 4;
/// Realisations per level (nonlinear twin: the NL variance has M − 1 degrees of freedom per line).
const M_NL: usize = 8;

/// Writes `m` realisations at `level_pct` (RMS, % of i_sat = 2 A) and records each on the twin;
/// returns the data files.
fn record_level(d: &Path, level_pct: f64, mode: &str, seed0: u64, m: usize) -> Vec<PathBuf> {
    let rms = format!("{}", level_pct / 100.0 * 2.0);
    let r = d.join(format!("r{level_pct}.csv"));
    let o = ambid(&[
        "excite",
        "multisine",
        "--phases",
        "random",
        "--grid",
        "random-odd",
        "--f-min",
        "20",
        "--f-max",
        "2000",
        "--period-samples",
        &N.to_string(),
        "--periods",
        &PERIODS.to_string(),
        "--rms",
        &rms,
        "--seed",
        "5",
        "--realisations",
        &m.to_string(),
        "--out",
        s(&r),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    (1..=m)
        .map(|m| {
            let rm = d.join(format!("r{level_pct}_m{m}.csv"));
            assert!(rm.exists(), "{} not written", rm.display());
            let out = d.join(format!("l{level_pct}m{m}"));
            let o = ambid(&[
                "simulate",
                "--excitation-file",
                s(&rm),
                "--mode",
                mode,
                "--seed",
                &(seed0 + m as u64).to_string(),
                "--out",
                s(&out),
            ]);
            assert!(o.status.success(), "{}", text(&o));
            out.join("data.csv")
        })
        .collect()
}

fn record_args(files: &[(f64, &[PathBuf])]) -> Vec<String> {
    let mut v = Vec::new();
    for (l, fs) in files {
        for f in fs.iter() {
            v.push("--record".to_string());
            v.push(format!("{l}:{}", f.display()));
        }
    }
    v
}

fn run_bla(extra: &[String], out: &Path) -> std::process::Output {
    let mut args: Vec<&str> = vec!["bla"];
    args.extend(extra.iter().map(String::as_str));
    let n = N.to_string();
    args.extend([
        "--period-samples",
        &n,
        "--skip-periods",
        "1",
        "--out",
        s(out),
    ]);
    ambid(&args)
}

fn read_csv(p: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let t = std::fs::read_to_string(p).unwrap();
    let mut lines = t.lines();
    let header = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    (header, rows)
}

fn col(header: &[String], name: &str) -> usize {
    header.iter().position(|h| h == name).unwrap()
}

/// Linear twin: the per-line BLA from files agrees with the exact plant within its own
/// uncertainty, and the nonlinear variance is statistically zero.
#[test]
fn recorded_bla_on_the_linear_twin_matches_the_exact_plant() {
    let d = tmpdir("bla-files-linear");
    let files = record_level(&d, 8.0, "linear", 100, M);
    let out = d.join("bla8.csv");
    let o = run_bla(&record_args(&[(8.0, &files)]), &out);
    assert!(o.status.success(), "{}", text(&o));
    println!("{}", text(&o));
    // without --period-samples: the period found in every realisation's r, the same output
    let found = d.join("bla8_found.csv");
    let mut args = vec!["bla".to_string()];
    args.extend(record_args(&[(8.0, &files)]));
    args.extend(["--skip-periods", "1", "--out"].map(String::from));
    args.push(found.display().to_string());
    let o = ambid(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        o.status.success() && text(&o).contains(&format!("repeats every {N} samples")),
        "{}",
        text(&o)
    );
    assert_eq!(
        std::fs::read(&out).unwrap(),
        std::fs::read(&found).unwrap(),
        "the found period's BLA is the given period's"
    );
    let (h, rows) = read_csv(&out);
    let f: Vec<f64> = rows
        .iter()
        .map(|r| r[col(&h, "f_hz")].parse().unwrap())
        .collect();
    let twin = ambid_twin::Twin::new(ambid_twin::TwinConfig::default()).unwrap();
    let truth = twin.plant_frf(&f).unwrap();
    let (mut inside, mut counted, mut errs) = (0usize, 0usize, Vec::new());
    let (mut z_nl, mut n_nl) = (0.0, 0usize);
    for (row, g0) in rows.iter().zip(&truth) {
        let fhz: f64 = row[col(&h, "f_hz")].parse().unwrap();
        if !(20.0..=1000.0).contains(&fhz) {
            continue;
        }
        let g = ambid_core::c64::new(
            row[col(&h, "bla_re")].parse().unwrap(),
            row[col(&h, "bla_im")].parse().unwrap(),
        );
        let sd: f64 = row[col(&h, "bla_std")].parse().unwrap();
        let noise_sd: f64 = row[col(&h, "noise_std")].parse().unwrap();
        let e = (g - g0).norm();
        errs.push(e / g0.norm());
        counted += 1;
        // noise-only complex error: |e|² / σ²_n ~ Exp(1) for a circular complex Gaussian, so
        // P(|e| > 2.45 σ_n) = e^{-6} ≈ 0.25 %
        if e <= 2.45 * noise_sd {
            inside += 1;
        }
        let var_nl: f64 = row[col(&h, "var_nl")].parse().unwrap();
        z_nl += var_nl / (M as f64 * noise_sd * noise_sd);
        n_nl += 1;
        let _ = sd;
    }
    errs.sort_by(f64::total_cmp);
    let median = errs[errs.len() / 2];
    println!(
        "linear twin, 8 %: {counted} lines in 20–1000 Hz, median |G − G0|/|G0| = {:.3} %, {inside} inside 2.45 σ_n, mean var_nl/(M σ²_n) = {:.3}",
        100.0 * median,
        z_nl / n_nl as f64
    );
    assert!(counted >= 15, "{counted} lines");
    assert!(inside as f64 >= 0.9 * counted as f64, "{inside}/{counted}");
    assert!(median < 0.05, "median error {median}");
    // var_nl = M(σ²_BLA − σ²_n) is zero on average for a linear system: relative to the noise
    // variance of one realisation its band mean stays within a few standard errors of 0
    // (M − 1 = 3 degrees of freedom per line)
    assert!((z_nl / n_nl as f64).abs() < 1.0, "{}", z_nl / n_nl as f64);
    let _ = std::fs::remove_dir_all(&d);
}

/// Nonlinear twin at 4 % and 32 % RMS: the file route finds the NL variance statistically zero
/// at 4 % and significant at 32 % with odd detection lines far above the noise; with the
/// saturation current given it leaves the clipping level out. The workflow's `[bla] files` on
/// the same records gives the same numbers as the CLI.
#[test]
fn recorded_bla_study_on_the_nonlinear_twin_and_in_the_workflow() {
    let d = tmpdir("bla-files-nonlinear");
    let low = record_level(&d, 4.0, "nonlinear", 200, M_NL);
    let high = record_level(&d, 32.0, "nonlinear", 300, M_NL);
    let args = record_args(&[(4.0, &low), (32.0, &high)]);
    let out = d.join("study.csv");
    let o = run_bla(&args, &out);
    assert!(o.status.success(), "{}", text(&o));
    println!("{}", text(&o));
    let (h, rows) = read_csv(&out);
    assert_eq!(rows.len(), 2);
    let v = |r: usize, c: &str| -> f64 { rows[r][col(&h, c)].parse().unwrap() };
    assert_eq!(v(0, "realisations") as usize, M_NL);
    assert_eq!(v(0, "periods") as usize, PERIODS - 1);
    assert!(
        v(0, "nl_rel").abs() < 3.0 * v(0, "nl_rel_se"),
        "4 %: NL {} ± {}",
        v(0, "nl_rel"),
        v(0, "nl_rel_se")
    );
    assert!(
        v(1, "nl_rel") > 3.0 * v(1, "nl_rel_se"),
        "32 %: NL {} ± {}",
        v(1, "nl_rel"),
        v(1, "nl_rel_se")
    );
    assert!(v(1, "odd_db") > 10.0, "odd lines {} dB", v(1, "odd_db"));
    assert!(
        v(0, "odd_db").abs() < 3.0,
        "odd lines {} dB",
        v(0, "odd_db")
    );
    // noise share ∝ 1/level²: 64× from 4 % to 32 %, within the scatter of 8 × 4 periods
    let ratio = v(0, "noise_rel") / v(1, "noise_rel");
    assert!((30.0..130.0).contains(&ratio), "noise ratio {ratio}");
    // without a limit the clipping is unknown; with it, the clipping level is left out
    let out2 = d.join("study_isat.csv");
    let mut a2 = args.clone();
    a2.extend(["--i-sat".to_string(), "2".to_string()]);
    let o2 = run_bla(&a2, &out2);
    assert!(o2.status.success(), "{}", text(&o2));
    let (h2, rows2) = read_csv(&out2);
    let sat32: f64 = rows2[1][col(&h2, "saturated_fraction")].parse().unwrap();
    assert!(sat32 > 0.01, "saturated fraction at 32 %: {sat32}");
    assert_eq!(rows2[0][col(&h2, "recommended")], "1");
    assert!(text(&o2).contains("left out"), "{}", text(&o2));

    // the workflow on the same records
    let mut entries = Vec::new();
    for (l, fs) in [(4.0, &low), (32.0, &high)] {
        for f in fs.iter() {
            entries.push(format!(
                "{{ level_pct = {l:.1}, path = \"{}\" }}",
                f.strip_prefix(&d).unwrap().display()
            ));
        }
    }
    let wf = d.join("bla.toml");
    std::fs::write(
        &wf,
        format!(
            "source = \"files\"\nsteps = [\"bla\"]\n[data]\nidentification = \"{}\"\ntime = \"t\"\nr = \"r\"\n\
             period_samples = {N}\nskip_periods = 1\n[bla]\nfiles = [{}]\n",
            low[0].strip_prefix(&d).unwrap().display(),
            entries.join(", ")
        ),
    )
    .unwrap();
    // with [data] period_samples, and without it (the period found in the records): the CLI's
    let given = std::fs::read_to_string(&wf).unwrap();
    let found = d.join("bla_found.toml");
    std::fs::write(
        &found,
        given.replace(&format!("period_samples = {N}\n"), ""),
    )
    .unwrap();
    for path in [&wf, &found] {
        let cfg = WorkflowConfig::from_path(path).unwrap();
        let mut progress = Progress::new(Verbosity::Quiet);
        let outcome = workflow::run(&cfg, &d, &mut progress).unwrap();
        let bla = outcome
            .timings
            .iter()
            .find(|t| t.step == "bla")
            .expect("bla step");
        assert_eq!(bla.status, "done", "{}", path.display());
        let levels = outcome.summary["bla"]["levels"].as_array().unwrap();
        assert_eq!(levels.len(), 2);
        for (k, lv) in levels.iter().enumerate() {
            for key in ["noise_rel", "nl_rel", "nl_rel_se"] {
                let w = lv[key].as_f64().unwrap();
                let c = v(k, key);
                // the workflow detrends (mean) like every other file step; the CLI does not
                assert!(
                    (w - c).abs() <= 1e-6 * c.abs().max(1e-300) + 1e-9 * v(k, "noise_rel"),
                    "level {k} {key}: workflow {w} vs CLI {c}"
                );
            }
            assert!(lv["bla_vs_linear_pct"].is_null());
        }
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// Bad recorded input: each mistake gets a message that names the fix.
#[test]
fn recorded_bla_bad_input_is_explained() {
    let d = tmpdir("bla-files-bad");
    let files = record_level(&d, 8.0, "linear", 400, M);
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            record_args(&[(8.0, &files[..1])]),
            "at least 2 realisations",
        ),
        (
            vec!["--record".into(), files[0].display().to_string()],
            "LEVEL_PCT:PATH",
        ),
        (
            vec!["--record".into(), format!("150:{}", files[0].display())],
            "(0, 100]",
        ),
    ];
    for (args, want) in cases {
        let o = run_bla(&args, &d.join("x.csv"));
        assert!(!o.status.success());
        assert!(text(&o).contains(want), "want `{want}` in: {}", text(&o));
    }
    // a period that does not divide the record
    let mut args = vec!["bla".to_string()];
    args.extend(record_args(&[(8.0, &files)]));
    args.extend(["--period-samples", "999", "--out"].map(String::from));
    args.push(d.join("y.csv").display().to_string());
    let o = ambid(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!o.status.success());
    println!("{}", text(&o));
    assert!(text(&o).contains("period"), "{}", text(&o));
    // no period given, and one realisation's excitation does not repeat (noise): named,
    // nothing written
    let noise = d.join("noise");
    let o = ambid(&["simulate", "--signal", "noise", "--out", s(&noise)]);
    assert!(o.status.success(), "{}", text(&o));
    let mut args = vec!["bla".to_string()];
    args.extend(record_args(&[(
        8.0,
        &[files[0].clone(), noise.join("data.csv")],
    )]));
    let none = d.join("none.csv");
    args.extend(["--out".to_string(), none.display().to_string()]);
    let o = ambid(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let t = text(&o);
    assert!(
        !o.status.success() && t.contains("--period-samples") && t.contains("does not repeat"),
        "{t}"
    );
    assert!(t.contains("noise"), "the realisation is named: {t}");
    assert!(!none.exists());
    // an excitation sampled at another rate than the twin's
    let r = d.join("slow.csv");
    std::fs::write(&r, "t,r\n0,0.1\n0.001,0.2\n0.002,0.1\n").unwrap();
    let o = ambid(&[
        "simulate",
        "--excitation-file",
        s(&r),
        "--out",
        s(&d.join("z")),
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("20000 Hz"), "{}", text(&o));
    let _ = std::fs::remove_dir_all(&d);
}

/// The library refuses a level with one realisation or with closed- and open-loop records mixed.
#[test]
fn recorded_levels_are_checked() {
    use ambid::bla::{bla_of_level, Realisation, RecordedLevel, RecordedPlan};
    let x = |r: bool| Realisation {
        r: r.then(|| [1.0, -1.0, 0.5, -0.5].repeat(3)),
        u: [1.0, -1.0, 0.5, -0.5].repeat(3),
        y: [2.0, -2.0, 1.0, -1.0].repeat(3),
        saturated_fraction: None,
        source: "x".into(),
    };
    let plan = RecordedPlan {
        fs: 4.0,
        period_samples: 4,
        skip_periods: 0,
        summary_band_hz: (0.1, 2.0),
    };
    let one = RecordedLevel {
        level_pct: 5.0,
        realisations: vec![x(true)],
    };
    let e = bla_of_level(&one, &plan).unwrap_err().to_string();
    assert!(e.contains("at least 2 realisations"), "{e}");
    let mixed = RecordedLevel {
        level_pct: 5.0,
        realisations: vec![x(true), x(false)],
    };
    let e = bla_of_level(&mixed, &plan).unwrap_err().to_string();
    assert!(e.contains("give r for all"), "{e}");
}
