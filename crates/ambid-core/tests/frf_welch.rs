//! `frf::window` and `frf::welch` against three oracles:
//! * fixtures written by `tests/fixtures/make_welch.py` (scipy `get_window`, `welch`, `csd`,
//!   `coherence`), compared with $\max_k |a_k - b_k| / \max_k |b_k| \le 10^{-10}$ per array and
//!   $|a_k - b_k| / |b_k| \le 10^{-10}$ per element where $|b_k| \ge 10^{-6} \max_k |b_k|$ (and
//!   the ratios coherence, H1 and H2 are compared on the lines where both auto spectra are
//!   $\ge 10^{-6}$ of their maxima: below that the segment DFTs are dominated by FFT rounding,
//!   in scipy as here, and the ratios are ill-conditioned);
//! * a naive in-test Welch built on an $O(L^2)$ DFT, for an awkward prime segment length;
//! * the one-shot estimate itself, which a streamed estimate (random chunk sizes) must equal
//!   bit for bit.
//!
//! Run with `-- --nocapture` to see the measured agreement with scipy.

use ambid_core::c64;
use ambid_core::frf::welch::{
    coherence, csd, etfe, psd, welch_spectra, CrossSpectra, Scaling, SegmentDetrend,
    WelchAccumulator, WelchOptions,
};
use ambid_core::frf::window::Window;
use ambid_core::Error;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;
use std::f64::consts::PI;

const TOL: f64 = 1e-10;
/// Elements smaller than this fraction of the array's largest are compared only through the
/// array-relative error.
const TINY: f64 = 1e-6;

fn load(name: &str) -> Value {
    let path = format!("{}/tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    serde_json::from_str(&text).unwrap()
}

fn vecf(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn vecc(v: &Value) -> Vec<c64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| c64::new(x[0].as_f64().unwrap(), x[1].as_f64().unwrap()))
        .collect()
}

/// (array-relative error, largest element-relative error over the elements that are not tiny).
fn errors<T: Copy>(
    got: &[T],
    want: &[T],
    abs: impl Fn(T) -> f64,
    sub: impl Fn(T, T) -> T,
) -> (f64, f64) {
    assert_eq!(got.len(), want.len(), "length");
    let scale = want.iter().map(|&b| abs(b)).fold(0.0f64, f64::max);
    let mut arr = 0.0f64;
    let mut elem = 0.0f64;
    for (&a, &b) in got.iter().zip(want) {
        let d = abs(sub(a, b));
        arr = arr.max(d);
        if abs(b) >= TINY * scale {
            elem = elem.max(d / abs(b));
        }
    }
    (if scale > 0.0 { arr / scale } else { arr }, elem)
}

fn errors_f(got: &[f64], want: &[f64]) -> (f64, f64) {
    errors(got, want, f64::abs, |a, b| a - b)
}

fn errors_c(got: &[c64], want: &[c64]) -> (f64, f64) {
    errors(got, want, |z: c64| z.norm(), |a, b| a - b)
}

/// Lines where every given auto spectrum is at least `TINY` times its maximum. Elsewhere the
/// segment DFTs are dominated by FFT rounding (relative to the whole segment's norm), so ratios of
/// spectra (coherence, H1, H2) are ill-conditioned there and compared only through the
/// array-relative error.
fn well_conditioned(autos: &[&[f64]]) -> Vec<bool> {
    let n = autos[0].len();
    (0..n)
        .map(|k| {
            autos.iter().all(|p| {
                let max = p.iter().fold(0.0f64, |m, v| m.max(*v));
                p[k] >= TINY * max
            })
        })
        .collect()
}

/// Tracks the worst errors over a test and asserts each one.
#[derive(Default)]
struct Worst {
    arr: f64,
    elem: f64,
}

impl Worst {
    fn check(&mut self, what: &str, (arr, elem): (f64, f64)) {
        assert!(
            arr <= TOL && elem <= TOL,
            "{what}: array-relative {arr:.2e}, element-relative {elem:.2e} (tolerance {TOL:.0e})"
        );
        self.arr = self.arr.max(arr);
        self.elem = self.elem.max(elem);
    }
}

