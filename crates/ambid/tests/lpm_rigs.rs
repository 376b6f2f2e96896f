//! The LPM's defaults on records it was not tuned on: 20 random rigs of the linear twin
//! (`ambid_twin::random_rig`, every physical and controller parameter drawn ±15–30 %), three
//! records each at the seed experiment's length (102 300 samples at 20 kHz, 10 % of i_sat):
//!
//! * (a) Gaussian noise band-limited to 1–2000 Hz (non-periodic),
//! * (b) one logarithmic chirp 1–2000 Hz over the whole record (non-periodic),
//! * (c) the seed PRBS (n = 10, 5 samples per bit, 20 periods: periodic).
//!
//! The LPM runs with its defaults as `ambid frf --method lpm` does: [`LpmOptions::auto`] on the
//! default band 1 Hz–fs/2. Its plant is compared with the rig's exact `Twin::plant_frf` and with
//! the estimator a user would otherwise take on the same record: Welch as `ambid frf` runs it
//! by default (Hann, nperseg = N/8, 50 % overlap) for (a) and (b), period averaging (first
//! period dropped) for (c). Errors are medians of |Ĝ − G|/|G| over each estimator's lines in
//! 10–2000 Hz, the band where every record has power.

use crate::common::{ambid, s, text, tmpdir};
use ambid::analysis::{analyze, FrfSettings, Record};
use ambid::experiment::{run, ExcitationKind, ExcitationPlan, Experiment, ExperimentOutput};
use ambid_core::c64;
use ambid_core::frf::lpm::{lpm_closed_loop, LpmClosedLoop, LpmOptions};
use ambid_core::frf::lrm::{lrm_closed_loop, LrmOptions};
use ambid_core::Error;
use ambid_twin::{random_rig, Mode};

/// Where the errors are compared: every record excites 1–2000 Hz.
const EVAL: (f64, f64) = (10.0, 2000.0);

