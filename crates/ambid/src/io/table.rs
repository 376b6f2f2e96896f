//! Reading recorded data files into named numeric columns: CSV and whitespace-separated text,
//! NumPy `.npy`/`.npz`, MATLAB `.mat` (v5, and v7.3 = HDF5), NI TDMS and Parquet (cargo feature
//! `parquet`).
//!
//! [`read_table`] is the one entry point; it picks the reader from [`ReadOptions::format`] or the
//! file extension and returns a [`Table`] of equally long `f64` columns. A subset of the columns
//! ([`ReadOptions::columns`]) and of the rows ([`ReadOptions::rows`]) can be asked for: the TDMS
//! and MAT v7.3 readers then read only those bytes of the file, the others read the file and
//! keep them. The rules (delimiter and header detection, column naming, errors) are described
//! in `docs/data-files.md`.

mod arrays;
pub use arrays::MAX_DECODED_BYTES;
pub use text::{TextRows, MAX_LINE_BYTES};
mod mat;
mod mat73;
mod npy;
#[cfg(feature = "parquet")]
mod parquet;
mod tdms;
mod text;

use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// File formats [`read_table`] understands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Delimited text (`,`, `;`, tab or whitespace; detected), optional header, `#`/`%` comments.
    Text,
    /// NumPy `.npy` (one 1-D or 2-D array).
    Npy,
    /// NumPy `.npz` (several arrays).
    Npz,
    /// MATLAB `.mat`: version 5 (`-v6`, `-v7`) or 7.3 (HDF5), told apart by the header.
    Mat,
    /// NI LabVIEW TDMS (`.tdms`).
    Tdms,
    /// Apache Parquet (needs the cargo feature `parquet`).
    Parquet,
}

impl Format {
    /// The format a file extension stands for (case-insensitive, without the dot): `csv`, `txt`,
    /// `dat`, `tsv` → [`Format::Text`], `npy`, `npz`, `mat`, `parquet`/`pq`. `None` otherwise.
    ///
    /// ```
    /// use ambid::io::table::Format;
    /// assert_eq!(Format::from_extension("CSV"), Some(Format::Text));
    /// assert_eq!(Format::from_extension("mat"), Some(Format::Mat));
    /// assert_eq!(Format::from_extension("xlsx"), None);
    /// ```
    pub fn from_extension(ext: &str) -> Option<Format> {
        match ext.to_ascii_lowercase().as_str() {
            "csv" | "txt" | "dat" | "tsv" => Some(Format::Text),
            "npy" => Some(Format::Npy),
            "npz" => Some(Format::Npz),
            "mat" => Some(Format::Mat),
            "parquet" | "pq" => Some(Format::Parquet),
            "tdms" => Some(Format::Tdms),
            _ => None,
        }
    }

    /// The format [`read_table`] reads `path` in: `opts_format` when given, else from the
    /// extension, else from the file's first bytes.
    pub fn of_file(path: &Path, opts_format: Option<Format>) -> Result<Format, DataFileError> {
        match opts_format {
            Some(f) => Ok(f),
            None => Format::detect(path),
        }
    }

    /// The format of a file: from its extension, else from its first bytes (NumPy, zip, MATLAB
    /// and Parquet signatures; anything else is read as text).
    fn detect(path: &Path) -> Result<Format, DataFileError> {
        if let Some(f) = path
            .extension()
            .and_then(|e| e.to_str())
            .and_then(Format::from_extension)
        {
            return Ok(f);
        }
        let start = first_bytes(path, 8)?;
        Ok(if start.starts_with(b"\x93NUMPY") {
            Format::Npy
        } else if start.starts_with(b"PK\x03\x04") || start.starts_with(b"PK\x05\x06") {
            Format::Npz
        } else if start.starts_with(b"MATLAB") {
            Format::Mat
        } else if start.starts_with(b"PAR1") {
            Format::Parquet
        } else if start.starts_with(b"TDSm") {
            Format::Tdms
        } else {
            Format::Text
        })
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Format::Text => "text",
            Format::Npy => "npy",
            Format::Npz => "npz",
            Format::Mat => "mat",
            Format::Parquet => "parquet",
            Format::Tdms => "tdms",
        })
    }
}

