//! Reading a window of a long TDMS log (issue 24's bar: a 5-s window of 3 channels of a
//! 10-minute, 16-channel, 20 kHz log, ≈ 1.5 GB, in ≤ 1 s and ≤ 200 MiB peak memory).
//!
//! `cargo bench -p ambid --bench tdms_window` writes the log into a temporary directory and runs
//! the CLI as a whole process on it, under `/usr/bin/time -v` (maximum resident set size and
//! wall time, printed as a Markdown table for docs/benchmarks.md):
//! `ambid frf log.tdms --excitation log/r --input log/u --output log/y --from 300 --to 305`
//! (the 5 s in the middle of the log)
//! (the Welch FRF at its defaults of the window, 100 000 samples: the reader plus everything
//! `frf` does after it),
//! once right after the log was written (the file in the page cache) and, when the bench may
//! drop the page cache (root), once more from a cold cache.
//!
//! The log: group `log`, channels `r`, `u`, `y` (a periodic ±0.1 A random binary excitation of
//! 5115 samples per period through a resonant second-order plant under a proportional
//! controller, with white output noise) and `aux01` … `aux13` (noise), float64, `wf_increment`
//! = 5e-5, written as LabVIEW's TDMS Write does in a loop: one segment per second, the first
//! with the metadata and properties, the others with raw data only (ToC = raw data: same
//! objects, same layout). The writer is this bench's own (npTDMS writes the test fixtures whose
//! values the reader must reproduce, tests/rig_formats.rs; here only the size matters). The
//! log is deleted at the end. Needs `/usr/bin/time` (GNU time).
//!
//! Options by environment: `AMBID_BENCH_MINUTES=10` (length of the log),
//! `AMBID_BENCH_SEGMENT=20000` (samples per segment; 1000 gives 12 000 segments of 50 ms, as a
//! LabVIEW loop that writes every iteration).

use std::io::{BufWriter, Write};
use std::path::Path;
use std::process::Command;

const EXE: &str = env!("CARGO_BIN_EXE_ambid");
const FS: usize = 20_000;
const CHANNELS: usize = 16;
const PERIOD: usize = 5115;

fn string(w: &mut impl Write, s: &str) -> std::io::Result<()> {
    w.write_all(&(s.len() as u32).to_le_bytes())?;
    w.write_all(s.as_bytes())
}

/// The metadata of the first segment: the file, the group and every channel with its raw-data
/// index (f64, `seg` values per chunk) and `wf_increment`.
fn metadata(names: &[String], seg: usize) -> std::io::Result<Vec<u8>> {
    let mut m = Vec::new();
    m.write_all(&((names.len() + 2) as u32).to_le_bytes())?;
    for (path, channel) in [("/".to_string(), false), ("/'log'".to_string(), false)]
        .into_iter()
        .chain(names.iter().map(|n| (format!("/'log'/'{n}'"), true)))
    {
        string(&mut m, &path)?;
        if channel {
            m.write_all(&20u32.to_le_bytes())?;
            m.write_all(&10u32.to_le_bytes())?; // tdsTypeDoubleFloat
            m.write_all(&1u32.to_le_bytes())?;
            m.write_all(&(seg as u64).to_le_bytes())?;
            m.write_all(&1u32.to_le_bytes())?;
            string(&mut m, "wf_increment")?;
            m.write_all(&10u32.to_le_bytes())?;
            m.write_all(&(1.0 / FS as f64).to_le_bytes())?;
        } else {
            m.write_all(&u32::MAX.to_le_bytes())?;
            m.write_all(&0u32.to_le_bytes())?;
        }
    }
    Ok(m)
}

