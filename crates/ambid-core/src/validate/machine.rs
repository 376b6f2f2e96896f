//! Whole-machine validation of an identified multivariable plant: the identified $n \times n$
//! plant $\hat P$ closed with the real (e.g. four decentralised) controllers $C$ and compared,
//! axis by axis, with an independent closed-loop record.
//!
//! # What is computed
//! For a record with the channels `y_<axis>`, `u_<axis>` and `r_<axis>` (and optionally
//! `w_<axis>`, `i_<axis>`; axis order as [`IoData::role_names`], e.g. `xa, xb, ya, yb`):
//! * **Closed-loop simulation** of $u = r + C(w - y)$, $y = \hat P u$ driven by the recorded
//!   $r$ (and $w$), from the loop's initial state that best explains the record
//!   ([`reconstruct_mimo`], [`InitialState::Estimate`] by default; simulated in a state basis
//!   scaled so that every state is seen equally at the outputs, which keeps that least squares
//!   well conditioned), and per axis the fit
//!   ([`fit_percent`]) of the **displacement** $y_k$ and of the **current reference** $u_k$ (the
//!   controller output the amplifier follows: what the SISO validation calls the current).
//! * **Coil current** $i_k$, when recorded: $\hat P$ does not contain the amplifier (it maps $u$
//!   to $y$), so $i$ is predicted from the simulated $\hat u_k$ through an amplifier model
//!   identified on the record's own $u_k \to i_k$ relation (an ARX model, default
//!   $n_a = 1$, $n_b = 2$, $n_k = 1$, [`CurrentModel`]; the amplifier is a stable, fast current
//!   loop measured in open loop by its own input and output, so this fit is consistent). The
//!   fit of $i_k$ then judges $\hat P$ through $\hat u_k$; the amplifier model's own one-step fit
//!   is reported with it.
//! * **Residual tests per output**: the output error $\varepsilon_k = y_k - \hat y_k$ of the
//!   simulated loop is, for the true plant, the noise through the loop (coloured), so only its
//!   **independence from the excitations** is tested ([`analyze_output_error`], generalised
//!   portmanteau), against every excited channel $r_j$ (a wrong cross-coupling $\hat P_{kj}$
//!   shows against $r_j$, not against $r_k$). The per-output verdict passes when every one of its
//!   $m$ tests has $Q$ below the $\chi^2$ quantile at the Bonferroni level $1 - 0.05/m$, so a
//!   true plant fails the verdict of an output in at most 5 % of records.
//! * **Sensitivity**: $S(e^{j\omega T_s}) = (I + C\hat P)^{-1}$ on a logarithmic grid (default
//!   4000 points from 1 Hz to $f_s/2$), its largest singular value $\bar\sigma(S)$ with its peak,
//!   and per axis $S_{kk}$ — the sensitivity of loop $k$ with the other loops closed, which is
//!   what ISO 14839-3 measures by injecting $r_k$ and reading $u_k$ — with its peak and
//!   ISO 14839-3 zone ([`sensitivity_zone`]). Each peak is refined between the grid neighbours
//!   of the largest grid value by golden-section search (the same search as the twin's
//!   `peak_sensitivity`).
//! * **Closed-loop model and poles**: $T_{ry} = (I + \hat P C)^{-1}\hat P$ as a state space
//!   ([`StateSpace::feedback`]; its states are the plant's then the controller's, so a modal
//!   analysis can read the plant part of every eigenvector) and its poles.
//!
//! A model that makes the loop unstable is not simulated: [`validate_machine`] returns
//! [`Error::Unstable`] with the unstable closed-loop poles. [`machine_output_fits`] gives the
//! displacement fits alone (the same closed-loop simulation without the grid, the tests and
//! the current fits), for a reference plant whose fits are compared with a model's.
//!
//! # Example
//! ```
//! use ambid_core::data::IoData;
//! use ambid_core::lti::StateSpace;
//! use ambid_core::validate::closed_loop::simulate_loop_mimo;
//! use ambid_core::validate::machine::{validate_machine, MachineValidationOptions};
//! use faer::mat;
//! // two coupled axes, one unstable, under proportional control
//! let ts = 1e-3;
//! let p = StateSpace::discrete(mat![[1.02, 0.05], [0.05, 0.9]], mat![[1.0, 0.0], [0.0, 1.0]],
//!     mat![[1.0, 0.0], [0.0, 1.0]], mat![[0.0, 0.0], [0.0, 0.0]], ts).unwrap();
//! let c = StateSpace::discrete(faer::Mat::zeros(0, 0), faer::Mat::zeros(0, 2),
//!     faer::Mat::zeros(2, 0), mat![[0.5, 0.0], [0.0, 0.3]], ts).unwrap();
//! let r0: Vec<f64> = (0..2000).map(|k| ((k * 7919 % 13) as f64 - 6.0)).collect();
//! let r1: Vec<f64> = (0..2000).map(|k| ((k * 104_729 % 11) as f64 - 5.0)).collect();
//! let sim = simulate_loop_mimo(&p, &c, None, Some(&[&r0[..], &r1[..]]), None).unwrap();
//! let rec = IoData::new(vec![
//!     ("r_xa".into(), r0), ("r_xb".into(), r1),
//!     ("u_xa".into(), sim.u[0].clone()), ("u_xb".into(), sim.u[1].clone()),
//!     ("y_xa".into(), sim.y[0].clone()), ("y_xb".into(), sim.y[1].clone()),
//! ], ts, None).unwrap();
//! let v = validate_machine(&p, &c, &rec, &MachineValidationOptions::default()).unwrap();
//! assert_eq!(v.axes.len(), 2);
//! assert!(v.axes.iter().all(|a| (a.fit_y - 100.0).abs() < 1e-9 && a.fit_i.is_none()));
//! assert!(v.sigma_max_peak >= v.axes[0].iso.peak - 1e-12); // σ̄(S) ≥ |S_kk|
//! ```

