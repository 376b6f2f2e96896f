//! FIR and ARX models by linear least squares, for one output and any number of inputs (MISO).
//!
//! # Model
//! With $n_u$ inputs, the ARX model is
//! $$ A(q)\,y_k = \sum_{i=0}^{n_u-1} B_i(q)\,u_{i,k} + e_k, \qquad
//!    A = 1 + a_1 q^{-1} + \dots + a_{n_a} q^{-n_a}, \qquad
//!    B_i = q^{-n_{k,i}} \bigl(b_{i,1} + b_{i,2} q^{-1} + \dots + b_{i,n_{b,i}} q^{-n_{b,i}+1}\bigr), $$
//! so that $y_k = \varphi_k^\top \theta + e_k$ with the regressor and parameter vectors
//! $$ \varphi_k = \bigl[-y_{k-1}, \dots, -y_{k-n_a},\;
//!      u_{0,k-n_{k,0}}, \dots, u_{0,k-n_{k,0}-n_{b,0}+1},\; \dots \bigr]^\top, \qquad
//!    \theta = [a_1, \dots, a_{n_a},\; b_{0,1}, \dots, b_{0,n_{b,0}},\; \dots]^\top, $$
//! $d = n_a + \sum_i n_{b,i}$ parameters. FIR is the special case $n_a = 0$ ([`fir`]). In the
//! returned [`ArxModel`], `a = [1, a_1, …]` and `b[i]` carries the delay as $n_{k,i}$ leading
//! zeros (`docs/conventions.md`), as MATLAB's `idpoly`.
//!
//! # Criterion window
//! Samples are numbered from $0$. The first sample whose regressor contains only measured data
//! (no assumed initial conditions) is
//! $$ k_0 = \max\bigl(n_a,\ \max_i (n_{b,i} + n_{k,i} - 1)\bigr), $$
//! and the criterion is
//! $$ V_N(\theta) = \frac1N \sum_{k=k_0}^{N_\text{tot}-1} (y_k - \varphi_k^\top\theta)^2,
//!    \qquad N = N_\text{tot} - k_0 . $$
//! This is also the protocol of the reference numbers of the real data sets in
//! `shared/data/real/` (e.g. the DaISy dryer). A larger start ([`ArxOptions::k0`]) lets models of
//! different orders share one window, so that their losses are comparable
//! ([`crate::estimate::order`] does this).
//!
//! # Solution
//! The columns of $\Phi = [\varphi_{k_0}, \dots]^\top$ are first scaled to unit norm,
//! $\Phi_s = \Phi D^{-1}$ with $D = \mathrm{diag}(\lVert\Phi_{:,j}\rVert)$ (so that outputs in metres
//! and inputs in amperes do not upset the rank test), then the target is appended and
//! $[\Phi_s\ \ Y] = Q R$ by one Householder QR (faer, in place), so that
//! $$ R = \begin{bmatrix} R_{11} & r_{12} \\ 0 & r_{22} \end{bmatrix}, \qquad
//!    \hat\theta = D^{-1} R_{11}^{-1} r_{12}, \qquad
//!    \sum_k \varepsilon_k^2 = r_{22}^2 . $$
//! The normal equations are never formed, so the accuracy depends on $\kappa(\Phi_s)$, not on its
//! square, and the loss is not a difference of large numbers.
//!
//! With a ridge (Tikhonov) weight $\lambda > 0$ ([`ArxOptions::ridge`]) the criterion becomes
//! $\lVert Y - \Phi\theta\rVert^2 + \lambda \lVert\theta\rVert^2$ (a *sum*, not a mean, of squares),
//! solved as the augmented least-squares problem
//! $$ \min_\theta \left\lVert \begin{bmatrix} Y \\ 0 \end{bmatrix} -
//!    \begin{bmatrix} \Phi \\ \sqrt\lambda\, I \end{bmatrix} \theta \right\rVert^2 $$
//! by the same QR (the residual is then summed directly, without the ridge term). A ridge makes a
//! rank-deficient regressor solvable (the minimum-norm direction is chosen), at the price of a bias
//! towards $\theta = 0$.
//!
//! **Rank test.** The regressor is rejected as rank deficient when
//! $\sigma_{\min}(R_{11})/\sigma_{\max}(R_{11}) \le \max(N, d)\,\varepsilon$ (MATLAB `rank`'s tolerance, on the
//! equilibrated columns); the error names the regressor columns that carry the right singular vector
//! of $\sigma_{\min}$, i.e. the lags that the data cannot tell apart (a constant input, a periodic
//! input with a period shorter than $n_b$, an identically zero output, …).
//!
//! # Covariance
//! With the residuals $\varepsilon_k = y_k - \varphi_k^\top\hat\theta$ and
//! $\hat\lambda = \sum_k \varepsilon_k^2 / (N - d)$ ([`Fitted::noise_variance`]),
//! $$ \mathrm{Cov}\,\hat\theta \approx \hat\lambda\,(\Phi^\top\Phi)^{-1}
//!    = \hat\lambda\, D^{-1} R_{11}^{-1} R_{11}^{-\top} D^{-1}, $$
//! which is asymptotically exact when the data come from an ARX model with white $e$ (the
//! true system is in the model set; Ljung 1999, §9.2). With a ridge, the variance part
//! $\hat\lambda\,M^{-1}\Phi^\top\Phi M^{-1}$, $M = \Phi^\top\Phi + \lambda I$, is returned; the
//! bias $-\lambda M^{-1}\theta_0$ is not included. [`Fitted::loss`] is $V_N(\hat\theta)$ without the
//! ridge term.
//!
//! # Prediction, simulation and fit
//! [`ArxModel::predict`] gives the one-step-ahead predictor
//! $\hat y_{k|k-1} = \varphi_k^\top\hat\theta$, [`ArxModel::simulate`] the simulated output
//! $A(q)\hat y_k = \sum_i B_i(q) u_{i,k}$ (started from given measured outputs), and
//! [`crate::validate::fit::fit_percent`] the normalised fit $100\,(1 - \lVert y-\hat y\rVert / \lVert y - \bar y\rVert)$ (MATLAB
//! `compare`).
//!
//! Complexity: $O(N d^2)$ for the QR, $O(N d)$ for building $\Phi$ and the residuals.
//!
//! # Example
//! ```
//! use ambid_core::estimate::arx::{arx, ArxOrders};
//! use ambid_core::validate::fit::fit_percent;
//! use rand::{RngExt, SeedableRng};
//! // y_k = 1.5 y_{k-1} - 0.7 y_{k-2} + u_{k-1} + 0.5 u_{k-2}: A = [1, -1.5, 0.7], B = [0, 1, 0.5]
//! let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
//! let u: Vec<f64> = (0..300).map(|_| rng.random::<f64>() - 0.5).collect();
//! let mut y = vec![0.0; 300];
//! for k in 2..300 {
//!     y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + u[k - 1] + 0.5 * u[k - 2];
//! }
//! let fitted = arx(&y, &[&u], &ArxOrders::siso(2, 2, 1), 1e-3).unwrap();
//! let m = &fitted.model;
//! assert!((m.a[1] + 1.5).abs() < 1e-10 && (m.a[2] - 0.7).abs() < 1e-10);
//! assert_eq!(m.b[0][0], 0.0); // the delay nk = 1 is a leading zero
//! assert!((m.b[0][1] - 1.0).abs() < 1e-10 && (m.b[0][2] - 0.5).abs() < 1e-10);
//! // noise-free data: the simulation started from the first k0 = 2 outputs reproduces y
//! let ysim = m.simulate(&[&u], &y[..m.k0()]).unwrap();
//! assert!(fit_percent(&y, &ysim).unwrap() > 99.999);
//! ```

