//! Frequency-response data: a SISO complex response on a grid of frequencies in Hz, with an
//! optional variance $\sigma^2_k = \mathrm{E}\,|\hat G(f_k) - G(f_k)|^2$.
//!
//! Algebra acts pointwise on a common grid. Variances propagate to first order (independent
//! operands, circular complex errors): for $Z = \phi(X, Y)$,
//! $\sigma_Z^2 \approx |\partial\phi/\partial X|^2 \sigma_X^2 + |\partial\phi/\partial Y|^2 \sigma_Y^2$, so
//!
//! | operation | value | variance |
//! |-----------|-------|----------|
//! | series    | $XY$ | $\lvert Y\rvert^2\sigma_X^2 + \lvert X\rvert^2\sigma_Y^2$ |
//! | parallel  | $X+Y$ | $\sigma_X^2 + \sigma_Y^2$ |
//! | divide    | $X/Y$ | $\sigma_X^2/\lvert Y\rvert^2 + \lvert X\rvert^2\sigma_Y^2/\lvert Y\rvert^4$ |
//! | inverse   | $1/X$ | $\sigma_X^2 / \lvert X\rvert^4$ |
//! | feedback  | $X/(1 - \sigma XY)$ | $\sigma_X^2/\lvert 1-\sigma XY\rvert^4 + \lvert X\rvert^4\sigma_Y^2/\lvert 1-\sigma XY\rvert^4$ |
//!
//! A missing variance counts as zero when the other operand has one; the result has no variance
//! only if neither operand has one.
//!
//! # Example
//! ```
//! use ambid_core::lti::{Frd, StateSpace};
//! use faer::mat;
//! let g = StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[0.5]], mat![[0.0]], 1e-3).unwrap();
//! let f = [0.0, 100.0, 250.0];
//! let frd = Frd::from_model(&g, &f).unwrap();
//! assert!((frd.values()[0].re - 1.0).abs() < 1e-14);
//! // unity negative feedback: 0.5/(z - 0.5) / (1 + 0.5/(z - 0.5)) = 0.5/z; |.| = 0.5 everywhere
//! let t = frd.feedback(&Frd::constant(&f, 1.0, Some(1e-3)).unwrap()).unwrap();
//! assert!(t.magnitude().iter().all(|m| (m - 0.5).abs() < 1e-14));
//! ```

use super::interconnect::{check_same_ts, FeedbackSign};
use super::ss::StateSpace;
use crate::error::{check_finite, Error, Result};
use faer::c64;

/// SISO frequency-response data.
#[derive(Debug, Clone, PartialEq)]
pub struct Frd {
    f_hz: Vec<f64>,
    values: Vec<c64>,
    variance: Option<Vec<f64>>,
    ts: Option<f64>,
}

impl Frd {
    /// Builds frequency-response data. `f_hz` must be finite, non-negative and strictly
    /// increasing; `values` finite and of the same length; `variance` (if any) finite, $\ge 0$ and
    /// of the same length; `ts` positive if given.
    pub fn new(
        f_hz: Vec<f64>,
        values: Vec<c64>,
        variance: Option<Vec<f64>>,
        ts: Option<f64>,
    ) -> Result<Self> {
        check_finite("f_hz", &f_hz)?;
        if let Some(i) = f_hz.iter().position(|f| *f < 0.0) {
            return Err(Error::invalid(
                "f_hz",
                format!("frequencies must be non-negative; f_hz[{i}] = {}", f_hz[i]),
            ));
        }
        if let Some(i) = f_hz.windows(2).position(|w| w[1] <= w[0]) {
            return Err(Error::invalid(
                "f_hz",
                format!(
                    "frequencies must be strictly increasing; f_hz[{}] ≤ f_hz[{i}]",
                    i + 1
                ),
            ));
        }
        if values.len() != f_hz.len() {
            return Err(Error::DimensionMismatch {
                context: "Frd values",
                expected: f_hz.len().to_string(),
                got: values.len().to_string(),
            });
        }
        if let Some(index) = values
            .iter()
            .position(|z| !(z.re.is_finite() && z.im.is_finite()))
        {
            return Err(Error::NonFinite {
                what: "values",
                index,
            });
        }
        if let Some(v) = &variance {
            if v.len() != f_hz.len() {
                return Err(Error::DimensionMismatch {
                    context: "Frd variance",
                    expected: f_hz.len().to_string(),
                    got: v.len().to_string(),
                });
            }
            check_finite("variance", v)?;
            if let Some(i) = v.iter().position(|x| *x < 0.0) {
                return Err(Error::invalid(
                    "variance",
                    format!("variances must be non-negative; variance[{i}] = {}", v[i]),
                ));
            }
        }
        if let Some(t) = ts {
            super::ss::check_ts(t)?;
        }
        Ok(Self {
            f_hz,
            values,
            variance,
            ts,
        })
    }

