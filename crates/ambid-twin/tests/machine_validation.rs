//! Whole-machine validation (`ambid_core::validate::machine`) against the 4-axis twin's exact
//! truth: the true plant reproduces a noise-free record to rounding, its σ̄(S), per-axis ISO
//! peaks and closed-loop poles equal the twin's; a 5 % gain error scores visibly lower; the
//! "within 1 point of the true plant's fit" quantity on independent records (helper
//! [`fits_against_truth`], demonstrated with an N4SID model and the exact plant in a random
//! basis); random rigs; typed errors. Debug run times (idle machine): 0.7, 6.6, 5.0, 0.01 and
//! 5.2 s.
//!
//! Records: 6000 samples (0.3 s at 20 kHz) of seeded white-noise excitation (0.05 A RMS) on all
//! four axes, seeds 1000 + s (different from every identification design), the twin's sensor
//! noise from seed 2000 + s; the loop runs 4000 samples before the record.
use crate::common::random_basis;

use ambid_core::data::IoData;
use ambid_core::lti::StateSpace;
use ambid_core::validate::machine::{
    validate_machine, MachineValidation, MachineValidationOptions,
};
use ambid_twin::{c64, Machine, MachineConfig, MachineSimOptions};
use faer::Mat;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

const N: usize = 6000;

/// The independent validation record of `seed` (module docs).
fn record(m: &Machine, seed: u64, noise: bool) -> IoData {
    let mut rng = ChaCha8Rng::seed_from_u64(1000 + seed);
    let r: Vec<Vec<f64>> = (0..4)
        .map(|_| {
            (0..N)
                .map(|_| {
                    let g: f64 = StandardNormal.sample(&mut rng);
                    0.05 * g
                })
                .collect()
        })
        .collect();
    let opts = MachineSimOptions {
        seed: 2000 + seed,
        noise,
        settle_samples: 4000,
        ..Default::default()
    };
    m.simulate([&r[0], &r[1], &r[2], &r[3]], &opts)
        .unwrap()
        .to_iodata(None)
        .unwrap()
}

fn validate(m: &Machine, p: &StateSpace, data: &IoData) -> MachineValidation {
    validate_machine(
        p,
        m.controller(),
        data,
        &MachineValidationOptions::default(),
    )
    .unwrap()
}

/// **The bar's helper** (issue 21: "the per-axis closed-loop validation fit within 1 point of
/// the true plant's fit on the same record"): the per-axis displacement fits of `p_hat` and of
/// the twin's exact plant on the independent record of `seed` (default noise), as
/// `(model, truth)` per axis in `xa, xb, ya, yb` order. Call it with a fitted model.
pub fn fits_against_truth(m: &Machine, p_hat: &StateSpace, seed: u64) -> [(f64, f64); 4] {
    let data = record(m, seed, true);
    let model = validate(m, p_hat, &data);
    let truth = validate(m, m.plant(), &data);
    std::array::from_fn(|k| (model.axes[k].fit_y, truth.axes[k].fit_y))
}

/// The plant with every output scaled by `g` (a gain error).
fn scaled(p: &StateSpace, g: f64) -> StateSpace {
    StateSpace::discrete(
        p.a().to_owned(),
        p.b().to_owned(),
        p.c() * faer::Scale(g),
        p.d() * faer::Scale(g),
        p.ts().unwrap(),
    )
    .unwrap()
}

/// Largest singular value (naive oracle): $G = S^H S$ raised to the power $2^{60}$ by repeated
/// squaring (normalised by the trace), whose largest column spans the top eigenvector even for
/// nearly equal singular values (the x/y pairs of a symmetric rotor), then the Rayleigh quotient.
fn sigma_max_naive(s: &Mat<c64>) -> f64 {
    let g = s.adjoint() * s;
    let mut p = g.clone();
    for _ in 0..60 {
        let q = &p * &p;
        let tr: f64 = (0..q.nrows()).map(|i| q[(i, i)].re).sum();
        p = Mat::from_fn(q.nrows(), q.ncols(), |i, j| q[(i, j)] / tr);
    }
    let j = (0..p.ncols())
        .max_by(|&a, &b| p.col(a).norm_l2().total_cmp(&p.col(b).norm_l2()))
        .unwrap();
    let v = p.col(j).to_owned();
    let gv = &g * &v;
    let num: c64 = (0..v.nrows()).map(|i| v[i].conj() * gv[i]).sum();
    let den: f64 = (0..v.nrows()).map(|i| v[i].norm_sqr()).sum();
    (num.re / den).sqrt()
}

