//! A small SVG plotter for report figures: one `<svg>` per [`Panel`], written as text.
//!
//! Text is emitted as SVG `<text>` (the browser lays it out with the page's fonts), so nothing
//! needs system fonts at render time. Coordinates are written with 0.1 px resolution.

use std::collections::HashSet;
use std::fmt::Write;

use super::geom::{band_runs, decimate_band, decimate_minmax, runs, AxisMap};
use super::html::escape;
use super::ticks::{fixed_range, linear_ticks, sane_range, text_width_em, ticks_for, to_axis};
use super::ticks::{TickLabel, Ticks};
use super::{format_number, Axis, Heatmap, Marker, Panel, PanelContent, Scale, Series, Style};

/// Okabe–Ito colours (colour-blind safe), with a neutral grey instead of the hard-to-see yellow.
pub(crate) const PALETTE: [&str; 8] = [
    "#0072B2", "#D55E00", "#009E73", "#E69F00", "#CC79A7", "#56B4E9", "#000000", "#7F7F7F",
];

/// Font stack written on every `<svg>` (the same as the page's).
pub(crate) const FONT_STACK: &str =
    "system-ui, -apple-system, 'Segoe UI', Roboto, 'Helvetica Neue', Arial, 'Noto Sans', 'Liberation Sans', 'DejaVu Sans', sans-serif";

/// Width of a figure's panel area in pixels.
pub(crate) const FIGURE_WIDTH: f64 = 900.0;
/// Horizontal gap between panels in a grid.
pub(crate) const PANEL_GAP: f64 = 12.0;

const TICK_FONT: f64 = 11.0;
const LABEL_FONT: f64 = 12.0;
const TITLE_FONT: f64 = 13.0;
const LEGEND_FONT: f64 = 11.5;
const TEXT_COLOR: &str = "#24292f";
const MUTED: &str = "#57606a";
const GRID_MAJOR: &str = "#e1e4e8";
const GRID_MINOR: &str = "#f1f3f5";
const FRAME: &str = "#afb8c1";

/// Writes into a `String` (infallible; the `fmt::Result` carries no information there).
macro_rules! w {
    ($out:expr, $($arg:tt)*) => {
        let _ = write!($out, $($arg)*);
    };
}

/// Size of the plot area for a panel in a grid of `columns`.
fn base_plot_height(columns: usize) -> f64 {
    match columns {
        0 | 1 => 290.0,
        2 => 230.0,
        _ => 190.0,
    }
}

/// Panel width for a grid of `columns` over [`FIGURE_WIDTH`].
pub(crate) fn panel_width(columns: usize) -> f64 {
    let c = columns.max(1) as f64;
    ((FIGURE_WIDTH - PANEL_GAP * (c - 1.0)) / c).floor()
}

/// One legend entry.
struct LegendEntry<'a> {
    name: &'a str,
    style: &'a Style,
    color: &'static str,
}

/// Resolves each series' colour: explicit palette indices are kept, the others take the next
/// palette colour not used explicitly in the panel.
fn series_colors(series: &[Series]) -> Vec<&'static str> {
    let used: HashSet<usize> = series
        .iter()
        .filter_map(|s| s.color.map(|c| c % PALETTE.len()))
        .collect();
    let mut next = 0usize;
    series
        .iter()
        .map(|s| match s.color {
            Some(c) => PALETTE[c % PALETTE.len()],
            None => {
                if used.len() < PALETTE.len() {
                    while used.contains(&(next % PALETTE.len())) {
                        next += 1;
                    }
                }
                let c = PALETTE[next % PALETTE.len()];
                next += 1;
                c
            }
        })
        .collect()
}

/// Running min/max.
#[derive(Clone, Copy)]
struct Extent {
    lo: f64,
    hi: f64,
}

impl Extent {
    fn new() -> Self {
        Extent {
            lo: f64::INFINITY,
            hi: f64::NEG_INFINITY,
        }
    }
    #[inline]
    fn add(&mut self, u: f64) {
        if u < self.lo {
            self.lo = u;
        }
        if u > self.hi {
            self.hi = u;
        }
    }
    fn get(self) -> Option<(f64, f64)> {
        (self.lo <= self.hi).then_some((self.lo, self.hi))
    }
}

/// Axis-space ranges of an Xy panel: `(x range, y range, any drawable point)`.
fn xy_ranges(panel: &Panel, series: &[Series]) -> ((f64, f64), (f64, f64), bool) {
    let (sx, sy) = (panel.x.scale, panel.y.scale);
    let fixed_x = fixed_range(sx, panel.x.range);
    let fixed_y = fixed_range(sy, panel.y.range);
    let (mut ex, mut ey) = (Extent::new(), Extent::new());
    let mut has_points = false;
    let mut pad_x = panel.equal_aspect;
    for s in series {
        let lower: &[f64] = match &s.style {
            Style::Band { lower } => lower,
            _ => &[],
        };
        if matches!(
            s.style,
            Style::Markers(_) | Style::LineMarkers(_) | Style::Stems
        ) {
            pad_x = true;
        }
        let mut any_drawn = false;
        for (i, (&xv, &yv)) in s.x.iter().zip(&s.y).enumerate() {
            let Some(ux) = to_axis(sx, xv) else { continue };
            if let Some((lo, hi)) = fixed_x {
                if ux < lo || ux > hi {
                    continue;
                }
            }
            let uy = to_axis(sy, yv);
            let ul = lower.get(i).and_then(|&l| to_axis(sy, l));
            if let Style::Band { .. } = s.style {
                if let (Some(a), Some(b)) = (uy, ul) {
                    ex.add(ux);
                    ey.add(a);
                    ey.add(b);
                    any_drawn = true;
                }
            } else if let Some(a) = uy {
                ex.add(ux);
                ey.add(a);
                any_drawn = true;
            }
        }
        if any_drawn {
            has_points = true;
            if s.style == Style::Stems && sy == Scale::Linear {
                ey.add(0.0);
            }
        }
    }
    let xr = match (fixed_x, ex.get()) {
        (Some(r), _) => r,
        (None, Some((lo, hi))) => {
            let (lo, hi) = sane_range(sx, lo, hi);
            let pad = if pad_x { 0.04 * (hi - lo) } else { 0.0 };
            (lo - pad, hi + pad)
        }
        (None, None) => sane_range(sx, f64::NAN, f64::NAN),
    };
    let yr = match (fixed_y, ey.get()) {
        (Some(r), _) => r,
        (None, Some((lo, hi))) => {
            let (lo, hi) = sane_range(sy, lo, hi);
            let pad = 0.05 * (hi - lo);
            (lo - pad, hi + pad)
        }
        (None, None) => sane_range(sy, f64::NAN, f64::NAN),
    };
    (xr, yr, has_points)
}

