//! `linalg::dare` against `scipy.linalg.solve_discrete_are` (fixtures written by
//! `tests/fixtures/make_subspace.py`) and against its own equation: the relative residual
//! $\lVert \mathcal R(X) \rVert_F / (\lVert A^\top X A \rVert_F + \lVert X \rVert_F +
//! \lVert T \rVert_F + \lVert Q \rVert_F) \le 10^{-10}$ with
//! $T = (A^\top X B + S)(R + B^\top X B)^{-1}(B^\top X A + S^\top)$ and
//! $\mathcal R(X) = A^\top X A - X - T + Q$.

use ambid_core::linalg::{dare, eigenvalues, solve};
use ambid_core::Error;
use faer::{mat, Mat, MatRef};
use serde_json::Value;

fn load(name: &str) -> Value {
    let path = format!("{}/tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    serde_json::from_str(&text).unwrap()
}

fn mat(v: &Value) -> Mat<f64> {
    let rows = v.as_array().unwrap();
    let nr = rows.len();
    let nc = rows.first().map_or(0, |r| r.as_array().unwrap().len());
    Mat::from_fn(nr, nc, |i, j| rows[i][j].as_f64().unwrap())
}

/// Relative residual of the DARE and the spectral radius of the closed loop.
fn check(
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
    q: MatRef<'_, f64>,
    r: MatRef<'_, f64>,
    s: MatRef<'_, f64>,
    x: MatRef<'_, f64>,
) -> (f64, f64) {
    let axb_s = a.transpose() * x * b + s;
    let rbxb = r + b.transpose() * x * b;
    let f = solve(rbxb.as_ref(), axb_s.transpose()).unwrap();
    let t = &axb_s * &f;
    let axa = a.transpose() * x * a;
    let res = &axa - x - &t + q;
    let scale = axa.norm_l2() + x.norm_l2() + t.norm_l2() + q.norm_l2();
    let acl = a - b * &f;
    let rho = eigenvalues(acl.as_ref())
        .unwrap()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max);
    (res.norm_l2() / scale, rho)
}

#[test]
fn matches_scipy_and_satisfies_the_equation() {
    let fx = load("subspace_dare.json");
    let cases = fx["cases"].as_array().unwrap();
    assert!(cases.len() >= 7);
    for c in cases {
        let name = c["name"].as_str().unwrap();
        let (a, b, q, r) = (mat(&c["a"]), mat(&c["b"]), mat(&c["q"]), mat(&c["r"]));
        let s = c.get("s").map(mat);
        let want = mat(&c["x"]);
        let x = dare(
            a.as_ref(),
            b.as_ref(),
            q.as_ref(),
            r.as_ref(),
            s.as_ref().map(|s| s.as_ref()),
        )
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        let err = (&x - &want).norm_max() / want.norm_max();
        let s0 = s.unwrap_or_else(|| Mat::zeros(a.nrows(), b.ncols()));
        let (res, rho) = check(
            a.as_ref(),
            b.as_ref(),
            q.as_ref(),
            r.as_ref(),
            s0.as_ref(),
            x.as_ref(),
        );
        eprintln!(
            "{name}: |X − X_scipy|/|X| = {err:.2e}, residual {res:.2e}, ρ(A − BF) = {rho:.4}"
        );
        assert!(err < 1e-9, "{name}: differs from scipy by {err:.2e}");
        assert!(res < 1e-10, "{name}: relative residual {res:.2e}");
        assert!(rho < 1.0, "{name}: closed loop not stable");
        assert!(
            (&x - x.transpose()).norm_max() == 0.0,
            "{name}: X not symmetric"
        );
    }
}

#[test]
fn slow_closed_loop_still_converges() {
    // x = a² x − a² x² b² / (r + b² x) + q with a = 1 (marginally stable open loop), tiny q:
    // the closed loop pole is close to 1, convergence of the doubling needs more steps.
    let a = mat![[1.0]];
    let b = mat![[1.0]];
    let q = mat![[1e-8]];
    let r = mat![[1.0]];
    let x = dare(a.as_ref(), b.as_ref(), q.as_ref(), r.as_ref(), None).unwrap();
    // x² − q x − q = 0
    let want = 0.5 * (1e-8 + (1e-16f64 + 4e-8).sqrt());
    assert!((x[(0, 0)] - want).abs() < 1e-12 * want);
}

#[test]
fn errors() {
    let i2 = mat![[1.0, 0.0], [0.0, 1.0]];
    let one = mat![[1.0]];
    // an unstable mode that B does not reach
    let a = mat![[2.0, 0.0], [0.0, 0.5]];
    let b = mat![[0.0], [1.0]];
    let e = dare(a.as_ref(), b.as_ref(), i2.as_ref(), one.as_ref(), None).unwrap_err();
    assert!(matches!(e, Error::Numerical { .. }), "{e}");
    assert!(e.to_string().contains("stabilis"), "{e}");
    // an undamped mode that Q does not see and B does not reach: eigenvalues on the unit circle
    let a = mat![[0.0, 1.0], [-1.0, 0.0]];
    let b = mat![[0.0], [0.0]];
    let z = mat![[0.0, 0.0], [0.0, 0.0]];
    assert!(dare(a.as_ref(), b.as_ref(), z.as_ref(), one.as_ref(), None).is_err());
    // R not positive definite
    let a = mat![[0.5]];
    let e = dare(
        a.as_ref(),
        one.as_ref(),
        one.as_ref(),
        mat![[0.0]].as_ref(),
        None,
    )
    .unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { name: "r", .. }), "{e}");
    // Q not symmetric
    let a2 = mat![[0.5, 0.0], [0.0, 0.5]];
    let qa = mat![[1.0, 0.5], [0.0, 1.0]];
    let b2 = mat![[1.0], [1.0]];
    let e = dare(a2.as_ref(), b2.as_ref(), qa.as_ref(), one.as_ref(), None).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { name: "q", .. }), "{e}");
    // shapes and finiteness
    let e = dare(a2.as_ref(), one.as_ref(), i2.as_ref(), one.as_ref(), None).unwrap_err();
    assert!(matches!(e, Error::DimensionMismatch { .. }), "{e}");
    let e = dare(
        a2.as_ref(),
        b2.as_ref(),
        i2.as_ref(),
        one.as_ref(),
        Some(mat![[1.0, 2.0]].as_ref()),
    )
    .unwrap_err();
    assert!(matches!(e, Error::DimensionMismatch { .. }), "{e}");
    let nan = mat![[f64::NAN]];
    assert!(dare(nan.as_ref(), one.as_ref(), one.as_ref(), one.as_ref(), None).is_err());
    // an empty problem has an empty solution
    let x = dare(
        Mat::<f64>::zeros(0, 0).as_ref(),
        Mat::<f64>::zeros(0, 1).as_ref(),
        Mat::<f64>::zeros(0, 0).as_ref(),
        one.as_ref(),
        None,
    )
    .unwrap();
    assert_eq!(x.nrows(), 0);
}

#[test]
fn kalman_filter_of_a_random_walk() {
    // x_{k+1} = x_k + w, y = x + v: P solves P = P − P²/(P + r) + q → P² − qP − qr = 0
    let (q, r) = (0.01, 1.0);
    let p = dare(
        mat![[1.0]].as_ref(),
        mat![[1.0]].as_ref(),
        mat![[q]].as_ref(),
        mat![[r]].as_ref(),
        None,
    )
    .unwrap();
    let want = 0.5 * (q + (q * q + 4.0 * q * r).sqrt());
    assert!((p[(0, 0)] - want).abs() < 1e-14);
}
