//! Model comparison over structures and orders (the seed paper's table 1): every candidate is
//! fitted to the same FRF and scored in the frequency domain and, given an independent record
//! and the controller, in the time domain through the closed loop.
//!
//! # Scores
//! For each structure ($\mathrm{ARX}$ by Levy's form, $\mathrm{OE}$ by SK + LM, state space by
//! frequency-domain subspace + LM; see [`crate::estimate::freqfit`]) and order $n$:
//! * the unweighted complex errors on the band ([`FreqErrors`]: RMSE, relative RMSE, dB RMSE,
//!   median relative error) and the relative RMSE below `low_band_hz` (the seed compares the
//!   structures below 200 Hz);
//! * $\mathrm{BIC} = 2L \ln(V / 2L) + n_\theta \ln 2L$ with $V$ the weighted cost over the $L$
//!   lines ($2L$ real residuals); lower is better, the penalty grows with the parameter count;
//! * the closed-loop validation fit $100\,(1 - \lVert y - \hat y\rVert / \lVert y - \bar y\rVert)$
//!   of the model with the real controller driven by the record's $r$
//!   ([`super::closed_loop::simulate_loop`]); an unstable loop scores `None` with the reason;
//! * the number of unstable poles (an AMB plant has one per unstable rigid-body direction).
//!
//! Orders: ARX and OE of order $n$ have $n_b = n$, $n_f = n$ and the given delay $n_k$; the state
//! space has $n$ states (and no feedthrough).
//!
//! # Unstable poles: how many the data support, and validity
//! The FRF was measured in a stable closed loop $u = C(w - y) + r$. By the argument principle
//! (discrete Nyquist criterion) the counter-clockwise winding number $W$ of $1 + L(e^{j\omega})$,
//! $L = PC$, around the origin for $\omega$ from $-\pi$ to $\pi$ equals the number of poles of
//! $L$ outside the unit circle minus the number of unstable closed-loop poles (zero). Poles of
//! $C$ on the unit circle (the PID's integrator at $z = 1$) are counted as stable by a small
//! indentation outside the circle. So
//! $$ n_u(P) = W - n_u(C), \qquad W = \frac{\theta(\pi) - \theta(0)}{\pi}, \quad
//! \theta = \arg\bigl(1 + \hat P C\bigr) \text{ tracked continuously}, $$
//! ([`unstable_poles_from_loop`]) with $\hat P$ the measured plant FRF on the band's lines and
//! $C$ the controller's exact model. Lines where the data do not determine the phase of
//! $1 + \hat P C$ (its standard deviation $|C|\sigma_P$ above half its modulus) are skipped, and the
//! first run of three such lines ends the data used: without excitation (above a PRBS's band,
//! at its nulls) a closed-loop estimate drifts to $-1/C$, so $1 + \hat P C$ to 0 with a random
//! phase, and the top of the data is where the count then needs $|L| < 1$. Outside the
//! band the rule needs two assumptions, which
//! it checks where it can: **above** the band $|L| < 1$ (the loop has rolled off; checked on
//! the top line, else the count is refused), so $1 + L$ stays in the right half-plane and
//! $\theta(\pi)$ is the multiple of $2\pi$ nearest $\theta(f_{\max})$; **below** the band $P$
//! is taken constant at its lowest line while $C$ is exact (for an AMB the plant is flat and
//! real below its unstable pole, and the loop gain is large, so the phase of $1 + L$ follows
//! $C$); each pole of $C$ at $z = 1$ adds $\pi/2$ for the indentation, and $\theta(0)$ must come
//! out within $\pi/4$ of a multiple of $\pi$ (else the count is refused). The count is
//! therefore only as good as the band: the band must reach below the plant's unstable
//! frequencies and up to where the loop gain is below 1 (10–1000 Hz on the AMB rigs).
//!
//! With that count (or one given by the user), [`CompareSpec::unstable_poles`] constrains every
//! fit ([`FreqFitOptions::max_unstable_poles`]: a constrained refinement, never a reflection of
//! the result) and a row is **valid** ([`CompareRow::valid`]) when the fit succeeded, has exactly
//! that many unstable poles, with a controller closes a stable loop, and has no pole–zero pair
//! that cancels within the data ([`cancelling_pairs`]: removing the pair does not raise the
//! fit's BIC, so the order exceeds what the data support); a row that is not valid stays in the
//! table with the reason in its note. [`choose`] picks among the valid rows
//! the best validation fit when there is one, else the smallest BIC. A fit whose model has
//! poles within [`PINNED`](crate::estimate::freqfit_ss::PINNED) of the unit circle under that
//! limit gets a note naming them (the limit holds them there: the fit stopped on the
//! constraint, and the model has an undamped mode); that is not a validity rule.

