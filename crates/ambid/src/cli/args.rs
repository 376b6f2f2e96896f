//! The command line's shared conventions, parsed in one place for every command
//! (docs/conventions.md, "Command line"):
//!
//! - **Excitation level**: a percentage of the actuator's saturation current $i_\mathrm{sat}$,
//!   written `12` or `12%` (`--level`, `--levels`); `0.24A` gives amperes where a command knows
//!   $i_\mathrm{sat}$ (`excite`, `compare`). Peak for PRBS and chirp (a PRBS's RMS equals its
//!   peak), RMS for noise and random-phase multisines (whose peak depends on the phases).
//! - **Band**: `f_min:f_max` in Hz (`--band 10:1000`); the older `f_min,f_max` is accepted with
//!   a note on stderr.
//! - **Columns**: `--excitation` (r), `--input` (the controller output u, the plant input),
//!   `--output` (y), `--current` (the coil current i) in every command that reads them.
//!
//!
//! The argument groups shared by several commands are defined here once and flattened into
//! each command (`#[command(flatten)]`): [`DataFileArgs`] (the reader: `--fs`, `--format`,
//! `--variable`, `--time`), the data columns [`ExcitationColumn`] (`--excitation`, r),
//! [`InputColumn`] (`--input`, u), [`OutputColumn`] (`--output`, y), [`CurrentColumn`]
//! (`--current`, i), [`BandArg`]
//! (`--band`) and [`Force`] (`--force`). A command whose option says more than the shared
//! help (its default band, a MIMO list) keeps its own text with `mut_arg`.
//!
//! Deprecated spellings keep working and print one `note:` line on stderr naming the new one;
//! malformed values are usage errors (exit code 2) naming the option.

use ambid::io::table::{ColumnRef, Format, ReadOptions};
use ambid::io::time::{Bound, Window};
use ambid::io::{read_time, TimeData, TimeOptions};
use clap::Args;
use std::path::Path;

/// How the data files of a command are read (every command that reads a record: `frf`, `fit`,
/// `order`, `validate`, `compare-models`, `bla`, `study amplitude`): one reader for every format
/// ([`ambid::io::time::read_time`], docs/data-files.md).
#[derive(Args, Clone, Debug, Default)]
pub struct DataFileArgs {
    /// Sample rate in Hz (when the file has no `t` column).
    #[arg(long)]
    pub fs: Option<f64>,
    #[command(flatten)]
    pub file: FileFormatArgs,
}

/// The format options of the data files (without the sample rate, for commands whose `--fs`
/// means more).
#[derive(Args, Clone, Debug, Default)]
pub struct FileFormatArgs {
    /// Format of the data files: csv (any delimited text), npy, npz, mat (v5 or v7.3), tdms
    /// or parquet (default: from the extension, else from the file's first bytes).
    #[arg(long, value_parser = parse_format)]
    pub format: Option<Format>,
    /// `.mat`/`.npz` data files: read only this variable (a 2-D variable `v` gives the columns
    /// `v1` … `vk`); `.tdms`: only this group.
    #[arg(long)]
    pub variable: Option<String>,
    /// Start of the part of the record to use: seconds after the first sample (`2.5`, `2.5s`)
    /// or a 0-based sample index (`#50000`). TDMS and MAT v7.3 files read only that part.
    #[arg(long, value_parser = parse_bound)]
    pub from: Option<Bound>,
    /// End (excluded) of the part of the record to use, as `--from`.
    #[arg(long, value_parser = parse_bound)]
    pub to: Option<Bound>,
    /// The time column of the data files, seconds: a name, or `#k` for the k-th column
    /// (default: the column `t` when there is one).
    #[arg(long)]
    pub time: Option<String>,
}

fn parse_format(s: &str) -> Result<Format, String> {
    s.parse()
}

fn parse_bound(s: &str) -> Result<Bound, String> {
    s.parse()
}

