//! Physical parameters of the whole rotor from its 4×4 plant FRF: $k_i$ and $k_x$ of **each
//! bearing's magnet in each direction** (axes `xa, xb, ya, yb`), the bending mode and its shape,
//! with confidence intervals.
//!
//! # Model
//! The plant of the machine with all four loops open (recorded $u$ → recorded $y$, the
//! matrix $P = T_{ry} S^{-1}$ the MIMO FRF estimates). Per plane $p \in \{x, y\}$ the rotor
//! coordinates are $q_p = (z_p, \theta_p, \eta_p)$ (translation, slope, free–free bending mode,
//! mass normalised); the displacement at bearing A is $c_A^\top q_p$ with
//! $c_A = (1, -a, \varphi_A)$, at B $c_B^\top q_p$ with $c_B = (1, b, \varphi_B)$. Each axis
//! $j$ has its own magnet, $F_j = k_{i,j}\, i_j + k_{x,j}\, x_j$, so per plane
//! $$ M\ddot q_p + \operatorname{diag}(0, 0, 2\zeta_b\omega_b)\dot q_p +
//!    \operatorname{diag}(0, 0, \omega_b^2)\, q_p =
//!    \sum_{B \in \{A, B\}} c_B \left(k_{x,pB}\, c_B^\top q_p + k_{i,pB}\, i_{pB}\right) $$
//! with $M = \operatorname{diag}(m, J, 1)$; the spinning rotor ($\Omega$ about $+z$, polar
//! inertia $J_p$) adds the gyroscopic moments
//! $J\ddot\theta_x \mathrel{+}= -\Omega J_p\dot\theta_y$,
//! $J\ddot\theta_y \mathrel{+}= +\Omega J_p\dot\theta_x$ (forward whirl stiffened); the bending
//! mode is planar, the same in both planes. Amplifiers $\dot i = \omega_a(g_a u - i)$ and sensors
//! $\dot y = \omega_s(g_s x - y)$ per axis; the 20-state model is discretised with a zero-order
//! hold and each input passes $d$ samples of computation delay (the drawing's). This is the
//! physics of the single-axis model of [`super`] without loop B closed, written for both
//! planes.
//!
//! # Estimate
//! $\theta = (\ln k_{i,j})_{j=1..4}, (\ln k_{x,j})_{j=1..4}, \ln f_b, \ln\zeta_b,
//! \varphi_A\sqrt m, \varphi_B\sqrt m$ (12 parameters) minimises
//! $\sum_k \sum_{i,j} |P_{ij}(\theta, z_k) - G_{ij,k}|^2 / \sigma_{ij,k}^2$ over the FRF's lines
//! and all 16 entries (each entry's own variance; the correlation between entries is not
//! modelled) by Levenberg–Marquardt with a central-difference Jacobian. Starts, from the data:
//! * the static ratios: with all loops open the rigid plane's static plant is
//!   $-\operatorname{diag}(k_{i,A}/k_{x,A},\ k_{i,B}/k_{x,B})\,g_a g_s$ (the rigid map
//!   $\Phi = (c_A, c_B)$ restricted to $(z, \theta)$ is invertible, so
//!   $\Phi^\top(\Phi K_x\Phi^\top)^{-1}\Phi = K_x^{-1}$), hence
//!   $r_j = |G_{jj}(f_{\min})|/(g_a g_s)$;
//! * a common scale $\kappa$ with $k_{x,j} = \kappa$, $k_{i,j} = r_j\kappa$, the least-cost value
//!   of a logarithmic grid of 57 values over $10^2$–$10^9$ N/m;
//! * the bending mode from the given candidates inside the lines (at most three) or, without
//!   any, the four best of a search: the three highest local maxima of
//!   $\sum_j |G_{jj}(f)| f^2$ (the mass line divided out) and a 48-point logarithmic grid over
//!   the lines, ranked by the cost with $\zeta_b = 0.05$; each with the mode-shape grid
//!   $\varphi_A\sqrt m \in \{0.7, 1.4, 2.8\}$, $\varphi_B\sqrt m \in \pm\{0.7, 1.4, 2.8\}$.
//!
//! The covariance is $\hat\sigma^2(J^\top J)^{-1}$ with
//! $\hat\sigma^2 = \max(1, \chi^2/(32N - 12))$; intervals $\exp(\hat\theta_j \pm z\sigma_j)$ for
//! the positive parameters, $\hat\theta_j \pm z\sigma_j$ for the mode shape (reported with
//! $\varphi_A > 0$; its sign is not identifiable).
//!
//! # Identifiable without the drawing
//! The static ratio $k_{i,j}/k_{x,j}$ of every axis (above), the open-loop poles (two unstable
//! rigid poles per plane) and the bending pole pairs. The bearing-coordinate mass matrix
//! $\Phi^{-1} M \Phi^{-\top}$ scales with $K_i$ and $K_x$ undetected, so the values
//! themselves need $m$, $J$, $a$, $b$ from the drawing.

