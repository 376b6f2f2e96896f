//! The uncertainty chain on random rigs of the linear twin that no rule was developed on
//! (rigs 301–303, noise seed 1), against the twin's exact plant (issue 23): the weight, with its
//! gain raised to cover the fitted model's error draws, overbounds the true relative error on
//! ≥ 95 % of the 10–1000 Hz lines; it overbounds its own draws as promised; the robust upper gain
//! margin keeps the true loop stable 90 % of the way and is at least half the true one; so do
//! both margins of the check on the lines (the bound itself, no weight fit).
//! The 100-rig figures are in docs/uncertainty.md (`uncertainty_rigs` example).

use ambid::uncertainty::{loop_stable, nominal_gain_interval, UncertaintyRun};
use ambid_core::validate::uncertainty::UncertaintyOptions;
use ambid_twin::Mode;

#[test]
fn the_raised_weight_covers_the_true_error_on_unseen_rigs() {
    let opts = UncertaintyOptions::default();
    for rig in 301..=303 {
        let run = UncertaintyRun::on_twin(rig, 1, Mode::Linear).unwrap();
        let a = &run.analysis;
        let c = run.coverage((10.0, 1000.0)).unwrap();
        assert!(c.lines > 200, "rig {rig}: {c:?}");
        // period averaging gives independent lines: no variance factor
        let lc = a.terms.line_correlation;
        assert!(lc.factor == 1.0 && lc.z < 3.0, "rig {rig}: {lc:?}");
        assert!(c.weight_coverage >= 0.95, "rig {rig}: {c:?}");
        // the raise is what the draws ask for: afterwards they need no more
        assert!(a.joint_raise >= 1.0, "rig {rig}");
        let factor = |m: &[f64]| {
            a.terms
                .errors
                .joint_factor(
                    m,
                    opts.raise_cover,
                    opts.run_coverage,
                    opts.draws,
                    opts.seed,
                )
                .unwrap()
        };
        let again = factor(&a.weight.weight.magnitude(&a.terms.f_hz));
        assert!(again <= 1.0 + 1e-9, "rig {rig}: {again}");
        // robust stability: conservative and useful against the true loop
        let (g_true_lo, g_true) = nominal_gain_interval(&run.truth_plant, &run.controller).unwrap();
        let g = a.robust.upper_gain_margin.expect("a finite robust margin");
        assert!(
            loop_stable(&run.truth_plant, &run.controller, 1.0 + 0.9 * (g - 1.0)).unwrap(),
            "rig {rig}: g {g}"
        );
        assert!(
            g - 1.0 >= 0.5 * (g_true - 1.0),
            "rig {rig}: {g} vs {g_true}"
        );
        assert!(
            g <= g_true * (1.0 + 1e-9),
            "rig {rig}: {g} above the true {g_true}"
        );
        // the check on the lines: the bound raised by its own joint factor, both margins
        assert!(a.lines_raise >= 1.0, "rig {rig}");
        let again = factor(
            &a.terms
                .multiplicative
                .iter()
                .map(|b| b * a.lines_raise)
                .collect::<Vec<_>>(),
        );
        assert!(again <= 1.0 + 1e-9, "rig {rig}: {again}");
        let ol = &a.on_lines;
        assert!(ol.robustly_stable, "rig {rig}: {ol:?}");
        let (lo, hi) = (ol.lower_gain_margin.unwrap(), ol.upper_gain_margin.unwrap());
        crate::common::assert_margin_bars(
            &run.truth_plant,
            &run.controller,
            (lo, hi),
            (g_true_lo, g_true),
            &format!("rig {rig}: the lines"),
        );
    }
}

