//! Period-synchronous averaging of periodically excited records.
//!
//! With a periodic excitation of period $N$ samples and an integer number of periods in the
//! analysed record, the DFT of each period on the lines $f_k = k f_s / N$ is free of leakage. For
//! $P$ periods (after dropping the transient ones) and each channel $x$ this module computes, per
//! line $k$,
//!
//! $$X_p(k) = \sum_{n=0}^{N-1} x_{pN+n}\, e^{-j 2\pi k n / N},\qquad
//!   \bar X(k) = \frac1P \sum_{p=1}^{P} X_p(k),$$
//!
//! and for every pair of channels $(x_i, x_j)$ the sample covariance across periods
//!
//! $$\hat\sigma_{ij}(k) = \frac{1}{P-1} \sum_{p=1}^{P} \big(X_{i,p}(k) - \bar X_i(k)\big)
//!   \overline{\big(X_{j,p}(k) - \bar X_j(k)\big)} .$$
//!
//! The covariance of the *means* is $\hat\sigma_{ij}/P$; it has $P-1$ complex degrees of freedom.
//! The DFT is unnormalised (a sine of amplitude $a$ on line $k$ gives $|X(k)| = aN/2$); ratios such
//! as frequency responses do not depend on the scale, [`PeriodicSpectra::amplitude`] converts.
//!
//! # Algorithm and complexity
//! A channel whose periods are bit-identical (a recorded digital excitation usually is) is
//! transformed once and gets zero variance. The other channels are transformed two at a time with
//! one complex FFT per period (the real pair $x + j y$ is packed and split by conjugate symmetry),
//! so $C$ noisy channels cost $\lceil C/2 \rceil P$ complex FFTs of length $N$,
//! $O(C\,P\,N\log N)$ in total, and $O(C^2 N)$ memory. The second moments are accumulated as sums
//! of deviations from the first analysed period, which avoids the cancellation of the textbook
//! $\sum |X|^2 - P|\bar X|^2$ at lines with a high signal-to-noise ratio. With more than two
//! noisy channels the deviations of up to 16 periods are held line by line and folded into the
//! $C^2/2$ pair sums once per block (each sum still in period order, so the numbers are those of
//! one accumulation per period), which reads and writes the sums once per block rather than once
//! per period; the block is shortened when it would hold more than $2^{22}$ numbers.
//!
//! # Example
//! ```
//! use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
//! let n = 64;
//! // 3 periods of a cosine on line 5, amplitude 2; y = 0.5 x
//! let x: Vec<f64> = (0..3 * n)
//!     .map(|k| 2.0 * (2.0 * std::f64::consts::PI * 5.0 * k as f64 / n as f64).cos())
//!     .collect();
//! let y: Vec<f64> = x.iter().map(|v| 0.5 * v).collect();
//! let mut an = PeriodicAnalyzer::new(n).unwrap();
//! let s = an.analyze(&[&x, &y], 1000.0, &PeriodicOptions::new(n)).unwrap();
//! assert_eq!(s.periods(), 3);
//! assert!((s.amplitude(0, 5) - 2.0).abs() < 1e-12);
//! let g = s.mean(1)[5] / s.mean(0)[5];
//! assert!((g.re - 0.5).abs() < 1e-12 && g.im.abs() < 1e-12);
//! assert_eq!(s.excited_lines(0, 1e-6).unwrap(), vec![5]);
//! ```

use crate::error::{check_finite, Error, Result};
use faer::c64;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// How a record is cut into periods.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PeriodicOptions {
    /// Samples per excitation period $N$.
    pub period_samples: usize,
    /// Leading periods dropped as transient.
    pub skip_periods: usize,
    /// Require the record to hold an integer number of periods (otherwise the incomplete tail is
    /// ignored and reported in [`PeriodicSpectra::dropped_tail`]).
    pub strict: bool,
}

impl PeriodicOptions {
    /// `period_samples` per period, no skipped period, strict.
    pub fn new(period_samples: usize) -> Self {
        Self {
            period_samples,
            skip_periods: 0,
            strict: true,
        }
    }

    /// Sets the number of leading (transient) periods to drop.
    pub fn skip(mut self, periods: usize) -> Self {
        self.skip_periods = periods;
        self
    }

    /// Allows a record that is not an integer number of periods (the tail is ignored).
    pub fn lenient(mut self) -> Self {
        self.strict = false;
        self
    }
}

/// Per-line period statistics of several channels; see the [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodicSpectra {
    fs: f64,
    period_samples: usize,
    periods: usize,
    skipped: usize,
    dropped_tail: usize,
    n_channels: usize,
    mean: Vec<Vec<c64>>,
    /// Upper triangle (i ≤ j) of the per-period covariance, row-major; an empty row is
    /// [`zero_row`](Self::zero_row) (a pair with an exactly periodic channel) or, for a pair
    /// left out by [`PeriodicAnalyzer::analyze_selected`], [`nan_row`](Self::nan_row).
    cov: Vec<Vec<c64>>,
    /// Per pair: the row was left out (not computed).
    cov_skipped: Vec<bool>,
    /// `n_lines` zeros, the covariance of every pair with an exactly periodic channel.
    zero_row: Vec<c64>,
    /// `n_lines` NaNs if some pair was left out (otherwise empty).
    nan_row: Vec<c64>,
    exact_periodic: Vec<bool>,
}

/// A reusable analyser holding the FFT plan and buffers of one period length.
pub struct PeriodicAnalyzer {
    n: usize,
    fft: Arc<dyn Fft<f64>>,
    buf: Vec<c64>,
    scratch: Vec<c64>,
}

impl std::fmt::Debug for PeriodicAnalyzer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PeriodicAnalyzer")
            .field("period_samples", &self.n)
            .finish()
    }
}

fn pair_index(n_channels: usize, i: usize, j: usize) -> usize {
    // row-major upper triangle including the diagonal
    i * n_channels - i * (i + 1) / 2 + j
}

impl PeriodicAnalyzer {
    /// Plans the FFT of one period of `period_samples` samples ($\ge 2$).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `period_samples < 2`.
    pub fn new(period_samples: usize) -> Result<Self> {
        if period_samples < 2 {
            return Err(Error::invalid(
                "period_samples",
                format!(
                    "a period must hold at least 2 samples, got {period_samples}; pass the excitation's period length"
                ),
            ));
        }
        let fft = FftPlanner::new().plan_fft_forward(period_samples);
        let scratch = vec![c64::new(0.0, 0.0); fft.get_inplace_scratch_len()];
        Ok(Self {
            n: period_samples,
            fft,
            buf: vec![c64::new(0.0, 0.0); period_samples],
            scratch,
        })
    }

