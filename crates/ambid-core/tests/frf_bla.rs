//! Robust BLA (`frf::bla`) against independent truths: a linear system (NL variance statistically
//! zero, BLA = G within its std), a Wiener system with a cubic (NL variance against a brute-force
//! Monte-Carlo reference), detection lines (x² → even lines, x³ → odd non-excited lines), typed
//! errors, and a numpy fixture (`tests/fixtures/make_bla_reference.py`).

use ambid_core::error::Error;
use ambid_core::frf::bla::{random_phase_period, robust_bla, Bla, Record};
use ambid_core::frf::closed_loop::band_radius_factor;
use ambid_core::frf::periodic::PeriodicOptions;
use ambid_core::lti::TransferFunction;
use ambid_core::signal::{Grid, MultisineSpec, Phases};
use faer::c64;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rustfft::FftPlanner;

const N: usize = 256;
const FS: f64 = 1000.0;

fn system() -> TransferFunction {
    TransferFunction::new(vec![0.0, 0.5, 0.2], vec![1.0, -0.6, 0.3], 1.0 / FS).unwrap()
}

fn odd_bins(k_max: usize) -> Vec<usize> {
    (1..=k_max).step_by(2).collect()
}

/// One realisation: `periods` periods (the first is the transient) of a random-phase multisine
/// through G, then the static map `nl`, plus white output noise.
fn realisation(
    bins: &[usize],
    periods: usize,
    seed: u64,
    nl: impl Fn(f64) -> f64,
    noise: f64,
) -> (Vec<f64>, Vec<f64>) {
    let period = random_phase_period(bins, N, 1.0, seed).unwrap();
    let u: Vec<f64> = (0..periods * N).map(|t| period[t % N]).collect();
    let x = system().simulate(&u).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let y: Vec<f64> = x
        .iter()
        .map(|&v| {
            let e: f64 = StandardNormal.sample(&mut rng);
            nl(v) + noise * e
        })
        .collect();
    (u, y)
}

fn run(
    bins: &[usize],
    m: usize,
    periods: usize,
    seed0: u64,
    nl: impl Fn(f64) -> f64 + Copy,
    noise: f64,
) -> Bla {
    let data: Vec<(Vec<f64>, Vec<f64>)> = (0..m)
        .map(|i| realisation(bins, periods, seed0 + i as u64, nl, noise))
        .collect();
    let recs: Vec<Record> = data.iter().map(|(u, y)| Record::open_loop(u, y)).collect();
    robust_bla(&recs, FS, &PeriodicOptions::new(N).skip(1)).unwrap()
}

#[test]
fn linear_system_has_no_nl_variance_and_the_bla_covers_g() {
    let bins = odd_bins(101);
    let (m, p) = (40, 5);
    let bla = run(&bins, m, p + 1, 100, |x| x, 0.05);
    let g = &bla.g;
    assert_eq!(g.lines, bins);
    assert_eq!((g.realisations, g.periods), (m, p));
    let truth = system().freq_response(&g.f_hz).unwrap();
    let s = g.band_summary(0.0, FS / 2.0).unwrap();
    println!(
        "linear: noise_rel {:.3e}, nl_rel {:.3e} ± {:.3e} (SE), {} lines",
        s.noise_rel, s.nl_rel, s.nl_rel_se, s.lines
    );
    assert!(s.nl_rel.abs() < 3.0 * s.nl_rel_se, "NL variance not ≈ 0");
    // per-realisation noise variance is M·σ²_n: the NL estimate is a small fraction of it
    assert!(s.nl_rel.abs() < 0.1 * m as f64 * s.noise_rel);
    // total variance ≈ noise variance (ratio within chi-square spread of a band average)
    assert!((s.total_rel / s.noise_rel - 1.0).abs() < 0.15);
    // coverage of the 95 % disc (F(2, 2(M−1)) radius)
    let q = band_radius_factor(0.95, (m - 1) as f64).unwrap();
    let inside = g
        .values
        .iter()
        .zip(&truth)
        .zip(g.std_total())
        .filter(|((gh, gt), sd)| (**gh - **gt).norm() <= q * sd)
        .count();
    let cov = inside as f64 / g.values.len() as f64;
    println!("linear: 95 % coverage {cov:.3}");
    assert!(cov > 0.88 && cov <= 1.0, "coverage {cov}");
}

