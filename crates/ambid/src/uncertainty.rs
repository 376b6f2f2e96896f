//! From identification to robust control (issue 23, SISO): the uncertainty of a nominal plant
//! model over frequency, the low-order weight that overbounds it, and the robust stability of the
//! current controller against it — one call for `ambid uncertainty`, the workflow and the
//! Python package ([`analyse`]); and the twin check of the same chain on a random rig
//! ([`UncertaintyRun`]), which the tests and the `uncertainty_rigs` example run.
//!
//! The terms, the weight and the margins are documented in
//! [`ambid_core::validate::uncertainty`], [`ambid_core::validate::weight`] and
//! [`ambid_core::validate::robust`].

use crate::error::{Context, Error, Result};
use crate::experiment::{run, ExcitationPlan, Experiment};
use ambid_core::c64;
use ambid_core::estimate::freqfit::{FreqData, FreqFitOptions, FreqWeights};
use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
use ambid_core::frf::bla::{BlaEstimate, NlGroup};
use ambid_core::lti::{Frd, StateSpace};
use ambid_core::validate::compare::{cancelling_pairs, unstable_poles_from_loop};
pub use ambid_core::validate::robust::{loop_stable, nominal_gain_interval};
use ambid_core::validate::robust::{
    robust_stability, robust_stability_matrix_drawn, robust_stability_on_lines,
    DrawnRobustStability, MatrixWeight, RobustStability,
};
use ambid_core::validate::uncertainty::{
    uncertainty_matrix, window_half_lines_for, window_scales, ExtraTerms, MatrixUncertainty,
    ProjectedShift, UncertaintyOptions, UncertaintyTerms,
};
use ambid_core::validate::weight::{fit_weight_shaped, WeightFit, DEFAULT_COVER, MAX_WEIGHT_ORDER};
use ambid_twin::{random_rig, Mode, TwinConfig};

/// What [`analyse`] returns.
#[derive(Debug, Clone)]
pub struct UncertaintyAnalysis {
    /// The terms and the bounds per line.
    pub terms: UncertaintyTerms,
    /// The weight overbounding the multiplicative bound.
    pub weight: WeightFit,
    /// The controller's robust stability against it.
    pub robust: RobustStability,
    /// The factor the weight's gain was raised by so that it overbounds the model's error on
    /// the fraction `raise_cover` of the band in the fraction `run_coverage` of the runs
    /// ([`ErrorModel::joint_factor`](ambid_core::validate::uncertainty::ErrorModel::joint_factor); 1: the per-line overbound already did).
    pub joint_raise: f64,
    /// The controller's robust stability against the bound on the lines itself, $g_\ell\,\ell_k$
    /// ([`robust_stability_on_lines`]): the $\mu$ analysis on the measured band without the
    /// weight's fit, so its verdict does not rest on how an order-≤4 weight compromises over a
    /// ragged bound; it says nothing outside the band.
    pub on_lines: RobustStability,
    /// $g_\ell \ge 1$: the factor the bound ℓ was raised by for [`Self::on_lines`], so that it
    /// overbounds the model's error on `raise_cover` of the lines in `run_coverage` of the draws.
    pub lines_raise: f64,
    /// Term (e) through the model ([`analyse_with_shift`]): its Wald test, or why it could not
    /// be computed (the bound then keeps the line term); `None` without per-line shifts.
    pub amplitude_projected: Option<std::result::Result<ProjectedShift, String>>,
    /// The controller's robust stability against [`COHERENT_DRAWS`] coherent draws of the
    /// model's error, each a whole curve over the lines, with the misfit of unknown phase
    /// around each and the weight outside the lines ([`RobustChecks::coherent`]): its margins
    /// are the reported ones, as on the machine (docs/uncertainty.md, "Coherent margins on one
    /// axis").
    pub coherent: DrawnRobustStability,
}

/// The number of coherent draws of the model's error
/// ([`MatrixUncertainty::coherent_draws`](ambid_core::validate::uncertainty::MatrixUncertainty::coherent_draws))
/// behind the coherent robust margins, on one axis and per speed of the machine.
pub const COHERENT_DRAWS: usize = 200;

/// The fraction of the coherent draws the coherent robust margins hold for.
pub const COHERENT_CONFIDENCE: f64 = 0.95;

/// The controller's robust stability against an uncertainty bound, three ways
/// ([`UncertainBound::robust_checks`]).
#[derive(Debug, Clone)]
pub struct RobustChecks {
    /// Against the weight, $P = \hat P(1 + W\Delta)$: $\mu = |W T|$ on a dense grid
    /// ([`robust_stability`]), the small-gain certificate of the uncertain model that is
    /// exported.
    pub weight: RobustStability,
    /// Against the bound on the lines raised by $g_\ell$ ([`robust_stability_on_lines`]): the
    /// band only.
    pub on_lines: RobustStability,
    /// Against [`COHERENT_DRAWS`] coherent draws $D_d$ of the model's error
    /// ([`robust_stability_matrix_drawn`], the $1\times 1$ case of the machine's check): per
    /// draw, the gain interval in which $\hat P + D_d$, with the part of the bound whose phase
    /// is not known (term (b)'s spread, (d), the per-line term (e)) as an element-wise
    /// remainder, keeps the loop stable at every line, capped by the weight's test up to an
    /// octave beyond the lines; the margins that [`COHERENT_CONFIDENCE`] of the draws reach.
    /// A statement at that confidence under the error model, not a worst case: the weight's
    /// and the lines' checks are the worst-case certificates beside it.
    pub coherent: DrawnRobustStability,
}

/// An amplitude study's per-line shift estimates at the identification level
/// ([`amplitude_shift_lines`]: complex, absolute, with the variance of a circular complex
/// error) on the study's lines `f_hz`, for term (e) through the model ([`analyse_with_shift`]).
#[derive(Debug, Clone, Copy)]
pub struct ShiftLines<'a> {
    /// The study's lines \[Hz\].
    pub f_hz: &'a [f64],
    /// $c_j a_e^2$ per line.
    pub shift: &'a [c64],
    /// Its variance per line.
    pub var: &'a [f64],
}

impl ShiftLines<'_> {
    /// The shifts and variances on the lines `f_hz` (those of the FRF the bound is computed
    /// on): a line of the study within $10^{-9}$ relative gives its values; a line the study
    /// does not have gets shift 0 with variance 0, so it adds nothing to the projection's
    /// right-hand side or to its test.
    ///
    /// # Errors
    /// Lengths that differ.
    ///
    /// # Example
    /// ```
    /// use ambid::uncertainty::ShiftLines;
    /// use ambid_core::c64;
    /// let (f, sh, v) = ([10.0, 20.0], [c64::new(1.0, 0.0), c64::new(2.0, 0.0)], [0.1, 0.2]);
    /// let lines = ShiftLines { f_hz: &f, shift: &sh, var: &v };
    /// let (s, var) = lines.on_lines(&[5.0, 20.0, 30.0]).unwrap();
    /// assert_eq!(s[1], c64::new(2.0, 0.0));
    /// assert_eq!((var[0], var[1], var[2]), (0.0, 0.2, 0.0));
    /// ```
    pub fn on_lines(&self, f_hz: &[f64]) -> Result<(Vec<c64>, Vec<f64>)> {
        let n = self.f_hz.len();
        if self.shift.len() != n || self.var.len() != n {
            return Err(Error::other(format!(
                "term (e) through the model: {n} lines, {} shifts and {} variances: give one of each per line",
                self.shift.len(),
                self.var.len()
            )));
        }
        let mut shift = vec![c64::new(0.0, 0.0); f_hz.len()];
        let mut var = vec![0.0; f_hz.len()];
        for (k, &f) in f_hz.iter().enumerate() {
            let j = self.f_hz.partition_point(|&x| x < f);
            let near = [j.wrapping_sub(1), j]
                .into_iter()
                .filter(|&i| i < n)
                .min_by(|&a, &b| {
                    (self.f_hz[a] - f)
                        .abs()
                        .total_cmp(&(self.f_hz[b] - f).abs())
                });
            if let Some(i) = near.filter(|&i| (self.f_hz[i] - f).abs() <= 1e-9 * f.abs().max(1.0)) {
                shift[k] = self.shift[i];
                var[k] = self.var[i];
            }
        }
        Ok((shift, var))
    }
}

/// The uncertainty of `nominal` around the measured plant FRF `frd` (with variances), its weight
/// of order ≤ `max_weight_order` overbounding the fraction `cover` of the lines — its gain then
/// raised, where needed, until it also overbounds the fitted model's error on `opts.raise_cover`
/// of the lines in `opts.run_coverage` of `opts.draws` seeded draws
/// ([`ErrorModel::joint_factor`](ambid_core::validate::uncertainty::ErrorModel::joint_factor),
/// [`UncertaintyAnalysis::joint_raise`]) — and the robust stability of `controller` against it,
/// and against the bound on the lines itself, raised the same way
/// ([`UncertaintyAnalysis::on_lines`]).
///
/// # Errors
/// Those of [`uncertainty`](ambid_core::validate::uncertainty::uncertainty), [`fit_weight_shaped`] and [`robust_stability`], with the step named.
///
/// # Example
/// ```
/// use ambid::uncertainty::analyse;
/// use ambid_core::lti::{Frd, StateSpace};
/// use ambid_core::validate::uncertainty::{ExtraTerms, UncertaintyOptions};
/// use faer::mat;
/// let ts = 1e-3;
/// let p = StateSpace::discrete(mat![[0.9]], mat![[1.0]], mat![[0.1]], mat![[0.0]], ts).unwrap();
/// let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[2.0]], ts).unwrap();
/// let f: Vec<f64> = (1..=100).map(|k| 4.0 * k as f64).collect();
/// let exact = Frd::from_model(&p, &f).unwrap();
/// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr()).collect();
/// let frd = Frd::new(f, exact.values().to_vec(), Some(var), Some(ts)).unwrap();
/// let a = analyse(&p, &frd, &c, &ExtraTerms::default(), &UncertaintyOptions::default(), 4, 1.0)
///     .unwrap();
/// assert!(a.robust.robustly_stable);
/// assert!(a.weight.weight.order() <= 4);
/// ```
pub fn analyse(
    nominal: &StateSpace,
    frd: &Frd,
    controller: &StateSpace,
    extra: &ExtraTerms<'_>,
    opts: &UncertaintyOptions,
    max_weight_order: usize,
    cover: f64,
) -> Result<UncertaintyAnalysis> {
    analyse_with_shift(
        nominal,
        frd,
        controller,
        extra,
        None,
        opts,
        max_weight_order,
        cover,
    )
}

