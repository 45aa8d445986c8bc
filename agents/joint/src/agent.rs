//! The joint agent's Zenoh loop: sample at the configured rate on the rig's tick grid, publish
//! the sample (and, simulated, the truth), apply commands the guard accepts, report the rest.
//!
//! One agent serves one joint board: usually one joint, but a board that drives several
//! joints on one bus (paper B's U2D2 drives all eight servos) serves them all from one
//! session and one loop — each joint keeps its own guard, keys and liveliness token.

use std::time::Duration;

use rig_config::{JointKind, RigConfig};
use rig_protocol::{
    JointCommand, JointSample, JointState, JointStatus, Keys, SimTruth, decode, encode,
};
use rig_runtime::{NetOverrides, now_ns, open, publisher, zenoh, zenoh_err as z};
use thiserror::Error;

use crate::backend::{BackendError, SimBackend, joint_index};
use crate::guard::{GuardLimits, JointGuard, Verdict};

/// Errors that stop the agent (bad input never does: it is reported and dropped).
#[derive(Debug, Error)]
pub enum AgentError {
    #[error(transparent)]
    Backend(#[from] BackendError),
    #[error(transparent)]
    Runtime(#[from] rig_runtime::RuntimeError),
}

impl From<rig_protocol::KeyError> for AgentError {
    fn from(e: rig_protocol::KeyError) -> Self {
        Self::Runtime(e.into())
    }
}

/// Most ticks sampled at one wake-up after a late timer; older ones are skipped and counted.
const MAX_CATCH_UP: u64 = 50;

/// Pause between joining the rig and the first sample.
const SETTLE: Duration = Duration::from_millis(500);

/// How to run one agent.
#[derive(Debug, Clone)]
pub struct AgentOptions {
    pub cfg: RigConfig,
    /// The names in the config of the joints this board serves (at least one).
    pub joints: Vec<String>,
    pub net: NetOverrides,
    /// Start of the simulated world's time [ns since the UNIX epoch].
    pub start_ns: u64,
    pub seed: u64,
    /// Stop after this long (None: until shutdown).
    pub duration: Option<Duration>,
    /// Undeclared effects of the simulated joints (none by default).
    pub effects: rig_sim::effects::Effects,
}

/// What the agent did for one joint.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AgentReport {
    pub samples: u64,
    pub skipped_ticks: u64,
    pub commands_accepted: u64,
    pub commands_rejected: u64,
    pub malformed: u64,
}

fn guard_limits(cfg: &RigConfig, j: usize) -> GuardLimits {
    let joint = &cfg.joints[j];
    let l = joint.limits;
    let (min, max, name, unit, scale) = match &joint.kind {
        JointKind::Lever { vsa, .. } => (vsa.d_min, vsa.d_max, "pivot", "mm", 1e3),
        JointKind::Awas { awas, .. } => (
            0.0,
            (awas.r0 - awas.r_min) / awas.n,
            "stiffness motor",
            "rad",
            1.0,
        ),
    };
    GuardLimits {
        motor_min_rad: l.motor_min_rad,
        motor_max_rad: l.motor_max_rad,
        actuator_min: min,
        actuator_max: max,
        actuator_rate: l.stiffness_rate,
        watchdog_s: l.watchdog_s,
        actuator_name: name,
        actuator_unit: unit,
        actuator_scale: scale,
    }
}

/// One joint of the board: its simulated hardware, guard, keys and counters.
struct Served {
    name: String,
    index: u16,
    backend: SimBackend,
    guard: JointGuard,
    limits: GuardLimits,
    sample_pub: zenoh::pubsub::Publisher<'static>,
    truth_pub: zenoh::pubsub::Publisher<'static>,
    commands: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    status_key: String,
    status_seq: u64,
    report: AgentReport,
    _token: zenoh::liveliness::LivelinessToken,
}

impl Served {
    async fn status(
        &mut self,
        session: &zenoh::Session,
        state: JointState,
        text: String,
    ) -> Result<(), AgentError> {
        self.status_seq += 1;
        let msg = JointStatus {
            joint: self.index,
            seq: self.status_seq,
            t_ns: now_ns(),
            state,
            text,
        };
        if let Ok(bytes) = encode(&msg) {
            session.put(&self.status_key, bytes).await.map_err(z)?;
        }
        Ok(())
    }

    /// Applies the commands that arrived since the last tick, then the watchdog.
    async fn commands(&mut self, session: &zenoh::Session, now: u64) -> Result<(), AgentError> {
        while let Ok(Some(s)) = self.commands.try_recv() {
            let bytes = s.payload().to_bytes();
            match decode::<JointCommand>(&bytes) {
                Err(e) => {
                    self.report.malformed += 1;
                    eprintln!("rig-joint {}: dropped a malformed command: {e}", self.name);
                }
                Ok(cmd) => match self.guard.on_command(&cmd, now, self.backend.actuator()) {
                    Verdict::Accepted { actuator_goal, .. } => {
                        self.report.commands_accepted += 1;
                        if let Some(g) = actuator_goal {
                            self.backend.set_actuator_goal(g);
                        }
                    }
                    Verdict::Rejected(why) => {
                        self.report.commands_rejected += 1;
                        self.status(session, JointState::Rejected, why).await?;
                    }
                },
            }
        }
        if let Some(state) = self.guard.on_tick(now, self.backend.actuator()) {
            self.backend.set_actuator_goal(self.guard.goal());
            let text = format!(
                "no command for {:.0} ms: holding the {} where it is",
                self.limits.watchdog_s * 1e3,
                self.limits.actuator_name
            );
            self.status(session, state, text).await?;
        }
        Ok(())
    }

