//! Model order selection: the ARX order scan with loss, AIC, BIC, FPE and validation fit.
//!
//! [`arx_order_scan`] fits every SISO ARX model with $n_a \in$ `na`, $n_b \in$ `nb` and
//! $n_k \in$ `nk` ([`ArxScanSpec`]) and tabulates, for each,
//! $$ V_N = \tfrac1N \textstyle\sum_k \varepsilon_k^2, \quad
//!    \mathrm{AIC} = N\ln V_N + 2d + N(\ln 2\pi + 1), \quad
//!    \mathrm{BIC} = N\ln V_N + d\ln N + N(\ln 2\pi + 1), \quad
//!    \mathrm{FPE} = V_N\,\frac{1 + d/N}{1 - d/N}, $$
//! with $d = n_a + n_b$ parameters and $N$ samples in the criterion (the AIC and BIC are $-2$ times
//! the Gaussian log-likelihood at $\hat\theta$, $\hat\sigma^2 = V_N$, plus the penalty; the constant
//! $N(\ln 2\pi + 1)$ does not affect any ranking). With validation data, each model's one-step
//! prediction loss and fit ([`crate::validate::fit::fit_percent`]) on them are added.
//!
//! # One window for all models
//! Every model is fitted over the same samples $k \ge k_0$ with $k_0$ that of the *largest* model,
//! $k_0 = \max(\max n_a,\ \max n_b + \max n_k - 1)$ (on the validation data too), so that the
//! losses are sums over the same residual samples and can be compared. A single model fitted by
//! [`crate::estimate::arx::arx`] starts at its own, smaller $k_0$; pass the scan's `k0` in
//! [`ArxOptions::k0`](crate::estimate::arx::ArxOptions::k0) to reproduce a row exactly.
//!
//! # One factorisation for all models
//! All regressor columns that any model uses, $-y_{k-1}, \dots, -y_{k-\max n_a}$ and
//! $u_{k-\min n_k}, \dots, u_{k-\max n_k-\max n_b+1}$, and the target $y_k$ as a last column, form
//! the full matrix $Z = [\Phi_\text{full}\ \ Y]$ ($N \times (D+1)$). Its columns are scaled to unit
//! norm and it is reduced *once* to a triangular $R$ with $R^\top R = Z_s^\top Z_s$. Because
//! $Z_s = Q R$ with orthonormal $Q$, every model's least-squares problem on a column subset $S$ is
//! the same problem on the columns $S$ of the small $R$:
//! $$ \lVert Y - \Phi_S\theta\rVert = \lVert R_{:,y} - R_{:,S}\,\theta\rVert . $$
//! The columns are ordered so that, for fixed $(n_a, n_k)$, the models $n_b = 1, 2, \dots$ use the
//! *leading* columns of $[R_{:,\,y\text{-lags}\le n_a},\ R_{:,\,u\text{-lags from }n_k},\ R_{:,y}]$:
//! one small QR $R' $ of that $(D+1) \times (n_a + \max n_b + 1)$ block gives all of them, with
//! $$ R'_{1:k,1:k}\,\theta_s = z_{1:k}, \qquad \mathrm{SSR}(k) = \sum_{i > k} z_i^2, \qquad
//!    k = n_a + n_b, \quad z = R'_{:,\text{last}}, $$
//! (no cancellation in the loss). Validation losses use the same trick on the validation data's
//! $R_v$: $\lVert Y_v - \Phi_{v,S}\theta\rVert = \lVert R_v c\rVert$ with $c$ the coefficient vector
//! ($1$ on $y$, $-\theta$ on $S$), $O(D\,d)$ per model.
//!
//! $R$ is obtained in one of two ways ([`ScanMethod`]):
//! * **Normal equations** (default when safe): $Z^\top Z$ is accumulated in $O(N D)$ by the shift
//!   structure of lagged columns, $\sum_{k=k_0}^{N-1} a_{k-l}b_{k-l'}$ for $l, l' \ge 1$ follows from
//!   the entry at $(l-1, l'-1)$ by adding one product and removing one, and $R$ is its Cholesky
//!   factor. Forming $Z^\top Z$ squares the condition number: the parameter error is
//!   $\approx \varepsilon\,\kappa(\Phi_s)^2$ instead of $\approx \varepsilon\,\kappa(\Phi_s)$, and the
//!   smallest loss $\mathrm{SSR}$ is the difference of numbers of size $\lVert Y\rVert^2$.
//!   So this path is used only when (i) the Cholesky factorisation succeeds, (ii) the equilibrated
//!   full regressor has $\kappa(\Phi_s) \le 10^3$ ([`NORMAL_EQUATIONS_MAX_CONDITION`]; every model's
//!   regressor is a column subset, and by eigenvalue interlacing its condition is no larger), which
//!   bounds the relative parameter error by about $d\,\varepsilon\,10^6 \approx 10^{-8}$ and
//!   typically $10^{-10}$, and (iii) the full model leaves at least $10^{-4}$ of
//!   $\lVert Y\rVert^2$ (and of $\lVert Y_v\rVert^2$) unexplained
//!   ([`NORMAL_EQUATIONS_MIN_RESIDUAL`]), so the cancellation costs at most four of the sixteen
//!   digits of every loss.
//! * **QR** otherwise (or when asked, [`ScanSolver::Qr`]): one Householder QR of $Z_s$,
//!   $O(N D^2)$, backward stable, as accurate as a QR per model.
//!
//! Either way the data are touched once (twice with validation data), not once per model; the
//! per-model work is $O(D\,d^2)$ per $(n_a, n_k)$ pair plus $O(d^2 + D d)$ per model.
//!
//! **Rank.** A model whose regressor is numerically rank deficient (a diagonal entry of $R'$ below
//! $\max(N, D)\,\varepsilon$, the columns having unit norm) makes the scan fail with an error that
//! names the model and the column; narrow the ranges. (The triangular diagonal reveals exact
//! dependencies such as a constant input, not every near-dependency.)
//!
//! # Candidate region
//! * `best_aic`, `best_bic`, `best_val`: the minimisers of AIC, BIC and the validation loss.
//! * `candidates`: every model whose BIC is within [`BIC_TOLERANCE`] $= 2$ of the minimum (a BIC
//!   difference below 2 is "not worth more than a bare mention", Kass & Raftery 1995), sorted by
//!   $d$ then BIC; `parsimonious` is the first, the smallest such model.
//! * `knee`: the knee of the loss curve. Take the lower envelope $L(d) = \min_{n_a + n_b = d} V_N$
//!   over the distinct $d$, map $d$ and $\ln L$ linearly onto $[0, 1]$ (first point $(0, 1)$, last
//!   $(1, 0)$), and pick the $d$ farthest below the chord between them, i.e. maximising
//!   $1 - x - y$ (the Kneedle rule); `None` with fewer than 3 distinct $d$ or no point below the
//!   chord. The row is the envelope model at that $d$.
//!
//! # Example
//! ```
//! use ambid_core::estimate::order::{arx_order_scan, ArxScanSpec};
//! use rand::{RngExt, SeedableRng};
//! let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
//! let n = 2000;
//! let u: Vec<f64> = (0..n).map(|_| rng.random::<f64>() - 0.5).collect();
//! let e: Vec<f64> = (0..n).map(|_| 0.05 * (rng.random::<f64>() - 0.5)).collect();
//! let mut y = vec![0.0; n];
//! for k in 2..n {
//!     y[k] = 1.2 * y[k - 1] - 0.5 * y[k - 2] + u[k - 1] + 0.4 * u[k - 2] + e[k];
//! }
//! let scan = arx_order_scan(&y, &u, &ArxScanSpec::new(1..=4, 1..=4, vec![1]), None).unwrap();
//! let best = &scan.rows[scan.best_bic];
//! assert_eq!((best.na, best.nb, best.nk), (2, 2, 1));
//! assert_eq!(scan.rows.len(), 16);
//! ```

