//! A streaming reader of delimited text tables: the rows of a file come in blocks of chosen
//! columns, so a record of any length is read with memory for one block.
//!
//! The dialect is the one of every text reader of ambid (`docs/data-files.md`): this is a thin
//! layer over [`crate::io::table::TextRows`], the row reader behind the whole-table reader too —
//! comment lines (`#`, `%`) and blank lines skipped, the delimiter (tab, `;`, `,`, whitespace)
//! and the header detected from the first lines, quoted cells, empty cells as missing samples
//! (NaN), a line longer than [`MAX_LINE_BYTES`] refused (a file without line breaks, such as
//! `/dev/zero`, is not read into memory whole), a header that names a column twice refused, and
//! every message naming the file, the line and the column.
//!
//! # Example
//! ```
//! use ambid::io::stream::RowStream;
//! let dir = std::env::temp_dir().join(format!("ambid-stream-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir).unwrap();
//! let p = dir.join("x.csv");
//! std::fs::write(&p, "# a comment\nt, r ,y\n0,1,2\n% another\n1,3,4\n2,5,\n").unwrap();
//! let mut s = RowStream::open(&p).unwrap();
//! assert_eq!(s.names(), ["t", "r", "y"]);
//! let cols = s.indices(&["y", "r"]).unwrap();
//! let mut out = vec![Vec::new(), Vec::new()];
//! assert_eq!(s.next_block(&cols, 2, &mut out).unwrap(), 2);
//! assert_eq!(out, vec![vec![2.0, 4.0], vec![1.0, 3.0]]);
//! assert_eq!(s.next_block(&cols, 2, &mut out).unwrap(), 1);
//! assert!(out[0][0].is_nan() && out[1][0] == 5.0);
//! assert_eq!(s.next_block(&cols, 2, &mut out).unwrap(), 0);
//! ```

use crate::error::{Error, Result};
use crate::io::table::{ReadOptions, TextRows};
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

pub use crate::io::table::MAX_LINE_BYTES;

/// A text table read row by row; see the [module docs](self).
pub struct RowStream {
    path: PathBuf,
    rows: TextRows<BufReader<File>>,
    names: Vec<String>,
    /// 1-based number of the last line read.
    line: usize,
    fields: Vec<f64>,
    /// Line number of every row of the last block.
    row_lines: Vec<usize>,
}

impl std::fmt::Debug for RowStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RowStream")
            .field("path", &self.path)
            .field("names", &self.names)
            .field("line", &self.line)
            .finish()
    }
}

impl RowStream {
    /// Opens `path` and reads up to its first data row.
    ///
    /// # Errors
    /// As [`TextRows::open`]: an unreadable or empty file, a column named twice, no data row, a
    /// line longer than [`MAX_LINE_BYTES`].
    pub fn open(path: &Path) -> Result<Self> {
        let rows = TextRows::open(path, &ReadOptions::default())?;
        let names = (0..rows.width()).map(|j| rows.column_name(j)).collect();
        Ok(Self {
            path: path.to_path_buf(),
            rows,
            names,
            line: 0,
            fields: Vec::new(),
            row_lines: Vec::new(),
        })
    }

    /// The column names of the header (`col1`, `col2`, … without one).
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The file read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The positions of `wanted` columns.
    ///
    /// # Errors
    /// A name that is not in the header (the message lists the columns there are).
    pub fn indices(&self, wanted: &[&str]) -> Result<Vec<usize>> {
        wanted
            .iter()
            .map(|w| {
                self.names.iter().position(|n| n == w).ok_or_else(|| {
                    Error::other(format!(
                        "{}: unknown column `{w}`; the file has columns: {}",
                        self.path.display(),
                        self.names.join(", ")
                    ))
                })
            })
            .collect()
    }

    /// Reads up to `max_rows` rows and appends the columns `cols` (positions from
    /// [`indices`](Self::indices)) to `out` (one vector per wanted column, cleared first).
    /// Returns the number of rows read; 0 at the end of the file.
    ///
    /// # Errors
    /// A row with another number of fields than the header, a field that is not a number (the
    /// message names the file, the line and the column), an overlong line.
    pub fn next_block(
        &mut self,
        cols: &[usize],
        max_rows: usize,
        out: &mut [Vec<f64>],
    ) -> Result<usize> {
        for o in out.iter_mut() {
            o.clear();
        }
        self.row_lines.clear();
        let mut rows = 0;
        while rows < max_rows {
            let Some(no) = self.rows.next_row(&mut self.fields)? else {
                break;
            };
            self.line = no;
            for (o, &c) in out.iter_mut().zip(cols) {
                o.push(self.fields[c]);
            }
            self.row_lines.push(no);
            rows += 1;
        }
        Ok(rows)
    }

    /// The 1-based line number of every row of the last block.
    pub fn block_lines(&self) -> &[usize] {
        &self.row_lines
    }

    /// 1-based number of the last line read.
    pub fn line(&self) -> usize {
        self.line
    }
}
