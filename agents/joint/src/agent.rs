//! The joint agent's Zenoh loop: sample at the configured rate on the rig's tick grid, publish
//! the sample (and, simulated, the truth), apply commands the guard accepts, report the rest.
//!
//! One agent serves one joint board: usually one joint, but a board that drives several
//! joints on one bus (paper B's U2D2 drives all eight servos) serves them all from one
//! session and one loop — each joint keeps its own guard, command and status keys and
//! liveliness token, and each tick's samples leave as one board message (kind 9 on
//! `rig/<rig>/board/<board>/sample`): one message per tick instead of one per joint.

use std::time::Duration;

use rig_config::{JointKind, RigConfig};
use rig_protocol::{
    BoardSample, JointCommand, JointSample, JointState, JointStatus, Keys, Message, SimTruth,
    decode, encode,
};
use rig_runtime::{NetOverrides, now_ns, open, publisher, zenoh, zenoh_err as z};
use thiserror::Error;

use crate::board::{
    Applied, BoardError, BoardRunner, JointBoard, Reading, SafeState, WatchdogAction, joint_index,
    unknown_joint,
};
use crate::guard::{GuardLimits, JointGuard, Verdict};
use crate::hardware::{BoardPlan, DynamixelBoard, PortOverrides};

/// Errors that stop the agent (bad input never does: it is reported and dropped).
#[derive(Debug, Error)]
pub enum AgentError {
    #[error(transparent)]
    Board(#[from] BoardError),
    #[error(transparent)]
    Runtime(#[from] rig_runtime::RuntimeError),
    /// No certificate fits what the agent serves.
    #[error("{0}")]
    Identity(String),
    /// A joint named twice in what the agent serves.
    #[error("joint {0} is named twice in --joint: a board serves each of its joints once")]
    JointTwice(String),
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
    /// Start of the rig's time [ns since the UNIX epoch]: the simulated world's zero.
    pub start_ns: u64,
    /// Stop after this long (None: until shutdown).
    pub duration: Option<Duration>,
    /// Where readings come from.
    pub backend: BackendKind,
}

/// The board an agent runs.
#[derive(Debug, Clone)]
pub enum BackendKind {
    /// The simulated joints, their sensors seeded (joint `j` with `seed + j`), with
    /// undeclared effects (none by default). Needs the `sim` feature.
    Sim {
        seed: u64,
        #[cfg(feature = "sim")]
        effects: rig_sim::effects::Effects,
    },
    /// Dynamixel servos and the encoder bridge, at the config's ports or these.
    Dynamixel(PortOverrides),
}

impl Default for BackendKind {
    fn default() -> Self {
        BackendKind::Sim {
            seed: 1,
            #[cfg(feature = "sim")]
            effects: Default::default(),
        }
    }
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
        max_clock_offset_s: cfg.clock.max_offset_s,
        actuator_name: name,
        actuator_unit: unit,
        actuator_scale: scale,
    }
}

/// One joint of the board: its simulated hardware, guard, keys and counters.
struct Served {
    name: String,
    index: u16,
    /// This joint's place on the board.
    k: usize,
    guard: JointGuard,
    limits: GuardLimits,
    /// The joint's own sample key: a board of one joint (a board of several sends one board
    /// message per tick instead).
    sample_pub: Option<zenoh::pubsub::Publisher<'static>>,
    truth_pub: zenoh::pubsub::Publisher<'static>,
    commands: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    status_key: String,
    status_seq: u64,
    /// Where the joint's stiffness actuator was at the last reading (the guard's reference).
    actuator: f64,
    report: AgentReport,
    /// Samples the encoder refused (non-finite readings): said at the 1st, 10th, 100th…
    unsent: rig_runtime::LogBudget,
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
    async fn commands(
        &mut self,
        session: &zenoh::Session,
        board: &mut BoardRunner,
        now: u64,
    ) -> Result<(), AgentError> {
        while let Ok(Some(s)) = self.commands.try_recv() {
            let bytes = s.payload().to_bytes();
            let verdict = match decode::<JointCommand>(&bytes) {
                Err(e) => {
                    self.report.malformed += 1;
                    if rig_runtime::worth_a_line(self.report.malformed) {
                        eprintln!(
                            "rig-joint {}: dropped a malformed command: {e} ({} malformed so far)",
                            self.name, self.report.malformed
                        );
                    }
                    continue;
                }
                Ok(cmd) => self.guard.on_command(&cmd, now, self.actuator),
            };
            match verdict {
                Verdict::Accepted {
                    actuator_goal,
                    motor_goal,
                    torque_enable,
                } => {
                    let k = self.k;
                    let applied = board
                        .call(move |b| {
                            if let Some(g) = actuator_goal {
                                b.set_actuator_goal(k, g);
                            }
                            b.apply(k, motor_goal, torque_enable)
                        })
                        .await??;
                    match applied {
                        Applied::Done => self.report.commands_accepted += 1,
                        Applied::Refused(why) => {
                            self.report.commands_rejected += 1;
                            self.status(session, JointState::Rejected, why).await?;
                        }
                    }
                }
                Verdict::Rejected(why) => {
                    self.report.commands_rejected += 1;
                    self.status(session, JointState::Rejected, why).await?;
                }
            }
        }
        if let Some(state) = self.guard.on_tick(now, self.actuator) {
            let (k, hold_at) = (self.k, self.guard.goal());
            let what = match board.call(move |b| b.on_watchdog(k, hold_at)).await?? {
                WatchdogAction::Held => {
                    format!("holding the {} where it is", self.limits.actuator_name)
                }
                WatchdogAction::TorqueOff => "torque off".to_string(),
            };
            let text = format!(
                "no command for {:.0} ms: {what}",
                self.limits.watchdog_s * 1e3,
            );
            self.status(session, state, text).await?;
        }
        Ok(())
    }

