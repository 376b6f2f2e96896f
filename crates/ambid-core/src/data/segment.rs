//! Cutting a record into whole excitation periods, and dropping the start-up transient.
//!
//! A periodic excitation of $P$ samples per period reaches steady state after the closed loop's
//! transient has died out. Periodic FRF estimation then averages whole periods: with $N$ recorded
//! samples and the first $K$ periods skipped,
//! $$ M = \left\lfloor N / P \right\rfloor - K \quad\text{periods are used, samples }
//! [K P,\; (K + M) P), $$
//! period $p$ being samples $[(K + p) P, (K + p + 1) P)$. Period boundaries stay aligned with sample
//! 0 of the record (where the excitation started), so an incomplete last period is dropped at the
//! *end* ([`Segmentation::dropped_tail`]). In strict mode ([`SegmentOptions::strict`]) a record that
//! is not a whole number of periods is an error instead: usually the period length is wrong.
//!
//! Non-periodic data only lose their first samples: [`drop_transient`].
//!
//! # Example
//! ```
//! use ambid_core::data::{segment_periods, SegmentOptions};
//! // 5115-sample PRBS periods (order 10, 5 samples per bit), 20 periods and 100 extra samples.
//! let seg = segment_periods(20 * 5115 + 100, 5115, 2, &SegmentOptions::default()).unwrap();
//! assert_eq!((seg.start, seg.periods, seg.dropped_tail), (2 * 5115, 18, 100));
//! assert_eq!(seg.range(), 10230..102300);
//! let strict = SegmentOptions { strict: true, ..SegmentOptions::default() };
//! assert!(segment_periods(20 * 5115 + 100, 5115, 2, &strict).is_err());
//! ```

use super::IoData;
use crate::error::{Error, Result};
use std::fmt;
use std::ops::Range;

/// How [`segment_periods`] treats the record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SegmentOptions {
    /// Fewest whole periods that must remain after skipping (at least 1; default 1).
    pub min_periods: usize,
    /// When `true`, a record that is not a whole number of periods is an error; when `false`
    /// (default) the incomplete last period is dropped and reported.
    pub strict: bool,
}

impl Default for SegmentOptions {
    fn default() -> Self {
        SegmentOptions {
            min_periods: 1,
            strict: false,
        }
    }
}

/// Where the whole periods of a record are.
///
/// Samples `[0, start)` are the skipped transient periods, `[start, start + periods · period_samples)`
/// the periods used, and the last `dropped_tail` samples an incomplete period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Segmentation {
    /// First sample of the first period used ($K P$).
    pub start: usize,
    /// Number of whole periods used ($M$).
    pub periods: usize,
    /// Samples per period ($P$).
    pub period_samples: usize,
    /// Periods skipped at the start as transient ($K$).
    pub skipped_periods: usize,
    /// Samples of the incomplete last period that were dropped ($N \bmod P$).
    pub dropped_tail: usize,
}

impl Segmentation {
    /// One past the last sample used.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{segment_periods, SegmentOptions};
    /// assert_eq!(segment_periods(25, 10, 1, &SegmentOptions::default()).unwrap().end(), 20);
    /// ```
    pub fn end(&self) -> usize {
        // Saturating: the fields are public, so a hand-made value must not overflow.
        self.start
            .saturating_add(self.periods.saturating_mul(self.period_samples))
    }

    /// The samples used, `start..end()`.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{segment_periods, SegmentOptions};
    /// assert_eq!(segment_periods(25, 10, 1, &SegmentOptions::default()).unwrap().range(), 10..20);
    /// ```
    pub fn range(&self) -> Range<usize> {
        self.start..self.end()
    }

    /// The samples of period `p` (0 = the first period *used*), or `None` past the last.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{segment_periods, SegmentOptions};
    /// let seg = segment_periods(30, 10, 1, &SegmentOptions::default()).unwrap();
    /// assert_eq!(seg.period_range(1), Some(20..30));
    /// assert_eq!(seg.period_range(2), None);
    /// ```
    pub fn period_range(&self, p: usize) -> Option<Range<usize>> {
        if p >= self.periods {
            return None;
        }
        let a = self
            .start
            .checked_add(p.checked_mul(self.period_samples)?)?;
        Some(a..a.checked_add(self.period_samples)?)
    }