    /// The response of a SISO state-space model at `f_hz` (no variance; `ts` from the model).
    pub fn from_model(model: &StateSpace, f_hz: &[f64]) -> Result<Self> {
        let v = model.freq_response_siso(f_hz)?;
        Self::new(f_hz.to_vec(), v, None, model.ts())
    }

    /// The response of a discrete transfer function at `f_hz` (no variance).
    pub fn from_transfer_function(tf: &super::TransferFunction, f_hz: &[f64]) -> Result<Self> {
        let v = tf.freq_response(f_hz)?;
        Self::new(f_hz.to_vec(), v, None, Some(tf.ts()))
    }

    /// A constant (static gain) response on the grid `f_hz`.
    pub fn constant(f_hz: &[f64], gain: f64, ts: Option<f64>) -> Result<Self> {
        Self::new(
            f_hz.to_vec(),
            vec![c64::new(gain, 0.0); f_hz.len()],
            None,
            ts,
        )
    }

    /// Frequencies in Hz.
    pub fn f_hz(&self) -> &[f64] {
        &self.f_hz
    }
    /// Complex response values.
    pub fn values(&self) -> &[c64] {
        &self.values
    }
    /// Variance $\mathrm{E}|\hat G - G|^2$ per frequency, if known.
    pub fn variance(&self) -> Option<&[f64]> {
        self.variance.as_deref()
    }
    /// Sample time of the underlying discrete system, `None` if continuous.
    pub fn ts(&self) -> Option<f64> {
        self.ts
    }
    /// Number of frequencies.
    pub fn len(&self) -> usize {
        self.f_hz.len()
    }
    /// `true` if there are no frequencies.
    pub fn is_empty(&self) -> bool {
        self.f_hz.is_empty()
    }
    /// Magnitude $|G|$.
    pub fn magnitude(&self) -> Vec<f64> {
        self.values.iter().map(|z| z.norm()).collect()
    }
    /// Magnitude in dB, $20 \log_{10} |G|$.
    pub fn magnitude_db(&self) -> Vec<f64> {
        self.values
            .iter()
            .map(|z| 20.0 * z.norm().log10())
            .collect()
    }
    /// Phase in degrees, in $(-180, 180]$.
    pub fn phase_deg(&self) -> Vec<f64> {
        self.values.iter().map(|z| z.arg().to_degrees()).collect()
    }
    /// Standard deviation $\sqrt{\sigma^2}$ per frequency, if the variance is known.
    pub fn std(&self) -> Option<Vec<f64>> {
        self.variance
            .as_ref()
            .map(|v| v.iter().map(|x| x.sqrt()).collect())
    }

    /// The data restricted to $f_{\min} \le f \le f_{\max}$ (Hz).
    pub fn band(&self, f_min: f64, f_max: f64) -> Result<Self> {
        if !(f_min.is_finite() && f_max.is_finite() && f_min <= f_max) {
            return Err(Error::invalid(
                "band",
                format!("need finite f_min ≤ f_max, got [{f_min}, {f_max}]"),
            ));
        }
        let keep: Vec<usize> = (0..self.len())
            .filter(|&k| self.f_hz[k] >= f_min && self.f_hz[k] <= f_max)
            .collect();
        Ok(Self {
            f_hz: keep.iter().map(|&k| self.f_hz[k]).collect(),
            values: keep.iter().map(|&k| self.values[k]).collect(),
            variance: self
                .variance
                .as_ref()
                .map(|v| keep.iter().map(|&k| v[k]).collect()),
            ts: self.ts,
        })
    }

