//! The allocator host's core, sans I/O.
//!
//! - A request (query) is answered with an allocation and, when it can be applied, pivot
//!   commands for every joint.
//! - A continuous goal is kept; when the end-effector estimate moves more than
//!   `reallocate_m` from the pose of the last allocation, it re-allocates.
//! - The current pivot goals are re-sent at a steady rate (the joints' watchdogs expect a
//!   heartbeat; without one they hold where they are).

use rig_config::RigConfig;
use rig_model::allocation::OperationalStiffness;
use rig_protocol::{
    AllocationRequest, AllocationResult, AllocationTarget, EeEstimate, JointCommand,
    StiffnessTriple,
};

use crate::plan::{PlanError, Target, allocate};

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
}

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
        Self {
            cfg,
            goal: None,
            pivots: None,
            last_pose: None,
            pose,
            cmd_seq: 0,
            reallocate_m: 0.002,
        }
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
        match allocate(&self.cfg, at_m, target) {
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
                    self.pivots = pivots;
                    self.last_pose = Some(at_m);
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

    /// An end-effector estimate: re-allocate if a goal is set and the pose moved enough.
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
        moved.then(|| self.apply(0, self.pose, goal, now_ns))
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
        let req = AllocationRequest {
            id: 9,
            x_m: 0.075,
            y_m: 0.2,
            target: AllocationTarget::Percent(25.0),
        };
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
        let goal = AllocationRequest {
            id: 3,
            x_m: 0.075,
            y_m: 0.2,
            target: AllocationTarget::Percent(25.0),
        };
        let (_, first) = c.on_goal(&goal, 1);
        let ee = |x: f64, y: f64| EeEstimate {
            seq: 1,
            t_ns: 2,
            stale_mask: 0,
            x_m: x,
            y_m: y,
            phi_rad: 0.0,
            force_n: None,
            stiffness_n_per_m: None,
        };
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
}
