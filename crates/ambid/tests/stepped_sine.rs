//! Stepped sine on the twin against the twin's exact linearised truth: noise-free accuracy and the
//! settling it needs, noisy errors against the predicted standard deviations, the nonlinear mode,
//! reproducibility, and the measurement time next to the seed's PRBS experiment.
//!
//! Budget: every test simulates fewer than 1e6 samples (the linear twin runs at ≳ 1e6 samples/s
//! in the test profile).

use ambid::experiment::log_grid;
use ambid::stepped_sine::{
    compare_with_truth, prbs_time_comparison, run_stepped_sine, SteppedSineOptions, TruthComparison,
};
use ambid_core::frf::stepped_sine::{NoiseEstimate, Settle, SteppedSinePlan};
use ambid_core::signal::PrbsSpec;
use ambid_twin::{Mode, Twin, TwinConfig};

/// 10 % of i_sat.
const AMPLITUDE_A: f64 = 0.2;

fn twin() -> Twin {
    Twin::new(TwinConfig::default()).unwrap()
}

fn max_rel(e: &TruthComparison) -> f64 {
    e.plant
        .max_rel()
        .max(e.t_ry.max_rel())
        .max(e.t_ru.max_rel())
}

#[test]
fn linear_noise_free_matches_the_truth_after_enough_settling() {
    let twin = twin();
    let f = log_grid(10.0, 2000.0, 12);
    let quiet = SteppedSineOptions {
        noise: false,
        ..Default::default()
    };
    // 0.3 s of settling: the integral poles (τ = 23.5 ms) have decayed by e^-12.8
    let plan = SteppedSinePlan::new(twin.fs(), &f, Settle::Seconds(0.3), 4, 0.05).unwrap();
    let out = run_stepped_sine(&twin, &plan, AMPLITUDE_A, &quiet).unwrap();
    let e = compare_with_truth(&out, &twin).unwrap();
    eprintln!(
        "settle 0.3 s: max rel error P {:.2e}, T_ry {:.2e}, S {:.2e}; {} samples = {:.3} s",
        e.plant.max_rel(),
        e.t_ry.max_rel(),
        e.t_ru.max_rel(),
        out.simulated_samples,
        out.experiment_time_s
    );
    assert!(e.plant.max_rel() <= 1e-6, "{:?}", e.plant.rel);
    assert!(e.t_ry.max_rel() <= 1e-6, "{:?}", e.t_ry.rel);
    assert!(e.t_ru.max_rel() <= 1e-6, "{:?}", e.t_ru.rel);
    assert_eq!(out.simulated_samples, plan.total_samples());
    assert!(out.saturated_fraction.iter().all(|s| *s == 0.0));
    // the snapped grid stays within 1/(2 N_min) of the requested one
    for p in plan.points() {
        assert!((p.f_hz / p.f_requested_hz - 1.0).abs() <= 1.0 / (2.0 * 1000.0));
    }
    // 0.1 s is not enough for 1e-6: what is left of the transient dominates
    let short = SteppedSinePlan::new(twin.fs(), &f, Settle::Seconds(0.1), 4, 0.05).unwrap();
    let e_short = compare_with_truth(
        &run_stepped_sine(&twin, &short, AMPLITUDE_A, &quiet).unwrap(),
        &twin,
    )
    .unwrap();
    eprintln!("settle 0.1 s: max rel error {:.2e}", max_rel(&e_short));
    assert!(max_rel(&e_short) > 1e-4);
}

/// Errors in units of the predicted std, pooled over three seeds (36 points per quantity).
fn pooled_normalized(
    twin: &Twin,
    plan: &SteppedSinePlan,
    noise_estimate: NoiseEstimate,
) -> [Vec<f64>; 3] {
    let mut z: [Vec<f64>; 3] = Default::default();
    for seed in [1u64, 2, 3] {
        let opts = SteppedSineOptions {
            seed,
            noise_estimate,
            ..Default::default()
        };
        let out = run_stepped_sine(twin, plan, AMPLITUDE_A, &opts).unwrap();
        let e = compare_with_truth(&out, twin).unwrap();
        z[0].extend(e.plant.normalized());
        z[1].extend(e.t_ry.normalized());
        z[2].extend(e.t_ru.normalized());
    }
    z
}

fn mean_sq(z: &[f64]) -> f64 {
    z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64
}

