//! The robust Best Linear Approximation (BLA) of a nonlinear system from $M$ random-phase
//! multisine realisations of $P$ periods each, in open loop ($u \to y$) or in closed loop with the
//! excitation $r$ as the reference.
//!
//! # Method
//! For every realisation $m = 1..M$ the record is cut into periods (leading transient periods
//! dropped) and averaged synchronously ([`periodic`](super::periodic)). On every excited line $k$
//! this gives the realisation's FRF $\hat G_m(k)$ and its **noise** variance $\hat\sigma^2_{n,m}(k)$
//! from the spread over the $P$ periods (variance of the period mean, first-order propagation
//! through the ratio, exactly as [`closed_loop::from_periodic`](super::closed_loop::from_periodic)):
//!
//! * open loop: $\hat G_m = \bar Y_m / \bar U_m$;
//! * closed loop ($u = C(w-y) + r$): $\hat T_{ry,m} = \bar Y_m/\bar R_m$, $\hat T_{ru,m} = \bar U_m/\bar R_m$,
//!   and the plant $\hat G_m = \hat T_{ry,m}/\hat T_{ru,m} = \bar Y_m/\bar U_m$. Because $r$ is the
//!   exactly periodic, noise-free reference, the ratio of the two $r$-referenced FRFs equals the
//!   ratio of the averaged cross-spectra $\bar Y\bar R^*/\bar U \bar R^*$; the ratio is taken per
//!   realisation (not of $M$-averaged spectra) because the phases of $\bar R_m$ change from one
//!   realisation to the next, so only the per-realisation ratio is a sample of the BLA.
//!
//! Then over the realisations (Pintelon & Schoukens 2012, Sec. 4.3; Schoukens et al. 2012):
//!
//! $$\hat G_{\mathrm{BLA}}(k) = \frac1M\sum_{m=1}^M \hat G_m(k),\qquad
//!   \hat\sigma^2_{\mathrm{BLA}}(k) = \frac{1}{M(M-1)}\sum_{m=1}^M \big|\hat G_m(k) - \hat G_{\mathrm{BLA}}(k)\big|^2,$$
//! $$\hat\sigma^2_{n}(k) = \frac{1}{M^2}\sum_{m=1}^M \hat\sigma^2_{n,m}(k),\qquad
//!   \hat\sigma^2_{S}(k) = M\big(\hat\sigma^2_{\mathrm{BLA}}(k) - \hat\sigma^2_{n}(k)\big).$$
//!
//! # Normalisations (be careful when comparing with other tools)
//! * [`BlaEstimate::var_total`] $=\hat\sigma^2_{\mathrm{BLA}}$: the total variance **of the BLA
//!   estimate** (noise and stochastic nonlinear distortions, $M$ realisations × $P$ periods);
//! * [`BlaEstimate::var_noise`] $=\hat\sigma^2_n$: the noise variance **of the BLA estimate**
//!   (already divided by $M$ and, through the period mean, by $P$);
//! * [`BlaEstimate::var_nl`] $=\hat\sigma^2_S$: the variance of the stochastic nonlinear
//!   distortion $G_S$ of **one realisation** ($\mathrm E|\hat G_m - G_{\mathrm{BLA}}|^2$ without
//!   noise). Its contribution to the BLA estimate is $\hat\sigma^2_S/M$. It is *not* clipped at zero
//!   (so that band averages are unbiased); use [`BlaEstimate::std_nl`] for a clipped standard
//!   deviation. In the book's notation $\sigma^2_{\mathrm{BLA}} = \sigma^2_S/M + \sigma^2_{n,\mathrm{period}}/(MP)$
//!   with the per-period noise variance $\sigma^2_{n,\mathrm{period}} = MP\,\hat\sigma^2_n$.
//!
//! $\hat\sigma^2_{\mathrm{BLA}}$ has $M-1$ complex degrees of freedom, $\hat\sigma^2_n$ has $M(P-1)$;
//! [`BlaEstimate::band_summary`] uses them for the standard error of a band average.
//!
//! # Detection lines
//! With an odd or random-odd grid, the output on the **non-excited** lines inside the excited band
//! holds only noise and nonlinear distortion: even lines show even-degree nonlinearities, odd
//! non-excited lines show odd-degree ones. [`Detection`] gives per line the output power
//! $\frac1M\sum_m|\bar Y_m(k)|^2$ and the noise level $\frac1M\sum_m\hat\sigma^2_{Y,m}(k)/P$ (the
//! variance of the period mean, so that a line with noise only has power ≈ noise level), and band
//! summaries per kind of line.
//!
//! # Requirements
//! $M \ge 2$ realisations (the NL variance needs the spread over realisations), $P \ge 2$ analysed
//! periods per realisation (the noise variance needs the spread over periods), records that are a
//! whole number of periods of equal length, finite samples, and at least one line excited in every
//! realisation. Lines used are those excited in **all** realisations.
//!
//! # Reference
//! R. Pintelon, J. Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed., Wiley
//! 2012, ch. 3–4 (Sec. 4.3, "robust method"); J. Schoukens, M. Vaes, R. Pintelon, "Linear system
//! identification in a nonlinear setting", IEEE Control Syst. Mag. 36(3), 2016; J. Schoukens et al.,
//! "Robustness issues of the best linear approximation of a nonlinear system", IEEE TIM 58(5), 2009/2012.
//!
//! # Example
//! ```
//! use ambid_core::frf::bla::{random_phase_period, robust_bla, Record};
//! use ambid_core::frf::periodic::PeriodicOptions;
//! let (n, p, m) = (64usize, 3usize, 4usize);
//! let bins: Vec<usize> = (1..20).step_by(2).collect(); // odd lines 1..19
//! let mut u_rec = Vec::new();
//! let mut y_rec = Vec::new();
//! for real in 0..m {
//!     let period = random_phase_period(&bins, n, 1.0, real as u64).unwrap();
//!     let u: Vec<f64> = (0..p * n).map(|t| period[t % n]).collect();
//!     // a static linear gain of 2: no noise, no nonlinearity
//!     let y: Vec<f64> = u.iter().map(|v| 2.0 * v).collect();
//!     u_rec.push(u);
//!     y_rec.push(y);
//! }
//! let recs: Vec<Record> = (0..m).map(|i| Record::open_loop(&u_rec[i], &y_rec[i])).collect();
//! let bla = robust_bla(&recs, 100.0, &PeriodicOptions::new(n)).unwrap();
//! assert_eq!(bla.g.lines, bins);
//! assert!(bla.g.values.iter().all(|g| (g.re - 2.0).abs() < 1e-12 && g.im.abs() < 1e-12));
//! assert!(bla.g.var_nl.iter().all(|v| v.abs() < 1e-20));
//! // odd grid: even lines 2..18 are detection lines
//! assert_eq!(bla.detection.even.lines, 9);
//! ```