/// [`analyse`] with term (e) also carried through the model: the amplitude study's per-line
/// shifts `shift` projected onto the model's tangent space
/// ([`MatrixUncertainty::add_projected_shift`](ambid_core::validate::uncertainty::MatrixUncertainty::add_projected_shift) on the 1×1 bound, Wald test at
/// [`AMPLITUDE_RUN_ALPHA`]; docs/uncertainty.md, "Term (e) through the model"), the rule the
/// whole machine's bound uses. A shift that is smooth over the lines moves the fitted model even
/// where each line's estimate is below its noise and [`ExtraTerms::amplitude_shift`]'s windows
/// see nothing. When the projection cannot be computed the bound keeps the line term and
/// [`UncertaintyAnalysis::amplitude_projected`] says why.
///
/// # Errors
/// As [`analyse`].
///
/// # Example
/// A model 2 % above a first-order plant, the amplitude study's per-line shift estimates
/// telling so at 1 % noise: the projection is kept and the bound covers the shift.
/// ```
/// use ambid::uncertainty::{analyse_with_shift, ShiftLines};
/// use ambid_core::{c64, lti::{Frd, StateSpace}};
/// use ambid_core::validate::uncertainty::{ExtraTerms, UncertaintyOptions};
/// use faer::mat;
/// let ts = 1e-3;
/// let p = StateSpace::discrete(mat![[0.9]], mat![[1.0]], mat![[0.1]], mat![[0.0]], ts).unwrap();
/// let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[2.0]], ts).unwrap();
/// let f: Vec<f64> = (1..=100).map(|k| 4.0 * k as f64).collect();
/// let exact = Frd::from_model(&p, &f).unwrap();
/// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr()).collect();
/// let frd = Frd::new(f.clone(), exact.values().to_vec(), Some(var), Some(ts)).unwrap();
/// let shift: Vec<c64> = exact.values().iter().map(|g| g * 0.02).collect();
/// let sv: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr()).collect();
/// let lines = ShiftLines { f_hz: &f, shift: &shift, var: &sv };
/// let a = analyse_with_shift(
///     &p, &frd, &c, &ExtraTerms::default(), Some(lines), &UncertaintyOptions::default(), 4, 1.0,
/// )
/// .unwrap();
/// assert!(a.amplitude_projected.unwrap().unwrap().kept);
/// assert!(a.terms.multiplicative.iter().all(|l| *l >= 0.02));
/// ```
#[allow(clippy::too_many_arguments)]
pub fn analyse_with_shift(
    nominal: &StateSpace,
    frd: &Frd,
    controller: &StateSpace,
    extra: &ExtraTerms<'_>,
    shift: Option<ShiftLines<'_>>,
    opts: &UncertaintyOptions,
    max_weight_order: usize,
    cover: f64,
) -> Result<UncertaintyAnalysis> {
    let b = bound_and_weight(nominal, frd, extra, shift, opts, max_weight_order, cover)?;
    let checks = b.robust_checks(nominal, controller)?;
    Ok(UncertaintyAnalysis {
        terms: b.terms,
        weight: b.weight,
        robust: checks.weight,
        joint_raise: b.joint_raise,
        on_lines: checks.on_lines,
        lines_raise: b.lines_raise,
        amplitude_projected: b.amplitude_projected,
        coherent: checks.coherent,
    })
}

/// What [`bound_and_weight`] returns: the uncertainty model without a controller's check.
#[derive(Debug, Clone)]
pub struct UncertainBound {
    /// The terms and the bounds per line.
    pub terms: UncertaintyTerms,
    /// The weight overbounding the multiplicative bound, raised by [`Self::joint_raise`].
    pub weight: WeightFit,
    /// As [`UncertaintyAnalysis::joint_raise`].
    pub joint_raise: f64,
    /// As [`UncertaintyAnalysis::lines_raise`].
    pub lines_raise: f64,
    /// As [`UncertaintyAnalysis::amplitude_projected`].
    pub amplitude_projected: Option<std::result::Result<ProjectedShift, String>>,
    /// The $1\times 1$ matrix bound whose entry is [`Self::terms`], which draws the model's
    /// error as whole curves for [`RobustChecks::coherent`].
    matrix: MatrixUncertainty,
    /// The draws' seed (`UncertaintyOptions::seed`).
    seed: u64,
}

impl UncertainBound {
    /// The bound on the lines as the check on the lines uses it: $g_\ell\,\ell_k$, the
    /// multiplicative bound (floored as the weight's fit floors it) raised by
    /// [`Self::lines_raise`].
    pub fn raised_bound(&self) -> Vec<f64> {
        floored(&self.terms.multiplicative)
            .into_iter()
            .map(|b| b * self.lines_raise)
            .collect()
    }

    /// The robust stability of the loop with `controller` around `nominal` (the model this
    /// bound was computed for): against the weight, against the bound on the lines raised by
    /// $g_\ell$, and against the coherent draws ([`RobustChecks`]).
    ///
    /// # Errors
    /// A controller whose sample time differs from the model's, or a loop that cannot be
    /// evaluated.
    ///
    /// # Example
    /// A first-order plant (pole 0.9, output 0.1 x) under a static gain of 2: the loop's pole
    /// $0.9 - 0.1\,g\cdot 2$ reaches $-1$ at the gain factor $g = 9.5$, which no robust
    /// margin may exceed. With 1 % noise variance every check is robustly stable, and the
    /// coherent upper margin lies just below that interval's end (9.48 here).
    /// ```
    /// use ambid::uncertainty::bound_and_weight;
    /// use ambid_core::lti::{Frd, StateSpace};
    /// use ambid_core::validate::uncertainty::{ExtraTerms, UncertaintyOptions};
    /// use faer::{mat, Mat};
    /// # fn main() -> Result<(), Box<dyn std::error::Error>> {
    /// let ts = 1e-3;
    /// let p = StateSpace::discrete(mat![[0.9]], mat![[1.0]], mat![[0.1]], mat![[0.0]], ts)?;
    /// let c = StateSpace::discrete(Mat::zeros(0, 0), Mat::zeros(0, 1), Mat::zeros(1, 0),
    ///     mat![[2.0]], ts)?;
    /// let f: Vec<f64> = (1..=100).map(|k| 4.0 * k as f64).collect();
    /// let exact = Frd::from_model(&p, &f)?;
    /// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr()).collect();
    /// let frd = Frd::new(f.clone(), exact.values().to_vec(), Some(var), Some(ts))?;
    /// let opts = UncertaintyOptions::default();
    /// let b = bound_and_weight(&p, &frd, &ExtraTerms::default(), None, &opts, 4, 1.0)?;
    /// let checks = b.robust_checks(&p, &c)?;
    /// assert!(checks.weight.robustly_stable && checks.on_lines.robustly_stable);
    /// let co = &checks.coherent;
    /// assert!(co.robustly_stable && co.per_draw.len() == 200);
    /// let hi = co.upper_gain_margin.ok_or("no coherent upper margin")?;
    /// assert!(hi > 9.0 && hi <= 9.5 * (1.0 + 1e-6), "{hi}");
    /// # Ok(())
    /// # }
    /// ```
    pub fn robust_checks(
        &self,
        nominal: &StateSpace,
        controller: &StateSpace,
    ) -> Result<RobustChecks> {
        let weight = robust_stability(nominal, controller, &self.weight.weight)
            .context("the robust-stability check")?;
        let on_lines =
            robust_stability_on_lines(nominal, controller, &self.terms.f_hz, &self.raised_bound())
                .context("the robust-stability check on the lines")?;
        let d = self
            .matrix
            .coherent_draws(COHERENT_DRAWS, self.seed)
            .context("the coherent draws of the model's error")?;
        // the draws know nothing outside the lines: there the weight bounds the error
        let coherent = robust_stability_matrix_drawn(
            nominal,
            controller,
            &d.f_hz,
            &d.draws,
            &d.remainder,
            Some(MatrixWeight::EntryRelative(std::slice::from_ref(
                &self.weight.weight,
            ))),
            COHERENT_CONFIDENCE,
        )
        .context("the robust-stability check against the coherent draws")?;
        Ok(RobustChecks {
            weight,
            on_lines,
            coherent,
        })
    }
}

/// The multiplicative bound with a floor of 1e-12 of its largest value: a line where every
/// term is 0 (no noise, no misfit) cannot be overbounded in log scale.
fn floored(multiplicative: &[f64]) -> Vec<f64> {
    let top = multiplicative.iter().copied().fold(0.0f64, f64::max);
    multiplicative
        .iter()
        .map(|b| b.max(1e-12 * top).max(f64::MIN_POSITIVE))
        .collect()
}

/// The uncertainty model of [`analyse_with_shift`] without a controller: the terms, the weight
/// of order ≤ `max_weight_order` fitted over the fraction `cover` of the lines and raised to
/// the joint coverage, and the raise of the bound on the lines. For a plant whose controller is
/// still to be designed, and for data without a loop (the real-data check of the bound,
/// docs/uncertainty.md, "Real data: a held-out measurement").
///
/// # Errors
/// As [`analyse`], without the robust-stability checks.
///
/// # Example
/// A first-order plant's exact response with 1 % noise variance: the weight is of order ≤ 4
/// and lies above the bound on the lines it overbounds.
/// ```
/// use ambid::uncertainty::bound_and_weight;
/// use ambid_core::lti::{Frd, StateSpace};
/// use ambid_core::validate::uncertainty::{ExtraTerms, UncertaintyOptions};
/// use faer::mat;
/// let ts = 1e-3;
/// let p = StateSpace::discrete(mat![[0.9]], mat![[1.0]], mat![[0.1]], mat![[0.0]], ts).unwrap();
/// let f: Vec<f64> = (1..=100).map(|k| 4.0 * k as f64).collect();
/// let exact = Frd::from_model(&p, &f).unwrap();
/// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr()).collect();
/// let frd = Frd::new(f.clone(), exact.values().to_vec(), Some(var), Some(ts)).unwrap();
/// let b = bound_and_weight(&p, &frd, &ExtraTerms::default(), None, &UncertaintyOptions::default(), 4, 1.0)
///     .unwrap();
/// assert!(b.weight.weight.order() <= 4 && b.joint_raise >= 1.0);
/// let w = b.weight.weight.magnitude(&f);
/// assert!(w.iter().zip(&b.terms.multiplicative).all(|(w, l)| *w >= *l * (1.0 - 1e-9)));
/// ```
pub fn bound_and_weight(
    nominal: &StateSpace,
    frd: &Frd,
    extra: &ExtraTerms<'_>,
    shift: Option<ShiftLines<'_>>,
    opts: &UncertaintyOptions,
    max_weight_order: usize,
    cover: f64,
) -> Result<UncertainBound> {
    // the 1×1 case of the matrix bound: the same terms as `uncertainty`, and the projection
    let mut u = uncertainty_matrix(nominal, frd, std::slice::from_ref(extra), opts)
        .context("the uncertainty terms")?;
    let amplitude_projected = shift.map(|s| {
        s.on_lines(frd.f_hz())
            .and_then(|(sh, v)| Ok(u.add_projected_shift(frd, &[sh], &[v], AMPLITUDE_RUN_ALPHA)?))
            .map_err(|e| e.to_string())
    });
    // the matrix bound stays with the result: the coherent draws come from it when a
    // controller is checked (`robust_checks`)
    let terms = u
        .entries
        .first()
        .cloned()
        .ok_or_else(|| Error::other("the uncertainty terms: the bound has no entry"))?;
    let ts = nominal
        .ts()
        .ok_or_else(|| Error::other("the nominal model must be discrete-time"))?;
    let bound = floored(&terms.multiplicative);
    let mut weight = fit_weight_shaped(
        &terms.f_hz,
        &bound,
        ts,
        max_weight_order.min(MAX_WEIGHT_ORDER),
        cover,
        opts.weight_shape,
    )
    .context("fitting the uncertainty weight")?;
    // the weight's and the bound's joint factors from one set of draws
    let factors = terms
        .errors
        .joint_factors(
            &[&weight.weight.magnitude(&terms.f_hz), &bound],
            opts.raise_cover,
            opts.run_coverage,
            opts.draws,
            opts.seed,
        )
        .context("the joint coverage of the weight and the bound")?;
    let (joint_raise, lines_raise) = (factors[0].max(1.0), factors[1].max(1.0));
    weight.raise(joint_raise, &terms.f_hz, &bound);
    Ok(UncertainBound {
        matrix: u,
        seed: opts.seed,
        terms,
        weight,
        joint_raise,
        lines_raise,
        amplitude_projected,
    })
}

