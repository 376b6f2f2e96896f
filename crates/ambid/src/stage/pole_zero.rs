//! The pole-zero stage: poles, zeros, unstable poles and near pole-zero cancellations of every
//! candidate of the chosen structure, and the chosen model's poles in continuous time.

use super::candidates::Candidate;
use super::TwinSource;
use crate::error::{Error, FailureClass, Result};
use ambid_core::c64;
use ambid_core::validate::pz::{PzAnalysis, PzOptions};
use std::f64::consts::TAU;

/// What the pole-zero stage reads: the models stage's candidates, the chosen one and, on the
/// twin, the exact truth.
#[derive(Clone, Copy)]
pub struct PoleZeroInput<'a> {
    /// The candidates of the models stage.
    pub candidates: &'a [Candidate],
    /// Index of the chosen one.
    pub chosen: usize,
    /// The twin (its exact plant's unstable poles), when the records come from it.
    pub twin: Option<&'a TwinSource>,
}

/// One candidate's poles and zeros.
#[derive(Debug, Clone)]
pub struct PzRow {
    /// The candidate's label, e.g. `OE 8`.
    pub label: String,
    /// Its poles $z$.
    pub poles: Vec<c64>,
    /// Its zeros $z$.
    pub zeros: Vec<c64>,
    /// Its unstable poles ($|z| > 1$ as `ambid_core::validate::pz` flags them).
    pub unstable: Vec<c64>,
    /// Near pole-zero cancellations (a pole and a zero closer than the tolerance).
    pub cancellations: usize,
    /// Distance of the closest such pair (`None`: no pair).
    pub closest: Option<f64>,
}

/// A pole of the chosen model in continuous time, $s = f_s \ln z$ (in Hz: $s / 2\pi$).
#[derive(Debug, Clone)]
pub struct PoleHz {
    /// The pole $z$.
    pub z: c64,
    /// $s / 2\pi = f_s \ln z / 2\pi$ \[Hz\].
    pub s_hz: c64,
    /// Natural frequency $|s| / 2\pi$ \[Hz\].
    pub natural_hz: f64,
    /// Damping ratio $-\operatorname{Re} s / |s|$ (0 for $s = 0$).
    pub damping: f64,
    /// Whether the pole is real ($|\operatorname{Im} z| < 10^{-12}$).
    pub real: bool,
    /// Time constant \[ms\] of an unstable pole ($1 / \operatorname{Re} s$) or a stable real one
    /// ($-1 / \operatorname{Re} s$); `None` for a stable complex pair.
    pub time_constant_ms: Option<f64>,
}

/// The chosen model's s-plane view: poles and zeros in Hz and the zoomed ranges.
#[derive(Debug, Clone)]
pub struct SPlane {
    /// Poles $s / 2\pi$ \[Hz\].
    pub poles_hz: Vec<c64>,
    /// Zeros with $|z| < 10$, as $s / 2\pi$ \[Hz\].
    pub zeros_hz: Vec<c64>,
    /// Axis ranges `(x, y)` zoomed onto the slow poles and the origin (`None`: no slow pole).
    pub range: Option<((f64, f64), (f64, f64))>,
    /// The poles with $\operatorname{Im} z \ge 0$ (one per complex pair), slowest first.
    pub table: Vec<PoleHz>,
}

/// The chosen model at a glance.
#[derive(Debug, Clone)]
pub struct ChosenPz {
    /// Its label.
    pub label: String,
    /// Its poles.
    pub poles: Vec<c64>,
    /// Its zeros.
    pub zeros: Vec<c64>,
    /// Radius of the z-plane view zoomed onto the poles near $z = 1$.
    pub zoom_radius: f64,
    /// Poles with a natural frequency above $f_s / 15$ (outside the zoomed views).
    pub outside: usize,
    /// The s-plane view (`None` without a positive sample time).
    pub s_plane: Option<SPlane>,
    /// Its near cancellations.
    pub near_cancellations: usize,
    /// Its unstable poles.
    pub unstable_poles: usize,
}

