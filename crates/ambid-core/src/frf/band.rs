//! Frequency bands derived from the data: where the excitation has power, where the quality
//! averages mean something, and where a measured sensitivity is reliable enough for the
//! ISO 14839-3 peak search.
//!
//! A nonparametric estimate is only as good as the excitation behind it: at a line where the
//! excitation $r$ has no power, $\hat G = \hat S_{ry}/\hat S_{ru}$ is a ratio of two noise terms
//! and its magnitude can be anything. ambid therefore never uses a fixed band (0–Nyquist, or the
//! nominal rig's 10–1000 Hz) unless the user gives one; it derives the bands from the
//! excitation's power per line $P_k$ (periodic data: $|\bar R_k|^2$ of the period-averaged DFT;
//! Welch: the PSD $\hat S_{rr}(f_k)$; open-loop data without $r$: the same for the input $u$):
//!
//! * **Excited band** $[f_\text{lo}, f_\text{hi}]$: the lowest and the highest line $k \ge k_0$
//!   with $P_k \ge P_\max\,10^{-\Delta_e/10}$, $\Delta_e$ = [`BandRule::excited_db`] = 10 dB,
//!   $P_\max = \max_{k\ge k_0} P_k$. A PRBS of $N_b$ samples per bit has the spectrum
//!   $\propto |\sin(\pi f N_b/f_s) / (N_b \sin(\pi f/f_s))|^2$ (≈ $\operatorname{sinc}^2$) with
//!   nulls at multiples of $f_s/N_b$; for $N_b = 5$ it is 10 dB down at $0.7465\,f_s/N_b$ and its
//!   highest side lobe peaks at −12.0 dB (−13.3 dB for large $N_b$), so 10 dB keeps the main lobe
//!   and never a side lobe (where the estimate of the seed experiment failed at 4 and 8 kHz). A
//!   flat multisine or linear chirp falls by far more than 10 dB at its band edge, so the band
//!   is its design band; a multisine's non-excited lines inside the band are skipped by the
//!   estimators anyway. $k_0$ excludes DC and the lines a window's leakage of the mean spoils:
//!   $k_0 = 1$ for period-synchronous data (no leakage), $k_0 = 2$ for Welch with a Hann
//!   window (its main lobe is ±2 bins wide, so bin 1 holds the DC leakage).
//!
//!   **A spectrum that slopes by design.** A logarithmic sweep spends the same time per octave,
//!   so its power per line falls as $1/f$ (3 dB per octave) over its whole design band: ambid's
//!   own identification chirp (1–2000 Hz) is 10 dB below its strongest line by about 40 Hz, and
//!   the 10 dB rule alone ended its band at 58.65 Hz. The models were then fitted on 4–59 Hz, and
//!   the robust gain margin of the workflow's `uncertainty` step, decided by the model's loop
//!   far above that band, was 7–94 where the true loop goes unstable at 2.9–5.2 (random rigs
//!   501–600 of the linear twin: the true loop was unstable at 90 % of the reported margin on 68
//!   of 100; docs/frf.md, "A spectrum that slopes by design"). So each edge of the 10 dB band is
//!   then carried outward, line by line, while a line's power is within
//!   [`BandRule::slope_db_per_octave`] = 6 dB of the strongest line in the octave on the band's
//!   side of it ($[f_k/2, f_k)$ above the band, $(f_k, 2f_k]$ below it), up to
//!   [`EDGE_GAP`] = 2 failing lines in a row (the non-excited lines of an odd or random-odd
//!   multisine grid); the edge is the last line that passed. A fall steeper than 6 dB per octave
//!   (20 dB per decade) is an edge: a PRBS's main lobe falls by 8.2 dB over the octave below its
//!   10 dB point (by more beyond it), so its band is the 10 dB rule's; a flat design band's
//!   edge falls by tens of dB within a line or two. Where an edge was carried, the quality band
//!   reaches it too (the power there falls by design, not by the excitation's roll-off).
//! * **Quality band**: the part of the excited band where the excitation is within
//!   $\Delta_q$ = [`BandRule::quality_db`] = 3 dB of its maximum (its half-power bandwidth;
//!   $0.450\,f_s/N_b$ for a PRBS with $N_b = 5$, the whole design band of a flat multisine). There the
//!   coherence and the variance averages measure the experiment, not the excitation's roll-off.
//! * **ISO |S| search** ([`reliable_lines`]): the lines of a measured $\hat S$ inside the
//!   excited band whose 95 % interval half-width $1.96\,\sigma_k/\sqrt2$ is at most
//!   [`BandRule::iso_rel_halfwidth`] = 10 % of $|\hat S_k|$. The ISO zone limits 3 / 4 / 5 are
//!   25–33 % apart, so a line known to ±10 % can decide between neighbouring zones, and the
//!   largest of many such lines is not a noise peak. The peak is then reported with its own
//!   interval (see [`crate::validate::iso`]). When no line qualifies, all lines of the excited
//!   band are searched and the caller must say so.
//! * **FRF-fit band** ([`fit_band`]): for a parametric fit to a measured FRF (a file, without
//!   the excitation), from the FRF's own variances: the span of the runs of lines whose 95 %
//!   half-width is within [`FIT_REL_HALFWIDTH`] = 20 % of the value.
//!
//! Evidence (docs/frf.md): on the nominal twin and on random rigs 1–20 (seed experiment) the
//! excited band is 3.9 Hz – 2.98 kHz (quality band to 1.80 kHz) and contains every rig's true $\max|S|$ frequency, the
//! measured peak agrees with the truth within its interval and the zone is right; on the F-16
//! GVT multisine (2–15 Hz at 400 Hz) the band is its design band and the resonances are the
//! 3.5–9.2 Hz modes; on Silverbox's Schroeder multisine the band ends at its ~200 Hz design edge.
//!
//! # Example
//! ```
//! use ambid_core::frf::band::{excitation_bands, BandRule};
//! // a PRBS spectrum, N_b = 5 samples per bit at 20 kHz, lines every 10 Hz up to Nyquist
//! let f: Vec<f64> = (0..=1000).map(|k| 10.0 * k as f64).collect();
//! let p: Vec<f64> = f.iter().map(|&f| {
//!     let x = std::f64::consts::PI * f / 20_000.0;
//!     if x == 0.0 { 1.0 } else { ((5.0 * x).sin() / (5.0 * x.sin())).powi(2) }
//! }).collect();
//! let b = excitation_bands(&f, &p, 1, &BandRule::default()).unwrap();
//! assert_eq!(b.excited.0, 10.0);
//! assert_eq!(b.excited.1, 2980.0); // 10 dB down at 0.7465 f_s/N_b = 2986 Hz
//! assert_eq!(b.quality.1, 1800.0); // 3 dB down at 0.4501 f_s/N_b = 1800.4 Hz
//! // the side lobes (−12 dB, beyond the null at f_s/N_b = 4 kHz) are not excited lines
//! assert!(b.excited.1 < 4000.0);
//! ```

