//! PID controllers: a continuous description and its discrete equivalent.
//!
//! A [`PidSpec`] describes the filtered PID
//! $$ C(s) = \frac{1}{1 + s/\omega_l}\left(K_p + \frac{K_i}{s} + \frac{K_d\, s}{1 + s/\omega_d}\right),
//!    \qquad \omega_d = 2\pi f_d,\ \omega_l = 2\pi f_l, $$
//! acting on the error $e = w - y$ (metres) and producing the controller output $u$ (amperes),
//! $u = C(q)\,(w - y)$ as in `docs/conventions.md`. $K_p$ is in A/m, $K_i$ in A/(m·s) ($0$: no
//! integrator), $K_d$ in A·s/m ($0$: no derivative), $f_d$ and $f_l$ in Hz. A pure derivative
//! $K_d s$ is improper and has no discrete equivalent, so $K_d \ne 0$ needs a finite $f_d$; the
//! output low-pass is optional.
//!
//! # Realisation
//! The continuous model ([`PidSpec::continuous_state_space`]) keeps only the parts that are
//! present, in the order integrator, derivative filter, low-pass. Its states are scaled like the
//! error (metres; the integrator state like the running sum of the error over samples) and one
//! gain $G$ carries the amperes. This keeps $A$ and $B$ of the order of the corner frequencies
//! and $1/T_s$, so the scaling and squaring of [`StateSpace::c2d_zoh`] and the solves of
//! [`StateSpace::c2d_tustin`] and of the frequency response stay accurate. With
//! $G = K_p + K_d\omega_d$ (or $K_i T_s$ when both vanish), $\kappa_i = K_i T_s/G$,
//! $\kappa_d = K_d\omega_d/G$ and $\kappa_0 = (K_p + K_d\omega_d)/G$:
//! $$ \dot x_I = e/T_s,\qquad \dot x_D = -\omega_d x_D + \omega_d e,\qquad
//!    v = G\,(\kappa_i x_I - \kappa_d x_D + \kappa_0 e), $$
//! since $K_d s/(1+s/\omega_d) = K_d\omega_d - K_d\omega_d\,\omega_d/(s+\omega_d)$; with the
//! low-pass $\dot x_L = -\omega_l x_L + \omega_l v/G$ and $u = G x_L$, otherwise $u = v$.
//!
//! # Discretisation
//! [`Discretisation::Tustin`] substitutes $s = \frac{2}{T}\frac{z-1}{z+1}$ with $T = T_s$
//! ([`StateSpace::c2d_tustin`]); [`Discretisation::TustinPrewarp`] uses
//! $T = 2\tan(\omega_p T_s/2)/\omega_p$ so that the response is exact at $f_p$;
//! [`Discretisation::Zoh`] is the step-invariant equivalent ([`StateSpace::c2d_zoh`]).
//! With $\alpha = 2/T$ the Tustin parts are
//! * integrator: $K_i \frac{T}{2}\frac{1 + q^{-1}}{1 - q^{-1}}$ (a pole at $z = 1$, so the
//!   response diverges at DC);
//! * filtered derivative: $g\,\frac{1 - q^{-1}}{1 - p\,q^{-1}}$,
//!   $p = \frac{\alpha - \omega_d}{\alpha + \omega_d}$,
//!   $g = \frac{K_d\omega_d\alpha}{\alpha + \omega_d}$; at the Nyquist frequency ($q^{-1} = -1$)
//!   it equals $2g/(1+p) = K_d\omega_d$, the high-frequency gain of the continuous part;
//! * low-pass: $h\,\frac{1 + q^{-1}}{1 - r\,q^{-1}}$, $r = \frac{\alpha - \omega_l}{\alpha +
//!   \omega_l}$, $h = \frac{\omega_l}{\alpha + \omega_l}$; zero at the Nyquist frequency.
//!
//! Every Tustin response satisfies $C_d(e^{j\omega T_s}) = C\!\left(j\tfrac{2}{T}
//! \tan\tfrac{\omega T_s}{2}\right)$. This is exactly how the twin (`ambid-twin`) discretises its
//! controller, so a `PidSpec` with the twin's gains reproduces `Twin::controller_frf`.
//!
//! All corner frequencies must lie below the Nyquist frequency $f_s/2 = 1/(2T_s)$.
//!
//! # Computation delay
//! `delay_samples` $= d$ appends $q^{-d}$ to the discrete controller. In ambid's convention the
//! one-sample computation delay belongs to the **plant** (the recorded controller output $u(k)$ is
//! computed from $y(k)$ and reaches the amplifier one sample later), so the default is $d = 0$.
//! Set $d > 0$ only when the recorded $u$ is taken *after* the delay (e.g. a rig that logs the
//! value written to the DAC); the identified plant then excludes those $d$ samples.
//!
//! # Example
//! ```
//! use ambid_core::lti::pid::{Discretisation, PidSpec};
//! let ts = 1.0 / 20e3;
//! let kp = 21_000.0;
//! let pid = PidSpec::new(kp, kp * 2.0 * std::f64::consts::PI * 5.0, 14.0, ts)
//!     .with_derivative_cutoff_hz(4e3)
//!     .with_lowpass_hz(5e3)
//!     .with_method(Discretisation::Tustin);
//! let ss = pid.state_space().unwrap();
//! assert_eq!((ss.order(), ss.ts()), (3, Some(ts)));
//! // Tustin: the discrete response equals the continuous one at the warped frequency
//! let f = 1234.0;
//! let fw = (std::f64::consts::PI * f * ts).tan() / (std::f64::consts::PI * ts);
//! let cd = pid.freq_response(&[f]).unwrap()[0];
//! let cc = pid.continuous_freq_response(&[fw]).unwrap()[0];
//! assert!((cd - cc).norm() < 1e-12 * cc.norm());
//! // a pure derivative is rejected with a message that says what to add
//! let err = PidSpec::new(kp, 0.0, 14.0, ts).state_space().unwrap_err();
//! assert!(err.to_string().contains("derivative_cutoff_hz"));
//! ```