    /// Reads the joint at grid time `t_acq` and publishes the sample (and the simulated truth).
    async fn sample(&mut self, t_acq: u64, t_world: f64, dt: f64) -> Result<(), AgentError> {
        let r = self.backend.read(t_world, dt)?;
        self.report.samples += 1;
        let sample = JointSample {
            joint: self.index,
            seq: self.report.samples,
            t_acq_ns: t_acq,
            motor_rad: r.motor_rad,
            deflection_rad: r.deflection_rad,
            pivot_m: r.pivot_m,
            torque_nm: r.torque_nm,
            motor_torque_nm: None,
            stiffness_motor_rad: r.stiffness_motor_rad,
        };
        match encode(&sample) {
            Ok(bytes) => self.sample_pub.put(bytes).await.map_err(z)?,
            Err(e) => eprintln!("rig-joint {}: sample not sent: {e}", self.name),
        }
        if let Some(t) = r.truth {
            let truth = SimTruth {
                joint: self.index,
                seq: self.report.samples,
                t_acq_ns: t_acq,
                deflection_rad: t.deflection_rad,
                torque_nm: t.torque_nm,
                link_rad: t.link_rad,
                stiffness_nm_per_rad: t.stiffness_nm_per_rad,
            };
            if let Ok(bytes) = encode(&truth) {
                self.truth_pub.put(bytes).await.map_err(z)?;
            }
        }
        Ok(())
    }
}

/// Runs the agent until `shutdown` resolves or the duration ends; one report per joint, in
/// the order of `opts.joints`.
pub async fn run(
    opts: AgentOptions,
    shutdown: impl std::future::Future<Output = ()>,
) -> Result<Vec<AgentReport>, AgentError> {
    let cfg = &opts.cfg;
    if opts.joints.is_empty() {
        return Err(BackendError::UnknownJoint(
            String::new(),
            cfg.joints
                .iter()
                .map(|j| j.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        )
        .into());
    }
    let keys = Keys::new(&cfg.name)?;
    let session = open(&cfg.zenoh, &opts.net).await?;
    let mut served = Vec::new();
    for name in &opts.joints {
        let j = joint_index(cfg, name)?;
        let backend = SimBackend::new(cfg, j, opts.seed.wrapping_add(j as u64), opts.effects)?;
        let limits = guard_limits(cfg, j);
        let mut joint = Served {
            name: name.clone(),
            index: j as u16,
            guard: JointGuard::new(j as u16, limits, backend.actuator()),
            backend,
            limits,
            sample_pub: publisher(&session, keys.joint_sample(name)?).await?,
            truth_pub: publisher(&session, keys.sim_truth(name)?).await?,
            commands: session
                .declare_subscriber(keys.joint_command(name)?)
                .await
                .map_err(z)?,
            status_key: keys.joint_status(name)?,
            status_seq: 0,
            report: AgentReport::default(),
            _token: session
                .liveliness()
                .declare_token(keys.alive("joint", name)?)
                .await
                .map_err(z)?,
        };
        joint
            .status(
                &session,
                JointState::Ok,
                format!("joint {name} up (sim backend)"),
            )
            .await?;
        served.push(joint);
    }

    // Let gossip link this peer to the rig's other peers (estimator, recorders, viewers)
    // before the first sample: in peer-to-peer mode a sample reaches only peers already linked.
    tokio::time::sleep(SETTLE).await;
    let period_ns = (1e9 / cfg.rate_hz).round() as u64;
    let mut ticker = tokio::time::interval(Duration::from_nanos(period_ns));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let deadline = opts.duration.map(|d| tokio::time::Instant::now() + d);
    let mut last_tick: Option<u64> = None;
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            _ = ticker.tick() => {}
        }
        if deadline.is_some_and(|d| tokio::time::Instant::now() >= d) {
            break;
        }
        let now = now_ns();
        let tick = now / period_ns;
        // Every grid tick since the last wake-up is sampled (the timer wakes at ~1 ms
        // granularity); more than MAX_CATCH_UP behind, the older ticks are skipped and counted.
        let first = match last_tick {
            Some(l) if tick <= l => continue,
            Some(l) => (l + 1).max(tick.saturating_sub(MAX_CATCH_UP)),
            None => tick,
        };
        let skipped = last_tick.map_or(0, |l| first.saturating_sub(l + 1));
        // Commands first: they apply from this tick on.
        for joint in &mut served {
            joint.report.skipped_ticks += skipped;
            joint.commands(&session, now).await?;
        }
        for t in first..=tick {
            let dt = last_tick.map_or(1, |l| t.saturating_sub(l)) as f64 * period_ns as f64 * 1e-9;
            last_tick = Some(t);
            let t_acq = t * period_ns;
            let t_world = t_acq.saturating_sub(opts.start_ns) as f64 * 1e-9;
            for joint in &mut served {
                joint.sample(t_acq, t_world, dt).await?;
            }
        }
    }
    let mut reports = Vec::new();
    for mut joint in served {
        let text = format!("joint {} stopped", joint.name);
        joint.status(&session, JointState::Stopped, text).await?;
        reports.push(joint.report);
    }
    // Closing drops what is still queued: give the last statuses time to leave.
    tokio::time::sleep(Duration::from_millis(50)).await;
    session.close().await.map_err(z)?;
    Ok(reports)
}
