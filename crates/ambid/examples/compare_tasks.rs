//! The ambid side of the peer comparison (`bench/compare/`, issue 9): runs one task in-process on
//! data files, times only the computation (after the files are read) and prints one JSON object
//! with the time of every repetition and the result, which the Python driver scores exactly as it
//! scores the peers' results.
//!
//! ```text
//! cargo run --release --example compare_tasks -- <task> [options]
//!
//! tasks and their options (every task: --reps K (default 5), --warmup W (default 1), --out FILE)
//!   welch     --data F --channels r,u,y --nperseg 4096 [--fs Hz]
//!             all auto and cross spectra of the channels (Hann, 50 % overlap, constant detrend)
//!             plus the coherences of the first channel with the others
//!   frf       --data F --period N --skip K [--fs Hz]
//!             period-averaged closed-loop FRF (columns r, u, y): T_ry, S, plant, controller with
//!             variances and coherences on the excited lines (FFT planning included)
//!   arx-scan  --data F --na-max A --nb-max B [--nk 1] [--fs Hz] [--input u --output y]
//!             ARX order scan na = 1..A × nb = 1..B, BIC choice
//!   n4sid     --data F --order n [--block-rows i] [--pem none|simulation] [--fs Hz]
//!             subspace identification (N4SID/CVA), optionally refined by state-space PEM
//!   oe        --data F --nb B --nf F [--nk 1] [--max-iterations 100] [--fs Hz]
//!             output-error model by the prediction-error method
//!   freqresp  --model M.json --nfreq K
//!             frequency response of a discrete state-space model (JSON with a, b, c, d as
//!             row-major nested lists and ts) at K frequencies, log-spaced from 1e-3 fs to 0.49 fs
//!   truth     [--config twin.toml] --period N --fmin a --fmax b
//!             not timed: the twin's exact T_ry, S and plant on the lines k fs / N in [a, b], the
//!             reference both sides' FRFs and models are scored against
//! ```
//!
//! Nothing here is part of the test suite or CI; `bench/compare/run.sh` drives it.

use ambid::io::{read_time, TimeOptions};
use ambid_core::estimate::order::{arx_order_scan, ArxScanSpec};
use ambid_core::estimate::pem::{self, Focus, PemOptions};
use ambid_core::estimate::ss_pem::{refine_ss, SsPemOptions};
use ambid_core::estimate::subspace::{n4sid_detailed, SubspaceOptions};
use ambid_core::frf::closed_loop::{from_periodic, Channels};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
use ambid_core::frf::welch::{welch_spectra, WelchOptions};
use ambid_core::lti::{Frd, StateSpace};
use anyhow::{anyhow, bail, Context, Result};
use faer::{Mat, MatRef};
use serde_json::{json, Value};
use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

fn main() {
    if let Err(e) = run() {
        eprintln!("compare_tasks: {e:#}");
        std::process::exit(1);
    }
}

/// `--key value` pairs after the task name.
struct Opts(HashMap<String, String>);

impl Opts {
    fn parse(args: &[String]) -> Result<Self> {
        let mut m = HashMap::new();
        let mut it = args.iter();
        while let Some(k) = it.next() {
            let key = k
                .strip_prefix("--")
                .ok_or_else(|| anyhow!("expected an option `--name value`, got `{k}`"))?;
            let v = it
                .next()
                .ok_or_else(|| anyhow!("option --{key} needs a value"))?;
            m.insert(key.to_string(), v.clone());
        }
        Ok(Self(m))
    }

    fn str(&self, k: &str) -> Result<&str> {
        self.0
            .get(k)
            .map(String::as_str)
            .ok_or_else(|| anyhow!("missing option --{k}"))
    }

    fn str_or<'a>(&'a self, k: &str, default: &'a str) -> &'a str {
        self.0.get(k).map_or(default, String::as_str)
    }

