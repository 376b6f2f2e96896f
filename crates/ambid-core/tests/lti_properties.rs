//! Property and analytic-oracle tests of `lti` and `linalg`: DFT of the impulse response,
//! logm∘expm, round trips, naive difference-equation filters, typed errors, and seeded proptests
//! of the interconnection algebra.

use ambid_core::c64;
use ambid_core::linalg;
use ambid_core::lti::{FeedbackSign, Frd, PolyModel, StateSpace, Structure, TransferFunction};
use ambid_core::Error;
use faer::{mat, Mat};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use std::f64::consts::PI;

/// Small deterministic generator (SplitMix64) for test matrices.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
    fn mat(&mut self, r: usize, c: usize, s: f64) -> Mat<f64> {
        Mat::from_fn(r, c, |_, _| s * self.next())
    }
}

/// A random discrete model with spectral radius `rho`.
fn random_discrete(rng: &mut Rng, n: usize, p: usize, m: usize, rho: f64, ts: f64) -> StateSpace {
    let a = rng.mat(n, n, 1.0);
    let r = linalg::eigenvalues(a.as_ref())
        .unwrap()
        .iter()
        .fold(0.0f64, |x, z| x.max(z.norm()));
    let a = Mat::from_fn(n, n, |i, j| a[(i, j)] * rho / r);
    StateSpace::discrete(
        a,
        rng.mat(n, m, 1.0),
        rng.mat(p, n, 1.0),
        rng.mat(p, m, 0.5),
        ts,
    )
    .unwrap()
}

#[test]
fn freq_response_equals_dft_of_impulse_response() {
    let mut rng = Rng(7);
    let ts = 1e-3;
    let sys = random_discrete(&mut rng, 5, 1, 1, 0.8, ts);
    let n = 1024; // 0.8^1024 ≈ 1e-99: truncation far below rounding
    let h = sys.impulse_response_siso(n).unwrap();
    let bins: Vec<usize> = (0..n / 2).step_by(7).collect();
    let f: Vec<f64> = bins.iter().map(|&k| k as f64 / (n as f64 * ts)).collect();
    let g = sys.freq_response_siso(&f).unwrap();
    for (i, &k) in bins.iter().enumerate() {
        // naive DFT, the oracle
        let mut s = c64::new(0.0, 0.0);
        for (t, ht) in h.iter().enumerate() {
            let ph = -2.0 * PI * ((k * t) % n) as f64 / n as f64;
            s += c64::from_polar(*ht, ph);
        }
        assert!(
            (s - g[i]).norm() <= 1e-10 * g[i].norm().max(1.0),
            "bin {k}: {s} vs {}",
            g[i]
        );
    }
    // the same through TransferFunction and PolyModel (OE)
    let tf = TransferFunction::from_state_space(&sys).unwrap();
    let g2 = tf.freq_response(&f).unwrap();
    let oe = PolyModel::oe(tf.num().to_vec(), tf.den().to_vec(), ts).unwrap();
    let g3 = oe.freq_response(&f).unwrap();
    for i in 0..f.len() {
        assert!((g2[i] - g[i]).norm() <= 1e-10 * g[i].norm().max(1.0));
        assert!((g3[i] - g[i]).norm() <= 1e-10 * g[i].norm().max(1.0));
    }
}

