//! The robust Best Linear Approximation of the plant: $M$ random-phase multisine realisations of
//! $P$ periods each, injected at the controller output, and the BLA of the plant
//! ($T_{ry}/T_{ru}$ per realisation, [`ambid_core::frf::bla`]) with its noise and stochastic
//! nonlinear variances; and the amplitude study built on it.
//!
//! The experiments come from the twin ([`BlaPlan`], [`run_level`], [`amplitude_study`], checked
//! against the twin's linearised plant) or from recorded files ([`RecordedLevel`],
//! [`bla_of_level`], [`amplitude_study_from_records`]); both end in the same figures
//! ([`figures_of`]) and the same recommendation ([`recommend`]).
//!
//! # Amplitude study
//! For each RMS level (fraction of `i_sat`) the BLA is estimated and, averaged over the excited
//! band and relative to $|\hat G_{\mathrm{BLA}}|^2$ line by line:
//!
//! * `noise_rel` $= \overline{M\hat\sigma^2_n/|\hat G|^2}$: the noise variance of **one
//!   realisation's** FRF (one experiment of $P$ periods);
//! * `nl_rel` $= \overline{\hat\sigma^2_S/|\hat G|^2}$: the stochastic nonlinear variance of one
//!   realisation.
//!
//! Both are on the footing of one $P$-period experiment, so their sum is the variance of a single
//! experiment's FRF around the BLA. Noise falls as $1/A^2$ with the level $A$, the distortion of a
//! degree-$n$ nonlinearity grows as $A^{2(n-1)}$; the recommended level is the one of the list
//! where the sum is smallest. The systematic part of the nonlinearity (the BLA itself drifting with
//! the level) is not in this sum; `bla_vs_linear_rel` reports it against the twin's linearised
//! plant.
//!
//! # Example
//! ```no_run
//! use ambid::bla::{amplitude_study, BlaPlan};
//! let plan = BlaPlan::default();
//! let study = amplitude_study(&plan, &[0.04, 0.08, 0.16]).unwrap();
//! println!("{}", study.reasoning);
//! ```

use crate::error::{Context, Error, Result};
use ambid_core::c64;
use ambid_core::frf::bla::{random_phase_period, robust_bla, Bla, BlaEstimate, Record};
use ambid_core::frf::periodic::PeriodicOptions;
use ambid_core::signal::{Grid, MultisineSpec, Phases};
use ambid_twin::{Mode, SimOptions, Twin, TwinConfig};
use rayon::prelude::*;
use serde::Serialize;

/// How the BLA experiment is run on the twin.
#[derive(Debug, Clone)]
pub struct BlaPlan {
    /// Twin parameters.
    pub twin: TwinConfig,
    /// Linear or nonlinear physics.
    pub mode: Mode,
    /// Sensor noise on or off.
    pub noise: bool,
    /// Multisine realisations $M$ ($\ge 2$).
    pub realisations: usize,
    /// Analysed periods per realisation $P$ ($\ge 2$); one more period is simulated before
    /// recording to settle the transient.
    pub periods: usize,
    /// Period length \[s\] (line spacing 1/period).
    pub period_s: f64,
    /// Lowest excited frequency \[Hz\].
    pub f_min_hz: f64,
    /// Highest excited frequency \[Hz\].
    pub f_max_hz: f64,
    /// Excitation grid (odd or random-odd for the detection lines); the same grid is used for
    /// every realisation, only the phases change.
    pub grid: Grid,
    /// Band over which the study averages \[Hz\] (lines outside are estimated but not averaged;
    /// the default stops at 1 kHz, above which the twin's sensor noise dominates the plant).
    pub summary_band_hz: (f64, f64),
    /// Seed of the grid and of the phases (realisation m uses `seed + 1 + m`) and of the noise.
    pub seed: u64,
}

impl Default for BlaPlan {
    /// Nonlinear twin with sensor noise, M = 8, P = 4, 0.05 s periods (20 Hz lines),
    /// 20–2000 Hz excited, random-odd grid, summaries over 20–1000 Hz.
    fn default() -> Self {
        Self {
            twin: TwinConfig::default(),
            mode: Mode::Nonlinear,
            noise: true,
            realisations: 8,
            periods: 4,
            period_s: 0.05,
            f_min_hz: 20.0,
            f_max_hz: 2000.0,
            grid: Grid::RandomOdd,
            summary_band_hz: (20.0, 1000.0),
            seed: 1,
        }
    }
}

