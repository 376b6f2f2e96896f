//! The uncertainty bound on a **Welch** FRF (non-periodic excitation) on random rigs of the twin:
//! why it can be short of the truth (docs/uncertainty.md, "Welch FRFs: where the bound falls
//! short").
//!
//! `cargo run --release -p ambid --example uncertainty_welch_rigs -- RIGS [SEEDS] [linear|nonlinear]`
//!
//! Each run is the chain of `ambid simulate --signal noise --level 5% --band 1:2000` (the seed
//! experiment's length, 20 × 5115 samples), `ambid frf` (Welch: Hann, the default segment,
//! 50 % overlap, the derived band), the BIC's state-space model ([`nominal_by_bic`]) and the
//! default bound ([`analyse`]), all judged on the FRF's own lines in 10–1000 Hz against the
//! twin's exact plant. Per run it prints:
//! - the FRF against the truth: the median of $|\hat G_k - G_k|^2/\sigma_k^2$ (ln 2 = 0.69 for a
//!   circular error of the stated variance), the fraction inside the FRF's 95 % disc, and the
//!   lag-1 and lag-2 correlation of the normalised errors $(\hat G_k - G_k)/\sigma_k$ (0 for
//!   independent lines);
//! - the bound's and the weight's coverage of the model's true relative error and the weight's
//!   looseness (as every sweep);
//! - the lines' correlation the bound found and its variance factor κ (`CorrelatedLines::Auto`;
//!   `OFF=1` takes the lines as independent, the rule before 2026-12-06);
//! - with `BIC_KAPPA=1`, the BIC's order chosen again with the variances times that factor
//!   (a diagnostic; the bound then estimates its factor from the new model's misfit);
//! - with `DUMP=prefix`, per line the true relative error, ℓ, |W| and terms (a), (b) in
//!   `prefix_<rig>_<seed>.csv`;
//! - with `NOISE_FREE=1`, the same excitation without sensor noise: its FRF's error against the
//!   truth, over the noisy FRF's $\sigma_k$ (the part of the error that does not average out
//!   with more data of the same noise realisation; a leakage bias or a leakage noise), and the
//!   error of a model fitted to that FRF against the noisy run's bound;
//! - with `DIAG=1`, the medians of the true error and of terms (a) and (b), block means of the
//!   normalised FRF error over 4, 16 and 64 lines against the short-range prediction, and the
//!   chain on synthetic FRFs (the truth plus circular noise of the measured variances,
//!   independent or with the measured lag-1 correlation).
//!
//! With several `SEEDS` per rig it also prints, per rig, the mean over the seeds of the
//! normalised FRF error per line: a bias shows as $|\bar e_k|\sqrt{S}$ well above 1 on lines
//! where the error does not average out.

use ambid::uncertainty::{analyse, nominal_by_bic, twin_noise_welch_frf, UncertaintyRun};
use ambid_core::c64;
use ambid_core::validate::uncertainty::{ExtraTerms, UncertaintyOptions};
use ambid_core::validate::weight::DEFAULT_COVER;
use ambid_twin::Mode;

mod common;
use common::range;

/// The plant FRF of the noise experiment on `rig` with noise seed `seed` (`noise`: sensor noise
/// on), by the command's Welch defaults, and the twin's exact plant and controller.
fn welch_plant(
    rig: u64,
    seed: u64,
    mode: Mode,
    noise: bool,
) -> (
    ambid_core::lti::Frd,
    ambid_core::lti::StateSpace,
    ambid_core::lti::StateSpace,
) {
    let (out, frd) = twin_noise_welch_frf(rig, seed, mode, noise).expect("the Welch FRF");
    (frd, out.twin.plant().clone(), out.twin.controller().clone())
}

/// Lag-`l` correlation of the complex sequence `e` (real part of the normalised sum).
fn lag_corr(e: &[c64], l: usize) -> f64 {
    let num: c64 = e.iter().zip(&e[l..]).map(|(a, b)| a.conj() * b).sum();
    let den: f64 = e.iter().map(|a| a.norm_sqr()).sum();
    num.re / den
}

