//! Speed of the whole seed workflow on the twin (issue 7's bar: `ambid run` in ≤ 10 s, release).
//! Run: `cargo bench -p ambid --bench workflow`.
//!
//! * `default_workflow`: [`workflow::run`] with the defaults (all eleven steps, computed in memory);
//! * `render_and_write`: the report's HTML, the figure and table CSVs and the model exports of
//!   that outcome written into a fresh directory ([`Outcome::write`]).
//!
//! The per-step breakdown is in each run's `summary.json` (`timing.*`) and in docs/benchmarks.md.

use ambid::workflow::{self, Outcome, Progress, Verbosity, WorkflowConfig};
use divan::Bencher;
use std::path::Path;

fn main() {
    divan::main();
}

fn outcome() -> Outcome {
    let mut p = Progress::new(Verbosity::Quiet);
    workflow::run(&WorkflowConfig::default(), Path::new("."), &mut p).expect("workflow")
}

#[divan::bench(sample_count = 5, sample_size = 1)]
fn default_workflow(b: Bencher) {
    b.bench(outcome);
}

#[divan::bench(sample_count = 10, sample_size = 1)]
fn render_and_write(b: Bencher) {
    let out = outcome();
    let dir = std::env::temp_dir().join(format!("ambid-bench-workflow-{}", std::process::id()));
    b.bench(|| {
        let _ = std::fs::remove_dir_all(&dir);
        out.write(&dir, true).expect("write")
    });
    let _ = std::fs::remove_dir_all(&dir);
}
