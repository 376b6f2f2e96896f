//! The [`Twin`]: configuration, linear truth and simulation entry point.

use crate::config::TwinConfig;
use crate::error::{Result, TwinError};
use crate::model::{assemble, LinearParams, Physics, Pid, UnstablePolePrediction, NX};
use crate::sim::ExpTables;
use ambid_core::lti::StateSpace;
use faer::c64;
use serde::Serialize;
use std::f64::consts::PI;

/// Damping-ratio threshold below which a closed-loop pole pair counts as a (lightly damped) mode.
pub const LIGHTLY_DAMPED: f64 = 0.5;

/// A complex closed-loop pole pair, mapped to continuous time by $s = \ln(z)/T_s$.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ClosedLoopMode {
    /// Natural frequency $|s|/2\pi$ \[Hz\].
    pub freq_hz: f64,
    /// Damped frequency $\operatorname{Im}(s)/2\pi$ \[Hz\].
    pub damped_freq_hz: f64,
    /// Damping ratio $\zeta = -\operatorname{Re}(s)/|s|$.
    pub damping: f64,
    /// The discrete pole (upper half plane member of the pair); serialised as `\[re, im\]`.
    #[serde(serialize_with = "ser_c64")]
    pub z: c64,
}

fn ser_c64<S: serde::Serializer>(z: &c64, s: S) -> std::result::Result<S::Ok, S::Error> {
    [z.re, z.im].serialize(s)
}

/// The AMB digital twin: two bearings A and B under decentralised digital PID control, with the
/// exact linearised discrete-time truth.
///
/// See the [crate documentation](crate) for the model and the timing convention.
///
/// # Example
/// ```
/// use ambid_twin::{Twin, TwinConfig, SimOptions, Mode};
/// let twin = Twin::new(TwinConfig::default()).unwrap();
/// assert_eq!(twin.fs(), 20e3);
/// // truth
/// let s = twin.sensitivity_frf(&[100.0]).unwrap();
/// let (f_pk, s_pk) = twin.peak_sensitivity().unwrap();
/// assert!(s_pk > 2.0 && s_pk < 3.0 && f_pk > 50.0);
/// assert_eq!(twin.plant_unstable_poles().unwrap().len(), 1);
/// // a short nonlinear run with a small square-wave excitation
/// let r: Vec<f64> = (0..400).map(|k| if (k / 50) % 2 == 0 { 0.04 } else { -0.04 }).collect();
/// let rec = twin.simulate(&r, &SimOptions { mode: Mode::Nonlinear, seed: 7, ..Default::default() }).unwrap();
/// assert_eq!(rec.y.len(), 400);
/// assert!(rec.y.iter().all(|y| y.abs() < 1e-4));
/// # let _ = s;
/// ```
#[derive(Debug, Clone)]
pub struct Twin {
    pub(crate) cfg: TwinConfig,
    pub(crate) ph: Physics,
    pub(crate) pid: Pid,
    pub(crate) ad: [[f64; NX]; NX],
    pub(crate) bd: [[f64; 2]; NX],
    pub(crate) exp: ExpTables,
    continuous: StateSpace,
    discrete: StateSpace,
    controller: StateSpace,
    plant: StateSpace,
    closed: StateSpace,
    cl_poles: Vec<c64>,
}