    fn check_grid(&self, other: &Frd) -> Result<()> {
        check_same_ts(self.ts, other.ts)?;
        if self.len() != other.len() {
            return Err(Error::DimensionMismatch {
                context: "Frd frequency grids",
                expected: format!("{} frequencies", self.len()),
                got: format!("{}", other.len()),
            });
        }
        for (k, (a, b)) in self.f_hz.iter().zip(&other.f_hz).enumerate() {
            if (a - b).abs() > 1e-12 * a.abs().max(b.abs()) {
                return Err(Error::invalid(
                    "f_hz",
                    format!("the frequency grids differ at index {k} ({a} Hz vs {b} Hz); interpolate onto a common grid first"),
                ));
            }
        }
        Ok(())
    }

    /// Pointwise combination with first-order variance propagation:
    /// `phi(x, y) -> (z, |dz/dx|^2, |dz/dy|^2)`.
    fn combine(
        &self,
        other: &Frd,
        what: &'static str,
        phi: impl Fn(c64, c64) -> (c64, f64, f64),
    ) -> Result<Self> {
        self.check_grid(other)?;
        let mut values = Vec::with_capacity(self.len());
        let mut var = Vec::with_capacity(self.len());
        for k in 0..self.len() {
            let (z, gx, gy) = phi(self.values[k], other.values[k]);
            if !(z.re.is_finite() && z.im.is_finite()) {
                return Err(Error::numerical(
                    what,
                    format!("division by zero at {} Hz", self.f_hz[k]),
                ));
            }
            values.push(z);
            let vx = self.variance.as_ref().map_or(0.0, |v| v[k]);
            let vy = other.variance.as_ref().map_or(0.0, |v| v[k]);
            var.push(gx * vx + gy * vy);
        }
        let variance = (self.variance.is_some() || other.variance.is_some()).then_some(var);
        Ok(Self {
            f_hz: self.f_hz.clone(),
            values,
            variance,
            ts: self.ts,
        })
    }

    /// Series connection (pointwise product) $X Y$.
    pub fn series(&self, other: &Frd) -> Result<Self> {
        self.combine(other, "Frd::series", |x, y| {
            (x * y, y.norm_sqr(), x.norm_sqr())
        })
    }

    /// Parallel connection (pointwise sum) $X + Y$.
    pub fn parallel(&self, other: &Frd) -> Result<Self> {
        self.combine(other, "Frd::parallel", |x, y| (x + y, 1.0, 1.0))
    }

    /// Pointwise quotient $X / Y$. Errors where $Y = 0$.
    pub fn divide(&self, other: &Frd) -> Result<Self> {
        self.combine(other, "Frd::divide", |x, y| {
            let y2 = y.norm_sqr();
            (x / y, 1.0 / y2, x.norm_sqr() / (y2 * y2))
        })
    }

    /// Pointwise inverse $1 / X$. Errors where $X = 0$.
    pub fn inverse(&self) -> Result<Self> {
        let one = Frd {
            f_hz: self.f_hz.clone(),
            values: vec![c64::new(1.0, 0.0); self.len()],
            variance: None,
            ts: self.ts,
        };
        one.divide(self)
    }

    /// Negative feedback $X / (1 + X Y)$ with `other` in the feedback path.
    pub fn feedback(&self, other: &Frd) -> Result<Self> {
        self.feedback_with_sign(other, FeedbackSign::Negative)
    }

    /// Feedback with sign $\sigma$: $X / (1 - \sigma X Y)$. Errors where $1 - \sigma XY = 0$.
    pub fn feedback_with_sign(&self, other: &Frd, sign: FeedbackSign) -> Result<Self> {
        let s = sign.value();
        self.combine(other, "Frd::feedback", move |x, y| {
            let den = c64::new(1.0, 0.0) - x * y * s;
            let d4 = den.norm_sqr() * den.norm_sqr();
            (x / den, 1.0 / d4, x.norm_sqr() * x.norm_sqr() / d4)
        })
    }
}
