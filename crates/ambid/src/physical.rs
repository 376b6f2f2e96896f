//! Physical parameters from the identified plant (issue 23, gray box): one call for
//! `ambid physical` ([`estimate`]) and the twin check of the same chain on a rig
//! ([`PhysicalRun`]), which the tests and the `physical_rigs` example run. The model, the starts
//! and the intervals are documented in [`ambid_core::estimate::graybox`].

pub mod operating;

use crate::error::{Context, Error, Result};
use crate::experiment::ExcitationPlan;
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
pub use ambid_core::estimate::graybox::{
    extrapolate_machine_to_zero_amplitude, extrapolate_to_zero_amplitude, fit_machine_physical,
    fit_physical, graybox_machine_plant, AtLevel, Drawing, Hints, MachineAtLevel, MachineParams,
    MachinePhysicalFit, MachineZeroAmplitude, PhysicalFit, PhysicalOptions, PhysicalParams,
    Rotation, ZeroAmplitude, MACHINE_AXES, MACHINE_PARAMETER_NAMES, PARAMETER_NAMES,
};
use ambid_core::lti::{Frd, StateSpace};
use ambid_core::validate::compare::unstable_poles_from_loop;
use ambid_twin::{Machine, MachineConfig, Mode, Twin, TwinConfig};

/// The physical parameters from the plant FRF `frd` with the drawing, loop B's controller and
/// the starts taken from the identified black-box `model` ([`Hints::from_model`]).
///
/// # Errors
/// Those of [`Hints::from_model`] and [`fit_physical`], with the step named.
pub fn estimate(
    frd: &Frd,
    model: &StateSpace,
    drawing: &Drawing,
    controller_b: &StateSpace,
    opts: &PhysicalOptions,
) -> Result<PhysicalFit> {
    let hints = Hints::from_model(model).context("the starting values from the black-box model")?;
    fit_physical(frd, drawing, controller_b, &hints, opts).context("the gray-box fit")
}

/// Reads a drawing TOML (the keys of [`Drawing`]; docs/physical.md).
///
/// # Errors
/// An input error naming the file: unreadable, or not a drawing (with the keys it needs).
pub fn read_drawing(path: &std::path::Path) -> Result<Drawing> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::input(format!("{}: cannot read the drawing ({e})", path.display())))?;
    toml::from_str(&text).map_err(|e| {
        Error::input(format!(
            "{}: {e}; a drawing has mass_kg, inertia_kgm2, bearing_a_m, bearing_b_m, \
             amplifier_bandwidth_hz, sensor_bandwidth_hz (and optionally amplifier_gain, \
             sensor_gain, delay_samples); docs/physical.md",
            path.display()
        ))
    })
}

/// The drawing of a twin rig: what its configuration says about the rotor, bearings, amplifier
/// and sensor (gains 1: the twin's records are in A and m), one sample of computation delay.
pub fn twin_drawing(cfg: &TwinConfig) -> Drawing {
    drawing_of(&cfg.rotor, &cfg.amplifier, &cfg.sensor)
}

/// The drawing of a rotor, amplifier and sensor configuration (gains 1, one sample of delay).
fn drawing_of(
    rotor: &ambid_twin::config::RotorConfig,
    amplifier: &ambid_twin::config::AmplifierConfig,
    sensor: &ambid_twin::config::SensorConfig,
) -> Drawing {
    Drawing {
        mass_kg: rotor.mass_kg,
        inertia_kgm2: rotor.inertia(),
        bearing_a_m: rotor.bearing_a_m,
        bearing_b_m: rotor.bearing_b_m,
        amplifier_bandwidth_hz: amplifier.bandwidth_hz,
        sensor_bandwidth_hz: sensor.bandwidth_hz,
        amplifier_gain: 1.0,
        sensor_gain: 1.0,
        delay_samples: 1,
    }
}

/// The twin's true values of the parameters: $k_i$, $k_x$ of its linearisation and its rotor's
/// bending mode, the mode shape with $\varphi_A > 0$ (as the estimate reports it).
pub fn twin_truth(twin: &Twin) -> PhysicalParams {
    let (lp, r) = (twin.linear_params(), &twin.config().rotor);
    let sign = if r.mode_shape_a < 0.0 { -1.0 } else { 1.0 };
    PhysicalParams {
        k_i: lp.k_i,
        k_x: lp.k_x,
        bending_hz: r.bending_freq_hz,
        bending_damping: r.bending_damping,
        mode_shape_a: sign * r.mode_shape_a,
        mode_shape_b: sign * r.mode_shape_b,
    }
}