use super::arx::{
    build_regressor, check_data, dot, equilibrate, qr_r_in_place, rank_tolerance, ArxOrders,
    Column, Signal,
};
use crate::error::{Error, Result};
use faer::{Mat, MatRef};
use serde::Serialize;
use std::ops::RangeInclusive;

/// BIC difference that still counts as "as good as the best" for [`OrderScan::candidates`].
pub const BIC_TOLERANCE: f64 = 2.0;

/// Largest condition number $\kappa(\Phi_s)$ of the equilibrated full regressor for which the
/// normal equations are used (their parameter error grows with $\kappa^2$).
pub const NORMAL_EQUATIONS_MAX_CONDITION: f64 = 1e3;

/// Smallest fraction $\mathrm{SSR}/\lVert Y\rVert^2$ of the full model for which the normal
/// equations are used (below it, the losses lose too many digits to cancellation).
pub const NORMAL_EQUATIONS_MIN_RESIDUAL: f64 = 1e-4;

/// How [`arx_order_scan`] may reduce the full regressor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ScanSolver {
    /// Normal equations when the guards of the module documentation pass, else QR.
    #[default]
    Auto,
    /// Always one Householder QR of the full regressor.
    Qr,
}

/// How the full regressor was reduced in a scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ScanMethod {
    /// Cholesky of $Z^\top Z$ accumulated by the shift structure, $O(N D)$.
    NormalEquations,
    /// Householder QR of $Z$, $O(N D^2)$.
    Qr,
}

