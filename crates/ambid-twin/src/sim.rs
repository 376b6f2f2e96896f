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
//! # Batches
//! [`Twin::simulate_batch`] runs independent nonlinear RK4 simulations (any twins, the same
//! substeps and number of periods) in lock-step, up to [`MAX_LANES`] at once: the continuous
//! part of every lane advances with the same IEEE operations in the same order as a lone run's
//! scalar RK4 (the branches of the amplifier limits become bitwise selects; with AVX2, detected
//! at run time, four lanes share one 256-bit register; no FMA), so every record is bit for bit
//! the lone run's (`tests/batch.rs`), at about 0.4–0.45× the CPU time per run.
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

    /// Advances one control period with `t`'s exponential RK4 steps; returns the limit flags,
    /// or the step and displacements at which |x| reached the gap (or became non-finite).
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

/// The constants of [`Nl`] for `L` lock-step simulations (one value per lane).
///
/// The classical RK4 of the nonlinear mode runs on `L` independent simulations at once: every
/// lane performs exactly the floating-point operations of a lone run, in the same order (the
/// branches of the limits become per-lane selects), so a lane's record is bit-for-bit the one
/// the run gives alone; the lanes only share the instruction stream (SIMD and instruction-level
/// parallelism).
#[derive(Clone, Copy)]
struct NlLanes<const L: usize> {
    inv_m: [f64; L],
    inv_j: [f64; L],
    a: [f64; L],
    b: [f64; L],
    phi_a: [f64; L],
    phi_b: [f64; L],
    wb2: [f64; L],
    cb: [f64; L],
    k: [f64; L],
    i0: [f64; L],
    g0: [f64; L],
    wa: [f64; L],
    ws: [f64; L],
    v_l: [f64; L],
    r_l: [f64; L],
    imax: [f64; L],
    /// RK4 step $h = T_s / \text{substeps}$.
    h: [f64; L],
}

/// One value per lane.
#[inline(always)]
fn lanes<const L: usize>(f: impl FnMut(usize) -> f64) -> [f64; L] {
    std::array::from_fn(f)
}

/// Per-lane masks (all ones or zero) of the limits met so far.
struct Limits<const L: usize> {
    slew: [u64; L],
    amp: [u64; L],
}

/// All ones for `true`, zero for `false`.
#[inline(always)]
fn mask(c: bool) -> u64 {
    0u64.wrapping_sub(u64::from(c))
}

/// `a` where `m` is all ones, `b` where it is zero (bit for bit).
#[inline(always)]
fn select(m: u64, a: f64, b: f64) -> f64 {
    f64::from_bits((a.to_bits() & m) | (b.to_bits() & !m))
}

/// `L` lanes of the state vector, element-major (`x[j][lane]`).
type LaneState<const L: usize> = [[f64; L]; NX];

impl<const L: usize> NlLanes<L> {
    fn new(nl: &[Nl; L], h: [f64; L]) -> Self {
        macro_rules! gather {
            ($f:ident) => {
                std::array::from_fn(|l| nl[l].$f)
            };
        }
        Self {
            inv_m: gather!(inv_m),
            inv_j: gather!(inv_j),
            a: gather!(a),
            b: gather!(b),
            phi_a: gather!(phi_a),
            phi_b: gather!(phi_b),
            wb2: gather!(wb2),
            cb: gather!(cb),
            k: gather!(k),
            i0: gather!(i0),
            g0: gather!(g0),
            wa: gather!(wa),
            ws: gather!(ws),
            v_l: gather!(v_l),
            r_l: gather!(r_l),
            imax: gather!(imax),
            h,
        }
    }

