//! The optional workflow steps of issue 23, `uncertainty` and `physical`, on the default twin
//! (nonlinear, the workflow's own record and chosen model), checked against the twin's exact
//! linearisation (independent truth):
//!
//! * naming them runs the FRF and models steps they need (and `uncertainty` the amplitude
//!   study, for its term (e));
//! * `uncertainty`: the report section and `summary.json`'s entry; the robust gain margins are
//!   conservative and useful against the true loop (stable with the gain moved 90 % of the way to
//!   either margin, each margin at least half the true one);
//! * `physical`: k_i and k_x within 2 %, the bending frequency within 0.5 % of the twin's values,
//!   which the section shows beside the estimates;
//! * with recorded files and no `[physical]` drawing the step is skipped with the reason; with
//!   the drawing it runs and meets the same bars.

use ambid::uncertainty::loop_stable;
use ambid::workflow::{run, Progress, Step, Verbosity, WorkflowConfig};
use ambid_twin::{Twin, TwinConfig};
use std::path::Path;

/// The blocks of the report's section `id`, as debug text.
fn section_blocks(out: &ambid::workflow::Outcome, id: &str) -> String {
    let section = out
        .report
        .sections
        .iter()
        .find(|s| s.id == id)
        .unwrap_or_else(|| panic!("the {id} section"));
    format!("{:?}", section.blocks)
}

#[test]
fn uncertainty_and_physical_steps_on_the_twin() {
    let (all, _) = Step::with_prerequisites(&[Step::Uncertainty, Step::Physical]);
    assert_eq!(
        all,
        vec![
            Step::Amplitude,
            Step::Bla,
            Step::Frf,
            Step::Models,
            Step::Uncertainty,
            Step::Physical
        ]
    );
    let cfg = WorkflowConfig {
        steps: Some(all),
        ..WorkflowConfig::default()
    };
    let out = run(&cfg, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
    let sm = &out.summary;
    let ids: Vec<&str> = out.report.sections.iter().map(|s| s.id.as_str()).collect();
    assert!(
        ids.contains(&"uncertainty") && ids.contains(&"physical"),
        "{ids:?}"
    );

    // no operating-point step: no term (d), neither plotted nor in the summary
    assert!(out.report.series("uncertainty", "(d)").is_none());
    // term (c) from the robust BLA study's lowest level at or above the identification
    // level, unscaled; its groups cover the BLA's lines and the term is plotted
    let chosen = sm["amplitude"]["chosen_pct"].as_f64().unwrap();
    let want = sm["bla"]["levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["level_pct"].as_f64().unwrap())
        .filter(|l| *l >= chosen)
        .fold(f64::INFINITY, f64::min);
    let uc = &sm["uncertainty"];
    assert_eq!(uc["nonlinear_level_pct"].as_f64(), Some(want), "{chosen}");
    assert_eq!(uc["nonlinear_variance_scale"].as_f64(), Some(1.0));
    // term (e) through the model: the Wald test is in the summary and decides "kept"
    let ap = &uc["amplitude_projected"];
    let (stat, thr) = (
        ap["statistic"].as_f64().unwrap(),
        ap["threshold"].as_f64().unwrap(),
    );
    assert!(thr > 0.0 && stat >= 0.0, "{ap}");
    assert_eq!(ap["kept"].as_bool(), Some(stat > thr));
    let groups = uc["nonlinear_groups"].as_array().unwrap();
    assert!(!groups.is_empty());
    let significant = groups.iter().filter(|g| g["significant"] == true).count();
    println!(
        "term (c): {significant} of {} groups significant",
        groups.len()
    );
    assert_eq!(
        out.report.series("uncertainty", "(c)").is_some(),
        significant > 0
    );
    assert!(sm["uncertainty"].get("operating_cases").is_none());
    let twin = Twin::new(TwinConfig::default()).unwrap();
    let u = &sm["uncertainty"];
    println!("{}", serde_json::to_string_pretty(u).unwrap());
    assert_eq!(u["robustly_stable"], true);
    let (g_lo, g_hi) = (
        u["lower_gain_margin"].as_f64().unwrap(),
        u["upper_gain_margin"].as_f64().unwrap(),
    );
    let t = u["twin_gain_interval"].as_array().unwrap();
    let (t_lo, t_hi) = (t[0].as_f64().unwrap(), t[1].as_f64().unwrap());
    assert!(loop_stable(twin.plant(), twin.controller(), 1.0 + 0.9 * (g_hi - 1.0)).unwrap());
    assert!(loop_stable(twin.plant(), twin.controller(), 1.0 - 0.9 * (1.0 - g_lo)).unwrap());
    assert!(g_hi - 1.0 >= 0.5 * (t_hi - 1.0) && 1.0 - g_lo >= 0.5 * (1.0 - t_lo));
    // the check on the lines (no weight fit): the same bars on the nominal twin
    assert_eq!(u["lines_robustly_stable"], true);
    assert!(u["lines_raise"].as_f64().unwrap() >= 1.0);
    // the twin's FRF is noise-limited: its misfit is not rough, term (b) keeps its windows
    let rough = u["misfit_roughness"].as_f64().unwrap();
    assert!(
        (0.6..1.6).contains(&rough) && u["per_line_misfit"] == false,
        "{rough}"
    );
    let (l_lo, l_hi) = (
        u["lines_lower_gain_margin"].as_f64().unwrap(),
        u["lines_upper_gain_margin"].as_f64().unwrap(),
    );
    assert!(loop_stable(twin.plant(), twin.controller(), 1.0 + 0.9 * (l_hi - 1.0)).unwrap());
    assert!(loop_stable(twin.plant(), twin.controller(), 1.0 - 0.9 * (1.0 - l_lo)).unwrap());
    assert!(l_hi - 1.0 >= 0.5 * (t_hi - 1.0) && 1.0 - l_lo >= 0.5 * (1.0 - t_lo));

    let p = &sm["physical"]["parameters"];
    println!("{}", serde_json::to_string_pretty(p).unwrap());
    let lp = twin.linear_params();
    for (k, truth, tol) in [
        (0, lp.k_i, 0.02),
        (1, lp.k_x, 0.02),
        (2, TwinConfig::default().rotor.bending_freq_hz, 0.005),
    ] {
        let e = p[k]["estimate"].as_f64().unwrap();
        assert!(
            ((e - truth) / truth).abs() < tol,
            "{}: {e} vs {truth}",
            p[k]["name"]
        );
        assert_eq!(p[k]["twin"].as_f64().unwrap(), truth);
    }
}

#[test]
fn physical_with_files_needs_the_drawing_section() {
    // the seed record of the twin, written as files (the workflow then knows no drawing)
    let dir = crate::common::tmpdir("workflow-physical-files");
    let d = |f: &str| dir.join(f).to_str().unwrap().to_string();
    let o = crate::common::ambid(&["simulate", "--out", &d("sim")]);
    assert!(o.status.success(), "{}", crate::common::text(&o));
    let wf = "steps = [\"frf\", \"models\", \"physical\"]\nsource = \"files\"\n[data]\nidentification = \"sim/data.csv\"\ncontroller = \"sim/controller.toml\"\nperiod_samples = 5115\n";
    std::fs::write(dir.join("wf.toml"), wf).unwrap();
    let o = crate::common::ambid(&["run", &d("wf.toml"), "--out", &d("out"), "-q"]);
    let t = crate::common::text(&o);
    assert!(o.status.success(), "{t}");
    let read = |f: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(f)).unwrap()).unwrap()
    };
    assert!(read("out/summary.json").get("physical").is_none());
    let html = std::fs::read_to_string(dir.join("out/report.html")).unwrap();
    assert!(
        html.contains("no drawing: add a [physical] section"),
        "the skip reason is in the report"
    );
    // with the drawing (the nominal twin's) the step runs and meets the bars
    let cfg = TwinConfig::default();
    let r = &cfg.rotor;
    let drawing = format!(
        "[physical]\nmass_kg = {:?}\ninertia_kgm2 = {:?}\nbearing_a_m = {:?}\nbearing_b_m = {:?}\namplifier_bandwidth_hz = {:?}\nsensor_bandwidth_hz = {:?}\n",
        r.mass_kg, r.inertia(), r.bearing_a_m, r.bearing_b_m, cfg.amplifier.bandwidth_hz, cfg.sensor.bandwidth_hz
    );
    std::fs::write(dir.join("wf2.toml"), format!("{wf}{drawing}")).unwrap();
    let o = crate::common::ambid(&["run", &d("wf2.toml"), "--out", &d("out2"), "-q"]);
    assert!(o.status.success(), "{}", crate::common::text(&o));
    let p = read("out2/summary.json")["physical"]["parameters"].clone();
    let lp = Twin::new(cfg.clone()).unwrap().linear_params();
    for (k, truth, tol) in [
        (0, lp.k_i, 0.02),
        (1, lp.k_x, 0.02),
        (2, r.bending_freq_hz, 0.005),
    ] {
        let e = p[k]["estimate"].as_f64().unwrap();
        assert!(
            ((e - truth) / truth).abs() < tol,
            "{}: {e} vs {truth}",
            p[k]["name"]
        );
        assert!(p[k].get("twin").is_none(), "files: no twin values");
    }
}

