//! Excitation designs for several inputs: sequential, orthogonal (Hadamard) and zippered multisines.
//!
//! A MIMO closed-loop FRF with $n$ excitations $r_1, \dots, r_n$ (one per axis, added at the
//! controller outputs) needs, at every frequency line $k$ where it is evaluated, an input matrix
//! $$ R(k) = \begin{pmatrix} R_{1,1}(k) & \cdots & R_{1,M}(k) \\ \vdots & & \vdots \\
//!    R_{n,1}(k) & \cdots & R_{n,M}(k) \end{pmatrix} \in \mathbb C^{n \times M}, $$
//! $R_{j,e}(k)$ the DFT of one period of input $j$ in experiment $e$, of full row rank: then
//! $T_{ry}(k) = Y(k) R(k)^{+}$ and $S(k) = U(k) R(k)^{+}$ (least squares over the experiments) and
//! $P = T_{ry} S^{-1}$. The smaller its condition number $\kappa(R(k)) = \sigma_{\max}/\sigma_{\min}$,
//! the less the measurement noise is amplified. [`MultiInputDesign`] builds the three classical
//! designs from one periodic base signal $s$ (a [`MultisineSpec`] or a [`PrbsSpec`]) with a level
//! $a_j$ per axis:
//!
//! * **sequential** ($M = n$): experiment $e$ excites axis $e$ only,
//!   $r_j^{(e)} = \delta_{je}\, a_j s$, so $R(k) = s(k) \operatorname{diag}(a)$ and
//!   $\kappa = \max_j a_j / \min_j a_j$ (1 at equal levels);
//! * **orthogonal** ($M$ = the Hadamard order $\ge n$): every axis carries the same signal with the
//!   signs of a Sylvester–Hadamard matrix $H \in \{\pm1\}^{M \times M}$ ($H^\mathsf{T} H = M I$,
//!   [`hadamard`]), $r_j^{(e)} = H_{ej}\, a_j s$, so
//!   $$ R(k) = s(k)\, \operatorname{diag}(a)\, H_{:,1:n}^\mathsf{T}, \qquad R R^\mathsf{H} = M |s(k)|^2 \operatorname{diag}(a)^2, $$
//!   and $\kappa = \max_j a_j / \min_j a_j$ again (1 at equal levels). Sylvester orders are powers of
//!   two, so $n = 3$ uses the order-4 matrix and its first three columns: four experiments (rows),
//!   the same conditioning, one experiment more than sequential;
//! * **zippered multisine** ($M = 1$): one multisine grid $\mathcal K = \{k_0 < k_1 < \dots\}$
//!   (the base [`MultisineSpec`]'s band and grid) is dealt out to the axes in turn, axis $j$
//!   taking the lines $k_i$ with $i \equiv j \pmod n$, each axis with its own Schroeder or random
//!   phases and the amplitude that gives it its RMS $a_j$ on its $F_j$ lines:
//!   $$ r_j(t) = a_j \sqrt{2/F_j} \sum_{i \equiv j\ (n)} \cos\!\Big(\frac{2\pi k_i t}{N} + \varphi_{j,i}\Big). $$
//!   The axes' line sets are disjoint and their union is $\mathcal K$. At a line of axis $j$ only
//!   input $j$ is excited, so one experiment measures column $j$ of $T_{ry}$ and $S$ there, and only
//!   there: the columns live on different lines and must be brought to a common grid before
//!   $P = T_{ry} S^{-1}$ can be formed. Downstream the MIMO FRF (`frf::mimo`, which documents its
//!   exact rule) interpolates each column onto the union of the lines from that column's own
//!   neighbouring lines (a local rational fit, one denominator per column); that assumes the response is smooth over
//!   $n$ line spacings and is biased near resonances sharper than that. The report takes the input matrix of each complete **group** of $n$ consecutive lines
//!   $(k_{gn}, \dots, k_{gn+n-1})$ — one line per axis, column $j$ the inputs' DFT at axis $j$'s line
//!   — which is diagonal, $\kappa = \max_j |R_j| / \min_j |R_j| = \max_j (a_j\sqrt{2/F_j}) / \min_j
//!   (a_j \sqrt{2/F_j})$.
//!
//! # What each costs and gives
//! At equal total measurement time $T$ and equal level $a$ on every axis (docs/signals.md,
//! "Several inputs"): the sequential design spends $T/n$ on each column, the orthogonal design
//! measures every entry from all $M$ experiments, $R R^\mathsf{H} = M |s|^2 a^2 I$, which gives
//! each entry $n\times$ the averaging (a variance $n\times$ smaller) on the same lines; the zipper
//! runs one experiment of length $T$ but gives each axis $1/n$ of the lines (each with
//! $\sqrt{n}\times$ the amplitude at the same RMS, so $n^2\times$ less variance per line than the
//! sequential design) and needs the interpolation above. Every axis is
//! driven at once in the orthogonal and zippered designs: the summed load on the bearings is larger
//! than in the sequential one.
//!
//! Transient periods: a closed loop needs time to reach its periodic steady state. With
//! `transient_periods` $= N_{tr}$ every experiment starts with $N_{tr}$ extra periods (the same
//! periodic signal) that the analysis drops; they count in the durations of [`MultiInputReport`].
//!
//! The single-input case $n = 1$ is the signal of the base spec itself, bit for bit (sequential and
//! orthogonal: $M = 1$, $H = (1)$; zipper: every line on the one axis with the base spec's phases).
//!
//! # Example
//! ```
//! use ambid_core::signal::{BaseSignal, MultiInputDesign, PrbsSpec};
//! let prbs = PrbsSpec { order: 10, samples_per_bit: 5, periods: 4, amplitude: 0.1, offset: 0.0 };
//! let design = MultiInputDesign::orthogonal(4, BaseSignal::Prbs(prbs)).with_transient_periods(1);
//! let ts = 50e-6;
//! let report = design.report(ts).unwrap();
//! assert_eq!(report.experiments, 4);
//! assert_eq!(report.samples_per_experiment, 5 * 5115);
//! assert!((report.total_duration_s - 4.0 * 5.0 * 5115.0 * ts).abs() < 1e-12);
//! assert!((report.max_condition - 1.0).abs() < 1e-9);
//! let x = design.generate(ts).unwrap();
//! let data = x.to_iodata().unwrap(); // channels r_xa, r_xb, r_ya, r_yb; 4 experiments
//! assert_eq!(data.n_experiments(), 4);
//! assert_eq!(data.names(), vec!["r_xa", "r_xb", "r_ya", "r_yb"]);
//! ```