/// Term (d) of the bound around the model `nominal` on the lines `f_hz`: [`operating_spread`]
/// with $|\hat P(f_k)|$ evaluated from the model.
///
/// # Errors
/// Those of [`operating_spread`], or a model that cannot be evaluated on the lines.
pub fn operating_term(plants: &[Frd], f_hz: &[f64], nominal: &StateSpace) -> Result<Vec<f64>> {
    operating_spread(plants, f_hz, &model_abs(nominal, f_hz)?)
}

/// Term (d) of the bound on the lines `f_hz` from an operating-point study's plant FRFs
/// `plants` (the nominal case first, all on the same lines): per study line $j$, the largest
/// distance of another case from the nominal one, corrected for the two estimates' noise where
/// they carry variances,
/// $$ r_j = \max_{c \ge 1} \frac{\sqrt{\max(0,\ |P_{c,j} - P_{0,j}|^2 - \sigma_{c,j}^2 -
///    \sigma_{0,j}^2)}}{|P_{0,j}|} , $$
/// carried to `f_hz` by linear interpolation of $r$ in frequency (the end line's value outside
/// the study's band) and scaled by `nominal_abs` $= |\hat P(f_k)|$: $s_k = r(f_k)\,|\hat P(f_k)|$.
/// The relative spread is what moves from one set of lines to another: the study and the
/// identification record need not share lines or a nominal estimate.
///
/// # Errors
/// Fewer than two plants, plants on other lines than the nominal one's, no line, lengths of
/// `f_hz` and `nominal_abs` that differ, or a nominal value of zero.
///
/// # Example
/// ```
/// use ambid::uncertainty::operating_spread;
/// use ambid_core::{c64, lti::Frd};
/// let f = vec![10.0, 20.0, 30.0];
/// let nom = Frd::new(f.clone(), vec![c64::new(1.0, 0.0); 3], None, Some(1e-3)).unwrap();
/// let hi = Frd::new(f.clone(), vec![c64::new(1.1, 0.0); 3], None, Some(1e-3)).unwrap();
/// let s = operating_spread(&[nom, hi], &[5.0, 15.0], &[2.0, 2.0]).unwrap();
/// assert!((s[0] - 0.2).abs() < 1e-12 && (s[1] - 0.2).abs() < 1e-12);
/// ```
pub fn operating_spread(plants: &[Frd], f_hz: &[f64], nominal_abs: &[f64]) -> Result<Vec<f64>> {
    let Some((nom, others)) = plants.split_first() else {
        return Err(Error::other(
            "an operating-point spread needs the nominal plant and another",
        ));
    };
    if others.is_empty() || nom.is_empty() {
        return Err(Error::other(
            "an operating-point spread needs the nominal plant and at least one other, on at least one line",
        ));
    }
    if f_hz.len() != nominal_abs.len() {
        return Err(Error::other(format!(
            "{} lines but {} nominal magnitudes",
            f_hz.len(),
            nominal_abs.len()
        )));
    }
    let g0 = nom.values();
    let v0 = nom.variance();
    let mut rel = vec![0.0f64; nom.len()];
    for p in others {
        if p.f_hz() != nom.f_hz() {
            return Err(Error::other(
                "the operating points' plant FRFs are on other lines than the nominal one's; estimate them with the same excitation",
            ));
        }
        for (j, r) in rel.iter_mut().enumerate() {
            if g0[j].norm() == 0.0 {
                return Err(Error::other(format!(
                    "the nominal plant FRF is zero at {} Hz",
                    nom.f_hz()[j]
                )));
            }
            let noise = v0.map_or(0.0, |v| v[j]) + p.variance().map_or(0.0, |v| v[j]);
            let d = ((p.values()[j] - g0[j]).norm_sqr() - noise).max(0.0).sqrt();
            *r = r.max(d / g0[j].norm());
        }
    }
    Ok(carry_relative(nom.f_hz(), &rel, f_hz, nominal_abs))
}

/// $|\hat P(f_k)|$ of the model on the lines `f_hz`, which the relative terms (c)–(e) are scaled by.
fn model_abs(nominal: &StateSpace, f_hz: &[f64]) -> Result<Vec<f64>> {
    Ok(nominal
        .freq_response_siso(f_hz)?
        .iter()
        .map(|p| p.norm())
        .collect())
}

/// A relative term `rel` on the study's lines `fs` carried to the lines `f_hz` by linear
/// interpolation in frequency (the end line's value outside the study's band) and scaled by
/// `nominal_abs` $= |\hat P(f_k)|$.
fn carry_relative(fs: &[f64], rel: &[f64], f_hz: &[f64], nominal_abs: &[f64]) -> Vec<f64> {
    f_hz.iter()
        .zip(nominal_abs)
        .map(|(&f, &m)| {
            let i = fs.partition_point(|&x| x < f);
            let r = if i == 0 {
                rel[0]
            } else if i >= fs.len() {
                rel[fs.len() - 1]
            } else {
                let t = (f - fs[i - 1]) / (fs[i] - fs[i - 1]);
                rel[i - 1] + t * (rel[i] - rel[i - 1])
            };
            r * m
        })
        .collect()
}

/// The test level of term (c)'s groups ([`BlaEstimate::nl_groups`]) and of its upper value.
pub const NONLINEAR_ALPHA: f64 = 0.05;

/// Term (c)'s input on the lines `f_hz` and how it was obtained ([`nonlinear_term`]).
#[derive(Debug, Clone, PartialEq)]
pub struct NonlinearTerm {
    /// $\sigma_{\mathrm{nl},k}$ on the lines `f_hz` (0 where no group is significant).
    pub std: Vec<f64>,
    /// The BLA's groups of lines, their test and upper values (relative, before the scale).
    pub groups: Vec<NlGroup>,
    /// The factor the relative variances were multiplied by (the level rule of
    /// [`nonlinear_level`]; 1 when the BLA was measured at or above the identification level).
    pub variance_scale: f64,
}

impl NonlinearTerm {
    /// Groups whose nonlinear variance is significant.
    pub fn significant_groups(&self) -> usize {
        self.groups.iter().filter(|g| g.significant).count()
    }
}

/// Term (c)'s input on the lines `f_hz`: the standard deviation $\sigma_{\mathrm{nl},k}$ of the
/// stochastic nonlinear contributions of one experiment, from a robust BLA measurement `bla`
/// (the plant's [`BlaEstimate`], `ambid bla --level` or the workflow's `bla` step).
///
/// One realisation's relative nonlinear variance $\hat\sigma^2_S/|\hat G|^2$ is far too noisy
/// line by line ($M - 1$ complex degrees of freedom, 7 at the default $M = 8$) to be a bound, and
/// its noise is as often positive as negative; so it is tested in groups of neighbouring lines
/// (at least a third of a decade and 4 lines, [`BlaEstimate::nl_groups`]) at level
/// [`NONLINEAR_ALPHA`] split over the groups. On the lines of a significant group the relative
/// standard deviation is $\sqrt{c\,(\bar r + z_{0.95}\,s)}$ (the group's one-sided 95 % upper
/// value, times the level scale $c$ = `variance_scale`), elsewhere 0: a BLA whose distortion is
/// not distinguishable from its noise adds nothing (the FRF's own noise is term (a)). The
/// relative values are carried to `f_hz` as term (d)'s (linear interpolation in frequency, the
/// end line's value outside the BLA's band) and scaled by $|\hat P(f_k)|$.
///
/// # Errors
/// A `variance_scale` that is not finite and positive, a BLA whose lines are not finite and
/// ascending, or the errors of [`BlaEstimate::nl_groups`] and of evaluating the model.
///
/// # Example
/// ```
/// use ambid::uncertainty::{nonlinear_term, NONLINEAR_ALPHA};
/// use ambid_core::{c64, frf::bla::BlaEstimate, lti::StateSpace};
/// use faer::mat;
/// let m = StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[0.5]], mat![[0.0]], 1e-3).unwrap();
/// // 8 lines 20..160 Hz, |G| = 2, one realisation's NL variance 4 % of |G|², exact variances
/// let (mm, p) = (8usize, 4usize);
/// let est = BlaEstimate {
///     lines: (1..=8).collect(),
///     f_hz: (1..=8).map(|k| 20.0 * k as f64).collect(),
///     values: vec![c64::new(2.0, 0.0); 8],
///     var_total: vec![0.16 / mm as f64 + 1e-4; 8],
///     var_noise: vec![1e-4; 8],
///     var_nl: vec![0.16; 8],
///     realisations: mm,
///     periods: p,
/// };
/// let t = nonlinear_term(&est, 1.0, &[50.0], &m, NONLINEAR_ALPHA).unwrap();
/// assert_eq!(t.significant_groups(), t.groups.len());
/// let g = t.groups[0];
/// let p50 = m.freq_response_siso(&[50.0]).unwrap()[0].norm();
/// assert!((t.std[0] / p50 - g.upper_rel.sqrt()).abs() < 1e-12);
/// assert!(g.upper_rel > 0.04);
/// ```
pub fn nonlinear_term(
    bla: &BlaEstimate,
    variance_scale: f64,
    f_hz: &[f64],
    nominal: &StateSpace,
    alpha: f64,
) -> Result<NonlinearTerm> {
    let bad = |why: String| Error::other(format!("the nonlinear term: {why}"));
    if !(variance_scale.is_finite() && variance_scale > 0.0) {
        return Err(bad(format!(
            "the level scale {variance_scale} is not a finite, positive number"
        )));
    }
    let fs = &bla.f_hz;
    if fs.iter().any(|f| !f.is_finite()) || fs.windows(2).any(|w| w[1] <= w[0]) {
        return Err(bad(
            "the BLA's frequencies must be finite and ascending".into()
        ));
    }
    let groups = bla.nl_groups(alpha).map_err(|e| bad(e.to_string()))?;
    let mut rel = Vec::with_capacity(fs.len());
    for g in &groups {
        let r = if g.significant {
            (variance_scale * g.upper_rel).sqrt()
        } else {
            0.0
        };
        rel.extend(std::iter::repeat_n(r, g.lines));
    }
    Ok(NonlinearTerm {
        std: carry_relative(fs, &rel, f_hz, &model_abs(nominal, f_hz)?),
        groups,
        variance_scale,
    })
}