    /// Period `p` (0 = the first period used) of a signal of the segmented length.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `p >= periods` or when `x` is too short for this segmentation
    /// (it was made for another record).
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{segment_periods, SegmentOptions};
    /// let x: Vec<f64> = (0..7).map(f64::from).collect();
    /// let seg = segment_periods(x.len(), 3, 1, &SegmentOptions::default()).unwrap();
    /// assert_eq!(seg.period(&x, 0).unwrap(), &[3.0, 4.0, 5.0]);
    /// assert!(seg.period(&x, 1).is_err());
    /// ```
    pub fn period<'a>(&self, x: &'a [f64], p: usize) -> Result<&'a [f64]> {
        self.check_len(x.len())?;
        let r = self.period_range(p).ok_or_else(|| {
            Error::invalid(
                "p",
                format!(
                    "period {p} does not exist; the segmentation has periods 0..{}",
                    self.periods
                ),
            )
        })?;
        Ok(&x[r])
    }

    /// The part of `data` made of the periods used (with its period length set to
    /// [`Segmentation::period_samples`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `data` is too short for this segmentation.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{segment_periods, IoData, SegmentOptions};
    /// let data = IoData::new(vec![("y".into(), (0..7).map(f64::from).collect())], 1.0, None).unwrap();
    /// let seg = segment_periods(data.len(), 3, 1, &SegmentOptions::default()).unwrap();
    /// let cut = seg.apply(&data).unwrap();
    /// assert_eq!(cut.channel("y").unwrap(), &[3.0, 4.0, 5.0]);
    /// assert_eq!(cut.period_samples(), Some(3));
    /// ```
    pub fn apply(&self, data: &IoData) -> Result<IoData> {
        self.check_len(data.len())?;
        data.slice(self.start, self.end())?
            .with_period_samples(Some(self.period_samples))
    }

    /// One line for a log or a report.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{segment_periods, SegmentOptions};
    /// let s = segment_periods(25, 10, 1, &SegmentOptions::default()).unwrap().summary();
    /// assert_eq!(s, "1 period of 10 samples used (samples 10..20); 1 transient period skipped; \
    ///                5 samples of an incomplete last period dropped");
    /// ```
    pub fn summary(&self) -> String {
        let plural = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
        let mut s = format!(
            "{} of {} samples used (samples {}..{})",
            plural(self.periods, "period"),
            self.period_samples,
            self.start,
            self.end()
        );
        s += &format!(
            "; {} skipped",
            plural(self.skipped_periods, "transient period")
        );
        if self.dropped_tail > 0 {
            s += &format!(
                "; {} of an incomplete last period dropped",
                plural(self.dropped_tail, "sample")
            );
        }
        s
    }

    fn check_len(&self, n: usize) -> Result<()> {
        if n < self.end() {
            return Err(Error::invalid(
                "x",
                format!(
                    "the signal has {n} samples but this segmentation uses samples up to {}; \
                     segment the record the signal belongs to",
                    self.end()
                ),
            ));
        }
        Ok(())
    }
}

impl fmt::Display for Segmentation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.summary())
    }
}

/// Locates the whole periods of a record of `n_samples` samples with `period_samples` samples per
/// period, skipping the first `skip_periods` periods as transient (see the [module docs](self)).
///
/// # Errors
/// [`Error::InvalidArgument`] when
/// * `period_samples == 0` or `opts.min_periods == 0`;
/// * the period is longer than the record;
/// * `opts.strict` and `n_samples` is not a multiple of `period_samples` (the message names the fix:
///   the right period length, `--period-samples` on the command line, or a trimmed record);
/// * fewer than `opts.min_periods` whole periods remain after skipping `skip_periods`.
///
/// # Example
/// ```
/// use ambid_core::data::{segment_periods, SegmentOptions};
/// let seg = segment_periods(1000, 100, 3, &SegmentOptions::default()).unwrap();
/// assert_eq!((seg.start, seg.periods, seg.dropped_tail), (300, 7, 0));
/// let need = SegmentOptions { min_periods: 8, ..SegmentOptions::default() };
/// assert!(segment_periods(1000, 100, 3, &need).is_err());
/// ```
pub fn segment_periods(
    n_samples: usize,
    period_samples: usize,
    skip_periods: usize,
    opts: &SegmentOptions,
) -> Result<Segmentation> {
    if period_samples == 0 {
        return Err(Error::invalid(
            "period_samples",
            "a period of 0 samples is meaningless; pass the excitation's period length in samples \
             (`--period-samples`)",
        ));
    }
    if opts.min_periods == 0 {
        return Err(Error::invalid(
            "min_periods",
            "at least one whole period must remain; pass min_periods >= 1",
        ));
    }
    if period_samples > n_samples {
        return Err(Error::invalid(
            "period_samples",
            format!(
                "the period of {period_samples} samples is longer than the record of {n_samples} \
                 samples; check the period length (`--period-samples`) or record at least {} periods",
                skip_periods.saturating_add(opts.min_periods)
            ),
        ));
    }
    let whole = n_samples / period_samples;
    let tail = n_samples % period_samples;
    if opts.strict && tail != 0 {
        return Err(Error::invalid(
            "period_samples",
            format!(
                "the record of {n_samples} samples is not a whole number of periods of \
                 {period_samples} samples ({whole} periods and {tail} samples left over); pass the \
                 right period length (`--period-samples`), or trim the record to {} samples, or \
                 allow dropping the incomplete period (strict = false)",
                whole * period_samples
            ),
        ));
    }
    let required = skip_periods.saturating_add(opts.min_periods);
    if whole < required {
        return Err(Error::invalid(
            "n_samples",
            format!(
                "the record holds {whole} whole periods of {period_samples} samples, but {required} \
                 are needed ({skip_periods} skipped as transient + at least {} used); record longer, \
                 skip fewer periods, or lower min_periods",
                opts.min_periods
            ),
        ));
    }
    Ok(Segmentation {
        start: skip_periods * period_samples,
        periods: whole - skip_periods,
        period_samples,
        skipped_periods: skip_periods,
        dropped_tail: tail,
    })
}

