//! One allocation: joint stiffnesses and pivot positions for a wanted operational stiffness
//! at an end-effector position (paper B §4.3).
//!
//! The pose gives G_u^A (rig_model::planar), hence S; the bounded least-squares solve and its
//! tie-break are rig_model::allocation; each joint stiffness becomes a pivot position through
//! the lever's inverse (rig_model::lever). Nothing is clamped silently.

use nalgebra::DVector;
use rig_config::{JointKind, RigConfig, Topology};
use rig_model::allocation::{
    Allocation, AllocationProblem, OperationalRange, OperationalStiffness,
};
use rig_model::planar::{Configuration, s_matrix};
use thiserror::Error;

/// Why there is no allocation to apply.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PlanError {
    /// The rig cannot allocate at all (single joint, no geometry).
    #[error("{0}")]
    Unsupported(String),
    /// The pose, the target or the joints' ranges make it impossible.
    #[error("{0}")]
    Infeasible(String),
}

/// What is wanted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target {
    Stiffness(OperationalStiffness),
    /// Paper B's decoupled target at this percent of the range.
    Percent(f64),
}

/// Everything one allocation computes.
#[derive(Debug, Clone)]
pub struct Plan {
    pub at_m: (f64, f64),
    pub configuration: Configuration,
    pub problem: AllocationProblem,
    pub range: OperationalRange,
    pub allocation: Allocation,
    /// Pivot position per joint [m], or why the joint's stiffness has none.
    pub pivots_m: Vec<Result<f64, String>>,
}

impl Plan {
    /// Why this plan must not be applied (target not met, a joint without a pivot), if so.
    pub fn failure(&self, topology: Topology) -> Option<String> {
        let a = &self.allocation;
        if !a.feasible {
            return Some(format!(
                "the target cannot be met exactly at this pose: best achievable (k_xx, k_xy, k_yy) = ({:.4}, {:.4}, {:.4}) N/m, residual {:.4} N/m{}",
                a.achieved.xx,
                a.achieved.xy,
                a.achieved.yy,
                a.residual,
                if topology == Topology::Serial {
                    " (a serial arm has 2 joint stiffnesses for 3 targets)"
                } else {
                    ""
                }
            ));
        }
        self.pivots_m
            .iter()
            .enumerate()
            .find_map(|(j, p)| p.as_ref().err().map(|e| format!("joint {j}: {e}")))
    }

    /// The pivots when every joint has one.
    pub fn pivots(&self) -> Option<Vec<f64>> {
        self.pivots_m
            .iter()
            .map(|p| p.as_ref().ok().copied())
            .collect()
    }
}

/// Computes the allocation for `target` with the end effector at `at_m`, each joint's pivot
/// giving its stiffness at rest (no deflection).
pub fn allocate(cfg: &RigConfig, at_m: (f64, f64), target: Target) -> Result<Plan, PlanError> {
    allocate_in_use(cfg, at_m, target, &[])
}

