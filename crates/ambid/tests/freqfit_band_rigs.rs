//! The FRF-fit band derived from the data (`ambid_core::frf::band::fit_band`, the default of
//! `ambid fit frf.csv`, `ambid compare-models` and the workflow's models step) on 20 random rigs
//! of the twin (`ambid_twin::random_rig`, linear twin, the seed experiment with each rig's own
//! noise): the FRF is what `ambid frf --period-samples 5115 --skip-periods 1 --controller …`
//! computes with its defaults (the excited band, up to ~3 kHz), and nothing about the nominal
//! rig's 10–1000 Hz is given. Two noise realisations per rig. Against each rig's exact plant (`Twin::plant_frf`) over 10–1000 Hz:
//! the default comparison's chosen model is within 0.5 % median (or 1/5 of the FRF's own error
//! where the FRF is too noisy for it, the rule of `freqfit_rigs`; on a rig where the same
//! comparison over the nominal 10–1000 Hz misses that rule too, within 1.25 times its error),
//! the median over the rigs is within 0.5 %, and the order-8 state-space
//! fit over the derived band is within a factor 1.5 (+0.05 %) of the fit over the explicit
//! 10–1000 Hz, and the median error it reports against the FRF measures the FRF's noise on
//! the band (≤ the rule's 20 %, ≤ 1.25 × the FRF's own error there).

use crate::common::{median, rig_experiment};

use ambid::analysis::{analyze, FrfSettings, Record};
use ambid::experiment::{run, ExcitationPlan};
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::frf::band::{fit_band, FIT_REL_HALFWIDTH};
use ambid_core::lti::Structure;
use ambid_core::validate::compare::{
    choose, compare_models, supported_unstable_poles, CompareRow, CompareSpec, ValidationRecord,
};

