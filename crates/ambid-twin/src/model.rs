//! The linearised physics and its discrete-time assembly.
//!
//! # Rotor
//! Generalised coordinates $q = (z, \theta, \eta)$: centre-of-mass translation $z$, tilt $\theta$
//! and the modal coordinate $\eta$ of the free–free bending mode (mass normalised, eigenfrequency
//! $\omega_b$, damping ratio $\zeta_b$). The displacements at bearing (= sensor) A, a distance $a$
//! on one side of the centre of mass, and at B, a distance $b$ on the other side, are
//! $$ x_A = z - a\ \theta + \varphi_A\ \eta = c_A^\top q, \qquad
//!    x_B = z + b\ \theta + \varphi_B\ \eta = c_B^\top q, $$
//! $c_A = (1, -a, \varphi_A)$, $c_B = (1, b, \varphi_B)$. The bearing forces enter through the
//! transpose (virtual work):
//! $$ \operatorname{diag}(m, J, 1)\ \ddot q + \operatorname{diag}(0, 0, 2\zeta_b\omega_b)\ \dot q
//!    + \operatorname{diag}(0, 0, \omega_b^2)\ q = c_A F_A + c_B F_B . $$
//!
//! # Magnet
//! Each bearing is a differential pair with coil currents $i_0 \pm i$ and gaps $g_0 \mp x$:
//! $$ F(i, x) = k\left(\frac{(i_0+i)^2}{(g_0-x)^2} - \frac{(i_0-i)^2}{(g_0+x)^2}\right),
//!    \qquad k = \frac{\mu_0 N^2 A \cos\alpha}{4}. $$
//! At $(i, x) = (0, 0)$ the force vanishes, and the partial derivatives are
//! $$ k_i = \frac{\partial F}{\partial i} = k\left(\frac{2 i_0}{g_0^2} + \frac{2 i_0}{g_0^2}\right)
//!    = \frac{4 k i_0}{g_0^2}, \qquad
//!    k_x = \frac{\partial F}{\partial x} = k\left(\frac{2 i_0^2}{g_0^3} + \frac{2 i_0^2}{g_0^3}\right)
//!    = \frac{4 k i_0^2}{g_0^3}, $$
//! so $F \approx k_i i + k_x x$ with a *negative* stiffness ($+k_x$ pushes the rotor further away).
//! Both are recomputed from the operating point $(i_0, g_0)$; the controller is not retuned.
//! The force law is odd, $F(-i, -x) = -F(i, x)$, so its first nonlinearity is cubic.
//!
//! # Amplifier and sensor
//! Current amplifier: $\dot i = \omega_a (i_\mathrm{ref} - i)$. Sensor:
//! $\dot y_s = \omega_s (x - y_s)$, sampled at $t_k = k T_s$ (then noise and quantisation).
//!
//! # Continuous model and ZOH
//! With the state $\xi = (q, \dot q, i_A, i_B, y_{sA}, y_{sB}) \in \mathbb R^{10}$ and the input
//! $(i_{\mathrm{ref},A}, i_{\mathrm{ref},B})$, the linear model $\dot \xi = A_c \xi + B_c v$ is
//! discretised exactly for a zero-order-hold input: $A_d = e^{A_c T_s}$,
//! $B_d = \int_0^{T_s} e^{A_c \tau} d\tau\  B_c$.
//!
//! # Controller (Tustin)
//! With $\alpha = 2/T_s$ (no prewarping) the three parts of $C(s)$ become
//! * integrator: $x_I^+ = x_I + K_i T_s e$, output $x_I + \tfrac{K_i T_s}{2} e$;
//! * filtered derivative $K_d \omega_d s/(s+\omega_d) \to g\ (z-1)/(z-p)$,
//!   $p = \frac{\alpha-\omega_d}{\alpha+\omega_d}$, $g = \frac{K_d\omega_d\alpha}{\alpha+\omega_d}$:
//!   $x_D^+ = p x_D + e$, output $g(p-1)x_D + g e$;
//! * low-pass $\omega_l/(s+\omega_l) \to h\ (z+1)/(z-q)$,
//!   $q = \frac{\alpha-\omega_l}{\alpha+\omega_l}$, $h = \frac{\omega_l}{\alpha+\omega_l}$:
//!   $x_L^+ = q x_L + v$, output $h(1+q)x_L + h v$, where $v$ is the PID sum.
//!
//! # Assembled plant
//! State $(\xi, d_A, d_B, x_{C,B})$ with the delay registers $d_A = u_A\[k-1\]$, $d_B = u_B\[k-1\]$
//! (computation delay) and loop B closed, $u_B = C(q)(-y_B)$:
//! $$ \xi^+ = A_d\xi + B_d (d_A, d_B)^\top,\quad d_A^+ = u_A,\quad d_B^+ = C_C x_{C,B} - D_C y_{sB},
//!    \quad x_{C,B}^+ = A_C x_{C,B} - B_C y_{sB}, \quad y_A = y_{sA}. $$

