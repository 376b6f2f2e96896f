//! Robust stability of the current controller against a multiplicative uncertainty weight:
//! $P = \hat P (1 + W\Delta)$, $\lVert\Delta\rVert_\infty \le 1$, in the loop $u = -C y + r$.
//!
//! # The one-block test
//! With $L = \hat P C$ and $T = L/(1 + L)$, the loop is stable for every admissible $\Delta$ iff
//! the nominal loop is stable and (small gain; for one full complex block the structured
//! singular value is $|W T|$ itself)
//! $$ \mu(\omega) = |W(e^{j\omega T_s}) T(e^{j\omega T_s})| < 1 \quad \forall \omega . $$
//! The **robust stability margin** is $1/\max_\omega \mu$: the factor by which the uncertainty
//! could grow before some admissible plant destabilises the loop.
//!
//! # Robust gain margins
//! A commissioning engineer asks a different question: by how much can the controller's gain
//! be raised (or lowered) with the loop stable for every admissible plant? For $C \to gC$,
//! $|W g L| < |1 + g L|$ is, at each frequency, the quadratic inequality
//! $$ q_\omega(g) = |L|^2(|W|^2 - 1)\,g^2 - 2\operatorname{Re}(L)\, g - 1 < 0 , $$
//! whose solution set in $g > 0$ is known exactly from its roots. The robust upper gain
//! margin $g_+$ is the smallest root above 1 over the frequency grid (the end of the interval
//! around $g = 1$), the lower one $g_-$ the largest root below 1, intersected with the nominal
//! loop's gain interval found from its closed-loop poles (the gain stepped by 1 % until a pole
//! leaves the unit circle, the edge refined by bisection), so that a phase crossover between
//! grid points is not missed. For any $g \in (g_-, g_+)$ the
//! loop with $gC$ is stable for every plant of the set (the nominal loop stays stable on the
//! way because a closed-loop pole reaching the unit circle at $e^{j\omega T}$ makes
//! $|1 + gL| = 0$ there).
//!
//! # On the lines
//! [`robust_stability_on_lines`] runs the same test and margins on given lines against given
//! magnitudes — the data's frequency-wise bound itself, the usual $\mu$ analysis on a grid —
//! instead of a rational weight: its verdict does not rest on how a low-order weight
//! compromises over a ragged bound, but it says nothing between or outside the lines, where
//! only the nominal loop's gain interval enters.
//!
//! # Grid
//! 4 000 points log-spaced from $10^{-4} f_s$ to the Nyquist frequency $f_N$, and 9 points within
//! $\pm 2\zeta\omega_n$ around every lightly damped pole of $\hat P$, $C$ and $W$ (where $|T|$ and
//! $|W|$ change fastest). The weight is fitted on the measured band; outside it the bound is its
//! extrapolation (with no lightly damped factor of its own there:
//! [`weight`](super::weight), "Outside the lines"), and the margins rest on the model there.
//!
//! # Example
//! ```
//! use ambid_core::lti::StateSpace;
//! use ambid_core::validate::robust::robust_stability;
//! use ambid_core::validate::weight::Weight;
//! use faer::mat;
//! // a stable first-order loop, weight 0: the robust margins are the nominal ones
//! let p = StateSpace::discrete(mat![[0.9]], mat![[1.0]], mat![[0.1]], mat![[0.0]], 1e-3).unwrap();
//! let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[2.0]], 1e-3).unwrap();
//! let w = Weight { ts: 1e-3, gain: 1e-9, numerator: vec![], denominator: vec![] };
//! let r = robust_stability(&p, &c, &w).unwrap();
//! assert!(r.nominal_stable && r.robustly_stable);
//! // L(-1) = 0.2 * (-1) / (-1.9): the gain can rise to 1 + 0.9 * ... (pole at z = 0.9 - 0.1 g)
//! let g_true = 19.0 / 2.0; // 0.9 - 0.1 * 2 g = -1  →  g = 9.5
//! assert!((r.upper_gain_margin.unwrap() - g_true).abs() < 0.05 * g_true, "{r:?}");
//! ```

use super::weight::Weight;
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use faer::c64;
use std::f64::consts::PI;

/// What [`robust_stability`] finds.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RobustStability {
    /// The nominal closed loop ($\hat P$ with $C$) is stable.
    pub nominal_stable: bool,
    /// $\max_\omega |W T|$ on the grid.
    pub mu_peak: f64,
    /// Where \[Hz\].
    pub mu_peak_hz: f64,
    /// $1 / \mu_{\text{peak}}$ (0 when the nominal loop is unstable).
    pub stability_margin: f64,
    /// Nominally stable and $\mu < 1$ everywhere.
    pub robustly_stable: bool,
    /// $g_+$: the controller gain factor up to which every plant of the set stays stable
    /// (`None` when not robustly stable at $g = 1$; infinite when nothing limits it).
    pub upper_gain_margin: Option<f64>,
    /// $g_-$: the factor down to which it stays stable (`None` when not robustly stable).
    pub lower_gain_margin: Option<f64>,
    /// The frequency grid \[Hz\].
    pub f_hz: Vec<f64>,
    /// $\mu$ on the grid.
    pub mu: Vec<f64>,
}

/// The robust-stability analysis of the loop of `plant` ($\hat P$) and `controller` ($C$,
/// $u = -Cy + r$) against the multiplicative weight `weight` (module docs). All discrete-time,
/// SISO, with one sample time.
///
/// # Errors
/// [`Error::InvalidArgument`] for a model that is not SISO or not discrete, or sample times that
/// differ; [`Error::Numerical`] when the closed loop's poles cannot be computed.
pub fn robust_stability(
    plant: &StateSpace,
    controller: &StateSpace,
    weight: &Weight,
) -> Result<RobustStability> {
    let ts = loop_ts(plant, controller, Some(weight.ts))?;
    let f = grid(&[plant, controller], &[weight], ts)?;
    let wr = weight.magnitude(&f);
    assess(plant, controller, f, &wr)
}

/// The robust-stability analysis of the loop of `plant` and `controller` against a
/// frequency-wise bound: $|\Delta_m(e^{j\omega_k T})| \le m_k$ on the lines `f_hz` only — the
/// usual $\mu$ analysis on a frequency grid, with the data's bound itself instead of a rational
/// weight fitted over it. The same test and margins as [`robust_stability`] (module docs), on
/// the lines: they say nothing about frequencies outside them, where only the nominal loop's
/// gain interval (from its closed-loop poles) enters the margins.
///
/// # Errors
/// [`Error::InvalidArgument`] for a model that is not SISO or not discrete, sample times that
/// differ, lengths that differ, no line, frequencies not in $(0, f_N)$, or a magnitude that is
/// negative or not finite; [`Error::Numerical`] when the closed loop's poles cannot be computed.
///
/// # Example
/// ```
/// use ambid_core::lti::StateSpace;
/// use ambid_core::validate::robust::robust_stability_on_lines;
/// use faer::mat;
/// let p = StateSpace::discrete(mat![[0.9]], mat![[1.0]], mat![[0.1]], mat![[0.0]], 1e-3).unwrap();
/// let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[2.0]], 1e-3).unwrap();
/// let f: Vec<f64> = (1..500).map(|k| k as f64).collect();
/// let r = robust_stability_on_lines(&p, &c, &f, &vec![0.0; f.len()]).unwrap();
/// // with no uncertainty, the nominal loop's margin (pole at 0.9 - 0.2 g reaches -1 at g = 9.5)
/// assert!((r.upper_gain_margin.unwrap() - 9.5).abs() < 0.05 * 9.5, "{r:?}");
/// ```
pub fn robust_stability_on_lines(
    plant: &StateSpace,
    controller: &StateSpace,
    f_hz: &[f64],
    magnitude: &[f64],
) -> Result<RobustStability> {
    let ts = loop_ts(plant, controller, None)?;
    check_lines("magnitude", f_hz, magnitude.len(), ts)?;
    if magnitude.iter().any(|m| !(*m >= 0.0 && m.is_finite())) {
        return Err(Error::invalid(
            "magnitude",
            "every bound must be finite and non-negative",
        ));
    }
    assess(plant, controller, f_hz.to_vec(), magnitude)
}

/// The uncertainty of a plant with several inputs and outputs on frequency lines, for
/// [`robust_stability_matrix_on_lines`]: at line $k$,
#[derive(Debug, Clone, Copy)]
pub enum LineBound<'a> {
    /// $P = \hat P + \Delta_A$ with $|\Delta_{A,ij}| \le L_{ij,k}$ for every entry independently
    /// (the bound of
    /// [`MatrixUncertainty::bounds`](super::uncertainty::MatrixUncertainty::bounds)); one
    /// $n_y\times n_u$ matrix per line.
    Elementwise(&'a [faer::Mat<f64>]),
    /// $P = \hat P + \Delta_A$ with $\bar\sigma(\Delta_A) \le s_k$, unstructured (e.g.
    /// [`MatrixUncertainty::norm_bound`](super::uncertainty::MatrixUncertainty::norm_bound)).
    Additive(&'a [f64]),
    /// $P = \hat P(I + \Delta_I)$ with $\bar\sigma(\Delta_I) \le s_k$: input-multiplicative,
    /// unstructured (e.g.
    /// [`MatrixUncertainty::input_multiplicative_bound`](super::uncertainty::MatrixUncertainty::input_multiplicative_bound));
    /// for a SISO plant the multiplicative bound $\ell_k$.
    InputMultiplicative(&'a [f64]),
}

impl LineBound<'_> {
    fn len(&self) -> usize {
        match self {
            LineBound::Elementwise(l) => l.len(),
            LineBound::Additive(s) | LineBound::InputMultiplicative(s) => s.len(),
        }
    }

    /// The small-gain quantity at line `k`, with $M = (I + gC\hat P)^{-1} gC$ (from the
    /// additive perturbation's output to its input) and the plant's response `p`:
    /// $\rho(L_k |M|)$, $s_k\,\bar\sigma(M)$ or $s_k\,\bar\sigma(M\hat P)$.
    fn mu(&self, k: usize, m: &faer::Mat<c64>, p: &faer::Mat<c64>) -> f64 {
        let top_sv = |x: &faer::Mat<c64>| {
            x.singular_values()
                .ok()
                .and_then(|v| v.into_iter().reduce(f64::max))
                .unwrap_or(f64::INFINITY)
        };
        match self {
            LineBound::Elementwise(l) => {
                let l = &l[k];
                let abs_m = faer::Mat::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)].norm());
                let lm = l * &abs_m;
                if lm.nrows() == 1 {
                    return lm[(0, 0)].abs();
                }
                crate::linalg::eigenvalues(lm.as_ref())
                    .map(|e| e.iter().map(|z| z.norm()).fold(0.0, f64::max))
                    .unwrap_or(f64::INFINITY)
            }
            LineBound::Additive(s) if s[k] == 0.0 => 0.0,
            LineBound::InputMultiplicative(s) if s[k] == 0.0 => 0.0,
            LineBound::Additive(s) => s[k] * top_sv(m),
            LineBound::InputMultiplicative(s) => s[k] * top_sv(&(m * p)),
        }
    }

    fn check(&self, ny: usize, nu: usize) -> Result<()> {
        let ok = match self {
            LineBound::Elementwise(l) => l.iter().all(|m| {
                m.nrows() == ny
                    && m.ncols() == nu
                    && (0..ny).all(|i| (0..nu).all(|j| m[(i, j)] >= 0.0 && m[(i, j)].is_finite()))
            }),
            LineBound::Additive(s) | LineBound::InputMultiplicative(s) => {
                s.iter().all(|v| *v >= 0.0 && v.is_finite())
            }
        };
        if ok {
            Ok(())
        } else {
            Err(Error::invalid(
                "bound",
                format!(
                    "every bound must be finite and non-negative (element-wise: one {ny}×{nu} matrix per line, as the plant)"
                ),
            ))
        }
    }
}