use super::{
    central_jacobian, check_drawing, cost, spread, start_and_refine, Drawing, PhysicalOptions,
};
use crate::error::{Error, Result};
use crate::estimate::pem::lm::{LeastSquaresProblem, StopReason};
use crate::lti::{Frd, StateSpace};
use crate::validate::machine::normal_quantile;
use faer::{c64, Mat};
use std::f64::consts::PI;

/// The axes in the order of the plant's inputs and outputs and of the per-axis parameters.
pub const MACHINE_AXES: [&str; 4] = ["xa", "xb", "ya", "yb"];

/// The names of the twelve parameters, in the order of [`MachinePhysicalFit::intervals`].
pub const MACHINE_PARAMETER_NAMES: [&str; 12] = [
    "k_i_xa",
    "k_i_xb",
    "k_i_ya",
    "k_i_yb",
    "k_x_xa",
    "k_x_xb",
    "k_x_ya",
    "k_x_yb",
    "bending_hz",
    "bending_damping",
    "mode_shape_a",
    "mode_shape_b",
];

/// The physical parameters of the machine (per axis in the order [`MACHINE_AXES`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MachineParams {
    /// Force–current factor of each axis' magnet $k_{i,j}$ \[N/A\].
    pub k_i: [f64; 4],
    /// Negative stiffness of each axis' magnet $k_{x,j}$ \[N/m\].
    pub k_x: [f64; 4],
    /// Free–free bending frequency $f_b$ \[Hz\] (both planes).
    pub bending_hz: f64,
    /// Modal damping ratio $\zeta_b$.
    pub bending_damping: f64,
    /// Mass-normalised mode shape at bearing A \[kg^-½\].
    pub mode_shape_a: f64,
    /// The same at bearing B.
    pub mode_shape_b: f64,
}

impl MachineParams {
    /// The parameters in the order of [`MACHINE_PARAMETER_NAMES`].
    pub fn to_array(&self) -> [f64; 12] {
        let mut out = [0.0; 12];
        out[..4].copy_from_slice(&self.k_i);
        out[4..8].copy_from_slice(&self.k_x);
        out[8] = self.bending_hz;
        out[9] = self.bending_damping;
        out[10] = self.mode_shape_a;
        out[11] = self.mode_shape_b;
        out
    }
}

/// The rotor's spin: speed and polar inertia (the gyroscopic moments; irrelevant at
/// standstill).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Rotation {
    /// Speed \[rpm\], ≥ 0, about $+z$.
    pub speed_rpm: f64,
    /// Polar moment of inertia $J_p$ \[kg·m²\].
    pub polar_inertia_kgm2: f64,
}

impl Rotation {
    /// Standstill (no gyroscopic moments).
    pub const STANDSTILL: Rotation = Rotation {
        speed_rpm: 0.0,
        polar_inertia_kgm2: 0.0,
    };
}

fn check_params(p: &MachineParams) -> Result<()> {
    for (j, v) in p.k_i.iter().enumerate() {
        positive(MACHINE_PARAMETER_NAMES[j], *v)?;
    }
    for (j, v) in p.k_x.iter().enumerate() {
        positive(MACHINE_PARAMETER_NAMES[4 + j], *v)?;
    }
    positive("bending_hz", p.bending_hz)?;
    positive("bending_damping", p.bending_damping)?;
    if !(p.mode_shape_a.is_finite() && p.mode_shape_b.is_finite()) {
        return Err(Error::invalid("mode_shape", "must be finite"));
    }
    Ok(())
}

fn positive(name: &'static str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            name,
            format!("must be positive and finite, got {v}"),
        ))
    }
}

fn check_rotation(r: &Rotation) -> Result<()> {
    if !(r.speed_rpm.is_finite() && r.speed_rpm >= 0.0) {
        return Err(Error::invalid(
            "speed_rpm",
            format!("must be finite and ≥ 0, got {}", r.speed_rpm),
        ));
    }
    if !(r.polar_inertia_kgm2.is_finite() && r.polar_inertia_kgm2 >= 0.0) {
        return Err(Error::invalid(
            "polar_inertia_kgm2",
            format!("must be finite and ≥ 0, got {}", r.polar_inertia_kgm2),
        ));
    }
    if r.speed_rpm > 0.0 && r.polar_inertia_kgm2 == 0.0 {
        return Err(Error::invalid(
            "polar_inertia_kgm2",
            "must be given (> 0) at a speed above 0: the gyroscopic moments need it",
        ));
    }
    Ok(())
}

