//! The number of unstable poles in fits to FRF data: the Nyquist count of a measured loop
//! (`validate::compare::unstable_poles_from_loop`) on loops with a known count, and fits held to
//! a count (`FreqFitOptions::max_unstable_poles`) on a noisy AMB-like plant.

use ambid_core::c64;
use ambid_core::estimate::freqfit::{arx_frd, oe_frd, FreqFitOptions, TfOrders};
use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
use ambid_core::lti::{Frd, StateSpace};
use ambid_core::validate::compare::{closed_loop_stable, unstable_poles_from_loop};
use faer::{mat, Mat};

fn first_order(pole: f64, gain: f64, ts: f64) -> StateSpace {
    StateSpace::discrete(mat![[pole]], mat![[1.0]], mat![[gain]], mat![[0.0]], ts).unwrap()
}

/// C(z) = (k1 z + k0)/(z + p) in controllable form.
fn lead(k1: f64, k0: f64, p: f64, ts: f64) -> StateSpace {
    // (k1 z + k0)/(z + p) = k1 + (k0 - k1 p)/(z + p)
    StateSpace::discrete(mat![[-p]], mat![[1.0]], mat![[k0 - k1 * p]], mat![[k1]], ts).unwrap()
}

#[test]
fn nyquist_count_of_loops_with_known_unstable_poles() {
    let ts = 1e-3;
    let f: Vec<f64> = (1..450).map(|k| k as f64).collect();
    let count = |p: &StateSpace, c: &StateSpace| {
        assert!(closed_loop_stable(p, c), "the test loop must be stable");
        unstable_poles_from_loop(&Frd::from_model(p, &f).unwrap(), c, None).unwrap()
    };
    let gain = |k: f64| {
        StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[k]], ts).unwrap()
    };
    // stable plant, proportional controller: closed-loop pole 0.9 - 0.2 = 0.7
    assert_eq!(count(&first_order(0.9, 0.1, ts), &gain(2.0)), 0);
    // one unstable pole at 1.05: closed-loop pole 0.85
    let p1 = first_order(1.05, 0.1, ts);
    assert_eq!(count(&p1, &gain(2.0)), 1);
    // the same with a PI controller 2 + 0.01 z/(z - 1) (a pole on the unit circle at z = 1:
    // closed-loop poles 0.993 and 0.856)
    let pi =
        StateSpace::discrete(mat![[1.0]], mat![[1.0]], mat![[0.01]], mat![[2.01]], ts).unwrap();
    assert_eq!(count(&p1, &pi), 1);
    // two unstable poles, 1.02 and 1.05, with a lead (k1 z + k0)/(z + p) placing the closed-loop
    // poles at 0.5 (triple): (z + p)(z² − 2.07 z + 1.071) + k1 z + k0 = (z − 0.5)³
    let (p, k1) = (0.57, 0.75 - 1.071 + 2.07 * 0.57);
    let k0 = -0.125 - 1.071 * p;
    let a = mat![[2.07, -1.071], [1.0, 0.0]];
    let p2 =
        StateSpace::discrete(a, mat![[1.0], [0.0]], mat![[0.0, 1.0]], mat![[0.0]], ts).unwrap();
    let c2 = lead(k1, k0, p, ts);
    let cl = p2.feedback(&c2).unwrap().poles().unwrap();
    assert!(
        cl.iter().all(|z| (z - c64::new(0.5, 0.0)).norm() < 1e-4),
        "{cl:?}"
    );
    assert_eq!(count(&p2, &c2), 2);
    // a band that stops where the loop gain is still above 1 cannot be counted
    let frd = Frd::from_model(&p1, &f).unwrap();
    let err = unstable_poles_from_loop(&frd, &gain(2.0), Some((1.0, 5.0))).unwrap_err();
    assert!(err.to_string().contains("rolled off"), "{err}");
}

/// An AMB-like plant at 20 kHz (as in the `freqfit_ss` unit tests): one unstable real pole at
/// 1.0206, a stable one at 0.9795, pairs at 125 Hz (ζ = 0.2) and 754 Hz (ζ = 0.016), a real pole
/// at 1868 Hz; seen on 253 lines in 12–1000 Hz with 1 % relative noise.
fn amb_like() -> (StateSpace, Frd, Vec<f64>) {
    let ts = 5e-5;
    let pi = std::f64::consts::PI;
    let pair = |f: f64, z: f64| {
        let s = c64::new(-z * 2.0 * pi * f, 2.0 * pi * f * (1.0 - z * z).sqrt());
        (s * ts).exp()
    };
    let (p1, p2) = (pair(125.0, 0.2), pair(754.0, 0.016));
    let n = 7;
    let mut a = Mat::<f64>::zeros(n, n);
    for (o, p) in [(0, p1), (2, p2)] {
        a[(o, o)] = p.re;
        a[(o, o + 1)] = p.im;
        a[(o + 1, o)] = -p.im;
        a[(o + 1, o + 1)] = p.re;
    }
    a[(4, 4)] = 1.0206;
    a[(5, 5)] = 0.9795;
    a[(6, 6)] = 0.55;
    let b = Mat::from_fn(n, 1, |i, _| [1.0, 0.0, 1.0, 0.0, 1.0, 1.0, 1.0][i]);
    let c = Mat::from_fn(1, n, |_, j| [0.02, 0.01, 0.1, -0.05, 0.01, -0.01, 0.3][j]);
    let truth = StateSpace::discrete(a, b, c, mat![[0.0]], ts).unwrap();
    let f: Vec<f64> = (3..256).map(|k| 3.91 * k as f64).collect();
    let g0 = truth.freq_response_siso(&f).unwrap();
    let mut seed = 777u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    // uniform in ±0.5 has RMS 0.29: 1 % relative RMS per component
    let vals: Vec<c64> = g0
        .iter()
        .map(|g| g * (1.0 + c64::new(rnd(), rnd()) * 0.01 / 0.29))
        .collect();
    (truth, Frd::new(f.clone(), vals, None, Some(ts)).unwrap(), f)
}

