//! CSV export of figure data and tables (long format, full precision).
//!
//! Figure CSV columns depend on the kinds of panels in the figure:
//!
//! | panels            | header                              |
//! |-------------------|-------------------------------------|
//! | only x-y (or none)| `panel,series,x,y,lower`            |
//! | only heatmaps     | `panel,x,y,z`                       |
//! | both              | `panel,series,x,y,z,lower`          |
//!
//! `panel` is the 0-based index into [`Figure::panels`]. x-y rows leave `z` empty and fill
//! `lower` only for [`Style::Band`] series; heatmap rows leave `series` and `lower` empty and
//! list every cell (`y` outer, `x` inner), missing cells as `NaN`. Numbers are written so that
//! they parse back to the identical `f64` (shortest round-trip form; `NaN`, `inf`, `-inf`).

use super::{Figure, PanelContent, Style, Table};

/// Formats an `f64` so that `str::parse::<f64>` gives back exactly the same value: plain
/// notation for ordinary magnitudes, exponent notation (`1.5e-9`) for very small or large ones.
pub(crate) fn fmt_f64(v: f64) -> String {
    let a = v.abs();
    if !v.is_finite() || a == 0.0 || (1e-5..1e16).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Writes records to a CSV string; a writer into memory cannot fail, so errors only stop
/// writing.
fn write_csv(records: impl Iterator<Item = Vec<String>>) -> String {
    let mut w = csv::WriterBuilder::new()
        .flexible(true)
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    for r in records {
        if w.write_record(&r).is_err() {
            break;
        }
    }
    match w.into_inner() {
        Ok(bytes) => String::from_utf8(bytes).unwrap_or_default(),
        Err(_) => String::new(),
    }
}

/// Layout of a figure CSV.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Xy,
    Heatmap,
    Mixed,
}

/// The figure's data as CSV (see the module documentation for the columns).
pub(crate) fn figure_csv(f: &Figure) -> String {
    let has_xy = f
        .panels
        .iter()
        .any(|p| matches!(p.content, PanelContent::Xy(_)));
    let has_heat = f
        .panels
        .iter()
        .any(|p| matches!(p.content, PanelContent::Heatmap(_)));
    let kind = match (has_xy, has_heat) {
        (true, true) => Kind::Mixed,
        (false, true) => Kind::Heatmap,
        _ => Kind::Xy,
    };
    let header: Vec<String> = match kind {
        Kind::Xy => vec!["panel", "series", "x", "y", "lower"],
        Kind::Heatmap => vec!["panel", "x", "y", "z"],
        Kind::Mixed => vec!["panel", "series", "x", "y", "z", "lower"],
    }
    .into_iter()
    .map(String::from)
    .collect();
    let mut rows: Vec<Vec<String>> = vec![header];
    for (pi, p) in f.panels.iter().enumerate() {
        let panel = pi.to_string();
        match &p.content {
            PanelContent::Xy(series) => {
                for s in series {
                    let lower: Option<&[f64]> = match &s.style {
                        Style::Band { lower } => Some(lower),
                        _ => None,
                    };
                    for (i, (&x, &y)) in s.x.iter().zip(&s.y).enumerate() {
                        let l = lower
                            .and_then(|l| l.get(i))
                            .map(|&v| fmt_f64(v))
                            .unwrap_or_default();
                        let mut r = vec![panel.clone(), s.name.clone(), fmt_f64(x), fmt_f64(y)];
                        if kind == Kind::Mixed {
                            r.push(String::new());
                        }
                        r.push(l);
                        rows.push(r);
                    }
                }
            }
            PanelContent::Heatmap(h) => {
                for (j, &y) in h.y.iter().enumerate() {
                    for (i, &x) in h.x.iter().enumerate() {
                        let z =
                            h.z.get(j)
                                .and_then(|r| r.get(i))
                                .copied()
                                .unwrap_or(f64::NAN);
                        let r = if kind == Kind::Mixed {
                            vec![
                                panel.clone(),
                                String::new(),
                                fmt_f64(x),
                                fmt_f64(y),
                                fmt_f64(z),
                                String::new(),
                            ]
                        } else {
                            vec![panel.clone(), fmt_f64(x), fmt_f64(y), fmt_f64(z)]
                        };
                        rows.push(r);
                    }
                }
            }
        }
    }
    write_csv(rows.into_iter())
}

/// The table as CSV: the header, then the rows, quoted where needed.
pub(crate) fn table_csv(t: &Table) -> String {
    let head = (!t.header.is_empty()).then(|| t.header.clone());
    write_csv(head.into_iter().chain(t.rows.iter().cloned()))
}

#[cfg(test)]
mod tests {
    use super::super::{Axis, Heatmap, Marker, Panel, Scale, Series};
    use super::*;

    fn axis() -> Axis {
        Axis {
            label: String::new(),
            scale: Scale::Linear,
            range: None,
        }
    }

    fn xy_panel(series: Vec<Series>) -> Panel {
        Panel {
            title: String::new(),
            x: axis(),
            y: axis(),
            content: PanelContent::Xy(series),
            spans: vec![],
            equal_aspect: false,
        }
    }