/// What one BLA experiment on the twin produced.
pub struct LevelRun {
    /// The twin that was run (for its truth).
    pub twin: Twin,
    /// The closed-loop BLA of the plant (and of T_ry, T_ru).
    pub bla: Bla,
    /// Largest fraction of samples with an amplifier/DAC limit active over the realisations.
    pub saturated_fraction: f64,
}

/// Runs the $M \times P$ experiment at RMS level `rms_frac` × `i_sat` and returns the twin (for
/// its truth), the closed-loop BLA and how often a limit was active.
///
/// # Errors
/// Invalid plan (M or P below 2, level outside (0, 1], empty band), simulation or BLA errors.
pub fn run_level(plan: &BlaPlan, rms_frac: f64) -> Result<LevelRun> {
    if !(rms_frac.is_finite() && rms_frac > 0.0 && rms_frac <= 1.0) {
        return Err(Error::other(format!(
            "the RMS level must be a fraction of i_sat in (0, 1], got {rms_frac}"
        )));
    }
    if plan.realisations < 2 || plan.periods < 2 {
        return Err(Error::other(format!(
            "the robust BLA needs at least 2 realisations and 2 periods (got M = {}, P = {})",
            plan.realisations, plan.periods
        )));
    }
    let twin = Twin::new(plan.twin.clone()).context("building the AMB twin")?;
    let ts = twin.ts();
    let n = (plan.period_s / ts).round() as usize;
    let spec = MultisineSpec {
        f_min_hz: plan.f_min_hz,
        f_max_hz: plan.f_max_hz,
        period_samples: n,
        periods: 1,
        rms: 1.0,
        grid: plan.grid,
        phases: Phases::Random,
        seed: plan.seed,
    };
    let bins = spec.bins(ts).context("designing the multisine grid")?;
    let rms = rms_frac * twin.i_sat();
    // the realisations are independent (realisation m: seed + 1 + m): simulated in lock-step
    // lanes (`Twin::simulate_batch`, each exactly its lone run), the lane groups in parallel,
    // then used in order (the first failing one is the one reported, as in a sequential loop)
    let inputs = (0..plan.realisations)
        .into_par_iter()
        .map(|m| {
            let seed = plan.seed.wrapping_add(1 + m as u64);
            let period = random_phase_period(&bins, n, rms, seed)?;
            let r: Vec<f64> = (0..plan.periods * n).map(|t| period[t % n]).collect();
            let opts = SimOptions {
                mode: plan.mode,
                seed: seed.wrapping_mul(7919),
                noise: plan.noise,
                settle_samples: n,
                ..SimOptions::default()
            };
            Ok((r, opts))
        })
        .collect::<Vec<Result<_>>>()
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
    let data = inputs
        .par_chunks(ambid_twin::sim::MAX_LANES)
        .enumerate()
        .flat_map_iter(|(c, chunk)| {
            let runs: Vec<(&Twin, &[f64], &SimOptions)> = chunk
                .iter()
                .map(|(r, o)| (&twin, r.as_slice(), o))
                .collect();
            Twin::simulate_batch(&runs)
                .into_iter()
                .enumerate()
                .map(move |(k, rec)| {
                    let m = c * ambid_twin::sim::MAX_LANES + k;
                    rec.with_context(|| format!("simulating realisation {m}"))
                })
        })
        .collect::<Vec<Result<_>>>()
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
    let recs: Vec<Record> = data
        .iter()
        .map(|d| Record::closed_loop(&d.r, &d.u, &d.y))
        .collect();
    let bla = robust_bla(&recs, twin.fs(), &PeriodicOptions::new(n))?;
    let saturated_fraction = data
        .iter()
        .map(|d| d.meta.saturated_fraction)
        .fold(0.0, f64::max);
    Ok(LevelRun {
        twin,
        bla,
        saturated_fraction,
    })
}

/// One recorded realisation of a robust-BLA experiment: a random-phase multisine applied for a
/// whole number of periods (the leading transient periods included).
#[derive(Debug, Clone)]
pub struct Realisation {
    /// The excitation $r$ added to the controller output (closed loop); `None` for open-loop
    /// data, where `u` is the excitation.
    pub r: Option<Vec<f64>>,
    /// Plant input (controller output including $r$).
    pub u: Vec<f64>,
    /// Plant output.
    pub y: Vec<f64>,
    /// Fraction of samples at an amplifier/current limit, if known.
    pub saturated_fraction: Option<f64>,
    /// Where it came from (for error messages).
    pub source: String,
}

