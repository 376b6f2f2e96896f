//! The workflow's `uncertainty` step with term (d) from its `operating_point` step (issue 23)
//! on random rigs of the twin: per rig the workflow with `steps = operating_point, uncertainty`
//! (and their prerequisites) on `random_rig(rig)` with noise seed `rig`; term (d) over the
//! twin's exact linearised plants at the five operating points (median and 10–90 % of the ratio
//! on the 20–1000 Hz lines), and whether the true loop of every operating point stays stable
//! with the controller gain moved 90 % of the way to each reported robust gain margin; and the
//! chosen model's true error (against the nominal plant) on 10–1000 Hz: the fraction of lines
//! the weight and the bound ℓ cover, and the weight's median over the error's median; and the
//! same margins check for the robust-stability check on the lines (no weight fit).
//!
//! `cargo run --release -p ambid --example uncertainty_operating_rigs -- RIGS [linear|nonlinear]`
//! (e.g. `61-80`). The `uncertainty` step brings the amplitude step (its chosen identification
//! level, and term (e) from its levels; before 2026-12-01 only with `AMPLITUDE=1`, which the
//! older figures in docs/uncertainty.md name). `SHOW_U=1` prints each rig's uncertainty summary, `SHOW_MODEL=1` the model
//! JSONs of a rig where the step did not run.

mod common;

