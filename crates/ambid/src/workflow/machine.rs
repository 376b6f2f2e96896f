//! The whole-machine procedure (`ambid run` with a `[machine]` section,
//! [`crate::config::MachineSection`]): for every speed the multi-input design on the 4-axis twin
//! ([`ambid_twin::Machine`]) or the recorded experiments → the 4×4 closed-loop FRF
//! (`ambid_core::frf::mimo::estimate`, with the synchronous 1× line removed at speed as
//! `ambid frf --speed-rpm` does) → the parametric models through one seam, the
//! [`MachineModels`] trait → the report's machine sections and `summary.json`'s `machine`.
//!
//! # The seam
//! Everything that needs a MIMO model (the fitted plant per speed, the comparison table, the
//! Campbell points of the identified models and the curves of the speed-scheduled model, the
//! per-axis closed-loop validation) comes from one call, [`MachineModels::identify`], whose input
//! ([`MachineModelInput`]: the per-speed FRFs and records, the controller, the twin's truth) and
//! output ([`MachineModelOutput`]) are plain structs. [`MeasuredOnly`] identifies nothing: the
//! report then shows what the measurement and (on the twin) the exact model give — the 4×4 Bode
//! matrix with its ±2σ band and the truth, the cross-coupling against speed, the Campbell
//! diagram of the truth with the 1× line, and the per-axis ISO 14839-3 zone of the measured
//! sensitivity — and leaves out the model-dependent sections with a note saying so.

use super::{Outcome, Progress, StepTime};
use crate::config::{MachineSection, WorkflowConfig};
use crate::error::{Error, FailureClass};
use crate::report::{Block, NoteKind, Report, Section};
use crate::stage::ModelOut;
use ambid_core::data::{IoData, AXES};
use ambid_core::frf::mimo::{self, MimoOptions};
use ambid_core::frf::synchronous::{synchronous, SynchronousOptions};
use ambid_core::lti::{Frd, StateSpace};
use ambid_core::signal::multi::MultiInputDesign;
use ambid_core::signal::{BaseSignal, Grid, MultisineSpec, Phases, PrbsSpec};
use ambid_core::validate::iso::{IsoZones, Zone};
use ambid_twin::{Machine, MachineConfig, MachineSimOptions, Mode, Whirl};
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The nonparametric 4×4 closed-loop FRF of one speed.
#[derive(Debug, Clone)]
pub struct MeasuredFrf {
    /// The plant $\hat P = \hat T_{ry} \hat S^{-1}$ (4×4, per-entry variances).
    pub plant: Frd,
    /// $\hat T_{ry}$ (absent when read from an FRF file without it).
    pub t_ry: Option<Frd>,
    /// $\hat S = \hat T_{ru}$ (absent when read from an FRF file without it).
    pub s: Option<Frd>,
}

/// What was measured at one speed.
#[derive(Debug, Clone)]
pub struct SpeedMeasurement {
    /// The speed \[rpm\].
    pub speed_rpm: f64,
    /// The 4×4 FRF.
    pub frf: MeasuredFrf,
    /// The experiments (channels `r_*, u_*, y_*` and, when recorded, `i_*`; with their period),
    /// with the 1× line removed; empty when the speed was read from an FRF file.
    pub records: Vec<IoData>,
    /// Where the data came from (`twin` or the path).
    pub source: String,
    /// The 1× frequency whose line was removed before the FRF \[Hz\], if any.
    pub sync_removed_hz: Option<f64>,
    /// Samples per period of the excitation (0 when read from an FRF file).
    pub period_samples: usize,
    /// The excitation's peak level \[% of i_sat\] (the twin's `level_pct`; recorded files:
    /// unknown).
    pub level_pct: Option<f64>,
    /// The amplitude study at this speed (`[machine] amplitude_levels_pct`; empty without one).
    pub amplitude: Vec<LevelFrf>,
    /// The largest fraction of samples where an axis' controller output hit ±i_sat in the
    /// identification experiments, over the axes and experiments (the twin; recorded files:
    /// unknown).
    pub saturated_fraction: Option<f64>,
}

/// The plant FRF of the identification design repeated at another excitation level (the
/// machine's amplitude study, term (e) of the uncertainty).
#[derive(Debug, Clone)]
pub struct LevelFrf {
    /// Peak level \[% of i_sat\].
    pub level_pct: f64,
    /// The 4×4 plant FRF (per-entry variances), on the identification FRF's lines.
    pub plant: Frd,
    /// The largest fraction of samples where an axis' controller output hit ±i_sat, over the
    /// axes and experiments (0: no saturation).
    pub saturated_fraction: f64,
}

/// The twin's exact model at one speed (source = twin).
#[derive(Debug, Clone)]
pub struct SpeedTruth {
    /// The speed \[rpm\].
    pub speed_rpm: f64,
    /// The exact discrete plant $u \to y$ (4×4, unstable).
    pub plant: StateSpace,
    /// The decentralised controller (4×4, discrete, $u = -C y + r$).
    pub controller: StateSpace,
    /// Exact (frequency \[Hz\], peak $|S_{ii}|$) per axis (`Machine::peak_sensitivity`).
    pub peak_sensitivity: [(f64, f64); 4],
}

/// The input of [`MachineModels::identify`].
#[derive(Debug, Clone, Copy)]
pub struct MachineModelInput<'a> {
    /// The measurement at every speed, in increasing speed.
    pub speeds: &'a [SpeedMeasurement],
    /// The controller (4×4, discrete), when known (the twin's; recorded files: none).
    pub controller: Option<&'a StateSpace>,
    /// The twin's exact model per speed (same order as `speeds`), on the twin only.
    pub truth: Option<&'a [SpeedTruth]>,
    /// The twin's configuration (speed set per run with `speed_rpm`) and the physics of the
    /// records (`Some` on the twin only): a fitter simulates its independent validation records
    /// with them (`Machine::new(MachineConfig { speed_rpm, ..cfg })` then `simulate`).
    pub twin: Option<(&'a MachineConfig, Mode)>,
    /// Whether the twin's records have sensor noise.
    pub noise: bool,
    /// Sample time \[s\].
    pub ts: f64,
    /// Band of the figures of merit \[Hz\].
    pub quality_band_hz: [f64; 2],
    /// The ISO 14839-3 limits of the workflow (`[iso]`).
    pub zones: IsoZones,
    /// Base seed (for anything random, e.g. a validation record).
    pub seed: u64,
}

/// The chosen MIMO model at one speed.
#[derive(Debug, Clone)]
pub struct SpeedModel {
    /// The speed \[rpm\].
    pub speed_rpm: f64,
    /// File stem and label, e.g. `ss12_15000rpm`.
    pub name: String,
    /// The model $u \to y$ (4×4, discrete; never stabilised).
    pub model: StateSpace,
    /// Metadata written into the JSON (structure, order, fit figures).
    pub meta: serde_json::Value,
}

