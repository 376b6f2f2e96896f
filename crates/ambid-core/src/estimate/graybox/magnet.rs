//! The magnet's constant and its effective air gap from gray-box estimates at several operating
//! points (the operating-point study: bias current and air gap varied).
//!
//! # Model
//! A differential magnet pair with bias current $i_0$ and air gap $g$ has (model docs of
//! `ambid-twin`, and any AMB text)
//! $$ k_i = \frac{4 k\, i_0}{g^2}, \qquad k_x = \frac{4 k\, i_0^2}{g^3}, $$
//! with one constant $k = \mu_0 N^2 A \cos\alpha / 4$ \[N m²/A²\] for the magnet's turns, pole
//! area and pole angle. An operating-point study sets the bias current $i_j$ (known: the
//! amplifier's bias set point) and changes the gap by a known offset $\Delta_j$ (a shim, or
//! the position set point) about an effective nominal gap $g_0$ that is **not** known exactly:
//! the drawing's mechanical gap does not include the iron path, coatings or the
//! bearing's actual clearance. With $g_j = g_0 + \Delta_j$:
//! $$ \ln k_{i,j} = \ln 4 + \ln k + \ln i_j - 2\ln g_j, \qquad
//!    \ln k_{x,j} = \ln 4 + \ln k + 2\ln i_j - 3\ln g_j . $$
//!
//! # Estimate
//! The observations are the gray-box estimates $(\ln\hat k_{i,j}, \ln\hat k_{x,j})$ of each
//! operating point with their $2\times2$ covariance $\Sigma_j$ ([`super::PhysicalFit::covariance`]),
//! the points being independent experiments. $p = (\ln k, \ln g_0)$ minimises
//! $\sum_j r_j^\top \Sigma_j^{-1} r_j$ ($r_j$ the observation minus the model) by Gauss–Newton
//! with the analytic Jacobian rows $(1, -2 g_0/g_j)$ and $(1, -3 g_0/g_j)$ and step halving.
//! Start: each point's own gap $g_j = i_j \hat k_{i,j}/\hat k_{x,j}$ (the ratio of the two
//! laws), $g_0$ the median of $g_j - \Delta_j$, $\ln k$ the mean of the $k_i$ law solved for it.
//!
//! Covariance $s\,(J^\top \Sigma^{-1} J)^{-1}$. With $J$ points the fit has $2J - 2$ degrees of
//! freedom, and $\chi^2$ tests the magnet law (the $i_0$ and $g$ scaling) against the
//! estimates' own spread: when it exceeds its 95 % point, $s = \chi^2/(2J-2)$ (the law holds
//! less well than the estimates' intervals say: an iron-saturated or eddy-current magnet,
//! or intervals too narrow), else $s = 1$ — the rule of the zero-amplitude extrapolation
//! (module `amplitude`). Intervals $\exp(\hat p \pm z\sigma)$.
//!
//! # Identifiable without the drawing
//! The ratio of the laws, $k_i/k_x = g/i_0$, is the plant's static ratio, identifiable without
//! the rotor's mass and inertia ([`super::PhysicalFit::ratio`]): so **each operating point's
//! effective gap** $g_j = i_j k_{i,j}/k_{x,j}$ needs only the bias current and the amplifier
//! and sensor gains ([`MagnetLawFit::gaps_from_ratio`]). The constant $k$ needs $k_i$ itself,
//! hence the mass.
//!
//! # Use
//! [`MagnetLawFit::predict`] gives $k_i$, $k_x$ with intervals at any bias and gap offset
//! (e.g. the bias that gives a wanted stiffness); at the nominal point it pools every operating
//! point's information.

use super::{MachinePhysicalFit, PhysicalFit};
use crate::error::{Error, Result};
use crate::validate::machine::normal_quantile;
use crate::validate::residuals::chi2_95;

/// One operating point's gray-box estimate of $k_i$ and $k_x$ with its set point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AtOperatingPoint {
    /// Bias current $i_j$ \[A\] (the amplifier's set point).
    pub bias_current_a: f64,
    /// Gap offset $\Delta_j$ from the nominal gap \[m\] (0 at the nominal gap; positive = wider).
    pub gap_offset_m: f64,
    /// The estimate of $k_i$ \[N/A\].
    pub k_i: f64,
    /// The estimate of $k_x$ \[N/m\].
    pub k_x: f64,
    /// The covariance of $(\ln k_i, \ln k_x)$, 2 × 2 row-major.
    pub cov_ln: [f64; 4],
}