use crate::c64;
use crate::error::{Error, Result};
use crate::estimate::freqfit::{
    arx_frd, oe_frd, FreqErrors, FreqFitOptions, FreqWeights, TfOrders,
};
use crate::lti::{Frd, StateSpace, Structure, TransferFunction};
use crate::validate::closed_loop::simulate_loop;
use crate::validate::fit::fit_percent;

/// What to compare.
#[derive(Debug, Clone, PartialEq)]
pub struct CompareSpec {
    /// Structures (default ARX, OE, SS).
    pub structures: Vec<Structure>,
    /// Orders (default 6, 7, 8, 9).
    pub orders: Vec<usize>,
    /// Input delay of the ARX and OE models in samples (default 1).
    pub nk: usize,
    /// Band, weights and iteration limits of the fits.
    pub fit: FreqFitOptions,
    /// Upper edge of the low band scored separately \[Hz\] (default 200).
    pub low_band_hz: f64,
    /// The number of unstable plant poles the data support (e.g. from
    /// [`unstable_poles_from_loop`]): every fit is constrained to at most this many and a row
    /// with another number is not valid. `None` (default): unconstrained, not checked.
    pub unstable_poles: Option<usize>,
    /// The controller of the loop the FRF was measured in: a row whose model does not close a
    /// stable loop with it is not valid. `None` (default): not checked.
    pub controller: Option<StateSpace>,
}

impl Default for CompareSpec {
    fn default() -> Self {
        Self {
            structures: vec![Structure::Arx, Structure::Oe, Structure::Ss],
            orders: vec![6, 7, 8, 9],
            nk: 1,
            fit: FreqFitOptions::default(),
            low_band_hz: 200.0,
            unstable_poles: None,
            controller: None,
        }
    }
}

/// An independent time-domain record for the closed-loop validation.
#[derive(Debug, Clone, Copy)]
pub struct ValidationRecord<'a> {
    /// Excitation injected at the controller output.
    pub r: &'a [f64],
    /// Measured plant output.
    pub y: &'a [f64],
    /// The controller in the loop (same sample time as the models).
    pub controller: &'a StateSpace,
    /// Samples at the start left out of the fit measure (the initial transient).
    pub skip: usize,
}

/// One row of the comparison table.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CompareRow {
    /// Structure.
    pub structure: Structure,
    /// Order.
    pub order: usize,
    /// Real parameters.
    pub n_params: usize,
    /// Errors on the band (`None` when the fit failed).
    pub rmse: Option<f64>,
    /// Relative RMSE on the band.
    pub relative_rmse: Option<f64>,
    /// RMS dB error on the band.
    pub db_rmse: Option<f64>,
    /// Median relative error on the band.
    pub median_relative: Option<f64>,
    /// Relative RMSE below `low_band_hz`.
    pub low_band_relative_rmse: Option<f64>,
    /// BIC of the weighted frequency-domain cost.
    pub bic: Option<f64>,
    /// Closed-loop validation fit \[%\].
    pub validation_fit: Option<f64>,
    /// Unstable poles of the model.
    pub unstable_poles: Option<usize>,
    /// Whether the refinement converged (`None` when the fit failed).
    pub converged: Option<bool>,
    /// Whether the model closes a stable loop with [`CompareSpec::controller`] (`None` without
    /// a controller or a model).
    pub closed_loop_stable: Option<bool>,
    /// A model that may be chosen: [admissible](Self::admissible) and without a pole–zero pair
    /// that cancels within the data (module docs).
    pub valid: bool,
    /// Fitted, with the supported number of unstable poles and a stable closed loop; the pairs
    /// aside (not serialised). The order scan counts an admissible row's error: a pair that
    /// cancels leaves the error of the order the data support.
    #[serde(skip)]
    pub admissible: bool,
    /// Why a fit or the validation failed, or why the row is not valid.
    pub note: Option<String>,
    /// The fitted model as a state-space realisation (not serialised).
    #[serde(skip)]
    pub model: Option<StateSpace>,
}