/// The median over the FRF's lines of $|M - G|/|G|$, the comparison of a model with the
/// measured plant (`NaN` for an empty FRF).
///
/// # Errors
/// When the model's response cannot be evaluated on the lines.
pub fn median_rel_error(model: &StateSpace, frd: &Frd) -> Result<f64> {
    let r = model.freq_response_siso(frd.f_hz())?;
    let mut e: Vec<f64> = r
        .iter()
        .zip(frd.values())
        .map(|(a, g)| (a - g).norm() / g.norm())
        .collect();
    e.sort_by(f64::total_cmp);
    Ok(e.get(e.len() / 2).copied().unwrap_or(f64::NAN))
}

/// The band of a twin run's FRF \[Hz\] (as the uncertainty run's).
pub const TWIN_BAND_HZ: (f64, f64) = crate::uncertainty::TWIN_BAND_HZ;

/// One run of the chain on the twin: the seed experiment on rig `rig` (0 = nominal) with noise
/// seed `seed`, the period-averaged plant FRF, a black-box state-space fit of order 8 with the
/// loop's unstable pole count (for the starts), [`estimate`], and the truth.
#[derive(Debug, Clone)]
pub struct PhysicalRun {
    /// The estimate.
    pub fit: PhysicalFit,
    /// The twin's linearisation and rotor values, in the same form.
    pub truth: PhysicalParams,
}

impl PhysicalRun {
    /// Runs the chain (type docs).
    ///
    /// # Errors
    /// Any step's error.
    pub fn on_twin(rig: u64, seed: u64, mode: Mode) -> Result<Self> {
        Self::on_twin_at(rig, seed, mode, ExcitationPlan::default().amplitude_frac)
    }

    /// [`Self::on_twin`] with the seed experiment's PRBS at `amplitude_frac` of $i_\text{sat}$.
    ///
    /// # Errors
    /// Any step's error.
    pub fn on_twin_at(rig: u64, seed: u64, mode: Mode, amplitude_frac: f64) -> Result<Self> {
        let (out, frd) = crate::uncertainty::twin_seed_frf_at(rig, seed, mode, amplitude_frac)?;
        let fit = estimate_with_starts_from_data(
            &frd,
            &twin_drawing(out.twin.config()),
            out.twin.controller(),
            &PhysicalOptions::default(),
        )?;
        Ok(Self {
            fit,
            truth: twin_truth(&out.twin),
        })
    }

    /// The truth as an array in the order of [`PARAMETER_NAMES`].
    pub fn truth_array(&self) -> [f64; 6] {
        as_array(&self.truth)
    }
}

/// [`estimate`] with its starts from a black-box model fitted here: the inverse-variance
/// state-space fit of order 8 to `frd` with the loop's unstable pole count (the Nyquist count
/// of `frd` with `controller_b`), as the twin checks use it.
///
/// # Errors
/// The black-box fit's errors, and those of [`estimate`].
pub fn estimate_with_starts_from_data(
    frd: &Frd,
    drawing: &Drawing,
    controller_b: &StateSpace,
    opts: &PhysicalOptions,
) -> Result<PhysicalFit> {
    let unstable = unstable_poles_from_loop(frd, controller_b, None).ok();
    let ffo = FreqFitOptions {
        weights: FreqWeights::InverseVariance,
        max_unstable_poles: unstable,
        ..FreqFitOptions::default()
    };
    let model = ss_frd(frd, 8, &ffo, &SsFreqOptions::default())
        .map_err(|e| Error::other(format!("the black-box model: {e}")))?
        .model;
    estimate(frd, &model, drawing, controller_b, opts)
}

/// The estimates at several excitation levels as the input of
/// [`extrapolate_to_zero_amplitude`]: `(level, fit)` pairs.
pub fn at_levels(fits: &[(f64, PhysicalFit)]) -> Vec<AtLevel> {
    fits.iter()
        .map(|(level, fit)| AtLevel {
            level: *level,
            params: fit.params,
            std: fit.std,
        })
        .collect()
}

/// The chain of [`PhysicalRun`] at several excitation levels on one twin rig, and the
/// parameters extrapolated to zero amplitude ([`extrapolate_to_zero_amplitude`], module docs of
/// `ambid_core::estimate::graybox::amplitude`): the small-signal $k_x$ of the nonlinear twin,
/// whose estimate at a finite level is the best linear approximation's.
#[derive(Debug, Clone)]
pub struct ExtrapolatedRun {
    /// The estimate at each level, in the order of the levels.
    pub at_levels: Vec<(f64, PhysicalFit)>,
    /// The extrapolation to zero amplitude.
    pub zero: ZeroAmplitude,
    /// The twin's linearisation and rotor values.
    pub truth: PhysicalParams,
}

