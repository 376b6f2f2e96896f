//! Preprocessing of measured data (`ambid_core::data`) against oracles: a naive least-squares line,
//! injected spikes at known places, analytic clip fractions, and every error path.

use ambid_core::data::{
    check_saturation, detrend, drop_transient, find_abnormal, hampel, repair_abnormal,
    segment_data, segment_periods, stuck_runs, AbnormalOptions, Detrend, HampelOptions, IoData,
    LimitSource, Repair, SaturationOptions, SegmentOptions,
};
use ambid_core::signal::PrbsSpec;
use ambid_core::Error;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use std::f64::consts::PI;

fn gaussian(n: usize, sigma: f64, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| sigma * rng.sample::<f64, _>(StandardNormal))
        .collect()
}

fn noisy_sine(n: usize, period: f64, amp: f64, sigma: f64, seed: u64) -> Vec<f64> {
    gaussian(n, sigma, seed)
        .into_iter()
        .enumerate()
        .map(|(k, e)| amp * (2.0 * PI * k as f64 / period).sin() + e)
        .collect()
}

/// A raw PRBS of order 10 from the crate's generator, `nb` samples per bit, plus noise.
fn noisy_prbs(n: usize, nb: usize, sigma: f64, seed: u64) -> Vec<f64> {
    let spec = PrbsSpec {
        order: 10,
        samples_per_bit: nb,
        periods: n.div_ceil(1023 * nb),
        amplitude: 1.0,
        offset: 0.0,
    };
    let r = spec.generate(1e-4).unwrap().values;
    r[..n]
        .iter()
        .zip(gaussian(n, sigma, seed))
        .map(|(a, e)| a + e)
        .collect()
}

/// The PRBS through a lightly damped second-order low-pass (a plant-like response), plus noise.
fn resonant_response(n: usize, nb: usize, sigma: f64, seed: u64) -> Vec<f64> {
    let r = noisy_prbs(n, nb, 0.0, 0);
    // Poles at radius ρ, angle θ: y_k = 2ρ cos θ y_{k-1} - ρ² y_{k-2} + g r_k, unit DC gain.
    let (rho, theta) = (0.995_f64, 2.0 * PI * 300.0 / 20_000.0);
    let (a1, a2) = (2.0 * rho * theta.cos(), -rho * rho);
    let g = 1.0 - a1 - a2;
    let mut y = vec![0.0; n];
    for k in 0..n {
        let y1 = if k >= 1 { y[k - 1] } else { 0.0 };
        let y2 = if k >= 2 { y[k - 2] } else { 0.0 };
        y[k] = a1 * y1 + a2 * y2 + g * r[k];
    }
    y.iter()
        .zip(gaussian(n, sigma, seed))
        .map(|(a, e)| a + e)
        .collect()
}

// ---------------------------------------------------------------------------------------------
// detrend

/// Naive oracle: the raw 2×2 normal equations in Σk, Σk², Σx, Σkx, solved by Cramer's rule.
fn naive_line(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let (mut sk, mut skk, mut sx, mut skx) = (0.0, 0.0, 0.0, 0.0);
    for (k, v) in x.iter().enumerate() {
        let k = k as f64;
        sk += k;
        skk += k * k;
        sx += v;
        skx += k * v;
    }
    let det = n * skk - sk * sk;
    let a = (skk * sx - sk * skx) / det;
    let b = (n * skx - sk * sx) / det;
    (a, b)
}

#[test]
fn detrend_matches_naive_least_squares() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for n in [2usize, 3, 10, 257, 4096] {
        let x: Vec<f64> = (0..n)
            .map(|k| 0.3 - 2e-3 * k as f64 + rng.random_range(-1.0..1.0))
            .collect();
        let (a, b) = naive_line(&x);
        let (d, rep) = detrend(&x, Detrend::Linear).unwrap();
        assert!(
            (rep.offset - a).abs() < 1e-9,
            "n={n}: {} vs {a}",
            rep.offset
        );
        assert!((rep.slope - b).abs() < 1e-11, "n={n}: {} vs {b}", rep.slope);
        for (k, (dv, xv)) in d.iter().zip(&x).enumerate() {
            assert!((dv - (xv - a - b * k as f64)).abs() < 1e-9);
        }
        let (m, rep) = detrend(&x, Detrend::Mean).unwrap();
        let mean = x.iter().sum::<f64>() / n as f64;
        assert!((rep.offset - mean).abs() < 1e-12 && rep.slope == 0.0);
        assert!(m.iter().sum::<f64>().abs() < 1e-9);
    }
}

