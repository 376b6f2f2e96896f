//! PRBS: maximal period for every order, balance, two-valued autocorrelation, the seed-paper design,
//! spectrum shape, report consistency and typed errors.
//!
//! Oracles: GF(2) polynomial arithmetic written here (primitivity: $x^{2^n-1} \equiv 1$ and
//! $x^{(2^n-1)/q} \not\equiv 1 \bmod p$ for every prime $q \mid 2^n-1$), full register runs, integer
//! autocorrelation sums, and the closed-form m-sequence spectrum $|X_k|^2 = L+1$.

use ambid_core::signal::prbs::{feedback_polynomial, prbs_length};
use ambid_core::signal::{
    amplitude_spectrum, autocorrelation, crest_factor, prbs_period, rms, Lfsr, PrbsSpec,
    MAX_PRBS_ORDER, MAX_SAMPLES, MIN_PRBS_ORDER,
};
use ambid_core::Error;

// ------------------------------------------------------------------------------------------------
// GF(2)[x] arithmetic on bit masks (bit i = coefficient of x^i), degree < 64.

fn gf2_mulmod(mut a: u64, mut b: u64, p: u64, n: u32) -> u64 {
    // a, b already reduced (degree < n); p has degree n.
    let mut r = 0u64;
    while b != 0 {
        if b & 1 == 1 {
            r ^= a;
        }
        b >>= 1;
        a <<= 1;
        if (a >> n) & 1 == 1 {
            a ^= p;
        }
    }
    r
}

/// x^e mod p.
fn gf2_xpow(mut e: u64, p: u64, n: u32) -> u64 {
    let mut base = 0b10u64; // x (n >= 2, so already reduced)
    let mut r = 1u64;
    while e > 0 {
        if e & 1 == 1 {
            r = gf2_mulmod(r, base, p, n);
        }
        base = gf2_mulmod(base, base, p, n);
        e >>= 1;
    }
    r
}

fn prime_factors(mut m: u64) -> Vec<u64> {
    let mut f = Vec::new();
    let mut d = 2u64;
    while d * d <= m {
        if m % d == 0 {
            f.push(d);
            while m % d == 0 {
                m /= d;
            }
        }
        d += 1;
    }
    if m > 1 {
        f.push(m);
    }
    f
}

#[test]
fn gf2_helpers_sanity() {
    // x^2 + x + 1 is primitive; x^4 + x^3 + x^2 + x + 1 is irreducible but not primitive (order 5).
    assert_eq!(gf2_xpow(3, 0b111, 2), 1);
    assert_eq!(gf2_xpow(1, 0b111, 2), 0b10);
    assert_eq!(gf2_xpow(5, 0b11111, 4), 1);
    assert_eq!(gf2_xpow(15 / 3, 0b11111, 4), 1); // so the primitivity test rejects it
    assert_eq!(prime_factors((1 << 11) - 1), vec![23, 89]);
    assert_eq!(prime_factors((1 << 31) - 1), vec![(1 << 31) - 1]);
}

#[test]
fn every_feedback_polynomial_is_primitive() {
    for n in MIN_PRBS_ORDER..=MAX_PRBS_ORDER {
        let p = feedback_polynomial(n).unwrap();
        assert_eq!(63 - p.leading_zeros(), n, "degree of order {n}");
        assert_eq!(p & 1, 1, "constant term of order {n}");
        let l = (1u64 << n) - 1;
        assert_eq!(gf2_xpow(l, p, n), 1, "x^(2^{n}-1) != 1 mod p for order {n}");
        for q in prime_factors(l) {
            assert_ne!(
                gf2_xpow(l / q, p, n),
                1,
                "order {n}: x^((2^n-1)/{q}) == 1, p is not primitive"
            );
        }
    }
}

#[test]
fn full_register_runs_have_period_2n_minus_1_and_balance() {
    for n in MIN_PRBS_ORDER..=22 {
        let mut r = Lfsr::new(n).unwrap();
        let start = r.state();
        let l = (1u64 << n) - 1;
        let mut ones = 0u64;
        let mut steps = 0u64;
        loop {
            ones += r.next_bit() as u64;
            steps += 1;
            if r.state() == start || steps > l {
                break;
            }
        }
        assert_eq!(steps, l, "period of order {n}");
        // 2^(n-1) ones and 2^(n-1) - 1 zeros: one more +1 than -1.
        assert_eq!(ones, 1u64 << (n - 1), "ones in order {n}");
        assert_eq!(prbs_length(n).unwrap() as u64, l);
    }
}

