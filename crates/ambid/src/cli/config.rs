//! `ambid config`: print the twin's configuration as TOML.

use super::common::RigArgs;
use ambid_twin::TwinConfig;
use anyhow::Result;

/// Prints the nominal configuration, or a random rig's (`--rig-seed`), as TOML.
pub fn config(a: RigArgs) -> Result<()> {
    let cfg = match a.rig_seed {
        Some(seed) => ambid_twin::random_rig(seed)?,
        None => TwinConfig::default(),
    };
    print!("{}", cfg.to_toml_string()?);
    Ok(())
}
