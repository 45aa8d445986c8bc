//! The joint agent's Zenoh loop: sample at the configured rate on the rig's tick grid, publish
//! the sample (and, simulated, the truth), apply commands the guard accepts, report the rest.

use std::time::Duration;

use rig_config::{JointKind, RigConfig};
use rig_protocol::{
    JointCommand, JointSample, JointState, JointStatus, Keys, SimTruth, decode, encode,
};
use rig_runtime::{NetOverrides, now_ns, open, zenoh_err as z};
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
    /// The joint's name in the config.
    pub joint: String,
    pub net: NetOverrides,
    /// Start of the simulated world's time [ns since the UNIX epoch].
    pub start_ns: u64,
    pub seed: u64,
    /// Stop after this long (None: until shutdown).
    pub duration: Option<Duration>,
}

/// What the agent did.
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

/// Runs the agent until `shutdown` resolves or the duration ends.
pub async fn run(
    opts: AgentOptions,
    shutdown: impl std::future::Future<Output = ()>,
) -> Result<AgentReport, AgentError> {
    let cfg = &opts.cfg;
    let j = joint_index(cfg, &opts.joint)?;
    let index = j as u16;
    let mut backend = SimBackend::new(cfg, j, opts.seed.wrapping_add(j as u64))?;
    let mut guard = JointGuard::new(index, guard_limits(cfg, j), backend.actuator());
    let keys = Keys::new(&cfg.name)?;
    let session = open(&cfg.zenoh, &opts.net).await?;
    let sample_pub = session
        .declare_publisher(keys.joint_sample(&opts.joint)?)
        .await
        .map_err(z)?;
    let truth_pub = session
        .declare_publisher(keys.sim_truth(&opts.joint)?)
        .await
        .map_err(z)?;
    let status_key = keys.joint_status(&opts.joint)?;
    let commands = session
        .declare_subscriber(keys.joint_command(&opts.joint)?)
        .await
        .map_err(z)?;
    let _token = session
        .liveliness()
        .declare_token(keys.alive("joint", &opts.joint)?)
        .await
        .map_err(z)?;

    let period_ns = (1e9 / cfg.rate_hz).round() as u64;
    let mut report = AgentReport::default();
    let mut status_seq = 0u64;
    let mut publish_status = |state: JointState, text: String| {
        status_seq += 1;
        let msg = JointStatus {
            joint: index,
            seq: status_seq,
            t_ns: now_ns(),
            state,
            text,
        };
        (status_key.clone(), encode(&msg))
    };
    let (k0, v0) = publish_status(
        JointState::Ok,
        format!("joint {} up (sim backend)", opts.joint),
    );
    if let Ok(bytes) = v0 {
        session.put(&k0, bytes).await.map_err(z)?;
    }

    // Let gossip link this peer to the rig's other peers (estimator, recorders, viewers)
    // before the first sample: in peer-to-peer mode a sample reaches only peers already linked.
    tokio::time::sleep(SETTLE).await;
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
        report.skipped_ticks += last_tick.map_or(0, |l| first.saturating_sub(l + 1));

        // Commands first: they apply from this tick on.
        while let Ok(Some(s)) = commands.try_recv() {
            let bytes = s.payload().to_bytes();
            match decode::<JointCommand>(&bytes) {
                Err(e) => {
                    report.malformed += 1;
                    eprintln!("rig-joint {}: dropped a malformed command: {e}", opts.joint);
                }
                Ok(cmd) => match guard.on_command(&cmd, now, backend.actuator()) {
                    Verdict::Accepted { actuator_goal, .. } => {
                        report.commands_accepted += 1;
                        if let Some(g) = actuator_goal {
                            backend.set_actuator_goal(g);
                        }
                    }
                    Verdict::Rejected(why) => {
                        report.commands_rejected += 1;
                        let (k, v) = publish_status(JointState::Rejected, why);
                        if let Ok(bytes) = v {
                            session.put(&k, bytes).await.map_err(z)?;
                        }
                    }
                },
            }
        }
        if let Some(state) = guard.on_tick(now, backend.actuator()) {
            backend.set_actuator_goal(guard.goal());
            let l = guard_limits(cfg, j);
            let text = format!(
                "no command for {:.0} ms: holding the {} where it is",
                l.watchdog_s * 1e3,
                l.actuator_name
            );
            let (k, v) = publish_status(state, text);
            if let Ok(bytes) = v {
                session.put(&k, bytes).await.map_err(z)?;
            }
        }

        for t in first..=tick {
            let dt_ticks = last_tick.map_or(1, |l| t.saturating_sub(l));
            last_tick = Some(t);
            let t_acq = t * period_ns;
            let t_world = t_acq.saturating_sub(opts.start_ns) as f64 * 1e-9;
            let r = backend.read(t_world, dt_ticks as f64 * period_ns as f64 * 1e-9)?;
            report.samples += 1;
            let sample = JointSample {
                joint: index,
                seq: report.samples,
                t_acq_ns: t_acq,
                motor_rad: r.motor_rad,
                deflection_rad: r.deflection_rad,
                pivot_m: r.pivot_m,
                torque_nm: r.torque_nm,
                motor_torque_nm: None,
                stiffness_motor_rad: r.stiffness_motor_rad,
            };
            match encode(&sample) {
                Ok(bytes) => sample_pub.put(bytes).await.map_err(z)?,
                Err(e) => eprintln!("rig-joint {}: sample not sent: {e}", opts.joint),
            }
            if let Some((deflection_rad, torque_nm, link_rad)) = r.truth {
                let truth = SimTruth {
                    joint: index,
                    seq: report.samples,
                    t_acq_ns: t_acq,
                    deflection_rad,
                    torque_nm,
                    link_rad,
                };
                if let Ok(bytes) = encode(&truth) {
                    truth_pub.put(bytes).await.map_err(z)?;
                }
            }
        }
    }
    let (k, v) = publish_status(JointState::Stopped, format!("joint {} stopped", opts.joint));
    if let Ok(bytes) = v {
        session.put(&k, bytes).await.map_err(z)?;
    }
    session.close().await.map_err(z)?;
    Ok(report)
}