#[test]
fn windows_match_scipy() {
    let fx = load("welch_windows.json");
    let mut worst = Worst::default();
    let mut count = 0;
    for case in fx["windows"].as_array().unwrap() {
        let w: Window = case["window"].as_str().unwrap().parse().unwrap();
        let n = case["n"].as_u64().unwrap() as usize;
        let periodic = case["periodic"].as_bool().unwrap();
        let got = w.coefficients(n, periodic).unwrap();
        worst.check(
            &format!("{w} n={n} periodic={periodic}"),
            errors_f(&got, &vecf(&case["w"])),
        );
        count += 1;
    }
    assert_eq!(count, 5 * 8 * 2);
    eprintln!(
        "windows vs scipy.signal.get_window ({count} cases): max array-relative {:.2e}, max element-relative {:.2e}",
        worst.arr, worst.elem
    );
}

fn options_of(case: &Value, fs: f64) -> WelchOptions {
    WelchOptions {
        noverlap: case["noverlap"].as_u64().unwrap() as usize,
        window: case["window"].as_str().unwrap().parse().unwrap(),
        detrend: match case["detrend"].as_str().unwrap() {
            "none" => SegmentDetrend::None,
            "constant" => SegmentDetrend::Constant,
            "linear" => SegmentDetrend::Linear,
            other => panic!("detrend {other}"),
        },
        scaling: match case["scaling"].as_str().unwrap() {
            "density" => Scaling::Density,
            "spectrum" => Scaling::Spectrum,
            other => panic!("scaling {other}"),
        },
        ..WelchOptions::new(fs, case["nperseg"].as_u64().unwrap() as usize)
    }
}