use super::Fitted;
use crate::data::{IoData, Role};
use crate::error::{check_finite, Error, Result};
use crate::lti::PolyModel;
use faer::{Mat, MatRef, Par};

/// Orders of a MISO ARX model: $n_a$, and per input $n_b$ (number of $B$ coefficients) and $n_k$
/// (delay in samples).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ArxOrders {
    /// Number of $A$ coefficients $a_1 \dots a_{n_a}$ ($0$ for FIR).
    pub na: usize,
    /// Number of free $B$ coefficients of each input (each $\ge 1$).
    pub nb: Vec<usize>,
    /// Delay of each input in samples ($0$ allows a direct feedthrough $u_k \to y_k$).
    pub nk: Vec<usize>,
}

impl ArxOrders {
    /// Orders of a single-input model.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxOrders;
    /// let o = ArxOrders::siso(2, 2, 3);
    /// assert_eq!((o.n_params(), o.k0()), (4, 4));
    /// ```
    pub fn siso(na: usize, nb: usize, nk: usize) -> Self {
        Self {
            na,
            nb: vec![nb],
            nk: vec![nk],
        }
    }

    /// Orders of a FIR model ($n_a = 0$) with the given $n_b$ and $n_k$ per input.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxOrders;
    /// let o = ArxOrders::fir(vec![10, 5], vec![1, 0]);
    /// assert_eq!((o.na, o.n_params(), o.k0()), (0, 15, 10));
    /// ```
    pub fn fir(nb: Vec<usize>, nk: Vec<usize>) -> Self {
        Self { na: 0, nb, nk }
    }

    /// Number of inputs (`nb.len()`).
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxOrders;
    /// assert_eq!(ArxOrders::siso(1, 1, 1).n_inputs(), 1);
    /// ```
    pub fn n_inputs(&self) -> usize {
        self.nb.len()
    }

    /// Number of parameters $d = n_a + \sum_i n_{b,i}$.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxOrders;
    /// assert_eq!(ArxOrders::siso(4, 4, 3).n_params(), 8);
    /// ```
    pub fn n_params(&self) -> usize {
        self.na + self.nb.iter().sum::<usize>()
    }

    /// First sample of the criterion, $k_0 = \max(n_a, \max_i(n_{b,i} + n_{k,i} - 1))$ (an input
    /// with $n_b = 0$ would contribute nothing).
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxOrders;
    /// assert_eq!(ArxOrders::siso(2, 2, 3).k0(), 4);
    /// assert_eq!(ArxOrders::siso(5, 1, 1).k0(), 5);
    /// ```
    pub fn k0(&self) -> usize {
        self.nb
            .iter()
            .zip(&self.nk)
            .map(|(&nb, &nk)| if nb == 0 { 0 } else { nb + nk - 1 })
            .fold(self.na, usize::max)
    }

    /// The regressor columns in the order of $\theta$.
    pub(crate) fn columns(&self) -> Vec<Column> {
        let mut cols: Vec<Column> = (1..=self.na).map(Column::y).collect();
        for (i, (&nb, &nk)) in self.nb.iter().zip(&self.nk).enumerate() {
            cols.extend((nk..nk + nb).map(|lag| Column::u(i, lag)));
        }
        cols
    }

    fn describe(&self) -> String {
        if self.nb.len() == 1 {
            format!("ARX(na={}, nb={}, nk={})", self.na, self.nb[0], self.nk[0])
        } else {
            format!("ARX(na={}, nb={:?}, nk={:?})", self.na, self.nb, self.nk)
        }
    }
}

/// Options of [`arx_with`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ArxOptions {
    /// Ridge (Tikhonov) weight $\lambda \ge 0$ on $\lVert\theta\rVert^2$, added to the *sum* of
    /// squared prediction errors; default $0$ (plain least squares).
    pub ridge: f64,
    /// First sample of the criterion; default (`None`) $k_0$ of the orders ([`ArxOrders::k0`]).
    /// A larger value is allowed (e.g. the $k_0$ of the largest model in an order comparison); a
    /// smaller one is an error because the regressor would need samples before $0$.
    pub k0: Option<usize>,
}

