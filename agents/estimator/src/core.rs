//! The estimator host's core, sans I/O: joint samples in, estimates and status out.
//!
//! - **Alignment by time**: samples are grouped by acquisition tick, round(t_acq / Ts); a tick
//!   is processed when every joint has reported it, in tick order. A tick some joints never
//!   report is processed without them once `max_lag` newer ticks have been seen (their models
//!   skip it; what needs every joint — the end-effector estimate — is withheld and counted).
//! - **Start**: incomplete ticks before the first complete one are dropped, so the models
//!   start on the same tick whatever order the first samples arrived in.
//! - **Staleness**: a joint whose samples stop for `stale_after` is marked stale with a status
//!   saying why; nothing that depends on it is published until it returns, which is announced.
//! - **Per joint**: paper B's restoring-torque model for a lever VSA; paper A's decoupled
//!   impedance observer for an AWAS joint with a torque sensor.
//! - **Robot**: loop closure, force and operational stiffness ([`RobotEstimator`], the code
//!   `rig reproduce` uses).

use std::collections::BTreeMap;

use crate::clock::{ClockEvent, ClockWatch};
use rig_config::{JointKind, RigConfig, Topology};
use rig_model::estimator::{JointReadings, RobotEstimator};
use rig_model::hysteresis::RestoringTorqueModel;
use rig_model::live::LiveJoint;
use rig_model::monitor::ResidualMonitor;
use rig_model::observer::{DecoupledObserver, ImpedanceSample};
use rig_protocol::{
    BoardSample, EeEstimate, JointEstimate, JointSample, JointState, JointStatus, StiffnessTriple,
};
use thiserror::Error;

/// Errors building the core.
#[derive(Debug, Error)]
pub enum CoreError {
    /// The config asks for something the estimator does not do (the text says what).
    #[error("estimator: {0}")]
    Setup(String),
    #[error("estimator: the robot's force estimator: {0}")]
    Robot(#[from] rig_model::estimator::EstimateError),
    #[error("estimator: the impedance observer: {0}")]
    Observer(#[from] rig_model::observer::ObserverError),
}

/// What the core wants published.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    Joint(JointEstimate),
    Ee(EeEstimate),
    Status(JointStatus),
}

/// Counters for summaries and tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CoreStats {
    pub samples: u64,
    pub ticks_processed: u64,
    pub ticks_incomplete: u64,
    pub late_dropped: u64,
    pub joint_estimates: u64,
    pub ee_estimates: u64,
    pub ee_withheld: u64,
    /// Incomplete ticks before the first complete one, dropped so that every model starts
    /// on the same tick whatever the arrival order (what makes offline replays exact).
    pub startup_skipped: u64,
    pub errors: u64,
    /// Samples refused: stamped further from this host's clock than the bound.
    pub refused_clock: u64,
    /// Samples refused: a sequence number and a stamp that do not advance (a replay).
    pub refused_replay: u64,
    /// Samples refused: a pivot outside the joint's travel.
    pub refused_range: u64,
    /// Samples refused: the payload's joint is not the one of the key it came on (or, on a
    /// board's key, one the board does not run).
    pub refused_key: u64,
    /// Samples missing from the accepted samples' sequence numbers (gaps; a restarted agent
    /// starts over). Counted after the checks above, so a refused sample cannot make a gap
    /// (a forged far sequence number would have); one refused between two accepted ones is
    /// in its refusal count and, the models never having seen it, in this gap too.
    pub lost: u64,
}

enum PerJoint {
    /// Lever joints of a robot (their models live in the robot estimator).
    Robot(Box<RobotEstimator>),
    /// Joints on their own (a single joint or a bench), each with its model.
    Alone(Vec<JointModel>),
}

enum JointModel {
    Lever(Box<LiveJoint>),
    Awas(Box<DecoupledObserver>),
}

/// How long a joint that never reported may take to come up before it is called stale.
pub const STARTUP_GRACE_NS: u64 = 5_000_000_000;

/// Timing parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoreTiming {
    /// Sample period [ns].
    pub period_ns: u64,
    /// A joint is stale after this long without a sample [ns].
    pub stale_after_ns: u64,
    /// Ticks to wait for a missing joint before processing without it.
    pub max_lag: u64,
    /// A sample stamped further than this from the host's clock is refused [ns].
    pub max_clock_offset_ns: u64,
}

/// The default bound on a sample's stamp against the host's clock [ns]: far above a sample's
/// transit (≤ 1 ms on a lab network), far below the hour a wrong clock or a forger can give.
pub const MAX_CLOCK_OFFSET_NS: u64 = 100_000_000;

impl CoreTiming {
    /// 1/rate periods, stale after 200 ms, wait up to 20 ticks, stamps within 100 ms.
    pub fn for_rate(rate_hz: f64) -> Self {
        Self {
            period_ns: (1e9 / rate_hz).round() as u64,
            stale_after_ns: 200_000_000,
            max_lag: 20,
            max_clock_offset_ns: MAX_CLOCK_OFFSET_NS,
        }
    }

    /// [`Self::for_rate`] at the config's rate, with its `[clock] max_offset_ms`.
    pub fn for_config(cfg: &RigConfig) -> Self {
        Self {
            max_clock_offset_ns: (cfg.clock.max_offset_s * 1e9).round() as u64,
            ..Self::for_rate(cfg.rate_hz)
        }
    }
}

/// Why a joint's samples are being refused (one status when it starts, one when it ends).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Refusal {
    /// Stamped this far from the host's clock [ns] (positive: ahead).
    Clock(i128),
    /// The pivot this far outside the travel [m].
    Range(f64),
}

