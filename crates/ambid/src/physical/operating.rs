//! The magnet's constant and effective air gap from the operating-point study (issue 23): the
//! gray box at each operating point, then the magnet law $k_i = 4ki_0/g^2$,
//! $k_x = 4ki_0^2/g^3$ through the estimates ([`fit_magnet_law`], module docs of
//! `ambid_core::estimate::graybox::magnet`). One call for `ambid physical --bias-current …
//! --operating …` and the workflow ([`estimate_at_operating_points`]) and the twin check of the
//! whole chain on a rig ([`OperatingRun`]), which the tests and the `physical_operating_rigs`
//! example run.

use super::{twin_drawing, twin_truth, PhysicalFit, PhysicalOptions, PhysicalParams};
use crate::error::{Context, Error, Result};
use crate::experiment::{run_batch, ExcitationPlan, Experiment};
use ambid_core::estimate::graybox::{
    fit_machine_physical, fit_physical, Drawing, Hints, MachinePhysicalFit, Rotation,
};
pub use ambid_core::estimate::graybox::{
    fit_magnet_law, AtOperatingPoint, MagnetLawFit, Predicted,
};
use ambid_core::lti::{Frd, StateSpace};
use ambid_twin::{random_rig, Machine, Mode, Twin, TwinConfig};
use rayon::prelude::*;

/// One operating point other than the nominal one: its bias current, its gap offset from the
/// nominal gap and its plant FRF (same axis, same controller at B, same drawing).
#[derive(Debug, Clone, Copy)]
pub struct OperatingFrf<'a> {
    /// Bias current \[A\].
    pub bias_current_a: f64,
    /// Gap offset from the nominal gap \[m\] (positive = wider).
    pub gap_offset_m: f64,
    /// The plant FRF at this operating point (with variances).
    pub frd: &'a Frd,
}

/// The gray box at every operating point and the magnet law through them.
#[derive(Debug, Clone)]
pub struct OperatingEstimate {
    /// The gray-box fit at each other operating point, in the order given.
    pub fits: Vec<PhysicalFit>,
    /// The magnet law through the nominal point and the others (nominal first).
    pub law: MagnetLawFit,
}

/// The starts at another operating point from the nominal estimate: the unstable pole scaled
/// by $\sqrt{k_{x,j}/k_{x,0}}$ with $k_x \propto i_0^2/g^3$ and the nominal point's own gap
/// $g = i_0 k_i/k_x$ (its static ratio), the bending mode at the nominal estimate. (The
/// unstable pole of the rotor pinned at B is exactly $\propto\sqrt{k_x}$; the fit refines it.)
fn hints_at(nominal: &PhysicalFit, nominal_bias: f64, bias: f64, offset: f64) -> Hints {
    let g = nominal_bias * nominal.params.k_i / nominal.params.k_x;
    let ratio = (bias / nominal_bias).powi(2) * (g / (g + offset).max(0.05 * g)).powi(3);
    Hints {
        unstable_pole_rad_s: nominal.unstable_pole_rad_s * ratio.sqrt(),
        bending: vec![(nominal.params.bending_hz, nominal.params.bending_damping)],
    }
}