use super::analysis::{real_fft, real_ifft};
use super::multisine::RANDOM_ODD_GROUP;
use super::{
    check_count, check_positive, check_ts, level_stats, repeat_period, Excitation, Grid,
    MultisineSpec, Phases, PrbsSpec, MAX_SAMPLES,
};
use crate::data::{IoData, Role, AXES};
use crate::error::{Error, Result};
use crate::linalg::singular_values;
use faer::Mat;
use num_complex::Complex;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use std::fmt;

/// Largest Hadamard order [`hadamard`] builds ($2^{16}$); far more experiments than any rig runs.
pub const MAX_HADAMARD_ORDER: usize = 1 << 16;

/// Largest number of inputs a [`MultiInputDesign`] takes (1024; a rotor has 4 radial axes).
pub const MAX_INPUTS: usize = 1 << 10;

fn check_inputs(n_inputs: usize) -> Result<()> {
    if n_inputs == 0 {
        return Err(Error::invalid(
            "n_inputs",
            "a design needs at least one input; pass the number of excited axes (4 for a \
             radial rotor: xa, xb, ya, yb)",
        ));
    }
    if n_inputs > MAX_INPUTS {
        return Err(Error::invalid(
            "n_inputs",
            format!(
                "{n_inputs} inputs are more than the {MAX_INPUTS} a design takes; excite fewer \
                 axes"
            ),
        ));
    }
    Ok(())
}

/// The three multi-input designs (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MultiInputKind {
    /// One experiment per axis, each exciting its axis only ($M = n$).
    Sequential,
    /// The same signal on every axis with Hadamard signs, one experiment per row ($M \ge n$, a
    /// power of two).
    Orthogonal,
    /// One experiment, each axis on its own interleaved multisine lines ($M = 1$).
    Zipper,
}

impl MultiInputKind {
    /// The name used in files and on the command line: `sequential`, `orthogonal`, `zipper`.
    pub fn name(self) -> &'static str {
        match self {
            MultiInputKind::Sequential => "sequential",
            MultiInputKind::Orthogonal => "orthogonal",
            MultiInputKind::Zipper => "zipper",
        }
    }
}

impl fmt::Display for MultiInputKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The periodic base signal of a [`MultiInputDesign`], tagged by `kind` when serialised
/// (`{"kind": "multisine", ...}`, `{"kind": "prbs", ...}`).
///
/// Its level field is the level of every axis unless [`MultiInputDesign::levels`] sets one per
/// axis, in the same quantity: the **RMS** of a multisine (`rms`), the **peak** deviation of a
/// PRBS (`amplitude`, equal to its RMS without offset). Its `periods` are the periods that are
/// measured (analysed) in each experiment; [`MultiInputDesign::transient_periods`] come on top.
/// A PRBS offset is part of the signal: multiplied by the Hadamard sign like the rest, absent on
/// an idle axis of a sequential experiment.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum BaseSignal {
    /// A bin-aligned multisine (band, period, grid, phases).
    Multisine(MultisineSpec),
    /// A maximum-length PRBS (order, samples per bit).
    Prbs(PrbsSpec),
}

impl From<MultisineSpec> for BaseSignal {
    fn from(s: MultisineSpec) -> Self {
        BaseSignal::Multisine(s)
    }
}

impl From<PrbsSpec> for BaseSignal {
    fn from(s: PrbsSpec) -> Self {
        BaseSignal::Prbs(s)
    }
}

impl BaseSignal {
    /// The level of the base spec: `rms` of a multisine, `amplitude` (peak) of a PRBS.
    pub fn level(&self) -> f64 {
        match self {
            BaseSignal::Multisine(s) => s.rms,
            BaseSignal::Prbs(s) => s.amplitude,
        }
    }

    /// The measured periods of the base spec.
    pub fn periods(&self) -> usize {
        match self {
            BaseSignal::Multisine(s) => s.periods,
            BaseSignal::Prbs(s) => s.periods,
        }
    }

    /// Samples in one period: `period_samples` of a multisine, $(2^n - 1) N_b$ of a PRBS.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a PRBS order outside `2..=31` or a period above
    /// [`MAX_SAMPLES`].
    pub fn period_samples(&self) -> Result<usize> {
        match self {
            BaseSignal::Multisine(s) => Ok(s.period_samples),
            BaseSignal::Prbs(s) => {
                let len = super::prbs::prbs_length(s.order)?;
                match len.checked_mul(s.samples_per_bit) {
                    Some(n) if n <= MAX_SAMPLES => Ok(n),
                    _ => Err(Error::invalid(
                        "samples_per_bit",
                        format!(
                            "order {} with {} samples per bit gives more than {MAX_SAMPLES} \
                             samples per period; lower the order or samples_per_bit",
                            s.order, s.samples_per_bit
                        ),
                    )),
                }
            }
        }
    }

    /// The same spec with another level and number of periods.
    fn with_level_periods(&self, level: f64, periods: usize) -> BaseSignal {
        match self {
            BaseSignal::Multisine(s) => BaseSignal::Multisine(MultisineSpec {
                rms: level,
                periods,
                ..s.clone()
            }),
            BaseSignal::Prbs(s) => BaseSignal::Prbs(PrbsSpec {
                amplitude: level,
                periods,
                ..s.clone()
            }),
        }
    }

    fn generate(&self, ts: f64) -> Result<Excitation> {
        match self {
            BaseSignal::Multisine(s) => s.generate(ts),
            BaseSignal::Prbs(s) => s.generate(ts),
        }
    }