    fn read(csv_text: &str) -> (Vec<String>, Vec<Vec<String>>) {
        let mut r = csv::ReaderBuilder::new()
            .flexible(true)
            .from_reader(csv_text.as_bytes());
        let header = r
            .headers()
            .expect("header")
            .iter()
            .map(String::from)
            .collect();
        let rows = r
            .records()
            .map(|rec| rec.expect("record").iter().map(String::from).collect())
            .collect();
        (header, rows)
    }

    fn same(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    #[test]
    fn xy_round_trip_is_bit_exact() {
        let x: Vec<f64> = (0..200)
            .map(|i| 0.1 * i as f64 + 1e-13 * i as f64)
            .collect();
        let mut y: Vec<f64> = x.iter().map(|v| (v * 1.7).sin() * 1e-7 + v.exp()).collect();
        y[3] = f64::NAN;
        y[4] = f64::INFINITY;
        y[5] = -f64::INFINITY;
        y[6] = 1e300;
        y[7] = -2.2250738585072014e-308;
        y[8] = 5e-324;
        y[9] = -0.0;
        let lower: Vec<f64> = y.iter().map(|v| v * 0.5 - 1.0 / 3.0).collect();
        let fig = Figure {
            id: "t".into(),
            panels: vec![xy_panel(vec![
                Series {
                    name: "curve, \"quoted\"".into(),
                    x: x.clone(),
                    y: y.clone(),
                    style: Style::Line,
                    color: None,
                },
                Series {
                    name: "band".into(),
                    x: x.clone(),
                    y: y.clone(),
                    style: Style::Band {
                        lower: lower.clone(),
                    },
                    color: None,
                },
            ])],
            ..Default::default()
        };
        let text = fig.to_csv();
        let (header, rows) = read(&text);
        assert_eq!(header, ["panel", "series", "x", "y", "lower"]);
        assert_eq!(rows.len(), 400);
        for (k, r) in rows.iter().enumerate() {
            let i = k % 200;
            assert_eq!(r[0], "0");
            let px: f64 = r[2].parse().expect("x");
            let py: f64 = r[3].parse().expect("y");
            assert!(same(px, x[i]), "{} vs {}", r[2], x[i]);
            assert!(same(py, y[i]), "{} vs {}", r[3], y[i]);
            if k < 200 {
                assert_eq!(r[1], "curve, \"quoted\"");
                assert_eq!(r[4], "");
            } else {
                assert_eq!(r[1], "band");
                let pl: f64 = r[4].parse().expect("lower");
                assert!(same(pl, lower[i]));
            }
        }
    }

    #[test]
    fn heatmap_and_mixed_headers() {
        let h = Heatmap {
            x: vec![1.0, 2.0],
            y: vec![0.5],
            z: vec![vec![f64::NAN]],
            z_label: "fit [%]".into(),
            highlight: None,
        };
        let hp = Panel {
            title: String::new(),
            x: axis(),
            y: axis(),
            content: PanelContent::Heatmap(h),
            spans: vec![],
            equal_aspect: false,
        };
        let fig = Figure {
            panels: vec![hp.clone()],
            ..Default::default()
        };
        let (header, rows) = read(&fig.to_csv());
        assert_eq!(header, ["panel", "x", "y", "z"]);
        assert_eq!(rows, [["0", "1", "0.5", "NaN"], ["0", "2", "0.5", "NaN"]]);

        let mixed = Figure {
            panels: vec![
                xy_panel(vec![Series {
                    name: "p".into(),
                    x: vec![1.0],
                    y: vec![2.0],
                    style: Style::Markers(Marker::Cross),
                    color: None,
                }]),
                hp,
            ],
            ..Default::default()
        };
        let (header, rows) = read(&mixed.to_csv());
        assert_eq!(header, ["panel", "series", "x", "y", "z", "lower"]);
        assert_eq!(rows[0], ["0", "p", "1", "2", "", ""]);
        assert_eq!(rows[1], ["1", "", "1", "0.5", "NaN", ""]);
    }

    #[test]
    fn empty_figure_csv_has_header_only() {
        let (header, rows) = read(&Figure::default().to_csv());
        assert_eq!(header, ["panel", "series", "x", "y", "lower"]);
        assert!(rows.is_empty());
    }

    #[test]
    fn table_csv_quotes() {
        let t = Table {
            id: "t".into(),
            caption: "c".into(),
            header: vec!["model".into(), "fit [%]".into()],
            rows: vec![
                vec!["n=4, \"best\"".into(), "97.1".into()],
                vec!["line\nbreak".into(), "12".into()],
            ],
            highlight: Some(0),
        };
        let text = t.to_csv();
        assert!(text.starts_with("model,fit [%]\n\"n=4, \"\"best\"\"\",97.1\n"));
        let (header, rows) = read(&text);
        assert_eq!(header, t.header);
        assert_eq!(rows, t.rows);
    }
}
