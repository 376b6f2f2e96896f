//! `ambid run` and `ambid init`: the seed workflow end to end.

use ambid::io::output::OutputDir;
use ambid::workflow::{self, Failure, FailureClass, Progress, Step, Verbosity, WorkflowConfig};
use anyhow::Result;
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct RunArgs {
    /// Workflow file (TOML; `ambid init` writes a commented example). Without it, the seed
    /// procedure runs on the embedded twin with the defaults.
    workflow: Option<PathBuf>,
    /// Output directory (report.html, summary.json, figures/, tables/, models/).
    #[arg(long, default_value = "ambid-report")]
    out: PathBuf,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
    /// Run only these steps (comma-separated; overrides the file's `steps`).
    #[arg(long, value_delimiter = ',')]
    steps: Option<Vec<String>>,
    /// Errors only on stderr.
    #[arg(long, short, conflicts_with = "verbose")]
    quiet: bool,
    /// Also print each step's details.
    #[arg(long, short)]
    verbose: bool,
}

#[derive(Args)]
pub struct InitArgs {
    /// Where to write the example workflow file.
    #[arg(default_value = "workflow.toml")]
    path: PathBuf,
    /// Overwrite an existing file.
    #[arg(long)]
    force: bool,
}

fn config_failure(e: impl Into<anyhow::Error>) -> Failure {
    Failure {
        class: FailureClass::Config,
        error: e.into(),
    }
}

pub fn run(a: RunArgs) -> Result<()> {
    let (mut cfg, base) = match &a.workflow {
        Some(p) => (
            WorkflowConfig::from_path(p).map_err(Failure::from)?,
            p.parent()
                .filter(|d| !d.as_os_str().is_empty())
                .map_or_else(|| PathBuf::from("."), Path::to_path_buf),
        ),
        None => (WorkflowConfig::default(), PathBuf::from(".")),
    };
    if let Some(steps) = &a.steps {
        let mut v = Vec::new();
        for s in steps {
            let step = Step::ALL
                .into_iter()
                .find(|x| x.name() == s.trim())
                .ok_or_else(|| {
                    config_failure(anyhow::anyhow!(
                        "--steps: unknown step `{s}` (steps: {})",
                        Step::ALL.map(|x| x.name()).join(", ")
                    ))
                })?;
            v.push(step);
        }
        cfg.steps = Some(v);
        // the file's values are checked again against the steps that will run
        let path = a
            .workflow
            .clone()
            .unwrap_or_else(|| PathBuf::from("--steps"));
        cfg.check(&path).map_err(Failure::from)?;
    }
    // refuse to overwrite before spending any time
    OutputDir::check(&a.out, a.force).map_err(Failure::from)?;
    let verbosity = if a.quiet {
        Verbosity::Quiet
    } else if a.verbose {
        Verbosity::Verbose
    } else {
        Verbosity::Normal
    };
    let mut progress = Progress::new(verbosity);
    let outcome = workflow::run(&cfg, &base, &mut progress)?;
    let files = outcome.write(&a.out, a.force)?;
    if !a.quiet {
        let total: f64 = outcome.timings.iter().map(|t| t.seconds).sum();
        println!(
            "report: {} ({} files in {}; {:.2} s)",
            a.out.join("report.html").display(),
            files.len(),
            a.out.display(),
            total
        );
    }
    Ok(())
}

pub fn init(a: InitArgs) -> Result<()> {
    if a.path.exists() && !a.force {
        return Err(Failure {
            class: FailureClass::Output,
            error: anyhow::anyhow!(
                "{} already exists: choose another path, or pass --force to overwrite it",
                a.path.display()
            ),
        }
        .into());
    }
    let parent = a
        .path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    let tmp = parent.join(format!(
        ".{}.tmp-{}",
        a.path
            .file_name()
            .map_or("workflow".into(), |s| s.to_string_lossy()),
        std::process::id()
    ));
    let write = std::fs::write(&tmp, workflow::config::EXAMPLE)
        .and_then(|_| std::fs::rename(&tmp, &a.path));
    if let Err(e) = write {
        let _ = std::fs::remove_file(&tmp);
        return Err(Failure {
            class: FailureClass::Output,
            error: anyhow::anyhow!("{}: {e}", a.path.display()),
        }
        .into());
    }
    println!(
        "written: {} (edit it, then `ambid run {}`)",
        a.path.display(),
        a.path.display()
    );
    Ok(())
}