/// The gray-box plant of the machine (module docs): 4×4, discrete with sample time `ts`, all
/// loops open, $20 + 4d$ states.
///
/// # Errors
/// [`Error::InvalidArgument`] for a bad drawing, parameters or rotation, a sample time that is
/// not positive; the errors of the discretisation.
///
/// # Example
/// ```
/// use ambid_core::estimate::graybox::{graybox_machine_plant, Drawing, MachineParams, Rotation};
/// let d = Drawing { mass_kg: 5.0, inertia_kgm2: 0.104, bearing_a_m: 0.2, bearing_b_m: 0.2,
///     amplifier_bandwidth_hz: 2000.0, sensor_bandwidth_hz: 1e4, amplifier_gain: 1.0,
///     sensor_gain: 1.0, delay_samples: 1 };
/// let p = MachineParams { k_i: [58.0, 52.0, 60.0, 55.0], k_x: [2.9e5, 3.1e5, 2.8e5, 3.0e5],
///     bending_hz: 730.0, bending_damping: 0.01, mode_shape_a: 0.6, mode_shape_b: 0.6 };
/// let plant = graybox_machine_plant(&d, &p, &Rotation::STANDSTILL, 5e-5).unwrap();
/// // four unstable rigid poles (two per plane)
/// assert_eq!(plant.poles().unwrap().iter().filter(|z| z.norm() > 1.0).count(), 4);
/// // the static plant is -diag(k_i/k_x) per bearing (the bending mode adds ~1e-4 here)
/// let g = &plant.freq_response(&[1e-3]).unwrap()[0];
/// assert!((g[(1, 1)].re / (-52.0 / 3.1e5) - 1.0).abs() < 1e-2);
/// assert!(g[(0, 1)].norm() < 1e-6 * g[(0, 0)].norm());
/// ```
pub fn graybox_machine_plant(
    d: &Drawing,
    p: &MachineParams,
    rot: &Rotation,
    ts: f64,
) -> Result<StateSpace> {
    check_drawing(d)?;
    check_params(p)?;
    check_rotation(rot)?;
    if !(ts.is_finite() && ts > 0.0) {
        return Err(Error::invalid(
            "ts",
            format!("must be positive and finite, got {ts}"),
        ));
    }
    // states: q_x (0..3), q_y (3..6), q̇_x (6..9), q̇_y (9..12), currents (12..16), sensors
    // (16..20), axes in the order xa, xb, ya, yb
    const N: usize = 20;
    let ca = [1.0, -d.bearing_a_m, p.mode_shape_a];
    let cb = [1.0, d.bearing_b_m, p.mode_shape_b];
    let minv = [1.0 / d.mass_kg, 1.0 / d.inertia_kgm2, 1.0];
    let wa = 2.0 * PI * d.amplifier_bandwidth_hz;
    let ws = 2.0 * PI * d.sensor_bandwidth_hz;
    let wb = 2.0 * PI * p.bending_hz;
    let mut a = Mat::<f64>::zeros(N, N);
    let mut b = Mat::<f64>::zeros(N, 4);
    let mut c = Mat::<f64>::zeros(4, N);
    for plane in 0..2 {
        let (q0, v0) = (3 * plane, 6 + 3 * plane);
        let (ja, jb) = (2 * plane, 2 * plane + 1);
        for r in 0..3 {
            a[(q0 + r, v0 + r)] = 1.0;
            for s in 0..3 {
                a[(v0 + r, q0 + s)] =
                    minv[r] * (p.k_x[ja] * ca[r] * ca[s] + p.k_x[jb] * cb[r] * cb[s]);
            }
            a[(v0 + r, 12 + ja)] = minv[r] * ca[r] * p.k_i[ja];
            a[(v0 + r, 12 + jb)] = minv[r] * cb[r] * p.k_i[jb];
            a[(16 + ja, q0 + r)] = ws * d.sensor_gain * ca[r];
            a[(16 + jb, q0 + r)] = ws * d.sensor_gain * cb[r];
        }
        a[(v0 + 2, q0 + 2)] -= wb * wb;
        a[(v0 + 2, v0 + 2)] -= 2.0 * p.bending_damping * wb;
    }
    for j in 0..4 {
        a[(12 + j, 12 + j)] = -wa;
        b[(12 + j, j)] = wa * d.amplifier_gain;
        a[(16 + j, 16 + j)] = -ws;
        c[(j, 16 + j)] = 1.0;
    }
    // gyroscopic moments on the slopes' accelerations (indices 7 = θ̇_x, 10 = θ̇_y)
    let g = rot.speed_rpm * PI / 30.0 * rot.polar_inertia_kgm2 / d.inertia_kgm2;
    a[(7, 10)] = -g;
    a[(10, 7)] = g;
    let disc = StateSpace::continuous(a, b, c, Mat::zeros(4, 4))?.c2d_zoh(ts)?;
    let k = d.delay_samples;
    if k == 0 {
        return Ok(disc);
    }
    // each input j through a chain of k registers at 20 + j k .. 20 + (j + 1) k
    let n = N + 4 * k;
    let (ad, bd, cd) = (disc.a(), disc.b(), disc.c());
    let mut aa = Mat::<f64>::zeros(n, n);
    let mut ba = Mat::<f64>::zeros(n, 4);
    let mut cc = Mat::<f64>::zeros(4, n);
    for r in 0..N {
        for s in 0..N {
            aa[(r, s)] = ad[(r, s)];
        }
        for j in 0..4 {
            aa[(r, N + j * k + k - 1)] = bd[(r, j)];
        }
    }
    for j in 0..4 {
        let r0 = N + j * k;
        ba[(r0, j)] = 1.0;
        for s in 1..k {
            aa[(r0 + s, r0 + s - 1)] = 1.0;
        }
        for s in 0..N {
            cc[(j, s)] = cd[(j, s)];
        }
    }
    StateSpace::discrete(aa, ba, cc, Mat::zeros(4, 4), ts)
}

