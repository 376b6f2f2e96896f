//! [`IoData`]: a record of named, equally long channels sampled every $T_s$ seconds.
//!
//! Sample $k$ of every channel is taken at $t_k = k T_s$ (`docs/conventions.md`). A record from a
//! periodic excitation also carries its period length $P$ in samples, so that whole periods can be
//! cut out and averaged ([`crate::data::segment_periods`]).
//!
//! Non-finite samples (NaN, $\pm\infty$) are *allowed* in an [`IoData`]: a record is loaded as it was
//! measured, screened and repaired ([`crate::data::repair_abnormal`]), and only then handed to an
//! estimator, which checks that its input is finite.
//!
//! # Example
//! ```
//! use ambid_core::data::IoData;
//! let data = IoData::new(
//!     vec![("r".into(), vec![1.0, -1.0, 1.0, -1.0]), ("y".into(), vec![0.0, 0.5, f64::NAN, 0.5])],
//!     1e-3,
//!     Some(2),
//! ).unwrap();
//! assert_eq!(data.names(), vec!["r", "y"]);
//! assert_eq!(data.len(), 4);
//! assert_eq!(data.fs(), 1000.0);
//! assert_eq!(data.channel("r").unwrap(), &[1.0, -1.0, 1.0, -1.0]);
//! let tail = data.slice(2, 4).unwrap();
//! assert_eq!(tail.channel("r").unwrap(), &[1.0, -1.0]);
//! ```

use crate::error::{Error, Result};
use crate::signal::check_ts;
use faer::Mat;
use std::collections::HashSet;

/// The axes of an AMB rotor, in their order: the two radial bearings A and B, each in $x$ and
/// $y$. A channel `y_xa` is the output of axis `xa`; a bare `y` is the single-axis case.
pub const AXES: [&str; 4] = ["xa", "xb", "ya", "yb"];

/// The role of a channel in the closed loop $u = -C y + r$ (`docs/conventions.md`).
///
/// Inferred from the name by the convention `<letter>` or `<letter>_<axis>` with the letters
/// `r`, `u`, `y`, `i`, `w` and the axes of [`AXES`] (`r_xa`, `y_yb`, …); any other name is
/// [`Role::Other`] unless a role is set with [`IoData::with_role`].
///
/// # Example
/// ```
/// use ambid_core::data::Role;
/// assert_eq!(Role::infer("y"), Role::Output);
/// assert_eq!(Role::infer("r_xb"), Role::Excitation);
/// assert_eq!(Role::infer("y_zz"), Role::Other); // not an axis
/// assert_eq!(Role::infer("gap"), Role::Other);
/// assert_eq!(Role::Input.letter(), "u");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// Excitation $r$, added to the controller output.
    Excitation,
    /// Plant input $u$ (the controller output including $r$).
    Input,
    /// Measured output $y$ (position).
    Output,
    /// Coil current $i$.
    Current,
    /// Reference $w$ (set point).
    Reference,
    /// Anything else (kept, not used by the estimators' front doors).
    Other,
}

impl Role {
    /// The letter of the naming convention: `r`, `u`, `y`, `i`, `w` (`other` for [`Role::Other`]).
    pub fn letter(self) -> &'static str {
        match self {
            Role::Excitation => "r",
            Role::Input => "u",
            Role::Output => "y",
            Role::Current => "i",
            Role::Reference => "w",
            Role::Other => "other",
        }
    }

    /// A readable name (`excitation`, `input`, …).
    pub fn describe(self) -> &'static str {
        match self {
            Role::Excitation => "excitation",
            Role::Input => "input",
            Role::Output => "output",
            Role::Current => "current",
            Role::Reference => "reference",
            Role::Other => "other",
        }
    }

    fn from_letter(l: &str) -> Option<Role> {
        Some(match l {
            "r" => Role::Excitation,
            "u" => Role::Input,
            "y" => Role::Output,
            "i" => Role::Current,
            "w" => Role::Reference,
            _ => return None,
        })
    }

    /// The role a channel name implies (see the type's docs).
    pub fn infer(name: &str) -> Role {
        match name.split_once('_') {
            None => Role::from_letter(name).unwrap_or(Role::Other),
            Some((l, axis)) if AXES.contains(&axis) => Role::from_letter(l).unwrap_or(Role::Other),
            Some(_) => Role::Other,
        }
    }
}

