//! The HTML report: one self-contained offline file (inline SVG, no network, no JavaScript),
//! built from a plain data model ([`Report`] → [`Section`] → [`Block`]) so that the workflow only
//! describes *what* to show. Every [`Figure`] can also be written as CSV ([`Figure::to_csv`]),
//! every [`Table`] too ([`Table::to_csv`]).
//!
//! Figures are drawn by a small built-in SVG plotter (one `<svg>` per [`Panel`], text as SVG
//! `<text>`, so no fonts are needed at render time). Long series are decimated for drawing
//! (min/max per pixel column, so peaks survive); the CSV keeps every point.
//! [`browser_check`] loads a written report in headless Chromium to check that it renders.
//! See `docs/report.md` for what a report contains and the CSV formats.

mod browser;
mod csv_out;
mod demo;
mod geom;
mod html;
mod svg;
mod ticks;

pub use browser::{browser_check, BrowserCheck, BrowserCounts, CHROMIUM, MIN_SCREENSHOT_BYTES};
pub use demo::demo_report;

/// A whole report.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// Page title (also the `<title>`).
    pub title: String,
    /// One line under the title (data source, date, ambid version).
    pub subtitle: String,
    /// Sections in order; each gets an entry in the table of contents.
    pub sections: Vec<Section>,
}

/// One section (a workflow step).
#[derive(Debug, Clone, Default)]
pub struct Section {
    /// Anchor id (`[a-z0-9-]+`).
    pub id: String,
    /// Heading.
    pub title: String,
    /// Content in order.
    pub blocks: Vec<Block>,
}

/// A piece of section content.
#[derive(Debug, Clone)]
pub enum Block {
    /// A paragraph of plain text (escaped when rendered).
    Text(String),
    /// A highlighted note (for example "step skipped: open-loop data").
    Note {
        /// How the note is highlighted.
        kind: NoteKind,
        /// The note's text (escaped when rendered).
        text: String,
    },
    /// A figure.
    Figure(Figure),
    /// A table.
    Table(Table),
}

/// How a note is highlighted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoteKind {
    /// Neutral information.
    Info,
    /// Something the reader should look at (a bar missed, saturation, a skipped step).
    Warning,
    /// A verdict that passed.
    Pass,
    /// A verdict that failed.
    Fail,
}

/// A table of preformatted cells.
#[derive(Debug, Clone, Default)]
pub struct Table {
    /// File-safe id (`[a-z0-9_-]+`); also used to write the table as `<id>.csv`.
    pub id: String,
    /// Caption: what the table shows and how it was computed.
    pub caption: String,
    /// Column headings (with units).
    pub header: Vec<String>,
    /// Rows of cells; each row has `header.len()` cells.
    pub rows: Vec<Vec<String>>,
    /// Row to highlight (for example the chosen model), if any.
    pub highlight: Option<usize>,
}

/// A figure: one or more panels, a title and a caption.
#[derive(Debug, Clone, Default)]
pub struct Figure {
    /// File-safe id (`[a-z0-9_-]+`); the data are written as `<id>.csv`.
    pub id: String,
    /// Title shown above the figure.
    pub title: String,
    /// Caption: what was computed and with which settings.
    pub caption: String,
    /// Panels, laid out in a grid of `columns` columns (row-major).
    pub panels: Vec<Panel>,
    /// Number of panel columns (0 or 1: one panel per row).
    pub columns: usize,
}

/// One set of axes.
#[derive(Debug, Clone)]
pub struct Panel {
    /// Panel title (may be empty).
    pub title: String,
    /// Horizontal axis.
    pub x: Axis,
    /// Vertical axis.
    pub y: Axis,
    /// What is drawn.
    pub content: PanelContent,
    /// Shaded vertical spans (for example the recommended amplitude range or a frequency band).
    pub spans: Vec<Span>,
    /// Equal scaling of x and y (pole-zero maps).
    pub equal_aspect: bool,
}

/// What a panel draws.
#[derive(Debug, Clone)]
pub enum PanelContent {
    /// Curves, markers and bands.
    Xy(Vec<Series>),
    /// A colour map over a grid.
    Heatmap(Heatmap),
}

