//! `lti` and `linalg` against fixtures written by `tests/fixtures/make_lti.py` (scipy, numpy,
//! python-control). Matrix comparisons are elementwise, relative to the max-abs norm of the
//! reference matrix: $\max_{ij} |M_{ij} - R_{ij}| \le \text{tol} \cdot \max_{ij} |R_{ij}|$.

use ambid_core::c64;
use ambid_core::linalg;
use ambid_core::lti::{FeedbackSign, StateSpace, TransferFunction};
use faer::{Mat, MatRef};
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

fn vecf(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn vecc(v: &Value) -> Vec<c64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| c64::new(x[0].as_f64().unwrap(), x[1].as_f64().unwrap()))
        .collect()
}

fn maxabs(m: MatRef<'_, f64>) -> f64 {
    let mut r = 0.0f64;
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            r = r.max(m[(i, j)].abs());
        }
    }
    r
}

fn assert_mat_close(what: &str, got: MatRef<'_, f64>, want: MatRef<'_, f64>, tol: f64) {
    assert_eq!(
        (got.nrows(), got.ncols()),
        (want.nrows(), want.ncols()),
        "{what}: shape"
    );
    // an all-zero reference is compared absolutely
    let scale = maxabs(want).max(1.0 * f64::from(u8::from(maxabs(want) == 0.0)));
    let err = maxabs((got - want).as_ref());
    assert!(
        err <= tol * scale,
        "{what}: error {err:.3e} > {tol:.1e} × {scale:.3e}"
    );
}

fn assert_ss_close(what: &str, got: &StateSpace, want: &Value, tol: f64) {
    assert_mat_close(&format!("{what} A"), got.a(), mat(&want["a"]).as_ref(), tol);
    assert_mat_close(&format!("{what} B"), got.b(), mat(&want["b"]).as_ref(), tol);
    assert_mat_close(&format!("{what} C"), got.c(), mat(&want["c"]).as_ref(), tol);
    assert_mat_close(&format!("{what} D"), got.d(), mat(&want["d"]).as_ref(), tol);
}

fn ss_from(v: &Value, ts: Option<f64>) -> StateSpace {
    StateSpace::new(mat(&v["a"]), mat(&v["b"]), mat(&v["c"]), mat(&v["d"]), ts).unwrap()
}

/// Every reference value has a distinct match in `got` within `tol · max(1, |z|)`.
fn assert_sets_close(what: &str, got: &[c64], want: &[c64], tol: f64) {
    assert_eq!(got.len(), want.len(), "{what}: count {got:?} vs {want:?}");
    let mut used = vec![false; got.len()];
    for w in want {
        let (k, d) = got
            .iter()
            .enumerate()
            .filter(|(k, _)| !used[*k])
            .map(|(k, g)| (k, (g - w).norm()))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        assert!(
            d <= tol * w.norm().max(1.0),
            "{what}: {w} matched at distance {d:.3e}; got {got:?}"
        );
        used[k] = true;
    }
}

#[test]
fn c2d_zoh_and_tustin_match_scipy() {
    let cases = load("lti_c2d.json");
    for case in cases.as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let ts = case["ts"].as_f64().unwrap();
        let sys = ss_from(case, None);
        let zoh = sys.c2d_zoh(ts).unwrap();
        assert_ss_close(&format!("{name} zoh"), &zoh, &case["zoh"], 1e-10);
        let tus = sys.c2d_tustin(ts, None).unwrap();
        assert_ss_close(&format!("{name} tustin"), &tus, &case["tustin"], 1e-10);
        let pw = &case["tustin_prewarp"];
        let f_p = pw["f_hz"].as_f64().unwrap();
        let tpw = sys.c2d_tustin(ts, Some(f_p)).unwrap();
        assert_ss_close(&format!("{name} tustin prewarp"), &tpw, pw, 1e-10);
        assert_eq!(tpw.ts(), Some(ts));
        // prewarping: exact match of the frequency response at f_p
        let gc = sys.freq_response(&[f_p]).unwrap();
        let gd = tpw.freq_response(&[f_p]).unwrap();
        let e = maxabs_c((&gc[0] - &gd[0]).as_ref()) / maxabs_c(gc[0].as_ref());
        assert!(e < 1e-9, "{name}: prewarped response off by {e:.3e}");
    }
}

fn maxabs_c(m: MatRef<'_, c64>) -> f64 {
    let mut r = 0.0f64;
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            r = r.max(m[(i, j)].norm());
        }
    }
    r
}

#[test]
fn d2c_inverts_c2d() {
    let cases = load("lti_c2d.json");
    for case in cases.as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let ts = case["ts"].as_f64().unwrap();
        let sys = ss_from(case, None);
        let want = case.clone();
        // Tustin, plain and prewarped
        let back = sys.c2d_tustin(ts, None).unwrap().d2c_tustin(None).unwrap();
        assert_ss_close(&format!("{name} d2c_tustin"), &back, &want, 1e-9);
        let f_p = case["tustin_prewarp"]["f_hz"].as_f64().unwrap();
        let back = sys
            .c2d_tustin(ts, Some(f_p))
            .unwrap()
            .d2c_tustin(Some(f_p))
            .unwrap();
        assert_ss_close(&format!("{name} d2c_tustin prewarp"), &back, &want, 1e-9);
        // ZOH: needs |Im λ(A)| ts < π and a well-conditioned logarithm; the stiff `large_norm`
        // system (poles e^{-200}) is checked separately below.
        if name != "large_norm" {
            let back = sys.c2d_zoh(ts).unwrap().d2c_zoh().unwrap();
            assert_ss_close(&format!("{name} d2c_zoh"), &back, &want, 1e-9);
        }
    }
}

