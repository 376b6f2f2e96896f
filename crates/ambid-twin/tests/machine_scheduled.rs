//! The speed-scheduled plant model (`ambid_core::estimate::scheduled`) on the 4-axis twin, issue
//! 21's bar: "the speed-scheduled model at an unused speed meets the 1 % plant bar", the plant
//! bar being the median over the lines in 10–1000 Hz of $\lVert\hat P - P\rVert_2/\lVert P\rVert_2$
//! (spectral norms of the 4×4 matrices, per line) ≤ 1 %.
//!
//! Built from 0, 7 500, 22 500 and 30 000 rpm, validated at 15 000 rpm (not used to build it)
//! against the twin's exact plant. The data are the plant's FRF on the lines of one PRBS period
//! (5115 samples at 20 kHz: Δf = 3.91 Hz, 253 lines in 10–1000 Hz). Cases:
//! * **exact**: per speed the exact plant in a random state basis, exact FRF;
//! * **noisy**: per speed the exact plant with every entry of $A - I$ perturbed by 0.3 %
//!   (relative, in the physical basis) in a random basis, and the FRF with complex Gaussian
//!   noise of 0.5 % of the line's RMS entry on every entry, with those variances;
//! * a **random rig** (`random_rig(3)` lifted to four axes), exact, so that the method is not
//!   tuned to the nominal machine.
//!
//! For contrast every case prints the error of the nearest build speed's exact plant used at
//! 15 000 rpm (what ignoring the speed dependence would give).
//!
//! Measured (median / max plant error at 15 000 rpm; debug profile, one fit):
//! | case | schedule | 7 500 rpm plant instead | fit |
//! |------|----------|-------------------------|-----|
//! | nominal, exact | 8.6e-11 / 2.9e-9 | 2.3e-3 | 2.7 s |
//! | nominal, noisy | 6.5e-4 / 2.4e-3 | 2.3e-3 | 3.6 s |
//! | random rig 3, exact | 1.2e-10 / 3.0e-9 | 2.3e-3 | 2.9 s |
//!
//! The nominal rotor's gyroscopic coupling is weak ($J_p/J_t \approx 0.01$): the 7 500 rpm plant
//! alone already meets the 1 % bar at 15 000 rpm, so the bar does not discriminate here; the
//! tests therefore also ask the exact schedule to be 100 times better than that and the noisy one
//! twice as good. Whole file: about 10 s in the debug profile.
use crate::common::random_basis;

use ambid_core::estimate::scheduled::{
    fit_scheduled, ScheduleOptions, SpeedData, SpeedScheduledModel,
};
use ambid_core::lti::{Frd, StateSpace};
use ambid_twin::{c64, random_rig, Machine, MachineConfig};
use faer::Mat;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::time::Instant;

const BUILD_RPM: [f64; 4] = [0.0, 7_500.0, 22_500.0, 30_000.0];
const UNUSED_RPM: f64 = 15_000.0;
/// Samples in one period of the default PRBS (order 10, 5 samples per bit: 1023 × 5).
const PERIOD: f64 = 5115.0;

/// The lines of one PRBS period in 10–1000 Hz.
fn lines(fs: f64) -> Vec<f64> {
    let df = fs / PERIOD;
    (1..)
        .map(|k| k as f64 * df)
        .skip_while(|&f| f < 10.0)
        .take_while(|&f| f <= 1000.0)
        .collect()
}

/// $A = I + \Delta$ with every entry of $\Delta$ times $1 + 0.003 g$ (structural zeros stay
/// zero): 0.3 % errors in the dynamics. (0.3 % of the entries of $A$ itself would move the poles
/// near $z = 1$ by some 10 % of their distance to 1, a model with errors of some 30 %, which no
/// identification would deliver.)
fn perturbed(p: &StateSpace, seed: u64) -> StateSpace {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let a = Mat::<f64>::from_fn(p.order(), p.order(), |i, j| {
        let g: f64 = StandardNormal.sample(&mut rng);
        let eye = if i == j { 1.0 } else { 0.0 };
        eye + (p.a()[(i, j)] - eye) * (1.0 + 0.003 * g)
    });
    StateSpace::discrete(
        a,
        p.b().to_owned(),
        p.c().to_owned(),
        p.d().to_owned(),
        p.ts().unwrap(),
    )
    .unwrap()
}

