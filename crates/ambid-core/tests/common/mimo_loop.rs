//! A discrete 4-axis (or 1-axis) closed loop built from state-space parts, for the MIMO FRF
//! tests: per axis an unstable mass with negative stiffness, an amplifier lag and a one-sample
//! sensor delay (ZOH), the axes coupled by a known stiffness matrix and a skew (gyroscopic-like)
//! velocity coupling; a discrete PD controller per axis, u = −C y + r. Truth: T_ry = (I + P C)⁻¹ P,
//! S = (I + C P)⁻¹ from the state spaces by `Frd` algebra.
#![allow(dead_code)]

use ambid_core::data::IoData;
use ambid_core::lti::{Frd, StateSpace};
use faer::Mat;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

pub const FS: f64 = 4000.0;
pub const AXES: [&str; 4] = ["xa", "xb", "ya", "yb"];

/// The discrete plant (u → y, 16 states) and controller (y → u_c, 4 states) of `n` axes (1 or 4).
pub struct Loop {
    pub plant: StateSpace,
    pub ctrl: StateSpace,
    pub n: usize,
}

pub fn build(n: usize) -> Loop {
    let ks = 3.55e4; // negative stiffness / mass [1/s²]: unstable pole at ≈ 30 Hz
    let tau = 1.0 / (2.0 * std::f64::consts::PI * 800.0);
    // stiffness coupling (symmetric) and skew velocity coupling
    let mut k = Mat::<f64>::zeros(n, n);
    let mut g = Mat::<f64>::zeros(n, n);
    for i in 0..n {
        k[(i, i)] = ks;
    }
    if n == 4 {
        for (a, b, v) in [
            (0, 1, 0.3),
            (2, 3, 0.3),
            (0, 2, 0.05),
            (1, 3, 0.04),
            (0, 3, 0.02),
        ] {
            k[(a, b)] = v * ks;
            k[(b, a)] = v * ks;
        }
        for (a, b, v) in [(0, 2, 25.0), (1, 3, 15.0)] {
            g[(a, b)] = v;
            g[(b, a)] = -v;
        }
    }
    let ns = 3 * n;
    let mut a = Mat::<f64>::zeros(ns, ns);
    let mut bm = Mat::<f64>::zeros(ns, n);
    let mut c = Mat::<f64>::zeros(n, ns);
    for i in 0..n {
        a[(i, n + i)] = 1.0;
        for j in 0..n {
            a[(n + i, j)] = k[(i, j)];
            a[(n + i, n + j)] = -g[(i, j)];
        }
        a[(n + i, 2 * n + i)] = ks; // force gain (normalised: |P(0)| = 1 per axis)
        a[(2 * n + i, 2 * n + i)] = -1.0 / tau;
        bm[(2 * n + i, i)] = 1.0 / tau;
        c[(i, i)] = 1.0;
    }
    let cont = StateSpace::new(a, bm, c, Mat::zeros(n, n), None).unwrap();
    let d = cont.c2d_zoh(1.0 / FS).unwrap();
    // one-sample sensor delay: state (x_p, q), q⁺ = C x_p, y = q
    let nd = ns + n;
    let mut ad = Mat::<f64>::zeros(nd, nd);
    let mut bd = Mat::<f64>::zeros(nd, n);
    let mut cd = Mat::<f64>::zeros(n, nd);
    for i in 0..ns {
        for j in 0..ns {
            ad[(i, j)] = d.a()[(i, j)];
        }
        for j in 0..n {
            bd[(i, j)] = d.b()[(i, j)];
        }
    }
    for i in 0..n {
        ad[(ns + i, i)] = 1.0;
        cd[(i, ns + i)] = 1.0;
    }
    let plant = StateSpace::new(ad, bd, cd, Mat::zeros(n, n), Some(1.0 / FS)).unwrap();
    // PD per axis: u_c = kp y + kd (y − y⁻)/Ts; A axes (even index in AXES order xa, xb, ya, yb → a = 0, 2)
    let mut ac = Mat::<f64>::zeros(n, n);
    let mut bc = Mat::<f64>::zeros(n, n);
    let mut cc = Mat::<f64>::zeros(n, n);
    let mut dc = Mat::<f64>::zeros(n, n);
    for i in 0..n {
        let bearing_a = n == 1 || i % 2 == 0;
        let (kp, kd) = if bearing_a {
            (3.0, 0.010)
        } else {
            (3.5, 0.012)
        };
        ac[(i, i)] = 0.0;
        bc[(i, i)] = 1.0;
        cc[(i, i)] = -kd * FS;
        dc[(i, i)] = kp + kd * FS;
    }
    let ctrl = StateSpace::new(ac, bc, cc, dc, Some(1.0 / FS)).unwrap();
    Loop { plant, ctrl, n }
}

