//! The second start of constrained state-space fits (`SsFreqOptions::second_start`) on random
//! twin rigs: for each rig, the seed experiment's period-averaged plant FRF (noise seed
//! `1000 + rig`, [`twin_seed_frf`]), the loop's unstable pole count from the controller
//! (`unstable_poles_from_loop`), and the sample maximum-likelihood `ss_frd` fits of the orders
//! [`TWIN_ORDERS`] held to that count, without and with the second start. Per fit: whether the
//! second start changed the model, the cost ratio, the median relative error against the exact
//! plant on the 10–1000 Hz lines, and pairs that cancel within the data. Prints one line per
//! rig and order that changed, a summary, and per order how many fits from the subspace start
//! end with a pole on the unit circle (`poles_on_unit_circle`; the workflow's models step
//! fits orders 6–9) (docs/estimation.md, "A second start for constrained fits").
//!
//! `cargo run --release -p ambid --example freqfit_free_start_rigs -- FIRST-LAST [linear|nonlinear]`

use ambid::uncertainty::{twin_seed_frf, TWIN_ORDERS};
use ambid_core::estimate::freqfit::{FreqData, FreqFitOptions, FreqWeights};
use ambid_core::estimate::freqfit_ss::{poles_on_unit_circle, ss_frd, SecondStart, SsFreqOptions};
use ambid_core::frf::closed_loop::RatioNoise;
use ambid_core::validate::compare::{cancelling_pairs, unstable_poles_from_loop};
use ambid_twin::Mode;
use anyhow::{Context, Result};
use std::time::{Duration, Instant};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let range = args.get(1).map_or("1-20", String::as_str);
    let (a, b) = range.split_once('-').context("FIRST-LAST")?;
    let (first, last): (u64, u64) = (a.parse()?, b.parse()?);
    let mode = match args.get(2).map(String::as_str) {
        Some("nonlinear") => Mode::Nonlinear,
        _ => Mode::Linear,
    };
    let (mut fits, mut changed, mut better, mut worse) = (0, 0, 0, 0);
    let (mut cancel_default, mut cancel_free, mut pinned) = (0, 0, 0);
    let mut pinned_per_order = std::collections::BTreeMap::<usize, usize>::new();
    let mut ratios = Vec::new();
    let (mut t_default, mut t_free) = (Duration::ZERO, Duration::ZERO);
    for rig in first..=last {
        let (out, frd) = twin_seed_frf(rig, 1000 + rig, mode)?;
        let noise: Vec<RatioNoise> = out
            .periodic_frf(ambid::uncertainty::TWIN_BAND_HZ, None)?
            .plant_noise
            .context("periodic estimate: plant noise")?;
        let controller = out.twin.controller().clone();
        let truth = out.twin.plant().freq_response_siso(frd.f_hz())?;
        let unstable = unstable_poles_from_loop(&frd, &controller, None).ok();
        let opts = FreqFitOptions {
            weights: FreqWeights::SampleMaximumLikelihood(noise),
            max_unstable_poles: unstable,
            ..FreqFitOptions::default()
        };
        let data = FreqData::new(&frd, &opts)?;
        let band: Vec<usize> = (0..frd.len())
            .filter(|&k| (10.0..=1000.0).contains(&frd.f_hz()[k]))
            .collect();
        let error = |m: &ambid_core::lti::StateSpace| -> Result<f64> {
            let r = m.freq_response_siso(frd.f_hz())?;
            Ok(median(
                band.iter()
                    .map(|&k| ((r[k] - truth[k]) / truth[k]).norm())
                    .collect(),
            ))
        };
        for order in TWIN_ORDERS {
            let t = Instant::now();
            let never = SsFreqOptions {
                second_start: SecondStart::Never,
                ..SsFreqOptions::default()
            };
            let d = ss_frd(&frd, order, &opts, &never);
            t_default += t.elapsed();
            let t = Instant::now();
            let fs = SsFreqOptions {
                second_start: std::env::var("ALWAYS")
                    .map_or(SecondStart::WhenPinned, |_| SecondStart::Always),
                ..SsFreqOptions::default()
            };
            let f = ss_frd(&frd, order, &opts, &fs);
            t_free += t.elapsed();
            let (Ok(d), Ok(f)) = (d, f) else {
                continue;
            };
            fits += 1;
            let on_circle = !poles_on_unit_circle(&d.model)?.is_empty();
            pinned += usize::from(on_circle);
            *pinned_per_order.entry(order).or_default() += usize::from(on_circle);
            let cd = !cancelling_pairs(&d.model, &data)?.is_empty();
            let cf = !cancelling_pairs(&f.model, &data)?.is_empty();
            cancel_default += usize::from(cd);
            cancel_free += usize::from(cf);
            if f.cost < d.cost {
                changed += 1;
                let (ed, ef) = (error(&d.model)?, error(&f.model)?);
                ratios.push(ef / ed);
                if ef < ed {
                    better += 1;
                } else {
                    worse += 1;
                }
                println!(
                    "rig {rig} order {order} (unstable {unstable:?}): cost x{:.4}, error vs truth {ed:.4e} -> {ef:.4e}, cancelling pairs {cd} -> {cf}",
                    f.cost / d.cost
                );
            }
        }
    }
    println!(
        "{fits} fits on rigs {first}-{last} ({mode:?}), {pinned} pinned from the subspace start: the second start changed {changed} (error vs truth lower on {better}, higher on {worse}; ratio median {:.3}), fits with a pair that cancels {cancel_default} -> {cancel_free}; fit time {:.1} s -> {:.1} s",
        if ratios.is_empty() { 1.0 } else { median(ratios.clone()) },
        t_default.as_secs_f64(),
        t_free.as_secs_f64()
    );
    let per: Vec<String> = pinned_per_order
        .iter()
        .map(|(o, n)| format!("{o}: {n}"))
        .collect();
    println!(
        "fits from the subspace start with a pole on the unit circle, per order (of {} rigs): {}",
        last - first + 1,
        per.join(", ")
    );
    Ok(())
}
