//! The data-driven count of the plant's unstable poles (`validate::nyquist`) on the 4-axis twin's
//! measured 4×4 FRF, against the exact linearised plant's poles: the nominal rig at 0, 15 000
//! and 30 000 rpm, and random rigs 1–5 (`random_rig(seed)` lifted to four axes, at
//! `(7919·seed) mod 30 000` rpm, with the seed's own noise), the `[machine]` defaults
//! (orthogonal PRBS design, 12 periods, linear twin, default sensor noise).

use crate::common;
use ambid::config::MachineSection;
use ambid::workflow::machine::acquire_twin;
use ambid_core::lti::Frd;
use ambid_core::validate::nyquist::loop_unstable_poles;
use std::path::Path;

fn check(m: &MachineSection, seed: u64, what: &str) {
    let data = acquire_twin(m, Path::new("."), seed).unwrap();
    let truth = data.truth.as_ref().unwrap();
    for (s, t) in data.speeds.iter().zip(truth) {
        let want = t
            .plant
            .poles()
            .unwrap()
            .iter()
            .filter(|z| z.norm() >= 1.0)
            .count();
        let measured = loop_unstable_poles(&s.frf.plant, &t.controller).unwrap();
        let exact = loop_unstable_poles(
            &Frd::from_model(&t.plant, s.frf.plant.f_hz()).unwrap(),
            &t.controller,
        )
        .unwrap();
        eprintln!(
            "{what} at {} rpm: truth {want}, measured {:?} (raw {:.3}, max step {:.1} deg, {} lines, q {}), exact on the lines {:?} (raw {:.3})",
            t.speed_rpm,
            measured.unstable_poles,
            measured.raw,
            measured.max_step_deg,
            measured.lines,
            measured.integrators,
            exact.unstable_poles,
            exact.raw
        );
        assert_eq!(exact.unstable_poles, Some(want), "{what}: {exact:?}");
        assert_eq!(measured.unstable_poles, Some(want), "{what}: {measured:?}");
    }
}

#[test]
fn the_count_from_the_measured_loop_is_the_plants_on_the_nominal_rig() {
    let m = MachineSection {
        speeds_rpm: Some(vec![0.0, 15_000.0, 30_000.0]),
        mode: "linear".into(),
        ..Default::default()
    };
    check(&m, 1, "nominal, seed 1");
}

#[test]
fn the_count_from_the_measured_loop_is_the_plants_on_random_rigs() {
    let dir = common::tmpdir("machine-nyquist");
    for seed in 1u64..=5 {
        check(
            &common::random_machine_rig(&dir, seed),
            seed,
            &format!("random rig {seed}"),
        );
    }
}