    /// Period length this analyser was planned for.
    pub fn period_samples(&self) -> usize {
        self.n
    }

    /// Checks `channels` and `opts` against the plan and returns the analysed periods $P$ and
    /// the first analysed sample (the errors of [`analyze`](Self::analyze) but for non-finite
    /// samples).
    fn layout(
        &self,
        channels: &[&[f64]],
        fs: f64,
        opts: &PeriodicOptions,
    ) -> Result<(usize, usize)> {
        let n = self.n;
        if opts.period_samples != n {
            return Err(Error::invalid(
                "period_samples",
                format!(
                    "the analyser was planned for {n} samples per period, the options ask for {}",
                    opts.period_samples
                ),
            ));
        }
        if channels.is_empty() {
            return Err(Error::invalid("channels", "no channel to analyse"));
        }
        if !(fs.is_finite() && fs > 0.0) {
            return Err(Error::invalid(
                "fs",
                format!("the sampling frequency must be positive and finite, got {fs}"),
            ));
        }
        let len = channels[0].len();
        for (c, x) in channels.iter().enumerate() {
            if x.len() != len {
                return Err(Error::DimensionMismatch {
                    context: "periodic analysis: channel lengths",
                    expected: len.to_string(),
                    got: format!("{} (channel {c})", x.len()),
                });
            }
        }
        let total_periods = len / n;
        let tail = len % n;
        if opts.strict && tail != 0 {
            return Err(Error::invalid(
                "period_samples",
                format!(
                    "the record has {len} samples, which is not an integer number of periods of {n} samples \
                     ({total_periods} periods and {tail} samples); pass the right period length or trim the \
                     record to a multiple of it (or allow an incomplete tail)"
                ),
            ));
        }
        if total_periods <= opts.skip_periods {
            return Err(Error::invalid(
                "skip_periods",
                format!(
                    "the record holds {total_periods} whole period(s) of {n} samples and {} are to be skipped; \
                     record more periods or skip fewer",
                    opts.skip_periods
                ),
            ));
        }
        Ok((total_periods - opts.skip_periods, opts.skip_periods * n))
    }

    /// The DFT $X_p(k)$ of every analysed period on the given `lines` (module docs), indexed
    /// `[period][channel][line]`: what the means and covariances of [`analyze`](Self::analyze)
    /// summarise, for statistics across periods that need more than the second moments on each
    /// line (e.g. the sample covariance of a fitted model's parameters,
    /// [`crate::frf::closed_loop::plant_period_deviations`]). $O(C\,P\,N\log N)$ time and
    /// $O(C\,P\,L)$ memory for $L$ lines.
    ///
    /// # Errors
    /// Those of [`analyze`](Self::analyze), and [`Error::InvalidArgument`] for a line at or
    /// beyond $N/2 + 1$.
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
    /// let n = 32;
    /// // 4 periods of a cosine on line 3 whose amplitude grows by 1 per period
    /// let x: Vec<f64> = (0..4 * n)
    ///     .map(|k| (1 + k / n) as f64 * (2.0 * std::f64::consts::PI * 3.0 * k as f64 / n as f64).cos())
    ///     .collect();
    /// let mut an = PeriodicAnalyzer::new(n).unwrap();
    /// let d = an.period_lines(&[&x], 1.0, &PeriodicOptions::new(n).skip(1), &[3]).unwrap();
    /// assert_eq!(d.len(), 3);
    /// // amplitude a on line 3 gives |X| = a N / 2
    /// for (p, per) in d.iter().enumerate() {
    ///     assert!((per[0][0].re - (p + 2) as f64 * 16.0).abs() < 1e-9);
    /// }
    /// ```
    pub fn period_lines(
        &mut self,
        channels: &[&[f64]],
        fs: f64,
        opts: &PeriodicOptions,
        lines: &[usize],
    ) -> Result<Vec<Vec<Vec<c64>>>> {
        let (p_used, start) = self.layout(channels, fs, opts)?;
        let n = self.n;
        if let Some(&k) = lines.iter().find(|&&k| k > n / 2) {
            return Err(Error::invalid(
                "lines",
                format!(
                    "line {k} is beyond the last line {} of a {n}-sample period",
                    n / 2
                ),
            ));
        }
        let mut out = Vec::with_capacity(p_used);
        for p in 0..p_used {
            let off = start + p * n;
            let mut per = Vec::with_capacity(channels.len());
            for x in channels {
                self.transform_pair(&x[off..off + n], None, off)?;
                per.push(lines.iter().map(|&k| self.buf[k]).collect());
            }
            out.push(per);
        }
        Ok(out)
    }

    /// Analyses `channels` (equal lengths, finite) sampled at `fs` Hz.
    ///
    /// # Errors
    /// * [`Error::InvalidArgument`]: no channel, `fs` not positive, `opts.period_samples` different
    ///   from the planned length, fewer than one period left after the skipped ones, or (strict)
    ///   a record that is not an integer number of periods;
    /// * [`Error::DimensionMismatch`]: channels of different lengths;
    /// * [`Error::NonFinite`]: a NaN or infinite sample in the analysed periods (repair it with
    ///   `data` first; samples of skipped periods and of an ignored tail are not read).
    pub fn analyze(
        &mut self,
        channels: &[&[f64]],
        fs: f64,
        opts: &PeriodicOptions,
    ) -> Result<PeriodicSpectra> {
        self.analyze_selected(channels, fs, opts, &|_, _| true, None)
    }

    /// [`analyze`](Self::analyze) computing the covariance only of the channel pairs
    /// `(i, j)`, `i ≤ j`, with `need(i, j)` and (if given) only on the lines `k` with
    /// `lines[k]`; the other pairs' and lines' covariances read as NaN. Means are computed on
    /// every line. With two channels that are not exactly periodic (the SISO case) every pair
    /// and line is computed (the fused path). The values computed are bit-identical to
    /// `analyze`'s.
    pub(crate) fn analyze_selected(
        &mut self,
        channels: &[&[f64]],
        fs: f64,
        opts: &PeriodicOptions,
        need: &dyn Fn(usize, usize) -> bool,
        lines: Option<&[bool]>,
    ) -> Result<PeriodicSpectra> {
        let (p_used, start) = self.layout(channels, fs, opts)?;
        let (n, tail) = (self.n, channels[0].len() % self.n);
        let exact: Vec<bool> = channels
            .iter()
            .map(|x| {
                let first = &x[start..start + n];
                (1..p_used).all(|p| &x[start + p * n..start + (p + 1) * n] == first)
            })
            .collect();
        let mut sums = PeriodSums::new(n, &exact, need, lines)?;
        for p in 0..p_used {
            let off = start + p * n;
            let period: Vec<&[f64]> = channels.iter().map(|x| &x[off..off + n]).collect();
            sums.add(self, &period, off)?;
        }
        sums.finish(self, fs, opts.skip_periods, tail)
    }