use super::closed_loop::{from_periodic, Channels};
use super::periodic::{PeriodicAnalyzer, PeriodicOptions, PeriodicSpectra};
use crate::error::{Error, Result};
use faer::c64;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Relative amplitude (to the largest line) above which a reference line counts as excited.
pub const EXCITED_THRESHOLD: f64 = 1e-2;

/// One realisation's record: the reference (excitation) `r` in closed loop, the input `u` and the
/// output `y`, equal lengths, a whole number of periods.
#[derive(Debug, Clone, Copy)]
pub struct Record<'a> {
    /// Closed-loop excitation added to the controller output; `None` in open loop.
    pub r: Option<&'a [f64]>,
    /// Input of the system to approximate (the plant input in closed loop).
    pub u: &'a [f64],
    /// Output.
    pub y: &'a [f64],
}

impl<'a> Record<'a> {
    /// Open loop: $u \to y$, $u$ is the (periodic) excitation.
    pub fn open_loop(u: &'a [f64], y: &'a [f64]) -> Self {
        Self { r: None, u, y }
    }

    /// Closed loop with the excitation `r` as the reference.
    pub fn closed_loop(r: &'a [f64], u: &'a [f64], y: &'a [f64]) -> Self {
        Self { r: Some(r), u, y }
    }
}

