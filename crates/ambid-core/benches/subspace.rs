//! Speed and memory of subspace identification on a record of the seed experiment's length.
//!
//! * `n4sid_order8_102300`: [`n4sid_detailed`] with the default options (CVA weighting,
//!   $i = 30$ block rows, B and D by the simulation regression, Kalman gain from the DARE), order 8,
//!   on 102 300 samples (PRBS order 10 × 5 samples per bit × 20 periods) of a synthetic SISO
//!   system with three lightly damped modes and two real poles, white input, 2 % output noise.
//! * `n4sid_order8_102300_projection`: the same with `BdMethod::Projection` (no simulation
//!   regression): the difference is the cost of that extra pass.
//!
//! Before the benches run, `main` identifies once and prints the peak resident set (`VmHWM` in
//! `/proc/self/status`) before and after, next to the size the block-Hankel matrices would have.
//!
//! Run: `cargo bench -p ambid-core --bench subspace`.
//!
//! Measured (shared 2-core AMD EPYC VM with other builds running, load average ≈ 6; release
//! profile, default target CPU; 2026-11-21): `n4sid_order8_102300` median 276 ms (fastest 244 ms),
//! `n4sid_order8_102300_projection` median 235 ms (fastest 195 ms): the streaming QR of the
//! $102\,241 \times 120$ Hankel data ($\approx 3 \cdot 10^9$ flops) dominates, the simulation
//! regression and the predictor pass add ≈ 40 ms. Peak RSS (`VmHWM`) grows by 1.4 MB during one
//! identification (the $1\,080 \times 120$ working matrix of the streaming QR and small buffers),
//! against 98 MB for the block-Hankel matrix that is never formed; the record itself is 1.6 MB.
//! For comparison, nfoursid 1.0.2 cannot run this case: its order step takes a full SVD of a
//! $102\,271 \times 102\,271$ matrix (78 GiB).

use ambid_core::estimate::subspace::{n4sid_detailed, BdMethod, SubspaceOptions};
use ambid_core::lti::StateSpace;
use ambid_core::signal::{Distribution, NoiseSpec};
use divan::{black_box, Bencher};
use faer::{Mat, MatRef};

const N: usize = 102_300;
const TS: f64 = 5e-5;

fn main() {
    if !std::env::args().any(|a| a == "--test") {
        report_memory();
    }
    divan::main();
}

fn rot(r: f64, th: f64) -> [[f64; 2]; 2] {
    [[r * th.cos(), r * th.sin()], [-r * th.sin(), r * th.cos()]]
}

/// Order 8: poles $0.995 e^{\pm 0.06j}$, $0.99 e^{\pm 0.35j}$, $0.985 e^{\pm 1.2j}$, 0.8, −0.4.
fn system() -> StateSpace {
    let blocks = [
        rot(0.995, 0.06),
        rot(0.99, 0.35),
        rot(0.985, 1.2),
        [[0.8, 0.0], [0.0, -0.4]],
    ];
    let a = Mat::from_fn(8, 8, |i, j| {
        if i / 2 == j / 2 {
            blocks[i / 2][i % 2][j % 2]
        } else {
            0.0
        }
    });
    let b = Mat::from_fn(8, 1, |i, _| [1.0, 0.0, 0.6, 0.0, 0.4, 0.0, 1.0, 0.5][i]);
    let c = Mat::from_fn(1, 8, |_, j| [0.05, 0.04, 0.2, -0.1, 0.3, 0.2, 0.5, -0.4][j]);
    StateSpace::discrete(a, b, c, Mat::zeros(1, 1), TS).expect("valid model")
}

fn white(rms: f64, seed: u64) -> Vec<f64> {
    NoiseSpec {
        distribution: Distribution::Gaussian,
        rms,
        n_samples: N,
        band_hz: None,
        seed,
    }
    .generate(TS)
    .expect("valid noise spec")
    .values
}

fn data() -> (Vec<f64>, Vec<f64>) {
    let u = white(1.0, 1);
    let y0 = system().simulate_siso(&u, None).expect("finite input");
    let ry = (y0.iter().map(|v| v * v).sum::<f64>() / N as f64).sqrt();
    let v = white(0.02 * ry, 2);
    let y = y0.iter().zip(&v).map(|(a, b)| a + b).collect();
    (y, u)
}

fn options(bd: BdMethod) -> SubspaceOptions {
    SubspaceOptions {
        order: Some(8),
        bd_method: bd,
        ..SubspaceOptions::new(TS)
    }
}

fn col(x: &[f64]) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(x, x.len(), 1)
}

#[divan::bench(sample_count = 10)]
fn n4sid_order8_102300(bencher: Bencher) {
    let (y, u) = data();
    let o = options(BdMethod::Auto);
    bencher.bench(|| black_box(n4sid_detailed(col(&y), col(&u), &o).expect("identifiable")));
}

#[divan::bench(sample_count = 10)]
fn n4sid_order8_102300_projection(bencher: Bencher) {
    let (y, u) = data();
    let o = options(BdMethod::Projection);
    bencher.bench(|| black_box(n4sid_detailed(col(&y), col(&u), &o).expect("identifiable")));
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
    let (y, u) = data();
    let o = options(BdMethod::Auto);
    let before = peak_rss_kb();
    let start = std::time::Instant::now();
    let r = n4sid_detailed(col(&y), col(&u), &o).expect("identifiable");
    let took = start.elapsed();
    let after = peak_rss_kb();
    let i = r.block_rows;
    let d = 2 * i * 2;
    let hankel_mb = (d * (N + 1 - 2 * i) * 8) as f64 / 1e6;
    eprintln!(
        "subspace memory: N = {N}, i = {i}, d = {d}: one identification took {took:.2?}; the block-Hankel \
         matrix would take {hankel_mb:.0} MB, the record itself {:.1} MB",
        (2 * N * 8) as f64 / 1e6
    );
    match (before, after) {
        (Some(b), Some(a)) => eprintln!(
            "subspace memory: peak RSS (VmHWM) {b} kB before, {a} kB after (+{} kB)",
            a.saturating_sub(b)
        ),
        _ => eprintln!("subspace memory: /proc/self/status not available, peak RSS not measured"),
    }
}
