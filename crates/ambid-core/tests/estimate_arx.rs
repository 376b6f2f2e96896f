//! `estimate::arx` against four oracles:
//! * noise-free data from known FIR / ARX / MISO ARX systems (a lightly damped one with poles at
//!   $0.995\,e^{\pm j0.1}$ among them), which must be recovered to $10^{-8}$;
//! * a Monte Carlo over 100 seeds of a true ARX system with white equation noise, where the true
//!   parameters must lie within $\pm 1.96\sigma$ of the estimates in 90–98 % of the runs;
//! * the normal equations written out naively in the test (covariance, ridge);
//! * the real DaISy dryer record (`shared/data/real/daisy-dryer`, read in place) with the
//!   reference coefficients and fits of its README.
//!
//! Run with `-- --nocapture` to see the measured numbers.

use crate::common;
use ambid_core::estimate::arx::{arx, arx_with, fir, ArxModel, ArxOptions, ArxOrders};
use ambid_core::lti::Structure;
use ambid_core::validate::fit::fit_percent;
use ambid_core::Error;
use faer::Mat;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

fn white(seed: u64, n: usize) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| StandardNormal.sample(&mut rng)).collect()
}

/// $A y = \sum_i B_i u_i + e$ from zero initial conditions.
fn simulate(a: &[f64], b: &[Vec<f64>], u: &[&[f64]], e: Option<&[f64]>) -> Vec<f64> {
    let n = u
        .first()
        .map_or_else(|| e.map_or(0, |e| e.len()), |u| u.len());
    let mut y = vec![0.0; n];
    for k in 0..n {
        let mut v = e.map_or(0.0, |e| e[k]);
        for (i, ai) in a.iter().enumerate().skip(1) {
            if k >= i {
                v -= ai * y[k - i];
            }
        }
        for (bi, ui) in b.iter().zip(u) {
            for (j, bij) in bi.iter().enumerate() {
                if k >= j {
                    v += bij * ui[k - j];
                }
            }
        }
        y[k] = v;
    }
    y
}

fn assert_close(got: &[f64], want: &[f64], tol: f64, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= tol * w.abs().max(1.0),
            "{what}[{i}]: got {g}, want {w} (tol {tol})"
        );
    }
}

fn lightly_damped_a() -> Vec<f64> {
    let (r, w) = (0.995f64, 0.1f64);
    vec![1.0, -2.0 * r * w.cos(), r * r]
}

#[test]
fn noise_free_arx_systems_are_recovered() {
    let u = white(1, 3000);
    // a well-damped ARX(2,2,1) and the lightly damped ARX(2,3,2)
    let systems = [
        (
            vec![1.0, -1.5, 0.7],
            vec![0.0, 1.0, 0.5],
            ArxOrders::siso(2, 2, 1),
        ),
        (
            lightly_damped_a(),
            vec![0.0, 0.0, 0.3, -0.1, 0.05],
            ArxOrders::siso(2, 3, 2),
        ),
    ];
    for (a, b, orders) in systems {
        let y = simulate(&a, std::slice::from_ref(&b), &[&u], None);
        let f = arx(&y, &[&u], &orders, 1e-4).unwrap();
        assert_close(&f.model.a, &a, 1e-8, "a");
        assert_close(&f.model.b[0], &b, 1e-8, "b");
        let nk = orders.nk[0];
        assert!(f.model.b[0][..nk].iter().all(|v| *v == 0.0));
        assert_eq!(f.n_samples, 3000 - orders.k0());
        assert!(f.loss < 1e-20 * y.iter().map(|v| v * v).sum::<f64>() / 3000.0);
        let std = f.std().unwrap();
        assert_eq!(std.len(), orders.n_params());
        assert!(std.iter().all(|s| *s < 1e-8));
        println!(
            "noise-free {:?}: max |a err| {:.1e}, max |b err| {:.1e}",
            orders,
            f.model
                .a
                .iter()
                .zip(&a)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max),
            f.model.b[0]
                .iter()
                .zip(&b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max)
        );
        // the model reproduces the data, and the PolyModel conversion agrees
        let ysim = f.model.simulate(&[&u], &[]).unwrap();
        assert!(fit_percent(&y, &ysim).unwrap() > 99.9999);
        let p = f.model.to_poly(0).unwrap();
        assert_eq!(p.structure(), Structure::Arx);
        let yp = p.simulate(&u, None, None).unwrap();
        let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (s, q) in ysim.iter().zip(&yp) {
            assert!((s - q).abs() < 1e-9 * scale);
        }
    }
}

