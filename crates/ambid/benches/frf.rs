//! Speed of the period-averaged closed-loop FRF on the seed data set (issue 3's bar: ≤ 3× one
//! real FFT of the whole record). Run: `cargo bench -p ambid --bench frf`.

use ambid::experiment::{run, Experiment};
use ambid_core::frf::closed_loop::{from_periodic, Channels};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
use ambid_twin::{Mode, SimRecord};
use divan::{black_box, Bencher};
use realfft::RealFftPlanner;

const N: usize = 5115;

fn main() {
    divan::main();
}

fn seed_record() -> SimRecord {
    run(&Experiment::seed_paper(Mode::Linear, 1e-7, 1))
        .expect("seed experiment")
        .record
}

/// The reference: one forward real FFT of the whole 102 300-sample record (plan made outside).
#[divan::bench]
fn fft_whole_record(b: Bencher) {
    let rec = seed_record();
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(rec.y.len());
    let mut input = rec.y.clone();
    let mut out = fft.make_output_vec();
    let mut scratch = fft.make_scratch_vec();
    b.bench_local(|| {
        input.copy_from_slice(&rec.y);
        fft.process_with_scratch(&mut input, &mut out, &mut scratch)
            .expect("fft");
        black_box(&out);
    });
}

/// Period-averaged T_ry, S, plant and controller with variances and coherences on every excited
/// line (analyser planned outside, as the FFT above).
#[divan::bench]
fn periodic_closed_loop_frf(b: Bencher) {
    let rec = seed_record();
    let mut an = PeriodicAnalyzer::new(N).expect("plan");
    b.bench_local(|| {
        let s = an
            .analyze(
                &[&rec.r, &rec.u, &rec.y],
                20_000.0,
                &PeriodicOptions::new(N).skip(1),
            )
            .expect("analysis");
        let lines = s.excited_lines(0, 1e-6).expect("lines");
        let frf = from_periodic(&s, Channels { r: 0, u: 1, y: 2 }, &lines, None).expect("frf");
        black_box(frf);
    });
}

/// The same including the FFT planning (a one-off cost per period length).
#[divan::bench]
fn periodic_closed_loop_frf_with_planning(b: Bencher) {
    let rec = seed_record();
    b.bench_local(|| {
        let mut an = PeriodicAnalyzer::new(N).expect("plan");
        let s = an
            .analyze(
                &[&rec.r, &rec.u, &rec.y],
                20_000.0,
                &PeriodicOptions::new(N).skip(1),
            )
            .expect("analysis");
        let lines = s.excited_lines(0, 1e-6).expect("lines");
        black_box(from_periodic(&s, Channels { r: 0, u: 1, y: 2 }, &lines, None).expect("frf"));
    });
}

/// Only the period spectra (the FFTs and the moment sums).
#[divan::bench]
fn periodic_spectra_only(b: Bencher) {
    let rec = seed_record();
    let mut an = PeriodicAnalyzer::new(N).expect("plan");
    b.bench_local(|| {
        black_box(
            an.analyze(
                &[&rec.r, &rec.u, &rec.y],
                20_000.0,
                &PeriodicOptions::new(N).skip(1),
            )
            .expect("analysis"),
        );
    });
}

/// 19 complex FFTs of one period, nothing else.
#[divan::bench]
fn nineteen_period_ffts(b: Bencher) {
    let rec = seed_record();
    let fft = rustfft::FftPlanner::<f64>::new().plan_fft_forward(N);
    let mut buf = vec![num_complex::Complex64::new(0.0, 0.0); N];
    let mut scratch = vec![num_complex::Complex64::new(0.0, 0.0); fft.get_inplace_scratch_len()];
    b.bench_local(|| {
        for p in 1..20 {
            for (z, (u, y)) in buf.iter_mut().zip(
                rec.u[p * N..(p + 1) * N]
                    .iter()
                    .zip(&rec.y[p * N..(p + 1) * N]),
            ) {
                *z = num_complex::Complex64::new(*u, *y);
            }
            fft.process_with_scratch(&mut buf, &mut scratch);
        }
        black_box(&buf);
    });
}

/// What `ambid frf --period-samples 5115 --skip-periods 1` computes on the record in memory
/// (`ambid::analysis::analyze`: bands, FRF, quality), without the screening of abnormal
/// samples; the Python package's `ambid.frf(..., screen=False)` calls exactly this (issue 22's
/// overhead bar compares the two, docs/benchmarks.md).
#[divan::bench]
fn analysis_periodic_unscreened(b: Bencher) {
    analysis_periodic(b, false);
}

/// The same with the default screening (Hampel filter on `y` and `u − r`): `ambid.frf(...)`.
#[divan::bench]
fn analysis_periodic_screened(b: Bencher) {
    analysis_periodic(b, true);
}

/// `ambid::analysis::analyze` with period averaging on the seed record, screening on or off.
fn analysis_periodic(b: Bencher, screen: bool) {
    let rec = seed_record();
    let mut settings = ambid::analysis::FrfSettings::periodic(N, 1);
    settings.screen = screen;
    let r = ambid::analysis::Record {
        r: &rec.r,
        u: &rec.u,
        y: &rec.y,
        i: None,
        fs: 20_000.0,
    };
    b.bench_local(|| black_box(ambid::analysis::analyze(&r, &settings, None).expect("frf")));
}
