//! The gray-box physical parameters (`ambid_core::estimate::graybox`, `ambid::physical`, issue 23)
//! against the twin, whose linearisation is written independently in `ambid-twin`:
//!
//! * the gray-box plant at the twin's parameters equals the twin's exact plant (nominal and
//!   random rigs) to 1e-9 — the structure is right;
//! * from the exact plant FRF (variances 1e-4 |P|²) the fit recovers every parameter to 1e-6
//!   relative, from the black-box starts;
//! * from the seed experiment on the linear twin, on random rigs 21–60 (not used while writing
//!   the estimator, which was developed on the nominal rig): k_i and k_x within 2 %, the bending
//!   frequency within 0.5 % (issue 23's bars) on every run, and the 95 % intervals covering the
//!   truth on 85–100 % of the 40 runs for every parameter (the 90–98 % over ≥ 100 runs is
//!   measured by the `physical_rigs` example, docs/physical.md; 40 runs in CI give a binomial
//!   spread of ±7 points, hence the wider test band);
//! * on the *nonlinear* twin (random rigs 5 and 41, one seed each), the estimate at the default
//!   10 % level is the best linear approximation's, with $k_x$ well above the linearisation
//!   (more than three of its own standard deviations); extrapolated to zero amplitude from 7, 10
//!   and 14 % of $i_\text{sat}$ ([`ExtrapolatedRun`]) it is within 0.5 % and within three of
//!   its standard deviations (the intervals' coverage over 200 unseen rigs is in
//!   docs/physical.md);
//! * bad input: a model without an unstable pole, an FRF without variances, a drawing with a zero
//!   mass, a controller of another sample rate give typed errors.

use ambid::physical::{
    as_array, estimate, fit_physical, twin_drawing, Drawing, ExtrapolatedRun, Hints,
    PhysicalOptions, PhysicalParams, PhysicalRun, PARAMETER_NAMES,
};
use ambid_core::estimate::graybox::graybox_plant;
use ambid_core::lti::{Frd, StateSpace};
use ambid_twin::{random_rig, Mode, Twin, TwinConfig};

fn params_of(twin: &Twin) -> PhysicalParams {
    let (lp, r) = (twin.linear_params(), &twin.config().rotor);
    PhysicalParams {
        k_i: lp.k_i,
        k_x: lp.k_x,
        bending_hz: r.bending_freq_hz,
        bending_damping: r.bending_damping,
        mode_shape_a: r.mode_shape_a,
        mode_shape_b: r.mode_shape_b,
    }
}

fn log_lines(f0: f64, f1: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| f0 * (f1 / f0).powf(k as f64 / (n - 1) as f64))
        .collect()
}

#[test]
fn the_graybox_plant_is_the_twins_linearisation() {
    let f = log_lines(1.0, 9000.0, 200);
    for rig in [0u64, 3, 17, 33] {
        let cfg = if rig == 0 {
            TwinConfig::default()
        } else {
            random_rig(rig).unwrap()
        };
        let twin = Twin::new(cfg).unwrap();
        let gb = graybox_plant(
            &twin_drawing(twin.config()),
            &params_of(&twin),
            twin.controller(),
        )
        .unwrap();
        let a = gb.freq_response_siso(&f).unwrap();
        let b = twin.plant_frf(&f).unwrap();
        let e = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).norm() / y.norm())
            .fold(0.0, f64::max);
        assert!(e < 1e-9, "rig {rig}: {e:e}");
        // the same single unstable pole
        let up = |m: &StateSpace| m.poles().unwrap().iter().filter(|p| p.norm() > 1.0).count();
        assert_eq!(up(&gb), 1, "rig {rig}");
        assert_eq!(up(twin.plant()), 1, "rig {rig}");
    }
}

#[test]
fn exact_data_give_the_exact_parameters() {
    for rig in [0u64, 9] {
        let cfg = if rig == 0 {
            TwinConfig::default()
        } else {
            random_rig(rig).unwrap()
        };
        let twin = Twin::new(cfg).unwrap();
        let f: Vec<f64> = (1..=600).map(|k| 4.8828125 * k as f64).collect();
        let g = twin.plant_frf(&f).unwrap();
        let var: Vec<f64> = g.iter().map(|v| 1e-4 * v.norm_sqr()).collect();
        let ts = twin.plant().ts();
        let frd = Frd::new(f, g, Some(var), ts).unwrap();
        // the starts from the exact plant's poles (a black-box model of any order gives the same)
        let hints = Hints::from_model(twin.plant()).unwrap();
        let fit = fit_physical(
            &frd,
            &twin_drawing(twin.config()),
            twin.controller(),
            &hints,
            &PhysicalOptions::default(),
        )
        .unwrap();
        let mut truth = params_of(&twin);
        if truth.mode_shape_a < 0.0 {
            truth.mode_shape_a = -truth.mode_shape_a;
            truth.mode_shape_b = -truth.mode_shape_b;
        }
        let (e, t) = (as_array(&fit.params), as_array(&truth));
        for k in 0..6 {
            assert!(
                ((e[k] - t[k]) / t[k]).abs() < 1e-6,
                "rig {rig} {}: {} vs {}",
                PARAMETER_NAMES[k],
                e[k],
                t[k]
            );
        }
        assert!(fit.chi2 < 1e-6, "{}", fit.chi2);
        // the identifiable-without-the-drawing ratio
        let (r, (lo, hi)) = fit.ratio();
        assert!((r / (t[0] / t[1]) - 1.0).abs() < 1e-6 && lo <= r && r <= hi);
    }
}

