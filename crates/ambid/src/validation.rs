//! Validation of an identified plant model on an independent closed-loop record, the way the
//! seed paper does it: the model is closed with the real controller and driven by the recorded
//! excitation (and position reference); the simulated displacement and controller output are
//! compared with the measured ones (fit %, error, windows), the output error is tested for
//! independence from the excitation, and the model's closed loop gives the stability margins and
//! the ISO 14839-3 sensitivity zone.
//!
//! # Residual test
//! The output error $\varepsilon = y - \hat y$ of the loop simulated with the model is, for the
//! true plant, the sensor noise seen through the loop, $\varepsilon = S v$ (plus the other
//! bearing's noise through its path): **coloured**, so it is not tested for whiteness (the plant
//! model has no noise model), and **correlated with $u$** (which contains $-C v$), so it is not
//! tested against $u$. What holds for the true plant, and fails for a wrong one, is that
//! $\varepsilon$ is **independent of the excitation $r$** (of the reference $w$ when there is no
//! excitation): [`analyze_output_error`], the generalised portmanteau test with the covariance of
//! coloured signals, rejecting 5 % of true plants (calibration in `tests/residuals_rigs.rs`).
//!
//! This is the library behind `ambid validate` and the workflow's validation steps: one
//! implementation of every number both report.
//!
//! The plant model is never simulated in open loop (it is unstable); a model that does not give a
//! stable closed loop with the controller is an error that names the unstable closed-loop poles.

use crate::error::{Error, Result};
use ambid_core::c64;
use ambid_core::frf::band::{iso_search, BandRule, IsoSearch};
use ambid_core::lti::{Frd, StateSpace};
use ambid_core::validate::closed_loop::{reconstruct_with, Reconstruction};
use ambid_core::validate::fit::fit_percent;
use ambid_core::validate::iso::{sensitivity_zone, IsoVerdict, IsoZones};
use ambid_core::validate::margins::{margins, Margins};
use ambid_core::validate::predict::InitialState;
use ambid_core::validate::pz::{PzAnalysis, PzOptions};
use ambid_core::validate::residuals::{analyze, analyze_output_error, ResidualTest};
use serde::Serialize;

/// Settings of [`validate_closed_loop`].
#[derive(Debug, Clone)]
pub struct ValidationSettings {
    /// Leading samples excluded from the fits and residual tests (the loop's start-up).
    pub skip: usize,
    /// Largest lag of the residual correlation tests.
    pub lags: usize,
    /// Number of time windows of the windowed fits.
    pub windows: usize,
    /// ISO 14839-3 zone limits.
    pub zones: IsoZones,
    /// Points of the logarithmic frequency grid (0.5 Hz to 0.98 × Nyquist) for the margins and
    /// the model's sensitivity.
    pub grid_points: usize,
    /// How the simulated loop (and an innovation model's predictor) starts: from the initial
    /// state that best explains the record (default, MATLAB `compare`'s; the loop was running
    /// before the first sample) or from rest.
    pub initial_state: InitialState,
}

impl Default for ValidationSettings {
    fn default() -> Self {
        Self {
            skip: 0,
            lags: 25,
            windows: 20,
            zones: IsoZones::default(),
            grid_points: 4000,
            initial_state: InitialState::Estimate,
        }
    }
}

/// A measured closed-loop record (same length for every signal).
#[derive(Debug, Clone, Copy)]
pub struct MeasuredLoop<'a> {
    /// Position reference \[m\] (zeros when there is none).
    pub w: &'a [f64],
    /// Excitation added to the controller output \[A\], if any.
    pub r: Option<&'a [f64]>,
    /// Measured displacement \[m\].
    pub y: &'a [f64],
    /// Measured controller output \[A\].
    pub u: &'a [f64],
    /// Sample time \[s\].
    pub ts: f64,
}

