//! Physical parameters of one AMB axis from its measured plant FRF (gray box): the magnet's
//! force–current factor $k_i$ and negative stiffness $k_x$, the bending mode's frequency,
//! damping and mode shape at the bearings, with confidence intervals — given what the drawing
//! says (rotor mass and transverse inertia, bearing/sensor positions, amplifier and sensor
//! bandwidths and gains, the computation delay) and the controller of the other bearing's loop.
//!
//! # Model
//! The plant $P$ from the controller output $u_A$ (current command at bearing A) to the sensor
//! signal $y_A$, with loop B closed by its controller $C_B$ ($u_B = -C_B y_B$). Rotor: centre-of-mass
//! translation $z$, tilt $\theta$ and the modal coordinate $\eta$ of the free–free bending mode
//! (mass normalised), displacements $x_A = z - a\theta + \varphi_A\eta$,
//! $x_B = z + b\theta + \varphi_B\eta$, the bearing forces $F = k_i i + k_x x$ entering through the
//! transposed map:
//! $$ \operatorname{diag}(m, J, 1)\ddot q + \operatorname{diag}(0, 0, 2\zeta_b\omega_b)\dot q +
//!    \operatorname{diag}(0, 0, \omega_b^2) q = c_A F_A + c_B F_B ,$$
//! amplifiers $\dot i = \omega_a(g_a i_{\mathrm{ref}} - i)$, sensors
//! $\dot y_s = \omega_s(g_s x - y_s)$; the 10-state model is discretised with a zero-order hold
//! at the controller's sample time, each input passes $d$ samples of computation delay, and
//! loop B is closed with the given discrete controller. (This is the structure of the twin's
//! linearisation, `ambid-twin`'s model docs, written here from the physics, not from that code.)
//!
//! # Estimate
//! $\theta = (\ln k_i, \ln k_x, \ln f_b, \ln\zeta_b, \varphi_A\sqrt m, \varphi_B\sqrt m)$ minimises
//! $\sum_k |P(\theta, z_k) - G_k|^2 / \sigma_k^2$ over the FRF lines (inverse-variance weights;
//! the real and imaginary parts of each line's error have variance $\sigma_k^2/2$) by
//! Levenberg–Marquardt with a central-difference Jacobian. Starts, from the data:
//! * $k_x$ from the identified unstable pole $s_+$ through the rotor pinned at B,
//!   $k_x = s_+^2 (J + m b^2)/(a + b)^2$;
//! * $k_i$ from the static gain: with loop B's integral action the rotor pivots about B at low
//!   frequency, and $P(0) = -g_a g_s k_i / k_x$, so $k_i = |G(f_{\min})|\,k_x/(g_a g_s)$;
//! * $f_b$, $\zeta_b$ from the pole pairs of the identified black-box model above $s_+$ with
//!   damping below 0.5 and inside the FRF's lines (the three least damped; without any, 12
//!   frequencies over the band's upper part);
//! * the mode shape from a 3 × 6 grid ($\varphi\sqrt m \in \{0.7, 1.4, 2.8\}$ at A,
//!   $\pm$ the same at B); the start of least cost over the bending candidates and this grid is
//!   refined.
//!
//! The covariance is $\hat\sigma^2 (J^\top J)^{-1}$ of the weighted residuals with
//! $\hat\sigma^2 = \max(1, \chi^2/(2N - 6))$ (the FRF's variances, inflated when the fit is worse than
//! they allow); the intervals are $\exp(\hat\theta_j \pm 1.96\,\sigma_j)$ for the positive
//! parameters and $\hat\theta_j \pm 1.96\,\sigma_j$ for the mode shape. The mode shape's sign
//! is not identifiable (($\varphi_A, \varphi_B, \eta) \to (-\varphi_A, -\varphi_B, -\eta)$ leaves
//! $P$ unchanged); it is reported with $\varphi_A > 0$.
//!
//! # Identifiable without the drawing
//! From the plant alone: the unstable pole $s_+$, the plant's bending pole pair (frequency and
//! damping), and the static ratio $k_i/k_x = |P(0)|/(g_a g_s)$. Scaling $m$, $J$ and $k_i$,
//! $k_x$ by one factor leaves the rigid-body part unchanged, so $k_i$ and $k_x$ themselves need
//! the mass (and inertia) from the drawing; [`PhysicalFit::ratio`] gives the ratio with its
//! interval.
//!
//! # Zero amplitude
//! On a nonlinear magnet the FRF at a finite excitation is the best linear approximation, whose
//! $k_x$ lies above the small-signal one by an amount proportional to the level squared;
//! [`extrapolate_to_zero_amplitude`] combines estimates at several levels (module
//! `amplitude`).
//!
//! # The whole machine
//! [`fit_machine_physical`] estimates $k_i$, $k_x$ of each of the four axes' magnets (so per
//! bearing and direction), the bending mode and its shape from the 4×4 plant FRF with all
//! loops open, at standstill or at speed ([`graybox_machine_plant`]; module `machine`).
//!
//! # Operating points
//! [`fit_magnet_law`] fits $k_i = 4k i_0/g^2$, $k_x = 4k i_0^2/g^3$ to the estimates at
//! several bias currents and gap offsets (the operating-point study): the magnet constant $k$
//! and the effective air gap $g_0$ with intervals, a $\chi^2$ test of the law, and $k_i$,
//! $k_x$ at any operating point (module `magnet`).