/// What [`fit_machine_physical`] returns.
#[derive(Debug, Clone)]
pub struct MachinePhysicalFit {
    /// The estimate ($\varphi_A > 0$).
    pub params: MachineParams,
    /// Standard deviations in the order of [`MACHINE_PARAMETER_NAMES`] (of the parameters
    /// themselves, to first order).
    pub std: [f64; 12],
    /// Confidence intervals `(low, high)`, same order.
    pub intervals: [(f64, f64); 12],
    /// Covariance of $\theta$ (module docs), 12 × 12 row-major.
    pub covariance: Vec<f64>,
    /// $\chi^2$ of the fit.
    pub chi2: f64,
    /// Its degrees of freedom $32N - 12$.
    pub dof: usize,
    /// The factor the covariance was inflated by, $\max(1, \chi^2/\text{dof})$.
    pub variance_scale: f64,
    /// The gray-box plant at the estimate.
    pub model: StateSpace,
    /// The rotation the fit assumed.
    pub rotation: Rotation,
    /// Iterations of the refinement.
    pub iterations: usize,
    /// Why the refinement stopped.
    pub stop: StopReason,
    /// The confidence level.
    pub confidence: f64,
}

impl MachinePhysicalFit {
    /// $k_{i,j}/k_{x,j}$ \[m/A\] of each axis with its interval (identifiable without the
    /// drawing, module docs).
    pub fn ratios(&self) -> [(f64, (f64, f64)); 4] {
        let c = &self.covariance;
        let z = normal_quantile(0.5 + 0.5 * self.confidence);
        std::array::from_fn(|j| {
            let (i, x) = (j, 4 + j);
            let var = (c[i * 12 + i] + c[x * 12 + x] - 2.0 * c[i * 12 + x]).max(0.0);
            let r = self.params.k_i[j] / self.params.k_x[j];
            let h = z * var.sqrt();
            (r, (r * (-h).exp(), r * h.exp()))
        })
    }
}

struct Problem<'a> {
    drawing: &'a Drawing,
    rotation: &'a Rotation,
    ts: f64,
    f: &'a [f64],
    g: Vec<Mat<c64>>,
    w: Vec<[f64; 16]>,
    sqrt_m: f64,
}

impl Problem<'_> {
    fn params(&self, x: &[f64]) -> MachineParams {
        MachineParams {
            k_i: std::array::from_fn(|j| x[j].exp()),
            k_x: std::array::from_fn(|j| x[4 + j].exp()),
            bending_hz: x[8].exp(),
            bending_damping: x[9].exp(),
            mode_shape_a: x[10] / self.sqrt_m,
            mode_shape_b: x[11] / self.sqrt_m,
        }
    }
}

impl LeastSquaresProblem for Problem<'_> {
    fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
        let m =
            graybox_machine_plant(self.drawing, &self.params(x), self.rotation, self.ts).ok()?;
        let r = m.freq_response(self.f).ok()?;
        let mut out = Vec::with_capacity(32 * r.len());
        for ((p, g), w) in r.iter().zip(&self.g).zip(&self.w) {
            for i in 0..4 {
                for j in 0..4 {
                    let e = (p[(i, j)] - g[(i, j)]) * w[4 * i + j];
                    if !(e.re.is_finite() && e.im.is_finite()) {
                        return None;
                    }
                    out.push(e.re);
                    out.push(e.im);
                }
            }
        }
        Some(out)
    }

    fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
        central_jacobian(self, x)
    }
}

