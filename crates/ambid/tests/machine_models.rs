//! Issue 21's first bar on the 4-axis twin (15 000 rpm, linear, default sensor noise, the
//! `[machine]` defaults: orthogonal PRBS design, 12 periods): the chosen MIMO model of
//! [`FrequencyFitter`] has a plant error, median over the measured lines in 10–1000 Hz of
//! ‖P̂ − P‖₂/‖P‖₂ against the twin's exact plant, ≤ 1 %; the true number of unstable poles; and
//! a per-axis closed-loop validation fit within 1 point of the exact plant's fit on the same
//! independent record. Seeds 1–5 of the twin's noise (each seed also changes the validation
//! record).
//!
//! `chosen_model_meets_the_plant_bar_on_five_seeds` checks all five (about 4 minutes in a
//! release build, longer in the test profile, so it is `#[ignore]`d by default; run it with
//! `cargo test --release -p ambid --test all machine_models:: -- --ignored --nocapture`, per-seed
//! numbers in docs/estimation.md). `seed_one_meets_the_whole_bar` runs by default on seed 1.
//! These are figures of the nominal twin only; `random_rigs_meet_the_plant_bar` checks the same
//! bar on random rigs.

use crate::common;
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

/// (median plant error over 10–1000 Hz, unstable poles of model and truth, the fitter's output).
type Identified = (
    f64,
    usize,
    usize,
    ambid::workflow::machine::MachineModelOutput,
);

/// The chosen model of seed `seed` on the nominal twin at 15 000 rpm: (median plant error,
/// unstable poles of model and truth, the fitter's output).
fn identify(seed: u64) -> Identified {
    identify_on(&nominal_section(), seed)
}

/// The nominal twin at 15 000 rpm, linear.
fn nominal_section() -> MachineSection {
    MachineSection {
        speeds_rpm: Some(vec![15_000.0]),
        mode: "linear".into(),
        ..Default::default()
    }
}

/// The twin's measurement of section `m` with seed `seed`, and the default fitter's output on it
/// (the twin's controllers and exact model given, as `ambid run` gives them).
fn fitted(
    m: &MachineSection,
    seed: u64,
) -> (
    ambid::workflow::machine::MachineData,
    ambid::workflow::machine::MachineModelOutput,
) {
    fitted_with(m, seed, true)
}

/// [`fitted`] with the scan stopping at the noise level (`stop`, the default) or fitting every
/// order.
fn fitted_with(
    m: &MachineSection,
    seed: u64,
    stop: bool,
) -> (
    ambid::workflow::machine::MachineData,
    ambid::workflow::machine::MachineModelOutput,
) {
    let data = acquire_twin(m, Path::new("."), seed).unwrap();
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
    let out = FrequencyFitter {
        stop_at_noise_level: stop,
        ..Default::default()
    }
    .identify(&input)
    .unwrap();
    (data, out)
}

/// As [`identify`], for the machine section `m` (one speed, linear).
fn identify_on(m: &MachineSection, seed: u64) -> Identified {
    let (data, out) = fitted(m, seed);
    assert_eq!(out.models.len(), 1, "seed {seed}: {:?}", out.notes);
    let (err, nu_model, nu_truth) = chosen_error(&data, &out);
    (err, nu_model, nu_truth, out)
}

/// The first chosen model's median plant error over the measured lines in 10–1000 Hz, and the
/// unstable poles of model and truth.
fn chosen_error(
    data: &ambid::workflow::machine::MachineData,
    out: &ambid::workflow::machine::MachineModelOutput,
) -> (f64, usize, usize) {
    let truth = &data.truth.as_ref().unwrap()[0];
    let model = &out.models[0].model;
    let f: Vec<f64> = data.speeds[0]
        .frf
        .plant
        .f_hz()
        .iter()
        .copied()
        .filter(|f| (10.0..=1000.0).contains(f))
        .collect();
    let err = median_plant_error(model, &truth.plant, &f);
    (err, unstable(model), unstable(&truth.plant))
}

