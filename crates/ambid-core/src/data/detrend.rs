//! Removal of an offset or a linear drift before spectral estimation.
//!
//! A constant offset leaks into the lowest frequency lines of every windowed spectrum and a slow
//! drift (thermal growth of the rotor, sensor drift) spreads over several; both are removed before
//! FRF estimation. With the sample index $k = 0, \dots, N-1$, [`Detrend::Linear`] subtracts the
//! least-squares line $a + b k$:
//! $$ \bar k = \frac{N-1}{2}, \qquad
//! b = \frac{\sum_k (k - \bar k)(x_k - \bar x)}{\sum_k (k - \bar k)^2}, \qquad
//! \sum_k (k - \bar k)^2 = \frac{N (N^2 - 1)}{12}, \qquad a = \bar x - b \bar k . $$
//! Centring the index keeps the normal equations well conditioned for any $N$ (the raw normal
//! equations in $\sum k^2$ lose about $\log_{10} N^2$ digits). [`Detrend::Mean`] subtracts $\bar x$.
//!
//! # Complexity
//! $O(N)$, two passes.
//!
//! # Example
//! ```
//! use ambid_core::data::{detrend, Detrend};
//! let x: Vec<f64> = (0..100).map(|k| 2.0 + 0.5 * k as f64).collect();
//! let (d, rep) = detrend(&x, Detrend::Linear).unwrap();
//! assert!(d.iter().all(|v| v.abs() < 1e-12));
//! assert!((rep.offset - 2.0).abs() < 1e-12 && (rep.slope - 0.5).abs() < 1e-14);
//! ```

use crate::error::{check_finite, Error, Result};
use std::fmt;

/// What [`detrend`] removes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Detrend {
    /// Nothing: the samples are returned unchanged.
    None,
    /// The mean $\bar x$.
    #[default]
    Mean,
    /// The least-squares line $a + b k$ over the sample index $k$.
    Linear,
}

/// The trend that [`detrend`] removed: $a + b k$ at sample $k$ (for [`Detrend::Mean`], $b = 0$).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DetrendReport {
    /// What was asked for.
    pub kind: Detrend,
    /// $a$: the removed trend's value at sample 0, in the unit of the signal.
    pub offset: f64,
    /// $b$: the removed trend's slope per sample (divide by $T_s$ for per second).
    pub slope: f64,
}

impl DetrendReport {
    /// One line for a log or a report.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{detrend, Detrend};
    /// let (_, rep) = detrend(&[1.0, 3.0], Detrend::Mean).unwrap();
    /// assert_eq!(rep.summary(), "removed the mean 2");
    /// ```
    pub fn summary(&self) -> String {
        match self.kind {
            Detrend::None => "nothing removed".to_string(),
            Detrend::Mean => format!("removed the mean {}", self.offset),
            Detrend::Linear => format!(
                "removed the line {} + {}·k (k: sample index)",
                self.offset, self.slope
            ),
        }
    }
}

impl fmt::Display for DetrendReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.summary())
    }
}

/// Removes the mean or the least-squares line (see the [module docs](self)); returns the detrended
/// samples and the removed trend.
///
/// A single sample has no defined slope: [`Detrend::Linear`] then removes the sample itself
/// (slope 0).
///
/// # Errors
/// [`Error::InvalidArgument`] for an empty signal; [`Error::NonFinite`] for NaN or infinite samples
/// (repair them first with [`crate::data::repair_abnormal`]).
///
/// # Example
/// ```
/// use ambid_core::data::{detrend, Detrend};
/// let (d, rep) = detrend(&[1.0, 2.0, 6.0], Detrend::Mean).unwrap();
/// assert_eq!(d, vec![-2.0, -1.0, 3.0]);
/// assert_eq!((rep.offset, rep.slope), (3.0, 0.0));
/// assert!(detrend(&[1.0, f64::NAN], Detrend::Mean).is_err());
/// ```
pub fn detrend(x: &[f64], kind: Detrend) -> Result<(Vec<f64>, DetrendReport)> {
    if x.is_empty() {
        return Err(Error::invalid(
            "x",
            "the signal is empty; pass at least one sample",
        ));
    }
    check_finite("x", x)?;
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let (offset, slope) = match kind {
        Detrend::None => (0.0, 0.0),
        Detrend::Mean => (mean, 0.0),
        Detrend::Linear => {
            if x.len() < 2 {
                (mean, 0.0)
            } else {
                let kbar = (n - 1.0) / 2.0;
                let sxy: f64 = x
                    .iter()
                    .enumerate()
                    .map(|(k, v)| (k as f64 - kbar) * (v - mean))
                    .sum();
                let sxx = n * (n * n - 1.0) / 12.0;
                let b = sxy / sxx;
                (mean - b * kbar, b)
            }
        }
    };
    let out = x
        .iter()
        .enumerate()
        .map(|(k, v)| v - (offset + slope * k as f64))
        .collect();
    Ok((
        out,
        DetrendReport {
            kind,
            offset,
            slope,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn none_is_identity() {
        let x = [3.0, -1.0, 2.5];
        let (d, rep) = detrend(&x, Detrend::None).unwrap();
        assert_eq!(d, x.to_vec());
        assert_eq!((rep.offset, rep.slope), (0.0, 0.0));
        assert_eq!(rep.summary(), "nothing removed");
    }

    #[test]
    fn mean_and_single_sample() {
        let (d, _) = detrend(&[5.0], Detrend::Linear).unwrap();
        assert_eq!(d, vec![0.0]);
        let (d, rep) = detrend(&[1.0, 2.0, 3.0, 6.0], Detrend::Mean).unwrap();
        assert_eq!(d, vec![-2.0, -1.0, 0.0, 3.0]);
        assert_eq!(rep.offset, 3.0);
    }

    #[test]
    fn linear_exact_on_a_line_and_orthogonal_residual() {
        let x: Vec<f64> = (0..1001).map(|k| -4.0 + 1e-3 * k as f64).collect();
        let (d, rep) = detrend(&x, Detrend::Linear).unwrap();
        assert!(d.iter().all(|v| v.abs() < 1e-13), "{:?}", &d[..3]);
        assert!((rep.offset + 4.0).abs() < 1e-13);
        assert!((rep.slope - 1e-3).abs() < 1e-16);
        assert!(rep.summary().contains("line"));
        // Residual of any signal is orthogonal to 1 and k.
        let y: Vec<f64> = (0..57).map(|k| ((k * k) % 13) as f64).collect();
        let (r, _) = detrend(&y, Detrend::Linear).unwrap();
        let s0: f64 = r.iter().sum();
        let s1: f64 = r.iter().enumerate().map(|(k, v)| k as f64 * v).sum();
        assert!(s0.abs() < 1e-10 && s1.abs() < 1e-8, "{s0} {s1}");
    }

    #[test]
    fn errors() {
        assert!(matches!(
            detrend(&[], Detrend::Mean),
            Err(Error::InvalidArgument { .. })
        ));
        assert!(matches!(
            detrend(&[0.0, f64::INFINITY], Detrend::Linear),
            Err(Error::NonFinite { index: 1, .. })
        ));
    }

    #[test]
    fn serde_names() {
        assert_eq!(
            serde_json::to_string(&Detrend::Linear).unwrap(),
            "\"linear\""
        );
        assert_eq!(Detrend::default(), Detrend::Mean);
    }
}
