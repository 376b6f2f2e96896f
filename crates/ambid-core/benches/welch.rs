//! Speed and memory of the streaming Welch estimator, and the reference FFT time.
//!
//! * `welch_3ch_1e7`: all 6 auto and cross spectra of 3 channels over $10^7$ samples per channel
//!   (500 s at 20 kHz), `nperseg` 4096, Hann, 50 % overlap (4 881 segments, 14 643 FFTs of 4096
//!   points), streamed in chunks of 65 536 samples that are generated on the fly, so neither the
//!   bench nor the estimator ever holds the record (3 × 10⁷ f64 would be 240 MB).
//! * `generate_only_3ch_1e7`: the same chunks without the estimator, to subtract.
//! * `fft_102300`: one realfft forward transform of a 102 300-sample real record (the seed
//!   experiment's length: PRBS order 10, 5 samples per bit, 20 periods), input copy excluded.
//!
//! Before the benches run, `main` streams the same $3 \times 10^7$ samples once and prints the
//! accumulator's own heap ([`WelchAccumulator::heap_bytes`]) and the process's peak resident set
//! (`VmHWM` in `/proc/self/status`) before and after: the peak does not grow with the record.
//!
//! Run: `cargo bench -p ambid-core --bench welch`.
//!
//! Measured (shared 2-core AMD EPYC VM with other builds running, load average 5; release profile,
//! default target CPU; medians of two runs, 2026-11-21): `welch_3ch_1e7` 211 ms and 270 ms (fastest
//! sample 210 ms), of which generating the chunks is `generate_only_3ch_1e7` 43 ms: the estimator
//! itself takes ≈ 170–225 ms, 5.6–7.5 ns per sample and channel, ≈ 2 000× real time at 20 kHz
//! (≈ 40 % in the FFTs, the rest in copying, detrending, windowing and the 6 product sums).
//! `fft_102300` 0.43 ms. Accumulator heap 458 kB; peak RSS (`VmHWM`) grows by 64 kB while the
//! 3 × 10⁷ samples stream through (the first touch of the accumulator's zeroed buffers), not with
//! the record.

use ambid_core::frf::welch::{WelchAccumulator, WelchOptions};
use divan::{black_box, Bencher};
use realfft::RealFftPlanner;

const TOTAL: usize = 10_000_000;
const CHUNK: usize = 65_536;
const NPERSEG: usize = 4096;
const FS: f64 = 20_000.0;
const RECORD: usize = 102_300;

fn main() {
    if !std::env::args().any(|a| a == "--test") {
        report_memory();
    }
    divan::main();
}

/// Three correlated low-passed noise channels from an xorshift64* generator: cheap (≈ 2 ns per
/// sample and channel) and deterministic.
struct Source {
    state: u64,
    lp: [f64; 3],
}

impl Source {
    fn new(seed: u64) -> Self {
        Self {
            state: seed | 1,
            lp: [0.0; 3],
        }
    }

    fn uniform(&mut self) -> f64 {
        self.state ^= self.state >> 12;
        self.state ^= self.state << 25;
        self.state ^= self.state >> 27;
        let r = self.state.wrapping_mul(0x2545_f491_4f6c_dd1d);
        (r >> 11) as f64 * (1.0 / (1u64 << 53) as f64) - 0.5
    }

    /// Fills the first `n` samples of each buffer.
    fn fill(&mut self, bufs: &mut [Vec<f64>; 3], n: usize) {
        let [a, b, c] = bufs;
        for ((a, b), c) in a[..n].iter_mut().zip(&mut b[..n]).zip(&mut c[..n]) {
            let e = self.uniform();
            self.lp[0] = 0.5 * self.lp[0] + e;
            self.lp[1] = 0.9 * self.lp[1] + 0.3 * self.lp[0] + 0.1 * self.uniform();
            self.lp[2] = -0.6 * self.lp[2] + e;
            (*a, *b, *c) = (self.lp[0], self.lp[1], self.lp[2]);
        }
    }
}

fn options() -> WelchOptions {
    WelchOptions::new(FS, NPERSEG)
}

fn chunk_buffers() -> [Vec<f64>; 3] {
    [vec![0.0; CHUNK], vec![0.0; CHUNK], vec![0.0; CHUNK]]
}

/// Streams the whole record through `acc` (or only generates it when `acc` is `None`), one chunk
/// at a time in `bufs`.
fn stream(mut acc: Option<&mut WelchAccumulator>, bufs: &mut [Vec<f64>; 3]) -> f64 {
    let mut src = Source::new(1);
    let mut left = TOTAL;
    let mut check = 0.0;
    while left > 0 {
        let n = left.min(CHUNK);
        src.fill(bufs, n);
        match acc.as_deref_mut() {
            Some(a) => a
                .push(&[&bufs[0][..n], &bufs[1][..n], &bufs[2][..n]])
                .expect("finite chunks of equal length"),
            None => check += bufs[2][n - 1],
        }
        left -= n;
    }
    check
}

#[divan::bench(sample_count = 10)]
fn welch_3ch_1e7(bencher: Bencher) {
    let opts = options();
    bencher.bench(|| {
        let mut acc = WelchAccumulator::new(3, &opts).expect("valid options");
        stream(Some(&mut acc), &mut chunk_buffers());
        black_box(acc.finish().expect("segments"))
    });
}

#[divan::bench(sample_count = 10)]
fn generate_only_3ch_1e7(bencher: Bencher) {
    bencher.bench(|| black_box(stream(None, &mut chunk_buffers())));
}

#[divan::bench(sample_count = 100)]
fn fft_102300(bencher: Bencher) {
    let fft = RealFftPlanner::<f64>::new().plan_fft_forward(RECORD);
    let mut src = Source::new(7);
    let x: Vec<f64> = (0..RECORD).map(|_| src.uniform()).collect();
    let mut out = fft.make_output_vec();
    let mut scratch = fft.make_scratch_vec();
    bencher.with_inputs(|| x.clone()).bench_local_refs(|buf| {
        fft.process_with_scratch(buf, &mut out, &mut scratch)
            .expect("buffer lengths from the plan");
        black_box(out[1])
    });
}

/// Peak resident set size in kB (Linux), if available.
fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

fn report_memory() {
    let opts = options();
    let mut acc = WelchAccumulator::new(3, &opts).expect("valid options");
    // the chunk buffers (3 × 512 kB) exist before the measurement starts, and are touched
    let mut bufs = chunk_buffers();
    Source::new(2).fill(&mut bufs, CHUNK);
    let before = peak_rss_kb();
    stream(Some(&mut acc), &mut bufs);
    let after = peak_rss_kb();
    let s = acc.finish().expect("segments");
    eprintln!(
        "welch memory: 3 channels × {TOTAL} samples streamed ({} segments); accumulator heap {} kB \
         (the record would be {} MB)",
        s.n_segments(),
        acc.heap_bytes() / 1000,
        3 * TOTAL * 8 / 1_000_000
    );
    match (before, after) {
        (Some(b), Some(a)) => eprintln!(
            "welch memory: peak RSS (VmHWM) {b} kB before streaming, {a} kB after (+{} kB)",
            a.saturating_sub(b)
        ),
        _ => eprintln!("welch memory: /proc/self/status not available, peak RSS not measured"),
    }
}
