//! The whole machine's parametric models ([`FrequencyFitter`], the default [`MachineModels`] of
//! `ambid run` with `[machine]`): per speed, MIMO state-space models of the 4×4 plant fitted to
//! the measured matrix FRF ([`ambid_core::estimate::freqfit_mimo`]: frequency-domain subspace,
//! then weighted nonlinear least squares on all 16 entries with inverse-variance weights, never
//! stabilised) over a scan of orders; the comparison table; the chosen model's closed-loop
//! validation with the controllers, its σ̄(S) and per-axis ISO 14839-3 zones; the closed-loop
//! modes with their whirl direction (the Campbell diagram's measured points); and across speeds
//! the speed-scheduled model ([`ambid_core::estimate::scheduled`]) whose modes on a dense speed
//! grid are the Campbell diagram's curves.
//!
//! # Rules (docs/workflow.md, "Whole machine: models")
//! * **Band.** The lines where the measured plant is precise: the relative standard deviation
//!   $\sqrt{\sum_{ij}\sigma^2_{ij}} / \lVert \hat P \rVert_F \le 0.102$ (a 95 % interval within
//!   ±20 %, the rule of the single-axis `fit frf.csv`), from the first to the last run of three
//!   such lines, clipped to the quality band (`[machine] quality_band_hz`, default 10–1000 Hz).
//! * **Orders.** Every order of the candidate list (default 16, 20, 24: the twin's 4×4 plant at
//!   20 kHz has 24 states — the rigid-body and bending modes of both planes (12), and per axis
//!   the amplifier, the sensor and the computation delay (4 × 3). In 10–1000 Hz the 12
//!   mechanical states and the four amplifier poles carry a model to 0.2–0.8 % on the nominal
//!   rig and random rigs 1 and 2, where the noise hides the rest; on a quieter record (random
//!   rig 3) the sensor and delay lag is above the noise and order 16 stays at 6.5 %, 20 reaches
//!   1.1 % — hence the span up to the full 24, with BIC to choose.
//!   The orders are fitted in increasing order, and the scan ends at the first admissible
//!   candidate (below) whose weighted cost is at the noise level, $2V/\nu \le 1 + 2.326
//!   \sqrt{2/\nu}$ with $\nu = 2Ln_yn_u - n_\theta$ ([`at_noise_level`]: the one-sided 99 %
//!   point of $\chi^2_\nu/\nu$, which $2V/\nu$ follows when the model holds the plant and the
//!   inverse-variance weights are right). A higher order could then lower $2V$ by about one
//!   unit per added parameter (the noise it fits), while BIC charges $\ln 2Ln_yn_u \approx 9$:
//!   BIC would not choose it, and fitting it only costs time. A report note names the orders
//!   left out. When no candidate reaches the noise level every order is fitted and BIC
//!   chooses, as before. The lowest order is fitted first and alone, held to the noise level
//!   ([`CostTarget::NoiseLevel`]): its refinement is abandoned once the race rule of the fit
//!   says that it cannot end there (on the nominal nonlinear twin, order 16 would otherwise
//!   crawl for 200 steps, 1.2 s of CPU, towards a BIC seven times the chosen one). The other
//!   orders are then fitted side by side, and the lowest one is resumed from its probed
//!   starts ([`ss_frd_mimo_in_loop_resumed`]: the same refinements as without the level),
//!   raced against the lowest BIC of the admissible others ([`CostTarget::Bic`]; to its end
//!   when no other is admissible). Where it cannot reach that either, it stays abandoned (its
//!   row says so, and it is not admissible, so never chosen); else it ends as the full scan's
//!   fit of that order, to the bit. So the table differs from the full scan's only in
//!   abandoned rows, and the choice only where the race's optimistic predictions (the
//!   Gauss–Newton step's and the pace of the last steps) both fail
//!   (`the_noise_level_stop_chooses_what_the_full_scan_chooses`: nominal linear twin seeds
//!   1–2, random rigs 1–3 and the nominal nonlinear twin at 15 000 rpm). The test is only as good as the variances: too small ones (few
//!   periods) keep $2V/\nu$ above the bound and the scan goes on (time lost, choice as
//!   before); too large ones let a model that is not at the noise level pass. `models =
//!   "fit-all"` ([`FrequencyFitter::stop_at_noise_level`] `false`) fits every order.
//! * **One scan for all speeds.** With several speeds the scan above runs at the *reference
//!   speed*, the middle one of the list (the speed-scheduled model takes its order from there
//!   too), and every other speed fits only the order it chose
//!   ([`FrequencyFitter::order_from_reference_speed`]). The plant has the same states at every
//!   speed — the gyroscopic terms move the modes, they add none — and the noise level that
//!   decides how many of them a record shows is a property of the experiment design, the same
//!   at every speed. Each other speed is fitted from its inner neighbour's chosen model
//!   ([`ss_frd_mimo_in_loop_from`]; outwards from the reference, the speeds below and above it
//!   side by side): the modes move little from one speed to the next, so the refinement is
//!   short and the models of the sequence stay in one basin. Where that fit is not admissible
//!   the order is fitted from scratch (the vector-fitting starts), and where no fit of the
//!   order is admissible the remaining orders are scanned there (notes say so). Measured on
//!   2026-11-29 (`ambid run` with `[machine] models = "fit"`, nominal twin, 0/15 000/30 000 rpm,
//!   seed 1): from scratch, the 30 000 rpm fit ended in a poor local minimum (linear twin:
//!   $2V/\nu = 10.3$, plant error 6.0 %; nonlinear: 5.7, 4.5 %), from the neighbour's model it
//!   reached 0.98 and 0.22 % (nonlinear: 1.53, 0.73 %) in a third of the time; at 0 rpm both
//!   ways were alike (linear 0.20 % against 0.18 %; nonlinear 0.86 % against 0.53 %).
//!   `models = "fit-all"` scans every order at every speed, each from scratch.
//! * **Side by side.** What does not depend on each other overlaps (each computation is the
//!   one of a sequential run, so the numbers do not depend on the thread count): the reference
//!   speed's validation runs beside the other speeds' fits; the other speeds' validations
//!   beside the speed-scheduled model; within a validation the model's closed-loop simulation
//!   beside the true plant's (on the twin, whose displacement fits alone are computed:
//!   `machine_output_fits`). On the default nonlinear twin this took the fitted workflow from
//!   13.3–15.3 s to 11.1–12.2 s wall (docs/benchmarks.md, 2026-11-30).
//! * **Loop.** With the controllers known (the twin), every fit is held to models whose loop
//!   with them is stable ([`ss_frd_mimo_in_loop`]): the measured loop was stable, and an
//!   unconstrained fit puts spurious fast unstable poles outside the band.
//! * **Out of band.** The lines above the fitted band are data the fit did not use. With the
//!   controllers and the measured $\hat T_{ry}$ known, each candidate's closed loop is checked
//!   against them: the misfit $X$, the mean over those lines of
//!   $\frac{1}{n_y n_u}\sum_{ij} |T_{ry,ij}^{\text{model}} - \hat T_{ry,ij}|^2/\sigma^2_{ij}$, is
//!   1 for the true plant (noise only) and grows with the model's error there;
//!   $X \le$ [`MAX_OUT_OF_BAND_MISFIT`] $= 5$ (the model's closed-loop error above the band has
//!   an RMS of at most 2σ of the measurement) is required. It rejects the spurious, nearly
//!   undamped closed-loop modes a fit can place above its band (on the twin, seed 1, with the
//!   former rank-one starts, order 22: a mode at 4.4 kHz with ζ = 10⁻⁴, $X = 570$, which ruined
//!   the closed-loop simulation while the plant error in the band was 0.7 %). It sees only
//!   errors far outside the measurement's noise: $\hat T_{ry}$ above the band is noisy (relative
//!   σ near 80 % at 2.5 kHz on that record) and $X$ averages over all lines above the band, so
//!   a broad 20 % plant error above 1.5 kHz leaves $X$ at 1.0 (measured, 2026-11-28).
//! * **Unstable poles.** With the controllers known, the measured loop itself says how many
//!   unstable poles the plant has: the generalised Nyquist count of $\det(I + \hat P C)$ over
//!   the FRF's lines ([`loop_unstable_poles`], when the lines support a count). A candidate
//!   with another number contradicts the measurement (its loop is stable, so its
//!   $\det(I + P C)$ winds differently from the measured one somewhere) and is not chosen.
//!   The fit itself is held to that count ([`ss_frd_mimo_in_loop`] uses it as its
//!   `max_unstable_poles`: the start's surplus unstable blocks are mirrored, the measured ones
//!   stay).
//!   On the twin the count is right on the nominal rig at 0/15 000/30 000 rpm and on random
//!   rigs 1–5 (`tests/machine_nyquist.rs`).
//! * **Choice.** Among the rows whose model gives a stable closed loop with the controllers,
//!   passes the out-of-band check and has the measured loop's unstable-pole count (when they
//!   can be made), the smallest BIC of the
//!   inverse-variance-weighted cost ($2V + n_\theta \ln 2 L n_y n_u$); without a valid row, no
//!   model is chosen and a note says why.
//! * **Whirl.** A closed-loop mode's eigenvector $v$ seen at the outputs, $y = C_{cl} v$, is split
//!   per bearing into its forward and backward circular parts
//!   $|y_x \mp j y_y|$ (the twin's rule, [`ambid_twin::Machine::closed_loop_pole_pairs`], with
//!   the sensors in place of the bearings); forward when the forward share exceeds one half, and
//!   planar at standstill.