#[test]
fn d2c_zoh_stiff_system_is_consistent() {
    // For the stiff case the exact inverse is ill-conditioned (A_d ≈ e^{-200}); check instead that
    // re-discretising the recovered model reproduces the discrete model.
    let cases = load("lti_c2d.json");
    let case = cases
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "large_norm")
        .unwrap();
    let ts = case["ts"].as_f64().unwrap();
    let d = ss_from(&case["zoh"], Some(ts));
    let back = d.d2c_zoh().unwrap();
    let again = back.c2d_zoh(ts).unwrap();
    assert_ss_close("large_norm zoh→d2c→zoh", &again, &case["zoh"], 1e-8);
}

#[test]
fn roots_match_numpy() {
    for case in load("lti_roots.json").as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let got = linalg::roots(&vecf(&case["coeffs"])).unwrap();
        assert_sets_close(name, &got, &vecc(&case["roots"]), 1e-9);
    }
}

#[test]
fn ss2tf_matches_scipy_and_round_trips() {
    for case in load("lti_ss2tf.json").as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let ts = case["ts"].as_f64().unwrap();
        let sys = ss_from(case, Some(ts));
        let (num, den) = sys.tf_coefficients().unwrap();
        let (wn, wd) = (vecf(&case["num"]), vecf(&case["den"]));
        // scipy forms num = poly(A - BC) + (D - 1) poly(A): its absolute error is of order
        // eps·max|den|, so the numerator is compared relative to the largest coefficient of the
        // pair (num, den); the denominator relative to itself.
        let pair_scale = wn.iter().chain(&wd).fold(0.0f64, |m, x| m.max(x.abs()));
        for (g, w) in num.iter().zip(&wn) {
            assert!(
                (g - w).abs() <= 1e-10 * pair_scale,
                "{name} num: {num:?} vs {wn:?}"
            );
        }
        assert_eq!(num.len(), wn.len());
        assert_vec_close(&format!("{name} den"), &den, &wd, 1e-10);
        // tf → ss → tf
        let tf = TransferFunction::new(wn.clone(), wd.clone(), ts).unwrap();
        let back = TransferFunction::from_state_space(&tf.to_state_space().unwrap()).unwrap();
        assert_vec_close(&format!("{name} rt num"), back.num(), &wn, 1e-10);
        assert_vec_close(&format!("{name} rt den"), back.den(), &wd, 1e-10);
        // our coefficients give the state-space frequency response
        let f: Vec<f64> = (1..20).map(|k| k as f64 * 0.024 / ts).collect();
        let g1 = sys.freq_response_siso(&f).unwrap();
        let g2 = TransferFunction::from_state_space(&sys)
            .unwrap()
            .freq_response(&f)
            .unwrap();
        for (a, b) in g1.iter().zip(&g2) {
            assert!(
                (a - b).norm() <= 1e-8 * a.norm().max(1e-12),
                "{name}: {a} vs {b}"
            );
        }
    }
}

fn assert_vec_close(what: &str, got: &[f64], want: &[f64], tol: f64) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    let scale = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() <= tol * scale, "{what}: {got:?} vs {want:?}");
    }
}

#[test]
fn zeros_match_python_control_and_scipy_pencil() {
    for case in load("lti_zeros.json").as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let ts = case["ts"].as_f64().unwrap();
        let sys = ss_from(case, Some(ts));
        let got = sys.zeros().unwrap();
        assert_sets_close(name, &got, &vecc(&case["zeros"]), 1e-8);
        if sys.ninputs() == 1 {
            // SISO: the same zeros from the transfer-function numerator
            let tf = TransferFunction::from_state_space(&sys).unwrap();
            let z2 = tf.zeros().unwrap();
            assert_sets_close(&format!("{name} via tf"), &z2, &vecc(&case["zeros"]), 1e-6);
        }
    }
}

#[test]
fn feedback_matches_python_control() {
    let fx = load("lti_feedback.json");
    let ts = fx["ts"].as_f64().unwrap();
    let plant = ss_from(&fx["plant"], Some(ts));
    let ctrl = ss_from(&fx["controller"], Some(ts));
    for case in fx["cases"].as_array().unwrap() {
        let sign = match case["sign"].as_i64().unwrap() {
            -1 => FeedbackSign::Negative,
            _ => FeedbackSign::Positive,
        };
        let f = vecf(&case["f_hz"]);
        let want = vecc(&case["response"]);
        let cl = plant.feedback_with_sign(&ctrl, sign).unwrap();
        let got = cl.freq_response_siso(&f).unwrap();
        for (k, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!(
                (g - w).norm() <= 1e-9 * w.norm(),
                "{sign:?} at {} Hz: {g} vs {w}",
                f[k]
            );
        }
        // frequency-response-data algebra gives the same
        let pf = ambid_core::lti::Frd::from_model(&plant, &f).unwrap();
        let kf = ambid_core::lti::Frd::from_model(&ctrl, &f).unwrap();
        let t = pf.feedback_with_sign(&kf, sign).unwrap();
        for (g, w) in t.values().iter().zip(&want) {
            assert!((g - w).norm() <= 1e-9 * w.norm());
        }
    }
    // negative feedback of this stabilising controller: the closed loop is stable
    assert!(plant.feedback(&ctrl).unwrap().is_stable().unwrap());
    assert!(!plant.is_stable().unwrap());
}
