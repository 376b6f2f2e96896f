//! Many noise realisations of one rig (issue 23's coverage bar speaks of "twin seeds/noise
//! realisations"): the workflow's `uncertainty` step as `uncertainty_workflow_rigs` runs it, on
//! `random_rig(rig)` with the noise seeds `1000 rig + s`, `s = 1..=N`. Per rig it prints
//!
//! * the coverage bar: runs whose |W| covers the chosen model's true relative error on ≥ 95 %
//!   of the 10–1000 Hz lines;
//! * the looseness two ways: **per run** (median |W| ÷ median error of the same run, the rule
//!   every sweep of docs/uncertainty.md uses), and **against the per-line median** of the error
//!   over the realisations (median over the lines of |W_k| ÷ med_r e_{r,k}, median over runs);
//! * an **oracle**: the tightest weights that knowledge of the true error over all realisations
//!   allows. (i) *unfitted*: a per-line quantile of the error over the runs, raised by
//!   the factor that makes it cover 95 % of the lines in 95 % of the runs; (ii) *order ≤ 4*:
//!   the mode-shaped fit ([`fit_weight_shaped`], order 0–4) to that quantile on the 10–1000 Hz lines alone,
//!   raised the same way. Each oracle takes the per-line quantile (50, 75, 90 or 95 %) and,
//!   fitted, the order (0–4) that gives the smallest per-run looseness. Their looseness, both ways, is what any weight of the family could
//!   reach with perfect knowledge of the error; the tool's weight knows one record.
//!
//! `cargo run --release -p ambid --example uncertainty_realisations -- RIGS N [linear|nonlinear]`

mod common;

use ambid::workflow::Step;
use ambid_core::validate::weight::{fit_weight_shaped, WeightShape};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The value at quantile `q` of `v` (the ⌈qn⌉-th smallest).
fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let i = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
    v[i]
}

/// The factor `w` must be raised by to cover 95 % of the lines in 95 % of the runs `errs`.
fn raise(w: &[f64], errs: &[Vec<f64>]) -> f64 {
    let per_run: Vec<f64> = errs
        .iter()
        .map(|e| quantile(e.iter().zip(w).map(|(e, w)| e / w).collect(), 0.95))
        .collect();
    quantile(per_run, 0.95)
}

/// (median over runs of median |W| ÷ median e_r; median over runs of median_k |W_k| ÷ m_k),
/// `w` per run or one for all.
fn looseness(w: &[&[f64]], errs: &[Vec<f64>], per_line_median: &[f64]) -> (f64, f64) {
    let w_of = |r: usize| if w.len() == 1 { w[0] } else { w[r] };
    let a = median(
        (0..errs.len())
            .map(|r| median(w_of(r).to_vec()) / median(errs[r].clone()))
            .collect(),
    );
    let b = median(
        (0..errs.len())
            .map(|r| {
                median(
                    w_of(r)
                        .iter()
                        .zip(per_line_median)
                        .map(|(w, m)| w / m)
                        .collect(),
                )
            })
            .collect(),
    );
    (a, b)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs = common::range(args.get(1).map_or("1", String::as_str));
    let n: u64 = args
        .get(2)
        .map_or(20, |s| s.parse().expect("a number of realisations"));
    let mode = args.get(3).cloned().unwrap_or_else(|| "linear".into());
    let dir = std::env::temp_dir().join(format!("ambid-unc-real-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let (steps, _) = Step::with_prerequisites(&[Step::Uncertainty]);
    println!("rig | runs | W covers ≥ 95 % | looseness per run, per-line median | oracle unfitted: raise, per run, per-line | oracle order ≤ 4: order, raise, per run, per-line");
    for rig in rigs {
        let mut f_band: Option<Vec<f64>> = None;
        let (mut ws, mut errs) = (Vec::new(), Vec::new());
        let mut ts = f64::NAN;
        for s in 1..=n {
            let seed = 1000 * rig + s;
            let (cfg, out) = common::workflow_on_rig_seed(rig, seed, &mode, &steps, &dir);
            ts = ambid_twin::Twin::new(cfg).expect("the rig's twin").ts();
            let Ok(out) = out else { continue };
            let pick = |p: &str| out.report.series("uncertainty", p).cloned();
            let (Some(w), Some(e)) = (pick("|W|"), pick("twin: true")) else {
                continue;
            };
            let idx: Vec<usize> = (0..e.x.len())
                .filter(|&k| (10.0..=1000.0).contains(&e.x[k]))
                .collect();
            let f: Vec<f64> = idx.iter().map(|&k| e.x[k]).collect();
            match &f_band {
                None => f_band = Some(f),
                Some(f0) if *f0 != f => {
                    println!("{rig}: seed {seed} has other lines, left out");
                    continue;
                }
                _ => {}
            }
            ws.push(idx.iter().map(|&k| w.y[k]).collect::<Vec<f64>>());
            errs.push(idx.iter().map(|&k| e.y[k]).collect::<Vec<f64>>());
        }
        let Some(f) = f_band else {
            println!("{rig} | 0 runs");
            continue;
        };
        let l = f.len();
        let covered = ws
            .iter()
            .zip(&errs)
            .filter(|(w, e)| {
                w.iter().zip(e.iter()).filter(|(w, e)| w >= e).count() as f64 >= 0.95 * l as f64
            })
            .count();
        let per_line_median: Vec<f64> = (0..l)
            .map(|k| median(errs.iter().map(|e| e[k]).collect()))
            .collect();
        let refs: Vec<&[f64]> = ws.iter().map(Vec::as_slice).collect();
        let (a, b) = looseness(&refs, &errs, &per_line_median);
        // the oracles: per-line quantile targets q, raised to 95 % of the lines in 95 % of the
        // runs; the smallest per-run looseness over q (and, fitted, over the orders 0–4)
        let mut best_unfitted = (f64::INFINITY, f64::NAN, f64::NAN, 0.0);
        let mut best_fitted = (f64::INFINITY, f64::NAN, f64::NAN, 0.0, 0usize);
        for q in [0.5, 0.75, 0.9, 0.95] {
            let target: Vec<f64> = (0..l)
                .map(|k| quantile(errs.iter().map(|e| e[k]).collect(), q).max(1e-15))
                .collect();
            let r0 = raise(&target, &errs);
            let unfitted: Vec<f64> = target.iter().map(|t| t * r0).collect();
            let (ua, ub) = looseness(&[&unfitted], &errs, &per_line_median);
            if ua < best_unfitted.0 {
                best_unfitted = (ua, ub, r0, q);
            }
            for order in 0..=4 {
                let Ok(fit) =
                    fit_weight_shaped(&f, &target, ts, order, 0.98, WeightShape::ModeShaped)
                else {
                    continue;
                };
                let m = fit.weight.magnitude(&f);
                let r = raise(&m, &errs);
                let m: Vec<f64> = m.iter().map(|x| x * r).collect();
                let (fa, fb) = looseness(&[&m], &errs, &per_line_median);
                if fa < best_fitted.0 {
                    best_fitted = (fa, fb, r, q, fit.weight.order());
                }
            }
        }
        let (ua, ub, r0, q0) = best_unfitted;
        let (fa, fb, r1, q1, order) = best_fitted;
        let fitted = format!("q {q1} order {order} raise {r1:.3}: {fa:.2} {fb:.2}");
        println!(
            "{rig} | {} | {covered} | {a:.2} {b:.2} | q {q0} raise {r0:.3}: {ua:.2} {ub:.2} | {fitted}",
            errs.len()
        );
    }
}