/// Robust stability of the loop of a plant with several inputs and outputs ($\hat P$, $n_y
/// \times n_u$) and its controller ($C$, $n_u\times n_y$, $u = -Cy + r$; the decentralised
/// controller of a magnetic bearing is diagonal) against an additive uncertainty on the lines
/// `f_hz`: $P = \hat P + \Delta_A$ with $\Delta_A$ bounded by `bound` ([`LineBound`]) and
/// stable (the plant's unstable poles are the model's).
///
/// # The test
/// The perturbation sees $M = -(I + C\hat P)^{-1} C$ (from its output, added to $y$, to its
/// input $u$), so the loop stays stable for every admissible $\Delta_A$ if the nominal loop is
/// stable and $\rho(\Delta_A M) < 1$ at every frequency. For the element-wise bound,
/// $\rho(\Delta_A M) \le \rho(|\Delta_A|\,|M|) \le \rho(L |M|)$ (Perron–Frobenius: the spectral
/// radius is monotone on non-negative matrices), the standard upper bound of the structured
/// singular value for independent complex entries; for the unstructured additive one,
/// $\rho(\Delta_A M) \le s\,\bar\sigma(M)$, and for the input-multiplicative one ($\Delta_A =
/// \hat P\Delta_I$) $\rho(\Delta_I M\hat P) \le s\,\bar\sigma(T_I)$ with $T_I = M\hat P = (I +
/// C\hat P)^{-1}C\hat P$ (small gain, exact for one full block). So
/// $$ \mu_k = \rho(L_k |M_k|), \quad s_k\,\bar\sigma(M_k) \quad\text{or}\quad
///    s_k\,\bar\sigma(T_{I,k}), $$
/// the margin is $1/\max_k \mu_k$ (the factor by which the bound could grow), and for a
/// $1\times 1$ plant the element-wise and the input-multiplicative forms equal $\ell_k |T_k|$
/// with $\ell_k = L_k / |\hat P_k|$: the result of [`robust_stability_on_lines`] for the
/// multiplicative bound $\ell$.
///
/// # Robust gain margins
/// All controllers' gains together, $C \to gC$ (the commissioning engineer's question for a
/// decentralised controller): $M(g) = (I + gC\hat P)^{-1} gC$. From $g = 1$ the gain is stepped
/// by 2 % up (down) until $\max_k \mu_k(g) \ge 1$ or the nominal loop's gain interval
/// ([`nominal_gain_interval`], from its closed-loop poles) ends; the edge is refined by bisection
/// to $10^{-6}$ relative. A crossing that enters and leaves within one step is missed (the SISO
/// function solves the per-line quadratic exactly instead). Margins at $10^3$ ($10^{-3}$) are
/// reported unlimited ($\infty$, 0).
///
/// # Errors
/// [`Error::InvalidArgument`] for models that are not discrete with one sample time, a controller
/// whose size is not the plant's transpose, no line, lines outside $(0, f_N)$, a bound of another
/// length or size, or one that is negative or not finite; [`Error::Numerical`] when the closed
/// loop's poles cannot be computed.
///
/// # Example
/// Two decoupled first-order loops with no uncertainty: the margins are the nominal ones, set by
/// the loop that fails first (poles $0.9 - 0.2g$ and $0.5 - 0.2g$ reach $-1$ at $g = 9.5$ and
/// $g = 7.5$); no lower limit (the plants are stable).
/// ```
/// use ambid_core::lti::StateSpace;
/// use ambid_core::validate::robust::{robust_stability_matrix_on_lines, LineBound};
/// use faer::{mat, Mat};
/// let p = StateSpace::discrete(mat![[0.9, 0.0], [0.0, 0.5]], mat![[1.0, 0.0], [0.0, 1.0]],
///     mat![[0.1, 0.0], [0.0, 0.1]], mat![[0.0, 0.0], [0.0, 0.0]], 1e-3).unwrap();
/// let c = StateSpace::discrete(Mat::zeros(0, 0), Mat::zeros(0, 2), Mat::zeros(2, 0),
///     mat![[2.0, 0.0], [0.0, 2.0]], 1e-3).unwrap();
/// let f: Vec<f64> = (1..500).map(|k| k as f64).collect();
/// let none = vec![Mat::<f64>::zeros(2, 2); f.len()];
/// let r = robust_stability_matrix_on_lines(&p, &c, &f, LineBound::Elementwise(&none)).unwrap();
/// assert!(r.robustly_stable);
/// assert!((r.upper_gain_margin.unwrap() - 7.5).abs() < 1e-3, "{r:?}");
/// assert_eq!(r.lower_gain_margin, Some(0.0));
/// ```
pub fn robust_stability_matrix_on_lines(
    plant: &StateSpace,
    controller: &StateSpace,
    f_hz: &[f64],
    bound: LineBound<'_>,
) -> Result<RobustStability> {
    let ts = matrix_loop_ts(plant, controller)?;
    check_lines("bound", f_hz, bound.len(), ts)?;
    bound.check(plant.noutputs(), plant.ninputs())?;
    assess_matrix(plant, controller, f_hz.to_vec(), bound)
}