/// Sort key of a channel within its role: the bare name first, then the axes in [`AXES`] order,
/// then other names (with an explicit role) in their stored order.
fn axis_rank(name: &str) -> usize {
    match name.split_once('_') {
        None => 0,
        Some((_, axis)) => AXES
            .iter()
            .position(|a| *a == axis)
            .map_or(AXES.len() + 1, |p| p + 1),
    }
}

/// Measured input-output data: named channels of equal length, sample time, optional period.
///
/// Invariants (checked by every constructor and modifier): at least one channel, every channel has
/// the same number of samples and at least one, channel names are non-empty and unique, `ts` is
/// finite and $> 0$, and `period_samples`, when given, is $> 0$. Sample values may be non-finite.
///
/// Serialised as `{"channels": [["y", [..]], ..], "ts": .., "period_samples": ..}`; deserialising
/// checks the same invariants as [`IoData::new`].
///
/// # Roles and experiments
/// Every channel has a [`Role`], inferred from its name (`r`, `u`, `y`, `i`, `w`, or
/// `<letter>_<axis>` for the axes of [`AXES`]) unless set with [`IoData::with_role`];
/// [`IoData::role_names`] lists a role's channels in axis order and [`IoData::signals`] /
/// [`IoData::role_matrix`] give their samples, so an estimator's front door selects $u$, $y$ and
/// $r$ by role and a SISO record is the $1 \times 1$ case of a MIMO one.
///
/// A record may hold several **experiments** of one system: the same channels (names and roles)
/// and sample time, each of its own length ([`IoData::from_experiments`],
/// [`IoData::with_experiment`]). The single-record accessors ([`IoData::channel`],
/// [`IoData::len`], [`IoData::channels`], …) read the first experiment; [`IoData::slice`] and
/// [`IoData::with_channel`] refuse a record of several experiments (cut or extend one
/// [`IoData::experiment`] instead), and so does every estimator that cannot join experiments
/// (never concatenating across a boundary silently).
///
/// The extra experiments and explicit roles are serialised as `"experiments"` and `"roles"`,
/// and only when present.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "IoDataParts")]
pub struct IoData {
    channels: Vec<(String, Vec<f64>)>,
    ts: f64,
    period_samples: Option<usize>,
    /// Experiments after the first: samples in the order of `channels`.
    #[serde(default, skip_serializing_if = "Vec::is_empty", rename = "experiments")]
    more: Vec<Vec<Vec<f64>>>,
    /// Roles set explicitly (by channel name).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    roles: Vec<(String, Role)>,
}

/// The unchecked serde form of [`IoData`].
#[derive(serde::Deserialize)]
struct IoDataParts {
    channels: Vec<(String, Vec<f64>)>,
    ts: f64,
    period_samples: Option<usize>,
    #[serde(default)]
    experiments: Vec<Vec<Vec<f64>>>,
    #[serde(default)]
    roles: Vec<(String, Role)>,
}

impl TryFrom<IoDataParts> for IoData {
    type Error = Error;
    fn try_from(p: IoDataParts) -> Result<Self> {
        let names: Vec<String> = p.channels.iter().map(|(n, _)| n.clone()).collect();
        let mut d = IoData::new(p.channels, p.ts, p.period_samples)?;
        for e in p.experiments {
            if e.len() != names.len() {
                return Err(Error::DimensionMismatch {
                    context: "IoData experiments (one sample vector per channel)",
                    expected: names.len().to_string(),
                    got: e.len().to_string(),
                });
            }
            d = d.with_experiment(names.iter().cloned().zip(e).collect())?;
        }
        for (name, role) in p.roles {
            d = d.with_role(&name, role)?;
        }
        Ok(d)
    }
}

fn check_period(period_samples: Option<usize>) -> Result<()> {
    if period_samples == Some(0) {
        return Err(Error::invalid(
            "period_samples",
            "a period of 0 samples is meaningless; pass the excitation's period length in \
             samples (`--period-samples`, `[data] period_samples`), or leave it unset for non-periodic data",
        ));
    }
    Ok(())
}

fn check_name(name: &str) -> Result<()> {
    if name.trim().is_empty() {
        return Err(Error::invalid(
            "channels",
            "a channel name is empty; give every channel a name such as \"u\" or \"y\"",
        ));
    }
    Ok(())
}