/// An axis.
#[derive(Debug, Clone)]
pub struct Axis {
    /// Label with unit, e.g. `"frequency [Hz]"`.
    pub label: String,
    /// Linear or logarithmic.
    pub scale: Scale,
    /// Fixed range; `None` fits the data (non-finite values and, on a log axis, values ≤ 0 are skipped).
    pub range: Option<(f64, f64)>,
}

/// Axis scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Linear.
    Linear,
    /// Base-10 logarithmic.
    Log,
}

/// One data series in an [`PanelContent::Xy`] panel.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend entry (and CSV series name).
    pub name: String,
    /// Abscissae.
    pub x: Vec<f64>,
    /// Ordinates (for a band: the upper edge).
    pub y: Vec<f64>,
    /// How it is drawn.
    pub style: Style,
    /// Palette index (series with the same index share a colour); `None` takes the next colour.
    pub color: Option<usize>,
}

/// How a series is drawn.
#[derive(Debug, Clone, PartialEq)]
pub enum Style {
    /// Solid line.
    Line,
    /// Dashed line.
    Dashed,
    /// Markers only.
    Markers(Marker),
    /// Line with markers.
    LineMarkers(Marker),
    /// A filled band between `lower` and the series' `y` (same length as `x`).
    Band {
        /// Lower edge.
        lower: Vec<f64>,
    },
    /// Vertical stems from 0 (correlation lags).
    Stems,
}

/// Marker shapes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Marker {
    /// Filled circle.
    Dot,
    /// Open circle (zeros).
    Circle,
    /// Cross `×` (poles).
    Cross,
    /// Square.
    Square,
}

/// A shaded vertical span.
#[derive(Debug, Clone)]
pub struct Span {
    /// Label (legend / tooltip).
    pub label: String,
    /// Start on the x axis.
    pub x0: f64,
    /// End on the x axis.
    pub x1: f64,
}

/// A colour map: `z[j][i]` is the value at (`x[i]`, `y[j]`).
#[derive(Debug, Clone)]
pub struct Heatmap {
    /// Column centres.
    pub x: Vec<f64>,
    /// Row centres.
    pub y: Vec<f64>,
    /// Values, one row per `y`; non-finite cells are drawn blank.
    pub z: Vec<Vec<f64>>,
    /// Colour-bar label with unit.
    pub z_label: String,
    /// Mark this cell (i, j) (for example the chosen order).
    pub highlight: Option<(usize, usize)>,
}

/// Formats a number the way the report prints it (4 significant digits, plain or scientific);
/// `summary.json` values are checked against the report through this function.
pub fn format_number(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if (1e-3..1e5).contains(&a) {
        let digits = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        let s = format!("{v:.digits$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{v:.3e}")
    }
}

impl Report {
    /// The first x–y series whose name starts with `prefix` in the figures of the section `id`
    /// (tests and rig sweeps read a figure's numbers back this way).
    ///
    /// ```
    /// use ambid::report::{Axis, Block, Figure, Panel, PanelContent, Report, Scale, Section,
    ///     Series, Style};
    /// let axis = || Axis { label: String::new(), scale: Scale::Linear, range: None };
    /// let s = Series { name: "(d) spread".into(), x: vec![1.0], y: vec![2.0], style: Style::Line,
    ///     color: None };
    /// let fig = Figure { id: "f".into(), title: String::new(), caption: String::new(), columns: 1,
    ///     panels: vec![Panel { title: String::new(), x: axis(), y: axis(),
    ///         content: PanelContent::Xy(vec![s]), spans: vec![], equal_aspect: false }] };
    /// let r = Report { title: String::new(), subtitle: String::new(), sections: vec![Section {
    ///     id: "u".into(), blocks: vec![Block::Figure(fig)], ..Section::default() }] };
    /// assert_eq!(r.series("u", "(d)").unwrap().y, [2.0]);
    /// assert!(r.series("u", "(c)").is_none());
    /// ```
    pub fn series(&self, id: &str, prefix: &str) -> Option<&Series> {
        self.sections
            .iter()
            .filter(|s| s.id == id)
            .flat_map(|s| &s.blocks)
            .filter_map(|b| match b {
                Block::Figure(f) => Some(f),
                _ => None,
            })
            .flat_map(|f| &f.panels)
            .filter_map(|p| match &p.content {
                PanelContent::Xy(s) => Some(s),
                _ => None,
            })
            .flatten()
            .find(|s| s.name.starts_with(prefix))
    }