impl ExtrapolatedRun {
    /// Runs [`PhysicalRun::on_twin_at`] at each of `levels` (fractions of $i_\text{sat}$) on
    /// rig `rig`, level $l$ (from 0) with noise seed `seed + 1000 l` so that the levels'
    /// records are independent, and extrapolates at the fits' confidence level.
    ///
    /// # Errors
    /// Any run's error, with its level named; those of [`extrapolate_to_zero_amplitude`].
    pub fn on_twin(rig: u64, seed: u64, mode: Mode, levels: &[f64]) -> Result<Self> {
        if levels.len() < 2 {
            // refused before any simulation
            return Err(Error::usage(format!(
                "{} level(s): the extrapolation to zero amplitude needs two or more excitation levels",
                levels.len()
            )));
        }
        let mut at = Vec::with_capacity(levels.len());
        let mut truth = None;
        for (l, &a) in levels.iter().enumerate() {
            let run = PhysicalRun::on_twin_at(rig, seed.wrapping_add(1000 * l as u64), mode, a)
                .with_context(|| format!("the run at level {a}"))?;
            truth = Some(run.truth);
            at.push((a, run.fit));
        }
        let confidence = at.first().map_or(0.95, |(_, f)| f.confidence);
        let zero = extrapolate_to_zero_amplitude(&at_levels(&at), confidence)
            .context("the extrapolation to zero amplitude")?;
        let truth = truth.ok_or_else(|| Error::other("no level was given"))?;
        Ok(Self {
            at_levels: at,
            zero,
            truth,
        })
    }
}

/// The parameters as an array in the order of [`PARAMETER_NAMES`].
pub fn as_array(p: &PhysicalParams) -> [f64; 6] {
    p.to_array()
}

/// The drawing of a machine configuration (as [`twin_drawing`] of its plane) and its rotation
/// (speed and polar inertia).
pub fn machine_drawing(cfg: &MachineConfig) -> (Drawing, Rotation) {
    let d = drawing_of(&cfg.rotor, &cfg.amplifier, &cfg.sensor);
    let rot = Rotation {
        speed_rpm: cfg.speed_rpm,
        polar_inertia_kgm2: cfg.polar_inertia(),
    };
    (d, rot)
}

/// The machine's true values: each axis' linearised magnet ([`Machine::axis_magnets`]) and the
/// rotor's bending mode, the mode shape with $\varphi_A > 0$ (as the estimate reports it).
pub fn machine_truth(machine: &Machine) -> MachineParams {
    let (k_i, k_x) = machine.axis_magnets();
    let r = &machine.config().rotor;
    let sign = if r.mode_shape_a < 0.0 { -1.0 } else { 1.0 };
    MachineParams {
        k_i,
        k_x,
        bending_hz: r.bending_freq_hz,
        bending_damping: r.bending_damping,
        mode_shape_a: sign * r.mode_shape_a,
        mode_shape_b: sign * r.mode_shape_b,
    }
}

/// The `[machine]` experiment `section` on the machine `cfg` with seed `seed` (its one speed),
/// and the plant FRF on the band of the physical runs ([`TWIN_BAND_HZ`]).
///
/// # Errors
/// The experiment's errors; an experiment that gave no speed.
pub fn twin_machine_frf(
    cfg: MachineConfig,
    section: &crate::config::MachineSection,
    seed: u64,
) -> Result<Frd> {
    let data = crate::workflow::machine::acquire_twin_config(cfg, section, seed)?;
    Ok(data
        .speeds
        .first()
        .ok_or_else(|| Error::other("the experiment gave no speed"))?
        .frf
        .plant
        .band(TWIN_BAND_HZ.0, TWIN_BAND_HZ.1)?)
}

/// One run of the whole-rotor chain on the 4-axis twin: machine rig `rig` (0 = the nominal
/// machine, symmetric; $k > 0$ = [`ambid_twin::random_machine_rig`]`(k)`, every axis its own
/// magnet) at `speed_rpm`, the `[machine]` section's default experiment (orthogonal PRBS design,
/// 12 periods, noise on) with noise seed `seed`, its 4×4 plant FRF on [`TWIN_BAND_HZ`], and
/// [`fit_machine_physical`] with the rig's drawing and rotation (bending starts from the grid),
/// beside the truth.
#[derive(Debug, Clone)]
pub struct MachinePhysicalRun {
    /// The estimate.
    pub fit: MachinePhysicalFit,
    /// The machine's linearisation and rotor values.
    pub truth: MachineParams,
    /// The FRF's lines used.
    pub lines: usize,
}