/// The estimator host's core.
pub struct EstimatorCore {
    names: Vec<String>,
    timing: CoreTiming,
    per: PerJoint,
    pending: BTreeMap<u64, Vec<Option<JointSample>>>,
    newest_tick: Option<u64>,
    last_processed: Option<u64>,
    seen_complete: bool,
    last_seen_ns: Vec<Option<u64>>,
    started_ns: Option<u64>,
    stale: Vec<bool>,
    status_seq: u64,
    ee_seq: u64,
    /// Residual monitors, one per joint, made at the joint's first torque-sensor reading.
    monitors: Vec<Option<ResidualMonitor>>,
    /// Per joint: the last accepted (seq, stamp), what its samples are refused for now, and
    /// its pivot travel with a 1 mm margin (lever joints).
    last_accepted: Vec<Option<(u64, u64)>>,
    refusing: Vec<Option<Refusal>>,
    pivot_range: Vec<Option<(f64, f64)>>,
    /// Per joint: the config's `[joint.effects]`, applied to each accepted sample.
    effects: Vec<rig_config::JointEffects>,
    /// Each board's clock against this host's, from the accepted samples.
    clock: ClockWatch,
    /// The config, for which boards may carry which joints ([`rig_config::board_may_carry`]),
    /// and per board key seen, that answer for each joint.
    boards_cfg: RigConfig,
    board_carries: std::collections::HashMap<String, Vec<bool>>,
    pub stats: CoreStats,
}

/// Board keys whose allowed joints are remembered.
const MAX_BOARDS_REMEMBERED: usize = 256;

/// How often each board's clock offset is estimated [ns].
pub const CLOCK_WINDOW_NS: u64 = 1_000_000_000;

/// How far a reported pivot may lie outside the configured travel before it is refused [m]
/// (an encoder count or a servo's overshoot is far less).
const PIVOT_MARGIN_M: f64 = 1e-3;

