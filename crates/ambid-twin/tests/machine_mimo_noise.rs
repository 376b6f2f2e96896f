//! Issue 20's noise bar on the whole-rotor twin: with the default sensor noise on (linear mode),
//! the 95 % confidence discs of `ambid_core::frf::mimo::periodic` (radius
//! `MimoClosedLoopFrf::band_factor(0.95)` × σ, the rule of the SISO closed-loop bands) cover the
//! machine's exact truth on 90–98 % of the entry-lines of P, T_ry and S, pooled over 20 noise
//! seeds, for the sequential and the orthogonal (Hadamard) PRBS designs, at 0 and 15 000 rpm;
//! and the same bar (plus the noise-off self-consistency ≤ 1e-6 up to 2 kHz) on random machines.
//!
//! Record (chosen for the debug run time): PRBS order 8, 2 samples per bit (N = 510 samples,
//! 39.2 Hz line spacing, 254 excited lines up to 10 kHz), amplitude 2 % of i_sat-ish (0.04 A),
//! 16 measured periods after a cyclic pre-roll of 20 periods (0.51 s; 4 periods left transients of 1e-4 on random rigs) (`settle_samples`), so every
//! experiment is 8 160 recorded samples (0.41 s) and ν = 15 degrees of freedom.

mod common_noise {
    use ambid_core::data::IoData;
    use ambid_core::frf::mimo::{periodic, MimoClosedLoopFrf, MimoOptions};
    use ambid_core::lti::Frd;
    use ambid_core::signal::multi::{MultiExcitation, MultiInputDesign};
    use ambid_core::signal::PrbsSpec;
    use ambid_twin::{Machine, MachineSimOptions, Mode};

    pub const SETTLE_PERIODS: usize = 20;

    pub fn prbs(amplitude: f64, periods: usize) -> PrbsSpec {
        PrbsSpec {
            order: 8,
            samples_per_bit: 2,
            periods,
            amplitude,
            offset: 0.0,
        }
    }

    /// The experiments of `exc` run on `machine` (noise on with `seed`, or off), joined.
    pub fn record(machine: &Machine, exc: &MultiExcitation, noise: bool, seed: u64) -> IoData {
        let n = exc.period_samples();
        let experiments = crate::common::run_design(machine, exc, |e| MachineSimOptions {
            mode: Mode::Linear,
            noise,
            // every experiment its own noise streams
            seed: seed * 16 + e as u64,
            settle_samples: SETTLE_PERIODS * n,
            ..MachineSimOptions::default()
        });
        IoData::from_experiments(experiments).unwrap()
    }

    pub fn estimate(data: &IoData) -> MimoClosedLoopFrf {
        periodic(data, &MimoOptions::new()).unwrap()
    }

    /// (covered, total) entry-lines of `est` whose disc of radius `fac`·σ holds `truth`.
    pub fn covered(est: &Frd, truth: &Frd, fac: f64) -> (usize, usize) {
        let var = est.variance().unwrap();
        let mut c = 0;
        for ((e, t), v) in est.values().iter().zip(truth.values()).zip(var) {
            if (e - t).norm() <= fac * v.sqrt() {
                c += 1;
            }
        }
        (c, var.len())
    }

    /// Largest error over the lines ≤ `f_max`, relative to each line's largest truth entry.
    pub fn max_rel(est: &Frd, truth: &Frd, f_max: f64) -> f64 {
        let per = est.ny() * est.nu();
        let mut worst = 0.0f64;
        for (k, f) in est.f_hz().iter().enumerate() {
            if *f > f_max {
                continue;
            }
            let e = &est.values()[k * per..(k + 1) * per];
            let t = &truth.values()[k * per..(k + 1) * per];
            let scale = t.iter().fold(0.0f64, |a, z| a.max(z.norm()));
            for (a, b) in e.iter().zip(t) {
                worst = worst.max((a - b).norm() / scale);
            }
        }
        worst
    }

    /// (covered, total) entry-lines of `est` on the lines below / from `f_split` Hz.
    pub fn covered_split(est: &Frd, truth: &Frd, fac: f64, f_split: f64) -> [(usize, usize); 2] {
        let var = est.variance().unwrap();
        let per = est.ny() * est.nu();
        let mut out = [(0, 0); 2];
        for (i, ((e, t), v)) in est.values().iter().zip(truth.values()).zip(var).enumerate() {
            let b = usize::from(est.f_hz()[i / per] >= f_split);
            out[b].1 += 1;
            if (e - t).norm() <= fac * v.sqrt() {
                out[b].0 += 1;
            }
        }
        out
    }

