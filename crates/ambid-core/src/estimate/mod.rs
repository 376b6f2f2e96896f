//! Parametric estimation from time-domain data: FIR and ARX by least squares, ARMAX / OE / BJ by
//! the prediction-error method, subspace state-space models, and order selection.

pub mod arx;
pub mod arx_mimo;
pub mod freqfit;
pub mod freqfit_mimo;
pub mod freqfit_ss;
pub mod graybox;
pub mod order;
pub mod pem;
mod qr_stream;
pub mod scheduled;
pub mod ss_pem;
pub mod subspace;

use crate::error::{Error, Result};
use faer::{Mat, MatRef};

/// A fitted model with its parameter uncertainty and fit statistics.
#[derive(Debug, Clone)]
pub struct Fitted<M> {
    /// The model.
    pub model: M,
    /// The estimated parameter vector $\hat\theta$ (ordering documented by each estimator).
    pub params: Vec<f64>,
    /// Covariance of $\hat\theta$ (from the final Jacobian / regressor), if computed.
    pub covariance: Option<Mat<f64>>,
    /// Loss $V_N = \frac1N \sum \varepsilon_k^2$ of the prediction errors on the estimation data.
    pub loss: f64,
    /// Estimated innovation variance $\hat\lambda$ (loss corrected for the number of parameters).
    pub noise_variance: f64,
    /// Samples used in the criterion.
    pub n_samples: usize,
}

impl<M> Fitted<M> {
    /// Standard deviations $\sqrt{\mathrm{diag}\,P}$ of the parameters, if a covariance exists.
    pub fn std(&self) -> Option<Vec<f64>> {
        self.covariance
            .as_ref()
            .map(|p| (0..p.nrows()).map(|i| p[(i, i)].max(0.0).sqrt()).collect())
    }
}

/// Errors with [`Error::NonFinite`] (the sample number as `index`) at the first NaN or infinite
/// sample of the `N × channels` matrix `x`.
pub(crate) fn check_samples(what: &'static str, x: MatRef<'_, f64>) -> Result<()> {
    for k in 0..x.nrows() {
        for c in 0..x.ncols() {
            if !x[(k, c)].is_finite() {
                return Err(Error::NonFinite { what, index: k });
            }
        }
    }
    Ok(())
}

/// RMS of each column of `x`; an identically zero (or overflowing) column is an error.
pub(crate) fn channel_rms(what: &'static str, x: MatRef<'_, f64>) -> Result<Vec<f64>> {
    (0..x.ncols())
        .map(|c| {
            let s = (x.col(c).iter().map(|v| v * v).sum::<f64>() / x.nrows() as f64).sqrt();
            if s > 0.0 && s.is_finite() {
                Ok(s)
            } else {
                Err(Error::invalid(
                    what,
                    format!("channel {c} is identically zero (or overflows); it carries no information, remove it"),
                ))
            }
        })
        .collect()
}