impl IoData {
    /// Builds a record from `(name, samples)` pairs, the sample time `ts` in seconds and the period
    /// length in samples (`None` for non-periodic data).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when there are no channels, a channel is empty, a name is empty or
    /// repeated, `ts` is not finite and $> 0$, or `period_samples == Some(0)`;
    /// [`Error::DimensionMismatch`] when the channels differ in length.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// let ok = IoData::new(vec![("u".into(), vec![1.0, 2.0]), ("y".into(), vec![3.0, 4.0])], 0.1, None);
    /// assert!(ok.is_ok());
    /// let bad = IoData::new(vec![("u".into(), vec![1.0, 2.0]), ("y".into(), vec![3.0])], 0.1, None);
    /// assert!(bad.is_err());
    /// ```
    pub fn new(
        channels: Vec<(String, Vec<f64>)>,
        ts: f64,
        period_samples: Option<usize>,
    ) -> Result<Self> {
        check_ts(ts)?;
        check_period(period_samples)?;
        let Some((first_name, first)) = channels.first() else {
            return Err(Error::invalid(
                "channels",
                "no channels were given; pass at least one (name, samples) pair",
            ));
        };
        let n = first.len();
        if n == 0 {
            return Err(Error::invalid(
                "channels",
                format!("channel `{first_name}` is empty; a record needs at least one sample"),
            ));
        }
        let mut seen = HashSet::new();
        for (name, values) in &channels {
            check_name(name)?;
            if !seen.insert(name.as_str()) {
                return Err(Error::invalid(
                    "channels",
                    format!("the channel name `{name}` appears twice; names must be unique"),
                ));
            }
            if values.len() != n {
                return Err(Error::DimensionMismatch {
                    context: "IoData channels (all must have the same number of samples)",
                    expected: format!("{n} samples (as channel `{first_name}`)"),
                    got: format!("{} samples in channel `{name}`", values.len()),
                });
            }
        }
        Ok(IoData {
            channels,
            ts,
            period_samples,
            more: Vec::new(),
            roles: Vec::new(),
        })
    }

    /// The samples of the channel called `name`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when there is no such channel; the message lists the names there
    /// are.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// let data = IoData::new(vec![("y".into(), vec![1.0, 2.0])], 1.0, None).unwrap();
    /// assert_eq!(data.channel("y").unwrap(), &[1.0, 2.0]);
    /// let err = data.channel("u").unwrap_err().to_string();
    /// assert!(err.contains("`y`"));
    /// ```
    pub fn channel(&self, name: &str) -> Result<&[f64]> {
        self.channels
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
            .ok_or_else(|| {
                let list: Vec<String> = self
                    .channels
                    .iter()
                    .map(|(n, _)| format!("`{n}`"))
                    .collect();
                Error::invalid(
                    "name",
                    format!(
                        "there is no channel `{name}`; the record has {}",
                        list.join(", ")
                    ),
                )
            })
    }

    /// Channel names in their stored order.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// let data = IoData::new(vec![("r".into(), vec![0.0]), ("y".into(), vec![0.0])], 1.0, None).unwrap();
    /// assert_eq!(data.names(), vec!["r", "y"]);
    /// ```
    pub fn names(&self) -> Vec<&str> {
        self.channels.iter().map(|(n, _)| n.as_str()).collect()
    }

    /// All `(name, samples)` pairs in their stored order.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// let data = IoData::new(vec![("y".into(), vec![1.0])], 1.0, None).unwrap();
    /// assert_eq!(data.channels()[0].0, "y");
    /// ```
    pub fn channels(&self) -> &[(String, Vec<f64>)] {
        &self.channels
    }

    /// Gives the `(name, samples)` pairs back.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// let data = IoData::new(vec![("y".into(), vec![1.0])], 1.0, None).unwrap();
    /// assert_eq!(data.into_channels(), vec![("y".to_string(), vec![1.0])]);
    /// ```
    pub fn into_channels(self) -> Vec<(String, Vec<f64>)> {
        self.channels
    }

    /// Number of samples per channel (at least 1).
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// assert_eq!(IoData::new(vec![("y".into(), vec![1.0, 2.0, 3.0])], 1.0, None).unwrap().len(), 3);
    /// ```
    pub fn len(&self) -> usize {
        self.channels.first().map_or(0, |(_, v)| v.len())
    }

    /// Always `false`: an [`IoData`] holds at least one sample (present for API symmetry with
    /// [`IoData::len`]).
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// assert!(!IoData::new(vec![("y".into(), vec![1.0])], 1.0, None).unwrap().is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Sample time $T_s$ in seconds.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// assert_eq!(IoData::new(vec![("y".into(), vec![1.0])], 5e-5, None).unwrap().ts(), 5e-5);
    /// ```
    pub fn ts(&self) -> f64 {
        self.ts
    }

