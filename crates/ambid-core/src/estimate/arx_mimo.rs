//! Multi-output ARX: the matrix difference equation
//! $$ y_t + \sum_{k=1}^{n_a} A_k\, y_{t-k} = \sum_{k=n_k}^{n_k+n_b-1} B_k\, u_{t-k} + e_t, $$
//! with $l$ outputs, $m$ inputs, $A_k \in \mathbb R^{l\times l}$, $B_k \in \mathbb R^{l \times m}$,
//! estimated by linear least squares, one output row at a time (the rows share no parameter, so
//! the joint least-squares problem separates). Two couplings of the outputs:
//! * [`OutputCoupling::Full`]: every $A_k$ full, each output regressed on the past of every
//!   output (MATLAB `arx` with scalar orders on multi-output data);
//! * [`OutputCoupling::Diagonal`]: $A_k$ diagonal, one MISO ARX per output (the outputs interact
//!   only through the inputs).
//!
//! Row $i$ is the MISO ARX of [`super::arx::arx`] with the other outputs as extra inputs (lags
//! $1 \dots n_a$), so its regressor checks and errors are the same. The model is returned as a
//! state-space realisation of the difference equation, state
//! $x_t = [y_{t-1}; \dots; y_{t-n_a}; u_{t-1}; \dots; u_{t-K}]$ with $K = n_k + n_b - 1$ (order
//! $l n_a + m K$, not minimal in general), for simulation, validation and export alike.
//!
//! # Example
//! ```
//! use ambid_core::estimate::arx_mimo::{arx_mimo, OutputCoupling};
//! // two outputs coupled through y1: y1 = 0.5 y1(-1) + u(-1), y2 = 0.3 y1(-1) + 2 u(-1)
//! let u: Vec<f64> = (0..200).map(|k| ((k * 7919) % 13) as f64 - 6.0).collect();
//! let (mut y1, mut y2) = (vec![0.0; 200], vec![0.0; 200]);
//! for t in 1..200 {
//!     y1[t] = 0.5 * y1[t - 1] + u[t - 1];
//!     y2[t] = 0.3 * y1[t - 1] + 2.0 * u[t - 1];
//! }
//! let m = arx_mimo(&[&y1, &y2], &[&u], 1, 1, 1, OutputCoupling::Full, 1.0).unwrap();
//! assert!((m.a[0][(0, 0)] + 0.5).abs() < 1e-10 && (m.a[0][(1, 0)] + 0.3).abs() < 1e-10);
//! assert!((m.b[1][(1, 0)] - 2.0).abs() < 1e-10);
//! ```

use super::arx::{arx, ArxOrders};
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use faer::Mat;

/// How the outputs enter each other's equations (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OutputCoupling {
    /// Full $A_k$: each output on the past of every output.
    #[default]
    Full,
    /// Diagonal $A_k$: one MISO ARX per output.
    Diagonal,
}

/// A multi-output ARX model (module docs).
#[derive(Debug, Clone)]
pub struct MimoArx {
    /// $A_1 \dots A_{n_a}$ ($l \times l$ each).
    pub a: Vec<Mat<f64>>,
    /// $B_0 \dots B_K$ ($l \times m$ each; zero below the delay $n_k$).
    pub b: Vec<Mat<f64>>,
    /// Sample time \[s\].
    pub ts: f64,
    /// Loss $V_N$ of each output's one-step prediction errors.
    pub loss: Vec<f64>,
    /// Samples in each output's criterion.
    pub n_samples: usize,
}