/// Random rig 162 with noise seed 1162: the BIC's best fit (order 9) puts a nearly undamped
/// pole pair at 3.2 kHz, just beyond the FRF's band (to 3.0 kHz), where the true loop has
/// |T| = 0.02 and the model's 2.8, so the weight-based check found no robust margin at all
/// (docs/uncertainty.md, "Independent noise realisations"). A mode whose resonance lies
/// outside the band is not identified, and the nominal fit refuses it: the chosen model has
/// none, and both robust-margin bars hold against the twin's exact loop.
/// A Welch FRF (noise excitation, `ambid frf`'s defaults) on the same unseen rigs: its lines
/// correlate at about 0.4 (Hann: $(2/3)^2 = 0.44$ in theory, factor $1 + 2 \cdot 0.44 = 1.89$),
/// the bound finds that in the misfit and widens terms (a) and (b) by it, and its weight then
/// covers the true error on ≥ 95 % of the 10–1000 Hz lines. Taking the lines as independent
/// gives a term (a) $\sqrt\kappa$ narrower. (Linear rigs 1–40: covered on 37 runs with the
/// factor, 34 without; docs/uncertainty.md, "Welch FRFs: correlated lines".)
#[test]
fn a_welch_frfs_correlated_lines_widen_the_bound() {
    use ambid::uncertainty::{analyse, nominal_by_bic, twin_noise_welch_frf};
    use ambid_core::validate::uncertainty::{CorrelatedLines, ExtraTerms};
    for rig in 301..=303 {
        let (out, frd) = twin_noise_welch_frf(rig, 1000 * rig, Mode::Linear, true).unwrap();
        let controller = out.twin.controller().clone();
        let nominal = nominal_by_bic(&frd, &controller).unwrap();
        let bound = |correlated_lines| {
            analyse(
                &nominal,
                &frd,
                &controller,
                &ExtraTerms::default(),
                &UncertaintyOptions {
                    correlated_lines,
                    ..UncertaintyOptions::default()
                },
                4,
                ambid_core::validate::weight::DEFAULT_COVER,
            )
            .unwrap()
        };
        let auto = bound(CorrelatedLines::Auto);
        let lc = auto.terms.line_correlation;
        assert!(
            (0.3..0.5).contains(&lc.rho1) && lc.rho2.abs() < 0.1,
            "rig {rig}: {lc:?}"
        );
        assert!((1.5..2.3).contains(&lc.factor), "rig {rig}: {lc:?}");
        let off = bound(CorrelatedLines::Off);
        for k in (0..frd.len()).step_by(37) {
            let r = auto.terms.frf_confidence[k] / off.terms.frf_confidence[k];
            assert!(
                (r - lc.factor.sqrt()).abs() < 1e-6,
                "rig {rig}, line {k}: {r}"
            );
        }
        let run = UncertaintyRun {
            frd: frd.clone(),
            nominal: nominal.clone(),
            analysis: auto,
            truth_plant: out.twin.plant().clone(),
            controller: controller.clone(),
            frf_periods: Vec::new(),
        };
        let c = run.coverage((10.0, 1000.0)).unwrap();
        assert!(c.weight_coverage >= 0.95, "rig {rig}: {c:?}");
    }
}

#[test]
fn a_resonance_beyond_the_band_is_not_a_nominal_model() {
    use ambid::uncertainty::out_of_band_resonance;
    let run = UncertaintyRun::on_twin(162, 1162, Mode::Linear).unwrap();
    let f = run.frd.f_hz();
    let band = (f[0], f[f.len() - 1]);
    assert!(out_of_band_resonance(&run.nominal, band).unwrap().is_none());
    let (g, g_true) = weight_margin_bars_hold(&run);
    assert!(g <= g_true * (1.0 + 1e-9), "{g} above the true {g_true}");
}

