//! The order stage: the evidence on the model order and its reconciliation into one
//! recommended order and range (rule in docs/workflow.md, "Order"): the ARX loss and BIC over
//! $n_a \times n_b$, the resonance peaks of the plant FRF, and state-space fits per order
//! (to the FRF, or to the time record scored on the validation record, with the subspace
//! singular values beside them).

use super::Recording;
use crate::analysis::FrfAnalysis;
use crate::config::{ModelsSection, OrderSection};
use crate::error::{Error, FailureClass, Result};
use crate::fitting::{identify_state_space, SsFitOptions, SsFocus};
use crate::io::ControllerModel;
use ambid_core::estimate::freqfit::FreqFitOptions;
use ambid_core::estimate::order::{arx_order_scan, ArxScanSpec, OrderScan};
use ambid_core::estimate::subspace::{n4sid_detailed, SubspaceOptions};
use ambid_core::frf::band::{fit_band, FIT_REL_HALFWIDTH};
use ambid_core::frf::resonance::{
    find_resonances_reliable, order_from_peaks, Resonance, ResonanceOptions,
};
use ambid_core::validate::compare::{compare_models, supported_unstable_poles, CompareSpec};
use ambid_core::validate::fit::fit_percent;

/// Relative tolerance on an error per order that makes an order adequate, from the number `n`
/// of residuals the error is computed on (FRF lines in the fit band, or validation samples):
/// $1 + 2/\sqrt{2n}$, two standard deviations of an RMS estimated from $n$ independent
/// residuals (its relative standard deviation is $\approx 1/\sqrt{2n}$), so an order within
/// it of the smallest error cannot be told apart from the best by the data.
///
/// ```
/// use ambid::stage::order_error_tolerance;
/// // 50 lines: 1 + 2/√100 = 1.2
/// assert!((order_error_tolerance(50) - 1.2).abs() < 1e-15);
/// ```
pub fn order_error_tolerance(n: usize) -> f64 {
    1.0 + 2.0 / (2.0 * n.max(1) as f64).sqrt()
}

/// How far the recommended range reaches above the recommended (smallest adequate) order: one
/// more complex pole pair, when those orders are adequate too, so that the models step
/// compares the smallest adequate model with ones that can hold a hidden mode or the delay.
pub const ORDER_RANGE_ABOVE: usize = 2;

/// The largest order the recommendation scans (state-space fits of orders 1 … this, or the
/// largest of `[models] orders` when that is larger): two states per mode, so five modes in the
/// band; above it the subspace singular values of measured records are noise.
pub const ORDER_SCAN_MAX: usize = 10;

/// The largest relative standard deviation of a plant line the resonance search uses: only
/// lines known to 10 % can show a mode (noise ripple is no resonance).
pub const RESONANCE_MAX_REL_STD: f64 = 0.1;

/// The resonance peaks of a plant FRF in its quality band ([`resonance_scan`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ResonanceScan {
    /// The band searched \[Hz\] (the analysis' quality band).
    pub band: (f64, f64),
    /// Smallest prominence of a peak \[dB\].
    pub min_prominence_db: f64,
    /// The peaks (empty when none, or when the search failed).
    pub peaks: Vec<Resonance>,
    /// Lines of the band with relative standard deviation ≤ [`RESONANCE_MAX_REL_STD`].
    pub searched: usize,
    /// Two states per peak ([`order_from_peaks`]).
    pub order: usize,
    /// Why the search failed (e.g. fewer than three reliable lines), if it did.
    pub error: Option<String>,
}