    /// Packs `a + j b` into the buffer and transforms it. The finiteness check rides along the
    /// packing loop (`x·0` is NaN exactly for NaN and ±inf), so the data are read once; `off` is
    /// the position of the period in the record, for the error message.
    fn transform_pair(&mut self, a: &[f64], b: Option<&[f64]>, off: usize) -> Result<()> {
        let mut guard = 0.0f64;
        match b {
            Some(b) => {
                for ((z, x), y) in self.buf.iter_mut().zip(a).zip(b) {
                    guard += x * 0.0 + y * 0.0;
                    *z = c64::new(*x, *y);
                }
            }
            None => {
                for (z, x) in self.buf.iter_mut().zip(a) {
                    guard += x * 0.0;
                    *z = c64::new(*x, 0.0);
                }
            }
        }
        if !guard.is_finite() {
            let bad = check_finite("channel", a)
                .and_then(|_| b.map_or(Ok(()), |b| check_finite("channel", b)));
            if let Err(Error::NonFinite { what, index }) = bad {
                return Err(Error::NonFinite {
                    what,
                    index: off + index,
                });
            }
        }
        self.fft
            .process_with_scratch(&mut self.buf, &mut self.scratch);
        Ok(())
    }
}

/// Most periods of deviations held before they are folded into the second-moment sums.
const BLOCK: usize = 16;
/// Largest block buffer (complex numbers) for which [`BLOCK`] periods are held; above it the
/// block shrinks so that the buffer stays within the size of the sums themselves.
const BLOCK_BUDGET: usize = 1 << 22;

/// Running sums of the analysed periods, shared by [`PeriodicAnalyzer::analyze`] and
/// [`PeriodicAccumulator`] so that both give bit-identical spectra.
///
/// Two noisy channels (the SISO case) are split, deviated and accumulated in one pass per
/// period. More noisy channels: the deviations of up to `block` periods are held line-major
/// (`dev[(k · block + p) · nn + a]`) and folded into the per-line pair sums
/// (`s2[k · n_pairs + q]`) once per block, each sum in period order — the same additions, in
/// the same order, as one accumulation per period, with one pass over the sums per block
/// instead of per period, and only for the pairs and lines asked for.
#[derive(Debug, Clone)]
struct PeriodSums {
    n: usize,
    lines: usize,
    nc: usize,
    exact: Vec<bool>,
    noisy: Vec<usize>,
    /// The first analysed period of every exactly periodic channel (transformed at the end).
    first_exact: Vec<Vec<f64>>,
    /// Position of the first analysed period in the record.
    first_off: usize,
    periods: usize,
    /// Spectra of the reference (first analysed) period, noisy channels.
    refp: Vec<Vec<c64>>,
    s1: Vec<Vec<c64>>,
    /// Two noisy channels: Σ|d_a|², Σ|d_b|², Σ d_a d_b*.
    saa: Vec<f64>,
    sbb: Vec<f64>,
    sab: Vec<c64>,
    /// Otherwise: the noisy pairs (a ≤ b, indices into `noisy`) whose sums are kept,
    pairs: Vec<(usize, usize)>,
    /// the lines on which they are kept (`None`: all),
    line_mask: Option<Vec<bool>>,
    /// Σ d_a d_b* per line and kept pair, line-major,
    s2: Vec<c64>,
    /// and the deviations of the periods of the current block.
    dev: Vec<c64>,
    block: usize,
    in_block: usize,
}

impl PeriodSums {
    fn new(
        n: usize,
        exact: &[bool],
        need: &dyn Fn(usize, usize) -> bool,
        line_mask: Option<&[bool]>,
    ) -> Result<Self> {
        let lines = n / 2 + 1;
        if let Some(m) = line_mask {
            if m.len() != lines {
                return Err(Error::invalid(
                    "lines",
                    format!("a line mask needs {lines} flags, got {}", m.len()),
                ));
            }
        }
        let zero = c64::new(0.0, 0.0);
        let noisy: Vec<usize> = (0..exact.len()).filter(|&c| !exact[c]).collect();
        let nn = noisy.len();
        let two = nn == 2;
        let pairs: Vec<(usize, usize)> = if two {
            Vec::new()
        } else {
            (0..nn)
                .flat_map(|a| (a..nn).map(move |b| (a, b)))
                .filter(|&(a, b)| need(noisy[a], noisy[b]))
                .collect()
        };
        let block = if two || nn == 0 {
            0
        } else if lines * nn * BLOCK <= BLOCK_BUDGET {
            BLOCK
        } else {
            nn.div_ceil(2).clamp(1, BLOCK)
        };
        Ok(Self {
            n,
            lines,
            nc: exact.len(),
            exact: exact.to_vec(),
            first_exact: exact.iter().map(|_| Vec::new()).collect(),
            first_off: 0,
            periods: 0,
            refp: vec![vec![zero; lines]; nn],
            s1: vec![vec![zero; lines]; nn],
            saa: vec![0.0; if two { lines } else { 0 }],
            sbb: vec![0.0; if two { lines } else { 0 }],
            sab: vec![zero; if two { lines } else { 0 }],
            s2: vec![zero; if two { 0 } else { lines * pairs.len() }],
            dev: Vec::new(),
            block,
            in_block: 0,
            line_mask: line_mask.map(|m| m.to_vec()),
            pairs,
            noisy,
        })
    }

