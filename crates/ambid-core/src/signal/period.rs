//! The period of a recorded excitation: the smallest lag at which every column repeats itself.
//!
//! A generator's reference signal `r` written to a file repeats *exactly* (or to the rounding of
//! its computation) when the design is periodic: a PRBS m-sequence, a multisine, a periodic
//! chirp. Period-synchronous averaging is then the right FRF estimator (no leakage, a variance
//! from the periods' scatter), and Welch's windowed segments are not: on periodic records they
//! bias lightly damped resonances (docs/frf.md). [`detect_period`] finds that period from the
//! record itself, so that a user who does not know it (or forgets to give it) gets the right
//! estimator.
//!
//! # The rule
//! The period of columns $x_j$ (each of length $\ge L$, the shortest length) is the smallest
//! $N \le L/2$ with
//! $$ |x_j(k + N) - x_j(k)| \le 10^{-9} \max_k |x_j(k)| \quad \text{for all } k < L - N \text{ and every } j, $$
//! counting only non-constant columns. $N \le L/2$ asks for two whole periods at least, the
//! fewest the period average can use. Measured signals never pass (their noise is far above
//! $10^{-9}$ of their peak), so on a measured input the answer is `None`, and the caller keeps
//! its non-periodic estimator.
//!
//! # Complexity
//! Testing every lag directly costs $O(L^2)$ on records such as a step, where each lag fails
//! only late. So every lag is screened first by the demeaned, unit-variance columns' squared
//! difference
//! $$ D(N) = \sum_j \sum_{k < L-N} (x_j(k+N) - x_j(k))^2
//!         = \sum_j \Big(\sum_{k<L-N} x_j(k)^2 + \sum_{k \ge N} x_j(k)^2 - 2 r_j(N)\Big), $$
//! with the linear autocorrelation $r_j$ from one zero-padded FFT pair and the two energies from
//! prefix sums: $O(L \log L)$ per column. Only lags with
//! $D(N) \le 10^{-6} E(N) + (L - N)\sum_j \tau_j^2/s_j$ go to the exact test ($E(N)$ the same
//! sums without the cross term, $\ge 1$ per column for $N \le L/2$; $\tau_j$ column $j$'s
//! tolerance and $s_j$ its demeaned sum of squares). A lag that passes the exact test has
//! $D(N) \le (L-N)\sum_j \tau_j^2/s_j$, and the FFT's rounding (about $10^{-15}$ of $E$) is
//! far inside $10^{-6} E$, so the screen never drops one. It passes lags at which the columns
//! repeat to about $10^{-3}$ of their RMS, and the exact test, stopping at its first mismatch,
//! settles those. A column that varies by no more than its tolerance passes every lag and is
//! left out of the screen.
//!
//! # Example
//! ```
//! use ambid_core::signal::detect_period;
//! let one: Vec<f64> = (0..7).map(|k| ((k * k) % 5) as f64).collect();
//! let r: Vec<f64> = one.iter().cycle().take(7 * 4 + 3).copied().collect();
//! assert_eq!(detect_period(&[&r]), Some(7));
//! // a record of fewer than two periods has none
//! assert_eq!(detect_period(&[&r[..12]]), None);
//! ```

use super::analysis::autocorrelation_fft;

/// Relative tolerance of the exact test (of each column's peak magnitude).
pub const PERIOD_TOLERANCE: f64 = 1e-9;

/// Relative squared difference below which a lag goes on to the exact test.
const SCREEN: f64 = 1e-6;

