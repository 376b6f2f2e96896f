//! Excitation signals (PRBS, chirp, noise, multisine) and their analysis.
//!
//! Closed-loop identification injects an excitation $r(k)$ at the controller output and records the
//! response. The excitation decides which frequencies the data can say anything about, how well
//! repeated periods can be averaged, and how hard the actuator is driven for a given power. This module
//! designs the four broadband signals compared in the seed paper (its Figure 3) and reports, for each
//! design, the band it covers, its frequency resolution, its duration and its crest factor
//! ([`BandReport`]).
//!
//! | signal | spectrum | repeatability | crest factor | leakage |
//! |---|---|---|---|---|
//! | [`PrbsSpec`] | flat $\operatorname{sinc}^2$-shaped envelope, lines at $k/(L N_b T_s)$ | exact, periodic | $1$ (two levels) | none when whole periods are analysed |
//! | [`ChirpSpec`] | band $[f_0, f_1]$, energy per band set by the sweep law | exact | $\sqrt 2$ | small ripple at the band edges |
//! | [`NoiseSpec`] | continuous, random amplitude at every bin | only through the seed | $\approx 3\text{–}4$ (Gaussian), $\sqrt 3$ (uniform) | yes, needs windows and averaging |
//! | [`MultisineSpec`] | exactly the chosen DFT bins, flat amplitude | exact, periodic | $\approx 1.5\text{–}1.9$ (Schroeder) | none when whole periods are analysed |
//!
//! * **PRBS** (pseudo-random binary sequence, [`prbs`]): a maximum-length shift-register sequence of
//!   order $n$, length $L = 2^n - 1$, each bit held for $N_b$ samples. Its circular autocorrelation is
//!   that of white noise up to $-1/L$, it uses the actuator range fully (crest factor 1) and it is
//!   trivial to reproduce on a digital controller. The seed paper selects it for closed-loop AMB
//!   identification: $n = 10$, $N_b = 5$, $T_s = 50\,\mu\text{s}$, $N_p = 20$ periods give $5115$
//!   samples per period, $\Delta f \approx 3.91$ Hz and $5.1$ s.
//! * **Chirp** ([`chirp`]): a swept sine. Easy to read (time maps to frequency) and used in the seed
//!   paper for closed-loop validation; the energy at each frequency is set by how long the sweep dwells
//!   there.
//! * **Noise** ([`noise`]): Gaussian or uniform, optionally band-limited. Broadband but every
//!   realisation differs, so repeated experiments agree only on average and spectral estimates need
//!   windowing (leakage) and averaging.
//! * **Multisine** ([`multisine`]): a sum of cosines exactly on DFT bins, with Schroeder or random
//!   phases. Full control of the excited lines (odd and random-odd grids reveal nonlinear distortion),
//!   no leakage over whole periods, but only the chosen frequencies are excited.
//!
//! Several inputs ([`multi`]): [`MultiInputDesign`] excites $n$ axes from one periodic base signal,
//! sequentially, with Hadamard signs (orthogonal) or on interleaved multisine lines (zipper), and
//! [`MultiInputReport`] gives the experiments, durations, lines per axis and the input matrix's
//! condition number per line (docs/signals.md, "Several inputs").
//!
//! The [`analysis`] functions ([`amplitude_spectrum`], [`autocorrelation`], [`crest_factor`], [`rms`])
//! reproduce the paper's Figure 3 views of any signal.
//!
//! # Example
//! ```
//! use ambid_core::signal::{ExcitationSpec, PrbsSpec};
//! let spec = ExcitationSpec::Prbs(PrbsSpec {
//!     order: 10, samples_per_bit: 5, periods: 20, amplitude: 0.1, offset: 0.0,
//! });
//! let ts = 50e-6;
//! let report = spec.report(ts).unwrap();
//! assert_eq!(report.period_samples, 5115);
//! assert!((report.resolution_hz - 3.91).abs() < 0.01);
//! let x = spec.generate(ts).unwrap();
//! assert_eq!(x.len(), 20 * 5115);
//! ```

pub mod analysis;
pub mod chirp;
pub mod multi;
pub mod multisine;
pub mod noise;
pub mod period;
pub mod prbs;

