//! Issue 4's twin bars: the order-8 model of T_ry (r → y, stable) from the closed-loop seed
//! experiment by subspace alone and by subspace + PEM, validated on an independent record and
//! against the exact T_ry; and the direct method (u → y in closed loop) against the exact plant.

use ambid::experiment::{run, Experiment, ExperimentOutput};
use ambid_core::estimate::arx::{arx, ArxOrders};
use ambid_core::estimate::pem::Focus;
use ambid_core::estimate::ss_pem::{refine_ss, SsPemOptions};
use ambid_core::estimate::subspace::{n4sid_detailed, SubspaceOptions};
use ambid_core::lti::StateSpace;
use ambid_core::validate::fit::fit_percent;
use ambid_twin::Mode;
use faer::Mat;
use num_complex::Complex64;

/// 200 log-spaced frequencies over 10–1000 Hz.
fn grid() -> Vec<f64> {
    (0..200)
        .map(|k| 10.0 * (100f64).powf(k as f64 / 199.0))
        .collect()
}

/// Median of |G·1e-6 − truth| / |truth| (the models are in µm).
fn median_rel(g: &[Complex64], truth: &[Complex64]) -> f64 {
    let mut rel: Vec<f64> = g
        .iter()
        .zip(truth)
        .map(|(a, t)| (a * 1e-6 - t).norm() / t.norm())
        .collect();
    rel.sort_by(|a, b| a.total_cmp(b));
    rel[rel.len() / 2]
}

/// Validation fit (%) of the simulated µm-model on the record `val` (r → y).
fn validation_fit(model: &StateSpace, val: &ExperimentOutput) -> f64 {
    let ysim: Vec<f64> = model
        .simulate_siso(&val.record.r, None)
        .unwrap()
        .iter()
        .map(|v| v * 1e-6)
        .collect();
    fit_percent(&val.record.y, &ysim).unwrap()
}

/// (r, y in µm) or (u, y in µm) as N × 1 matrices.
fn columns(x: &[f64], y: &[f64]) -> (Mat<f64>, Mat<f64>) {
    (
        Mat::from_fn(x.len(), 1, |k, _| x[k]),
        Mat::from_fn(y.len(), 1, |k, _| 1e6 * y[k]),
    )
}

#[test]
fn subspace_plus_pem_t_ry_model_of_order_8_meets_the_bar_under_both_focuses() {
    let est = run(&Experiment::seed_paper(Mode::Linear, 1e-7, 1)).unwrap();
    let val = run(&Experiment::seed_paper(Mode::Linear, 1e-7, 2)).unwrap();
    let (rm, ym) = columns(&est.record.r, &est.record.y);
    let mut opts = SubspaceOptions::new(est.twin.ts());
    opts.order = Some(8);
    opts.block_rows = Some(120);
    let sub = n4sid_detailed(ym.as_ref(), rm.as_ref(), &opts).unwrap();
    let f = grid();
    let truth = est.twin.t_ry_frf(&f).unwrap();
    let k = sub.kalman_gain.as_ref().map(|k| k.as_ref());
    // simulation focus (output error: what the validation fit measures) and the default
    // prediction focus, the latter with MATLAB's default cap of 20 iterations: its optimum
    // lies on the stability boundary (module docs of ss_pem) and is approached slowly
    for (focus, iters) in [(Focus::Simulation, 100), (Focus::Prediction, 20)] {
        let o = SsPemOptions {
            focus,
            lm: SsPemOptions::default()
                .lm
                .with_max_iterations(iters)
                .unwrap(),
            ..SsPemOptions::default()
        };
        let fit = refine_ss(ym.as_ref(), rm.as_ref(), &sub.fitted.model, k, &o).unwrap();
        let model = &fit.fitted.model;
        let vfit = validation_fit(model, &val);
        let med = median_rel(&model.freq_response_siso(&f).unwrap(), &truth);
        eprintln!(
            "order-8 subspace (i = 120) + PEM ({focus:?}, {} iterations, {:?}): validation fit {vfit:.2} %, median |ΔT_ry|/|T_ry| {:.3} % over 10–1000 Hz",
            fit.report.iterations,
            fit.report.reason,
            100.0 * med
        );
        assert!(vfit >= 97.0, "{focus:?}: {vfit}");
        assert!(med <= 0.02, "{focus:?}: {med}");
        assert!(fit.fitted.loss <= fit.start_loss * (1.0 + 1e-12));
    }
}

