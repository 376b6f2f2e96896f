//! `ambid campbell` and `ambid info --axes 4` end to end: the CSV and the printed modes against
//! the 4-axis twin's exact model (`ambid_twin::campbell`, `Machine::closed_loop_modes`), the
//! whirl split at speed, and the usage errors.

use crate::common::{ambid, s, text, tmpdir};
use ambid_twin::{Machine, MachineConfig, Whirl};
use std::path::Path;

/// One CSV row: (speed_rpm, sync_hz, mode, freq_hz, damping, whirl).
type Row = (f64, f64, usize, f64, f64, String);

fn read_rows(p: &Path) -> Vec<Row> {
    let mut r = csv::Reader::from_path(p).unwrap();
    let h: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(
        h,
        [
            "speed_rpm",
            "sync_hz",
            "mode",
            "freq_hz",
            "damping",
            "whirl"
        ]
    );
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            (
                rec[0].parse().unwrap(),
                rec[1].parse().unwrap(),
                rec[2].parse().unwrap(),
                rec[3].parse().unwrap(),
                rec[4].parse().unwrap(),
                rec[5].to_string(),
            )
        })
        .collect()
}

fn whirl_name(w: Whirl) -> &'static str {
    match w {
        Whirl::Forward => "forward",
        Whirl::Backward => "backward",
        Whirl::None => "none",
    }
}

#[test]
fn campbell_csv_equals_the_twins_campbell_and_the_tilt_pair_splits() {
    let d = tmpdir("campbell");
    let out = d.join("campbell.csv");
    let o = ambid(&["campbell", "--speeds", "0:30000:4", "--out", s(&out)]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("30000 rpm") && t.contains("tilt forward"), "{t}");
    let rows = read_rows(&out);

    // independent truth: the twin's own Campbell diagram at the same speeds
    let speeds = [0.0, 10_000.0, 20_000.0, 30_000.0];
    let truth = ambid_twin::campbell(&MachineConfig::default(), &speeds, 1000.0).unwrap();
    let n_truth: usize = truth.iter().map(|p| p.modes.len()).sum();
    assert_eq!(rows.len(), n_truth);
    let mut k = 0;
    for p in &truth {
        assert!(!p.modes.is_empty());
        for (i, m) in p.modes.iter().enumerate() {
            let r = &rows[k];
            k += 1;
            assert_eq!(r.0, p.speed_rpm);
            assert!(
                (r.1 - p.sync_hz).abs() <= 1e-8 * p.sync_hz.max(1.0),
                "{r:?}"
            );
            assert_eq!(r.2, i);
            // printed with 10 significant digits
            assert!(
                (r.3 - m.freq_hz).abs() <= 1e-9 * m.freq_hz,
                "{r:?} vs {m:?}"
            );
            assert!((r.4 - m.damping).abs() <= 1e-9 * m.damping.abs(), "{r:?}");
            assert_eq!(r.5, whirl_name(m.whirl));
        }
    }
    // sync line = speed / 60
    for r in &rows {
        assert!((r.1 - r.0 / 60.0).abs() < 1e-6, "{r:?}");
    }

    // at standstill: no whirl, each mode twice (x and y planes identical)
    let still: Vec<&Row> = rows.iter().filter(|r| r.0 == 0.0).collect();
    assert_eq!(still.len() % 2, 0);
    assert!(still.iter().all(|r| r.5 == "none"), "{still:?}");
    for pair in still.chunks(2) {
        assert!((pair[0].3 - pair[1].3).abs() < 1e-5 * pair[0].3, "{pair:?}");
    }
    assert!(still.len() >= 4, "translation and tilt pairs below 1 kHz");

    // the tilt pair (modes 2 and 3) splits: forward rises, backward falls with speed
    let tilt = |speed: f64, w: &str| -> f64 {
        rows.iter()
            .find(|r| r.0 == speed && (r.2 == 2 || r.2 == 3) && r.5 == w)
            .unwrap_or_else(|| panic!("no {w} tilt mode at {speed} rpm"))
            .3
    };
    let tilt0 = still[2].3;
    let mut prev = (tilt0, tilt0);
    for &v in &speeds[1..] {
        let (f, b) = (tilt(v, "forward"), tilt(v, "backward"));
        assert!(
            f > prev.0 && b < prev.1,
            "at {v} rpm: forward {f}, backward {b}, before {prev:?}"
        );
        prev = (f, b);
    }
    // by a visible amount at 30 000 rpm (gyroscopic split of several Hz)
    assert!(prev.0 - prev.1 > 1.0, "{prev:?}");
}