/// The models of an ARX order scan: every combination of `na`, `nb` and `nk`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ArxScanSpec {
    /// Range of $n_a$ ($0$ gives FIR models).
    pub na: RangeInclusive<usize>,
    /// Range of $n_b$ (from $1$).
    pub nb: RangeInclusive<usize>,
    /// Delays to try (duplicates are ignored).
    pub nk: Vec<usize>,
    /// Normal equations or QR; default [`ScanSolver::Auto`].
    pub solver: ScanSolver,
}

impl ArxScanSpec {
    /// A scan over `na` × `nb` × `nk` with the default solver.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::order::ArxScanSpec;
    /// let s = ArxScanSpec::new(1..=20, 1..=20, vec![1]);
    /// assert_eq!(s.n_models(), 400);
    /// ```
    pub fn new(na: RangeInclusive<usize>, nb: RangeInclusive<usize>, nk: Vec<usize>) -> Self {
        Self {
            na,
            nb,
            nk,
            solver: ScanSolver::Auto,
        }
    }

    /// Number of models in the scan.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::order::ArxScanSpec;
    /// assert_eq!(ArxScanSpec::new(0..=2, 1..=2, vec![1, 2, 2]).n_models(), 12);
    /// ```
    pub fn n_models(&self) -> usize {
        self.na.clone().count() * self.nb.clone().count() * self.delays().len()
    }

    fn delays(&self) -> Vec<usize> {
        let mut nk = self.nk.clone();
        nk.sort_unstable();
        nk.dedup();
        nk
    }
}

/// One model of an [`OrderScan`]; serialises to a flat CSV row (the parameters are skipped).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OrderRow {
    /// $n_a$.
    pub na: usize,
    /// $n_b$.
    pub nb: usize,
    /// $n_k$.
    pub nk: usize,
    /// $d = n_a + n_b$.
    pub n_params: usize,
    /// $V_N$ on the estimation data.
    pub loss: f64,
    /// Akaike's information criterion (module documentation).
    pub aic: f64,
    /// Bayesian information criterion.
    pub bic: f64,
    /// Akaike's final prediction error.
    pub fpe: f64,
    /// One-step prediction loss $\frac1{N_v}\sum_k \varepsilon_k^2$ on the validation data.
    pub val_loss: Option<f64>,
    /// One-step prediction fit in percent on the validation data (samples $k \ge k_0$).
    pub val_fit: Option<f64>,
    /// $\hat\theta = [a_1 \dots a_{n_a}, b_1 \dots b_{n_b}]$, as [`crate::estimate::arx::arx`].
    #[serde(skip)]
    pub params: Vec<f64>,
}

impl OrderRow {
    /// The row's orders, for a follow-up [`crate::estimate::arx::arx`] fit.
    ///
    /// # Example
    /// ```
    /// use ambid_core::estimate::order::{arx_order_scan, ArxScanSpec};
    /// let u: Vec<f64> = (0..200).map(|k| ((k * 7919) % 101) as f64 - 50.0).collect();
    /// let y: Vec<f64> = (0..200).map(|k| if k > 0 { u[k - 1] + 0.01 * ((k * 13) % 7) as f64 } else { 0.0 }).collect();
    /// let scan = arx_order_scan(&y, &u, &ArxScanSpec::new(0..=1, 1..=2, vec![1]), None).unwrap();
    /// let o = scan.rows[0].orders();
    /// assert_eq!((o.na, o.nb[0], o.nk[0]), (0, 1, 1));
    /// ```
    pub fn orders(&self) -> ArxOrders {
        ArxOrders::siso(self.na, self.nb, self.nk)
    }
}

/// Result of [`arx_order_scan`]. Indices refer to [`rows`](Self::rows).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OrderScan {
    /// One row per model, ordered by $n_k$, then $n_a$, then $n_b$.
    pub rows: Vec<OrderRow>,
    /// Minimiser of the AIC.
    pub best_aic: usize,
    /// Minimiser of the BIC.
    pub best_bic: usize,
    /// Minimiser of the validation loss, when validation data were given.
    pub best_val: Option<usize>,
    /// Models with BIC within [`BIC_TOLERANCE`] of the minimum, by $d$ then BIC.
    pub candidates: Vec<usize>,
    /// The smallest candidate, `candidates[0]`.
    pub parsimonious: usize,
    /// Knee of the loss-versus-$d$ curve (module documentation).
    pub knee: Option<usize>,
    /// First sample of the common criterion window (estimation and validation data).
    pub k0: usize,
    /// Samples in the estimation criterion, $N - k_0$.
    pub n_samples: usize,
    /// Samples in the validation criterion, when validation data were given.
    pub n_val_samples: Option<usize>,
    /// How the full regressor was reduced.
    pub method: ScanMethod,
    /// $\kappa(\Phi_s)$ of the equilibrated full estimation regressor (all columns of all models).
    pub condition: f64,
}

