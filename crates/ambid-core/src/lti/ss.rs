//! State-space models, continuous or discrete.
//!
//! Continuous: $\dot x = A x + B u,\; y = C x + D u$. Discrete (sample time $T_s$):
//! $x_{k+1} = A x_k + B u_k,\; y_k = C x_k + D u_k$.
//!
//! The frequency response at $f$ Hz is $G = C (\lambda I - A)^{-1} B + D$ with
//! $\lambda = j 2\pi f$ (continuous) or $\lambda = e^{j 2\pi f T_s}$ (discrete).
//!
//! # Example
//! ```
//! use ambid_core::lti::StateSpace;
//! use faer::mat;
//! // first-order low-pass 1/(s/ω + 1), ω = 2π·100 rad/s
//! let w = 2.0 * std::f64::consts::PI * 100.0;
//! let g = StateSpace::continuous(mat![[-w]], mat![[w]], mat![[1.0]], mat![[0.0]]).unwrap();
//! let h = g.freq_response_siso(&[100.0]).unwrap();
//! assert!((h[0].norm() - 0.5f64.sqrt()).abs() < 1e-12);
//! let gd = g.c2d_zoh(1e-4).unwrap();
//! assert!((gd.a()[(0, 0)] - (-w * 1e-4).exp()).abs() < 1e-14);
//! ```

use crate::error::{Error, Result};
use crate::linalg;
use faer::{c64, Mat, MatRef};

/// A state-space model. `ts = None` is continuous time; `Some(ts)` discrete with sample time `ts` s.
#[derive(Debug, Clone, PartialEq)]
pub struct StateSpace {
    a: Mat<f64>,
    b: Mat<f64>,
    c: Mat<f64>,
    d: Mat<f64>,
    ts: Option<f64>,
}

fn check_mat(what: &'static str, m: MatRef<'_, f64>) -> Result<()> {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            if !m[(i, j)].is_finite() {
                return Err(Error::NonFinite {
                    what,
                    index: i + j * m.nrows(),
                });
            }
        }
    }
    Ok(())
}