#[test]
fn spectra_match_scipy() {
    let fx = load("welch_spectra.json");
    let mut psd_w = Worst::default();
    let mut csd_w = Worst::default();
    let mut coh_w = Worst::default();
    let mut h_w = Worst::default();
    let mut freq_w = Worst::default();
    let mut coh_all = 0.0f64;
    for case in fx["cases"].as_array().unwrap() {
        let sig = &fx["signals"][case["signal"].as_str().unwrap()];
        let fs = sig["fs"].as_f64().unwrap();
        let (x, y) = (vecf(&sig["x"]), vecf(&sig["y"]));
        let opts = options_of(case, fs);
        let name = format!(
            "{} L={} overlap={} {} {:?} {:?}",
            case["signal"], opts.nperseg, opts.noverlap, opts.window, opts.detrend, opts.scaling
        );
        let (f, pxx, pyy, pxy, cxy) = (
            vecf(&case["f"]),
            vecf(&case["pxx"]),
            vecf(&case["pyy"]),
            vecc(&case["pxy"]),
            vecf(&case["cxy"]),
        );

        let s = welch_spectra(&[&x, &y], &opts).unwrap();
        assert_eq!(s.n_segments(), opts.n_segments(x.len()), "{name}");
        freq_w.check(&format!("{name} f"), errors_f(s.f_hz(), &f));
        psd_w.check(&format!("{name} Pxx"), errors_f(&s.psd(0).unwrap(), &pxx));
        psd_w.check(&format!("{name} Pyy"), errors_f(&s.psd(1).unwrap(), &pyy));
        csd_w.check(&format!("{name} Pxy"), errors_c(s.get(0, 1).unwrap(), &pxy));
        let pyx: Vec<c64> = pxy.iter().map(|z| z.conj()).collect();
        csd_w.check(&format!("{name} Pyx"), errors_c(s.get(1, 0).unwrap(), &pyx));
        // Ratios of spectra are compared on the well-conditioned lines only; H2 is huge where Pxy
        // is tiny. On all lines, coherence (in [0, 1]) is only checked absolutely and loosely: the
        // 4096-point case has lines 1e-16 below the peak, where the segment DFTs carry relative
        // rounding errors of ~1e-8 in both implementations.
        let mask = well_conditioned(&[&pxx, &pyy]);
        let keep = |v: &[c64]| -> Vec<c64> {
            v.iter()
                .zip(&mask)
                .filter_map(|(z, ok)| ok.then_some(*z))
                .collect()
        };
        let keep_f = |v: &[f64]| -> Vec<f64> {
            v.iter()
                .zip(&mask)
                .filter_map(|(z, ok)| ok.then_some(*z))
                .collect()
        };
        let c = s.coherence(0, 1).unwrap();
        coh_w.check(&format!("{name} Cxy"), errors_f(&keep_f(&c), &keep_f(&cxy)));
        let coh_abs = c
            .iter()
            .zip(&cxy)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            coh_abs < 1e-7,
            "{name}: coherence absolute error {coh_abs:.2e}"
        );
        coh_all = coh_all.max(coh_abs);
        // H1 = Pxy / Pxx, H2 = Pyy / Pyx from the scipy spectra
        let h1: Vec<c64> = pxy.iter().zip(&pxx).map(|(z, a)| z / a).collect();
        let h2: Vec<c64> = pyy.iter().zip(&pyx).map(|(b, z)| b / z).collect();
        let (g1, g2) = (s.h1(0, 1).unwrap(), s.h2(0, 1).unwrap());
        h_w.check(&format!("{name} H1"), errors_c(&keep(&g1), &keep(&h1)));
        h_w.check(&format!("{name} H2"), errors_c(&keep(&g2), &keep(&h2)));

        // the one-shot functions agree with the multi-channel estimate exactly
        let (f1, p1) = psd(&x, &opts).unwrap();
        assert_eq!((f1.as_slice(), p1), (s.f_hz(), s.psd(0).unwrap()), "{name}");
        let (_, c1) = csd(&x, &y, &opts).unwrap();
        assert_eq!(c1.as_slice(), s.get(0, 1).unwrap(), "{name}");
        let (_, g1) = coherence(&x, &y, &opts).unwrap();
        assert_eq!(g1, s.coherence(0, 1).unwrap(), "{name}");
    }
    eprintln!("agreement with scipy 1.17 (max over 11 cases; array-relative / element-relative where |ref| ≥ 1e-6 max):");
    for (what, w) in [
        ("f", &freq_w),
        ("welch (Pxx, Pyy)", &psd_w),
        ("csd (Pxy, Pyx)", &csd_w),
        ("coherence", &coh_w),
        ("H1, H2", &h_w),
    ] {
        eprintln!("  {what:18} {:.2e} / {:.2e}", w.arr, w.elem);
    }
    eprintln!("  (coherence, H1, H2 on lines where Pxx, Pyy ≥ 1e-6 max; coherence absolute error on all lines {coh_all:.2e})");
}

// ---------------------------------------------------------------------------------------------
// Naive oracle

fn random_record(n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    // uniform noise with an offset and a ramp, one-pole low-pass filtered
    let mut state = 0.0;
    (0..n)
        .map(|k| {
            state = 0.7 * state + rng.random_range(-1.0..1.0);
            state + 0.4 + 1e-3 * k as f64
        })
        .collect()
}

/// $X(k) = \sum_n x_n e^{-j 2\pi k n / L}$, $k = 0..=L/2$, from the definition.
fn naive_dft(x: &[f64]) -> Vec<c64> {
    let l = x.len();
    (0..=l / 2)
        .map(|k| {
            x.iter()
                .enumerate()
                .map(|(n, &v)| {
                    let ang = -2.0 * PI * ((k * n) % l) as f64 / l as f64;
                    c64::new(v * ang.cos(), v * ang.sin())
                })
                .sum()
        })
        .collect()
}

/// Least-squares fit of `a + b t` by the 2×2 normal equations, subtracted.
fn naive_detrend(x: &[f64], d: SegmentDetrend) -> Vec<f64> {
    let n = x.len() as f64;
    match d {
        SegmentDetrend::None => x.to_vec(),
        SegmentDetrend::Constant => {
            let m = x.iter().sum::<f64>() / n;
            x.iter().map(|v| v - m).collect()
        }
        SegmentDetrend::Linear => {
            let (mut st, mut stt, mut sx, mut stx) = (0.0, 0.0, 0.0, 0.0);
            for (t, v) in x.iter().enumerate() {
                let t = t as f64;
                st += t;
                stt += t * t;
                sx += v;
                stx += t * v;
            }
            let det = n * stt - st * st;
            let b = (n * stx - st * sx) / det;
            let a = (sx - b * st) / n;
            x.iter()
                .enumerate()
                .map(|(t, v)| v - a - b * t as f64)
                .collect()
        }
    }
}