use super::ss::StateSpace;
use super::tf::TransferFunction;
use crate::error::{check_finite, Error, Result};
use faer::{c64, Mat};
use std::f64::consts::PI;
use std::fmt;

/// How a [`PidSpec`] is turned into a discrete controller.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Discretisation {
    /// Bilinear transform $s = \frac{2}{T_s}\frac{z-1}{z+1}$ (the default; what the twin uses).
    #[default]
    Tustin,
    /// Bilinear transform prewarped so that the response is exact at `f_hz` (in
    /// $(0, f_s/2)$).
    TustinPrewarp {
        /// Prewarping frequency in Hz.
        f_hz: f64,
    },
    /// Zero-order-hold (step-invariant) equivalent.
    Zoh,
}

impl fmt::Display for Discretisation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Discretisation::Tustin => f.write_str("Tustin"),
            Discretisation::TustinPrewarp { f_hz } => write!(f, "Tustin prewarped at {f_hz} Hz"),
            Discretisation::Zoh => f.write_str("ZOH"),
        }
    }
}

/// A continuous filtered PID, its sample time, discretisation and computation delay (see the
/// [module docs](self) for the formulas).
///
/// Build it with [`PidSpec::new`] and the `with_*` methods, or fill the public fields directly.
/// Nothing is checked on construction; [`validate`](PidSpec::validate) (called by every
/// conversion) checks all fields and says what to change.
///
/// # Example
/// ```
/// use ambid_core::lti::PidSpec;
/// // pure P controller: the gain at every frequency
/// let p = PidSpec::new(2.0, 0.0, 0.0, 1e-4);
/// let h = p.freq_response(&[0.0, 1000.0, 5000.0]).unwrap();
/// assert!(h.iter().all(|c| (c.re - 2.0).abs() < 1e-15 && c.im.abs() < 1e-15));
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct PidSpec {
    /// Proportional gain $K_p$ \[A/m\], $\ge 0$.
    pub kp: f64,
    /// Integral gain $K_i$ \[A/(m·s)\], $\ge 0$; $0$ means no integrator.
    pub ki: f64,
    /// Derivative gain $K_d$ \[A·s/m\], $\ge 0$; $0$ means no derivative.
    pub kd: f64,
    /// Derivative filter corner $f_d = \omega_d/2\pi$ \[Hz\]. Required (finite, below Nyquist)
    /// when $K_d \ne 0$; `None` or $+\infty$ means "no filter", which is only allowed for
    /// $K_d = 0$.
    pub derivative_cutoff_hz: Option<f64>,
    /// Output low-pass corner $f_l = \omega_l/2\pi$ \[Hz\]; `None` or $+\infty$: no low-pass.
    pub lowpass_hz: Option<f64>,
    /// Sample time $T_s$ \[s\].
    pub ts: f64,
    /// Discretisation method.
    pub method: Discretisation,
    /// Computation delay $d$ in samples, appended as $q^{-d}$; default 0 because ambid puts the
    /// computation delay in the plant (see the [module docs](self#computation-delay)). At most
    /// [`PidSpec::MAX_DELAY_SAMPLES`].
    pub delay_samples: usize,
}