/// Cell boundaries (axis space) around centres; `None` for undrawable centres.
fn cell_edges(scale: Scale, centres: &[f64]) -> Vec<Option<(f64, f64)>> {
    let u: Vec<Option<f64>> = centres.iter().map(|&c| to_axis(scale, c)).collect();
    (0..u.len())
        .map(|i| {
            let ui = u[i]?;
            let prev = i
                .checked_sub(1)
                .and_then(|k| u[k])
                .map(|p| (ui - p).abs() / 2.0);
            let next = u
                .get(i + 1)
                .copied()
                .flatten()
                .map(|n| (n - ui).abs() / 2.0);
            let (hp, hn) = match (prev, next) {
                (Some(p), Some(n)) => (p, n),
                (Some(p), None) => (p, p),
                (None, Some(n)) => (n, n),
                (None, None) => (0.5, 0.5),
            };
            let (hp, hn) = (
                if hp > 0.0 { hp } else { 0.5 },
                if hn > 0.0 { hn } else { 0.5 },
            );
            Some((ui - hp, ui + hn))
        })
        .collect()
}

/// Whether all finite centres are integers (then ticks are integers too).
fn integer_centres(c: &[f64]) -> bool {
    !c.is_empty() && c.iter().all(|v| !v.is_finite() || v.fract() == 0.0)
}

