//! SISO discrete transfer functions in ascending powers of $q^{-1}$.
//!
//! $$ G(q) = \frac{b_0 + b_1 q^{-1} + \dots + b_{n_b} q^{-n_b}}{a_0 + a_1 q^{-1} + \dots + a_{n_a} q^{-n_a}},
//!    \qquad a_0 \ne 0, $$
//! stored with $a_0 = 1$ (the constructor divides through). An input delay is carried by leading
//! zeros of the numerator. This is the common currency for controllers given as `{ts, num, den}`.
//!
//! Padding both polynomials to the common length $L + 1$ and multiplying by $z^{L}$ gives the
//! same coefficient lists in descending powers of $z$; hence [`poles`](TransferFunction::poles)
//! and [`zeros`](TransferFunction::zeros) are [`linalg::roots`] of the padded lists (a delay is a
//! zero at infinity and is not listed; poles at the origin are).
//!
//! The state-space realisation is the controllable canonical form: with the padded
//! coefficients, $D = b_0$, $c_i = b_i - b_0 a_i$,
//! $$ A = \begin{bmatrix} -a_1 & \cdots & -a_{L-1} & -a_L \\ 1 & & & 0 \\ & \ddots & & \vdots
//!    \\ & & 1 & 0 \end{bmatrix},\quad B = e_1,\quad C = [c_1, \dots, c_L]. $$
//!
//! Series, parallel and feedback combine the polynomials directly (no pole–zero cancellation).
//!
//! # Example
//! ```
//! use ambid_core::lti::TransferFunction;
//! // G = 0.5 q^-1 / (1 - 0.5 q^-1): one-step delay, pole at z = 0.5, unit DC gain
//! let g = TransferFunction::new(vec![0.0, 0.5], vec![1.0, -0.5], 1e-3).unwrap();
//! assert!((g.freq_response(&[0.0]).unwrap()[0].re - 1.0).abs() < 1e-14);
//! assert!((g.poles().unwrap()[0].re - 0.5).abs() < 1e-14);
//! let ss = g.to_state_space().unwrap();
//! let y = ss.simulate_siso(&[1.0, 0.0, 0.0], None).unwrap();
//! assert_eq!(y, vec![0.0, 0.5, 0.25]);
//! ```

use super::interconnect::{check_same_ts, FeedbackSign};
use super::ss::{check_ts, StateSpace};
use crate::error::{check_finite, Error, Result};
use crate::linalg;
use faer::{c64, Mat};

/// A SISO discrete transfer function, numerator and denominator in ascending powers of $q^{-1}$.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferFunction {
    num: Vec<f64>,
    den: Vec<f64>,
    ts: f64,
}

/// Evaluates $\sum_k p_k x^k$ (Horner, ascending coefficients).
pub(crate) fn polyval_asc(p: &[f64], x: c64) -> c64 {
    p.iter()
        .rev()
        .fold(c64::new(0.0, 0.0), |acc, &c| acc * x + c64::new(c, 0.0))
}

/// Product of two polynomials (coefficient convolution).
pub(crate) fn poly_mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    if a.is_empty() || b.is_empty() {
        return Vec::new();
    }
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

fn pad(p: &[f64], len: usize) -> Vec<f64> {
    let mut v = p.to_vec();
    v.resize(len, 0.0);
    v
}

impl TransferFunction {
    /// Builds $G = \mathrm{num}/\mathrm{den}$ with sample time `ts` s, normalising `den[0]` to 1.
    ///
    /// Errors if a coefficient is not finite, a polynomial is empty, `den[0] == 0` (the model
    /// would not be causal) or `ts` is not positive.
    pub fn new(num: Vec<f64>, den: Vec<f64>, ts: f64) -> Result<Self> {
        check_finite("num", &num)?;
        check_finite("den", &den)?;
        check_ts(ts)?;
        if num.is_empty() {
            return Err(Error::invalid(
                "num",
                "the numerator needs at least one coefficient",
            ));
        }
        let a0 = match den.first() {
            Some(&a0) if a0 != 0.0 => a0,
            _ => return Err(Error::invalid(
                "den",
                "the leading denominator coefficient (of q^0) must be non-zero for a causal model",
            )),
        };
        Ok(Self {
            num: num.iter().map(|x| x / a0).collect(),
            den: den.iter().map(|x| x / a0).collect(),
            ts,
        })
    }

    /// Numerator coefficients (ascending powers of $q^{-1}$).
    pub fn num(&self) -> &[f64] {
        &self.num
    }
    /// Denominator coefficients (ascending powers of $q^{-1}$), `den[0] == 1`.
    pub fn den(&self) -> &[f64] {
        &self.den
    }
    /// Sample time in seconds.
    pub fn ts(&self) -> f64 {
        self.ts
    }

    fn padded(&self) -> (Vec<f64>, Vec<f64>) {
        let l = self.num.len().max(self.den.len());
        (pad(&self.num, l), pad(&self.den, l))
    }