    /// Renders the report as one self-contained HTML5 document: inline CSS, a header, a table of
    /// contents, and each section's blocks; figures as inline SVG. No JavaScript and no
    /// external resources, so the file opens offline. All text is HTML-escaped.
    ///
    /// ```
    /// use ambid::report::{Axis, Block, Figure, Panel, PanelContent, Report, Scale, Section,
    ///     Series, Style};
    ///
    /// let f: Vec<f64> = (1..=100).map(|k| k as f64).collect();
    /// let mag: Vec<f64> = f.iter().map(|f| 1.0 / (1.0 + (f / 20.0).powi(2))).collect();
    /// let report = Report {
    ///     title: "Identification <demo>".into(),
    ///     subtitle: "synthetic data".into(),
    ///     sections: vec![Section {
    ///         id: "frf".into(),
    ///         title: "Frequency response".into(),
    ///         blocks: vec![
    ///             Block::Text("A first-order low-pass.".into()),
    ///             Block::Figure(Figure {
    ///                 id: "frf-mag".into(),
    ///                 title: "Magnitude".into(),
    ///                 caption: "|G(jω)| of the model.".into(),
    ///                 panels: vec![Panel {
    ///                     title: String::new(),
    ///                     x: Axis { label: "frequency [Hz]".into(), scale: Scale::Log, range: None },
    ///                     y: Axis { label: "magnitude [-]".into(), scale: Scale::Log, range: None },
    ///                     content: PanelContent::Xy(vec![Series {
    ///                         name: "model".into(),
    ///                         x: f.clone(),
    ///                         y: mag,
    ///                         style: Style::Line,
    ///                         color: None,
    ///                     }]),
    ///                     spans: vec![],
    ///                     equal_aspect: false,
    ///                 }],
    ///                 columns: 1,
    ///             }),
    ///         ],
    ///     }],
    /// };
    /// let html = report.to_html();
    /// assert!(html.starts_with("<!DOCTYPE html>"));
    /// assert!(html.contains("Identification &lt;demo&gt;"));
    /// assert!(html.contains("<svg") && html.contains("<figcaption>"));
    /// assert!(!html.contains("<script"));
    /// ```
    pub fn to_html(&self) -> String {
        html::render(self)
    }
}

impl Figure {
    /// The figure's data as CSV, long format, every point at full precision (numbers parse back
    /// to the identical `f64`). Columns: `panel,series,x,y,lower` when all panels are x-y
    /// (`lower` filled only for [`Style::Band`]), `panel,x,y,z` when all are heatmaps, and the
    /// union `panel,series,x,y,z,lower` when the figure mixes both (unused cells empty).
    /// `panel` is the 0-based index into [`Figure::panels`].
    pub fn to_csv(&self) -> String {
        csv_out::figure_csv(self)
    }
}

impl Table {
    /// The table as CSV: the header row, then the rows, quoted where needed.
    pub fn to_csv(&self) -> String {
        csv_out::table_csv(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn axis(scale: Scale) -> Axis {
        Axis {
            label: "axis".into(),
            scale,
            range: None,
        }
    }

    fn panel(x: Scale, y: Scale, content: PanelContent) -> Panel {
        Panel {
            title: "p".into(),
            x: axis(x),
            y: axis(y),
            content,
            spans: vec![],
            equal_aspect: false,
        }
    }

    fn line(name: &str, x: Vec<f64>, y: Vec<f64>, style: Style) -> Series {
        Series {
            name: name.into(),
            x,
            y,
            style,
            color: None,
        }
    }

    fn one_figure(fig: Figure) -> Report {
        Report {
            title: "t".into(),
            subtitle: String::new(),
            sections: vec![Section {
                id: "s".into(),
                title: "S".into(),
                blocks: vec![Block::Figure(fig)],
            }],
        }
    }

    /// The `d` attribute of every `<path>` with the given stroke colour.
    fn paths_with_stroke<'a>(html: &'a str, color: &str) -> Vec<&'a str> {
        let key = format!("stroke=\"{color}\"");
        html.split("<path d=\"")
            .skip(1)
            .filter(|p| p.split('>').next().is_some_and(|tag| tag.contains(&key)))
            .filter_map(|p| p.split('"').next())
            .collect()
    }

