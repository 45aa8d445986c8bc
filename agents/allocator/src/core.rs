//! The allocator host's core, sans I/O.
//!
//! - A request (query) is answered with an allocation and, when it can be applied, pivot
//!   commands for every joint.
//! - A continuous goal is kept; when the end-effector estimate moves more than
//!   `reallocate_m` from the pose of the last allocation, it re-allocates; and when a joint's
//!   stiffness in use (the estimator's, at its current deflection) has drifted from what the
//!   pivots were chosen for ([`AllocatorCore::on_joint_estimate`]): what is allocated is then
//!   what the joints give over the motion, not only at rest.
//! - The current pivot goals are re-sent at a steady rate (the joints' watchdogs expect a
//!   heartbeat; without one they hold where they are).

use rig_config::{JointKind, RigConfig};
use rig_model::allocation::OperationalStiffness;
use rig_protocol::{
    AllocationRequest, AllocationResult, AllocationTarget, EeEstimate, JointCommand, JointEstimate,
    StiffnessTriple,
};

use crate::plan::{PlanError, Target, allocate_in_use, plausible_softening};

/// How a continuous goal's stamp (the time its publisher's Zenoh session gave it) stands against
/// this host's clock. A goal held up on the way, replayed from a recording or sent by a machine
/// whose clock is off must not move the pivots: the bound is the config's `[clock] max_offset_ms`,
/// the same one the estimator holds samples to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GoalAge {
    /// Within the bound: obeyed.
    Fresh,
    /// The publisher does not stamp (a Zenoh session with timestamping off): obeyed, and said
    /// once, since nothing can be checked.
    Unstamped,
    /// Older than the bound by this much [ns]: refused.
    Stale { age_ns: u64 },
    /// Ahead of this host's clock by more than the bound [ns]: refused.
    Ahead { ahead_ns: u64 },
}

/// The verdict on a goal stamped `stamp_ns` (Unix time [ns], `None`: unstamped) arriving at
/// `now_ns`, with the bound `bound_ns`. Pure: the edge reads the clock and the stamp.
pub fn goal_age(stamp_ns: Option<u64>, now_ns: u64, bound_ns: u64) -> GoalAge {
    match stamp_ns {
        None => GoalAge::Unstamped,
        Some(t) if now_ns > t && now_ns - t > bound_ns => GoalAge::Stale { age_ns: now_ns - t },
        Some(t) if t > now_ns && t - now_ns > bound_ns => GoalAge::Ahead {
            ahead_ns: t - now_ns,
        },
        Some(_) => GoalAge::Fresh,
    }
}

/// The answer to a request or goal that is not applied: nothing allocated, `why` said (at most
/// 1000 characters).
pub fn refusal(id: u64, why: &str) -> AllocationResult {
    let zero = StiffnessTriple {
        xx: 0.0,
        xy: 0.0,
        yy: 0.0,
    };
    AllocationResult {
        id,
        feasible: false,
        residual: 0.0,
        target: zero,
        achieved: zero,
        k_joint_nm_per_rad: vec![],
        pivot_m: vec![],
        error: why.chars().take(1000).collect(),
    }
}

/// The allocator host's core.
#[derive(Debug, Clone)]
pub struct AllocatorCore {
    cfg: RigConfig,
    goal: Option<Target>,
    pivots: Option<Vec<f64>>,
    last_pose: Option<(f64, f64)>,
    pose: (f64, f64),
    cmd_seq: u64,
    /// Re-allocate when the pose moves more than this [m].
    pub reallocate_m: f64,
    /// Per joint: the estimator's stiffness (at the joint's current deflection) over the
    /// table's stiffness at rest at the commanded pivot, averaged over about a second (see
    /// [`Self::on_joint_estimate`]); 1 until estimates come.
    softening: Vec<f64>,
    /// The softening the current pivots were chosen with.
    applied_softening: Vec<f64>,
    /// Per joint: the table's stiffness at rest at the commanded pivot (lever joints).
    k_at_pivot: Vec<Option<f64>>,
    /// When a softening change last re-allocated [ns].
    last_soft_ns: u64,
}