/// As [`allocate`], with joint j's pivot chosen for stiffness k_j / `softening[j]` at rest:
/// `softening[j]` is how much the deflections in use change that joint's stiffness (the
/// estimator's stiffness over the table's at rest, averaged; 1 where absent), so that over the
/// motion the joint gives k_j. The pivot stays within what the table reaches.
pub fn allocate_in_use(
    cfg: &RigConfig,
    at_m: (f64, f64),
    target: Target,
    softening: &[f64],
) -> Result<Plan, PlanError> {
    if !cfg.topology.is_robot() {
        return Err(PlanError::Unsupported(format!(
            "a {} rig has no operational space; allocation needs a serial or parallel robot",
            cfg.topology.name()
        )));
    }
    let robot = cfg
        .robot()
        .ok_or_else(|| PlanError::Unsupported("the config has no robot geometry".into()))?;
    let configuration = robot.at_position(at_m.0, at_m.1).map_err(|e| {
        PlanError::Infeasible(format!(
            "pose ({:.1}, {:.1}) mm: {e}",
            at_m.0 * 1e3,
            at_m.1 * 1e3
        ))
    })?;
    let bounds: Vec<(f64, f64)> = cfg.joints.iter().map(reach).collect();
    let k_min = DVector::from_iterator(bounds.len(), bounds.iter().map(|b| b.0));
    let k_max = DVector::from_iterator(bounds.len(), bounds.iter().map(|b| b.1));
    let problem = AllocationProblem::new(s_matrix(&configuration.g_u_a), k_min, k_max)
        .map_err(|e| PlanError::Unsupported(format!("allocation problem: {e}")))?;
    let range = problem.range();
    let target = match target {
        Target::Stiffness(k) => k,
        Target::Percent(p) => problem
            .decoupled_target(p)
            .map_err(|e| PlanError::Infeasible(e.to_string()))?,
    };
    check_target_in_range(&problem, target)?;
    let allocation = problem
        .solve(target)
        .map_err(|e| PlanError::Infeasible(e.to_string()))?;
    let pivots_m = cfg
        .joints
        .iter()
        .zip(allocation.k.iter())
        .enumerate()
        .map(|(i, (j, &k))| match &j.kind {
            // Through the calibrated k(d), the table the estimator reports its stiffness by,
            // so that what is allocated is what the joint gives (the lever law alone is a few
            // per cent off a real joint: friction in the loop, the spring's own rate).
            JointKind::Lever { vsa, restoring, .. } => restoring
                .pivot_for_stiffness(
                    at_rest(k, softening.get(i).copied(), bounds[i]),
                    vsa.d_min,
                    vsa.d_max,
                )
                .ok_or_else(|| {
                    let (lo, hi) = restoring.stiffness_range(vsa.d_min, vsa.d_max);
                    format!(
                        "{k:.4} N·m/rad is outside the calibrated table's range [{lo:.4}, {hi:.4}] N·m/rad over the pivot travel"
                    )
                }),
            JointKind::Awas { .. } => Err("an AWAS joint has no pivot".to_string()),
        })
        .collect();
    Ok(Plan {
        at_m,
        configuration,
        problem,
        range,
        allocation,
        pivots_m,
    })
}

/// Whether `r`, a joint's stiffness in use over its table's at rest, is a plausible softening
/// (finite, within ±30 %): what a lever's deflection can do, not a forged or broken estimate.
pub fn plausible_softening(r: f64) -> bool {
    r.is_finite() && (0.7..=1.3).contains(&r)
}

/// The stiffness at rest that gives `k` in use, `k / softening`, kept within `bounds` (an
/// absent or implausible softening counts as 1).
fn at_rest(k: f64, softening: Option<f64>, bounds: (f64, f64)) -> f64 {
    match softening {
        Some(r) if plausible_softening(r) => (k / r).clamp(bounds.0, bounds.1),
        _ => k,
    }
}

/// Joint `j`'s stiffness bounds for allocation: the config's, within what a lever joint's
/// calibrated table reaches over its travel (the pivot is found through that table).
fn reach(j: &rig_config::JointConfig) -> (f64, f64) {
    let (lo, hi) = (j.limits.k_min, j.limits.k_max);
    match &j.kind {
        JointKind::Lever { vsa, restoring, .. } => {
            let (t_lo, t_hi) = restoring.stiffness_range(vsa.d_min, vsa.d_max);
            // A table that misses the bounds altogether leaves them as they are; the pivot
            // lookup then says which stiffness it cannot reach.
            if t_lo.max(lo) < t_hi.min(hi) {
                (t_lo.max(lo), t_hi.min(hi))
            } else {
                (lo, hi)
            }
        }
        JointKind::Awas { .. } => (lo, hi),
    }
}

/// A target component outside what any joint stiffnesses in their bounds can give is refused
/// before solving (the solver would only return the nearest corner).
fn check_target_in_range(
    problem: &AllocationProblem,
    t: OperationalStiffness,
) -> Result<(), PlanError> {
    let e = problem.extent();
    for (name, v, lo, hi) in [
        ("k_xx", t.xx, e.min.xx, e.max.xx),
        ("k_xy", t.xy, e.min.xy, e.max.xy),
        ("k_yy", t.yy, e.min.yy, e.max.yy),
    ] {
        let tol = 1e-9 * (hi - lo).abs().max(1.0);
        if v < lo - tol || v > hi + tol {
            return Err(PlanError::Infeasible(format!(
                "target {name} = {v:.4} N/m is outside what the joints can give at this pose: [{lo:.4}, {hi:.4}] N/m"
            )));
        }
    }
    Ok(())
}