#[test]
fn seed_one_meets_the_whole_bar() {
    let (err, nu_model, nu_truth, out) = identify(1);
    eprintln!(
        "seed 1: {} median plant error {:.3} %",
        out.models[0].name,
        100.0 * err
    );
    check_bar(1, err, nu_model, nu_truth, &out);
    assert!(out.comparison.iter().filter(|r| r.chosen).count() == 1);
    // order 16 is at the noise level on this record (2V/ν = 0.98): the scan stops there
    let orders: Vec<usize> = out.comparison.iter().map(|r| r.order).collect();
    assert_eq!(orders, vec![16], "{:?}", out.notes);
    assert!(
        out.notes
            .iter()
            .any(|n| n.contains("orders 20, 24 were not fitted")),
        "{:?}",
        out.notes
    );
}

/// The scan that stops at the first order at the noise level chooses what the full scan (every
/// order, lowest BIC) chooses, and every order it fitted to its end is the full scan's fit to
/// the bit. On nominal seeds 1–2, random rigs 1–3 and the nominal *nonlinear* twin (seed 1),
/// where no order reaches the noise level and the lowest order's fit is held to it, then
/// resumed against the others' BIC (docs/workflow.md; about 2 min in release).
#[test]
#[ignore = "heavy: full scans; run with --release -- --ignored"]
fn the_noise_level_stop_chooses_what_the_full_scan_chooses() {
    let mut cases: Vec<(String, MachineSection, u64)> = (1..=2)
        .map(|seed| (format!("seed {seed}"), nominal_section(), seed))
        .collect();
    cases.push((
        "nonlinear seed 1".into(),
        MachineSection {
            mode: "nonlinear".into(),
            ..nominal_section()
        },
        1,
    ));
    let dir = common::tmpdir("machine-models-scan");
    for rig in 1..=3 {
        // the random-rig test's record: rig seed = data seed
        cases.push((
            format!("rig {rig}"),
            common::random_machine_rig(&dir, rig),
            rig,
        ));
    }
    for (name, m, seed) in cases {
        let (early_data, early) = fitted_with(&m, seed, true);
        let (_, full) = fitted_with(&m, seed, false);
        let order_of = |o: &ambid::workflow::machine::MachineModelOutput| {
            o.comparison.iter().find(|r| r.chosen).map(|r| r.order)
        };
        let (e, f) = (order_of(&early), order_of(&full));
        let bic_of = |o: &ambid::workflow::machine::MachineModelOutput| {
            o.comparison.iter().find(|r| r.chosen).and_then(|r| r.bic)
        };
        let (err, _, _) = chosen_error(&early_data, &early);
        let rows = |o: &ambid::workflow::machine::MachineModelOutput| {
            o.comparison
                .iter()
                .map(|r| format!("{} BIC {:.0}", r.model, r.bic.unwrap_or(f64::NAN)))
                .collect::<Vec<_>>()
        };
        eprintln!(
            "{name}: early stop chose {e:?} ({} orders fitted, plant error {:.3} %), full scan {f:?}; early {:?}, full {:?}",
            early.comparison.len(),
            100.0 * err,
            rows(&early),
            rows(&full)
        );
        assert!(e.is_some(), "{name}: {:?}", early.notes);
        if e != f {
            // where the early stop ended below the full scan's choice, its model must still
            // meet the plant bar (BIC may prefer a higher order by less than the noise can tell)
            assert!(err <= 0.01, "{name}: {e:?} vs {f:?}, plant error {err}");
        }
        // every row fitted to its end is the full scan's fit of that order: the same BIC
        for r in early
            .comparison
            .iter()
            .filter(|r| !r.model.contains("abandoned"))
        {
            let twin = full.comparison.iter().find(|q| q.order == r.order).unwrap();
            assert_eq!(
                r.bic.map(f64::to_bits),
                twin.bic.map(f64::to_bits),
                "{name}: {}",
                r.model
            );
        }
        // an abandoned lowest order is never chosen and sits above the chosen BIC
        for r in early
            .comparison
            .iter()
            .filter(|r| r.model.contains("abandoned"))
        {
            assert!(!r.chosen, "{name}");
            assert!(r.bic > bic_of(&early), "{name}: {:?}", r.bic);
        }
        if name.starts_with("nonlinear") {
            // no order is at the noise level there: every order is fitted
            assert_eq!(early.comparison.len(), 3, "{name}: {:?}", early.notes);
        }
    }
}