mod amplitude;
mod machine;
mod magnet;
pub use amplitude::{extrapolate_to_zero_amplitude, AtLevel, ZeroAmplitude};
pub use machine::{
    extrapolate_machine_to_zero_amplitude, fit_machine_physical, graybox_machine_plant,
    MachineAtLevel, MachineParams, MachinePhysicalFit, MachineZeroAmplitude, Rotation,
    MACHINE_AXES, MACHINE_PARAMETER_NAMES,
};
pub use magnet::{fit_magnet_law, AtOperatingPoint, MagnetLawFit, Predicted};

use crate::error::{Error, Result};
use crate::estimate::pem::lm::{minimize, LeastSquaresProblem, LmOptions, StopReason};
use crate::lti::{Frd, StateSpace};
use crate::validate::machine::normal_quantile;
use faer::{c64, Mat};
use std::f64::consts::PI;

/// What the drawing and the data sheets give (as a TOML file for `ambid physical`: these keys,
/// `amplifier_gain` and `sensor_gain` default to 1, `delay_samples` to 1).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Drawing {
    /// Rotor mass $m$ \[kg\].
    pub mass_kg: f64,
    /// Transverse moment of inertia $J$ about the centre of mass \[kg·m²\].
    pub inertia_kgm2: f64,
    /// Distance $a$ from the centre of mass to bearing (and sensor) A \[m\].
    pub bearing_a_m: f64,
    /// Distance $b$ to bearing B, on the other side \[m\].
    pub bearing_b_m: f64,
    /// Current-amplifier bandwidth \[Hz\].
    pub amplifier_bandwidth_hz: f64,
    /// Displacement-sensor bandwidth \[Hz\].
    pub sensor_bandwidth_hz: f64,
    /// Amplifier gain $g_a$ (coil current per unit of command; 1 when the command is in A).
    #[serde(default = "one")]
    pub amplifier_gain: f64,
    /// Sensor gain $g_s$ (signal per metre; 1 when the record's y is in m).
    #[serde(default = "one")]
    pub sensor_gain: f64,
    /// Computation delay $d$ of each input \[samples\].
    #[serde(default = "one_sample")]
    pub delay_samples: usize,
}

/// The physical parameters.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PhysicalParams {
    /// Force–current factor $k_i$ \[N/A\].
    pub k_i: f64,
    /// Negative stiffness $k_x$ \[N/m\].
    pub k_x: f64,
    /// Free–free bending frequency $f_b$ \[Hz\].
    pub bending_hz: f64,
    /// Modal damping ratio $\zeta_b$.
    pub bending_damping: f64,
    /// Mass-normalised mode shape at bearing A, $\varphi_A$ \[kg^-½\].
    pub mode_shape_a: f64,
    /// The same at bearing B.
    pub mode_shape_b: f64,
}

impl PhysicalParams {
    /// The parameters as an array in the order of [`PARAMETER_NAMES`].
    pub fn to_array(&self) -> [f64; 6] {
        [
            self.k_i,
            self.k_x,
            self.bending_hz,
            self.bending_damping,
            self.mode_shape_a,
            self.mode_shape_b,
        ]
    }
}

