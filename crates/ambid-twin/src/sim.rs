//! Closed-loop time-domain simulation of the twin.
//!
//! # One control period
//! At $t_k = k T_s$ the controller of each bearing reads the sampled sensor output
//! $y\[k\] = y_s(t_k) + v\[k\]$ (white Gaussian noise $v$, then optional ADC quantisation), computes
//! $c\[k\] = C(q)\ (w\[k\] - y\[k\])$ (Tustin PID, clamp $\pm i_\mathrm{sat}$, anti-windup) and, at
//! bearing A, the recorded output $u\[k\] = \operatorname{clamp}(c\[k\] + r\[k\], \pm i_\mathrm{sat})$.
//! Because of the one-sample computation delay, $u\[k\]$ is the amplifier's current reference
//! (zero-order hold) during $[t_{k+1}, t_{k+2})$. The recorded $i\[k\]$ is the actual coil control
//! current at $t_k$.
//!
//! # Modes
//! * [`Mode::Linear`]: linearised force law, linear amplifier and sensor; the continuous part
//!   advances exactly, $\xi_{k+1} = A_d \xi_k + B_d\  i_{\mathrm{ref}}$ (ZOH), so with noise off and
//!   no clamp active the record obeys the linear truth to rounding error.
//! * [`Mode::Nonlinear`]: the exact force law with the actual coil currents $i_0 \pm i$, amplifier
//!   output limit and slew limit; the continuous part advances with the configured
//!   [`Integrator`]: classical RK4 at `simulation.substeps` (≥ 10) steps per control period (the
//!   default and the reference), or exponential (Lawson) RK4 at `simulation.exp_substeps` (≥ 1)
//!   steps, which propagates the linearised model exactly with precomputed matrix exponentials
//!   and applies RK4 only to the nonlinear residual (see *Exponential RK4* below).
//!
//! Accuracy of `exp_rk4` against RK4 with 40 substeps (noise off, largest error over the record
//! relative to each signal's RMS, y/u/i of both bearings; `tests/exp_rk4.rs`): PRBS at 2 % of
//! $i_\mathrm{sat}$ 1.2e-7 (RK4-10: 1.7e-7); PRBS at 16 % (slew limit briefly active) 3.4e-3
//! with one step, 1.4e-3 with two (RK4-10: 1.7e-4); a slew-limited 90 % sine at 1 kHz 8e-2 / 3e-2
//! (RK4-10: 1.5e-3), with the same limit fractions. The kinks of the slew limit inside a step
//! cost the exponential scheme its order; use RK4 where limits dominate.
//!
//! The digital controller, its clamp and the DAC clamp are the same in both modes (software).
//!
//! # Exponential RK4 (`exp_rk4`)
//! ## Splitting
//! Write the exact right-hand side as $\dot\xi = f(\xi, v) = A_c\xi + B_c v + B_n\, n(P\xi, v)$,
//! with the linear model $(A_c, B_c)$ of [`crate::model`] (linearised force $k_i i + k_x x$,
//! amplifier lag, sensor low-pass, rotor) and the nonlinear residual
//! $$ n = \begin{pmatrix} F(i_A, x_A) - k_i i_A - k_x x_A \\ F(i_B, x_B) - k_i i_B - k_x x_B \\
//!   \dot i_A^{\lim} - \omega_a (i_{\mathrm{ref},A} - i_A) \\
//!   \dot i_B^{\lim} - \omega_a (i_{\mathrm{ref},B} - i_B) \end{pmatrix}, $$
//! where $\dot i^{\lim}$ is the amplifier rate after the slew and output limits. $n$ depends on
//! the state only through $p = P\xi = (x_A, x_B, i_A, i_B)$ ($P \in \mathbb R^{4\times 10}$) and
//! enters through $B_n \in \mathbb R^{10\times 4}$: the force columns
//! $(0, 0, 0, 1/m, -a/J, \varphi_A, 0, 0, 0, 0)$, $(0, 0, 0, 1/m, b/J, \varphi_B, 0, 0, 0, 0)$ and
//! the unit vectors of $i_A$, $i_B$.
//!
//! ## Step
//! With $E_\tau = e^{A_c\tau}$, $G_\tau = \int_0^\tau e^{A_c s} ds\, B_c$ and the exact linear
//! (ZOH) flow $\Phi_\tau\xi = E_\tau\xi + G_\tau v$, one Lawson RK4 step of length $h$ is
//! $$ \begin{aligned}
//! n_1 &= n(P\xi), & n_2 &= n\big(P\Phi_{h/2}\xi + \tfrac h2 P E_{h/2} B_n n_1\big),\\
//! n_3 &= n\big(P\Phi_{h/2}\xi + \tfrac h2 P B_n n_2\big), &
//! n_4 &= n\big(P\Phi_h\xi + h P E_{h/2} B_n n_3\big),\\
//! \xi^+ &= \Phi_h\xi + \tfrac h6\big(E_h B_n n_1 + 2 E_{h/2} B_n (n_2 + n_3) + B_n n_4\big),
//! \end{aligned} $$
//! i.e. classical RK4 applied to $\zeta(t) = e^{-\mathcal A t}(\xi(t), v)$ for the system augmented
//! by the held input, $\dot v = 0$, $\mathcal A = \begin{pmatrix} A_c & B_c \\ 0 & 0 \end{pmatrix}$
//! (integrating factor); $E_\tau$, $G_\tau$ are the blocks of $e^{\mathcal A\tau}$, computed once
//! per twin with [`ambid_core::linalg::expm`]. It is exact for $n \equiv 0$ and of
//! order 4 in $h$ for a smooth residual. Only $E_h$ (10×10), $G_h$ (10×2), $P E_{h/2}$ (4×10),
//! $P G_{h/2}$ (4×2), $E_h B_n$, $E_{h/2} B_n$ (10×4) and $P E_{h/2} B_n$ (4×4) are needed, so a
//! step costs one 10×10 and one 4×10 matrix–vector product, four residual evaluations on
//! 4-vectors and two 10×4 products. After the step the currents are clamped to the amplifier
//! output limit, as with RK4.
//!
//! # Amplifier limits (nonlinear mode)
//! The amplifier drives the two coils of a pair with $i_1 = i_0 + i$ and $i_2 = i_0 - i$. A coil
//! obeys $L_c \dot i_j + R_c i_j = V_j$ with $|V_j| \le V_\mathrm{bus}$. Raising $i$ means charging
//! coil 1 (and discharging coil 2, which the bus does faster), lowering $i$ means charging coil 2:
//! $$ -\frac{V_\mathrm{bus} - R_c (i_0 - i)}{L_c} \ \le\  \dot i \ \le\
//!     \frac{V_\mathrm{bus} - R_c (i_0 + i)}{L_c}, $$
//! applied to the first-order lag $\dot i = \omega_a (i_\mathrm{ref} - i)$. The output is limited
//! to $|i| \le \min(i_\mathrm{sat}, i_0)$: the unipolar coil currents never go negative.
//!
//! # Touchdown
//! If $|x_A|$ or $|x_B|$ reaches the air gap $g_0$ (checked at every integrator step in nonlinear mode,
//! at every sample in linear mode) the simulation stops with [`TwinError::Touchdown`].
//!
//! # Pre-roll
//! `settle_samples` control periods run before recording starts, with $r$ and $w$ taken
//! cyclically so that the pre-roll ends exactly where sample 0 begins: for a periodic excitation
//! whose period divides `r.len()` this puts the loop into periodic steady state.

