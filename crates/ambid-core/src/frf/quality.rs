//! Quality measures of a closed-loop FRF experiment, as the seed paper defines them (its
//! figure 6): average coherence over a band, average FRF variance across repeated periods, and the
//! output-side signal-to-noise ratio.
//!
//! * **Average coherence** $\bar\gamma^2 = \frac{1}{K}\sum_{k} \gamma^2_{ry}(f_k)$ over the
//!   lines in the band, resonance regions included. The band is the caller's: ambid's analyses
//!   derive it from the excitation ([`super::band`], the lines within 3 dB of the strongest),
//!   never from a fixed rig's numbers.
//! * **FRF variance across periods**: the variance of a single-period estimate
//!   $\sigma^2_{1}(f_k) = P\,\sigma^2_{\bar G}(f_k)$ (the spread of the $P$ per-period FRFs), averaged
//!   over the band; reported absolute (units of $|G|^2$) and relative to $|\hat G|^2$.
//! * **Output SNR** $= \dfrac{\overline{y_\text{exc}^2}}{\overline{y_\text{noise}^2}}$, the output
//!   power with excitation over the output power of a record *without* excitation under the same
//!   closed loop (both mean-removed), in dB as $10\log_{10}$. Without such a record,
//!   [`line_snr`] gives the per-line SNR $|\bar Y(k)|^2 / \hat\sigma^2_{Y}(k)$ from the period spread
//!   (signal power of one period's DFT over its noise variance).
//!
//! # Example
//! ```
//! use ambid_core::frf::quality::output_snr_db;
//! let exc: Vec<f64> = (0..100).map(|k| if k % 2 == 0 { 1.0 } else { -1.0 }).collect();
//! let noise: Vec<f64> = exc.iter().map(|v| 0.1 * v).collect();
//! assert!((output_snr_db(&exc, &noise).unwrap() - 20.0).abs() < 1e-12);
//! ```

use super::closed_loop::ClosedLoopFrf;
use super::periodic::PeriodicSpectra;
use crate::error::{check_finite, Error, Result};
use crate::lti::Frd;

/// The seed paper's band for the averages on its nominal rig \[Hz\]. Not a default for data:
/// derive the band from the excitation with [`super::band::excitation_bands`].
pub const DEFAULT_BAND: (f64, f64) = (10.0, 1000.0);

/// The three quality measures of one experiment (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quality {
    /// Band of the averages \[Hz\].
    pub band: (f64, f64),
    /// Lines in the band.
    pub lines: usize,
    /// Average $\gamma^2_{ry}$.
    pub mean_coherence_ry: f64,
    /// Average $\gamma^2_{ru}$.
    pub mean_coherence_ru: f64,
    /// Average variance of a single-period plant estimate (absolute, $(\mathrm{m/A})^2$ for an AMB).
    pub mean_plant_variance: f64,
    /// Average of $\sigma_1^2/|\hat P|^2$ (dimensionless).
    pub mean_plant_rel_variance: f64,
    /// Output SNR in dB when a noise-only record was given.
    pub output_snr_db: Option<f64>,
}

fn in_band(f: &[f64], band: (f64, f64)) -> Vec<usize> {
    (0..f.len())
        .filter(|&k| f[k] >= band.0 && f[k] <= band.1)
        .collect()
}

fn check_band(band: (f64, f64)) -> Result<()> {
    if !(band.0.is_finite() && band.1.is_finite() && band.0 >= 0.0 && band.1 > band.0) {
        return Err(Error::invalid(
            "band",
            format!(
                "a band needs 0 ≤ f_min < f_max, got {}–{} Hz",
                band.0, band.1
            ),
        ));
    }
    Ok(())
}

/// Average of `values` over the frequencies of `f_hz` inside `band`.
///
/// # Errors
/// [`Error::InvalidArgument`] for a malformed band or no frequency inside it;
/// [`Error::DimensionMismatch`] for different lengths.
pub fn band_mean(f_hz: &[f64], values: &[f64], band: (f64, f64)) -> Result<f64> {
    check_band(band)?;
    if f_hz.len() != values.len() {
        return Err(Error::DimensionMismatch {
            context: "band_mean",
            expected: f_hz.len().to_string(),
            got: values.len().to_string(),
        });
    }
    let idx = in_band(f_hz, band);
    if idx.is_empty() {
        return Err(Error::invalid(
            "band",
            format!(
                "no frequency line in {}–{} Hz; widen the band or refine the resolution",
                band.0, band.1
            ),
        ));
    }
    Ok(idx.iter().map(|&k| values[k]).sum::<f64>() / idx.len() as f64)
}

