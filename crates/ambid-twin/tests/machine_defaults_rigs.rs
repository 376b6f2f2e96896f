//! The defaults added for the whole rotor, on random machines (not the nominal one):
//! `frf::mimo_lpm` with its default window on a non-periodic record, and `frf::synchronous` with
//! its default noise bins plus `SynchronousLine::remove` on a record with unbalance. Machines:
//! `random_rig(seed)` lifted to four axes by `MachineConfig::from_twin`, a speed drawn in
//! 3 000–30 000 rpm from `ChaCha8Rng::seed_from_u64(seed)`; a draw whose closed loop is unstable
//! at that speed is skipped and printed.

use crate::common;
use ambid_core::frf::mimo::{periodic, MimoOptions};
use ambid_core::frf::mimo_lpm::{local_polynomial, MimoLpmOptions};
use ambid_core::frf::synchronous::{synchronous, SynchronousOptions};
use ambid_core::lti::Frd;
use ambid_core::signal::multi::MultiInputDesign;
use ambid_core::signal::{Grid, MultisineSpec, Phases};
use ambid_twin::{random_rig, Machine, MachineConfig, MachineSimOptions, Mode, UnbalanceConfig};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The first `count` stable random machines from seed 20 on, with `unbalance`.
fn machines(count: usize, unbalance: Option<UnbalanceConfig>) -> Vec<(u64, Machine)> {
    let mut out = Vec::new();
    for seed in 20.. {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let speed_rpm: f64 = rng.random_range(3_000.0..30_000.0);
        let cfg = MachineConfig {
            speed_rpm,
            unbalance: unbalance.clone(),
            ..MachineConfig::from_twin(&random_rig(seed).unwrap())
        };
        match Machine::new(cfg) {
            Ok(m) => out.push((seed, m)),
            Err(ambid_twin::TwinError::UnstableClosedLoop { .. }) => {
                println!("rig {seed}: unstable at {speed_rpm:.0} rpm, skipped");
            }
            Err(e) => panic!("rig {seed}: {e}"),
        }
        if out.len() == count {
            return out;
        }
    }
    out
}

/// Relative errors of every entry, per line relative to the line's largest truth entry.
fn rel_errors(est: &Frd, truth: &Frd) -> Vec<f64> {
    let mut out = Vec::new();
    for l in 0..est.len() {
        let (a, b) = (est.at(l).unwrap(), truth.at(l).unwrap());
        let big = (0..4)
            .flat_map(|i| (0..4).map(move |j| (i, j)))
            .fold(0.0f64, |acc, (i, j)| acc.max(b[(i, j)].norm()));
        for i in 0..4 {
            for j in 0..4 {
                out.push((a[(i, j)] - b[(i, j)]).norm() / big);
            }
        }
    }
    out.sort_by(f64::total_cmp);
    out
}

/// One experiment of 16 384 samples with four independent uniform noises at 2 % of i_sat,
/// linear, noise off: the local polynomial estimate with the default window (R = 2, 19 lines)
/// over 20–1000 Hz follows the exact plant to its bias (median below 1e-3 on every rig).
#[test]
fn local_polynomial_default_window_on_random_machines() {
    for (seed, m) in machines(3, None) {
        let len = 16_384;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let amp = 0.02 * m.i_sat();
        let r: Vec<Vec<f64>> = (0..4)
            .map(|_| {
                (0..len)
                    .map(|_| amp * rng.random_range(-1.0..1.0))
                    .collect()
            })
            .collect();
        let data = m
            .simulate(
                [&r[0], &r[1], &r[2], &r[3]],
                &MachineSimOptions {
                    mode: Mode::Linear,
                    noise: false,
                    ..MachineSimOptions::default()
                },
            )
            .unwrap()
            .to_iodata(None)
            .unwrap();
        let est = local_polynomial(&data, &MimoLpmOptions::new().band(20.0, 1000.0)).unwrap();
        let errs = rel_errors(&est.plant, &m.plant_frf(est.f_hz()).unwrap());
        let (med, p95) = (errs[errs.len() / 2], errs[errs.len() * 95 / 100]);
        println!(
            "rig {seed} ({:.0} rpm): LPM P error median {med:.2e}, 95th percentile {p95:.2e}",
            m.config().speed_rpm
        );
        assert!(med < 1e-3 && p95 < 5e-2, "rig {seed}: {med} {p95}");
    }
}

/// With unbalance (5 g at 2 mm), noise off, a sequential odd-line multisine (the 1× line off
/// the grid at these random speeds or on an even line): the default synchronous estimate equals
/// the exact 1× response, and after `remove` the plant at the excited lines is exact.
#[test]
fn synchronous_defaults_on_random_machines() {
    let unb = UnbalanceConfig {
        mass_kg: 5e-3,
        eccentricity_m: 2e-3,
        axial_position_m: 0.02,
        phase_deg: 30.0,
    };
    for (seed, m) in machines(3, Some(unb)) {
        let n = 512;
        let fs = m.fs();
        let exc = MultiInputDesign::sequential(
            4,
            MultisineSpec {
                f_min_hz: 0.5 * fs / n as f64,
                f_max_hz: 127.5 * fs / n as f64,
                period_samples: n,
                periods: 8,
                rms: 0.02 * m.i_sat(),
                grid: Grid::Odd,
                phases: Phases::Schroeder,
                seed: 1,
            },
        )
        .generate(m.ts())
        .unwrap();
        let data = ambid_core::data::IoData::from_experiments(common::run_design(&m, &exc, |_| {
            MachineSimOptions {
                mode: Mode::Linear,
                noise: false,
                settle_samples: 40 * n,
                ..MachineSimOptions::default()
            }
        }))
        .unwrap();
        let line = synchronous(&data, m.sync_hz(), &SynchronousOptions::new()).unwrap();
        let y = m.unbalance_response().unwrap();
        let scale = y.iter().fold(0.0f64, |a, v| a.max(v.norm()));
        let mut worst = 0.0f64;
        for ch in line.channels.iter().filter(|c| c.name.starts_with("y_")) {
            let axis = ["xa", "xb", "ya", "yb"]
                .iter()
                .position(|a| ch.name.ends_with(a))
                .unwrap();
            worst = worst.max((ch.amplitude - y[axis]).norm() / scale);
        }
        let est = periodic(&line.remove(&data).unwrap(), &MimoOptions::new()).unwrap();
        let errs = rel_errors(&est.plant, &m.plant_frf(est.f_hz()).unwrap());
        let p_max = *errs.last().unwrap();
        println!(
            "rig {seed} ({:.0} rpm, 1x at {:.1} Hz, {:+.3} lines off the grid): 1x amplitude \
             error {worst:.2e}, plant after remove {p_max:.2e}",
            m.config().speed_rpm,
            m.sync_hz(),
            line.grid_offset
        );
        assert!(worst < 1e-6, "rig {seed}: {worst}");
        assert!(p_max < 1e-6, "rig {seed}: {p_max}");
    }
}