/// The default options, or with `OFF=1` the lines taken as independent (the rule before
/// 2026-12-06).
fn opts() -> UncertaintyOptions {
    let mut o = UncertaintyOptions::default();
    if std::env::var("OFF").is_ok() {
        o.correlated_lines = ambid_core::validate::uncertainty::CorrelatedLines::Off;
    }
    o
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs = range(args.get(1).map_or("1-10", String::as_str));
    let seeds = range(args.get(2).map_or("0", String::as_str));
    let mode = match args.get(3).map_or("linear", String::as_str) {
        "nonlinear" => Mode::Nonlinear,
        _ => Mode::Linear,
    };
    let band = (10.0, 1000.0);
    let (mut runs, mut covered, mut ratios) = (0, 0, Vec::new());
    println!("rig seed | FRF: med chi2 in95 lag1 lag2 | model order | cov_l cov_W ratio");
    for &rig in &rigs {
        let mut sums: Vec<c64> = Vec::new();
        for &s in &seeds {
            let seed = rig * 1000 + s;
            let (frd, truth, controller) = welch_plant(rig, seed, mode, true);
            let f = frd.f_hz().to_vec();
            let idx: Vec<usize> = (0..f.len())
                .filter(|&k| (band.0..=band.1).contains(&f[k]))
                .collect();
            let fb: Vec<f64> = idx.iter().map(|&k| f[k]).collect();
            let g = truth.freq_response_siso(&fb).expect("truth");
            let var = frd.variance().expect("variances");
            let e: Vec<c64> = idx
                .iter()
                .zip(&g)
                .map(|(&k, gt)| (frd.values()[k] - gt) / var[k].sqrt())
                .collect();
            if sums.is_empty() {
                sums = vec![c64::new(0.0, 0.0); e.len()];
            }
            for (a, b) in sums.iter_mut().zip(&e) {
                *a += b;
            }
            let chi: Vec<f64> = e.iter().map(|x| x.norm_sqr()).collect();
            // a circular complex error of variance σ²: |e|²/σ² is exponential, 95 % below ln 20
            let in95 = chi.iter().filter(|&&c| c <= 20f64.ln()).count() as f64 / chi.len() as f64;
            let nominal = match nominal_by_bic(&frd, &controller) {
                Ok(m) => m,
                Err(err) => {
                    println!("{rig} {seed}: {err}");
                    continue;
                }
            };
            // BIC_KAPPA=1: the order chosen again with the variances times the lines' factor
            // (the likelihood of correlated lines, roughly), the fit on the FRF as measured
            let nominal = if std::env::var("BIC_KAPPA").is_ok() {
                let p = nominal.freq_response_siso(&f).expect("model");
                let m: Vec<c64> = (0..f.len()).map(|k| frd.values()[k] - p[k]).collect();
                let lc = ambid_core::validate::uncertainty::line_correlation(&[(&m, var)])
                    .expect("correlation");
                let scaled = ambid_core::lti::Frd::new(
                    f.clone(),
                    frd.values().to_vec(),
                    Some(var.iter().map(|v| v * lc.factor).collect()),
                    frd.ts(),
                )
                .expect("scaled FRF");
                nominal_by_bic(&scaled, &controller).unwrap_or(nominal)
            } else {
                nominal
            };
            let analysis = analyse(
                &nominal,
                &frd,
                &controller,
                &ExtraTerms::default(),
                &opts(),
                4,
                DEFAULT_COVER,
            )
            .expect("the bound");
            let ur = UncertaintyRun {
                frd: frd.clone(),
                nominal: nominal.clone(),
                analysis,
                truth_plant: truth.clone(),
                controller: controller.clone(),
                frf_periods: Vec::new(),
            };
            let c = ur.coverage(band).expect("coverage");
            let lc = ur.analysis.terms.line_correlation;
            runs += 1;
            covered += usize::from(c.weight_coverage >= 0.95);
            ratios.push(c.median_ratio);
            print!(
                "{rig:3} {seed:6} | {:.2} {:.3} {:+.2} {:+.2} | {:2} | κ {:.2} (ρ {:+.2} {:+.2}) | {:.3} {:.3} {:.2}",
                median(chi.clone()),
                in95,
                lag_corr(&e, 1),
                lag_corr(&e, 2),
                nominal.order(),
                lc.factor,
                lc.rho1,
                lc.rho2,
                c.bound_coverage,
                c.weight_coverage,
                c.median_ratio,
            );
            if std::env::var("NOISE_FREE").is_ok() {
                let (clean, _, _) = welch_plant(rig, seed, mode, false);
                assert_eq!(clean.f_hz(), frd.f_hz(), "the same lines without noise");
                let b: Vec<f64> = idx
                    .iter()
                    .zip(&g)
                    .map(|(&k, gt)| (clean.values()[k] - gt).norm_sqr() / var[k])
                    .collect();
                let worst = b.iter().copied().fold(0.0, f64::max);
                // the model fitted to the noise-free FRF (the noisy variances as weights): the
                // error the leakage bias alone leaves in a model, against the noisy run's bound
                let cf = ambid_core::lti::Frd::new(
                    f.clone(),
                    clean.values().to_vec(),
                    Some(var.to_vec()),
                    frd.ts(),
                )
                .expect("noise-free FRF");
                if let Ok(mc) = nominal_by_bic(&cf, &controller) {
                    let t = &ur.analysis.terms;
                    let pc = mc.freq_response_siso(&fb).expect("model");
                    let mut over = 0usize;
                    let mut rel = Vec::new();
                    for (i, &k) in idx.iter().enumerate() {
                        let eb = (pc[i] - g[i]).norm() / g[i].norm();
                        let et = (t.nominal[k] - g[i]).norm() / t.nominal[k].norm();
                        over += usize::from(eb > t.multiplicative[k]);
                        rel.push(eb / et);
                    }
                    print!(
                        " | bias-only model (order {}): above ℓ on {:.3}, median vs the true error {:.2}",
                        mc.order(),
                        over as f64 / idx.len() as f64,
                        median(rel)
                    );
                }
                print!(
                    " | noise-free: med {:.3} max {:.2} (|.|²/σ²)",
                    median(b.clone()),
                    worst
                );
            }
            if let Ok(path) = std::env::var("DUMP") {
                // per line in 10–1000 Hz: f, true relative error, ℓ, |W|, term (a) and (b)
                // relative, the FRF's relative std
                use std::fmt::Write;
                let t = &ur.analysis.terms;
                let mut out = String::from("f_hz,err,ell,w,a_rel,b_rel,std_rel\n");
                for &k in &idx {
                    let gt = truth.freq_response_siso(&[t.f_hz[k]]).expect("truth")[0];
                    let pn = t.nominal[k].norm();
                    let w = ur.analysis.weight.weight.magnitude(&[t.f_hz[k]])[0];
                    let _ = writeln!(
                        out,
                        "{},{:e},{:e},{:e},{:e},{:e},{:e}",
                        t.f_hz[k],
                        (gt - t.nominal[k]).norm() / pn,
                        t.multiplicative[k],
                        w,
                        t.frf_confidence[k] / pn,
                        t.model_error[k] / pn,
                        var[k].sqrt() / pn
                    );
                }
                std::fs::write(format!("{path}_{rig}_{seed}.csv"), out).expect("dump");
            }
            if std::env::var("DIAG").is_ok() {
                let t = &ur.analysis.terms;
                let ti: Vec<usize> = (0..t.f_hz.len())
                    .filter(|&k| (band.0..=band.1).contains(&t.f_hz[k]))
                    .collect();
                let gt = truth
                    .freq_response_siso(&ti.iter().map(|&k| t.f_hz[k]).collect::<Vec<_>>())
                    .expect("truth");
                let abs_err: Vec<f64> = ti
                    .iter()
                    .zip(&gt)
                    .map(|(&k, g)| (g - t.nominal[k]).norm())
                    .collect();
                let pick = |v: &[f64]| median(ti.iter().map(|&k| v[k]).collect());
                print!(
                    " | abs err {:.2e} (a) {:.2e} (b) {:.2e} misfit {:.2e} (b)>0 on {} | raise {:.2} roughness {:?}",
                    median(abs_err.clone()),
                    pick(&t.frf_confidence),
                    pick(&t.model_error),
                    pick(&t.misfit),
                    ti.iter().filter(|&&k| t.model_error[k] > 0.0).count(),
                    ur.analysis.joint_raise,
                    t.misfit_roughness.map(|r| (r * 100.0).round() / 100.0),
                );
                // the same chain on synthetic FRFs: the truth plus circular Gaussian noise of
                // the measured variances, independent over the lines (rho 0) or moving-average
                // correlated with the lag-1 correlation rho of the measured errors
                // block means of the normalised FRF error over w lines, against what an MA(1)
                // error of the measured lag-1 correlation gives: ~1 for short-range errors
                let r1 = lag_corr(&e, 1);
                for w in [4usize, 16, 64] {
                    let blocks: Vec<f64> = e
                        .chunks_exact(w)
                        .map(|c| c.iter().sum::<c64>().norm_sqr() / w as f64 / (1.0 + 2.0 * r1))
                        .collect();
                    let m = blocks.iter().sum::<f64>() / blocks.len() as f64;
                    print!(" | blocks {w}: {m:.2} ({})", blocks.len());
                }
                let rho = r1.clamp(0.0, 0.49);
                let gall = truth.freq_response_siso(&f).expect("truth");
                for r in [0.0, rho] {
                    use rand::SeedableRng;
                    use rand_distr::{Distribution, StandardNormal};
                    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
                    // MA(1) x_k = a w_k + b w_{k-1}, a² + b² = 1, ab = r
                    let b = if r > 0.0 {
                        ((1.0 - (1.0 - 4.0 * r * r).sqrt()) / 2.0).sqrt()
                    } else {
                        0.0
                    };
                    let a = (1.0 - b * b).sqrt();
                    let w: Vec<c64> = (0..=f.len())
                        .map(|_| {
                            let re: f64 = StandardNormal.sample(&mut rng);
                            let im: f64 = StandardNormal.sample(&mut rng);
                            c64::new(re, im) * std::f64::consts::FRAC_1_SQRT_2
                        })
                        .collect();
                    let vals: Vec<c64> = (0..f.len())
                        .map(|k| gall[k] + (w[k + 1] * a + w[k] * b) * var[k].sqrt())
                        .collect();
                    let synth =
                        ambid_core::lti::Frd::new(f.clone(), vals, Some(var.to_vec()), frd.ts())
                            .expect("synthetic FRF");
                    let Ok(m) = nominal_by_bic(&synth, &controller) else {
                        print!(" | synth rho {r:.2}: no model");
                        continue;
                    };
                    let an = analyse(
                        &m,
                        &synth,
                        &controller,
                        &ExtraTerms::default(),
                        &opts(),
                        4,
                        DEFAULT_COVER,
                    )
                    .expect("the bound");
                    let sr = UncertaintyRun {
                        frd: synth,
                        nominal: m,
                        analysis: an,
                        truth_plant: truth.clone(),
                        controller: controller.clone(),
                        frf_periods: Vec::new(),
                    };
                    let sc = sr.coverage(band).expect("coverage");
                    print!(
                        " | synth rho {r:.2}: {:.3} {:.3} {:.2}",
                        sc.bound_coverage, sc.weight_coverage, sc.median_ratio
                    );
                }
            }
            println!();
        }
        if seeds.len() > 1 {
            let ns = seeds.len() as f64;
            // the mean over seeds, in units of its own standard error: |Σe|/√S
            let t: Vec<f64> = sums.iter().map(|x| x.norm_sqr() / ns).collect();
            let over = t.iter().filter(|&&x| x > 20f64.ln()).count();
            println!(
                "rig {rig}: mean over {} seeds: med |Σe|²/S {:.2} (ln 2 = 0.69 unbiased), above ln 20 on {over} of {} lines",
                seeds.len(),
                median(t.clone()),
                t.len()
            );
        }
    }
    println!(
        "runs {runs}: weight covers ≥95 % of the lines in {covered}; ratio median {:.2}",
        if ratios.is_empty() {
            f64::NAN
        } else {
            median(ratios)
        }
    );
}