    /// [`Nl::amp_rate`] on every lane, branch-free: the same values, the limits in `lim`.
    #[inline(always)]
    fn amp_rate(&self, iref: &[f64; L], i: &[f64; L], lim: &mut Limits<L>) -> [f64; L] {
        let rate: [f64; L] = std::array::from_fn(|l| self.wa[l] * (iref[l] - i[l]));
        let up: [f64; L] = std::array::from_fn(|l| self.v_l[l] - self.r_l[l] * (self.i0[l] + i[l]));
        let dn: [f64; L] = std::array::from_fn(|l| self.r_l[l] * (self.i0[l] - i[l]) - self.v_l[l]);
        let hi: [u64; L] = std::array::from_fn(|l| mask(rate[l] > up[l]));
        let lo: [u64; L] = std::array::from_fn(|l| mask(rate[l] < dn[l]));
        // if rate > up { up } else if rate < dn { dn } else { rate }
        let r: [f64; L] =
            std::array::from_fn(|l| select(hi[l], up[l], select(lo[l], dn[l], rate[l])));
        let stop: [u64; L] = std::array::from_fn(|l| {
            (mask(i[l] >= self.imax[l]) & mask(r[l] > 0.0))
                | (mask(i[l] <= -self.imax[l]) & mask(r[l] < 0.0))
        });
        for l in 0..L {
            lim.slew[l] |= hi[l] | lo[l];
            lim.amp[l] |= stop[l];
        }
        std::array::from_fn(|l| select(stop[l], 0.0, r[l]))
    }

    /// The right-hand side at `x` with the references held, on every lane.
    #[inline(always)]
    fn deriv(
        &self,
        x: &LaneState<L>,
        ira: &[f64; L],
        irb: &[f64; L],
        lim: &mut Limits<L>,
    ) -> LaneState<L> {
        let xa: [f64; L] = lanes(|l| x[0][l] - self.a[l] * x[1][l] + self.phi_a[l] * x[2][l]);
        let xb: [f64; L] = lanes(|l| x[0][l] + self.b[l] * x[1][l] + self.phi_b[l] * x[2][l]);
        let fa: [f64; L] = lanes(|l| force_law(self.k[l], self.i0[l], self.g0[l], x[6][l], xa[l]));
        let fb: [f64; L] = lanes(|l| force_law(self.k[l], self.i0[l], self.g0[l], x[7][l], xb[l]));
        [
            x[3],
            x[4],
            x[5],
            lanes(|l| (fa[l] + fb[l]) * self.inv_m[l]),
            lanes(|l| (self.b[l] * fb[l] - self.a[l] * fa[l]) * self.inv_j[l]),
            lanes(|l| {
                self.phi_a[l] * fa[l] + self.phi_b[l] * fb[l]
                    - self.wb2[l] * x[2][l]
                    - self.cb[l] * x[5][l]
            }),
            self.amp_rate(ira, &x[6], lim),
            self.amp_rate(irb, &x[7], lim),
            lanes(|l| self.ws[l] * (xa[l] - x[8][l])),
            lanes(|l| self.ws[l] * (xb[l] - x[9][l])),
        ]
    }

    /// `x + c·k` with the per-lane factor `c`.
    #[inline(always)]
    fn ahead(x: &LaneState<L>, c: &[f64; L], k: &LaneState<L>) -> LaneState<L> {
        std::array::from_fn(|j| std::array::from_fn(|l| x[j][l] + c[l] * k[j][l]))
    }

    /// One classical RK4 step of length `h` with the references held.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // lane loops index several per-lane arrays
    fn rk4(&self, x: &mut LaneState<L>, ira: &[f64; L], irb: &[f64; L], lim: &mut Limits<L>) {
        let h = self.h;
        let hh: [f64; L] = std::array::from_fn(|l| 0.5 * h[l]);
        let k1 = self.deriv(x, ira, irb, lim);
        let k2 = self.deriv(&Self::ahead(x, &hh, &k1), ira, irb, lim);
        let k3 = self.deriv(&Self::ahead(x, &hh, &k2), ira, irb, lim);
        let k4 = self.deriv(&Self::ahead(x, &h, &k3), ira, irb, lim);
        let h6: [f64; L] = std::array::from_fn(|l| h[l] / 6.0);
        for j in 0..NX {
            for l in 0..L {
                x[j][l] += h6[l] * ((k1[j][l] + k4[j][l]) + 2.0 * (k2[j][l] + k3[j][l]));
            }
        }
        for l in 0..L {
            x[6][l] = x[6][l].clamp(-self.imax[l], self.imax[l]);
            x[7][l] = x[7][l].clamp(-self.imax[l], self.imax[l]);
        }
    }