use crate::config::{Integrator, Mode};
use crate::error::{Result, TwinError};
use crate::model::{force_law, Physics, PidState, NX};
use crate::twin::Twin;
use ambid_core::linalg::expm;
use ambid_core::lti::StateSpace;
use faer::Mat;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

/// Options of one simulation run.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOptions {
    /// Linear or nonlinear physics. Default: linear.
    pub mode: Mode,
    /// Seed of the sensor noise (`ChaCha8Rng::seed_from_u64`). Default 0.
    pub seed: u64,
    /// Sensor noise on (both sensors, RMS `sensor.noise_rms_m`). Default: on.
    pub noise: bool,
    /// Position reference $w$ at bearing A \[m\], one per sample of `r`; `None` means zero.
    pub w: Option<Vec<f64>>,
    /// Also record $u$, $i$, $y$ of bearing B.
    pub record_b: bool,
    /// Control periods simulated before recording (cyclic $r$, $w$). Default 0.
    pub settle_samples: usize,
}

impl Default for SimOptions {
    fn default() -> Self {
        Self {
            mode: Mode::Linear,
            seed: 0,
            noise: true,
            w: None,
            record_b: false,
            settle_samples: 0,
        }
    }
}

/// Recorded channels of bearing B.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Channels {
    /// Controller output (DAC value) \[A\].
    pub u: Vec<f64>,
    /// Actual coil control current at the sample instants \[A\].
    pub i: Vec<f64>,
    /// Sampled displacement (with noise and quantisation) \[m\].
    pub y: Vec<f64>,
}