fn at_speed(rpm: f64) -> Machine {
    Machine::new(MachineConfig {
        speed_rpm: rpm,
        ..Default::default()
    })
    .unwrap()
}

/// With the twin's exact plant as P̂ and noise off, the closed-loop simulation reproduces the
/// record (y, u and the coil current i: 100 % to 1e-6 points); σ̄(S) on the grid equals the
/// naive SVD of the twin's exact S, every axis's |S_kk| peak, its frequency and ISO zone equal
/// the twin's `peak_sensitivity`, and the closed-loop poles are the twin's.
#[test]
fn true_plant_reproduces_the_record_and_the_truths_sensitivity() {
    let m = at_speed(15_000.0);
    let data = record(&m, 0, false);
    let v = validate(&m, m.plant(), &data);
    for a in &v.axes {
        eprintln!(
            "{}: fit y {:.9} u {:.9} i {:.9} (amplifier {:.9}); |S| peak {:.6} at {:.3} Hz zone {:?}",
            a.axis,
            a.fit_y,
            a.fit_u,
            a.fit_i.unwrap(),
            a.amplifier_fit.unwrap(),
            a.iso.peak,
            a.iso.f_peak_hz,
            a.iso.zone
        );
        assert!(a.fit_y > 100.0 - 1e-6, "{} fit y {}", a.axis, a.fit_y);
        assert!(a.fit_u > 100.0 - 1e-6, "{} fit u {}", a.axis, a.fit_u);
        assert!(
            a.fit_i.unwrap() > 100.0 - 1e-6,
            "{} fit i {:?}",
            a.axis,
            a.fit_i
        );
    }
    assert_eq!(
        v.axes.iter().map(|a| a.axis.as_str()).collect::<Vec<_>>(),
        ["xa", "xb", "ya", "yb"]
    );
    // σ̄(S) against the naive oracle on the twin's exact S, every 40th grid line
    let idx: Vec<usize> = (0..v.grid_hz.len()).step_by(40).collect();
    let f: Vec<f64> = idx.iter().map(|&k| v.grid_hz[k]).collect();
    let s_true = m.sensitivity_frf(&f).unwrap();
    for (j, &k) in idx.iter().enumerate() {
        let want = sigma_max_naive(&s_true.at(j).unwrap());
        assert!(
            (v.sigma_max[k] - want).abs() < 1e-8 * want,
            "σ̄ at {} Hz: {} vs {want}",
            f[j],
            v.sigma_max[k]
        );
    }
    let grid_max = v.sigma_max.iter().fold(0.0f64, |a, b| a.max(*b));
    assert!(v.sigma_max_peak >= grid_max);
    let at_peak = sigma_max_naive(
        &m.sensitivity_frf(&[v.sigma_max_f_hz])
            .unwrap()
            .at(0)
            .unwrap(),
    );
    assert!((at_peak - v.sigma_max_peak).abs() < 1e-8 * at_peak);
    // per-axis ISO: the twin's own peak search on its exact S_kk
    let truth = m.peak_sensitivity().unwrap();
    let zones = ambid_core::validate::iso::IsoZones::default();
    for (a, (f_t, s_t)) in v.axes.iter().zip(truth) {
        assert!(
            (a.iso.peak - s_t).abs() < 1e-8 * s_t,
            "{}: {} vs {s_t}",
            a.axis,
            a.iso.peak
        );
        assert!(
            (a.iso.f_peak_hz - f_t).abs() < 1e-4 * f_t,
            "{}: {} vs {f_t} Hz",
            a.axis,
            a.iso.f_peak_hz
        );
        assert_eq!(a.iso.zone, zones.zone(s_t));
        assert!(v.sigma_max_peak >= a.iso.peak * (1.0 - 1e-12));
    }
    // closed-loop poles: the twin's 36, each matched within 1e-8
    let tp = m.closed_loop_poles().unwrap();
    assert_eq!(v.closed_loop_poles.len(), tp.len());
    for z in &v.closed_loop_poles {
        let d = tp
            .iter()
            .map(|t| (t - z).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(d < 1e-8, "pole {z} is {d} from the twin's");
    }
    assert_eq!(v.closed_loop.order(), 36);
}

/// On records with the default sensor noise (5 seeds, 15 000 rpm, linear): the exact plant in a
/// random state basis scores the true plant's fit (the bar's quantity: |Δfit| below 1e-2
/// points, at most 7e-3 measured — the initial-state least squares fits the noise slightly
/// differently in another basis); a 5 % gain error scores more than the bar's 1 point lower on
/// every axis and fails the residual test of an output. The standstill plant (gyroscopic
/// coupling missing) is printed for information: at 15 000 rpm it scores within 0.1 point of the
/// truth (the nominal rotor's J_p/J_t ≈ 0.01 makes the coupling small in the time domain).
#[test]
fn right_and_wrong_plants_on_noisy_records() {
    let m = at_speed(15_000.0);
    let m0 = at_speed(0.0);
    let gain = scaled(m.plant(), 1.05);
    for seed in 0..5 {
        let fits = fits_against_truth(&m, &random_basis(m.plant(), seed), seed);
        eprintln!("seed {seed}: random basis vs truth {fits:?}");
        for (model, truth) in fits {
            assert!((model - truth).abs() < 1e-2, "{model} vs {truth}");
            assert!(truth > 50.0 && truth < 100.0, "truth fit {truth}");
        }
    }
    let data = record(&m, 7, true);
    let truth = validate(&m, m.plant(), &data);
    for (name, p) in [("5 % gain", &gain), ("standstill plant", m0.plant())] {
        let v = validate(&m, p, &data);
        for (a, t) in v.axes.iter().zip(&truth.axes) {
            eprintln!(
                "{name} {}: fit y {:.2} (truth {:.2}), u {:.2} (truth {:.2}); residuals pass {} (truth {})",
                a.axis,
                a.fit_y,
                t.fit_y,
                a.fit_u,
                t.fit_u,
                a.residuals.as_ref().unwrap().pass,
                t.residuals.as_ref().unwrap().pass
            );
            if name == "5 % gain" {
                assert!(
                    a.fit_y < t.fit_y - 1.0,
                    "{name} {}: {} vs {}",
                    a.axis,
                    a.fit_y,
                    t.fit_y
                );
            }
        }
        if name == "5 % gain" {
            assert!(
                v.axes.iter().any(|a| !a.residuals.as_ref().unwrap().pass),
                "{name}: every residual test passed"
            );
        }
    }
}

/// Three random rigs lifted to the machine (at 15 000 rpm where their loops stay stable, else at
/// standstill): the true plant reproduces a noise-free record and its ISO peaks are the twin's;
/// a 5 % gain error scores lower on every axis of a noisy record (by more than 1 point on at
/// least one).
#[test]
fn random_rigs() {
    for seed in [1u64, 2, 3] {
        let cfg = MachineConfig::from_twin(&ambid_twin::random_rig(seed).unwrap());
        let m = Machine::new(MachineConfig {
            speed_rpm: 15_000.0,
            ..cfg.clone()
        })
        .or_else(|_| Machine::new(cfg))
        .unwrap();
        let v = validate(&m, m.plant(), &record(&m, seed, false));
        let truth = m.peak_sensitivity().unwrap();
        for (a, (_, s_t)) in v.axes.iter().zip(truth) {
            assert!(
                a.fit_y > 100.0 - 1e-6 && a.fit_u > 100.0 - 1e-6,
                "rig {seed} {}: {} {}",
                a.axis,
                a.fit_y,
                a.fit_u
            );
            assert!(
                (a.iso.peak - s_t).abs() < 1e-8 * s_t,
                "rig {seed} {}",
                a.axis
            );
        }
        let noisy = record(&m, seed, true);
        let t = validate(&m, m.plant(), &noisy);
        let g = validate(&m, &scaled(m.plant(), 1.05), &noisy);
        for (a, b) in g.axes.iter().zip(&t.axes) {
            eprintln!(
                "rig {seed} at {} rpm {}: 5 % gain {:.2} vs truth {:.2}",
                m.config().speed_rpm,
                a.axis,
                a.fit_y,
                b.fit_y
            );
            assert!(a.fit_y < b.fit_y, "rig {seed} {}", a.axis);
        }
        let drop = g
            .axes
            .iter()
            .zip(&t.axes)
            .map(|(a, b)| b.fit_y - a.fit_y)
            .fold(0.0, f64::max);
        assert!(drop > 1.0, "rig {seed}: largest drop {drop}");
    }
}

/// Bad input gets typed errors that name the fix; an unstable loop is reported, not simulated.
#[test]
fn bad_input_is_refused_with_typed_errors() {
    use ambid_core::error::Error;
    let m = at_speed(15_000.0);
    let data = record(&m, 0, false);
    let (p, c) = (m.plant(), m.controller());
    let o = MachineValidationOptions::default();
    let msg = |e: Error| e.to_string();
    // a record without the u channel of an axis
    let no_u = IoData::new(
        data.channels()
            .iter()
            .filter(|(n, _)| n != "u_yb")
            .cloned()
            .collect(),
        data.ts(),
        None,
    )
    .unwrap();
    let e = msg(validate_machine(p, c, &no_u, &o).unwrap_err());
    assert!(e.contains("u_yb") && e.contains("y_yb"), "{e}");
    // no excitation and no reference
    let no_r = IoData::new(
        data.channels()
            .iter()
            .filter(|(n, _)| !n.starts_with("r_"))
            .cloned()
            .collect(),
        data.ts(),
        None,
    )
    .unwrap();
    let e = msg(validate_machine(p, c, &no_r, &o).unwrap_err());
    assert!(e.contains("nothing drives the loop"), "{e}");
    // a plant of the wrong shape: one axis's plant for a 4-axis record
    let pa = m.axis_plant(0).unwrap();
    assert!(matches!(
        validate_machine(&pa, c, &data, &o),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        validate_machine(p, &pa, &data, &o),
        Err(Error::DimensionMismatch { .. })
    ));
    // another sample time, a continuous model
    let slow = data.clone().with_period_samples(None).unwrap();
    let slow = IoData::new(slow.into_channels(), 2.0 * m.ts(), None).unwrap();
    assert!(matches!(
        validate_machine(p, c, &slow, &o),
        Err(Error::SampleTimeMismatch { .. })
    ));
    assert!(matches!(
        validate_machine(m.continuous_model(), c, &data, &o),
        Err(Error::DimensionMismatch { .. }) | Err(Error::TimeDomain(_))
    ));
    // the plant with the wrong sign: the loop is unstable, reported with its poles
    let e = validate_machine(&scaled(p, -1.0), c, &data, &o).unwrap_err();
    assert!(matches!(e, Error::Unstable { .. }), "{e}");
    assert!(msg(e).contains("unstable closed-loop poles"));
    // too much skipped, a non-finite sample
    let e = validate_machine(
        p,
        c,
        &data,
        &MachineValidationOptions {
            skip: N - 10,
            ..o.clone()
        },
    );
    assert!(msg(e.unwrap_err()).contains("skip"));
    let mut ch = data.channels().to_vec();
    ch[9].1[100] = f64::NAN;
    let nan = IoData::new(ch, data.ts(), None).unwrap();
    assert!(msg(validate_machine(p, c, &nan, &o).unwrap_err()).contains("non-finite"));
    // the MIMO loop simulation refuses channels of different lengths
    let short = vec![0.0; 10];
    let long = vec![0.0; 11];
    let r: Vec<&[f64]> = vec![&short, &long, &short, &short];
    assert!(matches!(
        ambid_core::validate::closed_loop::simulate_loop_mimo(p, c, None, Some(&r), None),
        Err(Error::DimensionMismatch { .. })
    ));
}

/// The helper with an identified model: N4SID (order 24, 10 block rows, CVA) on a noise-free
/// closed-loop record of the twin at 15 000 rpm (excitation seed 1099, not a validation seed)
/// recovers the unstable plant (4 unstable poles, as the truth), and on the five independent
/// noisy validation records its per-axis fits equal the true plant's to 1e-6 points (≈ 1e-10
/// measured): the bar's "within 1 point", met by a model made without the MIMO fitter.
#[test]
fn n4sid_model_meets_the_bar() {
    use ambid_core::estimate::subspace::{n4sid, SubspaceOptions};
    let m = at_speed(15_000.0);
    let id = record(&m, 99, false);
    let (y, u) = (id.y_matrix(0).unwrap(), id.u_matrix(0).unwrap());
    let opts = SubspaceOptions {
        order: Some(24),
        block_rows: Some(10),
        ..SubspaceOptions::new(m.ts())
    };
    let p = n4sid(y.as_ref(), u.as_ref(), &opts).unwrap().model;
    let unstable = |p: &StateSpace| p.poles().unwrap().iter().filter(|z| z.norm() > 1.0).count();
    assert_eq!(unstable(&p), unstable(m.plant()));
    assert_eq!(unstable(&p), 4);
    for seed in 0..5 {
        let fits = fits_against_truth(&m, &p, seed);
        eprintln!("seed {seed}: n4sid vs truth {fits:?}");
        for (model, truth) in fits {
            assert!(
                (model - truth).abs() < 1e-6,
                "seed {seed}: {model} vs {truth}"
            );
        }
    }
}
