//! `frf::mimo_lpm` (the multivariable local polynomial method on non-periodic records) against
//! the exact truth of the discrete 4-axis closed loop of `common/mimo_loop.rs`, against the SISO
//! `lpm_closed_loop` for the 1×1 case, and its errors.

use crate::mimo_loop;

use ambid_core::data::IoData;
use ambid_core::frf::closed_loop::band_radius_factor;
use ambid_core::frf::lpm::{lpm_closed_loop, LpmOptions};
use ambid_core::frf::mimo_lpm::{local_polynomial, MimoLpmOptions};
use ambid_core::frf::MimoDesign;
use ambid_core::lti::Frd;
use ambid_core::Error;
use mimo_loop::{build, FS};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

fn noise(len: usize, amp: f64, rng: &mut ChaCha8Rng) -> Vec<f64> {
    (0..len)
        .map(|_| {
            let g: f64 = StandardNormal.sample(rng);
            amp * g
        })
        .collect()
}

/// Relative entry errors of `est` against `truth` (entries below 1e-3 of the line's largest are
/// compared to that floor), all entries of all lines.
fn rel_errs(est: &Frd, truth: &Frd) -> Vec<f64> {
    let mut out = Vec::new();
    for line in 0..est.len() {
        let (a, b) = (est.at(line).unwrap(), truth.at(line).unwrap());
        let big = (0..b.nrows())
            .flat_map(|i| (0..b.ncols()).map(move |j| (i, j)))
            .fold(0.0f64, |m, (i, j)| m.max(b[(i, j)].norm()));
        for j in 0..b.ncols() {
            for i in 0..b.nrows() {
                out.push((a[(i, j)] - b[(i, j)]).norm() / b[(i, j)].norm().max(1e-3 * big));
            }
        }
    }
    out
}

fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Fraction of entry-lines whose level-0.95 disc covers the truth.
fn coverage(est: &Frd, truth: &Frd, factor: f64) -> (usize, usize) {
    let var = est.variance().unwrap();
    let (mut hit, mut n) = (0, 0);
    for (i, (a, b)) in est.values().iter().zip(truth.values()).enumerate() {
        n += 1;
        if (a - b).norm() <= factor * var[i].sqrt() {
            hit += 1;
        }
    }
    (hit, n)
}

#[test]
fn the_1x1_case_is_the_siso_lpm_closed_loop() {
    let lp = build(1);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let len = 4096;
    let r = noise(len, 0.05, &mut rng);
    let data = lp.record(std::slice::from_ref(&r), 2e-3, &mut rng, None);
    let (u, y) = (data.channel("u").unwrap(), data.channel("y").unwrap());
    let siso = lpm_closed_loop(&r, u, y, FS, (0.0, FS / 2.0), &LpmOptions::default()).unwrap();
    let mimo = local_polynomial(&data, &MimoLpmOptions::new()).unwrap();
    assert_eq!(
        mimo.design,
        MimoDesign::LocalPolynomial {
            degree: 2,
            half_width: 4
        }
    );
    assert_eq!(mimo.dof, siso.dof() as f64);
    assert_eq!(mimo.f_hz(), siso.f_hz());
    for (a, b) in [
        (&mimo.t_ry, &siso.t_ry),
        (&mimo.s, &siso.t_ru),
        (&mimo.plant, &siso.plant),
    ] {
        for (x, z) in a.values().iter().zip(b.values()) {
            assert!((x - z).norm() <= 1e-10 * z.norm(), "{x} vs {z}");
        }
        for (x, z) in a.variance().unwrap().iter().zip(b.variance().unwrap()) {
            assert!((x - z).abs() <= 1e-9 * z, "variance {x} vs {z}");
        }
    }
}

/// Median and 95th-percentile relative errors of T_ry, S and P against the truth.
fn errors(lp: &mimo_loop::Loop, data: &IoData, opts: &MimoLpmOptions) -> [(f64, f64); 3] {
    let est = local_polynomial(data, opts).unwrap();
    assert!(est.coherence.iter().all(|c| *c > 0.999));
    let (t, s, p) = lp.truth(est.f_hz());
    [(&est.t_ry, &t), (&est.s, &s), (&est.plant, &p)].map(|(e, tr)| {
        let errs = rel_errs(e, tr);
        (quantile(errs.clone(), 0.5), quantile(errs, 0.95))
    })
}

