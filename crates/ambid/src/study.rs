//! The seed paper's two experiment studies, on the twin or on recorded files:
//!
//! * **excitation amplitude** (its figure 6): the FRF experiment at several excitation levels;
//!   average coherence, average FRF variance across periods and output SNR per level, and a
//!   recommended range (coherence saturated, variance near its minimum, no saturation);
//! * **operating point** (its figure 7): plant FRFs at nominal, bias ±20 % and air gap ±10 µm,
//!   with the deviation from nominal per band (low frequency, resonance region, high frequency).

use crate::analysis::{analyze, FrfAnalysis, FrfSettings, Record};
use crate::error::{Context, Error, Result};
use crate::experiment::{run_batch, ExcitationKind, ExcitationPlan, Experiment, ExperimentOutput};
use ambid_core::lti::Frd;
use ambid_twin::{Mode, TwinConfig};
use rayon::prelude::*;
use serde::Serialize;

/// One recorded experiment of an amplitude study.
#[derive(Debug, Clone)]
pub struct LevelRecord {
    /// Excitation level as a fraction of i_sat.
    pub level: f64,
    /// Excitation r \[A\].
    pub r: Vec<f64>,
    /// Controller output u \[A\].
    pub u: Vec<f64>,
    /// Displacement y \[m\].
    pub y: Vec<f64>,
    /// Coil current i \[A\] (for the saturation check), if recorded.
    pub i: Option<Vec<f64>>,
    /// Fraction of samples with a limit active, if known (twin metadata).
    pub saturated_fraction: Option<f64>,
}

/// Per-level figures of an amplitude study.
#[derive(Debug, Clone, Serialize)]
pub struct LevelFigures {
    /// Level \[% of i_sat\].
    pub level_pct: f64,
    /// Average γ²_ry over the band.
    pub mean_coh_ry: f64,
    /// Average γ²_ru over the band.
    pub mean_coh_ru: f64,
    /// Average single-period plant variance over the band \[(m/A)²\].
    pub mean_plant_var: f64,
    /// Average relative single-period plant variance.
    pub mean_plant_rel_var: f64,
    /// Output SNR \[dB\] (needs a noise-only record).
    pub snr_db: Option<f64>,
    /// Fraction of saturated samples (0 when unknown and not detected).
    pub saturated_fraction: f64,
    /// Median relative error of the plant against the twin's truth (twin runs only).
    pub plant_median_rel_err: Option<f64>,
}

/// Outcome of an amplitude study.
#[derive(Debug, Clone)]
pub struct AmplitudeOutcome {
    /// One row per level, in the given order.
    pub rows: Vec<LevelFigures>,
    /// Plant FRF per level.
    pub plants: Vec<Frd>,
    /// Recommended range of levels \[% of i_sat\], if any level qualifies.
    pub recommended_pct: Option<(f64, f64)>,
    /// Why that range (or none) was recommended.
    pub reasoning: String,
}

/// Rules of the recommendation.
#[derive(Debug, Clone, Copy)]
pub struct Recommendation {
    /// Coherence counts as saturated above `min + coherence_fraction·(max − min)`.
    pub coherence_fraction: f64,
    /// Variance counts as near its minimum below `variance_factor · min`.
    pub variance_factor: f64,
}

impl Default for Recommendation {
    fn default() -> Self {
        Self {
            coherence_fraction: 0.9,
            variance_factor: 2.0,
        }
    }
}

/// The seed's amplitude levels: 2, 4, …, 16 % of i_sat.
pub fn seed_levels() -> Vec<f64> {
    (1..=8).map(|k| 0.02 * k as f64).collect()
}

/// The true plant response at given frequencies (twin runs).
pub type TruthFn<'a> = dyn Fn(&[f64]) -> Result<Vec<ambid_core::c64>> + 'a;