    fn num<T: std::str::FromStr>(&self, k: &str) -> Result<T> {
        self.str(k)?.parse().map_err(|_| {
            anyhow!(
                "--{k}: `{}` is not a valid number",
                self.str(k).unwrap_or("")
            )
        })
    }

    fn num_or<T: std::str::FromStr>(&self, k: &str, default: T) -> Result<T> {
        if self.0.contains_key(k) {
            self.num(k)
        } else {
            Ok(default)
        }
    }

    fn fs(&self) -> Result<Option<f64>> {
        if self.0.contains_key("fs") {
            Ok(Some(self.num("fs")?))
        } else {
            Ok(None)
        }
    }
}

/// Runs `f` `warmup` times untimed, then `reps` times timed; returns the times and the last
/// result.
fn timed<T>(warmup: usize, reps: usize, mut f: impl FnMut() -> Result<T>) -> Result<(Vec<f64>, T)> {
    for _ in 0..warmup {
        std::hint::black_box(f()?);
    }
    let mut times = Vec::with_capacity(reps);
    let mut last = None;
    for _ in 0..reps.max(1) {
        let t0 = Instant::now();
        let r = std::hint::black_box(f()?);
        times.push(t0.elapsed().as_secs_f64());
        last = Some(r);
    }
    let last = last.ok_or_else(|| anyhow!("no repetition ran"))?;
    Ok((times, last))
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(task) = args.first() else {
        bail!("usage: compare_tasks <welch|frf|arx-scan|n4sid|oe|freqresp> [--option value ...]");
    };
    let o = Opts::parse(&args[1..])?;
    let reps: usize = o.num_or("reps", 5)?;
    let warmup: usize = o.num_or("warmup", 1)?;
    let (times, result) = match task.as_str() {
        "welch" => welch(&o, warmup, reps)?,
        "frf" => frf(&o, warmup, reps)?,
        "arx-scan" => arx_scan(&o, warmup, reps)?,
        "n4sid" => subspace(&o, warmup, reps)?,
        "oe" => oe(&o, warmup, reps)?,
        "freqresp" => freqresp(&o, warmup, reps)?,
        "truth" => (Vec::new(), truth(&o)?),
        t => bail!("unknown task `{t}`"),
    };
    let out = json!({ "task": task, "times_s": times, "result": result });
    let text = serde_json::to_string(&out)?;
    match o.0.get("out") {
        Some(p) => std::fs::write(p, text).with_context(|| format!("writing {p}"))?,
        None => {
            use std::io::Write;
            // a closed pipe (e.g. `| head`) is not an error of the task
            let _ = writeln!(std::io::stdout().lock(), "{text}");
        }
    }
    Ok(())
}

fn re_im(v: &[faer::c64]) -> Value {
    json!({
        "re": v.iter().map(|z| z.re).collect::<Vec<_>>(),
        "im": v.iter().map(|z| z.im).collect::<Vec<_>>(),
    })
}

fn frd_json(f: &Frd) -> Value {
    json!({ "value": re_im(f.values()), "variance": f.variance() })
}

fn welch(o: &Opts, warmup: usize, reps: usize) -> Result<(Vec<f64>, Value)> {
    let d = read_time(Path::new(o.str("data")?), &TimeOptions::with_fs(o.fs()?))?;
    let names: Vec<&str> = o.str_or("channels", "r,u,y").split(',').collect();
    let cols = names
        .iter()
        .map(|n| d.column(n))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    let opts = WelchOptions::new(1.0 / d.ts, o.num_or("nperseg", 4096)?);
    let nc = cols.len();
    let (times, (s, coh)) = timed(warmup, reps, || {
        let s = welch_spectra(&cols, &opts)?;
        let coh = (1..nc)
            .map(|j| s.coherence(0, j))
            .collect::<std::result::Result<Vec<_>, _>>()?;
        Ok((s, coh))
    })?;
    let mut spectra = serde_json::Map::new();
    for i in 0..nc {
        for j in i..nc {
            spectra.insert(format!("{}{}", names[i], names[j]), re_im(s.get(i, j)?));
        }
    }
    let cohs: serde_json::Map<String, Value> = (1..nc)
        .map(|j| (format!("{}{}", names[0], names[j]), json!(coh[j - 1])))
        .collect();
    Ok((
        times,
        json!({ "f": s.f_hz(), "csd": spectra, "coherence": cohs, "segments": s.n_segments() }),
    ))
}