/// Which of a BLA study's levels feeds term (c) for an identification experiment at level
/// `ident` (the same unit as `levels`), and the factor its relative nonlinear variance is
/// scaled by: the lowest level at or above `ident`, unscaled (the distortion grows with the
/// level, so it is not understated); when every level is below `ident`, the highest, scaled by
/// $(a_\text{ident}/a)^4$ (an odd, smooth nonlinearity's relative distortion variance grows with
/// the fourth power of the amplitude to leading order, the rule term (e) extrapolates by).
/// `None` when no level is a finite, positive number.
///
/// # Example
/// ```
/// use ambid::uncertainty::nonlinear_level;
/// assert_eq!(nonlinear_level(&[2.0, 4.0, 8.0, 16.0], 5.0), Some((2, 1.0)));
/// assert_eq!(nonlinear_level(&[2.0, 4.0], 8.0), Some((1, 16.0)));
/// assert_eq!(nonlinear_level(&[], 8.0), None);
/// ```
pub fn nonlinear_level(levels: &[f64], ident: f64) -> Option<(usize, f64)> {
    let ok = |l: f64| l.is_finite() && l > 0.0;
    let above = (0..levels.len())
        .filter(|&i| ok(levels[i]) && levels[i] >= ident)
        .min_by(|&a, &b| levels[a].total_cmp(&levels[b]));
    if let Some(i) = above {
        return Some((i, 1.0));
    }
    let i = (0..levels.len())
        .filter(|&i| ok(levels[i]))
        .max_by(|&a, &b| levels[a].total_cmp(&levels[b]))?;
    Some((i, (ident / levels[i]).powi(4)))
}

/// Term (e) of the bound around the model `nominal` on the lines `f_hz`: the systematic shift of
/// the best linear approximation (BLA) at the identification experiment's excitation level
/// `level` from its extrapolation to zero amplitude, from an amplitude study's plant FRFs
/// `levels` (level, FRF with variances; two or more distinct levels, all on the same lines, in
/// the same unit as `level`, e.g. the fraction of $i_\text{sat}$).
///
/// A magnetic bearing's force is not linear in current and gap, so the FRF of an experiment
/// converges to the BLA at its amplitude, not to the small-signal linearisation a controller is
/// designed on; the model fits that BLA, so terms (a) and (b) cannot see the difference. For an
/// odd, smooth nonlinearity the BLA moves with the square of the amplitude to leading order (the
/// rule of [`ambid_core::estimate::graybox::extrapolate_to_zero_amplitude`]), so per study line
/// $j$ the weighted line $G_{i,j} = G_{0,j} + c_j a_i^2$ (weights $1/\sigma_{i,j}^2$) gives the
/// shift at the level $a_e$ relative to the model and its variance
/// $$ \rho_j = \frac{c_j a_e^2}{\hat P(f_j)}, \qquad v_j = \frac{a_e^4}{S_{xx,j}\,|\hat P(f_j)|^2},
///    \qquad S_{xx,j} = \sum_i \frac{(a_i^2 - \bar x_j)^2}{\sigma_{i,j}^2} . $$
/// (the model, not the noisy $G_{0,j}$, in the denominator keeps $\rho_j$ linear in the data and
/// its noise Gaussian: a ratio of two noisy FRFs has heavy tails where the noise is large). The
/// shift is smooth in frequency while each line's estimate is about as noisy as the FRF,
/// so it is averaged over the windows of term (b): $2M + 1$ lines ($M$ from the model's
/// sharpest resonance) and the wider ones of
/// [`window_scales`] ($M, 2M, 4M, \dots$, at
/// most $S = 6$ scales, none wider than a quarter of the lines). Per window, the plain mean
/// $\bar\rho_j$ with the pooled variance $\bar v_j = \sum_i v_i / (2M'+1)^2$ (weights $1/v_i$
/// would let one line whose variance estimate came out low take the window over: on random rigs
/// of the *linear* twin that gave terms as large as the plant on single lines where the FRF's
/// noise exceeds it). Where it is significant, $|\bar\rho_j|^2 > \ln(W S/\alpha_e)\,\bar v_j$
/// with $W = L/(2M'+1)$ independent windows among the $L$ lines and $\alpha_e$ =
/// [`AMPLITUDE_RUN_ALPHA`] (meant to give a plant whose BLA does not move a term anywhere in
/// about 5 % of the runs; measured on random rigs 101–200 of the *linear* twin with each rig's
/// own noise and levels 5 %, 10 %, 16 %: 23 of 100 runs, 29 with the one window alone, mostly
/// on a few lines: the FRFs' errors are correlated over lines, docs/uncertainty.md), the window
/// gives its upper bound at `line_coverage`, $|\bar\rho_j| +
/// \sqrt{\bar v_j \ln(1/(1 - c))}$ (the quantile of the circular complex noise, added by the
/// triangle inequality); $r_j$ is the largest over the scales, 0 where none is significant. A
/// window wider than $2M + 1$ lines is used only where every level's FRF has a relative
/// standard deviation of at most [`AMPLITUDE_WIDE_REL_STD`] on all its lines.
/// (With the one window of $2M + 1$ lines, the workflow's `uncertainty` step on the nonlinear
/// twin, random rigs 1–100, missed the BLA's shift above about 140 Hz, where it lies below
/// one window's noise, and the weight covered the linearisation's error on only 73 of 100;
/// docs/uncertainty.md.)
/// $r$ is carried to `f_hz` as term (d) is and scaled by $|\hat P(f_k)|$, except above the
/// study's top line, where it is 0: no window saw those lines, and holding the top line's value
/// there carried a false positive of the windows' test at the study's noisiest lines over the
/// whole rest of the band (random rig 336 of the nonlinear twin, PRBS, whose models' band
/// reaches 1255 Hz while the twin's study ends at 1000 Hz: a held 0.11–0.135 of $|\hat P|$
/// against a true error of 0.002–0.009 made the order-4 weight report 1.6 % less than half the
/// true gain margin; the same held value appeared on the *linear* twin's rigs 334, 343, 361;
/// docs/uncertainty.md, "Unseen rigs 301–400"). Above the study's band a caller carries the
/// shift by its projection through the model
/// ([`MatrixUncertainty::add_projected_shift`](ambid_core::validate::uncertainty::MatrixUncertainty::add_projected_shift)),
/// which the model's dynamics extend beyond the measured lines. Below the study's bottom line
/// the end value is still held (the rigid-body band, where the shift is largest and smooth).
/// A curvature beyond $a^2$ over the study's levels is not modelled: keep the levels within the
/// range where the amplitude study's coherence is not yet saturated by distortion.
///
/// # Errors
/// Fewer than two distinct levels, a level that is not finite and positive, FRFs on other lines
/// than the first one's or without finite, positive variances, a model response of zero, a
/// `line_coverage` outside (0, 1), or a model that is not discrete-time — each message names
/// the fix.
///
/// # Example
/// ```
/// use ambid::uncertainty::amplitude_term;
/// use ambid_core::{c64, lti::{Frd, StateSpace}};
/// use faer::mat;
/// let f: Vec<f64> = (1..=50).map(|k| k as f64 * 4.0).collect();
/// // the BLA 1 % below the plant 1 at level 0.1 and 4 % below it at level 0.2
/// let at = |a: f64| {
///     let g = vec![c64::new(1.0 - a * a, 0.0); 50];
///     Frd::new(f.clone(), g, Some(vec![1e-8; 50]), Some(1e-3)).unwrap()
/// };
/// let (lo, hi) = (at(0.1), at(0.2));
/// let m = StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[0.5]], mat![[0.0]], 1e-3).unwrap();
/// let nominal_abs = m.freq_response_siso(&f).unwrap()[10].norm();
/// let e = amplitude_term(&[(0.1, &lo), (0.2, &hi)], 0.1, &f, &m, 0.95).unwrap();
/// assert!((e[10] / nominal_abs - 0.01).abs() < 1e-3); // the 1 % shift at level 0.1
/// // lines beyond the study's top line (200 Hz) get no line term; below its first, the end value
/// let wider = [2.0, 100.0, 200.0, 204.0, 260.0];
/// let e = amplitude_term(&[(0.1, &lo), (0.2, &hi)], 0.1, &wider, &m, 0.95).unwrap();
/// assert!(e[0] > 0.0 && e[1] > 0.0 && e[2] > 0.0);
/// assert_eq!((e[3], e[4]), (0.0, 0.0));
/// ```
/// The per-line regression of [`amplitude_term`]: on every line $j$ of the study's FRFs
/// `levels` (level, FRF with variances; two or more distinct levels on the same lines) the
/// weighted line $G_{i,j} = G_{0,j} + c_j a_i^2$, and the shift at the identification level
/// `level`, $c_j a_e^2$ (absolute, complex), with its variance $\kappa\,a_e^4/S_{xx,j}$ (of a
/// circular complex error). [`amplitude_term`] averages it over windows;
/// [`MatrixUncertainty::add_projected_shift`](ambid_core::validate::uncertainty::MatrixUncertainty::add_projected_shift)
/// projects it onto the model. Both are sums over neighbouring lines, and the lines of a
/// windowed (Welch) FRF share noise: the variance of such a sum is about $\kappa$ times the sum
/// of the per-line variances. $\kappa$ is
/// [`line_correlation`](ambid_core::validate::uncertainty::line_correlation)'s factor (its
/// lag-1 and lag-2 correlations, kept when significant and short-range, else 1) read on the
/// regression's normalised residuals $(G_{i,j} - \hat G_{0,j} - \hat c_j a_i^2)/
/// \sqrt{\sigma_{i,j}^2(1 - h_{i,j})}$ of every level ($h$ the leverage), which a shift linear in
/// $a^2$ does not enter; with two levels (no residual) it is 1. Periodic FRFs have independent
/// lines and $\kappa = 1$; on the twin's noise excitation (Welch, Hann, 50 % overlap) it is
/// about 2, and without it term (e)'s test took the shared noise for a shift on the linear
/// twin, whose BLA does not move (docs/uncertainty.md, "Term (e) on a Welch FRF").
///
/// # Errors
/// As [`amplitude_term`] for the levels.
///
/// # Example
/// ```
/// use ambid::uncertainty::amplitude_shift_lines;
/// use ambid_core::{c64, lti::Frd};
/// let f: Vec<f64> = (1..=20).map(|k| k as f64).collect();
/// let at = |a: f64| Frd::new(f.clone(), vec![c64::new(1.0 - a * a, 0.0); 20], Some(vec![1e-8; 20]), Some(1e-3)).unwrap();
/// let (lo, hi) = (at(0.1), at(0.2));
/// let (s, v) = amplitude_shift_lines(&[(0.1, &lo), (0.2, &hi)], 0.1).unwrap();
/// assert!((s[3] - c64::new(-0.01, 0.0)).norm() < 1e-9 && v[3] > 0.0);
/// ```
pub fn amplitude_shift_lines(levels: &[(f64, &Frd)], level: f64) -> Result<(Vec<c64>, Vec<f64>)> {
    let bad = |why: String| Error::other(format!("the amplitude term: {why}"));
    if !(level.is_finite() && level > 0.0) {
        return Err(bad(format!(
            "the identification experiment's level {level} is not a positive number: give its excitation amplitude in the unit of the study's levels"
        )));
    }
    let Some(((_, first), _)) = levels.split_first() else {
        return Err(bad(
            "no level: record the plant FRF at two or more excitation levels".into(),
        ));
    };
    let fs = first.f_hz();
    let mut x = Vec::with_capacity(levels.len());
    for (a, frd) in levels {
        if !(a.is_finite() && *a > 0.0) {
            return Err(bad(format!(
                "the level {a} is not a positive number: give each FRF's excitation amplitude"
            )));
        }
        if frd.f_hz() != fs {
            return Err(bad(format!(
                "the FRF at level {a} is on other lines than the one at level {}: record every level with the same excitation (period, band)",
                levels[0].0
            )));
        }
        match frd.variance() {
            Some(v) if v.iter().all(|v| v.is_finite() && *v > 0.0) => {}
            _ => {
                return Err(bad(format!(
                    "the FRF at level {a} has no finite, positive variances: estimate it from two or more periods"
                )))
            }
        }
        x.push(a * a);
    }
    let (xlo, xhi) = x
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, h), v| (l.min(*v), h.max(*v)));
    if levels.len() < 2 || xhi - xlo <= 1e-9 * xhi {
        return Err(bad(
            "the extrapolation to zero amplitude needs the plant FRF at two or more distinct levels".into(),
        ));
    }
    let ae2 = level * level;
    let l = fs.len();
    let (mut shift, mut var) = (Vec::with_capacity(l), Vec::with_capacity(l));
    // per level, the regression's residuals and their variances (for the lines' correlation)
    let mut resid: Vec<(Vec<ambid_core::c64>, Vec<f64>)> =
        vec![(Vec::with_capacity(l), Vec::with_capacity(l)); levels.len()];
    // per line, each level's value and variance (checked finite and positive above)
    let mut pts: Vec<(ambid_core::c64, f64)> = Vec::with_capacity(levels.len());
    for j in 0..l {
        pts.clear();
        pts.extend(
            levels
                .iter()
                .map(|(_, frd)| (frd.values()[j], frd.variance().map_or(1.0, |v| v[j]))),
        );
        let (mut sw, mut sx, mut sy) = (0.0, 0.0, ambid_core::c64::new(0.0, 0.0));
        for ((g, v), xi) in pts.iter().zip(&x) {
            let w = 1.0 / v;
            sw += w;
            sx += w * xi;
            sy += g * w;
        }
        let (xm, ym) = (sx / sw, sy / sw);
        let (mut sxx, mut sxy) = (0.0, ambid_core::c64::new(0.0, 0.0));
        for ((g, v), xi) in pts.iter().zip(&x) {
            let w = 1.0 / v;
            sxx += w * (xi - xm) * (xi - xm);
            sxy += (g - ym) * (w * (xi - xm));
        }
        let slope = sxy / sxx;
        for (((g, v), xi), r) in pts.iter().zip(&x).zip(&mut resid) {
            // the residual's variance: the level's times 1 − its leverage
            let h = (1.0 / sw + (xi - xm) * (xi - xm) / sxx) / v;
            r.0.push(g - ym - slope * (xi - xm));
            r.1.push((v * (1.0 - h)).max(f64::MIN_POSITIVE));
        }
        shift.push(slope * ae2);
        var.push(ae2 * ae2 / sxx);
    }
    // neighbouring lines of a windowed (Welch) estimate share noise: the variance of a smooth
    // average over the lines is κ times the per-line one's (`line_correlation`'s rule, read on
    // the residuals, which no shift linear in a² enters; 1 for independent lines)
    let entries: Vec<(&[ambid_core::c64], &[f64])> = resid
        .iter()
        .map(|(r, v)| (r.as_slice(), v.as_slice()))
        .collect();
    let kappa = if levels.len() > 2 {
        ambid_core::validate::uncertainty::line_correlation(&entries).map_or(1.0, |c| c.factor)
    } else {
        1.0
    };
    var.iter_mut().for_each(|v| *v *= kappa);
    Ok((shift, var))
}