/// Welch from the definitions of the module documentation, all pairs.
fn naive_welch(xs: &[Vec<f64>], o: &WelchOptions) -> Vec<Vec<Vec<c64>>> {
    let l = o.nperseg;
    let step = l - o.noverlap;
    let w = o.window.coefficients(l, true).unwrap();
    let s = match o.scaling {
        Scaling::Density => 1.0 / (o.fs * w.iter().map(|v| v * v).sum::<f64>()),
        Scaling::Spectrum => 1.0 / w.iter().sum::<f64>().powi(2),
    };
    let nc = xs.len();
    let nf = l / 2 + 1;
    let mut out = vec![vec![vec![c64::new(0.0, 0.0); nf]; nc]; nc];
    let mut k_seg = 0;
    let mut start = 0;
    while start + l <= xs[0].len() {
        let specs: Vec<Vec<c64>> = xs
            .iter()
            .map(|x| {
                let d = naive_detrend(&x[start..start + l], o.detrend);
                let dw: Vec<f64> = d.iter().zip(&w).map(|(a, b)| a * b).collect();
                naive_dft(&dw)
            })
            .collect();
        for i in 0..nc {
            for j in 0..nc {
                for k in 0..nf {
                    out[i][j][k] += specs[i][k].conj() * specs[j][k];
                }
            }
        }
        k_seg += 1;
        start += step;
    }
    for row in out.iter_mut() {
        for sij in row.iter_mut() {
            for (k, v) in sij.iter_mut().enumerate() {
                let fold = if k == 0 || 2 * k == l { 1.0 } else { 2.0 };
                *v *= fold * s / k_seg as f64;
            }
        }
    }
    out
}

fn assert_matches_naive(s: &CrossSpectra, naive: &[Vec<Vec<c64>>], what: &str) -> f64 {
    let mut worst = Worst::default();
    for (i, row) in naive.iter().enumerate() {
        for (j, want) in row.iter().enumerate() {
            worst.check(
                &format!("{what} S[{i},{j}]"),
                errors_c(s.get(i, j).unwrap(), want),
            );
        }
    }
    worst.arr
}

#[test]
fn matches_naive_dft_oracle_for_prime_segment() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let xs: Vec<Vec<f64>> = (0..3).map(|_| random_record(3001, &mut rng)).collect();
    let mut worst = 0.0f64;
    for (l, overlap, window, detrend, scaling) in [
        (
            257,
            100,
            Window::FlatTop,
            SegmentDetrend::Linear,
            Scaling::Density,
        ),
        (
            257,
            0,
            Window::Hann,
            SegmentDetrend::Constant,
            Scaling::Spectrum,
        ),
        (
            2,
            1,
            Window::Hamming,
            SegmentDetrend::None,
            Scaling::Density,
        ),
        (
            3,
            2,
            Window::Blackman,
            SegmentDetrend::Linear,
            Scaling::Spectrum,
        ),
        (
            100,
            37,
            Window::Rectangular,
            SegmentDetrend::Constant,
            Scaling::Density,
        ),
    ] {
        let o = WelchOptions {
            noverlap: overlap,
            window,
            detrend,
            scaling,
            ..WelchOptions::new(123.0, l)
        };
        let s = welch_spectra(&xs, &o).unwrap();
        let naive = naive_welch(&xs, &o);
        worst = worst.max(assert_matches_naive(&s, &naive, &format!("{o:?}")));
    }
    eprintln!("naive DFT oracle: max array-relative error {worst:.2e}");
}

// ---------------------------------------------------------------------------------------------
// Streaming