    /// The DFT bins of one period the signal is designed to excite, ascending: the multisine's
    /// lines ([`MultisineSpec::bins`]); for a PRBS of $L = 2^n - 1$ bits held $N_b$ samples, the
    /// lines of its band $[1/(L N_b T_s),\ 1/(2 N_b T_s)]$, i.e. the bins $1, \dots, \lfloor L/2
    /// \rfloor$ (all non-zero: the envelope's first zero is at bin $L$).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an invalid spec or sample time.
    pub fn bins(&self, ts: f64) -> Result<Vec<usize>> {
        match self {
            BaseSignal::Multisine(s) => s.bins(ts),
            BaseSignal::Prbs(s) => {
                s.report(ts)?; // validates every field and ts
                let len = super::prbs::prbs_length(s.order)?;
                Ok((1..=len / 2).collect())
            }
        }
    }
}

/// A multi-input excitation design: kind, number of inputs, base signal, levels, transient.
///
/// # Requirements
/// `n_inputs` in $1 \dots$ [`MAX_INPUTS`]; a valid base spec (see [`MultisineSpec`],
/// [`PrbsSpec`]); `levels`, when given, one finite level $> 0$ per input; the zipper needs a multisine base with at least
/// `n_inputs` lines; all experiments together at most [`MAX_SAMPLES`] samples (summed over the
/// inputs).
///
/// # Example
/// ```
/// use ambid_core::signal::{BaseSignal, Grid, MultiInputDesign, MultisineSpec, Phases};
/// let ms = MultisineSpec { f_min_hz: 1.0, f_max_hz: 8.0, period_samples: 100, periods: 2,
///                          rms: 0.5, grid: Grid::Full, phases: Phases::Schroeder, seed: 0 };
/// let ts = 0.01; // 1 Hz lines: bins 1..=8
/// let zip = MultiInputDesign::zipper(3, ms);
/// assert_eq!(zip.axis_bins(ts).unwrap(), vec![vec![1, 4, 7], vec![2, 5, 8], vec![3, 6]]);
/// let x = zip.generate(ts).unwrap();
/// assert_eq!(x.n_experiments(), 1);
/// assert_eq!(x.signal(0, 2).unwrap().len(), 200);
/// ```
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MultiInputDesign {
    /// Sequential, orthogonal or zipper.
    pub kind: MultiInputKind,
    /// Number of inputs (axes) $n \ge 1$.
    pub n_inputs: usize,
    /// The periodic base signal (its level is every axis's level unless `levels` is set).
    pub base: BaseSignal,
    /// Level per axis (RMS for a multisine, peak for a PRBS); `None`: the base's level on every
    /// axis.
    #[serde(default)]
    pub levels: Option<Vec<f64>>,
    /// Periods generated at the start of every experiment to let the loop settle (to be dropped).
    #[serde(default)]
    pub transient_periods: usize,
}

impl MultiInputDesign {
    /// A sequential design of `n_inputs` axes (one experiment per axis).
    pub fn sequential(n_inputs: usize, base: impl Into<BaseSignal>) -> Self {
        Self::new(MultiInputKind::Sequential, n_inputs, base.into())
    }

    /// An orthogonal (Hadamard) design of `n_inputs` axes.
    pub fn orthogonal(n_inputs: usize, base: impl Into<BaseSignal>) -> Self {
        Self::new(MultiInputKind::Orthogonal, n_inputs, base.into())
    }

    /// A zippered multisine of `n_inputs` axes on the lines of `multisine`.
    pub fn zipper(n_inputs: usize, multisine: MultisineSpec) -> Self {
        Self::new(
            MultiInputKind::Zipper,
            n_inputs,
            BaseSignal::Multisine(multisine),
        )
    }

    /// A design of `kind` with the base's level on every axis and no transient periods.
    pub fn new(kind: MultiInputKind, n_inputs: usize, base: BaseSignal) -> Self {
        MultiInputDesign {
            kind,
            n_inputs,
            base,
            levels: None,
            transient_periods: 0,
        }
    }

    /// The design with one level per axis (RMS for a multisine, peak for a PRBS).
    pub fn with_levels(mut self, levels: Vec<f64>) -> Self {
        self.levels = Some(levels);
        self
    }

    /// The design with `periods` transient periods at the start of every experiment.
    pub fn with_transient_periods(mut self, periods: usize) -> Self {
        self.transient_periods = periods;
        self
    }

    /// Checks every field against sample time `ts` (see the type's requirements).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the field and what to do; [`Error::DimensionMismatch`]
    /// for a level list of the wrong length.
    pub fn validate(&self, ts: f64) -> Result<()> {
        check_ts(ts)?;
        check_inputs(self.n_inputs)?;
        if let Some(levels) = &self.levels {
            if levels.len() != self.n_inputs {
                return Err(Error::DimensionMismatch {
                    context: "MultiInputDesign levels (one per input)",
                    expected: format!("{} levels", self.n_inputs),
                    got: format!("{} levels", levels.len()),
                });
            }
            for &l in levels {
                check_positive("levels", l)?;
            }
        } else {
            check_positive("level", self.base.level())?;
        }
        check_count("periods", self.base.periods(), 1)?;
        if self.kind == MultiInputKind::Zipper && !matches!(self.base, BaseSignal::Multisine(_)) {
            return Err(Error::invalid(
                "base",
                "the zipper deals the lines of a multisine out to the axes, so its base must be a \
                 multisine; use BaseSignal::Multisine, or the sequential or orthogonal design for \
                 a PRBS",
            ));
        }
        let bins = self.base.bins(ts)?;
        if self.kind == MultiInputKind::Zipper && bins.len() < self.n_inputs {
            return Err(Error::invalid(
                "period_samples",
                format!(
                    "the zipper needs at least one line per input, and the multisine has {} \
                     line(s) for {} inputs; lengthen the period (period_samples) or widen the \
                     band to get more lines, or use the orthogonal design",
                    bins.len(),
                    self.n_inputs
                ),
            ));
        }
        let m = self.n_experiments()?;
        let p = self.base.period_samples()?;
        let total = self.total_periods()?;
        let all = p
            .checked_mul(total)
            .and_then(|v| v.checked_mul(m))
            .and_then(|v| v.checked_mul(self.n_inputs));
        match all {
            Some(v) if v <= MAX_SAMPLES => Ok(()),
            _ => Err(Error::invalid(
                "periods",
                format!(
                    "{m} experiments x {} inputs x {total} periods x {p} samples exceed the \
                     limit of {MAX_SAMPLES} samples; use fewer periods, a shorter period or \
                     fewer inputs",
                    self.n_inputs
                ),
            )),
        }
    }

