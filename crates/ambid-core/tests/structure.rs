//! The one model-structure type: names, parsing, serde, and the typed errors where a structure
//! cannot be fitted.

use ambid_core::estimate::pem::{pem, Orders, PemOptions};
use ambid_core::lti::{Frd, PolyModel, Structure};
use ambid_core::validate::compare::{compare_models, CompareSpec};
use faer::c64;

#[test]
fn names_parse_display_and_serde_round_trip() {
    let expect = [
        (Structure::Fir, "fir"),
        (Structure::Arx, "arx"),
        (Structure::Armax, "armax"),
        (Structure::Oe, "oe"),
        (Structure::Bj, "bj"),
        (Structure::General, "general"),
        (Structure::Ss, "ss"),
    ];
    assert_eq!(Structure::ALL.len(), expect.len());
    for (s, name) in expect {
        assert_eq!(s.name(), name);
        assert_eq!(s.to_string(), name);
        assert_eq!(name.parse::<Structure>().unwrap(), s);
        assert_eq!(name.to_uppercase().parse::<Structure>().unwrap(), s);
        assert_eq!(format!("  {name} ").parse::<Structure>().unwrap(), s);
        let json = serde_json::to_string(&s).unwrap();
        assert_eq!(json, format!("\"{name}\""));
        assert_eq!(serde_json::from_str::<Structure>(&json).unwrap(), s);
    }
    for (alias, s) in [
        ("box-jenkins", Structure::Bj),
        ("Box_Jenkins", Structure::Bj),
        ("output-error", Structure::Oe),
        ("state-space", Structure::Ss),
        ("statespace", Structure::Ss),
    ] {
        assert_eq!(alias.parse::<Structure>().unwrap(), s, "{alias}");
    }
    let err = "arma".parse::<Structure>().unwrap_err().to_string();
    assert!(err.contains("unknown model structure `arma`"), "{err}");
    assert!(
        err.contains("fir, arx, armax, oe, bj, general, ss"),
        "{err}"
    );
    assert!(serde_json::from_str::<Structure>("\"n4sid\"").is_err());
}

#[test]
fn frf_fits_support_arx_oe_ss_only() {
    let fits: Vec<Structure> = Structure::ALL
        .into_iter()
        .filter(|s| s.fits_frf())
        .collect();
    assert_eq!(fits, Structure::FRF.to_vec());
    assert_eq!(fits, vec![Structure::Arx, Structure::Oe, Structure::Ss]);
    assert!(Structure::ALL
        .iter()
        .all(|s| s.is_polynomial() == (*s != Structure::Ss)));
    // a comparison asked for BJ is a typed error before any fit runs
    let f: Vec<f64> = (1..=40).map(|k| k as f64 * 10.0).collect();
    let v: Vec<c64> = f
        .iter()
        .map(|&x| c64::new(1.0, 0.0) / c64::new(1.0, x / 100.0))
        .collect();
    let frd = Frd::new(f, v, None, Some(1e-4)).unwrap();
    let spec = CompareSpec {
        structures: vec![Structure::Arx, Structure::Bj],
        orders: vec![2],
        ..CompareSpec::default()
    };
    let err = compare_models(&frd, &spec, None).unwrap_err().to_string();
    assert!(err.contains("arx, oe and ss, not `bj`"), "{err}");
}

#[test]
fn state_space_is_not_a_polynomial_model() {
    let err = PolyModel::new(
        Structure::Ss,
        vec![1.0],
        vec![0.0, 1.0],
        vec![1.0],
        vec![1.0],
        vec![1.0],
        1.0,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("not a polynomial model"), "{err}");
    let u: Vec<f64> = (0..64).map(|k| ((k * 7) % 5) as f64 - 2.0).collect();
    let y: Vec<f64> = u.iter().map(|v| 0.5 * v).collect();
    let err = pem(
        &y,
        &u,
        Structure::Ss,
        &Orders::oe(1, 1, 0),
        1.0,
        &PemOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("ss_pem"), "{err}");
}
