//! Speed of the MIMO closed-loop FRF ([`ambid_core::frf::mimo`]) on the size of the issue's
//! bar: 4 experiments (an orthogonal design) × 102 300 samples (20 periods of 5 115) of 12
//! channels (r, u, y of the axes xa, xb, ya, yb), in two shapes:
//!
//! * multisine: 1 023 excited lines of the 2 558 (10 kHz);
//! * PRBS (`*_prbs`): the twin's default excitation as `ambid simulate` writes it, order 10,
//!   5 samples per bit (period 5 115 at 20 kHz), 20 periods, ± the same PRBS on every axis
//!   with the signs of a Hadamard matrix; every line but the sinc nulls (2 555) excited.
//!
//! * `mimo_4x4_orthogonal`: [`periodic`] (period averages and covariances of every channel,
//!   then T_ry, S, P with variances, coherences and condition numbers per line);
//! * `rfft_all_channels`: one realfft forward transform of each of the 48 channel records
//!   (4 experiments × 12 channels × 102 300 samples), the reference of the bar (≤ 3×);
//! * `siso_periodic_frf`: today's SISO periodic closed-loop FRF of one experiment
//!   ([`PeriodicAnalyzer`] on r, u, y and [`from_periodic`]), the other reference (≤ 4× per
//!   experiment);
//! * `analysis_12_channels`: [`PeriodicAnalyzer::analyze`] of the 12 channels of one
//!   experiment (every pair's covariance), a piece of the MIMO cost.
//!
//! Run: `cargo bench -p ambid-core --bench mimo_frf`.

use ambid_core::data::IoData;
use ambid_core::frf::closed_loop::{from_periodic, Channels};
use ambid_core::frf::lpm::{lpm_closed_loop, LpmOptions};
use ambid_core::frf::mimo::{periodic, MimoOptions};
use ambid_core::frf::mimo_lpm::{local_polynomial, MimoLpmOptions};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
use ambid_core::signal::prbs_period;
use divan::{black_box, Bencher};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use realfft::RealFftPlanner;

const N: usize = 5115;
const PERIODS: usize = 20;
const FS: f64 = 10_000.0;
const FS_PRBS: f64 = 20_000.0;
/// Lines excited by the PRBS: all but DC and the sinc nulls at 1 023 and 2 046.
const LINES_PRBS: usize = 2555;
const LINES: usize = 1023;
const AXES: [&str; 4] = ["xa", "xb", "ya", "yb"];
const H4: [[f64; 4]; 4] = [
    [1.0, 1.0, 1.0, 1.0],
    [1.0, -1.0, 1.0, -1.0],
    [1.0, 1.0, -1.0, -1.0],
    [1.0, -1.0, -1.0, 1.0],
];

fn main() {
    divan::main();
}

/// One period of the multisine on lines 1..=1023 (Schroeder-like phases).
fn multisine() -> Vec<f64> {
    let phases: Vec<f64> = (0..LINES)
        .map(|k| (k * k) as f64 * std::f64::consts::PI / LINES as f64)
        .collect();
    let one: Vec<f64> = (0..N)
        .map(|t| {
            (1..=LINES)
                .map(|k| {
                    (2.0 * std::f64::consts::PI * (k * t % N) as f64 / N as f64 + phases[k - 1])
                        .cos()
                })
                .sum::<f64>()
                / (LINES as f64).sqrt()
        })
        .collect();
    one
}

/// One period of the default PRBS: order 10, 5 samples per bit (5 115 samples).
fn prbs() -> Vec<f64> {
    let p: Vec<f64> = prbs_period(10)
        .unwrap()
        .iter()
        .flat_map(|&b| std::iter::repeat_n(f64::from(b), 5))
        .collect();
    assert_eq!(p.len(), N);
    p
}

/// An orthogonal 4-experiment record: r = ±`one` (repeated), u and y fixed FIR mixes of r plus
/// noise.
fn record(one: &[f64], fs: f64) -> IoData {
    let mut rng = ChaCha8Rng::seed_from_u64(20);
    let len = N * PERIODS;
    let ms: Vec<f64> = (0..len).map(|t| one[t % N]).collect();
    let exps: Vec<IoData> = (0..4)
        .map(|e| {
            let r: Vec<Vec<f64>> = (0..4)
                .map(|j| ms.iter().map(|v| H4[e][j] * v).collect())
                .collect();
            let mut ch = Vec::new();
            let mut u = Vec::new();
            let mut y = Vec::new();
            for i in 0..4 {
                let mut ui = vec![0.0; len];
                let mut yi = vec![0.0; len];
                for t in 2..len {
                    let g1: f64 = StandardNormal.sample(&mut rng);
                    let g2: f64 = StandardNormal.sample(&mut rng);
                    ui[t] = r[i][t] - 0.3 * r[(i + 1) % 4][t - 1] + 0.01 * g1;
                    yi[t] = 0.5 * r[i][t - 1] + 0.2 * r[(i + 2) % 4][t - 2] + 0.01 * g2;
                }
                u.push(ui);
                y.push(yi);
            }
            for (l, s) in [("r", &r), ("u", &u), ("y", &y)] {
                for (i, v) in s.iter().enumerate() {
                    ch.push((format!("{l}_{}", AXES[i]), v.clone()));
                }
            }
            IoData::new(ch, 1.0 / fs, Some(N)).unwrap()
        })
        .collect();
    IoData::from_experiments(exps).unwrap()
}

fn data() -> IoData {
    record(&multisine(), FS)
}

fn data_prbs() -> IoData {
    record(&prbs(), FS_PRBS)
}

