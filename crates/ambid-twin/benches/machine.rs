//! Simulation speed of the 4-axis machine: 1 s of 20 kHz (20 000 samples), linear mode, noise on
//! (four streams), multisine excitation on all four axes, at 30 000 rpm with an unbalance
//! (22-state exact update) and at standstill without (20 states). Real time for this record is
//! 1 s; the bar is ≥ 200× real time (≤ 5 ms).
//!
//! Measured (shared 2-core VM, load ≈ 0.5, release, medians of 30): standstill, 20 states
//! 3.18 ms (≈ 315× real time); 30 000 rpm with unbalance, 22 states 3.52 ms (≈ 284× real
//! time). The exact update runs column by column so that it vectorises across the rows (a
//! row-by-row dot product ran at 4.0 / 4.3 ms).
//!
//! Run: `cargo bench -p ambid-twin --bench machine`.

use ambid_twin::{Machine, MachineConfig, MachineSimOptions, Mode, UnbalanceConfig};
use divan::{black_box, Bencher};

const SAMPLES: usize = 20_000;

fn main() {
    divan::main();
}

fn excitation(axis: usize) -> Vec<f64> {
    (0..SAMPLES)
        .map(|k| {
            (1..40)
                .map(|l| {
                    let ph = (l * l + 7 * axis) as f64 * 0.37;
                    0.002 * (2.0 * std::f64::consts::PI * (10 * l * k) as f64 / 20_000.0 + ph).cos()
                })
                .sum()
        })
        .collect()
}

fn machine(at_speed: bool) -> Machine {
    let cfg = if at_speed {
        MachineConfig {
            speed_rpm: 30_000.0,
            unbalance: Some(UnbalanceConfig::default()),
            ..Default::default()
        }
    } else {
        MachineConfig::default()
    };
    Machine::new(cfg).unwrap()
}

#[divan::bench(args = [false, true], sample_count = 30)]
fn simulate_linear_1s(bencher: Bencher, at_speed: bool) {
    let m = machine(at_speed);
    let r: Vec<Vec<f64>> = (0..4).map(excitation).collect();
    let opts = MachineSimOptions {
        mode: Mode::Linear,
        seed: 3,
        ..Default::default()
    };
    bencher.bench(|| {
        black_box(
            m.simulate([&r[0], &r[1], &r[2], &r[3]], black_box(&opts))
                .unwrap(),
        )
    });
}