/// The resonance peaks of the analysis' plant FRF in its quality band, on the lines whose
/// relative standard deviation is at most [`RESONANCE_MAX_REL_STD`], with prominence
/// ≥ 3 dB ([`ambid_core::frf::resonance::find_resonances_reliable`]); `ambid frf` prints them
/// and the order stage counts them. A failed search is kept in [`ResonanceScan::error`]
/// (no peaks), not returned as an error.
///
/// ```
/// use ambid::stage::{acquire_twin, frf, identification_plan, resonance_scan, AcquisitionPlan, FrfInput, Seeds, TwinSource};
/// use ambid::experiment::ExcitationKind;
/// use ambid::workflow::config::{ExcitationSection, FrfSection};
/// let twin = TwinSource::new(ambid_twin::TwinConfig::default(), ambid_twin::Mode::Nonlinear).unwrap();
/// let seeds = Seeds::from_workflow_seed(1);
/// let exc = ExcitationSection { periods: 8, ..ExcitationSection::default() };
/// let plan = AcquisitionPlan::new(identification_plan(&exc, 0.1, &seeds), ExcitationKind::Multisine, 0.1, seeds);
/// let rec = acquire_twin(&twin, &plan).unwrap().identification;
/// let fs = FrfSection::default();
/// let st = frf(&FrfInput { record: &rec, frf: &fs, skip_periods: 1, noise: None, controller: None, twin: None }).unwrap();
/// let s = resonance_scan(&st.analysis);
/// assert_eq!(s.band, st.analysis.quality.band);
/// assert_eq!(s.order, 2 * s.peaks.len());
/// assert!(s.error.is_none() && s.searched > 0);
/// assert!(s.peaks.iter().all(|p| (s.band.0..=s.band.1).contains(&p.f_hz)));
/// ```
pub fn resonance_scan(a: &FrfAnalysis) -> ResonanceScan {
    let opts = ResonanceOptions {
        band: a.quality.band,
        ..ResonanceOptions::default()
    };
    let (peaks, searched, error) =
        match find_resonances_reliable(&a.frf.plant, &opts, RESONANCE_MAX_REL_STD) {
            Ok((p, n)) => (p, n, None),
            Err(e) => (Vec::new(), 0, Some(e.to_string())),
        };
    ResonanceScan {
        band: opts.band,
        min_prominence_db: opts.min_prominence_db,
        order: order_from_peaks(&peaks),
        peaks,
        searched,
        error,
    }
}

/// The order stage's input.
#[derive(Clone, Copy)]
pub struct OrderInput<'a> {
    /// The identification record (the ARX scan and the fits use `u → y`).
    pub identification: &'a Recording,
    /// The independent validation record.
    pub validation: &'a Recording,
    /// The FRF of the identification record (resonances; the FRF fits of the scan), if made.
    pub frf: Option<&'a FrfAnalysis>,
    /// The `[order]` settings (ARX grid, samples used).
    pub order: &'a OrderSection,
    /// The `[models]` settings the scan mirrors (domain, band, weights, unstable poles, orders).
    pub models: &'a ModelsSection,
    /// Whether the models step runs: the time-domain fits per order run only then (they serve
    /// its order list and cost seconds on long records); without it the singular values decide.
    pub models_run: bool,
    /// The controller (closed loop), for the FRF fits' unstable-pole count and loop check.
    pub controller: Option<&'a ControllerModel>,
}

/// The ARX loss and BIC over the grid $n_a = 1 … n_{a,\max}$, $n_b = 1 … n_{b,\max}$.
#[derive(Debug, Clone)]
pub struct ArxGrid {
    /// The scan ([`arx_order_scan`] of the identification record, validated on the validation record).
    pub scan: OrderScan,
    /// The delay $n_k$.
    pub nk: usize,
    /// $n_a$ values (rows of the grids).
    pub na: Vec<f64>,
    /// $n_b$ values (columns of the grids).
    pub nb: Vec<f64>,
    /// $\log_{10} V_N$ per $(n_a, n_b)$.
    pub log10_loss: Vec<Vec<f64>>,
    /// BIC per $(n_a, n_b)$.
    pub bic: Vec<Vec<f64>>,
    /// $(n_a, n_b, n_k)$ of the smallest BIC.
    pub best: (usize, usize, usize),
    /// The smallest BIC lies on the grid's edge ($n_a = n_{a,\max}$ or $n_b = n_{b,\max}$).
    pub on_edge: bool,
}

