//! Stepped-sine lock-in: exactness on whole cycles, predicted noise variance (white and coloured,
//! single phasors and correlated ratios) against seeded Monte Carlo, the plan, and the errors.
//!
//! Oracles: the analytic phasor of a synthetic sine, and the empirical error spread over many
//! seeds (`ChaCha8Rng`).

use ambid_core::c64;
use ambid_core::frf::stepped_sine::{
    lock_in, lock_in_stats, phasor_ratio, NoiseEstimate, Quantity, Settle, SinePoint,
    SteppedSinePlan, SteppedSineResult,
};
use ambid_core::Error;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::f64::consts::PI;

/// $c + a\cos(2\pi f k T_s + \varphi)$, $k = 0..len$.
fn sine(len: usize, f: f64, fs: f64, a: f64, phi: f64, c: f64) -> Vec<f64> {
    (0..len)
        .map(|k| c + a * (2.0 * PI * f * k as f64 / fs + phi).cos())
        .collect()
}

fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

fn white(rng: &mut ChaCha8Rng, len: usize, sigma: f64) -> Vec<f64> {
    (0..len).map(|_| sigma * gauss(rng)).collect::<Vec<f64>>()
}

#[test]
fn lock_in_is_exact_on_whole_cycles() {
    let fs = 20_000.0;
    // (cycles m, window n, start): f = fs m / n
    for &(m, n, start) in &[
        (1usize, 2000usize, 0usize),
        (7, 1000, 123),
        (50, 1000, 5000),
        (333, 1000, 17),
        (499, 1000, 1),
        (3, 7, 2),
    ] {
        let f = fs * m as f64 / n as f64;
        for &(a, phi, c) in &[(1.0, 0.0, 0.0), (0.37, -2.1, 5.0), (2e-6, 1.3, -1e-3)] {
            let x = sine(start + n + 10, f, fs, a, phi, c);
            let z = lock_in(&x, f, fs, start, n).unwrap();
            let want = c64::from_polar(a, phi);
            let err = (z - want).norm();
            assert!(
                err <= 1e-12 * a.max(c.abs()) && err <= 1e-12 * a.max(1e-3),
                "m {m} n {n} start {start} a {a}: {z} vs {want} (error {err:e})"
            );
        }
    }
    // a sine has phasor -jA (phase reference t = k Ts, absolute k)
    let x: Vec<f64> = (0..4000)
        .map(|k| 0.2 * (2.0 * PI * 100.0 * k as f64 / 20_000.0).sin())
        .collect();
    let z = lock_in(&x, 100.0, 20_000.0, 1000, 2000).unwrap();
    assert!((z - c64::new(0.0, -0.2)).norm() < 1e-14);
}

#[test]
fn plan_excitation_locks_in_exactly() {
    let plan = SteppedSinePlan::new(
        20_000.0,
        &[10.0, 37.7, 97.0, 155.0, 781.0, 1999.0, 9_000.0],
        Settle::Seconds(0.01),
        3,
        0.05,
    )
    .unwrap();
    for (i, p) in plan.points().iter().enumerate() {
        let r = plan.excitation(i, 0.2).unwrap();
        assert_eq!(r.len(), p.settle_samples + p.measure_samples);
        let z = lock_in(
            &r,
            p.f_hz,
            plan.fs_hz(),
            p.settle_samples,
            p.measure_samples,
        )
        .unwrap();
        assert!((z - c64::new(0.0, -0.2)).norm() < 1e-13, "{p:?}: {z}");
        // the phase of sample k is 2π f k Ts also across the settle/measure boundary
        let k = p.settle_samples + 1;
        let want = 0.2 * (2.0 * PI * p.f_hz * k as f64 / plan.fs_hz()).sin();
        assert!((r[k] - want).abs() < 1e-12);
    }
    assert_eq!(
        plan.total_samples(),
        plan.settle_samples() + plan.measure_samples()
    );
    assert!((plan.total_time_s() - plan.total_samples() as f64 / 20_000.0).abs() < 1e-15);
}