#[test]
fn noise_free_fir_is_recovered() {
    let u = white(2, 500);
    let b: Vec<f64> = (0..10)
        .map(|j| 0.8f64.powi(j) * (0.7 * j as f64).cos())
        .collect();
    let y = simulate(&[1.0], std::slice::from_ref(&b), &[&u], None);
    let f = fir(&y, &[&u], &[10], &[0], 1e-3).unwrap();
    assert_close(&f.model.b[0], &b, 1e-8, "fir b");
    assert_eq!(f.model.a, vec![1.0]);
    assert_eq!(f.model.to_poly(0).unwrap().structure(), Structure::Fir);
    // with a delay: the same taps behind two leading zeros
    let mut bd = vec![0.0, 0.0];
    bd.extend_from_slice(&b);
    let y = simulate(&[1.0], std::slice::from_ref(&bd), &[&u], None);
    let f = fir(&y, &[&u], &[10], &[2], 1e-3).unwrap();
    assert_close(&f.model.b[0], &bd, 1e-8, "fir b with nk = 2");
    assert_eq!(f.n_samples, 500 - 11);
}

#[test]
fn noise_free_miso_with_two_delays_is_recovered() {
    let u0 = white(3, 2000);
    let u1 = white(4, 2000);
    let a = vec![1.0, -1.2, 0.6, -0.1];
    let b = vec![vec![0.0, 0.5, -0.3], vec![0.0, 0.0, 0.0, 1.0, 0.4, 0.2]];
    let y = simulate(&a, &b, &[&u0, &u1], None);
    let orders = ArxOrders {
        na: 3,
        nb: vec![2, 3],
        nk: vec![1, 3],
    };
    assert_eq!(orders.k0(), 5);
    let f = arx(&y, &[&u0, &u1], &orders, 1e-3).unwrap();
    assert_close(&f.model.a, &a, 1e-8, "a");
    assert_close(&f.model.b[0], &b[0], 1e-8, "b0");
    assert_close(&f.model.b[1], &b[1], 1e-8, "b1");
    // θ ordering: a, then b of input 0, then b of input 1
    assert_close(
        &f.params,
        &[-1.2, 0.6, -0.1, 0.5, -0.3, 1.0, 0.4, 0.2],
        1e-8,
        "theta",
    );
    let yhat = f.model.predict(&y, &[&u0, &u1]).unwrap();
    let k0 = f.model.k0();
    assert_eq!(k0, 5);
    assert!(fit_percent(&y[k0..], &yhat[k0..]).unwrap() > 99.9999);
    // to_poly of one input leaves the other out
    let p1 = f.model.to_poly(1).unwrap();
    assert_close(p1.b(), &b[1], 1e-8, "to_poly(1).b");
    assert_close(p1.a(), &a, 1e-8, "to_poly(1).a");
}

/// True ARX(2,2,1) with white equation noise: the ±1.96σ intervals must cover the true values
/// in 90–98 % of 100 runs, for each parameter and over all of them.
#[test]
fn parameter_std_is_honest_monte_carlo() {
    let a = [1.0, -1.5, 0.7];
    let b = vec![vec![0.0, 1.0, 0.5]];
    let truth = [-1.5, 0.7, 1.0, 0.5];
    let runs = 100;
    let n = 600;
    let mut covered = [0usize; 4];
    let mut estimates = vec![Vec::new(); 4];
    let mut reported = [0.0f64; 4];
    for seed in 0..runs {
        let u = white(1000 + seed, n);
        let e: Vec<f64> = white(5000 + seed, n).iter().map(|v| 0.3 * v).collect();
        let y = simulate(&a, &b, &[&u], Some(&e));
        let f = arx(&y, &[&u], &ArxOrders::siso(2, 2, 1), 1.0).unwrap();
        let std = f.std().unwrap();
        for p in 0..4 {
            if (f.params[p] - truth[p]).abs() <= 1.96 * std[p] {
                covered[p] += 1;
            }
            estimates[p].push(f.params[p]);
            reported[p] += std[p] / runs as f64;
        }
        assert!((f.noise_variance / 0.09 - 1.0).abs() < 0.25);
    }
    let total: usize = covered.iter().sum();
    let pooled = 100.0 * total as f64 / (4 * runs) as f64;
    println!("Monte Carlo coverage per parameter [a1 a2 b1 b2]: {covered:?} % of {runs}; pooled {pooled:.1} %");
    for p in 0..4 {
        let mean = estimates[p].iter().sum::<f64>() / runs as f64;
        let sd = (estimates[p].iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (runs - 1) as f64)
            .sqrt();
        println!(
            "  param {p}: empirical sd {sd:.4e}, mean reported sd {:.4e}, ratio {:.3}",
            reported[p],
            sd / reported[p]
        );
        assert!((0.75..1.33).contains(&(sd / reported[p])), "param {p}");
        assert!(
            (90..=98).contains(&covered[p]),
            "param {p}: coverage {} %",
            covered[p]
        );
    }
    assert!(
        (90.0..=98.0).contains(&pooled),
        "pooled coverage {pooled} %"
    );
}