impl std::str::FromStr for Format {
    type Err = String;

    /// Parses `text` (also `csv`, `txt`, `dat`, `tsv`), `npy`, `npz`, `mat`, `tdms`, `parquet`.
    fn from_str(s: &str) -> Result<Format, String> {
        if s.eq_ignore_ascii_case("text") {
            return Ok(Format::Text);
        }
        Format::from_extension(s).ok_or_else(|| {
            format!(
                "unknown data-file format `{s}`; use one of text, csv, npy, npz, mat, tdms, parquet"
            )
        })
    }
}

/// How to read a file. Everything is optional; the defaults detect.
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// Format; `None` decides from the extension (`.csv`, `.txt`, `.dat`, `.tsv` → text).
    pub format: Option<Format>,
    /// Text: the delimiter; `None` detects it from the first data lines. `' '` means runs of
    /// whitespace.
    pub delimiter: Option<char>,
    /// Text: whether the first non-comment line is a header; `None` detects it (non-numeric cells).
    pub header: Option<bool>,
    /// `.mat`/`.npz`: only read this variable (others are ignored); `.tdms`: only this group.
    pub variable: Option<String>,
    /// Only these columns, in this order (names, or `#k` counted over every column of the
    /// file); `None` reads every column. TDMS and MAT v7.3 files read nothing else.
    pub columns: Option<Vec<ColumnRef>>,
    /// Only these rows (0-based samples, end exclusive; clipped to the record); `None` reads
    /// all. TDMS and MAT v7.3 files read nothing else.
    pub rows: Option<Range<usize>>,
}

/// A column reference: by name, or by 1-based position (`"#3"` or the integer 3 in TOML).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ColumnRef {
    /// By name.
    Name(String),
    /// By 1-based position.
    Index(usize),
}

impl ColumnRef {
    /// `"#3"` → `Index(3)`; anything else (also `"#x"`) → `Name`, with surrounding whitespace
    /// removed.
    ///
    /// ```
    /// use ambid::io::table::ColumnRef;
    /// assert_eq!(ColumnRef::parse("#3"), ColumnRef::Index(3));
    /// assert_eq!(ColumnRef::parse("y_mm"), ColumnRef::Name("y_mm".into()));
    /// assert_eq!(ColumnRef::parse("#3").to_string(), "#3");
    /// ```
    pub fn parse(s: &str) -> ColumnRef {
        let s = s.trim();
        if let Some(k) = s.strip_prefix('#').and_then(|d| d.parse::<usize>().ok()) {
            return ColumnRef::Index(k);
        }
        ColumnRef::Name(s.to_string())
    }
}

impl fmt::Display for ColumnRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ColumnRef::Name(n) => f.write_str(n),
            ColumnRef::Index(k) => write!(f, "#{k}"),
        }
    }
}

impl From<&str> for ColumnRef {
    fn from(s: &str) -> ColumnRef {
        ColumnRef::parse(s)
    }
}

/// Named numeric columns read from one file. Without a header, text columns are named
/// `col1`, `col2`, …; a 2-D `.mat`/`.npz`/`.npy` variable `v` with k columns gives `v1` … `vk`
/// (a 1-D variable keeps its name `v`).
#[derive(Debug, Clone)]
pub struct Table {
    /// Where the data came from.
    pub path: PathBuf,
    /// Column names, in file order.
    pub names: Vec<String>,
    /// Columns (all of the same length).
    pub columns: Vec<Vec<f64>>,
    /// The sample time the file's own metadata give (TDMS `wf_increment`), if any.
    pub ts_metadata: Option<f64>,
}

impl Table {
    /// Number of rows (samples); 0 for a table without columns.
    pub fn len(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }

    /// Whether the table has no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Position (0-based) of a column; the error lists the available names.
    pub fn index_of(&self, c: &ColumnRef) -> Result<usize, DataFileError> {
        let found = match c {
            ColumnRef::Name(n) => self.names.iter().position(|m| m == n),
            ColumnRef::Index(k) => k.checked_sub(1).filter(|&i| i < self.columns.len()),
        };
        found.ok_or_else(|| DataFileError::MissingColumn {
            path: self.path.clone(),
            wanted: c.to_string(),
            available: self.available_names(),
        })
    }

