//! Calibration of the residual tests (`validate::residuals`): for the true model on simulated
//! data each χ² verdict rejects 5 % of 500 seeds (within the binomial band 2.5–7.5 %, ±2.6
//! standard deviations), with white signals, with a coloured (AR(1)) input and coloured
//! output-error residuals, and with a held PRBS input (5 samples per bit) and residuals shaped
//! like a closed loop's S v; the naive white-case statistic rejects far more than 5 % there; a
//! wrong model fails.

use ambid_core::error::Error;
use ambid_core::validate::residuals::{analyze, analyze_output_error, chi2_95};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

fn gauss(n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    (0..n).map(|_| rng.sample(StandardNormal)).collect()
}

/// First-order filter x(t) = a x(t−1) + w(t).
fn ar1(w: &[f64], a: f64) -> Vec<f64> {
    let mut x = vec![0.0; w.len()];
    for t in 0..w.len() {
        x[t] = w[t] + if t > 0 { a * x[t - 1] } else { 0.0 };
    }
    x
}

/// A resonant second-order filter (poles at radius ρ, angle θ) applied to `w` and added to it,
/// like a closed loop's S v: v plus a lightly damped closed-loop mode.
fn resonant(w: &[f64], rho: f64, theta: f64, gain: f64) -> Vec<f64> {
    let (a1, a2) = (2.0 * rho * theta.cos(), -rho * rho);
    let mut x = vec![0.0; w.len()];
    for t in 0..w.len() {
        let p1 = if t > 0 { x[t - 1] } else { 0.0 };
        let p2 = if t > 1 { x[t - 2] } else { 0.0 };
        x[t] = w[t] + a1 * p1 + a2 * p2;
    }
    w.iter().zip(&x).map(|(a, b)| a + gain * b).collect()
}

/// A random binary sequence held for `hold` samples (a PRBS-like excitation).
fn held_binary(n: usize, hold: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut v = Vec::with_capacity(n);
    while v.len() < n {
        let b = if rng.random::<bool>() { 1.0 } else { -1.0 };
        for _ in 0..hold {
            v.push(b);
        }
    }
    v.truncate(n);
    v
}

const N: usize = 2000;
const M: usize = 25;
const SEEDS: u64 = 500;
/// Binomial band for a 5 % rejection rate over 500 seeds (σ = 0.97 %): 2.5–7.5 %.
const BAND: std::ops::RangeInclusive<f64> = 0.025..=0.075;

fn rate(rejected: usize) -> f64 {
    rejected as f64 / SEEDS as f64
}

#[test]
fn white_input_and_white_residuals_reject_five_percent() {
    let (mut auto_out, mut cross_out, mut auto_n, mut cross_n) = (0, 0, 0, 0);
    let (mut white_rej, mut indep_rej) = (0, 0);
    for seed in 0..SEEDS {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // the true ARX model's residuals are its white innovations, independent of u
        let u = gauss(N, &mut rng);
        let e = gauss(N, &mut rng);
        let t = analyze(&e, Some(&u), M).unwrap();
        let w = t.whiteness.unwrap();
        auto_out += w.exceeding.len();
        auto_n += w.lags.len();
        let c = t.independence.unwrap();
        assert_eq!(c.dof, 2 * M + 1);
        cross_out += c.exceeding.len();
        cross_n += c.lags.len();
        white_rej += usize::from(!w.pass);
        indep_rej += usize::from(!c.pass);
    }
    let (ra, rc) = (
        auto_out as f64 / auto_n as f64,
        cross_out as f64 / cross_n as f64,
    );
    eprintln!(
        "white: lags outside the bounds {:.2} % (auto), {:.2} % (cross); χ² rejections whiteness {:.1} %, independence {:.1} % of {SEEDS}",
        100.0 * ra,
        100.0 * rc,
        100.0 * rate(white_rej),
        100.0 * rate(indep_rej)
    );
    assert!((0.04..=0.06).contains(&ra), "{ra}");
    assert!((0.04..=0.06).contains(&rc), "{rc}");
    assert!(BAND.contains(&rate(white_rej)), "{white_rej}");
    assert!(BAND.contains(&rate(indep_rej)), "{indep_rej}");
}

#[test]
fn coloured_input_and_coloured_output_error_reject_five_percent() {
    let (mut rej, mut naive_rej, mut out, mut total) = (0, 0, 0, 0);
    for seed in 0..SEEDS {
        let mut rng = ChaCha8Rng::seed_from_u64(1000 + seed);
        // an output-error model's residuals are the coloured noise v = e/(1 − 0.9 q^-1), and the
        // input is coloured too; both independent
        let u = ar1(&gauss(N, &mut rng), 0.9);
        let v = ar1(&gauss(N, &mut rng), 0.9);
        let t = analyze_output_error(&v, &u, M).unwrap();
        assert!(t.whiteness.is_none());
        let c = t.independence.unwrap();
        rej += usize::from(!c.pass);
        out += c.exceeding.len();
        total += c.lags.len();
        // the naive white-case statistic N Σ x² against χ²(2M+1)
        let q: f64 = N as f64 * c.values.iter().map(|x| x * x).sum::<f64>();
        naive_rej += usize::from(q >= chi2_95(2 * M + 1));
    }
    let r = out as f64 / total as f64;
    eprintln!(
        "AR(1) input and residuals: χ² rejections {:.1} % (white-case statistic {:.1} %); lags outside the corrected bound {:.2} %",
        100.0 * rate(rej),
        100.0 * rate(naive_rej),
        100.0 * r
    );
    assert!(BAND.contains(&rate(rej)), "{rej}");
    assert!((0.035..=0.065).contains(&r), "{r}");
    assert!(rate(naive_rej) > 0.5, "{naive_rej}");
}