/// Brute-force Monte-Carlo variance of the per-realisation FRF around its mean, noise-free, one
/// steady-state period per realisation, DFT by rustfft (independent of `frf::bla`).
fn monte_carlo_nl_variance(bins: &[usize], realisations: usize, alpha: f64) -> Vec<f64> {
    let fft = FftPlanner::<f64>::new().plan_fft_forward(N);
    let mut gs: Vec<Vec<c64>> = Vec::new();
    for i in 0..realisations {
        let (u, y) = realisation(bins, 2, 10_000 + i as u64, |x| x + alpha * x * x * x, 0.0);
        let mut uu: Vec<c64> = u[N..].iter().map(|&v| c64::new(v, 0.0)).collect();
        let mut yy: Vec<c64> = y[N..].iter().map(|&v| c64::new(v, 0.0)).collect();
        fft.process(&mut uu);
        fft.process(&mut yy);
        gs.push(bins.iter().map(|&k| yy[k] / uu[k]).collect());
    }
    let mf = realisations as f64;
    (0..bins.len())
        .map(|j| {
            let mean: c64 = gs.iter().map(|g| g[j]).sum::<c64>() / mf;
            gs.iter().map(|g| (g[j] - mean).norm_sqr()).sum::<f64>() / (mf - 1.0)
        })
        .collect()
}

#[test]
fn cubic_nl_variance_matches_monte_carlo() {
    let bins = odd_bins(101);
    let alpha = 0.3;
    let reference = monte_carlo_nl_variance(&bins, 1000, alpha);
    let (m, p) = (12, 4);
    let bla = run(&bins, m, p + 1, 1, |x| x + alpha * x * x * x, 0.01);
    let est = &bla.g.var_nl;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (r, e) = (mean(&reference), mean(est));
    let noise = mean(&bla.g.var_noise) * m as f64;
    println!(
        "cubic: band-mean NL variance {e:.4e}, Monte-Carlo (1000 realisations) {r:.4e}, ratio {:.3}; \
         per-realisation noise variance {noise:.3e}",
        e / r
    );
    assert!((e / r - 1.0).abs() < 0.2, "ratio {}", e / r);
    assert!(e > 10.0 * noise, "the test must be NL-dominated");
    // the low and high halves of the band separately (coarser: fewer lines)
    let h = bins.len() / 2;
    for (lo, hi) in [(0, h), (h, bins.len())] {
        let ratio = mean(&est[lo..hi]) / mean(&reference[lo..hi]);
        println!("cubic: lines {lo}..{hi}: ratio {ratio:.3}");
        assert!((ratio - 1.0).abs() < 0.3, "half-band ratio {ratio}");
    }
}

fn detection_run(nl: impl Fn(f64) -> f64 + Copy) -> Bla {
    let ts = 1.0 / FS;
    let spec = MultisineSpec {
        f_min_hz: 1.0,
        f_max_hz: 120.0 * FS / N as f64,
        period_samples: N,
        periods: 1,
        rms: 1.0,
        grid: Grid::RandomOdd,
        phases: Phases::Random,
        seed: 7,
    };
    let bins = spec.bins(ts).unwrap();
    run(&bins, 6, 5, 300, nl, 0.01)
}

#[test]
fn detection_lines_separate_even_and_odd_nonlinearities() {
    let even = detection_run(|x| x + 0.3 * x * x);
    let odd = detection_run(|x| x + 0.3 * x * x * x);
    let lin = detection_run(|x| x);
    for (name, b) in [("x²", &even), ("x³", &odd), ("linear", &lin)] {
        println!(
            "{name}: even lines {} at {:.1} dB over noise, odd detection lines {} at {:.1} dB",
            b.detection.even.lines,
            b.detection.even.ratio_db,
            b.detection.odd.lines,
            b.detection.odd.ratio_db
        );
        assert!(b.detection.even.lines > 50 && b.detection.odd.lines > 15);
    }
    assert!(even.detection.even.ratio_db > 20.0);
    assert!(even.detection.odd.ratio_db.abs() < 3.0);
    assert!(odd.detection.odd.ratio_db > 20.0);
    assert!(odd.detection.even.ratio_db.abs() < 3.0);
    assert!(lin.detection.even.ratio_db.abs() < 3.0 && lin.detection.odd.ratio_db.abs() < 3.0);
}