use crate::error::{Error, Result};
use crate::lti::Frd;
use crate::validate::iso::{sensitivity_zone, IsoVerdict, IsoZones};

/// The thresholds of the band rule (module docs); the defaults are the documented rule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BandRule {
    /// A line is excited when its excitation power is within this many dB of the largest
    /// (default 10 dB: a PRBS's main lobe without its side lobes, a multisine's design band).
    pub excited_db: f64,
    /// The quality band: lines within this many dB of the largest (default 3 dB, the
    /// excitation's half-power bandwidth).
    pub quality_db: f64,
    /// ISO search: largest 95 % half-width of $|\hat S_k|$ relative to $|\hat S_k|$ (default 0.1).
    pub iso_rel_halfwidth: f64,
    /// A line beyond the excited band's edge is still excited when its power is within this
    /// many dB of the strongest line in the octave on the band's side of it (default 6 dB: a
    /// logarithmic sweep's 3 dB per octave is a design slope, a PRBS main lobe's 8.2 dB per
    /// octave at its 10 dB point is an edge; module docs, "A spectrum that slopes by design").
    pub slope_db_per_octave: f64,
}

/// Failing lines in a row an excited band's edge is carried across (module docs, "A spectrum
/// that slopes by design": the non-excited lines of an odd or random-odd multisine grid).
pub const EDGE_GAP: usize = 2;

impl Default for BandRule {
    fn default() -> Self {
        Self {
            excited_db: 10.0,
            quality_db: 3.0,
            iso_rel_halfwidth: 0.1,
            slope_db_per_octave: 6.0,
        }
    }
}

impl BandRule {
    fn check(&self) -> Result<()> {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        if !(ok(self.excited_db)
            && ok(self.quality_db)
            && self.quality_db <= self.excited_db
            && ok(self.iso_rel_halfwidth)
            && ok(self.slope_db_per_octave))
        {
            return Err(Error::invalid(
                "rule",
                format!(
                    "need 0 < quality_db ≤ excited_db, iso_rel_halfwidth > 0 and slope_db_per_octave > 0, got {} / {} / {} / {}",
                    self.quality_db, self.excited_db, self.iso_rel_halfwidth, self.slope_db_per_octave
                ),
            ));
        }
        Ok(())
    }
}

/// The bands [`excitation_bands`] derives from the excitation.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ExcitationBands {
    /// Lowest and highest excited line \[Hz\].
    pub excited: (f64, f64),
    /// Lowest and highest line within [`BandRule::quality_db`] of the largest \[Hz\].
    pub quality: (f64, f64),
    /// Number of excited lines (power within [`BandRule::excited_db`], and the carried ones).
    pub excited_lines: usize,
    /// Of those, the lines beyond the 10 dB band carried over a spectrum that slopes by design
    /// (module docs; 0 for a PRBS or a flat multisine).
    pub carried_lines: usize,
    /// The frequency of the strongest line \[Hz\].
    pub f_max_power_hz: f64,
    /// The thresholds used \[dB below the largest line\] (excited, quality).
    pub thresholds_db: (f64, f64),
}