fn bench_mimo(bencher: Bencher, d: &IoData, lines: usize) {
    let o = MimoOptions::new();
    bencher.bench_local(|| {
        let f = periodic(black_box(d), &o).unwrap();
        assert_eq!(f.lines.len(), lines);
        f
    });
}

fn bench_siso(bencher: Bencher, d: &IoData, fs: f64) {
    let ch: Vec<&[f64]> = ["r_xa", "u_xa", "y_xa"]
        .iter()
        .map(|c| d.channel(c).unwrap())
        .collect();
    bencher.bench_local(|| {
        let s = PeriodicAnalyzer::new(N)
            .unwrap()
            .analyze(black_box(&ch), fs, &PeriodicOptions::new(N))
            .unwrap();
        let lines = s.excited_lines(0, 1e-6).unwrap();
        from_periodic(&s, Channels { r: 0, u: 1, y: 2 }, &lines, None).unwrap()
    });
}

#[divan::bench(sample_count = 10)]
fn mimo_4x4_orthogonal(bencher: Bencher) {
    bench_mimo(bencher, &data(), LINES);
}

#[divan::bench(sample_count = 10)]
fn mimo_4x4_orthogonal_prbs(bencher: Bencher) {
    bench_mimo(bencher, &data_prbs(), LINES_PRBS);
}

#[divan::bench(sample_count = 10)]
fn siso_periodic_frf(bencher: Bencher) {
    bench_siso(bencher, &data(), FS);
}

#[divan::bench(sample_count = 10)]
fn siso_periodic_frf_prbs(bencher: Bencher) {
    bench_siso(bencher, &data_prbs(), FS_PRBS);
}

#[divan::bench(sample_count = 10)]
fn analysis_12_channels(bencher: Bencher) {
    let d = data_prbs();
    let e = d.experiment(0).unwrap();
    let ch: Vec<&[f64]> = ["r", "u", "y"]
        .iter()
        .flat_map(|l| AXES.iter().map(move |a| format!("{l}_{a}")))
        .map(|c| e.channel(&c).unwrap())
        .collect();
    bencher.bench_local(|| {
        PeriodicAnalyzer::new(N)
            .unwrap()
            .analyze(black_box(&ch), FS_PRBS, &PeriodicOptions::new(N))
            .unwrap()
    });
}

#[divan::bench(sample_count = 10)]
fn rfft_all_channels(bencher: Bencher) {
    let d = data();
    let records: Vec<Vec<f64>> = (0..4)
        .flat_map(|e| {
            d.experiment(e)
                .unwrap()
                .into_channels()
                .into_iter()
                .map(|(_, v)| v)
        })
        .collect();
    assert_eq!(records.len(), 48);
    let fft = RealFftPlanner::<f64>::new().plan_fft_forward(N * PERIODS);
    let mut inp = fft.make_input_vec();
    let mut out = fft.make_output_vec();
    let mut scratch = fft.make_scratch_vec();
    bencher.bench_local(|| {
        for x in &records {
            inp.copy_from_slice(x);
            fft.process_with_scratch(&mut inp, &mut out, &mut scratch)
                .unwrap();
            black_box(&out);
        }
    });
}

/// One non-periodic experiment of 102 300 samples at 20 kHz: four independent white-noise
/// excitations, u and y the same FIR mixes of r plus noise as [`record`].
fn data_noise() -> IoData {
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let len = N * PERIODS;
    let r: Vec<Vec<f64>> = (0..4)
        .map(|_| (0..len).map(|_| StandardNormal.sample(&mut rng)).collect())
        .collect();
    let mut ch = Vec::new();
    let (mut u, mut y) = (Vec::new(), Vec::new());
    for i in 0..4 {
        let mut ui = vec![0.0; len];
        let mut yi = vec![0.0; len];
        for t in 2..len {
            let g1: f64 = StandardNormal.sample(&mut rng);
            let g2: f64 = StandardNormal.sample(&mut rng);
            ui[t] = r[i][t] - 0.3 * r[(i + 1) % 4][t - 1] + 0.01 * g1;
            yi[t] = 0.5 * r[i][t - 1] + 0.2 * r[(i + 2) % 4][t - 2] + 0.01 * g2;
        }
        u.push(ui);
        y.push(yi);
    }
    for (l, s) in [("r", &r), ("u", &u), ("y", &y)] {
        for (i, v) in s.iter().enumerate() {
            ch.push((format!("{l}_{}", AXES[i]), v.clone()));
        }
    }
    IoData::new(ch, 1.0 / FS_PRBS, None).unwrap()
}

/// The multivariable local polynomial method (`frf::mimo_lpm`, defaults: R = 2, 19-line
/// window) on the 4×4 noise record, lines up to 2 kHz (10 230 lines).
#[divan::bench(sample_count = 10)]
fn mimo_lpm_4x4_to_2khz(bencher: Bencher) {
    let d = data_noise();
    let o = MimoLpmOptions::new().band(0.0, 2000.0);
    bencher.bench_local(|| local_polynomial(black_box(&d), &o).unwrap());
}

/// Today's SISO closed-loop LPM (`lpm_closed_loop`, default 9-line window) on axis xa of the
/// same record and band, the reference.
#[divan::bench(sample_count = 10)]
fn siso_lpm_to_2khz(bencher: Bencher) {
    let d = data_noise();
    let (r, u, y) = (
        d.channel("r_xa").unwrap(),
        d.channel("u_xa").unwrap(),
        d.channel("y_xa").unwrap(),
    );
    bencher.bench_local(|| {
        lpm_closed_loop(
            black_box(r),
            u,
            y,
            FS_PRBS,
            (0.0, 2000.0),
            &LpmOptions::default(),
        )
        .unwrap()
    });
}