/// A MISO ARX model $A(q) y = \sum_i B_i(q) u_i + e$ with sample time `ts`.
#[derive(Debug, Clone, PartialEq)]
pub struct ArxModel {
    /// $A = [1, a_1, \dots, a_{n_a}]$ (monic, ascending powers of $q^{-1}$).
    pub a: Vec<f64>,
    /// $B_i$ of each input, the delay $n_{k,i}$ as leading zeros: $[0, \dots, 0, b_{i,1}, \dots]$.
    pub b: Vec<Vec<f64>>,
    /// Sample time in seconds.
    pub ts: f64,
}

impl ArxModel {
    /// Builds a model, checking that `a` is monic (`a[0] == 1` to 1e-12), every `b[i]` is
    /// non-empty, all coefficients are finite and `ts > 0`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] or [`Error::NonFinite`] naming what is wrong.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxModel;
    /// let m = ArxModel::new(vec![1.0, -0.9], vec![vec![0.0, 0.1]], 0.01).unwrap();
    /// assert_eq!(m.k0(), 1);
    /// assert!(ArxModel::new(vec![2.0], vec![vec![1.0]], 0.01).is_err());
    /// ```
    pub fn new(a: Vec<f64>, b: Vec<Vec<f64>>, ts: f64) -> Result<Self> {
        let m = Self { a, b, ts };
        m.check()?;
        Ok(m)
    }

    fn check(&self) -> Result<()> {
        check_ts(self.ts)?;
        check_finite("a", &self.a)?;
        match self.a.first() {
            Some(a0) if (a0 - 1.0).abs() <= 1e-12 => {}
            _ => {
                return Err(Error::invalid(
                    "a",
                    "A must be monic: [1, a1, a2, …] in ascending powers of q^-1",
                ))
            }
        }
        for (i, bi) in self.b.iter().enumerate() {
            if bi.is_empty() {
                return Err(Error::invalid(
                    "b",
                    format!("B of input {i} is empty; it needs at least one coefficient"),
                ));
            }
            check_finite(input_name(i), bi)?;
        }
        Ok(())
    }

    /// $n_a$, the degree of $A$.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxModel;
    /// let m = ArxModel::new(vec![1.0, -0.9], vec![vec![0.0, 0.1]], 0.01).unwrap();
    /// assert_eq!(m.na(), 1);
    /// ```
    pub fn na(&self) -> usize {
        self.a.len().saturating_sub(1)
    }

    /// Number of inputs.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxModel;
    /// let m = ArxModel::new(vec![1.0], vec![vec![1.0], vec![0.0, 2.0]], 0.01).unwrap();
    /// assert_eq!(m.n_inputs(), 2);
    /// ```
    pub fn n_inputs(&self) -> usize {
        self.b.len()
    }

    /// The first sample whose one-step prediction uses only measured data,
    /// $\max(n_a, \max_i(\mathrm{len}(B_i) - 1))$; equals [`ArxOrders::k0`] of the estimated orders.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxModel;
    /// let m = ArxModel::new(vec![1.0, -1.2, 0.4], vec![vec![0.0, 0.0, 0.0, 0.06, 0.04]], 0.08).unwrap();
    /// assert_eq!(m.k0(), 4);
    /// ```
    pub fn k0(&self) -> usize {
        self.b
            .iter()
            .map(|b| b.len().saturating_sub(1))
            .fold(self.na(), usize::max)
    }

    /// The single-input model $A y = B_i u_i + e$ of input `input` as a [`PolyModel`] (ARX, or FIR
    /// when $A = 1$). For a MISO model the other inputs' contributions are left out.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an input index out of range or an invalid model.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxModel;
    /// use ambid_core::lti::Structure;
    /// let m = ArxModel::new(vec![1.0, -0.5], vec![vec![0.0, 0.5]], 0.1).unwrap();
    /// let p = m.to_poly(0).unwrap();
    /// assert_eq!(p.structure(), Structure::Arx);
    /// assert!((p.freq_response(&[0.0]).unwrap()[0].re - 1.0).abs() < 1e-12);
    /// ```
    pub fn to_poly(&self, input: usize) -> Result<PolyModel> {
        self.check()?;
        let b = self.b.get(input).ok_or_else(|| {
            Error::invalid(
                "input",
                format!(
                    "input {input} does not exist; the model has {} input(s)",
                    self.b.len()
                ),
            )
        })?;
        if self.a.len() == 1 || self.a[1..].iter().all(|x| *x == 0.0) {
            PolyModel::fir(b.clone(), self.ts)
        } else {
            PolyModel::arx(self.a.clone(), b.clone(), self.ts)
        }
    }

    /// One-step-ahead prediction $\hat y_{k|k-1} = -\sum_i a_i y_{k-i} + \sum_i B_i(q) u_{i,k}$ for
    /// every sample $k$, taking unmeasured samples before $k = 0$ as zero. Only $k \ge$
    /// [`k0`](Self::k0) use measured data alone; compare there (`&y[k0..]`, `&yhat[k0..]`) to
    /// reproduce the estimation criterion.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] for a wrong number of inputs or different lengths;
    /// [`Error::NonFinite`]; [`Error::InvalidArgument`] for an invalid model.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxModel;
    /// let m = ArxModel::new(vec![1.0, -0.5], vec![vec![0.0, 2.0]], 1.0).unwrap();
    /// let yhat = m.predict(&[1.0, 2.0, 3.0], &[&[1.0, 0.0, 1.0]]).unwrap();
    /// assert_eq!(yhat, vec![0.0, 0.5 * 1.0 + 2.0 * 1.0, 0.5 * 2.0 + 0.0]);
    /// ```
    pub fn predict(&self, y: &[f64], u: &[&[f64]]) -> Result<Vec<f64>> {
        self.check()?;
        check_data(y, u, self.b.len())?;
        let mut yhat = vec![0.0; y.len()];
        for (k, out) in yhat.iter_mut().enumerate() {
            *out = self.input_part(u, k) - self.ar_part(y, k);
        }
        Ok(yhat)
    }

