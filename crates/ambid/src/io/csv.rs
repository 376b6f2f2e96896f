//! CSV time data and FRF files.
//!
//! Time data: a header row, one column per signal, SI units. An optional `t` column holds the
//! time in seconds; without it the sample rate must be given by the caller. Numbers are written
//! with 17 significant digits so a file read back reproduces the `f64` values exactly.
//!
//! FRF data: `f_hz, <q>_re, <q>_im, <q>_std, …` per quantity `q`, plus optional real columns such
//! as `coh_ry`.

use super::table::{read_table, ColumnRef, DataFileError, Format, ReadOptions};
use anyhow::{anyhow, bail, Result};
use num_complex::Complex64;
use std::path::{Path, PathBuf};

/// Time-domain data read from a file: named columns of equal length and the sample time.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeData {
    /// The file the data were read from (named in messages).
    pub path: PathBuf,
    /// Sample time in seconds.
    pub ts: f64,
    /// Column names in file order (without `t`).
    pub names: Vec<String>,
    /// Column values, same order as `names`.
    pub columns: Vec<Vec<f64>>,
}

/// The largest magnitude a signal sample may have: sums of squares of up to 2²⁸ samples of
/// this size stay far below `f64::MAX` (≈ 1.8·10³⁰⁸), so a larger (finite) value is refused at
/// the reader instead of overflowing to ±inf inside a computation.
pub const MAX_SAMPLE_MAGNITUDE: f64 = 1e100;

impl TimeData {
    /// The column called `name` with every sample finite: an error names the file, the column
    /// and the 1-based data row (rows after the header; comment and blank lines are not
    /// counted) of the first NaN, ±inf or missing value, or lists the available columns.
    pub fn column(&self, name: &str) -> Result<&[f64]> {
        let x = self.column_raw(name)?;
        if let Some(k) = x.iter().position(|v| !v.is_finite()) {
            return Err(DataFileError::Invalid {
                path: self.path.clone(),
                message: format!(
                    "column `{name}`, data row {} (counted after the header, without comment lines): the value is {}; every sample must be a number for this command: repair or cut the record (`ambid frf` screens and repairs missing samples)",
                    k + 1,
                    if x[k].is_nan() { "missing or NaN".to_string() } else { format!("{}", x[k]) }
                ),
            }
            .into());
        }
        Ok(x)
    }

    /// The column called `name` if the file has one, with every sample finite (as
    /// [`TimeData::column`]: a NaN is an error, not a reason to drop the column).
    pub fn optional_column(&self, name: &str) -> Result<Option<&[f64]>> {
        if self.names.iter().any(|n| n == name) {
            self.column(name).map(Some)
        } else {
            Ok(None)
        }
    }

    /// The column called `name` as read, missing samples as NaN (for the screening of
    /// `ambid frf`), or an error listing the available columns.
    pub fn column_raw(&self, name: &str) -> Result<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|k| self.columns[k].as_slice())
            .ok_or_else(|| {
                anyhow!(DataFileError::Invalid {
                    path: self.path.clone(),
                    message: if self.names.iter().enumerate().all(|(j, n)| *n == format!("col{}", j + 1)) {
                        format!(
                            "unknown column `{name}`; the file has no header row, so its columns are {}: add a header row naming them (e.g. `t,r,u,y`), or select these names",
                            self.names.join(", ")
                        )
                    } else {
                        format!(
                            "unknown column `{name}`; the file has columns: {}",
                            self.names.join(", ")
                        )
                    },
                })
            })
    }
}

/// Writes equal-length columns with a header row. Errors on unequal lengths. The file is
/// replaced atomically (written beside it, then renamed); commands use [`time_csv_bytes`] with
/// an [`OutputSet`](crate::io::output::OutputSet) instead, to write all their outputs as a set.
pub fn write_time_csv(path: &Path, columns: &[(&str, &[f64])]) -> Result<()> {
    let mut set = crate::io::output::OutputSet::new(true);
    set.write_with(path, |w| time_csv_to(w, columns))?;
    set.commit()?;
    Ok(())
}

/// The CSV text of [`write_time_csv`]. Errors on unequal lengths.
pub fn time_csv_bytes(columns: &[(&str, &[f64])]) -> Result<Vec<u8>> {
    let mut v = Vec::new();
    time_csv_to(&mut v, columns)?;
    Ok(v)
}

