//! The amplitude and operating-point studies on the twin.

use crate::common;
use ambid::experiment::ExcitationPlan;
use ambid::study::{amplitude_on_twin, operating_point_on_twin, seed_cases, TwinAmplitudeStudy};
use ambid_twin::{Mode, TwinConfig};

/// The seed's figure-6 study on the nonlinear twin (default noise 0.2 µm): coherence rises and
/// saturates, SNR rises by 20 log10 of the level ratio, the FRF variance across periods falls as
/// 1/A². The variance does not rise again on the twin; see the next test for why.
#[test]
fn amplitude_study_on_the_nonlinear_twin() {
    let out = amplitude_on_twin(&TwinAmplitudeStudy::default()).unwrap();
    for r in &out.rows {
        eprintln!(
            "{:5.1} %  coh_ry {:.4}  coh_ru {:.4}  var {:.3e}  relvar {:.3e}  snr {:6.2} dB  sat {:.4}  err {:.3} %",
            r.level_pct,
            r.mean_coh_ry,
            r.mean_coh_ru,
            r.mean_plant_var,
            r.mean_plant_rel_var,
            r.snr_db.unwrap(),
            r.saturated_fraction,
            100.0 * r.plant_median_rel_err.unwrap()
        );
    }
    eprintln!("{:?} {}", out.recommended_pct, out.reasoning);
    let rows = &out.rows;
    // coherence increases with the level and its growth flattens
    assert!(rows.windows(2).all(|w| w[1].mean_coh_ry > w[0].mean_coh_ry));
    let first_gain = rows[1].mean_coh_ry - rows[0].mean_coh_ry;
    let last_gain = rows[7].mean_coh_ry - rows[6].mean_coh_ry;
    assert!(last_gain < 0.1 * first_gain, "{first_gain} {last_gain}");
    // output SNR: total power over noise power; from 8 % to 16 % the excited part quadruples
    let snr = |r: &ambid::study::LevelFigures| 10f64.powf(r.snr_db.unwrap() / 10.0) - 1.0;
    let ratio = snr(&rows[7]) / snr(&rows[3]);
    assert!(
        (ratio / 4.0 - 1.0).abs() < 0.1,
        "excited-power ratio {ratio}"
    );
    // variance ∝ 1/A² (noise-dominated): log-log slope between 2 % and 14 %
    let slope = (rows[6].mean_plant_var / rows[0].mean_plant_var).ln() / (14f64 / 2.0).ln();
    eprintln!("log-log slope of the FRF variance, 2–14 %: {slope:.3}");
    assert!((-2.3..=-1.7).contains(&slope), "{slope}");
    // the recommendation lies in the upper half and excludes the saturated 16 % level
    let (lo, hi) = out.recommended_pct.unwrap();
    assert!(lo >= 8.0 && hi <= 14.0, "{lo}–{hi}");
    assert!(rows[7].saturated_fraction > 0.0);
}

/// Why the variance does not rise: period-to-period spread only sees what is not periodic. With
/// the noise off, the nonlinear twin's response to a periodic excitation is periodic (its
/// nonlinear distortion included), so the spread is zero at every level while the deviation from
/// the linearised truth (the nonlinear bias) grows with the level.
#[test]
fn nonlinear_distortion_is_invisible_to_the_period_spread() {
    let study = TwinAmplitudeStudy {
        levels: vec![0.02, 0.14],
        noise: false,
        ..TwinAmplitudeStudy::default()
    };
    let out = amplitude_on_twin(&study).unwrap();
    let (lo, hi) = (&out.rows[0], &out.rows[1]);
    eprintln!(
        "noise off: variance {:.2e} / {:.2e}, bias {:.4} % / {:.4} %",
        lo.mean_plant_rel_var,
        hi.mean_plant_rel_var,
        100.0 * lo.plant_median_rel_err.unwrap(),
        100.0 * hi.plant_median_rel_err.unwrap()
    );
    assert!(lo.mean_plant_rel_var < 1e-12 && hi.mean_plant_rel_var < 1e-12);
    assert!(hi.plant_median_rel_err.unwrap() > 5.0 * lo.plant_median_rel_err.unwrap());
}

/// The seed's figure-7 study: each case's estimate follows its own truth, and the deviation from
/// nominal that the estimates show matches the deviation of the true plants.
#[test]
fn operating_point_study_on_the_twin() {
    let nominal = TwinConfig::default();
    let out = operating_point_on_twin(
        &nominal,
        &seed_cases(&nominal),
        &ExcitationPlan::default(),
        Mode::Nonlinear,
        1,
        1,
        Some((10.0, 2000.0)),
    )
    .unwrap();
    for d in &out.deviations {
        eprintln!(
            "{:9} {:9}  est {:6.2} %  true {:6.2} %  max {:5.2} dB",
            d.case,
            d.band,
            100.0 * d.median_rel_dev,
            100.0 * d.truth_median_rel_dev.unwrap(),
            d.max_abs_db_dev
        );
    }
    eprintln!("errors against each case's truth: {:?}", out.truth_errors);
    assert!(out.truth_errors.iter().all(|e| *e < 0.1));
    for d in out.deviations.iter().filter(|d| d.band != "high") {
        let t = d.truth_median_rel_dev.unwrap();
        assert!(
            (d.median_rel_dev - t).abs() < 0.25 * t + 0.01,
            "{} {}: {} vs {t}",
            d.case,
            d.band,
            d.median_rel_dev
        );
    }
    // bias changes move the plant more than gap changes at low frequency (k_i ∝ i0, k_x ∝ i0²)
    let low = |c: &str| {
        out.deviations
            .iter()
            .find(|d| d.case == c && d.band == "low")
            .unwrap()
            .median_rel_dev
    };
    assert!(low("bias+20%") > 2.0 * low("gap+10um"));
}