/// Error std of the phasor over many seeds against the predicted $\sqrt{4\sigma^2/n}$, and the
/// per-seed estimate from the residual.
#[test]
fn white_noise_error_matches_the_predicted_std() {
    let (fs, n, start, sigma) = (1000.0, 1000usize, 200usize, 0.3);
    let f = fs * 37.0 / n as f64;
    let clean = sine(start + n, f, fs, 0.8, 0.7, 0.25);
    let truth = c64::from_polar(0.8, 0.7);
    let seeds = 400;
    let (mut sq, mut sq_re, mut sq_im, mut pred) = (0.0, 0.0, 0.0, 0.0);
    for seed in 0..seeds {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = white(&mut rng, start + n, sigma);
        let x: Vec<f64> = clean.iter().zip(&noise).map(|(a, b)| a + b).collect();
        let s = lock_in_stats(&x, f, fs, start, n).unwrap();
        let e = s.phasor - truth;
        sq += e.norm_sqr();
        sq_re += e.re * e.re;
        sq_im += e.im * e.im;
        pred += s.variance;
        assert!((s.mean - 0.25).abs() < 6.0 * sigma / (n as f64).sqrt());
    }
    let k = seeds as f64;
    let theory = 4.0 * sigma * sigma / n as f64;
    let measured = (sq / k).sqrt();
    eprintln!(
        "white: measured std {measured:.4e}, theory {:.4e}, mean predicted {:.4e}",
        theory.sqrt(),
        (pred / k).sqrt()
    );
    assert!(
        (measured / theory.sqrt() - 1.0).abs() < 0.2,
        "measured std {measured}, theory {}",
        theory.sqrt()
    );
    assert!(
        ((pred / k).sqrt() / measured - 1.0).abs() < 0.2,
        "predicted {} vs {measured}",
        (pred / k).sqrt()
    );
    // each part carries half: 2σ²/n
    for part in [sq_re, sq_im] {
        assert!(((part / k) / (theory / 2.0) - 1.0).abs() < 0.3, "{part}");
    }
}

/// AR(1) noise $e_k = a e_{k-1} + w_k$, started in its stationary state.
fn ar1(rng: &mut ChaCha8Rng, len: usize, a: f64, sigma_w: f64) -> Vec<f64> {
    let mut e = sigma_w / (1.0 - a * a).sqrt() * gauss(rng);
    (0..len)
        .map(|_| {
            e = a * e + sigma_w * gauss(rng);
            e
        })
        .collect()
}

/// With strongly coloured noise the white estimate is wrong at low frequency, the neighbour-bin
/// estimate follows the local density.
#[test]
fn neighbour_bins_follow_coloured_noise() {
    let (fs, n) = (1000.0, 2000usize);
    let f = fs * 20.0 / n as f64; // 10 Hz, deep in the AR(1) low-pass band
    let a = 0.95;
    let r = sine(n, f, fs, 1.0, 0.0, 0.0);
    let (mut sq, mut var_nb, mut var_w) = (0.0, 0.0, 0.0);
    let seeds = 300;
    for seed in 0..seeds {
        let mut rng = ChaCha8Rng::seed_from_u64(1000 + seed);
        let e = ar1(&mut rng, n, a, 0.05);
        let y: Vec<f64> = r.iter().zip(&e).map(|(r, e)| 0.5 * r + e).collect();
        let g = phasor_ratio(&y, &r, f, fs, 0, n, NoiseEstimate::NeighbourBins(8)).unwrap();
        let gw = phasor_ratio(&y, &r, f, fs, 0, n, NoiseEstimate::White).unwrap();
        assert_eq!(g.value, gw.value);
        sq += (g.value - 0.5).norm_sqr();
        var_nb += g.variance;
        var_w += gw.variance;
    }
    let k = seeds as f64;
    let ratio_nb = (var_nb / k) / (sq / k);
    let ratio_w = (var_w / k) / (sq / k);
    eprintln!("AR(1) at 10 Hz: predicted/actual variance, neighbour bins {ratio_nb:.3}, white {ratio_w:.4}");
    assert!(
        (ratio_nb - 1.0).abs() < 0.25,
        "neighbour bins: predicted/actual {ratio_nb}"
    );
    // the AR(1) density at 10 Hz is ~ (1+a)/(1-a) ≈ 39 times its mean: the white estimate is far off
    assert!(ratio_w < 0.1, "white: predicted/actual {ratio_w}");
}

