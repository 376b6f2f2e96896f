//! Sample maximum-likelihood weights in the state-space and output-error fits to an FRF
//! ([`FreqWeights::SampleMaximumLikelihood`]): a closed-loop ratio estimate $\hat G = \bar Y /
//! \bar U$ whose variance is estimated from the same periods. Weighting each line by its
//! variance evaluated at the data, $1/v_k(\hat G_k)$, ties the weight to the line's own error,
//! and over hundreds of lines the fit is pulled coherently off the plant; evaluated at the
//! model, $1/v_k(G_\theta)$, the cost is the errors-in-variables likelihood of the period means
//! and the fit is unbiased. The truth is the exact plant; the data are drawn per line from the
//! closed loop's equations (seeded `ChaCha8Rng`), the sample covariances from the periods.

use ambid_core::c64;
use ambid_core::estimate::freqfit::{oe_frd, FreqFitOptions, FreqWeights, TfOrders};
use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
use ambid_core::frf::closed_loop::RatioNoise;
use ambid_core::lti::{Frd, StateSpace};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

const TS: f64 = 1e-3;
const PERIODS: usize = 10;

/// A lightly damped stable pair at 50 Hz (|z| = 0.97).
fn plant() -> StateSpace {
    let th = 2.0 * std::f64::consts::PI * 50.0 * TS;
    let (c, s) = (0.97 * th.cos(), 0.97 * th.sin());
    StateSpace::discrete(
        faer::mat![[c, s], [-s, c]],
        faer::mat![[1.0], [0.0]],
        faer::mat![[0.1, 0.05]],
        faer::mat![[0.0]],
        TS,
    )
    .unwrap()
}

/// One record's plant FRF and its per-line noise: `PERIODS` periods of the loop $u = -C y + r$,
/// $y = P u + n$ (sensor noise $n$, circular of standard deviation `sigma`, independent per
/// period), $|R| = 1$ on every line, a static controller $C = 3$.
fn record(
    p0: &[c64],
    f: &[f64],
    sigma: f64,
    ctrl: f64,
    rng: &mut ChaCha8Rng,
) -> (Frd, Vec<RatioNoise>) {
    let m = PERIODS as f64;
    let (mut g, mut var, mut noise) = (Vec::new(), Vec::new(), Vec::new());
    for &p in p0 {
        let d = 1.0 + p * ctrl;
        let (mut us, mut ys) = (Vec::new(), Vec::new());
        for _ in 0..PERIODS {
            let (re, im): (f64, f64) = (
                StandardNormal.sample(&mut *rng),
                StandardNormal.sample(&mut *rng),
            );
            let n = c64::new(re, im) * (sigma / 2f64.sqrt());
            ys.push((p + n) / d);
            us.push((c64::new(1.0, 0.0) - n * ctrl) / d);
        }
        let ub = us.iter().sum::<c64>() / m;
        let yb = ys.iter().sum::<c64>() / m;
        // sample covariances of the periods, over M for the means' covariances
        let s = |a: &[c64], ab: c64, b: &[c64], bb: c64| -> c64 {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - ab) * (y - bb).conj())
                .sum::<c64>()
                / ((m - 1.0) * m)
        };
        let (suu, syy, suy) = (
            s(&us, ub, &us, ub).re,
            s(&ys, yb, &ys, yb).re,
            s(&us, ub, &ys, yb),
        );
        let u2 = ub.norm_sqr();
        let rn = RatioNoise {
            a: suu / u2,
            b: syy / u2,
            c: suy / u2,
        };
        let gk = yb / ub;
        g.push(gk);
        var.push(rn.variance_at(gk));
        noise.push(rn);
    }
    (Frd::new(f.to_vec(), g, Some(var), Some(TS)).unwrap(), noise)
}

