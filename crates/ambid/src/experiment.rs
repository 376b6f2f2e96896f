//! Running an identification experiment on the embedded twin: design the excitation, simulate the
//! closed loop, collect the exact linearised truth on a frequency grid.
//!
//! This is the library behind `ambid simulate`; everything it computes is reachable from Rust.

use crate::error::{Context, Error, Result};
use ambid_core::signal::{
    ChirpSpec, Distribution, Excitation, ExcitationSpec, Grid, MultisineSpec, NoiseSpec, Phases,
    PrbsSpec, Sweep,
};
use ambid_twin::{Mode, SimOptions, SimRecord, Twin, TwinConfig};
use num_complex::Complex64;
use serde::Serialize;

/// Which excitation to inject at the controller output of bearing A.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ExcitationKind {
    /// Maximum-length PRBS (the seed paper's choice).
    Prbs,
    /// Swept sine.
    Chirp,
    /// Gaussian white noise.
    Noise,
    /// Schroeder-phased odd multisine.
    Multisine,
    /// No excitation (noise-only run, e.g. for the output SNR).
    None,
}

/// Parameters of the excitation for a twin experiment. The level is a fraction of the amplifier's
/// saturation current `i_sat`: the peak value for PRBS, chirp and multisine, the RMS for noise.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExcitationPlan {
    /// Signal family.
    pub kind: ExcitationKind,
    /// Level as a fraction of i_sat (0.1 = 10 %).
    pub amplitude_frac: f64,
    /// PRBS order n (period 2^n − 1 bits).
    pub prbs_order: u32,
    /// PRBS samples per bit Nb.
    pub samples_per_bit: usize,
    /// Number of periods (PRBS, chirp, multisine).
    pub periods: usize,
    /// Lower frequency (chirp start, multisine lowest line, noise band), Hz.
    pub f_min_hz: f64,
    /// Upper frequency (chirp end, multisine highest line, noise band), Hz.
    pub f_max_hz: f64,
    /// Duration of one period (chirp, multisine), s. Noise and no-excitation records last
    /// `periods × period_s` so that every kind gives a record of the same length by default.
    pub period_s: f64,
    /// Seed for random signals (noise, random phases).
    pub seed: u64,
}

impl Default for ExcitationPlan {
    /// The seed paper's experiment: PRBS n = 10, Nb = 5, Np = 20 at 10 % of i_sat.
    fn default() -> Self {
        Self {
            kind: ExcitationKind::Prbs,
            amplitude_frac: 0.10,
            prbs_order: 10,
            samples_per_bit: 5,
            periods: 20,
            f_min_hz: 1.0,
            f_max_hz: 2000.0,
            period_s: 0.25575,
            seed: 1,
        }
    }
}

impl ExcitationPlan {
    /// The signal specification in amperes for a given saturation current, or `None` for no
    /// excitation.
    pub fn spec(&self, i_sat: f64, ts: f64) -> Result<Option<ExcitationSpec>> {
        if !(self.amplitude_frac.is_finite() && self.amplitude_frac >= 0.0) {
            return Err(Error::usage(format!(
                "excitation amplitude must be a finite, non-negative fraction of i_sat, got {}",
                self.amplitude_frac
            )));
        }
        if self.amplitude_frac > 1.0 {
            return Err(Error::usage(format!(
                "excitation amplitude {} exceeds i_sat (1.0 = 100 %); the amplifier would saturate permanently",
                self.amplitude_frac
            )));
        }
        let amp = self.amplitude_frac * i_sat;
        let period_samples = (self.period_s / ts).round() as usize;
        Ok(Some(match self.kind {
            ExcitationKind::None => return Ok(None),
            ExcitationKind::Prbs => ExcitationSpec::Prbs(PrbsSpec {
                order: self.prbs_order,
                samples_per_bit: self.samples_per_bit,
                periods: self.periods,
                amplitude: amp,
                offset: 0.0,
            }),
            ExcitationKind::Chirp => ExcitationSpec::Chirp(ChirpSpec {
                f0_hz: self.f_min_hz,
                f1_hz: self.f_max_hz,
                duration_s: self.period_s,
                amplitude: amp,
                sweep: Sweep::Logarithmic,
                periods: self.periods,
            }),
            ExcitationKind::Noise => ExcitationSpec::Noise(NoiseSpec {
                distribution: Distribution::Gaussian,
                rms: amp,
                n_samples: period_samples * self.periods,
                band_hz: Some((self.f_min_hz, self.f_max_hz)),
                seed: self.seed,
            }),
            ExcitationKind::Multisine => ExcitationSpec::Multisine(MultisineSpec {
                f_min_hz: self.f_min_hz,
                f_max_hz: self.f_max_hz,
                period_samples,
                periods: self.periods,
                rms: amp,
                grid: Grid::Odd,
                phases: Phases::Schroeder,
                seed: self.seed,
            }),
        }))
    }

