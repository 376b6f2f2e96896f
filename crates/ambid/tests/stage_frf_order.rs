//! The FRF and order stages on their own (issue 19: typed stages shared by the CLI and the
//! workflow), against independent truth: the twin's exact closed-loop responses, a naive
//! in-test quantile of the plant error, and a second-order system of known order.

use ambid::experiment::ExcitationKind;
use ambid::stage::{
    acquire_twin, frf, identification_plan, order, AcquisitionPlan, ErrorBasis, FrfInput,
    OrderInput, PlantEstimator, Recording, Seeds, Signals, TwinSource,
};
use ambid::workflow::config::{ExcitationSection, FrfSection, ModelsSection, OrderSection};
use ambid::workflow::{run, Progress, Step, Verbosity, WorkflowConfig};
use ambid_core::c64;
use ambid_twin::{Mode, TwinConfig};
use std::path::Path;

fn rel(a: c64, b: c64) -> f64 {
    (a - b).norm() / b.norm()
}

/// Median of `v` as the stage picks it (index round(0.5 (n − 1)) of the sorted values).
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[(0.5 * (v.len() - 1) as f64).round() as usize]
}

#[test]
fn the_frf_stage_on_the_twin_gives_the_exact_responses_and_measures_its_error_against_them() {
    let twin = TwinSource::new(TwinConfig::default(), Mode::Nonlinear).unwrap();
    let seeds = Seeds::from_workflow_seed(3);
    let exc = ExcitationSection {
        periods: 12,
        ..ExcitationSection::default()
    };
    let plan = AcquisitionPlan::new(
        identification_plan(&exc, 0.1, &seeds),
        ExcitationKind::Multisine,
        0.1,
        seeds,
    );
    let rec = acquire_twin(&twin, &plan).unwrap().identification;
    let st = frf(&FrfInput {
        record: &rec,
        frf: &FrfSection::default(),
        skip_periods: 1,
        noise: None,
        controller: None,
        twin: Some(&twin),
    })
    .unwrap();
    assert_eq!(st.estimator, PlantEstimator::Joint);
    assert!(st.has_r);
    assert_eq!(st.samples, rec.len());
    let f = st.f_hz().to_vec();
    assert!(f.len() > 50, "{} lines", f.len());
    let t = st.truth.as_ref().unwrap();
    // the exact responses are the twin's own, and satisfy T_ry = P S
    let (p, try_, s) = (
        twin.twin.plant_frf(&f).unwrap(),
        twin.twin.t_ry_frf(&f).unwrap(),
        twin.twin.sensitivity_frf(&f).unwrap(),
    );
    for k in 0..f.len() {
        assert!(rel(t.plant[k], p[k]) <= 1e-12);
        assert!(rel(t.t_ry[k], try_[k]) <= 1e-12, "T_ry at {} Hz", f[k]);
        assert!(rel(t.sensitivity[k], s[k]) <= 1e-12, "S at {} Hz", f[k]);
        assert!(rel(t.plant[k] * t.sensitivity[k], t.t_ry[k]) <= 1e-12);
    }
    // the measured closed-loop responses are close to the exact ones in the quality band
    let qb = st.analysis.quality.band;
    let in_band = |k: &usize| (qb.0..=qb.1).contains(&f[*k]);
    let fr = &st.analysis.frf;
    let e_try = median(
        (0..f.len())
            .filter(in_band)
            .map(|k| rel(fr.t_ry.values()[k], try_[k]))
            .collect(),
    );
    let e_s = median(
        (0..f.len())
            .filter(in_band)
            .map(|k| rel(fr.t_ru.values()[k], s[k]))
            .collect(),
    );
    assert!(
        e_try < 0.1 && e_s < 0.05,
        "median errors T_ry {e_try}, S {e_s}"
    );
    // the stage's error quantile against a naive in-test one
    let naive = 100.0
        * median(
            (0..f.len())
                .filter(in_band)
                .map(|k| rel(fr.plant.values()[k], p[k]))
                .collect(),
        );
    let e = st.errors_vs_truth.unwrap();
    assert!(
        (e.median_pct - naive).abs() <= 1e-12 * naive,
        "{} vs {naive}",
        e.median_pct
    );
    assert!(e.p90_pct >= e.median_pct && e.median_pct < 10.0, "{e:?}");
}