/// BLA statistics of one frequency response on the excited lines; see the [module docs](self)
/// for the normalisations.
#[derive(Debug, Clone, PartialEq)]
pub struct BlaEstimate {
    /// DFT lines $k$ (frequency $k f_s/N$).
    pub lines: Vec<usize>,
    /// Frequencies \[Hz\].
    pub f_hz: Vec<f64>,
    /// $\hat G_{\mathrm{BLA}}$.
    pub values: Vec<c64>,
    /// Total variance of the BLA estimate $\hat\sigma^2_{\mathrm{BLA}}$ (spread over realisations / M).
    pub var_total: Vec<f64>,
    /// Noise variance of the BLA estimate $\hat\sigma^2_n$ (mean over realisations of the
    /// period-spread variance, / M).
    pub var_noise: Vec<f64>,
    /// Stochastic nonlinear variance of one realisation $\hat\sigma^2_S = M(\hat\sigma^2_{\mathrm{BLA}} - \hat\sigma^2_n)$
    /// (unclipped, may be slightly negative).
    pub var_nl: Vec<f64>,
    /// Realisations $M$.
    pub realisations: usize,
    /// Analysed periods per realisation $P$.
    pub periods: usize,
}

/// Band averages of a [`BlaEstimate`], relative to $|\hat G_{\mathrm{BLA}}|^2$ line by line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlaBandSummary {
    /// Lines averaged.
    pub lines: usize,
    /// Mean of $\hat\sigma^2_n/|\hat G|^2$ (noise variance of the BLA estimate).
    pub noise_rel: f64,
    /// Mean of $\hat\sigma^2_S/|\hat G|^2$ (NL variance of one realisation).
    pub nl_rel: f64,
    /// Standard error of `nl_rel` (chi-square spread of both variance estimates, independent lines):
    /// per line $M\sqrt{\sigma^4_{\mathrm{BLA}}/(M-1) + \sigma^4_n/(M(P-1))}$ relative, averaged
    /// in quadrature and divided by the number of lines.
    pub nl_rel_se: f64,
    /// Mean of $\hat\sigma^2_{\mathrm{BLA}}/|\hat G|^2$.
    pub total_rel: f64,
}

impl BlaEstimate {
    /// Standard deviation of the BLA estimate, $\sqrt{\hat\sigma^2_{\mathrm{BLA}}}$.
    pub fn std_total(&self) -> Vec<f64> {
        self.var_total.iter().map(|v| v.max(0.0).sqrt()).collect()
    }

    /// Noise standard deviation of the BLA estimate, $\sqrt{\hat\sigma^2_n}$.
    pub fn std_noise(&self) -> Vec<f64> {
        self.var_noise.iter().map(|v| v.max(0.0).sqrt()).collect()
    }

    /// Standard deviation of the stochastic NL distortion of one realisation,
    /// $\sqrt{\max(\hat\sigma^2_S, 0)}$.
    pub fn std_nl(&self) -> Vec<f64> {
        self.var_nl.iter().map(|v| v.max(0.0).sqrt()).collect()
    }

