//! Delimited text: CSV, semicolon- or tab-separated, or columns separated by runs of whitespace.
//!
//! * Blank lines and lines starting with `#` or `%` (after leading whitespace) are skipped.
//! * Delimiter (unless given): the first of tab, `;`, `,`, whitespace that splits the first data
//!   lines into the same number (≥ 2) of fields.
//! * Header (unless told): the first line is a header if one of its cells is not a number.
//! * Cells may be quoted (`"V1"`); empty cells are NaN. A trailing delimiter on every line (an
//!   extra empty last column without a header name) is ignored.
//! * Numbers: anything Rust's `f64` parser accepts (`1e-3`, `NaN`, `nan`, `Inf`, `-inf`), also
//!   Fortran exponents (`1.0D-3`).

use std::borrow::Cow;
use std::path::Path;

use super::{DataFileError, ReadOptions, Table};

/// How a line is split into fields.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Delim {
    /// A single character (`,`, `;`, tab, …).
    Char(char),
    /// Runs of spaces and tabs.
    Whitespace,
    /// The whole line is one field (single-column files).
    None,
}

/// How many lines the delimiter detection looks at.
const SNIFF_LINES: usize = 20;

/// The longest line the reader accepts (a text data file has lines of a few hundred bytes; a
/// file without line breaks, such as `/dev/zero` or a binary file, is refused at this length
/// instead of being read whole).
pub const MAX_LINE_BYTES: usize = 1 << 20;

pub(super) fn read(path: &Path, opts: &ReadOptions) -> Result<Table, DataFileError> {
    let file = std::fs::File::open(path).map_err(|e| DataFileError::open(path, &e))?;
    parse(path, std::io::BufReader::new(file), opts)
}

/// Content lines of a text file, read one at a time: (1-based line number, line without the
/// line ending); blank and comment lines are skipped.
struct Lines<R> {
    path: std::path::PathBuf,
    rdr: R,
    no: usize,
    buf: Vec<u8>,
    /// Whether any non-blank line (also a comment) was seen.
    any_text: bool,
}

impl<R: std::io::BufRead> Lines<R> {
    fn next_line(&mut self) -> Result<Option<(usize, String)>, DataFileError> {
        use std::io::{BufRead, Read};
        loop {
            self.buf.clear();
            let n = (&mut self.rdr)
                .take(MAX_LINE_BYTES as u64 + 1)
                .read_until(b'\n', &mut self.buf)
                .map_err(|e| DataFileError::open(&self.path, &e))?;
            if n == 0 {
                return Ok(None);
            }
            self.no += 1;
            if self.buf.len() > MAX_LINE_BYTES && self.buf.last() != Some(&b'\n') {
                return Err(DataFileError::invalid(
                    &self.path,
                    format!(
                        "line {} is longer than {} MiB; this is not a text data file (if it is a binary file, give its format: npy, npz, mat, parquet)",
                        self.no,
                        MAX_LINE_BYTES >> 20
                    ),
                ));
            }
            let raw = self.buf.strip_suffix(b"\n").unwrap_or(&self.buf);
            let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
            let text = std::str::from_utf8(raw).map_err(|_| {
                DataFileError::invalid(
                    &self.path,
                    format!(
                        "line {} is not UTF-8 text; if this is a binary file give its format (npy, npz, mat, parquet) or fix the file's extension",
                        self.no
                    ),
                )
            })?;
            let text = if self.no == 1 {
                text.strip_prefix('\u{feff}').unwrap_or(text)
            } else {
                text
            };
            let t = text.trim();
            if !t.is_empty() {
                self.any_text = true;
            }
            if t.is_empty() || t.starts_with('#') || t.starts_with('%') {
                continue;
            }
            return Ok(Some((self.no, text.to_string())));
        }
    }
}

/// A delimited text table read one row at a time, in the dialect of the module docs: the first
/// lines decide the delimiter and the header, then every row comes as numbers (NaN for an empty
/// cell), checked against the header's width. Every reader of text data (the whole-table reader
/// `read` and the streaming FRF reader `ambid::io::stream`) goes through it, so there is one
/// dialect.
pub struct TextRows<R> {
    src: Lines<R>,
    delim: Delim,
    /// Header cells (raw), if there is a header.
    header: Option<Vec<String>>,
    width: usize,
    /// Sniffed lines not handed out yet.
    pending: std::collections::VecDeque<(usize, String)>,
    reference: String,
}

