//! Chirp, noise and multisine: frequency laws, levels, reproducibility, band limits and line sets.
//!
//! Oracles: the analytic instantaneous-frequency laws (checked against zero-crossing spacing), the
//! distributions' moments, and the library's FFT (itself tested against a naive DFT) for spectral
//! content.

use ambid_core::signal::multisine::RANDOM_ODD_GROUP;
use ambid_core::signal::{
    amplitude_spectrum, crest_factor, rms, ChirpSpec, Distribution, Grid, MultisineSpec, NoiseSpec,
    Phases, Sweep,
};
use ambid_core::Error;
use std::collections::BTreeSet;

// ------------------------------------------------------------------------------------------------
// Chirp

/// Zero-crossing instants by linear interpolation between samples.
fn zero_crossings(x: &[f64], ts: f64) -> Vec<f64> {
    let mut z = Vec::new();
    for k in 0..x.len() - 1 {
        let (a, b) = (x[k], x[k + 1]);
        if a == 0.0 {
            z.push(k as f64 * ts);
        } else if a * b < 0.0 {
            z.push((k as f64 + a / (a - b)) * ts);
        }
    }
    z
}

/// (midpoint, frequency) estimates from consecutive zero crossings (half a cycle apart).
fn local_frequencies(x: &[f64], ts: f64) -> Vec<(f64, f64)> {
    let z = zero_crossings(x, ts);
    z.windows(2)
        .map(|w| (0.5 * (w[0] + w[1]), 0.5 / (w[1] - w[0])))
        .collect()
}

fn check_chirp_law(spec: &ChirpSpec, ts: f64, law: impl Fn(f64) -> f64, rel_tol: f64) {
    let x = spec.generate(ts).unwrap();
    let period = x.period(0).unwrap();
    let est = local_frequencies(period, ts);
    assert!(est.len() > 10);
    for &(t, f) in &est {
        let want = law(t);
        assert!(
            ((f - want) / want).abs() < rel_tol,
            "t = {t}: measured {f} Hz, law {want} Hz"
        );
    }
    // Starts at f0 and ends at f1: the law holds from within the first cycle to within the last
    // one, and the law itself runs from f0 to f1.
    let (f0, f1) = (spec.f0_hz, spec.f1_hz);
    let t_end = x.period_samples as f64 * ts;
    assert!(est[0].0 < 1.0 / f0, "first estimate at {} s", est[0].0);
    assert!(t_end - est[est.len() - 1].0 < 1.0 / f1);
    assert!((law(0.0) - f0).abs() < 1e-9 * f0 && (law(t_end) - f1).abs() < 1e-9 * f1);
    for t in [0.0, 0.3 * t_end, t_end] {
        let f = spec.instantaneous_frequency_hz(t).unwrap();
        assert!((f - law(t)).abs() < 1e-9 * f);
    }
    // Amplitude respected: never above A, and the peaks reach it.
    let a = spec.amplitude;
    let peak = period.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(peak <= a * (1.0 + 1e-12) && peak > 0.999 * a, "peak {peak}");
    let r = rms(period).unwrap();
    assert!((r - a / 2f64.sqrt()).abs() < 0.01 * a, "rms {r}");
}

#[test]
fn linear_chirp_follows_its_law() {
    let spec = ChirpSpec {
        f0_hz: 10.0,
        f1_hz: 1000.0,
        duration_s: 1.0,
        amplitude: 0.7,
        sweep: Sweep::Linear,
        periods: 2,
    };
    let ts = 5e-5;
    check_chirp_law(&spec, ts, |t| 10.0 + 990.0 * t, 0.01);
    let x = spec.generate(ts).unwrap();
    assert_eq!((x.period_samples, x.periods, x.len()), (20_000, 2, 40_000));
    assert_eq!(x.period(0), x.period(1));
    assert_eq!(x.values[0], 0.0);
    assert!((spec.instantaneous_frequency_hz(0.0).unwrap() - 10.0).abs() < 1e-12);
    assert!((spec.instantaneous_frequency_hz(1.0).unwrap() - 1000.0).abs() < 1e-9);
}

#[test]
fn logarithmic_chirp_follows_its_law() {
    let spec = ChirpSpec {
        f0_hz: 5.0,
        f1_hz: 500.0,
        duration_s: 2.0,
        amplitude: 1.5,
        sweep: Sweep::Logarithmic,
        periods: 1,
    };
    check_chirp_law(&spec, 1e-4, |t| 5.0 * 100f64.powf(t / 2.0), 0.01);
    assert!((spec.instantaneous_frequency_hz(1.0).unwrap() - 50.0).abs() < 1e-9);
}