    /// Averages over the lines with $f_{\min} \le f \le f_{\max}$ Hz.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when no line lies in the band or the BLA vanishes on one.
    pub fn band_summary(&self, f_min_hz: f64, f_max_hz: f64) -> Result<BlaBandSummary> {
        let (rel, se2) = self.nl_rel_lines()?;
        let (mut n, mut sn, mut snl, mut sse, mut st) = (0usize, 0.0, 0.0, 0.0, 0.0);
        for (k, &f) in self.f_hz.iter().enumerate() {
            if !(f >= f_min_hz && f <= f_max_hz) {
                continue;
            }
            let g2 = self.values[k].norm_sqr();
            if g2 <= 0.0 || !g2.is_finite() {
                return Err(Error::invalid(
                    "band",
                    format!("the BLA vanishes at {f} Hz; cannot normalise by |G|²"),
                ));
            }
            n += 1;
            sn += self.var_noise[k] / g2;
            snl += rel[k];
            st += self.var_total[k] / g2;
            sse += se2[k];
        }
        if n == 0 {
            return Err(Error::invalid(
                "band",
                format!("no excited line in [{f_min_hz}, {f_max_hz}] Hz"),
            ));
        }
        let nf = n as f64;
        Ok(BlaBandSummary {
            lines: n,
            noise_rel: sn / nf,
            nl_rel: snl / nf,
            nl_rel_se: sse.sqrt() / nf,
            total_rel: st / nf,
        })
    }

    /// Per line $k$: the relative stochastic nonlinear variance $\hat\sigma^2_S/|\hat G|^2$ and
    /// the square of its standard error,
    /// $M^2\big(\hat\sigma^4_{\mathrm{BLA}}/(M-1) + \hat\sigma^4_n/(M(P-1))\big)/|\hat G|^4$ (the
    /// two variance estimates' $\chi^2$ spreads with $M-1$ and $M(P-1)$ complex degrees of
    /// freedom, taken independent).
    ///
    /// Where the BLA vanishes (or is not finite) both are NaN.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when fewer than 2 realisations or periods are recorded.
    pub fn nl_rel_lines(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        if self.realisations < 2 || self.periods < 2 {
            return Err(Error::invalid(
                "realisations",
                format!(
                    "{} realisation(s) of {} period(s): the nonlinear variance needs at least 2 of each",
                    self.realisations, self.periods
                ),
            ));
        }
        let m = self.realisations as f64;
        let p = self.periods as f64;
        let mut rel = Vec::with_capacity(self.f_hz.len());
        let mut se2 = Vec::with_capacity(self.f_hz.len());
        for k in 0..self.f_hz.len() {
            let g2 = self.values[k].norm_sqr();
            if g2 <= 0.0 || !g2.is_finite() {
                rel.push(f64::NAN);
                se2.push(f64::NAN);
                continue;
            }
            let (vt, vn) = (self.var_total[k] / g2, self.var_noise[k] / g2);
            rel.push(self.var_nl[k] / g2);
            se2.push(m * m * (vt * vt / (m - 1.0) + vn * vn / (m * (p - 1.0))));
        }
        Ok((rel, se2))
    }