    /// Simulated output $A(q)\hat y_k = \sum_i B_i(q) u_{i,k}$, $k = 0 \dots N-1$, with
    /// $\hat y_k = $ `y_init[k]` for the first `y_init.len()` samples (pass the measured
    /// `&y[..k0]` to start from the data, which is the protocol of the reference simulation fits of
    /// `shared/data/real/`, or `&[]` for zero initial conditions) and unmeasured samples before
    /// $k = 0$ taken as zero.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] for a wrong number of inputs, different input lengths or
    /// `y_init` longer than the inputs; [`Error::NonFinite`]; [`Error::InvalidArgument`] for an
    /// invalid model or no input (an AR model has no simulated output).
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::arx::ArxModel;
    /// let m = ArxModel::new(vec![1.0, -0.5], vec![vec![0.0, 1.0]], 1.0).unwrap();
    /// let y = m.simulate(&[&[1.0, 0.0, 0.0, 0.0]], &[]).unwrap();
    /// assert_eq!(y, vec![0.0, 1.0, 0.5, 0.25]);
    /// ```
    pub fn simulate(&self, u: &[&[f64]], y_init: &[f64]) -> Result<Vec<f64>> {
        self.check()?;
        let n = match u.first() {
            Some(u0) => u0.len(),
            None => {
                return Err(Error::invalid(
                    "u",
                    "simulation needs at least one input; a model without inputs has no simulated output",
                ))
            }
        };
        check_inputs(u, n, self.b.len())?;
        if y_init.len() > n {
            return Err(Error::DimensionMismatch {
                context: "ArxModel::simulate initial outputs",
                expected: format!("at most {n} (the input length)"),
                got: y_init.len().to_string(),
            });
        }
        check_finite("y_init", y_init)?;
        let mut ys = vec![0.0; n];
        ys[..y_init.len()].copy_from_slice(y_init);
        for k in y_init.len()..n {
            ys[k] = self.input_part(u, k) - self.ar_part(&ys, k);
        }
        Ok(ys)
    }

    /// $\sum_{i \ge 1} a_i y_{k-i}$ with zeros before the start.
    fn ar_part(&self, y: &[f64], k: usize) -> f64 {
        self.a
            .iter()
            .enumerate()
            .skip(1)
            .take_while(|(i, _)| *i <= k)
            .map(|(i, a)| a * y[k - i])
            .sum()
    }

    /// $\sum_i B_i(q) u_{i,k}$ with zeros before the start.
    fn input_part(&self, u: &[&[f64]], k: usize) -> f64 {
        self.b
            .iter()
            .zip(u)
            .map(|(b, ui)| {
                b.iter()
                    .enumerate()
                    .take_while(|(j, _)| *j <= k)
                    .map(|(j, bj)| bj * ui[k - j])
                    .sum::<f64>()
            })
            .sum()
    }
}

/// Estimates a MISO ARX model by QR least squares over the window $k \ge k_0$ (see the module
/// documentation). `u[i]` is input $i$; `orders.nb` and `orders.nk` have one entry per input.
///
/// The parameter vector of the result is $\theta = [a_1, \dots, a_{n_a}, b_{0,1}, \dots,
/// b_{0,n_{b,0}}, b_{1,1}, \dots]$, the covariance in the same order.
///
/// # Errors
/// * [`Error::InvalidArgument`]: `ts` not positive and finite; an `nb` of zero; no parameters;
///   fewer samples than the orders need (the message says how many); a rank-deficient regressor
///   (the message names the input and lag, or the output lag, that the data cannot identify).
/// * [`Error::DimensionMismatch`]: `u`, `nb` and `nk` of different lengths, or signals of
///   different lengths.
/// * [`Error::NonFinite`]: a NaN or infinite sample (with its index).
///
/// # Example
/// ```
/// use ambid_core::estimate::arx::{arx, ArxOrders};
/// // FIR y_k = 2 u_{k-1} - u_{k-2} (na = 0)
/// let u: Vec<f64> = (0..50).map(|k| ((k * 7919) % 13) as f64 - 6.0).collect();
/// let y: Vec<f64> = (0..50).map(|k| if k >= 2 { 2.0 * u[k - 1] - u[k - 2] } else { 0.0 }).collect();
/// let f = arx(&y, &[&u], &ArxOrders::fir(vec![2], vec![1]), 1.0).unwrap();
/// assert!((f.params[0] - 2.0).abs() < 1e-12 && (f.params[1] + 1.0).abs() < 1e-12);
/// assert_eq!(f.n_samples, 48);
/// ```
pub fn arx(y: &[f64], u: &[&[f64]], orders: &ArxOrders, ts: f64) -> Result<Fitted<ArxModel>> {
    arx_with(y, u, orders, ts, &ArxOptions::default())
}

/// FIR model $y = \sum_i B_i(q) u_i + e$: [`arx`] with $n_a = 0$.
///
/// # Errors
/// As [`arx`].
///
/// # Example
/// ```
/// use ambid_core::estimate::arx::fir;
/// let u: Vec<f64> = (0..40).map(|k| ((k * 31) % 11) as f64).collect();
/// let y: Vec<f64> = (0..40).map(|k| 0.5 * u[k]).collect();
/// let f = fir(&y, &[&u], &[1], &[0], 1.0).unwrap();
/// assert!((f.model.b[0][0] - 0.5).abs() < 1e-12 && f.model.a == vec![1.0]);
/// ```
pub fn fir(
    y: &[f64],
    u: &[&[f64]],
    nb: &[usize],
    nk: &[usize],
    ts: f64,
) -> Result<Fitted<ArxModel>> {
    arx(y, u, &ArxOrders::fir(nb.to_vec(), nk.to_vec()), ts)
}