/// Bending candidates without hints: the frequencies of the three highest local maxima of
/// $\sum_j |G_{jj}(f)|\,f^2$ (the diagonal with the rigid mass line divided out, where a
/// lightly damped mode stands out) and of a 48-point logarithmic grid over the lines, ranked by
/// the cost with $\zeta_b = 0.05$ and the shapes $(1.4, \pm 1.4)$; the best four, each with
/// $\zeta_b = 0.02$.
fn bending_candidates(
    prob: &mut Problem<'_>,
    kappa: f64,
    start: &dyn Fn(f64, f64, f64, f64, f64) -> Vec<f64>,
) -> Vec<(f64, f64)> {
    let f = prob.f;
    let (f_lo, f_hi) = (f[0], f[f.len() - 1]);
    let norm: Vec<f64> = (0..f.len())
        .map(|k| (0..4).map(|j| prob.g[k][(j, j)].norm()).sum::<f64>() * f[k] * f[k])
        .collect();
    let mut peaks: Vec<(f64, f64)> = (1..f.len().saturating_sub(1))
        .filter(|&k| norm[k] > norm[k - 1] && norm[k] >= norm[k + 1])
        .map(|k| (norm[k], f[k]))
        .collect();
    peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut freqs: Vec<f64> = peaks.iter().take(3).map(|p| p.1).collect();
    freqs.extend((0..48).map(|k| f_lo * (f_hi / f_lo).powf(k as f64 / 47.0)));
    let mut ranked: Vec<(f64, f64)> = freqs
        .iter()
        .map(|&fb| {
            let c = [1.4, -1.4]
                .iter()
                .map(|&pb| cost(prob, &start(kappa, fb, 0.05, 1.4, pb)))
                .fold(f64::INFINITY, f64::min);
            (c, fb)
        })
        .filter(|(c, _)| c.is_finite())
        .collect();
    ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
    ranked.iter().take(4).map(|&(_, fb)| (fb, 0.02)).collect()
}