/// Naive normal equations $(\Phi^\top\Phi + \lambda I)^{-1}$ for the checks below.
fn naive_solve(phi: &Mat<f64>, y: &[f64], ridge: f64) -> (Vec<f64>, Mat<f64>, Mat<f64>) {
    let d = phi.ncols();
    let g = phi.transpose() * phi;
    let m = Mat::from_fn(d, d, |i, j| g[(i, j)] + if i == j { ridge } else { 0.0 });
    let minv = ambid_core::linalg::solve(m.as_ref(), Mat::<f64>::identity(d, d).as_ref()).unwrap();
    let rhs = Mat::from_fn(d, 1, |i, _| {
        (0..y.len()).map(|k| phi[(k, i)] * y[k]).sum::<f64>()
    });
    let theta = &minv * &rhs;
    ((0..d).map(|i| theta[(i, 0)]).collect(), minv, g)
}

#[test]
fn covariance_and_ridge_equal_the_normal_equations() {
    let u = white(7, 400);
    let e: Vec<f64> = white(8, 400).iter().map(|v| 0.2 * v).collect();
    let y = simulate(&[1.0, -0.7], &[vec![0.0, 0.0, 1.0, -0.4]], &[&u], Some(&e));
    let orders = ArxOrders::siso(1, 2, 2);
    let k0 = orders.k0();
    let phi = Mat::from_fn(400 - k0, 3, |r, c| {
        let k = r + k0;
        match c {
            0 => -y[k - 1],
            1 => u[k - 2],
            _ => u[k - 3],
        }
    });
    let target = &y[k0..];
    for ridge in [0.0, 50.0] {
        let f = arx_with(&y, &[&u], &orders, 0.5, &ArxOptions { ridge, k0: None }).unwrap();
        let (theta, minv, g) = naive_solve(&phi, target, ridge);
        assert_close(&f.params, &theta, 1e-10, "theta");
        let res: Vec<f64> = (0..target.len())
            .map(|k| target[k] - (0..3).map(|j| phi[(k, j)] * theta[j]).sum::<f64>())
            .collect();
        let ssr: f64 = res.iter().map(|r| r * r).sum();
        assert!((f.loss - ssr / target.len() as f64).abs() < 1e-12 * f.loss);
        let lam = ssr / (target.len() - 3) as f64;
        assert!((f.noise_variance - lam).abs() < 1e-12 * lam);
        let want = if ridge == 0.0 {
            minv.clone()
        } else {
            &minv * &g * &minv
        };
        let p = f.covariance.as_ref().unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let w = lam * want[(i, j)];
                assert!(
                    (p[(i, j)] - w).abs() < 1e-9 * lam * want[(i, i)].abs().max(want[(j, j)].abs()),
                    "ridge {ridge}: P[{i},{j}] {} vs {w}",
                    p[(i, j)]
                );
            }
        }
        if ridge > 0.0 {
            // shrinkage: the ridge estimate is shorter than least squares
            let ls = arx(&y, &[&u], &orders, 0.5).unwrap();
            let norm = |t: &[f64]| t.iter().map(|v| v * v).sum::<f64>();
            assert!(norm(&f.params) < norm(&ls.params));
        }
    }
}