/// Weight of one joint estimate in the softening average (≈ 1 s at 1 kHz).
const SOFTENING_WEIGHT: f64 = 1e-3;
/// Re-allocate when a joint's softening moved this much since the pivots were chosen…
const SOFTENING_STEP: f64 = 0.003;
/// …at most this often [ns].
const SOFTENING_EVERY_NS: u64 = 250_000_000;

fn triple(k: OperationalStiffness) -> StiffnessTriple {
    StiffnessTriple {
        xx: k.xx,
        xy: k.xy,
        yy: k.yy,
    }
}

/// A request's target as the plan takes it.
impl From<AllocationTarget> for Target {
    fn from(t: AllocationTarget) -> Self {
        match t {
            AllocationTarget::Stiffness(k) => Target::Stiffness(OperationalStiffness {
                xx: k.xx,
                xy: k.xy,
                yy: k.yy,
            }),
            AllocationTarget::Percent(p) => Target::Percent(p),
        }
    }
}

/// A plan's target as a request carries it (`rig allocate --live`).
impl From<Target> for AllocationTarget {
    fn from(t: Target) -> Self {
        match t {
            Target::Stiffness(k) => AllocationTarget::Stiffness(triple(k)),
            Target::Percent(p) => AllocationTarget::Percent(p),
        }
    }
}

impl AllocatorCore {
    pub fn new(cfg: RigConfig) -> Self {
        let pose = cfg.geometry.map_or((0.0, 0.0), |g| g.home);
        let n = cfg.joints.len();
        Self {
            cfg,
            goal: None,
            pivots: None,
            last_pose: None,
            pose,
            cmd_seq: 0,
            reallocate_m: 0.002,
            softening: vec![1.0; n],
            applied_softening: vec![1.0; n],
            k_at_pivot: vec![None; n],
            last_soft_ns: 0,
        }
    }

    /// A joint estimate: folds the joint's stiffness in use, over the table's at rest at the
    /// pivot this allocator commanded, into that joint's softening. A lever joint's deflection
    /// changes its stiffness (at the stiff end of the travel by several per cent at the
    /// robots' working deflections); a pivot chosen for the stiffness at rest then gives less
    /// over the motion, and the next allocation asks the table for k / softening. Estimates
    /// that are not plausible (not finite, beyond ±30 %) are ignored.
    pub fn on_joint_estimate(&mut self, e: &JointEstimate) {
        let j = usize::from(e.joint);
        let (Some(k), Some(&Some(at_rest))) = (e.stiffness_nm_per_rad, self.k_at_pivot.get(j))
        else {
            return;
        };
        let r = k / at_rest;
        if plausible_softening(r) {
            self.softening[j] += SOFTENING_WEIGHT * (r - self.softening[j]);
        }
    }

    /// Whether a joint's softening moved enough since the pivots were chosen.
    fn softening_moved(&self, now_ns: u64) -> bool {
        now_ns >= self.last_soft_ns + SOFTENING_EVERY_NS
            && self
                .softening
                .iter()
                .zip(&self.applied_softening)
                .any(|(s, a)| (s - a).abs() > SOFTENING_STEP)
    }

    fn commands(&mut self, now_ns: u64) -> Vec<JointCommand> {
        let Some(pivots) = self.pivots.clone() else {
            return Vec::new();
        };
        pivots
            .iter()
            .enumerate()
            .map(|(j, &d)| {
                self.cmd_seq += 1;
                JointCommand {
                    joint: j as u16,
                    seq: self.cmd_seq,
                    t_ns: now_ns.max(1),
                    motor_goal_rad: None,
                    pivot_goal_m: Some(d),
                    stiffness_motor_goal_rad: None,
                    torque_enable: true,
                }
            })
            .collect()
    }