impl TextRows<std::io::BufReader<std::fs::File>> {
    /// Opens `path` and reads up to its first data row.
    ///
    /// # Errors
    /// An unreadable file, an empty file or one of comments only, a header that names a column
    /// twice, no data row after the header, a line that is not text or is longer than
    /// [`MAX_LINE_BYTES`].
    pub fn open(path: &Path, opts: &ReadOptions) -> Result<Self, DataFileError> {
        let file = std::fs::File::open(path).map_err(|e| DataFileError::open(path, &e))?;
        Self::new(path, std::io::BufReader::with_capacity(1 << 16, file), opts)
    }
}

impl<R: std::io::BufRead> TextRows<R> {
    /// As [`TextRows::open`], on the text read from `rdr` (`path` names it in messages).
    ///
    /// # Errors
    /// As [`TextRows::open`].
    pub fn new(path: &Path, rdr: R, opts: &ReadOptions) -> Result<Self, DataFileError> {
        let mut src = Lines {
            path: path.to_path_buf(),
            rdr,
            no: 0,
            buf: Vec::new(),
            any_text: false,
        };
        let mut head: Vec<(usize, String)> = Vec::new();
        while head.len() < SNIFF_LINES {
            match src.next_line()? {
                Some(l) => head.push(l),
                None => break,
            }
        }
        let Some((first_no, first_line)) = head.first().cloned() else {
            return Err(DataFileError::no_data(
                path,
                if src.any_text {
                    "the file has only comment and blank lines, no data; check that this is the right file"
                        .to_string()
                } else {
                    "the file is empty; check that this is the right file".to_string()
                },
            ));
        };
        let lines: Vec<(usize, &str)> = head.iter().map(|(n, l)| (*n, l.as_str())).collect();
        let delim = match opts.delimiter {
            Some(' ') => Delim::Whitespace,
            Some(c) => Delim::Char(c),
            None => detect_delimiter(&lines),
        };
        let split_at = |no: usize, line: &str| -> Result<Vec<String>, DataFileError> {
            Ok(split_line(path, no, line, delim)?
                .into_iter()
                .map(Cow::into_owned)
                .collect())
        };
        let first = split_at(first_no, &first_line)?;
        let has_header = match opts.header {
            Some(h) => h,
            None => first
                .iter()
                .any(|c| !c.is_empty() && parse_number(c).is_none()),
        };
        let (header, skip_head, reference) = if has_header {
            let names: Vec<String> = first.iter().map(|c| c.to_string()).collect();
            if let Some(m) = duplicate_names(&names) {
                return Err(DataFileError::invalid(
                    path,
                    format!("line {first_no}: {m}"),
                ));
            }
            (Some(names), 1, "the header".to_string())
        } else {
            (None, 0, format!("line {first_no} (the first data line)"))
        };
        let Some((ref_no, ref_line)) = head.get(skip_head).cloned() else {
            return Err(DataFileError::no_data(
                path,
                format!("there are no data rows after the header on line {first_no}; check that this is the right file"),
            ));
        };
        let width = match &header {
            Some(n) => n.len(),
            None => split_at(ref_no, &ref_line)?.len(),
        };
        Ok(Self {
            src,
            delim,
            header,
            width,
            pending: head.into_iter().skip(skip_head).collect(),
            reference,
        })
    }

    /// Number of fields of every row.
    pub fn width(&self) -> usize {
        self.width
    }

    /// The name of column `j` (0-based): the header's, or `col<j+1>` without a header or for an
    /// empty header cell.
    pub fn column_name(&self, j: usize) -> String {
        self.header
            .as_ref()
            .and_then(|n| n.get(j))
            .filter(|s| !s.is_empty())
            .cloned()
            .unwrap_or_else(|| format!("col{}", j + 1))
    }

    /// Whether the file has a header row, and whether its last cell is empty.
    fn unnamed_last(&self) -> bool {
        self.header
            .as_ref()
            .is_none_or(|n| n.last().is_some_and(|s| s.is_empty()))
    }