/// The uncertainty weight of a plant with several inputs and outputs, for
/// [`robust_stability_matrix_weight`]; every $\Delta$ stable.
#[derive(Debug, Clone, Copy)]
pub enum MatrixWeight<'a> {
    /// Additive and unstructured, $P = \hat P + w\Delta$, $\bar\sigma(\Delta) \le 1$ ($w$ in
    /// the plant's units, fitted over
    /// [`MatrixUncertainty::norm_bound`](super::uncertainty::MatrixUncertainty::norm_bound)).
    Additive(&'a Weight),
    /// Input-multiplicative and unstructured, $P = \hat P(I + w\Delta)$,
    /// $\bar\sigma(\Delta) \le 1$ (fitted over
    /// [`MatrixUncertainty::input_multiplicative_bound`](super::uncertainty::MatrixUncertainty::input_multiplicative_bound)).
    InputMultiplicative(&'a Weight),
    /// Relative per entry, structured: $P_{ij} = \hat P_{ij}(1 + W_{ij}\delta_{ij})$ with
    /// independent $|\delta_{ij}| \le 1$ (the weights of
    /// [`MatrixUncertainty::entry_weights`](super::uncertainty::MatrixUncertainty::entry_weights),
    /// entry $(i, j)$ at index $i + j\,n_y$). The additive perturbation is bounded element-wise
    /// by $|\hat P_{ij}|\,|W_{ij}|$, so the test is the element-wise one,
    /// $\mu = \rho\big((|\hat P| \circ |W|)\,|M|\big)$; for a $1\times 1$ plant
    /// $|W|\,|T|$, the test of [`robust_stability`]. Relative weights follow the model's
    /// roll-off outside the band they were fitted on (an additive weight flattens there, where
    /// $M \approx C$ is large).
    EntryRelative(&'a [Weight]),
    /// Additive per entry, structured: $P_{ij} = \hat P_{ij} + W_{ij}\delta_{ij}$ with
    /// independent $|\delta_{ij}| \le 1$; $\mu = \rho(|W|\,|M|)$.
    EntryAdditive(&'a [Weight]),
}

impl MatrixWeight<'_> {
    fn weights(&self) -> Vec<&Weight> {
        match self {
            MatrixWeight::Additive(w) | MatrixWeight::InputMultiplicative(w) => vec![w],
            MatrixWeight::EntryRelative(w) | MatrixWeight::EntryAdditive(w) => w.iter().collect(),
        }
    }

    /// That every weight has the sample time `ts` and that an entry form has one weight per
    /// entry of an $n_y\times n_u$ plant.
    fn check(&self, ts: f64, ny: usize, nu: usize) -> Result<()> {
        let weights = self.weights();
        if weights.iter().any(|w| (w.ts - ts).abs() > 1e-9 * ts) {
            return Err(Error::invalid(
                "weight",
                "every weight must have the plant's sample time",
            ));
        }
        let entries = matches!(
            self,
            MatrixWeight::EntryRelative(_) | MatrixWeight::EntryAdditive(_)
        );
        if entries && weights.len() != ny * nu {
            return Err(Error::invalid(
                "weight",
                format!(
                    "an entry weight needs one weight per entry ({} for a {ny}×{nu} plant), got {}",
                    ny * nu,
                    weights.len()
                ),
            ));
        }
        Ok(())
    }

    /// An element-wise bound $R_{ij}$ of the additive perturbation the weight admits at each
    /// frequency of `f` (the plant's responses `p` there), flat row-major: $|\hat P_{ij}|
    /// |W_{ij}|$ (entry-relative), $|W_{ij}|$ (entry-additive), $|w|$ (additive:
    /// $|\Delta_{ij}| \le \bar\sigma(\Delta)$) and $|w|\,\lVert \hat P_{i,:}\rVert_2$
    /// (input-multiplicative: $|(\hat P\Delta)_{ij}| \le \lVert \hat P_{i,:}\rVert_2
    /// \lVert\Delta_{:,j}\rVert_2$). The unstructured forms' sets lie inside these, so a test
    /// against them is conservative for those forms.
    fn elementwise(&self, f: &[f64], p: &[faer::Mat<c64>]) -> Vec<Vec<f64>> {
        let mags: Vec<Vec<f64>> = self.weights().iter().map(|w| w.magnitude(f)).collect();
        p.iter()
            .enumerate()
            .map(|(k, pk)| {
                let (ny, nu) = (pk.nrows(), pk.ncols());
                (0..ny)
                    .flat_map(|i| (0..nu).map(move |j| (i, j)))
                    .map(|(i, j)| match self {
                        MatrixWeight::EntryRelative(_) => pk[(i, j)].norm() * mags[i + j * ny][k],
                        MatrixWeight::EntryAdditive(_) => mags[i + j * ny][k],
                        MatrixWeight::Additive(_) => mags[0][k],
                        MatrixWeight::InputMultiplicative(_) => {
                            mags[0][k] * (0..nu).map(|q| pk[(i, q)].norm_sqr()).sum::<f64>().sqrt()
                        }
                    })
                    .collect()
            })
            .collect()
    }
}

/// [`robust_stability_matrix_on_lines`] against a rational weight ([`MatrixWeight`]) on the grid
/// of [`robust_stability`] (module docs, "Grid", with the lightly damped poles of every weight).
/// Outside the band it was fitted on, a weight is its extrapolation: a rising additive weight
/// meets $\bar\sigma(M) \approx \bar\sigma(C)$, large for a PID controller, while $T_I$ and
/// $|\hat P_{ij}|$ roll off, so the input-multiplicative and the entry-relative forms are the
/// ones whose verdict rests on the band.
///
/// # Errors
/// As [`robust_stability_matrix_on_lines`], a weight of another sample time, and for
/// [`MatrixWeight::EntryRelative`] a number of weights other than $n_y n_u$.
///
/// # Example
/// A decoupled 2×2 loop with a flat 10 % relative weight on every entry: the margin is
/// $1/\max_k(0.1\,\max_i |T_{ii}|)$, set by the loop whose $|T|$ peaks highest.
/// ```
/// use ambid_core::lti::StateSpace;
/// use ambid_core::validate::robust::{robust_stability_matrix_weight, MatrixWeight};
/// use ambid_core::validate::weight::Weight;
/// use faer::{mat, Mat};
/// let p = StateSpace::discrete(mat![[0.9, 0.0], [0.0, 0.5]], mat![[1.0, 0.0], [0.0, 1.0]],
///     mat![[0.1, 0.0], [0.0, 0.1]], mat![[0.0, 0.0], [0.0, 0.0]], 1e-3).unwrap();
/// let c = StateSpace::discrete(Mat::zeros(0, 0), Mat::zeros(0, 2), Mat::zeros(2, 0),
///     mat![[2.0, 0.0], [0.0, 2.0]], 1e-3).unwrap();
/// let w = Weight { ts: 1e-3, gain: 0.1, numerator: vec![], denominator: vec![] };
/// let ws = vec![w; 4];
/// let r = robust_stability_matrix_weight(&p, &c, MatrixWeight::EntryRelative(&ws)).unwrap();
/// // T_ii = 0.2 / (z − 0.7) and 0.2 / (z − 0.3) peak at z → 1 (the grid's lowest line):
/// // 0.2 / 0.3 = 0.667 and 0.2 / 0.7 = 0.286, so μ peaks at 0.1 · 0.667
/// assert!((r.mu_peak - 0.1 * 0.2 / 0.3).abs() < 1e-3, "{}", r.mu_peak);
/// assert!(r.robustly_stable);
/// ```
pub fn robust_stability_matrix_weight(
    plant: &StateSpace,
    controller: &StateSpace,
    weight: MatrixWeight<'_>,
) -> Result<RobustStability> {
    let ts = matrix_loop_ts(plant, controller)?;
    let (ny, nu) = (plant.noutputs(), plant.ninputs());
    weight.check(ts, ny, nu)?;
    let f = grid(&[plant, controller], &weight.weights(), ts)?;
    match weight {
        MatrixWeight::Additive(w) => {
            let s = w.magnitude(&f);
            assess_matrix(plant, controller, f, LineBound::Additive(&s))
        }
        MatrixWeight::InputMultiplicative(w) => {
            let s = w.magnitude(&f);
            assess_matrix(plant, controller, f, LineBound::InputMultiplicative(&s))
        }
        MatrixWeight::EntryRelative(_) | MatrixWeight::EntryAdditive(_) => {
            let pl = plant.freq_response(&f)?;
            let bounds: Vec<faer::Mat<f64>> = weight
                .elementwise(&f, &pl)
                .into_iter()
                .map(|r| faer::Mat::from_fn(ny, nu, |i, j| r[i * nu + j]))
                .collect();
            assess_matrix(plant, controller, f, LineBound::Elementwise(&bounds))
        }
    }
}

/// What [`robust_stability_matrix_drawn`] finds: the robust gain margins that a fraction
/// `confidence` of the drawn error matrices meet.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DrawnRobustStability {
    /// The fraction of the draws the margins hold for.
    pub confidence: f64,
    /// The nominal closed loop is stable.
    pub nominal_stable: bool,
    /// The fraction of the draws whose set (the draw plus the remainder) is stable with the
    /// controller as it is ($g = 1$).
    pub stable_fraction: f64,
    /// Nominally stable and `stable_fraction` $\ge$ `confidence`.
    pub robustly_stable: bool,
    /// $g_+$: at least the fraction `confidence` of the draws stay stable for every gain in
    /// $[1, g_+)$ (`None` when not robustly stable; infinite when nothing limits it).
    pub upper_gain_margin: Option<f64>,
    /// $g_-$: the same downwards (`None` when not robustly stable).
    pub lower_gain_margin: Option<f64>,
    /// Per draw, its interval $(g_-, g_+)$; $(1, 1)$ for a draw not stable at $g = 1$.
    pub per_draw: Vec<[f64; 2]>,
    /// With a weight for the frequencies outside the lines, the gain interval in which the loop
    /// passes the element-wise test against it there, up to an octave beyond the lines (within
    /// the nominal loop's interval; $(1, 1)$ when it fails at $g = 1$); it caps every draw's
    /// interval. `None` without one.
    pub outside_gain_interval: Option<[f64; 2]>,
    /// Where \[Hz\] that test fails just below and just above the interval (`None` at an end
    /// the nominal loop's interval, not the test, set).
    pub outside_critical_hz: [Option<f64>; 2],
}

/// Robust gain margins of the loop of a plant with several inputs and outputs against drawn
/// error matrices that keep the coherence between the entries, each with an element-wise
/// remainder of unknown phase (the draws of
/// [`MatrixUncertainty::coherent_draws`](super::uncertainty::MatrixUncertainty::coherent_draws);
/// docs/uncertainty.md, "Coherent draws for the machine").
///
/// # The test per draw
/// Draw $d$ claims $P = \hat P + D_{d} + \Delta_R$ on the lines with $|\Delta_{R,ij,k}| \le
/// R_{ij,k}$, every entry's phase free. With $M_k(g) = (I + gC\hat P)^{-1}gC$ the loop with $gC$
/// passes from $\hat P$ to every such plant without a closed-loop pole crossing the unit circle
/// if the nominal loop is stable and, at every line,
/// $$ \rho\big(M_k D_{d,k}\big) < 1 \quad\text{and}\quad
///    \rho\big(R_k\,|X_k|\big) < 1, \qquad X_k = (I + M_k D_{d,k})^{-1} M_k : $$
/// the first keeps $\det(I + \tau M D)$ away from 0 for $\tau \in [0, 1]$ (the path from
/// $\hat P$ to $\hat P + D_d$), the second is the element-wise test of
/// [`robust_stability_matrix_on_lines`] around $\hat P + D_d$, whose $M$ is $X$. Both use the
/// norm bound first ($\rho \le \min(\lVert\cdot\rVert_1, \lVert\cdot\rVert_\infty)$, then
/// Collatz–Wielandt's bound of the Perron root) and eigenvalues only where that is not below 1.
/// The test runs on the lines and, when the lines are increasing, at points around the nominal
/// loop's lightly damped closed-loop poles at that gain ($|z| \ge 0.9$; at the pole's
/// frequency and $\pm\tfrac12, \pm 1, \pm 2$ half-bandwidths), where $M$ is evaluated exactly
/// and $D_d$ and $R$ are interpolated linearly between the neighbouring lines: near the loop's
/// own stability edge $|M|$ peaks over a band that can be narrower than the lines' spacing.
/// Unlike the element-wise bound alone, the draw does not let the entries' errors take the
/// phases that line up worst against the loop: the draws hold the error model's phases and
/// their correlation, and only $R$ is taken at its worst.
///
/// # Outside the lines
/// The draws say nothing outside the lines' span, yet the loop can go unstable there first (a
/// mode or the phase lag above the excited band). With `outside = Some(w)` the error there is
/// bounded element-wise by the weight's $R$ (for an entry-relative weight $|\hat P_{ij}|
/// |W_{ij}|$, its extrapolation beyond the band it was fitted on; the unstructured forms by the
/// element-wise set that contains theirs) and tested with $D = 0$ on the grid of
/// [`robust_stability`] within an octave beyond the span on each side ($[f_1/2, f_1)$ and
/// $(f_K, 2 f_K]$) and at the nominal loop's closed-loop points there. That test is the same
/// for every draw: the gain interval in which it holds (`outside_gain_interval`, 2 % steps,
/// bisection to $10^{-6}$) caps every draw's interval, and `outside_critical_hz` says where it
/// fails. Farther out a weight fitted on the lines bounds nothing (on one machine rig its
/// extrapolation was 1.5 % at 5.4 kHz where the true error was 118 %), so there, as with
/// `None` everywhere outside the lines, only the nominal loop's gain interval enters, as in
/// [`robust_stability_matrix_on_lines`]: margins set there rest on the model and can exceed
/// the true loop's.
///
/// # Margins
/// Per draw the gain is stepped by 2 % from 1 up (down) until the test fails or the nominal
/// loop's gain interval ([`nominal_gain_interval`]) ends, and the edge is refined by bisection
/// to $10^{-3}$ relative (its lower end kept). The reported $g_+$ is the value at least $\lceil cN\rceil$ of the $N$
/// draws reach ($c$ = `confidence`), $g_-$ likewise. Margins at $10^3$ ($10^{-3}$) are
/// reported unlimited ($\infty$, 0). These are margins *at a confidence* under the error
/// model, not a worst case over a set: the element-wise check of
/// [`robust_stability_matrix_on_lines`] stays the worst-case one.
///
/// # Errors
/// [`Error::InvalidArgument`] for models that are not discrete with one sample time, a controller
/// whose size is not the plant's transpose, no line, lines outside $(0, f_N)$, no draw, draws or
/// a remainder of another length or size, non-finite values or a negative remainder, a
/// confidence outside (0, 1], or an outside weight of another sample time or (entry forms) not
/// one per entry; [`Error::Numerical`] when the closed loop's poles cannot be computed.
///
/// # Example
/// Two decoupled first-order loops (poles $0.9 - 0.2g$ and $0.5 - 0.2g$, nominal upper margin
/// 7.5) and one draw that raises the second plant's gain by 10 % at every line: that plant's
/// pole is then $0.5 - 0.22g$, at $-1$ for $g = 6.82$. The draw is exact on the lines, so the
/// margin is close to it (the test is the small-gain one on the draw, hence at or below it).
/// ```
/// use ambid_core::lti::{Frd, StateSpace};
/// use ambid_core::validate::robust::robust_stability_matrix_drawn;
/// use faer::{mat, Mat};
/// let p = StateSpace::discrete(mat![[0.9, 0.0], [0.0, 0.5]], mat![[1.0, 0.0], [0.0, 1.0]],
///     mat![[0.1, 0.0], [0.0, 0.1]], mat![[0.0, 0.0], [0.0, 0.0]], 1e-3).unwrap();
/// let c = StateSpace::discrete(Mat::zeros(0, 0), Mat::zeros(0, 2), Mat::zeros(2, 0),
///     mat![[2.0, 0.0], [0.0, 2.0]], 1e-3).unwrap();
/// let f: Vec<f64> = (1..500).map(|k| k as f64).collect();
/// let r = Frd::from_model(&p, &f).unwrap();
/// let draw: Vec<Mat<faer::c64>> = (0..f.len())
///     .map(|k| { let m = r.at(k).unwrap(); Mat::from_fn(2, 2, |i, j| if (i, j) == (1, 1) { m[(1, 1)] * 0.1 } else { m[(i, j)] * 0.0 }) })
///     .collect();
/// let rest = vec![Mat::<f64>::zeros(2, 2); f.len()];
/// let out = robust_stability_matrix_drawn(&p, &c, &f, &[draw], &rest, None, 0.95).unwrap();
/// assert!(out.robustly_stable);
/// let g = out.upper_gain_margin.unwrap();
/// assert!(g <= 1.5 / 0.22 + 1e-3 && g > 6.0, "{g}");
/// ```
pub fn robust_stability_matrix_drawn(
    plant: &StateSpace,
    controller: &StateSpace,
    f_hz: &[f64],
    draws: &[Vec<faer::Mat<c64>>],
    remainder: &[faer::Mat<f64>],
    outside: Option<MatrixWeight<'_>>,
    confidence: f64,
) -> Result<DrawnRobustStability> {
    use rayon::prelude::*;
    let ts = matrix_loop_ts(plant, controller)?;
    check_lines("remainder", f_hz, remainder.len(), ts)?;
    LineBound::Elementwise(remainder).check(plant.noutputs(), plant.ninputs())?;
    let (ny, nu) = (plant.noutputs(), plant.ninputs());
    if draws.is_empty() {
        return Err(Error::invalid("draws", "needs at least one draw"));
    }
    if !(confidence > 0.0 && confidence <= 1.0) {
        return Err(Error::invalid(
            "confidence",
            format!("must lie in (0, 1], got {confidence}"),
        ));
    }
    let shape_ok = draws.iter().all(|d| {
        d.len() == f_hz.len()
            && d.iter().all(|m| {
                m.nrows() == ny
                    && m.ncols() == nu
                    && (0..ny).all(|i| {
                        (0..nu).all(|j| m[(i, j)].re.is_finite() && m[(i, j)].im.is_finite())
                    })
            })
    });
    if !shape_ok {
        return Err(Error::invalid(
            "draws",
            format!(
                "every draw needs one finite {ny}×{nu} matrix per line ({} lines)",
                f_hz.len()
            ),
        ));
    }
    if let Some(w) = &outside {
        w.check(ts, ny, nu)?;
    }
    let nominal_stable = loop_stable(plant, controller, 1.0)?;
    let n = draws.len();
    if !nominal_stable {
        return Ok(DrawnRobustStability {
            confidence,
            nominal_stable,
            stable_fraction: 0.0,
            robustly_stable: false,
            upper_gain_margin: None,
            lower_gain_margin: None,
            per_draw: vec![[1.0, 1.0]; n],
            outside_gain_interval: outside.map(|_| [1.0, 1.0]),
            outside_critical_hz: [None, None],
        });
    }
    let (n_lo, n_hi) = nominal_gain_interval(plant, controller)?;
    // outside the lines' span the draws know nothing: there the weight, if given, bounds the
    // error element-wise, the same for every draw
    let span = (
        f_hz.iter().copied().fold(f64::INFINITY, f64::min),
        f_hz.iter().copied().fold(0.0, f64::max),
    );
    let cap = outside
        .map(|w| outside_interval(plant, controller, span, w, (n_lo, n_hi)))
        .transpose()?;
    let out_interval = cap.as_ref().map(|c| c.interval);
    let (n_lo, n_hi) = match out_interval {
        Some((a, b)) => (n_lo.max(a), n_hi.min(b)),
        None => (n_lo, n_hi),
    };
    let pl = plant.freq_response(f_hz)?;
    let cr = controller.freq_response(f_hz)?;
    let lines = f_hz.len();
    // flat row-major copies for the small dense arithmetic of the per-line test
    let (pf, cf): (Vec<Vec<c64>>, Vec<Vec<c64>>) =
        (pl.iter().map(flat).collect(), cr.iter().map(flat).collect());
    let df: Vec<Vec<Vec<c64>>> = draws.iter().map(|d| d.iter().map(flat).collect()).collect();
    let rf: Vec<Vec<f64>> = remainder
        .iter()
        .map(|m| {
            (0..ny)
                .flat_map(|i| (0..nu).map(move |j| m[(i, j)]))
                .collect()
        })
        .collect();
    // M_k(g) = (I + gCP̂)⁻¹ gC per line (n_u × n_y; None where singular: the test fails there)
    let m_line = |g: f64, k: usize| small::loop_m(&cf[k], &pf[k], g, nu, ny);
    // M at the lines and at points around the nominal loop's lightly damped closed-loop poles
    // within the lines' span, where the draw and the remainder are interpolated between lines
    let probe_at = |g: f64| -> Probe {
        let mut ms: Vec<Option<Vec<c64>>> = (0..lines).map(|k| m_line(g, k)).collect();
        let pts = closed_loop_points(plant, controller, g, f_hz);
        if !pts.is_empty() {
            let fx: Vec<f64> = pts.iter().map(|p| p.0).collect();
            match (plant.freq_response(&fx), controller.freq_response(&fx)) {
                (Ok(px), Ok(cx)) => {
                    for (pk, ck) in px.iter().zip(&cx) {
                        ms.push(small::loop_m(&flat(ck), &flat(pk), g, nu, ny));
                    }
                }
                // where the responses cannot be evaluated the test fails there
                _ => ms.extend(pts.iter().map(|_| None)),
            }
        }
        Probe {
            ms,
            between: pts.into_iter().map(|p| (p.1, p.2)).collect(),
        }
    };
    let ok_draw = |probe: &Probe, d: &[Vec<c64>]| -> bool {
        let mut scratch = small::Scratch::new(ny, nu);
        let on_lines = probe.ms[..lines]
            .iter()
            .zip(d)
            .zip(&rf)
            .all(|((m, dk), rk)| m.as_ref().is_some_and(|m| scratch.line_ok(m, dk, rk)));
        on_lines
            && probe.ms[lines..]
                .iter()
                .zip(&probe.between)
                .all(|(m, &(k, w))| {
                    let dk: Vec<c64> = d[k]
                        .iter()
                        .zip(&d[k + 1])
                        .map(|(a, b)| *a * (1.0 - w) + *b * w)
                        .collect();
                    let rk: Vec<f64> = rf[k]
                        .iter()
                        .zip(&rf[k + 1])
                        .map(|(a, b)| a * (1.0 - w) + b * w)
                        .collect();
                    m.as_ref().is_some_and(|m| scratch.line_ok(m, &dk, &rk))
                })
    };
    // the same test at a gain of its own (a bisection's probe); the draws failing in one step
    // share a bracket, so their bisections meet the same gains: each probe is computed once
    let cache: std::sync::Mutex<std::collections::HashMap<u64, std::sync::Arc<Probe>>> =
        std::sync::Mutex::new(std::collections::HashMap::new());
    let ok_at = |g: f64, d: &[Vec<c64>]| -> bool {
        let hit = cache.lock().ok().and_then(|c| c.get(&g.to_bits()).cloned());
        let probe = hit.unwrap_or_else(|| {
            let p = std::sync::Arc::new(probe_at(g));
            if let Ok(mut c) = cache.lock() {
                c.insert(g.to_bits(), p.clone());
            }
            p
        });
        ok_draw(&probe, d)
    };
    let ms1 = probe_at(1.0);
    let outside_ok = out_interval.is_none_or(|(a, b)| a < 1.0 && b > 1.0);
    let stable: Vec<bool> = df
        .par_iter()
        .map(|d| outside_ok && ok_draw(&ms1, d))
        .collect();
    // one direction: every draw stable at 1 walked in 2 % steps (the lines' M shared per step),
    // each failure bracketed and refined on its own
    let edges = |up: bool| -> Vec<f64> {
        let limit = if up { n_hi.min(1e3) } else { n_lo.max(1e-3) };
        let step = if up { 1.02 } else { 1.0 / 1.02 };
        let mut edge: Vec<Option<f64>> = stable
            .iter()
            .map(|s| if *s { None } else { Some(1.0) })
            .collect();
        let mut good = 1.0f64;
        loop {
            let next = good * step;
            let past = if up { next >= limit } else { next <= limit };
            let probe = if past { limit } else { next };
            let ms = probe_at(probe);
            let alive: Vec<usize> = (0..n).filter(|i| edge[*i].is_none()).collect();
            let failed: Vec<(usize, f64)> = alive
                .par_iter()
                .filter(|i| !ok_draw(&ms, &df[**i]))
                .map(|i| {
                    let (mut a, mut b) = (good, probe);
                    while (b - a).abs() > 1e-3 * a {
                        let mid = 0.5 * (a + b);
                        if ok_at(mid, &df[*i]) {
                            a = mid;
                        } else {
                            b = mid;
                        }
                    }
                    (*i, a)
                })
                .collect();
            for (i, a) in failed {
                edge[i] = Some(a);
            }
            if past || edge.iter().all(Option::is_some) {
                let open = if up && limit >= 1e3 {
                    f64::INFINITY
                } else if !up && limit <= 1e-3 {
                    0.0
                } else {
                    limit
                };
                return edge.into_iter().map(|e| e.unwrap_or(open)).collect();
            }
            good = next;
        }
    };
    let (hi, lo) = (edges(true), edges(false));
    let stable_fraction = stable.iter().filter(|s| **s).count() as f64 / n as f64;
    let robustly_stable = stable_fraction >= confidence;
    let rank = ((confidence * n as f64).ceil() as usize).clamp(1, n) - 1;
    let (upper, lower) = if robustly_stable {
        let mut h = hi.clone();
        h.sort_by(|a, b| b.total_cmp(a));
        let mut l = lo.clone();
        l.sort_by(f64::total_cmp);
        (Some(h[rank]), Some(l[rank]))
    } else {
        (None, None)
    };
    Ok(DrawnRobustStability {
        confidence,
        nominal_stable,
        stable_fraction,
        robustly_stable,
        upper_gain_margin: upper,
        lower_gain_margin: lower,
        per_draw: lo.into_iter().zip(hi).map(|(a, b)| [a, b]).collect(),
        outside_gain_interval: out_interval.map(|(a, b)| [a, b]),
        outside_critical_hz: cap.map_or([None, None], |c| c.critical_hz),
    })
}

/// The matrices $M(g)$ of one gain in [`robust_stability_matrix_drawn`]: at every line, then at
/// the points `between` lines $k$ and $k + 1$ at the fraction $w$.
struct Probe {
    ms: Vec<Option<Vec<c64>>>,
    between: Vec<(usize, f64)>,
}

/// The frequencies around the nominal loop's lightly damped closed-loop poles (gain `g`) in
/// the span of the module's grid, $(10^{-4} f_s, f_N)$: for a pole $z = r e^{j\theta}$ with $r \ge 0.9$, the frequency $f_p = \theta /
/// (2\pi T_s)$ and its half-bandwidth $h = -\ln r / (2\pi T_s)$, the points $f_p + h\,\{0,
/// \pm\tfrac12, \pm 1, \pm 2\}$. Near the loop's own stability edge $|M|$ peaks within $h$ of
/// $f_p$, which may be far narrower than the lines' spacing; none when the poles cannot be
/// computed.
fn closed_loop_freqs(plant: &StateSpace, controller: &StateSpace, g: f64) -> Vec<f64> {
    let Some(ts) = plant.ts() else {
        return Vec::new();
    };
    let poles = with_gain(controller, g)
        .and_then(|c| plant.feedback(&c))
        .and_then(|cl| cl.poles())
        .unwrap_or_default();
    let mut out = Vec::new();
    for z in poles {
        let r = z.norm();
        if !(r >= 0.9 && z.im > 0.0) {
            continue;
        }
        let fp = z.im.atan2(z.re) / (2.0 * PI * ts);
        let h = (-r.ln()).max(0.0) / (2.0 * PI * ts);
        for s in [-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0] {
            let x = fp + s * h;
            if x > 1e-4 / ts && x < 0.5 / ts {
                out.push(x);
            }
        }
    }
    out
}

/// [`closed_loop_freqs`] within the span of the increasing lines `f`, as `(f, k, w)`: the
/// frequency, the line below and the fraction towards the next.
fn closed_loop_points(
    plant: &StateSpace,
    controller: &StateSpace,
    g: f64,
    f: &[f64],
) -> Vec<(f64, usize, f64)> {
    if f.len() < 2 || f.windows(2).any(|w| w[1] <= w[0]) {
        return Vec::new();
    }
    let (lo, hi) = (f[0], f[f.len() - 1]);
    closed_loop_freqs(plant, controller, g)
        .into_iter()
        .filter(|x| *x > lo && *x < hi)
        .map(|x| {
            // the line below x (f is increasing)
            let k = f
                .partition_point(|v| *v <= x)
                .saturating_sub(1)
                .min(f.len() - 2);
            let w = ((x - f[k]) / (f[k + 1] - f[k])).clamp(0.0, 1.0);
            (x, k, w)
        })
        .collect()
}

/// The gain interval around 1 in which the loop of [`robust_stability_matrix_drawn`] passes the
/// element-wise test against `weight` at the frequencies outside the lines' span `(lo, hi)`,
/// up to an octave beyond it ($[lo/2, lo)$ and $(hi, 2\,hi]$): the grid of the module docs
/// (with the weights' and both models' lightly damped poles) there and the nominal loop's
/// closed-loop points ([`closed_loop_freqs`]) there,
/// every point tested with $D = 0$ and $R$ the weight's element-wise bound
/// ([`MatrixWeight::elementwise`]); walked by [`gain_edge`] in 2 % steps within `limits`,
/// with the frequency where the test fails just past each end. `(1, 1)` when the test fails at
/// $g = 1$.
fn outside_interval(
    plant: &StateSpace,
    controller: &StateSpace,
    span: (f64, f64),
    weight: MatrixWeight<'_>,
    limits: (f64, f64),
) -> Result<OutsideCap> {
    let ts = matrix_loop_ts(plant, controller)?;
    let (ny, nu) = (plant.noutputs(), plant.ninputs());
    // outside the span, up to an octave beyond it on each side
    let beyond = |x: f64| (x < span.0 && x >= 0.5 * span.0) || (x > span.1 && x <= 2.0 * span.1);
    let fixed: Vec<f64> = grid(&[plant, controller], &weight.weights(), ts)?
        .into_iter()
        .filter(|x| beyond(*x))
        .collect();
    // the responses and the bound at frequencies `x`, flat row-major
    let at = |x: &[f64]| -> Result<Vec<Point>> {
        let (px, cx) = (plant.freq_response(x)?, controller.freq_response(x)?);
        let rx = weight.elementwise(x, &px);
        Ok(px
            .iter()
            .zip(&cx)
            .zip(rx)
            .map(|((p, c), r)| (flat(p), flat(c), r))
            .collect())
    };
    let points = at(&fixed)?;
    let zero = vec![c64::new(0.0, 0.0); ny * nu];
    // the first frequency where the test fails at gain g (None: it holds everywhere)
    let first_failure = |g: f64| -> Result<Option<f64>> {
        let near: Vec<f64> = closed_loop_freqs(plant, controller, g)
            .into_iter()
            .filter(|x| beyond(*x))
            .collect();
        let extra = at(&near)?;
        let mut scratch = small::Scratch::new(ny, nu);
        let fails = points
            .iter()
            .chain(&extra)
            .zip(fixed.iter().chain(&near))
            .find(|((p, c, r), _)| {
                !small::loop_m(c, p, g, nu, ny).is_some_and(|m| scratch.line_ok(&m, &zero, r))
            });
        Ok(fails.map(|(_, x)| *x))
    };
    let ok = |g: f64| -> Result<bool> { Ok(first_failure(g)?.is_none()) };
    if let Some(x) = first_failure(1.0)? {
        return Ok(OutsideCap {
            interval: (1.0, 1.0),
            critical_hz: [Some(x), Some(x)],
        });
    }
    let (lo, hi) = (
        gain_edge(&ok, false, 1.02, limits.0.max(1e-3))?,
        gain_edge(&ok, true, 1.02, limits.1.min(1e3))?,
    );
    // where it fails just past each end (none where a limit, not the test, ended the walk)
    let past = |g: f64, limit: f64, up: bool| -> Result<Option<f64>> {
        let beyond = if up {
            g * (1.0 + 2e-6)
        } else {
            g * (1.0 - 2e-6)
        };
        let inside = if up { beyond < limit } else { beyond > limit };
        if g.is_finite() && g > 0.0 && inside {
            first_failure(beyond)
        } else {
            Ok(None)
        }
    };
    Ok(OutsideCap {
        interval: (lo, hi),
        critical_hz: [
            past(lo, limits.0.max(1e-3), false)?,
            past(hi, limits.1.min(1e3), true)?,
        ],
    })
}

/// A matrix's entries, flat row-major (the layout of [`small`]).
fn flat(m: &faer::Mat<c64>) -> Vec<c64> {
    (0..m.nrows())
        .flat_map(|i| (0..m.ncols()).map(move |j| m[(i, j)]))
        .collect()
}

/// One frequency of [`outside_interval`]: $\hat P$, $C$ and $R$, flat row-major.
type Point = (Vec<c64>, Vec<c64>, Vec<f64>);

/// What [`outside_interval`] finds.
struct OutsideCap {
    interval: (f64, f64),
    critical_hz: [Option<f64>; 2],
}

/// Small dense complex matrices (row-major slices) for the per-line test of
/// [`robust_stability_matrix_drawn`], without an allocation per line.
mod small {
    use faer::c64;

    /// $|z|$ without `hypot`'s care for overflow (the loop's values are far from it).
    fn abs(z: c64) -> f64 {
        (z.re * z.re + z.im * z.im).sqrt()
    }

    /// `out` ($r\times c$) $= a$ ($r\times q$) $b$ ($q\times c$).
    pub fn matmul(a: &[c64], b: &[c64], r: usize, q: usize, c: usize, out: &mut [c64]) {
        for i in 0..r {
            for j in 0..c {
                out[i * c + j] =
                    (0..q).fold(c64::new(0.0, 0.0), |s, m| s + a[i * q + m] * b[m * c + j]);
            }
        }
    }

    /// $M(g) = (I + gC\hat P)^{-1} gC$ ($n_u\times n_y$) from $C$ ($n_u\times n_y$) and $\hat P$
    /// ($n_y\times n_u$) at one frequency; `None` where $I + gC\hat P$ is singular.
    pub fn loop_m(c: &[c64], p: &[c64], g: f64, nu: usize, ny: usize) -> Option<Vec<c64>> {
        let mut gc: Vec<c64> = c.iter().map(|x| *x * g).collect();
        let mut a = vec![c64::new(0.0, 0.0); nu * nu];
        matmul(&gc, p, nu, ny, nu, &mut a);
        (0..nu).for_each(|i| a[i * nu + i] += 1.0);
        solve(&mut a, nu, &mut gc, ny).then_some(gc)
    }

    /// Solves $a x = b$ in place ($a$ $n\times n$, $b$ $n\times c$, overwritten by $x$) by Gaussian
    /// elimination with partial pivoting; false when $a$ is singular to rounding.
    pub fn solve(a: &mut [c64], n: usize, b: &mut [c64], c: usize) -> bool {
        let scale = a.iter().map(|x| x.norm_sqr()).fold(0.0, f64::max);
        for col in 0..n {
            let p = (col..n)
                .max_by(|x, y| {
                    a[x * n + col]
                        .norm_sqr()
                        .total_cmp(&a[y * n + col].norm_sqr())
                })
                .unwrap_or(col);
            // (a NaN pivot fails too)
            if a[p * n + col].norm_sqr().partial_cmp(&(1e-28 * scale))
                != Some(std::cmp::Ordering::Greater)
            {
                return false;
            }
            if p != col {
                for j in 0..n {
                    a.swap(p * n + j, col * n + j);
                }
                for j in 0..c {
                    b.swap(p * c + j, col * c + j);
                }
            }
            let inv = c64::new(1.0, 0.0) / a[col * n + col];
            for row in col + 1..n {
                let f = a[row * n + col] * inv;
                if f == c64::new(0.0, 0.0) {
                    continue;
                }
                for j in col..n {
                    let v = a[col * n + j];
                    a[row * n + j] -= f * v;
                }
                for j in 0..c {
                    let v = b[col * c + j];
                    b[row * c + j] -= f * v;
                }
            }
        }
        for col in (0..n).rev() {
            let inv = c64::new(1.0, 0.0) / a[col * n + col];
            for j in 0..c {
                let mut v = b[col * c + j];
                for m in col + 1..n {
                    v -= a[col * n + m] * b[m * c + j];
                }
                b[col * c + j] = v * inv;
            }
        }
        b.iter().all(|x| x.re.is_finite() && x.im.is_finite())
    }

    /// $\min(\lVert x\rVert_1, \lVert x\rVert_\infty)$ of an $n\times n$ matrix of magnitudes
    /// `abs(i, j)`: a bound of its spectral radius.
    fn norm_bound(n: usize, abs: impl Fn(usize, usize) -> f64) -> f64 {
        let rows = (0..n)
            .map(|i| (0..n).map(|j| abs(i, j)).sum::<f64>())
            .fold(0.0, f64::max);
        let cols = (0..n)
            .map(|j| (0..n).map(|i| abs(i, j)).sum::<f64>())
            .fold(0.0, f64::max);
        rows.min(cols)
    }

    /// An upper bound of the Perron root of the $n\times n$ non-negative matrix `abs(i, j)`
    /// (which bounds the spectral radius of any matrix of these magnitudes): Collatz–Wielandt's
    /// $\max_i (Bx)_i/x_i$ after a few power steps from $x = 1$.
    fn perron_upper(n: usize, abs: impl Fn(usize, usize) -> f64) -> f64 {
        let mut x = vec![1.0; n];
        let mut hi = f64::INFINITY;
        for _ in 0..8 {
            let y: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|j| abs(i, j) * x[j]).sum())
                .collect();
            hi = hi.min((0..n).map(|i| y[i] / x[i]).fold(0.0, f64::max));
            let top = y.iter().copied().fold(0.0, f64::max);
            if !(top > 0.0 && top.is_finite()) {
                break;
            }
            x = y.iter().map(|v| (v / top).max(1e-12)).collect();
        }
        hi
    }

    /// Buffers for one thread's lines.
    pub struct Scratch {
        ny: usize,
        nu: usize,
        a: Vec<c64>,
        x: Vec<c64>,
        b: Vec<f64>,
    }

    impl Scratch {
        pub fn new(ny: usize, nu: usize) -> Self {
            Scratch {
                ny,
                nu,
                a: vec![c64::new(0.0, 0.0); nu * nu],
                x: vec![c64::new(0.0, 0.0); nu * ny],
                b: vec![0.0; ny * ny],
            }
        }

        /// The two conditions at one line: $\rho(MD) < 1$ and $\rho(R\,|(I + MD)^{-1}M|) < 1$
        /// ($M$ $n_u\times n_y$, $D$ and $R$ $n_y\times n_u$), each by a norm bound first and
        /// eigenvalues only where that bound is not below 1.
        pub fn line_ok(&mut self, m: &[c64], d: &[c64], r: &[f64]) -> bool {
            let (ny, nu) = (self.ny, self.nu);
            matmul(m, d, nu, ny, nu, &mut self.a);
            if norm_bound(nu, |i, j| abs(self.a[i * nu + j])) >= 1.0
                && perron_upper(nu, |i, j| abs(self.a[i * nu + j])) >= 1.0
            {
                let a = faer::Mat::from_fn(nu, nu, |i, j| self.a[i * nu + j]);
                let rho = a
                    .eigenvalues()
                    .map(|e| e.iter().map(|z| z.norm()).fold(0.0, f64::max))
                    .unwrap_or(f64::INFINITY);
                if rho.partial_cmp(&1.0) != Some(std::cmp::Ordering::Less) {
                    return false;
                }
            }
            (0..nu).for_each(|i| self.a[i * nu + i] += 1.0);
            self.x.copy_from_slice(m);
            if !solve(&mut self.a, nu, &mut self.x, ny) {
                return false;
            }
            for i in 0..ny {
                for j in 0..ny {
                    self.b[i * ny + j] = (0..nu)
                        .map(|q| r[i * nu + q] * abs(self.x[q * ny + j]))
                        .sum();
                }
            }
            if norm_bound(ny, |i, j| self.b[i * ny + j]) < 1.0 {
                return true;
            }
            // Collatz–Wielandt: for x > 0, min_i (Bx)_i/x_i ≤ ρ(B) ≤ max_i (Bx)_i/x_i
            let mut x = vec![1.0; ny];
            let mut y = vec![0.0; ny];
            for _ in 0..40 {
                for (i, yi) in y.iter_mut().enumerate() {
                    *yi = (0..ny).map(|j| self.b[i * ny + j] * x[j]).sum::<f64>();
                }
                let ratio = |i: usize| y[i] / x[i];
                let (lo, hi) = (0..ny).fold((f64::INFINITY, 0.0f64), |(l, h), i| {
                    (l.min(ratio(i)), h.max(ratio(i)))
                });
                if hi < 1.0 {
                    return true;
                }
                if lo >= 1.0 {
                    return false;
                }
                let top = y.iter().copied().fold(0.0, f64::max);
                if !(top > 0.0 && top.is_finite()) {
                    break;
                }
                // a floor keeps x positive where B has a zero row
                for i in 0..ny {
                    x[i] = (y[i] / top).max(1e-12);
                }
            }
            let b = faer::Mat::from_fn(ny, ny, |i, j| self.b[i * ny + j]);
            crate::linalg::eigenvalues(b.as_ref())
                .map(|e| e.iter().map(|z| z.norm()).fold(0.0, f64::max))
                .is_ok_and(|rho| rho < 1.0)
        }
    }
}