/// Segments `data` by its own period length ([`IoData::period_samples`]); returns the periods used
/// (see [`Segmentation::apply`]) and where they were.
///
/// # Errors
/// [`Error::InvalidArgument`] when `data` has no period length, and as [`segment_periods`].
///
/// # Example
/// ```
/// use ambid_core::data::{segment_data, IoData, SegmentOptions};
/// let data = IoData::new(vec![("y".into(), vec![0.0; 35])], 1e-3, Some(10)).unwrap();
/// let (cut, seg) = segment_data(&data, 1, &SegmentOptions::default()).unwrap();
/// assert_eq!((cut.len(), seg.periods, seg.dropped_tail), (20, 2, 5));
/// ```
pub fn segment_data(
    data: &IoData,
    skip_periods: usize,
    opts: &SegmentOptions,
) -> Result<(IoData, Segmentation)> {
    let p = data.period_samples().ok_or_else(|| {
        Error::invalid(
            "data",
            "the record has no period length; set it (`--period-samples`, \
             IoData::with_period_samples) or use drop_transient for non-periodic data",
        )
    })?;
    let seg = segment_periods(data.len(), p, skip_periods, opts)?;
    Ok((seg.apply(data)?, seg))
}

/// What [`drop_transient`] cut from the start of a record.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TransientCut {
    /// Samples dropped at the start.
    pub dropped: usize,
    /// The same in seconds.
    pub dropped_s: f64,
    /// Samples kept.
    pub kept: usize,
}

impl TransientCut {
    /// One line for a log or a report.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{drop_transient, IoData};
    /// let data = IoData::new(vec![("y".into(), vec![0.0; 10])], 0.5, None).unwrap();
    /// let (_, cut) = drop_transient(&data, 4).unwrap();
    /// assert_eq!(cut.summary(), "dropped the first 4 samples (2 s) as transient; 6 samples kept");
    /// ```
    pub fn summary(&self) -> String {
        format!(
            "dropped the first {} samples ({} s) as transient; {} samples kept",
            self.dropped, self.dropped_s, self.kept
        )
    }
}

impl fmt::Display for TransientCut {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.summary())
    }
}