fn frf(o: &Opts, warmup: usize, reps: usize) -> Result<(Vec<f64>, Value)> {
    let d = read_time(Path::new(o.str("data")?), &TimeOptions::with_fs(o.fs()?))?;
    let (r, u, y) = (d.column("r")?, d.column("u")?, d.column("y")?);
    let n: usize = o.num("period")?;
    let skip: usize = o.num_or("skip", 1)?;
    let fs = 1.0 / d.ts;
    let (times, frf) = timed(warmup, reps, || {
        // the FFT plan is made inside the timed region (numpy plans on every call too)
        let mut an = PeriodicAnalyzer::new(n)?;
        let s = an.analyze(&[r, u, y], fs, &PeriodicOptions::new(n).skip(skip))?;
        let lines = s.excited_lines(0, 1e-6)?;
        Ok(from_periodic(
            &s,
            Channels { r: 0, u: 1, y: 2 },
            &lines,
            None,
        )?)
    })?;
    Ok((
        times,
        json!({
            "f": frf.f_hz(),
            "t_ry": frd_json(&frf.t_ry),
            "s": frd_json(&frf.t_ru),
            "plant": frd_json(&frf.plant),
            "controller": frd_json(&frf.controller),
            "coh_ry": frf.coh_ry,
            "coh_ru": frf.coh_ru,
        }),
    ))
}

fn io_columns(o: &Opts) -> Result<(Vec<f64>, Vec<f64>, f64)> {
    let d = read_time(Path::new(o.str("data")?), &TimeOptions::with_fs(o.fs()?))?;
    let u = d.column(o.str_or("input", "u"))?.to_vec();
    let y = d.column(o.str_or("output", "y"))?.to_vec();
    Ok((u, y, d.ts))
}

fn arx_scan(o: &Opts, warmup: usize, reps: usize) -> Result<(Vec<f64>, Value)> {
    let (u, y, _) = io_columns(o)?;
    let spec = ArxScanSpec::new(
        1..=o.num("na-max")?,
        1..=o.num("nb-max")?,
        vec![o.num_or("nk", 1)?],
    );
    let (times, scan) = timed(warmup, reps, || Ok(arx_order_scan(&y, &u, &spec, None)?))?;
    let best = &scan.rows[scan.best_bic];
    Ok((
        times,
        json!({
            "na": best.na, "nb": best.nb, "nk": best.nk,
            "params": best.params,
            "method": scan.method,
            "n_models": scan.rows.len(),
        }),
    ))
}

fn col(x: &[f64]) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(x, x.len(), 1)
}

fn ss_json(m: &StateSpace) -> Value {
    let rows = |a: MatRef<'_, f64>| -> Vec<Vec<f64>> {
        (0..a.nrows())
            .map(|i| (0..a.ncols()).map(|j| a[(i, j)]).collect())
            .collect()
    };
    json!({ "a": rows(m.a()), "b": rows(m.b()), "c": rows(m.c()), "d": rows(m.d()) })
}