use crate::config::TwinConfig;
use crate::error::Result;
use ambid_core::lti::StateSpace;
use faer::Mat;
use serde::Serialize;
use std::f64::consts::PI;

/// Vacuum permeability $\mu_0$ \[H/m\].
pub const MU0: f64 = 4e-7 * PI;

/// Linearised magnet parameters at the configured operating point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LinearParams {
    /// Force constant $k = \mu_0 N^2 A\cos\alpha / 4$ \[N·m²/A²\].
    pub force_constant: f64,
    /// Current gain $k_i = 4 k i_0 / g_0^2$ \[N/A\].
    pub k_i: f64,
    /// Negative stiffness $k_x = 4 k i_0^2 / g_0^3$ \[N/m\].
    pub k_x: f64,
    /// Bias current $i_0$ \[A\].
    pub bias_current_a: f64,
    /// Air gap $g_0$ \[m\].
    pub air_gap_m: f64,
}

/// The exact force law of a differential pair,
/// $F = k\left((i_0+i)^2/(g_0-x)^2 - (i_0-i)^2/(g_0+x)^2\right)$, with a single division.
#[inline(always)]
pub(crate) fn force_law(k: f64, i0: f64, g0: f64, i: f64, x: f64) -> f64 {
    let p = i0 + i;
    let n = i0 - i;
    let gp = g0 - x;
    let gn = g0 + x;
    // (p² gn² − n² gp²) / (gp² gn²)
    let (pg, ng) = (p * gn, n * gp);
    let d = gp * gn;
    k * (pg * pg - ng * ng) / (d * d)
}

/// All derived constants the model and the simulator need.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Physics {
    pub m: f64,
    pub j: f64,
    pub a: f64,
    pub b: f64,
    pub phi_a: f64,
    pub phi_b: f64,
    pub wb: f64,
    pub zb: f64,
    pub k: f64,
    pub ki: f64,
    pub kx: f64,
    pub i0: f64,
    pub g0: f64,
    pub wa: f64,
    pub ws: f64,
    pub vbus: f64,
    pub lcoil: f64,
    pub rcoil: f64,
    /// Amplifier output limit: $\min(i_\mathrm{sat}, i_0)$ (coil currents stay ≥ 0).
    pub i_amp_max: f64,
    pub i_sat: f64,
    pub ts: f64,
}

impl Physics {
    pub fn new(cfg: &TwinConfig) -> Physics {
        let mg = &cfg.magnet;
        let op = &cfg.operating_point;
        let k = MU0 * mg.turns * mg.turns * mg.pole_area_m2 * mg.pole_angle_deg.to_radians().cos()
            / 4.0;
        let (i0, g0) = (op.bias_current_a, op.air_gap_m);
        Physics {
            m: cfg.rotor.mass_kg,
            j: cfg.rotor.inertia(),
            a: cfg.rotor.bearing_a_m,
            b: cfg.rotor.bearing_b_m,
            phi_a: cfg.rotor.mode_shape_a,
            phi_b: cfg.rotor.mode_shape_b,
            wb: 2.0 * PI * cfg.rotor.bending_freq_hz,
            zb: cfg.rotor.bending_damping,
            k,
            ki: 4.0 * k * i0 / (g0 * g0),
            kx: 4.0 * k * i0 * i0 / (g0 * g0 * g0),
            i0,
            g0,
            wa: 2.0 * PI * cfg.amplifier.bandwidth_hz,
            ws: 2.0 * PI * cfg.sensor.bandwidth_hz,
            vbus: cfg.amplifier.bus_voltage_v,
            lcoil: cfg.amplifier.inductance_h,
            rcoil: cfg.amplifier.resistance_ohm,
            i_amp_max: mg.i_sat_a.min(i0),
            i_sat: mg.i_sat_a,
            ts: 1.0 / cfg.controller.fs_hz,
        }
    }