/// The names of the parameters, in the order of [`PhysicalFit::intervals`].
pub const PARAMETER_NAMES: [&str; 6] = [
    "k_i",
    "k_x",
    "bending_hz",
    "bending_damping",
    "mode_shape_a",
    "mode_shape_b",
];

/// Starting hints from an identified black-box model (see the module docs).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Hints {
    /// The plant's unstable pole $s_+$ \[rad/s\].
    pub unstable_pole_rad_s: f64,
    /// Candidates for the plant's bending pole pair, frequency \[Hz\] and damping ratio, least
    /// damped first (those outside the FRF's lines are not used).
    pub bending: Vec<(f64, f64)>,
}

impl Hints {
    /// From an identified SISO discrete plant model: its real unstable pole (the largest) and
    /// its complex pole pairs above it with damping below 0.5, least damped first.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a continuous model or one without a real unstable pole.
    pub fn from_model(model: &StateSpace) -> Result<Self> {
        let ts = model
            .ts()
            .ok_or_else(|| Error::invalid("model", "must be discrete-time"))?;
        let s: Vec<c64> = model
            .poles()?
            .iter()
            .map(|z| c64::new(z.norm().ln(), z.arg()) / ts)
            .collect();
        let up = s
            .iter()
            .filter(|p| p.re > 0.0 && p.im.abs() < 1e-9 * p.re.max(1.0))
            .map(|p| p.re)
            .fold(f64::NAN, f64::max);
        if !up.is_finite() {
            return Err(Error::invalid(
                "model",
                "has no real unstable pole: the gray-box start needs the plant's unstable pole (fit the model with the loop's unstable pole count)",
            ));
        }
        let mut bending: Vec<(f64, f64)> = s
            .iter()
            .filter(|p| p.im > 3.0 * up && p.re < 0.0 && -p.re < 0.5 * p.norm())
            .map(|p| (p.norm() / (2.0 * PI), -p.re / p.norm()))
            .collect();
        bending.sort_by(|a, b| a.1.total_cmp(&b.1));
        Ok(Self {
            unstable_pole_rad_s: up,
            bending,
        })
    }
}

fn one() -> f64 {
    1.0
}

fn one_sample() -> usize {
    1
}

fn check_drawing(d: &Drawing) -> Result<()> {
    for (name, v) in [
        ("mass_kg", d.mass_kg),
        ("inertia_kgm2", d.inertia_kgm2),
        ("bearing_a_m", d.bearing_a_m),
        ("bearing_b_m", d.bearing_b_m),
        ("amplifier_bandwidth_hz", d.amplifier_bandwidth_hz),
        ("sensor_bandwidth_hz", d.sensor_bandwidth_hz),
        ("amplifier_gain", d.amplifier_gain),
        ("sensor_gain", d.sensor_gain),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(Error::invalid(
                name,
                format!("must be positive and finite, got {v}"),
            ));
        }
    }
    Ok(())
}

