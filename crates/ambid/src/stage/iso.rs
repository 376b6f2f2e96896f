//! The ISO 14839-3 stage: the zone of the peak sensitivity $\max_f |S(f)|$ of the measured
//! $S = T_{ru}$ (with its 95 % interval), of the chosen model closed with the controller
//! ($S = 1/(1 + P C)$) and, on the twin, of the exact loop.

use super::{Recording, TwinSource};
use crate::analysis::FrfAnalysis;
use crate::error::{Error, FailureClass, Result};
use crate::validation::ValidationOutcome;
use ambid_core::c64;
use ambid_core::frf::band::{iso_search, BandRule, IsoSearch};
use ambid_core::lti::Frd;
use ambid_core::validate::iso::{sensitivity_zone, IsoVerdict, IsoZones, Zone};

fn computation(e: impl Into<Error>) -> Error {
    Error::classified(FailureClass::Computation, e)
}

/// The ISO stage's input.
pub struct IsoInput<'a> {
    /// Zone limits A/B, B/C, C/D on $|S|$.
    pub zones: IsoZones,
    /// The nonparametric FRF of the identification record (its $T_{ru}$ is the measured $S$).
    pub frf: Option<&'a FrfAnalysis>,
    /// The identification record: the measured $S$ is used only for closed-loop data with an
    /// excitation $r$.
    pub identification: Option<&'a Recording>,
    /// The chosen model's closed-loop validation (its $S$ on a grid and its zone).
    pub validation: Option<&'a ValidationOutcome>,
    /// The twin (the exact $S$).
    pub twin: Option<&'a TwinSource>,
}

/// The measured sensitivity and its verdict.
#[derive(Debug, Clone)]
pub struct MeasuredSensitivity {
    /// $S = T_{ru}$ with its variance.
    pub s: Frd,
    /// The peak searched over the lines of the FRF band where $S$ is known to ±10 %.
    pub search: IsoSearch,
}

/// A sensitivity on a frequency grid and its verdict.
#[derive(Debug, Clone)]
pub struct GridSensitivity {
    /// Frequencies \[Hz\].
    pub f_hz: Vec<f64>,
    /// $S$ on `f_hz`.
    pub s: Vec<c64>,
    /// The zone of its peak.
    pub verdict: IsoVerdict,
}

/// The ISO stage's output.
#[derive(Debug, Clone)]
pub struct IsoStage {
    /// The zone limits.
    pub zones: IsoZones,
    /// From the measured $S$ (closed-loop data with an excitation).
    pub measured: Option<MeasuredSensitivity>,
    /// From the chosen model with the controller.
    pub model: Option<GridSensitivity>,
    /// The chosen model's phase margin \[deg\].
    pub model_phase_margin_deg: Option<f64>,
    /// From the twin's exact loop (2000 log-spaced lines, 1 Hz to 0.49 fs).
    pub truth: Option<GridSensitivity>,
}

impl IsoStage {
    /// The verdict: the measured zone when there is one, else the model's (never the truth's).
    pub fn verdict(&self) -> Option<Zone> {
        self.measured
            .as_ref()
            .map(|m| m.search.verdict.zone)
            .or(self.model.as_ref().map(|m| m.verdict.zone))
    }

    /// Why there is nothing to judge, when there is neither a measured $S$ nor a model's or the
    /// truth's.
    pub fn not_done(&self) -> Option<String> {
        (self.measured.is_none() && self.model.is_none() && self.truth.is_none()).then(|| {
            "the ISO 14839-3 zone needs the measured sensitivity (closed-loop data with an excitation) or a model validated with the controller".into()
        })
    }
}

/// The ISO 14839-3 stage: the peak $|S|$ and its zone from each available source.
///
/// ```
/// use ambid::stage::{iso, IsoInput, TwinSource};
/// use ambid_twin::{Mode, TwinConfig};
/// let twin = TwinSource::new(TwinConfig::default(), Mode::Linear).unwrap();
/// let st = iso(&IsoInput { zones: Default::default(), frf: None, identification: None, validation: None, twin: Some(&twin) }).unwrap();
/// let t = st.truth.as_ref().unwrap();
/// // the peak is the largest |S| on the grid
/// let peak = t.s.iter().map(|s| s.norm()).fold(0.0, f64::max);
/// assert!((t.verdict.peak - peak).abs() <= 1e-12 * peak);
/// assert!(st.verdict().is_none()); // the truth alone gives no verdict
/// ```
///
/// # Errors
/// A computation error when the measured $S$ cannot be searched or the twin's $S$ cannot be
/// computed.
pub fn iso(input: &IsoInput<'_>) -> Result<IsoStage> {
    let z = input.zones;
    let measured = match (
        input.frf,
        input
            .identification
            .is_some_and(|r| r.r().is_some() && r.closed_loop),
    ) {
        (Some(a), true) => {
            let s = &a.frf.t_ru;
            let search =
                iso_search(s, a.bands.band, &BandRule::default(), &z).map_err(computation)?;
            Some(MeasuredSensitivity {
                s: s.clone(),
                search,
            })
        }
        _ => None,
    };
    let (model, model_phase_margin_deg) = match input.validation {
        Some(v) => (
            Some(GridSensitivity {
                f_hz: v.grid_hz.clone(),
                s: v.s_model.clone(),
                verdict: v.iso_model.clone(),
            }),
            v.margins.phase_margin(),
        ),
        None => (None, None),
    };
    let truth = match input.twin {
        Some(t) => {
            let f: Vec<f64> = (0..2000)
                .map(|k| 1.0 * (0.49 * t.twin.fs()).powf(k as f64 / 1999.0))
                .collect();
            let s: Vec<c64> = t.twin.sensitivity_frf(&f).map_err(computation)?;
            let frd =
                Frd::new(f.clone(), s.clone(), None, Some(t.twin.ts())).map_err(computation)?;
            let verdict = sensitivity_zone(&frd, &z).map_err(computation)?;
            Some(GridSensitivity {
                f_hz: f,
                s,
                verdict,
            })
        }
        None => None,
    };
    Ok(IsoStage {
        zones: z,
        measured,
        model,
        model_phase_margin_deg,
        truth,
    })
}
