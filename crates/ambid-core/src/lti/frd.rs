//! Frequency-response data: an $n_y \times n_u$ complex matrix $G(f_k)$ per frequency line (Hz),
//! with an optional variance $\sigma^2_{k,ij} = \mathrm{E}\,|\hat G_{ij}(f_k) - G_{ij}(f_k)|^2$ of
//! every entry. SISO data is the $1 \times 1$ case of the same type.
//!
//! # Storage
//! The values are stored flat, line after line; within a line the matrix is stored column by
//! column ($\mathrm{vec}\,G$), so entry $(i, j)$ of line $k$ is at
//! `k * ny * nu + j * ny + i` ([`Frd::values`], [`Frd::variance`]). For a $1 \times 1$ response
//! this is one value per line, so every SISO accessor ([`Frd::values`], [`Frd::magnitude_db`],
//! [`Frd::band`], …) reads as it always did; on a matrix they act on the flat storage.
//!
//! # Covariance: what is kept and why
//! Only the variance of every entry (the diagonal of $\mathrm{Cov}\,\mathrm{vec}\,\hat G$) is kept:
//! it is what every estimator of the project produces today (one value per SISO line), and it is
//! what a confidence band per entry needs. Cross-covariances between entries are not stored, so
//! the algebra below treats the entries' errors as **uncorrelated** (exact for $1 \times 1$ and
//! for entries estimated from independent experiments); where the entries of a MIMO estimate are
//! correlated, the propagated variances of the matrix operations that mix entries (product,
//! inverse, division, feedback) are first-order values under that stated assumption, not the
//! full covariance.
//!
//! # Algebra (written once for matrices)
//! All operations act line by line on a common grid, with dimension checks as typed errors
//! ([`Error::DimensionMismatch`]). Variances propagate to first order, for independent operands
//! with circular complex errors: a perturbation $\delta Z = \sum L(\delta X)$ gives
//! $\sigma^2_{Z_{ij}} = \sum_{kl} |\partial Z_{ij}/\partial X_{kl}|^2 \sigma^2_{X_{kl}}$.
//!
//! | operation | value | $\delta Z$ | $1 \times 1$ variance |
//! |-----------|-------|------------|------------------------|
//! | [`series`](Frd::series) (`self` first, then `next`) | $Y X$ | $\delta Y X + Y \delta X$ | $\lvert X\rvert^2\sigma_Y^2 + \lvert Y\rvert^2\sigma_X^2$ |
//! | [`product`](Frd::product) | $X Y$ | $\delta X\, Y + X \delta Y$ | as series |
//! | [`parallel`](Frd::parallel) | $X+Y$ | $\delta X + \delta Y$ | $\sigma_X^2 + \sigma_Y^2$ |
//! | [`divide`](Frd::divide) | $X Y^{-1}$ | $\delta X\, W - Z\, \delta Y\, W$, $W = Y^{-1}$ | $\sigma_X^2/\lvert Y\rvert^2 + \lvert X\rvert^2\sigma_Y^2/\lvert Y\rvert^4$ |
//! | [`inverse`](Frd::inverse) | $X^{-1}$ | $-Z\,\delta X\, Z$ | $\sigma_X^2 / \lvert X\rvert^4$ |
//! | [`feedback_with_sign`](Frd::feedback_with_sign) | $(I - s X Y)^{-1} X$ | $M \delta X\, N + s Z \delta Y Z$ | $\frac{\sigma_X^2 + \lvert X\rvert^4\sigma_Y^2}{\lvert 1-s XY\rvert^4}$ |
//!
//! with $M = (I - s X Y)^{-1}$ and $N = (I - s Y X)^{-1}$ (push-through:
//! $I + s Y M X = N$). So, e.g., $\sigma^2_{Z_{ij}} = \sum_k |Y_{kj}|^2\sigma^2_{X_{ik}} +
//! |X_{ik}|^2\sigma^2_{Y_{kj}}$ for the product and
//! $\sigma^2_{Z_{ij}} = \sum_{kl} |Z_{ik}|^2 |Z_{lj}|^2 \sigma^2_{X_{kl}}$ for the inverse.
//! Inverses are solved by Gaussian elimination with partial pivoting; a line whose matrix is
//! singular (a pivot $\le n\,\varepsilon \max_{ij}|A_{ij}|$, or a non-finite result) is a typed
//! error naming its frequency. On $1 \times 1$ data the values are the scalar formulas
//! bit for bit ($x y$, $x + y$, $x / y$, $1 / x$, $x / (1 - s x y)$).
//!
//! A missing variance counts as zero when the other operand has one; the result has no variance
//! only if neither operand has one.
//!
//! # Example
//! ```
//! use ambid_core::lti::{Frd, StateSpace};
//! use faer::mat;
//! let g = StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[0.5]], mat![[0.0]], 1e-3).unwrap();
//! let f = [0.0, 100.0, 250.0];
//! let frd = Frd::from_model(&g, &f).unwrap();
//! assert!((frd.values()[0].re - 1.0).abs() < 1e-14);
//! // unity negative feedback: 0.5/(z - 0.5) / (1 + 0.5/(z - 0.5)) = 0.5/z; |.| = 0.5 everywhere
//! let t = frd.feedback(&Frd::constant(&f, 1.0, Some(1e-3)).unwrap()).unwrap();
//! assert!(t.magnitude().iter().all(|m| (m - 0.5).abs() < 1e-14));
//! ```
//!
//! A $2 \times 2$ response per line, and the closed-loop plant $P = T S^{-1}$:
//! ```
//! use ambid_core::lti::Frd;
//! use faer::{c64, Mat};
//! let f = [10.0, 20.0];
//! let c = |re: f64, im: f64| c64::new(re, im);
//! let p = Mat::from_fn(2, 2, |i, j| c(1.0 + i as f64, j as f64 - 0.5));
//! let k = Mat::from_fn(2, 2, |i, j| c(if i == j { 0.3 } else { 0.1 }, 0.0));
//! let plant = Frd::from_matrices(&f, &[p.clone(), p.clone()], None, None).unwrap();
//! let ctrl = Frd::from_matrices(&f, &[k.clone(), k.clone()], None, None).unwrap();
//! assert_eq!((plant.ny(), plant.nu()), (2, 2));
//! // T = (I + P C)^-1 P and S = (I + C P)^-1 (`plant.series(&ctrl)` is C P), so P = T S^-1
//! let t = plant.feedback(&ctrl).unwrap();
//! let s = Frd::identity(&f, 2, None).unwrap().feedback(&plant.series(&ctrl).unwrap()).unwrap();
//! let back = t.divide(&s).unwrap();
//! for line in 0..2 {
//!     let (a, b) = (back.at(line).unwrap(), plant.at(line).unwrap());
//!     for i in 0..2 {
//!         for j in 0..2 {
//!             assert!((a[(i, j)] - b[(i, j)]).norm() < 1e-12);
//!         }
//!     }
//! }
//! assert!(t.divide(&Frd::identity(&f, 3, None).unwrap()).is_err()); // 2×2 · (3×3)⁻¹
//! ```

