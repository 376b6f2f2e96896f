//! Pixel geometry for the SVG plotter: data → pixel mapping, splitting series at undrawable
//! points, and decimation for drawing (min/max per pixel column, so peaks survive).

use super::ticks::to_axis;
use super::Scale;

/// Pixel coordinates are clamped to this magnitude so that far-out points (a fixed axis range
/// much narrower than the data) give finite, bounded SVG numbers; they are clipped anyway.
const PX_LIMIT: f64 = 1.0e5;

/// Maps one axis from data values to pixels.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AxisMap {
    /// Scale of the axis.
    pub scale: Scale,
    /// Range start in axis space (log10 of the value on a log axis).
    pub lo: f64,
    /// Range end in axis space.
    pub hi: f64,
    /// Pixel of `lo`.
    pub p0: f64,
    /// Pixel of `hi`.
    pub p1: f64,
}

impl AxisMap {
    /// Pixel of an axis-space value.
    #[inline]
    pub(crate) fn pu(&self, u: f64) -> f64 {
        let span = self.hi - self.lo;
        let t = if span != 0.0 {
            (u - self.lo) / span
        } else {
            0.5
        };
        let p = self.p0 + t * (self.p1 - self.p0);
        if p.is_nan() {
            self.p0
        } else {
            p.clamp(-PX_LIMIT, PX_LIMIT)
        }
    }

    /// Pixel of a data value, `None` when it cannot be drawn on this axis.
    #[inline]
    pub(crate) fn px(&self, v: f64) -> Option<f64> {
        to_axis(self.scale, v).map(|u| self.pu(u))
    }

    /// Whether an axis-space value is inside the range.
    #[inline]
    pub(crate) fn contains_u(&self, u: f64) -> bool {
        let eps = (self.hi - self.lo).abs() * 1e-9;
        u >= self.lo.min(self.hi) - eps && u <= self.lo.max(self.hi) + eps
    }
}

/// Splits `(x, y)` into runs of drawable points (in pixels); a non-finite value (or ≤ 0 on a log
/// axis) ends a run, so lines are broken there.
pub(crate) fn runs(x: &[f64], y: &[f64], mx: &AxisMap, my: &AxisMap) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    let mut cur: Vec<(f64, f64)> = Vec::new();
    for (&xv, &yv) in x.iter().zip(y) {
        match (mx.px(xv), my.px(yv)) {
            (Some(px), Some(py)) => cur.push((px, py)),
            _ => {
                if !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
            }
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Decimates a run of pixel points: consecutive points falling in the same pixel column are
/// reduced to the two with the smallest and largest pixel y, in their original order. Works for
/// any x order (a column group is a run of consecutive points in one column).
pub(crate) fn decimate_minmax(run: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(run.len().min(4096));
    let mut i = 0;
    while i < run.len() {
        let col = run[i].0.floor();
        let mut j = i;
        let (mut imin, mut imax) = (i, i);
        while j < run.len() && run[j].0.floor() == col {
            if run[j].1 < run[imin].1 {
                imin = j;
            }
            if run[j].1 > run[imax].1 {
                imax = j;
            }
            j += 1;
        }
        if imin == imax {
            out.push(run[imin]);
        } else {
            out.push(run[imin.min(imax)]);
            out.push(run[imin.max(imax)]);
        }
        i = j.max(i + 1);
    }
    out
}

/// Runs of a band: points where x, the upper and the lower edge are all drawable, as
/// `(x, y_upper, y_lower)` pixels.
pub(crate) fn band_runs(
    x: &[f64],
    upper: &[f64],
    lower: &[f64],
    mx: &AxisMap,
    my: &AxisMap,
) -> Vec<Vec<(f64, f64, f64)>> {
    let mut out = Vec::new();
    let mut cur = Vec::new();
    for ((&xv, &u), &l) in x.iter().zip(upper).zip(lower) {
        match (mx.px(xv), my.px(u), my.px(l)) {
            (Some(px), Some(pu), Some(pl)) => cur.push((px, pu, pl)),
            _ => {
                if !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
            }
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Decimates a band run: consecutive points in one pixel column become one point holding the
/// envelope (topmost upper edge, bottommost lower edge).
pub(crate) fn decimate_band(run: &[(f64, f64, f64)]) -> Vec<(f64, f64, f64)> {
    let mut out: Vec<(f64, f64, f64)> = Vec::new();
    let mut last_col = f64::NAN;
    for &(x, u, l) in run {
        let col = x.floor();
        match out.last_mut() {
            Some(p) if col == last_col => {
                let (top, bottom) = (u.min(l), u.max(l));
                let (ptop, pbottom) = (p.1.min(p.2), p.1.max(p.2));
                *p = (p.0, ptop.min(top), pbottom.max(bottom));
            }
            _ => out.push((x, u, l)),
        }
        last_col = col;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lin(lo: f64, hi: f64, p0: f64, p1: f64) -> AxisMap {
        AxisMap {
            scale: Scale::Linear,
            lo,
            hi,
            p0,
            p1,
        }
    }

    #[test]
    fn nan_and_log_nonpositive_break_runs() {
        let mx = lin(0.0, 10.0, 0.0, 100.0);
        let my = AxisMap {
            scale: Scale::Log,
            lo: 0.0,
            hi: 2.0,
            p0: 100.0,
            p1: 0.0,
        };
        let x = [0.0, 1.0, 2.0, f64::NAN, 4.0, 5.0, 6.0, 7.0];
        let y = [1.0, 10.0, 100.0, 5.0, 5.0, 0.0, -3.0, 50.0];
        let r = runs(&x, &y, &mx, &my);
        assert_eq!(r.len(), 3);
        assert_eq!(r[0].len(), 3);
        assert_eq!(r[0][1], (10.0, 50.0));
        assert_eq!(r[1].len(), 1);
        assert_eq!(r[2].len(), 1);
    }

    #[test]
    fn decimation_keeps_spike() {
        // 5000 points over 500 px; one spike in the middle.
        let mx = lin(0.0, 4999.0, 0.0, 500.0);
        let my = lin(-1.0, 10.0, 300.0, 0.0);
        let x: Vec<f64> = (0..5000).map(|i| i as f64).collect();
        let mut y: Vec<f64> = (0..5000).map(|i| (i as f64 * 0.1).sin() * 0.5).collect();
        y[2501] = 9.5;
        let r = runs(&x, &y, &mx, &my);
        assert_eq!(r.len(), 1);
        let d = decimate_minmax(&r[0]);
        assert!(d.len() <= 2 * 501, "{}", d.len());
        let spike = my.px(9.5).unwrap_or(f64::NAN);
        let top = d.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        assert_eq!(top, spike);
        // x order is kept.
        assert!(d.windows(2).all(|w| w[0].0 <= w[1].0));
    }

    #[test]
    fn band_decimation_keeps_envelope() {
        let run: Vec<(f64, f64, f64)> = (0..100)
            .map(|i| {
                (
                    i as f64 * 0.05,
                    50.0 - (i % 7) as f64,
                    60.0 + (i % 5) as f64,
                )
            })
            .collect();
        let d = decimate_band(&run);
        assert_eq!(d.len(), 5);
        assert!(d.iter().all(|p| p.1 == 44.0 && p.2 == 64.0));
    }
}