/// A usage error unless every bias is positive and finite and every offset finite.
fn check_set_points(nominal_bias: f64, others: &[OperatingFrf<'_>]) -> Result<()> {
    let ok = |i: f64| i.is_finite() && i > 0.0;
    if !ok(nominal_bias) {
        return Err(Error::usage(format!(
            "the nominal bias current must be positive and finite (A), got {nominal_bias}"
        )));
    }
    for (n, o) in others.iter().enumerate() {
        if !ok(o.bias_current_a) || !o.gap_offset_m.is_finite() {
            return Err(Error::usage(format!(
                "operating point {}: bias {} A, gap offset {} m; the bias must be positive and \
                 the offset finite",
                n + 1,
                o.bias_current_a,
                o.gap_offset_m
            )));
        }
    }
    Ok(())
}

/// The gray box at each of `others` (starts from `nominal`: the unstable pole scaled through the law, the bending mode at the nominal estimate) and the magnet law
/// through `nominal` (at bias `nominal_bias`, offset 0) and them, at `opts.confidence`.
///
/// # Errors
/// A usage error for a bias that is not positive and finite or an offset that is not finite
/// (naming the operating point); the gray box's errors at a point, naming it; those of
/// [`fit_magnet_law`].
pub fn estimate_at_operating_points(
    nominal: &PhysicalFit,
    nominal_bias: f64,
    others: &[OperatingFrf<'_>],
    drawing: &Drawing,
    controller_b: &StateSpace,
    opts: &PhysicalOptions,
) -> Result<OperatingEstimate> {
    check_set_points(nominal_bias, others)?;
    let fits: Vec<PhysicalFit> = others
        .par_iter()
        .enumerate()
        .map(|(n, o)| {
            let hints = hints_at(nominal, nominal_bias, o.bias_current_a, o.gap_offset_m);
            fit_physical(o.frd, drawing, controller_b, &hints, opts).with_context(|| {
                format!(
                    "the gray box at operating point {} (bias {} A, gap offset {} m)",
                    n + 1,
                    o.bias_current_a,
                    o.gap_offset_m
                )
            })
        })
        .collect::<Result<_>>()?;
    let mut points = vec![AtOperatingPoint::from_fit(nominal_bias, 0.0, nominal)];
    points.extend(
        others
            .iter()
            .zip(&fits)
            .map(|(o, f)| AtOperatingPoint::from_fit(o.bias_current_a, o.gap_offset_m, f)),
    );
    let law = fit_magnet_law(&points, opts.confidence).context("the magnet law")?;
    Ok(OperatingEstimate { fits, law })
}

/// The whole-machine gray box at each of `others` (its starts from the data, as for the
/// nominal one) and one magnet law per axis through `nominal` (at bias `nominal_bias`, offset
/// 0) and them ([`AtOperatingPoint::from_machine_fit`]): each bearing's magnet constant and
/// effective gap, in the axis order xa, xb, ya, yb.
///
/// # Errors
/// As [`estimate_at_operating_points`], with the axis named for the law.
pub fn estimate_machine_at_operating_points(
    nominal: &MachinePhysicalFit,
    nominal_bias: f64,
    others: &[OperatingFrf<'_>],
    drawing: &Drawing,
    rotation: &Rotation,
    opts: &PhysicalOptions,
) -> Result<MachineOperatingEstimate> {
    check_set_points(nominal_bias, others)?;
    let fits: Vec<MachinePhysicalFit> = others
        .par_iter()
        .enumerate()
        .map(|(n, o)| {
            fit_machine_physical(o.frd, drawing, rotation, &[], opts).with_context(|| {
                format!(
                    "the whole-machine gray box at operating point {} (bias {} A, gap offset {} m)",
                    n + 1,
                    o.bias_current_a,
                    o.gap_offset_m
                )
            })
        })
        .collect::<Result<_>>()?;
    let mut laws = Vec::with_capacity(4);
    for (axis, name) in ambid_core::data::AXES.iter().enumerate() {
        let mut points = vec![AtOperatingPoint::from_machine_fit(
            nominal_bias,
            0.0,
            nominal,
            axis,
        )?];
        for (o, f) in others.iter().zip(&fits) {
            points.push(AtOperatingPoint::from_machine_fit(
                o.bias_current_a,
                o.gap_offset_m,
                f,
                axis,
            )?);
        }
        laws.push(
            fit_magnet_law(&points, opts.confidence)
                .with_context(|| format!("the magnet law of axis {name}"))?,
        );
    }
    Ok(MachineOperatingEstimate { fits, laws })
}

/// The whole-machine gray box at every other operating point and each axis' magnet law.
#[derive(Debug, Clone)]
pub struct MachineOperatingEstimate {
    /// The gray-box fit at each other operating point, in the order given.
    pub fits: Vec<MachinePhysicalFit>,
    /// The magnet law of each axis, xa, xb, ya, yb.
    pub laws: Vec<MagnetLawFit>,
}

/// Each axis' magnet constant and gap of a machine \[N m²/A², m\], from its linearised magnets
/// ([`Machine::axis_magnets`]) at the configured bias $i_0$: $g = i_0 k_i/k_x$,
/// $k = k_i g^2/(4 i_0)$.
pub fn machine_magnet_truth(machine: &Machine) -> [(f64, f64); 4] {
    let (ki, kx) = machine.axis_magnets();
    let i0 = machine.config().operating_point.bias_current_a;
    std::array::from_fn(|a| {
        let g = i0 * ki[a] / kx[a];
        (ki[a] * g * g / (4.0 * i0), g)
    })
}

/// The twin's magnet constant and nominal air gap \[N m²/A², m\].
pub fn twin_magnet_truth(twin: &Twin) -> (f64, f64) {
    let lp = twin.linear_params();
    (lp.force_constant, lp.air_gap_m)
}

/// One run of the operating-point chain on the twin: rig `rig` (0 = nominal), the seed's cases
/// (nominal, bias ±20 %, gap ±10 µm about the rig's own operating point), the seed experiment
/// of each at one or more excitation levels (case $j$ at level $l$ with noise seed
/// `seed + j + 100 l`), the plant FRF on the band of the physical runs, the black-box model and
/// gray box at nominal and the first level (as [`super::PhysicalRun`]), the gray box at every
/// other case and level (starts from it, as in [`estimate_at_operating_points`]); with one level the magnet law through
/// the cases' estimates, with several through each case's estimate at zero amplitude
/// ([`AtOperatingPoint::from_levels`]); with every truth.
#[derive(Debug, Clone)]
pub struct OperatingRun {
    /// Each case's bias current \[A\] and gap offset \[m\], nominal first.
    pub cases: Vec<(f64, f64)>,
    /// The excitation levels (fractions of $i_\text{sat}$).
    pub levels: Vec<f64>,
    /// The gray box at each case (nominal first) and level: `fits[case][level]`.
    pub fits: Vec<Vec<PhysicalFit>>,
    /// The points the magnet law was fitted to, in the order of the cases.
    pub points: Vec<AtOperatingPoint>,
    /// Each case's truth, nominal first.
    pub truths: Vec<PhysicalParams>,
    /// The magnet law.
    pub law: MagnetLawFit,
    /// The twin's magnet constant \[N m²/A²\].
    pub truth_force_constant: f64,
    /// The twin's nominal air gap \[m\].
    pub truth_air_gap_m: f64,
}

impl OperatingRun {
    /// Runs the chain (type docs) at the seed experiment's default level.
    ///
    /// # Errors
    /// Any step's error.
    pub fn on_twin(rig: u64, seed: u64, mode: Mode) -> Result<Self> {
        Self::on_twin_at(rig, seed, mode, &[ExcitationPlan::default().amplitude_frac])
    }

    /// [`Self::on_twin`] with the PRBS at each of `levels` (fractions of $i_\text{sat}$).
    ///
    /// # Errors
    /// No level, and any step's error.
    pub fn on_twin_at(rig: u64, seed: u64, mode: Mode, levels: &[f64]) -> Result<Self> {
        if levels.is_empty() {
            return Err(Error::usage("no excitation level"));
        }
        let nominal = if rig == 0 {
            TwinConfig::default()
        } else {
            random_rig(rig).context("drawing the rig")?
        };
        let cases: Vec<(f64, f64)> = crate::study::seed_cases(&nominal)
            .iter()
            .map(|c| {
                (
                    c.bias_current_a,
                    c.air_gap_m - nominal.operating_point.air_gap_m,
                )
            })
            .collect();
        let (nc, nl) = (cases.len(), levels.len());
        let exps: Vec<Experiment> = (0..nc * nl)
            .map(|n| {
                let (j, l) = (n / nl, n % nl);
                let mut cfg = nominal.clone();
                cfg.operating_point.bias_current_a = cases[j].0;
                cfg.operating_point.air_gap_m += cases[j].1;
                Experiment {
                    twin: cfg,
                    excitation: ExcitationPlan {
                        amplitude_frac: levels[l],
                        ..ExcitationPlan::default()
                    },
                    mode,
                    seed: seed.wrapping_add((j + 100 * l) as u64),
                    noise: true,
                    record_b: false,
                }
            })
            .collect();
        let outs: Vec<_> = run_batch(&exps)
            .into_iter()
            .enumerate()
            .map(|(n, o)| {
                o.with_context(|| format!("operating point {} at level {}", n / nl, levels[n % nl]))
            })
            .collect::<Result<_>>()?;
        let frds: Vec<Frd> = outs
            .par_iter()
            .map(|o| Ok(o.periodic_frf(super::TWIN_BAND_HZ, None)?.plant))
            .collect::<Result<_>>()?;
        let twin = &outs[0].twin;
        let controller = twin.controller().clone();
        let drawing = twin_drawing(twin.config());
        let opts = PhysicalOptions::default();
        let first = super::estimate_with_starts_from_data(&frds[0], &drawing, &controller, &opts)?;
        let bias0 = cases[0].0;
        let rest: Vec<PhysicalFit> = (1..nc * nl)
            .into_par_iter()
            .map(|n| {
                let (bias, offset) = cases[n / nl];
                let hints = hints_at(&first, bias0, bias, offset);
                fit_physical(&frds[n], &drawing, &controller, &hints, &opts).with_context(|| {
                    format!(
                        "the gray box at operating point {} and level {}",
                        n / nl,
                        levels[n % nl]
                    )
                })
            })
            .collect::<Result<_>>()?;
        let mut all = vec![first];
        all.extend(rest);
        let fits: Vec<Vec<PhysicalFit>> = all.chunks(nl).map(<[PhysicalFit]>::to_vec).collect();
        let points: Vec<AtOperatingPoint> = fits
            .iter()
            .zip(&cases)
            .map(|(per_level, &(bias, offset))| {
                if nl == 1 {
                    Ok(AtOperatingPoint::from_fit(bias, offset, &per_level[0]))
                } else {
                    let at: Vec<(f64, &PhysicalFit)> =
                        levels.iter().copied().zip(per_level.iter()).collect();
                    AtOperatingPoint::from_levels(bias, offset, &at, opts.confidence)
                        .context("the extrapolation to zero amplitude")
                }
            })
            .collect::<Result<_>>()?;
        let law = fit_magnet_law(&points, opts.confidence).context("the magnet law")?;
        let (k, g0) = twin_magnet_truth(twin);
        Ok(Self {
            cases,
            levels: levels.to_vec(),
            fits,
            points,
            truths: outs
                .iter()
                .step_by(nl)
                .map(|o| twin_truth(&o.twin))
                .collect(),
            law,
            truth_force_constant: k,
            truth_air_gap_m: g0,
        })
    }
}

/// The whole-machine operating-point chain on the 4-axis twin: machine rig `rig`
/// ([`ambid_twin::random_machine_rig`], 0 = the nominal machine) at `speed_rpm`, with
/// `same_gap` each magnet's $k_x$ factor set to its $k_i$ factor (so every magnet keeps the
/// configured gap and differs only in its constant); three cases (nominal, bias −20 %, gap
/// +10 µm), case $j$ with seed `seed + j`; the `[machine]` default experiment and the 4×4 FRF on
/// the band of the physical runs for each; the whole-machine gray box at each; one magnet law
/// per axis; and each axis' true constant and gap ([`machine_magnet_truth`]).
///
/// On the twin a magnet whose $k_x$ factor differs from its $k_i$ factor is realised with the
/// gap $g_0 f_i/f_x$, so a gap change $\Delta$ moves it by $\Delta f_i/f_x$, not by $\Delta$; the
/// law with the stated offsets then misfits by that ratio (docs/physical.md).
#[derive(Debug, Clone)]
pub struct MachineOperatingRun {
    /// Each case's bias current \[A\] and gap offset \[m\], nominal first.
    pub cases: Vec<(f64, f64)>,
    /// The magnet law of each axis (xa, xb, ya, yb).
    pub laws: Vec<MagnetLawFit>,
    /// Each axis' true magnet constant and gap.
    pub truth: [(f64, f64); 4],
}

impl MachineOperatingRun {
    /// Runs the chain (type docs) on the linear or nonlinear twin.
    ///
    /// # Errors
    /// Any step's error.
    pub fn on_twin(
        rig: u64,
        seed: u64,
        speed_rpm: f64,
        mode: Mode,
        same_gap: bool,
    ) -> Result<Self> {
        let mut base = if rig == 0 {
            ambid_twin::MachineConfig::default()
        } else {
            ambid_twin::random_machine_rig(rig)?
        };
        base.speed_rpm = speed_rpm;
        if same_gap {
            base.asymmetry.kx_rel = base.asymmetry.ki_rel;
            base.asymmetry.kx_rel_b = base.asymmetry.ki_rel_b;
        }
        let (i0, g0) = (
            base.operating_point.bias_current_a,
            base.operating_point.air_gap_m,
        );
        let cases = vec![(i0, 0.0), (0.8 * i0, 0.0), (i0, 10e-6)];
        let section = crate::config::MachineSection {
            speeds_rpm: Some(vec![speed_rpm]),
            mode: match mode {
                Mode::Linear => "linear".into(),
                Mode::Nonlinear => "nonlinear".into(),
            },
            ..Default::default()
        };
        let (drawing, rotation) = super::machine_drawing(&base);
        let opts = PhysicalOptions::default();
        // each case's experiment (in parallel), then the gray boxes and the laws as the CLI
        let frds: Vec<Frd> = cases
            .par_iter()
            .enumerate()
            .map(|(j, &(bias, offset))| {
                let mut cfg = base.clone();
                cfg.operating_point.bias_current_a = bias;
                cfg.operating_point.air_gap_m = g0 + offset;
                super::twin_machine_frf(cfg, &section, seed.wrapping_add(j as u64))
                    .with_context(|| format!("the 4-axis experiment of operating point {j}"))
            })
            .collect::<Result<_>>()?;
        let nominal = fit_machine_physical(&frds[0], &drawing, &rotation, &[], &opts)
            .context("the gray box of the nominal operating point")?;
        let others: Vec<OperatingFrf<'_>> = cases[1..]
            .iter()
            .zip(&frds[1..])
            .map(|(&(bias_current_a, gap_offset_m), frd)| OperatingFrf {
                bias_current_a,
                gap_offset_m,
                frd,
            })
            .collect();
        let laws = estimate_machine_at_operating_points(
            &nominal, cases[0].0, &others, &drawing, &rotation, &opts,
        )?
        .laws;
        Ok(Self {
            cases,
            laws,
            truth: machine_magnet_truth(&Machine::new(base)?),
        })
    }
}