/// Analyses recorded experiments (one per level) and recommends a range.
pub fn amplitude_from_records(
    records: &[LevelRecord],
    fs: f64,
    y_noise: Option<&[f64]>,
    settings: &FrfSettings,
    truth: Option<&TruthFn<'_>>,
    rule: Recommendation,
) -> Result<AmplitudeOutcome> {
    if records.len() < 2 {
        return Err(Error::other(format!(
            "an amplitude study needs at least 2 levels, got {}",
            records.len()
        )));
    }
    // the levels' analyses are independent: in parallel, then used in level order (the first
    // failing level is the one reported, as in a sequential loop)
    let analyses: Vec<Result<FrfAnalysis>> = records
        .par_iter()
        .map(|rec| {
            let record = Record {
                r: &rec.r,
                u: &rec.u,
                y: &rec.y,
                i: rec.i.as_deref(),
                fs,
            };
            analyze(&record, settings, y_noise)
                .with_context(|| format!("level {:.1} %", 100.0 * rec.level))
        })
        .collect();
    let mut rows = Vec::with_capacity(records.len());
    let mut plants = Vec::with_capacity(records.len());
    for (rec, a) in records.iter().zip(analyses) {
        let a = a?;
        let err = match truth {
            Some(t) => {
                let tv = t(a.frf.f_hz())?;
                let mut e: Vec<f64> = a
                    .frf
                    .plant
                    .values()
                    .iter()
                    .zip(&tv)
                    .map(|(x, t)| (x - t).norm() / t.norm())
                    .collect();
                e.sort_by(|a, b| a.total_cmp(b));
                Some(e[e.len() / 2])
            }
            None => None,
        };
        rows.push(LevelFigures {
            level_pct: 100.0 * rec.level,
            mean_coh_ry: a.quality.mean_coherence_ry,
            mean_coh_ru: a.quality.mean_coherence_ru,
            mean_plant_var: a.quality.mean_plant_variance,
            mean_plant_rel_var: a.quality.mean_plant_rel_variance,
            snr_db: a.quality.output_snr_db,
            saturated_fraction: rec.saturated_fraction.unwrap_or(0.0),
            plant_median_rel_err: err,
        });
        plants.push(a.frf.plant);
    }
    let (recommended_pct, reasoning) = recommend(&rows, rule);
    Ok(AmplitudeOutcome {
        rows,
        plants,
        recommended_pct,
        reasoning,
    })
}

fn recommend(rows: &[LevelFigures], rule: Recommendation) -> (Option<(f64, f64)>, String) {
    let cmin = rows
        .iter()
        .map(|r| r.mean_coh_ry)
        .fold(f64::INFINITY, f64::min);
    let cmax = rows
        .iter()
        .map(|r| r.mean_coh_ry)
        .fold(f64::NEG_INFINITY, f64::max);
    let vmin = rows
        .iter()
        .map(|r| r.mean_plant_var)
        .fold(f64::INFINITY, f64::min);
    let c_thr = cmin + rule.coherence_fraction * (cmax - cmin);
    let v_thr = rule.variance_factor * vmin;
    let ok: Vec<&LevelFigures> = rows
        .iter()
        .filter(|r| {
            r.mean_coh_ry >= c_thr && r.mean_plant_var <= v_thr && r.saturated_fraction == 0.0
        })
        .collect();
    let why = format!(
        "levels whose average coherence γ²_ry ≥ {c_thr:.4} ({:.0} % of its rise from {cmin:.4} to {cmax:.4}), \
         whose average FRF variance ≤ {:.1}× its minimum ({vmin:.3e}) and that never saturated",
        100.0 * rule.coherence_fraction,
        rule.variance_factor
    );
    if ok.is_empty() {
        (None, format!("no level qualifies: none of the {why}"))
    } else {
        let lo = ok.iter().map(|r| r.level_pct).fold(f64::INFINITY, f64::min);
        let hi = ok
            .iter()
            .map(|r| r.level_pct)
            .fold(f64::NEG_INFINITY, f64::max);
        (Some((lo, hi)), format!("recommended: the {why}"))
    }
}