#[test]
fn down_sweep_and_report() {
    let spec = ChirpSpec {
        f0_hz: 400.0,
        f1_hz: 20.0,
        duration_s: 1.0,
        amplitude: 1.0,
        sweep: Sweep::Linear,
        periods: 3,
    };
    let ts = 1e-4;
    check_chirp_law(&spec, ts, |t| 400.0 - 380.0 * t, 0.01);
    let r = spec.report(ts).unwrap();
    assert_eq!((r.f_min_hz, r.f_max_hz), (20.0, 400.0));
    assert_eq!(
        (r.period_samples, r.periods, r.n_samples),
        (10_000, 3, 30_000)
    );
    assert!((r.resolution_hz - 1.0).abs() < 1e-9);
    assert!((r.duration_s - 3.0).abs() < 1e-9);
    assert!((r.crest_factor - 2f64.sqrt()).abs() < 0.02);
}

#[test]
fn chirp_errors_are_typed() {
    let ok = ChirpSpec {
        f0_hz: 1.0,
        f1_hz: 100.0,
        duration_s: 1.0,
        amplitude: 1.0,
        sweep: Sweep::Logarithmic,
        periods: 1,
    };
    let ts = 1e-3;
    assert!(ok.generate(ts).is_ok());
    let name = |s: ChirpSpec, ts: f64| match s.generate(ts) {
        Err(Error::InvalidArgument { name, .. }) => {
            assert!(s.report(ts).is_err());
            name
        }
        other => panic!("expected InvalidArgument, got {other:?}"),
    };
    assert_eq!(name(ok.clone(), 0.0), "ts");
    assert_eq!(
        name(
            ChirpSpec {
                f1_hz: 501.0,
                ..ok.clone()
            },
            ts
        ),
        "f1_hz"
    );
    assert_eq!(
        name(
            ChirpSpec {
                f0_hz: -1.0,
                ..ok.clone()
            },
            ts
        ),
        "f0_hz"
    );
    assert_eq!(
        name(
            ChirpSpec {
                f0_hz: 0.0,
                ..ok.clone()
            },
            ts
        ),
        "f0_hz"
    );
    assert!(ChirpSpec {
        f0_hz: 0.0,
        sweep: Sweep::Linear,
        ..ok.clone()
    }
    .generate(ts)
    .is_ok());
    assert_eq!(
        name(
            ChirpSpec {
                f0_hz: 100.0,
                ..ok.clone()
            },
            ts
        ),
        "f1_hz"
    );
    assert_eq!(
        name(
            ChirpSpec {
                f1_hz: f64::NAN,
                ..ok.clone()
            },
            ts
        ),
        "f1_hz"
    );
    assert_eq!(
        name(
            ChirpSpec {
                duration_s: 0.0,
                ..ok.clone()
            },
            ts
        ),
        "duration_s"
    );
    assert_eq!(
        name(
            ChirpSpec {
                duration_s: 1e-3,
                ..ok.clone()
            },
            ts
        ),
        "duration_s"
    );
    assert_eq!(
        name(
            ChirpSpec {
                duration_s: 1e12,
                ..ok.clone()
            },
            ts
        ),
        "duration_s"
    );
    assert_eq!(
        name(
            ChirpSpec {
                amplitude: 0.0,
                ..ok.clone()
            },
            ts
        ),
        "amplitude"
    );
    assert_eq!(
        name(
            ChirpSpec {
                periods: 0,
                ..ok.clone()
            },
            ts
        ),
        "periods"
    );
    assert_eq!(
        name(
            ChirpSpec {
                periods: usize::MAX,
                ..ok.clone()
            },
            ts
        ),
        "periods"
    );
}

// ------------------------------------------------------------------------------------------------
// Noise

fn noise(
    distribution: Distribution,
    rms: f64,
    n: usize,
    band: Option<(f64, f64)>,
    seed: u64,
) -> NoiseSpec {
    NoiseSpec {
        distribution,
        rms,
        n_samples: n,
        band_hz: band,
        seed,
    }
}

