//! The HTML document: header, table of contents, sections with text, notes, figures (inline
//! SVG from [`super::svg`]) and tables. One self-contained file: inline CSS, no JavaScript, no
//! external resources.

use std::fmt::Write;

use super::svg::{panel_svg, FIGURE_WIDTH, FONT_STACK, PANEL_GAP};
use super::{Block, Figure, NoteKind, Report, Table};

macro_rules! w {
    ($out:expr, $($arg:tt)*) => {
        let _ = write!($out, $($arg)*);
    };
}

/// Escapes text for HTML and SVG content and attribute values.
pub(crate) fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 8);
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// Makes a string usable as an element id (`[A-Za-z0-9_-]`, other characters become `-`).
pub(crate) fn anchor(s: &str) -> String {
    let a: String = s
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '-'
            }
        })
        .collect();
    if a.is_empty() {
        "x".into()
    } else {
        a
    }
}

/// The page style sheet.
fn css() -> String {
    format!(
        r#"*{{box-sizing:border-box}}
html{{-webkit-text-size-adjust:100%}}
body{{margin:0;background:#f3f4f6;color:#1f2328;font-family:{FONT_STACK};font-size:15px;line-height:1.55}}
main{{max-width:{main}px;margin:0 auto;background:#fff;padding:28px 32px 48px;min-height:100vh;box-shadow:0 0 0 1px #e5e7eb}}
header{{border-bottom:2px solid #0072B2;padding-bottom:12px;margin-bottom:18px}}
h1{{font-size:26px;line-height:1.25;margin:0 0 4px;font-weight:650}}
.subtitle{{color:#57606a;margin:0}}
h2{{font-size:20px;margin:36px 0 10px;padding-bottom:4px;border-bottom:1px solid #d8dee4;font-weight:620}}
h3{{font-size:15px;margin:0 0 8px;font-weight:620}}
a{{color:#0060a0;text-decoration:none}}
a:hover{{text-decoration:underline}}
nav.toc{{background:#f6f8fa;border:1px solid #d8dee4;border-radius:6px;padding:10px 18px;margin:0 0 8px}}
nav.toc h2{{font-size:14px;margin:0 0 4px;border:0;padding:0;text-transform:uppercase;letter-spacing:.04em;color:#57606a}}
nav.toc ol{{margin:0;padding-left:22px;columns:2;column-gap:32px}}
nav.toc li{{break-inside:avoid}}
nav.toc .count{{color:#8c959f;font-size:12px}}
p{{margin:8px 0}}
.note{{margin:12px 0;padding:9px 14px;border-left:4px solid;border-radius:4px}}
.note strong{{margin-right:6px}}
.note-info{{background:#eef6fc;border-color:#0072B2}}
.note-warning{{background:#fff6e0;border-color:#E69F00}}
.note-pass{{background:#e8f6ef;border-color:#009E73}}
.note-fail{{background:#fdece6;border-color:#D55E00}}
figure{{margin:18px 0;padding:14px 0 10px;border-top:1px solid #eaeef2}}
.panels{{display:grid;gap:6px {gap}px;max-width:{fig}px}}
.panels svg{{display:block;max-width:100%;height:auto}}
figcaption{{font-size:13px;color:#424a53;margin-top:6px;max-width:{fig}px}}
.fig-no,.tab-no{{font-weight:620;color:#1f2328}}
.table-wrap{{overflow-x:auto;margin:18px 0}}
table{{border-collapse:collapse;font-size:13px;font-variant-numeric:tabular-nums}}
caption{{caption-side:top;text-align:left;font-size:13px;color:#424a53;padding-bottom:6px}}
th,td{{padding:4px 10px;border-bottom:1px solid #e5e7eb;text-align:left;vertical-align:top;overflow-wrap:anywhere}}
th{{background:#f6f8fa;border-bottom:2px solid #d0d7de;font-weight:620}}
td.num{{text-align:right;white-space:nowrap}}
tr.hl td{{background:#e6f1fa;font-weight:650}}
footer{{margin-top:40px;color:#8c959f;font-size:12px;border-top:1px solid #eaeef2;padding-top:8px}}
@media print{{body{{background:#fff}}main{{box-shadow:none;max-width:none}}figure,.table-wrap{{break-inside:avoid}}}}
"#,
        main = FIGURE_WIDTH as usize + 64,
        fig = FIGURE_WIDTH as usize,
        gap = PANEL_GAP as usize,
    )
}

/// Renders the whole report.
pub(crate) fn render(report: &Report) -> String {
    let mut out = String::with_capacity(64 * 1024);
    let title = if report.title.is_empty() {
        "Report"
    } else {
        &report.title
    };
    w!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n<title>{}</title>\n<style>\n{}</style>\n</head>\n<body>\n<main>\n<header>\n<h1>{}</h1>\n",
        escape(title),
        css(),
        escape(title)
    );
    if !report.subtitle.is_empty() {
        w!(
            out,
            "<p class=\"subtitle\">{}</p>\n",
            escape(&report.subtitle)
        );
    }
    w!(out, "</header>\n");

    // Table of contents.
    if !report.sections.is_empty() {
        w!(out, "<nav class=\"toc\">\n<h2>Contents</h2>\n<ol>\n");
        for s in &report.sections {
            let figures = s
                .blocks
                .iter()
                .filter(|b| matches!(b, Block::Figure(_)))
                .count();
            let tables = s
                .blocks
                .iter()
                .filter(|b| matches!(b, Block::Table(_)))
                .count();
            let mut count = Vec::new();
            if figures > 0 {
                count.push(format!(
                    "{figures} figure{}",
                    if figures == 1 { "" } else { "s" }
                ));
            }
            if tables > 0 {
                count.push(format!(
                    "{tables} table{}",
                    if tables == 1 { "" } else { "s" }
                ));
            }
            w!(
                out,
                "<li><a href=\"#{}\">{}</a>",
                anchor(&s.id),
                escape(&s.title)
            );
            if !count.is_empty() {
                w!(out, " <span class=\"count\">({})</span>", count.join(", "));
            }
            w!(out, "</li>\n");
        }
        w!(out, "</ol>\n</nav>\n");
    }

    let (mut fig_no, mut tab_no, mut uid) = (0usize, 0usize, 0usize);
    for s in &report.sections {
        w!(
            out,
            "<section id=\"{}\">\n<h2>{}</h2>\n",
            anchor(&s.id),
            escape(&s.title)
        );
        for b in &s.blocks {
            match b {
                Block::Text(t) => text_html(&mut out, t),
                Block::Note { kind, text } => {
                    let (class, word) = match kind {
                        NoteKind::Info => ("info", "Note"),
                        NoteKind::Warning => ("warning", "Warning"),
                        NoteKind::Pass => ("pass", "Pass"),
                        NoteKind::Fail => ("fail", "Fail"),
                    };
                    w!(
                        out,
                        "<div class=\"note note-{class}\" role=\"note\"><strong>{word}</strong>{}</div>\n",
                        escape(text)
                    );
                }
                Block::Figure(f) => {
                    fig_no += 1;
                    figure_html(&mut out, f, fig_no, &mut uid);
                }
                Block::Table(t) => {
                    tab_no += 1;
                    table_html(&mut out, t, tab_no);
                }
            }
        }
        w!(out, "</section>\n");
    }
    w!(
        out,
        "<footer>Generated by ambid {}. Figure data: one CSV file per figure id.</footer>\n</main>\n</body>\n</html>\n",
        env!("CARGO_PKG_VERSION")
    );
    out
}

/// Paragraphs separated by blank lines.
fn text_html(out: &mut String, t: &str) {
    for para in t.split("\n\n") {
        let para = para.trim();
        if !para.is_empty() {
            w!(out, "<p>{}</p>\n", escape(para).replace('\n', "<br>"));
        }
    }
}

/// One figure: numbered title, the panel grid, the caption.
pub(crate) fn figure_html(out: &mut String, f: &Figure, number: usize, uid: &mut usize) {
    let columns = f.columns.max(1).min(f.panels.len().max(1));
    w!(
        out,
        "<figure id=\"fig-{}\">\n<h3><span class=\"fig-no\">Figure {number}.</span> {}</h3>\n",
        anchor(&f.id),
        escape(&f.title)
    );
    w!(
        out,
        "<div class=\"panels\" style=\"grid-template-columns:repeat({columns},minmax(0,1fr))\">\n"
    );
    for p in &f.panels {
        *uid += 1;
        panel_svg(p, columns, &format!("p{uid}"), out);
        out.push('\n');
    }
    if f.panels.is_empty() {
        // Nothing to draw: an empty frame that says so.
        w!(
            out,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" class=\"panel\" width=\"{w}\" height=\"80\" viewBox=\"0 0 {w} 80\" role=\"img\" aria-label=\"no data\"><rect x=\"0.5\" y=\"0.5\" width=\"{}\" height=\"79\" fill=\"#fff\" stroke=\"#d0d7de\"/><text x=\"{}\" y=\"45\" text-anchor=\"middle\" font-size=\"14\" fill=\"#8c959f\">no data</text></svg>\n",
            FIGURE_WIDTH - 1.0,
            FIGURE_WIDTH / 2.0,
            w = FIGURE_WIDTH
        );
    }
    w!(out, "</div>\n");
    if !f.caption.is_empty() {
        w!(out, "<figcaption>{}</figcaption>\n", escape(&f.caption));
    }
    w!(out, "</figure>\n");
}

/// Whether a cell reads as a number (right-aligned).
fn numeric(cell: &str) -> bool {
    let c = cell.trim().trim_end_matches('%');
    !c.is_empty() && c.parse::<f64>().is_ok()
}

/// One table with its caption; the highlighted row is bold and tinted.
fn table_html(out: &mut String, t: &Table, number: usize) {
    w!(
        out,
        "<div class=\"table-wrap\" id=\"tab-{}\">\n<table>\n<caption><span class=\"tab-no\">Table {number}.</span> {}</caption>\n",
        anchor(&t.id),
        escape(&t.caption)
    );
    if !t.header.is_empty() {
        w!(out, "<thead><tr>");
        for h in &t.header {
            w!(out, "<th scope=\"col\">{}</th>", escape(h));
        }
        w!(out, "</tr></thead>\n");
    }
    w!(out, "<tbody>\n");
    for (i, row) in t.rows.iter().enumerate() {
        if t.highlight == Some(i) {
            w!(out, "<tr class=\"hl\">");
        } else {
            w!(out, "<tr>");
        }
        for cell in row {
            if numeric(cell) {
                w!(out, "<td class=\"num\">{}</td>", escape(cell));
            } else {
                w!(out, "<td>{}</td>", escape(cell));
            }
        }
        w!(out, "</tr>\n");
    }
    w!(out, "</tbody>\n</table>\n</div>\n");
}