/// The common sample time of a plant and a controller of the transposed size.
fn matrix_loop_ts(plant: &StateSpace, controller: &StateSpace) -> Result<f64> {
    if controller.ninputs() != plant.noutputs() || controller.noutputs() != plant.ninputs() {
        return Err(Error::invalid(
            "controller",
            format!(
                "the controller must map the plant's {} outputs to its {} inputs, it is {}×{}",
                plant.noutputs(),
                plant.ninputs(),
                controller.noutputs(),
                controller.ninputs()
            ),
        ));
    }
    match (plant.ts(), controller.ts()) {
        (Some(a), Some(b)) if (a - b).abs() <= 1e-9 * a => Ok(a),
        _ => Err(Error::invalid(
            "controller",
            "the plant and the controller must be discrete-time with one sample time",
        )),
    }
}

/// The test and margins of [`robust_stability_matrix_on_lines`] on the lines `f`.
fn assess_matrix(
    plant: &StateSpace,
    controller: &StateSpace,
    f: Vec<f64>,
    bound: LineBound<'_>,
) -> Result<RobustStability> {
    let nominal_stable = loop_stable(plant, controller, 1.0)?;
    let pl = plant.freq_response(&f)?;
    let cr = controller.freq_response(&f)?;
    let nu = plant.ninputs();
    let mu_at = |g: f64| -> Vec<f64> {
        (0..f.len())
            .map(|k| {
                let gc = faer::Mat::from_fn(cr[k].nrows(), cr[k].ncols(), |i, j| cr[k][(i, j)] * g);
                let x = faer::Mat::<c64>::identity(nu, nu) + &gc * &pl[k];
                match crate::linalg::solve_c64(x.as_ref(), gc.as_ref()) {
                    Ok(m) => bound.mu(k, &m, &pl[k]),
                    Err(_) => f64::INFINITY,
                }
            })
            .collect()
    };
    let peak_of = |mu: &[f64]| mu.iter().copied().fold(0.0f64, f64::max);
    let mu = mu_at(1.0);
    let (mut peak, mut peak_hz) = (0.0f64, f[0]);
    for (k, m) in mu.iter().enumerate() {
        if *m > peak || !m.is_finite() {
            peak = if m.is_finite() { *m } else { f64::INFINITY };
            peak_hz = f[k];
        }
    }
    let robustly_stable = nominal_stable && peak < 1.0;
    let (upper, lower) = if robustly_stable {
        let (n_lo, n_hi) = nominal_gain_interval(plant, controller)?;
        let ok = |g: f64| Ok(peak_of(&mu_at(g)) < 1.0);
        (
            Some(gain_edge(ok, true, 1.02, n_hi.min(1e3))?),
            Some(gain_edge(ok, false, 1.02, n_lo.max(1e-3))?),
        )
    } else {
        (None, None)
    };
    Ok(RobustStability {
        nominal_stable,
        mu_peak: peak,
        mu_peak_hz: peak_hz,
        stability_margin: stability_margin(nominal_stable, peak),
        robustly_stable,
        upper_gain_margin: upper,
        lower_gain_margin: lower,
        f_hz: f,
        mu,
    })
}

