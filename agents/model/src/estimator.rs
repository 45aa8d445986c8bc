//! The estimator's core for a planar robot, sans I/O: joint samples in, joint torques, the
//! end-effector force and the operational stiffness out (paper B §3–4).
//!
//! Per actuated joint, paper B's restoring-torque model turns the measured deflection (and
//! pivot position) into a torque; the measured joint angles (motor + deflection) give the
//! configuration by loop closure from the independent joints θ1, θ2; then F = (G_u^A)ᵀ·τ̂ and
//! K_uu = (G_u^A)ᵀ·diag(k̂)·G_u^A with k̂ the model's stiffness at each joint's state.

use nalgebra::{Matrix2, Vector2};
use thiserror::Error;

use crate::live::{LiveJoint, LiveTorque};
use crate::planar::{
    Configuration, KinematicsError, PlanarRobot, end_effector_force, operational_stiffness,
};

/// Errors of the robot estimator.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EstimateError {
    #[error("expected {expected} joints, got {got}")]
    JointCount { expected: usize, got: usize },
    #[error("joint {joint}: non-finite {what}")]
    NonFinite { joint: usize, what: &'static str },
    #[error(transparent)]
    Kinematics(#[from] KinematicsError),
}

/// One aligned set of joint measurements.
#[derive(Debug, Clone, PartialEq)]
pub struct JointReadings<'a> {
    /// When they were taken [s] (any origin, non-decreasing from call to call).
    pub t_s: f64,
    /// Motor angles θ_m [rad].
    pub motor: &'a [f64],
    /// Measured deflections φ [rad].
    pub deflection: &'a [f64],
    /// Pivot positions d [m].
    pub pivot: &'a [f64],
}

/// The estimate for one aligned sample.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotEstimate {
    pub configuration: Configuration,
    /// Joint torques τ̂ [N·m].
    pub torque: Vec<f64>,
    /// Joint stiffnesses k̂ [N·m/rad].
    pub stiffness: Vec<f64>,
    /// External force at the end effector [N].
    pub force: Vector2<f64>,
    /// Operational stiffness [N/m].
    pub operational_stiffness: Matrix2<f64>,
}

/// Restoring-torque models of the actuated joints (with their live effects) plus the robot's
/// kinematics.
#[derive(Debug, Clone)]
pub struct RobotEstimator {
    robot: PlanarRobot,
    joints: Vec<LiveJoint>,
}

impl RobotEstimator {
    /// One restoring-torque model per actuated joint, in joint order (`LiveJoint::from` a
    /// bare model when no effect is applied).
    pub fn new(robot: PlanarRobot, joints: Vec<LiveJoint>) -> Result<Self, EstimateError> {
        if joints.len() != robot.actuated() {
            return Err(EstimateError::JointCount {
                expected: robot.actuated(),
                got: joints.len(),
            });
        }
        Ok(Self { robot, joints })
    }

    pub fn robot(&self) -> &PlanarRobot {
        &self.robot
    }

    /// Number of actuated joints.
    pub fn joints(&self) -> usize {
        self.joints.len()
    }

    /// Feeds one joint's sample taken at `t_s` [s] to its model: τ̂ (and the residual against
    /// `measured`, the joint's torque reference, when it has one) and k̂ at the current state
    /// ([`crate::hysteresis::RestoringTorqueModel::stiffness`]: the loop's centre-line slope at φ and d).
    /// Non-finite input leaves the model unchanged (it returns its last estimate).
    pub fn update_joint(
        &mut self,
        j: usize,
        t_s: f64,
        deflection: f64,
        pivot: f64,
        measured: Option<f64>,
    ) -> Option<(LiveTorque, f64)> {
        let m = self.joints.get_mut(j)?;
        let out = m.update(t_s, deflection, pivot, measured);
        Some((out, m.model().stiffness()))
    }

    /// Combines one aligned set of joint readings and their torques into the end-effector
    /// estimate: configuration by loop closure from θ1, θ2, then F and K_uu.
    pub fn combine(
        &self,
        r: &JointReadings<'_>,
        torque: Vec<f64>,
        stiffness: Vec<f64>,
    ) -> Result<RobotEstimate, EstimateError> {
        let n = self.joints.len();
        for len in [
            r.motor.len(),
            r.deflection.len(),
            r.pivot.len(),
            torque.len(),
            stiffness.len(),
        ] {
            if len != n {
                return Err(EstimateError::JointCount {
                    expected: n,
                    got: len,
                });
            }
        }
        let configuration = self
            .robot
            .from_independent(r.motor[0] + r.deflection[0], r.motor[1] + r.deflection[1])?;
        let force = end_effector_force(&configuration.g_u_a, &torque)?;
        let operational_stiffness = operational_stiffness(&configuration.g_u_a, &stiffness)?;
        Ok(RobotEstimate {
            configuration,
            torque,
            stiffness,
            force,
            operational_stiffness,
        })
    }