/// Scans SISO ARX orders over `spec` on the estimation data `(y, u)`, with optional validation
/// data `(y_v, u_v)`, from one factorisation of the largest regressor (module documentation).
///
/// # Errors
/// * [`Error::InvalidArgument`]: an empty range or delay list, `nb` starting at 0, records too
///   short for the largest model (the message says how many samples are needed), a model with a
///   rank-deficient regressor (named, with the column), or validation output that is constant.
/// * [`Error::DimensionMismatch`]: `y` and `u` (or `y_v` and `u_v`) of different lengths.
/// * [`Error::NonFinite`]: a NaN or infinite sample.
///
/// # Example
/// ```
/// use ambid_core::estimate::order::{arx_order_scan, ArxScanSpec, ScanMethod};
/// use rand::{RngExt, SeedableRng};
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
/// let sim = |rng: &mut rand_chacha::ChaCha8Rng| {
///     let u: Vec<f64> = (0..1000).map(|_| rng.random::<f64>() - 0.5).collect();
///     let mut y = vec![0.0; 1000];
///     for k in 1..1000 {
///         y[k] = 0.8 * y[k - 1] + u[k - 1] + 0.1 * (rng.random::<f64>() - 0.5);
///     }
///     (y, u)
/// };
/// let (y, u) = sim(&mut rng);
/// let (yv, uv) = sim(&mut rng);
/// let spec = ArxScanSpec::new(0..=3, 1..=3, vec![0, 1]);
/// let scan = arx_order_scan(&y, &u, &spec, Some((&yv, &uv))).unwrap();
/// assert_eq!(scan.method, ScanMethod::NormalEquations);
/// let best = &scan.rows[scan.best_bic];
/// assert_eq!((best.na, best.nb, best.nk), (1, 1, 1));
/// // ARX(1, 2, 0) contains the true model too (u(k) and u(k-1)): the validation may prefer it
/// let val = &scan.rows[scan.best_val.unwrap()];
/// assert!(val.val_fit.unwrap() > 90.0);
/// ```
pub fn arx_order_scan(
    y: &[f64],
    u: &[f64],
    spec: &ArxScanSpec,
    validation: Option<(&[f64], &[f64])>,
) -> Result<OrderScan> {
    let layout = Layout::new(spec)?;
    check_data(y, &[u], 1)?;
    let n_est = layout.check_length(y.len(), "y")?;
    let n_val = match validation {
        Some((yv, uv)) => {
            check_data(yv, &[uv], 1)?;
            Some(layout.check_length(yv.len(), "validation y")?)
        }
        None => None,
    };
    let cols = layout.columns();
    let names = |j: usize| cols[j].name(1);
    layout.check_nonzero_columns(y, u, &names)?;

    let val_spread = match validation {
        Some((yv, _)) => Some(spread(&yv[layout.k0..])?),
        None => None,
    };

    // Reduce the full regressors (estimation and validation) to R, once.
    let normal = match spec.solver {
        ScanSolver::Auto => normal_equations(y, u, validation, &cols, layout.k0)?,
        ScanSolver::Qr => None,
    };
    let (est, val, method, condition) = match normal {
        Some((est, val, cond)) => (est, val, ScanMethod::NormalEquations, cond),
        None => {
            let est = qr_factor(y, u, &cols, layout.k0);
            let val = validation.map(|(yv, uv)| qr_factor(yv, uv, &cols, layout.k0));
            let cond = regressor_condition(est.r.as_ref())?;
            (est, val, ScanMethod::Qr, cond)
        }
    };

    let rank_tol = rank_tolerance(n_est, layout.d_full);
    let mut rows = Vec::with_capacity(spec.n_models());
    let nb_max = *spec.nb.end();
    for &nk in &layout.nk {
        for na in spec.na.clone() {
            // columns: y lags 1..=na, u lags nk..nk+nb_max-1, target
            let mut idx: Vec<usize> = (0..na).collect();
            idx.extend((0..nb_max).map(|j| layout.u_column(nk + j)));
            idx.push(layout.d_full);
            let m = na + nb_max;
            let sub = Mat::from_fn(est.r.nrows(), m + 1, |i, j| est.r[(i, idx[j])]);
            let rp = crate::estimate::qr_stream::r_factor(sub.as_ref());
            let z: Vec<f64> = (0..=m).map(|i| rp[(i, m)]).collect();
            for nb in spec.nb.clone() {
                let k = na + nb;
                if let Some(i) = (0..k).find(|&i| rp[(i, i)].abs() <= rank_tol) {
                    return Err(Error::invalid(
                        "spec",
                        format!(
                            "ARX(na={na}, nb={nb}, nk={nk}) cannot be identified from these data: the regressor column {} is (numerically) a linear combination of the columns before it. Narrow the order ranges or use a richer input",
                            names(idx[i])
                        ),
                    ));
                }
                let theta_s = back_substitute(rp.as_ref(), &z, k);
                let theta: Vec<f64> = (0..k)
                    .map(|j| theta_s[j] * est.scale[layout.d_full] / est.scale[idx[j]])
                    .collect();
                let ssr =
                    est.scale[layout.d_full].powi(2) * z[k..].iter().map(|v| v * v).sum::<f64>();
                let (val_loss, val_fit) = match (&val, n_val, val_spread) {
                    (Some(v), Some(nv), Some(sst)) => {
                        let ssr_v = v.ssr(&idx[..k], layout.d_full, &theta);
                        (
                            Some(ssr_v / nv as f64),
                            Some(100.0 * (1.0 - (ssr_v / sst).sqrt())),
                        )
                    }
                    _ => (None, None),
                };
                rows.push(make_row(na, nb, nk, theta, ssr, n_est, val_loss, val_fit));
            }
        }
    }
    let (best_aic, best_bic, best_val, candidates, knee) = summarise(&rows);
    Ok(OrderScan {
        parsimonious: candidates[0],
        rows,
        best_aic,
        best_bic,
        best_val,
        candidates,
        knee,
        k0: layout.k0,
        n_samples: n_est,
        n_val_samples: n_val,
        method,
        condition,
    })
}