    /// Adds one period (`period[c]` holds `n` samples of channel `c`); `off` is its position in
    /// the record, for error messages.
    fn add(&mut self, an: &mut PeriodicAnalyzer, period: &[&[f64]], off: usize) -> Result<()> {
        let (n, lines) = (self.n, self.lines);
        let first = self.periods == 0;
        if first {
            self.first_off = off;
            for c in (0..self.nc).filter(|&c| self.exact[c]) {
                self.first_exact[c] = period[c].to_vec();
            }
        }
        if self.noisy.len() == 2 {
            // the common case (u and y): split, deviate and accumulate in one pass per period
            let (ia, ib) = (self.noisy[0], self.noisy[1]);
            an.transform_pair(period[ia], Some(period[ib]), off)?;
            let z = &an.buf;
            // A_k = (Z_k + conj Z_{N−k})/2, B_k = (Z_k − conj Z_{N−k})/(2j); Z_N ≡ Z_0
            for k in 0..lines {
                let zk = z[k];
                let zc = if k == 0 { z[0] } else { z[n - k] }.conj();
                let d = zk - zc;
                let a = (zk + zc) * 0.5;
                let b = c64::new(d.im * 0.5, -d.re * 0.5);
                if first {
                    self.refp[0][k] = a;
                    self.refp[1][k] = b;
                } else {
                    let (da, db) = (a - self.refp[0][k], b - self.refp[1][k]);
                    self.s1[0][k] += da;
                    self.s1[1][k] += db;
                    self.saa[k] += da.norm_sqr();
                    self.sbb[k] += db.norm_sqr();
                    self.sab[k] += da * db.conj();
                }
            }
        } else if !self.noisy.is_empty() {
            let nn = self.noisy.len();
            let keep = !first && !self.pairs.is_empty();
            if keep && self.dev.is_empty() {
                self.dev = vec![c64::new(0.0, 0.0); lines * self.block * nn];
            }
            let (block, p) = (self.block, self.in_block);
            for pair in (0..nn).step_by(2) {
                let a = period[self.noisy[pair]];
                let b = self.noisy.get(pair + 1).map(|&c| period[c]);
                an.transform_pair(a, b, off)?;
                if first {
                    split_pair(&an.buf, n, lines, &mut self.refp, pair, b.is_some());
                    continue;
                }
                // split (as split_pair), deviate from the reference period, sum and hold the
                // deviations in one pass
                let z = &an.buf;
                let has_b = b.is_some();
                let mask = self.line_mask.as_deref();
                let (s1a, s1b) = if has_b {
                    let (lo, hi) = self.s1.split_at_mut(pair + 1);
                    (&mut lo[pair], Some(&mut hi[0]))
                } else {
                    (&mut self.s1[pair], None)
                };
                let ra = &self.refp[pair];
                let rb = has_b.then(|| &self.refp[pair + 1]);
                let mut s1b = s1b;
                for k in 0..lines {
                    let (va, vb) = if !has_b {
                        (z[k], c64::new(0.0, 0.0))
                    } else if k == 0 {
                        (c64::new(z[0].re, 0.0), c64::new(z[0].im, 0.0))
                    } else {
                        let zk = z[k];
                        let zc = z[n - k].conj();
                        let d = zk - zc; // = 2j B
                        ((zk + zc) * 0.5, c64::new(d.im * 0.5, -d.re * 0.5))
                    };
                    let da = va - ra[k];
                    s1a[k] += da;
                    let db = match (rb, s1b.as_deref_mut()) {
                        (Some(rb), Some(s1b)) => {
                            let db = vb - rb[k];
                            s1b[k] += db;
                            Some(db)
                        }
                        _ => None,
                    };
                    if keep && mask.is_none_or(|m| m[k]) {
                        let at = (k * block + p) * nn + pair;
                        self.dev[at] = da;
                        if let Some(db) = db {
                            self.dev[at + 1] = db;
                        }
                    }
                }
            }
            if keep {
                self.in_block += 1;
                if self.in_block == self.block {
                    self.fold_block();
                }
            }
        }
        self.periods += 1;
        Ok(())
    }

    /// Folds the held deviations into the pair sums, period by period in order.
    fn fold_block(&mut self) {
        let (nn, block, np, held) = (
            self.noisy.len(),
            self.block,
            self.pairs.len(),
            self.in_block,
        );
        if held == 0 {
            return;
        }
        for k in 0..self.lines {
            if self.line_mask.as_ref().is_some_and(|m| !m[k]) {
                continue;
            }
            let d = &self.dev[k * block * nn..(k * block + held) * nn];
            let acc = &mut self.s2[k * np..(k + 1) * np];
            for (s, &(a, b)) in acc.iter_mut().zip(&self.pairs) {
                let mut v = *s;
                for row in d.chunks_exact(nn) {
                    v += row[a] * row[b].conj();
                }
                *s = v;
            }
        }
        self.in_block = 0;
    }

