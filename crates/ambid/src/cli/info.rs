//! `ambid info`: the twin's linearised facts.

use super::common::{twin_config, TwinArgs};
use anyhow::Result;

/// Prints the closed-loop modes, peak sensitivity and unstable plant poles of the twin.
pub fn info(a: TwinArgs) -> Result<()> {
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
