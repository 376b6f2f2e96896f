//! Closed-loop time-domain simulation of the 4-axis [`Machine`].
//!
//! One control period is the single-plane twin's (see [`sim`](crate::sim)), for each of the four
//! axes in [`AXES`] order: at $t_k$ the controller of axis $a$ reads
//! $y_a\[k\] = y_{s,a}(t_k) + v_a\[k\]$ (white Gaussian noise, RMS `sensor.noise_rms_m`, from its own
//! seeded stream: `ChaCha8Rng::seed_from_u64(seed)` with stream $a + 1$; then optional ADC
//! quantisation), computes $c_a\[k\] = C_a(q)(w_a\[k\] - y_a\[k\])$ (Tustin PID, clamp, anti-windup)
//! and records $u_a\[k\] = \operatorname{clamp}(c_a\[k\] + r_a\[k\], \pm i_\mathrm{sat})$, which is the
//! amplifier's reference during $[t_{k+1}, t_{k+2})$ (one-sample delay, ZOH).
//!
//! * [`Mode::Linear`]: the continuous part advances exactly,
//!   $\xi_{k+1} = A_d\xi_k + B_d u\[k-1\]$ (with the unbalance oscillator appended when
//!   configured), so with noise off and no clamp active the record obeys the linear truth of
//!   [`Machine`] to rounding error.
//! * [`Mode::Nonlinear`]: the exact force law of every magnet pair with the actual coil control
//!   currents (the y magnets' force constant scaled by $1 + \delta_i$), the amplifier output limit
//!   $|i| \le \min(i_\mathrm{sat}, i_0)$, gyroscopics and unbalance, integrated by classical RK4 at
//!   `simulation.substeps` steps per period. (Unlike the single-plane twin it has no amplifier
//!   slew limit and no exponential integrator.)
//!
//! The excitation is cyclic in the pre-roll (`settle_samples` samples before the record), so a
//! periodic excitation reaches its periodic steady state before sample 0.

// index loops over axes and states read clearer than zipped iterators here
#![allow(clippy::needless_range_loop)]

use crate::config::Mode;
use crate::error::{Result, TwinError};
use crate::machine::{Machine, AXES, I_CUR, I_SEN, NX4};
use crate::model::{force_law, PidState};
use ambid_core::data::IoData;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

/// Options of [`Machine::simulate`].
#[derive(Debug, Clone, PartialEq)]
pub struct MachineSimOptions {
    /// Linear or nonlinear physics. Default linear.
    pub mode: Mode,
    /// Seed of the four sensor-noise streams. Default 0.
    pub seed: u64,
    /// Sensor noise on. Default on.
    pub noise: bool,
    /// Optional position references $w$ per axis (each as long as `r`) \[m\].
    pub w: Option<[Vec<f64>; 4]>,
    /// Samples simulated (and discarded) before the record, with the excitation cyclic.
    pub settle_samples: usize,
}

impl Default for MachineSimOptions {
    fn default() -> Self {
        Self {
            mode: Mode::Linear,
            seed: 0,
            noise: true,
            w: None,
            settle_samples: 0,
        }
    }
}

/// What a run did, per axis in [`AXES`] order.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MachineSimMeta {
    /// Physics mode.
    pub mode: Mode,
    /// Noise seed.
    pub seed: u64,
    /// Whether noise was on.
    pub noise: bool,
    /// RMS of the sensor noise added \[m\] (0 with noise off).
    pub noise_rms_m: f64,
    /// Recorded samples.
    pub samples: usize,
    /// Pre-roll samples.
    pub settle_samples: usize,
    /// Sampling frequency \[Hz\].
    pub fs_hz: f64,
    /// Rotor speed \[rpm\].
    pub speed_rpm: f64,
    /// 1× frequency \[Hz\].
    pub sync_hz: f64,
    /// Whether an unbalance force acted.
    pub unbalance: bool,
    /// Fraction of recorded samples where the axis's recorded output $u$ hit $\pm i_\mathrm{sat}$
    /// (controller clamp or DAC clamp).
    pub saturated_fraction: [f64; 4],
    /// Largest rotor displacement at each bearing/direction \[m\].
    pub max_abs_displacement_m: [f64; 4],
}