/// $\sum_k (y_k - \bar y)^2$ of the validation window, which must not be zero.
fn spread(t: &[f64]) -> Result<f64> {
    let mean = t.iter().sum::<f64>() / t.len() as f64;
    let sst = t.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
    if sst == 0.0 {
        return Err(Error::invalid(
            "validation",
            "the validation output is constant over the criterion window, so no fit can be computed",
        ));
    }
    Ok(sst)
}

/// The normal-equations reduction of the estimation (and validation) regressors, with its
/// condition number, if it succeeds and passes the guards of the module documentation.
fn normal_equations(
    y: &[f64],
    u: &[f64],
    validation: Option<(&[f64], &[f64])>,
    cols: &[Column],
    k0: usize,
) -> Result<Option<(Reduced, Option<Reduced>, f64)>> {
    let Some(est) = gram_factor(y, u, cols, k0) else {
        return Ok(None);
    };
    let val = match validation {
        Some((yv, uv)) => match gram_factor(yv, uv, cols, k0) {
            Some(v) => Some(v),
            None => return Ok(None),
        },
        None => None,
    };
    let cond = regressor_condition(est.r.as_ref())?;
    let enough_residual = |r: &Reduced| r.residual_fraction() >= NORMAL_EQUATIONS_MIN_RESIDUAL;
    let ok = cond <= NORMAL_EQUATIONS_MAX_CONDITION
        && enough_residual(&est)
        && val.as_ref().is_none_or(enough_residual);
    Ok(ok.then_some((est, val, cond)))
}

/// The columns of the full regressor and where each model's columns sit.
struct Layout {
    na_max: usize,
    nk: Vec<usize>,
    /// Smallest and largest input lag of the full regressor.
    u_lag_min: usize,
    u_lag_max: usize,
    k0: usize,
    /// Number of regressor columns $D$ (the target is column $D$).
    d_full: usize,
}

impl Layout {
    fn new(spec: &ArxScanSpec) -> Result<Self> {
        if spec.na.is_empty() {
            return Err(Error::invalid("na", "the na range is empty"));
        }
        if spec.nb.is_empty() || *spec.nb.start() == 0 {
            return Err(Error::invalid(
                "nb",
                "the nb range must be non-empty and start at 1 or more (every model needs an input coefficient)",
            ));
        }
        let nk = spec.delays();
        let (Some(&nk_min), Some(&nk_max)) = (nk.first(), nk.last()) else {
            return Err(Error::invalid("nk", "give at least one delay nk"));
        };
        let na_max = *spec.na.end();
        let nb_max = *spec.nb.end();
        let u_lag_max = nk_max + nb_max - 1;
        let k0 = na_max.max(u_lag_max);
        let d_full = na_max + (u_lag_max - nk_min + 1);
        Ok(Self {
            na_max,
            nk,
            u_lag_min: nk_min,
            u_lag_max,
            k0,
            d_full,
        })
    }

    fn columns(&self) -> Vec<Column> {
        let mut cols: Vec<Column> = (1..=self.na_max).map(Column::y).collect();
        cols.extend((self.u_lag_min..=self.u_lag_max).map(|l| Column::u(0, l)));
        cols.push(Column::y(0));
        cols
    }

