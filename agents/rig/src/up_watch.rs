//! What `rig up`'s summary scores against the simulated truth, as messages arrive (bounded
//! memory however long the rig runs): the end-effector force, each joint's live residual, each
//! joint's stiffness estimate, and the operational stiffness — estimated and true — against the
//! allocated target.

use std::collections::BTreeMap;

use rig_config::RigConfig;
use rig_protocol::{AllocationResult, EeEstimate, JointEstimate, SimTruth, StiffnessTriple};
use rig_sim::world::{HAND_STROKE_M, HAND_STROKE_S, StrokeWorld};

/// The first seconds of the world, while the estimator's observers settle from the config's
/// values and the hysteresis models from their virgin state: reported apart (the distributed
/// test warms up as long).
pub(crate) const WARM_UP_S: f64 = 2.0;

/// How long an unmatched truth or estimate waits for its other half [ns].
const MATCH_WINDOW_NS: u64 = 2_000_000_000;

/// One joint's true torque and stiffness at one tick.
#[derive(Debug, Clone, Copy)]
struct JointTruth {
    torque: f64,
    stiffness: f64,
}

/// The counts and errors the summary prints.
pub(crate) struct Watch {
    pub samples: BTreeMap<u16, u64>,
    joints: usize,
    world: Option<StrokeWorld>,
    start_ns: u64,
    /// Truths, estimated forces and estimated operational stiffnesses by tick, until their
    /// other half arrives.
    truths: BTreeMap<u64, BTreeMap<u16, JointTruth>>,
    ee: BTreeMap<u64, EeEstimate>,
    /// Estimated joint stiffness by (tick, joint) until its truth arrives.
    joint_k: BTreeMap<(u64, u16), f64>,
    /// The allocator's last target (robots).
    target: Option<StiffnessTriple>,
    /// Squared error, count and peak truth of the ticks after the warm-up, and of those in it.
    settled: ForceError,
    warm_up: ForceError,
    /// Per joint: squared residual (measured − modelled torque) and count, after the warm-up.
    residuals: BTreeMap<u16, (f64, u64)>,
    /// Per joint: relative error of the stiffness estimate against the truth, after the warm-up.
    joint_stiffness: BTreeMap<u16, Relative>,
    /// Operational stiffness against the allocated target, after the warm-up: the estimate's
    /// and the truth's (the true joint stiffnesses through the true pose's Jacobian).
    op_estimated: Relative,
    op_true: Relative,
}

/// The estimated end-effector force against the truth over some ticks.
#[derive(Debug, Clone, Copy, Default)]
struct ForceError {
    sq: f64,
    count: usize,
    peak: f64,
}

impl ForceError {
    fn add(&mut self, err: (f64, f64), truth: f64) {
        self.sq += err.0 * err.0 + err.1 * err.1;
        self.count += 1;
        self.peak = self.peak.max(truth);
    }

    fn rmse(&self) -> f64 {
        (self.sq / self.count.max(1) as f64).sqrt()
    }
}

/// Relative errors (value − reference)/reference: their mean (the bias) and the largest.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Relative {
    sum: f64,
    worst: f64,
    count: u64,
}

impl Relative {
    fn add(&mut self, value: f64, reference: f64) {
        if !(value.is_finite() && reference.is_finite()) || reference.abs() < 1e-12 {
            return;
        }
        let e = (value - reference) / reference;
        self.sum += e;
        if e.abs() > self.worst.abs() {
            self.worst = e;
        }
        self.count += 1;
    }

    /// Mean relative error, if anything was scored.
    pub fn mean(&self) -> Option<f64> {
        (self.count > 0).then(|| self.sum / self.count as f64)
    }
}

/// An operational stiffness scored against a target: the diagonal terms relative to theirs,
/// the coupling relative to the diagonal's geometric mean (a decoupled target has k_xy = 0).
fn add_operational(r: &mut Relative, k: (f64, f64, f64), target: &StiffnessTriple) {
    r.add(k.0, target.xx);
    r.add(k.2, target.yy);
    let scale = (target.xx * target.yy).abs().sqrt();
    if scale > 0.0 {
        r.add(scale + (k.1 - target.xy), scale);
    }
}