    /// Generates the excitation for the twin's sample time; a multisine is rescaled so its peak is
    /// the requested level. `None` gives `periods × period_s` of zeros.
    pub fn generate(&self, i_sat: f64, ts: f64) -> Result<Excitation> {
        match self.spec(i_sat, ts)? {
            None => {
                let period_samples = (self.period_s / ts).round() as usize;
                if period_samples == 0 || self.periods == 0 {
                    return Err(Error::other(
                        "a record without excitation needs --period > 0 and --periods ≥ 1",
                    ));
                }
                Ok(Excitation {
                    values: vec![0.0; period_samples * self.periods],
                    ts,
                    period_samples,
                    periods: self.periods,
                })
            }
            Some(spec) => {
                let mut e = spec.generate(ts).context("designing the excitation")?;
                if self.kind == ExcitationKind::Multisine {
                    let peak = e.values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    if peak > 0.0 {
                        let g = self.amplitude_frac * i_sat / peak;
                        e.values.iter_mut().for_each(|v| *v *= g);
                    }
                }
                Ok(e)
            }
        }
    }
}

/// Exact linearised truth of the twin on a frequency grid.
#[derive(Debug, Clone)]
pub struct Truth {
    /// Frequencies, Hz.
    pub f_hz: Vec<f64>,
    /// Assembled plant P (u → y).
    pub plant: Vec<Complex64>,
    /// Process sensitivity T_ry = P/(1+PC).
    pub t_ry: Vec<Complex64>,
    /// Sensitivity S = T_ru = 1/(1+PC).
    pub t_ru: Vec<Complex64>,
    /// Controller C.
    pub controller: Vec<Complex64>,
}

/// Logarithmic grid of `n` points from `f0` to `f1` Hz.
pub fn log_grid(f0: f64, f1: f64, n: usize) -> Vec<f64> {
    if n < 2 {
        return vec![f0];
    }
    let (l0, l1) = (f0.ln(), f1.ln());
    (0..n)
        .map(|k| (l0 + (l1 - l0) * k as f64 / (n - 1) as f64).exp())
        .collect()
}

/// Evaluates the twin's truth at `f_hz`.
pub fn truth(twin: &Twin, f_hz: &[f64]) -> Result<Truth> {
    Ok(Truth {
        f_hz: f_hz.to_vec(),
        plant: twin.plant_frf(f_hz)?,
        t_ry: twin.t_ry_frf(f_hz)?,
        t_ru: twin.sensitivity_frf(f_hz)?,
        controller: twin.controller_frf(f_hz)?,
    })
}

/// A complete twin experiment: the excitation plan, the twin configuration and how to run it.
#[derive(Debug, Clone)]
pub struct Experiment {
    /// Twin parameters (operating point included).
    pub twin: TwinConfig,
    /// Excitation design.
    pub excitation: ExcitationPlan,
    /// Linear or nonlinear simulation.
    pub mode: Mode,
    /// Seed of the sensor noise.
    pub seed: u64,
    /// Sensor noise on or off.
    pub noise: bool,
    /// Record bearing B too.
    pub record_b: bool,
}

impl Experiment {
    /// The seed paper's experiment on the nominal twin (PRBS n = 10, 5 samples per bit, 20 periods
    /// at 10 % of i_sat) with sensor noise of `noise_rms_m` (issue 3 uses 0.1 µm) and noise seed
    /// `seed`.
    pub fn seed_paper(mode: Mode, noise_rms_m: f64, seed: u64) -> Self {
        let mut twin = TwinConfig::default();
        twin.sensor.noise_rms_m = noise_rms_m;
        Self {
            twin,
            excitation: ExcitationPlan::default(),
            mode,
            seed,
            noise: noise_rms_m > 0.0,
            record_b: false,
        }
    }
}