    pub fn linear_params(&self) -> LinearParams {
        LinearParams {
            force_constant: self.k,
            k_i: self.ki,
            k_x: self.kx,
            bias_current_a: self.i0,
            air_gap_m: self.g0,
        }
    }

    pub fn c_a(&self) -> [f64; 3] {
        [1.0, -self.a, self.phi_a]
    }

    pub fn c_b(&self) -> [f64; 3] {
        [1.0, self.b, self.phi_b]
    }

    /// Exact force law of one differential pair at this operating point.
    #[cfg(test)]
    pub fn force(&self, i: f64, x: f64) -> f64 {
        force_law(self.k, self.i0, self.g0, i, x)
    }

    /// The 10-state continuous linear model: inputs $(i_{\mathrm{ref},A}, i_{\mathrm{ref},B})$,
    /// outputs $(y_{sA}, y_{sB})$.
    pub fn continuous_model(&self) -> Result<StateSpace> {
        let n = 10;
        let mut a = Mat::<f64>::zeros(n, n);
        let mut b = Mat::<f64>::zeros(n, 2);
        let ca = self.c_a();
        let cb = self.c_b();
        let minv = [1.0 / self.m, 1.0 / self.j, 1.0];
        for r in 0..3 {
            a[(r, r + 3)] = 1.0;
            for c in 0..3 {
                a[(3 + r, c)] = minv[r] * self.kx * (ca[r] * ca[c] + cb[r] * cb[c]);
            }
            a[(3 + r, 6)] = minv[r] * ca[r] * self.ki;
            a[(3 + r, 7)] = minv[r] * cb[r] * self.ki;
            a[(8, r)] = self.ws * ca[r];
            a[(9, r)] = self.ws * cb[r];
        }
        a[(5, 2)] -= self.wb * self.wb;
        a[(5, 5)] -= 2.0 * self.zb * self.wb;
        a[(6, 6)] = -self.wa;
        a[(7, 7)] = -self.wa;
        b[(6, 0)] = self.wa;
        b[(7, 1)] = self.wa;
        a[(8, 8)] = -self.ws;
        a[(9, 9)] = -self.ws;
        let mut c = Mat::<f64>::zeros(2, n);
        c[(0, 8)] = 1.0;
        c[(1, 9)] = 1.0;
        Ok(StateSpace::continuous(a, b, c, Mat::zeros(2, 2))?)
    }

    /// Physics prediction of the unstable plant pole (see [`UnstablePolePrediction`]).
    pub fn unstable_pole_prediction(&self, kp: f64) -> UnstablePolePrediction {
        let (m, j, a, b, kx) = (self.m, self.j, self.a, self.b, self.kx);
        let jb = j + m * b * b;
        let pinned = (kx * (a + b) * (a + b) / jb).sqrt();
        let kb = self.ki * kp - kx;
        // K = kb cB cBᵀ − kx cA cAᵀ, cA = (1, −a), cB = (1, b); eigenvalues of M⁻¹K
        let k11 = kb - kx;
        let k12 = kb * b + kx * a;
        let k22 = kb * b * b - kx * a * a;
        let (m11, m12, m21, m22) = (k11 / m, k12 / m, k12 / j, k22 / j);
        let tr = m11 + m22;
        let det = m11 * m22 - m12 * m21;
        let disc = (tr * tr - 4.0 * det).max(0.0).sqrt();
        let lam_min = 0.5 * (tr - disc);
        let two = if lam_min < 0.0 {
            (-lam_min).sqrt()
        } else {
            0.0
        };
        UnstablePolePrediction {
            count: 1,
            pinned_at_b_rad_s: pinned,
            rigid_spring_b_rad_s: two,
            bearing_b_stiffness_n_per_m: kb,
        }
    }
}