/// One row of the MIMO comparison table.
#[derive(Debug, Clone, Serialize)]
pub struct ComparisonRow {
    /// The speed \[rpm\].
    pub speed_rpm: f64,
    /// Candidate, e.g. `freq ss 12` or `n4sid+pem 12`.
    pub model: String,
    /// State dimension.
    pub order: usize,
    /// Number of unstable poles.
    pub unstable_poles: usize,
    /// Median over the quality band of $\lVert\hat G - \hat P\rVert_2 / \lVert\hat P\rVert_2$ \[%\].
    pub median_norm_error_pct: f64,
    /// Largest over the 16 entries of the median relative entry error \[%\].
    pub max_entry_error_pct: f64,
    /// Bayesian information criterion (lower is better), when known.
    pub bic: Option<f64>,
    /// Closed-loop validation fit of y per axis \[%\] (`xa, xb, ya, yb`), when validated.
    pub fit_y_pct: Option<[f64; 4]>,
    /// Whether this row is the chosen model of its speed.
    pub chosen: bool,
}

/// One closed-loop mode of a Campbell diagram.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ModePoint {
    /// The speed \[rpm\].
    pub speed_rpm: f64,
    /// Natural frequency \[Hz\].
    pub freq_hz: f64,
    /// Damping ratio.
    pub damping: f64,
    /// Whirl direction (as the twin labels it: forward share of the orbit).
    #[serde(serialize_with = "whirl_name")]
    pub whirl: Whirl,
}

fn whirl_name<S: serde::Serializer>(w: &Whirl, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(whirl_str(*w))
}

/// `forward`, `backward` or `none` (planar).
pub fn whirl_str(w: Whirl) -> &'static str {
    match w {
        Whirl::Forward => "forward",
        Whirl::Backward => "backward",
        Whirl::None => "planar",
    }
}

/// One row of the per-axis validation table.
#[derive(Debug, Clone, Serialize)]
pub struct AxisValidationRow {
    /// The speed \[rpm\].
    pub speed_rpm: f64,
    /// Axis (`xa`, `xb`, `ya`, `yb`).
    pub axis: String,
    /// Fit of the displacement y \[%\] (closed-loop simulation against an independent record).
    pub fit_y_pct: f64,
    /// Fit of the coil current i \[%\], when the record has it.
    pub fit_i_pct: Option<f64>,
    /// The exact plant's fit on the same record \[%\] (twin).
    pub truth_fit_y_pct: Option<f64>,
    /// Whether the residual whiteness test passed.
    pub whiteness_ok: Option<bool>,
    /// Whether the residual–input independence test passed.
    pub independence_ok: Option<bool>,
}

/// One row of the ISO 14839-3 table: the peak of $|S_{ii}|$ on one axis at one speed.
#[derive(Debug, Clone, Serialize)]
pub struct IsoRow {
    /// The speed \[rpm\].
    pub speed_rpm: f64,
    /// Axis.
    pub axis: String,
    /// Where the peak comes from: `measured`, `model` or `truth`.
    pub from: String,
    /// Peak $|S_{ii}|$.
    pub peak: f64,
    /// Its frequency \[Hz\].
    pub f_hz: f64,
    /// Zone A–D.
    pub zone: Zone,
}

/// What the models give ([`MachineModels::identify`]); every field may be empty.
#[derive(Debug, Clone, Default)]
pub struct MachineModelOutput {
    /// The chosen model per speed (exported as JSON, `.m`, `.mat`, `.npz`).
    pub models: Vec<SpeedModel>,
    /// The comparison table.
    pub comparison: Vec<ComparisonRow>,
    /// Closed-loop modes of the identified models (the Campbell diagram's measured points).
    pub campbell_points: Vec<ModePoint>,
    /// Closed-loop modes of the speed-scheduled model on a dense speed grid (its curves).
    pub campbell_curves: Vec<ModePoint>,
    /// Per-axis closed-loop validation.
    pub validation: Vec<AxisValidationRow>,
    /// Per-axis ISO zones from the models' loops (added to the measured ones).
    pub iso: Vec<IsoRow>,
    /// Largest singular value of S per speed: (speed \[rpm\], peak σ̄(S), frequency \[Hz\]).
    pub sigma_max_s: Vec<(f64, f64, f64)>,
    /// The chosen model's uncertainty and robust stability per speed (`[machine] uncertainty`).
    pub uncertainty: Vec<UncertaintyRow>,
    /// Notes for the report (e.g. why a speed has no model).
    pub notes: Vec<String>,
}

/// The chosen model's uncertainty at one speed (`[machine] uncertainty = true`): the
/// element-wise bound of `ambid_core::validate::uncertainty::uncertainty_matrix` on the fit's
/// lines, raised by its joint factor, and the robust stability of the four decentralised
/// controllers against it on those lines (`robust_stability_matrix_on_lines`).
#[derive(Debug, Clone, Serialize)]
pub struct UncertaintyRow {
    /// The speed \[rpm\].
    pub speed_rpm: f64,
    /// The fit's band \[Hz\].
    pub band_hz: [f64; 2],
    /// The bound's band \[Hz\]: the fit band and the validation lines above it
    /// (`machine_fit::uncertainty_band`).
    pub bound_band_hz: [f64; 2],
    /// The bound's lines.
    pub lines: usize,
    /// The joint raise applied to the bound on the lines, its check and its export (98 % of the
    /// (line, entry) pairs in 95 % of 2 000 draws; ≥ 1).
    pub raise: f64,
    /// The joint raise of the bound the entry weights are fitted to (95 % of the pairs, the
    /// coverage bar's fraction, on the same draws; ≥ 1, ≤ `raise`).
    pub weight_raise: f64,
    /// Median over the lines of ‖L‖₂ / σ̄(P̂) \[%\].
    pub median_rel_pct: f64,
    /// Largest over the lines of ‖L‖₂ / σ̄(P̂) \[%\].
    pub max_rel_pct: f64,
    /// Nominally stable and ρ(L|M|) < 1 on every line.
    pub robustly_stable: bool,
    /// max ρ(L|M|) and where \[Hz\].
    pub mu_peak: f64,
    /// Where \[Hz\].
    pub mu_peak_hz: f64,
    /// Robust gain margins of all four controllers together (`None`: not robustly stable).
    pub gain_margins: Option<[f64; 2]>,
    /// The exact loop's gain interval (twin).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exact_gain_margins: Option<[f64; 2]>,
    /// Twin: the fraction of the lines in 10–1000 Hz where ‖L‖₂ ≥ σ̄(P − P̂).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth_coverage: Option<f64>,
    /// The structured weight: the highest order of the per-entry relative weights.
    pub weight_max_order: usize,
    /// The median over the entries of their weights' looseness (median |W_ij| / ℓ_ij).
    pub weight_looseness: f64,
    /// Nominally stable and ρ((|P̂|∘|W|)|M|) < 1 on the grid.
    pub weight_robustly_stable: bool,
    /// max ρ((|P̂|∘|W|)|M|) on the grid.
    pub weight_mu_peak: f64,
    /// Where \[Hz\].
    pub weight_mu_peak_hz: f64,
    /// Robust gain margins against the weights (`None`: not robustly stable).
    pub weight_gain_margins: Option<[f64; 2]>,
    /// Twin: the fraction of the lines in 10–1000 Hz where ‖ |P̂|∘|W| ‖₂ ≥ σ̄(P − P̂).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weight_truth_coverage: Option<f64>,
    /// The robust gain margins against coherent draws of the model's error
    /// (`robust_stability_matrix_drawn`; docs/uncertainty.md, "Coherent draws for the
    /// machine"): how many draws, at which confidence, the fraction of the draws stable with
    /// the controllers as they are, and the margins that fraction `coherent_confidence` of the
    /// draws reach (`None`: fewer than that fraction stable).
    pub coherent_draws: usize,
    /// The confidence of the coherent margins (the fraction of the draws they hold for).
    pub coherent_confidence: f64,
    /// The fraction of the draws stable at gain 1.
    pub coherent_stable_fraction: f64,
    /// The coherent margins `[lower, upper]`.
    pub coherent_gain_margins: Option<[f64; 2]>,
    /// The gain interval in which the loop passes the element-wise test against the entry
    /// weights at the frequencies outside the lines, where the draws know nothing; it caps
    /// the coherent margins; it is tested up to an octave beyond the lines.
    pub coherent_outside_gain_interval: Option<[f64; 2]>,
    /// Where \[Hz\] that test fails just below and above its interval (`null` at an end the
    /// nominal loop's interval set).
    pub coherent_outside_critical_hz: [Option<f64>; 2],
    /// The amplitude study's levels whose plant FRFs gave term (e) \[% of i_sat\], the
    /// identification level among them (absent: no study, or the term was left out).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub amplitude_levels_pct: Option<Vec<f64>>,
    /// Term (e)'s size: the median over the lines of σ̄(|E|)/σ̄(P̂) \[%\].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub amplitude_median_rel_pct: Option<f64>,
    /// Term (e) through the model (`MatrixUncertainty::add_projected_shift`): the Wald statistic
    /// of the amplitude shift projected onto the model, its χ² threshold and whether the
    /// projection entered the term (absent: no term (e)).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub amplitude_projected: Option<ambid_core::validate::uncertainty::ProjectedShift>,
    /// Why term (e) was left out, when an amplitude study ran but gave no term, or why its
    /// projection through the model was (the line term then stands alone).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub amplitude_note: Option<String>,
    /// The uncertain model for export (`models/<model>_uncertain.{json,m,mat,npz}`).
    #[serde(skip)]
    pub export: Option<Box<crate::io::export::uncertain_matrix::UncertainMatrixModel>>,
}

