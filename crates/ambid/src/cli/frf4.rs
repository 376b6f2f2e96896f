//! `ambid frf EXP1 EXP2 …`: the MIMO closed-loop FRF ([`ambid_core::frf::mimo`]) of several
//! experiment files (sequential or orthogonal designs) or of one zippered file, written as a
//! matrix FRF CSV (docs/formats.md, "Matrix FRF").
//!
//! **Which path.** Several files always take this path; one file takes it with `--axes N`
//! (N > 1), or when it has no column `--excitation` (default `r`) but an `r_<axis>` column
//! (`r_xa`, `r_xb`, `r_ya`, `r_yb`); everything else is the single-axis `ambid frf` unchanged.
//!
//! **Channels.** The axes are those of the first file's `r_<axis>` columns (axis order
//! `xa, xb, ya, yb`); every file must hold `r_<axis>`, `u_<axis>` and `y_<axis>` for each of them
//! (and no `u_<axis>` without its `r_<axis>`). Every file is read by the one reader of every
//! command (any supported format, docs/data-files.md); the files must share the sample rate and
//! the length.
//!
//! **Lines.** Every line some input excites (`frf::mimo`'s rule) within `--band`, by default the
//! band the single-axis `frf` derives from the excitation: the lines whose summed excitation
//! power (over the inputs and experiments) is within 10 dB of the strongest.
//!
//! **Period.** `--period-samples`, else derived from the excitation: the smallest $N \le L/2$
//! with $r_j[k + N] = r_j[k]$ (to $10^{-9}$ of the column's peak) for every non-constant
//! `r` column of every file ($L$ samples per file; `ambid_core::signal::detect_period`); a record whose excitation does not repeat
//! is refused (the MIMO FRF needs periodic excitation).

use super::frf::FrfArgs;
use super::simulate4::matrix_frf_csv;
use ambid::error::Error;
use ambid::io::table::Format;
use ambid::io::{OutputSet, TimeData};
use ambid_core::data::{IoData, AXES};
use ambid_core::frf::band::{excitation_bands, BandRule, ExcitationBands};
use ambid_core::frf::mimo::{self, MimoClosedLoopFrf, MimoDesign, MimoOptions};
use ambid_core::frf::mimo_lpm::{local_polynomial, MimoLpmOptions};
use ambid_core::frf::synchronous::{
    synchronous, SynchronousLine, SynchronousMethod, SynchronousOptions,
};
use ambid_core::signal::amplitude_spectrum;
use ambid_core::signal::detect_period;
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// Whether `ambid frf` takes the MIMO path for these arguments (module docs).
///
/// # Errors
/// `--axes 1` with several files.
pub fn is_mimo(a: &FrfArgs) -> Result<bool> {
    match (a.axes, a.files.len()) {
        (Some(1), n) if n > 1 => Err(Error::usage(format!(
            "--axes 1 takes one data file, and {n} were given; several files are the experiments \
             of a multi-axis FRF: leave --axes out (or give --axes 4)"
        ))
        .into()),
        (Some(1), _) => Ok(false),
        (Some(0), _) => Err(Error::usage("--axes must be at least 1").into()),
        (Some(_), _) => Ok(true),
        (None, n) if n > 1 => Ok(true),
        (None, _) => Ok(single_file_is_mimo(a)),
    }
}

/// One file: MIMO when it has no `--excitation` column but an `r_<axis>` column. A file that
/// cannot be read is left to the single-axis path (which reports it as it always has).
fn single_file_is_mimo(a: &FrfArgs) -> bool {
    let path = &a.files[0];
    let decide = |names: &[String]| {
        !names.contains(&a.r.excitation)
            && AXES
                .iter()
                .any(|ax| names.iter().any(|n| *n == format!("r_{ax}")))
    };
    let text = Format::of_file(path, a.file.file.format).is_ok_and(|f| f == Format::Text)
        && a.file.file.time.is_none();
    if text {
        ambid::io::stream::RowStream::open(path).is_ok_and(|s| decide(s.names()))
    } else {
        a.file.read(path).is_ok_and(|d| decide(&d.names))
    }
}