use super::interconnect::{check_same_ts, FeedbackSign};
use super::ss::StateSpace;
use crate::error::{check_finite, Error, Result};
use faer::{c64, Mat};

/// Frequency-response data: an $n_y \times n_u$ complex matrix per frequency line (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Frd {
    f_hz: Vec<f64>,
    ny: usize,
    nu: usize,
    values: Vec<c64>,
    variance: Option<Vec<f64>>,
    ts: Option<f64>,
}

const ZERO: c64 = c64 { re: 0.0, im: 0.0 };
const ONE: c64 = c64 { re: 1.0, im: 0.0 };

/// $A B$ for column-major $A$ ($m \times k$) and $B$ ($k \times n$).
fn mat_mul(a: &[c64], m: usize, k: usize, b: &[c64], n: usize) -> Vec<c64> {
    let mut out = vec![ZERO; m * n];
    for j in 0..n {
        for i in 0..m {
            let mut acc = ZERO;
            for l in 0..k {
                acc += a[i + l * m] * b[l + j * k];
            }
            out[i + j * m] = acc;
        }
    }
    out
}

/// $A^{-1} B$ for column-major $A$ ($n \times n$) and $B$ ($n \times r$) by Gaussian elimination
/// with partial pivoting; `None` if $A$ is singular (module docs) or the result is not finite.
/// For $n = 1$ this is exactly `b / a`.
fn solve(a: &[c64], n: usize, b: &[c64], r: usize) -> Option<Vec<c64>> {
    let mut a = a.to_vec();
    let mut x = b.to_vec();
    let scale = a.iter().fold(0.0f64, |s, z| s.max(z.norm()));
    let tol = n as f64 * f64::EPSILON * scale;
    if scale == 0.0 || !scale.is_finite() {
        return None;
    }
    for c in 0..n {
        let p = (c..n)
            .max_by(|&i, &j| a[i + c * n].norm().total_cmp(&a[j + c * n].norm()))
            .unwrap_or(c);
        if a[p + c * n].norm() <= tol {
            return None;
        }
        if p != c {
            for col in 0..n {
                a.swap(p + col * n, c + col * n);
            }
            for col in 0..r {
                x.swap(p + col * n, c + col * n);
            }
        }
        for row in c + 1..n {
            let f = a[row + c * n] / a[c + c * n];
            for col in c + 1..n {
                let v = a[c + col * n];
                a[row + col * n] -= f * v;
            }
            for col in 0..r {
                let v = x[c + col * n];
                x[row + col * n] -= f * v;
            }
        }
    }
    for col in 0..r {
        for i in (0..n).rev() {
            let mut acc = x[i + col * n];
            for l in i + 1..n {
                acc -= a[i + l * n] * x[l + col * n];
            }
            x[i + col * n] = acc / a[i + i * n];
        }
    }
    x.iter()
        .all(|z| z.re.is_finite() && z.im.is_finite())
        .then_some(x)
}