/// Drops the first `samples` samples of every channel (the start-up transient of non-periodic
/// data; periodic data skip whole periods with [`segment_periods`]). The period length is kept.
///
/// # Errors
/// [`Error::InvalidArgument`] when nothing would be left (`samples >= data.len()`).
///
/// # Example
/// ```
/// use ambid_core::data::{drop_transient, IoData};
/// let data = IoData::new(vec![("y".into(), vec![9.0, 9.0, 1.0, 2.0])], 1.0, None).unwrap();
/// let (kept, cut) = drop_transient(&data, 2).unwrap();
/// assert_eq!(kept.channel("y").unwrap(), &[1.0, 2.0]);
/// assert_eq!((cut.dropped, cut.kept), (2, 2));
/// assert!(drop_transient(&data, 4).is_err());
/// ```
pub fn drop_transient(data: &IoData, samples: usize) -> Result<(IoData, TransientCut)> {
    let n = data.len();
    if samples >= n {
        return Err(Error::invalid(
            "samples",
            format!(
                "dropping {samples} transient samples leaves nothing of a record of {n} samples; \
                 drop fewer or record longer"
            ),
        ));
    }
    let kept = data.slice(samples, n)?;
    Ok((
        kept,
        TransientCut {
            dropped: samples,
            dropped_s: samples as f64 * data.ts(),
            kept: n - samples,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    const STRICT: SegmentOptions = SegmentOptions {
        min_periods: 1,
        strict: true,
    };

    #[test]
    fn whole_record() {
        let s = segment_periods(40, 10, 0, &STRICT).unwrap();
        assert_eq!(
            s,
            Segmentation {
                start: 0,
                periods: 4,
                period_samples: 10,
                skipped_periods: 0,
                dropped_tail: 0
            }
        );
        assert_eq!(s.range(), 0..40);
        assert_eq!(s.period_range(3), Some(30..40));
        assert!(s.summary().contains("4 periods of 10 samples"));
        assert!(!s.summary().contains("incomplete"));
    }

    #[test]
    fn tail_and_skip() {
        let s = segment_periods(47, 10, 2, &SegmentOptions::default()).unwrap();
        assert_eq!(
            (s.start, s.periods, s.dropped_tail, s.end()),
            (20, 2, 7, 40)
        );
        let x: Vec<f64> = (0..47).map(f64::from).collect();
        assert_eq!(s.period(&x, 1).unwrap()[0], 30.0);
        assert!(s.period(&x, 2).is_err());
        assert!(s.period(&x[..39], 0).is_err(), "too short a signal");
        // Exactly the minimum.
        let s = segment_periods(30, 10, 2, &SegmentOptions::default()).unwrap();
        assert_eq!(s.periods, 1);
    }

    #[test]
    fn error_paths() {
        let e = segment_periods(10, 0, 0, &SegmentOptions::default()).unwrap_err();
        assert!(e.to_string().contains("0 samples"));
        let e = segment_periods(
            10,
            5,
            0,
            &SegmentOptions {
                min_periods: 0,
                strict: false,
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("min_periods"));
        let e = segment_periods(9, 10, 0, &SegmentOptions::default()).unwrap_err();
        assert!(e.to_string().contains("longer than the record"), "{e}");
        let e = segment_periods(45, 10, 0, &STRICT).unwrap_err().to_string();
        assert!(
            e.contains("--period-samples") && e.contains("trim the record to 40"),
            "{e}"
        );
        let e = segment_periods(45, 10, 4, &SegmentOptions::default()).unwrap_err();
        assert!(e.to_string().contains("4 whole periods"), "{e}");
        let e = segment_periods(
            45,
            10,
            2,
            &SegmentOptions {
                min_periods: 3,
                strict: false,
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("5 are needed"), "{e}");
        // Huge skip counts do not overflow.
        assert!(segment_periods(45, 10, usize::MAX, &SegmentOptions::default()).is_err());
    }

    #[test]
    fn hand_made_segmentation_does_not_overflow() {
        let s = Segmentation {
            start: usize::MAX - 1,
            periods: usize::MAX,
            period_samples: usize::MAX,
            skipped_periods: 0,
            dropped_tail: 0,
        };
        assert_eq!(s.end(), usize::MAX);
        assert_eq!(s.period_range(1), None);
        assert!(s.period(&[0.0; 4], 0).is_err());
        let d = IoData::new(vec![("y".into(), vec![0.0; 4])], 1.0, None).unwrap();
        assert!(s.apply(&d).is_err());
        assert!(!s.summary().is_empty());
    }

    #[test]
    fn data_level() {
        let y: Vec<f64> = (0..25).map(f64::from).collect();
        let d = IoData::new(vec![("y".into(), y)], 0.1, Some(10)).unwrap();
        let (cut, seg) = segment_data(&d, 1, &SegmentOptions::default()).unwrap();
        assert_eq!(cut.channel("y").unwrap()[0], 10.0);
        assert_eq!(cut.len(), 10);
        assert_eq!(seg.dropped_tail, 5);
        let short = d.slice(0, 5).unwrap();
        assert!(seg.apply(&short).is_err());
        let np = d.clone().with_period_samples(None).unwrap();
        let e = segment_data(&np, 0, &SegmentOptions::default()).unwrap_err();
        assert!(e.to_string().contains("no period length"));
        let (kept, cut) = drop_transient(&d, 24).unwrap();
        assert_eq!(kept.len(), 1);
        assert_eq!(kept.period_samples(), Some(10));
        assert!((cut.dropped_s - 2.4).abs() < 1e-12);
        assert!(drop_transient(&d, 25).is_err());
    }
}
