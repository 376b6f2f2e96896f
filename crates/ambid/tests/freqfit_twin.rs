//! End to end: the twin's seed experiment → period-averaged plant FRF → state-space model fitted
//! to it (`estimate::freqfit_ss`) → compared with the twin's exact plant over 10–1000 Hz.

use ambid::experiment::{run, Experiment};
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
use ambid_core::frf::closed_loop::{from_periodic, Channels, ClosedLoopFrf};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
use ambid_core::lti::StateSpace;
use ambid_twin::{Mode, Twin};

const PERIOD: usize = 1023 * 5;

fn seed_experiment(seed: u64) -> Experiment {
    Experiment::seed_paper(Mode::Linear, 0.1e-6, seed)
}

/// Period-averaged closed-loop FRFs of the seed experiment on the excited lines in 10–1000 Hz
/// (as in `frf_twin.rs`).
fn estimate(seed: u64, controller: Option<&StateSpace>) -> (ClosedLoopFrf, Twin) {
    let out = run(&seed_experiment(seed)).unwrap();
    let rec = &out.record;
    let mut an = PeriodicAnalyzer::new(PERIOD).unwrap();
    let s = an
        .analyze(
            &[&rec.r, &rec.u, &rec.y],
            1.0 / rec.ts,
            &PeriodicOptions::new(PERIOD).skip(1),
        )
        .unwrap();
    let lines: Vec<usize> = s
        .excited_lines(0, 1e-6)
        .unwrap()
        .into_iter()
        .filter(|&k| (10.0..=1000.0).contains(&s.line_hz(k)))
        .collect();
    let frf = from_periodic(&s, Channels { r: 0, u: 1, y: 2 }, &lines, controller).unwrap();
    (frf, out.twin)
}

