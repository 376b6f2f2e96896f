//! Matrix-valued `Frd`: the 2×2 algebra against an independent complex computation written here
//! (explicit 2×2 products and adjugate inverses), the first-order variances against numerical
//! derivatives of that independent computation, typed errors, and the 1×1 case against the
//! scalar formulas the SISO `Frd` used before it held matrices.

use ambid_core::lti::{FeedbackSign, Frd};
use faer::{c64, Mat};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

type M2 = [[c64; 2]; 2];

fn c(re: f64, im: f64) -> c64 {
    c64::new(re, im)
}

// ---- the independent oracle: hand-expanded 2×2 complex algebra -------------------------------

fn mul(a: &M2, b: &M2) -> M2 {
    [
        [
            a[0][0] * b[0][0] + a[0][1] * b[1][0],
            a[0][0] * b[0][1] + a[0][1] * b[1][1],
        ],
        [
            a[1][0] * b[0][0] + a[1][1] * b[1][0],
            a[1][0] * b[0][1] + a[1][1] * b[1][1],
        ],
    ]
}

fn add(a: &M2, b: &M2) -> M2 {
    [
        [a[0][0] + b[0][0], a[0][1] + b[0][1]],
        [a[1][0] + b[1][0], a[1][1] + b[1][1]],
    ]
}

fn scale(a: &M2, s: f64) -> M2 {
    [[a[0][0] * s, a[0][1] * s], [a[1][0] * s, a[1][1] * s]]
}

fn eye() -> M2 {
    [[c(1.0, 0.0), c(0.0, 0.0)], [c(0.0, 0.0), c(1.0, 0.0)]]
}

/// Adjugate inverse: [[d, −b], [−c, a]] / (ad − bc).
fn inv(a: &M2) -> M2 {
    let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    [
        [a[1][1] / det, -a[0][1] / det],
        [-a[1][0] / det, a[0][0] / det],
    ]
}

fn rand_m2(rng: &mut ChaCha8Rng) -> M2 {
    let mut z = || {
        c(
            rng.random::<f64>() * 2.0 - 1.0,
            rng.random::<f64>() * 2.0 - 1.0,
        )
    };
    [[z(), z()], [z(), z()]]
}

fn to_mat(a: &M2) -> Mat<c64> {
    Mat::from_fn(2, 2, |i, j| a[i][j])
}

fn frd_of(f: &[f64], ms: &[M2], var: Option<&[[[f64; 2]; 2]]>) -> Frd {
    let mats: Vec<Mat<c64>> = ms.iter().map(to_mat).collect();
    let vars: Option<Vec<Mat<f64>>> = var.map(|v| {
        v.iter()
            .map(|m| Mat::from_fn(2, 2, |i, j| m[i][j]))
            .collect()
    });
    Frd::from_matrices(f, &mats, vars.as_deref(), Some(1e-4)).unwrap()
}

fn assert_close(got: &Frd, want: &[M2], tol: f64, what: &str) {
    assert_eq!((got.ny(), got.nu()), (2, 2), "{what}");
    for (k, w) in want.iter().enumerate() {
        let g = got.at(k).unwrap();
        let scale = w.iter().flatten().fold(0.0f64, |s, z| s.max(z.norm()));
        for i in 0..2 {
            for j in 0..2 {
                let err = (g[(i, j)] - w[i][j]).norm();
                assert!(
                    err <= tol * scale,
                    "{what}: line {k} entry ({i},{j}): {} vs {} (rel {:.2e})",
                    g[(i, j)],
                    w[i][j],
                    err / scale
                );
            }
        }
    }
}

struct Case {
    f: Vec<f64>,
    x: Vec<M2>,
    y: Vec<M2>,
    vx: Vec<[[f64; 2]; 2]>,
    vy: Vec<[[f64; 2]; 2]>,
}