    /// The stochastic nonlinear variance tested in groups of neighbouring lines: each group
    /// spans at least a third of a decade and holds at least [`NL_GROUP_MIN_LINES`] lines (a
    /// last group with fewer joins the one before). Per group the mean $\bar r$ of
    /// [`nl_rel_lines`](Self::nl_rel_lines) and its standard error $s$ (root of the summed
    /// squares over the count) give a one-sided test at level `alpha` split over the $B$
    /// groups, $\bar r > z_{1-\alpha/B}\,s$, and the upper value $\bar r + z_{1-\alpha}\,s$
    /// ([`NlGroup`]).
    ///
    /// # Errors
    /// `alpha` outside (0, 0.5), no line, a line where the BLA vanishes or a variance is not
    /// finite, or as [`nl_rel_lines`](Self::nl_rel_lines).
    ///
    /// # Example
    /// ```
    /// use ambid_core::c64;
    /// use ambid_core::frf::bla::BlaEstimate;
    /// // 12 lines at 20..240 Hz, |G| = 1, one realisation's NL variance 0.01 and
    /// // exact variances (M = 8, P = 4): the NL is far above its standard error
    /// let (m, p) = (8usize, 4usize);
    /// let f: Vec<f64> = (1..=12).map(|k| 20.0 * k as f64).collect();
    /// let vn = 1e-4;
    /// let est = BlaEstimate {
    ///     lines: (1..=12).collect(),
    ///     f_hz: f.clone(),
    ///     values: vec![c64::new(1.0, 0.0); 12],
    ///     var_total: vec![0.01 / m as f64 + vn; 12],
    ///     var_noise: vec![vn; 12],
    ///     var_nl: vec![0.01; 12],
    ///     realisations: m,
    ///     periods: p,
    /// };
    /// let g = est.nl_groups(0.05).unwrap();
    /// assert!(g.iter().all(|g| g.significant && (g.nl_rel - 0.01).abs() < 1e-12));
    /// assert_eq!(g.iter().map(|g| g.lines).sum::<usize>(), 12);
    /// ```
    pub fn nl_groups(&self, alpha: f64) -> Result<Vec<NlGroup>> {
        if !(alpha > 0.0 && alpha < 0.5) {
            return Err(Error::invalid(
                "alpha",
                format!("the test level must be in (0, 0.5), got {alpha}"),
            ));
        }
        let l = self.f_hz.len();
        if l == 0 {
            return Err(Error::invalid("lines", "the BLA has no line"));
        }
        let (rel, se2) = self.nl_rel_lines()?;
        if let Some(k) = (0..l).find(|&k| !(rel[k].is_finite() && se2[k].is_finite())) {
            return Err(Error::invalid(
                "lines",
                format!(
                    "the BLA or its variances are zero or not finite at {} Hz; cannot normalise by |G|²",
                    self.f_hz[k]
                ),
            ));
        }
        let third = 10f64.powf(1.0 / 3.0);
        let mut bounds = Vec::new();
        let mut i = 0;
        while i < l {
            let mut j = i + 1;
            while j < l && (self.f_hz[j] <= self.f_hz[i] * third || j - i < NL_GROUP_MIN_LINES) {
                j += 1;
            }
            if l - j < NL_GROUP_MIN_LINES {
                j = l;
            }
            bounds.push((i, j));
            i = j;
        }
        let b = bounds.len() as f64;
        let z_b = crate::validate::uncertainty::normal_upper_quantile(alpha / b);
        let z = crate::validate::uncertainty::normal_upper_quantile(alpha);
        Ok(bounds
            .into_iter()
            .map(|(i, j)| {
                let n = (j - i) as f64;
                let nl_rel = rel[i..j].iter().sum::<f64>() / n;
                let nl_rel_se = se2[i..j].iter().sum::<f64>().sqrt() / n;
                NlGroup {
                    f_lo_hz: self.f_hz[i],
                    f_hi_hz: self.f_hz[j - 1],
                    lines: j - i,
                    nl_rel,
                    nl_rel_se,
                    threshold: z_b * nl_rel_se,
                    significant: nl_rel > z_b * nl_rel_se,
                    upper_rel: nl_rel + z * nl_rel_se,
                }
            })
            .collect())
    }
}

/// Fewest lines in a group of [`BlaEstimate::nl_groups`].
pub const NL_GROUP_MIN_LINES: usize = 4;

/// One group of neighbouring lines of [`BlaEstimate::nl_groups`]: relative to $|\hat G|^2$, the
/// variance of one realisation's stochastic nonlinear distortion.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NlGroup {
    /// Lowest line \[Hz\].
    pub f_lo_hz: f64,
    /// Highest line \[Hz\].
    pub f_hi_hz: f64,
    /// Lines in the group.
    pub lines: usize,
    /// Mean relative nonlinear variance $\bar r$ (not clipped: may be negative).
    pub nl_rel: f64,
    /// Its standard error $s$.
    pub nl_rel_se: f64,
    /// The test's threshold $z_{1-\alpha/B}\,s$.
    pub threshold: f64,
    /// $\bar r$ above the threshold.
    pub significant: bool,
    /// The one-sided upper value $\bar r + z_{1-\alpha}\,s$.
    pub upper_rel: f64,
}

/// Which kind of non-excited line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineKind {
    /// Even line: even-degree nonlinear distortion.
    Even,
    /// Odd line not excited: odd-degree nonlinear distortion.
    OddDetection,
}

