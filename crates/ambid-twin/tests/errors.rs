//! Bad input gives typed errors with helpful text; nothing panics.

use ambid_twin::{Mode, SimOptions, Twin, TwinConfig, TwinError};

#[test]
fn unstable_config_is_rejected_with_hint() {
    let mut cfg = TwinConfig::default();
    cfg.controller.kp = 3000.0; // k_i·K_p = 1.7e5 N/m < k_x = 2.9e5 N/m
    let err = Twin::new(cfg).unwrap_err();
    eprintln!("{err}");
    match &err {
        TwinError::UnstableClosedLoop {
            max_pole_magnitude, ..
        } => assert!(*max_pole_magnitude > 1.0),
        other => panic!("wrong error {other:?}"),
    }
    let msg = err.to_string();
    assert!(msg.contains("largest closed-loop pole magnitude"));
    assert!(msg.contains("raise controller.kp"));
}

#[test]
fn malformed_toml_and_unknown_fields() {
    let e = TwinConfig::from_toml_str("[magnet]\nturns = \"many\"\n").unwrap_err();
    assert!(matches!(e, TwinError::Toml(_)), "{e}");
    let e = TwinConfig::from_toml_str("[controler]\nkp = 1.0\n").unwrap_err();
    assert!(e.to_string().contains("controler"), "{e}");
    let e = TwinConfig::from_toml_str("[sensor]\nnoise_rms = 1e-7\n").unwrap_err();
    assert!(e.to_string().contains("noise_rms"), "{e}");
    eprintln!("{e}");
}

#[test]
fn negative_gap_and_other_bad_values() {
    let mut cfg = TwinConfig::default();
    cfg.operating_point.air_gap_m = -0.4e-3;
    let e = Twin::new(cfg).unwrap_err();
    assert!(matches!(e, TwinError::Config { .. }));
    assert!(e.to_string().contains("operating_point.air_gap_m"), "{e}");
    let mut cfg = TwinConfig::default();
    cfg.rotor.mass_kg = f64::NAN;
    assert!(Twin::new(cfg)
        .unwrap_err()
        .to_string()
        .contains("rotor.mass_kg"));
    let mut cfg = TwinConfig::default();
    cfg.operating_point.bias_current_a = 0.0;
    assert!(Twin::new(cfg).is_err());
    let mut cfg = TwinConfig::default();
    cfg.magnet.i_sat_a = -1.0;
    assert!(Twin::new(cfg).is_err());
    let mut cfg = TwinConfig::default();
    cfg.controller.fs_hz = 0.0;
    assert!(Twin::new(cfg).is_err());
    let mut cfg = TwinConfig::default();
    cfg.simulation.substeps = 5;
    assert!(Twin::new(cfg).unwrap_err().to_string().contains("substeps"));
}

#[test]
fn bad_signals() {
    let twin = Twin::new(TwinConfig::default()).unwrap();
    let mut r = vec![0.01; 100];
    r[42] = f64::NAN;
    let e = twin.simulate(&r, &SimOptions::default()).unwrap_err();
    assert_eq!(
        e,
        TwinError::NonFinite {
            what: "r",
            index: 42
        }
    );
    assert!(e.to_string().contains("index 42"));
    let r = vec![0.01; 100];
    let e = twin
        .simulate(
            &r,
            &SimOptions {
                w: Some(vec![0.0; 99]),
                ..Default::default()
            },
        )
        .unwrap_err();
    assert!(matches!(
        e,
        TwinError::LengthMismatch {
            what: "w",
            expected: 100,
            got: 99
        }
    ));
    eprintln!("{e}");
    let mut w = vec![0.0; 100];
    w[7] = f64::INFINITY;
    let e = twin
        .simulate(
            &r,
            &SimOptions {
                w: Some(w),
                ..Default::default()
            },
        )
        .unwrap_err();
    assert_eq!(
        e,
        TwinError::NonFinite {
            what: "w",
            index: 7
        }
    );
    assert!(twin.simulate(&[], &SimOptions::default()).is_err());
    assert!(twin.plant_frf(&[f64::NAN]).is_err());
}

#[test]
fn reference_step_is_followed_and_large_reference_touches_down() {
    let twin = Twin::new(TwinConfig::default()).unwrap();
    let n = 4000;
    let w = vec![20e-6; n];
    let rec = twin
        .simulate(
            &vec![0.0; n],
            &SimOptions {
                mode: Mode::Nonlinear,
                noise: false,
                w: Some(w),
                ..Default::default()
            },
        )
        .unwrap();
    // integral action: y → w
    assert!((rec.y[n - 1] - 20e-6).abs() < 0.5e-6, "{}", rec.y[n - 1]);
    let e = twin
        .simulate(
            &vec![0.0; n],
            &SimOptions {
                mode: Mode::Nonlinear,
                noise: false,
                w: Some(vec![0.45e-3; n]),
                ..Default::default()
            },
        )
        .unwrap_err();
    eprintln!("{e}");
    assert!(matches!(
        e,
        TwinError::Touchdown { .. } | TwinError::Diverged { .. }
    ));
}