fn nyquist_hint(ts: f64) -> String {
    format!(
        "the Nyquist frequency fs/2 = {} Hz (ts = {ts:e} s)",
        0.5 / ts
    )
}

impl PidSpec {
    /// The largest accepted `delay_samples`.
    pub const MAX_DELAY_SAMPLES: usize = 64;

    /// $K_p + K_i/s + K_d s$ sampled every `ts` s, with no filters, Tustin and no delay.
    /// Add the derivative filter (required when `kd != 0`) with
    /// [`with_derivative_cutoff_hz`](Self::with_derivative_cutoff_hz).
    pub fn new(kp: f64, ki: f64, kd: f64, ts: f64) -> Self {
        Self {
            kp,
            ki,
            kd,
            derivative_cutoff_hz: None,
            lowpass_hz: None,
            ts,
            method: Discretisation::Tustin,
            delay_samples: 0,
        }
    }

    /// Sets the derivative filter corner $f_d$ \[Hz\].
    pub fn with_derivative_cutoff_hz(mut self, f_hz: f64) -> Self {
        self.derivative_cutoff_hz = Some(f_hz);
        self
    }

    /// Sets the output low-pass corner $f_l$ \[Hz\].
    pub fn with_lowpass_hz(mut self, f_hz: f64) -> Self {
        self.lowpass_hz = Some(f_hz);
        self
    }

    /// Sets the discretisation method.
    pub fn with_method(mut self, method: Discretisation) -> Self {
        self.method = method;
        self
    }

    /// Sets the computation delay in samples.
    pub fn with_delay_samples(mut self, d: usize) -> Self {
        self.delay_samples = d;
        self
    }

    /// Sampling frequency $1/T_s$ \[Hz\].
    pub fn fs_hz(&self) -> f64 {
        1.0 / self.ts
    }

    /// The derivative corner in rad/s when the derivative part is present.
    fn wd(&self) -> Option<f64> {
        (self.kd != 0.0)
            .then_some(self.derivative_cutoff_hz)
            .flatten()
            .map(|f| 2.0 * PI * f)
    }