/// Output power and noise level on one non-excited line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectionLine {
    /// DFT line.
    pub line: usize,
    /// Frequency \[Hz\].
    pub f_hz: f64,
    /// Even or odd.
    pub kind: LineKind,
    /// $\frac1M\sum_m |\bar Y_m(k)|^2$ (unnormalised DFT, as [`PeriodicSpectra::mean`]).
    pub power: f64,
    /// $\frac1M\sum_m \hat\sigma^2_{Y,m}(k)/P$: the expected `power` with noise only.
    pub noise: f64,
}

/// Summary of one kind of detection line.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DetectionSummary {
    /// Number of lines.
    pub lines: usize,
    /// Mean output power.
    pub mean_power: f64,
    /// Mean noise level.
    pub mean_noise: f64,
    /// `10 log10(mean_power / mean_noise)`: ≈ 0 dB with noise only, > 0 dB with distortion
    /// (NaN without lines).
    pub ratio_db: f64,
}

/// Nonlinearity detection on the non-excited lines between the first and the last excited line.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// Per line, ascending.
    pub lines: Vec<DetectionLine>,
    /// Even lines.
    pub even: DetectionSummary,
    /// Odd non-excited lines.
    pub odd: DetectionSummary,
}

/// The robust BLA: the approximated system and, in closed loop, the two $r$-referenced FRFs.
#[derive(Debug, Clone, PartialEq)]
pub struct Bla {
    /// The BLA of $u \to y$ (open loop) or of the plant $T_{ry}/T_{ru}$ (closed loop).
    pub g: BlaEstimate,
    /// Closed loop only: BLA statistics of $T_{ry}$.
    pub t_ry: Option<BlaEstimate>,
    /// Closed loop only: BLA statistics of $T_{ru} = S$.
    pub t_ru: Option<BlaEstimate>,
    /// Detection lines of the output $y$.
    pub detection: Detection,
}

/// Per-realisation FRF values and noise variances on the common lines.
struct Samples {
    values: Vec<Vec<c64>>,
    var: Vec<Vec<f64>>,
}

impl Samples {
    fn new(m: usize) -> Self {
        Self {
            values: Vec::with_capacity(m),
            var: Vec::with_capacity(m),
        }
    }
}

fn statistics(s: &Samples, lines: &[usize], f_hz: &[f64], periods: usize) -> Result<BlaEstimate> {
    let m = s.values.len();
    let mf = m as f64;
    let nl = lines.len();
    let mut values = vec![c64::new(0.0, 0.0); nl];
    let mut var_total = vec![0.0; nl];
    let mut var_noise = vec![0.0; nl];
    for (gm, vm) in s.values.iter().zip(&s.var) {
        for i in 0..nl {
            values[i] += gm[i] / mf;
            var_noise[i] += vm[i] / (mf * mf);
        }
    }
    for gm in &s.values {
        for i in 0..nl {
            var_total[i] += (gm[i] - values[i]).norm_sqr() / (mf * (mf - 1.0));
        }
    }
    let var_nl: Vec<f64> = var_total
        .iter()
        .zip(&var_noise)
        .map(|(t, n)| mf * (t - n))
        .collect();
    if let Some(i) = (0..nl).find(|&i| !values[i].norm_sqr().is_finite()) {
        return Err(Error::Numerical {
            context: "robust BLA",
            reason: format!("non-finite BLA on line {}", lines[i]),
        });
    }
    Ok(BlaEstimate {
        lines: lines.to_vec(),
        f_hz: f_hz.to_vec(),
        values,
        var_total,
        var_noise,
        var_nl,
        realisations: m,
        periods,
    })
}