/// Closed-loop-like correlated noise: y = P u + v, u = r − C y, so the errors of U and Y are
/// correlated; the ratio variances must still match the Monte Carlo spread.
#[test]
fn closed_loop_ratios_have_the_predicted_variance() {
    let (fs, n, settle) = (1000.0, 1000usize, 200usize);
    let f = fs * 31.0 / n as f64;
    // static loop: P = 2, C = 0.7 → T_ry = P/(1+PC) = 0.8333, S = 1/(1+PC) = 0.4167
    let (p, c) = (2.0, 0.7);
    let r = sine(settle + n, f, fs, 0.2, 0.3, 0.0);
    let seeds = 300;
    let mut z = [[0.0f64; 2]; 3]; // (sum |err|²/var, sum |err|²/predicted mean var) for t_ry, t_ru, plant
    let want = [p / (1.0 + p * c), 1.0 / (1.0 + p * c), p];
    for noise in [NoiseEstimate::White, NoiseEstimate::NeighbourBins(8)] {
        z = [[0.0; 2]; 3];
        for seed in 0..seeds {
            let mut rng = ChaCha8Rng::seed_from_u64(7 + seed);
            let v = white(&mut rng, settle + n, 0.05);
            // y = P u + v, u = r − C y  ⇒  y = (P r + v)/(1 + PC)
            let y: Vec<f64> = r
                .iter()
                .zip(&v)
                .map(|(r, v)| (p * r + v) / (1.0 + p * c))
                .collect();
            let u: Vec<f64> = r.iter().zip(&y).map(|(r, y)| r - c * y).collect();
            let pt = SinePoint::estimate(&r, &u, &y, f, fs, settle, n, noise).unwrap();
            for (i, q) in [pt.t_ry, pt.t_ru, pt.plant].iter().enumerate() {
                let e2 = (q.value - want[i]).norm_sqr();
                z[i][0] += e2 / q.variance;
                z[i][1] += e2;
            }
        }
        for (i, name) in ["t_ry", "t_ru", "plant"].iter().enumerate() {
            let mean_z = z[i][0] / seeds as f64;
            eprintln!("{noise:?} {name}: mean |err|²/var = {mean_z:.3}");
            // E[|e|²/σ̂²] = 1 (white, many dof), 16/15 for 16 complex bins
            assert!(
                (0.8..1.3).contains(&mean_z),
                "{noise:?} {name}: mean |err|²/var = {mean_z}"
            );
        }
    }
    // the plant: δY − P δU = v/(1+PC)·(1 + PC) = v exactly, so var P̂ = 4σ²/(n |U|²)
    let u_amp = 0.2 / (1.0 + p * c);
    let var_p = 4.0 * 0.05f64.powi(2) / (n as f64 * u_amp * u_amp);
    let measured = z[2][1] / seeds as f64;
    assert!(
        (measured / var_p - 1.0).abs() < 0.25,
        "{measured} vs {var_p}"
    );
}

#[test]
fn result_collects_points_and_converts_to_frd() {
    let (fs, n) = (1000.0, 500usize);
    let mut points = Vec::new();
    for m in [5usize, 20, 80] {
        let f = fs * m as f64 / n as f64;
        let r = sine(n, f, fs, 1.0, 0.0, 0.0);
        let u = sine(n, f, fs, 0.5, 0.1, 0.0);
        let y = sine(n, f, fs, 0.25, -0.4, 0.0);
        points.push(
            SinePoint::estimate(&r, &u, &y, f, fs, 0, n, NoiseEstimate::NeighbourBins(2)).unwrap(),
        );
    }
    let res = SteppedSineResult::from_points(&points);
    assert_eq!(res.f_hz, vec![10.0, 40.0, 160.0]);
    for (q, want) in [
        (Quantity::TRy, c64::from_polar(0.25, -0.4)),
        (Quantity::TRu, c64::from_polar(0.5, 0.1)),
        (Quantity::Plant, c64::from_polar(0.5, -0.5)),
    ] {
        let frd = res.to_frd(q, Some(1e-3)).unwrap();
        for v in frd.values() {
            assert!((v - want).norm() < 1e-12, "{q:?}");
        }
        assert!(frd.std().unwrap().iter().all(|s| *s < 1e-12));
    }
}

fn is_invalid(e: Error, name: &str) -> bool {
    matches!(e, Error::InvalidArgument { name: n, .. } if n == name)
}

