//! The data contract: channel roles, several experiments, and the estimators' front doors on
//! `IoData` (ARX/FIR stacking experiments against a naive least-squares oracle written here,
//! MIMO ARX and subspace against known systems, the SISO-only doors' typed errors, the
//! closed-loop FRF doors selecting channels by role).

use ambid_core::data::{IoData, Role};
use ambid_core::estimate::arx::{arx, arx_iodata, fir_iodata, ArxOptions, ArxOrders};
use ambid_core::estimate::arx_mimo::{arx_mimo_iodata, OutputCoupling};
use ambid_core::estimate::pem::{pem, pem_iodata, Orders, PemOptions};
use ambid_core::estimate::subspace::{n4sid_iodata, SubspaceOptions};
use ambid_core::frf::closed_loop::{
    from_periodic, from_periodic_iodata, from_welch, from_welch_iodata, Channels,
};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
use ambid_core::frf::welch::{welch_spectra, WelchOptions};
use ambid_core::lti::Structure;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn noise(seed: u64, n: usize) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| rng.random::<f64>() * 2.0 - 1.0).collect()
}

/// y_k = 1.2 y_{k-1} − 0.5 y_{k-2} + u_{k-1} + 0.3 u_{k-2} + 0.05 e_k
fn arx_system(u: &[f64], e: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; u.len()];
    for k in 2..u.len() {
        y[k] = 1.2 * y[k - 1] - 0.5 * y[k - 2] + u[k - 1] + 0.3 * u[k - 2] + 0.05 * e[k];
    }
    y
}

fn rec(ch: Vec<(&str, Vec<f64>)>) -> IoData {
    IoData::new(
        ch.into_iter().map(|(n, v)| (n.to_string(), v)).collect(),
        1e-3,
        None,
    )
    .unwrap()
}

/// Naive least squares by the normal equations and Gauss–Jordan elimination (independent of
/// the library's QR): rows are [regressors..., target].
fn naive_ls(rows: &[Vec<f64>]) -> Vec<f64> {
    let d = rows[0].len() - 1;
    let mut g = vec![vec![0.0; d + 1]; d];
    for r in rows {
        for i in 0..d {
            for j in 0..d {
                g[i][j] += r[i] * r[j];
            }
            g[i][d] += r[i] * r[d];
        }
    }
    for c in 0..d {
        let p = (c..d)
            .max_by(|&a, &b| g[a][c].abs().total_cmp(&g[b][c].abs()))
            .unwrap();
        g.swap(c, p);
        for r in 0..d {
            if r != c {
                let f = g[r][c] / g[c][c];
                let pivot = g[c].clone();
                for (x, pv) in g[r].iter_mut().zip(&pivot).skip(c) {
                    *x -= f * pv;
                }
            }
        }
    }
    (0..d).map(|i| g[i][d] / g[i][i]).collect()
}

/// ARX(2, 2, 1) regression rows [−y_{k−1}, −y_{k−2}, u_{k−1}, u_{k−2}, y_k] for k ≥ 2.
fn rows(y: &[f64], u: &[f64]) -> Vec<Vec<f64>> {
    (2..y.len())
        .map(|k| vec![-y[k - 1], -y[k - 2], u[k - 1], u[k - 2], y[k]])
        .collect()
}