/// The realisations recorded at one excitation level.
#[derive(Debug, Clone)]
pub struct RecordedLevel {
    /// RMS level \[% of i_sat\] (a label: the data are used as recorded).
    pub level_pct: f64,
    /// $M \ge 2$ realisations, same length and period.
    pub realisations: Vec<Realisation>,
}

impl RecordedLevel {
    /// Groups realisations tagged with their level \[% of i_sat\] into levels (realisations in
    /// their given order), ascending by level.
    pub fn group(tagged: impl IntoIterator<Item = (f64, Realisation)>) -> Vec<RecordedLevel> {
        let mut levels: Vec<RecordedLevel> = Vec::new();
        for (level_pct, x) in tagged {
            match levels
                .iter_mut()
                .find(|l| (l.level_pct - level_pct).abs() < 1e-9)
            {
                Some(l) => l.realisations.push(x),
                None => levels.push(RecordedLevel {
                    level_pct,
                    realisations: vec![x],
                }),
            }
        }
        levels.sort_by(|a, b| a.level_pct.total_cmp(&b.level_pct));
        levels
    }
}

/// The multisine period shared by every realisation of `levels`: the period of each one's
/// excitation (`r`, or `u` for open-loop data) as `ambid frf` finds it
/// ([`PeriodScan`](ambid_core::signal::PeriodScan), docs/frf.md "Which estimator"), `Err` with
/// the first realisation whose excitation does not repeat or repeats with another period.
///
/// # Example
/// ```
/// use ambid::bla::{common_period, Realisation, RecordedLevel};
/// let one: Vec<f64> = (0..50).map(|k| ((k * 7) % 11) as f64 - 5.0).collect();
/// let rec = |shift: usize, src: &str| Realisation {
///     r: Some(one.iter().cycle().skip(shift).take(250).copied().collect()),
///     u: vec![0.0; 250],
///     y: vec![0.0; 250],
///     saturated_fraction: None,
///     source: src.into(),
/// };
/// let levels = RecordedLevel::group([(4.0, rec(0, "a")), (4.0, rec(3, "b"))]);
/// assert_eq!(common_period(&levels), Ok(50));
/// let levels = RecordedLevel::group([(4.0, rec(0, "a")), (4.0, Realisation { r: Some((0..250).map(f64::from).collect()), ..rec(0, "c") })]);
/// assert!(common_period(&levels).unwrap_err().contains("c"));
/// ```
pub fn common_period(levels: &[RecordedLevel]) -> std::result::Result<usize, String> {
    let mut found: Option<(usize, &str)> = None;
    for x in levels.iter().flat_map(|l| &l.realisations) {
        let exc = x.r.as_deref().unwrap_or(&x.u);
        match (ambid_core::signal::PeriodScan::of(exc), found) {
            (None, _) => {
                return Err(format!(
                    "{}: the excitation does not repeat (no period of at most half the record)",
                    x.source
                ))
            }
            (Some(p), Some((q, first))) if p != q => {
                return Err(format!(
                    "{}: the excitation repeats every {p} samples, {first}'s every {q}",
                    x.source
                ))
            }
            (Some(p), None) => found = Some((p, &x.source)),
            _ => {}
        }
    }
    found
        .map(|(p, _)| p)
        .ok_or_else(|| "no realisation is given".to_string())
}

/// How recorded BLA experiments are cut.
#[derive(Debug, Clone, Copy)]
pub struct RecordedPlan {
    /// Sample rate \[Hz\].
    pub fs: f64,
    /// Samples per multisine period $N$.
    pub period_samples: usize,
    /// Leading periods dropped as transient (at least $P \ge 2$ must remain).
    pub skip_periods: usize,
    /// Band of the study's averages \[Hz\].
    pub summary_band_hz: (f64, f64),
}