/// What physics predicts for the unstable pole(s) of the assembled plant $P$ (loop A open,
/// loop B closed).
///
/// With loop A open nothing compensates the negative stiffness $k_x$ at bearing A, while loop B
/// holds bearing B with the positive net stiffness $k_B \approx k_i K_p - k_x$ (the
/// proportional action; the integrator and the derivative matter little at the pole's
/// frequency). The rigid rotor $(z, \theta)$ then obeys
/// $$ \operatorname{diag}(m, J)\ \ddot q + K q = 0, \qquad
///    K = k_B\  c_B c_B^\top - k_x\  c_A c_A^\top, \  c_A = (1, -a),\  c_B = (1, b), $$
/// whose stiffness matrix has exactly **one** negative eigenvalue (the one-dimensional negative
/// spring at A cannot make more than one direction unstable; the other direction is held by
/// $k_B > 0$). It gives one real unstable pole $s_+ = \sqrt{-\lambda_{\min}(M^{-1}K)}$ and its
/// mirror image $-s_+$; in discrete time one pole $z = e^{s_+ T_s} > 1$.
/// The limit $k_B \to \infty$ pins the rotor at B: it rotates about B with inertia
/// $J_B = J + m b^2$ and the lever $(a+b)$ at A,
/// $$ J_B \ddot\psi = k_x (a+b)^2 \psi \ \Rightarrow\  s_+ = \sqrt{k_x (a+b)^2 / J_B}, $$
/// a lower bound (a finite $k_B$ lets B yield and raises $s_+$). The bending mode (730 Hz) and
/// the dynamics of amplifier, sensor and digital loop B shift the exact value only slightly;
/// the exact value is the eigenvalue of the discrete assembled plant, mapped by $s = \ln z/T_s$.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct UnstablePolePrediction {
    /// Predicted number of unstable poles (always 1 for a stabilised loop B).
    pub count: usize,
    /// $\sqrt{k_x (a+b)^2/J_B}$, rotor pinned at B \[rad/s\].
    pub pinned_at_b_rad_s: f64,
    /// Rigid rotor with bearing B as the spring $k_B = k_i K_p - k_x$ \[rad/s\].
    pub rigid_spring_b_rad_s: f64,
    /// $k_B$ used above \[N/m\].
    pub bearing_b_stiffness_n_per_m: f64,
}

/// Tustin PID coefficients and the per-sample controller (shared by the truth and the simulator).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Pid {
    /// $K_p + K_i T_s/2 + g$: direct gain of the PID sum.
    pub dv: f64,
    pub ki_ts: f64,
    /// $g(p-1)$
    pub dcoef: f64,
    pub p: f64,
    pub q: f64,
    /// $h(1+q)$
    pub lcoef: f64,
    pub h: f64,
    pub i_sat: f64,
}

/// Controller state $(x_I, x_D, x_L)$.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct PidState {
    pub xi: f64,
    pub xd: f64,
    pub xl: f64,
}

impl Pid {
    pub fn new(cfg: &TwinConfig) -> Pid {
        let c = &cfg.controller;
        let ts = 1.0 / c.fs_hz;
        let alpha = 2.0 / ts;
        let wd = 2.0 * PI * c.derivative_cutoff_hz;
        let wl = 2.0 * PI * c.lowpass_hz;
        let p = (alpha - wd) / (alpha + wd);
        let g = c.kd * wd * alpha / (alpha + wd);
        let q = (alpha - wl) / (alpha + wl);
        let h = wl / (alpha + wl);
        let ki = c.ki();
        Pid {
            dv: c.kp + ki * ts / 2.0 + g,
            ki_ts: ki * ts,
            dcoef: g * (p - 1.0),
            p,
            q,
            lcoef: h * (1.0 + q),
            h,
            i_sat: cfg.magnet.i_sat_a,
        }
    }

