//! The validation, reconstruction and ISO 14839-3 stages on their own (`ambid::stage`), against
//! independent truth: the twin's exact plant and controller, naive in-test predictors and the
//! chirp's own frequency law.

use ambid::experiment::ExcitationPlan;
use ambid::io::ControllerModel;
use ambid::stage::{
    iso, reconstruction, validation, validation_settings, IsoInput, ModelUnderTest,
    ReconstructionInput, ReconstructionSource, Recording, Signals, TwinSource, ValidationCheck,
    ValidationInput, ONE_STEP, SIMULATION,
};
use ambid::workflow::config::{ReconstructionSection, ValidationSection};
use ambid_core::c64;
use ambid_core::lti::{PolyModel, StateSpace, Structure};
use ambid_twin::{Mode, TwinConfig};

fn twin(noise: bool) -> TwinSource {
    let mut cfg = TwinConfig::default();
    if !noise {
        cfg.sensor.noise_rms_m = 0.0;
    }
    TwinSource::new(cfg, Mode::Linear).unwrap()
}

fn controller(t: &TwinSource) -> ControllerModel {
    ControllerModel::new(t.twin.controller().clone(), "the twin's PID").unwrap()
}

/// max_k |a_k − b_k| / max_k |b_k|
fn rel_dev(a: &[c64], b: &[c64]) -> f64 {
    let m = b.iter().map(|x| x.norm()).fold(0.0, f64::max);
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).norm())
        .fold(0.0, f64::max)
        / m
}

/// The twin's exact sensitivity 1/(1 + P C) from its plant and controller responses.
fn exact_s(t: &TwinSource, f: &[f64]) -> Vec<c64> {
    let p = t.twin.plant_frf(f).unwrap();
    let c = t.twin.controller_frf(f).unwrap();
    p.iter()
        .zip(&c)
        .map(|(p, c)| 1.0 / (c64::new(1.0, 0.0) + p * c))
        .collect()
}

#[test]
fn closed_loop_validation_of_the_exact_plant_matches_the_twin() {
    let t = twin(true);
    let ctrl = controller(&t);
    let plan = ExcitationPlan {
        periods: 2,
        ..ExcitationPlan::default()
    };
    let (rec, _) = t.record(plan, 11, "validation").unwrap();
    let plant = t.twin.plant().clone();
    let st = validation(&ValidationInput {
        model: ModelUnderTest {
            name: "exact",
            model: &plant,
            poly: None,
            kalman: None,
        },
        record: &rec,
        controller: Some(&ctrl),
        twin: Some(&t),
        settings: validation_settings(&ValidationSection::default(), Default::default(), rec.len()),
        lags: None,
    })
    .unwrap();
    let ValidationCheck::ClosedLoop(c) = &st.check else {
        panic!("not validated in closed loop: {:?}", st.check)
    };
    // the model is the twin's exact plant: the reference check is the same computation
    let exact = c.exact_plant.as_ref().expect("the twin's reference");
    assert_eq!(c.outcome.fit_y, exact.fit_y);
    // the exact plant reproduces the record to the sensor noise
    assert!(c.outcome.fit_y > 80.0, "fit y {}", c.outcome.fit_y);
    // the model's sensitivity on the grid is the twin's exact 1/(1 + P C)
    let s = exact_s(&t, &c.outcome.grid_hz);
    let dev = rel_dev(&c.outcome.s_model, &s);
    assert!(dev < 1e-9, "S deviates by {dev:e}");
    // the lag rule of the stage is the CLI's
    let n = rec.len() - c.outcome.skip;
    let rule = ambid::validation::residual_lags(&plant, Some(ctrl.state_space()), n);
    assert_eq!(c.lags, rule);
    // the figures' measured series are the record's
    assert_eq!(st.y, rec.y());
    assert_eq!(st.u, rec.u());
}

#[test]
fn a_record_without_excitation_is_not_validated_and_says_why() {
    let t = twin(true);
    let ctrl = controller(&t);
    let n = 4000;
    let rec = Recording::from_signals(
        t.twin.ts(),
        None,
        Signals {
            r: Some(vec![0.0; n]),
            u: vec![0.1; n],
            y: vec![1e-6; n],
            i: None,
            w: None,
        },
        true,
        "still.csv",
    )
    .unwrap();
    let plant = t.twin.plant().clone();
    let st = validation(&ValidationInput {
        model: ModelUnderTest {
            name: "exact",
            model: &plant,
            poly: None,
            kalman: None,
        },
        record: &rec,
        controller: Some(&ctrl),
        twin: None,
        settings: validation_settings(&ValidationSection::default(), Default::default(), rec.len()),
        lags: None,
    })
    .unwrap();
    let ValidationCheck::NotDone(why) = &st.check else {
        panic!("validated a record without excitation")
    };
    assert!(
        why.contains("still.csv") && why.contains("nothing drives the loop"),
        "{why}"
    );
}