#[test]
fn unseen_random_rigs_meet_the_accuracy_bars_and_the_intervals_cover() {
    let rigs: Vec<u64> = (21..=60).collect();
    let runs: Vec<PhysicalRun> = std::thread::scope(|s| {
        let handles: Vec<_> = rigs
            .chunks(rigs.len().div_ceil(2))
            .map(|chunk| {
                s.spawn(move || {
                    chunk
                        .iter()
                        // each rig with its own noise seed: no two runs share a realisation
                        .map(|&rig| PhysicalRun::on_twin(rig, rig, Mode::Linear).unwrap())
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    });
    let mut covered = [0usize; 6];
    let mut worst = [0.0f64; 6];
    for (rig, r) in rigs.iter().zip(&runs) {
        let (e, t) = (as_array(&r.fit.params), r.truth_array());
        for k in 0..6 {
            let rel = ((e[k] - t[k]) / t[k]).abs();
            worst[k] = worst[k].max(rel);
            let (lo, hi) = r.fit.intervals[k];
            covered[k] += usize::from(lo <= t[k] && t[k] <= hi);
        }
        assert!(((e[0] - t[0]) / t[0]).abs() < 0.02, "rig {rig}: k_i");
        assert!(((e[1] - t[1]) / t[1]).abs() < 0.02, "rig {rig}: k_x");
        assert!(((e[2] - t[2]) / t[2]).abs() < 0.005, "rig {rig}: f_b");
    }
    for k in 0..6 {
        let c = covered[k] as f64 / runs.len() as f64;
        println!(
            "{:>16}: coverage {c:.3}, worst |rel. error| {:.3} %",
            PARAMETER_NAMES[k],
            100.0 * worst[k]
        );
        assert!((0.85..=1.0).contains(&c), "{}: {c}", PARAMETER_NAMES[k]);
    }
}

#[test]
fn the_small_signal_kx_of_the_nonlinear_twin_is_recovered_by_extrapolation() {
    for (rig, seed) in [(5u64, 5u64), (41, 41)] {
        let r = ExtrapolatedRun::on_twin(rig, seed, Mode::Nonlinear, &[0.07, 0.10, 0.14]).unwrap();
        let kx = r.truth.k_x;
        // at 10 %: the BLA's stiffness, above the linearisation by more than 3σ
        let at10 = &r.at_levels[1].1;
        assert!(
            at10.params.k_x - kx > 3.0 * at10.std[1],
            "rig {rig}: k_x at 10 % {} vs {kx} (σ {})",
            at10.params.k_x,
            at10.std[1]
        );
        // at zero amplitude: within 0.5 % and within three of its standard deviations (one run
        // misses its 95 % interval in 5 % of runs by design; the coverage is measured over 200
        // rigs, docs/physical.md); the slope positive (the BLA stiffens with the level)
        let e = r.zero.params.k_x / kx - 1.0;
        assert!(
            e.abs() < 5e-3,
            "rig {rig}: k_x at zero amplitude {:+.3} %",
            100.0 * e
        );
        assert!(
            (r.zero.params.k_x - kx).abs() < 3.0 * r.zero.std[1],
            "rig {rig}: {} ± {} vs {kx}",
            r.zero.params.k_x,
            r.zero.std[1]
        );
        assert!(r.zero.slope[1] > 0.0, "rig {rig}");
        // the other bars hold at zero amplitude too
        let (est, truth) = (r.zero.params_array(), as_array(&r.truth));
        assert!((est[0] / truth[0] - 1.0).abs() < 0.02, "rig {rig}: k_i");
        assert!((est[2] / truth[2] - 1.0).abs() < 0.005, "rig {rig}: f_b");
    }
    // one level is refused with the fix named
    let err = ExtrapolatedRun::on_twin(5, 5, Mode::Nonlinear, &[0.1]).unwrap_err();
    assert!(err.to_string().contains("two or more"), "{err}");
}

#[test]
fn bad_input_gives_typed_errors() {
    let twin = Twin::new(TwinConfig::default()).unwrap();
    let f: Vec<f64> = (1..=100).map(|k| 10.0 * k as f64).collect();
    let g = twin.plant_frf(&f).unwrap();
    let var: Vec<f64> = g.iter().map(|v| 1e-4 * v.norm_sqr()).collect();
    let ts = twin.plant().ts();
    let frd = Frd::new(f.clone(), g.clone(), Some(var.clone()), ts).unwrap();
    let drawing = twin_drawing(twin.config());
    let opts = PhysicalOptions::default();
    // a stable model has no unstable pole to start k_x from
    let stable = twin.controller().clone();
    let e = estimate(&frd, &stable, &drawing, twin.controller(), &opts).unwrap_err();
    assert!(e.to_string().contains("unstable pole"), "{e}");
    // no variances
    let bare = Frd::new(f.clone(), g.clone(), None, ts).unwrap();
    let e = estimate(&bare, twin.plant(), &drawing, twin.controller(), &opts).unwrap_err();
    assert!(e.to_string().contains("variances"), "{e}");
    // a zero mass
    let bad = Drawing {
        mass_kg: 0.0,
        ..drawing
    };
    let e = estimate(&frd, twin.plant(), &bad, twin.controller(), &opts).unwrap_err();
    assert!(e.to_string().contains("mass_kg"), "{e}");
    // a controller of another sample rate
    let c2 = StateSpace::discrete(
        faer::mat![[0.5]],
        faer::mat![[1.0]],
        faer::mat![[1.0]],
        faer::mat![[1.0]],
        1e-4,
    )
    .unwrap();
    let e = estimate(&frd, twin.plant(), &drawing, &c2, &opts).unwrap_err();
    assert!(e.to_string().contains("sample time"), "{e}");
}