    /// Allocates for `target` at `at_m`; applies it (commands) only when it can be met.
    fn apply(
        &mut self,
        id: u64,
        at_m: (f64, f64),
        target: Target,
        now_ns: u64,
    ) -> (AllocationResult, Vec<JointCommand>) {
        let softening = self.softening.clone();
        match allocate_in_use(&self.cfg, at_m, target, &softening) {
            Ok(plan) => {
                let failure = plan.failure(self.cfg.topology);
                let a = &plan.allocation;
                let pivots = plan.pivots();
                let result = AllocationResult {
                    id,
                    feasible: failure.is_none(),
                    residual: a.residual,
                    target: triple(a.target),
                    achieved: triple(a.achieved),
                    k_joint_nm_per_rad: a.k.iter().copied().collect(),
                    pivot_m: pivots.clone().unwrap_or_else(|| vec![0.0; a.k.len()]),
                    error: failure.clone().unwrap_or_default(),
                };
                if failure.is_none() {
                    if let Some(p) = &pivots {
                        self.k_at_pivot = self
                            .cfg
                            .joints
                            .iter()
                            .zip(p)
                            .map(|(j, &d)| match &j.kind {
                                JointKind::Lever { restoring, .. } => Some(restoring.at(d).k),
                                JointKind::Awas { .. } => None,
                            })
                            .collect();
                    }
                    self.pivots = pivots;
                    self.last_pose = Some(at_m);
                    self.applied_softening = softening;
                    self.last_soft_ns = now_ns;
                    return (result, self.commands(now_ns));
                }
                (result, Vec::new())
            }
            Err(PlanError::Unsupported(e) | PlanError::Infeasible(e)) => {
                (refusal(id, &e), Vec::new())
            }
        }
    }

    /// A one-off request (the queryable).
    pub fn on_request(
        &mut self,
        req: &AllocationRequest,
        now_ns: u64,
    ) -> (AllocationResult, Vec<JointCommand>) {
        self.apply(req.id, (req.x_m, req.y_m), req.target.into(), now_ns)
    }

    /// A continuous goal: kept and re-applied as the pose changes. The request's position is
    /// where to start; later poses come from the end-effector estimates.
    pub fn on_goal(
        &mut self,
        req: &AllocationRequest,
        now_ns: u64,
    ) -> (AllocationResult, Vec<JointCommand>) {
        self.goal = Some(req.target.into());
        self.pose = (req.x_m, req.y_m);
        self.apply(req.id, self.pose, req.target.into(), now_ns)
    }

    /// An end-effector estimate: re-allocate if a goal is set and the pose moved enough, or a
    /// joint's softening did.
    pub fn on_ee(
        &mut self,
        ee: &EeEstimate,
        now_ns: u64,
    ) -> Option<(AllocationResult, Vec<JointCommand>)> {
        self.pose = (ee.x_m, ee.y_m);
        let goal = self.goal?;
        let moved = self
            .last_pose
            .is_none_or(|(x, y)| (x - ee.x_m).hypot(y - ee.y_m) > self.reallocate_m);
        (moved || self.softening_moved(now_ns)).then(|| self.apply(0, self.pose, goal, now_ns))
    }

