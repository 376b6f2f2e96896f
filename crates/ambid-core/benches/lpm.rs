//! Speed of the Local Polynomial Method ([`ambid_core::frf::lpm`]) on $10^5$ samples, every DFT
//! line up to $f_s/2$ ($5\cdot 10^4$ lines), default options ($R = 2$, $n = 4$, $q = 3$).
//!
//! * `lpm_siso_1e5`: one input, one output (two real FFTs plus 5·10⁴ local fits);
//! * `lpm_simo2_1e5`: one input, two outputs (the closed-loop form r → [y, u]);
//! * `lpm_closed_loop_1e5`: [`lpm_closed_loop`] (the SIMO fit plus T_ry, S, the plant and
//!   their variances as `Frd`s);
//! * `lrm_closed_loop_1e5`: the Local Rational Method ([`ambid_core::frf::lrm`], degrees
//!   (2, 2, 2), n = 6) in the same closed-loop form;
//! * `fft_1e5`: one realfft forward transform of the 10⁵-sample record, for reference.
//!
//! Run: `cargo bench -p ambid-core --bench lpm`. Measured numbers are in docs/lpm.md.

use ambid_core::frf::lpm::{lpm, lpm_closed_loop, LpmOptions};
use ambid_core::frf::lrm::{lrm_closed_loop, LrmOptions};
use divan::{black_box, Bencher};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use realfft::RealFftPlanner;

const N: usize = 100_000;
const FS: f64 = 20_000.0;

fn main() {
    divan::main();
}

fn data() -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut g = || -> f64 { StandardNormal.sample(&mut rng) };
    let u: Vec<f64> = (0..N).map(|_| g()).collect();
    // y: a first-order system plus noise; v: another output
    let mut y = vec![0.0; N];
    let mut v = vec![0.0; N];
    for t in 1..N {
        y[t] = 0.9 * y[t - 1] + 0.1 * u[t - 1] + 0.01 * g();
        v[t] = u[t] - 0.5 * y[t] + 0.01 * g();
    }
    (u, y, v)
}

#[divan::bench(sample_count = 20)]
fn lpm_siso_1e5(bencher: Bencher) {
    let (u, y, _) = data();
    let o = LpmOptions::default();
    bencher.bench_local(|| lpm(black_box(&u), &[black_box(&y)], FS, (0.0, FS / 2.0), &o).unwrap());
}

#[divan::bench(sample_count = 20)]
fn lpm_simo2_1e5(bencher: Bencher) {
    let (u, y, v) = data();
    let o = LpmOptions::default();
    bencher.bench_local(|| {
        lpm(
            black_box(&u),
            &[black_box(&y), black_box(&v)],
            FS,
            (0.0, FS / 2.0),
            &o,
        )
        .unwrap()
    });
}

#[divan::bench(sample_count = 20)]
fn lpm_closed_loop_1e5(bencher: Bencher) {
    let (r, y, u) = data();
    let o = LpmOptions::default();
    bencher
        .bench_local(|| lpm_closed_loop(black_box(&r), &u, &y, FS, (0.0, FS / 2.0), &o).unwrap());
}

#[divan::bench(sample_count = 100)]
fn fft_1e5(bencher: Bencher) {
    let (u, _, _) = data();
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(N);
    let mut input = u.clone();
    let mut out = fft.make_output_vec();
    bencher.bench_local(|| {
        input.copy_from_slice(&u);
        fft.process(&mut input, &mut out).unwrap();
        black_box(&out);
    });
}

#[divan::bench(sample_count = 10)]
fn lrm_closed_loop_1e5(bencher: Bencher) {
    let (u, y, v) = data();
    let o = LrmOptions::default();
    bencher.bench_local(|| {
        lrm_closed_loop(
            black_box(&u),
            black_box(&v),
            black_box(&y),
            FS,
            (1.0, FS / 2.0),
            &o,
        )
        .unwrap()
    });
}
