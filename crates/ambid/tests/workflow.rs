//! The seed workflow end to end (`ambid run`): on the twin against its exact linearised plant,
//! on the measured files under ../shared/data/real, and with bad input.

use crate::common;
use crate::common::{ambid, s, text, tmpdir};
use ambid::report::Block;
use ambid::workflow::{self, Outcome, Progress, Verbosity, WorkflowConfig};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn num(v: &Value, path: &str) -> f64 {
    let mut x = v;
    for k in path.split('.') {
        x = &x[k];
    }
    x.as_f64()
        .unwrap_or_else(|| panic!("summary has no number at {path}: {x}"))
}

fn run(cfg: &WorkflowConfig, base: &Path) -> Outcome {
    let mut progress = Progress::new(Verbosity::Quiet);
    workflow::run(cfg, base, &mut progress).unwrap_or_else(|e| panic!("workflow failed: {e}"))
}

/// The report opens with its summary (issue 18): a headline table that states the chosen model
/// with its validation fit, the excitation level, the ISO zone and the unstable poles as
/// summary.json records them; and no text of the page (outside style and SVG) looks like Rust
/// debug output. (The dump of every summary.json key that used to end the report is gone: the
/// summary links the file instead.)
fn assert_summary_in_report(out: &Outcome) {
    use ambid::report::format_number as f;
    let s = &out.report.sections[0];
    assert_eq!(s.id, "summary", "the first section is {}", s.id);
    let table = s
        .blocks
        .iter()
        .find_map(|b| match b {
            Block::Table(t) if t.id == "headline" => Some(t),
            _ => None,
        })
        .expect("the summary has its headline table");
    let row = |what: &str| -> String {
        table
            .rows
            .iter()
            .find(|r| r[0].starts_with(what))
            .map(|r| r[1].clone())
            .unwrap_or_else(|| panic!("no summary row '{what}': {:?}", table.rows))
    };
    let sm = &out.summary;
    if let Some(chosen) = sm["models"]["chosen"].as_str() {
        let r = row("chosen model");
        assert!(r.starts_with(chosen), "{r}");
        if let Some(fit) = sm["validation"]["fit_y_pct"].as_f64() {
            assert!(r.contains(&format!("{} %", f(fit))), "{r}");
        }
        let poles = row("unstable poles");
        if let Some(n) = sm["pole_zero"]["chosen_unstable_poles"].as_f64() {
            let stated = if n == 0.0 {
                "none".to_string()
            } else {
                format!("{n:.0}:")
            };
            assert!(poles.starts_with(&stated), "{poles} vs {n}");
        }
    }
    if let Some(level) = sm["identification"]["level_pct"].as_f64() {
        let r = row("excitation level");
        assert!(r.starts_with(&format!("{} %", f(level))), "{r}");
    }
    if let Some(zone) = sm["iso"]["zone"].as_str() {
        let r = row("peak sensitivity");
        assert!(r.starts_with(&format!("zone {zone}")), "{r}");
    }
    row("warnings");
    // visible text without style and SVG
    let html = out.report.to_html();
    let mut visible = String::new();
    let mut rest = html.as_str();
    while let Some(i) = rest.find(['<']) {
        visible.push_str(&rest[..i]);
        let skip_to = ["<svg", "<style"]
            .iter()
            .find(|t| rest[i..].starts_with(*t))
            .map(|t| format!("</{}>", &t[1..]));
        rest = match skip_to {
            Some(end) => rest[i..]
                .find(&end)
                .map_or("", |j| &rest[i + j + end.len()..]),
            None => rest[i..].find('>').map_or("", |j| &rest[i + j + 1..]),
        };
    }
    visible.push_str(rest);
    for pat in ["Some(", "::", "None,", "(None", "None)"] {
        assert!(!visible.contains(pat), "debug text '{pat}' on the page");
    }
}