use super::machine::{
    AxisValidationRow, ComparisonRow, IsoRow, LevelFrf, MachineModelInput, MachineModelOutput,
    MachineModels, ModePoint, SpeedMeasurement, SpeedModel, UncertaintyRow,
};
use crate::error::Error;
use ambid_core::data::{IoData, AXES};
use ambid_core::estimate::freqfit_mimo::{
    ss_frd_mimo, ss_frd_mimo_in_loop, ss_frd_mimo_in_loop_from, ss_frd_mimo_in_loop_resumed,
    CostTarget, MimoFreqFit, MimoFreqOptions,
};
use ambid_core::estimate::scheduled::{
    fit_scheduled, ScheduleOptions, SpeedData, SpeedScheduledModel,
};
use ambid_core::lti::{Frd, StateSpace};
use ambid_core::signal::{noise::Distribution, NoiseSpec};
use ambid_core::validate::machine::{
    machine_output_fits, validate_machine, MachineValidationOptions,
};
use ambid_core::validate::nyquist::loop_unstable_poles;
use ambid_twin::{c64, Machine, MachineConfig, MachineSimOptions, Whirl};
use rayon::prelude::*;

/// Relative standard deviation of a line below which it is precise enough to fit (a 95 %
/// interval within ±20 %).
pub const MAX_RELATIVE_STD: f64 = 0.102;

/// Largest admissible out-of-band misfit of a candidate's closed loop (module docs, "Out of
/// band"): an RMS error of 2σ of the measured $\hat T_{ry}$ on the lines above the fitted band.
pub const MAX_OUT_OF_BAND_MISFIT: f64 = 5.0;

/// Damping ratio below which a closed-loop mode enters the Campbell diagram (the twin's
/// `LIGHTLY_DAMPED`).
pub const CAMPBELL_DAMPING: f64 = ambid_twin::LIGHTLY_DAMPED;

/// Samples of the twin's independent validation record (0.3 s at 20 kHz).
pub const VALIDATION_SAMPLES: usize = 6000;

/// RMS of the white-noise excitation of the validation record on every axis \[A\].
pub const VALIDATION_RMS_A: f64 = 0.05;

/// The default [`MachineModels`]: MIMO state-space models fitted to the measured 4×4 FRF (module
/// docs).
#[derive(Debug, Clone, PartialEq)]
pub struct FrequencyFitter {
    /// Candidate orders (default 16, 20, 24).
    pub orders: Vec<usize>,
    /// Iteration limit of the nonlinear refinement (default 100).
    pub max_iterations: usize,
    /// Fit the orders in increasing order and stop at the first admissible one whose
    /// weighted cost is at the noise level ([`at_noise_level`]; module docs, "Orders"); with
    /// `false`, every order is fitted. Default `true`.
    pub stop_at_noise_level: bool,
    /// Scan the orders at the reference speed only (the middle one of the list) and fit its
    /// chosen order at the other speeds, scanning the rest only where that order gives no
    /// admissible model (module docs, "Orders"); with `false`, every speed scans every order.
    /// Default `true`.
    pub order_from_reference_speed: bool,
    /// The chosen model's uncertainty and robust stability per speed ([`speed_uncertainty`];
    /// `[machine] uncertainty`). Default `false`.
    pub uncertainty: bool,
}

impl Default for FrequencyFitter {
    fn default() -> Self {
        Self {
            orders: vec![16, 20, 24],
            max_iterations: 100,
            stop_at_noise_level: true,
            order_from_reference_speed: true,
            uncertainty: false,
        }
    }
}

/// The amplitude study of one speed for the uncertainty's term (e): the identification
/// experiment's level \[% of i_sat\] and the plant FRFs at the study's other levels.
#[derive(Debug, Clone, Copy)]
pub struct AmplitudeStudy<'a> {
    /// The identification experiment's peak level \[% of i_sat\].
    pub level_pct: f64,
    /// The study's levels (any order; those with a limit active on more than
    /// [`AMPLITUDE_MAX_SATURATED`](crate::uncertainty::AMPLITUDE_MAX_SATURATED) of the samples
    /// are left out).
    pub levels: &'a [LevelFrf],
}

/// The study's levels that saturate on at most
/// [`AMPLITUDE_MAX_SATURATED`](crate::uncertainty::AMPLITUDE_MAX_SATURATED) of the samples and
/// the identification FRF as `(level, FRF)` in
/// increasing level (levels as fractions), all on `plant`'s lines, and the levels used \[%\]
/// (the rules and errors of [`amplitude_terms`]).
#[allow(clippy::type_complexity)]
fn study_levels(
    plant: &Frd,
    study: &AmplitudeStudy<'_>,
) -> Result<(Vec<(f64, Frd)>, Vec<f64>), String> {
    let (Some(&lo), Some(&hi)) = (plant.f_hz().first(), plant.f_hz().last()) else {
        return Err("the FRF has no line".into());
    };
    let mut levels: Vec<(f64, Frd)> = Vec::with_capacity(study.levels.len() + 1);
    let mut saturated = Vec::new();
    for l in study.levels {
        if l.saturated_fraction > crate::uncertainty::AMPLITUDE_MAX_SATURATED {
            saturated.push(format!(
                "{} % ({:.2e} of the samples saturated)",
                l.level_pct, l.saturated_fraction
            ));
            continue;
        }
        let g = l.plant.band(lo, hi).map_err(|e| e.to_string())?;
        if g.f_hz() != plant.f_hz() {
            return Err(format!(
                "the FRF at {} % is on other lines than the identification FRF's",
                l.level_pct
            ));
        }
        levels.push((l.level_pct / 100.0, g));
    }
    levels.push((study.level_pct / 100.0, plant.clone()));
    levels.sort_by(|a, b| a.0.total_cmp(&b.0));
    let used: Vec<f64> = levels.iter().map(|l| 100.0 * l.0).collect();
    if levels.len() < 2 {
        return Err(format!(
            "only the identification level is left{}; term (e) needs a second level that saturates on at most {:.0} % of the samples — lower the study's levels",
            if saturated.is_empty() {
                String::new()
            } else {
                format!(" (left out: {})", saturated.join(", "))
            },
            100.0 * crate::uncertainty::AMPLITUDE_MAX_SATURATED
        ));
    }
    Ok((levels, used))
}

/// `f(i, j, levels' entries (i, j))` for every entry of `plant`'s shape, column-major (the
/// order of `MatrixUncertainty::entries`).
fn per_entry<T>(
    plant: &Frd,
    levels: &[(f64, Frd)],
    f: impl Fn(usize, usize, &[(f64, &Frd)]) -> Result<T, String>,
) -> Result<Vec<T>, String> {
    let (ny, nu) = (plant.ny(), plant.nu());
    let mut out = Vec::with_capacity(ny * nu);
    for j in 0..nu {
        for i in 0..ny {
            let at: Vec<(f64, Frd)> = levels
                .iter()
                .map(|(a, g)| g.entry(i, j).map(|e| (*a, e)))
                .collect::<Result<_, _>>()
                .map_err(|e| e.to_string())?;
            let refs: Vec<(f64, &Frd)> = at.iter().map(|(a, g)| (*a, g)).collect();
            out.push(f(i, j, &refs)?);
        }
    }
    Ok(out)
}

/// Term (e) of every entry of a MIMO model (`ambid::uncertainty::amplitude_term` entry by
/// entry, the SISO rule on the channel $(i, j)$): the model `model`'s entry against the
/// identification plant FRF's entry `plant` (the fit's lines, the term's lines) at
/// `study.level_pct` and the study's levels' entries on the same lines; levels with a limit
/// active on more than [`AMPLITUDE_MAX_SATURATED`](crate::uncertainty::AMPLITUDE_MAX_SATURATED)
/// of the samples are left out (a limit is not the smooth distortion the $a^2$ rule
/// extrapolates).
/// Returns the terms in the order of `MatrixUncertainty::entries` (column-major) and the levels
/// used \[%\], the identification level among them.
///
/// # Errors
/// The reason as text: fewer than two levels within that limit, FRFs on other lines, an entry
/// whose term cannot be computed (named).
pub fn amplitude_terms(
    model: &StateSpace,
    plant: &Frd,
    study: &AmplitudeStudy<'_>,
) -> Result<(Vec<Vec<f64>>, Vec<f64>), String> {
    let (terms, used) = amplitude_terms_and_shifts(model, plant, study)?;
    Ok((terms.into_iter().map(|t| t.term).collect(), used))
}

/// [`amplitude_terms`] with every entry's per-line shifts kept
/// (`ambid::uncertainty::amplitude_term_and_shifts`, on `plant`'s lines), for
/// `MatrixUncertainty::add_projected_shift`: one regression per entry for both.
///
/// # Errors
/// As [`amplitude_terms`].
pub fn amplitude_terms_and_shifts(
    model: &StateSpace,
    plant: &Frd,
    study: &AmplitudeStudy<'_>,
) -> Result<(Vec<crate::uncertainty::AmplitudeTerm>, Vec<f64>), String> {
    let (levels, used) = study_levels(plant, study)?;
    let line_coverage =
        ambid_core::validate::uncertainty::UncertaintyOptions::default().line_coverage;
    let terms = per_entry(plant, &levels, |i, j, refs| {
        let entry = model.entry(i, j).map_err(|e| e.to_string())?;
        crate::uncertainty::amplitude_term_and_shifts(
            refs,
            study.level_pct / 100.0,
            plant.f_hz(),
            &entry,
            line_coverage,
        )
        .map_err(|e| format!("entry (output {i}, input {j}): {e}"))
    })?;
    Ok((terms, used))
}

pub use crate::uncertainty::{COHERENT_CONFIDENCE, COHERENT_DRAWS};