/// From recorded files the study gives exactly what the twin run gives for the same records: the
/// same experiments (same seeds), analysed by `operating_point_from_records`, reproduce the twin
/// study's deviations bit for bit (without the truth columns, which files cannot have).
#[test]
fn operating_point_study_from_records_matches_the_twin_run() {
    use ambid::analysis::{FrfSettings, Record};
    use ambid::experiment::{run, Experiment};
    use ambid::study::operating_point_from_records;
    let nominal = TwinConfig::default();
    let cases: Vec<_> = seed_cases(&nominal).into_iter().take(3).collect();
    let plan = ExcitationPlan::default();
    let twin = operating_point_on_twin(
        &nominal,
        &cases,
        &plan,
        Mode::Linear,
        5,
        1,
        Some((10.0, 2000.0)),
    )
    .unwrap();
    let outs: Vec<_> = cases
        .iter()
        .enumerate()
        .map(|(j, c)| {
            let mut cfg = nominal.clone();
            cfg.operating_point.bias_current_a = c.bias_current_a;
            cfg.operating_point.air_gap_m = c.air_gap_m;
            run(&Experiment {
                twin: cfg,
                excitation: plan.clone(),
                mode: Mode::Linear,
                seed: 5 + j as u64,
                noise: true,
                record_b: false,
            })
            .unwrap()
        })
        .collect();
    let records: Vec<Record<'_>> = outs
        .iter()
        .map(|o| Record {
            r: &o.record.r,
            u: &o.record.u,
            y: &o.record.y,
            i: Some(&o.record.i),
            fs: o.twin.fs(),
        })
        .collect();
    let mut settings = FrfSettings::periodic(outs[0].excitation.period_samples, 1);
    settings.band = Some((10.0, 2000.0));
    settings.quality_band = Some((10.0, 2000.0));
    settings.i_sat = Some(outs[0].twin.i_sat());
    let names: Vec<String> = cases.iter().map(|c| c.name.clone()).collect();
    let files = operating_point_from_records(&names, &records, &settings).unwrap();
    assert_eq!(files.deviations.len(), twin.deviations.len());
    for (a, b) in files.deviations.iter().zip(&twin.deviations) {
        assert_eq!(
            (a.case.as_str(), a.band.as_str()),
            (b.case.as_str(), b.band.as_str())
        );
        assert_eq!(a.median_rel_dev, b.median_rel_dev);
        assert_eq!(a.max_abs_db_dev, b.max_abs_db_dev);
        assert!(a.truth_median_rel_dev.is_none());
    }
    assert!(files.truth_errors.is_empty());
    // bad input: one record only
    assert!(operating_point_from_records(&names[..1], &records[..1], &settings).is_err());
}

/// The deviation bands come from the nominal estimate, not from the nominal rig's numbers: on 20
/// random rigs (seed experiment, linear twin, 4 periods) the `low` band ends within ±15 % of the
/// −6 dB corner of the rig's **true** plant on the same lines, and the `resonance` band holds the
/// rig's bending-mode frequency.
#[test]
fn deviation_bands_follow_each_random_rig() {
    use ambid::analysis::{analyze, FrfSettings, Record};
    for rig in 0..20u64 {
        let out = common::seed_record_on_rig(rig, 40 + rig, 0.1, 4);
        let twin = &out.twin;
        let rec = &out.record;
        let a = analyze(
            &Record {
                r: &rec.r,
                u: &rec.u,
                y: &rec.y,
                i: None,
                fs: twin.fs(),
            },
            &FrfSettings::periodic(out.excitation.period_samples, 1),
            None,
        )
        .unwrap();
        let bands = ambid::study::deviation_bands(&a.frf.plant);
        // naive oracle: the first line where the true |P| is half its median over the lowest 5 %
        let f = a.frf.plant.f_hz();
        let truth: Vec<f64> = twin
            .plant_frf(f)
            .unwrap()
            .iter()
            .map(|v| v.norm())
            .collect();
        let mut lowest = truth[..(f.len() / 20).max(1)].to_vec();
        lowest.sort_by(f64::total_cmp);
        let level = lowest[lowest.len() / 2];
        let fc_true = f[truth.iter().position(|m| *m <= 0.5 * level).unwrap()];
        let f_bend = ambid_twin::random_rig(rig).unwrap().rotor.bending_freq_hz;
        let names: Vec<&str> = bands.iter().map(|b| b.0.as_str()).collect();
        println!(
            "rig {rig:2}: true corner {fc_true:.1} Hz, bending {f_bend:.0} Hz; bands {bands:.1?}"
        );
        assert_eq!(names, ["low", "resonance", "high"], "rig {rig}");
        let fc = bands[0].2;
        assert!(
            (fc - fc_true).abs() <= 0.15 * fc_true,
            "rig {rig}: corner {fc} vs true {fc_true}"
        );
        assert!(
            bands[1].1 < f_bend && f_bend < bands[1].2,
            "rig {rig}: bending {f_bend} outside {:?}",
            bands[1]
        );
    }
}