/// Estimates the model of the module docs from `y` ($l$ outputs) and `u` ($m$ inputs), all of one
/// length, with $n_a$, $n_b \ge 1$, $n_k$ common to every entry.
///
/// # Errors
/// [`Error::InvalidArgument`] for no outputs or inputs, or $n_b = 0$; signals of different
/// lengths ([`Error::DimensionMismatch`]); and the errors of [`arx`] for each output row (too few
/// samples, a rank-deficient regressor, non-finite data), prefixed with the output's index.
pub fn arx_mimo(
    y: &[&[f64]],
    u: &[&[f64]],
    na: usize,
    nb: usize,
    nk: usize,
    coupling: OutputCoupling,
    ts: f64,
) -> Result<MimoArx> {
    let (l, m) = (y.len(), u.len());
    if l == 0 || m == 0 {
        return Err(Error::invalid(
            "y",
            "a multi-output ARX needs at least one output and one input",
        ));
    }
    if nb == 0 {
        return Err(Error::invalid("nb", "nb must be at least 1"));
    }
    let n = y[0].len();
    for (what, x) in y.iter().map(|x| ("y", x)).chain(u.iter().map(|x| ("u", x))) {
        if x.len() != n {
            return Err(Error::DimensionMismatch {
                context: "arx_mimo: signals",
                expected: format!("{n} samples"),
                got: format!("{} samples in a column of {what}", x.len()),
            });
        }
    }
    let kmax = nk + nb - 1;
    let mut a = vec![Mat::<f64>::zeros(l, l); na];
    let mut b = vec![Mat::<f64>::zeros(l, m); kmax + 1];
    let mut loss = Vec::with_capacity(l);
    let mut n_samples = n;
    for i in 0..l {
        let others: Vec<usize> = match coupling {
            OutputCoupling::Full if na > 0 => (0..l).filter(|&j| j != i).collect(),
            _ => Vec::new(),
        };
        let mut inputs: Vec<&[f64]> = others.iter().map(|&j| y[j]).collect();
        inputs.extend_from_slice(u);
        let mut nbs = vec![na; others.len()];
        let mut nks = vec![1; others.len()];
        nbs.extend(std::iter::repeat_n(nb, m));
        nks.extend(std::iter::repeat_n(nk, m));
        let orders = ArxOrders {
            na,
            nb: nbs,
            nk: nks,
        };
        let f = arx(y[i], &inputs, &orders, ts).map_err(|e| match e {
            Error::InvalidArgument { name, reason } => Error::InvalidArgument {
                name,
                reason: format!("output {}: {reason}", i + 1),
            },
            other => other,
        })?;
        let mdl = &f.model;
        for k in 1..=na {
            a[k - 1][(i, i)] = mdl.a[k];
        }
        for (q, &j) in others.iter().enumerate() {
            // y_i + … = b_{y_j}(q) y_j + …  →  A_k[(i, j)] = −b_{y_j, k}
            for (k, v) in mdl.b[q].iter().enumerate().skip(1) {
                a[k - 1][(i, j)] = -v;
            }
        }
        for c in 0..m {
            for (k, v) in mdl.b[others.len() + c].iter().enumerate() {
                b[k][(i, c)] = *v;
            }
        }
        loss.push(f.loss);
        n_samples = n_samples.min(f.n_samples);
    }
    Ok(MimoArx {
        a,
        b,
        ts,
        loss,
        n_samples,
    })
}

impl MimoArx {
    /// Number of outputs $l$.
    pub fn noutputs(&self) -> usize {
        self.b.first().map_or(0, Mat::nrows)
    }

    /// Number of inputs $m$.
    pub fn ninputs(&self) -> usize {
        self.b.first().map_or(0, Mat::ncols)
    }

