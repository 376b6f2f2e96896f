//! Abnormal samples: non-finite values, spikes and a stuck sensor; detection and repair.
//!
//! Three kinds of fault are looked for ([`find_abnormal`]), and handled as [`Repair`] says
//! ([`repair_abnormal`]):
//!
//! * **Non-finite** samples: NaN or $\pm\infty$ (lost packets, overflowing conversions).
//! * **Spikes** (electromagnetic interference, bit errors), by a robust moving rule ([`hampel`]).
//!   For sample $i$, let $W_i$ be the $2w$ samples around it, the centre itself excluded,
//!   $m_i = \operatorname{med} W_i$ and
//!   $s_i = 1.4826 \operatorname{med}_{j \in W_i} |x_j - m_i|$ (the factor $1.4826 = 1/\Phi^{-1}(3/4)$
//!   makes $s_i$ estimate $\sigma$ for Gaussian noise). Sample $i$ is a spike when
//!   $$ |x_i - m_i| > k \max(s_i,\; s_g,\; s_{\min}), \qquad
//!   s_g = 1.4826 \operatorname{med}_j |x_j - m_j| , $$
//!   and the same holds with $m_i, s_i$ taken over the $2w + 1$ samples *including* the centre.
//!   This is the Hampel filter with two changes:
//!   1. The test is made without the centre, so that a spike cannot pull the median or the MAD
//!      towards itself, and confirmed with it. The odd window with the centre gives the textbook
//!      filter's guarantee at a clean step (the centre's side holds a majority, so its deviation
//!      is at most the MAD); the even window without it can split evenly at a step and, next to a
//!      run of identical values, raise a false alarm.
//!   2. The local scale has a floor $s_g$, the typical size of the residual $x_j - m_j$ over the
//!      whole record: the MAD of 10 or 11 samples is often small by chance, and the textbook filter
//!      ($s_i$ only) flags about 0.5 % of the samples of Gaussian white noise at $w = 5, k = 5$
//!      (measured on $2 \cdot 10^6$ samples; this rule without the floor, 0.4 %); with the floor
//!      the rate is about $P(|z| > 5) \approx 6 \cdot 10^{-7}$, i.e. about one false alarm in
//!      $1.7 \cdot 10^6$ samples of white noise.
//!
//!   Where the signal itself changes fast, $s_i$ is large and governs, so steps and resonances are
//!   not taken for spikes, but small spikes on steep flanks go unnoticed.
//!   $s_{\min}$ ([`HampelOptions::min_scale`], default 0) is for quantised signals whose local
//!   spread is often exactly zero: set it to about one quantisation step.
//!
//!   The first and last $w$ samples are not judged: at the ends of the record only one side is
//!   known, and a level change there (a PRBS bit cut short by the end of the record) cannot be told
//!   from a spike. Samples in stuck runs are neither judged nor used as reference by
//!   [`find_abnormal`] (a window full of one repeated value has no spread, and its neighbours
//!   would look like spikes).
//!
//!   **Limitation**: a plateau of at most $w$ samples between longer stretches at another level *is*
//!   a spike to this rule. A raw PRBS with $N_b \le w$ samples per bit is therefore flagged at its
//!   isolated bits: keep $w < N_b$ (the seed paper's $N_b = 5$ needs $w \le 4$), or screen only the
//!   measured responses (the excitation $r$ is known exactly anyway).
//! * The **global** rule ([`global_outliers`], off by default): $|x_i - m| > k \cdot 1.4826
//!   \operatorname{MAD}$ with the median $m$ and MAD of the whole record. It suits unimodal signals
//!   only: for a two-level signal such as a PRBS the MAD is the noise level and every sample of the
//!   less frequent level is flagged.
//! * **Stuck sensor** ([`stuck_runs`]): runs of at least $L$ (default 20) exactly equal consecutive
//!   samples. Runs at the record's maximum or minimum are left to the saturation check
//!   ([`crate::data::check_saturation`]), except in a constant record (a dead channel), which is one
//!   stuck run.
//!
//! Repair ([`Repair::Interpolate`]) replaces every non-finite sample and spike by linear
//! interpolation between the nearest good samples on either side (the nearest good sample at the
//! ends of the record); a line is repaired exactly. Gaps longer than [`AbnormalOptions::max_gap`]
//! are refused: that much missing data should be cut out, not invented. Stuck runs are reported but
//! never repaired.
//!
//! # Complexity
//! [`hampel`]: $O(N w)$ time and $O(N)$ memory. The window is kept sorted while it slides (one
//! removal and one insertion per sample, $O(w)$ each), and each median and MAD is read from it in
//! $O(w)$ by merging the deviations below and above the median; about 0.3 s for $10^6$ samples at
//! $w = 5$ in the test profile (opt-level 1). A direct implementation that selects every median
//! afresh is the oracle it is tested against.
//! [`global_outliers`], [`stuck_runs`] and the repair: $O(N)$ (the global median by linear-time
//! selection).
//!
//! # Example
//! ```
//! use ambid_core::data::{repair_abnormal, AbnormalOptions};
//! let mut x: Vec<f64> = (0..200).map(|k| (0.05 * k as f64).sin()).collect();
//! x[50] = f64::NAN;
//! x[120] += 3.0; // a spike
//! let (fixed, report) = repair_abnormal(&x, &AbnormalOptions::default()).unwrap();
//! assert_eq!(report.nonfinite, vec![50]);
//! assert_eq!(report.spikes, vec![120]);
//! assert_eq!(report.repaired, 2);
//! assert!((fixed[120] - (0.05 * 120.0f64).sin()).abs() < 1e-2);
//! println!("{}", report.summary());
//! ```