/// An amplitude study on the twin.
#[derive(Debug, Clone)]
pub struct TwinAmplitudeStudy {
    /// Twin parameters.
    pub twin: TwinConfig,
    /// Excitation template (its level is replaced by each of `levels`).
    pub excitation: ExcitationPlan,
    /// Levels as fractions of i_sat.
    pub levels: Vec<f64>,
    /// Simulation mode (the study is meant for the nonlinear twin).
    pub mode: Mode,
    /// Base noise seed (level j uses `seed + j`, the noise-only record `seed + 1000`).
    pub seed: u64,
    /// Leading periods skipped.
    pub skip_periods: usize,
    /// Band of the FRF and of the averages \[Hz\]; `None`: both derived from the excitation
    /// (`ambid_core::frf::band`). Default: the seed paper's study band 10–1000 Hz, because the
    /// study compares averages over one band across levels and the excitation's band (to ≈ 3 kHz
    /// for the seed PRBS) holds lines where the plant is below the noise at every level, whose
    /// variance then dominates the averages (no level qualifies). Records from files default to
    /// the derived band (`ambid study amplitude --files`, the workflow).
    pub band: Option<(f64, f64)>,
    /// Sensor noise on (off: no noise-only record, no SNR).
    pub noise: bool,
}

impl Default for TwinAmplitudeStudy {
    fn default() -> Self {
        Self {
            twin: TwinConfig::default(),
            excitation: ExcitationPlan::default(),
            levels: seed_levels(),
            mode: Mode::Nonlinear,
            seed: 1,
            skip_periods: 1,
            band: Some(ambid_core::frf::quality::DEFAULT_BAND),
            noise: true,
        }
    }
}

/// Runs the amplitude study on the twin (one experiment per level plus one without excitation
/// for the output SNR).
pub fn amplitude_on_twin(study: &TwinAmplitudeStudy) -> Result<AmplitudeOutcome> {
    if study.excitation.kind == ExcitationKind::None {
        return Err(Error::other(
            "the amplitude study needs an excitation (prbs, chirp, noise or multisine)",
        ));
    }
    // one experiment per level (seed + j) and the noise record (seed + 1000), all independent:
    // simulated in lock-step lanes and in parallel (`run_batch`, each exactly its lone run),
    // then used in level order
    let mut exps: Vec<Experiment> = study
        .levels
        .iter()
        .enumerate()
        .map(|(j, &level)| Experiment {
            twin: study.twin.clone(),
            excitation: ExcitationPlan {
                amplitude_frac: level,
                ..study.excitation.clone()
            },
            mode: study.mode,
            seed: study.seed + j as u64,
            noise: study.noise,
            record_b: false,
        })
        .collect();
    if study.noise {
        exps.push(Experiment {
            twin: study.twin.clone(),
            excitation: ExcitationPlan {
                kind: ExcitationKind::None,
                ..study.excitation.clone()
            },
            mode: study.mode,
            seed: study.seed + 1000,
            noise: true,
            record_b: false,
        });
    }
    let mut outs: Vec<Result<ExperimentOutput>> = run_batch(&exps)
        .into_iter()
        .enumerate()
        .map(|(j, out)| match study.levels.get(j) {
            Some(level) => out.with_context(|| format!("level {:.1} %", 100.0 * level)),
            None => out,
        })
        .collect();
    let noise = if study.noise { outs.pop() } else { None };
    let mut records = Vec::with_capacity(study.levels.len());
    let mut twin = None;
    let (mut period, mut samples) = (0, 0);
    for (out, &level) in outs.into_iter().zip(&study.levels) {
        let out = out?;
        period = out.excitation.period_samples;
        samples = out.record.r.len();
        records.push(LevelRecord {
            level,
            r: out.record.r,
            u: out.record.u,
            y: out.record.y,
            i: Some(out.record.i),
            saturated_fraction: Some(out.record.meta.saturated_fraction),
        });
        twin = Some(out.twin);
    }
    let noise = noise.transpose()?;
    let twin = twin.ok_or_else(|| Error::other("no level given"))?;
    // the identification's estimator: period averaging, or Welch for a noise excitation
    let mut settings = FrfSettings::for_record(Some(period), samples, study.skip_periods, None);
    settings.band = study.band;
    settings.quality_band = study.band;
    settings.i_sat = Some(twin.i_sat());
    let truth = |f: &[f64]| -> Result<Vec<ambid_core::c64>> { Ok(twin.plant_frf(f)?) };
    amplitude_from_records(
        &records,
        twin.fs(),
        noise.as_ref().map(|n| n.record.y.as_slice()),
        &settings,
        Some(&truth),
        Recommendation::default(),
    )
}