#[test]
fn linear_noisy_errors_are_consistent_with_the_predicted_std() {
    let twin = twin();
    let f = log_grid(10.0, 2000.0, 12);
    // 0.15 s of settling leaves ≤ 6.4e-5 relative of transient, below the noise (σ/|G| ≥ 1.8e-4)
    let plan = SteppedSinePlan::new(twin.fs(), &f, Settle::Seconds(0.15), 4, 0.1).unwrap();
    let z = pooled_normalized(&twin, &plan, NoiseEstimate::default());
    for (name, z) in ["P", "T_ry", "S"].iter().zip(&z) {
        let m = mean_sq(z);
        let worst = z.iter().fold(0.0f64, |a, b| a.max(*b));
        eprintln!(
            "{name}: mean |err|²/σ² = {m:.3}, max |err|/σ = {worst:.2} over {} points",
            z.len()
        );
        assert!((0.5..=2.0).contains(&m), "{name}: mean |err|²/σ² = {m}");
        assert!(worst < 4.0, "{name}: an error of {worst} σ");
    }
    // The white-noise variance ignores that the loop colours the noise: for S it is far too large
    // at low frequency (the residual's power is mostly at other frequencies).
    let zw = pooled_normalized(&twin, &plan, NoiseEstimate::White);
    let m_white = mean_sq(&zw[2]);
    eprintln!("S with the white-noise estimate: mean |err|²/σ² = {m_white:.3}");
    assert!(m_white < 0.5, "{m_white}");
}

#[test]
fn noisy_runs_are_reproducible_and_seeded_per_point() {
    let twin = twin();
    let plan =
        SteppedSinePlan::new(twin.fs(), &[40.0, 400.0], Settle::Seconds(0.05), 4, 0.05).unwrap();
    let opts = SteppedSineOptions {
        seed: 11,
        ..Default::default()
    };
    let a = run_stepped_sine(&twin, &plan, AMPLITUDE_A, &opts).unwrap();
    let b = run_stepped_sine(&twin, &plan, AMPLITUDE_A, &opts).unwrap();
    assert_eq!(a.points, b.points);
    assert_ne!(a.seeds[0], a.seeds[1]);
    let c = run_stepped_sine(
        &twin,
        &plan,
        AMPLITUDE_A,
        &SteppedSineOptions { seed: 12, ..opts },
    )
    .unwrap();
    assert_ne!(a.points[0].y, c.points[0].y);
}

#[test]
fn nonlinear_mode_runs_and_deviates_at_second_order_in_amplitude() {
    let twin = twin();
    let f = log_grid(20.0, 1000.0, 4);
    let plan = SteppedSinePlan::new(twin.fs(), &f, Settle::Seconds(0.15), 4, 0.05).unwrap();
    let opts = SteppedSineOptions {
        mode: Mode::Nonlinear,
        noise: false,
        ..Default::default()
    };
    let dev = |a: f64| {
        let out = run_stepped_sine(&twin, &plan, a, &opts).unwrap();
        assert!(out.saturated_fraction.iter().all(|s| *s == 0.0));
        max_rel(&compare_with_truth(&out, &twin).unwrap())
    };
    let (d1, d2) = (dev(AMPLITUDE_A), dev(2.0 * AMPLITUDE_A));
    eprintln!("nonlinear vs linear truth: {d1:.2e} at 0.2 A, {d2:.2e} at 0.4 A");
    // the force law's curvature: small, well above the linear-mode transient (≤ 6.4e-5), and ~A²
    assert!(d1 < 5e-3 && d1 > 2e-4, "{d1}");
    assert!(d2 / d1 > 3.0 && d2 / d1 < 5.0, "{d1} {d2}");
}