/// The weight's upper robust margin against the exact loop: the true loop stable at 90 % of the
/// raise and the raise at least half the true one. Returns (reported, true).
fn weight_margin_bars_hold(run: &UncertaintyRun) -> (f64, f64) {
    let (_, g_true) = nominal_gain_interval(&run.truth_plant, &run.controller).unwrap();
    let g = run
        .analysis
        .robust
        .upper_gain_margin
        .expect("a robust margin");
    assert!(loop_stable(&run.truth_plant, &run.controller, 1.0 + 0.9 * (g - 1.0)).unwrap());
    assert!(g - 1.0 >= 0.5 * (g_true - 1.0), "{g} vs {g_true}");
    (g, g_true)
}

/// Term (e) on the *nonlinear* twin, rigs 301 and 303 (noise seed 1; the amplitude study at 5
/// and 16 % of i_sat beside the seed experiment's 10 %): the seed FRF converges to the best
/// linear approximation at 10 %, a smooth few tenths of a percent off the linearisation the
/// truth is. Without term (e) the weight leaves more than 5 % of the 10–1000 Hz lines
/// uncovered; with it, it covers ≥ 95 % of them, and the term is present where the shift is
/// (10–200 Hz).
#[test]
fn the_amplitude_term_covers_the_nonlinear_twins_shift() {
    for rig in [301, 303] {
        let without = UncertaintyRun::on_twin(rig, 1, Mode::Nonlinear).unwrap();
        let c0 = without.coverage((10.0, 1000.0)).unwrap();
        assert!(c0.weight_coverage < 0.95, "rig {rig}: {c0:?}");
        assert!(without.analysis.terms.amplitude.is_none());
        let with =
            UncertaintyRun::on_twin_with_levels(rig, 1, Mode::Nonlinear, &[0.05, 0.16]).unwrap();
        let c = with.coverage((10.0, 1000.0)).unwrap();
        assert!(c.weight_coverage >= 0.95, "rig {rig}: {c:?}");
        let t = &with.analysis.terms;
        let e = t.amplitude.as_ref().expect("term (e)");
        let low: Vec<usize> = (0..t.f_hz.len())
            .filter(|&k| (10.0..=200.0).contains(&t.f_hz[k]))
            .collect();
        let present = low.iter().filter(|&&k| e[k] > 0.0).count();
        assert!(
            present * 2 > low.len(),
            "rig {rig}: term (e) on {present} of {} lines in 10-200 Hz",
            low.len()
        );
        // the robust-stability bars still hold with the wider bound
        let (_, g_true) = nominal_gain_interval(&with.truth_plant, &with.controller).unwrap();
        let g = with.analysis.robust.upper_gain_margin.unwrap();
        assert!(loop_stable(&with.truth_plant, &with.controller, 1.0 + 0.9 * (g - 1.0)).unwrap());
        assert!(
            g - 1.0 >= 0.5 * (g_true - 1.0),
            "rig {rig}: {g} vs {g_true}"
        );
    }
}

/// A plant whose FRF moves as G(a) = P (1 + κ(f) a²) with a known smooth κ, measured at three
/// levels with 0.2 % relative noise per line (seeded): term (e) at the level 0.1 covers the true
/// shift |κ| a² at ≥ 95 % of the lines without being loose (median ≤ 1.6× it); with κ = 0 the
/// same noise gives no term on ≥ 98 % of the lines; with 0.15 κ, a shift mostly below one
/// window's noise, the wider windows give a covering term on ≥ 75 % of the lines (the one window
/// alone: 44 %); noise-free, it is the shift to 0.2 % (the
/// smoothing window's average of a κ that moves with frequency); bad
/// input is refused with the fix named.
/// A plant with a lightly damped resonance at about 300 Hz, at $T = 0.1$ ms.
fn resonance_model() -> (ambid_core::lti::StateSpace, f64) {
    let ts = 1e-4;
    let m = ambid_core::lti::StateSpace::discrete(
        faer::mat![[1.9, -0.96], [1.0, 0.0]],
        faer::mat![[1.0], [0.0]],
        faer::mat![[1.0, 0.5]],
        faer::mat![[0.0]],
        ts,
    )
    .unwrap();
    (m, ts)
}

