//! Writes the demonstration report (every block kind, series style and axis scale) so that one
//! can look at it, with one CSV file per figure and table next to it.
//!
//! ```text
//! cargo run -p ambid --example report_demo -- /tmp/report/report.html
//! ```

use std::path::PathBuf;
use std::time::Instant;

use ambid::report::{demo_report, Block};

fn main() -> anyhow::Result<()> {
    let path = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "report_demo.html".to_string()),
    );
    let report = demo_report();
    let start = Instant::now();
    let html = report.to_html();
    let elapsed = start.elapsed();
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("."));
    std::fs::create_dir_all(&dir)?;
    std::fs::write(&path, &html)?;
    let mut files = 0;
    for section in &report.sections {
        for block in &section.blocks {
            match block {
                Block::Figure(f) => {
                    std::fs::write(dir.join(format!("{}.csv", f.id)), f.to_csv())?;
                    files += 1;
                }
                Block::Table(t) => {
                    std::fs::write(dir.join(format!("{}.csv", t.id)), t.to_csv())?;
                    files += 1;
                }
                _ => {}
            }
        }
    }
    println!(
        "wrote {} ({} bytes, rendered in {:.1} ms) and {files} CSV files",
        path.display(),
        html.len(),
        elapsed.as_secs_f64() * 1e3
    );
    Ok(())
}