#[test]
fn streaming_equals_one_shot_for_random_chunks() {
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let n = 7919;
    let xs: Vec<Vec<f64>> = (0..3).map(|_| random_record(n, &mut rng)).collect();
    for o in [
        WelchOptions::new(1e3, 256),
        WelchOptions {
            noverlap: 0,
            window: Window::FlatTop,
            ..WelchOptions::new(1e3, 101)
        },
        WelchOptions {
            noverlap: 63,
            detrend: SegmentDetrend::Linear,
            scaling: Scaling::Spectrum,
            ..WelchOptions::new(1e3, 64)
        },
        WelchOptions::new(1e3, n),
    ] {
        let one_shot = welch_spectra(&xs, &o).unwrap();
        for _ in 0..4 {
            let mut acc = WelchAccumulator::new(3, &o).unwrap();
            let mut pos = 0;
            while pos < n {
                // mostly small chunks, sometimes empty, sometimes several segments long
                let len = match rng.random_range(0..10) {
                    0 => 0,
                    1 => rng.random_range(1000..3000),
                    _ => rng.random_range(1..200),
                }
                .min(n - pos);
                let chunk: Vec<&[f64]> = xs.iter().map(|x| &x[pos..pos + len]).collect();
                acc.push(&chunk).unwrap();
                pos += len;
            }
            assert_eq!(acc.n_samples(), n);
            assert_eq!(acc.finish().unwrap(), one_shot, "{o:?}");
        }
    }
}

#[test]
fn finish_midway_then_continue() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let x = random_record(5000, &mut rng);
    let o = WelchOptions::new(1.0, 128);
    let mut acc = WelchAccumulator::new(1, &o).unwrap();
    acc.push(&[&x[..2000]]).unwrap();
    assert_eq!(
        acc.finish().unwrap(),
        welch_spectra(&[&x[..2000]], &o).unwrap()
    );
    acc.push(&[&x[2000..]]).unwrap();
    assert_eq!(acc.finish().unwrap(), welch_spectra(&[&x], &o).unwrap());
}

// ---------------------------------------------------------------------------------------------
// Physics sanity

#[test]
fn h1_recovers_fir_and_variance_is_consistent() {
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let n = 200_000;
    let u: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let b = [0.3, -0.2, 0.1];
    let noise = 0.1;
    let y: Vec<f64> = (0..n)
        .map(|k| {
            let mut v = noise * rng.random_range(-1.0..1.0) * 3f64.sqrt();
            for (m, bm) in b.iter().enumerate() {
                if k >= m {
                    v += bm * u[k - m];
                }
            }
            v
        })
        .collect();
    let fs = 1.0;
    let s = welch_spectra(&[&u, &y], &WelchOptions::new(fs, 128)).unwrap();
    let h1 = s.h1(0, 1).unwrap();
    let var = s.h1_variance(0, 1).unwrap();
    // normalised squared errors average to about 1
    let mut z = 0.0;
    for (k, f) in s.f_hz().iter().enumerate().skip(1) {
        let g: c64 = b
            .iter()
            .enumerate()
            .map(|(m, bm)| c64::from_polar(*bm, -2.0 * PI * f * m as f64 / fs))
            .sum();
        z += (h1[k] - g).norm_sqr() / var[k];
    }
    let z = z / (s.f_hz().len() - 1) as f64;
    assert!((0.6..1.5).contains(&z), "mean normalised error {z}");
    assert!((s.effective_averages() - s.n_segments() as f64 / (1.0 + 2.0 / 36.0)).abs() < 0.1);
}