#[test]
fn noise_is_reproducible_per_seed_and_differs_across_seeds() {
    for d in [Distribution::Gaussian, Distribution::Uniform] {
        for band in [None, Some((20.0, 80.0))] {
            let a = noise(d, 1.0, 1000, band, 5).generate(1e-3).unwrap();
            let b = noise(d, 1.0, 1000, band, 5).generate(1e-3).unwrap();
            let c = noise(d, 1.0, 1000, band, 6).generate(1e-3).unwrap();
            assert_eq!(a, b);
            let same = a
                .values
                .iter()
                .zip(&c.values)
                .filter(|(u, v)| u == v)
                .count();
            assert!(
                same < 5,
                "{d:?} {band:?}: {same} equal samples across seeds"
            );
        }
    }
}

#[test]
fn white_noise_moments() {
    let n = 200_000;
    let sigma = 0.3;
    let g = noise(Distribution::Gaussian, sigma, n, None, 11)
        .generate(1e-4)
        .unwrap()
        .values;
    let mean = g.iter().sum::<f64>() / n as f64;
    assert!(mean.abs() < 0.01 * sigma, "mean {mean}");
    assert!((rms(&g).unwrap() / sigma - 1.0).abs() < 0.01);
    let within = g.iter().filter(|v| v.abs() <= sigma).count() as f64 / n as f64;
    assert!((within - 0.6827).abs() < 0.01, "P(|x| <= sigma) = {within}");

    let u = noise(Distribution::Uniform, sigma, n, None, 11)
        .generate(1e-4)
        .unwrap()
        .values;
    let a = 3f64.sqrt() * sigma;
    assert!((rms(&u).unwrap() / sigma - 1.0).abs() < 0.01);
    let peak = u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(peak <= a && peak > 0.999 * a, "peak {peak} vs {a}");
    assert!(crest_factor(&u).unwrap() <= 3f64.sqrt());
    // Uniform: P(|x| <= a/2) = 1/2.
    let half = u.iter().filter(|v| v.abs() <= a / 2.0).count() as f64 / n as f64;
    assert!((half - 0.5).abs() < 0.01);
}

#[test]
fn band_limited_noise_has_no_energy_outside_the_band() {
    let ts = 1e-3;
    let n = 8192;
    for d in [Distribution::Gaussian, Distribution::Uniform] {
        let spec = noise(d, 0.25, n, Some((50.0, 150.0)), 3);
        let x = spec.generate(ts).unwrap();
        assert!((rms(&x.values).unwrap() - 0.25).abs() < 1e-12);
        let (f, a) = amplitude_spectrum(&x.values, ts).unwrap();
        let (mut inside, mut outside) = (0.0, 0.0);
        for (fk, ak) in f.iter().zip(&a) {
            if (50.0..=150.0).contains(fk) {
                inside += ak * ak;
            } else {
                outside += ak * ak;
            }
        }
        assert!(
            outside <= 1e-24 * inside,
            "{d:?}: outside/inside = {}",
            outside / inside
        );
        let r = spec.report(ts).unwrap();
        assert_eq!((r.f_min_hz, r.f_max_hz), (50.0, 150.0));
        assert!((r.resolution_hz - 1.0 / (n as f64 * ts)).abs() < 1e-12);
        assert!((r.rms - 0.25).abs() < 1e-12);
    }
    // A band starting at DC keeps the mean line.
    let x = noise(Distribution::Gaussian, 1.0, 1000, Some((0.0, 10.0)), 1)
        .generate(1e-3)
        .unwrap();
    let (_, a) = amplitude_spectrum(&x.values, 1e-3).unwrap();
    assert!(a[0] > 0.0 && a[11..].iter().all(|&v| v < 1e-12));
}

#[test]
fn noise_errors_are_typed() {
    let ok = noise(Distribution::Gaussian, 1.0, 100, Some((10.0, 100.0)), 0);
    let ts = 1e-3;
    assert!(ok.generate(ts).is_ok());
    let name = |s: NoiseSpec| match s.generate(ts) {
        Err(Error::InvalidArgument { name, .. }) => {
            assert!(s.report(ts).is_err());
            name
        }
        other => panic!("expected InvalidArgument, got {other:?}"),
    };
    assert_eq!(
        name(NoiseSpec {
            rms: 0.0,
            ..ok.clone()
        }),
        "rms"
    );
    assert_eq!(
        name(NoiseSpec {
            rms: f64::NAN,
            ..ok.clone()
        }),
        "rms"
    );
    assert_eq!(
        name(NoiseSpec {
            n_samples: 1,
            ..ok.clone()
        }),
        "n_samples"
    );
    assert_eq!(
        name(NoiseSpec {
            n_samples: usize::MAX,
            ..ok.clone()
        }),
        "n_samples"
    );
    assert_eq!(
        name(NoiseSpec {
            band_hz: Some((10.0, 501.0)),
            ..ok.clone()
        }),
        "band_hz"
    );
    assert_eq!(
        name(NoiseSpec {
            band_hz: Some((100.0, 10.0)),
            ..ok.clone()
        }),
        "band_hz"
    );
    assert_eq!(
        name(NoiseSpec {
            band_hz: Some((-1.0, 10.0)),
            ..ok.clone()
        }),
        "band_hz"
    );
    // Line spacing 10 Hz: (11, 19) Hz holds no line.
    assert_eq!(
        name(NoiseSpec {
            band_hz: Some((11.0, 19.0)),
            ..ok.clone()
        }),
        "band_hz"
    );
    assert!(matches!(
        ok.generate(f64::NAN),
        Err(Error::InvalidArgument { name: "ts", .. })
    ));
}