/// The `physical` step after the `amplitude` step on the nominal (nonlinear) twin: the gray box
/// at every level of the amplitude study, extrapolated to zero amplitude. The estimate of the
/// identification record (10 %) has k_x above the twin's linearisation by more than three of
/// its standard deviations (the best linear approximation stiffens with the level); at zero
/// amplitude it is within 0.5 % and three standard deviations of it, k_i within 2 %, the
/// bending frequency within 0.5 %, and the report has the table.
#[test]
fn physical_after_the_amplitude_study_extrapolates_to_zero_amplitude() {
    let (all, _) = Step::with_prerequisites(&[Step::Amplitude, Step::Physical]);
    let cfg = WorkflowConfig {
        steps: Some(all),
        ..WorkflowConfig::default()
    };
    let out = run(&cfg, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
    let ph = &out.summary["physical"];
    let z = &ph["zero_amplitude"];
    println!("{}", serde_json::to_string_pretty(z).unwrap());
    assert!(z["levels_pct"].as_array().unwrap().len() >= 3, "{z}");
    let lp = Twin::new(TwinConfig::default()).unwrap().linear_params();
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    let (at, zr) = (&ph["parameters"][1], &z["parameters"][1]);
    assert_eq!(at["name"], "k_x");
    assert!(f(&at["estimate"]) - lp.k_x > 3.0 * f(&at["std"]), "{at}");
    let e = f(&zr["estimate"]) - lp.k_x;
    assert!(
        e.abs() < 5e-3 * lp.k_x && e.abs() < 3.0 * f(&zr["std"]),
        "{zr}"
    );
    assert!(f(&z["change_at_top_level"][1]) > 0.0);
    assert!((f(&z["parameters"][0]["estimate"]) / lp.k_i - 1.0).abs() < 0.02);
    let fb = TwinConfig::default().rotor.bending_freq_hz;
    assert!((f(&z["parameters"][2]["estimate"]) / fb - 1.0).abs() < 0.005);
    let html = section_blocks(&out, "physical");
    println!(
        "{}",
        &html[html.find("At zero amplitude").unwrap_or(0)..]
            .chars()
            .take(900)
            .collect::<String>()
    );
    assert!(html.contains("physical_zero_amplitude"));
}

/// The workflow with `uncertainty` and its prerequisites on random rig `rig` of the nonlinear
/// twin (noise seed `rig`), the rig written to `dir`: the rig's configuration and the outcome.
fn uncertainty_on_nonlinear_rig(dir: &Path, rig: u64) -> (TwinConfig, ambid::workflow::Outcome) {
    uncertainty_on_rig(dir, rig, "nonlinear", None)
}

/// [`uncertainty_on_nonlinear_rig`] on the twin of `mode`, with the excitation `kind` instead of
/// the default PRBS when given.
fn uncertainty_on_rig(
    dir: &Path,
    rig: u64,
    mode: &str,
    kind: Option<&str>,
) -> (TwinConfig, ambid::workflow::Outcome) {
    let twin_cfg = ambid_twin::random_rig(rig).unwrap();
    let path = dir.join(format!("rig{rig}.toml"));
    std::fs::write(&path, twin_cfg.to_toml_string().unwrap()).unwrap();
    let (all, _) = Step::with_prerequisites(&[Step::Uncertainty]);
    assert_eq!(all[0], Step::Amplitude);
    let mut cfg = WorkflowConfig {
        steps: Some(all),
        seed: rig,
        ..WorkflowConfig::default()
    };
    cfg.twin.mode = mode.into();
    cfg.twin.config = Some(path);
    if let Some(k) = kind {
        cfg.excitation.kind = k.into();
    }
    let out = run(&cfg, dir, &mut Progress::new(Verbosity::Quiet)).unwrap();
    (twin_cfg, out)
}

/// Random rig 53 of the nonlinear twin (noise seed 53), the one rig of 400 workflow runs where
/// the weight's upper gain margin was below half the true one (1.51 against the true 8.07):
/// the FRF's band ends at 1060 Hz and the mode-shaped fit had put a lightly damped pole pair
/// ($\zeta = 0.01$) at 2529 Hz, outside the lines, where no line constrains it ($|W| = 22$
/// there). Lightly damped factors now lie within the lines (`validate::weight`, "Outside the
/// lines"). Checked against the twin's exact plant (independent truth): both weight margins
/// keep the true loop stable 90 % of the way and are at least half the true ones.
#[test]
fn the_weight_does_not_peak_outside_the_measured_band() {
    let band_hi = weight_margins_hold_on_nonlinear_rig(53);
    // the step's band is the FRF's, well below the loop's high-frequency range on this rig
    assert!(band_hi < 1500.0, "band to {band_hi} Hz");
}

/// Random rig 336 of the nonlinear twin (noise seed 336), unseen while the rules were set and the
/// one rig of 1 200 workflow runs (rigs 1–100, 201–400; PRBS and noise; both twins) whose weight's
/// upper gain margin was below half the true one (2.017 against 2.034 needed): its models' band
/// reaches 1255 Hz while the amplitude study's ends at 1000 Hz, and term (e)'s line term held
/// the study's top line value (a false positive of the windows' test at its noisiest lines,
/// 0.11–0.135 of $|\hat P|$ against a true error of 0.002–0.009) over 1000–1255 Hz. Above the
/// study's lines only the projection through the model now carries the shift
/// (`amplitude_term_and_shifts`). Checked against the twin's exact plant as rig 53 is.
#[test]
fn term_e_is_not_held_above_the_amplitude_studys_band() {
    let band_hi = weight_margins_hold_on_nonlinear_rig(336);
    // the case this rig stands for: the models' band reaches beyond the study's 1000 Hz
    assert!(band_hi > 1000.0, "band to {band_hi} Hz");
}

/// A logarithmic chirp (`[excitation] kind = "chirp"`, 1–2000 Hz) falls by 3 dB per octave by
/// design, so the 10 dB band rule alone ended its FRF's band at 58.65 Hz: the models were fitted
/// on 4–59 Hz and, on random rig 501 of the linear twin, the `uncertainty` step reported an upper
/// gain margin of 59.1 where the true loop goes unstable at 2.88 (on 68 of random rigs 501–600 the
/// true loop was unstable at 90 % of the reported margin). The band rule now carries each edge
/// over a spectrum falling by less than 6 dB per octave (`ambid_core::frf::band`, "A spectrum that
/// slopes by design"): the step's band reaches past 1 kHz and both weight margins hold against
/// the twin's exact loop.
#[test]
fn a_logarithmic_chirp_is_measured_over_its_design_band() {
    let rig = 501;
    let dir = crate::common::tmpdir("workflow-uncertainty-chirp-501");
    let (twin_cfg, out) = uncertainty_on_rig(&dir, rig, "linear", Some("chirp"));
    let u = &out.summary["uncertainty"];
    let band_hi = u["band_hz"][1].as_f64().unwrap();
    assert!(band_hi > 1000.0, "band to {band_hi} Hz");
    println!("rig {rig}, chirp: band to {band_hi:.0} Hz");
    weight_margins_hold(twin_cfg, u, "rig 501, chirp: the weight");
}

/// The `uncertainty` step's weight margins and its coherent (reported) margins in the summary
/// `u` against the exact loop of the twin `twin_cfg`: the true loop stable 90 % of the way to
/// each, and each at least half the true one (`common::assert_margin_bars`, with `label`).
fn weight_margins_hold(twin_cfg: TwinConfig, u: &serde_json::Value, label: &str) {
    let twin = Twin::new(twin_cfg).unwrap();
    let weight = (
        u["lower_gain_margin"].as_f64(),
        u["upper_gain_margin"].as_f64(),
    );
    margins_hold(&twin, weight, label);
    coherent_margins_hold(&twin, u, label);
}

/// The `uncertainty` step's coherent margins (`coherent_gain_margins`, the reported ones) in
/// the summary `u` against the exact loop of `twin`: both bars, as [`weight_margins_hold`].
fn coherent_margins_hold(twin: &Twin, u: &serde_json::Value, label: &str) {
    let m = &u["coherent_gain_margins"];
    assert_eq!(u["coherent_draws"], 200, "{u}");
    println!(
        "{label}: {} of the coherent draws stable",
        u["coherent_stable_fraction"]
    );
    margins_hold(
        twin,
        (m[0].as_f64(), m[1].as_f64()),
        &format!("{label}, coherent"),
    );
}

/// Margins `(lower, upper)` against the exact loop of `twin`: both present, and both bars.
fn margins_hold(twin: &Twin, (lo, hi): (Option<f64>, Option<f64>), label: &str) {
    let (g_lo, g_hi) =
        ambid::uncertainty::nominal_gain_interval(twin.plant(), twin.controller()).unwrap();
    let (lo, hi) = (lo.expect(label), hi.expect(label));
    println!("{label}: margins {lo:.3} … {hi:.3}, true {g_lo:.3} … {g_hi:.3}");
    crate::common::assert_margin_bars(
        twin.plant(),
        twin.controller(),
        (lo, hi),
        (g_lo, g_hi),
        label,
    );
}

/// Random rig 605 of the nonlinear twin with a logarithmic chirp (noise seed 605), SS 8: the
/// relative bound has a notch of about 15 lines at the model's bending resonance (≈ 907 Hz),
/// where $|T|$ decides the upper margin, and the order-≤ 4 weight does not follow it (3–9 times
/// the bound there). Its upper margin was 1.406 against the true 2.343, short of half the raise
/// (the only miss of 2 200 workflow runs). The coherent draws carry the model's error as whole
/// curves and see the notch line by line: both their margins hold against the twin's exact
/// loop (docs/uncertainty.md, "Coherent margins on one axis").
#[test]
fn the_coherent_margins_hold_where_the_weight_misses_a_notch() {
    let rig = 605;
    let dir = crate::common::tmpdir("workflow-uncertainty-chirp-605");
    let (twin_cfg, out) = uncertainty_on_rig(&dir, rig, "nonlinear", Some("chirp"));
    let u = &out.summary["uncertainty"];
    println!(
        "rig {rig}, chirp: the weight's margins {} … {}",
        u["lower_gain_margin"], u["upper_gain_margin"]
    );
    coherent_margins_hold(&Twin::new(twin_cfg).unwrap(), u, "rig 605, chirp");
    // the report's table carries them
    let rows: Vec<&Vec<String>> = out
        .report
        .sections
        .iter()
        .flat_map(|s| &s.blocks)
        .filter_map(|b| match b {
            ambid::report::Block::Table(t) if t.id == "robust_stability" => Some(&t.rows),
            _ => None,
        })
        .flatten()
        .collect();
    assert!(
        rows.iter()
            .any(|r| r[0] == "robust gain margins, coherent (reported)"),
        "{rows:?}"
    );
}

/// Random rig 531 of the nonlinear twin with a multisine excitation (noise seed 531): the models
/// step chooses OE 7, and term (f) is its distance from the FRF's own inverse-variance
/// state-space fit of order 7. Started from the subspace step alone that fit ended in a poor
/// local optimum (10.4 % median error against the exact plant, the OE model's 0.51 %): term (f)
/// was 15.6 % of $|\hat P|$, the weight 33 times the true error and its upper gain margin 4.588
/// against the true 8.342, short of half. The fit now also starts from the nominal model's poles
/// and keeps the better (`validate::uncertainty::fit_distance`): term (f) is below 1 % and both
/// weight margins hold against the twin's exact loop (docs/uncertainty.md, "Term (f) from the
/// nominal's poles").
#[test]
fn term_f_starts_the_frfs_own_fit_from_the_nominals_poles() {
    let rig = 531;
    let dir = crate::common::tmpdir("workflow-uncertainty-multisine-531");
    let (twin_cfg, out) = uncertainty_on_rig(&dir, rig, "nonlinear", Some("multisine"));
    let u = &out.summary["uncertainty"];
    let d = u["fit_distance_median_rel"].as_f64().expect("term (f)");
    println!("rig {rig}, multisine: term (f) median {d:.2e} of |P̂|");
    assert!(d < 0.01, "term (f) median {d}");
    weight_margins_hold(twin_cfg, u, "rig 531, multisine: the weight");
}

/// The workflow's `uncertainty` step on random rig `rig` of the nonlinear twin (noise seed
/// `rig`), against the twin's exact plant: both weight margins keep the true loop stable 90 % of
/// the way and are at least half the true ones. Returns the top of the step's band \[Hz\].
fn weight_margins_hold_on_nonlinear_rig(rig: u64) -> f64 {
    let dir = crate::common::tmpdir(&format!("workflow-uncertainty-margins-{rig}"));
    let (twin_cfg, out) = uncertainty_on_nonlinear_rig(&dir, rig);
    let u = &out.summary["uncertainty"];
    let band_hi = u["band_hz"][1].as_f64().unwrap();
    println!("rig {rig}: band to {band_hi:.0} Hz, summary {u}");
    weight_margins_hold(twin_cfg, u, &format!("rig {rig}: the weight"));
    band_hi
}

/// `uncertainty` alone on random rigs 14 and 98 of the nonlinear twin (noise seeds 14 and 98):
/// naming it runs the amplitude study, whose levels saturated on at most 1 % of the samples and the
/// identification record's own FRF at its level give term (e), and the weight then covers the
/// chosen model's true relative error (against the twin's linearisation) on ≥ 95 % of the
/// 10–1000 Hz lines (and with steps listed without the study, the section warns that the bound
/// has no term (e)). Without the study the step covered 68 % and 85 % of them; with the study's
/// levels alone and term (e) over one window, 78 % and 85 % (these two rigs were looked at while
/// the rule was changed; the 100-rig sweep is in docs/uncertainty.md, "Term (e) in the
/// workflow").
#[test]
fn uncertainty_alone_bounds_the_nonlinear_twins_shift() {
    let dir = crate::common::tmpdir("workflow-uncertainty-nonlinear");
    let mut above = 0;
    for rig in [14u64, 98] {
        let (twin_cfg, out) = uncertainty_on_nonlinear_rig(&dir, rig);
        let u = &out.summary["uncertainty"];
        // the identification record's level is among term (e)'s levels
        let chosen = out.summary["amplitude"]["chosen_pct"].as_f64().unwrap();
        let levels: Vec<f64> = u["amplitude_levels_pct"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert!(
            levels.iter().any(|l| (l - chosen).abs() < 1e-9),
            "rig {rig}: {levels:?} without {chosen}"
        );
        // the study's levels in term (e) are exactly those saturated on at most 1 % of the
        // samples: the ones just above the identification level among them
        for row in out.summary["amplitude"]["levels"].as_array().unwrap() {
            let (l, sat) = (
                row["level_pct"].as_f64().unwrap(),
                row["saturated_pct"].as_f64().unwrap() / 100.0,
            );
            let used = levels.iter().filter(|x| (*x - l).abs() < 1e-9).count()
                > usize::from((l - chosen).abs() < 1e-9);
            assert_eq!(
                used,
                sat <= ambid::uncertainty::AMPLITUDE_MAX_SATURATED,
                "rig {rig}: level {l} % saturated on {sat:.2e} of the samples, levels {levels:?}"
            );
            above += usize::from(used && l > chosen);
        }
        // coverage of the true error on 10–1000 Hz, from the twin (independent truth)
        let sr = out.report.series("uncertainty", "|W|").unwrap();
        let truth = Twin::new(twin_cfg)
            .unwrap()
            .plant()
            .freq_response_siso(&sr.x)
            .unwrap();
        let nominal = out
            .models_stage
            .as_ref()
            .and_then(|m| m.chosen())
            .and_then(|c| c.model.clone())
            .unwrap()
            .freq_response_siso(&sr.x)
            .unwrap();
        let idx: Vec<usize> = (0..sr.x.len())
            .filter(|&k| (10.0..=1000.0).contains(&sr.x[k]))
            .collect();
        let covered = idx
            .iter()
            .filter(|&&k| sr.y[k] >= (truth[k] - nominal[k]).norm() / nominal[k].norm())
            .count();
        println!(
            "rig {rig}: |W| covers {covered} of {} lines, levels {levels:?}",
            idx.len()
        );
        assert!(
            covered as f64 >= 0.95 * idx.len() as f64,
            "rig {rig}: |W| covers {covered} of {} lines",
            idx.len()
        );
    }
    // on at least one of the two rigs a lightly saturated level above the identification
    // level entered (before 2026-12-04 none could)
    assert!(
        above > 0,
        "no level above the identification level entered term (e)"
    );
    // steps listed without the study (a workflow file's `steps` gets no prerequisites): no
    // term (e), and the section says what the bound then holds
    let cfg = WorkflowConfig {
        steps: Some(vec![Step::Frf, Step::Models, Step::Uncertainty]),
        ..WorkflowConfig::default()
    };
    let out = run(&cfg, &dir, &mut Progress::new(Verbosity::Quiet)).unwrap();
    assert!(out.summary["uncertainty"]
        .get("amplitude_levels_pct")
        .is_none());
    let blocks = section_blocks(&out, "uncertainty");
    assert!(blocks.contains("no amplitude study ran"), "{blocks}");
}

/// With the operating-point step, the uncertainty step adds term (d): its relative spread
/// matches the twin's exact linearised plants at the five operating points (independent truth:
/// each case's `Twin::plant`), and the robust margins stay conservative against the nominal
/// true loop.
#[test]
fn the_operating_point_study_enters_the_bound_as_term_d() {
    let (all, _) = Step::with_prerequisites(&[Step::OperatingPoint, Step::Uncertainty]);
    let cfg = WorkflowConfig {
        steps: Some(all),
        ..WorkflowConfig::default()
    };
    let out = run(&cfg, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
    let u = &out.summary["uncertainty"];
    println!("{}", serde_json::to_string_pretty(u).unwrap());
    let cases: Vec<&str> = u["operating_cases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    assert_eq!(cases, ["bias-20%", "bias+20%", "gap-10um", "gap+10um"]);
    // term (d) per line, from the report's figure
    let series = out
        .report
        .series("uncertainty", "(d)")
        .cloned()
        .expect("the (d) series");
    // the truth: the largest relative distance of the exact plants from the nominal one
    let nominal = TwinConfig::default();
    let plant_at = |bias: f64, gap: f64| {
        let mut c = nominal.clone();
        c.operating_point.bias_current_a = nominal.operating_point.bias_current_a * bias;
        c.operating_point.air_gap_m = nominal.operating_point.air_gap_m + gap;
        Twin::new(c)
            .unwrap()
            .plant()
            .freq_response_siso(&series.x)
            .unwrap()
    };
    let p0 = plant_at(1.0, 0.0);
    let others = [
        plant_at(0.8, 0.0),
        plant_at(1.2, 0.0),
        plant_at(1.0, -10e-6),
        plant_at(1.0, 10e-6),
    ];
    let mut ratios = Vec::new();
    for (k, f) in series.x.iter().enumerate() {
        if !(20.0..=1000.0).contains(f) {
            continue;
        }
        let truth = others
            .iter()
            .map(|p| (p[k] - p0[k]).norm() / p0[k].norm())
            .fold(0.0f64, f64::max);
        ratios.push(series.y[k] / truth);
    }
    ratios.sort_by(f64::total_cmp);
    let n = ratios.len();
    let (q10, q50, q90) = (ratios[n / 10], ratios[n / 2], ratios[9 * n / 10]);
    println!("term (d) / true spread over {n} lines: q10 {q10:.3} median {q50:.3} q90 {q90:.3}");
    assert!(n > 100 && (0.9..1.1).contains(&q50), "{q10} {q50} {q90}");
    assert!(q10 > 0.7 && q90 < 1.4, "{q10} {q50} {q90}");
    // the bound now holds the operating points too: still robustly stable here, and its margins
    // stay inside the nominal true loop's
    assert_eq!(u["robustly_stable"], true);
    let twin = Twin::new(nominal).unwrap();
    let g_hi = u["upper_gain_margin"].as_f64().unwrap();
    assert!(loop_stable(twin.plant(), twin.controller(), g_hi).unwrap());
}

/// The `physical` step after the operating-point study: the magnet law through the study's five
/// operating points. On the linear twin (rig 52, not used while writing the estimator) the
/// magnet constant and the effective air gap are within 0.5 % and four standard deviations of
/// the twin's, the law's χ² is not flagged, and the report has both tables. On the default
/// nonlinear twin at the study's 10 % the estimates are the best linear approximation's: the gap
/// is low by more than three standard deviations, and the report warns.
#[test]
fn physical_after_the_operating_point_study_fits_the_magnet_law() {
    let (all, _) = Step::with_prerequisites(&[Step::OperatingPoint, Step::Physical]);
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    let dir = crate::common::tmpdir("workflow-magnet-law");
    std::fs::write(
        dir.join("rig52.toml"),
        ambid_twin::random_rig(52)
            .unwrap()
            .to_toml_string()
            .unwrap(),
    )
    .unwrap();
    for (mode, rig) in [("linear", Some(52)), ("nonlinear", None)] {
        let mut cfg = WorkflowConfig {
            steps: Some(all.clone()),
            ..WorkflowConfig::default()
        };
        cfg.twin.mode = mode.into();
        cfg.twin.config = rig.map(|_| "rig52.toml".into());
        let out = run(&cfg, &dir, &mut Progress::new(Verbosity::Quiet)).unwrap();
        let op = &out.summary["physical"]["operating"];
        println!("{mode}: {}", serde_json::to_string_pretty(op).unwrap());
        let twin_cfg = rig.map_or_else(TwinConfig::default, |r| ambid_twin::random_rig(r).unwrap());
        let lp = Twin::new(twin_cfg).unwrap().linear_params();
        assert_eq!(op["cases"].as_array().unwrap().len(), 5);
        assert_eq!(op["dof"].as_u64().unwrap(), 8);
        let (k, g) = (&op["force_constant"], &op["air_gap_m"]);
        assert_eq!(f(&k["twin"]), lp.force_constant);
        assert_eq!(f(&g["twin"]), lp.air_gap_m);
        let html = section_blocks(&out, "physical");
        assert!(html.contains("magnet_law") && html.contains("operating_points_physical"));
        if mode == "linear" {
            for (row, truth) in [(k, lp.force_constant), (g, lp.air_gap_m)] {
                let e = f(&row["estimate"]) - truth;
                assert!(
                    e.abs() < 5e-3 * truth && e.abs() < 4.0 * f(&row["std"]),
                    "{row}"
                );
            }
            assert_eq!(f(&op["variance_scale"]), 1.0);
            let kx = f(&op["pooled_k_x"]["value"]);
            assert!((kx / lp.k_x - 1.0).abs() < 3e-3, "{kx} vs {}", lp.k_x);
        } else {
            assert!(lp.air_gap_m - f(&g["estimate"]) > 3.0 * f(&g["std"]), "{g}");
            assert!(html.contains("best linear approximation"));
        }
    }
}

/// The magnet law from recorded operating points: three linear-twin records of rig 61 (nominal,
/// bias −20 %, gap −10 µm; own noise seeds) as `[operating_point] files` with their set points,
/// the drawing as `[physical]`. k and g0 within 0.5 % of the twin's (no twin values in the
/// summary: files); without a file's set point the table is replaced by a note naming it.
#[test]
fn physical_with_recorded_operating_points_fits_the_magnet_law() {
    let dir = crate::common::tmpdir("workflow-magnet-files");
    let d = |f: &str| dir.join(f).to_str().unwrap().to_string();
    let cfg = ambid_twin::random_rig(61).unwrap();
    let (i0, g0) = (
        cfg.operating_point.bias_current_a,
        cfg.operating_point.air_gap_m,
    );
    for (name, extra, seed) in [
        ("nominal", vec![], "1"),
        (
            "bias",
            vec!["--bias".to_string(), format!("{}", 0.8 * i0)],
            "2",
        ),
        (
            "gap",
            vec!["--gap".to_string(), format!("{}", g0 - 10e-6)],
            "3",
        ),
    ] {
        let mut args = vec![
            "simulate",
            "--rig-seed",
            "61",
            "--mode",
            "linear",
            "--seed",
            seed,
        ];
        args.extend(extra.iter().map(String::as_str));
        let out = d(name);
        args.extend(["--out", out.as_str()]);
        let o = crate::common::ambid(&args);
        assert!(o.status.success(), "{}", crate::common::text(&o));
    }
    let r = &cfg.rotor;
    let drawing = format!(
        "[physical]\nmass_kg = {:?}\ninertia_kgm2 = {:?}\nbearing_a_m = {:?}\nbearing_b_m = {:?}\namplifier_bandwidth_hz = {:?}\nsensor_bandwidth_hz = {:?}\n",
        r.mass_kg, r.inertia(), r.bearing_a_m, r.bearing_b_m, cfg.amplifier.bandwidth_hz, cfg.sensor.bandwidth_hz
    );
    let wf = |gap_set_point: &str| {
        format!(
            "steps = [\"operating_point\", \"frf\", \"models\", \"physical\"]\nsource = \"files\"\n[data]\nidentification = \"nominal/data.csv\"\ncontroller = \"nominal/controller.toml\"\nperiod_samples = 5115\n[operating_point]\nfiles = [{{ name = \"nominal\", path = \"nominal/data.csv\", bias_current_a = {i0:?}, gap_offset_um = 0.0 }}, {{ name = \"bias-20%\", path = \"bias/data.csv\", bias_current_a = {:?}, gap_offset_um = 0.0 }}, {{ name = \"gap-10um\", path = \"gap/data.csv\", bias_current_a = {i0:?}{gap_set_point} }}]\n{drawing}",
            0.8 * i0
        )
    };
    std::fs::write(dir.join("wf.toml"), wf(", gap_offset_um = -10.0")).unwrap();
    let o = crate::common::ambid(&["run", &d("wf.toml"), "--out", &d("out"), "-q"]);
    assert!(o.status.success(), "{}", crate::common::text(&o));
    let read = |f: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(f)).unwrap()).unwrap()
    };
    let op = read("out/summary.json")["physical"]["operating"].clone();
    println!("{}", serde_json::to_string_pretty(&op).unwrap());
    let lp = Twin::new(cfg.clone()).unwrap().linear_params();
    for (key, truth) in [
        ("force_constant", lp.force_constant),
        ("air_gap_m", lp.air_gap_m),
    ] {
        let e = op[key]["estimate"].as_f64().unwrap();
        assert!((e / truth - 1.0).abs() < 5e-3, "{key}: {e} vs {truth}");
        assert!(op[key].get("twin").is_none(), "files: no twin values");
    }
    assert_eq!(op["dof"].as_u64().unwrap(), 4);
    // a file without its gap offset: a note naming it, no law
    std::fs::write(dir.join("wf2.toml"), wf("")).unwrap();
    let o = crate::common::ambid(&["run", &d("wf2.toml"), "--out", &d("out2"), "-q"]);
    assert!(o.status.success(), "{}", crate::common::text(&o));
    assert!(read("out2/summary.json")["physical"]
        .get("operating")
        .is_none());
    let html = std::fs::read_to_string(dir.join("out2/report.html")).unwrap();
    assert!(html.contains("`gap-10um` does not give bias_current_a and gap_offset_um"));
}

/// The workflow on a noise excitation (a Welch FRF, whose neighbouring lines correlate at about
/// 0.4 with Hann): the `uncertainty` step finds the correlation in the misfit, takes the
/// variances times its factor (Hann theory: $1 + 2 \cdot 0.44 = 1.89$), and says so in the
/// report and `summary.json`; the same workflow on the default PRBS (period averaging,
/// independent lines) has no factor and no note (docs/uncertainty.md, "Welch FRFs: correlated
/// lines"). The periodic FRF's variances are taken at the model, the Welch FRF's at the data.
#[test]
fn uncertainty_on_a_welch_frf_allows_for_its_correlated_lines() {
    for kind in ["noise", "prbs"] {
        let mut cfg = WorkflowConfig {
            steps: Some(vec![Step::Frf, Step::Models, Step::Uncertainty]),
            seed: 3,
            ..WorkflowConfig::default()
        };
        cfg.twin.mode = "linear".into();
        cfg.excitation.kind = kind.into();
        cfg.excitation.amplitude_pct = Some(5.0);
        let out = run(&cfg, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
        let u = &out.summary["uncertainty"];
        let blocks = section_blocks(&out, "uncertainty");
        // the variances at the model (sample maximum likelihood) on the periodic FRF only; a
        // Welch FRF's noise description is not independent of its value (docs/uncertainty.md,
        // "Sample maximum likelihood as the default")
        let at = if kind == "noise" { "data" } else { "model" };
        assert_eq!(u["variances_at"], at, "{u}");
        if kind == "noise" {
            let k = u["line_variance_factor"]
                .as_f64()
                .expect("a variance factor");
            assert!((1.5..2.3).contains(&k), "{k}");
            assert!(
                blocks.contains("neighbouring lines are correlated"),
                "{blocks}"
            );
        } else {
            assert!(u.get("line_variance_factor").is_none(), "{u}");
            assert!(
                !blocks.contains("neighbouring lines are correlated"),
                "{blocks}"
            );
        }
    }
}

/// The whole default workflow (the main job's steps) on a noise excitation, one of the four
/// kinds `[excitation] kind` offers. Its record has no periods, so the identification's FRF is
/// Welch's; the amplitude and operating-point studies run the same excitation and used to
/// average over periods regardless, which stopped the run at the amplitude study ("the record
/// holds 1 whole period(s) of 102300 samples"). They now choose their estimator by the FRF
/// step's rule (`FrfSettings::for_record`). Against the twin's exact plant: the amplitude
/// study's plant FRF gets closer to the truth as the level rises from 2 to 10 % of i_sat (more
/// signal over the same sensor noise), and at the identification level its median error is a
/// few per cent, as is the operating-point study's nominal case.
#[test]
fn the_whole_workflow_runs_on_a_noise_excitation() {
    let mut cfg = WorkflowConfig {
        seed: 5,
        ..WorkflowConfig::default()
    };
    cfg.twin.mode = "linear".into();
    cfg.excitation.kind = "noise".into();
    let out = run(&cfg, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
    let s = &out.summary;
    assert!(s["frf"]["lines"].as_f64().unwrap() > 100.0, "{}", s["frf"]);
    let levels = s["amplitude"]["levels"].as_array().unwrap();
    let err_at = |pct: f64| {
        levels
            .iter()
            .find(|l| (l["level_pct"].as_f64().unwrap() - pct).abs() < 1e-9)
            .and_then(|l| l["plant_median_rel_err_pct"].as_f64())
            .unwrap_or_else(|| panic!("no level {pct} %: {levels:?}"))
    };
    let (e2, e10) = (err_at(2.0), err_at(10.0));
    println!("noise excitation: amplitude study's plant error vs the truth {e2:.2} % at 2 %, {e10:.2} % at 10 %");
    assert!(e10 < 0.5 * e2, "{e2} -> {e10}");
    assert!(e10 < 3.0, "{e10}");
    let nominal = s["operating_point"]["nominal"]["error_vs_truth_pct"]
        .as_f64()
        .unwrap();
    assert!(nominal < 10.0, "{nominal}");
}

/// The `uncertainty` step on a noise excitation (a Welch FRF) on random rig 88 of the linear
/// twin (noise seed 88). The models step chooses an output-error polynomial model (OE 8, fitted
/// to the FRF by its own iteration), whose distance from the FRF's own inverse-variance
/// state-space fit of its order, in the upper band where the Welch FRF is too noisy for term
/// (b) to see it, is term (f) (docs/uncertainty.md, "A model not fitted to the FRF"; the test
/// ran on rig 42 until the models step refused pole–zero pairs that cancel within the data, and
/// rig 42 now chooses a state-space model, whose term (f) is 0). Term (f) is in the bound and
/// the weight covers the true error (against the twin's exact plant) on ≥ 95 % of the
/// 10–1000 Hz lines.
#[test]
fn term_f_bounds_an_output_error_model_on_a_welch_frf() {
    let dir = crate::common::tmpdir("workflow-uncertainty-term-f");
    let (_, out) = uncertainty_on_rig(&dir, 88, "linear", Some("noise"));
    let u = &out.summary["uncertainty"];
    let d = u["fit_distance_median_rel"].as_f64().expect("term (f)");
    let pick = |prefix: &str| out.report.series("uncertainty", prefix).cloned().unwrap();
    let (w, err) = (pick("|W|"), pick("twin: true"));
    let idx: Vec<usize> = (0..err.x.len())
        .filter(|&k| (10.0..=1000.0).contains(&err.x[k]))
        .collect();
    let cov = idx.iter().filter(|&&k| w.y[k] >= err.y[k]).count() as f64 / idx.len() as f64;
    println!(
        "rig 88, noise: term (f) median {:.4} of |P̂|, W covers {cov:.3}",
        d
    );
    assert!(d > 1e-4, "{d}");
    assert!(cov >= 0.95, "{cov}");
}

/// The models step on a noise excitation (a Welch FRF) on random rigs 255 and 279 of the
/// linear twin (noise seeds 255, 279), where the best validation fit, OE 9, held an undamped
/// pole–zero pair between two lines (1325 and 1647 Hz) that changed no line but swung the
/// loop's phase through −180°: its own loop went unstable at 3.03 and 2.49 times the
/// controller's gain, where the true loop does at 6.97 and 6.00, and no uncertainty bound
/// around it could report more (docs/uncertainty.md, "Pole–zero pairs that cancel within the
/// data"). A candidate with a pair the data do not support (`validate::compare::
/// cancelling_pairs`, by the BIC) is now not valid, with the pair in its note. Checked against
/// the twin's exact plant: the chosen model's own upper gain limit is within 10 % of the true
/// loop's.
#[test]
fn the_models_step_refuses_pole_zero_pairs_that_cancel_within_the_data() {
    let dir = crate::common::tmpdir("workflow-models-cancelling-pairs");
    let (steps, _) = Step::with_prerequisites(&[Step::Models]);
    for rig in [255u64, 279] {
        let twin_cfg = ambid_twin::random_rig(rig).unwrap();
        let path = dir.join(format!("rig{rig}.toml"));
        std::fs::write(&path, twin_cfg.to_toml_string().unwrap()).unwrap();
        let mut cfg = WorkflowConfig {
            steps: Some(steps.clone()),
            seed: rig,
            ..WorkflowConfig::default()
        };
        cfg.twin.mode = "linear".into();
        cfg.twin.config = Some(path);
        cfg.excitation.kind = "noise".into();
        let out = run(&cfg, &dir, &mut Progress::new(Verbosity::Quiet)).unwrap();
        let stage = out.models_stage.as_ref().expect("the models stage");
        let refused: Vec<String> = stage
            .candidates
            .iter()
            .filter(|c| {
                !c.valid
                    && c.note
                        .as_deref()
                        .is_some_and(|n| n.contains("cancel within the data"))
            })
            .map(|c| c.label())
            .collect();
        let chosen = stage.chosen().expect("a chosen model");
        let twin = Twin::new(twin_cfg).unwrap();
        let (_, g_true) =
            ambid::uncertainty::nominal_gain_interval(twin.plant(), twin.controller()).unwrap();
        let (_, g_model) = ambid::uncertainty::nominal_gain_interval(
            chosen.model.as_ref().expect("a model"),
            twin.controller(),
        )
        .unwrap();
        println!(
            "rig {rig}: refused {refused:?}; chosen {} with its own upper gain limit {g_model:.3} (true {g_true:.3})",
            chosen.label()
        );
        assert!(refused.contains(&"OE 9".to_string()), "{refused:?}");
        assert!(chosen.valid);
        assert!(
            (g_model / g_true - 1.0).abs() < 0.1,
            "{g_model} vs {g_true}"
        );
    }
}
