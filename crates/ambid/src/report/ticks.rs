//! Axis ranges and "nice" tick positions and labels for linear and base-10 logarithmic axes.
//!
//! All positions here are in *axis space*: the value itself on a linear axis, `log10(value)` on a
//! logarithmic axis ([`to_axis`]). Labels are always about the data value.

use super::Scale;

/// The label of one major tick.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum TickLabel {
    /// Plain text, e.g. `"0.25"` or `"2e6"`.
    Plain(String),
    /// `10^k`, drawn with a superscript exponent.
    Pow10(i32),
}

impl TickLabel {
    /// Rough width in units of the font size (for layout only).
    pub(crate) fn width_em(&self) -> f64 {
        match self {
            TickLabel::Plain(s) => text_width_em(s),
            TickLabel::Pow10(k) => 1.15 + 0.45 * k.to_string().len() as f64,
        }
    }

    /// The label as plain text (tooltips, tests).
    #[cfg(test)]
    pub(crate) fn text(&self) -> String {
        match self {
            TickLabel::Plain(s) => s.clone(),
            TickLabel::Pow10(k) => format!("10^{k}"),
        }
    }
}

/// Ticks of one axis, in axis space.
#[derive(Debug, Clone, Default)]
pub(crate) struct Ticks {
    /// Labelled ticks with gridlines.
    pub major: Vec<(f64, TickLabel)>,
    /// Unlabelled light gridlines (log axes: 2…9 × 10^k).
    pub minor: Vec<f64>,
}

/// Rough width of a text in units of the font size (sans-serif average advance).
pub(crate) fn text_width_em(s: &str) -> f64 {
    s.chars()
        .map(|c| match c {
            'i' | 'l' | 'j' | '.' | ',' | ':' | ';' | '\'' | '|' | '!' | ' ' => 0.3,
            'f' | 't' | 'r' | '(' | ')' | '[' | ']' | '-' => 0.38,
            'm' | 'w' | 'M' | 'W' => 0.85,
            c if c.is_ascii_uppercase() => 0.68,
            c if c.is_ascii_digit() => 0.56,
            _ => 0.55,
        })
        .sum()
}

/// Maps a data value to axis space; `None` for values that cannot be drawn on this scale
/// (non-finite, or ≤ 0 on a log axis).
#[inline]
pub(crate) fn to_axis(scale: Scale, v: f64) -> Option<f64> {
    match scale {
        Scale::Linear if v.is_finite() => Some(v),
        Scale::Log if v.is_finite() && v > 0.0 => Some(v.log10()),
        _ => None,
    }
}

/// A fixed axis range in axis space, if it is usable on this scale.
pub(crate) fn fixed_range(scale: Scale, range: Option<(f64, f64)>) -> Option<(f64, f64)> {
    let (a, b) = range?;
    let (a, b) = (to_axis(scale, a)?, to_axis(scale, b)?);
    let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
    (hi > lo).then_some((lo, hi))
}

/// Widens a degenerate (or empty) range so that it can be drawn.
pub(crate) fn sane_range(scale: Scale, lo: f64, hi: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) || hi < lo {
        // Linear: 0 … 1; log: 1 … 10 (one decade).
        return (0.0, 1.0);
    }
    if hi > lo {
        return (lo, hi);
    }
    let half = match scale {
        Scale::Linear => (lo.abs() * 0.1).max(0.5),
        Scale::Log => 0.5,
    };
    (lo - half, hi + half)
}

/// A "nice" step (1, 2, 2.5 or 5 × 10^k; only 1, 2, 5 with `integer`) close to `raw`.
fn nice_step(raw: f64, integer: bool) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let m = if f < 1.5 {
        1.0
    } else if f < 2.25 {
        2.0
    } else if f < 3.5 && !integer {
        2.5
    } else if f < 3.5 {
        2.0
    } else if f < 7.5 {
        5.0
    } else {
        10.0
    };
    let step = m * mag;
    if integer {
        step.max(1.0)
    } else {
        step
    }
}