/// The chosen model's uncertainty at one speed ([`UncertaintyRow`]): the element-wise bound of
/// `uncertainty_matrix` on the measured plant FRF's lines in the fit's band `band` and the
/// validation lines above it ([`uncertainty_band`]; the model's covariance from the fitted lines
/// alone, `UncertaintyOptions::fitted_band_hz`), raised by
/// [`MatrixUncertainty::joint_raises`](ambid_core::validate::uncertainty::MatrixUncertainty::joint_raises)
/// (98 % of the pairs in 95 % of 2 000 draws, seed 0; never lowered), and the robust stability of
/// `controller` against it on those lines; the structured weight (one relative weight of order
/// ≤ 4 per entry of the mode-shaped family, `MatrixUncertainty::entry_weights_shaped`, over the
/// bound raised for 95 % of the pairs on the same draws) and the
/// robust stability against it on
/// the dense grid (`MatrixWeight::EntryRelative`), kept with the bound for export; with the
/// twin's exact model `truth`, its gain interval and the coverage of σ̄(P − P̂) on the lines in
/// 10–1000 Hz by the bound and by the weights. With an amplitude study `amplitude`, every
/// entry's bound has term (e) ([`amplitude_terms`]); when it cannot be computed the row says
/// why and the bound goes on without it. Beside them, the robust gain margins against
/// [`COHERENT_DRAWS`] coherent draws of the model's error at [`COHERENT_CONFIDENCE`]
/// (`robust_stability_matrix_drawn`), with the structured weight bounding the error outside the
/// lines, where the draws know nothing.
///
/// # Errors
/// The reason as text (the FRF has no variance on a line, the model is singular on a line, …).
pub fn speed_uncertainty(
    speed_rpm: f64,
    plant: &Frd,
    band: (f64, f64),
    model: &StateSpace,
    controller: &StateSpace,
    truth: Option<&StateSpace>,
    amplitude: Option<&AmplitudeStudy<'_>>,
) -> Result<UncertaintyRow, String> {
    use ambid_core::validate::robust::{
        nominal_gain_interval, robust_stability_matrix_drawn, robust_stability_matrix_on_lines,
        robust_stability_matrix_weight, LineBound, MatrixWeight,
    };
    use ambid_core::validate::uncertainty::{
        uncertainty_matrix, EntryForm, ExtraTerms, UncertaintyOptions, DEFAULT_RAISE_COVER,
    };
    use ambid_core::validate::weight::{Weight, WeightShape, DEFAULT_COVER, MAX_WEIGHT_ORDER};
    let err = |e: ambid_core::Error| e.to_string();
    // the bound's lines: the fit band and the validation lines above it (docs/uncertainty.md,
    // "Lines beyond the fit band")
    let bound_band = uncertainty_band(plant, band).map_err(|e| e.to_string())?;
    let frd = plant.band(bound_band.0, bound_band.1).map_err(err)?;
    let opts = UncertaintyOptions {
        fitted_band_hz: (bound_band.1 > band.1).then_some([band.0, band.1]),
        ..UncertaintyOptions::default()
    };
    let (amp, mut amplitude_note) =
        match amplitude.map(|a| amplitude_terms_and_shifts(model, &frd, a)) {
            None => (None, None),
            Some(Ok(t)) => (Some(t), None),
            Some(Err(e)) => (None, Some(format!("term (e) left out: {e}"))),
        };
    let extra: Vec<ExtraTerms<'_>> = amp.as_ref().map_or_else(Vec::new, |(t, _)| {
        t.iter()
            .map(|e| ExtraTerms {
                amplitude_shift: Some(e.term.as_slice()),
                ..ExtraTerms::default()
            })
            .collect()
    });
    let mut u = uncertainty_matrix(model, &frd, &extra, &opts).map_err(err)?;
    // term (e) through the model: the per-line shifts projected onto the model's tangent space
    // (docs/uncertainty.md, "Term (e) through the model")
    // (when it cannot be computed the bound keeps the line term, and the row says why)
    let amplitude_projected = match &amp {
        Some((t, _)) => {
            let shifts: Vec<Vec<c64>> = t.iter().map(|e| e.shift.clone()).collect();
            let vars: Vec<Vec<f64>> = t.iter().map(|e| e.shift_var.clone()).collect();
            let projected = u
                .add_projected_shift(
                    &frd,
                    &shifts,
                    &vars,
                    crate::uncertainty::AMPLITUDE_RUN_ALPHA,
                )
                .map_err(err);
            match projected {
                Ok(p) => Some(p),
                Err(e) => {
                    amplitude_note = Some(format!("term (e) through the model left out: {e}"));
                    None
                }
            }
        }
        _ => None,
    };
    // two raises on the same draws (docs/uncertainty.md, "Two raises for the machine"): the
    // bound on the lines, its check and its export claim ‖L‖₂ ≥ σ̄(P − P̂), so they cover 98 %
    // of the (line, entry) pairs; the entry weights answer the coverage bar's 95 % of the
    // lines, so the bound they are fitted to covers 95 % of the pairs (on nonlinear machine
    // rigs 1–100 their half-margin bar 60 → 65, coverage 100/100 kept)
    let raises = u
        .joint_raises(&[DEFAULT_COVER, DEFAULT_RAISE_COVER], 0.95, 2000, 0)
        .map_err(err)?;
    let (raise, weight_raise) = (raises[0].max(1.0), raises[1].max(1.0));
    let for_weights = u.scaled(weight_raise).map_err(err)?;
    let u = u.scaled(raise).map_err(err)?;
    let f = u.f_hz().to_vec();
    let norm = u.norm_bound();
    let top = |m: &faer::Mat<c64>| {
        m.singular_values()
            .ok()
            .and_then(|v| v.into_iter().reduce(f64::max))
            .unwrap_or(f64::NAN)
    };
    let mut rel: Vec<f64> = (0..f.len())
        .map(|k| norm[k] / top(&u.nominal_at(k)))
        .collect();
    rel.sort_by(f64::total_cmp);
    // term (e)'s size (after the projection): the median over the lines of σ̄(|E|) / σ̄(P̂)
    let amplitude_median_rel_pct = amp.as_ref().map(|_| {
        let ny = model.noutputs();
        let t: Vec<&[f64]> = u
            .entries
            .iter()
            .map(|e| e.amplitude.as_deref().unwrap_or(&[]))
            .collect();
        let mut r: Vec<f64> = (0..f.len())
            .map(|k| {
                let e = faer::Mat::from_fn(ny, t.len() / ny, |i, j| {
                    t[i + j * ny].get(k).copied().unwrap_or(0.0)
                });
                ambid_core::linalg::singular_values(e.as_ref())
                    .ok()
                    .and_then(|v| v.into_iter().reduce(f64::max))
                    .unwrap_or(f64::NAN)
                    / top(&u.nominal_at(k))
            })
            .collect();
        r.sort_by(f64::total_cmp);
        100.0 * r.get(r.len() / 2).copied().unwrap_or(f64::NAN)
    });
    let bounds = u.bounds();
    let ts = model
        .ts()
        .ok_or_else(|| "the model must be discrete-time".to_string())?;
    // the coherent draws: the model's error as whole matrices (the entries' phases and their
    // correlation kept), only the part of unknown phase taken element-wise at its worst
    // (docs/uncertainty.md, "Coherent draws for the machine")
    let drawn = u.coherent_draws(COHERENT_DRAWS, 0).map_err(err)?;
    // the line test and the structured weight's fit are independent: side by side
    let (r, weights) = rayon::join(
        || robust_stability_matrix_on_lines(model, controller, &f, LineBound::Elementwise(&bounds)),
        // the mode-shaped family: on machine rigs 1–100 (each its own noise) it kept the
        // coverage (100/100) and raised the rigs whose weight margins are ≥ half the exact ones
        // from 54 to 74 (docs/uncertainty.md, "Mode-shaped entry weights")
        || {
            for_weights.entry_weights_shaped(
                ts,
                MAX_WEIGHT_ORDER,
                DEFAULT_COVER,
                EntryForm::Relative,
                WeightShape::ModeShaped,
            )
        },
    );
    let (r, weights) = (r.map_err(err)?, weights.map_err(err)?);
    let ws: Vec<Weight> = weights.iter().map(|w| w.weight.clone()).collect();
    // the draws know nothing outside the lines: there the entry weights bound the error (their
    // extrapolation; docs/uncertainty.md, "Coherent draws for the machine")
    let rc = robust_stability_matrix_drawn(
        model,
        controller,
        &drawn.f_hz,
        &drawn.draws,
        &drawn.remainder,
        Some(MatrixWeight::EntryRelative(&ws)),
        COHERENT_CONFIDENCE,
    )
    .map_err(err)?;
    let rw = robust_stability_matrix_weight(model, controller, MatrixWeight::EntryRelative(&ws))
        .map_err(err)?;
    let wmag: Vec<Vec<f64>> = ws.iter().map(|w| w.magnitude(&f)).collect();
    let ny = model.noutputs();
    let weight_norm = |k: usize| {
        let ph = u.nominal_at(k);
        let b = faer::Mat::from_fn(ph.nrows(), ph.ncols(), |i, j| {
            ph[(i, j)].norm() * wmag[i + j * ny][k]
        });
        ambid_core::linalg::singular_values(b.as_ref())
            .ok()
            .and_then(|v| v.into_iter().reduce(f64::max))
            .unwrap_or(f64::NAN)
    };
    let mut loose: Vec<f64> = weights.iter().map(|w| w.looseness).collect();
    loose.sort_by(f64::total_cmp);
    let (exact_gain_margins, truth_coverage, weight_truth_coverage) = match truth {
        Some(t) => {
            let (lo, hi) = nominal_gain_interval(t, controller).map_err(err)?;
            let exact = Frd::from_model(t, &f).map_err(err)?;
            let (mut n, mut ok, mut ok_w) = (0usize, 0usize, 0usize);
            for (k, fk) in f.iter().enumerate() {
                if !(10.0..=1000.0).contains(fk) {
                    continue;
                }
                let (p, ph) = (exact.at(k).map_err(err)?, u.nominal_at(k));
                let d = faer::Mat::from_fn(p.nrows(), p.ncols(), |i, j| p[(i, j)] - ph[(i, j)]);
                let e = top(&d);
                n += 1;
                ok += usize::from(e <= norm[k]);
                ok_w += usize::from(e <= weight_norm(k));
            }
            let frac = |x: usize| (n > 0).then(|| x as f64 / n as f64);
            (Some([lo, hi]), frac(ok), frac(ok_w))
        }
        None => (None, None, None),
    };
    let margins = |r: &ambid_core::validate::robust::RobustStability| {
        r.lower_gain_margin
            .zip(r.upper_gain_margin)
            .map(|(a, b)| [a, b])
    };
    Ok(UncertaintyRow {
        speed_rpm,
        band_hz: [band.0, band.1],
        bound_band_hz: [bound_band.0, bound_band.1],
        lines: f.len(),
        raise,
        weight_raise,
        median_rel_pct: 100.0 * rel.get(rel.len() / 2).copied().unwrap_or(f64::NAN),
        max_rel_pct: 100.0 * rel.last().copied().unwrap_or(f64::NAN),
        robustly_stable: r.robustly_stable,
        mu_peak: r.mu_peak,
        mu_peak_hz: r.mu_peak_hz,
        gain_margins: margins(&r),
        exact_gain_margins,
        truth_coverage,
        weight_max_order: ws.iter().map(Weight::order).max().unwrap_or(0),
        weight_looseness: loose.get(loose.len() / 2).copied().unwrap_or(f64::NAN),
        weight_robustly_stable: rw.robustly_stable,
        weight_mu_peak: rw.mu_peak,
        weight_mu_peak_hz: rw.mu_peak_hz,
        weight_gain_margins: margins(&rw),
        weight_truth_coverage,
        coherent_draws: COHERENT_DRAWS,
        coherent_confidence: rc.confidence,
        coherent_stable_fraction: rc.stable_fraction,
        coherent_gain_margins: rc
            .lower_gain_margin
            .zip(rc.upper_gain_margin)
            .map(|(a, b)| [a, b]),
        coherent_outside_gain_interval: rc.outside_gain_interval,
        coherent_outside_critical_hz: rc.outside_critical_hz,
        amplitude_levels_pct: amp.map(|(_, l)| l),
        amplitude_median_rel_pct,
        amplitude_projected,
        amplitude_note,
        export: Some(Box::new(
            crate::io::export::uncertain_matrix::UncertainMatrixModel {
                nominal: model.clone(),
                f_hz: f.clone(),
                bounds: u.entries.iter().map(|e| e.additive.clone()).collect(),
                weights,
                on_lines: r,
                on_weights: rw,
            },
        )),
    })
}