#[test]
fn bad_input_gives_typed_errors() {
    let bins = odd_bins(21);
    let (u, y) = realisation(&bins, 3, 1, |x| x, 0.01);
    let opts = PeriodicOptions::new(N);
    // one realisation
    let e = robust_bla(&[Record::open_loop(&u, &y)], FS, &opts).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { .. }), "{e}");
    assert!(e.to_string().contains("at least 2"), "{e}");
    // one analysed period
    let recs = [Record::open_loop(&u, &y), Record::open_loop(&u, &y)];
    let e = robust_bla(&recs, FS, &opts.skip(2)).unwrap_err();
    assert!(e.to_string().contains("at least 2"), "{e}");
    // not a whole number of periods
    let recs = [
        Record::open_loop(&u[..2 * N + 5], &y[..2 * N + 5]),
        Record::open_loop(&u[..2 * N + 5], &y[..2 * N + 5]),
    ];
    let e = robust_bla(&recs, FS, &opts.lenient()).unwrap_err();
    assert!(e.to_string().contains("integer number of periods"), "{e}");
    // NaN
    let mut bad = y.clone();
    bad[10] = f64::NAN;
    let recs = [Record::open_loop(&u, &bad), Record::open_loop(&u, &y)];
    assert!(matches!(
        robust_bla(&recs, FS, &opts),
        Err(Error::NonFinite { index: 10, .. })
    ));
    // no excitation
    let z = vec![0.0; u.len()];
    let recs = [Record::open_loop(&z, &y), Record::open_loop(&z, &y)];
    assert!(matches!(
        robust_bla(&recs, FS, &opts),
        Err(Error::InvalidArgument { .. })
    ));
    // different grids: no common line
    let (u2, y2) = realisation(&[2, 4], 3, 2, |x| x, 0.01);
    let recs = [Record::open_loop(&u, &y), Record::open_loop(&u2, &y2)];
    let e = robust_bla(&recs, FS, &opts).unwrap_err();
    assert!(e.to_string().contains("no line is excited"), "{e}");
    // mixed open/closed
    let recs = [Record::open_loop(&u, &y), Record::closed_loop(&u, &u, &y)];
    assert!(robust_bla(&recs, FS, &opts).is_err());
    assert!(random_phase_period(&[], N, 1.0, 0).is_err());
    assert!(random_phase_period(&[128], N, 1.0, 0).is_err());
    assert!(random_phase_period(&[3], N, f64::NAN, 0).is_err());
}

/// Closed loop with a static controller c: u = r − c·y, y = G u: the plant BLA equals G, T_ru is
/// 1/(1 + G c), and without a nonlinearity the NL variance is ≈ 0.
#[test]
fn closed_loop_plant_is_t_ry_over_t_ru() {
    let bins = odd_bins(61);
    let g = system();
    let c = 0.8;
    let (m, p) = (8, 4);
    let mut data = Vec::new();
    for i in 0..m {
        let period = random_phase_period(&bins, N, 1.0, 50 + i as u64).unwrap();
        let len = (p + 1) * N;
        let r: Vec<f64> = (0..len).map(|t| period[t % N]).collect();
        // G has a pure delay (b0 = 0), so the loop is computable sample by sample
        let (b, a) = (g.num().to_vec(), g.den().to_vec());
        let mut rng = ChaCha8Rng::seed_from_u64(900 + i as u64);
        let (mut u, mut x, mut y) = (vec![0.0; len], vec![0.0; len], vec![0.0; len]);
        for t in 0..len {
            let mut acc = 0.0;
            for j in 1..b.len().min(t + 1) {
                acc += b[j] * u[t - j];
            }
            for j in 1..a.len().min(t + 1) {
                acc -= a[j] * x[t - j];
            }
            x[t] = acc;
            let e: f64 = StandardNormal.sample(&mut rng);
            y[t] = x[t] + 0.01 * e;
            u[t] = r[t] - c * y[t];
        }
        data.push((r, u, y));
    }
    let recs: Vec<Record> = data
        .iter()
        .map(|(r, u, y)| Record::closed_loop(r, u, y))
        .collect();
    let bla = robust_bla(&recs, FS, &PeriodicOptions::new(N).skip(1)).unwrap();
    let truth = g.freq_response(&bla.g.f_hz).unwrap();
    let t_ru = bla.t_ru.as_ref().unwrap();
    let t_ry = bla.t_ry.as_ref().unwrap();
    for (i, &gt) in truth.iter().enumerate() {
        assert!((bla.g.values[i] - gt).norm() < 5.0 * bla.g.std_total()[i] + 1e-9);
        let s = c64::new(1.0, 0.0) / (c64::new(1.0, 0.0) + gt * c);
        assert!((t_ru.values[i] - s).norm() < 5.0 * t_ru.std_total()[i] + 1e-9);
        assert!((t_ry.values[i] - gt * s).norm() < 5.0 * t_ry.std_total()[i] + 1e-9);
        let ratio = t_ry.values[i] / t_ru.values[i];
        // the ratio of the BLAs is not the BLA of the ratios, but both estimate G here
        assert!((ratio - gt).norm() < 5.0 * bla.g.std_total()[i] + 1e-9);
    }
    let s = bla.g.band_summary(0.0, FS).unwrap();
    println!("closed loop: nl_rel {:.3e} ± {:.3e}", s.nl_rel, s.nl_rel_se);
    assert!(s.nl_rel.abs() < 3.0 * s.nl_rel_se);
}

