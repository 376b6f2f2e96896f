//! CSV time data (writing; reading is [`crate::io::time::read_time`], for every format) and FRF
//! files.
//!
//! Time data: a header row, one column per signal, SI units. An optional `t` column holds the
//! time in seconds; without it the sample rate must be given by the caller. Numbers are written
//! with 17 significant digits so a file read back reproduces the `f64` values exactly.
//!
//! FRF data: `f_hz, <q>_re, <q>_im, <q>_std, …` per quantity `q`, plus optional real columns such
//! as `coh_ry`.

use super::table::{read_table, DataFileError, Format, ReadOptions};
use crate::error::{Error, Result};
use num_complex::Complex64;
use std::path::Path;

/// The largest signal magnitude the reader accepts (defined with the reader, [`crate::io::time`]).
pub use super::time::MAX_SAMPLE_MAGNITUDE;

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
    time_csv_to(&mut v, columns).map_err(|e| Error::other(e.to_string()))?;
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

/// A CSV writer's error as an error of no class (its message kept).
fn csv_error(e: ::csv::Error) -> Error {
    Error::other(e.to_string())
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
        return Err(Error::other(format!(
            "FRF column `{name}` has {} values but there are {} frequencies",
            v.len(),
            f_hz.len()
        )));
    }
    for q in quantities {
        if q.values.len() != f_hz.len() || q.std.is_some_and(|s| s.len() != f_hz.len()) {
            return Err(Error::other(format!(
                "FRF quantity `{}` has {} values but there are {} frequencies",
                q.name,
                q.values.len(),
                f_hz.len()
            )));
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
    w.write_record(&header).map_err(csv_error)?;
    for (k, f) in f_hz.iter().enumerate() {
        let mut row = vec![format!("{f:.17e}")];
        for q in quantities {
            let v = q.values[k];
            row.push(format!("{:.17e}", v.re));
            row.push(format!("{:.17e}", v.im));
            row.push(format!("{:.17e}", q.std.map_or(0.0, |s| s[k])));
        }
        row.extend(extras.iter().map(|e| format!("{:.17e}", e.1[k])));
        w.write_record(&row).map_err(csv_error)?;
    }
    w.into_inner()
        .map_err(|e| Error::other(format!("{}", e.error())))
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
            _ => {
                return Err(Error::input(format!(
                    "the FRF file has no quantity `{q}` (columns {q}_re, {q}_im); it has: {}",
                    self.quantities.join(", ")
                )))
            }
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

    /// Quantity `q`'s noise per line as a function of its value, from the columns
    /// `<q>_noise_a, <q>_noise_b, <q>_noise_c_re, <q>_noise_c_im` that `ambid frf` writes for
    /// the plant ([`RatioNoise`](ambid_core::frf::closed_loop::RatioNoise): the variance at a
    /// value $G$ is $a|G|^2 + b - 2\operatorname{Re}(G c)$); `None` when the file has none of
    /// them (another tool's FRF, or an estimate without one).
    ///
    /// # Errors
    /// Some of the four columns but not all, or a negative `a` or `b`.
    ///
    /// # Example
    /// ```
    /// use ambid::io::csv::FrfFile;
    /// # fn main() -> Result<(), Box<dyn std::error::Error>> {
    /// let mut file = FrfFile {
    ///     f_hz: vec![10.0, 20.0],
    ///     quantities: vec!["plant".into()],
    ///     names: ["plant_noise_a", "plant_noise_b", "plant_noise_c_re", "plant_noise_c_im"]
    ///         .map(String::from)
    ///         .to_vec(),
    ///     columns: vec![vec![0.1, 0.2], vec![1e-4, 2e-4], vec![0.0, 1e-3], vec![0.0, 0.0]],
    /// };
    /// let n = file.ratio_noise("plant")?.ok_or("the four columns")?;
    /// // a|G|² + b − 2 Re(G c) at G = 1 on the second line
    /// let v = n[1].variance_at(ambid_core::c64::new(1.0, 0.0));
    /// assert!((v - (0.2 + 2e-4 - 2e-3)).abs() < 1e-15);
    /// assert!(file.ratio_noise("t_ry")?.is_none()); // no columns: none
    /// file.names.pop();
    /// file.columns.pop();
    /// assert!(file.ratio_noise("plant").is_err()); // three of the four
    /// # Ok(())
    /// # }
    /// ```
    pub fn ratio_noise(
        &self,
        q: &str,
    ) -> Result<Option<Vec<ambid_core::frf::closed_loop::RatioNoise>>> {
        let names = ["a", "b", "c_re", "c_im"].map(|s| format!("{q}_noise_{s}"));
        let cols: Vec<Option<&[f64]>> = names.iter().map(|n| self.col(n)).collect();
        match cols.as_slice() {
            [None, None, None, None] => Ok(None),
            [Some(a), Some(b), Some(cr), Some(ci)] => {
                if let Some(k) = (0..a.len()).find(|&k| !(a[k] >= 0.0 && b[k] >= 0.0)) {
                    return Err(Error::input(format!(
                        "`{q}_noise_a` and `{q}_noise_b` must be non-negative (variances); data row {} has {} and {}",
                        k + 1,
                        a[k],
                        b[k]
                    )));
                }
                Ok(Some(
                    (0..a.len())
                        .map(|k| ambid_core::frf::closed_loop::RatioNoise {
                            a: a[k],
                            b: b[k],
                            c: ambid_core::c64::new(cr[k], ci[k]),
                        })
                        .collect(),
                ))
            }
            _ => Err(Error::input(format!(
                "the FRF file has some of the noise columns {} but not all: give all four or none",
                names.join(", ")
            ))),
        }
    }

    /// A real extra column such as `coh_ry`.
    pub fn extra(&self, name: &str) -> Result<&[f64]> {
        self.col(name).ok_or_else(|| {
            Error::input(format!(
                "the FRF file has no column `{name}`; it has: {}",
                self.names.join(", ")
            ))
        })
    }
}

/// Reads an FRF CSV (`f_hz`, then `<q>_re, <q>_im, <q>_std` per quantity, then extra real
/// columns), in the one text dialect of [`crate::io::table`]. Every field must be a finite
/// number, every `_std` column non-negative and `f_hz` strictly increasing.
pub fn read_frf_csv(path: &Path) -> Result<FrfFile> {
    let table = read_text(path)?;
    let (header, mut cols) = (table.names, table.columns);
    if header.first().map(String::as_str) != Some("f_hz") {
        return Err(Error::input(format!(
            "{}: an FRF file starts with the column `f_hz` (got {}); see docs/formats.md",
            path.display(),
            header
                .first()
                .map_or("no column".to_string(), |h| format!("`{h}`"))
        )));
    }
    // a field refused at column `h`, data row `k + 1`
    let invalid = |h: &str, k: usize, why: String| -> Error {
        DataFileError::Invalid {
            path: path.to_path_buf(),
            message: format!("column `{h}`, data row {}: {why}", k + 1),
        }
        .into()
    };
    for (h, c) in header.iter().zip(&cols) {
        if let Some(k) = c.iter().position(|v| !v.is_finite()) {
            return Err(invalid(h, k, "the value is missing or not finite; every field of an FRF file must be a finite number".into()));
        }
    }
    // a standard deviation is not negative: its square would pass for a variance unnoticed
    for (h, c) in header
        .iter()
        .zip(&cols)
        .filter(|(h, _)| h.ends_with("_std"))
    {
        if let Some(k) = c.iter().position(|v| *v < 0.0) {
            return Err(invalid(h, k, format!("the standard deviation {} is negative; a `_std` column holds sqrt(E|Ĝ − G|²) ≥ 0 (0 for exact data)", c[k])));
        }
    }
    if let Some(k) = (1..cols[0].len()).find(|&k| cols[0][k] <= cols[0][k - 1]) {
        return Err(Error::input(format!(
            "{}: f_hz must increase strictly (data row {} has {:.6e} after {:.6e})",
            path.display(),
            k + 1,
            cols[0][k],
            cols[0][k - 1]
        )));
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