/// Fits every structure × order of `spec` to `frd` and scores it (module docs). A candidate that
/// fails (rank-deficient fit, unstable closed loop) gets a row with the reason in `note`; the
/// comparison itself fails only on invalid input (a bad band or weights, a structure an FRF fit
/// does not support).
///
/// # Errors
/// The errors of [`crate::estimate::freqfit::FreqData::new`] for the band and weights;
/// [`Error::InvalidArgument`] naming a structure that is not [`Structure::fits_frf`] (e.g. `bj`).
pub fn compare_models(
    frd: &Frd,
    spec: &CompareSpec,
    validation: Option<ValidationRecord<'_>>,
) -> Result<Vec<CompareRow>> {
    frd.require_siso("compare::compare_models")?;
    // validate the band and the weights once, so that bad input is an error, not a note per row
    let data = crate::estimate::freqfit::FreqData::new(frd, &spec.fit)?;
    if let Some(&s) = spec.structures.iter().find(|s| !s.fits_frf()) {
        return Err(unsupported_frf_structure(s));
    }
    let mut rows = Vec::new();
    for &structure in &spec.structures {
        for &order in &spec.orders {
            rows.push(candidate(frd, &data, spec, structure, order, validation));
        }
    }
    Ok(rows)
}

/// The typed error for a structure an FRF fit cannot fit ([`Structure::fits_frf`]).
fn unsupported_frf_structure(s: Structure) -> Error {
    Error::invalid(
        "structures",
        format!(
            "a fit to frequency-response data supports the structures arx, oe and ss, not `{s}` \
             (its noise model is not identifiable from an FRF); fit `{s}` to time-domain data instead"
        ),
    )
}

fn candidate(
    frd: &Frd,
    data: &crate::estimate::freqfit::FreqData,
    spec: &CompareSpec,
    structure: Structure,
    order: usize,
    validation: Option<ValidationRecord<'_>>,
) -> CompareRow {
    let mut row = CompareRow {
        structure,
        order,
        n_params: 0,
        rmse: None,
        relative_rmse: None,
        db_rmse: None,
        median_relative: None,
        low_band_relative_rmse: None,
        bic: None,
        validation_fit: None,
        unstable_poles: None,
        converged: None,
        closed_loop_stable: None,
        valid: false,
        admissible: false,
        note: None,
        model: None,
    };
    let mut notes: Vec<String> = Vec::new();
    let mut fit_opts = spec.fit.clone();
    if fit_opts.max_unstable_poles.is_none() {
        fit_opts.max_unstable_poles = spec.unstable_poles;
    }
    let fit_opts = &fit_opts;
    let fitted: Result<(StateSpace, usize, f64, FreqErrors, bool)> = (|| {
        let o = TfOrders {
            nb: order,
            nf: order,
            nk: spec.nk,
        };
        let tf = |t: TransferFunction| t.to_state_space();
        match structure {
            Structure::Arx => {
                // linear in its parameters, ARX cannot take the variance at the model: with
                // sample maximum-likelihood weights it keeps the variance at the data
                let f = match &fit_opts.weights {
                    FreqWeights::SampleMaximumLikelihood(_) => arx_frd(
                        frd,
                        &o,
                        &FreqFitOptions {
                            weights: FreqWeights::InverseVariance,
                            ..fit_opts.clone()
                        },
                    )?,
                    _ => arx_frd(frd, &o, fit_opts)?,
                };
                Ok((tf(f.model)?, f.n_params, f.cost, f.errors, f.converged))
            }
            Structure::Oe => {
                let f = oe_frd(frd, &o, fit_opts)?;
                Ok((tf(f.model)?, f.n_params, f.cost, f.errors, f.converged))
            }
            Structure::Ss => {
                let f = crate::estimate::freqfit_ss::ss_frd(
                    frd,
                    order,
                    fit_opts,
                    &crate::estimate::freqfit_ss::SsFreqOptions::default(),
                )?;
                Ok((f.model, f.n_params, f.cost, f.errors, f.converged))
            }
            other => Err(unsupported_frf_structure(other)),
        }
    })();
    let (model, n_params, cost, errors, converged) = match fitted {
        Ok(v) => v,
        Err(e) => {
            row.note = Some(format!("fit failed: {e}"));
            return row;
        }
    };
    row.n_params = n_params;
    row.converged = Some(converged);
    if !converged {
        notes.push(format!(
            "the refinement stopped at its iteration limit ({}) before converging: the model may not be at the optimum",
            spec.fit.max_iterations
        ));
    }
    // poles the unstable-pole limit holds on the unit circle: the fit stopped on the
    // constraint (`freqfit_ss`, "Second start"); a note, not a validity rule
    if let Some(lim) = spec.unstable_poles {
        if let Ok(on) = crate::estimate::freqfit_ss::poles_on_unit_circle(&model) {
            let at: Vec<String> = on
                .iter()
                .map(|z| {
                    format!(
                        "{:.1} Hz",
                        z.arg().abs() / (2.0 * std::f64::consts::PI * data.ts)
                    )
                })
                .collect();
            if !at.is_empty() {
                notes.push(format!(
                    "poles on the unit circle at {}: the limit of {lim} unstable pole(s) holds them there, so the fit stopped on that constraint and the model is undamped there",
                    at.join(", ")
                ));
            }
        }
    }
    row.rmse = Some(errors.rmse);
    row.relative_rmse = Some(errors.relative_rmse);
    row.db_rmse = Some(errors.db_rmse);
    row.median_relative = Some(errors.median_relative);
    let l2 = 2.0 * data.len() as f64;
    row.bic = Some(l2 * (cost.max(f64::MIN_POSITIVE) / l2).ln() + n_params as f64 * l2.ln());
    match model.freq_response_siso(&data.f_hz) {
        Ok(resp) => {
            let low: Vec<f64> = resp
                .iter()
                .zip(&data.g)
                .zip(&data.f_hz)
                .filter(|(_, f)| **f <= spec.low_band_hz)
                .map(|((m, g), _)| (m - g).norm_sqr() / g.norm_sqr().max(f64::MIN_POSITIVE))
                .collect();
            if !low.is_empty() {
                row.low_band_relative_rmse =
                    Some((low.iter().sum::<f64>() / low.len() as f64).sqrt());
            }
        }
        Err(e) => notes.push(format!("frequency response failed: {e}")),
    }
    row.unstable_poles = model
        .poles()
        .ok()
        .map(|p| p.iter().filter(|z| z.norm() > 1.0).count());
    let controller = spec
        .controller
        .as_ref()
        .or(validation.map(|v| v.controller));
    if let Some(c) = controller {
        row.closed_loop_stable = Some(closed_loop_stable(&model, c));
    }
    if let Some(v) = validation {
        match simulate_loop(&model, v.controller, v.r) {
            Ok(out) => {
                let n = v.y.len().min(out.y.len());
                let k0 = v.skip.min(n);
                row.validation_fit = fit_percent(&v.y[k0..n], &out.y[k0..n]).ok();
            }
            Err(e) => notes.push(format!("closed-loop validation failed: {e}")),
        }
    }
    let mut valid = row.unstable_poles.is_some();
    if let (Some(want), Some(got)) = (spec.unstable_poles, row.unstable_poles) {
        if got != want {
            valid = false;
            notes.push(format!(
                "not valid: {got} unstable poles, the data support {want}"
            ));
        }
    }
    if row.closed_loop_stable == Some(false) {
        valid = false;
        notes.push("not valid: the loop with the controller is unstable".into());
    }
    row.admissible = valid;
    match cancelling_pairs(&model, data) {
        Ok(pairs) => {
            if !pairs.is_empty() {
                valid = false;
                let each: Vec<String> = pairs
                    .iter()
                    .map(|p| {
                        format!(
                            "{:.1} Hz (ζ {:.3}; Λ {:.2} ≤ BIC price {:.2})",
                            p.f_hz, p.damping, p.statistic, p.critical
                        )
                    })
                    .collect();
                notes.push(format!(
                    "not valid: pole–zero pairs cancel within the data at {}: the data do not support order {order}",
                    each.join(", ")
                ));
            }
        }
        Err(e) => notes.push(format!("the pole–zero cancellation test failed: {e}")),
    }
    row.valid = valid;
    if !notes.is_empty() {
        row.note = Some(notes.join("; "));
    }
    row.model = Some(model);
    row
}