#[test]
fn the_amplitude_term_recovers_a_known_shift_and_refuses_bad_input() {
    use ambid::uncertainty::amplitude_term;
    use ambid_core::{c64, lti::Frd};
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let (m, ts) = resonance_model();
    let f: Vec<f64> = (1..=250).map(|k| 4.0 * k as f64).collect();
    let p = m.freq_response_siso(&f).unwrap();
    let kappa = |fk: f64, scale: f64| c64::new(-0.4 * scale, 0.12 * scale * fk / 1000.0);
    let levels = [0.05, 0.1, 0.16];
    let measure = |scale: f64, noise: f64, seed: u64| -> Vec<(f64, Frd)> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        levels
            .iter()
            .map(|&a| {
                let (mut g, mut v) = (Vec::new(), Vec::new());
                for (k, &fk) in f.iter().enumerate() {
                    let s = noise * p[k].norm();
                    let (re, im): (f64, f64) = (
                        StandardNormal.sample(&mut rng),
                        StandardNormal.sample(&mut rng),
                    );
                    let n = c64::new(re, im) * (s * std::f64::consts::FRAC_1_SQRT_2);
                    g.push(p[k] * (c64::new(1.0, 0.0) + kappa(fk, scale) * (a * a)) + n);
                    v.push((s * s).max(1e-30));
                }
                (a, Frd::new(f.clone(), g, Some(v), Some(ts)).unwrap())
            })
            .collect()
    };
    let term = |data: &[(f64, Frd)]| {
        let refs: Vec<(f64, &Frd)> = data.iter().map(|(a, g)| (*a, g)).collect();
        amplitude_term(&refs, 0.1, &f, &m, 0.95).unwrap()
    };
    // noisy, with the shift
    let e = term(&measure(1.0, 2e-3, 7));
    let ratio: Vec<f64> = (0..f.len())
        .map(|k| e[k] / p[k].norm() / (kappa(f[k], 1.0).norm() * 0.01))
        .collect();
    let covered = ratio.iter().filter(|r| **r >= 1.0).count();
    assert!(
        covered * 100 >= 95 * f.len(),
        "covered {covered} of {}",
        f.len()
    );
    let mut sorted = ratio.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    assert!(
        median > 1.0 && median <= 1.6,
        "median term / shift {median}"
    );
    // noisy, no shift: (almost) no term
    let e0 = term(&measure(0.0, 2e-3, 8));
    let zero = e0.iter().filter(|x| **x == 0.0).count();
    assert!(
        zero * 100 >= 98 * f.len(),
        "{zero} of {} lines without a term",
        f.len()
    );
    // a shift 0.15 times as large, mostly below the noise of one window of 2M + 1 lines: the
    // wider windows see it (with the one window, 110 of the 250 lines had a term here; now 206)
    let small = term(&measure(0.15, 2e-3, 9));
    let (mut present, mut covers) = (0, 0);
    for k in 0..f.len() {
        let want = kappa(f[k], 0.15).norm() * 0.01;
        present += usize::from(small[k] > 0.0);
        covers += usize::from(small[k] / p[k].norm() >= want);
    }
    println!(
        "small shift: term on {present}, covering on {covers} of {} lines",
        f.len()
    );
    assert!(
        present * 100 >= 75 * f.len() && covers * 100 >= 75 * f.len(),
        "small shift: term on {present}, covering on {covers} of {} lines",
        f.len()
    );
    // noise-free: the shift itself, up to the window's weighted average of a κ that moves with
    // f (the weights |P|² are not symmetric about a line near the resonance: 0.14 % here)
    let worst = |data: &[(f64, Frd)], scale: f64| {
        let ex = term(data);
        (0..f.len())
            .map(|k| {
                let want = kappa(f[k], scale).norm() * 0.01;
                (ex[k] / p[k].norm() - want).abs() / want
            })
            .fold(0.0f64, f64::max)
    };
    let w = worst(&measure(1.0, 0.0, 9), 1.0);
    assert!(w <= 2e-3, "noise-free: worst relative deviation {w}");
    // bad input
    let data = measure(1.0, 2e-3, 10);
    let refs: Vec<(f64, &Frd)> = data.iter().map(|(a, g)| (*a, g)).collect();
    let msg = |r: ambid::error::Result<Vec<f64>>| r.unwrap_err().to_string();
    assert!(msg(amplitude_term(&refs[..1], 0.1, &f, &m, 0.95)).contains("two or more"));
    let same = [refs[0], (0.05, refs[1].1)];
    assert!(msg(amplitude_term(&same, 0.1, &f, &m, 0.95)).contains("distinct"));
    assert!(msg(amplitude_term(&refs, 0.0, &f, &m, 0.95)).contains("positive"));
    assert!(msg(amplitude_term(&refs, f64::NAN, &f, &m, 0.95)).contains("positive"));
    let neg = [refs[0], (-0.1, refs[1].1)];
    assert!(msg(amplitude_term(&neg, 0.1, &f, &m, 0.95)).contains("positive"));
    let other = Frd::new(
        f.iter().map(|x| x + 1.0).collect(),
        data[1].1.values().to_vec(),
        data[1].1.variance().map(<[f64]>::to_vec),
        Some(ts),
    )
    .unwrap();
    let mixed = [refs[0], (0.16, &other)];
    assert!(msg(amplitude_term(&mixed, 0.1, &f, &m, 0.95)).contains("same excitation"));
    let novar = Frd::new(f.clone(), data[1].1.values().to_vec(), None, Some(ts)).unwrap();
    let nv = [refs[0], (0.16, &novar)];
    assert!(msg(amplitude_term(&nv, 0.1, &f, &m, 0.95)).contains("two or more periods"));
    assert!(msg(amplitude_term(&refs, 0.1, &f, &m, 1.0)).contains("(0, 1)"));
}