    /// One controller sample: returns the clamped output and whether the clamp was active.
    /// Anti-windup: the integrator holds while the clamp is active and the error drives further
    /// into it (conditional integration).
    #[inline(always)]
    pub fn step(&self, s: &mut PidState, e: f64) -> (f64, bool) {
        let v = self.dv * e + s.xi + self.dcoef * s.xd;
        let c = self.lcoef * s.xl + self.h * v;
        let (out, clamped) = if c > self.i_sat {
            (self.i_sat, true)
        } else if c < -self.i_sat {
            (-self.i_sat, true)
        } else {
            (c, false)
        };
        let freeze = (c > self.i_sat && e > 0.0) || (c < -self.i_sat && e < 0.0);
        if !freeze {
            s.xi += self.ki_ts * e;
        }
        s.xd = self.p * s.xd + e;
        s.xl = self.q * s.xl + v;
        (out, clamped)
    }

    /// $(A_C, B_C, C_C, D_C)$ of the unclamped controller, state $(x_I, x_D, x_L)$, input $e$.
    pub fn matrices(&self) -> ([[f64; 3]; 3], [f64; 3], [f64; 3], f64) {
        let a = [
            [1.0, 0.0, 0.0],
            [0.0, self.p, 0.0],
            [1.0, self.dcoef, self.q],
        ];
        let b = [self.ki_ts, 1.0, self.dv];
        let c = [self.h, self.h * self.dcoef, self.lcoef];
        (a, b, c, self.h * self.dv)
    }

    pub fn state_space(&self, ts: f64) -> Result<StateSpace> {
        let (a, b, c, d) = self.matrices();
        Ok(StateSpace::discrete(
            Mat::from_fn(3, 3, |i, j| a[i][j]),
            Mat::from_fn(3, 1, |i, _| b[i]),
            Mat::from_fn(1, 3, |_, j| c[j]),
            Mat::from_fn(1, 1, |_, _| d),
            ts,
        )?)
    }
}

/// Index layout of the assembled models.
pub(crate) const NX: usize = 10;
const IDA: usize = NX;
const IDB: usize = NX + 1;
const ICB: usize = NX + 2;
const ICA: usize = NX + 5;