/// The smallest period $N \le L/2$ shared by every non-constant column (module docs), `None` if
/// there is none, if every column is constant, or if a column holds a non-finite sample.
///
/// # Example
/// ```
/// use ambid_core::signal::detect_period;
/// let a = [1.0, -1.0, 0.5, 1.0, -1.0, 0.5, 1.0, -1.0];
/// let b = [2.0, 2.0, 3.0, 3.0, 2.0, 2.0, 3.0, 3.0];
/// assert_eq!(detect_period(&[&a]), Some(3));
/// assert_eq!(detect_period(&[&b]), Some(4));
/// assert_eq!(detect_period(&[&a, &b]), None); // 12 > 8 / 2
/// assert_eq!(detect_period(&[&[5.0; 8][..], &a]), Some(3)); // constant columns do not count
/// ```
pub fn detect_period(columns: &[&[f64]]) -> Option<usize> {
    let n = columns.iter().map(|c| c.len()).min()?;
    if columns.iter().any(|c| c.iter().any(|v| !v.is_finite())) {
        return None;
    }
    let cols: Vec<&[f64]> = columns
        .iter()
        .map(|c| &c[..n])
        .filter(|c| c.iter().any(|v| *v != c[0]))
        .collect();
    if cols.is_empty() || n < 2 {
        return None;
    }
    let half = n / 2;
    let tols: Vec<f64> = cols
        .iter()
        .map(|c| PERIOD_TOLERANCE * c.iter().fold(0.0f64, |m, v| m.max(v.abs())))
        .collect();
    let mut d = vec![0.0; half + 1];
    let mut e = vec![0.0; half + 1];
    // the exact test's own allowance, in the screen's units: Σ_j tol_j² / Σ_k x_j[k]² per sample
    let mut allowance = 0.0;
    for (c, tol) in cols.iter().zip(&tols) {
        let mean = c.iter().sum::<f64>() / n as f64;
        let x: Vec<f64> = c.iter().map(|v| v - mean).collect();
        let ss: f64 = x.iter().map(|v| v * v).sum();
        let (lo, hi) = x
            .iter()
            .fold((f64::MAX, f64::MIN), |(l, h), v| (l.min(*v), h.max(*v)));
        if hi - lo <= *tol {
            // a column that varies by no more than the tolerance passes every lag
            continue;
        }
        allowance += tol * tol / ss;
        let x: Vec<f64> = x.iter().map(|v| v / ss.sqrt()).collect();
        let acf = autocorrelation_fft(&x, half, false).ok()?;
        // prefix sums of x²: s[j] = Σ_{k<j} x[k]²
        let mut s = Vec::with_capacity(n + 1);
        s.push(0.0);
        for v in &x {
            s.push(s.last().copied().unwrap_or(0.0) + v * v);
        }
        for p in 1..=half {
            let en = s[n - p] + (s[n] - s[p]);
            e[p] += en;
            d[p] += en - 2.0 * acf[p];
        }
    }
    (1..=half).find(|&p| {
        d[p] <= SCREEN * e[p] + (n - p) as f64 * allowance
            && cols.iter().zip(&tols).all(|(c, tol)| {
                c[..n - p]
                    .iter()
                    .zip(&c[p..])
                    .all(|(a, b)| (b - a).abs() <= *tol)
            })
    })
}

/// Samples of the prefix in which [`PeriodScan`] looks for the period ($2^{19}$).
pub const SCAN_PREFIX: usize = 1 << 19;

/// [`detect_period`] of one column read block by block, in memory for [`SCAN_PREFIX`]
/// samples whatever the record's length.
///
/// A record of at most [`SCAN_PREFIX`] samples gets exactly [`detect_period`]'s answer. On a
/// longer one the candidate is the period of the first [`SCAN_PREFIX`] samples, and it is kept
/// only if every later sample repeats the one a period before it to the same tolerance
/// ($10^{-9}$ of the whole column's peak). A record whose smallest period $N$ is at most
/// $\text{SCAN\_PREFIX}/2$ is found (its prefix holds two periods, and with exact repeats the
/// prefix's smallest period is then $N$ itself, by the Fine–Wilf theorem); a longer period is
/// not looked for (`None`).
///
/// # Example
/// ```
/// use ambid_core::signal::{detect_period, PeriodScan};
/// let one: Vec<f64> = (0..9).map(|k| (k as f64).sin()).collect();
/// let r: Vec<f64> = one.iter().cycle().take(100).copied().collect();
/// let mut scan = PeriodScan::new();
/// for block in r.chunks(16) {
///     scan.push(block);
/// }
/// assert_eq!(scan.finish(), Some(9));
/// assert_eq!(detect_period(&[&r]), Some(9));
/// ```
#[derive(Debug, Clone)]
pub struct PeriodScan {
    limit: usize,
    prefix: Vec<f64>,
    /// The prefix's period once the prefix is full, and the last period's samples.
    candidate: Option<(usize, Vec<f64>)>,
    n: usize,
    max_abs: f64,
    max_dev: f64,
    finite: bool,
}

impl Default for PeriodScan {
    fn default() -> Self {
        Self::new()
    }
}

impl PeriodScan {
    /// A scan with the prefix of [`SCAN_PREFIX`] samples.
    pub fn new() -> Self {
        Self::with_prefix(SCAN_PREFIX)
    }