/// [`arx`] with options: a ridge weight and/or a later start of the criterion window.
///
/// # Errors
/// As [`arx`], and [`Error::InvalidArgument`] for a negative or non-finite ridge or a window start
/// before the orders' $k_0$.
///
/// # Example
/// ```
/// use ambid_core::estimate::arx::{arx_with, ArxOptions, ArxOrders};
/// // a constant input cannot identify two B coefficients, unless regularised
/// let u = vec![1.0; 30];
/// let y = vec![3.0; 30];
/// let o = ArxOrders::fir(vec![2], vec![0]);
/// assert!(arx_with(&y, &[&u], &o, 1.0, &ArxOptions::default()).is_err());
/// let f = arx_with(&y, &[&u], &o, 1.0, &ArxOptions { ridge: 1e-6, k0: None }).unwrap();
/// assert!((f.params[0] - 1.5).abs() < 1e-6 && (f.params[1] - 1.5).abs() < 1e-6);
/// ```
pub fn arx_with(
    y: &[f64],
    u: &[&[f64]],
    orders: &ArxOrders,
    ts: f64,
    opts: &ArxOptions,
) -> Result<Fitted<ArxModel>> {
    arx_experiments(&[(y, u)], orders, ts, opts)
}

/// [`arx_with`] on several experiments of one system: the regressions of every experiment (each
/// from its own $k_0$, so no regressor reaches across a boundary) are stacked into one
/// least-squares problem, $\min_\theta \sum_e \lVert Y_e - \Phi_e \theta\rVert^2$. One experiment
/// is exactly [`arx_with`]; [`Fitted::n_samples`] counts the rows of all experiments.
///
/// # Errors
/// As [`arx_with`]; [`Error::InvalidArgument`] for no experiment or an experiment not longer
/// than $k_0$ (named).
///
/// # Example
/// ```
/// use ambid_core::estimate::arx::{arx_experiments, ArxOptions, ArxOrders};
/// // y_k = 0.5 y_{k-1} + u_{k-1}, two records
/// let sim = |u: &[f64]| {
///     let mut y = vec![0.0; u.len()];
///     for k in 1..u.len() { y[k] = 0.5 * y[k - 1] + u[k - 1]; }
///     y
/// };
/// let u1: Vec<f64> = (0..20).map(|k| ((k * 7) % 5) as f64 - 2.0).collect();
/// let u2: Vec<f64> = (0..15).map(|k| ((k * 3) % 4) as f64 - 1.5).collect();
/// let (y1, y2) = (sim(&u1), sim(&u2));
/// let f = arx_experiments(&[(&y1, &[&u1]), (&y2, &[&u2])], &ArxOrders::siso(1, 1, 1), 1.0,
///     &ArxOptions::default()).unwrap();
/// assert!((f.model.a[1] + 0.5).abs() < 1e-12 && (f.model.b[0][1] - 1.0).abs() < 1e-12);
/// assert_eq!(f.n_samples, 19 + 14);
/// ```
pub fn arx_experiments(
    experiments: &[(&[f64], &[&[f64]])],
    orders: &ArxOrders,
    ts: f64,
    opts: &ArxOptions,
) -> Result<Fitted<ArxModel>> {
    let Some(&(y0, u0)) = experiments.first() else {
        return Err(Error::invalid(
            "experiments",
            "no experiment was given; pass at least one (y, u) record",
        ));
    };
    check_ts(ts)?;
    check_orders(orders, u0.len())?;
    for &(y, u) in experiments {
        check_data(y, u, orders.n_inputs())?;
    }
    if !(opts.ridge.is_finite() && opts.ridge >= 0.0) {
        return Err(Error::invalid(
            "ridge",
            format!(
                "the ridge weight must be finite and >= 0, got {}",
                opts.ridge
            ),
        ));
    }
    let k0_min = orders.k0();
    let k0 = match opts.k0 {
        Some(k) if k < k0_min => {
            return Err(Error::invalid(
                "k0",
                format!(
                    "the criterion cannot start at sample {k}: {} needs samples back to k - {k0_min}, so the window starts at k0 >= {k0_min}",
                    orders.describe()
                ),
            ))
        }
        Some(k) => k,
        None => k0_min,
    };
    let d = orders.n_params();
    if experiments.len() > 1 {
        if let Some(e) = experiments.iter().position(|(y, _)| y.len() <= k0) {
            return Err(Error::invalid(
                "experiments",
                format!(
                    "experiment {e} has {} samples, but {} needs more than k0 = {k0} to give one equation; drop it or lower the orders",
                    experiments[e].0.len(),
                    orders.describe()
                ),
            ));
        }
    }
    let n_rows: usize = experiments
        .iter()
        .map(|(y, _)| y.len().saturating_sub(k0))
        .sum();
    if n_rows < d + 1 {
        let n_tot = if experiments.len() == 1 {
            y0.len().to_string()
        } else {
            format!("{n_rows} equations from {} experiments", experiments.len())
        };
        return Err(Error::invalid(
            "y",
            format!(
                "{} needs at least {} samples (k0 = {k0} to fill the regressor, then more than d = {d} equations to estimate {d} parameters and their variance); got {n_tot}. Use a longer record or lower orders",
                orders.describe(),
                k0 + d + 1
            ),
        ));
    }
    let cols = orders.columns();
    let mut with_target = cols.clone();
    with_target.push(Column::y(0));
    let z = if experiments.len() == 1 {
        build_regressor(y0, u0, &with_target, k0)
    } else {
        let parts: Vec<Mat<f64>> = experiments
            .iter()
            .map(|&(y, u)| build_regressor(y, u, &with_target, k0))
            .collect();
        let mut z = Mat::<f64>::zeros(n_rows, with_target.len());
        let mut row = 0;
        for p in &parts {
            for j in 0..p.ncols() {
                for i in 0..p.nrows() {
                    z[(row + i, j)] = p[(i, j)];
                }
            }
            row += p.nrows();
        }
        z
    };
    let n = n_rows;
    let u = u0;
    let ls = lstsq_columns(z, opts.ridge, &|j| cols[j].name(u.len())).map_err(|e| match e {
        Error::InvalidArgument { name, reason } => Error::InvalidArgument {
            name,
            reason: format!("{}: {reason}", orders.describe()),
        },
        other => other,
    })?;
    let noise_variance = ls.ssr / (n - d) as f64;
    let covariance = Mat::from_fn(d, d, |i, j| noise_variance * ls.inv_gram[(i, j)]);
    let a: Vec<f64> = std::iter::once(1.0)
        .chain(ls.theta[..orders.na].iter().copied())
        .collect();
    let mut b = Vec::with_capacity(orders.n_inputs());
    let mut pos = orders.na;
    for (&nb, &nk) in orders.nb.iter().zip(&orders.nk) {
        let mut bi = vec![0.0; nk];
        bi.extend_from_slice(&ls.theta[pos..pos + nb]);
        pos += nb;
        b.push(bi);
    }
    Ok(Fitted {
        model: ArxModel { a, b, ts },
        params: ls.theta,
        covariance: Some(covariance),
        loss: ls.ssr / n as f64,
        noise_variance,
        n_samples: n,
    })
}

