//! Pole–zero pairs that cancel within the data (`validate::compare::pole_zero_pairs`,
//! `cancelling_pairs`): the likelihood-ratio statistic of removing a pair against a naive
//! recomputation from the transfer functions' coefficients, and the BIC rule's verdict on pairs
//! placed at random between the lines of a noisy FRF.

use ambid_core::c64;
use ambid_core::estimate::freqfit::{FreqData, FreqFitOptions, FreqWeights};
use ambid_core::lti::{Frd, TransferFunction};
use ambid_core::validate::compare::{cancelling_pairs, pole_zero_pairs};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

const TS: f64 = 1e-3;

fn conv(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut c = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            c[i + j] += x * y;
        }
    }
    c
}

/// $1 - 2r\cos\omega\,z^{-1} + r^2 z^{-2}$: roots $r e^{\pm j\omega}$, $\omega = 2\pi f T$.
fn pair(r: f64, f_hz: f64) -> Vec<f64> {
    let w = std::f64::consts::TAU * f_hz * TS;
    vec![1.0, -2.0 * r * w.cos(), r * r]
}

/// The naive response $\sum_k b_k z^{-k} / \sum_k a_k z^{-k}$ at $z = e^{j 2\pi f T}$.
fn naive(b: &[f64], a: &[f64], f_hz: f64) -> c64 {
    let zi = c64::from_polar(1.0, -std::f64::consts::TAU * f_hz * TS);
    let ev = |p: &[f64]| {
        p.iter()
            .enumerate()
            .fold(c64::new(0.0, 0.0), |acc, (k, &c)| {
                acc + c * zi.powi(k as i32)
            })
    };
    ev(b) / ev(a)
}

/// The state-space form of `b / a` at sample time `ts`.
fn ss(b: &[f64], a: &[f64], ts: f64) -> ambid_core::lti::StateSpace {
    TransferFunction::new(b.to_vec(), a.to_vec(), ts)
        .unwrap()
        .to_state_space()
        .unwrap()
}

/// `frd`'s lines with uniform weights.
fn uniform(frd: &Frd) -> FreqData {
    let opts = FreqFitOptions {
        weights: FreqWeights::Uniform,
        ..FreqFitOptions::default()
    };
    FreqData::new(frd, &opts).unwrap()
}

/// A random stable plant (a real pole, a resonance and an anti-resonance): its coefficients.
fn plant(rng: &mut ChaCha8Rng) -> (Vec<f64>, Vec<f64>) {
    let f_res: f64 = rng.random_range(40.0..150.0);
    let f_anti = f_res * rng.random_range(1.2..1.8);
    let num = conv(&[0.1], &pair(rng.random_range(0.95..0.99), f_anti));
    let den = conv(
        &[1.0, -rng.random_range(0.5..0.95)],
        &pair(rng.random_range(0.97..0.995), f_res),
    );
    (num, den)
}

/// The FRF of `b / a` on 250 lines 2 Hz apart with 1 % complex Gaussian noise.
fn measure(b: &[f64], a: &[f64], rng: &mut ChaCha8Rng) -> Frd {
    let f: Vec<f64> = (1..=250).map(|k| 2.0 * k as f64).collect();
    let g: Vec<c64> = f
        .iter()
        .map(|&fk| {
            let v = naive(b, a, fk);
            let (re, im): (f64, f64) = (StandardNormal.sample(rng), StandardNormal.sample(rng));
            v + v.norm() * 0.01 * c64::new(re, im) / std::f64::consts::SQRT_2
        })
        .collect();
    Frd::new(f, g, None, Some(TS)).unwrap()
}

