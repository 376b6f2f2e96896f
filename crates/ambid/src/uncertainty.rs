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
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
use ambid_core::lti::{Frd, StateSpace};
use ambid_core::validate::compare::unstable_poles_from_loop;
pub use ambid_core::validate::robust::{loop_stable, nominal_gain_interval};
use ambid_core::validate::robust::{robust_stability, robust_stability_on_lines, RobustStability};
use ambid_core::validate::uncertainty::{
    uncertainty, ExtraTerms, UncertaintyOptions, UncertaintyTerms,
};
use ambid_core::validate::weight::{fit_weight, WeightFit, DEFAULT_COVER, MAX_WEIGHT_ORDER};
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
    /// the fraction `cover` of the band in the fraction `run_coverage` of the runs
    /// ([`ErrorModel::joint_factor`](ambid_core::validate::uncertainty::ErrorModel::joint_factor); 1: the per-line overbound already did).
    pub joint_raise: f64,
    /// The controller's robust stability against the bound on the lines itself, $g_\ell\,\ell_k$
    /// ([`robust_stability_on_lines`]): the $\mu$ analysis on the measured band without the
    /// weight's fit, so its verdict does not rest on how an order-≤4 weight compromises over a
    /// ragged bound; it says nothing outside the band.
    pub on_lines: RobustStability,
    /// $g_\ell \ge 1$: the factor the bound ℓ was raised by for [`Self::on_lines`], so that it
    /// overbounds the model's error on `cover` of the lines in `run_coverage` of the draws.
    pub lines_raise: f64,
}

/// The uncertainty of `nominal` around the measured plant FRF `frd` (with variances), its weight
/// of order ≤ `max_weight_order` overbounding the fraction `cover` of the lines — its gain then
/// raised, where needed, until it also overbounds the fitted model's error on `cover` of the lines
/// in `opts.run_coverage` of `opts.draws` seeded draws
/// ([`ErrorModel::joint_factor`](ambid_core::validate::uncertainty::ErrorModel::joint_factor),
/// [`UncertaintyAnalysis::joint_raise`]) — and the robust stability of `controller` against it,
/// and against the bound on the lines itself, raised the same way
/// ([`UncertaintyAnalysis::on_lines`]).
///
/// # Errors
/// Those of [`uncertainty`], [`fit_weight`] and [`robust_stability`], with the step named.
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
    let terms = uncertainty(nominal, frd, extra, opts).context("the uncertainty terms")?;
    let ts = nominal
        .ts()
        .ok_or_else(|| Error::other("the nominal model must be discrete-time"))?;
    // a line where every term is 0 (no noise, no misfit) cannot be overbounded in log scale:
    // the floor is 1e-12 of the largest bound
    let top = terms.multiplicative.iter().copied().fold(0.0f64, f64::max);
    let bound: Vec<f64> = terms
        .multiplicative
        .iter()
        .map(|b| b.max(1e-12 * top).max(f64::MIN_POSITIVE))
        .collect();
    let mut weight = fit_weight(
        &terms.f_hz,
        &bound,
        ts,
        max_weight_order.min(MAX_WEIGHT_ORDER),
        cover,
    )
    .context("fitting the uncertainty weight")?;
    // the weight's and the bound's joint factors from one set of draws
    let factors = terms
        .errors
        .joint_factors(
            &[&weight.weight.magnitude(&terms.f_hz), &bound],
            cover,
            opts.run_coverage,
            opts.draws,
            opts.seed,
        )
        .context("the joint coverage of the weight and the bound")?;
    let (joint_raise, lines_raise) = (factors[0].max(1.0), factors[1].max(1.0));
    weight.raise(joint_raise, &terms.f_hz, &bound);
    let robust = robust_stability(nominal, controller, &weight.weight)
        .context("the robust-stability check")?;
    let raised: Vec<f64> = bound.iter().map(|b| b * lines_raise).collect();
    let on_lines = robust_stability_on_lines(nominal, controller, &terms.f_hz, &raised)
        .context("the robust-stability check on the lines")?;
    Ok(UncertaintyAnalysis {
        terms,
        weight,
        robust,
        joint_raise,
        on_lines,
        lines_raise,
    })
}