fn subspace(o: &Opts, warmup: usize, reps: usize) -> Result<(Vec<f64>, Value)> {
    let (u, y, ts) = io_columns(o)?;
    let mut so = SubspaceOptions::new(ts);
    so.order = Some(o.num("order")?);
    if o.0.contains_key("block-rows") {
        so.block_rows = Some(o.num("block-rows")?);
    }
    let pem_focus = match o.str_or("pem", "none") {
        "none" => None,
        "simulation" => Some(Focus::Simulation),
        "prediction" => Some(Focus::Prediction),
        p => bail!("--pem: `{p}` is not none, simulation or prediction"),
    };
    let (times, (model, i)) = timed(warmup, reps, || {
        let sub = n4sid_detailed(col(&y), col(&u), &so)?;
        let model = match pem_focus {
            None => sub.fitted.model,
            Some(focus) => {
                let p = SsPemOptions {
                    focus,
                    ..SsPemOptions::default()
                };
                let k = sub.kalman_gain.as_ref().map(|k| k.as_ref());
                refine_ss(col(&y), col(&u), &sub.fitted.model, k, &p)?
                    .fitted
                    .model
            }
        };
        Ok((model, sub.block_rows))
    })?;
    let mut v = ss_json(&model);
    v["block_rows"] = json!(i);
    Ok((times, v))
}

fn oe(o: &Opts, warmup: usize, reps: usize) -> Result<(Vec<f64>, Value)> {
    let (u, y, ts) = io_columns(o)?;
    let (nb, nf, nk): (usize, usize, usize) = (o.num("nb")?, o.num("nf")?, o.num_or("nk", 1)?);
    let opts = PemOptions::default().with_max_iterations(o.num_or("max-iterations", 100)?)?;
    let (times, (fit, iterations)) = timed(warmup, reps, || {
        let (f, rep) = pem::oe(&y, &u, nb, nf, nk, ts, &opts)?;
        Ok((f, rep.iterations()))
    })?;
    Ok((
        times,
        json!({ "b": fit.model.b(), "f": fit.model.f(), "iterations": iterations }),
    ))
}

fn freqresp(o: &Opts, warmup: usize, reps: usize) -> Result<(Vec<f64>, Value)> {
    let path = o.str("model")?;
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {path}"))?;
    let v: Value = serde_json::from_str(&text)?;
    let mat = |k: &str| -> Result<Mat<f64>> {
        let rows: Vec<Vec<f64>> = serde_json::from_value(v[k].clone())
            .with_context(|| format!("model field `{k}` must be a list of rows"))?;
        let (nr, nc) = (rows.len(), rows.first().map_or(0, Vec::len));
        if rows.iter().any(|r| r.len() != nc) {
            bail!("model field `{k}`: rows of different lengths");
        }
        Ok(Mat::from_fn(nr, nc, |i, j| rows[i][j]))
    };
    let ts = v["ts"]
        .as_f64()
        .ok_or_else(|| anyhow!("model field `ts` missing"))?;
    let m = StateSpace::discrete(mat("a")?, mat("b")?, mat("c")?, mat("d")?, ts)?;
    let k: usize = o.num("nfreq")?;
    let (lo, hi) = ((1e-3 / ts).ln(), (0.49 / ts).ln());
    let f: Vec<f64> = (0..k)
        .map(|i| (lo + (hi - lo) * i as f64 / (k.max(2) - 1) as f64).exp())
        .collect();
    let (times, h) = timed(warmup, reps, || Ok(m.freq_response_siso(&f)?))?;
    Ok((times, json!({ "f": f, "h": re_im(&h) })))
}

fn truth(o: &Opts) -> Result<Value> {
    let cfg = match o.0.get("config") {
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| format!("reading {p}"))?;
            ambid_twin::TwinConfig::from_toml_str(&text).with_context(|| format!("in {p}"))?
        }
        None => ambid_twin::TwinConfig::default(),
    };
    let twin = ambid_twin::Twin::new(cfg)?;
    let n: usize = o.num("period")?;
    let (fmin, fmax): (f64, f64) = (o.num("fmin")?, o.num("fmax")?);
    let df = twin.fs() / n as f64;
    let f: Vec<f64> = (1..=n / 2)
        .map(|k| k as f64 * df)
        .filter(|f| (fmin..=fmax).contains(f))
        .collect();
    Ok(json!({
        "f": f,
        "t_ry": re_im(&twin.t_ry_frf(&f)?),
        "s": re_im(&twin.sensitivity_frf(&f)?),
        "plant": re_im(&twin.plant_frf(&f)?),
    }))
}