/// Estimates the machine's physical parameters from its 4×4 plant FRF `frd` (discrete, with
/// every entry's variance; the lines to use, e.g. the fit band) with the drawing, the rotation
/// the FRF was measured at, and candidate bending modes `(f [Hz], ζ)` (e.g. from a black-box
/// model's poles; may be empty). Module docs for the model, the starts and the intervals.
///
/// # Errors
/// [`Error::InvalidArgument`] for an FRF that is not 4×4, is continuous, has no variances or
/// a variance that is not positive and finite, or fewer than 2 lines; a bad drawing or
/// rotation; a confidence level outside (0, 1). [`Error::Numerical`] when no start gives a
/// finite model or the information matrix is singular (a parameter these lines do not
/// determine, e.g. a bending mode outside the band).
///
/// # Example
/// ```
/// use ambid_core::estimate::graybox::{
///     fit_machine_physical, graybox_machine_plant, Drawing, MachineParams, PhysicalOptions,
///     Rotation,
/// };
/// use ambid_core::lti::Frd;
/// let d = Drawing { mass_kg: 5.0, inertia_kgm2: 0.104, bearing_a_m: 0.2, bearing_b_m: 0.2,
///     amplifier_bandwidth_hz: 2000.0, sensor_bandwidth_hz: 1e4, amplifier_gain: 1.0,
///     sensor_gain: 1.0, delay_samples: 1 };
/// let truth = MachineParams { k_i: [58.0, 52.0, 60.0, 55.0], k_x: [2.9e5, 3.1e5, 2.8e5, 3.0e5],
///     bending_hz: 730.0, bending_damping: 0.01, mode_shape_a: 0.6, mode_shape_b: 0.5 };
/// let ts = 5e-5;
/// let f: Vec<f64> = (1..=60).map(|k| 10.0 * 1.09f64.powi(k)).collect(); // 11 Hz – 1.8 kHz
/// let plant = graybox_machine_plant(&d, &truth, &Rotation::STANDSTILL, ts).unwrap();
/// let exact = Frd::from_model(&plant, &f).unwrap();
/// // variances 1e-4 |P_ij|² plus a floor for the entries that are 0 (the planes at standstill)
/// let var: Vec<f64> = exact.values().iter().map(|v| 1e-4 * v.norm_sqr() + 1e-16).collect();
/// let frd = Frd::new_matrix(f.clone(), 4, 4, exact.values().to_vec(), Some(var), Some(ts)).unwrap();
/// let fit = fit_machine_physical(&frd, &d, &Rotation::STANDSTILL, &[], &PhysicalOptions::default())
///     .unwrap();
/// for j in 0..4 {
///     assert!((fit.params.k_i[j] / truth.k_i[j] - 1.0).abs() < 1e-6);
///     assert!((fit.params.k_x[j] / truth.k_x[j] - 1.0).abs() < 1e-6);
/// }
/// assert!((fit.params.bending_hz / 730.0 - 1.0).abs() < 1e-6);
/// ```
pub fn fit_machine_physical(
    frd: &Frd,
    drawing: &Drawing,
    rotation: &Rotation,
    bending: &[(f64, f64)],
    opts: &PhysicalOptions,
) -> Result<MachinePhysicalFit> {
    if frd.ny() != 4 || frd.nu() != 4 {
        return Err(Error::invalid(
            "frd",
            format!(
                "is {}×{}; the machine's physical parameters need the 4×4 plant (axes xa, xb, ya, yb)",
                frd.ny(),
                frd.nu()
            ),
        ));
    }
    check_drawing(drawing)?;
    check_rotation(rotation)?;
    if !(opts.confidence > 0.0 && opts.confidence < 1.0) {
        return Err(Error::invalid(
            "confidence",
            format!("must lie in (0, 1), got {}", opts.confidence),
        ));
    }
    let ts = frd.ts().ok_or_else(|| {
        Error::invalid(
            "frd",
            "must be discrete (the sample time of the recorded data)",
        )
    })?;
    if frd.len() < 2 {
        return Err(Error::invalid(
            "frd",
            format!(
                "has {} line(s); the twelve parameters need at least 2 lines of 16 entries",
                frd.len()
            ),
        ));
    }
    let mut g = Vec::with_capacity(frd.len());
    let mut w = Vec::with_capacity(frd.len());
    for k in 0..frd.len() {
        let var = frd.variance_at(k)?.ok_or_else(|| {
            Error::invalid("frd", "needs the FRF's variances (inverse-variance fit)")
        })?;
        let gk = frd.at(k)?;
        let mut wk = [0.0; 16];
        for i in 0..4 {
            for j in 0..4 {
                let v = var[(i, j)];
                let x = gk[(i, j)];
                if !(v.is_finite() && v > 0.0 && x.re.is_finite() && x.im.is_finite()) {
                    return Err(Error::invalid(
                        "frd",
                        format!(
                            "entry ({}, {}) at {} Hz: every value must be finite and every variance positive and finite, got {x} with variance {v}",
                            MACHINE_AXES[i],
                            MACHINE_AXES[j],
                            frd.f_hz()[k]
                        ),
                    ));
                }
                wk[4 * i + j] = (2.0 / v).sqrt();
            }
        }
        g.push(gk);
        w.push(wk);
    }
    let f = frd.f_hz();
    let ratio: [f64; 4] = std::array::from_fn(|j| {
        g[0][(j, j)].norm() / (drawing.amplifier_gain * drawing.sensor_gain)
    });
    if let Some(j) = ratio.iter().position(|r| !(r.is_finite() && *r > 0.0)) {
        return Err(Error::invalid(
            "frd",
            format!(
                "the diagonal entry of {} at the lowest line is zero: no static ratio k_i/k_x to start from",
                MACHINE_AXES[j]
            ),
        ));
    }
    let mut prob = Problem {
        drawing,
        rotation,
        ts,
        f,
        g,
        w,
        sqrt_m: drawing.mass_kg.sqrt(),
    };
    let (f_lo, f_hi) = (f[0], f[f.len() - 1]);
    // the common scale κ, with a bending mode above the band
    let start = |kappa: f64, fb: f64, zb: f64, pa: f64, pb: f64| -> Vec<f64> {
        let mut x = Vec::with_capacity(12);
        x.extend(ratio.iter().map(|r| (r * kappa).ln()));
        x.extend([kappa.ln(); 4]);
        x.extend([fb.ln(), zb.ln(), pa, pb]);
        x
    };
    let mut best_kappa: Option<(f64, f64)> = None;
    for e in 0..57 {
        let kappa = 10f64.powf(2.0 + e as f64 / 8.0);
        let c = cost(&mut prob, &start(kappa, 2.0 * f_hi, 0.02, 1.0, 1.0));
        if c.is_finite() && best_kappa.is_none_or(|b| c < b.0) {
            best_kappa = Some((c, kappa));
        }
    }
    let (_, kappa) = best_kappa.ok_or_else(|| {
        Error::numerical(
            "the gray-box start",
            "no stiffness scale gives a finite gray-box model (check the drawing)",
        )
    })?;
    // bending starts: the given candidates inside the lines, else a search (module docs)
    let given: Vec<(f64, f64)> = bending
        .iter()
        .copied()
        .filter(|(fb, z)| (f_lo..=f_hi).contains(fb) && *z > 0.0)
        .take(3)
        .collect();
    let cands = if given.is_empty() {
        bending_candidates(&mut prob, kappa, &start)
    } else {
        given
    };
    let (x, report) = start_and_refine(
        &mut prob,
        &cands,
        |fb, zb, pa, pb| start(kappa, fb, zb, pa, pb),
        10,
        opts.max_iterations,
    )?;
    let sqrt_m = prob.sqrt_m;
    let sp = spread(&mut prob, &x, 10, sqrt_m, opts.confidence)?;
    let params = prob.params(&x);
    let model = graybox_machine_plant(drawing, &params, rotation, ts)?;
    Ok(MachinePhysicalFit {
        params,
        std: std::array::from_fn(|k| sp.std[k]),
        intervals: std::array::from_fn(|k| sp.intervals[k]),
        covariance: sp.cov,
        chi2: sp.chi2,
        dof: sp.dof,
        variance_scale: sp.scale,
        model,
        rotation: *rotation,
        iterations: report.iterations,
        stop: report.reason,
        confidence: opts.confidence,
    })
}

