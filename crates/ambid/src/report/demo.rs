//! A demonstration report that uses every block kind, series style and axis scale, with the
//! awkward cases (NaN gaps, values ≤ 0 on log axes, empty panels, HTML in captions). Used by the
//! `report_demo` example and the browser test.

use super::{
    Axis, Block, Figure, Heatmap, Marker, NoteKind, Panel, PanelContent, Report, Scale, Section,
    Series, Span, Style, Table,
};
use std::f64::consts::PI;

fn axis(label: &str, scale: Scale) -> Axis {
    Axis {
        label: label.into(),
        scale,
        range: None,
    }
}

fn series(name: &str, x: Vec<f64>, y: Vec<f64>, style: Style, color: Option<usize>) -> Series {
    Series {
        name: name.into(),
        x,
        y,
        style,
        color,
    }
}

fn xy(title: &str, x: Axis, y: Axis, s: Vec<Series>) -> Panel {
    Panel {
        title: title.into(),
        x,
        y,
        content: PanelContent::Xy(s),
        spans: vec![],
        equal_aspect: false,
    }
}

/// Deterministic pseudo-random numbers in [-1, 1) (no dependency on `rand`).
fn noise(n: usize, seed: u64) -> Vec<f64> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        })
        .collect()
}

/// |G| and phase of a lightly damped two-mass rotor model at `f` Hz.
fn plant(f: f64) -> (f64, f64) {
    let s = num_complex::Complex64::new(0.0, 2.0 * PI * f);
    let w1 = 2.0 * PI * 180.0;
    let w2 = 2.0 * PI * 720.0;
    let g = 4.0e4 / (s * s + 0.02 * w1 * s + w1 * w1) * (1.0 + s * s / (w2 * w2))
        / (1.0 + s / (2.0 * PI * 900.0));
    (g.norm(), g.arg().to_degrees())
}