/// At least one line, one bound (`name`) per line, every line in $(0, f_N)$.
fn check_lines(name: &'static str, f_hz: &[f64], bounds: usize, ts: f64) -> Result<()> {
    if f_hz.is_empty() || bounds != f_hz.len() {
        return Err(Error::invalid(
            name,
            format!(
                "needs one bound per line and at least one line (got {} lines, {bounds} bounds)",
                f_hz.len()
            ),
        ));
    }
    if f_hz.iter().any(|f| !(*f > 0.0 && *f < 0.5 / ts)) {
        return Err(Error::invalid(
            "f_hz",
            "every line must lie between 0 and the Nyquist frequency",
        ));
    }
    Ok(())
}

/// The common sample time of a SISO `plant`, `controller` (and weight).
fn loop_ts(plant: &StateSpace, controller: &StateSpace, weight_ts: Option<f64>) -> Result<f64> {
    for (name, m) in [("plant", plant), ("controller", controller)] {
        if m.ninputs() != 1 || m.noutputs() != 1 {
            return Err(Error::invalid(name, "must be SISO"));
        }
    }
    match (plant.ts(), controller.ts()) {
        (Some(a), Some(b))
            if (a - b).abs() <= 1e-9 * a && weight_ts.is_none_or(|w| (a - w).abs() <= 1e-9 * a) =>
        {
            Ok(a)
        }
        _ => Err(Error::invalid(
            "controller",
            "the plant, the controller (and the weight) must be discrete-time with one sample time",
        )),
    }
}

