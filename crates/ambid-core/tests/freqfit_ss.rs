//! State-space fits to frequency-response data (`estimate::freqfit_ss`): exact data of known
//! systems must be reproduced to rounding level, bad input must give typed errors.

use ambid_core::c64;
use ambid_core::error::Error;
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
use ambid_core::lti::{Frd, StateSpace};
use faer::Mat;

const TS: f64 = 5e-5; // 20 kHz

/// 2×2 real block with eigenvalues r e^{±jθ}.
fn rot(r: f64, th: f64) -> [[f64; 2]; 2] {
    let (c, s) = (r * th.cos(), r * th.sin());
    [[c, s], [-s, c]]
}

fn block_diag(blocks: &[Vec<Vec<f64>>]) -> Mat<f64> {
    let n: usize = blocks.iter().map(|b| b.len()).sum();
    let mut a = Mat::zeros(n, n);
    let mut o = 0;
    for b in blocks {
        for (i, row) in b.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                a[(o + i, o + j)] = *v;
            }
        }
        o += b.len();
    }
    a
}

fn col(v: &[f64]) -> Mat<f64> {
    Mat::from_fn(v.len(), 1, |i, _| v[i])
}

fn row(v: &[f64]) -> Mat<f64> {
    Mat::from_fn(1, v.len(), |_, j| v[j])
}

fn to_vecs(b: [[f64; 2]; 2]) -> Vec<Vec<f64>> {
    b.iter().map(|r| r.to_vec()).collect()
}

/// 200 log-spaced lines from 10 Hz to 9 kHz.
fn grid() -> Vec<f64> {
    let n = 200;
    (0..n)
        .map(|k| 10.0 * (900.0f64).powf(k as f64 / (n - 1) as f64))
        .collect()
}

/// (a) stable, two lightly damped modes: 0.995∠0.05 and 0.97∠0.4.
fn stable_4th() -> StateSpace {
    let a = block_diag(&[to_vecs(rot(0.995, 0.05)), to_vecs(rot(0.97, 0.4))]);
    StateSpace::discrete(
        a,
        col(&[1.0, 0.0, 0.5, 0.0]),
        row(&[0.0, 0.02, 0.0, 0.7]),
        faer::mat![[0.0]],
        TS,
    )
    .unwrap()
}

/// (b) unstable: a real pole at 1.02 and a damped pair 0.9∠0.3.
fn unstable_3rd() -> StateSpace {
    let a = block_diag(&[vec![vec![1.02]], to_vecs(rot(0.9, 0.3))]);
    StateSpace::discrete(
        a,
        col(&[1.0, 1.0, 0.0]),
        row(&[0.05, 0.0, 1.0]),
        faer::mat![[0.0]],
        TS,
    )
    .unwrap()
}

/// (c) with feedthrough: a pair 0.98∠0.1, a real pole 0.6, D = 0.3.
fn with_feedthrough() -> StateSpace {
    let a = block_diag(&[to_vecs(rot(0.98, 0.1)), vec![vec![0.6]]]);
    StateSpace::discrete(
        a,
        col(&[0.0, 0.2, 1.0]),
        row(&[1.0, 0.5, -0.4]),
        faer::mat![[0.3]],
        TS,
    )
    .unwrap()
}

/// Max relative response error over the lines and max pole error (nearest-pole matching in
/// both directions).
fn errors(truth: &StateSpace, fit: &StateSpace, f: &[f64]) -> (f64, f64) {
    let g = truth.freq_response_siso(f).unwrap();
    let h = fit.freq_response_siso(f).unwrap();
    let rel = g
        .iter()
        .zip(&h)
        .map(|(g, h)| (g - h).norm() / g.norm())
        .fold(0.0, f64::max);
    let (pt, pf) = (truth.poles().unwrap(), fit.poles().unwrap());
    assert_eq!(pt.len(), pf.len());
    let nearest =
        |p: &c64, set: &[c64]| set.iter().map(|q| (p - q).norm()).fold(f64::MAX, f64::min);
    let pe = pt
        .iter()
        .map(|p| nearest(p, &pf))
        .chain(pf.iter().map(|p| nearest(p, &pt)))
        .fold(0.0, f64::max);
    (rel, pe)
}

fn fit_exact(truth: &StateSpace, feedthrough: bool) -> (f64, f64, StateSpace) {
    let f = grid();
    let frd = Frd::from_model(truth, &f).unwrap();
    let t0 = std::time::Instant::now();
    let fit = ss_frd(
        &frd,
        truth.order(),
        &FreqFitOptions::default(),
        &SsFreqOptions {
            feedthrough,
            ..SsFreqOptions::default()
        },
    )
    .unwrap();
    let dt = t0.elapsed();
    let (rel, pe) = errors(truth, &fit.model, &f);
    eprintln!(
        "order {}: max relative error {rel:.2e}, max pole error {pe:.2e}, cost {:.2e}, {} iterations, {:.1} ms",
        truth.order(),
        fit.cost,
        fit.iterations,
        dt.as_secs_f64() * 1e3
    );
    assert_eq!(fit.n_params, 2 * truth.order() + usize::from(feedthrough));
    assert!(fit.errors.median_relative <= rel);
    (rel, pe, fit.model)
}

#[test]
fn exact_data_of_a_stable_4th_order_system_with_two_lightly_damped_modes() {
    let truth = stable_4th();
    let (rel, pe, model) = fit_exact(&truth, false);
    assert!(rel <= 1e-8, "relative error {rel}");
    assert!(pe <= 1e-8, "pole error {pe}");
    assert_eq!(model.d()[(0, 0)], 0.0);
    assert!(model.is_stable().unwrap());
}