    /// Measured plus transient periods per experiment.
    fn total_periods(&self) -> Result<usize> {
        self.base
            .periods()
            .checked_add(self.transient_periods)
            .ok_or_else(|| {
                Error::invalid(
                    "transient_periods",
                    "periods + transient_periods overflows; use fewer periods",
                )
            })
    }

    /// The level of axis `j`.
    fn level(&self, j: usize) -> f64 {
        match &self.levels {
            Some(l) => l[j],
            None => self.base.level(),
        }
    }

    /// Number of experiments $M$: $n$ (sequential), the Hadamard order (orthogonal, the smallest
    /// power of two $\ge n$), 1 (zipper).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for `n_inputs` $= 0$ or above [`MAX_INPUTS`].
    pub fn n_experiments(&self) -> Result<usize> {
        check_inputs(self.n_inputs)?;
        match self.kind {
            MultiInputKind::Sequential => Ok(self.n_inputs),
            MultiInputKind::Orthogonal => hadamard_order(self.n_inputs),
            MultiInputKind::Zipper => Ok(1),
        }
    }

    /// The $M \times n$ weights $W$ with $r_j^{(e)} = W_{ej}\, a_j s$: the identity (sequential),
    /// the first $n$ columns of the Hadamard matrix (orthogonal), one row of ones (zipper, where
    /// each axis carries its own lines).
    ///
    /// # Errors
    /// As [`MultiInputDesign::n_experiments`].
    ///
    /// # Example
    /// ```
    /// use ambid_core::signal::{BaseSignal, MultiInputDesign, PrbsSpec};
    /// let d = MultiInputDesign::orthogonal(3, BaseSignal::Prbs(PrbsSpec::default()));
    /// let w = d.weights().unwrap();
    /// assert_eq!(w, vec![vec![1.0, 1.0, 1.0], vec![1.0, -1.0, 1.0],
    ///                    vec![1.0, 1.0, -1.0], vec![1.0, -1.0, -1.0]]);
    /// ```
    pub fn weights(&self) -> Result<Vec<Vec<f64>>> {
        let n = self.n_inputs;
        let m = self.n_experiments()?;
        Ok(match self.kind {
            MultiInputKind::Sequential => (0..m)
                .map(|e| (0..n).map(|j| if e == j { 1.0 } else { 0.0 }).collect())
                .collect(),
            MultiInputKind::Orthogonal => hadamard(m)?
                .into_iter()
                .map(|row| row[..n].to_vec())
                .collect(),
            MultiInputKind::Zipper => vec![vec![1.0; n]],
        })
    }

    /// The excited DFT bins of each axis (bin $k$ is at $k/(N T_s)$ Hz, $N$ the period): every
    /// axis has the base's bins ([`BaseSignal::bins`]) in the sequential and orthogonal designs;
    /// in the zipper axis $j$ has the base lines of index $i \equiv j \pmod n$.
    ///
    /// # Errors
    /// As [`MultiInputDesign::validate`].
    pub fn axis_bins(&self, ts: f64) -> Result<Vec<Vec<usize>>> {
        self.validate(ts)?;
        let bins = self.base.bins(ts)?;
        let n = self.n_inputs;
        Ok(match self.kind {
            MultiInputKind::Zipper => (0..n)
                .map(|j| bins.iter().skip(j).step_by(n).copied().collect())
                .collect(),
            _ => vec![bins; n],
        })
    }

    /// Generates every experiment at sample time `ts`: per experiment and axis
    /// `transient_periods + periods` periods of the base period.
    ///
    /// # Errors
    /// As [`MultiInputDesign::validate`].
    pub fn generate(&self, ts: f64) -> Result<MultiExcitation> {
        let axis_bins = self.axis_bins(ts)?;
        let n = self.n_inputs;
        let weights = self.weights()?;
        let period_samples = self.base.period_samples()?;
        let total = self.total_periods()?;
        let per_axis: Vec<Vec<f64>> = match self.kind {
            MultiInputKind::Zipper => {
                let BaseSignal::Multisine(ms) = &self.base else {
                    // validate() refuses a zipper on a PRBS.
                    return Err(Error::invalid("base", "the zipper needs a multisine base"));
                };
                (0..n)
                    .map(|j| {
                        let period = zipper_period(ms, ts, j, &axis_bins[j], self.level(j))?;
                        Ok(repeat_period(&period, total))
                    })
                    .collect::<Result<_>>()?
            }
            _ => (0..n)
                .map(|j| {
                    Ok(self
                        .base
                        .with_level_periods(self.level(j), total)
                        .generate(ts)?
                        .values)
                })
                .collect::<Result<_>>()?,
        };
        let samples = weights
            .iter()
            .map(|row| {
                row.iter()
                    .zip(&per_axis)
                    .map(|(&w, x)| {
                        if w == 1.0 {
                            x.clone()
                        } else if w == -1.0 {
                            x.iter().map(|v| -v).collect()
                        } else {
                            vec![0.0; x.len()]
                        }
                    })
                    .collect()
            })
            .collect();
        Ok(MultiExcitation {
            kind: self.kind,
            ts,
            period_samples,
            periods: self.base.periods(),
            transient_periods: self.transient_periods,
            axis_bins,
            weights,
            samples,
        })
    }

    /// Experiments, durations, lines per axis, the input matrix's condition number per line and
    /// the crest factor per axis, computed from the generated signals (the DFT of one period of
    /// every input in every experiment).
    ///
    /// # Errors
    /// As [`MultiInputDesign::validate`]; [`Error::Numerical`] if an SVD fails.
    pub fn report(&self, ts: f64) -> Result<MultiInputReport> {
        self.generate(ts)?.report()
    }
}