/// A pole of a fitted model with its nearest zero, and what the data say of the pair
/// ([`pole_zero_pairs`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoleZeroPair {
    /// The pole (upper half-plane or real).
    pub pole: c64,
    /// Its nearest zero of the same kind (complex or real).
    pub zero: c64,
    /// The pole's natural frequency \[Hz\].
    pub f_hz: f64,
    /// The pole's damping ratio (negative: unstable).
    pub damping: f64,
    /// The likelihood-ratio statistic $\Lambda = 2L \ln(V_r / V)$ of removing the pair.
    pub statistic: f64,
    /// The BIC's price of the pair's parameters, $d \ln 2L$ with $d$ = 4 (a complex pair) or 2
    /// (a real one): the pair is supported only when $\Lambda$ exceeds it.
    pub critical: f64,
}

impl PoleZeroPair {
    /// Whether the pair cancels within the data: $\Lambda \le d \ln 2L$ (removing it does not
    /// raise the BIC).
    pub fn cancels(&self) -> bool {
        self.statistic <= self.critical
    }
}

/// The pole–zero pairs of `model` that cancel within the data: for each pole $p$ (of a complex
/// pair, the one in the upper half-plane) its nearest zero $q$ of the same kind, and the
/// model's response on `data`'s lines without the pair, $\hat G_k / D_k$ with
/// $$ D_k = \frac{(z_k - q)(z_k - \bar q)}{(z_k - p)(z_k - \bar p)} \quad\text{(a real pair:}
///    \ \tfrac{z_k - q}{z_k - p}\text{)}, $$
/// against the data by the weighted cost $V = \sum_k w_k |\hat G_k - G_k|^2$ of the fit. With
/// the noise scale estimated from the residuals, removing the pair changes the fit's BIC
/// ($2L \ln(V/2L) + n_\theta \ln 2L$, module docs) by $\Lambda - d \ln 2L$, where
/// $\Lambda = 2L \ln(V_r / V)$ is the likelihood-ratio statistic over the $L$ lines and $d$ the
/// pair's real parameters (4 for a complex pole and zero pair, 2 for a real one). The pair is
/// returned when $\Lambda \le d \ln 2L$: the model without it is as good by the BIC, so the
/// data do not support it. Without refitting, $V_r$ bounds the reduced order's best cost from
/// above, so a returned pair is unsupported whatever a refit would give.
///
/// The BIC's price rather than a $\chi^2_d$ quantile: the fit chose the pair's frequency where
/// it helps most, so under "no pair" $\Lambda$ is the largest of many $\chi^2_d$-like gains
/// over the band, not one. On the twin's Welch FRFs near-cancelling pairs that only fitted
/// noise had $\Lambda$ = 11–17, above $\chi^2_4$'s 9.49 and below $4 \ln 2L \approx 26$.
///
/// Such a pair is what an order above the data's leaves: on the twin's rigs an OE 9 fit to a
/// Welch FRF put an undamped pair of poles and zeros at 1325 Hz, between two lines; it changed
/// no line, and its 360° phase swing put the loop's gain margin at 3.0 where the plant's is
/// 7.0. No pair is returned when the model fits the lines exactly ($V = 0$: no noise scale).
///
/// # Errors
/// [`Error::InvalidArgument`] for a model that is not SISO or not discrete at the data's sample
/// time; the errors of the model's poles and zeros.
///
/// # Example
/// ```
/// use ambid_core::estimate::freqfit::{FreqData, FreqFitOptions, FreqWeights};
/// use ambid_core::lti::{Frd, TransferFunction};
/// use ambid_core::validate::compare::cancelling_pairs;
/// # fn main() -> ambid_core::Result<()> {
/// let ts = 1e-3;
/// let tf = |b: Vec<f64>, a: Vec<f64>| TransferFunction::new(b, a, ts)?.to_state_space();
/// let conv = |a: &[f64], b: &[f64]| {
///     let mut c = vec![0.0; a.len() + b.len() - 1];
///     for (i, x) in a.iter().enumerate() {
///         for (j, y) in b.iter().enumerate() {
///             c[i + j] += x * y;
///         }
///     }
///     c
/// };
/// // a second-order polynomial with roots r·e^{±j2πf·ts}
/// let pair = |r: f64, f: f64| {
///     let w = 2.0 * std::f64::consts::PI * f * ts;
///     vec![1.0, -2.0 * r * w.cos(), r * r]
/// };
/// // the plant: a real pole, a resonance at 50 Hz and an anti-resonance at 70 Hz; measured on
/// // 200 lines 2 Hz apart with 1 % noise
/// let (num, den) = (conv(&[0.1], &pair(0.97, 70.0)), conv(&[1.0, -0.9], &pair(0.99, 50.0)));
/// let plant = tf(num.clone(), den.clone())?;
/// let f: Vec<f64> = (1..=200).map(|k| 2.0 * k as f64).collect();
/// let g = plant.freq_response_siso(&f)?;
/// let noisy: Vec<_> = g.iter().enumerate()
///     .map(|(k, v)| v * (1.0 + 0.01 * ((k * 7919 % 101) as f64 / 50.0 - 1.0)))
///     .collect();
/// let frd = Frd::new(f, noisy, None, Some(ts))?;
/// let opts = FreqFitOptions { weights: FreqWeights::Uniform, ..FreqFitOptions::default() };
/// let data = FreqData::new(&frd, &opts)?;
/// // the plant's own pairs are seen by the data
/// assert!(cancelling_pairs(&plant, &data)?.is_empty());
/// // the plant times an undamped pole pair at 101 Hz, between two lines, and a zero pair
/// // 0.1 % above it: that pair, and only it, cancels within the data
/// let over = tf(conv(&num, &pair(0.999_999, 101.1)), conv(&den, &pair(0.999_999, 101.0)))?;
/// let pairs = cancelling_pairs(&over, &data)?;
/// assert_eq!(pairs.len(), 1);
/// assert!((pairs[0].f_hz - 101.0).abs() < 0.5 && pairs[0].statistic <= pairs[0].critical);
/// # Ok(())
/// # }
/// ```
pub fn cancelling_pairs(
    model: &StateSpace,
    data: &crate::estimate::freqfit::FreqData,
) -> Result<Vec<PoleZeroPair>> {
    Ok(pole_zero_pairs(model, data)?
        .into_iter()
        .filter(PoleZeroPair::cancels)
        .collect())
}