    /// Sample rate $f_s = 1/T_s$ in Hz.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// assert_eq!(IoData::new(vec![("y".into(), vec![1.0])], 0.5, None).unwrap().fs(), 2.0);
    /// ```
    pub fn fs(&self) -> f64 {
        1.0 / self.ts
    }

    /// Duration $N T_s$ in seconds.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// assert_eq!(IoData::new(vec![("y".into(), vec![1.0; 4])], 0.5, None).unwrap().duration_s(), 2.0);
    /// ```
    pub fn duration_s(&self) -> f64 {
        self.len() as f64 * self.ts
    }

    /// Sample instants $k T_s$, $k = 0, \dots, N-1$, in seconds.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// let data = IoData::new(vec![("y".into(), vec![0.0; 3])], 0.5, None).unwrap();
    /// assert_eq!(data.times(), vec![0.0, 0.5, 1.0]);
    /// ```
    pub fn times(&self) -> Vec<f64> {
        (0..self.len()).map(|k| k as f64 * self.ts).collect()
    }

    /// Period length in samples, `None` for non-periodic data.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// assert_eq!(IoData::new(vec![("y".into(), vec![0.0; 4])], 1.0, Some(2)).unwrap().period_samples(), Some(2));
    /// ```
    pub fn period_samples(&self) -> Option<usize> {
        self.period_samples
    }

    /// The same record with another period length (`None`: non-periodic).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for `Some(0)`.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// let data = IoData::new(vec![("y".into(), vec![0.0; 6])], 1.0, None).unwrap();
    /// assert_eq!(data.with_period_samples(Some(3)).unwrap().period_samples(), Some(3));
    /// ```
    pub fn with_period_samples(mut self, period_samples: Option<usize>) -> Result<Self> {
        check_period(period_samples)?;
        self.period_samples = period_samples;
        Ok(self)
    }

    /// The record with channel `name` set to `values`: replaced in place when the name exists,
    /// appended otherwise. Use it to put a preprocessed channel back.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an empty name; [`Error::DimensionMismatch`] when `values` does
    /// not have [`IoData::len`] samples.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// let data = IoData::new(vec![("y".into(), vec![1.0, 2.0])], 1.0, None).unwrap();
    /// let data = data.with_channel("y", vec![0.0, 0.0]).unwrap().with_channel("u", vec![5.0, 6.0]).unwrap();
    /// assert_eq!(data.names(), vec!["y", "u"]);
    /// assert_eq!(data.channel("y").unwrap(), &[0.0, 0.0]);
    /// ```
    pub fn with_channel(mut self, name: impl Into<String>, values: Vec<f64>) -> Result<Self> {
        let name = name.into();
        self.require_single_experiment("IoData::with_channel")?;
        check_name(&name)?;
        if values.len() != self.len() {
            return Err(Error::DimensionMismatch {
                context: "IoData::with_channel (the new channel must be as long as the record)",
                expected: format!("{} samples", self.len()),
                got: format!("{} samples in channel `{name}`", values.len()),
            });
        }
        match self.channels.iter_mut().find(|(n, _)| *n == name) {
            Some((_, v)) => *v = values,
            None => self.channels.push((name, values)),
        }
        Ok(self)
    }

    /// Samples `start..end` of every channel (sample `start` becomes sample 0; `ts` and the period
    /// length are kept).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] unless `start < end <= len()`.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// let data = IoData::new(vec![("y".into(), vec![0.0, 1.0, 2.0, 3.0])], 1.0, None).unwrap();
    /// assert_eq!(data.slice(1, 3).unwrap().channel("y").unwrap(), &[1.0, 2.0]);
    /// assert!(data.slice(3, 3).is_err());
    /// ```
    pub fn slice(&self, start: usize, end: usize) -> Result<IoData> {
        self.require_single_experiment("IoData::slice")?;
        let n = self.len();
        if start >= end || end > n {
            return Err(Error::invalid(
                "start..end",
                format!(
                    "the range {start}..{end} is not a non-empty part of a record of {n} samples; \
                     pass start < end <= {n}"
                ),
            ));
        }
        Ok(IoData {
            channels: self
                .channels
                .iter()
                .map(|(name, v)| (name.clone(), v[start..end].to_vec()))
                .collect(),
            ts: self.ts,
            period_samples: self.period_samples,
            more: Vec::new(),
            roles: self.roles.clone(),
        })
    }
}