/// One period of axis `j` of a zippered multisine: its `bins`, RMS `level`, Schroeder phases over
/// its own lines or random phases from stream `j` of the spec's seed.
fn zipper_period(
    ms: &MultisineSpec,
    ts: f64,
    j: usize,
    bins: &[usize],
    level: f64,
) -> Result<Vec<f64>> {
    let n = ms.period_samples;
    let f = bins.len();
    let amp = level * (2.0 / f as f64).sqrt();
    let mag = amp * n as f64 / 2.0;
    let mut rng = if ms.phases == Phases::Random {
        Some(phase_rng(ms, ts, j)?)
    } else {
        None
    };
    let mut half = vec![Complex::new(0.0, 0.0); n / 2 + 1];
    for (i, &k) in bins.iter().enumerate() {
        let phi = match rng.as_mut() {
            None => {
                let i1 = (i + 1) as f64;
                -PI * i1 * (i1 - 1.0) / f as f64
            }
            Some(r) => r.random_range(0.0..2.0 * PI),
        };
        half[k] = Complex::from_polar(mag, phi);
    }
    real_ifft(&half, n)
}

/// The phase generator of zipper axis `j`: stream `j` of the spec's seed, advanced past the draws
/// the random-odd grid makes (one per complete group), so that axis 0 of a one-input zipper draws
/// exactly the phases [`MultisineSpec::generate`] draws.
fn phase_rng(ms: &MultisineSpec, ts: f64, j: usize) -> Result<ChaCha8Rng> {
    let mut rng = ChaCha8Rng::seed_from_u64(ms.seed);
    rng.set_stream(j as u64);
    if ms.grid == Grid::RandomOdd {
        let odd = MultisineSpec {
            grid: Grid::Odd,
            ..ms.clone()
        }
        .bins(ts)?;
        for _ in 0..odd.len() / RANDOM_ODD_GROUP {
            let _ = rng.random_range(0..RANDOM_ODD_GROUP);
        }
    }
    Ok(rng)
}

/// Order of the Sylvester–Hadamard matrix used for `n_inputs` inputs: the smallest power of two
/// $\ge n$ (1, 2, 4, 4, 8, …).
///
/// # Errors
/// [`Error::InvalidArgument`] for 0 inputs or an order above [`MAX_HADAMARD_ORDER`].
///
/// # Example
/// ```
/// use ambid_core::signal::hadamard_order;
/// assert_eq!([1, 2, 3, 4, 5].map(|n| hadamard_order(n).unwrap()), [1, 2, 4, 4, 8]);
/// ```
pub fn hadamard_order(n_inputs: usize) -> Result<usize> {
    if n_inputs == 0 {
        return Err(Error::invalid(
            "n_inputs",
            "a design needs at least one input",
        ));
    }
    if n_inputs > MAX_HADAMARD_ORDER {
        return Err(Error::invalid(
            "n_inputs",
            format!(
                "{n_inputs} inputs need a Hadamard order above {MAX_HADAMARD_ORDER}; use fewer \
                 inputs"
            ),
        ));
    }
    Ok(n_inputs.next_power_of_two())
}

/// The Sylvester–Hadamard matrix of order $M = 2^m$ as rows of $\pm 1$:
/// $H_1 = (1)$, $H_{2M} = \begin{pmatrix} H_M & H_M \\ H_M & -H_M \end{pmatrix}$, i.e.
/// $H_{ij} = (-1)^{\operatorname{popcount}(i \wedge j)}$. It is symmetric and
/// $H^\mathsf{T} H = M I$; its first row and column are all ones.
///
/// # Errors
/// [`Error::InvalidArgument`] unless `order` is a power of two in $1 \dots$ [`MAX_HADAMARD_ORDER`]
/// (Sylvester's construction has no other orders; use [`hadamard_order`] to round up).
///
/// # Example
/// ```
/// use ambid_core::signal::hadamard;
/// assert_eq!(hadamard(2).unwrap(), vec![vec![1.0, 1.0], vec![1.0, -1.0]]);
/// assert!(hadamard(3).is_err());
/// ```
pub fn hadamard(order: usize) -> Result<Vec<Vec<f64>>> {
    if !order.is_power_of_two() || order > MAX_HADAMARD_ORDER {
        return Err(Error::invalid(
            "order",
            format!(
                "a Sylvester-Hadamard matrix has an order that is a power of two up to \
                 {MAX_HADAMARD_ORDER}, got {order}; round up with hadamard_order and use the \
                 first columns"
            ),
        ));
    }
    Ok((0..order)
        .map(|i| {
            (0..order)
                .map(|j| {
                    if (i & j).count_ones() % 2 == 0 {
                        1.0
                    } else {
                        -1.0
                    }
                })
                .collect()
        })
        .collect())
}

/// The generated signals of a [`MultiInputDesign`] ([`MultiInputDesign::generate`]).
///
/// [`MultiExcitation::signal`]`(e, j)` is input (axis) $j$ in experiment $e$:
/// `(transient_periods + periods) * period_samples` samples at `ts`, the first `transient_periods`
/// periods to be dropped.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MultiExcitation {
    kind: MultiInputKind,
    ts: f64,
    period_samples: usize,
    periods: usize,
    transient_periods: usize,
    axis_bins: Vec<Vec<usize>>,
    weights: Vec<Vec<f64>>,
    samples: Vec<Vec<Vec<f64>>>,
}

impl MultiExcitation {
    /// The design kind.
    pub fn kind(&self) -> MultiInputKind {
        self.kind
    }

    /// Sample time in seconds.
    pub fn ts(&self) -> f64 {
        self.ts
    }

    /// Samples per period.
    pub fn period_samples(&self) -> usize {
        self.period_samples
    }

    /// Measured periods per experiment (after the transient).
    pub fn periods(&self) -> usize {
        self.periods
    }

    /// Transient periods at the start of every experiment.
    pub fn transient_periods(&self) -> usize {
        self.transient_periods
    }

    /// Excited DFT bins (of one period) per axis ([`MultiInputDesign::axis_bins`]).
    pub fn axis_bins(&self) -> &[Vec<usize>] {
        &self.axis_bins
    }

    /// The $M \times n$ weights ([`MultiInputDesign::weights`]).
    pub fn weights(&self) -> &[Vec<f64>] {
        &self.weights
    }