impl AtOperatingPoint {
    /// The point from a single-axis gray-box fit at bias `bias_current_a` and gap offset
    /// `gap_offset_m` (the fit's $k_i$, $k_x$ and the first 2 × 2 block of its covariance).
    pub fn from_fit(bias_current_a: f64, gap_offset_m: f64, fit: &PhysicalFit) -> Self {
        let c = &fit.covariance;
        Self {
            bias_current_a,
            gap_offset_m,
            k_i: fit.params.k_i,
            k_x: fit.params.k_x,
            cov_ln: [c[0], c[1], c[6], c[7]],
        }
    }

    /// The point of axis `axis` (0–3: xa, xb, ya, yb) from a whole-machine gray-box fit at bias
    /// `bias_current_a` and gap offset `gap_offset_m`: that axis' $k_i$, $k_x$ and the 2 × 2
    /// block of the fit's covariance (rows and columns `axis` and `4 + axis`), so that each
    /// bearing's magnet gets its own law.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an axis above 3.
    pub fn from_machine_fit(
        bias_current_a: f64,
        gap_offset_m: f64,
        fit: &MachinePhysicalFit,
        axis: usize,
    ) -> Result<Self> {
        if axis > 3 {
            return Err(Error::invalid(
                "axis",
                format!("must be 0-3 (xa, xb, ya, yb), got {axis}"),
            ));
        }
        let c = &fit.covariance;
        let (i, x) = (axis, 4 + axis);
        Ok(Self {
            bias_current_a,
            gap_offset_m,
            k_i: fit.params.k_i[axis],
            k_x: fit.params.k_x[axis],
            cov_ln: [c[i * 12 + i], c[i * 12 + x], c[x * 12 + i], c[x * 12 + x]],
        })
    }

    /// The point at zero excitation amplitude from gray-box fits at several excitation levels
    /// of one operating point (`(level, fit)`, the levels' records independent): $k_i$, $k_x$
    /// and their standard deviations from [`super::extrapolate_to_zero_amplitude`], their
    /// correlation that of the two intercepts. Each intercept is a linear combination
    /// $\hat\theta_0 = \sum_l c_l \hat\theta_l$ of the levels' estimates, with
    /// $c = e_0^\top (X^\top W X)^{-1} X^\top W$ of the parameter's own weighted line, so
    /// $\operatorname{cov}(\ln k_{i,0}, \ln k_{x,0}) = \sum_l c^{(i)}_l c^{(x)}_l
    /// \operatorname{cov}_l(\ln k_i, \ln k_x)$.
    ///
    /// # Errors
    /// Those of [`super::extrapolate_to_zero_amplitude`].
    pub fn from_levels(
        bias_current_a: f64,
        gap_offset_m: f64,
        fits: &[(f64, &PhysicalFit)],
        confidence: f64,
    ) -> Result<Self> {
        let points: Vec<super::AtLevel> = fits
            .iter()
            .map(|(level, f)| super::AtLevel {
                level: *level,
                params: f.params,
                std: f.std,
            })
            .collect();
        let zero = super::extrapolate_to_zero_amplitude(&points, confidence)?;
        let x: Vec<f64> = fits.iter().map(|(a, _)| a * a).collect();
        let weights = |k: usize| {
            // the weighted line's intercept coefficients (var of ln p: cov[k][k])
            let w: Vec<f64> = fits
                .iter()
                .map(|(_, f)| 1.0 / f.covariance[k * 7])
                .collect();
            let (s0, s1, s2) = w.iter().zip(&x).fold((0.0, 0.0, 0.0), |acc, (w, x)| {
                (acc.0 + w, acc.1 + w * x, acc.2 + w * x * x)
            });
            let det = s0 * s2 - s1 * s1;
            w.iter()
                .zip(&x)
                .map(|(w, x)| w * (s2 - s1 * x) / det)
                .collect::<Vec<f64>>()
        };
        let (ci, cx) = (weights(0), weights(1));
        let (mut vi, mut vx, mut cix) = (0.0, 0.0, 0.0);
        for (l, (_, f)) in fits.iter().enumerate() {
            let c = &f.covariance;
            vi += ci[l] * ci[l] * c[0];
            vx += cx[l] * cx[l] * c[7];
            cix += ci[l] * cx[l] * c[1];
        }
        let rho = (cix / (vi * vx).sqrt()).clamp(-0.999, 0.999);
        let (si, sx) = (zero.std[0] / zero.params.k_i, zero.std[1] / zero.params.k_x);
        Ok(Self {
            bias_current_a,
            gap_offset_m,
            k_i: zero.params.k_i,
            k_x: zero.params.k_x,
            cov_ln: [si * si, rho * si * sx, rho * si * sx, sx * sx],
        })
    }
}

