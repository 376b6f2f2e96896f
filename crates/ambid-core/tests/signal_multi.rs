//! Multi-input excitation designs (`signal::multi`) against independent truth: a naive O(N²) DFT,
//! Hadamard orthogonality, hand-computed durations and line counts, the single-input specs
//! (bit for bit at n = 1), and typed errors for bad input.

use ambid_core::data::{Role, AXES};
use ambid_core::signal::{
    hadamard, hadamard_order, BaseSignal, Grid, MultiInputDesign, MultiInputKind, MultisineSpec,
    Phases, PrbsSpec,
};
use ambid_core::Error;
use num_complex::Complex;
use std::f64::consts::PI;

/// $X_k = \sum_n x_n e^{-j 2\pi k n / N}$ from the definition, for $k = 0 \dots \lfloor N/2 \rfloor$.
fn naive_dft(x: &[f64]) -> Vec<Complex<f64>> {
    let n = x.len();
    (0..=n / 2)
        .map(|k| {
            x.iter()
                .enumerate()
                .map(|(t, &v)| {
                    let ang = -2.0 * PI * ((k * t) % n) as f64 / n as f64;
                    Complex::new(v * ang.cos(), v * ang.sin())
                })
                .sum()
        })
        .collect()
}

fn ms(
    f_min: f64,
    f_max: f64,
    n: usize,
    periods: usize,
    grid: Grid,
    phases: Phases,
) -> MultisineSpec {
    MultisineSpec {
        f_min_hz: f_min,
        f_max_hz: f_max,
        period_samples: n,
        periods,
        rms: 0.3,
        grid,
        phases,
        seed: 11,
    }
}

fn prbs(order: u32, nb: usize, periods: usize) -> PrbsSpec {
    PrbsSpec {
        order,
        samples_per_bit: nb,
        periods,
        amplitude: 0.2,
        offset: 0.0,
    }
}

fn invalid_name(e: Error) -> &'static str {
    match e {
        Error::InvalidArgument { name, .. } => name,
        other => panic!("expected InvalidArgument, got {other:?}"),
    }
}

