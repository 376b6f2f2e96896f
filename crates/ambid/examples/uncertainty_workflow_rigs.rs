//! The workflow's `uncertainty` step as a user runs it (issue 23): per rig the workflow with
//! `steps = uncertainty` and its prerequisites (the FRF, the order study, the models step and its
//! choice) on `random_rig(rig)` with noise seed `rig`, the chosen model's bound against the twin.
//! Unlike `uncertainty_rigs`, whose nominal model is the BIC's choice among state-space fits,
//! the nominal model here is the one the workflow's models step chooses (`[models] select`,
//! default the best validation fit).
//!
//! Per rig: the chosen model, a resonance of it outside the models' band
//! ([`ambid::uncertainty::out_of_band_resonance`]), the fraction of the 10–1000 Hz lines where
//! |W| covers the chosen model's true relative error, median |W| / median error, and both
//! robust gain margins of the weight and of the check on the lines against the true loop's
//! interval: whether the true loop stays stable with the gain moved 90 % of the way to each,
//! and whether each is at least half the true one; the same for the coherent margins (the
//! reported ones since 2026-12-07, docs/uncertainty.md "Coherent margins on one axis") on a
//! line `coherent | rig | lower upper | stable half` per rig and in the summary. A missing
//! margin (not robustly stable) fails both.
//!
//! `cargo run --release -p ambid --example uncertainty_workflow_rigs -- RIGS [linear|nonlinear]`
//! (e.g. `1-40`, or `3,7,11`). The step's prerequisites bring the amplitude study (term (e)).
//! `SHOW_U=1` prints the step's summary and the amplitude study's, `SHOW_TABLE=1` the step's
//! tables, `DECOMPOSE=1` median ℓ / median error, median |W| / ℓ, the joint raise and the
//! weight's order, and the per-line medians of ℓ_k / e_k and |W_k| / e_k (the looseness read
//! line by line), `SHOW_MISS=1` the lines where
//! |W| is below the true error, with the terms there. Since 2026-12-02 the prerequisites also
//! bring the robust BLA study (term (c)); `NO_BLA=1` leaves it out (the bound then has no
//! term (c), as before). Per rig the last column is term (c): the BLA level it was read at and
//! its significant groups of lines. `PRINT_E=1` prints every 10th line's term (e) and term (a)
//! (relative) beside the true error. `DUMP_SERIES=DIR` writes per run `DIR/<mode>_<rig>_raise<g>.csv`
//! (`f_hz`, `bound`, `weight`, `error` on the weight's lines; g the joint raise) for
//! `scripts/weight_global_fit.py`. `EXCITATION=noise` (or `chirp`, `multisine`) runs the
//! workflow with that excitation instead of the default PRBS (a noise excitation gives a Welch
//! FRF); `FRF_BAND=lo,hi` gives the FRF's band (`[frf] band_hz`) instead of deriving it from the
//! excitation; `REF_FIT=1` prints the BIC's inverse-variance state-space fit to the step's FRF beside
//! the chosen model, both against the truth (docs/uncertainty.md, "A model not fitted to the
//! FRF"); `AMP_LEVELS_AT=F` prints each amplitude-study level's plant FRF against the exact plant
//! on the lines within 20 Hz of F Hz (error and standard deviation relative to |P|, and their
//! ratio; docs/uncertainty.md, "Term (e) on a Welch FRF"); `NOMINAL_GM=1` prints the chosen
//! model's own gain interval with the twin's controller (no robust margin can exceed it);
//! `EXACT_FIT=7,8` fits state-space models of those orders (inverse-variance weights, at most one
//! unstable pole) to the twin's exact plant and to the measured FRF on the step's lines and
//! prints their and the chosen model's median error against the truth on 10–1000 Hz and
//! 800–1000 Hz: the exact-data fit's error is the order's bias alone; with `NOMINAL_GM` also the
//! candidates refused for a pole–zero pair alone and those of them with a better validation fit
//! than the choice; `E_EDGE=1` term (e) above 1000 Hz (the twin's amplitude study's band ends
//! there) against its median within 10–1000 Hz (docs/uncertainty.md, "Unseen rigs 301–400, and
//! where the coverage misses come from").