    fn u_column(&self, lag: usize) -> usize {
        self.na_max + lag - self.u_lag_min
    }

    /// Samples in the criterion, after checking there are enough.
    fn check_length(&self, n: usize, what: &str) -> Result<usize> {
        // the QR of the full regressor needs D + 1 rows, the noise variance N - d > 0
        let need = self.k0 + self.d_full + 1;
        if n < need {
            return Err(Error::invalid(
                if what == "y" { "y" } else { "validation" },
                format!(
                    "the order scan needs at least {need} samples in {what} (k0 = {} to fill the regressor of the largest model, then {} more for its {} regressor columns); got {n}. Use a longer record or smaller order ranges",
                    self.k0,
                    self.d_full + 1,
                    self.d_full
                ),
            ));
        }
        Ok(n - self.k0)
    }

    fn check_nonzero_columns(
        &self,
        y: &[f64],
        u: &[f64],
        names: &dyn Fn(usize) -> String,
    ) -> Result<()> {
        let window =
            |x: &[f64], lag: usize| x[self.k0 - lag..x.len() - lag].iter().all(|v| *v == 0.0);
        for (j, lag) in (1..=self.na_max).enumerate() {
            if window(y, lag) {
                return Err(zero_column(&names(j)));
            }
        }
        for lag in self.u_lag_min..=self.u_lag_max {
            if window(u, lag) {
                return Err(zero_column(&names(self.u_column(lag))));
            }
        }
        Ok(())
    }
}

fn zero_column(name: &str) -> Error {
    Error::invalid(
        "spec",
        format!(
            "the regressor column {name} is identically zero over the criterion window, so no model that uses it can be identified; check the signal or narrow the order ranges"
        ),
    )
}

/// An upper-triangular $R$ with $R^\top R = Z_s^\top Z_s$, $Z_s = Z\,\mathrm{diag}(1/\text{scale})$.
struct Reduced {
    r: Mat<f64>,
    scale: Vec<f64>,
}

impl Reduced {
    /// $\mathrm{SSR}/\lVert Y\rVert^2$ of the full model: $R_{DD}^2$ (the target has unit norm).
    fn residual_fraction(&self) -> f64 {
        let d = self.r.nrows();
        self.r[(d - 1, d - 1)].powi(2)
    }

    /// $\lVert Y - \Phi_S \theta\rVert^2 = \lVert R\,\mathrm{diag}(\text{scale})\,c\rVert^2$, with
    /// $c = 1$ on the target column, $-\theta$ on the columns `idx`.
    fn ssr(&self, idx: &[usize], target: usize, theta: &[f64]) -> f64 {
        let mut c: Vec<(usize, f64)> = idx
            .iter()
            .zip(theta)
            .map(|(&j, &t)| (j, -t * self.scale[j]))
            .collect();
        c.push((target, self.scale[target]));
        let mut ssr = 0.0;
        for i in 0..self.r.nrows() {
            let ri: f64 = c
                .iter()
                .filter(|(j, _)| *j >= i)
                .map(|&(j, cj)| self.r[(i, j)] * cj)
                .sum();
            ssr += ri * ri;
        }
        ssr
    }
}

/// $R$ by one Householder QR of the equilibrated full regressor.
fn qr_factor(y: &[f64], u: &[f64], cols: &[Column], k0: usize) -> Reduced {
    let mut z = build_regressor(y, &[u], cols, k0);
    let (scale, _) = equilibrate(&mut z, cols.len());
    Reduced {
        r: qr_r_in_place(z),
        scale,
    }
}

/// $R$ as the Cholesky factor of the equilibrated $Z^\top Z$, accumulated by the shift structure;
/// `None` when the factorisation breaks down.
fn gram_factor(y: &[f64], u: &[f64], cols: &[Column], k0: usize) -> Option<Reduced> {
    let y_lag_max = cols
        .iter()
        .filter(|c| c.signal == Signal::Y)
        .map(|c| c.lag)
        .max()
        .unwrap_or(0);
    let u_lag_max = cols
        .iter()
        .filter(|c| c.signal != Signal::Y)
        .map(|c| c.lag)
        .max()
        .unwrap_or(0);
    let t_yy = lagged_products(y, y, k0, y_lag_max, y_lag_max);
    let t_yu = lagged_products(y, u, k0, y_lag_max, u_lag_max);
    let t_uu = lagged_products(u, u, k0, u_lag_max, u_lag_max);
    let d = cols.len();
    let g = Mat::from_fn(d, d, |i, j| {
        let (a, b) = (cols[i], cols[j]);
        let t = match (a.signal, b.signal) {
            (Signal::Y, Signal::Y) => t_yy[(a.lag, b.lag)],
            (Signal::Y, Signal::U(_)) => t_yu[(a.lag, b.lag)],
            (Signal::U(_), Signal::Y) => t_yu[(b.lag, a.lag)],
            (Signal::U(_), Signal::U(_)) => t_uu[(a.lag, b.lag)],
        };
        a.sign() * b.sign() * t
    });
    let scale: Vec<f64> = (0..d).map(|j| g[(j, j)].max(0.0).sqrt()).collect();
    if scale.contains(&0.0) {
        return None;
    }
    let gs = Mat::from_fn(d, d, |i, j| g[(i, j)] / (scale[i] * scale[j]));
    let r = cholesky_upper(gs.as_ref())?;
    Some(Reduced { r, scale })
}