/// Quantile of the standard normal distribution for [`at_noise_level`]: one-sided 99 %.
pub const NOISE_LEVEL_QUANTILE: f64 = 2.326;

/// Whether a fit's inverse-variance-weighted cost is at the noise level (module docs,
/// "Orders"): with the model class holding the plant and the weights right, $2V$ is
/// $\chi^2$-distributed with $\nu = 2 L n_y n_u - n_\theta$ degrees of freedom, so
/// $2V/\nu$ ([`MimoFreqFit::normalised_cost`]) has mean 1 and standard deviation
/// $\sqrt{2/\nu}$; the fit is at the noise level when
/// $2V/\nu \le 1 + $ [`NOISE_LEVEL_QUANTILE`] $\sqrt{2/\nu}$ (the one-sided 99 % point). A model
/// of higher order can then lower $2V$ only by about its $\chi^2$ share of noise (one unit per
/// added parameter), less than BIC charges for it ($\ln 2Ln_yn_u \approx 9$ per parameter at
/// 253 lines of a 4×4 FRF), so BIC would not choose it either.
///
/// # Example
/// ```
/// use ambid::workflow::machine_fit::at_noise_level;
/// // 8 096 real equations, 128 parameters: 2V/ν ≤ 1 + 2.326·√(2/7 968) = 1.0368
/// assert!(at_noise_level(3984.0, 8096, 128));
/// assert!(!at_noise_level(4200.0, 8096, 128));
/// ```
pub fn at_noise_level(cost: f64, n_equations: usize, n_params: usize) -> bool {
    cost <= CostTarget::NoiseLevel {
        quantile: NOISE_LEVEL_QUANTILE,
    }
    .cost_bound(n_equations, n_params)
}

/// The degrees of freedom $\nu = 2Ln_yn_u - n_\theta$ of [`at_noise_level`] (at least 1).
fn noise_level_dof(n_equations: usize, n_params: usize) -> usize {
    n_equations.saturating_sub(n_params).max(1)
}

/// The bound of [`at_noise_level`] on $2V/\nu$: $1 + $ [`NOISE_LEVEL_QUANTILE`] $\sqrt{2/\nu}$.
fn noise_level_bound(nu: usize) -> f64 {
    1.0 + NOISE_LEVEL_QUANTILE * (2.0 / nu as f64).sqrt()
}

/// One fitted candidate of one speed.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// State dimension.
    pub order: usize,
    /// The fit, or why it failed.
    pub fit: Result<MimoFreqFit, String>,
    /// Whether the model's loop with the controllers is stable (`None`: no controller known).
    pub loop_stable: Option<bool>,
    /// The out-of-band misfit $X$ of the model's closed loop against the measured $\hat T_{ry}$
    /// (module docs; `None`: no controller, no $\hat T_{ry}$ with variances, or no line above
    /// the band).
    pub out_of_band: Option<f64>,
    /// The plant's unstable poles as the measured loop shows them
    /// ([`loop_unstable_poles`]; `None`: no controller, or the lines do not support a count).
    pub measured_unstable: Option<usize>,
}

impl Candidate {
    /// Whether the candidate may be chosen: fitted, a stable loop with the controllers, and
    /// consistent with the measured closed loop above the band (each where it can be checked).
    pub fn admissible(&self) -> bool {
        self.fit.as_ref().is_ok_and(|f| !f.abandoned)
            && self.loop_stable != Some(false)
            && self.out_of_band.is_none_or(|x| x <= MAX_OUT_OF_BAND_MISFIT)
            && !self.contradicts_the_unstable_count()
    }

    /// Whether the fit's weighted cost is at the noise level ([`at_noise_level`]).
    pub fn is_at_noise_level(&self) -> bool {
        self.fit
            .as_ref()
            .is_ok_and(|f| at_noise_level(f.cost, f.n_equations, f.n_params))
    }

    /// Whether the model's unstable poles differ from the count the measured loop shows.
    pub fn contradicts_the_unstable_count(&self) -> bool {
        match (&self.fit, self.measured_unstable) {
            (Ok(f), Some(k)) => !f.unstable_poles().is_ok_and(|n| n == k),
            _ => false,
        }
    }
}

/// The out-of-band misfit $X$ (module docs, "Out of band") of `plant`'s loop with `controller`
/// against the measured `t_ry` on its lines above `above_hz`; `None` when `t_ry` has no
/// variances or no line above `above_hz`, or the loop cannot be evaluated.
pub fn out_of_band_misfit(
    plant: &StateSpace,
    controller: &StateSpace,
    t_ry: &Frd,
    above_hz: f64,
) -> Option<f64> {
    let var = t_ry.variance()?;
    let lines: Vec<usize> = (0..t_ry.len())
        .filter(|&k| t_ry.f_hz()[k] > above_hz)
        .collect();
    if lines.is_empty() {
        return None;
    }
    let f: Vec<f64> = lines.iter().map(|&k| t_ry.f_hz()[k]).collect();
    let resp = plant.feedback(controller).ok()?.freq_response(&f).ok()?;
    let (ny, nu) = (t_ry.ny(), t_ry.nu());
    let e = ny * nu;
    let mut total = 0.0;
    for (kk, &k) in lines.iter().enumerate() {
        let meas = &t_ry.values()[k * e..(k + 1) * e];
        for j in 0..nu {
            for i in 0..ny {
                let v = var[k * e + j * ny + i];
                if !(v > 0.0 && v.is_finite()) {
                    return None;
                }
                total += (resp[kk][(i, j)] - meas[j * ny + i]).norm_sqr() / v;
            }
        }
    }
    let x = total / (lines.len() * e) as f64;
    x.is_finite().then_some(x)
}

/// The band of a measured plant FRF that a fit uses (module docs, "Band"): `None` when no run of
/// three precise lines lies in the quality band.
///
/// # Errors
/// [`Error`] when the FRF has no variance.
pub fn fit_band(plant: &Frd, quality_band_hz: [f64; 2]) -> Result<Option<(f64, f64)>, Error> {
    let var = plant.variance().ok_or_else(|| {
        Error::input("the measured plant FRF has no variance; the MIMO fit weights every entry by its inverse variance")
    })?;
    let good: Vec<bool> = (0..plant.len())
        .map(|k| {
            let f = plant.f_hz()[k];
            f >= quality_band_hz[0]
                && f <= quality_band_hz[1]
                && line_relative_std(plant, var, k) <= MAX_RELATIVE_STD
        })
        .collect();
    let runs: Vec<usize> = (0..good.len().saturating_sub(2))
        .filter(|&k| good[k] && good[k + 1] && good[k + 2])
        .collect();
    Ok(match (runs.first(), runs.last()) {
        (Some(&a), Some(&b)) => Some((plant.f_hz()[a], plant.f_hz()[b + 2])),
        _ => None,
    })
}

/// Relative standard deviation (of the line's entries together, as in [`fit_band`]) up to which
/// the lines above the fit band still carry the uncertainty bound ([`uncertainty_band`]): a
/// line's 95 % interval within ±50 %. Over term (b)'s window of up to 17 lines the misfit is
/// then known to about ±0.12 relative, far tighter than the weights' extrapolation there.
pub const MAX_VALIDATION_RELATIVE_STD: f64 = 0.25;