/// The viridis colour map at `t` in [0, 1] (perceptually uniform, colour-blind safe).
pub(crate) fn viridis(t: f64) -> (u8, u8, u8) {
    const STOPS: [(f64, f64, f64); 9] = [
        (68.0, 1.0, 84.0),
        (71.0, 44.0, 122.0),
        (59.0, 81.0, 139.0),
        (44.0, 113.0, 142.0),
        (33.0, 144.0, 141.0),
        (39.0, 173.0, 129.0),
        (92.0, 200.0, 99.0),
        (170.0, 220.0, 50.0),
        (253.0, 231.0, 37.0),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let f = t * (STOPS.len() - 1) as f64;
    let i = (f.floor() as usize).min(STOPS.len() - 2);
    let a = f - i as f64;
    let (c0, c1) = (STOPS[i], STOPS[i + 1]);
    let mix = |p: f64, q: f64| (p + (q - p) * a).round().clamp(0.0, 255.0) as u8;
    (mix(c0.0, c1.0), mix(c0.1, c1.1), mix(c0.2, c1.2))
}

/// Writes a number with 0.1 resolution, without a trailing ".0".
#[inline]
fn num(out: &mut String, v: f64) {
    let r = (v * 10.0).round();
    if r == (r / 10.0).trunc() * 10.0 {
        w!(out, "{}", (r / 10.0) as i64);
    } else {
        w!(out, "{:.1}", r / 10.0);
    }
}

/// Pixel layout of one panel.
struct Layout {
    width: f64,
    height: f64,
    left: f64,
    top: f64,
    pw: f64,
    ph: f64,
    legend_y: f64,
}

/// Renders one panel as an `<svg>` element. `uid` must be unique in the document (clip path and
/// gradient ids are derived from it).
pub(crate) fn panel_svg(panel: &Panel, columns: usize, uid: &str, out: &mut String) {
    let width = panel_width(columns);
    let heatmap = matches!(panel.content, PanelContent::Heatmap(_));
    let empty: Vec<Series> = Vec::new();
    let series: &[Series] = match &panel.content {
        PanelContent::Xy(s) => s,
        PanelContent::Heatmap(_) => &empty,
    };
    let colors = series_colors(series);

    // Axis ranges (axis space) and whether anything can be drawn.
    let (xr, yr, has_data, x_int, y_int) = match &panel.content {
        PanelContent::Xy(s) => {
            let (xr, yr, has) = xy_ranges(panel, s);
            // Integer abscissae (orders, lags): integer ticks.
            let x_int = s.iter().any(|s| !s.x.is_empty())
                && s.iter().all(|s| integer_centres(&s.x) || s.x.is_empty());
            (xr, yr, has, x_int, false)
        }
        PanelContent::Heatmap(h) => {
            let (xr, yr, has) = heatmap_ranges(panel, h);
            (xr, yr, has, integer_centres(&h.x), integer_centres(&h.y))
        }
    };

    // Legend entries (only with two or more named series).
    let mut legend: Vec<LegendEntry> = Vec::new();
    for (s, &c) in series.iter().zip(&colors) {
        if s.name.is_empty() {
            continue;
        }
        if legend
            .iter()
            .any(|e| e.name == s.name && e.color == c && e.style == &s.style)
        {
            continue;
        }
        legend.push(LegendEntry {
            name: &s.name,
            style: &s.style,
            color: c,
        });
    }
    if legend.len() < 2 {
        legend.clear();
    }

    // Layout: y ticks first (they set the left margin), then the plot width, then x ticks.
    // The title row is always reserved so that panels in one grid row line up.
    let top = 30.0;
    let right = if heatmap { 96.0 } else { 18.0 };
    let mut ph = base_plot_height(columns);
    let y_target = |ph: f64| ((ph / 42.0).round() as usize).clamp(3, 10);
    let mut yt = ticks_for(panel.y.scale, yr.0, yr.1, y_target(ph), y_int);
    let y_label_w = yt
        .major
        .iter()
        .map(|(_, l)| l.width_em() * TICK_FONT)
        .fold(0.0f64, f64::max);
    let left = (if panel.y.label.is_empty() { 10.0 } else { 26.0 }) + y_label_w + 8.0;
    let pw = (width - left - right).max(40.0);
    let (mut xr, mut yr) = (xr, yr);
    if panel.equal_aspect {
        ph = pw.min(ph * 1.45).max(ph);
        if panel.x.scale == Scale::Linear && panel.y.scale == Scale::Linear {
            let ux = (xr.1 - xr.0) / pw;
            let uy = (yr.1 - yr.0) / ph;
            let u = ux.max(uy);
            if u.is_finite() && u > 0.0 {
                let (cx, cy) = ((xr.0 + xr.1) / 2.0, (yr.0 + yr.1) / 2.0);
                xr = (cx - u * pw / 2.0, cx + u * pw / 2.0);
                yr = (cy - u * ph / 2.0, cy + u * ph / 2.0);
            }
        }
        yt = ticks_for(panel.y.scale, yr.0, yr.1, y_target(ph), y_int);
    }
    let x_target = ((pw / 85.0).round() as usize).clamp(2, 10);
    // A fitted linear x range ending just short of a tick (0 … 0.9998 s) is widened to it.
    if panel.x.scale == Scale::Linear
        && fixed_range(panel.x.scale, panel.x.range).is_none()
        && !panel.equal_aspect
    {
        let (_, step) = linear_ticks(xr.0, xr.1, x_target, x_int);
        let span = xr.1 - xr.0;
        let lo = (xr.0 / step).floor() * step;
        let hi = (xr.1 / step).ceil() * step;
        if lo.is_finite() && xr.0 - lo <= 0.03 * span {
            xr.0 = lo;
        }
        if hi.is_finite() && hi - xr.1 <= 0.03 * span {
            xr.1 = hi;
        }
    }
    let xt = ticks_for(panel.x.scale, xr.0, xr.1, x_target, x_int);

    let axis_bottom = top + ph;
    let legend_y = axis_bottom + if panel.x.label.is_empty() { 36.0 } else { 58.0 };
    let legend_rows = legend_layout(&legend, left, width - 8.0);
    let legend_h = legend_rows
        .iter()
        .map(|(_, row)| row + 1)
        .max()
        .unwrap_or(0) as f64
        * 18.0;
    let height = if legend_h > 0.0 {
        legend_y + legend_h - 4.0
    } else {
        legend_y - 12.0
    }
    .ceil();
    let lay = Layout {
        width,
        height,
        left,
        top,
        pw,
        ph,
        legend_y,
    };
    let mx = AxisMap {
        scale: panel.x.scale,
        lo: xr.0,
        hi: xr.1,
        p0: left,
        p1: left + pw,
    };
    let my = AxisMap {
        scale: panel.y.scale,
        lo: yr.0,
        hi: yr.1,
        p0: top + ph,
        p1: top,
    };

    // Root element.
    w!(
        out,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" class=\"panel\" width=\"{}\" height=\"{}\" viewBox=\"0 0 {} {}\" font-family=\"{}\" role=\"img\" aria-label=\"{}\">",
        lay.width,
        lay.height,
        lay.width,
        lay.height,
        FONT_STACK,
        escape(if panel.title.is_empty() { "plot" } else { &panel.title })
    );
    w!(
        out,
        "<defs><clipPath id=\"clip-{uid}\"><rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\"/></clipPath></defs>",
        lay.left,
        lay.top,
        lay.pw,
        lay.ph
    );
    if !panel.title.is_empty() {
        w!(
            out,
            "<text x=\"{}\" y=\"{}\" font-size=\"{TITLE_FONT}\" font-weight=\"600\" fill=\"{TEXT_COLOR}\">{}</text>",
            lay.left,
            lay.top - 10.0,
            escape(&panel.title)
        );
    }
    // Plot background and grid.
    w!(
        out,
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"#fff\"/>",
        lay.left,
        lay.top,
        lay.pw,
        lay.ph
    );
    grid(out, &xt, &yt, &mx, &my);

    // Data.
    w!(out, "<g clip-path=\"url(#clip-{uid})\">");
    spans_svg(out, panel, &mx, &lay);
    match &panel.content {
        PanelContent::Xy(series) => {
            for (s, &c) in series.iter().zip(&colors) {
                series_svg(out, s, c, &mx, &my, lay.pw);
            }
        }
        PanelContent::Heatmap(h) => heatmap_cells(out, panel, h, &mx, &my),
    }
    w!(out, "</g>");
    if !has_data {
        w!(
            out,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"14\" fill=\"#8c959f\">no data</text>",
            lay.left + lay.pw / 2.0,
            lay.top + lay.ph / 2.0 + 5.0
        );
    }
    // Frame, ticks, labels.
    w!(
        out,
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"{FRAME}\"/>",
        lay.left,
        lay.top,
        lay.pw,
        lay.ph
    );
    axes_labels(out, panel, &xt, &yt, &mx, &my, &lay);
    if let PanelContent::Heatmap(h) = &panel.content {
        colorbar(out, h, uid, &lay);
    }
    legend_svg(out, &legend, &legend_rows, &lay);
    w!(out, "</svg>");
}

/// Axis-space ranges of a heatmap panel from its cell edges.
fn heatmap_ranges(panel: &Panel, h: &Heatmap) -> ((f64, f64), (f64, f64), bool) {
    let ex_edges = cell_edges(panel.x.scale, &h.x);
    let ey_edges = cell_edges(panel.y.scale, &h.y);
    let mut ex = Extent::new();
    let mut ey = Extent::new();
    for (lo, hi) in ex_edges.iter().flatten() {
        ex.add(*lo);
        ex.add(*hi);
    }
    for (lo, hi) in ey_edges.iter().flatten() {
        ey.add(*lo);
        ey.add(*hi);
    }
    let has = h.z.iter().enumerate().any(|(j, row)| {
        ey_edges.get(j).copied().flatten().is_some()
            && row
                .iter()
                .enumerate()
                .any(|(i, v)| v.is_finite() && ex_edges.get(i).copied().flatten().is_some())
    });
    let pick = |axis: &Axis, e: Extent| match (fixed_range(axis.scale, axis.range), e.get()) {
        (Some(r), _) => r,
        (None, Some((lo, hi))) => sane_range(axis.scale, lo, hi),
        (None, None) => sane_range(axis.scale, f64::NAN, f64::NAN),
    };
    (pick(&panel.x, ex), pick(&panel.y, ey), has)
}

/// Light gridlines (minor and major) of both axes.
fn grid(out: &mut String, xt: &Ticks, yt: &Ticks, mx: &AxisMap, my: &AxisMap) {
    let (t, b) = (my.p1, my.p0);
    let (l, r) = (mx.p0, mx.p1);
    let mut minor = String::new();
    let mut major = String::new();
    for &u in &xt.minor {
        if mx.contains_u(u) {
            let x = mx.pu(u).round() + 0.5;
            w!(minor, "M{x} {t}V{b}");
        }
    }
    for &u in &yt.minor {
        if my.contains_u(u) {
            let y = my.pu(u).round() + 0.5;
            w!(minor, "M{l} {y}H{r}");
        }
    }
    for (u, _) in &xt.major {
        if mx.contains_u(*u) {
            let x = mx.pu(*u).round() + 0.5;
            w!(major, "M{x} {t}V{b}");
        }
    }
    for (u, _) in &yt.major {
        if my.contains_u(*u) {
            let y = my.pu(*u).round() + 0.5;
            w!(major, "M{l} {y}H{r}");
        }
    }
    if !minor.is_empty() {
        w!(
            out,
            "<path d=\"{minor}\" stroke=\"{GRID_MINOR}\" fill=\"none\" shape-rendering=\"crispEdges\"/>"
        );
    }
    if !major.is_empty() {
        w!(
            out,
            "<path d=\"{major}\" stroke=\"{GRID_MAJOR}\" fill=\"none\" shape-rendering=\"crispEdges\"/>"
        );
    }
}

/// A tick label as SVG text content (`10^k` with a superscript).
fn tick_text(out: &mut String, x: f64, y: f64, anchor: &str, label: &TickLabel) {
    w!(
        out,
        "<text x=\"{x:.1}\" y=\"{y:.1}\" text-anchor=\"{anchor}\">"
    );
    match label {
        TickLabel::Plain(s) => {
            w!(out, "{}", escape(s));
        }
        TickLabel::Pow10(k) => {
            w!(
                out,
                "10<tspan dy=\"-0.45em\" font-size=\"0.75em\">{k}</tspan>"
            );
        }
    }
    w!(out, "</text>");
}

/// Tick marks, tick labels and axis labels.
fn axes_labels(
    out: &mut String,
    panel: &Panel,
    xt: &Ticks,
    yt: &Ticks,
    mx: &AxisMap,
    my: &AxisMap,
    lay: &Layout,
) {
    let bottom = lay.top + lay.ph;
    let mut marks = String::new();
    for (u, _) in &xt.major {
        if mx.contains_u(*u) {
            let x = mx.pu(*u).round() + 0.5;
            w!(marks, "M{x} {bottom}v4");
        }
    }
    for (u, _) in &yt.major {
        if my.contains_u(*u) {
            let y = my.pu(*u).round() + 0.5;
            w!(marks, "M{} {y}h-4", lay.left);
        }
    }
    if !marks.is_empty() {
        w!(
            out,
            "<path d=\"{marks}\" stroke=\"{FRAME}\" fill=\"none\" shape-rendering=\"crispEdges\"/>"
        );
    }
    w!(
        out,
        "<g font-size=\"{TICK_FONT}\" fill=\"{MUTED}\" class=\"ticks\">"
    );
    for (u, label) in &xt.major {
        if mx.contains_u(*u) {
            tick_text(out, mx.pu(*u), bottom + 17.0, "middle", label);
        }
    }
    for (u, label) in &yt.major {
        if my.contains_u(*u) {
            tick_text(out, lay.left - 7.0, my.pu(*u) + 4.0, "end", label);
        }
    }
    w!(out, "</g>");
    if !panel.x.label.is_empty() {
        w!(
            out,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" font-size=\"{LABEL_FONT}\" fill=\"{TEXT_COLOR}\">{}</text>",
            lay.left + lay.pw / 2.0,
            bottom + 36.0,
            escape(&panel.x.label)
        );
    }
    if !panel.y.label.is_empty() {
        let (x, y) = (14.0, lay.top + lay.ph / 2.0);
        w!(
            out,
            "<text x=\"{x}\" y=\"{y:.1}\" transform=\"rotate(-90 {x} {y:.1})\" text-anchor=\"middle\" font-size=\"{LABEL_FONT}\" fill=\"{TEXT_COLOR}\">{}</text>",
            escape(&panel.y.label)
        );
    }
}

/// Shaded vertical spans with their labels.
fn spans_svg(out: &mut String, panel: &Panel, mx: &AxisMap, lay: &Layout) {
    for span in &panel.spans {
        let (Some(a), Some(b)) = (mx.px(span.x0), mx.px(span.x1)) else {
            continue;
        };
        let (x0, x1) = (
            a.min(b).max(lay.left - 1.0),
            a.max(b).min(lay.left + lay.pw + 1.0),
        );
        if x1 <= x0 {
            continue;
        }
        w!(out, "<rect class=\"span\" x=\"");
        num(out, x0);
        w!(out, "\" y=\"{}\" width=\"", lay.top);
        num(out, (x1 - x0).max(1.0));
        w!(
            out,
            "\" height=\"{}\" fill=\"#000\" fill-opacity=\"0.07\">",
            lay.ph
        );
        w!(
            out,
            "<title>{}: {} … {}</title></rect>",
            escape(&span.label),
            format_number(span.x0.min(span.x1)),
            format_number(span.x0.max(span.x1))
        );
        if !span.label.is_empty() {
            // left-aligned inside the span's left edge; when that would run past the plot's
            // right edge (about 6 px per character at 10 px), right-aligned so it stays inside
            let width = 6.0 * span.label.chars().count() as f64;
            let right = lay.left + lay.pw - 3.0;
            let (x, anchor) = if x0 + 4.0 + width <= right {
                (x0 + 4.0, "start")
            } else {
                ((x1 - 4.0).min(right).max(lay.left + width), "end")
            };
            w!(
                out,
                "<text x=\"{:.1}\" y=\"{}\" font-size=\"10\" fill=\"{MUTED}\" text-anchor=\"{anchor}\">{}</text>",
                x,
                lay.top + 13.0,
                escape(&span.label)
            );
        }
    }
}

/// Appends a polyline path (`M x y L x y x y …`) for one run of pixel points.
fn path_run(d: &mut String, pts: &[(f64, f64)]) {
    let mut last: Option<(i64, i64)> = None;
    let mut n = 0usize;
    for &(x, y) in pts {
        let key = ((x * 10.0).round() as i64, (y * 10.0).round() as i64);
        if last == Some(key) && n > 0 {
            continue;
        }
        last = Some(key);
        d.push(match n {
            0 => 'M',
            1 => 'L',
            _ => ' ',
        });
        num(d, x);
        d.push(' ');
        num(d, y);
        n += 1;
    }
    if n == 1 {
        // A lone point: a zero-length segment with round caps shows it as a dot.
        d.push_str("h0");
    }
}

/// Marker path data for one point.
fn marker_path(d: &mut String, marker: Marker, x: f64, y: f64) {
    match marker {
        Marker::Dot | Marker::Circle => {
            let r = if marker == Marker::Dot { 3.0 } else { 3.6 };
            d.push('M');
            num(d, x - r);
            d.push(' ');
            num(d, y);
            w!(
                d,
                "a{r} {r} 0 1 0 {} 0a{r} {r} 0 1 0 -{} 0z",
                2.0 * r,
                2.0 * r
            );
        }
        Marker::Cross => {
            let r = 3.6;
            d.push('M');
            num(d, x - r);
            d.push(' ');
            num(d, y - r);
            w!(
                d,
                "l{} {}m0 -{}l-{} {}",
                2.0 * r,
                2.0 * r,
                2.0 * r,
                2.0 * r,
                2.0 * r
            );
        }
        Marker::Square => {
            let r = 3.0;
            d.push('M');
            num(d, x - r);
            d.push(' ');
            num(d, y - r);
            w!(d, "h{}v{}h-{}z", 2.0 * r, 2.0 * r, 2.0 * r);
        }
    }
}

/// Presentation attributes of a marker path.
fn marker_attrs(marker: Marker, color: &str) -> String {
    match marker {
        Marker::Dot | Marker::Square => format!("fill=\"{color}\" stroke=\"none\""),
        Marker::Circle => format!("fill=\"none\" stroke=\"{color}\" stroke-width=\"1.5\""),
        Marker::Cross => format!("fill=\"none\" stroke=\"{color}\" stroke-width=\"1.7\""),
    }
}

/// Draws one series.
fn series_svg(out: &mut String, s: &Series, color: &str, mx: &AxisMap, my: &AxisMap, pw: f64) {
    let n = s.x.len().min(s.y.len());
    let (x, y) = (&s.x[..n], &s.y[..n]);
    let decimate = n as f64 > 2.0 * pw;
    let title = if s.name.is_empty() {
        String::new()
    } else {
        format!("<title>{}</title>", escape(&s.name))
    };
    let line = |out: &mut String, dash: &str| {
        let mut d = String::new();
        for run in runs(x, y, mx, my) {
            if decimate {
                path_run(&mut d, &decimate_minmax(&run));
            } else {
                path_run(&mut d, &run);
            }
        }
        if !d.is_empty() {
            w!(
                out,
                "<path d=\"{d}\" fill=\"none\" stroke=\"{color}\" stroke-width=\"1.6\" stroke-linejoin=\"round\" stroke-linecap=\"round\"{dash}>{title}</path>"
            );
        }
    };
    // Markers closer than half a pixel to an already drawn one are drawn once. On a decimated
    // line (LineMarkers) markers go on the kept points only.
    let markers = |out: &mut String, m: Marker, on_line: bool| {
        let mut d = String::new();
        let mut seen: HashSet<(i64, i64)> = HashSet::new();
        let mut put = |d: &mut String, px: f64, py: f64| {
            if seen.insert(((px * 2.0).round() as i64, (py * 2.0).round() as i64)) {
                marker_path(d, m, px, py);
            }
        };
        if on_line && decimate {
            for run in runs(x, y, mx, my) {
                for (px, py) in decimate_minmax(&run) {
                    put(&mut d, px, py);
                }
            }
        } else {
            for (&xv, &yv) in x.iter().zip(y) {
                if let (Some(px), Some(py)) = (mx.px(xv), my.px(yv)) {
                    put(&mut d, px, py);
                }
            }
        }
        if !d.is_empty() {
            w!(
                out,
                "<path d=\"{d}\" {}>{title}</path>",
                marker_attrs(m, color)
            );
        }
    };
    match &s.style {
        Style::Line => line(out, ""),
        Style::Dashed => line(out, " stroke-dasharray=\"6 4\""),
        Style::Markers(m) => markers(out, *m, false),
        Style::LineMarkers(m) => {
            line(out, "");
            markers(out, *m, true);
        }
        Style::Band { lower } => {
            let m = n.min(lower.len());
            let mut d = String::new();
            for run in band_runs(&x[..m], &y[..m], &lower[..m], mx, my) {
                let run = if decimate { decimate_band(&run) } else { run };
                let upper: Vec<(f64, f64)> = run.iter().map(|p| (p.0, p.1)).collect();
                let low: Vec<(f64, f64)> = run.iter().rev().map(|p| (p.0, p.2)).collect();
                path_run(&mut d, &upper);
                if let Some(first) = low.first() {
                    d.push('L');
                    num(&mut d, first.0);
                    d.push(' ');
                    num(&mut d, first.1);
                    for p in &low[1..] {
                        d.push(' ');
                        num(&mut d, p.0);
                        d.push(' ');
                        num(&mut d, p.1);
                    }
                }
                d.push('Z');
            }
            if !d.is_empty() {
                w!(
                    out,
                    "<path d=\"{d}\" fill=\"{color}\" fill-opacity=\"0.22\" stroke=\"{color}\" stroke-opacity=\"0.35\" stroke-width=\"0.6\">{title}</path>"
                );
            }
        }
        Style::Stems => {
            let base = match my.scale {
                Scale::Linear => my.pu(0.0),
                Scale::Log => my.p0,
            }
            .clamp(my.p1.min(my.p0), my.p1.max(my.p0));
            // One stem per pixel column: the extent of all tips in it, from the baseline.
            let mut cols: Vec<(f64, f64, f64)> = Vec::new();
            let mut tips: Vec<(f64, f64)> = Vec::new();
            for (&xv, &yv) in x.iter().zip(y) {
                if let (Some(px), Some(py)) = (mx.px(xv), my.px(yv)) {
                    tips.push((px, py));
                    match cols
                        .iter_mut()
                        .rev()
                        .take(4)
                        .find(|c| c.0.round() == px.round())
                    {
                        Some(c) => {
                            c.1 = c.1.min(py);
                            c.2 = c.2.max(py);
                        }
                        None => cols.push((px, py, py)),
                    }
                }
            }
            let mut d = String::new();
            for (px, lo, hi) in &cols {
                d.push('M');
                num(&mut d, *px);
                d.push(' ');
                num(&mut d, lo.min(base));
                d.push('V');
                num(&mut d, hi.max(base));
            }
            if !d.is_empty() {
                w!(
                    out,
                    "<path d=\"{d}\" fill=\"none\" stroke=\"{color}\" stroke-width=\"1.3\">{title}</path>"
                );
                if tips.len() <= 150 {
                    let mut dots = String::new();
                    for (px, py) in &tips {
                        marker_path(&mut dots, Marker::Dot, *px, *py);
                    }
                    w!(out, "<path d=\"{dots}\" fill=\"{color}\"/>");
                }
            }
        }
    }
}

/// Heatmap cells with hover titles, and the highlighted cell.
fn heatmap_cells(out: &mut String, panel: &Panel, h: &Heatmap, mx: &AxisMap, my: &AxisMap) {
    let xe = cell_edges(panel.x.scale, &h.x);
    let ye = cell_edges(panel.y.scale, &h.y);
    let Some((zlo, zhi)) = z_range(h) else {
        return;
    };
    let zspan = if zhi > zlo { zhi - zlo } else { 1.0 };
    let xl = if panel.x.label.is_empty() {
        "x"
    } else {
        &panel.x.label
    };
    let yl = if panel.y.label.is_empty() {
        "y"
    } else {
        &panel.y.label
    };
    let zl = if h.z_label.is_empty() {
        "z"
    } else {
        &h.z_label
    };
    let (xl, yl, zl) = (escape(xl), escape(yl), escape(zl));
    let rect = |i: usize, j: usize| -> Option<(f64, f64, f64, f64)> {
        let (x0, x1) = xe.get(i).copied().flatten()?;
        let (y0, y1) = ye.get(j).copied().flatten()?;
        let (a, b) = (mx.pu(x0), mx.pu(x1));
        let (c, e) = (my.pu(y0), my.pu(y1));
        Some((a.min(b), c.min(e), (a - b).abs(), (c - e).abs()))
    };
    for (j, row) in h.z.iter().enumerate() {
        for (i, &z) in row.iter().enumerate() {
            if !z.is_finite() {
                continue;
            }
            let Some((x, y, wd, ht)) = rect(i, j) else {
                continue;
            };
            let (r, g, b) = viridis((z - zlo) / zspan);
            // Cells overlap by a hair to avoid anti-aliasing seams.
            w!(out, "<rect x=\"");
            num(out, x);
            out.push_str("\" y=\"");
            num(out, y);
            out.push_str("\" width=\"");
            num(out, wd + 0.3);
            out.push_str("\" height=\"");
            num(out, ht + 0.3);
            w!(
                out,
                "\" fill=\"#{r:02x}{g:02x}{b:02x}\"><title>{xl}: {}\n{yl}: {}\n{zl}: {}</title></rect>",
                format_number(h.x.get(i).copied().unwrap_or(f64::NAN)),
                format_number(h.y.get(j).copied().unwrap_or(f64::NAN)),
                format_number(z)
            );
        }
    }
    if let Some((i, j)) = h.highlight {
        if let Some((x, y, wd, ht)) = rect(i, j) {
            for (stroke, sw) in [("#000", 3.0), ("#fff", 1.2)] {
                w!(out, "<rect class=\"highlight\" x=\"");
                num(out, x + 1.0);
                out.push_str("\" y=\"");
                num(out, y + 1.0);
                out.push_str("\" width=\"");
                num(out, (wd - 2.0).max(1.0));
                out.push_str("\" height=\"");
                num(out, (ht - 2.0).max(1.0));
                w!(
                    out,
                    "\" fill=\"none\" stroke=\"{stroke}\" stroke-width=\"{sw}\"/>"
                );
            }
        }
    }
}

/// Range of the finite heatmap values.
fn z_range(h: &Heatmap) -> Option<(f64, f64)> {
    let mut e = Extent::new();
    for v in h.z.iter().flatten() {
        if v.is_finite() {
            e.add(*v);
        }
    }
    e.get()
}

/// The colour bar right of a heatmap, with ticks and the `z_label`.
fn colorbar(out: &mut String, h: &Heatmap, uid: &str, lay: &Layout) {
    let x = lay.left + lay.pw + 14.0;
    let (top, ht) = (lay.top, lay.ph);
    let Some((zlo, zhi)) = z_range(h) else {
        return;
    };
    let (blo, bhi) = if zhi > zlo {
        (zlo, zhi)
    } else {
        (zlo - 0.5, zhi + 0.5)
    };
    w!(
        out,
        "<defs><linearGradient id=\"cbar-{uid}\" x1=\"0\" y1=\"1\" x2=\"0\" y2=\"0\">"
    );
    for k in 0..=8 {
        let t = k as f64 / 8.0;
        let (r, g, b) = viridis(t);
        w!(
            out,
            "<stop offset=\"{t}\" stop-color=\"#{r:02x}{g:02x}{b:02x}\"/>"
        );
    }
    w!(out, "</linearGradient></defs>");
    w!(
        out,
        "<rect x=\"{x}\" y=\"{top}\" width=\"12\" height=\"{ht}\" fill=\"url(#cbar-{uid})\" stroke=\"{FRAME}\"/>"
    );
    let map = AxisMap {
        scale: Scale::Linear,
        lo: blo,
        hi: bhi,
        p0: top + ht,
        p1: top,
    };
    let target = ((ht / 40.0).round() as usize).clamp(2, 8);
    let ticks = ticks_for(Scale::Linear, blo, bhi, target, false);
    let mut wmax = 0.0f64;
    w!(
        out,
        "<g font-size=\"{TICK_FONT}\" fill=\"{MUTED}\" class=\"ticks\">"
    );
    for (u, label) in &ticks.major {
        if map.contains_u(*u) {
            let y = map.pu(*u);
            tick_text(out, x + 16.0, y + 4.0, "start", label);
            wmax = wmax.max(label.width_em() * TICK_FONT);
        }
    }
    w!(out, "</g>");
    if !h.z_label.is_empty() {
        let lx = (x + 16.0 + wmax + 14.0).min(lay.width - 4.0);
        let ly = top + ht / 2.0;
        w!(
            out,
            "<text x=\"{lx:.1}\" y=\"{ly:.1}\" transform=\"rotate(-90 {lx:.1} {ly:.1})\" text-anchor=\"middle\" font-size=\"{LABEL_FONT}\" fill=\"{TEXT_COLOR}\">{}</text>",
            escape(&h.z_label)
        );
    }
}

/// Legend placement: for each entry its x offset and row.
fn legend_layout(entries: &[LegendEntry], left: f64, right: f64) -> Vec<(f64, usize)> {
    let mut out = Vec::with_capacity(entries.len());
    let (mut x, mut row) = (left, 0usize);
    for e in entries {
        let w = 30.0 + text_width_em(e.name) * LEGEND_FONT + 18.0;
        if x > left && x + w > right {
            x = left;
            row += 1;
        }
        out.push((x, row));
        x += w;
    }
    out
}

/// Draws the legend below the axes.
fn legend_svg(out: &mut String, entries: &[LegendEntry], places: &[(f64, usize)], lay: &Layout) {
    if entries.is_empty() {
        return;
    }
    w!(
        out,
        "<g class=\"legend\" font-size=\"{LEGEND_FONT}\" fill=\"{TEXT_COLOR}\">"
    );
    for (e, &(x, row)) in entries.iter().zip(places) {
        let y = lay.legend_y + row as f64 * 18.0;
        let c = e.color;
        let (x0, x1, cx) = (x, x + 24.0, x + 12.0);
        match e.style {
            Style::Line => {
                w!(
                    out,
                    "<path d=\"M{x0} {y}H{x1}\" stroke=\"{c}\" stroke-width=\"2\"/>"
                );
            }
            Style::Dashed => {
                w!(
                    out,
                    "<path d=\"M{x0} {y}H{x1}\" stroke=\"{c}\" stroke-width=\"2\" stroke-dasharray=\"6 4\"/>"
                );
            }
            Style::Markers(m) => {
                let mut d = String::new();
                marker_path(&mut d, *m, cx, y);
                w!(out, "<path d=\"{d}\" {}/>", marker_attrs(*m, c));
            }
            Style::LineMarkers(m) => {
                let mut d = String::new();
                marker_path(&mut d, *m, cx, y);
                w!(
                    out,
                    "<path d=\"M{x0} {y}H{x1}\" stroke=\"{c}\" stroke-width=\"2\"/>"
                );
                w!(out, "<path d=\"{d}\" {}/>", marker_attrs(*m, c));
            }
            Style::Band { .. } => {
                w!(
                    out,
                    "<rect x=\"{x0}\" y=\"{}\" width=\"24\" height=\"10\" fill=\"{c}\" fill-opacity=\"0.22\" stroke=\"{c}\" stroke-opacity=\"0.35\"/>",
                    y - 5.0
                );
            }
            Style::Stems => {
                let mut d = String::new();
                marker_path(&mut d, Marker::Dot, cx, y - 4.0);
                w!(
                    out,
                    "<path d=\"M{cx} {}V{}\" stroke=\"{c}\" stroke-width=\"1.5\"/><path d=\"{d}\" fill=\"{c}\"/>",
                    y - 4.0,
                    y + 6.0
                );
            }
        }
        w!(
            out,
            "<text x=\"{}\" y=\"{}\">{}</text>",
            x1 + 6.0,
            y + 4.0,
            escape(e.name)
        );
    }
    w!(out, "</g>");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn number_writer() {
        let mut s = String::new();
        num(&mut s, 12.0);
        s.push(',');
        num(&mut s, 12.04);
        s.push(',');
        num(&mut s, -3.26);
        s.push(',');
        num(&mut s, -0.01);
        assert_eq!(s, "12,12,-3.3,0");
    }

    #[test]
    fn colors_skip_explicit_indices() {
        let mk = |color| Series {
            name: String::new(),
            x: vec![],
            y: vec![],
            style: Style::Line,
            color,
        };
        let c = series_colors(&[mk(Some(0)), mk(None), mk(None), mk(Some(9))]);
        assert_eq!(c, [PALETTE[0], PALETTE[2], PALETTE[3], PALETTE[1]]);
    }

    /// A span label that would run past the plot's right edge is right-aligned inside it (the
    /// amplitude study's "recommended" label was cut at the edge); one with room stays
    /// left-aligned at the span.
    #[test]
    fn span_labels_stay_inside_the_plot() {
        use crate::report::{Axis, PanelContent, Span};
        let panel = |x0: f64| Panel {
            title: String::new(),
            x: Axis {
                label: "x".into(),
                scale: crate::report::Scale::Linear,
                range: Some((0.0, 16.0)),
            },
            y: Axis {
                label: "y".into(),
                scale: crate::report::Scale::Linear,
                range: Some((0.0, 1.0)),
            },
            content: PanelContent::Xy(vec![Series {
                name: "a".into(),
                x: vec![0.0, 16.0],
                y: vec![0.0, 1.0],
                style: Style::Line,
                color: None,
            }]),
            spans: vec![Span {
                label: "recommended".into(),
                x0,
                x1: x0 + 1.0,
            }],
            equal_aspect: false,
        };
        let text_of = |svg: &str| {
            let i = svg.find(">recommended<").expect("label drawn");
            let start = svg[..i].rfind("<text").expect("text element");
            svg[start..i].to_string()
        };
        let mut near_edge = String::new();
        panel_svg(&panel(14.5), 3, "t1", &mut near_edge);
        assert!(
            text_of(&near_edge).contains("text-anchor=\"end\""),
            "{}",
            text_of(&near_edge)
        );
        let mut roomy = String::new();
        panel_svg(&panel(2.0), 3, "t2", &mut roomy);
        assert!(
            text_of(&roomy).contains("text-anchor=\"start\""),
            "{}",
            text_of(&roomy)
        );
    }

    #[test]
    fn viridis_ends() {
        assert_eq!(viridis(0.0), (68, 1, 84));
        assert_eq!(viridis(1.0), (253, 231, 37));
        assert_eq!(viridis(f64::NAN), (68, 1, 84));
    }

    #[test]
    fn cell_edges_are_midpoints() {
        let e = cell_edges(Scale::Linear, &[1.0, 2.0, 4.0]);
        assert_eq!(e, [Some((0.5, 1.5)), Some((1.5, 3.0)), Some((3.0, 5.0))]);
        let e = cell_edges(Scale::Log, &[0.0, 10.0]);
        assert_eq!(e, [None, Some((0.5, 1.5))]);
    }
}
