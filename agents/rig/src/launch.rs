//! Starting the rig's roles in one process, one way for `rig up` and `rig bench`.
//!
//! 1. [`Hub::start`]: the estimator host listens (it is the hub everyone connects to) and the
//!    launcher opens its own session, waiting for the estimator's liveliness token instead of
//!    sleeping. The caller attaches what must see the first sample (a viewer, a counter of
//!    estimates, a summary's subscribers) to [`Hub::session`].
//! 2. [`Hub::start_roles`]: the allocator (optional) and one joint agent per board, then the
//!    wait for their tokens; a role not up in time is named in [`Launched::missing`].
//! 3. [`Launched::stop`]: the boards stop first (their last statuses leave), then, after a
//!    drain for samples in flight, the allocator and the estimator; every report comes back.
//!
//! Separate processes (the distributed tests, a board computer's `rig-joint`) wait on the same
//! `alive/*` tokens through [`rig_runtime::wait_alive`].

use std::time::Duration;

use rig_allocator::edge::{
    AllocatorError, AllocatorOptions, AllocatorReport, run as run_allocator,
};
use rig_config::RigConfig;
use rig_estimator::edge::{
    EstimatorError, EstimatorOptions, EstimatorReport, run as run_estimator,
};
use rig_joint::agent::{AgentError, AgentOptions, AgentReport, BackendKind, run as run_joint};
use rig_protocol::Keys;
use rig_runtime::{NetOverrides, open, wait_alive, zenoh};
use tokio::sync::watch;
use tokio::task::JoinHandle;

use crate::error::CliError;

/// A future that resolves once `rx` turns true.
async fn stopped(mut rx: watch::Receiver<bool>) {
    let _ = rx.wait_for(|s| *s).await;
}

/// A board agent: the joints it serves and its task.
type Board = (
    Vec<String>,
    JoinHandle<Result<Vec<AgentReport>, AgentError>>,
);

/// The estimator host, up, and the launcher's session connected to it.
pub struct Hub {
    cfg: RigConfig,
    /// Where the roles connect: the hub first, then the other machines' endpoints.
    pub peer: NetOverrides,
    /// The launcher's own session (a peer of the rig).
    pub session: zenoh::Session,
    pub keys: Keys,
    up_within: Duration,
    stop_estimator: watch::Sender<bool>,
    estimator: JoinHandle<Result<EstimatorReport, EstimatorError>>,
}

impl Hub {
    /// Starts the estimator listening on `listen` (its first endpoint is the hub) and
    /// connecting to `connect`, and waits up to `up_within` for its token.
    pub async fn start(
        cfg: &RigConfig,
        listen: Vec<String>,
        connect: Vec<String>,
        up_within: Duration,
    ) -> Result<Self, CliError> {
        let hub = listen
            .first()
            .cloned()
            .ok_or_else(|| CliError::Rig("the hub needs an endpoint to listen on".into()))?;
        let (stop_estimator, rx) = watch::channel(false);
        let estimator = tokio::spawn(run_estimator(
            EstimatorOptions {
                cfg: cfg.clone(),
                net: NetOverrides {
                    listen,
                    connect: connect.clone(),
                    ..Default::default()
                },
                duration: None,
            },
            stopped(rx),
        ));
        let peer = NetOverrides {
            listen: vec![],
            connect: std::iter::once(hub.clone()).chain(connect).collect(),
            ..Default::default()
        };
        let keys = Keys::new(&cfg.name)?;
        let session = open(cfg, &peer, &rig_config::Identity::Operator).await?;
        let missing = wait_alive(&session, &[keys.alive("estimator", "0")?], up_within).await?;
        if !missing.is_empty() {
            let _ = stop_estimator.send(true);
            // The estimator's own error, if it failed, says more than the timeout.
            if estimator.is_finished() {
                estimator.await??;
            }
            return Err(CliError::Rig(format!(
                "the estimator did not come up on {hub} within {} s",
                up_within.as_secs()
            )));
        }
        Ok(Self {
            cfg: cfg.clone(),
            peer,
            session,
            keys,
            up_within,
            stop_estimator,
            estimator,
        })
    }

    /// Stops the estimator and closes the launcher's session (when no roles were started
    /// through [`Hub::start_roles`]); the estimator's report.
    pub async fn stop(self) -> Result<EstimatorReport, CliError> {
        let _ = self.stop_estimator.send(true);
        let report = self.estimator.await??;
        let _ = self.session.close().await;
        Ok(report)
    }

    /// Starts the allocator (if `allocator`) and one joint agent per board (the joints each
    /// serves), each on `backend(its joints)`, and waits for their tokens. `duration`: how
    /// long the agents sample (None: until [`Launched::stop`]).
    pub async fn start_roles(
        self,
        allocator: bool,
        boards: Vec<Vec<String>>,
        backend: impl Fn(&[String]) -> BackendKind,
        start_ns: u64,
        duration: Option<Duration>,
    ) -> Result<Launched, CliError> {
        let (stop_roles, rx) = watch::channel(false);
        let alloc = allocator.then(|| {
            tokio::spawn(run_allocator(
                AllocatorOptions {
                    cfg: self.cfg.clone(),
                    net: self.peer.clone(),
                    duration: None,
                },
                stopped(rx.clone()),
            ))
        });
        let mut tokens = Vec::new();
        if allocator {
            tokens.push(self.keys.alive("allocator", "0")?);
        }
        let mut joints = Vec::new();
        for names in boards {
            for n in &names {
                tokens.push(self.keys.alive("joint", n)?);
            }
            let o = AgentOptions {
                cfg: self.cfg.clone(),
                joints: names.clone(),
                net: self.peer.clone(),
                start_ns,
                duration,
                backend: backend(&names),
            };
            joints.push((names, tokio::spawn(run_joint(o, stopped(rx.clone())))));
        }
        let missing = wait_alive(&self.session, &tokens, self.up_within).await?;
        Ok(Launched {
            hub: self,
            stop_roles,
            allocator: alloc,
            joints,
            missing,
        })
    }
}

/// The roles running.
pub struct Launched {
    pub hub: Hub,
    stop_roles: watch::Sender<bool>,
    allocator: Option<JoinHandle<Result<AllocatorReport, AllocatorError>>>,
    joints: Vec<Board>,
    /// Roles whose token did not appear in time (`alive/joint/j3`, …).
    pub missing: Vec<String>,
}

/// What every role reported.
#[derive(Debug)]
pub struct Reports {
    pub estimator: EstimatorReport,
    pub allocator: Option<AllocatorReport>,
    /// Per joint, in the order of the boards.
    pub joints: Vec<(String, AgentReport)>,
}

impl Launched {
    /// Whether a board agent still runs (agents with a duration end on their own).
    pub fn boards_running(&self) -> bool {
        self.joints.iter().any(|(_, h)| !h.is_finished())
    }

    /// Stops the boards and waits for them, lets `drain` pass for their last samples, then
    /// stops the allocator and the estimator; closes the launcher's session.
    pub async fn stop(self, drain: Duration) -> Result<Reports, CliError> {
        let _ = self.stop_roles.send(true);
        let mut joints = Vec::new();
        for (names, h) in self.joints {
            joints.extend(names.into_iter().zip(h.await??));
        }
        tokio::time::sleep(drain).await;
        let allocator = match self.allocator {
            Some(h) => Some(h.await??),
            None => None,
        };
        let _ = self.hub.stop_estimator.send(true);
        let estimator = self.hub.estimator.await??;
        let _ = self.hub.session.close().await;
        Ok(Reports {
            estimator,
            allocator,
            joints,
        })
    }
}