#[test]
fn mimo_simulation_is_convolution_with_markov_parameters() {
    let mut rng = Rng(11);
    let sys = random_discrete(&mut rng, 4, 2, 3, 0.9, 0.01);
    let nt = 60;
    let u = rng.mat(nt, 3, 1.0);
    let y = sys.simulate(u.as_ref(), None).unwrap();
    let h = sys.impulse_response(nt).unwrap();
    for k in 0..nt {
        for o in 0..2 {
            let mut s = 0.0;
            for j in 0..=k {
                for i in 0..3 {
                    s += h[j][(o, i)] * u[(k - j, i)];
                }
            }
            assert!((s - y[(k, o)]).abs() < 1e-12 * (1.0 + s.abs()));
        }
    }
    // SISO path agrees with the MIMO path, with an initial state
    let siso = random_discrete(&mut rng, 3, 1, 1, 0.95, 0.01);
    let u1: Vec<f64> = (0..30).map(|_| rng.next()).collect();
    let x0 = [0.3, -1.0, 2.0];
    let y1 = siso.simulate_siso(&u1, Some(&x0)).unwrap();
    let um = Mat::from_fn(30, 1, |k, _| u1[k]);
    let y2 = siso.simulate(um.as_ref(), Some(&x0)).unwrap();
    for k in 0..30 {
        assert!((y1[k] - y2[(k, 0)]).abs() < 1e-13);
    }
}

#[test]
fn logm_inverts_expm() {
    let mut rng = Rng(3);
    for (n, s) in [(1, 0.5), (3, 1.0), (5, 2.0), (8, 0.7), (4, 5.0)] {
        // |Im λ| < π is needed for logm(expm(X)) = X; scale a random matrix accordingly
        let x = rng.mat(n, n, s);
        let r = linalg::eigenvalues(x.as_ref())
            .unwrap()
            .iter()
            .fold(0.0f64, |m, z| m.max(z.im.abs()));
        let x = if r > 2.5 {
            Mat::from_fn(n, n, |i, j| x[(i, j)] * 2.5 / r)
        } else {
            x
        };
        let e = linalg::expm(x.as_ref()).unwrap();
        let l = linalg::logm(e.as_ref()).unwrap();
        let err = (&l - &x).norm_max();
        assert!(err < 1e-10 * x.norm_max().max(1.0), "n={n}: {err:.3e}");
    }
    // rotation by 3 rad (close to π): the principal logarithm is the generator
    let x = mat![[0.0, 3.0], [-3.0, 0.0]];
    let l = linalg::logm(linalg::expm(x.as_ref()).unwrap().as_ref()).unwrap();
    assert!((&l - &x).norm_max() < 1e-12);
    // identity and a diagonal: log is exact
    let l = linalg::logm(mat![[2.0, 0.0], [0.0, 0.5]].as_ref()).unwrap();
    assert!((l[(0, 0)] - 2f64.ln()).abs() < 1e-15 && (l[(1, 1)] - 0.5f64.ln()).abs() < 1e-15);
    // negative real eigenvalue: typed error
    assert!(matches!(
        linalg::logm(mat![[-1.0, 0.0], [0.0, 1.0]].as_ref()),
        Err(Error::InvalidArgument { .. })
    ));
    assert!(linalg::logm(mat![[0.0]].as_ref()).is_err());
}

#[test]
fn tf_ss_tf_round_trip_with_delay_and_normalisation() {
    // 2 q^-2 (1 + 0.5 q^-1) / (2 - 1.4 q^-1 + 0.5 q^-2): delay of two samples, den[0] = 2
    let tf = TransferFunction::new(vec![0.0, 0.0, 2.0, 1.0], vec![2.0, -1.4, 0.5], 1e-4).unwrap();
    assert_eq!(tf.den()[0], 1.0);
    let ss = tf.to_state_space().unwrap();
    assert_eq!(ss.order(), 3);
    let back = TransferFunction::from_state_space(&ss).unwrap();
    let want_num = [0.0, 0.0, 1.0, 0.5];
    let want_den = [1.0, -0.7, 0.25, 0.0];
    for (g, w) in back.num().iter().zip(want_num) {
        assert!((g - w).abs() < 1e-12, "{:?}", back.num());
    }
    for (g, w) in back.den().iter().zip(want_den) {
        assert!((g - w).abs() < 1e-12, "{:?}", back.den());
    }
    // time-domain: difference equation = state-space simulation
    let u: Vec<f64> = (0..40).map(|k| ((k * 7919) % 13) as f64 - 6.0).collect();
    let y1 = tf.simulate(&u).unwrap();
    let y2 = ss.simulate_siso(&u, None).unwrap();
    for k in 0..u.len() {
        assert!((y1[k] - y2[k]).abs() < 1e-12 * (1.0 + y1[k].abs()));
    }
    assert_eq!(&y1[..2], &[0.0, 0.0]);
    // zeros: -0.5 (delay gives zeros at infinity, not listed); poles: 0.35 ± j·0.357, 0
    let z = tf.zeros().unwrap();
    assert_eq!(z.len(), 1);
    assert!((z[0].re + 0.5).abs() < 1e-14);
    assert_eq!(tf.poles().unwrap().len(), 3);
}