/// What the errors per order of [`OrderErrors`] measure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ErrorBasis {
    /// State-space fits to the plant FRF over `band` \[Hz\]: relative RMSE (a fraction).
    Frf {
        /// The fit band \[Hz\].
        band: (f64, f64),
    },
    /// Time-domain state-space fits: validation error $100\,\% - $ fit (in %).
    TimeValidation,
}

/// One order of the scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrderError {
    /// The order.
    pub order: usize,
    /// Its error (`None`: the fit is not valid, or there is none).
    pub error: Option<f64>,
    /// Within the tolerance of the smallest error.
    pub adequate: bool,
}

/// The errors per order the recommendation rests on.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderErrors {
    /// What the errors measure.
    pub basis: ErrorBasis,
    /// The largest order scanned.
    pub scan_max: usize,
    /// [`order_error_tolerance`] of the residual count.
    pub tolerance: f64,
    /// The smallest error.
    pub best: f64,
    /// Per order, 1 … `scan_max`.
    pub rows: Vec<OrderError>,
}

impl OrderErrors {
    /// The rows of `errs` (order, error) with each marked adequate when its error is within
    /// `tolerance` × `best`.
    fn new(
        basis: ErrorBasis,
        scan_max: usize,
        tolerance: f64,
        best: f64,
        errs: &[(usize, Option<f64>)],
    ) -> Self {
        Self {
            basis,
            scan_max,
            tolerance,
            best,
            rows: errs
                .iter()
                .map(|&(order, error)| OrderError {
                    order,
                    error,
                    adequate: error.is_some_and(|e| e <= tolerance * best),
                })
                .collect(),
        }
    }
}

/// The subspace (CVA) evidence: the singular values of $u \to y$ and the order at their
/// largest gap.
#[derive(Debug, Clone, PartialEq)]
pub struct SubspaceEvidence {
    /// The first singular values (up to the scan's largest order + 1).
    pub singular_values: Vec<f64>,
    /// The order after the largest gap.
    pub order: usize,
}

/// The reconciled order recommendation.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderRecommendation {
    /// Recommended order.
    pub n: usize,
    /// Lowest adequate order of the range.
    pub lo: usize,
    /// Highest order of the range.
    pub hi: usize,
    /// Which evidence set the range: `frf_fit_error`, `time_fit_error` or
    /// `subspace_singular_values`.
    pub source: &'static str,
    /// The order scanned just below `lo`, which is not adequate (0 when `lo` is the first).
    pub below: usize,
    /// The errors per order, when fits set the range.
    pub errors: Option<OrderErrors>,
    /// The subspace singular values (time-domain recommendations).
    pub subspace: Option<SubspaceEvidence>,
}

/// The order stage's output.
#[derive(Debug, Clone)]
pub struct OrderStage {
    /// The ARX scan over the grid.
    pub arx: ArxGrid,
    /// The resonance peaks of the plant FRF (when the FRF was made).
    pub resonances: Option<ResonanceScan>,
    /// Closed-loop data (the rigid-body pair adds two states to the peaks' count).
    pub closed_loop: bool,
    /// The number of significant peaks the recommendation compares with (when some line of the
    /// band was reliable enough to search).
    pub significant_peaks: Option<usize>,
    /// The recommendation, or why there is none.
    pub recommendation: std::result::Result<OrderRecommendation, String>,
}