use super::IoData;
use crate::error::{Error, Result};
use std::fmt;

/// $1/\Phi^{-1}(3/4)$: scales a median absolute deviation to a standard deviation for Gaussian data.
pub const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

/// Settings of the [`hampel`] spike detector.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HampelOptions {
    /// $w$: the reference window holds the $w$ samples either side of the centre (default 5).
    pub half_window: usize,
    /// $k$: threshold in robust standard deviations (default 5).
    pub k: f64,
    /// Floor the local scale with the record's typical residual $s_g$ (default `true`; `false` is
    /// the textbook filter, with many false alarms on noise, see the [module docs](self)).
    pub global_floor: bool,
    /// $s_{\min}$: absolute floor of the scale, in the unit of the signal (default 0; about one
    /// quantisation step for quantised signals).
    pub min_scale: f64,
}

impl Default for HampelOptions {
    fn default() -> Self {
        HampelOptions {
            half_window: 5,
            k: 5.0,
            global_floor: true,
            min_scale: 0.0,
        }
    }
}

impl HampelOptions {
    fn check(&self, n: usize) -> Result<()> {
        if self.half_window == 0 {
            return Err(Error::invalid(
                "half_window",
                "must be at least 1 (a window of 3 samples); 5 is usual",
            ));
        }
        if !(self.k.is_finite() && self.k > 0.0) {
            return Err(Error::invalid(
                "k",
                format!(
                    "the threshold must be finite and > 0 (5 is usual), got {}",
                    self.k
                ),
            ));
        }
        if !(self.min_scale.is_finite() && self.min_scale >= 0.0) {
            return Err(Error::invalid(
                "min_scale",
                format!("must be finite and >= 0, got {}", self.min_scale),
            ));
        }
        let span = self.half_window.saturating_mul(2).saturating_add(1);
        if span > n {
            return Err(Error::invalid(
                "half_window",
                format!(
                    "the window of 2·{} + 1 = {span} samples is longer than the record of {n} \
                     samples; use a half-window of at most {} or a longer record",
                    self.half_window,
                    n.saturating_sub(1) / 2
                ),
            ));
        }
        Ok(())
    }
}

/// What [`repair_abnormal`] does with the abnormal samples it finds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Repair {
    /// Replace non-finite samples and spikes by linear interpolation (default).
    #[default]
    Interpolate,
    /// Change nothing; only report, so that the caller can cut the bad parts out (samples cannot be
    /// removed from a uniformly sampled record without shifting time).
    ReportOnly,
    /// Return an error if anything abnormal is found.
    Fail,
}

/// Settings of [`find_abnormal`] and [`repair_abnormal`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AbnormalOptions {
    /// Spike detection by the moving rule (default on, [`HampelOptions::default`]); `None` skips it.
    pub hampel: Option<HampelOptions>,
    /// Spike detection by the global median/MAD rule with this $k$ (default `None`: off).
    pub global_k: Option<f64>,
    /// Shortest run of equal samples reported as a stuck sensor (default `Some(20)`); `None` skips
    /// the check.
    pub stuck_min_run: Option<usize>,
    /// What to do with what is found (default [`Repair::Interpolate`]).
    pub repair: Repair,
    /// Longest run of consecutive bad samples that [`Repair::Interpolate`] fills (default 10).
    pub max_gap: usize,
}

impl Default for AbnormalOptions {
    fn default() -> Self {
        AbnormalOptions {
            hampel: Some(HampelOptions::default()),
            global_k: None,
            stuck_min_run: Some(20),
            repair: Repair::Interpolate,
            max_gap: 10,
        }
    }
}

/// What [`find_abnormal`] found and [`repair_abnormal`] changed. Indices are sample numbers.
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct AbnormalReport {
    /// Number of samples screened.
    pub n_samples: usize,
    /// NaN or infinite samples, ascending.
    pub nonfinite: Vec<usize>,
    /// Spikes (moving and global rule together), ascending; disjoint from `nonfinite`.
    pub spikes: Vec<usize>,
    /// Stuck runs as `(start, length)`, ascending.
    pub stuck_runs: Vec<(usize, usize)>,
    /// Samples replaced by interpolation (0 unless [`Repair::Interpolate`]).
    pub repaired: usize,
}

fn list(ix: &[usize]) -> String {
    const SHOWN: usize = 5;
    // 1-based sample numbers, as a user counts the rows of a record
    let mut s: Vec<String> = ix.iter().take(SHOWN).map(|i| (i + 1).to_string()).collect();
    if ix.len() > SHOWN {
        s.push("…".into());
    }
    s.join(", ")
}

impl AbnormalReport {
    /// `true` when nothing abnormal was found.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{find_abnormal, AbnormalOptions};
    /// let x: Vec<f64> = (0..50).map(|k| (0.1 * k as f64).sin()).collect();
    /// assert!(find_abnormal(&x, &AbnormalOptions::default()).unwrap().is_clean());
    /// ```
    pub fn is_clean(&self) -> bool {
        self.nonfinite.is_empty() && self.spikes.is_empty() && self.stuck_runs.is_empty()
    }

