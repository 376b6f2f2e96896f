//! The acquisition stage: the records an identification works on — from the twin (simulated
//! with named seeds, [`Seeds`]) or from files — as [`Recording`]s in SI units.

use super::Seeds;
use crate::error::{Context, Error, FailureClass, Result};
use crate::experiment::{self, ExcitationKind, ExcitationPlan, Experiment};
use ambid_core::data::{IoData, Role};
use ambid_twin::{Mode, Twin, TwinConfig};
use serde::Serialize;

/// One closed- or open-loop record in SI units: the samples as an [`IoData`] (channels `r` when
/// recorded, `u`, `y`, `i` and `w` when recorded, with their roles inferred from the names; the
/// sample time and the excitation period) and where they came from.
///
/// A one-axis record is the 1×1 case of the core's data contract; the accessors [`Recording::y`],
/// [`Recording::u`], … read its channels by role.
///
/// ```
/// use ambid::stage::{Recording, Signals};
/// let rec = Recording::from_signals(
///     1e-3,
///     Some(2),
///     Signals { r: Some(vec![1.0, -1.0, 1.0, -1.0]), u: vec![0.5, -0.5, 0.4, -0.6], y: vec![0.0, 1.0, 0.0, 1.0], i: None, w: None },
///     true,
///     "example",
/// ).unwrap();
/// assert_eq!(rec.len(), 4);
/// assert_eq!(rec.y(), &[0.0, 1.0, 0.0, 1.0]);
/// assert_eq!(rec.r(), Some(&[1.0, -1.0, 1.0, -1.0][..]));
/// assert_eq!(rec.period(), Some(2));
/// assert!(rec.i().is_none());
/// assert_eq!(rec.data.role_count(ambid_core::data::Role::Output), 1);
/// ```
#[derive(Debug, Clone, Serialize)]
pub struct Recording {
    /// The samples with their roles, sample time and period.
    pub data: IoData,
    /// Closed-loop data.
    pub closed_loop: bool,
    /// Where it came from.
    pub source: String,
    /// Fraction of saturated samples (twin).
    pub saturated_fraction: Option<f64>,
    /// Notes on how the record was read (e.g. columns taken by their names).
    pub notes: Vec<String>,
}

/// The signals of a one-axis record by role, in SI units ([`Recording::from_signals`]).
#[derive(Debug, Clone, Default)]
pub struct Signals {
    /// Excitation at the controller output, if recorded.
    pub r: Option<Vec<f64>>,
    /// Plant input.
    pub u: Vec<f64>,
    /// Plant output.
    pub y: Vec<f64>,
    /// Coil current, if recorded.
    pub i: Option<Vec<f64>>,
    /// Position reference, if recorded.
    pub w: Option<Vec<f64>>,
}

impl Recording {
    /// A record of `signals` with sample time `ts` \[s\] and `period` samples per excitation
    /// period (when periodic).
    ///
    /// # Errors
    /// An input error when the signals differ in length or are empty, `ts` is not positive, or
    /// the period is 0 (the core's [`IoData::new`] checks).
    pub fn from_signals(
        ts: f64,
        period: Option<usize>,
        signals: Signals,
        closed_loop: bool,
        source: impl Into<String>,
    ) -> Result<Self> {
        let source = source.into();
        let Signals { r, u, y, i, w } = signals;
        let channels: Vec<(String, Vec<f64>)> =
            [("r", r), ("u", Some(u)), ("y", Some(y)), ("i", i), ("w", w)]
                .into_iter()
                .filter_map(|(n, x)| x.map(|x| (n.to_string(), x)))
                .collect();
        let data = IoData::new(channels, ts, period)
            .with_context(|| format!("{source}: the record's signals"))
            .map_err(|e| Error::classified(FailureClass::Input, e))?;
        Ok(Self {
            data,
            closed_loop,
            source,
            saturated_fraction: None,
            notes: Vec::new(),
        })
    }

    /// The record's signals, copied out by role.
    pub fn signals(&self) -> Signals {
        Signals {
            r: self.r().map(<[f64]>::to_vec),
            u: self.u().to_vec(),
            y: self.y().to_vec(),
            i: self.i().map(<[f64]>::to_vec),
            w: self.w().map(<[f64]>::to_vec),
        }
    }