    /// The current pivot goals again (heartbeat for the joints' watchdogs).
    pub fn heartbeat(&mut self, now_ns: u64) -> Vec<JointCommand> {
        self.commands(now_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_goal_is_obeyed_within_the_clock_bound_and_refused_beyond_it_either_way() {
        let (now, bound) = (1_700_000_000_000_000_000_u64, 100_000_000);
        assert_eq!(goal_age(Some(now), now, bound), GoalAge::Fresh);
        assert_eq!(goal_age(Some(now - bound), now, bound), GoalAge::Fresh);
        assert_eq!(goal_age(Some(now + bound), now, bound), GoalAge::Fresh);
        assert_eq!(
            goal_age(Some(now - 2_000_000_000), now, bound),
            GoalAge::Stale {
                age_ns: 2_000_000_000
            }
        );
        assert_eq!(
            goal_age(Some(now + bound + 1), now, bound),
            GoalAge::Ahead {
                ahead_ns: bound + 1
            }
        );
        assert_eq!(goal_age(None, now, bound), GoalAge::Unstamped);
        // Absurd stamps are verdicts, not overflows.
        assert_eq!(
            goal_age(Some(u64::MAX), 0, bound),
            GoalAge::Ahead { ahead_ns: u64::MAX }
        );
        assert_eq!(
            goal_age(Some(0), u64::MAX, bound),
            GoalAge::Stale { age_ns: u64::MAX }
        );
    }

    fn core() -> AllocatorCore {
        AllocatorCore::new(rig_config::examples::load("parallel").unwrap())
    }

    /// Request `id`: paper B's decoupled target at 25 % with the end effector at (75, 200) mm.
    fn request(id: u64) -> AllocationRequest {
        AllocationRequest {
            id,
            x_m: 0.075,
            y_m: 0.2,
            target: AllocationTarget::Percent(25.0),
        }
    }

    /// An end-effector estimate at (x, y) [m], stamped `t_ns`.
    fn ee_at(x: f64, y: f64, t_ns: u64) -> EeEstimate {
        EeEstimate {
            seq: 1,
            t_ns,
            stale_mask: 0,
            x_m: x,
            y_m: y,
            phi_rad: 0.0,
            force_n: None,
            stiffness_n_per_m: None,
        }
    }

    /// Joint `joint`'s estimate with stiffness `k` and nothing else.
    fn stiffness_estimate(joint: u16, seq: u64, k: f64) -> JointEstimate {
        JointEstimate {
            joint,
            seq,
            t_acq_ns: seq,
            torque_nm: 0.0,
            stiffness_nm_per_rad: Some(k),
            inertia_kg_m2: None,
            inertia_var: None,
            damping_nms_per_rad: None,
            damping_var: None,
            residual_nm: None,
        }
    }

    #[test]
    fn a_target_survives_the_wire_both_ways() {
        let k = OperationalStiffness {
            xx: 800.0,
            xy: -12.5,
            yy: 900.0,
        };
        for t in [Target::Stiffness(k), Target::Percent(37.5)] {
            let wire: AllocationTarget = t.into();
            match (Target::from(wire), t) {
                (Target::Stiffness(a), Target::Stiffness(b)) => {
                    assert_eq!((a.xx, a.xy, a.yy), (b.xx, b.xy, b.yy));
                }
                (Target::Percent(a), Target::Percent(b)) => assert_eq!(a, b),
                (a, b) => panic!("{a:?} came back from {b:?}"),
            }
        }
    }

    #[test]
    fn a_request_becomes_pivot_commands_within_travel() {
        let mut c = core();
        let req = request(9);
        let (r, cmds) = c.on_request(&req, 5);
        assert!(r.feasible, "{}", r.error);
        assert_eq!(r.id, 9);
        assert!(r.achieved.xy.abs() < 1e-6);
        assert_eq!(cmds.len(), 4);
        for (j, cmd) in cmds.iter().enumerate() {
            assert_eq!(cmd.joint as usize, j);
            let d = cmd.pivot_goal_m.unwrap();
            assert!((0.0..=0.018).contains(&d));
            assert_eq!(d, r.pivot_m[j]);
        }
        assert_eq!(c.heartbeat(6).len(), 4);
    }

    #[test]
    fn infeasible_requests_answer_why_and_command_nothing() {
        let mut c = core();
        let far = AllocationRequest {
            id: 1,
            x_m: 0.075,
            y_m: 0.9,
            target: AllocationTarget::Percent(25.0),
        };
        let (r, cmds) = c.on_request(&far, 1);
        assert!(
            !r.feasible && r.error.contains("out of reach") && cmds.is_empty(),
            "{}",
            r.error
        );
        let big = AllocationRequest {
            id: 2,
            x_m: 0.075,
            y_m: 0.2,
            target: AllocationTarget::Stiffness(StiffnessTriple {
                xx: 1e6,
                xy: 0.0,
                yy: 100.0,
            }),
        };
        let (r, cmds) = c.on_request(&big, 1);
        assert!(!r.feasible && r.error.contains("k_xx") && cmds.is_empty());
        assert!(
            c.heartbeat(2).is_empty(),
            "nothing applied, nothing to repeat"
        );
    }

    #[test]
    fn a_goal_follows_the_pose() {
        let mut c = core();
        let goal = request(3);
        let (_, first) = c.on_goal(&goal, 1);
        let ee = |x: f64, y: f64| ee_at(x, y, 2);
        assert!(
            c.on_ee(&ee(0.0755, 0.2), 2).is_none(),
            "0.5 mm is below the threshold"
        );
        let (r, cmds) = c.on_ee(&ee(0.085, 0.2), 3).unwrap();
        assert!(r.feasible);
        assert_ne!(
            cmds[0].pivot_goal_m, first[0].pivot_goal_m,
            "new pose, new pivots"
        );
    }

    #[test]
    fn joints_softened_by_their_deflection_get_pivots_that_give_the_allocated_stiffness_in_use() {
        // Every joint reports 96 % of its table's stiffness at rest (its deflection in use):
        // after about a second of estimates the goal is re-allocated at the same pose, the
        // joint stiffnesses unchanged and each pivot's stiffness at rest k / 0.96.
        let mut c = core();
        let goal = request(4);
        let (first, _) = c.on_goal(&goal, 1);
        let cfg = c.cfg.clone();
        let table = |j: usize, d: f64| match &cfg.joints[j].kind {
            JointKind::Lever { restoring, .. } => restoring.at(d).k,
            JointKind::Awas { .. } => unreachable!(),
        };
        let ks: Vec<f64> = (0..4).map(|j| table(j, first.pivot_m[j])).collect();
        for (j, k) in ks.iter().enumerate() {
            assert!(
                (k - first.k_joint_nm_per_rad[j]).abs() < 1e-6 * k,
                "at rest at first"
            );
        }
        let ee = ee_at(0.075, 0.2, 2);
        for i in 0..3000_u64 {
            for (j, k) in ks.iter().enumerate() {
                c.on_joint_estimate(&stiffness_estimate(j as u16, i, 0.96 * k));
            }
        }
        assert!(
            c.on_ee(&ee, 2).is_none(),
            "not sooner than 250 ms after the last"
        );
        let (r, cmds) = c
            .on_ee(&ee, 300_000_000)
            .expect("the softening re-allocates");
        assert!(r.feasible, "{}", r.error);
        let soft = 1.0 - 0.04 * (1.0 - (-3.0_f64).exp()); // the average after 3000 estimates
        for (j, cmd) in cmds.iter().enumerate() {
            assert_eq!(r.k_joint_nm_per_rad[j], first.k_joint_nm_per_rad[j]);
            let at_rest = table(j, cmd.pivot_goal_m.unwrap());
            let want = first.k_joint_nm_per_rad[j] / soft;
            assert!(
                (at_rest - want).abs() < 1e-3 * want,
                "joint {j}: {at_rest} for {want}"
            );
        }
        // A forged, implausible estimate moves nothing.
        let before = c.softening.clone();
        let mut e = stiffness_estimate(0, 0, 1e6);
        c.on_joint_estimate(&e);
        e.stiffness_nm_per_rad = Some(f64::NAN);
        c.on_joint_estimate(&e);
        e.joint = 99;
        c.on_joint_estimate(&e);
        assert_eq!(c.softening, before);
    }
}