/// Run metadata: what was simulated and how often a limit was active.
///
/// Fractions are over the recorded samples; a sample counts if the limit was active at either
/// bearing at any time in its control period.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimMeta {
    /// Simulation mode.
    pub mode: Mode,
    /// Noise seed.
    pub seed: u64,
    /// Whether noise was on.
    pub noise: bool,
    /// RMS of the sensor noise actually added \[m\] (0 with noise off).
    pub noise_rms_m: f64,
    /// Whether the ADC quantisation was applied.
    pub quantized: bool,
    /// ADC step in metres (if quantised).
    pub adc_lsb_m: Option<f64>,
    /// Recorded samples.
    pub samples: usize,
    /// Pre-roll samples.
    pub settle_samples: usize,
    /// Sampling frequency \[Hz\].
    pub fs_hz: f64,
    /// Integrator of the nonlinear mode (`None` in linear mode).
    pub integrator: Option<Integrator>,
    /// Integrator steps per period (nonlinear mode: `substeps` for RK4, `exp_substeps` for
    /// exponential RK4), 0 for the exact linear update.
    pub substeps: usize,
    /// Bias current $i_0$ \[A\].
    pub bias_current_a: f64,
    /// Air gap $g_0$ \[m\].
    pub air_gap_m: f64,
    /// $k_i$ at the operating point \[N/A\].
    pub k_i: f64,
    /// $k_x$ at the operating point \[N/m\].
    pub k_x: f64,
    /// Fraction of samples with any limit active (clamp, amplifier output limit or slew limit).
    pub saturated_fraction: f64,
    /// Fraction of samples with the controller clamp or the DAC clamp active.
    pub clamp_fraction: f64,
    /// Fraction of samples with the amplifier output limit active (nonlinear mode).
    pub amp_limit_fraction: f64,
    /// Fraction of samples with the slew-rate limit active (nonlinear mode).
    pub slew_limited_fraction: f64,
    /// Largest true $|x_A|$ at the recorded sample instants \[m\].
    pub max_abs_displacement_a_m: f64,
    /// Largest true $|x_B|$ at the recorded sample instants \[m\].
    pub max_abs_displacement_b_m: f64,
}

/// A simulation record of bearing A (and B on request). All vectors have one value per sample.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimRecord {
    /// Sample time \[s\].
    pub ts: f64,
    /// Time $t_k = k T_s$ \[s\].
    pub t: Vec<f64>,
    /// Position reference \[m\].
    pub w: Vec<f64>,
    /// Excitation added to the controller output \[A\].
    pub r: Vec<f64>,
    /// Recorded controller output including $r$ (after the DAC clamp) \[A\].
    pub u: Vec<f64>,
    /// Actual coil control current at $t_k$ \[A\].
    pub i: Vec<f64>,
    /// Sampled displacement with noise and quantisation \[m\].
    pub y: Vec<f64>,
    /// Bearing B, if `record_b`.
    pub b: Option<Channels>,
    /// Metadata.
    pub meta: SimMeta,
}

const F_CLAMP: u8 = 1;
const F_AMP: u8 = 2;
const F_SLEW: u8 = 4;

/// Constants of the nonlinear right-hand side, precomputed once per run.
#[derive(Clone, Copy)]
struct Nl {
    inv_m: f64,
    inv_j: f64,
    a: f64,
    b: f64,
    phi_a: f64,
    phi_b: f64,
    wb2: f64,
    cb: f64,
    k: f64,
    ki: f64,
    kx: f64,
    i0: f64,
    g0: f64,
    wa: f64,
    ws: f64,
    v_l: f64,
    r_l: f64,
    imax: f64,
}

impl Nl {
    #[inline(always)]
    fn force(&self, i: f64, x: f64) -> f64 {
        force_law(self.k, self.i0, self.g0, i, x)
    }

