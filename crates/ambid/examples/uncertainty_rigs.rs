//! The uncertainty bound and the robust gain margin on random rigs of the twin (issue 23):
//! per rig and noise seed, the identified plant's error against the exact one, the bound's and
//! the weight's coverage of it on 10–1000 Hz, the weight's looseness, the robust upper gain
//! margin against the true loop's, and both robust gain margins of the check on the lines
//! (`on_lines`) and of the coherent draws (`coherent`, the reported ones) against the true ones.
//!
//! `cargo run --release -p ambid --example uncertainty_rigs -- RIGS SEEDS [linear|nonlinear] [LEVELS]`
//! (e.g. `1-20 1-5`; `LEVELS` such as `0.05,0.16` adds an amplitude study at those fractions of
//! $i_\text{sat}$ and its term (e); rig 0 is the nominal twin; the truth is the twin's linearised plant in
//! both modes, so with `nonlinear` the distortion the chain does not model is part of the
//! error). Each row also gives the joint raise and the coverage and ratio of
//! the weight before it (`W0`). Diagnostics: `DUMP=dir` writes each run's per-line bound, true
//! error and weight; `BAND_FIT=1` also fits a weight on the 10–1000 Hz lines alone, and
//! `ADDITIVE_FIT=1` an additive weight over the additive bound, judged as $|W_a|/|\hat P|$
//! (neither is a rule of the tool: docs/uncertainty.md, "Why the looseness bar is not met").
//! `CALIB=1` prints where the true error falls among draws of the first-order error model, and
//! statistics of the measured FRF's error against the exact plant (per line, over 16 lines,
//! its circularity and its sums over the whole band; with `CALIB_LAGS=1` its lag correlations;
//! with `SPLIT=1` the models of the record's two halves against each other by the same test);
//! `CALIB_SYNTH=1` first replaces the FRF by the exact plant plus circular Gaussian noise of the
//! measured variances; `TWIN_NOISE=noquant` simulates without the ADC quantisation and
//! `TWIN_NOISE=bias` also prints the noise-free record's FRF against the exact plant
//! (docs/uncertainty.md, "Mode-shaped weights").
//! `SHAPE=smooth|mode` refits the weight with that family (`WeightShape`; runs without
//! `LEVELS`; the default since 2026-12-02 is the mode-shaped one: docs/uncertainty.md,
//! "Mode-shaped weights" and "The mode-shaped weight as the single-axis default").
//! `SEED_PER_RIG=1` gives each rig its own noise realisation (seed = rig + each of `SEEDS`);
//! without it every rig runs with the same `SEEDS`, i.e. the same sensor-noise sequence
//! (docs/uncertainty.md, "Independent noise realisations"). With `CALIB=1`: `CALIB_FLOOR=1`
//! prints the looseness an ideal weight (the bound on the lines itself, raised for joint
//! coverage) would have against the draws and the truth; `PERIOD_DIAG=1` the correlation of
//! the FRF's deviations between neighbouring periods and the whole-band sum of the true error
//! against the periods' prediction (`PERIOD_SEQ=1`: that sum per period, its mean's t
//! statistics); `SYNTH_DOF=n` (with `CALIB_SYNTH=1`) hands the fit variances estimated with
//! `n` complex degrees of freedom instead of the true ones. `SMOOTH_VAR=m` refits with the
//! FRF's variances smoothed over ±m lines (as $\sigma_k^2|\bar U_k|^2$). `SHAPE` applies to
//! every refit. The nominal model's fits are by sample maximum likelihood (the FRF's variance
//! at the model, `FreqWeights::SampleMaximumLikelihood` with the estimate's `plant_noise`, the
//! default since the twenty-ninth session; the bound with the variance at the chosen model);
//! `AT_DATA=1` fits and bounds with the variance at the data instead
//! (`UncertaintyRun::on_twin_weighted`; `SML=1`, the option's old name, is accepted and changes
//! nothing);
//! `SMOOTH_VAR_PLAIN=m` refits with the variances themselves averaged over ±m lines (without
//! `LEVELS`; docs/uncertainty.md, "Weights that follow the data's noise").

use ambid::uncertainty::{loop_stable, nominal_gain_interval, UncertaintyRun};
use ambid_twin::Mode;

mod common;
use common::range;

/// The options of every re-analysis here: the default ones with `SHAPE`'s weight family
/// (`smooth` or `mode`; unset: the default, the mode-shaped family).
fn shape_opts() -> ambid_core::validate::uncertainty::UncertaintyOptions {
    let mut o = ambid_core::validate::uncertainty::UncertaintyOptions::default();
    if let Ok(name) = std::env::var("SHAPE") {
        o.weight_shape =
            ambid_core::validate::weight::WeightShape::from_name(&name).expect("SHAPE=smooth|mode");
    }
    o
}

