//! `ambid init`: write a commented example workflow file.

use ambid::io::output::write_file;
use ambid::workflow;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct InitArgs {
    /// Where to write the example workflow file.
    #[arg(default_value = "workflow.toml")]
    path: PathBuf,
    /// Replace an existing file.
    #[arg(long)]
    force: bool,
}

pub fn init(a: InitArgs) -> Result<()> {
    write_file(&a.path, workflow::config::EXAMPLE.as_bytes(), a.force)
        .map_err(ambid::error::Error::from)?;
    println!(
        "written: {} (edit it, then `ambid run {}`)",
        a.path.display(),
        a.path.display()
    );
    Ok(())
}