/// Noise-free, the only error is the local polynomial's bias, which falls like $(w/B)^{R+1}$:
/// 8× per doubling of the record for $R = 2$ (the lines get twice as dense, the window of
/// lines the same). One experiment with four independent white-noise excitations; and four
/// experiments with one each (sequential), whose window is 7 lines instead of 19.
#[test]
fn four_axes_noise_free_bias_falls_at_the_polynomial_rate() {
    let lp = build(4);
    let opts = MimoLpmOptions::new().band(5.0, 1500.0);
    let one = |len: usize| {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let r: Vec<Vec<f64>> = (0..4).map(|_| noise(len, 0.05, &mut rng)).collect();
        lp.record(&r, 0.0, &mut rng, None)
    };
    let (e1, e2) = (
        errors(&lp, &one(8192), &opts),
        errors(&lp, &one(16384), &opts),
    );
    for (q, (a, b)) in ["T_ry", "S", "P"].iter().zip(e1.iter().zip(&e2)) {
        eprintln!(
            "one experiment {q}: median {:.2e} → {:.2e}, 95th percentile {:.2e} → {:.2e}",
            a.0, b.0, a.1, b.1
        );
        let rate = a.0 / b.0;
        assert!((6.0..=10.0).contains(&rate), "{q}: median falls {rate:.2}×");
        assert!(b.0 < 1e-5 && b.1 < 1e-3, "{q}: {b:?}");
    }
    let len = 8192;
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let seq = IoData::from_experiments(
        (0..4)
            .map(|e| {
                let r: Vec<Vec<f64>> = (0..4)
                    .map(|j| {
                        if j == e {
                            noise(len, 0.05, &mut rng)
                        } else {
                            vec![0.0; len]
                        }
                    })
                    .collect();
                lp.record(&r, 0.0, &mut rng, None)
            })
            .collect(),
    )
    .unwrap();
    let est = local_polynomial(&seq, &opts).unwrap();
    assert_eq!(
        est.design,
        MimoDesign::LocalPolynomial {
            degree: 2,
            half_width: 3
        }
    );
    for (q, (med, p95)) in ["T_ry", "S", "P"].iter().zip(errors(&lp, &seq, &opts)) {
        eprintln!("sequential {q}: median {med:.2e}, 95th percentile {p95:.2e}");
        assert!(med < 1e-7 && p95 < 1e-4, "{q}: {med:.2e} {p95:.2e}");
    }
}

/// Sensor noise on: the 95 % discs of T_ry, S and P cover the truth on 90–98 % of the
/// entry-lines over 20 seeds (one experiment, four independent noises).
#[test]
fn noise_bands_cover_the_truth() {
    let lp = build(4);
    let len = 4096;
    let opts = MimoLpmOptions::new().band(5.0, 600.0);
    let mut tot = [(0usize, 0usize); 3];
    for seed in 0..20 {
        let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
        let r: Vec<Vec<f64>> = (0..4).map(|_| noise(len, 0.05, &mut rng)).collect();
        let data = lp.record(&r, 1e-3, &mut rng, None);
        let est = local_polynomial(&data, &opts).unwrap();
        let k = band_radius_factor(0.95, est.dof).unwrap();
        let (t, s, p) = lp.truth(est.f_hz());
        for (acc, (e, tr)) in tot
            .iter_mut()
            .zip([(&est.t_ry, &t), (&est.s, &s), (&est.plant, &p)])
        {
            let (h, n) = coverage(e, tr, k);
            acc.0 += h;
            acc.1 += n;
        }
    }
    for (q, (h, n)) in ["T_ry", "S", "P"].iter().zip(tot) {
        let c = h as f64 / n as f64;
        eprintln!("{q}: coverage {c:.4} of {n} entry-lines");
        assert!((0.90..=0.98).contains(&c), "{q}: coverage {c}");
    }
}

#[test]
fn bad_records_get_clear_errors() {
    let lp = build(4);
    let len = 2048;
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    // the same noise on two axes: the inputs are not independent
    let a = noise(len, 0.05, &mut rng);
    let r = vec![
        a.clone(),
        a,
        noise(len, 0.05, &mut rng),
        noise(len, 0.05, &mut rng),
    ];
    let data = lp.record(&r, 0.0, &mut rng, None);
    let e = local_polynomial(&data, &MimoLpmOptions::new()).unwrap_err();
    assert!(
        matches!(e, Error::Numerical { .. }) && e.to_string().contains("independently"),
        "{e}"
    );
    // a periodic excitation belongs to frf::mimo::periodic
    let per: Vec<Vec<f64>> = (0..4)
        .map(|_| {
            let one = noise(256, 0.05, &mut rng);
            (0..len).map(|t| one[t % 256]).collect()
        })
        .collect();
    let data = lp.record(&per, 0.0, &mut rng, None);
    let e = local_polynomial(&data, &MimoLpmOptions::new()).unwrap_err();
    assert!(e.to_string().contains("periodic"), "{e}");
    // experiments of different lengths
    let r1: Vec<Vec<f64>> = (0..4).map(|_| noise(len, 0.05, &mut rng)).collect();
    let r2: Vec<Vec<f64>> = (0..4).map(|_| noise(len / 2, 0.05, &mut rng)).collect();
    let two = IoData::from_experiments(vec![
        lp.record(&r1, 0.0, &mut rng, None),
        lp.record(&r2, 0.0, &mut rng, None),
    ]);
    if let Ok(two) = two {
        let e = local_polynomial(&two, &MimoLpmOptions::new()).unwrap_err();
        assert!(e.to_string().contains("same length"), "{e}");
    }
    // an axis never excited
    let mut r3: Vec<Vec<f64>> = (0..4).map(|_| noise(len, 0.05, &mut rng)).collect();
    r3[2] = vec![0.0; len];
    let data = lp.record(&r3, 0.0, &mut rng, None);
    let e = local_polynomial(&data, &MimoLpmOptions::new()).unwrap_err();
    assert!(e.to_string().contains("r_ya"), "{e}");
    // a NaN
    let mut r4: Vec<Vec<f64>> = (0..4).map(|_| noise(len, 0.05, &mut rng)).collect();
    r4[1][7] = f64::NAN;
    let d = lp.record(&r4, 0.0, &mut rng, None);
    assert!(local_polynomial(&d, &MimoLpmOptions::new()).is_err());
}
