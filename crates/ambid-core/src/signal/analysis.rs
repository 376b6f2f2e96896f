//! Analysis of excitation signals: one-sided amplitude spectrum, normalised autocorrelation, RMS and
//! crest factor (the views of the seed paper's Figure 3).
//!
//! # Complexity
//! * [`amplitude_spectrum`]: one real FFT (realfft), $O(N \log N)$ for any $N$ (RustFFT picks
//!   mixed-radix, Rader or Bluestein algorithms for awkward lengths).
//! * [`autocorrelation`]: direct sums, $O(N \cdot (\tau_{\max}+1))$, when that is at most
//!   $2^{16}$ multiply-adds; otherwise via the power spectrum (Wiener–Khinchin), $O(N \log N)$.
//!   Both paths are tested against a naive $O(N^2)$ oracle.
//! * [`rms`], [`crest_factor`]: $O(N)$.
//!
//! # Example
//! ```
//! use ambid_core::signal::{amplitude_spectrum, autocorrelation, crest_factor};
//! let ts = 1e-3;
//! let n = 1000;
//! // 2 sin(2π 50 t): 50 Hz is bin 50 of a 1 s record.
//! let x: Vec<f64> = (0..n).map(|k| 2.0 * (2.0 * std::f64::consts::PI * 50.0 * k as f64 * ts).sin()).collect();
//! let (f, a) = amplitude_spectrum(&x, ts).unwrap();
//! assert!((f[50] - 50.0).abs() < 1e-12 && (a[50] - 2.0).abs() < 1e-12);
//! assert!((crest_factor(&x).unwrap() - 2f64.sqrt()).abs() < 1e-9);
//! let r = autocorrelation(&x, 10, true).unwrap();
//! assert!((r[0] - 1.0).abs() < 1e-15 && (r[5] - (2.0 * std::f64::consts::PI * 0.25).cos()).abs() < 1e-12);
//! ```

use crate::error::{check_finite, Error, Result};
use num_complex::Complex;
use realfft::RealFftPlanner;

/// Direct sums are used while $N(\tau_{\max}+1)$ is at most this many multiply-adds.
const DIRECT_WORK_LIMIT: usize = 1 << 16;

fn check_signal(x: &[f64]) -> Result<()> {
    if x.is_empty() {
        return Err(Error::invalid(
            "x",
            "the signal is empty; pass at least one sample",
        ));
    }
    check_finite("x", x)
}

/// Root mean square $\sqrt{\frac1N\sum_k x_k^2}$.
///
/// # Errors
/// [`Error::InvalidArgument`] for an empty signal, [`Error::NonFinite`] for NaN or infinite samples.
///
/// # Example
/// ```
/// use ambid_core::signal::rms;
/// assert!((rms(&[3.0, -3.0, 3.0, -3.0]).unwrap() - 3.0).abs() < 1e-15);
/// ```
pub fn rms(x: &[f64]) -> Result<f64> {
    check_signal(x)?;
    Ok((x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt())
}

/// Crest factor $\max_k |x_k| \,/\, \mathrm{rms}(x)$: 1 for a binary signal such as a PRBS, $\sqrt2$
/// for a sine, about 3–4 for Gaussian noise. A low crest factor puts much power into the plant for a
/// given actuator peak.
///
/// # Errors
/// [`Error::InvalidArgument`] for an empty or all-zero signal, [`Error::NonFinite`] for NaN or
/// infinite samples.
///
/// # Example
/// ```
/// use ambid_core::signal::crest_factor;
/// assert_eq!(crest_factor(&[1.0, -1.0, 1.0]).unwrap(), 1.0);
/// assert!(crest_factor(&[0.0, 0.0]).is_err());
/// ```
pub fn crest_factor(x: &[f64]) -> Result<f64> {
    let r = rms(x)?;
    if r == 0.0 {
        return Err(Error::invalid(
            "x",
            "the signal is identically zero, so its crest factor is undefined",
        ));
    }
    let peak = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    Ok(peak / r)
}

/// One-sided amplitude spectrum of `x` sampled at `ts` seconds.
///
/// With $X_k = \sum_{n=0}^{N-1} x_n e^{-j 2\pi k n / N}$, returns the frequencies
/// $f_k = k / (N T_s)$ in Hz, $k = 0, \dots, \lfloor N/2 \rfloor$, and the amplitudes
/// $$ A_0 = \frac{|X_0|}{N}, \qquad A_k = \frac{2 |X_k|}{N} \;(0 < k < N/2), \qquad
/// A_{N/2} = \frac{|X_{N/2}|}{N} \;(N \text{ even}), $$
/// so that a sinusoid of amplitude $a$ at a bin frequency shows $a$ and a constant $c$ shows $|c|$ at
/// DC. No window is applied: analyse whole periods of periodic signals to avoid leakage.
///
/// # Errors
/// [`Error::InvalidArgument`] for an empty signal or a sample time that is not finite and $> 0$;
/// [`Error::NonFinite`] for NaN or infinite samples. An all-zero signal is valid (zero spectrum).
///
/// # Example
/// ```
/// use ambid_core::signal::amplitude_spectrum;
/// let (f, a) = amplitude_spectrum(&[1.0, 1.0, 1.0, 1.0], 0.5).unwrap();
/// assert_eq!(f, vec![0.0, 0.5, 1.0]);
/// assert_eq!(a, vec![1.0, 0.0, 0.0]);
/// ```
pub fn amplitude_spectrum(x: &[f64], ts: f64) -> Result<(Vec<f64>, Vec<f64>)> {
    super::check_ts(ts)?;
    check_signal(x)?;
    let n = x.len();
    let spec = real_fft(x)?;
    let nf = n as f64;
    let freqs = (0..spec.len()).map(|k| k as f64 / (nf * ts)).collect();
    let amps = spec
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let edge = k == 0 || 2 * k == n;
            c.norm() * if edge { 1.0 } else { 2.0 } / nf
        })
        .collect();
    Ok((freqs, amps))
}