/// $T_{l,l'} = \sum_{k=k_0}^{N-1} a_{k-l}\,b_{k-l'}$ for $l \le$ `la`, $l' \le$ `lb` (both
/// $\le k_0$): the first row and column by dot products, the rest by
/// $T_{l,l'} = T_{l-1,l'-1} + a_{k_0-l} b_{k_0-l'} - a_{N-l} b_{N-l'}$.
fn lagged_products(a: &[f64], b: &[f64], k0: usize, la: usize, lb: usize) -> Mat<f64> {
    let n = a.len();
    let mut t = Mat::<f64>::zeros(la + 1, lb + 1);
    for l in 0..=lb {
        t[(0, l)] = dot(&a[k0..n], &b[k0 - l..n - l]);
    }
    for l in 1..=la {
        t[(l, 0)] = dot(&a[k0 - l..n - l], &b[k0..n]);
    }
    for j in 1..=lb {
        for i in 1..=la {
            t[(i, j)] = t[(i - 1, j - 1)] + a[k0 - i] * b[k0 - j] - a[n - i] * b[n - j];
        }
    }
    t
}

/// Upper Cholesky factor $R$ ($R^\top R = G$) of a symmetric matrix with unit diagonal; `None` if
/// a pivot is not safely positive.
fn cholesky_upper(g: MatRef<'_, f64>) -> Option<Mat<f64>> {
    let n = g.nrows();
    let mut r = Mat::<f64>::zeros(n, n);
    let tiny = n as f64 * f64::EPSILON;
    for j in 0..n {
        let s = g[(j, j)] - (0..j).map(|k| r[(k, j)].powi(2)).sum::<f64>();
        // also rejects NaN
        if s.is_nan() || s <= tiny * g[(j, j)] {
            return None;
        }
        let rjj = s.sqrt();
        r[(j, j)] = rjj;
        for i in j + 1..n {
            let v = g[(j, i)] - (0..j).map(|k| r[(k, j)] * r[(k, i)]).sum::<f64>();
            r[(j, i)] = v / rjj;
        }
    }
    Some(r)
}

/// $\kappa$ of the regressor part (all but the last column) of $R$.
fn regressor_condition(r: MatRef<'_, f64>) -> Result<f64> {
    let d = r.ncols().saturating_sub(1);
    if d == 0 {
        return Ok(1.0);
    }
    let s = crate::linalg::singular_values(r.get(..d, ..d))?;
    let (smax, smin) = (s[0], s[d - 1]);
    Ok(if smin > 0.0 {
        smax / smin
    } else {
        f64::INFINITY
    })
}

/// Solves $R_{1:k,1:k}\,x = z_{1:k}$.
fn back_substitute(r: MatRef<'_, f64>, z: &[f64], k: usize) -> Vec<f64> {
    let mut x = z[..k].to_vec();
    for i in (0..k).rev() {
        let s: f64 = (i + 1..k).map(|j| r[(i, j)] * x[j]).sum();
        x[i] = (x[i] - s) / r[(i, i)];
    }
    x
}

#[allow(clippy::too_many_arguments)]
fn make_row(
    na: usize,
    nb: usize,
    nk: usize,
    params: Vec<f64>,
    ssr: f64,
    n: usize,
    val_loss: Option<f64>,
    val_fit: Option<f64>,
) -> OrderRow {
    let d = (na + nb) as f64;
    let nf = n as f64;
    let loss = ssr / nf;
    let log_lik =
        nf * loss.max(f64::MIN_POSITIVE).ln() + nf * ((2.0 * std::f64::consts::PI).ln() + 1.0);
    OrderRow {
        na,
        nb,
        nk,
        n_params: na + nb,
        loss,
        aic: log_lik + 2.0 * d,
        bic: log_lik + d * nf.ln(),
        fpe: loss * (1.0 + d / nf) / (1.0 - d / nf),
        val_loss,
        val_fit,
        params,
    }
}

type Summary = (usize, usize, Option<usize>, Vec<usize>, Option<usize>);