use crate::c64;
use crate::data::{IoData, Role};
use crate::error::{Error, Result};
use crate::estimate::arx::{arx, ArxModel, ArxOrders};
use crate::lti::{Frd, StateSpace};
use crate::validate::closed_loop::{reconstruct_mimo, ReconstructionMimo, WindowFit};
use crate::validate::fit::fit_percent;
use crate::validate::iso::{sensitivity_zone, IsoVerdict, IsoZones};
use crate::validate::predict::InitialState;
use crate::validate::residuals::{analyze_output_error, ResidualTest};
use faer::Mat;

/// How the coil current $i$ is predicted from the simulated current reference $\hat u$.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CurrentModel {
    /// An ARX amplifier model $A(q)\,i = B(q)\,u$ per axis, fitted by least squares on the
    /// record's own $u_k \to i_k$ ([`crate::estimate::arx::arx`]); refused unless stable.
    Arx {
        /// Number of $A$ coefficients.
        na: usize,
        /// Number of $B$ coefficients.
        nb: usize,
        /// Delay of $u$ in samples.
        nk: usize,
    },
    /// No current prediction (the `i` channels are ignored).
    Off,
}

impl Default for CurrentModel {
    /// ARX with $n_a = 1$, $n_b = 2$, $n_k = 1$: a first-order amplifier behind up to two
    /// samples of delay (the twin's amplifier, a first-order lag behind the one-sample
    /// computation delay, is $i_k = a\,i_{k-1} + b\,u_{k-2}$, inside this set). Larger orders
    /// than the data need make the regressor of noise-free data rank-deficient (an error).
    fn default() -> Self {
        CurrentModel::Arx {
            na: 1,
            nb: 2,
            nk: 1,
        }
    }
}

/// Settings of [`validate_machine`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MachineValidationOptions {
    /// Leading samples excluded from the fits and residual tests. Default 0 (the loop starts
    /// from its estimated initial state).
    pub skip: usize,
    /// Largest lag $M$ of the residual tests. Default 25.
    pub lags: usize,
    /// Time windows of the windowed fits per axis. Default 10.
    pub windows: usize,
    /// How the simulated loop starts. Default [`InitialState::Estimate`].
    pub initial_state: InitialState,
    /// ISO 14839-3 zone limits.
    pub zones: IsoZones,
    /// Points of the logarithmic frequency grid of $S$. Default 4000.
    pub grid_points: usize,
    /// Lowest grid frequency \[Hz\]. Default 1.
    pub f_min_hz: f64,
    /// Highest grid frequency \[Hz\]; `None` = the Nyquist frequency $f_s/2$.
    pub f_max_hz: Option<f64>,
    /// Prediction of the coil current from $\hat u$.
    pub current: CurrentModel,
}

impl Default for MachineValidationOptions {
    fn default() -> Self {
        Self {
            skip: 0,
            lags: 25,
            windows: 10,
            initial_state: InitialState::Estimate,
            zones: IsoZones::default(),
            grid_points: 4000,
            f_min_hz: 1.0,
            f_max_hz: None,
            current: CurrentModel::default(),
        }
    }
}

/// The residual tests of one output.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct OutputResiduals {
    /// The channel each test was run against (`r_xa`, …; `w_…` for a record without excitation).
    pub inputs: Vec<String>,
    /// Independence of the output error from each of `inputs` ([`analyze_output_error`]).
    pub tests: Vec<ResidualTest>,
    /// The Bonferroni level $1 - 0.05/m$ of the verdict ($m$ = number of tests).
    pub level: f64,
    /// The $\chi^2$ quantile at `level` for each test's degrees of freedom.
    pub thresholds: Vec<f64>,
    /// Every test's statistic below its threshold.
    pub pass: bool,
}