    /// The low-pass corner in rad/s when present (`+inf` counts as absent).
    fn wl(&self) -> Option<f64> {
        self.lowpass_hz
            .filter(|f| *f != f64::INFINITY)
            .map(|f| 2.0 * PI * f)
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the field when: `ts` is not positive and finite; a gain
    /// is negative or not finite, or all three are zero; `kd != 0` without a finite
    /// `derivative_cutoff_hz`; a corner or the prewarping frequency is not positive or not below
    /// the Nyquist frequency $1/(2T_s)$; `delay_samples` exceeds
    /// [`MAX_DELAY_SAMPLES`](Self::MAX_DELAY_SAMPLES).
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::PidSpec;
    /// let pid = PidSpec::new(1.0, 0.0, 1e-3, 1e-4).with_derivative_cutoff_hz(6e3);
    /// let msg = pid.validate().unwrap_err().to_string();
    /// assert!(msg.contains("derivative_cutoff_hz") && msg.contains("Nyquist"));
    /// ```
    pub fn validate(&self) -> Result<()> {
        let ts = self.ts;
        if !(ts.is_finite() && ts > 0.0) {
            return Err(Error::invalid(
                "ts",
                format!("the sample time must be positive and finite, got {ts}"),
            ));
        }
        for (name, v) in [("kp", self.kp), ("ki", self.ki), ("kd", self.kd)] {
            if !v.is_finite() {
                return Err(Error::invalid(
                    name,
                    format!("the gain must be finite, got {v}"),
                ));
            }
            if v < 0.0 {
                return Err(Error::invalid(
                    name,
                    format!(
                        "the gain must be >= 0, got {v}: ambid's controller acts on the error \
                         w - y (u = C(q)(w - y), see docs/conventions.md), so an AMB PID has \
                         non-negative gains; if your controller is written for y - w, give the \
                         magnitudes of its gains"
                    ),
                ));
            }
        }
        if self.kp == 0.0 && self.ki == 0.0 && self.kd == 0.0 {
            return Err(Error::invalid(
                "kp",
                "kp, ki and kd are all zero, so the controller would be C = 0; give at least one \
                 non-zero gain",
            ));
        }
        let nyq = 0.5 / ts;
        let corner = |name: &'static str, f: f64, what: &str| -> Result<()> {
            if f.is_nan() || f <= 0.0 {
                return Err(Error::invalid(
                    name,
                    format!("the {what} must be a positive frequency in Hz, got {f}"),
                ));
            }
            if f >= nyq {
                return Err(Error::invalid(
                    name,
                    format!(
                        "the {what} {f} Hz is not below {}; a discrete controller cannot \
                         represent it: lower the corner or raise the sampling rate",
                        nyquist_hint(ts)
                    ),
                ));
            }
            Ok(())
        };
        match self.derivative_cutoff_hz {
            Some(f) if f != f64::INFINITY => {
                corner("derivative_cutoff_hz", f, "derivative filter corner")?
            }
            _ if self.kd != 0.0 => {
                return Err(Error::invalid(
                    "derivative_cutoff_hz",
                    format!(
                        "kd = {} needs a finite derivative filter corner: a pure derivative \
                         K_d s is improper and has no discrete equivalent; give \
                         derivative_cutoff_hz = omega_d/2pi in Hz, below {}",
                        self.kd,
                        nyquist_hint(ts)
                    ),
                ))
            }
            _ => {}
        }
        if let Some(f) = self.lowpass_hz {
            if f != f64::INFINITY {
                corner("lowpass_hz", f, "low-pass corner")?;
            }
        }
        if let Discretisation::TustinPrewarp { f_hz } = self.method {
            if !f_hz.is_finite() {
                return Err(Error::invalid(
                    "prewarp_hz",
                    format!("the prewarping frequency must be finite, got {f_hz}"),
                ));
            }
            corner("prewarp_hz", f_hz, "prewarping frequency")?;
        }
        if self.delay_samples > Self::MAX_DELAY_SAMPLES {
            return Err(Error::invalid(
                "delay_samples",
                format!(
                    "{} samples is more than the {} accepted; a computation delay is a few \
                     samples at most (and 0 in ambid's convention, where the delay belongs to \
                     the plant)",
                    self.delay_samples,
                    Self::MAX_DELAY_SAMPLES
                ),
            ));
        }
        Ok(())
    }

    /// The continuous controller $C(s)$ (without the computation delay) as a state-space model,
    /// realised as in the [module docs](self#realisation). Its order is the number of parts
    /// present (integrator, derivative filter, low-pass), 0 for a pure P controller.
    ///
    /// # Errors
    /// As [`validate`](Self::validate).
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::PidSpec;
    /// let pi = PidSpec::new(10.0, 100.0, 0.0, 1e-3).with_lowpass_hz(50.0);
    /// let c = pi.continuous_state_space().unwrap();
    /// assert_eq!((c.order(), c.ts()), (2, None));
    /// ```
    pub fn continuous_state_space(&self) -> Result<StateSpace> {
        self.validate()?;
        let (ki, kp, kd) = (self.ki, self.kp, self.kd);
        let wd = self.wd();
        let wl = self.wl();
        let kdwd = wd.map_or(0.0, |w| kd * w);
        let g = if kp + kdwd > 0.0 {
            kp + kdwd
        } else {
            ki * self.ts
        };
        let ii = (ki != 0.0).then_some(0);
        let id = wd.map(|_| usize::from(ii.is_some()));
        let n_pid = usize::from(ii.is_some()) + usize::from(id.is_some());
        let il = wl.map(|_| n_pid);
        let n = n_pid + usize::from(il.is_some());
        // v/G = cv x + k0 e: the PID sum in units of the error
        let k0 = (kp + kdwd) / g;
        let mut a = Mat::<f64>::zeros(n, n);
        let mut b = Mat::<f64>::zeros(n, 1);
        let mut cv = Mat::<f64>::zeros(1, n);
        if let Some(i) = ii {
            b[(i, 0)] = 1.0 / self.ts;
            cv[(0, i)] = ki * self.ts / g;
        }
        if let (Some(i), Some(w)) = (id, wd) {
            a[(i, i)] = -w;
            b[(i, 0)] = w;
            cv[(0, i)] = -kdwd / g;
        }
        let (c, d) = match (il, wl) {
            (Some(l), Some(w)) => {
                for j in 0..n_pid {
                    a[(l, j)] = w * cv[(0, j)];
                }
                a[(l, l)] = -w;
                b[(l, 0)] = w * k0;
                let c = Mat::from_fn(1, n, |_, j| if j == l { g } else { 0.0 });
                (c, 0.0)
            }
            _ => (Mat::from_fn(1, n, |_, j| g * cv[(0, j)]), kp + kdwd),
        };
        StateSpace::continuous(a, b, c, Mat::from_fn(1, 1, |_, _| d))
    }