/// The lines of a measured plant FRF that the uncertainty bound is built on, around a model
/// fitted on `fit` (docs/uncertainty.md, "Lines beyond the fit band"): the fit band, extended
/// upwards over the contiguous lines whose relative standard deviation (all entries together)
/// is at most [`MAX_VALIDATION_RELATIVE_STD`], no further than an octave above the fit band's
/// end. The model was not fitted there, so these are validation lines
/// ([`UncertaintyOptions::fitted_band_hz`](ambid_core::validate::uncertainty::UncertaintyOptions::fitted_band_hz)):
/// the bound there is the measured misfit, where a gain margin above the fitted band is
/// otherwise decided by the weights' extrapolation. The fit band's own limit,
/// [`MAX_RELATIVE_STD`], asks more of a line that a fit leans on than of one a windowed mean
/// averages.
///
/// # Errors
/// [`Error`] when the FRF has no variance.
///
/// # Example
/// ```
/// use ambid::workflow::machine_fit::uncertainty_band;
/// use ambid_core::{c64, lti::Frd};
/// let f: Vec<f64> = (1..=40).map(|k| 25.0 * k as f64).collect();
/// // relative std 0.05 up to 600 Hz, 0.2 up to 800 Hz, 0.5 above
/// let var: Vec<f64> = f.iter().map(|f| if *f <= 600.0 { 0.05f64 } else if *f <= 800.0 { 0.2 } else { 0.5 }.powi(2)).collect();
/// let g = Frd::new(f.clone(), vec![c64::new(1.0, 0.0); 40], Some(var), Some(1e-4)).unwrap();
/// assert_eq!(uncertainty_band(&g, (25.0, 600.0)).unwrap(), (25.0, 800.0));
/// assert_eq!(uncertainty_band(&g, (25.0, 300.0)).unwrap(), (25.0, 600.0)); // an octave
/// ```
pub fn uncertainty_band(plant: &Frd, fit: (f64, f64)) -> Result<(f64, f64), Error> {
    let var = plant.variance().ok_or_else(|| {
        Error::input("the measured plant FRF has no variance; the uncertainty bound needs the lines' confidence regions")
    })?;
    let mut end = fit.1;
    for k in 0..plant.len() {
        let f = plant.f_hz()[k];
        if f <= fit.1 {
            continue;
        }
        // a line without response (NaN) ends the run too
        let precise = line_relative_std(plant, var, k) <= MAX_VALIDATION_RELATIVE_STD;
        if f > 2.0 * fit.1 || !precise {
            break;
        }
        end = f;
    }
    Ok((fit.0, end))
}

/// The relative standard deviation of line `k` of the matrix FRF `plant` with the variances
/// `var`, all entries together: $\sqrt{\sum_{ij}\sigma^2_{ij,k} / \sum_{ij}|G_{ij,k}|^2}$ (NaN
/// on a line without response), the measure of [`fit_band`] and [`uncertainty_band`].
fn line_relative_std(plant: &Frd, var: &[f64], k: usize) -> f64 {
    let e = plant.ny() * plant.nu();
    let v: f64 = var[k * e..(k + 1) * e].iter().sum();
    let g: f64 = plant.values()[k * e..(k + 1) * e]
        .iter()
        .map(|x| x.norm_sqr())
        .sum();
    if g > 0.0 {
        (v / g).sqrt()
    } else {
        f64::NAN
    }
}

/// Fits the candidate orders to one speed's plant FRF, with the loop check against
/// `controller`, the out-of-band check against the measured `t_ry` and the unstable-pole count
/// of the measured loop (module docs). With `stop_at_noise_level` the candidates end at the
/// first admissible one, in increasing order, whose cost is at the noise level
/// ([`at_noise_level`]): the lowest order is fitted alone, and only when it is not such a
/// candidate are the others fitted (side by side); else every order is fitted (in parallel).
pub fn scan(
    plant: &Frd,
    band: (f64, f64),
    orders: &[usize],
    max_iterations: usize,
    controller: Option<&StateSpace>,
    t_ry: Option<&Frd>,
    stop_at_noise_level: bool,
) -> Vec<Candidate> {
    let measured_unstable = measured_unstable_of(plant, controller);
    let candidate = |order: usize, target: Option<CostTarget>, origin: FitOrigin<'_>| {
        fit_candidate(
            plant,
            band,
            order,
            max_iterations,
            controller,
            t_ry,
            measured_unstable,
            origin,
            target,
        )
    };
    if !stop_at_noise_level {
        return orders
            .par_iter()
            .map(|&order| candidate(order, None, FitOrigin::Scratch))
            .collect();
    }
    let mut sorted = orders.to_vec();
    sorted.sort_unstable();
    sorted.dedup();
    // the lowest order alone, abandoned once it cannot reach the noise level; when it is not
    // valid there, the others side by side, kept up to the first that is (the same table as
    // one order after the other)
    let Some((&first, rest)) = sorted.split_first() else {
        return Vec::new();
    };
    let noise_level = CostTarget::NoiseLevel {
        quantile: NOISE_LEVEL_QUANTILE,
    };
    let mut out = vec![candidate(first, Some(noise_level), FitOrigin::Scratch)];
    if out[0].admissible() && out[0].is_at_noise_level() {
        return out;
    }
    out.extend(
        rest.par_iter()
            .map(|&order| candidate(order, None, FitOrigin::Scratch))
            .collect::<Vec<_>>(),
    );
    if let Some(k) = out
        .iter()
        .skip(1)
        .position(|c| c.admissible() && c.is_at_noise_level())
    {
        out.truncate(k + 2);
    }
    // the lowest order is still to be finished, where it can beat the others by BIC
    out[0] = finish_lowest(&out[0], &out[1..], &candidate);
    out
}