#[test]
fn detrend_is_exact_on_a_pure_line() {
    // Large offset, small slope, long record: the centred formula keeps full accuracy.
    let n = 100_000;
    let (a, b) = (1.0e3, -3.0e-6);
    let x: Vec<f64> = (0..n).map(|k| a + b * k as f64).collect();
    let (d, rep) = detrend(&x, Detrend::Linear).unwrap();
    let worst = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(worst < 1e-9, "largest residual {worst}");
    assert!((rep.offset - a).abs() < 1e-9 && (rep.slope - b).abs() < 1e-15);
}

// ---------------------------------------------------------------------------------------------
// spikes

#[test]
fn hampel_finds_injected_spikes_exactly() {
    let n = 100_000;
    let sigma = 0.01;
    let mut x = noisy_sine(n, 2000.0, 1.0, sigma, 1);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut injected = Vec::new();
    while injected.len() < 60 {
        let i = rng.random_range(0..n - 1);
        if injected.iter().any(|&j: &usize| j.abs_diff(i) < 12) {
            continue;
        }
        let sign = if rng.random_range(0..2) == 0 {
            -1.0
        } else {
            1.0
        };
        // Single spikes and, every fifth time, a two-sample burst; 30σ to 100σ.
        x[i] += sign * rng.random_range(0.3..1.0);
        injected.push(i);
        if injected.len() % 5 == 0 {
            x[i + 1] -= sign * rng.random_range(0.3..1.0);
            injected.push(i + 1);
        }
    }
    injected.sort_unstable();
    let found = hampel(&x, &HampelOptions::default()).unwrap();
    assert_eq!(found, injected);
    // The first and last judged samples (w from each end); the ends themselves are not judged.
    let mut y = noisy_sine(1000, 2000.0, 1.0, sigma, 3);
    for i in [0, 5, 994, 999] {
        y[i] += 0.5;
    }
    assert_eq!(hampel(&y, &HampelOptions::default()).unwrap(), vec![5, 994]);
}

#[test]
fn hampel_has_no_false_positives_on_clean_signals() {
    let n = 100_000;
    let opts = HampelOptions::default();
    let signals = [
        ("white noise", gaussian(n, 1.0, 21)),
        ("slow sine + noise", noisy_sine(n, 1000.0, 10.0, 0.1, 22)),
        ("fast sine + noise", noisy_sine(n, 7.3, 1.0, 0.01, 23)),
        ("raw PRBS, 6 samples/bit", noisy_prbs(n, 6, 0.05, 24)),
        ("resonant PRBS response", resonant_response(n, 5, 0.01, 25)),
        (
            "resonant PRBS response, low noise",
            resonant_response(n, 5, 1e-5, 26),
        ),
    ];
    for (name, x) in &signals {
        let found = hampel(x, &opts).unwrap();
        assert!(
            found.is_empty(),
            "{name}: {} false alarms, first {:?}",
            found.len(),
            &found[..found.len().min(5)]
        );
    }
    // The seed paper's 5 samples per bit needs a half-window of at most 4 ...
    let x = noisy_prbs(n, 5, 0.05, 27);
    let w4 = HampelOptions {
        half_window: 4,
        ..opts
    };
    assert!(hampel(&x, &w4).unwrap().is_empty());
    // ... because with w = 5 an isolated bit is a plateau of w samples: a spike by definition
    // (documented limitation).
    assert!(hampel(&x, &opts).unwrap().len() > 100);
}

#[test]
fn without_the_floor_the_rule_raises_false_alarms_on_noise() {
    // Why the global floor is on by default: the MAD of 10 or 11 samples is often small by chance.
    let n = 100_000;
    let x = gaussian(n, 1.0, 31);
    let no_floor = HampelOptions {
        global_floor: false,
        ..HampelOptions::default()
    };
    let rate = hampel(&x, &no_floor).unwrap().len() as f64 / n as f64;
    println!("false-alarm rate without the floor: {rate}");
    assert!(rate > 1e-3 && rate < 3e-2, "false-alarm rate {rate}");
}

#[test]
fn hampel_on_a_million_samples_is_linear_time() {
    // O(N w): a million samples with w = 5 take a fraction of a second even at opt-level 1.
    let n = 1_000_000;
    let mut x = noisy_sine(n, 5000.0, 1.0, 0.01, 41);
    x[500_000] += 1.0;
    let t = std::time::Instant::now();
    let found = hampel(&x, &HampelOptions::default()).unwrap();
    let dt = t.elapsed().as_secs_f64();
    println!("hampel, w = 5, on 1e6 samples: {dt:.3} s");
    assert_eq!(found, vec![500_000]);
    assert!(dt < 5.0, "hampel took {dt} s on 1e6 samples");
}

// ---------------------------------------------------------------------------------------------
// repair, stuck runs