/// Every pole of `model` (of a complex pair, the one in the upper half-plane) with its nearest
/// zero of the same kind and the statistic of removing the pair on `data` (the rule of
/// [`cancelling_pairs`], which keeps the pairs that [cancel](PoleZeroPair::cancels)); a pole
/// without a zero of its kind, or whose pair's removal puts a pole on a line, is left out.
/// Empty when the model fits the lines exactly.
///
/// # Errors
/// As [`cancelling_pairs`].
pub fn pole_zero_pairs(
    model: &StateSpace,
    data: &crate::estimate::freqfit::FreqData,
) -> Result<Vec<PoleZeroPair>> {
    if model.ninputs() != 1 || model.noutputs() != 1 {
        return Err(Error::invalid(
            "model",
            "the pole–zero cancellation test takes a SISO model",
        ));
    }
    match model.ts() {
        Some(t) if (t - data.ts).abs() <= 1e-9 * data.ts => {}
        _ => {
            return Err(Error::invalid(
                "model",
                format!(
                    "the model must be discrete at the data's sample time {} s",
                    data.ts
                ),
            ))
        }
    }
    let resp = model.freq_response_siso(&data.f_hz)?;
    let v = data.weighted_cost(resp.iter().copied());
    let l2 = 2.0 * data.len() as f64;
    if !(v > 0.0 && v.is_finite()) {
        return Ok(Vec::new());
    }
    let poles = model.poles()?;
    let zeros: Vec<c64> = model
        .zeros()?
        .into_iter()
        .filter(|q| q.re.is_finite() && q.im.is_finite())
        .collect();
    let tol = |x: c64| 1e-9 * x.norm().max(1.0);
    let is_real = |x: c64| x.im.abs() <= tol(x);
    let mut out = Vec::new();
    for &p in poles.iter().filter(|p| is_real(**p) || p.im > 0.0) {
        let real = is_real(p);
        let Some(&q) = zeros
            .iter()
            .filter(|q| if real { is_real(**q) } else { q.im > tol(**q) })
            .min_by(|a, b| (**a - p).norm().total_cmp(&(**b - p).norm()))
        else {
            continue;
        };
        let dipole = |z: c64| -> c64 {
            if real {
                (z - c64::new(q.re, 0.0)) / (z - c64::new(p.re, 0.0))
            } else {
                (z - q) * (z - q.conj()) / ((z - p) * (z - p.conj()))
            }
        };
        let vr = data.weighted_cost(resp.iter().zip(&data.z).map(|(g, z)| g / dipole(*z)));
        if !vr.is_finite() {
            continue;
        }
        let statistic = l2 * (vr / v).ln();
        let d = if real { 2.0 } else { 4.0 };
        // a pole at the origin has no continuous equivalent: 0 Hz, ζ 0
        let root = crate::validate::pz::Root::new(p, data.ts, 0.0);
        out.push(PoleZeroPair {
            pole: p,
            zero: q,
            f_hz: root.f_hz.unwrap_or(0.0),
            damping: root.damping.unwrap_or(0.0),
            statistic,
            critical: d * l2.ln(),
        });
    }
    Ok(out)
}

