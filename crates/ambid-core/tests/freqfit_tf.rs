//! Transfer-function fits to frequency data (`estimate::freqfit`): exact recovery on the FRF of
//! known discrete systems (lightly damped, unstable, with delay), the bias of Levy's ARX form
//! with noise, and typed errors.

use ambid_core::c64;
use ambid_core::error::Error;
use ambid_core::estimate::freqfit::{arx_frd, oe_frd, FreqFitOptions, FreqWeights, TfOrders};
use ambid_core::lti::{Frd, TransferFunction};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

const TS: f64 = 1e-3;

fn log_grid(n: usize, f0: f64, f1: f64) -> Vec<f64> {
    (0..n)
        .map(|k| f0 * (f1 / f0).powf(k as f64 / (n - 1) as f64))
        .collect()
}

fn frd_of(g: &TransferFunction, f: &[f64]) -> Frd {
    Frd::new(f.to_vec(), g.freq_response(f).unwrap(), None, Some(TS)).unwrap()
}

/// Denominator (ascending q^-1) with the given roots.
fn den_of(roots: &[c64]) -> Vec<f64> {
    ambid_core::linalg::poly_from_roots(roots)
}

fn pair(r: f64, w: f64) -> [c64; 2] {
    [c64::from_polar(r, w), c64::from_polar(r, -w)]
}

/// The largest relative error of the fitted response over a fine grid (not only the fitted lines).
fn response_error(fit: &TransferFunction, truth: &TransferFunction) -> f64 {
    let f = log_grid(400, 0.5, 499.0);
    let (a, b) = (
        fit.freq_response(&f).unwrap(),
        truth.freq_response(&f).unwrap(),
    );
    a.iter()
        .zip(&b)
        .map(|(x, y)| (x - y).norm() / y.norm())
        .fold(0.0, f64::max)
}

fn systems() -> Vec<(&'static str, TransferFunction, TfOrders)> {
    let (p1, p2) = (pair(0.995, 0.05), pair(0.97, 0.4));
    let lightly = TransferFunction::new(
        vec![0.0, 0.02, -0.01, 0.015],
        den_of(&[p1[0], p1[1], p2[0], p2[1]]),
        TS,
    )
    .unwrap();
    let p3 = pair(0.94, 0.3);
    let unstable = TransferFunction::new(
        vec![0.0, 0.1, 0.05],
        den_of(&[c64::new(1.02, 0.0), p3[0], p3[1]]),
        TS,
    )
    .unwrap();
    let delayed =
        TransferFunction::new(vec![0.0, 0.0, 0.0, 0.3, 0.2], vec![1.0, -0.6], TS).unwrap();
    vec![
        (
            "two lightly damped modes",
            lightly,
            TfOrders {
                nb: 3,
                nf: 4,
                nk: 1,
            },
        ),
        (
            "unstable pole at 1.02",
            unstable,
            TfOrders {
                nb: 2,
                nf: 3,
                nk: 1,
            },
        ),
        (
            "three-sample delay",
            delayed,
            TfOrders {
                nb: 2,
                nf: 1,
                nk: 3,
            },
        ),
    ]
}

#[test]
fn exact_data_are_recovered_by_arx_and_oe_at_the_true_order() {
    let f = log_grid(200, 1.0, 450.0);
    for (name, g, o) in systems() {
        let frd = frd_of(&g, &f);
        let opts = FreqFitOptions::default();
        let arx = arx_frd(&frd, &o, &opts).unwrap();
        let oe = oe_frd(&frd, &o, &opts).unwrap();
        let (ea, eo) = (
            response_error(&arx.model, &g),
            response_error(&oe.model, &g),
        );
        eprintln!(
            "{name}: ARX (Levy) {ea:.2e}, OE (SK + LM) {eo:.2e} ({} LM iterations)",
            oe.iterations
        );
        assert!(ea < 1e-8, "{name}: ARX {ea:e}");
        assert!(eo < 1e-8, "{name}: OE {eo:e}");
        // the same number of unstable poles as the truth: nothing is stabilised
        let unstable =
            |t: &TransferFunction| t.poles().unwrap().iter().filter(|p| p.norm() > 1.0).count();
        assert_eq!(unstable(&oe.model), unstable(&g), "{name}");
    }
}