impl ExcitationBands {
    /// One sentence saying which bands were derived and why (for reports and CLI output).
    pub fn describe(&self) -> String {
        format!(
            "derived from the excitation: {} excited lines within {} dB of the strongest{} in {:.4}–{:.4} Hz; quality band (within {} dB{}) {:.4}–{:.4} Hz",
            self.excited_lines,
            self.thresholds_db.0,
            self.carried(),
            self.excited.0,
            self.excited.1,
            self.thresholds_db.1,
            if self.carried_lines > 0 { ", to the carried edge" } else { "" },
            self.quality.0,
            self.quality.1
        )
    }

    /// `" or, N of them, on its design slope"` when N lines were carried, else empty (module
    /// docs, "A spectrum that slopes by design").
    pub fn carried(&self) -> String {
        if self.carried_lines > 0 {
            format!(" or, {} of them, on its design slope", self.carried_lines)
        } else {
            String::new()
        }
    }
}

/// The excited and the quality band of an excitation with power `power[k]` on the increasing
/// lines `f_hz[k]`, lines below index `first_line` left out (DC, leakage; module docs).
///
/// # Errors
/// [`Error::DimensionMismatch`] for different lengths; [`Error::InvalidArgument`] for a malformed
/// rule, negative or non-finite powers, or no power on any line from `first_line` on (the
/// message says to check the excitation channel).
pub fn excitation_bands(
    f_hz: &[f64],
    power: &[f64],
    first_line: usize,
    rule: &BandRule,
) -> Result<ExcitationBands> {
    rule.check()?;
    if f_hz.len() != power.len() {
        return Err(Error::DimensionMismatch {
            context: "excitation_bands: frequencies and powers",
            expected: f_hz.len().to_string(),
            got: power.len().to_string(),
        });
    }
    if let Some(k) = power.iter().position(|p| !(p.is_finite() && *p >= 0.0)) {
        return Err(Error::invalid(
            "power",
            format!(
                "line {k} has power {}; powers must be finite and ≥ 0",
                power[k]
            ),
        ));
    }
    let idx = first_line..f_hz.len();
    let (kmax, pmax) = idx
        .clone()
        .map(|k| (k, power[k]))
        .fold((usize::MAX, 0.0f64), |a, b| if b.1 > a.1 { b } else { a });
    if kmax == usize::MAX || pmax <= 0.0 {
        return Err(Error::invalid(
            "excitation",
            "the excitation has no power on any line above DC: check the excitation column (r, or u for open-loop data) and that the excitation was on",
        ));
    }
    let span = |db: f64| -> (usize, usize, usize) {
        let thr = pmax * 10f64.powf(-db / 10.0);
        let lines: Vec<usize> = idx.clone().filter(|&k| power[k] >= thr).collect();
        // non-empty: the strongest line passes
        let lo = lines.first().copied().unwrap_or(kmax);
        let hi = lines.last().copied().unwrap_or(kmax);
        (lo, hi, lines.len())
    };
    let (e0, e1, n) = span(rule.excited_db);
    let (q0, q1, _) = span(rule.quality_db);
    // each edge carried outward over a spectrum that slopes by design (module docs)
    let slope = 10f64.powf(-rule.slope_db_per_octave / 10.0);
    let (up, down) = (
        carried_edge(f_hz, power, first_line, e1, true, slope),
        carried_edge(f_hz, power, first_line, e0, false, slope),
    );
    let added = up.1 + down.1;
    let (e0, e1) = (down.0, up.0);
    let q1 = if up.1 > 0 { e1 } else { q1 };
    let q0 = if down.1 > 0 { e0 } else { q0 };
    Ok(ExcitationBands {
        excited: (f_hz[e0], f_hz[e1]),
        quality: (f_hz[q0], f_hz[q1]),
        excited_lines: n + added,
        carried_lines: added,
        f_max_power_hz: f_hz[kmax],
        thresholds_db: (rule.excited_db, rule.quality_db),
    })
}