/// The demonstration report (about ten figures, 5000-point series, every feature).
pub fn demo_report() -> Report {
    let n = 5000;
    let f: Vec<f64> = (0..n)
        .map(|k| 10f64.powf(0.0 + 3.3 * k as f64 / (n - 1) as f64))
        .collect();
    let e = noise(n, 7);
    let (mag_model, ph_model): (Vec<f64>, Vec<f64>) = f.iter().map(|&f| plant(f)).unzip();
    let mut mag: Vec<f64> = mag_model
        .iter()
        .zip(&e)
        .map(|(m, e)| m * (1.0 + 0.15 * e))
        .collect();
    // A narrow spike (must survive decimation), a NaN gap and a non-positive value (skipped on
    // the log axis).
    mag[3900] *= 30.0;
    for v in &mut mag[2000..2040] {
        *v = f64::NAN;
    }
    mag[2500] = 0.0;
    let ph: Vec<f64> = ph_model.iter().zip(&e).map(|(p, e)| p + 6.0 * e).collect();
    let upper: Vec<f64> = mag_model.iter().map(|m| m * 1.35).collect();
    let lower: Vec<f64> = mag_model.iter().map(|m| m / 1.35).collect();

    let mut bode_mag = xy(
        "Magnitude",
        axis("frequency [Hz]", Scale::Log),
        axis("|G| [µm/A]", Scale::Log),
        vec![
            series(
                "95 % band",
                f.clone(),
                upper,
                Style::Band { lower },
                Some(0),
            ),
            series("measured FRF", f.clone(), mag, Style::Line, Some(6)),
            series(
                "model (n = 6)",
                f.clone(),
                mag_model,
                Style::Dashed,
                Some(1),
            ),
        ],
    );
    bode_mag.spans = vec![Span {
        label: "excitation band".into(),
        x0: 20.0,
        x1: 1000.0,
    }];
    let mut bode_ph = xy(
        "Phase",
        axis("frequency [Hz]", Scale::Log),
        axis("phase [°]", Scale::Linear),
        vec![
            series("measured FRF", f.clone(), ph, Style::Line, Some(6)),
            series("model (n = 6)", f.clone(), ph_model, Style::Dashed, Some(1)),
        ],
    );
    bode_ph.spans = bode_mag.spans.clone();

    // Time series with a NaN gap, 5000 points.
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 2e-4).collect();
    let en = noise(n, 11);
    let mut y1: Vec<f64> = t
        .iter()
        .zip(&en)
        .map(|(t, e)| 12.0 * (2.0 * PI * 35.0 * t).sin() + 2.0 * e)
        .collect();
    for v in &mut y1[1200..1300] {
        *v = f64::NAN;
    }
    let u1: Vec<f64> = t
        .iter()
        .map(|t| 0.4 * (2.0 * PI * 35.0 * t + 0.6).sin())
        .collect();

    // Correlation with stems and a confidence band.
    let lags: Vec<f64> = (-30..=30).map(|k| k as f64).collect();
    let rc = noise(lags.len(), 3);
    let corr: Vec<f64> = lags
        .iter()
        .zip(&rc)
        .map(|(l, r)| if *l == 0.0 { 1.0 } else { 0.08 * r })
        .collect();
    let conf = 1.96 / (n as f64).sqrt();

    // Markers of every shape.
    let k: Vec<f64> = (1..=12).map(|k| k as f64).collect();
    let fits = |a: f64| -> Vec<f64> { k.iter().map(|k| 100.0 - a / k.powf(1.3)).collect() };

    // Pole-zero map (the workflow adds the unit circle as a line).
    let circle_x: Vec<f64> = (0..=200)
        .map(|i| (2.0 * PI * i as f64 / 200.0).cos())
        .collect();
    let circle_y: Vec<f64> = (0..=200)
        .map(|i| (2.0 * PI * i as f64 / 200.0).sin())
        .collect();
    let poles = [
        (0.95, 0.21),
        (0.95, -0.21),
        (0.62, 0.55),
        (0.62, -0.55),
        (0.3, 0.0),
    ];
    let zeros = [(1.05, 0.0), (-0.4, 0.0), (0.7, 0.69), (0.7, -0.69)];
    let mut pz = xy(
        "Discrete-time model",
        axis("real", Scale::Linear),
        axis("imaginary", Scale::Linear),
        vec![
            series("unit circle", circle_x, circle_y, Style::Line, Some(7)),
            series(
                "poles",
                poles.iter().map(|p| p.0).collect(),
                poles.iter().map(|p| p.1).collect(),
                Style::Markers(Marker::Cross),
                Some(1),
            ),
            series(
                "zeros",
                zeros.iter().map(|p| p.0).collect(),
                zeros.iter().map(|p| p.1).collect(),
                Style::Markers(Marker::Circle),
                Some(0),
            ),
        ],
    );
    pz.equal_aspect = true;

    // Order-selection heatmap with blank (NaN) cells and a highlighted cell.
    let orders: Vec<f64> = (1..=12).map(|n| n as f64).collect();
    let horizons: Vec<f64> = vec![5.0, 10.0, 15.0, 20.0, 30.0, 40.0];
    let z: Vec<Vec<f64>> = horizons
        .iter()
        .map(|&h| {
            orders
                .iter()
                .map(|&n| {
                    if n > h / 2.0 + 3.0 {
                        f64::NAN
                    } else {
                        95.0 - 40.0 / n - 0.1 * (h - 20.0).abs() - 0.3 * (n - 6.0).max(0.0)
                    }
                })
                .collect()
        })
        .collect();
    let heat = Panel {
        title: "Validation fit".into(),
        x: axis("model order n", Scale::Linear),
        y: axis("horizon i", Scale::Linear),
        content: PanelContent::Heatmap(Heatmap {
            x: orders,
            y: horizons,
            z,
            z_label: "fit [%]".into(),
            highlight: Some((5, 3)),
        }),
        spans: vec![],
        equal_aspect: false,
    };
    let freqs: Vec<f64> = (0..40)
        .map(|i| 10f64.powf(1.0 + 2.0 * i as f64 / 39.0))
        .collect();
    let amps: Vec<f64> = vec![0.05, 0.1, 0.2, 0.5, 1.0, 2.0];
    let z2: Vec<Vec<f64>> = amps
        .iter()
        .map(|a| {
            freqs
                .iter()
                .map(|f| (1.0 - (-a * 3.0).exp()) * (1.0 + (f / 200.0f64).ln().abs()).recip())
                .collect()
        })
        .collect();
    let heat_log = Panel {
        title: "Coherence".into(),
        x: axis("frequency [Hz]", Scale::Log),
        y: axis("amplitude [A]", Scale::Log),
        content: PanelContent::Heatmap(Heatmap {
            x: freqs,
            y: amps,
            z: z2,
            z_label: "γ² [-]".into(),
            highlight: None,
        }),
        spans: vec![],
        equal_aspect: false,
    };

    let mut empty_with_span = xy(
        "Only non-finite data",
        axis("x", Scale::Log),
        axis("y", Scale::Log),
        vec![series(
            "nan",
            vec![f64::NAN, 1.0, -2.0],
            vec![1.0, f64::INFINITY, 3.0],
            Style::Line,
            None,
        )],
    );
    empty_with_span.spans = vec![Span {
        label: "a span".into(),
        x0: 2.0,
        x1: 5.0,
    }];

    let table = Table {
        id: "models".into(),
        caption: "Candidate models: validation fit on the held-out data; the chosen model is highlighted. <script>alert('x')</script>".into(),
        header: vec![
            "model".into(),
            "order".into(),
            "fit [%]".into(),
            "max |e| [µm]".into(),
            "stable".into(),
        ],
        rows: vec![
            vec!["ARX".into(), "4".into(), "81.2".into(), "3.1".into(), "yes".into()],
            vec!["subspace".into(), "6".into(), "94.7".into(), "1.02".into(), "yes".into()],
            vec!["PEM, \"refined\"".into(), "6".into(), "95.1".into(), "0.98".into(), "yes".into()],
            vec!["subspace".into(), "10".into(), "95.3".into(), "0.97".into(), "no".into()],
        ],
        highlight: Some(2),
    };

    Report {
        title: "ambid identification report — demo".into(),
        subtitle: "Synthetic rotor data · 5000 samples per series · generated by report_demo".into(),
        sections: vec![
            Section {
                id: "overview".into(),
                title: "Overview".into(),
                blocks: vec![
                    Block::Text("This demo report exercises every element of the renderer: notes, tables, line, dashed, marker, stem and band series, log axes, spans, pole-zero maps, heatmaps and empty panels.\n\nText is escaped: <b>not bold</b> & \"quoted\".".into()),
                    Block::Note { kind: NoteKind::Info, text: "Data: synthetic, closed loop, 5 kHz sampling.".into() },
                    Block::Note { kind: NoteKind::Warning, text: "Step skipped: open-loop data.".into() },
                    Block::Note { kind: NoteKind::Pass, text: "Validation fit 95.1 % ≥ 90 %.".into() },
                    Block::Note { kind: NoteKind::Fail, text: "Residual whiteness test failed at lag 3.".into() },
                    Block::Table(table),
                ],
            },
            Section {
                id: "frf".into(),
                title: "Frequency response".into(),
                blocks: vec![
                    Block::Figure(Figure {
                        id: "bode".into(),
                        title: "Frequency response of the x-axis bearing".into(),
                        caption: "Measured FRF (H1 estimator, 5000 log-spaced lines, one narrow spike near 370 Hz, a gap and a zero that the log axis skips) with the identified model and its 95 % band; the excitation band is shaded.".into(),
                        panels: vec![bode_mag, bode_ph],
                        columns: 1,
                    }),
                ],
            },
            Section {
                id: "time".into(),
                title: "Time domain".into(),
                blocks: vec![
                    Block::Figure(Figure {
                        id: "time-series".into(),
                        title: "Input and output".into(),
                        caption: "Rotor displacement (with a 20 ms gap of missing samples) and coil current.".into(),
                        panels: vec![
                            xy("Displacement", axis("time [s]", Scale::Linear), axis("x [µm]", Scale::Linear),
                                vec![series("x", t.clone(), y1, Style::Line, None)]),
                            xy("Current", axis("time [s]", Scale::Linear), axis("i [A]", Scale::Linear),
                                vec![series("i", t, u1, Style::Line, Some(1))]),
                        ],
                        columns: 2,
                    }),
                    Block::Figure(Figure {
                        id: "residuals".into(),
                        title: "Residual analysis".into(),
                        caption: "Left: residual autocorrelation with the 99 % confidence band. Right: fit against model order for three methods, every marker shape.".into(),
                        panels: vec![
                            xy("Autocorrelation", axis("lag [samples]", Scale::Linear), axis("r(τ) [-]", Scale::Linear),
                                vec![
                                    series("confidence", lags.clone(), vec![conf; lags.len()], Style::Band { lower: vec![-conf; lags.len()] }, Some(5)),
                                    series("r(τ)", lags, corr, Style::Stems, Some(0)),
                                ]),
                            xy("Fit vs order", axis("order", Scale::Linear), axis("fit [%]", Scale::Linear),
                                vec![
                                    series("ARX", k.clone(), fits(60.0), Style::LineMarkers(Marker::Square), None),
                                    series("subspace", k.clone(), fits(40.0), Style::LineMarkers(Marker::Dot), None),
                                    series("PEM", k.clone(), fits(30.0), Style::Markers(Marker::Cross), None),
                                    series("limit", k.clone(), vec![90.0; k.len()], Style::Dashed, Some(7)),
                                    series("target", k.clone(), fits(20.0), Style::Markers(Marker::Circle), None),
                                ]),
                        ],
                        columns: 2,
                    }),
                ],
            },
            Section {
                id: "model".into(),
                title: "Model".into(),
                blocks: vec![
                    Block::Figure(Figure {
                        id: "pole-zero".into(),
                        title: "Poles and zeros".into(),
                        caption: "Poles (×) and zeros (○) of the chosen model with the unit circle; equal axis scaling.".into(),
                        panels: vec![pz],
                        columns: 1,
                    }),
                    Block::Figure(Figure {
                        id: "order-map".into(),
                        title: "Order selection".into(),
                        caption: "Validation fit over model order and horizon; blank cells were not computed; the chosen order is outlined. Hover a cell for its value.".into(),
                        panels: vec![heat, heat_log],
                        columns: 2,
                    }),
                ],
            },
            Section {
                id: "edge-cases".into(),
                title: "Edge cases".into(),
                blocks: vec![
                    Block::Note { kind: NoteKind::Info, text: "Empty panels draw their axes and say \"no data\".".into() },
                    Block::Figure(Figure {
                        id: "empty".into(),
                        title: "Empty panels <script>alert(1)</script>".into(),
                        caption: "An empty panel, a panel with only non-finite data, and an empty heatmap. Caption with <script>alert('caption')</script>.".into(),
                        panels: vec![
                            xy("", axis("x [-]", Scale::Linear), axis("y [-]", Scale::Linear), vec![]),
                            empty_with_span,
                            Panel {
                                title: "Empty heatmap".into(),
                                x: axis("n", Scale::Linear),
                                y: axis("i", Scale::Linear),
                                content: PanelContent::Heatmap(Heatmap { x: vec![], y: vec![], z: vec![], z_label: "z".into(), highlight: Some((0, 0)) }),
                                spans: vec![],
                                equal_aspect: false,
                            },
                        ],
                        columns: 3,
                    }),
                    Block::Figure(Figure {
                        id: "no-panels".into(),
                        title: "A figure without panels".into(),
                        caption: String::new(),
                        panels: vec![],
                        columns: 0,
                    }),
                ],
            },
        ],
    }
}