/// The bar's checks on one seed's result.
fn check_bar(
    seed: u64,
    err: f64,
    nu_model: usize,
    nu_truth: usize,
    out: &ambid::workflow::machine::MachineModelOutput,
) {
    assert!(err <= 0.01, "seed {seed}: median plant error {err}");
    assert_eq!(nu_model, nu_truth, "seed {seed}");
    assert_eq!(out.validation.len(), 4, "seed {seed}: {:?}", out.notes);
    for r in &out.validation {
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
    assert!(!out.campbell_points.is_empty(), "seed {seed}");
}

#[test]
#[ignore = "about 4 minutes in release (longer in the test profile); seed 1 runs by default"]
fn chosen_model_meets_the_plant_bar_on_five_seeds() {
    let mut worst = 0.0f64;
    for seed in seeds() {
        let (err, nu_model, nu_truth, out) = identify(seed);
        eprintln!(
            "seed {seed}: {} median plant error {:.3} %, unstable poles {nu_model} (truth {nu_truth}), fits {:?}",
            out.models[0].name,
            100.0 * err,
            out.validation
                .iter()
                .map(|r| (r.axis.clone(), r.fit_y_pct, r.truth_fit_y_pct.unwrap()))
                .collect::<Vec<_>>()
        );
        check_bar(seed, err, nu_model, nu_truth, &out);
        worst = worst.max(err);
    }
    eprintln!(
        "worst median plant error over the seeds: {:.3} %",
        100.0 * worst
    );
}

fn seeds() -> Vec<u64> {
    std::env::var("AMBID_SEEDS")
        .ok()
        .map(|s| s.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or_else(|| (1..=5).collect())
}

/// The same defaults and the same bar on random rigs (`random_rig(seed)` lifted to four axes,
/// at `(7919·seed) mod 30 000` rpm): a chosen model with a median plant error ≤ 1 %, the true
/// unstable-pole count and a closed-loop validation fit within 1 point of the exact plant's on
/// every axis. Rigs 1–3 by default (those seen while the fitter's starts and orders were
/// chosen); `AMBID_RIGS=4,5,6` runs others (docs/estimation.md has both). About 2 minutes in
/// release: `cargo test --release -p ambid --test all machine_models::random_rigs -- --ignored --nocapture`.
#[test]
#[ignore = "about 2 minutes in release"]
fn random_rigs_meet_the_plant_bar() {
    let dir = common::tmpdir("machine-models");
    let rigs: Vec<u64> = std::env::var("AMBID_RIGS")
        .ok()
        .map(|s| s.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or_else(|| vec![1, 2, 3]);
    let mut failed = Vec::new();
    for seed in rigs {
        let speed = ((seed * 7919) % 30_000) as f64;
        let m = common::random_machine_rig(&dir, seed);
        let (data, out) = fitted(&m, seed);
        if out.models.is_empty() {
            eprintln!(
                "rig {seed} at {speed} rpm: no model chosen: {:?}",
                out.notes
            );
            for r in &out.comparison {
                eprintln!(
                    "    {}: {:.3} %, {} unstable",
                    r.model, r.median_norm_error_pct, r.unstable_poles
                );
            }
            failed.push(seed);
            continue;
        }
        let (err, nu_model, nu_truth) = chosen_error(&data, &out);
        let gap = out
            .validation
            .iter()
            .map(|r| (r.fit_y_pct - r.truth_fit_y_pct.unwrap()).abs())
            .fold(0.0f64, f64::max);
        eprintln!(
            "rig {seed} at {speed} rpm: {} median plant error {:.3} %, unstable poles {} (truth {}), largest validation gap {gap:.3} points",
            out.models[0].name,
            100.0 * err,
            nu_model,
            nu_truth,
        );
        if err > 0.01 || nu_model != nu_truth || out.validation.len() != 4 || gap > 1.0 {
            failed.push(seed);
        }
    }
    assert!(failed.is_empty(), "rigs outside the bar: {failed:?}");
}

/// Issue 21's Campbell bar: from the models identified at 5 speeds (0–30 000 rpm, nominal twin,
/// linear, default noise, seed 1), every closed-loop mode of the exact loop in 20–1000 Hz with
/// damping below the twin's `LIGHTLY_DAMPED` has an identified mode within 1 % in frequency, of
/// the same whirl where the speed splits the pair (a pair within 0.01 % of each other is a double
/// eigenvalue whose whirl label is arbitrary, in the exact model too; the split pairs here are
/// 0.98–4 % apart). About 4 minutes in release:
/// `cargo test --release -p ambid --test all machine_models::campbell -- --ignored --nocapture`.
#[test]
#[ignore = "about 4 minutes in release"]
fn campbell_from_identified_models_at_five_speeds() {
    let speeds = vec![0.0, 7_500.0, 15_000.0, 22_500.0, 30_000.0];
    let m = MachineSection {
        speeds_rpm: Some(speeds.clone()),
        mode: "linear".into(),
        ..Default::default()
    };
    let (data, out) = fitted(&m, 1);
    assert_eq!(out.models.len(), speeds.len(), "{:?}", out.notes);
    // the orders are scanned at the reference speed (the middle one); every other speed fits
    // its choice, and scans the rest only where that choice is not admissible (with a note)
    let reference = out
        .comparison
        .iter()
        .find(|r| r.chosen && r.speed_rpm == 15_000.0)
        .map(|r| r.order)
        .expect("a model at the reference speed");
    for &s in speeds.iter().filter(|&&s| s != 15_000.0) {
        let rows: Vec<usize> = out
            .comparison
            .iter()
            .filter(|r| r.speed_rpm == s)
            .map(|r| r.order)
            .collect();
        let fell_back = out
            .notes
            .iter()
            .any(|n| n.starts_with(&format!("{s} rpm: order {reference} (the reference")));
        assert!(
            rows == vec![reference] || (fell_back && rows.contains(&reference)),
            "{s} rpm: orders {rows:?}, reference order {reference}, notes {:?}",
            out.notes
        );
    }
    let cfg = data.twin.as_ref().unwrap();
    let mut worst = 0.0f64;
    for &s in &speeds {
        let machine = ambid_twin::Machine::new(ambid_twin::MachineConfig {
            speed_rpm: s,
            ..cfg.clone()
        })
        .unwrap();
        let exact: Vec<_> = machine
            .closed_loop_modes()
            .unwrap()
            .into_iter()
            .filter(|md| (20.0..=1000.0).contains(&md.freq_hz))
            .collect();
        assert!(!exact.is_empty(), "{s} rpm");
        let ident: Vec<_> = out
            .campbell_points
            .iter()
            .filter(|p| p.speed_rpm == s)
            .collect();
        for (k, md) in exact.iter().enumerate() {
            // a pair that the speed does not split (the cylindrical and bending modes here: the
            // gyroscopic moment acts on the tilt) is a double eigenvalue: any combination of its
            // two eigenvectors is one, so its forward/backward label is arbitrary in the exact
            // model as in the identified one, and only the frequency is compared
            let resolved = exact
                .iter()
                .enumerate()
                .all(|(j, o)| j == k || (o.freq_hz - md.freq_hz).abs() > 1e-4 * md.freq_hz);
            let best = ident
                .iter()
                .filter(|p| !resolved || p.whirl == md.whirl)
                .map(|p| (p.freq_hz - md.freq_hz).abs() / md.freq_hz)
                .fold(f64::INFINITY, f64::min);
            eprintln!(
                "{s} rpm: exact {:.2} Hz ({:?}{}, ζ {:.3}): nearest identified {}{:.3} %",
                md.freq_hz,
                md.whirl,
                if resolved { "" } else { ", unsplit pair" },
                md.damping,
                if resolved { "of the same whirl " } else { "" },
                100.0 * best
            );
            worst = worst.max(best);
        }
    }
    eprintln!("worst relative frequency error: {:.3} %", 100.0 * worst);
    assert!(worst <= 0.01, "worst {worst}");
}

/// Issue 23's MIMO entries on random 4-axis rigs 5 and 11 (linear, default noise, seed as rig,
/// the default fitter's chosen model): the element-wise bound of `uncertainty_matrix` on the
/// fit's band, raised by its joint factor (98 % of the pairs in 95 % of 2 000 draws), and the
/// robust-stability check of the four decentralised controllers against it on the lines. On
/// both rigs the bound's norm covers σ̄(P − P̂) on ≥ 95 % of the 10–1000 Hz lines (rig 11, at
/// 27 109 rpm, only since term (b) tests several window widths: 50.5 % with one) and the exact
/// loop stays stable at 90 % of both robust gain margins (the pole oracle); on rig 5 each margin
/// is at least half the exact one. On rig 11 the upper one is not (4.44 against the exact 8.48,
/// printed, not asserted; docs/uncertainty.md, "MIMO entries", gives the sweep of rigs 0–99).
/// The robust gain margins against 200 coherent draws of the model's error at 95 %
/// (`robust_stability_matrix_drawn`, with the entry weights outside the lines) meet both margin
/// bars on both rigs. On rig 11 the exact loop goes unstable above the lines (printed): without
/// the weights there the coherent upper margin was 9.84 against the exact 8.48
/// (docs/uncertainty.md, "Coherent draws for the machine").
#[test]
fn the_mimo_bound_and_its_robust_margins_on_random_rigs() {
    use ambid_core::validate::robust::{
        loop_stable, nominal_gain_interval, robust_stability_matrix_drawn,
        robust_stability_matrix_on_lines, LineBound, MatrixWeight,
    };
    use ambid_core::validate::uncertainty::{uncertainty_matrix, UncertaintyOptions};
    use ambid_core::validate::weight::Weight;
    let dir = common::tmpdir("machine-uncertainty");
    for (rig, half_bar) in [(5u64, true), (11, false)] {
        let m = common::random_machine_rig(&dir, rig);
        let (data, out) = fitted(&m, rig);
        let model = &out.models[0].model;
        let truth = &data.truth.as_ref().unwrap()[0];
        let measured = &data.speeds[0].frf.plant;
        let band = ambid::workflow::machine_fit::fit_band(measured, m.quality_band_hz)
            .unwrap()
            .unwrap();
        // the workflow's lines: the fit band and the validation lines above it
        let bound_band = ambid::workflow::machine_fit::uncertainty_band(measured, band).unwrap();
        assert!(bound_band.0 == band.0 && bound_band.1 >= band.1 && bound_band.1 <= 2.0 * band.1);
        let plant = measured.band(bound_band.0, bound_band.1).unwrap();
        let opts = UncertaintyOptions {
            fitted_band_hz: (bound_band.1 > band.1).then_some([band.0, band.1]),
            ..UncertaintyOptions::default()
        };
        let mut u = uncertainty_matrix(model, &plant, &[], &opts).unwrap();
        let raise = u.joint_raise(0.98, 0.95, 2000, 0).unwrap().max(1.0);
        // the workflow's entry weights (over the bound raised for 95 % of the pairs), the
        // coherent check's bound outside the lines
        let weights: Vec<Weight> = {
            use ambid_core::validate::uncertainty::EntryForm;
            use ambid_core::validate::weight::{WeightShape, DEFAULT_COVER, MAX_WEIGHT_ORDER};
            let wr = u
                .joint_raise(DEFAULT_COVER, 0.95, 2000, 0)
                .unwrap()
                .max(1.0);
            u.scaled(wr)
                .unwrap()
                .entry_weights_shaped(
                    model.ts().unwrap(),
                    MAX_WEIGHT_ORDER,
                    DEFAULT_COVER,
                    EntryForm::Relative,
                    WeightShape::ModeShaped,
                )
                .unwrap()
                .into_iter()
                .map(|w| w.weight)
                .collect()
        };
        assert!(raise < 2.0, "rig {rig}: raise {raise}");
        for e in &mut u.entries {
            for b in &mut e.additive {
                *b *= raise;
            }
        }
        let f = u.f_hz().to_vec();
        let exact = Frd::from_model(&truth.plant, &f).unwrap();
        let norm = u.norm_bound();
        let (mut lines, mut covered) = (0, 0);
        for (k, fk) in f.iter().enumerate() {
            if !(10.0..=1000.0).contains(fk) {
                continue;
            }
            let (p, ph) = (exact.at(k).unwrap(), u.nominal_at(k));
            let d = Mat::from_fn(4, 4, |i, j| p[(i, j)] - ph[(i, j)]);
            lines += 1;
            covered += usize::from(norm2(&d) <= norm[k]);
        }
        let cover = covered as f64 / lines as f64;
        let bounds = u.bounds();
        let r = robust_stability_matrix_on_lines(
            model,
            &truth.controller,
            &f,
            LineBound::Elementwise(&bounds),
        )
        .unwrap();
        let (lo, hi) = nominal_gain_interval(&truth.plant, &truth.controller).unwrap();
        let (rl, rh) = (r.lower_gain_margin.unwrap(), r.upper_gain_margin.unwrap());
        eprintln!(
            "rig {rig}: raise {raise:.2}, σ̄ covered on {:.1} % of {lines} lines, robust gain margins {rl:.3}…{rh:.3} (exact {lo:.3}…{hi:.3}), max μ {:.3}",
            100.0 * cover,
            r.mu_peak
        );
        assert!(r.robustly_stable, "rig {rig}");
        for g in [1.0 + 0.9 * (rh - 1.0), 1.0 - 0.9 * (1.0 - rl)] {
            assert!(
                loop_stable(&truth.plant, &truth.controller, g).unwrap(),
                "rig {rig} at {g}"
            );
        }
        assert!(1.0 - rl >= 0.5 * (1.0 - lo), "rig {rig}");
        if half_bar {
            assert!(rh - 1.0 >= 0.5 * (hi - 1.0), "rig {rig}");
        }
        assert!(cover >= 0.95, "rig {rig}: {cover}");
        // the coherent draws meet both margin bars on both rigs, rig 11 included
        let cd = u.coherent_draws(200, 0).unwrap();
        let rc = robust_stability_matrix_drawn(
            model,
            &truth.controller,
            &cd.f_hz,
            &cd.draws,
            &cd.remainder,
            Some(MatrixWeight::EntryRelative(&weights)),
            0.95,
        )
        .unwrap();
        let (cl, ch) = (rc.lower_gain_margin.unwrap(), rc.upper_gain_margin.unwrap());
        eprintln!(
            "rig {rig}: coherent margins {cl:.3}…{ch:.3} ({:.1} % of the draws stable; outside the lines {:?})",
            100.0 * rc.stable_fraction,
            rc.outside_gain_interval
        );
        // where the exact loop goes unstable above its upper margin (the band ends at f[last])
        let ts = model.ts().unwrap();
        let scaled = |c: &ambid_core::lti::StateSpace, g: f64| {
            ambid_core::lti::StateSpace::new(
                c.a().to_owned(),
                c.b().to_owned(),
                c.c().to_owned() * g,
                c.d().to_owned() * g,
                c.ts(),
            )
            .unwrap()
        };
        let crossing: Vec<f64> = truth
            .plant
            .feedback(&scaled(&truth.controller, hi * 1.001))
            .unwrap()
            .poles()
            .unwrap()
            .iter()
            .filter(|z| z.norm() >= 1.0 && z.im >= 0.0)
            .map(|z| z.im.atan2(z.re) / (2.0 * std::f64::consts::PI * ts))
            .collect();
        eprintln!(
            "rig {rig}: the exact loop at 1.001 × {hi:.3} is unstable at {crossing:?} Hz; lines {:.1}…{:.1} Hz",
            f[0],
            f[f.len() - 1]
        );
        // both bars on both rigs: on rig 11 the exact loop goes unstable above the lines,
        // where only the entry weights' test caps the margin (without it 9.84 against the
        // exact 8.48; docs/uncertainty.md, "Coherent draws for the machine")
        for g in [1.0 - 0.9 * (1.0 - cl), 1.0 + 0.9 * (ch - 1.0)] {
            assert!(
                loop_stable(&truth.plant, &truth.controller, g).unwrap(),
                "rig {rig} at {g}"
            );
        }
        assert!(1.0 - cl >= 0.5 * (1.0 - lo), "rig {rig}: {cl} {lo}");
        assert!(ch - 1.0 >= 0.5 * (hi - 1.0), "rig {rig}: {ch} {hi}");
        let [ol, oh] = rc.outside_gain_interval.unwrap();
        assert!(ol <= cl && oh >= ch, "rig {rig}: outside {ol}…{oh}");
    }
}