/// Writes `seconds` of log in segments of `seg` samples to `path` (`seg` divides `FS`).
fn write_log(path: &Path, seconds: usize, seg: usize) -> std::io::Result<()> {
    let names: Vec<String> = ["r", "u", "y"]
        .iter()
        .map(|s| s.to_string())
        .chain((1..=CHANNELS - 3).map(|k| format!("aux{k:02}")))
        .collect();
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
    let meta = metadata(&names, seg)?;
    let raw_len = (seg * CHANNELS * 8) as u64;
    let mut w = BufWriter::with_capacity(1 << 22, std::fs::File::create(path)?);
    let (mut y1, mut y2, mut u1) = (0.0f64, 0.0f64, 0.0f64);
    let mut cols = vec![vec![0.0f64; seg]; CHANNELS];
    for s in 0..seconds * FS / seg {
        for j in 0..seg {
            let k = s * seg + j;
            let r = base[k % PERIOD];
            let y = 1.9 * y1 - 0.95 * y2 + 2e-6 * u1 + 1e-8 * rnd();
            let u = r - 2000.0 * y;
            (y2, y1, u1) = (y1, y, u);
            cols[0][j] = r;
            cols[1][j] = u;
            cols[2][j] = y;
            for c in cols.iter_mut().skip(3) {
                c[j] = rnd();
            }
        }
        let (toc, meta_now): (u32, &[u8]) = if s == 0 {
            ((1 << 1) | (1 << 2) | (1 << 3), &meta)
        } else {
            (1 << 3, &[])
        };
        w.write_all(b"TDSm")?;
        w.write_all(&toc.to_le_bytes())?;
        w.write_all(&4713u32.to_le_bytes())?;
        w.write_all(&(meta_now.len() as u64 + raw_len).to_le_bytes())?;
        w.write_all(&(meta_now.len() as u64).to_le_bytes())?;
        w.write_all(meta_now)?;
        for c in &cols {
            for v in c {
                w.write_all(&v.to_le_bytes())?;
            }
        }
    }
    w.flush()
}

#[path = "common/time_v.rs"]
mod time_v;

/// Drops the page cache (root only); whether it did.
fn drop_caches() -> bool {
    Command::new("sync").status().is_ok()
        && std::fs::write("/proc/sys/vm/drop_caches", "3\n").is_ok()
}

fn main() {
    let minutes: usize = std::env::var("AMBID_BENCH_MINUTES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10);
    let seg: usize = std::env::var("AMBID_BENCH_SEGMENT")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&s: &usize| s > 0 && FS % s == 0)
        .unwrap_or(FS);
    let dir = std::env::temp_dir().join(format!("ambid-bench-tdms-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let log = dir.join("log.tdms");
    write_log(&log, minutes * 60, seg).expect("the log is written");
    let size = std::fs::metadata(&log).map(|m| m.len()).unwrap_or(0);
    println!(
        "log: {minutes} min, {CHANNELS} channels, {FS} Hz, {:.2} GB, {} segments of {seg} samples",
        size as f64 / 1e9,
        minutes * 60 * FS / seg
    );
    let out = dir.join("frf.csv");
    let (l, o) = (log.display().to_string(), out.display().to_string());
    // 5 s in the middle of the log (300–305 s of 10 minutes)
    let (from, to) = ((minutes * 30).to_string(), (minutes * 30 + 5).to_string());
    let args = [
        "frf",
        l.as_str(),
        "--excitation",
        "log/r",
        "--input",
        "log/u",
        "--output",
        "log/y",
        "--from",
        from.as_str(),
        "--to",
        to.as_str(),
        "--out",
        o.as_str(),
        "--force",
    ];
    println!("| page cache | peak RSS [MiB] | wall [s] |");
    println!("|---|---|---|");
    for (label, cold) in [
        ("warm (file just written)", false),
        ("cold (dropped)", true),
    ] {
        if cold && !drop_caches() {
            println!("| cold | not measured: cannot drop the page cache (needs root) | |");
            continue;
        }
        match time_v::measure(EXE, &args) {
            Ok((mib, s)) => println!("| {label} | {mib:.1} | {s:.3} |"),
            Err(e) => println!("| {label} | failed: {e} | |"),
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
