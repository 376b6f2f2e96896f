//! A streaming reader of delimited text tables: the rows of a file come in blocks of chosen
//! columns, so a record of any length is read with memory for one block.
//!
//! The dialect is the one of the CLI's tables (`docs/formats.md`): lines whose first
//! non-blank character is `#` or `%` are comments, blank lines are skipped, the first other
//! line is the header (column names), fields are separated by commas (when the header holds
//! one) or else by runs of blanks, fields are trimmed and may be quoted with `"`, and an empty
//! field is a missing sample (NaN). A line longer than [`MAX_LINE_BYTES`] is an error (a file
//! without line breaks, such as `/dev/zero`, is not read into memory whole), as is a row with
//! another number of fields than the header or a field that is not a number; every message
//! names the file, the line and the column.
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

use anyhow::{anyhow, bail, Context, Result};
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

/// Longest line accepted (1 MiB): a table row of hundreds of columns is far shorter.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// A text table read row by row; see the [module docs](self).
#[derive(Debug)]
pub struct RowStream {
    path: PathBuf,
    reader: BufReader<File>,
    names: Vec<String>,
    comma: bool,
    /// 1-based number of the last line read.
    line: usize,
    buf: Vec<u8>,
    fields: Vec<f64>,
    /// Line number of every row of the last block.
    row_lines: Vec<usize>,
}

impl RowStream {
    /// Opens `path` and reads up to its header.
    ///
    /// # Errors
    /// An unreadable file, no header line, an empty or repeated column name, a line longer than
    /// [`MAX_LINE_BYTES`].
    pub fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
        let mut s = Self {
            path: path.to_path_buf(),
            reader: BufReader::with_capacity(1 << 16, file),
            names: Vec::new(),
            comma: true,
            line: 0,
            buf: Vec::new(),
            fields: Vec::new(),
            row_lines: Vec::new(),
        };
        let Some(header) = s.next_line()? else {
            bail!(
                "{}: no header row: the file is empty or holds only comments; the first line \
                 must name the columns, e.g. t,r,u,y",
                path.display()
            );
        };
        s.comma = header.contains(',');
        let names: Vec<String> = split(&header, s.comma)
            .map(|f| f.trim_matches('"').to_string())
            .collect();
        if let Some(k) = names.iter().position(String::is_empty) {
            bail!(
                "{}: line {}: column {} of the header has no name; name every column",
                path.display(),
                s.line,
                k + 1
            );
        }
        for (k, n) in names.iter().enumerate() {
            if names[..k].contains(n) {
                bail!(
                    "{}: line {}: the header names column `{n}` twice; give every column its own \
                     name",
                    path.display(),
                    s.line
                );
            }
        }
        s.names = names;
        Ok(s)
    }

    /// The column names of the header.
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
                    anyhow!(
                        "{}: unknown column `{w}`; the file has columns: {}",
                        self.path.display(),
                        self.names.join(", ")
                    )
                })
            })
            .collect()
    }

    /// The next data line (comments and blank lines skipped), without its line break.
    fn next_line(&mut self) -> Result<Option<String>> {
        loop {
            self.buf.clear();
            let got = (&mut self.reader)
                .take(MAX_LINE_BYTES as u64 + 1)
                .read_until(b'\n', &mut self.buf)
                .with_context(|| {
                    format!(
                        "{}: cannot read line {}",
                        self.path.display(),
                        self.line + 1
                    )
                })?;
            if got == 0 {
                return Ok(None);
            }
            self.line += 1;
            if self.buf.len() > MAX_LINE_BYTES && self.buf.last() != Some(&b'\n') {
                bail!(
                    "{}: line {} is longer than {} MiB (MAX_LINE_BYTES) without a line break: \
                     this is not a text table of samples (a binary file?); give a CSV file with \
                     one row per sample",
                    self.path.display(),
                    self.line,
                    MAX_LINE_BYTES >> 20
                );
            }
            let text = std::str::from_utf8(&self.buf).map_err(|_| {
                anyhow!(
                    "{}: line {} is not UTF-8 text (a binary file?); give a CSV file with one \
                     row per sample",
                    self.path.display(),
                    self.line
                )
            })?;
            let t = text.trim();
            if t.is_empty() || t.starts_with('#') || t.starts_with('%') {
                continue;
            }
            return Ok(Some(t.to_string()));
        }
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
        let width = self.names.len();
        let mut rows = 0;
        while rows < max_rows {
            let Some(line) = self.next_line()? else {
                break;
            };
            self.fields.clear();
            let mut count = 0;
            for (k, f) in split(&line, self.comma).enumerate() {
                count += 1;
                if k >= width {
                    continue;
                }
                let f = f.trim_matches('"');
                let v = if f.is_empty() {
                    f64::NAN
                } else {
                    f.parse::<f64>().map_err(|_| {
                        anyhow!(
                            "{}: line {}, column `{}`: `{}` is not a number",
                            self.path.display(),
                            self.line,
                            self.names[k],
                            short(f)
                        )
                    })?
                };
                self.fields.push(v);
            }
            if count != width {
                bail!(
                    "{}: line {} has {count} fields, the header has {width}; every row needs one \
                     field per column",
                    self.path.display(),
                    self.line
                );
            }
            for (o, &c) in out.iter_mut().zip(cols) {
                o.push(self.fields[c]);
            }
            self.row_lines.push(self.line);
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

/// The fields of a line: comma separated, or separated by runs of blanks.
fn split(line: &str, comma: bool) -> Box<dyn Iterator<Item = &str> + '_> {
    if comma {
        Box::new(line.split(',').map(str::trim))
    } else {
        Box::new(line.split_whitespace())
    }
}

/// At most 40 characters of a field, for messages.
fn short(f: &str) -> String {
    if f.chars().count() > 40 {
        format!("{}…", f.chars().take(40).collect::<String>())
    } else {
        f.to_string()
    }
}