/// One operating point of the operating-point study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OperatingCase {
    /// Label, e.g. `bias-20%`.
    pub name: String,
    /// Bias current \[A\].
    pub bias_current_a: f64,
    /// Air gap \[m\].
    pub air_gap_m: f64,
}

/// The seed's cases around a nominal operating point: nominal, bias ±20 %, gap ±10 µm.
pub fn seed_cases(nominal: &TwinConfig) -> Vec<OperatingCase> {
    let (i0, g0) = (
        nominal.operating_point.bias_current_a,
        nominal.operating_point.air_gap_m,
    );
    let case = |name: &str, i: f64, g: f64| OperatingCase {
        name: name.into(),
        bias_current_a: i,
        air_gap_m: g,
    };
    vec![
        case("nominal", i0, g0),
        case("bias-20%", 0.8 * i0, g0),
        case("bias+20%", 1.2 * i0, g0),
        case("gap-10um", i0, g0 - 10e-6),
        case("gap+10um", i0, g0 + 10e-6),
    ]
}

/// The bands of the deviation summary \[Hz\], derived from the **nominal** plant estimate (no
/// rig's numbers): `low` from the first line to the corner $f_c$ where $|P|$ has fallen 6 dB below
/// its low-frequency level (the median of the lowest 5 % of the lines: where the plant's flat,
/// stiffness-like part, $\approx k_i/k_x$ for a single unstable mass, gives way to the mass line;
/// changes of $k_i$ and $k_x$ show below it), `resonance` from $f_c$ to 1.2 × the highest resonance peak found on the
/// lines known to ±10 % ([`ambid_core::frf::resonance::find_resonances_reliable`]), `high` from
/// there to the last line. Without a peak the resonance region is dropped (`low` and `high`);
/// without a 6 dB fall, one band `all`.
pub fn deviation_bands(nominal: &Frd) -> Vec<(String, f64, f64)> {
    use ambid_core::frf::resonance::{find_resonances_reliable, ResonanceOptions};
    let (f, g) = (nominal.f_hz(), nominal.values());
    let (Some(&f0), Some(&f1)) = (f.first(), f.last()) else {
        return Vec::new();
    };
    let n_low = (f.len() / 20).max(1);
    let low_level = median(g[..n_low].iter().map(|v| v.norm()).collect());
    let corner = (0..f.len())
        .find(|&k| g[k].norm() <= 0.5 * low_level)
        .map(|k| f[k]);
    let top_peak = find_resonances_reliable(nominal, &ResonanceOptions::default(), 0.1)
        .ok()
        .and_then(|(peaks, _)| {
            peaks
                .iter()
                .map(|p| p.f_hz)
                .filter(|&fp| corner.is_none_or(|c| fp > c))
                .fold(None, |m: Option<f64>, x| Some(m.map_or(x, |m| m.max(x))))
        });
    let Some(fc) = corner else {
        return vec![("all".into(), f0, f1)];
    };
    let mut bands = vec![("low".to_string(), f0, fc)];
    match top_peak.map(|p| (1.2 * p).min(f1)) {
        Some(fh) if fh > fc => {
            bands.push(("resonance".into(), fc, fh));
            if fh < f1 {
                bands.push(("high".into(), fh, f1));
            }
        }
        _ => bands.push(("high".into(), fc, f1)),
    }
    bands
}

/// Deviation of one case's plant FRF from the nominal one in one band.
#[derive(Debug, Clone, Serialize)]
pub struct BandDeviation {
    /// Case label.
    pub case: String,
    /// Band label.
    pub band: String,
    /// Band limits \[Hz\].
    pub f_min_hz: f64,
    /// Band limits \[Hz\].
    pub f_max_hz: f64,
    /// Median of |P − P_nom| / |P_nom| over the band's lines.
    pub median_rel_dev: f64,
    /// Largest |20 log10(|P|/|P_nom|)| in the band \[dB\].
    pub max_abs_db_dev: f64,
    /// Largest phase difference in the band \[deg\].
    pub max_abs_phase_dev_deg: f64,
    /// Median relative deviation of the case's *true* plant from the nominal true plant (twin).
    pub truth_median_rel_dev: Option<f64>,
}

