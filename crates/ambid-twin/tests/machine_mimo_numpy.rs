//! Issue 20's numpy bar: on the same twin record (4-axis machine at 15 000 rpm, noise on,
//! orthogonal PRBS design), `ambid_core::frf::mimo::periodic` equals a plain-numpy reference
//! (`tests/fixtures/mimo_twin/reference.py`: np.fft.rfft per period, means, per-period
//! covariances, np.linalg.pinv/inv per line) in every value and standard deviation of T_ry, S
//! and P, and so in its error against the machine's exact truth, to 1e-9 relative. Skips visibly
//! (the project's skip mechanism) without python3/numpy.

use crate::common;
#[path = "../../ambid/tests/common/skip.rs"]
mod skip;

use ambid_core::data::IoData;
use ambid_core::frf::mimo::{periodic, MimoOptions};
use ambid_core::lti::Frd;
use ambid_core::signal::multi::MultiInputDesign;
use ambid_core::signal::PrbsSpec;
use ambid_twin::{c64, Machine, MachineConfig, MachineSimOptions, Mode};
use std::fmt::Write as _;
use std::process::Command;

const SCRIPT: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/fixtures/mimo_twin/reference.py"
);

#[test]
fn mimo_frf_on_twin_data_equals_the_numpy_reference() {
    let check = "machine_mimo_numpy (ambid's MIMO FRF vs plain numpy on twin data)";
    let ok = Command::new("python3")
        .args(["-c", "import numpy"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !ok {
        skip::skip(
            check,
            "python3 with numpy not found; install python3 and numpy",
        );
        return;
    }
    let machine = Machine::new(MachineConfig {
        speed_rpm: 15_000.0,
        ..MachineConfig::default()
    })
    .unwrap();
    let prbs = PrbsSpec {
        order: 6,
        samples_per_bit: 2,
        periods: 6,
        amplitude: 0.04,
        offset: 0.0,
    };
    let exc = MultiInputDesign::orthogonal(4, prbs)
        .generate(machine.ts())
        .unwrap();
    let n = exc.period_samples();
    let skip_periods = 1;
    let recs: Vec<IoData> = common::run_design(&machine, &exc, |e| MachineSimOptions {
        mode: Mode::Linear,
        noise: true,
        seed: 7 + e as u64,
        settle_samples: 40 * n,
        ..MachineSimOptions::default()
    });
    // the record as CSV, every value in full precision
    let names: Vec<String> = ["r", "u", "y"]
        .iter()
        .flat_map(|l| ["xa", "xb", "ya", "yb"].map(|a| format!("{l}_{a}")))
        .collect();
    let mut csv = format!("exp,{}\n", names.join(","));
    for (e, rec) in recs.iter().enumerate() {
        let cols: Vec<&[f64]> = names.iter().map(|c| rec.channel(c).unwrap()).collect();
        for t in 0..rec.len() {
            write!(csv, "{e}").unwrap();
            for c in &cols {
                write!(csv, ",{:?}", c[t]).unwrap();
            }
            csv.push('\n');
        }
    }
    let dir = std::env::temp_dir().join(format!("ambid-mimo-twin-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("record.csv"), csv).unwrap();
    let out = Command::new("python3")
        .arg(SCRIPT)
        .arg(&dir)
        .arg(n.to_string())
        .arg(skip_periods.to_string())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "reference.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(dir.join("reference.csv")).unwrap();
    let _ = std::fs::remove_dir_all(&dir);

    let data = IoData::from_experiments(recs).unwrap();
    let est = periodic(&data, &MimoOptions::new().skip(skip_periods)).unwrap();
    let f = est.f_hz().to_vec();
    let truth: [Frd; 3] = [
        machine.t_ry_frf(&f).unwrap(),
        machine.sensitivity_frf(&f).unwrap(),
        machine.plant_frf(&f).unwrap(),
    ];
    let ests = [&est.t_ry, &est.s, &est.plant];
    let mut rows = 0;
    // per quantity: sum |err_ambid|², sum |err_numpy|², worst value/std mismatch
    let mut err2 = [[0.0f64; 2]; 3];
    let mut worst = [0.0f64; 3];
    for row in text.lines().skip(1) {
        let v: Vec<&str> = row.split(',').collect();
        let k: usize = v[0].parse().unwrap();
        let q = ["T", "S", "P"].iter().position(|q| *q == v[1]).unwrap();
        let (i, j): (usize, usize) = (v[2].parse().unwrap(), v[3].parse().unwrap());
        let z = c64::new(v[4].parse().unwrap(), v[5].parse().unwrap());
        let sd: f64 = v[6].parse().unwrap();
        let li = est.lines.iter().position(|&l| l == k).expect("line");
        let g = ests[q].at(li).unwrap()[(i, j)];
        let gsd = ests[q].variance_at(li).unwrap().unwrap()[(i, j)].sqrt();
        let t = truth[q].at(li).unwrap()[(i, j)];
        // relative to the line's largest entry (cross terms can be small)
        let scale = (0..4)
            .flat_map(|a| (0..4).map(move |b| (a, b)))
            .map(|(a, b)| ests[q].at(li).unwrap()[(a, b)].norm())
            .fold(0.0f64, f64::max);
        worst[q] = worst[q]
            .max((g - z).norm() / scale)
            .max((gsd - sd).abs() / sd);
        err2[q][0] += (g - t).norm_sqr();
        err2[q][1] += (z - t).norm_sqr();
        rows += 1;
    }
    assert_eq!(
        rows,
        est.lines.len() * 16 * 3,
        "every line and entry compared"
    );
    for (q, name) in ["T_ry", "S", "P"].iter().enumerate() {
        let (ea, en) = (err2[q][0].sqrt(), err2[q][1].sqrt());
        println!(
            "{name}: worst value/std mismatch {:.2e}, error vs truth ambid {ea:.6e} numpy {en:.6e}",
            worst[q]
        );
        assert!(worst[q] < 1e-9, "{name}: {}", worst[q]);
        assert!((ea - en).abs() <= 1e-9 * en, "{name}: {ea} vs {en}");
        assert!(en > 0.0);
    }
}