fn open_loop_record(u: Vec<f64>, y: Vec<f64>) -> Recording {
    Recording::from_signals(
        1e-3,
        None,
        Signals {
            r: None,
            u,
            y,
            i: None,
            w: None,
        },
        false,
        "open.csv",
    )
    .unwrap()
}

#[test]
fn open_loop_validation_simulates_stable_and_predicts_unstable_arx_models() {
    let n = 3000;
    // a rich deterministic input (no two commensurate tones)
    let u: Vec<f64> = (0..n)
        .map(|k| (0.37 * k as f64).sin() + 0.5 * (1.91 * k as f64 + 0.3).sin())
        .collect();
    // a stable second-order model, started away from rest
    let m = StateSpace::new(
        faer::mat![[1.2, -0.5], [1.0, 0.0]],
        faer::mat![[1.0], [0.0]],
        faer::mat![[0.3, 0.2]],
        faer::mat![[0.0]],
        Some(1e-3),
    )
    .unwrap();
    let y = m.simulate_siso(&u, Some(&[0.7, -0.2])).unwrap();
    let rec = open_loop_record(u.clone(), y.clone());
    let st = validation(&ValidationInput {
        model: ModelUnderTest {
            name: "SS 2",
            model: &m,
            poly: None,
            kalman: None,
        },
        record: &rec,
        controller: None,
        twin: None,
        settings: Default::default(),
        lags: None,
    })
    .unwrap();
    let ValidationCheck::OpenLoop(o) = &st.check else {
        panic!("{:?}", st.check)
    };
    assert_eq!(o.kind, SIMULATION);
    // the least-squares initial state recovers the record exactly
    assert!(o.fit_y > 99.9999, "fit {}", o.fit_y);
    assert!(o.without_controller.is_none());

    // an unstable ARX model y_k = 1.5 y_{k-1} + 0.8 u_{k-1} + e_k: its one-step predictor
    let p = PolyModel::new(
        Structure::Arx,
        vec![1.0, -1.5],
        vec![0.0, 0.8],
        vec![1.0],
        vec![1.0],
        vec![1.0],
        1e-3,
    )
    .unwrap();
    let ss = p.g().unwrap().to_state_space().unwrap();
    let yr: Vec<f64> = (0..n)
        .map(|k| (0.73 * k as f64).cos() + 0.3 * (2.3 * k as f64).sin())
        .collect();
    let rec = open_loop_record(u.clone(), yr.clone());
    let input = |poly| ValidationInput {
        model: ModelUnderTest {
            name: "ARX 1",
            model: &ss,
            poly,
            kalman: None,
        },
        record: &rec,
        controller: None,
        twin: None,
        settings: Default::default(),
        lags: Some(12),
    };
    let st = validation(&input(Some(&p))).unwrap();
    let ValidationCheck::OpenLoop(o) = &st.check else {
        panic!("{:?}", st.check)
    };
    assert_eq!(o.kind, ONE_STEP);
    assert_eq!(
        (o.lags.lags, o.lags.basis),
        (12, ambid::validation::LagBasis::Given)
    );
    // the naive predictor, from the second sample on (the first has no past)
    for k in 1..n {
        let naive = 1.5 * yr[k - 1] + 0.8 * u[k - 1];
        assert!(
            (o.yhat[k] - naive).abs() < 1e-9,
            "k = {k}: {} vs {naive}",
            o.yhat[k]
        );
    }
    let r = o.residuals.as_ref().expect("residual tests");
    assert_eq!(r.signal, "input u");
    assert_eq!(r.test.whiteness.as_ref().map(|w| w.values.len()), Some(12));
    // without its polynomial form the same unstable model has no predictor
    let st = validation(&input(None)).unwrap();
    let ValidationCheck::NotDone(why) = &st.check else {
        panic!("{:?}", st.check)
    };
    assert!(
        why.contains("ARX 1 is unstable and has no predictor"),
        "{why}"
    );
}

