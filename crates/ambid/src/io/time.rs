//! Time data from any data file: the one reader behind every command that reads a record
//! (`frf`, `fit`, `order`, `validate`, `compare-models`, `bla`, `study amplitude`).
//!
//! [`read_time`] reads the file through [`read_table`] (delimited text, NumPy `.npy`/`.npz`,
//! MATLAB `.mat` v5 and v7.3, NI TDMS, Parquet; the format from [`TimeOptions::read`] or the
//! extension; a window [`TimeOptions::window`] and, for TDMS and MAT v7.3, only the columns
//! [`TimeOptions::columns`] read from the file), takes the
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
    /// Column specs (`#k` or names) that [`TimeOptions::columns`] asked for, with the index
    /// into [`TimeData::names`] each was read into (a file read in part no longer has every
    /// column, so `#k` cannot be counted in `names`).
    pub aliases: Vec<(String, usize)>,
    /// The first row of the record that was read (0 unless a window was asked for).
    pub first_row: usize,
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
        if let Some((_, k)) = self.aliases.iter().find(|(a, _)| a == name) {
            return Some(*k);
        }
        if !self.aliases.is_empty() {
            // read in part: positions in the file are known only through the aliases
            return None;
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
    /// The part of the record to keep (`--from`/`--to`); `None`: all of it.
    pub window: Option<Window>,
    /// The signal columns a command needs (names or `#k`; columns the file does not have are
    /// left out, so optional ones may be listed). TDMS and MAT v7.3 files then read only these
    /// and the time column; other formats are read whole. `None`: every column.
    pub columns: Option<Vec<String>>,
}

/// One end of a [`Window`]: seconds from the record's first sample, or a 0-based sample index.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bound {
    /// Seconds after the first sample (the sample whose time is the first at or after it).
    Seconds(f64),
    /// A 0-based sample index.
    Sample(usize),
}

impl std::str::FromStr for Bound {
    type Err = String;

    /// `2.5` or `2.5s`: seconds; `#50000`: the sample with 0-based index 50000.
    ///
    /// ```
    /// use ambid::io::time::Bound;
    /// assert_eq!("2.5".parse::<Bound>(), Ok(Bound::Seconds(2.5)));
    /// assert_eq!("10s".parse::<Bound>(), Ok(Bound::Seconds(10.0)));
    /// assert_eq!("#400".parse::<Bound>(), Ok(Bound::Sample(400)));
    /// assert!("-1".parse::<Bound>().is_err());
    /// ```
    fn from_str(s: &str) -> Result<Bound, String> {
        let s = s.trim();
        if let Some(k) = s.strip_prefix('#') {
            return k.parse().map(Bound::Sample).map_err(|_| {
                format!("`{s}` is not a sample index; write `#` and a whole number, e.g. `#20000`")
            });
        }
        let v: f64 = s.strip_suffix('s').unwrap_or(s).trim().parse().map_err(|_| {
            format!("`{s}` is not a time; write seconds (`2.5` or `2.5s`) or a sample index (`#20000`)")
        })?;
        if !(v.is_finite() && v >= 0.0) {
            return Err(format!(
                "`{s}`: a time must be zero or positive (seconds from the first sample)"
            ));
        }
        Ok(Bound::Seconds(v))
    }
}

/// The part of a record to read: from `from` (included) to `to` (excluded); a missing end is the
/// record's start or end.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Window {
    /// Start (default: the first sample).
    pub from: Option<Bound>,
    /// End, excluded (default: after the last sample).
    pub to: Option<Bound>,
}

impl Window {
    /// The rows of a record of `n` samples with sample time `ts`: seconds $s$ become the sample
    /// $\lceil s/T_s - 10^{-9}\rceil$ (the first at or after $s$).
    fn rows(&self, n: usize, ts: f64) -> std::ops::Range<usize> {
        let idx = |b: Bound| match b {
            Bound::Sample(k) => k,
            Bound::Seconds(s) => {
                let k = (s / ts - 1e-9).ceil().max(0.0);
                if k >= n as f64 {
                    n
                } else {
                    k as usize
                }
            }
        };
        let a = self.from.map_or(0, idx).min(n);
        let b = self.to.map_or(n, idx).min(n);
        a..b.max(a)
    }