    /// Feeds one aligned sample of every joint. On error no model state changes.
    pub fn update(&mut self, r: &JointReadings<'_>) -> Result<RobotEstimate, EstimateError> {
        let n = self.joints.len();
        for len in [r.motor.len(), r.deflection.len(), r.pivot.len()] {
            if len != n {
                return Err(EstimateError::JointCount {
                    expected: n,
                    got: len,
                });
            }
        }
        for j in 0..n {
            for (v, what) in [
                (r.motor[j], "motor angle"),
                (r.deflection[j], "deflection"),
                (r.pivot[j], "pivot position"),
            ] {
                if !v.is_finite() {
                    return Err(EstimateError::NonFinite { joint: j, what });
                }
            }
        }
        // Loop closure first: an unreachable reading must not advance the models.
        self.robot
            .from_independent(r.motor[0] + r.deflection[0], r.motor[1] + r.deflection[1])?;
        let (torque, stiffness): (Vec<f64>, Vec<f64>) = (0..n)
            .map(|j| {
                self.update_joint(j, r.t_s, r.deflection[j], r.pivot[j], None)
                    .map_or((0.0, 0.0), |(t, k)| (t.torque_nm, k))
            })
            .unzip();
        self.combine(r, torque, stiffness)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::{
        AS5048A_COUNT_RAD, RestoringCurve, RestoringParams, RestoringTorqueModel,
    };
    use crate::planar::FiveBar;

    fn estimator() -> RobotEstimator {
        let curve = RestoringCurve::constant(RestoringParams {
            k: 3.0,
            h: 0.0,
            a_s: 1e6,
            n: 1.0,
        });
        let joints = (0..4)
            .map(|_| RestoringTorqueModel::new(curve.clone(), AS5048A_COUNT_RAD).into())
            .collect();
        RobotEstimator::new(PlanarRobot::FiveBar(FiveBar::example()), joints).unwrap()
    }

    #[test]
    fn linear_springs_give_k_uu_times_displacement() {
        // Without hysteresis (h = 0, instant transition), τ = k·φ, so for a small end-effector
        // displacement δu from the rest pose F ≈ K_uu·δu.
        let mut est = estimator();
        let robot = PlanarRobot::FiveBar(FiveBar::example());
        let rest = robot.at_position(0.075, 0.2).unwrap();
        let motor: Vec<f64> = rest.theta[..4].to_vec();
        let moved = robot.at_position(0.0752, 0.2001).unwrap();
        let defl: Vec<f64> = (0..4).map(|i| moved.theta[i] - motor[i]).collect();
        let pivot = [0.009; 4];
        est.update(&JointReadings {
            t_s: 0.0,
            motor: &motor,
            deflection: &[0.0; 4],
            pivot: &pivot,
        })
        .unwrap();
        let e = est
            .update(&JointReadings {
                t_s: 1e-3,
                motor: &motor,
                deflection: &defl,
                pivot: &pivot,
            })
            .unwrap();
        let expected = e.operational_stiffness * Vector2::new(0.0002, 0.0001);
        assert!(
            (e.force - expected).norm() < 2e-3 * expected.norm(),
            "{} vs {}",
            e.force,
            expected
        );
    }

    #[test]
    fn bad_readings_are_errors() {
        let mut est = estimator();
        let m = [1.0, -1.0, 1.0, 1.0];
        assert!(
            est.update(&JointReadings {
                t_s: 1e-3,
                motor: &m[..3],
                deflection: &[0.0; 4],
                pivot: &[0.0; 4]
            })
            .is_err()
        );
        let e = est.update(&JointReadings {
            t_s: 0.0,
            motor: &m,
            deflection: &[0.0, f64::NAN, 0.0, 0.0],
            pivot: &[0.0; 4],
        });
        assert_eq!(
            e.unwrap_err(),
            EstimateError::NonFinite {
                joint: 1,
                what: "deflection"
            }
        );
    }
}