/// Normalised autocorrelation $r_\tau / r_0$ for lags $\tau = 0, \dots, \tau_{\max}$ (so the first value
/// is 1), without mean removal (detrend first if the mean should not count):
/// $$ r_\tau = \sum_{n=0}^{N-1-\tau} x_n x_{n+\tau} \quad\text{(linear)}, \qquad
/// r_\tau = \sum_{n=0}^{N-1} x_n x_{(n+\tau) \bmod N} \quad\text{(circular, for periodic signals)}. $$
/// One period of a $\pm1$ PRBS of length $L$ gives, circularly, $1$ at lag 0 and $-1/L$ elsewhere.
///
/// # Errors
/// [`Error::InvalidArgument`] for an empty or all-zero signal or `max_lag >= x.len()`;
/// [`Error::NonFinite`] for NaN or infinite samples.
///
/// # Example
/// ```
/// use ambid_core::signal::autocorrelation;
/// let r = autocorrelation(&[1.0, 1.0, 1.0, 1.0], 2, false).unwrap();
/// assert_eq!(r, vec![1.0, 0.75, 0.5]);
/// let r = autocorrelation(&[1.0, 1.0, 1.0, 1.0], 2, true).unwrap();
/// assert_eq!(r, vec![1.0, 1.0, 1.0]);
/// ```
pub fn autocorrelation(x: &[f64], max_lag: usize, circular: bool) -> Result<Vec<f64>> {
    check_signal(x)?;
    let n = x.len();
    if max_lag >= n {
        return Err(Error::invalid(
            "max_lag",
            format!("must be smaller than the signal length {n}, got {max_lag}"),
        ));
    }
    let r0: f64 = x.iter().map(|v| v * v).sum();
    if r0 == 0.0 {
        return Err(Error::invalid(
            "x",
            "the signal is identically zero, so its normalised autocorrelation is undefined",
        ));
    }
    let raw = if n.saturating_mul(max_lag + 1) <= DIRECT_WORK_LIMIT {
        autocorrelation_direct(x, max_lag, circular)
    } else {
        autocorrelation_fft(x, max_lag, circular)?
    };
    let r0 = raw[0];
    Ok(raw.into_iter().map(|r| r / r0).collect())
}