/// The gray-box plant (module docs) for the parameters `p`, closed at bearing B by
/// `controller` ($u_B = -C_B y_B$, SISO, discrete; its sample time is the model's).
///
/// # Errors
/// [`Error::InvalidArgument`] for a drawing value that is not positive and finite, parameters
/// that are not finite (or a non-positive $k_i$, $k_x$, $f_b$, $\zeta_b$), a controller that is
/// not SISO or not discrete; the errors of the discretisation.
///
/// # Example
/// ```
/// use ambid_core::estimate::graybox::{graybox_plant, Drawing, PhysicalParams};
/// use ambid_core::lti::StateSpace;
/// use faer::mat;
/// let d = Drawing { mass_kg: 5.0, inertia_kgm2: 0.17, bearing_a_m: 0.2, bearing_b_m: 0.2,
///     amplifier_bandwidth_hz: 2000.0, sensor_bandwidth_hz: 1e4, amplifier_gain: 1.0,
///     sensor_gain: 1.0, delay_samples: 1 };
/// let p = PhysicalParams { k_i: 58.0, k_x: 2.9e5, bending_hz: 730.0, bending_damping: 0.01,
///     mode_shape_a: 0.6, mode_shape_b: 0.6 };
/// let ts = 5e-5;
/// // a PD-like stabilising controller at B
/// let c = StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[-5e3]], mat![[3e4]], ts).unwrap();
/// let plant = graybox_plant(&d, &p, &c).unwrap();
/// // the static gain is -k_i/k_x (the rotor pivots about the held bearing B)
/// let g = plant.freq_response_siso(&[0.01]).unwrap()[0];
/// assert!(g.re < 0.0);
/// ```
pub fn graybox_plant(
    d: &Drawing,
    p: &PhysicalParams,
    controller: &StateSpace,
) -> Result<StateSpace> {
    check_drawing(d)?;
    for (name, v) in [
        ("k_i", p.k_i),
        ("k_x", p.k_x),
        ("bending_hz", p.bending_hz),
        ("bending_damping", p.bending_damping),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(Error::invalid(
                name,
                format!("must be positive and finite, got {v}"),
            ));
        }
    }
    if !(p.mode_shape_a.is_finite() && p.mode_shape_b.is_finite()) {
        return Err(Error::invalid("mode_shape", "must be finite"));
    }
    if controller.ninputs() != 1 || controller.noutputs() != 1 {
        return Err(Error::invalid("controller", "must be SISO"));
    }
    let ts = controller
        .ts()
        .ok_or_else(|| Error::invalid("controller", "must be discrete-time"))?;
    // the 10-state continuous model: q = (z, θ, η), q̇, i_A, i_B, y_sA, y_sB
    let ca = [1.0, -d.bearing_a_m, p.mode_shape_a];
    let cb = [1.0, d.bearing_b_m, p.mode_shape_b];
    let minv = [1.0 / d.mass_kg, 1.0 / d.inertia_kgm2, 1.0];
    let wa = 2.0 * PI * d.amplifier_bandwidth_hz;
    let ws = 2.0 * PI * d.sensor_bandwidth_hz;
    let wb = 2.0 * PI * p.bending_hz;
    let mut a = Mat::<f64>::zeros(10, 10);
    let mut b = Mat::<f64>::zeros(10, 2);
    for r in 0..3 {
        a[(r, r + 3)] = 1.0;
        for c in 0..3 {
            a[(3 + r, c)] = minv[r] * p.k_x * (ca[r] * ca[c] + cb[r] * cb[c]);
        }
        a[(3 + r, 6)] = minv[r] * ca[r] * p.k_i;
        a[(3 + r, 7)] = minv[r] * cb[r] * p.k_i;
        a[(8, r)] = ws * d.sensor_gain * ca[r];
        a[(9, r)] = ws * d.sensor_gain * cb[r];
    }
    a[(5, 2)] -= wb * wb;
    a[(5, 5)] -= 2.0 * p.bending_damping * wb;
    a[(6, 6)] = -wa;
    a[(7, 7)] = -wa;
    b[(6, 0)] = wa * d.amplifier_gain;
    b[(7, 1)] = wa * d.amplifier_gain;
    a[(8, 8)] = -ws;
    a[(9, 9)] = -ws;
    let mut c = Mat::<f64>::zeros(2, 10);
    c[(0, 8)] = 1.0;
    c[(1, 9)] = 1.0;
    let disc = StateSpace::continuous(a, b, c, Mat::zeros(2, 2))?.c2d_zoh(ts)?;
    let (ad, bd, cd) = (disc.a(), disc.b(), disc.c());
    // assembly: [ξ (10) | delay chain A (k) | delay chain B (k) | controller B (n_c)]
    let k = d.delay_samples;
    let nc = controller.order();
    let (ac, bc, cc, dc) = (
        controller.a(),
        controller.b(),
        controller.c(),
        controller.d()[(0, 0)],
    );
    let n = 10 + 2 * k + nc;
    let (ia, ib, ic) = (10, 10 + k, 10 + 2 * k);
    let mut aa = Mat::<f64>::zeros(n, n);
    let mut ba = Mat::<f64>::zeros(n, 1);
    let mut c_out = Mat::<f64>::zeros(1, n);
    for r in 0..10 {
        for s in 0..10 {
            aa[(r, s)] = ad[(r, s)];
        }
        c_out[(0, r)] = cd[(0, r)];
    }
    // v_B = C_C x_C − D_C y_sB with y_sB = cd[1, :] ξ: the row it adds, into `target`
    let add_vb = |aa: &mut Mat<f64>, target: usize, scale: f64| {
        for s in 0..10 {
            aa[(target, s)] -= scale * dc * cd[(1, s)];
        }
        for s in 0..nc {
            aa[(target, ic + s)] += scale * cc[(0, s)];
        }
    };
    if k == 0 {
        for r in 0..10 {
            ba[(r, 0)] = bd[(r, 0)];
            add_vb(&mut aa, r, bd[(r, 1)]);
        }
    } else {
        for r in 0..10 {
            aa[(r, ia + k - 1)] += bd[(r, 0)];
            aa[(r, ib + k - 1)] += bd[(r, 1)];
        }
        ba[(ia, 0)] = 1.0;
        add_vb(&mut aa, ib, 1.0);
        for j in 1..k {
            aa[(ia + j, ia + j - 1)] = 1.0;
            aa[(ib + j, ib + j - 1)] = 1.0;
        }
    }
    // x_C⁺ = A_C x_C − B_C y_sB
    for r in 0..nc {
        for s in 0..nc {
            aa[(ic + r, ic + s)] = ac[(r, s)];
        }
        for s in 0..10 {
            aa[(ic + r, s)] -= bc[(r, 0)] * cd[(1, s)];
        }
    }
    StateSpace::discrete(aa, ba, c_out, Mat::zeros(1, 1), ts)
}