    /// The values of a column; a missing column is an error listing the available names.
    pub fn column(&self, c: &ColumnRef) -> Result<&[f64], DataFileError> {
        let i = self.index_of(c)?;
        self.columns
            .get(i)
            .map(Vec::as_slice)
            .ok_or_else(|| DataFileError::MissingColumn {
                path: self.path.clone(),
                wanted: c.to_string(),
                available: self.available_names(),
            })
    }

    fn available_names(&self) -> String {
        if self.names.is_empty() {
            return "(none)".into();
        }
        self.names
            .iter()
            .enumerate()
            .map(|(i, n)| format!("`{n}` (#{})", i + 1))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The sample time in seconds: from the time column `t` (checked to be strictly increasing
    /// and uniform: every sample within 1e-3·Ts of the straight line from the first to the last
    /// time — time stamps written with few digits stay usable, real jitter is refused), else
    /// `1/fs_hz`. With both given, the time column is checked and must agree with `fs_hz` to 1e-4
    /// relative. With neither, an error asks for one.
    pub fn sample_time(
        &self,
        t: Option<&ColumnRef>,
        fs_hz: Option<f64>,
    ) -> Result<f64, DataFileError> {
        let err = |message: String| DataFileError::SampleTime {
            path: self.path.clone(),
            message,
        };
        if let Some(fs) = fs_hz {
            if !(fs.is_finite() && fs > 0.0) {
                return Err(err(format!(
                    "the sampling frequency fs = {} Hz is not a positive number; give fs in Hz, e.g. fs = 1000",
                    num(fs)
                )));
            }
        }
        let from_t = match t {
            None => None,
            Some(c) => Some(uniform_step(self.column(c)?, c).map_err(err)?),
        };
        match (from_t, fs_hz) {
            (Some(ts), Some(fs)) => {
                let ts_fs = 1.0 / fs;
                if ((ts - ts_fs) / ts_fs).abs() > 1e-4 {
                    return Err(err(format!(
                        "the time column gives Ts = {ts:e} s but fs = {} Hz gives Ts = {ts_fs:e} s; give only one of them, or correct fs",
                        num(fs)
                    )));
                }
                Ok(ts)
            }
            (Some(ts), None) => Ok(ts),
            (None, Some(fs)) => Ok(1.0 / fs),
            (None, None) => Err(err(
                "no sample time: give the sampling frequency `fs` (Hz) or a time column `t`".into(),
            )),
        }
    }
}

use crate::config::fmt_num as num;

/// Sample time of a time column: strictly increasing and uniform to 1e-3·Ts.
fn uniform_step(t: &[f64], c: &ColumnRef) -> Result<f64, String> {
    let n = t.len();
    let (Some(&first), Some(&last)) = (t.first(), t.last()) else {
        return Err(format!("the time column `{c}` is empty; give fs instead"));
    };
    if n < 2 {
        return Err(format!(
            "the time column `{c}` has only one sample, so it gives no sample time; give fs instead"
        ));
    }
    if let Some(i) = t.iter().position(|v| !v.is_finite()) {
        return Err(format!(
            "the time column `{c}` has the non-finite value {} in row {}; fix the time column or give fs instead",
            t[i],
            i + 1
        ));
    }
    if let Some(k) = t.windows(2).position(|w| w[1] <= w[0]) {
        return Err(format!(
            "the time column `{c}` is not strictly increasing: row {} has t = {} after t = {} in row {}; sort the data or give fs instead",
            k + 2,
            num(t[k + 1]),
            num(t[k]),
            k + 1
        ));
    }
    let ts = (last - first) / (n - 1) as f64;
    let tol = 1e-3 * ts;
    let mut worst = (0usize, 0.0f64);
    for (i, &v) in t.iter().enumerate() {
        let dev = (v - (first + i as f64 * ts)).abs();
        if dev > worst.1 {
            worst = (i, dev);
        }
    }
    if worst.1 > tol {
        return Err(format!(
            "the time column `{c}` is not uniformly sampled: row {} has t = {}, {:.3e} s ({:.2e}·Ts) off the uniform grid with Ts = {ts:e} s (allowed 1e-3·Ts); resample the data to a uniform grid or give fs if the time stamps are only rounded",
            worst.0 + 1,
            num(t[worst.0]),
            worst.1,
            worst.1 / ts
        ));
    }
    Ok(ts)
}

/// Why a data file could not be read. Every message names the file and what to do.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DataFileError {
    /// The file does not exist or cannot be opened.
    #[error("{path}: cannot open ({reason}); check the path in the workflow file or on the command line")]
    Open {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        reason: String,
    },
    /// Anything else that is wrong with the file's content.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong and what to do.
        message: String,
    },
    /// The file holds no data (empty, only comments, only a header, or no numeric variables).
    #[error("{path}: {message}")]
    NoData {
        /// The file.
        path: PathBuf,
        /// What was found and what to do.
        message: String,
    },
    /// A text row with a different number of fields than the header (or the first data row).
    #[error("{path}: line {line} has {fields} fields, {reference} has {expected}; every row needs the same number of fields (check for a missing or extra delimiter, or give the delimiter explicitly)")]
    RaggedRow {
        /// The file.
        path: PathBuf,
        /// 1-based line number in the file.
        line: usize,
        /// Number of fields found on that line.
        fields: usize,
        /// Number of fields expected.
        expected: usize,
        /// What the expectation comes from: "the header" or "line 3 (the first data line)".
        reference: String,
    },
    /// A text cell that is not a number.
    #[error("{path}: line {line}, column `{column}`: cannot read `{cell}` as a number; fix the cell, or comment the line out with `#`")]
    NotANumber {
        /// The file.
        path: PathBuf,
        /// 1-based line number in the file.
        line: usize,
        /// Column name (header name or `colK`).
        column: String,
        /// The cell's text.
        cell: String,
    },
    /// A column asked for is not in the file.
    #[error("{path}: no column `{wanted}`; the file has {available}; use one of these names or `#k` for the k-th column")]
    MissingColumn {
        /// The file.
        path: PathBuf,
        /// The column asked for.
        wanted: String,
        /// The available columns, listed.
        available: String,
    },
    /// Variables (or columns) of different lengths.
    #[error("{path}: the signals have different lengths ({lengths}); all signals must have the same number of samples: select one variable with `variable`, or save signals of equal length")]
    LengthMismatch {
        /// The file.
        path: PathBuf,
        /// `name: length` for every variable.
        lengths: String,
    },
    /// A Parquet file, but ambid was built without the `parquet` feature.
    #[error("{path}: reading Parquet files needs ambid built with the cargo feature `parquet`; rebuild with `cargo build --release --features parquet` (or `cargo install ... --features parquet`), or export the data to CSV")]
    ParquetDisabled {
        /// The file.
        path: PathBuf,
    },
    /// No usable sample time (missing, non-uniform or non-increasing time column, bad `fs`).
    #[error("{path}: {message}")]
    SampleTime {
        /// The file.
        path: PathBuf,
        /// What is wrong and what to do.
        message: String,
    },
}