    #[inline(always)]
    fn amp_rate(&self, iref: f64, i: f64, flags: &mut u8) -> f64 {
        let mut rate = self.wa * (iref - i);
        let up = self.v_l - self.r_l * (self.i0 + i);
        let dn = self.r_l * (self.i0 - i) - self.v_l;
        if rate > up {
            rate = up;
            *flags |= F_SLEW;
        } else if rate < dn {
            rate = dn;
            *flags |= F_SLEW;
        }
        if (i >= self.imax && rate > 0.0) || (i <= -self.imax && rate < 0.0) {
            rate = 0.0;
            *flags |= F_AMP;
        }
        rate
    }

    #[inline(always)]
    fn deriv(&self, x: &[f64; NX], ira: f64, irb: f64, flags: &mut u8) -> [f64; NX] {
        let xa = x[0] - self.a * x[1] + self.phi_a * x[2];
        let xb = x[0] + self.b * x[1] + self.phi_b * x[2];
        let fa = self.force(x[6], xa);
        let fb = self.force(x[7], xb);
        [
            x[3],
            x[4],
            x[5],
            (fa + fb) * self.inv_m,
            (self.b * fb - self.a * fa) * self.inv_j,
            self.phi_a * fa + self.phi_b * fb - self.wb2 * x[2] - self.cb * x[5],
            self.amp_rate(ira, x[6], flags),
            self.amp_rate(irb, x[7], flags),
            self.ws * (xa - x[8]),
            self.ws * (xb - x[9]),
        ]
    }

    /// One classical RK4 step of length `h` with the references held.
    #[inline(always)]
    fn rk4(&self, x: &mut [f64; NX], ira: f64, irb: f64, h: f64, flags: &mut u8) {
        let hh = 0.5 * h;
        let k1 = self.deriv(x, ira, irb, flags);
        let t: [f64; NX] = std::array::from_fn(|j| x[j] + hh * k1[j]);
        let k2 = self.deriv(&t, ira, irb, flags);
        let t: [f64; NX] = std::array::from_fn(|j| x[j] + hh * k2[j]);
        let k3 = self.deriv(&t, ira, irb, flags);
        let t: [f64; NX] = std::array::from_fn(|j| x[j] + h * k3[j]);
        let k4 = self.deriv(&t, ira, irb, flags);
        let h6 = h / 6.0;
        for j in 0..NX {
            x[j] += h6 * ((k1[j] + k4[j]) + 2.0 * (k2[j] + k3[j]));
        }
        x[6] = x[6].clamp(-self.imax, self.imax);
        x[7] = x[7].clamp(-self.imax, self.imax);
    }

    /// Displacements $(x_A, x_B)$ at the two bearings.
    #[inline(always)]
    fn bearings(&self, x: &[f64; NX]) -> (f64, f64) {
        (
            x[0] - self.a * x[1] + self.phi_a * x[2],
            x[0] + self.b * x[1] + self.phi_b * x[2],
        )
    }

    /// Advances one control period with `nsub` RK4 substeps; returns the limit flags, or the
    /// substep and displacements at which |x| reached the gap (or became non-finite).
    #[inline(never)]
    fn period(
        &self,
        x: &mut [f64; NX],
        ira: f64,
        irb: f64,
        h: f64,
        nsub: usize,
    ) -> std::result::Result<u8, (usize, f64, f64)> {
        let mut flags = 0u8;
        for s in 0..nsub {
            self.rk4(x, ira, irb, h, &mut flags);
            let (xa, xb) = self.bearings(x);
            if !(xa.abs() < self.g0 && xb.abs() < self.g0) {
                return Err((s, xa, xb));
            }
        }
        Ok(flags)
    }

    /// The nonlinear residual $n = (\Delta F_A, \Delta F_B, \Delta r_A, \Delta r_B)$ at the
    /// projected state $p = P\xi = (x_A, x_B, i_A, i_B)$ (see the module docs).
    #[inline(always)]
    fn residual(&self, p: &[f64; 4], ira: f64, irb: f64, flags: &mut u8) -> [f64; 4] {
        let [xa, xb, ia, ib] = *p;
        [
            self.force(ia, xa) - (self.ki * ia + self.kx * xa),
            self.force(ib, xb) - (self.ki * ib + self.kx * xb),
            self.amp_rate(ira, ia, flags) - self.wa * (ira - ia),
            self.amp_rate(irb, ib, flags) - self.wa * (irb - ib),
        ]
    }