#[test]
fn exact_data_of_an_unstable_system_keep_the_unstable_pole() {
    let truth = unstable_3rd();
    let (rel, pe, model) = fit_exact(&truth, false);
    assert!(rel <= 1e-8, "relative error {rel}");
    assert!(pe <= 1e-8, "pole error {pe}");
    let pmax = model
        .poles()
        .unwrap()
        .iter()
        .map(|p| p.norm())
        .fold(0.0, f64::max);
    assert!((pmax - 1.02).abs() <= 1e-8, "largest pole {pmax}");
}

#[test]
fn exact_data_with_feedthrough() {
    let truth = with_feedthrough();
    let (rel, pe, model) = fit_exact(&truth, true);
    assert!(rel <= 1e-8, "relative error {rel}");
    assert!(pe <= 1e-8, "pole error {pe}");
    assert!((model.d()[(0, 0)] - 0.3).abs() <= 1e-8);
}

#[test]
fn the_subspace_start_alone_is_already_exact_and_horizons_agree() {
    // max_iterations = 0 returns the subspace poles with least-squares numerators
    let truth = stable_4th();
    let f = grid();
    let frd = Frd::from_model(&truth, &f).unwrap();
    for q in [5, 10, 20] {
        let opts = FreqFitOptions {
            max_iterations: 0,
            ..Default::default()
        };
        let fit = ss_frd(
            &frd,
            4,
            &opts,
            &SsFreqOptions {
                horizon: Some(q),
                ..SsFreqOptions::default()
            },
        )
        .unwrap();
        let (rel, pe) = errors(&truth, &fit.model, &f);
        eprintln!("subspace only, q = {q}: relative {rel:.2e}, poles {pe:.2e}");
        assert_eq!(fit.iterations, 0);
        assert!(rel <= 1e-10 && pe <= 1e-12, "q = {q}: {rel} {pe}");
    }
}

#[test]
fn weighted_band_limited_fit_is_exact_on_exact_data() {
    // given weights and a band: exact data stay exact
    let truth = unstable_3rd();
    let f = grid();
    let frd = Frd::from_model(&truth, &f).unwrap();
    let w: Vec<f64> = f.iter().map(|x| 1.0 + (x / 100.0).sin().abs()).collect();
    let opts = FreqFitOptions {
        band_hz: Some((20.0, 3000.0)),
        weights: FreqWeights::Given(w),
        ..Default::default()
    };
    let fit = ss_frd(&frd, 3, &opts, &SsFreqOptions::default()).unwrap();
    let (rel, pe) = errors(&truth, &fit.model, &f);
    assert!(rel <= 1e-8 && pe <= 1e-8, "{rel} {pe}");
}

#[test]
fn enforce_stability_gives_a_stable_model() {
    let truth = unstable_3rd();
    let f = grid();
    let frd = Frd::from_model(&truth, &f).unwrap();
    let opts = FreqFitOptions {
        enforce_stability: true,
        ..Default::default()
    };
    let fit = ss_frd(&frd, 3, &opts, &SsFreqOptions::default()).unwrap();
    assert!(fit.model.is_stable().unwrap());
    // the unstable pole cannot be matched by a stable one: the error stays large
    assert!(fit.errors.relative_rmse > 1e-3);
}

#[test]
fn bad_input_gives_typed_errors() {
    let truth = stable_4th();
    let f = grid();
    let frd = Frd::from_model(&truth, &f).unwrap();
    let d = FreqFitOptions::default();
    let s = SsFreqOptions::default();
    let is_invalid = |r: ambid_core::error::Result<_>, name: &str| match r {
        Err(Error::InvalidArgument { name: n, .. }) => assert_eq!(n, name),
        Err(e) => panic!("expected invalid `{name}`, got {e}"),
        Ok(_) => panic!("expected invalid `{name}`, got a fit"),
    };
    // order 0
    is_invalid(ss_frd(&frd, 0, &d, &s).map(|_| ()), "order");
    // a band with 3 lines cannot determine 8 parameters
    let band = FreqFitOptions {
        band_hz: Some((100.0, 105.0)),
        ..Default::default()
    };
    let n_in = f.iter().filter(|x| (100.0..=105.0).contains(*x)).count();
    assert!(n_in < 4);
    is_invalid(ss_frd(&frd, 4, &band, &s).map(|_| ()), "band_hz");
    // continuous FRF
    let cont = Frd::new(f.clone(), frd.values().to_vec(), None, None).unwrap();
    is_invalid(ss_frd(&cont, 4, &d, &s).map(|_| ()), "frd");
    // zero weights everywhere
    let zero = FreqFitOptions {
        weights: FreqWeights::Given(vec![0.0; f.len()]),
        ..Default::default()
    };
    is_invalid(ss_frd(&frd, 4, &zero, &s).map(|_| ()), "band_hz");
    // horizon outside [n + 1, L]
    for q in [4, 201] {
        let h = SsFreqOptions {
            horizon: Some(q),
            ..SsFreqOptions::default()
        };
        is_invalid(ss_frd(&frd, 4, &d, &h).map(|_| ()), "horizon");
    }
    // inverse-variance weights without variances
    let iv = FreqFitOptions {
        weights: FreqWeights::InverseVariance,
        ..Default::default()
    };
    is_invalid(ss_frd(&frd, 4, &iv, &s).map(|_| ()), "weights");
    // a zero response has nothing to fit: a numerical error, not a panic
    let zero_resp = Frd::new(f.clone(), vec![c64::new(0.0, 0.0); f.len()], None, Some(TS)).unwrap();
    match ss_frd(&zero_resp, 2, &d, &s) {
        Err(Error::Numerical { .. }) => {}
        other => panic!("expected a numerical error, got {other:?}"),
    }
}
