//! Speed and memory of subspace identification on a record of the seed experiment's length:
//! order 8 on 102 300 samples (PRBS order 10 × 5 samples per bit × 20 periods) of a synthetic SISO
//! system with three lightly damped modes and two real poles, white input, 2 % output noise.
//!
//! * `default_ladder`: [`n4sid_detailed`] with the default options (CVA weighting, horizon ladder
//!   from 30 block rows, automatic data product, B and D by the simulation regression, Kalman gain
//!   from the DARE);
//! * `i30_qr`, `i120_qr`, `i120_gram`: one identification at a fixed horizon with the streaming QR
//!   or the Gram data product (the cost of a long horizon, and why `DataProduct::Auto` switches);
//! * `i30_projection`: as `i30_qr` without the simulation regression for B and D.
//!
//! Before the benches run, `main` identifies once with the defaults and prints the peak resident
//! set (`VmHWM` in `/proc/self/status`) before and after, next to the size the block-Hankel matrix
//! of the chosen horizon would have.
//!
//! Run: `cargo bench -p ambid-core --bench subspace`.
//!
//! Measured (2-core AMD EPYC VM, idle; release profile, default target CPU; medians,
//! 2026-11-21, after the Gram product was vectorised):
//!
//! | bench | median | |
//! |---|---|---|
//! | `default_ladder` | 292 ms | climbs $i$ = 30 (QR) → 60 (Gram) → 120 (Gram, rejected), keeps 60 |
//! | `i30_qr` | 185 ms | streaming QR of the $102\,241 \times 120$ Hankel data ≈ 3·10⁹ flops dominates |
//! | `i30_projection` | 159 ms | the simulation regression for B, D costs ≈ 25 ms |
//! | `i120_qr` | 1.40 s | $d = 480$: the QR grows with $d^2$ |
//! | `i120_gram` | 61 ms | the Gram route at the same horizon: 23× faster |
//!
//! Peak RSS (`VmHWM`) grows by 8.3 MB during the default identification (the $d \times d$
//! matrices of the $i = 120$ rung, $d = 480$), independent of $N$; the block-Hankel matrix of the
//! chosen horizon, never formed, would take 196 MB and the record itself is 1.6 MB. For
//! comparison, nfoursid 1.0.2 cannot run this case: its order step takes a full SVD of a
//! $102\,271 \times 102\,271$ matrix (78 GiB).

use ambid_core::estimate::subspace::{n4sid_detailed, BdMethod, DataProduct, SubspaceOptions};
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

fn options(block_rows: Option<usize>, data_product: DataProduct, bd: BdMethod) -> SubspaceOptions {
    SubspaceOptions {
        order: Some(8),
        block_rows,
        data_product,
        bd_method: bd,
        ..SubspaceOptions::new(TS)
    }
}

fn col(x: &[f64]) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(x, x.len(), 1)
}

fn bench_with(bencher: Bencher, o: SubspaceOptions) {
    let (y, u) = data();
    bencher.bench(|| black_box(n4sid_detailed(col(&y), col(&u), &o).expect("identifiable")));
}

#[divan::bench(sample_count = 5)]
fn default_ladder(bencher: Bencher) {
    bench_with(bencher, options(None, DataProduct::Auto, BdMethod::Auto));
}

#[divan::bench(sample_count = 10)]
fn i30_qr(bencher: Bencher) {
    bench_with(bencher, options(Some(30), DataProduct::Qr, BdMethod::Auto));
}

#[divan::bench(sample_count = 10)]
fn i30_projection(bencher: Bencher) {
    bench_with(
        bencher,
        options(Some(30), DataProduct::Qr, BdMethod::Projection),
    );
}

#[divan::bench(sample_count = 5)]
fn i120_qr(bencher: Bencher) {
    bench_with(bencher, options(Some(120), DataProduct::Qr, BdMethod::Auto));
}

#[divan::bench(sample_count = 10)]
fn i120_gram(bencher: Bencher) {
    bench_with(
        bencher,
        options(Some(120), DataProduct::Gram, BdMethod::Auto),
    );
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
    let o = options(None, DataProduct::Auto, BdMethod::Auto);
    let before = peak_rss_kb();
    let start = std::time::Instant::now();
    let r = n4sid_detailed(col(&y), col(&u), &o).expect("identifiable");
    let took = start.elapsed();
    let after = peak_rss_kb();
    let i = r.block_rows;
    let d = 2 * i * 2;
    let hankel_mb = (d * (N + 1 - 2 * i) * 8) as f64 / 1e6;
    eprintln!(
        "subspace memory: N = {N}, ladder {:?} chose i = {i} ({:?}), d = {d}: {took:.2?}; the \
         block-Hankel matrix would take {hankel_mb:.0} MB, the record itself {:.1} MB",
        r.block_rows_scan,
        r.data_product,
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