#[test]
fn lock_in_rejects_bad_input() {
    let x = sine(100, 100.0, 1000.0, 1.0, 0.0, 0.0);
    for f in [500.0, 600.0, 0.0, -10.0, f64::NAN, f64::INFINITY] {
        assert!(
            is_invalid(lock_in(&x, f, 1000.0, 0, 100).unwrap_err(), "f_hz"),
            "{f}"
        );
    }
    for fs in [0.0, -1.0, f64::NAN] {
        assert!(is_invalid(
            lock_in(&x, 100.0, fs, 0, 100).unwrap_err(),
            "fs_hz"
        ));
    }
    assert!(is_invalid(
        lock_in(&x, 100.0, 1000.0, 0, 0).unwrap_err(),
        "n"
    ));
    assert!(is_invalid(
        lock_in(&x, 100.0, 1000.0, 1, 100).unwrap_err(),
        "start"
    ));
    assert!(is_invalid(
        lock_in(&x, 100.0, 1000.0, 100, 1).unwrap_err(),
        "start"
    ));
    assert!(is_invalid(
        lock_in(&x, 100.0, 1000.0, usize::MAX, 2).unwrap_err(),
        "start"
    ));
    let mut bad = x.clone();
    bad[42] = f64::NAN;
    assert_eq!(
        lock_in(&bad, 100.0, 1000.0, 10, 50).unwrap_err(),
        Error::NonFinite {
            what: "x",
            index: 42
        }
    );
    // outside the window a NaN does not matter
    assert!(lock_in(&bad, 100.0, 1000.0, 50, 50).is_ok());
    assert!(is_invalid(
        lock_in_stats(&x, 100.0, 1000.0, 0, 3).unwrap_err(),
        "n"
    ));
    // neighbour bins need whole cycles and usable bins
    let e = phasor_ratio(
        &x,
        &x,
        105.0,
        1000.0,
        0,
        100,
        NoiseEstimate::NeighbourBins(3),
    )
    .unwrap_err();
    assert!(is_invalid(e, "f_hz"));
    assert!(phasor_ratio(&x, &x, 105.0, 1000.0, 0, 100, NoiseEstimate::White).is_ok());
    let e = phasor_ratio(
        &x,
        &x,
        100.0,
        1000.0,
        0,
        100,
        NoiseEstimate::NeighbourBins(0),
    )
    .unwrap_err();
    assert!(is_invalid(e, "noise"));
    // one cycle: every neighbour is a harmonic
    let e = phasor_ratio(
        &x,
        &x,
        10.0,
        1000.0,
        0,
        100,
        NoiseEstimate::NeighbourBins(4),
    )
    .unwrap_err();
    assert!(is_invalid(e, "noise"));
    // less than one cycle in the window
    let e = phasor_ratio(
        &x,
        &x,
        1e-9,
        1000.0,
        0,
        100,
        NoiseEstimate::NeighbourBins(4),
    )
    .unwrap_err();
    assert!(is_invalid(e, "f_hz"));
    // zero denominator
    let zero = vec![0.0; 100];
    assert!(matches!(
        phasor_ratio(&x, &zero, 100.0, 1000.0, 0, 100, NoiseEstimate::White).unwrap_err(),
        Error::Numerical { .. }
    ));
    // channel names in SinePoint errors
    let mut y = x.clone();
    y[3] = f64::INFINITY;
    assert_eq!(
        SinePoint::estimate(&x, &x, &y, 100.0, 1000.0, 0, 100, NoiseEstimate::White).unwrap_err(),
        Error::NonFinite {
            what: "y",
            index: 3
        }
    );
}

#[test]
fn plan_rejects_bad_input() {
    let ok = Settle::Seconds(0.1);
    assert!(is_invalid(
        SteppedSinePlan::new(0.0, &[1.0], ok, 1, 0.0).unwrap_err(),
        "fs_hz"
    ));
    assert!(is_invalid(
        SteppedSinePlan::new(f64::NAN, &[1.0], ok, 1, 0.0).unwrap_err(),
        "fs_hz"
    ));
    assert!(is_invalid(
        SteppedSinePlan::new(1000.0, &[], ok, 1, 0.0).unwrap_err(),
        "freqs_hz"
    ));
    for f in [0.0, 500.0, 700.0, -3.0, f64::NAN] {
        assert!(
            is_invalid(
                SteppedSinePlan::new(1000.0, &[10.0, f], ok, 1, 0.0).unwrap_err(),
                "freqs_hz"
            ),
            "{f}"
        );
    }
    for s in [
        Settle::Seconds(-1.0),
        Settle::Cycles(f64::NAN),
        Settle::Seconds(f64::INFINITY),
    ] {
        assert!(is_invalid(
            SteppedSinePlan::new(1000.0, &[10.0], s, 1, 0.0).unwrap_err(),
            "settle"
        ));
    }
    assert!(is_invalid(
        SteppedSinePlan::new(1000.0, &[10.0], ok, 0, 0.0).unwrap_err(),
        "measure_cycles"
    ));
    assert!(is_invalid(
        SteppedSinePlan::new(1000.0, &[10.0], ok, 1, -0.1).unwrap_err(),
        "min_measure_s"
    ));
    assert!(is_invalid(
        SteppedSinePlan::new(1000.0, &[10.0], ok, 1, 1e300).unwrap_err(),
        "min_measure_s"
    ));
    assert!(SteppedSinePlan::new(1000.0, &[1e-9], ok, 1, 0.0).is_err());
    let plan = SteppedSinePlan::new(1000.0, &[10.0], ok, 1, 0.0).unwrap();
    assert!(is_invalid(plan.excitation(1, 1.0).unwrap_err(), "index"));
    assert!(is_invalid(
        plan.excitation(0, f64::NAN).unwrap_err(),
        "amplitude"
    ));
    // unsorted plans are fine, but not as Frd
    let plan = SteppedSinePlan::new(1000.0, &[100.0, 10.0], ok, 2, 0.0).unwrap();
    let pts: Vec<SinePoint> = (0..2)
        .map(|i| {
            let r = plan.excitation(i, 1.0).unwrap();
            plan.estimate_point(i, &r, &r, &r, NoiseEstimate::White)
                .unwrap()
        })
        .collect();
    assert!(SteppedSineResult::from_points(&pts)
        .to_frd(Quantity::Plant, None)
        .is_err());
}