    /// [`NlLanes::period`] for the baseline target.
    #[inline(never)]
    fn period_base(
        &self,
        x: &mut LaneState<L>,
        ira: &[f64; L],
        irb: &[f64; L],
        nsub: usize,
        flags: &mut [u8; L],
        fail: &mut [Option<(usize, f64, f64)>; L],
    ) {
        self.period(x, ira, irb, nsub, flags, fail)
    }

    /// [`NlLanes::period`] compiled for AVX2: four lanes fill one 256-bit register. The same
    /// IEEE operations in the same order as [`NlLanes::period_base`] (no FMA contraction:
    /// `fma` is not enabled and Rust never contracts), so the same bits.
    ///
    /// # Safety
    /// Only on a CPU with AVX2 (`is_x86_feature_detected!("avx2")`).
    #[cfg(target_arch = "x86_64")]
    #[inline(never)]
    #[target_feature(enable = "avx2")]
    unsafe fn period_avx2(
        &self,
        x: &mut LaneState<L>,
        ira: &[f64; L],
        irb: &[f64; L],
        nsub: usize,
        flags: &mut [u8; L],
        fail: &mut [Option<(usize, f64, f64)>; L],
    ) {
        self.period(x, ira, irb, nsub, flags, fail)
    }

    /// Whether [`NlLanes::period_avx2`] may run here (and pays: four lanes or more).
    fn use_avx2() -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            L >= 4 && std::arch::is_x86_feature_detected!("avx2")
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    }

    /// [`NlLanes::period`] with the widest instructions the CPU has (`avx2` from
    /// [`NlLanes::use_avx2`]).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn period_dispatch(
        &self,
        avx2: bool,
        x: &mut LaneState<L>,
        ira: &[f64; L],
        irb: &[f64; L],
        nsub: usize,
        flags: &mut [u8; L],
        fail: &mut [Option<(usize, f64, f64)>; L],
    ) {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: `avx2` comes from `use_avx2`, which detected AVX2 on this CPU.
            unsafe { self.period_avx2(x, ira, irb, nsub, flags, fail) };
            return;
        }
        let _ = avx2;
        self.period_base(x, ira, irb, nsub, flags, fail)
    }

    /// Advances one control period with `nsub` RK4 substeps. A lane whose $|x_A|$ or $|x_B|$
    /// reaches the gap (or becomes non-finite) gets the substep and displacements in `fail`
    /// (its later values are not used); `flags` collects the limits of every lane.
    #[allow(clippy::needless_range_loop)] // lane loops index several per-lane arrays
    #[inline(always)]
    fn period(
        &self,
        x: &mut LaneState<L>,
        ira: &[f64; L],
        irb: &[f64; L],
        nsub: usize,
        flags: &mut [u8; L],
        fail: &mut [Option<(usize, f64, f64)>; L],
    ) {
        let mut lim = Limits {
            slew: [0; L],
            amp: [0; L],
        };
        for s in 0..nsub {
            self.rk4(x, ira, irb, &mut lim);
            let mut bad = false;
            for l in 0..L {
                let xa = x[0][l] - self.a[l] * x[1][l] + self.phi_a[l] * x[2][l];
                let xb = x[0][l] + self.b[l] * x[1][l] + self.phi_b[l] * x[2][l];
                bad |= !(xa.abs() < self.g0[l] && xb.abs() < self.g0[l]);
            }
            if bad {
                for (l, f) in fail.iter_mut().enumerate() {
                    let xa = x[0][l] - self.a[l] * x[1][l] + self.phi_a[l] * x[2][l];
                    let xb = x[0][l] + self.b[l] * x[1][l] + self.phi_b[l] * x[2][l];
                    if f.is_none() && !(xa.abs() < self.g0[l] && xb.abs() < self.g0[l]) {
                        *f = Some((s, xa, xb));
                    }
                }
            }
        }
        for (l, f) in flags.iter_mut().enumerate() {
            *f |= (u8::from(lim.slew[l] != 0) * F_SLEW) | (u8::from(lim.amp[l] != 0) * F_AMP);
        }
    }
}