#[test]
fn campbell_takes_a_list_of_speeds_and_a_config_file() {
    let d = tmpdir("campbell-list");
    let cfg = MachineConfig {
        speed_rpm: 0.0,
        ..MachineConfig::default()
    };
    // a heavier polar inertia: a larger split than the nominal rig's
    let cfg = MachineConfig {
        polar_inertia_kgm2: Some(2.0 * cfg.polar_inertia()),
        ..cfg
    };
    let cfg_path = d.join("machine.toml");
    std::fs::write(&cfg_path, cfg.to_toml_string().unwrap()).unwrap();
    let out = d.join("c.csv");
    let o = ambid(&[
        "campbell",
        "--config",
        s(&cfg_path),
        "--speeds",
        "0, 25000",
        "--f-max",
        "300",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_rows(&out);
    let truth = ambid_twin::campbell(&cfg, &[0.0, 25_000.0], 300.0).unwrap();
    let freqs: Vec<f64> = truth
        .iter()
        .flat_map(|p| p.modes.iter().map(|m| m.freq_hz))
        .collect();
    assert_eq!(rows.len(), freqs.len());
    assert!(rows.iter().all(|r| r.3 <= 300.0));
    for (r, f) in rows.iter().zip(&freqs) {
        assert!((r.3 - f).abs() <= 1e-9 * f, "{r:?} vs {f}");
    }
}

#[test]
fn bad_speeds_are_usage_errors_naming_speeds() {
    let d = tmpdir("campbell-bad");
    let out = d.join("c.csv");
    for bad in [
        "-100,2000",
        "nan",
        "0,inf",
        "5000:1000:3",
        "0:1000:0",
        "",
        "0:1000",
        "a,b",
    ] {
        let arg = format!("--speeds={bad}");
        let o = ambid(&["campbell", &arg, "--out", s(&out)]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{bad:?}: {t}");
        assert!(t.contains("--speeds"), "{bad:?}: {t}");
        assert!(!t.contains("panicked"), "{t}");
        assert!(!out.exists(), "{bad:?} wrote an output");
    }
    let o = ambid(&["campbell", "--f-max", "-1", "--out", s(&out)]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("--f-max"));
}

#[test]
fn an_existing_output_is_refused_without_force() {
    let d = tmpdir("campbell-force");
    let out = d.join("c.csv");
    std::fs::write(&out, "keep me\n").unwrap();
    let o = ambid(&["campbell", "--speeds", "0", "--out", s(&out)]);
    let t = text(&o);
    assert!(!o.status.success(), "{t}");
    // the same class and message as the other commands' refusal (io::output)
    let reference = ambid(&["excite", "prbs", "--out", s(&out)]);
    assert_eq!(o.status.code(), reference.status.code(), "{t}");
    assert!(t.contains("already exists") && t.contains("--force"), "{t}");
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "keep me\n");
    let o = ambid(&["campbell", "--speeds", "0", "--out", s(&out), "--force"]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_rows(&out);
    assert!(!rows.is_empty() && rows.iter().all(|r| r.0 == 0.0 && r.5 == "none"));
}

#[test]
fn info_axes_4_lists_the_machines_modes_and_facts() {
    let o = ambid(&["info", "--axes", "4", "--speed-rpm", "30000"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let cfg = MachineConfig {
        speed_rpm: 30_000.0,
        ..MachineConfig::default()
    };
    let m = Machine::new(cfg.clone()).unwrap();
    // the modes, in order, to the printed precision
    let printed: Vec<(f64, f64, String)> = t
        .lines()
        .filter(|l| l.contains("whirl ") && l.contains("damping"))
        .map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            (
                w[0].parse().unwrap(),
                w[3].parse().unwrap(),
                w[5].to_string(),
            )
        })
        .collect();
    let modes = m.closed_loop_modes().unwrap();
    assert_eq!(printed.len(), modes.len(), "{t}");
    for (p, md) in printed.iter().zip(&modes) {
        assert!((p.0 - md.freq_hz).abs() <= 0.05 + 1e-9, "{p:?} vs {md:?}");
        assert!((p.1 - md.damping).abs() <= 5e-4 + 1e-12, "{p:?} vs {md:?}");
        assert_eq!(p.2, whirl_name(md.whirl));
    }
    assert!(printed.iter().any(|p| p.2 == "forward") && printed.iter().any(|p| p.2 == "backward"));
    // 1× = 30000/60 Hz, the inertias, four unstable open-loop poles, peak |S| per axis
    assert!(t.contains("1x frequency 500.000 Hz"), "{t}");
    assert!(
        t.contains(&format!("J_p = {:.4e}", cfg.polar_inertia())),
        "{t}"
    );
    assert!(
        t.contains(&format!("J_t = {:.4e}", cfg.rotor.inertia())),
        "{t}"
    );
    let unstable = m
        .plant()
        .poles()
        .unwrap()
        .iter()
        .filter(|z| z.norm() > 1.0)
        .count();
    assert_eq!(unstable, 4, "one unstable pole per open loop");
    assert!(t.contains("all four loops open): 4"), "{t}");
    for (axis, (f, s)) in ambid_twin::AXES.iter().zip(m.peak_sensitivity().unwrap()) {
        assert!(
            t.contains(&format!("  {axis}: {s:.3} at {f:.1} Hz")),
            "{axis}: {t}"
        );
    }

    // at standstill: no whirl, the planes' modes twice
    let o = ambid(&["info", "--axes", "4"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let whirls: Vec<&str> = t
        .lines()
        .filter(|l| l.contains("whirl "))
        .map(|l| l.split_whitespace().last().unwrap())
        .collect();
    assert!(
        !whirls.is_empty() && whirls.iter().all(|w| *w == "none"),
        "{t}"
    );
    assert!(t.contains("1x frequency 0.000 Hz"), "{t}");
}

#[test]
fn info_axes_usage_errors() {
    for args in [
        &["info", "--axes", "3"][..],
        &["info", "--speed-rpm", "1000"],
        &["info", "--axes", "4", "--speed-rpm", "-5"],
        &["info", "--axes", "4", "--rig-seed", "3"],
    ] {
        let o = ambid(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o));
        assert!(!text(&o).contains("panicked"));
    }
    // --axes 1 is the default: the same bytes
    let a = ambid(&["info"]);
    let b = ambid(&["info", "--axes", "1"]);
    assert!(a.status.success());
    assert_eq!(a.stdout, b.stdout);
}