/// Tick values `k·step` inside `[lo, hi]`.
fn linear_values(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let eps = step * 1e-9;
    let k0 = ((lo - eps) / step).ceil();
    let k1 = ((hi + eps) / step).floor();
    if !(k0.is_finite() && k1.is_finite()) || k1 - k0 > 1000.0 {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut k = k0;
    while k <= k1 {
        let v = k * step;
        out.push(if v.abs() < eps { 0.0 } else { v });
        k += 1.0;
    }
    out
}

/// Formats tick values with the fewest digits that still tell them apart and give back each
/// value to within `1e-6·step` (plain notation, or scientific for very large or small numbers).
pub(crate) fn format_ticks(values: &[f64], step: f64) -> Vec<String> {
    let max_abs = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let scientific = max_abs >= 1e5 || (max_abs > 0.0 && max_abs < 1e-3);
    let tol = (step.abs() * 1e-6).max(f64::MIN_POSITIVE);
    for digits in 0..=12usize {
        let labels: Vec<String> = values
            .iter()
            .map(|&v| {
                if v == 0.0 && scientific {
                    "0".to_string()
                } else if scientific {
                    format!("{v:.digits$e}")
                } else {
                    format!("{v:.digits$}")
                }
            })
            .collect();
        let exact = labels
            .iter()
            .zip(values)
            .all(|(s, v)| s.parse::<f64>().is_ok_and(|p| (p - v).abs() <= tol));
        if exact {
            return labels.into_iter().map(clean_label).collect();
        }
    }
    values.iter().map(|&v| super::format_number(v)).collect()
}

/// Removes a negative zero sign ("-0", "-0.0").
fn clean_label(s: String) -> String {
    if s.starts_with('-')
        && s.trim_start_matches('-')
            .chars()
            .all(|c| c == '0' || c == '.')
    {
        s[1..].to_string()
    } else {
        s
    }
}

/// Nice ticks for a linear axis over `[lo, hi]`, about `target` of them.
pub(crate) fn linear_ticks(lo: f64, hi: f64, target: usize, integer: bool) -> (Ticks, f64) {
    let target = target.max(2) as f64;
    let step = nice_step((hi - lo) / target, integer);
    let values = linear_values(lo, hi, step);
    let labels = format_ticks(&values, step);
    let major = values
        .into_iter()
        .zip(labels)
        .map(|(v, s)| (v, TickLabel::Plain(s)))
        .collect();
    (
        Ticks {
            major,
            minor: Vec::new(),
        },
        step,
    )
}

/// Ticks for a log axis over `[lo, hi]` in decades (log10 of the values).
///
/// Two or more whole decades inside: labels `10^k` (every m-th decade when there are many),
/// minor gridlines at 2…9 × 10^k. Otherwise 1-2-5 (or 1…9) × 10^k, labelled plainly; for very
/// narrow ranges linear ticks of the values.
pub(crate) fn log_ticks(lo: f64, hi: f64, target: usize) -> Ticks {
    let target = target.max(2);
    let eps = 1e-9;
    let k0 = (lo - eps).ceil();
    let k1 = (hi + eps).floor();
    if !(k0.is_finite() && k1.is_finite()) || k1 - k0 > 600.0 {
        return Ticks::default();
    }
    let (k0, k1) = (k0 as i32, k1 as i32);
    let decades = k1 - k0 + 1;
    let mut ticks = Ticks::default();
    if decades >= 2 {
        let stride = ((decades as usize).div_ceil(target)).max(1) as i32;
        // Anchor the stride at multiples so that 10^0 is labelled when possible.
        let first = k0 + (stride - k0.rem_euclid(stride)) % stride;
        let mut k = first;
        while k <= k1 {
            ticks.major.push((k as f64, TickLabel::Pow10(k)));
            k += stride;
        }
        let span = hi - lo;
        // Minor gridlines only when a decade is wide enough (≈ 60 px for ≈ 40 px per target
        // tick), else they turn into a grey wash.
        if stride == 1 && span * 1.5 <= target as f64 {
            let d0 = lo.floor() as i32;
            let d1 = hi.ceil() as i32;
            for d in d0..=d1 {
                for m in 2..=9 {
                    let u = d as f64 + (m as f64).log10();
                    if u >= lo - eps && u <= hi + eps {
                        ticks.minor.push(u);
                    }
                }
            }
        } else if stride > 1 {
            for k in k0..=k1 {
                if (k - first).rem_euclid(stride) != 0 {
                    ticks.minor.push(k as f64);
                }
            }
        }
        return ticks;
    }
    // Fewer than two decade ticks: mantissa ticks.
    let d0 = lo.floor() as i32;
    let d1 = hi.ceil() as i32;
    for mantissas in [
        &[1.0, 2.0, 5.0][..],
        &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
    ] {
        let mut values = Vec::new();
        for d in d0..=d1 {
            for &m in mantissas {
                let v = m * 10f64.powi(d);
                let u = v.log10();
                if u >= lo - eps && u <= hi + eps {
                    values.push(v);
                }
            }
        }
        if values.len() >= 3 || (values.len() >= 2 && mantissas.len() > 3) {
            let step = values
                .windows(2)
                .map(|w| w[1] - w[0])
                .fold(f64::INFINITY, f64::min);
            let labels = format_ticks(&values, if step.is_finite() { step } else { 1.0 });
            ticks.major = values
                .iter()
                .zip(labels)
                .map(|(v, s)| (v.log10(), TickLabel::Plain(s)))
                .collect();
            return ticks;
        }
    }
    // Very narrow: linear ticks of the values.
    let (vlo, vhi) = (10f64.powf(lo), 10f64.powf(hi));
    let (lin, _) = linear_ticks(vlo, vhi, target.min(5), false);
    ticks.major = lin
        .major
        .into_iter()
        .filter(|(v, _)| *v > 0.0)
        .map(|(v, l)| (v.log10(), l))
        .collect();
    ticks
}

/// Ticks for an axis of the given scale over `[lo, hi]` (axis space).
pub(crate) fn ticks_for(scale: Scale, lo: f64, hi: f64, target: usize, integer: bool) -> Ticks {
    match scale {
        Scale::Linear => linear_ticks(lo, hi, target, integer).0,
        Scale::Log => log_ticks(lo, hi, target),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels(t: &Ticks) -> Vec<String> {
        t.major.iter().map(|(_, l)| l.text()).collect()
    }

    #[test]
    fn linear_unit_interval() {
        let (t, step) = linear_ticks(0.0, 1.0, 5, false);
        assert_eq!(step, 0.2);
        assert_eq!(labels(&t), ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
    }

    #[test]
    fn linear_negative_and_no_negative_zero() {
        let (t, _) = linear_ticks(-1.05, 1.05, 4, false);
        assert_eq!(labels(&t), ["-1.0", "-0.5", "0.0", "0.5", "1.0"]);
        // 0.1 + 0.2 style rounding noise must not leak into labels.
        let (t, _) = linear_ticks(0.0, 0.7, 7, false);
        assert_eq!(
            labels(&t),
            ["0.0", "0.1", "0.2", "0.3", "0.4", "0.5", "0.6", "0.7"]
        );
        let (t, _) = linear_ticks(-20.0, 20.0, 4, false);
        assert_eq!(labels(&t), ["-20", "-10", "0", "10", "20"]);
    }

    #[test]
    fn linear_quarter_steps_keep_two_decimals() {
        let (t, step) = linear_ticks(0.0, 1.0, 4, false);
        assert_eq!(step, 0.25);
        assert_eq!(labels(&t), ["0.00", "0.25", "0.50", "0.75", "1.00"]);
    }

    #[test]
    fn linear_large_and_small_use_scientific() {
        let (t, _) = linear_ticks(0.0, 3e6, 3, false);
        assert_eq!(labels(&t), ["0", "1e6", "2e6", "3e6"]);
        let (t, _) = linear_ticks(0.0, 3e-5, 3, false);
        assert_eq!(labels(&t), ["0", "1e-5", "2e-5", "3e-5"]);
        let (t, _) = linear_ticks(1.0e6, 1.3e6, 3, false);
        assert_eq!(labels(&t), ["1.0e6", "1.1e6", "1.2e6", "1.3e6"]);
    }

    #[test]
    fn integer_ticks_never_fractional() {
        let (t, step) = linear_ticks(0.5, 3.5, 8, true);
        assert_eq!(step, 1.0);
        assert_eq!(labels(&t), ["1", "2", "3"]);
    }

    #[test]
    fn log_decades() {
        let t = log_ticks(0.0, 3.0, 8);
        assert!(log_ticks(0.0, 5.0, 6).minor.is_empty());
        assert_eq!(labels(&t), ["10^0", "10^1", "10^2", "10^3"]);
        assert_eq!(t.major[2].0, 2.0);
        // 2..9 in each of the three decades.
        assert_eq!(t.minor.len(), 24);
        assert!((t.minor[0] - 2f64.log10()).abs() < 1e-12);
    }

    #[test]
    fn log_many_decades_stride() {
        let t = log_ticks(-12.0, 12.0, 6);
        let ks: Vec<String> = labels(&t);
        assert!(ks.len() <= 7, "{ks:?}");
        assert!(ks.contains(&"10^0".to_string()), "{ks:?}");
        assert!(!t.minor.is_empty());
    }

    #[test]
    fn log_narrow_uses_mantissas() {
        // 2 .. 30: only one decade tick (10) inside.
        let t = log_ticks(2f64.log10(), 30f64.log10(), 6);
        assert_eq!(labels(&t), ["2", "5", "10", "20"]);
        // 3 .. 8: 1-2-5 gives only 5; 1..9 gives 3..8.
        let t = log_ticks(3f64.log10(), 8f64.log10(), 6);
        assert_eq!(labels(&t), ["3", "4", "5", "6", "7", "8"]);
        // Very narrow: linear ticks of the values.
        let t = log_ticks(100f64.log10(), 104f64.log10(), 5);
        assert_eq!(labels(&t), ["100", "101", "102", "103", "104"]);
    }

    #[test]
    fn axis_mapping_skips_undrawable() {
        assert_eq!(to_axis(Scale::Log, 0.0), None);
        assert_eq!(to_axis(Scale::Log, -1.0), None);
        assert_eq!(to_axis(Scale::Log, 100.0), Some(2.0));
        assert_eq!(to_axis(Scale::Linear, f64::NAN), None);
        assert_eq!(to_axis(Scale::Linear, f64::INFINITY), None);
        assert_eq!(fixed_range(Scale::Log, Some((0.0, 10.0))), None);
        assert_eq!(
            fixed_range(Scale::Linear, Some((2.0, -2.0))),
            Some((-2.0, 2.0))
        );
        assert_eq!(sane_range(Scale::Linear, 3.0, 3.0), (2.5, 3.5));
    }
}