    /// The discrete controller without the computation delay.
    fn discrete_core(&self) -> Result<StateSpace> {
        let cont = self.continuous_state_space()?;
        if cont.order() == 0 {
            // nothing to discretise (and no 0×0 solves)
            return StateSpace::discrete(
                Mat::zeros(0, 0),
                Mat::zeros(0, 1),
                Mat::zeros(1, 0),
                cont.d().to_owned(),
                self.ts,
            );
        }
        match self.method {
            Discretisation::Tustin => cont.c2d_tustin(self.ts, None),
            Discretisation::TustinPrewarp { f_hz } => cont.c2d_tustin(self.ts, Some(f_hz)),
            Discretisation::Zoh => cont.c2d_zoh(self.ts),
        }
    }

    /// The discrete controller $C(q)\,q^{-d}$ with sample time `ts`: input $e = w - y$ \[m\],
    /// output $u$ \[A\]. The delay states (if any) follow the controller states.
    ///
    /// # Errors
    /// As [`validate`](Self::validate); [`Error::Numerical`] if the discretisation fails (not
    /// expected for a valid specification).
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::PidSpec;
    /// let p = PidSpec::new(3.0, 0.0, 0.0, 1e-3).with_delay_samples(2);
    /// let y = p.state_space().unwrap().simulate_siso(&[1.0, 0.0, 0.0, 0.0], None).unwrap();
    /// assert_eq!(y, vec![0.0, 0.0, 3.0, 0.0]);
    /// ```
    pub fn state_space(&self) -> Result<StateSpace> {
        let core = self.discrete_core()?;
        let d = self.delay_samples;
        if d == 0 {
            return Ok(core);
        }
        let a = Mat::from_fn(d, d, |i, j| f64::from(u8::from(i == j + 1)));
        let b = Mat::from_fn(d, 1, |i, _| f64::from(u8::from(i == 0)));
        let c = Mat::from_fn(1, d, |_, j| f64::from(u8::from(j + 1 == d)));
        let delay = StateSpace::discrete(a, b, c, Mat::zeros(1, 1), self.ts)?;
        core.series(&delay)
    }

    /// The discrete controller as a transfer function in ascending powers of $q^{-1}$; the
    /// computation delay appears as $d$ leading zeros of the numerator.
    ///
    /// # Errors
    /// As [`state_space`](Self::state_space).
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::PidSpec;
    /// // Tustin PI: Kp + Ki T/2 (1 + q^-1)/(1 - q^-1)
    /// let tf = PidSpec::new(2.0, 100.0, 0.0, 1e-3).transfer_function().unwrap();
    /// let (num, den) = (tf.num(), tf.den());
    /// assert!((num[0] - 2.05).abs() < 1e-12 && (num[1] + 1.95).abs() < 1e-12);
    /// assert!((den[0] - 1.0).abs() < 1e-15 && (den[1] + 1.0).abs() < 1e-12);
    /// ```
    pub fn transfer_function(&self) -> Result<TransferFunction> {
        let core = self.discrete_core()?;
        let (num, den) = if core.order() == 0 {
            (vec![core.d()[(0, 0)]], vec![1.0])
        } else {
            core.tf_coefficients()?
        };
        let mut delayed = vec![0.0; self.delay_samples];
        delayed.extend(num);
        TransferFunction::new(delayed, den, self.ts)
    }