/// Term (e)'s projection through the model uses only the lines where every level's FRF is
/// within [`AMPLITUDE_PROJECTION_REL_STD`](ambid::uncertainty::AMPLITUDE_PROJECTION_REL_STD) of
/// $|\hat P|$: with 30 % relative noise on the lowest 100 of 250 lines (one level's only on
/// lines 100–119) and 0.2 % elsewhere, exactly the lines whose every level's standard deviation
/// is within 10 % are flagged, [`AmplitudeTerm::shift_lines`](ambid::uncertainty::AmplitudeTerm)
/// gives shift 0 with variance 0 on the others and the regression's shift and variance on the
/// flagged ones, and the line term is the one without the flags (the windows keep their own
/// rule).
#[test]
fn the_amplitude_projection_uses_only_precise_lines() {
    use ambid::uncertainty::{
        amplitude_term, amplitude_term_and_shifts, AMPLITUDE_PROJECTION_REL_STD,
    };
    use ambid_core::{c64, lti::Frd};
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let (m, ts) = resonance_model();
    let f: Vec<f64> = (1..=250).map(|k| 4.0 * k as f64).collect();
    let p = m.freq_response_siso(&f).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
    let levels = [0.05, 0.1, 0.16];
    let noise = |i: usize, k: usize| {
        if k < 100 || (i == 2 && k < 120) {
            0.3
        } else {
            2e-3
        }
    };
    let data: Vec<(f64, Frd)> = levels
        .iter()
        .enumerate()
        .map(|(i, &a)| {
            let (mut g, mut v) = (Vec::new(), Vec::new());
            for (k, pk) in p.iter().enumerate() {
                let s = noise(i, k) * pk.norm();
                let (re, im): (f64, f64) = (
                    StandardNormal.sample(&mut rng),
                    StandardNormal.sample(&mut rng),
                );
                let n = c64::new(re, im) * (s * std::f64::consts::FRAC_1_SQRT_2);
                g.push(pk * c64::new(1.0 - 0.4 * a * a, 0.0) + n);
                v.push(s * s);
            }
            (a, Frd::new(f.clone(), g, Some(v), Some(ts)).unwrap())
        })
        .collect();
    let refs: Vec<(f64, &Frd)> = data.iter().map(|(a, g)| (*a, g)).collect();
    let both = amplitude_term_and_shifts(&refs, 0.1, &f, &m, 0.95).unwrap();
    let want: Vec<bool> = (0..f.len())
        .map(|k| (0..3).all(|i| noise(i, k) <= AMPLITUDE_PROJECTION_REL_STD))
        .collect();
    assert_eq!(both.projected, want);
    assert_eq!(want.iter().filter(|b| **b).count(), 130);
    let lines = both.shift_lines();
    assert_eq!(lines.f_hz, &f[..]);
    for (k, &precise) in want.iter().enumerate() {
        if precise {
            assert_eq!(lines.shift[k], both.shift[k], "line {k}");
            assert_eq!(lines.var[k], both.shift_var[k], "line {k}");
            assert!(lines.var[k] > 0.0);
        } else {
            assert_eq!(lines.shift[k], c64::new(0.0, 0.0), "line {k}");
            assert_eq!(lines.var[k], 0.0, "line {k}");
        }
    }
    // on the precise lines the shift is the truth's, -0.4 a_e² P, within its noise
    for k in (120..f.len()).step_by(10) {
        let truth = p[k] * (-0.4 * 0.01);
        let err = (lines.shift[k] - truth).norm();
        assert!(
            err <= 4.0 * lines.var[k].sqrt(),
            "line {k}: {err} against sd {}",
            lines.var[k].sqrt()
        );
    }
    assert_eq!(both.term, amplitude_term(&refs, 0.1, &f, &m, 0.95).unwrap());
}

