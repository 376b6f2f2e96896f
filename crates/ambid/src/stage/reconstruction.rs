//! The reconstruction stage (seed paper, section 4): the chosen model closed with the real
//! controller and driven by a chirp position reference, against the measured loop — the fit of
//! the displacement and the controller output, per time window and against the chirp's
//! instantaneous frequency, with the worst window.

use super::validation::validation_settings;
use super::{Recording, Seeds, TwinSource};
use crate::config::{ReconstructionSection, ValidationSection};
use crate::error::{Error, FailureClass, Result};
use crate::io::ControllerModel;
use crate::validation::{
    chirp_frequency, validate_closed_loop, worst_window, MeasuredLoop, ValidationOutcome,
    ValidationSettings, WorstWindow,
};
use ambid_core::lti::StateSpace;
use ambid_core::validate::closed_loop::WindowFit;
use ambid_core::validate::iso::IsoZones;

/// The offset of the twin's noise seed in the chirp record from the workflow seed (`s + 500`).
pub const RECONSTRUCTION_SEED_OFFSET: u64 = 500;

/// The seed of the twin's noise in the chirp record of a run with `seeds`.
///
/// ```
/// let s = ambid::stage::Seeds::from_workflow_seed(42);
/// assert_eq!(ambid::stage::reconstruction_seed(&s), 542);
/// ```
pub fn reconstruction_seed(seeds: &Seeds) -> u64 {
    seeds.workflow.wrapping_add(RECONSTRUCTION_SEED_OFFSET)
}

/// Where the chirp record comes from.
pub enum ReconstructionSource<'a> {
    /// Simulated on the twin with the chirp of the input's `chirp` as position reference and
    /// the twin's noise from `seed`.
    Twin {
        /// The twin.
        twin: &'a TwinSource,
        /// Seed of the twin's noise ([`reconstruction_seed`]).
        seed: u64,
    },
    /// A recorded file with the position reference `w`.
    Record(&'a Recording),
}

/// The reconstruction stage's input.
pub struct ReconstructionInput<'a> {
    /// The model's name.
    pub name: &'a str,
    /// The model (plant input u to output y).
    pub model: &'a StateSpace,
    /// The loop's controller.
    pub controller: &'a ControllerModel,
    /// `[reconstruction]`: the chirp (amplitude, band, duration) simulated on the twin.
    pub chirp: &'a ReconstructionSection,
    /// `[validation]`: windows and initial state (no start-up is skipped here).
    pub settings: &'a ValidationSection,
    /// ISO 14839-3 zone limits.
    pub zones: IsoZones,
    /// The chirp record.
    pub source: ReconstructionSource<'a>,
}

/// The reconstruction stage's output.
#[derive(Debug, Clone)]
pub struct ReconstructionStage {
    /// The model's name.
    pub model: String,
    /// Where the record came from (`the twin`, or the file).
    pub source: String,
    /// Sample time \[s\].
    pub ts: f64,
    /// The position reference w.
    pub w: Vec<f64>,
    /// The measured displacement y.
    pub y: Vec<f64>,
    /// The measured controller output u.
    pub u: Vec<f64>,
    /// The closed-loop simulation with the model and its fits (whole record, nothing skipped).
    pub outcome: ValidationOutcome,
    /// The worst window ([`worst_window`]), if any window is judged.
    pub worst: Option<WorstWindow>,
    /// The chirp's instantaneous frequency per sample \[Hz\] ([`chirp_frequency`]); `None` when
    /// the reference is not a rising sweep.
    pub frequency: Option<Vec<f64>>,
    /// Per window: the RMS of the measured y about its mean.
    pub window_signal_rms: Vec<f64>,
}

impl ReconstructionStage {
    /// The windows' fits.
    pub fn windows(&self) -> &[WindowFit] {
        &self.outcome.reconstruction.windows
    }

    /// The sample nearest time `t` \[s\] (clamped to the record).
    pub fn sample_at(&self, t: f64) -> usize {
        ((t / self.ts).round().max(0.0) as usize).min(self.y.len().saturating_sub(1))
    }

    /// The chirp's frequency range \[Hz\] over a window, when the frequency is known.
    pub fn window_frequency(&self, wf: &WindowFit) -> Option<(f64, f64)> {
        self.frequency
            .as_ref()
            .map(|f| (f[self.sample_at(wf.t_s.0)], f[self.sample_at(wf.t_s.1)]))
    }

    /// The worst window's fit, when there is one.
    pub fn worst_fit(&self) -> Option<&WindowFit> {
        self.worst.as_ref().map(|w| &self.windows()[w.index])
    }
}