/// What an experiment produced.
pub struct ExperimentOutput {
    /// The twin that was run (for its truth).
    pub twin: Twin,
    /// The excitation that was injected.
    pub excitation: Excitation,
    /// The recorded signals.
    pub record: SimRecord,
}

/// Runs the experiment on the twin.
pub fn run(exp: &Experiment) -> Result<ExperimentOutput> {
    let (twin, excitation) = prepare(exp)?;
    simulate_with(twin, exp, excitation)
}

/// What [`run`] and [`run_batch`] do before they simulate: the twin, the length the plan asks
/// for (checked before the excitation is even generated) and the excitation.
fn prepare(exp: &Experiment) -> Result<(Twin, Excitation)> {
    let twin = Twin::new(exp.twin.clone()).context("building the AMB twin")?;
    let p = &exp.excitation;
    let per_period = match p.kind {
        ExcitationKind::Prbs => 1usize
            .checked_shl(p.prbs_order.min(63))
            .map_or(usize::MAX, |v| v.saturating_sub(1))
            .saturating_mul(p.samples_per_bit),
        _ => (p.period_s / twin.ts()).round().min(usize::MAX as f64) as usize,
    };
    check_sim_length(per_period.saturating_mul(p.periods))?;
    let excitation = exp.excitation.generate(twin.i_sat(), twin.ts())?;
    check_sim_length(excitation.values.len())?;
    Ok((twin, excitation))
}

/// Runs independent experiments on the twin and returns their outputs in the order given, each
/// exactly what [`run`] returns for it (errors included), whatever the number of threads.
///
/// The nonlinear simulations run in lock-step lanes of up to [`ambid_twin::sim::MAX_LANES`]
/// ([`Twin::simulate_batch`]: bit for bit the lone runs, at a fraction of their CPU time), the
/// lane groups in parallel (rayon).
///
/// ```
/// use ambid::experiment::{run, run_batch, ExcitationPlan, Experiment};
/// use ambid_twin::Mode;
/// let exps: Vec<Experiment> = (0..3)
///     .map(|seed| Experiment {
///         excitation: ExcitationPlan { periods: 2, ..ExcitationPlan::default() },
///         ..Experiment::seed_paper(Mode::Nonlinear, 1e-7, seed)
///     })
///     .collect();
/// let outs = run_batch(&exps);
/// for (out, exp) in outs.iter().zip(&exps) {
///     assert_eq!(out.as_ref().unwrap().record, run(exp).unwrap().record);
/// }
/// ```
pub fn run_batch(exps: &[Experiment]) -> Vec<Result<ExperimentOutput>> {
    use rayon::prelude::*;
    let prepared: Vec<Result<(Twin, Excitation, SimOptions)>> = exps
        .par_iter()
        .map(|exp| prepare(exp).map(|(twin, excitation)| (twin, excitation, sim_options(exp))))
        .collect();
    let ready: Vec<usize> = (0..exps.len()).filter(|&j| prepared[j].is_ok()).collect();
    let records: Vec<(usize, ambid_twin::Result<SimRecord>)> = ready
        .par_chunks(ambid_twin::sim::MAX_LANES)
        .flat_map_iter(|chunk| {
            let runs: Vec<(&Twin, &[f64], &SimOptions)> = chunk
                .iter()
                .filter_map(|&j| prepared[j].as_ref().ok())
                .map(|(t, e, o)| (t, e.values.as_slice(), o))
                .collect();
            chunk.iter().copied().zip(Twin::simulate_batch(&runs))
        })
        .collect();
    let mut records: Vec<Option<ambid_twin::Result<SimRecord>>> = {
        let mut v: Vec<_> = (0..exps.len()).map(|_| None).collect();
        for (j, r) in records {
            v[j] = Some(r);
        }
        v
    };
    prepared
        .into_iter()
        .enumerate()
        .map(|(j, p)| {
            let (twin, excitation, _) = p?;
            let record = records[j]
                .take()
                .ok_or_else(|| Error::other("internal: an experiment was not simulated"))?
                .context("simulating the closed loop")?;
            Ok(ExperimentOutput {
                twin,
                excitation,
                record,
            })
        })
        .collect()
}