/// The excited band's edge `start` carried outward (`up`: to higher lines) over the lines from
/// `first_line` on: the last line of the run whose power is at least `slope` times the strongest
/// line in the octave on the band's side of it (and the last line that passed), at most
/// [`EDGE_GAP`] failing lines in a row
/// (module docs, "A spectrum that slopes by design"), and the number of lines that passed. The
/// octave's maximum is a sliding-window maximum (a monotone deque): linear in the lines.
fn carried_edge(
    f: &[f64],
    p: &[f64],
    first_line: usize,
    start: usize,
    up: bool,
    slope: f64,
) -> (usize, usize) {
    use std::collections::VecDeque;
    // the lines from `first_line` on, outward from the band; `start` (a line of the band, so at
    // or above `first_line`) at `pos`
    let (order, pos): (Vec<usize>, usize) = if up {
        ((first_line..f.len()).collect(), start - first_line)
    } else {
        ((first_line..f.len()).rev().collect(), f.len() - 1 - start)
    };
    // the lines of the octave on the band's side of line k
    let within = |j: usize, k: usize| {
        if up {
            f[j] >= 0.5 * f[k]
        } else {
            f[j] <= 2.0 * f[k]
        }
    };
    let push = |dq: &mut VecDeque<usize>, j: usize| {
        while dq.back().is_some_and(|&b| p[b] <= p[j]) {
            dq.pop_back();
        }
        dq.push_back(j);
    };
    let mut dq = VecDeque::new();
    for &j in &order[..=pos] {
        push(&mut dq, j);
    }
    let (mut last, mut passed, mut misses) = (start, 0, 0);
    for &k in &order[pos + 1..] {
        while dq.front().is_some_and(|&j| !within(j, k)) {
            dq.pop_front();
        }
        // the octave's strongest line, and the last line that passed (a failing line must not
        // become the reference of the next: lines sparser than an octave)
        let strongest = dq.front().map_or(p[last], |&j| p[j].max(p[last]));
        if p[k] > 0.0 && p[k] >= slope * strongest {
            passed += 1;
            last = k;
            misses = 0;
        } else {
            misses += 1;
            if misses > EDGE_GAP {
                break;
            }
        }
        push(&mut dq, k);
    }
    (last, passed)
}

/// The lines of a measured sensitivity `s` inside `band` on which the ISO 14839-3 peak search
/// is done: those whose 95 % half-width $1.96\sqrt{\sigma_k^2/2}$ is at most
/// `rule.iso_rel_halfwidth` $\cdot|\hat S_k|$ (module docs). Returns the indices into `s` and
/// whether the reliability filter was applied (`false`: `s` has no variance, or no line in the
/// band passed it, and every line of the band is returned).
///
/// # Errors
/// [`Error::InvalidArgument`] for a malformed rule or no line of `s` inside `band`.
pub fn reliable_lines(s: &Frd, band: (f64, f64), rule: &BandRule) -> Result<(Vec<usize>, bool)> {
    s.require_siso("band::reliable_lines")?;
    rule.check()?;
    let f = s.f_hz();
    let inside: Vec<usize> = (0..f.len())
        .filter(|&k| f[k] >= band.0 && f[k] <= band.1)
        .collect();
    if inside.is_empty() {
        return Err(Error::invalid(
            "band",
            format!(
                "the sensitivity has no line in {}–{} Hz; widen the band",
                band.0, band.1
            ),
        ));
    }
    let Some(var) = s.variance() else {
        return Ok((inside, false));
    };
    let z = 1.959_963_984_540_054;
    let good: Vec<usize> = inside
        .iter()
        .copied()
        .filter(|&k| z * (var[k] / 2.0).sqrt() <= rule.iso_rel_halfwidth * s.values()[k].norm())
        .collect();
    if good.is_empty() {
        Ok((inside, false))
    } else {
        Ok((good, true))
    }
}

/// The ISO 14839-3 verdict of a measured sensitivity searched by the band rule, and how.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct IsoSearch {
    /// The verdict over the searched lines (peak, its 95 % interval, zone and zone range).
    pub verdict: IsoVerdict,
    /// The band searched \[Hz\].
    pub band: (f64, f64),
    /// Lines searched.
    pub lines: usize,
    /// Whether the reliability filter was applied (`false`: every line of the band was searched
    /// because `s` has no variance or no line passed; say so to the user).
    pub reliable: bool,
}

impl IsoSearch {
    /// One sentence: peak, interval, where, zone, and which lines were searched.
    pub fn describe(&self) -> String {
        let v = &self.verdict;
        let ci = v.interval.map_or(String::new(), |(lo, hi)| {
            format!(" (95 % interval {lo:.3}–{hi:.3})")
        });
        let range = if v.zone_range.0 != v.zone_range.1 {
            format!(
                ", uncertain: zones {:?}–{:?}",
                v.zone_range.0, v.zone_range.1
            )
        } else {
            String::new()
        };
        format!(
            "max|S| {:.3}{ci} at {:.1} Hz → zone {:?}{range}; searched {} lines in {:.1}–{:.1} Hz{}",
            v.peak,
            v.f_peak_hz,
            v.zone,
            self.lines,
            self.band.0,
            self.band.1,
            if self.reliable {
                " whose 95 % interval is within ±10 % of |S|".to_string()
            } else {
                " (no variance, or no line known to ±10 %: every line of the band searched)".to_string()
            }
        )
    }
}

/// The ISO 14839-3 zone of a measured sensitivity `s` over its [`reliable_lines`] inside `band`.
///
/// # Errors
/// As [`reliable_lines`] and [`sensitivity_zone`].
pub fn iso_search(
    s: &Frd,
    band: (f64, f64),
    rule: &BandRule,
    zones: &IsoZones,
) -> Result<IsoSearch> {
    s.require_siso("band::iso_search")?;
    let (idx, reliable) = reliable_lines(s, band, rule)?;
    let sub = select_lines(s, &idx)?;
    Ok(IsoSearch {
        verdict: sensitivity_zone(&sub, zones)?,
        band,
        lines: idx.len(),
        reliable,
    })
}