impl std::fmt::Debug for EstimatorCore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EstimatorCore")
            .field("joints", &self.names)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl EstimatorCore {
    /// A core for the rig in `cfg`.
    pub fn new(cfg: &RigConfig, timing: CoreTiming) -> Result<Self, CoreError> {
        let n = cfg.joints.len();
        let lever_model = |k: &JointKind| match k {
            JointKind::Lever {
                restoring,
                dead_band_rad,
                ..
            } => Ok(RestoringTorqueModel::new(
                (**restoring).clone(),
                *dead_band_rad,
            )),
            JointKind::Awas { .. } => Err(CoreError::Setup(
                "robots are built from lever joints".into(),
            )),
        };
        let per = match cfg.topology {
            Topology::Serial | Topology::Parallel => {
                let robot = cfg
                    .robot()
                    .ok_or_else(|| CoreError::Setup("no robot geometry".into()))?;
                let models = cfg
                    .joints
                    .iter()
                    .map(|j| lever_model(&j.kind).map(|m| LiveJoint::new(m, j.effects.live)))
                    .collect::<Result<Vec<_>, _>>()?;
                PerJoint::Robot(Box::new(RobotEstimator::new(robot, models)?))
            }
            Topology::Single | Topology::Bench => {
                let ts = timing.period_ns as f64 * 1e-9;
                let o = cfg.observer;
                let model = |j: &rig_config::JointConfig| -> Result<JointModel, CoreError> {
                    Ok(match &j.kind {
                        JointKind::Lever {
                            restoring,
                            dead_band_rad,
                            ..
                        } => JointModel::Lever(Box::new(LiveJoint::new(
                            RestoringTorqueModel::new((**restoring).clone(), *dead_band_rad),
                            j.effects.live,
                        ))),
                        JointKind::Awas { dynamics, .. } => {
                            let motor = Some(rig_model::observer::MotorParams {
                                b1: dynamics.b1,
                                d1: dynamics.d1,
                            });
                            JointModel::Awas(Box::new(DecoupledObserver::new(
                                o.ekf(ts),
                                o.alpha,
                                o.k0,
                                motor,
                            )?))
                        }
                    })
                };
                PerJoint::Alone(cfg.joints.iter().map(model).collect::<Result<_, _>>()?)
            }
        };
        Ok(Self {
            names: cfg.joints.iter().map(|j| j.name.clone()).collect(),
            timing,
            per,
            pending: BTreeMap::new(),
            newest_tick: None,
            last_processed: None,
            seen_complete: false,
            last_seen_ns: vec![None; n],
            started_ns: None,
            stale: vec![false; n],
            status_seq: 0,
            ee_seq: 0,
            monitors: vec![None; n],
            last_accepted: vec![None; n],
            refusing: vec![None; n],
            pivot_range: cfg
                .joints
                .iter()
                .map(|j| match &j.kind {
                    JointKind::Lever { vsa, .. } => {
                        Some((vsa.d_min - PIVOT_MARGIN_M, vsa.d_max + PIVOT_MARGIN_M))
                    }
                    JointKind::Awas { .. } => None,
                })
                .collect(),
            effects: cfg.joints.iter().map(|j| j.effects).collect(),
            clock: ClockWatch::new(n, timing.period_ns, CLOCK_WINDOW_NS),
            boards_cfg: cfg.clone(),
            board_carries: std::collections::HashMap::new(),
            stats: CoreStats::default(),
        })
    }

    /// Joint names, in index order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Which joints are stale now.
    pub fn stale(&self) -> &[bool] {
        &self.stale
    }

    /// Each joint's board clock against this host's, the last estimate [ns] (positive: the
    /// board is ahead; one way, low by the smallest transit: [`crate::clock`]).
    pub fn clock_offsets_ns(&self) -> &[Option<i64>] {
        self.clock.offsets_ns()
    }

    /// The status a clock event makes.
    fn clock_status(&mut self, e: ClockEvent, now_ns: u64) -> Output {
        let half_tick_ms = self.timing.period_ns as f64 * 0.5e-6;
        let (j, text) = match e {
            ClockEvent::Measured { joint, offset_ns } => (
                joint,
                format!(
                    "clock measured: the board is {:+.3} ms from this host (one way: the smallest arrival delay over {:.0} s, transit included)",
                    offset_ns as f64 * 1e-6,
                    CLOCK_WINDOW_NS as f64 * 1e-9
                ),
            ),
            ClockEvent::Beyond { joint, offset_ns } => (
                joint,
                format!(
                    "clock {:+.3} ms from this host, over half a tick ({half_tick_ms:.2} ms): its samples land in other ticks than its peers'; synchronise the board (chrony, PTP)",
                    offset_ns as f64 * 1e-6
                ),
            ),
            ClockEvent::Within { joint, offset_ns } => (
                joint,
                format!(
                    "clock back within half a tick: {:+.3} ms from this host",
                    offset_ns as f64 * 1e-6
                ),
            ),
        };
        let text = format!("joint {}: {text}", self.names[j]);
        self.status(j, JointState::Ok, text, now_ns)
    }

    fn status(&mut self, joint: usize, state: JointState, text: String, now_ns: u64) -> Output {
        self.status_seq += 1;
        Output::Status(JointStatus {
            joint: joint as u16,
            seq: self.status_seq,
            t_ns: now_ns.max(1),
            state,
            text,
        })
    }

    /// Feeds one sample that arrived on joint `key_joint`'s key: refused and counted when the
    /// payload names another joint (a forged or misrouted sample), else [`Self::on_sample`].
    pub fn on_sample_from(&mut self, key_joint: &str, s: JointSample, now_ns: u64) -> Vec<Output> {
        if self.names.get(s.joint as usize).map(String::as_str) != Some(key_joint) {
            self.stats.refused_key += 1;
            return Vec::new();
        }
        self.on_sample(s, now_ns)
    }

    /// Feeds a board's tick that arrived on board `board`'s key, sample by sample (as if each
    /// had come on its joint's key). A sample of a joint the board may not carry (a machine of
    /// the plan carries the joints it runs) is refused and counted like one on another
    /// joint's key.
    pub fn on_board_sample_from(
        &mut self,
        board: &str,
        b: BoardSample,
        now_ns: u64,
    ) -> Vec<Output> {
        // Remembered for the first boards seen (a peer inventing board names cannot grow it).
        let carries: Vec<bool> = match self.board_carries.get(board) {
            Some(c) => c.clone(),
            None => {
                let c: Vec<bool> = self
                    .names
                    .iter()
                    .map(|j| rig_config::board_may_carry(&self.boards_cfg, board, j))
                    .collect();
                if self.board_carries.len() < MAX_BOARDS_REMEMBERED {
                    self.board_carries.insert(board.to_string(), c.clone());
                }
                c
            }
        };
        let mut out = Vec::new();
        for s in b.samples {
            let allowed = carries.get(s.joint as usize).copied().unwrap_or(false);
            if allowed {
                out.extend(self.on_sample(s, now_ns));
            } else {
                self.stats.refused_key += 1;
            }
        }
        out
    }

    /// Why sample `s` of joint `j` cannot be believed, if it cannot: a stamp beyond the
    /// clock bound, a pivot outside the travel. (A replay is refused apart: it says nothing
    /// about the joint's state.)
    fn refusal(&self, j: usize, s: &JointSample, now_ns: u64) -> Option<Refusal> {
        let offset = i128::from(s.t_acq_ns) - i128::from(now_ns);
        if offset.unsigned_abs() > u128::from(self.timing.max_clock_offset_ns) {
            return Some(Refusal::Clock(offset));
        }
        if let (Some((lo, hi)), Some(d)) = (self.pivot_range[j], s.pivot_m)
            && !(lo..=hi).contains(&d)
        {
            return Some(Refusal::Range(if d < lo { d - lo } else { d - hi }));
        }
        None
    }

    /// Why joint samples are refused, in words.
    fn refusal_reason(&self, r: Refusal) -> String {
        match r {
            Refusal::Clock(off) => format!(
                "stamped {:+.1} ms from this host's clock, bound ±{:.0} ms: held up on the way (a link that came back) or a board clock that is off (chrony, PTP)",
                off as f64 * 1e-6,
                self.timing.max_clock_offset_ns as f64 * 1e-6
            ),
            Refusal::Range(by) => format!("the pivot {:+.1} mm outside its travel", by * 1e3),
        }
    }

    /// Feeds one (validated) sample that arrived at local time `now_ns`. Refused and counted
    /// (never fed to a model): a stamp further than the clock bound from `now_ns`, a pivot
    /// outside the travel, a sequence number and stamp that do not advance. A joint whose
    /// samples start or stop being refused gets a status; one whose samples are all refused
    /// goes stale, the status naming why.
    pub fn on_sample(&mut self, s: JointSample, now_ns: u64) -> Vec<Output> {
        let mut out = Vec::new();
        let j = s.joint as usize;
        if j >= self.names.len() {
            self.stats.errors += 1;
            return out;
        }
        self.started_ns.get_or_insert(now_ns);
        if let Some(r) = self.refusal(j, &s, now_ns) {
            match r {
                Refusal::Clock(_) => self.stats.refused_clock += 1,
                Refusal::Range(_) => self.stats.refused_range += 1,
            }
            let started = self.refusing[j].is_none();
            self.refusing[j] = Some(r);
            if started {
                let text = format!(
                    "joint {}: samples refused: {}",
                    self.names[j],
                    self.refusal_reason(r)
                );
                out.push(self.status(j, JointState::Rejected, text, now_ns));
            }
            return out;
        }
        // A restarted agent counts from 1 again, with a later stamp: only a sample whose
        // sequence number and stamp both fail to advance is a replay.
        if self.last_accepted[j].is_some_and(|(seq, t)| s.seq <= seq && s.t_acq_ns <= t) {
            self.stats.refused_replay += 1;
            return out;
        }
        if let Some((seq, _)) = self.last_accepted[j]
            && s.seq > seq
        {
            self.stats.lost += s.seq - seq - 1;
        }
        self.last_accepted[j] = Some((s.seq, s.t_acq_ns));
        if let Some(e) = self.clock.on_sample(j, s.t_acq_ns, now_ns) {
            out.push(self.clock_status(e, now_ns));
        }
        // The identified sensor zeros (`[joint.effects]`), before any model sees the sample.
        let e = self.effects[j];
        let mut s = s;
        s.deflection_rad -= e.encoder_offset_rad;
        s.torque_nm = s.torque_nm.map(|t| t - e.torque_offset_nm);
        if self.refusing[j].take().is_some() && !self.stale[j] {
            let name = self.names[j].clone();
            out.push(self.status(
                j,
                JointState::Ok,
                format!("joint {name}: samples accepted again"),
                now_ns,
            ));
        }
        self.stats.samples += 1;
        self.last_seen_ns[j] = Some(now_ns);
        if self.stale[j] {
            self.stale[j] = false;
            let name = self.names[j].clone();
            out.push(self.status(
                j,
                JointState::Ok,
                format!("joint {name}: samples resumed"),
                now_ns,
            ));
        }
        let tick = (s.t_acq_ns + self.timing.period_ns / 2) / self.timing.period_ns;
        if self.last_processed.is_some_and(|p| tick <= p) {
            self.stats.late_dropped += 1;
            return out;
        }
        let n = self.names.len();
        self.pending.entry(tick).or_insert_with(|| vec![None; n])[j] = Some(s);
        self.newest_tick = Some(self.newest_tick.map_or(tick, |t| t.max(tick)));
        self.drain(&mut out);
        out
    }

    /// Periodic check at local time `now_ns`: staleness, and ticks waiting on stale joints.
    pub fn on_tick(&mut self, now_ns: u64) -> Vec<Output> {
        let mut out = Vec::new();
        let start = *self.started_ns.get_or_insert(now_ns);
        for j in 0..self.names.len() {
            let since = self.last_seen_ns[j].unwrap_or(start);
            let silent = now_ns.saturating_sub(since);
            // A joint never heard from gets a start-up grace: agents come up in any order.
            let limit = if self.last_seen_ns[j].is_some() {
                self.timing.stale_after_ns
            } else {
                self.timing.stale_after_ns.max(STARTUP_GRACE_NS)
            };
            if !self.stale[j] && silent > limit {
                self.stale[j] = true;
                let (name, ms, limit) = (
                    self.names[j].clone(),
                    silent as f64 * 1e-6,
                    self.timing.stale_after_ns as f64 * 1e-6,
                );
                let why = match (self.refusing[j], self.last_seen_ns[j]) {
                    (Some(r), _) => format!("every sample refused ({})", self.refusal_reason(r)),
                    (None, Some(_)) => "no sample".to_string(),
                    (None, None) => "no sample yet".to_string(),
                };
                out.push(self.status(
                    j,
                    JointState::Stale,
                    format!("joint {name}: {why} for {ms:.0} ms (limit {limit:.0} ms); end-effector estimates withheld"),
                    now_ns,
                ));
            }
        }
        self.drain(&mut out);
        out
    }

    fn drain(&mut self, out: &mut Vec<Output>) {
        let Some(newest) = self.newest_tick else {
            return;
        };
        while let Some((&tick, slots)) = self.pending.iter().next() {
            let complete = slots
                .iter()
                .enumerate()
                .all(|(j, s)| s.is_some() || self.stale[j]);
            let waited = newest.saturating_sub(tick) >= self.timing.max_lag;
            if !(complete || waited) {
                break;
            }
            let slots = self.pending.remove(&tick).unwrap_or_default();
            self.last_processed = Some(tick);
            let all = slots.iter().all(Option::is_some);
            if !self.seen_complete && !all {
                self.stats.startup_skipped += 1;
                continue;
            }
            self.seen_complete = true;
            self.process(tick, &slots, out);
        }
    }

    fn process(&mut self, tick: u64, slots: &[Option<JointSample>], out: &mut Vec<Output>) {
        self.stats.ticks_processed += 1;
        let all = slots.iter().all(Option::is_some);
        if !all {
            self.stats.ticks_incomplete += 1;
        }
        let t_ns = tick * self.timing.period_ns;
        let mut joint_out = Vec::new();
        match &mut self.per {
            PerJoint::Robot(est) => {
                let mut torque = vec![0.0; slots.len()];
                let mut stiffness = vec![0.0; slots.len()];
                for (j, s) in slots.iter().enumerate() {
                    let Some(s) = s else { continue };
                    let pivot = s.pivot_m.unwrap_or(0.0);
                    let t_s = s.t_acq_ns as f64 * 1e-9;
                    let Some((live, k)) =
                        est.update_joint(j, t_s, s.deflection_rad, pivot, s.torque_nm)
                    else {
                        continue;
                    };
                    let tau = live.torque_nm;
                    torque[j] = tau;
                    stiffness[j] = k;
                    joint_out.push(JointEstimate {
                        joint: j as u16,
                        seq: s.seq,
                        t_acq_ns: s.t_acq_ns,
                        torque_nm: tau,
                        stiffness_nm_per_rad: Some(k),
                        inertia_kg_m2: None,
                        inertia_var: None,
                        damping_nms_per_rad: None,
                        damping_var: None,
                        residual_nm: live.residual_nm,
                    });
                }
                if all {
                    let motor: Vec<f64> = slots.iter().flatten().map(|s| s.motor_rad).collect();
                    let defl: Vec<f64> = slots.iter().flatten().map(|s| s.deflection_rad).collect();
                    let pivot: Vec<f64> = slots
                        .iter()
                        .flatten()
                        .map(|s| s.pivot_m.unwrap_or(0.0))
                        .collect();
                    match est.combine(
                        &JointReadings {
                            t_s: t_ns as f64 * 1e-9,
                            motor: &motor,
                            deflection: &defl,
                            pivot: &pivot,
                        },
                        torque,
                        stiffness,
                    ) {
                        Ok(e) => {
                            self.ee_seq += 1;
                            let k = e.operational_stiffness;
                            out.push(Output::Ee(EeEstimate {
                                seq: self.ee_seq,
                                t_ns,
                                stale_mask: 0,
                                x_m: e.configuration.pose.x,
                                y_m: e.configuration.pose.y,
                                phi_rad: e.configuration.pose.phi,
                                force_n: Some((e.force[0], e.force[1])),
                                stiffness_n_per_m: Some(StiffnessTriple {
                                    xx: k[(0, 0)],
                                    xy: k[(0, 1)],
                                    yy: k[(1, 1)],
                                }),
                            }));
                            self.stats.ee_estimates += 1;
                        }
                        Err(_) => self.stats.errors += 1,
                    }
                } else {
                    self.stats.ee_withheld += 1;
                }
            }
            PerJoint::Alone(models) => {
                for (j, (s, model)) in slots.iter().zip(models.iter_mut()).enumerate() {
                    let Some(s) = s else { continue };
                    if let Some(e) = estimate_alone(j as u16, s, model) {
                        joint_out.push(e);
                    } else {
                        self.stats.errors += 1;
                    }
                }
            }
        }
        self.stats.joint_estimates += joint_out.len() as u64;
        // Where a torque sensor measures what the model predicts, watch the residual.
        let mut diagnoses = Vec::new();
        // 2 s windows, looked at every 0.25 s.
        let per_s = 1e9 / self.timing.period_ns.max(1) as f64;
        let n = self.names.len();
        // Each joint's fits on its own ticks (`staggered`): not all of them on one.
        let new = |j: usize| {
            move || {
                ResidualMonitor::new(
                    (2.0 * per_s).round() as usize,
                    (0.25 * per_s).round() as usize,
                )
                .staggered(j, n)
            }
        };
        for e in &joint_out {
            let j = e.joint as usize;
            if let (Some(r), Some(Some(s)), Some(m)) =
                (e.residual_nm, slots.get(j), self.monitors.get_mut(j))
                && let Some(d) =
                    m.get_or_insert_with(new(j))
                        .push(e.t_acq_ns as f64 * 1e-9, s.deflection_rad, r)
            {
                diagnoses.push((j, d));
            }
        }
        out.extend(joint_out.into_iter().map(Output::Joint));
        for (j, d) in diagnoses {
            let o = self.status(j, JointState::Ok, d.text(), t_ns);
            out.push(o);
        }
    }
}