/// One simulation of a batch: the twin, the excitation and the options, already checked.
#[derive(Clone, Copy)]
struct Job<'a> {
    twin: &'a Twin,
    r: &'a [f64],
    opts: &'a SimOptions,
}

impl Job<'_> {
    /// Whether the continuous part advances by the lane-parallel RK4.
    fn rk4(&self) -> bool {
        self.opts.mode == Mode::Nonlinear && self.twin.cfg.simulation.integrator == Integrator::Rk4
    }

    /// Runs that may share lanes: RK4 with the same substeps and the same number of periods.
    fn lane_key(&self) -> Option<(usize, usize)> {
        self.rk4().then(|| {
            (
                self.twin.cfg.simulation.substeps,
                self.opts.settle_samples.saturating_add(self.r.len()),
            )
        })
    }
}

/// The widest batch [`Twin::simulate_batch`] runs in lock-step: four lanes fill one AVX2
/// register. On the 2-core AMD EPYC of docs/benchmarks.md four nonlinear runs in lock-step take
/// about 1.6–1.8 lone runs' CPU time with AVX2 (3.0 on the baseline SSE2 path); wider batches were
/// not faster per run.
pub const MAX_LANES: usize = 4;

/// The constants of the nonlinear right-hand side of a twin.
fn nl_of(ph: &Physics) -> Nl {
    Nl {
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
    }
}

/// What one lane keeps between samples: everything but the continuous state.
struct Lane<'a> {
    job: Job<'a>,
    nl: Nl,
    pid: crate::model::Pid,
    sigma: f64,
    noisy: bool,
    rng: ChaCha8Rng,
    quant: bool,
    lsb_v: f64,
    gain: f64,
    vmax: f64,
    i_sat: f64,
    g0: f64,
    ts: f64,
    /// Steps per period and their length.
    nsub: usize,
    h: f64,
    ca: [f64; 3],
    cb: [f64; 3],
    rec_t: Vec<f64>,
    rec_w: Vec<f64>,
    rec_u: Vec<f64>,
    rec_i: Vec<f64>,
    rec_y: Vec<f64>,
    b_u: Vec<f64>,
    b_i: Vec<f64>,
    b_y: Vec<f64>,
    sa: PidState,
    sb: PidState,
    /// Delayed references (the amplifiers' inputs over the current period).
    da: f64,
    db: f64,
    /// This sample's controller outputs (the next period's references).
    ua: f64,
    ub: f64,
    flags: u8,
    n_any: usize,
    n_clamp: usize,
    n_amp: usize,
    n_slew: usize,
    max_a: f64,
    max_b: f64,
    /// Next index into the (cyclic) excitation.
    idx: usize,
    /// The error that ended this lane.
    err: Option<TwinError>,
}