    /// The same record with its signals replaced by `signals` (same sample time, period, source
    /// and notes).
    ///
    /// # Errors
    /// As [`Recording::from_signals`].
    pub fn with_signals(&self, signals: Signals) -> Result<Self> {
        Ok(Self {
            saturated_fraction: self.saturated_fraction,
            notes: self.notes.clone(),
            ..Self::from_signals(
                self.ts(),
                self.period(),
                signals,
                self.closed_loop,
                self.source.clone(),
            )?
        })
    }

    /// The first channel of `role`, if the record has one.
    fn first(&self, role: Role) -> Option<&[f64]> {
        self.data
            .signals(role, 0)
            .ok()
            .and_then(|s| s.first().copied())
    }

    /// The excitation `r` at the controller output, if recorded.
    pub fn r(&self) -> Option<&[f64]> {
        self.first(Role::Excitation)
    }

    /// The plant input `u`.
    pub fn u(&self) -> &[f64] {
        self.first(Role::Input).unwrap_or(&[])
    }

    /// The plant output `y`.
    pub fn y(&self) -> &[f64] {
        self.first(Role::Output).unwrap_or(&[])
    }

    /// The coil current `i`, if recorded.
    pub fn i(&self) -> Option<&[f64]> {
        self.first(Role::Current)
    }

    /// The position reference `w`, if recorded.
    pub fn w(&self) -> Option<&[f64]> {
        self.first(Role::Reference)
    }

    /// Samples per excitation period, when periodic.
    pub fn period(&self) -> Option<usize> {
        self.data.period_samples()
    }

    /// Sample time \[s\].
    pub fn ts(&self) -> f64 {
        self.data.ts()
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// `true` for a record without samples.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// Sample rate \[Hz\].
    pub fn fs(&self) -> f64 {
        1.0 / self.ts()
    }
}

/// The twin and how it is run.
pub struct TwinSource {
    /// Its configuration.
    pub cfg: TwinConfig,
    /// Linear or nonlinear physics.
    pub mode: Mode,
    /// Whether the sensor is noisy (a noise-only record is then meaningful).
    pub noise: bool,
    /// The twin built from `cfg` (exact truth).
    pub twin: Twin,
}

impl TwinSource {
    /// The twin of a configuration.
    ///
    /// # Errors
    /// An input error when the configuration does not make a twin.
    pub fn new(cfg: TwinConfig, mode: Mode) -> Result<Self> {
        let twin = Twin::new(cfg.clone())
            .context("building the twin")
            .map_err(|e| Error::classified(FailureClass::Input, e))?;
        Ok(Self {
            noise: cfg.sensor.noise_rms_m > 0.0,
            cfg,
            mode,
            twin,
        })
    }

    /// Runs one experiment on the twin: the closed-loop record of excitation `plan` with the
    /// twin's noise drawn from `seed`; `what` names the record in messages and its source.
    ///
    /// # Errors
    /// A computation error when the simulation fails.
    pub fn record(
        &self,
        plan: ExcitationPlan,
        seed: u64,
        what: &str,
    ) -> Result<(Recording, experiment::ExperimentOutput)> {
        self.recording(experiment::run(&self.experiment(plan, seed)), what)
    }

    /// The experiment of excitation `plan` with the twin's noise drawn from `seed`.
    pub fn experiment(&self, plan: ExcitationPlan, seed: u64) -> Experiment {
        Experiment {
            twin: self.cfg.clone(),
            excitation: plan,
            mode: self.mode,
            seed,
            noise: self.noise,
            record_b: false,
        }
    }