#[test]
fn reconstruction_of_the_exact_plant_follows_the_chirp() {
    let t = twin(false);
    let ctrl = controller(&t);
    let plant = t.twin.plant().clone();
    let chirp = ReconstructionSection {
        duration_s: 0.5,
        ..ReconstructionSection::default()
    };
    let st = reconstruction(&ReconstructionInput {
        name: "exact",
        model: &plant,
        controller: &ctrl,
        chirp: &chirp,
        settings: &ValidationSection::default(),
        zones: Default::default(),
        source: ReconstructionSource::Twin { twin: &t, seed: 1 },
    })
    .unwrap();
    // the linear twin without noise is its exact plant in the loop
    let fit = st.outcome.reconstruction.fit_y;
    assert!(fit > 99.0, "fit y {fit}");
    // the chirp's instantaneous frequency against its law f0 + (f1 − f0) t / T
    let f = st.frequency.as_ref().expect("a rising sweep");
    for wf in st.windows() {
        let tm = 0.5 * (wf.t_s.0 + wf.t_s.1);
        let law = chirp.f0_hz + (chirp.f1_hz - chirp.f0_hz) * tm / chirp.duration_s;
        let got = f[st.sample_at(tm)];
        assert!(
            (got - law).abs() < 0.05 * law + 2.0,
            "at {tm} s: {got} Hz, law {law} Hz"
        );
    }
    // the window's signal RMS, by a naive computation
    let wf = &st.windows()[3];
    let (i0, i1) = (st.sample_at(wf.t_s.0), st.sample_at(wf.t_s.1));
    let seg = &st.y[i0..i1];
    let mean = seg.iter().sum::<f64>() / seg.len() as f64;
    let rms = (seg.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / seg.len() as f64).sqrt();
    assert!((st.window_signal_rms[3] - rms).abs() <= 1e-12 * rms);

    // a file without the reference w is refused with a clear input error
    let rec = open_loop_record(vec![0.0; 100], vec![0.0; 100]);
    let e = reconstruction(&ReconstructionInput {
        source: ReconstructionSource::Record(&rec),
        name: "exact",
        model: &plant,
        controller: &ctrl,
        chirp: &chirp,
        settings: &ValidationSection::default(),
        zones: Default::default(),
    })
    .unwrap_err();
    assert!(e.to_string().contains("position reference"), "{e}");
    assert_eq!(e.exit_code(), 3);
}

#[test]
fn iso_stage_truth_is_the_exact_sensitivity() {
    let t = twin(true);
    let st = iso(&IsoInput {
        zones: Default::default(),
        frf: None,
        identification: None,
        validation: None,
        twin: Some(&t),
    })
    .unwrap();
    let tr = st.truth.as_ref().unwrap();
    let dev = rel_dev(&tr.s, &exact_s(&t, &tr.f_hz));
    assert!(dev < 1e-9, "S deviates by {dev:e}");
    let peak = tr.s.iter().map(|s| s.norm()).fold(0.0, f64::max);
    assert!((tr.verdict.peak - peak).abs() <= 1e-9 * peak);
    // the truth alone gives no verdict; nothing at all is not done
    assert!(st.verdict().is_none() && st.not_done().is_none());
    let none = iso(&IsoInput {
        zones: Default::default(),
        frf: None,
        identification: None,
        validation: None,
        twin: None,
    })
    .unwrap();
    assert!(none
        .not_done()
        .unwrap()
        .contains("needs the measured sensitivity"));
}

/// `ambid run` hands its caller the three stages' typed results beside summary.json, and they
/// are what summary.json says; the ISO truth is the twin's exact 1/(1 + P C).
#[test]
fn the_workflow_outcome_carries_the_typed_stage_results() {
    use ambid::workflow::{run, Progress, Step, Verbosity, WorkflowConfig};
    let cfg = WorkflowConfig {
        steps: Some(vec![
            Step::Frf,
            Step::Order,
            Step::Models,
            Step::Validation,
            Step::Reconstruction,
            Step::Iso,
        ]),
        ..WorkflowConfig::default()
    };
    let out = run(
        &cfg,
        std::path::Path::new("."),
        &mut Progress::new(Verbosity::Quiet),
    )
    .unwrap();
    let s = &out.summary;
    let v = out.validation_stage.as_ref().expect("validation stage");
    let cl = v.closed_loop().expect("validated through the closed loop");
    assert_eq!(s["validation"]["fit_y_pct"].as_f64(), Some(cl.fit_y));
    assert_eq!(s["validation"]["model"].as_str(), Some(v.model.as_str()));
    let r = out
        .reconstruction_stage
        .as_ref()
        .expect("reconstruction stage");
    assert_eq!(
        s["reconstruction"]["fit_y_pct"].as_f64(),
        Some(r.outcome.reconstruction.fit_y)
    );
    let iso = out.iso_stage.as_ref().expect("iso stage");
    let m = iso.measured.as_ref().expect("measured S on the twin");
    assert_eq!(
        s["iso"]["measured"]["peak"].as_f64(),
        Some(m.search.verdict.peak)
    );
    assert_eq!(
        s["iso"]["zone"].as_str().map(str::to_string),
        iso.verdict().map(|z| format!("{z:?}"))
    );
    let t = twin(true);
    let tr = iso.truth.as_ref().unwrap();
    assert!(rel_dev(&tr.s, &exact_s(&t, &tr.f_hz)) < 1e-9);
    // the measured peak against the twin's exact |S| at that line: within 1 % (the default twin
    // runs its nonlinear physics, so the measured S is a best linear approximation and its
    // 95 % interval, a few per mille wide, need not hold the linearised truth)
    let (lo, hi) = m.search.verdict.interval.expect("an interval");
    assert!(lo <= m.search.verdict.peak && m.search.verdict.peak <= hi);
    let exact_at = exact_s(&t, &[m.search.verdict.f_peak_hz])[0].norm();
    let err = (m.search.verdict.peak - exact_at).abs() / exact_at;
    assert!(
        err < 0.01,
        "peak {} vs exact {exact_at}",
        m.search.verdict.peak
    );
}
