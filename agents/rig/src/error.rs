//! Errors of the command line, each with its exit status.

use std::process::ExitCode;

use thiserror::Error;

#[derive(Debug, Error)]
pub enum CliError {
    /// A config file is invalid (the message lists every problem).
    #[error("{0}")]
    Config(#[from] rig_config::ConfigErrors),
    /// Input files are invalid; their problems were already printed.
    #[error("{0}")]
    Invalid(String),
    /// The request cannot be met: unreachable pose, target out of range, infeasible target.
    #[error("{0}")]
    Infeasible(String),
    /// The rig in the config cannot do what was asked.
    #[error("{0}")]
    Unsupported(String),
    /// Writing the output failed.
    #[error("cannot write output: {0}")]
    Io(#[from] std::io::Error),
}

impl CliError {
    pub fn exit_code(&self) -> ExitCode {
        match self {
            CliError::Config(_)
            | CliError::Invalid(_)
            | CliError::Unsupported(_)
            | CliError::Io(_) => ExitCode::from(1),
            CliError::Infeasible(_) => ExitCode::from(3),
        }
    }
}