/// The lowest order's fit of [`scan`] after the others (module docs, "Orders"): a fit that
/// was abandoned because it could not reach the noise level is resumed from its probed starts
/// ([`ss_frd_mimo_in_loop_resumed`]), raced against the lowest BIC of the admissible others
/// (to its end when no other is admissible); a finished fit, or a failed one, stands.
fn finish_lowest<F>(lowest: &Candidate, others: &[Candidate], candidate: &F) -> Candidate
where
    F: Fn(usize, Option<CostTarget>, FitOrigin<'_>) -> Candidate,
{
    let Some(f) = lowest.fit.as_ref().ok().filter(|f| f.abandoned) else {
        return lowest.clone();
    };
    let best_bic = others
        .iter()
        .filter(|c| c.admissible())
        .filter_map(|c| c.fit.as_ref().ok().map(MimoFreqFit::bic))
        .min_by(f64::total_cmp);
    candidate(
        lowest.order,
        best_bic.map(CostTarget::Bic),
        FitOrigin::Resumed(f),
    )
}

/// Where a candidate's fit starts ([`fit_candidate`]).
#[derive(Clone, Copy)]
enum FitOrigin<'a> {
    /// From scratch (the subspace and vector-fitting starts).
    Scratch,
    /// From a neighbouring speed's model ([`ss_frd_mimo_in_loop_from`]).
    Model(&'a StateSpace),
    /// The abandoned fit resumed ([`ss_frd_mimo_in_loop_resumed`]).
    Resumed(&'a MimoFreqFit),
}

/// The plant's unstable poles as the measured loop with `controller` shows them (module docs,
/// "Unstable poles"; `None` without a controller or when the lines do not support a count).
fn measured_unstable_of(plant: &Frd, controller: Option<&StateSpace>) -> Option<usize> {
    controller
        .and_then(|c| loop_unstable_poles(plant, c).ok())
        .and_then(|w| w.unstable_poles)
}

/// One candidate of [`scan`]: the fit of `order` from `origin`, held to `target` when given
/// ([`MimoFreqOptions::abandon_unless`]), its loop and out-of-band checks; `measured_unstable`
/// is [`measured_unstable_of`] the same plant and controller.
#[allow(clippy::too_many_arguments)]
fn fit_candidate(
    plant: &Frd,
    band: (f64, f64),
    order: usize,
    max_iterations: usize,
    controller: Option<&StateSpace>,
    t_ry: Option<&Frd>,
    measured_unstable: Option<usize>,
    origin: FitOrigin<'_>,
    target: Option<CostTarget>,
) -> Candidate {
    let opts = MimoFreqOptions {
        band_hz: Some(band),
        max_iterations,
        abandon_unless: target,
        ..Default::default()
    };
    // with a controller the fit holds itself to the measured loop's unstable-pole
    // count (module docs, "Unstable poles")
    let fit = match (controller, origin) {
        (Some(c), FitOrigin::Model(w)) => ss_frd_mimo_in_loop_from(plant, &opts, c, w),
        (Some(c), FitOrigin::Resumed(f)) => ss_frd_mimo_in_loop_resumed(plant, &opts, c, f),
        (Some(c), FitOrigin::Scratch) => ss_frd_mimo_in_loop(plant, order, &opts, c),
        (None, _) => ss_frd_mimo(plant, order, &opts),
    }
    .map_err(|e| e.to_string());
    let loop_stable = match (&fit, controller) {
        (Ok(f), Some(c)) => Some(
            f.model
                .feedback(c)
                .and_then(|cl| cl.is_stable())
                .unwrap_or(false),
        ),
        _ => None,
    };
    let out_of_band = match (&fit, controller, t_ry) {
        (Ok(f), Some(c), Some(t)) if loop_stable == Some(true) => {
            out_of_band_misfit(&f.model, c, t, band.1)
        }
        _ => None,
    };
    Candidate {
        order,
        fit,
        loop_stable,
        out_of_band,
        measured_unstable,
    }
}

/// The index of the chosen candidate (module docs, "Choice").
pub fn choose(cands: &[Candidate]) -> Option<usize> {
    cands
        .iter()
        .enumerate()
        .filter(|(_, c)| c.admissible())
        .min_by(|(_, a), (_, b)| {
            let ba = a.fit.as_ref().map_or(f64::INFINITY, MimoFreqFit::bic);
            let bb = b.fit.as_ref().map_or(f64::INFINITY, MimoFreqFit::bic);
            ba.total_cmp(&bb)
        })
        .map(|(i, _)| i)
}

/// The closed-loop modes of `plant` under `controller` (damping below [`CAMPBELL_DAMPING`],
/// natural frequency in `band_hz`), with the whirl direction read from the outputs (module
/// docs, "Whirl"; outputs in axis order `xa, xb, ya, yb`).
///
/// # Errors
/// [`Error`] when the loop cannot be formed or its eigendecomposition fails.
pub fn closed_loop_modes(
    plant: &StateSpace,
    controller: &StateSpace,
    speed_rpm: f64,
    band_hz: [f64; 2],
) -> Result<Vec<ModePoint>, Error> {
    let cl = plant
        .feedback(controller)
        .map_err(|e| Error::computation(format!("closed loop of the model: {e}")))?;
    let ts = cl
        .ts()
        .ok_or_else(|| Error::computation("the model is continuous; a discrete model is needed"))?;
    let a = cl.a().to_owned();
    let eig = a
        .eigen()
        .map_err(|e| Error::computation(format!("closed-loop eigendecomposition: {e:?}")))?;
    let (u, s) = (eig.U(), eig.S());
    let c = cl.c();
    let n = a.nrows();
    let mut out = Vec::new();
    for k in 0..n {
        let z = s[k];
        if !(z.im > 1e-12 && z.norm() > 1e-12) {
            continue;
        }
        let sc = z.ln() / ts;
        let freq_hz = sc.norm() / (2.0 * std::f64::consts::PI);
        let damping = -sc.re / sc.norm();
        if !(damping < CAMPBELL_DAMPING && freq_hz >= band_hz[0] && freq_hz <= band_hz[1]) {
            continue;
        }
        let y: Vec<c64> = (0..c.nrows())
            .map(|i| (0..n).map(|j| u[(j, k)] * c[(i, j)]).sum())
            .collect();
        let j = c64::new(0.0, 1.0);
        let (mut ef, mut eb) = (0.0, 0.0);
        // bearings A and B: (xa, ya) and (xb, yb)
        for (ix, iy) in [(0usize, 2usize), (1, 3)] {
            if iy < y.len() {
                ef += (y[ix] + j * y[iy]).norm_sqr();
                eb += (y[ix] - j * y[iy]).norm_sqr();
            }
        }
        let frac = if ef + eb > 0.0 { ef / (ef + eb) } else { 0.5 };
        let whirl = if speed_rpm == 0.0 || (frac - 0.5).abs() < 1e-9 {
            Whirl::None
        } else if frac > 0.5 {
            Whirl::Forward
        } else {
            Whirl::Backward
        };
        out.push(ModePoint {
            speed_rpm,
            freq_hz,
            damping,
            whirl,
        });
    }
    out.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
    Ok(out)
}

/// The twin's independent validation record at one speed: [`VALIDATION_SAMPLES`] samples of
/// seeded Gaussian white noise ([`VALIDATION_RMS_A`] RMS, `NoiseSpec` seeds `s + 16 + axis`) on all
/// four axes, the loop settled for 4000 samples first, sensor-noise seed `s + 1`, with
/// `s = seed ^ 0x5EED_0FF1`, so the record shares no random number with the identification
/// experiments.
///
/// # Errors
/// [`Error`] from the twin.
pub fn twin_validation_record(
    cfg: &MachineConfig,
    mode: ambid_twin::Mode,
    speed_rpm: f64,
    noise: bool,
    seed: u64,
) -> Result<(Machine, IoData), Error> {
    let m = Machine::new(MachineConfig {
        speed_rpm,
        ..cfg.clone()
    })
    .map_err(Error::from)?;
    let s = seed ^ 0x5EED_0FF1;
    let r: Vec<Vec<f64>> = (0..4u64)
        .map(|a| {
            NoiseSpec {
                distribution: Distribution::Gaussian,
                rms: VALIDATION_RMS_A,
                n_samples: VALIDATION_SAMPLES,
                band_hz: None,
                seed: s.wrapping_add(16 + a),
            }
            .generate(m.ts())
            .map(|e| e.values)
            .map_err(|e| Error::computation(format!("validation excitation: {e}")))
        })
        .collect::<Result<_, _>>()?;
    let opts = MachineSimOptions {
        mode,
        seed: s.wrapping_add(1),
        noise,
        w: None,
        settle_samples: 4000,
    };
    let rec = m
        .simulate([&r[0], &r[1], &r[2], &r[3]], &opts)
        .map_err(Error::from)?;
    let data = rec.to_iodata(None).map_err(Error::from)?;
    Ok((m, data))
}

/// One speed's fits.
struct SpeedResult {
    cands: Vec<Candidate>,
    chosen: Option<usize>,
    band: Option<(f64, f64)>,
    notes: Vec<String>,
}

/// One speed's validation of its chosen model ([`FrequencyFitter::validate`]).
#[derive(Default)]
struct SpeedValidation {
    validation: Vec<AxisValidationRow>,
    iso: Vec<IsoRow>,
    sigma: Option<(f64, f64, f64)>,
    modes: Vec<ModePoint>,
    notes: Vec<String>,
}

impl FrequencyFitter {
    /// One speed's fits: the `orders` fitted (the scan), then, when none of them can be chosen,
    /// the `fallback` orders (module docs, "Orders"); [`FrequencyFitter::validate`] adds the
    /// chosen model's validation.
    fn speed(
        &self,
        input: &MachineModelInput<'_>,
        sp: &SpeedMeasurement,
        orders: &[usize],
        fallback: &[usize],
        warm: Option<&StateSpace>,
    ) -> Result<SpeedResult, Error> {
        let controller = input.controller;
        let mut notes = Vec::new();
        let band = fit_band(&sp.frf.plant, input.quality_band_hz)?;
        let Some(band) = band else {
            notes.push(format!(
                "{} rpm: no run of three lines in {}–{} Hz has a plant estimate within ±20 % (95 %); no model was fitted — raise the excitation level or record more periods",
                sp.speed_rpm, input.quality_band_hz[0], input.quality_band_hz[1]
            ));
            return Ok(SpeedResult {
                cands: Vec::new(),
                chosen: None,
                band: None,
                notes,
            });
        };
        let scan_of = |orders: &[usize]| {
            scan(
                &sp.frf.plant,
                band,
                orders,
                self.max_iterations,
                controller,
                sp.frf.t_ry.as_ref(),
                self.stop_at_noise_level,
            )
        };
        // from the neighbouring speed's model when given (module docs, "One scan for all
        // speeds"); from scratch when that fit is not admissible
        let mut cands = match warm {
            Some(w) => {
                let c = fit_candidate(
                    &sp.frf.plant,
                    band,
                    w.order(),
                    self.max_iterations,
                    controller,
                    sp.frf.t_ry.as_ref(),
                    measured_unstable_of(&sp.frf.plant, controller),
                    FitOrigin::Model(w),
                    None,
                );
                if c.admissible() {
                    vec![c]
                } else {
                    notes.push(format!(
                        "{} rpm: the fit of order {} from the neighbouring speed's model is not admissible ({}); it was fitted from scratch",
                        sp.speed_rpm,
                        w.order(),
                        match &c.fit {
                            Err(e) => e.clone(),
                            Ok(_) => "unstable loop, a misfit above the band or another unstable-pole count".into(),
                        }
                    ));
                    scan_of(orders)
                }
            }
            None => scan_of(orders),
        };
        let mut chosen = choose(&cands);
        if chosen.is_none() && !fallback.is_empty() {
            notes.push(format!(
                "{} rpm: order {} (the reference speed's choice) gives no admissible model here; orders {} were scanned as well",
                sp.speed_rpm,
                list(orders),
                list(fallback)
            ));
            cands.extend(scan_of(fallback));
            cands.sort_by_key(|c| c.order);
            chosen = choose(&cands);
        }
        if let Some(last) = cands.last().filter(|_| orders.len() > 1) {
            let skipped: Vec<String> = orders
                .iter()
                .filter(|&&o| o > last.order)
                .map(|o| o.to_string())
                .collect();
            if !skipped.is_empty() {
                if let Ok(f) = &last.fit {
                    let nu = noise_level_dof(f.n_equations, f.n_params);
                    notes.push(format!(
                        "{} rpm: order {} is at the noise level (2V/ν = {:.3} ≤ {:.3}, the one-sided 99 % point of χ²/ν with ν = {nu}); orders {} were not fitted (a higher order could not lower BIC) — set `[machine] models = \"fit-all\"` to fit them",
                        sp.speed_rpm,
                        last.order,
                        f.normalised_cost(),
                        noise_level_bound(nu),
                        skipped.join(", ")
                    ));
                }
            }
        }
        if let Some(Ok(f)) = chosen.map(|c| &cands[c].fit) {
            if !f.floored.is_empty() {
                let pairs: Vec<String> = f
                    .floored
                    .iter()
                    .map(|p| {
                        format!(
                            "{:.2} Hz (ζ {:.1e} → {:.1e})",
                            p.f_hz, p.zeta_fitted, p.zeta_floored
                        )
                    })
                    .collect();
                notes.push(format!(
                    "{} rpm: the chosen model's pole pairs at {} were narrower than the spacing of the lines around them, which cannot show their damping; each was given the largest damping the data accept, at most the spacing's (the damping floor of ambid_core::estimate::freqfit_mimo)",
                    sp.speed_rpm,
                    pairs.join(", ")
                ));
            }
        }
        if chosen.is_none() {
            notes.push(format!(
                "{} rpm: no candidate model gives a stable closed loop with the controllers that agrees with the measured closed loop above the fitted band (misfit ≤ {MAX_OUT_OF_BAND_MISFIT}) and has the measured loop's number of unstable poles; none was chosen (the table lists why each failed) — try other orders",
                sp.speed_rpm
            ));
        }
        Ok(SpeedResult {
            cands,
            chosen,
            band: Some(band),
            notes,
        })
    }

    /// The validation of the chosen model of speed `k` (its fits `r` from
    /// [`FrequencyFitter::speed`]): its closed-loop modes, then the closed-loop simulation
    /// of it and, on the twin, of the true plant against an independent record (side by side).
    fn validate(
        &self,
        input: &MachineModelInput<'_>,
        k: usize,
        sp: &SpeedMeasurement,
        r: &SpeedResult,
    ) -> Result<SpeedValidation, Error> {
        let controller = input.controller;
        let (cands, chosen) = (&r.cands, r.chosen);
        let mut out = SpeedValidation::default();
        let SpeedValidation {
            validation,
            iso,
            sigma,
            modes,
            notes,
        } = &mut out;
        if let (Some(ci), Some(ctl)) = (chosen, controller) {
            if let Ok(fit) = &cands[ci].fit {
                *modes = closed_loop_modes(&fit.model, ctl, sp.speed_rpm, input.quality_band_hz)?;
                // validation: an independent twin record, or (files) the first experiment
                let record = match input.twin {
                    Some((cfg, mode)) => Some((
                        twin_validation_record(
                            cfg,
                            mode,
                            sp.speed_rpm,
                            input.noise,
                            input.seed.wrapping_add(k as u64),
                        )?
                        .1,
                        true,
                    )),
                    None => sp.records.first().cloned().map(|r| (r, false)),
                };
                if let Some((rec, independent)) = record {
                    if !independent {
                        notes.push(format!(
                            "{} rpm: validated on the first identification experiment (no independent record was given); the fit is optimistic",
                            sp.speed_rpm
                        ));
                    }
                    let opts = MachineValidationOptions {
                        zones: input.zones,
                        ..Default::default()
                    };
                    let (model_validation, truth) = rayon::join(
                        || validate_machine(&fit.model, ctl, &rec, &opts),
                        || {
                            input
                                .truth
                                .and_then(|t| t.get(k))
                                .and_then(|t| machine_output_fits(&t.plant, ctl, &rec, &opts).ok())
                        },
                    );
                    match model_validation {
                        Ok(v) => {
                            for (a, ax) in v.axes.iter().enumerate() {
                                validation.push(AxisValidationRow {
                                    speed_rpm: sp.speed_rpm,
                                    axis: ax.axis.clone(),
                                    fit_y_pct: ax.fit_y,
                                    fit_i_pct: ax.fit_i,
                                    truth_fit_y_pct: truth.as_ref().and_then(|t| t.get(a).copied()),
                                    whiteness_ok: None,
                                    independence_ok: ax.residuals.as_ref().map(|r| r.pass),
                                });
                                iso.push(IsoRow {
                                    speed_rpm: sp.speed_rpm,
                                    axis: ax.axis.clone(),
                                    from: "model".into(),
                                    peak: ax.iso.peak,
                                    f_hz: ax.iso.f_peak_hz,
                                    zone: ax.iso.zone,
                                });
                            }
                            *sigma = Some((sp.speed_rpm, v.sigma_max_peak, v.sigma_max_f_hz));
                        }
                        Err(e) => notes.push(format!(
                            "{} rpm: the chosen model could not be validated: {e}",
                            sp.speed_rpm
                        )),
                    }
                }
            }
        } else if chosen.is_some() {
            notes.push(format!(
                "{} rpm: no controller is known (recorded files), so the model is not validated in closed loop and has no closed-loop modes",
                sp.speed_rpm
            ));
        }
        Ok(out)
    }
}

/// Every speed's fits and validations and the speed-scheduled model
/// ([`FrequencyFitter::all_speeds`]).
struct AllSpeeds {
    results: Vec<SpeedResult>,
    validations: Vec<SpeedValidation>,
    /// `None` without a controller (recorded files).
    schedule: Option<Result<Option<SpeedScheduledModel>, Error>>,
}

impl FrequencyFitter {
    /// Every speed's fits (module docs, "Orders"): with
    /// [`FrequencyFitter::order_from_reference_speed`] and more than one speed, the orders are
    /// scanned at the reference speed (the middle one of the list) and the other speeds fit its
    /// chosen order, scanning the rest only where that order gives no admissible model; else
    /// every speed scans every order. Then every speed's validation and (with a controller) the
    /// speed-scheduled model. What does not depend on each other runs side by side: the
    /// reference speed's validation beside the other speeds' fits, the other validations
    /// beside the speed-scheduled model (each computation is the same as one after the other,
    /// so the result does not depend on the number of threads).
    fn all_speeds(
        &self,
        input: &MachineModelInput<'_>,
        notes: &mut Vec<String>,
    ) -> Result<AllSpeeds, Error> {
        let n = input.speeds.len();
        let schedule =
            |results: &[SpeedResult]| input.controller.map(|_| self.scheduled(input, results));
        let validate_all = |results: &[SpeedResult], skip: Option<usize>| {
            input
                .speeds
                .par_iter()
                .zip(results)
                .enumerate()
                .map(|(k, (sp, r))| {
                    if Some(k) == skip {
                        Ok(SpeedValidation::default())
                    } else {
                        self.validate(input, k, sp, r)
                    }
                })
                .collect::<Result<Vec<_>, Error>>()
        };
        if !self.order_from_reference_speed || n < 2 || self.orders.len() < 2 {
            let results = input
                .speeds
                .par_iter()
                .map(|sp| self.speed(input, sp, &self.orders, &[], None))
                .collect::<Result<Vec<_>, Error>>()?;
            let (validations, schedule) =
                rayon::join(|| validate_all(&results, None), || schedule(&results));
            return Ok(AllSpeeds {
                validations: validations?,
                results,
                schedule,
            });
        }
        let kr = n / 2;
        let reference = self.speed(input, &input.speeds[kr], &self.orders, &[], None)?;
        let ref_model = reference
            .chosen
            .and_then(|c| reference.cands[c].fit.as_ref().ok())
            .map(|f| f.model.clone());
        let order = reference.chosen.map(|c| reference.cands[c].order);
        let rest: Vec<usize> = self
            .orders
            .iter()
            .copied()
            .filter(|&x| Some(x) != order)
            .collect();
        // outwards from the reference, each speed from its inner neighbour's model: the
        // speeds below and those above side by side
        let chain = |ks: Vec<usize>| -> Result<Vec<(usize, SpeedResult)>, Error> {
            let mut warm = ref_model.clone();
            let mut out = Vec::new();
            for k in ks {
                let sp = &input.speeds[k];
                let r = match order {
                    Some(o) => self.speed(input, sp, &[o], &rest, warm.as_ref())?,
                    None => self.speed(input, sp, &self.orders, &[], None)?,
                };
                if let Some(f) = r
                    .chosen
                    .and_then(|c| r.cands[c].fit.as_ref().ok())
                    .filter(|f| Some(f.model.order()) == order)
                {
                    warm = Some(f.model.clone());
                }
                out.push((k, r));
            }
            Ok(out)
        };
        let (ref_validation, others) = rayon::join(
            || self.validate(input, kr, &input.speeds[kr], &reference),
            || {
                let (below, above) = rayon::join(
                    || chain((0..kr).rev().collect()),
                    || chain((kr + 1..n).collect()),
                );
                let mut others = below?;
                others.extend(above?);
                Ok::<_, Error>(others)
            },
        );
        let ref_validation = ref_validation?;
        let mut others = others?;
        if let Some(o) = order {
            notes.push(format!(
                "Orders: {} scanned at the reference speed {} rpm (the middle of the list), which chose order {o}; every other speed fits order {o} (the plant has the same states at every speed) starting from its inner neighbour's model, from scratch where that fit is not admissible, and scans the rest only where no fit of order {o} is admissible — `[machine] models = \"fit-all\"` scans every order at every speed, each from scratch",
                list(&self.orders),
                input.speeds[kr].speed_rpm
            ));
        }
        others.push((kr, reference));
        others.sort_by_key(|(k, _)| *k);
        let results: Vec<SpeedResult> = others.into_iter().map(|(_, r)| r).collect();
        let (validations, schedule) =
            rayon::join(|| validate_all(&results, Some(kr)), || schedule(&results));
        let mut validations = validations?;
        validations[kr] = ref_validation;
        Ok(AllSpeeds {
            results,
            validations,
            schedule,
        })
    }
}

/// Orders as a comma-separated list, for the notes.
fn list(orders: &[usize]) -> String {
    orders
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Speeds of the Campbell curves' grid, minus one.
pub const SCHEDULE_GRID: usize = 24;

impl FrequencyFitter {
    /// The speed-scheduled model of the per-speed fits (`None` with fewer than two speeds of the
    /// common order).
    fn scheduled(
        &self,
        input: &MachineModelInput<'_>,
        results: &[SpeedResult],
    ) -> Result<Option<SpeedScheduledModel>, Error> {
        let chosen: Vec<usize> = results
            .iter()
            .filter_map(|r| r.chosen.map(|c| r.cands[c].order))
            .collect();
        let Some(&order) = chosen.get(chosen.len() / 2) else {
            return Ok(None);
        };
        let mut data = Vec::new();
        let mut band = (f64::INFINITY, f64::NEG_INFINITY);
        for (sp, r) in input.speeds.iter().zip(results) {
            let Some(fit) = r
                .cands
                .iter()
                .find(|c| c.order == order)
                .and_then(|c| c.fit.as_ref().ok())
            else {
                continue;
            };
            if let Some(b) = r.band {
                band = (band.0.min(b.0), band.1.max(b.1));
            }
            data.push(SpeedData {
                speed_rpm: sp.speed_rpm,
                model: &fit.model,
                frd: &sp.frf.plant,
            });
        }
        if data.len() < 2 {
            return Ok(None);
        }
        let opts = ScheduleOptions {
            band_hz: Some(band),
            ..Default::default()
        };
        fit_scheduled(&data, &opts)
            .map(Some)
            .map_err(|e| Error::computation(format!("speed-scheduled model: {e}")))
    }
}

impl MachineModels for FrequencyFitter {
    fn identify(&self, input: &MachineModelInput<'_>) -> Result<MachineModelOutput, Error> {
        let mut out = MachineModelOutput::default();
        let AllSpeeds {
            results,
            validations,
            schedule,
        } = self.all_speeds(input, &mut out.notes)?;
        // the chosen models whose uncertainty is asked for: (speed index, band, model)
        let mut unc_jobs: Vec<(usize, (f64, f64), StateSpace)> = Vec::new();
        for (si, ((sp, res), val)) in input
            .speeds
            .iter()
            .zip(&results)
            .zip(&validations)
            .enumerate()
        {
            for (i, c) in res.cands.iter().enumerate() {
                let chosen = res.chosen == Some(i);
                match &c.fit {
                    Ok(fit) => {
                        let unstable = fit.unstable_poles().unwrap_or(usize::MAX);
                        let max_entry = fit
                            .errors
                            .median_entry_relative
                            .iter()
                            .copied()
                            .filter(|v| v.is_finite())
                            .fold(0.0, f64::max);
                        out.comparison.push(ComparisonRow {
                            speed_rpm: sp.speed_rpm,
                            model: format!(
                                "freq ss {}{}",
                                c.order,
                                match (c.loop_stable, c.out_of_band, c.measured_unstable) {
                                    _ if fit.abandoned => format!(
                                        " (abandoned after {} steps: it cannot reach the lowest BIC of the other orders)",
                                        fit.iterations
                                    ),
                                    (Some(false), _, _) => " (unstable loop)".to_string(),
                                    (_, Some(x), _) if x > MAX_OUT_OF_BAND_MISFIT => format!(
                                        " (contradicts the closed loop above the band: misfit {x:.1})"
                                    ),
                                    (_, _, Some(k)) if c.contradicts_the_unstable_count() => format!(
                                        " (contradicts the measured loop: {unstable} unstable poles, its Nyquist count is {k})"
                                    ),
                                    _ => String::new(),
                                }
                            ),
                            order: c.order,
                            unstable_poles: unstable,
                            median_norm_error_pct: 100.0 * fit.errors.median_norm_relative,
                            max_entry_error_pct: 100.0 * max_entry,
                            bic: Some(fit.bic()),
                            fit_y_pct: if chosen && val.validation.len() == 4 {
                                Some(std::array::from_fn(|a| val.validation[a].fit_y_pct))
                            } else {
                                None
                            },
                            chosen,
                        });
                        if chosen {
                            if let (true, Some(band)) = (self.uncertainty, res.band) {
                                unc_jobs.push((si, band, fit.model.clone()));
                            }
                            let name = format!("ss{}_{}rpm", c.order, sp.speed_rpm.round());
                            out.models.push(SpeedModel {
                                speed_rpm: sp.speed_rpm,
                                name,
                                model: fit.model.clone(),
                                meta: serde_json::json!({
                                    "structure": "ss",
                                    "method": "frequency-domain subspace + weighted least squares on the 4x4 FRF (inverse-variance weights)",
                                    "order": c.order,
                                    "band_hz": res.band.map(|b| [b.0, b.1]),
                                    "lines": fit.f_hz.len(),
                                    "bic": fit.bic(),
                                    "normalised_cost": fit.normalised_cost(),
                                    "median_norm_error": fit.errors.median_norm_relative,
                                    "unstable_poles": unstable,
                                    "iterations": fit.iterations,
                                    "converged": fit.converged,
                                    "damping_floor": fit.floored.iter().map(|p| serde_json::json!({
                                        "f_hz": p.f_hz,
                                        "zeta_fitted": p.zeta_fitted,
                                        "zeta": p.zeta_floored,
                                        "spacing_hz": p.spacing_hz,
                                        "cost_rise": p.cost_rise,
                                    })).collect::<Vec<_>>(),
                                }),
                            });
                        }
                    }
                    Err(e) => out.notes.push(format!(
                        "{} rpm, order {}: not fitted: {e}",
                        sp.speed_rpm, c.order
                    )),
                }
            }
            out.validation.extend(val.validation.iter().cloned());
            out.iso.extend(val.iso.iter().cloned());
            out.sigma_max_s.extend(val.sigma);
            out.campbell_points.extend(val.modes.iter().copied());
            out.notes.extend(res.notes.iter().cloned());
            out.notes.extend(val.notes.iter().cloned());
        }
        if self.uncertainty {
            match input.controller {
                None => out.notes.push(
                    "No uncertainty bound: the robust-stability check needs the controllers (the twin's; recorded files carry none).".into(),
                ),
                Some(ctl) => {
                    let rows: Vec<_> = unc_jobs
                        .par_iter()
                        .map(|(si, band, model)| {
                            let sp = &input.speeds[*si];
                            let truth = input.truth.and_then(|t| t.get(*si)).map(|t| &t.plant);
                            let study = sp.level_pct.filter(|_| !sp.amplitude.is_empty()).map(
                                |level_pct| AmplitudeStudy {
                                    level_pct,
                                    levels: &sp.amplitude,
                                },
                            );
                            speed_uncertainty(
                                sp.speed_rpm,
                                &sp.frf.plant,
                                *band,
                                model,
                                ctl,
                                truth,
                                study.as_ref(),
                            )
                                .map_err(|e| format!("{} rpm: no uncertainty bound: {e}", sp.speed_rpm))
                        })
                        .collect();
                    for r in rows {
                        match r {
                            Ok(row) => out.uncertainty.push(row),
                            Err(e) => out.notes.push(e),
                        }
                    }
                }
            }
        }
        // the speed-scheduled model: the middle speed's chosen order at every speed that has
        // a fit of that order; its closed-loop modes on a dense speed grid are the curves
        if let (Some(ctl), Some(schedule)) = (input.controller, schedule) {
            match schedule {
                Ok(Some(sched)) => {
                    let (lo, hi) = sched.range_rpm();
                    for g in 0..=SCHEDULE_GRID {
                        let speed = lo + (hi - lo) * g as f64 / SCHEDULE_GRID as f64;
                        let model = sched.at(speed).map_err(|e| {
                            Error::computation(format!("speed-scheduled model at {speed} rpm: {e}"))
                        })?;
                        match closed_loop_modes(&model, ctl, speed, input.quality_band_hz) {
                            Ok(m) => out.campbell_curves.extend(m),
                            Err(e) => out.notes.push(format!(
                                "speed-scheduled model at {speed:.0} rpm: no closed-loop modes ({e})"
                            )),
                        }
                    }
                    out.notes.push(format!(
                        "Speed-scheduled model: order {}, A(Ω) polynomial of degree {} in the speed over {:.0}–{:.0} rpm, B, C, D common (estimate::scheduled); its closed-loop modes are the Campbell diagram's curves.",
                        sched.b().nrows(),
                        sched.degree(),
                        lo,
                        hi
                    ));
                }
                Ok(None) => {}
                Err(e) => out.notes.push(format!("No speed-scheduled model: {e}")),
            }
        }
        let _ = AXES;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::{amplitude_terms, AmplitudeStudy};
    use crate::workflow::machine::LevelFrf;
    use ambid_core::lti::{Frd, StateSpace};
    use faer::mat;

    /// A 2×2 model, and its "measured" FRF at level `a` (fraction of i_sat) whose entry (0, 0)
    /// is the best linear approximation $P_{00}(1 - a^2)$ and whose other entries do not move.
    fn setup() -> (StateSpace, impl Fn(f64) -> Frd) {
        let m = StateSpace::discrete(
            mat![[0.9, 0.0], [0.0, 0.5]],
            mat![[1.0, 0.3], [0.2, 1.0]],
            mat![[0.1, 0.0], [0.0, 0.2]],
            mat![[0.0, 0.0], [0.0, 0.0]],
            1e-3,
        )
        .unwrap();
        let f: Vec<f64> = (1..=60).map(|k| k as f64 * 5.0).collect();
        let exact = Frd::from_model(&m, &f).unwrap();
        let at = move |a: f64| {
            let mut v = exact.values().to_vec();
            for k in 0..f.len() {
                v[4 * k] *= 1.0 - a * a;
            }
            let var: Vec<f64> = v.iter().map(|g| 1e-12 * g.norm_sqr()).collect();
            Frd::new_matrix(f.clone(), 2, 2, v, Some(var), Some(1e-3)).unwrap()
        };
        (m, at)
    }

    #[test]
    fn the_amplitude_term_of_each_entry_is_its_own_shift() {
        let (m, at) = setup();
        let levels = [
            LevelFrf {
                level_pct: 5.0,
                plant: at(0.05),
                saturated_fraction: 0.0,
            },
            LevelFrf {
                level_pct: 20.0,
                plant: at(0.2),
                saturated_fraction: 0.0,
            },
        ];
        let ident = at(0.1);
        let study = AmplitudeStudy {
            level_pct: 10.0,
            levels: &levels,
        };
        let (terms, used) = amplitude_terms(&m, &ident, &study).unwrap();
        assert_eq!(used, vec![5.0, 10.0, 20.0]);
        assert_eq!(terms.len(), 4);
        let p00 = m
            .entry(0, 0)
            .unwrap()
            .freq_response_siso(ident.f_hz())
            .unwrap();
        // entry (0, 0): the BLA at 10 % lies 1 % below the small-signal plant (the model is
        // the small-signal plant itself here, so the relative shift is 0.01 on every line, plus
        // the quantile of a negligible noise)
        for (k, p) in p00.iter().enumerate() {
            let rel = terms[0][k] / p.norm();
            assert!((rel - 0.01).abs() < 2e-4, "line {k}: {rel}");
        }
        // the entries that do not move have no term
        for e in &terms[1..] {
            assert!(e.iter().all(|x| *x == 0.0), "{e:?}");
        }
        // the study with its second level's limits active on the fraction `p` of the samples
        let with_saturation = |p: f64| {
            let study = [
                levels[0].clone(),
                LevelFrf {
                    saturated_fraction: p,
                    ..levels[1].clone()
                },
            ];
            let out = amplitude_terms(
                &m,
                &ident,
                &AmplitudeStudy {
                    level_pct: 10.0,
                    levels: &study,
                },
            );
            (study, out)
        };
        // a level saturated on more than 1 % of the samples is left out; the other one still
        // gives the term
        let (sat, out2) = with_saturation(0.02);
        let (t2, used2) = out2.unwrap();
        assert_eq!(used2, vec![5.0, 10.0]);
        assert!((t2[0][30] / p00[30].norm() - 0.01).abs() < 2e-4);
        // a level whose limits act on 0.5 % of the samples stays in
        let (_, used3) = with_saturation(0.005).1.unwrap();
        assert_eq!(used3, used);
        // every study level saturated: no term, and the message says why
        let all_sat: Vec<LevelFrf> = sat
            .iter()
            .map(|l| LevelFrf {
                saturated_fraction: 0.05,
                ..l.clone()
            })
            .collect();
        let e = amplitude_terms(
            &m,
            &ident,
            &AmplitudeStudy {
                level_pct: 10.0,
                levels: &all_sat,
            },
        )
        .unwrap_err();
        assert!(
            e.contains("saturated") && e.contains("lower the study's levels"),
            "{e}"
        );
    }
}