    /// What was found and changed, in one line (the first samples of each kind are listed, as
    /// 1-based sample numbers: index `i` of the slice is sample `i + 1`).
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{repair_abnormal, AbnormalOptions};
    /// let (_, rep) = repair_abnormal(&[0.0, 1.0, f64::NAN, 3.0], &AbnormalOptions { hampel: None,
    ///     ..AbnormalOptions::default() }).unwrap();
    /// assert_eq!(rep.summary(), "4 samples: 1 non-finite (at sample 3); 1 sample repaired by linear interpolation");
    /// ```
    pub fn summary(&self) -> String {
        let plural =
            |n: usize, one: &str, many: &str| format!("{n} {}", if n == 1 { one } else { many });
        if self.is_clean() {
            return format!("{} samples: clean", self.n_samples);
        }
        let mut parts = Vec::new();
        if !self.nonfinite.is_empty() {
            parts.push(format!(
                "{} non-finite (at sample{} {})",
                self.nonfinite.len(),
                if self.nonfinite.len() == 1 { "" } else { "s" },
                list(&self.nonfinite)
            ));
        }
        if !self.spikes.is_empty() {
            parts.push(format!(
                "{} (at sample{} {})",
                plural(self.spikes.len(), "spike", "spikes"),
                if self.spikes.len() == 1 { "" } else { "s" },
                list(&self.spikes)
            ));
        }
        if !self.stuck_runs.is_empty() {
            let runs: Vec<String> = self
                .stuck_runs
                .iter()
                .take(3)
                .map(|(s, l)| format!("{l} samples from sample {}", s + 1))
                .collect();
            let more = if self.stuck_runs.len() > 3 {
                ", …"
            } else {
                ""
            };
            parts.push(format!(
                "{} ({}{more})",
                plural(self.stuck_runs.len(), "stuck run", "stuck runs"),
                runs.join(", ")
            ));
        }
        let mut s = format!("{} samples: {}", self.n_samples, parts.join(", "));
        if self.repaired > 0 {
            s += &format!(
                "; {} by linear interpolation",
                plural(self.repaired, "sample repaired", "samples repaired")
            );
        }
        if !self.stuck_runs.is_empty() {
            s += "; stuck runs are not repaired: check the sensor and cut them out of the record";
        }
        s
    }
}

impl fmt::Display for AbnormalReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.summary())
    }
}

fn check_nonempty(x: &[f64]) -> Result<()> {
    if x.is_empty() {
        return Err(Error::invalid(
            "x",
            "the signal is empty; pass at least one sample",
        ));
    }
    Ok(())
}