    /// One-step-ahead prediction $\hat y_t = -\sum_k A_k y_{t-k} + \sum_k B_k u_{t-k}$ from the
    /// measured signals (samples before $0$ taken as zero); one vector per output.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] for the wrong number of signals or lengths.
    pub fn predict(&self, y: &[&[f64]], u: &[&[f64]]) -> Result<Vec<Vec<f64>>> {
        let (l, m) = (self.noutputs(), self.ninputs());
        if y.len() != l || u.len() != m {
            return Err(Error::DimensionMismatch {
                context: "MimoArx::predict",
                expected: format!("{l} outputs and {m} inputs"),
                got: format!("{} outputs and {} inputs", y.len(), u.len()),
            });
        }
        let n = y.first().map_or(0, |x| x.len());
        if y.iter().chain(u).any(|x| x.len() != n) {
            return Err(Error::DimensionMismatch {
                context: "MimoArx::predict: signals",
                expected: format!("{n} samples each"),
                got: "signals of different lengths".into(),
            });
        }
        let mut out = vec![vec![0.0; n]; l];
        for t in 0..n {
            for i in 0..l {
                let mut v = 0.0;
                for (k, ak) in self.a.iter().enumerate() {
                    if t > k {
                        for j in 0..l {
                            v -= ak[(i, j)] * y[j][t - k - 1];
                        }
                    }
                }
                for (k, bk) in self.b.iter().enumerate() {
                    if t >= k {
                        for c in 0..m {
                            v += bk[(i, c)] * u[c][t - k];
                        }
                    }
                }
                out[i][t] = v;
            }
        }
        Ok(out)
    }

    /// The state-space realisation of the module docs (state: past outputs, then past inputs).
    ///
    /// # Errors
    /// The errors of [`StateSpace::discrete`].
    pub fn to_state_space(&self) -> Result<StateSpace> {
        let (l, m, na) = (self.noutputs(), self.ninputs(), self.a.len());
        let kk = self.b.len() - 1;
        let nx = l * na + m * kk;
        // output row block: y_t = C x_t + D u_t
        let c = Mat::<f64>::from_fn(l, nx, |i, s| {
            if s < l * na {
                -self.a[s / l][(i, s % l)]
            } else {
                let q = s - l * na;
                self.b[1 + q / m][(i, q % m)]
            }
        });
        let d = self.b[0].clone();
        let mut am = Mat::<f64>::zeros(nx, nx);
        let mut bm = Mat::<f64>::zeros(nx, m);
        if na > 0 {
            // newest output block = y_t
            for i in 0..l {
                for s in 0..nx {
                    am[(i, s)] = c[(i, s)];
                }
                for q in 0..m {
                    bm[(i, q)] = d[(i, q)];
                }
            }
            // older output blocks shift
            for s in l..l * na {
                am[(s, s - l)] = 1.0;
            }
        }
        if kk > 0 {
            let base = l * na;
            for q in 0..m {
                bm[(base + q, q)] = 1.0;
            }
            for s in base + m..nx {
                am[(s, s - m)] = 1.0;
            }
        }
        StateSpace::discrete(am, bm, c, d, self.ts)
    }
}