/// $k_i$ or $k_x$ predicted by the magnet law, with its standard deviation and interval.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Predicted {
    /// The value.
    pub value: f64,
    /// Its standard deviation (to first order).
    pub std: f64,
    /// Its confidence interval.
    pub interval: (f64, f64),
}

/// What [`fit_magnet_law`] returns (module docs).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MagnetLawFit {
    /// The magnet constant $k$ \[N m²/A²\].
    pub force_constant: f64,
    /// The effective nominal air gap $g_0$ \[m\].
    pub air_gap_m: f64,
    /// Standard deviations of $k$ and $g_0$ (to first order).
    pub std: [f64; 2],
    /// Confidence intervals of $k$ and $g_0$.
    pub intervals: [(f64, f64); 2],
    /// Covariance of $(\ln k, \ln g_0)$, 2 × 2 row-major (with the factor $s$).
    pub covariance: [f64; 4],
    /// $\chi^2$ of the fit.
    pub chi2: f64,
    /// Its degrees of freedom $2J - 2$.
    pub dof: usize,
    /// The variance factor $s$ (module docs).
    pub variance_scale: f64,
    /// Each point's whitened residuals ($L_j^{-1} r_j$ with $\Sigma_j = L_j L_j^\top$), in the
    /// order of the points: $k_i$, then $k_x$.
    pub residuals: Vec<[f64; 2]>,
    /// Each point's own effective gap $i_j k_{i,j}/k_{x,j}$ \[m\] with its interval (module
    /// docs: identifiable without the drawing).
    pub gaps_from_ratio: Vec<(f64, (f64, f64))>,
    /// Gauss–Newton iterations.
    pub iterations: usize,
    /// The confidence level.
    pub confidence: f64,
}

impl MagnetLawFit {
    /// $k_i$ and $k_x$ at bias `bias_current_a` and gap offset `gap_offset_m` (module docs).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a bias that is not positive and finite, or an offset that
    /// closes the estimated gap.
    pub fn predict(
        &self,
        bias_current_a: f64,
        gap_offset_m: f64,
    ) -> Result<(Predicted, Predicted)> {
        if !(bias_current_a.is_finite() && bias_current_a > 0.0) {
            return Err(Error::invalid(
                "bias_current_a",
                format!("must be positive and finite, got {bias_current_a}"),
            ));
        }
        let g = self.air_gap_m + gap_offset_m;
        if !(gap_offset_m.is_finite() && g > 0.0) {
            return Err(Error::invalid(
                "gap_offset_m",
                format!(
                    "{gap_offset_m} m closes the estimated gap of {} m",
                    self.air_gap_m
                ),
            ));
        }
        let z = normal_quantile(0.5 + 0.5 * self.confidence);
        let c = self.air_gap_m / g;
        let one = |power_i: f64, power_g: f64| {
            let value = 4.0 * self.force_constant * bias_current_a.powf(power_i) / g.powf(power_g);
            let grad = [1.0, -power_g * c];
            let var = quad(&self.covariance, grad).max(0.0);
            let sd = var.sqrt();
            Predicted {
                value,
                std: value * sd,
                interval: (value * (-z * sd).exp(), value * (z * sd).exp()),
            }
        };
        Ok((one(1.0, 2.0), one(2.0, 3.0)))
    }
}

/// $g^\top C g$ for a 2 × 2 row-major $C$.
fn quad(c: &[f64; 4], g: [f64; 2]) -> f64 {
    g[0] * (c[0] * g[0] + c[1] * g[1]) + g[1] * (c[2] * g[0] + c[3] * g[1])
}