impl StateSpace {
    /// Builds a model after checking dimensions, finiteness and the sample time.
    pub fn new(
        a: Mat<f64>,
        b: Mat<f64>,
        c: Mat<f64>,
        d: Mat<f64>,
        ts: Option<f64>,
    ) -> Result<Self> {
        let n = a.nrows();
        let dims = |ctx: &'static str, e: (usize, usize), g: (usize, usize)| {
            if e != g {
                Err(Error::DimensionMismatch {
                    context: ctx,
                    expected: format!("{}×{}", e.0, e.1),
                    got: format!("{}×{}", g.0, g.1),
                })
            } else {
                Ok(())
            }
        };
        dims("state-space A", (n, n), (a.nrows(), a.ncols()))?;
        dims("state-space B", (n, b.ncols()), (b.nrows(), b.ncols()))?;
        dims("state-space C", (c.nrows(), n), (c.nrows(), c.ncols()))?;
        dims(
            "state-space D",
            (c.nrows(), b.ncols()),
            (d.nrows(), d.ncols()),
        )?;
        check_mat("A", a.as_ref())?;
        check_mat("B", b.as_ref())?;
        check_mat("C", c.as_ref())?;
        check_mat("D", d.as_ref())?;
        if let Some(t) = ts {
            if !(t.is_finite() && t > 0.0) {
                return Err(Error::invalid(
                    "ts",
                    format!("sample time must be positive and finite, got {t}"),
                ));
            }
        }
        Ok(Self { a, b, c, d, ts })
    }

    /// Continuous-time model.
    pub fn continuous(a: Mat<f64>, b: Mat<f64>, c: Mat<f64>, d: Mat<f64>) -> Result<Self> {
        Self::new(a, b, c, d, None)
    }

    /// Discrete-time model with sample time `ts` seconds.
    pub fn discrete(a: Mat<f64>, b: Mat<f64>, c: Mat<f64>, d: Mat<f64>, ts: f64) -> Result<Self> {
        Self::new(a, b, c, d, Some(ts))
    }

    /// State matrix.
    pub fn a(&self) -> MatRef<'_, f64> {
        self.a.as_ref()
    }
    /// Input matrix.
    pub fn b(&self) -> MatRef<'_, f64> {
        self.b.as_ref()
    }
    /// Output matrix.
    pub fn c(&self) -> MatRef<'_, f64> {
        self.c.as_ref()
    }
    /// Feed-through matrix.
    pub fn d(&self) -> MatRef<'_, f64> {
        self.d.as_ref()
    }
    /// Sample time in seconds, `None` for continuous time.
    pub fn ts(&self) -> Option<f64> {
        self.ts
    }
    /// Number of states.
    pub fn order(&self) -> usize {
        self.a.nrows()
    }
    /// Number of inputs.
    pub fn ninputs(&self) -> usize {
        self.b.ncols()
    }
    /// Number of outputs.
    pub fn noutputs(&self) -> usize {
        self.c.nrows()
    }

    fn lambda(&self, f_hz: f64) -> c64 {
        let w = 2.0 * std::f64::consts::PI * f_hz;
        match self.ts {
            None => c64::new(0.0, w),
            Some(t) => c64::from_polar(1.0, w * t),
        }
    }

    /// Frequency response at each frequency (Hz): one `noutputs × ninputs` complex matrix each.
    ///
    /// Errors if a frequency is not finite or sits on a pole.
    pub fn freq_response(&self, f_hz: &[f64]) -> Result<Vec<Mat<c64>>> {
        crate::error::check_finite("f_hz", f_hz)?;
        let n = self.order();
        let bc = Mat::from_fn(n, self.ninputs(), |i, j| c64::new(self.b[(i, j)], 0.0));
        let cc = Mat::from_fn(self.noutputs(), n, |i, j| c64::new(self.c[(i, j)], 0.0));
        let mut out = Vec::with_capacity(f_hz.len());
        for &f in f_hz {
            let lam = self.lambda(f);
            let m = Mat::from_fn(n, n, |i, j| {
                let d = if i == j { lam } else { c64::new(0.0, 0.0) };
                d - c64::new(self.a[(i, j)], 0.0)
            });
            let x = if n > 0 {
                linalg::solve_c64(m.as_ref(), bc.as_ref()).map_err(|_| {
                    Error::numerical(
                        "freq_response",
                        format!("frequency {f} Hz coincides with a pole of the model"),
                    )
                })?
            } else {
                Mat::zeros(0, self.ninputs())
            };
            let mut g = &cc * &x;
            for i in 0..g.nrows() {
                for j in 0..g.ncols() {
                    g[(i, j)] += c64::new(self.d[(i, j)], 0.0);
                }
            }
            out.push(g);
        }
        Ok(out)
    }

    /// Frequency response of a SISO model at each frequency (Hz).
    pub fn freq_response_siso(&self, f_hz: &[f64]) -> Result<Vec<c64>> {
        self.require_siso("freq_response_siso")?;
        Ok(self
            .freq_response(f_hz)?
            .into_iter()
            .map(|g| g[(0, 0)])
            .collect())
    }

    pub(crate) fn require_siso(&self, context: &'static str) -> Result<()> {
        if self.ninputs() != 1 || self.noutputs() != 1 {
            return Err(Error::DimensionMismatch {
                context,
                expected: "a single-input single-output model".into(),
                got: format!("{} outputs × {} inputs", self.noutputs(), self.ninputs()),
            });
        }
        Ok(())
    }

    /// Poles: eigenvalues of $A$ (in $s$ for continuous, in $z$ for discrete models).
    pub fn poles(&self) -> Result<Vec<c64>> {
        linalg::eigenvalues(self.a.as_ref())
    }

    /// Asymptotic stability: all poles in the open left half plane (continuous) or strictly inside
    /// the unit circle (discrete).
    pub fn is_stable(&self) -> Result<bool> {
        let p = self.poles()?;
        Ok(match self.ts {
            None => p.iter().all(|z| z.re < 0.0),
            Some(_) => p.iter().all(|z| z.norm() < 1.0),
        })
    }

    /// Zero-order-hold discretisation with sample time `ts`:
    /// $\exp\left(\begin{bmatrix} A & B \\ 0 & 0\end{bmatrix} T_s\right) =
    /// \begin{bmatrix} A_d & B_d \\ 0 & I\end{bmatrix}$, $C_d = C$, $D_d = D$.
    pub fn c2d_zoh(&self, ts: f64) -> Result<StateSpace> {
        if self.ts.is_some() {
            return Err(Error::TimeDomain(
                "c2d needs a continuous-time model; this one is already discrete".into(),
            ));
        }
        if !(ts.is_finite() && ts > 0.0) {
            return Err(Error::invalid(
                "ts",
                format!("sample time must be positive and finite, got {ts}"),
            ));
        }
        let n = self.order();
        let m = self.ninputs();
        let big = Mat::from_fn(n + m, n + m, |i, j| {
            if i < n && j < n {
                self.a[(i, j)] * ts
            } else if i < n {
                self.b[(i, j - n)] * ts
            } else {
                0.0
            }
        });
        let e = linalg::expm(big.as_ref())?;
        let ad = Mat::from_fn(n, n, |i, j| e[(i, j)]);
        let bd = Mat::from_fn(n, m, |i, j| e[(i, n + j)]);
        StateSpace::discrete(ad, bd, self.c.clone(), self.d.clone(), ts)
    }

    /// Simulates a discrete SISO model from initial state `x0` (zeros if `None`).
    pub fn simulate_siso(&self, u: &[f64], x0: Option<&[f64]>) -> Result<Vec<f64>> {
        self.require_siso("simulate_siso")?;
        if self.ts.is_none() {
            return Err(Error::TimeDomain(
                "simulation needs a discrete-time model; discretise it with c2d first".into(),
            ));
        }
        crate::error::check_finite("u", u)?;
        let n = self.order();
        let mut x = match x0 {
            Some(x0) if x0.len() != n => {
                return Err(Error::DimensionMismatch {
                    context: "simulate_siso initial state",
                    expected: n.to_string(),
                    got: x0.len().to_string(),
                })
            }
            Some(x0) => x0.to_vec(),
            None => vec![0.0; n],
        };
        let mut xn = vec![0.0; n];
        let mut y = Vec::with_capacity(u.len());
        for &uk in u {
            let mut yk = self.d[(0, 0)] * uk;
            for i in 0..n {
                yk += self.c[(0, i)] * x[i];
            }
            y.push(yk);
            for i in 0..n {
                let mut s = self.b[(i, 0)] * uk;
                for j in 0..n {
                    s += self.a[(i, j)] * x[j];
                }
                xn[i] = s;
            }
            std::mem::swap(&mut x, &mut xn);
        }
        Ok(y)
    }
}