// ------------------------------------------------------------------------------------------------
// Multisine

fn ms(grid: Grid, phases: Phases, seed: u64) -> MultisineSpec {
    MultisineSpec {
        f_min_hz: 5.0,
        f_max_hz: 400.0,
        period_samples: 2000,
        periods: 3,
        rms: 0.2,
        grid,
        phases,
        seed,
    }
}

const TS: f64 = 1e-3; // fs = 1 kHz, N = 2000: 0.5 Hz lines

#[test]
fn multisine_energy_is_exactly_on_the_chosen_bins() {
    for grid in [Grid::Full, Grid::Odd, Grid::RandomOdd] {
        for phases in [Phases::Schroeder, Phases::Random] {
            let spec = ms(grid, phases, 17);
            let bins = spec.bins(TS).unwrap();
            let chosen: BTreeSet<usize> = bins.iter().copied().collect();
            let x = spec.generate(TS).unwrap();
            assert_eq!((x.len(), x.period_samples, x.periods), (6000, 2000, 3));
            let p0 = x.period(0).unwrap();
            for p in 1..3 {
                assert_eq!(x.period(p).unwrap(), p0);
            }
            assert!((rms(p0).unwrap() - 0.2).abs() < 1e-12);
            let (f, a) = amplitude_spectrum(p0, TS).unwrap();
            let line = 0.2 * (2.0 / bins.len() as f64).sqrt();
            for (k, ak) in a.iter().enumerate() {
                if chosen.contains(&k) {
                    assert!(
                        ((ak - line) / line).abs() < 1e-9,
                        "{grid:?} {phases:?} bin {k}: {ak} vs {line}"
                    );
                } else {
                    assert!(*ak < 1e-9 * line, "{grid:?} {phases:?} bin {k} leaks {ak}");
                }
            }
            // lines() in Hz agree with the bins and lie in the band.
            let lines = spec.lines(TS).unwrap();
            assert_eq!(lines.len(), bins.len());
            for (&k, &fl) in bins.iter().zip(&lines) {
                assert!((fl - f[k]).abs() < 1e-9);
                assert!((5.0..=400.0).contains(&fl));
            }
            let r = spec.report(TS).unwrap();
            assert_eq!((r.f_min_hz, r.f_max_hz), (lines[0], lines[lines.len() - 1]));
            assert!((r.resolution_hz - 0.5).abs() < 1e-12);
            assert!((r.crest_factor - crest_factor(p0).unwrap()).abs() < 1e-12);
        }
    }
}

#[test]
fn grids_have_the_right_lines() {
    let full = ms(Grid::Full, Phases::Schroeder, 0).bins(TS).unwrap();
    assert_eq!(full, (10..=800).collect::<Vec<_>>());
    let odd = ms(Grid::Odd, Phases::Schroeder, 0).bins(TS).unwrap();
    assert!(odd.iter().all(|k| k % 2 == 1));
    assert_eq!(odd, (11..=799).step_by(2).collect::<Vec<_>>());

    let ro = |seed| ms(Grid::RandomOdd, Phases::Random, seed).bins(TS).unwrap();
    let a = ro(1);
    assert_eq!(a, ro(1), "random-odd grid is reproducible");
    assert_ne!(a, ro(2), "random-odd grid depends on the seed");
    // Exactly one line left out of each complete group of consecutive odd lines.
    let kept: BTreeSet<usize> = a.iter().copied().collect();
    for group in odd.chunks(RANDOM_ODD_GROUP) {
        let n_kept = group.iter().filter(|k| kept.contains(k)).count();
        if group.len() == RANDOM_ODD_GROUP {
            assert_eq!(n_kept, RANDOM_ODD_GROUP - 1, "group {group:?}");
        } else {
            assert_eq!(n_kept, group.len());
        }
    }
    assert!(kept.iter().all(|k| k % 2 == 1));
    // Same seed, same signal.
    let s1 = ms(Grid::RandomOdd, Phases::Random, 9).generate(TS).unwrap();
    let s2 = ms(Grid::RandomOdd, Phases::Random, 9).generate(TS).unwrap();
    assert_eq!(s1, s2);
}