/// Options of [`fit_physical`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicalOptions {
    /// Two-sided confidence level of the intervals.
    pub confidence: f64,
    /// Levenberg–Marquardt iteration limit.
    pub max_iterations: usize,
}

impl Default for PhysicalOptions {
    /// 95 % intervals, 200 iterations.
    fn default() -> Self {
        Self {
            confidence: 0.95,
            max_iterations: 200,
        }
    }
}

/// What [`fit_physical`] returns.
#[derive(Debug, Clone)]
pub struct PhysicalFit {
    /// The estimate ($\varphi_A > 0$).
    pub params: PhysicalParams,
    /// Standard deviations, in the order of [`PARAMETER_NAMES`] (of the parameters themselves,
    /// to first order).
    pub std: [f64; 6],
    /// Confidence intervals `(low, high)`, in the order of [`PARAMETER_NAMES`].
    pub intervals: [(f64, f64); 6],
    /// Covariance of $\theta$ (module docs), 6 × 6 row-major.
    pub covariance: Vec<f64>,
    /// $\chi^2$ of the fit and its degrees of freedom $2N - 6$.
    pub chi2: f64,
    /// Degrees of freedom.
    pub dof: usize,
    /// The factor the covariance was inflated by, $\max(1, \chi^2/\text{dof})$.
    pub variance_scale: f64,
    /// The gray-box plant at the estimate.
    pub model: StateSpace,
    /// Its unstable pole \[rad/s\].
    pub unstable_pole_rad_s: f64,
    /// Iterations and why the fit stopped.
    pub iterations: usize,
    /// Why the fit stopped.
    pub stop: StopReason,
    /// The confidence level.
    pub confidence: f64,
}

impl PhysicalFit {
    /// $k_i/k_x$ \[m/A\] with its interval (identifiable without the drawing, module docs).
    pub fn ratio(&self) -> (f64, (f64, f64)) {
        let c = &self.covariance;
        let var = (c[0] + c[7] - 2.0 * c[1]).max(0.0);
        let z = normal_quantile(0.5 + 0.5 * self.confidence);
        let r = self.params.k_i / self.params.k_x;
        let h = z * var.sqrt();
        (r, (r * (-h).exp(), r * h.exp()))
    }
}

struct Problem<'a> {
    drawing: &'a Drawing,
    controller: &'a StateSpace,
    f: &'a [f64],
    g: &'a [c64],
    w: Vec<f64>,
    sqrt_m: f64,
}

impl Problem<'_> {
    fn params(&self, x: &[f64]) -> PhysicalParams {
        PhysicalParams {
            k_i: x[0].exp(),
            k_x: x[1].exp(),
            bending_hz: x[2].exp(),
            bending_damping: x[3].exp(),
            mode_shape_a: x[4] / self.sqrt_m,
            mode_shape_b: x[5] / self.sqrt_m,
        }
    }

    fn response(&self, x: &[f64]) -> Option<Vec<c64>> {
        let m = graybox_plant(self.drawing, &self.params(x), self.controller).ok()?;
        let r = m.freq_response_siso(self.f).ok()?;
        r.iter()
            .all(|v| v.re.is_finite() && v.im.is_finite())
            .then_some(r)
    }
}