    /// The file being read.
    pub fn path(&self) -> &Path {
        &self.src.path
    }

    /// The next row into `out` (cleared first; `width` numbers, NaN for an empty cell); returns
    /// its 1-based line number, `None` at the end of the file.
    ///
    /// # Errors
    /// A row with another number of fields, a cell that is not a number (file, line and column
    /// named), an overlong or non-text line.
    pub fn next_row(&mut self, out: &mut Vec<f64>) -> Result<Option<usize>, DataFileError> {
        let (no, line) = match self.pending.pop_front() {
            Some(l) => l,
            None => match self.src.next_line()? {
                Some(l) => l,
                None => return Ok(None),
            },
        };
        let path = self.src.path.as_path();
        let mut cells = split_line(path, no, &line, self.delim)?;
        // Tolerate one extra trailing empty field (a trailing delimiter).
        if cells.len() == self.width + 1 && cells.last().is_some_and(|c| c.is_empty()) {
            cells.pop();
        }
        if cells.len() != self.width {
            return Err(DataFileError::RaggedRow {
                path: path.to_path_buf(),
                line: no,
                fields: cells.len(),
                expected: self.width,
                reference: self.reference.clone(),
            });
        }
        out.clear();
        for (j, cell) in cells.iter().enumerate() {
            let v = if cell.is_empty() {
                f64::NAN
            } else {
                match parse_number(cell) {
                    Some(v) => v,
                    None => {
                        return Err(DataFileError::NotANumber {
                            path: path.to_path_buf(),
                            line: no,
                            column: self.column_name(j),
                            cell: cell.to_string(),
                        })
                    }
                }
            };
            out.push(v);
        }
        Ok(Some(no))
    }
}

/// Parses the text read from `rdr` (the file `path`, named in messages), one line at a time.
fn parse<R: std::io::BufRead>(
    path: &Path,
    rdr: R,
    opts: &ReadOptions,
) -> Result<Table, DataFileError> {
    let mut rows = TextRows::new(path, rdr, opts)?;
    let width = rows.width();
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); width];
    // Whether every cell of a column is empty so far.
    let mut all_empty = vec![true; width];
    let mut row = Vec::with_capacity(width);
    while rows.next_row(&mut row)?.is_some() {
        for (j, v) in row.iter().enumerate() {
            if !v.is_nan() {
                all_empty[j] = false;
            }
            columns[j].push(*v);
        }
    }
    // A trailing delimiter on every line gives a last column without name and without values.
    let mut n_cols = width;
    if width > 1 && rows.unnamed_last() && all_empty.last() == Some(&true) {
        columns.pop();
        n_cols -= 1;
    }
    let names = unique_names((0..n_cols).map(|j| rows.column_name(j)).collect());
    Ok(Table {
        path: path.to_path_buf(),
        names,
        columns,
        ts_metadata: None,
    })
}

/// [`split`] with the error naming the file and line.
fn split_line<'a>(
    path: &Path,
    no: usize,
    line: &'a str,
    delim: Delim,
) -> Result<Vec<Cow<'a, str>>, DataFileError> {
    split(line, delim).map_err(|m| DataFileError::invalid(path, format!("line {no}: {m}")))
}

/// A header that names a column twice: which name, at which positions, and what to do.
fn duplicate_names(names: &[String]) -> Option<String> {
    for (j, n) in names.iter().enumerate() {
        if n.is_empty() {
            continue;
        }
        if let Some(k) = names[j + 1..].iter().position(|m| m == n) {
            return Some(format!(
                "the header names column `{n}` twice (columns {} and {}), so `{n}` would be ambiguous; rename one of them",
                j + 1,
                j + k + 2
            ));
        }
    }
    None
}

/// Makes duplicate names unique by appending `_2`, `_3`, … (a generated `colK` may meet a
/// header name `colK`).
fn unique_names(names: Vec<String>) -> Vec<String> {
    let mut out: Vec<String> = Vec::with_capacity(names.len());
    for n in names {
        let mut candidate = n.clone();
        let mut k = 2;
        while out.contains(&candidate) {
            candidate = format!("{n}_{k}");
            k += 1;
        }
        out.push(candidate);
    }
    out
}