impl FileFormatArgs {
    /// The reader's options with sample rate `fs_hz`.
    pub fn options(&self, fs_hz: Option<f64>) -> TimeOptions {
        TimeOptions {
            fs_hz,
            time: self.time.as_deref().map(ColumnRef::parse),
            read: ReadOptions {
                format: self.format,
                variable: self.variable.clone(),
                ..ReadOptions::default()
            },
            window: (self.from.is_some() || self.to.is_some()).then_some(Window {
                from: self.from,
                to: self.to,
            }),
            columns: None,
        }
    }

    /// Reads only the columns `columns` (names or `#k`; those the file lacks are left out) of
    /// the record `path`, with sample rate `fs_hz`: TDMS and MAT v7.3 files read nothing else.
    pub fn read_columns(
        &self,
        path: &Path,
        fs_hz: Option<f64>,
        columns: &[&str],
    ) -> anyhow::Result<TimeData> {
        let mut o = self.options(fs_hz);
        o.columns = Some(columns.iter().map(|c| c.to_string()).collect());
        Ok(read_time(path, &o)?)
    }

    /// Reads the record `path` with sample rate `fs_hz` (for a file without a time column).
    pub fn read(&self, path: &Path, fs_hz: Option<f64>) -> anyhow::Result<TimeData> {
        Ok(read_time(path, &self.options(fs_hz))?)
    }
}

impl DataFileArgs {
    /// Reads the record `path` with `--fs`.
    pub fn read(&self, path: &Path) -> anyhow::Result<TimeData> {
        self.file.read(path, self.fs)
    }
}

/// The column of the excitation r.
#[derive(Args, Clone, Debug)]
pub struct ExcitationColumn {
    /// Column of the excitation r (a name, or `#k` for the k-th column of the file).
    #[arg(long, default_value = "r")]
    pub excitation: String,
}

/// The column of the plant input u (the controller output).
#[derive(Args, Clone, Debug)]
pub struct InputColumn {
    /// Column of the controller output u, the plant input (a name, or `#k`).
    #[arg(long, default_value = "u")]
    pub input: String,
}

/// The column of the measured output y.
#[derive(Args, Clone, Debug)]
pub struct OutputColumn {
    /// Column of the measured output y (a name, or `#k`).
    #[arg(long, default_value = "y")]
    pub output: String,
}

/// The coil-current column i.
#[derive(Args, Clone, Debug)]
pub struct CurrentColumn {
    /// Column of the coil current (saturation check); used when present.
    #[arg(long, default_value = "i")]
    pub current: String,
}

/// A frequency band `f_min:f_max` in Hz.
#[derive(Args, Clone, Debug)]
pub struct BandArg {
    /// Band, Hz, as `f_min:f_max`.
    #[arg(long, value_parser = parse_band)]
    pub band: Option<(f64, f64)>,
}

/// Replace outputs that exist.
#[derive(Args, Clone, Debug)]
pub struct Force {
    /// Replace the output file if it exists.
    #[arg(long)]
    pub force: bool,
}

/// Prints the one-line deprecation note of an old spelling on stderr.
pub(crate) fn deprecated(old: &str, new: &str) {
    // huge values print compactly, as in the error messages
    eprintln!(
        "{}",
        ambid::workflow::compact_numbers(&format!(
            "note: {old} is deprecated; write {new} (docs/conventions.md, \"Command line\")"
        ))
    );
}

fn number(s: &str, what: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number ({what})"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("`{s}` is not a finite number ({what})"))
    }
}

/// Parses a frequency band in Hz: `f_min:f_max` (e.g. `10:1000`); the older `f_min,f_max` is
/// accepted with a deprecation note on stderr. Needs $0 \le f_\mathrm{min} < f_\mathrm{max}$.
pub(crate) fn parse_band(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = match s.split_once(':') {
        Some(p) => p,
        None => {
            let p = s.split_once(',').ok_or_else(|| {
                format!("`{s}`: give a band as f_min:f_max in Hz, e.g. 10:1000 (the older f_min,f_max is accepted)")
            })?;
            deprecated(&format!("the band `{s}`"), &format!("`{}:{}`", p.0, p.1));
            p
        }
    };
    let lo = number(a, "band f_min, Hz")?;
    let hi = number(b, "band f_max, Hz")?;
    if !(lo >= 0.0 && hi > lo) {
        return Err(format!("`{s}`: need 0 ≤ f_min < f_max, e.g. 10:1000 (Hz)"));
    }
    Ok((lo, hi))
}