    // parallel per-line arrays, indexed alike
    #[allow(clippy::needless_range_loop)]
    fn finish(
        &mut self,
        an: &mut PeriodicAnalyzer,
        fs: f64,
        skipped: usize,
        tail: usize,
    ) -> Result<PeriodicSpectra> {
        self.fold_block();
        let (lines, nc) = (self.lines, self.nc);
        let zero = c64::new(0.0, 0.0);
        let p_used = self.periods;
        let mut mean = vec![vec![zero; lines]; nc];
        let npairs = nc * (nc + 1) / 2;
        let mut cov: Vec<Vec<c64>> = vec![Vec::new(); npairs];
        let mut cov_skipped = vec![false; npairs];
        // Exactly periodic channels: one transform, zero (co)variance.
        for c in (0..nc).filter(|&c| self.exact[c]) {
            an.transform_pair(&self.first_exact[c], None, self.first_off)?;
            mean[c].copy_from_slice(&an.buf[..lines]);
        }
        let pf = p_used as f64;
        let nn = self.noisy.len();
        if nn == 2 {
            let (ia, ib) = (self.noisy[0], self.noisy[1]);
            for k in 0..lines {
                mean[ia][k] = self.refp[0][k] + self.s1[0][k] / pf;
                mean[ib][k] = self.refp[1][k] + self.s1[1][k] / pf;
            }
            let (paa, pbb, pab) = (
                pair_index(nc, ia, ia),
                pair_index(nc, ib, ib),
                pair_index(nc, ia, ib),
            );
            for q in [paa, pbb, pab] {
                cov[q] = vec![zero; lines];
            }
            if p_used > 1 {
                let denom = pf - 1.0;
                for k in 0..lines {
                    let va = (self.saa[k] - self.s1[0][k].norm_sqr() / pf) / denom;
                    let vb = (self.sbb[k] - self.s1[1][k].norm_sqr() / pf) / denom;
                    cov[paa][k] = c64::new(va.max(0.0), 0.0);
                    cov[pbb][k] = c64::new(vb.max(0.0), 0.0);
                    cov[pab][k] = (self.sab[k] - self.s1[0][k] * self.s1[1][k].conj() / pf) / denom;
                }
            }
        } else if nn > 0 {
            for a in 0..nn {
                for k in 0..lines {
                    mean[self.noisy[a]][k] = self.refp[a][k] + self.s1[a][k] / pf;
                }
            }
            for a in 0..nn {
                for b in a..nn {
                    let (ia, ib) = (self.noisy[a], self.noisy[b]);
                    cov_skipped[pair_index(nc, ia.min(ib), ia.max(ib))] = true;
                }
            }
            let np = self.pairs.len();
            let denom = pf - 1.0;
            let nan = c64::new(f64::NAN, f64::NAN);
            for (q, &(a, b)) in self.pairs.iter().enumerate() {
                let (ia, ib) = (self.noisy[a], self.noisy[b]);
                let (lo, hi, swap) = if ia <= ib {
                    (ia, ib, false)
                } else {
                    (ib, ia, true)
                };
                let pi = pair_index(nc, lo, hi);
                cov_skipped[pi] = false;
                let out = &mut cov[pi];
                *out = vec![zero; lines];
                if p_used > 1 {
                    for k in 0..lines {
                        if self.line_mask.as_ref().is_some_and(|m| !m[k]) {
                            out[k] = nan;
                            continue;
                        }
                        // Σ d_a d_b* − (Σ d_a)(Σ d_b)*/P, d = X − X_ref
                        let acc = self.s2[k * np + q];
                        let v = (acc - self.s1[a][k] * self.s1[b][k].conj() / pf) / denom;
                        out[k] = if a == b {
                            c64::new(v.re.max(0.0), 0.0)
                        } else if swap {
                            v.conj()
                        } else {
                            v
                        };
                    }
                }
            }
        }
        let any_skipped = cov_skipped.iter().any(|&s| s);
        Ok(PeriodicSpectra {
            fs,
            period_samples: self.n,
            periods: p_used,
            skipped,
            dropped_tail: tail,
            n_channels: nc,
            mean,
            cov,
            cov_skipped,
            zero_row: vec![zero; lines],
            nan_row: if any_skipped {
                vec![c64::new(f64::NAN, f64::NAN); lines]
            } else {
                Vec::new()
            },
            exact_periodic: self.exact.clone(),
        })
    }
}

/// Period-synchronous averaging fed one chunk at a time: holds one period of every channel
/// and the running sums ($O(C^2 N)$ numbers), never the record, and gives the same
/// [`PeriodicSpectra`], bit for bit, as [`PeriodicAnalyzer::analyze`] on the whole record.
///
/// `analyze` transforms a channel whose analysed periods are all bit-identical once (zero
/// variance) and pairs the others in complex FFTs; a stream cannot know that before its end,
/// so the caller says which channels are exactly periodic (`exact`, e.g. from a first pass
/// over the file); every period of such a channel is compared with the first analysed one,
/// and [`finish`](Self::finish) is an error if one differs.
///
/// # Example
/// ```
/// use ambid_core::frf::periodic::{PeriodicAccumulator, PeriodicAnalyzer, PeriodicOptions};
/// let n = 64;
/// let x: Vec<f64> = (0..4 * n).map(|k| ((k % n) as f64 * 0.3).sin()).collect();
/// let y: Vec<f64> = (0..4 * n).map(|k| 0.5 * x[k] + 1e-3 * ((k * 7919) % 13) as f64).collect();
/// let u: Vec<f64> = (0..4 * n).map(|k| x[k] - y[k]).collect();
/// let opts = PeriodicOptions::new(n).skip(1);
/// let whole = PeriodicAnalyzer::new(n).unwrap().analyze(&[&x, &u, &y], 1e3, &opts).unwrap();
/// let mut acc = PeriodicAccumulator::new(3, &opts, vec![true, false, false]).unwrap();
/// for k in (0..4 * n).step_by(50) {
///     let e = (k + 50).min(4 * n);
///     acc.push(&[&x[k..e], &u[k..e], &y[k..e]]).unwrap();
/// }
/// assert_eq!(acc.finish(1e3).unwrap(), whole);
/// ```
#[derive(Debug)]
pub struct PeriodicAccumulator {
    an: PeriodicAnalyzer,
    opts: PeriodicOptions,
    sums: PeriodSums,
    /// Channel-major buffer of the period being filled.
    buf: Vec<f64>,
    filled: usize,
    n_samples: usize,
    /// The first exactly-periodic channel found to differ, with the period's offset.
    broken: Option<(usize, usize)>,
}

impl PeriodicAccumulator {
    /// An empty accumulator for `n_channels` channels cut as `opts` says; `exact[c]` declares
    /// channel `c` exactly periodic.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for `period_samples < 2`, no channel or an `exact` of another
    /// length.
    pub fn new(n_channels: usize, opts: &PeriodicOptions, exact: Vec<bool>) -> Result<Self> {
        let an = PeriodicAnalyzer::new(opts.period_samples)?;
        if n_channels == 0 {
            return Err(Error::invalid("channels", "no channel to analyse"));
        }
        if exact.len() != n_channels {
            return Err(Error::invalid(
                "exact",
                format!(
                    "one flag per channel is needed: {} flags for {n_channels} channels",
                    exact.len()
                ),
            ));
        }
        let n = opts.period_samples;
        Ok(Self {
            an,
            opts: *opts,
            sums: PeriodSums::new(n, &exact, &|_, _| true, None)?,
            buf: vec![0.0; n_channels * n],
            filled: 0,
            n_samples: 0,
            broken: None,
        })
    }

