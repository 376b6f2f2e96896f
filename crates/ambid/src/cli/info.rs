//! `ambid info`: the twin's linearised facts (the single-plane twin, or with `--axes 4` the
//! whole rotor, `ambid_twin::Machine`).

use super::campbell::machine_config;
use super::common::{twin_config, TwinArgs};
use ambid_twin::{Machine, Whirl, AXES};
use anyhow::Result;
use clap::Args;

#[derive(Args)]
pub struct InfoArgs {
    #[command(flatten)]
    pub twin: TwinArgs,
    /// 1: the single-plane twin (default); 4: the whole rotor (both planes, gyroscopic coupling
    /// at speed); then `--config` is a machine configuration (`MachineConfig` TOML).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=4))]
    pub axes: u8,
    /// Rotor speed in rpm (with `--axes 4`; overrides the configuration's `speed_rpm`).
    #[arg(long, allow_negative_numbers = true)]
    pub speed_rpm: Option<f64>,
}

/// Runs `ambid info`: the single-plane twin's facts, or with `--axes 4` the whole rotor's.
pub fn info(a: InfoArgs) -> Result<()> {
    match a.axes {
        4 => return info_machine(&a),
        1 => {}
        n => {
            return Err(ambid::error::Error::usage(format!(
                "--axes {n}: give 1 (the single-plane twin) or 4 (the whole rotor)"
            ))
            .into())
        }
    }
    if a.speed_rpm.is_some() {
        return Err(ambid::error::Error::usage(
            "--speed-rpm needs --axes 4 (the single-plane twin does not rotate)",
        )
        .into());
    }
    info_plane(a.twin)
}

/// Prints the closed-loop modes, peak sensitivity and unstable plant poles of the twin.
fn info_plane(a: TwinArgs) -> Result<()> {
    let twin = ambid_twin::Twin::new(twin_config(&a)?)?;
    let lp = twin.linear_params();
    println!(
        "linearised magnet: k_i = {:.2} N/A, k_x = {:.4e} N/m",
        lp.k_i, lp.k_x
    );
    println!("closed-loop modes (lightly damped pole pairs):");
    for m in twin.closed_loop_modes() {
        println!("  {:8.1} Hz   damping {:.3}", m.freq_hz, m.damping);
    }
    let (f, s) = twin.peak_sensitivity()?;
    println!("peak sensitivity |S| = {s:.3} at {f:.1} Hz");
    println!("unstable poles of the assembled plant P (z; s = ln z / Ts):");
    for z in twin.plant_unstable_poles()? {
        let s = twin.pole_to_s(z);
        println!(
            "  z = {:.6}{:+.6}j   s = {:.2}{:+.2}j rad/s",
            z.re, z.im, s.re, s.im
        );
    }
    let pred = twin.predicted_unstable_pole();
    println!(
        "physics prediction ({} unstable pole): rigid rotor with loop B as a spring k_B = {:.4e} N/m: \
         s = +{:.2} rad/s; rotor pinned at B (lower bound): s = +{:.2} rad/s",
        pred.count, pred.bearing_b_stiffness_n_per_m, pred.rigid_spring_b_rad_s, pred.pinned_at_b_rad_s
    );
    Ok(())
}

fn whirl_name(w: Whirl) -> &'static str {
    match w {
        Whirl::Forward => "forward",
        Whirl::Backward => "backward",
        Whirl::None => "none",
    }
}

/// Prints the whole rotor's facts: speed, inertias, closed-loop modes with whirl, peak |S| per
/// axis, unstable plant poles (all loops open) and the 1× frequency.
fn info_machine(a: &InfoArgs) -> Result<()> {
    if a.twin.rig.rig_seed.is_some() {
        return Err(ambid::error::Error::usage(
            "--rig-seed is not available with --axes 4: pass a machine configuration with --config",
        )
        .into());
    }
    let mut cfg = machine_config(a.twin.config.as_deref())?;
    if let Some(v) = a.speed_rpm {
        if !(v.is_finite() && v >= 0.0) {
            return Err(ambid::error::Error::usage(format!(
                "--speed-rpm {v} must be finite and >= 0 (e.g. --speed-rpm 30000)"
            ))
            .into());
        }
        cfg.speed_rpm = v;
    }
    if let Some(b) = a.twin.bias {
        cfg.operating_point.bias_current_a = b;
    }
    if let Some(g) = a.twin.gap {
        cfg.operating_point.air_gap_m = g;
    }
    cfg.validate()?;
    let m = Machine::new(cfg)?;
    let c = m.config();
    println!(
        "whole rotor (4 axes): speed {} rpm, 1x frequency {:.3} Hz",
        c.speed_rpm,
        m.sync_hz()
    );
    println!(
        "inertia: polar J_p = {:.4e} kg m^2, transverse J_t = {:.4e} kg m^2 (J_p/J_t = {:.4})",
        c.polar_inertia(),
        c.rotor.inertia(),
        c.polar_inertia() / c.rotor.inertia()
    );
    println!("closed-loop modes (lightly damped pole pairs):");
    for md in m.closed_loop_modes()? {
        println!(
            "  {:8.1} Hz   damping {:.3}   whirl {}",
            md.freq_hz,
            md.damping,
            whirl_name(md.whirl)
        );
    }
    println!("peak sensitivity |S_ii| per axis:");
    for (axis, (f, s)) in AXES.iter().zip(m.peak_sensitivity()?) {
        println!("  {axis}: {s:.3} at {f:.1} Hz");
    }
    let unstable = m.plant().poles()?.iter().filter(|z| z.norm() > 1.0).count();
    println!("unstable poles of the plant P (all four loops open): {unstable}");
    Ok(())
}
