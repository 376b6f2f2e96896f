//! `ambid run` and `ambid init`: the seed workflow end to end.

use ambid::error::Error;
use ambid::io::output::OutputDir;
use ambid::workflow::{self, FailureClass, Progress, Step, Verbosity, WorkflowConfig};
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
    /// Replace the output directory if it exists (never `/`, the home or current directory,
    /// an ancestor of it, or a directory holding an input file).
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

fn config_failure(message: String) -> Error {
    Error::classified(FailureClass::Config, Error::other(message))
}

pub fn run(a: RunArgs) -> Result<()> {
    let (mut cfg, base) = match &a.workflow {
        Some(p) => (
            WorkflowConfig::from_path(p).map_err(Error::from)?,
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
                .chain(Step::OPTIONAL)
                .find(|x| x.name() == s.trim())
                .ok_or_else(|| {
                    config_failure(format!(
                        "--steps: unknown step `{s}` (steps: {})",
                        Step::ALL
                            .into_iter()
                            .chain(Step::OPTIONAL)
                            .map(|x| x.name())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })?;
            v.push(step);
        }
        // a step runs with the steps whose results it reads (`run --steps models` fits the
        // FRF, as the full run does, instead of falling back to the slower time-domain fit)
        let (v, added) = Step::with_prerequisites(&v);
        for (p, by) in added.iter().filter(|_| !a.quiet) {
            eprintln!(
                "note: --steps: also running `{}` (`{}` uses its results)",
                p.name(),
                by.name()
            );
        }
        cfg.steps = Some(v);
        // the file's values are checked again against the steps that will run
        let path = a
            .workflow
            .clone()
            .unwrap_or_else(|| PathBuf::from("--steps"));
        cfg.check(&path).map_err(Error::from)?;
    }
    // refuse to overwrite (or to delete a directory holding our inputs) before spending any time
    let inputs: Vec<PathBuf> = a
        .workflow
        .iter()
        .cloned()
        .chain(
            [
                &cfg.twin.config,
                &cfg.data.identification,
                &cfg.data.validation,
                &cfg.data.noise,
                &cfg.data.reconstruction,
                &cfg.data.controller,
            ]
            .into_iter()
            .flatten()
            .map(|p| base.join(p)),
        )
        .chain(cfg.machine.iter().flat_map(|m| {
            m.config
                .iter()
                .cloned()
                .chain(m.files.iter().map(|f| f.path.clone()))
                .map(|p| base.join(p))
                .collect::<Vec<_>>()
        }))
        .collect();
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    OutputDir::check_with_inputs(&a.out, a.force, &inputs).map_err(Error::from)?;
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