#[test]
fn nan_repair_by_interpolation_is_exact_on_a_line() {
    let n = 500;
    let line: Vec<f64> = (0..n).map(|k| -2.0 + 0.013 * k as f64).collect();
    let mut x = line.clone();
    for &i in &[3usize, 4, 5, 100, 250, 251, 252, 253, 399] {
        x[i] = f64::NAN;
    }
    x[300] = f64::INFINITY;
    x[301] = f64::NEG_INFINITY;
    x[200] += 5.0; // a spike is repaired the same way
    let (y, rep) = repair_abnormal(&x, &AbnormalOptions::default()).unwrap();
    assert_eq!(
        rep.nonfinite,
        vec![3, 4, 5, 100, 250, 251, 252, 253, 300, 301, 399]
    );
    assert_eq!(rep.spikes, vec![200]);
    assert_eq!(rep.repaired, 12);
    for (k, (a, b)) in y.iter().zip(&line).enumerate() {
        assert!((a - b).abs() < 1e-12, "sample {k}: {a} vs {b}");
    }
    assert!(rep.summary().contains("12 samples repaired"));
}

#[test]
fn stuck_runs_are_found_and_saturation_is_not_stuck() {
    let n = 20_000;
    let mut x = noisy_sine(n, 500.0, 1.0, 0.01, 51);
    x[1000..1040].fill(0.25); // stuck sensor, mid-range
    x[5000..5019].fill(-0.1); // too short (19 < 20)
    let held = x[8000];
    x[8000..8200].fill(held); // long stuck run
    let max = x.iter().copied().fold(f64::NEG_INFINITY, f64::max) + 0.5;
    x[12_000..12_050].fill(max); // flat top at the record's maximum: saturation
    let runs = stuck_runs(&x, 20).unwrap();
    assert_eq!(runs, vec![(1000, 40), (8000, 200)]);
    let rep = find_abnormal(&x, &AbnormalOptions::default()).unwrap();
    assert_eq!(rep.stuck_runs, runs);
    assert!(rep.spikes.is_empty(), "{:?}", rep.spikes);
    let sat = check_saturation(&x, None, &SaturationOptions::default()).unwrap();
    assert_eq!(sat.runs, vec![(12_000, 50)]);
    // Stuck runs are reported, never repaired, and Fail refuses them.
    let (y, rep) = repair_abnormal(&x, &AbnormalOptions::default()).unwrap();
    assert_eq!(y, x);
    assert!(rep.summary().contains("not repaired"));
    let fail = AbnormalOptions {
        repair: Repair::Fail,
        ..AbnormalOptions::default()
    };
    let e = repair_abnormal(&x, &fail).unwrap_err().to_string();
    assert!(e.contains("2 stuck runs"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// saturation

#[test]
fn saturation_fraction_is_exact_on_clipped_sines() {
    let n = 100_000;
    let period = 97.3; // not a divisor: the clipped stretches vary in length
    let amp = 2.0;
    let theta = |k: usize| 2.0 * PI * k as f64 / period + 0.1;
    for c in [0.5, 1.0, 1.5, 1.9] {
        let x: Vec<f64> = (0..n)
            .map(|k| (amp * theta(k).sin()).clamp(-c, c))
            .collect();
        // Naive oracle: samples whose unclipped value reaches the limit.
        let naive = (0..n)
            .filter(|&k| (amp * theta(k).sin()).abs() >= c)
            .count();
        let given = check_saturation(&x, Some(c), &SaturationOptions::default()).unwrap();
        assert_eq!(given.count, naive, "c = {c}");
        assert_eq!(given.source, LimitSource::Given);
        assert_eq!((given.upper, given.lower), (Some(c), Some(-c)));
        // Analytic share of time with |sin| >= c/A.
        let analytic = 1.0 - 2.0 / PI * (c / amp).asin();
        assert!(
            (given.fraction - analytic).abs() < 2e-3,
            "c = {c}: {} vs {analytic}",
            given.fraction
        );
        let expected_runs: usize = given.runs.iter().map(|r| r.1).sum();
        assert_eq!(expected_runs, given.count);
        // Detected without the limit: the flat tops are long enough at these levels.
        let found = check_saturation(&x, None, &SaturationOptions::default()).unwrap();
        assert_eq!(found.source, LimitSource::Detected);
        assert_eq!(found.count, naive, "c = {c}");
        assert_eq!((found.upper, found.lower), (Some(c), Some(-c)));
        assert!(found.summary().contains("likely clipping"));
    }
    // The unclipped sine shows no flat top.
    let x: Vec<f64> = (0..n).map(|k| amp * theta(k).sin()).collect();
    let found = check_saturation(&x, None, &SaturationOptions::default()).unwrap();
    assert_eq!((found.count, found.upper, found.lower), (0, None, None));
}

// ---------------------------------------------------------------------------------------------
// segmentation, transient

#[test]
fn periodic_segmentation_of_a_prbs_record() {
    let spec = PrbsSpec {
        order: 6,
        samples_per_bit: 3,
        periods: 7,
        amplitude: 1.0,
        offset: 0.0,
    };
    let r = spec.generate(1e-3).unwrap();
    let p = r.period_samples;
    let mut values = r.values.clone();
    values.extend_from_slice(&r.values[..17]); // an incomplete eighth period
    let data = IoData::new(vec![("r".into(), values)], r.ts, Some(p)).unwrap();
    let (cut, seg) = segment_data(&data, 2, &SegmentOptions::default()).unwrap();
    assert_eq!((seg.start, seg.periods, seg.dropped_tail), (2 * p, 5, 17));
    for q in 0..seg.periods {
        assert_eq!(
            seg.period(data.channel("r").unwrap(), q).unwrap(),
            r.period(0).unwrap()
        );
    }
    assert_eq!(cut.len(), 5 * p);
    let strict = SegmentOptions {
        strict: true,
        ..SegmentOptions::default()
    };
    assert!(segment_data(&data, 2, &strict).is_err());
    let (kept, t) = drop_transient(&data, 100).unwrap();
    assert_eq!((kept.len(), t.dropped), (data.len() - 100, 100));
}

// ---------------------------------------------------------------------------------------------
// error paths

fn is_invalid(r: &Result<impl std::fmt::Debug, Error>) -> bool {
    matches!(r, Err(Error::InvalidArgument { .. }))
}

#[test]
fn every_error_path() {
    let o = AbnormalOptions::default();
    // Empty input.
    assert!(is_invalid(&detrend(&[], Detrend::Linear)));
    assert!(is_invalid(&hampel(&[], &HampelOptions::default())));
    assert!(is_invalid(&stuck_runs(&[], 20)));
    assert!(is_invalid(&find_abnormal(&[], &o)));
    assert!(is_invalid(&repair_abnormal(&[], &o)));
    assert!(is_invalid(&check_saturation(
        &[],
        None,
        &SaturationOptions::default()
    )));
    assert!(IoData::new(vec![("y".into(), vec![])], 1.0, None).is_err());
    assert!(IoData::new(vec![], 1.0, None).is_err());
    // NaN where forbidden.
    assert!(matches!(
        detrend(&[1.0, f64::NAN, 2.0], Detrend::Mean),
        Err(Error::NonFinite { index: 1, .. })
    ));
    assert!(matches!(
        check_saturation(
            &[f64::NEG_INFINITY],
            Some(1.0),
            &SaturationOptions::default()
        ),
        Err(Error::NonFinite { index: 0, .. })
    ));
    assert!(IoData::new(vec![("y".into(), vec![1.0])], f64::NAN, None).is_err());
    // Window too long.
    let e = hampel(&[0.0; 10], &HampelOptions::default()).unwrap_err();
    assert!(e.to_string().contains("longer than the record"), "{e}");
    assert!(is_invalid(&find_abnormal(&[0.0; 10], &o)));
    // Period longer than the record.
    let e = segment_periods(100, 101, 0, &SegmentOptions::default()).unwrap_err();
    assert!(e.to_string().contains("longer than the record"), "{e}");
    // Not a whole number of periods in strict mode; the message names the fix.
    let strict = SegmentOptions {
        strict: true,
        ..SegmentOptions::default()
    };
    let e = segment_periods(1050, 100, 0, &strict)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("--period-samples") && e.contains("trim the record to 1000"),
        "{e}"
    );
    // Fewer periods than required, period 0.
    assert!(is_invalid(&segment_periods(
        1050,
        100,
        10,
        &SegmentOptions::default()
    )));
    assert!(is_invalid(&segment_periods(
        1050,
        0,
        0,
        &SegmentOptions::default()
    )));
    // Gap too long to interpolate, Fail on a NaN.
    let mut x: Vec<f64> = (0..100).map(f64::from).collect();
    x[40..60].fill(f64::NAN);
    let e = repair_abnormal(&x, &o).unwrap_err().to_string();
    assert!(e.contains("40..60") && e.contains("max_gap"), "{e}");
    let fail = AbnormalOptions {
        repair: Repair::Fail,
        ..o
    };
    assert!(is_invalid(&repair_abnormal(&x, &fail)));
    // Unknown channel, out-of-range slice, transient eating the record.
    let d = IoData::new(vec![("y".into(), vec![0.0; 10])], 1.0, Some(3)).unwrap();
    assert!(d.channel("u").unwrap_err().to_string().contains("`y`"));
    assert!(d.slice(5, 11).is_err());
    assert!(drop_transient(&d, 10).is_err());
    // Saturation options.
    let bad = SaturationOptions {
        rel_tol: 2.0,
        ..SaturationOptions::default()
    };
    assert!(is_invalid(&check_saturation(&[1.0], Some(1.0), &bad)));
}
