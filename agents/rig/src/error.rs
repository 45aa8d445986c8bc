//! Errors of the command line, each with its exit status.
//!
//! Errors of the crates below keep their type and their chain (`#[from]`, `#[source]`): a
//! Zenoh failure stays a [`RuntimeError`], a board's a [`BoardError`]. The `String` variants
//! are for what this command itself finds wrong with the request, in its own words.

use std::process::ExitCode;

use rig_joint::agent::AgentError;
use rig_joint::board::BoardError;
use rig_runtime::RuntimeError;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum CliError {
    /// A config file is invalid (the message lists every problem).
    #[error("{0}")]
    Config(#[from] rig_config::ConfigErrors),
    /// Input files are invalid; the message names the file and what is wrong.
    #[error("{0}")]
    Invalid(String),
    /// The request cannot be met: unreachable pose, target out of range, infeasible target.
    #[error("{0}")]
    Infeasible(String),
    /// The rig in the config cannot do what was asked.
    #[error("{0}")]
    Unsupported(String),
    /// A role did not come up, or the rig did not do what the command waits for.
    #[error("{0}")]
    Rig(String),
    /// Reading or writing a file failed.
    #[error("cannot write output: {0}")]
    Io(#[from] std::io::Error),
    /// The Zenoh edge failed (configuration, session, a declaration, a put).
    #[error(transparent)]
    Network(#[from] RuntimeError),
    /// A key expression could not be built from the config's names.
    #[error(transparent)]
    Key(#[from] rig_protocol::KeyError),
    /// A joint board (simulated, virtual or hardware) failed.
    #[error(transparent)]
    Board(#[from] BoardError),
    /// A joint agent ended with an error.
    #[error(transparent)]
    Agent(#[from] AgentError),
    /// The estimator host ended with an error.
    #[error(transparent)]
    Estimator(#[from] rig_estimator::edge::EstimatorError),
    /// The viewer could not be opened or fed.
    #[error(transparent)]
    Viz(#[from] rig_viz::VizError),
    /// An MCAP recording could not be read or written.
    #[error("recording: {0}")]
    Recording(#[from] mcap::McapError),
    /// A paper's reproduction failed.
    #[error(transparent)]
    Reproduce(#[from] rig_sim::reproduce::ReproduceError),
    /// A scenario could not be loaded or run.
    #[error(transparent)]
    Scenario(#[from] rig_sim::scenario::ScenarioError),
    /// `rig identify` could not fit the data.
    #[error(transparent)]
    Identify(#[from] rig_model::identify::IdentifyError),
    /// A bus scan failed.
    #[error(transparent)]
    Scan(#[from] rig_dynamixel::scan::ScanError),
    /// A CSV file could not be read.
    #[error("{file}: {source}")]
    Csv {
        file: String,
        #[source]
        source: csv::Error,
    },
    /// A message this command built is not one the protocol accepts.
    #[error(transparent)]
    Message(#[from] rig_protocol::ValidationError),
    /// A role's task panicked or was cancelled.
    #[error("a role's task ended abnormally: {0}")]
    Task(#[from] tokio::task::JoinError),
}

impl From<rig_joint::hardware::PlanError> for CliError {
    fn from(e: rig_joint::hardware::PlanError) -> Self {
        Self::Board(e.into())
    }
}

impl From<rig_joint::hardware::HardwareError> for CliError {
    fn from(e: rig_joint::hardware::HardwareError) -> Self {
        Self::Board(e.into())
    }
}

impl From<rig_estimator::core::CoreError> for CliError {
    fn from(e: rig_estimator::core::CoreError) -> Self {
        Self::Estimator(e.into())
    }
}

impl CliError {
    pub fn exit_code(&self) -> ExitCode {
        match self {
            CliError::Infeasible(_) => ExitCode::from(3),
            _ => ExitCode::from(1),
        }
    }
}