impl<'a> Lane<'a> {
    fn new(job: Job<'a>) -> Self {
        let twin = job.twin;
        let ph = &twin.ph;
        let sens = &twin.cfg.sensor;
        let opts = job.opts;
        let n = job.r.len();
        let sigma = if opts.noise { sens.noise_rms_m } else { 0.0 };
        let nsub = twin.cfg.simulation.steps_per_period();
        let cap_b = if opts.record_b { n } else { 0 };
        Self {
            job,
            nl: nl_of(ph),
            pid: twin.pid,
            sigma,
            noisy: opts.noise && sigma > 0.0,
            rng: ChaCha8Rng::seed_from_u64(opts.seed),
            quant: sens.quantize,
            lsb_v: 2.0 * sens.adc_range_v / (2f64).powi(sens.adc_bits as i32),
            gain: sens.gain_v_per_m,
            vmax: sens.adc_range_v,
            i_sat: ph.i_sat,
            g0: ph.g0,
            ts: ph.ts,
            nsub,
            h: ph.ts / nsub as f64,
            ca: ph.c_a(),
            cb: ph.c_b(),
            rec_t: Vec::with_capacity(n),
            rec_w: Vec::with_capacity(n),
            rec_u: Vec::with_capacity(n),
            rec_i: Vec::with_capacity(n),
            rec_y: Vec::with_capacity(n),
            b_u: Vec::with_capacity(cap_b),
            b_i: Vec::with_capacity(cap_b),
            b_y: Vec::with_capacity(cap_b),
            sa: PidState::default(),
            sb: PidState::default(),
            da: 0.0,
            db: 0.0,
            ua: 0.0,
            ub: 0.0,
            flags: 0,
            n_any: 0,
            n_clamp: 0,
            n_amp: 0,
            n_slew: 0,
            max_a: 0.0,
            max_b: 0.0,
            // first index of the cyclic pre-roll
            idx: (n - opts.settle_samples % n) % n,
            err: None,
        }
    }

    /// Displacements at the bearings.
    #[inline(always)]
    fn disp(&self, x: &[f64; NX]) -> (f64, f64) {
        let (ca, cb) = (&self.ca, &self.cb);
        (
            ca[0] * x[0] + ca[1] * x[1] + ca[2] * x[2],
            cb[0] * x[0] + cb[1] * x[1] + cb[2] * x[2],
        )
    }

    /// The error of $|x|$ at the gap (or non-finite) at time `t` during sample `k`.
    fn touchdown(&self, xa: f64, xb: f64, k: i64, t: f64) -> Option<TwinError> {
        let g0 = self.g0;
        if !(xa.is_finite() && xb.is_finite()) {
            return Some(TwinError::Diverged { sample: k });
        }
        if xa.abs() >= g0 || xb.abs() >= g0 {
            let (bearing, d) = if xa.abs() >= g0 { ('A', xa) } else { ('B', xb) };
            return Some(TwinError::Touchdown {
                bearing,
                time_s: t,
                sample: k,
                displacement_m: d,
                gap_m: g0,
            });
        }
        None
    }

    /// Sample `k` (negative in the pre-roll) at continuous state `x`: sensors, controllers and
    /// the record; leaves the controller outputs in `ua`, `ub` and the clamp in `flags`.
    #[inline(always)]
    fn sample(&mut self, k: i64, x: &[f64; NX]) {
        let n = self.job.r.len();
        let rk = self.job.r[self.idx];
        let wk = match &self.job.opts.w {
            Some(w) => w[self.idx],
            None => 0.0,
        };
        self.idx += 1;
        if self.idx == n {
            self.idx = 0;
        }
        // sample the sensors
        let (mut ya, mut yb) = (x[8], x[9]);
        if self.noisy {
            let na: f64 = StandardNormal.sample(&mut self.rng);
            let nb: f64 = StandardNormal.sample(&mut self.rng);
            ya += self.sigma * na;
            yb += self.sigma * nb;
        }
        if self.quant {
            let (gain, vmax, lsb_v) = (self.gain, self.vmax, self.lsb_v);
            let adc = |y: f64| -> f64 {
                let v = (y * gain).clamp(-vmax, vmax);
                (v / lsb_v).round() * lsb_v / gain
            };
            ya = adc(ya);
            yb = adc(yb);
        }
        // controllers
        let (c_a, cl_a) = self.pid.step(&mut self.sa, wk - ya);
        let u_raw = c_a + rk;
        let ua = u_raw.clamp(-self.i_sat, self.i_sat);
        let (ub, cl_b) = self.pid.step(&mut self.sb, -yb);
        self.flags = if cl_a || cl_b || ua != u_raw {
            F_CLAMP
        } else {
            0
        };
        self.ua = ua;
        self.ub = ub;
        if k >= 0 {
            self.rec_t.push(k as f64 * self.ts);
            self.rec_w.push(wk);
            self.rec_u.push(ua);
            self.rec_i.push(x[6]);
            self.rec_y.push(ya);
            if self.job.opts.record_b {
                self.b_u.push(ub);
                self.b_i.push(x[7]);
                self.b_y.push(yb);
            }
            let (xa, xb) = self.disp(x);
            self.max_a = self.max_a.max(xa.abs());
            self.max_b = self.max_b.max(xb.abs());
        }
    }