/// The order stage: the ARX scan of the identification record (the first
/// `[order] max_samples` samples; validation on the validation record), the resonance peaks
/// of the plant FRF ([`resonance_scan`]) and the recommendation (rule in docs/workflow.md,
/// "Order"):
/// * when the models step fits FRFs (closed loop with an excitation, or `[models] domain =
///   "frf"`): state-space fits of orders 1 … [`ORDER_SCAN_MAX`] to the plant FRF on the models
///   step's fit band, with its weights and unstable-pole count; the adequate orders are the
///   valid fits whose relative RMSE is at most [`order_error_tolerance`] (of the band's line
///   count) times the smallest; the recommendation is the smallest adequate order, the range the
///   adequate orders from it up to [`ORDER_RANGE_ABOVE`] more;
/// * otherwise (time-domain models): the same rule on time-domain state-space fits scored by
///   $100\,\% -$ their fit on the validation record (tolerance of its sample count), with the
///   largest gap of the subspace (CVA) singular values quoted beside it (and used alone when no
///   fit has a predictor, or when the models step does not run);
/// * the resonance count (a lower bound) and the ARX BIC minimum (an upper bound, or nothing
///   when it lies on the grid's edge) are compared with the range and each disagreement stated.
///
/// # Example
/// A second-order system $y_k = 1.5 y_{k-1} - 0.7 y_{k-2} + u_{k-1} + 0.5 u_{k-2} + e_k$: the
/// ARX BIC and the subspace singular values both find order 2.
/// ```
/// use ambid::stage::{order, OrderInput, Recording, Signals};
/// use ambid::workflow::config::{ModelsSection, OrderSection};
/// let record = |seed: u64| {
///     let mut s = seed;
///     let mut rnd = move || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5 };
///     let n = 2000;
///     let u: Vec<f64> = (0..n).map(|_| rnd()).collect();
///     let mut y = vec![0.0; n];
///     for k in 2..n {
///         y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + u[k - 1] + 0.5 * u[k - 2] + 1e-3 * rnd();
///     }
///     Recording::from_signals(1e-3, None, Signals { u, y, ..Signals::default() }, false, "example").unwrap()
/// };
/// let (ident, valid) = (record(1), record(2));
/// let o = OrderSection { na_max: 4, nb_max: 4, ..OrderSection::default() };
/// let st = order(&OrderInput {
///     identification: &ident,
///     validation: &valid,
///     frf: None,
///     order: &o,
///     models: &ModelsSection::default(),
///     models_run: false,
///     controller: None,
/// })
/// .unwrap();
/// assert_eq!((st.arx.best.0, st.arx.best.1), (2, 2));
/// let r = st.recommendation.unwrap();
/// assert_eq!((r.n, r.source), (2, "subspace_singular_values"));
/// ```
///
/// # Errors
/// A computation error when the ARX scan fails (e.g. a record too short for the grid); a failed
/// recommendation is kept in [`OrderStage::recommendation`].
pub fn order(input: &OrderInput<'_>) -> Result<OrderStage> {
    let o = input.order;
    let cut = |r: &Recording| -> (Vec<f64>, Vec<f64>) {
        let n = if o.max_samples > 0 {
            o.max_samples.min(r.len())
        } else {
            r.len()
        };
        (r.y()[..n].to_vec(), r.u()[..n].to_vec())
    };
    let (y, u) = cut(input.identification);
    let (yv, uv) = cut(input.validation);
    let (na_max, nb_max) = (o.na_max.max(1), o.nb_max.max(1));
    let spec = ArxScanSpec::new(1..=na_max, 1..=nb_max, vec![o.nk]);
    let scan = arx_order_scan(&y, &u, &spec, Some((&yv, &uv)))
        .map_err(|e| Error::classified(FailureClass::Computation, e))?;
    let na: Vec<f64> = (1..=na_max).map(|v| v as f64).collect();
    let nb: Vec<f64> = (1..=nb_max).map(|v| v as f64).collect();
    let mut log10_loss = vec![vec![f64::NAN; nb.len()]; na.len()];
    let mut bic = vec![vec![f64::NAN; nb.len()]; na.len()];
    for r in &scan.rows {
        if r.na >= 1 && r.nb >= 1 && r.na <= na.len() && r.nb <= nb.len() {
            log10_loss[r.na - 1][r.nb - 1] = r.loss.log10();
            bic[r.na - 1][r.nb - 1] = r.bic;
        }
    }
    let b = &scan.rows[scan.best_bic];
    let best = (b.na, b.nb, b.nk);
    let on_edge = best.0 == na.len() || best.1 == nb.len();
    let closed_loop = input.identification.closed_loop;
    let resonances = input.frf.map(resonance_scan);
    let n_peaks = resonances
        .as_ref()
        .filter(|s| s.searched > 0)
        .map(|s| s.peaks.len());
    let recommendation = recommend(input);
    Ok(OrderStage {
        arx: ArxGrid {
            scan,
            nk: o.nk,
            na,
            nb,
            log10_loss,
            bic,
            best,
            on_edge,
        },
        resonances,
        closed_loop,
        significant_peaks: n_peaks,
        recommendation,
    })
}