/// One whole-machine estimate at an excitation level (as [`MachinePhysicalFit::params`] and
/// [`MachinePhysicalFit::std`]); the level in any unit proportional to the amplitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MachineAtLevel {
    /// The excitation level $a > 0$.
    pub level: f64,
    /// The estimate at that level.
    pub params: MachineParams,
    /// Its standard deviations, in the order of [`MACHINE_PARAMETER_NAMES`].
    pub std: [f64; 12],
}

/// The machine's parameters extrapolated to zero amplitude (the single-axis
/// [`super::extrapolate_to_zero_amplitude`]'s rule per parameter: a weighted line in $a^2$, in
/// $\ln p$ for the positive parameters, module `amplitude`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MachineZeroAmplitude {
    /// The estimate at $a = 0$.
    pub params: MachineParams,
    /// Its standard deviations, in the order of [`MACHINE_PARAMETER_NAMES`].
    pub std: [f64; 12],
    /// Confidence intervals `(low, high)`, same order.
    pub intervals: [(f64, f64); 12],
    /// The slope per parameter: $\mathrm d\ln p/\mathrm d(a^2)$ (positive parameters),
    /// $\mathrm dp/\mathrm d(a^2)$ (mode shape).
    pub slope: [f64; 12],
    /// The line's $\chi^2$ per parameter (0 with two levels).
    pub chi2: [f64; 12],
    /// Its degrees of freedom $L - 2$.
    pub dof: usize,
    /// The variance factor per parameter.
    pub variance_scale: [f64; 12],
    /// The confidence level.
    pub confidence: f64,
}

impl MachineZeroAmplitude {
    /// The relative change of each parameter from $a = 0$ to level `a` predicted by the line
    /// (as [`super::ZeroAmplitude::change_at`]; for the mode shape relative to its value at
    /// $a = 0$).
    pub fn change_at(&self, a: f64) -> [f64; 12] {
        let p = self.params.to_array();
        std::array::from_fn(|k| {
            if k < 10 {
                (self.slope[k] * a * a).exp() - 1.0
            } else {
                self.slope[k] * a * a / p[k]
            }
        })
    }
}

/// The machine's physical parameters at zero excitation amplitude from estimates at two or more
/// levels, with intervals at `confidence`: the small-signal $k_x$ of nonlinear magnets, whose
/// estimate at a finite level is the best linear approximation's (docs/physical.md).
///
/// # Errors
/// As [`super::extrapolate_to_zero_amplitude`]: fewer than two distinct positive levels, a
/// standard deviation that is not finite and positive, a positive parameter that is not
/// positive, a confidence outside (0, 1).
///
/// # Example
/// ```
/// use ambid_core::estimate::graybox::{
///     extrapolate_machine_to_zero_amplitude, MachineAtLevel, MachineParams,
/// };
/// // every k_x 1 % and 2 % above 3e5 N/m at levels 0.1 and 0.1·√2: the line gives 3e5
/// let at = |a: f64, up: f64| MachineAtLevel {
///     level: a,
///     params: MachineParams { k_i: [58.0; 4], k_x: [3e5 * up.exp(); 4], bending_hz: 730.0,
///         bending_damping: 0.01, mode_shape_a: 0.6, mode_shape_b: 0.6 },
///     std: [0.01; 12],
/// };
/// let z = extrapolate_machine_to_zero_amplitude(
///     &[at(0.1, 0.01), at(0.1 * 2f64.sqrt(), 0.02)], 0.95).unwrap();
/// assert!(z.params.k_x.iter().all(|k| (k / 3e5 - 1.0).abs() < 1e-12));
/// assert!((z.slope[4] - 1.0).abs() < 1e-9);
/// ```
pub fn extrapolate_machine_to_zero_amplitude(
    points: &[MachineAtLevel],
    confidence: f64,
) -> Result<MachineZeroAmplitude> {
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(Error::invalid(
            "confidence",
            format!("the confidence level must lie in (0, 1), got {confidence}"),
        ));
    }
    let x = super::amplitude::level_squares(&points.iter().map(|p| p.level).collect::<Vec<_>>())?;
    for p in points {
        let v = p.params.to_array();
        for k in 0..12 {
            super::amplitude::check_estimate(
                MACHINE_PARAMETER_NAMES[k],
                v[k],
                p.std[k],
                k < 10,
                p.level,
            )?;
        }
    }
    let z = normal_quantile(0.5 + 0.5 * confidence);
    let mut est = [0.0; 12];
    let mut std = [0.0; 12];
    let mut intervals = [(0.0, 0.0); 12];
    let mut slope = [0.0; 12];
    let mut chi2 = [0.0; 12];
    let mut scale = [1.0; 12];
    for k in 0..12 {
        let values: Vec<f64> = points.iter().map(|p| p.params.to_array()[k]).collect();
        let sds: Vec<f64> = points.iter().map(|p| p.std[k]).collect();
        let l = super::amplitude::line_at_zero(&x, &values, &sds, k < 10, z);
        (est[k], std[k], intervals[k]) = (l.estimate, l.std, l.interval);
        (slope[k], chi2[k], scale[k]) = (l.slope, l.chi2, l.variance_scale);
    }
    Ok(MachineZeroAmplitude {
        params: MachineParams {
            k_i: std::array::from_fn(|j| est[j]),
            k_x: std::array::from_fn(|j| est[4 + j]),
            bending_hz: est[8],
            bending_damping: est[9],
            mode_shape_a: est[10],
            mode_shape_b: est[11],
        },
        std,
        intervals,
        slope,
        chi2,
        dof: points.len() - 2,
        variance_scale: scale,
        confidence,
    })
}