    /// Advances `x` over the period of sample `k` without the lane-parallel RK4: the exact
    /// linear update or the exponential RK4.
    fn advance_alone(&mut self, k: i64, x: &mut [f64; NX]) {
        let twin = self.job.twin;
        if self.job.opts.mode == Mode::Nonlinear {
            match self.nl.exp_period(&twin.exp, x, self.da, self.db) {
                Ok(f) => self.flags |= f,
                Err((s, xa, xb)) => {
                    self.err =
                        self.touchdown(xa, xb, k, k as f64 * self.ts + (s + 1) as f64 * self.h);
                }
            }
        } else {
            let (ad, bd) = (&twin.ad, &twin.bd);
            let mut xn = [0.0f64; NX];
            for (i, row) in ad.iter().enumerate() {
                let mut acc = bd[i][0] * self.da + bd[i][1] * self.db;
                for j in 0..NX {
                    acc += row[j] * x[j];
                }
                xn[i] = acc;
            }
            *x = xn;
            let (xa, xb) = self.disp(x);
            if !(xa.abs() < self.g0 && xb.abs() < self.g0) {
                self.err = self.touchdown(xa, xb, k, (k + 1) as f64 * self.ts);
            }
        }
    }

    /// After the period of sample `k`: the references for the next one and the counters.
    #[inline(always)]
    fn close(&mut self, k: i64) {
        self.da = self.ua;
        self.db = self.ub;
        let flags = self.flags;
        if k >= 0 && flags != 0 {
            self.n_any += 1;
            self.n_clamp += (flags & F_CLAMP != 0) as usize;
            self.n_amp += (flags & F_AMP != 0) as usize;
            self.n_slew += (flags & F_SLEW != 0) as usize;
        }
    }

    fn finish(self) -> Result<SimRecord> {
        if let Some(e) = self.err {
            return Err(e);
        }
        let Job { twin, r, opts } = self.job;
        let ph = &twin.ph;
        let sens = &twin.cfg.sensor;
        let n = r.len();
        let nl_mode = opts.mode == Mode::Nonlinear;
        let frac = |c: usize| c as f64 / n as f64;
        let lp = ph.linear_params();
        let meta = SimMeta {
            mode: opts.mode,
            seed: opts.seed,
            noise: opts.noise,
            noise_rms_m: self.sigma,
            quantized: self.quant,
            adc_lsb_m: self.quant.then(|| sens.lsb_m()),
            samples: n,
            settle_samples: opts.settle_samples,
            fs_hz: twin.fs(),
            integrator: nl_mode.then_some(twin.cfg.simulation.integrator),
            substeps: if nl_mode { self.nsub } else { 0 },
            bias_current_a: lp.bias_current_a,
            air_gap_m: lp.air_gap_m,
            k_i: lp.k_i,
            k_x: lp.k_x,
            saturated_fraction: frac(self.n_any),
            clamp_fraction: frac(self.n_clamp),
            amp_limit_fraction: frac(self.n_amp),
            slew_limited_fraction: frac(self.n_slew),
            max_abs_displacement_a_m: self.max_a,
            max_abs_displacement_b_m: self.max_b,
        };
        Ok(SimRecord {
            ts: self.ts,
            t: self.rec_t,
            w: self.rec_w,
            r: r.to_vec(),
            u: self.rec_u,
            i: self.rec_i,
            y: self.rec_y,
            b: opts.record_b.then_some(Channels {
                u: self.b_u,
                i: self.b_i,
                y: self.b_y,
            }),
            meta,
        })
    }
}

