//! Reading recorded data files into named numeric columns: CSV and whitespace-separated text,
//! NumPy `.npy`/`.npz`, MATLAB `.mat` (v5) and Parquet (cargo feature `parquet`).
//!
//! SKELETON: the interface is fixed; the readers are being written.

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
    /// MATLAB `.mat` version 5.
    Mat,
    /// Apache Parquet (needs the cargo feature `parquet`).
    Parquet,
}

/// How to read a file. Everything is optional; the defaults detect.
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// Format; `None` decides from the extension (`.csv`, `.txt`, `.dat`, `.tsv` → text).
    pub format: Option<Format>,
    /// Text: the delimiter; `None` detects it from the first data lines.
    pub delimiter: Option<char>,
    /// Text: whether the first non-comment line is a header; `None` detects it (non-numeric cells).
    pub header: Option<bool>,
    /// `.mat`/`.npz`: only read this variable (others are ignored).
    pub variable: Option<String>,
}

/// A column reference: by name, or by 1-based position (`"#3"` or the integer 3 in TOML).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ColumnRef {
    /// By name.
    Name(String),
    /// By 1-based position.
    Index(usize),
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
}

/// Reads a data file.
pub fn read_table(path: &Path, opts: &ReadOptions) -> Result<Table, DataFileError> {
    let _ = opts;
    Err(DataFileError::Invalid {
        path: path.to_path_buf(),
        message: "not implemented yet".into(),
    })
}

// TEMPORARY minimal methods so that the workflow compiles before the readers land.
impl ColumnRef {
    /// `"#3"` → position 3, anything else a name.
    pub fn parse(s: &str) -> Self {
        match s.strip_prefix('#').and_then(|k| k.parse().ok()) {
            Some(k) => ColumnRef::Index(k),
            None => ColumnRef::Name(s.to_string()),
        }
    }
}

impl Table {
    /// A column.
    pub fn column(&self, c: &ColumnRef) -> Result<&[f64], DataFileError> {
        let k = match c {
            ColumnRef::Index(k) => k.checked_sub(1),
            ColumnRef::Name(n) => self.names.iter().position(|x| x == n),
        };
        k.and_then(|k| self.columns.get(k))
            .map(Vec::as_slice)
            .ok_or_else(|| DataFileError::Invalid {
                path: self.path.clone(),
                message: format!("no column {c:?}"),
            })
    }

    /// The sample time.
    pub fn sample_time(
        &self,
        t: Option<&ColumnRef>,
        fs_hz: Option<f64>,
    ) -> Result<f64, DataFileError> {
        match (t, fs_hz) {
            (_, Some(fs)) => Ok(1.0 / fs),
            (Some(c), None) => {
                let t = self.column(c)?;
                Ok((t[t.len() - 1] - t[0]) / (t.len() - 1) as f64)
            }
            _ => Err(DataFileError::Invalid {
                path: self.path.clone(),
                message: "give fs_hz or a time column".into(),
            }),
        }
    }
}
