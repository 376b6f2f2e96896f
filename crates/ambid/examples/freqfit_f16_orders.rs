//! The stable state-space fit on the F-16 ground vibration test (`shared/data/real/f16-gvt`,
//! full multisine level 1; docs/estimation.md, "A second start for constrained fits"): for
//! output `OUT` (0, 1 or 2), the SISO period-averaged FRF of periods 2–5 (r = voltage, u =
//! force, 2–15 Hz, `from_periodic_iodata`), fitted by `ss_frd` with the inverse variance at the
//! data, held to 0 unstable poles, orders 10–32, from the subspace start alone
//! (`SecondStart::Never`, the default) and with the second start (`WhenPinned`). Per fit: the
//! poles within `PINNED` of the unit circle (frequency; "real" for z = ±1), χ² against the
//! FRF's variances, BIC, refinement steps, the pairs that cancel within the data, whether
//! `out_of_band_resonance` flags it, and the median relative error against the held-out FRF of
//! periods 6–9. The last lines count, per start, the fits with a pole on the circle and those
//! flagged out of band.
//!
//! `cargo run --release -p ambid --example freqfit_f16_orders -- OUT`
use ambid_core::data::IoData;
use ambid_core::estimate::freqfit::{FreqData, FreqFitOptions, FreqWeights};
use ambid_core::estimate::freqfit_ss::{poles_on_unit_circle, ss_frd, SecondStart, SsFreqOptions};
use ambid_core::frf::closed_loop::from_periodic_iodata;
use ambid_core::validate::compare::cancelling_pairs;
use std::error::Error;

const PERIOD: usize = 8192;

fn main() -> Result<(), Box<dyn Error>> {
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let path = here
        .ancestors()
        .map(|a| a.join("shared/data/real/f16-gvt/F16Data_FullMSine_Level1.csv"))
        .find(|p| p.exists())
        .ok_or("shared/data/real/f16-gvt/F16Data_FullMSine_Level1.csv not found")?;
    let text = std::fs::read_to_string(path)?;
    let mut cols = vec![Vec::new(); 5];
    for line in text.lines().skip(1).filter(|l| !l.trim().is_empty()) {
        for (c, v) in line.split(',').take(5).enumerate() {
            cols[c].push(v.trim().parse::<f64>()?);
        }
    }
    let out: usize = std::env::args().nth(1).map_or(Ok(0), |s| s.parse())?;
    if out > 2 {
        return Err("OUT is 0, 1 or 2".into());
    }
    let siso = |(from, to): (usize, usize)| -> Result<_, Box<dyn Error>> {
        let part = |c: usize| cols[c][from * PERIOD..to * PERIOD].to_vec();
        let d = IoData::new(
            vec![
                ("r".into(), part(1)),
                ("u".into(), part(0)),
                ("y".into(), part(2 + out)),
            ],
            1.0 / 400.0,
            Some(PERIOD),
        )?;
        Ok(from_periodic_iodata(&d, (2.0, 15.0), 1e-3, None)?)
    };
    let (est, held) = (siso((1, 5))?, siso((5, 9))?);
    let frd = &est.plant;
    let var = frd.variance().ok_or("no variances")?;
    let opts = FreqFitOptions {
        weights: FreqWeights::InverseVariance,
        max_unstable_poles: Some(0),
        ..FreqFitOptions::default()
    };
    let data = FreqData::new(frd, &opts)?;
    let n_eq = 2.0 * frd.len() as f64;
    let starts = [SecondStart::Never, SecondStart::WhenPinned];
    let (mut on_circle, mut beyond) = ([0usize; 2], [0usize; 2]);
    println!("output y_{}: order start | poles on the unit circle | chi2 | BIC | steps | cancelling pairs | out of band | held-out median relative error", out + 1);
    for order in 10..=32 {
        for (s, ss) in starts.iter().enumerate() {
            let ss_opts = SsFreqOptions {
                second_start: *ss,
                ..SsFreqOptions::default()
            };
            let fit = match ss_frd(frd, order, &opts, &ss_opts) {
                Ok(f) => f,
                Err(e) => {
                    println!("{order} {ss:?}: failed: {e}");
                    continue;
                }
            };
            let g = fit.model.freq_response_siso(frd.f_hz())?;
            let chi2: f64 = g
                .iter()
                .zip(frd.values())
                .enumerate()
                .map(|(k, (m, v))| (m - v).norm_sqr() / var[k])
                .sum();
            let bic = 2.0 * chi2 + fit.n_params as f64 * n_eq.ln();
            let ts = 1.0 / 400.0;
            let pinned: Vec<String> = poles_on_unit_circle(&fit.model)?
                .iter()
                .map(|p| {
                    let f = p.arg().abs() / (2.0 * std::f64::consts::PI * ts);
                    if p.im == 0.0 {
                        format!("{f:.1} Hz (real)")
                    } else {
                        format!("{f:.2} Hz")
                    }
                })
                .collect();
            let cancel = cancelling_pairs(&fit.model, &data)?.len();
            let oob = ambid::uncertainty::out_of_band_resonance(&fit.model, (2.0, 15.0))?.is_some();
            let mut e: Vec<f64> = g
                .iter()
                .zip(held.plant.values())
                .map(|(m, v)| (v - m).norm() / m.norm())
                .collect();
            e.sort_by(f64::total_cmp);
            on_circle[s] += usize::from(!pinned.is_empty());
            beyond[s] += usize::from(oob);
            println!(
                "{order} {ss:?} | {pinned:?} | {chi2:.0} | {bic:.0} | {} | {cancel} | {oob} | {:.4}",
                fit.iterations,
                e[e.len() / 2]
            );
        }
    }
    for (s, ss) in starts.iter().enumerate() {
        println!(
            "{ss:?}: {} of 23 fits with a pole on the unit circle, {} flagged out of band",
            on_circle[s], beyond[s]
        );
    }
    Ok(())
}
