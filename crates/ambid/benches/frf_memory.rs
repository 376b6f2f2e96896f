//! Peak memory of `ambid frf` as a whole process on long records (issue 17's bar: ≤ 100 MiB on
//! 10⁷ samples, and within 20 % between 10⁶ and 10⁷ samples).
//!
//! `cargo bench -p ambid --bench frf_memory` builds the release binary, writes two records of
//! a deterministic closed loop into a temporary directory (a periodic ±0.1 A random binary
//! excitation of 5115 samples per period through a resonant second-order plant under a
//! proportional controller, with white output noise; columns `t,r,u,y` at 20 kHz;
//! 196 periods ≈ 10⁶ samples and 1955 periods ≈ 10⁷ samples) and runs `ambid frf` on each
//! with period averaging (`--period-samples 5115`) and with Welch at its defaults (the default
//! segment is 8192 samples on both records), under
//! `/usr/bin/time -v`: it prints the maximum resident set size and the wall time as a Markdown
//! table for docs/benchmarks.md. The records (about 0.6 GB for 10⁷ samples) are deleted at the
//! end. Needs `/usr/bin/time` (GNU time).
//!
//! Options by environment: `AMBID_BENCH_PERIODS=196,1955` (periods per record).

use std::io::{BufWriter, Write};
use std::path::Path;

const EXE: &str = env!("CARGO_BIN_EXE_ambid");
const PERIOD: usize = 5115;

/// Writes `periods` periods of the synthetic loop to `path`.
fn write_record(path: &Path, periods: usize) -> std::io::Result<()> {
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let base: Vec<f64> = (0..PERIOD)
        .map(|_| if rnd() > 0.0 { 0.1 } else { -0.1 })
        .collect();
    let mut w = BufWriter::with_capacity(1 << 20, std::fs::File::create(path)?);
    writeln!(w, "t,r,u,y")?;
    let (mut y1, mut y2, mut u1) = (0.0f64, 0.0f64, 0.0f64);
    for k in 0..periods * PERIOD {
        let r = base[k % PERIOD];
        // plant y = (b1 q^-1) / (1 - 1.9 q^-1 + 0.95 q^-2) u [m/A], controller u = r - 2000 y
        let y = 1.9 * y1 - 0.95 * y2 + 2e-6 * u1 + 1e-8 * rnd();
        let u = r - 2000.0 * y;
        writeln!(w, "{:.8e},{r:e},{u:.12e},{y:.12e}", k as f64 * 5e-5)?;
        (y2, y1, u1) = (y1, y, u);
    }
    w.flush()
}

#[path = "common/time_v.rs"]
mod time_v;

fn main() {
    let periods: Vec<usize> = std::env::var("AMBID_BENCH_PERIODS")
        .unwrap_or_else(|_| "196,1955".into())
        .split(',')
        .filter_map(|v| v.trim().parse().ok())
        .collect();
    let dir = std::env::temp_dir().join(format!("ambid-bench-frfmem-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    println!("| samples | method | peak RSS [MiB] | wall [s] |");
    println!("|---|---|---|---|");
    for p in periods {
        let n = p * PERIOD;
        let data = dir.join(format!("rec{n}.csv"));
        write_record(&data, p).expect("the record is written");
        let out = dir.join("frf.csv");
        let (d, o) = (data.display().to_string(), out.display().to_string());
        let per = PERIOD.to_string();
        for (label, extra) in [
            (
                "period averaging (--period-samples 5115)",
                vec!["--period-samples", &per],
            ),
            // no option: the period found in r while the file streams (PeriodScan)
            ("defaults (the period found in r)", vec![]),
            // Welch at its default segment (a power of two ≤ N/8, at most 8192)
            ("Welch (--method welch)", vec!["--method", "welch"]),
        ] {
            let mut args = vec!["frf", d.as_str(), "--out", o.as_str(), "--force"];
            args.extend(extra);
            match time_v::measure(EXE, &args) {
                Ok((mib, s)) => println!("| {n} | {label} | {mib:.1} | {s:.2} |"),
                Err(e) => println!("| {n} | {label} | failed: {e} | |"),
            }
        }
        let _ = std::fs::remove_file(&data);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
