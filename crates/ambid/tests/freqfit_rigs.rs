//! FRF fits and the model comparison on 20 random rigs of the twin (`ambid_twin::random_rig`,
//! linear twin, the seed experiment with each rig's own noise, plant FRF by period averaging on
//! the excited lines in 10–1000 Hz): the number of unstable plant poles found from the data (the
//! Nyquist count of the measured loop with the rig's controller) equals the truth's on every
//! rig, no fit (ARX, OE, SS at orders 6–10) carries more unstable poles than the plant, and the
//! chosen model of the default comparison (orders 6–9) is valid and close to the exact plant.

use crate::common::{median, rig_experiment};

use ambid::experiment::{run, ExcitationPlan};
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::validate::compare::{
    choose, compare_models, unstable_poles_from_loop, CompareRow, CompareSpec, ValidationRecord,
};

const PERIOD: usize = 1023 * 5;

#[test]
fn frf_fits_keep_the_plants_unstable_poles_on_random_rigs() {
    let t0 = std::time::Instant::now();
    let (mut chosen_bic, mut chosen_val) = (Vec::new(), Vec::new());
    let mut fits = 0;
    for rig in 1..=20u64 {
        let default_amp = ExcitationPlan::default().amplitude_frac;
        let out = run(&rig_experiment(rig, 100 + rig, default_amp)).unwrap();
        let val = run(&rig_experiment(rig, 200 + rig, 1.2 * default_amp)).unwrap();
        let frf = out.periodic_frf((10.0, 1000.0), None).unwrap();
        let f = frf.f_hz().to_vec();
        let twin = &out.twin;
        let truth = twin.plant_frf(&f).unwrap();
        let n_true = twin.plant_unstable_poles().unwrap().len();
        // the count from the data equals the truth's
        let n_u =
            unstable_poles_from_loop(&frf.plant, twin.controller(), Some((10.0, 1000.0))).unwrap();
        assert_eq!(n_u, n_true, "rig {rig}: Nyquist count");
        let spec = CompareSpec {
            orders: vec![6, 7, 8, 9, 10],
            fit: FreqFitOptions {
                band_hz: Some((10.0, 1000.0)),
                weights: FreqWeights::InverseVariance,
                ..Default::default()
            },
            unstable_poles: Some(n_u),
            controller: Some(twin.controller().clone()),
            ..CompareSpec::default()
        };
        let rec = ValidationRecord {
            r: &val.record.r,
            y: &val.record.y,
            controller: twin.controller(),
            skip: PERIOD,
        };
        let rows = compare_models(&frf.plant, &spec, Some(rec)).unwrap();
        let err_of = |r: &CompareRow| {
            let g = r.model.as_ref().unwrap().freq_response_siso(&f).unwrap();
            median(
                g.iter()
                    .zip(&truth)
                    .map(|(a, b)| (a - b).norm() / b.norm())
                    .collect(),
            )
        };
        for r in &rows {
            fits += 1;
            let u = r.unstable_poles.expect("every fit succeeds");
            assert!(
                u <= n_true,
                "rig {rig} {} {}: {u} unstable poles, the plant has {n_true}",
                r.structure.name(),
                r.order
            );
        }
        // the default comparison: orders 6–9
        let default_rows: Vec<CompareRow> = rows.iter().filter(|r| r.order <= 9).cloned().collect();
        let frf_err = median(
            frf.plant
                .values()
                .iter()
                .zip(&truth)
                .map(|(a, b)| (a - b).norm() / b.norm())
                .collect(),
        );
        // by the validation fit (the workflow's default) and by BIC (no validation record)
        let by_val = choose(&default_rows).unwrap();
        let no_val: Vec<CompareRow> = default_rows
            .iter()
            .cloned()
            .map(|mut r| {
                r.validation_fit = None;
                r
            })
            .collect();
        let by_bic = choose(&no_val).unwrap();
        for (i, store) in [(by_val, &mut chosen_val), (by_bic, &mut chosen_bic)] {
            let r = &default_rows[i];
            assert!(
                r.valid && r.unstable_poles == Some(n_true) && r.closed_loop_stable == Some(true)
            );
            let e = err_of(r);
            store.push(e);
            // 0.5 %, or where the rig's FRF is too noisy for it, 1/5 of the FRF's own error
            // (an efficient fit of 2n parameters to L lines reduces it by about sqrt(2n/2L))
            assert!(
                e <= 0.005_f64.max(0.2 * frf_err),
                "rig {rig}: chosen {} {} median error {e} (FRF's own {frf_err})",
                r.structure.name(),
                r.order
            );
        }
        eprintln!(
            "rig {rig}: {n_u} unstable (truth {n_true}); FRF median error {:.2} %; chosen by validation fit {} {} ({:.3} %), by BIC {} {} ({:.3} %)",
            100.0 * frf_err,
            default_rows[by_val].structure.name(),
            default_rows[by_val].order,
            100.0 * chosen_val[chosen_val.len() - 1],
            default_rows[by_bic].structure.name(),
            default_rows[by_bic].order,
            100.0 * chosen_bic[chosen_bic.len() - 1],
        );
    }
    let (mv, mb) = (median(chosen_val.clone()), median(chosen_bic.clone()));
    let within = |v: &[f64]| v.iter().filter(|e| **e <= 0.005).count();
    eprintln!(
        "{fits} fits; chosen model's median plant error over the rigs: {:.3} % (validation fit), {:.3} % (BIC); within 0.5 % on {} / {} rigs; {:.1} s",
        100.0 * mv,
        100.0 * mb,
        within(&chosen_val),
        within(&chosen_bic),
        t0.elapsed().as_secs_f64()
    );
    assert!(mv <= 0.005 && mb <= 0.005);
}