    /// Pooled coverage of P, T_ry and S over `seeds` for one design on one machine.
    pub fn coverage(
        machine: &Machine,
        design: &MultiInputDesign,
        seeds: std::ops::Range<u64>,
    ) -> [(usize, usize); 3] {
        let exc = design.generate(machine.ts()).unwrap();
        let mut acc = [(0usize, 0usize); 3];
        let mut split = [(0usize, 0usize); 2];
        let mut truth: Option<[Frd; 3]> = None;
        for seed in seeds {
            let est = estimate(&record(machine, &exc, true, seed));
            let f = est.f_hz().to_vec();
            let tr = truth.get_or_insert_with(|| {
                [
                    machine.plant_frf(&f).unwrap(),
                    machine.t_ry_frf(&f).unwrap(),
                    machine.sensitivity_frf(&f).unwrap(),
                ]
            });
            let fac = est.band_factor(0.95).unwrap();
            for (q, (e, t)) in [&est.plant, &est.t_ry, &est.s]
                .iter()
                .zip(tr.iter())
                .enumerate()
            {
                assert_eq!(e.f_hz(), t.f_hz());
                let (c, n) = covered(e, t, fac);
                acc[q].0 += c;
                acc[q].1 += n;
                if q == 0 {
                    for (b, (c, n)) in covered_split(e, t, fac, 500.0).into_iter().enumerate() {
                        split[b].0 += c;
                        split[b].1 += n;
                    }
                }
            }
        }
        println!(
            "  P coverage below 500 Hz {:.4} ({} entry-lines), from 500 Hz {:.4} ({})",
            split[0].0 as f64 / split[0].1.max(1) as f64,
            split[0].1,
            split[1].0 as f64 / split[1].1.max(1) as f64,
            split[1].1
        );
        acc
    }
}

use ambid_core::signal::multi::MultiInputDesign;
use ambid_twin::{random_rig, Machine, MachineConfig};
use common_noise::*;

const SEEDS: u64 = 20;
/// Noise seeds per random machine and design.
const RIG_SEEDS: u64 = 20;