/// Everything [`validate_closed_loop`] computes.
#[derive(Debug, Clone)]
pub struct ValidationOutcome {
    /// The closed-loop simulation and its windowed fits (whole record).
    pub reconstruction: Reconstruction,
    /// Fit % of the displacement after `skip`.
    pub fit_y: f64,
    /// Fit % of the controller output after `skip`.
    pub fit_u: f64,
    /// RMS output error after `skip` \[m\].
    pub rmse_y: f64,
    /// Largest absolute output error after `skip` \[m\].
    pub max_error_y: f64,
    /// Residual test of the output error: independence from the excitation $r$ (or the reference
    /// $w$ without one); no whiteness test (module docs).
    pub residuals: ResidualTest,
    /// The signal the residuals were tested against: `"r"` or `"w"`.
    pub residual_input: &'static str,
    /// Poles of the model's closed loop with the controller.
    pub closed_loop: PzAnalysis,
    /// Stability margins of the model's loop gain.
    pub margins: Margins,
    /// Frequency grid of `s_model` \[Hz\].
    pub grid_hz: Vec<f64>,
    /// The model's sensitivity $S = 1/(1 + P C)$ on `grid_hz`.
    pub s_model: Vec<c64>,
    /// ISO 14839-3 verdict of the model's sensitivity.
    pub iso_model: IsoVerdict,
    /// Samples in the fits and tests.
    pub samples: usize,
    /// Leading samples excluded.
    pub skip: usize,
}

impl ValidationOutcome {
    /// Output error $y - \hat y$ over the whole record.
    pub fn error_y(&self, y: &[f64]) -> Vec<f64> {
        y.iter()
            .zip(&self.reconstruction.simulated.y)
            .map(|(a, b)| a - b)
            .collect()
    }
}

/// Validates `model` with `controller` on the record `rec` (module docs).
///
/// # Errors
/// A sample time that differs from the record's, a record with neither excitation nor reference,
/// too few samples after `skip` for the residual tests, an unstable closed loop (with its poles),
/// and the errors of the underlying computations.
pub fn validate_closed_loop(
    model: &StateSpace,
    controller: &StateSpace,
    rec: &MeasuredLoop<'_>,
    s: &ValidationSettings,
) -> Result<ValidationOutcome> {
    let ts = rec.ts;
    let mts = model.ts().unwrap_or(0.0);
    if (mts - ts).abs() > 1e-9 * ts {
        return Err(Error::other(format!(
            "the model's sample time {mts} s differs from the data's {ts} s: identify the model at the data's rate (or resample the data)"
        )));
    }
    let (y, u, w) = (rec.y, rec.u, rec.w);
    let r = rec.r.filter(|r| r.iter().any(|v| *v != 0.0));
    if r.is_none() && w.iter().all(|v| *v == 0.0) {
        return Err(Error::other("the record has neither an excitation nor a position reference: nothing drives the loop"));
    }
    if s.skip + 4 * s.lags.max(5) >= y.len() {
        return Err(Error::other(format!(
            "skipping {} samples leaves too few ({}) for the residual tests with {} lags",
            s.skip,
            y.len().saturating_sub(s.skip),
            s.lags
        )));
    }
    let k0 = s.skip;
    let cl = model.feedback(controller)?;
    let closed_loop = PzAnalysis::from_state_space(&cl, &PzOptions::default())?;
    let unstable: Vec<String> = closed_loop
        .poles
        .iter()
        .filter(|p| p.z.norm() >= 1.0)
        .map(|p| format!("{:.6}{:+.6}j (|z| = {:.6})", p.z.re, p.z.im, p.z.norm()))
        .collect();
    if !unstable.is_empty() {
        return Err(Error::other(format!(
            "the model does not give a stable closed loop with this controller; unstable closed-loop poles: {}. The model is wrong near crossover or the controller does not match the data",
            unstable.join(", ")
        )));
    }
    let reconstruction = reconstruct_with(
        model,
        controller,
        w,
        r,
        y,
        u,
        s.windows,
        ts,
        s.initial_state,
    )?;
    let sim = &reconstruction.simulated;
    let eps: Vec<f64> = y[k0..]
        .iter()
        .zip(&sim.y[k0..])
        .map(|(a, b)| a - b)
        .collect();
    let input = r.map_or(&w[k0..], |r| &r[k0..]);
    let residual_input = if r.is_some() { "r" } else { "w" };
    let residuals = analyze_output_error(&eps, input, s.lags)?;
    let rmse_y = (eps.iter().map(|e| e * e).sum::<f64>() / eps.len() as f64).sqrt();
    let max_error_y = eps.iter().map(|e| e.abs()).fold(0.0, f64::max);
    let fit_y = fit_percent(&y[k0..], &sim.y[k0..])?;
    let fit_u = fit_percent(&u[k0..], &sim.u[k0..])?;
    let fny = 0.5 / ts;
    let n = s.grid_points.max(2);
    let grid_hz: Vec<f64> = (0..n)
        .map(|k| 0.5 * (0.98 * fny / 0.5f64).powf(k as f64 / (n - 1) as f64))
        .collect();
    let gp = model.freq_response_siso(&grid_hz)?;
    let gc = controller.freq_response_siso(&grid_hz)?;
    let l: Vec<c64> = gp.iter().zip(&gc).map(|(p, c)| p * c).collect();
    let margins = margins(&grid_hz, &l)?;
    let s_model: Vec<c64> = l.iter().map(|v| (c64::new(1.0, 0.0) + v).inv()).collect();
    let s_frd = Frd::new(grid_hz.clone(), s_model.clone(), None, Some(ts))?;
    let iso_model = sensitivity_zone(&s_frd, &s.zones)?;
    Ok(ValidationOutcome {
        reconstruction,
        fit_y,
        fit_u,
        rmse_y,
        max_error_y,
        residuals,
        residual_input,
        closed_loop,
        margins,
        grid_hz,
        s_model,
        iso_model,
        samples: y.len() - k0,
        skip: k0,
    })
}