/// Every multisine design puts power exactly on each axis's intended lines, with the amplitude
/// $a_j \sqrt{2/F_j}\,N/2$, and (numerically) none elsewhere — checked on every period.
#[test]
fn multisine_power_only_on_intended_lines() {
    let ts = 1e-3; // N = 240: 1/0.24 Hz lines
    let levels = [0.3, 0.1, 0.25, 0.05];
    let cases = [
        (MultiInputKind::Sequential, Grid::Full, Phases::Schroeder),
        (MultiInputKind::Orthogonal, Grid::Odd, Phases::Random),
        (MultiInputKind::Zipper, Grid::Full, Phases::Schroeder),
        (MultiInputKind::Zipper, Grid::RandomOdd, Phases::Random),
    ];
    for n in [3usize, 4] {
        for (kind, grid, phases) in cases {
            let spec = ms(5.0, 200.0, 240, 2, grid, phases);
            let base_bins = spec.bins(ts).unwrap();
            let design = MultiInputDesign::new(kind, n, spec.into())
                .with_levels(levels[..n].to_vec())
                .with_transient_periods(1);
            let x = design.generate(ts).unwrap();
            let m = x.n_experiments();
            assert_eq!(
                m,
                match kind {
                    MultiInputKind::Sequential => n,
                    MultiInputKind::Orthogonal => 4,
                    MultiInputKind::Zipper => 1,
                }
            );
            for e in 0..m {
                for (j, &level) in levels.iter().enumerate().take(n) {
                    let sig = x.signal(e, j).unwrap();
                    assert_eq!(sig.len(), 3 * 240);
                    // Intended lines of axis j in experiment e.
                    let lines: Vec<usize> = match kind {
                        MultiInputKind::Sequential if e != j => vec![],
                        MultiInputKind::Zipper => {
                            base_bins.iter().copied().skip(j).step_by(n).collect()
                        }
                        _ => base_bins.clone(),
                    };
                    let f = lines.len().max(1) as f64;
                    let amp = level * (2.0 / f).sqrt() * 240.0 / 2.0;
                    for p in 0..3 {
                        let xk = naive_dft(&sig[p * 240..(p + 1) * 240]);
                        for (k, v) in xk.iter().enumerate() {
                            if lines.contains(&k) {
                                assert!(
                                    (v.norm() - amp).abs() < 1e-9 * amp,
                                    "{kind:?} n={n} e={e} j={j} k={k}: |X| = {} != {amp}",
                                    v.norm()
                                );
                            } else {
                                assert!(
                                    v.norm() < 1e-9 * amp,
                                    "{kind:?} n={n} e={e} j={j}: power {} on bin {k}",
                                    v.norm()
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}

/// PRBS base: every excited axis carries ±the single-input PRBS, whose DFT magnitude is
/// $a\sqrt{L+1}\,|\sin(\pi k/L)/\sin(\pi k/N)|$ at every bin $k \not\equiv 0 \pmod L$; idle axes
/// are exactly zero.
#[test]
fn prbs_designs_match_the_analytic_spectrum() {
    let ts = 1e-4;
    let (order, nb) = (5u32, 3usize);
    let l = 31.0;
    let p = 93;
    for kind in [MultiInputKind::Sequential, MultiInputKind::Orthogonal] {
        let design = MultiInputDesign::new(kind, 3, prbs(order, nb, 2).into());
        let x = design.generate(ts).unwrap();
        let w = design.weights().unwrap();
        let single = prbs(order, nb, 2).generate(ts).unwrap();
        for (e, row) in w.iter().enumerate() {
            for (j, &wj) in row.iter().enumerate() {
                let sig = x.signal(e, j).unwrap();
                let expect: Vec<f64> = single.values.iter().map(|v| wj * v).collect();
                assert_eq!(sig, expect.as_slice(), "{kind:?} e={e} j={j}");
                let xk = naive_dft(&sig[..p]);
                for (k, v) in xk.iter().enumerate().skip(1) {
                    let truth = if wj == 0.0 {
                        0.0
                    } else {
                        let kf = k as f64;
                        0.2 * (l + 1.0f64).sqrt()
                            * ((PI * kf / l).sin() / (PI * kf / p as f64).sin()).abs()
                    };
                    assert!(
                        (v.norm() - truth).abs() < 1e-10,
                        "{kind:?} e={e} j={j} k={k}: {} vs {truth}",
                        v.norm()
                    );
                }
            }
        }
    }
}

#[test]
fn hadamard_rows_are_orthogonal() {
    for m in [1usize, 2, 4, 8, 16, 32] {
        let h = hadamard(m).unwrap();
        assert_eq!(h.len(), m);
        for i in 0..m {
            assert!(h[i].iter().all(|&v| v == 1.0 || v == -1.0));
            for j in 0..m {
                // H^T H = M I (columns) and H H^T = M I (rows).
                let cols: f64 = (0..m).map(|r| h[r][i] * h[r][j]).sum();
                let rows: f64 = (0..m).map(|c| h[i][c] * h[j][c]).sum();
                let want = if i == j { m as f64 } else { 0.0 };
                assert_eq!((cols, rows), (want, want), "M={m} ({i},{j})");
            }
        }
    }
    // Sylvester recursion H_2M = [[H, H], [H, -H]] checked against the formula's output.
    let h4 = hadamard(4).unwrap();
    let h8 = hadamard(8).unwrap();
    for i in 0..8 {
        for j in 0..8 {
            let s = if i >= 4 && j >= 4 { -1.0 } else { 1.0 };
            assert_eq!(h8[i][j], s * h4[i % 4][j % 4]);
        }
    }
    for m in [0usize, 3, 5, 6, 12] {
        assert_eq!(invalid_name(hadamard(m).unwrap_err()), "order");
    }
    assert_eq!(
        (1..=9)
            .map(|n| hadamard_order(n).unwrap())
            .collect::<Vec<_>>(),
        vec![1, 2, 4, 4, 8, 8, 8, 8, 16]
    );
    // n = 3: the order-4 matrix and its first three columns, M = 4 experiments.
    let d = MultiInputDesign::orthogonal(3, prbs(4, 1, 1));
    let w = d.weights().unwrap();
    assert_eq!(w.len(), 4);
    for (e, row) in w.iter().enumerate() {
        assert_eq!(row.as_slice(), &h4[e][..3]);
    }
}

/// cond R(k) = 1 at every excited line of the sequential and orthogonal designs at equal levels,
/// and max/min level with unequal ones; the zipper's group matrices are diagonal with the
/// amplitudes $a_j\sqrt{2/F_j}$.
#[test]
fn condition_numbers() {
    let ts = 1e-3;
    for n in 1..=5 {
        for kind in [MultiInputKind::Sequential, MultiInputKind::Orthogonal] {
            for base in [
                BaseSignal::from(ms(4.0, 300.0, 200, 1, Grid::Odd, Phases::Schroeder)),
                BaseSignal::from(prbs(6, 2, 1)),
            ] {
                let r = MultiInputDesign::new(kind, n, base.clone())
                    .report(ts)
                    .unwrap();
                let lines = base.bins(ts).unwrap();
                assert_eq!(r.condition.len(), lines.len());
                for (c, &k) in r.condition.iter().zip(&lines) {
                    assert_eq!(c.bins, vec![k]);
                    assert!(
                        (c.cond - 1.0).abs() < 1e-9,
                        "{kind:?} n={n} bin {k}: {}",
                        c.cond
                    );
                }
                // Unequal levels: cond = max/min level.
                let levels: Vec<f64> = (0..n).map(|j| 0.1 * (j + 1) as f64).collect();
                let r = MultiInputDesign::new(kind, n, base)
                    .with_levels(levels)
                    .report(ts)
                    .unwrap();
                assert!((r.max_condition - n as f64).abs() < 1e-9 * n as f64);
            }
        }
    }
    // Zipper, 8 lines over 3 axes: F = (3, 3, 2), two complete groups, cond = sqrt(3/2).
    let spec = ms(1.0, 8.0, 100, 1, Grid::Full, Phases::Schroeder);
    let r = MultiInputDesign::zipper(3, spec.clone())
        .report(0.01)
        .unwrap();
    assert_eq!(r.condition.len(), 2);
    assert_eq!(r.condition[0].bins, vec![1, 2, 3]);
    assert_eq!(r.condition[1].bins, vec![4, 5, 6]);
    assert!((r.condition[0].f_hz - 2.0).abs() < 1e-12);
    for c in &r.condition {
        assert!((c.cond - 1.5f64.sqrt()).abs() < 1e-9, "{}", c.cond);
    }
    // 9 lines over 3 axes at equal level: cond 1; levels (1, 2, 4): cond 4.
    let spec = ms(1.0, 9.0, 100, 1, Grid::Full, Phases::Random);
    let r = MultiInputDesign::zipper(3, spec.clone())
        .report(0.01)
        .unwrap();
    assert_eq!(r.condition.len(), 3);
    assert!((r.max_condition - 1.0).abs() < 1e-9);
    let r = MultiInputDesign::zipper(3, spec)
        .with_levels(vec![1.0, 2.0, 4.0])
        .report(0.01)
        .unwrap();
    assert!((r.max_condition - 4.0).abs() < 1e-9);
}

#[test]
fn zipper_lines_are_disjoint_and_cover_the_grid() {
    let ts = 2.5e-4;
    for grid in [Grid::Full, Grid::Odd, Grid::RandomOdd] {
        let spec = ms(10.0, 1000.0, 4000, 1, grid, Phases::Schroeder);
        let all = spec.bins(ts).unwrap();
        for n in 1..=7 {
            let per_axis = MultiInputDesign::zipper(n, spec.clone())
                .axis_bins(ts)
                .unwrap();
            assert_eq!(per_axis.len(), n);
            let mut union: Vec<usize> = per_axis.iter().flatten().copied().collect();
            let count = union.len();
            union.sort_unstable();
            union.dedup();
            assert_eq!(union.len(), count, "lines shared between axes");
            assert_eq!(union, all, "the union is the base grid");
            for (j, b) in per_axis.iter().enumerate() {
                // Axis j holds the lines of index i ≡ j (mod n).
                for (i, k) in all.iter().enumerate() {
                    assert_eq!(b.contains(k), i % n == j);
                }
                // Counts ceil((F - j)/n).
                assert_eq!(b.len(), (all.len() - j).div_ceil(n));
            }
        }
    }
}

/// Durations and line counts by hand.
#[test]
fn durations_and_line_counts_by_hand() {
    // Seed PRBS (n = 10, Nb = 5) at 50 us, 4 measured + 1 transient period, orthogonal on 3 axes:
    // M = 4, 5 x 5115 = 25575 samples per experiment, 102300 in all = 5.115 s; 511 lines per axis
    // (bins 1..=511), resolution 1/(5115 x 50 us) = 3.910068426... Hz.
    let ts = 50e-6;
    let r = MultiInputDesign::orthogonal(3, prbs(10, 5, 4))
        .with_transient_periods(1)
        .report(ts)
        .unwrap();
    assert_eq!(r.experiments, 4);
    assert_eq!(r.samples_per_experiment, 25_575);
    assert_eq!(r.total_samples, 102_300);
    assert!((r.total_duration_s - 5.115).abs() < 1e-12);
    assert!((r.measured_duration_s - 4.092).abs() < 1e-12);
    assert!((r.resolution_hz - 1.0 / (5115.0 * 50e-6)).abs() < 1e-12);
    for a in &r.axes {
        assert_eq!(a.bins.len(), 511);
        assert_eq!((a.bins[0], a.bins[510]), (1, 511));
        assert!((a.lines_hz[510] - 511.0 / (5115.0 * 50e-6)).abs() < 1e-9);
        assert!((a.crest_factor - 1.0).abs() < 1e-12);
        assert!((a.rms - 0.2).abs() < 1e-12);
    }
    // Sequential on 4 axes, same PRBS without transient: 4 x 20460 samples = 4.092 s.
    let r = MultiInputDesign::sequential(4, prbs(10, 5, 4))
        .report(ts)
        .unwrap();
    assert_eq!((r.experiments, r.samples_per_experiment), (4, 20_460));
    assert!((r.total_duration_s - 4.092).abs() < 1e-12);
    assert_eq!(r.total_duration_s, r.measured_duration_s);
    // Zipper: 10..1000 Hz at 1 Hz (fs 4 kHz, N 4000) = 991 lines over 4 axes = 248, 248, 248, 247;
    // one experiment of 2 + 3 periods = 20000 samples = 5 s.
    let spec = ms(10.0, 1000.0, 4000, 3, Grid::Full, Phases::Schroeder);
    let r = MultiInputDesign::zipper(4, spec)
        .with_transient_periods(2)
        .report(2.5e-4)
        .unwrap();
    assert_eq!(r.experiments, 1);
    assert_eq!(
        r.axes.iter().map(|a| a.bins.len()).collect::<Vec<_>>(),
        vec![248, 248, 248, 247]
    );
    assert_eq!(r.axes[3].bins[..3], [13, 17, 21]);
    assert_eq!(r.axes[0].lines_hz[..2], [10.0, 14.0]);
    assert_eq!(r.condition.len(), 247);
    assert!((r.total_duration_s - 5.0).abs() < 1e-12);
    assert!((r.measured_duration_s - 3.0).abs() < 1e-12);
    for a in &r.axes {
        assert!((a.rms - 0.3).abs() < 1e-12, "each axis has its RMS");
        assert!(
            a.crest_factor > 1.0 && a.crest_factor < 2.5,
            "{}",
            a.crest_factor
        );
    }
    // The report's text names the design and the counts.
    let text = r.to_string();
    assert!(
        text.contains("zipper (4 inputs, 1 experiment(s))"),
        "{text}"
    );
    assert!(text.contains("248 lines"), "{text}");
}

/// n = 1 reproduces today's single-input signal bit for bit, for every kind, grid and phase choice.
#[test]
fn one_input_is_the_single_input_signal() {
    let ts = 2.5e-4;
    for grid in [Grid::Full, Grid::Odd, Grid::RandomOdd] {
        for phases in [Phases::Schroeder, Phases::Random] {
            let spec = ms(10.0, 1000.0, 4000, 3, grid, phases);
            let single = spec.generate(ts).unwrap();
            let band = spec.report(ts).unwrap();
            for kind in [
                MultiInputKind::Sequential,
                MultiInputKind::Orthogonal,
                MultiInputKind::Zipper,
            ] {
                let design = MultiInputDesign::new(kind, 1, spec.clone().into());
                let x = design.generate(ts).unwrap();
                assert_eq!(x.n_experiments(), 1);
                assert_eq!(
                    x.excitation(0, 0).unwrap(),
                    single,
                    "{kind:?} {grid:?} {phases:?}"
                );
                let r = design.report(ts).unwrap();
                assert_eq!(r.axes[0].crest_factor, band.crest_factor);
                assert_eq!(r.axes[0].bins, spec.bins(ts).unwrap());
                assert_eq!(r.total_duration_s, band.duration_s);
            }
        }
    }
    for p in [
        prbs(10, 5, 2),
        PrbsSpec {
            offset: 0.05,
            ..prbs(7, 1, 3)
        },
    ] {
        let single = p.generate(ts).unwrap();
        for kind in [MultiInputKind::Sequential, MultiInputKind::Orthogonal] {
            let x = MultiInputDesign::new(kind, 1, p.clone().into())
                .generate(ts)
                .unwrap();
            assert_eq!(x.excitation(0, 0).unwrap(), single);
        }
    }
}

/// The transient periods are the same periodic signal: every experiment is exactly periodic, and
/// `measured` drops the transient.
#[test]
fn transient_periods_are_periodic_and_dropped_by_measured() {
    let spec = ms(1.0, 20.0, 64, 2, Grid::Odd, Phases::Random);
    let x = MultiInputDesign::zipper(2, spec)
        .with_transient_periods(3)
        .generate(1.0 / 64.0)
        .unwrap();
    let s = x.signal(0, 1).unwrap();
    assert_eq!(s.len(), 5 * 64);
    for k in 64..s.len() {
        assert_eq!(s[k], s[k - 64]);
    }
    assert_eq!(x.measured(0, 1).unwrap(), &s[3 * 64..]);
    assert!(x.signal(1, 0).is_none() && x.signal(0, 2).is_none());
}

#[test]
fn iodata_experiments() {
    let ts = 1e-3;
    let x = MultiInputDesign::orthogonal(4, prbs(4, 2, 2))
        .with_transient_periods(1)
        .generate(ts)
        .unwrap();
    let d = x.to_iodata().unwrap();
    assert_eq!(d.n_experiments(), 4);
    assert_eq!(d.period_samples(), Some(30));
    assert_eq!(d.ts(), ts);
    let names: Vec<String> = AXES.iter().map(|a| format!("r_{a}")).collect();
    assert_eq!(d.role_names(Role::Excitation), names);
    for e in 0..4 {
        let de = d.experiment(e).unwrap();
        assert_eq!(de.len(), 90);
        for (j, n) in names.iter().enumerate() {
            assert_eq!(de.channel(n).unwrap(), x.signal(e, j).unwrap());
        }
    }
    // Two inputs take the first two default axes; other names get the excitation role set.
    let x2 = MultiInputDesign::sequential(2, prbs(3, 1, 1))
        .generate(ts)
        .unwrap();
    assert_eq!(x2.to_iodata().unwrap().names(), vec!["r_xa", "r_xb"]);
    let d = x2.to_iodata_with_axes(&["a", "b"]).unwrap();
    assert_eq!(d.role_names(Role::Excitation), vec!["r_a", "r_b"]);
    assert_eq!(
        d.experiment(1).unwrap().channel("r_b").unwrap(),
        x2.signal(1, 1).unwrap()
    );
    let ch = x2.channels(1, &["xa", "yb"]).unwrap();
    assert_eq!(ch[1].0, "r_yb");
}

/// At equal total measurement time the variance factor $[(\sum_p R_p R_p^\mathsf{H})^{-1}]_{jj}$ of
/// each entry, computed from the generated signals' DFTs, is n× smaller for the orthogonal design
/// than for the sequential one on the same lines, and n² × smaller per zipper line (each of its
/// lines carries n× the power at the same RMS), on 1/n of the lines.
#[test]
fn variance_factors_at_equal_total_time() {
    let ts = 1e-3;
    let n = 4;
    let total_periods = 8; // per input, summed over the experiments
    let spec = |periods| ms(5.0, 100.0, 200, periods, Grid::Full, Phases::Schroeder);
    let seq = MultiInputDesign::sequential(n, spec(total_periods / n))
        .generate(ts)
        .unwrap();
    let orth = MultiInputDesign::orthogonal(n, spec(total_periods / n))
        .generate(ts)
        .unwrap();
    let zip = MultiInputDesign::zipper(n, spec(total_periods))
        .generate(ts)
        .unwrap();
    assert_eq!(seq.total_duration_s(), orth.total_duration_s());
    assert_eq!(seq.total_duration_s(), zip.total_duration_s());
    // Σ over experiments and periods of |R_j,e(k)|² for a diagonal Σ R Rᴴ (all three designs).
    let gram_diag = |x: &ambid_core::signal::MultiExcitation, j: usize, k: usize| -> f64 {
        let mut g = 0.0;
        let mut cross = vec![Complex::new(0.0, 0.0); n];
        for e in 0..x.n_experiments() {
            for p in 0..x.periods() {
                let per =
                    |i: usize| naive_dft(&x.measured(e, i).unwrap()[p * 200..(p + 1) * 200])[k];
                let rj = per(j);
                g += rj.norm_sqr();
                for (i, c) in cross.iter_mut().enumerate() {
                    if i != j {
                        *c += per(i) * rj.conj();
                    }
                }
            }
        }
        let off: f64 = cross.iter().map(|c| c.norm()).sum();
        assert!(off < 1e-9 * g, "off-diagonal Gram {off} vs {g}");
        g
    };
    // Base bins 1..=20 (5 Hz lines); axis 3 of the zipper holds the indices 3, 7, … = bins 4, 8, ….
    let k = 8;
    assert!(zip.axis_bins()[3].contains(&k));
    for j in 0..n {
        let v_seq = 1.0 / gram_diag(&seq, j, k);
        let v_orth = 1.0 / gram_diag(&orth, j, k);
        assert!(
            (v_seq / v_orth - n as f64).abs() < 1e-9,
            "{}",
            v_seq / v_orth
        );
    }
    let v_seq = 1.0 / gram_diag(&seq, 3, k);
    let v_zip = 1.0 / gram_diag(&zip, 3, k);
    assert!(
        (v_seq / v_zip - (n * n) as f64).abs() < 1e-9,
        "{}",
        v_seq / v_zip
    );
}

#[test]
fn bad_input_gives_typed_errors() {
    let ts = 1e-3;
    let spec = ms(5.0, 100.0, 200, 1, Grid::Full, Phases::Schroeder);
    // 0 inputs.
    for kind in [
        MultiInputKind::Sequential,
        MultiInputKind::Orthogonal,
        MultiInputKind::Zipper,
    ] {
        let e = MultiInputDesign::new(kind, 0, spec.clone().into())
            .generate(ts)
            .unwrap_err();
        assert_eq!(invalid_name(e.clone()), "n_inputs");
        assert!(e.to_string().contains("at least one input"), "{e}");
    }
    // Too many inputs (sequential would need MAX_INPUTS + 1 experiments): refused before any
    // allocation, also by weights().
    let huge = MultiInputDesign::sequential(ambid_core::signal::MAX_INPUTS + 1, spec.clone());
    assert_eq!(invalid_name(huge.weights().unwrap_err()), "n_inputs");
    assert_eq!(invalid_name(huge.report(ts).unwrap_err()), "n_inputs");
    // More inputs than lines for a zipper (6 lines at 5 Hz spacing in 5..30 Hz, 7 inputs).
    let short = ms(5.0, 30.0, 200, 1, Grid::Full, Phases::Schroeder);
    let e = MultiInputDesign::zipper(7, short.clone())
        .report(ts)
        .unwrap_err();
    assert_eq!(invalid_name(e.clone()), "period_samples");
    assert!(e.to_string().contains("6 line(s) for 7 inputs"), "{e}");
    assert!(MultiInputDesign::zipper(6, short).report(ts).is_ok());
    // A period too short: 3 samples, or too short for any line of the band.
    let e = MultiInputDesign::orthogonal(
        2,
        MultisineSpec {
            period_samples: 3,
            ..spec.clone()
        },
    )
    .generate(ts)
    .unwrap_err();
    assert_eq!(invalid_name(e), "period_samples");
    let e = MultiInputDesign::sequential(
        2,
        MultisineSpec {
            period_samples: 8,
            f_min_hz: 10.0,
            f_max_hz: 100.0,
            ..spec.clone()
        },
    )
    .generate(ts)
    .unwrap_err();
    assert!(e.to_string().contains("increase period_samples"), "{e}");
    // Zipper on a PRBS.
    let e = MultiInputDesign::new(MultiInputKind::Zipper, 2, prbs(5, 1, 1).into())
        .generate(ts)
        .unwrap_err();
    assert_eq!(invalid_name(e.clone()), "base");
    assert!(e.to_string().contains("multisine"), "{e}");
    // Levels: wrong count, non-positive, non-finite.
    let e = MultiInputDesign::sequential(3, spec.clone())
        .with_levels(vec![1.0, 1.0])
        .generate(ts)
        .unwrap_err();
    assert!(matches!(e, Error::DimensionMismatch { .. }), "{e:?}");
    for bad in [0.0, -1.0, f64::NAN] {
        let e = MultiInputDesign::sequential(2, spec.clone())
            .with_levels(vec![1.0, bad])
            .generate(ts)
            .unwrap_err();
        assert_eq!(invalid_name(e), "levels");
    }
    // Bad sample time; too many samples.
    assert_eq!(
        invalid_name(
            MultiInputDesign::sequential(2, spec.clone())
                .generate(0.0)
                .unwrap_err()
        ),
        "ts"
    );
    let e = MultiInputDesign::orthogonal(4, prbs(20, 50, 10))
        .generate(ts)
        .unwrap_err();
    assert_eq!(invalid_name(e), "periods");
    // Axis names: 5 inputs have no default names; duplicates and wrong counts are refused.
    let x5 = MultiInputDesign::sequential(5, prbs(3, 1, 1))
        .generate(ts)
        .unwrap();
    assert_eq!(invalid_name(x5.to_iodata().unwrap_err()), "axes");
    assert!(x5.to_iodata_with_axes(&["a", "b", "c", "d", "e"]).is_ok());
    assert_eq!(
        invalid_name(
            x5.to_iodata_with_axes(&["a", "b", "c", "d", "a"])
                .unwrap_err()
        ),
        "axes"
    );
    assert_eq!(
        invalid_name(x5.to_iodata_with_axes(&["a", "b"]).unwrap_err()),
        "axes"
    );
    assert_eq!(
        invalid_name(x5.channels(5, &["a", "b", "c", "d", "e"]).unwrap_err()),
        "experiment"
    );
}

#[test]
fn serde_round_trip() {
    let d = MultiInputDesign::orthogonal(3, prbs(6, 2, 3))
        .with_levels(vec![0.1, 0.2, 0.3])
        .with_transient_periods(2);
    let json = serde_json::to_string(&d).unwrap();
    assert!(
        json.contains(r#""kind":"orthogonal""#) && json.contains(r#""kind":"prbs""#),
        "{json}"
    );
    let back: MultiInputDesign = serde_json::from_str(&json).unwrap();
    assert_eq!(back, d);
    // levels and transient_periods default.
    let z: MultiInputDesign = serde_json::from_str(
        r#"{"kind":"zipper","n_inputs":2,"base":{"kind":"multisine","f_min_hz":1.0,"f_max_hz":10.0,
            "period_samples":100,"periods":1,"rms":1.0,"grid":"full","phases":"schroeder","seed":0}}"#,
    )
    .unwrap();
    assert_eq!((z.levels.clone(), z.transient_periods), (None, 0));
    assert_eq!(z.axis_bins(0.01).unwrap()[1], vec![2, 4, 6, 8, 10]);
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig {
        cases: 300,
        rng_seed: proptest::test_runner::RngSeed::Fixed(20),
        ..proptest::prelude::ProptestConfig::default()
    })]

    /// Hostile fields never panic: every design, report and IoData either works or returns a
    /// typed error; when it works the zipper's lines partition the base grid and cond ≥ 1.
    #[test]
    fn never_panics(
        kind in 0usize..3,
        n in 0usize..7,
        use_prbs in proptest::bool::ANY,
        period in 0usize..80,
        f_lo in -10.0f64..60.0,
        f_hi in -10.0f64..60.0,
        order in 0u32..8,
        nb in 0usize..4,
        periods in 0usize..3,
        transient in 0usize..3,
        level in -1.0f64..2.0,
        levels in proptest::collection::vec(-0.5f64..2.0, 0..6),
        ts in proptest::prop_oneof![proptest::strategy::Just(f64::NAN), proptest::strategy::Just(0.0), 1e-3f64..2e-2],
        grid in 0usize..3,
        random in proptest::bool::ANY,
        with_levels in proptest::bool::ANY,
    ) {
        let kind = [MultiInputKind::Sequential, MultiInputKind::Orthogonal, MultiInputKind::Zipper][kind];
        let base: BaseSignal = if use_prbs {
            PrbsSpec { order, samples_per_bit: nb, periods, amplitude: level, offset: 0.0 }.into()
        } else {
            MultisineSpec {
                f_min_hz: f_lo, f_max_hz: f_hi, period_samples: period, periods, rms: level,
                grid: [Grid::Full, Grid::Odd, Grid::RandomOdd][grid],
                phases: if random { Phases::Random } else { Phases::Schroeder }, seed: 3,
            }.into()
        };
        let mut d = MultiInputDesign::new(kind, n, base.clone()).with_transient_periods(transient);
        if with_levels {
            d = d.with_levels(levels);
        }
        if let Ok(r) = d.report(ts) {
            let x = d.generate(ts).unwrap();
            proptest::prop_assert_eq!(r.experiments, x.n_experiments());
            for c in &r.condition {
                proptest::prop_assert!(c.cond >= 1.0 - 1e-9);
            }
            if kind == MultiInputKind::Zipper {
                let mut all: Vec<usize> = x.axis_bins().iter().flatten().copied().collect();
                all.sort_unstable();
                proptest::prop_assert_eq!(all, base.bins(ts).unwrap());
            }
            let _ = x.to_iodata();
        }
    }
}
