//! The magnet constant and effective air gap from the operating-point study on rigs of the
//! twin (issue 23): per rig the seed's five cases (nominal, bias ±20 %, gap ±10 µm), the gray
//! box at each, the magnet law through them ([`OperatingRun`]); the errors of $k$, $g_0$ and of
//! the pooled $k_i$, $k_x$ at nominal against the twin, whether each 95 % interval covers, and
//! at the end the coverage and the worst error.
//!
//! `cargo run --release -p ambid --example physical_operating_rigs -- RIGS [linear|nonlinear] [LEVELS]`
//! (RIGS `1-100` or `3,7,9`; rig r uses the noise seeds 3000 + 1000 r + case + 100 level, so
//! that no two runs share a noise realisation; LEVELS the PRBS amplitudes as fractions of
//! i_sat, default the seed experiment's; several, e.g. `0.05,0.075,0.1`, extrapolate each case
//! to zero amplitude before the magnet law). The last line: each case's point (its estimate,
//! or its extrapolation) covering that case's own linearisation.

use ambid::experiment::ExcitationPlan;
use ambid::physical::operating::OperatingRun;
use ambid_twin::Mode;

mod common;
use common::range;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs = range(args.get(1).map_or("1-10", String::as_str));
    let mode = match args.get(2).map(String::as_str) {
        Some("nonlinear") => Mode::Nonlinear,
        _ => Mode::Linear,
    };
    let levels: Vec<f64> = args
        .get(3)
        .map_or(vec![ExcitationPlan::default().amplitude_frac], |s| {
            s.split(',').map(|x| x.parse().unwrap()).collect()
        });
    const NAMES: [&str; 4] = ["k", "g0", "k_i(nominal)", "k_x(nominal)"];
    let mut covered = [0usize; 4];
    let mut worst = [0.0f64; 4];
    let mut errors: [Vec<f64>; 4] = Default::default();
    let mut z2 = [0.0f64; 4];
    let (mut case_cov, mut case_n) = ([0usize; 2], 0usize);
    let mut case_z2 = [0.0f64; 3];
    let mut chi_over = 0;
    let mut runs = 0;
    println!("rig | rel. error % (k g0 k_i k_x at nominal) | covered | chi2/dof s | single-point k_i k_x covered");
    for &rig in &rigs {
        let t = std::time::Instant::now();
        let r = match OperatingRun::on_twin_at(rig, 3000 + 1000 * rig, mode, &levels) {
            Ok(r) => r,
            Err(e) => {
                println!("{rig}: {e}");
                continue;
            }
        };
        runs += 1;
        let (ki, kx) = r.law.predict(r.cases[0].0, 0.0).unwrap();
        let t0 = &r.truths[0];
        let rows = [
            (
                r.law.force_constant,
                r.law.intervals[0],
                r.truth_force_constant,
            ),
            (r.law.air_gap_m, r.law.intervals[1], r.truth_air_gap_m),
            (ki.value, ki.interval, t0.k_i),
            (kx.value, kx.interval, t0.k_x),
        ];
        let sds = [r.law.std[0], r.law.std[1], ki.std, kx.std];
        for k in 0..4 {
            z2[k] += ((rows[k].0 - rows[k].2) / sds[k]).powi(2);
        }
        let (mut errs, mut cov) = (String::new(), String::new());
        for (k, &(v, (lo, hi), truth)) in rows.iter().enumerate() {
            let e = v / truth - 1.0;
            worst[k] = worst[k].max(e.abs());
            errors[k].push(e);
            errs += &format!(" {:+.3}", 100.0 * e);
            let c = lo <= truth && truth <= hi;
            covered[k] += usize::from(c);
            cov += if c { "1" } else { "0" };
        }
        let mut single = String::new();
        for (p, tr) in r.points.iter().zip(&r.truths) {
            case_n += 1;
            let z = 1.959964;
            for (k, v, var, truth) in [
                (0, p.k_i, p.cov_ln[0], tr.k_i),
                (1, p.k_x, p.cov_ln[3], tr.k_x),
            ] {
                let c = ((truth / v).ln()).abs() <= z * var.sqrt();
                case_z2[k] += (truth / v).ln().powi(2) / var;
                case_cov[k] += usize::from(c);
                single += if c { "1" } else { "0" };
            }
            // the ratio k_i/k_x (the point's own gap)
            let lr = (p.k_i / p.k_x).ln() - (tr.k_i / tr.k_x).ln();
            case_z2[2] += lr * lr / (p.cov_ln[0] + p.cov_ln[3] - p.cov_ln[1] - p.cov_ln[2]);
            single += " ";
        }
        let chi = r.law.chi2 / r.law.dof as f64;
        chi_over += usize::from(r.law.variance_scale > 1.0);
        println!(
            "{rig} |{errs} | {cov} | {chi:.2} {:.1} | {single}",
            t.elapsed().as_secs_f64()
        );
    }
    println!("runs {runs}; chi2 above its 95 % point (variance inflated) on {chi_over}");
    for k in 0..4 {
        let e = &mut errors[k];
        e.sort_by(f64::total_cmp);
        println!(
            "{:>13}: coverage {:.3}, rms error/std {:.2}, worst |rel. error| {:.3} %, median error {:+.3} %",
            NAMES[k],
            covered[k] as f64 / runs.max(1) as f64,
            (z2[k] / runs.max(1) as f64).sqrt(),
            100.0 * worst[k],
            100.0 * e.get(e.len() / 2).copied().unwrap_or(f64::NAN)
        );
    }
    println!(
        "each case's point over all {case_n} cases: k_i coverage {:.3}, k_x coverage {:.3}; rms error/std k_i {:.2}, k_x {:.2}, k_i/k_x {:.2}",
        case_cov[0] as f64 / case_n.max(1) as f64,
        case_cov[1] as f64 / case_n.max(1) as f64,
        (case_z2[0] / case_n.max(1) as f64).sqrt(),
        (case_z2[1] / case_n.max(1) as f64).sqrt(),
        (case_z2[2] / case_n.max(1) as f64).sqrt()
    );
}