fn median(x: &[f64]) -> f64 {
    let mut v = x.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median relative plant error over the lines of `f` in [`EVAL`] up to `f_max` Hz.
fn plant_error(out: &ExperimentOutput, f: &[f64], est: &[c64], f_max: f64) -> f64 {
    let (ff, vv): (Vec<f64>, Vec<c64>) = f
        .iter()
        .zip(est)
        .filter(|(f, _)| (EVAL.0..=EVAL.1.min(f_max)).contains(*f))
        .map(|(f, v)| (*f, *v))
        .unzip();
    let truth = out.twin.plant_frf(&ff).unwrap();
    let e: Vec<f64> = vv
        .iter()
        .zip(&truth)
        .map(|(e, t)| (e - t).norm() / t.norm())
        .collect();
    median(&e)
}

/// A record of rig `rig` (sensor-noise seed 2000 + rig, excitation seed 1000 + rig) with
/// `kind`; noise and chirp are one non-periodic record of `periods` × 5115 samples.
fn experiment(rig: u64, kind: ExcitationKind, periods: usize) -> ExperimentOutput {
    let mut excitation = ExcitationPlan {
        kind,
        seed: 1000 + rig,
        periods,
        ..ExcitationPlan::default()
    };
    if kind == ExcitationKind::Chirp {
        // one sweep over the whole record
        excitation.period_s *= periods as f64;
        excitation.periods = 1;
    }
    let twin = random_rig(rig).unwrap();
    let noise = twin.sensor.noise_rms_m > 0.0;
    run(&Experiment {
        twin,
        excitation,
        mode: Mode::Linear,
        seed: 2000 + rig,
        noise,
        record_b: false,
    })
    .unwrap()
}

fn lpm_default(out: &ExperimentOutput) -> LpmClosedLoop {
    let rec = &out.record;
    let fs = 1.0 / rec.ts;
    lpm_closed_loop(
        &rec.r,
        &rec.u,
        &rec.y,
        fs,
        (1.0, 0.5 * fs),
        &LpmOptions::auto(),
    )
    .unwrap()
}

/// Welch as `ambid frf` runs it by default: frequencies and plant.
fn welch_default(out: &ExperimentOutput) -> (Vec<f64>, Vec<c64>) {
    let rec = &out.record;
    let record = Record {
        r: &rec.r,
        u: &rec.u,
        y: &rec.y,
        i: None,
        fs: 1.0 / rec.ts,
    };
    // as `ambid frf` runs it on a file: nperseg = N/8, the band derived from the excitation
    let settings = FrfSettings::welch(rec.r.len() / 8);
    let a = analyze(&record, &settings, None).unwrap();
    (a.frf.f_hz().to_vec(), a.frf.plant.values().to_vec())
}

/// Median plant errors of the LPM and Welch over the range both report.
fn lpm_and_welch(out: &ExperimentOutput, cl: &LpmClosedLoop) -> (f64, f64) {
    let (wf, wv) = welch_default(out);
    let top = wf
        .last()
        .copied()
        .unwrap_or(0.0)
        .min(cl.f_hz().last().copied().unwrap_or(0.0));
    (
        plant_error(out, cl.f_hz(), cl.plant.values(), top),
        plant_error(out, &wf, &wv, top),
    )
}

#[test]
fn lpm_default_is_as_good_as_welch_or_period_averaging_on_20_rigs() {
    let t0 = std::time::Instant::now();
    let mut worst: [(f64, u64); 3] = [(0.0, 0); 3];
    for rig in 1..=20u64 {
        // (a), (b): non-periodic records, the window chosen from the data
        for (i, kind) in [ExcitationKind::Noise, ExcitationKind::Chirp]
            .into_iter()
            .enumerate()
        {
            let out = experiment(rig, kind, 20);
            let cl = lpm_default(&out);
            assert_eq!(cl.fit.periods(), None);
            assert!(cl.fit.window_chosen());
            let (e, w) = lpm_and_welch(&out, &cl);
            // band limited to where r has power: nothing below 1.9 kHz is left out, everything
            // above 2.2 kHz is (the excitation stops at 2 kHz)
            let df = 1.0 / (out.record.ts * out.record.r.len() as f64);
            let f_last = *cl.f_hz().last().unwrap();
            assert!(
                (2000.0..2200.0).contains(&f_last),
                "rig {rig} {kind:?}: last line {f_last} Hz"
            );
            let first_out = cl.fit.excluded_lines().first().map(|&k| k as f64 * df);
            assert!(
                first_out.is_some_and(|f| f > 1900.0),
                "rig {rig} {kind:?}: first line left out at {first_out:?} Hz"
            );
            eprintln!(
                "rig {rig:2} {kind:?}: LPM (R = {}, n = {}) {:.3} % vs Welch {:.3} % (ratio {:.2}), {} lines left out",
                cl.fit.degree(),
                cl.fit.half_width(),
                100.0 * e,
                100.0 * w,
                e / w,
                cl.fit.excluded_lines().len()
            );
            assert!(e <= 1.5 * w, "rig {rig} {kind:?}: LPM {e} vs Welch {w}");
            if e / w > worst[i].0 {
                worst[i] = (e / w, rig);
            }
        }
        // (c): the periodic seed PRBS: the periodic LPM on the excited lines
        let out = experiment(rig, ExcitationKind::Prbs, 20);
        let cl = lpm_default(&out);
        assert_eq!(cl.fit.periods(), Some(20));
        assert!(cl.fit.lines().iter().all(|k| k % 20 == 0));
        // the PRBS (5 samples per bit) has nulls at multiples of 4 kHz: left out, not an error
        assert!(cl.f_hz().iter().all(|f| (f - 4000.0).abs() > 10.0));
        assert!(cl
            .fit
            .excluded_lines()
            .iter()
            .any(|&k| (k as f64 * 20_000.0 / 102_300.0 - 4000.0).abs() < 1.0));
        let per = out.periodic_frf((1.0, 10_000.0), None).unwrap();
        let top = *per.f_hz().last().unwrap();
        let e = plant_error(&out, cl.f_hz(), cl.plant.values(), top);
        let p = plant_error(&out, per.f_hz(), per.plant.values(), top);
        eprintln!(
            "rig {rig:2} PRBS: periodic LPM {:.3} % vs period averaging {:.3} % (ratio {:.2}), {} lines left out",
            100.0 * e,
            100.0 * p,
            e / p,
            cl.fit.excluded_lines().len()
        );
        assert!(
            e <= 1.5 * p,
            "rig {rig} PRBS: LPM {e} vs period averaging {p}"
        );
        if e / p > worst[2].0 {
            worst[2] = (e / p, rig);
        }
    }
    eprintln!(
        "worst ratio (rig): noise {:.2} ({}), chirp {:.2} ({}), PRBS {:.2} ({}); {:.1} s",
        worst[0].0,
        worst[0].1,
        worst[1].0,
        worst[1].1,
        worst[2].0,
        worst[2].1,
        t0.elapsed().as_secs_f64()
    );
}

/// The window follows the record: on one PRBS period's worth of noise (5115 samples, 3.9 Hz
/// lines) the chosen window is narrower than on the 20 times longer record of the same rig.
/// (On such short, noisy records Welch with 8 segments can beat the LPM — rig 11: 29 % against
/// 13 % — so no accuracy bar is asserted here; see docs/lpm.md.)
#[test]
fn lpm_default_window_narrows_on_short_records() {
    for rig in [3u64, 11, 17] {
        let long = lpm_default(&experiment(rig, ExcitationKind::Noise, 20));
        let out = experiment(rig, ExcitationKind::Noise, 1);
        let short = lpm_default(&out);
        eprintln!(
            "rig {rig}: long record R = {}, n = {}; short record R = {}, n = {}",
            long.fit.degree(),
            long.fit.half_width(),
            short.fit.degree(),
            short.fit.half_width()
        );
        assert!(short.fit.half_width() < long.fit.half_width());
        assert!(short.fit.half_width() <= 11);
        let (e, w) = lpm_and_welch(&out, &short);
        eprintln!(
            "  short record: LPM {:.2} %, Welch {:.2} %",
            100.0 * e,
            100.0 * w
        );
    }
}

/// What a user sees: the messages name the LPM's input r, a periodic record gets the periodic
/// LPM (or, from the LRM, a refusal that says what to use), and a band without excitation says
/// so.
#[test]
fn lpm_messages_on_periodic_and_unexcited_records() {
    let out = experiment(5, ExcitationKind::Prbs, 20);
    let rec = &out.record;
    let fs = 1.0 / rec.ts;
    // LRM on the periodic PRBS: refused, naming r and both alternatives
    let err = lrm_closed_loop(
        &rec.r,
        &rec.u,
        &rec.y,
        fs,
        (10.0, 1000.0),
        &LrmOptions::default(),
    )
    .unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, Error::InvalidArgument { name: "r", .. }),
        "{msg}"
    );
    assert!(
        msg.contains("the input r is periodic (20 periods of 5115 samples)"),
        "{msg}"
    );
    assert!(msg.contains("--method lpm") && msg.contains("--period-samples 5115"));
    // periodic LPM on a band between two excited lines (3.91 Hz apart)
    let err = lpm_closed_loop(
        &rec.r,
        &rec.u,
        &rec.y,
        fs,
        (102.0, 105.0),
        &LpmOptions::auto(),
    )
    .unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, Error::InvalidArgument { name: "r", .. }),
        "{msg}"
    );
    assert!(
        msg.contains("only on every 20-th DFT line (3.9101 Hz apart)"),
        "{msg}"
    );
    // band-limited noise (1–2000 Hz) asked for 3–4 kHz
    let out = experiment(5, ExcitationKind::Noise, 1);
    let rec = &out.record;
    let err = lpm_closed_loop(
        &rec.r,
        &rec.u,
        &rec.y,
        fs,
        (3000.0, 4000.0),
        &LpmOptions::auto(),
    )
    .unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, Error::InvalidArgument { name: "r", .. }),
        "{msg}"
    );
    assert!(
        msg.contains("the input r has no power in 3000–4000 Hz"),
        "{msg}"
    );
}

