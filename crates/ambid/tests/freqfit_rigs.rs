//! Exploration: FRF fits on random rigs.
use ambid::experiment::{run, ExcitationPlan, Experiment};
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::validate::compare::{
    choose, compare_models, unstable_poles_from_loop, CompareSpec,
};
use ambid_twin::{random_rig, Mode};

#[test]
fn explore() {
    for rig in 1..=20u64 {
        let exp = Experiment {
            twin: random_rig(rig).unwrap(),
            excitation: ExcitationPlan::default(),
            mode: Mode::Linear,
            seed: 100 + rig,
            noise: true,
            record_b: false,
        };
        let out = run(&exp).unwrap();
        let frf = out.periodic_frf((10.0, 1000.0), None).unwrap();
        let f = frf.f_hz().to_vec();
        let truth = out.twin.plant_frf(&f).unwrap();
        let nu = out.twin.plant_unstable_poles().unwrap().len();
        let t1 = std::time::Instant::now();
        let count =
            unstable_poles_from_loop(&frf.plant, out.twin.controller(), Some((10.0, 1000.0)));
        let dtc = t1.elapsed().as_secs_f64();
        let mut fe: Vec<f64> = frf
            .plant
            .values()
            .iter()
            .zip(&truth)
            .map(|(a, b)| (a - b).norm() / b.norm())
            .collect();
        fe.sort_by(f64::total_cmp);
        let spec = CompareSpec {
            unstable_poles: count.as_ref().ok().copied(),
            controller: Some(out.twin.controller().clone()),
            orders: vec![6, 7, 8, 9, 10],
            fit: FreqFitOptions {
                band_hz: Some((10.0, 1000.0)),
                weights: FreqWeights::InverseVariance,
                max_iterations: std::env::var("MAXIT").ok().and_then(|v| v.parse().ok()).unwrap_or(100),
                ..Default::default()
            },
            ..CompareSpec::default()
        };
        let t0 = std::time::Instant::now();
        let rows = compare_models(&frf.plant, &spec, None).unwrap();
        let dt = t0.elapsed().as_secs_f64();
        let ch = choose(&rows);
        let mut s = format!(
            "rig {rig} nu {nu} count {count:?} ({dtc:.3}s) frf-med {:.2} {dt:.2}s chosen {:?}:",
            100.0 * fe[fe.len() / 2],
            ch.map(|i| (rows[i].structure.name(), rows[i].order))
        );
        for r in &rows {
            let med = r.model.as_ref().map(|m| {
                let g = m.freq_response_siso(&f).unwrap();
                let mut e: Vec<f64> = g
                    .iter()
                    .zip(&truth)
                    .map(|(a, b)| (a - b).norm() / b.norm())
                    .collect();
                e.sort_by(f64::total_cmp);
                e[e.len() / 2]
            });
            let bad = r.unstable_poles.map_or(true, |u| u > nu);
            s.push_str(&format!(
                " {}{}:{}/{:.2}{}{}{}",
                r.structure.name(),
                r.order,
                r.unstable_poles.map_or(9, |u| u),
                100.0 * med.unwrap_or(f64::NAN),
                if bad { "!" } else { "" },
                if r.valid { "" } else { "X" },
                if r.note.as_deref().is_some_and(|n| n.contains("limit")) {
                    "L"
                } else {
                    ""
                },
            ));
        }
        eprintln!("{s}");
    }
}
