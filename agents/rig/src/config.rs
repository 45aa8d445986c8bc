//! The rig config a command runs on: the file given, or the example parallel robot.

use std::path::PathBuf;

use rig_config::RigConfig;

use crate::error::CliError;

/// `--config FILE` if given, else `rig-config/examples/parallel.toml` (built in).
pub fn load_or_parallel(config: &Option<PathBuf>) -> Result<RigConfig, CliError> {
    Ok(match config {
        Some(p) => rig_config::load(p)?,
        None => rig_config::examples::load("parallel")?,
    })
}
