//! ambid's nonparametric FRFs against a numpy/scipy reference pipeline on the same twin data
//! (fixture from `tests/fixtures/make_frf_reference.py`).

use ambid::experiment::{run, Experiment};
use ambid_core::c64;
use ambid_core::frf::closed_loop::{from_periodic, Channels};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
use ambid_twin::Mode;
use serde_json::Value;

fn fixture() -> Value {
    let p = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/frf_reference.json"
    );
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

fn complex(v: &Value, re: &str, im: &str) -> Vec<c64> {
    let re = v[re].as_array().unwrap();
    let im = v[im].as_array().unwrap();
    re.iter()
        .zip(im)
        .map(|(a, b)| c64::new(a.as_f64().unwrap(), b.as_f64().unwrap()))
        .collect()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn seed_record() -> ambid::experiment::ExperimentOutput {
    run(&Experiment::seed_paper(Mode::Linear, 1e-7, 1)).unwrap()
}

fn median_p90(mut e: Vec<f64>) -> (f64, f64) {
    e.sort_by(|a, b| a.total_cmp(b));
    (e[e.len() / 2], e[(e.len() - 1) * 9 / 10])
}

#[test]
fn period_averaging_equals_the_numpy_pipeline_on_the_same_data() {
    let fx = fixture();
    let per = &fx["periodic"];
    let out = seed_record();
    let rec = &out.record;
    let n = 5115;
    let s = PeriodicAnalyzer::new(n)
        .unwrap()
        .analyze(
            &[&rec.r, &rec.u, &rec.y],
            20_000.0,
            &PeriodicOptions::new(n).skip(1),
        )
        .unwrap();
    let lines: Vec<usize> = s
        .excited_lines(0, 1e-6)
        .unwrap()
        .into_iter()
        .filter(|&k| (10.0..=1000.0).contains(&s.line_hz(k)))
        .collect();
    let ref_lines: Vec<usize> = per["lines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(lines, ref_lines);
    let frf = from_periodic(&s, Channels { r: 0, u: 1, y: 2 }, &lines, None).unwrap();
    for (name, ours, re, im) in [
        ("plant", frf.plant.values(), "plant_re", "plant_im"),
        ("t_ry", frf.t_ry.values(), "t_ry_re", "t_ry_im"),
        ("t_ru", frf.t_ru.values(), "t_ru_re", "t_ru_im"),
    ] {
        let theirs = complex(per, re, im);
        let worst = ours
            .iter()
            .zip(&theirs)
            .map(|(a, b)| (a - b).norm() / b.norm())
            .fold(0.0, f64::max);
        eprintln!("{name}: ambid vs numpy, worst relative difference {worst:.2e}");
        // Different FFTs (rustfft vs pocketfft) and summation orders: rounding relative to the
        // largest line, so lines 1e-4 below the peak differ by up to ~1e-9 relative.
        assert!(worst < 1e-8, "{name}: {worst}");
    }
    // both pipelines therefore have the same error against the twin's truth
    let f = floats(&per["f_hz"]);
    let truth = out.twin.plant_frf(&f).unwrap();
    let theirs = complex(per, "plant_re", "plant_im");
    let (m, p) = median_p90(
        theirs
            .iter()
            .zip(&truth)
            .map(|(a, t)| (a - t).norm() / t.norm())
            .collect(),
    );
    let (mo, po) = median_p90(
        frf.plant
            .values()
            .iter()
            .zip(&truth)
            .map(|(a, t)| (a - t).norm() / t.norm())
            .collect(),
    );
    eprintln!(
        "plant vs truth: numpy {:.3} % / {:.3} %, ambid {:.3} % / {:.3} % (median / p90)",
        100.0 * m,
        100.0 * p,
        100.0 * mo,
        100.0 * po
    );
    assert!((m - mo).abs() < 1e-9 && (p - po).abs() < 1e-9);
}

#[test]
fn welch_closed_loop_equals_scipy_csd_on_the_same_data() {
    use ambid_core::frf::closed_loop::from_welch;
    use ambid_core::frf::welch::{welch_spectra, WelchOptions};
    let fx = fixture();
    let w = &fx["welch"];
    let out = seed_record();
    let rec = &out.record;
    let opts = WelchOptions::new(20_000.0, 5115);
    let cs = welch_spectra(&[&rec.r, &rec.u, &rec.y], &opts).unwrap();
    let frf = from_welch(
        &cs,
        Channels { r: 0, u: 1, y: 2 },
        (10.0, 1000.0),
        0.0,
        None,
    )
    .unwrap();
    let f = floats(&w["f_hz"]);
    assert_eq!(frf.f_hz().len(), f.len());
    assert!(frf.f_hz().iter().zip(&f).all(|(a, b)| (a - b).abs() < 1e-9));
    for (name, ours, re, im) in [
        ("plant", frf.plant.values(), "plant_re", "plant_im"),
        ("t_ry", frf.t_ry.values(), "t_ry_re", "t_ry_im"),
    ] {
        let theirs = complex(w, re, im);
        let worst = ours
            .iter()
            .zip(&theirs)
            .map(|(a, b)| (a - b).norm() / b.norm())
            .fold(0.0, f64::max);
        eprintln!("Welch {name}: ambid vs scipy, worst relative difference {worst:.2e}");
        assert!(worst < 1e-10, "{name}: {worst}");
    }
    let coh = floats(&w["coh_ry"]);
    let worst = frf
        .coh_ry
        .iter()
        .zip(&coh)
        .map(|(a, b)| (a - b).abs() / b)
        .fold(0.0, f64::max);
    eprintln!("Welch coherence: worst relative difference {worst:.2e}");
    assert!(worst < 1e-10);
    let truth = out.twin.plant_frf(&f).unwrap();
    let (m, p) = median_p90(
        frf.plant
            .values()
            .iter()
            .zip(&truth)
            .map(|(a, t)| (a - t).norm() / t.norm())
            .collect(),
    );
    eprintln!(
        "Welch (Hann, one period per segment) plant vs truth: {:.3} % / {:.3} %",
        100.0 * m,
        100.0 * p
    );
}