#[test]
fn prbs_period_matches_register_and_is_balanced() {
    for n in MIN_PRBS_ORDER..=16 {
        let s = prbs_period(n).unwrap();
        assert_eq!(s.len(), (1usize << n) - 1);
        assert_eq!(s.iter().map(|&v| v as i64).sum::<i64>(), 1, "order {n}");
        let bits: Vec<i8> = Lfsr::new(n)
            .unwrap()
            .take(2 * s.len())
            .map(|b| if b { 1 } else { -1 })
            .collect();
        assert_eq!(&bits[..s.len()], &s[..]);
        assert_eq!(&bits[s.len()..], &s[..], "order {n} repeats after L");
    }
}

#[test]
fn circular_autocorrelation_is_two_valued_integer_oracle() {
    // Exact integer sums: sum_k s_k s_{k+tau} = L at tau = 0 and -1 elsewhere.
    for n in MIN_PRBS_ORDER..=10 {
        let s = prbs_period(n).unwrap();
        let l = s.len();
        for tau in 0..l {
            let r: i64 = (0..l).map(|k| (s[k] * s[(k + tau) % l]) as i64).sum();
            assert_eq!(
                r,
                if tau == 0 { l as i64 } else { -1 },
                "order {n} lag {tau}"
            );
        }
    }
}

#[test]
fn circular_autocorrelation_is_two_valued_fft() {
    // Through the library's FFT path (tested against a naive oracle in the unit tests).
    for n in 2..=20 {
        let s: Vec<f64> = prbs_period(n).unwrap().iter().map(|&v| v as f64).collect();
        let l = s.len();
        let r = autocorrelation(&s, l - 1, true).unwrap();
        assert!((r[0] - 1.0).abs() < 1e-12);
        let want = -1.0 / l as f64;
        let worst = r[1..].iter().fold(0.0f64, |m, v| m.max((v - want).abs()));
        assert!(worst < 1e-9, "order {n}: worst deviation {worst}");
    }
}

#[test]
fn seed_paper_design() {
    // n = 10, Ts = 50 us, Nb = 5, Np = 20 (seed paper, Section 4).
    let spec = PrbsSpec {
        order: 10,
        samples_per_bit: 5,
        periods: 20,
        amplitude: 0.1,
        offset: 0.0,
    };
    assert_eq!(
        spec,
        PrbsSpec {
            amplitude: 0.1,
            ..PrbsSpec::default()
        }
    );
    let ts = 50e-6;
    let r = spec.report(ts).unwrap();
    assert_eq!(r.period_samples, 5115);
    assert_eq!(r.periods, 20);
    assert_eq!(r.n_samples, 102_300);
    assert!(
        (r.resolution_hz - 3.91).abs() < 0.005,
        "{}",
        r.resolution_hz
    );
    assert!((r.resolution_hz - 1.0 / (5115.0 * 50e-6)).abs() < 1e-9);
    assert_eq!(r.f_min_hz, r.resolution_hz);
    assert!((r.f_max_hz - 2000.0).abs() < 1e-9);
    assert!((r.duration_s - 5.115).abs() < 1e-9);
    assert!((r.duration_s - 5.1).abs() < 0.02);
    assert!((r.crest_factor - 1.0).abs() < 1e-12);

    let x = spec.generate(ts).unwrap();
    assert_eq!(x.len(), 102_300);
    assert_eq!((x.period_samples, x.periods), (5115, 20));
    assert!((x.duration_s() - r.duration_s).abs() < 1e-12);
    // Every bit is held for exactly Nb samples and the periods repeat.
    let p0 = x.period(0).unwrap().to_vec();
    for b in 0..1023 {
        let chunk = &p0[5 * b..5 * b + 5];
        assert!(chunk.iter().all(|&v| v == chunk[0]));
    }
    let bits = prbs_period(10).unwrap();
    for (b, &s) in bits.iter().enumerate() {
        assert_eq!(p0[5 * b], 0.1 * s as f64);
    }
    for p in 1..20 {
        assert_eq!(x.period(p).unwrap(), &p0[..]);
    }
    assert!(x.period(20).is_none());
}

#[test]
fn one_bit_per_sample_spectrum_is_flat() {
    // For an m-sequence |X_k|^2 = L + 1 for k != 0 and X_0 = 1.
    let n = 9;
    let s: Vec<f64> = prbs_period(n).unwrap().iter().map(|&v| v as f64).collect();
    let l = s.len() as f64;
    let (_, a) = amplitude_spectrum(&s, 1e-3).unwrap();
    assert!((a[0] - 1.0 / l).abs() < 1e-12);
    let want = 2.0 * (l + 1.0).sqrt() / l;
    for (k, v) in a.iter().enumerate().skip(1) {
        assert!((v - want).abs() < 1e-12, "bin {k}: {v} vs {want}");
    }
}

