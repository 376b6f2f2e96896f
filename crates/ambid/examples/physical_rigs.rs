//! The gray-box physical parameters on rigs of the twin (issue 23): per rig and noise seed the
//! estimate against the twin's linearisation, the relative errors and whether each 95 %
//! interval covers the truth; at the end the coverage per parameter.
//!
//! `cargo run --release -p ambid --example physical_rigs -- RIGS SEEDS [linear|nonlinear] [LEVELS]`
//! (e.g. `0 1-50`; rig 0 is the nominal twin; SEEDS `rig` runs each rig once with its own number
//! as the noise seed, so that no two runs share a noise realisation). With LEVELS (fractions of
//! i_sat, e.g. `0.10,0.14`) each run estimates at every level (`ExtrapolatedRun`) and the
//! table is that of the extrapolation to zero amplitude; the last lines also give the coverage
//! of the first level's own estimate.

use ambid::physical::{as_array, ExtrapolatedRun, PhysicalRun, PARAMETER_NAMES};
use ambid_twin::Mode;

mod common;
use common::range;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs = range(args.get(1).map_or("0", String::as_str));
    let seed_arg = args.get(2).map_or("1-5", String::as_str);
    let paired = seed_arg == "rig";
    let seeds = if paired { vec![0] } else { range(seed_arg) };
    let mode = match args.get(3).map(String::as_str) {
        Some("nonlinear") => Mode::Nonlinear,
        _ => Mode::Linear,
    };
    let levels: Option<Vec<f64>> = args
        .get(4)
        .map(|s| s.split(',').map(|x| x.parse().unwrap()).collect());
    let mut covered = [0usize; 6];
    let mut covered_first = [0usize; 6];
    let mut worst_first = [0.0f64; 6];
    let mut worst = [0.0f64; 6];
    let mut runs = 0;
    println!(
        "rig seed | rel. error % (k_i k_x f_b zeta_b phi_A phi_B) | covered | chi2/dof iters s"
    );
    for &rig in &rigs {
        for &seed in &seeds {
            let seed = if paired { rig } else { seed };
            let t = std::time::Instant::now();
            let (est, intervals, truth, first, chi) = if let Some(levels) = &levels {
                let r = match ExtrapolatedRun::on_twin(rig, seed, mode, levels) {
                    Ok(r) => r,
                    Err(e) => {
                        println!("{rig} {seed}: {e}");
                        continue;
                    }
                };
                let f = &r.at_levels[0].1;
                (
                    r.zero.params_array(),
                    r.zero.intervals,
                    as_array(&r.truth),
                    Some((as_array(&f.params), f.intervals)),
                    (r.zero.chi2[1], r.zero.dof, 0),
                )
            } else {
                let r = match PhysicalRun::on_twin(rig, seed, mode) {
                    Ok(r) => r,
                    Err(e) => {
                        println!("{rig} {seed}: {e}");
                        continue;
                    }
                };
                (
                    as_array(&r.fit.params),
                    r.fit.intervals,
                    r.truth_array(),
                    None,
                    (r.fit.chi2, r.fit.dof, r.fit.iterations),
                )
            };
            runs += 1;
            if let Some((fe, fi)) = first {
                for k in 0..6 {
                    worst_first[k] = worst_first[k].max(((fe[k] - truth[k]) / truth[k]).abs());
                    covered_first[k] += usize::from(fi[k].0 <= truth[k] && truth[k] <= fi[k].1);
                }
            }
            let mut errs = String::new();
            let mut cov = String::new();
            for k in 0..6 {
                let e = (est[k] - truth[k]) / truth[k];
                worst[k] = worst[k].max(e.abs());
                errs += &format!(" {:+.3}", 100.0 * e);
                let (lo, hi) = intervals[k];
                let c = lo <= truth[k] && truth[k] <= hi;
                covered[k] += usize::from(c);
                cov += if c { "1" } else { "0" };
            }
            println!(
                "{rig} {seed} |{errs} | {cov} | {:.3} {} {:.1}",
                chi.0 / chi.1.max(1) as f64,
                chi.2,
                t.elapsed().as_secs_f64()
            );
        }
    }
    println!("runs {runs}");
    for k in 0..6 {
        println!(
            "{:>16}: coverage {:.3}, worst |rel. error| {:.3} %",
            PARAMETER_NAMES[k],
            covered[k] as f64 / runs.max(1) as f64,
            100.0 * worst[k]
        );
    }
    if levels.is_some() {
        for k in 0..6 {
            println!(
                "{:>16}: first level alone: coverage {:.3}, worst |rel. error| {:.3} %",
                PARAMETER_NAMES[k],
                covered_first[k] as f64 / runs.max(1) as f64,
                100.0 * worst_first[k]
            );
        }
    }
}