/// The one-line verdict of the closed-loop residual test of [`validate_closed_loop`] (`input`:
/// its `residual_input`): what was tested, against what, the statistic, and why whiteness is not
/// tested. Used by `ambid validate` and the workflow report.
pub fn residual_summary(res: &ResidualTest, input: &str) -> String {
    let name = if input == "r" {
        "excitation r"
    } else {
        "reference w"
    };
    let ind = res.independence.as_ref().map_or_else(
        || "not computed".to_string(),
        |c| {
            format!(
                "{} (Q {:.1} vs 95 % threshold {:.1}, χ²({}), lags ±{}; {} of {} lags outside the per-lag bound, expected ≈ 5 %)",
                if c.pass { "pass" } else { "FAIL" },
                c.statistic,
                c.threshold,
                c.dof,
                c.lags.len() / 2,
                c.exceeding.len(),
                c.lags.len()
            )
        },
    );
    format!(
        "residuals: output error y − ŷ independent of the {name}: {ind}; whiteness not tested (the loop's output error is S·v, coloured even for the true plant)"
    )
}

/// Residual tests of an **innovation-form** model (Kalman gain `k_gain`, $n$ entries): its own
/// 1-step predictor $\hat y(t|t-1)$ from the measured $y$ and $u$ (valid in closed loop, the
/// direct method) leaves, for the true model, the white innovations $e$, independent of the
/// excitation. So both tests apply: whiteness (Ljung–Box) and independence from `r` (or `w`
/// without an excitation), after `s.skip` samples (the predictor's start-up from zero state
/// should be inside it). Returns the test and the signal name (`"r"`/`"w"`).
///
/// # Errors
/// A gain of the wrong length, a record with neither excitation nor reference, and the errors of
/// the predictor and the tests.
pub fn innovation_residuals(
    model: &StateSpace,
    k_gain: &[f64],
    rec: &MeasuredLoop<'_>,
    s: &ValidationSettings,
) -> Result<(ResidualTest, &'static str)> {
    if k_gain.len() != model.order() {
        return Err(Error::other(format!(
            "the model's Kalman gain has {} entries for {} states",
            k_gain.len(),
            model.order()
        )));
    }
    let r = rec.r.filter(|r| r.iter().any(|v| *v != 0.0));
    let (x, name) = match r {
        Some(r) => (r, "r"),
        None if rec.w.iter().any(|v| *v != 0.0) => (rec.w, "w"),
        None => {
            return Err(Error::other(
                "the record has neither an excitation nor a position reference",
            ))
        }
    };
    let km = faer::Mat::from_fn(k_gain.len(), 1, |i, _| k_gain[i]);
    let (yhat, _) = ambid_core::validate::predict::predict_k_with(
        model,
        km.as_ref(),
        rec.y,
        rec.u,
        1,
        s.initial_state,
    )?;
    let k0 = s.skip.min(rec.y.len());
    let eps: Vec<f64> = rec.y[k0..]
        .iter()
        .zip(&yhat[k0..])
        .map(|(a, b)| a - b)
        .collect();
    Ok((analyze(&eps, Some(&x[k0..]), s.lags)?, name))
}