#[test]
fn two_experiments_stack_the_regressions_without_the_boundary_rows() {
    let n = 600;
    let u = noise(1, n);
    let y = arx_system(&u, &noise(2, n));
    let h = 277;
    let one = rec(vec![("u", u[..h].to_vec()), ("y", y[..h].to_vec())]);
    let two = one
        .clone()
        .with_experiment(vec![
            ("y".into(), y[h..].to_vec()),
            ("u".into(), u[h..].to_vec()),
        ])
        .unwrap();
    assert_eq!(two.n_experiments(), 2);
    let orders = ArxOrders::siso(2, 2, 1);
    let fit = arx_iodata(&two, &orders, &ArxOptions::default()).unwrap();
    // the oracle: both halves' rows, none reaching across the boundary
    let mut all = rows(&y[..h], &u[..h]);
    all.extend(rows(&y[h..], &u[h..]));
    let want = naive_ls(&all);
    assert_eq!(fit.n_samples, all.len());
    for (g, w) in fit.params.iter().zip(&want) {
        assert!((g - w).abs() <= 1e-10 * w.abs().max(1.0), "{g} vs {w}");
    }
    // ... which differs from the regression over the joined record (two boundary rows more)
    let joined = arx(&y, &[&u], &orders, 1e-3).unwrap();
    let jw = naive_ls(&rows(&y, &u));
    assert!((joined.params[0] - jw[0]).abs() < 1e-10);
    assert!(joined
        .params
        .iter()
        .zip(&fit.params)
        .any(|(a, b)| (a - b).abs() > 1e-9));
    // the truth is near: 0.05 noise over ~600 samples
    for (g, t) in fit.params.iter().zip([-1.2, 0.5, 1.0, 0.3]) {
        assert!((g - t).abs() < 0.02, "{g} vs {t}");
    }
    // from_experiments builds the same record
    let again = IoData::from_experiments(vec![
        one.clone(),
        rec(vec![("u", u[h..].to_vec()), ("y", y[h..].to_vec())]),
    ])
    .unwrap();
    assert_eq!(again, two);
    // FIR through the same door: y = B u only, rows [u_{k−1}, u_{k−2}, y_k]
    let fir = fir_iodata(&two, &[2], &[1]).unwrap();
    let fr = |y: &[f64], u: &[f64]| -> Vec<Vec<f64>> {
        (2..y.len())
            .map(|k| vec![u[k - 1], u[k - 2], y[k]])
            .collect()
    };
    let mut fa = fr(&y[..h], &u[..h]);
    fa.extend(fr(&y[h..], &u[h..]));
    for (g, w) in fir.params.iter().zip(naive_ls(&fa)) {
        assert!((g - w).abs() <= 1e-10 * w.abs().max(1.0));
    }
}

#[test]
fn roles_select_channels_whatever_their_order() {
    let n = 400;
    let u = noise(3, n);
    let y = arx_system(&u, &noise(4, n));
    let a = rec(vec![("u", u.clone()), ("y", y.clone())]);
    let b = rec(vec![
        ("y", y.clone()),
        ("note", vec![0.0; n]),
        ("u", u.clone()),
    ]);
    let o = ArxOrders::siso(2, 2, 1);
    let fa = arx_iodata(&a, &o, &ArxOptions::default()).unwrap();
    let fb = arx_iodata(&b, &o, &ArxOptions::default()).unwrap();
    assert_eq!(fa.params, fb.params);
    assert_eq!(b.role("note").unwrap(), Role::Other);
    // explicit roles for names outside the convention
    let c = rec(vec![("pos", y.clone()), ("drive", u.clone())])
        .with_role("pos", Role::Output)
        .unwrap()
        .with_role("drive", Role::Input)
        .unwrap();
    assert_eq!(
        arx_iodata(&c, &o, &ArxOptions::default()).unwrap().params,
        fa.params
    );
    // missing role, NaN: typed errors that say what to do
    let e = arx_iodata(&rec(vec![("y", y.clone())]), &o, &ArxOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no input channel (u)") && e.contains("`y` (output)"),
        "{e}"
    );
    let mut yn = y.clone();
    yn[17] = f64::NAN;
    let e = arx_iodata(
        &rec(vec![("u", u.clone()), ("y", yn)]),
        &o,
        &ArxOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("`y` of experiment 0") && e.contains("sample 18"),
        "{e}"
    );
}