impl LeastSquaresProblem for Problem<'_> {
    fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
        let r = self.response(x)?;
        let mut out = Vec::with_capacity(2 * r.len());
        for ((p, g), w) in r.iter().zip(self.g).zip(&self.w) {
            let e = (p - g) * *w;
            out.push(e.re);
            out.push(e.im);
        }
        Some(out)
    }

    fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
        central_jacobian(self, x)
    }
}

/// The Jacobian of `p`'s residuals at `x` by central differences (step
/// $10^{-6}\max(|x_c|, 1)$); `None` where a residual is not finite.
fn central_jacobian<P: LeastSquaresProblem>(p: &mut P, x: &[f64]) -> Option<Mat<f64>> {
    let mut j: Option<Mat<f64>> = None;
    for c in 0..x.len() {
        let h = 1e-6 * x[c].abs().max(1.0);
        let mut xp = x.to_vec();
        let mut xm = x.to_vec();
        xp[c] += h;
        xm[c] -= h;
        let (rp, rm) = (p.residuals(&xp)?, p.residuals(&xm)?);
        let jm = j.get_or_insert_with(|| Mat::zeros(rp.len(), x.len()));
        for r in 0..rp.len() {
            jm[(r, c)] = (rp[r] - rm[r]) / (2.0 * h);
        }
    }
    j
}

/// The sum of squared residuals of `p` at `x` (infinite where the model is not finite).
fn cost<P: LeastSquaresProblem>(p: &mut P, x: &[f64]) -> f64 {
    p.residuals(x)
        .map_or(f64::INFINITY, |r| r.iter().map(|v| v * v).sum())
}

/// The mode-shape grid of the starts: $\varphi_A\sqrt m$ (positive: the sign is not
/// identifiable) and $\varphi_B\sqrt m$ of either sign.
const SHAPE_GRID: ([f64; 3], [f64; 6]) = ([0.7, 1.4, 2.8], [0.7, 1.4, 2.8, -0.7, -1.4, -2.8]);

/// The least-cost start of `p` over the bending candidates `cands` `(f_b, ζ_b)` and the
/// mode-shape grid (`start(f_b, ζ_b, φ_A√m, φ_B√m)` builds the parameter vector), refined by
/// Levenberg–Marquardt; the mode shape (at `shape`, `shape + 1`) reported with $\varphi_A > 0$.
fn start_and_refine<P: LeastSquaresProblem>(
    p: &mut P,
    cands: &[(f64, f64)],
    start: impl Fn(f64, f64, f64, f64) -> Vec<f64>,
    shape: usize,
    max_iterations: usize,
) -> Result<(Vec<f64>, crate::estimate::pem::lm::LmReport)> {
    let mut best: Option<(f64, Vec<f64>)> = None;
    for &(fb0, zb0) in cands {
        for pa in SHAPE_GRID.0 {
            for pb in SHAPE_GRID.1 {
                let x = start(fb0, zb0, pa, pb);
                let c = cost(p, &x);
                if c.is_finite() && best.as_ref().is_none_or(|b| c < b.0) {
                    best = Some((c, x));
                }
            }
        }
    }
    let (_, x0) = best.ok_or_else(|| {
        Error::numerical(
            "the gray-box start",
            "no starting point gives a finite gray-box model (check the drawing)",
        )
    })?;
    let lm = LmOptions::default().with_max_iterations(max_iterations)?;
    let (mut x, report) = minimize(p, &x0, &lm)?;
    // the sign of the mode shape is not identifiable: report φ_A > 0
    if x[shape] < 0.0 {
        x[shape] = -x[shape];
        x[shape + 1] = -x[shape + 1];
    }
    Ok((x, report))
}

/// The covariance of a gray-box estimate and what follows from it (module docs).
struct Spread {
    chi2: f64,
    dof: usize,
    scale: f64,
    /// $\hat\sigma^2 (J^\top J)^{-1}$, row-major.
    cov: Vec<f64>,
    /// Standard deviations of the parameters themselves.
    std: Vec<f64>,
    /// Confidence intervals.
    intervals: Vec<(f64, f64)>,
}