/// [`ambid::uncertainty::analyse`] of `nominal` on `frd` with [`shape_opts`] and no extra term.
fn analyse_with_shape(
    nominal: &ambid_core::lti::StateSpace,
    frd: &ambid_core::lti::Frd,
    controller: &ambid_core::lti::StateSpace,
) -> ambid::uncertainty::UncertaintyAnalysis {
    ambid::uncertainty::analyse(
        nominal,
        frd,
        controller,
        &ambid_core::validate::uncertainty::ExtraTerms::default(),
        &shape_opts(),
        4,
        ambid_core::validate::weight::DEFAULT_COVER,
    )
    .unwrap()
}

/// The run's chain again from another FRF (the twin's truth kept): the BIC's nominal model and
/// its analysis.
fn refit(run: &mut UncertaintyRun, frd: ambid_core::lti::Frd) {
    let nominal = ambid::uncertainty::nominal_by_bic(&frd, &run.controller).unwrap();
    run.analysis = analyse_with_shape(&nominal, &frd, &run.controller);
    run.nominal = nominal;
    run.frd = frd;
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs = range(args.get(1).map_or("1-10", String::as_str));
    let seeds = range(args.get(2).map_or("1", String::as_str));
    let mode = match args.get(3).map_or("linear", String::as_str) {
        "nonlinear" => Mode::Nonlinear,
        _ => Mode::Linear,
    };
    // the amplitude study's extra levels (fractions of i_sat), e.g. `0.05,0.16`: term (e)
    let levels: Vec<f64> = args
        .get(4)
        .map(|s| s.split(',').map(|x| x.parse().unwrap()).collect())
        .unwrap_or_default();
    let (mut runs, mut ok_runs, mut ratios) = (0, 0, Vec::new());
    let (mut rs_ok, mut rs_half) = (0, 0);
    let (mut lines_ok, mut lines_half, mut lines_within) = (0, 0, 0);
    let (mut co_ok, mut co_half) = (0, 0);
    println!("rig seed order | cov_l cov_W | med_err med_W ratio | g_rob g_true | stable@90% half");
    for &rig in &rigs {
        // SEED_PER_RIG=1: the noise seed of each rig is the rig's number plus the given seed,
        // so that no two rigs share a noise realisation
        let seeds: Vec<u64> = if std::env::var("SEED_PER_RIG").is_ok() {
            seeds.iter().map(|s| s + rig).collect()
        } else {
            seeds.clone()
        };
        for &seed in &seeds {
            let t = std::time::Instant::now();
            // AT_DATA=1: the nominal model's fits with the variance at the data
            let weights = if std::env::var("AT_DATA").is_ok() {
                ambid::uncertainty::FitWeights::AtData
            } else {
                ambid::uncertainty::FitWeights::AtModel
            };
            let mut run = match UncertaintyRun::on_twin_weighted(rig, seed, mode, &levels, weights)
            {
                Ok(r) => r,
                Err(e) => {
                    println!("{rig} {seed}: {e}");
                    continue;
                }
            };
            if std::env::var("SHAPE").is_ok() {
                // the weight family SHAPE names (without levels: term (e) is not re-added)
                assert!(levels.is_empty(), "SHAPE is for runs without LEVELS");
                run.analysis = analyse_with_shape(&run.nominal, &run.frd, &run.controller);
            }
            if let Ok(what) = std::env::var("TWIN_NOISE") {
                // diagnostic: the same chain with the twin's measurement changed: `noquant`
                // (no ADC quantisation), `nonoise` is not allowed (no variances)
                use ambid::experiment::{run as simulate, ExcitationPlan, Experiment};
                let mut twin = if rig == 0 {
                    ambid_twin::TwinConfig::default()
                } else {
                    ambid_twin::random_rig(rig).unwrap()
                };
                assert!(
                    what == "noquant" || what == "bias",
                    "TWIN_NOISE=noquant|bias"
                );
                twin.sensor.quantize = false;
                if what == "bias" {
                    // the noise-free record's FRF against the exact plant, in units of the
                    // noisy FRF's standard deviation: the simulation's own systematic error
                    let exp = Experiment {
                        twin: twin.clone(),
                        excitation: ExcitationPlan::default(),
                        mode,
                        seed,
                        noise: false,
                        record_b: false,
                    };
                    let cl = simulate(&exp)
                        .unwrap()
                        .periodic_frf(ambid::uncertainty::TWIN_BAND_HZ, None)
                        .unwrap();
                    let g0 = cl.plant.values();
                    let f = cl.plant.f_hz().to_vec();
                    let truth = run.truth_plant.freq_response_siso(&f).unwrap();
                    let var = run.frd.variance().unwrap();
                    let band: Vec<usize> = (0..f.len())
                        .filter(|&k| (10.0..=1000.0).contains(&f[k]))
                        .collect();
                    let mut zs: Vec<f64> = band
                        .iter()
                        .map(|&k| (g0[k] - truth[k]).norm() / var[k].sqrt())
                        .collect();
                    let mut rel: Vec<f64> = band
                        .iter()
                        .map(|&k| (g0[k] - truth[k]).norm() / truth[k].norm())
                        .collect();
                    zs.sort_by(f64::total_cmp);
                    rel.sort_by(f64::total_cmp);
                    println!(
                        "    noise-free FRF - exact plant on 10-1000 Hz: |.|/sigma median {:.3} max {:.3}; relative median {:.2e} max {:.2e}",
                        zs[zs.len() / 2],
                        zs[zs.len() - 1],
                        rel[rel.len() / 2],
                        rel[rel.len() - 1]
                    );
                }
                let exp = Experiment {
                    twin,
                    excitation: ExcitationPlan::default(),
                    mode,
                    seed,
                    noise: true,
                    record_b: false,
                };
                let out = simulate(&exp).unwrap();
                let frd = out
                    .periodic_frf(ambid::uncertainty::TWIN_BAND_HZ, None)
                    .unwrap()
                    .plant;
                refit(&mut run, frd);
            }
            if let Ok(m) = std::env::var("SMOOTH_VAR") {
                // diagnostic: the FRF's variances smoothed over ±m lines before the fit and the
                // bound, as the output-referred noise σ_k² |Ū_k|² (smooth where |Ū| is not)
                let m: usize = m.parse().unwrap();
                let (out, _) = ambid::uncertainty::twin_seed_frf(rig, seed, mode).unwrap();
                let period = out.excitation.period_samples;
                let df = 1.0 / (out.record.ts * period as f64);
                let lines: Vec<usize> = run
                    .frd
                    .f_hz()
                    .iter()
                    .map(|f| (f / df).round() as usize)
                    .collect();
                let per = ambid_core::frf::periodic::PeriodicAnalyzer::new(period)
                    .unwrap()
                    .period_lines(
                        &[&out.record.u],
                        1.0 / out.record.ts,
                        &ambid_core::frf::periodic::PeriodicOptions::new(period).skip(1),
                        &lines,
                    )
                    .unwrap();
                let np = per.len() as f64;
                let u2: Vec<f64> = (0..lines.len())
                    .map(|i| (per.iter().map(|x| x[0][i]).sum::<ambid_core::c64>() / np).norm_sqr())
                    .collect();
                let var = run.frd.variance().unwrap();
                let sv: Vec<f64> = var.iter().zip(&u2).map(|(v, u)| v * u).collect();
                let l = sv.len();
                let smooth: Vec<f64> = (0..l)
                    .map(|k| {
                        let (lo, hi) = (k.saturating_sub(m), (k + m).min(l - 1));
                        sv[lo..=hi].iter().sum::<f64>() / (hi - lo + 1) as f64 / u2[k]
                    })
                    .collect();
                let frd = ambid_core::lti::Frd::new(
                    run.frd.f_hz().to_vec(),
                    run.frd.values().to_vec(),
                    Some(smooth),
                    run.frd.ts(),
                )
                .unwrap();
                refit(&mut run, frd);
            }
            if let Ok(m) = std::env::var("SMOOTH_VAR_PLAIN") {
                // diagnostic: the FRF's variances themselves averaged over ±m lines before the
                // fit and the bound (weights that do not follow each line's own noise)
                let m: usize = m.parse().unwrap();
                let var = run.frd.variance().unwrap();
                let l = var.len();
                let smooth: Vec<f64> = (0..l)
                    .map(|k| {
                        let (lo, hi) = (k.saturating_sub(m), (k + m).min(l - 1));
                        var[lo..=hi].iter().sum::<f64>() / (hi - lo + 1) as f64
                    })
                    .collect();
                let frd = ambid_core::lti::Frd::new(
                    run.frd.f_hz().to_vec(),
                    run.frd.values().to_vec(),
                    Some(smooth),
                    run.frd.ts(),
                )
                .unwrap();
                refit(&mut run, frd);
            }
            if std::env::var("CALIB_SYNTH").is_ok() {
                // diagnostic: the same chain on a synthetic FRF, the exact plant plus circular
                // complex Gaussian noise of the measured FRF's variances, so that the
                // first-order error model's assumptions hold but for the fit's linearisation
                use rand::SeedableRng;
                use rand_distr::{Distribution, StandardNormal};
                let f = run.frd.f_hz().to_vec();
                let var = run.frd.variance().unwrap().to_vec();
                let exact = run.truth_plant.freq_response_siso(&f).unwrap();
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
                let g: Vec<ambid_core::c64> = exact
                    .iter()
                    .zip(&var)
                    .map(|(p, v)| {
                        let s = (0.5 * v).sqrt();
                        let (a, b): (f64, f64) = (
                            StandardNormal.sample(&mut rng),
                            StandardNormal.sample(&mut rng),
                        );
                        p + ambid_core::c64::new(s * a, s * b)
                    })
                    .collect();
                // SYNTH_DOF=n: the variances handed to the fit are estimates with n complex
                // degrees of freedom (scaled chi-square), as the measured FRF's are
                let var: Vec<f64> = match std::env::var("SYNTH_DOF") {
                    Ok(n) => {
                        let n: usize = n.parse().unwrap();
                        var.iter()
                            .map(|v| {
                                let s: f64 = (0..2 * n)
                                    .map(|_| {
                                        let x: f64 = StandardNormal.sample(&mut rng);
                                        x * x
                                    })
                                    .sum();
                                v * s / (2 * n) as f64
                            })
                            .collect()
                    }
                    Err(_) => var,
                };
                let frd = ambid_core::lti::Frd::new(f, g, Some(var), run.frd.ts()).unwrap();
                refit(&mut run, frd);
            }
            let c = run.coverage((10.0, 1000.0)).unwrap();
            if std::env::var("CALIB").is_ok() {
                // diagnostic: is the true error a typical draw of the first-order error model?
                // T = the 95 % quantile over the 10-1000 Hz lines of e_k / ell_k, for the true
                // error and for 2 000 draws
                use rand::SeedableRng;
                let t = &run.analysis.terms;
                let band: Vec<usize> = (0..t.f_hz.len())
                    .filter(|&k| (10.0..=1000.0).contains(&t.f_hz[k]))
                    .collect();
                let f: Vec<f64> = band.iter().map(|&k| t.f_hz[k]).collect();
                let truth = run.truth_plant.freq_response_siso(&f).unwrap();
                let stat = |e: &dyn Fn(usize, usize) -> f64| {
                    let mut r: Vec<f64> = band
                        .iter()
                        .enumerate()
                        .map(|(i, &k)| e(i, k) / t.multiplicative[k])
                        .collect();
                    r.sort_by(f64::total_cmp);
                    r[(0.95 * r.len() as f64).ceil() as usize - 1]
                };
                let real = stat(&|i, k| (truth[i] - t.nominal[k]).norm() / t.nominal[k].norm());
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
                let mut draws = Vec::new();
                let mut e = Vec::new();
                for _ in 0..2000 {
                    t.errors.draw_relative(&mut rng, &mut e);
                    draws.push(stat(&|_, k| e[k]));
                }
                draws.sort_by(f64::total_cmp);
                if std::env::var("CALIB_FLOOR").is_ok() {
                    // the looseness an ideal weight would have: |W| = g_l * ell_k (the bound on
                    // the lines raised for joint coverage, no order-4 compromise) over the
                    // median of a draw's error, per draw of the error model and for the truth
                    let med = |v: &mut Vec<f64>| {
                        v.sort_by(f64::total_cmp);
                        v[v.len() / 2]
                    };
                    let g = run.analysis.lines_raise;
                    let mw = med(&mut band.iter().map(|&k| g * t.multiplicative[k]).collect());
                    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
                    let mut ratios: Vec<f64> = (0..2000)
                        .map(|_| {
                            t.errors.draw_relative(&mut rng, &mut e);
                            mw / med(&mut band.iter().map(|&k| e[k]).collect())
                        })
                        .collect();
                    ratios.sort_by(f64::total_cmp);
                    let under3 = ratios.iter().filter(|r| **r <= 3.0).count() as f64 / 2000.0;
                    let truth_ratio = mw
                        / med(&mut band
                            .iter()
                            .enumerate()
                            .map(|(i, &k)| (truth[i] - t.nominal[k]).norm() / t.nominal[k].norm())
                            .collect());
                    println!(
                        "    floor: ideal weight g_l*ell (g_l {g:.2}): median |W| / median error over draws: median {:.2}, q05 {:.2}, q95 {:.2}, <= 3 in {:.1} %; truth {truth_ratio:.2}",
                        ratios[1000], ratios[100], ratios[1900], 100.0 * under3
                    );
                }
                if std::env::var("SPLIT").is_ok() {
                    // the models of the record's two halves (periods 0-9 and 10-19, each with
                    // its first period skipped) against each other, by the same statistic, the
                    // draws scaled by the first-order ratio sqrt(2 * 19 / 9): the excess of the
                    // true error seen from the data alone
                    let half = |h: usize| {
                        let (mut o, _) =
                            ambid::uncertainty::twin_seed_frf(rig, seed, mode).unwrap();
                        let per = o.excitation.period_samples;
                        let (a, b) = (h * 10 * per, (h + 1) * 10 * per);
                        o.record.r = o.record.r[a..b].to_vec();
                        o.record.u = o.record.u[a..b].to_vec();
                        o.record.y = o.record.y[a..b].to_vec();
                        o.record.t = o.record.t[a..b].to_vec();
                        o.record.w = o.record.w[a..b].to_vec();
                        o.record.i = o.record.i[a..b].to_vec();
                        o.excitation.values = o.excitation.values[a..b].to_vec();
                        o.excitation.periods = 10;
                        let g = o
                            .periodic_frf(ambid::uncertainty::TWIN_BAND_HZ, None)
                            .unwrap()
                            .plant;
                        let m = ambid::uncertainty::nominal_by_bic(&g, &run.controller).unwrap();
                        m.freq_response_siso(&f).unwrap()
                    };
                    let (p1, p2) = (half(0), half(1));
                    let scale = (2.0f64 * 19.0 / 9.0).sqrt();
                    let td = stat(&|i, k| (p1[i] - p2[i]).norm() / t.nominal[k].norm() / scale);
                    let rank_d = draws.iter().filter(|d| **d < td).count() as f64 / 2000.0;
                    println!("    split: T_halves {td:.3} percentile {rank_d:.3}");
                }
                let rank = draws.iter().filter(|d| **d < real).count() as f64 / 2000.0;
                println!(
                    "    calib: T_true {real:.3}, draws median {:.3}, 95 % {:.3}; percentile {rank:.3}",
                    draws[1000], draws[1899]
                );
                // the FRF itself against the exact plant on the band's lines: chi2 per line
                // (1 if its variances are right and it is unbiased), and the same of 16-line
                // means of the normalised error (1 without a bias that is coherent over lines)
                let var = run.frd.variance().unwrap();
                let g = run.frd.values();
                let z: Vec<ambid_core::c64> = band
                    .iter()
                    .enumerate()
                    .map(|(i, &k)| (g[k] - truth[i]) / var[k].sqrt())
                    .collect();
                let chi2 = z.iter().map(|v| v.norm_sqr()).sum::<f64>() / z.len() as f64;
                let chunks: Vec<f64> = z
                    .chunks_exact(16)
                    .map(|c| (c.iter().sum::<ambid_core::c64>() / 16.0).norm_sqr() * 16.0)
                    .collect();
                let coherent = chunks.iter().sum::<f64>() / chunks.len() as f64;
                // non-circularity: the mean of the squared error turned by the plant's phase
                // (0 for circular noise; ±1 for noise along / across the plant's direction)
                let pseudo = band
                    .iter()
                    .enumerate()
                    .map(|(i, _)| {
                        let u = z[i] * truth[i].conj() / truth[i].norm();
                        u * u
                    })
                    .sum::<ambid_core::c64>()
                    / z.iter().map(|v| v.norm_sqr()).sum::<f64>();
                // correlation over the whole band: |sum z_k c_k|^2 / sum |c_k|^2 for a few
                // smooth complex weightings c_k (1 for independent noise, on average)
                let n = z.len() as f64;
                let whole = |c: &dyn Fn(usize) -> ambid_core::c64| {
                    let s: ambid_core::c64 = (0..z.len()).map(|i| z[i] * c(i)).sum();
                    s.norm_sqr() / (0..z.len()).map(|i| c(i).norm_sqr()).sum::<f64>()
                };
                if std::env::var("CALIB_LAGS").is_ok() {
                    let m2 = z.iter().map(|v| v.norm_sqr()).sum::<f64>() / n;
                    let lag = |m: usize| {
                        let s: ambid_core::c64 =
                            (0..z.len() - m).map(|i| z[i] * z[i + m].conj()).sum();
                        s / ((z.len() - m) as f64 * m2)
                    };
                    let l: Vec<String> = [1, 2, 3, 5, 10, 20, 50]
                        .iter()
                        .map(|&m| {
                            let r = lag(m);
                            format!("{m}:{:+.3}{:+.3}j", r.re, r.im)
                        })
                        .collect();
                    println!("    lags {}", l.join(" "));
                }
                if std::env::var("PERIOD_DIAG").is_ok() {
                    // the periods' deviations on the band: correlation between neighbouring
                    // periods (-1/(P-1) for independent periods), and the along-P whole-band
                    // sum of the true error against the periods' prediction of it
                    let d = &run.frf_periods;
                    let np = d.len();
                    let (mut c1, mut c2, mut c0) = (
                        ambid_core::c64::new(0.0, 0.0),
                        ambid_core::c64::new(0.0, 0.0),
                        0.0,
                    );
                    for &k in &band {
                        for p in 0..np {
                            c0 += d[p][k].norm_sqr();
                            if p + 1 < np {
                                c1 += d[p][k] * d[p + 1][k].conj();
                            }
                            if p + 2 < np {
                                c2 += d[p][k] * d[p + 2][k].conj();
                            }
                        }
                    }
                    let cw: Vec<ambid_core::c64> = band
                        .iter()
                        .enumerate()
                        .map(|(i, &k)| truth[i].conj() / truth[i].norm() / var[k].sqrt())
                        .collect();
                    let nc: f64 = cw
                        .iter()
                        .zip(&band)
                        .map(|(c, &k)| c.norm_sqr() * var[k])
                        .sum();
                    let true_sum: ambid_core::c64 = band
                        .iter()
                        .enumerate()
                        .map(|(i, &k)| (g[k] - truth[i]) * cw[i])
                        .sum();
                    // each period's deviation summed the same way
                    let dev_sums: Vec<ambid_core::c64> = d
                        .iter()
                        .map(|dp| {
                            band.iter()
                                .enumerate()
                                .map(|(i, &k)| dp[k] * cw[i])
                                .sum::<ambid_core::c64>()
                        })
                        .collect();
                    let pred: f64 =
                        dev_sums.iter().map(|x| x.norm_sqr()).sum::<f64>() / (np * (np - 1)) as f64;
                    if std::env::var("PERIOD_SEQ").is_ok() {
                        // each period's error against the truth: its deviation plus the mean's
                        let sv: Vec<ambid_core::c64> =
                            dev_sums.iter().map(|x| x + true_sum).collect();
                        let seq: Vec<String> = sv
                            .iter()
                            .map(|x| format!("{:+.1}", x.re / nc.sqrt()))
                            .collect();
                        println!(
                            "    seq(re, along-P, per period, units of one line-sum sd): {}",
                            seq.join(" ")
                        );
                        // t statistics of the per-period sums' mean, and their lag-1 correlation
                        let m = sv.iter().sum::<ambid_core::c64>() / np as f64;
                        let (mut vr, mut vi, mut l1) = (0.0, 0.0, 0.0);
                        for p in 0..np {
                            let x = sv[p] - m;
                            vr += x.re * x.re;
                            vi += x.im * x.im;
                            if p + 1 < np {
                                l1 += (x * (sv[p + 1] - m).conj()).re;
                            }
                        }
                        let sdm = |v: f64| (v / ((np - 1) * np) as f64).sqrt();
                        println!(
                            "    tstat re {:+.2} im {:+.2} lag1 {:+.3}",
                            m.re / sdm(vr),
                            m.im / sdm(vi),
                            l1 / (vr + vi)
                        );
                    }
                    let bands = [(10.0, 100.0), (100.0, 400.0), (400.0, 1000.0)];
                    let chis: Vec<String> = bands
                        .iter()
                        .map(|&(lo, hi)| {
                            let v: Vec<f64> = band
                                .iter()
                                .enumerate()
                                .filter(|(_, &k)| (lo..hi).contains(&t.f_hz[k]))
                                .map(|(i, _)| z[i].norm_sqr())
                                .collect();
                            format!("{:.2}", v.iter().sum::<f64>() / v.len().max(1) as f64)
                        })
                        .collect();
                    println!(
                        "    periods: P {np} lag1 {:+.3}{:+.3}j lag2 {:+.3}{:+.3}j | along-P true {:.2} periods {:.2} (independent lines: 1) | chi2 bands {}",
                        (c1 / c0).re, (c1 / c0).im, (c2 / c0).re, (c2 / c0).im,
                        true_sum.norm_sqr() / nc, pred / nc,  chis.join(" ")
                    );
                }
                let flat = whole(&|_| ambid_core::c64::new(1.0, 0.0));
                let along = whole(&|i| truth[i].conj() / truth[i].norm());
                let ramp = whole(&|i| ambid_core::c64::new(i as f64 / n - 0.5, 0.0));
                println!(
                    "    frf: chi2 {chi2:.3}, 16-line means {coherent:.3}, pseudo {:.3}{:+.3}j, whole-band sums flat {flat:.2} along-P {along:.2} ramp {ramp:.2}",
                    pseudo.re, pseudo.im
                );
            }
            let c0 = {
                let mut r0 = run.clone();
                r0.analysis.weight.weight.gain /= run.analysis.joint_raise;
                r0.coverage((10.0, 1000.0)).unwrap()
            };
            if std::env::var("BAND_FIT").is_ok() {
                // diagnostic: the weight fitted on the judgement band's lines alone
                let t = &run.analysis.terms;
                let idx: Vec<usize> = (0..t.f_hz.len())
                    .filter(|&k| (10.0..=1000.0).contains(&t.f_hz[k]))
                    .collect();
                let f: Vec<f64> = idx.iter().map(|&k| t.f_hz[k]).collect();
                let b: Vec<f64> = idx
                    .iter()
                    .map(|&k| t.multiplicative[k].max(1e-15))
                    .collect();
                let ts = run.nominal.ts().unwrap();
                if let Ok(wf) = ambid_core::validate::weight::fit_weight(&f, &b, ts, 4, 0.98) {
                    let mut r2 = run.clone();
                    r2.analysis.weight.weight = wf.weight;
                    let c2 = r2.coverage((10.0, 1000.0)).unwrap();
                    println!(
                        "    band-fitted weight: cov {:.3} ratio {:.2} order {}",
                        c2.weight_coverage,
                        c2.median_ratio,
                        r2.analysis.weight.weight.order()
                    );
                }
            }
            if std::env::var("ADDITIVE_FIT").is_ok() {
                // diagnostic: an additive weight |W_a| over the additive bound Δ, judged as
                // |W_a|/|P̂| against the relative error
                let t = &run.analysis.terms;
                let b: Vec<f64> = t.additive.iter().map(|x| x.max(1e-300)).collect();
                let ts = run.nominal.ts().unwrap();
                let o = shape_opts();
                match ambid_core::validate::weight::fit_weight_shaped(
                    &t.f_hz,
                    &b,
                    ts,
                    4,
                    0.98,
                    o.weight_shape,
                ) {
                    Ok(wf) => {
                        let mut wa = wf.weight.magnitude(&t.f_hz);
                        // raised as the tool raises its weight: the draws of the model's error
                        // against |W_a| / |P̂|
                        let rel: Vec<f64> = wa
                            .iter()
                            .zip(&t.nominal)
                            .map(|(w, p)| w / p.norm())
                            .collect();
                        let g = t
                            .errors
                            .joint_factors(&[&rel], o.raise_cover, o.run_coverage, o.draws, o.seed)
                            .map_or(f64::NAN, |v| v[0].max(1.0));
                        for x in &mut wa {
                            *x *= g;
                        }
                        let truth = run.truth_plant.freq_response_siso(&t.f_hz).unwrap();
                        let (mut cov, mut n, mut e, mut w) = (0, 0, vec![], vec![]);
                        for k in 0..t.f_hz.len() {
                            if (10.0..=1000.0).contains(&t.f_hz[k]) {
                                let pn = t.nominal[k].norm();
                                let err = (truth[k] - t.nominal[k]).norm() / pn;
                                n += 1;
                                cov += usize::from(wa[k] / pn >= err);
                                e.push(err);
                                w.push(wa[k] / pn);
                            }
                        }
                        e.sort_by(f64::total_cmp);
                        w.sort_by(f64::total_cmp);
                        println!(
                            "    additive weight: order {} raise {g:.3} cov {:.3} ratio {:.2} loose {:.2}",
                            wf.weight.order(),
                            cov as f64 / n as f64,
                            w[n / 2] / e[n / 2],
                            wf.looseness
                        );
                    }
                    Err(e) => println!("    additive weight: {e}"),
                }
            }
            if let Ok(dir) = std::env::var("DUMP") {
                let t = &run.analysis.terms;
                let truth = run.truth_plant.freq_response_siso(&t.f_hz).unwrap();
                let w = run.analysis.weight.weight.magnitude(&t.f_hz);
                let mut out = String::from("f,ell,err,W,conf,bias,absP,misfit,sigma,amp\n");
                let var = run.frd.variance().unwrap();
                for k in 0..t.f_hz.len() {
                    let e = (truth[k] - t.nominal[k]).norm() / t.nominal[k].norm();
                    out += &format!(
                        "{},{},{},{},{},{},{},{},{},{}\n",
                        t.f_hz[k],
                        t.multiplicative[k],
                        e,
                        w[k],
                        t.frf_confidence[k] / t.nominal[k].norm(),
                        t.model_error[k] / t.nominal[k].norm(),
                        t.nominal[k].norm(),
                        t.misfit[k] / t.nominal[k].norm(),
                        var[k].sqrt() / t.nominal[k].norm(),
                        t.amplitude.as_ref().map_or(0.0, |a| a[k]) / t.nominal[k].norm()
                    );
                }
                std::fs::write(format!("{dir}/u_{rig}_{seed}.csv"), out).unwrap();
            }
            runs += 1;
            if c.weight_coverage >= 0.95 {
                ok_runs += 1;
            }
            ratios.push(c.median_ratio);
            let (g_lo, g_hi) = nominal_gain_interval(&run.truth_plant, &run.controller).unwrap();
            let g = run.analysis.robust.upper_gain_margin.unwrap_or(f64::NAN);
            if g.is_nan() || std::env::var("MU_PEAK").is_ok() {
                let r = &run.analysis.robust;
                let w = &run.analysis.weight.weight;
                println!(
                    "    not robustly stable: nominal stable {}, mu peak {:.3} at {:.1} Hz; |W| there {:.3}; FRF band {:.1}-{:.1} Hz; W poles/zeros Hz {:?}",
                    r.nominal_stable,
                    r.mu_peak,
                    r.mu_peak_hz,
                    w.magnitude(&[r.mu_peak_hz])[0],
                    run.frd.f_hz()[0],
                    run.frd.f_hz()[run.frd.len() - 1],
                    w
                );
                let fp = [r.mu_peak_hz, 2500.0, 2900.0, 3100.0, 3300.0, 4000.0];
                let tt = |p: &ambid_core::lti::StateSpace| -> Vec<String> {
                    let pp = p.freq_response_siso(&fp).unwrap();
                    let cc = run.controller.freq_response_siso(&fp).unwrap();
                    pp.iter()
                        .zip(&cc)
                        .map(|(a, b)| format!("{:.2}", (a * b / (a * b + 1.0)).norm()))
                        .collect()
                };
                println!(
                    "    |T| at {:?} Hz: nominal {:?} true {:?}; nominal poles {:?}",
                    fp,
                    tt(&run.nominal),
                    tt(&run.truth_plant),
                    run.nominal
                        .poles()
                        .unwrap()
                        .iter()
                        .map(|z| format!(
                            "{:.1}Hz|{:.3}",
                            (z.ln().im / (2.0 * std::f64::consts::PI * 5e-5)).abs(),
                            z.norm()
                        ))
                        .collect::<Vec<_>>()
                );
            }
            let test_gain = 1.0 + 0.9 * (g - 1.0);
            let stable = loop_stable(&run.truth_plant, &run.controller, test_gain).unwrap_or(false);
            let half = (g - 1.0) >= 0.5 * (g_hi - 1.0);
            rs_ok += usize::from(stable);
            rs_half += usize::from(half);
            // both margins of a check: (lower, upper), stable at 90 % of each, at least half of
            // each true one
            let both = |lo: Option<f64>, hi: Option<f64>| {
                let (l, u) = (lo.unwrap_or(f64::NAN), hi.unwrap_or(f64::NAN));
                let stable = [1.0 + 0.9 * (u - 1.0), 1.0 - 0.9 * (1.0 - l)]
                    .iter()
                    .all(|g| loop_stable(&run.truth_plant, &run.controller, *g).unwrap_or(false));
                let half = (u - 1.0) >= 0.5 * (g_hi - 1.0) && (1.0 - l) >= 0.5 * (1.0 - g_lo);
                (l, u, stable, half)
            };
            // the check on the lines, and never beyond the true margins
            let ol = &run.analysis.on_lines;
            let (ll, lu, l_stable, l_half) = both(ol.lower_gain_margin, ol.upper_gain_margin);
            lines_ok += usize::from(l_stable);
            lines_half += usize::from(l_half);
            lines_within += usize::from(lu <= g_hi * (1.0 + 1e-3) && ll >= g_lo * (1.0 - 1e-3));
            // the coherent draws (the reported margins)
            let co = &run.analysis.coherent;
            let (cl, cu, c_stable, c_half) = both(co.lower_gain_margin, co.upper_gain_margin);
            co_ok += usize::from(c_stable);
            co_half += usize::from(c_half);
            println!("    coherent {cl:.3} {cu:.3} {c_stable} {c_half}");
            println!(
                "{rig:3} {seed:3} {:2} | {:.3} {:.3} | {:.2e} {:.2e} {:.2} | {:.3} {:.3} | {} {} | W order {} loose {:.2} | raise {:.2} W0 cov {:.3} ratio {:.2} | lines {ll:.3} {lu:.3} (true {g_lo:.3} {g_hi:.3}) {l_stable} {l_half} | (e) on {} lines | (f) {:.1e} | {:.1}s",
                run.nominal.order(),
                c.bound_coverage,
                c.weight_coverage,
                c.median_error,
                c.median_weight,
                c.median_ratio,
                g,
                g_hi,
                stable,
                half,
                run.analysis.weight.weight.order(),
                run.analysis.weight.looseness,
                run.analysis.joint_raise,
                c0.weight_coverage,
                c0.median_ratio,
                run.analysis
                    .terms
                    .amplitude
                    .as_ref()
                    .map_or(0, |e| e.iter().filter(|x| **x > 0.0).count()),
                // term (f): 0 for the BIC's own fit (a model of another estimator has a distance)
                run.analysis.terms.fit_distance_median_rel().unwrap_or(f64::NAN),
                t.elapsed().as_secs_f64()
            );
        }
    }
    ratios.sort_by(f64::total_cmp);
    println!(
        "runs {runs}: weight covers ≥95 % of lines in {ok_runs} ({:.1} %); ratio median {:.2}, max {:.2}; RS stable at 90 %: {rs_ok}, margin ≥ half: {rs_half}; on the lines (both margins): stable at 90 % {lines_ok}, ≥ half {lines_half}, within the true {lines_within}; coherent (both margins): stable at 90 % {co_ok}, ≥ half {co_half}",
        100.0 * ok_runs as f64 / runs.max(1) as f64,
        ratios.get(ratios.len() / 2).copied().unwrap_or(f64::NAN),
        ratios.last().copied().unwrap_or(f64::NAN)
    );
}
