//! Robust BLA on the twin: on the nonlinear twin the stochastic NL variance rises with the
//! excitation level; on the linear twin it is statistically zero.

use ambid::bla::{amplitude_study, BlaPlan};
use ambid_twin::Mode;

fn plan(mode: Mode) -> BlaPlan {
    BlaPlan {
        mode,
        realisations: 8,
        periods: 4,
        ..BlaPlan::default()
    }
}

fn print(study: &ambid::bla::BlaStudy, name: &str) {
    println!("{name}: level %, noise_rel, nl_rel ± se, even dB, odd dB, BLA vs linear, saturated");
    for r in &study.rows {
        println!(
            "  {:5.1} {:.3e} {:.3e} ± {:.1e} {:6.1} {:6.1} {:.3} {:.4}",
            r.level_pct,
            r.noise_rel,
            r.nl_rel,
            r.nl_rel_se,
            r.even_db,
            r.odd_db,
            r.bla_vs_linear_rel,
            r.saturated_fraction
        );
    }
    println!(
        "  recommended {:.1} %: {}",
        study.recommended_pct, study.reasoning
    );
}

#[test]
fn nl_variance_rises_with_level_on_the_nonlinear_twin() {
    let levels = [0.04, 0.08, 0.16, 0.32];
    let s = amplitude_study(&plan(Mode::Nonlinear), &levels).unwrap();
    print(&s, "nonlinear twin");
    let nl: Vec<f64> = s.rows.iter().map(|r| r.nl_rel).collect();
    // the low levels are statistically zero; the NL variance then rises clearly
    for r in &s.rows[..2] {
        assert!(r.nl_rel < 3.0 * r.nl_rel_se, "{nl:?}");
    }
    assert!(nl[3] > nl[2] && nl[3] > nl[1] && nl[3] > nl[0], "{nl:?}");
    let top = &s.rows[3];
    assert!(
        top.nl_rel > 3.0 * top.nl_rel_se,
        "NL not significant at 32 %"
    );
    assert!(
        top.odd_db > 10.0,
        "odd detection lines at 32 %: {} dB",
        top.odd_db
    );
    // noise share falls with the level (∝ 1/level²)
    assert!(s.rows[0].noise_rel > 10.0 * s.rows[2].noise_rel);
    assert!(levels
        .iter()
        .any(|l| (100.0 * l - s.recommended_pct).abs() < 1e-9));
}

#[test]
fn nl_variance_is_zero_on_the_linear_twin() {
    let s = amplitude_study(&plan(Mode::Linear), &[0.04, 0.16, 0.32]).unwrap();
    print(&s, "linear twin");
    for r in &s.rows {
        assert!(
            r.nl_rel.abs() < 3.0 * r.nl_rel_se,
            "level {}: {} ± {}",
            r.level_pct,
            r.nl_rel,
            r.nl_rel_se
        );
        // below the current limits the detection lines hold noise only; at 32 % RMS the peaks of
        // a random-phase multisine reach the limits and odd distortion appears even here
        if r.level_pct < 20.0 {
            assert!(r.even_db.abs() < 3.0 && r.odd_db.abs() < 3.0);
            assert_eq!(r.saturated_fraction, 0.0);
        }
    }
}