#[test]
fn mismatched_experiments_are_typed_errors() {
    let a = rec(vec![("u", vec![1.0; 5]), ("y", vec![0.0; 5])]);
    let e = a
        .clone()
        .with_experiment(vec![("u".into(), vec![1.0; 3]), ("w".into(), vec![0.0; 3])])
        .unwrap_err()
        .to_string();
    assert!(e.contains("channel `w` the first has not"), "{e}");
    let e = a
        .clone()
        .with_experiment(vec![("u".into(), vec![1.0; 3]), ("y".into(), vec![0.0; 2])])
        .unwrap_err();
    assert!(matches!(e, ambid_core::Error::DimensionMismatch { .. }));
    let other_ts = IoData::new(
        vec![("u".into(), vec![1.0; 4]), ("y".into(), vec![0.0; 4])],
        2e-3,
        None,
    )
    .unwrap();
    let e = IoData::from_experiments(vec![a.clone(), other_ts])
        .unwrap_err()
        .to_string();
    assert!(e.contains("resample"), "{e}");
    let relabelled = a.clone().with_role("y", Role::Current).unwrap();
    let e = IoData::from_experiments(vec![a.clone(), relabelled])
        .unwrap_err()
        .to_string();
    assert!(e.contains("`y` is the current in experiment 1"), "{e}");
    assert!(IoData::from_experiments(vec![]).is_err());
    assert!(a.experiment(1).is_err());
    // serde keeps experiments and roles, and reads the old single-record form
    let two = a
        .clone()
        .with_role("u", Role::Input)
        .unwrap()
        .with_experiment(vec![("y".into(), vec![2.0; 3]), ("u".into(), vec![3.0; 3])])
        .unwrap();
    let json = serde_json::to_string(&two).unwrap();
    assert_eq!(serde_json::from_str::<IoData>(&json).unwrap(), two);
    let old = serde_json::to_string(&a).unwrap();
    assert!(
        !old.contains("experiments") && !old.contains("roles"),
        "{old}"
    );
    assert_eq!(serde_json::from_str::<IoData>(&old).unwrap(), a);
}

#[test]
fn siso_only_doors_refuse_mimo_and_several_experiments() {
    let n = 500;
    let u = noise(5, n);
    let y = arx_system(&u, &noise(6, n));
    let d = rec(vec![("u", u.clone()), ("y", y.clone())]);
    let o = Orders {
        na: 2,
        nb: 2,
        nk: 1,
        ..Orders::default()
    };
    let opts = PemOptions::default();
    // the door is the slice function on the channels it selects
    let (a, _) = pem_iodata(&d, Structure::Arx, &o, &opts).unwrap();
    let (b, _) = pem(&y, &u, Structure::Arx, &o, 1e-3, &opts).unwrap();
    assert_eq!(a.params, b.params);
    let mimo = rec(vec![
        ("u_xa", u.clone()),
        ("u_xb", u.clone()),
        ("y_xa", y.clone()),
        ("y_xb", y.clone()),
    ]);
    let e = pem_iodata(&mimo, Structure::Oe, &o, &opts)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("pem is SISO-only") && e.contains("2 output and 2 input channels"),
        "{e}"
    );
    assert!(e.contains("y_xa, y_xb, u_xa, u_xb"), "{e}");
    let two = d
        .clone()
        .with_experiment(vec![("u".into(), u.clone()), ("y".into(), y.clone())])
        .unwrap();
    let e = pem_iodata(&two, Structure::Arx, &o, &opts)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("pem takes one experiment") && e.contains("holds 2"),
        "{e}"
    );
    let e = arx_iodata(&mimo, &ArxOrders::siso(2, 2, 1), &ArxOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("2 output channels (y_xa, y_xb) and 2 input channels"),
        "{e}"
    );
    assert!(n4sid_iodata(&two, &SubspaceOptions::new(1e-3)).is_err());
}