/// The shifts' variances allow for lines that share noise (a Welch FRF's): with independent
/// lines they are the regression's own $a_e^4/S_{xx}$ (a naive weighted regression in the test);
/// with noise that is a moving average over neighbouring lines, $x_k = a w_k + b w_{k-1}$, they
/// are that times about $1 + 2ab$ (the variance of a smooth average over the lines), read on the
/// regression's residuals, so a shift linear in $a^2$ does not enter the factor. Each line's
/// shift keeps the regression's estimate, whose error has the per-line variance.
#[test]
fn the_amplitude_shifts_variance_allows_for_correlated_lines() {
    use ambid::uncertainty::amplitude_shift_lines;
    use ambid_core::{c64, lti::Frd};
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let (m, ts) = resonance_model();
    let f: Vec<f64> = (1..=600).map(|k| 2.0 * k as f64).collect();
    let p = m.freq_response_siso(&f).unwrap();
    let levels = [0.05, 0.08, 0.1, 0.13, 0.16];
    let (ae, noise): (f64, f64) = (0.1, 2e-3);
    // (a, b) of the moving average, a² + b² = 1
    let measure = |shift: f64, b: f64, seed: u64| -> Vec<(f64, Frd)> {
        let a = (1.0 - b * b).sqrt();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut gauss = || {
            let (re, im): (f64, f64) = (
                StandardNormal.sample(&mut rng),
                StandardNormal.sample(&mut rng),
            );
            c64::new(re, im) * std::f64::consts::FRAC_1_SQRT_2
        };
        levels
            .iter()
            .map(|&lv| {
                let w: Vec<c64> = (0..=f.len()).map(|_| gauss()).collect();
                let (mut g, mut v) = (Vec::new(), Vec::new());
                for k in 0..f.len() {
                    let s = noise * p[k].norm();
                    let n = (w[k + 1] * a + w[k] * b) * s;
                    g.push(p[k] * (1.0 - shift * lv * lv) + n);
                    v.push(s * s);
                }
                (lv, Frd::new(f.clone(), g, Some(v), Some(ts)).unwrap())
            })
            .collect()
    };
    // the naive weighted regression's variance of the shift at a_e
    let naive = |data: &[(f64, Frd)], k: usize| {
        let w: Vec<f64> = data
            .iter()
            .map(|(_, g)| 1.0 / g.variance().unwrap()[k])
            .collect();
        let x: Vec<f64> = data.iter().map(|(a, _)| a * a).collect();
        let sw: f64 = w.iter().sum();
        let xm = w.iter().zip(&x).map(|(w, x)| w * x).sum::<f64>() / sw;
        let sxx: f64 = w.iter().zip(&x).map(|(w, x)| w * (x - xm) * (x - xm)).sum();
        ae.powi(4) / sxx
    };
    for (b, shift, seed, want) in [
        (0.0, 3.0, 1, (1.0, 1.0)),
        (0.5, 3.0, 2, (1.6, 2.1)),
        (0.5, 0.0, 3, (1.6, 2.1)),
    ] {
        let data = measure(shift, b, seed);
        let r: Vec<(f64, &Frd)> = data.iter().map(|(a, g)| (*a, g)).collect();
        let (s, v) = amplitude_shift_lines(&r, ae).unwrap();
        let factor = v[100] / naive(&data, 100);
        // every line carries the same factor
        assert!(
            (0..f.len()).all(|k| (v[k] / naive(&data, k) - factor).abs() < 1e-9 * factor),
            "b {b}: the factor differs between lines"
        );
        assert!(
            factor >= want.0 - 1e-12 && factor <= want.1 + 1e-12,
            "b {b}, shift {shift}: factor {factor}, expected {want:?} (1 + 2ab = {})",
            1.0 + 2.0 * b * (1.0 - b * b).sqrt()
        );
        // the shift itself is the regression's, relative error below its noise
        let z = (0..f.len())
            .map(|k| (s[k] + p[k] * shift * ae * ae).norm_sqr() / naive(&data, k))
            .sum::<f64>()
            / f.len() as f64;
        assert!(z > 0.8 && z < 1.25, "b {b}: mean |ŝ − s|² / var {z}");
    }
}

