//! `ambid fit --structure ss --order 8 --input r --output y` as a whole process (start-up, CSV
//! reading, subspace with the automatic horizon, PEM with the automatic focus, model JSON) on the
//! seed record, against issue 16's bar (≤ 1 s), next to the same pipeline in-process.
//!
//! The record is written once by `ambid simulate --out DIR` (simulate's defaults are the seed
//! experiment on the nominal twin: PRBS n = 10, 5 samples per bit, 20 periods, 102 300 samples).
//! * `cli_fit_ss_order8_defaults`: the built `ambid` binary, spawned and awaited per sample;
//! * `library_identify_state_space_defaults`: [`identify_state_space`] with order 8 and otherwise
//!   [`SsFitOptions::default`] on the same (mean-removed) columns — the CLI minus process start-up,
//!   file reading and output.
//!
//! Run: `cargo bench -p ambid --bench cli_fit`. Figures: docs/benchmarks.md.

use ambid::fitting::{identify_state_space, SsFitOptions};
use ambid::io::{read_time, TimeOptions};
use divan::{black_box, Bencher};
use std::path::PathBuf;
use std::process::Command;

const AMBID: &str = env!("CARGO_BIN_EXE_ambid");

fn main() {
    divan::main();
}

/// The seed record, simulated once per bench run into a temporary directory.
fn seed_record() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("ambid-bench-cli-fit-{}", std::process::id()));
    let data = dir.join("data.csv");
    if !data.exists() {
        let o = Command::new(AMBID)
            .args(["simulate", "--out", dir.to_str().expect("utf-8 temp dir")])
            .output()
            .expect("ambid simulate runs");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    data
}

#[divan::bench(sample_count = 5)]
fn cli_fit_ss_order8_defaults(b: Bencher) {
    let data = seed_record();
    let out = data.with_file_name("model.json");
    b.bench_local(|| {
        let o = Command::new(AMBID)
            .args(["fit", data.to_str().expect("utf-8 path")])
            .args([
                "--structure",
                "ss",
                "--order",
                "8",
                "--input",
                "r",
                "--output",
                "y",
            ])
            .args(["--out", out.to_str().expect("utf-8 path")])
            .output()
            .expect("ambid fit runs");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        black_box(o)
    });
}

#[divan::bench(sample_count = 5)]
fn library_identify_state_space_defaults(b: Bencher) {
    let d = read_time(&seed_record(), &TimeOptions::default()).expect("seed record");
    let centred = |name: &str| {
        let x = d.column(name).expect("column");
        let m = x.iter().sum::<f64>() / x.len() as f64;
        x.iter().map(|v| v - m).collect::<Vec<f64>>()
    };
    let (u, y) = (centred("r"), centred("y"));
    let o = SsFitOptions {
        order: Some(8),
        ..SsFitOptions::default()
    };
    b.bench_local(|| black_box(identify_state_space(&u, &y, d.ts, &o).expect("fit")));
}