impl Watch {
    pub fn new(cfg: &RigConfig, start_ns: u64) -> Self {
        let world = cfg.robot().zip(cfg.geometry).and_then(|(robot, g)| {
            StrokeWorld::new(robot, g.home, HAND_STROKE_M, HAND_STROKE_S).ok()
        });
        Self {
            samples: BTreeMap::new(),
            joints: cfg.joints.len(),
            world,
            start_ns,
            truths: BTreeMap::new(),
            ee: BTreeMap::new(),
            joint_k: BTreeMap::new(),
            target: None,
            settled: ForceError::default(),
            warm_up: ForceError::default(),
            residuals: BTreeMap::new(),
            joint_stiffness: BTreeMap::new(),
            op_estimated: Relative::default(),
            op_true: Relative::default(),
        }
    }

    fn settled_at(&self, t_ns: u64) -> bool {
        t_ns.saturating_sub(self.start_ns) as f64 * 1e-9 >= WARM_UP_S
    }

    /// A joint estimate: its live residual (where the joint has a torque reference) and its
    /// stiffness, scored when the truth of the same tick arrives.
    pub fn joint_estimate(&mut self, m: &JointEstimate) {
        if let (true, Some(r)) = (self.settled_at(m.t_acq_ns), m.residual_nm) {
            let e = self.residuals.entry(m.joint).or_default();
            e.0 += r * r;
            e.1 += 1;
        }
        if let Some(k) = m.stiffness_nm_per_rad {
            let truth = self
                .truths
                .get(&m.t_acq_ns)
                .and_then(|t| t.get(&m.joint))
                .map(|t| t.stiffness);
            match truth {
                Some(kt) => self.score_joint(m.t_acq_ns, m.joint, k, kt),
                None => {
                    self.joint_k.insert((m.t_acq_ns, m.joint), k);
                }
            }
        }
        self.forget_before(m.t_acq_ns);
    }

    fn score_joint(&mut self, t_ns: u64, joint: u16, estimate: f64, truth: f64) {
        if self.settled_at(t_ns) {
            self.joint_stiffness
                .entry(joint)
                .or_default()
                .add(estimate, truth);
        }
    }

    /// Joint `j`'s residual RMS [N·m], if it has a torque reference.
    pub fn residual_rms(&self, j: u16) -> Option<f64> {
        self.residuals
            .get(&j)
            .filter(|(_, n)| *n > 0)
            .map(|(sq, n)| (sq / *n as f64).sqrt())
    }

    /// Joint `j`'s mean relative stiffness error against the truth.
    pub fn stiffness_error(&self, j: u16) -> Option<f64> {
        self.joint_stiffness.get(&j).and_then(Relative::mean)
    }

    pub fn truth(&mut self, m: &SimTruth) {
        if let Some(k) = self.joint_k.remove(&(m.t_acq_ns, m.joint)) {
            self.score_joint(m.t_acq_ns, m.joint, k, m.stiffness_nm_per_rad);
        }
        if self.world.is_some() {
            self.truths.entry(m.t_acq_ns).or_default().insert(
                m.joint,
                JointTruth {
                    torque: m.torque_nm,
                    stiffness: m.stiffness_nm_per_rad,
                },
            );
            self.score(m.t_acq_ns);
        }
        self.forget_before(m.t_acq_ns);
    }

    pub fn estimate(&mut self, m: &EeEstimate) {
        if self.world.is_some() {
            self.ee.insert(m.t_ns, *m);
            self.score(m.t_ns);
        }
    }

    pub fn allocation(&mut self, m: &AllocationResult) {
        if m.feasible {
            self.target = Some(m.target);
        }
    }

    /// Scores tick `t_ns` once it has an estimate and every joint's truth.
    fn score(&mut self, t_ns: u64) {
        let complete = self
            .truths
            .get(&t_ns)
            .is_some_and(|t| t.len() == self.joints);
        if !complete {
            return;
        }
        let Some(est) = self.ee.remove(&t_ns) else {
            return;
        };
        let truths: Vec<JointTruth> = self
            .truths
            .remove(&t_ns)
            .map(|t| t.into_values().collect())
            .unwrap_or_default();
        let torques: Vec<f64> = truths.iter().map(|t| t.torque).collect();
        let stiffness: Vec<f64> = truths.iter().map(|t| t.stiffness).collect();
        let t = t_ns.saturating_sub(self.start_ns) as f64 * 1e-9;
        let Some(world) = self.world.as_ref() else {
            return;
        };
        if let (Some((fx, fy)), Ok(f)) = (est.force_n, world.force(t, &torques)) {
            let part = if t < WARM_UP_S {
                &mut self.warm_up
            } else {
                &mut self.settled
            };
            part.add((fx - f[0], fy - f[1]), f.norm());
        }
        if let (true, Some(target)) = (t >= WARM_UP_S, self.target) {
            if let Some(k) = est.stiffness_n_per_m {
                add_operational(&mut self.op_estimated, (k.xx, k.xy, k.yy), &target);
            }
            if let Ok(k) = world.operational_stiffness(t, &stiffness) {
                add_operational(
                    &mut self.op_true,
                    (k[(0, 0)], k[(0, 1)], k[(1, 1)]),
                    &target,
                );
            }
        }
    }