fn case(seed: u64, lines: usize) -> Case {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let f: Vec<f64> = (1..=lines).map(|k| 7.5 * k as f64).collect();
    let x: Vec<M2> = (0..lines).map(|_| rand_m2(&mut rng)).collect();
    let y: Vec<M2> = (0..lines).map(|_| rand_m2(&mut rng)).collect();
    let mut v = || {
        let mut r = || 1e-3 * rng.random::<f64>();
        [[r(), r()], [r(), r()]]
    };
    let vx = (0..lines).map(|_| v()).collect();
    let vy = (0..lines).map(|_| v()).collect();
    Case { f, x, y, vx, vy }
}

#[test]
fn two_by_two_algebra_matches_the_hand_expanded_computation() {
    for seed in 0..20 {
        let cs = case(seed, 16);
        let (x, y) = (frd_of(&cs.f, &cs.x, None), frd_of(&cs.f, &cs.y, None));
        let each = |g: &dyn Fn(&M2, &M2) -> M2| -> Vec<M2> {
            cs.x.iter().zip(&cs.y).map(|(a, b)| g(a, b)).collect()
        };
        // series: `x` first, then `y` — the product Y X
        assert_close(
            &x.series(&y).unwrap(),
            &each(&|a, b| mul(b, a)),
            1e-12,
            "series",
        );
        assert_close(
            &x.product(&y).unwrap(),
            &each(&|a, b| mul(a, b)),
            1e-12,
            "product",
        );
        assert_close(
            &x.parallel(&y).unwrap(),
            &each(&|a, b| add(a, b)),
            1e-12,
            "parallel",
        );
        assert_close(
            &x.inverse().unwrap(),
            &each(&|a, _| inv(a)),
            1e-12,
            "inverse",
        );
        assert_close(
            &x.divide(&y).unwrap(),
            &each(&|a, b| mul(a, &inv(b))),
            1e-12,
            "divide",
        );
        // feedback: (I ∓ X Y)⁻¹ X
        assert_close(
            &x.feedback(&y).unwrap(),
            &each(&|a, b| mul(&inv(&add(&eye(), &mul(a, b))), a)),
            1e-12,
            "negative feedback",
        );
        assert_close(
            &x.feedback_with_sign(&y, FeedbackSign::Positive).unwrap(),
            &each(&|a, b| mul(&inv(&add(&eye(), &scale(&mul(a, b), -1.0))), a)),
            1e-12,
            "positive feedback",
        );
    }
}

#[test]
fn closed_loop_plant_from_t_ry_and_s_is_the_plant() {
    // u = −C y + r, y = P u: T_ry = (I + P C)⁻¹ P, S = T_ru = (I + C P)⁻¹; P = T_ry S⁻¹ and the
    // indirect P = T_ry (I − C T_ry)⁻¹ both give P back.
    for seed in 100..110 {
        let cs = case(seed, 12);
        let (p, k) = (&cs.x, &cs.y);
        let t: Vec<M2> = p
            .iter()
            .zip(k)
            .map(|(p, k)| mul(&inv(&add(&eye(), &mul(p, k))), p))
            .collect();
        let s: Vec<M2> = p
            .iter()
            .zip(k)
            .map(|(p, k)| inv(&add(&eye(), &mul(k, p))))
            .collect();
        let (pf, kf) = (frd_of(&cs.f, p, None), frd_of(&cs.f, k, None));
        let tf = frd_of(&cs.f, &t, None);
        let sf = frd_of(&cs.f, &s, None);
        // the Frd algebra forms T and S as the oracle does
        assert_close(&pf.feedback(&kf).unwrap(), &t, 1e-12, "T_ry");
        let i2 = Frd::identity(&cs.f, 2, Some(1e-4)).unwrap();
        assert_close(
            &i2.feedback(&pf.series(&kf).unwrap()).unwrap(),
            &s,
            1e-12,
            "S",
        );
        // and P comes back from T and S
        assert_close(&tf.divide(&sf).unwrap(), p, 1e-12, "P = T S⁻¹");
        let one_minus_ct = i2.parallel(&kf.product(&tf).unwrap().scaled(-1.0)).unwrap();
        let indirect = tf.divide(&one_minus_ct).unwrap();
        assert_close(&indirect, p, 1e-10, "P = T (I − C T)⁻¹");
    }
}