    /// All samples: `samples()[e][j]` is input $j$ in experiment $e$, transient included.
    pub fn samples(&self) -> &[Vec<Vec<f64>>] {
        &self.samples
    }

    /// The samples, consumed (`[e][j]`, as [`MultiExcitation::samples`]).
    pub fn into_samples(self) -> Vec<Vec<Vec<f64>>> {
        self.samples
    }

    /// Number of experiments $M$.
    pub fn n_experiments(&self) -> usize {
        self.samples.len()
    }

    /// Number of inputs $n$.
    pub fn n_inputs(&self) -> usize {
        self.axis_bins.len()
    }

    /// Samples per experiment (transient included).
    pub fn samples_per_experiment(&self) -> usize {
        self.period_samples * (self.periods + self.transient_periods)
    }

    /// Duration of all experiments, transient included, in seconds.
    pub fn total_duration_s(&self) -> f64 {
        (self.n_experiments() * self.samples_per_experiment()) as f64 * self.ts
    }

    /// All samples of input `j` in experiment `e` (transient included), `None` if out of range.
    pub fn signal(&self, e: usize, j: usize) -> Option<&[f64]> {
        self.samples.get(e)?.get(j).map(|v| v.as_slice())
    }

    /// The measured part (transient dropped) of input `j` in experiment `e`.
    pub fn measured(&self, e: usize, j: usize) -> Option<&[f64]> {
        let x = self.signal(e, j)?;
        x.get(self.transient_periods * self.period_samples..)
    }

    /// Input `j` of experiment `e` as a single-input [`Excitation`] (all its periods, transient
    /// included); for $n = 1$ this is the base spec's own signal.
    pub fn excitation(&self, e: usize, j: usize) -> Option<Excitation> {
        Some(Excitation {
            values: self.signal(e, j)?.to_vec(),
            ts: self.ts,
            period_samples: self.period_samples,
            periods: self.periods + self.transient_periods,
        })
    }

    /// The excitation channels of experiment `e` named `r_<axis>` for the given axis names (one per
    /// input), ready to be joined with the measured `u_<axis>`, `y_<axis>` channels.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for no experiment `e`, or axis names that are not one distinct,
    /// non-empty name per input.
    pub fn channels(&self, e: usize, axes: &[&str]) -> Result<Vec<(String, Vec<f64>)>> {
        self.check_axes(axes)?;
        let exp = self.samples.get(e).ok_or_else(|| {
            Error::invalid(
                "experiment",
                format!(
                    "there is no experiment {e}; the design has {} (0-based)",
                    self.n_experiments()
                ),
            )
        })?;
        Ok(axes
            .iter()
            .zip(exp)
            .map(|(a, x)| (format!("r_{a}"), x.clone()))
            .collect())
    }

    fn check_axes(&self, axes: &[&str]) -> Result<()> {
        if axes.len() != self.n_inputs() {
            return Err(Error::invalid(
                "axes",
                format!(
                    "{} axis names were given for {} inputs; pass one name per input (e.g. {:?})",
                    axes.len(),
                    self.n_inputs(),
                    &AXES[..self.n_inputs().min(AXES.len())]
                ),
            ));
        }
        for (i, a) in axes.iter().enumerate() {
            if a.trim().is_empty() || axes[..i].contains(a) {
                return Err(Error::invalid(
                    "axes",
                    format!("axis names must be distinct and non-empty, got {axes:?}"),
                ));
            }
        }
        Ok(())
    }

    /// All experiments as one [`IoData`] with channels `r_xa, r_xb, …` (the first $n$ of
    /// [`AXES`]) and the period length set.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for more than 4 inputs (name them with
    /// [`MultiExcitation::to_iodata_with_axes`]).
    pub fn to_iodata(&self) -> Result<IoData> {
        if self.n_inputs() > AXES.len() {
            return Err(Error::invalid(
                "axes",
                format!(
                    "{} inputs but only {} default axis names ({AXES:?}); name the axes with \
                     to_iodata_with_axes",
                    self.n_inputs(),
                    AXES.len()
                ),
            ));
        }
        self.to_iodata_with_axes(&AXES[..self.n_inputs()])
    }

    /// All experiments as one [`IoData`] with channels `r_<axis>` for the given axis names, every
    /// one of role [`Role::Excitation`] (set explicitly for names outside [`AXES`]), and the period
    /// length set. The transient periods are included (drop them downstream).
    ///
    /// # Errors
    /// As [`MultiExcitation::channels`].
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::Role;
    /// use ambid_core::signal::{BaseSignal, MultiInputDesign, PrbsSpec};
    /// let prbs = PrbsSpec { order: 3, samples_per_bit: 1, periods: 2, amplitude: 1.0, offset: 0.0 };
    /// let x = MultiInputDesign::sequential(2, BaseSignal::Prbs(prbs)).generate(1e-3).unwrap();
    /// let d = x.to_iodata_with_axes(&["left", "right"]).unwrap();
    /// assert_eq!(d.role_names(Role::Excitation), vec!["r_left", "r_right"]);
    /// assert_eq!(d.experiment(1).unwrap().channel("r_left").unwrap(), &[0.0; 14]);
    /// ```
    pub fn to_iodata_with_axes(&self, axes: &[&str]) -> Result<IoData> {
        self.check_axes(axes)?;
        let exps = (0..self.n_experiments())
            .map(|e| {
                let ch = self.channels(e, axes)?;
                let names: Vec<String> = ch.iter().map(|(n, _)| n.clone()).collect();
                let mut d = IoData::new(ch, self.ts, Some(self.period_samples))?;
                for n in &names {
                    if Role::infer(n) != Role::Excitation {
                        d = d.with_role(n, Role::Excitation)?;
                    }
                }
                Ok(d)
            })
            .collect::<Result<Vec<_>>>()?;
        IoData::from_experiments(exps)
    }

