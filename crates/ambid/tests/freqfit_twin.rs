//! End to end: the twin's seed experiment → period-averaged plant FRF → state-space model fitted
//! to it (`estimate::freqfit_ss`) → compared with the twin's exact plant over 10–1000 Hz.

use crate::common::percentile;
use ambid::experiment::{run, Experiment};
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
use ambid_core::frf::closed_loop::ClosedLoopFrf;
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
    let frf = out.periodic_frf((10.0, 1000.0), controller).unwrap();
    (frf, out.twin)
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

/// Issue 5's comparison (the seed's table 1) on the twin, and the closed-loop validation bar:
/// ARX, OE, SS × orders 6–9 fitted to the seed-1 plant FRF, validated through the loop with the
/// twin's controller on the independent seed-2 record (first period left out: the transient).
#[test]
fn comparison_table_and_closed_loop_validation() {
    use ambid_core::lti::Structure;
    use ambid_core::validate::compare::{compare_models, table, CompareSpec, ValidationRecord};
    let (frf, twin) = estimate(1, None);
    let val = run(&seed_experiment(2)).unwrap();
    let spec = CompareSpec {
        fit: FreqFitOptions {
            band_hz: Some((10.0, 1000.0)),
            weights: FreqWeights::InverseVariance,
            ..Default::default()
        },
        ..CompareSpec::default()
    };
    let rec = ValidationRecord {
        r: &val.record.r,
        y: &val.record.y,
        controller: twin.controller(),
        skip: PERIOD,
    };
    let rows = compare_models(&frf.plant, &spec, Some(rec)).unwrap();
    eprintln!("{}", table(&rows));
    let get = |s: Structure, n: usize| {
        rows.iter()
            .find(|r| r.structure == s && r.order == n)
            .unwrap()
    };
    // the bar: the state-space model of order <= 10 chosen by the FRF criteria (order 7)
    // validates through the closed loop at >= 97 %
    let ss7 = get(Structure::Ss, 7);
    let vfit = ss7.validation_fit.unwrap();
    eprintln!(
        "SS order 7: closed-loop validation fit {vfit:.2} % (seed paper's chosen model: 88.1 %)"
    );
    assert!(vfit >= 97.0, "{vfit}");
    // the exact plant in the same loop is the noise ceiling of this record
    let exact = ambid_core::validate::closed_loop::simulate_loop(
        twin.plant(),
        twin.controller(),
        &val.record.r,
    )
    .unwrap();
    let n0 = PERIOD;
    let num: f64 = val.record.y[n0..]
        .iter()
        .zip(&exact.y[n0..])
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    let m = val.record.y[n0..].iter().sum::<f64>() / (val.record.y.len() - n0) as f64;
    let den: f64 = val.record.y[n0..]
        .iter()
        .map(|a| (a - m).powi(2))
        .sum::<f64>()
        .sqrt();
    eprintln!(
        "exact plant in the loop: validation fit {:.2} %",
        100.0 * (1.0 - num / den)
    );
    // the seed's qualitative finding: ARX worst below 200 Hz, for every order
    for n in 6..=9 {
        let arx = get(Structure::Arx, n).low_band_relative_rmse.unwrap();
        let oe = get(Structure::Oe, n).low_band_relative_rmse.unwrap();
        let ss = get(Structure::Ss, n).low_band_relative_rmse.unwrap();
        assert!(
            arx > 10.0 * oe.max(ss),
            "order {n}: ARX {arx} OE {oe} SS {ss}"
        );
    }
    // the best BIC is at order 7, where OE and SS (the same model class: strictly proper,
    // 7 poles) reach the same optimum; SS stays usable at order 9 where OE overfits into
    // spurious unstable poles and an unstable loop
    let best = rows
        .iter()
        .filter(|r| r.bic.is_some())
        .min_by(|a, b| a.bic.unwrap().total_cmp(&b.bic.unwrap()))
        .unwrap();
    eprintln!("best BIC: {} order {}", best.structure.name(), best.order);
    assert_eq!(best.order, 7);
    let (b_oe, b_ss) = (
        get(Structure::Oe, 7).bic.unwrap(),
        get(Structure::Ss, 7).bic.unwrap(),
    );
    assert!((b_oe - b_ss).abs() < 1e-3 * b_oe.abs(), "{b_oe} vs {b_ss}");
    assert!(get(Structure::Ss, 9).validation_fit.unwrap() >= 97.0);
}

