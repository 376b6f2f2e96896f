//! The stepped-sine (point-by-point) experiment on the twin, its comparison with the twin's truth,
//! and its measurement time next to the seed paper's PRBS experiment.
//!
//! For each point of a [`SteppedSinePlan`] the twin is run from rest with
//! $r_k = A \sin(2\pi f_i k T_s)$ added to controller A's output for the point's settling plus
//! measurement samples; the lock-in of $r$, $u$, $y$ over the measurement window gives
//! $\hat T_{ry} = Y/R$, $\hat S = U/R$ and $\hat P = Y/U$ with their standard deviations
//! ([`ambid_core::frf::stepped_sine`]). Each point draws its own sensor noise from a seed derived
//! from the base seed ([`point_seed`]), so a run is reproducible and the points are independent.
//!
//! # Settling on the nominal twin
//! The slowest closed-loop poles of the nominal twin are two real poles at $s \approx -42.5$ 1/s
//! ($\tau = 23.5$ ms, the integral actions of the two PID loops), then the 96 Hz translational
//! and the 780 Hz bending pairs ($\tau \approx 11$ ms). Switching a sine on excites them all; what
//! is left of the transient in the measurement window is the error of a noise-free point. On
//! 12 log-spaced points from 10 Hz to 2 kHz (linear twin, noise off, $A = 0.2$ A, windows of at
//! least 0.05 s and 4 cycles), the largest relative error over $P$, $T_{ry}$, $S$ (always at
//! 10 Hz, in $T_{ry}$) is 4.5e-3 after 0.05 s of settling, 5.4e-4 after 0.1 s, 6.4e-5 after
//! 0.15 s, 7.6e-6 after 0.2 s, 9.1e-7 after 0.25 s and 1.1e-7 after 0.3 s: a factor
//! $e^{-42.5 \cdot 0.05} = 0.12$ per 50 ms, the integral poles. So **0.3 s** of settling gives
//! ≤ 1e-6 with margin (`tests/stepped_sine.rs` asserts it). With sensor noise on, the transient
//! only has to fall well below the noise: at 10 % of $i_\mathrm{sat}$ (0.2 A) the relative
//! standard deviations are ≥ 1.8e-4, so 0.15 s suffice.
//!
//! # Measurement time
//! [`prbs_time_comparison`] plans a stepped sine on the same lines as a PRBS experiment (for the
//! seed's, $n = 10$, $N_b = 5$, 20 periods: lines every 3.91 Hz, 253 of them between 10 and
//! 1000 Hz, 5.115 s in all) and reports how long it takes, as planned and with the shortest
//! measurement windows that match the PRBS's noise level per line at equal excitation peak.
//!
//! # Example
//! ```
//! use ambid::stepped_sine::{compare_with_truth, run_stepped_sine, SteppedSineOptions};
//! use ambid_core::frf::stepped_sine::{Settle, SteppedSinePlan};
//! use ambid_twin::{Twin, TwinConfig};
//! let twin = Twin::new(TwinConfig::default()).unwrap();
//! let plan = SteppedSinePlan::new(twin.fs(), &[50.0, 300.0], Settle::Seconds(0.3), 4, 0.05).unwrap();
//! let out = run_stepped_sine(&twin, &plan, 0.2, &SteppedSineOptions { noise: false, ..Default::default() }).unwrap();
//! let err = compare_with_truth(&out, &twin).unwrap();
//! assert!(err.plant.max_rel() < 1e-6 && err.t_ry.max_rel() < 1e-6 && err.t_ru.max_rel() < 1e-6);
//! assert!((out.experiment_time_s - plan.total_time_s()).abs() < 1e-12);
//! ```

use crate::error::{Context, Error, Result};
use ambid_core::c64;
use ambid_core::frf::stepped_sine::{
    lock_in, NoiseEstimate, Ratio, Settle, SinePoint, SteppedSinePlan, SteppedSineResult,
};
use ambid_core::signal::PrbsSpec;
use ambid_twin::{Mode, SimOptions, Twin};
use rayon::prelude::*;

/// How to run a stepped-sine experiment on the twin.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SteppedSineOptions {
    /// Linear or nonlinear simulation. Default: linear.
    pub mode: Mode,
    /// Base seed of the sensor noise; point `i` uses [`point_seed`]`(seed, i)`. Default 0.
    pub seed: u64,
    /// Sensor noise on or off. Default: on.
    pub noise: bool,
    /// How the standard deviations are estimated. Default: 8 neighbour bins on each side (the
    /// loop colours the noise, so the white-noise estimate would be wrong).
    pub noise_estimate: NoiseEstimate,
}

