//! The studies run their levels, operating points, realisations and points in parallel (rayon):
//! every number must be the same whatever the number of threads, and the same as the sequential
//! composition of the per-item functions each item runs with its own seed (the results of the
//! studies before they ran in parallel).
//!
//! Each study runs inside a rayon `ThreadPool` of 1 and of 3 threads; the outcomes are compared
//! through their `Debug` text, which prints every `f64` in its shortest round-trip form, so two
//! equal texts mean bit-identical numbers (and the same NaN / ±0 placement).

use ambid::bla::{
    amplitude_study, amplitude_study_from_records, level_figures, recommend, run_level, BlaPlan,
    Realisation, RecordedLevel, RecordedPlan,
};
use ambid::experiment::{run, ExcitationPlan, Experiment};
use ambid::stepped_sine::{run_stepped_sine, SteppedSineOptions};
use ambid::study::{
    amplitude_from_records, amplitude_on_twin, operating_point_on_twin, seed_cases, LevelRecord,
    Recommendation, TwinAmplitudeStudy,
};
use ambid_core::frf::bla::random_phase_period;
use ambid_core::frf::stepped_sine::{Settle, SteppedSinePlan};
use ambid_twin::{Mode, SimOptions, Twin, TwinConfig};

/// `f` run on a pool of `threads` threads.
fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// Same `Debug` text on 1 and on 3 threads; returns it.
fn same_on_1_and_3_threads<T: std::fmt::Debug>(f: impl Fn() -> T + Send + Sync) -> String {
    let one = on_threads(1, || format!("{:?}", f()));
    let three = on_threads(3, || format!("{:?}", f()));
    assert!(
        one == three,
        "the result depends on the number of threads:\n{one}\n{three}"
    );
    one
}

fn small_amplitude_study() -> TwinAmplitudeStudy {
    TwinAmplitudeStudy {
        levels: vec![0.04, 0.10, 0.16],
        ..TwinAmplitudeStudy::default()
    }
}

#[test]
fn amplitude_study_on_the_twin_is_independent_of_the_threads_and_equals_the_sequential_levels() {
    let study = small_amplitude_study();
    let par = same_on_1_and_3_threads(|| amplitude_on_twin(&study).unwrap());
    // the oracle: each level's experiment run on its own (seed + j), the noise record (seed +
    // 1000), then the records analysed together, as the study did before it ran in parallel
    let mut records = Vec::new();
    let mut twin = None;
    let mut period = 0;
    for (j, &level) in study.levels.iter().enumerate() {
        let out = run(&Experiment {
            twin: study.twin.clone(),
            excitation: ExcitationPlan {
                amplitude_frac: level,
                ..study.excitation.clone()
            },
            mode: study.mode,
            seed: study.seed + j as u64,
            noise: study.noise,
            record_b: false,
        })
        .unwrap();
        period = out.excitation.period_samples;
        records.push(LevelRecord {
            level,
            r: out.record.r,
            u: out.record.u,
            y: out.record.y,
            i: Some(out.record.i),
            saturated_fraction: Some(out.record.meta.saturated_fraction),
        });
        twin = Some(out.twin);
    }
    let noise = run(&Experiment {
        twin: study.twin.clone(),
        excitation: ExcitationPlan {
            kind: ambid::experiment::ExcitationKind::None,
            ..study.excitation.clone()
        },
        mode: study.mode,
        seed: study.seed + 1000,
        noise: true,
        record_b: false,
    })
    .unwrap();
    let twin = twin.unwrap();
    let mut settings = ambid::analysis::FrfSettings::periodic(period, study.skip_periods);
    settings.band = study.band;
    settings.quality_band = study.band;
    settings.i_sat = Some(twin.i_sat());
    let truth =
        |f: &[f64]| -> ambid::error::Result<Vec<ambid_core::c64>> { Ok(twin.plant_frf(f)?) };
    let seq = on_threads(1, || {
        amplitude_from_records(
            &records,
            twin.fs(),
            Some(&noise.record.y),
            &settings,
            Some(&truth),
            Recommendation::default(),
        )
        .unwrap()
    });
    assert_eq!(par, format!("{seq:?}"));
    // and the levels really differ (the comparison is not of empty or constant outcomes)
    assert_eq!(seq.rows.len(), 3);
    assert!(seq.rows[2].mean_coh_ry > seq.rows[0].mean_coh_ry);
}