/// The seam between the measurement and the MIMO models: one call that takes every speed's FRF
/// and records and returns the models and their figures. The workflow renders a model-dependent
/// section only when this returns its rows.
pub trait MachineModels: Sync {
    /// Identifies (and validates) the models.
    ///
    /// # Errors
    /// An [`Error`] with its class (a computation that failed, data the fitter refuses).
    fn identify(&self, input: &MachineModelInput<'_>) -> Result<MachineModelOutput, Error>;
}

/// A [`MachineModels`] that identifies no model: the report shows the measurement and the
/// twin's truth only.
///
/// ```
/// use ambid::workflow::machine::{MachineModels, MachineModelInput, MeasuredOnly};
/// use ambid_core::validate::iso::IsoZones;
/// let input = MachineModelInput { speeds: &[], controller: None, truth: None, twin: None, noise: true, ts: 5e-5,
///     quality_band_hz: [10.0, 1000.0], zones: IsoZones::default(), seed: 1 };
/// let out = MeasuredOnly.identify(&input).unwrap();
/// assert!(out.models.is_empty() && out.comparison.is_empty());
/// ```
#[derive(Debug, Clone, Copy, Default)]
pub struct MeasuredOnly;

impl MachineModels for MeasuredOnly {
    fn identify(&self, _input: &MachineModelInput<'_>) -> Result<MachineModelOutput, Error> {
        Ok(MachineModelOutput::default())
    }
}

/// Cross-coupling strength of a 4×4 plant at one speed (see [`coupling`]).
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Coupling {
    /// The speed \[rpm\].
    pub speed_rpm: f64,
    /// x–y (gyroscopic) pairs: median over the lines of the band.
    pub xy_median: f64,
    /// x–y pairs: largest over the lines.
    pub xy_max: f64,
    /// A–B pairs (same plane, the two bearings): median over the lines.
    pub ab_median: f64,
    /// A–B pairs: largest over the lines.
    pub ab_max: f64,
    /// Lines used.
    pub lines: usize,
}

/// The x–y pairs (indices into `xa, xb, ya, yb`): every x axis with every y axis.
pub const XY_PAIRS: [(usize, usize); 4] = [(0, 2), (0, 3), (1, 2), (1, 3)];
/// The A–B pairs: the two bearings in one plane.
pub const AB_PAIRS: [(usize, usize); 2] = [(0, 1), (2, 3)];

/// Cross-coupling strength of a 4×4 FRF `p` on the lines in `band` \[Hz\]: per line
///
/// $$\kappa(f) = \max_{(i,j)} \max\left(\frac{|P_{ij}|}{\sqrt{|P_{ii}|\,|P_{jj}|}},
///   \frac{|P_{ji}|}{\sqrt{|P_{ii}|\,|P_{jj}|}}\right)$$
///
/// over the x–y pairs ([`XY_PAIRS`], the gyroscopic coupling, zero at standstill on a symmetric
/// rotor) and, separately, over the A–B pairs ([`AB_PAIRS`], the coupling through the rigid
/// rotor); then its median and largest value over the lines. 0 means decoupled; 1 means an
/// off-diagonal entry as large as the geometric mean of the two diagonal ones.
///
/// ```
/// use ambid::workflow::machine::coupling;
/// use ambid_core::lti::Frd;
/// use ambid_core::c64;
/// // P = diag(1, 1, 2, 2) with P_13 = 0.5 (xa from ya), one line
/// let mut v = vec![c64::new(0.0, 0.0); 16];
/// for (k, d) in [1.0, 1.0, 2.0, 2.0].iter().enumerate() { v[k + 4 * k] = c64::new(*d, 0.0); }
/// v[0 + 4 * 2] = c64::new(0.5, 0.0); // row xa, column ya
/// let p = Frd::new_matrix(vec![100.0], 4, 4, v, None, Some(5e-5)).unwrap();
/// let c = coupling(&p, [10.0, 1000.0], 0.0).unwrap();
/// assert!((c.xy_max - 0.5 / 2f64.sqrt()).abs() < 1e-15);
/// assert_eq!(c.ab_max, 0.0);
/// ```
///
/// # Errors
/// When `p` is not 4×4 or has no line in `band`.
pub fn coupling(p: &Frd, band: [f64; 2], speed_rpm: f64) -> Result<Coupling, Error> {
    if p.ny() != 4 || p.nu() != 4 {
        return Err(Error::input(format!(
            "the cross-coupling needs a 4×4 plant, got {}×{}",
            p.ny(),
            p.nu()
        )));
    }
    let per = 16;
    let v = p.values();
    let mut xy = Vec::new();
    let mut ab = Vec::new();
    for (k, f) in p.f_hz().iter().enumerate() {
        if *f < band[0] || *f > band[1] {
            continue;
        }
        let at = |i: usize, j: usize| v[k * per + i + 4 * j].norm();
        let kappa = |pairs: &[(usize, usize)]| {
            pairs
                .iter()
                .map(|&(i, j)| {
                    let d = (at(i, i) * at(j, j)).sqrt();
                    at(i, j).max(at(j, i)) / d
                })
                .fold(0.0f64, f64::max)
        };
        xy.push(kappa(&XY_PAIRS));
        ab.push(kappa(&AB_PAIRS));
    }
    if xy.is_empty() {
        return Err(Error::input(format!(
            "no line of the FRF ({} lines) lies in the band {}–{} Hz; widen \
             machine.quality_band_hz",
            p.len(),
            band[0],
            band[1]
        )));
    }
    let lines = xy.len();
    Ok(Coupling {
        speed_rpm,
        xy_median: median(&xy),
        xy_max: xy.iter().copied().fold(0.0, f64::max),
        ab_median: median(&ab),
        ab_max: ab.iter().copied().fold(0.0, f64::max),
        lines,
    })
}

fn median(v: &[f64]) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => s[n / 2],
        n => 0.5 * (s[n / 2 - 1] + s[n / 2]),
    }
}