/// Reads one cell as a number (`None` if it is not one).
fn parse_number(cell: &str) -> Option<f64> {
    let s = cell.trim();
    if let Ok(v) = s.parse::<f64>() {
        return Some(v);
    }
    // Fortran-style exponent: 1.0D-03.
    if s.contains(['d', 'D']) && s.bytes().any(|b| b.is_ascii_digit()) {
        return s.replace(['d', 'D'], "e").parse::<f64>().ok();
    }
    None
}

/// The delimiter that gives the same number (≥ 2) of fields on the first data lines; tried in
/// the order tab, `;`, `,`, whitespace. If none does on all lines, the first line (a header may
/// be spelt differently) is left out; if still none, a file whose lines are single fields is
/// one column, and otherwise the candidate with the most fields on the second line is taken
/// (the row check then reports the offending line).
fn detect_delimiter(lines: &[(usize, &str)]) -> Delim {
    let candidates = [
        Delim::Char('\t'),
        Delim::Char(';'),
        Delim::Char(','),
        Delim::Whitespace,
    ];
    let sample: Vec<&str> = lines.iter().take(SNIFF_LINES).map(|(_, l)| *l).collect();
    let consistent = |d: Delim, ls: &[&str]| -> bool {
        let mut counts = ls.iter().map(|l| split(l, d).map(|f| f.len()).unwrap_or(0));
        match counts.next() {
            Some(n) if n >= 2 => counts.all(|m| m == n),
            _ => false,
        }
    };
    for ls in [&sample[..], sample.get(1..).unwrap_or(&[])] {
        if ls.is_empty() {
            continue;
        }
        if let Some(d) = candidates.iter().copied().find(|&d| consistent(d, ls)) {
            return d;
        }
    }
    let probe = sample.get(1).or(sample.first()).copied().unwrap_or("");
    let (best, n) = candidates
        .iter()
        .map(|&d| (d, split(probe, d).map(|f| f.len()).unwrap_or(0)))
        .fold((Delim::None, 1), |acc, x| if x.1 > acc.1 { x } else { acc });
    if n >= 2 {
        best
    } else {
        Delim::None
    }
}

/// Splits a line into trimmed, unquoted fields. Double quotes group a field (`""` inside
/// quotes is a quote).
fn split(line: &str, delim: Delim) -> Result<Vec<Cow<'_, str>>, String> {
    match delim {
        Delim::None => Ok(vec![unquote(line.trim())?]),
        Delim::Whitespace => {
            let mut out = Vec::new();
            let mut rest = line.trim();
            while !rest.is_empty() {
                let end = if rest.starts_with('"') {
                    closing_quote(rest)?
                } else {
                    rest.find(char::is_whitespace).unwrap_or(rest.len())
                };
                let (field, tail) = rest.split_at(end);
                out.push(unquote(field)?);
                rest = tail.trim_start();
            }
            Ok(out)
        }
        Delim::Char(c) => {
            // Tab-separated lines keep their tabs (an empty last cell is a cell).
            let line = if c == '\t' {
                line.trim_matches(|ch: char| ch.is_whitespace() && ch != '\t')
            } else {
                line.trim()
            };
            let mut out = Vec::new();
            let mut rest = line;
            loop {
                let lead = rest.len() - rest.trim_start_matches([' ', '\t']).len();
                let body = rest.get(lead..).unwrap_or("");
                let end = if body.starts_with('"') && c != '"' {
                    let q = closing_quote(body)?;
                    lead + q
                        + body
                            .get(q..)
                            .and_then(|t| t.find(c))
                            .unwrap_or(body.len() - q)
                } else {
                    rest.find(c).unwrap_or(rest.len())
                };
                let (field, tail) = rest.split_at(end);
                out.push(unquote(field.trim())?);
                match tail.strip_prefix(c) {
                    Some(t) => rest = t,
                    None => break,
                }
            }
            Ok(out)
        }
    }
}

/// Byte index just after the closing quote of a field starting with `"`.
fn closing_quote(s: &str) -> Result<usize, String> {
    let mut chars = s.char_indices().skip(1).peekable();
    while let Some((i, ch)) = chars.next() {
        if ch == '"' {
            if chars.peek().is_some_and(|&(_, n)| n == '"') {
                chars.next();
                continue;
            }
            return Ok(i + 1);
        }
    }
    Err("a quoted field is not closed (missing `\"`); close the quote or remove it".into())
}