    #[test]
    fn everything_is_escaped() {
        let mut r = one_figure(Figure {
            id: "f\"><script>".into(),
            title: "<script>alert(1)</script>".into(),
            caption: "caption <script>alert('c')</script> & more".into(),
            panels: vec![panel(
                Scale::Linear,
                Scale::Linear,
                PanelContent::Xy(vec![
                    line("<b>a</b>", vec![1.0, 2.0], vec![1.0, 2.0], Style::Line),
                    line("b & c", vec![1.0, 2.0], vec![2.0, 1.0], Style::Dashed),
                ]),
            )],
            columns: 1,
        });
        r.title = "<title>".into();
        r.subtitle = "\"quoted\" 'single'".into();
        r.sections[0].blocks.push(Block::Note {
            kind: NoteKind::Fail,
            text: "<img src=x onerror=alert(1)>".into(),
        });
        r.sections[0].blocks.push(Block::Table(Table {
            id: "t".into(),
            caption: "<script>".into(),
            header: vec!["<th>".into()],
            rows: vec![vec!["</td>".into()]],
            highlight: None,
        }));
        let html = r.to_html();
        assert!(!html.contains("<script"), "unescaped script");
        assert!(!html.contains("<img"), "unescaped img");
        assert!(!html.contains("<b>a</b>"));
        assert!(html
            .contains("<figcaption>caption &lt;script&gt;alert(&#39;c&#39;)&lt;/script&gt; &amp; more</figcaption>"));
        assert!(html.contains("&lt;title&gt;"));
        assert!(html.contains("&quot;quoted&quot;"));
        assert!(html.contains("id=\"fig-f---script-\""));
    }

    #[test]
    fn nan_breaks_lines_and_log_skips_nonpositive() {
        let x: Vec<f64> = (1..=10).map(f64::from).collect();
        let mut y: Vec<f64> = x.clone();
        y[4] = f64::NAN;
        y[7] = 0.0;
        let r = one_figure(Figure {
            id: "f".into(),
            panels: vec![panel(
                Scale::Log,
                Scale::Log,
                PanelContent::Xy(vec![line("s", x, y, Style::Line)]),
            )],
            columns: 1,
            ..Default::default()
        });
        let html = r.to_html();
        assert!(!html.contains("NaN"));
        let d = paths_with_stroke(&html, svg::PALETTE[0]);
        assert_eq!(d.len(), 1, "{d:?}");
        // Three runs: 1..4, 6..7, 9..10.
        assert_eq!(d[0].matches('M').count(), 3, "{}", d[0]);
    }

    #[test]
    fn empty_figures_and_panels_say_no_data() {
        let empty_xy = panel(Scale::Linear, Scale::Log, PanelContent::Xy(vec![]));
        let empty_series = panel(
            Scale::Log,
            Scale::Linear,
            PanelContent::Xy(vec![line("e", vec![], vec![], Style::Stems)]),
        );
        let empty_heat = panel(
            Scale::Linear,
            Scale::Linear,
            PanelContent::Heatmap(Heatmap {
                x: vec![],
                y: vec![],
                z: vec![],
                z_label: "z".into(),
                highlight: Some((3, 3)),
            }),
        );
        let html = one_figure(Figure {
            id: "f".into(),
            panels: vec![empty_xy, empty_series, empty_heat],
            columns: 5,
            ..Default::default()
        })
        .to_html();
        assert_eq!(html.matches(">no data</text>").count(), 3);
        assert_eq!(html.matches("<svg").count(), 3);
        let html = one_figure(Figure::default()).to_html();
        assert_eq!(html.matches(">no data</text>").count(), 1);
        assert!(Report::default().to_html().contains("</html>"));
    }

