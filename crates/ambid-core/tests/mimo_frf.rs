//! `frf::mimo` against the exact truth of a discrete 4-axis closed loop built in
//! `common/mimo_loop.rs` from state-space parts: per axis an unstable mass with negative stiffness, an amplifier lag and a
//! one-sample sensor delay (ZOH), the axes coupled by a known stiffness matrix (A–B through the
//! rotor, x–y cross stiffness) and a skew (gyroscopic-like) velocity coupling; a discrete PD
//! controller per axis (one design for the A axes, one for the B axes), u = −C y + r. Truth:
//! T_ry = (I + P C)⁻¹ P, S = (I + C P)⁻¹ from the state spaces by `Frd` algebra.

use ambid_core::data::IoData;
use ambid_core::frf::closed_loop::{band_radius_factor, from_periodic, Channels};
use ambid_core::frf::mimo::{estimate, periodic, zippered, MimoDesign, MimoOptions};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
use ambid_core::lti::{Frd, StateSpace};
use ambid_core::Error;
use faer::{c64, Mat};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Uniform};

use crate::mimo_loop;
use mimo_loop::{build, Loop, FS};

/// One period of a random-phase multisine on `lines` (amplitude `amp` per line), repeated.
fn multisine(
    n: usize,
    lines: &[usize],
    amp: f64,
    periods: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<f64> {
    let ph = Uniform::new(0.0, 2.0 * std::f64::consts::PI).unwrap();
    let phases: Vec<f64> = lines.iter().map(|_| ph.sample(rng)).collect();
    let one: Vec<f64> = (0..n)
        .map(|t| {
            lines
                .iter()
                .zip(&phases)
                .map(|(&k, p)| {
                    amp * (2.0 * std::f64::consts::PI * (k * t % n) as f64 / n as f64 + p).cos()
                })
                .sum()
        })
        .collect();
    (0..n * periods).map(|t| one[t % n]).collect()
}

const H4: [[f64; 4]; 4] = [
    [1.0, 1.0, 1.0, 1.0],
    [1.0, -1.0, 1.0, -1.0],
    [1.0, 1.0, -1.0, -1.0],
    [1.0, -1.0, -1.0, 1.0],
];

#[derive(Clone, Copy, PartialEq, Debug)]
enum Design {
    Sequential,
    Orthogonal,
    Zipper,
}

/// The record of a design: N samples per period, `periods` in all; lines 1..=n_lines excited.
fn run(
    lp: &Loop,
    design: Design,
    n: usize,
    periods: usize,
    n_lines: usize,
    noise: f64,
    seed: u64,
) -> IoData {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let all: Vec<usize> = (1..=n_lines).collect();
    let amp = 0.05;
    match design {
        Design::Sequential | Design::Orthogonal => {
            let ms = multisine(n, &all, amp, periods, &mut rng);
            let recs: Vec<IoData> = (0..4)
                .map(|e| {
                    let r: Vec<Vec<f64>> = (0..4)
                        .map(|j| {
                            let s = match design {
                                Design::Sequential => f64::from(u8::from(e == j)),
                                _ => H4[e][j],
                            };
                            ms.iter().map(|v| s * v).collect()
                        })
                        .collect();
                    lp.record(&r, noise, &mut rng, Some(n))
                })
                .collect();
            IoData::from_experiments(recs).unwrap()
        }
        Design::Zipper => {
            let r: Vec<Vec<f64>> = (0..4)
                .map(|j| {
                    let own: Vec<usize> =
                        all.iter().copied().filter(|k| (k - 1) % 4 == j).collect();
                    multisine(n, &own, amp, periods, &mut rng)
                })
                .collect();
            lp.record(&r, noise, &mut rng, Some(n))
        }
    }
}

/// Largest relative entry error of `est` against `truth` (entries below 1e-3 of the line's
/// largest are compared to that floor).
fn max_rel_err(est: &Frd, truth: &Frd, mask: Option<&[bool]>) -> f64 {
    let mut worst = 0.0f64;
    for line in 0..est.len() {
        let (a, b) = (est.at(line).unwrap(), truth.at(line).unwrap());
        let big = (0..b.nrows())
            .flat_map(|i| (0..b.ncols()).map(move |j| (i, j)))
            .fold(0.0f64, |m, (i, j)| m.max(b[(i, j)].norm()));
        for j in 0..b.ncols() {
            if mask.is_some_and(|m| !m[line * b.ncols() + j]) {
                continue;
            }
            for i in 0..b.nrows() {
                let e = (a[(i, j)] - b[(i, j)]).norm() / b[(i, j)].norm().max(1e-3 * big);
                worst = worst.max(e);
            }
        }
    }
    worst
}

#[test]
fn the_test_loop_is_stable_and_the_plant_unstable() {
    let lp = build(4);
    let pmax = lp
        .plant
        .poles()
        .unwrap()
        .iter()
        .fold(0.0f64, |m, p| m.max(p.norm()));
    assert!(pmax > 1.01, "plant poles max |z| = {pmax}");
    // closed loop: states (x_p, z), u = −(Cc z + Dc C x_p) + r
    let (a, b, c) = (lp.plant.a(), lp.plant.b(), lp.plant.c());
    let (ac, bc, cc, dc) = (lp.ctrl.a(), lp.ctrl.b(), lp.ctrl.c(), lp.ctrl.d());
    let (np, nc) = (a.nrows(), ac.nrows());
    let bdc = b * dc * c;
    let bcc = b * cc;
    let bcc2 = bc * c;
    let acl = Mat::<f64>::from_fn(np + nc, np + nc, |i, j| match (i < np, j < np) {
        (true, true) => a[(i, j)] - bdc[(i, j)],
        (true, false) => -bcc[(i, j - np)],
        (false, true) => bcc2[(i - np, j)],
        (false, false) => ac[(i - np, j - np)],
    });
    let cl = StateSpace::new(
        acl,
        Mat::zeros(np + nc, 1),
        Mat::zeros(1, np + nc),
        Mat::zeros(1, 1),
        Some(1.0 / FS),
    )
    .unwrap();
    let cmax = cl
        .poles()
        .unwrap()
        .iter()
        .fold(0.0f64, |m, p| m.max(p.norm()));
    assert!(cmax < 0.999, "closed-loop poles max |z| = {cmax}");
    // and the truth algebra is consistent: P = T S⁻¹
    let f = [10.0, 55.0, 300.0];
    let (t, s, p) = lp.truth(&f);
    assert!(max_rel_err(&t.divide(&s).unwrap(), &p, None) < 1e-10);
}

/// Noise-free: the multi-experiment designs equal the truth to 1e-6 at every excited line.
#[test]
fn noise_free_sequential_and_orthogonal_equal_the_truth() {
    let lp = build(4);
    for design in [Design::Sequential, Design::Orthogonal] {
        let data = run(&lp, design, 256, 7, 100, 0.0, 1);
        let frf = estimate(&data, &MimoOptions::new().skip(4)).unwrap();
        assert_eq!(frf.design, MimoDesign::Experiments(4));
        assert_eq!(frf.lines, (1..=100).collect::<Vec<_>>());
        let (t, s, p) = lp.truth(frf.f_hz());
        let (et, es, ep) = (
            max_rel_err(&frf.t_ry, &t, None),
            max_rel_err(&frf.s, &s, None),
            max_rel_err(&frf.plant, &p, None),
        );
        eprintln!("{design:?}: max rel err T {et:.2e} S {es:.2e} P {ep:.2e}");
        assert!(
            et < 1e-6 && es < 1e-6 && ep < 1e-6,
            "{design:?}: {et} {es} {ep}"
        );
        // orthogonal and sequential inputs are perfectly conditioned
        assert!(
            frf.cond_r.iter().all(|c| (c - 1.0).abs() < 1e-9),
            "{:?}",
            &frf.cond_r[..3]
        );
        assert!(frf.coherence.iter().all(|c| (c - 1.0).abs() < 1e-9));
        // the indirect plant with the known controller
        let c = Frd::from_model(&lp.ctrl, frf.f_hz()).unwrap();
        let frf = frf.with_indirect(&c).unwrap();
        let ei = max_rel_err(frf.plant_indirect.as_ref().unwrap(), &p, None);
        assert!(ei < 1e-6, "indirect {ei}");
    }
}

/// Noise-free zippered: the measured columns equal the truth to 1e-6; the interpolated entries
/// and the plant carry the interpolation bias of the module docs, which falls like the fourth
/// power of the line spacing (a 4× finer grid: ≥ 50× smaller).
#[test]
fn noise_free_zippered_measured_columns_exact_interpolated_biased() {
    let lp = build(4);
    let mut worst = Vec::new();
    for (n, skip, lines) in [(1024usize, 4usize, 400usize), (4096, 1, 1600)] {
        let data = run(&lp, Design::Zipper, n, skip + 1, lines, 0.0, 2);
        let frf = zippered(&data, &MimoOptions::new().skip(skip)).unwrap();
        assert_eq!(frf.design, MimoDesign::Zippered);
        assert_eq!(frf.lines, (1..=lines).collect::<Vec<_>>());
        assert_eq!(frf.measured.iter().filter(|m| **m).count(), lines);
        let (t, s, p) = lp.truth(frf.f_hz());
        let et = max_rel_err(&frf.t_ry, &t, Some(&frf.measured));
        let es = max_rel_err(&frf.s, &s, Some(&frf.measured));
        assert!(et < 1e-6 && es < 1e-6, "measured columns: {et} {es}");
        // interpolated entries and the plant, from 20 Hz (no extrapolation below the first lines)
        let band = |g: &Frd, lo: f64| g.band(lo, 2000.0).unwrap();
        let (it, ip) = (
            max_rel_err(&band(&frf.t_ry, 20.0), &band(&t, 20.0), None),
            max_rel_err(&band(&frf.plant, 20.0), &band(&p, 20.0), None),
        );
        let (it_hi, ip_hi) = (
            max_rel_err(&band(&frf.t_ry, 300.0), &band(&t, 300.0), None),
            max_rel_err(&band(&frf.plant, 300.0), &band(&p, 300.0), None),
        );
        eprintln!(
            "zipper N = {n} (column spacing {:.1} Hz): interpolated T {it:.2e}, P {ip:.2e} from 20 Hz; \
             T {it_hi:.2e}, P {ip_hi:.2e} from 300 Hz",
            4.0 * FS / n as f64
        );
        assert!(it > 1e-9, "interpolated entries cannot be exact");
        worst.push((it.max(ip), it_hi.max(ip_hi)));
    }
    assert!(worst[1].0 < worst[0].0 / 50.0, "{worst:?}");
    assert!(worst[1].0 < 2e-2 && worst[1].1 < 1e-5, "{worst:?}");
}

/// With sensor noise the 95 % discs cover the truth on 90–98 % of the entry-lines over 20 seeds.
#[test]
fn noisy_bands_cover_the_truth() {
    let lp = build(4);
    for design in [Design::Sequential, Design::Orthogonal] {
        let (mut inside, mut total) = (0usize, 0usize);
        let (mut inside_t, mut total_t) = (0usize, 0usize);
        for seed in 0..20 {
            let data = run(&lp, design, 256, 4 + 16, 60, 2e-4, 100 + seed);
            let frf = periodic(&data, &MimoOptions::new().skip(4)).unwrap();
            let q = band_radius_factor(0.95, frf.dof).unwrap();
            let (t, _, p) = lp.truth(frf.f_hz());
            for (est, tr, ins, tot) in [
                (&frf.plant, &p, &mut inside, &mut total),
                (&frf.t_ry, &t, &mut inside_t, &mut total_t),
            ] {
                let var = est.variance().unwrap();
                for (i, (a, b)) in est.values().iter().zip(tr.values()).enumerate() {
                    *tot += 1;
                    if (a - b).norm() <= q * var[i].sqrt() {
                        *ins += 1;
                    }
                }
            }
        }
        let (cp, ct) = (
            inside as f64 / total as f64,
            inside_t as f64 / total_t as f64,
        );
        eprintln!("{design:?}: 95 % coverage P {cp:.3}, T_ry {ct:.3} over {total} entry-lines");
        assert!(
            (0.90..=0.98).contains(&cp) && (0.90..=0.98).contains(&ct),
            "{design:?}: {cp} {ct}"
        );
    }
}

/// The 1×1 case equals today's SISO periodic closed-loop FRF to 1e-12.
#[test]
fn siso_case_equals_the_siso_estimator() {
    let lp = build(1);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let n = 256;
    let lines: Vec<usize> = (1..=80).collect();
    let r = vec![multisine(n, &lines, 0.05, 10, &mut rng)];
    let data = lp.record(&r, 1e-4, &mut rng, Some(n));
    let frf = estimate(&data, &MimoOptions::new().skip(3)).unwrap();
    let ch: Vec<&[f64]> = ["r", "u", "y"]
        .iter()
        .map(|c| data.channel(c).unwrap())
        .collect();
    let sp = PeriodicAnalyzer::new(n)
        .unwrap()
        .analyze(&ch, FS, &PeriodicOptions::new(n).skip(3))
        .unwrap();
    let ex = sp.excited_lines(0, 1e-6).unwrap();
    assert_eq!(ex, frf.lines);
    let siso = from_periodic(&sp, Channels { r: 0, u: 1, y: 2 }, &ex, None).unwrap();
    let same = |a: &Frd, b: &Frd| {
        for (x, y) in a.values().iter().zip(b.values()) {
            assert!((x - y).norm() <= 1e-12 * y.norm(), "{x} vs {y}");
        }
        for (x, y) in a.variance().unwrap().iter().zip(b.variance().unwrap()) {
            assert!((x - y).abs() <= 1e-12 * y, "var {x} vs {y}");
        }
    };
    same(&frf.t_ry, &siso.t_ry);
    same(&frf.s, &siso.t_ru);
    same(&frf.plant, &siso.plant);
    for (a, b) in frf.coherence.iter().zip(&siso.coh_ry) {
        assert!((a - b).abs() <= 1e-12, "{a} {b}");
    }
    for (a, b) in frf.coherence_u.iter().zip(&siso.coh_ru) {
        assert!((a - b).abs() <= 1e-12, "{a} {b}");
    }
    assert_eq!(frf.dof, siso.dof);
}

fn msg(e: Error) -> String {
    e.to_string()
}

#[test]
fn bad_input_gets_a_clear_error() {
    let lp = build(4);
    let seq = run(&lp, Design::Sequential, 64, 3, 20, 0.0, 3);
    let opts = MimoOptions::new().skip(1);
    // two identical experiments: R singular on every line, the frequency named
    let e0 = seq.experiment(0).unwrap();
    let orth = run(&lp, Design::Orthogonal, 64, 3, 20, 0.0, 4);
    let o0 = orth.experiment(0).unwrap();
    let dup = IoData::from_experiments(vec![
        o0.clone(),
        o0.clone(),
        orth.experiment(2).unwrap(),
        orth.experiment(3).unwrap(),
    ])
    .unwrap();
    let m = msg(periodic(&dup, &opts).unwrap_err());
    assert!(
        m.contains("singular at line") && m.contains("Hz") && m.contains("identical experiments"),
        "{m}"
    );
    // fewer experiments than inputs
    let three =
        IoData::from_experiments((0..3).map(|e| seq.experiment(e).unwrap()).collect()).unwrap();
    let m = msg(periodic(&three, &opts).unwrap_err());
    assert!(m.contains("3 experiment(s) for 4 inputs"), "{m}");
    // different lengths
    let short = e0.slice(0, 128).unwrap();
    let mixed = IoData::from_experiments(vec![
        short,
        seq.experiment(1).unwrap(),
        seq.experiment(2).unwrap(),
        seq.experiment(3).unwrap(),
    ])
    .unwrap();
    let m = msg(periodic(&mixed, &opts).unwrap_err());
    assert!(m.contains("same length"), "{m}");
    // different sample times
    let fast = IoData::new(e0.channels().to_vec(), 0.5 / FS, Some(64)).unwrap();
    let m = msg(ambid_core::frf::mimo::periodic_records(&[fast, e0.clone()], &opts).unwrap_err());
    assert!(m.contains("resample"), "{m}");
    // a missing axis column
    let no_u = IoData::new(
        e0.channels()
            .iter()
            .filter(|(n, _)| n != "u_yb")
            .cloned()
            .collect(),
        1.0 / FS,
        Some(64),
    )
    .unwrap();
    let m = msg(periodic(&no_u, &opts).unwrap_err());
    assert!(
        m.contains("4 excitation channels") && m.contains("3 input channels"),
        "{m}"
    );
    let no_y = IoData::new(
        e0.channels()
            .iter()
            .filter(|(n, _)| !n.starts_with('y'))
            .cloned()
            .collect(),
        1.0 / FS,
        Some(64),
    )
    .unwrap();
    assert!(msg(periodic(&no_y, &opts).unwrap_err()).contains("no output channel (y)"));
    // non-finite samples
    let mut ch = e0.channels().to_vec();
    ch[6].1[100] = f64::NAN;
    let nan = IoData::new(ch, 1.0 / FS, Some(64)).unwrap();
    let m = msg(periodic(&nan, &opts).unwrap_err());
    assert!(m.contains("non-finite") && m.contains("sample 101"), "{m}");
    // no period: periodic() says how to proceed; estimate() takes the local polynomial method,
    // which needs every input excited (this sequential experiment drives xa only)
    let np = IoData::new(e0.channels().to_vec(), 1.0 / FS, None).unwrap();
    let m = msg(periodic(&np, &opts).unwrap_err());
    assert!(
        m.contains("no period length") && m.contains("local_polynomial"),
        "{m}"
    );
    let m = msg(estimate(&np, &opts).unwrap_err());
    assert!(m.contains("r_xb") && m.contains("no power"), "{m}");
    // a sequential experiment handed to the zippered estimator: inputs 1..3 are silent
    assert!(msg(zippered(&e0, &opts).unwrap_err()).contains("no power"));
    // an orthogonal experiment is not zippered: every line excited by all inputs
    let m = msg(zippered(&orth.experiment(0).unwrap(), &opts).unwrap_err());
    assert!(m.contains("not a zippered design"), "{m}");
    // a controller without the estimate's lines
    let frf = periodic(&seq, &opts).unwrap();
    let c = Frd::from_model(&lp.ctrl, &[1.0, 2.0]).unwrap();
    assert!(msg(frf.with_indirect(&c).unwrap_err()).contains("evaluate it at the estimate's lines"));
}

/// Results do not depend on the number of threads.
#[test]
fn thread_count_does_not_change_the_result() {
    let lp = build(4);
    let data = run(&lp, Design::Orthogonal, 128, 6, 40, 1e-4, 9);
    let opts = MimoOptions::new().skip(2);
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| periodic(&data, &opts).unwrap());
    let two = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .unwrap()
        .install(|| periodic(&data, &opts).unwrap());
    assert_eq!(one, two);
    let _ = c64::new(0.0, 0.0);
}