/// One joint estimated on its own: paper B's restoring torque for a lever VSA, paper A's
/// decoupled observer for an AWAS joint. None when the observer refuses the sample.
fn estimate_alone(joint: u16, s: &JointSample, model: &mut JointModel) -> Option<JointEstimate> {
    match model {
        JointModel::Lever(m) => {
            let pivot = s.pivot_m.unwrap_or(0.0);
            let t_s = s.t_acq_ns as f64 * 1e-9;
            let live = m.update(t_s, s.deflection_rad, pivot, s.torque_nm);
            Some(JointEstimate {
                joint,
                seq: s.seq,
                t_acq_ns: s.t_acq_ns,
                torque_nm: live.torque_nm,
                stiffness_nm_per_rad: Some(m.model().stiffness()),
                inertia_kg_m2: None,
                inertia_var: None,
                damping_nms_per_rad: None,
                damping_var: None,
                residual_nm: live.residual_nm,
            })
        }
        JointModel::Awas(obs) => {
            let sample = ImpedanceSample {
                q: s.motor_rad + s.deflection_rad,
                theta1: s.motor_rad,
                tau_e: s.torque_nm,
                tau1: s.motor_torque_nm,
                tau_ext: 0.0,
            };
            let e = obs.step(&sample).ok()?;
            let link = e.link;
            let finite = |v: Option<f64>| v.filter(|x| x.is_finite());
            Some(JointEstimate {
                joint,
                seq: s.seq,
                t_acq_ns: s.t_acq_ns,
                torque_nm: if e.tau_e.is_finite() { e.tau_e } else { 0.0 },
                stiffness_nm_per_rad: finite(Some(e.stiffness)),
                inertia_kg_m2: finite(link.and_then(|l| l.inertia)).filter(|v| *v >= 0.0),
                inertia_var: finite(link.and_then(|l| l.inertia_var)),
                damping_nms_per_rad: finite(link.and_then(|l| l.damping)),
                damping_var: finite(link.and_then(|l| l.damping_var)),
                residual_nm: None,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> RigConfig {
        rig_config::examples::load("parallel").unwrap()
    }

    fn sample(j: u16, tick: u64, defl: f64) -> JointSample {
        let c = cfg();
        let robot = c.robot().unwrap();
        let home = robot.at_position(0.075, 0.2).unwrap();
        JointSample {
            joint: j,
            seq: tick,
            t_acq_ns: tick * 1_000_000,
            motor_rad: home.theta[j as usize],
            deflection_rad: defl,
            pivot_m: Some(0.009),
            torque_nm: None,
            motor_torque_nm: None,
            stiffness_motor_rad: None,
        }
    }

    fn ee(out: &[Output]) -> usize {
        out.iter().filter(|o| matches!(o, Output::Ee(_))).count()
    }

    #[test]
    fn aligns_by_tick_not_arrival_order() {
        let mut core = EstimatorCore::new(&cfg(), CoreTiming::for_rate(1000.0)).unwrap();
        let mut out = Vec::new();
        // Joint 3 of tick 1 arrives before the others; tick 1 completes only with all four.
        out.extend(core.on_sample(sample(3, 1, 0.0), 10));
        for j in 0..3 {
            assert_eq!(ee(&out), 0);
            out.extend(core.on_sample(sample(j, 1, 0.0), 11));
        }
        assert_eq!(ee(&out), 1);
        assert_eq!(
            out.iter().filter(|o| matches!(o, Output::Joint(_))).count(),
            4
        );
        // A (new) sample for an already processed tick is late and dropped; the same sample
        // again is a replay.
        let mut late = sample(0, 1, 0.0);
        late.seq = 2;
        core.on_sample(late, 12);
        assert_eq!(core.stats.late_dropped, 1);
        core.on_sample(late, 13);
        assert_eq!((core.stats.late_dropped, core.stats.refused_replay), (1, 1));
    }

    #[test]
    fn a_silent_joint_goes_stale_withholds_ee_and_recovers() {
        let t = CoreTiming {
            period_ns: 1_000_000,
            stale_after_ns: 200_000_000,
            max_lag: 20,
            max_clock_offset_ns: MAX_CLOCK_OFFSET_NS,
        };
        let mut core = EstimatorCore::new(&cfg(), t).unwrap();
        let ms = 1_000_000u64;
        let mut ee_count = 0;
        let mut statuses = Vec::new();
        for tick in 1..=1000u64 {
            let now = tick * ms;
            for j in 0..4u16 {
                // Joint 2 is silent between 300 ms and 700 ms.
                if j == 2 && (300..700).contains(&tick) {
                    continue;
                }
                for o in core.on_sample(sample(j, tick, 0.0), now) {
                    ee_count += usize::from(matches!(o, Output::Ee(_)));
                    if let Output::Status(s) = o {
                        statuses.push((tick, s));
                    }
                }
            }
            for o in core.on_tick(now) {
                ee_count += usize::from(matches!(o, Output::Ee(_)));
                if let Output::Status(s) = o {
                    statuses.push((tick, s));
                }
            }
        }
        let stale: Vec<_> = statuses
            .iter()
            .filter(|(_, s)| s.state == JointState::Stale)
            .collect();
        assert_eq!(stale.len(), 1, "{statuses:?}");
        assert_eq!(stale[0].1.joint, 2);
        assert!(
            (500..=502).contains(&stale[0].0),
            "stale after 200 ms of silence: tick {}",
            stale[0].0
        );
        assert!(stale[0].1.text.contains("withheld"));
        let ok: Vec<_> = statuses
            .iter()
            .filter(|(_, s)| s.state == JointState::Ok)
            .collect();
        assert_eq!(ok.len(), 1);
        assert_eq!(ok[0].0, 700, "announced when samples resume");
        // End-effector estimates: every tick but the 400 with joint 2 missing.
        assert_eq!(ee_count, 600, "{:?}", core.stats);
        assert_eq!(core.stats.ee_withheld, 400);
    }

    #[test]
    fn bench_joints_are_estimated_alone_each_like_its_own_model() {
        // Three copies of the parallel example's first joint on a bench.
        let mut c = cfg();
        let template = c.joints[0].clone();
        c.topology = Topology::Bench;
        c.geometry = None;
        c.joints = (0..3)
            .map(|i| {
                let mut j = template.clone();
                j.name = format!("b{i}");
                j.index = i;
                j
            })
            .collect();
        let mut core = EstimatorCore::new(&c, CoreTiming::for_rate(1000.0)).unwrap();
        let JointKind::Lever {
            restoring,
            dead_band_rad,
            ..
        } = &template.kind
        else {
            panic!("the example's joints are lever VSAs")
        };
        // The peer: one standalone model per joint, fed the same deflections.
        let mut peers: Vec<_> = (0..3)
            .map(|_| RestoringTorqueModel::new((**restoring).clone(), *dead_band_rad))
            .collect();
        let defl = |j: u16, tick: u64| 0.02 * (j as f64 + 1.0) * (tick as f64 * 0.01).sin();
        let mut got = 0;
        for tick in 1..=500u64 {
            for j in 0..3u16 {
                let mut s = sample(0, tick, defl(j, tick));
                s.joint = j;
                for o in core.on_sample(s, tick * 1_000_000) {
                    let Output::Joint(e) = o else {
                        panic!("a bench publishes joint estimates only: {o:?}")
                    };
                    let t = e.t_acq_ns / 1_000_000;
                    let want = peers[e.joint as usize].update(defl(e.joint, t), 0.009);
                    assert!(
                        (e.torque_nm - want).abs() < 1e-12,
                        "{} vs {want}",
                        e.torque_nm
                    );
                    got += 1;
                }
            }
        }
        assert_eq!(got, 1500);
        assert_eq!(core.stats.ee_estimates, 0);
    }

    #[test]
    fn a_torque_sensor_offset_that_appears_is_diagnosed_in_a_status() {
        // One bench joint whose torque sensor reads the model's own torque, then, from 3 s
        // on, 0.05 N·m more (a zero that slipped).
        let mut c = cfg();
        c.topology = Topology::Bench;
        c.geometry = None;
        c.joints.truncate(1);
        let mut core = EstimatorCore::new(&c, CoreTiming::for_rate(1000.0)).unwrap();
        let JointKind::Lever {
            restoring,
            dead_band_rad,
            ..
        } = &c.joints[0].kind
        else {
            panic!("the example's joints are lever VSAs")
        };
        let mut sensor = RestoringTorqueModel::new((**restoring).clone(), *dead_band_rad);
        let mut diagnoses = Vec::new();
        for tick in 1..=6000u64 {
            let defl = 0.03 * (tick as f64 * 0.004).sin();
            let mut s = sample(0, tick, defl);
            let noise = 1e-3 * (((tick * 7919) % 1000) as f64 / 1000.0 - 0.5);
            let offset = if tick >= 3000 { 0.05 } else { 0.0 };
            s.torque_nm = Some(sensor.update(defl, 0.009) + offset + noise);
            for o in core.on_sample(s, tick * 1_000_000) {
                if let Output::Status(st) = o
                    && st.text.starts_with("diagnosis:")
                {
                    diagnoses.push((tick, st.text));
                }
            }
        }
        assert!(!diagnoses.is_empty(), "no diagnosis");
        let (tick, text) = &diagnoses[0];
        assert!(*tick > 3000 && *tick < 5500, "seen at {tick}: {text}");
        assert!(
            text.starts_with("diagnosis:") && text.contains("offset"),
            "{text}"
        );
    }

    fn statuses(out: &[Output]) -> Vec<JointStatus> {
        out.iter()
            .filter_map(|o| match o {
                Output::Status(s) => Some(s.clone()),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_sample_stamped_an_hour_ahead_is_refused_once_said_and_estimates_go_on() {
        let mut core = EstimatorCore::new(&cfg(), CoreTiming::for_rate(1000.0)).unwrap();
        let ms = 1_000_000u64;
        let (mut ee_after, mut said) = (0, Vec::new());
        for tick in 1..=300u64 {
            let now = tick * ms;
            for j in 0..4u16 {
                let mut out = core.on_sample(sample(j, tick, 0.0), now);
                if j == 1 && tick == 100 {
                    // A forged (or wrongly clocked) j2 sample, an hour ahead, three times.
                    for k in 0..3 {
                        let mut f = sample(1, tick + 1000 + k, 0.0);
                        f.t_acq_ns = now + 3_600_000_000_000;
                        out.extend(core.on_sample(f, now));
                    }
                }
                if tick > 100 {
                    ee_after += ee(&out);
                }
                said.extend(statuses(&out));
            }
        }
        assert_eq!(core.stats.refused_clock, 3);
        // Before the bound, one such sample stopped every later end-effector estimate.
        assert!(
            ee_after >= 195,
            "{ee_after} estimates after the forged stamp"
        );
        assert_eq!(said.len(), 2, "{said:?}");
        assert_eq!(said[0].state, JointState::Rejected);
        assert!(
            said[0].text.contains("j2") && said[0].text.contains("+3600000.0 ms"),
            "{}",
            said[0].text
        );
        assert_eq!(said[1].state, JointState::Ok);
    }

    #[test]
    fn a_board_under_a_ms_ahead_is_measured_and_said_to_be_past_half_a_tick_while_its_samples_count()
     {
        let mut core = EstimatorCore::new(&cfg(), CoreTiming::for_rate(1000.0)).unwrap();
        let ms = 1_000_000u64;
        let mut said = Vec::new();
        for tick in 1..=2500u64 {
            let now = tick * ms;
            for j in 0..4u16 {
                // Transits of 50–250 µs; j2's board 0.8 ms ahead (within the 100 ms bound).
                let mut s = sample(j, tick, 0.0);
                s.t_acq_ns -= 50_000 + (tick * 7 + u64::from(j) * 3) % 5 * 50_000;
                if j == 1 {
                    s.t_acq_ns += 800_000;
                }
                said.extend(statuses(&core.on_sample(s, now)));
            }
        }
        assert_eq!(core.stats.refused_clock, 0);
        let offsets = core.clock_offsets_ns();
        assert_eq!(offsets[1], Some(750_000), "{offsets:?}");
        for j in [0, 2, 3] {
            assert_eq!(offsets[j], Some(-50_000), "{offsets:?}");
        }
        // One status per joint, at the end of its first second; j2's says what to do.
        assert_eq!(said.len(), 4, "{said:?}");
        let j2 = said.iter().find(|s| s.joint == 1).unwrap();
        assert!(
            j2.text.contains("j2: clock +0.750 ms") && j2.text.contains("over half a tick"),
            "{}",
            j2.text
        );
        assert!(said.iter().all(|s| s.state == JointState::Ok));
        assert!(core.stats.ee_estimates > 2000);
    }

    #[test]
    fn a_board_two_seconds_behind_goes_stale_and_the_status_names_its_clock() {
        let mut core = EstimatorCore::new(&cfg(), CoreTiming::for_rate(1000.0)).unwrap();
        let ms = 1_000_000u64;
        let mut said = Vec::new();
        for tick in 1..=6000u64 {
            let now = 3_000 * ms + tick * ms;
            for j in 0..4u16 {
                let mut s = sample(j, 3_000 + tick, 0.0);
                if j == 2 {
                    s.t_acq_ns -= 2_000 * ms;
                }
                said.extend(statuses(&core.on_sample(s, now)));
            }
            if tick % 20 == 0 {
                said.extend(statuses(&core.on_tick(now)));
            }
        }
        let stale = said
            .iter()
            .find(|s| s.state == JointState::Stale)
            .expect("j3 goes stale");
        assert_eq!(stale.joint, 2);
        assert!(
            stale
                .text
                .contains("every sample refused (stamped -2000.0 ms"),
            "{}",
            stale.text
        );
        assert!(core.stale()[2] && !core.stale()[0]);
        assert_eq!(
            core.stats.ee_estimates, 0,
            "never an estimate with a joint withheld"
        );
    }

    #[test]
    fn replays_wrong_keys_and_pivots_off_the_travel_are_refused_and_counted() {
        let mut core = EstimatorCore::new(&cfg(), CoreTiming::for_rate(1000.0)).unwrap();
        let ms = 1_000_000u64;
        core.on_sample(sample(0, 10, 0.0), 10 * ms);
        // The same sample again: refused as a replay.
        core.on_sample(sample(0, 10, 0.0), 11 * ms);
        assert_eq!(core.stats.refused_replay, 1);
        // A restarted agent: seq 1 again, a later stamp: accepted.
        let mut restarted = sample(0, 12, 0.0);
        restarted.seq = 1;
        core.on_sample(restarted, 12 * ms);
        assert_eq!(core.stats.refused_replay, 1);
        // j3's payload on j1's key.
        assert!(
            core.on_sample_from("j1", sample(2, 13, 0.0), 13 * ms)
                .is_empty()
        );
        assert_eq!(core.stats.refused_key, 1);
        // A pivot 50 mm out: refused, said once.
        let mut off = sample(1, 14, 0.0);
        off.pivot_m = Some(0.05);
        let said = statuses(&core.on_sample(off, 14 * ms));
        assert_eq!(core.stats.refused_range, 1);
        assert!(said[0].text.contains("outside its travel"), "{said:?}");
    }

    #[test]
    fn gaps_in_the_sequence_count_as_lost_only_between_accepted_samples() {
        let mut core = EstimatorCore::new(&cfg(), CoreTiming::for_rate(1000.0)).unwrap();
        let ms = 1_000_000u64;
        core.on_sample(sample(0, 10, 0.0), 10 * ms);
        // Seq 11 and 12 never came: two lost.
        core.on_sample(sample(0, 13, 0.0), 13 * ms);
        assert_eq!(core.stats.lost, 2);
        // A forged sample on another joint's key with a far sequence number: refused, and the
        // gap it would make is not counted, nor the one back to the real sequence.
        let mut forged = sample(0, 14, 0.0);
        forged.seq = 1_000;
        core.on_sample_from("j2", forged, 14 * ms);
        assert_eq!(core.stats.refused_key, 1);
        core.on_sample(sample(0, 14, 0.0), 14 * ms);
        assert_eq!(core.stats.lost, 2);
        // A pivot off the travel: 15 refused, 16 accepted. The models never saw 15, so it is
        // a gap of the accepted sequence as well as a refusal.
        let mut off = sample(0, 15, 0.0);
        off.pivot_m = Some(0.05);
        core.on_sample(off, 15 * ms);
        core.on_sample(sample(0, 16, 0.0), 16 * ms);
        assert_eq!((core.stats.refused_range, core.stats.lost), (1, 3));
        // A restarted agent counts from 1 again: no gap.
        let mut restarted = sample(0, 17, 0.0);
        restarted.seq = 1;
        core.on_sample(restarted, 17 * ms);
        assert_eq!(core.stats.lost, 3);
    }

    #[test]
    fn a_boards_tick_completes_a_tick_at_once_and_its_key_carries_only_the_joints_it_runs() {
        let mut c = cfg();
        c.machines = vec![rig_config::Machine {
            name: "left".into(),
            roles: vec![
                rig_config::Role::Joint("j1".into()),
                rig_config::Role::Joint("j2".into()),
            ],
            listen: vec![],
            connect: vec![],
        }];
        let mut core = EstimatorCore::new(&c, CoreTiming::for_rate(1000.0)).unwrap();
        let ms = 1_000_000u64;
        let board = |js: &[u16], tick: u64| BoardSample {
            samples: js.iter().map(|&j| sample(j, tick, 0.0)).collect(),
        };
        // Machine `left` runs j1 and j2 (indices 0, 1): a j3 sample on its key is refused.
        let out = core.on_board_sample_from("left", board(&[0, 1, 2], 1), ms);
        assert_eq!(core.stats.refused_key, 1);
        assert_eq!(ee(&out), 0);
        // A board that is no machine of the plan carries any joint without [security]: the
        // other two joints of tick 1 complete it, one end-effector estimate for the tick.
        core.on_board_sample_from("left", board(&[0, 1], 2), 2 * ms);
        let out = core.on_board_sample_from("j3", board(&[2, 3], 1), 2 * ms);
        assert_eq!(core.stats.refused_key, 1);
        assert_eq!(ee(&out), 1, "{out:?}");
        // Under [security] a board key that is no machine's carries nothing.
        c.security = Some(rig_config::SecurityConfig {
            ca: "ca.pem".into(),
            certs: "certs".into(),
        });
        let mut core = EstimatorCore::new(&c, CoreTiming::for_rate(1000.0)).unwrap();
        assert!(
            core.on_board_sample_from("j3", board(&[2, 3], 1), ms)
                .is_empty()
        );
        assert_eq!(core.stats.refused_key, 2);
        core.on_board_sample_from("left", board(&[0, 1], 1), ms);
        assert_eq!(core.stats.refused_key, 2);
        assert_eq!(core.stats.samples, 2);
    }
}