/// The lower Cholesky factor `(l11, l21, l22)` of a symmetric 2 × 2 matrix, `None` unless it
/// is positive definite.
fn cholesky2(c: &[f64; 4]) -> Option<(f64, f64, f64)> {
    let a = c[0];
    let b = 0.5 * (c[1] + c[2]);
    if !(a.is_finite() && a > 0.0 && b.is_finite() && c[3].is_finite()) {
        return None;
    }
    let l11 = a.sqrt();
    let l21 = b / l11;
    let d = c[3] - l21 * l21;
    (d > 0.0).then(|| (l11, l21, d.sqrt()))
}

/// One point's whitened Jacobian rows ($k_i$, $k_x$) with respect to $(\ln k, \ln g_0)$.
type JacobianRows = [[f64; 2]; 2];

/// The whitened residuals and Jacobian rows of all points at $p = (\ln k, \ln g_0)$; `None`
/// when a point's gap $g_0 + \Delta_j$ is not positive.
fn whitened(
    points: &[AtOperatingPoint],
    factors: &[(f64, f64, f64)],
    p: [f64; 2],
) -> Option<(Vec<[f64; 2]>, Vec<JacobianRows>)> {
    let g0 = p[1].exp();
    let mut res = Vec::with_capacity(points.len());
    let mut jac = Vec::with_capacity(points.len());
    for (pt, &(l11, l21, l22)) in points.iter().zip(factors) {
        let g = g0 + pt.gap_offset_m;
        if g.is_nan() || g <= 0.0 {
            return None;
        }
        let (li, lg) = (pt.bias_current_a.ln(), g.ln());
        let base = 4f64.ln() + p[0];
        let r = [
            pt.k_i.ln() - (base + li - 2.0 * lg),
            pt.k_x.ln() - (base + 2.0 * li - 3.0 * lg),
        ];
        // d model / d p; the residual's derivative is its negative (sign irrelevant in GN
        // when used consistently below)
        let c = g0 / g;
        let j = [[1.0, -2.0 * c], [1.0, -3.0 * c]];
        // L^{-1} v for the lower-triangular L
        let solve = |v: [f64; 2]| {
            let a = v[0] / l11;
            [a, (v[1] - l21 * a) / l22]
        };
        res.push(solve(r));
        let c0 = solve([j[0][0], j[1][0]]);
        let c1 = solve([j[0][1], j[1][1]]);
        jac.push([[c0[0], c1[0]], [c0[1], c1[1]]]);
    }
    Some((res, jac))
}

fn cost(res: &[[f64; 2]]) -> f64 {
    res.iter().map(|r| r[0] * r[0] + r[1] * r[1]).sum()
}

/// The information matrix $J^\top J$ and $J^\top r$ of the whitened problem.
fn normal_equations(res: &[[f64; 2]], jac: &[JacobianRows]) -> ([f64; 4], [f64; 2]) {
    let mut a = [0.0; 4];
    let mut b = [0.0; 2];
    for (r, j) in res.iter().zip(jac) {
        for row in 0..2 {
            let (j0, j1) = (j[row][0], j[row][1]);
            a[0] += j0 * j0;
            a[1] += j0 * j1;
            a[3] += j1 * j1;
            b[0] += j0 * r[row];
            b[1] += j1 * r[row];
        }
    }
    a[2] = a[1];
    (a, b)
}

fn invert2(a: &[f64; 4]) -> Option<[f64; 4]> {
    let det = a[0] * a[3] - a[1] * a[2];
    let scale = a[0].abs().max(a[3].abs());
    if !(det.is_finite() && det > 1e-14 * scale * scale) {
        return None;
    }
    Some([a[3] / det, -a[1] / det, -a[2] / det, a[0] / det])
}

