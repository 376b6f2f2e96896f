//! Side-by-side comparison of the four excitation families at the same RMS level, as the seed
//! paper's figure 3 does: waveform statistics, one-sided amplitude spectra and autocorrelations.
//!
//! The four signals share the sample rate and the record length of one seed PRBS period
//! (order 10, 5 samples per bit: 5115 samples) so that their spectra fall on the same DFT grid.

use crate::error::{Error, Result};
use ambid_core::signal::{
    amplitude_spectrum, autocorrelation, BandReport, ChirpSpec, Distribution, ExcitationSpec, Grid,
    MultisineSpec, NoiseSpec, Phases, PrbsSpec, Sweep,
};

/// One signal of the comparison.
#[derive(Debug, Clone)]
pub struct Compared {
    /// Family name (`prbs`, `chirp`, `noise`, `multisine`).
    pub name: &'static str,
    /// Band, resolution, duration, RMS, peak and crest factor.
    pub report: BandReport,
    /// One record, scaled to the common RMS.
    pub values: Vec<f64>,
    /// One-sided amplitude spectrum of the record (on [`Comparison::f_hz`]).
    pub spectrum: Vec<f64>,
    /// Normalised autocorrelation (circular for the periodic signals), lags 0..`max_lag`.
    pub autocorr: Vec<f64>,
}

/// The four signals on a common grid.
#[derive(Debug, Clone)]
pub struct Comparison {
    /// Sample time, s.
    pub ts: f64,
    /// Frequencies of the spectra, Hz.
    pub f_hz: Vec<f64>,
    /// PRBS, chirp, white noise, multisine.
    pub signals: Vec<Compared>,
}

/// Compares PRBS (order 10, 5 samples/bit), a linear chirp (f_res … f_max), band-unlimited
/// Gaussian white noise (seeded) and a full-grid Schroeder multisine (f_res … f_max), all of one
/// PRBS period's length and scaled to the RMS `level`. `max_lag` bounds the autocorrelation.
pub fn compare(fs_hz: f64, level: f64, seed: u64, max_lag: usize) -> Result<Comparison> {
    if !(fs_hz.is_finite() && fs_hz > 0.0) {
        return Err(Error::other(format!(
            "the sample rate must be positive and finite, got {fs_hz}"
        )));
    }
    if !(level.is_finite() && level > 0.0) {
        return Err(Error::other(format!(
            "the RMS level must be positive and finite, got {level}"
        )));
    }
    let ts = 1.0 / fs_hz;
    let prbs = PrbsSpec {
        order: 10,
        samples_per_bit: 5,
        periods: 1,
        amplitude: level,
        offset: 0.0,
    };
    let n = prbs.report(ts)?.period_samples;
    let df = fs_hz / n as f64;
    let f_max = prbs.report(ts)?.f_max_hz;
    let specs: [(&'static str, ExcitationSpec, bool); 4] = [
        ("prbs", prbs.into(), true),
        (
            "chirp",
            ChirpSpec {
                f0_hz: df,
                f1_hz: f_max,
                duration_s: n as f64 * ts,
                amplitude: level,
                sweep: Sweep::Linear,
                periods: 1,
            }
            .into(),
            false,
        ),
        (
            "noise",
            NoiseSpec {
                distribution: Distribution::Gaussian,
                rms: level,
                n_samples: n,
                band_hz: None,
                seed,
            }
            .into(),
            false,
        ),
        (
            "multisine",
            MultisineSpec {
                f_min_hz: df,
                f_max_hz: f_max,
                period_samples: n,
                periods: 1,
                rms: level,
                grid: Grid::Full,
                phases: Phases::Schroeder,
                seed,
            }
            .into(),
            true,
        ),
    ];
    let mut signals = Vec::with_capacity(4);
    let mut f_hz = Vec::new();
    for (name, spec, periodic) in specs {
        let mut values = spec.generate(ts)?.values;
        values.truncate(n);
        // common RMS (the chirp's and noise's RMS differ slightly from the nominal value)
        let rms = (values.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
        values.iter_mut().for_each(|v| *v *= level / rms);
        let mut report = spec.report(ts)?;
        let peak = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        report.rms = level;
        report.peak = peak;
        report.crest_factor = peak / level;
        let (f, spectrum) = amplitude_spectrum(&values, ts)?;
        f_hz = f;
        let autocorr = autocorrelation(&values, max_lag.min(n - 1), periodic)?;
        signals.push(Compared {
            name,
            report,
            values,
            spectrum,
            autocorr,
        });
    }
    Ok(Comparison { ts, f_hz, signals })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_signals_on_one_grid_with_the_expected_character() {
        let c = compare(20_000.0, 0.1, 1, 200).unwrap();
        assert_eq!(c.signals.len(), 4);
        let by = |n: &str| c.signals.iter().find(|s| s.name == n).unwrap();
        for s in &c.signals {
            assert_eq!(s.values.len(), 5115);
            assert_eq!(s.spectrum.len(), c.f_hz.len());
            let rms = (s.values.iter().map(|v| v * v).sum::<f64>() / 5115.0).sqrt();
            assert!((rms - 0.1).abs() < 1e-12, "{}: {rms}", s.name);
            assert_eq!(s.autocorr[0], 1.0);
        }
        // crest factors: PRBS 1, chirp √2, multisine (Schroeder) below noise
        assert!((by("prbs").report.crest_factor - 1.0).abs() < 1e-12);
        assert!((by("chirp").report.crest_factor - 2f64.sqrt()).abs() < 0.01);
        assert!(by("multisine").report.crest_factor < by("noise").report.crest_factor);
        // PRBS circular autocorrelation beyond one bit (5 samples) is exactly −1/L
        for v in &by("prbs").autocorr[5..] {
            assert!((v + 1.0 / 1023.0).abs() < 1e-12, "{v}");
        }
        // the multisine has energy only up to f_max = 2 kHz
        let m = by("multisine");
        for (f, a) in c.f_hz.iter().zip(&m.spectrum) {
            if *f > 2000.0 + 1.0 {
                assert!(*a < 1e-12, "{f}: {a}");
            }
        }
    }

    #[test]
    fn bad_levels_are_rejected() {
        assert!(compare(20_000.0, 0.0, 1, 10).is_err());
        assert!(compare(f64::NAN, 0.1, 1, 10).is_err());
    }
}