impl Default for SteppedSineOptions {
    fn default() -> Self {
        Self {
            mode: Mode::Linear,
            seed: 0,
            noise: true,
            noise_estimate: NoiseEstimate::default(),
        }
    }
}

/// What a stepped-sine experiment produced.
#[derive(Debug, Clone)]
pub struct SteppedSineOutcome {
    /// The plan that was run.
    pub plan: SteppedSinePlan,
    /// Sine amplitude, A.
    pub amplitude_a: f64,
    /// Per point: phasors and ratios with variances.
    pub points: Vec<SinePoint>,
    /// The same, per quantity.
    pub result: SteppedSineResult,
    /// Noise seed of each point.
    pub seeds: Vec<u64>,
    /// Fraction of each point's samples with any limiter active (clamp, amplifier, slew).
    pub saturated_fraction: Vec<f64>,
    /// Total experiment time (settling plus measurement over all points), s: the measurement time
    /// of the method.
    pub experiment_time_s: f64,
    /// Samples simulated in all.
    pub simulated_samples: usize,
}

/// The noise seed of point `index` for base seed `base`: the SplitMix64 finaliser of
/// `base + (index + 1)·0x9E3779B97F4A7C15` (wrapping). Deterministic, and distinct points get
/// unrelated streams.
///
/// # Example
/// ```
/// use ambid::stepped_sine::point_seed;
/// assert_eq!(point_seed(7, 3), point_seed(7, 3));
/// assert_ne!(point_seed(7, 3), point_seed(7, 4));
/// assert_ne!(point_seed(7, 3), point_seed(8, 3));
/// ```
pub fn point_seed(base: u64, index: usize) -> u64 {
    let mut z = base.wrapping_add(
        (index as u64)
            .wrapping_add(1)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15),
    );
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Runs the stepped-sine experiment `plan` on `twin` with sine amplitude `amplitude_a` (A) at
/// controller A's output: one simulation from rest per point, settling plus measurement samples
/// ([`SteppedSinePlan::excitation`]), lock-in over the measurement window.
///
/// # Errors
/// If the plan's sample rate is not the twin's, the amplitude is not in $(0, i_\mathrm{sat}]$, a
/// simulation fails (touchdown, divergence: the message names the point and the frequency) or a
/// lock-in fails (e.g. the neighbour-bin noise estimate has no usable bins: plan more cycles).
///
/// # Example
/// ```
/// use ambid::stepped_sine::{run_stepped_sine, SteppedSineOptions};
/// use ambid_core::frf::stepped_sine::{Settle, SteppedSinePlan};
/// use ambid_twin::{Twin, TwinConfig};
/// let twin = Twin::new(TwinConfig::default()).unwrap();
/// let plan = SteppedSinePlan::new(twin.fs(), &[120.0], Settle::Seconds(0.15), 10, 0.1).unwrap();
/// let out = run_stepped_sine(&twin, &plan, 0.2, &SteppedSineOptions::default()).unwrap();
/// let s = out.result.t_ru[0];
/// println!("S(120 Hz) = {:.4} ± {:.4}", s.value, s.std());
/// assert!(s.std() < 0.01 * s.value.norm());
/// ```
pub fn run_stepped_sine(
    twin: &Twin,
    plan: &SteppedSinePlan,
    amplitude_a: f64,
    opts: &SteppedSineOptions,
) -> Result<SteppedSineOutcome> {
    let fs = twin.fs();
    if (plan.fs_hz() - fs).abs() > 1e-9 * fs {
        return Err(Error::usage(format!(
            "the plan was made for {} Hz but the twin samples at {fs} Hz; plan with twin.fs()",
            plan.fs_hz()
        )));
    }
    if !(amplitude_a.is_finite() && amplitude_a > 0.0 && amplitude_a <= twin.i_sat()) {
        return Err(Error::usage(format!(
            "the sine amplitude must be in (0, i_sat] = (0, {}] A, got {amplitude_a}",
            twin.i_sat()
        )));
    }
    let n = plan.len();
    // the points are independent experiments (point i: `point_seed(seed, i)`): simulated and
    // locked in in parallel, then used in point order (the first failing point is the one
    // reported, as in a sequential loop)
    let per_point: Vec<Result<(SinePoint, u64, f64, usize)>> = plan
        .points()
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let r = plan.excitation(i, amplitude_a)?;
            let seed = point_seed(opts.seed, i);
            let sim = SimOptions {
                mode: opts.mode,
                seed,
                noise: opts.noise,
                ..SimOptions::default()
            };
            let rec = twin.simulate(&r, &sim).with_context(|| {
                format!("simulating stepped-sine point {i} at {:.3} Hz", p.f_hz)
            })?;
            let pt = plan
                .estimate_point(i, &rec.r, &rec.u, &rec.y, opts.noise_estimate)
                .with_context(|| {
                    format!("lock-in of stepped-sine point {i} at {:.3} Hz", p.f_hz)
                })?;
            Ok((pt, seed, rec.meta.saturated_fraction, r.len()))
        })
        .collect();
    let (mut points, mut seeds, mut saturated) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    let mut simulated = 0usize;
    for item in per_point {
        let (pt, seed, sat, len) = item?;
        simulated += len;
        points.push(pt);
        seeds.push(seed);
        saturated.push(sat);
    }
    Ok(SteppedSineOutcome {
        plan: plan.clone(),
        amplitude_a,
        result: SteppedSineResult::from_points(&points),
        points,
        seeds,
        saturated_fraction: saturated,
        experiment_time_s: plan.total_time_s(),
        simulated_samples: simulated,
    })
}

