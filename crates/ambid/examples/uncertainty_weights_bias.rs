//! Why the library chain's bound missed on some random rigs (docs/uncertainty.md, "Weights that
//! follow the data's noise"): over `N` noise realisations of one twin rig (seeds 50 000 + i), the
//! fit of one order (the BIC's choice on the rig's own seed) with four kinds of weights, and the
//! per-100-Hz medians of the complex mean of its relative error (its bias) and of its standard
//! deviation over the realisations:
//!
//! * `data`: $1/v_k(\hat G_k)$, the FRF's variance at the data (`InverseVariance`, the default);
//! * `sml`: $1/v_k(G_\theta)$, at the model (`SampleMaximumLikelihood` with `plant_noise`);
//! * `mean`: the variances averaged over the `N` realisations (an oracle no record has: fixed
//!   weights close to the true variances);
//! * `smooth`: each record's variances averaged over ±`SM` lines (default 8).
//!
//! It also prints the order's own bias (the same fit to the exact plant on the same lines) for
//! the orders 6–12, so that a model-order bias can be told from an estimator bias.
//!
//! `cargo run --release -p ambid --example uncertainty_weights_bias -- RIG SEED N [linear|nonlinear]`
//! (e.g. `142 1142 40`).

use ambid::uncertainty::{twin_seed_frf, UncertaintyRun, TWIN_BAND_HZ, TWIN_ORDERS};
use ambid_core::c64;
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::estimate::freqfit_ss::{ss_frd, SsFreqOptions};
use ambid_core::lti::Frd;
use ambid_core::validate::compare::unstable_poles_from_loop;
use ambid_twin::Mode;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// `var` averaged over ±m lines.
fn smoothed(var: &[f64], m: usize) -> Vec<f64> {
    let l = var.len();
    (0..l)
        .map(|k| {
            let (lo, hi) = (k.saturating_sub(m), (k + m).min(l - 1));
            var[lo..=hi].iter().sum::<f64>() / (hi - lo + 1) as f64
        })
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |i: usize, d: &str| args.get(i).cloned().unwrap_or_else(|| d.to_string());
    let rig: u64 = arg(1, "142").parse().expect("RIG");
    let seed: u64 = arg(2, "1142").parse().expect("SEED");
    let n_real: usize = arg(3, "40").parse().expect("N");
    let mode = if arg(4, "linear") == "nonlinear" {
        Mode::Nonlinear
    } else {
        Mode::Linear
    };
    let sm: usize = std::env::var("SM").map_or(8, |v| v.parse().expect("SM"));
    let run = UncertaintyRun::on_twin_with_levels(rig, seed, mode, &[]).expect("the rig's run");
    let frd = &run.frd;
    let f = frd.f_hz().to_vec();
    let truth = run.truth_plant.freq_response_siso(&f).expect("truth");
    let n = run.nominal.order();
    let unstable = unstable_poles_from_loop(frd, &run.controller, None).ok();
    let opts = |weights| FreqFitOptions {
        weights,
        max_unstable_poles: unstable,
        ..FreqFitOptions::default()
    };
    println!(
        "rig {rig} seed {seed}: the BIC chose order {n}; {} lines",
        f.len()
    );
    let band: Vec<usize> = (0..f.len())
        .filter(|&k| (10.0..=1000.0).contains(&f[k]))
        .collect();
    let exact = Frd::new(
        f.clone(),
        truth.clone(),
        frd.variance().map(<[f64]>::to_vec),
        frd.ts(),
    )
    .expect("exact");
    for order in TWIN_ORDERS {
        if let Ok(fit) = ss_frd(
            &exact,
            order,
            &opts(FreqWeights::InverseVariance),
            &SsFreqOptions::default(),
        ) {
            let r = fit.model.freq_response_siso(&f).expect("response");
            let e: Vec<f64> = band
                .iter()
                .map(|&k| ((r[k] - truth[k]) / truth[k]).norm())
                .collect();
            println!(
                "  order {order} fitted to the exact plant: median relative error {:.1e}",
                median(e)
            );
        }
    }
    // the realisations
    let mut recs = Vec::new();
    for i in 0..n_real {
        let (out, g) = twin_seed_frf(rig, 50_000 + i as u64, mode).expect("realisation");
        let noise = out
            .periodic_frf(TWIN_BAND_HZ, None)
            .expect("frf")
            .plant_noise
            .expect("periodic estimate: plant noise");
        recs.push((g, noise));
    }
    let nn = n_real as f64;
    let mut vbar = vec![0.0; f.len()];
    for (g, _) in &recs {
        for (v, x) in vbar.iter_mut().zip(g.variance().expect("variance")) {
            *v += x / nn;
        }
    }
    let kinds = ["data", "sml", "mean", "smooth"];
    let z = c64::new(0.0, 0.0);
    let mut sum = vec![vec![z; f.len()]; kinds.len()];
    let mut sq = vec![vec![0.0; f.len()]; kinds.len()];
    for (g, noise) in &recs {
        let with_var =
            |v: Vec<f64>| Frd::new(f.clone(), g.values().to_vec(), Some(v), g.ts()).expect("frd");
        let fits = [
            (g.clone(), FreqWeights::InverseVariance),
            (
                g.clone(),
                FreqWeights::SampleMaximumLikelihood(noise.clone()),
            ),
            (with_var(vbar.clone()), FreqWeights::InverseVariance),
            (
                with_var(smoothed(g.variance().expect("variance"), sm)),
                FreqWeights::InverseVariance,
            ),
        ];
        for (j, (data, w)) in fits.into_iter().enumerate() {
            let m = ss_frd(&data, n, &opts(w), &SsFreqOptions::default())
                .expect("fit")
                .model;
            let r = m.freq_response_siso(&f).expect("response");
            for k in 0..f.len() {
                let e = (r[k] - truth[k]) / truth[k];
                sum[j][k] += e;
                sq[j][k] += e.norm_sqr();
            }
        }
    }
    println!("per 100 Hz: |mean relative error| / its sd over the {n_real} realisations (medians over the lines)");
    for lo in (0..10).map(|i| i as f64 * 100.0) {
        let ks: Vec<usize> = band
            .iter()
            .copied()
            .filter(|&k| f[k] >= lo && f[k] < lo + 100.0)
            .collect();
        let cells: Vec<String> = (0..kinds.len())
            .map(|j| {
                let b = median(ks.iter().map(|&k| (sum[j][k] / nn).norm()).collect());
                let sd = median(
                    ks.iter()
                        .map(|&k| {
                            (sq[j][k] / nn - (sum[j][k] / nn).norm_sqr())
                                .max(0.0)
                                .sqrt()
                        })
                        .collect(),
                );
                format!("{} {b:.1e}/{sd:.1e}", kinds[j])
            })
            .collect();
        println!("  {lo:4} Hz: {}", cells.join(" | "));
    }
}