    /// A scan with a prefix of `limit` samples (at least 2).
    pub fn with_prefix(limit: usize) -> Self {
        Self {
            limit: limit.max(2),
            prefix: Vec::new(),
            candidate: None,
            n: 0,
            max_abs: 0.0,
            max_dev: 0.0,
            finite: true,
        }
    }

    /// Whether the prefix is full, so that the candidate is fixed.
    fn decided(&self) -> bool {
        self.prefix.len() == self.limit
    }

    /// The scan of a whole column at once: the answer of pushing it block by block.
    pub fn of(x: &[f64]) -> Option<usize> {
        let mut s = Self::new();
        s.push(x);
        s.finish()
    }

    /// The next samples of the column.
    pub fn push(&mut self, block: &[f64]) {
        for &v in block {
            if !v.is_finite() {
                self.finite = false;
            }
            self.max_abs = self.max_abs.max(v.abs());
            let g = self.n;
            self.n += 1;
            if !self.decided() {
                self.prefix.push(v);
                if self.decided() {
                    self.candidate = detect_period(&[&self.prefix]).map(|p| {
                        // ring[j] = the latest sample with index ≡ j (mod p)
                        let mut ring = vec![0.0; p];
                        for (k, x) in self.prefix.iter().enumerate().skip(self.limit - p) {
                            ring[k % p] = *x;
                        }
                        (p, ring)
                    });
                }
                continue;
            }
            if let Some((p, ring)) = self.candidate.as_mut() {
                let slot = &mut ring[g % *p];
                self.max_dev = self.max_dev.max((v - *slot).abs());
                *slot = v;
            }
        }
    }

