//! Diagnostic sweep of the MIMO uncertainty bound (issue 23, MIMO entries) on the 4-axis twin:
//! per rig (0 = the nominal twin at 15 000 rpm, k > 0 = `random_rig(k)` at `(7919 k) mod 30 000`
//! rpm), default noise, the `[machine]` defaults and the default fitter's chosen model (as `ambid
//! run` with a `[machine]` section), the element-wise bound of
//! `ambid_core::validate::uncertainty::uncertainty_matrix` on the plant FRF's lines of the fit's
//! band (`machine_fit::fit_band`: its precise lines in the quality band) and the validation
//! lines above it (`machine_fit::uncertainty_band`, as the workflow's; `UNC_BAND=fit`: the fit
//! band alone, the rule before 2026-12-05), judged against the twin's exact plant on 10–1000 Hz:
//!
//! * `cov_e`: the fraction of (line, entry) pairs with $|P_{ij} - \hat P_{ij}| \le L_{ij}$;
//! * `cov_n`: the fraction of lines with $\bar\sigma(P - \hat P) \le \lVert L\rVert_2$;
//! * `cov_w`: the fraction of lines with $\bar\sigma(P - \hat P) \le \lVert\,|\hat P|\circ|W|\,\rVert_2$,
//!   the structured weight (`MatrixUncertainty::entry_weights`: one relative weight of order
//!   ≤ 4 per entry over its raised bound), and `loose_w` its looseness as `loose` below;
//! * `loose`: median $\lVert L\rVert_2$ / median $\bar\sigma(P - \hat P)$;
//! * robust gain margins (all four controllers' gains together) on the lines (element-wise) and
//!   against the weight, each with the bars: the exact loop stable at 90 % of the margin, and the
//!   margin at least half the exact one (`nominal_gain_interval` of the exact plant);
//! * the coherent margins (`robust_stability_matrix_drawn`, `COHERENT_DRAWS` draws, default
//!   200, at `CONF`, default 0.95) with the same bars, capped outside the lines by the entry
//!   weights (`OUTSIDE=0`: not); where the cap is set above, the true relative error of the
//!   diagonal entries against their weights there.
//!
//! `MODE=nonlinear` simulates the nonlinear twin (the exact plant is then the linearisation).
//! `SEED_PER_RIG=1` gives each rig its own noise realisation (base seed rig + 1000); without it
//! every rig's experiments use the seeds derived from 1, i.e. the same noise sequences.
//! `DUMP_ENTRIES=dir` writes `dir/rig<k>.txt`: per line the frequency, then for each entry
//! (column-major) its relative bound $L_{ij}/|\hat P_{ij}|$, its weight's magnitude and the true
//! relative error $|P_{ij} - \hat P_{ij}|/|\hat P_{ij}|$.
//!
//! `LEVELS=none` runs no amplitude study (else the `[machine]` default with `uncertainty = true`:
//! the design repeated at 5 and 16 % of i_sat, whose plant FRFs with the identification FRF give
//! every entry's term (e), `machine_fit::amplitude_terms`); `LEVELS=5,20` other levels.
//!
//! Term (e) is also projected through the model as the workflow does
//! (`MatrixUncertainty::add_projected_shift`); `NO_PROJECT=1` leaves that out. `DEBUG_E=1`
//! prints the line terms' medians and the projection's Wald statistic; `DEBUG_AMP=1` the
//! coherent relative shift κ of each level's FRF (and of the model) against the exact plant on
//! the diagonal entries per band. `COVER_RAISE` / `COVER_W` set the joint raise's and the
//! weight fit's `cover` (default 0.98); `COVER_RAISE` may list several values (`0.98,0.95`):
//! the same rig's data then give one row per value (the rig number tagged `@value`) and one
//! summary per value. The entry weights are fitted to the bound raised for `COVER_RAISE_W`
//! of the pairs on the same draws (default `DEFAULT_RAISE_COVER`, 0.95, as the workflow's
//! `speed_uncertainty`; `COVER_RAISE_W=same`: each `COVER_RAISE` value, the build before
//! "Two raises for the machine" in docs/uncertainty.md). `NO_RAISE=1` skips the raise.
//! `DUMP_MU=DIR` writes per rig (and raise) `DIR/rig<N>.json`: the lines' model, controller and
//! exact plant, the bound on the lines and the weights' on the lines, the exact interval and
//! the robust margins, for `scripts/mimo_margin_oracle.py`. `FRF_ERR=1` prints, per
//! line in 150–350 Hz, the measured FRF's complex error against the exact plant and its
//! standard deviation for the entries (xa, ya) and (xa, xa) (`FRFERR f re im std re im std`).
//!
//! The coherent draws' diagnostics: `REMAINDER=0` leaves the element-wise remainder out,
//! `REMAINDER=old` adds the per-line amplitude term back beside a kept projection (the double
//! count before the tenth session of 2026-12-05), `REMAINDER=freeb` puts term (b) back at a free
//! phase (before the eleventh), `REMAINDER=b|e` keeps term (b)'s spread alone or the rest alone;
//! `DEBUG_REM=1` prints per entry term (b) and the rest relative to $|\hat P|$; `DEBUG_SHIFT=1`
//! compares the draws' mean and the amplitude shift with the exact error (`debug_shift`).
//! `DEBUG_BEYOND=1` prints, every fourth line from 0.9× to 1.5× the fit band's end, the lines'
//! relative standard deviation (all entries together, and per diagonal entry) and the model's
//! misfit against the FRF averaged over ±4 lines beside its true error, relative to $|\hat P|$
//! (docs/uncertainty.md, "Lines beyond the fit band").
//!
//! Run: `cargo run --release -p ambid --example uncertainty_machine_rigs -- 0,1,2,3`.
use ambid::config::MachineSection;
use ambid::workflow::machine::{acquire_twin, MachineModelInput, MachineModels};
use ambid::workflow::machine_fit::{
    amplitude_terms, amplitude_terms_and_shifts, fit_band, uncertainty_band, AmplitudeStudy,
    FrequencyFitter,
};
use ambid_core::lti::Frd;
use ambid_core::validate::iso::IsoZones;
use ambid_core::validate::robust::{
    loop_stable, nominal_gain_interval, robust_stability_matrix_drawn,
    robust_stability_matrix_on_lines, robust_stability_matrix_weight, LineBound, MatrixWeight,
    RobustStability,
};
use ambid_core::validate::uncertainty::{
    uncertainty_matrix, CoherentDraws, EntryForm, ExtraTerms, MatrixUncertainty, UncertaintyOptions,
};
use ambid_core::validate::weight::{Weight, DEFAULT_COVER};
use faer::Mat;
use std::path::Path;
use std::time::Instant;