    /// Frequency response of the discrete controller, $C(e^{j2\pi fT_s})\,e^{-j2\pi f d T_s}$,
    /// at each frequency (Hz).
    ///
    /// # Errors
    /// As [`validate`](Self::validate); [`Error::NonFinite`] for a non-finite frequency;
    /// [`Error::Numerical`] at a pole on the unit circle (DC, for a controller with an
    /// integrator).
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::PidSpec;
    /// let pi = PidSpec::new(2.0, 100.0, 0.0, 1e-3);
    /// assert!(pi.freq_response(&[0.0]).is_err()); // the integrator's pole at z = 1
    /// ```
    pub fn freq_response(&self, f_hz: &[f64]) -> Result<Vec<c64>> {
        check_finite("f_hz", f_hz)?;
        let core = self.discrete_core()?;
        let h = core.freq_response_siso(f_hz)?;
        let d = self.delay_samples as f64;
        Ok(h.into_iter()
            .zip(f_hz)
            .map(|(h, &f)| {
                if d == 0.0 {
                    h
                } else {
                    h * c64::from_polar(1.0, -2.0 * PI * f * d * self.ts)
                }
            })
            .collect())
    }

    /// Frequency response of the continuous controller $C(j2\pi f)$ (no computation delay),
    /// evaluated from the formula in the [module docs](self), at each frequency (Hz).
    ///
    /// # Errors
    /// As [`validate`](Self::validate); [`Error::NonFinite`] for a non-finite frequency;
    /// [`Error::Numerical`] at $f = 0$ with an integrator.
    ///
    /// # Example
    /// ```
    /// use ambid_core::lti::PidSpec;
    /// let pd = PidSpec::new(1.0, 0.0, 1e-3, 1e-4).with_derivative_cutoff_hz(1e3);
    /// let c = pd.continuous_freq_response(&[1e3]).unwrap()[0];
    /// // Kp + Kd·jω/(1 + j) at ω = ω_d
    /// let wd = 2.0 * std::f64::consts::PI * 1e3;
    /// assert!((c.re - (1.0 + 1e-3 * wd / 2.0)).abs() < 1e-12);
    /// assert!((c.im - 1e-3 * wd / 2.0).abs() < 1e-12);
    /// ```
    pub fn continuous_freq_response(&self, f_hz: &[f64]) -> Result<Vec<c64>> {
        self.validate()?;
        check_finite("f_hz", f_hz)?;
        let one = c64::new(1.0, 0.0);
        f_hz.iter()
            .map(|&f| {
                let s = c64::new(0.0, 2.0 * PI * f);
                let mut v = c64::new(self.kp, 0.0);
                if self.ki != 0.0 {
                    if f == 0.0 {
                        return Err(Error::numerical(
                            "continuous_freq_response",
                            "the integrator has a pole at f = 0 Hz; evaluate at f > 0",
                        ));
                    }
                    v += c64::new(self.ki, 0.0) / s;
                }
                if let Some(wd) = self.wd() {
                    v += s * self.kd / (one + s / wd);
                }
                if let Some(wl) = self.wl() {
                    v /= one + s / wl;
                }
                Ok(v)
            })
            .collect()
    }
}

impl fmt::Display for PidSpec {
    /// One line: gains, corners, sampling, method and delay.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "PID kp = {} A/m, ki = {} A/(m s)", self.kp, self.ki)?;
        if self.kd != 0.0 {
            write!(f, ", kd = {} A s/m", self.kd)?;
        }
        if let (Some(fd), true) = (self.derivative_cutoff_hz, self.kd != 0.0) {
            write!(f, ", derivative filter {fd} Hz")?;
        }
        match self.lowpass_hz {
            Some(fl) if fl != f64::INFINITY => write!(f, ", low-pass {fl} Hz")?,
            _ => {}
        }
        write!(f, ", fs = {} Hz, {}", self.fs_hz(), self.method)?;
        if self.delay_samples != 0 {
            write!(f, ", delay {} samples", self.delay_samples)?;
        }
        Ok(())
    }
}