    /// The record of an experiment's output (`what` names it in messages and its source).
    fn recording(
        &self,
        out: Result<experiment::ExperimentOutput>,
        what: &str,
    ) -> Result<(Recording, experiment::ExperimentOutput)> {
        let out = out
            .with_context(|| format!("simulating the {what} record on the twin"))
            .map_err(|e| Error::classified(FailureClass::Computation, e))?;
        let rec = &out.record;
        let periodic = out.excitation.periods >= 2;
        Ok((
            Recording {
                saturated_fraction: Some(rec.meta.saturated_fraction),
                ..Recording::from_signals(
                    rec.ts,
                    periodic.then_some(out.excitation.period_samples),
                    Signals {
                        r: Some(rec.r.clone()),
                        u: rec.u.clone(),
                        y: rec.y.clone(),
                        i: Some(rec.i.clone()),
                        w: Some(rec.w.clone()),
                    },
                    true,
                    format!("twin, {what} record"),
                )?
            },
            out,
        ))
    }
}

/// The excitation kind named in a workflow file (`prbs`, `chirp`, `noise`, `multisine`; anything
/// else is a PRBS, as the file's check allows no other name).
pub fn excitation_kind(name: &str) -> ExcitationKind {
    match name {
        "chirp" => ExcitationKind::Chirp,
        "noise" => ExcitationKind::Noise,
        "multisine" => ExcitationKind::Multisine,
        _ => ExcitationKind::Prbs,
    }
}

/// What the acquisition stage simulates on the twin.
#[derive(Debug, Clone, Serialize)]
pub struct AcquisitionPlan {
    /// The identification experiment (its `seed` is the excitation's).
    pub identification: ExcitationPlan,
    /// The validation experiment: a different excitation realisation and noise.
    pub validation: ExcitationPlan,
    /// Whether to record a run without excitation (the output SNR); only with a noisy sensor.
    pub noise_record: bool,
    /// The seeds of the twin's noise in each record.
    pub seeds: Seeds,
}

impl AcquisitionPlan {
    /// The workflow's plan: identification by `identification` (with the identification
    /// excitation seed), validation by the same plan with kind `validation_kind` at
    /// `validation_frac` of i_sat and the validation excitation seed, and a noise-only record.
    pub fn new(
        identification: ExcitationPlan,
        validation_kind: ExcitationKind,
        validation_frac: f64,
        seeds: Seeds,
    ) -> Self {
        let validation = ExcitationPlan {
            kind: validation_kind,
            seed: seeds.validation_excitation,
            amplitude_frac: validation_frac,
            ..identification.clone()
        };
        Self {
            identification: ExcitationPlan {
                seed: seeds.identification_excitation,
                ..identification
            },
            validation,
            noise_record: true,
            seeds,
        }
    }
}

/// The records of one identification: the identification record, the independent validation
/// record and the output of a run without excitation (the output SNR's reference).
#[derive(Debug, Clone, Serialize)]
pub struct Acquisition {
    /// The estimation record.
    pub identification: Recording,
    /// The validation record.
    pub validation: Recording,
    /// The output `y` of a record without excitation (twin with a noisy sensor).
    pub noise_y: Option<Vec<f64>>,
}

/// The acquisition stage on the twin: the three records of `plan`, simulated in parallel (each
/// from its own seed, so the records do not depend on the number of threads).
///
/// ```
/// use ambid::stage::{acquire_twin, AcquisitionPlan, Seeds, TwinSource};
/// use ambid::experiment::{ExcitationKind, ExcitationPlan};
/// let twin = TwinSource::new(ambid_twin::TwinConfig::default(), ambid_twin::Mode::Nonlinear).unwrap();
/// let plan = AcquisitionPlan::new(
///     ExcitationPlan { periods: 3, ..ExcitationPlan::default() },
///     ExcitationKind::Multisine,
///     0.1,
///     Seeds::from_workflow_seed(1),
/// );
/// let a = acquire_twin(&twin, &plan).unwrap();
/// // PRBS n = 10, 5 samples per bit: 5115 samples per period, 3 periods
/// assert_eq!(a.identification.len(), 3 * 5115);
/// assert_eq!(a.identification.period(), Some(5115));
/// assert!(a.noise_y.is_some());
/// ```
///
/// # Errors
/// A computation error when a simulation fails.
pub fn acquire_twin(twin: &TwinSource, plan: &AcquisitionPlan) -> Result<Acquisition> {
    let noise_plan = ExcitationPlan {
        kind: ExcitationKind::None,
        amplitude_frac: 0.0,
        ..plan.identification.clone()
    };
    let want_noise = plan.noise_record && twin.noise;
    // the records side by side: lock-step lanes of the twin's simulation (each record bit for
    // bit its lone run's), experiment::run_batch
    let mut exps = vec![
        twin.experiment(
            plan.identification.clone(),
            plan.seeds.identification_record,
        ),
        twin.experiment(plan.validation.clone(), plan.seeds.validation_record),
    ];
    if want_noise {
        exps.push(twin.experiment(noise_plan, plan.seeds.noise_record));
    }
    let mut outs = experiment::run_batch(&exps).into_iter();
    let mut next = |what: &str| match outs.next() {
        Some(out) => twin.recording(out, what),
        None => Err(Error::computation(format!(
            "the {what} record was not simulated"
        ))),
    };
    let identification = next("identification")?.0;
    let validation = next("validation")?.0;
    let noise_y = if want_noise {
        Some(next("noise")?.0.y().to_vec())
    } else {
        None
    };
    Ok(Acquisition {
        identification,
        validation,
        noise_y,
    })
}