/// The front door on an [`IoData`]: ARX of the one output channel ([`Role::Output`]) on the
/// input channels ([`Role::Input`], in axis order; several inputs make a MISO model, the orders
/// having one `nb`/`nk` per input), the regressions of all experiments stacked
/// ([`arx_experiments`]).
///
/// # Errors
/// [`Error::InvalidArgument`] for a record without an output or input channel, with several
/// output channels (the message gives the counts; use
/// [`crate::estimate::arx_mimo::arx_mimo_iodata`]) or with a non-finite sample in a used
/// channel; the errors of [`arx_experiments`].
///
/// # Example
/// ```
/// use ambid_core::data::IoData;
/// use ambid_core::estimate::arx::{arx_iodata, ArxOptions, ArxOrders};
/// let u: Vec<f64> = (0..60).map(|k| ((k * 7) % 5) as f64 - 2.0).collect();
/// let mut y = vec![0.0; 60];
/// for k in 1..60 { y[k] = 0.5 * y[k - 1] + u[k - 1]; }
/// let d = IoData::new(vec![("u".into(), u), ("y".into(), y)], 1e-3, None).unwrap();
/// let f = arx_iodata(&d, &ArxOrders::siso(1, 1, 1), &ArxOptions::default()).unwrap();
/// assert!((f.model.a[1] + 0.5).abs() < 1e-12);
/// ```
pub fn arx_iodata(
    data: &IoData,
    orders: &ArxOrders,
    opts: &ArxOptions,
) -> Result<Fitted<ArxModel>> {
    let ny = data.role_count(Role::Output);
    if ny > 1 {
        return Err(Error::invalid(
            "channels",
            format!(
                "arx fits one output, and the record has {ny} output channels ({}) and {} input channels; fit them jointly with arx_mimo (estimate::arx_mimo::arx_mimo_iodata) or select one output",
                data.role_names(Role::Output).join(", "),
                data.role_count(Role::Input)
            ),
        ));
    }
    data.require_finite(&[Role::Output, Role::Input])?;
    let mut ys = Vec::with_capacity(data.n_experiments());
    let mut us = Vec::with_capacity(data.n_experiments());
    for e in 0..data.n_experiments() {
        ys.push(data.signals(Role::Output, e)?[0]);
        us.push(data.signals(Role::Input, e)?);
    }
    let exps: Vec<(&[f64], &[&[f64]])> = ys
        .iter()
        .zip(&us)
        .map(|(y, u)| (*y, u.as_slice()))
        .collect();
    arx_experiments(&exps, orders, data.ts(), opts)
}

/// The FIR front door: [`arx_iodata`] with $n_a = 0$ and the given `nb`, `nk` per input.
///
/// # Errors
/// As [`arx_iodata`].
pub fn fir_iodata(data: &IoData, nb: &[usize], nk: &[usize]) -> Result<Fitted<ArxModel>> {
    arx_iodata(
        data,
        &ArxOrders::fir(nb.to_vec(), nk.to_vec()),
        &ArxOptions::default(),
    )
}

// ---------------------------------------------------------------------------------------------
// crate-internal building blocks, shared with `estimate::order`

/// One regressor column: $-y_{k-\text{lag}}$ or $u_{i,k-\text{lag}}$ (or $y_k$ itself as a target
/// column in the order scan, `Signal::Y` with lag 0, sign +).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Column {
    pub(crate) signal: Signal,
    pub(crate) lag: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Signal {
    Y,
    U(usize),
}

impl Column {
    pub(crate) fn y(lag: usize) -> Self {
        Self {
            signal: Signal::Y,
            lag,
        }
    }
    pub(crate) fn u(i: usize, lag: usize) -> Self {
        Self {
            signal: Signal::U(i),
            lag,
        }
    }
    /// The sign of the column's entries: $-1$ for past outputs, $+1$ for inputs and the target.
    pub(crate) fn sign(&self) -> f64 {
        match self.signal {
            Signal::Y if self.lag > 0 => -1.0,
            _ => 1.0,
        }
    }
    /// A user-facing name: "output lag 2, -y(k-2)" or "input 1 lag 4, u1(k-4)".
    pub(crate) fn name(&self, n_inputs: usize) -> String {
        match self.signal {
            Signal::Y => format!("output lag {}, -y(k-{})", self.lag, self.lag),
            Signal::U(i) => {
                let u = if n_inputs == 1 {
                    "u".to_string()
                } else {
                    format!("u{i}")
                };
                if self.lag == 0 {
                    format!("input {i} lag 0, {u}(k)")
                } else {
                    format!("input {i} lag {}, {u}(k-{})", self.lag, self.lag)
                }
            }
        }
    }
}

/// $\Phi$ with rows $k = k_0 \dots N-1$ and the given columns.
pub(crate) fn build_regressor(y: &[f64], u: &[&[f64]], cols: &[Column], k0: usize) -> Mat<f64> {
    let n = y.len() - k0;
    let mut phi = Mat::<f64>::zeros(n, cols.len());
    for (j, c) in cols.iter().enumerate() {
        let dst = phi.col_as_slice_mut(j);
        let (src, sign) = match c.signal {
            Signal::Y => (y, c.sign()),
            Signal::U(i) => (u[i], 1.0),
        };
        let src = &src[k0 - c.lag..k0 - c.lag + n];
        for (d, s) in dst.iter_mut().zip(src) {
            *d = sign * s;
        }
    }
    phi
}