pub fn amplitude_term(
    levels: &[(f64, &Frd)],
    level: f64,
    f_hz: &[f64],
    nominal: &StateSpace,
    line_coverage: f64,
) -> Result<Vec<f64>> {
    Ok(amplitude_term_and_shifts(levels, level, f_hz, nominal, line_coverage)?.term)
}

/// Term (e) in both forms from one per-line regression: what [`amplitude_term`] returns and the
/// per-line shifts of [`amplitude_shift_lines`] for the projection through the model
/// ([`AmplitudeTerm::shift_lines`], [`analyse_with_shift`]).
#[derive(Debug, Clone, PartialEq)]
pub struct AmplitudeTerm {
    /// The windowed line term on the lines `f_hz` ([`amplitude_term`]).
    pub term: Vec<f64>,
    /// The study's lines \[Hz\].
    pub study_f_hz: Vec<f64>,
    /// The shift $c_j a_e^2$ per study line.
    pub shift: Vec<c64>,
    /// Its variance per study line.
    pub shift_var: Vec<f64>,
    /// The study lines the projection through the model uses: those where every level's FRF
    /// has a relative standard deviation of at most [`AMPLITUDE_PROJECTION_REL_STD`]
    /// ([`AmplitudeTerm::shift_lines`]).
    pub projected: Vec<bool>,
    /// `shift` and `shift_var` on the `projected` lines, 0 elsewhere.
    projected_shift: (Vec<c64>, Vec<f64>),
}

impl AmplitudeTerm {
    /// The per-line shifts for the projection through the model as [`ShiftLines`]: those of
    /// the [`projected`](AmplitudeTerm::projected) lines; a line where some level's FRF is
    /// noisier than [`AMPLITUDE_PROJECTION_REL_STD`] of $|\hat P|$ gets shift 0 with variance
    /// 0, so it adds nothing to the projection or its test (the reason is the constant's).
    pub fn shift_lines(&self) -> ShiftLines<'_> {
        ShiftLines {
            f_hz: &self.study_f_hz,
            shift: &self.projected_shift.0,
            var: &self.projected_shift.1,
        }
    }
}

/// [`amplitude_term`] that also keeps the per-line shifts it was computed from
/// ([`AmplitudeTerm`]), so a caller that projects them runs the regression once.
///
/// # Errors
/// As [`amplitude_term`].
///
/// # Example
/// ```
/// use ambid::uncertainty::{amplitude_term, amplitude_term_and_shifts};
/// use ambid_core::{c64, lti::{Frd, StateSpace}};
/// use faer::mat;
/// let f: Vec<f64> = (1..=50).map(|k| k as f64 * 4.0).collect();
/// let at = |a: f64| {
///     Frd::new(f.clone(), vec![c64::new(1.0 - a * a, 0.0); 50], Some(vec![1e-8; 50]), Some(1e-3))
///         .unwrap()
/// };
/// let (lo, hi) = (at(0.1), at(0.2));
/// let m = StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[0.5]], mat![[0.0]], 1e-3).unwrap();
/// let levels = [(0.1, &lo), (0.2, &hi)];
/// let both = amplitude_term_and_shifts(&levels, 0.1, &f, &m, 0.95).unwrap();
/// assert_eq!(both.term, amplitude_term(&levels, 0.1, &f, &m, 0.95).unwrap());
/// assert!((both.shift[3] - c64::new(-0.01, 0.0)).norm() < 1e-9);
/// assert_eq!(both.shift_lines().f_hz, &f[..]);
/// ```
pub fn amplitude_term_and_shifts(
    levels: &[(f64, &Frd)],
    level: f64,
    f_hz: &[f64],
    nominal: &StateSpace,
    line_coverage: f64,
) -> Result<AmplitudeTerm> {
    let bad = |why: String| Error::other(format!("the amplitude term: {why}"));
    if !(line_coverage > 0.0 && line_coverage < 1.0) {
        return Err(bad(format!(
            "the coverage per line must lie in (0, 1), got {line_coverage}"
        )));
    }
    let (shift, shift_var) = amplitude_shift_lines(levels, level)?;
    let fs = levels[0].1.f_hz();
    let l = fs.len();
    let p_study = nominal.freq_response_siso(fs)?;
    if let Some(j) = p_study
        .iter()
        .position(|p| !(p.norm() > 0.0 && p.norm().is_finite()))
    {
        return Err(bad(format!(
            "the model's response is zero or not finite at {} Hz",
            fs[j]
        )));
    }
    // relative to the model (noise-free), so that ρ stays linear in the data
    let rho: Vec<c64> = shift.iter().zip(&p_study).map(|(s, p)| s / p).collect();
    let var: Vec<f64> = shift_var
        .iter()
        .zip(&p_study)
        .map(|(v, p)| v / p.norm_sqr())
        .collect();
    let m_half = window_half_lines_for(nominal, fs)?;
    let halves = window_scales(m_half, l);
    let q = (1.0 / (1.0 - line_coverage)).ln();
    // the lines where every level's FRF has a relative standard deviation of at most `rel`
    let every_level_within = |rel: f64| -> Vec<bool> {
        (0..l)
            .map(|j| {
                levels.iter().all(|(_, frd)| {
                    frd.variance()
                        .is_some_and(|v| v[j].sqrt() <= rel * p_study[j].norm())
                })
            })
            .collect()
    };
    // lines where every level's FRF is precise enough for the wider windows (type docs)
    let precise = every_level_within(AMPLITUDE_WIDE_REL_STD);
    let mut rel = vec![0.0f64; l];
    for (s_idx, &half) in halves.iter().enumerate() {
        // the significance level per window: 5 % over the run's independent windows of every
        // scale
        let windows = (l as f64 / (2 * half + 1) as f64).max(1.0);
        let thr = (windows * halves.len() as f64 / AMPLITUDE_RUN_ALPHA).ln();
        for (j, r) in rel.iter_mut().enumerate() {
            let (lo, hi) = (j.saturating_sub(half), (j + half).min(l - 1));
            if s_idx > 0 && !precise[lo..=hi].iter().all(|&b| b) {
                continue;
            }
            // the plain mean and its pooled variance: a line whose variance estimate came out
            // low does not take the window over
            let n = (hi - lo + 1) as f64;
            let (mut sv, mut s) = (0.0, ambid_core::c64::new(0.0, 0.0));
            for i in lo..=hi {
                sv += var[i];
                s += rho[i];
            }
            let (mean, v) = (s / n, sv / (n * n));
            if mean.norm_sqr() > thr * v {
                *r = r.max(mean.norm() + (q * v).sqrt());
            }
        }
    }
    let mut term = carry_relative(fs, &rel, f_hz, &model_abs(nominal, f_hz)?);
    // above the study's top line the windows saw nothing: no line term there (type docs)
    let top = fs[l - 1];
    for (t, &f) in term.iter_mut().zip(f_hz) {
        if f > top {
            *t = 0.0;
        }
    }
    // the projection's lines: every level's FRF within AMPLITUDE_PROJECTION_REL_STD (type docs)
    let projected = every_level_within(AMPLITUDE_PROJECTION_REL_STD);
    let projected_shift = (0..l)
        .map(|j| {
            if projected[j] {
                (shift[j], shift_var[j])
            } else {
                (c64::new(0.0, 0.0), 0.0)
            }
        })
        .unzip();
    Ok(AmplitudeTerm {
        term,
        study_f_hz: fs.to_vec(),
        shift,
        shift_var,
        projected,
        projected_shift,
    })
}

/// The largest relative standard deviation $\sigma_{i,j}/|\hat P(f_j)|$ of any level's FRF on
/// the lines of a window wider than $2M + 1$ lines in [`amplitude_term`]. Where the noise is
/// of the plant's order, a closed-loop FRF's ratio estimate carries a bias that depends on the
/// level's signal-to-noise ratio; the wide windows average it over up to a quarter of the lines
/// and would read it as a shift (random rigs 101–200 of the nonlinear twin: terms of up to 0.8
/// relative at 2–3 kHz, and a looser weight).
pub const AMPLITUDE_WIDE_REL_STD: f64 = 0.5;

