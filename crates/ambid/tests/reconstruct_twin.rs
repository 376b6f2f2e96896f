//! Closed-loop reconstruction on the twin (issue 6): a 5 µm, 10 s, 1–1000 Hz linear chirp position
//! reference; the model plus the real controller against the twin's own response.

use ambid::experiment::{run, Experiment};
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
use ambid_core::lti::StateSpace;
use ambid_core::signal::chirp::{ChirpSpec, Sweep};
use ambid_core::validate::closed_loop::{reconstruct, simulate_loop};
use ambid_core::validate::residuals::analyze;
use ambid_twin::{Mode, SimOptions, Twin};

const PERIOD: usize = 1023 * 5;

fn chirp(ts: f64) -> Vec<f64> {
    ChirpSpec {
        f0_hz: 1.0,
        f1_hz: 1000.0,
        duration_s: 10.0,
        amplitude: 5e-6,
        sweep: Sweep::Linear,
        periods: 1,
    }
    .generate(ts)
    .unwrap()
    .values
}

/// The twin's response (y, u) to the chirp reference, r = 0.
fn twin_response(twin: &Twin, w: &[f64], noise: bool) -> (Vec<f64>, Vec<f64>) {
    let r = vec![0.0; w.len()];
    let opts = SimOptions {
        mode: Mode::Linear,
        seed: 5,
        noise,
        w: Some(w.to_vec()),
        ..SimOptions::default()
    };
    let rec = twin.simulate(&r, &opts).unwrap();
    (rec.y, rec.u)
}

/// The plant model of `order` fitted to the period-averaged seed-1 plant FRF (10–1000 Hz).
fn identified(order: usize) -> (StateSpace, Twin) {
    let out = run(&Experiment::seed_paper(Mode::Linear, 0.1e-6, 1)).unwrap();
    let frf = out.periodic_frf((10.0, 1000.0), None).unwrap();
    let opts = FreqFitOptions {
        band_hz: Some((10.0, 1000.0)),
        weights: FreqWeights::InverseVariance,
        max_iterations: 200,
        ..Default::default()
    };
    (
        ss_frd(&frf.plant, order, &opts, &SsFreqOptions::default())
            .unwrap()
            .model,
        out.twin,
    )
}

#[test]
fn exact_plant_reconstructs_the_twins_chirp_response() {
    let out = run(&Experiment::seed_paper(Mode::Linear, 0.0, 1)).unwrap();
    let twin = out.twin;
    let ts = 1.0 / twin.fs();
    let w = chirp(ts);
    let (y, u) = twin_response(&twin, &w, false);
    let rec = reconstruct(twin.plant(), twin.controller(), &w, None, &y, &u, 20, ts).unwrap();
    eprintln!(
        "exact plant, noise-free chirp: fit y {:.4} %, u {:.4} %",
        rec.fit_y, rec.fit_u
    );
    assert!(
        rec.fit_y >= 99.0 && rec.fit_u >= 99.0,
        "{} {}",
        rec.fit_y,
        rec.fit_u
    );
}