/// Runs `L` checked jobs in lock-step: all with the same number of periods and, when more than
/// one, all with the lane-parallel RK4 at the same substeps ([`Job::lane_key`]).
fn run_lanes<const L: usize>(jobs: [Job<'_>; L]) -> [Result<SimRecord>; L] {
    let mut lanes: [Lane<'_>; L] = jobs.map(Lane::new);
    let total = jobs[0].opts.settle_samples + jobs[0].r.len();
    let ns = jobs[0].opts.settle_samples as i64;
    let rk4 = jobs[0].rk4();
    let nsub = lanes[0].nsub;
    let nl = NlLanes::new(
        &std::array::from_fn(|l| lanes[l].nl),
        std::array::from_fn(|l| lanes[l].h),
    );
    let mut xs: LaneState<L> = [[0.0; L]; NX];
    let avx2 = NlLanes::<L>::use_avx2();
    for kk in 0..total {
        let k = kk as i64 - ns;
        for (l, lane) in lanes.iter_mut().enumerate() {
            if lane.err.is_none() {
                let x: [f64; NX] = std::array::from_fn(|j| xs[j][l]);
                lane.sample(k, &x);
            }
        }
        // advance the continuous part over [t_k, t_{k+1}) with the delayed references
        if rk4 {
            let da: [f64; L] = std::array::from_fn(|l| lanes[l].da);
            let db: [f64; L] = std::array::from_fn(|l| lanes[l].db);
            let mut flags = [0u8; L];
            let mut fail = [None; L];
            if L == 1 {
                // a lone run: the scalar RK4 (branches are cheaper than selects)
                let lane = &lanes[0];
                let mut x: [f64; NX] = std::array::from_fn(|j| xs[j][0]);
                match lane.nl.period(&mut x, da[0], db[0], lane.h, nsub) {
                    Ok(f) => flags[0] = f,
                    Err(e) => fail[0] = Some(e),
                }
                for (xj, v) in xs.iter_mut().zip(x) {
                    xj[0] = v;
                }
            } else {
                nl.period_dispatch(avx2, &mut xs, &da, &db, nsub, &mut flags, &mut fail);
            }
            for (l, lane) in lanes.iter_mut().enumerate() {
                if lane.err.is_some() {
                    continue;
                }
                lane.flags |= flags[l];
                if let Some((s, xa, xb)) = fail[l] {
                    let t = k as f64 * lane.ts + (s + 1) as f64 * lane.h;
                    lane.err = lane.touchdown(xa, xb, k, t);
                }
            }
        } else {
            for (l, lane) in lanes.iter_mut().enumerate() {
                if lane.err.is_none() {
                    let mut x: [f64; NX] = std::array::from_fn(|j| xs[j][l]);
                    lane.advance_alone(k, &mut x);
                    for (xj, v) in xs.iter_mut().zip(x) {
                        xj[l] = v;
                    }
                }
            }
        }
        for (l, lane) in lanes.iter_mut().enumerate() {
            if lane.err.is_none() {
                lane.close(k);
            } else {
                // an ended lane rests at the origin (its values are not used)
                for xj in xs.iter_mut() {
                    xj[l] = 0.0;
                }
                lane.da = 0.0;
                lane.db = 0.0;
            }
        }
        if lanes.iter().all(|l| l.err.is_some()) {
            break;
        }
    }
    lanes.map(Lane::finish)
}

impl Twin {
    /// Checks `r` and `opts` for a simulation.
    fn check(r: &[f64], opts: &SimOptions) -> Result<()> {
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
        Ok(())
    }

    /// Simulates the closed loop with excitation `r` \[A\] added to controller A's output.
    ///
    /// Returns one record sample per element of `r`. Errors: non-finite `r` or `w` (with the
    /// index), `w` of the wrong length, empty `r`, touchdown ([`TwinError::Touchdown`]) or a
    /// diverging state. Library code never panics on user input.
    pub fn simulate(&self, r: &[f64], opts: &SimOptions) -> Result<SimRecord> {
        Self::check(r, opts)?;
        let [rec] = run_lanes([Job {
            twin: self,
            r,
            opts,
        }]);
        rec
    }

    /// Simulates independent runs — each a twin, an excitation `r` \[A\] and its options — and
    /// returns their records in the order given, each exactly (bit for bit) what
    /// [`Twin::simulate`] returns for it alone, errors included.
    ///
    /// Nonlinear runs with the classical RK4 that have the same substeps and the same number of
    /// periods (`settle_samples + r.len()`) run in lock-step, up to [`MAX_LANES`] at a time:
    /// each lane performs exactly a lone run's floating-point operations in the same order, the
    /// lanes share the instruction stream (SIMD, instruction-level parallelism), which costs
    /// far less than running them one after the other. The twins may differ (e.g. operating
    /// points). Other runs are simulated one by one. Nothing is run in parallel threads: split
    /// a long list across threads and call this on each part.
    ///
    /// ```
    /// use ambid_twin::{Mode, SimOptions, Twin, TwinConfig};
    /// let twin = Twin::new(TwinConfig::default()).unwrap();
    /// let r: Vec<f64> = (0..400).map(|k| 0.05 * (0.3 * k as f64).sin()).collect();
    /// let opts: Vec<SimOptions> = (0..3)
    ///     .map(|seed| SimOptions { mode: Mode::Nonlinear, seed, ..Default::default() })
    ///     .collect();
    /// let runs: Vec<(&Twin, &[f64], &SimOptions)> =
    ///     opts.iter().map(|o| (&twin, r.as_slice(), o)).collect();
    /// let recs = Twin::simulate_batch(&runs);
    /// for (rec, o) in recs.iter().zip(&opts) {
    ///     assert_eq!(rec.as_ref().unwrap(), &twin.simulate(&r, o).unwrap());
    /// }
    /// ```
    pub fn simulate_batch(runs: &[(&Twin, &[f64], &SimOptions)]) -> Vec<Result<SimRecord>> {
        let mut out: Vec<Option<Result<SimRecord>>> = (0..runs.len()).map(|_| None).collect();
        // lane groups: runs that may share lanes, in the order given
        let mut groups: Vec<((usize, usize), Vec<usize>)> = Vec::new();
        for (j, &(twin, r, opts)) in runs.iter().enumerate() {
            if let Err(e) = Self::check(r, opts) {
                out[j] = Some(Err(e));
                continue;
            }
            let job = Job { twin, r, opts };
            match job.lane_key() {
                Some(key) => match groups.iter_mut().find(|(k, _)| *k == key) {
                    Some((_, g)) => g.push(j),
                    None => groups.push((key, vec![j])),
                },
                None => {
                    let [rec] = run_lanes([job]);
                    out[j] = Some(rec);
                }
            }
        }
        let job = |j: usize| {
            let (twin, r, opts) = runs[j];
            Job { twin, r, opts }
        };
        for (_, members) in groups {
            for chunk in members.chunks(MAX_LANES) {
                let recs: Vec<Result<SimRecord>> = if let [j] = *chunk {
                    run_lanes([job(j)]).into()
                } else {
                    // four lanes (as cheap as two); spare lanes repeat the last run
                    run_lanes::<4>(std::array::from_fn(|l| job(chunk[l.min(chunk.len() - 1)])))
                        .into()
                };
                for (&j, rec) in chunk.iter().zip(recs) {
                    out[j] = Some(rec);
                }
            }
        }
        out.into_iter()
            .map(|o| {
                o.unwrap_or_else(|| {
                    Err(TwinError::InvalidArgument {
                        name: "runs",
                        reason: "internal: a run was not simulated".into(),
                    })
                })
            })
            .collect()
    }
}