/// The largest relative standard deviation $\sigma_{i,j}/|\hat P(f_j)|$ of any level's FRF
/// on a line that term (e)'s projection through the model uses
/// ([`AmplitudeTerm::shift_lines`]). A closed-loop plant FRF is a ratio of two noisy averages,
/// $\bar Y/\bar U$, whose bias relative to the plant is of the order of its relative
/// variance and grows as a level's signal-to-noise ratio falls, so it changes from level to
/// level like a shift. The windows of [`amplitude_term`] test a few lines each, and a bias below
/// their noise passes; the projection is a weighted sum over every line, so the bias adds up
/// coherently while the noise averages, and its Wald test reads it as a shift. With the
/// workflow's logarithmic chirp (3 dB less power per octave) the test kept a projected shift on
/// 15–16 of random rigs 501–600 of the *linear* twin, whose plant does not move with the
/// amplitude, against its level of 5 %; on rigs 516, 547, 590 and 605 it put 1.5–2.9 % of
/// $|\hat P|$ into the bound at the median and the weight's upper gain margin fell below half
/// the true one. With every level within 10 % (a bias of about 1 %) the test kept 3 of rigs
/// 501–540, against 9 with [`AMPLITUDE_WIDE_REL_STD`] (0.5) and 7 with 0.2
/// (docs/uncertainty.md, "Other excitations"). Measured on 2 200 workflow runs with the weight's
/// corners floored at the lowest line (PRBS and noise rigs 1–500, chirp 501–700, multisine
/// 501–600, both twins): the true loop stable at 90 % of the weight's margins on all, the
/// margins at least half the true ones on all but 2 (8 before), 9 false positives of 100 on the
/// linear twin with the chirp (15–16 before) (docs/uncertainty.md, "Term (e)'s projection on
/// precise lines").
pub const AMPLITUDE_PROJECTION_REL_STD: f64 = 0.1;

/// The largest fraction of a level's samples with a limit active (controller or DAC clamp,
/// amplifier output or slew limit) for the level to enter term (e)'s regression
/// ([`amplitude_term`]; the workflow's `uncertainty` step and `[machine]`). The a² rule holds
/// for the smooth force law, not for a limit; but a limit that acts on a fraction $p$ of a
/// Gaussian-like signal's samples changes that signal's linear gain by about $p$ (Bussgang: the
/// best linear gain of a hard limiter is the probability of staying within it, $1 - p$), and the
/// twin's controller clamp, before the recorded $u$, does not enter $y/u$ at all. A level just
/// above the identification level is what makes the extrapolation precise: its variance there
/// is about $(a_e^2/(a_\text{top}^2 - a_e^2))^2$ times the top level's, and the amplitude
/// study picks the identification level among the levels without any saturated sample (on the
/// twin usually the highest), so with a threshold of 0 the levels above it were left out. The
/// same 1 % as the robust BLA study's [`crate::bla::MAX_SATURATED`]. Measured on the workflow's step (docs/uncertainty.md,
/// "Lightly saturated levels in term (e)"): random rigs 1–100 of the nonlinear twin, weight
/// coverage 98 → 99 of 100 and looseness 5.74 → 5.23; unseen rigs 201–300, 98 → 100 and
/// 5.94 → 5.32; the linear twin unchanged.
pub const AMPLITUDE_MAX_SATURATED: f64 = 0.01;

/// The probability that term (e) appears anywhere on a plant whose BLA does not move with the
/// amplitude ([`amplitude_term`]: the significance level per window is this over the number of
/// independent windows).
pub const AMPLITUDE_RUN_ALPHA: f64 = 0.05;

/// The orders a twin run's nominal model is chosen from (by BIC).
pub const TWIN_ORDERS: std::ops::RangeInclusive<usize> = 6..=12;

/// The band of a twin run's FRF and fit \[Hz\]: the seed excitation's lines up to 3 kHz (its
/// power falls to the sinc null at 4 kHz).
pub const TWIN_BAND_HZ: (f64, f64) = (3.0, 3000.0);

/// How [`UncertaintyRun::on_twin_weighted`] weights the nominal model's fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FitWeights {
    /// $1/\sigma_k^2$ with the FRF's variance at the data ([`FreqWeights::InverseVariance`];
    /// [`nominal_by_bic`]).
    AtData,
    /// The variance at the model ([`FreqWeights::SampleMaximumLikelihood`]; the default of
    /// [`UncertaintyRun::on_twin`] since the twenty-ninth session).
    AtModel,
}

/// `frd` with each line's variance evaluated at `model`'s response, $v_k(\hat P(z_k))$
/// ([`RatioNoise::variance_at`](ambid_core::frf::closed_loop::RatioNoise::variance_at)): the
/// variances a sample maximum-likelihood fit's bound takes.
///
/// # Errors
/// A `noise` of another length than `frd`, a model that is not SISO, or a line where the
/// variance at the model is 0 (a model value where the noise vanishes).
///
/// # Example
/// Output noise only: the variance does not depend on the model.
/// ```
/// use ambid::uncertainty::variances_at_model;
/// use ambid_core::c64;
/// use ambid_core::frf::closed_loop::RatioNoise;
/// use ambid_core::lti::{Frd, StateSpace};
/// use faer::mat;
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let m = StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 1e-3)?;
/// let f = [10.0, 20.0];
/// let frd = Frd::new(f.to_vec(), m.freq_response_siso(&f)?, Some(vec![1.0, 1.0]), Some(1e-3))?;
/// let noise = [RatioNoise { a: 0.0, b: 0.5, c: c64::new(0.0, 0.0) }; 2];
/// let at = variances_at_model(&frd, &noise, &m)?;
/// assert_eq!(at.variance().unwrap_or(&[]), &[0.5, 0.5]);
/// # Ok(())
/// # }
/// ```
pub fn variances_at_model(
    frd: &Frd,
    noise: &[ambid_core::frf::closed_loop::RatioNoise],
    model: &StateSpace,
) -> Result<Frd> {
    if noise.len() != frd.len() {
        return Err(Error::other(format!(
            "{} noise descriptions for {} lines",
            noise.len(),
            frd.len()
        )));
    }
    let p = model.freq_response_siso(frd.f_hz())?;
    let v: Vec<f64> = noise
        .iter()
        .zip(&p)
        .map(|(n, x)| n.variance_at(*x))
        .collect();
    if let Some(k) = v
        .iter()
        .position(|x| x.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater))
    {
        return Err(Error::other(format!(
            "the variance at the model vanishes on line {k} ({} Hz)",
            frd.f_hz()[k]
        )));
    }
    Ok(Frd::new(
        frd.f_hz().to_vec(),
        frd.values().to_vec(),
        Some(v),
        frd.ts(),
    )?)
}

/// The noise descriptions of `frd`'s lines out of `noise`, one per line of `f_hz` (an FRF and
/// its [`plant_noise`](ambid_core::frf::closed_loop::ClosedLoopFrf::plant_noise)), when `frd`
/// is a band of those lines ([`Frd::band`]): the description of every line of `f_hz` within
/// `frd`'s first and last frequency.
///
/// # Errors
/// `noise` of another length than `f_hz`, an empty `frd`, or a band whose line count differs
/// from `frd`'s (not a band of `f_hz`).
///
/// # Example
/// ```
/// use ambid::uncertainty::noise_on_lines;
/// use ambid_core::c64;
/// use ambid_core::frf::closed_loop::RatioNoise;
/// use ambid_core::lti::Frd;
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let f = [10.0, 20.0, 30.0, 40.0];
/// let noise: Vec<RatioNoise> =
///     f.iter().map(|&x| RatioNoise { a: 0.0, b: x, c: c64::new(0.0, 0.0) }).collect();
/// let all = Frd::new(f.to_vec(), vec![c64::new(1.0, 0.0); 4], None, Some(1e-3))?;
/// let band = all.band(15.0, 35.0)?;
/// let on = noise_on_lines(&f, &noise, &band)?;
/// assert_eq!(on.iter().map(|n| n.b).collect::<Vec<_>>(), vec![20.0, 30.0]);
/// # Ok(())
/// # }
/// ```
pub fn noise_on_lines(
    f_hz: &[f64],
    noise: &[ambid_core::frf::closed_loop::RatioNoise],
    frd: &Frd,
) -> Result<Vec<ambid_core::frf::closed_loop::RatioNoise>> {
    if noise.len() != f_hz.len() {
        return Err(Error::other(format!(
            "{} noise descriptions for {} lines",
            noise.len(),
            f_hz.len()
        )));
    }
    let (Some(&lo), Some(&hi)) = (frd.f_hz().first(), frd.f_hz().last()) else {
        return Err(Error::other("the FRF has no lines"));
    };
    let on: Vec<_> = f_hz
        .iter()
        .zip(noise)
        .filter(|(f, _)| (lo..=hi).contains(*f))
        .map(|(_, n)| *n)
        .collect();
    if on.len() != frd.len() {
        return Err(Error::other(format!(
            "the noise descriptions give {} lines in {lo}–{hi} Hz, the FRF {}",
            on.len(),
            frd.len()
        )));
    }
    Ok(on)
}

/// One run of the whole chain on the twin: the seed experiment on rig `rig` (0 = nominal) with
/// noise seed `seed`, the period-averaged plant FRF, the nominal model ([`nominal_by_bic_weighted`]:
/// the BIC choice among [`TWIN_ORDERS`] of sample maximum-likelihood frequency-domain
/// state-space fits with the loop's unstable pole count and a stable loop with the controller;
/// inverse-variance fits, [`nominal_by_bic`], with [`FitWeights::AtData`]), [`analyse`], and
/// the truth to check it against.
#[derive(Debug, Clone)]
pub struct UncertaintyRun {
    /// The measured plant FRF (with [`FitWeights::AtModel`], its variances at the nominal
    /// model).
    pub frd: Frd,
    /// The nominal model.
    pub nominal: StateSpace,
    /// The analysis.
    pub analysis: UncertaintyAnalysis,
    /// The twin's exact plant.
    pub truth_plant: StateSpace,
    /// The twin's controller.
    pub controller: StateSpace,
    /// The plant FRF's per-period deviations
    /// ([`ExperimentOutput::period_deviations`](crate::experiment::ExperimentOutput::period_deviations)).
    pub frf_periods: Vec<Vec<ambid_core::c64>>,
}

/// How well a run's bound and weight cover the true error (see [`UncertaintyRun::coverage`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coverage {
    /// Lines in the band.
    pub lines: usize,
    /// Fraction of them where $\ell_k \ge |P - \hat P| / |\hat P|$.
    pub bound_coverage: f64,
    /// Fraction where $|W| \ge |P - \hat P| / |\hat P|$.
    pub weight_coverage: f64,
    /// Median of the true relative error.
    pub median_error: f64,
    /// Median of $|W|$.
    pub median_weight: f64,
    /// Median of $|W|$ over the median of the true relative error.
    pub median_ratio: f64,
}

impl UncertaintyRun {
    /// Runs the chain on the twin (type docs).
    ///
    /// # Errors
    /// Any step's error.
    pub fn on_twin(rig: u64, seed: u64, mode: Mode) -> Result<Self> {
        Self::on_twin_with_levels(rig, seed, mode, &[])
    }