    /// One Lawson (integrating-factor) RK4 step of length `t.h` with the references held.
    ///
    /// The matrix products run column by column (`acc += column · scalar`), which vectorises
    /// without horizontal sums.
    #[inline(always)]
    fn exp_rk4(&self, t: &ExpTables, x: &mut [f64; NX], ira: f64, irb: f64, flags: &mut u8) {
        let h = t.h;
        let hh = 0.5 * h;
        let v: [f64; NX + 2] = std::array::from_fn(|j| {
            if j < NX {
                x[j]
            } else if j == NX {
                ira
            } else {
                irb
            }
        });
        // n_1 at the current state
        let (xa, xb) = self.bearings(x);
        let p1 = [xa, xb, x[6], x[7]];
        let n1 = self.residual(&p1, ira, irb, flags);
        // exact linear flows: Φ_h ξ (full) and P Φ_{h/2} ξ (projected)
        let mut w = [0.0f64; NX];
        let mut a = [0.0f64; 4];
        for ((cw, ca), &vj) in t.lin_h.iter().zip(&t.plin_half).zip(&v) {
            axpy(&mut w, cw, vj);
            axpy(&mut a, ca, vj);
        }
        let mut p2 = a;
        for (c, &nj) in t.pebn_half.iter().zip(&n1) {
            axpy(&mut p2, c, hh * nj);
        }
        let n2 = self.residual(&p2, ira, irb, flags);
        // P B_n = [0 0 0 0; 0 0 0 0; 0 0 1 0; 0 0 0 1]: forces do not move x_A, x_B directly
        let p3 = [a[0], a[1], a[2] + hh * n2[2], a[3] + hh * n2[3]];
        let n3 = self.residual(&p3, ira, irb, flags);
        let mut p4 = [
            t.pw[0][0] * w[0] + t.pw[0][1] * w[1] + t.pw[0][2] * w[2],
            t.pw[1][0] * w[0] + t.pw[1][1] * w[1] + t.pw[1][2] * w[2],
            w[6],
            w[7],
        ];
        for (c, &nj) in t.pebn_half.iter().zip(&n3) {
            axpy(&mut p4, c, h * nj);
        }
        let n4 = self.residual(&p4, ira, irb, flags);
        let h6 = h / 6.0;
        for j in 0..4 {
            axpy(&mut w, &t.kn[j], h6 * n1[j]);
            axpy(&mut w, &t.kn[4 + j], 2.0 * h6 * (n2[j] + n3[j]));
        }
        // + h/6 B_n n_4 (sparse)
        let (fa, fb) = (h6 * n4[0], h6 * n4[1]);
        w[3] += (fa + fb) * self.inv_m;
        w[4] += (self.b * fb - self.a * fa) * self.inv_j;
        w[5] += self.phi_a * fa + self.phi_b * fb;
        w[6] = (w[6] + h6 * n4[2]).clamp(-self.imax, self.imax);
        w[7] = (w[7] + h6 * n4[3]).clamp(-self.imax, self.imax);
        *x = w;
    }

    /// Advances one control period with `t`'s exponential RK4 steps; same contract as
    /// [`Nl::period`].
    #[inline(never)]
    fn exp_period(
        &self,
        t: &ExpTables,
        x: &mut [f64; NX],
        ira: f64,
        irb: f64,
    ) -> std::result::Result<u8, (usize, f64, f64)> {
        let mut flags = 0u8;
        for s in 0..t.steps {
            self.exp_rk4(t, x, ira, irb, &mut flags);
            let (xa, xb) = self.bearings(x);
            if !(xa.abs() < self.g0 && xb.abs() < self.g0) {
                return Err((s, xa, xb));
            }
        }
        Ok(flags)
    }
}

/// `acc += col · s`.
#[inline(always)]
fn axpy<const N: usize>(acc: &mut [f64; N], col: &[f64; N], s: f64) {
    for (a, c) in acc.iter_mut().zip(col) {
        *a += c * s;
    }
}

/// Precomputed tables of the exponential (Lawson) RK4 integrator, built once per twin (see the
/// module docs, *Exponential RK4*).
#[derive(Debug, Clone)]
pub(crate) struct ExpTables {
    /// Step length $h = T_s / \text{steps}$.
    h: f64,
    /// Steps per control period.
    steps: usize,
    /// Columns of $[E_h \ G_h]$.
    lin_h: [[f64; NX]; NX + 2],
    /// Columns of $[P E_{h/2} \ P G_{h/2}]$.
    plin_half: [[f64; 4]; NX + 2],
    /// Columns of $[E_h B_n \ E_{h/2} B_n]$.
    kn: [[f64; NX]; 8],
    /// Columns of $P E_{h/2} B_n$.
    pebn_half: [[f64; 4]; 4],
    /// Rows $c_A$, $c_B$ of $P$ on $(z, \theta, \eta)$.
    pw: [[f64; 3]; 2],
}