#[test]
fn held_prbs_and_closed_loop_shaped_residuals_reject_five_percent() {
    let mut rej = 0;
    let mut uncorrelated_lags_rej = 0;
    for seed in 0..SEEDS {
        let mut rng = ChaCha8Rng::seed_from_u64(5000 + seed);
        // a PRBS-like excitation (5 samples per bit) and S v with a lightly damped mode
        // (ρ = 0.97, 0.05 cycles per sample): strongly coloured, independent of r
        let r = held_binary(N, 5, &mut rng);
        let eps = resonant(&gauss(N, &mut rng), 0.97, 0.1 * std::f64::consts::PI, 0.5);
        let c = analyze_output_error(&eps, &r, M)
            .unwrap()
            .independence
            .unwrap();
        rej += usize::from(!c.pass);
        // the per-lag-corrected statistic that ignores the correlation between lags
        let ratio = (c.bound * (N as f64).sqrt() / 1.959964).powi(2);
        let q: f64 = N as f64 * c.values.iter().map(|x| x * x).sum::<f64>() / ratio;
        uncorrelated_lags_rej += usize::from(q >= chi2_95(2 * M + 1));
    }
    eprintln!(
        "held PRBS and resonant residuals: χ² rejections {:.1} % (statistic that treats lags as independent {:.1} %)",
        100.0 * rate(rej),
        100.0 * rate(uncorrelated_lags_rej)
    );
    assert!(BAND.contains(&rate(rej)), "{rej}");
}

#[test]
fn a_wrong_model_fails_and_bad_input_is_refused() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let u = gauss(N, &mut rng);
    // residuals of a model that missed a slow pole: coloured and correlated with past inputs
    let miss = ar1(&u, 0.8);
    let e: Vec<f64> = gauss(N, &mut rng)
        .iter()
        .enumerate()
        .map(|(t, w)| w + if t > 0 { 0.5 * miss[t - 1] } else { 0.0 })
        .collect();
    let t = analyze(&e, Some(&u), M).unwrap();
    assert!(!t.whiteness.unwrap().pass);
    let c = t.independence.unwrap();
    assert!(!c.pass && c.exceeding.contains(&1), "{:?}", c.exceeding);
    // an error on a strongly coloured output error (RMS ≈ 3) still fails: 0.3 r leaking through
    let r = held_binary(N, 5, &mut rng);
    let v = resonant(&gauss(N, &mut rng), 0.97, 0.1 * std::f64::consts::PI, 0.5);
    let leak: Vec<f64> = v.iter().zip(&r).map(|(a, b)| a + 0.3 * b).collect();
    let c = analyze_output_error(&leak, &r, M)
        .unwrap()
        .independence
        .unwrap();
    eprintln!(
        "leak: Q {} threshold {} dof {}",
        c.statistic, c.threshold, c.dof
    );
    assert!(!c.pass);
    // a single sine input (rank-2 Σ, the test is conservative there): the true model passes, a
    // model that lets 15 % of the sine through fails
    let s: Vec<f64> = (0..N).map(|k| (0.3 * k as f64).sin()).collect();
    let v = gauss(N, &mut rng);
    let c = analyze_output_error(&v, &s, M)
        .unwrap()
        .independence
        .unwrap();
    eprintln!(
        "sine: Q {} threshold {} dof {}",
        c.statistic, c.threshold, c.dof
    );
    assert!(c.pass, "{} {}", c.statistic, c.threshold);
    let leak: Vec<f64> = v.iter().zip(&s).map(|(a, b)| a + 0.15 * b).collect();
    let c = analyze_output_error(&leak, &s, M)
        .unwrap()
        .independence
        .unwrap();
    eprintln!(
        "sine leak: Q {} threshold {} dof {}",
        c.statistic, c.threshold, c.dof
    );
    assert!(!c.pass, "{} {}", c.statistic, c.threshold);
    // bad input
    assert!(matches!(
        analyze(&e[..50], None, M),
        Err(Error::InvalidArgument { .. })
    ));
    assert!(matches!(
        analyze(&e, Some(&u[..10]), M),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        analyze(&vec![1.0; N], None, M),
        Err(Error::InvalidArgument { .. })
    ));
    let mut bad = e.clone();
    bad[3] = f64::NAN;
    assert!(matches!(
        analyze(&bad, None, M),
        Err(Error::NonFinite { .. })
    ));
    assert!(matches!(
        analyze(&e, None, 0),
        Err(Error::InvalidArgument { .. })
    ));
}