/// The robust BLA of one recorded level: closed loop ($r$ recorded: the plant as
/// $T_{ry}/T_{ru}$ per realisation) or open loop ($u \to y$).
///
/// # Errors
/// Fewer than 2 realisations, a level mixing closed- and open-loop records, and the errors of
/// [`robust_bla`] (records of different lengths, not a whole number of periods, fewer than 2
/// periods left after the skipped ones, no line excited in every realisation, non-finite
/// samples), each naming the level and the fix.
pub fn bla_of_level(level: &RecordedLevel, plan: &RecordedPlan) -> Result<Bla> {
    let m = level.realisations.len();
    if m < 2 {
        return Err(Error::other(format!(
            "level {} %: the robust BLA needs at least 2 realisations (independent random-phase \
             multisines), got {m}; record more realisations at this level",
            level.level_pct
        )));
    }
    let closed = level.realisations.iter().filter(|x| x.r.is_some()).count();
    if closed != 0 && closed != m {
        return Err(Error::other(format!(
            "level {} %: {closed} of {m} realisations have the excitation r and the others do not; \
             give r for all (closed loop) or for none (open loop)",
            level.level_pct
        )));
    }
    let recs: Vec<Record> = level
        .realisations
        .iter()
        .map(|x| match &x.r {
            Some(r) => Record::closed_loop(r, &x.u, &x.y),
            None => Record::open_loop(&x.u, &x.y),
        })
        .collect();
    let opts = PeriodicOptions::new(plan.period_samples).skip(plan.skip_periods);
    robust_bla(&recs, plan.fs, &opts).with_context(|| {
        let names: Vec<&str> = level
            .realisations
            .iter()
            .map(|x| x.source.as_str())
            .collect();
        format!(
            "robust BLA of level {} % ({})",
            level.level_pct,
            names.join(", ")
        )
    })
}

/// The BLA amplitude study on recorded data: one [`RecordedLevel`] per level, figures over the
/// plan's band (no truth, so `bla_vs_linear_rel` is `None`) and the recommendation of
/// [`recommend`].
///
/// # Example
/// Two levels of an open-loop static gain of 2 with a small output disturbance: no nonlinear
/// distortion, and the higher level has the smaller relative noise.
/// ```
/// use ambid::bla::{amplitude_study_from_records, Realisation, RecordedLevel, RecordedPlan};
/// use ambid_core::frf::bla::random_phase_period;
/// let (n, periods) = (64usize, 4usize);
/// let bins: Vec<usize> = (1..20).step_by(2).collect();
/// let level = |pct: f64| RecordedLevel {
///     level_pct: pct,
///     realisations: (0..4u64)
///         .map(|m| {
///             let p = random_phase_period(&bins, n, pct / 100.0, m).unwrap();
///             let u: Vec<f64> = (0..periods * n).map(|t| p[t % n]).collect();
///             // a deterministic "noise" that differs from period to period
///             let y = u.iter().enumerate().map(|(t, v)| 2.0 * v + 1e-3 * ((t * t + 7 * m as usize) as f64).sin()).collect();
///             Realisation { r: None, u, y, saturated_fraction: None, source: format!("m{m}") }
///         })
///         .collect(),
/// };
/// let plan = RecordedPlan { fs: 64.0, period_samples: n, skip_periods: 1, summary_band_hz: (0.5, 20.0) };
/// let study = amplitude_study_from_records(&[level(5.0), level(20.0)], &plan).unwrap();
/// assert!(study.rows[1].noise_rel < study.rows[0].noise_rel);
/// assert!(study.rows.iter().all(|r| r.bla_vs_linear_rel.is_none()));
/// ```
///
/// # Errors
/// No level, a level outside (0, 100] %, or the errors of [`bla_of_level`].
pub fn amplitude_study_from_records(
    levels: &[RecordedLevel],
    plan: &RecordedPlan,
) -> Result<BlaStudy> {
    if levels.is_empty() {
        return Err(Error::other(
            "give at least one level of recorded realisations",
        ));
    }
    // the levels are independent: in parallel, then used in level order (the first failing
    // level is the one reported, as in a sequential loop)
    let rows = levels
        .par_iter()
        .map(|level| {
            if !(level.level_pct.is_finite() && level.level_pct > 0.0 && level.level_pct <= 100.0) {
                return Err(Error::other(format!(
                    "a level must be in (0, 100] % of i_sat, got {}",
                    level.level_pct
                )));
            }
            let bla = bla_of_level(level, plan)?;
            let sat = level
                .realisations
                .iter()
                .filter_map(|x| x.saturated_fraction)
                .fold(0.0, f64::max);
            figures_of(&bla, level.level_pct, plan.summary_band_hz, sat, None)
        })
        .collect::<Vec<Result<LevelBla>>>()
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
    recommend(rows)
}