/// Refuses the single-axis options that the MIMO path does not take.
fn refuse_siso_options(a: &FrfArgs) -> Result<()> {
    use super::frf::MethodArg;
    let bad: &[(bool, &str, &str)] = &[
        (
            a.controller.is_some(),
            "--controller",
            "the indirect plant needs the 4×4 controller response, which a controller file (one \
             SISO controller) does not give; the joint estimate P = T_ry S⁻¹ is written",
        ),
        (
            a.method == MethodArg::Lrm,
            "--method lrm",
            "the local rational method is single-axis; the multi-axis FRF takes the period \
             average (periodic excitation) or --method lpm (non-periodic)",
        ),
        (
            super::frf::welch_options(a) || a.method == MethodArg::Welch,
            "--method welch/--nperseg/--noverlap/--window/--skip-samples",
            "Welch averaging is single-axis; the multi-axis FRF averages periods",
        ),
        (a.noise.is_some(), "--noise", "no output SNR is computed"),
        (
            a.quality_band.is_some(),
            "--quality-band",
            "the summary covers every line written",
        ),
        (
            a.method != MethodArg::Lpm && (a.lpm_degree.is_some() || a.lpm_half_width.is_some()),
            "--lpm-degree/--lpm-half-width",
            "they set the local polynomial method: add --method lpm",
        ),
        (
            a.method == MethodArg::Lpm && a.speed_rpm.is_some(),
            "--speed-rpm",
            "the synchronous line is separated from a periodic excitation's response by the \
             period average; with --method lpm the 1× line stays in the record",
        ),
    ];
    if let Some((_, opt, why)) = bad.iter().find(|b| b.0) {
        return Err(Error::usage(format!(
            "{opt} is not available for a multi-axis FRF (several files or r_<axis> columns): \
             {why}; leave it out"
        ))
        .into());
    }
    Ok(())
}

/// The axes of the record: those with an `r_<axis>` column in the first file, every file with
/// `r_`, `u_`, `y_` of each.
fn check_axes(files: &[TimeData]) -> Result<Vec<&'static str>> {
    let first = &files[0];
    let has = |d: &TimeData, c: &str| d.has(c);
    let axes: Vec<&'static str> = AXES
        .iter()
        .copied()
        .filter(|ax| has(first, &format!("r_{ax}")))
        .collect();
    if axes.is_empty() {
        return Err(Error::input(format!(
            "{}: no excitation column r_xa, r_xb, r_ya or r_yb; a multi-axis FRF needs one \
             `r_<axis>` column per excited axis beside its `u_<axis>` and `y_<axis>` (the file \
             has: {})",
            first.path.display(),
            first.names.join(", ")
        ))
        .into());
    }
    for d in files {
        for ax in AXES {
            let (r, u) = (format!("r_{ax}"), format!("u_{ax}"));
            if has(d, &r) && !axes.contains(&ax) {
                return Err(Error::input(format!(
                    "{} has the excitation column `{r}`, {} has not: every experiment must excite \
                     the same axes (give every file the columns r_, u_, y_ of the same axes)",
                    d.path.display(),
                    first.path.display()
                ))
                .into());
            }
            if has(d, &u) && !axes.contains(&ax) {
                let (nr, nu) = (
                    AXES.iter().filter(|a| has(d, &format!("r_{a}"))).count(),
                    AXES.iter().filter(|a| has(d, &format!("u_{a}"))).count(),
                );
                return Err(Error::input(format!(
                    "{}: `{u}` has no excitation column `{r}` ({nr} r_ column(s), {nu} u_ \
                     column(s)): the excitation is added to every controller output, so give one \
                     `r_<axis>` per `u_<axis>` (a zero column for an axis that is not excited)",
                    d.path.display()
                ))
                .into());
            }
        }
        for ax in &axes {
            for q in ["r", "u", "y"] {
                let c = format!("{q}_{ax}");
                if !has(d, &c) {
                    return Err(Error::input(format!(
                        "{}: the column `{c}` is missing; a {}-axis experiment needs r_, u_ and y_ \
                         for every axis ({}) — the file has: {}",
                        d.path.display(),
                        axes.len(),
                        axes.join(", "),
                        d.names.join(", ")
                    ))
                    .into());
                }
            }
        }
    }
    Ok(axes)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