#[test]
fn a_later_window_start_is_honoured() {
    let u = white(9, 300);
    let y = simulate(&[1.0, -0.5], &[vec![0.0, 1.0]], &[&u], None);
    let f = arx_with(
        &y,
        &[&u],
        &ArxOrders::siso(1, 1, 1),
        1.0,
        &ArxOptions {
            ridge: 0.0,
            k0: Some(20),
        },
    )
    .unwrap();
    assert_eq!(f.n_samples, 280);
    assert_close(&f.params, &[-0.5, 1.0], 1e-10, "theta");
}

/// The DaISy dryer, with the protocol of its README: first-half means removed, estimation on
/// samples 1..500, validation on 501..1000, criterion and fits over k >= k0 of each half; the
/// simulation starts from the measured first k0 outputs of the validation half.
#[test]
fn dryer_reference_numbers() {
    let rows = common::daisy("daisy-dryer", "dryer.dat", 1000);
    let mean_u = rows[..500].iter().map(|r| r.0).sum::<f64>() / 500.0;
    let mean_y = rows[..500].iter().map(|r| r.1).sum::<f64>() / 500.0;
    assert!((mean_u - 4.994).abs() < 1e-12 && (mean_y - 4.84337228).abs() < 1e-8);
    let u: Vec<f64> = rows.iter().map(|r| r.0 - 4.994).collect();
    let y: Vec<f64> = rows.iter().map(|r| r.1 - 4.84337228).collect();
    let (ue, ye, uv, yv) = (&u[..500], &y[..500], &u[500..], &y[500..]);

    let f = arx(ye, &[ue], &ArxOrders::siso(2, 2, 3), 0.08).unwrap();
    let want = [-1.2765387524, 0.3967106056, 0.0651903038, 0.0451791996];
    for (g, w) in f.params.iter().zip(&want) {
        assert!((g / w - 1.0).abs() < 1e-8, "theta {g} vs {w}");
    }
    assert_eq!(f.model.b[0][..3], [0.0, 0.0, 0.0]);
    let reference = [((2, 2, 3), 95.04, 85.57), ((4, 4, 3), 95.22, 85.78)];
    for ((na, nb, nk), want_pred, want_sim) in reference {
        let f = arx(ye, &[ue], &ArxOrders::siso(na, nb, nk), 0.08).unwrap();
        let k0 = f.model.k0();
        let pred = f.model.predict(yv, &[uv]).unwrap();
        let fit_pred = fit_percent(&yv[k0..], &pred[k0..]).unwrap();
        let sim = f.model.simulate(&[uv], &yv[..k0]).unwrap();
        let fit_sim = fit_percent(&yv[k0..], &sim[k0..]).unwrap();
        println!(
            "dryer ARX({na},{nb},{nk}): theta {:?}, std {:?}; 1-step fit {fit_pred:.4} %, simulation fit {fit_sim:.4} %",
            f.params,
            f.std().unwrap()
        );
        assert!(
            (fit_pred - want_pred).abs() < 0.005,
            "1-step fit {fit_pred}"
        );
        assert!(
            (fit_sim - want_sim).abs() < 0.005,
            "simulation fit {fit_sim}"
        );
    }
}

#[test]
fn predict_and_simulate_follow_their_definitions() {
    let m = ArxModel::new(vec![1.0, -0.5, 0.1], vec![vec![0.0, 2.0], vec![1.0]], 1.0).unwrap();
    assert_eq!((m.na(), m.n_inputs(), m.k0()), (2, 2, 2));
    let y = [1.0, 2.0, 3.0, 4.0];
    let u0 = [1.0, -1.0, 0.5, 0.0];
    let u1 = [0.0, 1.0, 0.0, 2.0];
    let p = m.predict(&y, &[&u0, &u1]).unwrap();
    // k = 3: 0.5 y2 - 0.1 y1 + 2 u0(2) + u1(3)
    assert!((p[3] - (0.5 * 3.0 - 0.1 * 2.0 + 2.0 * 0.5 + 2.0)).abs() < 1e-15);
    // k = 0: everything before the start is zero
    assert_eq!(p[0], 0.0 + u1[0]);
    let s = m.simulate(&[&u0, &u1], &[10.0, 20.0]).unwrap();
    assert_eq!(s[..2], [10.0, 20.0]);
    assert!((s[2] - (0.5 * 20.0 - 0.1 * 10.0 + 2.0 * u0[1] + u1[2])).abs() < 1e-15);
    assert!((s[3] - (0.5 * s[2] - 0.1 * 20.0 + 2.0 * 0.5 + 2.0)).abs() < 1e-15);
}

