//! Saturation and clipping: how much of a record sits at an actuator or sensor limit.
//!
//! A saturated amplifier or a clipped sensor makes the loop nonlinear, and a linear FRF estimated
//! from such data is biased. [`check_saturation`] measures the share of the record at the limit:
//!
//! * **Given limit** $L$ (e.g. the amplifier's saturation current $i_{\text{sat}}$): sample $k$
//!   counts when $|x_k| \ge L (1 - \epsilon)$, with the relative tolerance $\epsilon$
//!   ([`SaturationOptions::rel_tol`], default $10^{-9}$) absorbing rounding in the recorded value.
//!   The limit is symmetric, $\pm L$.
//! * **No limit given**: clipping shows as flat tops. With $x_{\max}$ and $x_{\min}$ the record's
//!   extremes, a sample is *at a rail* when
//!   $|x_k - x_{\max}| \le \tau$ or $|x_k - x_{\min}| \le \tau$,
//!   $\tau = \tau_r \max(|x_{\max}|, |x_{\min}|)$ ([`SaturationOptions::flat_tol`], default
//!   $\tau_r = 10^{-12}$), and it counts when it belongs to a run of at least $m$
//!   ([`SaturationOptions::min_run`], default 3) consecutive samples at the same rail. The levels
//!   of the rails where such runs were found are reported. A smooth signal reaches its maximum at
//!   one sample, or at two equal samples placed symmetrically around a peak, so $m = 3$ does not
//!   mistake it for clipping.
//!
//! The result, a [`SaturationReport`], gives the fraction, the count, the runs and the levels, and
//! a [`SaturationReport::summary`] for the user.
//!
//! # Complexity
//! $O(N)$.
//!
//! # Example
//! ```
//! use ambid_core::data::{check_saturation, SaturationOptions};
//! // A sine of amplitude 1 clipped at ±0.8.
//! let x: Vec<f64> = (0..1000)
//!     .map(|k| (2.0 * std::f64::consts::PI * k as f64 / 100.0).sin().clamp(-0.8, 0.8))
//!     .collect();
//! let given = check_saturation(&x, Some(0.8), &SaturationOptions::default()).unwrap();
//! let found = check_saturation(&x, None, &SaturationOptions::default()).unwrap();
//! assert_eq!(given.count, found.count);
//! assert_eq!((found.upper, found.lower), (Some(0.8), Some(-0.8)));
//! // Analytically 1 - (2/π) asin(0.8) ≈ 0.410 of the time; 100 samples per period give 0.42.
//! assert!((given.fraction - 0.410).abs() < 0.015);
//! ```

use crate::error::{check_finite, Error, Result};
use std::fmt;

/// Settings of [`check_saturation`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SaturationOptions {
    /// $\epsilon$: with a given limit $L$, samples with $|x| \ge L(1-\epsilon)$ count (default
    /// $10^{-9}$; must be in $[0, 1)$).
    pub rel_tol: f64,
    /// $m$: without a limit, the shortest flat run at a rail that counts (default 3, at least 2).
    pub min_run: usize,
    /// $\tau_r$: without a limit, how close to $x_{\max}$ or $x_{\min}$ a sample must be, relative
    /// to $\max(|x_{\max}|, |x_{\min}|)$ (default $10^{-12}$; finite and $\ge 0$).
    pub flat_tol: f64,
}

impl Default for SaturationOptions {
    fn default() -> Self {
        SaturationOptions {
            rel_tol: 1e-9,
            min_run: 3,
            flat_tol: 1e-12,
        }
    }
}

/// Where the limit in a [`SaturationReport`] came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LimitSource {
    /// The caller gave the limit.
    Given,
    /// No limit was given; flat runs at the record's extremes were looked for.
    Detected,
}