#[test]
fn stepped_sine_takes_much_longer_than_the_seed_prbs() {
    // seed PRBS: n = 10, 5 samples/bit, 20 periods at 20 kHz; lines every 3.91 Hz
    let prbs = PrbsSpec::default();
    let noisy =
        prbs_time_comparison(20e3, &prbs, (10.0, 1000.0), Settle::Seconds(0.15), 4, 0.05).unwrap();
    let exact =
        prbs_time_comparison(20e3, &prbs, (10.0, 1000.0), Settle::Seconds(0.3), 4, 0.05).unwrap();
    for c in [&noisy, &exact] {
        eprintln!(
            "PRBS {:.3} s ({} samples, {:.3} Hz lines); stepped sine on its {} lines in 10–1000 Hz: \
             {:.2} s ({:.1}x; settling {:.2} s), {:.2} s at the PRBS's noise level",
            c.prbs_time_s,
            c.prbs_samples,
            c.resolution_hz,
            c.plan.len(),
            c.stepped_time_s,
            c.time_ratio,
            c.plan.settle_samples() as f64 / 20e3,
            c.equal_noise_time_s
        );
        assert_eq!(c.prbs_samples, 102_300);
        assert!((c.prbs_time_s - 5.115).abs() < 1e-12);
        assert_eq!(c.plan.len(), 253);
        assert!(c.time_ratio > 8.0);
    }
    // one window at equal peak amplitude reaches the PRBS's noise in ~ T_PRBS/256 per line
    assert!(noisy
        .equal_noise_measure_s
        .iter()
        .all(|t| (0.01..0.03).contains(t)));
    assert!((exact.stepped_time_s - noisy.stepped_time_s - 253.0 * 0.15).abs() < 1e-6);
    // too short windows would snap lines by more than half the spacing
    assert!(
        prbs_time_comparison(20e3, &prbs, (10.0, 1000.0), Settle::Seconds(0.1), 1, 0.0).is_err()
    );
}

/// The seed's comparison of its two routes on the same rig (linear twin, 0.1 µm noise, 10 % of
/// i_sat): at a dozen of the PRBS's own lines the stepped sine is more accurate per line (all the
/// power in one line for ≥ 0.1 s), but covering the PRBS's 253 lines in 10–1000 Hz that way takes
/// ten times longer.
#[test]
fn stepped_sine_vs_prbs_on_the_same_lines() {
    use ambid::analysis::{analyze, FrfSettings, Record};
    use ambid::experiment::{run, ExcitationPlan, Experiment};
    let mut cfg = TwinConfig::default();
    cfg.sensor.noise_rms_m = 1e-7;
    let out = run(&Experiment {
        twin: cfg.clone(),
        excitation: ExcitationPlan::default(),
        mode: Mode::Linear,
        seed: 5,
        noise: true,
        record_b: false,
    })
    .unwrap();
    let rec = &out.record;
    let a = analyze(
        &Record {
            r: &rec.r,
            u: &rec.u,
            y: &rec.y,
            i: None,
            fs: 20e3,
        },
        &FrfSettings::periodic(5115, 1),
        None,
    )
    .unwrap();
    let f_prbs = a.frf.f_hz().to_vec();
    // twelve of the PRBS lines, log-spaced
    let picks: Vec<usize> = log_grid(12.0, 950.0, 12)
        .iter()
        .map(|f| {
            (0..f_prbs.len())
                .min_by(|&i, &j| (f_prbs[i] - f).abs().total_cmp(&(f_prbs[j] - f).abs()))
                .unwrap()
        })
        .collect();
    let freqs: Vec<f64> = picks.iter().map(|&k| f_prbs[k]).collect();
    let twin = Twin::new(cfg).unwrap();
    let truth = twin.plant_frf(&freqs).unwrap();
    let prbs_err: Vec<f64> = picks
        .iter()
        .zip(&truth)
        .map(|(&k, t)| (a.frf.plant.values()[k] - t).norm() / t.norm())
        .collect();
    let plan = SteppedSinePlan::new(20e3, &freqs, Settle::Seconds(0.15), 4, 0.1).unwrap();
    let outcome = run_stepped_sine(
        &twin,
        &plan,
        AMPLITUDE_A,
        &SteppedSineOptions {
            seed: 5,
            ..SteppedSineOptions::default()
        },
    )
    .unwrap();
    let sine_err = compare_with_truth(&outcome, &twin).unwrap().plant.rel;
    let med = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(|a, b| a.total_cmp(b));
        0.5 * (s[5] + s[6])
    };
    let per_line_sine = outcome.experiment_time_s / freqs.len() as f64;
    eprintln!(
        "plant at 12 PRBS lines: stepped sine median error {:.3} % ({:.3} s per line, {:.1} s for \
         253 lines) vs PRBS period averaging {:.3} % (5.115 s for all 2 555 lines)",
        100.0 * med(&sine_err),
        per_line_sine,
        253.0 * per_line_sine,
        100.0 * med(&prbs_err)
    );
    assert!(
        med(&sine_err) < med(&prbs_err),
        "{sine_err:?} vs {prbs_err:?}"
    );
    assert!(253.0 * per_line_sine > 10.0 * 5.115);
}