/// Outcome of an operating-point study.
#[derive(Debug, Clone)]
pub struct OperatingPointOutcome {
    /// The cases, nominal first.
    pub cases: Vec<OperatingCase>,
    /// Plant FRF per case (common grid).
    pub plants: Vec<Frd>,
    /// Deviation from nominal per case and band (nominal excluded).
    pub deviations: Vec<BandDeviation>,
    /// Median relative error of each case's estimate against its own truth.
    pub truth_errors: Vec<f64>,
}

/// Deviation of every case's plant FRF from the first (nominal) one per band of
/// [`deviation_bands`] (of the nominal estimate): median relative deviation, largest magnitude (dB) and phase deviation, and,
/// with `truths` (one response per case on the same lines), the same median for the truths.
///
/// # Errors
/// Fewer than two cases, cases on different frequency lines, or `truths` of the wrong shape.
pub fn band_deviations(
    names: &[String],
    plants: &[Frd],
    truths: Option<&[Vec<ambid_core::c64>]>,
) -> Result<Vec<BandDeviation>> {
    if plants.len() < 2 || names.len() != plants.len() {
        return Err(Error::other("an operating-point comparison needs the nominal case and at least one other, each named"));
    }
    let nom = &plants[0];
    let f = nom.f_hz();
    for (n, p) in names.iter().zip(plants) {
        if p.f_hz() != f {
            return Err(Error::other(format!(
                "operating point `{n}` has other frequency lines than nominal; use the same excitation \
                 (and period) for every case"
            )));
        }
    }
    if let Some(t) = truths {
        if t.len() != plants.len() || t.iter().any(|v| v.len() != f.len()) {
            return Err(Error::other(
                "one true response per case, on the plants' lines, is needed",
            ));
        }
    }
    let mut deviations = Vec::new();
    let bands = deviation_bands(nom);
    for (j, name) in names.iter().enumerate().skip(1) {
        for (bname, lo, hi) in &bands {
            let (lo, hi) = (*lo, *hi);
            let idx: Vec<usize> = (0..f.len()).filter(|&k| f[k] >= lo && f[k] <= hi).collect();
            if idx.is_empty() {
                continue;
            }
            let p = plants[j].values();
            let pn = nom.values();
            let rel = idx
                .iter()
                .map(|&k| (p[k] - pn[k]).norm() / pn[k].norm())
                .collect();
            let db = idx
                .iter()
                .map(|&k| (20.0 * (p[k].norm() / pn[k].norm()).log10()).abs())
                .fold(0.0, f64::max);
            let ph = idx
                .iter()
                .map(|&k| (p[k] / pn[k]).arg().to_degrees().abs())
                .fold(0.0, f64::max);
            let trel = truths.map(|t| {
                median(
                    idx.iter()
                        .map(|&k| (t[j][k] - t[0][k]).norm() / t[0][k].norm())
                        .collect(),
                )
            });
            deviations.push(BandDeviation {
                case: name.clone(),
                band: bname.clone(),
                f_min_hz: lo,
                f_max_hz: hi,
                median_rel_dev: median(rel),
                max_abs_db_dev: db,
                max_abs_phase_dev_deg: ph,
                truth_median_rel_dev: trel,
            });
        }
    }
    Ok(deviations)
}