/// A 4-axis record: per axis (in [`AXES`] order) $r$, $u$, $y$, $i$, and $w$.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MachineRecord {
    /// Sample time \[s\].
    pub ts: f64,
    /// Sample times \[s\].
    pub t: Vec<f64>,
    /// Excitations \[A\].
    pub r: [Vec<f64>; 4],
    /// Recorded controller outputs \[A\].
    pub u: [Vec<f64>; 4],
    /// Sampled displacements (with noise) \[m\].
    pub y: [Vec<f64>; 4],
    /// Coil control currents at $t_k$ \[A\].
    pub i: [Vec<f64>; 4],
    /// Position references \[m\].
    pub w: [Vec<f64>; 4],
    /// Run metadata.
    pub meta: MachineSimMeta,
}

impl MachineRecord {
    /// The record as [`IoData`] with the channels `r_xa … r_yb`, `u_xa … u_yb`, `y_xa … y_yb`,
    /// `i_xa … i_yb` (roles from the names), sample time `ts` and optional period.
    pub fn to_iodata(&self, period_samples: Option<usize>) -> Result<IoData> {
        let mut ch = Vec::with_capacity(16);
        for (letter, sig) in [
            ("r", &self.r),
            ("u", &self.u),
            ("y", &self.y),
            ("i", &self.i),
        ] {
            for (k, ax) in AXES.iter().enumerate() {
                ch.push((format!("{letter}_{ax}"), sig[k].clone()));
            }
        }
        Ok(IoData::new(ch, self.ts, period_samples)?)
    }
}

fn check_signal(what: &'static str, x: &[f64], n: usize) -> Result<()> {
    if x.len() != n {
        return Err(TwinError::LengthMismatch {
            what,
            expected: n,
            got: x.len(),
        });
    }
    if let Some(index) = x.iter().position(|v| !v.is_finite()) {
        return Err(TwinError::NonFinite { what, index });
    }
    Ok(())
}

const R_NAMES: [&str; 4] = ["r_xa", "r_xb", "r_ya", "r_yb"];
const W_NAMES: [&str; 4] = ["w_xa", "w_xb", "w_ya", "w_yb"];

impl Machine {
    /// Simulates the closed loop with the excitations `r` (one per axis, equal lengths, added to
    /// the controller outputs). See the [module documentation](crate::sim4).
    ///
    /// Errors: empty or unequal excitations, non-finite samples, wrong reference lengths
    /// ([`TwinError::LengthMismatch`], [`TwinError::NonFinite`], [`TwinError::InvalidArgument`]);
    /// [`TwinError::Touchdown`] when a displacement reaches the air gap, [`TwinError::Diverged`].
    ///
    /// ```
    /// use ambid_twin::{Machine, MachineConfig, MachineSimOptions};
    /// let m = Machine::new(MachineConfig::default()).unwrap();
    /// let r: Vec<f64> = (0..400).map(|k| 0.05 * (k as f64 * 0.3).sin()).collect();
    /// let z = vec![0.0; 400];
    /// let rec = m.simulate([&r, &z, &z, &z], &MachineSimOptions::default()).unwrap();
    /// assert_eq!(rec.y[0].len(), 400);
    /// let data = rec.to_iodata(None).unwrap();
    /// assert_eq!(data.channel("u_yb").unwrap().len(), 400);
    /// ```
    pub fn simulate(&self, r: [&[f64]; 4], opts: &MachineSimOptions) -> Result<MachineRecord> {
        let n = r[0].len();
        if n == 0 {
            return Err(TwinError::InvalidArgument {
                name: "r",
                reason: "the excitation is empty; pass at least one sample per axis".into(),
            });
        }
        for k in 0..4 {
            check_signal(R_NAMES[k], r[k], n)?;
        }
        if let Some(w) = &opts.w {
            for k in 0..4 {
                check_signal(W_NAMES[k], &w[k], n)?;
            }
        }
        match (opts.mode, &self.discrete_unb) {
            (Mode::Linear, None) => self.run::<NX4>(r, opts, Stepper::Linear),
            (Mode::Linear, Some(_)) => self.run::<{ NX4 + 2 }>(r, opts, Stepper::Linear),
            (Mode::Nonlinear, _) => self.run::<{ NX4 + 2 }>(r, opts, Stepper::Nonlinear),
        }
    }