/// The one-line verdict of [`innovation_residuals`].
pub fn innovation_summary(res: &ResidualTest, input: &str) -> String {
    let v = |c: Option<&ambid_core::validate::residuals::CorrelationTest>| {
        c.map_or_else(
            || "not computed".to_string(),
            |c| {
                format!(
                    "{} (Q {:.1} vs 95 % threshold {:.1}, χ²({}))",
                    if c.pass { "pass" } else { "FAIL" },
                    c.statistic,
                    c.threshold,
                    c.dof
                )
            },
        )
    };
    format!(
        "innovations (1-step prediction errors of the model's Kalman predictor): white {}; independent of {input} {}",
        v(res.whiteness.as_ref()),
        v(res.independence.as_ref())
    )
}

/// The median over lines of $|\hat G_k - G_k| / |G_k|$ (NaN for no lines).
pub fn median_relative_error(estimate: &[c64], reference: &[c64]) -> f64 {
    let mut r: Vec<f64> = estimate
        .iter()
        .zip(reference)
        .map(|(a, b)| (a - b).norm() / b.norm())
        .collect();
    r.sort_by(f64::total_cmp);
    r.get(r.len() / 2).copied().unwrap_or(f64::NAN)
}

/// How well a model's closed loop matches measured closed-loop FRFs.
#[derive(Debug, Clone, Serialize)]
pub struct Consistency {
    /// Median relative error of the model's $S$ against the measured $S = T_{ru}$.
    pub s_median_relative_error: f64,
    /// Median relative error of the model's $T_{ry}$ against the measured one.
    pub t_ry_median_relative_error: f64,
    /// Lines compared.
    pub lines: usize,
    /// ISO 14839-3 verdict of the measured sensitivity, over its lines known to ±10 %
    /// ([`ambid_core::frf::band::iso_search`]).
    pub iso_measured: IsoVerdict,
    /// How the measured peak was searched (band, lines, whether the reliability filter applied).
    pub iso_search: IsoSearch,
}

/// Compares the model's closed loop with measured $S$ and $T_{ry}$ (same frequency lines) and
/// gives the ISO 14839-3 zone of the measured sensitivity (peak over the lines known to ±10 %).
///
/// # Errors
/// Measured FRFs on different lines, or the errors of the frequency responses.
pub fn consistency(
    model: &StateSpace,
    controller: &StateSpace,
    s_meas: &Frd,
    t_meas: &Frd,
    zones: &IsoZones,
) -> Result<Consistency> {
    let f = s_meas.f_hz();
    if t_meas.f_hz() != f {
        return Err(Error::other(
            "the measured S and T_ry must be on the same frequency lines",
        ));
    }
    let (gp, gc) = (
        model.freq_response_siso(f)?,
        controller.freq_response_siso(f)?,
    );
    let med = median_relative_error;
    // the measured FRF's lines are its band (ambid frf writes the excited band); within it the
    // peak is searched on the lines known to ±10 %
    let band = (
        f.first().copied().unwrap_or(0.0),
        f.last().copied().unwrap_or(0.0),
    );
    let search = iso_search(s_meas, band, &BandRule::default(), zones)?;
    let s_pred: Vec<c64> = gp
        .iter()
        .zip(&gc)
        .map(|(p, c)| (c64::new(1.0, 0.0) + p * c).inv())
        .collect();
    let t_pred: Vec<c64> = gp.iter().zip(&s_pred).map(|(p, s)| p * s).collect();
    Ok(Consistency {
        s_median_relative_error: med(&s_pred, s_meas.values()),
        t_ry_median_relative_error: med(&t_pred, t_meas.values()),
        lines: f.len(),
        iso_measured: search.verdict.clone(),
        iso_search: search,
    })
}