fn summarise(lines: &[DetectionLine], kind: LineKind) -> DetectionSummary {
    let sel: Vec<&DetectionLine> = lines.iter().filter(|l| l.kind == kind).collect();
    if sel.is_empty() {
        return DetectionSummary {
            ratio_db: f64::NAN,
            ..DetectionSummary::default()
        };
    }
    let n = sel.len() as f64;
    let mean_power = sel.iter().map(|l| l.power).sum::<f64>() / n;
    let mean_noise = sel.iter().map(|l| l.noise).sum::<f64>() / n;
    DetectionSummary {
        lines: sel.len(),
        mean_power,
        mean_noise,
        ratio_db: 10.0 * (mean_power / mean_noise).log10(),
    }
}

/// The robust BLA from $M$ realisations; see the [module docs](self).
///
/// `opts` gives the period length $N$ and the transient periods to drop; records must be a whole
/// number of periods (`opts.strict` is enforced).
///
/// # Errors
/// [`Error::InvalidArgument`]: fewer than 2 realisations, fewer than 2 analysed periods, records
/// of different lengths or not a whole number of periods, a mix of open- and closed-loop records,
/// no line excited in every realisation; [`Error::NonFinite`]: a NaN or infinite sample;
/// [`Error::DimensionMismatch`]: channels of one record of different lengths.
pub fn robust_bla(records: &[Record], fs: f64, opts: &PeriodicOptions) -> Result<Bla> {
    let m = records.len();
    if m < 2 {
        return Err(Error::invalid(
            "records",
            format!(
                "the robust BLA needs at least 2 multisine realisations (the NL variance is the spread \
                 over realisations), got {m}"
            ),
        ));
    }
    let closed = records[0].r.is_some();
    if records.iter().any(|r| r.r.is_some() != closed) {
        return Err(Error::invalid(
            "records",
            "mix of open-loop and closed-loop records; give r for all or for none",
        ));
    }
    let len = records[0].u.len();
    if let Some(i) = records.iter().position(|r| r.u.len() != len) {
        return Err(Error::invalid(
            "records",
            format!(
                "realisation {i} has {} samples, realisation 0 has {len}; all realisations must have the same length",
                records[i].u.len()
            ),
        ));
    }
    let opts = PeriodicOptions {
        strict: true,
        ..*opts
    };
    let mut an = PeriodicAnalyzer::new(opts.period_samples)?;
    let mut spectra: Vec<PeriodicSpectra> = Vec::with_capacity(m);
    for rec in records {
        let s = match rec.r {
            Some(r) => an.analyze(&[r, rec.u, rec.y], fs, &opts)?,
            None => an.analyze(&[rec.u, rec.y], fs, &opts)?,
        };
        if s.periods() < 2 {
            return Err(Error::invalid(
                "periods",
                format!(
                    "{} period(s) analysed after skipping {}; the noise variance needs at least 2",
                    s.periods(),
                    opts.skip_periods
                ),
            ));
        }
        spectra.push(s);
    }
    let (ch_ref, ch_u, ch_y) = if closed { (0, 1, 2) } else { (0, 0, 1) };
    // lines excited in every realisation
    let mut common: Option<Vec<usize>> = None;
    let mut union: Vec<bool> = vec![false; spectra[0].n_lines()];
    for s in &spectra {
        let ex = s.excited_lines(ch_ref, EXCITED_THRESHOLD)?;
        for &k in &ex {
            union[k] = true;
        }
        common = Some(match common {
            None => ex,
            Some(c) => c.into_iter().filter(|k| ex.contains(k)).collect(),
        });
    }
    let lines = common.unwrap_or_default();
    // exclude the Nyquist line: its phase is not free
    let n = opts.period_samples;
    let lines: Vec<usize> = lines.into_iter().filter(|&k| 2 * k != n).collect();
    if lines.is_empty() {
        return Err(Error::invalid(
            "records",
            "no line is excited in every realisation; use the same excitation grid for all realisations",
        ));
    }
    let s0 = &spectra[0];
    let f_hz: Vec<f64> = lines.iter().map(|&k| s0.line_hz(k)).collect();
    let channels = Channels {
        r: ch_ref,
        u: ch_u,
        y: ch_y,
    };
    let (mut g, mut t, mut su) = (Samples::new(m), Samples::new(m), Samples::new(m));
    for s in &spectra {
        let frf = from_periodic(s, channels, &lines, None)?;
        let var = |f: &crate::lti::Frd| -> Vec<f64> {
            f.variance()
                .map(|v| v.to_vec())
                .unwrap_or_else(|| vec![0.0; lines.len()])
        };
        g.values.push(frf.plant.values().to_vec());
        g.var.push(var(&frf.plant));
        if closed {
            t.values.push(frf.t_ry.values().to_vec());
            t.var.push(var(&frf.t_ry));
            su.values.push(frf.t_ru.values().to_vec());
            su.var.push(var(&frf.t_ru));
        }
    }
    let p = s0.periods();
    let g = statistics(&g, &lines, &f_hz, p)?;
    let (t_ry, t_ru) = if closed {
        (
            Some(statistics(&t, &lines, &f_hz, p)?),
            Some(statistics(&su, &lines, &f_hz, p)?),
        )
    } else {
        (None, None)
    };

    // detection lines: between first and last excited line, never excited in any realisation
    let (lo, hi) = (lines[0], lines[lines.len() - 1]);
    let mf = m as f64;
    let pf = p as f64;
    let mut det = Vec::new();
    for k in lo..=hi {
        if union.get(k).copied().unwrap_or(true) {
            continue;
        }
        let power = spectra
            .iter()
            .map(|s| s.mean(ch_y)[k].norm_sqr())
            .sum::<f64>()
            / mf;
        let noise = spectra
            .iter()
            .map(|s| s.cov_at(ch_y, ch_y, k).re)
            .sum::<f64>()
            / (mf * pf);
        det.push(DetectionLine {
            line: k,
            f_hz: s0.line_hz(k),
            kind: if k % 2 == 0 {
                LineKind::Even
            } else {
                LineKind::OddDetection
            },
            power,
            noise,
        });
    }
    let detection = Detection {
        even: summarise(&det, LineKind::Even),
        odd: summarise(&det, LineKind::OddDetection),
        lines: det,
    };
    Ok(Bla {
        g,
        t_ry,
        t_ru,
        detection,
    })
}