#[test]
fn mimo_arx_and_subspace_through_the_door_recover_known_systems() {
    // y_t + A1 y_{t−1} = B1 u_{t−1}, 2 outputs, 2 inputs, noise-free
    let n = 300;
    let (u1, u2) = (noise(7, n), noise(8, n));
    let a1 = [[-0.5, 0.1], [0.2, -0.3]];
    let b1 = [[1.0, 0.5], [-0.4, 2.0]];
    let (mut y1, mut y2) = (vec![0.0; n], vec![0.0; n]);
    for t in 1..n {
        let (p1, p2) = (y1[t - 1], y2[t - 1]);
        y1[t] = -(a1[0][0] * p1 + a1[0][1] * p2) + b1[0][0] * u1[t - 1] + b1[0][1] * u2[t - 1];
        y2[t] = -(a1[1][0] * p1 + a1[1][1] * p2) + b1[1][0] * u1[t - 1] + b1[1][1] * u2[t - 1];
    }
    // stored out of axis order: the door sorts by axis (xa before xb)
    let d = rec(vec![
        ("y_xb", y2.clone()),
        ("u_xb", u2.clone()),
        ("y_xa", y1.clone()),
        ("u_xa", u1.clone()),
    ]);
    let m = arx_mimo_iodata(&d, 1, 1, 1, OutputCoupling::Full).unwrap();
    for i in 0..2 {
        for j in 0..2 {
            assert!((m.a[0][(i, j)] - a1[i][j]).abs() < 1e-10);
            assert!((m.b[1][(i, j)] - b1[i][j]).abs() < 1e-10);
        }
    }
    // SISO subspace: x_{k+1} = 0.8 x_k + u_k, y = x
    let mut y = vec![0.0; n];
    for k in 1..n {
        y[k] = 0.8 * y[k - 1] + u1[k - 1];
    }
    let s = rec(vec![("y", y), ("u", u1)]);
    let opts = SubspaceOptions {
        order: Some(1),
        block_rows: Some(4),
        ..SubspaceOptions::new(1e-3)
    };
    let g = n4sid_iodata(&s, &opts).unwrap().model;
    assert!((g.a()[(0, 0)] - 0.8).abs() < 1e-8);
}

#[test]
fn closed_loop_frf_doors_select_r_u_y_by_role() {
    // periodic r; u = r − C y with C = 0.25 static; y = 2 u (P = 2): u = r/(1.5), y = 2u
    let p = 16;
    let base = noise(9, p);
    let r: Vec<f64> = (0..8 * p).map(|k| base[k % p]).collect();
    let u: Vec<f64> = r.iter().map(|v| v / 1.5).collect();
    let y: Vec<f64> = u.iter().map(|v| 2.0 * v + 1e-3 * v.sin()).collect();
    let d = IoData::new(
        vec![
            ("y".into(), y.clone()),
            ("r".into(), r.clone()),
            ("u".into(), u.clone()),
        ],
        1e-3,
        Some(p),
    )
    .unwrap();
    let got = from_periodic_iodata(&d, (0.0, 500.0), 1e-6, None).unwrap();
    let s = PeriodicAnalyzer::new(p)
        .unwrap()
        .analyze(&[&r, &u, &y], 1000.0, &PeriodicOptions::new(p))
        .unwrap();
    let lines = s.excited_lines(0, 1e-6).unwrap();
    let want = from_periodic(&s, Channels { r: 0, u: 1, y: 2 }, &lines, None).unwrap();
    assert_eq!(got, want);
    assert!(got
        .t_ru
        .values()
        .iter()
        .all(|v| (v.re - 1.0 / 1.5).abs() < 1e-12));
    let opts = WelchOptions::new(1000.0, 32);
    let got = from_welch_iodata(&d, &opts, (0.0, 500.0), 1e-6, None).unwrap();
    let sp = welch_spectra(&[&r, &u, &y], &opts).unwrap();
    let want = from_welch(&sp, Channels { r: 0, u: 1, y: 2 }, (0.0, 500.0), 1e-6, None).unwrap();
    assert_eq!(got, want);
    // no period, no excitation: typed errors
    let e = from_periodic_iodata(
        &d.clone().with_period_samples(None).unwrap(),
        (0.0, 500.0),
        1e-6,
        None,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("no period"), "{e}");
    let no_r = IoData::new(vec![("y".into(), y), ("u".into(), u)], 1e-3, Some(p)).unwrap();
    let e = from_welch_iodata(&no_r, &opts, (0.0, 500.0), 1e-6, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no excitation channel (r)"), "{e}");
}