    fn run<const N: usize>(
        &self,
        r: [&[f64]; 4],
        opts: &MachineSimOptions,
        stepper: Stepper,
    ) -> Result<MachineRecord> {
        let n = r[0].len();
        let sens = &self.cfg.sensor;
        let sigma = if opts.noise { sens.noise_rms_m } else { 0.0 };
        let noisy = sigma > 0.0;
        let mut rngs: [ChaCha8Rng; 4] = std::array::from_fn(|k| {
            let mut g = ChaCha8Rng::seed_from_u64(opts.seed);
            g.set_stream(k as u64 + 1);
            g
        });
        let lsb_v = 2.0 * sens.adc_range_v / (2f64).powi(sens.adc_bits as i32);
        let (gain, vmax, quant) = (sens.gain_v_per_m, sens.adc_range_v, sens.quantize);
        // exact linear update (N = 20 without, 22 with the unbalance oscillator)
        // transposed: adt[j] is column j of A_d, bdt[k] column k of B_d
        let mut adt = [[0.0f64; N]; N];
        let mut bdt = [[0.0f64; N]; 4];
        let disc = if N == NX4 {
            &self.discrete
        } else {
            self.discrete_unb.as_ref().unwrap_or(&self.discrete)
        };
        let nd = disc.order();
        for i in 0..nd.min(N) {
            for j in 0..nd.min(N) {
                adt[j][i] = disc.a()[(i, j)];
            }
            for k in 0..4 {
                bdt[k][i] = disc.b()[(i, k)];
            }
        }
        let nl = NlModel::new(self);
        let mut x = [0.0f64; N];
        if N > NX4 {
            // oscillator (cos, sin) of the unbalance phase at t = 0
            // phase φ at the first recorded sample t = 0, so φ − Ω T_s settle at the pre-roll start
            let phase = self.ph.unb.map(|u| u.2).unwrap_or(0.0)
                - self.ph.omega * self.ts * opts.settle_samples as f64;
            x[NX4] = phase.cos();
            x[NX4 + 1] = phase.sin();
            if nd == NX4 {
                // no unbalance configured: oscillator idle, no force
                x[NX4] = 0.0;
                x[NX4 + 1] = 0.0;
            }
        }
        let mut d = [0.0f64; 4];
        let mut st = [PidState::default(); 4];
        let i_sat = self.i_sat();
        let g0 = self.ph.pl[0].g0;
        let mk = || -> [Vec<f64>; 4] { std::array::from_fn(|_| Vec::with_capacity(n)) };
        let (mut ru, mut rr, mut ry, mut ri, mut rw) = (mk(), mk(), mk(), mk(), mk());
        let mut t = Vec::with_capacity(n);
        let mut nsat = [0usize; 4];
        let mut maxd = [0.0f64; 4];
        let settle = opts.settle_samples as i64;
        let mut idx = (n - opts.settle_samples % n) % n;
        let ts = self.ts;
        for k in -settle..n as i64 {
            let mut u = [0.0f64; 4];
            for a in 0..4 {
                let mut y = x[I_SEN + a];
                if noisy {
                    let v: f64 = StandardNormal.sample(&mut rngs[a]);
                    y += sigma * v;
                }
                if quant {
                    let v = (y * gain).clamp(-vmax, vmax);
                    y = (v / lsb_v).round() * lsb_v / gain;
                }
                let wk = opts.w.as_ref().map(|w| w[a][idx]).unwrap_or(0.0);
                let (c, cl) = self.pids[a].step(&mut st[a], wk - y);
                let raw = c + r[a][idx];
                u[a] = raw.clamp(-i_sat, i_sat);
                if k >= 0 {
                    if cl || u[a] != raw {
                        nsat[a] += 1;
                    }
                    rr[a].push(r[a][idx]);
                    ru[a].push(u[a]);
                    ry[a].push(y);
                    ri[a].push(x[I_CUR + a]);
                    rw[a].push(wk);
                }
            }
            if k >= 0 {
                t.push(k as f64 * ts);
            }
            idx += 1;
            if idx == n {
                idx = 0;
            }
            match stepper {
                Stepper::Linear => {
                    // column by column (the update vectorises across the rows)
                    let mut xn = [0.0f64; N];
                    for (col, &dk) in bdt.iter().zip(&d) {
                        for i in 0..N {
                            xn[i] += col[i] * dk;
                        }
                    }
                    for (col, &xj) in adt.iter().zip(&x) {
                        for i in 0..N {
                            xn[i] += col[i] * xj;
                        }
                    }
                    x = xn;
                }
                Stepper::Nonlinear => nl.period(&mut x, &d),
            }
            d = u;
            let disp = nl.displacements(&x);
            for a in 0..4 {
                if !disp[a].is_finite() {
                    return Err(TwinError::Diverged { sample: k });
                }
                let gap = g0 * self.ph.g_scale[a];
                if disp[a].abs() >= gap {
                    return Err(TwinError::Touchdown {
                        bearing: if a % 2 == 0 { 'A' } else { 'B' },
                        time_s: (k + 1) as f64 * ts,
                        sample: k,
                        displacement_m: disp[a],
                        gap_m: gap,
                    });
                }
                if k >= 0 {
                    maxd[a] = maxd[a].max(disp[a].abs());
                }
            }
        }
        Ok(MachineRecord {
            ts,
            t,
            r: rr,
            u: ru,
            y: ry,
            i: ri,
            w: rw,
            meta: MachineSimMeta {
                mode: opts.mode,
                seed: opts.seed,
                noise: opts.noise,
                noise_rms_m: sigma,
                samples: n,
                settle_samples: opts.settle_samples,
                fs_hz: 1.0 / ts,
                speed_rpm: self.cfg.speed_rpm,
                sync_hz: self.sync_hz(),
                unbalance: self.ph.unb.is_some(),
                saturated_fraction: std::array::from_fn(|a| nsat[a] as f64 / n as f64),
                max_abs_displacement_m: maxd,
            },
        })
    }
}