/// The test and the margins on the frequencies `f` with the uncertainty magnitudes `wr`.
fn assess(
    plant: &StateSpace,
    controller: &StateSpace,
    f: Vec<f64>,
    wr: &[f64],
) -> Result<RobustStability> {
    let cl = plant.feedback(controller)?;
    let nominal_stable = cl.poles()?.iter().all(|p| p.norm() < 1.0);
    let pl = plant.freq_response_siso(&f)?;
    let cr = controller.freq_response_siso(&f)?;
    let mut mu = Vec::with_capacity(f.len());
    let (mut peak, mut peak_hz) = (0.0f64, f[0]);
    let (mut g_hi, mut g_lo) = (f64::INFINITY, 0.0f64);
    for k in 0..f.len() {
        let l = pl[k] * cr[k];
        let t = l / (c64::new(1.0, 0.0) + l);
        let m = wr[k] * t.norm();
        if m > peak || !m.is_finite() {
            peak = if m.is_finite() { m } else { f64::INFINITY };
            peak_hz = f[k];
        }
        mu.push(m);
        let (lo, hi) = gain_interval(l, wr[k]);
        g_hi = g_hi.min(hi);
        g_lo = g_lo.max(lo);
    }
    let robustly_stable = nominal_stable && peak < 1.0;
    let (upper, lower) = if robustly_stable {
        let (n_lo, n_hi) = nominal_gain_interval(plant, controller)?;
        (Some(g_hi.min(n_hi)), Some(g_lo.max(n_lo)))
    } else {
        (None, None)
    };
    Ok(RobustStability {
        nominal_stable,
        mu_peak: peak,
        mu_peak_hz: peak_hz,
        stability_margin: stability_margin(nominal_stable, peak),
        robustly_stable,
        upper_gain_margin: upper,
        lower_gain_margin: lower,
        f_hz: f,
        mu,
    })
}

/// $1/\max\mu$: infinite without uncertainty, 0 when the nominal loop is unstable.
fn stability_margin(nominal_stable: bool, peak: f64) -> f64 {
    if nominal_stable && peak > 0.0 {
        1.0 / peak
    } else if nominal_stable {
        f64::INFINITY
    } else {
        0.0
    }
}

/// The loop with the controller's gain scaled by $g$, $u = -gCy + r$.
fn with_gain(controller: &StateSpace, g: f64) -> Result<StateSpace> {
    StateSpace::new(
        controller.a().to_owned(),
        controller.b().to_owned(),
        controller.c().to_owned() * g,
        controller.d().to_owned() * g,
        controller.ts(),
    )
}

/// Whether the loop of `plant` with `controller` scaled by `g` ($u = -gCy + r$) is stable: all
/// its closed-loop poles inside the unit circle.
///
/// # Errors
/// When the loop is not well posed or its poles cannot be computed.
pub fn loop_stable(plant: &StateSpace, controller: &StateSpace, g: f64) -> Result<bool> {
    Ok(plant
        .feedback(&with_gain(controller, g)?)?
        .poles()?
        .iter()
        .all(|p| p.norm() < 1.0))
}

/// The nominal loop's gain interval around 1 from its closed-loop poles: the gain is stepped by
/// 1 % from 1 up to $10^3$ (down to $10^{-3}$) until the loop is unstable, and the edge is found
/// by bisection to $10^{-6}$ relative (a pole leaving and re-entering within one step is missed);
/// $\infty$ (0) when nothing limits it there. Returns `(lower, upper)`.
///
/// # Errors
/// As [`loop_stable`].
pub fn nominal_gain_interval(plant: &StateSpace, controller: &StateSpace) -> Result<(f64, f64)> {
    let stable = |g: f64| loop_stable(plant, controller, g);
    Ok((
        gain_edge(stable, false, 1.01, 1e-3)?,
        gain_edge(stable, true, 1.01, 1e3)?,
    ))
}

/// The edge of the gain interval around 1 where `ok` holds: the gain stepped by the factor
/// `step` up (`up`) or down from 1 until `ok` fails or `limit` is passed, the edge refined by
/// bisection to $10^{-6}$ relative; $\infty$ (0) when `ok` still holds at the limit $10^3$
/// ($10^{-3}$), the limit itself for a nearer limit.
fn gain_edge(
    mut ok: impl FnMut(f64) -> Result<bool>,
    up: bool,
    step: f64,
    limit: f64,
) -> Result<f64> {
    let step = if up { step } else { 1.0 / step };
    let mut good = 1.0f64;
    loop {
        let next = good * step;
        let past = if up { next >= limit } else { next <= limit };
        let probe = if past { limit } else { next };
        if !ok(probe)? {
            let (mut a, mut b) = (good, probe);
            while (b - a).abs() > 1e-6 * a {
                let m = 0.5 * (a + b);
                if ok(m)? {
                    a = m;
                } else {
                    b = m;
                }
            }
            return Ok(a);
        }
        if past {
            return Ok(if up && limit >= 1e3 {
                f64::INFINITY
            } else if !up && limit <= 1e-3 {
                0.0
            } else {
                limit
            });
        }
        good = next;
    }
}

/// The interval $(g_-, g_+) \ni 1$ of gains with $|W g L| < |1 + gL|$ at one frequency
/// ($q(1) < 0$ assumed; a degenerate interval $(1, 1)$ otherwise).
fn gain_interval(l: c64, w: f64) -> (f64, f64) {
    let a = l.norm_sqr() * (w * w - 1.0);
    let b = -2.0 * l.re;
    let c = -1.0;
    let q = |g: f64| a * g * g + b * g + c;
    if q(1.0) >= 0.0 || !q(1.0).is_finite() {
        return (1.0, 1.0);
    }
    let mut roots = Vec::new();
    if a.abs() < 1e-300 {
        if b != 0.0 {
            roots.push(-c / b);
        }
    } else {
        let disc = b * b - 4.0 * a * c;
        if disc >= 0.0 {
            let s = disc.sqrt();
            // stable form of the two roots
            let qq = -0.5 * (b + b.signum() * s);
            if qq != 0.0 {
                roots.push(qq / a);
                roots.push(c / qq);
            } else {
                roots.push((-b + s) / (2.0 * a));
                roots.push((-b - s) / (2.0 * a));
            }
        }
    }
    let hi = roots
        .iter()
        .copied()
        .filter(|r| *r > 1.0)
        .fold(f64::INFINITY, f64::min);
    let lo = roots
        .iter()
        .copied()
        .filter(|r| *r < 1.0 && *r > 0.0)
        .fold(0.0f64, f64::max);
    (lo, hi)
}