fn percentile(v: &[f64], p: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let pos = p * (s.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    s[lo] + (s[hi] - s[lo]) * (pos - lo as f64)
}

#[test]
fn state_space_fit_of_the_period_averaged_plant_frf() {
    let (frf, twin) = estimate(1, None);
    let f = frf.f_hz().to_vec();
    let truth = twin.plant_frf(&f).unwrap();
    let opts = FreqFitOptions {
        band_hz: Some((10.0, 1000.0)),
        weights: FreqWeights::InverseVariance,
        max_iterations: 200,
        ..Default::default()
    };
    let l = f.len() as f64;
    let var = frf.plant.variance().unwrap().to_vec();
    // (order, BIC, median, p90, fit)
    let mut rows = Vec::new();
    for order in 6..=10 {
        let t0 = std::time::Instant::now();
        let fit = ss_frd(&frf.plant, order, &opts, &SsFreqOptions::default()).unwrap();
        let dt = t0.elapsed().as_secs_f64();
        let model = fit.model.freq_response_siso(&f).unwrap();
        let err: Vec<f64> = model
            .iter()
            .zip(&truth)
            .map(|(m, t)| (m - t).norm() / t.norm())
            .collect();
        let (med, p90) = (percentile(&err, 0.5), percentile(&err, 0.9));
        // the order is selected on the data, not on the truth: χ² = Σ |Ĝ_k − G_k|² / σ_k²
        // (σ_k² = E|Ĝ_k − G_k|² of the FRF estimate; expected L − n_params/2 at the true order;
        // the fit's `cost` has weights normalised to mean 1, so it is not in variance units)
        // and, for complex Gaussian errors (2L real observations), BIC = 2 χ² + ln(2L) n_params
        // (AIC, 2 χ² + 2 n_params, picks order 10 by 0.4 over order 7 and with it a spurious
        // pair at |z| = 1.0003 that fits the noise: BIC's larger penalty is the safer choice)
        let chi2: f64 = model
            .iter()
            .zip(frf.plant.values())
            .zip(&var)
            .map(|((m, g), v)| (m - g).norm_sqr() / v)
            .sum();
        let bic = 2.0 * chi2 + (2.0 * l).ln() * fit.n_params as f64;
        let pmax = fit
            .model
            .poles()
            .unwrap()
            .iter()
            .map(|p| p.norm())
            .fold(0.0, f64::max);
        eprintln!(
            "order {order}: χ² {chi2:.1} (L = {}), BIC {bic:.1}, vs truth median {:.3} % p90 {:.3} %, vs data median {:.3} %, max |p| {pmax:.5}, {} it, {:.1} ms",
            l,
            100.0 * med,
            100.0 * p90,
            100.0 * fit.errors.median_relative,
            fit.iterations,
            dt * 1e3
        );
        rows.push((order, bic, med, p90, fit));
    }
    let best = rows.iter().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
    let (order, _, med, p90, fit) = best;
    let poles = fit.model.poles().unwrap();
    let ts = 1.0 / twin.fs();
    let s_of = |z: &ambid_core::c64| z.ln() / ts;
    eprintln!(
        "selected order {order}: median {:.3} %, p90 {:.3} %",
        100.0 * med,
        100.0 * p90
    );
    for p in &poles {
        let s = s_of(p);
        eprintln!(
            "  pole z = {:.6}{:+.6}j |z| = {:.6}  f = {:.1} Hz  ζ = {:.4}",
            p.re,
            p.im,
            p.norm(),
            s.norm() / (2.0 * std::f64::consts::PI),
            -s.re / s.norm()
        );
    }
    // the twin's exact plant poles for comparison
    let truth_poles = twin.plant().poles().unwrap();
    for p in truth_poles.iter().filter(|p| p.im >= 0.0) {
        let s = s_of(p);
        eprintln!(
            "  truth z = {:.6}{:+.6}j |z| = {:.6}  f = {:.1} Hz  ζ = {:.4}",
            p.re,
            p.im,
            p.norm(),
            s.norm() / (2.0 * std::f64::consts::PI),
            -s.re / s.norm()
        );
    }
    // the bar: median ≤ 1 %, p90 ≤ 5 % over 10–1000 Hz
    assert!(*med <= 0.01, "median relative error {med}");
    assert!(*p90 <= 0.05, "90th percentile {p90}");
    assert_eq!(*order, 7, "selected order");
    // the AMB rigid-body mode: exactly one unstable pole, real, at the plant's (z = 1.02065)
    let unstable: Vec<_> = poles.iter().filter(|p| p.norm() > 1.0).collect();
    let exact_unstable = twin.plant_unstable_poles().unwrap();
    assert_eq!(unstable.len(), 1, "unstable poles {unstable:?}");
    assert_eq!(exact_unstable.len(), 1);
    let du = (unstable[0] - exact_unstable[0]).norm();
    eprintln!("unstable pole error {du:.2e}");
    assert!(
        unstable[0].im == 0.0 && du < 1e-4,
        "{unstable:?} vs {exact_unstable:?}"
    );
    // the lightly damped bending mode: the plant's (loop A open, loop B closed) is at 754 Hz,
    // ζ = 0.016 (780 Hz is the closed-loop frequency); within 60 Hz of 780 Hz and close to the
    // exact plant pole
    let bending = |set: &[ambid_core::c64]| {
        set.iter()
            .copied()
            .filter(|p| {
                let s = s_of(p);
                let fhz = s.norm() / (2.0 * std::f64::consts::PI);
                p.im > 0.0 && (fhz - 780.0).abs() < 60.0 && -s.re / s.norm() < 0.05
            })
            .collect::<Vec<_>>()
    };
    let (bm, bt) = (bending(&poles), bending(&truth_poles));
    assert_eq!(bm.len(), 1, "lightly damped modes near 780 Hz: {bm:?}");
    assert_eq!(bt.len(), 1);
    let db = (bm[0] - bt[0]).norm();
    eprintln!("bending pole error {db:.2e}");
    assert!(db < 1e-4, "bending pole {} vs {}", bm[0], bt[0]);
}

#[test]
fn order_7_meets_the_bar_on_other_seeds() {
    let opts = FreqFitOptions {
        band_hz: Some((10.0, 1000.0)),
        weights: FreqWeights::InverseVariance,
        max_iterations: 200,
        ..Default::default()
    };
    let (mut worst_med, mut worst_p90) = (0.0f64, 0.0f64);
    for seed in 2..8 {
        let (frf, twin) = estimate(seed, None);
        let f = frf.f_hz().to_vec();
        let truth = twin.plant_frf(&f).unwrap();
        let fit = ss_frd(&frf.plant, 7, &opts, &SsFreqOptions::default()).unwrap();
        let model = fit.model.freq_response_siso(&f).unwrap();
        let err: Vec<f64> = model
            .iter()
            .zip(&truth)
            .map(|(m, t)| (m - t).norm() / t.norm())
            .collect();
        let (med, p90) = (percentile(&err, 0.5), percentile(&err, 0.9));
        let n_unstable = fit
            .model
            .poles()
            .unwrap()
            .iter()
            .filter(|p| p.norm() > 1.0)
            .count();
        eprintln!(
            "seed {seed}: median {:.3} %, p90 {:.3} %, {n_unstable} unstable pole(s), {} it",
            100.0 * med,
            100.0 * p90,
            fit.iterations
        );
        assert_eq!(n_unstable, 1, "seed {seed}");
        worst_med = worst_med.max(med);
        worst_p90 = worst_p90.max(p90);
    }
    assert!(
        worst_med <= 0.01 && worst_p90 <= 0.05,
        "{worst_med} {worst_p90}"
    );
}
