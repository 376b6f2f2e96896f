//! The FRF of a text record streamed from its file (`ambid frf` with Welch or period
//! averaging): memory for one block of rows, one Welch segment or one period and the running
//! sums, whatever the record's length.
//!
//! Three passes over the file ([`RowStream`], the CLI's table dialect):
//! 1. the length, the time column's first and last values, the extremes of `u` and `i` (for
//!    the saturation rails) and the period of `r` ([`PeriodScan`]: one block's memory);
//! 2. the uniform sampling of `t`, the saturation runs of `u` and `i` and, for period averaging,
//!    which channels are exactly periodic;
//! 3. the screening of `y` and `u − r` and the accumulation of the spectra
//!    ([`WelchAccumulator`], [`PeriodicAccumulator`]).
//!
//! Everything that [`analyze`](crate::analysis::analyze) does on the whole record is done here
//! with the same arithmetic, except the screening (abnormal samples), which needs a window of
//! the record: it runs on blocks of [`STREAM_BLOCK`] samples (26 s at 20 kHz), each with its
//! own robust noise floor. A record of at most one block gives bit-for-bit the spectra and FRFs
//! of the in-memory path; on a longer record the per-block screening can flag (and repair)
//! other samples than the whole-record screening, and when neither flags any the results are
//! again identical (both tested: a twin record of random rig 5, seed excitation, 6 periods; a
//! synthetic record of two blocks).
//! The noise record of `--noise` (output SNR) and the local methods (LPM, LRM) need the whole
//! record and keep the in-memory path.

use crate::analysis::{analyze_spectra, Checks, FrfAnalysis, FrfMethod, FrfSettings, Spectra};
use crate::error::{Context, Error, Result};
use crate::io::stream::RowStream;
use ambid_core::data::{AbnormalReport, LimitSource, SaturationOptions, SaturationReport};
use ambid_core::frf::periodic::PeriodicAccumulator;
use ambid_core::frf::welch::WelchAccumulator;
use ambid_core::signal::PeriodScan;
use std::path::Path;

/// Rows per block (screening block and read block): 2¹⁹ samples.
pub const STREAM_BLOCK: usize = 1 << 19;

/// Rows per block of the first two passes.
const SCAN_BLOCK: usize = 1 << 16;

/// The columns to read.
#[derive(Debug, Clone, Copy)]
pub struct StreamColumns<'a> {
    /// Excitation r.
    pub r: &'a str,
    /// Controller output u.
    pub u: &'a str,
    /// Measured output y.
    pub y: &'a str,
    /// Coil current, used when the file has it.
    pub i: Option<&'a str>,
}

/// Streaming saturation check with the rules of `ambid_core::data::check_saturation`.
struct SatRuns {
    name: String,
    limit: Option<f64>,
    opts: SaturationOptions,
    max: f64,
    min: f64,
    n: usize,
    /// (start, length, rail, value at the start) of the run being extended.
    cur: Option<(usize, usize, i8, f64)>,
    runs: Vec<(usize, usize, i8, f64)>,
}

impl SatRuns {
    fn new(name: &str, limit: Option<f64>, max: f64, min: f64) -> Self {
        Self {
            name: name.into(),
            limit,
            opts: SaturationOptions::default(),
            max,
            min,
            n: 0,
            cur: None,
            runs: Vec::new(),
        }
    }

    fn mark(&self, v: f64) -> i8 {
        match self.limit {
            Some(l) => {
                let at = l * (1.0 - self.opts.rel_tol);
                if v >= at {
                    1
                } else if v <= -at {
                    -1
                } else {
                    0
                }
            }
            None => {
                let tau = self.opts.flat_tol * self.max.abs().max(self.min.abs());
                if (self.max - v) <= tau {
                    1
                } else if (v - self.min) <= tau {
                    -1
                } else {
                    0
                }
            }
        }
    }

    fn min_run(&self) -> usize {
        if self.limit.is_some() {
            1
        } else {
            self.opts.min_run
        }
    }

    fn close(&mut self) {
        if let Some(run) = self.cur.take() {
            if run.2 != 0 && run.1 >= self.min_run() {
                self.runs.push(run);
            }
        }
    }

    fn push(&mut self, x: &[f64]) {
        for &v in x {
            let m = self.mark(v);
            match &mut self.cur {
                Some(run) if run.2 == m => run.1 += 1,
                _ => {
                    self.close();
                    self.cur = Some((self.n, 1, m, v));
                }
            }
            self.n += 1;
        }
    }