/// Naive simulation of A y = B/F u + C/D e by filtering, the oracle for PolyModel::simulate.
fn filter(num: &[f64], den: &[f64], x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    for k in 0..x.len() {
        let mut s = 0.0;
        for (i, b) in num.iter().enumerate() {
            if i <= k {
                s += b * x[k - i];
            }
        }
        for (i, a) in den.iter().enumerate().skip(1) {
            if i <= k {
                s -= a * y[k - i];
            }
        }
        y[k] = s / den[0];
    }
    y
}

fn conv(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

#[test]
fn poly_model_general_structure() {
    let (a, b, c, d, f) = (
        vec![1.0, -0.5],
        vec![0.0, 0.0, 1.0, 0.4],
        vec![1.0, 0.3],
        vec![1.0, -0.9],
        vec![1.0, -1.2, 0.5],
    );
    let m =
        PolyModel::general(a.clone(), b.clone(), c.clone(), d.clone(), f.clone(), 1e-3).unwrap();
    assert_eq!(m.structure(), Structure::General);
    assert_eq!(m.delay(), 2);
    let mut rng = Rng(5);
    let u: Vec<f64> = (0..200).map(|_| rng.next()).collect();
    let e: Vec<f64> = (0..200).map(|_| 0.1 * rng.next()).collect();
    let y = m.simulate(&u, Some(&e), None).unwrap();
    let yu = filter(&b, &conv(&a, &f), &u);
    let ye = filter(&c, &conv(&a, &d), &e);
    for k in 0..u.len() {
        assert!((y[k] - yu[k] - ye[k]).abs() < 1e-12);
    }
    // frequency responses: G = B/(AF), H = C/(AD) evaluated directly
    let fr: Vec<f64> = (0..30).map(|k| k as f64 * 16.0).collect();
    let g = m.freq_response(&fr).unwrap();
    let h = m.noise_response(&fr).unwrap();
    let ss = m.to_state_space().unwrap();
    let gs = ss.freq_response(&fr).unwrap();
    for k in 0..fr.len() {
        let q = c64::from_polar(1.0, -2.0 * PI * fr[k] * 1e-3);
        let ev = |p: &[f64]| p.iter().rev().fold(c64::new(0.0, 0.0), |s, x| s * q + x);
        let gw = ev(&b) / (ev(&a) * ev(&f));
        let hw = ev(&c) / (ev(&a) * ev(&d));
        assert!((g[k] - gw).norm() < 1e-12 * gw.norm().max(1.0));
        assert!((h[k] - hw).norm() < 1e-12 * hw.norm().max(1.0));
        assert!((gs[k][(0, 0)] - gw).norm() < 1e-10 * gw.norm().max(1.0));
        assert!((gs[k][(0, 1)] - hw).norm() < 1e-10 * hw.norm().max(1.0));
    }
    // poles = roots of A F; zeros = roots of B; noise zeros = roots of C
    let p = m.poles().unwrap();
    assert_eq!(p.len(), 3);
    assert!(p
        .iter()
        .any(|z| (z.re - 0.5).abs() < 1e-12 && z.im.abs() < 1e-12));
    let z = m.zeros().unwrap();
    assert_eq!(z.len(), 1);
    assert!((z[0].re + 0.4).abs() < 1e-14);
    assert!((m.noise_zeros().unwrap()[0].re + 0.3).abs() < 1e-14);
    assert_eq!(m.noise_poles().unwrap().len(), 2);
}

#[test]
fn poly_model_validation() {
    assert!(PolyModel::arx(vec![1.0, -0.5], vec![0.0, 1.0], 0.1).is_ok());
    // non-monic A
    assert!(matches!(
        PolyModel::arx(vec![2.0, -0.5], vec![0.0, 1.0], 0.1),
        Err(Error::InvalidArgument { name: "a", .. })
    ));
    // structure fixes F = 1 for ARMAX
    assert!(matches!(
        PolyModel::new(
            Structure::Armax,
            vec![1.0],
            vec![1.0],
            vec![1.0],
            vec![1.0],
            vec![1.0, 0.2],
            0.1
        ),
        Err(Error::InvalidArgument { name: "f", .. })
    ));
    assert!(matches!(
        PolyModel::fir(vec![f64::NAN], 0.1),
        Err(Error::NonFinite { .. })
    ));
    assert!(PolyModel::fir(vec![], 0.1).is_err());
    assert!(PolyModel::fir(vec![1.0], 0.0).is_err());
    let m = PolyModel::bj(
        vec![0.0, 1.0],
        vec![1.0],
        vec![1.0, -0.5],
        vec![1.0, -0.2],
        0.1,
    )
    .unwrap();
    assert!(m.simulate(&[1.0, 2.0], Some(&[1.0]), None).is_err());
    assert_eq!(Structure::Bj.name(), "bj");
}

#[test]
fn typed_errors() {
    let g = StateSpace::discrete(mat![[1.0]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 1e-3).unwrap();
    let g2 =
        StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 2e-3).unwrap();
    let gc = StateSpace::continuous(mat![[-1.0]], mat![[1.0]], mat![[1.0]], mat![[0.0]]).unwrap();
    // mismatched sample times
    for r in [
        g.series(&g2),
        g.parallel(&g2),
        g.feedback(&g2),
        g.series(&gc),
    ] {
        assert!(matches!(r, Err(Error::SampleTimeMismatch { .. })), "{r:?}");
    }
    // NaN matrices and wrong dimensions
    assert!(matches!(
        StateSpace::discrete(mat![[f64::NAN]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 1.0),
        Err(Error::NonFinite { .. })
    ));
    assert!(matches!(
        StateSpace::discrete(
            mat![[1.0]],
            mat![[1.0], [2.0]],
            mat![[1.0]],
            mat![[0.0]],
            1.0
        ),
        Err(Error::DimensionMismatch { .. })
    ));
    let two_out = StateSpace::discrete(
        mat![[0.5]],
        mat![[1.0]],
        mat![[1.0], [2.0]],
        mat![[0.0], [0.0]],
        1e-3,
    )
    .unwrap();
    assert!(matches!(
        g.series(&g.parallel(&g).unwrap()).map(|_| ()),
        Ok(())
    ));
    assert!(matches!(
        two_out.parallel(&g),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        two_out.zeros(),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        two_out.freq_response_siso(&[1.0]),
        Err(Error::DimensionMismatch { .. })
    ));
    let u = Mat::<f64>::zeros(5, 2);
    assert!(matches!(
        g.simulate(u.as_ref(), None),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        gc.simulate(Mat::<f64>::zeros(5, 1).as_ref(), None),
        Err(Error::TimeDomain(_))
    ));
    // pole at the evaluation frequency: integrator at z = 1, f = 0
    assert!(matches!(
        g.freq_response(&[0.0]),
        Err(Error::Numerical { .. })
    ));
    let tf = TransferFunction::new(vec![1.0], vec![1.0, -1.0], 1e-3).unwrap();
    assert!(matches!(
        tf.freq_response(&[0.0]),
        Err(Error::Numerical { .. })
    ));
    assert!(matches!(
        g.freq_response(&[f64::NAN]),
        Err(Error::NonFinite { .. })
    ));
    // d2c: pole on the negative real axis (ZOH), pole at z = -1 (Tustin)
    let neg =
        StateSpace::discrete(mat![[-0.5]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 1e-3).unwrap();
    assert!(matches!(neg.d2c_zoh(), Err(Error::InvalidArgument { .. })));
    assert!(neg.d2c_tustin(None).is_ok());
    let m1 =
        StateSpace::discrete(mat![[-1.0]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 1e-3).unwrap();
    assert!(matches!(m1.d2c_tustin(None), Err(Error::Numerical { .. })));
    // time-domain mismatches and bad prewarp frequency
    assert!(matches!(g.c2d_zoh(1e-3), Err(Error::TimeDomain(_))));
    assert!(matches!(
        g.c2d_tustin(1e-3, None),
        Err(Error::TimeDomain(_))
    ));
    assert!(matches!(gc.d2c_zoh(), Err(Error::TimeDomain(_))));
    assert!(matches!(
        gc.c2d_tustin(1e-3, Some(600.0)),
        Err(Error::InvalidArgument { .. })
    ));
    assert!(matches!(
        gc.c2d_tustin(-1.0, None),
        Err(Error::InvalidArgument { .. })
    ));
    // transfer functions
    assert!(TransferFunction::new(vec![1.0], vec![0.0, 1.0], 1e-3).is_err());
    assert!(TransferFunction::new(vec![], vec![1.0], 1e-3).is_err());
    assert!(TransferFunction::from_state_space(&gc).is_err());
    let tf2 = TransferFunction::new(vec![1.0], vec![1.0, -0.5], 2e-3).unwrap();
    assert!(matches!(
        tf.series(&tf2),
        Err(Error::SampleTimeMismatch { .. })
    ));
    assert!(matches!(
        tf.feedback(&tf2),
        Err(Error::SampleTimeMismatch { .. })
    ));
    // G = K = 1 (static) in positive feedback: 1/(1 - 1) is not well posed
    let one = TransferFunction::new(vec![1.0], vec![1.0], 1e-3).unwrap();
    assert!(matches!(
        one.feedback_with_sign(&one, FeedbackSign::Positive),
        Err(Error::Numerical { .. })
    ));
    // ill-posed algebraic loop: D_G D_K = -1 under negative feedback
    let dg = StateSpace::discrete(
        Mat::zeros(0, 0),
        Mat::zeros(0, 1),
        Mat::zeros(1, 0),
        mat![[1.0]],
        1e-3,
    )
    .unwrap();
    let dk = StateSpace::discrete(
        Mat::zeros(0, 0),
        Mat::zeros(0, 1),
        Mat::zeros(1, 0),
        mat![[-1.0]],
        1e-3,
    )
    .unwrap();
    assert!(matches!(dg.feedback(&dk), Err(Error::Numerical { .. })));
}

#[test]
fn frd_construction_algebra_and_variance() {
    let f = vec![1.0, 2.0, 3.0];
    let x = Frd::new(
        f.clone(),
        vec![c64::new(2.0, 0.0), c64::new(0.0, 1.0), c64::new(1.0, 1.0)],
        Some(vec![0.1, 0.2, 0.3]),
        Some(1e-3),
    )
    .unwrap();
    let y = Frd::constant(&f, 2.0, Some(1e-3)).unwrap();
    let s = x.series(&y).unwrap();
    assert_eq!(s.values()[0], c64::new(4.0, 0.0));
    assert!((s.variance().unwrap()[0] - 0.4).abs() < 1e-15); // |2|² · 0.1
    let inv = x.inverse().unwrap();
    assert!((inv.values()[1] - c64::new(0.0, -1.0)).norm() < 1e-15);
    assert!((inv.variance().unwrap()[0] - 0.1 / 16.0).abs() < 1e-15);
    let q = x.divide(&x).unwrap();
    assert!(q.values().iter().all(|z| (z - 1.0).norm() < 1e-15));
    let p = x.parallel(&y).unwrap();
    assert_eq!(p.values()[0], c64::new(4.0, 0.0));
    assert_eq!(p.variance().unwrap(), &[0.1, 0.2, 0.3]);
    assert!((x.magnitude_db()[0] - 20.0 * 2f64.log10()).abs() < 1e-14);
    assert!((x.phase_deg()[1] - 90.0).abs() < 1e-12);
    assert!((x.std().unwrap()[0] - 0.1f64.sqrt()).abs() < 1e-15);
    let b = x.band(1.5, 3.0).unwrap();
    assert_eq!(b.f_hz(), &[2.0, 3.0]);
    assert_eq!(b.variance().unwrap(), &[0.2, 0.3]);
    // errors
    assert!(Frd::new(vec![1.0, 1.0], vec![c64::new(1.0, 0.0); 2], None, None).is_err());
    assert!(Frd::new(vec![f64::NAN], vec![c64::new(1.0, 0.0)], None, None).is_err());
    assert!(Frd::new(vec![1.0], vec![c64::new(1.0, 0.0)], Some(vec![-1.0]), None).is_err());
    assert!(Frd::new(vec![1.0], vec![], None, None).is_err());
    let z = Frd::constant(&f, 0.0, Some(1e-3)).unwrap();
    assert!(matches!(x.divide(&z), Err(Error::Numerical { .. })));
    let other_ts = Frd::constant(&f, 1.0, Some(2e-3)).unwrap();
    assert!(matches!(
        x.series(&other_ts),
        Err(Error::SampleTimeMismatch { .. })
    ));
    let other_grid = Frd::constant(&[1.0, 2.0, 4.0], 1.0, Some(1e-3)).unwrap();
    assert!(x.parallel(&other_grid).is_err());
    // positive unity feedback of 1: 1/(1 - 1) fails
    let one = Frd::constant(&f, 1.0, Some(1e-3)).unwrap();
    assert!(one
        .feedback_with_sign(&one, FeedbackSign::Positive)
        .is_err());
}

fn model_strategy() -> impl Strategy<Value = (u64, usize, usize)> {
    (any::<u64>(), 1usize..5, 1usize..5)
}

fn config() -> Config {
    Config {
        cases: 24,
        rng_seed: RngSeed::Fixed(0x000A_3B1D),
        failure_persistence: None,
        ..Config::default()
    }
}

fn close(a: c64, b: c64) -> bool {
    (a - b).norm() <= 1e-9 * (1.0 + b.norm())
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn interconnections_match_frequency_response_algebra((seed, n1, n2) in model_strategy()) {
        let mut rng = Rng(seed);
        let ts = 1e-3;
        let g = random_discrete(&mut rng, n1, 1, 1, 0.9, ts);
        let k = random_discrete(&mut rng, n2, 1, 1, 0.9, ts);
        let f: Vec<f64> = (0..12).map(|i| 3.0 + i as f64 * 37.0).collect();
        let gf = g.freq_response_siso(&f).unwrap();
        let kf = k.freq_response_siso(&f).unwrap();
        let s = g.series(&k).unwrap().freq_response_siso(&f).unwrap();
        let p = g.parallel(&k).unwrap().freq_response_siso(&f).unwrap();
        for i in 0..f.len() {
            prop_assert!(close(s[i], gf[i] * kf[i]));
            prop_assert!(close(p[i], gf[i] + kf[i]));
        }
        if let Ok(cl) = g.feedback(&k) {
            if let Ok(t) = cl.freq_response_siso(&f) {
                for i in 0..f.len() {
                    let want = gf[i] / (1.0 + gf[i] * kf[i]);
                    prop_assert!((t[i] - want).norm() <= 1e-7 * (1.0 + want.norm()));
                }
            }
        }
        // transfer-function algebra agrees too
        let gt = TransferFunction::from_state_space(&g).unwrap();
        let kt = TransferFunction::from_state_space(&k).unwrap();
        let st = gt.series(&kt).unwrap().freq_response(&f).unwrap();
        let pt = gt.parallel(&kt).unwrap().freq_response(&f).unwrap();
        let ft = Frd::from_transfer_function(&gt.feedback(&kt).unwrap(), &f).unwrap();
        let fd = Frd::from_transfer_function(&gt, &f)
            .unwrap()
            .feedback(&Frd::from_transfer_function(&kt, &f).unwrap())
            .unwrap();
        for i in 0..f.len() {
            prop_assert!((st[i] - s[i]).norm() <= 1e-8 * (1.0 + s[i].norm()));
            prop_assert!((pt[i] - p[i]).norm() <= 1e-8 * (1.0 + p[i].norm()));
            let w = fd.values()[i];
            prop_assert!((ft.values()[i] - w).norm() <= 1e-7 * (1.0 + w.norm()));
        }
        // Frd algebra agrees with the model algebra
        let gd = Frd::from_model(&g, &f).unwrap();
        let kd = Frd::from_model(&k, &f).unwrap();
        let sd = gd.series(&kd).unwrap();
        for (x, y) in sd.values().iter().zip(&s) {
            prop_assert!(close(*x, *y));
        }
    }

    #[test]
    fn c2d_d2c_round_trips_recover_the_model((seed, n, _m) in model_strategy()) {
        let mut rng = Rng(seed);
        // continuous model with poles well below Nyquist (ts = 1e-3 → 500 Hz)
        let a0 = rng.mat(n, n, 100.0);
        let a = Mat::from_fn(n, n, |i, j| a0[(i, j)] - if i == j { 300.0 } else { 0.0 });
        let sys = StateSpace::continuous(a, rng.mat(n, 2, 1.0), rng.mat(2, n, 1.0), rng.mat(2, 2, 1.0)).unwrap();
        let ts = 1e-3;
        for back in [
            sys.c2d_zoh(ts).unwrap().d2c_zoh().unwrap(),
            sys.c2d_tustin(ts, None).unwrap().d2c_tustin(None).unwrap(),
            sys.c2d_tustin(ts, Some(100.0)).unwrap().d2c_tustin(Some(100.0)).unwrap(),
        ] {
            prop_assert!((back.a() - sys.a()).norm_max() <= 1e-9 * sys.a().norm_max());
            prop_assert!((back.b() - sys.b()).norm_max() <= 1e-9 * sys.b().norm_max());
            prop_assert!((back.d() - sys.d()).norm_max() <= 1e-9 * (1.0 + sys.d().norm_max()));
        }
    }
}

/// The least-squares initial state reproduces a known one exactly (noise-free) and is unbiased
/// under noise; the oracle is the state the data were simulated from.
#[test]
fn the_estimated_initial_state_is_the_one_the_data_came_from() {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    // a lightly damped mode and a real pole, with a direct term
    let a = faer::mat![[1.6, -0.81, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.5]];
    let b = faer::mat![[1.0], [0.0], [1.0]];
    let c = faer::mat![[0.3, 0.2, -1.0]];
    let d = faer::mat![[0.1]];
    let m = ambid_core::lti::StateSpace::discrete(a, b, c, d, 1e-3).unwrap();
    let u: Vec<f64> = (0..400).map(|_| rng.random_range(-1.0..1.0)).collect();
    let x0 = [0.7, -1.3, 2.0];
    let y = m.simulate_siso(&u, Some(&x0)).unwrap();
    let est = m.estimate_initial_state(&u, &y).unwrap();
    for (e, t) in est.iter().zip(x0) {
        assert!((e - t).abs() < 1e-9, "{est:?}");
    }
    assert!(m.estimate_initial_state(&u[..10], &y).is_err());
}