/// An excitation level as given on the command line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Level {
    /// Percent of $i_\mathrm{sat}$ (`12` or `12%`).
    Pct(f64),
    /// Amperes (`0.24A`), converted with the command's $i_\mathrm{sat}$.
    Amps(f64),
}

impl Level {
    /// The level in amperes for the saturation current `i_sat` (A).
    pub(crate) fn amps(self, i_sat: f64) -> f64 {
        match self {
            Level::Pct(p) => p / 100.0 * i_sat,
            Level::Amps(a) => a,
        }
    }
}

/// Parses a level: `12` or `12%` (percent of i_sat, in (0, 100]) or `0.24A` (amperes, > 0).
pub(crate) fn parse_level(s: &str) -> Result<Level, String> {
    let t = s.trim();
    if let Some(a) = t.strip_suffix(['A', 'a']) {
        let v = number(a, "level in A")?;
        if v <= 0.0 {
            return Err(format!("`{s}`: a level in A must be positive"));
        }
        return Ok(Level::Amps(v));
    }
    parse_pct(t).map(Level::Pct)
}

/// Parses a level in % of i_sat: `12` or `12%`, in (0, 100].
pub(crate) fn parse_pct(s: &str) -> Result<f64, String> {
    let t = s.trim();
    let v = number(
        t.strip_suffix('%').unwrap_or(t),
        "level in % of i_sat, e.g. 10 or 10%",
    )?;
    if !(v > 0.0 && v <= 100.0) {
        return Err(format!(
            "`{s}`: a level is a percentage of i_sat in (0, 100], e.g. 10 or 10%"
        ));
    }
    Ok(v)
}

/// `x` printed without binary noise: the shortest decimal that reads back to `x` rounded to
/// 12 significant digits (`100.0 * 0.14` prints `14`, not `14.000000000000002`).
pub(crate) fn clean(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let mag = 10f64.powi(11 - x.abs().log10().floor() as i32);
    (x * mag).round() / mag
}

/// The value parser of a model-structure option: one of `allowed` by its name
/// ([`ambid_core::lti::Structure`]'s `FromStr`), the names listed in `--help`.
pub(crate) fn structure_parser(
    allowed: &'static [ambid_core::lti::Structure],
) -> impl clap::builder::TypedValueParser<Value = ambid_core::lti::Structure> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(allowed.iter().map(|s| s.name()))
        .try_map(|s: String| s.parse::<ambid_core::lti::Structure>())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_forms() {
        assert_eq!(parse_band("10:1000"), Ok((10.0, 1000.0)));
        assert_eq!(parse_band("10,1000"), Ok((10.0, 1000.0)));
        assert!(parse_band("1000:10").is_err());
        assert!(parse_band("10-1000").is_err());
        assert!(parse_band("a:1000").is_err());
    }

    #[test]
    fn level_forms() {
        assert_eq!(parse_level("12"), Ok(Level::Pct(12.0)));
        assert_eq!(parse_level("12%"), Ok(Level::Pct(12.0)));
        assert_eq!(parse_level("0.24A"), Ok(Level::Amps(0.24)));
        assert!((Level::Pct(12.0).amps(2.0) - 0.24).abs() < 1e-15);
        assert!(parse_level("0").is_err());
        assert!(parse_level("150%").is_err());
        assert!(parse_level("x%").is_err());
    }

    #[test]
    fn clean_prints_without_binary_noise() {
        assert_eq!(format!("{}", clean(100.0 * 0.14)), "14");
        assert_eq!(format!("{}", clean(100.0 * 0.07)), "7");
        assert_eq!(format!("{}", clean(0.1 + 0.2)), "0.3");
        assert_eq!(format!("{}", clean(1.0 / 3.0)), "0.333333333333");
    }
}