/// Removes surrounding double quotes (and unescapes `""`), or returns the field as it is.
fn unquote(field: &str) -> Result<Cow<'_, str>, String> {
    match field.strip_prefix('"') {
        None => Ok(Cow::Borrowed(field)),
        Some(inner) => {
            let end = closing_quote(field)?;
            if end != field.len() {
                return Err(format!(
                    "text after a closing quote in `{field}`; quote the whole field or remove the quotes"
                ));
            }
            let inner = inner.strip_suffix('"').unwrap_or(inner);
            Ok(Cow::Owned(inner.replace("\"\"", "\"").trim().to_string()))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_str(s: &str) -> Result<Table, DataFileError> {
        parse(Path::new("mem.csv"), s.as_bytes(), &ReadOptions::default())
    }

    #[test]
    fn csv_with_header_comments_crlf_and_special_numbers() {
        let t = read_str(
            "% recorded 2024\r\n# another comment\r\n\r\n\"t\", \"u\" ,y\r\n0,1e-3,NaN\r\n1, -inf ,Inf\r\n2,+3.5,nan\r\n",
        )
        .unwrap();
        assert_eq!(t.names, ["t", "u", "y"]);
        assert_eq!(t.columns[0], [0.0, 1.0, 2.0]);
        assert_eq!(t.columns[1][0], 1e-3);
        assert_eq!(t.columns[1][1], f64::NEG_INFINITY);
        assert_eq!(t.columns[1][2], 3.5);
        assert!(t.columns[2][0].is_nan() && t.columns[2][2].is_nan());
        assert_eq!(t.columns[2][1], f64::INFINITY);
    }

    #[test]
    fn delimiters_are_detected() {
        let t = read_str("a;b\n1,5;2\n3;4\n").unwrap_err().to_string();
        assert!(t.contains("line 2, column `a`: cannot read `1,5`"), "{t}");
        let t = read_str("a;b\n1;2\n3;4\n").unwrap();
        assert_eq!(t.columns, vec![vec![1.0, 3.0], vec![2.0, 4.0]]);
        let t = read_str("1\t2\t3\n4\t5\t6\n").unwrap();
        assert_eq!(t.names, ["col1", "col2", "col3"]);
        assert_eq!(t.columns[2], [3.0, 6.0]);
        let t = read_str("   1.0e+00    -2   \n  3 4\n").unwrap();
        assert_eq!(t.columns, vec![vec![1.0, 3.0], vec![-2.0, 4.0]]);
        // header with spaces in names, data separated by whitespace runs
        let t = read_str("\"time s\"  \"y m\"\n0 1\n1 2\n").unwrap();
        assert_eq!(t.names, ["time s", "y m"]);
        // single column, header with a space
        let t = read_str("my signal\n1\n2\n").unwrap();
        assert_eq!(t.names, ["my signal"]);
        assert_eq!(t.columns, vec![vec![1.0, 2.0]]);
        // given delimiter
        let opts = ReadOptions {
            delimiter: Some('|'),
            ..ReadOptions::default()
        };
        let t = parse(Path::new("p.txt"), &b"a|b\n1|2\n"[..], &opts).unwrap();
        assert_eq!(t.names, ["a", "b"]);
    }

    #[test]
    fn trailing_delimiters_and_empty_cells() {
        // nonlinearbenchmark style: quoted header, trailing comma, constant only in row 1
        let t = read_str("\"u\",\"y\",\"Ts\",\n1,2,4,\n3,4,,\n").unwrap();
        assert_eq!(t.names, ["u", "y", "Ts"]);
        assert_eq!(t.columns[2][0], 4.0);
        assert!(t.columns[2][1].is_nan());
        // DaISy style: spaces and a trailing tab, no header
        let t = read_str("   1.0e+00\t  2.0e+00\t\n   3.0e+00\t  4.0e+00\t\n").unwrap();
        assert_eq!(t.names, ["col1", "col2"]);
        assert_eq!(t.columns, vec![vec![1.0, 3.0], vec![2.0, 4.0]]);
        // a row with one extra trailing delimiter is fine
        let t = read_str("a,b\n1,2,\n3,4\n").unwrap();
        assert_eq!(t.columns, vec![vec![1.0, 3.0], vec![2.0, 4.0]]);
    }

    #[test]
    fn header_option_and_duplicate_names() {
        let opts = ReadOptions {
            header: Some(true),
            ..ReadOptions::default()
        };
        let t = parse(Path::new("h.csv"), &b"1,2\n3,4\n"[..], &opts).unwrap();
        assert_eq!(t.names, ["1", "2"]);
        assert_eq!(t.len(), 1);
        // a header naming a column twice is refused (it used to be renamed `x_2`, and a lookup
        // of `x` silently took the first); an unnamed column is `colK`
        let e = read_str("x,x,,y\n1,2,3,4\n").unwrap_err().to_string();
        assert!(
            e.contains("line 1: the header names column `x` twice (columns 1 and 2)"),
            "{e}"
        );
        let t = read_str("x,w,,y\n1,2,3,4\n").unwrap();
        assert_eq!(t.names, ["x", "w", "col3", "y"]);
        let t = read_str("1.0D-03,2d0\n").unwrap();
        assert_eq!(t.columns, vec![vec![1e-3], vec![2.0]]);
    }

    #[test]
    fn errors_carry_file_line_numbers() {
        let e = read_str("# c\nt,u,y\n0,1,2\n\n1,2\n").unwrap_err();
        match &e {
            DataFileError::RaggedRow {
                line,
                fields,
                expected,
                ..
            } => assert_eq!((*line, *fields, *expected), (5, 2, 3)),
            other => panic!("{other:?}"),
        }
        let m = e.to_string();
        assert!(
            m.starts_with("mem.csv: line 5 has 2 fields, the header has 3"),
            "{m}"
        );
        let e = read_str("1 2 3\n% c\n4 5\n").unwrap_err().to_string();
        assert!(
            e.contains("line 3 has 2 fields, line 1 (the first data line) has 3"),
            "{e}"
        );
        let e = read_str("t,u,y\n0,1,2\n1,2,abc\n").unwrap_err();
        assert!(matches!(e, DataFileError::NotANumber { line: 3, .. }));
        let e = e.to_string();
        assert!(
            e.contains("line 3, column `y`: cannot read `abc` as a number"),
            "{e}"
        );
        let e = read_str("").unwrap_err();
        assert!(matches!(e, DataFileError::NoData { .. }), "{e}");
        assert!(e.to_string().contains("empty"));
        let e = read_str("# only\n% comments\n\n").unwrap_err().to_string();
        assert!(e.contains("only comment"), "{e}");
        let e = read_str("t,u\n# nothing\n").unwrap_err().to_string();
        assert!(e.contains("no data rows after the header on line 1"), "{e}");
        let e = read_str("t,\"u\n1,2\n").unwrap_err().to_string();
        assert!(e.contains("line 1") && e.contains("not closed"), "{e}");
        let e = parse(
            Path::new("b.csv"),
            &b"a,b\n1,2\n\xff\xfe,3\n"[..],
            &ReadOptions::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("line 3 is not UTF-8"), "{e}");
    }

    #[test]
    fn splitter_never_panics_on_odd_lines() {
        let odd = [
            "",
            "\"",
            "\"\"",
            ",,,",
            "\"a\"\"b\",c",
            " \" x \" , y",
            "\t\t",
            "é,ü;ß\tø",
            "\"a\"b",
            "a\"b,c",
            "\u{feff}1,2",
            ";;\"",
            "  \"  ",
        ];
        for l in odd {
            for d in [
                Delim::Char(','),
                Delim::Char(';'),
                Delim::Char('\t'),
                Delim::Char('"'),
                Delim::Whitespace,
                Delim::None,
            ] {
                let _ = split(l, d);
            }
            let _ = read_str(l);
            let _ = read_str(&format!("{l}\n{l}\n"));
        }
        assert_eq!(
            split("\"a\"\"b\",c", Delim::Char(',')).unwrap(),
            ["a\"b", "c"]
        );
        assert_eq!(split("\"x,y\",2", Delim::Char(',')).unwrap(), ["x,y", "2"]);
    }
}