/// $(E_\tau, G_\tau)$ of the exact ZOH flow.
type Flow = ([[f64; NX]; NX], [[f64; 2]; NX]);

impl ExpTables {
    /// Builds the tables for `steps` steps per control period from the continuous model.
    pub(crate) fn new(ph: &Physics, cont: &StateSpace, steps: usize) -> Result<ExpTables> {
        let h = ph.ts / steps as f64;
        let (ac, bc) = (cont.a(), cont.b());
        let flow = |tau: f64| -> Result<Flow> {
            let aug = Mat::from_fn(NX + 2, NX + 2, |i, j| {
                if i >= NX {
                    0.0
                } else if j < NX {
                    ac[(i, j)] * tau
                } else {
                    bc[(i, j - NX)] * tau
                }
            });
            let ex = expm(aug.as_ref())?;
            let e = std::array::from_fn(|i| std::array::from_fn(|j| ex[(i, j)]));
            let g = std::array::from_fn(|i| [ex[(i, NX)], ex[(i, NX + 1)]]);
            Ok((e, g))
        };
        let (e_h, g_h) = flow(h)?;
        let (e_half, g_half) = flow(0.5 * h)?;
        let (ca, cb) = (ph.c_a(), ph.c_b());
        let mut p = [[0.0; NX]; 4];
        p[0][..3].copy_from_slice(&ca);
        p[1][..3].copy_from_slice(&cb);
        p[2][6] = 1.0;
        p[3][7] = 1.0;
        let minv = [1.0 / ph.m, 1.0 / ph.j, 1.0];
        let mut bn = [[0.0; 4]; NX];
        for r in 0..3 {
            bn[3 + r][0] = minv[r] * ca[r];
            bn[3 + r][1] = minv[r] * cb[r];
        }
        bn[6][2] = 1.0;
        bn[7][3] = 1.0;
        let mul_bn = |e: &[[f64; NX]; NX]| -> [[f64; 4]; NX] {
            std::array::from_fn(|i| {
                std::array::from_fn(|j| (0..NX).map(|k| e[i][k] * bn[k][j]).sum())
            })
        };
        let ebn_h = mul_bn(&e_h);
        let ebn_half = mul_bn(&e_half);
        let pe_half: [[f64; NX]; 4] = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..NX).map(|k| p[i][k] * e_half[k][j]).sum())
        });
        let pg_half: [[f64; 2]; 4] = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..NX).map(|k| p[i][k] * g_half[k][j]).sum())
        });
        let pebn_half: [[f64; 4]; 4] = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..NX).map(|k| p[i][k] * ebn_half[k][j]).sum())
        });
        // column-major copies for the hot loop
        let lin_h = std::array::from_fn(|j| {
            std::array::from_fn(|i| if j < NX { e_h[i][j] } else { g_h[i][j - NX] })
        });
        let plin_half = std::array::from_fn(|j| {
            std::array::from_fn(|i| {
                if j < NX {
                    pe_half[i][j]
                } else {
                    pg_half[i][j - NX]
                }
            })
        });
        let kn = std::array::from_fn(|j| {
            std::array::from_fn(|i| {
                if j < 4 {
                    ebn_h[i][j]
                } else {
                    ebn_half[i][j - 4]
                }
            })
        });
        let pebn_half = std::array::from_fn(|j| std::array::from_fn(|i| pebn_half[i][j]));
        Ok(ExpTables {
            h,
            steps,
            lin_h,
            plin_half,
            kn,
            pebn_half,
            pw: [ca, cb],
        })
    }
}

