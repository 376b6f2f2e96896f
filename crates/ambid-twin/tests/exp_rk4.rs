//! The exponential (Lawson) RK4 integrator against the RK4 reference and the exact linear mode.
//!
//! Errors are stated as $\max_k |a_k - b_k| / \operatorname{RMS}(b)$ per recorded signal.

use ambid_core::signal::PrbsSpec;
use ambid_twin::{Integrator, Mode, SimOptions, SimRecord, Twin, TwinConfig};

fn prbs10(amp: f64, periods: usize) -> Vec<f64> {
    PrbsSpec {
        order: 10,
        samples_per_bit: 5,
        periods,
        amplitude: amp,
        offset: 0.0,
    }
    .generate(5e-5)
    .unwrap()
    .values
}

fn twin(integrator: Integrator, substeps: usize, exp_substeps: usize) -> Twin {
    let mut cfg = TwinConfig::default();
    cfg.simulation.integrator = integrator;
    cfg.simulation.substeps = substeps;
    cfg.simulation.exp_substeps = exp_substeps;
    Twin::new(cfg).unwrap()
}

fn run(twin: &Twin, r: &[f64], mode: Mode) -> SimRecord {
    let opts = SimOptions {
        mode,
        noise: false,
        record_b: true,
        ..Default::default()
    };
    twin.simulate(r, &opts).unwrap()
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// Largest error relative to the reference's RMS over y, u, i of bearing A and B.
fn rel_err(a: &SimRecord, reference: &SimRecord) -> [f64; 3] {
    let e = |x: &[f64], r: &[f64]| {
        x.iter()
            .zip(r)
            .map(|(x, r)| (x - r).abs())
            .fold(0.0, f64::max)
            / rms(r)
    };
    let (ab, rb) = (a.b.as_ref().unwrap(), reference.b.as_ref().unwrap());
    [
        e(&a.y, &reference.y).max(e(&ab.y, &rb.y)),
        e(&a.u, &reference.u).max(e(&ab.u, &rb.u)),
        e(&a.i, &reference.i).max(e(&ab.i, &rb.i)),
    ]
}

fn worst(e: [f64; 3]) -> f64 {
    e.into_iter().fold(0.0, f64::max)
}

#[test]
fn tiny_amplitude_matches_exact_linear_mode() {
    let exp = twin(Integrator::ExpRk4, 10, 1);
    let r = prbs10(0.001 * exp.i_sat(), 2);
    let lin = run(&exp, &r, Mode::Linear);
    let nl = run(&exp, &r, Mode::Nonlinear);
    let e = rel_err(&nl, &lin);
    eprintln!(
        "0.1 % i_sat, exp_rk4 vs exact linear mode: y {:.2e}, u {:.2e}, i {:.2e}",
        e[0], e[1], e[2]
    );
    // the residual is second order in the (relative) amplitude 1e-3
    assert!(worst(e) < 5e-6, "{e:?}");
    assert_eq!(nl.meta.integrator, Some(Integrator::ExpRk4));
    assert_eq!(nl.meta.substeps, 1);
}

/// exp_rk4 (1 and 2 steps) and RK4-10 against RK4-40 at `frac` of i_sat.
fn against_reference(
    r: &[f64],
) -> (
    [f64; 3],
    [f64; 3],
    [f64; 3],
    SimRecord,
    SimRecord,
    SimRecord,
) {
    let reference = run(&twin(Integrator::Rk4, 40, 1), r, Mode::Nonlinear);
    let rk10 = run(&twin(Integrator::Rk4, 10, 1), r, Mode::Nonlinear);
    let exp1 = run(&twin(Integrator::ExpRk4, 10, 1), r, Mode::Nonlinear);
    let exp2 = run(&twin(Integrator::ExpRk4, 10, 2), r, Mode::Nonlinear);
    let (e10, e1, e2) = (
        rel_err(&rk10, &reference),
        rel_err(&exp1, &reference),
        rel_err(&exp2, &reference),
    );
    let f = |e: [f64; 3]| format!("{:.2e}/{:.2e}/{:.2e}", e[0], e[1], e[2]);
    eprintln!(
        "  RK4-40 slew fraction {:.4}, exp_rk4-1 {:.4}",
        reference.meta.slew_limited_fraction, exp1.meta.slew_limited_fraction
    );
    eprintln!(
        "  vs RK4-40 (y/u/i): rk4-10 {}, exp_rk4-1 {}, exp_rk4-2 {}",
        f(e10),
        f(e1),
        f(e2)
    );
    (e10, e1, e2, reference, rk10, exp1)
}

#[test]
fn prbs_2_and_16_percent_match_rk4_reference() {
    // 2 %: smooth (no limit active); exp_rk4 with one step per period is at least as close to
    // the reference as RK4 with 10 substeps
    let r = prbs10(0.02 * 2.0, 3);
    eprintln!("PRBS 2 % i_sat:");
    let (e10, e1, e2, reference, ..) = against_reference(&r);
    assert_eq!(reference.meta.saturated_fraction, 0.0);
    assert!(
        worst(e1) <= worst(e10) && worst(e1) < 3e-7,
        "{e1:?} vs {e10:?}"
    );
    assert!(worst(e2) < 5e-8, "{e2:?}");
    // 16 %: the slew limit is briefly active (≈ 0.3 % of the samples); the kink inside a step
    // costs exp_rk4 its order there, so it is NOT as close as RK4-10 (≈ 2e-4): ≈ 3.4e-3 with one
    // step, ≈ 1.4e-3 with two
    let r = prbs10(0.16 * 2.0, 3);
    eprintln!("PRBS 16 % i_sat:");
    let (e10, e1, e2, reference, _, exp1) = against_reference(&r);
    assert!(worst(e10) < 5e-4, "{e10:?}");
    assert!(worst(e1) < 5e-3, "{e1:?}");
    assert!(worst(e2) < 2e-3, "{e2:?}");
    let dslew = (exp1.meta.slew_limited_fraction - reference.meta.slew_limited_fraction).abs();
    assert!(dslew < 1e-3, "{dslew}");
}

#[test]
fn slew_limited_sine_matches_rk4_reference() {
    let fs = 20e3;
    let r: Vec<f64> = (0..4000)
        .map(|k| 0.9 * 2.0 * (2.0 * std::f64::consts::PI * 1000.0 * k as f64 / fs).sin())
        .collect();
    eprintln!("90 % sine 1 kHz:");
    let (e10, e1, e2, reference, rk10, exp1) = against_reference(&r);
    for (name, rec) in [
        ("rk4-40", &reference),
        ("rk4-10", &rk10),
        ("exp_rk4-1", &exp1),
    ] {
        let m = &rec.meta;
        eprintln!(
            "  {name}: saturated {:.4}, clamp {:.4}, amp {:.4}, slew {:.4}",
            m.saturated_fraction, m.clamp_fraction, m.amp_limit_fraction, m.slew_limited_fraction
        );
    }
    for (a, b) in [
        (
            exp1.meta.saturated_fraction,
            reference.meta.saturated_fraction,
        ),
        (
            exp1.meta.slew_limited_fraction,
            reference.meta.slew_limited_fraction,
        ),
        (exp1.meta.clamp_fraction, reference.meta.clamp_fraction),
        (
            exp1.meta.amp_limit_fraction,
            reference.meta.amp_limit_fraction,
        ),
    ] {
        assert!((a - b).abs() < 0.005, "{a} vs {b}");
    }
    // slew-limited most of the time: first-order-like behaviour at the kinks; RK4-10 ≈ 1.5e-3,
    // exp_rk4 ≈ 8e-2 (1 step) and ≈ 3e-2 (2 steps) of each signal's RMS
    assert!(worst(e10) < 3e-3, "{e10:?}");
    assert!(worst(e1) < 0.12, "{e1:?}");
    assert!(worst(e2) < 0.045, "{e2:?}");
}

#[test]
fn same_seed_same_record() {
    let exp = twin(Integrator::ExpRk4, 10, 1);
    let r = prbs10(0.04, 1);
    let opts = SimOptions {
        mode: Mode::Nonlinear,
        seed: 42,
        noise: true,
        ..Default::default()
    };
    let a = exp.simulate(&r, &opts).unwrap();
    let b = exp.simulate(&r, &opts).unwrap();
    assert_eq!(a, b);
    let c = exp.simulate(&r, &SimOptions { seed: 43, ..opts }).unwrap();
    assert_ne!(a.y, c.y);
}