    fn in_seconds(&self) -> bool {
        matches!(self.from, Some(Bound::Seconds(_))) || matches!(self.to, Some(Bound::Seconds(_)))
    }
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
    let part = read_part(path, opts)?;
    let mut d = assemble(path, part.table, opts)?;
    d.first_row = part.first_row;
    if let Some(aliases) = part.aliases {
        // positions in the table read (time column included) → in `names` (without it)
        let t = d.time_column;
        d.aliases = aliases
            .into_iter()
            .filter(|&(_, k)| Some(k) != t)
            .map(|(w, k)| (w, k - usize::from(t.is_some_and(|t| t < k))))
            .collect();
        if d.aliases.is_empty() {
            // nothing asked for is in the file: lookups by position find nothing
            d.aliases.push((String::new(), usize::MAX));
        }
    }
    Ok(d)
}

/// The part of a record that `opts` asks for ([`TimeOptions::window`],
/// [`TimeOptions::columns`]): the table (the window's rows; for TDMS and MAT v7.3 only the
/// asked-for columns and the time column, read from the file alone), the index of its first row
/// in the record, and, when columns were asked for, each asked-for spec with its column in the
/// table.
pub(crate) struct Part {
    pub table: super::table::Table,
    pub first_row: usize,
    pub aliases: Option<Vec<(String, usize)>>,
}

/// See [`Part`]. The sample time of a window in seconds: the time column, else the file's
/// metadata (TDMS `wf_increment`), else `opts.fs_hz`.
pub(crate) fn read_part(path: &Path, opts: &TimeOptions) -> Result<Part, DataFileError> {
    let Some(listing) = super::table::list_columns(path, &opts.read)? else {
        // read whole; the window is cut from the columns in memory
        let mut table = read_table(path, &opts.read)?;
        let mut first_row = 0;
        if let Some(w) = opts.window {
            let n = table.len();
            let t_idx = time_index(&table, opts)?;
            let ts = sample_time(path, &table, t_idx, opts.fs_hz)?;
            let r = w.rows(n, ts);
            if r.is_empty() {
                return Err(DataFileError::NoData {
                    path: path.to_path_buf(),
                    message: format!("the window selects no samples (the record has {n}, Ts = {ts:e} s); choose --from/--to inside the record"),
                });
            }
            for c in &mut table.columns {
                *c = c[r.clone()].to_vec();
            }
            first_row = r.start;
        }
        return Ok(Part {
            table,
            first_row,
            aliases: None,
        });
    };
    // TDMS / MAT v7.3: the column names first (nothing is read but the metadata), then only
    // the time column (for a window in seconds) and the wanted columns' rows
    let listed: Vec<String> = listing.iter().map(|(n, _)| n.clone()).collect();
    let time = match &opts.time {
        Some(c) => Some(c.clone()),
        None => listed
            .iter()
            .any(|n| n == "t")
            .then(|| ColumnRef::Name("t".into())),
    };
    let mut cols: Vec<ColumnRef> = Vec::new();
    if let Some(t) = &time {
        cols.push(t.clone());
    }
    let mut aliases = Vec::new();
    match &opts.columns {
        Some(wanted) => {
            let probe = super::table::Table {
                path: path.to_path_buf(),
                names: listed.clone(),
                columns: vec![Vec::new(); listed.len()],
                ts_metadata: None,
            };
            for w in wanted {
                let c = ColumnRef::parse(w);
                if let Ok(i) = probe.index_of(&c) {
                    let c = ColumnRef::Name(listed[i].clone());
                    if !cols.contains(&c) {
                        cols.push(c.clone());
                    }
                    aliases.push((w.clone(), c));
                }
            }
        }
        None => cols.clear(),
    }
    let with_cols = |rows| ReadOptions {
        columns: opts.columns.as_ref().map(|_| cols.clone()),
        rows,
        ..opts.read.clone()
    };
    let rows = match opts.window {
        None => None,
        Some(w) if !w.in_seconds() => Some(w.rows(usize::MAX, 1.0)),
        Some(w) => {
            // the sample time: the time column, else the file's metadata, else --fs
            let ts = match &time {
                Some(t) => {
                    let tt = read_table(
                        path,
                        &ReadOptions {
                            columns: Some(vec![t.clone()]),
                            rows: None,
                            ..opts.read.clone()
                        },
                    )?;
                    tt.sample_time(Some(&ColumnRef::Index(1)), None)?
                }
                None => {
                    // the metadata of the wanted columns (of every column without a choice)
                    let meta = listing
                        .iter()
                        .filter(|(n, _)| {
                            opts.columns.is_none()
                                || cols
                                    .iter()
                                    .any(|c| matches!(c, ColumnRef::Name(m) if m == n))
                        })
                        .find_map(|(_, ts)| *ts);
                    match (meta, opts.fs_hz) {
                        (Some(ts), _) => ts,
                        (None, Some(fs)) if fs.is_finite() && fs > 0.0 => 1.0 / fs,
                        _ => {
                            return Err(DataFileError::SampleTime {
                                path: path.to_path_buf(),
                                message: "a window in seconds needs the sample time: the file has no time column and no wf_increment; give --fs, or the window in samples (`#k`)".into(),
                            })
                        }
                    }
                }
            };
            Some(w.rows(usize::MAX, ts))
        }
    };
    let table = read_table(path, &with_cols(rows.clone()))?;
    let first_row = rows.map_or(0, |r| r.start);
    let aliases = opts.columns.as_ref().map(|_| {
        aliases
            .into_iter()
            .filter_map(|(w, c)| {
                let ColumnRef::Name(n) = c else { return None };
                table.names.iter().position(|m| *m == n).map(|k| (w, k))
            })
            .collect()
    });
    Ok(Part {
        table,
        first_row,
        aliases,
    })
}

