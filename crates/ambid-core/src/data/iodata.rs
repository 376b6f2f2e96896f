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
use std::collections::HashSet;

/// Measured input-output data: named channels of equal length, sample time, optional period.
///
/// Invariants (checked by every constructor and modifier): at least one channel, every channel has
/// the same number of samples and at least one, channel names are non-empty and unique, `ts` is
/// finite and $> 0$, and `period_samples`, when given, is $> 0$. Sample values may be non-finite.
///
/// Serialised as `{"channels": [["y", [..]], ..], "ts": .., "period_samples": ..}`; deserialising
/// checks the same invariants as [`IoData::new`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "IoDataParts")]
pub struct IoData {
    channels: Vec<(String, Vec<f64>)>,
    ts: f64,
    period_samples: Option<usize>,
}

/// The unchecked serde form of [`IoData`].
#[derive(serde::Deserialize)]
struct IoDataParts {
    channels: Vec<(String, Vec<f64>)>,
    ts: f64,
    period_samples: Option<usize>,
}

impl TryFrom<IoDataParts> for IoData {
    type Error = Error;
    fn try_from(p: IoDataParts) -> Result<Self> {
        IoData::new(p.channels, p.ts, p.period_samples)
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
        })
    }
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