/// The default reliability threshold of [`fit_band`]: a line is measured reliably when the 95 %
/// half-width of the FRF there is at most 20 % of its modulus (±1.6 dB, ±12°). Twice the ISO
/// search's ±10 % ([`BandRule::iso_rel_halfwidth`]), which must decide a zone from single lines:
/// a fit combines hundreds of lines, each weighted by its inverse variance, so a line still helps
/// at ±20 %; at ±10 % the band of a noisy rig ended below its bending mode (evidence in
/// [`fit_band`]).
pub const FIT_REL_HALFWIDTH: f64 = 0.2;

/// Consecutive reliable lines that open and close a [`fit_band`] (a lone line that passes by
/// chance among noisy ones does not stretch the band).
pub const FIT_EDGE_RUN: usize = 3;

/// The band over which a parametric model is fitted to a measured FRF, derived from the FRF
/// itself by [`fit_band`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FitBand {
    /// Lowest and highest line of the band \[Hz\].
    pub band: (f64, f64),
    /// Lines of the FRF inside the band.
    pub lines: usize,
    /// Of those, the lines that pass the reliability test.
    pub reliable_lines: usize,
    /// Lines of the whole FRF.
    pub total_lines: usize,
    /// The threshold used (largest 95 % half-width relative to the modulus).
    pub max_rel_halfwidth: f64,
    /// Whether the band was derived from the variances (`false`: the FRF has no variance, or no
    /// run of reliable lines, and the band is every line; say so).
    pub from_variance: bool,
}

impl FitBand {
    /// One sentence saying which band was derived and from what (for CLI output and reports).
    pub fn describe(&self) -> String {
        if self.from_variance {
            format!(
                "band {:.1}–{:.1} Hz derived from the FRF's standard deviations: from the first to the last run of {FIT_EDGE_RUN} lines whose 95 % interval is within ±{:.0} % of the value ({} of {} lines in the band reliable, {} lines in the file); give --band to override",
                self.band.0,
                self.band.1,
                100.0 * self.max_rel_halfwidth,
                self.reliable_lines,
                self.lines,
                self.total_lines
            )
        } else {
            format!(
                "band {:.1}–{:.1} Hz: every line of the file ({} lines), because the FRF has no standard deviations or no run of {FIT_EDGE_RUN} lines known to ±{:.0} %; give --band to restrict it",
                self.band.0,
                self.band.1,
                self.total_lines,
                100.0 * self.max_rel_halfwidth
            )
        }
    }
}

/// The fit band of a measured FRF `q`: where the data measure it reliably.
///
/// A line $k$ is **reliable** when the 95 % half-width of $\hat q_k$ is at most
/// `max_rel_halfwidth` ([`FIT_REL_HALFWIDTH`] = 20 %) of its modulus,
/// $$ 1.96\,\sqrt{\sigma_k^2/2} \le h\,|\hat q_k| , $$
/// with $\sigma_k^2$ the variance of the complex estimate (the file's `<q>_std` squared). The
/// band runs from the first line that opens a run of [`FIT_EDGE_RUN`] = 3 consecutive reliable
/// lines to the last line that closes one; unreliable lines inside it stay (an antiresonance,
/// where $|\hat q|$ is small, is part of the dynamics, and the inverse-variance weights of the fit
/// already discount it), a lone line that passes by chance among noisy ones does not stretch it.
///
/// Why: a PRBS (or any excitation) leaves lines where $\hat q$ is a ratio of noise terms (above
/// its main lobe, near its nulls); a fit or an error figure over them measures the noise, not the
/// model. Evidence (docs/estimation.md; `cargo test -p ambid --test all freqfit_band_rigs::`): on 20
/// random rigs with two noise seeds each (seed experiment) the derived plant band is 3.9 Hz to
/// 0.9–1.7 kHz, and the models fitted over it are as close to the exact plant over 10–1000 Hz as
/// those fitted over the nominal 10–1000 Hz; with ±10 % instead, one rig's band ended at 790 Hz,
/// below its bending mode, and its chosen model was 3× worse.
///
/// When `q` has no variance (exact data) or no run of reliable lines exists, the band is every
/// line and [`FitBand::from_variance`] is `false`.
///
/// # Errors
/// [`Error::InvalidArgument`] for a threshold that is not positive and finite or an FRF without
/// lines.
///
/// # Example
/// ```
/// use ambid_core::frf::band::{fit_band, FIT_REL_HALFWIDTH};
/// use ambid_core::lti::Frd;
/// use faer::c64;
/// // |q| = 1; σ grows with frequency: reliable below 50 Hz, except one antiresonance line
/// let f: Vec<f64> = (1..=100).map(|k| k as f64).collect();
/// let q = vec![c64::new(1.0, 0.0); 100];
/// let var: Vec<f64> = f.iter().map(|&f| {
///     let s = if f == 20.0 { 0.2 } else if f <= 50.0 { 0.01 } else { 0.5 };
///     s * s
/// }).collect();
/// let frd = Frd::new(f, q, Some(var), Some(1e-3)).unwrap();
/// let b = fit_band(&frd, FIT_REL_HALFWIDTH).unwrap();
/// assert_eq!(b.band, (1.0, 50.0));
/// assert_eq!((b.lines, b.reliable_lines), (50, 49));
/// ```
pub fn fit_band(q: &Frd, max_rel_halfwidth: f64) -> Result<FitBand> {
    q.require_siso("band::fit_band")?;
    if !(max_rel_halfwidth.is_finite() && max_rel_halfwidth > 0.0) {
        return Err(Error::invalid(
            "max_rel_halfwidth",
            format!("must be positive and finite, got {max_rel_halfwidth}"),
        ));
    }
    let f = q.f_hz();
    let n = f.len();
    if n == 0 {
        return Err(Error::invalid("frf", "the FRF has no lines"));
    }
    let all = |from_variance| FitBand {
        band: (f[0], f[n - 1]),
        lines: n,
        reliable_lines: 0,
        total_lines: n,
        max_rel_halfwidth,
        from_variance,
    };
    let Some(var) = q.variance() else {
        return Ok(all(false));
    };
    let z = 1.959_963_984_540_054;
    let ok: Vec<bool> = (0..n)
        .map(|k| {
            let m = q.values()[k].norm();
            m.is_finite()
                && var[k].is_finite()
                && z * (var[k] / 2.0).sqrt() <= max_rel_halfwidth * m
        })
        .collect();
    let run = FIT_EDGE_RUN.min(n);
    let starts: Vec<usize> = (0..=n - run)
        .filter(|&k| ok[k..k + run].iter().all(|b| *b))
        .collect();
    let (Some(&lo), Some(&hi)) = (starts.first(), starts.last()) else {
        return Ok(all(false));
    };
    let hi = hi + run - 1;
    Ok(FitBand {
        band: (f[lo], f[hi]),
        lines: hi - lo + 1,
        reliable_lines: ok[lo..=hi].iter().filter(|b| **b).count(),
        total_lines: n,
        max_rel_halfwidth,
        from_variance: true,
    })
}