/// The validation of one axis.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AxisValidation {
    /// Axis name (the channel suffix: `xa`, …; empty for bare `y`, `u`).
    pub axis: String,
    /// Fit of the displacement $y$ after `skip` \[%\].
    pub fit_y: f64,
    /// Fit of the current reference (controller output) $u$ after `skip` \[%\].
    pub fit_u: f64,
    /// Fit of the coil current $i$ after `skip` \[%\], predicted from $\hat u$ through the
    /// amplifier model (`None` without an `i` channel or with [`CurrentModel::Off`]).
    pub fit_i: Option<f64>,
    /// The amplifier model's own one-step-ahead fit on the record \[%\] (how well $u \to i$ is
    /// modelled at all), when `fit_i` is given.
    pub amplifier_fit: Option<f64>,
    /// RMS displacement error after `skip`.
    pub rmse_y: f64,
    /// Windowed fits (whole record).
    pub windows: Vec<WindowFit>,
    /// Residual tests of the output error; `None` when the output error is identically zero
    /// (a perfect reproduction of noise-free data, where correlations are undefined).
    pub residuals: Option<OutputResiduals>,
    /// Peak of $|S_{kk}|$ (other loops closed), its frequency and ISO 14839-3 zone.
    pub iso: IsoVerdict,
}

/// Everything [`validate_machine`] computes.
#[derive(Debug, Clone, serde::Serialize)]
pub struct MachineValidation {
    /// Per axis, in the record's axis order.
    pub axes: Vec<AxisValidation>,
    /// Peak of $\bar\sigma(S)$ over frequency.
    pub sigma_max_peak: f64,
    /// Its frequency \[Hz\].
    pub sigma_max_f_hz: f64,
    /// The frequency grid \[Hz\].
    pub grid_hz: Vec<f64>,
    /// $\bar\sigma(S)$ on the grid.
    pub sigma_max: Vec<f64>,
    /// $S_{kk}$ on the grid, per axis.
    #[serde(skip)]
    pub s_diag: Vec<Vec<c64>>,
    /// The closed-loop simulation (fits over the whole record, initial state in the models'
    /// own state bases: plant states, then controller states).
    pub reconstruction: ReconstructionMimo,
    /// The model's closed loop $T_{ry} = (I + \hat P C)^{-1}\hat P$ (inputs $r$, outputs $y$;
    /// states: the plant's, then the controller's).
    #[serde(skip)]
    pub closed_loop: StateSpace,
    /// Its poles (all inside the unit circle).
    #[serde(skip)]
    pub closed_loop_poles: Vec<c64>,
    /// The amplifier models per axis (when the current was predicted).
    #[serde(skip)]
    pub amplifiers: Vec<Option<ArxModel>>,
    /// Samples in the fits and tests (after `skip`).
    pub samples: usize,
}

/// The per-axis channels of a record.
struct Channels<'a> {
    axes: Vec<String>,
    y: Vec<&'a [f64]>,
    u: Vec<&'a [f64]>,
    r: Vec<Option<&'a [f64]>>,
    w: Vec<Option<&'a [f64]>>,
    i: Vec<Option<&'a [f64]>>,
}

fn axis_of(name: &str) -> &str {
    name.split_once('_').map_or("", |(_, a)| a)
}

fn channel_name(letter: &str, axis: &str) -> String {
    if axis.is_empty() {
        letter.to_string()
    } else {
        format!("{letter}_{axis}")
    }
}

fn channels(data: &IoData) -> Result<Channels<'_>> {
    data.require_single_experiment("validate_machine")?;
    let ys = data.role_names(Role::Output);
    if ys.is_empty() {
        return Err(data.missing_role(Role::Output));
    }
    let axes: Vec<String> = ys.iter().map(|n| axis_of(n).to_string()).collect();
    let find = |role: Role, axis: &str| -> Option<&[f64]> {
        data.role_names(role)
            .into_iter()
            .find(|n| axis_of(n) == axis)
            .and_then(|n| data.channel(n).ok())
    };
    let mut u = Vec::new();
    for ax in &axes {
        match find(Role::Input, ax) {
            Some(x) => u.push(x),
            None => {
                return Err(Error::invalid(
                    "data",
                    format!(
                        "the record has the output `{}` but no plant input `{}`: the closed-loop validation compares both per axis; add the controller output channel (u = r + C(w − y)) for every axis",
                        channel_name("y", ax),
                        channel_name("u", ax)
                    ),
                ))
            }
        }
    }
    let opt = |role: Role| -> Vec<Option<&[f64]>> { axes.iter().map(|a| find(role, a)).collect() };
    let (r, w, i) = (
        opt(Role::Excitation),
        opt(Role::Reference),
        opt(Role::Current),
    );
    let excited = |v: &[Option<&[f64]>]| v.iter().flatten().any(|x| x.iter().any(|s| *s != 0.0));
    if !excited(&r) && !excited(&w) {
        return Err(Error::invalid(
            "data",
            format!(
                "the record has no nonzero excitation ({}) or position reference ({}): nothing drives the loop to validate against; record the excitation added to the controller outputs",
                axes.iter().map(|a| channel_name("r", a)).collect::<Vec<_>>().join(", "),
                axes.iter().map(|a| channel_name("w", a)).collect::<Vec<_>>().join(", ")
            ),
        ));
    }
    Ok(Channels {
        axes,
        y: data.signals(Role::Output, 0)?,
        u,
        r,
        w,
        i,
    })
}