/// A system with a pole pair between two lines and its zero pair at a random distance, measured
/// with noise, and the system itself as the model: the statistic of the pair equals
/// $2L \ln(V_r/V)$ computed from the coefficients (the plant's own for the model without the
/// pair, the product for the model with it), and the verdict is the BIC rule on it. Both
/// verdicts occur: the data show a pair whose zeros lie far enough from its poles and not one
/// that nearly cancels; the plant's own resonance is never taken for a cancellation.
#[test]
fn the_statistic_is_the_likelihood_ratio_and_the_verdict_the_bic() {
    let mut rng = ChaCha8Rng::seed_from_u64(23);
    let (mut cancelled, mut seen) = (0, 0);
    for case in 0..40 {
        let (num, den) = plant(&mut rng);
        // a pole pair between two lines (odd Hz), lightly damped, above the plant's resonance
        // and anti-resonance (≤ 270 Hz), and its zero pair offset by a random fraction of the
        // line spacing (log-uniform from 1e-4 to 3 lines)
        let f_p = 2.0 * rng.random_range(170..240) as f64 + 1.0;
        let r_p = 1.0 - 10f64.powf(rng.random_range(-6.0..-2.5));
        let off = 2.0 * 10f64.powf(rng.random_range(-4.0..0.5));
        let (b, a) = (
            conv(&num, &pair(r_p, f_p + off)),
            conv(&den, &pair(r_p, f_p)),
        );
        let frd = measure(&b, &a, &mut rng);
        let data = uniform(&frd);
        let model = ss(&b, &a, TS);
        let pairs = pole_zero_pairs(&model, &data).unwrap();
        let added = pairs
            .iter()
            .find(|p| (p.f_hz - f_p).abs() < 0.5 && p.pole.norm() > r_p - 1e-9)
            .unwrap_or_else(|| panic!("case {case}: the added pair at {f_p} Hz: {pairs:?}"));
        let want_zero = c64::from_polar(r_p, std::f64::consts::TAU * (f_p + off) * TS);
        assert!(
            (added.zero - want_zero).norm() < 1e-6,
            "case {case}: {added:?}"
        );
        // the oracle: both costs from the coefficients (uniform weights are 1)
        let cost = |b: &[f64], a: &[f64]| -> f64 {
            frd.f_hz()
                .iter()
                .zip(frd.values())
                .map(|(&fk, g)| (naive(b, a, fk) - g).norm_sqr())
                .sum()
        };
        let l2 = 2.0 * frd.len() as f64;
        let want = l2 * (cost(&num, &den) / cost(&b, &a)).ln();
        assert!(
            (added.statistic - want).abs() <= 1e-6 * want.abs().max(1.0),
            "case {case}: {} vs the oracle's {want}",
            added.statistic
        );
        assert_eq!(added.cancels(), want <= 4.0 * l2.ln(), "case {case}");
        if added.cancels() {
            cancelled += 1;
        } else {
            seen += 1;
        }
        // the plant's resonance with its nearest zero (the anti-resonance) is what the data show
        let flagged = cancelling_pairs(&model, &data).unwrap();
        assert!(
            flagged.iter().all(|p| (p.f_hz - f_p).abs() < 0.5),
            "case {case}: {flagged:?}"
        );
    }
    println!("added pairs: {cancelled} cancel within the data, {seen} are seen");
    assert!(cancelled >= 5 && seen >= 5, "{cancelled} / {seen}");
}

/// Without noise the model equals the lines, no scale can be estimated and nothing is
/// flagged; a model that is not SISO or at another sample time is an error.
#[test]
fn exact_data_and_bad_input() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (num, den) = plant(&mut rng);
    let frd = measure(&num, &den, &mut rng);
    let exact: Vec<c64> = frd.f_hz().iter().map(|&f| naive(&num, &den, f)).collect();
    let frd0 = Frd::new(frd.f_hz().to_vec(), exact, None, Some(TS)).unwrap();
    let data = uniform(&frd0);
    let plant = ss(&num, &den, TS);
    let pairs = pole_zero_pairs(&plant, &data).unwrap();
    assert!(
        pairs.iter().all(|p| !p.cancels()),
        "an exact fit has nothing to test: {pairs:?}"
    );
    let other_ts = ss(&num, &den, 2.0 * TS);
    let e = pole_zero_pairs(&other_ts, &data).unwrap_err();
    assert!(e.to_string().contains("sample time"), "{e}");
}