#[test]
fn sample_maximum_likelihood_removes_the_bias_of_weights_taken_at_the_data() {
    let truth = plant();
    let f: Vec<f64> = (1..=300).map(|k| 1.5 * k as f64).collect();
    let p0 = truth.freq_response_siso(&f).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(20261207);
    // |PC| 1.7–54 and a relative standard deviation of 0.14 at the median line (0.4 at most):
    // the AMB loop's 300–1000 Hz, where the library chain's fits were pulled off
    let (ctrl, sig) = (30.0, 0.02);
    let runs = 40;
    // the state-space fit, and the output-error fit B/F with nb = nf = 2, nk = 1 (the plant's
    // own structure)
    let fit = |frd: &Frd, weights: FreqWeights, oe: bool| -> Vec<c64> {
        let opts = FreqFitOptions {
            weights,
            ..FreqFitOptions::default()
        };
        if oe {
            let o = TfOrders {
                nb: 2,
                nf: 2,
                nk: 1,
            };
            let m = oe_frd(frd, &o, &opts).unwrap().model;
            m.freq_response(&f).unwrap()
        } else {
            let m = ss_frd(frd, 2, &opts, &SsFreqOptions::default())
                .unwrap()
                .model;
            m.freq_response_siso(&f).unwrap()
        }
    };
    // per run, the relative error averaged over the lines (complex: a coherent pull shows);
    // [state-space, output-error][weights at the data, at the model]
    let mut pulls = [vec![Vec::new(), Vec::new()], vec![Vec::new(), Vec::new()]];
    for _ in 0..runs {
        let (frd, noise) = record(&p0, &f, sig, ctrl, &mut rng);
        for (s, oe) in [(0, false), (1, true)] {
            for (w, weights) in [
                FreqWeights::InverseVariance,
                FreqWeights::SampleMaximumLikelihood(noise.clone()),
            ]
            .into_iter()
            .enumerate()
            {
                let r = fit(&frd, weights, oe);
                let e: c64 =
                    r.iter().zip(&p0).map(|(m, p)| (m - p) / p).sum::<c64>() / f.len() as f64;
                pulls[s][w].push(e);
            }
        }
    }
    // mean over the runs and its standard error
    let stats = |v: &[c64]| -> (c64, f64) {
        let n = v.len() as f64;
        let mean = v.iter().sum::<c64>() / n;
        let var = v.iter().map(|x| (x - mean).norm_sqr()).sum::<f64>() / (n - 1.0);
        (mean, (var / n).sqrt())
    };
    for (s, name) in [(0, "state space"), (1, "output error")] {
        let (md, sd) = stats(&pulls[s][0]);
        let (mm, sm) = stats(&pulls[s][1]);
        eprintln!(
            "{name}: weights at the data: mean {md:.3e} se {sd:.3e}; at the model: mean {mm:.3e} se {sm:.3e}"
        );
        // at the data: a coherent pull of about 4 % of |P|, tens of standard errors
        assert!(md.norm() > 10.0 * sd, "{name}: {md} {sd}");
        // at the model: no pull the runs can tell from zero, and a tenth of the other at most
        assert!(mm.norm() < 3.0 * sm, "{name}: {mm} {sm}");
        assert!(mm.norm() < 0.1 * md.norm(), "{name}: {mm} {md}");
    }
}

#[test]
fn sample_maximum_likelihood_weights_are_checked() {
    let f: Vec<f64> = (1..=20).map(|k| 10.0 * k as f64).collect();
    let p0 = plant().freq_response_siso(&f).unwrap();
    let frd = Frd::new(f, p0, None, Some(TS)).unwrap();
    let one = RatioNoise {
        a: 0.0,
        b: 1e-4,
        c: c64::new(0.0, 0.0),
    };
    // one description per line
    let opts = FreqFitOptions {
        weights: FreqWeights::SampleMaximumLikelihood(vec![one; 19]),
        ..FreqFitOptions::default()
    };
    let e = ss_frd(&frd, 2, &opts, &SsFreqOptions::default()).unwrap_err();
    assert!(
        e.to_string().contains("19 noise descriptions for 20 lines"),
        "{e}"
    );
    // ARX (linear in its parameters) holds its weights fixed and refuses them
    let opts = FreqFitOptions {
        weights: FreqWeights::SampleMaximumLikelihood(vec![one; 20]),
        ..FreqFitOptions::default()
    };
    let o = TfOrders {
        nb: 2,
        nf: 2,
        nk: 1,
    };
    let e = ambid_core::estimate::freqfit::arx_frd(&frd, &o, &opts).unwrap_err();
    assert!(e.to_string().contains("ss_frd, oe_frd"), "{e}");
    // a noise of the output alone: the weights are constant and the fit is the plain one
    let sml = ss_frd(&frd, 2, &opts, &SsFreqOptions::default())
        .unwrap()
        .model;
    let plain = ss_frd(
        &frd,
        2,
        &FreqFitOptions::default(),
        &SsFreqOptions::default(),
    )
    .unwrap()
    .model;
    let (a, b) = (
        sml.freq_response_siso(frd.f_hz()).unwrap(),
        plain.freq_response_siso(frd.f_hz()).unwrap(),
    );
    assert!(a
        .iter()
        .zip(&b)
        .all(|(x, y)| (x - y).norm() <= 1e-9 * y.norm()));
}