fn check_models(plant: &StateSpace, controller: &StateSpace, n_axes: usize, ts: f64) -> Result<()> {
    if plant.noutputs() != n_axes || plant.ninputs() != n_axes {
        return Err(Error::DimensionMismatch {
            context: "validate_machine: the plant maps the record's u channels to its y channels",
            expected: format!("{n_axes} outputs × {n_axes} inputs (one per axis of the record)"),
            got: format!("{} outputs × {} inputs", plant.noutputs(), plant.ninputs()),
        });
    }
    if controller.noutputs() != n_axes || controller.ninputs() != n_axes {
        return Err(Error::DimensionMismatch {
            context: "validate_machine: the controller maps the y channels to the u channels",
            expected: format!("{n_axes} outputs × {n_axes} inputs (one per axis of the record)"),
            got: format!(
                "{} outputs × {} inputs",
                controller.noutputs(),
                controller.ninputs()
            ),
        });
    }
    for (what, m) in [("plant", plant), ("controller", controller)] {
        match m.ts() {
            None => {
                return Err(Error::TimeDomain(format!(
                    "the {what} is a continuous-time model; validate_machine simulates the sampled loop: discretise it at the record's sample time {ts} s (c2d_zoh for a plant, the controller's own discretisation)"
                )))
            }
            Some(t) if (t - ts).abs() > 1e-9 * ts => {
                return Err(Error::SampleTimeMismatch { left: t, right: ts })
            }
            Some(_) => {}
        }
    }
    Ok(())
}

/// The closed loop of `plant` and `controller` simulated against the record `data` (the part of
/// [`validate_machine`] before the fits; its checks and errors).
struct Simulated<'d> {
    ch: Channels<'d>,
    k0: usize,
    n_axes: usize,
    ts: f64,
    n: usize,
    closed_loop: StateSpace,
    closed_loop_poles: Vec<c64>,
    reconstruction: ReconstructionMimo,
}

fn simulate_against<'d>(
    plant: &StateSpace,
    controller: &StateSpace,
    data: &'d IoData,
    opts: &MachineValidationOptions,
) -> Result<Simulated<'d>> {
    let ch = channels(data)?;
    let (n_axes, ts, n) = (ch.axes.len(), data.ts(), data.len());
    check_models(plant, controller, n_axes, ts)?;
    data.require_finite(&[
        Role::Output,
        Role::Input,
        Role::Excitation,
        Role::Reference,
        Role::Current,
    ])?;
    let k0 = opts.skip;
    let need = (4 * opts.lags.max(5)).max(20);
    if k0 + need > n {
        return Err(Error::invalid(
            "skip",
            format!(
                "skipping {k0} of {n} samples leaves {} for the residual tests with {} lags (at least {need} needed): skip fewer samples, use fewer lags or a longer record",
                n.saturating_sub(k0),
                opts.lags
            ),
        ));
    }
    // the model's closed loop: stable, or reported
    let closed_loop = plant.feedback(controller)?;
    let closed_loop_poles = closed_loop.poles()?;
    let unstable: Vec<String> = closed_loop_poles
        .iter()
        .filter(|z| z.norm() >= 1.0)
        .map(|z| format!("{:.6}{:+.6}j (|z| = {:.6})", z.re, z.im, z.norm()))
        .collect();
    if !unstable.is_empty() {
        return Err(Error::Unstable {
            context: "validate_machine",
            reason: format!(
                "the model does not give a stable closed loop with this controller, so it cannot be simulated against the record; unstable closed-loop poles: {}. The model is wrong near the loops' crossover (e.g. a wrong count or place of its unstable poles), or the controller does not match the one of the record",
                unstable.join(", ")
            ),
        });
    }
    let zeros = vec![0.0; n];
    let r: Vec<&[f64]> = ch.r.iter().map(|x| x.unwrap_or(&zeros)).collect();
    let w: Vec<&[f64]> = ch.w.iter().map(|x| x.unwrap_or(&zeros)).collect();
    let has_r = ch.r.iter().any(|x| x.is_some());
    let has_w = ch.w.iter().any(|x| x.is_some());
    // the simulation in a state basis where every state is seen equally at the outputs: the
    // initial-state least squares would otherwise truncate badly scaled states (displacements
    // in m next to currents in A) and miss a noise-free record by ~1e-5 points
    let (plant_b, plant_scale) = observability_scaled(plant)?;
    let (ctl_b, ctl_scale) = observability_scaled(controller)?;
    let mut reconstruction = reconstruct_mimo(
        &plant_b,
        &ctl_b,
        has_w.then_some(&w[..]),
        has_r.then_some(&r[..]),
        &ch.y,
        &ch.u,
        opts.windows,
        ts,
        opts.initial_state,
    )?;
    // the initial state in the models' own bases: x = D x'
    for (x, d) in reconstruction
        .initial_state
        .iter_mut()
        .zip(plant_scale.iter().chain(&ctl_scale))
    {
        *x *= d;
    }
    Ok(Simulated {
        ch,
        k0,
        n_axes,
        ts,
        n,
        closed_loop,
        closed_loop_poles,
        reconstruction,
    })
}

