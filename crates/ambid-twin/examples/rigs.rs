//! Prints the random rigs of `ambid_twin::rig` for seeds 0..N: peak sensitivity, closed-loop
//! modes and the unstable plant pole (`cargo run -p ambid-twin --example rigs -- 20`).
fn main() {
    let n: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    for seed in 0..n {
        let cfg = ambid_twin::random_rig(seed).expect("rig");
        let twin = ambid_twin::Twin::new(cfg.clone()).expect("twin");
        let (f, s) = twin.peak_sensitivity().expect("peak");
        let modes: Vec<String> = twin
            .closed_loop_modes()
            .iter()
            .map(|m| format!("{:.0}Hz/{:.3}", m.freq_hz, m.damping))
            .collect();
        let up: Vec<String> = twin
            .plant_unstable_poles()
            .expect("poles")
            .iter()
            .map(|z| format!("{:.1}", twin.pole_to_s(*z).re))
            .collect();
        println!(
            "seed {seed:2}: m {:.2} kg kp {:.0} kd {:.1} |S| {s:.2} at {f:.0} Hz, modes {}, unstable s {}",
            cfg.rotor.mass_kg,
            cfg.controller.kp,
            cfg.controller.kd,
            modes.join(" "),
            up.join(",")
        );
    }
}