/// The frequency grid of the module docs.
fn grid(models: &[&StateSpace], weights: &[&Weight], ts: f64) -> Result<Vec<f64>> {
    let fs = 1.0 / ts;
    let (lo, hi) = (1e-4 * fs, 0.5 * fs);
    let n = 4000;
    let mut f: Vec<f64> = (0..n)
        .map(|i| (lo.ln() + (hi.ln() - lo.ln()) * i as f64 / (n - 1) as f64).exp())
        .collect();
    let mut poles = Vec::new();
    for m in models {
        poles.extend(m.poles()?);
    }
    for w in weights {
        poles.extend(w.poles());
    }
    for p in poles {
        if p.norm() == 0.0 || p.im.abs() < 1e-12 {
            continue;
        }
        let s = p.ln() / ts;
        let wn = s.norm();
        let zeta = (-s.re / wn).abs();
        let fc = s.im.abs() / (2.0 * PI);
        if zeta > 0.3 || fc <= lo || fc >= hi {
            continue;
        }
        let half = (2.0 * zeta * wn / (2.0 * PI)).max(1e-6 * fc);
        for i in -4..=4 {
            let x = fc + half * i as f64 / 4.0;
            if x > lo && x < hi {
                f.push(x);
            }
        }
    }
    f.sort_by(f64::total_cmp);
    f.dedup_by(|a, b| (*a - *b).abs() <= 1e-12 * b.abs());
    Ok(f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validate::weight::Factor;
    use faer::{mat, Mat};

    /// A naive oracle: the closed-loop poles of the loop with gain g, stable or not.
    fn stable_with_gain(p: &StateSpace, c: &StateSpace, g: f64) -> bool {
        let cg = StateSpace::discrete(
            c.a().to_owned(),
            c.b().to_owned(),
            c.c().to_owned() * g,
            c.d().to_owned() * g,
            c.ts().unwrap(),
        )
        .unwrap();
        p.feedback(&cg)
            .unwrap()
            .poles()
            .unwrap()
            .iter()
            .all(|z| z.norm() < 1.0)
    }

    /// An unstable plant $P(s) = 1/(s^2 - 400^2)$ (ZOH) and a lead controller $C(s) = k (1 +
    /// s/\omega_d) / (1 + s/(10\omega_d))$ (Tustin) that stabilises it.
    fn bearing_loop(ts: f64) -> (StateSpace, StateSpace) {
        let pc = StateSpace::continuous(
            mat![[0.0, 1.0], [160_000.0, 0.0]],
            mat![[0.0], [1.0]],
            mat![[1.0, 0.0]],
            mat![[0.0]],
        )
        .unwrap();
        let (k, wd) = (4.0e5, 300.0);
        let cc = StateSpace::continuous(
            mat![[-10.0 * wd]],
            mat![[1.0]],
            mat![[k * 10.0 * wd * (1.0 - 10.0)]],
            mat![[k * 10.0]],
        )
        .unwrap();
        (pc.c2d_zoh(ts).unwrap(), cc.c2d_tustin(ts, None).unwrap())
    }

    /// An unstable plant (a magnetic-bearing-like real pole pair) under a PD-like controller:
    /// with a tiny weight the robust gain margins are the nominal ones of the pole oracle; with
    /// a 20 % weight they shrink, every gain inside them keeps the loop stable for the members
    /// P̂(1 ± 0.2) of the set, and they do not reach beyond where those members fail.
    #[test]
    fn gain_margins_agree_with_the_closed_loop_poles() {
        let ts = 1e-4;
        let (p, c) = bearing_loop(ts);
        assert!(stable_with_gain(&p, &c, 1.0));
        // the nominal gain margins by bisection on the pole oracle
        let edge = |mut a: f64, mut b: f64| {
            for _ in 0..60 {
                let m = 0.5 * (a + b);
                if stable_with_gain(&p, &c, m) {
                    a = m
                } else {
                    b = m
                }
            }
            0.5 * (a + b)
        };
        let g_up = edge(1.0, 100.0);
        let g_dn = edge(1.0, 0.0);
        let tiny = Weight {
            ts,
            gain: 1e-9,
            numerator: vec![],
            denominator: vec![],
        };
        let r = robust_stability(&p, &c, &tiny).unwrap();
        assert!(r.robustly_stable);
        let (gu, gl) = (r.upper_gain_margin.unwrap(), r.lower_gain_margin.unwrap());
        assert!((gu - g_up).abs() < 0.01 * g_up, "{gu} vs {g_up}");
        assert!((gl - g_dn).abs() < 0.01 * g_dn, "{gl} vs {g_dn}");
        // a 20 % weight: margins inside the nominal ones; plants P̂(1 ± 0.2) stay stable with
        // any gain inside them
        let w = Weight {
            ts,
            gain: 0.2,
            numerator: vec![Factor::First { omega: 1.0 }],
            denominator: vec![Factor::First { omega: 1.0 }],
        };
        let r = robust_stability(&p, &c, &w).unwrap();
        let (ru, rl) = (r.upper_gain_margin.unwrap(), r.lower_gain_margin.unwrap());
        assert!(ru < gu && rl > gl && ru > 1.0 && rl < 1.0, "{ru} {rl}");
        for scale in [0.8, 1.2] {
            let ps = StateSpace::discrete(
                p.a().to_owned(),
                p.b().to_owned(),
                p.c().to_owned() * scale,
                p.d().to_owned(),
                ts,
            )
            .unwrap();
            for g in [rl * 1.001, 1.0, ru * 0.999] {
                assert!(stable_with_gain(&ps, &c, g), "scale {scale}, gain {g}");
            }
        }
        // members of the set bound it from outside: P̂·1.2 loses stability at g_up / 1.2 and
        // P̂·0.8 at g_dn / 0.8, so the robust margins cannot reach beyond those
        assert!(ru <= g_up / 1.2 * (1.0 + 1e-3), "{ru} vs {}", g_up / 1.2);
        assert!(rl >= g_dn / 0.8 * (1.0 - 1e-3), "{rl} vs {}", g_dn / 0.8);
        assert!(r.stability_margin > 1.0 && r.mu_peak < 1.0);
    }

    /// The frequency-wise check with a constant bound of 0.2 on dense lines over the whole
    /// axis equals the check against the constant weight 0.2 (the same test on another grid);
    /// the bound on one band only leaves the margins at least as wide; bad input is refused.
    #[test]
    fn the_check_on_lines_matches_the_weight_and_refuses_bad_input() {
        let ts = 1e-4;
        let (p, c) = bearing_loop(ts);
        let w = Weight {
            ts,
            gain: 0.2,
            numerator: vec![],
            denominator: vec![],
        };
        let rw = robust_stability(&p, &c, &w).unwrap();
        let nyq = 0.5 / ts;
        let f: Vec<f64> = (0..20_000)
            .map(|i| 0.5 * 10f64.powf(i as f64 / 19_999.0 * (nyq * 0.9999 / 0.5).log10()))
            .collect();
        let rl = robust_stability_on_lines(&p, &c, &f, &vec![0.2; f.len()]).unwrap();
        assert_eq!(rl.robustly_stable, rw.robustly_stable);
        assert!(
            (rl.mu_peak - rw.mu_peak).abs() < 1e-3 * rw.mu_peak,
            "{} {}",
            rl.mu_peak,
            rw.mu_peak
        );
        for (a, b) in [
            (rl.upper_gain_margin, rw.upper_gain_margin),
            (rl.lower_gain_margin, rw.lower_gain_margin),
        ] {
            let (a, b) = (a.unwrap(), b.unwrap());
            assert!((a - b).abs() < 2e-3 * b, "{a} vs {b}");
        }
        // the bound on 100-1000 Hz only: no narrower than on all lines
        let band: Vec<f64> = f
            .iter()
            .copied()
            .filter(|x| (100.0..=1000.0).contains(x))
            .collect();
        let rb = robust_stability_on_lines(&p, &c, &band, &vec![0.2; band.len()]).unwrap();
        assert!(rb.upper_gain_margin.unwrap() >= rl.upper_gain_margin.unwrap() * (1.0 - 1e-9));
        assert!(rb.lower_gain_margin.unwrap() <= rl.lower_gain_margin.unwrap() * (1.0 + 1e-9));
        assert!(robust_stability_on_lines(&p, &c, &[], &[]).is_err());
        assert!(robust_stability_on_lines(&p, &c, &[10.0], &[0.1, 0.2]).is_err());
        assert!(robust_stability_on_lines(&p, &c, &[nyq], &[0.1]).is_err());
        assert!(robust_stability_on_lines(&p, &c, &[10.0], &[f64::NAN]).is_err());
        assert!(robust_stability_on_lines(&p, &c, &[10.0], &[-0.1]).is_err());
    }

    #[test]
    fn an_unstable_nominal_loop_is_reported() {
        let ts = 1e-3;
        let p =
            StateSpace::discrete(mat![[1.1]], mat![[1.0]], mat![[1.0]], mat![[0.0]], ts).unwrap();
        let c =
            StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[0.01]], ts).unwrap();
        let w = Weight {
            ts,
            gain: 0.1,
            numerator: vec![],
            denominator: vec![],
        };
        let r = robust_stability(&p, &c, &w).unwrap();
        assert!(!r.nominal_stable && !r.robustly_stable);
        assert_eq!(r.stability_margin, 0.0);
        assert!(r.upper_gain_margin.is_none());
        let other = Weight { ts: 2e-3, ..w };
        assert!(robust_stability(&p, &c, &other).is_err());
    }

    /// For a SISO loop the matrix test is the SISO one: the element-wise bound $L = \ell|\hat
    /// P|$ and the input-multiplicative bound $\ell$ give $\mu = \ell|T|$ of
    /// [`robust_stability_on_lines`], and the scanned gain margins its exact ones.
    #[test]
    fn the_matrix_test_of_a_siso_loop_is_the_siso_test() {
        let ts = 1e-4;
        let (p, c) = bearing_loop(ts);
        let f: Vec<f64> = (0..600)
            .map(|i| 2.0 * 1.01f64.powi(i))
            .filter(|f| *f < 4900.0)
            .collect();
        let ell: Vec<f64> = f.iter().map(|x| 0.05 + 0.2 * x / 4900.0).collect();
        let ph = p.freq_response_siso(&f).unwrap();
        let l: Vec<Mat<f64>> = ell
            .iter()
            .zip(&ph)
            .map(|(e, g)| Mat::from_fn(1, 1, |_, _| e * g.norm()))
            .collect();
        let siso = robust_stability_on_lines(&p, &c, &f, &ell).unwrap();
        assert!(siso.robustly_stable);
        for bound in [
            LineBound::Elementwise(&l),
            LineBound::InputMultiplicative(&ell),
        ] {
            let r = robust_stability_matrix_on_lines(&p, &c, &f, bound).unwrap();
            for (a, b) in r.mu.iter().zip(&siso.mu) {
                assert!((a - b).abs() <= 1e-9 * b.max(1e-12), "{a} {b}");
            }
            assert_eq!(r.robustly_stable, siso.robustly_stable);
            for (a, b) in [
                (r.upper_gain_margin, siso.upper_gain_margin),
                (r.lower_gain_margin, siso.lower_gain_margin),
            ] {
                let (a, b) = (a.unwrap(), b.unwrap());
                assert!((a - b).abs() <= 1e-4 * b, "{a} {b}");
            }
        }
        // bad input
        let c2 = StateSpace::discrete(
            mat![[0.0]],
            mat![[0.0, 0.0]],
            mat![[0.0]],
            mat![[1.0, 1.0]],
            ts,
        )
        .unwrap();
        assert!(robust_stability_matrix_on_lines(&p, &c2, &f, LineBound::Additive(&ell)).is_err());
        assert!(
            robust_stability_matrix_on_lines(&p, &c, &f[1..], LineBound::Additive(&ell)).is_err()
        );
        let neg: Vec<f64> = ell.iter().map(|x| -x).collect();
        assert!(robust_stability_matrix_on_lines(&p, &c, &f, LineBound::Additive(&neg)).is_err());
        let wrong = vec![Mat::<f64>::zeros(2, 2); f.len()];
        assert!(
            robust_stability_matrix_on_lines(&p, &c, &f, LineBound::Elementwise(&wrong)).is_err()
        );
    }

    /// For a SISO loop the per-entry weight forms are the SISO weight test: the relative entry
    /// weight gives $\mu = |W||T|$ of [`robust_stability`] on the same grid, and its margins;
    /// the additive entry weight $|\hat P|\,|W|$ — here checked against the additive weight
    /// $w$ of constant magnitude, $\mu = w|M|$ — equals the unstructured additive form. A
    /// weight of another sample time or the wrong number of weights is refused.
    #[test]
    fn the_entry_weights_of_a_siso_loop_are_the_siso_weight_test() {
        let ts = 1e-4;
        let (p, c) = bearing_loop(ts);
        let w = Weight {
            ts,
            gain: 0.15,
            numerator: vec![Factor::Second {
                omega: 2.0e4,
                zeta: 0.7,
            }],
            denominator: vec![Factor::Second {
                omega: 6.0e3,
                zeta: 0.5,
            }],
        };
        let siso = robust_stability(&p, &c, &w).unwrap();
        assert!(siso.robustly_stable, "{}", siso.mu_peak);
        let ws = [w.clone()];
        let r = robust_stability_matrix_weight(&p, &c, MatrixWeight::EntryRelative(&ws)).unwrap();
        assert_eq!(r.f_hz, siso.f_hz);
        for (a, b) in r.mu.iter().zip(&siso.mu) {
            assert!((a - b).abs() <= 1e-9 * b.max(1e-12), "{a} {b}");
        }
        for (a, b) in [
            (r.upper_gain_margin, siso.upper_gain_margin),
            (r.lower_gain_margin, siso.lower_gain_margin),
        ] {
            let (a, b) = (a.unwrap(), b.unwrap());
            assert!((a - b).abs() <= 1e-4 * b, "{a} {b}");
        }
        let flat = Weight {
            ts,
            gain: 1e-6,
            numerator: vec![],
            denominator: vec![],
        };
        let fs = [flat.clone()];
        let ra = robust_stability_matrix_weight(&p, &c, MatrixWeight::EntryAdditive(&fs)).unwrap();
        let ru = robust_stability_matrix_weight(&p, &c, MatrixWeight::Additive(&flat)).unwrap();
        for (a, b) in ra.mu.iter().zip(&ru.mu) {
            assert!((a - b).abs() <= 1e-9 * b.max(1e-12), "{a} {b}");
        }
        assert_eq!(ra.upper_gain_margin, ru.upper_gain_margin);
        let two = [w.clone(), w.clone()];
        assert!(robust_stability_matrix_weight(&p, &c, MatrixWeight::EntryRelative(&two)).is_err());
        let other = [Weight { ts: 2e-4, ..w }];
        assert!(
            robust_stability_matrix_weight(&p, &c, MatrixWeight::EntryRelative(&other)).is_err()
        );
    }

    /// Two bearing axes mixed by `t` at the sensors, $P = T\,\mathrm{diag}(p_1, p_1)$, and the
    /// decentralised controller $\mathrm{diag}(c_1, c_1)$ of [`bearing_loop`].
    fn coupled_loop(ts: f64, t: Mat<f64>) -> (StateSpace, StateSpace) {
        let (p1, c1) = bearing_loop(ts);
        let (a, b, cc) = (p1.a(), p1.b(), p1.c());
        let n = 2 * p1.order();
        let big_a = Mat::from_fn(n, n, |i, j| {
            if i / 2 == j / 2 {
                a[(i % 2, j % 2)]
            } else {
                0.0
            }
        });
        let big_b = Mat::from_fn(n, 2, |i, j| if i / 2 == j { b[(i % 2, 0)] } else { 0.0 });
        let big_c = Mat::from_fn(2, n, |i, j| t[(i, j / 2)] * cc[(0, j % 2)]);
        let p = StateSpace::discrete(big_a, big_b, big_c, Mat::zeros(2, 2), ts).unwrap();
        let m = c1.order();
        let ca = Mat::from_fn(2 * m, 2 * m, |i, j| {
            if i / m == j / m {
                c1.a()[(i % m, j % m)]
            } else {
                0.0
            }
        });
        let cb = Mat::from_fn(
            2 * m,
            2,
            |i, j| if i / m == j { c1.b()[(i % m, 0)] } else { 0.0 },
        );
        let ccm = Mat::from_fn(
            2,
            2 * m,
            |i, j| if j / m == i { c1.c()[(0, j % m)] } else { 0.0 },
        );
        let cd = Mat::from_fn(2, 2, |i, j| if i == j { c1.d()[(0, 0)] } else { 0.0 });
        let c = StateSpace::discrete(ca, cb, ccm, cd, ts).unwrap();
        (p, c)
    }

    /// Two bearing axes coupled through a mixing matrix, decentralised control: with a constant
    /// element-wise bound on dense lines, every static perturbation within 0.98 of the reported
    /// margin (all sign patterns of the extreme entries) keeps the loop stable (the pole
    /// oracle), and so does the gain at 98 % of the robust gain margin for them.
    #[test]
    fn perturbations_inside_the_margin_keep_a_coupled_loop_stable() {
        let ts = 1e-4;
        let (p, c) = coupled_loop(ts, mat![[1.0, 0.3], [0.2, 1.0]]);
        let f: Vec<f64> = (0..1500)
            .map(|i| 0.5 * 1.005f64.powi(i))
            .filter(|f| *f < 4990.0)
            .collect();
        let l0 = mat![[1.2e-7, 3e-8], [3e-8, 1.2e-7]];
        let l = vec![l0.clone(); f.len()];
        let r = robust_stability_matrix_on_lines(&p, &c, &f, LineBound::Elementwise(&l)).unwrap();
        assert!(r.nominal_stable && r.robustly_stable, "{}", r.mu_peak);
        // a margin that means something: the perturbations below are not vanishingly small
        assert!(r.mu_peak > 0.2, "{}", r.mu_peak);
        let scale = 0.98 * r.stability_margin.min(1.0);
        let g_hi = 1.0 + 0.98 * (r.upper_gain_margin.unwrap().min(50.0) - 1.0);
        for signs in 0..16u32 {
            let d = Mat::from_fn(2, 2, |i, j| {
                let s = if signs >> (2 * i + j) & 1 == 1 {
                    -1.0
                } else {
                    1.0
                };
                s * scale * l0[(i, j)]
            });
            let pp =
                StateSpace::discrete(p.a().to_owned(), p.b().to_owned(), p.c().to_owned(), d, ts)
                    .unwrap();
            assert!(stable_with_gain(&pp, &c, 1.0), "signs {signs}");
            assert!(stable_with_gain(&pp, &c, g_hi), "signs {signs} at g {g_hi}");
        }
    }

    /// Lines 0.5 % apart over 0.5 Hz … 4.99 kHz, below f_N = 5 kHz, for the coupled loop.
    fn dense_lines() -> Vec<f64> {
        (0..1900)
            .map(|i| 0.5 * 1.005f64.powi(i))
            .filter(|f| *f < 4990.0)
            .collect()
    }

    /// With zero draws the drawn test is the element-wise one on the lines: the same margins
    /// (bisection to 1e-3 against 1e-6).
    #[test]
    fn drawn_margins_without_a_draw_are_the_elementwise_ones() {
        let ts = 1e-4;
        let (p, c) = coupled_loop(ts, mat![[1.0, 0.3], [0.2, 1.0]]);
        let f = dense_lines();
        let l = vec![mat![[1.2e-7, 3e-8], [3e-8, 1.2e-7]]; f.len()];
        let r = robust_stability_matrix_on_lines(&p, &c, &f, LineBound::Elementwise(&l)).unwrap();
        let zero = vec![vec![Mat::<c64>::zeros(2, 2); f.len()]];
        let d = robust_stability_matrix_drawn(&p, &c, &f, &zero, &l, None, 0.95).unwrap();
        assert!(d.robustly_stable && d.stable_fraction == 1.0);
        let (a, b) = (r.upper_gain_margin.unwrap(), d.upper_gain_margin.unwrap());
        assert!(b <= a * (1.0 + 1e-6) && b >= a * (1.0 - 2e-3), "{a} {b}");
        let (a, b) = (r.lower_gain_margin.unwrap(), d.lower_gain_margin.unwrap());
        assert!(b >= a * (1.0 - 1e-6) && b <= a * (1.0 + 2e-3), "{a} {b}");
    }

    /// The exact error of another coupling, as one draw on dense lines: its margin never
    /// exceeds the true loop's (the pole oracle) and is close to it, while the element-wise
    /// bound of the same magnitudes with free phases gives less.
    #[test]
    fn a_coherent_draw_keeps_the_true_loops_margin() {
        let ts = 1e-4;
        let (p, c) = coupled_loop(ts, mat![[1.0, 0.3], [0.2, 1.0]]);
        let (pt, _) = coupled_loop(ts, mat![[1.06, 0.36], [0.16, 0.97]]);
        let f = dense_lines();
        let (rp, rt) = (p.freq_response(&f).unwrap(), pt.freq_response(&f).unwrap());
        let draw: Vec<Mat<c64>> = rp.iter().zip(&rt).map(|(a, b)| b - a).collect();
        let zero = vec![Mat::<f64>::zeros(2, 2); f.len()];
        let d = robust_stability_matrix_drawn(
            &p,
            &c,
            &f,
            std::slice::from_ref(&draw),
            &zero,
            None,
            1.0,
        )
        .unwrap();
        let (lo, hi) = nominal_gain_interval(&pt, &c).unwrap();
        let (dl, dh) = (d.lower_gain_margin.unwrap(), d.upper_gain_margin.unwrap());
        assert!(
            dh <= hi * 1.001 && dh - 1.0 >= 0.8 * (hi - 1.0),
            "{dh} against {hi}"
        );
        assert!(
            dl >= lo * 0.999 && 1.0 - dl >= 0.8 * (1.0 - lo),
            "{dl} against {lo}"
        );
        for g in [dh * 0.999, dl * 1.001] {
            assert!(stable_with_gain(&pt, &c, g), "{g}");
        }
        let abs: Vec<Mat<f64>> = draw
            .iter()
            .map(|m| Mat::from_fn(2, 2, |i, j| m[(i, j)].norm()))
            .collect();
        let e = robust_stability_matrix_on_lines(&p, &c, &f, LineBound::Elementwise(&abs)).unwrap();
        assert!(
            e.upper_gain_margin.unwrap() <= dh,
            "{:?} {dh}",
            e.upper_gain_margin
        );
        eprintln!(
            "exact {lo:.4}…{hi:.4}, coherent {dl:.4}…{dh:.4}, element-wise {:.4}…{:.4}",
            e.lower_gain_margin.unwrap(),
            e.upper_gain_margin.unwrap()
        );
    }

    /// The margin at a confidence is the draw ranked there (a naive oracle: each draw alone).
    #[test]
    fn the_margin_at_a_confidence_is_the_ranked_draws() {
        let ts = 1e-4;
        let (p, c) = coupled_loop(ts, mat![[1.0, 0.3], [0.2, 1.0]]);
        let (pt, _) = coupled_loop(ts, mat![[1.06, 0.36], [0.16, 0.97]]);
        let f = dense_lines();
        let (rp, rt) = (p.freq_response(&f).unwrap(), pt.freq_response(&f).unwrap());
        let zero = vec![Mat::<f64>::zeros(2, 2); f.len()];
        // 10 draws: the error scaled by 0.3 … 3.0
        let draws: Vec<Vec<Mat<c64>>> = (1..=10)
            .map(|n| {
                let s = 0.3 * n as f64;
                rp.iter()
                    .zip(&rt)
                    .map(|(a, b)| Mat::from_fn(2, 2, |i, j| (b[(i, j)] - a[(i, j)]) * s))
                    .collect()
            })
            .collect();
        let alone: Vec<[f64; 2]> = draws
            .iter()
            .map(|d| {
                let r = robust_stability_matrix_drawn(
                    &p,
                    &c,
                    &f,
                    std::slice::from_ref(d),
                    &zero,
                    None,
                    1.0,
                )
                .unwrap();
                match (r.lower_gain_margin, r.upper_gain_margin) {
                    (Some(a), Some(b)) => [a, b],
                    _ => [1.0, 1.0],
                }
            })
            .collect();
        let all = robust_stability_matrix_drawn(&p, &c, &f, &draws, &zero, None, 0.8).unwrap();
        assert_eq!(all.per_draw, alone);
        let mut hi: Vec<f64> = alone.iter().map(|m| m[1]).collect();
        hi.sort_by(|a, b| b.total_cmp(a));
        let mut lo: Vec<f64> = alone.iter().map(|m| m[0]).collect();
        lo.sort_by(f64::total_cmp);
        // 0.8 of 10 draws: the 8th best
        assert_eq!(all.upper_gain_margin, Some(hi[7]));
        assert_eq!(all.lower_gain_margin, Some(lo[7]));
        // larger errors leave less margin
        assert!(alone[9][1] < alone[0][1], "{alone:?}");
        let frac = alone.iter().filter(|m| m[1] > 1.0).count() as f64 / 10.0;
        assert_eq!(all.stable_fraction, frac);
    }

    /// Lines that stop below the frequency at which the true loop goes unstable as the gain
    /// rises: the draws (the exact error on the lines) see nothing there, and without a weight
    /// outside the lines the drawn margin is the model's own, above the true loop's. With an
    /// entry-additive weight outside the lines that bounds the true error there, the margin is
    /// at or below the true one (the pole oracle) and still most of it.
    #[test]
    fn a_weight_outside_the_lines_caps_the_drawn_margins() {
        let ts = 1e-4;
        let (p, c) = coupled_loop(ts, mat![[1.0, 0.3], [0.2, 1.0]]);
        let (pt, _) = coupled_loop(ts, mat![[1.06, 0.36], [0.16, 0.97]]);
        let (lo, hi) = nominal_gain_interval(&pt, &c).unwrap();
        let (_, hi_model) = nominal_gain_interval(&p, &c).unwrap();
        // where the true loop goes unstable just above its upper margin
        let cross: Vec<f64> = pt
            .feedback(&with_gain(&c, hi * 1.001).unwrap())
            .unwrap()
            .poles()
            .unwrap()
            .iter()
            .filter(|z| z.norm() >= 1.0 && z.im >= 0.0)
            .map(|z| z.im.atan2(z.re) / (2.0 * PI * ts))
            .collect();
        assert!(
            hi_model > hi && cross.iter().all(|x| *x > 900.0),
            "{cross:?}"
        );
        let f: Vec<f64> = dense_lines().into_iter().filter(|x| *x < 800.0).collect();
        let (rp, rt) = (p.freq_response(&f).unwrap(), pt.freq_response(&f).unwrap());
        let draw: Vec<Mat<c64>> = rp.iter().zip(&rt).map(|(a, b)| b - a).collect();
        let zero = vec![Mat::<f64>::zeros(2, 2); f.len()];
        let one = std::slice::from_ref(&draw);
        let blind = robust_stability_matrix_drawn(&p, &c, &f, one, &zero, None, 1.0).unwrap();
        let bh = blind.upper_gain_margin.unwrap();
        assert!(bh > hi, "{bh} against the true {hi}");
        assert_eq!(blind.outside_gain_interval, None);
        // a flat weight per entry: the largest true error above the lines
        let above: Vec<f64> = (0..2000)
            .map(|i| 800.0 * 6.2f64.powf(i as f64 / 2000.0))
            .collect();
        let (ep, et) = (
            p.freq_response(&above).unwrap(),
            pt.freq_response(&above).unwrap(),
        );
        let ws: Vec<Weight> = (0..4)
            .map(|e| {
                let (i, j) = (e % 2, e / 2);
                let gain = ep
                    .iter()
                    .zip(&et)
                    .map(|(a, b)| (b[(i, j)] - a[(i, j)]).norm())
                    .fold(0.0, f64::max);
                Weight {
                    ts,
                    gain,
                    numerator: vec![],
                    denominator: vec![],
                }
            })
            .collect();
        let capped = robust_stability_matrix_drawn(
            &p,
            &c,
            &f,
            one,
            &zero,
            Some(MatrixWeight::EntryAdditive(&ws)),
            1.0,
        )
        .unwrap();
        let ch = capped.upper_gain_margin.unwrap();
        let [ol, oh] = capped.outside_gain_interval.unwrap();
        eprintln!(
            "true {lo:.4}…{hi:.4} (crossing {cross:?} Hz), model {hi_model:.4}, blind {bh:.4}, capped {:.4}…{ch:.4}, outside {ol:.4}…{oh:.4}",
            capped.lower_gain_margin.unwrap()
        );
        assert!(ch <= hi && ch <= oh * (1.0 + 1e-9), "{ch} {hi} {oh}");
        assert!(ch - 1.0 >= 0.5 * (hi - 1.0), "{ch} {hi}");
        assert!(stable_with_gain(&pt, &c, ch));
        // the lower margin is set on the lines, where the draw is exact
        let cl = capped.lower_gain_margin.unwrap();
        assert!(
            cl >= lo * 0.999 && cl <= blind.lower_gain_margin.unwrap() * 1.001,
            "{cl}"
        );
    }

    #[test]
    fn the_drawn_test_refuses_bad_input() {
        let ts = 1e-4;
        let (p, c) = coupled_loop(ts, mat![[1.0, 0.3], [0.2, 1.0]]);
        let f = dense_lines();
        let zero = vec![Mat::<f64>::zeros(2, 2); f.len()];
        let draw = vec![vec![Mat::<c64>::zeros(2, 2); f.len()]];
        assert!(robust_stability_matrix_drawn(&p, &c, &f, &[], &zero, None, 0.9).is_err());
        for conf in [0.0, 1.5, f64::NAN] {
            assert!(robust_stability_matrix_drawn(&p, &c, &f, &draw, &zero, None, conf).is_err());
        }
        let short = vec![vec![Mat::<c64>::zeros(2, 2); f.len() - 1]];
        assert!(robust_stability_matrix_drawn(&p, &c, &f, &short, &zero, None, 0.9).is_err());
        let mut nan = draw.clone();
        nan[0][3][(0, 1)] = c64::new(f64::NAN, 0.0);
        let e = robust_stability_matrix_drawn(&p, &c, &f, &nan, &zero, None, 0.9).unwrap_err();
        assert!(e.to_string().contains("finite"), "{e}");
        let mut neg = zero.clone();
        neg[2][(1, 1)] = -1.0;
        assert!(robust_stability_matrix_drawn(&p, &c, &f, &draw, &neg, None, 0.9).is_err());
        let wrong = vec![vec![Mat::<c64>::zeros(1, 2); f.len()]];
        assert!(robust_stability_matrix_drawn(&p, &c, &f, &wrong, &zero, None, 0.9).is_err());
        // an outside weight: one per entry, of the loop's sample time
        let w = |ts: f64| Weight {
            ts,
            gain: 0.1,
            numerator: vec![],
            denominator: vec![],
        };
        for ws in [vec![w(ts); 3], vec![w(2.0 * ts); 4]] {
            let e = robust_stability_matrix_drawn(
                &p,
                &c,
                &f,
                &draw,
                &zero,
                Some(MatrixWeight::EntryRelative(&ws)),
                0.9,
            )
            .unwrap_err();
            assert!(e.to_string().contains("weight"), "{e}");
        }
    }
}
