//! Hostile configurations never panic: every numeric setting replaced by zero, a negative, a huge
//! or a tiny value gives either a working twin or a typed error, and a short simulation of any
//! twin that builds either runs or fails with a typed error.

use ambid_twin::{Mode, SimOptions, Twin, TwinConfig};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

/// Paths (section, key) of every numeric field of the default configuration.
fn numeric_fields() -> Vec<(String, String)> {
    let v: toml::Value = toml::from_str(&TwinConfig::default().to_toml_string().unwrap()).unwrap();
    let mut out = Vec::new();
    for (sec, tab) in v.as_table().unwrap() {
        for (key, val) in tab.as_table().unwrap() {
            if val.is_float() || val.is_integer() {
                out.push((sec.clone(), key.clone()));
            }
        }
    }
    out
}

fn with_value(sec: &str, key: &str, value: f64) -> String {
    let mut v: toml::Value =
        toml::from_str(&TwinConfig::default().to_toml_string().unwrap()).unwrap();
    let tab = v.get_mut(sec).unwrap().as_table_mut().unwrap();
    let old = tab.get(key).unwrap().clone();
    tab.insert(
        key.to_string(),
        if old.is_integer() {
            toml::Value::Integer(value.clamp(-1e15, 1e15) as i64)
        } else {
            toml::Value::Float(value)
        },
    );
    toml::to_string(&v).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 96,
        failure_persistence: None,
        rng_seed: RngSeed::Fixed(0x0A3B_2026),
        ..ProptestConfig::default()
    })]
    #[test]
    fn hostile_settings_give_a_twin_or_a_typed_error(
        field in 0usize..64,
        value in prop_oneof![
            Just(0.0), Just(-1.0), Just(1e-30), Just(1e30), Just(f64::MAX), Just(-f64::MAX),
            -1e6f64..1e6,
        ],
    ) {
        let fields = numeric_fields();
        let (sec, key) = &fields[field % fields.len()];
        let text = with_value(sec, key, value);
        if let Ok(cfg) = TwinConfig::from_toml_str(&text) {
            if let Ok(twin) = Twin::new(cfg) {
                let r = vec![0.01; 200];
                for mode in [Mode::Linear, Mode::Nonlinear] {
                    let _ = twin.simulate(&r, &SimOptions { mode, ..Default::default() });
                }
                let _ = twin.t_ry_frf(&[1.0, 97.0, 780.0, 9000.0]);
                let _ = twin.plant_unstable_poles();
            }
        }
    }
}

#[test]
fn every_numeric_field_is_exercised() {
    // guards the test above against a silently shrinking field list
    assert!(numeric_fields().len() >= 30, "{}", numeric_fields().len());
}