/// The direct method: the plant P (u → y, unstable) from the closed-loop record. The
/// prediction-error method with a flexible noise model (the innovation form's K) is consistent
/// in closed loop; subspace projections and ARX (noise model 1/A) are not, because the input
/// u = r − C y is correlated with the past noise.
#[test]
fn direct_method_in_closed_loop_is_unbiased_only_with_a_flexible_noise_model() {
    let est = run(&Experiment::seed_paper(Mode::Linear, 1e-7, 1)).unwrap();
    let (um, ym) = columns(&est.record.u, &est.record.y);
    let f = grid();
    let truth = est.twin.plant_frf(&f).unwrap();
    let mut opts = SubspaceOptions::new(est.twin.ts());
    opts.order = Some(8);
    opts.block_rows = Some(120);
    let sub = n4sid_detailed(ym.as_ref(), um.as_ref(), &opts).unwrap();
    let med_sub = median_rel(&sub.fitted.model.freq_response_siso(&f).unwrap(), &truth);
    let o = SsPemOptions {
        lm: SsPemOptions::default().lm.with_max_iterations(40).unwrap(),
        ..SsPemOptions::default()
    };
    let k = sub.kalman_gain.as_ref().map(|k| k.as_ref());
    let fit = refine_ss(ym.as_ref(), um.as_ref(), &sub.fitted.model, k, &o).unwrap();
    let med_pem = median_rel(&fit.fitted.model.freq_response_siso(&f).unwrap(), &truth);
    let y: Vec<f64> = ym.col(0).iter().copied().collect();
    let arx8 = arx(
        &y,
        &[&est.record.u],
        &ArxOrders::siso(8, 8, 1),
        est.twin.ts(),
    )
    .unwrap();
    let med_arx = median_rel(
        &arx8.model.to_poly(0).unwrap().freq_response(&f).unwrap(),
        &truth,
    );
    eprintln!(
        "direct method, plant over 10–1000 Hz, median relative error: subspace {:.2} %, ARX(8,8,1) {:.2} %, subspace + PEM (prediction) {:.3} % ({} iterations); plant poles outside the unit circle in the PEM model: {}",
        100.0 * med_sub,
        100.0 * med_arx,
        100.0 * med_pem,
        fit.report.iterations,
        fit.fitted.model.poles().unwrap().iter().filter(|z| z.norm() > 1.0).count()
    );
    assert!(med_pem <= 0.005, "{med_pem}");
    assert!(med_sub >= 0.02, "{med_sub}");
    assert!(med_arx >= 0.02, "{med_arx}");
    // the unstable plant stays unstable: nothing is stabilised
    assert!(!fit.fitted.model.is_stable().unwrap());
}

#[test]
fn subspace_t_ry_model_of_order_8_validates_on_an_independent_record() {
    let est = run(&Experiment::seed_paper(Mode::Linear, 1e-7, 1)).unwrap();
    let val = run(&Experiment::seed_paper(Mode::Linear, 1e-7, 2)).unwrap();
    // y in micrometres keeps the data well scaled; the model is scaled back below
    let (rm, ym) = columns(&est.record.r, &est.record.y);
    let mut opts = SubspaceOptions::new(est.twin.ts());
    opts.order = Some(8);
    let fit = n4sid_detailed(ym.as_ref(), rm.as_ref(), &opts).unwrap();
    let model = &fit.fitted.model;
    let vfit = validation_fit(model, &val);
    // the model's T_ry against the twin's exact one on a log grid 10–1000 Hz
    let f = grid();
    let med = median_rel(
        &model.freq_response_siso(&f).unwrap(),
        &est.twin.t_ry_frf(&f).unwrap(),
    );
    eprintln!(
        "order-8 subspace T_ry: validation fit {vfit:.2} %, median |ΔT_ry|/|T_ry| {:.3} % over 10–1000 Hz (block rows {})",
        100.0 * med,
        fit.block_rows
    );
    assert!(vfit >= 97.0, "{vfit}");
    assert!(med <= 0.02, "{med}");
}

/// OE(8, 8, 1) of T_ry on one PRBS period of the twin: from the SRIV start alone the
/// Levenberg–Marquardt iteration crawled (loss 1.57 after the default 100 iterations, the
/// optimum 0.665 only after 317–417); with the subspace fallback the default budget reaches the
/// optimum, which further iterations do not improve, and the model matches the exact T_ry.
#[test]
fn oe_of_a_lightly_damped_loop_converges_within_the_default_budget() {
    use ambid_core::estimate::pem::{oe, refine, PemOptions};
    let out = run(&Experiment::seed_paper(Mode::Linear, 0.1e-6, 1)).unwrap();
    let rec = &out.record;
    let (a, b) = (5115usize, 10230usize);
    let u: Vec<f64> = rec.r[a..b].to_vec();
    let y: Vec<f64> = rec.y[a..b].iter().map(|v| v * 1e6).collect();
    let (fit, rep) = oe(&y, &u, 8, 8, 1, rec.ts, &PemOptions::default()).unwrap();
    let longer = PemOptions::default().with_max_iterations(1000).unwrap();
    let (more, more_rep) = refine(&y, &u, &fit.model, &longer).unwrap();
    let f = grid();
    let g: Vec<Complex64> = fit
        .model
        .freq_response(&f)
        .unwrap()
        .iter()
        .map(|z| Complex64::new(z.re, z.im))
        .collect();
    let truth = out.twin.t_ry_frf(&f).unwrap();
    let err = median_rel(&g, &truth);
    println!(
        "OE(8,8,1), one period: {} iterations, loss {:.5e}; 1000 more allowed: {} iterations, loss {:.5e}; T_ry median error {:.2} %",
        rep.iterations(),
        fit.loss,
        more_rep.iterations(),
        more.loss,
        100.0 * err
    );
    assert!(rep.iterations() <= 100);
    assert!(
        (fit.loss - more.loss) / more.loss < 1e-3,
        "{} vs {}",
        fit.loss,
        more.loss
    );
    assert!(err < 0.06, "T_ry median error {err}");
}