/// Builds the discrete assembled plant (15 states) and the full closed loop (18 states, inputs
/// $(r, w)$, outputs $(y_A, u_A)$) from the ZOH model $(A_d, B_d)$ and the controller.
pub(crate) fn assemble(
    ad: &[[f64; NX]; NX],
    bd: &[[f64; 2]; NX],
    pid: &Pid,
    ts: f64,
) -> Result<(StateSpace, StateSpace)> {
    let (ac, bc, cc, dc) = pid.matrices();
    // Wires a controller (states from `ctrl`) acting on −(sensor state `sensor`) into the delay
    // register `delay`: d⁺ = C_C x_C − D_C y_s, x_C⁺ = A_C x_C − B_C y_s.
    let close_loop = |a: &mut Mat<f64>, delay: usize, ctrl: usize, sensor: usize| {
        for j in 0..3 {
            a[(delay, ctrl + j)] = cc[j];
        }
        a[(delay, sensor)] = -dc;
        for i in 0..3 {
            for j in 0..3 {
                a[(ctrl + i, ctrl + j)] = ac[i][j];
            }
            a[(ctrl + i, sensor)] = -bc[i];
        }
    };
    let fill_common = |a: &mut Mat<f64>| {
        for i in 0..NX {
            for j in 0..NX {
                a[(i, j)] = ad[i][j];
            }
            a[(i, IDA)] = bd[i][0];
            a[(i, IDB)] = bd[i][1];
        }
        // loop B: d_B⁺ = C_C x_CB − D_C y_sB ; x_CB⁺ = A_C x_CB − B_C y_sB
        close_loop(a, IDB, ICB, 9);
    };
    let np = NX + 5;
    let mut ap = Mat::<f64>::zeros(np, np);
    fill_common(&mut ap);
    let mut bp = Mat::<f64>::zeros(np, 1);
    bp[(IDA, 0)] = 1.0;
    let mut cp = Mat::<f64>::zeros(1, np);
    cp[(0, 8)] = 1.0;
    let plant = StateSpace::discrete(ap, bp, cp, Mat::zeros(1, 1), ts)?;

    let nf = NX + 8;
    let mut af = Mat::<f64>::zeros(nf, nf);
    fill_common(&mut af);
    // u_A = C_C x_CA + D_C (w − y_sA) + r ; d_A⁺ = u_A ; x_CA⁺ = A_C x_CA + B_C (w − y_sA)
    close_loop(&mut af, IDA, ICA, 8);
    let mut bf = Mat::<f64>::zeros(nf, 2);
    bf[(IDA, 0)] = 1.0; // r
    bf[(IDA, 1)] = dc; // w
    for i in 0..3 {
        bf[(ICA + i, 1)] = bc[i];
    }
    let mut cf = Mat::<f64>::zeros(2, nf);
    cf[(0, 8)] = 1.0;
    for j in 0..3 {
        cf[(1, ICA + j)] = cc[j];
    }
    cf[(1, 8)] = -dc;
    let mut df = Mat::<f64>::zeros(2, 2);
    df[(1, 0)] = 1.0;
    df[(1, 1)] = dc;
    let closed = StateSpace::discrete(af, bf, cf, df, ts)?;
    Ok((plant, closed))
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::c64;

    #[test]
    fn nominal_magnet_constants() {
        let ph = Physics::new(&TwinConfig::default());
        assert!((ph.ki - 58.0).abs() < 0.5, "k_i = {}", ph.ki);
        assert!((ph.kx - 2.9e5).abs() < 0.02e5, "k_x = {}", ph.kx);
        // finite-difference check of the linearisation
        let h = 1e-7;
        let dfi = (ph.force(h, 0.0) - ph.force(-h, 0.0)) / (2.0 * h);
        let dfx = (ph.force(0.0, h * 1e-4) - ph.force(0.0, -h * 1e-4)) / (2.0 * h * 1e-4);
        assert!((dfi / ph.ki - 1.0).abs() < 1e-7);
        assert!((dfx / ph.kx - 1.0).abs() < 1e-7);
        assert_eq!(ph.force(0.0, 0.0), 0.0);
        assert!((ph.force(0.3, 1e-5) + ph.force(-0.3, -1e-5)).abs() < 1e-9);
    }

    #[test]
    fn tustin_controller_matches_bilinear_substitution() {
        let cfg = TwinConfig::default();
        let pid = Pid::new(&cfg);
        let ts = 1.0 / cfg.controller.fs_hz;
        let ss = pid.state_space(ts).unwrap();
        let c = &cfg.controller;
        let (wd, wl) = (2.0 * PI * c.derivative_cutoff_hz, 2.0 * PI * c.lowpass_hz);
        for &f in &[1.0, 10.0, 97.0, 500.0, 2000.0, 7000.0] {
            let z = c64::from_polar(1.0, 2.0 * PI * f * ts);
            let s = (z - 1.0) / (z + 1.0) * (2.0 / ts);
            let cs = (s * c.kd / (s / wd + 1.0) + c.ki() / s + c.kp) / (s / wl + 1.0);
            let cz = ss.freq_response_siso(&[f]).unwrap()[0];
            assert!((cz - cs).norm() / cs.norm() < 1e-12, "f {f}: {cz} vs {cs}");
        }
    }

    #[test]
    fn pid_step_equals_state_space_when_unclamped() {
        let cfg = TwinConfig::default();
        let pid = Pid::new(&cfg);
        let ss = pid.state_space(1.0 / cfg.controller.fs_hz).unwrap();
        let e: Vec<f64> = (0..200).map(|k| 1e-6 * ((k as f64) * 0.37).sin()).collect();
        let y_ss = ss.simulate_siso(&e, None).unwrap();
        let mut st = PidState::default();
        for (k, &ek) in e.iter().enumerate() {
            let (c, cl) = pid.step(&mut st, ek);
            assert!(!cl);
            assert!((c - y_ss[k]).abs() < 1e-12 * (1.0 + y_ss[k].abs()));
        }
    }
}