    /// The report of these signals (see [`MultiInputDesign::report`]).
    ///
    /// # Errors
    /// [`Error::Numerical`] if an SVD fails.
    pub fn report(&self) -> Result<MultiInputReport> {
        let n = self.n_inputs();
        let m = self.n_experiments();
        let p = self.period_samples;
        let start = self.transient_periods * p;
        // DFT of one measured period of every input in every experiment.
        let spectra: Vec<Vec<Vec<Complex<f64>>>> = self
            .samples
            .iter()
            .map(|exp| {
                exp.iter()
                    .map(|x| real_fft(&x[start..start + p]))
                    .collect::<Result<_>>()
            })
            .collect::<Result<_>>()?;
        let df = 1.0 / (p as f64 * self.ts);
        let axes = (0..n)
            .map(|j| {
                let e = self
                    .weights
                    .iter()
                    .position(|w| w[j] != 0.0)
                    .unwrap_or_default();
                let (rms, peak, crest) = level_stats(&self.samples[e][j][start..start + p]);
                let bins = self.axis_bins[j].clone();
                AxisLines {
                    lines_hz: bins.iter().map(|&k| k as f64 * df).collect(),
                    bins,
                    rms,
                    peak,
                    crest_factor: crest,
                }
            })
            .collect::<Vec<_>>();
        // (bins of the matrix's columns: one per experiment at one line, or one per axis)
        let columns: Vec<Vec<(usize, usize)>> = match self.kind {
            MultiInputKind::Zipper => {
                let groups = self.axis_bins.iter().map(Vec::len).min().unwrap_or(0);
                (0..groups)
                    .map(|g| (0..n).map(|j| (0, self.axis_bins[j][g])).collect())
                    .collect()
            }
            _ => self.axis_bins[0]
                .iter()
                .map(|&k| (0..m).map(|e| (e, k)).collect())
                .collect(),
        };
        let condition = columns
            .iter()
            .map(|cols| {
                let r: Vec<Vec<Complex<f64>>> = cols
                    .iter()
                    .map(|&(e, k)| (0..n).map(|i| spectra[e][i][k]).collect())
                    .collect();
                let mut bins: Vec<usize> = cols.iter().map(|&(_, k)| k).collect();
                bins.dedup();
                Ok(LineCondition {
                    f_hz: bins.iter().map(|&k| k as f64 * df).sum::<f64>() / bins.len() as f64,
                    bins,
                    cond: condition_number(&r)?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let max_condition = condition.iter().fold(0.0f64, |a, c| a.max(c.cond));
        let per_exp = self.samples_per_experiment();
        let total_samples = per_exp * m;
        Ok(MultiInputReport {
            kind: self.kind,
            n_inputs: n,
            experiments: m,
            period_samples: p,
            periods: self.periods,
            transient_periods: self.transient_periods,
            samples_per_experiment: per_exp,
            total_samples,
            total_duration_s: total_samples as f64 * self.ts,
            measured_duration_s: (m * self.periods * p) as f64 * self.ts,
            resolution_hz: df,
            axes,
            condition,
            max_condition,
        })
    }
}

/// $\kappa = \sigma_{\max}/\sigma_{\min}$ of the $n \times M$ complex matrix given by its columns
/// (`cols[c][i]` = row $i$ of column $c$), through the real $2n \times 2M$ embedding
/// $\begin{pmatrix} \Re & -\Im \\ \Im & \Re \end{pmatrix}$, whose singular values are those of the
/// complex matrix, each twice. Infinite for a numerically rank-deficient matrix
/// ($\sigma_{\min} \le 4 M \varepsilon\, \sigma_{\max}$) and for fewer columns than rows.
fn condition_number(cols: &[Vec<Complex<f64>>]) -> Result<f64> {
    let mcols = cols.len();
    let n = cols.first().map_or(0, Vec::len);
    if n == 0 || mcols < n {
        return Ok(f64::INFINITY);
    }
    let a = Mat::from_fn(2 * n, 2 * mcols, |i, c| {
        let z = cols[c % mcols][i % n];
        match (i < n, c < mcols) {
            (true, true) | (false, false) => z.re,
            (true, false) => -z.im,
            (false, true) => z.im,
        }
    });
    let s = singular_values(a.as_ref())?;
    let (max, min) = (s[0], s[2 * n - 1]);
    // Numerically singular (rank below n in floating point): infinite.
    let tol = 2.0 * (2 * mcols) as f64 * f64::EPSILON * max;
    Ok(if min > tol { max / min } else { f64::INFINITY })
}

/// The lines and level of one axis of a design.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AxisLines {
    /// Excited DFT bins of one period.
    pub bins: Vec<usize>,
    /// Their frequencies in Hz.
    pub lines_hz: Vec<f64>,
    /// RMS of one period (in an experiment where the axis is excited).
    pub rms: f64,
    /// Peak absolute value of one period.
    pub peak: f64,
    /// Crest factor peak / RMS.
    pub crest_factor: f64,
}

/// The condition number of the input matrix at one line (or one zipper group).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LineCondition {
    /// The bins of the matrix's columns: the one line (sequential, orthogonal), or one line per
    /// axis (zipper group $g$: lines $k_{gn}, \dots, k_{gn+n-1}$, axis $j$'s at position $j$).
    pub bins: Vec<usize>,
    /// The mean frequency of `bins` in Hz.
    pub f_hz: f64,
    /// $\kappa = \sigma_{\max}/\sigma_{\min}$ of the input matrix ($\infty$ when numerically
    /// singular, $\sigma_{\min} \le 4 M \varepsilon\, \sigma_{\max}$; serialised as `null` in JSON).
    pub cond: f64,
}

/// What a multi-input design costs and gives (see [`MultiInputDesign::report`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MultiInputReport {
    /// Design kind.
    pub kind: MultiInputKind,
    /// Number of inputs $n$.
    pub n_inputs: usize,
    /// Number of experiments $M$.
    pub experiments: usize,
    /// Samples per period.
    pub period_samples: usize,
    /// Measured periods per experiment.
    pub periods: usize,
    /// Transient periods per experiment (generated, to be dropped).
    pub transient_periods: usize,
    /// Samples per experiment, transient included.
    pub samples_per_experiment: usize,
    /// Samples of all experiments (per input), transient included.
    pub total_samples: usize,
    /// Duration of all experiments, transient included, in seconds.
    pub total_duration_s: f64,
    /// Duration of the measured periods of all experiments, in seconds.
    pub measured_duration_s: f64,
    /// Line spacing $1/(N T_s)$ in Hz.
    pub resolution_hz: f64,
    /// Lines and level per axis.
    pub axes: Vec<AxisLines>,
    /// Condition number of the input matrix per excited line (sequential, orthogonal: the
    /// $n \times M$ matrix of the inputs' DFT over the experiments) or per complete group of $n$
    /// consecutive lines (zipper: the $n \times n$ matrix whose column $j$ is the inputs' DFT at
    /// axis $j$'s line).
    pub condition: Vec<LineCondition>,
    /// The largest condition number over the lines.
    pub max_condition: f64,
}

impl fmt::Display for MultiInputReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "design        {} ({} inputs, {} experiment(s))",
            self.kind, self.n_inputs, self.experiments
        )?;
        writeln!(
            f,
            "duration      {:.6} s in all ({} experiment(s) x {} samples = {} + {} transient \
             periods x {} samples); measured {:.6} s",
            self.total_duration_s,
            self.experiments,
            self.samples_per_experiment,
            self.periods,
            self.transient_periods,
            self.period_samples,
            self.measured_duration_s
        )?;
        writeln!(f, "resolution    {:.6} Hz", self.resolution_hz)?;
        for (j, a) in self.axes.iter().enumerate() {
            let lo = a.lines_hz.first().copied().unwrap_or(0.0);
            let hi = a.lines_hz.last().copied().unwrap_or(0.0);
            writeln!(
                f,
                "input {j}       {} lines {:.6} .. {:.6} Hz, rms {:.6e}, peak {:.6e}, crest {:.4}",
                a.bins.len(),
                lo,
                hi,
                a.rms,
                a.peak,
                a.crest_factor
            )?;
        }
        write!(
            f,
            "condition     max {:.6} over {} {}",
            self.max_condition,
            self.condition.len(),
            if self.kind == MultiInputKind::Zipper {
                "line groups"
            } else {
                "lines"
            }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// κ of a 2×2 complex matrix from the closed form of its Gram matrix's eigenvalues:
    /// $\lambda_\pm = (t \pm \sqrt{t^2 - 4d})/2$, $t = \|A\|_F^2$, $d = |\det A|^2$.
    fn cond2_oracle(a: [[Complex<f64>; 2]; 2]) -> f64 {
        let t: f64 = a.iter().flatten().map(|z| z.norm_sqr()).sum();
        let d = (a[0][0] * a[1][1] - a[0][1] * a[1][0]).norm_sqr();
        let disc = (t * t - 4.0 * d).max(0.0).sqrt();
        (((t + disc) / 2.0) / ((t - disc) / 2.0)).sqrt()
    }

    #[test]
    fn condition_number_matches_closed_form() {
        let c = |re: f64, im: f64| Complex::new(re, im);
        let mats = [
            [[c(3.0, 0.0), c(0.0, 0.0)], [c(0.0, 0.0), c(1.0, 1.0)]],
            [[c(1.0, 2.0), c(-0.5, 0.3)], [c(0.2, -1.0), c(2.0, 0.1)]],
            [[c(1.0, 0.0), c(1.0, 0.0)], [c(1.0, 0.0), c(-1.0, 0.0)]],
        ];
        for a in mats {
            // Columns of the matrix for condition_number.
            let cols = vec![vec![a[0][0], a[1][0]], vec![a[0][1], a[1][1]]];
            let k = condition_number(&cols).unwrap();
            let want = cond2_oracle(a);
            assert!((k - want).abs() < 1e-12 * want, "{k} vs {want}");
        }
        // diag(3, 1+i): 3/sqrt(2).
        let k = condition_number(&[
            vec![c(3.0, 0.0), c(0.0, 0.0)],
            vec![c(0.0, 0.0), c(1.0, 1.0)],
        ])
        .unwrap();
        assert!((k - 3.0 / 2f64.sqrt()).abs() < 1e-12);
        // Two identical experiments of a 2-input design: rank 1, infinite.
        let col = vec![c(1.0, 0.5), c(-2.0, 0.1)];
        assert_eq!(
            condition_number(&[col.clone(), col]).unwrap(),
            f64::INFINITY
        );
        // Fewer experiments than inputs: infinite.
        assert_eq!(
            condition_number(&[vec![c(1.0, 0.0), c(0.0, 1.0)]]).unwrap(),
            f64::INFINITY
        );
    }

    #[test]
    fn zipper_axes_draw_their_own_random_phases() {
        let ms = MultisineSpec {
            f_min_hz: 1.0,
            f_max_hz: 40.0,
            period_samples: 100,
            periods: 1,
            rms: 1.0,
            grid: Grid::Full,
            phases: Phases::Random,
            seed: 5,
        };
        let x = MultiInputDesign::zipper(2, ms).generate(0.01).unwrap();
        let phase = |j: usize, i: usize| {
            let spec = real_fft(x.signal(0, j).unwrap()).unwrap();
            spec[x.axis_bins()[j][i]].arg()
        };
        // Stream 0 and stream 1 of one seed: the first phases differ.
        assert!((phase(0, 0) - phase(1, 0)).abs() > 1e-3);
        assert!((phase(0, 1) - phase(1, 1)).abs() > 1e-3);
    }

    #[test]
    fn sequential_weights_are_the_identity() {
        let d = MultiInputDesign::sequential(3, PrbsSpec::default());
        assert_eq!(
            d.weights().unwrap(),
            vec![
                vec![1.0, 0.0, 0.0],
                vec![0.0, 1.0, 0.0],
                vec![0.0, 0.0, 1.0]
            ]
        );
        assert_eq!(
            MultiInputDesign::zipper(
                3,
                MultisineSpec {
                    f_min_hz: 1.0,
                    f_max_hz: 4.0,
                    period_samples: 16,
                    periods: 1,
                    rms: 1.0,
                    grid: Grid::Full,
                    phases: Phases::Schroeder,
                    seed: 0
                }
            )
            .weights()
            .unwrap(),
            vec![vec![1.0; 3]]
        );
    }
}