/// The operating-point study on recorded experiments, one per case (the first is nominal): the
/// plant FRF of each by [`analyze`] with `settings`, and their deviations from nominal
/// ([`band_deviations`]). The cases' bias current and air gap are not known from files: they are
/// NaN in the outcome, and `truth_errors` is empty.
///
/// # Errors
/// Fewer than two records, and the errors of [`analyze`] and [`band_deviations`].
pub fn operating_point_from_records(
    names: &[String],
    records: &[Record<'_>],
    settings: &FrfSettings,
) -> Result<OperatingPointOutcome> {
    if records.len() < 2 || names.len() != records.len() {
        return Err(Error::computation(
            "an operating-point study needs the nominal record and at least one other, each named",
        ));
    }
    // independent analyses: in parallel, then used in record order
    let analyses: Vec<Result<FrfAnalysis>> = names
        .par_iter()
        .zip(records)
        .map(|(n, r)| analyze(r, settings, None).with_context(|| format!("operating point `{n}`")))
        .collect();
    let mut plants = Vec::with_capacity(records.len());
    for a in analyses {
        plants.push(a?.frf.plant);
    }
    let deviations = band_deviations(names, &plants, None)?;
    Ok(OperatingPointOutcome {
        cases: names
            .iter()
            .map(|n| OperatingCase {
                name: n.clone(),
                bias_current_a: f64::NAN,
                air_gap_m: f64::NAN,
            })
            .collect(),
        plants,
        deviations,
        truth_errors: Vec::new(),
    })
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// Runs the seed experiment at each operating point on the twin and compares with nominal; the
/// FRF band `band`, or (`None`) the one derived from the excitation.
pub fn operating_point_on_twin(
    nominal: &TwinConfig,
    cases: &[OperatingCase],
    excitation: &ExcitationPlan,
    mode: Mode,
    seed: u64,
    skip_periods: usize,
    band: Option<(f64, f64)>,
) -> Result<OperatingPointOutcome> {
    if cases.len() < 2 {
        return Err(Error::other(
            "an operating-point study needs the nominal case and at least one other",
        ));
    }
    // the cases are independent experiments (seed + j): simulated in lock-step lanes and in
    // parallel (`run_batch`, each exactly its lone run), analysed in parallel, then checked and
    // used in case order (the first failing case is the one reported, as in a sequential loop)
    let exps: Vec<Experiment> = cases
        .iter()
        .enumerate()
        .map(|(j, case)| {
            let mut cfg = nominal.clone();
            cfg.operating_point.bias_current_a = case.bias_current_a;
            cfg.operating_point.air_gap_m = case.air_gap_m;
            Experiment {
                twin: cfg,
                excitation: excitation.clone(),
                mode,
                seed: seed + j as u64,
                noise: true,
                record_b: false,
            }
        })
        .collect();
    let per_case: Vec<Result<(Frd, Vec<ambid_core::c64>, f64)>> = cases
        .par_iter()
        .zip(run_batch(&exps))
        .map(|(case, out)| {
            let out = out.with_context(|| format!("operating point `{}`", case.name))?;
            let mut settings = FrfSettings::for_record(
                Some(out.excitation.period_samples),
                out.record.r.len(),
                skip_periods,
                None,
            );
            settings.band = band;
            settings.quality_band = band;
            settings.i_sat = Some(out.twin.i_sat());
            let rec = &out.record;
            let record = Record {
                r: &rec.r,
                u: &rec.u,
                y: &rec.y,
                i: Some(&rec.i),
                fs: out.twin.fs(),
            };
            let a = analyze(&record, &settings, None)
                .with_context(|| format!("operating point `{}`", case.name))?;
            let truth = out.twin.plant_frf(a.frf.f_hz())?;
            let truth_error = median(
                a.frf
                    .plant
                    .values()
                    .iter()
                    .zip(&truth)
                    .map(|(x, t)| (x - t).norm() / t.norm())
                    .collect(),
            );
            Ok((a.frf.plant, truth, truth_error))
        })
        .collect();
    let mut plants: Vec<Frd> = Vec::with_capacity(cases.len());
    let mut truths = Vec::with_capacity(cases.len());
    let mut truth_errors = Vec::with_capacity(cases.len());
    for (case, item) in cases.iter().zip(per_case) {
        let (plant, truth, truth_error) = item?;
        if let Some(first) = plants.first() {
            if first.f_hz() != plant.f_hz() {
                return Err(Error::other(format!(
                    "operating point `{}` gave a different frequency grid from nominal; use the same \
                     excitation for every case",
                    case.name
                )));
            }
        }
        truth_errors.push(truth_error);
        plants.push(plant);
        truths.push(truth);
    }
    let names: Vec<String> = cases.iter().map(|c| c.name.clone()).collect();
    let deviations = band_deviations(&names, &plants, Some(&truths))?;
    Ok(OperatingPointOutcome {
        cases: cases.to_vec(),
        plants,
        deviations,
        truth_errors,
    })
}