/// Reads a fixture CSV with a header into (header, rows of f64).
fn read_csv(name: &str) -> (Vec<String>, Vec<Vec<f64>>) {
    let path = format!("{}/tests/fixtures/bla/{name}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    let head: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(|s| s.to_string())
        .collect();
    let rows = lines
        .filter(|l| !l.is_empty())
        .map(|l| l.split(',').map(|v| v.parse::<f64>().unwrap()).collect())
        .collect();
    (head, rows)
}

fn column(head: &[String], rows: &[Vec<f64>], name: &str) -> Vec<f64> {
    let j = head.iter().position(|h| h == name).unwrap();
    rows.iter().map(|r| r[j]).collect()
}

/// Splits the long-format data (`m` first) into per-realisation channels.
fn realisations(head: &[String], rows: &[Vec<f64>], chans: &[&str]) -> Vec<Vec<Vec<f64>>> {
    let m = column(head, rows, "m");
    let n_real = m.iter().fold(0.0f64, |a, &b| a.max(b)) as usize + 1;
    let cols: Vec<Vec<f64>> = chans.iter().map(|c| column(head, rows, c)).collect();
    (0..n_real)
        .map(|i| {
            cols.iter()
                .map(|c| {
                    c.iter()
                        .zip(&m)
                        .filter(|(_, &mm)| mm as usize == i)
                        .map(|(v, _)| *v)
                        .collect()
                })
                .collect()
        })
        .collect()
}

fn assert_matches(
    est: &ambid_core::frf::bla::BlaEstimate,
    head: &[String],
    rows: &[Vec<f64>],
    q: &str,
) {
    let close = |a: f64, b: f64, what: &str| {
        assert!(
            (a - b).abs() <= 1e-8 * b.abs().max(1e-12),
            "{q} {what}: ambid {a:e} vs numpy {b:e}"
        );
    };
    let lines = column(head, rows, "line");
    assert_eq!(
        est.lines,
        lines.iter().map(|&l| l as usize).collect::<Vec<_>>()
    );
    let re = column(head, rows, &format!("{q}_re"));
    let im = column(head, rows, &format!("{q}_im"));
    let vt = column(head, rows, &format!("{q}_var_total"));
    let vn = column(head, rows, &format!("{q}_var_noise"));
    let vnl = column(head, rows, &format!("{q}_var_nl"));
    let mut worst = 0.0f64;
    for i in 0..lines.len() {
        let g = c64::new(re[i], im[i]);
        assert!(
            (est.values[i] - g).norm() <= 1e-8 * g.norm(),
            "{q} value line {}",
            lines[i]
        );
        close(est.var_total[i], vt[i], "var_total");
        close(est.var_noise[i], vn[i], "var_noise");
        close(est.var_nl[i], vnl[i], "var_nl");
        worst = worst
            .max((est.values[i] - g).norm() / g.norm())
            .max(((est.var_total[i] - vt[i]) / vt[i]).abs())
            .max(((est.var_noise[i] - vn[i]) / vn[i]).abs())
            .max(((est.var_nl[i] - vnl[i]) / vnl[i]).abs());
    }
    println!("fixture {q}: worst relative difference {worst:.2e}");
}

#[test]
fn matches_the_numpy_reference_fixture() {
    let opts = PeriodicOptions::new(32).skip(1);
    let fs = 100.0;
    let (h, rows) = read_csv("data_open.csv");
    let data = realisations(&h, &rows, &["u", "y"]);
    let recs: Vec<Record> = data
        .iter()
        .map(|c| Record::open_loop(&c[0], &c[1]))
        .collect();
    let bla = robust_bla(&recs, fs, &opts).unwrap();
    let (rh, rr) = read_csv("ref_open.csv");
    assert_matches(&bla.g, &rh, &rr, "g");

    let (h, rows) = read_csv("data_closed.csv");
    let data = realisations(&h, &rows, &["r", "u", "y"]);
    let recs: Vec<Record> = data
        .iter()
        .map(|c| Record::closed_loop(&c[0], &c[1], &c[2]))
        .collect();
    let bla = robust_bla(&recs, fs, &opts).unwrap();
    let (rh, rr) = read_csv("ref_closed.csv");
    assert_matches(&bla.g, &rh, &rr, "g");
    assert_matches(bla.t_ry.as_ref().unwrap(), &rh, &rr, "t_ry");
    assert_matches(bla.t_ru.as_ref().unwrap(), &rh, &rr, "t_ru");
}