/// `s` restricted to the lines `idx` (increasing), with their variances.
///
/// # Errors
/// As [`Frd::new`] (e.g. no lines).
pub fn select_lines(s: &Frd, idx: &[usize]) -> Result<Frd> {
    s.require_siso("band::select_lines")?;
    if idx.is_empty() {
        return Err(Error::invalid("lines", "no line selected"));
    }
    Frd::new(
        idx.iter().map(|&k| s.f_hz()[k]).collect(),
        idx.iter().map(|&k| s.values()[k]).collect(),
        s.variance().map(|v| idx.iter().map(|&k| v[k]).collect()),
        s.ts(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::c64;

    /// Lines every 0.5 Hz to 249.5 Hz: power `level(f)` on the odd lines of 1–100 Hz (an odd
    /// multisine grid), `floor` elsewhere.
    fn odd_grid(level: impl Fn(f64) -> f64, floor: f64) -> (Vec<f64>, Vec<f64>) {
        let f: Vec<f64> = (0..500).map(|k| 0.5 * k as f64).collect();
        let p = f
            .iter()
            .enumerate()
            .map(|(k, &f)| {
                if (1.0..=100.0).contains(&f) && k % 2 == 1 {
                    level(f)
                } else {
                    floor
                }
            })
            .collect();
        (f, p)
    }

    #[test]
    fn a_multisine_band_edge_gives_its_design_band() {
        // 1–100 Hz flat, odd lines only, −60 dB elsewhere (noise floor)
        let (f, p) = odd_grid(|_| 1.0, 1e-6);
        let b = excitation_bands(&f, &p, 1, &BandRule::default()).unwrap();
        assert_eq!(b.excited, (1.5, 99.5));
        assert_eq!(b.quality, (1.5, 99.5));
        assert_eq!(b.excited_lines, 99);
        assert!(b.describe().contains("derived from the excitation"));
    }

    /// $|X_k|^2$ of one period of `x` on the lines $k f_s / N$, $k = 0 \dots N/2$.
    fn period_power(x: &[f64], fs: f64) -> Result<(Vec<f64>, Vec<f64>)> {
        let n = x.len();
        let fft = realfft::RealFftPlanner::<f64>::new().plan_fft_forward(n);
        let (mut inp, mut out) = (x.to_vec(), fft.make_output_vec());
        fft.process(&mut inp, &mut out)
            .map_err(|e| Error::numerical("real FFT", e.to_string()))?;
        let f = (0..out.len()).map(|k| k as f64 * fs / n as f64).collect();
        Ok((f, out.iter().map(|v| v.norm_sqr()).collect()))
    }

    /// One period of the workflow's identification chirp (`ambid::experiment::ExcitationPlan`:
    /// 1–2000 Hz in 0.25575 s at 20 kHz).
    fn chirp_power(sweep: crate::signal::Sweep) -> Result<(Vec<f64>, Vec<f64>)> {
        let spec = crate::signal::ChirpSpec {
            f0_hz: 1.0,
            f1_hz: 2000.0,
            duration_s: 0.25575,
            amplitude: 1.0,
            sweep,
            periods: 1,
        };
        period_power(&spec.generate(5e-5)?.values, 20_000.0)
    }

    #[test]
    fn a_logarithmic_sweep_gives_its_design_band() -> Result<()> {
        let (f, p) = chirp_power(crate::signal::Sweep::Logarithmic)?;
        let b = excitation_bands(&f, &p, 1, &BandRule::default())?;
        // the first line (3.91 Hz) to the sweep's end at 2000 Hz, within its edge's ripple
        assert_eq!(b.excited.0, f[1]);
        assert!(
            b.excited.1 > 1900.0 && b.excited.1 < 2030.0,
            "{:?}",
            b.excited
        );
        assert_eq!(b.quality, b.excited);
        // the 10 dB rule alone (no line is carried) ends the band below 100 Hz
        let strict = BandRule {
            slope_db_per_octave: 1e-9,
            ..BandRule::default()
        };
        let b10 = excitation_bands(&f, &p, 1, &strict)?;
        assert!(b10.excited.1 < 100.0, "{:?}", b10.excited);
        assert!(b.excited_lines > 480 && b10.excited_lines < 30);
        assert_eq!(b.excited_lines - b.carried_lines, b10.excited_lines);
        assert!(b.describe().contains("design slope"), "{}", b.describe());
        assert!(!b10.describe().contains("design slope"));
        // a linear sweep is flat: its design band by the 10 dB rule, nothing carried
        let (f, p) = chirp_power(crate::signal::Sweep::Linear)?;
        let lin = excitation_bands(&f, &p, 1, &BandRule::default())?;
        let lin10 = excitation_bands(&f, &p, 1, &strict)?;
        assert!(
            lin.excited.1 > 1950.0 && lin.excited.1 < 2030.0,
            "{:?}",
            lin.excited
        );
        assert_eq!(
            (lin.excited, lin.excited_lines),
            (lin10.excited, lin10.excited_lines)
        );
        Ok(())
    }

    #[test]
    fn a_sloped_odd_multisine_is_carried_and_a_steep_roll_off_is_an_edge() -> Result<()> {
        // odd lines of 1–100 Hz with power ∝ 1/f (pink), −80 dB elsewhere
        let (f, pink) = odd_grid(|f| 1.0 / f, 1e-8);
        let b = excitation_bands(&f, &pink, 1, &BandRule::default())?;
        assert_eq!(b.excited, (1.5, 99.5));
        assert_eq!(b.quality, (1.5, 99.5));
        assert_eq!(b.excited_lines, 99);
        // the same lines rising with f (a spectrum ∝ f): the lower edge is carried down
        let blue: Vec<f64> = pink
            .iter()
            .zip(&f)
            .map(|(p, f)| if *p > 1e-6 { f * f * p } else { *p })
            .collect();
        assert_eq!(
            excitation_bands(&f, &blue, 1, &BandRule::default())?.excited,
            (1.5, 99.5)
        );
        // flat to 20 Hz, then 12 dB per octave (a second-order roll-off): the 10 dB point
        let steep: Vec<f64> = f
            .iter()
            .map(|&f| if f <= 20.0 { 1.0 } else { (20.0 / f).powi(4) })
            .collect();
        let b = excitation_bands(&f, &steep, 1, &BandRule::default())?;
        let ten_db = 20.0 * 10f64.powf(0.25); // (20/f)^4 = 0.1
        assert!(
            (b.excited.1 - ten_db).abs() <= 0.5,
            "{:?} against {ten_db}",
            b.excited
        );
        // 4 dB per octave is a design slope: carried to the end of the lines
        let gentle: Vec<f64> = f
            .iter()
            .map(|&f| {
                if f <= 20.0 {
                    1.0
                } else {
                    (20.0 / f).powf(4.0 / 3.0103)
                }
            })
            .collect();
        let b = excitation_bands(&f, &gentle, 1, &BandRule::default())?;
        assert_eq!(b.excited.1, f[f.len() - 1]);
        // a malformed slope is an error
        let bad = BandRule {
            slope_db_per_octave: 0.0,
            ..BandRule::default()
        };
        assert!(excitation_bands(&f, &gentle, 1, &bad).is_err());
        Ok(())
    }

    #[test]
    fn dc_and_leakage_lines_are_left_out_and_errors_are_clear() {
        let f = [0.0, 1.0, 2.0, 3.0, 4.0];
        let p = [100.0, 50.0, 1.0, 1.0, 0.01];
        let b = excitation_bands(&f, &p, 2, &BandRule::default()).unwrap();
        assert_eq!(b.excited, (2.0, 3.0));
        let b = excitation_bands(&f, &p, 1, &BandRule::default()).unwrap();
        assert_eq!(b.excited, (1.0, 1.0));
        let e = excitation_bands(&f, &[1.0, 0.0, 0.0, 0.0, 0.0], 1, &BandRule::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("no power"), "{e}");
        assert!(excitation_bands(&f, &p[..3], 1, &BandRule::default()).is_err());
        assert!(
            excitation_bands(&f, &[1.0, f64::NAN, 1.0, 1.0, 1.0], 1, &BandRule::default()).is_err()
        );
        let bad = BandRule {
            quality_db: 20.0,
            ..BandRule::default()
        };
        assert!(excitation_bands(&f, &p, 1, &bad).is_err());
    }

    #[test]
    fn the_iso_search_drops_noisy_lines() {
        // a true peak of 3.5 at line 1 (σ small) and a noise line of 8 with σ = 4 at line 3
        let s = Frd::new(
            vec![10.0, 20.0, 30.0, 40.0],
            vec![
                c64::new(2.0, 0.0),
                c64::new(3.5, 0.0),
                c64::new(1.0, 0.0),
                c64::new(8.0, 0.0),
            ],
            Some(vec![1e-4, 1e-3, 1e-4, 16.0]),
            None,
        )
        .unwrap();
        let (idx, filtered) = reliable_lines(&s, (0.0, 100.0), &BandRule::default()).unwrap();
        assert!(filtered);
        assert_eq!(idx, vec![0, 1, 2]);
        let sub = select_lines(&s, &idx).unwrap();
        assert_eq!(sub.f_hz(), &[10.0, 20.0, 30.0]);
        // the zone: 3.5 at 20 Hz (B), not the noise line's 8 (D)
        let v = iso_search(&s, (0.0, 100.0), &BandRule::default(), &IsoZones::default()).unwrap();
        assert_eq!(v.verdict.zone, crate::validate::iso::Zone::B);
        assert_eq!(
            (v.verdict.peak, v.verdict.f_peak_hz, v.lines),
            (3.5, 20.0, 3)
        );
        assert!(v.describe().contains("zone B"), "{}", v.describe());
        // outside the band nothing; without variances everything in the band
        assert!(reliable_lines(&s, (50.0, 60.0), &BandRule::default()).is_err());
        let s2 = Frd::new(s.f_hz().to_vec(), s.values().to_vec(), None, None).unwrap();
        let (idx, filtered) = reliable_lines(&s2, (15.0, 45.0), &BandRule::default()).unwrap();
        assert!(!filtered);
        assert_eq!(idx, vec![1, 2, 3]);
    }

    #[test]
    fn the_fit_band_is_the_span_of_reliable_runs() {
        // |q| = 2 on 20 lines; σ_k such that the 95 % half-width is 2 % (reliable) or 40 %
        let f: Vec<f64> = (1..=20).map(f64::from).collect();
        let q = vec![c64::new(0.0, 2.0); 20];
        let sigma = |h: f64| (h * 2.0 / 1.959_963_984_540_054) * 2f64.sqrt();
        // noisy 1–2, reliable 3–9, two noisy lines 10–11 (an antiresonance), reliable 12–15,
        // noisy 16–20 except a lone reliable line at 18 (by chance)
        let var: Vec<f64> = f
            .iter()
            .map(|&f| {
                let ok = (3.0..=9.0).contains(&f) || (12.0..=15.0).contains(&f) || f == 18.0;
                sigma(if ok { 0.02 } else { 0.4 }).powi(2)
            })
            .collect();
        let frd = Frd::new(f.clone(), q.clone(), Some(var), Some(1e-3)).unwrap();
        let b = fit_band(&frd, FIT_REL_HALFWIDTH).unwrap();
        assert_eq!(b.band, (3.0, 15.0));
        assert_eq!((b.lines, b.reliable_lines, b.total_lines), (13, 11, 20));
        assert!(b.from_variance);
        assert!(
            b.describe().contains("band 3.0–15.0 Hz derived"),
            "{}",
            b.describe()
        );
        // a looser threshold takes every line
        let b = fit_band(&frd, 0.5).unwrap();
        assert_eq!(b.band, (1.0, 20.0));
        // no variance, or no run of 3 reliable lines: every line, and it says so
        let exact = Frd::new(f.clone(), q.clone(), None, Some(1e-3)).unwrap();
        let b = fit_band(&exact, FIT_REL_HALFWIDTH).unwrap();
        assert_eq!((b.band, b.from_variance), ((1.0, 20.0), false));
        assert!(b.describe().contains("every line"), "{}", b.describe());
        let noisy = Frd::new(f, q, Some(vec![sigma(0.4).powi(2); 20]), Some(1e-3)).unwrap();
        assert!(!fit_band(&noisy, FIT_REL_HALFWIDTH).unwrap().from_variance);
        // a malformed threshold is an error
        assert!(fit_band(&noisy, 0.0).is_err());
        assert!(fit_band(&noisy, f64::NAN).is_err());
    }
}