/// Errors of one quantity against the truth, per point.
#[derive(Debug, Clone, PartialEq)]
pub struct QuantityErrors {
    /// The truth $G(f_i)$.
    pub truth: Vec<c64>,
    /// $|\hat G - G|$.
    pub abs: Vec<f64>,
    /// $|\hat G - G| / |G|$.
    pub rel: Vec<f64>,
    /// The estimate's predicted standard deviation $\sqrt{\mathrm E|\hat G - G|^2}$.
    pub std: Vec<f64>,
}

impl QuantityErrors {
    fn new(est: &[Ratio], truth: Vec<c64>) -> Self {
        let abs: Vec<f64> = est
            .iter()
            .zip(&truth)
            .map(|(e, t)| (e.value - t).norm())
            .collect();
        let rel = abs.iter().zip(&truth).map(|(a, t)| a / t.norm()).collect();
        Self {
            truth,
            abs,
            rel,
            std: est.iter().map(|e| e.std()).collect(),
        }
    }

    /// Largest relative error.
    pub fn max_rel(&self) -> f64 {
        self.rel.iter().fold(0.0, |m, v| m.max(*v))
    }

    /// $|\hat G - G| / \sigma$ per point (infinite where the predicted std is 0 and the error is not).
    pub fn normalized(&self) -> Vec<f64> {
        self.abs
            .iter()
            .zip(&self.std)
            .map(|(a, s)| if *a == 0.0 { 0.0 } else { a / s })
            .collect()
    }

    /// Mean of $|\hat G - G|^2 / \sigma^2$ over the points: about 1 when the predicted std is right.
    pub fn mean_normalized_sq(&self) -> f64 {
        let z = self.normalized();
        z.iter().map(|v| v * v).sum::<f64>() / z.len().max(1) as f64
    }
}

/// A stepped-sine outcome scored against the twin's exact linearised truth.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthComparison {
    /// Frequencies, Hz.
    pub f_hz: Vec<f64>,
    /// Plant $P$ against [`Twin::plant_frf`].
    pub plant: QuantityErrors,
    /// $T_{ry}$ against [`Twin::t_ry_frf`].
    pub t_ry: QuantityErrors,
    /// $S = T_{ru}$ against [`Twin::sensitivity_frf`].
    pub t_ru: QuantityErrors,
}

/// Scores `outcome` against `twin`'s truth at the snapped frequencies (relative error per point,
/// and the error in units of the predicted standard deviation).
///
/// # Errors
/// If the truth cannot be evaluated at the plan's frequencies.
///
/// # Example
/// See the [module documentation](self).
pub fn compare_with_truth(outcome: &SteppedSineOutcome, twin: &Twin) -> Result<TruthComparison> {
    let f = &outcome.result.f_hz;
    Ok(TruthComparison {
        f_hz: f.clone(),
        plant: QuantityErrors::new(&outcome.result.plant, twin.plant_frf(f)?),
        t_ry: QuantityErrors::new(&outcome.result.t_ry, twin.t_ry_frf(f)?),
        t_ru: QuantityErrors::new(&outcome.result.t_ru, twin.sensitivity_frf(f)?),
    })
}