/// The pole-zero stage's result.
#[derive(Debug, Clone)]
pub struct PoleZeroStage {
    /// The chosen structure (`arx`, `oe`, `ss`).
    pub structure: &'static str,
    /// Every candidate of that structure that has a model, in table order.
    pub rows: Vec<PzRow>,
    /// The chosen model (`None`: it has no model).
    pub chosen: Option<ChosenPz>,
    /// On the twin: the exact plant's unstable poles (empty off the twin or when they could not
    /// be computed).
    pub truth_unstable_poles: Vec<c64>,
    /// The distance under which a pole and a zero count as a near cancellation.
    pub cancellation_tol: f64,
}

/// Poles and zeros of every candidate of the chosen one's structure
/// (`ambid_core::validate::pz`), and the chosen model's poles near $z = 1$ and in continuous
/// time, $s = f_s \ln z$, with natural frequency $|s|/2\pi$ and damping $-\operatorname{Re}
/// s/|s|$.
///
/// # Example
/// ```
/// use ambid::stage::{pole_zero, Candidate, PoleZeroInput};
/// let one = |v: f64| faer::Mat::from_fn(1, 1, |_, _| v);
/// // one unstable real pole at z = 1.01, 1 ms sample time
/// let m = ambid_core::lti::StateSpace::discrete(one(1.01), one(1.0), one(1.0), one(0.0), 1e-3).unwrap();
/// let c = Candidate { model: Some(m), ..Candidate::time_fit("ss", 1, None, 3, None) };
/// let pz = pole_zero(&PoleZeroInput { candidates: &[c], chosen: 0, twin: None }).unwrap();
/// let chosen = pz.chosen.unwrap();
/// assert_eq!(chosen.unstable_poles, 1);
/// let p = &chosen.s_plane.unwrap().table[0];
/// // s = f_s ln z = 1000 ln 1.01 1/s: time constant 1/s = 100.50 ms
/// assert!((p.time_constant_ms.unwrap() - 1e3 / (1e3 * 1.01f64.ln())).abs() < 1e-9);
/// ```
///
/// # Errors
/// A computation error when a candidate's poles or zeros cannot be computed.
pub fn pole_zero(input: &PoleZeroInput<'_>) -> Result<PoleZeroStage> {
    let ch = input.chosen;
    let structure = input
        .candidates
        .get(ch)
        .map(|c| c.structure)
        .ok_or_else(|| {
            Error::classified(
                FailureClass::Computation,
                Error::other(format!(
                    "pole-zero: the chosen candidate {ch} is not among the {} candidates",
                    input.candidates.len()
                )),
            )
        })?;
    let truth_unstable_poles: Vec<c64> = match input.twin {
        Some(t) => t.twin.plant_unstable_poles().unwrap_or_default(),
        None => Vec::new(),
    };
    let opts = PzOptions::default();
    let mut rows = Vec::new();
    let mut chosen_pz = None;
    for (i, c) in input.candidates.iter().enumerate() {
        if c.structure != structure {
            continue;
        }
        let Some(m) = &c.model else { continue };
        let pz = PzAnalysis::from_state_space(m, &opts)
            .map_err(|e| Error::classified(FailureClass::Computation, e))?;
        let poles: Vec<c64> = pz.poles.iter().map(|r| r.z).collect();
        let zeros: Vec<c64> = pz.zeros.iter().map(|r| r.z).collect();
        let unstable: Vec<c64> = pz
            .poles
            .iter()
            .filter(|r| r.unstable)
            .map(|r| r.z)
            .collect();
        let min_d = pz
            .cancellations
            .iter()
            .map(|x| x.distance)
            .fold(f64::INFINITY, f64::min);
        if i == ch {
            chosen_pz = Some(chosen_view(
                c.label(),
                &poles,
                &zeros,
                m.ts(),
                (pz.cancellations.len(), unstable.len()),
            ));
        }
        rows.push(PzRow {
            label: c.label(),
            poles,
            zeros,
            unstable,
            cancellations: pz.cancellations.len(),
            closest: min_d.is_finite().then_some(min_d),
        });
    }
    Ok(PoleZeroStage {
        structure,
        rows,
        chosen: chosen_pz,
        truth_unstable_poles,
        cancellation_tol: opts.cancellation_tol,
    })
}

