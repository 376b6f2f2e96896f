//! Fit metrics, defined once (`docs/conventions.md`, "Metrics").
//!
//! * [`fit_percent`]: the normalised (NRMSE) fit of a time-domain output,
//!   $100\,(1 - \lVert y - \hat y\rVert / \lVert y - \bar y\rVert)$ (MATLAB `compare`).
//!
//! The frequency-domain errors of a fitted model (RMSE, relative and dB RMSE on a band) are
//! [`crate::estimate::freqfit::FreqErrors`].
//!
//! # Example
//! ```
//! use ambid_core::validate::fit::fit_percent;
//! let y = [0.0, 1.0, 0.0, -1.0];
//! let yhat = [0.0, 0.5, 0.0, -0.5];
//! // ‖y − ŷ‖ = √0.5, ‖y − ȳ‖ = √2: fit = 100 (1 − 1/2) = 50
//! assert!((fit_percent(&y, &yhat).unwrap() - 50.0).abs() < 1e-12);
//! ```

use crate::error::{check_finite, Error, Result};

/// The normalised fit in percent, $100\,(1 - \lVert y - \hat y\rVert / \lVert y - \bar y\rVert)$
/// (NRMSE fit, MATLAB `compare`): $100$ is perfect, $0$ is no better than the mean $\bar y$ of
/// `y`, and it is negative for a worse model. Pass the samples to be compared (e.g. `&y[k0..]`).
///
/// This is the project's one fit metric (`docs/conventions.md`).
///
/// # Errors
/// [`Error::DimensionMismatch`] for different lengths; [`Error::InvalidArgument`] for empty or
/// constant `y` (the fit is undefined); [`Error::NonFinite`].
///
/// # Example
/// ```
/// use ambid_core::validate::fit::fit_percent;
/// let y = [1.0, 2.0, 3.0];
/// assert_eq!(fit_percent(&y, &y).unwrap(), 100.0);
/// assert_eq!(fit_percent(&y, &[2.0, 2.0, 2.0]).unwrap(), 0.0);
/// ```
pub fn fit_percent(y: &[f64], yhat: &[f64]) -> Result<f64> {
    if y.len() != yhat.len() {
        return Err(Error::DimensionMismatch {
            context: "fit_percent: measured and model output",
            expected: y.len().to_string(),
            got: yhat.len().to_string(),
        });
    }
    if y.is_empty() {
        return Err(Error::invalid(
            "y",
            "the fit of an empty record is undefined",
        ));
    }
    check_finite("y", y)?;
    check_finite("yhat", yhat)?;
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let spread = y.iter().map(|v| (v - mean).powi(2)).sum::<f64>().sqrt();
    if spread == 0.0 {
        return Err(Error::invalid(
            "y",
            "y is constant, so the fit (relative to its variation about the mean) is undefined",
        ));
    }
    let err = y
        .iter()
        .zip(yhat)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    Ok(100.0 * (1.0 - err / spread))
}