impl IoData {
    /// The role of channel `name`: set by [`IoData::with_role`], else [`Role::infer`].
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when there is no such channel.
    pub fn role(&self, name: &str) -> Result<Role> {
        self.channel(name)?;
        Ok(self.role_unchecked(name))
    }

    fn role_unchecked(&self, name: &str) -> Role {
        self.roles
            .iter()
            .find(|(n, _)| n == name)
            .map_or_else(|| Role::infer(name), |(_, r)| *r)
    }

    /// Sets the role of channel `name` (e.g. a channel `gap_a` as [`Role::Output`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when there is no such channel.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{IoData, Role};
    /// let d = IoData::new(vec![("exc".into(), vec![1.0]), ("pos".into(), vec![2.0])], 1.0, None)
    ///     .unwrap()
    ///     .with_role("exc", Role::Excitation).unwrap()
    ///     .with_role("pos", Role::Output).unwrap();
    /// assert_eq!(d.role_names(Role::Output), vec!["pos"]);
    /// assert!(d.with_role("nope", Role::Input).is_err());
    /// ```
    pub fn with_role(mut self, name: &str, role: Role) -> Result<Self> {
        self.channel(name)?;
        self.roles.retain(|(n, _)| n != name);
        self.roles.push((name.to_string(), role));
        Ok(self)
    }

    /// The names of the channels of `role`, in axis order (the bare name, then `xa`, `xb`, `ya`,
    /// `yb`, then other names in their stored order).
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{IoData, Role};
    /// let ch = |n: &str| (n.to_string(), vec![0.0; 3]);
    /// let d = IoData::new(vec![ch("y_xb"), ch("u_xa"), ch("y_xa"), ch("u_xb"), ch("r_xa")], 1e-4, None).unwrap();
    /// assert_eq!(d.role_names(Role::Output), vec!["y_xa", "y_xb"]);
    /// assert_eq!(d.role_names(Role::Input), vec!["u_xa", "u_xb"]);
    /// assert_eq!(d.role_count(Role::Excitation), 1);
    /// assert!(d.role_names(Role::Current).is_empty());
    /// ```
    pub fn role_names(&self, role: Role) -> Vec<&str> {
        let mut v: Vec<&str> = self
            .channels
            .iter()
            .map(|(n, _)| n.as_str())
            .filter(|n| self.role_unchecked(n) == role)
            .collect();
        v.sort_by_key(|n| axis_rank(n));
        v
    }

    /// Number of channels of `role`.
    pub fn role_count(&self, role: Role) -> usize {
        self.role_names(role).len()
    }

    /// Number of experiments (at least 1).
    pub fn n_experiments(&self) -> usize {
        1 + self.more.len()
    }

    /// Samples per channel in experiment `e` (`None` if there is no such experiment).
    pub fn experiment_len(&self, e: usize) -> Option<usize> {
        match e {
            0 => Some(self.len()),
            _ => self.more.get(e - 1).map(|x| x[0].len()),
        }
    }

    fn check_experiment(&self, e: usize) -> Result<()> {
        if e >= self.n_experiments() {
            return Err(Error::invalid(
                "experiment",
                format!(
                    "there is no experiment {e}; the record holds {} (0..{})",
                    self.n_experiments(),
                    self.n_experiments()
                ),
            ));
        }
        Ok(())
    }

    fn samples(&self, e: usize, idx: usize) -> &[f64] {
        if e == 0 {
            &self.channels[idx].1
        } else {
            &self.more[e - 1][idx]
        }
    }

    /// The samples of the channels of `role` in experiment `e`, in [`IoData::role_names`] order.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the record has no channel of that role (the message says
    /// how to name one) or no experiment `e`.
    pub fn signals(&self, role: Role, e: usize) -> Result<Vec<&[f64]>> {
        self.check_experiment(e)?;
        let names = self.role_names(role);
        if names.is_empty() {
            return Err(self.missing_role(role));
        }
        Ok(names
            .iter()
            .map(|n| {
                let idx = self.channels.iter().position(|(m, _)| m == n).unwrap_or(0);
                self.samples(e, idx)
            })
            .collect())
    }