/// Transpose of a column-major $m \times n$ matrix.
fn transpose(a: &[c64], m: usize, n: usize) -> Vec<c64> {
    let mut t = vec![ZERO; m * n];
    for j in 0..n {
        for i in 0..m {
            t[j + i * n] = a[i + j * m];
        }
    }
    t
}

/// The $n \times n$ identity, column-major.
fn eye(n: usize) -> Vec<c64> {
    let mut e = vec![ZERO; n * n];
    for i in 0..n {
        e[i + i * n] = ONE;
    }
    e
}

/// $\sum_{kl} |L_{ik}|^2 |R_{lj}|^2 v_{kl}$: the variance of $(L\,\delta X\,R)_{ij}$ for
/// uncorrelated entries of $\delta X$ ($p \times q$) with variances `v`; $L$ is $m \times p$, $R$ is
/// $q \times n$, all column-major. Added into `out` ($m \times n$).
#[allow(clippy::too_many_arguments)]
fn add_sandwich_var(
    out: &mut [f64],
    l: &[c64],
    m: usize,
    p: usize,
    v: &[f64],
    r: &[c64],
    q: usize,
    n: usize,
) {
    for j in 0..n {
        for i in 0..m {
            let mut acc = 0.0;
            for kk in 0..p {
                let lik = l[i + kk * m].norm_sqr();
                for ll in 0..q {
                    acc += lik * r[ll + j * q].norm_sqr() * v[kk + ll * p];
                }
            }
            out[i + j * m] += acc;
        }
    }
}

impl Frd {
    /// Builds SISO ($1 \times 1$) frequency-response data. `f_hz` must be finite, non-negative and
    /// strictly increasing; `values` finite and of the same length; `variance` (if any) finite,
    /// $\ge 0$ and of the same length; `ts` positive if given.
    pub fn new(
        f_hz: Vec<f64>,
        values: Vec<c64>,
        variance: Option<Vec<f64>>,
        ts: Option<f64>,
    ) -> Result<Self> {
        Self::new_matrix(f_hz, 1, 1, values, variance, ts)
    }

    /// Builds $n_y \times n_u$ frequency-response data from the flat storage (module docs:
    /// line after line, each line column by column): `values` and `variance` (if any) hold
    /// `f_hz.len() * ny * nu` numbers. The checks are those of [`Frd::new`], and $n_y, n_u \ge 1$.
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::Frd;
    /// use faer::c64;
    /// // one line, G = [[1, 3], [2, 4]] stored column by column
    /// let v: Vec<c64> = [1.0, 2.0, 3.0, 4.0].iter().map(|&x| c64::new(x, 0.0)).collect();
    /// let g = Frd::new_matrix(vec![5.0], 2, 2, v, None, None).unwrap();
    /// assert_eq!(g.at(0).unwrap()[(0, 1)], c64::new(3.0, 0.0));
    /// assert_eq!(g.entry(1, 0).unwrap().values(), &[c64::new(2.0, 0.0)]);
    /// ```
    pub fn new_matrix(
        f_hz: Vec<f64>,
        ny: usize,
        nu: usize,
        values: Vec<c64>,
        variance: Option<Vec<f64>>,
        ts: Option<f64>,
    ) -> Result<Self> {
        check_finite("f_hz", &f_hz)?;
        if ny == 0 || nu == 0 {
            return Err(Error::invalid(
                "Frd dimensions",
                format!("a response needs at least one output and one input, got {ny}×{nu}"),
            ));
        }
        if let Some(i) = f_hz.iter().position(|f| *f < 0.0) {
            return Err(Error::invalid(
                "f_hz",
                format!("frequencies must be non-negative; f_hz[{i}] = {}", f_hz[i]),
            ));
        }
        if let Some(i) = f_hz.windows(2).position(|w| w[1] <= w[0]) {
            return Err(Error::invalid(
                "f_hz",
                format!(
                    "frequencies must be strictly increasing; f_hz[{}] ≤ f_hz[{i}]",
                    i + 1
                ),
            ));
        }
        let per = ny * nu;
        let expected = |n: usize| {
            if per == 1 {
                n.to_string()
            } else {
                format!("{} ({n} lines × {ny}×{nu})", n * per)
            }
        };
        if values.len() != f_hz.len() * per {
            return Err(Error::DimensionMismatch {
                context: "Frd values",
                expected: expected(f_hz.len()),
                got: values.len().to_string(),
            });
        }
        if let Some(index) = values
            .iter()
            .position(|z| !(z.re.is_finite() && z.im.is_finite()))
        {
            return Err(Error::NonFinite {
                what: "values",
                index,
            });
        }
        if let Some(v) = &variance {
            if v.len() != f_hz.len() * per {
                return Err(Error::DimensionMismatch {
                    context: "Frd variance",
                    expected: expected(f_hz.len()),
                    got: v.len().to_string(),
                });
            }
            check_finite("variance", v)?;
            if let Some(i) = v.iter().position(|x| *x < 0.0) {
                return Err(Error::invalid(
                    "variance",
                    format!("variances must be non-negative; variance[{i}] = {}", v[i]),
                ));
            }
        }
        if let Some(t) = ts {
            super::ss::check_ts(t)?;
        }
        Ok(Self {
            f_hz,
            ny,
            nu,
            values,
            variance,
            ts,
        })
    }