/// Figures of one level of the amplitude study (see the [module docs](self)), averaged over the
/// summary band.
#[derive(Debug, Clone, Serialize)]
pub struct LevelBla {
    /// RMS level \[% of i_sat\].
    pub level_pct: f64,
    /// Excited lines averaged.
    pub lines: usize,
    /// Realisations $M$.
    pub realisations: usize,
    /// Analysed periods per realisation $P$.
    pub periods: usize,
    /// Band mean of the relative noise variance of one realisation.
    pub noise_rel: f64,
    /// Band mean of the relative NL variance of one realisation.
    pub nl_rel: f64,
    /// Standard error of `nl_rel`.
    pub nl_rel_se: f64,
    /// `noise_rel + max(nl_rel, 0)` (a negative NL estimate is noise, not a gain).
    pub sum_rel: f64,
    /// Even detection lines of y over their noise level \[dB\].
    pub even_db: f64,
    /// Odd detection lines of y over their noise level \[dB\].
    pub odd_db: f64,
    /// RMS relative difference of the BLA from the linearised plant over the band, when the
    /// plant is known (the twin); `None` on recorded data.
    pub bla_vs_linear_rel: Option<f64>,
    /// Largest fraction of samples with a limit active (clipping makes even the linear twin
    /// nonlinear).
    pub saturated_fraction: f64,
    /// The plant's BLA per line with its variances (term (c) of the uncertainty step reads
    /// it; not in the study's CSV or JSON).
    #[serde(skip)]
    pub plant: BlaEstimate,
}

/// Outcome of the BLA amplitude study.
#[derive(Debug, Clone, Serialize)]
pub struct BlaStudy {
    /// One row per level, in the given order.
    pub rows: Vec<LevelBla>,
    /// The level with the smallest `sum_rel` \[% of i_sat\].
    pub recommended_pct: f64,
    /// Why.
    pub reasoning: String,
}

/// The true plant FRF at given frequencies \[Hz\] (the twin's linearised plant).
pub type PlantTruth<'a> = dyn Fn(&[f64]) -> Result<Vec<c64>> + 'a;

/// The figures of one level from its BLA (summary band `band_hz`), with the RMS relative
/// difference from a known linear plant when `truth` (the plant FRF at given frequencies) is
/// given.
///
/// # Errors
/// A BLA that vanishes on a line, no excited line in the band, or `truth` failing.
pub fn figures_of(
    bla: &Bla,
    level_pct: f64,
    band_hz: (f64, f64),
    saturated_fraction: f64,
    truth: Option<&PlantTruth<'_>>,
) -> Result<LevelBla> {
    let g = &bla.g;
    let s = g.band_summary(band_hz.0, band_hz.1)?;
    let m = g.realisations as f64;
    let bla_vs_linear_rel = match truth {
        Some(truth) => {
            let in_band: Vec<usize> = (0..g.f_hz.len())
                .filter(|&i| g.f_hz[i] >= band_hz.0 && g.f_hz[i] <= band_hz.1)
                .collect();
            let f: Vec<f64> = in_band.iter().map(|&i| g.f_hz[i]).collect();
            let t = truth(&f)?;
            Some(
                (in_band
                    .iter()
                    .zip(&t)
                    .map(|(&i, b)| (g.values[i] - b).norm_sqr() / b.norm_sqr())
                    .sum::<f64>()
                    / t.len().max(1) as f64)
                    .sqrt(),
            )
        }
        None => None,
    };
    Ok(LevelBla {
        level_pct,
        lines: s.lines,
        realisations: g.realisations,
        periods: g.periods,
        noise_rel: m * s.noise_rel,
        nl_rel: s.nl_rel,
        nl_rel_se: s.nl_rel_se,
        sum_rel: m * s.noise_rel + s.nl_rel.max(0.0),
        even_db: bla.detection.even.ratio_db,
        odd_db: bla.detection.odd.ratio_db,
        bla_vs_linear_rel,
        saturated_fraction,
        plant: g.clone(),
    })
}