/// Term (f) with the FRF's noise ([`ExtraTerms::fit_noise`]): its reference is the sample
/// maximum-likelihood fit, so the SML fit itself is at distance 0, and the inverse-variance fit
/// is at its distance from the SML fit computed here by hand, the pull of the weights at the
/// data (which the reference without the noise would not show).
#[test]
fn term_f_takes_the_sample_maximum_likelihood_fit_as_its_reference_with_the_noise() {
    use ambid_core::validate::uncertainty::{uncertainty, ExtraTerms, UncertaintyOptions};
    let truth = plant();
    let f: Vec<f64> = (1..=300).map(|k| 1.5 * k as f64).collect();
    let p0 = truth.freq_response_siso(&f).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (frd, noise) = record(&p0, &f, 0.02, 30.0, &mut rng);
    let fit = |weights: FreqWeights| {
        let opts = FreqFitOptions {
            weights,
            max_unstable_poles: Some(0),
            ..FreqFitOptions::default()
        };
        ss_frd(&frd, 2, &opts, &SsFreqOptions::default())
            .unwrap()
            .model
    };
    let sml = fit(FreqWeights::SampleMaximumLikelihood(noise.clone()));
    let iv = fit(FreqWeights::InverseVariance);
    let (ps, pi) = (
        sml.freq_response_siso(&f).unwrap(),
        iv.freq_response_siso(&f).unwrap(),
    );
    // the bound's variances at the SML model, as the workflow passes them
    let at_model: Vec<f64> = noise
        .iter()
        .zip(&ps)
        .map(|(n, p)| n.variance_at(*p))
        .collect();
    let frd_m = Frd::new(f.clone(), frd.values().to_vec(), Some(at_model), Some(TS)).unwrap();
    let with = ExtraTerms {
        fit_noise: Some(&noise),
        ..ExtraTerms::default()
    };
    let opts = UncertaintyOptions::default();
    let own = uncertainty(&sml, &frd_m, &with, &opts).unwrap();
    let d = own.fit_distance.expect("term (f)");
    assert!(
        d.iter().zip(&ps).all(|(d, p)| *d <= 1e-6 * p.norm()),
        "the SML fit's own term (f): {:?}",
        d.iter()
            .zip(&ps)
            .map(|(d, p)| d / p.norm())
            .fold(0.0, f64::max)
    );
    // the inverse-variance fit: its distance from the SML fit, line by line
    let other = uncertainty(&iv, &frd_m, &with, &opts).unwrap();
    let d = other.fit_distance.expect("term (f)");
    let mut rel = Vec::new();
    for ((d, a), b) in d.iter().zip(&pi).zip(&ps) {
        let want = (a - b).norm();
        assert!(
            (d - want).abs() <= 1e-5 * b.norm() + 1e-3 * want,
            "{d} {want}"
        );
        rel.push(want / b.norm());
    }
    rel.sort_by(f64::total_cmp);
    // the pull of the weights at the data is of the order of the first test's 4 % of |P|
    assert!(rel[rel.len() / 2] > 1e-3, "median {}", rel[rel.len() / 2]);
    // without the noise the reference is the inverse-variance fit to these variances at the
    // model, which is not the SML fit: the SML model is then not at distance 0
    let plain = uncertainty(&sml, &frd_m, &ExtraTerms::default(), &opts).unwrap();
    let d = plain.fit_distance.expect("term (f)");
    let mut rel: Vec<f64> = d.iter().zip(&ps).map(|(d, p)| d / p.norm()).collect();
    rel.sort_by(f64::total_cmp);
    eprintln!(
        "without the noise, the SML fit's term (f): median {:.3e}",
        rel[rel.len() / 2]
    );
    // a wrong length is a typed error
    let short = ExtraTerms {
        fit_noise: Some(&noise[1..]),
        ..ExtraTerms::default()
    };
    let e = uncertainty(&sml, &frd_m, &short, &opts).unwrap_err();
    assert!(e.to_string().contains("fit_noise"), "{e}");
}