    /// Frequency response $G(e^{j 2\pi f T_s})$ at each frequency (Hz).
    ///
    /// Errors if a frequency is not finite or the denominator vanishes there (a pole on the unit
    /// circle at that frequency).
    pub fn freq_response(&self, f_hz: &[f64]) -> Result<Vec<c64>> {
        check_finite("f_hz", f_hz)?;
        let scale: f64 = self.den.iter().map(|x| x.abs()).sum();
        f_hz.iter()
            .map(|&f| {
                let qinv = c64::from_polar(1.0, -2.0 * std::f64::consts::PI * f * self.ts);
                let d = polyval_asc(&self.den, qinv);
                if d.norm() <= 1e3 * f64::EPSILON * scale {
                    return Err(Error::numerical(
                        "freq_response",
                        format!("frequency {f} Hz coincides with a pole of the transfer function"),
                    ));
                }
                Ok(polyval_asc(&self.num, qinv) / d)
            })
            .collect()
    }

    /// Poles in $z$ (roots of the padded denominator), including poles at the origin.
    pub fn poles(&self) -> Result<Vec<c64>> {
        let (_, d) = self.padded();
        linalg::roots(&d)
    }

    /// Finite zeros in $z$ (roots of the padded numerator). Errors for the zero transfer function.
    pub fn zeros(&self) -> Result<Vec<c64>> {
        let (n, _) = self.padded();
        linalg::roots(&n)
    }

    /// Controllable canonical state-space realisation (see the module docs), of order
    /// $\max(n_a, n_b)$.
    pub fn to_state_space(&self) -> Result<StateSpace> {
        let (b, a) = self.padded();
        let l = a.len() - 1;
        let b0 = b[0];
        let am = Mat::from_fn(l, l, |i, j| {
            if i == 0 {
                -a[j + 1]
            } else if i == j + 1 {
                1.0
            } else {
                0.0
            }
        });
        let bm = Mat::from_fn(l, 1, |i, _| if i == 0 { 1.0 } else { 0.0 });
        let cm = Mat::from_fn(1, l, |_, j| b[j + 1] - b0 * a[j + 1]);
        let dm = Mat::from_fn(1, 1, |_, _| b0);
        StateSpace::discrete(am, bm, cm, dm, self.ts)
    }

    /// Transfer function of a discrete SISO state-space model via
    /// [`StateSpace::tf_coefficients`] (numerator and denominator of length `order + 1`).
    pub fn from_state_space(ss: &StateSpace) -> Result<Self> {
        let ts = ss.ts().ok_or_else(|| {
            Error::TimeDomain(
                "TransferFunction is discrete-time; discretise the continuous model first".into(),
            )
        })?;
        let (num, den) = ss.tf_coefficients()?;
        Self::new(num, den, ts)
    }

    /// Simulates $a(q) y = b(q) u$ from rest (zero initial conditions).
    pub fn simulate(&self, u: &[f64]) -> Result<Vec<f64>> {
        check_finite("u", u)?;
        let mut y = vec![0.0; u.len()];
        for k in 0..u.len() {
            let mut acc = 0.0;
            for (i, b) in self.num.iter().enumerate().take(k + 1) {
                acc += b * u[k - i];
            }
            for (i, a) in self.den.iter().enumerate().skip(1).take(k) {
                acc -= a * y[k - i];
            }
            y[k] = acc;
        }
        Ok(y)
    }
    /// Series connection $G_{\text{self}}\, G_{\text{other}}$: numerators and denominators
    /// multiplied (no cancellation is attempted).
    pub fn series(&self, other: &TransferFunction) -> Result<Self> {
        check_same_ts(Some(self.ts), Some(other.ts))?;
        Self::new(
            poly_mul(&self.num, &other.num),
            poly_mul(&self.den, &other.den),
            self.ts,
        )
    }

    /// Parallel connection $G_1 + G_2 = (b_1 a_2 + b_2 a_1) / (a_1 a_2)$.
    pub fn parallel(&self, other: &TransferFunction) -> Result<Self> {
        check_same_ts(Some(self.ts), Some(other.ts))?;
        Self::new(
            poly_add(
                &poly_mul(&self.num, &other.den),
                &poly_mul(&other.num, &self.den),
            ),
            poly_mul(&self.den, &other.den),
            self.ts,
        )
    }

    /// Negative feedback $G / (1 + G K)$ with `k` in the feedback path.
    pub fn feedback(&self, k: &TransferFunction) -> Result<Self> {
        self.feedback_with_sign(k, FeedbackSign::Negative)
    }

    /// Feedback with sign $\sigma$:
    /// $G / (1 - \sigma G K) = b_G a_K / (a_G a_K - \sigma b_G b_K)$.
    /// Errors if the closed loop is not causal (its $q^0$ denominator coefficient vanishes).
    pub fn feedback_with_sign(&self, k: &TransferFunction, sign: FeedbackSign) -> Result<Self> {
        check_same_ts(Some(self.ts), Some(k.ts))?;
        let s = sign.value();
        let bb: Vec<f64> = poly_mul(&self.num, &k.num).iter().map(|x| -s * x).collect();
        let den = poly_add(&poly_mul(&self.den, &k.den), &bb);
        Self::new(poly_mul(&self.num, &k.den), den, self.ts).map_err(|e| match e {
            Error::InvalidArgument { name: "den", .. } => Error::numerical(
                "TransferFunction::feedback",
                "1 - sign·G·K vanishes at q^-1 = 0: the loop is not well posed",
            ),
            other => other,
        })
    }
}

/// Sum of two polynomials with ascending coefficients.
pub(crate) fn poly_add(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len().max(b.len())];
    for (i, x) in a.iter().enumerate() {
        out[i] += x;
    }
    for (i, x) in b.iter().enumerate() {
        out[i] += x;
    }
    out
}