impl Twin {
    /// Simulates the closed loop with excitation `r` \[A\] added to controller A's output.
    ///
    /// Returns one record sample per element of `r`. Errors: non-finite `r` or `w` (with the
    /// index), `w` of the wrong length, empty `r`, touchdown ([`TwinError::Touchdown`]) or a
    /// diverging state. Library code never panics on user input.
    pub fn simulate(&self, r: &[f64], opts: &SimOptions) -> Result<SimRecord> {
        if r.is_empty() {
            return Err(TwinError::InvalidArgument {
                name: "r",
                reason: "the excitation is empty; pass one value per sample to record".into(),
            });
        }
        if let Some(index) = r.iter().position(|v| !v.is_finite()) {
            return Err(TwinError::NonFinite { what: "r", index });
        }
        if let Some(w) = &opts.w {
            if w.len() != r.len() {
                return Err(TwinError::LengthMismatch {
                    what: "w",
                    expected: r.len(),
                    got: w.len(),
                });
            }
            if let Some(index) = w.iter().position(|v| !v.is_finite()) {
                return Err(TwinError::NonFinite { what: "w", index });
            }
        }
        match opts.mode {
            Mode::Linear => self.run::<false>(r, opts),
            Mode::Nonlinear => self.run::<true>(r, opts),
        }
    }