    fn finish(mut self) -> Result<SaturationReport> {
        if let Some(l) = self.limit {
            if !(l.is_finite() && l > 0.0) {
                return Err(Error::other(format!(
                    "saturation check of `{}`: the saturation limit must be finite and > 0 (the \
                     magnitude of the symmetric limit ±L), got {l}",
                    self.name
                )));
            }
        }
        self.close();
        let count = self.runs.iter().map(|r| r.1).sum::<usize>();
        let (upper, lower, source) = match self.limit {
            Some(l) => (Some(l), Some(-l), LimitSource::Given),
            None => {
                let level = |rail: i8| self.runs.iter().find(|r| r.2 == rail).map(|r| r.3);
                (level(1), level(-1), LimitSource::Detected)
            }
        };
        Ok(SaturationReport {
            n_samples: self.n,
            count,
            fraction: count as f64 / self.n as f64,
            runs: self.runs.iter().map(|r| (r.0, r.1)).collect(),
            upper,
            lower,
            source,
            min_run: self.min_run(),
        })
    }
}

/// Appends `b` (a block starting at sample `off`) to `a`.
fn merge(a: &mut AbnormalReport, b: AbnormalReport, off: usize) {
    a.n_samples += b.n_samples;
    a.nonfinite.extend(b.nonfinite.into_iter().map(|k| k + off));
    a.spikes.extend(b.spikes.into_iter().map(|k| k + off));
    a.stuck_runs
        .extend(b.stuck_runs.into_iter().map(|(s, l)| (s + off, l)));
    a.repaired += b.repaired;
}