#[cfg(test)]
mod tests {
    use super::super::{extrapolate_to_zero_amplitude, AtLevel, PhysicalParams};
    use super::*;

    /// Each machine parameter's line is the single-axis rule's on the same numbers.
    #[test]
    fn the_machine_extrapolation_is_the_single_axis_rule_per_parameter() {
        let levels = [0.05, 0.08, 0.12];
        let mach: Vec<MachineAtLevel> = levels
            .iter()
            .enumerate()
            .map(|(l, &a)| {
                let f = 1.0 + 0.3 * a * a + 1e-4 * (l as f64 - 1.0);
                MachineAtLevel {
                    level: a,
                    params: MachineParams {
                        k_i: [58.0 / f, 55.0, 60.0 * f, 57.0],
                        k_x: [2.9e5 * f, 3.0e5 * f, 2.8e5, 3.1e5 * f * f],
                        bending_hz: 730.0 * f,
                        bending_damping: 0.01 * f,
                        mode_shape_a: 0.6 * f,
                        mode_shape_b: -0.5 / f,
                    },
                    std: std::array::from_fn(|k| 1e-3 * (k as f64 + 1.0) * (l as f64 + 1.0)),
                }
            })
            .collect();
        let z = extrapolate_machine_to_zero_amplitude(&mach, 0.9).unwrap();
        let zarr = z.params.to_array();
        for j in 0..4 {
            // the single-axis rule on (k_i of axis j, k_x of axis j, the bending, the shape)
            let pts: Vec<AtLevel> = mach
                .iter()
                .map(|m| AtLevel {
                    level: m.level,
                    params: PhysicalParams {
                        k_i: m.params.k_i[j],
                        k_x: m.params.k_x[j],
                        bending_hz: m.params.bending_hz,
                        bending_damping: m.params.bending_damping,
                        mode_shape_a: m.params.mode_shape_a,
                        mode_shape_b: m.params.mode_shape_b,
                    },
                    std: [
                        m.std[j],
                        m.std[4 + j],
                        m.std[8],
                        m.std[9],
                        m.std[10],
                        m.std[11],
                    ],
                })
                .collect();
            let s = extrapolate_to_zero_amplitude(&pts, 0.9).unwrap();
            let sarr = s.params.to_array();
            for (mk, sk) in [(j, 0), (4 + j, 1), (8, 2), (9, 3), (10, 4), (11, 5)] {
                let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs());
                assert!(
                    close(zarr[mk], sarr[sk]),
                    "{mk}: {} vs {}",
                    zarr[mk],
                    sarr[sk]
                );
                assert!(close(z.std[mk], s.std[sk]));
                assert!(close(z.intervals[mk].0, s.intervals[sk].0));
                assert!(close(z.intervals[mk].1, s.intervals[sk].1));
                assert!(close(z.slope[mk], s.slope[sk]));
                assert!(close(z.variance_scale[mk], s.variance_scale[sk]));
            }
        }
        // bad input: one level; a zero standard deviation; a negative k_x
        assert!(extrapolate_machine_to_zero_amplitude(&mach[..1], 0.95).is_err());
        let mut bad = mach.clone();
        bad[1].std[7] = 0.0;
        let e = extrapolate_machine_to_zero_amplitude(&bad, 0.95).unwrap_err();
        assert!(e.to_string().contains("k_x_yb"), "{e}");
        let mut bad = mach.clone();
        bad[0].params.k_x[1] = -1.0;
        let e = extrapolate_machine_to_zero_amplitude(&bad, 0.95).unwrap_err();
        assert!(e.to_string().contains("k_x_xb"), "{e}");
        assert!(extrapolate_machine_to_zero_amplitude(&mach, 1.5).is_err());
    }
}
