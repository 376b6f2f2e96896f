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
            r.bla_vs_linear_rel.unwrap_or(f64::NAN),
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

/// `ambid bla`: the study CSV (one row per level, one recommended) and the per-line CSV.
#[test]
fn cli_writes_the_study_and_the_lines() {
    let dir = std::env::temp_dir().join(format!("ambid-bla-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let exe = env!("CARGO_BIN_EXE_ambid");
    let study = dir.join("bla.csv");
    let out = std::process::Command::new(exe)
        .args([
            "bla",
            "--levels",
            "4,16",
            "--realisations",
            "3",
            "--periods",
            "2",
            "--out",
        ])
        .arg(&study)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&study).unwrap();
    let rows: Vec<&str> = text.lines().collect();
    assert!(rows[0].starts_with("level_pct,realisations,periods,lines,noise_rel,nl_rel"));
    assert_eq!(rows.len(), 3);
    assert_eq!(rows[1..].iter().filter(|r| r.ends_with(",1")).count(), 1);
    let lines = dir.join("lines.csv");
    let out = std::process::Command::new(exe)
        .args([
            "bla",
            "--level",
            "10",
            "--realisations",
            "3",
            "--periods",
            "2",
            "--mode",
            "linear",
            "--out",
        ])
        .arg(&lines)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&lines).unwrap();
    assert!(text.starts_with("f_hz,bla_re,bla_im,bla_std,noise_std,nl_std,var_nl\n"));
    assert!(text.lines().count() > 20);
    // M = 1 is refused with a clear message
    let out = std::process::Command::new(exe)
        .args([
            "bla",
            "--level",
            "10",
            "--realisations",
            "1",
            "--force",
            "--out",
        ])
        .arg(&lines)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("at least 2"));
    std::fs::remove_dir_all(&dir).ok();
}
