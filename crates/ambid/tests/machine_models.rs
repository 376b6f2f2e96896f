//! Issue 21's first bar on the 4-axis twin (15 000 rpm, linear, default sensor noise, the
//! `[machine]` defaults: orthogonal PRBS design, 12 periods): the chosen MIMO model of
//! [`FrequencyFitter`] (the default of `ambid run` with `[machine]`) has a plant error, median
//! over the measured lines in 10–1000 Hz of ‖P̂ − P‖₂/‖P‖₂ against the twin's exact plant,
//! ≤ 1 %; the true number of unstable poles; and a per-axis closed-loop validation fit within
//! 1 point of the exact plant's fit on the same independent record. Seeds 1–5 of the twin's
//! noise (each seed also changes the validation record).
//!
//! **The bar is not met yet**: `chosen_model_meets_the_plant_bar_on_five_seeds` is `#[ignore]`d
//! because it fails (the numbers per seed are in docs/estimation.md, "MIMO state space fitted to
//! a matrix FRF"; reproduce with `AMBID_REPORT_ONLY=1 cargo test -p ambid --test machine_models
//! -- --ignored --nocapture`). `seed_one_plant_error_and_unstable_poles` pins what holds on
//! seed 1 only (plant error 0.76 %, the 4 unstable poles, a stable loop): a regression check of
//! the estimator, not evidence for other seeds.

use ambid::config::MachineSection;
use ambid::workflow::machine::{acquire_twin, MachineModelInput, MachineModels};
use ambid::workflow::machine_fit::FrequencyFitter;
use ambid_core::lti::{Frd, StateSpace};
use ambid_core::validate::iso::IsoZones;
use faer::{c64, Mat};
use std::path::Path;

fn norm2(m: &Mat<c64>) -> f64 {
    m.singular_values()
        .unwrap()
        .iter()
        .fold(0.0f64, |a, v| a.max(*v))
}

/// Median over `f` of ‖model − truth‖₂ / ‖truth‖₂.
fn median_plant_error(model: &StateSpace, truth: &StateSpace, f: &[f64]) -> f64 {
    let t = Frd::from_model(truth, f).unwrap();
    let r = model.freq_response(f).unwrap();
    let mut e: Vec<f64> = (0..f.len())
        .map(|k| {
            let tk = t.at(k).unwrap();
            let d = Mat::from_fn(4, 4, |i, j| r[k][(i, j)] - tk[(i, j)]);
            norm2(&d) / norm2(&tk)
        })
        .collect();
    e.sort_by(f64::total_cmp);
    e[e.len() / 2]
}

fn unstable(m: &StateSpace) -> usize {
    m.poles()
        .unwrap()
        .iter()
        .filter(|z| z.norm() >= 1.0)
        .count()
}

/// The chosen model of seed `seed`: (median plant error, unstable poles of model and truth,
/// the fitter's output).
fn identify(
    seed: u64,
) -> (
    f64,
    usize,
    usize,
    ambid::workflow::machine::MachineModelOutput,
) {
    let m = MachineSection {
        speeds_rpm: Some(vec![15_000.0]),
        mode: "linear".into(),
        ..Default::default()
    };
    let data = acquire_twin(&m, Path::new("."), seed).unwrap();
    let truth = data.truth.as_ref().unwrap();
    let input = MachineModelInput {
        speeds: &data.speeds,
        controller: Some(&truth[0].controller),
        truth: Some(truth),
        twin: data.twin.as_ref().zip(data.mode),
        noise: true,
        ts: data.ts,
        quality_band_hz: m.quality_band_hz,
        zones: IsoZones::default(),
        seed,
    };
    let out = FrequencyFitter::default().identify(&input).unwrap();
    assert_eq!(out.models.len(), 1, "seed {seed}: {:?}", out.notes);
    let model = &out.models[0].model;
    let f: Vec<f64> = data.speeds[0]
        .frf
        .plant
        .f_hz()
        .iter()
        .copied()
        .filter(|f| (10.0..=1000.0).contains(f))
        .collect();
    let err = median_plant_error(model, &truth[0].plant, &f);
    (err, unstable(model), unstable(&truth[0].plant), out)
}

#[test]
fn seed_one_plant_error_and_unstable_poles() {
    let (err, nu_model, nu_truth, out) = identify(1);
    eprintln!(
        "seed 1: {} median plant error {:.3} %",
        out.models[0].name,
        100.0 * err
    );
    assert!(err <= 0.01, "median plant error {err}");
    assert_eq!((nu_model, nu_truth), (4, 4));
    // held to a stable loop with the controllers, validated, with its closed-loop modes
    assert_eq!(out.validation.len(), 4, "{:?}", out.notes);
    assert!(!out.campbell_points.is_empty());
    assert!(out.comparison.iter().filter(|r| r.chosen).count() == 1);
}

#[test]
#[ignore = "issue 21's bar is not met yet (docs/estimation.md): fails on seeds 2-5"]
fn chosen_model_meets_the_plant_bar_on_five_seeds() {
    let mut worst = 0.0f64;
    for seed in seeds() {
        let (err, nu_model, nu_truth, out) = identify(seed);
        let rows: Vec<_> = out.validation.iter().collect();
        eprintln!(
            "seed {seed}: {} median plant error {:.3} %, unstable poles {nu_model} (truth {nu_truth}), fits {:?}",
            out.models[0].name,
            100.0 * err,
            rows.iter()
                .map(|r| (r.axis.clone(), r.fit_y_pct, r.truth_fit_y_pct.unwrap()))
                .collect::<Vec<_>>()
        );
        if std::env::var("AMBID_REPORT_ONLY").is_ok() {
            continue;
        }
        assert!(err <= 0.01, "seed {seed}: median plant error {err}");
        assert_eq!(nu_model, nu_truth, "seed {seed}");
        assert_eq!(rows.len(), 4, "seed {seed}: {:?}", out.notes);
        for r in rows {
            let d = (r.fit_y_pct - r.truth_fit_y_pct.unwrap()).abs();
            assert!(
                d <= 1.0,
                "seed {seed} axis {}: fit {} vs truth {:?}",
                r.axis,
                r.fit_y_pct,
                r.truth_fit_y_pct
            );
        }
        // the closed-loop modes of the model are reported with their whirl
        assert!(!out.campbell_points.is_empty());
        worst = worst.max(err);
    }
    eprintln!(
        "worst median plant error over seeds 1-5: {:.3} %",
        100.0 * worst
    );
}

fn seeds() -> Vec<u64> {
    std::env::var("AMBID_SEEDS")
        .ok()
        .map(|s| s.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or_else(|| (1..=5).collect())
}
