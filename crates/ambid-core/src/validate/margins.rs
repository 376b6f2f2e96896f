//! Stability margins of a loop from its loop gain $L = PC$ on a frequency grid.
//!
//! * **Gain crossovers** $|L| = 1$: phase margin $\mathrm{PM} = 180° + \angle L$ (the angle wrapped
//!   to $(-360°, 0°]$), one per crossover; the smallest is the phase margin.
//! * **Phase crossovers** $\angle L = -180°$: gain margin $1/|L|$ there. An AMB plant is open-loop
//!   unstable, so the loop is conditionally stable: a crossover with $|L| > 1$ gives a
//!   **lower** gain margin ($< 1$: the loop goes unstable if the gain drops by that factor), one
//!   with $|L| < 1$ an upper one; both are reported.
//! * The peak of $|S| = 1/|1 + L|$ and its frequency: $1/\max|S|$ is the distance of the Nyquist
//!   curve to $-1$, the margin the ISO 14839-3 zones judge ([`super::iso`]).
//!
//! Crossovers are located by linear interpolation between grid points (in $\log|L|$ and in the
//! unwrapped phase): give a grid fine enough for the loop's resonances. The margins say nothing
//! about stability by themselves for an unstable plant (that needs the encirclement count):
//! check the closed-loop poles ([`super::closed_loop`] refuses an unstable loop).
//!
//! # Example
//! ```
//! use ambid_core::validate::margins::margins;
//! use ambid_core::c64;
//! // L = 2 / (s (s + 1)) at s = jω (ω in rad/s = 2π f): crossover near 1.25 rad/s
//! let f: Vec<f64> = (1..2000).map(|k| k as f64 * 1e-3).collect();
//! let l: Vec<c64> = f.iter().map(|f| { let s = c64::new(0.0, 2.0 * std::f64::consts::PI * f);
//!                                        c64::new(2.0, 0.0) / (s * (s + 1.0)) }).collect();
//! let m = margins(&f, &l).unwrap();
//! let pm = m.phase_margins[0].1;
//! assert!((pm - 38.67).abs() < 0.1, "{pm}");
//! ```

use crate::error::{Error, Result};
use faer::c64;

/// What [`margins`] finds.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Margins {
    /// (frequency \[Hz\], phase margin \[deg\]) at every gain crossover.
    pub phase_margins: Vec<(f64, f64)>,
    /// (frequency \[Hz\], gain margin factor $1/|L|$) at every phase crossover.
    pub gain_margins: Vec<(f64, f64)>,
    /// $\max |S|$ on the grid and its frequency \[Hz\].
    pub peak_sensitivity: (f64, f64),
}

impl Margins {
    /// The smallest phase margin \[deg\], if any crossover.
    pub fn phase_margin(&self) -> Option<f64> {
        self.phase_margins
            .iter()
            .map(|m| m.1)
            .min_by(f64::total_cmp)
    }
    /// The upper gain margin (smallest factor above 1), if any.
    pub fn upper_gain_margin(&self) -> Option<f64> {
        self.gain_margins
            .iter()
            .map(|m| m.1)
            .filter(|g| *g > 1.0)
            .min_by(f64::total_cmp)
    }
    /// The lower gain margin (largest factor below 1), if any.
    pub fn lower_gain_margin(&self) -> Option<f64> {
        self.gain_margins
            .iter()
            .map(|m| m.1)
            .filter(|g| *g < 1.0)
            .max_by(f64::total_cmp)
    }
}