fn designs(amplitude: f64, periods: usize) -> [(&'static str, MultiInputDesign); 2] {
    [
        (
            "sequential",
            MultiInputDesign::sequential(4, prbs(amplitude, periods)),
        ),
        (
            "orthogonal",
            MultiInputDesign::orthogonal(4, prbs(amplitude, periods)),
        ),
    ]
}

fn assert_bar(label: &str, cov: [(usize, usize); 3]) {
    for (q, (c, n)) in ["P", "T_ry", "S"].iter().zip(cov) {
        let r = c as f64 / n as f64;
        println!("{label}: {q} coverage {r:.4} ({c}/{n})");
        assert!(
            (0.90..=0.98).contains(&r),
            "{label}: {q} coverage {r} ({c}/{n})"
        );
    }
}

#[test]
fn bands_cover_the_truth_on_90_to_98_percent_at_0_and_15000_rpm() {
    for speed_rpm in [0.0, 15_000.0] {
        let machine = Machine::new(MachineConfig {
            speed_rpm,
            ..MachineConfig::default()
        })
        .unwrap();
        for (name, design) in designs(0.04, 16) {
            let cov = coverage(&machine, &design, 0..SEEDS);
            assert_bar(&format!("nominal {speed_rpm} rpm {name}"), cov);
        }
    }
}

/// The first `count` stable random machines: rig `seed` of `random_rig` lifted to four axes by
/// `MachineConfig::from_twin`, at a speed drawn uniformly in 0–30 000 rpm from
/// `ChaCha8Rng::seed_from_u64(seed)`. A draw whose closed loop is unstable at that speed
/// (`TwinError::UnstableClosedLoop` from `Machine::new`: the rig's controller was tuned at
/// standstill) is skipped and printed; the next seed is tried.
fn random_machines(count: usize) -> Vec<(u64, Machine)> {
    use rand::{RngExt, SeedableRng};
    let mut out = Vec::new();
    for seed in 1.. {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let speed_rpm: f64 = rng.random_range(0.0..30_000.0);
        let cfg = MachineConfig {
            speed_rpm,
            ..MachineConfig::from_twin(&random_rig(seed).unwrap())
        };
        match Machine::new(cfg) {
            Ok(m) => {
                println!("rig {seed}: {speed_rpm:.0} rpm, fs {:.0} Hz", m.fs());
                out.push((seed, m));
            }
            Err(ambid_twin::TwinError::UnstableClosedLoop { .. }) => {
                println!("rig {seed}: unstable at {speed_rpm:.0} rpm, skipped");
            }
            Err(e) => panic!("rig {seed}: {e}"),
        }
        if out.len() == count {
            break;
        }
    }
    out
}

#[test]
fn random_machines_self_consistency_and_band_coverage() {
    for (seed, machine) in random_machines(5) {
        // 8 % of the rig's current saturation per axis. The first-order plant variance needs a
        // good SNR in u at every line (P = Y U⁻¹ is an errors-in-variables ratio): on rig 1 the
        // P bands cover 0.9646 at 8 %, but over-cover (0.9825) at 2 % and under-cover (0.912,
        // 0.908 above 500 Hz) at 0.5 %, where the controller-amplified sensor noise in u rivals
        // the excitation at high frequency. T_ry and S cover 0.951/0.954 at every level.
        let amp = 0.08 * machine.i_sat();
        for (name, design) in designs(amp, 16) {
            let exc = design.generate(machine.ts()).unwrap();
            let est = estimate(&record(&machine, &exc, false, 0));
            let f = est.f_hz().to_vec();
            let t = max_rel(&est.t_ry, &machine.t_ry_frf(&f).unwrap(), 2000.0);
            let s = max_rel(&est.s, &machine.sensitivity_frf(&f).unwrap(), 2000.0);
            let p = max_rel(&est.plant, &machine.plant_frf(&f).unwrap(), 2000.0);
            println!("rig {seed} {name} noise off: T_ry {t:.2e}, S {s:.2e}, P {p:.2e}");
            assert!(
                t < 1e-6 && s < 1e-6 && p < 1e-6,
                "rig {seed} {name}: {t} {s} {p}"
            );
            let cov = coverage(&machine, &design, 0..RIG_SEEDS);
            assert_bar(&format!("rig {seed} {name}"), cov);
        }
    }
}

/// The zippered design (one experiment, each axis on its own interleaved lines of a full-grid
/// multisine, N = 512, lines 1–127, 16 periods): the 95 % discs of the **measured** entries
/// (column j of T_ry and S on the lines of input j) cover the truth on 90–98 %, 20 seeds, at
/// 0 and 15 000 rpm. (The interpolated columns carry the interpolation bias, module docs of
/// `frf::mimo`, and P needs all columns: neither is a pure noise question.)
#[test]
fn zipper_measured_entries_are_covered_at_0_and_15000_rpm() {
    use ambid_core::frf::mimo::zippered;
    use ambid_core::frf::mimo::MimoOptions;
    use ambid_core::signal::{Grid, MultisineSpec, Phases};
    for speed_rpm in [0.0, 15_000.0] {
        let machine = Machine::new(MachineConfig {
            speed_rpm,
            ..MachineConfig::default()
        })
        .unwrap();
        let fs = machine.fs();
        let exc = MultiInputDesign::zipper(
            4,
            MultisineSpec {
                f_min_hz: 0.5 * fs / 512.0,
                f_max_hz: 127.5 * fs / 512.0,
                period_samples: 512,
                periods: 16,
                rms: 0.04,
                grid: Grid::Full,
                phases: Phases::Schroeder,
                seed: 1,
            },
        )
        .generate(machine.ts())
        .unwrap();
        let mut acc = [(0usize, 0usize); 2];
        for seed in 0..SEEDS {
            let est = zippered(&record(&machine, &exc, true, seed), &MimoOptions::new()).unwrap();
            let f = est.f_hz().to_vec();
            let fac = est.band_factor(0.95).unwrap();
            let truths = [
                machine.t_ry_frf(&f).unwrap(),
                machine.sensitivity_frf(&f).unwrap(),
            ];
            for (q, (e, t)) in [&est.t_ry, &est.s].iter().zip(&truths).enumerate() {
                let var = e.variance().unwrap();
                for (idx, ((a, b), v)) in e.values().iter().zip(t.values()).zip(var).enumerate() {
                    let (line, j) = (idx / 16, (idx % 16) / 4);
                    if !est.measured[line * 4 + j] {
                        continue;
                    }
                    acc[q].1 += 1;
                    if (a - b).norm() <= fac * v.sqrt() {
                        acc[q].0 += 1;
                    }
                }
            }
        }
        for (q, (c, n)) in ["T_ry", "S"].iter().zip(acc) {
            let r = c as f64 / n as f64;
            println!("zipper {speed_rpm} rpm: measured {q} coverage {r:.4} ({c}/{n})");
            assert!((0.90..=0.98).contains(&r), "{speed_rpm} rpm {q}: {r}");
        }
    }
}