/// How long a stepped sine on the lines of a PRBS experiment takes, next to the PRBS.
#[derive(Debug, Clone, PartialEq)]
pub struct PrbsTimeComparison {
    /// The PRBS experiment.
    pub prbs: PrbsSpec,
    /// Its samples (all periods).
    pub prbs_samples: usize,
    /// Its duration, s.
    pub prbs_time_s: f64,
    /// Its line spacing $f_s / (L N_b)$, Hz.
    pub resolution_hz: f64,
    /// The band of lines compared, Hz.
    pub band_hz: (f64, f64),
    /// The stepped sine on the PRBS lines inside the band, with the given settling and measurement rule.
    pub plan: SteppedSinePlan,
    /// Its duration, s (`plan.total_time_s()`).
    pub stepped_time_s: f64,
    /// `stepped_time_s / prbs_time_s`.
    pub time_ratio: f64,
    /// Per line, the measurement time a sine with the PRBS's peak amplitude needs to reach the
    /// noise level of the PRBS estimate (averaged over all its periods) at that line, s:
    /// $T_\mathrm{PRBS} |R_k|^2 / a^2$, $R_k$ the PRBS's phasor at the line, $a$ its amplitude.
    pub equal_noise_measure_s: Vec<f64>,
    /// The stepped sine's duration with the same settling and those measurement times (but at
    /// least `measure_cycles` whole cycles), s.
    pub equal_noise_time_s: f64,
}

/// Plans a stepped sine on the lines of `prbs` (sampled at `fs_hz`) that fall inside `band_hz`,
/// settling by `settle`, measuring at least `measure_cycles` cycles and `min_measure_s` seconds per
/// line, and compares its duration with the PRBS experiment's. See [`PrbsTimeComparison`].
///
/// # Errors
/// If the PRBS design is invalid, the band holds no line, the plan cannot be made (see
/// [`SteppedSinePlan::new`]), or snapping to whole cycles would move a line by half the line
/// spacing or more (raise `min_measure_s`: the snap is at most $f/(2N)$ for an $N$-sample window).
///
/// # Example
/// The seed paper's PRBS (n = 10, 5 samples per bit, 20 periods at 20 kHz) against a stepped sine
/// on its 253 lines in 10–1000 Hz, settling 0.15 s (enough at 10 % of $i_\mathrm{sat}$ with
/// noise) and measuring at least 0.05 s and 4 cycles per line:
/// ```
/// use ambid::stepped_sine::prbs_time_comparison;
/// use ambid_core::frf::stepped_sine::Settle;
/// use ambid_core::signal::PrbsSpec;
/// let c = prbs_time_comparison(20e3, &PrbsSpec::default(), (10.0, 1000.0), Settle::Seconds(0.15), 4, 0.05).unwrap();
/// assert_eq!(c.prbs_samples, 102_300);
/// assert!((c.prbs_time_s - 5.115).abs() < 1e-12 && (c.resolution_hz - 3.91).abs() < 0.01);
/// assert_eq!(c.plan.len(), 253);
/// println!(
///     "PRBS {:.3} s; stepped sine on the same {} lines {:.1} s ({:.1}x), {:.1} s at equal noise",
///     c.prbs_time_s, c.plan.len(), c.stepped_time_s, c.time_ratio, c.equal_noise_time_s
/// );
/// assert!(c.stepped_time_s > 50.0 && c.stepped_time_s < 60.0);
/// assert!(c.equal_noise_time_s > 40.0 && c.equal_noise_time_s < c.stepped_time_s);
/// ```
pub fn prbs_time_comparison(
    fs_hz: f64,
    prbs: &PrbsSpec,
    band_hz: (f64, f64),
    settle: Settle,
    measure_cycles: usize,
    min_measure_s: f64,
) -> Result<PrbsTimeComparison> {
    if !(fs_hz.is_finite() && fs_hz > 0.0) {
        return Err(Error::usage(format!(
            "the sample rate must be finite and positive, got {fs_hz}"
        )));
    }
    let ts = 1.0 / fs_hz;
    let report = prbs.report(ts).context("the PRBS design")?;
    let np = report.period_samples;
    let df = fs_hz / np as f64;
    let (f_lo, f_hi) = band_hz;
    if !(f_lo.is_finite() && f_hi.is_finite() && 0.0 < f_lo && f_lo <= f_hi) {
        return Err(Error::usage(format!(
            "the band must satisfy 0 < f_lo ≤ f_hi, got ({f_lo}, {f_hi}) Hz"
        )));
    }
    let k_lo = (f_lo / df).ceil().max(1.0) as usize;
    let k_hi = ((f_hi / df).floor() as usize).min((np - 1) / 2);
    if k_hi < k_lo {
        return Err(Error::usage(format!(
            "no PRBS line ({df:.4} Hz spacing) lies in {f_lo}–{f_hi} Hz; widen the band"
        )));
    }
    let lines: Vec<f64> = (k_lo..=k_hi).map(|k| k as f64 * df).collect();
    let plan = SteppedSinePlan::new(fs_hz, &lines, settle, measure_cycles, min_measure_s)?;
    check_snap(&plan, df)?;
    // the PRBS's phasor per line, for an amplitude-1 PRBS: one period holds k cycles of line k
    let unit = PrbsSpec {
        periods: 1,
        amplitude: 1.0,
        offset: 0.0,
        ..prbs.clone()
    };
    let period = unit.generate(ts)?.values;
    let prbs_time_s = report.duration_s;
    let mut equal_noise_measure_s = Vec::with_capacity(lines.len());
    let mut equal_noise_time_s = 0.0;
    for f in &lines {
        let rk = lock_in(&period, *f, fs_hz, 0, np)?;
        let t = prbs_time_s * rk.norm_sqr();
        let one = SteppedSinePlan::new(fs_hz, &[*f], settle, measure_cycles, t)?;
        check_snap(&one, df)?;
        equal_noise_measure_s.push(t);
        equal_noise_time_s += one.total_time_s();
    }
    let stepped_time_s = plan.total_time_s();
    Ok(PrbsTimeComparison {
        prbs: prbs.clone(),
        prbs_samples: report.n_samples,
        prbs_time_s,
        resolution_hz: df,
        band_hz,
        plan,
        stepped_time_s,
        time_ratio: stepped_time_s / prbs_time_s,
        equal_noise_measure_s,
        equal_noise_time_s,
    })
}