/// Margins of the loop gain `l` given at the frequencies `f_hz` (increasing), module docs.
///
/// # Errors
/// [`Error::InvalidArgument`] for fewer than 2 points, different lengths, non-finite values or
/// frequencies that do not increase.
pub fn margins(f_hz: &[f64], l: &[c64]) -> Result<Margins> {
    if f_hz.len() != l.len() || f_hz.len() < 2 {
        return Err(Error::invalid(
            "l",
            format!(
                "need the loop gain at ≥ 2 frequencies, equal lengths (got {} and {})",
                f_hz.len(),
                l.len()
            ),
        ));
    }
    if f_hz
        .windows(2)
        .any(|w| w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater))
        || l.iter().any(|v| !(v.re.is_finite() && v.im.is_finite()))
        || f_hz.iter().any(|f| !f.is_finite())
    {
        return Err(Error::invalid(
            "f_hz",
            "frequencies must increase and the loop gain must be finite",
        ));
    }
    // unwrapped phase in degrees
    let mut ph = Vec::with_capacity(l.len());
    let mut prev = l[0].arg();
    let mut off = 0.0;
    for v in l {
        let a = v.arg();
        let mut d = a - prev;
        while d > std::f64::consts::PI {
            d -= 2.0 * std::f64::consts::PI;
            off -= 2.0 * std::f64::consts::PI;
        }
        while d < -std::f64::consts::PI {
            d += 2.0 * std::f64::consts::PI;
            off += 2.0 * std::f64::consts::PI;
        }
        ph.push((a + off).to_degrees());
        prev = a;
    }
    let mag: Vec<f64> = l
        .iter()
        .map(|v| v.norm().max(f64::MIN_POSITIVE).ln())
        .collect();
    let lerp = |k: usize, t: f64, x: &[f64]| x[k] + t * (x[k + 1] - x[k]);
    let mut phase_margins = Vec::new();
    let mut gain_margins = Vec::new();
    for k in 0..l.len() - 1 {
        // gain crossover: ln|L| changes sign
        if mag[k] == 0.0 || mag[k] * mag[k + 1] < 0.0 {
            let t = if mag[k] == 0.0 {
                0.0
            } else {
                mag[k] / (mag[k] - mag[k + 1])
            };
            let p = lerp(k, t, &ph);
            // phase wrapped to (−360, 0]
            let pw = p - 360.0 * (p / 360.0).ceil();
            phase_margins.push((lerp(k, t, f_hz), 180.0 + pw));
        }
        // phase crossover: the unwrapped phase crosses −180 + 360 m
        let (p0, p1) = (ph[k], ph[k + 1]);
        let lo = p0.min(p1);
        let hi = p0.max(p1);
        let mut m = ((lo + 180.0) / 360.0).ceil();
        while -180.0 + 360.0 * m <= hi {
            let target = -180.0 + 360.0 * m;
            if (p1 - p0).abs() > 0.0 && target >= lo && target <= hi {
                let t = (target - p0) / (p1 - p0);
                gain_margins.push((lerp(k, t, f_hz), 1.0 / lerp(k, t, &mag).exp()));
            }
            m += 1.0;
        }
    }
    let (ks, smax) = l
        .iter()
        .map(|v| 1.0 / (c64::new(1.0, 0.0) + v).norm())
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, f64::NAN));
    Ok(Margins {
        phase_margins,
        gain_margins,
        peak_sensitivity: (smax, f_hz[ks]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// L = K/(s + 1)³: the phase crosses −180° at ω = √3 where |L| = K/8, so the gain margin is
    /// 8/K (analytic); with K = 2 the peak |S| equals 1/min|1 + L|.
    #[test]
    fn gain_margin_of_a_third_order_lag() {
        let f: Vec<f64> = (1..20000).map(|k| k as f64 * 5e-5).collect();
        let l: Vec<c64> = f
            .iter()
            .map(|f| {
                let s = c64::new(1.0, 2.0 * std::f64::consts::PI * f);
                c64::new(2.0, 0.0) / (s * s * s)
            })
            .collect();
        let m = margins(&f, &l).unwrap();
        assert_eq!(m.gain_margins.len(), 1);
        let (fg, g) = m.gain_margins[0];
        assert!((g - 4.0).abs() < 1e-6, "{g}");
        assert!(
            (2.0 * std::f64::consts::PI * fg - 3f64.sqrt()).abs() < 1e-4,
            "{fg}"
        );
        assert_eq!(m.upper_gain_margin(), Some(g));
        assert!(m.lower_gain_margin().is_none());
        let smax = l
            .iter()
            .map(|v| 1.0 / (c64::new(1.0, 0.0) + v).norm())
            .fold(0.0, f64::max);
        assert_eq!(m.peak_sensitivity.0, smax);
        assert!(margins(&f[..1], &l[..1]).is_err());
    }
}