/// Runs the experiment on the twin with a given excitation `r` \[A\] (e.g. read from a file)
/// instead of `exp.excitation`; `ts` is its sample time when known, which must be the twin's.
///
/// # Errors
/// An empty or non-finite excitation, a sample time other than the twin's, or simulation errors.
pub fn run_with_excitation(
    exp: &Experiment,
    r: Vec<f64>,
    ts: Option<f64>,
) -> Result<ExperimentOutput> {
    let twin = Twin::new(exp.twin.clone()).context("building the AMB twin")?;
    if r.is_empty() {
        return Err(Error::other("the excitation is empty"));
    }
    if let Some(k) = r.iter().position(|v| !v.is_finite()) {
        return Err(Error::other(format!(
            "excitation sample {k} is not finite ({}); repair or regenerate the excitation",
            r[k]
        )));
    }
    if let Some(ts) = ts {
        if (ts / twin.ts() - 1.0).abs() > 1e-6 {
            return Err(Error::other(format!(
                "the excitation is sampled at {} Hz but the twin's controller runs at {} Hz; \
                 regenerate it at the twin's rate (e.g. `ambid excite … --fs {}`)",
                1.0 / ts,
                twin.fs(),
                twin.fs()
            )));
        }
    }
    let n = r.len();
    let excitation = Excitation {
        values: r,
        ts: twin.ts(),
        period_samples: n,
        periods: 1,
    };
    simulate_with(twin, exp, excitation)
}

/// Longest record a twin experiment simulates: 2²³ samples (7 min at 20 kHz). The twin keeps
/// about 60 bytes per sample for the record and what is written from it, so this bounds one
/// experiment to about 0.5 GB (1.34·10⁸ samples aborted at 7.1 GiB before the bound).
pub const MAX_SIM_SAMPLES: usize = 1 << 23;

fn check_sim_length(n: usize) -> Result<()> {
    if n > MAX_SIM_SAMPLES {
        return Err(Error::usage(format!(
            "the experiment would record {n} samples, more than the limit of {MAX_SIM_SAMPLES} \
             a simulation may record (MAX_SIM_SAMPLES, about 60 bytes per sample); use fewer \
             periods (or a shorter period) and simulate several records with different seeds"
        )));
    }
    Ok(())
}

/// The simulation options of an experiment.
fn sim_options(exp: &Experiment) -> SimOptions {
    SimOptions {
        mode: exp.mode,
        seed: exp.seed,
        noise: exp.noise,
        record_b: exp.record_b,
        ..SimOptions::default()
    }
}

fn simulate_with(twin: Twin, exp: &Experiment, excitation: Excitation) -> Result<ExperimentOutput> {
    check_sim_length(excitation.values.len())?;
    let opts = sim_options(exp);
    let record = twin
        .simulate(&excitation.values, &opts)
        .context("simulating the closed loop")?;
    Ok(ExperimentOutput {
        twin,
        excitation,
        record,
    })
}

impl ExperimentOutput {
    /// The period-averaged closed-loop FRFs of a periodic experiment ([`from_periodic`]:
    /// joint input–output plant, T_ry, S = T_ru, variances and coherences) on the excited lines in
    /// `band_hz`, with the first period dropped (the transient); with `controller`, also the
    /// indirect plant estimate.
    ///
    /// [`from_periodic`]: ambid_core::frf::closed_loop::from_periodic
    ///
    /// # Errors
    /// A non-periodic excitation, or the errors of the periodic analysis.
    pub fn periodic_frf(
        &self,
        band_hz: (f64, f64),
        controller: Option<&ambid_core::lti::StateSpace>,
    ) -> Result<ambid_core::frf::closed_loop::ClosedLoopFrf> {
        use ambid_core::frf::closed_loop::{from_periodic, Channels};
        use ambid_core::frf::periodic::PeriodicAnalyzer;
        let (period, opts) = self.periods("use a Welch estimate instead")?;
        let rec = &self.record;
        let mut an = PeriodicAnalyzer::new(period)?;
        let s = an.analyze(&[&rec.r, &rec.u, &rec.y], 1.0 / rec.ts, &opts)?;
        let lines: Vec<usize> = s
            .excited_lines(0, 1e-6)?
            .into_iter()
            .filter(|&k| (band_hz.0..=band_hz.1).contains(&s.line_hz(k)))
            .collect();
        Ok(from_periodic(
            &s,
            Channels { r: 0, u: 1, y: 2 },
            &lines,
            controller,
        )?)
    }

