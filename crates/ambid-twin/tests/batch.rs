//! `Twin::simulate_batch` against `Twin::simulate`: the lock-step lanes (their own RK4 code,
//! branch-free, SIMD) must give every run's record bit for bit as the scalar RK4 of a lone run
//! gives it, errors included, whatever the mix of twins, limits and options in the batch.

use ambid_core::signal::PrbsSpec;
use ambid_twin::{Integrator, Mode, SimOptions, SimRecord, Twin, TwinConfig};

fn prbs(amp: f64, periods: usize) -> Vec<f64> {
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

fn twin_at(i0: f64, g0: f64) -> Twin {
    let mut c = TwinConfig::default();
    c.operating_point.bias_current_a = i0;
    c.operating_point.air_gap_m = g0;
    Twin::new(c).unwrap()
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Equal to the last bit (`==` on f64 would let −0 equal +0).
fn assert_same(a: &SimRecord, b: &SimRecord, what: &str) {
    assert_eq!(a, b, "{what}");
    for (x, y, name) in [(&a.u, &b.u, "u"), (&a.y, &b.y, "y"), (&a.i, &b.i, "i")] {
        assert_eq!(bits(x), bits(y), "{what}: {name}");
    }
    if let (Some(x), Some(y)) = (&a.b, &b.b) {
        assert_eq!(bits(&x.u), bits(&y.u), "{what}: b.u");
        assert_eq!(bits(&x.y), bits(&y.y), "{what}: b.y");
        assert_eq!(bits(&x.i), bits(&y.i), "{what}: b.i");
    }
}

#[test]
fn every_run_of_a_batch_is_its_lone_run_bit_for_bit() {
    let nominal = twin_at(2.0, 4e-4);
    let low_bias = twin_at(1.6, 4e-4);
    let small_gap = twin_at(2.0, 3.9e-4);
    let mut qcfg = TwinConfig::default();
    qcfg.sensor.quantize = true;
    let quantized = Twin::new(qcfg).unwrap();
    let mut ecfg = TwinConfig::default();
    ecfg.simulation.integrator = Integrator::ExpRk4;
    let exp = Twin::new(ecfg).unwrap();

    let n = 5115;
    let small = prbs(0.04, 1);
    let mid = prbs(0.32, 1);
    // drives the rotor into the magnet: a touchdown error inside a batch
    let hard = prbs(0.9 * nominal.i_sat(), 1);
    // 90 % sine at 1 kHz: the slew limit is active, the rotor stays off the magnet
    let fs = nominal.fs();
    let sine: Vec<f64> = (0..n)
        .map(|k| {
            0.9 * nominal.i_sat() * (2.0 * std::f64::consts::PI * 1000.0 * k as f64 / fs).sin()
        })
        .collect();
    let nl = |seed: u64| SimOptions {
        mode: Mode::Nonlinear,
        seed,
        ..Default::default()
    };
    let with_w = SimOptions {
        w: Some((0..n).map(|k| 5e-6 * (k as f64 / 300.0).sin()).collect()),
        record_b: true,
        ..nl(7)
    };
    let settled = SimOptions {
        settle_samples: 1000,
        ..nl(8)
    };
    let quiet = SimOptions {
        noise: false,
        ..nl(9)
    };
    let linear = SimOptions {
        mode: Mode::Linear,
        ..nl(10)
    };
    let (o1, o2, o3, o4, o5, o6) = (nl(1), nl(2), nl(3), nl(4), nl(5), nl(6));
    let empty: Vec<f64> = Vec::new();
    let runs: Vec<(&Twin, &[f64], &SimOptions)> = vec![
        (&nominal, &small, &o1),
        (&low_bias, &mid, &o2),
        (&nominal, &hard, &o3),
        (&small_gap, &sine, &o4),
        (&quantized, &mid, &o5),
        (&nominal, &small, &with_w),
        (&nominal, &small, &settled),
        (&exp, &small, &o6),
        (&nominal, &empty, &o1),
        (&low_bias, &sine, &quiet),
        (&nominal, &mid, &linear),
        (&small_gap, &mid, &settled),
    ];
    let batch = Twin::simulate_batch(&runs);
    assert_eq!(batch.len(), runs.len());
    let mut limited = 0;
    for (j, (&(twin, r, opts), got)) in runs.iter().zip(&batch).enumerate() {
        let alone = twin.simulate(r, opts);
        match (got, &alone) {
            (Ok(a), Ok(b)) => {
                assert_same(a, b, &format!("run {j}"));
                limited += usize::from(a.meta.slew_limited_fraction > 0.0);
            }
            (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "run {j}"),
            _ => panic!("run {j}: batch {got:?} vs alone {alone:?}"),
        }
    }
    // the batch exercised the limits and the errors, not only the smooth path
    assert!(limited >= 2, "slew-limited runs: {limited}");
    assert!(matches!(
        batch[2],
        Err(ambid_twin::TwinError::Touchdown { .. })
    ));
    assert!(matches!(
        batch[8],
        Err(ambid_twin::TwinError::InvalidArgument { .. })
    ));
}

#[test]
fn a_lone_run_and_its_batch_are_equal_whatever_the_batch_size() {
    let twin = twin_at(2.0, 4e-4);
    let r = prbs(0.1, 1);
    let opts: Vec<SimOptions> = (0..5)
        .map(|seed| SimOptions {
            mode: Mode::Nonlinear,
            seed,
            ..Default::default()
        })
        .collect();
    let alone: Vec<SimRecord> = opts.iter().map(|o| twin.simulate(&r, o).unwrap()).collect();
    for size in 1..=opts.len() {
        let runs: Vec<(&Twin, &[f64], &SimOptions)> = opts[..size]
            .iter()
            .map(|o| (&twin, r.as_slice(), o))
            .collect();
        for (j, rec) in Twin::simulate_batch(&runs).into_iter().enumerate() {
            assert_same(&rec.unwrap(), &alone[j], &format!("size {size}, run {j}"));
        }
    }
}
