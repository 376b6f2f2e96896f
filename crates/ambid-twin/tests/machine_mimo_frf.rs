//! Issue 20's self-consistency bar on the whole-rotor twin: the linear 4-axis `Machine`, noise
//! off, excited by the sequential and the orthogonal (Hadamard) PRBS designs of
//! `ambid_core::signal::multi`, analysed by `ambid_core::frf::mimo::periodic`: the estimated
//! T_ry, S and P equal the machine's exact 4×4 truth at every excited line up to 2 kHz, at 0 and
//! 30 000 rpm.

use ambid_core::data::IoData;
use ambid_core::frf::mimo::{periodic, MimoOptions};
use ambid_core::lti::Frd;
use ambid_core::signal::multi::MultiInputDesign;
use ambid_core::signal::PrbsSpec;
use ambid_twin::{Machine, MachineConfig, MachineSimOptions, Mode};

/// Largest relative error over the lines ≤ `f_max` and all 16 entries, relative to each line's
/// largest truth entry (so a zero cross term at standstill is measured against the line's scale).
fn max_rel(est: &Frd, truth: &Frd, f_max: f64) -> f64 {
    let mut worst = 0.0f64;
    for (k, f) in est.f_hz().iter().enumerate() {
        if *f > f_max {
            continue;
        }
        let (e, t) = (est.at(k).unwrap(), truth.at(k).unwrap());
        let mut scale = 0.0f64;
        for i in 0..4 {
            for j in 0..4 {
                scale = scale.max(t[(i, j)].norm());
            }
        }
        for i in 0..4 {
            for j in 0..4 {
                worst = worst.max((e[(i, j)] - t[(i, j)]).norm() / scale);
            }
        }
    }
    worst
}

fn check(speed_rpm: f64, design: MultiInputDesign) {
    let machine = Machine::new(MachineConfig {
        speed_rpm,
        ..MachineConfig::default()
    })
    .unwrap();
    let ts = 5e-5;
    let exc = design.generate(ts).unwrap();
    let n = exc.period_samples();
    let mut experiments = Vec::new();
    for r in exc.samples() {
        let rec = machine
            .simulate(
                [&r[0], &r[1], &r[2], &r[3]],
                &MachineSimOptions {
                    mode: Mode::Linear,
                    noise: false,
                    ..MachineSimOptions::default()
                },
            )
            .unwrap();
        experiments.push(rec.to_iodata(Some(n)).unwrap());
    }
    let data = IoData::from_experiments(experiments).unwrap();
    let est = periodic(
        &data,
        &MimoOptions {
            skip_periods: exc.transient_periods(),
            ..MimoOptions::default()
        },
    )
    .unwrap();
    let f = est.f_hz().to_vec();
    assert!(f.iter().filter(|f| **f <= 2000.0).count() > 100);
    let t = max_rel(&est.t_ry, &machine.t_ry_frf(&f).unwrap(), 2000.0);
    let s = max_rel(&est.s, &machine.sensitivity_frf(&f).unwrap(), 2000.0);
    let p = max_rel(&est.plant, &machine.plant_frf(&f).unwrap(), 2000.0);
    println!("{speed_rpm} rpm: T_ry {t:.2e}, S {s:.2e}, P {p:.2e}");
    assert!(t < 1e-6 && s < 1e-6 && p < 1e-6, "T {t} S {s} P {p}");
    if speed_rpm > 0.0 {
        // the test tells the speeds apart: the standstill truth is far from this estimate
        let still = Machine::new(MachineConfig::default()).unwrap();
        let d = max_rel(&est.plant, &still.plant_frf(&f).unwrap(), 2000.0);
        println!("  vs the standstill plant: {d:.2e}");
        assert!(d > 1e3 * p, "{d} vs {p}");
    }
}

fn prbs() -> PrbsSpec {
    // the seed PRBS (order 10, 5 samples per bit) at 2 % of i_sat per axis, 2 measured periods
    PrbsSpec {
        order: 10,
        samples_per_bit: 5,
        periods: 2,
        amplitude: 0.04,
        offset: 0.0,
    }
}

#[test]
fn sequential_and_orthogonal_estimates_equal_the_machine_truth_at_0_and_30000_rpm() {
    for speed in [0.0, 30_000.0] {
        check(
            speed,
            MultiInputDesign::sequential(4, prbs()).with_transient_periods(2),
        );
        check(
            speed,
            MultiInputDesign::orthogonal(4, prbs()).with_transient_periods(2),
        );
    }
}