/// $\sum_{kl} |\partial Z_{ij} / \partial X_{kl}|^2 v_{kl}$ by central differences of the oracle
/// (the maps are holomorphic, so a real step gives the complex derivative).
fn fd_var(z: &dyn Fn(&M2) -> M2, x: &M2, v: &[[f64; 2]; 2]) -> [[f64; 2]; 2] {
    let mut out = [[0.0; 2]; 2];
    let h = 1e-6;
    for k in 0..2 {
        for l in 0..2 {
            let (mut xp, mut xm) = (*x, *x);
            xp[k][l] += c(h, 0.0);
            xm[k][l] -= c(h, 0.0);
            let (zp, zm) = (z(&xp), z(&xm));
            for i in 0..2 {
                for j in 0..2 {
                    let d = (zp[i][j] - zm[i][j]) / (2.0 * h);
                    out[i][j] += d.norm_sqr() * v[k][l];
                }
            }
        }
    }
    out
}

#[test]
fn first_order_variances_match_numerical_derivatives_of_the_oracle() {
    type Op = (&'static str, fn(&Frd, &Frd) -> Frd, fn(&M2, &M2) -> M2);
    let ops: [Op; 6] = [
        ("series", |x, y| x.series(y).unwrap(), |a, b| mul(b, a)),
        ("product", |x, y| x.product(y).unwrap(), |a, b| mul(a, b)),
        ("parallel", |x, y| x.parallel(y).unwrap(), |a, b| add(a, b)),
        ("inverse", |x, _| x.inverse().unwrap(), |a, _| inv(a)),
        (
            "divide",
            |x, y| x.divide(y).unwrap(),
            |a, b| mul(a, &inv(b)),
        ),
        (
            "feedback",
            |x, y| x.feedback(y).unwrap(),
            |a, b| mul(&inv(&add(&eye(), &mul(a, b))), a),
        ),
    ];
    for seed in 200..205 {
        let cs = case(seed, 6);
        let x = frd_of(&cs.f, &cs.x, Some(&cs.vx));
        let y = frd_of(&cs.f, &cs.y, Some(&cs.vy));
        for (name, op, oracle) in ops {
            let z = op(&x, &y);
            for k in 0..cs.f.len() {
                let (a, b) = (cs.x[k], cs.y[k]);
                let from_x = fd_var(&|p| oracle(p, &b), &a, &cs.vx[k]);
                let uses_y = name != "inverse";
                let from_y = fd_var(&|q| oracle(&a, q), &b, &cs.vy[k]);
                let got = z.variance_at(k).unwrap().unwrap();
                for i in 0..2 {
                    for j in 0..2 {
                        let want = from_x[i][j] + if uses_y { from_y[i][j] } else { 0.0 };
                        let rel = (got[(i, j)] - want).abs() / want;
                        assert!(
                            rel < 1e-6,
                            "{name} seed {seed} line {k} ({i},{j}): {} vs {want}",
                            got[(i, j)]
                        );
                    }
                }
            }
        }
    }
    // no variance in, none out; one side's variance alone is propagated
    let cs = case(7, 3);
    let x = frd_of(&cs.f, &cs.x, None);
    assert!(x.divide(&x).unwrap().variance().is_none());
    let y = frd_of(&cs.f, &cs.y, Some(&cs.vy));
    assert!(x.product(&y).unwrap().variance().is_some());
}

#[test]
fn matrix_access_entries_and_band() {
    let cs = case(11, 5);
    let x = frd_of(&cs.f, &cs.x, Some(&cs.vx));
    assert_eq!((x.len(), x.ny(), x.nu(), x.is_siso()), (5, 2, 2, false));
    // flat storage: line after line, column by column
    assert_eq!(x.values()[4 + 2], cs.x[1][0][1]);
    assert_eq!(x.variance().unwrap()[4 * 3 + 1], cs.vx[3][1][0]);
    let e = x.entry(1, 0).unwrap();
    assert!(e.is_siso());
    let want: Vec<c64> = cs.x.iter().map(|m| m[1][0]).collect();
    assert_eq!(e.values(), want.as_slice());
    let wv: Vec<f64> = cs.vx.iter().map(|m| m[1][0]).collect();
    assert_eq!(e.variance().unwrap(), wv.as_slice());
    assert!(x
        .entry(2, 0)
        .unwrap_err()
        .to_string()
        .contains("outside the 2×2"));
    let b = x.band(cs.f[1], cs.f[3]).unwrap();
    assert_eq!(b.f_hz(), &cs.f[1..4]);
    for k in 0..3 {
        assert_eq!(b.at(k).unwrap(), x.at(k + 1).unwrap());
        assert_eq!(b.variance_at(k).unwrap(), x.variance_at(k + 1).unwrap());
    }
    // a line past the end is a typed error, not a panic
    assert!(b
        .at(3)
        .unwrap_err()
        .to_string()
        .contains("line 3 is outside"));
    assert!(b.variance_at(3).is_err());
    // a 2×3 response: products and series check the inner dimension
    let g = Frd::from_matrices(
        &[1.0],
        &[Mat::from_fn(2, 3, |i, j| c(i as f64 + 1.0, j as f64))],
        None,
        None,
    )
    .unwrap();
    let h = Frd::from_matrices(
        &[1.0],
        &[Mat::from_fn(3, 2, |i, j| c(j as f64, i as f64))],
        None,
        None,
    )
    .unwrap();
    let gh = g.product(&h).unwrap();
    assert_eq!((gh.ny(), gh.nu()), (2, 2));
    // (GH)_01 = Σ_k G_0k H_k1 = 1·1 + (1+i)(1+i) + (1+2i)(1+2i) = 1 + 2i + (−3+4i) = −2 + 6i
    assert!((gh.at(0).unwrap()[(0, 1)] - c(-2.0, 6.0)).norm() < 1e-15);
    assert_eq!(
        (h.series(&g).unwrap().ny(), h.series(&g).unwrap().nu()),
        (2, 2)
    );
}

#[test]
fn dimension_mismatches_and_singular_lines_are_typed_errors() {
    let f = [1.0, 2.0, 3.0];
    let m = |r: usize, cc: usize| {
        Frd::from_matrices(
            &f,
            &vec![Mat::from_fn(r, cc, |i, j| c(1.0 + i as f64, j as f64)); 3],
            None,
            None,
        )
        .unwrap()
    };
    let (a23, a22, a33) = (m(2, 3), m(2, 2), m(3, 3));
    let msg = |r: ambid_core::Result<Frd>| r.unwrap_err().to_string();
    assert!(msg(a23.product(&a22)).contains("dimension mismatch"));
    assert!(msg(a22.parallel(&a23)).contains("dimension mismatch in Frd::parallel"));
    assert!(msg(a23.inverse()).contains("dimension mismatch in Frd::inverse"));
    assert!(msg(a22.divide(&a33)).contains("dimension mismatch in Frd::divide"));
    assert!(msg(a23.feedback(&a22)).contains("dimension mismatch in Frd::feedback"));
    assert!(msg(a22.series(&a33)).contains("dimension mismatch in Frd::series"));
    // a singular line: the error names its frequency
    let sing = [[c(1.0, 1.0), c(2.0, 2.0)], [c(0.5, 0.5), c(1.0, 1.0)]];
    let ok = [[c(1.0, 0.0), c(0.0, 0.0)], [c(0.0, 0.0), c(2.0, 0.0)]];
    let g = frd_of(&f, &[ok, sing, ok], None);
    let e = msg(g.inverse());
    assert!(e.contains("singular at 2 Hz"), "{e}");
    let e = msg(frd_of(&f, &[ok, ok, ok], None).divide(&g));
    assert!(e.contains("singular at 2 Hz"), "{e}");
    // (I + G K) singular: G = I, K = −I
    let minus = [[c(-1.0, 0.0), c(0.0, 0.0)], [c(0.0, 0.0), c(-1.0, 0.0)]];
    let e = msg(frd_of(&f, &[ok, ok, ok], None).feedback(&frd_of(&f, &[ok, ok, minus], None)));
    assert!(
        e.contains("singular at 3 Hz") || e.contains("at 3 Hz"),
        "{e}"
    );
    // constructors
    assert!(Frd::new_matrix(vec![1.0], 0, 2, vec![], None, None).is_err());
    let e = Frd::new_matrix(vec![1.0, 2.0], 2, 2, vec![c(0.0, 0.0); 7], None, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("8 (2 lines × 2×2)"), "{e}");
    assert!(Frd::from_matrices(&f, &[Mat::zeros(2, 2)], None, None).is_err());
    let mixed = [Mat::<c64>::zeros(2, 2), Mat::zeros(2, 2), Mat::zeros(2, 1)];
    assert!(Frd::from_matrices(&f, &mixed, None, None)
        .unwrap_err()
        .to_string()
        .contains("2×1 at line 2"));
}

// ---- SISO: the 1×1 case against the scalar formulas used before the matrix Frd ----------------

fn old_series(x: c64, y: c64, vx: f64, vy: f64) -> (c64, f64) {
    (x * y, y.norm_sqr() * vx + x.norm_sqr() * vy)
}
fn old_parallel(x: c64, y: c64, vx: f64, vy: f64) -> (c64, f64) {
    (x + y, 1.0 * vx + 1.0 * vy)
}
fn old_divide(x: c64, y: c64, vx: f64, vy: f64) -> (c64, f64) {
    let y2 = y.norm_sqr();
    (x / y, 1.0 / y2 * vx + x.norm_sqr() / (y2 * y2) * vy)
}
fn old_inverse(x: c64, vx: f64) -> (c64, f64) {
    let (z, v) = old_divide(c(1.0, 0.0), x, 0.0, vx);
    (z, 0.0 * 0.0 + v)
}
fn old_feedback(x: c64, y: c64, vx: f64, vy: f64, s: f64) -> (c64, f64) {
    let den = c(1.0, 0.0) - x * y * s;
    let d4 = den.norm_sqr() * den.norm_sqr();
    (
        x / den,
        1.0 / d4 * vx + x.norm_sqr() * x.norm_sqr() / d4 * vy,
    )
}

#[test]
fn siso_results_are_the_scalar_formulas() {
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let n = 2000;
    let f: Vec<f64> = (1..=n).map(|k| k as f64).collect();
    let mut z = |s: f64| {
        c(
            s * (rng.random::<f64>() * 2.0 - 1.0),
            s * (rng.random::<f64>() * 2.0 - 1.0),
        )
    };
    // magnitudes over several decades, as loop gains are
    let x: Vec<c64> = (0..n).map(|k| z(10f64.powi((k % 7) as i32 - 3))).collect();
    let y: Vec<c64> = (0..n).map(|k| z(10f64.powi((k % 5) as i32 - 2))).collect();
    let vx: Vec<f64> = x.iter().map(|v| 1e-3 * v.norm_sqr()).collect();
    let vy: Vec<f64> = y.iter().map(|v| 2e-3 * v.norm_sqr()).collect();
    let fx = Frd::new(f.clone(), x.clone(), Some(vx.clone()), Some(1e-4)).unwrap();
    let fy = Frd::new(f.clone(), y.clone(), Some(vy.clone()), Some(1e-4)).unwrap();
    // variances: the matrix formulas reorder the scalar ones (|1/d|²|1/d|² for 1/|d|⁴ in the
    // feedback), a few roundings apart; 1e-15 relative (≈ 5 ulp), 2e-15 for the feedback
    let check = |name: &str, got: &Frd, old: &dyn Fn(usize) -> (c64, f64)| {
        assert!(got.is_siso());
        let mut worst = 0.0f64;
        for k in 0..n {
            let (zv, vv) = old(k);
            // values: the same floating-point operations, bit for bit
            assert_eq!(got.values()[k], zv, "{name} value at line {k}");
            let rel = (got.variance().unwrap()[k] - vv).abs() / vv;
            worst = worst.max(rel);
        }
        let tol = if name.contains("feedback") {
            2e-15
        } else {
            1e-15
        };
        println!("{name}: worst relative variance difference {worst:.2e}");
        assert!(
            worst <= tol,
            "{name}: variance differs by {worst:.2e} relative"
        );
    };
    check("series", &fx.series(&fy).unwrap(), &|k| {
        old_series(x[k], y[k], vx[k], vy[k])
    });
    check("product", &fx.product(&fy).unwrap(), &|k| {
        old_series(x[k], y[k], vx[k], vy[k])
    });
    check("parallel", &fx.parallel(&fy).unwrap(), &|k| {
        old_parallel(x[k], y[k], vx[k], vy[k])
    });
    check("divide", &fx.divide(&fy).unwrap(), &|k| {
        old_divide(x[k], y[k], vx[k], vy[k])
    });
    check("inverse", &fx.inverse().unwrap(), &|k| {
        old_inverse(x[k], vx[k])
    });
    check("feedback", &fx.feedback(&fy).unwrap(), &|k| {
        old_feedback(x[k], y[k], vx[k], vy[k], -1.0)
    });
    check(
        "positive feedback",
        &fx.feedback_with_sign(&fy, FeedbackSign::Positive).unwrap(),
        &|k| old_feedback(x[k], y[k], vx[k], vy[k], 1.0),
    );
    // a zero divisor is still "division by zero at … Hz"
    let mut y0 = y.clone();
    y0[9] = c(0.0, 0.0);
    let fy0 = Frd::new(f, y0, None, Some(1e-4)).unwrap();
    let e = fx.divide(&fy0).unwrap_err().to_string();
    assert!(e.contains("division by zero at 10 Hz"), "{e}");
}

#[test]
fn closed_loop_set_from_two_by_two_responses() {
    use ambid_core::frf::closed_loop::{Averaging, ClosedLoopFrf};
    let cs = case(300, 8);
    let (p, k) = (&cs.x, &cs.y);
    let t: Vec<M2> = p
        .iter()
        .zip(k)
        .map(|(p, k)| mul(&inv(&add(&eye(), &mul(p, k))), p))
        .collect();
    let s: Vec<M2> = p
        .iter()
        .zip(k)
        .map(|(p, k)| inv(&add(&eye(), &mul(k, p))))
        .collect();
    let tf = frd_of(&cs.f, &t, Some(&cs.vx));
    let sf = frd_of(&cs.f, &s, None);
    let kf = frd_of(&cs.f, k, None);
    let cl = ClosedLoopFrf::from_responses(
        tf,
        sf,
        Some(&kf),
        vec![1.0; 32],
        vec![1.0; 32],
        Averaging::Periods(4),
        3.0,
    )
    .unwrap();
    assert_close(&cl.plant, p, 1e-12, "joint P");
    assert_close(&cl.controller, k, 1e-11, "C = (I − S) T⁻¹");
    let ind = cl.plant_indirect.as_ref().unwrap();
    assert_close(ind, p, 1e-11, "indirect P");
    // indirect variance: δP = (I − T C)⁻¹ δT (I − C T)⁻¹, checked by numerical derivatives
    for line in 0..cs.f.len() {
        let kk = k[line];
        let want = fd_var(
            &|tt| mul(tt, &inv(&add(&eye(), &scale(&mul(&kk, tt), -1.0)))),
            &t[line],
            &cs.vx[line],
        );
        let got = ind.variance_at(line).unwrap().unwrap();
        for i in 0..2 {
            for j in 0..2 {
                assert!((got[(i, j)] - want[i][j]).abs() <= 1e-6 * want[i][j]);
            }
        }
    }
    let bad = ClosedLoopFrf::from_responses(
        frd_of(&cs.f, &t, None),
        frd_of(&cs.f, &s, None),
        None,
        vec![1.0; 8],
        vec![1.0; 32],
        Averaging::Periods(4),
        3.0,
    );
    assert!(bad.unwrap_err().to_string().contains("coh_ry"));
}
