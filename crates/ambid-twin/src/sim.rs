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
//!   output limit and slew limit; the continuous part advances with classical RK4 at
//!   `simulation.substeps` (≥ 10) steps per control period.
//!
//! The digital controller, its clamp and the DAC clamp are the same in both modes (software).
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
//! If $|x_A|$ or $|x_B|$ reaches the air gap $g_0$ (checked at every RK4 substep in nonlinear mode,
//! at every sample in linear mode) the simulation stops with [`TwinError::Touchdown`].
//!
//! # Pre-roll
//! `settle_samples` control periods run before recording starts, with $r$ and $w$ taken
//! cyclically so that the pre-roll ends exactly where sample 0 begins: for a periodic excitation
//! whose period divides `r.len()` this puts the loop into periodic steady state.

use crate::config::Mode;
use crate::error::{Result, TwinError};
use crate::model::{force_law, PidState, NX};
use crate::twin::Twin;
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
    /// RK4 substeps per period (nonlinear mode), 0 for the exact linear update.
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
            let xa = x[0] - self.a * x[1] + self.phi_a * x[2];
            let xb = x[0] + self.b * x[1] + self.phi_b * x[2];
            if !(xa.abs() < self.g0 && xb.abs() < self.g0) {
                return Err((s, xa, xb));
            }
        }
        Ok(flags)
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
        let nsub = self.cfg.simulation.substeps;
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
                match nl.period(&mut x, da, db, h, nsub) {
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