impl MachinePhysicalRun {
    /// Runs the chain (type docs).
    ///
    /// # Errors
    /// Any step's error.
    pub fn on_twin(rig: u64, seed: u64, speed_rpm: f64, mode: Mode) -> Result<Self> {
        Self::on_twin_at(rig, seed, speed_rpm, mode, 0.1)
    }

    /// [`Self::on_twin`] with the excitation's peak at `level` of $i_\text{sat}$ per input
    /// (the `[machine]` section's `level_pct` / 100; default 0.1).
    ///
    /// # Errors
    /// Any step's error.
    pub fn on_twin_at(rig: u64, seed: u64, speed_rpm: f64, mode: Mode, level: f64) -> Result<Self> {
        let base = if rig == 0 {
            MachineConfig::default()
        } else {
            ambid_twin::random_machine_rig(rig)?
        };
        let cfg = MachineConfig { speed_rpm, ..base };
        let section = crate::config::MachineSection {
            speeds_rpm: Some(vec![speed_rpm]),
            mode: match mode {
                Mode::Linear => "linear".into(),
                Mode::Nonlinear => "nonlinear".into(),
            },
            level_pct: 100.0 * level,
            ..Default::default()
        };
        let frd = twin_machine_frf(cfg.clone(), &section, seed).context("the 4-axis experiment")?;
        let (drawing, rotation) = machine_drawing(&cfg);
        let fit = fit_machine_physical(&frd, &drawing, &rotation, &[], &PhysicalOptions::default())
            .context("the gray-box fit of the machine")?;
        Ok(Self {
            fit,
            truth: machine_truth(&Machine::new(cfg)?),
            lines: frd.len(),
        })
    }
}

/// The whole-machine chain at several excitation levels on one machine rig and the parameters
/// extrapolated to zero amplitude ([`extrapolate_machine_to_zero_amplitude`]): the small-signal
/// $k_x$ of every axis of the nonlinear twin.
#[derive(Debug, Clone)]
pub struct MachineExtrapolatedRun {
    /// The estimate at each level, in the order of the levels.
    pub at_levels: Vec<(f64, MachinePhysicalFit)>,
    /// The extrapolation to zero amplitude.
    pub zero: MachineZeroAmplitude,
    /// The machine's linearisation and rotor values.
    pub truth: MachineParams,
}

impl MachineExtrapolatedRun {
    /// Runs [`MachinePhysicalRun::on_twin_at`] at each of `levels` (fractions of
    /// $i_\text{sat}$), level $l$ (from 0) with noise seed `seed + 1000 l`, and extrapolates at
    /// the fits' confidence level.
    ///
    /// # Errors
    /// Fewer than two levels (before any simulation); any run's error with its level named;
    /// those of [`extrapolate_machine_to_zero_amplitude`].
    pub fn on_twin(
        rig: u64,
        seed: u64,
        speed_rpm: f64,
        mode: Mode,
        levels: &[f64],
    ) -> Result<Self> {
        if levels.len() < 2 {
            return Err(Error::usage(format!(
                "{} level(s): the extrapolation to zero amplitude needs two or more excitation levels",
                levels.len()
            )));
        }
        let mut at = Vec::with_capacity(levels.len());
        let mut truth = None;
        for (l, &a) in levels.iter().enumerate() {
            let run = MachinePhysicalRun::on_twin_at(
                rig,
                seed.wrapping_add(1000 * l as u64),
                speed_rpm,
                mode,
                a,
            )
            .with_context(|| format!("the run at level {a}"))?;
            truth = Some(run.truth);
            at.push((a, run.fit));
        }
        let points: Vec<MachineAtLevel> = at
            .iter()
            .map(|(level, f)| MachineAtLevel {
                level: *level,
                params: f.params,
                std: f.std,
            })
            .collect();
        let confidence = at.first().map_or(0.95, |(_, f)| f.confidence);
        let zero = extrapolate_machine_to_zero_amplitude(&points, confidence)
            .context("the extrapolation to zero amplitude")?;
        let truth = truth.ok_or_else(|| Error::other("no level was given"))?;
        Ok(Self {
            at_levels: at,
            zero,
            truth,
        })
    }
}