    /// The sample of this joint's reading taken at grid time `t_acq`, or None when the
    /// protocol refuses it (a non-finite reading: counted and said at the 1st, 10th, 100th…).
    fn sample(&mut self, t_acq: u64, r: &Reading) -> Option<JointSample> {
        self.report.samples += 1;
        self.actuator = r.actuator;
        let sample = JointSample {
            joint: self.index,
            seq: self.report.samples,
            t_acq_ns: t_acq,
            motor_rad: r.motor_rad,
            deflection_rad: r.deflection_rad,
            pivot_m: r.pivot_m,
            torque_nm: r.torque_nm,
            motor_torque_nm: r.motor_torque_nm,
            stiffness_motor_rad: r.stiffness_motor_rad,
        };
        match sample.validate() {
            Ok(()) => Some(sample),
            Err(e) => {
                if let Some(n) = self.unsent.count() {
                    eprintln!(
                        "rig-joint {}: sample not sent: {e} ({n} not sent so far)",
                        self.name
                    );
                }
                None
            }
        }
    }

    /// Publishes the simulated truth of the reading taken at `t_acq` (simulated boards only).
    async fn truth(&self, t_acq: u64, r: &Reading) -> Result<(), AgentError> {
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

/// Publishes one tick's readings: each joint's sample on its key (a board of one joint), or
/// all of them as one board message; then the simulated truths.
async fn publish_tick(
    served: &mut [Served],
    board_pub: Option<&zenoh::pubsub::Publisher<'static>>,
    t_acq: u64,
    readings: &[Reading],
) -> Result<(), AgentError> {
    let mut samples = Vec::with_capacity(served.len());
    for (joint, r) in served.iter_mut().zip(readings) {
        let Some(sample) = joint.sample(t_acq, r) else {
            continue;
        };
        match &joint.sample_pub {
            Some(p) => {
                // Validated above: encoding cannot refuse it.
                if let Ok(bytes) = encode(&sample) {
                    p.put(bytes).await.map_err(z)?;
                }
            }
            None => samples.push(sample),
        }
    }
    if let (Some(p), false) = (board_pub, samples.is_empty()) {
        // Each sample is valid and each joint served once (checked at the start): a board
        // message the protocol refuses would be a bug, said rather than dropped in silence.
        match encode(&BoardSample { samples }) {
            Ok(bytes) => p.put(bytes).await.map_err(z)?,
            Err(e) => {
                if let Some(first) = served.first_mut()
                    && let Some(n) = first.unsent.count()
                {
                    eprintln!("rig-joint: board message not sent: {e} ({n} not sent so far)");
                }
            }
        }
    }
    for (joint, r) in served.iter().zip(readings) {
        joint.truth(t_acq, r).await?;
    }
    Ok(())
}

/// Opens the board of joints `js` (indices into the config): a simulation inline, hardware
/// on a thread that owns its ports (the plan is checked before any port is touched).
async fn open_board(opts: &AgentOptions, js: &[usize]) -> Result<BoardRunner, BoardError> {
    match &opts.backend {
        #[cfg(feature = "sim")]
        BackendKind::Sim { seed, effects } => {
            let b = crate::sim_board::SimBoard::new(&opts.cfg, js, *seed, *effects)?;
            Ok(BoardRunner::inline(Box::new(b)))
        }
        #[cfg(not(feature = "sim"))]
        BackendKind::Sim { .. } => Err(BoardError::NoSimulator),
        BackendKind::Dynamixel(ports) => {
            let plan = BoardPlan::from_config(&opts.cfg, js, ports)?;
            BoardRunner::on_thread(move || {
                let b = DynamixelBoard::open(&plan)?;
                Ok(Box::new(b) as Box<dyn JointBoard>)
            })
            .await
        }
    }
}

/// A fault: every joint reports it, the board goes to its safe state (torque off), and the
/// error ends the agent.
async fn fault(
    session: &zenoh::Session,
    served: &mut [Served],
    board: Option<&mut BoardRunner>,
    e: AgentError,
) -> AgentError {
    let mut text = format!("fault: {e}");
    if let Some(b) = board {
        match b.call(|b| b.safe_state()).await {
            Ok(SafeState::NothingToSwitch) => {}
            Ok(SafeState::TorqueOff) => text.push_str("; torque off"),
            Ok(SafeState::TorqueOffFailed(failed)) => {
                text.push_str("; torque off failed on some servos");
                for f in failed {
                    eprintln!("rig-joint: torque off: {f}");
                }
            }
            // The board's thread is gone: its Drop has turned torque off, or tried to.
            Err(_) => text.push_str("; the board's thread stopped (its drop turns torque off)"),
        }
    }
    for joint in served.iter_mut() {
        let _ = joint.status(session, JointState::Fault, text.clone()).await;
    }
    // Closing drops what is still queued: give the statuses time to leave.
    tokio::time::sleep(Duration::from_millis(50)).await;
    let _ = session.close().await;
    e
}

/// Runs the agent until `shutdown` resolves or the duration ends; one report per joint, in
/// the order of `opts.joints`.
pub async fn run(
    opts: AgentOptions,
    shutdown: impl std::future::Future<Output = ()>,
) -> Result<Vec<AgentReport>, AgentError> {
    let cfg = &opts.cfg;
    if opts.joints.is_empty() {
        return Err(unknown_joint(cfg, "").into());
    }
    let js = opts
        .joints
        .iter()
        .map(|n| joint_index(cfg, n))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some((k, _)) = js.iter().enumerate().find(|(k, j)| js[..*k].contains(j)) {
        return Err(AgentError::JointTwice(opts.joints[k].clone()));
    }
    let keys = Keys::new(&cfg.name)?;
    // Under [security] a board presents its joint's certificate; an agent serving several
    // joints presents that of the plan's machine that runs them (or `--identity`), or its
    // samples would be refused.
    let who = match rig_config::board_identity(cfg, &opts.joints) {
        Some(who) => who,
        None if cfg.security.is_none() || opts.net.identity.is_some() => {
            rig_config::Identity::Joint(opts.joints[0].clone())
        }
        None => {
            return Err(AgentError::Identity(format!(
                "serving joints {} under [security] needs one certificate that may publish for all of them: put them on one machine of the plan ([[machine]] roles) or give --identity machine-<name> (docs/SECURITY.md)",
                opts.joints.join(",")
            )));
        }
    };
    let session = open(cfg, &opts.net, &who).await?;
    // A board of several joints sends each tick as one message on its board key.
    let board_pub = match opts.joints.len() {
        1 => None,
        _ => Some(
            publisher(
                &session,
                keys.board_sample(&rig_config::board_name(cfg, &opts.joints))?,
            )
            .await?,
        ),
    };
    let mut served = Vec::new();
    for (k, (name, &j)) in opts.joints.iter().zip(&js).enumerate() {
        let limits = guard_limits(cfg, j);
        served.push(Served {
            name: name.clone(),
            index: j as u16,
            k,
            guard: JointGuard::new(j as u16, limits, f64::NAN),
            limits,
            sample_pub: match board_pub {
                None => Some(publisher(&session, keys.joint_sample(name)?).await?),
                Some(_) => None,
            },
            truth_pub: publisher(&session, keys.sim_truth(name)?).await?,
            commands: session
                .declare_subscriber(keys.joint_command(name)?)
                .await
                .map_err(z)?,
            status_key: keys.joint_status(name)?,
            status_seq: 0,
            actuator: f64::NAN,
            report: AgentReport::default(),
            unsent: rig_runtime::LogBudget::default(),
            _token: session
                .liveliness()
                .declare_token(keys.alive("joint", name)?)
                .await
                .map_err(z)?,
        });
    }
    // The hardware is opened once every joint can report what went wrong.
    let mut board = match open_board(&opts, &js).await {
        Ok(b) => b,
        Err(e) => return Err(fault(&session, &mut served, None, e.into()).await),
    };
    let ks: Vec<usize> = served.iter().map(|j| j.k).collect();
    let actuators = match board
        .call(move |b| ks.iter().map(|&k| b.actuator(k)).collect::<Vec<_>>())
        .await
    {
        Ok(a) => a,
        Err(e) => return Err(fault(&session, &mut served, Some(&mut board), e.into()).await),
    };
    // A rate the board's read cycle cannot keep is said loudly, before the first tick.
    let rate_hz = opts.cfg.rate_hz;
    let pace = match board.call(move |b| b.pace(rate_hz)).await {
        Ok(Ok(p)) => p,
        Ok(Err(e)) | Err(e) => {
            return Err(fault(&session, &mut served, Some(&mut board), e.into()).await);
        }
    };
    if let Some(p) = &pace {
        eprintln!("rig-joint: {p}");
    }
    for (joint, actuator) in served.iter_mut().zip(actuators) {
        joint.actuator = actuator;
        joint.guard = JointGuard::new(joint.index, joint.limits, actuator);
        let mut text = format!("joint {} up ({} backend)", joint.name, board.name());
        if let Some(p) = &pace {
            text.push_str(&format!("; {p}"));
        }
        joint.status(&session, JointState::Ok, text).await?;
    }

    let result = sample_loop(
        &opts,
        &session,
        &mut served,
        board_pub.as_ref(),
        &mut board,
        shutdown,
    )
    .await;
    if let Err(e) = result {
        return Err(fault(&session, &mut served, Some(&mut board), e).await);
    }
    let safe = board.call(|b| b.safe_state()).await;
    let mut reports = Vec::new();
    for mut joint in served {
        let text = match &safe {
            Ok(SafeState::NothingToSwitch) => format!("joint {} stopped", joint.name),
            Ok(SafeState::TorqueOff) => format!("joint {} stopped; torque off", joint.name),
            Ok(SafeState::TorqueOffFailed(failed)) => format!(
                "joint {} stopped; torque off failed: {}",
                joint.name,
                failed.join("; ")
            ),
            Err(e) => format!("joint {} stopped; {e}", joint.name),
        };
        joint.status(&session, JointState::Stopped, text).await?;
        reports.push(joint.report);
    }
    // Closing drops what is still queued: give the last statuses time to leave.
    tokio::time::sleep(Duration::from_millis(50)).await;
    session.close().await.map_err(z)?;
    Ok(reports)
}

/// Samples on the tick grid until `shutdown` or the duration's end.
async fn sample_loop(
    opts: &AgentOptions,
    session: &zenoh::Session,
    served: &mut [Served],
    board_pub: Option<&zenoh::pubsub::Publisher<'static>>,
    board: &mut BoardRunner,
    shutdown: impl std::future::Future<Output = ()>,
) -> Result<(), AgentError> {
    // Let gossip link this peer to the rig's other peers (estimator, recorders, viewers)
    // before the first sample: in peer-to-peer mode a sample reaches only peers already linked.
    tokio::time::sleep(SETTLE).await;
    let period_ns = (1e9 / opts.cfg.rate_hz).round() as u64;
    let mut ticks =
        rig_runtime::Ticks::new(Duration::from_nanos(period_ns), opts.duration, shutdown);
    let mut last_tick: Option<u64> = None;
    let hardware = !board.reads_the_past();
    while ticks.next().await {
        let now = now_ns();
        let tick = now / period_ns;
        // Every grid tick since the last wake-up is sampled (the timer wakes at ~1 ms
        // granularity); more than MAX_CATCH_UP behind, the older ticks are skipped and counted.
        // Hardware reads only the present: the latest tick, the others counted as skipped.
        let first = match last_tick {
            Some(l) if tick <= l => continue,
            Some(_) if hardware => tick,
            Some(l) => (l + 1).max(tick.saturating_sub(MAX_CATCH_UP)),
            None => tick,
        };
        let skipped = last_tick.map_or(0, |l| first.saturating_sub(l + 1));
        // Commands first: they apply from this tick on.
        for joint in served.iter_mut() {
            joint.report.skipped_ticks += skipped;
            joint.commands(session, board, now).await?;
        }
        for t in first..=tick {
            let dt = last_tick.map_or(1, |l| t.saturating_sub(l)) as f64 * period_ns as f64 * 1e-9;
            last_tick = Some(t);
            let t_acq = t * period_ns;
            let t_world = t_acq.saturating_sub(opts.start_ns) as f64 * 1e-9;
            let readings = board.call(move |b| b.read(t_world, dt)).await??;
            publish_tick(served, board_pub, t_acq, &readings).await?;
        }
    }
    Ok(())
}