/// Largest relative standard deviation $\sigma_{ii}/|S_{ii}|$ of a line that the measured ISO
/// peak is searched on: lines where the excitation is weak (the nulls of a PRBS at multiples of
/// $f_s/N_b$) carry noise, not the sensitivity.
pub const ISO_MAX_REL_STD: f64 = 0.1;

/// The peak of $|S_{ii}|$ per axis of a measured 4×4 sensitivity, with its frequency and zone,
/// over the lines where $\sigma_{ii} \le$ [`ISO_MAX_REL_STD`] $|S_{ii}|$ (every line when `s`
/// has no variance).
///
/// # Errors
/// When `s` is not 4×4 or empty, or no line of an axis is measured well enough.
pub fn iso_rows(
    s: &Frd,
    speed_rpm: f64,
    zones: &IsoZones,
    from: &str,
) -> Result<Vec<IsoRow>, Error> {
    if s.ny() != 4 || s.nu() != 4 || s.is_empty() {
        return Err(Error::input(format!(
            "the per-axis ISO zone needs a 4×4 sensitivity on at least one line, got {}×{} on {} lines",
            s.ny(),
            s.nu(),
            s.len()
        )));
    }
    (0..4)
        .map(|i| {
            let at = |k: usize| k * 16 + i + 4 * i;
            let good = |k: usize| {
                s.variance()
                    .is_none_or(|v| v[at(k)].sqrt() <= ISO_MAX_REL_STD * s.values()[at(k)].norm())
            };
            let (k, peak) = (0..s.len())
                .filter(|&k| good(k))
                .map(|k| (k, s.values()[at(k)].norm()))
                .fold((usize::MAX, f64::NEG_INFINITY), |a, b| {
                    if b.1 > a.1 {
                        b
                    } else {
                        a
                    }
                });
            if k == usize::MAX {
                return Err(Error::input(format!(
                    "no line of the measured S_{0}{0} at {speed_rpm} rpm has a relative standard \
                     deviation below {ISO_MAX_REL_STD}: the sensitivity is not measured well \
                     enough for an ISO zone; raise machine.level_pct or record more periods",
                    AXES[i]
                )));
            }
            Ok(IsoRow {
                speed_rpm,
                axis: AXES[i].to_string(),
                from: from.to_string(),
                peak,
                f_hz: s.f_hz()[k],
                zone: zones.zone(peak),
            })
        })
        .collect()
}

/// `summary.json`'s `machine`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct MachineSummary {
    /// `twin` or `files`.
    pub source: String,
    /// Speeds \[rpm\].
    pub speeds_rpm: Vec<f64>,
    /// The multi-input design (twin).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub design: Option<String>,
    /// Lines of the FRF per speed.
    pub lines: Vec<usize>,
    /// Cross-coupling per speed, measured.
    pub coupling: Vec<Coupling>,
    /// Cross-coupling per speed of the twin's exact plant on the same lines.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub coupling_truth: Vec<Coupling>,
    /// Median over the quality band of ‖P̂ − P‖₂/‖P‖₂ per speed \[%\] (twin: measured FRF against
    /// the exact plant).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub frf_error_vs_truth_pct: Vec<f64>,
    /// Per-axis ISO rows (measured, truth, models).
    pub iso: Vec<IsoRow>,
    /// The worst zone over every measured axis and speed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst_zone: Option<Zone>,
    /// The comparison table (models).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub comparison: Vec<ComparisonRow>,
    /// Per-axis validation (models).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub validation: Vec<AxisValidationRow>,
    /// Campbell points of the identified models.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub campbell_points: Vec<ModePoint>,
    /// Exported model names.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub models: Vec<String>,
    /// The chosen models' uncertainty per speed (`[machine] uncertainty`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub uncertainty: Vec<UncertaintyRow>,
    /// The whole-machine gray box per speed (`[machine] physical`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub physical: Vec<super::machine_physical::MachinePhysicalRow>,
}