/// What [`check_saturation`] found.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SaturationReport {
    /// Samples checked.
    pub n_samples: usize,
    /// Samples at a limit.
    pub count: usize,
    /// `count / n_samples`.
    pub fraction: f64,
    /// Runs of consecutive samples at the same limit, as `(start, length)`, ascending.
    pub runs: Vec<(usize, usize)>,
    /// Upper level: $+L$ when given; when detected, $x_{\max}$ if flat runs were found there.
    pub upper: Option<f64>,
    /// Lower level: $-L$ when given; when detected, $x_{\min}$ if flat runs were found there.
    pub lower: Option<f64>,
    /// Whether the levels were given or detected.
    pub source: LimitSource,
    /// The shortest run that counted: 1 for a given limit, [`SaturationOptions::min_run`] when
    /// detected.
    pub min_run: usize,
}

impl SaturationReport {
    /// The longest run, `(start, length)`, if any.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{check_saturation, SaturationOptions};
    /// let rep = check_saturation(&[0.0, 1.0, 1.0, 0.0, -1.0], Some(1.0), &SaturationOptions::default()).unwrap();
    /// assert_eq!(rep.longest_run(), Some((1, 2)));
    /// ```
    pub fn longest_run(&self) -> Option<(usize, usize)> {
        // The first of equally long runs.
        self.runs
            .iter()
            .copied()
            .fold(None, |best: Option<(usize, usize)>, r| match best {
                Some(b) if b.1 >= r.1 => Some(b),
                _ => Some(r),
            })
    }

    /// What was found, in one line (samples numbered from 1).
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{check_saturation, SaturationOptions};
    /// let rep = check_saturation(&[0.0, 1.0, 1.0, 0.0], Some(1.0), &SaturationOptions::default()).unwrap();
    /// assert_eq!(rep.summary(), "2 of 4 samples (50.0 %) at the given limit ±1, in 1 run \
    ///     (longest 2 samples from sample 2)");
    /// ```
    pub fn summary(&self) -> String {
        let pct = percent(self.fraction);
        let runs = match self.longest_run() {
            Some((s, l)) => format!(
                "in {} run{} (longest {l} samples from sample {})",
                self.runs.len(),
                if self.runs.len() == 1 { "" } else { "s" },
                s + 1
            ),
            None => String::new(),
        };
        match self.source {
            LimitSource::Given => {
                let level = self.upper.unwrap_or(f64::NAN);
                if self.count == 0 {
                    format!(
                        "no sample reaches the given limit ±{level} (0 of {} samples)",
                        self.n_samples
                    )
                } else {
                    format!(
                        "{} of {} samples ({pct} %) at the given limit ±{level}, {runs}",
                        self.count, self.n_samples
                    )
                }
            }
            LimitSource::Detected => {
                if self.count == 0 {
                    format!(
                        "no flat run of {} or more samples at the record's maximum or minimum: \
                         no sign of clipping in {} samples",
                        self.min_run, self.n_samples
                    )
                } else {
                    let mut levels = Vec::new();
                    if let Some(u) = self.upper {
                        levels.push(format!("{u} (upper)"));
                    }
                    if let Some(l) = self.lower {
                        levels.push(format!("{l} (lower)"));
                    }
                    format!(
                        "{} of {} samples ({pct} %) flat at the record's extremes {}, {runs}, \
                         of at least {} samples: likely clipping; give the known limit to check it",
                        self.count,
                        self.n_samples,
                        levels.join(" and "),
                        self.min_run
                    )
                }
            }
        }
    }
}

impl fmt::Display for SaturationReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.summary())
    }
}

/// `100 · fraction` with at least two significant digits (`0.00010` for one sample in a million,
/// `41.0` for 0.41).
fn percent(fraction: f64) -> String {
    let p = 100.0 * fraction;
    if p <= 0.0 || !p.is_finite() {
        return format!("{p}");
    }
    let decimals = (1 - p.log10().floor() as i32).clamp(1, 12) as usize;
    format!("{p:.decimals$}")
}

/// Which rail a sample is at: +1 upper, -1 lower, 0 neither.
type Rail = i8;

/// Maximal runs of equal non-zero rail marks, as (start, length, rail).
fn rail_runs(marks: &[Rail]) -> Vec<(usize, usize, Rail)> {
    let mut runs = Vec::new();
    let mut i = 0;
    while i < marks.len() {
        let m = marks[i];
        let len = marks[i..].iter().take_while(|&&v| v == m).count();
        if m != 0 {
            runs.push((i, len, m));
        }
        i += len;
    }
    runs
}