/// The coprime route on the twin: T_ry and S (= T_ru) fitted jointly with a common denominator,
/// P = T_ry / S, no controller model; compared with the exact plant.
#[test]
fn coprime_route_recovers_the_unstable_plant_without_a_controller_model() {
    use ambid_core::estimate::freqfit::coprime_frd;
    let (frf, twin) = estimate(1, None);
    let f = frf.f_hz().to_vec();
    let truth = twin.plant_frf(&f).unwrap();
    let opts = FreqFitOptions {
        band_hz: Some((10.0, 1000.0)),
        weights: FreqWeights::InverseVariance,
        max_iterations: 200,
        ..Default::default()
    };
    let mut best: Option<(usize, f64, f64, usize, f64)> = None;
    for n in [8usize, 9, 10, 11, 12] {
        let fit = match coprime_frd(&frf.t_ry, &frf.t_ru, n, 1, &opts) {
            Ok(fit) => fit,
            Err(e) => {
                eprintln!("closed-loop order {n}: {e}");
                continue;
            }
        };
        // an over-parameterised fit can put a zero of S (a plant pole) on a data line
        let g = match fit.plant.freq_response(&f) {
            Ok(g) => g,
            Err(e) => {
                eprintln!("closed-loop order {n}: plant response undefined ({e})");
                continue;
            }
        };
        let mut rel: Vec<f64> = g
            .iter()
            .zip(&truth)
            .map(|(a, t)| (a - t).norm() / t.norm())
            .collect();
        let (med, p90) = (percentile(&rel, 0.5), percentile(&rel, 0.9));
        rel.clear();
        // unstable plant poles that are not part of a near pole-zero cancellation
        let pz = ambid_core::validate::pz::PzAnalysis::from_state_space(
            &fit.plant.to_state_space().unwrap(),
            &ambid_core::validate::pz::PzOptions::default(),
        )
        .unwrap();
        let unstable = (0..pz.poles.len())
            .filter(|&i| pz.poles[i].unstable && pz.cancellation_of_pole(i).is_none())
            .count();
        let unstable_all = pz.unstable_poles().len();
        let true_unstable = twin
            .plant()
            .poles()
            .unwrap()
            .into_iter()
            .find(|p| p.norm() > 1.0)
            .unwrap();
        let near_true = pz
            .unstable_poles()
            .iter()
            .any(|r| (r.z - true_unstable).norm() < 1e-3);
        for r in pz.unstable_poles() {
            eprintln!(
                "    order {n} unstable plant pole z = {:.6}{:+.6}j",
                r.z.re, r.z.im
            );
        }
        // order chosen from the data alone: BIC of the joint weighted cost (4L real residuals)
        let l4 = 4.0 * f.len() as f64;
        let bic = l4 * (fit.cost / l4).ln() + (3 * n + 1) as f64 * l4.ln();
        eprintln!(
            "coprime, closed-loop order {n}: BIC {bic:.1}, plant median {:.3} %, p90 {:.3} %, unstable plant poles {unstable_all} ({unstable} not cancelled), T_ry median {:.3} %, S median {:.3} %, {} iterations",
            100.0 * med,
            100.0 * p90,
            100.0 * fit.errors.0.median_relative,
            100.0 * fit.errors.1.median_relative,
            fit.iterations
        );
        if best.is_none_or(|b| bic < b.4) {
            best = Some((n, med, p90, usize::from(near_true), bic));
        }
    }
    let (n, med, p90, unstable, _) = best.unwrap();
    eprintln!(
        "closed-loop order chosen by BIC {n}: plant median {:.3} %, p90 {:.3} %",
        100.0 * med,
        100.0 * p90
    );
    // the plant bar (1 % / 5 %) holds for the coprime route too, and the plant's
    // unstable pole is found (to 1e-3); the BIC order may add a spurious unstable pole outside
    // the band's influence (printed above), which the pole-zero table shows
    assert!(med <= 0.01 && p90 <= 0.05, "{med} {p90}");
    assert_eq!(
        unstable, 1,
        "the plant's unstable pole is among the fitted ones"
    );
}