/// With noisy FRF data Levy's form weights the error by |A|², which for a low-pass plant
/// emphasises high frequencies and biases the fit; OE (SK + LM) minimises the true error and has a
/// much smaller error at the lines where |A| is small (around the resonance).
#[test]
fn oe_beats_levy_arx_on_noisy_data_and_inverse_variance_weights_work() {
    let (_, g, o) = systems().remove(0);
    let f = log_grid(200, 1.0, 450.0);
    let truth = g.freq_response(&f).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    // 2 % relative complex noise, variance known
    let noisy: Vec<c64> = truth
        .iter()
        .map(|t| {
            let s = 0.02 * t.norm() / 2f64.sqrt();
            t + c64::new(
                s * rng.sample::<f64, _>(StandardNormal),
                s * rng.sample::<f64, _>(StandardNormal),
            )
        })
        .collect();
    let var: Vec<f64> = truth.iter().map(|t| (0.02 * t.norm()).powi(2)).collect();
    let frd = Frd::new(f.clone(), noisy, Some(var), Some(TS)).unwrap();
    let iv = FreqFitOptions {
        weights: FreqWeights::InverseVariance,
        ..FreqFitOptions::default()
    };
    let arx = arx_frd(&frd, &o, &iv).unwrap();
    let oe = oe_frd(&frd, &o, &iv).unwrap();
    let med = |m: &TransferFunction| {
        let v = m.freq_response(&f).unwrap();
        let mut r: Vec<f64> = v
            .iter()
            .zip(&truth)
            .map(|(a, b)| (a - b).norm() / b.norm())
            .collect();
        r.sort_by(f64::total_cmp);
        r[r.len() / 2]
    };
    let (ma, mo) = (med(&arx.model), med(&oe.model));
    eprintln!(
        "2 % noise, inverse-variance weights: median error vs truth ARX {:.3} %, OE {:.3} %",
        100.0 * ma,
        100.0 * mo
    );
    // OE with ML weights averages the noise: well below the 2 % per-line noise
    assert!(mo < 0.005, "{mo}");
    assert!(ma > mo, "{ma} vs {mo}");
    // honest weights: with w = 1/σ² the minimised cost Σ |e_k|²/σ_k² has expectation
    // L − n_θ/2 (each complex line carries two real equations of variance σ²/2); the fit reports
    // it with the weights normalised to mean 1, so multiply the mean of 1/σ² back
    let mean_inv_var = frd.variance().unwrap().iter().map(|v| 1.0 / v).sum::<f64>() / l_lines(&f);
    let chi2 = oe.cost * mean_inv_var;
    let expected = l_lines(&f) - o.n_params() as f64 / 2.0;
    eprintln!("normalised OE cost {chi2:.1}, expected {expected:.1}");
    assert!((chi2 / expected - 1.0).abs() < 0.2, "{chi2} vs {expected}");
}

fn l_lines(f: &[f64]) -> f64 {
    f.len() as f64
}

#[test]
fn bad_input_gives_typed_errors() {
    let (_, g, o) = systems().remove(1);
    let f = log_grid(50, 1.0, 450.0);
    let frd = frd_of(&g, &f);
    let opts = FreqFitOptions::default();
    // band with too few lines for the parameters
    let narrow = FreqFitOptions {
        band_hz: Some((10.0, 11.0)),
        ..opts.clone()
    };
    assert!(matches!(
        oe_frd(&frd, &o, &narrow),
        Err(Error::InvalidArgument { .. })
    ));
    // empty band
    let empty = FreqFitOptions {
        band_hz: Some((600.0, 700.0)),
        ..opts.clone()
    };
    assert!(matches!(
        arx_frd(&frd, &o, &empty),
        Err(Error::InvalidArgument { .. })
    ));
    // zero weights everywhere
    let zero = FreqFitOptions {
        weights: FreqWeights::Given(vec![0.0; f.len()]),
        ..opts.clone()
    };
    assert!(matches!(
        oe_frd(&frd, &o, &zero),
        Err(Error::InvalidArgument { .. })
    ));
    // wrong weight length, negative weight
    let short = FreqFitOptions {
        weights: FreqWeights::Given(vec![1.0; 3]),
        ..opts.clone()
    };
    assert!(matches!(
        oe_frd(&frd, &o, &short),
        Err(Error::InvalidArgument { .. })
    ));
    let mut w = vec![1.0; f.len()];
    w[4] = -1.0;
    let neg = FreqFitOptions {
        weights: FreqWeights::Given(w),
        ..opts.clone()
    };
    assert!(matches!(
        oe_frd(&frd, &o, &neg),
        Err(Error::InvalidArgument { .. })
    ));
    // inverse variance without variances
    let iv = FreqFitOptions {
        weights: FreqWeights::InverseVariance,
        ..opts.clone()
    };
    assert!(matches!(
        oe_frd(&frd, &o, &iv),
        Err(Error::InvalidArgument { .. })
    ));
    // a continuous FRF
    let cont = Frd::new(f.clone(), g.freq_response(&f).unwrap(), None, None).unwrap();
    assert!(matches!(
        oe_frd(&cont, &o, &opts),
        Err(Error::InvalidArgument { .. })
    ));
    // nb = 0
    assert!(matches!(
        arx_frd(
            &frd,
            &TfOrders {
                nb: 0,
                nf: 2,
                nk: 1
            },
            &opts
        ),
        Err(Error::InvalidArgument { .. })
    ));
    // non-finite FRF values are refused when the Frd is built
    let mut v = g.freq_response(&f).unwrap();
    v[2] = c64::new(f64::NAN, 0.0);
    assert!(Frd::new(f.clone(), v, None, Some(TS)).is_err());
}