#[test]
fn etfe_matches_naive_dft_and_skips_zero_lines() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let n = 211;
    let u = random_record(n, &mut rng);
    let y = random_record(n, &mut rng);
    for window in [None, Some(Window::Hann)] {
        let w = window.map_or(vec![1.0; n], |w| w.coefficients(n, true).unwrap());
        let uw: Vec<f64> = u.iter().zip(&w).map(|(a, b)| a * b).collect();
        let yw: Vec<f64> = y.iter().zip(&w).map(|(a, b)| a * b).collect();
        let want: Vec<c64> = naive_dft(&yw)
            .iter()
            .zip(naive_dft(&uw))
            .map(|(a, b)| a / b)
            .collect();
        let (f, g) = etfe(&u, &y, 50.0, window).unwrap();
        assert_eq!(f.len(), n / 2 + 1);
        assert!((f[3] - 3.0 * 50.0 / n as f64).abs() < 1e-12);
        let (arr, elem) = errors_c(&g, &want);
        assert!(arr < 1e-10 && elem < 1e-10, "{arr} {elem}");
    }
    // alternating input: U(0) = 0 exactly, so the DC line is skipped
    let u: Vec<f64> = (0..16)
        .map(|k| if k % 2 == 0 { 1.0 } else { -1.0 })
        .collect();
    let y: Vec<f64> = u.iter().map(|v| 3.0 * v).collect();
    let (f, g) = etfe(&u, &y, 16.0, None).unwrap();
    assert!(!f.is_empty() && f[0] > 0.0, "{f:?}");
    assert!(f.contains(&8.0));
    assert!(g.iter().all(|z| (z - 3.0).norm() < 1e-12));
}

// ---------------------------------------------------------------------------------------------
// Errors

fn invalid_name(e: Error) -> &'static str {
    match e {
        Error::InvalidArgument { name, .. } => name,
        other => panic!("expected InvalidArgument, got {other:?}"),
    }
}

#[test]
fn bad_options_are_rejected() {
    let x = vec![0.5; 1000];
    let base = WelchOptions::new(100.0, 64);
    for (o, name) in [
        (WelchOptions { fs: 0.0, ..base }, "fs"),
        (WelchOptions { fs: -1.0, ..base }, "fs"),
        (
            WelchOptions {
                fs: f64::NAN,
                ..base
            },
            "fs",
        ),
        (
            WelchOptions {
                fs: f64::INFINITY,
                ..base
            },
            "fs",
        ),
        (
            WelchOptions {
                nperseg: 1,
                noverlap: 0,
                ..base
            },
            "nperseg",
        ),
        (
            WelchOptions {
                nperseg: 0,
                noverlap: 0,
                ..base
            },
            "nperseg",
        ),
        (
            WelchOptions {
                noverlap: 64,
                ..base
            },
            "noverlap",
        ),
        (
            WelchOptions {
                noverlap: 100,
                ..base
            },
            "noverlap",
        ),
    ] {
        assert_eq!(invalid_name(o.validate().unwrap_err()), name);
        assert_eq!(invalid_name(psd(&x, &o).unwrap_err()), name);
        assert_eq!(
            invalid_name(WelchAccumulator::new(1, &o).unwrap_err()),
            name
        );
    }
    assert_eq!(
        invalid_name(WelchAccumulator::new(0, &base).unwrap_err()),
        "n_channels"
    );
    let none: [&[f64]; 0] = [];
    assert_eq!(
        invalid_name(welch_spectra(&none, &base).unwrap_err()),
        "n_channels"
    );
}

#[test]
fn record_shorter_than_segment() {
    let x = vec![1.0; 100];
    let o = WelchOptions::new(1.0, 128);
    let e = psd(&x, &o).unwrap_err();
    assert!(
        e.to_string()
            .contains("record has 100 samples, nperseg is 128: lower nperseg"),
        "{e}"
    );
    // streaming: no segment yet
    let mut acc = WelchAccumulator::new(1, &o).unwrap();
    assert_eq!(invalid_name(acc.finish().unwrap_err()), "nperseg");
    acc.push(&[&x]).unwrap();
    let e = acc.finish().unwrap_err();
    assert!(e.to_string().contains("record has 100 samples"), "{e}");
    acc.push(&[&x[..28]]).unwrap();
    assert_eq!(acc.finish().unwrap().n_segments(), 1);
    // empty record
    assert!(psd(&[], &o)
        .unwrap_err()
        .to_string()
        .contains("record has 0 samples"));
}