    /// The typed error for a record without a channel of `role`.
    pub fn missing_role(&self, role: Role) -> Error {
        let l = role.letter();
        Error::invalid(
            "channels",
            format!(
                "the record has no {} channel ({l}); name one `{l}` (or `{l}_xa`, `{l}_xb`, … per axis) or set a channel's role; the record has {}",
                role.describe(),
                self.channels
                    .iter()
                    .map(|(n, _)| format!("`{n}` ({})", self.role_unchecked(n).describe()))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )
    }

    /// The channels of `role` in experiment `e` as an $N \times n$ matrix (one row per sample,
    /// one column per channel in axis order), e.g. the `u` and `y` matrices of a subspace fit.
    ///
    /// # Errors
    /// As [`IoData::signals`].
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{IoData, Role};
    /// let d = IoData::new(vec![("y_xb".into(), vec![1.0, 2.0]), ("y_xa".into(), vec![3.0, 4.0])], 1.0, None).unwrap();
    /// let y = d.role_matrix(Role::Output, 0).unwrap();
    /// assert_eq!((y.nrows(), y.ncols()), (2, 2));
    /// assert_eq!((y[(0, 0)], y[(1, 1)]), (3.0, 2.0)); // xa first
    /// assert!(d.role_matrix(Role::Input, 0).unwrap_err().to_string().contains("no input channel (u)"));
    /// ```
    pub fn role_matrix(&self, role: Role, e: usize) -> Result<Mat<f64>> {
        let s = self.signals(role, e)?;
        Ok(Mat::from_fn(s[0].len(), s.len(), |k, j| s[j][k]))
    }

    /// The output matrix $Y$ of experiment `e` ([`IoData::role_matrix`] of [`Role::Output`]).
    pub fn y_matrix(&self, e: usize) -> Result<Mat<f64>> {
        self.role_matrix(Role::Output, e)
    }

    /// The input matrix $U$ of experiment `e` ([`IoData::role_matrix`] of [`Role::Input`]).
    pub fn u_matrix(&self, e: usize) -> Result<Mat<f64>> {
        self.role_matrix(Role::Input, e)
    }

    /// Experiment `e` as a record of its own (same channels, roles, sample time and period).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when there is no experiment `e`.
    pub fn experiment(&self, e: usize) -> Result<IoData> {
        self.check_experiment(e)?;
        Ok(IoData {
            channels: self
                .channels
                .iter()
                .enumerate()
                .map(|(idx, (n, _))| (n.clone(), self.samples(e, idx).to_vec()))
                .collect(),
            ts: self.ts,
            period_samples: self.period_samples,
            more: Vec::new(),
            roles: self.roles.clone(),
        })
    }

    /// Adds an experiment: the same channel names (in any order), every channel of one length
    /// (which may differ from the other experiments').
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a missing, extra or repeated channel name or an empty
    /// experiment; [`Error::DimensionMismatch`] for channels of different lengths.
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::IoData;
    /// let a = IoData::new(vec![("u".into(), vec![1.0, 2.0, 3.0]), ("y".into(), vec![0.0; 3])], 0.1, None).unwrap();
    /// let ab = a.with_experiment(vec![("y".into(), vec![5.0; 2]), ("u".into(), vec![4.0, 5.0])]).unwrap();
    /// assert_eq!(ab.n_experiments(), 2);
    /// assert_eq!(ab.experiment_len(1), Some(2));
    /// assert_eq!(ab.experiment(1).unwrap().channel("u").unwrap(), &[4.0, 5.0]);
    /// assert!(ab.slice(0, 1).is_err()); // cut one experiment instead
    /// ```
    pub fn with_experiment(mut self, channels: Vec<(String, Vec<f64>)>) -> Result<Self> {
        let names = self.names().join(", ");
        let mismatch = |what: String| {
            Error::invalid(
                "experiments",
                format!("{what}; every experiment of a record has the channels {names}"),
            )
        };
        if channels.len() != self.channels.len() {
            return Err(mismatch(format!(
                "experiment {} has {} channels, not {}",
                self.n_experiments(),
                channels.len(),
                self.channels.len()
            )));
        }
        let n = channels[0].1.len();
        if n == 0 {
            return Err(mismatch(format!(
                "experiment {} is empty",
                self.n_experiments()
            )));
        }
        let mut slots: Vec<Option<Vec<f64>>> = vec![None; self.channels.len()];
        for (name, values) in channels {
            let Some(idx) = self.channels.iter().position(|(m, _)| *m == name) else {
                return Err(mismatch(format!(
                    "experiment {} has a channel `{name}` the first has not",
                    self.n_experiments()
                )));
            };
            if slots[idx].is_some() {
                return Err(mismatch(format!("the channel `{name}` appears twice")));
            }
            if values.len() != n {
                return Err(Error::DimensionMismatch {
                    context:
                        "IoData experiment (all channels of one experiment have the same length)",
                    expected: format!("{n} samples"),
                    got: format!("{} samples in channel `{name}`", values.len()),
                });
            }
            slots[idx] = Some(values);
        }
        self.more.push(slots.into_iter().flatten().collect());
        Ok(self)
    }

    /// One record from several experiments of one system: the same channel names and roles and
    /// the same sample time (to 1e-12 relative) and period; lengths may differ.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for no experiment, or experiments that differ in channels,
    /// roles, sample time or period (the message names the first difference).
    pub fn from_experiments(experiments: Vec<IoData>) -> Result<Self> {
        let mut it = experiments.into_iter();
        let Some(first) = it.next() else {
            return Err(Error::invalid(
                "experiments",
                "no experiment was given; pass at least one record",
            ));
        };
        let mut acc = first;
        for (k, e) in it.enumerate() {
            let k = k + 1;
            if ((e.ts - acc.ts) / acc.ts).abs() > 1e-12 {
                return Err(Error::invalid(
                    "experiments",
                    format!(
                        "experiment {k} is sampled every {} s, the first every {} s; resample to one rate first",
                        e.ts, acc.ts
                    ),
                ));
            }
            if e.period_samples != acc.period_samples {
                return Err(Error::invalid(
                    "experiments",
                    format!(
                        "experiment {k} has the period {:?} samples, the first {:?}",
                        e.period_samples, acc.period_samples
                    ),
                ));
            }
            for (n, _) in &e.channels {
                if acc.channel(n).is_ok() && acc.role_unchecked(n) != e.role_unchecked(n) {
                    return Err(Error::invalid(
                        "experiments",
                        format!(
                            "channel `{n}` is the {} in experiment {k} but the {} in the first",
                            e.role_unchecked(n).describe(),
                            acc.role_unchecked(n).describe()
                        ),
                    ));
                }
            }
            for x in 0..e.n_experiments() {
                acc = acc.with_experiment(e.experiment(x)?.channels)?;
            }
        }
        Ok(acc)
    }

    /// A typed error unless the record holds a single experiment; `what` names the caller.
    pub fn require_single_experiment(&self, what: &str) -> Result<()> {
        if self.n_experiments() > 1 {
            return Err(Error::invalid(
                "experiments",
                format!(
                    "{what} takes one experiment, and this record holds {}; pass one (IoData::experiment) — experiments are never joined across their boundary",
                    self.n_experiments()
                ),
            ));
        }
        Ok(())
    }

    /// A typed error unless every sample of the channels of `roles`, in every experiment, is
    /// finite (NaN and $\pm\infty$ are kept in a record until repaired; estimators need finite
    /// data).
    ///
    /// # Example
    /// ```
    /// use ambid_core::data::{IoData, Role};
    /// let d = IoData::new(vec![("u".into(), vec![1.0, 2.0]), ("y".into(), vec![0.0, f64::NAN])], 1.0, None).unwrap();
    /// assert!(d.require_finite(&[Role::Input]).is_ok());
    /// let e = d.require_finite(&[Role::Output]).unwrap_err().to_string();
    /// assert!(e.contains("`y`") && e.contains("sample 2"), "{e}");
    /// ```
    pub fn require_finite(&self, roles: &[Role]) -> Result<()> {
        for e in 0..self.n_experiments() {
            for (idx, (name, _)) in self.channels.iter().enumerate() {
                if !roles.contains(&self.role_unchecked(name)) {
                    continue;
                }
                if let Some(k) = self.samples(e, idx).iter().position(|x| !x.is_finite()) {
                    return Err(Error::invalid(
                        "data",
                        format!(
                            "channel `{name}` of experiment {e} has a non-finite sample (NaN or ±inf) at sample {} (1-based); repair it (data::repair_abnormal) or cut the record there",
                            k + 1
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// The single output and input of a single-experiment SISO record, for the SISO-only
/// estimators' front doors; `what` names the estimator in the errors.
pub(crate) fn siso_pair<'a>(data: &'a IoData, what: &str) -> Result<(&'a [f64], &'a [f64])> {
    data.require_single_experiment(what)?;
    let (ny, nu) = (data.role_count(Role::Output), data.role_count(Role::Input));
    if ny > 1 || nu > 1 {
        return Err(Error::invalid(
            "channels",
            format!(
                "{what} is SISO-only, and the record has {ny} output and {nu} input channels ({}); select one output and one input",
                data.role_names(Role::Output)
                    .into_iter()
                    .chain(data.role_names(Role::Input))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    }
    data.require_finite(&[Role::Output, Role::Input])?;
    Ok((
        data.signals(Role::Output, 0)?[0],
        data.signals(Role::Input, 0)?[0],
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two() -> IoData {
        IoData::new(
            vec![
                ("u".into(), vec![1.0, 2.0, 3.0, 4.0]),
                ("y".into(), vec![f64::NAN, 0.0, f64::INFINITY, 1.0]),
            ],
            0.25,
            Some(2),
        )
        .unwrap()
    }

    #[test]
    fn accessors() {
        let d = two();
        assert_eq!(d.len(), 4);
        assert!(!d.is_empty());
        assert_eq!(d.ts(), 0.25);
        assert_eq!(d.fs(), 4.0);
        assert_eq!(d.duration_s(), 1.0);
        assert_eq!(d.times(), vec![0.0, 0.25, 0.5, 0.75]);
        assert_eq!(d.period_samples(), Some(2));
        assert_eq!(d.names(), vec!["u", "y"]);
        assert!(
            d.channel("y").unwrap()[0].is_nan(),
            "non-finite samples are kept"
        );
    }

    #[test]
    fn constructor_errors() {
        let e = IoData::new(vec![], 1.0, None).unwrap_err();
        assert!(e.to_string().contains("no channels"));
        let e = IoData::new(vec![("y".into(), vec![])], 1.0, None).unwrap_err();
        assert!(e.to_string().contains("empty"));
        let e = IoData::new(
            vec![("y".into(), vec![1.0]), ("y".into(), vec![2.0])],
            1.0,
            None,
        )
        .unwrap_err();
        assert!(e.to_string().contains("twice"));
        let e = IoData::new(vec![(" ".into(), vec![1.0])], 1.0, None).unwrap_err();
        assert!(e.to_string().contains("name is empty"));
        let e = IoData::new(
            vec![("u".into(), vec![1.0, 2.0]), ("y".into(), vec![2.0])],
            1.0,
            None,
        )
        .unwrap_err();
        assert!(matches!(e, Error::DimensionMismatch { .. }));
        assert!(e.to_string().contains("`y`"));
        for ts in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(IoData::new(vec![("y".into(), vec![1.0])], ts, None).is_err());
        }
        let e = IoData::new(vec![("y".into(), vec![1.0])], 1.0, Some(0)).unwrap_err();
        assert!(e.to_string().contains("period"));
    }

    #[test]
    fn channel_error_lists_names() {
        let e = two().channel("x").unwrap_err().to_string();
        assert!(
            e.contains("`x`") && e.contains("`u`") && e.contains("`y`"),
            "{e}"
        );
    }

    #[test]
    fn with_channel_replaces_or_appends() {
        let d = two().with_channel("u", vec![0.0; 4]).unwrap();
        assert_eq!(d.names(), vec!["u", "y"]);
        assert_eq!(d.channel("u").unwrap(), &[0.0; 4]);
        let d = d.with_channel("w", vec![9.0; 4]).unwrap();
        assert_eq!(d.names(), vec!["u", "y", "w"]);
        assert!(matches!(
            d.clone().with_channel("w", vec![1.0]).unwrap_err(),
            Error::DimensionMismatch { .. }
        ));
        assert!(d.with_channel("", vec![1.0; 4]).is_err());
    }

    #[test]
    fn slice_and_period() {
        let d = two();
        let s = d.slice(1, 3).unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(s.channel("u").unwrap(), &[2.0, 3.0]);
        assert_eq!(s.period_samples(), Some(2));
        assert!(d.slice(2, 1).is_err());
        assert!(d.slice(0, 5).is_err());
        assert!(d.slice(4, 4).is_err());
        assert!(d.clone().with_period_samples(Some(0)).is_err());
        assert_eq!(d.with_period_samples(None).unwrap().period_samples(), None);
    }

    #[test]
    fn serde_round_trip_checks_invariants() {
        let d = IoData::new(vec![("y".into(), vec![1.0, 2.0])], 0.5, Some(1)).unwrap();
        let json = serde_json::to_string(&d).unwrap();
        let back: IoData = serde_json::from_str(&json).unwrap();
        assert_eq!(back, d);
        let bad = r#"{"channels":[["y",[1.0]],["u",[1.0,2.0]]],"ts":0.5,"period_samples":null}"#;
        assert!(serde_json::from_str::<IoData>(bad).is_err());
        let bad = r#"{"channels":[["y",[1.0]]],"ts":-1.0,"period_samples":null}"#;
        assert!(serde_json::from_str::<IoData>(bad).is_err());
    }
}
