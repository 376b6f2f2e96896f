//! The twin's linear truth against an independent oracle.
//!
//! `tests/fixtures/twin_truth.json` is written by `python3 tests/fixtures/make_twin_truth.py`
//! (from the repository root): a numpy/scipy/python-control model built from the physical
//! specification of the rig (10-state continuous rotor/amplifier/sensor model, ZOH, one-sample
//! computation delay, Tustin PID, loop B closed by hand), not translated from the Rust code. The
//! script itself cross-checks two independent routes (transfer-matrix algebra vs python-control
//! interconnection) to ~1e-11.
//!
//! For the nominal rig and the operating points (1.6 A, 0.41 mm) and (2.4 A, 0.39 mm) we check
//! k_i, k_x, the FRFs of P, C, T_ry, S on a 68-point grid (1 Hz .. 9.9 kHz plus points at the
//! closed-loop modes and the bending mode), the unstable pole of P and the 18 closed-loop poles
//! (matched one-to-one by nearest neighbour, in both directions). Measured agreement (see the
//! tolerances below): FRFs <= 5.6e-12, closed-loop poles <= 4e-13, unstable pole <= 3.5e-15,
//! k_i, k_x exact to rounding. Details in the `eprintln!` output (`cargo test -p ambid-twin --test all oracle:: --
//! --nocapture`).

use ambid_twin::{c64, Twin, TwinConfig};
use serde_json::Value;

const FIXTURE: &str = include_str!("fixtures/twin_truth.json");

/// Relative tolerance on the FRFs (P, C, T_ry, S). Achieved: P, T_ry <= 5.6e-12 (worst near
/// 8.5-9.9 kHz, where |P| is small; the oracle's own two routes agree to the same level),
/// S <= 1.1e-13, C 2.9e-14. Before the balanced ZOH (Padé-13 on the unbalanced augmented
/// matrix) T_ry was off by 1.6e-8 at 780 Hz.
const TOL_FRF: f64 = 1e-9;
/// Relative tolerance on the closed-loop poles. Achieved: <= 4e-13. Before balancing the
/// eigenvalue problem the fast pair at z = -0.0196 +/- 0.0330j was off by 1.6e-3.
const TOL_CL_POLES: f64 = 1e-10;
/// Relative tolerance on the unstable pole(s) of P. Achieved: <= 3.5e-15 (5.6e-10 before
/// balancing the eigenvalue problem).
const TOL_UNSTABLE: f64 = 1e-12;
/// Relative tolerance on k_i, k_x (closed-form formulas on both sides).
const TOL_GAINS: f64 = 1e-13;

