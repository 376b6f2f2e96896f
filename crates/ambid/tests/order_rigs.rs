//! The order step's reconciled recommendation (issue 18) against independent truth:
//! - on the nominal twin and 20 random rigs of the twin (the seed experiment, linear twin, an
//!   independent validation record), `order.recommended_lo … order.recommended_hi` contains
//!   the order of the model the models step chooses, and the order of the exact plant that
//!   matters in the band: the smallest state-space order whose fit to the *noise-free* exact
//!   plant FRF (`Twin::plant_frf` on the measured FRF's lines in the coherent band, relative
//!   weights) has a relative RMSE ≤ 1 % (an oracle that sees no data);
//! - on the MagnetoShield maglev record (the example workflow, the README's split) the
//!   recommendation is a small order (≤ 6, not "near 50") whose range contains the chosen
//!   model's order (SS 3).

use crate::common;
use crate::common::{ambid, s, text, tmpdir};
use ambid::workflow::{self, Progress, Verbosity, WorkflowConfig};
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::lti::Frd;
use ambid_core::lti::Structure;
use ambid_core::validate::compare::{compare_models, CompareSpec};
use ambid_twin::{random_rig, Twin, TwinConfig};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn simulate(dir: &Path, rig: Option<u64>, extra: &[&str]) {
    let mut args = vec!["simulate", "--mode", "linear", "--out", s(dir)];
    let r = rig.map(|r| r.to_string());
    if let Some(r) = &r {
        args.extend_from_slice(&["--rig-seed", r]);
    }
    args.extend_from_slice(extra);
    let o = ambid(&args);
    assert!(o.status.success(), "{}", text(&o));
}

fn num(sm: &Value, path: &str) -> f64 {
    let mut v = sm;
    for k in path.split('.') {
        v = &v[k];
    }
    v.as_f64()
        .unwrap_or_else(|| panic!("summary has no number at {path}"))
}

/// The oracle: the smallest state-space order (1 … 12) whose fit to the exact plant FRF on
/// `f` (relative weights, the truth's unstable-pole count) has a relative RMSE ≤ 1 %, and the
/// errors per order.
fn true_in_band_order(twin: &Twin, f: &[f64]) -> (usize, Vec<f64>) {
    let p = twin.plant_frf(f).unwrap();
    let var: Vec<f64> = p.iter().map(|g| (0.01 * g.norm()).powi(2)).collect();
    let frd = Frd::new(f.to_vec(), p, Some(var), Some(twin.plant().ts().unwrap())).unwrap();
    let spec = CompareSpec {
        structures: vec![Structure::Ss],
        orders: (1..=12).collect(),
        fit: FreqFitOptions {
            weights: FreqWeights::InverseVariance,
            ..FreqFitOptions::default()
        },
        unstable_poles: Some(twin.plant_unstable_poles().unwrap().len()),
        ..CompareSpec::default()
    };
    let rows = compare_models(&frd, &spec, None).unwrap();
    let errs: Vec<f64> = rows
        .iter()
        .map(|r| r.relative_rmse.filter(|_| r.valid).unwrap_or(f64::INFINITY))
        .collect();
    let n = errs
        .iter()
        .position(|e| *e <= 0.01)
        .map(|i| rows[i].order)
        .unwrap_or_else(|| panic!("no order fits the exact plant to 1 %: {errs:?}"));
    (n, errs)
}