    /// [`UncertaintyRun::on_twin`] with an amplitude study: the seed experiment repeated at each
    /// of `levels` (fractions of $i_\text{sat}$; level $l$ from 0 with noise seed
    /// `seed + 1000 (l + 1)`), which with the seed experiment's own FRF at its level give term
    /// (e) ([`amplitude_term`]). No level: no term, the same run as [`UncertaintyRun::on_twin`].
    ///
    /// # Errors
    /// Those of [`UncertaintyRun::on_twin`], a level's run (named) and [`amplitude_term`].
    pub fn on_twin_with_levels(rig: u64, seed: u64, mode: Mode, levels: &[f64]) -> Result<Self> {
        Self::on_twin_weighted(rig, seed, mode, levels, FitWeights::AtModel)
    }

    /// [`UncertaintyRun::on_twin_with_levels`] with the nominal model's fits weighted as
    /// `weights` says. With [`FitWeights::AtModel`] the fits and the BIC take each line's
    /// variance at the model ([`nominal_by_bic_weighted`] with sample maximum-likelihood weights
    /// and the estimate's
    /// [`plant_noise`](ambid_core::frf::closed_loop::ClosedLoopFrf::plant_noise)), and the
    /// run's [`frd`](Self::frd) carries the variances at the chosen model, which the bound uses;
    /// term (f)'s reference is then the SML fit too ([`ExtraTerms::fit_noise`]), 0 for the
    /// nominal (an inverse-variance reference fit would measure the weights' pull itself: a
    /// median of 0.45 % of $|\hat P|$ on linear rigs 101–200; docs/uncertainty.md, "Weights
    /// that follow the data's noise").
    ///
    /// # Errors
    /// Those of [`UncertaintyRun::on_twin_with_levels`].
    pub fn on_twin_weighted(
        rig: u64,
        seed: u64,
        mode: Mode,
        levels: &[f64],
        weights: FitWeights,
    ) -> Result<Self> {
        let (out, cl) =
            twin_seed_closed_loop(rig, seed, mode, ExcitationPlan::default().amplitude_frac)?;
        let measured = cl.plant;
        let frf_periods = out
            .period_deviations(&measured)
            .context("the FRF's periods")?;
        let controller = out.twin.controller().clone();
        let noise = match weights {
            FitWeights::AtData => None,
            FitWeights::AtModel => Some(
                cl.plant_noise
                    .ok_or_else(|| Error::other("the periodic estimate has no noise per line"))?,
            ),
        };
        let (nominal, frd) = match &noise {
            None => (nominal_by_bic(&measured, &controller)?, measured),
            Some(noise) => {
                let unstable = unstable_poles_from_loop(&measured, &controller, None).ok();
                let nominal = nominal_by_bic_weighted(
                    &measured,
                    FreqWeights::SampleMaximumLikelihood(noise.clone()),
                    unstable,
                    TWIN_ORDERS,
                    Some(&controller),
                )?;
                let frd = variances_at_model(&measured, noise, &nominal)?;
                (nominal, frd)
            }
        };
        let own = ExcitationPlan::default().amplitude_frac;
        let mut study = vec![(own, frd.clone())];
        for (l, &a) in levels.iter().enumerate() {
            let (_, g) = twin_seed_frf_at(rig, seed.wrapping_add(1000 * (l as u64 + 1)), mode, a)
                .with_context(|| format!("the run at level {a}"))?;
            study.push((a, g));
        }
        // term (e): the line term and the per-line shifts for its projection through the model
        let amplitude = if levels.is_empty() {
            None
        } else {
            let refs: Vec<(f64, &Frd)> = study.iter().map(|(a, g)| (*a, g)).collect();
            let opts = UncertaintyOptions::default();
            Some(amplitude_term_and_shifts(
                &refs,
                own,
                frd.f_hz(),
                &nominal,
                opts.line_coverage,
            )?)
        };
        let analysis = analyse_with_shift(
            &nominal,
            &frd,
            &controller,
            &ExtraTerms {
                amplitude_shift: amplitude.as_ref().map(|a| a.term.as_slice()),
                // term (f)'s reference is the FRF's fit under the nominal's own criterion
                fit_noise: noise.as_deref(),
                ..ExtraTerms::default()
            },
            amplitude.as_ref().map(AmplitudeTerm::shift_lines),
            &UncertaintyOptions::default(),
            MAX_WEIGHT_ORDER,
            DEFAULT_COVER,
        )?;
        Ok(Self {
            frd,
            nominal,
            analysis,
            truth_plant: out.twin.plant().clone(),
            controller,
            frf_periods,
        })
    }

    /// The coverage of the true relative error on the lines of `band_hz`.
    ///
    /// # Errors
    /// When the true plant's response cannot be evaluated on the lines.
    pub fn coverage(&self, band_hz: (f64, f64)) -> Result<Coverage> {
        let t = &self.analysis.terms;
        let idx: Vec<usize> = (0..t.f_hz.len())
            .filter(|&k| (band_hz.0..=band_hz.1).contains(&t.f_hz[k]))
            .collect();
        let f: Vec<f64> = idx.iter().map(|&k| t.f_hz[k]).collect();
        let truth = self.truth_plant.freq_response_siso(&f)?;
        let w = self.analysis.weight.weight.magnitude(&f);
        let mut err = Vec::with_capacity(f.len());
        let (mut cb, mut cw) = (0usize, 0usize);
        for (i, &k) in idx.iter().enumerate() {
            let e = (truth[i] - t.nominal[k]).norm() / t.nominal[k].norm();
            cb += usize::from(t.multiplicative[k] >= e);
            cw += usize::from(w[i] >= e);
            err.push(e);
        }
        let med = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
        };
        let n = f.len().max(1) as f64;
        let (me, mw) = (med(&mut err), med(&mut w.clone()));
        Ok(Coverage {
            lines: f.len(),
            bound_coverage: cb as f64 / n,
            weight_coverage: cw as f64 / n,
            median_error: me,
            median_weight: mw,
            median_ratio: mw / me,
        })
    }
}

/// Twin rig `rig`: 0 the nominal one, else `random_rig(rig)`.
fn twin_rig(rig: u64) -> Result<TwinConfig> {
    Ok(if rig == 0 {
        TwinConfig::default()
    } else {
        random_rig(rig).context("drawing the rig")?
    })
}

/// A Gaussian-noise experiment on twin rig `rig` (0 = nominal, else `random_rig(rig)`) with
/// noise seed `seed` (sensor noise on when `sensor_noise`), and its plant FRF by the Welch
/// defaults of `ambid frf` (Hann, [`FrfSettings::default_nperseg`](crate::analysis::FrfSettings::default_nperseg),
/// 50 % overlap, the derived band): the chain of `ambid simulate --signal noise --level 5%
/// --band 1:2000` and `ambid frf`, whose lines are correlated (docs/uncertainty.md, "Welch
/// FRFs: correlated lines").
///
/// # Errors
/// Drawing the rig, the simulation or the FRF.
pub fn twin_noise_welch_frf(
    rig: u64,
    seed: u64,
    mode: Mode,
    sensor_noise: bool,
) -> Result<(crate::experiment::ExperimentOutput, Frd)> {
    use crate::analysis::{analyze, FrfSettings, Record};
    let exp = Experiment {
        twin: twin_rig(rig)?,
        excitation: ExcitationPlan {
            kind: crate::experiment::ExcitationKind::Noise,
            amplitude_frac: 0.05,
            seed,
            ..ExcitationPlan::default()
        },
        mode,
        seed,
        noise: sensor_noise,
        record_b: false,
    };
    let out = run(&exp)?;
    let rec = &out.record;
    let settings = FrfSettings::welch(FrfSettings::default_nperseg(rec.r.len()));
    let a = analyze(
        &Record {
            r: &rec.r,
            u: &rec.u,
            y: &rec.y,
            i: None,
            fs: 1.0 / rec.ts,
        },
        &settings,
        None,
    )?;
    Ok((out, a.frf.plant))
}

/// The seed experiment on twin rig `rig` (0 = nominal, else `random_rig(rig)`) with noise seed
/// `seed`, and its period-averaged plant FRF on [`TWIN_BAND_HZ`] (the twin checks of
/// [`UncertaintyRun`] and [`crate::physical::PhysicalRun`]).
///
/// # Errors
/// Drawing the rig, the simulation or the FRF.
pub fn twin_seed_frf(
    rig: u64,
    seed: u64,
    mode: Mode,
) -> Result<(crate::experiment::ExperimentOutput, Frd)> {
    twin_seed_frf_at(rig, seed, mode, ExcitationPlan::default().amplitude_frac)
}

/// [`twin_seed_frf`] with the seed experiment's PRBS at `amplitude_frac` of $i_\text{sat}$
/// instead of its default 10 % (the amplitude extrapolation of
/// [`crate::physical::ExtrapolatedRun::on_twin`]).
///
/// # Errors
/// Drawing the rig, the simulation or the FRF.
pub fn twin_seed_frf_at(
    rig: u64,
    seed: u64,
    mode: Mode,
    amplitude_frac: f64,
) -> Result<(crate::experiment::ExperimentOutput, Frd)> {
    let (out, cl) = twin_seed_closed_loop(rig, seed, mode, amplitude_frac)?;
    Ok((out, cl.plant))
}

/// [`twin_seed_frf_at`]'s experiment and its whole closed-loop estimate (the plant's noise per
/// line with it).
fn twin_seed_closed_loop(
    rig: u64,
    seed: u64,
    mode: Mode,
    amplitude_frac: f64,
) -> Result<(
    crate::experiment::ExperimentOutput,
    ambid_core::frf::closed_loop::ClosedLoopFrf,
)> {
    let exp = Experiment {
        twin: twin_rig(rig)?,
        excitation: ExcitationPlan {
            amplitude_frac,
            ..ExcitationPlan::default()
        },
        mode,
        seed,
        noise: true,
        record_b: false,
    };
    let out = run(&exp)?;
    let cl = out.periodic_frf(TWIN_BAND_HZ, None)?;
    Ok((out, cl))
}