#[derive(Debug, Clone, Copy)]
enum Stepper {
    Linear,
    Nonlinear,
}

/// The nonlinear continuous model (22 states: 20 + unbalance oscillator) and RK4.
struct NlModel {
    /// Per plane: c_A, c_B, 1/m, 1/J_t, ω_b², 2ζ_bω_b, force constant k, k scale (asymmetry).
    c: [[[f64; 3]; 2]; 2],
    minv: [f64; 2],
    wb2: f64,
    dampb: f64,
    /// The force constant of each axis' magnet (asymmetry applied).
    k: [f64; 4],
    /// The air gap of each axis' magnet (asymmetry applied).
    g: [f64; 4],
    i0: f64,
    wa: f64,
    ws: f64,
    i_max: f64,
    gyro: f64,
    omega: f64,
    f0: f64,
    zu: f64,
    nsub: usize,
    h: f64,
}

impl NlModel {
    fn new(m: &Machine) -> NlModel {
        let [px, py] = m.ph.pl;
        let (f0, zu) = m.ph.unb.map(|u| (u.0, u.1)).unwrap_or((0.0, 0.0));
        // the magnets' asymmetry: each magnet's force constant and air gap realise its k_i and
        // k_x factors (see crate::machine)
        let nsub = m.cfg.simulation.substeps.max(1);
        NlModel {
            c: [[px.c_a(), px.c_b()], [py.c_a(), py.c_b()]],
            minv: [1.0 / px.m, 1.0 / px.j],
            wb2: px.wb * px.wb,
            dampb: 2.0 * px.zb * px.wb,
            k: m.ph.k_scale.map(|f| f * px.k),
            g: m.ph.g_scale.map(|f| f * px.g0),
            i0: px.i0,
            wa: px.wa,
            ws: px.ws,
            i_max: px.i_amp_max,
            gyro: m.ph.omega * m.ph.jp_over_jt,
            omega: m.ph.omega,
            f0,
            zu,
            nsub,
            h: m.ts / nsub as f64,
        }
    }