    /// The period (see the type's docs), `None` if there is none.
    pub fn finish(self) -> Option<usize> {
        if !self.finite {
            return None;
        }
        if !self.decided() {
            return detect_period(&[&self.prefix]);
        }
        let (p, _) = self.candidate?;
        (self.max_dev <= PERIOD_TOLERANCE * self.max_abs).then_some(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The definition, lag by lag: the oracle.
    fn naive(columns: &[&[f64]]) -> Option<usize> {
        let cols: Vec<(&[f64], f64)> = columns
            .iter()
            .filter(|c| c.iter().any(|v| *v != c[0]))
            .map(|c| (*c, 1e-9 * c.iter().fold(0.0f64, |m, v| m.max(v.abs()))))
            .collect();
        let n = columns.iter().map(|c| c.len()).min()?;
        if cols.is_empty() {
            return None;
        }
        (1..=n / 2).find(|&p| {
            cols.iter()
                .all(|(c, tol)| (0..n - p).all(|k| (c[k + p] - c[k]).abs() <= *tol))
        })
    }

    fn repeat(one: &[f64], len: usize) -> Vec<f64> {
        one.iter().cycle().take(len).copied().collect()
    }

    #[test]
    fn agrees_with_the_definition_on_random_records() {
        let mut rng = ChaCha8Rng::seed_from_u64(31);
        let mut found = 0;
        for case in 0..400 {
            let p = rng.random_range(1..60usize);
            let len = rng.random_range(2..400usize);
            let one: Vec<f64> = match case % 4 {
                // ±1 levels, as a PRBS: short runs of equal values
                0 => (0..p)
                    .map(|_| if rng.random::<bool>() { 1.0 } else { -1.0 })
                    .collect(),
                // a few levels, so that a divisor of p may be the period, with an offset
                1 => (0..p)
                    .map(|_| 100.0 + rng.random_range(0..2) as f64)
                    .collect(),
                // a large offset: variations of a few tolerances (1e-6 here)
                3 => (0..p)
                    .map(|_| 1e3 + 3e-6 * rng.random_range(-1.0..1.0))
                    .collect(),
                _ => (0..p).map(|_| rng.random_range(-1.0..1.0)).collect(),
            };
            let mut x = repeat(&one, len);
            if case % 5 == 0 && len > 3 {
                // one sample off by far more than the tolerance
                let k = rng.random_range(0..len);
                x[k] += 1e-6;
            }
            if case % 7 == 0 {
                // rounding-level jitter stays a period
                for v in x.iter_mut() {
                    *v += rng.random_range(-1e-13..1e-13);
                }
            }
            let y = repeat(&one.iter().rev().copied().collect::<Vec<_>>(), len + 5);
            let want = naive(&[&x]);
            assert_eq!(detect_period(&[&x]), want, "case {case}: p {p} len {len}");
            assert_eq!(
                detect_period(&[&x, &y]),
                naive(&[&x, &y]),
                "case {case} (two)"
            );
            found += want.is_some() as usize;
        }
        // the cases are not all of one kind
        assert!((100..380).contains(&found), "{found} of 400 periodic");
    }

    #[test]
    fn measured_steps_and_bad_samples_have_no_period() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        // a periodic design plus measurement noise of 1e-4: no period
        let one: Vec<f64> = (0..50).map(|_| rng.random_range(-1.0..1.0)).collect();
        let noisy: Vec<f64> = repeat(&one, 1000)
            .iter()
            .map(|v| v + 1e-4 * rng.random_range(-1.0..1.0))
            .collect();
        assert_eq!(detect_period(&[&noisy]), None);
        // the clean design: 50
        assert_eq!(detect_period(&[&repeat(&one, 1000)]), Some(50));
        // a step (every lag fails late: the case the screen is for), and a zero lead-in before
        // a periodic signal
        let step: Vec<f64> = (0..200_000).map(|k| (k >= 100_000) as u8 as f64).collect();
        assert_eq!(detect_period(&[&step]), None);
        let mut lead = vec![0.0; 5_000];
        lead.extend(repeat(&one, 100_000));
        assert_eq!(detect_period(&[&lead]), None);
        // NaN, constant, empty
        let mut bad = repeat(&one, 200);
        bad[3] = f64::NAN;
        assert_eq!(detect_period(&[&bad]), None);
        assert_eq!(detect_period(&[&[2.0; 10][..]]), None);
        assert_eq!(detect_period(&[]), None);
        assert_eq!(detect_period(&[&[][..]]), None);
    }

    #[test]
    fn a_prbs_m_sequence_with_samples_per_bit() {
        let one: Vec<f64> = crate::signal::prbs_period(10)
            .unwrap()
            .iter()
            .flat_map(|b| std::iter::repeat_n(*b as f64 * 0.3, 5))
            .collect();
        assert_eq!(one.len(), 5115);
        let r = repeat(&one, 20 * 5115);
        assert_eq!(detect_period(&[&r]), Some(5115));
        // a multisine computed sample by sample from t = k ts (not copied period by period)
        let ts = 1.0 / 1024.0;
        let ms: Vec<f64> = (0..8 * 1024)
            .map(|k| {
                let t = k as f64 * ts;
                (1..40)
                    .map(|l| {
                        (2.0 * std::f64::consts::PI * l as f64 * t + 0.1 * (l * l) as f64).cos()
                    })
                    .sum()
            })
            .collect();
        assert_eq!(detect_period(&[&ms]), Some(1024));
    }

    #[test]
    fn the_block_scan_agrees_with_the_whole_record() {
        let mut rng = ChaCha8Rng::seed_from_u64(77);
        for case in 0..300 {
            let limit = rng.random_range(2..120usize);
            let p = rng.random_range(1..50usize);
            let len = rng.random_range(1..500usize);
            let one: Vec<f64> = (0..p).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut x = repeat(&one, len);
            if case % 3 == 0 && len > 0 {
                let k = rng.random_range(0..len);
                x[k] += 1e-3;
            }
            let mut scan = PeriodScan::with_prefix(limit);
            let mut k = 0;
            while k < len {
                let b = rng.random_range(1..40usize).min(len - k);
                scan.push(&x[k..k + b]);
                k += b;
            }
            let got = scan.finish();
            let whole = detect_period(&[&x]);
            if len <= limit {
                assert_eq!(got, whole, "case {case}: the whole record is the prefix");
            } else if whole.is_some_and(|q| q <= limit / 2) {
                assert_eq!(got, whole, "case {case}: a period inside the prefix");
            } else {
                // a longer period is not looked for; anything found must be a period
                assert!(
                    got.is_none() || got == whole,
                    "case {case}: {got:?} vs {whole:?}"
                );
            }
        }
        let mut scan = PeriodScan::with_prefix(8);
        scan.push(&[1.0, 2.0, 1.0, 2.0, 1.0, 2.0, 1.0, 2.0, 1.0, f64::NAN]);
        assert_eq!(scan.finish(), None);
    }
}
