//! `ambid bla`: the robust Best Linear Approximation of the plant on the twin — an amplitude
//! study (noise and nonlinear variance per RMS level and the recommended level) or, with
//! `--level`, the per-line BLA at one level.

use ambid::bla::{amplitude_study, level_figures, run_level, BlaPlan};
use ambid_twin::Mode;
use anyhow::{Context, Result};
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Args)]
pub struct BlaArgs {
    /// RMS levels of the study in % of i_sat (ignored with --level).
    #[arg(long, value_delimiter = ',', default_value = "2,4,8,16,32")]
    levels: Vec<f64>,
    /// One RMS level in % of i_sat: write the per-line BLA (value, std, noise std, NL std).
    #[arg(long)]
    level: Option<f64>,
    /// Random-phase multisine realisations M (≥ 2).
    #[arg(long, default_value_t = 8)]
    realisations: usize,
    /// Analysed periods per realisation P (≥ 2; one more settles the transient).
    #[arg(long, default_value_t = 4)]
    periods: usize,
    /// Twin physics.
    #[arg(long, value_enum, default_value_t = crate::ModeArg::Nonlinear)]
    mode: crate::ModeArg,
    /// Seed of the grid, the phases and the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output CSV.
    #[arg(long, default_value = "bla.csv")]
    out: PathBuf,
}

pub fn bla(a: BlaArgs) -> Result<()> {
    let plan = BlaPlan {
        mode: match a.mode {
            crate::ModeArg::Linear => Mode::Linear,
            crate::ModeArg::Nonlinear => Mode::Nonlinear,
        },
        realisations: a.realisations,
        periods: a.periods,
        seed: a.seed,
        ..BlaPlan::default()
    };
    let mut csv = String::new();
    if let Some(level) = a.level {
        let run = run_level(&plan, level / 100.0)?;
        let g = &run.bla.g;
        csv.push_str("f_hz,bla_re,bla_im,bla_std,noise_std,nl_std,var_nl\n");
        let (st, sn, snl) = (g.std_total(), g.std_noise(), g.std_nl());
        for i in 0..g.f_hz.len() {
            writeln!(
                csv,
                "{},{:e},{:e},{:e},{:e},{:e},{:e}",
                g.f_hz[i], g.values[i].re, g.values[i].im, st[i], sn[i], snl[i], g.var_nl[i]
            )?;
        }
        let f = level_figures(&run, level / 100.0, plan.summary_band_hz)?;
        println!(
            "BLA at {level} % of i_sat RMS, M = {}, P = {}: {} lines; over {:?} Hz noise {:.2e}, NL {:.2e} ± {:.1e} \
             (relative, one realisation); detection lines: even {:.1} dB, odd {:.1} dB over noise; limits active on {:.2} % of samples",
            plan.realisations,
            plan.periods,
            g.f_hz.len(),
            plan.summary_band_hz,
            f.noise_rel,
            f.nl_rel,
            f.nl_rel_se,
            f.even_db,
            f.odd_db,
            100.0 * f.saturated_fraction
        );
    } else {
        let levels: Vec<f64> = a.levels.iter().map(|l| l / 100.0).collect();
        let s = amplitude_study(&plan, &levels)?;
        csv.push_str(
            "level_pct,lines,noise_rel,nl_rel,nl_rel_se,sum_rel,even_db,odd_db,bla_vs_linear_rel,saturated_fraction,recommended\n",
        );
        for r in &s.rows {
            writeln!(
                csv,
                "{},{},{:e},{:e},{:e},{:e},{:.2},{:.2},{:e},{:e},{}",
                r.level_pct,
                r.lines,
                r.noise_rel,
                r.nl_rel,
                r.nl_rel_se,
                r.sum_rel,
                r.even_db,
                r.odd_db,
                r.bla_vs_linear_rel,
                r.saturated_fraction,
                u8::from(r.level_pct == s.recommended_pct)
            )?;
            println!(
                "{:5.1} %: noise {:.2e}, NL {:.2e} ± {:.1e}, sum {:.2e}, even {:.1} dB, odd {:.1} dB",
                r.level_pct, r.noise_rel, r.nl_rel, r.nl_rel_se, r.sum_rel, r.even_db, r.odd_db
            );
        }
        println!("recommended {:.1} %: {}", s.recommended_pct, s.reasoning);
    }
    std::fs::write(&a.out, csv).with_context(|| format!("writing {}", a.out.display()))?;
    println!("wrote {}", a.out.display());
    Ok(())
}