/// SplitMix64 of `seed` and `stream`: independent seeds per speed and experiment.
fn split_seed(seed: u64, stream: u64) -> u64 {
    let mut z = seed.wrapping_add(stream.wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The noise seed of experiment `e` at speed index `k`.
pub fn experiment_seed(seed: u64, k: usize, e: usize) -> u64 {
    split_seed(split_seed(seed, 1000 + k as u64), e as u64)
}

/// Fewest whole periods simulated before each record, and the decay the slowest closed-loop
/// pole must reach (as `ambid simulate --axes 4`).
const SETTLE_PERIODS: usize = 2;
const SETTLE_DECAY: f64 = 1e-13;
const MAX_SETTLE_S: f64 = 20.0;

fn settle_samples(machine: &Machine, period: usize) -> Result<usize, Error> {
    let rho = machine
        .closed_loop_poles()?
        .iter()
        .map(|z| z.norm())
        .fold(0.0f64, f64::max);
    let max = (MAX_SETTLE_S / machine.ts()).round() as usize;
    let need = if rho < 1.0 {
        (SETTLE_DECAY.ln() / rho.ln()).ceil().min(max as f64) as usize
    } else {
        max
    };
    Ok(need.div_ceil(period.max(1)).max(SETTLE_PERIODS) * period)
}

/// The machine configuration of the twin: `[machine] config` (a `MachineConfig` or a
/// single-plane twin configuration lifted to the machine) or the nominal rig, with the
/// section's unbalance, asymmetry and noise.
pub fn machine_config(m: &MachineSection, base: &Path) -> Result<MachineConfig, Error> {
    let mut cfg = match &m.config {
        Some(p) => {
            let path = base.join(p);
            let s = std::fs::read_to_string(&path).map_err(|e| {
                Error::input(format!(
                    "{}: cannot read the machine configuration ({e})",
                    path.display()
                ))
            })?;
            match MachineConfig::from_toml_str(&s) {
                Ok(c) => c,
                Err(e1) => match ambid_twin::TwinConfig::from_toml_str(&s) {
                    Ok(t) => MachineConfig::from_twin(&t),
                    Err(_) => {
                        return Err(Error::input(format!(
                            "{}: neither a machine nor a twin configuration ({e1}); `ambid \
                             config` writes a twin configuration, docs/twin.md describes both",
                            path.display()
                        )))
                    }
                },
            }
        }
        None => MachineConfig::default(),
    };
    if let Some(u) = &m.unbalance {
        cfg.unbalance = Some(u.clone());
    }
    if let Some(a) = &m.asymmetry {
        cfg.asymmetry = a.clone();
    }
    if let Some(n) = m.noise_rms_um {
        cfg.sensor.noise_rms_m = n * 1e-6;
    }
    cfg.validate()?;
    Ok(cfg)
}

/// The multi-input design of the section at sample time `ts` for a machine with `i_sat`.
pub fn machine_design(m: &MachineSection, ts: f64, i_sat: f64) -> Result<MultiInputDesign, Error> {
    let amp = m.level_pct / 100.0 * i_sat;
    let prbs = || {
        BaseSignal::Prbs(PrbsSpec {
            order: m.prbs_order,
            samples_per_bit: m.samples_per_bit,
            periods: m.periods,
            amplitude: amp,
            offset: 0.0,
        })
    };
    let d = match m.design.as_str() {
        "sequential" => MultiInputDesign::sequential(4, prbs()),
        "zipper" => {
            let ms = |rms: f64, seed: u64| MultisineSpec {
                f_min_hz: m.band_hz[0],
                f_max_hz: m.band_hz[1],
                period_samples: (m.period_s / ts).round() as usize,
                periods: m.periods,
                rms,
                grid: Grid::Full,
                phases: Phases::Schroeder,
                seed,
            };
            // linear in the level: scaled so that the largest peak is `amp`
            let unit = MultiInputDesign::zipper(4, ms(1.0, 1)).generate(ts)?;
            let peak = unit
                .samples()
                .iter()
                .flatten()
                .flatten()
                .fold(0.0f64, |a, v| a.max(v.abs()));
            if peak.is_nan() || peak <= 0.0 {
                return Err(Error::usage(
                    "the zippered multisine has no lines: widen machine.band_hz or lengthen \
                     machine.period_s",
                ));
            }
            MultiInputDesign::zipper(4, ms(amp / peak, 1))
        }
        _ => MultiInputDesign::orthogonal(4, prbs()),
    };
    d.validate(ts)?;
    Ok(d)
}

/// The r, u, y channels of `rec` (in that order, axis order) with its period.
fn ruy(rec: &IoData, period: usize, what: &str) -> Result<IoData, Error> {
    let mut ch = Vec::with_capacity(12);
    for q in ["r", "u", "y"] {
        for ax in AXES {
            let name = format!("{q}_{ax}");
            let v = rec.channel(&name).map_err(|_| {
                Error::input(format!(
                    "{what}: the column `{name}` is missing; a 4-axis experiment needs r_, u_ \
                     and y_ of every axis (xa, xb, ya, yb) — the record has: {}",
                    rec.names().join(", ")
                ))
            })?;
            ch.push((name, v.to_vec()));
        }
    }
    Ok(IoData::new(ch, rec.ts(), Some(period))?)
}

/// One speed's FRF, its experiments (1× removed) and the 1× frequency removed.
pub type Measured = (MeasuredFrf, Vec<IoData>, Option<f64>);

/// The 4×4 FRF of the experiments `records` (one speed) with the section's settings
/// ([`measure_records`]; the band only for the zippered design).
fn measure(
    records: Vec<IoData>,
    period: usize,
    m: &MachineSection,
    speed_rpm: f64,
    what: &str,
) -> Result<Measured, Error> {
    let band = (m.design == "zipper").then_some((m.band_hz[0], m.band_hz[1]));
    measure_records(records, period, m.skip_periods, band, speed_rpm, what)
}

/// The 4×4 FRF of the experiments `records` of one speed (channels `r_*`, `u_*`, `y_*` of the
/// four axes, any others kept in the returned records): the 1× line at `speed_rpm`/60 Hz
/// estimated and removed from every channel when `speed_rpm` > 0 (and below Nyquist), then the
/// period average over the periods after the first `skip` ([`mimo::estimate`]: several
/// experiments are solved per line, one zippered experiment column by column on its lines;
/// `band` limits the lines). Returns the FRF (plant, T_ry, S with variances), the experiments
/// with the 1× line removed and the 1× frequency removed. `what` names the data in errors.
///
/// # Errors
/// A missing channel, experiments that do not fit together, a 1× line or an FRF that cannot be
/// estimated (each naming `what`).
pub fn measure_records(
    records: Vec<IoData>,
    period: usize,
    skip: usize,
    band: Option<(f64, f64)>,
    speed_rpm: f64,
    what: &str,
) -> Result<Measured, Error> {
    let exps = records
        .iter()
        .map(|r| ruy(r, period, what))
        .collect::<Result<Vec<_>, _>>()?;
    let data = IoData::from_experiments(exps)?;
    let full = IoData::from_experiments(records)?;
    let f1 = speed_rpm / 60.0;
    let fs = data.fs();
    let (data, full, sync) = if speed_rpm > 0.0 && f1 < 0.5 * fs {
        let opts = SynchronousOptions::new().period(period).skip(skip);
        let line = synchronous(&data, f1, &opts)
            .map_err(|e| Error::from(e).context(format!("{what}: the 1× line at {f1} Hz")))?;
        let clean = line.remove(&data)?;
        let full_line = synchronous(&full, f1, &opts)?;
        (clean, full_line.remove(&full)?, Some(line))
    } else {
        (data, full, None)
    };
    let mut opts = MimoOptions::new().period(period).skip(skip);
    if let Some((lo, hi)) = band {
        opts = opts.band(lo, hi);
    }
    let mut est = mimo::estimate(&data, &opts)
        .map_err(|e| Error::from(e).context(format!("{what}: the MIMO FRF")))?;
    // what the 1× removal leaves at the lines beside it, which the periods' spread misses
    if let Some(line) = &sync {
        line.widen_estimate(&mut est, fs, period)?;
    }
    let n = full.n_experiments();
    let exps = (0..n)
        .map(|e| full.experiment(e))
        .collect::<Result<Vec<_>, _>>()?;
    Ok((
        MeasuredFrf {
            plant: est.plant,
            t_ry: Some(est.t_ry),
            s: Some(est.s),
        },
        exps,
        sync.map(|l| l.f_sync_hz),
    ))
}

/// Everything acquired, before the models.
pub struct MachineData {
    /// Per speed.
    pub speeds: Vec<SpeedMeasurement>,
    /// The twin's truth per speed (source = twin).
    pub truth: Option<Vec<SpeedTruth>>,
    /// The twin's configuration (source = twin), for the Campbell curves of the truth.
    pub twin: Option<MachineConfig>,
    /// The twin's physics (source = twin).
    pub mode: Option<Mode>,
    /// Sample time \[s\].
    pub ts: f64,
}

/// Runs the design on the twin at every speed (speeds and experiments in parallel, each
/// experiment from its own seed, so the numbers do not depend on the thread count).
pub fn acquire_twin(m: &MachineSection, base: &Path, seed: u64) -> Result<MachineData, Error> {
    acquire_twin_config(machine_config(m, base)?, m, seed)
}

/// [`acquire_twin`] on the machine `cfg0` as given (the section's `config`, `unbalance`,
/// `asymmetry` and `noise_rms_um` are not applied; its speeds, design, mode, noise switch and
/// periods are).
pub fn acquire_twin_config(
    cfg0: MachineConfig,
    m: &MachineSection,
    seed: u64,
) -> Result<MachineData, Error> {
    cfg0.validate()?;
    let speeds = m.speeds();
    let mode = if m.mode == "linear" {
        Mode::Linear
    } else {
        Mode::Nonlinear
    };
    let machines = speeds
        .iter()
        .map(|&speed_rpm| {
            Machine::new(MachineConfig {
                speed_rpm,
                ..cfg0.clone()
            })
            .map_err(Error::from)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let ts = machines.first().map_or(5e-5, Machine::ts);
    let design = machine_design(m, ts, machines.first().map_or(1.0, Machine::i_sat))?;
    let period = design.base.period_samples()?;
    let settle = machines
        .iter()
        .map(|mc| settle_samples(mc, period))
        .collect::<Result<Vec<_>, _>>()?;
    let twin = TwinRun {
        machines: &machines,
        settle: &settle,
        mode,
        noise: m.noise,
    };
    let (per_speed, saturated): (Vec<Vec<IoData>>, Vec<f64>) =
        twin.records(&design, ts, seed)?.into_iter().unzip();
    let mut studies = amplitude_study(m, &twin, &speeds, seed)?;
    // the measurements, and beside them the true loops' peak sensitivities (a dense frequency
    // grid each)
    let (measured, peaks): (Vec<Result<Measured, Error>>, Vec<Result<_, Error>>) = rayon::join(
        || {
            per_speed
                .into_par_iter()
                .zip(speeds.par_iter())
                .map(|(recs, &s)| measure(recs, period, m, s, &format!("the twin at {s} rpm")))
                .collect()
        },
        || {
            machines
                .par_iter()
                .map(|mc| mc.peak_sensitivity().map_err(Error::from))
                .collect()
        },
    );
    let mut out = Vec::with_capacity(speeds.len());
    let mut truth = Vec::with_capacity(speeds.len());
    for (((res, &speed_rpm), mc), peak) in
        measured.into_iter().zip(&speeds).zip(&machines).zip(peaks)
    {
        let (frf, records, sync) = res?;
        out.push(SpeedMeasurement {
            speed_rpm,
            frf,
            records,
            source: "twin".into(),
            sync_removed_hz: sync,
            period_samples: period,
            level_pct: Some(m.level_pct),
            amplitude: std::mem::take(&mut studies[out.len()]),
            saturated_fraction: Some(saturated[out.len()]),
        });
        truth.push(SpeedTruth {
            speed_rpm,
            plant: mc.plant().clone(),
            controller: mc.controller().clone(),
            peak_sensitivity: peak?,
        });
    }
    Ok(MachineData {
        speeds: out,
        truth: Some(truth),
        twin: Some(cfg0),
        mode: Some(mode),
        ts,
    })
}

/// The machines of a twin acquisition, one per speed, with their pre-rolls and physics.
struct TwinRun<'a> {
    machines: &'a [Machine],
    settle: &'a [usize],
    mode: Mode,
    noise: bool,
}

impl TwinRun<'_> {
    /// The experiments of `design` on every machine (speeds and experiments in parallel,
    /// experiment `e` at speed `k` from the noise seed `experiment_seed(seed, k, e)`, so the
    /// numbers do not depend on the thread count): per speed the records and the largest
    /// fraction of samples where an axis' controller output hit ±i_sat.
    fn records(
        &self,
        design: &MultiInputDesign,
        ts: f64,
        seed: u64,
    ) -> Result<Vec<(Vec<IoData>, f64)>, Error> {
        let exc = design.generate(ts)?;
        let period = design.base.period_samples()?;
        let samples = exc.samples();
        let jobs: Vec<(usize, usize)> = (0..self.machines.len())
            .flat_map(|k| (0..exc.n_experiments()).map(move |e| (k, e)))
            .collect();
        let recs: Vec<Result<(IoData, f64), Error>> = jobs
            .par_iter()
            .map(|&(k, e)| {
                let r = &samples[e];
                let opts = MachineSimOptions {
                    mode: self.mode,
                    seed: experiment_seed(seed, k, e),
                    noise: self.noise,
                    w: None,
                    settle_samples: self.settle[k],
                };
                let rec = self.machines[k].simulate([&r[0], &r[1], &r[2], &r[3]], &opts)?;
                let sat = rec
                    .meta
                    .saturated_fraction
                    .iter()
                    .fold(0.0f64, |a, b| a.max(*b));
                Ok((rec.to_iodata(Some(period))?, sat))
            })
            .collect();
        let mut per_speed: Vec<(Vec<IoData>, f64)> = vec![(Vec::new(), 0.0); self.machines.len()];
        for ((k, _), r) in jobs.iter().zip(recs) {
            let (rec, sat) = r?;
            per_speed[*k].0.push(rec);
            per_speed[*k].1 = per_speed[*k].1.max(sat);
        }
        Ok(per_speed)
    }
}

/// The amplitude study on the twin (`[machine] amplitude_levels_pct`): the identification design
/// at each level and every speed of `twin`, each experiment from its own seed (level $l$: the
/// experiments' seeds of base seed `seed` + 7 919 (l + 1)); per speed the levels' plant FRFs in
/// increasing level, with their saturated fractions. No level: empty lists.
fn amplitude_study(
    m: &MachineSection,
    twin: &TwinRun<'_>,
    speeds: &[f64],
    seed: u64,
) -> Result<Vec<Vec<LevelFrf>>, Error> {
    let mut levels = m.amplitude_levels();
    levels.sort_by(f64::total_cmp);
    let mut out: Vec<Vec<LevelFrf>> = vec![Vec::new(); twin.machines.len()];
    let Some(first) = twin.machines.first() else {
        return Ok(out);
    };
    for (l, &pct) in levels.iter().enumerate() {
        let at = MachineSection {
            level_pct: pct,
            ..m.clone()
        };
        let design = machine_design(&at, first.ts(), first.i_sat())?;
        let period = design.base.period_samples()?;
        let base = seed.wrapping_add(7919 * (l as u64 + 1));
        let plants: Vec<Result<LevelFrf, Error>> = twin
            .records(&design, first.ts(), base)?
            .into_par_iter()
            .zip(speeds.par_iter())
            .map(|((recs, sat), &s)| {
                let what = format!("the twin's amplitude study at {s} rpm, {pct} % of i_sat");
                let (frf, _, _) = measure(recs, period, m, s, &what)?;
                Ok(LevelFrf {
                    level_pct: pct,
                    plant: frf.plant,
                    saturated_fraction: sat,
                })
            })
            .collect();
        for (k, p) in plants.into_iter().enumerate() {
            out[k].push(p?);
        }
    }
    Ok(out)
}

/// Reads the recorded experiments of `[[machine.files]]`.
pub fn acquire_files(m: &MachineSection, base: &Path) -> Result<MachineData, Error> {
    let mut speeds = Vec::with_capacity(m.files.len());
    let mut ts: Option<f64> = None;
    for f in &m.files {
        let path = base.join(&f.path);
        let s = if path.is_dir() {
            read_experiment_dir(&path, f.speed_rpm, m)?
        } else {
            read_machine_frf(&path, f.speed_rpm)?
        };
        let t = s.frf.plant.ts().unwrap_or(f64::NAN);
        if let Some(t0) = ts {
            if ((t - t0) / t0).abs() > 1e-9 {
                return Err(Error::input(format!(
                    "{} is sampled at {} Hz, the first speed's data at {} Hz: every speed must be \
                     recorded at one sample rate",
                    path.display(),
                    1.0 / t,
                    1.0 / t0
                )));
            }
        }
        ts = Some(t);
        speeds.push(s);
    }
    Ok(MachineData {
        speeds,
        truth: None,
        twin: None,
        mode: None,
        ts: ts.unwrap_or(f64::NAN),
    })
}

/// A directory as `ambid simulate --axes 4` writes it: `exp<k>/data.csv` and `meta.json`.
fn read_experiment_dir(
    dir: &Path,
    speed_rpm: f64,
    m: &MachineSection,
) -> Result<SpeedMeasurement, Error> {
    let meta_path = dir.join("meta.json");
    let meta: serde_json::Value = match std::fs::read_to_string(&meta_path) {
        Ok(s) => serde_json::from_str(&s)
            .map_err(|e| Error::input(format!("{}: not valid JSON ({e})", meta_path.display())))?,
        Err(e) => {
            return Err(Error::input(format!(
                "{}: cannot read it ({e}); a directory of [[machine.files]] is one as `ambid \
                 simulate --axes 4 --out DIR` writes it (exp1/data.csv … and meta.json with \
                 speed_rpm and period_samples), or give the matrix FRF CSV of `ambid frf` instead",
                meta_path.display()
            )))
        }
    };
    if let Some(s) = meta.get("speed_rpm").and_then(serde_json::Value::as_f64) {
        if (s - speed_rpm).abs() > 1e-9 * s.abs().max(1.0) {
            return Err(Error::input(format!(
                "{}: the records were made at speed_rpm = {s}, but [[machine.files]] gives \
                 speed_rpm = {speed_rpm} for them; write speed_rpm = {s} (or point the entry at \
                 the directory of {speed_rpm} rpm)",
                meta_path.display()
            )));
        }
    }
    let period = meta
        .get("period_samples")
        .and_then(serde_json::Value::as_u64)
        .map(|p| p as usize)
        .filter(|p| *p >= 1)
        .ok_or_else(|| {
            Error::input(format!(
                "{}: no period_samples (the samples per excitation period); the MIMO FRF averages \
                 periods of a periodic design",
                meta_path.display()
            ))
        })?;
    let mut exps: Vec<(usize, PathBuf)> = std::fs::read_dir(dir)
        .map_err(|e| Error::input(format!("{}: cannot list it ({e})", dir.display())))?
        .filter_map(|d| d.ok())
        .filter_map(|d| {
            let name = d.file_name().to_string_lossy().into_owned();
            let k: usize = name.strip_prefix("exp")?.parse().ok()?;
            Some((k, d.path().join("data.csv")))
        })
        .collect();
    exps.sort();
    if exps.is_empty() {
        return Err(Error::input(format!(
            "{}: no experiment directory exp1, exp2, …; give the directory `ambid simulate --axes \
             4 --out DIR` wrote",
            dir.display()
        )));
    }
    let mut records = Vec::with_capacity(exps.len());
    for (_, p) in &exps {
        let d = crate::io::read_time(p, &crate::io::TimeOptions::with_fs(None))?;
        let mut ch = Vec::new();
        for q in ["r", "u", "y", "i"] {
            for ax in AXES {
                let c = format!("{q}_{ax}");
                if d.has(&c) {
                    ch.push((c.clone(), d.column(&c)?.to_vec()));
                } else if q != "i" {
                    return Err(Error::input(format!(
                        "{}: the column `{c}` is missing; a 4-axis experiment needs r_, u_ and y_ \
                         for every axis (xa, xb, ya, yb) — the file has: {}",
                        p.display(),
                        d.names.join(", ")
                    )));
                }
            }
        }
        records.push(IoData::new(ch, d.ts, Some(period))?);
    }
    let what = dir.display().to_string();
    let (frf, records, sync) = measure(records, period, m, speed_rpm, &what)?;
    Ok(SpeedMeasurement {
        speed_rpm,
        frf,
        records,
        source: what,
        sync_removed_hz: sync,
        period_samples: period,
        level_pct: None,
        amplitude: Vec::new(),
        saturated_fraction: None,
    })
}

/// The 4×4 matrix of quantity `q` from an FRF file, or the list of its missing entries.
fn matrix_from_file(
    file: &crate::io::csv::FrfFile,
    q: &str,
    ts: f64,
) -> Result<Result<Frd, Vec<String>>, Error> {
    let mut missing = Vec::new();
    let mut cols = Vec::with_capacity(16);
    for (j, ain) in AXES.iter().enumerate() {
        for (i, aout) in AXES.iter().enumerate() {
            let name = format!("{q}_{aout}_{ain}");
            if file.quantities.contains(&name) {
                cols.push((i, j, file.frd(&name, ts)?));
            } else {
                missing.push(name);
            }
        }
    }
    if !missing.is_empty() {
        return Ok(Err(missing));
    }
    let nl = file.f_hz.len();
    let mut values = vec![ambid_core::c64::new(0.0, 0.0); nl * 16];
    let mut var = vec![0.0; nl * 16];
    let mut any_var = false;
    for (i, j, g) in &cols {
        for k in 0..nl {
            values[k * 16 + i + 4 * j] = g.values()[k];
            if let Some(v) = g.variance() {
                var[k * 16 + i + 4 * j] = v[k];
                any_var = true;
            }
        }
    }
    Ok(Ok(Frd::new_matrix(
        file.f_hz.clone(),
        4,
        4,
        values,
        any_var.then_some(var),
        Some(ts),
    )?))
}

/// A matrix FRF CSV as `ambid frf` writes it (P, T_ry, S of the 4 axes; P required, with the
/// sample rate in its `fs_hz` column), measured at `speed_rpm`.
///
/// # Errors
/// An input error naming the file and what is missing (the sample rate, entries of the 4×4
/// plant), or the file's read error.
pub fn read_machine_frf(path: &Path, speed_rpm: f64) -> Result<SpeedMeasurement, Error> {
    let file = crate::io::csv::read_frf_csv(path)
        .map_err(|e| Error::classified(FailureClass::Input, e))?;
    let fs = file
        .extra("fs_hz")
        .ok()
        .and_then(|c| c.first().copied())
        .filter(|v| v.is_finite() && *v > 0.0)
        .ok_or_else(|| {
            Error::input(format!(
                "{}: no `fs_hz` column (the sample rate); `ambid frf` writes it — add a column \
                 fs_hz with the sample rate in Hz on every row",
                path.display()
            ))
        })?;
    let ts = 1.0 / fs;
    let plant = match matrix_from_file(&file, "P", ts)? {
        Ok(p) => p,
        Err(missing) => {
            return Err(Error::input(format!(
                "{}: the 4×4 plant FRF has {} missing entr{} ({}): a whole-machine FRF file needs \
                 P_<out>_<in>_re, _im (and _std) for every pair of the axes xa, xb, ya, yb; write \
                 it with `ambid frf` from all four experiments of the design (or the zippered \
                 one), or give the experiment directories instead",
                path.display(),
                missing.len(),
                if missing.len() == 1 { "y" } else { "ies" },
                missing.join(", ")
            )))
        }
    };
    let t_ry = matrix_from_file(&file, "T_ry", ts)?.ok();
    let s = matrix_from_file(&file, "S", ts)?.ok();
    Ok(SpeedMeasurement {
        speed_rpm,
        frf: MeasuredFrf { plant, t_ry, s },
        records: Vec::new(),
        source: path.display().to_string(),
        sync_removed_hz: None,
        period_samples: 0,
        level_pct: None,
        amplitude: Vec::new(),
        saturated_fraction: None,
    })
}

/// The whole-machine outcome beside the report (for callers and tests).
pub struct MachineOutcome {
    /// The acquired data.
    pub data: MachineData,
    /// What the models gave.
    pub models: MachineModelOutput,
    /// The typed summary (`summary.json`'s `machine`).
    pub summary: MachineSummary,
}

/// Runs the whole-machine procedure with the models of `fitter` (see the module docs).
///
/// # Errors
/// An [`Error`] with its class.
pub fn run_with(
    cfg: &WorkflowConfig,
    base: &Path,
    progress: &mut Progress,
    fitter: &dyn MachineModels,
) -> Result<(Outcome, MachineOutcome), Error> {
    let m = cfg.machine.clone().unwrap_or_default();
    m.check(Path::new("workflow file"), false)?;
    let seed = m.seed.unwrap_or(cfg.seed);
    let zones = IsoZones {
        a: cfg.iso.a,
        b: cfg.iso.b,
        c: cfg.iso.c,
    };
    progress.total = if m.physical { 4 } else { 3 };
    let t0 = Instant::now();
    progress.start("machine data");
    let data = if m.from_files() {
        acquire_files(&m, base)?
    } else {
        acquire_twin(&m, base, seed)?
    };
    let t_data = t0.elapsed().as_secs_f64();
    progress.finish("machine data", t_data, "done");
    let t1 = Instant::now();
    progress.start("machine models");
    let controller = data
        .truth
        .as_ref()
        .and_then(|t| t.first())
        .map(|t| &t.controller);
    let input = MachineModelInput {
        speeds: &data.speeds,
        controller,
        truth: data.truth.as_deref(),
        twin: data.twin.as_ref().zip(data.mode),
        noise: m.noise,
        ts: data.ts,
        quality_band_hz: m.quality_band_hz,
        zones,
        seed,
    };
    let models = fitter.identify(&input)?;
    let t_models = t1.elapsed().as_secs_f64();
    progress.finish("machine models", t_models, "done");
    let t2 = Instant::now();
    progress.start("machine report");
    let (mut sections, mut summary) = super::machine_render::sections(&m, &data, &models, &zones)?;
    let t_report = t2.elapsed().as_secs_f64();
    progress.finish("machine report", t_report, "done");
    let mut t_physical = None;
    if m.physical {
        let t3 = Instant::now();
        progress.start("machine physical");
        let rows = super::machine_physical::machine_physical(&m, base, &data)?;
        sections.push(super::machine_physical::physical_section(&rows));
        summary.physical = rows;
        let t = t3.elapsed().as_secs_f64();
        progress.finish("machine physical", t, "done");
        t_physical = Some(t);
    }
    let timings = vec![
        StepTime {
            step: "machine_data".into(),
            seconds: t_data,
            status: "done".into(),
        },
        StepTime {
            step: "machine_models".into(),
            seconds: t_models,
            status: "done".into(),
        },
        StepTime {
            step: "machine_report".into(),
            seconds: t_report,
            status: "done".into(),
        },
    ];
    let mut timings = timings;
    if let Some(t) = t_physical {
        timings.push(StepTime {
            step: "machine_physical".into(),
            seconds: t,
            status: "done".into(),
        });
    }
    let mut typed = super::Summary::default();
    let total: f64 = timings.iter().map(|t| t.seconds).sum();
    typed.timing.insert("total_s".into(), total);
    for t in &timings {
        typed.timing.insert(format!("{}_s", t.step), t.seconds);
    }
    typed
        .timing
        .insert("wall_s".into(), t0.elapsed().as_secs_f64());
    typed.machine = Some(summary.clone());
    let json = serde_json::to_value(&typed)
        .map_err(|e| Error::computation(format!("summary.json: {e}")))?;
    let model_outs: Vec<ModelOut> = models
        .models
        .iter()
        .map(|sm| {
            let mut meta = sm.meta.clone();
            if let Some(o) = meta.as_object_mut() {
                o.insert("speed_rpm".into(), sm.speed_rpm.into());
                o.insert(
                    "inputs".into(),
                    AXES.iter()
                        .map(|a| format!("u_{a}"))
                        .collect::<Vec<_>>()
                        .into(),
                );
                o.insert(
                    "outputs".into(),
                    AXES.iter()
                        .map(|a| format!("y_{a}"))
                        .collect::<Vec<_>>()
                        .into(),
                );
            }
            ModelOut {
                name: sm.name.clone(),
                ss: sm.model.clone(),
                poly: None,
                kalman: None,
                meta,
            }
        })
        .collect();
    let speeds_txt = m
        .speeds()
        .iter()
        .map(|s| format!("{s}"))
        .collect::<Vec<_>>()
        .join(", ");
    let report = Report {
        title: cfg.title.clone().unwrap_or_else(|| {
            if m.from_files() {
                "ambid: whole-machine identification report".into()
            } else {
                "ambid: whole-machine identification of the embedded 4-axis twin".into()
            }
        }),
        subtitle: format!(
            "ambid {} · seed {} · {} · 4 axes (xa, xb, ya, yb) at {speeds_txt} rpm",
            env!("CARGO_PKG_VERSION"),
            seed,
            if m.from_files() {
                "recorded files"
            } else {
                "embedded 4-axis twin"
            }
        ),
        sections,
    };
    let uncertain_models = models
        .uncertainty
        .iter()
        .filter_map(|row| {
            let u = row.export.as_ref()?;
            let name = models
                .models
                .iter()
                .find(|m| m.speed_rpm == row.speed_rpm)
                .map_or_else(
                    || format!("plant_{:.0}rpm", row.speed_rpm),
                    |m| m.name.clone(),
                );
            Some((
                crate::io::export::mimo::MimoNames::axes(
                    &format!("{name}_uncertain"),
                    &AXES,
                    Some(row.speed_rpm),
                ),
                (**u).clone(),
            ))
        })
        .collect();
    let outcome = Outcome {
        report,
        stages: typed,
        summary: json,
        models: model_outs,
        uncertain_models,
        timings,
        excitation: None,
        operating_point: None,
        bla: None,
        models_stage: None,
        pole_zero_stage: None,
        validation_stage: None,
        reconstruction_stage: None,
        iso_stage: None,
        frf_stage: None,
        order_stage: None,
    };
    Ok((
        outcome,
        MachineOutcome {
            data,
            models,
            summary,
        },
    ))
}

/// A note block.
pub(crate) fn note(kind: NoteKind, text: impl Into<String>) -> Block {
    Block::Note {
        kind,
        text: text.into(),
    }
}

/// A section.
pub(crate) fn section(id: &str, title: &str, blocks: Vec<Block>) -> Section {
    Section {
        id: id.into(),
        title: title.into(),
        blocks,
    }
}