/// The reconstruction stage: the chirp record (simulated on the twin, or the file's), the model
/// closed with the controller and driven by its reference $w$
/// ([`validate_closed_loop`] with nothing skipped), the worst window and the chirp's
/// instantaneous frequency.
///
/// ```
/// use ambid::stage::{reconstruction, ReconstructionInput, ReconstructionSource, TwinSource};
/// use ambid::workflow::config::{ReconstructionSection, ValidationSection};
/// use ambid_twin::{Mode, TwinConfig};
/// let twin = TwinSource::new(TwinConfig::default(), Mode::Linear).unwrap();
/// let ctrl = ambid::io::ControllerModel::new(twin.twin.controller().clone(), "the twin's PID").unwrap();
/// let chirp = ReconstructionSection { duration_s: 0.2, ..ReconstructionSection::default() };
/// let plant = twin.twin.plant().clone();
/// let st = reconstruction(&ReconstructionInput {
///     name: "exact",
///     model: &plant,
///     controller: &ctrl,
///     chirp: &chirp,
///     settings: &ValidationSection::default(),
///     zones: Default::default(),
///     source: ReconstructionSource::Twin { twin: &twin, seed: 5 },
/// }).unwrap();
/// assert_eq!(st.y.len(), (0.2 / twin.twin.ts()).round() as usize);
/// // the exact plant reconstructs the measured displacement to the sensor noise
/// assert!(st.outcome.reconstruction.fit_y > 90.0, "{}", st.outcome.reconstruction.fit_y);
/// ```
///
/// # Errors
/// An input error for a chirp that cannot be made or a record without the reference `w`; a
/// computation error when the simulation or the closed-loop check fails.
pub fn reconstruction(input: &ReconstructionInput<'_>) -> Result<ReconstructionStage> {
    let rc = input.chirp;
    let (w, y, u, ts, source) = match &input.source {
        ReconstructionSource::Twin { twin: t, seed } => {
            let w = ambid_core::signal::ChirpSpec {
                amplitude: rc.amplitude_um * 1e-6,
                duration_s: rc.duration_s,
                f0_hz: rc.f0_hz,
                f1_hz: rc.f1_hz,
                sweep: ambid_core::signal::Sweep::Linear,
                periods: 1,
            }
            .generate(t.twin.ts())
            .map_err(|e| Error::classified(FailureClass::Input, e))?
            .values;
            let opts = ambid_twin::SimOptions {
                mode: t.mode,
                seed: *seed,
                noise: t.noise,
                w: Some(w.clone()),
                ..ambid_twin::SimOptions::default()
            };
            let rec = t
                .twin
                .simulate(&vec![0.0; w.len()], &opts)
                .map_err(|e| Error::classified(FailureClass::Computation, e))?;
            (w, rec.y, rec.u, rec.ts, "the twin".to_string())
        }
        ReconstructionSource::Record(r) => {
            let Some(w) = r.w().map(<[f64]>::to_vec) else {
                return Err(Error::input(format!(
                    "{}: the reconstruction record needs the position reference column ([data] w = \"…\")",
                    r.source
                )));
            };
            (w, r.y().to_vec(), r.u().to_vec(), r.ts(), r.source.clone())
        }
    };
    let s = ValidationSettings {
        skip: 0,
        ..validation_settings(input.settings, input.zones, y.len())
    };
    let outcome = validate_closed_loop(
        input.model,
        input.controller.state_space(),
        &MeasuredLoop {
            w: &w,
            r: None,
            y: &y,
            u: &u,
            ts,
        },
        &s,
    )
    .map_err(|e| Error::classified(FailureClass::Computation, e))?;
    let worst = worst_window(&outcome.reconstruction.windows, &y, ts);
    // the chirp's instantaneous frequency, from the reference's zero crossings
    let frequency = chirp_frequency(&w, ts);
    let n = y.len();
    let idx = |t: f64| ((t / ts).round().max(0.0) as usize).min(n.saturating_sub(1));
    let window_signal_rms = outcome
        .reconstruction
        .windows
        .iter()
        .map(|wf| {
            let (i0, i1) = (idx(wf.t_s.0), idx(wf.t_s.1).max(idx(wf.t_s.0) + 1).min(n));
            let seg = &y[i0..i1];
            let m = seg.iter().sum::<f64>() / seg.len() as f64;
            (seg.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / seg.len() as f64).sqrt()
        })
        .collect();
    Ok(ReconstructionStage {
        model: input.name.to_string(),
        source,
        ts,
        w,
        y,
        u,
        outcome,
        worst,
        frequency,
        window_signal_rms,
    })
}
