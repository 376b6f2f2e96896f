//! The magnet law of every axis from the whole machine at three operating points (issue 23):
//! per machine rig ([`MachineOperatingRun`]) at the speed (7919 r) mod 30 000 rpm, nominal,
//! bias −20 % and gap +10 µm (noise seeds 5000 + 10 r + case), the 4×4 gray box at each and one
//! law per axis; the errors of each axis' magnet constant and gap against the twin and whether
//! each 95 % interval covers, and the coverage over all axes and rigs at the end.
//!
//! `cargo run --release -p ambid --example physical_machine_operating_rigs -- RIGS [linear|nonlinear] [scaled]`
//! (RIGS `1-50` or `3,7`; `scaled` keeps the rigs' magnets with k_x factors other than their
//! k_i factors, whose gaps the twin scales: see `MachineOperatingRun`).

use ambid::physical::operating::MachineOperatingRun;
use ambid_twin::Mode;

mod common;
use common::range;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rigs = range(args.get(1).map_or("1-5", String::as_str));
    let mode = match args.get(2).map(String::as_str) {
        Some("nonlinear") => Mode::Nonlinear,
        _ => Mode::Linear,
    };
    let same_gap = args.get(3).map(String::as_str) != Some("scaled");
    let (mut covered, mut worst, mut n, mut rejected, mut z2) =
        ([0usize; 2], [0.0f64; 2], 0, 0, [0.0f64; 2]);
    println!("rig rpm | per axis: k error %, g0 error % | covered (k g0 per axis) | chi2/dof per axis | s");
    for &rig in &rigs {
        let t = std::time::Instant::now();
        let speed = ((7919 * rig) % 30_000) as f64;
        let r = match MachineOperatingRun::on_twin(rig, 5000 + 10 * rig, speed, mode, same_gap) {
            Ok(r) => r,
            Err(e) => {
                println!("{rig} {speed}: {e}");
                continue;
            }
        };
        let (mut errs, mut cov, mut chi) = (String::new(), String::new(), String::new());
        for (law, &(k, g)) in r.laws.iter().zip(&r.truth) {
            n += 1;
            rejected += usize::from(law.variance_scale > 1.0);
            for (q, (v, truth)) in [(law.force_constant, k), (law.air_gap_m, g)]
                .into_iter()
                .enumerate()
            {
                let e = v / truth - 1.0;
                worst[q] = worst[q].max(e.abs());
                z2[q] += ((v - truth) / law.std[q]).powi(2);
                let (lo, hi) = law.intervals[q];
                let c = lo <= truth && truth <= hi;
                covered[q] += usize::from(c);
                cov += if c { "1" } else { "0" };
                errs += &format!(" {:+.3}", 100.0 * e);
            }
            cov += " ";
            chi += &format!(" {:.2}", law.chi2 / law.dof as f64);
        }
        println!(
            "{rig} {speed} |{errs} | {cov}|{chi} | {:.1}",
            t.elapsed().as_secs_f64()
        );
    }
    println!("axes {n} (4 per rig); law rejected on {rejected}");
    for (q, name) in ["k", "g0"].iter().enumerate() {
        println!(
            "{name:>3}: coverage {:.3}, rms error/std {:.2}, worst |rel. error| {:.3} %",
            covered[q] as f64 / n.max(1) as f64,
            (z2[q] / n.max(1) as f64).sqrt(),
            100.0 * worst[q]
        );
    }
}