/// The spread of the estimate `x` of `p`: $\chi^2$, $\hat\sigma^2 = \max(1, \chi^2/\text{dof})$,
/// the covariance $\hat\sigma^2(J^\top J)^{-1}$; the first `n_log` parameters are logarithms
/// (standard deviation $e^{x}\sigma$, interval $e^{x \pm z\sigma}$), the others are the mode
/// shape times `shape_scale` ($\sqrt m$).
fn spread<P: LeastSquaresProblem>(
    p: &mut P,
    x: &[f64],
    n_log: usize,
    shape_scale: f64,
    confidence: f64,
) -> Result<Spread> {
    let n = x.len();
    let jac = central_jacobian(p, x).ok_or_else(|| {
        Error::numerical(
            "the gray-box fit",
            "the Jacobian at the estimate is not finite",
        )
    })?;
    let r = p.residuals(x).ok_or_else(|| {
        Error::numerical(
            "the gray-box fit",
            "the residuals at the estimate are not finite",
        )
    })?;
    let chi2: f64 = r.iter().map(|v| v * v).sum();
    let dof = r.len().saturating_sub(n).max(1);
    let scale = (chi2 / dof as f64).max(1.0);
    let info = jac.transpose() * &jac;
    let inv = invert_spd(&info).ok_or_else(|| {
        Error::numerical(
            "the gray-box covariance",
            "the information matrix is singular: a parameter is not determined by these lines (is the bending mode inside the band?)",
        )
    })?;
    let mut cov = vec![0.0; n * n];
    for r in 0..n {
        for c in 0..n {
            cov[r * n + c] = scale * inv[(r, c)];
        }
    }
    let z = normal_quantile(0.5 + 0.5 * confidence);
    let mut std = vec![0.0; n];
    let mut intervals = vec![(0.0, 0.0); n];
    for k in 0..n {
        let sd = cov[k * (n + 1)].max(0.0).sqrt();
        if k < n_log {
            std[k] = x[k].exp() * sd;
            intervals[k] = ((x[k] - z * sd).exp(), (x[k] + z * sd).exp());
        } else {
            std[k] = sd / shape_scale;
            intervals[k] = ((x[k] - z * sd) / shape_scale, (x[k] + z * sd) / shape_scale);
        }
    }
    Ok(Spread {
        chi2,
        dof,
        scale,
        cov,
        std,
        intervals,
    })
}