/// Average single-period variance of `frd` over `band` (absolute and relative), for an estimate
/// averaged over `periods` periods.
///
/// # Errors
/// [`Error::InvalidArgument`] when the FRF has no variance, or as [`band_mean`].
pub fn band_variance(frd: &Frd, periods: usize, band: (f64, f64)) -> Result<(f64, f64)> {
    frd.require_siso("quality::band_variance")?;
    let var = frd.variance().ok_or_else(|| {
        Error::invalid(
            "frd",
            "the FRF carries no variance: at least 2 periods (or segments) are needed",
        )
    })?;
    let p = periods as f64;
    let abs: Vec<f64> = var.iter().map(|v| v * p).collect();
    let rel: Vec<f64> = abs
        .iter()
        .zip(frd.values())
        .map(|(v, g)| v / g.norm_sqr().max(f64::MIN_POSITIVE))
        .collect();
    Ok((
        band_mean(frd.f_hz(), &abs, band)?,
        band_mean(frd.f_hz(), &rel, band)?,
    ))
}

/// Output SNR $10\log_{10}(\overline{y_\text{exc}^2}/\overline{y_\text{noise}^2})$ \[dB\] (both
/// records mean-removed).
///
/// # Errors
/// [`Error::InvalidArgument`] for a record shorter than 2 samples or a noise record without power;
/// [`Error::NonFinite`].
pub fn output_snr_db(y_excited: &[f64], y_noise: &[f64]) -> Result<f64> {
    let power = |x: &[f64], what: &'static str| -> Result<f64> {
        if x.len() < 2 {
            return Err(Error::invalid(
                what,
                format!("{} samples; at least 2 are needed", x.len()),
            ));
        }
        check_finite(what, x)?;
        let m = x.iter().sum::<f64>() / x.len() as f64;
        Ok(x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len() as f64)
    };
    let pe = power(y_excited, "y_excited")?;
    let pn = power(y_noise, "y_noise")?;
    if pn == 0.0 {
        return Err(Error::invalid(
            "y_noise",
            "the noise-only record has no power (constant); it cannot serve as the noise reference",
        ));
    }
    Ok(10.0 * (pe / pn).log10())
}

/// Per-line SNR of channel `c` from the period spread, $|\bar X(k)|^2/\hat\sigma^2_X(k)$, on
/// `lines` (infinite where the spread is zero).
pub fn line_snr(s: &PeriodicSpectra, c: usize, lines: &[usize]) -> Vec<f64> {
    let var = s.var(c);
    lines
        .iter()
        .map(|&k| {
            let p = s.mean(c)[k].norm_sqr();
            if var[k] > 0.0 {
                p / var[k]
            } else {
                f64::INFINITY
            }
        })
        .collect()
}

/// All three measures of a period-averaged closed-loop FRF over `band`, with the output SNR when
/// `snr_db` was computed from a noise-only record.
///
/// # Errors
/// As [`band_mean`] and [`band_variance`].
pub fn assess(frf: &ClosedLoopFrf, band: (f64, f64), snr_db: Option<f64>) -> Result<Quality> {
    let f = frf.f_hz();
    let periods = match frf.averaging {
        super::closed_loop::Averaging::Periods(p) => p,
        super::closed_loop::Averaging::Welch { effective, .. } => {
            effective.round().max(1.0) as usize
        }
    };
    let (v_abs, v_rel) = band_variance(&frf.plant, periods, band)?;
    Ok(Quality {
        band,
        lines: in_band(f, band).len(),
        mean_coherence_ry: band_mean(f, &frf.coh_ry, band)?,
        mean_coherence_ru: band_mean(f, &frf.coh_ru, band)?,
        mean_plant_variance: v_abs,
        mean_plant_rel_variance: v_rel,
        output_snr_db: snr_db,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_mean_and_errors() {
        let f = [1.0, 10.0, 100.0, 1000.0, 2000.0];
        let v = [9.0, 1.0, 2.0, 3.0, 9.0];
        assert_eq!(band_mean(&f, &v, (10.0, 1000.0)).unwrap(), 2.0);
        assert!(band_mean(&f, &v, (3000.0, 4000.0))
            .unwrap_err()
            .to_string()
            .contains("no frequency line"));
        assert!(band_mean(&f, &v, (10.0, 5.0)).is_err());
        assert!(band_mean(&f, &v[..2], DEFAULT_BAND).is_err());
    }

    #[test]
    fn snr_errors() {
        assert!(output_snr_db(&[1.0, 2.0], &[3.0, 3.0]).is_err());
        assert!(output_snr_db(&[1.0], &[3.0, 1.0]).is_err());
        assert!(output_snr_db(&[1.0, f64::NAN], &[3.0, 1.0]).is_err());
    }
}
