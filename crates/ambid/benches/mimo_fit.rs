//! Benchmark of the MIMO frequency-domain fit (issue 21: an order ≤ 16 fit on 4×4×255 lines
//! ≤ 1 s on the project machine): `ss_frd_mimo_in_loop` with default options and the
//! workflow's band rule on the nominal 4-axis twin's plant FRF (15 000 rpm, linear, default
//! noise, seed 1: 253 lines in 11.7–997 Hz), orders 16, 20 and 24 as `FrequencyFitter` scans
//! them (`AMBID_BENCH_ORDERS=16,20` picks others). Wall time of each fit (the fit uses both
//! cores for its starts and probes), median of `AMBID_BENCH_REPS` runs (default 3); prints a
//! Markdown table for docs/benchmarks.md.
//!
//! Run: `cargo bench -p ambid --bench mimo_fit`.
use ambid::config::MachineSection;
use ambid::workflow::machine::acquire_twin;
use ambid::workflow::machine_fit::fit_band;
use ambid_core::estimate::freqfit_mimo::{ss_frd_mimo_in_loop, MimoFreqOptions};
use std::path::Path;
use std::time::Instant;

fn main() {
    let reps: usize = std::env::var("AMBID_BENCH_REPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3)
        .max(1);
    let m = MachineSection {
        speeds_rpm: Some(vec![15_000.0]),
        mode: "linear".into(),
        ..Default::default()
    };
    let data = acquire_twin(&m, Path::new("."), 1).expect("twin");
    let truth = &data.truth.as_ref().expect("truth")[0];
    let plant = &data.speeds[0].frf.plant;
    let band = fit_band(plant, m.quality_band_hz)
        .expect("band")
        .expect("a band");
    let opts = MimoFreqOptions {
        band_hz: Some(band),
        ..Default::default()
    };
    println!("| order | median wall [s] | runs | iterations |");
    println!("|---|---|---|---|");
    let orders: Vec<usize> = std::env::var("AMBID_BENCH_ORDERS")
        .ok()
        .map(|v| v.split(',').filter_map(|o| o.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![16, 20, 24]);
    for order in orders {
        let mut times = Vec::new();
        let mut iterations = 0;
        for _ in 0..reps {
            let t = Instant::now();
            let fit = ss_frd_mimo_in_loop(plant, order, &opts, &truth.controller).expect("fit");
            times.push(t.elapsed().as_secs_f64());
            iterations = fit.iterations;
        }
        times.sort_by(f64::total_cmp);
        println!(
            "| {order} | {:.2} | {reps} | {iterations} |",
            times[times.len() / 2]
        );
    }
}