    /// Appends the next samples of every channel (all the same length, any length).
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] for a wrong number of slices or slices of different
    /// lengths; [`Error::NonFinite`] for a NaN or infinite sample of an analysed period (its
    /// index counted from the start of the record).
    pub fn push<S: AsRef<[f64]>>(&mut self, chunk: &[S]) -> Result<()> {
        let nc = self.sums.nc;
        if chunk.len() != nc {
            return Err(Error::DimensionMismatch {
                context: "PeriodicAccumulator::push (one slice per channel)",
                expected: format!("{nc} channels"),
                got: format!("{} slices", chunk.len()),
            });
        }
        let len = chunk[0].as_ref().len();
        if let Some(c) = chunk.iter().position(|x| x.as_ref().len() != len) {
            return Err(Error::DimensionMismatch {
                context: "PeriodicAccumulator::push (every channel's chunk the same length)",
                expected: format!("{len} samples (channel 0)"),
                got: format!("{} samples in channel {c}", chunk[c].as_ref().len()),
            });
        }
        let n = self.opts.period_samples;
        let mut pos = 0;
        while pos < len {
            let take = (len - pos).min(n - self.filled);
            for (c, x) in chunk.iter().enumerate() {
                self.buf[c * n + self.filled..c * n + self.filled + take]
                    .copy_from_slice(&x.as_ref()[pos..pos + take]);
            }
            self.filled += take;
            pos += take;
            self.n_samples += take;
            if self.filled == n {
                self.filled = 0;
                let index = self.n_samples / n - 1;
                if index >= self.opts.skip_periods {
                    let off = index * n;
                    let period: Vec<&[f64]> = self.buf.chunks(n).collect();
                    if self.sums.periods > 0 && self.broken.is_none() {
                        self.broken = (0..nc)
                            .find(|&c| {
                                self.sums.exact[c] && period[c] != &self.sums.first_exact[c][..]
                            })
                            .map(|c| (c, off));
                    }
                    self.sums.add(&mut self.an, &period, off)?;
                }
            }
        }
        Ok(())
    }

    /// Samples pushed so far.
    pub fn n_samples(&self) -> usize {
        self.n_samples
    }

    /// The spectra of the whole periods pushed, as [`PeriodicAnalyzer::analyze`] gives them
    /// for the same record, `fs` and options.
    ///
    /// # Errors
    /// As `analyze`: `fs` not positive, a strict record that is not a whole number of periods,
    /// no period left after the skipped ones; and a channel declared exactly periodic whose
    /// periods differ.
    pub fn finish(&mut self, fs: f64) -> Result<PeriodicSpectra> {
        if !(fs.is_finite() && fs > 0.0) {
            return Err(Error::invalid(
                "fs",
                format!("the sampling frequency must be positive and finite, got {fs}"),
            ));
        }
        let n = self.opts.period_samples;
        let (len, total_periods, tail) = (self.n_samples, self.n_samples / n, self.filled);
        if self.opts.strict && tail != 0 {
            return Err(Error::invalid(
                "period_samples",
                format!(
                    "the record has {len} samples, which is not an integer number of periods of {n} samples \
                     ({total_periods} periods and {tail} samples); pass the right period length or trim the \
                     record to a multiple of it (or allow an incomplete tail)"
                ),
            ));
        }
        if total_periods <= self.opts.skip_periods {
            return Err(Error::invalid(
                "skip_periods",
                format!(
                    "the record holds {total_periods} whole period(s) of {n} samples and {} are to be skipped; \
                     record more periods or skip fewer",
                    self.opts.skip_periods
                ),
            ));
        }
        if let Some((c, off)) = self.broken {
            return Err(Error::invalid(
                "exact",
                format!(
                    "channel {c} was declared exactly periodic but the period at sample {off} \
                     differs from the first analysed one; declare it noisy"
                ),
            ));
        }
        self.sums
            .finish(&mut self.an, fs, self.opts.skip_periods, tail)
    }
}

/// Splits $Z = \mathrm{DFT}(a + j b)$ into $A_k = (Z_k + \bar Z_{N-k})/2$ and
/// $B_k = (Z_k - \bar Z_{N-k})/(2j)$.
fn split_pair(z: &[c64], n: usize, lines: usize, out: &mut [Vec<c64>], a: usize, has_b: bool) {
    if !has_b {
        out[a].copy_from_slice(&z[..lines]);
        return;
    }
    let (lo, hi) = out.split_at_mut(a + 1);
    let (oa, ob) = (&mut lo[a], &mut hi[0]);
    oa[0] = c64::new(z[0].re, 0.0);
    ob[0] = c64::new(z[0].im, 0.0);
    for k in 1..lines {
        let zk = z[k];
        let zc = z[n - k].conj();
        oa[k] = (zk + zc) * 0.5;
        let d = zk - zc; // = 2j B
        ob[k] = c64::new(d.im * 0.5, -d.re * 0.5);
    }
}

impl PeriodicSpectra {
    /// Sampling frequency \[Hz\].
    pub fn fs(&self) -> f64 {
        self.fs
    }

    /// Samples per period $N$.
    pub fn period_samples(&self) -> usize {
        self.period_samples
    }

    /// Periods averaged $P$ (after the skipped ones).
    pub fn periods(&self) -> usize {
        self.periods
    }

    /// Leading periods dropped as transient.
    pub fn skipped_periods(&self) -> usize {
        self.skipped
    }

    /// Samples after the last whole period that were ignored (0 in strict mode).
    pub fn dropped_tail(&self) -> usize {
        self.dropped_tail
    }

    /// Number of channels.
    pub fn n_channels(&self) -> usize {
        self.n_channels
    }

    /// Number of lines $\lfloor N/2 \rfloor + 1$ (DC included).
    pub fn n_lines(&self) -> usize {
        self.period_samples / 2 + 1
    }

    /// Frequency of line `k`: $k f_s / N$ \[Hz\].
    pub fn line_hz(&self, k: usize) -> f64 {
        k as f64 * self.fs / self.period_samples as f64
    }

    /// Frequency resolution $f_s/N$ \[Hz\].
    pub fn resolution_hz(&self) -> f64 {
        self.fs / self.period_samples as f64
    }

    /// Whether channel `c` was bit-identical in every analysed period.
    pub fn is_exactly_periodic(&self, c: usize) -> bool {
        self.exact_periodic.get(c).copied().unwrap_or(false)
    }

    /// Mean DFT $\bar X(k)$ of channel `c` on every line (unnormalised, see the module docs).
    ///
    /// # Panics
    /// Never for `c < n_channels()`; an out-of-range `c` is a programming error and panics.
    pub fn mean(&self, c: usize) -> &[c64] {
        &self.mean[c]
    }

    /// The stored row of the pair `i ≤ j`.
    fn cov_row(&self, i: usize, j: usize) -> &[c64] {
        let q = pair_index(self.n_channels, i, j);
        let row = &self.cov[q];
        if !row.is_empty() {
            row
        } else if self.cov_skipped[q] {
            &self.nan_row
        } else {
            &self.zero_row
        }
    }