/// The displacement fit $\mathrm{fit}_y$ of every axis ([`AxisValidation::fit_y`]) alone: the
/// closed-loop simulation of [`validate_machine`] without its sensitivity grid, residual tests
/// and current fits (for a reference plant whose fit is compared with a model's; the same
/// numbers as [`validate_machine`]'s).
///
/// # Errors
/// As [`validate_machine`] before its fits.
///
/// # Example
/// ```
/// use ambid_core::data::IoData;
/// use ambid_core::lti::StateSpace;
/// use ambid_core::validate::closed_loop::simulate_loop_mimo;
/// use ambid_core::validate::machine::{machine_output_fits, validate_machine, MachineValidationOptions};
/// use faer::mat;
/// let ts = 1e-3;
/// let plant = |a: f64| StateSpace::discrete(mat![[a, 0.05], [0.05, 0.9]],
///     mat![[1.0, 0.0], [0.0, 1.0]], mat![[1.0, 0.0], [0.0, 1.0]], mat![[0.0, 0.0], [0.0, 0.0]], ts).unwrap();
/// let c = StateSpace::discrete(faer::Mat::zeros(0, 0), faer::Mat::zeros(0, 2),
///     faer::Mat::zeros(2, 0), mat![[0.5, 0.0], [0.0, 0.3]], ts).unwrap();
/// let r0: Vec<f64> = (0..2000).map(|k| ((k * 7919 % 13) as f64 - 6.0)).collect();
/// let r1: Vec<f64> = (0..2000).map(|k| ((k * 104_729 % 11) as f64 - 5.0)).collect();
/// let sim = simulate_loop_mimo(&plant(1.02), &c, None, Some(&[&r0[..], &r1[..]]), None).unwrap();
/// let rec = IoData::new(vec![
///     ("r_xa".into(), r0), ("r_xb".into(), r1),
///     ("u_xa".into(), sim.u[0].clone()), ("u_xb".into(), sim.u[1].clone()),
///     ("y_xa".into(), sim.y[0].clone()), ("y_xb".into(), sim.y[1].clone()),
/// ], ts, None).unwrap();
/// // a model with the unstable pole off: the same fits as the whole validation's, below 100 %
/// let opts = MachineValidationOptions::default();
/// let fits = machine_output_fits(&plant(1.01), &c, &rec, &opts).unwrap();
/// let full = validate_machine(&plant(1.01), &c, &rec, &opts).unwrap();
/// assert_eq!(fits, full.axes.iter().map(|a| a.fit_y).collect::<Vec<_>>());
/// assert!(fits[0] < 99.0);
/// ```
pub fn machine_output_fits(
    plant: &StateSpace,
    controller: &StateSpace,
    data: &IoData,
    opts: &MachineValidationOptions,
) -> Result<Vec<f64>> {
    let Simulated {
        ch,
        k0,
        reconstruction,
        ..
    } = simulate_against(plant, controller, data, opts)?;
    ch.y.iter()
        .zip(&reconstruction.simulated.y)
        .map(|(y, s)| fit_percent(&y[k0..], &s[k0..]))
        .collect()
}