    fn run<const NL: bool>(&self, r: &[f64], opts: &SimOptions) -> Result<SimRecord> {
        let ph = &self.ph;
        let pid = self.pid;
        let sens = &self.cfg.sensor;
        let n = r.len();
        let ns = opts.settle_samples;
        let ts = ph.ts;
        let exp = self.cfg.simulation.integrator == Integrator::ExpRk4;
        let nsub = self.cfg.simulation.steps_per_period();
        let h = ts / nsub as f64;
        let nl = Nl {
            inv_m: 1.0 / ph.m,
            inv_j: 1.0 / ph.j,
            a: ph.a,
            b: ph.b,
            phi_a: ph.phi_a,
            phi_b: ph.phi_b,
            wb2: ph.wb * ph.wb,
            cb: 2.0 * ph.zb * ph.wb,
            k: ph.k,
            ki: ph.ki,
            kx: ph.kx,
            i0: ph.i0,
            g0: ph.g0,
            wa: ph.wa,
            ws: ph.ws,
            v_l: ph.vbus / ph.lcoil,
            r_l: ph.rcoil / ph.lcoil,
            imax: ph.i_amp_max,
        };
        let ad = &self.ad;
        let bd = &self.bd;
        let i_sat = ph.i_sat;
        let g0 = ph.g0;
        let sigma = if opts.noise { sens.noise_rms_m } else { 0.0 };
        let noisy = opts.noise && sigma > 0.0;
        let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
        let quant = sens.quantize;
        let lsb_v = 2.0 * sens.adc_range_v / (2f64).powi(sens.adc_bits as i32);
        let gain = sens.gain_v_per_m;
        let vmax = sens.adc_range_v;
        let adc = |y: f64| -> f64 {
            let v = (y * gain).clamp(-vmax, vmax);
            (v / lsb_v).round() * lsb_v / gain
        };
        let w = opts.w.as_deref();

        let mut rec_t = Vec::with_capacity(n);
        let mut rec_w = Vec::with_capacity(n);
        let mut rec_u = Vec::with_capacity(n);
        let mut rec_i = Vec::with_capacity(n);
        let mut rec_y = Vec::with_capacity(n);
        let cap_b = if opts.record_b { n } else { 0 };
        let mut b_u = Vec::with_capacity(cap_b);
        let mut b_i = Vec::with_capacity(cap_b);
        let mut b_y = Vec::with_capacity(cap_b);

        let mut x = [0.0f64; NX];
        let (mut da, mut db) = (0.0f64, 0.0f64);
        let mut sa = PidState::default();
        let mut sb = PidState::default();
        let (mut n_any, mut n_clamp, mut n_amp, mut n_slew) = (0usize, 0usize, 0usize, 0usize);
        let (mut max_a, mut max_b) = (0.0f64, 0.0f64);
        let (ca, cb) = (ph.c_a(), ph.c_b());
        let disp = |x: &[f64; NX]| -> (f64, f64) {
            (
                ca[0] * x[0] + ca[1] * x[1] + ca[2] * x[2],
                cb[0] * x[0] + cb[1] * x[1] + cb[2] * x[2],
            )
        };
        let touchdown = |xa: f64, xb: f64, k: i64, t: f64| -> Result<()> {
            if !(xa.is_finite() && xb.is_finite()) {
                return Err(TwinError::Diverged { sample: k });
            }
            if xa.abs() >= g0 || xb.abs() >= g0 {
                let (bearing, d) = if xa.abs() >= g0 { ('A', xa) } else { ('B', xb) };
                return Err(TwinError::Touchdown {
                    bearing,
                    time_s: t,
                    sample: k,
                    displacement_m: d,
                    gap_m: g0,
                });
            }
            Ok(())
        };

        // first index of the cyclic pre-roll
        let mut idx = (n - ns % n) % n;
        for kk in 0..(ns + n) {
            let k = kk as i64 - ns as i64;
            let recording = k >= 0;
            let rk = r[idx];
            let wk = match w {
                Some(w) => w[idx],
                None => 0.0,
            };
            idx += 1;
            if idx == n {
                idx = 0;
            }
            // sample the sensors
            let (mut ya, mut yb) = (x[8], x[9]);
            if noisy {
                let na: f64 = StandardNormal.sample(&mut rng);
                let nb: f64 = StandardNormal.sample(&mut rng);
                ya += sigma * na;
                yb += sigma * nb;
            }
            if quant {
                ya = adc(ya);
                yb = adc(yb);
            }
            // controllers
            let (c_a, cl_a) = pid.step(&mut sa, wk - ya);
            let u_raw = c_a + rk;
            let ua = u_raw.clamp(-i_sat, i_sat);
            let (ub, cl_b) = pid.step(&mut sb, -yb);
            let mut flags = if cl_a || cl_b || ua != u_raw {
                F_CLAMP
            } else {
                0
            };
            if recording {
                rec_t.push(k as f64 * ts);
                rec_w.push(wk);
                rec_u.push(ua);
                rec_i.push(x[6]);
                rec_y.push(ya);
                if opts.record_b {
                    b_u.push(ub);
                    b_i.push(x[7]);
                    b_y.push(yb);
                }
                let (xa, xb) = disp(&x);
                max_a = max_a.max(xa.abs());
                max_b = max_b.max(xb.abs());
            }
            // advance the continuous part over [t_k, t_{k+1}) with the delayed references
            if NL {
                let res = if exp {
                    nl.exp_period(&self.exp, &mut x, da, db)
                } else {
                    nl.period(&mut x, da, db, h, nsub)
                };
                match res {
                    Ok(f) => flags |= f,
                    Err((s, xa, xb)) => {
                        touchdown(xa, xb, k, k as f64 * ts + (s + 1) as f64 * h)?;
                    }
                }
            } else {
                let mut xn = [0.0f64; NX];
                for (i, row) in ad.iter().enumerate() {
                    let mut acc = bd[i][0] * da + bd[i][1] * db;
                    for j in 0..NX {
                        acc += row[j] * x[j];
                    }
                    xn[i] = acc;
                }
                x = xn;
                let (xa, xb) = disp(&x);
                if !(xa.abs() < g0 && xb.abs() < g0) {
                    touchdown(xa, xb, k, (k + 1) as f64 * ts)?;
                }
            }
            da = ua;
            db = ub;
            if recording && flags != 0 {
                n_any += 1;
                n_clamp += (flags & F_CLAMP != 0) as usize;
                n_amp += (flags & F_AMP != 0) as usize;
                n_slew += (flags & F_SLEW != 0) as usize;
            }
        }
        let frac = |c: usize| c as f64 / n as f64;
        let lp = ph.linear_params();
        let meta = SimMeta {
            mode: opts.mode,
            seed: opts.seed,
            noise: opts.noise,
            noise_rms_m: sigma,
            quantized: quant,
            adc_lsb_m: quant.then(|| sens.lsb_m()),
            samples: n,
            settle_samples: ns,
            fs_hz: self.fs(),
            integrator: NL.then_some(self.cfg.simulation.integrator),
            substeps: if NL { nsub } else { 0 },
            bias_current_a: lp.bias_current_a,
            air_gap_m: lp.air_gap_m,
            k_i: lp.k_i,
            k_x: lp.k_x,
            saturated_fraction: frac(n_any),
            clamp_fraction: frac(n_clamp),
            amp_limit_fraction: frac(n_amp),
            slew_limited_fraction: frac(n_slew),
            max_abs_displacement_a_m: max_a,
            max_abs_displacement_b_m: max_b,
        };
        Ok(SimRecord {
            ts,
            t: rec_t,
            w: rec_w,
            r: r.to_vec(),
            u: rec_u,
            i: rec_i,
            y: rec_y,
            b: opts.record_b.then_some(Channels {
                u: b_u,
                i: b_i,
                y: b_y,
            }),
            meta,
        })
    }
}