impl DataFileError {
    fn open(path: &Path, e: &std::io::Error) -> DataFileError {
        DataFileError::Open {
            path: path.to_path_buf(),
            reason: e.to_string(),
        }
    }

    fn invalid(path: &Path, message: impl Into<String>) -> DataFileError {
        DataFileError::Invalid {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    fn no_data(path: &Path, message: impl Into<String>) -> DataFileError {
        DataFileError::NoData {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}

/// Reads a data file into named numeric columns.
///
/// The format comes from `opts.format`, else from the extension, else from the file's first
/// bytes. Text is parsed with detected (or given) delimiter and header; `.npy`, `.npz` and `.mat`
/// variables become columns (`v`, or `v1`…`vk` for a 2-D variable with k signals); Parquet reads
/// the numeric columns. All columns of the result have the same length, at least 1.
///
/// ```
/// use ambid::io::table::{read_table, ColumnRef, ReadOptions};
///
/// let dir = std::env::temp_dir().join(format!("ambid-doc-table-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// let path = dir.join("run.csv");
/// std::fs::write(&path, "# step test\nt,u,y\n0.000,1,0.5\n0.001,1,0.7\n0.002,0,NaN\n")?;
///
/// let table = read_table(&path, &ReadOptions::default())?;
/// assert_eq!(table.names, ["t", "u", "y"]);
/// assert_eq!(table.len(), 3);
/// assert_eq!(table.column(&ColumnRef::parse("u"))?, &[1.0, 1.0, 0.0]);
/// assert!(table.column(&ColumnRef::parse("#3"))?[2].is_nan());
/// let ts = table.sample_time(Some(&ColumnRef::parse("t")), None)?;
/// assert!((ts - 0.001).abs() < 1e-12);
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn read_table(path: &Path, opts: &ReadOptions) -> Result<Table, DataFileError> {
    let format = match opts.format {
        Some(f) => f,
        None => Format::detect(path)?,
    };
    let table = match format {
        Format::Text => text::read(path, opts)?,
        Format::Npy => npy::read_npy(path, opts)?,
        Format::Npz => npy::read_npz(path, opts)?,
        Format::Mat if mat_v73(path)? => {
            return read_lazy(
                Lazy::Mat(mat73::Mat73File::open(path, opts.variable.as_deref())?),
                path,
                opts,
            )
        }
        Format::Mat => mat::read(path, opts)?,
        Format::Tdms => return read_lazy(Lazy::Tdms(tdms::TdmsFile::open(path)?), path, opts),
        Format::Parquet => read_parquet(path, opts)?,
    };
    select(check_table(table)?, opts)
}

/// Whether a `.mat` file is version 7.3 (HDF5): its header text says so.
fn mat_v73(path: &Path) -> Result<bool, DataFileError> {
    Ok(mat73::is_v73(&first_bytes(path, 16)?))
}

/// The first `n` bytes of a file (fewer if it is shorter).
fn first_bytes(path: &Path, n: usize) -> Result<Vec<u8>, DataFileError> {
    use std::io::Read;
    let mut start = Vec::with_capacity(n);
    std::fs::File::open(path)
        .and_then(|f| f.take(n as u64).read_to_end(&mut start))
        .map_err(|e| DataFileError::open(path, &e))?;
    Ok(start)
}

/// The columns and rows of `opts` of a whole table.
fn select(table: Table, opts: &ReadOptions) -> Result<Table, DataFileError> {
    if opts.columns.is_none() && opts.rows.is_none() {
        return Ok(table);
    }
    let idx: Vec<usize> = match &opts.columns {
        None => (0..table.columns.len()).collect(),
        Some(c) => c
            .iter()
            .map(|c| table.index_of(c))
            .collect::<Result<_, _>>()?,
    };
    let n = table.len();
    let rows = clip(opts.rows.clone(), n, &table.path)?;
    let names = idx.iter().map(|&k| table.names[k].clone()).collect();
    let columns = idx
        .iter()
        .map(|&k| table.columns[k][rows.clone()].to_vec())
        .collect();
    Ok(Table {
        names,
        columns,
        ..table
    })
}

/// `rows` clipped to a record of `n` rows; an empty result is an error.
fn clip(rows: Option<Range<usize>>, n: usize, path: &Path) -> Result<Range<usize>, DataFileError> {
    let r = rows.unwrap_or(0..n);
    let r = r.start.min(n)..r.end.min(n);
    if r.is_empty() {
        return Err(DataFileError::no_data(
            path,
            format!(
                "the window selects no samples (the record has {n}); choose --from/--to inside the record"
            ),
        ));
    }
    Ok(r)
}

/// A file read column by column (TDMS, MAT v7.3).
enum Lazy {
    Tdms(tdms::TdmsFile),
    Mat(mat73::Mat73File),
}

impl Lazy {
    fn names(&self) -> Vec<String> {
        match self {
            Lazy::Tdms(t) => t.names(),
            Lazy::Mat(m) => m.names(),
        }
    }

    fn len(&self, k: usize) -> u64 {
        match self {
            Lazy::Tdms(t) => t.len(k),
            Lazy::Mat(m) => m.len(k),
        }
    }

    fn read(&mut self, k: usize, rows: Range<u64>) -> Result<Vec<f64>, DataFileError> {
        match self {
            Lazy::Tdms(t) => t.read(k, rows),
            Lazy::Mat(m) => m.read(k, rows),
        }
    }
}

/// A column of a file read in part: its name and the sample time its metadata give.
pub(crate) type Listed = (String, Option<f64>);

/// The columns of a TDMS or MAT v7.3 file (after `opts.variable`) and the sample time its
/// metadata give for each (TDMS `wf_increment`), without reading any sample; `None` for the
/// other formats, which are read whole.
pub(crate) fn list_columns(
    path: &Path,
    opts: &ReadOptions,
) -> Result<Option<Vec<Listed>>, DataFileError> {
    let format = match opts.format {
        Some(f) => f,
        None => Format::detect(path)?,
    };
    let src = match format {
        Format::Tdms => Lazy::Tdms(tdms::TdmsFile::open(path)?),
        Format::Mat if mat_v73(path)? => {
            Lazy::Mat(mat73::Mat73File::open(path, opts.variable.as_deref())?)
        }
        _ => return Ok(None),
    };
    let names = src.names();
    Ok(Some(
        names
            .into_iter()
            .enumerate()
            .filter_map(|(k, n)| match &src {
                Lazy::Tdms(t) => opts
                    .variable
                    .as_deref()
                    .is_none_or(|g| t.group(k) == g)
                    .then(|| (n, t.sample_time(k))),
                Lazy::Mat(_) => Some((n, None)),
            })
            .collect(),
    ))
}

/// [`read_table`] of a file read column by column: only the columns and rows asked for.
fn read_lazy(mut src: Lazy, path: &Path, opts: &ReadOptions) -> Result<Table, DataFileError> {
    let all = src.names();
    // TDMS: `variable` names the group; every listed column is a candidate, strings included
    // (reading one is then an error that says why)
    let listed: Vec<usize> = (0..all.len())
        .filter(|&k| match &src {
            Lazy::Tdms(t) => opts.variable.as_deref().is_none_or(|g| t.group(k) == g),
            Lazy::Mat(_) => true,
        })
        .collect();
    let probe = Table {
        path: path.to_path_buf(),
        names: listed.iter().map(|&k| all[k].clone()).collect(),
        columns: vec![Vec::new(); listed.len()],
        ts_metadata: None,
    };
    let wanted: Vec<usize> = match &opts.columns {
        Some(c) => c
            .iter()
            .map(|c| probe.index_of(c).map(|i| listed[i]))
            .collect::<Result<_, _>>()
            .map_err(|e| match (&src, e) {
                (
                    Lazy::Mat(m),
                    DataFileError::MissingColumn {
                        path,
                        wanted,
                        available,
                    },
                ) => match m.unusable.iter().find(|u| u.name == wanted) {
                    Some(u) => DataFileError::invalid(
                        &path,
                        format!(
                            "variable `{}` is {}, not a signal; select a numeric variable",
                            u.name, u.reason
                        ),
                    ),
                    None => DataFileError::MissingColumn {
                        path,
                        wanted,
                        available,
                    },
                },
                (_, e) => e,
            })?,
        // every numeric column
        None => listed
            .iter()
            .copied()
            .filter(|&k| match &src {
                Lazy::Tdms(t) => t.is_numeric(k) && t.len(k) > 0,
                Lazy::Mat(_) => true,
            })
            .collect(),
    };
    if wanted.is_empty() {
        let why = match &src {
            Lazy::Mat(m) if !m.unusable.is_empty() => format!(
                "no numeric signals; the file has {}",
                m.unusable
                    .iter()
                    .map(|u| format!("`{}` ({})", u.name, u.reason))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            _ => "no numeric signals; check that this is the right file (and --variable)".into(),
        };
        return Err(DataFileError::no_data(path, why));
    }
    let lens: Vec<u64> = wanted.iter().map(|&k| src.len(k)).collect();
    if lens.iter().any(|&l| l != lens[0]) {
        let lengths = wanted
            .iter()
            .zip(&lens)
            .map(|(&k, l)| format!("{}: {l}", all[k]))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(DataFileError::LengthMismatch {
            path: path.to_path_buf(),
            lengths,
        });
    }
    let n = usize::try_from(lens[0]).unwrap_or(usize::MAX);
    let rows = clip(opts.rows.clone(), n, path)?;
    let bytes = 8 * (rows.end - rows.start) as u64 * wanted.len() as u64;
    if bytes > MAX_DECODED_BYTES {
        return Err(DataFileError::invalid(
            path,
            arrays::too_big("the selected columns and rows", bytes),
        ));
    }
    let mut columns = Vec::with_capacity(wanted.len());
    for &k in &wanted {
        columns.push(src.read(k, rows.start as u64..rows.end as u64)?);
    }
    let ts_metadata = match &src {
        Lazy::Tdms(t) => {
            let ts: Vec<Option<f64>> = wanted.iter().map(|&k| t.sample_time(k)).collect();
            match ts.first().copied().flatten() {
                Some(t0) if ts.iter().all(|t| t.is_some_and(|t| ((t - t0) / t0).abs() <= 1e-9)) => Some(t0),
                Some(_) if ts.iter().any(|t| t.is_some_and(|t| ts[0].is_some_and(|t0| ((t - t0) / t0).abs() > 1e-9))) => {
                    return Err(DataFileError::SampleTime {
                        path: path.to_path_buf(),
                        message: format!(
                            "the selected channels have different sample times (wf_increment: {}); select channels recorded at one rate",
                            wanted
                                .iter()
                                .zip(&ts)
                                .map(|(&k, t)| format!("{} {}", all[k], t.map_or("none".into(), |t| format!("{t:e} s"))))
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    })
                }
                _ => None,
            }
        }
        Lazy::Mat(_) => None,
    };
    Ok(Table {
        path: path.to_path_buf(),
        names: wanted.iter().map(|&k| all[k].clone()).collect(),
        columns,
        ts_metadata,
    })
}

#[cfg(feature = "parquet")]
fn read_parquet(path: &Path, opts: &ReadOptions) -> Result<Table, DataFileError> {
    parquet::read(path, opts)
}

#[cfg(not(feature = "parquet"))]
fn read_parquet(path: &Path, _opts: &ReadOptions) -> Result<Table, DataFileError> {
    Err(DataFileError::ParquetDisabled {
        path: path.to_path_buf(),
    })
}

/// Final checks shared by all readers: at least one column and one row, equal lengths.
fn check_table(table: Table) -> Result<Table, DataFileError> {
    if table.columns.is_empty() || table.is_empty() {
        return Err(DataFileError::no_data(
            &table.path,
            "no data rows; check that this is the right file",
        ));
    }
    let n = table.len();
    if table.columns.iter().any(|c| c.len() != n) || table.names.len() != table.columns.len() {
        let lengths = table
            .names
            .iter()
            .zip(&table.columns)
            .map(|(name, c)| format!("{name}: {}", c.len()))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(DataFileError::LengthMismatch {
            path: table.path.clone(),
            lengths,
        });
    }
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(names: &[&str], columns: Vec<Vec<f64>>) -> Table {
        Table {
            path: PathBuf::from("mem.csv"),
            names: names.iter().map(|s| s.to_string()).collect(),
            columns,
            ts_metadata: None,
        }
    }

    #[test]
    fn column_ref_parse_and_display() {
        assert_eq!(ColumnRef::parse("#3"), ColumnRef::Index(3));
        assert_eq!(ColumnRef::parse(" #12 "), ColumnRef::Index(12));
        assert_eq!(ColumnRef::parse("#x"), ColumnRef::Name("#x".into()));
        assert_eq!(ColumnRef::parse("y"), ColumnRef::Name("y".into()));
        assert_eq!(ColumnRef::Index(2).to_string(), "#2");
        assert_eq!(ColumnRef::Name("u_V".into()).to_string(), "u_V");
    }

    #[test]
    fn format_from_str_and_extension() {
        assert_eq!("csv".parse::<Format>(), Ok(Format::Text));
        assert_eq!("TEXT".parse::<Format>(), Ok(Format::Text));
        assert_eq!("pq".parse::<Format>(), Ok(Format::Parquet));
        assert!("xlsx".parse::<Format>().is_err());
        assert_eq!(Format::from_extension("Dat"), Some(Format::Text));
    }

    #[test]
    fn column_lookup_and_missing_column_lists_names() {
        let t = table(&["t", "u"], vec![vec![0.0, 1.0], vec![2.0, 3.0]]);
        assert_eq!(t.len(), 2);
        assert_eq!(t.column(&ColumnRef::parse("u")).unwrap(), &[2.0, 3.0]);
        assert_eq!(t.column(&ColumnRef::Index(1)).unwrap(), &[0.0, 1.0]);
        let e = t.column(&ColumnRef::parse("y")).unwrap_err().to_string();
        assert!(e.contains("mem.csv") && e.contains("no column `y`"), "{e}");
        assert!(e.contains("`t` (#1), `u` (#2)"), "{e}");
        let e = t.column(&ColumnRef::Index(3)).unwrap_err().to_string();
        assert!(e.contains("no column `#3`"), "{e}");
        assert!(t.column(&ColumnRef::Index(0)).is_err());
    }

    #[test]
    fn sample_time_from_t_or_fs() {
        let t: Vec<f64> = (0..1000).map(|k| k as f64 * 1e-3).collect();
        let tab = table(&["t"], vec![t]);
        let c = ColumnRef::parse("t");
        assert!((tab.sample_time(Some(&c), None).unwrap() - 1e-3).abs() < 1e-15);
        assert!((tab.sample_time(Some(&c), Some(1000.0)).unwrap() - 1e-3).abs() < 1e-15);
        assert_eq!(tab.sample_time(None, Some(250.0)).unwrap(), 0.004);
        let e = tab.sample_time(None, None).unwrap_err().to_string();
        assert!(e.contains("`fs`") && e.contains("`t`"), "{e}");
        let e = tab
            .sample_time(Some(&c), Some(500.0))
            .unwrap_err()
            .to_string();
        assert!(e.contains("fs = 500"), "{e}");
        assert!(tab.sample_time(None, Some(0.0)).is_err());
        assert!(tab.sample_time(None, Some(f64::NAN)).is_err());
    }

    #[test]
    fn sample_time_rejects_bad_time_columns() {
        let c = ColumnRef::parse("t");
        let tab = table(&["t"], vec![vec![0.0, 0.1, 0.2, 0.2, 0.4]]);
        let e = tab.sample_time(Some(&c), None).unwrap_err().to_string();
        assert!(
            e.contains("not strictly increasing") && e.contains("row 4"),
            "{e}"
        );
        let tab = table(&["t"], vec![vec![0.0, 0.1, 0.25, 0.3, 0.4]]);
        let e = tab.sample_time(Some(&c), None).unwrap_err().to_string();
        assert!(
            e.contains("not uniformly sampled") && e.contains("row 3"),
            "{e}"
        );
        let tab = table(&["t"], vec![vec![0.0, f64::NAN, 0.2]]);
        assert!(tab.sample_time(Some(&c), None).is_err());
        let tab = table(&["t"], vec![vec![0.0]]);
        assert!(tab.sample_time(Some(&c), None).is_err());
        // rounding below 1e-3 Ts is fine
        let t: Vec<f64> = (0..100)
            .map(|k| (k as f64 * 0.1 * 1e9).round() / 1e9)
            .collect();
        let tab = table(&["t"], vec![t]);
        assert!(tab.sample_time(Some(&c), None).is_ok());
    }

    #[test]
    fn check_table_reports_lengths() {
        let t = table(&["a", "b"], vec![vec![1.0; 5], vec![1.0; 4]]);
        let e = check_table(t).unwrap_err().to_string();
        assert!(e.contains("a: 5, b: 4"), "{e}");
        let t = table(&[], vec![]);
        assert!(matches!(check_table(t), Err(DataFileError::NoData { .. })));
    }

    #[test]
    fn parquet_without_feature_says_how_to_enable_it() {
        if cfg!(feature = "parquet") {
            return;
        }
        let opts = ReadOptions {
            format: Some(Format::Parquet),
            ..ReadOptions::default()
        };
        let e = read_table(Path::new("x.parquet"), &opts)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("x.parquet") && e.contains("--features parquet"),
            "{e}"
        );
    }
}