/// Validates the identified plant `plant` ($n \times n$, discrete) with the `controller`
/// ($n \times n$, mapping $w - y$ to the controller output) on the independent record `data`
/// (module docs). The record's axes are its output channels (`y_<axis>` in
/// [`IoData::role_names`] order); each needs `u_<axis>`, and `r_<axis>`, `w_<axis>` (zero when
/// absent) and `i_<axis>` (current fit) are used when present.
///
/// # Errors
/// * [`Error::InvalidArgument`]: a record of several experiments, without outputs, with an
///   output without its input, or without any nonzero excitation or reference; too few samples
///   after `skip` for the residual tests; bad options (`windows`, grid).
/// * [`Error::DimensionMismatch`]: a plant or controller whose shape is not one input and one
///   output per axis of the record.
/// * [`Error::SampleTimeMismatch`], [`Error::TimeDomain`]: a model at another sample time than
///   the record, or a continuous one.
/// * [`Error::Unstable`]: the model does not give a stable closed loop with the controller (the
///   unstable poles are listed; nothing is simulated).
/// * [`Error::NonFinite`]: a NaN or infinite sample in a used channel.
/// * the errors of the amplifier fit (e.g. a constant current).
pub fn validate_machine(
    plant: &StateSpace,
    controller: &StateSpace,
    data: &IoData,
    opts: &MachineValidationOptions,
) -> Result<MachineValidation> {
    let Simulated {
        ch,
        k0,
        n_axes,
        ts,
        n,
        closed_loop,
        closed_loop_poles,
        reconstruction,
    } = simulate_against(plant, controller, data, opts)?;
    // the excitations the residuals are tested against: every nonzero r (w without any)
    let nonzero = |x: &&[f64]| x.iter().any(|v| *v != 0.0);
    let mut drivers: Vec<(String, &[f64])> = ch
        .axes
        .iter()
        .zip(&ch.r)
        .filter_map(|(a, x)| x.filter(nonzero).map(|x| (channel_name("r", a), x)))
        .collect();
    if drivers.is_empty() {
        drivers = ch
            .axes
            .iter()
            .zip(&ch.w)
            .filter_map(|(a, x)| x.filter(nonzero).map(|x| (channel_name("w", a), x)))
            .collect();
    }
    let (grid_hz, s_lines) = sensitivity_grid(plant, controller, opts, ts)?;
    let sigma_max: Vec<f64> = s_lines
        .iter()
        .map(sigma_max_of)
        .collect::<Result<Vec<_>>>()?;
    let (sigma_max_f_hz, sigma_max_peak) = refine_peak(&grid_hz, &sigma_max, |f| {
        sigma_max_of(&sensitivity_at(plant, controller, f)?)
    })?;
    let s_diag: Vec<Vec<c64>> = (0..n_axes)
        .map(|k| s_lines.iter().map(|s| s[(k, k)]).collect())
        .collect();
    let sim = &reconstruction.simulated;
    let mut axes = Vec::with_capacity(n_axes);
    let mut amplifiers = Vec::with_capacity(n_axes);
    for (k, s_kk) in s_diag.iter().enumerate() {
        let (y, u) = (ch.y[k], ch.u[k]);
        let eps: Vec<f64> = y[k0..]
            .iter()
            .zip(&sim.y[k][k0..])
            .map(|(a, b)| a - b)
            .collect();
        let rmse_y = (eps.iter().map(|e| e * e).sum::<f64>() / eps.len() as f64).sqrt();
        let residuals = if eps.iter().all(|e| *e == 0.0) {
            None
        } else {
            Some(output_residuals(&eps, &drivers, k0, opts.lags)?)
        };
        let (fit_i, amplifier_fit, amp) = match (ch.i[k], opts.current) {
            (Some(i), CurrentModel::Arx { na, nb, nk }) => {
                let (fi, fa, m) = current_fit(i, u, &sim.u[k], na, nb, nk, k0, ts, &ch.axes[k])?;
                (Some(fi), Some(fa), Some(m))
            }
            _ => (None, None, None),
        };
        amplifiers.push(amp);
        let mags: Vec<f64> = s_kk.iter().map(|v| v.norm()).collect();
        let (fp, _) = refine_peak(&grid_hz, &mags, |f| {
            Ok(sensitivity_at(plant, controller, f)?[(k, k)].norm())
        })?;
        let s_peak = sensitivity_at(plant, controller, fp)?[(k, k)];
        let iso = sensitivity_zone(
            &Frd::new(vec![fp], vec![s_peak], None, Some(ts))?,
            &opts.zones,
        )?;
        axes.push(AxisValidation {
            axis: ch.axes[k].clone(),
            fit_y: fit_percent(&y[k0..], &sim.y[k][k0..])?,
            fit_u: fit_percent(&u[k0..], &sim.u[k][k0..])?,
            fit_i,
            amplifier_fit,
            rmse_y,
            windows: reconstruction.windows[k].clone(),
            residuals,
            iso,
        });
    }
    Ok(MachineValidation {
        axes,
        sigma_max_peak,
        sigma_max_f_hz,
        grid_hz,
        sigma_max,
        s_diag,
        reconstruction,
        closed_loop,
        closed_loop_poles,
        amplifiers,
        samples: n - k0,
    })
}