#[test]
fn non_finite_samples_are_located() {
    let mut y = vec![0.25; 300];
    y[123] = f64::NAN;
    let x = vec![1.0; 300];
    let o = WelchOptions::new(1.0, 32);
    assert_eq!(
        csd(&x, &y, &o).unwrap_err(),
        Error::NonFinite {
            what: "y",
            index: 123
        }
    );
    assert_eq!(
        coherence(&y, &x, &o).unwrap_err(),
        Error::NonFinite {
            what: "x",
            index: 123
        }
    );
    assert_eq!(
        welch_spectra(&[&x, &x, &y], &o).unwrap_err(),
        Error::NonFinite {
            what: "channel 2",
            index: 123
        }
    );
    // streaming: the index counts from the start of the record, and a failed push changes nothing
    let mut acc = WelchAccumulator::new(2, &o).unwrap();
    acc.push(&[&x[..100], &x[..100]]).unwrap();
    let before = acc.finish().unwrap();
    let mut z = vec![0.0; 50];
    z[7] = f64::NEG_INFINITY;
    assert_eq!(
        acc.push(&[&x[..50], &z]).unwrap_err(),
        Error::NonFinite {
            what: "channel 1",
            index: 107
        }
    );
    assert_eq!(acc.n_samples(), 100);
    assert_eq!(acc.finish().unwrap(), before);
    assert!(matches!(
        etfe(&x, &y, 1.0, None).unwrap_err(),
        Error::NonFinite {
            what: "y",
            index: 123
        }
    ));
}

#[test]
fn mismatched_lengths_and_channels() {
    let x = vec![1.0; 300];
    let o = WelchOptions::new(1.0, 32);
    assert!(matches!(
        csd(&x, &x[..299], &o).unwrap_err(),
        Error::DimensionMismatch { .. }
    ));
    // a short first channel is reported as a mismatch, not as a short record
    assert!(matches!(
        welch_spectra(&[&x[..10], &x[..]], &o).unwrap_err(),
        Error::DimensionMismatch { .. }
    ));
    let mut acc = WelchAccumulator::new(2, &o).unwrap();
    assert!(matches!(
        acc.push(&[&x[..10], &x[..11]]).unwrap_err(),
        Error::DimensionMismatch { .. }
    ));
    assert!(matches!(
        acc.push(&[&x[..10]]).unwrap_err(),
        Error::DimensionMismatch { .. }
    ));
    assert_eq!(acc.n_samples(), 0);
    assert!(matches!(
        etfe(&x, &x[..3], 1.0, None).unwrap_err(),
        Error::DimensionMismatch { .. }
    ));
}

#[test]
fn bad_channel_indices_and_zero_power() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let x = random_record(512, &mut rng);
    let zero = vec![0.0; 512];
    let s = welch_spectra(&[&x, &zero], &WelchOptions::new(1.0, 64)).unwrap();
    assert_eq!(invalid_name(s.get(2, 0).unwrap_err()), "i");
    assert_eq!(invalid_name(s.get(0, 5).unwrap_err()), "j");
    assert_eq!(invalid_name(s.psd(2).unwrap_err()), "i");
    assert_eq!(invalid_name(s.h1(0, 2).unwrap_err()), "j_out");
    assert_eq!(invalid_name(s.h2(3, 0).unwrap_err()), "i_in");
    assert_eq!(invalid_name(s.coherence(0, 9).unwrap_err()), "j");
    // zero channel: coherence and H1 from it are undefined, H1 into it is 0
    assert!(matches!(
        s.coherence(0, 1).unwrap_err(),
        Error::Numerical { .. }
    ));
    assert!(matches!(s.h1(1, 0).unwrap_err(), Error::Numerical { .. }));
    assert!(matches!(s.h2(0, 1).unwrap_err(), Error::Numerical { .. }));
    assert!(s.h1(0, 1).unwrap().iter().all(|z| *z == c64::new(0.0, 0.0)));
}

#[test]
fn bad_etfe_arguments() {
    let x = vec![1.0, 2.0, 3.0];
    assert_eq!(invalid_name(etfe(&x, &x, 0.0, None).unwrap_err()), "fs");
    assert_eq!(
        invalid_name(etfe(&x, &x, f64::NAN, None).unwrap_err()),
        "fs"
    );
    assert_eq!(
        invalid_name(etfe(&x[..1], &x[..1], 1.0, None).unwrap_err()),
        "u"
    );
}
