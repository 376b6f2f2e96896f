//! Issue 16: the polynomial prediction-error defaults (`ambid fit --structure oe|armax|bj`) on
//! random rigs of the twin, not on the nominal one.
//!
//! For each rig seed: the seed experiment (PRBS n = 10, 5 samples per bit, 20 periods, 20 kHz,
//! 10 % of i_sat, 102 300 samples) on the linear twin of `random_rig(seed)` is the estimation
//! record; an independent run (12 % of i_sat, another noise seed, 4 periods) the validation
//! record. OE(8, 8, 1) of $T_{ry}$ (r → y, means removed as the CLI does) is fitted by
//! [`pem`] with [`PemOptions::default`] — what `ambid fit --structure oe --nb 8 --nf 8` runs.
//! The reference is the exact $T_{ry}$: the twin's linear closed loop simulated from rest on the
//! validation `r`, scored with the same fit % against the same noisy validation `y`. Bars: the
//! iteration converged within the default budget (stopped on a tolerance, not on its limit) and
//! the model's validation fit is within 0.5 point of the truth's.
//!
//! ARMAX(4, 4, 4, 1) of $u \to y$ (what `ambid fit --structure armax --na 4 --nb 4 --nc 4` runs
//! on the record: closed-loop data, the direct method) and BJ(4, 2, 2, 4, 1) of $r \to y$ are
//! low-order approximations without an exact reference; their bar is the iteration's own: it
//! stops on a real criterion (the statistical rule of `pem`'s module docs, not the iteration
//! limit) and loses nothing against the same fit run to its 100-iteration limit with every
//! tolerance 0 (validation fit at least that one's minus 0.1 point; the 1-step prediction fit for
//! ARMAX, whose $u \to y$ model is unstable, the simulation fit for BJ).
//!
//! The full sweep with timings: `PEM_REFERENCE=1 cargo run --release -p ambid --example
//! pem_rig_sweep -- 1 20` (docs/estimation.md).

use crate::common::{exact_loop_fit, mean, seed_record_on_rig};

use ambid_core::estimate::pem::lm::{LmOptions, StopReason};
use ambid_core::estimate::pem::{pem, Orders, PemOptions};
use ambid_core::lti::{PolyModel, Structure};
use ambid_core::validate::fit::fit_percent;
use ambid_core::validate::predict::{poly_one_step, InitialState};

/// Rig seeds tested here.
const RIGS: u64 = 20;

#[test]
fn oe88_defaults_converge_and_reach_the_true_systems_fit_on_random_rigs() {
    let mut worst: f64 = f64::NEG_INFINITY;
    let mut failures = Vec::new();
    for rig in 1..=RIGS {
        let est = seed_record_on_rig(rig, 1000 + rig, 0.10, 20);
        let val = seed_record_on_rig(rig, 2000 + rig, 0.12, 4);
        assert_eq!(est.record.r.len(), 102_300);
        let (mu, my) = (mean(&est.record.r), mean(&est.record.y));
        let u: Vec<f64> = est.record.r.iter().map(|v| v - mu).collect();
        let y: Vec<f64> = est.record.y.iter().map(|v| v - my).collect();
        let uv: Vec<f64> = val.record.r.iter().map(|v| v - mu).collect();
        let yv: Vec<f64> = val.record.y.iter().map(|v| v - my).collect();
        let (fit, rep) = pem(
            &y,
            &u,
            Structure::Oe,
            &Orders::oe(8, 8, 1),
            est.twin.ts(),
            &PemOptions::default(),
        )
        .unwrap();
        let f_model = fit_percent(&yv, &fit.model.simulate(&uv, None, None).unwrap()).unwrap();
        // the truth: the exact closed loop from rest, w = 0
        let f_truth = exact_loop_fit(&val.twin, &val.record.r, &val.record.y);
        let gap = f_truth - f_model;
        worst = worst.max(gap);
        eprintln!(
            "rig {rig}: OE(8,8,1) {} iterations ({:?}), fit {f_model:.3} %, truth {f_truth:.3} %, gap {gap:.3}",
            rep.iterations(),
            rep.reason()
        );
        if !rep.reason().converged() || gap > 0.5 {
            failures.push(rig);
        }
    }
    assert!(
        failures.is_empty(),
        "OE(8,8,1) not converged or more than 0.5 point below the truth on rigs {failures:?} (worst gap {worst:.3})"
    );
}

/// ARMAX(4,4,4,1) u → y and BJ(4,2,2,4,1) r → y with the defaults: converged on a statistical or
/// numerical criterion, and the validation fit within 0.1 point of the 100-iteration result.
/// Rigs 1 and 2 only (test-time budget: each rig costs two 100-iteration reference runs); the
/// 20-rig sweep and the rigs where the bar is not met are in docs/estimation.md.
#[test]
fn armax_and_bj_defaults_stop_on_a_criterion_and_lose_nothing_against_the_full_budget() {
    let full = PemOptions::default().with_lm(LmOptions::exhaustive(100).unwrap());
    let mut failures = Vec::new();
    for rig in 1..=2u64 {
        let est = seed_record_on_rig(rig, 1000 + rig, 0.10, 20);
        let val = seed_record_on_rig(rig, 2000 + rig, 0.12, 4);
        let my = mean(&est.record.y);
        let y: Vec<f64> = est.record.y.iter().map(|v| v - my).collect();
        let yv: Vec<f64> = val.record.y.iter().map(|v| v - my).collect();
        let centre = |x: &[f64], m: f64| -> Vec<f64> { x.iter().map(|v| v - m).collect() };
        let cases = [
            (
                "ARMAX(4,4,4,1) u→y",
                Structure::Armax,
                Orders::armax(4, 4, 4, 1),
                &est.record.u,
                &val.record.u,
                true,
            ),
            (
                "BJ(4,2,2,4,1) r→y",
                Structure::Bj,
                Orders::bj(4, 2, 2, 4, 1),
                &est.record.r,
                &val.record.r,
                false,
            ),
        ];
        for (name, s, o, ue, uv, one_step) in cases {
            let mu = mean(ue);
            let (u, uv) = (centre(ue, mu), centre(uv, mu));
            let score = |m: &PolyModel| -> f64 {
                let yh = if one_step {
                    poly_one_step(m, &yv, &uv, InitialState::Zero).unwrap()
                } else {
                    m.simulate(&uv, None, None).unwrap()
                };
                fit_percent(&yv, &yh).unwrap()
            };
            let ts = est.twin.ts();
            let (fit, rep) = pem(&y, &u, s, &o, ts, &PemOptions::default()).unwrap();
            let (reference, ref_rep) = pem(&y, &u, s, &o, ts, &full).unwrap();
            let (f, f_ref) = (score(&fit.model), score(&reference.model));
            eprintln!(
                "rig {rig}: {name} {} iterations ({:?}), validation fit {f:.4} %; 100 iterations ({:?}): {f_ref:.4} %, loss ratio − 1 = {:.1e}",
                rep.iterations(),
                rep.reason(),
                ref_rep.reason(),
                fit.loss / reference.loss - 1.0
            );
            if rep.reason() == StopReason::MaxIterations || f < f_ref - 0.1 {
                failures.push(format!("rig {rig} {name}"));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "not converged or more than 0.1 point below the 100-iteration fit: {failures:?}"
    );
}