/// Streams the CSV text of [`write_time_csv`] into `w` (for
/// [`OutputSet::write_with`](crate::io::output::OutputSet::write_with): a long record is never
/// held as text in memory). Unequal lengths are an [`std::io::ErrorKind::InvalidInput`] error.
pub fn time_csv_to(w: &mut dyn std::io::Write, columns: &[(&str, &[f64])]) -> std::io::Result<()> {
    let n = columns.first().map_or(0, |c| c.1.len());
    if let Some((name, c)) = columns.iter().find(|c| c.1.len() != n) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "column `{name}` has {} samples but the first column has {n}",
                c.len()
            ),
        ));
    }
    let mut w = ::csv::Writer::from_writer(w);
    w.write_record(columns.iter().map(|c| c.0))
        .map_err(csv_io)?;
    let mut row = Vec::with_capacity(columns.len());
    for k in 0..n {
        row.clear();
        row.extend(columns.iter().map(|c| format!("{:.17e}", c.1[k])));
        w.write_record(&row).map_err(csv_io)?;
    }
    w.flush()
}

/// A CSV writer's error as the I/O error it wraps.
fn csv_io(e: ::csv::Error) -> std::io::Error {
    match e.into_kind() {
        ::csv::ErrorKind::Io(e) => e,
        k => std::io::Error::other(format!("{k:?}")),
    }
}

/// One complex FRF quantity for [`write_frf_csv`]: name (e.g. `t_ry`), values, optional standard
/// deviation of the complex estimate (written as 0 when absent, meaning exact).
pub struct FrfColumn<'a> {
    /// Quantity name, used as the column prefix.
    pub name: &'a str,
    /// Complex values at each frequency.
    pub values: &'a [Complex64],
    /// Standard deviation $\sqrt{E|\hat G - G|^2}$ at each frequency, if known.
    pub std: Option<&'a [f64]>,
}

