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

/// Largest controllable and observable part whose zeros [`StateSpace::zeros`] computes: the
/// QZ iteration on the $(n+m) \times (n+m)$ Rosenbrock pencil costs $O(n^3)$ with a large
/// constant and can stall on highly structured pencils (a 400-state pencil with one
/// controllable mode ran for more than 590 s before the reduction existed). 300 states take
/// about a second on one core.
pub const ZEROS_MAX_ORDER: usize = 300;

/// Orthonormal basis (as columns) of $\operatorname{span}\{B, AB, A^2B, \dots\}$: Arnoldi with
/// classical Gram–Schmidt applied twice, candidates processed first-in first-out (the columns
/// of $B$, then $A$ times each accepted vector). See [`StateSpace::minimal_part`] for the
/// tolerances.
fn krylov_basis(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Mat<f64> {
    let n = a.nrows();
    let fro = |m: MatRef<'_, f64>| m.norm_l2();
    let tol_a = 10.0 * n as f64 * f64::EPSILON * fro(a);
    let tol_b = 10.0 * n as f64 * f64::EPSILON * fro(b);
    let mut basis: Vec<Vec<f64>> = Vec::new();
    let mut queue: std::collections::VecDeque<(Vec<f64>, f64)> = (0..b.ncols())
        .map(|j| ((0..n).map(|i| b[(i, j)]).collect(), tol_b))
        .collect();
    while let Some((mut w, tol)) = queue.pop_front() {
        if basis.len() == n {
            break;
        }
        for _ in 0..2 {
            for q in &basis {
                let h: f64 = q.iter().zip(&w).map(|(x, y)| x * y).sum();
                for (wi, qi) in w.iter_mut().zip(q) {
                    *wi -= h * qi;
                }
            }
        }
        let norm = w.iter().map(|x| x * x).sum::<f64>().sqrt();
        if !norm.is_finite() || norm <= tol {
            continue;
        }
        for x in w.iter_mut() {
            *x /= norm;
        }
        let aw: Vec<f64> = (0..n)
            .map(|i| (0..n).map(|k| a[(i, k)] * w[k]).sum())
            .collect();
        queue.push_back((aw, tol_a));
        basis.push(w);
    }
    Mat::from_fn(n, basis.len(), |i, j| basis[j][i])
}

/// An orthonormal basis of the orthogonal complement of the orthonormal columns `v` ($n \times r$,
/// result $n \times (n - r)$): the last $n - r$ columns of the Householder $Q$ of `v`.
fn complement(v: MatRef<'_, f64>) -> Mat<f64> {
    let (n, r) = (v.nrows(), v.ncols());
    let mut w = v.to_owned();
    // Householder vectors (unit norm, zero above the diagonal); a zero vector is no reflection
    let mut hs: Vec<Vec<f64>> = Vec::with_capacity(r);
    for k in 0..r {
        let x: Vec<f64> = (k..n).map(|i| w[(i, k)]).collect();
        let norm = x.iter().map(|t| t * t).sum::<f64>().sqrt();
        let mut h = vec![0.0; n];
        if norm > 0.0 {
            let alpha = if x[0] >= 0.0 { -norm } else { norm };
            for (i, xi) in x.iter().enumerate() {
                h[k + i] = *xi;
            }
            h[k] -= alpha;
            let hn = h.iter().map(|t| t * t).sum::<f64>().sqrt();
            if hn > 0.0 {
                for t in h.iter_mut() {
                    *t /= hn;
                }
            }
        }
        // apply (I - 2 h hᵀ) to the remaining columns
        for j in k..r {
            let d: f64 = (k..n).map(|i| h[i] * w[(i, j)]).sum();
            for i in k..n {
                w[(i, j)] -= 2.0 * d * h[i];
            }
        }
        hs.push(h);
    }
    // Q e_j for j = r..n: apply the reflectors in reverse order to the unit vectors
    let mut q = Mat::from_fn(n, n - r, |i, j| if i == r + j { 1.0 } else { 0.0 });
    for h in hs.iter().rev() {
        for j in 0..n - r {
            let d: f64 = (0..n).map(|i| h[i] * q[(i, j)]).sum();
            if d != 0.0 {
                for i in 0..n {
                    q[(i, j)] -= 2.0 * d * h[i];
                }
            }
        }
    }
    q
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

    /// The SISO channel from input $j$ to output $i$: $(A, B_{:,j}, C_{i,:}, D_{ij})$, with all
    /// the model's states (so its poles are the model's).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an index outside $n_y \times n_u$.
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::StateSpace;
    /// use faer::mat;
    /// let m = StateSpace::discrete(mat![[0.5]], mat![[1.0, 2.0]], mat![[1.0], [3.0]],
    ///     mat![[0.0, 0.1], [0.0, 0.0]], 1e-3).unwrap();
    /// let e = m.entry(0, 1).unwrap();
    /// // 2 / (z - 0.5) + 0.1 at z = 1
    /// assert!((e.freq_response_siso(&[0.0]).unwrap()[0].re - 4.1).abs() < 1e-12);
    /// ```
    pub fn entry(&self, i: usize, j: usize) -> Result<StateSpace> {
        if i >= self.noutputs() || j >= self.ninputs() {
            return Err(Error::invalid(
                "entry",
                format!(
                    "entry ({i}, {j}) is outside the {}×{} model",
                    self.noutputs(),
                    self.ninputs()
                ),
            ));
        }
        let n = self.order();
        StateSpace::new(
            self.a.clone(),
            Mat::from_fn(n, 1, |r, _| self.b[(r, j)]),
            Mat::from_fn(1, n, |_, c| self.c[(i, c)]),
            Mat::from_fn(1, 1, |_, _| self.d[(i, j)]),
            self.ts,
        )
    }

    fn lambda(&self, f_hz: f64) -> c64 {
        let w = 2.0 * std::f64::consts::PI * f_hz;
        match self.ts {
            None => c64::new(0.0, w),
            Some(t) => c64::from_polar(1.0, w * t),
        }
    }

    /// Frequency response at each frequency (Hz): one `noutputs × ninputs` complex matrix each,
    /// $G(\lambda) = C(\lambda I - A)^{-1}B + D$ with $\lambda = j\omega$ or $e^{j\omega T_s}$.
    ///
    /// $A$ is balanced (an exact power-of-2 diagonal scaling) and reduced once to upper
    /// Hessenberg form $H = Q^{\mathsf T}AQ$ by Householder reflections (Laub 1981). Each
    /// frequency then factors $\lambda I - H$ by Gaussian elimination with partial pivoting in
    /// $O(n^2)$ instead of $O(n^3)$, solves for every input, and refines the solution once with
    /// the residual $b - (\lambda I - A)x$ computed with the balanced $A$ itself: without it the
    /// rounding of the reduction costs up to two digits on badly scaled models (the twin's
    /// closed loop: 4e-11 instead of 5e-14), near poles and where an output is a small
    /// difference of large terms.
    ///
    /// Errors if a frequency is not finite or sits on a pole.
    pub fn freq_response(&self, f_hz: &[f64]) -> Result<Vec<Mat<c64>>> {
        crate::error::check_finite("f_hz", f_hz)?;
        let (n, m, p) = (self.order(), self.ninputs(), self.noutputs());
        let hess = Hessenberg::of(self);
        let zero = c64::new(0.0, 0.0);
        let mut lu = HessLu::new(n);
        let (mut xh, mut x, mut r) = (vec![zero; n], vec![zero; n], vec![zero; n]);
        let mut xs = vec![zero; n * m];
        let mut out = Vec::with_capacity(f_hz.len());
        for &f in f_hz {
            let lam = self.lambda(f);
            let pole = || {
                Error::numerical(
                    "freq_response",
                    format!("frequency {f} Hz coincides with a pole of the model"),
                )
            };
            lu.factor(&hess.h, lam).map_err(|_| pole())?;
            for j in 0..m {
                // x_h = (λI − H)⁻¹ Qᵀ b, so that x = Q x_h and C x = (CQ) x_h
                for (i, v) in xh.iter_mut().enumerate() {
                    *v = c64::new(hess.qtb[i * m + j], 0.0);
                }
                lu.solve(&mut xh).map_err(|_| pole())?;
                // one refinement step with the residual b − (λI − A) Q x_h in the balanced
                // coordinates
                hess.rotate(&xh, &mut x);
                for (i, ri) in r.iter_mut().enumerate() {
                    let arow = &hess.a[i * n..(i + 1) * n];
                    let ax: c64 = x.iter().zip(arow).map(|(xk, a)| xk * a).sum();
                    *ri = c64::new(hess.b[i * m + j], 0.0) - lam * x[i] + ax;
                }
                hess.rotate_t(&r, &mut x);
                lu.solve(&mut x).map_err(|_| pole())?;
                for (a, b) in xh.iter_mut().zip(&x) {
                    *a += b;
                }
                for i in 0..n {
                    let z = xh[i];
                    if !(z.re.is_finite() && z.im.is_finite()) {
                        return Err(pole());
                    }
                    xs[i * m + j] = z;
                }
            }
            let g = Mat::from_fn(p, m, |i, j| {
                let mut v = c64::new(self.d[(i, j)], 0.0);
                for k in 0..n {
                    v += xs[k * m + j] * hess.cq[i * n + k];
                }
                v
            });
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
        let u = faer::MatRef::from_column_major_slice(u, u.len(), 1);
        let y = self.simulate(u, x0)?;
        Ok(y.col_as_slice(0).to_vec())
    }

    /// The initial state that best explains a measured SISO response (MATLAB `compare`'s
    /// default, `InitialCondition = 'e'`): the least-squares solution of
    ///
    /// $$ y_k - y^{(0)}_k = C A^k x_0, \qquad k = 0, \dots, N-1, $$
    ///
    /// where $y^{(0)}$ is the response to `u` from rest. Meant for stable models (for an
    /// unstable one the rows $C A^k$ grow without bound and the estimate is ill-conditioned).
    ///
    /// # Errors
    /// A non-SISO or continuous model, `u` and `y` of different lengths or shorter than the order,
    /// non-finite samples.
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::StateSpace;
    /// use faer::mat;
    /// let m = StateSpace::discrete(mat![[0.9]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 1.0).unwrap();
    /// let u = vec![0.0; 20];
    /// let y = m.simulate_siso(&u, Some(&[2.0])).unwrap();
    /// let x0 = m.estimate_initial_state(&u, &y).unwrap();
    /// assert!((x0[0] - 2.0).abs() < 1e-12);
    /// ```
    pub fn estimate_initial_state(&self, u: &[f64], y: &[f64]) -> Result<Vec<f64>> {
        self.require_siso("estimate_initial_state")?;
        let n = self.order();
        if u.len() != y.len() {
            return Err(Error::DimensionMismatch {
                context: "estimate_initial_state: u and y",
                expected: format!("{} samples", u.len()),
                got: format!("{} samples", y.len()),
            });
        }
        if y.len() < n.max(1) {
            return Err(Error::invalid(
                "y",
                format!("{} samples cannot determine {n} initial states", y.len()),
            ));
        }
        crate::error::check_finite("y", y)?;
        if n == 0 {
            return Ok(Vec::new());
        }
        let y0 = self.simulate_siso(u, None)?;
        let a = self.a();
        let mut obs = Mat::<f64>::zeros(y.len(), n);
        let mut row: Vec<f64> = (0..n).map(|j| self.c()[(0, j)]).collect();
        let mut next = vec![0.0; n];
        for k in 0..y.len() {
            for j in 0..n {
                obs[(k, j)] = row[j];
            }
            for (j, v) in next.iter_mut().enumerate() {
                *v = (0..n).map(|i| row[i] * a[(i, j)]).sum();
            }
            std::mem::swap(&mut row, &mut next);
        }
        let r = Mat::from_fn(y.len(), 1, |k, _| y[k] - y0[k]);
        let x0 = crate::linalg::lstsq(obs.as_ref(), r.as_ref())?;
        Ok((0..n).map(|i| x0[(i, 0)]).collect())
    }

    /// Simulates a discrete model from initial state `x0` (zeros if `None`): `u` is `N × m`
    /// (one row per sample), the result `N × p`.
    ///
    /// $$ y_k = C x_k + D u_k, \qquad x_{k+1} = A x_k + B u_k. $$
    pub fn simulate(&self, u: MatRef<'_, f64>, x0: Option<&[f64]>) -> Result<Mat<f64>> {
        if self.ts.is_none() {
            return Err(Error::TimeDomain(
                "simulation needs a discrete-time model; discretise it with c2d first".into(),
            ));
        }
        if u.ncols() != self.ninputs() {
            return Err(Error::DimensionMismatch {
                context: "simulate input columns",
                expected: self.ninputs().to_string(),
                got: u.ncols().to_string(),
            });
        }
        check_mat("u", u)?;
        let n = self.order();
        let mut x: Vec<f64> = match x0 {
            Some(x0) if x0.len() != n => {
                return Err(Error::DimensionMismatch {
                    context: "simulate initial state",
                    expected: n.to_string(),
                    got: x0.len().to_string(),
                })
            }
            Some(x0) => {
                crate::error::check_finite("x0", x0)?;
                x0.to_vec()
            }
            None => vec![0.0; n],
        };
        let (p, m) = (self.noutputs(), self.ninputs());
        // row-major copies of the matrices: the per-sample products run over contiguous rows
        // and allocate nothing
        let rows = |m: &Mat<f64>| crate::linalg::row_major(m.as_ref());
        let (ar, br, cr, dr) = (rows(&self.a), rows(&self.b), rows(&self.c), rows(&self.d));
        let dot = |row: &[f64], v: &[f64]| -> f64 { row.iter().zip(v).map(|(a, b)| a * b).sum() };
        let mut y = Mat::zeros(u.nrows(), p);
        let mut uk = vec![0.0; m];
        let mut xn = vec![0.0; n];
        for k in 0..u.nrows() {
            for (i, v) in uk.iter_mut().enumerate() {
                *v = u[(k, i)];
            }
            for i in 0..p {
                y[(k, i)] = dot(&cr[i * n..(i + 1) * n], &x) + dot(&dr[i * m..(i + 1) * m], &uk);
            }
            for (i, v) in xn.iter_mut().enumerate() {
                *v = dot(&ar[i * n..(i + 1) * n], &x) + dot(&br[i * m..(i + 1) * m], &uk);
            }
            std::mem::swap(&mut x, &mut xn);
        }
        Ok(y)
    }

    /// Impulse response (Markov parameters) of a discrete model: $h_0 = D$,
    /// $h_k = C A^{k-1} B$ for $k = 1, \dots, n-1$; one `p × m` matrix per sample.
    pub fn impulse_response(&self, n: usize) -> Result<Vec<Mat<f64>>> {
        if self.ts.is_none() {
            return Err(Error::TimeDomain(
                "the impulse response is computed for discrete-time models; discretise first"
                    .into(),
            ));
        }
        let mut out = Vec::with_capacity(n);
        let mut ab = self.b.clone();
        for k in 0..n {
            if k == 0 {
                out.push(self.d.clone());
            } else {
                out.push(&self.c * &ab);
                ab = &self.a * &ab;
            }
        }
        Ok(out)
    }

    /// Impulse response of a discrete SISO model, `n` samples.
    pub fn impulse_response_siso(&self, n: usize) -> Result<Vec<f64>> {
        self.require_siso("impulse_response_siso")?;
        Ok(self
            .impulse_response(n)?
            .into_iter()
            .map(|h| h[(0, 0)])
            .collect())
    }

    /// Invariant zeros of a square model ($p = m$): the finite generalized eigenvalues of the
    /// Rosenbrock system pencil
    /// $$ \begin{bmatrix} A & B \\ C & D \end{bmatrix} - \lambda
    ///    \begin{bmatrix} I & 0 \\ 0 & 0 \end{bmatrix}, $$
    /// as `control.zeros` / the scipy pencil give them. For a SISO model these are the roots of
    /// the transfer-function numerator before any cancellation.
    ///
    /// They are computed without running QZ on the whole pencil: in the orthogonal Kalman
    /// decomposition of [`minimal_part`](Self::minimal_part) the pencil is block triangular,
    /// so its finite eigenvalues are those of the pencil of the controllable and observable
    /// part (the transmission zeros) together with the eigenvalues of the uncontrollable part
    /// and of the unobservable part of the controllable one (the decoupling zeros, by a plain
    /// eigenvalue routine). Infinite eigenvalues ($|\beta| \le 10^{-9} |\alpha|$, relative to
    /// the pencil scale) are dropped. A model that is already minimal gives bit-for-bit the
    /// full pencil's result. A degenerate pencil (e.g. an input that reaches no state and no
    /// output) has no well defined zeros; the result is then meaningless.
    ///
    /// Bounded: the reduction and the eigenvalues are $O(n^3)$; the QZ step is refused with an
    /// [`Error::InvalidArgument`] naming [`ZEROS_MAX_ORDER`] when the controllable and observable
    /// part has more states (QZ on large, highly structured pencils ran for minutes).
    ///
    /// ```
    /// use ambid_core::lti::StateSpace;
    /// use faer::{mat, Mat};
    /// // 400 identical modes seen through one input and one output: one controllable mode,
    /// // G(z) = 400/(z - 0.5); the other 399 modes are decoupling zeros at 0.5
    /// let n = 400;
    /// let g = StateSpace::discrete(
    ///     Mat::from_fn(n, n, |i, j| if i == j { 0.5 } else { 0.0 }),
    ///     Mat::from_fn(n, 1, |_, _| 1.0),
    ///     Mat::from_fn(1, n, |_, _| 1.0),
    ///     mat![[0.0]],
    ///     1e-3,
    /// )
    /// .unwrap();
    /// let m = g.minimal_part().unwrap();
    /// assert_eq!(m.order(), 1);
    /// assert!(m.zeros().unwrap().is_empty()); // no transmission zero
    /// let z = g.zeros().unwrap();
    /// assert_eq!(z.len(), 399);
    /// assert!(z.iter().all(|z| (z.re - 0.5).abs() < 1e-12 && z.im.abs() < 1e-12));
    /// ```
    pub fn zeros(&self) -> Result<Vec<c64>> {
        let (m, p) = (self.ninputs(), self.noutputs());
        if m != p {
            return Err(Error::DimensionMismatch {
                context: "zeros (square systems only)",
                expected: format!("as many outputs as inputs ({m})"),
                got: p.to_string(),
            });
        }
        let (r, decoupling) = self.kalman_split()?;
        let n = r.order();
        if n > ZEROS_MAX_ORDER {
            return Err(Error::invalid(
                "model order",
                format!(
                    "the zeros of a model whose controllable and observable part has {n} states \
                     are not computed (limit ZEROS_MAX_ORDER = {ZEROS_MAX_ORDER} states): reduce \
                     the model first (a lower order or balanced truncation)"
                ),
            ));
        }
        let mut z = r.pencil_zeros()?;
        z.extend(decoupling);
        Ok(z)
    }

    /// The finite eigenvalues of the full Rosenbrock pencil (no reduction).
    fn pencil_zeros(&self) -> Result<Vec<c64>> {
        let (n, m) = (self.order(), self.ninputs());
        let big = Mat::from_fn(n + m, n + m, |i, j| match (i < n, j < n) {
            (true, true) => self.a[(i, j)],
            (true, false) => self.b[(i, j - n)],
            (false, true) => self.c[(i - n, j)],
            (false, false) => self.d[(i - n, j - n)],
        });
        let e = Mat::from_fn(n + m, n + m, |i, j| if i == j && i < n { 1.0 } else { 0.0 });
        let pairs = linalg::generalized_eigenvalues(big.as_ref(), e.as_ref())?;
        Ok(pairs
            .into_iter()
            .filter(|(al, be)| be.norm() > 1e-9 * al.norm() && be.norm() > 0.0)
            .map(|(al, be)| al / be)
            .collect())
    }

    /// The controllable and observable part of the model (a Kalman decomposition by
    /// orthogonal projections): $V$ is an orthonormal basis of the controllable subspace
    /// $\operatorname{span}\{B, AB, A^2B, \dots\}$ and $W$ one of the observable subspace of
    /// $(V^{\mathsf T}AV, C V)$; the result is
    /// $(W^{\mathsf T}V^{\mathsf T}AVW,\; W^{\mathsf T}V^{\mathsf T}B,\; CVW,\; D)$, with the same
    /// transfer function. The bases are built by Arnoldi with Gram–Schmidt applied twice; a
    /// new direction is kept when its component orthogonal to the basis exceeds
    /// $10\,n\,\varepsilon\,\lVert A\rVert_F$ (for $A$ times a basis vector) or
    /// $10\,n\,\varepsilon\,\lVert B\rVert_F$ (for a column of $B$): only exact (rounding-level)
    /// uncontrollable or unobservable modes are removed. A model that is already minimal is
    /// returned unchanged. $O(n^3)$.
    pub fn minimal_part(&self) -> Result<StateSpace> {
        Ok(self.kalman_split()?.0)
    }

    /// [`minimal_part`](Self::minimal_part) and the eigenvalues of the parts it removed (the
    /// uncontrollable part $V_\perp^{\mathsf T} A V_\perp$, then the unobservable part of the
    /// controllable one).
    fn kalman_split(&self) -> Result<(StateSpace, Vec<c64>)> {
        let n = self.order();
        let mut removed = Vec::new();
        let v = krylov_basis(self.a.as_ref(), self.b.as_ref());
        let (a1, b1, c1) = if v.ncols() == n {
            (self.a.clone(), self.b.clone(), self.c.clone())
        } else {
            let vc = complement(v.as_ref());
            let au = vc.transpose() * (&self.a * &vc);
            removed.extend(linalg::eigenvalues(au.as_ref())?);
            let av = &self.a * &v;
            (v.transpose() * &av, v.transpose() * &self.b, &self.c * &v)
        };
        let w = krylov_basis(a1.transpose(), c1.transpose());
        if v.ncols() == n && w.ncols() == n {
            return Ok((self.clone(), removed));
        }
        let (a2, b2, c2) = if w.ncols() == a1.nrows() {
            (a1, b1, c1)
        } else {
            let wc = complement(w.as_ref());
            let auo = wc.transpose() * (&a1 * &wc);
            removed.extend(linalg::eigenvalues(auo.as_ref())?);
            let aw = &a1 * &w;
            (w.transpose() * &aw, w.transpose() * &b1, &c1 * &w)
        };
        Ok((
            StateSpace::new(a2, b2, c2, self.d.clone(), self.ts)?,
            removed,
        ))
    }

    fn require_continuous(&self, context: &str) -> Result<()> {
        if self.ts.is_some() {
            return Err(Error::TimeDomain(format!(
                "{context} needs a continuous-time model; this one is already discrete"
            )));
        }
        Ok(())
    }

    fn require_discrete(&self, context: &str) -> Result<f64> {
        self.ts.ok_or_else(|| {
            Error::TimeDomain(format!(
                "{context} needs a discrete-time model; this one is continuous"
            ))
        })
    }

    /// Tustin (bilinear) discretisation with sample time `ts`, optionally prewarped so that the
    /// frequency response matches exactly at `prewarp_hz`.
    ///
    /// With $T = T_s$, or $T = 2\tan(\omega_p T_s / 2)/\omega_p$ when prewarping at
    /// $\omega_p = 2\pi f_p$ (the substitution $s = \frac{2}{T}\frac{z-1}{z+1}$), and
    /// $M = I - A T/2$:
    /// $$ A_d = M^{-1}(I + A T/2),\quad B_d = M^{-1} B T,\quad C_d = C M^{-1},\quad
    ///    D_d = D + C B_d / 2, $$
    /// the realisation of `scipy.signal.cont2discrete(method="bilinear")` (python-control for the
    /// prewarped form). Errors if $M$ is singular (a pole at $s = 2/T$) or if
    /// $f_p \ge 1/(2 T_s)$.
    pub fn c2d_tustin(&self, ts: f64, prewarp_hz: Option<f64>) -> Result<StateSpace> {
        self.require_continuous("c2d_tustin")?;
        check_ts(ts)?;
        let t = warped_period(ts, prewarp_hz)?;
        let n = self.order();
        let id = Mat::<f64>::identity(n, n);
        let m = Mat::from_fn(n, n, |i, j| id[(i, j)] - 0.5 * t * self.a[(i, j)]);
        let p = Mat::from_fn(n, n, |i, j| id[(i, j)] + 0.5 * t * self.a[(i, j)]);
        let sing = |_| Error::numerical("c2d_tustin", "I - A T/2 is singular (a pole at s = 2/T)");
        let ad = linalg::solve(m.as_ref(), p.as_ref()).map_err(sing)?;
        let bt = Mat::from_fn(n, self.ninputs(), |i, j| self.b[(i, j)] * t);
        let bd = linalg::solve(m.as_ref(), bt.as_ref()).map_err(sing)?;
        let ct = linalg::solve(m.transpose(), self.c.transpose()).map_err(sing)?;
        let cd = ct.transpose().to_owned();
        let cb = &self.c * &bd;
        let dd = Mat::from_fn(self.noutputs(), self.ninputs(), |i, j| {
            self.d[(i, j)] + 0.5 * cb[(i, j)]
        });
        StateSpace::discrete(ad, bd, cd, dd, ts)
    }

    /// Inverse of [`c2d_tustin`](Self::c2d_tustin) (same `prewarp_hz`): with $T$ as there,
    /// $$ A = \tfrac{2}{T}(A_d - I)(A_d + I)^{-1},\quad B = \tfrac{2}{T}(A_d + I)^{-1} B_d,\quad
    ///    C = 2 C_d (A_d + I)^{-1},\quad D = D_d - C_d (A_d + I)^{-1} B_d. $$
    /// Errors if $A_d$ has an eigenvalue at $z = -1$ (no continuous equivalent).
    pub fn d2c_tustin(&self, prewarp_hz: Option<f64>) -> Result<StateSpace> {
        let ts = self.require_discrete("d2c_tustin")?;
        let t = warped_period(ts, prewarp_hz)?;
        let n = self.order();
        let id = Mat::<f64>::identity(n, n);
        let ap = &self.a + &id;
        let am = &self.a - &id;
        let sing = |_| {
            Error::numerical(
                "d2c_tustin",
                "A_d + I is singular: the model has a pole at z = -1, which has no continuous-time equivalent",
            )
        };
        // (A_d - I)(A_d + I)^{-1} = ((A_d + I)^{-T} (A_d - I)^T)^T
        let a = linalg::solve(ap.transpose(), am.transpose())
            .map_err(sing)?
            .transpose()
            .to_owned();
        let a = Mat::from_fn(n, n, |i, j| a[(i, j)] * 2.0 / t);
        let x = linalg::solve(ap.as_ref(), self.b.as_ref()).map_err(sing)?;
        let b = Mat::from_fn(n, self.ninputs(), |i, j| x[(i, j)] * 2.0 / t);
        let ct = linalg::solve(ap.transpose(), self.c.transpose()).map_err(sing)?;
        let c = Mat::from_fn(self.noutputs(), n, |i, j| 2.0 * ct[(j, i)]);
        let cx = &self.c * &x;
        let d = &self.d - &cx;
        StateSpace::continuous(a, b, c, d)
    }

    /// Inverse of [`c2d_zoh`](Self::c2d_zoh) by the principal matrix logarithm
    /// ([`linalg::logm`]):
    /// $$ \begin{bmatrix} A & B \\ 0 & 0\end{bmatrix} = \frac{1}{T_s}
    ///    \log \begin{bmatrix} A_d & B_d \\ 0 & I\end{bmatrix}. $$
    /// Well defined when $A_d$ has no eigenvalue on the closed negative real axis; otherwise
    /// [`Error::InvalidArgument`]. The result is the continuous model whose poles have
    /// $|\operatorname{Im} s| < \pi / T_s$ (below the Nyquist frequency).
    pub fn d2c_zoh(&self) -> Result<StateSpace> {
        let ts = self.require_discrete("d2c_zoh")?;
        let (n, m) = (self.order(), self.ninputs());
        for l in self.poles()? {
            if l.re <= 0.0 && l.im.abs() <= 1e-12 * l.norm().max(1.0) {
                return Err(Error::invalid(
                    "model",
                    format!(
                        "d2c_zoh: the pole {:.6e}{:+.3e}i lies on the non-positive real axis, so no continuous model has this ZOH equivalent; use d2c_tustin or resample",
                        l.re, l.im
                    ),
                ));
            }
        }
        let big = Mat::from_fn(n + m, n + m, |i, j| match (i < n, j < n) {
            (true, true) => self.a[(i, j)],
            (true, false) => self.b[(i, j - n)],
            (false, true) => 0.0,
            (false, false) => {
                if i == j {
                    1.0
                } else {
                    0.0
                }
            }
        });
        let l = linalg::logm(big.as_ref())?;
        let a = Mat::from_fn(n, n, |i, j| l[(i, j)] / ts);
        let b = Mat::from_fn(n, m, |i, j| l[(i, n + j)] / ts);
        StateSpace::continuous(a, b, self.c.clone(), self.d.clone())
    }

    /// Transfer-function coefficients of a SISO model, `(num, den)`, both of length
    /// `order + 1`, in descending powers of $s$ or $z$ (for a discrete model that is also
    /// ascending powers of $q^{-1}$), with monic `den`.
    ///
    /// The denominator is the characteristic polynomial $\det(\lambda I - A) = \sum_i a_i
    /// \lambda^{n-i}$ (from the eigenvalues, as `numpy.poly`). The numerator follows from the
    /// Markov parameters $h_k = C A^{k-1} B$: since $G(\lambda) - D = \sum_{k \ge 1} h_k
    /// \lambda^{-k}$, multiplying by the denominator gives
    /// $$ \mathrm{num}_0 = D, \qquad \mathrm{num}_k = D a_k + \sum_{i=0}^{k-1} a_i h_{k-i},
    ///    \quad k = 1, \dots, n. $$
    /// This avoids the cancellation in `scipy.signal.ss2tf`'s
    /// $\det(\lambda I - A + BC) + (D - 1)\det(\lambda I - A)$ when the numerator is small
    /// compared with the denominator. Numerically sound for orders up to about 20.
    pub fn tf_coefficients(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        self.require_siso("tf_coefficients")?;
        let n = self.order();
        let den = linalg::charpoly(self.a.as_ref())?;
        let mut h = vec![0.0; n + 1];
        let mut ab = self.b.clone();
        for hk in h.iter_mut().skip(1) {
            *hk = (&self.c * &ab)[(0, 0)];
            ab = &self.a * &ab;
        }
        let d = self.d[(0, 0)];
        let num = (0..=n)
            .map(|k| d * den[k] + (0..k).map(|i| den[i] * h[k - i]).sum::<f64>())
            .collect();
        Ok((num, den))
    }
}

pub(crate) fn check_ts(ts: f64) -> Result<()> {
    if !(ts.is_finite() && ts > 0.0) {
        return Err(Error::invalid(
            "ts",
            format!("sample time must be positive and finite, got {ts}"),
        ));
    }
    Ok(())
}

/// The bilinear-transform period: `ts`, or $2\tan(\omega_p T_s/2)/\omega_p$ when prewarping.
fn warped_period(ts: f64, prewarp_hz: Option<f64>) -> Result<f64> {
    match prewarp_hz {
        None => Ok(ts),
        Some(f) => {
            if !(f.is_finite() && f > 0.0 && f < 0.5 / ts) {
                return Err(Error::invalid(
                    "prewarp_hz",
                    format!(
                        "the prewarping frequency must lie in (0, {}) Hz (below Nyquist), got {f}",
                        0.5 / ts
                    ),
                ));
            }
            let w = 2.0 * std::f64::consts::PI * f;
            Ok(2.0 * (w * ts / 2.0).tan() / w)
        }
    }
}

/// The balanced model and the Hessenberg form of its $A$, for [`StateSpace::freq_response`]
/// (all row-major).
struct Hessenberg {
    n: usize,
    /// balanced $A$ and $B$
    a: Vec<f64>,
    b: Vec<f64>,
    /// $H = Q^{\mathsf T} A Q$
    h: Vec<f64>,
    /// $Q$
    q: Vec<f64>,
    /// $Q^{\mathsf T} B$
    qtb: Vec<f64>,
    /// $C Q$
    cq: Vec<f64>,
}

impl Hessenberg {
    fn of(sys: &StateSpace) -> Self {
        let (n, m, p) = (sys.order(), sys.ninputs(), sys.noutputs());
        let mut a: Vec<f64> = (0..n * n).map(|k| sys.a[(k / n, k % n)]).collect();
        let mut b: Vec<f64> = (0..n * m).map(|k| sys.b[(k / m, k % m)]).collect();
        let mut c: Vec<f64> = (0..p * n).map(|k| sys.c[(k / n, k % n)]).collect();
        balance(n, m, p, &mut a, &mut b, &mut c);
        let mut h = a.clone();
        let mut q: Vec<f64> = (0..n * n)
            .map(|k| if k / n == k % n { 1.0 } else { 0.0 })
            .collect();
        let mut v = vec![0.0; n];
        for k in 0..n.saturating_sub(2) {
            let alpha: f64 = (k + 1..n).map(|i| h[i * n + k].powi(2)).sum::<f64>().sqrt();
            if alpha == 0.0 {
                continue;
            }
            let beta = if h[(k + 1) * n + k] >= 0.0 {
                -alpha
            } else {
                alpha
            };
            v.iter_mut().for_each(|x| *x = 0.0);
            for i in k + 1..n {
                v[i] = h[i * n + k];
            }
            v[k + 1] -= beta;
            let vnorm2: f64 = (k + 1..n).map(|i| v[i] * v[i]).sum();
            if vnorm2 == 0.0 {
                continue;
            }
            let tau = 2.0 / vnorm2;
            // H ← P H P, Q ← Q P (P = I − τ v vᵀ, symmetric)
            for j in 0..n {
                let s: f64 = (k + 1..n).map(|i| v[i] * h[i * n + j]).sum::<f64>() * tau;
                for i in k + 1..n {
                    h[i * n + j] -= s * v[i];
                }
            }
            for row in 0..n {
                let s: f64 = (k + 1..n).map(|j| h[row * n + j] * v[j]).sum::<f64>() * tau;
                for j in k + 1..n {
                    h[row * n + j] -= s * v[j];
                }
                let s: f64 = (k + 1..n).map(|j| q[row * n + j] * v[j]).sum::<f64>() * tau;
                for j in k + 1..n {
                    q[row * n + j] -= s * v[j];
                }
            }
            for i in k + 2..n {
                h[i * n + k] = 0.0;
            }
        }
        let qtb: Vec<f64> = (0..n * m)
            .map(|idx| {
                let (i, j) = (idx / m, idx % m);
                (0..n).map(|k| q[k * n + i] * b[k * m + j]).sum()
            })
            .collect();
        let cq: Vec<f64> = (0..p * n)
            .map(|idx| {
                let (i, j) = (idx / n, idx % n);
                (0..n).map(|k| c[i * n + k] * q[k * n + j]).sum()
            })
            .collect();
        Self {
            n,
            a,
            b,
            h,
            q,
            qtb,
            cq,
        }
    }

    /// `out = Q x`.
    fn rotate(&self, x: &[c64], out: &mut [c64]) {
        let n = self.n;
        for (i, o) in out.iter_mut().enumerate() {
            let mut v = c64::new(0.0, 0.0);
            for (k, xk) in x.iter().enumerate() {
                v += xk * self.q[i * n + k];
            }
            *o = v;
        }
    }

    /// `out = Qᵀ x`.
    fn rotate_t(&self, x: &[c64], out: &mut [c64]) {
        let n = self.n;
        for (i, o) in out.iter_mut().enumerate() {
            let mut v = c64::new(0.0, 0.0);
            for (k, xk) in x.iter().enumerate() {
                v += xk * self.q[k * n + i];
            }
            *o = v;
        }
    }
}

/// Parlett–Reinsch balancing by powers of 2 (exact): $A \leftarrow D^{-1}AD$,
/// $B \leftarrow D^{-1}B$, $C \leftarrow CD$.
fn balance(n: usize, m: usize, p: usize, a: &mut [f64], b: &mut [f64], c: &mut [f64]) {
    for _sweep in 0..100 {
        let mut converged = true;
        for i in 0..n {
            let col: f64 = (0..n).filter(|&k| k != i).map(|k| a[k * n + i].abs()).sum();
            let row: f64 = (0..n).filter(|&k| k != i).map(|k| a[i * n + k].abs()).sum();
            if col == 0.0 || row == 0.0 || !(col + row).is_finite() {
                continue;
            }
            let (mut cc, mut rr, mut f) = (col, row, 1.0);
            while cc < rr / 2.0 {
                cc *= 2.0;
                rr /= 2.0;
                f *= 2.0;
            }
            while cc >= rr * 2.0 {
                cc /= 2.0;
                rr *= 2.0;
                f /= 2.0;
            }
            if cc + rr < 0.95 * (col + row) {
                converged = false;
                for k in 0..n {
                    a[i * n + k] /= f;
                    a[k * n + i] *= f;
                }
                for j in 0..m {
                    b[i * m + j] /= f;
                }
                for r in 0..p {
                    c[r * n + i] *= f;
                }
            }
        }
        if converged {
            break;
        }
    }
}

/// Gaussian elimination with partial pivoting of $\lambda I - H$, $H$ upper Hessenberg: only
/// adjacent rows are ever swapped.
struct HessLu {
    n: usize,
    /// $U$ (row-major; entries below the diagonal unused)
    u: Vec<c64>,
    mult: Vec<c64>,
    swapped: Vec<bool>,
}

impl HessLu {
    fn new(n: usize) -> Self {
        let zero = c64::new(0.0, 0.0);
        Self {
            n,
            u: vec![zero; n * n],
            mult: vec![zero; n],
            swapped: vec![false; n],
        }
    }

    /// Factors $\lambda I - H$.
    fn factor(&mut self, h: &[f64], lam: c64) -> std::result::Result<(), ()> {
        let n = self.n;
        let u = &mut self.u;
        for i in 0..n {
            for j in i.saturating_sub(1)..n {
                let d = if i == j { lam } else { c64::new(0.0, 0.0) };
                u[i * n + j] = d - c64::new(h[i * n + j], 0.0);
            }
        }
        for k in 0..n.saturating_sub(1) {
            let swap = u[(k + 1) * n + k].norm_sqr() > u[k * n + k].norm_sqr();
            if swap {
                for j in k..n {
                    u.swap(k * n + j, (k + 1) * n + j);
                }
            }
            self.swapped[k] = swap;
            let piv = u[k * n + k];
            if piv.norm_sqr() == 0.0 {
                return Err(());
            }
            let l = u[(k + 1) * n + k] / piv;
            self.mult[k] = l;
            for j in k + 1..n {
                let v = u[k * n + j];
                u[(k + 1) * n + j] -= l * v;
            }
        }
        if n > 0 && u[(n - 1) * n + n - 1].norm_sqr() == 0.0 {
            return Err(());
        }
        Ok(())
    }

    fn solve(&self, x: &mut [c64]) -> std::result::Result<(), ()> {
        let n = self.n;
        for k in 0..n.saturating_sub(1) {
            if self.swapped[k] {
                x.swap(k, k + 1);
            }
            let v = x[k];
            x[k + 1] -= self.mult[k] * v;
        }
        for i in (0..n).rev() {
            let urow = &self.u[i * n + i + 1..(i + 1) * n];
            let s: c64 = urow.iter().zip(&x[i + 1..]).map(|(u, xk)| u * xk).sum();
            let z = (x[i] - s) / self.u[i * n + i];
            if !(z.re.is_finite() && z.im.is_finite()) {
                return Err(());
            }
            x[i] = z;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::TransferFunction;
    use rand::{RngExt, SeedableRng};

    /// Sorted by (re, im) for comparison.
    fn sorted(mut v: Vec<c64>) -> Vec<c64> {
        v.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
        v
    }

    fn close(a: &[c64], b: &[c64], tol: f64) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).norm() <= tol)
    }

    /// A minimal 3-state model, augmented by an uncontrollable mode (0.7) and an unobservable
    /// one (-0.4), in random non-orthogonal coordinates: the reduction finds the 3 states with
    /// the zeros of the minimal model, and `zeros` (minimal part plus decoupling zeros) equals
    /// the full pencil's QZ.
    #[test]
    fn zeros_by_kalman_split_equal_the_full_pencil_on_a_non_minimal_model() {
        // (1 - 0.3 q^-1)(1 + 0.5 q^-1) / ((1 - 0.9 q^-1)(1 - 1.2 q^-1)(1 + 0.2 q^-1)):
        // zeros 0.3, -0.5 and the origin (numerator of degree 2 over 3 poles)
        let num = [1.0, 0.2, -0.15];
        let den = TransferFunction::new(vec![1.0], vec![1.0, -2.1, 1.08], 1e-3)
            .unwrap()
            .series(&TransferFunction::new(vec![1.0], vec![1.0, 0.2], 1e-3).unwrap())
            .unwrap()
            .den()
            .to_vec();
        let g = TransferFunction::new(num.to_vec(), den, 1e-3)
            .unwrap()
            .to_state_space()
            .unwrap();
        assert_eq!(g.order(), 3);
        let n = 5;
        let a = Mat::from_fn(n, n, |i, j| match (i < 3, j < 3) {
            (true, true) => g.a()[(i, j)],
            _ if i == 3 && j == 3 => 0.7,
            _ if i == 4 && j == 4 => -0.4,
            // the uncontrollable state feeds the others, the others feed the unobservable one
            _ if i < 3 && j == 3 => 0.3,
            _ if i == 4 && j < 3 => 0.25,
            _ => 0.0,
        });
        let b = Mat::from_fn(n, 1, |i, _| match i {
            0..=2 => g.b()[(i, 0)],
            4 => 1.0,
            _ => 0.0,
        });
        let c = Mat::from_fn(1, n, |_, j| match j {
            0..=2 => g.c()[(0, j)],
            3 => 0.8,
            _ => 0.0,
        });
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let t = Mat::from_fn(n, n, |i, j| {
            (if i == j { 1.0 } else { 0.0 }) + 0.3 * rng.random_range(-1.0..1.0)
        });
        let ti = linalg::solve(t.as_ref(), Mat::<f64>::identity(n, n).as_ref()).unwrap();
        let big =
            StateSpace::discrete(&ti * &a * &t, &ti * &b, &c * &t, g.d().to_owned(), 1e-3).unwrap();
        let r = big.minimal_part().unwrap();
        assert_eq!(r.order(), 3);
        let f = [10.0, 123.0, 400.0];
        let (h1, h2) = (
            g.freq_response_siso(&f).unwrap(),
            r.freq_response_siso(&f).unwrap(),
        );
        for (x, y) in h1.iter().zip(&h2) {
            assert!((x - y).norm() <= 1e-10 * x.norm(), "{x} vs {y}");
        }
        let want = sorted(g.pencil_zeros().unwrap());
        assert_eq!(want.len(), 3);
        // transmission zeros: those of the minimal part
        let got = sorted(r.zeros().unwrap());
        assert!(close(&got, &want, 1e-9), "{got:?} vs {want:?}");
        // invariant zeros: the full pencil's, i.e. with the decoupling zeros 0.7 and -0.4
        let full = sorted(big.pencil_zeros().unwrap());
        let mut with_decoupling = want.clone();
        with_decoupling.extend([c64::new(0.7, 0.0), c64::new(-0.4, 0.0)]);
        let with_decoupling = sorted(with_decoupling);
        assert!(close(&full, &with_decoupling, 1e-8), "full pencil {full:?}");
        let split = sorted(big.zeros().unwrap());
        assert!(close(&split, &with_decoupling, 1e-9), "{split:?}");
        assert!(close(&split, &full, 1e-8));
        // a minimal model is used as it is
        assert_eq!(g.minimal_part().unwrap(), g);
    }

    #[test]
    fn zeros_refuse_a_minimal_part_above_the_limit_with_the_limit_named() {
        // a chain of distinct modes, fully controllable and observable
        let n = ZEROS_MAX_ORDER + 1;
        let a = Mat::from_fn(n, n, |i, j| {
            if i == j {
                0.9 * (i as f64 / n as f64) - 0.45
            } else if i == j + 1 {
                1.0
            } else {
                0.0
            }
        });
        let b = Mat::from_fn(n, 1, |i, _| if i == 0 { 1.0 } else { 0.0 });
        let c = Mat::from_fn(1, n, |_, j| if j == n - 1 { 1.0 } else { 0.0 });
        let g = StateSpace::discrete(a, b, c, Mat::zeros(1, 1), 1e-3).unwrap();
        let msg = g.zeros().unwrap_err().to_string();
        assert!(msg.contains("ZEROS_MAX_ORDER = 300"), "{msg}");
    }
}
