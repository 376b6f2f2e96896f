//! Browser check of the HTML report: the demo report (every block kind, every series style, log
//! axes, heatmaps, a pole-zero map, bands, spans, empty panels) is written to a temporary
//! directory and loaded in headless Chromium (`/usr/bin/chromium`): the screenshot must be
//! non-trivial, every `<svg>` in the rendered DOM must draw something, and there must be no
//! console message and no external resource. Skipped (recorded by `common::skip`, listed at the
//! end of `bash .ci/run`) when Chromium is not installed.
//!
//! Also: a deliberately broken page must be flagged (so the check can fail), and a large report
//! (25 figures of 5000-point series) must stay small and render fast.

use crate::common;
use std::path::PathBuf;
use std::time::Instant;

use ambid::report::{
    browser_check, demo_report, Axis, Block, BrowserCheck, Figure, Panel, PanelContent, Report,
    Scale, Section, Series, Style,
};

/// A fresh temporary directory for this test.
fn temp_dir(tag: &str) -> PathBuf {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let dir = std::env::temp_dir().join(format!(
        "ambid-report-test-{tag}-{}-{nanos}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).expect("create temp dir");
    dir
}

/// Number of `<svg>` elements the report should have: one per panel, one for a figure
/// without panels.
fn expected_svgs(report: &Report) -> usize {
    report
        .sections
        .iter()
        .flat_map(|s| &s.blocks)
        .map(|b| match b {
            Block::Figure(f) => f.panels.len().max(1),
            _ => 0,
        })
        .sum()
}

#[test]
fn demo_report_renders_in_chromium() {
    let report = demo_report();
    let html = report.to_html();
    // Static checks that hold with or without a browser.
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(
        !html.contains("<script"),
        "unescaped <script> in the report"
    );
    assert!(html.contains("&lt;script&gt;alert(1)&lt;/script&gt;"));
    assert_eq!(html.matches("<svg").count(), expected_svgs(&report));
    assert_eq!(html.matches("<figcaption>").count(), 6);

    let dir = temp_dir("demo");
    let path = dir.join("report.html");
    std::fs::write(&path, &html).expect("write report");
    let check = browser_check(&path).expect("browser check ran");
    match &check {
        BrowserCheck::Unavailable { reason } => {
            common::skip(
                "report_browser: the demo report in headless Chromium",
                reason,
            );
        }
        BrowserCheck::Checked(c) => {
            println!("browser check: {c:?}");
            assert_eq!(c.svgs, expected_svgs(&report), "svg count in rendered DOM");
            assert_eq!(c.empty_svgs, 0);
            assert!(c.console_errors.is_empty(), "{:?}", c.console_errors);
            assert!(c.external_refs.is_empty(), "{:?}", c.external_refs);
            assert!(c.screenshot_bytes > 200_000, "{}", c.screenshot_bytes);
            assert!(check.problems().is_empty(), "{:?}", check.problems());
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn broken_page_is_flagged() {
    let dir = temp_dir("broken");
    let path = dir.join("broken.html");
    std::fs::write(
        &path,
        "<!DOCTYPE html><html><head><link rel=\"stylesheet\" href=\"missing.css\"></head><body>\
         <svg width=\"100\" height=\"50\"><path d=\"M0 0L10 10\"/></svg>\
         <svg width=\"100\" height=\"50\"></svg>\
         <script>console.error('boom'); notDefined();</script>\
         <div id=\"wide\" style=\"width:3000px\">wide</div><p>measured Some(42) here</p>\
         <div class=\"table-wrap\" id=\"tw\" style=\"overflow-x:auto;width:200px\"><table><tr>\
         <td style=\"white-space:nowrap\">aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa</td>\
         </tr></table></div></body></html>",
    )
    .expect("write page");
    match browser_check(&path).expect("browser check ran") {
        BrowserCheck::Unavailable { reason } => {
            common::skip("report_browser: a broken page flagged by Chromium", &reason)
        }
        BrowserCheck::Checked(c) => {
            println!("broken page: {c:?}");
            assert_eq!(c.svgs, 2);
            assert_eq!(c.empty_svgs, 1);
            // console.error and the uncaught ReferenceError, each once.
            assert_eq!(c.console_errors.len(), 2, "{:?}", c.console_errors);
            assert!(!c.external_refs.is_empty());
            // the layout probe: the 3000-px div, the scrolling table, the debug text
            assert!(
                c.overflowing
                    .iter()
                    .any(|e| e.starts_with("div#wide ends at")),
                "{:?}",
                c.overflowing
            );
            assert!(
                c.overflowing.iter().any(|e| e.starts_with("div#tw: table")),
                "{:?}",
                c.overflowing
            );
            assert_eq!(c.debug_text.len(), 1, "{:?}", c.debug_text);
            assert!(c.debug_text[0].contains("Some(42)"));
            assert_eq!(c.first_section, "");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_file_is_an_error_not_a_skip() {
    let r = browser_check(std::path::Path::new("/nonexistent/report.html"));
    match r {
        Ok(BrowserCheck::Unavailable { .. }) | Err(_) => {}
        Ok(BrowserCheck::Checked(c)) => panic!("checked a missing file: {c:?}"),
    }
}

/// 25 figures, each two panels of three 5000-point series (one a band): the size budget (10 MB)
/// and the time budget (well under 1 s in release; generous here for debug builds).
#[test]
fn large_report_stays_small_and_fast() {
    let n = 5000;
    let x: Vec<f64> = (0..n)
        .map(|k| 10f64.powf(3.0 * k as f64 / n as f64))
        .collect();
    let y: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(k, f)| 1.0 / (1.0 + f * f / 1e4) * (1.0 + 0.2 * ((k * 7919) % 101) as f64 / 101.0))
        .collect();
    let lower: Vec<f64> = y.iter().map(|v| v * 0.8).collect();
    let axis = |scale| Axis {
        label: "axis [unit]".into(),
        scale,
        range: None,
    };
    let panel = |scale| Panel {
        title: "panel".into(),
        x: axis(Scale::Log),
        y: axis(scale),
        content: PanelContent::Xy(vec![
            Series {
                name: "band".into(),
                x: x.clone(),
                y: y.iter().map(|v| v * 1.2).collect(),
                style: Style::Band {
                    lower: lower.clone(),
                },
                color: None,
            },
            Series {
                name: "data".into(),
                x: x.clone(),
                y: y.clone(),
                style: Style::Line,
                color: None,
            },
            Series {
                name: "model".into(),
                x: x.clone(),
                y: y.iter().map(|v| v * 0.95).collect(),
                style: Style::Dashed,
                color: None,
            },
        ]),
        spans: vec![],
        equal_aspect: false,
    };
    let figures: Vec<Block> = (0..25)
        .map(|i| {
            Block::Figure(Figure {
                id: format!("f{i}"),
                title: format!("figure {i}"),
                caption: "caption".into(),
                panels: vec![panel(Scale::Log), panel(Scale::Linear)],
                columns: 1 + i % 2,
            })
        })
        .collect();
    let report = Report {
        title: "large".into(),
        subtitle: String::new(),
        sections: vec![Section {
            id: "all".into(),
            title: "All".into(),
            blocks: figures,
        }],
    };
    let start = Instant::now();
    let html = report.to_html();
    let elapsed = start.elapsed();
    println!(
        "25 figures × 2 panels × 3 series × {n} points: {} bytes in {elapsed:?}",
        html.len()
    );
    assert!(html.len() < 10_000_000, "{} bytes", html.len());
    assert!(elapsed.as_secs_f64() < 5.0, "{elapsed:?}");
}