#[test]
fn the_derived_fit_band_holds_on_random_rigs() {
    let t0 = std::time::Instant::now();
    let amp = ExcitationPlan::default().amplitude_frac;
    let (mut chosen, mut ratios, mut bands) = (Vec::new(), Vec::new(), Vec::new());
    let mut by_rule = 0;
    // two noise realisations per rig (identification seeds 301–320 and 501–520, validation
    // records 401–420 and 601–620)
    for (rig, seed) in (1..=20u64).flat_map(|k| [(k, 300 + k), (k, 500 + k)]) {
        let out = run(&rig_experiment(rig, seed, amp)).unwrap();
        let val = run(&rig_experiment(rig, seed + 100, 1.2 * amp)).unwrap();
        let twin = &out.twin;
        let ctrl = twin.controller();
        let rec = &out.record;
        // `ambid frf … --period-samples 5115 --skip-periods 1 --controller`: default bands
        let settings = FrfSettings {
            controller: Some(ctrl.clone()),
            ..FrfSettings::periodic(1023 * 5, 1)
        };
        let an = analyze(
            &Record {
                r: &rec.r,
                u: &rec.u,
                y: &rec.y,
                i: None,
                fs: 1.0 / rec.ts,
            },
            &settings,
            None,
        )
        .unwrap();
        let frd = &an.frf.plant;
        let fb = fit_band(frd, FIT_REL_HALFWIDTH).unwrap();
        assert!(fb.from_variance, "rig {rig} seed {seed}: {}", fb.describe());
        // the derived band is narrower than the file (which runs to the PRBS's 10 dB edge)
        let f_all = frd.f_hz();
        assert!(
            fb.band.1 < 0.8 * f_all[f_all.len() - 1],
            "rig {rig} seed {seed}: {}",
            fb.describe()
        );
        bands.push(fb.band);
        // the truth over 10–1000 Hz on the FRF's lines
        let idx: Vec<usize> = (0..f_all.len())
            .filter(|&k| f_all[k] >= 10.0 && f_all[k] <= 1000.0)
            .collect();
        let f: Vec<f64> = idx.iter().map(|&k| f_all[k]).collect();
        let truth = twin.plant_frf(&f).unwrap();
        let err = |g: &[ambid_core::c64]| {
            median(
                g.iter()
                    .zip(&truth)
                    .map(|(a, b)| (a - b).norm() / b.norm())
                    .collect(),
            )
        };
        let frf_err = err(&idx.iter().map(|&k| frd.values()[k]).collect::<Vec<_>>());
        let model_err =
            |r: &CompareRow| err(&r.model.as_ref().unwrap().freq_response_siso(&f).unwrap());
        // `compare-models frf.csv --controller c --validation v.csv` defaults: structures
        // arx,oe,ss, orders 6–9, 400 iterations, skip 0, the count on all lines
        let (n_u, how) = supported_unstable_poles(frd, Some(ctrl), None, None);
        assert_eq!(
            n_u,
            Some(twin.plant_unstable_poles().unwrap().len()),
            "rig {rig} seed {seed}: {how}"
        );
        let spec = |structures: Vec<Structure>, orders: Vec<usize>, band| CompareSpec {
            structures,
            orders,
            fit: FreqFitOptions {
                band_hz: Some(band),
                weights: FreqWeights::InverseVariance,
                max_iterations: 400,
                ..Default::default()
            },
            unstable_poles: n_u,
            controller: Some(ctrl.clone()),
            ..CompareSpec::default()
        };
        let all = vec![Structure::Arx, Structure::Oe, Structure::Ss];
        let vrec = ValidationRecord {
            r: &val.record.r,
            y: &val.record.y,
            controller: ctrl,
            skip: 0,
        };
        let rows = compare_models(
            frd,
            &spec(all.clone(), vec![6, 7, 8, 9], fb.band),
            Some(vrec),
        )
        .unwrap();
        let rows_x = compare_models(
            frd,
            &spec(all, vec![6, 7, 8, 9], (10.0, 1000.0)),
            Some(vrec),
        )
        .unwrap();
        let e_x = model_err(&rows_x[choose(&rows_x).unwrap()]);
        let i = choose(&rows).unwrap_or_else(|| panic!("rig {rig} seed {seed}: no valid row"));
        let e = model_err(&rows[i]);
        // 0.5 %, or 1/5 of the FRF's own error where the FRF is too noisy for 0.5 % (the rule
        // of freqfit_rigs); where the same comparison over the nominal 10–1000 Hz misses that
        // rule too (unmodelled dynamics at orders 6–9 on this rig's noise), no worse than it
        let rule = e <= 0.005_f64.max(0.2 * frf_err);
        let rule_x = e_x <= 0.005_f64.max(0.2 * frf_err);
        if rule {
            by_rule += 1;
        }
        assert!(
            rule || (!rule_x && e <= 1.25 * e_x),
            "rig {rig} seed {seed}: chosen {} {} over {} has median error {e} (FRF's own {frf_err}; over 10–1000 Hz {e_x})",
            rows[i].structure.name(),
            rows[i].order,
            fb.describe()
        );
        chosen.push(e);
        // `fit frf.csv --structure ss --order 8` (default band) against `--band 10:1000`
        let ss = |band| {
            let r = compare_models(frd, &spec(vec![Structure::Ss], vec![8], band), None).unwrap();
            model_err(&r[0])
        };
        let (e_def, e_exp) = (ss(fb.band), ss((10.0, 1000.0)));
        // the figure `fit` prints (median relative error against the FRF on the band) measures
        // the FRF's noise on the derived band, not unexcited lines: within the rule's ±20 % and
        // within 1.25 times the FRF's own error against the truth on the same lines (over every
        // line of the file it was 7–58 % on these rigs)
        let reported = {
            let r =
                compare_models(frd, &spec(vec![Structure::Ss], vec![8], fb.band), None).unwrap();
            r[0].median_relative.unwrap()
        };
        let in_band: Vec<usize> = (0..f_all.len())
            .filter(|&k| f_all[k] >= fb.band.0 && f_all[k] <= fb.band.1)
            .collect();
        let fb_f: Vec<f64> = in_band.iter().map(|&k| f_all[k]).collect();
        let frf_err_band = median(
            in_band
                .iter()
                .zip(twin.plant_frf(&fb_f).unwrap())
                .map(|(&k, t)| (frd.values()[k] - t).norm() / t.norm())
                .collect(),
        );
        assert!(
            reported <= FIT_REL_HALFWIDTH && reported <= 1.25 * frf_err_band + 1e-3,
            "rig {rig} seed {seed}: SS(8) reports a median error {reported} on the derived band, the FRF's own error there is {frf_err_band}"
        );
        assert!(
            e_def <= 1.5 * e_exp + 5e-4,
            "rig {rig} seed {seed}: SS(8) over the derived {} has median error {e_def}, over 10–1000 Hz {e_exp}",
            fb.describe()
        );
        ratios.push(e_def / e_exp);
        eprintln!(
            "rig {rig} seed {seed}: derived band {:.1}–{:.1} Hz; FRF error {:.2} % (on the derived band {:.2} %, SS(8) reports {:.2} %); chosen {} {} {:.3} % (10–1000 Hz: {:.3} %); SS(8) {:.3} % (10–1000 Hz: {:.3} %)",
            fb.band.0,
            fb.band.1,
            100.0 * frf_err,
            100.0 * frf_err_band,
            100.0 * reported,
            rows[i].structure.name(),
            rows[i].order,
            100.0 * e,
            100.0 * e_x,
            100.0 * e_def,
            100.0 * e_exp
        );
    }
    let within = chosen.iter().filter(|e| **e <= 0.005).count();
    let (lo, hi) = bands
        .iter()
        .fold((f64::MAX, 0.0f64), |a, b| (a.0.min(b.1), a.1.max(b.1)));
    eprintln!(
        "derived upper band edge {lo:.0}–{hi:.0} Hz; chosen model's median plant error over the rigs {:.3} % (within 0.5 % on {within} / 40, within the FRF-noise rule on {by_rule} / 40); SS(8) derived/explicit error ratio median {:.2}, max {:.2}; {:.1} s",
        100.0 * median(chosen.clone()),
        median(ratios.clone()),
        ratios.iter().fold(0.0f64, |a, b| a.max(*b)),
        t0.elapsed().as_secs_f64()
    );
    assert!(median(chosen) <= 0.005);
}