/// Unnormalised autocorrelation by direct sums.
pub(crate) fn autocorrelation_direct(x: &[f64], max_lag: usize, circular: bool) -> Vec<f64> {
    let n = x.len();
    (0..=max_lag)
        .map(|tau| {
            if circular {
                let (head, tail) = x.split_at(tau);
                // x[n] x[n+tau] for n + tau < N, then the wrapped part.
                let a: f64 = x.iter().zip(tail).map(|(u, v)| u * v).sum();
                let b: f64 = x[n - tau..].iter().zip(head).map(|(u, v)| u * v).sum();
                a + b
            } else {
                x.iter().zip(&x[tau..]).map(|(u, v)| u * v).sum()
            }
        })
        .collect()
}

/// Unnormalised autocorrelation via the power spectrum: $r = \mathcal F^{-1}\{|\mathcal F x|^2\}$,
/// on $N$ points (circular) or zero-padded to a power of two $\ge N + \tau_{\max}$ (linear, so that no
/// wrapped products reach the requested lags).
pub(crate) fn autocorrelation_fft(x: &[f64], max_lag: usize, circular: bool) -> Result<Vec<f64>> {
    let n = x.len();
    let m = if circular {
        n
    } else {
        (n + max_lag).next_power_of_two()
    };
    let mut padded = vec![0.0; m];
    padded[..n].copy_from_slice(x);
    let mut spec = real_fft(&padded)?;
    for c in spec.iter_mut() {
        *c = Complex::new(c.norm_sqr(), 0.0);
    }
    let mut planner = RealFftPlanner::<f64>::new();
    let inv = planner.plan_fft_inverse(m);
    let mut out = inv.make_output_vec();
    inv.process(&mut spec, &mut out)
        .map_err(|e| Error::numerical("autocorrelation (inverse FFT)", e.to_string()))?;
    let scale = 1.0 / m as f64;
    Ok(out[..=max_lag].iter().map(|v| v * scale).collect())
}

/// Forward real FFT: $X_k$ for $k = 0, \dots, \lfloor N/2 \rfloor$ (no scaling).
pub(crate) fn real_fft(x: &[f64]) -> Result<Vec<Complex<f64>>> {
    let mut planner = RealFftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(x.len());
    let mut input = x.to_vec();
    let mut out = fwd.make_output_vec();
    fwd.process(&mut input, &mut out)
        .map_err(|e| Error::numerical("real FFT", e.to_string()))?;
    Ok(out)
}

/// Inverse real FFT of a half spectrum to `n` real samples, scaled by $1/N$ so that
/// `real_ifft(real_fft(x)) == x`. The imaginary parts of the DC (and, for even `n`, Nyquist) bins
/// are ignored.
pub(crate) fn real_ifft(half: &[Complex<f64>], n: usize) -> Result<Vec<f64>> {
    let mut planner = RealFftPlanner::<f64>::new();
    let inv = planner.plan_fft_inverse(n);
    let mut spec = half.to_vec();
    if let Some(c) = spec.first_mut() {
        c.im = 0.0;
    }
    if n % 2 == 0 {
        if let Some(c) = spec.last_mut() {
            c.im = 0.0;
        }
    }
    let mut out = inv.make_output_vec();
    inv.process(&mut spec, &mut out)
        .map_err(|e| Error::numerical("inverse real FFT", e.to_string()))?;
    let scale = 1.0 / n as f64;
    out.iter_mut().for_each(|v| *v *= scale);
    Ok(out)
}

#[cfg(test)]
pub(crate) mod naive {
    //! O(N²) oracles for the fast paths (RustFFT style): written straight from the definitions.
    use num_complex::Complex;
    use std::f64::consts::PI;

    /// $X_k = \sum_n x_n e^{-j2\pi kn/N}$ for all $k$.
    pub fn dft(x: &[f64]) -> Vec<Complex<f64>> {
        let n = x.len();
        (0..n)
            .map(|k| {
                x.iter()
                    .enumerate()
                    .map(|(t, &v)| {
                        // Reduce k*t mod n exactly before scaling to keep the angle small.
                        let ang = -2.0 * PI * ((k * t) % n) as f64 / n as f64;
                        Complex::new(v * ang.cos(), v * ang.sin())
                    })
                    .sum()
            })
            .collect()
    }