/// The FRF analysis of the text record at `path`, streamed; `settings(n, ts, period)` gives the
/// settings for a record of `n` samples at sample time `ts` whose excitation `r` repeats every
/// `period` samples (found in the first pass by [`PeriodScan`] when `find_period`; `None` if it
/// does not repeat or was not looked for; only Welch and period averaging).
/// `fs` is the sampling rate when the file has no `t` column (and must agree with it when it
/// has one).
///
/// # Errors
/// Those of reading the file (named with the line and column), a non-uniform or missing time
/// base, a non-finite excitation, `u` or `i` (named with the line), and those of
/// [`analyze_spectra`].
///
/// # Example
/// ```
/// use ambid::analysis::{analyze, FrfSettings, Record};
/// use ambid::experiment::{run, Experiment};
/// use ambid::frf_stream::{analyze_csv, StreamColumns};
/// use ambid::io::{read_time, write_time_csv, TimeOptions};
/// let mut exp = Experiment::seed_paper(ambid_twin::Mode::Linear, 1e-7, 1);
/// exp.excitation.periods = 3;
/// let rec = run(&exp).unwrap().record;
/// let dir = std::env::temp_dir().join(format!("ambid-frfstream-doc-{}", std::process::id()));
/// std::fs::create_dir_all(&dir).unwrap();
/// let p = dir.join("data.csv");
/// write_time_csv(&p, &[("t", &rec.t), ("r", &rec.r), ("u", &rec.u), ("y", &rec.y)]).unwrap();
/// let cols = StreamColumns { r: "r", u: "u", y: "y", i: None };
/// let streamed = analyze_csv(&p, &cols, None, true, |_n, _ts, period| {
///     assert_eq!(period, Some(5115)); // the excitation's period, found in the file
///     Ok(FrfSettings::periodic(5115, 1))
/// })
///     .unwrap();
/// let d = read_time(&p, &TimeOptions::default()).unwrap();
/// let whole = Record {
///     r: d.column("r").unwrap(),
///     u: d.column("u").unwrap(),
///     y: d.column("y").unwrap(),
///     i: None,
///     fs: 1.0 / d.ts,
/// };
/// let in_memory = analyze(&whole, &FrfSettings::periodic(5115, 1), None).unwrap();
/// assert_eq!(streamed.frf, in_memory.frf); // bit for bit
/// ```
pub fn analyze_csv(
    path: &Path,
    cols: &StreamColumns<'_>,
    fs: Option<f64>,
    find_period: bool,
    settings: impl FnOnce(usize, f64, Option<usize>) -> Result<FrfSettings>,
) -> Result<FrfAnalysis> {
    let open = || RowStream::open(path);
    let st0 = open()?;
    let has_t = st0.names().iter().any(|n| n == "t");
    let has_i = cols
        .i
        .is_some_and(|i| i != "t" && st0.names().iter().any(|n| n == i));
    for c in [cols.r, cols.u, cols.y] {
        if c == "t" {
            return Err(Error::other(format!(
                "{}: `t` is the time column, not a signal",
                path.display()
            )));
        }
    }
    let mut names = vec![cols.r, cols.u, cols.y];
    if has_i {
        names.push(cols.i.unwrap_or("i"));
    }
    if has_t {
        names.push("t");
    }
    let idx = st0.indices(&names)?;
    let (ti, ii) = (has_t.then_some(names.len() - 1), has_i.then_some(3));
    let mut out: Vec<Vec<f64>> = vec![Vec::new(); names.len()];

    // pass 1: length, time span, extremes of u and i, finiteness
    let mut st = st0;
    let mut n = 0usize;
    let mut scan = find_period.then(PeriodScan::new);
    let (mut t0, mut t1) = (f64::NAN, f64::NAN);
    let mut ext = [(f64::NEG_INFINITY, f64::INFINITY); 2];
    loop {
        let rows = st.next_block(&idx, SCAN_BLOCK, &mut out)?;
        if rows == 0 {
            break;
        }
        let lines = st.block_lines();
        for (c, what) in [(
            0,
            "the excitation must be complete (repair or cut the record)",
        )]
        .into_iter()
        .chain([(
            1,
            "the saturation check needs every sample of u (repair or cut the record)",
        )])
        .chain(ii.map(|c| {
            (
                c,
                "the saturation check needs every sample of i (repair or cut the record)",
            )
        }))
        .chain(ti.map(|c| (c, "the time column must be complete")))
        {
            if let Some(k) = out[c].iter().position(|v| !v.is_finite()) {
                return Err(Error::input(format!(
                    "{}: line {}, column `{}`: not finite ({}); {what}",
                    path.display(),
                    lines[k],
                    names[c],
                    out[c][k]
                )));
            }
        }
        if let Some(sc) = scan.as_mut() {
            sc.push(&out[0]);
        }
        for (e, c) in ext.iter_mut().zip([Some(1), ii]) {
            if let Some(c) = c {
                for &v in &out[c] {
                    e.0 = e.0.max(v);
                    e.1 = e.1.min(v);
                }
            }
        }
        if let Some(c) = ti {
            if n == 0 {
                t0 = out[c][0];
            }
            t1 = out[c][rows - 1];
        }
        n += rows;
    }
    crate::analysis::check_frf_length(n, Some(&path.display().to_string()))?;
    let ts = match (has_t, fs) {
        (true, _) => {
            let ts = (t1 - t0) / (n - 1) as f64;
            if ts.is_nan() || ts <= 0.0 {
                return Err(Error::other(format!(
                    "{}: the `t` column must increase",
                    path.display()
                )));
            }
            ts
        }
        (false, Some(f)) if f.is_finite() && f > 0.0 => 1.0 / f,
        (false, Some(f)) => {
            return Err(Error::other(format!(
                "sample rate must be positive and finite, got {f}"
            )))
        }
        (false, None) => {
            return Err(Error::other(format!(
                "{}: no `t` column; give the sample rate (--fs) to read this file",
                path.display()
            )))
        }
    };
    crate::analysis::check_fs_matches(fs, ts)?;
    let settings = settings(n, ts, scan.and_then(PeriodScan::finish))?;
    let rate = 1.0 / ts;

    // exactly periodic channels (period averaging): found in pass 2 from the raw samples
    let period = match &settings.method {
        FrfMethod::Periodic {
            period_samples,
            skip_periods,
        } => Some((*period_samples, *skip_periods)),
        FrfMethod::Welch { .. } => None,
    };

    // pass 2: uniform time base, saturation runs, exact periodicity
    let mut st = open()?;
    let mut sat: Vec<SatRuns> = [("u", Some(1), ext[0]), ("i", ii, ext[1])]
        .into_iter()
        .filter_map(|(name, c, (mx, mn))| c.map(|_| SatRuns::new(name, settings.i_sat, mx, mn)))
        .collect();
    let sat_cols: Vec<usize> = [Some(1), ii].into_iter().flatten().collect();
    // first differing whole period (counted from the first analysed one) of r, u, y
    let mut first_period: Vec<Vec<f64>> = vec![Vec::new(); 3];
    let mut differs: [Option<usize>; 3] = [None; 3];
    let (mut k0, mut t_prev) = (0usize, f64::NAN);
    loop {
        let rows = st.next_block(&idx, SCAN_BLOCK, &mut out)?;
        if rows == 0 {
            break;
        }
        if let Some(c) = ti {
            let t = &out[c];
            for j in 0..rows {
                let g = k0 + j;
                if g > 0 {
                    let prev = if j == 0 { t_prev } else { t[j - 1] };
                    if ((t[j] - prev) - ts).abs() > 1e-6 * ts {
                        return Err(Error::other(format!(
                            "{}: the `t` column is not uniformly sampled (step at row {} is {} s, \
                             mean step {ts} s)",
                            path.display(),
                            g + 1,
                            t[j] - prev
                        )));
                    }
                }
            }
            t_prev = t[rows - 1];
        }
        for (s, &c) in sat.iter_mut().zip(&sat_cols) {
            s.push(&out[c]);
        }
        if let Some((np, skip)) = period {
            let start = skip * np;
            for (c, col) in out.iter().take(3).enumerate() {
                for (j, &v) in col.iter().enumerate() {
                    let g = k0 + j;
                    if g < start {
                        continue;
                    }
                    let (p, q) = ((g - start) / np, (g - start) % np);
                    if p == 0 {
                        first_period[c].push(v);
                    } else if differs[c].is_none() && v != first_period[c][q] {
                        differs[c] = Some(p);
                    }
                }
            }
        }
        k0 += rows;
    }
    let mut warnings = Vec::new();
    let mut saturation = Vec::new();
    for s in sat {
        let name = s.name.clone();
        let rep = s
            .finish()
            .with_context(|| format!("saturation check of `{name}`"))?;
        if rep.count > 0 {
            warnings.push(format!(
                "the FRF was computed from saturated data: `{name}` {}",
                rep.summary()
            ));
        }
        saturation.push((name, rep));
    }
    let u_saturated = saturation.iter().any(|(n, r)| n == "u" && r.count > 0);

    // pass 3: screening and accumulation
    enum Acc {
        Welch(Box<WelchAccumulator>, usize),
        Periodic(Box<PeriodicAccumulator>),
    }
    let mut acc = match &settings.method {
        FrfMethod::Periodic {
            period_samples,
            skip_periods,
        } => {
            let total = n / period_samples;
            let exact: Vec<bool> = differs
                .iter()
                .map(|d| d.is_none_or(|p| p >= total.saturating_sub(*skip_periods)))
                .collect();
            let opts = crate::analysis::periodic_options(
                *period_samples,
                *skip_periods,
                settings.incomplete_tail,
            );
            Acc::Periodic(Box::new(
                PeriodicAccumulator::new(3, &opts, exact)
                    .context("period-synchronous averaging")?,
            ))
        }
        FrfMethod::Welch { skip_samples, .. } => {
            let opts = crate::analysis::welch_options(&settings.method, rate, n)?;
            let acc = WelchAccumulator::new(3, &opts).context("Welch spectra")?;
            if opts.n_segments(n - skip_samples) == 0 {
                return Err(Error::from(opts.too_short(n - skip_samples)).context("Welch spectra"));
            }
            Acc::Welch(Box::new(acc), *skip_samples)
        }
    };
    let mut st = open()?;
    let screen = settings.screen;
    let mut ry = AbnormalReport::default();
    let mut rc = AbnormalReport::default();
    let mut k0 = 0usize;
    loop {
        let rows = st.next_block(&idx, STREAM_BLOCK, &mut out)?;
        if rows == 0 {
            break;
        }
        let r = &out[0];
        let (u, y) = if screen {
            let (u2, y2, bc, by) =
                crate::analysis::screen_channels(r, &out[1], &out[2], u_saturated)?;
            merge(&mut ry, by, k0);
            merge(&mut rc, bc, k0);
            (u2, y2)
        } else {
            (out[1].clone(), out[2].clone())
        };
        match &mut acc {
            Acc::Welch(w, skip) => {
                let from = skip.saturating_sub(k0).min(rows);
                w.push(&[&r[from..], &u[from..], &y[from..]])
                    .context("Welch spectra")?;
            }
            Acc::Periodic(p) => p
                .push(&[&r[..], &u[..], &y[..]])
                .context("period-synchronous averaging")?,
        }
        k0 += rows;
    }
    let mut abnormal = Vec::new();
    if screen {
        for (name, rep) in [("y", &ry), ("u - r", &rc)] {
            if !rep.is_clean() {
                warnings.push(format!("{name}: {}", rep.summary()));
            }
        }
        abnormal.push(("y".to_string(), ry));
        abnormal.push(("u - r".to_string(), rc));
    }
    let spectra = match &mut acc {
        Acc::Welch(w, _) => Spectra::Welch(w.finish().context("Welch spectra")?),
        Acc::Periodic(p) => {
            Spectra::Periodic(p.finish(rate).context("period-synchronous averaging")?)
        }
    };
    analyze_spectra(
        spectra,
        &settings,
        Checks {
            snr: None,
            abnormal,
            saturation,
            warnings,
        },
    )
}