/// The band of the lines written when `--band` is not given, as the single-axis `frf` derives
/// it ([`excitation_bands`] with the default [`BandRule`]): the lines within 10 dB of the
/// strongest, the power of line $k$ being $\sum_{e, j} A_{j,e}(k)^2$ over the inputs $j$ and
/// experiments $e$ ($A$ the amplitude spectrum of one period of `r_<axis>`).
fn derived_band(data: &IoData, n_inputs: usize, period: usize) -> Result<ExcitationBands> {
    let mut power: Vec<f64> = Vec::new();
    let mut f: Vec<f64> = Vec::new();
    for e in 0..data.n_experiments() {
        let ex = data.experiment(e).map_err(ambid::error::Error::from)?;
        for ch in ex.channels().iter().take(n_inputs) {
            let x = ch.1.get(..period).ok_or_else(|| {
                Error::input(format!(
                    "the record ({} samples) is shorter than one period ({period} samples); give \
                     the right --period-samples",
                    ch.1.len()
                ))
            })?;
            let (fk, ak) = amplitude_spectrum(x, data.ts()).map_err(ambid::error::Error::from)?;
            if power.is_empty() {
                power = vec![0.0; ak.len()];
                f = fk;
            }
            power.iter_mut().zip(&ak).for_each(|(p, a)| *p += a * a);
        }
    }
    Ok(excitation_bands(&f, &power, 1, &BandRule::default()).map_err(ambid::error::Error::from)?)
}

/// Pairs of files whose excitation columns are identical (the same experiment twice).
fn identical_excitations(files: &[TimeData], axes: &[&str]) -> Option<(usize, usize)> {
    for i in 0..files.len() {
        for j in i + 1..files.len() {
            if axes.iter().all(|ax| {
                let c = format!("r_{ax}");
                files[i].column_raw(&c).ok() == files[j].column_raw(&c).ok()
            }) {
                return Some((i, j));
            }
        }
    }
    None
}