pub use analysis::{amplitude_spectrum, autocorrelation, crest_factor, rms};
pub use chirp::{ChirpSpec, Sweep};
pub use multi::{
    hadamard, hadamard_order, AxisLines, BaseSignal, LineCondition, MultiExcitation,
    MultiInputDesign, MultiInputKind, MultiInputReport, MAX_HADAMARD_ORDER, MAX_INPUTS,
};
pub use multisine::{Grid, MultisineSpec, Phases};
pub use noise::{Distribution, NoiseSpec};
pub use period::{detect_period, PeriodScan, PERIOD_TOLERANCE, SCAN_PREFIX};
pub use prbs::{prbs_period, Lfsr, PrbsSpec, MAX_PRBS_ORDER, MIN_PRBS_ORDER};

use crate::error::{Error, Result};
use std::fmt;

/// Largest number of samples any generator in this module will allocate ($2^{28}$, i.e. 2 GiB of
/// `f64`). Larger designs are refused with an [`Error::InvalidArgument`] that says how to shrink them.
pub const MAX_SAMPLES: usize = 1 << 28;

/// A generated excitation: samples, sample time and periodic structure.
///
/// `values.len() == period_samples * periods`; a non-periodic signal (noise) has
/// `period_samples == values.len()` and `periods == 1`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Excitation {
    /// The samples, in the unit of the excitation (e.g. A when injected at the controller output).
    pub values: Vec<f64>,
    /// Sample time in seconds.
    pub ts: f64,
    /// Samples in one period (equal to `values.len()` for a non-periodic signal).
    pub period_samples: usize,
    /// Number of repeated periods.
    pub periods: usize,
}

impl Excitation {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// `true` when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Duration $N T_s$ in seconds.
    pub fn duration_s(&self) -> f64 {
        self.values.len() as f64 * self.ts
    }

    /// Sample rate $f_s = 1/T_s$ in Hz.
    pub fn fs_hz(&self) -> f64 {
        1.0 / self.ts
    }

    /// The samples of period `p` (0-based), or `None` if there is no such period.
    pub fn period(&self, p: usize) -> Option<&[f64]> {
        let start = p.checked_mul(self.period_samples)?;
        let end = start.checked_add(self.period_samples)?;
        self.values.get(start..end)
    }

    /// Sample instants $k T_s$, $k = 0, \dots, N-1$, in seconds.
    pub fn times(&self) -> Vec<f64> {
        (0..self.values.len()).map(|k| k as f64 * self.ts).collect()
    }
}

/// What an excitation design covers: band, resolution, duration and level.
///
/// Frequencies are in Hz, durations in seconds; `rms`, `peak` and `crest_factor` are those of the
/// generated samples (computed exactly from the design where that is possible without generating).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BandReport {
    /// Lowest excited frequency in Hz.
    pub f_min_hz: f64,
    /// Highest usefully excited frequency in Hz.
    pub f_max_hz: f64,
    /// Frequency resolution (spacing of the frequency lines of one period) in Hz.
    pub resolution_hz: f64,
    /// Total duration of all periods in seconds.
    pub duration_s: f64,
    /// Total number of samples.
    pub n_samples: usize,
    /// Samples per period.
    pub period_samples: usize,
    /// Number of periods.
    pub periods: usize,
    /// Root mean square value $\sqrt{\tfrac1N \sum x_k^2}$.
    pub rms: f64,
    /// Peak absolute value $\max_k |x_k|$.
    pub peak: f64,
    /// Crest factor $\max_k |x_k| / \mathrm{rms}$.
    pub crest_factor: f64,
}

impl fmt::Display for BandReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "band          {:.6} Hz .. {:.6} Hz",
            self.f_min_hz, self.f_max_hz
        )?;
        writeln!(f, "resolution    {:.6} Hz", self.resolution_hz)?;
        writeln!(
            f,
            "duration      {:.6} s ({} samples = {} periods x {} samples)",
            self.duration_s, self.n_samples, self.periods, self.period_samples
        )?;
        writeln!(f, "rms           {:.6e}", self.rms)?;
        writeln!(f, "peak          {:.6e}", self.peak)?;
        write!(f, "crest factor  {:.4}", self.crest_factor)
    }
}