/// Random rig 143 of the linear twin, noise seed 1143 (one of the library chain's misses on
/// rigs 101–200, docs/uncertainty.md, "Weights that follow the data's noise"): with the fits
/// weighted by the FRF's variance at the data the weight covers the true error on fewer than
/// 95 % of the 10–1000 Hz lines (81 %: the BIC's fit is pulled off the plant by weights that
/// follow each line's error); by sample maximum likelihood (the variance at the model) it
/// covers ≥ 95 % (98 %), and the margin bars hold against the exact loop.
#[test]
fn sample_maximum_likelihood_fits_restore_the_coverage_of_rig_143() {
    use ambid::uncertainty::FitWeights;
    let at_data =
        UncertaintyRun::on_twin_weighted(143, 1143, Mode::Linear, &[], FitWeights::AtData).unwrap();
    let c0 = at_data.coverage((10.0, 1000.0)).unwrap();
    assert!(c0.weight_coverage < 0.95, "{c0:?}");
    let run = UncertaintyRun::on_twin_weighted(143, 1143, Mode::Linear, &[], FitWeights::AtModel)
        .unwrap();
    let c = run.coverage((10.0, 1000.0)).unwrap();
    assert!(c.weight_coverage >= 0.95, "{c:?}");
    // the bound takes the variances at the chosen model
    let (v0, v) = (at_data.frd.variance().unwrap(), run.frd.variance().unwrap());
    assert_eq!(run.frd.values(), at_data.frd.values());
    assert!(v.iter().zip(v0).any(|(a, b)| (a - b).abs() > 1e-3 * b));
    weight_margin_bars_hold(&run);
}