    #[test]
    fn heatmap_with_nan_cells() {
        let h = Heatmap {
            x: vec![1.0, 2.0, 3.0],
            y: vec![10.0, 20.0],
            z: vec![vec![1.0, f64::NAN, 3.0], vec![f64::INFINITY, 5.0]],
            z_label: "fit [%]".into(),
            highlight: Some((1, 1)),
        };
        let html = one_figure(Figure {
            id: "h".into(),
            panels: vec![panel(
                Scale::Linear,
                Scale::Linear,
                PanelContent::Heatmap(h),
            )],
            columns: 1,
            ..Default::default()
        })
        .to_html();
        // Three finite cells, each with a hover title; the blank ones are not drawn.
        assert_eq!(html.matches("<title>axis: ").count(), 3);
        assert!(html.contains("fit [%]: 5</title>"));
        assert!(!html.contains("NaN") && !html.contains(": inf"));
        assert_eq!(html.matches("class=\"highlight\"").count(), 2);
        assert!(html.contains(">fit [%]</text>"));
    }

    #[test]
    fn spike_survives_decimation_in_html() {
        let n = 20_000;
        let x: Vec<f64> = (0..n).map(f64::from).collect();
        let mut y = vec![0.0; n as usize];
        y[12_345] = 1.0;
        let html = one_figure(Figure {
            id: "s".into(),
            panels: vec![panel(
                Scale::Linear,
                Scale::Linear,
                PanelContent::Xy(vec![line("s", x, y, Style::Line)]),
            )],
            columns: 1,
            ..Default::default()
        })
        .to_html();
        let d = paths_with_stroke(&html, svg::PALETTE[0]);
        assert_eq!(d.len(), 1);
        let ys: Vec<f64> = d[0]
            .split(['M', 'L', ' '])
            .filter(|t| !t.is_empty())
            .skip(1)
            .step_by(2)
            .filter_map(|t| t.parse().ok())
            .collect();
        let (top, bottom) = ys
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        // y = 1 is the top of the data (5 % padding above), y = 0 the bottom.
        assert!(bottom - top > 200.0, "{top} {bottom}");
        assert!(ys.len() < 4 * 900, "{}", ys.len());
    }

    #[test]
    fn hostile_values_do_not_panic() {
        let weird = vec![
            f64::MAX,
            -f64::MAX,
            f64::MIN_POSITIVE,
            5e-324,
            0.0,
            -0.0,
            f64::NAN,
            f64::INFINITY,
            1.0,
        ];
        let styles = [
            Style::Line,
            Style::Dashed,
            Style::Markers(Marker::Cross),
            Style::LineMarkers(Marker::Square),
            Style::Band {
                lower: vec![1.0; 3],
            },
            Style::Stems,
        ];
        let mut panels = Vec::new();
        for sx in [Scale::Linear, Scale::Log] {
            for sy in [Scale::Linear, Scale::Log] {
                for range in [
                    None,
                    Some((5.0, 5.0)),
                    Some((f64::NAN, 1.0)),
                    Some((10.0, -1.0)),
                ] {
                    let series: Vec<Series> = styles
                        .iter()
                        .map(|s| {
                            line(
                                "w",
                                weird.clone(),
                                weird.iter().rev().copied().collect(),
                                s.clone(),
                            )
                        })
                        .collect();
                    let mut p = panel(sx, sy, PanelContent::Xy(series));
                    p.x.range = range;
                    p.y.range = range;
                    p.equal_aspect = range.is_none();
                    p.spans = vec![Span {
                        label: "s".into(),
                        x0: f64::NAN,
                        x1: 1.0,
                    }];
                    panels.push(p);
                }
                panels.push(panel(
                    sx,
                    sy,
                    PanelContent::Heatmap(Heatmap {
                        x: weird.clone(),
                        y: vec![1.0, 1.0, f64::NAN],
                        z: vec![weird.clone(), vec![], vec![1.0]],
                        z_label: String::new(),
                        highlight: Some((usize::MAX, 0)),
                    }),
                ));
            }
        }
        let fig = Figure {
            id: "w".into(),
            panels,
            columns: 3,
            ..Default::default()
        };
        let html = one_figure(fig.clone()).to_html();
        assert!(html.ends_with("</html>\n"));
        assert!(!html.contains("NaN"));
        assert!(!fig.to_csv().is_empty());
    }
}