/// One period of a random-phase multisine on the given DFT `bins` of a period of `n` samples,
/// flat amplitude spectrum, RMS `rms`, phases uniform in $[0, 2\pi)$ from
/// `ChaCha8Rng::seed_from_u64(seed)`: one realisation of the robust BLA's excitation (keep `bins`
/// fixed and change `seed` between realisations).
///
/// # Errors
/// [`Error::InvalidArgument`] when `bins` is empty, a bin is 0 or $\ge n/2$, `n < 4`, or `rms` is
/// not positive and finite.
pub fn random_phase_period(bins: &[usize], n: usize, rms: f64, seed: u64) -> Result<Vec<f64>> {
    if n < 4 {
        return Err(Error::invalid(
            "n",
            format!("a period needs at least 4 samples, got {n}"),
        ));
    }
    if bins.is_empty() {
        return Err(Error::invalid("bins", "no excited line"));
    }
    if let Some(&k) = bins.iter().find(|&&k| k == 0 || 2 * k >= n) {
        return Err(Error::invalid(
            "bins",
            format!(
                "bin {k} is outside 1..{} (DC and Nyquist excluded)",
                n.div_ceil(2)
            ),
        ));
    }
    if !(rms.is_finite() && rms > 0.0) {
        return Err(Error::invalid(
            "rms",
            format!("must be positive and finite, got {rms}"),
        ));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let amp = rms * (2.0 / bins.len() as f64).sqrt();
    let mag = amp * n as f64 / 2.0;
    let mut half = vec![c64::new(0.0, 0.0); n / 2 + 1];
    for &k in bins {
        let phi = rng.random_range(0.0..2.0 * std::f64::consts::PI);
        half[k] += c64::from_polar(mag, phi);
    }
    crate::signal::analysis::real_ifft(&half, n)
}