#[test]
fn operating_point_study_is_independent_of_the_threads() {
    let nominal = TwinConfig::default();
    let cases: Vec<_> = seed_cases(&nominal).into_iter().take(3).collect();
    let text = same_on_1_and_3_threads(|| {
        let out = operating_point_on_twin(
            &nominal,
            &cases,
            &ExcitationPlan::default(),
            Mode::Nonlinear,
            7,
            1,
            Some((10.0, 2000.0)),
        )
        .unwrap();
        // a bias change moves the plant: the deviations are real numbers, not zeros
        assert!(out.deviations.iter().any(|d| d.median_rel_dev > 1e-3));
        assert_eq!(out.plants.len(), 3);
        out
    });
    assert!(text.contains("truth_errors"));
}

#[test]
fn bla_amplitude_study_is_independent_of_the_threads_and_equals_the_sequential_levels() {
    let plan = BlaPlan {
        realisations: 4,
        ..BlaPlan::default()
    };
    let levels = [0.03, 0.12];
    let par = same_on_1_and_3_threads(|| amplitude_study(&plan, &levels).unwrap());
    // the oracle: each level on its own, then the recommendation
    let rows = levels
        .iter()
        .map(|&l| level_figures(&run_level(&plan, l).unwrap(), l, plan.summary_band_hz).unwrap())
        .collect();
    let seq = on_threads(1, || recommend(rows).unwrap());
    assert_eq!(par, format!("{seq:?}"));
    assert!(seq.rows[0].noise_rel > seq.rows[1].noise_rel);
}

#[test]
fn recorded_bla_study_is_independent_of_the_threads() {
    // four random-phase multisine realisations per level, recorded in closed loop on the twin
    let twin = Twin::new(TwinConfig::default()).unwrap();
    let n = 1000;
    let bins: Vec<usize> = (1..100).step_by(2).collect();
    let level = |pct: f64| RecordedLevel {
        level_pct: pct,
        realisations: (0..4u64)
            .map(|m| {
                let p = random_phase_period(&bins, n, pct / 100.0 * twin.i_sat(), m).unwrap();
                let r: Vec<f64> = (0..5 * n).map(|t| p[t % n]).collect();
                let rec = twin
                    .simulate(
                        &r,
                        &SimOptions {
                            mode: Mode::Nonlinear,
                            seed: 100 + m,
                            ..SimOptions::default()
                        },
                    )
                    .unwrap();
                Realisation {
                    r: Some(rec.r),
                    u: rec.u,
                    y: rec.y,
                    saturated_fraction: Some(rec.meta.saturated_fraction),
                    source: format!("m{m}"),
                }
            })
            .collect(),
    };
    let levels = [level(3.0), level(12.0)];
    let plan = RecordedPlan {
        fs: twin.fs(),
        period_samples: n,
        skip_periods: 1,
        summary_band_hz: (20.0, 1000.0),
    };
    same_on_1_and_3_threads(|| {
        let s = amplitude_study_from_records(&levels, &plan).unwrap();
        assert_eq!(s.rows.len(), 2);
        assert!(s.rows[0].noise_rel > s.rows[1].noise_rel);
        s
    });
}

#[test]
fn stepped_sine_is_independent_of_the_threads() {
    let twin = Twin::new(TwinConfig::default()).unwrap();
    let f = ambid::experiment::log_grid(20.0, 1000.0, 5);
    let plan = SteppedSinePlan::new(twin.fs(), &f, Settle::Seconds(0.05), 4, 0.02).unwrap();
    let text = same_on_1_and_3_threads(|| {
        let out = run_stepped_sine(&twin, &plan, 0.2, &SteppedSineOptions::default()).unwrap();
        assert_eq!(out.points.len(), 5);
        out
    });
    assert!(text.contains("seeds"));
}