/// The model in the state basis $x = D x'$ with $D = \operatorname{diag}(1/\lVert O e_j\rVert)$,
/// $O = [C; CA; \dots; CA^{h-1}]$, $h = 2n + 20$ (each state's output energy over the first
/// samples normalised to one; states the outputs do not see, or a non-finite norm, keep scale
/// 1): the same input-output model, with the initial-state least squares well conditioned.
/// Returns the model and the diagonal of $D$.
fn observability_scaled(m: &StateSpace) -> Result<(StateSpace, Vec<f64>)> {
    let n = m.order();
    let (a, c) = (m.a(), m.c());
    let mut norms = vec![0.0f64; n];
    let mut ca = c.to_owned();
    for _ in 0..2 * n + 20 {
        for (j, v) in norms.iter_mut().enumerate() {
            *v += (0..ca.nrows())
                .map(|i| ca[(i, j)] * ca[(i, j)])
                .sum::<f64>();
        }
        ca = &ca * a;
    }
    let d: Vec<f64> = norms
        .iter()
        .map(|v| {
            let s = v.sqrt();
            if s.is_finite() && s > 0.0 {
                1.0 / s
            } else {
                1.0
            }
        })
        .collect();
    let (nu, ny) = (m.ninputs(), m.noutputs());
    let scaled = StateSpace::new(
        Mat::from_fn(n, n, |i, j| a[(i, j)] * d[j] / d[i]),
        Mat::from_fn(n, nu, |i, j| m.b()[(i, j)] / d[i]),
        Mat::from_fn(ny, n, |i, j| c[(i, j)] * d[j]),
        m.d().to_owned(),
        m.ts(),
    )?;
    Ok((scaled, d))
}

/// The residual tests of one output error against every driving channel (module docs).
fn output_residuals(
    eps: &[f64],
    drivers: &[(String, &[f64])],
    k0: usize,
    lags: usize,
) -> Result<OutputResiduals> {
    let m = drivers.len().max(1);
    let level = 1.0 - 0.05 / m as f64;
    let mut tests = Vec::with_capacity(drivers.len());
    for (_, x) in drivers {
        tests.push(analyze_output_error(eps, &x[k0..], lags)?);
    }
    let thresholds: Vec<f64> = tests
        .iter()
        .map(|t| {
            t.independence
                .as_ref()
                .map_or(f64::NAN, |c| chi2_quantile(c.dof, level))
        })
        .collect();
    let pass = tests
        .iter()
        .zip(&thresholds)
        .all(|(t, th)| t.independence.as_ref().is_some_and(|c| c.statistic < *th));
    Ok(OutputResiduals {
        inputs: drivers.iter().map(|(n, _)| n.clone()).collect(),
        tests,
        level,
        thresholds,
        pass,
    })
}

/// The coil-current fit of one axis: an ARX amplifier model on the recorded $u \to i$, driven
/// by the simulated $\hat u$ from the recorded first samples. Returns (fit of $i$ after `k0`,
/// the amplifier's one-step fit, the model).
#[allow(clippy::too_many_arguments)]
fn current_fit(
    i: &[f64],
    u: &[f64],
    u_sim: &[f64],
    na: usize,
    nb: usize,
    nk: usize,
    k0: usize,
    ts: f64,
    axis: &str,
) -> Result<(f64, f64, ArxModel)> {
    let fitted = arx(i, &[u], &ArxOrders::siso(na, nb, nk), ts)?;
    let model = fitted.model;
    let poles = crate::linalg::roots(&model.a)?;
    if poles.iter().any(|p| p.norm() >= 1.0) {
        return Err(Error::Unstable {
            context: "validate_machine: amplifier model",
            reason: format!(
                "the ARX model of the recorded current {} from {} is unstable; the current channel does not follow the controller output (check the channel), or set the current model to `off`",
                channel_name("i", axis),
                channel_name("u", axis)
            ),
        });
    }
    // from the recorded first samples, where the model's regressor is complete
    let start = model.k0().min(i.len());
    let pred = model.simulate(&[u_sim], &i[..start])?;
    let one_step = model.predict(i, &[u])?;
    let s = start.max(k0).min(i.len());
    let from = k0.min(i.len());
    Ok((
        fit_percent(&i[from..], &pred[from..])?,
        fit_percent(&i[s..], &one_step[s..])?,
        model,
    ))
}

/// The log grid of the options (1 Hz to Nyquist by default) and $S = (I + C\hat P)^{-1}$ on it.
fn sensitivity_grid(
    plant: &StateSpace,
    controller: &StateSpace,
    opts: &MachineValidationOptions,
    ts: f64,
) -> Result<(Vec<f64>, Vec<Mat<c64>>)> {
    let f1 = opts.f_max_hz.unwrap_or(0.5 / ts);
    let f0 = opts.f_min_hz;
    if !(f0 > 0.0 && f1 > f0 && f1 <= 0.5 / ts * (1.0 + 1e-12) && opts.grid_points >= 2) {
        return Err(Error::invalid(
            "grid",
            format!(
                "the sensitivity grid needs 0 < f_min_hz < f_max_hz ≤ fs/2 = {} Hz and at least 2 points, got {f0} … {f1} Hz, {} points",
                0.5 / ts,
                opts.grid_points
            ),
        ));
    }
    let n = opts.grid_points;
    let grid: Vec<f64> = (0..n)
        .map(|k| f0 * (f1 / f0).powf(k as f64 / (n - 1) as f64))
        .collect();
    let s = sensitivity_lines(plant, controller, &grid)?;
    Ok((grid, s))
}

