//! Speed of subspace + PEM on the twin's closed-loop seed data (issue 4's bar: order-8 T_ry
//! model ≥ 50× faster than SIPPY's N4SID at its best-fit setting, timed by
//! `tests/fixtures/time_sippy.py` on the same data). Run: `cargo bench -p ambid --bench estimate`.
//!
//! Data: `Experiment::seed_paper(Mode::Linear, 1e-7, 1)` (102 300 samples, r → y with y in µm),
//! order 8.
//! * `subspace_i120`: [`n4sid_detailed`] at 120 block rows (Gram data product);
//! * `subspace_i120_pem_simulation`: the same, then [`refine_ss`] with the simulation focus
//!   (what `ambid fit --structure ss --order 8 --block-rows 120 --focus simulation` runs);
//! * `subspace_i120_pem_prediction_20`: the same with the prediction focus, 20 iterations;
//! * `subspace_default_ladder`: the default horizon ladder (30 → 60 → 120 → 240);
//! * `compare_models_3x4_on_plant_frf`: issue 5's comparison (ARX, OE, SS × orders 6–9) on the
//!   period-averaged plant FRF (≤ 200 ms bar).

use ambid::experiment::{run, Experiment};
use ambid_core::estimate::pem::Focus;
use ambid_core::estimate::ss_pem::{refine_ss, SsPemOptions};
use ambid_core::estimate::subspace::{n4sid_detailed, SubspaceOptions};
use ambid_twin::Mode;
use divan::{black_box, Bencher};
use faer::Mat;

fn main() {
    divan::main();
}

fn data() -> (Mat<f64>, Mat<f64>, f64) {
    let est = run(&Experiment::seed_paper(Mode::Linear, 1e-7, 1)).expect("seed experiment");
    let (r, y) = (&est.record.r, &est.record.y);
    (
        Mat::from_fn(r.len(), 1, |k, _| r[k]),
        Mat::from_fn(y.len(), 1, |k, _| 1e6 * y[k]),
        est.twin.ts(),
    )
}

fn options(ts: f64, block_rows: Option<usize>) -> SubspaceOptions {
    let mut o = SubspaceOptions::new(ts);
    o.order = Some(8);
    o.block_rows = block_rows;
    o
}

#[divan::bench(sample_count = 10)]
fn subspace_i120(b: Bencher) {
    let (r, y, ts) = data();
    let o = options(ts, Some(120));
    b.bench_local(|| black_box(n4sid_detailed(y.as_ref(), r.as_ref(), &o).expect("n4sid")));
}

#[divan::bench(sample_count = 10)]
fn subspace_default_ladder(b: Bencher) {
    let (r, y, ts) = data();
    let o = options(ts, None);
    b.bench_local(|| black_box(n4sid_detailed(y.as_ref(), r.as_ref(), &o).expect("n4sid")));
}

fn subspace_plus_pem(b: Bencher, focus: Focus, iterations: usize) {
    let (r, y, ts) = data();
    let o = options(ts, Some(120));
    let p = SsPemOptions {
        focus,
        lm: SsPemOptions::default()
            .lm
            .with_max_iterations(iterations)
            .expect("iterations"),
        ..SsPemOptions::default()
    };
    b.bench_local(|| {
        let sub = n4sid_detailed(y.as_ref(), r.as_ref(), &o).expect("n4sid");
        let k = sub.kalman_gain.as_ref().map(|k| k.as_ref());
        black_box(refine_ss(y.as_ref(), r.as_ref(), &sub.fitted.model, k, &p).expect("pem"))
    });
}

#[divan::bench(sample_count = 10)]
fn subspace_i120_pem_simulation(b: Bencher) {
    subspace_plus_pem(b, Focus::Simulation, 100);
}

#[divan::bench(sample_count = 5)]
fn subspace_i120_pem_prediction_20(b: Bencher) {
    subspace_plus_pem(b, Focus::Prediction, 20);
}

/// Issue 5's speed bar: the full comparison (ARX, OE, SS × orders 6–9) on the period-averaged
/// plant FRF of the seed experiment (the excited lines in 10–1000 Hz), inverse-variance weights,
/// without the time-domain validation.
#[divan::bench(sample_count = 10)]
fn compare_models_3x4_on_plant_frf(b: Bencher) {
    use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
    use ambid_core::validate::compare::{compare_models, CompareSpec};
    let frf = run(&Experiment::seed_paper(Mode::Linear, 1e-7, 1))
        .expect("seed experiment")
        .periodic_frf((10.0, 1000.0), None)
        .expect("frf");
    let spec = CompareSpec {
        fit: FreqFitOptions {
            weights: FreqWeights::InverseVariance,
            ..FreqFitOptions::default()
        },
        ..CompareSpec::default()
    };
    eprintln!("{} lines", frf.plant.len());
    b.bench_local(|| black_box(compare_models(&frf.plant, &spec, None).expect("compare")));
}