/// The smallest adequate order and the range from it up to [`ORDER_RANGE_ABOVE`] more adequate
/// orders: `(i0, i1)` indices into `errs`.
fn adequate_range(
    errs: &[(usize, Option<f64>)],
    ok: impl Fn(Option<f64>) -> bool,
) -> Option<(usize, usize)> {
    let i0 = errs.iter().position(|e| ok(e.1))?;
    let mut i1 = i0;
    while i1 + 1 < errs.len() && i1 < i0 + ORDER_RANGE_ABOVE && ok(errs[i1 + 1].1) {
        i1 += 1;
    }
    Some((i0, i1))
}

/// Reconciles the three order sources into one recommended order and range (see [`order`]).
fn recommend(input: &OrderInput<'_>) -> std::result::Result<OrderRecommendation, String> {
    let rec = input.identification;
    let mcfg = input.models;
    let scan_max = ORDER_SCAN_MAX.max(mcfg.orders.iter().copied().max().unwrap_or(1));
    let frf_domain = match mcfg.domain.as_deref() {
        Some(d) => d == "frf" && input.frf.is_some(),
        None => rec.r().is_some() && rec.closed_loop && input.frf.is_some(),
    };
    let (n, lo, hi, source, below, errors, subspace) = if let (true, Some(a)) =
        (frf_domain, input.frf)
    {
        let frd = &a.frf.plant;
        let explicit_band = mcfg.band_hz.map(|[a, b]| (a, b));
        let band = match explicit_band {
            Some(b) => b,
            None => {
                fit_band(frd, FIT_REL_HALFWIDTH)
                    .map_err(|e| format!("no fit band for the order scan ({e})"))?
                    .band
            }
        };
        let weights = super::models::frf_weights(&mcfg.weights, a);
        let ctrl = input.controller.map(|c| c.state_space());
        let (n_u, _) = supported_unstable_poles(frd, ctrl, explicit_band, mcfg.unstable_poles);
        let spec = CompareSpec {
            structures: vec![ambid_core::lti::Structure::Ss],
            orders: (1..=scan_max).collect(),
            nk: mcfg.nk,
            fit: FreqFitOptions {
                band_hz: Some(band),
                weights,
                max_iterations: mcfg.max_iterations,
                ..FreqFitOptions::default()
            },
            unstable_poles: n_u,
            controller: ctrl.cloned(),
            ..CompareSpec::default()
        };
        let rows = compare_models(frd, &spec, None)
            .map_err(|e| format!("the state-space fits of the order scan failed ({e})"))?;
        let errs: Vec<(usize, Option<f64>)> = rows
            .iter()
            // a pair that cancels within the data does not take an order out of the scan:
            // its error is that of the order the data support
            .map(|r| (r.order, r.relative_rmse.filter(|_| r.admissible)))
            .collect();
        let Some(best) = errs
            .iter()
            .filter_map(|e| e.1)
            .min_by(|a, b| a.total_cmp(b))
        else {
            return Err("no state-space fit of the order scan is valid".into());
        };
        let lines = frd
            .f_hz()
            .iter()
            .filter(|f| (band.0..=band.1).contains(*f))
            .count();
        let tol = order_error_tolerance(lines);
        let ok = |e: Option<f64>| e.is_some_and(|e| e <= tol * best);
        let Some((i0, i1)) = adequate_range(&errs, ok) else {
            return Err("no order of the scan is adequate".into());
        };
        let errors = OrderErrors::new(ErrorBasis::Frf { band }, scan_max, tol, best, &errs);
        (
            errs[i0].0,
            errs[i0].0,
            errs[i1].0,
            "frf_fit_error",
            if i0 > 0 { errs[i0 - 1].0 } else { 0 },
            Some(errors),
            None,
        )
    } else {
        let n = rec.len();
        let y = faer::Mat::from_fn(n, 1, |k, _| rec.y()[k]);
        let u = faer::Mat::from_fn(n, 1, |k, _| rec.u()[k]);
        let opts = SubspaceOptions {
            max_order: scan_max,
            ..SubspaceOptions::new(rec.ts())
        };
        let fit = match n4sid_detailed(y.as_ref(), u.as_ref(), &opts) {
            Ok(f) => f,
            Err(e) => return Err(format!("the subspace fit of the order scan failed ({e})")),
        };
        let subspace = SubspaceEvidence {
            singular_values: fit
                .singular_values
                .iter()
                .take(scan_max + 1)
                .copied()
                .collect(),
            order: fit.order,
        };
        // time-domain state-space fits per order, scored by their one-step prediction error
        // on the validation record (the models step's fits and criterion)
        // (only when the models step runs: the scan serves its order list, and ten state-space
        // fits of a long record cost seconds; without it the singular values decide)
        let val = input.validation;
        let errs: Vec<(usize, Option<f64>)> = if input.models_run {
            (1..=scan_max)
                .map(|o| {
                    let so = SsFitOptions {
                        order: Some(o),
                        focus: if rec.closed_loop {
                            SsFocus::Prediction
                        } else {
                            SsFocus::Auto
                        },
                        max_iterations: mcfg.max_iterations,
                        ..SsFitOptions::default()
                    };
                    let e = identify_state_space(rec.u(), rec.y(), rec.ts(), &so)
                        .ok()
                        .and_then(|f| {
                            // the models step's own criterion: simulation when the model is
                            // stable, else the one-step prediction of its innovations form
                            let k = f.pem.and_then(|p| p.kalman_gain);
                            let (yh, _) = super::validation::open_loop_response(
                                &super::validation::ModelUnderTest {
                                    name: "ss",
                                    model: &f.model,
                                    poly: None,
                                    kalman: k.as_deref(),
                                },
                                val.y(),
                                val.u(),
                            )?;
                            fit_percent(val.y(), &yh).ok().map(|p| 100.0 - p)
                        });
                    (o, e)
                })
                .collect()
        } else {
            Vec::new()
        };
        let best = errs
            .iter()
            .filter_map(|e| e.1)
            .min_by(|a, b| a.total_cmp(b));
        let tol = order_error_tolerance(val.len());
        let ok = |e: Option<f64>| best.is_some_and(|b| e.is_some_and(|e| e <= tol * b));
        match adequate_range(&errs, ok) {
            Some((i0, i1)) => {
                let b = best.unwrap_or(f64::NAN);
                let errors = OrderErrors::new(ErrorBasis::TimeValidation, scan_max, tol, b, &errs);
                let (lo, hi) = (errs[i0].0, errs[i1].0);
                (
                    lo,
                    lo,
                    hi,
                    "time_fit_error",
                    lo - 1,
                    Some(errors),
                    Some(subspace),
                )
            }
            None => (
                fit.order,
                fit.order,
                fit.order,
                "subspace_singular_values",
                0,
                None,
                Some(subspace),
            ),
        }
    };
    Ok(OrderRecommendation {
        n,
        lo,
        hi,
        source,
        below,
        errors,
        subspace,
    })
}