#[test]
fn schroeder_crest_factor_beats_random_phases() {
    let schroeder = crest_factor(
        &ms(Grid::Full, Phases::Schroeder, 0)
            .generate(TS)
            .unwrap()
            .values,
    )
    .unwrap();
    assert!(schroeder < 1.9, "Schroeder crest factor {schroeder}");
    let mut sum = 0.0;
    for seed in 0..8 {
        let c = crest_factor(
            &ms(Grid::Full, Phases::Random, seed)
                .generate(TS)
                .unwrap()
                .values,
        )
        .unwrap();
        assert!(
            c > schroeder,
            "seed {seed}: random {c} vs Schroeder {schroeder}"
        );
        sum += c;
    }
    let mean_random = sum / 8.0;
    // Starting at the first bin, Schroeder phases do better still.
    let baseband = MultisineSpec {
        f_min_hz: 0.5,
        ..ms(Grid::Full, Phases::Schroeder, 0)
    };
    let c = crest_factor(&baseband.generate(TS).unwrap().values).unwrap();
    assert!(c < 1.7, "baseband Schroeder crest factor {c}");
    assert!(
        mean_random > schroeder + 0.8,
        "mean random {mean_random} vs Schroeder {schroeder}"
    );
}

#[test]
fn nyquist_line_is_never_excited() {
    let spec = MultisineSpec {
        f_min_hz: 400.0,
        f_max_hz: 500.0,
        period_samples: 100,
        periods: 1,
        rms: 1.0,
        grid: Grid::Full,
        phases: Phases::Schroeder,
        seed: 0,
    };
    // 10 Hz lines; bin 50 (500 Hz) is Nyquist.
    assert_eq!(spec.bins(TS).unwrap(), (40..=49).collect::<Vec<_>>());
    let odd_n = MultisineSpec {
        period_samples: 101,
        ..spec
    };
    assert_eq!(*odd_n.bins(TS).unwrap().last().unwrap(), 50);
}

#[test]
fn multisine_errors_are_typed() {
    let ok = ms(Grid::Full, Phases::Schroeder, 0);
    assert!(ok.generate(TS).is_ok());
    let name = |s: MultisineSpec| match s.generate(TS) {
        Err(Error::InvalidArgument { name, .. }) => {
            assert!(s.report(TS).is_err());
            assert!(s.lines(TS).is_err() || name == "periods");
            name
        }
        other => panic!("expected InvalidArgument, got {other:?}"),
    };
    assert_eq!(
        name(MultisineSpec {
            f_min_hz: 0.0,
            ..ok.clone()
        }),
        "f_min_hz"
    );
    assert_eq!(
        name(MultisineSpec {
            f_max_hz: 501.0,
            ..ok.clone()
        }),
        "f_max_hz"
    );
    assert_eq!(
        name(MultisineSpec {
            f_max_hz: 4.0,
            ..ok.clone()
        }),
        "f_max_hz"
    );
    assert_eq!(
        name(MultisineSpec {
            rms: -1.0,
            ..ok.clone()
        }),
        "rms"
    );
    assert_eq!(
        name(MultisineSpec {
            period_samples: 3,
            ..ok.clone()
        }),
        "period_samples"
    );
    assert_eq!(
        name(MultisineSpec {
            periods: 0,
            ..ok.clone()
        }),
        "periods"
    );
    assert_eq!(
        name(MultisineSpec {
            periods: usize::MAX,
            ..ok.clone()
        }),
        "periods"
    );
    // 0.5 Hz lines: (5.1, 5.4) Hz holds none.
    assert_eq!(
        name(MultisineSpec {
            f_min_hz: 5.1,
            f_max_hz: 5.4,
            ..ok.clone()
        }),
        "f_min_hz"
    );
    // Odd grid on a band with only an even line.
    assert_eq!(
        name(MultisineSpec {
            f_min_hz: 5.0,
            f_max_hz: 5.0,
            grid: Grid::Odd,
            ..ok.clone()
        }),
        "f_min_hz"
    );
    assert!(matches!(
        ok.bins(-1.0),
        Err(Error::InvalidArgument { name: "ts", .. })
    ));
}