/// Whether the SISO `plant` closes a stable loop $u = C(w - y) + r$ with `controller` (every
/// closed-loop pole strictly inside the unit circle); `false` when the loop cannot be formed.
pub fn closed_loop_stable(plant: &StateSpace, controller: &StateSpace) -> bool {
    plant
        .feedback(controller)
        .and_then(|cl| cl.poles())
        .is_ok_and(|p| p.iter().all(|z| z.norm() < 1.0))
}

/// The row chosen by the comparison (module docs): among the [valid](CompareRow::valid) rows,
/// the best validation fit when any valid row has one, else the smallest BIC; `None` when no
/// row is valid.
pub fn choose(rows: &[CompareRow]) -> Option<usize> {
    let valid = || rows.iter().enumerate().filter(|(_, r)| r.valid);
    let by = |key: &dyn Fn(&CompareRow) -> Option<f64>| {
        valid()
            .filter_map(|(i, r)| key(r).filter(|v| v.is_finite()).map(|v| (i, v)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    };
    by(&|r| r.validation_fit.map(|f| -f)).or_else(|| by(&|r| r.bic))
}

/// The number of unstable poles of the plant supported by a measured plant FRF and the
/// controller of the (stable) loop it was measured in: the discrete Nyquist count of the
/// module docs, $n_u(P) = W - n_u(C)$, over the lines of `plant` in `band_hz` (all lines when
/// `None`).
///
/// # Errors
/// [`Error::InvalidArgument`] when the FRF has fewer than 2 lines in the band, no sample time,
/// or another sample time than the controller, or a non-SISO controller;
/// [`Error::Numerical`] when the count cannot be made: the loop gain is 1 or more on the top
/// line (the band must reach where the loop has rolled off), the phase at DC is not near a
/// multiple of $\pi$, or the winding number is not an integer (too coarse a grid, or a loop
/// that is not stable); the message says what to do.
///
/// # Example
/// ```
/// use ambid_core::lti::{Frd, StateSpace};
/// use ambid_core::validate::compare::unstable_poles_from_loop;
/// use faer::mat;
/// // P = 0.1/(z - 1.05) (one unstable pole), C = 2: closed-loop pole 1.05 - 0.2 = 0.85
/// let ts = 1e-3;
/// let p = StateSpace::discrete(mat![[1.05]], mat![[1.0]], mat![[0.1]], mat![[0.0]], ts).unwrap();
/// let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[2.0]], ts).unwrap();
/// let f: Vec<f64> = (1..400).map(|k| k as f64).collect();
/// let frd = Frd::from_model(&p, &f).unwrap();
/// assert_eq!(unstable_poles_from_loop(&frd, &c, None).unwrap(), 1);
/// ```
pub fn unstable_poles_from_loop(
    plant: &Frd,
    controller: &StateSpace,
    band_hz: Option<(f64, f64)>,
) -> Result<usize> {
    plant.require_siso("compare::unstable_poles_from_loop")?;
    use std::f64::consts::PI;
    const CTX: &str = "unstable_poles_from_loop";
    let ts = plant
        .ts()
        .ok_or_else(|| Error::invalid("plant", "the FRF has no sample time (continuous data)"))?;
    match controller.ts() {
        Some(tc) if (tc / ts - 1.0).abs() <= 1e-9 => {}
        _ => {
            return Err(Error::invalid(
                "controller",
                "the controller must be discrete with the FRF's sample time",
            ))
        }
    }
    if controller.ninputs() != 1 || controller.noutputs() != 1 {
        return Err(Error::invalid("controller", "the controller must be SISO"));
    }
    let (lo, hi) = band_hz.unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
    let one = crate::c64::new(1.0, 0.0);
    let mut lines: Vec<(f64, crate::c64, f64)> = plant
        .f_hz()
        .iter()
        .zip(plant.values())
        .enumerate()
        .filter(|(_, (f, g))| **f > 0.0 && **f >= lo && **f <= hi && g.norm().is_finite())
        .map(|(k, (f, g))| (*f, *g, plant.variance().map_or(0.0, |v| v[k])))
        .collect();
    lines.sort_by(|a, b| a.0.total_cmp(&b.0));
    // the lines where the data determine the phase of 1 + PC: its standard deviation |C| σ_P at
    // most half its modulus (this drops lines without excitation, where a closed-loop estimate
    // tends to P̂ = −1/C and 1 + P̂C to 0 with a random phase)
    let f_all: Vec<f64> = lines.iter().map(|l| l.0).collect();
    let c_all = controller.freq_response_siso(&f_all)?;
    // isolated undetermined lines are skipped; the first run of 3 ends the data used (the
    // excitation has run out: above it the estimate drifts to −1/C before the phase is lost)
    let mut kept: Vec<(f64, crate::c64, crate::c64)> = Vec::new();
    let mut run = 0;
    for (l, c) in lines.iter().zip(&c_all) {
        if l.2.sqrt() * c.norm() <= 0.5 * (one + l.1 * *c).norm() {
            run = 0;
            kept.push((l.0, l.1, l.1 * c));
        } else {
            run += 1;
            if run == 3 && !kept.is_empty() {
                break;
            }
        }
    }
    let f: Vec<f64> = kept.iter().map(|k| k.0).collect();
    let loop_in_band: Vec<crate::c64> = kept.iter().map(|k| k.2).collect();
    if f.len() < 2 {
        return Err(Error::invalid(
            "band_hz",
            "the unstable-pole count needs at least 2 lines of the plant FRF in the band whose phase the data determine",
        ));
    }
    // θ on the band, tracked upwards
    let unwrap = |prev: f64, z: crate::c64| {
        let a = z.arg();
        prev + (a - prev + PI).rem_euclid(2.0 * PI) - PI
    };
    let mut theta = (one + loop_in_band[0]).arg();
    let theta_lo = theta;
    for l in &loop_in_band[1..] {
        theta = unwrap(theta, one + l);
    }
    let top = loop_in_band[loop_in_band.len() - 1].norm();
    if top >= 1.0 {
        return Err(Error::numerical(
            CTX,
            format!(
                "the loop gain |PC| is {top:.3} (>= 1) on the top line ({:.1} Hz): the count needs a band that reaches where the loop has rolled off; widen the band or give the number of unstable poles",
                f[f.len() - 1]
            ),
        ));
    }
    let theta_pi = 2.0 * PI * (theta / (2.0 * PI)).round();
    // below the band: P constant at its lowest line, C exact, on a log grid down to f_lo·1e-6
    let p0 = kept[0].1;
    let n_grid = 400;
    let f_low: Vec<f64> = (1..=n_grid)
        .map(|k| f[0] * 10f64.powf(-6.0 * k as f64 / n_grid as f64))
        .collect();
    let c_low = controller.freq_response_siso(&f_low)?;
    let mut th = theta_lo;
    for cl in &c_low {
        th = unwrap(th, one + p0 * cl);
    }
    let poles = controller.poles()?;
    let at_one = poles.iter().filter(|z| (*z - one).norm() < 1e-9).count();
    let c_unstable = poles
        .iter()
        .filter(|z| z.norm() > 1.0 && (*z - one).norm() >= 1e-9)
        .count();
    let theta_0_raw = th + at_one as f64 * PI / 2.0;
    let theta_0 = PI * (theta_0_raw / PI).round();
    if (theta_0_raw - theta_0).abs() > PI / 4.0 {
        return Err(Error::numerical(
            CTX,
            "the phase of 1 + PC towards DC is not near a multiple of pi (the low-frequency loop is not as assumed); give the number of unstable poles",
        ));
    }
    let w = ((theta_pi - theta_0) / PI).round() as i64;
    let n = w - c_unstable as i64;
    if n < 0 {
        return Err(Error::numerical(
            CTX,
            format!(
                "the Nyquist count is negative ({n}): the measured loop is not consistent with a stable closed loop and this controller; check the controller file and the band, or give the number of unstable poles"
            ),
        ));
    }
    Ok(n as usize)
}

/// The comparison as a plain-text table (one row per candidate; `—` for missing values).
pub fn table(rows: &[CompareRow]) -> String {
    let opt = |v: Option<f64>, scale: f64, prec: usize| {
        v.map_or("—".to_string(), |x| format!("{:.*}", prec, x * scale))
    };
    let mut s = String::from(
        "structure order n_params  rel_rmse_%  low_rel_rmse_%  db_rmse  median_rel_%        bic  val_fit_%  unstable  note\n",
    );
    for r in rows {
        s.push_str(&format!(
            "{:<9} {:>5} {:>8} {:>11} {:>15} {:>8} {:>13} {:>10} {:>10} {:>9}  {}\n",
            r.structure.name(),
            r.order,
            r.n_params,
            opt(r.relative_rmse, 100.0, 3),
            opt(r.low_band_relative_rmse, 100.0, 3),
            opt(r.db_rmse, 1.0, 3),
            opt(r.median_relative, 100.0, 3),
            opt(r.bic, 1.0, 1),
            opt(r.validation_fit, 1.0, 2),
            r.unstable_poles.map_or("—".to_string(), |u| u.to_string()),
            r.note.as_deref().unwrap_or("")
        ));
    }
    s
}

/// The number of unstable plant poles the fits are held to, and how it was found: `given` when
/// the user set it, else the Nyquist count of the measured loop with the controller
/// ([`unstable_poles_from_loop`]), else `None` (unconstrained, with the reason).
pub fn supported_unstable_poles(
    frd: &Frd,
    controller: Option<&StateSpace>,
    band: Option<(f64, f64)>,
    given: Option<usize>,
) -> (Option<usize>, String) {
    if let Some(n) = given {
        return (Some(n), format!("{n} (given)"));
    }
    let Some(c) = controller else {
        return (
            None,
            "not constrained (no controller: give the controller for the Nyquist count of the measured loop, or the number)".into(),
        );
    };
    match unstable_poles_from_loop(frd, c, band) {
        Ok(n) => (
            Some(n),
            format!("{n} (Nyquist count of the measured loop with the controller)"),
        ),
        Err(e) => (None, format!("not constrained: {e}")),
    }
}