/// Any of the four excitation designs, tagged by `kind` when serialised
/// (`{"kind": "prbs", "order": 10, ...}`).
///
/// # Example
/// ```
/// use ambid_core::signal::{ExcitationSpec, NoiseSpec, Distribution};
/// let json = r#"{"kind":"noise","distribution":"gaussian","rms":0.5,"n_samples":1000,
///                "band_hz":null,"seed":7}"#;
/// let spec: ExcitationSpec = serde_json::from_str(json).unwrap();
/// assert!(matches!(spec, ExcitationSpec::Noise(NoiseSpec { distribution: Distribution::Gaussian, .. })));
/// assert_eq!(spec.generate(1e-3).unwrap().len(), 1000);
/// ```
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ExcitationSpec {
    /// Pseudo-random binary sequence.
    Prbs(PrbsSpec),
    /// Swept sine.
    Chirp(ChirpSpec),
    /// Random noise.
    Noise(NoiseSpec),
    /// Multisine on DFT bins.
    Multisine(MultisineSpec),
}

impl ExcitationSpec {
    /// Generates the samples at sample time `ts` (seconds); see each spec's `generate`.
    pub fn generate(&self, ts: f64) -> Result<Excitation> {
        match self {
            ExcitationSpec::Prbs(s) => s.generate(ts),
            ExcitationSpec::Chirp(s) => s.generate(ts),
            ExcitationSpec::Noise(s) => s.generate(ts),
            ExcitationSpec::Multisine(s) => s.generate(ts),
        }
    }

    /// Reports band, resolution, duration and level at sample time `ts`; see each spec's `report`.
    pub fn report(&self, ts: f64) -> Result<BandReport> {
        match self {
            ExcitationSpec::Prbs(s) => s.report(ts),
            ExcitationSpec::Chirp(s) => s.report(ts),
            ExcitationSpec::Noise(s) => s.report(ts),
            ExcitationSpec::Multisine(s) => s.report(ts),
        }
    }
}

impl From<PrbsSpec> for ExcitationSpec {
    fn from(s: PrbsSpec) -> Self {
        ExcitationSpec::Prbs(s)
    }
}
impl From<ChirpSpec> for ExcitationSpec {
    fn from(s: ChirpSpec) -> Self {
        ExcitationSpec::Chirp(s)
    }
}
impl From<NoiseSpec> for ExcitationSpec {
    fn from(s: NoiseSpec) -> Self {
        ExcitationSpec::Noise(s)
    }
}
impl From<MultisineSpec> for ExcitationSpec {
    fn from(s: MultisineSpec) -> Self {
        ExcitationSpec::Multisine(s)
    }
}

// ---------------------------------------------------------------------------------------------
// Shared validation helpers.

/// Checks a sample time: finite and strictly positive.
pub(crate) fn check_ts(ts: f64) -> Result<()> {
    if ts.is_finite() && ts > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            "ts",
            format!("sample time must be a finite number of seconds > 0, got {ts}"),
        ))
    }
}

/// Checks a level (amplitude, rms): finite and strictly positive.
pub(crate) fn check_positive(name: &'static str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            name,
            format!("must be a finite number > 0, got {v}"),
        ))
    }
}

/// Checks a count: at least `min`.
pub(crate) fn check_count(name: &'static str, v: usize, min: usize) -> Result<()> {
    if v >= min {
        Ok(())
    } else {
        Err(Error::invalid(
            name,
            format!("must be at least {min}, got {v}"),
        ))
    }
}

/// `a * b` as the total number of samples, refused above [`MAX_SAMPLES`].
pub(crate) fn total_samples(period_samples: usize, periods: usize, hint: &str) -> Result<usize> {
    match period_samples.checked_mul(periods) {
        Some(n) if n <= MAX_SAMPLES => Ok(n),
        _ => Err(Error::invalid(
            "periods",
            format!(
                "{periods} periods x {period_samples} samples exceed the limit of {MAX_SAMPLES} \
                 samples; {hint}"
            ),
        )),
    }
}

/// Repeats one period `periods` times.
pub(crate) fn repeat_period(period: &[f64], periods: usize) -> Vec<f64> {
    let mut v = Vec::with_capacity(period.len() * periods);
    for _ in 0..periods {
        v.extend_from_slice(period);
    }
    v
}

/// Level statistics `(rms, peak, crest)` of generated samples; crest is 0 for an all-zero signal.
pub(crate) fn level_stats(x: &[f64]) -> (f64, f64, f64) {
    if x.is_empty() {
        return (0.0, 0.0, 0.0);
    }
    let ms = x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64;
    let rms = ms.sqrt();
    let peak = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let crest = if rms > 0.0 { peak / rms } else { 0.0 };
    (rms, peak, crest)
}