/// Best AIC, BIC and validation loss, the BIC candidates and the knee (module documentation).
fn summarise(rows: &[OrderRow]) -> Summary {
    let argmin = |key: &dyn Fn(&OrderRow) -> f64| {
        (0..rows.len())
            .min_by(|&a, &b| {
                key(&rows[a])
                    .total_cmp(&key(&rows[b]))
                    .then(rows[a].n_params.cmp(&rows[b].n_params))
            })
            .unwrap_or(0)
    };
    let best_aic = argmin(&|r| r.aic);
    let best_bic = argmin(&|r| r.bic);
    let best_val = rows
        .first()
        .and_then(|r| r.val_loss)
        .map(|_| argmin(&|r| r.val_loss.unwrap_or(f64::INFINITY)));
    let bic_min = rows[best_bic].bic;
    let mut candidates: Vec<usize> = (0..rows.len())
        .filter(|&i| rows[i].bic <= bic_min + BIC_TOLERANCE)
        .collect();
    candidates.sort_by(|&a, &b| {
        rows[a]
            .n_params
            .cmp(&rows[b].n_params)
            .then(rows[a].bic.total_cmp(&rows[b].bic))
    });
    // lower envelope of the loss over d
    let mut envelope: Vec<(usize, usize)> = Vec::new(); // (d, row)
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.sort_by(|&a, &b| {
        rows[a]
            .n_params
            .cmp(&rows[b].n_params)
            .then(rows[a].loss.total_cmp(&rows[b].loss))
    });
    for i in order {
        if envelope.last().map(|e| e.0) != Some(rows[i].n_params) {
            envelope.push((rows[i].n_params, i));
        }
    }
    (
        best_aic,
        best_bic,
        best_val,
        candidates,
        knee(rows, &envelope),
    )
}

fn knee(rows: &[OrderRow], envelope: &[(usize, usize)]) -> Option<usize> {
    if envelope.len() < 3 {
        return None;
    }
    let ln = |i: usize| rows[i].loss.max(f64::MIN_POSITIVE).ln();
    let (d0, d1) = (envelope[0].0 as f64, envelope[envelope.len() - 1].0 as f64);
    let (l0, l1) = (ln(envelope[0].1), ln(envelope[envelope.len() - 1].1));
    if l0.is_nan() || l1.is_nan() || l0 <= l1 {
        return None;
    }
    let mut best: Option<(f64, usize)> = None;
    for &(d, i) in &envelope[1..envelope.len() - 1] {
        let x = (d as f64 - d0) / (d1 - d0);
        let y = (ln(i) - l1) / (l0 - l1);
        let gap = 1.0 - x - y;
        if gap > 0.0 && best.is_none_or(|(g, _)| gap > g) {
            best = Some((gap, i));
        }
    }
    best.map(|(_, i)| i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lagged_products_equal_direct_sums() {
        let a: Vec<f64> = (0..50).map(|k| ((k * 37) % 11) as f64 - 5.0).collect();
        let b: Vec<f64> = (0..50).map(|k| ((k * 53) % 7) as f64 * 0.5).collect();
        let k0 = 6;
        let t = lagged_products(&a, &b, k0, 4, 6);
        for l in 0..=4 {
            for m in 0..=6 {
                let direct: f64 = (k0..50).map(|k| a[k - l] * b[k - m]).sum();
                assert!((t[(l, m)] - direct).abs() < 1e-12 * direct.abs().max(1.0));
            }
        }
    }

    #[test]
    fn cholesky_matches_its_definition_and_rejects_singular() {
        let g = faer::mat![[1.0, 0.5, 0.2], [0.5, 1.0, 0.3], [0.2, 0.3, 1.0]];
        let r = cholesky_upper(g.as_ref()).unwrap();
        let back = r.transpose() * &r;
        for i in 0..3 {
            for j in 0..3 {
                assert!((back[(i, j)] - g[(i, j)]).abs() < 1e-15);
            }
        }
        let s = faer::mat![[1.0, 1.0], [1.0, 1.0]];
        assert!(cholesky_upper(s.as_ref()).is_none());
    }

    #[test]
    fn knee_of_an_elbow() {
        let mk = |d: usize, loss: f64| make_row(d, 0, 1, vec![], loss * 100.0, 100, None, None);
        let rows: Vec<OrderRow> = [(1, 10.0), (2, 1.0), (3, 0.9), (4, 0.85), (5, 0.8)]
            .iter()
            .map(|&(d, l)| mk(d, l))
            .collect();
        let env: Vec<(usize, usize)> = (0..5).map(|i| (i + 1, i)).collect();
        assert_eq!(knee(&rows, &env), Some(1));
        assert_eq!(knee(&rows, &env[..2]), None);
    }
}