/// The chosen model's map zoomed onto the poles near z = 1 (at a high sample rate every mode
/// sits there), its s-plane in Hz and its poles in Hz and damping.
fn chosen_view(
    label: String,
    poles: &[c64],
    zeros: &[c64],
    ts: Option<f64>,
    (near_cancellations, unstable_poles): (usize, usize),
) -> ChosenPz {
    // the poles that matter for the loop: natural frequency below f_s/15 (rigid-body and
    // bending modes; actuator, sensor and delay poles lie beyond)
    let fs_model = ts.filter(|t| *t > 0.0).map_or(1.0, |t| 1.0 / t);
    let slow = |z: &c64| z.norm() > 1e-9 && (z.ln() * fs_model).norm() / TAU < fs_model / 15.0;
    let near: Vec<f64> = poles
        .iter()
        .filter(|z| slow(z))
        .map(|z| (c64::new(1.0, 0.0) - z).norm())
        .collect();
    let excess = poles.iter().map(|z| z.norm() - 1.0).fold(0.0_f64, f64::max);
    let zoom_radius = (1.5 * near.iter().copied().fold(0.0, f64::max))
        .max(2.5 * excess)
        .clamp(1e-4, 0.6);
    let outside = poles.len() - near.len();
    let s_plane = ts.filter(|t| *t > 0.0).map(|ts| {
        let fs = 1.0 / ts;
        let to_hz = |z: &c64| -> Option<c64> { (z.norm() > 1e-9).then(|| z.ln() * fs / TAU) };
        let poles_hz: Vec<c64> = poles.iter().filter_map(to_hz).collect();
        let zeros_hz: Vec<c64> = zeros
            .iter()
            .filter(|z| z.norm() < 10.0)
            .filter_map(to_hz)
            .collect();
        // zoomed onto the slow poles (with the origin)
        let slow_s: Vec<c64> = poles.iter().filter(|z| slow(z)).filter_map(to_hz).collect();
        let range = (!slow_s.is_empty()).then(|| {
            let xr = slow_s
                .iter()
                .map(|v| v.re.abs())
                .fold(0.0, f64::max)
                .max(1.0);
            let yr = slow_s
                .iter()
                .map(|v| v.im.abs())
                .fold(0.0, f64::max)
                .max(xr);
            ((-1.2 * xr, 1.2 * xr), (-1.2 * yr, 1.2 * yr))
        });
        let mut sorted: Vec<(&c64, c64)> = poles
            .iter()
            .filter(|z| z.im >= 0.0)
            .filter_map(|z| to_hz(z).map(|s| (z, s)))
            .collect();
        sorted.sort_by(|a, b| a.1.norm().total_cmp(&b.1.norm()));
        let table = sorted
            .into_iter()
            .map(|(z, s)| {
                let fnat = s.norm();
                let real = z.im.abs() < 1e-12;
                PoleHz {
                    z: *z,
                    s_hz: s,
                    natural_hz: fnat,
                    damping: if fnat > 0.0 { -s.re / fnat } else { 0.0 },
                    real,
                    time_constant_ms: if z.norm() > 1.0 {
                        Some(1e3 / (s.re * TAU))
                    } else if real {
                        Some(-1e3 / (s.re * TAU))
                    } else {
                        None
                    },
                }
            })
            .collect();
        SPlane {
            poles_hz,
            zeros_hz,
            range,
            table,
        }
    });
    ChosenPz {
        label,
        poles: poles.to_vec(),
        zeros: zeros.to_vec(),
        zoom_radius,
        outside,
        s_plane,
        near_cancellations,
        unstable_poles,
    }
}