/// Writes the report and checks it in headless Chromium: it renders, the summary is the first
/// section, nothing is wider than a 1280-px page and no visible text looks like debug output
/// (`BrowserCheck::problems`). Skipped, saying so, without Chromium.
fn browser_checked(out: &Outcome, tag: &str) {
    let dir = tmpdir(tag);
    let dest = dir.join("report");
    out.write(&dest, false).unwrap();
    match ambid::report::browser_check(&dest.join("report.html")) {
        Ok(check @ ambid::report::BrowserCheck::Checked(_)) => {
            assert!(check.problems().is_empty(), "{tag}: {:?}", check.problems());
            let Some(c) = check.counts() else {
                unreachable!()
            };
            assert_eq!(c.first_section, "summary", "{tag}");
        }
        Ok(ambid::report::BrowserCheck::Unavailable { reason }) => common::skip(
            &format!("workflow: the {tag} report in headless Chromium"),
            &reason,
        ),
        Err(e) => panic!("browser check failed: {e}"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn figures(out: &Outcome) -> Vec<&ambid::report::Figure> {
    out.report
        .sections
        .iter()
        .flat_map(|s| &s.blocks)
        .filter_map(|b| match b {
            Block::Figure(f) => Some(f),
            _ => None,
        })
        .collect()
}

#[test]
fn the_default_workflow_on_the_twin_recovers_the_truth_and_reports_every_number() {
    let out = run(&WorkflowConfig::default(), Path::new("."));
    let sm = &out.summary;
    for t in &out.timings {
        assert_eq!(t.status, "done", "step {} was {}", t.step, t.status);
    }
    // the chosen model's poles in Hz: its unstable pole at the exact plant's, s = f_s ln z
    let twin = ambid_twin::Twin::new(ambid_twin::TwinConfig::default()).unwrap();
    let z_true = twin.plant_unstable_poles().unwrap()[0];
    let f_true = z_true.norm().ln() / twin.ts() / std::f64::consts::TAU;
    let poles_hz = out
        .report
        .sections
        .iter()
        .flat_map(|s| &s.blocks)
        .find_map(|b| match b {
            Block::Table(t) if t.id == "poles_hz" => Some(t),
            _ => None,
        })
        .expect("the table of the chosen model's poles in Hz");
    let unstable: Vec<f64> = poles_hz
        .rows
        .iter()
        .filter(|r| r[4].starts_with("unstable"))
        .map(|r| r[2].parse::<f64>().unwrap())
        .collect();
    assert_eq!(unstable.len(), 1, "{:?}", poles_hz.rows);
    assert!(
        (unstable[0] - f_true).abs() < 0.03 * f_true,
        "unstable pole at {} Hz, exact plant {f_true} Hz",
        unstable[0]
    );
    // amplitude study: a recommended range inside the studied levels, and the chosen level in it
    let (lo, hi) = (
        num(sm, "amplitude.recommended_min_pct"),
        num(sm, "amplitude.recommended_max_pct"),
    );
    let chosen = num(sm, "amplitude.chosen_pct");
    assert!(
        (2.0..=16.0).contains(&lo) && lo <= chosen && chosen <= hi,
        "{lo} {chosen} {hi}"
    );
    // the robust BLA at the same levels: one row per level and a recommended level among them
    let bla = sm["bla"]["levels"].as_array().unwrap();
    assert_eq!(bla.len(), 8);
    let rec = num(sm, "bla.recommended_pct");
    assert!(bla.iter().any(|r| num(r, "level_pct") == rec), "{rec}");
    // the nonparametric plant against the twin's exact linearised plant (nonlinear twin: the
    // estimate also carries the force law's distortion)
    // (issue 16: the quality band is derived from the excitation now, 3.9–1800 Hz here; the
    // seed paper's bar is stated over 10–1000 Hz, so the check reads that figure)
    let e_frf = num(sm, "frf.plant_median_error_vs_truth_10_1000_pct");
    assert!(e_frf < 3.0, "FRF median error vs truth {e_frf} %");
    // the chosen parametric model against the exact plant, and through the closed loop
    let e_model = num(sm, "models.chosen_error_vs_truth_pct");
    assert!(
        e_model < 2.0,
        "chosen model's median error vs truth {e_model} %"
    );
    let (fit, exact) = (
        num(sm, "validation.fit_y_pct"),
        num(sm, "validation.exact_plant_fit_y_pct"),
    );
    assert!(
        fit > 90.0 && fit > exact - 1.0,
        "validation fit {fit} % (exact plant {exact} %)"
    );
    // one unstable plant pole, as in the twin
    assert_eq!(num(sm, "pole_zero.chosen_unstable_poles"), 1.0);
    // the chirp reconstruction and the ISO verdict agree with the truth
    assert!(num(sm, "reconstruction.fit_y_pct") > 85.0);
    assert_eq!(sm["iso"]["zone"], sm["iso"]["truth"]["zone"]);
    let (pk, pk_true) = (num(sm, "iso.measured.peak"), num(sm, "iso.truth.peak"));
    assert!((pk - pk_true).abs() < 0.05 * pk_true, "{pk} vs {pk_true}");
    assert_summary_in_report(&out);
    // every figure has data in every panel
    let figs = figures(&out);
    assert!(figs.len() >= 14, "{} figures", figs.len());
    for f in &figs {
        assert!(!f.caption.is_empty(), "{} has no caption", f.id);
        let csv = f.to_csv();
        assert!(csv.lines().count() > 2, "{} has no data", f.id);
    }
    // written atomically, with the models in every format
    let dir = tmpdir("wf-twin");
    let dest = dir.join("report");
    let files = out.write(&dest, false).unwrap();
    for name in [
        "report.html",
        "summary.json",
        "figures/plant_frf.csv",
        "tables/model_comparison.csv",
    ] {
        assert!(dest.join(name).is_file(), "{name} missing");
    }
    let chosen = sm["models"]["chosen"]
        .as_str()
        .unwrap()
        .replace(' ', "")
        .to_lowercase();
    for ext in ["json", "m", "mat", "npz"] {
        assert!(
            dest.join(format!("models/{chosen}.{ext}")).is_file(),
            "{chosen}.{ext}"
        );
    }
    assert_eq!(files.len(), walk(&dest));
    // ARX and OE candidates (fitted to the FRF, held in companion form) are exported as
    // polynomials: idpoly in the script, B and F in the .npz/JSON; ss as idss (issue 18)
    let mut kinds = std::collections::BTreeSet::new();
    for e in std::fs::read_dir(dest.join("models")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_none_or(|x| x != "json") {
            continue;
        }
        let j: Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
        let st = j["meta"]["structure"].as_str().unwrap().to_string();
        let script = std::fs::read_to_string(p.with_extension("m")).unwrap();
        if st == "ss" {
            assert_eq!(j["kind"], "state_space", "{}", p.display());
            assert!(script.contains("= idss("), "{}", p.display());
        } else {
            assert_eq!(j["kind"], "polynomial", "{}", p.display());
            assert_eq!(j["structure"], st.as_str(), "{}", p.display());
            assert!(
                script.contains("= idpoly(A, B, C, D, F,"),
                "{}",
                p.display()
            );
        }
        kinds.insert(st);
    }
    assert!(kinds.contains("oe") && kinds.contains("ss"), "{kinds:?}");
    let back: Value =
        serde_json::from_str(&std::fs::read_to_string(dest.join("summary.json")).unwrap()).unwrap();
    assert_eq!(&back, sm);
    // a second write without force is refused and leaves the first intact
    assert!(out.write(&dest, false).is_err());
    assert!(dest.join("report.html").is_file());
    // the report renders in a real browser, every figure drawn, no console errors
    match ambid::report::browser_check(&dest.join("report.html")) {
        Ok(check @ ambid::report::BrowserCheck::Checked(_)) => {
            assert!(check.problems().is_empty(), "{:?}", check.problems());
            let Some(c) = check.counts() else {
                unreachable!()
            };
            assert_eq!(c.first_section, "summary");
            println!(
                "browser check: {} svgs, {} empty, {} console errors, screenshot {} bytes",
                c.svgs,
                c.empty_svgs,
                c.console_errors.len(),
                c.screenshot_bytes
            );
            assert!(
                c.svgs >= figs.len(),
                "{} svgs for {} figures",
                c.svgs,
                figs.len()
            );
        }
        Ok(ambid::report::BrowserCheck::Unavailable { reason }) => {
            common::skip("workflow: the twin report in headless Chromium", &reason)
        }
        Err(e) => panic!("browser check failed: {e}"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn walk(d: &Path) -> usize {
    std::fs::read_dir(d)
        .unwrap()
        .flatten()
        .map(|e| {
            if e.path().is_dir() {
                walk(&e.path())
            } else {
                1
            }
        })
        .sum()
}

fn shared(rel: &str) -> Option<PathBuf> {
    common::real_data(rel)
}

fn example(name: &str) -> (WorkflowConfig, PathBuf) {
    let p = root().join("examples/workflows").join(name);
    let cfg = WorkflowConfig::from_path(&p).unwrap();
    (cfg, p.parent().unwrap().to_path_buf())
}

fn table_row<'a>(sm: &'a Value, model: &str) -> &'a Value {
    sm["models"]["table"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["model"] == model)
        .unwrap_or_else(|| panic!("no row {model}"))
}

#[test]
fn the_workflow_runs_on_the_open_loop_robot_arm_and_skips_the_closed_loop_steps() {
    if shared("daisy-robot-arm/robot_arm.dat").is_none() {
        return;
    }
    let (cfg, base) = example("robot-arm.toml");
    let out = run(&cfg, &base);
    let sm = &out.summary;
    let status = |step: &str| {
        out.timings
            .iter()
            .find(|t| t.step == step)
            .map(|t| t.status.clone())
            .unwrap()
    };
    for step in ["amplitude", "operating_point", "reconstruction", "iso"] {
        assert_eq!(status(step), "skipped", "{step}");
    }
    for step in [
        "excitation",
        "frf",
        "order",
        "models",
        "pole_zero",
        "validation",
    ] {
        assert_eq!(status(step), "done", "{step}");
    }
    // the README's numpy baseline: ARX(8,8,1) simulation fit 97.13 % and ARX(6,6,1) 94.74 %
    // on the second half (its simulation starts from the measured outputs, ours from the
    // least-squares initial state, as MATLAB compare does)
    let f8 = num(table_row(sm, "ARX 8"), "validation_fit_pct");
    let f6 = num(table_row(sm, "ARX 6"), "validation_fit_pct");
    println!(
        "robot arm: ARX 8 {f8:.2} %, ARX 6 {f6:.2} %, chosen {}",
        sm["models"]["chosen"]
    );
    assert!((f8 - 97.13).abs() < 1.0, "ARX 8 {f8}");
    assert!((f6 - 94.74).abs() < 1.5, "ARX 6 {f6}");
    assert!(num(sm, "validation.fit_y_pct") >= f8 - 1e-9);
    assert_summary_in_report(&out);
    let html = out.report.to_html();
    assert!(html.contains("Open-loop data"), "no open-loop note");
    browser_checked(&out, "wf-robot-arm");
}

#[test]
fn the_workflow_runs_on_the_matlab_maglev_file() {
    if shared("magnetoshield-maglev/MagnetoShield_ID_Data.mat").is_none() {
        return;
    }
    let (cfg, base) = example("maglev.toml");
    let out = run(&cfg, &base);
    let sm = &out.summary;
    assert_eq!(num(sm, "data.identification_samples"), 3700.0);
    // the README's numpy baseline: direct ARX(3,3,1) one-step fit 97.10 % on the second half,
    // with one real pole outside the unit circle
    let row = table_row(sm, "ARX 3");
    let f3 = num(row, "validation_fit_pct");
    println!("maglev: ARX 3 one-step fit {f3:.2} %");
    assert!((f3 - 97.10).abs() < 0.3, "ARX 3 {f3}");
    assert_eq!(num(row, "unstable_poles"), 1.0);
    // the chosen (unstable) model is validated by its one-step predictor on the second half
    assert_eq!(sm["validation"]["kind"], "1-step prediction");
    assert!(num(sm, "validation.fit_y_pct") >= f3 - 0.5);
    assert_summary_in_report(&out);
    browser_checked(&out, "wf-maglev");
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn init_writes_an_example_that_parses_to_the_defaults() {
    let d = tmpdir("wf-init");
    let p = d.join("workflow.toml");
    let o = ambid(&["init", s(&p)]);
    assert!(o.status.success(), "{}", text(&o));
    let cfg = WorkflowConfig::from_path(&p).unwrap();
    assert_eq!(
        serde_json::to_value(&cfg).unwrap(),
        serde_json::to_value(WorkflowConfig::default()).unwrap()
    );
    let o = ambid(&["init", s(&p)]);
    assert_eq!(o.status.code(), Some(5), "{}", text(&o));
    assert!(text(&o).contains("--force"));
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn bad_input_gives_a_clear_message_an_exit_code_per_class_and_writes_nothing() {
    let d = tmpdir("wf-bad");
    let out = d.join("out");
    // an unknown key, reported with its line
    let wf = write(
        &d,
        "unknown.toml",
        "seed = 3\n\n[models]\norders = [6]\nbogus = 1\n",
    );
    let o = ambid(&["run", s(&wf), "--out", s(&out), "-q"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("line 5") && t.contains("bogus"), "{t}");
    // a value that is not allowed
    let wf = write(
        &d,
        "value.toml",
        "[models]\nstructures = [\"arx\", \"narx\"]\n",
    );
    let o = ambid(&["run", s(&wf), "--out", s(&out), "-q"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("narx"));
    // a missing data file
    let wf = write(
        &d,
        "missing.toml",
        "source = \"files\"\n[data]\nidentification = \"nowhere.csv\"\nfs_hz = 100.0\n",
    );
    let o = ambid(&["run", s(&wf), "--out", s(&out), "-q"]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    assert!(text(&o).contains("nowhere.csv"), "{}", text(&o));
    // a column that does not exist
    let rows: String = (0..400)
        .map(|k| format!("{},{}\n", (k as f64 * 0.1).sin(), (k as f64 * 0.1).cos()))
        .collect();
    write(&d, "data.csv", &format!("u,y\n{rows}"));
    let wf = write(
        &d,
        "column.toml",
        "source = \"files\"\n[data]\nidentification = \"data.csv\"\nfs_hz = 100.0\ny = \"displacement\"\n",
    );
    let o = ambid(&["run", s(&wf), "--out", s(&out), "-q"]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    assert!(text(&o).contains("displacement"), "{}", text(&o));
    // an unknown step on the command line
    let o = ambid(&["run", "--steps", "frf,bode", "--out", s(&out), "-q"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    // nothing half-written: neither the output nor a temporary directory
    assert!(!out.exists());
    let leftovers: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .flatten()
        .filter(|e| e.path().is_dir())
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // an existing output directory needs --force (checked before any work)
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("mine.txt"), "keep").unwrap();
    let o = ambid(&["run", "--steps", "excitation", "--out", s(&out), "-q"]);
    assert_eq!(o.status.code(), Some(5), "{}", text(&o));
    assert!(out.join("mine.txt").exists());
    let o = ambid(&[
        "run",
        "--steps",
        "excitation",
        "--out",
        s(&out),
        "-q",
        "--force",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(out.join("report.html").is_file() && !out.join("mine.txt").exists());
    let _ = std::fs::remove_dir_all(&d);
}

/// The studies run on recorded files too: records written by `ambid simulate` (CSV with a time
/// column) at two levels and at two operating points give the study tables, and the recorded
/// bias change shows the twin's true deviation.
#[test]
fn the_studies_run_on_recorded_files() {
    let d = tmpdir("wf-study-files");
    let sim = |name: &str, extra: &[&str]| {
        let out = d.join(name);
        let mut args = vec!["simulate", "--mode", "linear", "--out", s(&out)];
        args.extend_from_slice(extra);
        let o = ambid(&args);
        assert!(o.status.success(), "{}", text(&o));
    };
    sim("a05", &["--amplitude", "0.05"]);
    sim("a10", &["--amplitude", "0.10", "--seed", "2"]);
    sim(
        "bias80",
        &["--amplitude", "0.10", "--bias", "1.6", "--seed", "3"],
    );
    let wf = d.join("studies.toml");
    std::fs::write(
        &wf,
        r#"source = "files"
steps = ["amplitude", "operating_point", "frf"]
[data]
identification = "a10/data.csv"
time = "t"
r = "r"
i = "i"
period_samples = 5115
[amplitude_study]
files = [{ level_pct = 5.0, path = "a05/data.csv" }, { level_pct = 10.0, path = "a10/data.csv" }]
[operating_point]
files = [{ name = "nominal", path = "a10/data.csv" }, { name = "bias-20%", path = "bias80/data.csv" }]
[frf]
band_hz = [10.0, 2000.0]
quality_band_hz = [10.0, 1000.0]
"#,
    )
    .unwrap();
    let cfg = WorkflowConfig::from_path(&wf).unwrap();
    let out = run(&cfg, &d);
    for t in &out.timings {
        assert_eq!(t.status, "done", "{}", t.step);
    }
    let sm = &out.summary;
    let levels = sm["amplitude"]["levels"].as_array().unwrap();
    assert_eq!(levels.len(), 2);
    // the coherence rises with the level (noise fixed)
    assert!(num(&levels[1], "mean_coh_ry") > num(&levels[0], "mean_coh_ry"));
    // the recorded bias change: in the resonance band the estimate shows the true deviation
    let dev = num(sm, "operating_point.bias-20%.resonance_median_dev_pct");
    let twin = ambid::study::operating_point_on_twin(
        &ambid_twin::TwinConfig::default(),
        &ambid::study::seed_cases(&ambid_twin::TwinConfig::default())[..2],
        &ambid::experiment::ExcitationPlan::default(),
        ambid_twin::Mode::Linear,
        1,
        1,
        Some((10.0, 2000.0)),
    )
    .unwrap();
    let truth = twin
        .deviations
        .iter()
        .find(|x| x.band == "resonance")
        .and_then(|x| x.truth_median_rel_dev)
        .unwrap();
    println!(
        "bias −20 %, resonance band: from files {dev:.2} %, true {:.2} %",
        100.0 * truth
    );
    assert!(
        (dev - 100.0 * truth).abs() < 0.1 * 100.0 * truth,
        "{dev} vs {truth}"
    );
    assert_summary_in_report(&out);
    let _ = std::fs::remove_dir_all(&d);
}
