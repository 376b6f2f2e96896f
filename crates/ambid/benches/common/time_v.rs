//! Shared by the whole-process benches: one run of the CLI under GNU `/usr/bin/time -v`.

use std::process::Command;

/// (peak RSS in MiB, wall time in s) of `ambid args…`.
pub fn measure(exe: &str, args: &[&str]) -> Result<(f64, f64), String> {
    let out = Command::new("/usr/bin/time")
        .arg("-v")
        .arg(exe)
        .args(args)
        .output()
        .map_err(|e| format!("cannot run /usr/bin/time: {e}"))?;
    let err = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        return Err(err.lines().take(3).collect::<Vec<_>>().join(" / "));
    }
    let field = |name: &str| {
        err.lines()
            .find_map(|l| l.trim().strip_prefix(name))
            .map(str::trim)
            .map(str::to_string)
    };
    let kb: f64 = field("Maximum resident set size (kbytes):")
        .and_then(|v| v.parse().ok())
        .ok_or("no maximum resident set size in the output of /usr/bin/time -v")?;
    let wall = field("Elapsed (wall clock) time (h:mm:ss or m:ss):").unwrap_or_default();
    let secs = wall
        .split(':')
        .filter_map(|p| p.parse::<f64>().ok())
        .fold(0.0, |acc, v| acc * 60.0 + v);
    Ok((kb / 1024.0, secs))
}