impl Loop {
    /// Closed-loop simulation from rest; `noise` is the standard deviation of white sensor noise
    /// (it enters the loop). Returns (u, y) per axis.
    pub fn simulate(
        &self,
        r: &[Vec<f64>],
        noise: f64,
        rng: &mut ChaCha8Rng,
    ) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let n = self.n;
        let len = r[0].len();
        let (a, b, c) = (self.plant.a(), self.plant.b(), self.plant.c());
        let (ac, bc, cc, dc) = (self.ctrl.a(), self.ctrl.b(), self.ctrl.c(), self.ctrl.d());
        let (np, nc) = (a.nrows(), ac.nrows());
        let mut x = vec![0.0; np];
        let mut z = vec![0.0; nc];
        let mut u = vec![vec![0.0; len]; n];
        let mut y = vec![vec![0.0; len]; n];
        let mut yk = vec![0.0; n];
        let mut uk = vec![0.0; n];
        for t in 0..len {
            for i in 0..n {
                let v: f64 = if noise > 0.0 {
                    StandardNormal.sample(rng)
                } else {
                    0.0
                };
                yk[i] = (0..np).map(|j| c[(i, j)] * x[j]).sum::<f64>() + noise * v;
            }
            for i in 0..n {
                let uc: f64 = (0..nc).map(|j| cc[(i, j)] * z[j]).sum::<f64>()
                    + (0..n).map(|j| dc[(i, j)] * yk[j]).sum::<f64>();
                uk[i] = -uc + r[i][t];
                u[i][t] = uk[i];
                y[i][t] = yk[i];
            }
            let xn: Vec<f64> = (0..np)
                .map(|i| {
                    (0..np).map(|j| a[(i, j)] * x[j]).sum::<f64>()
                        + (0..n).map(|j| b[(i, j)] * uk[j]).sum::<f64>()
                })
                .collect();
            let zn: Vec<f64> = (0..nc)
                .map(|i| {
                    (0..nc).map(|j| ac[(i, j)] * z[j]).sum::<f64>()
                        + (0..n).map(|j| bc[(i, j)] * yk[j]).sum::<f64>()
                })
                .collect();
            x = xn;
            z = zn;
        }
        (u, y)
    }

    /// Exact (T_ry, S, P) on `f`.
    pub fn truth(&self, f: &[f64]) -> (Frd, Frd, Frd) {
        let p = Frd::from_model(&self.plant, f).unwrap();
        let c = Frd::from_model(&self.ctrl, f).unwrap();
        let t = p.feedback(&c).unwrap();
        let s = Frd::identity(f, self.n, p.ts())
            .unwrap()
            .feedback(&p.series(&c).unwrap())
            .unwrap();
        (t, s, p)
    }

    pub fn record(
        &self,
        r: &[Vec<f64>],
        noise: f64,
        rng: &mut ChaCha8Rng,
        period: Option<usize>,
    ) -> IoData {
        let (u, y) = self.simulate(r, noise, rng);
        let name = |l: &str, i: usize| {
            if self.n == 1 {
                l.to_string()
            } else {
                format!("{l}_{}", AXES[i])
            }
        };
        let mut ch = Vec::new();
        for (l, s) in [("r", r), ("u", &u[..]), ("y", &y[..])] {
            for (i, v) in s.iter().enumerate() {
                ch.push((name(l, i), v.clone()));
            }
        }
        IoData::new(ch, 1.0 / FS, period).unwrap()
    }
}