impl Twin {
    /// Builds the twin: validates the configuration, linearises at the operating point,
    /// discretises, assembles the plant and the closed loop, and checks closed-loop stability.
    ///
    /// Errors: [`TwinError::Config`] for a malformed configuration,
    /// [`TwinError::UnstableClosedLoop`] if the linearised closed loop is not asymptotically
    /// stable (with the largest pole magnitude and what to change).
    pub fn new(cfg: TwinConfig) -> Result<Twin> {
        cfg.validate()?;
        let ph = Physics::new(&cfg);
        let pid = Pid::new(&cfg);
        let ts = ph.ts;
        let continuous = ph.continuous_model()?;
        let discrete = continuous.c2d_zoh(ts)?;
        let mut ad = [[0.0; NX]; NX];
        let mut bd = [[0.0; 2]; NX];
        for (i, (row, brow)) in ad.iter_mut().zip(bd.iter_mut()).enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = discrete.a()[(i, j)];
            }
            *brow = [discrete.b()[(i, 0)], discrete.b()[(i, 1)]];
        }
        let exp = ExpTables::new(&ph, &continuous, cfg.simulation.exp_substeps)?;
        let controller = pid.state_space(ts)?;
        let (plant, closed) = assemble(&ad, &bd, &pid, ts)?;
        let cl_poles = closed.poles()?;
        let worst = cl_poles
            .iter()
            .copied()
            .max_by(|a, b| a.norm().total_cmp(&b.norm()))
            .unwrap_or(c64::new(0.0, 0.0));
        let worst = if worst.im < 0.0 { worst.conj() } else { worst };
        if worst.norm() >= 1.0 {
            let s = z_to_s(worst, ts);
            let kp = cfg.controller.kp;
            let hint = if ph.ki * kp <= ph.kx {
                format!(
                    "the proportional stiffness k_i·K_p = {:.4e} N/m does not exceed the magnets' negative \
                     stiffness k_x = {:.4e} N/m; raise controller.kp well above k_x/k_i = {:.0} A/m \
                     (nominal 21000), or lower the bias current / enlarge the air gap",
                    ph.ki * kp,
                    ph.kx,
                    ph.kx / ph.ki
                )
            } else {
                "the loop lacks phase margin or damping: check controller.kd, the filter corners \
                 (derivative_cutoff_hz, lowpass_hz), fs_hz and the amplifier/sensor bandwidths, or move the \
                 operating point back toward nominal"
                    .to_string()
            };
            return Err(TwinError::UnstableClosedLoop {
                max_pole_magnitude: worst.norm(),
                s_re: s.re,
                s_im: s.im,
                hint,
            });
        }
        Ok(Twin {
            cfg,
            ph,
            pid,
            ad,
            bd,
            exp,
            continuous,
            discrete,
            controller,
            plant,
            closed,
            cl_poles,
        })
    }

    /// Sample time $T_s = 1/f_s$ \[s\].
    pub fn ts(&self) -> f64 {
        self.ph.ts
    }

    /// Sampling frequency $f_s$ \[Hz\].
    pub fn fs(&self) -> f64 {
        self.cfg.controller.fs_hz
    }

    /// Control-current saturation $i_\mathrm{sat}$ \[A\].
    pub fn i_sat(&self) -> f64 {
        self.ph.i_sat
    }

    /// The configuration the twin was built from.
    pub fn config(&self) -> &TwinConfig {
        &self.cfg
    }

    /// $k$, $k_i$ and $k_x$ at the configured operating point.
    pub fn linear_params(&self) -> LinearParams {
        self.ph.linear_params()
    }

    /// The 10-state continuous linear model (rotor 6, amplifiers A/B, sensor low-passes A/B),
    /// inputs $(i_{\mathrm{ref},A}, i_{\mathrm{ref},B})$, outputs the sensor states $(y_{sA}, y_{sB})$.
    pub fn continuous_model(&self) -> &StateSpace {
        &self.continuous
    }

    /// Its exact ZOH discretisation at $T_s$.
    pub fn discrete_model(&self) -> &StateSpace {
        &self.discrete
    }

    /// The discrete assembled plant $P$: recorded $u_A$ → recorded $y_A$, including the one-sample
    /// computation delay, the ZOH, amplifier, magnet, rotor, sensor low-pass, sampling and loop B
    /// closed by its own controller (15 states).
    pub fn plant(&self) -> &StateSpace {
        &self.plant
    }

    /// The discrete controller $C$ (Tustin PID with filters, no delay, no clamp): $w - y \to u$.
    pub fn controller(&self) -> &StateSpace {
        &self.controller
    }

    /// The discrete closed loop with both loops closed (18 states): inputs $(r, w)$ at bearing A,
    /// outputs $(y_A, u_A)$.
    pub fn closed_loop(&self) -> &StateSpace {
        &self.closed
    }

    /// Exact frequency response of the assembled plant $P(e^{j2\pi f T_s})$ at `f_hz` \[Hz\].
    pub fn plant_frf(&self, f_hz: &[f64]) -> Result<Vec<c64>> {
        Ok(self.plant.freq_response_siso(f_hz)?)
    }

    /// Exact frequency response of the controller $C(e^{j2\pi f T_s})$.
    pub fn controller_frf(&self, f_hz: &[f64]) -> Result<Vec<c64>> {
        Ok(self.controller.freq_response_siso(f_hz)?)
    }

    /// Process sensitivity $T_{ry} = P/(1+PC)$ (excitation $r$ → measured $y$).
    pub fn t_ry_frf(&self, f_hz: &[f64]) -> Result<Vec<c64>> {
        let p = self.plant_frf(f_hz)?;
        let c = self.controller_frf(f_hz)?;
        Ok(p.iter().zip(&c).map(|(p, c)| p / (*p * c + 1.0)).collect())
    }

    /// Sensitivity $S = T_{ru} = 1/(1+PC)$ (excitation $r$ → recorded controller output $u$).
    pub fn sensitivity_frf(&self, f_hz: &[f64]) -> Result<Vec<c64>> {
        let p = self.plant_frf(f_hz)?;
        let c = self.controller_frf(f_hz)?;
        Ok(p.iter()
            .zip(&c)
            .map(|(p, c)| (*p * c + 1.0).inv())
            .collect())
    }

    /// Poles of the discrete closed loop (both loops closed), in $z$.
    pub fn closed_loop_poles(&self) -> Vec<c64> {
        self.cl_poles.clone()
    }

    /// Every complex closed-loop pole pair as a mode, sorted by natural frequency.
    pub fn closed_loop_pole_pairs(&self) -> Vec<ClosedLoopMode> {
        let ts = self.ts();
        let mut v: Vec<ClosedLoopMode> = self
            .cl_poles
            .iter()
            .filter(|z| z.im > 1e-12 && z.norm() > 1e-12)
            .map(|&z| {
                let s = z_to_s(z, ts);
                ClosedLoopMode {
                    freq_hz: s.norm() / (2.0 * PI),
                    damped_freq_hz: s.im / (2.0 * PI),
                    damping: -s.re / s.norm(),
                    z,
                }
            })
            .collect();
        v.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
        v
    }

    /// The lightly damped closed-loop modes (damping ratio below [`LIGHTLY_DAMPED`]), sorted by
    /// frequency. At nominal: the translational (≈ 97 Hz), the tilting (≈ 156 Hz) and the
    /// bending (≈ 780 Hz) mode.
    pub fn closed_loop_modes(&self) -> Vec<ClosedLoopMode> {
        self.closed_loop_pole_pairs()
            .into_iter()
            .filter(|m| m.damping < LIGHTLY_DAMPED)
            .collect()
    }

    /// Peak of $|S|$ over 1 Hz … $f_s/2$: a 4000-point log grid, then golden-section refinement
    /// between the neighbours of the grid maximum. Returns `(f_hz, |S|)`.
    pub fn peak_sensitivity(&self) -> Result<(f64, f64)> {
        let n = 4000;
        let (f0, f1) = (1.0f64, self.fs() / 2.0);
        let grid: Vec<f64> = (0..n)
            .map(|k| f0 * (f1 / f0).powf(k as f64 / (n - 1) as f64))
            .collect();
        let s = self.sensitivity_frf(&grid)?;
        let (kmax, _) = s
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.norm().total_cmp(&b.1.norm()))
            .ok_or_else(|| TwinError::InvalidArgument {
                name: "grid",
                reason: "empty frequency grid".into(),
            })?;
        let mag = |f: f64| -> Result<f64> { Ok(self.sensitivity_frf(&[f])?[0].norm()) };
        let (mut lo, mut hi) = (grid[kmax.saturating_sub(1)], grid[(kmax + 1).min(n - 1)]);
        let gr = (5f64.sqrt() - 1.0) / 2.0;
        let mut x1 = hi - gr * (hi - lo);
        let mut x2 = lo + gr * (hi - lo);
        let (mut m1, mut m2) = (mag(x1)?, mag(x2)?);
        for _ in 0..60 {
            if m1 > m2 {
                hi = x2;
                x2 = x1;
                m2 = m1;
                x1 = hi - gr * (hi - lo);
                m1 = mag(x1)?;
            } else {
                lo = x1;
                x1 = x2;
                m1 = m2;
                x2 = lo + gr * (hi - lo);
                m2 = mag(x2)?;
            }
            if hi - lo < 1e-9 * hi {
                break;
            }
        }
        let fbest = 0.5 * (lo + hi);
        let best = mag(fbest)?.max(s[kmax].norm());
        let fbest = if best > s[kmax].norm() {
            fbest
        } else {
            grid[kmax]
        };
        Ok((fbest, best))
    }

    /// Poles of the assembled plant $P$ outside the unit circle ($|z| > 1$), in $z$.
    pub fn plant_unstable_poles(&self) -> Result<Vec<c64>> {
        Ok(self
            .plant
            .poles()?
            .into_iter()
            .filter(|z| z.norm() > 1.0)
            .collect())
    }

    /// What physics predicts for the unstable pole(s) of $P$ (see [`UnstablePolePrediction`]).
    pub fn predicted_unstable_pole(&self) -> UnstablePolePrediction {
        self.ph.unstable_pole_prediction(self.cfg.controller.kp)
    }

    /// Maps a discrete pole to continuous time, $s = \ln(z)/T_s$ (principal branch).
    pub fn pole_to_s(&self, z: c64) -> c64 {
        z_to_s(z, self.ts())
    }
}

pub(crate) fn z_to_s(z: c64, ts: f64) -> c64 {
    c64::new(z.norm().ln(), z.im.atan2(z.re)) / ts
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_loop_state_space_matches_frf_algebra() {
        let t = Twin::new(TwinConfig::default()).unwrap();
        let f = [3.0, 97.0, 156.0, 780.0, 3000.0];
        let g = t.closed_loop().freq_response(&f).unwrap();
        let tr = t.t_ry_frf(&f).unwrap();
        let s = t.sensitivity_frf(&f).unwrap();
        for k in 0..f.len() {
            println!(
                "{} Hz: T_ry {:.2e}, S {:.2e}",
                f[k],
                (g[k][(0, 0)] - tr[k]).norm() / tr[k].norm(),
                (g[k][(1, 0)] - s[k]).norm() / s[k].norm()
            );
        }
        for k in 0..f.len() {
            assert!((g[k][(0, 0)] - tr[k]).norm() < 1e-11 * tr[k].norm());
            assert!((g[k][(1, 0)] - s[k]).norm() < 1e-11 * s[k].norm());
        }
    }
}
