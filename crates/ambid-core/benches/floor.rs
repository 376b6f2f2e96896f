//! The physical floor the other benchmark figures are measured against (issue 9): the cost of one
//! real FFT of a whole record and of one Householder QR of the largest ARX regressor. No
//! identification algorithm that looks at every sample in the frequency domain can beat one FFT
//! of the record, and no order scan that reduces the full regressor by orthogonal
//! transformations can beat one QR of it, so docs/benchmarks.md also quotes each figure as a
//! multiple of these.
//!
//! * `fft_102300`, `fft_1e6`: one realfft forward transform of a 102 300-sample (the seed record)
//!   and of a 1 002 540-sample record (196 periods, the long record of `bench/compare`), planned
//!   outside, input copy excluded;
//! * `qr_1e5x41`: one in-place Householder QR (faer, blocked, sequential) of the
//!   $10^5 \times 41$ matrix $[\Phi\ Y]$ of the ARX scan na, nb = 1..20 (the largest regressor of
//!   `cargo bench --bench arx`), copy excluded;
//! * `qr_102300x21`: the same for the $n_a = n_b = 10$ scan of the seed record.
//!
//! Data: uniform noise from an xorshift generator (the timing does not depend on the values).
//!
//! Run: `cargo bench -p ambid-core --bench floor`.

use divan::{black_box, Bencher};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::factor;
use faer::{Mat, Par};
use realfft::RealFftPlanner;

fn main() {
    divan::main();
}

fn noise(n: usize, seed: u64) -> Vec<f64> {
    let mut s = seed | 1;
    (0..n)
        .map(|_| {
            s ^= s >> 12;
            s ^= s << 25;
            s ^= s >> 27;
            (s.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        })
        .collect()
}

fn fft(bencher: Bencher, n: usize) {
    let plan = RealFftPlanner::<f64>::new().plan_fft_forward(n);
    let x = noise(n, 3);
    let mut out = plan.make_output_vec();
    let mut scratch = plan.make_scratch_vec();
    bencher.with_inputs(|| x.clone()).bench_local_refs(|buf| {
        plan.process_with_scratch(buf, &mut out, &mut scratch)
            .expect("buffer lengths from the plan");
        black_box(out[1])
    });
}

#[divan::bench(sample_count = 100)]
fn fft_102300(bencher: Bencher) {
    fft(bencher, 102_300);
}

#[divan::bench(sample_count = 30)]
fn fft_1e6(bencher: Bencher) {
    fft(bencher, 1_002_540);
}

fn qr(bencher: Bencher, m: usize, n: usize) {
    let x = noise(m * n, 5);
    let a = Mat::from_fn(m, n, |i, j| x[i + m * j]);
    let bs = factor::recommended_block_size::<f64>(m, n);
    let mut coeff = Mat::<f64>::zeros(bs, n);
    let mut mem = MemBuffer::new(factor::qr_in_place_scratch::<f64>(
        m,
        n,
        bs,
        Par::Seq,
        Default::default(),
    ));
    bencher.with_inputs(|| a.clone()).bench_local_refs(|a| {
        factor::qr_in_place(
            a.as_mut(),
            coeff.as_mut(),
            Par::Seq,
            MemStack::new(&mut mem),
            Default::default(),
        );
        black_box(a[(0, 0)])
    });
}

#[divan::bench(sample_count = 20)]
fn qr_1e5x41(bencher: Bencher) {
    qr(bencher, 100_000, 41);
}

#[divan::bench(sample_count = 20)]
fn qr_102300x21(bencher: Bencher) {
    qr(bencher, 102_300, 21);
}