    /// The plant FRF's deviation in each analysed period on the lines of `frd` (a
    /// [`periodic_frf`](Self::periodic_frf) of this record), `[period][line]`
    /// ([`plant_period_deviations`](ambid_core::frf::closed_loop::plant_period_deviations)): what
    /// the spread across periods that the per-line variances summarise
    /// (docs/uncertainty.md, "Independent noise realisations", uses them to test whether the
    /// FRF's error is correlated over the band).
    ///
    /// # Errors
    /// A record that is not periodic, a line of `frd` that is not a line of the period, and
    /// those of `plant_period_deviations`.
    pub fn period_deviations(&self, frd: &ambid_core::lti::Frd) -> Result<Vec<Vec<Complex64>>> {
        use ambid_core::frf::closed_loop::{plant_period_deviations, Channels};
        let (period, opts) = self.periods("no deviations across periods")?;
        let rec = &self.record;
        let df = 1.0 / (rec.ts * period as f64);
        let mut lines = Vec::with_capacity(frd.len());
        for &f in frd.f_hz() {
            let k = (f / df).round();
            if (f / df - k).abs() > 1e-6 {
                return Err(Error::other(format!(
                    "{f} Hz is not a line of the {period}-sample period ({df} Hz apart)"
                )));
            }
            lines.push(k as usize);
        }
        Ok(plant_period_deviations(
            &[&rec.r, &rec.u, &rec.y],
            1.0 / rec.ts,
            Channels { r: 0, u: 1, y: 2 },
            &opts,
            &lines,
        )?)
    }

    /// The period length in samples and how the record is cut into periods (the first one
    /// skipped as the transient) for [`periodic_frf`](Self::periodic_frf) and
    /// [`period_deviations`](Self::period_deviations); an excitation of one period is refused
    /// with `otherwise` as the advice.
    fn periods(
        &self,
        otherwise: &str,
    ) -> Result<(usize, ambid_core::frf::periodic::PeriodicOptions)> {
        let period = self.excitation.period_samples;
        if self.excitation.periods < 2 {
            return Err(Error::other(format!(
                "the excitation is not periodic (one period): {otherwise}"
            )));
        }
        Ok((
            period,
            ambid_core::frf::periodic::PeriodicOptions::new(period).skip(1),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peak(x: &[f64]) -> f64 {
        x.iter().fold(0.0f64, |m, v| m.max(v.abs()))
    }

    #[test]
    fn every_kind_gives_the_seed_record_length_and_the_stated_level() {
        let (i_sat, ts) = (2.0, 5e-5);
        for kind in [
            ExcitationKind::Prbs,
            ExcitationKind::Chirp,
            ExcitationKind::Noise,
            ExcitationKind::Multisine,
            ExcitationKind::None,
        ] {
            let plan = ExcitationPlan {
                kind,
                ..ExcitationPlan::default()
            };
            let e = plan.generate(i_sat, ts).unwrap();
            assert_eq!(e.values.len(), 102_300, "{kind:?}");
            let level = 0.1 * i_sat;
            match kind {
                ExcitationKind::Prbs | ExcitationKind::Chirp => {
                    assert!((peak(&e.values) - level).abs() < 1e-3 * level, "{kind:?}")
                }
                ExcitationKind::Multisine => {
                    assert!((peak(&e.values) - level).abs() < 1e-12, "{kind:?}")
                }
                ExcitationKind::Noise => {
                    let rms = (e.values.iter().map(|v| v * v).sum::<f64>() / e.values.len() as f64)
                        .sqrt();
                    assert!((rms - level).abs() < 1e-9, "{rms}")
                }
                ExcitationKind::None => assert_eq!(peak(&e.values), 0.0),
            }
        }
    }

    #[test]
    fn out_of_range_levels_are_rejected() {
        for frac in [-0.1, f64::NAN, f64::INFINITY, 1.5] {
            let plan = ExcitationPlan {
                amplitude_frac: frac,
                ..ExcitationPlan::default()
            };
            assert!(plan.generate(2.0, 5e-5).is_err(), "{frac}");
        }
    }
}