/// The front door on an [`crate::data::IoData`]: [`arx_mimo`] of the output channels on the
/// input channels (roles, in axis order) of a single-experiment record.
///
/// # Errors
/// [`Error::InvalidArgument`] for a record without output or input channels, with several
/// experiments (not joined yet) or a non-finite sample in a used channel; the errors of
/// [`arx_mimo`].
pub fn arx_mimo_iodata(
    data: &crate::data::IoData,
    na: usize,
    nb: usize,
    nk: usize,
    coupling: OutputCoupling,
) -> Result<MimoArx> {
    use crate::data::Role;
    data.require_single_experiment("arx_mimo")?;
    data.require_finite(&[Role::Output, Role::Input])?;
    let y = data.signals(Role::Output, 0)?;
    let u = data.signals(Role::Input, 0)?;
    arx_mimo(&y, &u, na, nb, nk, coupling, data.ts())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signal(n: usize, seed: u64) -> Vec<f64> {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
    }

    /// A 2 × 2 ARX with full A (na = 2, nb = 2, nk = 1), noise-free: the estimate is exact, and the
    /// state-space realisation simulates the difference equation (naive oracle) to rounding; the
    /// diagonal coupling of the same data cannot explain the cross terms.
    #[test]
    fn two_by_two_full_coupling_is_recovered_and_realised() {
        let n = 600;
        let (u1, u2) = (signal(n, 1), signal(n, 2));
        let a1 = [[-0.6, 0.2], [0.1, -0.5]];
        let a2 = [[0.1, 0.0], [-0.05, 0.08]];
        let b1 = [[1.0, 0.3], [0.0, 0.8]];
        let b2 = [[0.5, -0.2], [0.4, 0.1]];
        let (mut y1, mut y2) = (vec![0.0; n], vec![0.0; n]);
        for t in 0..n {
            let mut v = [0.0; 2];
            for i in 0..2 {
                for j in 0..2 {
                    let yj = if j == 0 { &y1 } else { &y2 };
                    if t >= 1 {
                        v[i] -= a1[i][j] * yj[t - 1];
                    }
                    if t >= 2 {
                        v[i] -= a2[i][j] * yj[t - 2];
                    }
                }
                for (c, uc) in [&u1, &u2].iter().enumerate() {
                    if t >= 1 {
                        v[i] += b1[i][c] * uc[t - 1];
                    }
                    if t >= 2 {
                        v[i] += b2[i][c] * uc[t - 2];
                    }
                }
            }
            y1[t] = v[0];
            y2[t] = v[1];
        }
        let m = arx_mimo(
            &[&y1, &y2],
            &[&u1, &u2],
            2,
            2,
            1,
            OutputCoupling::Full,
            1e-3,
        )
        .unwrap();
        for i in 0..2 {
            for j in 0..2 {
                assert!((m.a[0][(i, j)] - a1[i][j]).abs() < 1e-9);
                assert!((m.a[1][(i, j)] - a2[i][j]).abs() < 1e-9);
                assert!((m.b[1][(i, j)] - b1[i][j]).abs() < 1e-9);
                assert!((m.b[2][(i, j)] - b2[i][j]).abs() < 1e-9);
                assert_eq!(m.b[0][(i, j)], 0.0);
            }
        }
        let ss = m.to_state_space().unwrap();
        assert_eq!(ss.order(), 2 * 2 + 2 * 2);
        let um = Mat::from_fn(n, 2, |k, c| if c == 0 { u1[k] } else { u2[k] });
        let ys = ss.simulate(um.as_ref(), None).unwrap();
        for t in 0..n {
            assert!(
                (ys[(t, 0)] - y1[t]).abs() < 1e-9 * (1.0 + y1[t].abs()),
                "y1 at {t}"
            );
            assert!(
                (ys[(t, 1)] - y2[t]).abs() < 1e-9 * (1.0 + y2[t].abs()),
                "y2 at {t}"
            );
        }
        let p = m.predict(&[&y1, &y2], &[&u1, &u2]).unwrap();
        assert!((2..n).all(|t| (p[0][t] - y1[t]).abs() < 1e-9 && (p[1][t] - y2[t]).abs() < 1e-9));
        let diag = arx_mimo(
            &[&y1, &y2],
            &[&u1, &u2],
            2,
            2,
            1,
            OutputCoupling::Diagonal,
            1e-3,
        )
        .unwrap();
        assert_eq!(diag.a[0][(0, 1)], 0.0);
        assert!(diag.loss[0] > 1e-6, "{:?}", diag.loss);
    }

    /// A feed-through (nk = 0) and a FIR (na = 0) realise with D = B_0.
    #[test]
    fn feedthrough_and_fir() {
        let n = 300;
        let u = signal(n, 3);
        let y: Vec<f64> = (0..n)
            .map(|t| 0.7 * u[t] + if t >= 1 { -0.2 * u[t - 1] } else { 0.0 })
            .collect();
        let m = arx_mimo(&[&y], &[&u], 0, 2, 0, OutputCoupling::Full, 1.0).unwrap();
        let ss = m.to_state_space().unwrap();
        assert!((ss.d()[(0, 0)] - 0.7).abs() < 1e-12);
        let sim = ss.simulate_siso(&u, None).unwrap();
        assert!(sim.iter().zip(&y).all(|(a, b)| (a - b).abs() < 1e-12));
        assert!(arx_mimo(&[&y], &[&u], 1, 0, 1, OutputCoupling::Full, 1.0).is_err());
        assert!(arx_mimo(&[&y], &[&u[..10]], 1, 1, 1, OutputCoupling::Full, 1.0).is_err());
    }
}