/// The index of the time column: `opts.time`, else a column `t`.
fn time_index(
    table: &super::table::Table,
    opts: &TimeOptions,
) -> Result<Option<usize>, DataFileError> {
    Ok(match &opts.time {
        Some(c) => Some(table.index_of(c)?),
        None => table.names.iter().position(|h| h == "t"),
    })
}

/// The sample time of a table: its time column `t_idx`, else its metadata (checked against
/// `fs`), else `fs`.
fn sample_time(
    path: &Path,
    table: &super::table::Table,
    t_idx: Option<usize>,
    fs_hz: Option<f64>,
) -> Result<f64, DataFileError> {
    match (t_idx, table.ts_metadata, fs_hz) {
        (Some(k), _, _) => table.sample_time(Some(&ColumnRef::Index(k + 1)), None),
        (None, Some(ts), fs) => {
            if let Some(fs) = fs {
                if !(fs.is_finite() && fs > 0.0) || ((ts * fs) - 1.0).abs() > 1e-4 {
                    return Err(DataFileError::SampleTime {
                        path: path.to_path_buf(),
                        message: format!(
                            "the file's metadata give Ts = {ts:e} s (wf_increment) but fs = {} Hz was given; leave out --fs, or correct it",
                            crate::config::fmt_num(fs)
                        ),
                    });
                }
            }
            Ok(ts)
        }
        (None, None, Some(fs)) => table.sample_time(None, Some(fs)),
        (None, None, None) => Err(DataFileError::SampleTime {
            path: path.to_path_buf(),
            message: "no `t` column; give the sample rate (--fs) to read this file".into(),
        }),
    }
}

/// [`TimeData`] from a (windowed) table: the time column (or metadata or `fs`) gives the sample
/// time, every signal sample is checked.
fn assemble(
    path: &Path,
    table: super::table::Table,
    opts: &TimeOptions,
) -> Result<TimeData, DataFileError> {
    let n = table.len();
    if n < 2 {
        return Err(DataFileError::NoData {
            path: path.to_path_buf(),
            message: format!("needs at least 2 data rows, found {n}"),
        });
    }
    let t_idx = time_index(&table, opts)?;
    let ts = sample_time(path, &table, t_idx, opts.fs_hz)?;
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
        aliases: Vec::new(),
        first_row: 0,
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