/// Measures how much of `x` sits at a limit: the symmetric limit $\pm$`limit` when given, otherwise
/// flat runs at the record's extremes (see the [module docs](self)).
///
/// # Errors
/// [`Error::InvalidArgument`] for an empty signal, a `limit` that is not finite and $> 0$,
/// `opts.rel_tol` outside $[0, 1)$, `opts.min_run < 2` or `opts.flat_tol` not finite and $\ge 0$;
/// [`Error::NonFinite`] for NaN or infinite samples (repair them first with
/// [`crate::data::repair_abnormal`]).
///
/// # Example
/// ```
/// use ambid_core::data::{check_saturation, LimitSource, SaturationOptions};
/// let x = [0.0, 0.5, 2.0, 2.0, 2.0, 0.3, -1.0];
/// let rep = check_saturation(&x, None, &SaturationOptions::default()).unwrap();
/// assert_eq!((rep.count, rep.upper, rep.lower), (3, Some(2.0), None));
/// assert_eq!(rep.source, LimitSource::Detected);
/// assert_eq!(rep.runs, vec![(2, 3)]);
/// assert!(check_saturation(&x, Some(-1.0), &SaturationOptions::default()).is_err());
/// ```
pub fn check_saturation(
    x: &[f64],
    limit: Option<f64>,
    opts: &SaturationOptions,
) -> Result<SaturationReport> {
    if x.is_empty() {
        return Err(Error::invalid(
            "x",
            "the signal is empty; pass at least one sample",
        ));
    }
    check_finite("x", x)?;
    if !(opts.rel_tol.is_finite() && (0.0..1.0).contains(&opts.rel_tol)) {
        return Err(Error::invalid(
            "rel_tol",
            format!("must be in [0, 1) (1e-9 is usual), got {}", opts.rel_tol),
        ));
    }
    if opts.min_run < 2 {
        return Err(Error::invalid(
            "min_run",
            format!(
                "a flat run needs at least 2 samples (3 is usual), got {}",
                opts.min_run
            ),
        ));
    }
    if !(opts.flat_tol.is_finite() && opts.flat_tol >= 0.0) {
        return Err(Error::invalid(
            "flat_tol",
            format!(
                "must be finite and >= 0 (1e-12 is usual), got {}",
                opts.flat_tol
            ),
        ));
    }
    let n = x.len();
    let (marks, min_run, source) = match limit {
        Some(l) => {
            if !(l.is_finite() && l > 0.0) {
                return Err(Error::invalid(
                    "limit",
                    format!(
                        "the saturation limit must be finite and > 0 (the magnitude of the \
                         symmetric limit ±L), got {l}"
                    ),
                ));
            }
            let at = l * (1.0 - opts.rel_tol);
            let marks: Vec<Rail> = x
                .iter()
                .map(|&v| {
                    if v >= at {
                        1
                    } else if v <= -at {
                        -1
                    } else {
                        0
                    }
                })
                .collect();
            (marks, 1, LimitSource::Given)
        }
        None => {
            let max = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let min = x.iter().copied().fold(f64::INFINITY, f64::min);
            let tau = opts.flat_tol * max.abs().max(min.abs());
            let marks: Vec<Rail> = x
                .iter()
                .map(|&v| {
                    if (max - v) <= tau {
                        1
                    } else if (v - min) <= tau {
                        -1
                    } else {
                        0
                    }
                })
                .collect();
            (marks, opts.min_run, LimitSource::Detected)
        }
    };
    let runs: Vec<(usize, usize, Rail)> = rail_runs(&marks)
        .into_iter()
        .filter(|r| r.1 >= min_run)
        .collect();
    let count = runs.iter().map(|r| r.1).sum::<usize>();
    let (upper, lower) = match (source, limit) {
        (LimitSource::Given, Some(l)) => (Some(l), Some(-l)),
        _ => {
            let level = |rail: Rail| runs.iter().find(|r| r.2 == rail).map(|r| x[r.0]);
            (level(1), level(-1))
        }
    };
    Ok(SaturationReport {
        n_samples: n,
        count,
        fraction: count as f64 / n as f64,
        runs: runs.into_iter().map(|(s, l, _)| (s, l)).collect(),
        upper,
        lower,
        source,
        min_run,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percent_keeps_two_significant_digits() {
        assert_eq!(percent(0.5), "50.0");
        assert_eq!(percent(0.41), "41.0");
        assert_eq!(percent(0.0123), "1.2");
        assert_eq!(percent(1e-6), "0.00010");
        assert_eq!(percent(0.0), "0");
    }

    #[test]
    fn given_limit_counts_both_rails() {
        let x = [0.0, 1.0, 1.0, -1.0, -1.0 + 1e-12, 0.5, 1.0 - 1e-6];
        let rep = check_saturation(&x, Some(1.0), &SaturationOptions::default()).unwrap();
        assert_eq!(rep.count, 4);
        assert_eq!(rep.runs, vec![(1, 2), (3, 2)]);
        assert_eq!((rep.upper, rep.lower), (Some(1.0), Some(-1.0)));
        assert_eq!(rep.source, LimitSource::Given);
        assert_eq!(rep.longest_run(), Some((1, 2)));
        // A looser tolerance takes in the last sample too.
        let loose = SaturationOptions {
            rel_tol: 1e-5,
            ..SaturationOptions::default()
        };
        assert_eq!(check_saturation(&x, Some(1.0), &loose).unwrap().count, 5);
        let none = check_saturation(&x, Some(2.0), &SaturationOptions::default()).unwrap();
        assert_eq!((none.count, none.fraction), (0, 0.0));
        assert!(none.summary().starts_with("no sample reaches"));
    }

    #[test]
    fn detected_flat_runs() {
        // Two equal samples at a smooth peak do not count; three do.
        let x = [0.0, 0.9, 1.0, 1.0, 0.9, 0.0, -0.5, -0.5, -0.5, 0.0];
        let rep = check_saturation(&x, None, &SaturationOptions::default()).unwrap();
        assert_eq!(rep.runs, vec![(6, 3)]);
        assert_eq!((rep.upper, rep.lower), (None, Some(-0.5)));
        assert_eq!(rep.min_run, 3);
        assert!(rep.summary().contains("-0.5 (lower)"), "{}", rep.summary());
        let two = SaturationOptions {
            min_run: 2,
            ..SaturationOptions::default()
        };
        let rep = check_saturation(&x, None, &two).unwrap();
        assert_eq!(rep.runs, vec![(2, 2), (6, 3)]);
        assert_eq!(rep.upper, Some(1.0));
        // A constant record is one flat run at its "maximum".
        let rep = check_saturation(&[0.0; 5], None, &SaturationOptions::default()).unwrap();
        assert_eq!((rep.count, rep.upper, rep.lower), (5, Some(0.0), None));
        // Nothing flat.
        let rep = check_saturation(&[0.0, 1.0, 0.0], None, &SaturationOptions::default()).unwrap();
        assert!(
            rep.summary().starts_with("no flat run of 3"),
            "{}",
            rep.summary()
        );
    }

    #[test]
    fn error_paths() {
        let o = SaturationOptions::default();
        assert!(matches!(
            check_saturation(&[], Some(1.0), &o),
            Err(Error::InvalidArgument { .. })
        ));
        assert!(matches!(
            check_saturation(&[0.0, f64::NAN], None, &o),
            Err(Error::NonFinite { index: 1, .. })
        ));
        for l in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(check_saturation(&[0.0], Some(l), &o).is_err());
        }
        for bad in [
            SaturationOptions { rel_tol: 1.0, ..o },
            SaturationOptions {
                rel_tol: -1e-3,
                ..o
            },
            SaturationOptions {
                rel_tol: f64::NAN,
                ..o
            },
            SaturationOptions { min_run: 1, ..o },
            SaturationOptions {
                flat_tol: -1.0,
                ..o
            },
            SaturationOptions {
                flat_tol: f64::INFINITY,
                ..o
            },
        ] {
            assert!(
                check_saturation(&[0.0, 1.0], None, &bad).is_err(),
                "{bad:?}"
            );
        }
    }
}
