//! Calibration of the residual tests (`validate::residuals`): for the true model on simulated
//! data the rate of lags outside the 95 % bounds is 5 % ± 1.5 % over 200 seeds, with a white
//! input and — thanks to the coloured-input correction — with a coloured input and coloured
//! (output-error) residuals; a wrong model fails.

use ambid_core::error::Error;
use ambid_core::validate::residuals::analyze;
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

const N: usize = 2000;
const M: usize = 25;
const SEEDS: u64 = 200;

#[test]
fn white_input_and_white_residuals_give_five_percent() {
    let (mut auto_out, mut cross_out, mut auto_n, mut cross_n) = (0, 0, 0, 0);
    let (mut white_pass, mut indep_pass) = (0, 0);
    for seed in 0..SEEDS {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // the true ARX model's residuals are its white innovations, independent of u
        let u = gauss(N, &mut rng);
        let e = gauss(N, &mut rng);
        let t = analyze(&e, Some(&u), M).unwrap();
        auto_out += t.whiteness.exceeding.len();
        auto_n += t.whiteness.lags.len();
        let c = t.independence.unwrap();
        cross_out += c.exceeding.len();
        cross_n += c.lags.len();
        white_pass += usize::from(t.whiteness.pass);
        indep_pass += usize::from(c.pass);
    }
    let (ra, rc) = (
        auto_out as f64 / auto_n as f64,
        cross_out as f64 / cross_n as f64,
    );
    eprintln!(
        "white input: out-of-bound rate autocorrelation {:.2} %, cross-correlation {:.2} %; portmanteau passes {white_pass} / {indep_pass} of {SEEDS}",
        100.0 * ra,
        100.0 * rc
    );
    assert!((0.035..=0.065).contains(&ra), "{ra}");
    assert!((0.035..=0.065).contains(&rc), "{rc}");
    // the χ² verdicts reject about 5 % of true models
    for p in [white_pass, indep_pass] {
        assert!((180..=198).contains(&p), "{p}");
    }
}

#[test]
fn coloured_input_with_coloured_residuals_needs_the_correction() {
    let (mut out, mut naive_out, mut total) = (0, 0, 0);
    for seed in 0..SEEDS {
        let mut rng = ChaCha8Rng::seed_from_u64(1000 + seed);
        // an output-error model's residuals are the coloured noise v = e/(1 − 0.9 q^-1), and the
        // input is coloured too; both independent
        let u = ar1(&gauss(N, &mut rng), 0.9);
        let v = ar1(&gauss(N, &mut rng), 0.9);
        let c = analyze(&v, Some(&u), M).unwrap().independence.unwrap();
        out += c.exceeding.len();
        total += c.lags.len();
        // the uncorrected bound 1.96/√N
        let naive = 1.959964 / (N as f64).sqrt();
        naive_out += c.values.iter().filter(|x| x.abs() > naive).count();
    }
    let (r, rn) = (out as f64 / total as f64, naive_out as f64 / total as f64);
    eprintln!(
        "coloured input and residuals: out-of-bound rate with the correction {:.2} %, with the white-case bound {:.2} %",
        100.0 * r,
        100.0 * rn
    );
    assert!((0.035..=0.065).contains(&r), "{r}");
    assert!(rn > 0.3, "{rn}");
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
    assert!(!t.whiteness.pass);
    let c = t.independence.unwrap();
    assert!(!c.pass && c.exceeding.contains(&1), "{:?}", c.exceeding);
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