/// Smallest number of residual-test lags [`residual_lags`] chooses (enough degrees of freedom
/// for the portmanteau test to see a model error at all).
pub const RESIDUAL_LAGS_MIN: usize = 10;
/// Largest number of residual-test lags [`residual_lags`] chooses: the test's cost grows as
/// $(2M+1)^3$ (the pseudo-inverse of its lag covariance), about 0.5 s per 20 000-sample record at
/// 150 lags in the test profile.
pub const RESIDUAL_LAGS_MAX: usize = 150;
/// The lags are this multiple of the impulse response's peak time.
pub const RESIDUAL_LAGS_PEAK_FACTOR: usize = 2;
/// The fallback when the rule has nothing to follow (an unstable model without a controller).
pub const RESIDUAL_LAGS_FALLBACK: usize = 25;

/// What the residual tests' number of lags was derived from (see [`residual_lags`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LagBasis {
    /// The model's closed-loop impulse response $r \to y$, $T_{ry} = P/(1 + PC)$, with the controller.
    ClosedLoop,
    /// The model's own impulse response (no controller; a stable model).
    Model,
    /// Nothing to follow (an unstable model without a controller): [`RESIDUAL_LAGS_FALLBACK`].
    Fallback,
    /// Given by the user.
    Given,
}

/// The residual tests' number of lags and where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LagChoice {
    /// Largest lag $M$ of the tests (the cross-correlation spans $-M \dots M$).
    pub lags: usize,
    /// The sample at which the followed impulse response peaks, if one was followed.
    pub peak_sample: Option<usize>,
    /// What it was derived from.
    pub basis: LagBasis,
}

impl LagChoice {
    /// One sentence for captions: the lags in samples and ms and the rule.
    pub fn describe(&self, ts: f64) -> String {
        let ms = self.lags as f64 * ts * 1e3;
        let rule = match (self.basis, self.peak_sample) {
            (LagBasis::ClosedLoop, Some(k)) => format!(
                "{RESIDUAL_LAGS_PEAK_FACTOR}× the peak time of the chosen model's closed-loop impulse response r → y (T_ry = P/(1 + PC) with the controller), which peaks after {k} samples ({:.3} ms), clamped to {RESIDUAL_LAGS_MIN}–{RESIDUAL_LAGS_MAX} lags",
                k as f64 * ts * 1e3
            ),
            (LagBasis::Model, Some(k)) => format!(
                "{RESIDUAL_LAGS_PEAK_FACTOR}× the peak time of the chosen model's impulse response, which peaks after {k} samples ({:.3} ms), clamped to {RESIDUAL_LAGS_MIN}–{RESIDUAL_LAGS_MAX} lags",
                k as f64 * ts * 1e3
            ),
            (LagBasis::Given, _) => "set in the configuration ([validation] lags)".to_string(),
            _ => format!(
                "the fallback {RESIDUAL_LAGS_FALLBACK}: the model is unstable and no controller closes its loop, so it has no impulse response to follow"
            ),
        };
        format!("lags ±{} ({ms:.3} ms): {rule}", self.lags)
    }
}