/// Runs the MIMO `ambid frf` (module docs).
pub fn frf4(a: &FrfArgs) -> Result<()> {
    refuse_siso_options(a)?;
    OutputSet::check(&a.out, a.f.force)?;
    let mut files = Vec::with_capacity(a.files.len());
    for p in &a.files {
        let d = a.file.read(p)?;
        ambid::analysis::check_fs_matches(a.file.fs, d.ts)
            .with_context(|| format!("{}", p.display()))?;
        files.push(d);
    }
    let axes = check_axes(&files)?;
    if let Some(n) = a.axes.filter(|&n| n as usize != axes.len()) {
        return Err(Error::input(format!(
            "--axes {n}, but {} has the excitation columns of {} axes ({}); give --axes {} or \
             the files of the {n} axes",
            a.files[0].display(),
            axes.len(),
            axes.join(", "),
            axes.len()
        ))
        .into());
    }
    let (d0, p0) = (&files[0], &a.files[0]);
    let len0 = d0.columns.first().map_or(0, Vec::len);
    for (d, p) in files.iter().zip(&a.files).skip(1) {
        if ((d.ts - d0.ts) / d0.ts).abs() > 1e-9 {
            return Err(Error::input(format!(
                "{} is sampled at {} Hz, {} at {} Hz (from their `t` columns): every experiment \
                 must be recorded at one sample rate; resample, or pass the files of one rate",
                p.display(),
                1.0 / d.ts,
                p0.display(),
                1.0 / d0.ts
            ))
            .into());
        }
        let len = d.columns.first().map_or(0, Vec::len);
        if len != len0 {
            return Err(Error::input(format!(
                "{} has {len} samples, {} has {len0}: every experiment must have the same length \
                 (the same number of periods); record them alike or cut them to the shortest",
                p.display(),
                p0.display()
            ))
            .into());
        }
    }
    // every sample a number (the message names the file, the column and the row)
    let mut records = Vec::with_capacity(files.len());
    for d in &files {
        let mut ch = Vec::with_capacity(3 * axes.len());
        for q in ["r", "u", "y"] {
            for ax in &axes {
                let c = format!("{q}_{ax}");
                ch.push((c.clone(), d.column(&c)?.to_vec()));
            }
        }
        records.push(ch);
    }
    let lpm = a.method == super::frf::MethodArg::Lpm;
    let period = match a.period_samples {
        _ if lpm => 0,
        Some(0) => return Err(Error::usage("--period-samples must be at least 1").into()),
        Some(p) => p,
        None => {
            let rs: Vec<&[f64]> = records
                .iter()
                .flat_map(|ch| ch[..axes.len()].iter().map(|c| c.1.as_slice()))
                .collect();
            match detect_period(&rs) {
                Some(p) => {
                    println!(
                        "period: {p} samples (the excitation repeats every {p} samples; give \
                         --period-samples to override)"
                    );
                    p
                }
                None => {
                    return Err(Error::input(format!(
                        "the excitation of {} is not periodic (no period of at most half the \
                         record repeats in every r_ column): the multi-axis FRF averages periods \
                         of a periodic excitation; give --period-samples N if it is periodic \
                         with N samples, use --method lpm (the local polynomial method) for a \
                         non-periodic excitation (noise, chirps), or record a periodic design \
                         (`ambid simulate --axes 4`, docs/signals.md)",
                        a.files
                            .iter()
                            .map(|p| p.display().to_string())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                    .into())
                }
            }
        }
    };
    let m = records.len();
    if m > 1 && m < axes.len() && !lpm {
        return Err(Error::input(format!(
            "{m} experiment files for {} excited axes ({}): the MIMO FRF solves T_ry and S per \
             line from at least as many experiments as inputs; give {} files (a sequential or \
             orthogonal design, `ambid simulate --axes 4 --design sequential`) or one zippered \
             file",
            axes.len(),
            axes.join(", "),
            axes.len()
        ))
        .into());
    }
    let ts = d0.ts;
    let mut exps = Vec::with_capacity(m);
    for (ch, p) in records.into_iter().zip(&a.files) {
        exps.push(
            IoData::new(ch, ts, (!lpm).then_some(period))
                .map_err(ambid::error::Error::from)
                .with_context(|| format!("{}", p.display()))?,
        );
    }
    let data = IoData::from_experiments(exps).map_err(ambid::error::Error::from)?;
    let names = a
        .files
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ");
    let mut extra_files: Vec<(PathBuf, Vec<u8>)> = Vec::new();
    let (data, sync) = match a.speed_rpm {
        None => (data, None),
        Some(rpm) => {
            let (clean, bytes, line) =
                synchronous_line(&data, rpm, period, a.skip_periods, &names)?;
            extra_files.push((sync_path(&a.out), bytes));
            (clean, Some(line))
        }
    };
    let est = if lpm {
        let mut lo = MimoLpmOptions::new();
        if let Some(r) = a.lpm_degree {
            lo.degree = r;
        }
        lo.half_width = a.lpm_half_width;
        lo.band = a.b.band;
        local_polynomial(&data, &lo)
            .map_err(ambid::error::Error::from)
            .with_context(|| format!("the MIMO local polynomial FRF of {names}"))?
    } else {
        let mut est = periodic_estimate(a, &data, &files, &axes, period, &names)?;
        // what the 1× removal leaves at the lines beside it, which the periods' spread misses
        // (`SynchronousLine::variance_factor`)
        if let Some(line) = &sync {
            line.widen_estimate(&mut est, data.fs(), period)
                .map_err(ambid::error::Error::from)?;
        }
        est
    };
    write_estimate(a, &est, &axes, period, &names, ts, extra_files)
}

/// `<out>` with `_sync` before the extension.
fn sync_path(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = out
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    out.with_file_name(format!("{stem}_sync{ext}"))
}

/// Measures the 1× line at `rpm`/60 Hz on every u and y channel (printed, and as CSV bytes:
/// `experiment, channel, f_hz, re, im, abs, phase_deg, std`) and returns the record without it
/// and the line.
fn synchronous_line(
    data: &IoData,
    rpm: f64,
    period: usize,
    skip: usize,
    names: &str,
) -> Result<(IoData, Vec<u8>, SynchronousLine)> {
    if !(rpm.is_finite() && rpm > 0.0) {
        return Err(Error::usage(format!(
            "--speed-rpm must be a positive speed, got {rpm}; leave it out at standstill"
        ))
        .into());
    }
    let f = rpm / 60.0;
    let opts = SynchronousOptions::new().period(period).skip(skip);
    let line = synchronous(data, f, &opts)
        .map_err(ambid::error::Error::from)
        .with_context(|| format!("the synchronous (1×) line at {f} Hz of {names}"))?;
    let how = match line.method {
        SynchronousMethod::Regression => format!(
            "cos/sin regression after removing the period mean ({:+.3} lines off the period \
             grid)",
            line.grid_offset
        ),
        SynchronousMethod::PeriodLine { line: k } => {
            format!("on the unexcited period line {k}: its period-mean DFT")
        }
    };
    println!("synchronous line: {f:.4} Hz ({rpm} rpm), {how}; removed from u and y before the FRF");
    let mut csv = String::from("experiment,channel,f_hz,re,im,abs,phase_deg,std\n");
    for c in &line.channels {
        println!(
            "  experiment {} {}: |A| {:.4e} ∠ {:.2}° ± {:.2e}",
            c.experiment + 1,
            c.name,
            c.amplitude.norm(),
            c.amplitude.arg().to_degrees(),
            c.std
        );
        csv.push_str(&format!(
            "{},{},{:e},{:e},{:e},{:e},{:e},{:e}\n",
            c.experiment + 1,
            c.name,
            f,
            c.amplitude.re,
            c.amplitude.im,
            c.amplitude.norm(),
            c.amplitude.arg().to_degrees(),
            c.std
        ));
    }
    let clean = line.remove(data).map_err(ambid::error::Error::from)?;
    Ok((clean, csv.into_bytes(), line))
}

/// The period-averaged estimate (`frf::mimo::estimate`) in the band of `--band` or the one
/// derived from the excitation.
fn periodic_estimate(
    a: &FrfArgs,
    data: &IoData,
    files: &[TimeData],
    axes: &[&str],
    period: usize,
    names: &str,
) -> Result<MimoClosedLoopFrf> {
    let mut opts = MimoOptions::new().period(period).skip(a.skip_periods);
    let band = match a.b.band {
        Some(b) => b,
        None => {
            let d = derived_band(data, axes.len(), period)?;
            println!("band: {}", d.describe());
            d.excited
        }
    };
    opts = opts.band(band.0, band.1);
    let est = match mimo::estimate(data, &opts) {
        Ok(e) => e,
        Err(e) => {
            let e = ambid::error::Error::from(e);
            return Err(match identical_excitations(files, axes) {
                Some((i, j)) => anyhow::Error::from(e).context(format!(
                    "{} and {} have the same excitation: the same experiment twice? The input \
                     matrix of the experiments must have full rank on every line — give \
                     experiments whose excitations differ (sequential: one axis each; \
                     orthogonal: the Hadamard signs)",
                    a.files[i].display(),
                    a.files[j].display()
                )),
                None => anyhow::Error::from(e).context(format!("the MIMO FRF of {names}")),
            });
        }
    };
    Ok(est)
}

/// Writes the matrix FRF CSV (and `extra_files`, all or nothing) and prints the summary.
fn write_estimate(
    a: &FrfArgs,
    est: &MimoClosedLoopFrf,
    axes: &[&str],
    period: usize,
    names: &str,
    ts: f64,
    extra_files: Vec<(PathBuf, Vec<u8>)>,
) -> Result<()> {
    let f = est.f_hz().to_vec();
    let nl = f.len();
    let (ny, nu) = (est.plant.ny(), est.plant.nu());
    let coh: Vec<Vec<f64>> = (0..ny)
        .map(|i| (0..nl).map(|k| est.coherence[k * ny + i]).collect())
        .collect();
    let meas: Vec<Vec<f64>> = (0..nu)
        .map(|j| {
            (0..nl)
                .map(|k| f64::from(u8::from(est.measured[k * nu + j])))
                .collect()
        })
        .collect();
    let fs_col = vec![1.0 / ts; nl];
    let coh_names: Vec<String> = axes.iter().map(|ax| format!("coh_{ax}")).collect();
    let meas_names: Vec<String> = axes.iter().map(|ax| format!("measured_{ax}")).collect();
    let mut extras: Vec<(&str, &[f64])> = coh_names
        .iter()
        .zip(&coh)
        .map(|(n, c)| (n.as_str(), c.as_slice()))
        .collect();
    extras.push(("cond_r", &est.cond_r));
    extras.push(("cond_u", &est.cond_u));
    let zipper = est.design == MimoDesign::Zippered;
    if zipper {
        extras.extend(
            meas_names
                .iter()
                .zip(&meas)
                .map(|(n, c)| (n.as_str(), c.as_slice())),
        );
    }
    extras.push(("fs_hz", &fs_col));
    let bytes = matrix_frf_csv(
        &f,
        axes,
        &[("P", &est.plant), ("T_ry", &est.t_ry), ("S", &est.s)],
        &extras,
    )?;
    // summary
    let design = match est.design {
        MimoDesign::Experiments(k) => format!("{k} experiments (sequential/orthogonal)"),
        MimoDesign::Zippered => "one zippered experiment".to_string(),
        MimoDesign::LocalPolynomial { degree, half_width } => format!(
            "local polynomial method (degree {degree}, {} lines per window, {} residual degrees \
             of freedom)",
            2 * half_width + 1,
            est.dof
        ),
    };
    println!(
        "MIMO closed-loop FRF, {}×{} ({}): {design}: {names}",
        ny,
        nu,
        axes.join(", ")
    );
    if matches!(est.design, MimoDesign::LocalPolynomial { .. }) {
        println!(
            "{nl} lines in {:.1}–{:.1} Hz",
            f.first().copied().unwrap_or(f64::NAN),
            f.last().copied().unwrap_or(f64::NAN)
        );
    } else {
        println!(
            "period averaging: {} periods of {period} samples per experiment ({} skipped), {nl} \
             lines in {:.1}–{:.1} Hz",
            est.periods,
            a.skip_periods,
            f.first().copied().unwrap_or(f64::NAN),
            f.last().copied().unwrap_or(f64::NAN)
        );
    }
    let worst = |v: &[f64]| v.iter().copied().fold(0.0f64, f64::max);
    println!(
        "condition numbers: input matrix R worst {:.3}, U worst {:.3}",
        worst(&est.cond_r),
        worst(&est.cond_u)
    );
    let cohs: Vec<String> = axes
        .iter()
        .zip(&coh)
        .map(|(ax, c)| format!("{ax} {:.4}", median(c.clone())))
        .collect();
    println!("median multiple coherence per output: {}", cohs.join(", "));
    if zipper {
        println!(
            "zippered: each column of T_ry and S measured on its own lines (measured_<axis> = 1), \
             interpolated on the others; P uses all columns on every line"
        );
    }
    let mut set = OutputSet::new(a.f.force);
    set.write(&a.out, &bytes)?;
    for (p, b) in &extra_files {
        set.write(p, b)?;
    }
    set.commit()?;
    println!("written: {}", a.out.display());
    for (p, _) in &extra_files {
        println!("written: {}", p.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use ambid_core::signal::detect_period;

    #[test]
    fn the_period_is_the_smallest_exact_repeat_of_every_varying_column() {
        let base = [0.3, -1.0, 1.0, 1.0, -1.0, 0.5, 0.0];
        let a: Vec<f64> = (0..3 * 7).map(|k| base[k % 7]).collect();
        let b: Vec<f64> = (0..3 * 7).map(|k| -2.0 * base[(k + 3) % 7]).collect();
        let zero = vec![0.0; 21];
        assert_eq!(detect_period(&[&a, &zero, &b]), Some(7));
        // a column repeating every 14 samples only: the common period is 14 (not ≤ L/2 = 10)
        let c: Vec<f64> = (0..21)
            .map(|k| if k % 14 == 3 { 1.0 } else { 0.0 })
            .collect();
        assert_eq!(detect_period(&[&a, &c]), None);
        // a record of 4 periods of 14 samples: 14
        let c: Vec<f64> = (0..56)
            .map(|k| if k % 14 == 3 { 1.0 } else { 0.0 })
            .collect();
        let a: Vec<f64> = (0..56).map(|k| base[k % 7]).collect();
        assert_eq!(detect_period(&[&a, &c]), Some(14));
        // nothing varies, or nothing repeats
        assert_eq!(detect_period(&[&zero]), None);
        let mut x = 1u64;
        let noise: Vec<f64> = (0..200)
            .map(|_| {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
                (x >> 11) as f64
            })
            .collect();
        assert_eq!(detect_period(&[&noise]), None);
    }
}