/// `frd` plus complex Gaussian noise of standard deviation `rel` × the line's RMS entry on every
/// entry, with those variances.
fn noisy(frd: &Frd, rel: f64, seed: u64) -> Frd {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut var = Vec::new();
    let mut mats = Vec::new();
    for k in 0..frd.len() {
        let g = frd.at(k).unwrap();
        let sigma = rel * g.norm_l2() / 4.0;
        let noisy = Mat::<c64>::from_fn(4, 4, |i, j| {
            let (a, b): (f64, f64) = (
                StandardNormal.sample(&mut rng),
                StandardNormal.sample(&mut rng),
            );
            g[(i, j)] + c64::new(a, b) * (sigma / 2f64.sqrt())
        });
        var.push(Mat::<f64>::from_fn(4, 4, |_, _| sigma * sigma));
        mats.push(noisy);
    }
    Frd::from_matrices(frd.f_hz(), &mats, Some(&var), frd.ts()).unwrap()
}

/// Largest singular value of a small complex matrix.
fn sigma_max(m: &Mat<c64>) -> f64 {
    m.singular_values().unwrap().into_iter().fold(0.0, f64::max)
}

/// Median and maximum over the lines of $\lVert\hat P - P\rVert_2/\lVert P\rVert_2$.
fn plant_error(model: &StateSpace, truth: &Frd) -> (f64, f64) {
    let g = model.freq_response(truth.f_hz()).unwrap();
    let mut r: Vec<f64> = (0..truth.len())
        .map(|k| {
            let t = truth.at(k).unwrap();
            sigma_max(&(&g[k] - &t)) / sigma_max(&t)
        })
        .collect();
    r.sort_by(f64::total_cmp);
    let l = r.len();
    let med = if l % 2 == 1 {
        r[l / 2]
    } else {
        0.5 * (r[l / 2 - 1] + r[l / 2])
    };
    (med, r[l - 1])
}

fn unstable(p: &StateSpace) -> Vec<c64> {
    let mut u: Vec<c64> = p
        .poles()
        .unwrap()
        .into_iter()
        .filter(|z| z.norm() > 1.0)
        .collect();
    u.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
    u
}

struct Case {
    name: &'static str,
    cfg: MachineConfig,
    exact: bool,
    seed: u64,
}