/// The coprime route on exact data: T = q^-1 B_t/F and S = B_s/F with a stable F of degree 4 and
/// an unstable plant P = q^-1 B_t/B_s (a zero of S at 1.03 and a lightly damped pair): the plant is
/// recovered to the bar, with its unstable pole.
#[test]
fn coprime_route_recovers_an_unstable_plant_from_t_ry_and_s() {
    use ambid_core::estimate::freqfit::coprime_frd;
    let (p1, p2) = (pair(0.9, 0.2), pair(0.95, 0.6));
    let f_den = den_of(&[p1[0], p1[1], p2[0], p2[1]]);
    let q = pair(0.985, 0.1);
    let bs = den_of(&[c64::new(1.03, 0.0), q[0], q[1], c64::new(0.3, 0.0)]);
    let bt = vec![0.02, -0.01, 0.005, 0.001];
    let mut num_t = vec![0.0];
    num_t.extend_from_slice(&bt);
    let t = TransferFunction::new(num_t.clone(), f_den.clone(), TS).unwrap();
    let s = TransferFunction::new(bs.clone(), f_den, TS).unwrap();
    let plant = TransferFunction::new(num_t, bs, TS).unwrap();
    let f = log_grid(200, 1.0, 450.0);
    let fit = coprime_frd(
        &frd_of(&t, &f),
        &frd_of(&s, &f),
        4,
        1,
        &FreqFitOptions::default(),
    )
    .unwrap();
    let err = response_error(&fit.plant, &plant);
    eprintln!(
        "coprime route, exact data: plant response error {err:.2e} ({} LM iterations)",
        fit.iterations
    );
    assert!(err < 1e-8, "{err:e}");
    let p = fit.plant.poles().unwrap();
    assert!(
        p.iter().any(|z| (z - c64::new(1.03, 0.0)).norm() < 1e-8),
        "{p:?}"
    );
    // mismatched lines are refused
    let f2 = log_grid(150, 1.0, 450.0);
    assert!(matches!(
        coprime_frd(
            &frd_of(&t, &f),
            &frd_of(&s, &f2),
            4,
            1,
            &FreqFitOptions::default()
        ),
        Err(Error::InvalidArgument { .. })
    ));
}

/// Coherence weights γ²/((1 − γ²)|G|²) equal the inverse-variance weights when the coherence is
/// the one that the H1 estimate's variance σ² = (1 − γ²)|G|²/(2 n_d γ²) implies (after both are
/// normalised to mean 1).
#[test]
fn coherence_weights_match_inverse_variance_weights() {
    use ambid_core::estimate::freqfit::FreqData;
    let (_, g, _) = systems().remove(0);
    let f = log_grid(80, 1.0, 450.0);
    let v = g.freq_response(&f).unwrap();
    let nd = 19.0;
    let var: Vec<f64> = v
        .iter()
        .enumerate()
        .map(|(k, g)| g.norm_sqr() * (0.001 + 0.0001 * k as f64))
        .collect();
    let coh: Vec<f64> = v
        .iter()
        .zip(&var)
        .map(|(g, s2)| 1.0 / (1.0 + 2.0 * nd * s2 / g.norm_sqr()))
        .collect();
    let frd = Frd::new(f.clone(), v, Some(var), Some(TS)).unwrap();
    let iv = FreqData::new(
        &frd,
        &FreqFitOptions {
            weights: FreqWeights::InverseVariance,
            ..FreqFitOptions::default()
        },
    )
    .unwrap();
    let ch = FreqData::new(
        &frd,
        &FreqFitOptions {
            weights: FreqWeights::Coherence(coh),
            ..FreqFitOptions::default()
        },
    )
    .unwrap();
    for (a, b) in iv.w.iter().zip(&ch.w) {
        assert!((a - b).abs() < 1e-12 * a, "{a} vs {b}");
    }
}