fn sigma_max(m: &Mat<f64>) -> f64 {
    ambid_core::linalg::singular_values(m.as_ref())
        .map(|s| s.into_iter().fold(0.0, f64::max))
        .unwrap_or(f64::NAN)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The two bars on one robust-stability result: (stable at 90 % of both margins, both margins
/// at least half the exact ones); `None` when no margin was reported.
fn bars(
    r: &RobustStability,
    truth: &ambid_core::lti::StateSpace,
    c: &ambid_core::lti::StateSpace,
    exact: (f64, f64),
) -> Option<(bool, bool)> {
    bars_of(r.lower_gain_margin?, r.upper_gain_margin?, truth, c, exact)
}

fn bars_of(
    lo: f64,
    hi: f64,
    truth: &ambid_core::lti::StateSpace,
    c: &ambid_core::lti::StateSpace,
    exact: (f64, f64),
) -> Option<(bool, bool)> {
    let up = if hi.is_finite() {
        1.0 + 0.9 * (hi - 1.0)
    } else {
        1e3
    };
    let stable = [up, 1.0 - 0.9 * (1.0 - lo)]
        .iter()
        .all(|g| loop_stable(truth, c, *g).unwrap_or(false));
    let half = (hi - 1.0) >= 0.5 * (exact.1 - 1.0) && (1.0 - lo) >= 0.5 * (1.0 - exact.0);
    Some((stable, half))
}

/// One rig's figures: coverages, looseness and the two sets of bars.
type Row = (
    f64,
    f64,
    f64,
    f64,
    Option<(bool, bool)>,
    Option<(bool, bool)>,
    f64,
    Option<(bool, bool)>,
);

/// `DEBUG_SHIFT=1`: the exact error $E = P_0 - \hat P$ on the lines regressed on the coherent
/// draws' mean $\bar D$, diagonal and cross entries apart (weights $1/(|\hat P_{ii}||\hat
/// P_{jj}|)$: a cross entry's own $|\hat P_{ij}|$ has zeros that would take a relative weighting
/// over), as the coefficient $\sum \operatorname{Re}(E\bar D^*)/\sum|\bar D|^2$ and the share
/// of $\sum|E|^2$ it explains; per band, $\bar D$ and the per-line shift estimates $s$ as
/// relative shifts κ on the diagonal; and $G - P_0$ and $\hat P - P_0$ regressed on $s$
/// (weights $1/|\hat P_{ij}|^2$); on the six top lines, per diagonal entry, $|E|$, $|E - \bar
/// D|$, $|E - \bar D + c|$ (the mean without term (b)'s centre $c$) and the remainder, each
/// relative to $|\hat P|$ (what sets the error just beyond the lines).
fn debug_shift(u: &MatrixUncertainty, cd: &CoherentDraws, exact: &Frd, shifts: &[Vec<faer::c64>]) {
    let lines = cd.f_hz.len();
    let n = cd.draws.len() as f64;
    let p0: Vec<Mat<faer::c64>> = (0..lines).map(|k| exact.at(k).expect("line")).collect();
    let mean: Vec<Mat<faer::c64>> = (0..lines)
        .map(|k| {
            Mat::from_fn(4, 4, |i, j| {
                cd.draws.iter().map(|d| d[k][(i, j)]).sum::<faer::c64>() / n
            })
        })
        .collect();
    let nominal = |i: usize, j: usize, k: usize| u.entries[i + 4 * j].nominal[k];
    for (name, diag) in [("diagonal", true), ("cross", false)] {
        let (mut ed, mut dd, mut ee) = (0.0, 0.0, 0.0);
        for (i, j) in (0..16)
            .map(|e| (e % 4, e / 4))
            .filter(|(i, j)| (i == j) == diag)
        {
            for k in 0..lines {
                let w = 1.0
                    / (nominal(i, i, k).norm() * nominal(j, j, k).norm()).max(f64::MIN_POSITIVE);
                let (err, m) = (p0[k][(i, j)] - nominal(i, j, k), mean[k][(i, j)]);
                ed += w * (err * m.conj()).re;
                dd += w * m.norm_sqr();
                ee += w * err.norm_sqr();
            }
        }
        println!(
            "    shift ({name}): E on D̄ coefficient {:.3}, explains {:.3}",
            ed / dd,
            ed * ed / dd / ee
        );
    }
    // the top lines: per diagonal entry, the exact error, what the draws' mean leaves of it,
    // what it leaves without term (b)'s centre, and the remainder, each relative to |P̂|
    for k in lines.saturating_sub(6)..lines {
        let row: Vec<String> = (0..4)
            .map(|d| {
                let p = nominal(d, d, k).norm();
                let err = p0[k][(d, d)] - nominal(d, d, k);
                let left = err - mean[k][(d, d)];
                format!(
                    "{:.3}/{:.3}/{:.3}/{:.3}",
                    err.norm() / p,
                    left.norm() / p,
                    (left + cd.bias_centre[k][(d, d)]).norm() / p,
                    cd.remainder[k][(d, d)] / p
                )
            })
            .collect();
        println!(
            "    top line {:.1} Hz: |E| / |E − D̄| / |E − D̄ + c| / R {}",
            cd.f_hz[k],
            row.join(" | ")
        );
    }
    for (lo, hi) in [(10.0, 100.0), (100.0, 300.0), (300.0, 1000.0)] {
        let row: Vec<String> = (0..4)
            .map(|d| {
                let (mut a, mut b, mut den) =
                    (faer::c64::new(0.0, 0.0), faer::c64::new(0.0, 0.0), 0.0);
                for k in (0..lines).filter(|&k| (lo..hi).contains(&cd.f_hz[k])) {
                    let p = nominal(d, d, k);
                    a += p.conj() * mean[k][(d, d)];
                    if let Some(s) = shifts.get(d * 5) {
                        b += p.conj() * s[k];
                    }
                    den += p.norm_sqr();
                }
                format!("D̄ {:+.4} ŝ {:+.4}", (a / den).re, (b / den).re)
            })
            .collect();
        println!("    band {lo}-{hi}: κ {}", row.join(" | "));
    }
    if !shifts.is_empty() {
        let (mut gs, mut ps, mut ss) = (0.0, 0.0, 0.0);
        for ((e, t), se) in u.entries.iter().enumerate().zip(shifts) {
            for (k, &sk) in se.iter().enumerate() {
                let w = 1.0 / t.nominal[k].norm_sqr().max(f64::MIN_POSITIVE);
                let p = p0[k][(e % 4, e / 4)];
                gs += w * ((t.measured[k] - p) * sk.conj()).re;
                ps += w * ((t.nominal[k] - p) * sk.conj()).re;
                ss += w * sk.norm_sqr();
            }
        }
        println!(
            "    shift: G − P0 on s coefficient {:.3}; P̂ − P0 on s coefficient {:.3}",
            gs / ss,
            ps / ss
        );
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs: Vec<u64> = args
        .get(1)
        .map_or("0", String::as_str)
        .split(',')
        .filter_map(|x| x.parse().ok())
        .collect();
    let mode = std::env::var("MODE").unwrap_or_else(|_| "linear".into());
    let dir = std::env::temp_dir().join(format!("ambid-unc-machine-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp dir");
    let covers: Vec<f64> = std::env::var("COVER_RAISE").map_or_else(
        |_| vec![DEFAULT_COVER],
        |v| {
            v.split(',')
                .map(|x| {
                    x.trim()
                        .parse()
                        .unwrap_or_else(|_| panic!("COVER_RAISE: {x:?} is not a number"))
                })
                .collect()
        },
    );
    // the weights' raise: a fraction, or `same` (each line raise's)
    let cover_w_raise: Option<f64> = match std::env::var("COVER_RAISE_W") {
        Err(_) => Some(ambid_core::validate::uncertainty::DEFAULT_RAISE_COVER),
        Ok(v) if v == "same" => None,
        Ok(v) => Some(
            v.trim()
                .parse()
                .unwrap_or_else(|_| panic!("COVER_RAISE_W: {v:?} is neither a number nor same")),
        ),
    };
    let mut summaries: Vec<Vec<Row>> = vec![Vec::new(); covers.len()];
    println!("rig rpm | lines | cov_e cov_n cov_w | loose_n loose_w | lines: g- g+ (exact g- g+) stable half | entry weights: max order g- g+ stable half | s");
    for rig in rigs {
        let t0 = Instant::now();
        let m = if rig == 0 {
            MachineSection {
                speeds_rpm: Some(vec![15_000.0]),
                mode: mode.clone(),
                ..Default::default()
            }
        } else {
            let path = dir.join(format!("rig{rig}.toml"));
            std::fs::write(
                &path,
                ambid_twin::random_rig(rig)
                    .expect("rig")
                    .to_toml_string()
                    .expect("toml"),
            )
            .expect("write rig");
            MachineSection {
                speeds_rpm: Some(vec![((rig * 7919) % 30_000) as f64]),
                mode: mode.clone(),
                config: Some(path),
                ..Default::default()
            }
        };
        let m = MachineSection {
            models: "fit".into(),
            uncertainty: true,
            amplitude_levels_pct: match std::env::var("LEVELS").ok().as_deref() {
                None => None,
                Some("none") => Some(Vec::new()),
                Some(v) => Some(v.split(',').filter_map(|x| x.parse().ok()).collect()),
            },
            ..m
        };
        // SEED_PER_RIG=1: each rig its own noise realisation (the experiments' seeds derive
        // from rig + 1000 instead of 1 for every rig)
        let noise_seed = if std::env::var("SEED_PER_RIG").is_ok() {
            rig + 1000
        } else {
            1
        };
        let data = acquire_twin(&m, Path::new("."), noise_seed).expect("twin");
        let truth = data.truth.as_ref().expect("truth");
        let input = MachineModelInput {
            speeds: &data.speeds,
            controller: Some(&truth[0].controller),
            truth: Some(truth),
            twin: data.twin.as_ref().zip(data.mode),
            noise: true,
            ts: data.ts,
            quality_band_hz: m.quality_band_hz,
            zones: IsoZones::default(),
            seed: 1,
        };
        let out = FrequencyFitter::default().identify(&input).expect("fit");
        let Some(model) = out.models.first() else {
            println!("rig {rig}: no model ({:?})", out.notes);
            continue;
        };
        // the lines the fit used: the plant FRF's precise lines in the quality band
        let measured = &data.speeds[0].frf.plant;
        let Some(band) = fit_band(measured, m.quality_band_hz).expect("band") else {
            println!("rig {rig}: no band");
            continue;
        };
        // the bound's lines: the fit band and the validation lines above it, as the workflow's
        // (UNC_BAND=fit: the fit band alone, the rule before 2026-12-05)
        let unc_end = if std::env::var("UNC_BAND").as_deref() == Ok("fit") {
            band.1
        } else {
            uncertainty_band(measured, band).expect("band").1
        };
        let plant = &measured.band(band.0, unc_end).expect("band");
        let unc_opts = UncertaintyOptions {
            fitted_band_hz: (unc_end > band.1).then_some([band.0, band.1]),
            ..UncertaintyOptions::default()
        };
        if std::env::var("DEBUG_1X").is_ok() {
            // the FRF's error against the exact plant in units of its standard deviation,
            // largest over the entries, at the lines nearest the 1× frequency and the median
            let f1 = truth[0].speed_rpm / 60.0;
            let fl = plant.f_hz().to_vec();
            let ex = Frd::from_model(&truth[0].plant, &fl).expect("exact");
            let z: Vec<f64> = (0..fl.len())
                .map(|k| {
                    let mut worst = 0.0f64;
                    for i in 0..4 {
                        for j in 0..4 {
                            let e = plant.entry(i, j).expect("entry");
                            let v = e.variance().expect("variance")[k];
                            let d = e.values()[k] - ex.at(k).expect("line")[(i, j)];
                            worst = worst.max(d.norm_sqr() / v);
                        }
                    }
                    worst
                })
                .collect();
            let spacing = fl[1] - fl[0];
            let near: Vec<String> = (0..fl.len())
                .filter(|&k| (fl[k] - f1).abs() < 2.5 * spacing)
                .map(|k| {
                    format!(
                        "{:.2} Hz (δ {:+.3}): {:.1}",
                        fl[k],
                        (f1 - fl[k]) / spacing,
                        z[k]
                    )
                })
                .collect();
            println!(
                "  1× {f1:.3} Hz; max over entries of |G − P|²/σ² near it: {}; median over the lines {:.2}",
                near.join(", "),
                median(z.clone())
            );
            for z in model.model.poles().expect("poles") {
                let sp = z.ln() / data.ts;
                let fz = sp.im / (2.0 * std::f64::consts::PI);
                if (fz - f1).abs() < 5.0 {
                    println!("    model pole {fz:.2} Hz ζ {:.2e}", -sp.re / sp.norm());
                }
            }
        }
        if std::env::var("DEBUG_BEYOND").is_ok() {
            // the measured FRF beyond the fit band: per diagonal entry, relative std, the
            // windowed (±4 lines) misfit to the model and the true error, both relative to |P̂|
            let fl: Vec<f64> = measured
                .f_hz()
                .iter()
                .copied()
                .filter(|f| *f > band.1 * 0.9 && *f < band.1 * 1.5)
                .collect();
            let g = measured.band(fl[0], fl[fl.len() - 1]).expect("band");
            let ex = Frd::from_model(&truth[0].plant, &fl).expect("exact");
            let mh = Frd::from_model(&model.model, &fl).expect("model");
            for k in (0..fl.len()).step_by(4) {
                let e = 16;
                let vs: f64 = g.variance().expect("v")[k * e..(k + 1) * e].iter().sum();
                let gs: f64 = g.values()[k * e..(k + 1) * e]
                    .iter()
                    .map(|x| x.norm_sqr())
                    .sum();
                print!("  summed rel std {:.3}", (vs / gs).sqrt());
                let row: Vec<String> = (0..4)
                    .map(|d| {
                        let e = g.entry(d, d).expect("entry");
                        let v = e.variance().expect("variance");
                        let ph = mh.at(k).expect("l")[(d, d)];
                        let lo = k.saturating_sub(4);
                        let hi = (k + 5).min(fl.len());
                        let mut w = faer::c64::new(0.0, 0.0);
                        for q in lo..hi {
                            w += (e.values()[q] - mh.at(q).expect("l")[(d, d)])
                                / mh.at(q).expect("l")[(d, d)];
                        }
                        w /= (hi - lo) as f64;
                        let t = (ex.at(k).expect("l")[(d, d)] - ph) / ph;
                        format!(
                            "σ {:.3} mis {:.3}∠{:+.0} true {:.3}∠{:+.0}",
                            v[k].sqrt() / ph.norm(),
                            w.norm(),
                            w.arg().to_degrees(),
                            t.norm(),
                            t.arg().to_degrees()
                        )
                    })
                    .collect();
                println!("  {:.1} Hz: {}", fl[k], row.join(" | "));
            }
        }
        if std::env::var("DEBUG_AMP").is_ok() {
            // the coherent relative shift of each level's FRF (and of the model) against the
            // exact plant per band: κ = Σ w conj(P)(G − P) / Σ w |P|², w = 1/σ², with its std
            let fl = plant.f_hz().to_vec();
            let ex = Frd::from_model(&truth[0].plant, &fl).expect("exact");
            let mh = Frd::from_model(&model.model, &fl).expect("model");
            let sp = &data.speeds[0];
            let mut srcs: Vec<(String, Frd)> =
                vec![(format!("id {:?}", sp.level_pct), plant.clone())];
            for l in &sp.amplitude {
                let g = l.plant.band(fl[0], fl[fl.len() - 1]).expect("band");
                srcs.push((format!("{}", l.level_pct), g));
            }
            for (lo, hi) in [(10.0, 100.0), (100.0, 300.0), (300.0, 1000.0)] {
                println!("  band {lo}-{hi} Hz, diagonal entries: κ (re, im) ± std");
                for (name, g) in &srcs {
                    let mut row = Vec::new();
                    for d in 0..4 {
                        let e = g.entry(d, d).expect("entry");
                        let var = e.variance().expect("variance");
                        let (mut num, mut den) = (faer::c64::new(0.0, 0.0), 0.0);
                        let (mut numm, mut denm) = (faer::c64::new(0.0, 0.0), 0.0);
                        for k in 0..fl.len() {
                            if !(lo..hi).contains(&fl[k]) {
                                continue;
                            }
                            let p = ex.at(k).expect("line")[(d, d)];
                            let w = 1.0 / var[k];
                            num += p.conj() * (e.values()[k] - p) * w;
                            den += w * p.norm_sqr();
                            let pm = mh.at(k).expect("line")[(d, d)];
                            numm += p.conj() * (pm - p) * w;
                            denm += w * p.norm_sqr();
                        }
                        let k = num / den;
                        let km = numm / denm;
                        row.push(format!(
                            "{:+.4} {:+.4} ±{:.4} (model {:+.4} {:+.4})",
                            k.re,
                            k.im,
                            (1.0 / den).sqrt(),
                            km.re,
                            km.im
                        ));
                    }
                    println!("    {name:>10}: {}", row.join(" | "));
                }
            }
        }
        let t_unc = Instant::now();
        // term (e) per entry from the amplitude study, as the workflow computes it
        let sp = &data.speeds[0];
        let amp = sp
            .level_pct
            .filter(|_| !sp.amplitude.is_empty())
            .map(|level_pct| {
                amplitude_terms(
                    &model.model,
                    plant,
                    &AmplitudeStudy {
                        level_pct,
                        levels: &sp.amplitude,
                    },
                )
            });
        let amp = match amp {
            Some(Ok((t, used))) => {
                if std::env::var("DEBUG_E").is_ok() {
                    let med: Vec<String> = t
                        .iter()
                        .map(|e| format!("{:.1e}", median(e.clone())))
                        .collect();
                    println!(
                        "  term (e) from levels {used:?}: entry medians {}",
                        med.join(" ")
                    );
                }
                t
            }
            Some(Err(e)) => {
                println!("  term (e) left out: {e}");
                Vec::new()
            }
            None => Vec::new(),
        };
        let extra: Vec<ExtraTerms<'_>> = amp
            .iter()
            .map(|e| ExtraTerms {
                amplitude_shift: Some(e.as_slice()),
                ..ExtraTerms::default()
            })
            .collect();
        let u = match uncertainty_matrix(&model.model, plant, &extra, &unc_opts) {
            Ok(u) => u,
            Err(e) => {
                println!("rig {rig}: no bound: {e}");
                continue;
            }
        };
        // the lines' correlation the bound found (period averaging: independent, factor 1)
        let lc = u.entries[0].line_correlation;
        println!(
            "    line correlation: ρ₁ {:+.3} ρ₂ {:+.3} z {:+.1} factor {:.2}",
            lc.rho1, lc.rho2, lc.z, lc.factor
        );
        // term (e) through the model, as the workflow does (NO_PROJECT=1: without it)
        let mut u = u;
        let mut projected_kept = false;
        let mut shifts_seen: Vec<Vec<faer::c64>> = Vec::new();
        if std::env::var("NO_PROJECT").is_err() {
            if let Some(a) = sp
                .level_pct
                .filter(|_| !sp.amplitude.is_empty())
                .map(|level_pct| AmplitudeStudy {
                    level_pct,
                    levels: &sp.amplitude,
                })
            {
                let (terms, _) =
                    amplitude_terms_and_shifts(&model.model, plant, &a).expect("shifts");
                let shifts: Vec<Vec<_>> = terms.iter().map(|t| t.shift.clone()).collect();
                let vars: Vec<Vec<f64>> = terms.iter().map(|t| t.shift_var.clone()).collect();
                let ps = u
                    .add_projected_shift(
                        plant,
                        &shifts,
                        &vars,
                        ambid::uncertainty::AMPLITUDE_RUN_ALPHA,
                    )
                    .expect("projection");
                projected_kept = ps.kept;
                shifts_seen = shifts;
                if std::env::var("DEBUG_E").is_ok() {
                    println!("  projected shift: {ps:?}");
                }
            }
        }
        let t_bound = t_unc.elapsed().as_secs_f64();
        // COVER_RAISE / COVER_W: the joint raise's and the weight fit's `cover` (default DEFAULT_COVER)
        let env_f = |k: &str| {
            std::env::var(k)
                .ok()
                .and_then(|v| v.parse::<f64>().ok())
                .unwrap_or(DEFAULT_COVER)
        };
        let cover_w = env_f("COVER_W");
        // COVER_RAISE may list several values (e.g. 0.98,0.95): one row per value, same data
        // the lines, the exact plant and the weight family are the same for every raise
        let f = u.f_hz().to_vec();
        let exact = Frd::from_model(&truth[0].plant, &f).expect("exact");
        let additive = std::env::var("ADDITIVE").is_ok();
        let form = if additive {
            EntryForm::Additive
        } else {
            EntryForm::Relative
        };
        // SHAPE=mode: the mode-shaped family for every entry (opt-in; docs/uncertainty.md)
        let shape = if std::env::var("SHAPE").is_ok_and(|v| v == "mode") {
            ambid_core::validate::weight::WeightShape::ModeShaped
        } else {
            ambid_core::validate::weight::WeightShape::Smooth
        };
        let u0 = u;
        for (vi, cover_raise) in covers.iter().copied().enumerate() {
            let tag = if covers.len() > 1 {
                format!("@{cover_raise}")
            } else {
                String::new()
            };
            let u = u0.clone();
            let t_r = Instant::now();
            // the lines' raise and the weights' on the same draws (machine_fit::speed_uncertainty)
            let raises = u
                .joint_raises(
                    &[cover_raise, cover_w_raise.unwrap_or(cover_raise)],
                    0.95,
                    2000,
                    0,
                )
                .expect("joint raise");
            let (raise, weight_raise) = (raises[0].max(1.0), raises[1].max(1.0));
            let t_raise = t_r.elapsed().as_secs_f64();
            let raised = |u: &MatrixUncertainty, g: f64| {
                if std::env::var("NO_RAISE").is_err() {
                    u.scaled(g).expect("a positive raise")
                } else {
                    u.clone()
                }
            };
            let for_weights = raised(&u, weight_raise);
            let u = raised(&u, raise);
            let norm = u.norm_bound();
            let t_w = Instant::now();
            let wfits = for_weights
                .entry_weights_shaped(data.ts, 4, cover_w, form, shape)
                .expect("entry weights");
            let t_weights = t_w.elapsed().as_secs_f64();
            let weights: Vec<Weight> = wfits.iter().map(|w| w.weight.clone()).collect();
            let wmags: Vec<Vec<f64>> = weights.iter().map(|w| w.magnitude(&f)).collect();
            // the structured weight's element-wise bound |P̂_ij||W_ij| at line k
            let wbound = |k: usize| {
                let ph = u.nominal_at(k);
                Mat::from_fn(4, 4, |i, j| {
                    let scale = if additive { 1.0 } else { ph[(i, j)].norm() };
                    scale * wmags[i + j * 4][k]
                })
            };
            let mut wbnds = Vec::new();
            let (mut pairs, mut pairs_ok, mut n_lines, mut n_ok, mut w_ok) = (0, 0, 0, 0, 0);
            let (mut errs, mut bnds) = (Vec::new(), Vec::new());
            for (k, fk) in f.iter().enumerate() {
                if !(10.0..=1000.0).contains(fk) {
                    continue;
                }
                let p = exact.at(k).expect("line");
                if std::env::var("FRF_ERR").is_ok() && (150.0..=350.0).contains(fk) {
                    let g = plant.at(k).expect("line");
                    let v = plant.variance().expect("var");
                    let e = |i: usize, j: usize| g[(i, j)] - p[(i, j)];
                    println!(
                        "FRFERR {fk:.1} {:.3e} {:.3e} {:.3e} {:.3e} {:.3e} {:.3e}",
                        e(0, 2).re,
                        e(0, 2).im,
                        v[k * 16 + 2 * 4].sqrt(),
                        e(0, 0).re,
                        e(0, 0).im,
                        v[k * 16].sqrt()
                    );
                }
                let ph = u.nominal_at(k);
                let l = u.bound_at(k);
                let d = Mat::from_fn(4, 4, |i, j| (p[(i, j)] - ph[(i, j)]).norm());
                let dc = Mat::from_fn(4, 4, |i, j| p[(i, j)] - ph[(i, j)]);
                for i in 0..4 {
                    for j in 0..4 {
                        pairs += 1;
                        pairs_ok += usize::from(d[(i, j)] <= l[(i, j)]);
                    }
                }
                let e = dc
                    .singular_values()
                    .map(|s| s.into_iter().fold(0.0, f64::max))
                    .unwrap_or(f64::NAN);
                n_lines += 1;
                n_ok += usize::from(e <= norm[k]);
                if std::env::var("DEBUG_ENTRIES").is_ok() && k % 40 == 0 {
                    println!(
                        "   {fk:7.1} Hz (window ±{} lines):",
                        u.entries[0].window_half_lines
                    );
                    for i in 0..4 {
                        let row: Vec<String> = (0..4)
                            .map(|j| {
                                let t = u.entry(i, j).expect("entry");
                                format!(
                                    "{:.1e}/{:.1e}/{:.1e}",
                                    d[(i, j)],
                                    t.additive[k],
                                    plant
                                        .variance()
                                        .map_or(f64::NAN, |v| v[k * 16 + j * 4 + i].sqrt())
                                )
                            })
                            .collect();
                        println!("     {}", row.join("  "));
                    }
                }
                if std::env::var("DEBUG_LINES").is_ok() && k % 8 == 0 {
                    let t = u.entry(0, 0).expect("entry");
                    println!(
                        "   {fk:7.1} Hz: σ̄ err {e:.3e} ‖L‖ {:.3e} | (0,0) err {:.3e} a {:.3e} b {:.3e} misfit {:.3e} σ {:.3e} |P̂| {:.3e}",
                        norm[k], d[(0, 0)], t.frf_confidence[k], t.model_error[k], t.misfit[k],
                        plant.variance().map_or(f64::NAN, |v| v[k * 16].sqrt()), t.nominal[k].norm()
                    );
                }
                let wb = sigma_max(&wbound(k));
                w_ok += usize::from(e <= wb);
                wbnds.push(wb);
                errs.push(e);
                bnds.push(sigma_max(&l));
            }
            let cov_e = pairs_ok as f64 / pairs as f64;
            let cov_n = n_ok as f64 / n_lines as f64;
            let cov_w = w_ok as f64 / n_lines as f64;
            let loose_w = median(wbnds) / median(errs.clone());
            let loose = median(bnds) / median(errs);
            let c = &truth[0].controller;
            let tp = &truth[0].plant;
            let exact_g = nominal_gain_interval(tp, c).expect("exact margins");
            if std::env::var("DEBUG_NOM").is_ok() {
                // the least damped closed-loop poles of the model and of the exact plant near
                // the model's own gain interval, and the largest pole modulus of the same loop
                // with the plant through a random similarity (equal when the poles are those of
                // the model and not of its realisation; docs/uncertainty.md, "Closed-loop poles
                // of a fitted model")
                let ts = model.model.ts().unwrap_or(data.ts);
                let (glo, ghi) = nominal_gain_interval(&model.model, c).expect("model margins");
                for (name, p) in [("model", &model.model), ("exact", tp)] {
                    let n = p.order();
                    let t = Mat::<f64>::from_fn(n, n, |i, j| {
                        if i == j {
                            1.0
                        } else {
                            0.3 * (((i * 31 + j * 17) % 13) as f64 / 13.0 - 0.5)
                        }
                    });
                    let ti = {
                        use faer::linalg::solvers::DenseSolveCore;
                        t.partial_piv_lu().inverse()
                    };
                    let pt = ambid_core::lti::StateSpace::new(
                        &ti * p.a() * &t,
                        &ti * p.b(),
                        p.c() * &t,
                        p.d().to_owned(),
                        p.ts(),
                    )
                    .expect("similar");
                    for g in [glo * 0.995, glo * 1.005, 1.0, ghi * 0.995, ghi * 1.005] {
                        let cg = ambid_core::lti::StateSpace::new(
                            c.a().to_owned(),
                            c.b().to_owned(),
                            c.c().to_owned() * g,
                            c.d().to_owned() * g,
                            c.ts(),
                        )
                        .expect("gain");
                        let zeta = |z: &faer::c64| {
                            let sc = z.ln() / ts;
                            -sc.re / sc.norm()
                        };
                        let mut poles = p.feedback(&cg).expect("loop").poles().expect("poles");
                        let max = |v: &[faer::c64]| v.iter().map(|z| z.norm()).fold(0.0, f64::max);
                        let sim = max(&pt.feedback(&cg).expect("loop").poles().expect("poles"));
                        let top = max(&poles);
                        poles.sort_by(|a, b| zeta(a).total_cmp(&zeta(b)));
                        let s: Vec<String> = poles
                            .iter()
                            .filter(|z| z.im >= 0.0)
                            .take(4)
                            .map(|z| {
                                let sc = z.ln() / ts;
                                format!(
                                    "{:.1} Hz |z| {:.5} zeta {:.3}",
                                    sc.norm() / std::f64::consts::TAU,
                                    z.norm(),
                                    zeta(z)
                                )
                            })
                            .collect();
                        println!(
                            "    {name} g {g:.4}: max |z| {top:.5} (through a similarity {sim:.5}); {}",
                            s.join("; ")
                        );
                    }
                }
            }
            let bounds = u.bounds();
            let on_lines = robust_stability_matrix_on_lines(
                &model.model,
                c,
                &f,
                LineBound::Elementwise(&bounds),
            )
            .expect("robust on lines");
            let mw = if additive {
                MatrixWeight::EntryAdditive(&weights)
            } else {
                MatrixWeight::EntryRelative(&weights)
            };
            let on_w = robust_stability_matrix_weight(&model.model, c, mw).expect("robust weight");
            // coherent draws (docs/uncertainty.md, "Coherent draws for the machine")
            let t_c = Instant::now();
            let n_draws: usize = std::env::var("COHERENT_DRAWS")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(200);
            let conf: f64 = std::env::var("CONF")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(0.95);
            let mut cd = u.coherent_draws(n_draws, 0).expect("coherent draws");
            if std::env::var("DEBUG_SHIFT").is_ok() {
                debug_shift(&u, &cd, &exact, &shifts_seen);
            }
            // REMAINDER=0: the draws alone, the element-wise remainder left out (a diagnostic of
            // what sets the coherent margin; not a bound)
            match std::env::var("REMAINDER").as_deref() {
                Ok("0") => cd.remainder.iter_mut().for_each(|r| r.fill(0.0)),
                // REMAINDER=old: the per-line amplitude term back in beside a kept projection
                // (the coherent draws before 2026-12-05, tenth session)
                Ok("old") if projected_kept && !amp.is_empty() => {
                    for (k, r) in cd.remainder.iter_mut().enumerate() {
                        for (e, a) in amp.iter().enumerate() {
                            r[(e % 4, e / 4)] += a[k];
                        }
                    }
                }
                // REMAINDER=freeb: term (b) back at a free phase (its centre out of every draw,
                // all of b_k in the remainder; the coherent draws before 2026-12-05, eleventh
                // session)
                Ok("freeb") => {
                    for (k, r) in cd.remainder.iter_mut().enumerate() {
                        for (e, t) in u.entries.iter().enumerate() {
                            let (i, j) = (e % 4, e / 4);
                            let c = cd.bias_centre[k][(i, j)];
                            cd.draws.iter_mut().for_each(|d| d[k][(i, j)] -= c);
                            r[(i, j)] += t.model_error[k] - cd.bias_spread[k][(i, j)];
                        }
                    }
                }
                // REMAINDER=b: term (b)'s spread alone; REMAINDER=e: the rest
                Ok(part @ ("b" | "e")) => {
                    for (k, r) in cd.remainder.iter_mut().enumerate() {
                        for e in 0..16 {
                            let (i, j) = (e % 4, e / 4);
                            let (rem, b) = (r[(i, j)], cd.bias_spread[k][(i, j)]);
                            r[(i, j)] = if part == "b" {
                                rem.min(b)
                            } else {
                                (rem - b).max(0.0)
                            };
                        }
                    }
                }
                _ => {}
            }
            if std::env::var("DEBUG_REM").is_ok() {
                // per entry, the median and the maximum over the lines of term (b) and of the rest,
                // relative to |P̂|
                let ph = Frd::from_model(&model.model, &cd.f_hz).expect("model");
                let rows: Vec<String> = (0..16)
                    .map(|e| {
                        let t = &u.entries[e];
                        let rel = |x: &dyn Fn(usize) -> f64| {
                            let mut v: Vec<f64> = (0..cd.f_hz.len())
                                .map(|k| x(k) / ph.at(k).expect("line")[(e % 4, e / 4)].norm())
                                .collect();
                            v.sort_by(f64::total_cmp);
                            (v[v.len() / 2], v[v.len() - 1])
                        };
                        let (bm, bx) = rel(&|k| t.model_error[k]);
                        let (rm, rx) =
                            rel(&|k| (cd.remainder[k][(e % 4, e / 4)] - t.model_error[k]).max(0.0));
                        format!("{e}: b {bm:.4}/{bx:.3} e {rm:.4}/{rx:.3}")
                    })
                    .collect();
                println!("    remainder (median/max relative): {}", rows.join("; "));
            }
            let coh = robust_stability_matrix_drawn(
                &model.model,
                c,
                &cd.f_hz,
                &cd.draws,
                &cd.remainder,
                // OUTSIDE=0: nothing tested outside the lines (the margins rest on the model)
                (std::env::var("OUTSIDE").as_deref() != Ok("0")).then_some(mw),
                conf,
            )
            .expect("drawn");
            let bc = coh
                .lower_gain_margin
                .zip(coh.upper_gain_margin)
                .and_then(|(lo, hi)| bars_of(lo, hi, &truth[0].plant, c, exact_g));
            let t_coh = t_c.elapsed().as_secs_f64();
            let t_robust = t_r.elapsed().as_secs_f64() - t_raise - t_coh;
            if std::env::var("TIMING").is_ok() {
                println!("  bound {t_bound:.2} s, raise {t_raise:.2} s, entry weights {t_weights:.2} s, weights + exact margins + robust {t_robust:.2} s");
            }
            let bl = bars(&on_lines, tp, c, exact_g);
            // DUMP_MU=dir: the lines' P̂, C, L and the exact and robust intervals as JSON (one
            // file per rig and raise), to compare μ bounds outside
            if let Ok(dir) = std::env::var("DUMP_MU") {
                let ph = Frd::from_model(&model.model, &f).expect("model");
                let cf = Frd::from_model(c, &f).expect("controller");
                let flat = |fr: &Frd| -> Vec<[f64; 2]> {
                    (0..f.len())
                        .flat_map(|k| {
                            let m = fr.at(k).expect("line");
                            (0..16).map(move |e| [m[(e % 4, e / 4)].re, m[(e % 4, e / 4)].im])
                        })
                        .collect()
                };
                let lb: Vec<f64> = (0..f.len())
                    .flat_map(|k| {
                        let l = u.bound_at(k);
                        (0..16).map(move |e| l[(e % 4, e / 4)])
                    })
                    .collect();
                let wb: Vec<f64> = (0..f.len())
                    .flat_map(|k| {
                        let l = wbound(k);
                        (0..16).map(move |e| l[(e % 4, e / 4)])
                    })
                    .collect();
                let j = serde_json::json!({
                    "f": f, "phat": flat(&ph), "c": flat(&cf), "exact": flat(&exact),
                    "l": lb, "lw": wb,
                    "exact_interval": [exact_g.0, exact_g.1],
                    "lines_margins": [on_lines.lower_gain_margin, on_lines.upper_gain_margin],
                    "weight_margins": [on_w.lower_gain_margin, on_w.upper_gain_margin],
                });
                std::fs::write(
                    Path::new(&dir).join(format!("rig{rig}{tag}.json")),
                    j.to_string(),
                )
                .expect("dump");
            }
            if std::env::var("DEBUG").is_ok() {
                if let Some(g) = on_lines.upper_gain_margin.filter(|g| g.is_finite()) {
                    let cg = ambid_core::lti::StateSpace::new(
                        c.a().to_owned(),
                        c.b().to_owned(),
                        c.c().to_owned() * (g * 1.001),
                        c.d().to_owned() * (g * 1.001),
                        c.ts(),
                    )
                    .expect("scaled");
                    let r = robust_stability_matrix_on_lines(
                        &model.model,
                        &cg,
                        &f,
                        LineBound::Elementwise(&bounds),
                    )
                    .expect("robust");
                    let k = f.iter().position(|x| *x == r.mu_peak_hz).unwrap_or(0);
                    println!(
                        "  at g+ {g:.3}: mu {:.3} at {:.1} Hz (line {k} of {})",
                        r.mu_peak,
                        r.mu_peak_hz,
                        f.len()
                    );
                    for (i, j) in [(0, 0), (1, 1), (2, 2), (3, 3), (0, 1), (0, 2)] {
                        let e = u.entry(i, j).expect("entry");
                        let p = exact.at(k).expect("line");
                        println!(
                            "   ({i},{j}) |P̂| {:.3e} |err| {:.3e} L {:.3e}: (a) {:.3e} (b) {:.3e} misfit {:.3e}",
                            e.nominal[k].norm(),
                            (p[(i, j)] - e.nominal[k]).norm(),
                            e.additive[k],
                            e.frf_confidence[k],
                            e.model_error[k],
                            e.misfit[k]
                        );
                    }
                }
            }
            if std::env::var("DEBUG_W").is_ok() {
                let k = f
                    .iter()
                    .enumerate()
                    .min_by(|a, b| {
                        (a.1 - on_w.mu_peak_hz)
                            .abs()
                            .total_cmp(&(b.1 - on_w.mu_peak_hz).abs())
                    })
                    .map_or(0, |x| x.0);
                let wb = wbound(k);
                let l = u.bound_at(k);
                let ph = u.nominal_at(k);
                println!("  weight μ peak {:.1} Hz, line {k} at {:.1} Hz: |P̂_ij| / (|P̂||W|)/L / uncovered lines", on_w.mu_peak_hz, f[k]);
                for i in 0..4 {
                    let row: Vec<String> = (0..4)
                        .map(|j| {
                            format!(
                                "{:.1e}/{:6.2}/{}",
                                ph[(i, j)].norm(),
                                wb[(i, j)] / l[(i, j)],
                                wfits[i + j * 4].uncovered_hz.len()
                            )
                        })
                        .collect();
                    println!("     {}", row.join("  "));
                }
                // at the μ peak itself (between lines, on the dense grid): the model's and the
                // weights' magnitudes against the nearest line's, and the model's poles near it
                let fp = on_w.mu_peak_hz;
                // two evaluations: the peak may lie on the line itself
                let at_p = Frd::from_model(&model.model, &[fp]).expect("model");
                let at_l = Frd::from_model(&model.model, &[f[k]]).expect("model");
                let (pp, pl) = (at_p.at(0).expect("p"), at_l.at(0).expect("l"));
                let mut worst = (0.0, 0, 0);
                for i in 0..4 {
                    for j in 0..4 {
                        let w = &weights[i + j * 4];
                        let (wp, wl) = (w.magnitude(&[fp])[0], w.magnitude(&[f[k]])[0]);
                        let r = (pp[(i, j)].norm() * wp) / (pl[(i, j)].norm() * wl);
                        if r > worst.0 {
                            worst = (r, i, j);
                        }
                    }
                }
                let (r, i, j) = worst;
                let w = &weights[i + j * 4];
                println!(
                    "  at {fp:.2} Hz: largest |P̂||W| over the line's, entry ({i},{j}): {r:.3e} (|P̂| {:.3e} / {:.3e}, |W| {:.3e} / {:.3e})",
                    pp[(i, j)].norm(),
                    pl[(i, j)].norm(),
                    w.magnitude(&[fp])[0],
                    w.magnitude(&[f[k]])[0]
                );
                let ts = data.ts;
                let a = model.model.a();
                let off = (0..a.nrows())
                    .flat_map(|i| (0..a.ncols()).map(move |j| (i, j)))
                    .filter(|&(i, j)| i.abs_diff(j) > 1 && a[(i, j)] != 0.0)
                    .count();
                println!(
                    "    A {}×{}: {off} nonzero entries off the tridiagonal band",
                    a.nrows(),
                    a.ncols()
                );
                for z in model.model.poles().expect("poles") {
                    let sp = z.ln() / ts;
                    let fz = sp.norm() / (2.0 * std::f64::consts::PI);
                    if (fz / fp - 1.0).abs() < 0.2 {
                        println!(
                            "    model pole {fz:.2} Hz ζ {:.2e} |z| {:.6}",
                            -sp.re / sp.norm(),
                            z.norm()
                        );
                    }
                }
                for z in truth[0].plant.poles().expect("poles") {
                    let sp = if let Some(t) = truth[0].plant.ts() {
                        z.ln() / t
                    } else {
                        z
                    };
                    let fz = sp.norm() / (2.0 * std::f64::consts::PI);
                    if (fz / fp - 1.0).abs() < 0.2 {
                        println!(
                            "    exact pole {fz:.2} Hz ζ {:.2e} re {:.3e}",
                            -sp.re / sp.norm(),
                            sp.re
                        );
                    }
                }
            }
            if let Ok(dump) = std::env::var("DUMP_ENTRIES") {
                // per line: f, then per entry the relative bound and the weight's magnitude
                let mut out = String::new();
                for (k, fk) in f.iter().enumerate() {
                    out.push_str(&format!("{fk}"));
                    for j in 0..4 {
                        for i in 0..4 {
                            let e = u.entry(i, j).expect("entry");
                            let p = exact.at(k).expect("line")[(i, j)];
                            out.push_str(&format!(
                                " {} {} {}",
                                e.additive[k] / e.nominal[k].norm(),
                                wmags[i + j * 4][k],
                                (p - e.nominal[k]).norm() / e.nominal[k].norm()
                            ));
                        }
                    }
                    out.push('\n');
                }
                std::fs::write(format!("{dump}/rig{rig}.txt"), out).expect("dump");
            }
            let bw = bars(&on_w, tp, c, exact_g);
            // where the weights cap the coherent margin outside the lines: the true relative
            // error there against the weights' magnitude, per entry
            if let Some(fc) = coh.outside_critical_hz[1] {
                let (pt, ph) = (
                    Frd::from_model(tp, &[fc]).expect("truth"),
                    Frd::from_model(&model.model, &[fc]).expect("model"),
                );
                let (pt, ph) = (pt.at(0).expect("truth"), ph.at(0).expect("model"));
                let ny = ph.nrows();
                let mut worst = (0.0f64, 0.0f64, 0usize);
                for (e, w) in weights.iter().enumerate() {
                    let (i, j) = (e % ny, e / ny);
                    let truth_rel = (pt[(i, j)] - ph[(i, j)]).norm() / ph[(i, j)].norm();
                    let wm = w.magnitude(&[fc])[0];
                    if truth_rel / wm > worst.0 / worst.1.max(1e-300) || e == 0 {
                        worst = (truth_rel, wm, e);
                    }
                }
                let diag: Vec<String> = (0..ny)
                    .map(|i| {
                        let e = i + i * ny;
                        format!(
                            "{:.3}/{:.3}",
                            (pt[(i, i)] - ph[(i, i)]).norm() / ph[(i, i)].norm(),
                            weights[e].magnitude(&[fc])[0]
                        )
                    })
                    .collect();
                println!(
                    "    outside cap at {fc:.1} Hz: true relative error / weight on the diagonal {diag:?}; entry {} closest {:.3}/{:.3}",
                    worst.2, worst.0, worst.1
                );
            }
            println!(
                "    coherent ({n_draws} draws, {conf}): stable {:.3}, margins {:.3} {:.3} {:?} outside {:?} exact {:.3} {:.3} ({t_coh:.1} s)",
                coh.stable_fraction,
                coh.lower_gain_margin.unwrap_or(f64::NAN),
                coh.upper_gain_margin.unwrap_or(f64::NAN),
                bc,
                coh.outside_gain_interval,
                exact_g.0,
                exact_g.1
            );
            let fmt = |r: &RobustStability| {
                format!(
                    "[mu {:.2} at {:.0} Hz] {:.3} {:.3}",
                    r.mu_peak,
                    r.mu_peak_hz,
                    r.lower_gain_margin.unwrap_or(f64::NAN),
                    r.upper_gain_margin.unwrap_or(f64::NAN)
                )
            };
            println!(
                "{rig:3}{tag} {:5.0} | {} ({:.1}-{:.0} Hz) raise {raise:.2}/{weight_raise:.2} | {cov_e:.3} {cov_n:.3} {cov_w:.3} | {loose:.2} {loose_w:.2} | {} ({:.3} {:.3}) {:?} | {} {} {:?} | {:.1}",
                truth[0].speed_rpm,
                f.len(),
                f[0],
                f[f.len() - 1],
                fmt(&on_lines),
                exact_g.0,
                exact_g.1,
                bl,
                weights.iter().map(Weight::order).max().unwrap_or(0),
                fmt(&on_w),
                bw,
                t0.elapsed().as_secs_f64()
            );
            summaries[vi].push((cov_e, cov_n, cov_w, loose, bl, bw, loose_w, bc));
        }
    }
    for (summary, cover) in summaries.iter().zip(&covers) {
        print!("raise cover {cover}: ");
        let n = summary.len();
        let count = |p: &dyn Fn(&Row) -> bool| summary.iter().filter(|s| p(s)).count();
        println!(
            "runs {n}: element-wise ≥95 % of pairs {}; norm ≥95 % of lines {}; weight ≥95 % {}; looseness median {:.2}; lines: stable@90 % {} half {}; weight: stable@90 % {} half {}; weight looseness median {:.2}",
            count(&|s| s.0 >= 0.95),
            count(&|s| s.1 >= 0.95),
            count(&|s| s.2 >= 0.95),
            if n > 0 { median(summary.iter().map(|s| s.3).collect()) } else { f64::NAN },
            count(&|s| s.4.is_some_and(|b| b.0)),
            count(&|s| s.4.is_some_and(|b| b.1)),
            count(&|s| s.5.is_some_and(|b| b.0)),
            count(&|s| s.5.is_some_and(|b| b.1)),
            if n > 0 { median(summary.iter().map(|s| s.6).collect()) } else { f64::NAN },
        );
        println!(
            "  coherent draws: stable@90 % {} half {}",
            count(&|s| s.7.is_some_and(|b| b.0)),
            count(&|s| s.7.is_some_and(|b| b.1)),
        );
    }
}
