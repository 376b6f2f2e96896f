//! The state-space frequency response (balanced Hessenberg form, O(n²) per frequency, one
//! refinement step near poles) against a naive in-test oracle: the dense complex system
//! (λI − A) x = B solved by Gaussian elimination with partial pivoting, on random MIMO models,
//! continuous and discrete, badly scaled states, and frequencies next to a pole.

use ambid_core::c64;
use ambid_core::lti::StateSpace;
use faer::Mat;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn naive(a: &Mat<f64>, b: &Mat<f64>, c: &Mat<f64>, d: &Mat<f64>, lam: c64) -> Vec<c64> {
    let n = a.nrows();
    let m = b.ncols();
    let mut out = Vec::new();
    for j in 0..m {
        let mut mtx: Vec<Vec<c64>> = (0..n)
            .map(|i| {
                let mut row: Vec<c64> = (0..n)
                    .map(|k| {
                        let dd = if i == k { lam } else { c64::new(0.0, 0.0) };
                        dd - c64::new(a[(i, k)], 0.0)
                    })
                    .collect();
                row.push(c64::new(b[(i, j)], 0.0));
                row
            })
            .collect();
        for col in 0..n {
            let piv = (col..n)
                .max_by(|&x, &y| mtx[x][col].norm().total_cmp(&mtx[y][col].norm()))
                .unwrap();
            mtx.swap(col, piv);
            let prow = mtx[col].clone();
            for (i, row) in mtx.iter_mut().enumerate() {
                if i != col {
                    let f = row[col] / prow[col];
                    for (x, v) in row.iter_mut().zip(&prow).skip(col) {
                        *x -= f * v;
                    }
                }
            }
        }
        let x: Vec<c64> = (0..n).map(|i| mtx[i][n] / mtx[i][i]).collect();
        for i in 0..c.nrows() {
            let mut v = c64::new(d[(i, j)], 0.0);
            for (k, xk) in x.iter().enumerate() {
                v += xk * c[(i, k)];
            }
            out.push(v);
        }
    }
    out
}

#[test]
fn hessenberg_frequency_response_matches_a_dense_oracle() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut worst: f64 = 0.0;
    for (n, discrete) in [
        (1usize, true),
        (2, false),
        (8, true),
        (30, true),
        (40, false),
    ] {
        // badly scaled states: a random matrix conjugated by a diagonal of 10^{±3}
        let s: Vec<f64> = (0..n)
            .map(|_| 10f64.powf(rng.random_range(-3.0..3.0)))
            .collect();
        let raw = Mat::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0) / (n as f64).sqrt());
        let shift = if discrete { 0.0 } else { -2.0 };
        let a = Mat::from_fn(n, n, |i, k| {
            raw[(i, k)] * s[i] / s[k] + if i == k { shift } else { 0.0 }
        });
        let b = Mat::from_fn(n, 2, |i, _| rng.random_range(-1.0..1.0) * s[i]);
        let c = Mat::from_fn(3, n, |_, k| rng.random_range(-1.0..1.0) / s[k]);
        let d = Mat::from_fn(3, 2, |_, _| rng.random_range(-1.0..1.0));
        let ts = 1e-3;
        let sys = if discrete {
            StateSpace::discrete(a.clone(), b.clone(), c.clone(), d.clone(), ts).unwrap()
        } else {
            StateSpace::continuous(a.clone(), b.clone(), c.clone(), d.clone()).unwrap()
        };
        let mut f: Vec<f64> = (0..50).map(|k| 0.1 + 4.9 * k as f64).collect();
        // next to a pole: the frequency of the pole closest to the axis / circle, nudged
        let poles = sys.poles().unwrap();
        if let Some(pz) = poles.iter().find(|p| p.im > 1e-6) {
            let w = if discrete {
                pz.im.atan2(pz.re) / ts
            } else {
                pz.im
            };
            f.push(w / (2.0 * std::f64::consts::PI) * (1.0 + 1e-9));
        }
        let g = sys.freq_response(&f).unwrap();
        for (k, &fk) in f.iter().enumerate() {
            let w = 2.0 * std::f64::consts::PI * fk;
            let lam = if discrete {
                c64::from_polar(1.0, w * ts)
            } else {
                c64::new(0.0, w)
            };
            let want = naive(&a, &b, &c, &d, lam);
            for j in 0..2 {
                for i in 0..3 {
                    let got = g[k][(i, j)];
                    let t = want[j * 3 + i];
                    let scale = t.norm().max(1e-300);
                    worst = worst.max((got - t).norm() / scale);
                }
            }
        }
    }
    println!("worst relative difference to the dense oracle: {worst:.2e}");
    assert!(worst < 1e-10, "{worst}");
}