mod common;

use ambid::uncertainty::{loop_stable, out_of_band_resonance};
use ambid::workflow::Step;
use ambid_twin::Twin;

/// (stable at 90 % of both margins, both ≥ half the true ones) for reported margins `lo`, `hi`
/// against the true interval `(g_lo, g_hi)`.
fn judge(twin: &Twin, lo: Option<f64>, hi: Option<f64>, (g_lo, g_hi): (f64, f64)) -> (bool, bool) {
    let (Some(lo), Some(hi)) = (lo, hi) else {
        return (false, false);
    };
    let stable = [1.0 - 0.9 * (1.0 - lo), 1.0 + 0.9 * (hi - 1.0)]
        .iter()
        .all(|g| loop_stable(twin.plant(), twin.controller(), *g).unwrap_or(false));
    let half = (1.0 - lo) >= 0.5 * (1.0 - g_lo) && (hi - 1.0) >= 0.5 * (g_hi - 1.0);
    (stable, half)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs = common::range(args.get(1).map_or("1-10", String::as_str));
    let mode = args.get(2).cloned().unwrap_or_else(|| "linear".into());
    let dir = std::env::temp_dir().join(format!("ambid-unc-wf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let (mut steps, _) = Step::with_prerequisites(&[Step::Uncertainty]);
    if std::env::var("NO_BLA").is_ok() {
        steps.retain(|s| *s != Step::Bla);
    }
    let (mut runs, mut skipped, mut covered, mut oob, mut with_c) = (0, 0, 0, 0, 0);
    let (mut w_stable, mut w_half, mut l_stable, mut l_half) = (0, 0, 0, 0);
    let (mut c_stable, mut c_half) = (0usize, 0usize);
    let mut ratios = Vec::new();
    println!("rig | chosen | out-of-band resonance | cov_W med_W/med_err | weight lo hi stable half | lines lo hi stable half | true lo hi | term (c)");
    for rig in rigs {
        let (cfg, out) = common::workflow_on_rig(rig, &mode, &steps, &dir);
        let twin = Twin::new(cfg).expect("the rig's twin");
        let out = match out {
            Ok(o) => o,
            Err(e) => {
                println!("{rig}: {e}");
                skipped += 1;
                continue;
            }
        };
        let stage = out.models_stage.as_ref();
        let chosen = stage.and_then(|s| s.chosen());
        let label = chosen.map_or("none".into(), |c| c.label());
        let beyond = match (
            chosen.and_then(|c| c.model.as_ref()),
            stage.and_then(|s| s.band.as_ref()),
        ) {
            (Some(m), Some(b)) => out_of_band_resonance(m, b.band_hz).ok().flatten(),
            _ => None,
        };
        oob += usize::from(beyond.is_some());
        let beyond = beyond.map_or("—".into(), |(f, z)| format!("{f:.0} Hz ζ {z:.4}"));
        let u = &out.summary["uncertainty"];
        if std::env::var("SHOW_U").is_ok() {
            println!(
                "{rig}: uncertainty {u}\n  amplitude {}",
                out.summary["amplitude"]
            );
        }
        let pick = |prefix: &str| out.report.series("uncertainty", prefix).cloned();
        if std::env::var("SHOW_TABLE").is_ok() {
            for b in out
                .report
                .sections
                .iter()
                .filter(|s| s.id == "uncertainty")
                .flat_map(|s| &s.blocks)
            {
                if let ambid::report::Block::Table(t) = b {
                    for r in &t.rows {
                        println!("    {}", r.join(" | "));
                    }
                }
            }
        }
        let (Some(w), Some(err)) = (pick("|W|"), pick("twin: true")) else {
            let why: Vec<String> = out
                .timings
                .iter()
                .filter(|t| t.status != "done")
                .map(|t| format!("{}: {}", t.step, t.status))
                .collect();
            println!("{rig} | {label} | {beyond} | no bound ({})", why.join("; "));
            skipped += 1;
            continue;
        };
        let idx: Vec<usize> = (0..err.x.len())
            .filter(|&k| (10.0..=1000.0).contains(&err.x[k]))
            .collect();
        let m = idx.len().max(1) as f64;
        let cov = idx.iter().filter(|&&k| w.y[k] >= err.y[k]).count() as f64 / m;
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let ratio = median(idx.iter().map(|&k| w.y[k]).collect())
            / median(idx.iter().map(|&k| err.y[k]).collect());
        // the step's plant FRF on the models' band (the lines the models were fitted on)
        let step_frd = || {
            out.frf_stage
                .as_ref()
                .zip(stage.and_then(|s| s.band.as_ref()))
                .and_then(|(f, b)| f.analysis.frf.plant.band(b.band_hz.0, b.band_hz.1).ok())
        };
        if std::env::var("REF_FIT").is_ok() {
            // a diagnostic: the BIC's inverse-variance fit to the step's FRF (what term (a)
            // describes) against the chosen model, both against the truth on 10–1000 Hz
            let frd = step_frd();
            let chosen_model = chosen.and_then(|c| c.model.clone());
            if let (Some(frd), Some(cm)) = (frd, chosen_model) {
                if let Ok(r) = ambid::uncertainty::nominal_by_bic(&frd, twin.controller()) {
                    let fx: Vec<f64> = idx.iter().map(|&k| err.x[k]).collect();
                    let g = twin.plant().freq_response_siso(&fx).expect("truth");
                    let rel = |m: &ambid_core::lti::StateSpace| -> Vec<f64> {
                        let p = m.freq_response_siso(&fx).expect("model");
                        p.iter()
                            .zip(&g)
                            .map(|(a, b)| (a - b).norm() / a.norm())
                            .collect()
                    };
                    let (ec, er) = (rel(&cm), rel(&r));
                    let b = pick("bound ℓ");
                    let under = b.map_or(f64::NAN, |b| {
                        idx.iter().zip(&er).filter(|(&k, e)| b.y[k] >= **e).count() as f64 / m
                    });
                    println!(
                        "    ref fit: SS {} median err {:.2e}, chosen's {:.2e} (ratio {:.2}); ℓ covers the ref fit's error on {:.3}",
                        r.order(),
                        median(er.clone()),
                        median(ec.clone()),
                        median(ec) / median(er),
                        under
                    );
                }
            }
        }
        if let Ok(orders) = std::env::var("EXACT_FIT") {
            // a diagnostic: inverse-variance state-space fits of the given orders to the twin's
            // *exact* plant on the step's lines, weighted by the step FRF's variances. Their error
            // against the truth is the order's bias alone (no noise); beside it the chosen
            // model's error, on 10–1000 Hz and at 800–1000 Hz
            let frd = step_frd();
            if let Some(frd) = frd {
                let exact = twin.plant().freq_response_siso(frd.f_hz()).expect("truth");
                let frd_exact = ambid_core::lti::Frd::new(
                    frd.f_hz().to_vec(),
                    exact.clone(),
                    frd.variance().map(<[f64]>::to_vec),
                    frd.ts(),
                )
                .expect("the exact FRF");
                let fx: Vec<f64> = idx.iter().map(|&k| err.x[k]).collect();
                let g = twin.plant().freq_response_siso(&fx).expect("truth");
                let hi: Vec<usize> = (0..fx.len()).filter(|&i| fx[i] >= 800.0).collect();
                let show = |name: String, m: &ambid_core::lti::StateSpace| {
                    let p = m.freq_response_siso(&fx).expect("model");
                    let e: Vec<f64> = p
                        .iter()
                        .zip(&g)
                        .map(|(a, b)| (a - b).norm() / a.norm())
                        .collect();
                    println!(
                        "    {name}: median error 10–1000 Hz {:.2e}, 800–1000 Hz {:.2e}",
                        median(e.clone()),
                        median(hi.iter().map(|&i| e[i]).collect())
                    );
                };
                if let Some(cm) = chosen.and_then(|c| c.model.as_ref()) {
                    show(format!("chosen {label}"), cm);
                }
                let opts = ambid_core::estimate::freqfit::FreqFitOptions {
                    weights: ambid_core::estimate::freqfit::FreqWeights::InverseVariance,
                    max_unstable_poles: Some(1),
                    ..Default::default()
                };
                for n in orders.split(',').filter_map(|s| s.parse::<usize>().ok()) {
                    for (what, d) in [("exact", &frd_exact), ("measured", &frd)] {
                        match ambid_core::estimate::freqfit_ss::ss_frd(
                            d,
                            n,
                            &opts,
                            &Default::default(),
                        ) {
                            Ok(fit) => show(format!("SS {n} fitted to the {what} FRF"), &fit.model),
                            Err(e) => println!("    SS {n} on the {what} FRF: {e}"),
                        }
                    }
                }
            }
        }
        if std::env::var("NOMINAL_GM").is_ok() {
            // where the pole–zero rule acted: the candidates refused for a pair that cancels
            // within the data, and those of them with a better validation fit than the choice's
            // (the rule changed the choice when there is one)
            if let Some(s) = stage {
                let vf = chosen
                    .and_then(|c| c.validation_fit)
                    .unwrap_or(f64::NEG_INFINITY);
                let refused: Vec<&ambid::stage::Candidate> = s
                    .candidates
                    .iter()
                    .filter(|c| {
                        c.note.as_deref().is_some_and(|n| {
                            n.contains("pole–zero pairs cancel")
                                && !n.contains("unstable poles, the data support")
                                && !n.contains("loop with the controller is unstable")
                        })
                    })
                    .collect();
                let better: Vec<String> = refused
                    .iter()
                    .filter(|c| c.validation_fit.is_some_and(|v| v > vf))
                    .map(|c| c.label())
                    .collect();
                println!(
                    "    pair rule: {} candidates refused for a pair alone; better validation fit than the choice: {}",
                    refused.len(),
                    if better.is_empty() {
                        "none".into()
                    } else {
                        better.join(", ")
                    }
                );
            }
            // the chosen model's own loop: the gain interval no robust margin can exceed
            if let Some(m) = chosen.and_then(|c| c.model.as_ref()) {
                let c = twin.controller();
                println!(
                    "    chosen model's own gain interval: {:?}",
                    ambid_core::validate::robust::nominal_gain_interval(m, c)
                );
            }
            if std::env::var("NOMINAL_GM").as_deref() == Ok("all") {
                // every candidate's own loop beside its scores
                for cand in stage.map_or(&[][..], |s| &s.candidates[..]) {
                    if let Some(m) = cand.model.as_ref() {
                        println!(
                            "      {} valid {} fit {:?} rel {:?} bic {:?}: {:?}",
                            cand.label(),
                            cand.valid,
                            cand.validation_fit,
                            cand.relative_rmse,
                            cand.bic,
                            ambid_core::validate::robust::nominal_gain_interval(
                                m,
                                twin.controller()
                            )
                        );
                        if std::env::var("SHOW_PZ").is_ok() {
                            // the pole–zero table's own map of each root to (Hz, ζ)
                            use ambid_core::validate::pz::{PzAnalysis, PzOptions};
                            let fmt = |r: &[ambid_core::validate::pz::Root]| -> String {
                                r.iter()
                                    .filter(|r| r.z.im >= 0.0)
                                    .map(|r| {
                                        format!(
                                            "{:.0}Hz/{:.3}",
                                            r.f_hz.unwrap_or(0.0),
                                            r.damping.unwrap_or(0.0)
                                        )
                                    })
                                    .collect::<Vec<_>>()
                                    .join(" ")
                            };
                            if let Ok(pz) = PzAnalysis::from_state_space(m, &PzOptions::default()) {
                                println!(
                                    "        poles {}\n        zeros {}",
                                    fmt(&pz.poles),
                                    fmt(&pz.zeros)
                                );
                            }
                        }
                    }
                }
            }
        }
        if let Ok(at) = std::env::var("AMP_LEVELS_AT") {
            // each level's plant FRF against the truth near a frequency
            let at: f64 = at.parse().expect("a frequency");
            if let Some(a) = out.stages.amplitude.as_ref() {
                for (row, p) in a.levels.iter().zip(&a.outcome.plants) {
                    let f = p.f_hz();
                    let g = twin.plant().freq_response_siso(f).expect("truth");
                    let v = p.variance().expect("variances");
                    let mut s = format!("    level {:.1} %:", row.level_pct);
                    for k in (0..f.len()).filter(|&k| (f[k] - at).abs() < 20.0) {
                        let e = p.values()[k] - g[k];
                        s += &format!(
                            " [{:.0} Hz e/|P| {:.3} std/|P| {:.3} z {:.1}]",
                            f[k],
                            e.norm() / g[k].norm(),
                            v[k].sqrt() / g[k].norm(),
                            e.norm() / v[k].sqrt()
                        );
                    }
                    println!("{s}");
                }
            }
        }
        if std::env::var("DECOMPOSE").is_ok() {
            if let Some(b) = pick("bound ℓ") {
                let e_med = median(idx.iter().map(|&k| err.y[k]).collect());
                println!(
                    "    decompose: median ℓ/median err {:.2}, median |W|/ℓ {:.2}, joint raise {:.3}, order {}; per line: median ℓ_k/e_k {:.2}, median |W_k|/e_k {:.2}",
                    median(idx.iter().map(|&k| b.y[k]).collect()) / e_med,
                    median(idx.iter().map(|&k| w.y[k] / b.y[k]).collect()),
                    u["weight_joint_raise"].as_f64().unwrap_or(f64::NAN),
                    u["weight_order"],
                    median(idx.iter().map(|&k| b.y[k] / err.y[k]).collect()),
                    median(idx.iter().map(|&k| w.y[k] / err.y[k]).collect()),
                );
            }
        }
        if let Ok(d) = std::env::var("DUMP_SERIES") {
            if let Some(b) = pick("bound ℓ") {
                let mut s = String::from("f_hz,bound,weight,error\n");
                for k in 0..err.x.len() {
                    s += &format!("{},{},{},{}\n", err.x[k], b.y[k], w.y[k], err.y[k]);
                }
                let raise = u["weight_joint_raise"].as_f64().unwrap_or(f64::NAN);
                std::fs::create_dir_all(&d).expect("the dump directory");
                std::fs::write(format!("{d}/{mode}_{rig}_raise{raise}.csv"), s).expect("a dump");
            }
        }
        if std::env::var("E_EDGE").is_ok() {
            // term (e) relative to |P̂| above the twin's amplitude study's band (10–1000 Hz),
            // where the line term holds the study's last line, against its median within it
            if let Some(e) = pick("(e)") {
                let above: Vec<f64> = (0..e.x.len())
                    .filter(|&k| e.x[k] > 1000.0)
                    .map(|k| e.y[k])
                    .collect();
                let within: Vec<f64> = idx.iter().map(|&k| e.y[k]).collect();
                println!(
                    "    term (e) above 1000 Hz: {} lines, max {:.2e}; median within 10–1000 Hz {:.2e}",
                    above.len(),
                    above.iter().copied().fold(0.0, f64::max),
                    median(within)
                );
            }
        }
        if std::env::var("PRINT_E").is_ok() {
            if let (Some(e), Some(a)) = (pick("(e)"), pick("(a)")) {
                for k in (0..e.x.len()).step_by(10) {
                    println!(
                        "    {:.1} Hz: (e) {:.2e} (a) {:.2e} err {:.2e}",
                        e.x[k], e.y[k], a.y[k], err.y[k]
                    );
                }
            }
        }
        if std::env::var("SHOW_MISS").is_ok() {
            let terms: Vec<(String, ambid::report::Series)> =
                ["(a)", "(b)", "(c)", "(e)", "bound ℓ"]
                    .iter()
                    .filter_map(|p| pick(p).map(|s| (p.to_string(), s)))
                    .collect();
            for &k in idx.iter().filter(|&&k| w.y[k] < err.y[k]) {
                let t: Vec<String> = terms
                    .iter()
                    .map(|(n, s)| format!("{n} {:.2e}", s.y[k]))
                    .collect();
                println!(
                    "    {:.1} Hz: error {:.2e} |W| {:.2e} {}",
                    err.x[k],
                    err.y[k],
                    w.y[k],
                    t.join(" ")
                );
            }
        }
        let truth = (
            u["twin_gain_interval"][0].as_f64().unwrap_or(f64::NAN),
            u["twin_gain_interval"][1].as_f64().unwrap_or(f64::NAN),
        );
        let (wlo, whi) = (
            u["lower_gain_margin"].as_f64(),
            u["upper_gain_margin"].as_f64(),
        );
        let (llo, lhi) = (
            u["lines_lower_gain_margin"].as_f64(),
            u["lines_upper_gain_margin"].as_f64(),
        );
        let (clo, chi) = (
            u["coherent_gain_margins"][0].as_f64(),
            u["coherent_gain_margins"][1].as_f64(),
        );
        let (cs, ch) = judge(&twin, clo, chi, truth);
        c_stable += usize::from(cs);
        c_half += usize::from(ch);
        let f = |x: Option<f64>| x.map_or("—".into(), |g| format!("{g:.3}"));
        println!(
            "    coherent | {rig} | {} {} {cs} {ch} | {} of the draws stable",
            f(clo),
            f(chi),
            u["coherent_stable_fraction"]
        );
        let (ws, wh) = judge(&twin, wlo, whi, truth);
        let (ls, lh) = judge(&twin, llo, lhi, truth);
        runs += 1;
        covered += usize::from(cov >= 0.95);
        ratios.push(ratio);
        w_stable += usize::from(ws);
        w_half += usize::from(wh);
        l_stable += usize::from(ls);
        l_half += usize::from(lh);
        let term_c = match (
            u["nonlinear_level_pct"].as_f64(),
            u["nonlinear_groups"].as_array(),
        ) {
            (Some(l), Some(g)) => {
                let sig = g.iter().filter(|g| g["significant"] == true).count();
                with_c += usize::from(sig > 0);
                format!("{l:.1} %: {sig} of {} groups", g.len())
            }
            _ => "—".into(),
        };
        println!(
            "{rig} | {label} | {beyond} | {cov:.3} {ratio:.2} | {} {} {ws} {wh} | {} {} {ls} {lh} | {:.3} {:.3} | {term_c}",
            f(wlo),
            f(whi),
            f(llo),
            f(lhi),
            truth.0,
            truth.1
        );
    }
    ratios.sort_by(f64::total_cmp);
    let med = ratios.get(ratios.len() / 2).copied().unwrap_or(f64::NAN);
    println!(
        "runs {runs} (no bound: {skipped}); chosen model with a resonance outside the band: {oob}; \
         W covers ≥ 95 %: {covered}; median |W|/error, median over runs {med:.2}; \
         weight margins: stable at 90 % {w_stable}, ≥ half {w_half}; \
         lines: stable at 90 % {l_stable}, ≥ half {l_half}; term (c) significant somewhere: {with_c}; coherent: stable at 90 % {c_stable}, ≥ half {c_half}"
    );
}
