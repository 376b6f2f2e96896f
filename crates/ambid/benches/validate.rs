//! Speed of the closed-loop reconstruction (issue 6's bar: a 10 s chirp at 20 kHz, 200 000 steps,
//! in ≤ 20 ms). Run: `cargo bench -p ambid --bench validate`.
//!
//! * `reconstruct_exact_plant`: the twin's exact plant (15 states) with its controller, driven by
//!   the 5 µm 1–1000 Hz linear chirp reference, compared with the twin's noise-free response in
//!   20 windows ([`reconstruct`]);
//! * `simulate_loop_order_7`, `simulate_loop_order_10`: the loop alone with a 7- and a 10-state
//!   plant (the sizes of the identified models).
//!
//! Measured (idle 2-core VM, 2026-11-21): `reconstruct_exact_plant` 23.5 ms (15 plant states),
//! `simulate_loop_order_7` 9.6 ms, `simulate_loop_order_10` 13.4 ms.

use ambid::experiment::{run, Experiment};
use ambid_core::signal::chirp::{ChirpSpec, Sweep};
use ambid_core::validate::closed_loop::{reconstruct, simulate_loop_with};
use ambid_twin::{Mode, SimOptions};
use divan::{black_box, Bencher};

fn main() {
    divan::main();
}

fn chirp(ts: f64) -> Vec<f64> {
    ChirpSpec {
        f0_hz: 1.0,
        f1_hz: 1000.0,
        duration_s: 10.0,
        amplitude: 5e-6,
        sweep: Sweep::Linear,
        periods: 1,
    }
    .generate(ts)
    .expect("chirp")
    .values
}

#[divan::bench(sample_count = 20)]
fn reconstruct_exact_plant(b: Bencher) {
    let twin = run(&Experiment::seed_paper(Mode::Linear, 0.0, 1))
        .expect("twin")
        .twin;
    let ts = 1.0 / twin.fs();
    let w = chirp(ts);
    let rec = twin
        .simulate(
            &vec![0.0; w.len()],
            &SimOptions {
                noise: false,
                w: Some(w.clone()),
                ..SimOptions::default()
            },
        )
        .expect("twin response");
    eprintln!("{} steps, plant order {}", w.len(), twin.plant().order());
    b.bench_local(|| {
        black_box(
            reconstruct(
                twin.plant(),
                twin.controller(),
                &w,
                None,
                &rec.y,
                &rec.u,
                20,
                ts,
            )
            .expect("reconstruct"),
        )
    });
}

/// The loop alone with an `n`-state stand-in for an identified plant (the cost depends only on
/// the state counts); its loop with the twin's controller is stable (checked before timing).
fn loop_with_states(b: Bencher, n: usize) {
    use ambid_core::lti::StateSpace;
    let twin = run(&Experiment::seed_paper(Mode::Linear, 0.0, 1))
        .expect("twin")
        .twin;
    let ts = 1.0 / twin.fs();
    let w = chirp(ts);
    let a = faer::Mat::from_fn(n, n, |i, j| {
        if i == j {
            0.9
        } else if j == i + 1 {
            0.05
        } else {
            0.0
        }
    });
    let p = StateSpace::discrete(
        a,
        faer::Mat::from_fn(n, 1, |_, _| 1e-7),
        faer::Mat::from_fn(1, n, |_, _| 1.0),
        faer::Mat::zeros(1, 1),
        ts,
    )
    .expect("model");
    simulate_loop_with(&p, twin.controller(), Some(&w), None).expect("a stable loop");
    b.bench_local(|| black_box(simulate_loop_with(&p, twin.controller(), Some(&w), None)));
}

#[divan::bench(sample_count = 20)]
fn simulate_loop_order_7(b: Bencher) {
    loop_with_states(b, 7);
}

#[divan::bench(sample_count = 20)]
fn simulate_loop_order_10(b: Bencher) {
    loop_with_states(b, 10);
}