    /// Per-period covariance $\hat\sigma_{ij}(k)$ between channels `i` and `j` on every line (zero
    /// when $P = 1$). The covariance of the means is this divided by [`periods`](Self::periods).
    pub fn cov(&self, i: usize, j: usize) -> Vec<c64> {
        if i <= j {
            self.cov_row(i, j).to_vec()
        } else {
            self.cov_row(j, i).iter().map(|v| v.conj()).collect()
        }
    }

    /// Per-period variance $\hat\sigma_{ii}(k)$ of channel `c` on every line.
    pub fn var(&self, c: usize) -> Vec<f64> {
        self.cov_row(c, c).iter().map(|v| v.re).collect()
    }

    /// The stored covariance row of the pair `(i, j)` and whether it must be conjugated to give
    /// $\hat\sigma_{ij}$ (the upper triangle is stored).
    pub fn cov_slice(&self, i: usize, j: usize) -> (&[c64], bool) {
        if i <= j {
            (self.cov_row(i, j), false)
        } else {
            (self.cov_row(j, i), true)
        }
    }

    /// One covariance entry without allocating.
    pub fn cov_at(&self, i: usize, j: usize, k: usize) -> c64 {
        if i <= j {
            self.cov_row(i, j)[k]
        } else {
            self.cov_row(j, i)[k].conj()
        }
    }

    /// Mean second moment across periods $\frac1P\sum_p X_{i,p}(k)\overline{X_{j,p}(k)}$.
    pub fn moment_at(&self, i: usize, j: usize, k: usize) -> c64 {
        let p = self.periods as f64;
        self.cov_at(i, j, k) * ((p - 1.0) / p) + self.mean[i][k] * self.mean[j][k].conj()
    }

    /// Amplitude of the mean periodic component of channel `c` on line `k` (the $a$ of
    /// $a\cos(2\pi f_k t + \varphi)$; for DC and the Nyquist line the value itself).
    pub fn amplitude(&self, c: usize, k: usize) -> f64 {
        let n = self.period_samples;
        let scale = if k == 0 || 2 * k == n { 1.0 } else { 2.0 };
        scale * self.mean[c][k].norm() / n as f64
    }

    /// Coherence $\gamma^2_{ij}(k) = |\overline{X_i^* X_j}|^2 / (\overline{|X_i|^2}\,\overline{|X_j|^2})$
    /// with averages over the periods (a Welch estimate with a rectangular window of one period);
    /// NaN where either channel has no power.
    pub fn coherence_at(&self, i: usize, j: usize, k: usize) -> f64 {
        let sij = self.moment_at(i, j, k);
        let sii = self.moment_at(i, i, k).re;
        let sjj = self.moment_at(j, j, k).re;
        if sii > 0.0 && sjj > 0.0 {
            (sij.norm_sqr() / (sii * sjj)).min(1.0)
        } else {
            f64::NAN
        }
    }