struct Case {
    name: String,
    bias: f64,
    gap: f64,
    k_i: f64,
    k_x: f64,
    freq: Vec<f64>,
    plant: Vec<c64>,
    controller: Vec<c64>,
    t_ry: Vec<c64>,
    sensitivity: Vec<c64>,
    cl_poles: Vec<c64>,
    unstable: Vec<c64>,
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

fn complex(v: &Value) -> Vec<c64> {
    let re = floats(&v["re"]);
    let im = floats(&v["im"]);
    assert_eq!(re.len(), im.len());
    re.iter().zip(&im).map(|(&r, &i)| c64::new(r, i)).collect()
}

fn cases() -> Vec<Case> {
    let root: Value = serde_json::from_str(FIXTURE).expect("valid fixture JSON");
    assert_eq!(root["fs_hz"].as_f64(), Some(20_000.0));
    root["cases"]
        .as_array()
        .expect("cases")
        .iter()
        .map(|c| Case {
            name: c["name"].as_str().expect("name").to_string(),
            bias: c["bias_current_a"].as_f64().unwrap(),
            gap: c["air_gap_m"].as_f64().unwrap(),
            k_i: c["k_i"].as_f64().unwrap(),
            k_x: c["k_x"].as_f64().unwrap(),
            freq: floats(&c["freq_hz"]),
            plant: complex(&c["plant"]),
            controller: complex(&c["controller"]),
            t_ry: complex(&c["t_ry"]),
            sensitivity: complex(&c["sensitivity"]),
            cl_poles: complex(&c["closed_loop_poles"]),
            unstable: complex(&c["plant_unstable_poles"]),
        })
        .collect()
}

fn twin_for(c: &Case) -> Twin {
    let toml = format!(
        "[operating_point]\nbias_current_a = {:?}\nair_gap_m = {:?}\n",
        c.bias, c.gap
    );
    let twin = Twin::new(TwinConfig::from_toml_str(&toml).expect("config")).expect("twin");
    assert_eq!(twin.fs(), 20_000.0, "{}: sample rate", c.name);
    twin
}

/// Max over the grid of |a - b| / |b|, with the frequency where it occurs.
fn max_rel(a: &[c64], b: &[c64], f: &[f64]) -> (f64, f64) {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .zip(f)
        .map(|((a, b), &f)| ((a - b).norm() / b.norm(), f))
        .fold((0.0, 0.0), |acc, x| if x.0 > acc.0 { x } else { acc })
}

/// Match every pole of `a` to its nearest neighbour in `b` (one-to-one, greedy) and return the
/// largest relative distance |a - b| / |b|.
fn pole_set_rel(a: &[c64], b: &[c64]) -> f64 {
    assert_eq!(a.len(), b.len(), "pole counts differ: {a:?} vs {b:?}");
    let mut used = vec![false; b.len()];
    let mut worst: f64 = 0.0;
    for p in a {
        let (j, d) = b
            .iter()
            .enumerate()
            .filter(|(j, _)| !used[*j])
            .map(|(j, q)| (j, (p - q).norm()))
            .fold((usize::MAX, f64::INFINITY), |acc, x| {
                if x.1 < acc.1 {
                    x
                } else {
                    acc
                }
            });
        used[j] = true;
        worst = worst.max(d / b[j].norm());
    }
    worst
}

#[test]
fn oracle_magnet_gains() {
    for c in cases() {
        let lp = twin_for(&c).linear_params();
        let ei = (lp.k_i / c.k_i - 1.0).abs();
        let ex = (lp.k_x / c.k_x - 1.0).abs();
        eprintln!("{}: k_i rel err {ei:.1e}, k_x rel err {ex:.1e}", c.name);
        assert!(
            ei < TOL_GAINS && ex < TOL_GAINS,
            "{}: k_i {ei:e}, k_x {ex:e}",
            c.name
        );
    }
}

#[test]
fn oracle_frequency_responses() {
    for c in cases() {
        let twin = twin_for(&c);
        let f = &c.freq;
        for (label, got, want) in [
            ("P", twin.plant_frf(f).unwrap(), &c.plant),
            ("C", twin.controller_frf(f).unwrap(), &c.controller),
            ("T_ry", twin.t_ry_frf(f).unwrap(), &c.t_ry),
            ("S", twin.sensitivity_frf(f).unwrap(), &c.sensitivity),
        ] {
            let (e, fe) = max_rel(&got, want, f);
            eprintln!("{}: {label:4} max rel err {e:.2e} (at {fe:.1} Hz)", c.name);
            assert!(
                e < TOL_FRF,
                "{}: {label} differs from the oracle by {e:e} (relative) at {fe} Hz",
                c.name
            );
        }
    }
}

#[test]
fn oracle_plant_unstable_poles() {
    for c in cases() {
        let got = twin_for(&c).plant_unstable_poles().unwrap();
        assert_eq!(got.len(), 1, "{}: {got:?}", c.name);
        let e = pole_set_rel(&got, &c.unstable);
        eprintln!(
            "{}: unstable pole of P z = {:.12} (oracle {:.12}), rel err {e:.1e}",
            c.name, got[0].re, c.unstable[0].re
        );
        assert!(e < TOL_UNSTABLE, "{}: unstable pole rel err {e:e}", c.name);
    }
}

#[test]
fn oracle_closed_loop_poles() {
    for c in cases() {
        let got = twin_for(&c).closed_loop_poles();
        assert_eq!(got.len(), c.cl_poles.len(), "{}: pole count", c.name);
        // both directions, so that the matching cannot hide a missing or duplicated pole
        let e = pole_set_rel(&got, &c.cl_poles).max(pole_set_rel(&c.cl_poles, &got));
        eprintln!(
            "{}: {} closed-loop poles, max rel err {e:.1e}",
            c.name,
            got.len()
        );
        assert!(
            e < TOL_CL_POLES,
            "{}: closed-loop poles rel err {e:e}",
            c.name
        );
    }
}