fn sensitivity_lines(
    plant: &StateSpace,
    controller: &StateSpace,
    f_hz: &[f64],
) -> Result<Vec<Mat<c64>>> {
    let (p, c) = (plant.freq_response(f_hz)?, controller.freq_response(f_hz)?);
    p.iter()
        .zip(&c)
        .zip(f_hz)
        .map(|((p, c), f)| {
            let m = p.ncols();
            let a = Mat::<c64>::identity(m, m) + c * p;
            use faer::linalg::solvers::DenseSolveCore;
            let inv = a.partial_piv_lu().inverse();
            if inv
                .col_iter()
                .all(|col| col.iter().all(|v| v.re.is_finite() && v.im.is_finite()))
            {
                Ok(inv)
            } else {
                Err(Error::numerical(
                    "validate_machine: sensitivity",
                    format!(
                        "I + C P is singular at {f} Hz (a closed-loop pole on the unit circle)"
                    ),
                ))
            }
        })
        .collect()
}

fn sensitivity_at(plant: &StateSpace, controller: &StateSpace, f: f64) -> Result<Mat<c64>> {
    sensitivity_lines(plant, controller, &[f])?
        .pop()
        .ok_or_else(|| Error::numerical("validate_machine", "no sensitivity line"))
}

/// Largest singular value of a complex matrix.
fn sigma_max_of(s: &Mat<c64>) -> Result<f64> {
    let sv = s
        .singular_values()
        .map_err(|e| Error::numerical("validate_machine: σ̄(S)", format!("{e:?}")))?;
    Ok(sv.iter().fold(0.0f64, |a, v| a.max(*v)))
}

/// The largest of `values` on `grid`, refined between its grid neighbours by golden-section
/// search on `eval` (kept only when larger): `(f, value)`.
fn refine_peak(
    grid: &[f64],
    values: &[f64],
    eval: impl Fn(f64) -> Result<f64>,
) -> Result<(f64, f64)> {
    let n = grid.len();
    let (mut kmax, mut vmax) = (0, f64::NEG_INFINITY);
    for (k, &v) in values.iter().enumerate() {
        if v > vmax {
            (kmax, vmax) = (k, v);
        }
    }
    let (mut lo, mut hi) = (grid[kmax.saturating_sub(1)], grid[(kmax + 1).min(n - 1)]);
    let gr = (5f64.sqrt() - 1.0) / 2.0;
    let mut x1 = hi - gr * (hi - lo);
    let mut x2 = lo + gr * (hi - lo);
    let (mut m1, mut m2) = (eval(x1)?, eval(x2)?);
    for _ in 0..60 {
        if m1 > m2 {
            hi = x2;
            x2 = x1;
            m2 = m1;
            x1 = hi - gr * (hi - lo);
            m1 = eval(x1)?;
        } else {
            lo = x1;
            x1 = x2;
            m1 = m2;
            x2 = lo + gr * (hi - lo);
            m2 = eval(x2)?;
        }
        if hi - lo < 1e-9 * hi {
            break;
        }
    }
    let fb = 0.5 * (lo + hi);
    let vb = eval(fb)?;
    Ok(if vb > vmax {
        (fb, vb)
    } else {
        (grid[kmax], vmax)
    })
}

/// Quantile $z_p$ of the standard normal distribution (Acklam's rational approximation,
/// relative error below $1.2 \cdot 10^{-9}$), for $0 < p < 1$.
pub(crate) fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    let plow = 0.02425;
    if p < plow {
        tail((-2.0 * p.ln()).sqrt())
    } else if p <= 1.0 - plow {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    }
}

/// Quantile of $\chi^2(k)$ at level `p` by the Wilson–Hilferty approximation
/// $k\,(1 - \tfrac{2}{9k} + z_p\sqrt{2/(9k)})^3$ (as [`crate::validate::residuals::chi2_95`],
/// which is the case $p = 0.95$).
fn chi2_quantile(k: usize, p: f64) -> f64 {
    let k = k as f64;
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + normal_quantile(p) * a.sqrt()).powi(3)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The normal quantiles against tabulated values (scipy.stats.norm.ppf), and the χ²
    /// quantile at 95 % equal to the residual module's.
    #[test]
    fn quantiles_match_tables() {
        for (p, z) in [
            (0.5, 0.0),
            (0.95, 1.644_853_626_951_472_2),
            (0.975, 1.959_963_984_540_054),
            (0.9875, 2.241_402_727_604_947),
            (0.991_666_666_666_666_7, 2.393_979_799_818_510_4),
            (0.01, -2.326_347_874_040_841),
        ] {
            assert!((normal_quantile(p) - z).abs() < 5e-9, "z({p})");
        }
        for k in [1, 4, 51, 200] {
            let a = chi2_quantile(k, 0.95);
            let b = crate::validate::residuals::chi2_95(k);
            assert!((a - b).abs() < 1e-7 * b, "χ²({k})");
        }
    }
}
