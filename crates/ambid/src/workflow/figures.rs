//! Small builders for the report's figures (the report module only draws what it is given).

use crate::report::{Axis, Figure, Marker, Panel, PanelContent, Scale, Series, Span, Style};
use ambid_core::c64;

/// A linear axis.
pub fn lin(label: &str) -> Axis {
    Axis {
        label: label.into(),
        scale: Scale::Linear,
        range: None,
    }
}

/// A logarithmic axis.
pub fn log(label: &str) -> Axis {
    Axis {
        label: label.into(),
        scale: Scale::Log,
        range: None,
    }
}

/// A series.
pub fn series(name: &str, x: &[f64], y: &[f64], style: Style, color: Option<usize>) -> Series {
    Series {
        name: name.into(),
        x: x.to_vec(),
        y: y.to_vec(),
        style,
        color,
    }
}

/// An x–y panel.
pub fn xy(title: &str, x: Axis, y: Axis, series: Vec<Series>) -> Panel {
    Panel {
        title: title.into(),
        x,
        y,
        content: PanelContent::Xy(series),
        spans: Vec::new(),
        equal_aspect: false,
    }
}

/// A panel with shaded spans.
pub fn with_spans(mut p: Panel, spans: Vec<Span>) -> Panel {
    p.spans = spans;
    p
}

/// A figure.
pub fn figure(
    id: &str,
    title: &str,
    caption: String,
    panels: Vec<Panel>,
    columns: usize,
) -> Figure {
    Figure {
        id: id.into(),
        title: title.into(),
        caption,
        panels,
        columns,
    }
}

/// Magnitude in dB.
pub fn db(v: &[c64]) -> Vec<f64> {
    v.iter().map(|z| 20.0 * z.norm().log10()).collect()
}

/// Phase in degrees, unwrapped along the frequency axis.
pub fn phase_deg(v: &[c64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(v.len());
    let mut prev = 0.0f64;
    let mut offset = 0.0;
    for (k, z) in v.iter().enumerate() {
        let p = z.arg().to_degrees();
        if k > 0 {
            let d = p + offset - prev;
            if d > 180.0 {
                offset -= 360.0 * ((d + 180.0) / 360.0).floor();
            } else if d < -180.0 {
                offset += 360.0 * ((-d + 180.0) / 360.0).floor();
            }
        }
        if k == 0 && p > 90.0 {
            // start in (−270°, 90°]: a negative DC gain reads −180° whatever the sign of its
            // rounding-level imaginary part, so curves of one plant line up
            offset = -360.0;
        }
        let q = p + offset;
        out.push(q);
        prev = q;
    }
    out
}

/// A named complex response for a Bode plot.
pub struct Curve<'a> {
    /// Legend.
    pub name: &'a str,
    /// Frequencies \[Hz\].
    pub f: &'a [f64],
    /// Values.
    pub g: &'a [c64],
    /// Standard deviation (draws a ±1.96σ band on the magnitude).
    pub std: Option<&'a [f64]>,
    /// Style.
    pub style: Style,
    /// Palette colour.
    pub color: Option<usize>,
}

/// Magnitude (dB) and phase (deg) panels of several curves on a log frequency axis.
pub fn bode_panels(curves: &[Curve<'_>], mag_label: &str) -> Vec<Panel> {
    let mut mag = Vec::new();
    let mut ph = Vec::new();
    // the confidence bands first, then the lines in reverse order: the first curve (the
    // estimate) is drawn last, on top of the references it is compared with
    for c in curves {
        if let Some(s) = c.std {
            let hi: Vec<f64> =
                c.g.iter()
                    .zip(s)
                    .map(|(z, s)| 20.0 * (z.norm() + 1.96 * s).log10())
                    .collect();
            let lo: Vec<f64> =
                c.g.iter()
                    .zip(s)
                    .map(|(z, s)| 20.0 * (z.norm() - 1.96 * s).max(0.1 * z.norm()).log10())
                    .collect();
            mag.push(Series {
                name: format!("{} 95 % band", c.name),
                x: c.f.to_vec(),
                y: hi,
                style: Style::Band { lower: lo },
                color: c.color,
            });
        }
    }
    for c in curves.iter().rev() {
        mag.push(series(c.name, c.f, &db(c.g), c.style.clone(), c.color));
        ph.push(series(
            c.name,
            c.f,
            &phase_deg(c.g),
            c.style.clone(),
            c.color,
        ));
    }
    vec![
        xy("magnitude", log("frequency [Hz]"), lin(mag_label), mag),
        xy("phase", log("frequency [Hz]"), lin("phase [deg]"), ph),
    ]
}

/// A pole-zero map panel (unit circle, poles ×, zeros ○).
pub fn pz_panel(title: &str, poles: &[c64], zeros: &[c64], zoom: Option<f64>) -> Panel {
    let circle: Vec<(f64, f64)> = (0..=360)
        .map(|k| {
            let t = (k as f64).to_radians();
            (t.cos(), t.sin())
        })
        .collect();
    let (cx, cy): (Vec<f64>, Vec<f64>) = circle.into_iter().unzip();
    let finite_zeros: Vec<&c64> = zeros.iter().filter(|z| z.norm() < 10.0).collect();
    let mut p = xy(
        title,
        lin("real part"),
        lin("imaginary part"),
        vec![
            series("unit circle", &cx, &cy, Style::Dashed, Some(7)),
            series(
                "poles",
                &poles.iter().map(|z| z.re).collect::<Vec<_>>(),
                &poles.iter().map(|z| z.im).collect::<Vec<_>>(),
                Style::Markers(Marker::Cross),
                Some(0),
            ),
            series(
                "zeros",
                &finite_zeros.iter().map(|z| z.re).collect::<Vec<_>>(),
                &finite_zeros.iter().map(|z| z.im).collect::<Vec<_>>(),
                Style::Markers(Marker::Circle),
                Some(1),
            ),
        ],
    );
    p.equal_aspect = true;
    if let Some(r) = zoom {
        p.x.range = Some((1.0 - r, 1.0 + r * 0.5));
        p.y.range = Some((-r, r));
    }
    p
}

/// Decimates a long time series to about `max_points` points keeping each block's minimum and
/// maximum (in time order), so that peaks survive; returns (t, x).
pub fn envelope(t: &[f64], x: &[f64], max_points: usize) -> (Vec<f64>, Vec<f64>) {
    let n = t.len().min(x.len());
    let blocks = (max_points / 2).max(1);
    if n <= max_points.max(2) {
        return (t[..n].to_vec(), x[..n].to_vec());
    }
    let size = n.div_ceil(blocks);
    let (mut to, mut xo) = (
        Vec::with_capacity(2 * blocks),
        Vec::with_capacity(2 * blocks),
    );
    let mut k = 0;
    while k < n {
        let end = (k + size).min(n);
        let (mut imin, mut imax) = (k, k);
        for j in k..end {
            if x[j] < x[imin] {
                imin = j;
            }
            if x[j] > x[imax] {
                imax = j;
            }
        }
        let (a, b) = if imin <= imax {
            (imin, imax)
        } else {
            (imax, imin)
        };
        to.push(t[a]);
        xo.push(x[a]);
        if b != a {
            to.push(t[b]);
            xo.push(x[b]);
        }
        k = end;
    }
    (to, xo)
}
