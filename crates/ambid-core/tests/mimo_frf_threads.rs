//! `frf::mimo::periodic` (the path made fast in issue 20: excited lines first from r, selected
//! period covariances folded in blocks of periods, per-line Jacobi SVD in a per-task
//! workspace) gives the same numbers, bit for bit, on 1 and on 3 rayon threads, and its
//! T_ry, S and P equal an independent oracle built from the public period averages
//! ([`PeriodicAnalyzer`]) and `Frd::divide` (faer's solve): with M = n_r experiments,
//! T = Y R⁻¹, S = U R⁻¹, P = Y U⁻¹ per line.
//!
//! Record: 4 experiments of the orthogonal design (± a PRBS of order 7, 2 samples per bit,
//! period 254) on 4 axes, 24 periods with 1 skipped (23 analysed: one full block of 16
//! deviations and a partial one), u and y fixed FIR mixes of r plus noise. Debug run ≈ 1 s.

use ambid_core::data::IoData;
use ambid_core::frf::mimo::{periodic, MimoOptions};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
use ambid_core::lti::Frd;
use ambid_core::signal::prbs_period;
use faer::c64;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

const AXES: [&str; 4] = ["xa", "xb", "ya", "yb"];
const H4: [[f64; 4]; 4] = [
    [1.0, 1.0, 1.0, 1.0],
    [1.0, -1.0, 1.0, -1.0],
    [1.0, 1.0, -1.0, -1.0],
    [1.0, -1.0, -1.0, 1.0],
];
const PERIODS: usize = 24;
const FS: f64 = 5000.0;

fn one_period() -> Vec<f64> {
    prbs_period(7)
        .unwrap()
        .iter()
        .flat_map(|&b| std::iter::repeat_n(f64::from(b), 2))
        .collect()
}

fn record() -> IoData {
    let one = one_period();
    let n = one.len();
    let len = n * PERIODS;
    let mut rng = ChaCha8Rng::seed_from_u64(2020);
    let exps: Vec<IoData> = (0..4)
        .map(|e| {
            let r: Vec<Vec<f64>> = (0..4)
                .map(|j| (0..len).map(|t| H4[e][j] * one[t % n]).collect())
                .collect();
            let mut u = Vec::new();
            let mut y = Vec::new();
            for i in 0..4 {
                let mut ui = vec![0.0; len];
                let mut yi = vec![0.0; len];
                for t in 2..len {
                    let g1: f64 = StandardNormal.sample(&mut rng);
                    let g2: f64 = StandardNormal.sample(&mut rng);
                    ui[t] = r[i][t] - 0.3 * r[(i + 1) % 4][t - 1] + 0.05 * g1;
                    yi[t] = 0.5 * r[i][t - 1] + 0.2 * r[(i + 2) % 4][t - 2] - 0.1 * ui[t - 1]
                        + 0.05 * g2;
                }
                u.push(ui);
                y.push(yi);
            }
            let mut ch = Vec::new();
            for (l, s) in [("r", &r), ("u", &u), ("y", &y)] {
                for (i, v) in s.iter().enumerate() {
                    ch.push((format!("{l}_{}", AXES[i]), v.clone()));
                }
            }
            IoData::new(ch, 1.0 / FS, Some(n)).unwrap()
        })
        .collect();
    IoData::from_experiments(exps).unwrap()
}

#[test]
fn same_numbers_on_any_thread_count_and_equal_to_the_oracle() {
    let d = record();
    let o = MimoOptions::new().skip(1);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| periodic(&d, &o).unwrap())
    };
    let a = run(1);
    let b = run(3);
    assert_eq!(a, b, "the estimate depends on the thread count");
    let n = one_period().len();
    // the PRBS of order 7 with 2 samples/bit excites every line but DC and the sinc null 127
    let want: Vec<usize> = (1..=n / 2).filter(|&k| k != 127).collect();
    assert_eq!(a.lines, want);
    assert_eq!(a.periods, PERIODS - 1);

    // oracle: period means from the public analyser, P = Y U⁻¹ and T = Y R⁻¹ by Frd::divide
    let means: Vec<Vec<Vec<c64>>> = (0..4)
        .map(|e| {
            let x = d.experiment(e).unwrap();
            let names: Vec<String> = ["r", "u", "y"]
                .iter()
                .flat_map(|l| AXES.iter().map(move |a| format!("{l}_{a}")))
                .collect();
            let ch: Vec<&[f64]> = names.iter().map(|c| x.channel(c).unwrap()).collect();
            let s = PeriodicAnalyzer::new(n)
                .unwrap()
                .analyze(&ch, FS, &PeriodicOptions::new(n).skip(1))
                .unwrap();
            (0..12).map(|c| s.mean(c).to_vec()).collect()
        })
        .collect();
    let stack = |off: usize| -> Frd {
        let v: Vec<c64> = a
            .lines
            .iter()
            .flat_map(|&k| {
                let means = &means;
                // column e (experiment), row i (channel off + i): column-major per line
                (0..4).flat_map(move |e| (0..4).map(move |i| means[e][off + i][k]))
            })
            .collect();
        Frd::new_matrix(a.f_hz().to_vec(), 4, 4, v, None, Some(1.0 / FS)).unwrap()
    };
    let (r, u, y) = (stack(0), stack(4), stack(8));
    let checks = [
        ("P = Y U⁻¹", &a.plant, y.divide(&u).unwrap()),
        ("T = Y R⁻¹", &a.t_ry, y.divide(&r).unwrap()),
        ("S = U R⁻¹", &a.s, u.divide(&r).unwrap()),
    ];
    for (what, est, oracle) in checks {
        let mut worst = 0.0f64;
        for l in 0..a.lines.len() {
            let (e, o) = (est.at(l).unwrap(), oracle.at(l).unwrap());
            let scale = (0..4)
                .flat_map(|i| (0..4).map(move |j| (i, j)))
                .map(|(i, j)| o[(i, j)].norm())
                .fold(0.0f64, f64::max);
            for i in 0..4 {
                for j in 0..4 {
                    worst = worst.max((e[(i, j)] - o[(i, j)]).norm() / scale);
                }
            }
        }
        assert!(worst < 1e-12, "{what}: {worst:e}");
        eprintln!("{what}: largest difference {worst:.2e} of the line's largest entry");
    }
}