/// Builds the schedule for `case`, checks it at the unused speed and at a build speed, and
/// returns the median plant error at the unused speed.
fn run(case: &Case) -> (f64, f64, SpeedScheduledModel) {
    let machine = |rpm: f64| {
        Machine::new(MachineConfig {
            speed_rpm: rpm,
            ..case.cfg.clone()
        })
        .unwrap()
    };
    let ms: Vec<Machine> = BUILD_RPM.iter().map(|&s| machine(s)).collect();
    let f = lines(ms[0].fs());
    assert!((250..=256).contains(&f.len()), "{} lines", f.len());
    let (models, frds): (Vec<StateSpace>, Vec<Frd>) = ms
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let seed = case.seed + 10 * i as u64;
            let exact = m.plant_frf(&f).unwrap();
            if case.exact {
                (random_basis(m.plant(), seed), exact)
            } else {
                (
                    random_basis(&perturbed(m.plant(), seed + 1), seed),
                    noisy(&exact, 0.005, seed + 2),
                )
            }
        })
        .unzip();
    let data: Vec<SpeedData> = (0..BUILD_RPM.len())
        .map(|i| SpeedData {
            speed_rpm: BUILD_RPM[i],
            model: &models[i],
            frd: &frds[i],
        })
        .collect();
    let t0 = Instant::now();
    let sched = fit_scheduled(&data, &ScheduleOptions::default()).unwrap();
    let dt = t0.elapsed().as_secs_f64();
    eprintln!(
        "{}: fit in {dt:.1} s, reference {} rpm, degree {}, {} free entries of A",
        case.name,
        sched.reference_speed_rpm(),
        sched.degree(),
        sched.free_entries().len()
    );
    for fit in sched.fits() {
        eprintln!(
            "  {:>6} rpm: start {:?}, cost {:.3e} -> {:.3e} in {} steps ({:?}); per-speed model median/max {:.2e}/{:.2e}, schedule {:.2e}/{:.2e}",
            fit.speed_rpm,
            fit.start,
            fit.initial_cost,
            fit.cost,
            fit.iterations,
            fit.stop,
            fit.median_relative_error,
            fit.max_relative_error,
            fit.schedule_median_relative_error,
            fit.schedule_max_relative_error
        );
    }
    // the unused speed against the exact plant
    let truth_m = machine(UNUSED_RPM);
    let truth = truth_m.plant_frf(&f).unwrap();
    let p = sched.at(UNUSED_RPM).unwrap();
    let (med, max) = plant_error(&p, &truth);
    // contrast: the nearest build speed's exact plant
    let (near, _) = plant_error(ms[1].plant(), &truth);
    eprintln!(
        "  at {UNUSED_RPM} rpm (unused): plant error median {med:.3e}, max {max:.3e}; \
         the 7 500 rpm plant instead: median {near:.3e}"
    );
    assert!(med <= 0.01, "{}: median plant error {med}", case.name);
    // the truth's unstable poles
    let (u_hat, u_true) = (unstable(&p), unstable(truth_m.plant()));
    assert_eq!(u_true.len(), 4);
    assert_eq!(u_hat.len(), 4, "{}: unstable poles {u_hat:?}", case.name);
    for (a, b) in u_hat.iter().zip(&u_true) {
        eprintln!("  unstable pole {a:.6} (truth {b:.6})");
    }
    // a build speed: the schedule reproduces it
    let (med_b, max_b) = plant_error(
        &sched.at(BUILD_RPM[1]).unwrap(),
        &ms[1].plant_frf(&f).unwrap(),
    );
    eprintln!(
        "  at {} rpm (build): median {med_b:.3e}, max {max_b:.3e}",
        BUILD_RPM[1]
    );
    assert!(med_b <= 0.01, "{}: build speed {med_b}", case.name);
    (med, near, sched)
}

/// Exact per-speed models in random bases: the unused speed far below the bar.
#[test]
fn exact_models_meet_the_bar_at_an_unused_speed() {
    let (med, near, sched) = run(&Case {
        name: "nominal, exact",
        cfg: MachineConfig::default(),
        exact: true,
        seed: 100,
    });
    assert!(med < 1e-5, "median {med}");
    // the test has teeth: ignoring the speed would fail (or nearly fail) the bar by far more
    assert!(near > 100.0 * med, "nearest plant {near} vs {med}");
    for fit in sched.fits() {
        assert!(fit.max_relative_error < 1e-8, "{fit:?}");
    }
}

/// Perturbed models and noisy data with variances: the bar at the unused speed.
#[test]
fn noisy_data_meet_the_bar_at_an_unused_speed() {
    let (med, near, sched) = run(&Case {
        name: "nominal, noisy",
        cfg: MachineConfig::default(),
        exact: false,
        seed: 200,
    });
    assert!(med <= 0.01);
    // the speed dependence is resolved through the noise: better than the nearest build speed
    assert!(med < 0.5 * near, "{med} vs nearest plant {near}");
    for fit in sched.fits() {
        assert!(fit.median_relative_error < 0.02, "{fit:?}");
    }
}

/// A random rig lifted to four axes, exact models.
#[test]
fn random_rig_meets_the_bar_at_an_unused_speed() {
    let cfg = MachineConfig::from_twin(&random_rig(3).unwrap());
    let (med, _, _) = run(&Case {
        name: "random rig 3, exact",
        cfg,
        exact: true,
        seed: 300,
    });
    assert!(med < 1e-4, "median {med}");
}