/// Term (d) of the bound around the model `nominal` on the lines `f_hz`: [`operating_spread`]
/// with $|\hat P(f_k)|$ evaluated from the model.
///
/// # Errors
/// Those of [`operating_spread`], or a model that cannot be evaluated on the lines.
pub fn operating_term(plants: &[Frd], f_hz: &[f64], nominal: &StateSpace) -> Result<Vec<f64>> {
    let abs: Vec<f64> = nominal
        .freq_response_siso(f_hz)?
        .iter()
        .map(|p| p.norm())
        .collect();
    operating_spread(plants, f_hz, &abs)
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
    let fs = nom.f_hz();
    Ok(f_hz
        .iter()
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
        .collect())
}

/// The orders a twin run's nominal model is chosen from (by BIC).
pub const TWIN_ORDERS: std::ops::RangeInclusive<usize> = 6..=12;

/// The band of a twin run's FRF and fit \[Hz\]: the seed excitation's lines up to 3 kHz (its
/// power falls to the sinc null at 4 kHz).
pub const TWIN_BAND_HZ: (f64, f64) = (3.0, 3000.0);

/// One run of the whole chain on the twin: the seed experiment on rig `rig` (0 = nominal) with
/// noise seed `seed`, the period-averaged plant FRF, the nominal model (the BIC choice among
/// [`TWIN_ORDERS`] of inverse-variance frequency-domain state-space fits with the loop's unstable
/// pole count), [`analyse`], and the truth to check it against.
#[derive(Debug, Clone)]
pub struct UncertaintyRun {
    /// The measured plant FRF.
    pub frd: Frd,
    /// The nominal model.
    pub nominal: StateSpace,
    /// The analysis.
    pub analysis: UncertaintyAnalysis,
    /// The twin's exact plant.
    pub truth_plant: StateSpace,
    /// The twin's controller.
    pub controller: StateSpace,
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
        let (out, frd) = twin_seed_frf(rig, seed, mode)?;
        let controller = out.twin.controller().clone();
        let nominal = nominal_by_bic(&frd, &controller)?;
        let analysis = analyse(
            &nominal,
            &frd,
            &controller,
            &ExtraTerms::default(),
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
    let twin = if rig == 0 {
        TwinConfig::default()
    } else {
        random_rig(rig).context("drawing the rig")?
    };
    let exp = Experiment {
        twin,
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
    let frd = out.periodic_frf(TWIN_BAND_HZ, None)?.plant;
    Ok((out, frd))
}

/// The nominal model of a twin run (type docs of [`UncertaintyRun`]).
fn nominal_by_bic(frd: &Frd, controller: &StateSpace) -> Result<StateSpace> {
    let unstable = unstable_poles_from_loop(frd, controller, None).ok();
    let opts = FreqFitOptions {
        weights: FreqWeights::InverseVariance,
        max_unstable_poles: unstable,
        ..FreqFitOptions::default()
    };
    let n_eq = 2.0 * frd.len() as f64;
    let var = frd
        .variance()
        .ok_or_else(|| Error::other("the FRF has no variances"))?;
    let mut best: Option<(f64, StateSpace)> = None;
    for order in TWIN_ORDERS {
        let Ok(fit) = ss_frd(frd, order, &opts, &SsFreqOptions::default()) else {
            continue;
        };
        // the fit's cost has weights of mean 1: the χ² of the inverse-variance misfit instead
        let resp = fit.model.freq_response_siso(frd.f_hz())?;
        let chi2: f64 = resp
            .iter()
            .zip(frd.values())
            .zip(var)
            .map(|((m, g), v)| (m - g).norm_sqr() / v)
            .sum();
        let bic = 2.0 * chi2 + fit.n_params as f64 * n_eq.ln();
        if best.as_ref().is_none_or(|b| bic < b.0) {
            best = Some((bic, fit.model));
        }
    }
    best.map(|b| b.1)
        .ok_or_else(|| Error::other("no nominal model could be fitted to the twin's FRF"))
}