#[test]
fn held_bits_put_a_spectral_null_at_the_bit_rate() {
    let spec = PrbsSpec {
        order: 7,
        samples_per_bit: 5,
        periods: 1,
        amplitude: 1.0,
        offset: 0.0,
    };
    let ts = 1e-3;
    let x = spec.generate(ts).unwrap();
    let (f, a) = amplitude_spectrum(&x.values, ts).unwrap();
    let l = 127;
    // Null at f = 1/(Nb Ts) = 200 Hz = bin L; f_max = 100 Hz is half of it.
    assert!((f[l] - 200.0).abs() < 1e-9);
    assert!(a[l] < 1e-12, "{}", a[l]);
    let r = spec.report(ts).unwrap();
    assert!((r.f_max_hz - f[l] / 2.0).abs() < 1e-9);
    // The hold's sinc envelope is down by about 4 dB (factor 2/pi) at f_max.
    let k_max = (r.f_max_hz / r.resolution_hz).round() as usize;
    let ratio = a[k_max] / a[1];
    assert!(ratio > 0.6 && ratio < 0.7, "{ratio}");
}

#[test]
fn report_levels_match_generated_samples() {
    for (amplitude, offset) in [(1.0, 0.0), (0.3, 0.5), (0.2, -1.0), (2.0, 1.5)] {
        let spec = PrbsSpec {
            order: 6,
            samples_per_bit: 3,
            periods: 2,
            amplitude,
            offset,
        };
        let ts = 1e-4;
        let r = spec.report(ts).unwrap();
        let x = spec.generate(ts).unwrap();
        assert_eq!(r.n_samples, x.len());
        assert!((r.rms - rms(&x.values).unwrap()).abs() < 1e-12);
        let peak = x.values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!((r.peak - peak).abs() < 1e-15);
        assert!((r.crest_factor - crest_factor(&x.values).unwrap()).abs() < 1e-12);
    }
}

#[test]
fn invalid_designs_give_typed_errors() {
    let ok = PrbsSpec {
        order: 8,
        samples_per_bit: 2,
        periods: 1,
        amplitude: 1.0,
        offset: 0.0,
    };
    assert!(ok.generate(1e-3).is_ok());
    let name_of = |s: &PrbsSpec, ts: f64| match s.generate(ts) {
        Err(Error::InvalidArgument { name, reason }) => {
            assert!(!reason.is_empty());
            assert!(matches!(s.report(ts), Err(Error::InvalidArgument { .. })));
            name
        }
        other => panic!("expected InvalidArgument, got {other:?}"),
    };
    for ts in [0.0, -1e-3, f64::NAN, f64::INFINITY] {
        assert_eq!(name_of(&ok, ts), "ts");
    }
    for order in [0, 1, 32, 100] {
        assert_eq!(
            name_of(
                &PrbsSpec {
                    order,
                    ..ok.clone()
                },
                1e-3
            ),
            "order"
        );
    }
    assert_eq!(
        name_of(
            &PrbsSpec {
                samples_per_bit: 0,
                ..ok.clone()
            },
            1e-3
        ),
        "samples_per_bit"
    );
    assert_eq!(
        name_of(
            &PrbsSpec {
                periods: 0,
                ..ok.clone()
            },
            1e-3
        ),
        "periods"
    );
    for amplitude in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert_eq!(
            name_of(
                &PrbsSpec {
                    amplitude,
                    ..ok.clone()
                },
                1e-3
            ),
            "amplitude"
        );
    }
    assert_eq!(
        name_of(
            &PrbsSpec {
                offset: f64::NAN,
                ..ok.clone()
            },
            1e-3
        ),
        "offset"
    );
}

#[test]
fn memory_guard_refuses_huge_designs_but_reports_them() {
    let big = PrbsSpec {
        order: 31,
        samples_per_bit: 1,
        periods: 1,
        amplitude: 1.0,
        offset: 0.0,
    };
    let r = big.report(1e-6).unwrap();
    assert_eq!(r.period_samples, (1usize << 31) - 1);
    assert!(r.period_samples > MAX_SAMPLES);
    assert!(matches!(
        big.generate(1e-6),
        Err(Error::InvalidArgument { .. })
    ));
    assert!(prbs_period(29).is_err());
    // Fits per period, too many periods.
    let many = PrbsSpec {
        order: 20,
        samples_per_bit: 10,
        periods: 1000,
        ..big.clone()
    };
    assert!(matches!(
        many.generate(1e-6),
        Err(Error::InvalidArgument {
            name: "periods",
            ..
        })
    ));
    // Overflowing sizes are an error, never a panic.
    let absurd = PrbsSpec {
        samples_per_bit: usize::MAX,
        periods: usize::MAX,
        ..big
    };
    assert!(absurd.report(1e-6).is_err());
    assert!(absurd.generate(1e-6).is_err());
}