/// Fits the magnet law to the gray-box estimates at the operating points (module docs), at the
/// confidence level `confidence`.
///
/// # Errors
/// [`Error::InvalidArgument`] for no point, a bias, $k_i$ or $k_x$ that is not positive and
/// finite, an offset that is not finite, a covariance that is not positive definite, a
/// confidence level outside (0, 1), or offsets that no positive gap fits (an offset closing the
/// gap that the ratios give); [`Error::Numerical`] when the iteration leaves the valid region.
///
/// # Example
/// Two exact operating points of a magnet with $k = 2.5\cdot10^{-5}$ N m²/A² and
/// $g_0 = 0.4$ mm, at 2 A and at 1.6 A with the gap 10 µm wider:
/// ```
/// use ambid_core::estimate::graybox::{fit_magnet_law, AtOperatingPoint};
/// let (k, g0) = (2.5e-5, 4e-4);
/// let at = |i: f64, d: f64| {
///     let g = g0 + d;
///     AtOperatingPoint { bias_current_a: i, gap_offset_m: d, k_i: 4.0 * k * i / (g * g),
///         k_x: 4.0 * k * i * i / (g * g * g), cov_ln: [1e-6, 2e-7, 2e-7, 4e-6] }
/// };
/// let fit = fit_magnet_law(&[at(2.0, 0.0), at(1.6, 1e-5)], 0.95).unwrap();
/// assert!((fit.force_constant / k - 1.0).abs() < 1e-9);
/// assert!((fit.air_gap_m / g0 - 1.0).abs() < 1e-9);
/// assert_eq!(fit.dof, 2);
/// let (ki, _) = fit.predict(2.4, 0.0).unwrap();
/// assert!((ki.value / (4.0 * k * 2.4 / (g0 * g0)) - 1.0).abs() < 1e-9);
/// ```
pub fn fit_magnet_law(points: &[AtOperatingPoint], confidence: f64) -> Result<MagnetLawFit> {
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(Error::invalid(
            "confidence",
            format!("the confidence level must lie in (0, 1), got {confidence}"),
        ));
    }
    if points.is_empty() {
        return Err(Error::invalid(
            "points",
            "no operating point: the magnet law needs at least one gray-box estimate",
        ));
    }
    let mut factors = Vec::with_capacity(points.len());
    for (n, p) in points.iter().enumerate() {
        for (name, v) in [
            ("bias_current_a", p.bias_current_a),
            ("k_i", p.k_i),
            ("k_x", p.k_x),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(
                    name,
                    format!("operating point {n}: must be positive and finite, got {v}"),
                ));
            }
        }
        if !p.gap_offset_m.is_finite() {
            return Err(Error::invalid(
                "gap_offset_m",
                format!(
                    "operating point {n}: must be finite, got {}",
                    p.gap_offset_m
                ),
            ));
        }
        factors.push(cholesky2(&p.cov_ln).ok_or_else(|| {
            Error::invalid(
                "cov_ln",
                format!(
                    "operating point {n}: the covariance of (ln k_i, ln k_x) must be positive definite, got {:?}",
                    p.cov_ln
                ),
            )
        })?);
    }
    // start (module docs)
    let mut g0s: Vec<f64> = points
        .iter()
        .map(|p| p.bias_current_a * p.k_i / p.k_x - p.gap_offset_m)
        .collect();
    g0s.sort_by(f64::total_cmp);
    let g0 = g0s[g0s.len() / 2];
    let max_closing = points
        .iter()
        .map(|p| -p.gap_offset_m)
        .fold(f64::NEG_INFINITY, f64::max);
    if !(g0 > max_closing && g0 > 0.0) {
        return Err(Error::invalid(
            "gap_offset_m",
            format!(
                "the operating points' ratios k_i/k_x give a nominal gap of {g0:.3e} m, which the \
                 offsets (down to {:.3e} m) close: check the offsets' sign (positive = wider) and unit (m)",
                -max_closing
            ),
        ));
    }
    let lnk0 = points
        .iter()
        .map(|p| {
            let g = g0 + p.gap_offset_m;
            p.k_i.ln() - 4f64.ln() - p.bias_current_a.ln() + 2.0 * g.ln()
        })
        .sum::<f64>()
        / points.len() as f64;
    let mut p = [lnk0, g0.ln()];
    let invalid = || {
        Error::numerical(
            "the magnet law",
            "the iteration left the region where every gap is positive",
        )
    };
    let (mut res, mut jac) = whitened(points, &factors, p).ok_or_else(invalid)?;
    let mut iterations = 0;
    for it in 1..=100 {
        iterations = it;
        let (a, b) = normal_equations(&res, &jac);
        let inv = invert2(&a).ok_or_else(|| {
            Error::numerical("the magnet law", "the information matrix is singular")
        })?;
        // residual = obs - model, so the Gauss-Newton step on p is +(J'J)^{-1} J' r
        let step = [inv[0] * b[0] + inv[1] * b[1], inv[2] * b[0] + inv[3] * b[1]];
        let c0 = cost(&res);
        let mut t = 1.0;
        let mut accepted = false;
        for _ in 0..40 {
            let q = [p[0] + t * step[0], p[1] + t * step[1]];
            if let Some((r2, j2)) = whitened(points, &factors, q) {
                if cost(&r2) <= c0 {
                    (p, res, jac) = (q, r2, j2);
                    accepted = true;
                    break;
                }
            }
            t *= 0.5;
        }
        if !accepted || (t * step[0]).abs().max((t * step[1]).abs()) < 1e-13 {
            break;
        }
    }
    let chi2 = cost(&res);
    let dof = 2 * points.len() - 2;
    let scale = if dof > 0 && chi2 > chi2_95(dof) {
        chi2 / dof as f64
    } else {
        1.0
    };
    let (a, _) = normal_equations(&res, &jac);
    let inv = invert2(&a)
        .ok_or_else(|| Error::numerical("the magnet law", "the information matrix is singular"))?;
    let covariance = inv.map(|v| v * scale);
    let z = normal_quantile(0.5 + 0.5 * confidence);
    let (k, g0) = (p[0].exp(), p[1].exp());
    let spread = |v: f64, var: f64| {
        let sd = var.max(0.0).sqrt();
        (v * sd, (v * (-z * sd).exp(), v * (z * sd).exp()))
    };
    let (sk, ik) = spread(k, covariance[0]);
    let (sg, ig) = spread(g0, covariance[3]);
    let gaps_from_ratio = points
        .iter()
        .map(|pt| {
            let c = &pt.cov_ln;
            let g = pt.bias_current_a * pt.k_i / pt.k_x;
            (g, spread(g, c[0] + c[3] - c[1] - c[2]).1)
        })
        .collect();
    Ok(MagnetLawFit {
        force_constant: k,
        air_gap_m: g0,
        std: [sk, sg],
        intervals: [ik, ig],
        covariance,
        chi2,
        dof,
        variance_scale: scale,
        residuals: res,
        gaps_from_ratio,
        iterations,
        confidence,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    const K: f64 = 2.2e-5;
    const G0: f64 = 4.3e-4;

    /// The seed study's five points (nominal, bias ±20 %, gap ±10 µm) with correlated log
    /// errors of 0.1 % / 0.3 % (correlation 0.6), moved by the draw `e` when given.
    fn study(rng: Option<&mut ChaCha8Rng>) -> Vec<AtOperatingPoint> {
        let (si, sx, rho) = (1e-3, 3e-3, 0.6);
        let cov = [si * si, rho * si * sx, rho * si * sx, sx * sx];
        let (l11, l21, l22) = cholesky2(&cov).unwrap();
        let mut draws: Vec<[f64; 2]> = vec![[0.0; 2]; 5];
        if let Some(r) = rng {
            for d in &mut draws {
                let (a, b): (f64, f64) = (StandardNormal.sample(r), StandardNormal.sample(r));
                *d = [l11 * a, l21 * a + l22 * b];
            }
        }
        [
            (2.0, 0.0),
            (1.6, 0.0),
            (2.4, 0.0),
            (2.0, -1e-5),
            (2.0, 1e-5),
        ]
        .iter()
        .zip(draws)
        .map(|(&(i, d), e)| {
            let g = G0 + d;
            AtOperatingPoint {
                bias_current_a: i,
                gap_offset_m: d,
                k_i: 4.0 * K * i / (g * g) * e[0].exp(),
                k_x: 4.0 * K * i * i / (g * g * g) * e[1].exp(),
                cov_ln: cov,
            }
        })
        .collect()
    }

    #[test]
    fn exact_points_give_the_constant_and_the_gap() {
        let fit = fit_magnet_law(&study(None), 0.95).unwrap();
        assert!((fit.force_constant / K - 1.0).abs() < 1e-10);
        assert!((fit.air_gap_m / G0 - 1.0).abs() < 1e-10);
        assert!(fit.chi2 < 1e-16, "{}", fit.chi2);
        assert_eq!(fit.dof, 8);
        for (g, _) in &fit.gaps_from_ratio[..3] {
            assert!((g / G0 - 1.0).abs() < 1e-12);
        }
        assert!((fit.gaps_from_ratio[3].0 / (G0 - 1e-5) - 1.0).abs() < 1e-12);
    }

    /// The covariance against an oracle: the linear least-squares of the linearised problem,
    /// written out with the full 10 × 2 design matrix and the block-diagonal weight.
    #[test]
    fn the_covariance_is_the_weighted_least_squares_one() {
        let pts = study(None);
        let fit = fit_magnet_law(&pts, 0.95).unwrap();
        let mut info = [[0.0; 2]; 2];
        for p in &pts {
            let c = G0 / (G0 + p.gap_offset_m);
            let x = [[1.0, -2.0 * c], [1.0, -3.0 * c]];
            let det = p.cov_ln[0] * p.cov_ln[3] - p.cov_ln[1] * p.cov_ln[2];
            let w = [
                [p.cov_ln[3] / det, -p.cov_ln[1] / det],
                [-p.cov_ln[2] / det, p.cov_ln[0] / det],
            ];
            for a in 0..2 {
                for b in 0..2 {
                    for r in 0..2 {
                        for s in 0..2 {
                            info[a][b] += x[r][a] * w[r][s] * x[s][b];
                        }
                    }
                }
            }
        }
        let det = info[0][0] * info[1][1] - info[0][1] * info[1][0];
        let var_lng = info[0][0] / det;
        assert!((fit.covariance[3] / var_lng - 1.0).abs() < 1e-8);
        assert!((fit.std[1] / (G0 * var_lng.sqrt()) - 1.0).abs() < 1e-6);
    }

    /// Monte Carlo: 2000 studies with draws from the stated covariances; the 95 % intervals of
    /// k and g0 cover in 93.5-96.5 % and the mean chi2 is the dof.
    #[test]
    fn intervals_cover_at_their_level() {
        let mut rng = ChaCha8Rng::seed_from_u64(23);
        let n = 2000;
        let (mut ck, mut cg, mut chi) = (0, 0, 0.0);
        for _ in 0..n {
            let fit = fit_magnet_law(&study(Some(&mut rng)), 0.95).unwrap();
            ck += usize::from(fit.intervals[0].0 <= K && K <= fit.intervals[0].1);
            cg += usize::from(fit.intervals[1].0 <= G0 && G0 <= fit.intervals[1].1);
            chi += fit.chi2 / n as f64;
        }
        for c in [ck, cg] {
            let f = c as f64 / n as f64;
            assert!((0.935..=0.965).contains(&f), "coverage {f}");
        }
        assert!((chi / 8.0 - 1.0).abs() < 0.06, "mean chi2 {chi}");
    }

    #[test]
    fn a_single_point_is_determined_exactly() {
        let pts = study(None);
        let fit = fit_magnet_law(&pts[1..2], 0.95).unwrap();
        assert_eq!(fit.dof, 0);
        assert!((fit.air_gap_m / G0 - 1.0).abs() < 1e-12);
        assert!((fit.force_constant / K - 1.0).abs() < 1e-12);
    }

    #[test]
    fn bad_input_is_named() {
        let good = study(None);
        let mut p = good.clone();
        p[1].bias_current_a = f64::NAN;
        let e = fit_magnet_law(&p, 0.95).unwrap_err().to_string();
        assert!(
            e.contains("bias_current_a") && e.contains("operating point 1"),
            "{e}"
        );
        let mut p = good.clone();
        p[2].cov_ln = [1e-6, 2e-6, 2e-6, 1e-6];
        let e = fit_magnet_law(&p, 0.95).unwrap_err().to_string();
        assert!(e.contains("positive definite"), "{e}");
        let mut p = good.clone();
        p[3].gap_offset_m = -1.0; // closes the gap
        let e = fit_magnet_law(&p, 0.95).unwrap_err().to_string();
        assert!(e.contains("close"), "{e}");
        assert!(fit_magnet_law(&[], 0.95).is_err());
        assert!(fit_magnet_law(&good, 1.0).is_err());
        let fit = fit_magnet_law(&good, 0.95).unwrap();
        assert!(fit.predict(0.0, 0.0).is_err());
        assert!(fit.predict(2.0, -1e-3).is_err());
    }
}