fn check_rig(base: &Path, name: &str, rig: Option<u64>, cfg_twin: TwinConfig) {
    let (id, va) = (base.join(name), base.join(format!("{name}v")));
    let seed = (700 + rig.unwrap_or(0)).to_string();
    simulate(&id, rig, &["--seed", &seed]);
    simulate(&va, rig, &["--seed", "13", "--amplitude", "0.12"]);
    let wf = format!(
        "source = \"files\"\nsteps = [\"frf\", \"order\", \"models\"]\n\
         [data]\nidentification = \"{name}/data.csv\"\nvalidation = \"{name}v/data.csv\"\n\
         period_samples = 5115\nskip_periods = 1\ncontroller = \"{name}/controller.toml\"\n"
    );
    let cfg = WorkflowConfig::from_toml_str(&wf, Path::new("wf.toml")).unwrap();
    let out = workflow::run(&cfg, base, &mut Progress::new(Verbosity::Quiet))
        .unwrap_or_else(|e| panic!("{name}: workflow failed: {e}"));
    let sm = &out.summary;
    let (n, lo, hi) = (
        num(sm, "order.recommended") as usize,
        num(sm, "order.recommended_lo") as usize,
        num(sm, "order.recommended_hi") as usize,
    );
    let chosen = out
        .models
        .iter()
        .find(|m| m.meta["chosen"] == true)
        .unwrap_or_else(|| panic!("{name}: no chosen model"));
    let n_chosen = chosen.meta["order"]
        .as_u64()
        .unwrap_or_else(|| panic!("{name}: chosen model without order: {}", chosen.meta))
        as usize;
    // the coherent band's lines of the period-averaged FRF
    let twin = Twin::new(cfg_twin).unwrap();
    let fs = 1.0 / twin.plant().ts().unwrap();
    let (b0, b1) = (
        num(sm, "frf.quality_band_lo_hz"),
        num(sm, "frf.quality_band_hi_hz"),
    );
    let f: Vec<f64> = (1..5115 / 2)
        .map(|k| k as f64 * fs / 5115.0)
        .filter(|f| (b0..=b1).contains(f))
        .collect();
    let (n_true, errs) = true_in_band_order(&twin, &f);
    println!(
        "{name}: recommended {n} ({lo}–{hi}), chosen {} ({n_chosen} states), true in-band order \
         {n_true} (exact-FRF fit errors per order [%]: {:?}), resonances {}, ARX BIC na {}",
        chosen.name,
        errs.iter()
            .map(|e| (1000.0 * e).round() / 10.0)
            .collect::<Vec<_>>(),
        sm["order"]["resonances"],
        sm["order"]["arx_best_bic"]["na"],
    );
    assert!(lo <= n && n <= hi, "{name}: {n} outside {lo}–{hi}");
    assert!(
        (lo..=hi).contains(&n_chosen),
        "{name}: chosen {} outside the recommended {lo}–{hi}",
        chosen.name
    );
    assert!(
        (lo..=hi).contains(&n_true),
        "{name}: true in-band order {n_true} outside the recommended {lo}–{hi}"
    );
    // the report states it in one paragraph
    let html = out.report.to_html();
    assert!(
        html.contains(&format!("Recommended order {n} (range {lo}–{hi}) because")),
        "{name}: no recommendation paragraph"
    );
}

#[test]
fn the_order_range_holds_the_chosen_and_the_true_order_on_the_nominal_twin_and_20_rigs() {
    let base = tmpdir("order_rigs");
    check_rig(&base, "nominal", None, TwinConfig::default());
    for rig in 1..=20u64 {
        check_rig(
            &base,
            &format!("r{rig}"),
            Some(rig),
            random_rig(rig).unwrap(),
        );
    }
}

#[test]
fn the_maglev_recommendation_is_a_small_order_consistent_with_the_chosen_model() {
    let Some(_) = common::real_data("magnetoshield-maglev/MagnetoShield_ID_Data.mat") else {
        return;
    };
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let p = root.join("examples/workflows/maglev.toml");
    let cfg = WorkflowConfig::from_path(&p).unwrap();
    let out = workflow::run(
        &cfg,
        p.parent().unwrap(),
        &mut Progress::new(Verbosity::Quiet),
    )
    .unwrap();
    let sm = &out.summary;
    let (n, lo, hi) = (
        num(sm, "order.recommended") as usize,
        num(sm, "order.recommended_lo") as usize,
        num(sm, "order.recommended_hi") as usize,
    );
    let chosen = sm["models"]["chosen"].as_str().unwrap().to_string();
    println!("maglev: recommended {n} ({lo}–{hi}), chosen {chosen}");
    assert!(n <= 6 && hi <= 8, "maglev: recommended {n} ({lo}–{hi})");
    let n_chosen: usize = chosen.split(' ').nth(1).unwrap().parse().unwrap();
    assert!(
        (lo..=hi).contains(&n_chosen),
        "maglev: chosen {chosen} outside {lo}–{hi}"
    );
    assert_eq!(num(sm, "order.resonances"), 0.0);
    // the twin's exact oracle does not apply; the independent check is the README's ARX(3,3,1)
    // baseline: order 3 is within the range
    assert!((lo..=hi).contains(&3));
}
