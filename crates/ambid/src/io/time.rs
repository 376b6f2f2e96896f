//! Time data from any data file: the one reader behind every command that reads a record
//! (`frf`, `fit`, `order`, `validate`, `compare-models`, `bla`, `study amplitude`).
//!
//! [`read_time`] reads the file through [`read_table`] (delimited text, NumPy `.npy`/`.npz`,
//! MATLAB `.mat` v5, Parquet; the format from [`TimeOptions::read`] or the extension), takes the
//! sample time from the time column (`t`, or [`TimeOptions::time`]) or from
//! [`TimeOptions::fs_hz`], and returns a [`TimeData`]: the signal columns by name. A column is
//! selected by name or by its 1-based position in the file (`#3`), the same in every format and
//! every command (`docs/data-files.md`).

use super::table::{read_table, ColumnRef, DataFileError, ReadOptions};
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
    /// The 0-based position of the time column in the file, if it had one (a column `#k`
    /// counts the file's columns, the time column included).
    pub time_column: Option<usize>,
}

/// The largest magnitude a signal sample may have: sums of squares of up to 2²⁸ samples of
/// this size stay far below `f64::MAX` (≈ 1.8·10³⁰⁸), so a larger (finite) value is refused at
/// the reader instead of overflowing to ±inf inside a computation.
pub const MAX_SAMPLE_MAGNITUDE: f64 = 1e100;

impl TimeData {
    /// The column called `name` with every sample finite: an error names the file, the column
    /// and the 1-based data row (rows after the header; comment and blank lines are not
    /// counted) of the first NaN, ±inf or missing value, or lists the available columns.
    pub fn column(&self, name: &str) -> Result<&[f64], DataFileError> {
        let x = self.column_raw(name)?;
        if let Some(k) = x.iter().position(|v| !v.is_finite()) {
            return Err(DataFileError::Invalid {
                path: self.path.clone(),
                message: format!(
                    "column `{name}`, data row {} (counted after the header, without comment lines): the value is {}; every sample must be a number for this command: repair or cut the record (`ambid frf` screens and repairs missing samples)",
                    k + 1,
                    if x[k].is_nan() { "missing or NaN".to_string() } else { format!("{}", x[k]) }
                ),
            });
        }
        Ok(x)
    }

    /// The column called `name` if the file has one, with every sample finite (as
    /// [`TimeData::column`]: a NaN is an error, not a reason to drop the column).
    pub fn optional_column(&self, name: &str) -> Result<Option<&[f64]>, DataFileError> {
        if self.position(name).is_some() {
            self.column(name).map(Some)
        } else {
            Ok(None)
        }
    }

