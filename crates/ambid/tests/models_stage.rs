//! The models and pole-zero stages' typed results against independent truth: the twin's exact
//! plant (truth errors recomputed naively in the test, the unstable pole), the choice rule
//! against a naive argmax and against `ambid_core::validate::compare::choose`, and the
//! continuous-time poles of a model built from known s-plane poles (analytic values).

use ambid::stage::{choose, pole_zero, Candidate, PoleZeroInput, Select};
use ambid::workflow::{run, Progress, Step, Verbosity, WorkflowConfig};
use ambid_core::c64;
use ambid_core::lti::{StateSpace, Structure};
use ambid_core::validate::compare::CompareRow;
use std::f64::consts::TAU;
use std::path::Path;

/// The median over lines of |g − p| / |p|, written out (upper median for an even count).
fn naive_median_rel(g: &[c64], p: &[c64]) -> f64 {
    let mut e: Vec<f64> = g
        .iter()
        .zip(p)
        .map(|(a, b)| ((a.re - b.re).hypot(a.im - b.im)) / b.re.hypot(b.im))
        .collect();
    e.sort_by(|a, b| a.partial_cmp(b).unwrap());
    e[e.len() / 2]
}

#[test]
fn the_models_stage_on_the_twin_matches_the_exact_plant_and_chooses_by_its_rule() {
    let cfg = WorkflowConfig {
        steps: Some(vec![Step::Frf, Step::Models, Step::PoleZero]),
        ..WorkflowConfig::default()
    };
    let out = run(&cfg, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
    let st = out.models_stage.as_ref().expect("the models stage ran");
    assert!(st.skipped.is_none());
    assert_eq!(st.domain, "frf");
    let m = st.measured.as_ref().unwrap();
    // the twin's exact plant, independently
    let twin = ambid_twin::Twin::new(ambid_twin::TwinConfig::default()).unwrap();
    let truth = twin.plant_frf(&m.f_hz).unwrap();
    let mut fitted = 0;
    for c in &st.candidates {
        let Some(model) = &c.model else {
            assert!(c.truth_median_relative.is_none());
            continue;
        };
        fitted += 1;
        let g = model.freq_response_siso(&m.f_hz).unwrap();
        let want = naive_median_rel(&g, &truth);
        let got = c.truth_median_relative.unwrap();
        assert!(
            (got - want).abs() <= 1e-12 * want,
            "{}: {got} vs {want}",
            c.label()
        );
    }
    assert!(fitted >= 8, "only {fitted} candidates fitted");
    // the rule: the best validation fit among the valid fitted candidates
    let best = st
        .candidates
        .iter()
        .enumerate()
        .filter(|(_, c)| c.valid && c.model.is_some())
        .filter_map(|(i, c)| Some((i, c.validation_fit.filter(|f| f.is_finite())?)))
        .max_by(|a, b| a.1.partial_cmp(&b.1).unwrap())
        .map(|(i, _)| i);
    assert!(best.is_some());
    assert_eq!(st.choice.index, best);
    assert!(st.choice.among_valid);
    let chosen = st.chosen().unwrap();
    // the chosen model is close to the exact plant (the seed's bar: a few per cent)
    assert!(chosen.truth_median_relative.unwrap() < 0.05);
    // its unstable poles: the exact plant's one, s = f_s ln z within 10 %
    let exact = twin.plant_unstable_poles().unwrap();
    assert_eq!(st.truth_unstable_poles.as_deref(), Some(&exact[..]));
    assert_eq!(st.chosen_unstable.len(), exact.len());
    let fs = twin.fs();
    for (z, t) in st.chosen_unstable.iter().zip(&exact) {
        let (s, st_) = (z.ln() * fs, t.ln() * fs);
        assert!((s - st_).norm() < 0.1 * st_.norm(), "{s} vs exact {st_}");
    }
    // the summary holds the same figures and the export marks exactly the chosen model
    let sm = out.stages.models.as_ref().unwrap();
    assert_eq!(sm.chosen.as_deref(), Some(chosen.label().as_str()));
    assert_eq!(sm.table.len(), st.candidates.len());
    let marked: Vec<&str> = out
        .models
        .iter()
        .filter(|m| m.meta["chosen"] == true)
        .map(|m| m.name.as_str())
        .collect();
    assert_eq!(
        marked,
        vec![format!("{}{}", chosen.structure, chosen.order).as_str()]
    );
    assert_eq!(out.models.len(), fitted);
    // the pole-zero stage: the chosen structure's candidates, the chosen model's count
    let pz = out.pole_zero_stage.as_ref().unwrap();
    assert_eq!(pz.structure, chosen.structure);
    let cp = pz.chosen.as_ref().unwrap();
    assert_eq!(cp.unstable_poles, exact.len());
    let sp = out.stages.pole_zero.as_ref().unwrap();
    assert_eq!(sp.chosen_unstable_poles, cp.unstable_poles as f64);
    assert_eq!(sp.chosen_near_cancellations, cp.near_cancellations as f64);
}

/// A discrete model whose poles are given in continuous time (1/s) at sample rate `fs`: one
/// complex pair (as a real 2×2 block) and one real pole.
fn model_with_poles(pair: c64, real: f64, fs: f64) -> StateSpace {
    let z = (pair / fs).exp();
    let zr = (real / fs).exp();
    let a = faer::Mat::from_fn(3, 3, |i, j| match (i, j) {
        (0, 0) | (1, 1) => z.re,
        (0, 1) => -z.im,
        (1, 0) => z.im,
        (2, 2) => zr,
        _ => 0.0,
    });
    let b = faer::Mat::from_fn(3, 1, |_, _| 1.0);
    let c = faer::Mat::from_fn(1, 3, |_, j| [1.0, 0.5, 1.0][j]);
    StateSpace::discrete(a, b, c, faer::Mat::zeros(1, 1), 1.0 / fs).unwrap()
}

#[test]
fn the_pole_zero_stage_gives_the_analytic_natural_frequency_damping_and_time_constant() {
    let fs = 10_000.0;
    let (f0, zeta) = (50.0, 0.1);
    let w0 = TAU * f0;
    let pair = c64::new(-zeta * w0, w0 * (1.0 - zeta * zeta).sqrt());
    let a_unstable = TAU * 20.0; // an unstable real pole at +2π·20 1/s
    let m = model_with_poles(pair, a_unstable, fs);
    let c = Candidate {
        model: Some(m),
        ..Candidate::time_fit("ss", 3, None, 15, None)
    };
    let pz = pole_zero(&PoleZeroInput {
        candidates: std::slice::from_ref(&c),
        chosen: 0,
        twin: None,
    })
    .unwrap();
    assert!(pz.truth_unstable_poles.is_empty());
    assert_eq!(pz.rows.len(), 1);
    assert_eq!(pz.rows[0].poles.len(), 3);
    assert_eq!(pz.rows[0].unstable.len(), 1);
    let ch = pz.chosen.unwrap();
    assert_eq!(ch.unstable_poles, 1);
    assert_eq!(ch.outside, 0); // both below f_s / 15
    let sp = ch.s_plane.unwrap();
    // one row per pair, slowest first: the real pole (20 Hz), then the pair (50 Hz)
    assert_eq!(sp.table.len(), 2);
    let (r, p) = (&sp.table[0], &sp.table[1]);
    assert!(r.real && !p.real);
    assert!((r.natural_hz - 20.0).abs() < 1e-9, "{}", r.natural_hz);
    assert!((r.time_constant_ms.unwrap() - 1e3 / a_unstable).abs() < 1e-9);
    assert!((p.natural_hz - f0).abs() < 1e-9, "{}", p.natural_hz);
    assert!((p.damping - zeta).abs() < 1e-12, "{}", p.damping);
    assert!(p.time_constant_ms.is_none());
    assert!((p.s_hz - pair / TAU).norm() < 1e-9);
    // the zoomed view holds every slow pole: 1.5 × the largest |1 − z| (or 2.5 × |z| − 1)
    let zs = [(pair / fs).exp(), c64::new((a_unstable / fs).exp(), 0.0)];
    let want = zs
        .iter()
        .map(|z| 1.5 * (c64::new(1.0, 0.0) - z).norm())
        .fold(2.5 * (zs[1].norm() - 1.0), f64::max)
        .clamp(1e-4, 0.6);
    assert!((ch.zoom_radius - want).abs() < 1e-15);
}

/// A comparison row with the figures the choice reads.
fn row(valid: bool, fit: Option<f64>, bic: Option<f64>, fitted: bool) -> CompareRow {
    CompareRow {
        structure: Structure::Oe,
        order: 2,
        n_params: 4,
        rmse: None,
        relative_rmse: bic.map(|b| b.abs()),
        db_rmse: None,
        median_relative: None,
        low_band_relative_rmse: None,
        bic,
        validation_fit: fit,
        unstable_poles: None,
        converged: None,
        closed_loop_stable: None,
        valid,
        admissible: valid,
        note: None,
        model: fitted.then(|| {
            StateSpace::discrete(
                faer::Mat::from_fn(1, 1, |_, _| 0.5),
                faer::Mat::from_fn(1, 1, |_, _| 1.0),
                faer::Mat::from_fn(1, 1, |_, _| 1.0),
                faer::Mat::zeros(1, 1),
                1e-3,
            )
            .unwrap()
        }),
    }
}

#[test]
fn the_choice_rule_is_the_cores_on_valid_rows_and_falls_back_as_documented() {
    // a deterministic pseudo-random sweep of 400 tables (xorshift)
    let mut state = 0x9E37_79B9_7F4A_7C15_u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for _ in 0..400 {
        let n = 1 + (next() % 8) as usize;
        let rows: Vec<CompareRow> = (0..n)
            .map(|_| {
                let fitted = next() % 5 != 0;
                let valid = fitted && next() % 3 != 0;
                let fit = (next() % 4 != 0).then(|| (next() % 1000) as f64 / 10.0);
                let bic = (next() % 4 != 0).then(|| -((next() % 1000) as f64));
                row(
                    valid,
                    fit.filter(|_| fitted),
                    bic.filter(|_| fitted),
                    fitted,
                )
            })
            .collect();
        let c = choose(&rows, Select::Validation);
        let core = ambid_core::validate::compare::choose(&rows);
        assert_eq!(c.index.filter(|_| c.among_valid), core);
        // naive oracles
        let argmin = |keep: &dyn Fn(&CompareRow) -> bool,
                      key: &dyn Fn(&CompareRow) -> Option<f64>| {
            let mut best: Option<(usize, f64)> = None;
            for (i, r) in rows.iter().enumerate() {
                if let Some(v) = key(r).filter(|_| keep(r)) {
                    if best.is_none_or(|(_, b)| v < b) {
                        best = Some((i, v));
                    }
                }
            }
            best.map(|(i, _)| i)
        };
        let valid = |r: &CompareRow| r.valid && r.model.is_some();
        let any = |r: &CompareRow| r.model.is_some();
        let want_valid = argmin(&valid, &|r| r.validation_fit.map(|f| -f))
            .or_else(|| argmin(&valid, &|r| r.bic));
        let want = want_valid
            .or_else(|| argmin(&any, &|r| r.validation_fit.map(|f| -f)))
            .or_else(|| rows.iter().position(|r| r.model.is_some()));
        assert_eq!(c.index, want);
        assert_eq!(c.among_valid, want_valid.is_some());
        let b = choose(&rows, Select::Bic);
        let want_b = argmin(&valid, &|r| r.bic)
            .or_else(|| argmin(&any, &|r| r.bic))
            .or_else(|| rows.iter().position(|r| r.model.is_some()));
        assert_eq!(b.index, want_b);
    }
}
