//! ISO 14839-3 stability-margin zone from the peak of the sensitivity function.
//!
//! ISO 14839-3 judges an AMB control loop by the peak of its sensitivity function
//! $S = 1/(1 + PC)$ (measured with an excitation injected into the loop) and assigns a zone:
//! **A** (newly commissioned, good) for $\max|S| < 3$ (9.5 dB), **B** (unrestricted long-term
//! operation) below 4 (12 dB), **C** (limited operation) below 5 (14 dB), **D** (damage may occur)
//! above. The limits are [`IsoZones`], with the standard's values as the default and
//! configurable.
//!
//! From a measured $S$ with variances the peak line's magnitude gets a 95 % interval
//! $|\hat S| \pm 1.96\,\sigma/\sqrt2$ ($\sigma^2 = E|\hat S - S|^2$ is the variance of the complex
//! estimate; half of it lies along the radial direction), and the zones of its two ends are
//! reported: when they differ the verdict is uncertain. The largest of many noisy lines is
//! biased upwards by a fraction of $\sigma$; on a model's $S$ (no variance) the interval is empty.
//! The peak is taken over the given lines: give a grid fine enough to catch a sharp peak.
//!
//! # Example
//! ```
//! use ambid_core::lti::Frd;
//! use ambid_core::validate::iso::{sensitivity_zone, IsoZones, Zone};
//! use ambid_core::c64;
//! let s = Frd::new(vec![10.0, 100.0, 300.0], vec![c64::new(1.0, 0.0), c64::new(2.2, -1.0),
//!                  c64::new(1.1, 0.2)], Some(vec![1e-4, 1e-2, 1e-4]), Some(5e-5)).unwrap();
//! let v = sensitivity_zone(&s, &IsoZones::default()).unwrap();
//! assert_eq!(v.zone, Zone::A);
//! assert!((v.peak - (2.2f64.powi(2) + 1.0).sqrt()).abs() < 1e-12 && v.f_peak_hz == 100.0);
//! ```

use crate::error::{Error, Result};
use crate::lti::Frd;

/// Upper limits of the zones A, B, C for $\max|S|$ (absolute, not dB).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IsoZones {
    /// Upper limit of zone A (default 3, i.e. 9.5 dB).
    pub a: f64,
    /// Upper limit of zone B (default 4, 12 dB).
    pub b: f64,
    /// Upper limit of zone C (default 5, 14 dB); above is zone D.
    pub c: f64,
}

impl Default for IsoZones {
    fn default() -> Self {
        Self {
            a: 3.0,
            b: 4.0,
            c: 5.0,
        }
    }
}

impl IsoZones {
    /// The zone of a peak value.
    pub fn zone(&self, peak: f64) -> Zone {
        if peak < self.a {
            Zone::A
        } else if peak < self.b {
            Zone::B
        } else if peak < self.c {
            Zone::C
        } else {
            Zone::D
        }
    }
    fn check(&self) -> Result<()> {
        if !(self.a.is_finite()
            && self.a > 1.0
            && self.a < self.b
            && self.b < self.c
            && self.c.is_finite())
        {
            return Err(Error::invalid(
                "zones",
                format!(
                    "the zone limits must satisfy 1 < A < B < C (finite), got {} / {} / {}",
                    self.a, self.b, self.c
                ),
            ));
        }
        Ok(())
    }
}

/// ISO 14839-3 zone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
pub enum Zone {
    /// Newly commissioned machines.
    A,
    /// Unrestricted long-term operation.
    B,
    /// Limited operation.
    C,
    /// Damage may occur.
    D,
}

/// The verdict of [`sensitivity_zone`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct IsoVerdict {
    /// $\max_k |S_k|$.
    pub peak: f64,
    /// Its frequency \[Hz\].
    pub f_peak_hz: f64,
    /// 95 % interval of the peak line's magnitude (when the FRF has variances).
    pub interval: Option<(f64, f64)>,
    /// Zone of the peak.
    pub zone: Zone,
    /// Zones of the interval's ends (equal to `zone` without variances).
    pub zone_range: (Zone, Zone),
}

/// The ISO 14839-3 zone of a sensitivity function given on lines (module docs).
///
/// # Errors
/// [`Error::InvalidArgument`] for an empty FRF or zone limits that are not increasing above 1.
pub fn sensitivity_zone(s: &Frd, zones: &IsoZones) -> Result<IsoVerdict> {
    s.require_siso("iso::sensitivity_zone")?;
    zones.check()?;
    let (k, peak) = s
        .values()
        .iter()
        .map(|v| v.norm())
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .ok_or_else(|| Error::invalid("s", "the sensitivity FRF has no lines"))?;
    let interval = s.variance().map(|v| {
        let h = 1.959_963_984_540_054 * (v[k] / 2.0).sqrt();
        ((peak - h).max(0.0), peak + h)
    });
    let zone = zones.zone(peak);
    let zone_range = interval.map_or((zone, zone), |(lo, hi)| (zones.zone(lo), zones.zone(hi)));
    Ok(IsoVerdict {
        peak,
        f_peak_hz: s.f_hz()[k],
        interval,
        zone,
        zone_range,
    })
}