#[test]
fn identified_order_7_reconstructs_and_order_5_is_located_and_rejected() {
    let (m7, twin) = identified(7);
    // order 5: too low for the rigid-body modes, the anti-resonance and the bending mode together
    // (order 4 is worse still: its loop with the controller is unstable and cannot be simulated)
    let (m5, _) = identified(5);
    let ts = 1.0 / twin.fs();
    let w = chirp(ts);
    // against the noisy response the current is limited by the controller's reaction to the
    // sensor noise (the exact plant scores the ceiling); the model error is measured against the
    // noise-free response
    let (yn, un) = twin_response(&twin, &w, true);
    let ceiling = reconstruct(twin.plant(), twin.controller(), &w, None, &yn, &un, 20, ts).unwrap();
    let noisy = reconstruct(&m7, twin.controller(), &w, None, &yn, &un, 20, ts).unwrap();
    eprintln!(
        "with 0.1 µm sensor noise: exact plant fit y {:.2} %, u {:.2} % (ceiling); order 7 fit y {:.2} %, u {:.2} %",
        ceiling.fit_y, ceiling.fit_u, noisy.fit_y, noisy.fit_u
    );
    let (y, u) = twin_response(&twin, &w, false);
    let r7 = reconstruct(&m7, twin.controller(), &w, None, &y, &u, 20, ts).unwrap();
    eprintln!(
        "identified order 7, noise-free response: chirp reconstruction fit y {:.2} %, u {:.2} %",
        r7.fit_y, r7.fit_u
    );
    assert!(
        r7.fit_y >= 95.0 && r7.fit_u >= 95.0,
        "{} {}",
        r7.fit_y,
        r7.fit_u
    );
    // margins of the identified loop against the exact loop (log grid up to 9.8 kHz)
    let grid: Vec<f64> = (0..4000)
        .map(|k| 0.5 * (9800.0f64 / 0.5).powf(k as f64 / 3999.0))
        .collect();
    let lg = |p: &StateSpace| -> ambid_core::validate::margins::Margins {
        let (gp, gc) = (
            p.freq_response_siso(&grid).unwrap(),
            twin.controller().freq_response_siso(&grid).unwrap(),
        );
        let l: Vec<ambid_core::c64> = gp.iter().zip(&gc).map(|(a, b)| a * b).collect();
        ambid_core::validate::margins::margins(&grid, &l).unwrap()
    };
    let (me, mi) = (lg(twin.plant()), lg(&m7));
    eprintln!(
        "margins exact / order 7: phase {:.2} / {:.2} deg, lower gain {:.4} / {:.4}, upper gain {:.3} / {:.3}, max|S| {:.3} / {:.3}",
        me.phase_margin().unwrap(), mi.phase_margin().unwrap(),
        me.lower_gain_margin().unwrap(), mi.lower_gain_margin().unwrap(),
        me.upper_gain_margin().unwrap(), mi.upper_gain_margin().unwrap(),
        me.peak_sensitivity.0, mi.peak_sensitivity.0
    );
    assert!((me.phase_margin().unwrap() - mi.phase_margin().unwrap()).abs() < 1.0);
    assert!((me.lower_gain_margin().unwrap() / mi.lower_gain_margin().unwrap() - 1.0).abs() < 0.02);
    assert!((me.peak_sensitivity.0 / mi.peak_sensitivity.0 - 1.0).abs() < 0.02);
    let r5 = reconstruct(&m5, twin.controller(), &w, None, &y, &u, 20, ts).unwrap();
    let worst = r5.worst_window().unwrap();
    // a linear chirp 1–1000 Hz over 10 s: the window's frequency band
    let band = (1.0 + 99.9 * worst.t_s.0, 1.0 + 99.9 * worst.t_s.1);
    eprintln!(
        "order 5: fit y {:.2} %, u {:.2} %; worst window {:.1}–{:.1} s ({:.0}–{:.0} Hz): fit y {:.1} %",
        r5.fit_y, r5.fit_u, worst.t_s.0, worst.t_s.1, band.0, band.1, worst.fit_y
    );
    assert!(r5.fit_y < 90.0, "{}", r5.fit_y);
    // located between the plant's anti-resonance (611 Hz) and its bending mode (754 Hz)
    assert!(band.0 >= 500.0 && band.1 <= 800.0, "{band:?}");
    // residual test on the independent seed-2 record (closed-loop simulation error against r):
    // the exact plant passes, order 5 fails; order 7 is printed: with 97 000 samples the test
    // resolves model errors of ~0.01 % of the output, below the 7th-order model's 0.1 %
    let val = run(&Experiment::seed_paper(Mode::Linear, 0.1e-6, 2)).unwrap();
    let r = &val.record.r;
    for (name, m, pass) in [
        ("exact plant", twin.plant(), Some(true)),
        ("order 7", &m7, None),
        ("order 5", &m5, Some(false)),
    ] {
        match simulate_loop(m, twin.controller(), r) {
            Ok(sim) => {
                let eps: Vec<f64> = val
                    .record
                    .y
                    .iter()
                    .zip(&sim.y)
                    .map(|(a, b)| a - b)
                    .collect();
                let t = analyze(&eps[PERIOD..], Some(&r[PERIOD..]), 25).unwrap();
                let c = t.independence.unwrap();
                eprintln!(
                    "{name}: residual–reference cross-correlation statistic {:.1} (95 % threshold {:.1}), {} of {} lags outside",
                    c.statistic, c.threshold, c.exceeding.len(), c.lags.len()
                );
                if let Some(pass) = pass {
                    assert_eq!(c.pass, pass, "{name}");
                }
            }
            Err(e) => panic!("{name}: {e}"),
        }
    }
}