#[test]
fn fit_percent_is_the_nrmse_fit() {
    let y = [1.0, 3.0, 2.0, 6.0];
    let yh = [1.5, 2.5, 2.0, 5.0];
    let mean = 3.0;
    let num = (0.25f64 + 0.25 + 0.0 + 1.0).sqrt();
    let den = ((1.0f64 - mean).powi(2) + 0.0 + 1.0 + 9.0).sqrt();
    assert!((fit_percent(&y, &yh).unwrap() - 100.0 * (1.0 - num / den)).abs() < 1e-12);
    assert!(fit_percent(&y, &[0.0; 4]).unwrap() < 0.0);
}

#[test]
fn every_error_path_is_a_clear_error() {
    let u = white(11, 100);
    let y = simulate(&[1.0, -0.5], &[vec![0.0, 1.0]], &[&u], None);
    let o = ArxOrders::siso(1, 1, 1);
    let msg = |e: Error| e.to_string();

    // too few samples: say how many are needed
    let e = arx(&y[..10], &[&u[..10]], &ArxOrders::siso(5, 5, 3), 1.0).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { name: "y", .. }), "{e}");
    assert!(msg(e.clone()).contains("at least 18 samples"), "{e}");
    // rank deficiency: a constant input cannot identify two lags; the lag is named
    let c = vec![1.0; 100];
    let e = arx(&y, &[&c], &ArxOrders::fir(vec![2], vec![1]), 1.0).unwrap_err();
    let s = msg(e.clone());
    assert!(
        matches!(e, Error::InvalidArgument { name: "orders", .. }),
        "{s}"
    );
    assert!(
        s.contains("rank deficient") && s.contains("input 0 lag 1") && s.contains("input 0 lag 2"),
        "{s}"
    );
    // ... and in MISO the input is named
    let e = arx(
        &y,
        &[&u, &c],
        &ArxOrders {
            na: 1,
            nb: vec![1, 2],
            nk: vec![1, 0],
        },
        1.0,
    )
    .unwrap_err();
    assert!(msg(e.clone()).contains("u1(k)") && msg(e).contains("u1(k-1)"));
    // an identically zero input
    let z = vec![0.0; 100];
    let e = arx(&y, &[&z], &o, 1.0).unwrap_err();
    assert!(msg(e).contains("identically zero"));
    // non-finite samples, with the index
    let mut yb = y.clone();
    yb[17] = f64::NAN;
    assert_eq!(
        arx(&yb, &[&u], &o, 1.0).unwrap_err(),
        Error::NonFinite {
            what: "y",
            index: 17
        }
    );
    let mut ub = u.clone();
    ub[42] = f64::INFINITY;
    assert_eq!(
        arx(
            &y,
            &[&u, &ub],
            &ArxOrders {
                na: 1,
                nb: vec![1, 1],
                nk: vec![1, 1]
            },
            1.0
        )
        .unwrap_err(),
        Error::NonFinite {
            what: "u[1]",
            index: 42
        }
    );
    // length mismatches
    assert!(matches!(
        arx(&y, &[&u[..99]], &o, 1.0),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        arx(&y, &[&u, &u], &o, 1.0),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        arx(
            &y,
            &[&u],
            &ArxOrders {
                na: 1,
                nb: vec![1],
                nk: vec![]
            },
            1.0
        ),
        Err(Error::DimensionMismatch { .. })
    ));
    // sample time
    for ts in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            arx(&y, &[&u], &o, ts),
            Err(Error::InvalidArgument { name: "ts", .. })
        ));
    }
    // orders
    assert!(matches!(
        arx(&y, &[&u], &ArxOrders::siso(1, 0, 1), 1.0),
        Err(Error::InvalidArgument { name: "nb", .. })
    ));
    assert!(matches!(
        arx(&y, &[], &ArxOrders::fir(vec![], vec![]), 1.0),
        Err(Error::InvalidArgument { name: "na", .. })
    ));
    // options
    for ridge in [-1.0, f64::NAN] {
        let e = arx_with(&y, &[&u], &o, 1.0, &ArxOptions { ridge, k0: None }).unwrap_err();
        assert!(matches!(e, Error::InvalidArgument { name: "ridge", .. }));
    }
    let e = arx_with(
        &y,
        &[&u],
        &ArxOrders::siso(3, 1, 1),
        1.0,
        &ArxOptions {
            ridge: 0.0,
            k0: Some(2),
        },
    )
    .unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { name: "k0", .. }) && msg(e).contains("k0 >= 3"));
    // models
    assert!(ArxModel::new(vec![], vec![vec![1.0]], 1.0).is_err());
    assert!(ArxModel::new(vec![1.0], vec![vec![]], 1.0).is_err());
    assert!(ArxModel::new(vec![1.0, f64::NAN], vec![vec![1.0]], 1.0).is_err());
    assert!(ArxModel::new(vec![1.0], vec![vec![1.0]], 0.0).is_err());
    let m = ArxModel::new(vec![1.0, -0.5], vec![vec![0.0, 1.0]], 1.0).unwrap();
    assert!(matches!(
        m.to_poly(1),
        Err(Error::InvalidArgument { name: "input", .. })
    ));
    assert!(matches!(
        m.predict(&y, &[&u[..50]]),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        m.predict(&y, &[]),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        m.simulate(&[&u[..3]], &[1.0; 4]),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        m.simulate(&[], &[]),
        Err(Error::InvalidArgument { name: "u", .. })
    ));
    assert_eq!(
        m.simulate(&[&u], &[f64::NAN]).unwrap_err(),
        Error::NonFinite {
            what: "y_init",
            index: 0
        }
    );
    let broken = ArxModel {
        a: vec![2.0],
        b: vec![vec![1.0]],
        ts: 1.0,
    };
    assert!(broken.predict(&[1.0], &[&[1.0]]).is_err());
    // fit
    assert!(matches!(
        fit_percent(&[1.0, 2.0], &[1.0]),
        Err(Error::DimensionMismatch { .. })
    ));
    assert!(matches!(
        fit_percent(&[], &[]),
        Err(Error::InvalidArgument { .. })
    ));
    assert!(matches!(
        fit_percent(&[2.0, 2.0], &[1.0, 2.0]),
        Err(Error::InvalidArgument { .. })
    ));
    assert_eq!(
        fit_percent(&[1.0, 2.0], &[1.0, f64::NAN]).unwrap_err(),
        Error::NonFinite {
            what: "yhat",
            index: 1
        }
    );
}