/// Zippered with sensor noise: where the interpolation bias is small against the noise (above
/// 300 Hz on a 3.9 Hz grid, bias ≤ 3e-4 relative) the 95 % discs of the measured and the
/// interpolated entries cover the truth on 90–98 % of the entry-lines over 20 seeds.
#[test]
fn noisy_zippered_bands_cover_the_truth_where_the_bias_is_small() {
    let lp = build(4);
    let (mut inside, mut total) = ([0usize; 3], [0usize; 3]);
    for seed in 0..20 {
        let data = run(&lp, Design::Zipper, 1024, 4 + 16, 400, 2e-4, 300 + seed);
        let frf = zippered(&data, &MimoOptions::new().skip(4).band(300.0, 2000.0)).unwrap();
        let q = band_radius_factor(0.95, frf.dof).unwrap();
        let (t, s, p) = lp.truth(frf.f_hz());
        for (g, (est, tr)) in [(&frf.t_ry, &t), (&frf.s, &s), (&frf.plant, &p)]
            .into_iter()
            .enumerate()
        {
            let var = est.variance().unwrap();
            for (i, (a, b)) in est.values().iter().zip(tr.values()).enumerate() {
                total[g] += 1;
                if (a - b).norm() <= q * var[i].sqrt() {
                    inside[g] += 1;
                }
            }
        }
    }
    let cov: Vec<f64> = (0..3).map(|g| inside[g] as f64 / total[g] as f64).collect();
    eprintln!(
        "zipper 95 % coverage T_ry {:.3}, S {:.3}, P {:.3} over {} entry-lines each",
        cov[0], cov[1], cov[2], total[0]
    );
    assert!(cov.iter().all(|c| (0.90..=0.98).contains(c)), "{cov:?}");
}