    /// The column called `name` as read, missing samples as NaN (for the screening of
    /// `ambid frf`), or an error listing the available columns. `name` is a column name or
    /// `#k`, the k-th column of the file (1-based, the time column counted).
    pub fn column_raw(&self, name: &str) -> Result<&[f64], DataFileError> {
        self.position(name)
            .map(|k| self.columns[k].as_slice())
            .ok_or_else(|| DataFileError::Invalid {
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
    }

    /// Whether the record has the signal column `name` (a name or `#k`).
    pub fn has(&self, name: &str) -> bool {
        self.position(name).is_some()
    }

    /// The index into [`TimeData::names`] of the column `name`: by name, or `#k` for the k-th
    /// column of the file (the time column counted, but not a signal: `None`).
    fn position(&self, name: &str) -> Option<usize> {
        if let Some(k) = self.names.iter().position(|n| n == name) {
            return Some(k);
        }
        match ColumnRef::parse(name) {
            ColumnRef::Index(k) if k >= 1 => {
                let file = k - 1;
                match self.time_column {
                    Some(t) if file == t => None,
                    Some(t) if file > t => Some(file - 1),
                    _ => Some(file),
                }
                .filter(|&j| j < self.names.len())
            }
            _ => None,
        }
    }
}

/// How [`read_time`] reads a record. The defaults read a file with a `t` column in the format
/// its extension names.
#[derive(Debug, Clone, Default)]
pub struct TimeOptions {
    /// The sample rate in Hz, for a file without a time column (ignored when the file has one).
    pub fs_hz: Option<f64>,
    /// The time column (seconds); `None`: the column `t` if the file has one.
    pub time: Option<ColumnRef>,
    /// Format, and the text dialect or the `.mat`/`.npz` variable ([`read_table`]).
    pub read: ReadOptions,
}

impl TimeOptions {
    /// The options of a file with sample rate `fs_hz` (when it has no `t` column), its format
    /// from the extension.
    pub fn with_fs(fs_hz: Option<f64>) -> TimeOptions {
        TimeOptions {
            fs_hz,
            ..TimeOptions::default()
        }
    }
}

impl TimeData {
    /// Checks a sample rate `fs_hz` given beside the record's time column against it (1e-4
    /// relative, as [`crate::io::table::Table::sample_time`] with both): for commands that
    /// refuse a contradicting `--fs` rather than ignore it. Nothing to check without a time
    /// column or without `fs_hz`.
    pub fn check_fs(&self, fs_hz: Option<f64>) -> Result<(), DataFileError> {
        let (Some(fs), Some(_)) = (fs_hz, self.time_column) else {
            return Ok(());
        };
        let ts_fs = 1.0 / fs;
        if !(fs.is_finite() && fs > 0.0) || ((self.ts - ts_fs) / ts_fs).abs() > 1e-4 {
            return Err(DataFileError::SampleTime {
                path: self.path.clone(),
                message: if fs.is_finite() && fs > 0.0 {
                    format!(
                        "the time column gives Ts = {:e} s but fs = {} Hz gives Ts = {ts_fs:e} s; give only one of them, or correct fs",
                        self.ts,
                        crate::config::fmt_num(fs)
                    )
                } else {
                    format!(
                        "the sampling frequency fs = {} Hz is not a positive number; give fs in Hz, e.g. fs = 1000",
                        crate::config::fmt_num(fs)
                    )
                },
            });
        }
        Ok(())
    }
}

/// Reads a record of time data from a file in any format of [`read_table`] (text in the one
/// dialect of [`crate::io::table`], see `docs/data-files.md`: `#`/`%` comment lines, detected
/// delimiter, quoted cells, a header row detected — without one the columns are `col1`,
/// `col2`, …; `.npy`, `.npz`, `.mat`, Parquet). A header names every column once. The sample
/// time comes from the time column when present (`opts.time`, else a column `t`; it must be
/// finite, strictly increasing and uniform), otherwise from `opts.fs_hz`. `NaN`, `inf` and empty
/// fields in a signal column are read as missing samples (NaN): [`TimeData::column`] refuses
/// them with the file, row and column, [`TimeData::column_raw`] keeps them for the screening of
/// `ambid frf`. A finite value beyond ±[`MAX_SAMPLE_MAGNITUDE`] is refused.
///
/// ```
/// use ambid::io::time::{read_time, TimeOptions};
///
/// let dir = std::env::temp_dir().join(format!("ambid-doc-time-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// let path = dir.join("rec.csv");
/// std::fs::write(&path, "t,u,y\n0,1,0.5\n0.001,1,0.7\n0.002,0,0.1\n")?;
/// let d = read_time(&path, &TimeOptions::default())?;
/// assert_eq!(d.names, ["u", "y"]);
/// assert!((d.ts - 0.001).abs() < 1e-15);
/// // by name or by position in the file (`t` is #1)
/// assert_eq!(d.column("y")?, d.column("#3")?);
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn read_time(path: &Path, opts: &TimeOptions) -> Result<TimeData, DataFileError> {
    let table = read_table(path, &opts.read)?;
    let n = table.len();
    if n < 2 {
        return Err(DataFileError::NoData {
            path: path.to_path_buf(),
            message: format!("needs at least 2 data rows, found {n}"),
        });
    }
    let t_idx = match &opts.time {
        Some(c) => Some(table.index_of(c)?),
        None => table.names.iter().position(|h| h == "t"),
    };
    let ts = match (t_idx, opts.fs_hz) {
        (Some(k), _) => table.sample_time(Some(&ColumnRef::Index(k + 1)), None)?,
        (None, Some(fs)) => table.sample_time(None, Some(fs))?,
        (None, None) => {
            return Err(DataFileError::SampleTime {
                path: path.to_path_buf(),
                message: "no `t` column; give the sample rate (--fs) to read this file".into(),
            })
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
                });
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
        time_column: t_idx,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::csv::write_time_csv;

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
        let d = read_time(&p, &TimeOptions::default()).unwrap();
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
        let e = read_time(&p, &TimeOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 3, column `y`: cannot read `abc` as a number"),
            "{e}"
        );
        std::fs::write(&p, "y\n1\n2\n").unwrap();
        let e = read_time(&p, &TimeOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("--fs"), "{e}");
        assert!(read_time(&p, &TimeOptions::with_fs(Some(100.0))).is_ok());
        // missing or non-finite samples in a signal column are kept (as NaN) for the screening
        std::fs::write(&p, "t,y\n0,1\n0.1,NaN\n0.2,\n").unwrap();
        let d = read_time(&p, &TimeOptions::default()).unwrap();
        let y = d.column_raw("y").unwrap();
        assert!(y[1].is_nan() && y[2].is_nan());
        // … and named with their row and column where a command needs every sample
        let e = d.column("y").unwrap_err().to_string();
        assert!(e.contains("column `y`, data row 2"), "{e}");
        std::fs::write(&p, "t,y\n0,1\nNaN,2\n").unwrap();
        let e = read_time(&p, &TimeOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("non-finite value NaN in row 2"), "{e}");
        // comment lines are comments, as in every reader (one dialect)
        std::fs::write(&p, "# recorded\nt,y\n0,1\n% note\n0.1,2\n").unwrap();
        assert_eq!(
            read_time(&p, &TimeOptions::default())
                .unwrap()
                .column("y")
                .unwrap(),
            [1.0, 2.0]
        );
        // a header naming a column twice is refused
        std::fs::write(&p, "t,y,y\n0,1,2\n0.1,2,3\n").unwrap();
        let e = read_time(&p, &TimeOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("`y` twice"), "{e}");
        // a finite value that would overflow sums of squares is refused with row and column
        std::fs::write(&p, "t,y\n0,1\n0.1,1e308\n").unwrap();
        let e = read_time(&p, &TimeOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("column `y`, data row 2") && e.len() < 400, "{e}");
        std::fs::write(&p, "t,y\n0,1\n0.1,2,3\n").unwrap();
        assert!(read_time(&p, &TimeOptions::default()).is_err());
        assert!(write_time_csv(&p, &[("a", &[1.0, 2.0]), ("b", &[1.0])]).is_err());
    }
}