/// Writes an FRF CSV: `f_hz`, then `<q>_re, <q>_im, <q>_std` for each quantity.
pub fn write_frf_csv(path: &Path, f_hz: &[f64], quantities: &[FrfColumn<'_>]) -> Result<()> {
    write_frf_csv_with(path, f_hz, quantities, &[])
}

/// Writes an FRF CSV with extra real columns after the quantities (e.g. `coh_ry`, `coh_ru`),
/// replacing the file atomically (see [`write_time_csv`]).
pub fn write_frf_csv_with(
    path: &Path,
    f_hz: &[f64],
    quantities: &[FrfColumn<'_>],
    extras: &[(&str, &[f64])],
) -> Result<()> {
    let bytes = frf_csv_bytes(f_hz, quantities, extras)?;
    let mut set = crate::io::output::OutputSet::new(true);
    set.write(path, &bytes)?;
    set.commit()?;
    Ok(())
}

/// The CSV text of [`write_frf_csv_with`].
pub fn frf_csv_bytes(
    f_hz: &[f64],
    quantities: &[FrfColumn<'_>],
    extras: &[(&str, &[f64])],
) -> Result<Vec<u8>> {
    if let Some((name, v)) = extras.iter().find(|e| e.1.len() != f_hz.len()) {
        bail!(
            "FRF column `{name}` has {} values but there are {} frequencies",
            v.len(),
            f_hz.len()
        );
    }
    for q in quantities {
        if q.values.len() != f_hz.len() || q.std.is_some_and(|s| s.len() != f_hz.len()) {
            bail!(
                "FRF quantity `{}` has {} values but there are {} frequencies",
                q.name,
                q.values.len(),
                f_hz.len()
            );
        }
    }
    let mut w = ::csv::Writer::from_writer(Vec::new());
    let mut header = vec!["f_hz".to_string()];
    for q in quantities {
        for s in ["re", "im", "std"] {
            header.push(format!("{}_{s}", q.name));
        }
    }
    header.extend(extras.iter().map(|e| e.0.to_string()));
    w.write_record(&header)?;
    for (k, f) in f_hz.iter().enumerate() {
        let mut row = vec![format!("{f:.17e}")];
        for q in quantities {
            let v = q.values[k];
            row.push(format!("{:.17e}", v.re));
            row.push(format!("{:.17e}", v.im));
            row.push(format!("{:.17e}", q.std.map_or(0.0, |s| s[k])));
        }
        row.extend(extras.iter().map(|e| format!("{:.17e}", e.1[k])));
        w.write_record(&row)?;
    }
    w.into_inner().map_err(|e| anyhow!("{}", e.error()))
}

/// Reads a time-data CSV (any delimited text file in the one text dialect of
/// [`crate::io::table`], see `docs/data-files.md`: `#`/`%` comment lines, detected delimiter,
/// quoted cells, a header row detected; without one the columns are `col1`, `col2`, …). A
/// header names every column once. The
/// sample time comes from the `t` column when present (it must be strictly increasing and
/// uniform), otherwise from `fs_hz`. `NaN`, `inf` and empty fields in a signal column are read as
/// missing samples (NaN): [`TimeData::column`] refuses them with the file, row and column,
/// [`TimeData::column_raw`] keeps them for the screening of `ambid frf`; the `t` column must be
/// finite. A finite value beyond ±[`MAX_SAMPLE_MAGNITUDE`] is refused.
pub fn read_time_csv(path: &Path, fs_hz: Option<f64>) -> Result<TimeData> {
    let table = read_text(path)?;
    let n = table.len();
    if n < 2 {
        return Err(DataFileError::NoData {
            path: path.to_path_buf(),
            message: format!("needs at least 2 data rows, found {n}"),
        }
        .into());
    }
    let t_idx = table.names.iter().position(|h| h == "t");
    let ts = match (t_idx, fs_hz) {
        (Some(_), _) => table.sample_time(Some(&ColumnRef::Name("t".into())), None)?,
        (None, Some(fs)) => table.sample_time(None, Some(fs))?,
        (None, None) => {
            return Err(DataFileError::SampleTime {
                path: path.to_path_buf(),
                message: "no `t` column; give the sample rate (--fs) to read this file".into(),
            }
            .into())
        }
    };
    let mut names = Vec::new();
    let mut columns = Vec::new();
    for (k, (h, c)) in table.names.into_iter().zip(table.columns).enumerate() {
        if Some(k) != t_idx {
            if let Some(j) = c
                .iter()
                .position(|v| v.is_finite() && v.abs() > MAX_SAMPLE_MAGNITUDE)
            {
                return Err(DataFileError::Invalid {
                    path: path.to_path_buf(),
                    message: format!(
                        "column `{h}`, data row {} (counted after the header, without comment lines): {:.6e} is beyond ±{MAX_SAMPLE_MAGNITUDE:e}, where sums of squares overflow; check the units of the column",
                        j + 1,
                        c[j]
                    ),
                }
                .into());
            }
            names.push(h);
            columns.push(c);
        }
    }
    Ok(TimeData {
        path: path.to_path_buf(),
        ts,
        names,
        columns,
    })
}

/// A text file read in the one dialect (header detected: without one the columns are `col1`,
/// `col2`, …).
fn read_text(path: &Path) -> Result<crate::io::table::Table> {
    let table = read_table(
        path,
        &ReadOptions {
            format: Some(Format::Text),
            ..ReadOptions::default()
        },
    )?;
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("ambid-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    #[test]
    fn time_csv_round_trip_is_exact() {
        let p = tmp("rt.csv");
        let t: Vec<f64> = (0..50).map(|k| k as f64 * 5e-5).collect();
        let y: Vec<f64> = (0..50).map(|k| (k as f64 * 0.37).sin() * 1e-6).collect();
        write_time_csv(&p, &[("t", &t), ("y", &y)]).unwrap();
        let d = read_time_csv(&p, None).unwrap();
        assert_eq!(d.names, vec!["y"]);
        assert_eq!(d.column("y").unwrap(), y.as_slice());
        assert!((d.ts - 5e-5).abs() < 1e-18);
        let e = d.column("x").unwrap_err().to_string();
        assert!(e.contains("unknown column `x`") && e.contains("y"), "{e}");
    }

    #[test]
    fn malformed_files_give_clear_errors() {
        let p = tmp("bad.csv");
        std::fs::write(&p, "t,y\n0,1\n0.1,abc\n").unwrap();
        let e = read_time_csv(&p, None).unwrap_err().to_string();
        assert!(
            e.contains("line 3, column `y`: cannot read `abc` as a number"),
            "{e}"
        );
        std::fs::write(&p, "y\n1\n2\n").unwrap();
        let e = read_time_csv(&p, None).unwrap_err().to_string();
        assert!(e.contains("--fs"), "{e}");
        assert!(read_time_csv(&p, Some(100.0)).is_ok());
        // missing or non-finite samples in a signal column are kept (as NaN) for the screening
        std::fs::write(&p, "t,y\n0,1\n0.1,NaN\n0.2,\n").unwrap();
        let d = read_time_csv(&p, None).unwrap();
        let y = d.column_raw("y").unwrap();
        assert!(y[1].is_nan() && y[2].is_nan());
        // … and named with their row and column where a command needs every sample
        let e = d.column("y").unwrap_err().to_string();
        assert!(e.contains("column `y`, data row 2"), "{e}");
        std::fs::write(&p, "t,y\n0,1\nNaN,2\n").unwrap();
        let e = read_time_csv(&p, None).unwrap_err().to_string();
        assert!(e.contains("non-finite value NaN in row 2"), "{e}");
        // comment lines are comments, as in every reader (one dialect)
        std::fs::write(&p, "# recorded\nt,y\n0,1\n% note\n0.1,2\n").unwrap();
        assert_eq!(
            read_time_csv(&p, None).unwrap().column("y").unwrap(),
            [1.0, 2.0]
        );
        // a header naming a column twice is refused
        std::fs::write(&p, "t,y,y\n0,1,2\n0.1,2,3\n").unwrap();
        let e = read_time_csv(&p, None).unwrap_err().to_string();
        assert!(e.contains("`y` twice"), "{e}");
        // a finite value that would overflow sums of squares is refused with row and column
        std::fs::write(&p, "t,y\n0,1\n0.1,1e308\n").unwrap();
        let e = read_time_csv(&p, None).unwrap_err().to_string();
        assert!(e.contains("column `y`, data row 2") && e.len() < 400, "{e}");
        std::fs::write(&p, "t,y\n0,1\n0.1,2,3\n").unwrap();
        assert!(read_time_csv(&p, None).is_err());
        assert!(write_time_csv(&p, &[("a", &[1.0, 2.0]), ("b", &[1.0])]).is_err());
    }
}

/// FRF data read from a file: the frequencies and every quantity and extra column.
#[derive(Debug, Clone, PartialEq)]
pub struct FrfFile {
    /// Frequencies \[Hz\].
    pub f_hz: Vec<f64>,
    /// Quantity names in file order (`t_ry`, `plant`, …).
    pub quantities: Vec<String>,
    /// Column names and values in file order (including `<q>_re`, `<q>_im`, `<q>_std`).
    pub names: Vec<String>,
    /// Columns, same order as `names`.
    pub columns: Vec<Vec<f64>>,
}

impl FrfFile {
    fn col(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|k| self.columns[k].as_slice())
    }

    /// Quantity `q` as an [`Frd`](ambid_core::lti::Frd) with sample time `ts`; the variance is
    /// `<q>_std²` unless every std is 0 (exact data), then `None`.
    pub fn frd(&self, q: &str, ts: f64) -> Result<ambid_core::lti::Frd> {
        let (re, im, sd) = match (
            self.col(&format!("{q}_re")),
            self.col(&format!("{q}_im")),
            self.col(&format!("{q}_std")),
        ) {
            (Some(re), Some(im), sd) => (re, im, sd),
            _ => bail!(
                "the FRF file has no quantity `{q}` (columns {q}_re, {q}_im); it has: {}",
                self.quantities.join(", ")
            ),
        };
        let values = re
            .iter()
            .zip(im)
            .map(|(r, i)| ambid_core::c64::new(*r, *i))
            .collect();
        let variance = sd
            .filter(|s| s.iter().any(|v| *v != 0.0))
            .map(|s| s.iter().map(|v| v * v).collect());
        Ok(ambid_core::lti::Frd::new(
            self.f_hz.clone(),
            values,
            variance,
            Some(ts),
        )?)
    }

    /// A real extra column such as `coh_ry`.
    pub fn extra(&self, name: &str) -> Result<&[f64]> {
        self.col(name).ok_or_else(|| {
            anyhow!(
                "the FRF file has no column `{name}`; it has: {}",
                self.names.join(", ")
            )
        })
    }
}

/// Reads an FRF CSV (`f_hz`, then `<q>_re, <q>_im, <q>_std` per quantity, then extra real
/// columns), in the one text dialect of [`crate::io::table`]. Every field must be a finite
/// number and `f_hz` strictly increasing.
pub fn read_frf_csv(path: &Path) -> Result<FrfFile> {
    let table = read_text(path)?;
    let (header, mut cols) = (table.names, table.columns);
    if header.first().map(String::as_str) != Some("f_hz") {
        bail!(
            "{}: an FRF file starts with the column `f_hz` (got {}); see docs/formats.md",
            path.display(),
            header
                .first()
                .map_or("no column".to_string(), |h| format!("`{h}`"))
        );
    }
    for (h, c) in header.iter().zip(&cols) {
        if let Some(k) = c.iter().position(|v| !v.is_finite()) {
            return Err(DataFileError::Invalid {
                path: path.to_path_buf(),
                message: format!(
                    "column `{h}`, data row {}: the value is missing or not finite; every field of an FRF file must be a finite number",
                    k + 1
                ),
            }
            .into());
        }
    }
    if let Some(k) = (1..cols[0].len()).find(|&k| cols[0][k] <= cols[0][k - 1]) {
        bail!(
            "{}: f_hz must increase strictly (data row {} has {:.6e} after {:.6e})",
            path.display(),
            k + 1,
            cols[0][k],
            cols[0][k - 1]
        );
    }
    let quantities = header
        .iter()
        .filter_map(|h| h.strip_suffix("_re"))
        .filter(|q| header.iter().any(|h| *h == format!("{q}_im")))
        .map(str::to_string)
        .collect();
    let f_hz = cols.remove(0);
    let mut names = header;
    names.remove(0);
    Ok(FrfFile {
        f_hz,
        quantities,
        names,
        columns: cols,
    })
}