/// Result of [`lstsq_columns`].
pub(crate) struct LsSolution {
    /// $\hat\theta$.
    pub(crate) theta: Vec<f64>,
    /// Sum of squared residuals (without any ridge term).
    pub(crate) ssr: f64,
    /// $(\Phi^\top\Phi)^{-1}$, or with a ridge $M^{-1}\Phi^\top\Phi M^{-1}$.
    pub(crate) inv_gram: Mat<f64>,
}

/// Relative rank tolerance on the equilibrated columns (MATLAB `rank`'s default).
pub(crate) fn rank_tolerance(rows: usize, cols: usize) -> f64 {
    rows.max(cols) as f64 * f64::EPSILON
}

/// Dot product with eight independent partial sums (vectorisable).
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 8];
    let ca = a.chunks_exact(8);
    let cb = b.chunks_exact(8);
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for ((s, xv), yv) in acc.iter_mut().zip(x).zip(y) {
            *s += xv * yv;
        }
    }
    acc.iter().sum::<f64>() + tail
}

/// Scales the first `d` columns of `z` to unit norm in place; returns their norms (1 for a zero
/// column) and the first zero column, if any.
pub(crate) fn equilibrate(z: &mut Mat<f64>, d: usize) -> (Vec<f64>, Option<usize>) {
    let mut scale = vec![1.0; d];
    let mut zero = None;
    for (j, s) in scale.iter_mut().enumerate() {
        let col = z.col_as_slice_mut(j);
        let norm = dot(col, col).sqrt();
        if norm > 0.0 {
            *s = norm;
            let inv = 1.0 / norm;
            col.iter_mut().for_each(|v| *v *= inv);
        } else if zero.is_none() {
            zero = Some(j);
        }
    }
    (scale, zero)
}

/// Householder QR of `a` in place (no copy); returns the upper triangle $R$ (`ncols` square),
/// triangular also when columns are dependent.
pub(crate) fn qr_r_in_place(a: Mat<f64>) -> Mat<f64> {
    crate::estimate::qr_stream::r_factor_in_place(a)
}

/// Column-equilibrated QR least squares of the last column of `z` on its other columns, with an
/// optional ridge, a rank test that names the dependent columns, the residual sum of squares and
/// the unscaled covariance. `z` ($n \times (d+1)$, the target last) is overwritten.
///
/// Without a ridge, $[\Phi_s\ Y] = Q R$ in place gives $\hat\theta_s = R_{11}^{-1} r_{12}$ and
/// $\mathrm{SSR} = r_{22}^2$; with one, the augmented matrix is factorised and the residual is
/// summed directly.
pub(crate) fn lstsq_columns(
    mut z: Mat<f64>,
    ridge: f64,
    name: &dyn Fn(usize) -> String,
) -> Result<LsSolution> {
    let (n, d) = (z.nrows(), z.ncols() - 1);
    let (scale, zero) = equilibrate(&mut z, d);
    if let (Some(j), true) = (zero, ridge == 0.0) {
        return Err(Error::invalid(
            "orders",
            format!(
                "the regressor column {} is identically zero over the criterion window, so its parameter cannot be identified; check the signal, reduce the order or set a ridge",
                name(j)
            ),
        ));
    }
    let (r_full, kept) = if ridge > 0.0 {
        let sqrt_ridge = ridge.sqrt();
        let mut a = Mat::<f64>::zeros(n + d, d + 1);
        for j in 0..=d {
            let col = a.col_as_slice_mut(j);
            col[..n].copy_from_slice(z.col_as_slice(j));
            if j < d {
                col[n + j] = sqrt_ridge / scale[j];
            }
        }
        (qr_r_in_place(a), Some(z))
    } else {
        (qr_r_in_place(z), None)
    };
    let rows = if ridge > 0.0 { n + d } else { n };
    let r = r_full.get(..d, ..d).to_owned();
    check_rank(r.as_ref(), rows, name)?;
    let mut theta_s: Vec<f64> = (0..d).map(|i| r_full[(i, d)]).collect();
    for i in (0..d).rev() {
        let s: f64 = (i + 1..d).map(|j| r[(i, j)] * theta_s[j]).sum();
        theta_s[i] = (theta_s[i] - s) / r[(i, i)];
    }
    let theta: Vec<f64> = theta_s.iter().zip(&scale).map(|(t, s)| t / s).collect();
    if let Some(j) = theta.iter().position(|t| !t.is_finite()) {
        return Err(Error::numerical(
            "arx",
            format!(
                "the least-squares solution for {} is not finite; the data are too badly scaled",
                name(j)
            ),
        ));
    }
    let ssr = if let Some(z) = kept {
        let mut res = z.col_as_slice(d).to_vec();
        for (j, t) in theta_s.iter().enumerate() {
            for (r, p) in res.iter_mut().zip(z.col_as_slice(j)) {
                *r -= p * t;
            }
        }
        dot(&res, &res)
    } else {
        r_full[(d, d)].powi(2)
    };
    // R^{-1} (scaled coordinates)
    let mut rinv = Mat::<f64>::zeros(d, d);
    faer::linalg::triangular_inverse::invert_upper_triangular(rinv.as_mut(), r.as_ref(), Par::Seq);
    // M_s^{-1} = R^{-1} R^{-T}
    let ms_inv = &rinv * rinv.transpose();
    let inv_scaled = if ridge > 0.0 {
        // M_s^{-1} (M_s - λ D^{-2}) M_s^{-1} = M_s^{-1} - λ M_s^{-1} D^{-2} M_s^{-1}
        let w = Mat::from_fn(d, d, |i, j| ms_inv[(i, j)] / scale[j].powi(2));
        let corr = &w * &ms_inv;
        Mat::from_fn(d, d, |i, j| ms_inv[(i, j)] - ridge * corr[(i, j)])
    } else {
        ms_inv
    };
    let inv_gram = Mat::from_fn(d, d, |i, j| {
        0.5 * (inv_scaled[(i, j)] + inv_scaled[(j, i)]) / (scale[i] * scale[j])
    });
    Ok(LsSolution {
        theta,
        ssr,
        inv_gram,
    })
}