    fn displacements<const N: usize>(&self, x: &[f64; N]) -> [f64; 4] {
        std::array::from_fn(|a| {
            let (p, b) = (a / 2, a % 2);
            let c = &self.c[p][b];
            c[0] * x[3 * p] + c[1] * x[3 * p + 1] + c[2] * x[3 * p + 2]
        })
    }

    fn deriv<const N: usize>(&self, x: &[f64; N], iref: &[f64; 4]) -> [f64; N] {
        let mut dx = [0.0f64; N];
        let disp = self.displacements(x);
        let (fc, fs) = if N > NX4 {
            (self.f0 * x[NX4], self.f0 * x[NX4 + 1])
        } else {
            (0.0, 0.0)
        };
        for p in 0..2 {
            let (q0, v0) = (3 * p, 6 + 3 * p);
            let mut gen = [0.0f64; 3];
            for b in 0..2 {
                let a = 2 * p + b;
                let i = x[I_CUR + a].clamp(-self.i_max, self.i_max);
                let f = force_law(self.k[a], self.i0, self.g[a], i, disp[a]);
                for r in 0..3 {
                    gen[r] += self.c[p][b][r] * f;
                }
                dx[I_CUR + a] = self.wa * (iref[a] - x[I_CUR + a]);
                dx[I_SEN + a] = self.ws * (disp[a] - x[I_SEN + a]);
            }
            let fu = if p == 0 { fc } else { fs };
            gen[0] += fu;
            gen[1] += fu * self.zu;
            dx[q0..q0 + 3].copy_from_slice(&x[v0..v0 + 3]);
            dx[v0] = self.minv[0] * gen[0];
            dx[v0 + 1] = self.minv[1] * gen[1];
            dx[v0 + 2] = gen[2] - self.wb2 * x[q0 + 2] - self.dampb * x[v0 + 2];
        }
        dx[7] -= self.gyro * x[10];
        dx[10] += self.gyro * x[7];
        if N > NX4 {
            dx[NX4] = -self.omega * x[NX4 + 1];
            dx[NX4 + 1] = self.omega * x[NX4];
        }
        dx
    }

    /// One control period by RK4 with the references `iref` held.
    fn period<const N: usize>(&self, x: &mut [f64; N], iref: &[f64; 4]) {
        let h = self.h;
        for _ in 0..self.nsub {
            let k1 = self.deriv(x, iref);
            let x2: [f64; N] = std::array::from_fn(|i| x[i] + 0.5 * h * k1[i]);
            let k2 = self.deriv(&x2, iref);
            let x3: [f64; N] = std::array::from_fn(|i| x[i] + 0.5 * h * k2[i]);
            let k3 = self.deriv(&x3, iref);
            let x4: [f64; N] = std::array::from_fn(|i| x[i] + h * k3[i]);
            let k4 = self.deriv(&x4, iref);
            for i in 0..N {
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        for a in 0..4 {
            x[I_CUR + a] = x[I_CUR + a].clamp(-self.i_max, self.i_max);
        }
    }
}