/// Median of `v` (mean of the two middle values for an even count), reordering `v`.
/// `v` must be non-empty and finite.
pub(crate) fn median_in_place(v: &mut [f64]) -> f64 {
    let n = v.len();
    let mid = n / 2;
    let (lower, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    let upper = *m;
    if n % 2 == 1 {
        upper
    } else {
        let below = lower.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * below + 0.5 * upper
    }
}

/// Spikes by the moving median/MAD rule (see the [module docs](self)); returns their indices,
/// ascending. The first and last $w$ samples are not judged; non-finite samples are neither flagged
/// nor used as reference, and a sample with fewer than $w + 1$ finite neighbours in its window is
/// not judged.
///
/// # Errors
/// [`Error::InvalidArgument`] for an empty signal, `half_window == 0`, a window of $2w+1$ samples
/// longer than the signal, or `k` or `min_scale` out of range.
///
/// # Example
/// ```
/// use ambid_core::data::{hampel, HampelOptions};
/// let mut x: Vec<f64> = (0..100).map(|k| (0.2 * k as f64).cos()).collect();
/// x[30] = 10.0;
/// x[31] = -8.0;
/// assert_eq!(hampel(&x, &HampelOptions::default()).unwrap(), vec![30, 31]);
/// let too_long = HampelOptions { half_window: 50, ..HampelOptions::default() };
/// assert!(hampel(&x, &too_long).is_err());
/// ```
pub fn hampel(x: &[f64], opts: &HampelOptions) -> Result<Vec<usize>> {
    hampel_masked(x, opts, &[])
}

/// [`hampel`] with the samples `ignore` (as `(start, length)` runs, ascending) neither judged nor
/// used as reference.
fn hampel_masked(x: &[f64], opts: &HampelOptions, ignore: &[(usize, usize)]) -> Result<Vec<usize>> {
    check_nonempty(x)?;
    opts.check(x.len())?;
    let n = x.len();
    let w = opts.half_window;
    let k = opts.k;
    let mut usable: Vec<bool> = x.iter().map(|v| v.is_finite()).collect();
    for &(s, l) in ignore {
        usable[s..s + l].fill(false);
    }
    // `r_ex[i]`: residual without the centre (for the floor); `cand[i]`: min(|r_ex|, |r_inc|) when
    // both local tests pass, else NaN. Both NaN where sample i is not judged.
    let mut r_ex = vec![f64::NAN; n];
    let mut cand = vec![f64::NAN; n];
    // The usable samples of the window [i - w, i + w], sorted; slid by one removal and one
    // insertion per step, O(w) each.
    let mut win: Vec<f64> = Vec::with_capacity(2 * w + 1);
    for j in 0..2 * w {
        if usable[j] {
            sorted_insert(&mut win, x[j]);
        }
    }
    for i in w..n - w {
        if i > w && usable[i - w - 1] {
            sorted_remove(&mut win, x[i - w - 1]);
        }
        if usable[i + w] {
            sorted_insert(&mut win, x[i + w]);
        }
        if !usable[i] || win.len() <= w + 1 {
            continue;
        }
        let xi = x[i];
        let own = win.partition_point(|v| *v < xi);
        let (m_ex, s_ex) = median_and_scale(&win, own);
        r_ex[i] = xi - m_ex;
        let re = (xi - m_ex).abs();
        if re > k * s_ex {
            // Confirm with the centre included (rarely needed, so computed only here).
            let (m_inc, s_inc) = median_and_scale(&win, usize::MAX);
            let ri = (xi - m_inc).abs();
            if ri > k * s_inc {
                cand[i] = re.min(ri);
            }
        }
    }
    let mut floor = opts.min_scale;
    if opts.global_floor {
        let mut abs: Vec<f64> = r_ex
            .iter()
            .filter(|r| r.is_finite())
            .map(|r| r.abs())
            .collect();
        if !abs.is_empty() {
            floor = floor.max(MAD_TO_SIGMA * median_in_place(&mut abs));
        }
    }
    Ok((0..n).filter(|&i| cand[i] > k * floor).collect())
}

/// Inserts finite `v` into the ascending `sorted`.
fn sorted_insert(sorted: &mut Vec<f64>, v: f64) {
    let at = sorted.partition_point(|u| *u < v);
    sorted.insert(at, v);
}

/// Removes one element equal to `v` from the ascending `sorted`, which holds it.
fn sorted_remove(sorted: &mut Vec<f64>, v: f64) {
    let at = sorted.partition_point(|u| *u < v);
    if at < sorted.len() {
        sorted.remove(at);
    }
}

/// Median $m$ and $1.4826 \cdot \operatorname{med} |v - m|$ of the ascending `sorted` with the element
/// at index `skip` left out (`usize::MAX`: none), in $O(\text{len})$ without reordering: the
/// deviations below and above the median are each monotone, so their order statistics come from
/// merging the two sides outwards from the middle.
fn median_and_scale(sorted: &[f64], skip: usize) -> (f64, f64) {
    let count = if skip < sorted.len() {
        sorted.len() - 1
    } else {
        sorted.len()
    };
    let at = |r: usize| sorted[if r < skip { r } else { r + 1 }];
    let h = count / 2;
    let m = if count % 2 == 1 {
        at(h)
    } else {
        0.5 * at(h - 1) + 0.5 * at(h)
    };
    // Ranks <= lo hold values <= m, ranks >= lo + 1 values >= m.
    let (mut lo, mut hi) = (Some((count - 1) / 2), (count - 1) / 2 + 1);
    let (mut prev, mut cur) = (0.0, 0.0);
    for _ in 0..=h {
        let left = lo.map(|r| m - at(r));
        let right = (hi < count).then(|| at(hi) - m);
        prev = cur;
        cur = match (left, right) {
            (Some(a), Some(b)) if a <= b => {
                lo = lo.and_then(|r| r.checked_sub(1));
                a
            }
            (_, Some(b)) => {
                hi += 1;
                b
            }
            (Some(a), None) => {
                lo = lo.and_then(|r| r.checked_sub(1));
                a
            }
            (None, None) => cur,
        };
    }
    let mad = if count % 2 == 1 {
        cur
    } else {
        0.5 * prev + 0.5 * cur
    };
    (m, MAD_TO_SIGMA * mad)
}

/// Spikes by the global rule $|x_i - m| > k \cdot 1.4826 \operatorname{MAD}$ over all finite
/// samples (see the [module docs](self) for when it is unsuitable); returns their indices,
/// ascending. Non-finite samples are ignored.
///
/// # Errors
/// [`Error::InvalidArgument`] for an empty signal, one without any finite sample, or `k` not finite
/// and $> 0$.
///
/// # Example
/// ```
/// use ambid_core::data::global_outliers;
/// let x = [0.1, -0.2, 0.0, 0.15, 9.0, -0.1, 0.05];
/// assert_eq!(global_outliers(&x, 5.0).unwrap(), vec![4]);
/// ```
pub fn global_outliers(x: &[f64], k: f64) -> Result<Vec<usize>> {
    check_nonempty(x)?;
    if !(k.is_finite() && k > 0.0) {
        return Err(Error::invalid(
            "global_k",
            format!("the threshold must be finite and > 0 (5 is usual), got {k}"),
        ));
    }
    let mut buf: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    if buf.is_empty() {
        return Err(Error::invalid(
            "x",
            "no sample is finite, so there is nothing to judge; check the channel",
        ));
    }
    let m = median_in_place(&mut buf);
    for v in buf.iter_mut() {
        *v = (*v - m).abs();
    }
    let limit = k * MAD_TO_SIGMA * median_in_place(&mut buf);
    Ok((0..x.len())
        .filter(|&i| x[i].is_finite() && (x[i] - m).abs() > limit)
        .collect())
}

/// Runs of at least `min_run` exactly equal consecutive samples, as `(start, length)`, ascending;
/// runs at the record's finite maximum or minimum are left out (saturation, see
/// [`crate::data::check_saturation`]) unless the record is constant. Non-finite samples end a run.
///
/// # Errors
/// [`Error::InvalidArgument`] for an empty signal or `min_run < 2`.
///
/// # Example
/// ```
/// use ambid_core::data::stuck_runs;
/// let mut x: Vec<f64> = (0..100).map(|k| (0.3 * k as f64).sin()).collect();
/// for v in &mut x[40..65] { *v = 0.123; }
/// assert_eq!(stuck_runs(&x, 20).unwrap(), vec![(40, 25)]);
/// ```
pub fn stuck_runs(x: &[f64], min_run: usize) -> Result<Vec<(usize, usize)>> {
    check_nonempty(x)?;
    if min_run < 2 {
        return Err(Error::invalid(
            "stuck_min_run",
            format!("a stuck run needs at least 2 equal samples (20 is usual), got {min_run}"),
        ));
    }
    let finite = x.iter().copied().filter(|v| v.is_finite());
    let max = finite.clone().fold(f64::NEG_INFINITY, f64::max);
    let min = finite.fold(f64::INFINITY, f64::min);
    let constant = max == min;
    let mut runs = Vec::new();
    let mut start = 0;
    while start < x.len() {
        let v = x[start];
        let len = x[start..].iter().take_while(|&&u| u == v).count().max(1);
        let at_rail = v == max || v == min;
        if v.is_finite() && len >= min_run && (constant || !at_rail) {
            runs.push((start, len));
        }
        start += len;
    }
    Ok(runs)
}

/// Looks for non-finite samples, spikes and stuck runs as `opts` says, without changing anything
/// (`opts.repair` is not used; `repaired` is 0).
///
/// # Errors
/// [`Error::InvalidArgument`] for an empty signal or invalid options (see [`hampel`],
/// [`global_outliers`], [`stuck_runs`]); the moving rule also needs at least one finite sample
/// more than twice the half-window.
///
/// # Example
/// ```
/// use ambid_core::data::{find_abnormal, AbnormalOptions};
/// let mut x = vec![0.0; 30];
/// for (k, v) in x.iter_mut().enumerate() { *v = (k as f64).sqrt(); }
/// x[3] = f64::INFINITY;
/// let rep = find_abnormal(&x, &AbnormalOptions::default()).unwrap();
/// assert_eq!(rep.nonfinite, vec![3]);
/// ```
pub fn find_abnormal(x: &[f64], opts: &AbnormalOptions) -> Result<AbnormalReport> {
    check_nonempty(x)?;
    let nonfinite: Vec<usize> = (0..x.len()).filter(|&i| !x[i].is_finite()).collect();
    let stuck = match opts.stuck_min_run {
        Some(l) => stuck_runs(x, l)?,
        None => Vec::new(),
    };
    let mut spikes = match &opts.hampel {
        Some(h) => hampel_masked(x, h, &stuck)?,
        None => Vec::new(),
    };
    if let Some(k) = opts.global_k {
        spikes.extend(global_outliers(x, k)?);
        spikes.sort_unstable();
        spikes.dedup();
    }
    Ok(AbnormalReport {
        n_samples: x.len(),
        nonfinite,
        spikes,
        stuck_runs: stuck,
        repaired: 0,
    })
}

/// Finds abnormal samples ([`find_abnormal`]) and handles them as `opts.repair` says; returns the
/// (possibly repaired) samples and the report.
///
/// # Errors
/// As [`find_abnormal`]; with [`Repair::Fail`], [`Error::InvalidArgument`] carrying the report's
/// summary when anything was found; with [`Repair::Interpolate`], [`Error::InvalidArgument`] when a
/// run of bad samples is longer than `opts.max_gap` or no sample is good.
///
/// # Example
/// ```
/// use ambid_core::data::{repair_abnormal, AbnormalOptions, Repair};
/// let x = [1.0, 2.0, f64::NAN, f64::NAN, 5.0, 6.0];
/// let opts = AbnormalOptions { hampel: None, ..AbnormalOptions::default() };
/// let (y, rep) = repair_abnormal(&x, &opts).unwrap();
/// assert_eq!(y, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
/// assert_eq!(rep.repaired, 2);
/// let fail = AbnormalOptions { repair: Repair::Fail, ..opts };
/// assert!(repair_abnormal(&x, &fail).is_err());
/// ```
pub fn repair_abnormal(x: &[f64], opts: &AbnormalOptions) -> Result<(Vec<f64>, AbnormalReport)> {
    let mut report = find_abnormal(x, opts)?;
    match opts.repair {
        Repair::ReportOnly => Ok((x.to_vec(), report)),
        Repair::Fail if report.is_clean() => Ok((x.to_vec(), report)),
        Repair::Fail => Err(Error::invalid(
            "x",
            format!(
                "abnormal samples found ({}); repair them by interpolation or cut them out of the \
                 record",
                report.summary()
            ),
        )),
        Repair::Interpolate => {
            let mut bad: Vec<usize> = report
                .nonfinite
                .iter()
                .chain(&report.spikes)
                .copied()
                .collect();
            bad.sort_unstable();
            bad.dedup();
            let y = interpolate_gaps(x, &bad, opts.max_gap)?;
            report.repaired = bad.len();
            Ok((y, report))
        }
    }
}

/// Replaces the samples at the (ascending, unique) indices `bad` by linear interpolation between
/// the nearest good samples, or by the nearest good sample at the record's ends.
fn interpolate_gaps(x: &[f64], bad: &[usize], max_gap: usize) -> Result<Vec<f64>> {
    let n = x.len();
    let mut y = x.to_vec();
    if bad.is_empty() {
        return Ok(y);
    }
    if bad.len() == n {
        return Err(Error::invalid(
            "x",
            "every sample is abnormal, so there is nothing to interpolate from; check the channel",
        ));
    }
    let mut g = 0;
    while g < bad.len() {
        let a = bad[g];
        let mut e = g;
        while e + 1 < bad.len() && bad[e + 1] == bad[e] + 1 {
            e += 1;
        }
        let b = bad[e] + 1; // gap is a..b
        if b - a > max_gap {
            return Err(Error::invalid(
                "max_gap",
                format!(
                    "samples {a}..{b} ({} in a row) are abnormal, more than max_gap = {max_gap} can \
                     be interpolated; cut that part out (IoData::slice) or raise max_gap",
                    b - a
                ),
            ));
        }
        match (a.checked_sub(1), (b < n).then_some(b)) {
            (Some(l), Some(r)) => {
                let (xl, xr) = (x[l], x[r]);
                let span = (r - l) as f64;
                for (j, v) in y[a..b].iter_mut().enumerate() {
                    let t = (j + 1) as f64 / span;
                    *v = xl + (xr - xl) * t;
                }
            }
            (Some(l), None) => y[a..b].fill(x[l]),
            (None, Some(r)) => y[a..b].fill(x[r]),
            // A gap without a good sample on either side would be the whole record, excluded
            // above.
            (None, None) => {}
        }
        g = e + 1;
    }
    Ok(y)
}

/// Applies [`repair_abnormal`] to the channels `names` of `data` (all channels when `names` is
/// empty); returns the new record and one report per screened channel.
///
/// Do not screen a raw excitation channel whose bits are at most $w$ samples long (see the
/// [module docs](self)).
///
/// # Errors
/// [`Error::InvalidArgument`] for an unknown channel name, and as [`repair_abnormal`] (the message
/// names the channel).
///
/// # Example
/// ```
/// use ambid_core::data::{repair_data, AbnormalOptions, IoData};
/// let y: Vec<f64> = (0..40).map(|k| if k == 7 { f64::NAN } else { k as f64 }).collect();
/// let data = IoData::new(vec![("y".into(), y)], 1e-3, None).unwrap();
/// let (fixed, reports) = repair_data(&data, &["y"], &AbnormalOptions::default()).unwrap();
/// assert_eq!(fixed.channel("y").unwrap()[7], 7.0);
/// assert_eq!(reports[0].0, "y");
/// ```
pub fn repair_data(
    data: &IoData,
    names: &[&str],
    opts: &AbnormalOptions,
) -> Result<(IoData, Vec<(String, AbnormalReport)>)> {
    let names: Vec<String> = if names.is_empty() {
        data.names().into_iter().map(String::from).collect()
    } else {
        names.iter().map(|s| s.to_string()).collect()
    };
    let mut out = data.clone();
    let mut reports = Vec::with_capacity(names.len());
    for name in names {
        let x = data.channel(&name)?;
        let (y, rep) = repair_abnormal(x, opts).map_err(|e| match e {
            Error::InvalidArgument { name: arg, reason } => Error::InvalidArgument {
                name: arg,
                reason: format!("channel `{name}`: {reason}"),
            },
            other => other,
        })?;
        out = out.with_channel(name.clone(), y)?;
        reports.push((name, rep));
    }
    Ok((out, reports))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The direct form of the rule (select the median and MAD of each window afresh), as oracle.
    fn hampel_naive(x: &[f64], opts: &HampelOptions, ignore: &[(usize, usize)]) -> Vec<usize> {
        let n = x.len();
        let w = opts.half_window;
        let mut usable: Vec<bool> = x.iter().map(|v| v.is_finite()).collect();
        for &(s, l) in ignore {
            usable[s..s + l].fill(false);
        }
        let stats = |xi: f64, mut v: Vec<f64>| {
            let m = median_in_place(&mut v);
            let mut d: Vec<f64> = v.iter().map(|u| (u - m).abs()).collect();
            (xi - m, MAD_TO_SIGMA * median_in_place(&mut d))
        };
        let mut judged = Vec::new();
        for i in w..n - w {
            let nb: Vec<f64> = (i - w..=i + w)
                .filter(|&j| j != i && usable[j])
                .map(|j| x[j])
                .collect();
            if !usable[i] || nb.len() <= w {
                continue;
            }
            let (re, se) = stats(x[i], nb.clone());
            let mut all = nb;
            all.push(x[i]);
            let (ri, si) = stats(x[i], all);
            judged.push((i, re, se, ri, si));
        }
        let mut floor = opts.min_scale;
        if opts.global_floor && !judged.is_empty() {
            let mut a: Vec<f64> = judged.iter().map(|j| j.1.abs()).collect();
            floor = floor.max(MAD_TO_SIGMA * median_in_place(&mut a));
        }
        judged
            .into_iter()
            .filter(|&(_, re, se, ri, si)| {
                re.abs() > opts.k * se.max(floor) && ri.abs() > opts.k * si.max(floor)
            })
            .map(|j| j.0)
            .collect()
    }

    #[test]
    fn sliding_hampel_matches_naive_oracle() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for case in 0..60 {
            let n = rng.random_range(3..400);
            let w = rng.random_range(1..=((n - 1) / 2).min(8));
            // Coarse values make ties and zero MADs common; some NaN, spikes and masked runs.
            let levels = rng.random_range(2..12) as f64;
            let mut x: Vec<f64> = (0..n)
                .map(|k| ((k as f64 * 0.05).sin() * levels + rng.random_range(-1.0..1.0)).round())
                .collect();
            for _ in 0..n / 20 {
                let i = rng.random_range(0..n);
                x[i] = if rng.random_range(0..2) == 0 {
                    f64::NAN
                } else {
                    x[i] + 40.0
                };
            }
            let ignore = if case % 3 == 0 && n > 30 {
                vec![(3, 5), (n - 12, 4)]
            } else {
                vec![]
            };
            let opts = HampelOptions {
                half_window: w,
                k: [2.0, 3.0, 5.0][case % 3],
                global_floor: case % 2 == 0,
                min_scale: if case % 5 == 0 { 0.5 } else { 0.0 },
            };
            assert_eq!(
                hampel_masked(&x, &opts, &ignore).unwrap(),
                hampel_naive(&x, &opts, &ignore),
                "case {case}: n = {n}, w = {w}"
            );
        }
    }

    #[test]
    fn median_and_scale_of_sorted() {
        let v = [1.0, 2.0, 4.0, 7.0, 11.0];
        // Without 4: [1, 2, 7, 11], median 4.5, deviations 3.5, 2.5, 2.5, 6.5 -> MAD 3.
        let (m, s) = median_and_scale(&v, 2);
        assert_eq!(m, 4.5);
        assert!((s - 3.0 * MAD_TO_SIGMA).abs() < 1e-15);
        // All: median 4, deviations 3, 2, 0, 3, 7 -> MAD 3.
        let (m, s) = median_and_scale(&v, usize::MAX);
        assert_eq!(m, 4.0);
        assert!((s - 3.0 * MAD_TO_SIGMA).abs() < 1e-15);
        assert_eq!(median_and_scale(&[5.0], usize::MAX), (5.0, 0.0));
    }

    #[test]
    fn median_even_and_odd() {
        assert_eq!(median_in_place(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median_in_place(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median_in_place(&mut [7.0]), 7.0);
    }

    #[test]
    fn hampel_constant_with_spike_and_edges() {
        let mut x = vec![1.0; 50];
        x[0] = 9.0; // the first and last w samples are not judged
        x[5] = 5.0;
        x[25] = 1.5;
        x[44] = -3.0;
        x[49] = -9.0;
        assert_eq!(
            hampel(&x, &HampelOptions::default()).unwrap(),
            vec![5, 25, 44]
        );
        // min_scale hides a small step on a quantised signal.
        let opts = HampelOptions {
            min_scale: 0.2,
            ..HampelOptions::default()
        };
        assert_eq!(hampel(&x, &opts).unwrap(), vec![5, 44]);
    }

    #[test]
    fn hampel_ignores_nan_and_skips_unjudgeable() {
        let mut x: Vec<f64> = (0..40).map(|k| k as f64 * 0.1).collect();
        x[10] = f64::NAN;
        x[20] = 50.0;
        assert_eq!(hampel(&x, &HampelOptions::default()).unwrap(), vec![20]);
        // Mostly NaN: nothing can be judged, nothing is flagged.
        let mut y = vec![f64::NAN; 11];
        y[5] = 1.0;
        assert!(hampel(&y, &HampelOptions::default()).unwrap().is_empty());
    }

    #[test]
    fn hampel_step_is_not_a_spike() {
        let x: Vec<f64> = (0..100).map(|k| if k < 50 { 0.0 } else { 1.0 }).collect();
        assert!(hampel(&x, &HampelOptions::default()).unwrap().is_empty());
    }

    #[test]
    fn hampel_option_errors() {
        let x = vec![0.0; 20];
        for bad in [
            HampelOptions {
                half_window: 0,
                ..HampelOptions::default()
            },
            HampelOptions {
                k: 0.0,
                ..HampelOptions::default()
            },
            HampelOptions {
                k: f64::NAN,
                ..HampelOptions::default()
            },
            HampelOptions {
                min_scale: -1.0,
                ..HampelOptions::default()
            },
            HampelOptions {
                half_window: 10,
                ..HampelOptions::default()
            },
            HampelOptions {
                half_window: usize::MAX,
                ..HampelOptions::default()
            },
        ] {
            assert!(hampel(&x, &bad).is_err(), "{bad:?}");
        }
        let e = hampel(
            &x,
            &HampelOptions {
                half_window: 10,
                ..HampelOptions::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("longer than the record") && e.contains("at most 9"),
            "{e}"
        );
        assert!(hampel(&[], &HampelOptions::default()).is_err());
    }

    #[test]
    fn global_rule() {
        assert!(global_outliers(&[], 5.0).is_err());
        assert!(global_outliers(&[1.0], -5.0).is_err());
        assert!(global_outliers(&[f64::NAN, f64::INFINITY], 5.0).is_err());
        let x = [0.0, 1.0, -1.0, 0.5, f64::NAN, 100.0, -0.5];
        assert_eq!(global_outliers(&x, 5.0).unwrap(), vec![5]);
    }

    #[test]
    fn stuck_runs_rules() {
        assert!(stuck_runs(&[], 20).is_err());
        assert!(stuck_runs(&[1.0], 1).is_err());
        // Runs at max/min are saturation, not stuck.
        let mut x: Vec<f64> = (0..200).map(|k| (0.1 * k as f64).sin()).collect();
        x[10..40].fill(2.0);
        x[100..125].fill(-2.0);
        x[150..170].fill(0.3);
        x[180..198].fill(0.4); // too short
        assert_eq!(stuck_runs(&x, 20).unwrap(), vec![(150, 20)]);
        // NaN breaks runs and a constant record is one stuck run.
        let mut c = vec![0.7; 30];
        assert_eq!(stuck_runs(&c, 20).unwrap(), vec![(0, 30)]);
        c[15] = f64::NAN;
        assert!(stuck_runs(&c, 20).unwrap().is_empty());
        assert!(stuck_runs(&[f64::NAN; 30], 2).unwrap().is_empty());
    }

    #[test]
    fn interpolation_edges_and_gaps() {
        let opts = AbnormalOptions {
            hampel: None,
            max_gap: 2,
            ..AbnormalOptions::default()
        };
        let x = [f64::NAN, 1.0, 2.0, f64::NAN, 4.0, f64::INFINITY];
        let (y, rep) = repair_abnormal(&x, &opts).unwrap();
        assert_eq!(y, vec![1.0, 1.0, 2.0, 3.0, 4.0, 4.0]);
        assert_eq!(rep.nonfinite, vec![0, 3, 5]);
        assert_eq!(rep.repaired, 3);
        let x = [0.0, f64::NAN, f64::NAN, f64::NAN, 4.0];
        let e = repair_abnormal(&x, &opts).unwrap_err().to_string();
        assert!(e.contains("1..4") && e.contains("max_gap = 2"), "{e}");
        let e = repair_abnormal(&[f64::NAN; 2], &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("every sample"), "{e}");
    }

    #[test]
    fn report_only_and_fail() {
        let x = [0.0, 1.0, f64::NAN, 3.0];
        let base = AbnormalOptions {
            hampel: None,
            ..AbnormalOptions::default()
        };
        let (y, rep) = repair_abnormal(
            &x,
            &AbnormalOptions {
                repair: Repair::ReportOnly,
                ..base
            },
        )
        .unwrap();
        assert!(y[2].is_nan());
        assert_eq!((rep.nonfinite.clone(), rep.repaired), (vec![2], 0));
        let fail = AbnormalOptions {
            repair: Repair::Fail,
            ..base
        };
        let e = repair_abnormal(&x, &fail).unwrap_err().to_string();
        assert!(e.contains("1 non-finite (at sample 3)"), "{e}");
        let (y, rep) = repair_abnormal(&[0.0, 1.0, 2.0], &fail).unwrap();
        assert_eq!(y, vec![0.0, 1.0, 2.0]);
        assert_eq!(rep.summary(), "3 samples: clean");
        assert!(repair_abnormal(&[], &base).is_err());
    }

    #[test]
    fn summary_lists_everything() {
        let rep = AbnormalReport {
            n_samples: 1000,
            nonfinite: vec![1, 2, 3, 4, 5, 6],
            spikes: vec![9],
            stuck_runs: vec![(100, 30)],
            repaired: 7,
        };
        let s = rep.summary();
        assert!(
            s.contains("6 non-finite (at samples 2, 3, 4, 5, 6, …)"),
            "{s}"
        );
        assert!(s.contains("1 spike (at sample 10)"), "{s}");
        assert!(
            s.contains("1 stuck run (30 samples from sample 101)"),
            "{s}"
        );
        assert!(s.contains("7 samples repaired"), "{s}");
        assert!(s.contains("not repaired"), "{s}");
        assert_eq!(rep.to_string(), s);
    }

    #[test]
    fn repair_data_channels() {
        let y: Vec<f64> = (0..30).map(|k| k as f64).collect();
        let mut u = y.clone();
        u[4] = f64::NAN;
        let d = IoData::new(vec![("u".into(), u), ("y".into(), y)], 1.0, None).unwrap();
        let (out, reps) = repair_data(&d, &[], &AbnormalOptions::default()).unwrap();
        assert_eq!(out.channel("u").unwrap()[4], 4.0);
        assert_eq!(reps.len(), 2);
        assert!(reps[1].1.is_clean());
        assert!(repair_data(&d, &["nope"], &AbnormalOptions::default()).is_err());
        let fail = AbnormalOptions {
            repair: Repair::Fail,
            ..AbnormalOptions::default()
        };
        let e = repair_data(&d, &["u"], &fail).unwrap_err().to_string();
        assert!(e.contains("channel `u`"), "{e}");
    }
}