    /// Builds frequency-response data from one matrix per line (all of the same shape) and,
    /// optionally, one matrix of entry variances per line.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] when the number of matrices differs from the number of
    /// frequencies or the shapes differ; the checks of [`Frd::new_matrix`].
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::Frd;
    /// use faer::{c64, Mat};
    /// let g = Mat::from_fn(2, 3, |i, j| c64::new(i as f64, j as f64));
    /// let frd = Frd::from_matrices(&[1.0, 2.0], &[g.clone(), g], None, Some(1e-3)).unwrap();
    /// assert_eq!((frd.len(), frd.ny(), frd.nu()), (2, 2, 3));
    /// assert_eq!(frd.at(1).unwrap()[(1, 2)], c64::new(1.0, 2.0));
    /// ```
    pub fn from_matrices(
        f_hz: &[f64],
        values: &[Mat<c64>],
        variance: Option<&[Mat<f64>]>,
        ts: Option<f64>,
    ) -> Result<Self> {
        if values.len() != f_hz.len() {
            return Err(Error::DimensionMismatch {
                context: "Frd::from_matrices (one matrix per frequency)",
                expected: f_hz.len().to_string(),
                got: values.len().to_string(),
            });
        }
        let (ny, nu) = values.first().map_or((1, 1), |m| (m.nrows(), m.ncols()));
        let shape = |what: &'static str, k: usize, r: usize, c: usize| -> Result<()> {
            if (r, c) != (ny, nu) {
                return Err(Error::DimensionMismatch {
                    context: what,
                    expected: format!("{ny}×{nu} (the shape of line 0)"),
                    got: format!("{r}×{c} at line {k}"),
                });
            }
            Ok(())
        };
        let mut flat = Vec::with_capacity(values.len() * ny * nu);
        for (k, m) in values.iter().enumerate() {
            shape("Frd::from_matrices values", k, m.nrows(), m.ncols())?;
            for j in 0..nu {
                for i in 0..ny {
                    flat.push(m[(i, j)]);
                }
            }
        }
        let var = match variance {
            None => None,
            Some(vs) => {
                if vs.len() != f_hz.len() {
                    return Err(Error::DimensionMismatch {
                        context: "Frd::from_matrices variance (one matrix per frequency)",
                        expected: f_hz.len().to_string(),
                        got: vs.len().to_string(),
                    });
                }
                let mut out = Vec::with_capacity(flat.len());
                for (k, m) in vs.iter().enumerate() {
                    shape("Frd::from_matrices variance", k, m.nrows(), m.ncols())?;
                    for j in 0..nu {
                        for i in 0..ny {
                            out.push(m[(i, j)]);
                        }
                    }
                }
                Some(out)
            }
        };
        Self::new_matrix(f_hz.to_vec(), ny, nu, flat, var, ts)
    }

    /// The response of a state-space model at `f_hz` ($n_y \times n_u$; no variance; `ts` from
    /// the model).
    pub fn from_model(model: &StateSpace, f_hz: &[f64]) -> Result<Self> {
        let m = model.freq_response(f_hz)?;
        Self::from_matrices(f_hz, &m, None, model.ts())
    }

    /// The response of a discrete transfer function at `f_hz` (no variance).
    pub fn from_transfer_function(tf: &super::TransferFunction, f_hz: &[f64]) -> Result<Self> {
        let v = tf.freq_response(f_hz)?;
        Self::new(f_hz.to_vec(), v, None, Some(tf.ts()))
    }

    /// A constant (static gain) SISO response on the grid `f_hz`.
    pub fn constant(f_hz: &[f64], gain: f64, ts: Option<f64>) -> Result<Self> {
        Self::new(
            f_hz.to_vec(),
            vec![c64::new(gain, 0.0); f_hz.len()],
            None,
            ts,
        )
    }

    /// The $n \times n$ identity on the grid `f_hz` (no variance).
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::Frd;
    /// use faer::c64;
    /// let i2 = Frd::identity(&[1.0], 2, None).unwrap();
    /// assert_eq!(i2.values(), &[c64::new(1.0, 0.0), c64::new(0.0, 0.0), c64::new(0.0, 0.0), c64::new(1.0, 0.0)]);
    /// ```
    pub fn identity(f_hz: &[f64], n: usize, ts: Option<f64>) -> Result<Self> {
        let e = eye(n);
        let values = (0..f_hz.len()).flat_map(|_| e.iter().copied()).collect();
        Self::new_matrix(f_hz.to_vec(), n, n, values, None, ts)
    }

    /// Frequencies in Hz.
    pub fn f_hz(&self) -> &[f64] {
        &self.f_hz
    }
    /// Complex response values, flat (module docs; one per line for SISO data).
    pub fn values(&self) -> &[c64] {
        &self.values
    }
    /// Variance $\mathrm{E}|\hat G_{ij} - G_{ij}|^2$ per line and entry (flat, as
    /// [`Frd::values`]), if known.
    pub fn variance(&self) -> Option<&[f64]> {
        self.variance.as_deref()
    }
    /// Sample time of the underlying discrete system, `None` if continuous.
    pub fn ts(&self) -> Option<f64> {
        self.ts
    }
    /// Number of frequencies.
    pub fn len(&self) -> usize {
        self.f_hz.len()
    }
    /// `true` if there are no frequencies.
    pub fn is_empty(&self) -> bool {
        self.f_hz.is_empty()
    }
    /// Number of outputs $n_y$ (rows).
    pub fn ny(&self) -> usize {
        self.ny
    }
    /// Number of inputs $n_u$ (columns).
    pub fn nu(&self) -> usize {
        self.nu
    }
    /// `true` for $1 \times 1$ data.
    pub fn is_siso(&self) -> bool {
        self.ny == 1 && self.nu == 1
    }

    /// A typed error unless the response is $1 \times 1$: for the SISO-only consumers (fits to
    /// FRF data, band rules, resonance search, the ISO zones); `what` names the caller.
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::Frd;
    /// let g = Frd::identity(&[1.0], 2, None).unwrap();
    /// assert!(g.require_siso("my_fit").unwrap_err().to_string().contains("2×2"));
    /// assert!(g.entry(0, 0).unwrap().require_siso("my_fit").is_ok());
    /// ```
    pub fn require_siso(&self, what: &'static str) -> Result<()> {
        if !self.is_siso() {
            return Err(Error::invalid(
                "frd",
                format!(
                    "{what} takes SISO frequency-response data, and this one is {}×{} per line; pass one entry (Frd::entry)",
                    self.ny, self.nu
                ),
            ));
        }
        Ok(())
    }

    fn block(&self, line: usize) -> &[c64] {
        let per = self.ny * self.nu;
        &self.values[line * per..(line + 1) * per]
    }

    fn var_block(&self, line: usize) -> Option<&[f64]> {
        let per = self.ny * self.nu;
        self.variance
            .as_ref()
            .map(|v| &v[line * per..(line + 1) * per])
    }

    /// The $n_y \times n_u$ matrix of line `line`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if `line >= self.len()`.
    pub fn at(&self, line: usize) -> Result<Mat<c64>> {
        self.check_line(line)?;
        let b = self.block(line);
        Ok(Mat::from_fn(self.ny, self.nu, |i, j| b[i + j * self.ny]))
    }

    /// The entry variances of line `line`, if known.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if `line >= self.len()`.
    pub fn variance_at(&self, line: usize) -> Result<Option<Mat<f64>>> {
        self.check_line(line)?;
        Ok(self
            .var_block(line)
            .map(|b| Mat::from_fn(self.ny, self.nu, |i, j| b[i + j * self.ny])))
    }

    fn check_line(&self, line: usize) -> Result<()> {
        if line < self.len() {
            Ok(())
        } else {
            Err(Error::invalid(
                "line",
                format!(
                    "line {line} is outside the response's {} frequency lines (0-based)",
                    self.len()
                ),
            ))
        }
    }

    /// Entry $(i, j)$ (output $i$, input $j$) as SISO data with its variance.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an index outside $n_y \times n_u$.
    pub fn entry(&self, i: usize, j: usize) -> Result<Self> {
        if i >= self.ny || j >= self.nu {
            return Err(Error::invalid(
                "entry",
                format!(
                    "entry ({i}, {j}) is outside the {}×{} response",
                    self.ny, self.nu
                ),
            ));
        }
        let per = self.ny * self.nu;
        let at = i + j * self.ny;
        Ok(Self {
            f_hz: self.f_hz.clone(),
            ny: 1,
            nu: 1,
            values: (0..self.len()).map(|k| self.values[k * per + at]).collect(),
            variance: self
                .variance
                .as_ref()
                .map(|v| (0..self.len()).map(|k| v[k * per + at]).collect()),
            ts: self.ts,
        })
    }

    /// Magnitude $|G|$ (flat, as [`Frd::values`]).
    pub fn magnitude(&self) -> Vec<f64> {
        self.values.iter().map(|z| z.norm()).collect()
    }
    /// Magnitude in dB, $20 \log_{10} |G|$ (flat).
    pub fn magnitude_db(&self) -> Vec<f64> {
        self.values
            .iter()
            .map(|z| 20.0 * z.norm().log10())
            .collect()
    }
    /// Phase in degrees, in $(-180, 180]$ (flat).
    pub fn phase_deg(&self) -> Vec<f64> {
        self.values.iter().map(|z| z.arg().to_degrees()).collect()
    }
    /// Standard deviation $\sqrt{\sigma^2}$ per line and entry (flat), if the variance is known.
    pub fn std(&self) -> Option<Vec<f64>> {
        self.variance
            .as_ref()
            .map(|v| v.iter().map(|x| x.sqrt()).collect())
    }

    /// The data restricted to $f_{\min} \le f \le f_{\max}$ (Hz).
    pub fn band(&self, f_min: f64, f_max: f64) -> Result<Self> {
        if !(f_min.is_finite() && f_max.is_finite() && f_min <= f_max) {
            return Err(Error::invalid(
                "band",
                format!("need finite f_min ≤ f_max, got [{f_min}, {f_max}]"),
            ));
        }
        let keep: Vec<usize> = (0..self.len())
            .filter(|&k| self.f_hz[k] >= f_min && self.f_hz[k] <= f_max)
            .collect();
        Ok(Self {
            f_hz: keep.iter().map(|&k| self.f_hz[k]).collect(),
            ny: self.ny,
            nu: self.nu,
            values: keep
                .iter()
                .flat_map(|&k| self.block(k).iter().copied())
                .collect(),
            variance: self.variance.as_ref().map(|_| {
                keep.iter()
                    .flat_map(|&k| self.var_block(k).unwrap_or(&[]).iter().copied())
                    .collect()
            }),
            ts: self.ts,
        })
    }

    fn check_grid(&self, other: &Frd) -> Result<()> {
        check_same_ts(self.ts, other.ts)?;
        if self.len() != other.len() {
            return Err(Error::DimensionMismatch {
                context: "Frd frequency grids",
                expected: format!("{} frequencies", self.len()),
                got: format!("{}", other.len()),
            });
        }
        for (k, (a, b)) in self.f_hz.iter().zip(&other.f_hz).enumerate() {
            if (a - b).abs() > 1e-12 * a.abs().max(b.abs()) {
                return Err(Error::invalid(
                    "f_hz",
                    format!("the frequency grids differ at index {k} ({a} Hz vs {b} Hz); interpolate onto a common grid first"),
                ));
            }
        }
        Ok(())
    }

    fn check_dims(
        context: &'static str,
        expected: (usize, usize),
        got: (usize, usize),
    ) -> Result<()> {
        if expected != got {
            return Err(Error::DimensionMismatch {
                context,
                expected: format!("{}×{}", expected.0, expected.1),
                got: format!("{}×{}", got.0, got.1),
            });
        }
        Ok(())
    }

    fn singular(&self, what: &'static str, k: usize) -> Error {
        if self.is_siso() {
            Error::numerical(what, format!("division by zero at {} Hz", self.f_hz[k]))
        } else {
            Error::numerical(
                what,
                format!(
                    "the matrix to invert is singular at {} Hz (line {k}); the result is not defined there — restrict the band or check the data",
                    self.f_hz[k]
                ),
            )
        }
    }

    /// Line-by-line combination: `phi(k, x, y, vx, vy) -> (z, vz)` on blocks, with the result's
    /// shape `(ny, nu)`; missing variances are passed as zeros.
    fn combine(
        &self,
        other: &Frd,
        shape: (usize, usize),
        phi: impl Fn(&[c64], &[c64], &[f64], &[f64], bool) -> Option<(Vec<c64>, Vec<f64>)>,
        what: &'static str,
    ) -> Result<Self> {
        self.check_grid(other)?;
        let has_var = self.variance.is_some() || other.variance.is_some();
        let per = shape.0 * shape.1;
        let mut values = Vec::with_capacity(self.len() * per);
        let mut var = Vec::with_capacity(if has_var { self.len() * per } else { 0 });
        let zx = vec![0.0; self.ny * self.nu];
        let zy = vec![0.0; other.ny * other.nu];
        for k in 0..self.len() {
            let vx = self.var_block(k).unwrap_or(&zx);
            let vy = other.var_block(k).unwrap_or(&zy);
            let Some((z, vz)) = phi(self.block(k), other.block(k), vx, vy, has_var) else {
                return Err(self.singular(what, k));
            };
            if z.iter().any(|z| !(z.re.is_finite() && z.im.is_finite())) {
                return Err(self.singular(what, k));
            }
            values.extend_from_slice(&z);
            if has_var {
                var.extend_from_slice(&vz);
            }
        }
        Ok(Self {
            f_hz: self.f_hz.clone(),
            ny: shape.0,
            nu: shape.1,
            values,
            variance: has_var.then_some(var),
            ts: self.ts,
        })
    }

    /// $a\,G$ for a real scalar $a$ (variance $a^2 \sigma^2$).
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::Frd;
    /// let g = Frd::constant(&[1.0], 2.0, None).unwrap().scaled(-0.5);
    /// assert_eq!(g.values()[0].re, -1.0);
    /// ```
    pub fn scaled(&self, a: f64) -> Self {
        Self {
            values: self.values.iter().map(|z| z * a).collect(),
            variance: self
                .variance
                .as_ref()
                .map(|v| v.iter().map(|x| a * a * x).collect()),
            ..self.clone()
        }
    }

    /// Matrix product $X Y$ per line (`self` $= X$ is $n_y \times m$, `right` $= Y$ is
    /// $m \times n_u$); first-order variances in the module docs.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] unless the columns of $X$ match the rows of $Y$; different
    /// grids or sample times.
    pub fn product(&self, right: &Frd) -> Result<Self> {
        if right.ny != self.nu {
            return Err(Error::DimensionMismatch {
                context: "Frd::product (the right factor needs a row per column of the left)",
                expected: format!("{} rows (left factor {}×{})", self.nu, self.ny, self.nu),
                got: format!("{}×{}", right.ny, right.nu),
            });
        }
        let (m, k, n) = (self.ny, self.nu, right.nu);
        self.combine(
            right,
            (m, n),
            |x, y, vx, vy, has_var| {
                let z = mat_mul(x, m, k, y, n);
                let mut v = vec![0.0; m * n];
                if has_var {
                    for j in 0..n {
                        for i in 0..m {
                            let mut acc = 0.0;
                            for l in 0..k {
                                acc += y[l + j * k].norm_sqr() * vx[i + l * m]
                                    + x[i + l * m].norm_sqr() * vy[l + j * k];
                            }
                            v[i + j * m] = acc;
                        }
                    }
                }
                Some((z, v))
            },
            "Frd::product",
        )
    }

    /// Series connection: the outputs of `self` drive the inputs of `next`, so the result is the
    /// product $G_{\text{next}}\, G_{\text{self}}$ (as [`StateSpace::series`], MATLAB
    /// `series(self, next)`); for SISO data the pointwise product.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] unless `next` has as many inputs as `self` has outputs.
    pub fn series(&self, next: &Frd) -> Result<Self> {
        if next.nu != self.ny {
            return Err(Error::DimensionMismatch {
                context: "Frd::series (`next` needs an input per output of `self`)",
                expected: format!("{} inputs (`self` is {}×{})", self.ny, self.ny, self.nu),
                got: format!("{}×{}", next.ny, next.nu),
            });
        }
        next.product(self)
    }

    /// Parallel connection (sum) $X + Y$.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] for different shapes.
    pub fn parallel(&self, other: &Frd) -> Result<Self> {
        Self::check_dims("Frd::parallel", (self.ny, self.nu), (other.ny, other.nu))?;
        self.combine(
            other,
            (self.ny, self.nu),
            |x, y, vx, vy, _| {
                Some((
                    x.iter().zip(y).map(|(a, b)| a + b).collect(),
                    vx.iter().zip(vy).map(|(a, b)| 1.0 * a + 1.0 * b).collect(),
                ))
            },
            "Frd::parallel",
        )
    }

    /// Right division $X Y^{-1}$ per line ($X$ is $n_y \times n$, $Y$ is $n \times n$): how the
    /// plant is formed from closed-loop responses, $P = T_{ry} S^{-1}$. Pointwise quotient for
    /// SISO data.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] unless $Y$ is square with as many rows as $X$ has columns;
    /// [`Error::Numerical`] naming the frequency of a line where $Y$ is singular.
    pub fn divide(&self, other: &Frd) -> Result<Self> {
        Self::check_dims(
            "Frd::divide (the divisor must be square, of the dividend's column count)",
            (self.nu, self.nu),
            (other.ny, other.nu),
        )?;
        let (p, n) = (self.ny, self.nu);
        self.combine(
            other,
            (p, n),
            |x, y, vx, vy, has_var| {
                // Z Y = X  <=>  Yᵀ Zᵀ = Xᵀ
                let zt = solve(&transpose(y, n, n), n, &transpose(x, p, n), p)?;
                let z = transpose(&zt, n, p);
                let mut v = vec![0.0; p * n];
                if has_var {
                    let w = solve(y, n, &eye(n), n)?;
                    add_sandwich_var(&mut v, &eye(p), p, p, vx, &w, n, n);
                    add_sandwich_var(&mut v, &z, p, n, vy, &w, n, n);
                }
                Some((z, v))
            },
            "Frd::divide",
        )
    }

    /// Matrix inverse $X^{-1}$ per line (pointwise $1/X$ for SISO data).
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] for a non-square response; [`Error::Numerical`] naming the
    /// frequency of a singular line.
    pub fn inverse(&self) -> Result<Self> {
        Self::check_dims(
            "Frd::inverse (square)",
            (self.ny, self.ny),
            (self.ny, self.nu),
        )?;
        let n = self.ny;
        let one = Frd::identity(&self.f_hz, n, self.ts)?;
        self.combine(
            &one,
            (n, n),
            |x, _, vx, _, has_var| {
                let z = solve(x, n, &eye(n), n)?;
                let mut v = vec![0.0; n * n];
                if has_var {
                    add_sandwich_var(&mut v, &z, n, n, vx, &z, n, n);
                }
                Some((z, v))
            },
            "Frd::inverse",
        )
    }

    /// Negative feedback $(I + G K)^{-1} G$ with `other` $= K$ in the feedback path.
    pub fn feedback(&self, other: &Frd) -> Result<Self> {
        self.feedback_with_sign(other, FeedbackSign::Negative)
    }

    /// Feedback with sign $s$: $u = r + s K y$, $y = G u$, so $y = (I - s G K)^{-1} G\, r$
    /// ($G$ = `self` is $n_y \times n_u$, $K$ = `other` is $n_u \times n_y$); for SISO data
    /// $G / (1 - s G K)$.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] unless $K$ is $n_u \times n_y$; [`Error::Numerical`] naming
    /// the frequency of a line where $I - s G K$ is singular.
    pub fn feedback_with_sign(&self, other: &Frd, sign: FeedbackSign) -> Result<Self> {
        Self::check_dims(
            "Frd::feedback (the feedback path maps the outputs back to the inputs)",
            (self.nu, self.ny),
            (other.ny, other.nu),
        )?;
        let s = sign.value();
        let (ny, nu) = (self.ny, self.nu);
        self.combine(
            other,
            (ny, nu),
            move |g, k, vg, vk, has_var| {
                let loop_matrix = |a: &[c64], ra: usize, ca: usize, b: &[c64]| {
                    let ab = mat_mul(a, ra, ca, b, ra);
                    let mut m = eye(ra);
                    for (mi, x) in m.iter_mut().zip(&ab) {
                        *mi -= x * s;
                    }
                    m
                };
                let den = loop_matrix(g, ny, nu, k);
                let z = solve(&den, ny, g, nu)?;
                let mut v = vec![0.0; ny * nu];
                if has_var {
                    let m = solve(&den, ny, &eye(ny), ny)?;
                    let n = solve(&loop_matrix(k, nu, ny, g), nu, &eye(nu), nu)?;
                    add_sandwich_var(&mut v, &m, ny, ny, vg, &n, nu, nu);
                    add_sandwich_var(&mut v, &z, ny, nu, vk, &z, ny, nu);
                }
                Some((z, v))
            },
            "Frd::feedback",
        )
    }
}
