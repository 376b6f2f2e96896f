//! Measured input-output data and its preprocessing.
//!
//! A measurement arrives as an [`IoData`]: named channels of equal length (in closed loop typically
//! `r`, `u`, `y`), the sample time $T_s$ and, for a periodic excitation, the period length $P$ in
//! samples. Each channel has a [`Role`] (excitation, input, output, current, reference, other;
//! from its name, `y` or `y_xa`, or set explicitly), a role may have a channel per axis of
//! [`AXES`], and a record may hold several experiments of one system; the estimators' front doors
//! (`*_iodata`) select their signals by role. Before a nonparametric FRF is estimated, the record is screened and prepared; every step
//! returns the new data together with a report of what it changed and where, so that nothing happens
//! silently:
//!
//! | step | function | report |
//! |---|---|---|
//! | non-finite samples, spikes (moving median/MAD rule), stuck sensor | [`find_abnormal`], [`repair_abnormal`], [`repair_data`] ([`hampel`], [`global_outliers`], [`stuck_runs`]) | [`AbnormalReport`] |
//! | saturation and clipping, at a given limit or as detected flat tops | [`check_saturation`] | [`SaturationReport`] |
//! | transient: skip the first $K$ periods, cut whole periods | [`segment_periods`], [`segment_data`] | [`Segmentation`] |
//! | transient of non-periodic data: drop the first samples | [`drop_transient`] | [`TransientCut`] |
//! | offset or linear drift | [`detrend()`] | [`DetrendReport`] |
//!
//! A sensible order is: screen and repair ([`repair_data`]), check saturation (a saturated record
//! is not repaired but reported: the linear FRF of a saturating loop is biased), cut the transient
//! and whole periods, then detrend each channel. Non-finite samples may live in an [`IoData`]; the
//! preprocessing steps that need finite samples ([`detrend()`], [`check_saturation`]) say so with
//! [`crate::Error::NonFinite`], as every estimator does.
//!
//! # Example
//! ```
//! use ambid_core::data::{
//!     check_saturation, detrend, repair_data, segment_data, AbnormalOptions, Detrend, IoData,
//!     SaturationOptions, SegmentOptions,
//! };
//! let p = 50;
//! let r: Vec<f64> = (0..10 * p).map(|k| if (k / 5) % 3 == 0 { 1.0 } else { -1.0 }).collect();
//! let mut y: Vec<f64> = (0..10 * p).map(|k| 0.2 + (k as f64 * 0.1).sin()).collect();
//! y[123] = f64::NAN;
//! let data = IoData::new(vec![("r".into(), r), ("y".into(), y)], 1e-3, Some(p)).unwrap();
//!
//! let (data, reports) = repair_data(&data, &["y"], &AbnormalOptions::default()).unwrap();
//! assert_eq!(reports[0].1.repaired, 1);
//! let sat = check_saturation(data.channel("r").unwrap(), Some(1.0), &SaturationOptions::default()).unwrap();
//! assert_eq!(sat.fraction, 1.0); // a binary excitation sits at its level by design
//! let (data, seg) = segment_data(&data, 2, &SegmentOptions::default()).unwrap();
//! assert_eq!((seg.periods, data.len()), (8, 8 * p));
//! let (y, trend) = detrend(data.channel("y").unwrap(), Detrend::Mean).unwrap();
//! let data = data.with_channel("y", y).unwrap();
//! println!("{}\n{}\n{}", reports[0].1, seg, trend);
//! # let _ = data;
//! ```

pub mod detrend;
pub mod iodata;
pub mod outliers;
pub mod saturation;
pub mod segment;

pub use detrend::{detrend, Detrend, DetrendReport};
pub use iodata::{IoData, Role, AXES};
pub use outliers::{
    find_abnormal, global_outliers, hampel, repair_abnormal, repair_data, stuck_runs,
    AbnormalOptions, AbnormalReport, HampelOptions, Repair, MAD_TO_SIGMA,
};
pub use saturation::{check_saturation, LimitSource, SaturationOptions, SaturationReport};
pub use segment::{
    drop_transient, segment_data, segment_periods, SegmentOptions, Segmentation, TransientCut,
};