/// The nominal model of a twin run (type docs of [`UncertaintyRun`]): of the inverse-variance
/// `ss_frd` fits of the orders [`TWIN_ORDERS`] to `frd` (the loop's unstable pole count from
/// `controller` kept) whose loop with `controller` is stable, with no resonance beyond the
/// band ([`out_of_band_resonance`]) and no pole–zero pair that cancels within the data
/// (`validate::compare::cancelling_pairs`, the models step's validity rule; since 2026-12-08),
/// the one of least BIC $2\chi^2 + n_\theta \ln(2L)$, with $L$ lines. The measured loop was
/// stable, so a fit whose loop is not contradicts the data; it is refused, never stabilised (random rig 110 of the nonlinear twin,
/// noise seed 1110: the order-12 fit of least BIC had a closed-loop pole outside the unit
/// circle, $|\hat T| = 5.4$ at 56 Hz against the true 1.5, and no robust margin came from any
/// check; docs/uncertainty.md, "Weights that follow the data's noise").
///
/// # Errors
/// An FRF without variances, or no order could be fitted.
///
/// # Example
/// A stable second-order plant's exact response with 1 % noise variance: the lowest order
/// tried reproduces it.
/// ```
/// use ambid::uncertainty::{nominal_by_bic, TWIN_ORDERS};
/// use ambid_core::lti::{Frd, StateSpace};
/// use faer::mat;
/// let ts = 1e-3;
/// let p = StateSpace::discrete(
///     mat![[1.6, -0.8], [1.0, 0.0]], mat![[1.0], [0.0]], mat![[0.1, 0.05]], mat![[0.0]], ts,
/// ).unwrap();
/// let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[0.1]], ts).unwrap();
/// let f: Vec<f64> = (1..=200).map(|k| 2.0 * k as f64).collect();
/// let exact = Frd::from_model(&p, &f).unwrap();
/// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr()).collect();
/// let frd = Frd::new(f.clone(), exact.values().to_vec(), Some(var), Some(ts)).unwrap();
/// let m = nominal_by_bic(&frd, &c).unwrap();
/// assert!(TWIN_ORDERS.contains(&m.order()));
/// let fit = m.freq_response_siso(&f).unwrap();
/// let worst = fit.iter().zip(exact.values()).map(|(a, b)| (a - b).norm() / b.norm()).fold(0.0, f64::max);
/// assert!(worst < 1e-3, "{worst}");
/// ```
pub fn nominal_by_bic(frd: &Frd, controller: &StateSpace) -> Result<StateSpace> {
    let unstable = unstable_poles_from_loop(frd, controller, None).ok();
    nominal_by_bic_weighted(
        frd,
        FreqWeights::InverseVariance,
        unstable,
        TWIN_ORDERS,
        Some(controller),
    )
}

/// [`nominal_by_bic`] over the given `orders`, with at most `max_unstable_poles` unstable poles
/// (`None`: unconstrained), for data without a controller.
///
/// # Errors
/// As [`nominal_by_bic`].
///
/// # Example
/// A stable second-order plant's exact response with 1 % noise variance, at most 0 unstable
/// poles: order 2 of the orders 2–4 reproduces it.
/// ```
/// use ambid::uncertainty::nominal_by_bic_of;
/// use ambid_core::lti::{Frd, StateSpace};
/// use faer::mat;
/// let ts = 1e-3;
/// let p = StateSpace::discrete(
///     mat![[1.6, -0.8], [1.0, 0.0]], mat![[1.0], [0.0]], mat![[0.1, 0.05]], mat![[0.0]], ts,
/// ).unwrap();
/// let f: Vec<f64> = (1..=200).map(|k| 2.0 * k as f64).collect();
/// let exact = Frd::from_model(&p, &f).unwrap();
/// let var: Vec<f64> = exact.values().iter().map(|g| 1e-4 * g.norm_sqr()).collect();
/// let frd = Frd::new(f.clone(), exact.values().to_vec(), Some(var), Some(ts)).unwrap();
/// let m = nominal_by_bic_of(&frd, Some(0), 2..=4).unwrap();
/// let fit = m.freq_response_siso(&f).unwrap();
/// let worst = fit.iter().zip(exact.values()).map(|(a, b)| (a - b).norm() / b.norm()).fold(0.0, f64::max);
/// assert!(worst < 1e-3, "{worst}");
/// ```
pub fn nominal_by_bic_of(
    frd: &Frd,
    max_unstable_poles: Option<usize>,
    orders: impl IntoIterator<Item = usize>,
) -> Result<StateSpace> {
    nominal_by_bic_weighted(
        frd,
        FreqWeights::InverseVariance,
        max_unstable_poles,
        orders,
        None,
    )
}

/// [`nominal_by_bic_of`] with the fits' `weights`: [`FreqWeights::InverseVariance`], or
/// [`FreqWeights::SampleMaximumLikelihood`] with the FRF's per-line noise
/// ([`ClosedLoopFrf::plant_noise`](ambid_core::frf::closed_loop::ClosedLoopFrf::plant_noise)),
/// whose $\chi^2$ takes each line's variance at the model. Any other weights are refused. With
/// a `controller` (the one the data were measured under) a fit whose loop with it is unstable
/// is refused ([`nominal_by_bic`]).
///
/// # Errors
/// As [`nominal_by_bic`]; weights other than those two.
///
/// # Example
/// A stable second-order plant's exact response with output noise of 1 % of $|P|$ described
/// per line: order 2 of the orders 2–4 reproduces it.
/// ```
/// use ambid::uncertainty::nominal_by_bic_weighted;
/// use ambid_core::c64;
/// use ambid_core::estimate::freqfit::FreqWeights;
/// use ambid_core::frf::closed_loop::RatioNoise;
/// use ambid_core::lti::{Frd, StateSpace};
/// use faer::mat;
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let ts = 1e-3;
/// let p = StateSpace::discrete(
///     mat![[1.6, -0.8], [1.0, 0.0]], mat![[1.0], [0.0]], mat![[0.1, 0.05]], mat![[0.0]], ts,
/// )?;
/// let f: Vec<f64> = (1..=200).map(|k| 2.0 * k as f64).collect();
/// let exact = Frd::from_model(&p, &f)?;
/// let noise: Vec<RatioNoise> = exact.values().iter()
///     .map(|g| RatioNoise { a: 0.0, b: 1e-4 * g.norm_sqr(), c: c64::new(0.0, 0.0) })
///     .collect();
/// let var: Vec<f64> = noise.iter().zip(exact.values()).map(|(n, g)| n.variance_at(*g)).collect();
/// let frd = Frd::new(f.clone(), exact.values().to_vec(), Some(var), Some(ts))?;
/// let m = nominal_by_bic_weighted(&frd, FreqWeights::SampleMaximumLikelihood(noise), Some(0), 2..=4, None)?;
/// let fit = m.freq_response_siso(&f)?;
/// let worst = fit.iter().zip(exact.values()).map(|(a, b)| (a - b).norm() / b.norm()).fold(0.0, f64::max);
/// assert!(worst < 1e-3, "{worst}");
/// # Ok(())
/// # }
/// ```
pub fn nominal_by_bic_weighted(
    frd: &Frd,
    weights: FreqWeights,
    max_unstable_poles: Option<usize>,
    orders: impl IntoIterator<Item = usize>,
    controller: Option<&StateSpace>,
) -> Result<StateSpace> {
    let noise =
        match &weights {
            FreqWeights::InverseVariance => None,
            FreqWeights::SampleMaximumLikelihood(n) => Some(n.clone()),
            _ => return Err(Error::other(
                "the BIC's chi-square needs inverse-variance or sample maximum-likelihood weights",
            )),
        };
    let opts = FreqFitOptions {
        weights,
        max_unstable_poles,
        ..FreqFitOptions::default()
    };
    let n_eq = 2.0 * frd.len() as f64;
    let var = frd
        .variance()
        .ok_or_else(|| Error::other("the FRF has no variances"))?;
    let band = match (frd.f_hz().first(), frd.f_hz().last()) {
        (Some(&lo), Some(&hi)) => (lo, hi),
        _ => return Err(Error::other("the FRF has no lines")),
    };
    let data = FreqData::new(frd, &opts)?;
    let mut best: Option<(f64, StateSpace)> = None;
    for order in orders {
        let Ok(fit) = ss_frd(frd, order, &opts, &SsFreqOptions::default()) else {
            continue;
        };
        if out_of_band_resonance(&fit.model, band)?.is_some() {
            continue;
        }
        // a fit whose pole–zero pairs cancel within the data: the data do not support its
        // order (the models step's validity rule, `validate::compare::cancelling_pairs`)
        if !cancelling_pairs(&fit.model, &data)?.is_empty() {
            continue;
        }
        if let Some(c) = controller {
            if !loop_stable(&fit.model, c, 1.0)? {
                continue;
            }
        }
        // the fit's cost has weights of mean 1: the χ² of the inverse-variance misfit instead
        let resp = fit.model.freq_response_siso(frd.f_hz())?;
        let chi2: f64 = resp
            .iter()
            .zip(frd.values())
            .enumerate()
            .map(|(k, (m, g))| {
                let v = noise.as_ref().map_or(var[k], |n| n[k].variance_at(*m));
                (m - g).norm_sqr() / v
            })
            .sum();
        let bic = 2.0 * chi2 + fit.n_params as f64 * n_eq.ln();
        if best.as_ref().is_none_or(|b| bic < b.0) {
            best = Some((bic, fit.model));
        }
    }
    best.map(|b| b.1).ok_or_else(|| {
        Error::other(
            "no nominal model could be fitted to the FRF without a resonance outside its band \
             (and, with the controller, with a stable loop)",
        )
    })
}

/// The first stable, complex pole pair of `model` whose resonance lies outside the measured
/// band `band_hz` by more than its half-power half-bandwidth, as (natural frequency \[Hz\],
/// damping ratio) of its continuous equivalent $s = \ln z / T_s$: $f_n = |s|/2\pi$,
/// $\zeta = -\operatorname{Re}s/|s|$, out of band when $f_n - f_\text{max} > \zeta f_n$ or
/// $f_\text{min} - f_n > \zeta f_n$. The data see only the tail of such a mode, so neither its frequency nor
/// its damping is identified; a fit puts one there to absorb noise at the band's edge, nearly
/// undamped, and the model's loop then shows a peak the true loop does not have (random rigs
/// 162 and 198 with noise seeds 1162 and 1198: an order-9 fit with a pair at 3.1–3.2 kHz,
/// $|z| = 1.000$, beside a band ending at 3.0 kHz, gave $|\hat T| = 2.8$–$25$ against the
/// true 0.02 and no robust margin). `None` when there is none.
///
/// # Errors
/// When the model's poles cannot be computed, or it is continuous-time.
///
/// # Example
/// ```
/// use ambid::uncertainty::out_of_band_resonance;
/// use ambid_core::lti::StateSpace;
/// use faer::mat;
/// let ts = 1e-4;
/// // a pole pair at 1 kHz with ζ = 0.01, discretised by z = exp(s T)
/// let s = num_complex::Complex64::new(-0.01, (1.0f64 - 1e-4).sqrt()) * (2.0 * std::f64::consts::PI * 1000.0);
/// let z = (s * ts).exp();
/// let (a1, a2) = (2.0 * z.re, -z.norm_sqr());
/// let m = StateSpace::discrete(mat![[a1, a2], [1.0, 0.0]], mat![[1.0], [0.0]], mat![[0.0, 1.0]], mat![[0.0]], ts).unwrap();
/// // inside a band to 1.2 kHz: seen; a band ending at 900 Hz sees only its tail
/// assert!(out_of_band_resonance(&m, (10.0, 1200.0)).unwrap().is_none());
/// let (f, zeta) = out_of_band_resonance(&m, (10.0, 900.0)).unwrap().unwrap();
/// assert!((f - 1000.0).abs() < 1e-6 && (zeta - 0.01).abs() < 1e-9);
/// ```
pub fn out_of_band_resonance(
    model: &StateSpace,
    band_hz: (f64, f64),
) -> Result<Option<(f64, f64)>> {
    let ts = model
        .ts()
        .ok_or_else(|| Error::other("the model must be discrete-time"))?;
    for z in model.poles()? {
        if z.im <= 0.0 || z.norm() >= 1.0 {
            continue;
        }
        let s = z.ln() / ts;
        let f_n = s.norm() / (2.0 * std::f64::consts::PI);
        let zeta = -s.re / s.norm();
        let half = zeta * f_n;
        if f_n - band_hz.1 > half || band_hz.0 - f_n > half {
            return Ok(Some((f_n, zeta)));
        }
    }
    Ok(None)
}