    /// Lines $k \ge 1$ where the mean amplitude of channel `c` exceeds `rel_threshold` times its
    /// largest line amplitude (DC excluded): the excited lines of a periodic excitation.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `rel_threshold` is not in $[0, 1)$ or the channel has no
    /// power on any line (no excitation).
    pub fn excited_lines(&self, c: usize, rel_threshold: f64) -> Result<Vec<usize>> {
        if !(0.0..1.0).contains(&rel_threshold) {
            return Err(Error::invalid(
                "rel_threshold",
                format!("must be in [0, 1), got {rel_threshold}"),
            ));
        }
        let m = &self.mean[c];
        let peak = m[1..].iter().fold(0.0f64, |a, v| a.max(v.norm_sqr()));
        if peak == 0.0 {
            return Err(Error::invalid(
                "excitation",
                "the excitation channel has no power on any line: check the column and that the \
                 excitation was on",
            ));
        }
        Ok((1..m.len())
            .filter(|&k| m[k].norm_sqr() > rel_threshold * rel_threshold * peak)
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    fn naive_dft(x: &[f64], k: usize) -> c64 {
        let n = x.len();
        x.iter()
            .enumerate()
            .map(|(t, v)| {
                let ph = -2.0 * std::f64::consts::PI * (k * t % n) as f64 / n as f64;
                c64::new(v * ph.cos(), v * ph.sin())
            })
            .sum()
    }

    /// The textbook oracle on line `k`: the per-period DFTs (by the definition) of the periods
    /// `skip..periods` of every channel, their means and their sample covariance (zero for
    /// one period), `cov[i][j]`.
    fn naive_stats(
        chans: &[&[f64]],
        n: usize,
        skip: usize,
        periods: usize,
        k: usize,
    ) -> (Vec<c64>, Vec<Vec<c64>>) {
        let p = periods - skip;
        let dft: Vec<Vec<c64>> = chans
            .iter()
            .map(|x| {
                (skip..periods)
                    .map(|q| naive_dft(&x[q * n..(q + 1) * n], k))
                    .collect()
            })
            .collect();
        let means: Vec<c64> = dft
            .iter()
            .map(|d| d.iter().sum::<c64>() / p as f64)
            .collect();
        let cov = (0..chans.len())
            .map(|i| {
                (0..chans.len())
                    .map(|j| {
                        if p == 1 {
                            return c64::new(0.0, 0.0);
                        }
                        (0..p)
                            .map(|q| (dft[i][q] - means[i]) * (dft[j][q] - means[j]).conj())
                            .sum::<c64>()
                            / (p as f64 - 1.0)
                    })
                    .collect()
            })
            .collect();
        (means, cov)
    }

    /// Naive oracle: per-period DFTs by the O(N²) definition, then textbook mean and covariance.
    #[test]
    fn matches_naive_oracle_for_odd_and_even_lengths() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for &(n, periods, skip) in &[(31usize, 5usize, 1usize), (24, 4, 0), (15, 3, 2), (9, 3, 1)] {
            let len = n * periods;
            let base: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut rng)).collect();
            let r: Vec<f64> = (0..len).map(|k| base[k % n]).collect();
            let u: Vec<f64> = (0..len)
                .map(|k| {
                    base[k % n]
                        + 0.3 * {
                            let z: f64 = StandardNormal.sample(&mut rng);
                            z
                        }
                })
                .collect();
            let y: Vec<f64> = (0..len)
                .map(|k| {
                    0.5 * base[(k + 1) % n]
                        + 0.2 * {
                            let z: f64 = StandardNormal.sample(&mut rng);
                            z
                        }
                })
                .collect();
            let w: Vec<f64> = (0..len).map(|_| StandardNormal.sample(&mut rng)).collect();
            let all: [&[f64]; 4] = [&r, &u, &y, &w];
            // 3 channels: the fused two-noisy-channel path; 4: the general path
            for m in [3usize, 4] {
                let chans = &all[..m];
                let mut an = PeriodicAnalyzer::new(n).unwrap();
                let s = an
                    .analyze(chans, 100.0, &PeriodicOptions::new(n).skip(skip))
                    .unwrap();
                let p = periods - skip;
                assert_eq!(s.periods(), p);
                assert!(s.is_exactly_periodic(0) && (p == 1 || !s.is_exactly_periodic(1)));
                for k in 0..s.n_lines() {
                    let (means, cov) = naive_stats(chans, n, skip, periods, k);
                    for i in 0..m {
                        assert!(
                            (s.mean(i)[k] - means[i]).norm() < 1e-10,
                            "mean {i} line {k}"
                        );
                        for (j, &c) in cov[i].iter().enumerate() {
                            assert!(
                                (s.cov_at(i, j, k) - c).norm() < 1e-9,
                                "cov {i}{j} line {k}: {} vs {c}",
                                s.cov_at(i, j, k)
                            );
                        }
                    }
                }
            }
        }
    }

    /// Many periods (several blocks of held deviations, the last one partial) against the
    /// naive oracle; the selected analysis equals the full one bit for bit where it computes,
    /// and reads NaN where it does not.
    #[test]
    fn blocks_of_periods_and_selected_pairs_and_lines() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (n, periods, skip) = (14usize, 37usize, 2usize);
        let len = n * periods;
        let base: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut rng)).collect();
        let r: Vec<f64> = (0..len).map(|k| base[k % n]).collect();
        let mut noisy = |g: f64, lag: usize| -> Vec<f64> {
            (0..len)
                .map(|k| {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    g * base[(k + lag) % n] + 0.3 * z
                })
                .collect()
        };
        let chans: Vec<Vec<f64>> = vec![
            r.clone(),
            noisy(1.0, 0),
            noisy(0.5, 1),
            noisy(-0.7, 2),
            noisy(0.2, 3),
            noisy(1.5, 4),
        ];
        let refs: Vec<&[f64]> = chans.iter().map(|c| c.as_slice()).collect();
        let opts = PeriodicOptions::new(n).skip(skip);
        let mut an = PeriodicAnalyzer::new(n).unwrap();
        let full = an.analyze(&refs, 10.0, &opts).unwrap();
        for k in 0..full.n_lines() {
            let (means, cov) = naive_stats(&refs, n, skip, periods, k);
            for i in 0..refs.len() {
                assert!((full.mean(i)[k] - means[i]).norm() < 1e-10);
                for (j, &c) in cov[i].iter().enumerate() {
                    assert!(
                        (full.cov_at(i, j, k) - c).norm() < 1e-9 * (1.0 + c.norm()),
                        "cov {i}{j} line {k}"
                    );
                }
            }
        }
        // channels 1, 2 as "u", 3..5 as "y": u–u, u–y and y–y on the diagonal, odd lines
        let need = |i: usize, j: usize| i >= 1 && (i < 3 || i == j);
        let mask: Vec<bool> = (0..full.n_lines()).map(|k| k % 2 == 1).collect();
        let sel = an
            .analyze_selected(&refs, 10.0, &opts, &need, Some(&mask))
            .unwrap();
        for (k, &on) in mask.iter().enumerate() {
            for i in 0..refs.len() {
                assert_eq!(sel.mean(i)[k], full.mean(i)[k]);
                for j in i..refs.len() {
                    let (a, b) = (sel.cov_at(i, j, k), full.cov_at(i, j, k));
                    if i == 0 {
                        assert_eq!(a, c64::new(0.0, 0.0), "exact channel {i}{j}");
                    } else if need(i, j) && on {
                        assert_eq!(a, b, "pair {i}{j} line {k}");
                    } else {
                        assert!(a.re.is_nan() && a.im.is_nan(), "pair {i}{j} line {k}: {a}");
                    }
                }
            }
        }
        assert!(an
            .analyze_selected(&refs, 10.0, &opts, &need, Some(&mask[1..]))
            .is_err());
    }

    #[test]
    fn coherence_is_one_without_noise_and_below_with() {
        let n = 20;
        let x: Vec<f64> = (0..4 * n).map(|k| ((k % n) as f64).sin()).collect();
        let y: Vec<f64> = x.iter().map(|v| 2.0 * v).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let z: Vec<f64> = y
            .iter()
            .map(|v| {
                v + 0.5 * {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    z
                }
            })
            .collect();
        let mut an = PeriodicAnalyzer::new(n).unwrap();
        let s = an
            .analyze(&[&x, &y, &z], 1.0, &PeriodicOptions::new(n))
            .unwrap();
        for k in 1..s.n_lines() {
            assert!((s.coherence_at(0, 1, k) - 1.0).abs() < 1e-12);
            assert!(s.coherence_at(0, 2, k) < 1.0);
        }
    }

    #[test]
    fn errors_are_clear() {
        let x = vec![1.0; 100];
        let mut an = PeriodicAnalyzer::new(30).unwrap();
        let e = an
            .analyze(&[&x], 1.0, &PeriodicOptions::new(30))
            .unwrap_err();
        assert!(
            e.to_string().contains("not an integer number of periods"),
            "{e}"
        );
        let s = an
            .analyze(&[&x], 1.0, &PeriodicOptions::new(30).lenient())
            .unwrap();
        assert_eq!((s.periods(), s.dropped_tail()), (3, 10));
        assert!(an
            .analyze(&[&x], 1.0, &PeriodicOptions::new(30).lenient().skip(3))
            .unwrap_err()
            .to_string()
            .contains("skip fewer"));
        let short = vec![1.0; 99];
        assert!(matches!(
            an.analyze(&[&x[..90], &short[..60]], 1.0, &PeriodicOptions::new(30)),
            Err(Error::DimensionMismatch { .. })
        ));
        let mut bad = vec![0.0; 90];
        bad[7] = f64::NAN;
        assert!(matches!(
            an.analyze(&[&bad], 1.0, &PeriodicOptions::new(30)),
            Err(Error::NonFinite { index: 7, .. })
        ));
        assert!(PeriodicAnalyzer::new(1).is_err());
        let s = an
            .analyze(&[&vec![0.0; 90]], 1.0, &PeriodicOptions::new(30))
            .unwrap();
        assert!(s
            .excited_lines(0, 1e-6)
            .unwrap_err()
            .to_string()
            .contains("no power"));
    }
}