    /// Unnormalised autocorrelation from the definition.
    pub fn autocorr(x: &[f64], max_lag: usize, circular: bool) -> Vec<f64> {
        let n = x.len();
        (0..=max_lag)
            .map(|tau| {
                let mut s = 0.0;
                for i in 0..n {
                    let j = i + tau;
                    if j < n {
                        s += x[i] * x[j];
                    } else if circular {
                        s += x[i] * x[j - n];
                    }
                }
                s
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_signal(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n).map(|_| rng.random_range(-1.0..1.0) + 0.3).collect()
    }

    #[test]
    fn spectrum_matches_naive_dft() {
        for (i, n) in [1usize, 2, 3, 7, 16, 97, 128, 250, 511]
            .into_iter()
            .enumerate()
        {
            let x = random_signal(n, i as u64);
            let ts = 1e-3;
            let (f, a) = amplitude_spectrum(&x, ts).unwrap();
            let d = naive::dft(&x);
            assert_eq!(f.len(), n / 2 + 1);
            let scale = x.iter().map(|v| v.abs()).sum::<f64>().max(1.0);
            for k in 0..f.len() {
                assert!((f[k] - k as f64 / (n as f64 * ts)).abs() < 1e-9);
                let w = if k == 0 || 2 * k == n { 1.0 } else { 2.0 };
                let want = w * d[k].norm() / n as f64;
                assert!(
                    (a[k] - want).abs() <= 1e-10 * scale / n as f64 * w,
                    "n={n} k={k}: {} vs {want}",
                    a[k]
                );
            }
        }
    }

    #[test]
    fn fft_roundtrip() {
        for n in [1usize, 2, 5, 64, 1023] {
            let x = random_signal(n, 99);
            let y = real_ifft(&real_fft(&x).unwrap(), n).unwrap();
            for (u, v) in x.iter().zip(&y) {
                assert!((u - v).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn autocorrelation_paths_match_naive() {
        for (i, n) in [1usize, 2, 9, 64, 100, 333, 1000].into_iter().enumerate() {
            let x = random_signal(n, 10 + i as u64);
            for &max_lag in &[0, n / 3, n - 1] {
                for circular in [false, true] {
                    let want = naive::autocorr(&x, max_lag, circular);
                    let direct = autocorrelation_direct(&x, max_lag, circular);
                    let fft = autocorrelation_fft(&x, max_lag, circular).unwrap();
                    let r0 = want[0];
                    for k in 0..=max_lag {
                        assert!(
                            (direct[k] - want[k]).abs() <= 1e-10 * r0,
                            "direct n={n} k={k}"
                        );
                        assert!((fft[k] - want[k]).abs() <= 1e-10 * r0, "fft n={n} k={k}");
                    }
                    let norm = autocorrelation(&x, max_lag, circular).unwrap();
                    for k in 0..=max_lag {
                        assert!((norm[k] - want[k] / r0).abs() <= 1e-10);
                    }
                }
            }
        }
    }

    #[test]
    fn bad_input_is_typed() {
        assert!(matches!(
            amplitude_spectrum(&[], 1.0),
            Err(Error::InvalidArgument { name: "x", .. })
        ));
        assert!(matches!(
            amplitude_spectrum(&[1.0], 0.0),
            Err(Error::InvalidArgument { name: "ts", .. })
        ));
        assert!(matches!(
            amplitude_spectrum(&[1.0, f64::NAN], 1.0),
            Err(Error::NonFinite {
                what: "x",
                index: 1
            })
        ));
        assert!(matches!(
            autocorrelation(&[0.0; 4], 1, true),
            Err(Error::InvalidArgument { name: "x", .. })
        ));
        assert!(matches!(
            autocorrelation(&[1.0; 4], 4, true),
            Err(Error::InvalidArgument {
                name: "max_lag",
                ..
            })
        ));
        assert!(matches!(
            autocorrelation(&[1.0, f64::INFINITY], 0, false),
            Err(Error::NonFinite { .. })
        ));
        assert!(matches!(
            crest_factor(&[]),
            Err(Error::InvalidArgument { .. })
        ));
        assert!(matches!(
            crest_factor(&[0.0, 0.0]),
            Err(Error::InvalidArgument { .. })
        ));
        assert!(matches!(
            crest_factor(&[f64::NAN]),
            Err(Error::NonFinite { .. })
        ));
    }
}
