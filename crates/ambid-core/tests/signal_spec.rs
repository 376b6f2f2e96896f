//! The `ExcitationSpec` front: serde form, delegation, the report's text, `Excitation` helpers, and
//! "never panics" properties over hostile inputs.

use ambid_core::signal::{
    BandReport, ChirpSpec, Distribution, Excitation, ExcitationSpec, Grid, MultisineSpec,
    NoiseSpec, Phases, PrbsSpec, Sweep,
};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

fn all_specs() -> Vec<ExcitationSpec> {
    vec![
        PrbsSpec {
            order: 6,
            samples_per_bit: 2,
            periods: 3,
            amplitude: 0.5,
            offset: 0.1,
        }
        .into(),
        ChirpSpec {
            f0_hz: 1.0,
            f1_hz: 200.0,
            duration_s: 0.5,
            amplitude: 1.0,
            sweep: Sweep::Logarithmic,
            periods: 2,
        }
        .into(),
        NoiseSpec {
            distribution: Distribution::Uniform,
            rms: 0.3,
            n_samples: 777,
            band_hz: Some((10.0, 100.0)),
            seed: 12,
        }
        .into(),
        MultisineSpec {
            f_min_hz: 2.0,
            f_max_hz: 300.0,
            period_samples: 1000,
            periods: 2,
            rms: 0.05,
            grid: Grid::RandomOdd,
            phases: Phases::Random,
            seed: 4,
        }
        .into(),
    ]
}

#[test]
fn json_round_trip_and_tag() {
    let kinds = ["prbs", "chirp", "noise", "multisine"];
    for (spec, kind) in all_specs().into_iter().zip(kinds) {
        let json = serde_json::to_string(&spec).unwrap();
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert_eq!(v["kind"], kind, "{json}");
        let back: ExcitationSpec = serde_json::from_str(&json).unwrap();
        assert_eq!(back, spec);
    }
    let json = r#"{"kind":"multisine","f_min_hz":1,"f_max_hz":10,"period_samples":100,"periods":1,
                   "rms":1,"grid":"random_odd","phases":"schroeder","seed":0}"#;
    let spec: ExcitationSpec = serde_json::from_str(json).unwrap();
    assert!(matches!(
        spec,
        ExcitationSpec::Multisine(MultisineSpec {
            grid: Grid::RandomOdd,
            phases: Phases::Schroeder,
            ..
        })
    ));
    let chirp = r#"{"kind":"chirp","f0_hz":1,"f1_hz":10,"duration_s":1,"amplitude":1,
                    "sweep":"logarithmic","periods":1}"#;
    assert!(serde_json::from_str::<ExcitationSpec>(chirp).is_ok());
    let bad = r#"{"kind":"square","order":3}"#;
    assert!(serde_json::from_str::<ExcitationSpec>(bad).is_err());
}

#[test]
fn enum_delegates_to_the_specs() {
    let ts = 1e-3;
    for spec in all_specs() {
        let (x, r) = (spec.generate(ts).unwrap(), spec.report(ts).unwrap());
        let (x2, r2) = match &spec {
            ExcitationSpec::Prbs(s) => (s.generate(ts).unwrap(), s.report(ts).unwrap()),
            ExcitationSpec::Chirp(s) => (s.generate(ts).unwrap(), s.report(ts).unwrap()),
            ExcitationSpec::Noise(s) => (s.generate(ts).unwrap(), s.report(ts).unwrap()),
            ExcitationSpec::Multisine(s) => (s.generate(ts).unwrap(), s.report(ts).unwrap()),
        };
        assert_eq!(x, x2);
        assert_eq!(r, r2);
        // The report describes the generated signal.
        assert_eq!(r.n_samples, x.len());
        assert_eq!(r.period_samples, x.period_samples);
        assert_eq!(r.periods, x.periods);
        assert!((r.duration_s - x.duration_s()).abs() < 1e-12);
        assert_eq!(x.ts, ts);
        assert!(r.f_min_hz > 0.0 && r.f_min_hz <= r.f_max_hz && r.f_max_hz <= 0.5 / ts + 1e-9);
        assert!(r.resolution_hz > 0.0);
        assert!(r.rms > 0.0 && r.peak >= r.rms && (r.crest_factor - r.peak / r.rms).abs() < 1e-12);
    }
}

#[test]
fn report_display_and_serialize() {
    let r = PrbsSpec::default().report(50e-6).unwrap();
    let text = r.to_string();
    assert!(text.lines().count() >= 5, "{text}");
    for needle in [
        "band",
        "resolution",
        "3.910",
        "2000",
        "5.115",
        "5115",
        "20 periods",
        "crest factor",
    ] {
        assert!(text.contains(needle), "missing {needle:?} in\n{text}");
    }
    let v: serde_json::Value = serde_json::to_value(&r).unwrap();
    assert_eq!(v["period_samples"], 5115);
    let back: BandReport = serde_json::from_value(v).unwrap();
    assert_eq!(back, r);
}