use ambid::report::Block;
use ambid::uncertainty::loop_stable;
use ambid::workflow::{Step, WorkflowConfig};
use ambid_twin::{Twin, TwinConfig};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs = common::range(args.get(1).map_or("61-70", String::as_str));
    let mode = args.get(2).cloned().unwrap_or_else(|| "linear".into());
    let dir = std::env::temp_dir().join(format!("ambid-unc-op-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (all, _) = Step::with_prerequisites(&[Step::OperatingPoint, Step::Uncertainty]);
    let (mut runs, mut all_stable, mut medians, mut covered) = (0, 0, Vec::new(), 0);
    let (mut lines_robust, mut weight_robust, mut lines_all_stable) = (0, 0, 0);
    println!("rig | (d)/truth q10 median q90 | spread median | margins lo hi | every case stable at 90 % | chosen model: cov_W cov_l medW/med_err");
    for rig in rigs {
        let (cfg, out) = common::workflow_on_rig(rig, &mode, &all, &dir);
        let out = match out {
            Ok(o) => o,
            Err(e) => {
                println!("{rig}: {e}");
                continue;
            }
        };
        let u = &out.summary["uncertainty"];
        if std::env::var("SHOW_U").is_ok() {
            println!("{rig}: {u}");
            for pre in ["(a)", "(b)", "bound", "|W|", "(d)", "(e)"] {
                if let Some(sr) = out.report.series("uncertainty", pre) {
                    let pts: Vec<String> =
                        sr.x.iter()
                            .zip(&sr.y)
                            .step_by(20)
                            .map(|(x, y)| format!("{x:.0}:{y:.2e}"))
                            .collect();
                    println!("{pre} {}", pts.join(" "));
                }
            }
        }
        let Some(series) = out
            .report
            .series("uncertainty", "(d)")
            .cloned()
            .filter(|s| !s.y.is_empty())
        else {
            let why: Vec<String> = out
                .timings
                .iter()
                .filter(|t| t.status != "done")
                .map(|t| format!("{}: {}", t.step, t.status))
                .chain(
                    out.report
                        .sections
                        .iter()
                        .flat_map(|s| &s.blocks)
                        .filter_map(|b| match b {
                            Block::Note { text, .. } if text.contains("skipped") => {
                                Some(text.clone())
                            }
                            _ => None,
                        }),
                )
                .collect();
            println!(
                "{rig}: no term (d) ({}); chosen model {}",
                why.join("; "),
                out.summary["models"]["chosen"]
            );
            if std::env::var("SHOW_MODEL").is_ok() {
                for (name, j) in out.model_jsons().unwrap() {
                    println!("{name}: {j}");
                }
            }
            continue;
        };
        let (b, g) = (
            WorkflowConfig::default().operating_point.bias_pct / 100.0,
            WorkflowConfig::default().operating_point.air_gap_um * 1e-6,
        );
        let case = |bias: f64, gap: f64| -> TwinConfig {
            let mut c = cfg.clone();
            c.operating_point.bias_current_a = cfg.operating_point.bias_current_a * bias;
            c.operating_point.air_gap_m = cfg.operating_point.air_gap_m + gap;
            c
        };
        let twins: Vec<Twin> = [
            case(1.0, 0.0),
            case(1.0 - b, 0.0),
            case(1.0 + b, 0.0),
            case(1.0, -g),
            case(1.0, g),
        ]
        .into_iter()
        .map(|c| Twin::new(c).unwrap())
        .collect();
        let resp: Vec<_> = twins
            .iter()
            .map(|t| t.plant().freq_response_siso(&series.x).unwrap())
            .collect();
        let mut ratios = Vec::new();
        for (k, f) in series.x.iter().enumerate() {
            if (20.0..=1000.0).contains(f) {
                let truth = resp[1..]
                    .iter()
                    .map(|p| (p[k] - resp[0][k]).norm() / resp[0][k].norm())
                    .fold(0.0f64, f64::max);
                ratios.push(series.y[k] / truth);
            }
        }
        ratios.sort_by(f64::total_cmp);
        let n = ratios.len();
        // the chosen model's true error against the weight and the bound on 10–1000 Hz
        let pick = |prefix: &str| out.report.series("uncertainty", prefix).cloned();
        let (w, ell, err) = (pick("|W|"), pick("bound ℓ"), pick("twin: true"));
        let (mut cov_w, mut cov_l, mut med) = (f64::NAN, f64::NAN, f64::NAN);
        if let (Some(w), Some(ell), Some(err)) = (w, ell, err) {
            let idx: Vec<usize> = (0..err.x.len())
                .filter(|&k| (10.0..=1000.0).contains(&err.x[k]))
                .collect();
            let m = idx.len().max(1) as f64;
            cov_w = idx.iter().filter(|&&k| w.y[k] >= err.y[k]).count() as f64 / m;
            cov_l = idx.iter().filter(|&&k| ell.y[k] >= err.y[k]).count() as f64 / m;
            let median = |mut v: Vec<f64>| {
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            med = median(idx.iter().map(|&k| w.y[k]).collect())
                / median(idx.iter().map(|&k| err.y[k]).collect());
            covered += usize::from(cov_w >= 0.95);
        }
        let (lo, hi) = (
            u["lower_gain_margin"].as_f64(),
            u["upper_gain_margin"].as_f64(),
        );
        let stable_at = |lo: Option<f64>, hi: Option<f64>| {
            twins.iter().all(|t| {
                [
                    lo.map(|g| 1.0 - 0.9 * (1.0 - g)),
                    hi.map(|g| 1.0 + 0.9 * (g - 1.0)),
                ]
                .into_iter()
                .flatten()
                .all(|gain| loop_stable(t.plant(), t.controller(), gain).unwrap_or(false))
            })
        };
        let stable = stable_at(lo, hi);
        // the check on the lines (no weight fit)
        let (l_lo, l_hi) = (
            u["lines_lower_gain_margin"].as_f64(),
            u["lines_upper_gain_margin"].as_f64(),
        );
        let l_stable = stable_at(l_lo, l_hi);
        lines_robust += usize::from(u["lines_robustly_stable"] == true);
        weight_robust += usize::from(u["robustly_stable"] == true);
        lines_all_stable += usize::from(l_stable);
        runs += 1;
        all_stable += usize::from(stable);
        medians.push(ratios[n / 2]);
        println!(
            "{rig} | {:.3} {:.3} {:.3} | {:.3} | {:?} {:?} | {stable} | {} {cov_w:.3} {cov_l:.3} {med:.2} | lines {l_lo:?} {l_hi:?} {l_stable} | (e) {:?} {:?}",
            ratios[n / 10],
            ratios[n / 2],
            ratios[9 * n / 10],
            u["operating_spread_median_rel"]
                .as_f64()
                .unwrap_or(f64::NAN),
            lo,
            hi,
            out.summary["models"]["chosen"],
            u["amplitude_shift_median_rel"].as_f64(),
            u["amplitude_levels_pct"].as_array().map(Vec::len)
        );
    }
    medians.sort_by(f64::total_cmp);
    println!(
        "runs {runs}: median (d)/truth from {:.3} to {:.3}; every operating point stable at 90 % of both margins in {all_stable}; the weight covers >= 95 % of the chosen model's 10-1000 Hz true error in {covered}; robustly stable against the weight in {weight_robust}, against the bound on the lines in {lines_robust} (every operating point stable at 90 % of those margins in {lines_all_stable})",
        medians.first().copied().unwrap_or(f64::NAN),
        medians.last().copied().unwrap_or(f64::NAN)
    );
}