/// A record of the second-order ARX system
/// y_k = 1.5 y_{k−1} − 0.7 y_{k−2} + u_{k−1} + 0.5 u_{k−2} + e_k (poles 0.75 ± 0.37j).
fn second_order(seed: u64, n: usize) -> Recording {
    let mut s = seed;
    let mut rnd = move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let u: Vec<f64> = (0..n).map(|_| rnd()).collect();
    let mut y = vec![0.0; n];
    for k in 2..n {
        y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + u[k - 1] + 0.5 * u[k - 2] + 0.01 * rnd();
    }
    let sig = Signals {
        u,
        y,
        ..Signals::default()
    };
    Recording::from_signals(1e-3, None, sig, false, "second order").unwrap()
}

#[test]
fn the_order_stage_finds_the_order_of_a_known_second_order_system() {
    let (ident, valid) = (second_order(11, 3000), second_order(12, 3000));
    let o = OrderSection {
        na_max: 5,
        nb_max: 5,
        ..OrderSection::default()
    };
    let models = ModelsSection::default();
    let input = OrderInput {
        identification: &ident,
        validation: &valid,
        frf: None,
        order: &o,
        models: &models,
        models_run: false,
        controller: None,
    };
    // the singular values alone
    let st = order(&input).unwrap();
    assert_eq!((st.arx.best.0, st.arx.best.1, st.arx.best.2), (2, 2, 1));
    assert!(!st.arx.on_edge);
    assert_eq!(st.arx.log10_loss.len(), 5);
    // the grids hold the scan's rows
    for r in &st.arx.scan.rows {
        assert_eq!(st.arx.bic[r.na - 1][r.nb - 1], r.bic);
        assert_eq!(st.arx.log10_loss[r.na - 1][r.nb - 1], r.loss.log10());
    }
    assert!(st.resonances.is_none());
    let r = st.recommendation.as_ref().unwrap();
    assert_eq!(
        (r.n, r.lo, r.hi, r.source),
        (2, 2, 2, "subspace_singular_values")
    );
    assert_eq!(r.subspace.as_ref().unwrap().order, 2);
    // with the models step: the time-domain fits per order decide
    let st = order(&OrderInput {
        models_run: true,
        ..input
    })
    .unwrap();
    let r = st.recommendation.as_ref().unwrap();
    assert_eq!((r.n, r.lo, r.source), (2, 2, "time_fit_error"), "{r:?}");
    assert!(r.hi >= 2 && r.hi <= 2 + ambid::stage::ORDER_RANGE_ABOVE);
    let e = r.errors.as_ref().unwrap();
    assert_eq!(e.basis, ErrorBasis::TimeValidation);
    assert_eq!(e.rows.len(), ambid::stage::ORDER_SCAN_MAX);
    // the tolerance of 3000 validation samples, and adequacy by the rule, recomputed here
    let tol = 1.0 + 2.0 / (6000.0f64).sqrt();
    assert!((e.tolerance - tol).abs() < 1e-15);
    let best = e
        .rows
        .iter()
        .filter_map(|r| r.error)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(e.best, best);
    for row in &e.rows {
        assert_eq!(
            row.adequate,
            row.error.is_some_and(|v| v <= tol * best),
            "{row:?}"
        );
    }
    // order 1 cannot follow a complex pole pair
    assert!(!e.rows[0].adequate);
}

#[test]
fn the_workflow_outcome_carries_the_stage_results_it_summarised() {
    let cfg = WorkflowConfig {
        steps: Some(vec![Step::Frf, Step::Order]),
        ..WorkflowConfig::default()
    };
    let out = run(&cfg, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
    let sm = &out.summary;
    let fs = out.frf_stage.as_ref().unwrap();
    assert_eq!(
        fs.analysis.quality.mean_coherence_ry,
        sm["frf"]["mean_coh_ry"].as_f64().unwrap()
    );
    assert_eq!(
        fs.errors_vs_truth.unwrap().median_pct,
        sm["frf"]["plant_median_error_vs_truth_pct"]
            .as_f64()
            .unwrap()
    );
    let os = out.order_stage.as_ref().unwrap();
    let r = os.recommendation.as_ref().unwrap();
    assert_eq!(r.n as f64, sm["order"]["recommended"].as_f64().unwrap());
    assert_eq!(
        r.source,
        sm["order"]["recommended_source"].as_str().unwrap()
    );
    assert_eq!(
        os.resonances.as_ref().unwrap().peaks.len() as f64,
        sm["order"]["resonances"].as_f64().unwrap()
    );
    // on the twin (closed loop with r) the FRF fits set the range
    assert!(matches!(
        r.errors.as_ref().unwrap().basis,
        ErrorBasis::Frf { .. }
    ));
}