    /// Forgets what waited longer than the match window.
    fn forget_before(&mut self, t_ns: u64) {
        let oldest = t_ns.saturating_sub(MATCH_WINDOW_NS);
        if self
            .truths
            .first_key_value()
            .is_some_and(|(&t, _)| t < oldest)
        {
            self.truths = self.truths.split_off(&oldest);
        }
        if self.ee.first_key_value().is_some_and(|(&t, _)| t < oldest) {
            self.ee = self.ee.split_off(&oldest);
        }
        if self
            .joint_k
            .first_key_value()
            .is_some_and(|(&(t, _), _)| t < oldest)
        {
            self.joint_k = self.joint_k.split_off(&(oldest, 0));
        }
    }

    /// The estimated force against the simulated truth (robots only).
    pub fn force_error(&self) -> Option<String> {
        self.world.as_ref()?;
        let (s, w) = (self.settled, self.warm_up);
        let warm = if w.count > 0 {
            format!(
                "; in the first {WARM_UP_S} s, while the observers settle: RMSE {:.4} N over {} estimates",
                w.rmse(),
                w.count
            )
        } else {
            String::new()
        };
        if s.count == 0 {
            return Some(format!(
                "force vs simulated truth: no estimate after the first {WARM_UP_S} s matched a complete truth{warm}"
            ));
        }
        Some(format!(
            "force vs simulated truth over {} estimates after the first {WARM_UP_S} s: RMSE {:.4} N = {:.2} % of the {:.3} N peak{warm}",
            s.count,
            s.rmse(),
            100.0 * s.rmse() / s.peak.max(1e-12),
            s.peak
        ))
    }

    /// The operational stiffness, estimated and true, against the allocated target (robots
    /// with a feasible allocation only).
    pub fn operational_error(&self) -> Option<String> {
        let target = self.target?;
        let pct = |r: &Relative| {
            r.mean()
                .map_or("—".to_string(), |m| format!("{:+.1} %", 100.0 * m))
        };
        Some(format!(
            "operational stiffness vs the allocated target (k_xx {:.0}, k_xy {:.0}, k_yy {:.0} N/m), mean relative error after the first {WARM_UP_S} s: estimated {}, true {}",
            target.xx,
            target.xy,
            target.yy,
            pct(&self.op_estimated),
            pct(&self.op_true)
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_error_is_the_mean_signed_fraction() {
        let mut r = Relative::default();
        r.add(0.9, 1.0);
        r.add(2.2, 2.0);
        assert!((r.mean().unwrap() - 0.0).abs() < 1e-12);
        r.add(f64::NAN, 1.0);
        r.add(1.0, 0.0);
        assert_eq!(r.count, 2);
        assert!((r.worst - 0.1).abs() < 1e-12);
    }

    #[test]
    fn a_joint_estimate_meets_its_truth_in_either_order() {
        let cfg = rig_config::examples::load("parallel").unwrap();
        let start = 1_000_000_000;
        let mut w = Watch::new(&cfg, start);
        let t = start + 3_000_000_000;
        let est = |j: u16, k: f64| JointEstimate {
            joint: j,
            seq: 1,
            t_acq_ns: t,
            torque_nm: 0.0,
            stiffness_nm_per_rad: Some(k),
            inertia_kg_m2: None,
            inertia_var: None,
            damping_nms_per_rad: None,
            damping_var: None,
            residual_nm: None,
        };
        let truth = |j: u16, k: f64| SimTruth {
            joint: j,
            seq: 1,
            t_acq_ns: t,
            deflection_rad: 0.0,
            torque_nm: 0.0,
            link_rad: 0.0,
            stiffness_nm_per_rad: k,
        };
        w.joint_estimate(&est(0, 9.0));
        w.truth(&truth(0, 10.0));
        w.truth(&truth(1, 4.0));
        w.joint_estimate(&est(1, 5.0));
        assert!((w.stiffness_error(0).unwrap() + 0.1).abs() < 1e-12);
        assert!((w.stiffness_error(1).unwrap() - 0.25).abs() < 1e-12);
        assert_eq!(w.stiffness_error(2), None);
    }
}
