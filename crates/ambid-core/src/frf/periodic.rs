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
//! $\sum |X|^2 - P|\bar X|^2$ at lines with a high signal-to-noise ratio.
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
    /// Upper triangle (i ≤ j) of the per-period covariance, row-major.
    cov: Vec<Vec<c64>>,
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
        let p_used = total_periods - opts.skip_periods;
        let start = opts.skip_periods * n;
        let lines = n / 2 + 1;
        let nc = channels.len();
        let zero = c64::new(0.0, 0.0);

        let exact: Vec<bool> = channels
            .iter()
            .map(|x| {
                let first = &x[start..start + n];
                (1..p_used).all(|p| &x[start + p * n..start + (p + 1) * n] == first)
            })
            .collect();
        let mut mean = vec![vec![zero; lines]; nc];
        let mut cov = vec![vec![zero; lines]; nc * (nc + 1) / 2];

        // Exactly periodic channels: one transform, zero (co)variance.
        for c in (0..nc).filter(|&c| exact[c]) {
            self.transform_pair(&channels[c][start..start + n], None, start)?;
            mean[c].copy_from_slice(&self.buf[..lines]);
        }

        // Noisy channels, packed two per complex FFT.
        let noisy: Vec<usize> = (0..nc).filter(|&c| !exact[c]).collect();
        if noisy.len() == 2 {
            // the common case (u and y): split, deviate and accumulate in one pass per period
            let (ia, ib) = (noisy[0], noisy[1]);
            let (ca, cb) = (channels[ia], channels[ib]);
            let mut ref_a = vec![zero; lines];
            let mut ref_b = vec![zero; lines];
            let (mut s1a, mut s1b) = (vec![zero; lines], vec![zero; lines]);
            let (mut saa, mut sbb) = (vec![0.0f64; lines], vec![0.0f64; lines]);
            let mut sab = vec![zero; lines];
            for p in 0..p_used {
                let off = start + p * n;
                self.transform_pair(&ca[off..off + n], Some(&cb[off..off + n]), off)?;
                let z = &self.buf;
                // A_k = (Z_k + conj Z_{N−k})/2, B_k = (Z_k − conj Z_{N−k})/(2j); Z_N ≡ Z_0
                let first = p == 0;
                for k in 0..lines {
                    let zk = z[k];
                    let zc = if k == 0 { z[0] } else { z[n - k] }.conj();
                    let d = zk - zc;
                    let a = (zk + zc) * 0.5;
                    let b = c64::new(d.im * 0.5, -d.re * 0.5);
                    if first {
                        ref_a[k] = a;
                        ref_b[k] = b;
                    } else {
                        let (da, db) = (a - ref_a[k], b - ref_b[k]);
                        s1a[k] += da;
                        s1b[k] += db;
                        saa[k] += da.norm_sqr();
                        sbb[k] += db.norm_sqr();
                        sab[k] += da * db.conj();
                    }
                }
            }
            let pf = p_used as f64;
            for k in 0..lines {
                mean[ia][k] = ref_a[k] + s1a[k] / pf;
                mean[ib][k] = ref_b[k] + s1b[k] / pf;
            }
            if p_used > 1 {
                let denom = pf - 1.0;
                let (paa, pbb, pab) = (
                    pair_index(nc, ia, ia),
                    pair_index(nc, ib, ib),
                    pair_index(nc, ia, ib),
                );
                for k in 0..lines {
                    let va = (saa[k] - s1a[k].norm_sqr() / pf) / denom;
                    let vb = (sbb[k] - s1b[k].norm_sqr() / pf) / denom;
                    cov[paa][k] = c64::new(va.max(0.0), 0.0);
                    cov[pbb][k] = c64::new(vb.max(0.0), 0.0);
                    cov[pab][k] = (sab[k] - s1a[k] * s1b[k].conj() / pf) / denom;
                }
            }
        } else if !noisy.is_empty() {
            let nn = noisy.len();
            // spectra of the current period and of the reference (first) period
            let mut cur = vec![vec![zero; lines]; nn];
            let mut refp = vec![vec![zero; lines]; nn];
            let mut s1 = vec![vec![zero; lines]; nn];
            let mut s2 = vec![vec![zero; lines]; nn * (nn + 1) / 2];
            for p in 0..p_used {
                let off = start + p * n;
                for pair in (0..nn).step_by(2) {
                    let a = channels[noisy[pair]];
                    let b = noisy.get(pair + 1).map(|&c| channels[c]);
                    self.transform_pair(&a[off..off + n], b.map(|b| &b[off..off + n]), off)?;
                    split_pair(&self.buf, n, lines, &mut cur, pair, b.is_some());
                }
                if p == 0 {
                    for (r, c) in refp.iter_mut().zip(&cur) {
                        r.copy_from_slice(c);
                    }
                    continue;
                }
                // deviations from the reference period
                for a in 0..nn {
                    for k in 0..lines {
                        cur[a][k] -= refp[a][k];
                        s1[a][k] += cur[a][k];
                    }
                }
                for a in 0..nn {
                    for b in a..nn {
                        let acc = &mut s2[pair_index(nn, a, b)];
                        let (da, db) = (&cur[a], &cur[b]);
                        for k in 0..lines {
                            acc[k] += da[k] * db[k].conj();
                        }
                    }
                }
            }
            let pf = p_used as f64;
            for a in 0..nn {
                for k in 0..lines {
                    mean[noisy[a]][k] = refp[a][k] + s1[a][k] / pf;
                }
            }
            if p_used > 1 {
                let denom = pf - 1.0;
                for a in 0..nn {
                    for b in a..nn {
                        let (ia, ib) = (noisy[a], noisy[b]);
                        let (lo, hi, swap) = if ia <= ib {
                            (ia, ib, false)
                        } else {
                            (ib, ia, true)
                        };
                        let out = &mut cov[pair_index(nc, lo, hi)];
                        let acc = &s2[pair_index(nn, a, b)];
                        for k in 0..lines {
                            // Σ d_a d_b* − (Σ d_a)(Σ d_b)*/P, d = X − X_ref
                            let v = (acc[k] - s1[a][k] * s1[b][k].conj() / pf) / denom;
                            out[k] = if swap { v.conj() } else { v };
                        }
                        if a == b {
                            for v in out.iter_mut() {
                                *v = c64::new(v.re.max(0.0), 0.0);
                            }
                        }
                    }
                }
            }
        }

        Ok(PeriodicSpectra {
            fs,
            period_samples: n,
            periods: p_used,
            skipped: opts.skip_periods,
            dropped_tail: tail,
            n_channels: nc,
            mean,
            cov,
            exact_periodic: exact,
        })
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

    /// Per-period covariance $\hat\sigma_{ij}(k)$ between channels `i` and `j` on every line (zero
    /// when $P = 1$). The covariance of the means is this divided by [`periods`](Self::periods).
    pub fn cov(&self, i: usize, j: usize) -> Vec<c64> {
        let nc = self.n_channels;
        if i <= j {
            self.cov[pair_index(nc, i, j)].clone()
        } else {
            self.cov[pair_index(nc, j, i)]
                .iter()
                .map(|v| v.conj())
                .collect()
        }
    }

    /// Per-period variance $\hat\sigma_{ii}(k)$ of channel `c` on every line.
    pub fn var(&self, c: usize) -> Vec<f64> {
        self.cov[pair_index(self.n_channels, c, c)]
            .iter()
            .map(|v| v.re)
            .collect()
    }

    /// The stored covariance row of the pair `(i, j)` and whether it must be conjugated to give
    /// $\hat\sigma_{ij}$ (the upper triangle is stored).
    pub fn cov_slice(&self, i: usize, j: usize) -> (&[c64], bool) {
        let nc = self.n_channels;
        if i <= j {
            (&self.cov[pair_index(nc, i, j)], false)
        } else {
            (&self.cov[pair_index(nc, j, i)], true)
        }
    }

    /// One covariance entry without allocating.
    pub fn cov_at(&self, i: usize, j: usize, k: usize) -> c64 {
        let nc = self.n_channels;
        if i <= j {
            self.cov[pair_index(nc, i, j)][k]
        } else {
            self.cov[pair_index(nc, j, i)][k].conj()
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
                    for i in 0..m {
                        assert!(
                            (s.mean(i)[k] - means[i]).norm() < 1e-10,
                            "mean {i} line {k}"
                        );
                        for j in 0..m {
                            let c: c64 = (0..p)
                                .map(|q| (dft[i][q] - means[i]) * (dft[j][q] - means[j]).conj())
                                .sum::<c64>()
                                / (p as f64 - 1.0);
                            let c = if p == 1 { c64::new(0.0, 0.0) } else { c };
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
