//! Simulation speed of the twin: 102 300 samples (5.115 s at 20 kHz), linear and nonlinear mode,
//! noise on, bearing B not recorded. Real time for this record is 5.115 s.
//!
//! Run: `cargo bench -p ambid-twin`.
//!
//! Measured (shared 2-core AMD EPYC VM, release profile, default target CPU, medians):
//! linear 5.8 ms (≈ 880× real time); nonlinear RK4 (10 substeps, 4.09 M right-hand-side
//! evaluations ≈ 15 ns each) 62 ms (≈ 83× real time); nonlinear exponential RK4
//! (`simulation.integrator = "exp_rk4"`, exact linear flow + RK4 on the nonlinear residual)
//! 16.5 ms with 1 step per period (≈ 310× real time), 26.2 ms with 2. The step is bound by
//! instruction throughput (one 10×12 and one 4×12 product, four residual evaluations, two 10×4
//! products per step, SSE2 only); an AVX2 build of the step gained only ≈ 5 % and was not kept.
//! The nonlinear target of ≤ 10 ms (≥ 500× real time) is NOT met by either integrator; the
//! physics was not reduced to chase it.

use ambid_twin::{Integrator, Mode, SimOptions, Twin, TwinConfig};
use divan::{black_box, Bencher};

const SAMPLES: usize = 102_300;

fn main() {
    divan::main();
}

/// The seed experiment's PRBS (order 10, 5 samples per bit, 20 periods = 102 300 samples) at
/// 2 % of i_sat.
fn excitation() -> Vec<f64> {
    let spec = ambid_core::signal::PrbsSpec {
        order: 10,
        samples_per_bit: 5,
        periods: 20,
        amplitude: 0.04,
        offset: 0.0,
    };
    let v = spec.generate(5e-5).unwrap().values;
    assert_eq!(v.len(), SAMPLES);
    v
}

#[divan::bench(args = [Mode::Linear, Mode::Nonlinear], sample_count = 30)]
fn simulate_102300(bencher: Bencher, mode: Mode) {
    let twin = Twin::new(TwinConfig::default()).unwrap();
    let r = excitation();
    let opts = SimOptions {
        mode,
        seed: 1,
        noise: true,
        ..Default::default()
    };
    bencher.bench(|| black_box(twin.simulate(black_box(&r), &opts).unwrap()));
}

/// Nonlinear mode with the exponential (Lawson) RK4, 1 and 2 steps per control period.
#[divan::bench(args = [1, 2], sample_count = 30)]
fn simulate_102300_exp_rk4(bencher: Bencher, exp_substeps: usize) {
    let mut cfg = TwinConfig::default();
    cfg.simulation.integrator = Integrator::ExpRk4;
    cfg.simulation.exp_substeps = exp_substeps;
    let twin = Twin::new(cfg).unwrap();
    let r = excitation();
    let opts = SimOptions {
        mode: Mode::Nonlinear,
        seed: 1,
        noise: true,
        ..Default::default()
    };
    bencher.bench(|| black_box(twin.simulate(black_box(&r), &opts).unwrap()));
}

/// Four nonlinear RK4 runs (seeds 1–4) of 102 300 samples in lock-step lanes
/// (`Twin::simulate_batch`, AVX2 when the CPU has it); compare with 4 × `simulate_102300`
/// (Nonlinear).
#[divan::bench(sample_count = 10)]
fn simulate_102300_batch_of_4(bencher: Bencher) {
    let twin = Twin::new(TwinConfig::default()).unwrap();
    let r = excitation();
    let opts: Vec<SimOptions> = (1..=4)
        .map(|seed| SimOptions {
            mode: Mode::Nonlinear,
            seed,
            noise: true,
            ..Default::default()
        })
        .collect();
    let runs: Vec<(&Twin, &[f64], &SimOptions)> =
        opts.iter().map(|o| (&twin, r.as_slice(), o)).collect();
    bencher.bench(|| black_box(Twin::simulate_batch(black_box(&runs))));
}

#[divan::bench(sample_count = 10)]
fn build_twin() -> Twin {
    Twin::new(TwinConfig::default()).unwrap()
}

#[divan::bench(sample_count = 10)]
fn peak_sensitivity(bencher: Bencher) {
    let twin = Twin::new(TwinConfig::default()).unwrap();
    bencher.bench(|| black_box(twin.peak_sensitivity().unwrap()));
}

/// The floor of any RK4 twin at 10 substeps: a stripped-down kernel with only the rigid rotor
/// (translation and tilt), the exact force law at both bearings and a constant proportional
/// current command — no bending mode, amplifier, sensor, noise, controller or recording — run
/// for the same 102 300 control periods × 10 substeps. It is not the twin; it shows how much of
/// the twin's RK4 time the dependent chain of right-hand-side evaluations alone costs.
#[divan::bench(sample_count = 10)]
fn rk4_floor_rigid_rotor_force_law_only() -> [f64; 4] {
    let (m, j, a, b) = (5.0f64, 5.0 * 0.25 / 12.0, 0.2165f64, 0.2165f64);
    let (k, i0, g0) = (1.1609e-6f64, 2.0f64, 4e-4f64);
    let kp = 21_000.0f64;
    let force = |i: f64, x: f64| {
        let (p, n, gp, gn) = (i0 + i, i0 - i, g0 - x, g0 + x);
        let (pg, ng, d) = (p * gn, n * gp, gp * gn);
        k * (pg * pg - ng * ng) / (d * d)
    };
    // state: z, θ, ż, θ̇; currents held per control period from a stiff P law
    let deriv = |s: &[f64; 4], ia: f64, ib: f64| -> [f64; 4] {
        let (xa, xb) = (s[0] - a * s[1], s[0] + b * s[1]);
        let (fa, fb) = (force(ia, xa), force(ib, xb));
        [s[2], s[3], (fa + fb) / m, (b * fb - a * fa) / j]
    };
    let h = 5e-5 / 10.0;
    let mut s = black_box([1e-6, 0.0, 0.0, 0.0]);
    for _ in 0..SAMPLES {
        let (xa, xb) = (s[0] - a * s[1], s[0] + b * s[1]);
        let (ia, ib) = ((-kp * xa).clamp(-2.0, 2.0), (-kp * xb).clamp(-2.0, 2.0));
        for _ in 0..10 {
            let k1 = deriv(&s, ia, ib);
            let t = std::array::from_fn(|q| s[q] + 0.5 * h * k1[q]);
            let k2 = deriv(&t, ia, ib);
            let t = std::array::from_fn(|q| s[q] + 0.5 * h * k2[q]);
            let k3 = deriv(&t, ia, ib);
            let t = std::array::from_fn(|q| s[q] + h * k3[q]);
            let k4 = deriv(&t, ia, ib);
            for q in 0..4 {
                s[q] += h / 6.0 * (k1[q] + 2.0 * (k2[q] + k3[q]) + k4[q]);
            }
        }
    }
    s
}