/// The number of lags $M$ of the residual tests, from the dynamics of the chosen `model`.
///
/// A model error shows in the cross-correlation of the output error with the excitation at the
/// lags where the loop's response $r \to y$, $T_{ry} = P/(1 + PC)$, carries it: its first swing
/// and the swing back, which take about twice the time to its peak. **Rule:**
/// $M = 2\,k_{\mathrm{peak}}$, where $k_{\mathrm{peak}} = \arg\max_k |h(k)|$ for the model's
/// impulse response $h$ (of $T_{ry}$ with `controller`; of the model itself without one), clamped to
/// [`RESIDUAL_LAGS_MIN`]–[`RESIDUAL_LAGS_MAX`] and to at most a tenth of the `n` tested samples.
/// (Following $h$ down to 5 % of its peak would need 365–940 lags on random rigs 0–19, whose
/// integral action leaves a slow tail; the test's cost grows as $M^3$.) An unstable model without
/// a controller has no impulse response to follow: [`RESIDUAL_LAGS_FALLBACK`]; an unstable loop
/// gets the fallback too (its validation fails with the unstable poles anyway).
///
/// # Example
/// ```
/// use ambid::validation::{residual_lags, LagBasis};
/// use ambid_core::lti::StateSpace;
/// use faer::mat;
/// // y = q⁻²/(1 − 0.93 q⁻¹)² u: h(k) = (k − 1) 0.93^(k−2), largest at k = 15
/// let p = StateSpace::discrete(
///     mat![[1.86, -0.8649], [1.0, 0.0]], mat![[1.0], [0.0]], mat![[0.0, 1.0]], mat![[0.0]], 1e-3,
/// ).unwrap();
/// let l = residual_lags(&p, None, 100_000);
/// assert_eq!((l.peak_sample, l.lags, l.basis), (Some(15), 30, LagBasis::Model));
/// ```
pub fn residual_lags(model: &StateSpace, controller: Option<&StateSpace>, n: usize) -> LagChoice {
    let horizon = 20 * RESIDUAL_LAGS_MAX;
    let mut imp = vec![0.0; horizon];
    imp[0] = 1.0;
    let (h, basis) = match controller {
        Some(c) => (
            ambid_core::validate::closed_loop::simulate_loop(model, c, &imp)
                .ok()
                .filter(|_| {
                    model
                        .feedback(c)
                        .and_then(|cl| cl.is_stable())
                        .unwrap_or(false)
                })
                .map(|r| r.y),
            LagBasis::ClosedLoop,
        ),
        None => (
            model
                .is_stable()
                .unwrap_or(false)
                .then(|| model.simulate_siso(&imp, None).ok())
                .flatten(),
            LagBasis::Model,
        ),
    };
    let cap = RESIDUAL_LAGS_MAX
        .min(n / 10)
        .max(RESIDUAL_LAGS_MIN.min(n / 10).max(1));
    let fallback = LagChoice {
        lags: RESIDUAL_LAGS_FALLBACK.min(cap),
        peak_sample: None,
        basis: LagBasis::Fallback,
    };
    let Some(h) = h.filter(|h| h.iter().all(|v| v.is_finite())) else {
        return fallback;
    };
    let peak = h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if peak <= 0.0 {
        return fallback;
    }
    let k_peak = h.iter().position(|v| v.abs() >= peak).unwrap_or(0);
    LagChoice {
        lags: (RESIDUAL_LAGS_PEAK_FACTOR * k_peak)
            .clamp(RESIDUAL_LAGS_MIN, RESIDUAL_LAGS_MAX)
            .min(cap),
        peak_sample: Some(k_peak),
        basis,
    }
}

/// The instantaneous frequency \[Hz\] of a sweep reference `w` at every sample, from its zero
/// crossings (of $w - \bar w$, located by linear interpolation): half a period between two
/// crossings, $f = 1/(2\,\Delta t)$ at their midpoint, linear in between and held before the first
/// and after the last midpoint. `None` with fewer than 4 crossings (not a sweep) or when the
/// frequency is not rising through the record (each midpoint's at least 0.9 of the largest before
/// it): only a rising sweep maps time onto frequency one to one.
///
/// # Example
/// ```
/// // a linear chirp 10 → 100 Hz over 1 s at 10 kHz: f(t) = 10 + 90 t
/// let ts = 1e-4;
/// let w: Vec<f64> = (0..10_000)
///     .map(|k| {
///         let t = k as f64 * ts;
///         (2.0 * std::f64::consts::PI * (10.0 * t + 45.0 * t * t)).sin()
///     })
///     .collect();
/// let f = ambid::validation::chirp_frequency(&w, ts).unwrap();
/// assert!((f[5000] - 55.0).abs() < 0.5);
/// ```
pub fn chirp_frequency(w: &[f64], ts: f64) -> Option<Vec<f64>> {
    let n = w.len();
    if n < 4 || ts <= 0.0 {
        return None;
    }
    let mean = w.iter().sum::<f64>() / n as f64;
    let mut cross = Vec::new();
    for k in 1..n {
        let (a, b) = (w[k - 1] - mean, w[k] - mean);
        if (a < 0.0 && b >= 0.0) || (a > 0.0 && b <= 0.0) {
            cross.push((k - 1) as f64 + a / (a - b));
        }
    }
    if cross.len() < 4 {
        return None;
    }
    let mids: Vec<(f64, f64)> = cross
        .windows(2)
        .filter(|c| c[1] > c[0])
        .map(|c| (0.5 * (c[0] + c[1]), 0.5 / ((c[1] - c[0]) * ts)))
        .collect();
    let mut top = 0.0f64;
    for (_, f) in &mids {
        if *f < 0.9 * top {
            return None;
        }
        top = top.max(*f);
    }
    let mut out = Vec::with_capacity(n);
    let mut j = 0;
    for k in 0..n {
        let x = k as f64;
        while j + 1 < mids.len() && mids[j + 1].0 <= x {
            j += 1;
        }
        let f = if x <= mids[0].0 {
            mids[0].1
        } else if j + 1 >= mids.len() {
            mids[mids.len() - 1].1
        } else {
            let ((x0, f0), (x1, f1)) = (mids[j], mids[j + 1]);
            f0 + (f1 - f0) * (x - x0) / (x1 - x0)
        };
        out.push(f);
    }
    Some(out)
}