/// Estimates the physical parameters from the plant FRF `frd` (SISO, discrete, with variances;
/// the lines to use, e.g. the fit band) with the drawing, loop B's `controller` and the starting
/// `hints` (module docs).
///
/// # Errors
/// [`Error::InvalidArgument`] for an FRF that is not SISO, has no variances or fewer than 7
/// lines, a sample time other than the controller's, a bad drawing or hints, a confidence level
/// outside (0, 1); [`Error::Numerical`] when no start gives a finite model or the information
/// matrix is singular (a parameter the data do not determine, e.g. a bending mode outside the
/// band).
pub fn fit_physical(
    frd: &Frd,
    drawing: &Drawing,
    controller: &StateSpace,
    hints: &Hints,
    opts: &PhysicalOptions,
) -> Result<PhysicalFit> {
    frd.require_siso("the physical parameters")?;
    check_drawing(drawing)?;
    if !(opts.confidence > 0.0 && opts.confidence < 1.0) {
        return Err(Error::invalid(
            "confidence",
            format!("must lie in (0, 1), got {}", opts.confidence),
        ));
    }
    let var = frd
        .variance()
        .ok_or_else(|| Error::invalid("frd", "needs the FRF's variances (inverse-variance fit)"))?;
    if frd.len() < 7 {
        return Err(Error::invalid(
            "frd",
            format!(
                "has {} lines; the six parameters need at least 7",
                frd.len()
            ),
        ));
    }
    if let Some(v) = var.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
        return Err(Error::invalid(
            "frd",
            format!("every variance must be positive and finite, got {v}"),
        ));
    }
    match (frd.ts(), controller.ts()) {
        (Some(a), Some(b)) if (a - b).abs() <= 1e-9 * a => {}
        _ => {
            return Err(Error::invalid(
                "controller",
                "must be discrete with the FRF's sample time",
            ))
        }
    }
    if !(hints.unstable_pole_rad_s.is_finite() && hints.unstable_pole_rad_s > 0.0) {
        return Err(Error::invalid(
            "hints",
            "the unstable pole must be positive and finite",
        ));
    }
    let (f, g) = (frd.f_hz(), frd.values());
    let mut prob = Problem {
        drawing,
        controller,
        f,
        g,
        w: var.iter().map(|v| (2.0 / v).sqrt()).collect(),
        sqrt_m: drawing.mass_kg.sqrt(),
    };
    // starts (module docs)
    let (m, j, a, b) = (
        drawing.mass_kg,
        drawing.inertia_kgm2,
        drawing.bearing_a_m,
        drawing.bearing_b_m,
    );
    let sp = hints.unstable_pole_rad_s;
    let kx0 = sp * sp * (j + m * b * b) / ((a + b) * (a + b));
    let ki0 = g[0].norm() * kx0 / (drawing.amplifier_gain * drawing.sensor_gain);
    if !(ki0.is_finite() && ki0 > 0.0) {
        return Err(Error::invalid(
            "hints",
            "the starting k_i is not positive (check the FRF's lowest line)",
        ));
    }
    // bending candidates inside the lines (at most 3, least damped first); without any, a grid
    // over the band's upper half
    let (f_lo, f_hi) = (f[0], f[f.len() - 1]);
    let mut cands: Vec<(f64, f64)> = hints
        .bending
        .iter()
        .copied()
        .filter(|(fb, z)| (f_lo..=f_hi).contains(fb) && *z > 0.0)
        .take(3)
        .collect();
    if cands.is_empty() {
        cands = (0..12)
            .map(|k| (f_hi * 0.3 * (1.0f64 / 0.3).powf(k as f64 / 11.0), 0.02))
            .collect();
    }
    let (x, report) = start_and_refine(
        &mut prob,
        &cands,
        |fb, zb, pa, pb| vec![ki0.ln(), kx0.ln(), fb.ln(), zb.ln(), pa, pb],
        4,
        opts.max_iterations,
    )?;
    let sqrt_m = prob.sqrt_m;
    let sp = spread(&mut prob, &x, 4, sqrt_m, opts.confidence)?;
    let params = prob.params(&x);
    let model = graybox_plant(drawing, &params, controller)?;
    let ts = model.ts().unwrap_or(1.0);
    let unstable_pole_rad_s = model
        .poles()?
        .iter()
        .filter(|p| p.norm() > 1.0)
        .map(|p| p.norm().ln() / ts)
        .fold(f64::NAN, f64::max);
    Ok(PhysicalFit {
        params,
        std: std::array::from_fn(|k| sp.std[k]),
        intervals: std::array::from_fn(|k| sp.intervals[k]),
        covariance: sp.cov,
        chi2: sp.chi2,
        dof: sp.dof,
        variance_scale: sp.scale,
        model,
        unstable_pole_rad_s,
        iterations: report.iterations,
        stop: report.reason,
        confidence: opts.confidence,
    })
}

/// Inverse of a small symmetric positive-definite matrix by Cholesky; `None` when it is not
/// (numerically) positive definite.
fn invert_spd(a: &Mat<f64>) -> Option<Mat<f64>> {
    let n = a.nrows();
    // scale to unit diagonal for conditioning
    let d: Vec<f64> = (0..n).map(|i| a[(i, i)].max(0.0).sqrt()).collect();
    if d.iter().any(|v| *v == 0.0 || !v.is_finite()) {
        return None;
    }
    let s = Mat::from_fn(n, n, |i, j| a[(i, j)] / (d[i] * d[j]));
    let llt = s.llt(faer::Side::Lower).ok()?;
    let inv = faer::linalg::solvers::DenseSolveCore::inverse(&llt);
    let out = Mat::from_fn(n, n, |i, j| inv[(i, j)] / (d[i] * d[j]));
    // a near-singular matrix gives a huge, useless inverse: refuse it (condition ~1e14)
    let cond_guard = (0..n).map(|i| inv[(i, i)]).fold(0.0f64, f64::max);
    (cond_guard.is_finite() && cond_guard < 1e14).then_some(out)
}