/// The figures of one twin level (see [`figures_of`]), checked against the twin's linearised
/// plant.
///
/// # Errors
/// As [`figures_of`].
pub fn level_figures(run: &LevelRun, rms_frac: f64, band_hz: (f64, f64)) -> Result<LevelBla> {
    let truth = |f: &[f64]| -> Result<Vec<c64>> { Ok(run.twin.plant_frf(f)?) };
    figures_of(
        &run.bla,
        100.0 * rms_frac,
        band_hz,
        run.saturated_fraction,
        Some(&truth),
    )
}

/// Largest fraction of clipped samples for a level to be recommended.
pub const MAX_SATURATED: f64 = 0.01;

/// Runs the BLA at every RMS level (fractions of i_sat) and recommends the level where noise plus
/// NL variance of one experiment (`sum_rel`) is smallest among the levels that clip on at most
/// [`MAX_SATURATED`] of the samples.
///
/// # Errors
/// No level, or the errors of [`run_level`].
pub fn amplitude_study(plan: &BlaPlan, levels: &[f64]) -> Result<BlaStudy> {
    if levels.is_empty() {
        return Err(Error::other("give at least one level"));
    }
    // the levels are independent experiments: in parallel (each with the plan's seeds, as in a
    // sequential loop), then used in level order (the first failing level is the one reported)
    let rows = levels
        .par_iter()
        .map(|&l| {
            let run = run_level(plan, l).with_context(|| format!("level {l}"))?;
            level_figures(&run, l, plan.summary_band_hz)
        })
        .collect::<Vec<Result<LevelBla>>>()
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
    recommend(rows)
}

/// Recommends, among the study's rows, the level where noise plus NL variance of one experiment
/// (`sum_rel`) is smallest, leaving out levels that clip on more than [`MAX_SATURATED`] of the
/// samples (unless all do), and says why.
///
/// # Errors
/// No row.
pub fn recommend(rows: Vec<LevelBla>) -> Result<BlaStudy> {
    // levels that clip on more than MAX_SATURATED of the samples are not recommended (unless all do)
    let ok: Vec<&LevelBla> = rows
        .iter()
        .filter(|r| r.saturated_fraction <= MAX_SATURATED)
        .collect();
    let candidates: Vec<&LevelBla> = if ok.is_empty() {
        rows.iter().collect()
    } else {
        ok
    };
    let excluded = rows.len() - candidates.len();
    let best = *candidates
        .iter()
        .min_by(|a, b| a.sum_rel.total_cmp(&b.sum_rel))
        .ok_or_else(|| Error::other("no level"))?;
    let recommended_pct = best.level_pct;
    let significant = |r: &LevelBla| r.nl_rel > 3.0 * r.nl_rel_se;
    let first_nl = rows.iter().find(|r| significant(r)).map(|r| r.level_pct);
    let dominant = if best.nl_rel > best.noise_rel {
        "NL distortion already dominates there"
    } else {
        "noise still dominates there"
    };
    let reasoning = format!(
        "{excluded_txt}noise + NL variance of one {P}-period experiment (relative to |G_BLA|², band mean) is smallest \
         at {recommended_pct:.1} % of i_sat RMS ({:.2e}: noise {:.2e}, NL {}; {dominant}). Below it \
         the noise share grows as 1/level²; above it the stochastic NL distortion (and clipping) grows faster than the \
         noise falls. NL variance significant (> 3 standard errors) from {}.{}{}",
        best.sum_rel,
        best.noise_rel,
        if significant(best) {
            format!("{:.2e}", best.nl_rel)
        } else {
            format!(
                "not significant (below 3 standard errors, {:.2e})",
                3.0 * best.nl_rel_se
            )
        },
        first_nl.map_or("no level of the list".to_string(), |p| format!("{p:.1} %")),
        best.bla_vs_linear_rel.map_or(String::new(), |e| format!(
            " The BLA's systematic drift from the linearised plant is not in the sum \
             (the BLA differs from it by {:.1} % RMS at the recommended level).",
            100.0 * e
        )),
        if best.saturated_fraction > 0.0 {
            format!(
                " Caution: a current limit was active on {:.2} % of the samples at that level.",
                100.0 * best.saturated_fraction
            )
        } else {
            String::new()
        },
        P = best.periods,
        excluded_txt = if excluded > 0 {
            format!(
                "{excluded} level(s) with a current limit active on more than {:.0} % of the samples \
                 left out; among the others the ",
                100.0 * MAX_SATURATED
            )
        } else {
            "The ".to_string()
        },
    );
    Ok(BlaStudy {
        rows,
        recommended_pct,
        reasoning,
    })
}
