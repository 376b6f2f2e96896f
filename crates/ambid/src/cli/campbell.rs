//! `ambid campbell`: the 4-axis twin's true closed-loop modes against rotor speed (Campbell
//! diagram), written as CSV (docs/formats.md, "Campbell diagram").

use ambid::io::output::write_file;
use ambid_twin::{CampbellPoint, MachineConfig, Whirl};
use anyhow::{Context, Result};
use clap::Args;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct CampbellArgs {
    /// Machine configuration (TOML, a `MachineConfig`); defaults to the nominal 4-axis rig.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Rotor speeds in rpm: `START:STOP:COUNT` (COUNT equally spaced speeds, both ends
    /// included) or a comma-separated list `0,10000,20000`.
    #[arg(long, default_value = "0:30000:7")]
    pub speeds: String,
    /// Highest natural frequency of the modes listed \[Hz\].
    #[arg(long, default_value_t = 1000.0, allow_negative_numbers = true)]
    pub f_max: f64,
    /// Output CSV: `speed_rpm,sync_hz,mode,freq_hz,damping,whirl`.
    #[arg(long)]
    pub out: PathBuf,
    /// Replace the output file if it exists.
    #[arg(long)]
    pub force: bool,
}

/// Reads a `MachineConfig` TOML, or the default machine.
pub fn machine_config(path: Option<&Path>) -> Result<MachineConfig> {
    let cfg = match path {
        Some(p) => {
            let s = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            MachineConfig::from_toml_str(&s).with_context(|| format!("in {}", p.display()))?
        }
        None => MachineConfig::default(),
    };
    cfg.validate()?;
    Ok(cfg)
}

/// Parses `--speeds`: `START:STOP:COUNT` or a comma-separated list; every speed finite and
/// non-negative, at least one.
pub fn parse_speeds(s: &str) -> Result<Vec<f64>, ambid::error::Error> {
    let bad = |why: String| {
        ambid::error::Error::usage(format!(
            "--speeds {s:?}: {why}; give START:STOP:COUNT (e.g. 0:30000:7) or a list (e.g. 0,10000,20000) of speeds in rpm, each finite and >= 0"
        ))
    };
    let num = |t: &str| -> Result<f64, ambid::error::Error> {
        t.trim()
            .parse::<f64>()
            .map_err(|_| bad(format!("{:?} is not a number", t.trim())))
    };
    let speeds: Vec<f64> = if s.contains(':') {
        let parts: Vec<&str> = s.split(':').collect();
        if parts.len() != 3 {
            return Err(bad("a range has three parts START:STOP:COUNT".into()));
        }
        let (a, b) = (num(parts[0])?, num(parts[1])?);
        let n: usize = parts[2]
            .trim()
            .parse()
            .map_err(|_| bad(format!("COUNT {:?} is not a whole number", parts[2].trim())))?;
        if n == 0 {
            return Err(bad("the range is empty (COUNT is 0)".into()));
        }
        if !(a.is_finite() && b.is_finite()) {
            return Err(bad("START and STOP must be finite".into()));
        }
        if n == 1 {
            if a != b {
                return Err(bad("COUNT 1 needs START = STOP".into()));
            }
            vec![a]
        } else {
            if b < a {
                return Err(bad(format!("the range is empty (STOP {b} < START {a})")));
            }
            (0..n)
                .map(|k| a + (b - a) * k as f64 / (n - 1) as f64)
                .collect()
        }
    } else {
        s.split(',')
            .filter(|t| !t.trim().is_empty())
            .map(num)
            .collect::<Result<_, _>>()?
    };
    if speeds.is_empty() {
        return Err(bad("no speeds given".into()));
    }
    if let Some(v) = speeds.iter().find(|v| !v.is_finite()) {
        return Err(bad(format!("speed {v} is not finite")));
    }
    if let Some(v) = speeds.iter().find(|v| **v < 0.0) {
        return Err(bad(format!("speed {v} is negative")));
    }
    Ok(speeds)
}

fn whirl_name(w: Whirl) -> &'static str {
    match w {
        Whirl::Forward => "forward",
        Whirl::Backward => "backward",
        Whirl::None => "none",
    }
}

/// The CSV text of a Campbell diagram (one row per mode and speed; 10 significant digits).
pub fn campbell_csv(points: &[CampbellPoint]) -> String {
    let mut out = String::from("speed_rpm,sync_hz,mode,freq_hz,damping,whirl\n");
    for p in points {
        for (k, m) in p.modes.iter().enumerate() {
            let _ = writeln!(
                out,
                "{},{:.9e},{},{:.9e},{:.9e},{}",
                p.speed_rpm,
                p.sync_hz,
                k,
                m.freq_hz,
                m.damping,
                whirl_name(m.whirl)
            );
        }
    }
    out
}

/// The forward/backward pair of the tilt modes at one speed: the second pair by frequency
/// (modes 2 and 3; the first pair is the translation, the third the bending mode).
fn tilt_pair(p: &CampbellPoint) -> String {
    let pair = match p.modes.get(2..4) {
        Some(pair) => pair,
        None => return "tilt pair not found below --f-max".into(),
    };
    let find = |w: Whirl| pair.iter().find(|m| m.whirl == w).map(|m| m.freq_hz);
    match (find(Whirl::Forward), find(Whirl::Backward)) {
        (Some(f), Some(b)) => format!("tilt forward {f:.1} Hz, backward {b:.1} Hz"),
        _ if pair.iter().all(|m| m.whirl == Whirl::None) => format!(
            "tilt {:.1} Hz twice (no whirl at standstill)",
            pair[0].freq_hz
        ),
        _ => format!(
            "tilt {:.1} Hz ({}), {:.1} Hz ({})",
            pair[0].freq_hz,
            whirl_name(pair[0].whirl),
            pair[1].freq_hz,
            whirl_name(pair[1].whirl)
        ),
    }
}

/// Runs `ambid campbell`.
pub fn campbell(a: CampbellArgs) -> Result<()> {
    let speeds = parse_speeds(&a.speeds)?;
    if !(a.f_max.is_finite() && a.f_max > 0.0) {
        return Err(ambid::error::Error::usage(format!(
            "--f-max {} must be a positive, finite frequency in Hz (e.g. --f-max 1000)",
            a.f_max
        ))
        .into());
    }
    let cfg = machine_config(a.config.as_deref())?;
    ambid::io::output::OutputSet::check(&a.out, a.force)?;
    let points = ambid_twin::campbell(&cfg, &speeds, a.f_max)?;
    write_file(&a.out, campbell_csv(&points).as_bytes(), a.force)?;
    println!(
        "Campbell diagram: {} speeds, modes up to {} Hz",
        points.len(),
        a.f_max
    );
    for p in &points {
        println!(
            "  {:8.0} rpm  1x {:7.1} Hz  {} modes  {}",
            p.speed_rpm,
            p.sync_hz,
            p.modes.len(),
            tilt_pair(p)
        );
    }
    println!("wrote {}", a.out.display());
    Ok(())
}