/// `ambid frf --method lpm` with its defaults on a random rig's periodic PRBS record (the
/// case that failed with "no power in the window around line 6"): the periodic LPM, the PRBS
/// nulls reported, the plant close to the truth; the LRM refuses with the documented message.
#[test]
fn cli_lpm_on_a_periodic_record_of_a_random_rig() {
    let d = tmpdir("lpm-rig");
    let o = ambid(&[
        "simulate",
        "--rig-seed",
        "7",
        "--mode",
        "linear",
        "--out",
        s(&d),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let data = d.join("data.csv");
    let out = d.join("frf.csv");
    let o = ambid(&["frf", s(&data), "--method", "lpm", "--out", s(&out)]);
    let t = text(&o);
    println!("{t}");
    assert!(o.status.success(), "{t}");
    assert!(t.contains("LPM for periodic data: r holds 20 periods of 5115 samples"));
    assert!(t.contains("left out: "));
    let frf = ambid::io::csv::read_frf_csv(&out).unwrap();
    let est = frf.frd("plant", 5e-5).unwrap();
    let twin = ambid_twin::Twin::new(random_rig(7).unwrap()).unwrap();
    let (f, v): (Vec<f64>, Vec<c64>) = est
        .f_hz()
        .iter()
        .zip(est.values())
        .filter(|(f, _)| (10.0..=1000.0).contains(*f))
        .map(|(f, v)| (*f, *v))
        .unzip();
    let med = ambid::validation::median_relative_error(&v, &twin.plant_frf(&f).unwrap());
    println!(
        "periodic LPM plant, 10–1000 Hz: median {:.3} %",
        100.0 * med
    );
    assert!(med < 0.05, "{med}");
    let o = ambid(&[
        "frf",
        s(&data),
        "--method",
        "lrm",
        "--out",
        s(&d.join("lrm.csv")),
    ]);
    let t = text(&o);
    assert!(!o.status.success());
    assert!(
        t.contains("the input r is periodic (20 periods of 5115 samples)"),
        "{t}"
    );
    assert!(!d.join("lrm.csv").exists());
    // a record that is not a whole number of periods (the first 100 000 samples): the line
    // pattern shows no period, the LPM for non-periodic data runs; with --period-samples the
    // record is cut to 19 whole periods and the periodic LPM runs
    let cut = d.join("cut.csv");
    let all = std::fs::read_to_string(&data).unwrap();
    let head: Vec<&str> = all.lines().take(100_001).collect();
    std::fs::write(&cut, head.join("\n") + "\n").unwrap();
    let median_on = |path: &std::path::Path| {
        let frf = ambid::io::csv::read_frf_csv(path).unwrap();
        let est = frf.frd("plant", 5e-5).unwrap();
        let (f, v): (Vec<f64>, Vec<c64>) = est
            .f_hz()
            .iter()
            .zip(est.values())
            .filter(|(f, _)| (10.0..=1000.0).contains(*f))
            .map(|(f, v)| (*f, *v))
            .unzip();
        ambid::validation::median_relative_error(&v, &twin.plant_frf(&f).unwrap())
    };
    let o = ambid(&[
        "frf",
        s(&cut),
        "--method",
        "lpm",
        "--out",
        s(&d.join("c1.csv")),
    ]);
    let t = text(&o);
    println!("{t}");
    assert!(o.status.success(), "{t}");
    assert!(t.contains("chosen from the record"), "{t}");
    let med_np = median_on(&d.join("c1.csv"));
    let o = ambid(&[
        "frf",
        s(&cut),
        "--method",
        "lpm",
        "--period-samples",
        "5115",
        "--out",
        s(&d.join("c2.csv")),
    ]);
    let t = text(&o);
    println!("{t}");
    assert!(o.status.success(), "{t}");
    assert!(t.contains("using the first 19 whole periods (97185 of 100000 samples)"));
    assert!(t.contains("r holds 19 periods of 5115 samples"));
    let med_p = median_on(&d.join("c2.csv"));
    println!(
        "100 000 samples of the periodic record: non-periodic LPM {:.3} %, cut to 19 periods {:.3} %",
        100.0 * med_np,
        100.0 * med_p
    );
    assert!(med_p < 0.05, "{med_p}");
}