/// The DaISy robot arm with its README's protocol (first-half means removed, estimate on 1..512,
/// validate on 513..1024, fits over k >= k0, simulation started from the measured first k0
/// outputs): ARX(4,4,1) equals the reference coefficients, and the best ARX model of order <= 8
/// reaches the README's best reference simulation fit (ARX(8,8,1), 97.13 %).
#[test]
fn robot_arm_reference_numbers() {
    let rows = common::daisy("daisy-robot-arm", "robot_arm.dat", 1024);
    let mu = rows[..512].iter().map(|r| r.0).sum::<f64>() / 512.0;
    let my = rows[..512].iter().map(|r| r.1).sum::<f64>() / 512.0;
    let u: Vec<f64> = rows.iter().map(|r| r.0 - mu).collect();
    let y: Vec<f64> = rows.iter().map(|r| r.1 - my).collect();
    let (ue, ye, uv, yv) = (&u[..512], &y[..512], &u[512..], &y[512..]);
    let f = arx(ye, &[ue], &ArxOrders::siso(4, 4, 1), 0.01).unwrap();
    let want = [
        -3.1548850975,
        4.4340455548,
        -3.124986255,
        0.9803744645,
        0.0175146255,
        -0.0263487958,
        0.0532257723,
        -0.0293811148,
    ];
    for (g, w) in f.params.iter().zip(&want) {
        assert!((g / w - 1.0).abs() < 1e-8, "theta {g} vs {w}");
    }
    let mut best = (0.0f64, 0usize);
    for n in 1..=8 {
        let f = arx(ye, &[ue], &ArxOrders::siso(n, n, 1), 0.01).unwrap();
        let k0 = f.model.k0();
        let sim = f.model.simulate(&[uv], &yv[..k0]).unwrap();
        let fit = fit_percent(&yv[k0..], &sim[k0..]).unwrap();
        if fit > best.0 {
            best = (fit, n);
        }
    }
    println!(
        "robot arm: best ARX(n,n,1), n <= 8: n = {}, simulation fit {:.2} %",
        best.1, best.0
    );
    assert!(best.0 >= 97.13 - 0.005, "{best:?}");
}