/// Errors when the triangular factor of equilibrated columns is numerically rank deficient,
/// naming the columns that carry the right singular vector of the smallest singular value.
pub(crate) fn check_rank(
    r: MatRef<'_, f64>,
    rows: usize,
    name: &dyn Fn(usize) -> String,
) -> Result<()> {
    let d = r.ncols();
    if d == 0 {
        return Ok(());
    }
    let svd = r
        .svd()
        .map_err(|e| Error::numerical("arx rank test", format!("SVD failed: {e:?}")))?;
    let s = svd.S().column_vector();
    let (smax, smin) = (s[0], s[d - 1]);
    let tol = rank_tolerance(rows, d);
    if smax > 0.0 && smin > smax * tol {
        return Ok(());
    }
    let v = svd.V().col(d - 1);
    let vmax = (0..d).map(|j| v[j].abs()).fold(0.0, f64::max);
    let mut involved: Vec<usize> = (0..d).filter(|&j| v[j].abs() >= 0.2 * vmax).collect();
    involved.sort_by(|&a, &b| v[b].abs().total_cmp(&v[a].abs()));
    let names: Vec<String> = involved.iter().map(|&j| name(j)).collect();
    Err(Error::invalid(
        "orders",
        format!(
            "the regressor is rank deficient (smallest/largest singular value {:.1e} <= {tol:.1e} after scaling the columns to unit norm): the columns [{}] are (nearly) linearly dependent, so the data cannot identify their parameters separately. Typical causes: a constant or too slowly varying input, an input periodic with a period shorter than nb, or an order higher than the data support. Lower nb/na, excite the system with a richer input, or set a ridge",
            smin / smax.max(f64::MIN_POSITIVE),
            names.join("; ")
        ),
    ))
}

/// Static names for [`Error::NonFinite`] of the first inputs.
const INPUT_NAMES: [&str; 16] = [
    "u[0]", "u[1]", "u[2]", "u[3]", "u[4]", "u[5]", "u[6]", "u[7]", "u[8]", "u[9]", "u[10]",
    "u[11]", "u[12]", "u[13]", "u[14]", "u[15]",
];

pub(crate) fn input_name(i: usize) -> &'static str {
    INPUT_NAMES.get(i).copied().unwrap_or("u")
}

pub(crate) fn check_ts(ts: f64) -> Result<()> {
    if !(ts.is_finite() && ts > 0.0) {
        return Err(Error::invalid(
            "ts",
            format!("the sample time must be positive and finite (seconds), got {ts}"),
        ));
    }
    Ok(())
}

fn check_orders(orders: &ArxOrders, n_inputs: usize) -> Result<()> {
    if orders.nb.len() != n_inputs || orders.nk.len() != n_inputs {
        return Err(Error::DimensionMismatch {
            context: "arx: orders nb and nk per input",
            expected: format!("{n_inputs} (one per input signal)"),
            got: format!("nb: {}, nk: {}", orders.nb.len(), orders.nk.len()),
        });
    }
    if let Some(i) = orders.nb.iter().position(|&nb| nb == 0) {
        return Err(Error::invalid(
            "nb",
            format!("nb of input {i} is 0; every input needs nb >= 1 (leave an unused input out of `u`)"),
        ));
    }
    if orders.n_params() == 0 {
        return Err(Error::invalid(
            "na",
            "the model has no parameters: give na >= 1 or at least one input",
        ));
    }
    Ok(())
}

/// Checks that `u` has `n_inputs` signals of the same length as `y`, all finite.
pub(crate) fn check_data(y: &[f64], u: &[&[f64]], n_inputs: usize) -> Result<()> {
    check_inputs(u, y.len(), n_inputs)?;
    check_finite("y", y)
}

fn check_inputs(u: &[&[f64]], n: usize, n_inputs: usize) -> Result<()> {
    if u.len() != n_inputs {
        return Err(Error::DimensionMismatch {
            context: "number of input signals",
            expected: n_inputs.to_string(),
            got: u.len().to_string(),
        });
    }
    for (i, ui) in u.iter().enumerate() {
        if ui.len() != n {
            return Err(Error::DimensionMismatch {
                context: if i == 0 {
                    "length of input 0 vs the output"
                } else {
                    "length of an input vs the output (or input 0)"
                },
                expected: n.to_string(),
                got: format!("{} (input {i})", ui.len()),
            });
        }
        check_finite(if n_inputs == 1 { "u" } else { input_name(i) }, ui)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regressor_layout_matches_the_definition() {
        let y: Vec<f64> = (0..8).map(|k| k as f64).collect();
        let u0: Vec<f64> = (0..8).map(|k| 10.0 * k as f64).collect();
        let u1: Vec<f64> = (0..8).map(|k| 100.0 * k as f64).collect();
        let o = ArxOrders {
            na: 2,
            nb: vec![2, 1],
            nk: vec![1, 3],
        };
        assert_eq!(o.k0(), 3);
        let phi = build_regressor(&y, &[&u0, &u1], &o.columns(), o.k0());
        assert_eq!((phi.nrows(), phi.ncols()), (5, 5));
        // k = 3: [-y2, -y1, u0(2), u0(1), u1(0)]
        let row: Vec<f64> = (0..5).map(|j| phi[(0, j)]).collect();
        assert_eq!(row, vec![-2.0, -1.0, 20.0, 10.0, 0.0]);
        let row: Vec<f64> = (0..5).map(|j| phi[(4, j)]).collect();
        assert_eq!(row, vec![-6.0, -5.0, 60.0, 50.0, 400.0]);
    }

    #[test]
    fn column_names_are_readable() {
        assert_eq!(Column::y(2).name(1), "output lag 2, -y(k-2)");
        assert_eq!(Column::u(0, 3).name(1), "input 0 lag 3, u(k-3)");
        assert_eq!(Column::u(1, 0).name(2), "input 1 lag 0, u1(k)");
    }
}