#[test]
fn excitation_helpers() {
    let x = Excitation {
        values: vec![1.0, 2.0, 3.0, 1.0, 2.0, 3.0],
        ts: 0.5,
        period_samples: 3,
        periods: 2,
    };
    assert_eq!(x.len(), 6);
    assert!(!x.is_empty());
    assert_eq!(x.duration_s(), 3.0);
    assert_eq!(x.fs_hz(), 2.0);
    assert_eq!(x.period(1), Some(&[1.0, 2.0, 3.0][..]));
    assert_eq!(x.period(2), None);
    assert_eq!(x.period(usize::MAX), None);
    assert_eq!(x.times(), vec![0.0, 0.5, 1.0, 1.5, 2.0, 2.5]);
}

fn hostile_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        -2.0f64..2.0,
        Just(0.0),
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(-f64::INFINITY),
        Just(f64::MIN_POSITIVE),
        Just(1e300),
    ]
}

fn hostile_ts() -> impl Strategy<Value = f64> {
    prop_oneof![
        1e-3f64..0.1,
        Just(0.0),
        Just(-1e-3),
        Just(f64::NAN),
        Just(f64::INFINITY),
    ]
}

proptest! {
    // Fixed seed: CI runs are reproducible (a failure names its input; add it as a plain test).
    #![proptest_config(ProptestConfig {
        cases: 200,
        rng_seed: RngSeed::Fixed(0x5167_2026),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// Any PRBS design is either reported or refused with an error; generation succeeds exactly
    /// when the report does and the design is small.
    #[test]
    fn prbs_never_panics(order in 0u32..40, nb in 0usize..8, np in 0usize..4,
                         amplitude in hostile_f64(), offset in hostile_f64(), ts in hostile_ts()) {
        let spec = PrbsSpec { order, samples_per_bit: nb, periods: np, amplitude, offset };
        let r = spec.report(ts);
        if order <= 12 {
            let g = spec.generate(ts);
            prop_assert_eq!(r.is_ok(), g.is_ok());
            if let (Ok(r), Ok(g)) = (r, g) {
                prop_assert_eq!(r.n_samples, g.len());
            }
        }
    }

    #[test]
    fn chirp_never_panics(f0 in hostile_f64(), f1 in hostile_f64(), dur in hostile_f64(),
                          amplitude in hostile_f64(), log in any::<bool>(), periods in 0usize..3,
                          ts in hostile_ts()) {
        let spec = ChirpSpec { f0_hz: f0 * 10.0, f1_hz: f1 * 10.0, duration_s: dur, amplitude,
                               sweep: if log { Sweep::Logarithmic } else { Sweep::Linear }, periods };
        if let Ok(x) = spec.generate(ts) {
            prop_assert!(x.values.iter().all(|v| v.is_finite() && v.abs() <= amplitude * (1.0 + 1e-12)));
        }
        let _ = spec.report(ts);
        let _ = spec.instantaneous_frequency_hz(dur);
    }

    #[test]
    fn noise_never_panics(rms in hostile_f64(), n in 0usize..300, lo in hostile_f64(), hi in hostile_f64(),
                          band in any::<bool>(), gauss in any::<bool>(), seed in any::<u64>(),
                          ts in hostile_ts()) {
        let spec = NoiseSpec {
            distribution: if gauss { Distribution::Gaussian } else { Distribution::Uniform },
            rms, n_samples: n, band_hz: band.then_some((lo * 5.0, hi * 5.0)), seed,
        };
        if let Ok(x) = spec.generate(ts) {
            prop_assert_eq!(x.len(), n);
            prop_assert!(x.values.iter().all(|v| v.is_finite()));
        }
        let _ = spec.report(ts);
    }

    #[test]
    fn multisine_never_panics(lo in hostile_f64(), hi in hostile_f64(), n in 0usize..300,
                              periods in 0usize..3, rms in hostile_f64(), grid in 0u8..3,
                              random in any::<bool>(), seed in any::<u64>(), ts in hostile_ts()) {
        let spec = MultisineSpec {
            f_min_hz: lo * 5.0, f_max_hz: hi * 5.0, period_samples: n, periods, rms,
            grid: [Grid::Full, Grid::Odd, Grid::RandomOdd][grid as usize],
            phases: if random { Phases::Random } else { Phases::Schroeder }, seed,
        };
        if let Ok(x) = spec.generate(ts) {
            prop_assert_eq!(x.len(), n * periods);
            // exact RMS wherever the samples stay normal floats (not at subnormal levels ~1e-308)
            if rms > 1e-290 {
                let r = ambid_core::signal::rms(x.period(0).unwrap()).unwrap();
                prop_assert!((r - rms).abs() <= 1e-9 * rms);
            }
        }
        let _ = spec.report(ts);
        let _ = spec.lines(ts);
    }
}

/// Found by the property test above with a random seed: a multisine at the smallest normal RMS
/// level generates (its samples are subnormal, so the RMS is not exact) and does not panic.
#[test]
fn multisine_at_the_smallest_normal_level_generates() {
    let spec = MultisineSpec {
        f_min_hz: 1e-307,
        f_max_hz: 6.82,
        period_samples: 4,
        periods: 1,
        rms: f64::MIN_POSITIVE,
        grid: Grid::Full,
        phases: Phases::Schroeder,
        seed: 0,
    };
    let ts = 0.052534678978579885;
    if let Ok(x) = spec.generate(ts) {
        assert!(x.values.iter().all(|v| v.is_finite()));
    }
}