/// Below this multiple of the error floor a window's signal is too small to be judged (see
/// [`worst_window`]).
pub const WORST_WINDOW_SIGNAL_FACTOR: f64 = 3.0;

/// The worst window of a reconstruction, by [`worst_window`]'s rule.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WorstWindow {
    /// Index into the reconstruction's windows.
    pub index: usize,
    /// $100\,(1 - e_{\mathrm{rms},k} / \sigma_y)$: the window's error against the whole record's
    /// signal RMS $\sigma_y$ \[%\].
    pub record_fit_pct: f64,
    /// The window's measured signal RMS (about its mean).
    pub signal_rms: f64,
    /// The error floor: the smallest window error RMS (the sensor noise through the loop).
    pub error_floor: f64,
    /// Windows judged (signal RMS at least [`WORST_WINDOW_SIGNAL_FACTOR`] × the floor).
    pub judged: usize,
}

/// The window where the model is worst, judged so that a quiet window where the error is only
/// sensor noise is not reported. **Rule:** each window's error RMS $e_k$ is compared with the
/// whole record's measured signal RMS $\sigma_y$ (not the window's own, which makes a quiet
/// window's noise look like a bad fit); the error floor $e_{\min} = \min_k e_k$ estimates the
/// noise every window carries, and windows whose measured signal RMS is below
/// [`WORST_WINDOW_SIGNAL_FACTOR`] $\cdot e_{\min}$ are not judged (all are when none is above it).
/// The worst is the judged window with the largest $e_k$. `y` is the measured signal, `windows`
/// the reconstruction's windows (times in s), `ts` the sample time.
pub fn worst_window(
    windows: &[ambid_core::validate::closed_loop::WindowFit],
    y: &[f64],
    ts: f64,
) -> Option<WorstWindow> {
    let rms = |x: &[f64]| {
        if x.is_empty() {
            return 0.0;
        }
        let m = x.iter().sum::<f64>() / x.len() as f64;
        (x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len() as f64).sqrt()
    };
    let sigma = rms(y);
    let n = y.len();
    let sig: Vec<f64> = windows
        .iter()
        .map(|w| {
            let i0 = ((w.t_s.0 / ts).round().max(0.0) as usize).min(n);
            let i1 = ((w.t_s.1 / ts).round().max(0.0) as usize).clamp(i0, n);
            rms(&y[i0..i1])
        })
        .collect();
    let floor = windows
        .iter()
        .map(|w| w.rms_error_y)
        .filter(|e| e.is_finite())
        .fold(f64::INFINITY, f64::min);
    if !floor.is_finite() || sigma.is_nan() || sigma <= 0.0 {
        return None;
    }
    let eligible: Vec<usize> = (0..windows.len())
        .filter(|&k| sig[k] >= WORST_WINDOW_SIGNAL_FACTOR * floor)
        .collect();
    let judged: Vec<usize> = if eligible.is_empty() {
        (0..windows.len()).collect()
    } else {
        eligible
    };
    let index = *judged.iter().max_by(|a, b| {
        windows[**a]
            .rms_error_y
            .total_cmp(&windows[**b].rms_error_y)
    })?;
    Some(WorstWindow {
        index,
        record_fit_pct: 100.0 * (1.0 - windows[index].rms_error_y / sigma),
        signal_rms: sig[index],
        error_floor: floor,
        judged: judged.len(),
    })
}