fn median_error(m: &StateSpace, truth: &StateSpace, f: &[f64]) -> f64 {
    let (g, t) = (
        m.freq_response_siso(f).unwrap(),
        truth.freq_response_siso(f).unwrap(),
    );
    let mut e: Vec<f64> = g
        .iter()
        .zip(&t)
        .map(|(a, b)| (a - b).norm() / b.norm())
        .collect();
    e.sort_by(f64::total_cmp);
    e[e.len() / 2]
}

#[test]
fn fits_held_to_the_supported_number_of_unstable_poles() {
    let (truth, frd, f) = amb_like();
    let held = FreqFitOptions {
        max_unstable_poles: Some(1),
        max_iterations: 300,
        ..FreqFitOptions::default()
    };
    let free = FreqFitOptions {
        max_iterations: 300,
        ..FreqFitOptions::default()
    };
    let unstable = |m: &StateSpace| -> Vec<c64> {
        m.poles()
            .unwrap()
            .into_iter()
            .filter(|z| z.norm() > 1.0)
            .collect()
    };
    let mut spurious_free = 0;
    for order in 7..=10 {
        let o = TfOrders {
            nb: order,
            nf: order,
            nk: 1,
        };
        let fits = [
            (
                "ss",
                ss_frd(&frd, order, &held, &SsFreqOptions::default())
                    .unwrap()
                    .model,
                ss_frd(&frd, order, &free, &SsFreqOptions::default())
                    .unwrap()
                    .model,
            ),
            (
                "oe",
                oe_frd(&frd, &o, &held)
                    .unwrap()
                    .model
                    .to_state_space()
                    .unwrap(),
                oe_frd(&frd, &o, &free)
                    .unwrap()
                    .model
                    .to_state_space()
                    .unwrap(),
            ),
            (
                "arx",
                arx_frd(&frd, &o, &held)
                    .unwrap()
                    .model
                    .to_state_space()
                    .unwrap(),
                arx_frd(&frd, &o, &free)
                    .unwrap()
                    .model
                    .to_state_space()
                    .unwrap(),
            ),
        ];
        for (name, m, m_free) in &fits {
            let u = unstable(m);
            let (e, e_free) = (
                median_error(m, &truth, &f),
                median_error(m_free, &truth, &f),
            );
            eprintln!(
                "{name} {order}: held {} unstable {:?}, median {:.3} % | free {} unstable, median {:.3} %",
                u.len(),
                u,
                100.0 * e,
                unstable(m_free).len(),
                100.0 * e_free
            );
            spurious_free += usize::from(unstable(m_free).len() > 1);
            assert!(u.len() <= 1, "{name} {order}: {u:?}");
            if *name != "arx" {
                // the unstable pole is the plant's (kept, not reflected), and holding the count
                // costs no accuracy: at most 1 % median error or 10 % above the free fit's
                // (OE 8 lands in the same poorer local optimum with or without the constraint)
                assert_eq!(u.len(), 1, "{name} {order}");
                assert!(
                    (u[0] - c64::new(1.0206, 0.0)).norm() < 5e-3,
                    "{name} {order}: {u:?}"
                );
                assert!(
                    e < 0.01_f64.max(1.1 * e_free),
                    "{name} {order}: median error {e} (free {e_free})"
                );
            }
        }
    }
    eprintln!("unconstrained fits with spurious unstable poles: {spurious_free}");
    // the premise: without the constraint some fits do carry spurious unstable poles
    assert!(spurious_free >= 1);
    // with no unstable pole allowed the fit honours it (a worse model, never a reflected one)
    let none = FreqFitOptions {
        max_unstable_poles: Some(0),
        ..FreqFitOptions::default()
    };
    let m = ss_frd(&frd, 7, &none, &SsFreqOptions::default()).unwrap();
    let m1 = ss_frd(&frd, 7, &held, &SsFreqOptions::default()).unwrap();
    let (e0, e1) = (
        median_error(&m.model, &truth, &f),
        median_error(&m1.model, &truth, &f),
    );
    eprintln!(
        "SS 7 held to 0 unstable poles: median {:.3} %, cost {:.4e} (held to 1: {:.3} %, {:.4e})",
        100.0 * e0,
        m.cost,
        100.0 * e1,
        m1.cost
    );
    assert!(unstable(&m.model).is_empty());
    assert!(e0 > 3.0 * e1 && m.cost > 3.0 * m1.cost);
}