/// Refuses a plan whose whole-cycle snapping moves a line by half the PRBS line spacing or more
/// (the stepped sine would no longer measure the PRBS's lines).
fn check_snap(plan: &SteppedSinePlan, df: f64) -> Result<()> {
    for p in plan.points() {
        if (p.f_hz - p.f_requested_hz).abs() >= 0.5 * df {
            return Err(Error::usage(format!(
                "snapping {:.3} Hz to a whole number of cycles in {} samples moved it to {:.3} Hz, \
                 half a PRBS line spacing ({df:.3} Hz) or more; raise min_measure_s (the snap is at \
                 most f/(2 N), N the window in samples)",
                p.f_requested_hz,
                p.measure_samples,
                p.f_hz
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_are_spread() {
        let s: std::collections::BTreeSet<u64> = (0..1000).map(|i| point_seed(0, i)).collect();
        assert_eq!(s.len(), 1000);
    }

    #[test]
    fn bad_arguments_are_rejected() {
        let twin = Twin::new(ambid_twin::TwinConfig::default()).unwrap();
        let plan = SteppedSinePlan::new(10_000.0, &[100.0], Settle::Seconds(0.0), 1, 0.0).unwrap();
        assert!(run_stepped_sine(&twin, &plan, 0.1, &SteppedSineOptions::default()).is_err());
        let plan = SteppedSinePlan::new(twin.fs(), &[100.0], Settle::Seconds(0.0), 1, 0.0).unwrap();
        for a in [0.0, -0.1, f64::NAN, 2.5] {
            assert!(
                run_stepped_sine(&twin, &plan, a, &SteppedSineOptions::default()).is_err(),
                "{a}"
            );
        }
        let p = PrbsSpec::default();
        assert!(prbs_time_comparison(20e3, &p, (1.0, 2.0), Settle::Seconds(0.1), 4, 0.05).is_err());
        assert!(
            prbs_time_comparison(20e3, &p, (100.0, 10.0), Settle::Seconds(0.1), 4, 0.05).is_err()
        );
        assert!(
            prbs_time_comparison(0.0, &p, (10.0, 100.0), Settle::Seconds(0.1), 4, 0.05).is_err()
        );
    }
}
