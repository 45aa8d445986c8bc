//! The simulated world of a running rig, as a function of rig time: a hand pushing the end
//! effector along guide lines, stroke after stroke (x, then y, then again). Every simulated
//! joint agent evaluates the same world at its acquisition times, so agents on different
//! processes agree without talking: joint angles follow from kinematics alone (the motion is
//! prescribed), and each agent's own torque from its own joint. On a single-joint bench the
//! hand rotates the output link back and forth instead ([`bench_path`]).

use nalgebra::Matrix2;
use nalgebra::Vector2;
use rig_model::planar::{
    KinematicsError, PlanarRobot, end_effector_force, operational_stiffness, wrap_angle,
};

use crate::noise::Noise;
use crate::planar_rig::Stroke;

/// Stroke amplitude [m] of the simulated hand in a running robot rig (every simulated joint
/// agent and every scorer of its estimates uses the same world).
pub const HAND_STROKE_M: f64 = 0.006;
/// Duration [s] of one stroke of the simulated hand.
pub const HAND_STROKE_S: f64 = 4.0;

/// Strokes repeated forever.
#[derive(Debug, Clone)]
pub struct StrokeWorld {
    pub robot: PlanarRobot,
    pub home: (f64, f64),
    /// Joint angles held by the motors (those of the home pose).
    pub motors: Vec<f64>,
    pub strokes: Vec<Stroke>,
}

impl StrokeWorld {
    /// x then y strokes of `amplitude_m`, one cycle of `stroke_s` seconds each.
    pub fn new(
        robot: PlanarRobot,
        home: (f64, f64),
        amplitude_m: f64,
        stroke_s: f64,
    ) -> Result<Self, KinematicsError> {
        let c = robot.at_position(home.0, home.1)?;
        let motors = c.theta[..robot.actuated()].to_vec();
        let strokes = (0..2)
            .map(|axis| Stroke {
                axis,
                amplitude_m,
                cycles: 1.0,
                duration_s: stroke_s,
            })
            .collect();
        Ok(Self {
            robot,
            home,
            motors,
            strokes,
        })
    }

    /// End-effector position at rig time `t` [s].
    pub fn position(&self, t: f64) -> (f64, f64) {
        let period: f64 = self.strokes.iter().map(|s| s.duration_s).sum();
        let mut tau = t.rem_euclid(period.max(1e-9));
        for s in &self.strokes {
            if tau < s.duration_s {
                let (dx, dy) = s.offset(tau);
                return (self.home.0 + dx, self.home.1 + dy);
            }
            tau -= s.duration_s;
        }
        self.home
    }

    /// Link angle and deflection of actuated joint `j` at time `t`.
    pub fn joint(&self, j: usize, t: f64) -> Result<(f64, f64), KinematicsError> {
        let (x, y) = self.position(t);
        let c = self.robot.at_position(x, y)?;
        let theta = *c.theta.get(j).ok_or(KinematicsError::Dimension {
            expected: self.motors.len(),
            got: j + 1,
        })?;
        let motor = *self.motors.get(j).ok_or(KinematicsError::Dimension {
            expected: self.motors.len(),
            got: j + 1,
        })?;
        Ok((theta, wrap_angle(theta - motor)))
    }

    /// The force the hand applies at time `t` given every joint's true torque.
    pub fn force(&self, t: f64, torques: &[f64]) -> Result<Vector2<f64>, KinematicsError> {
        let (x, y) = self.position(t);
        let c = self.robot.at_position(x, y)?;
        end_effector_force(&c.g_u_a, torques)
    }

    /// The operational stiffness K_uu [N/m] at time `t` given every joint's true stiffness
    /// (small loads: the load-dependent geometric term neglected, as MODEL.md §3).
    pub fn operational_stiffness(
        &self,
        t: f64,
        stiffness: &[f64],
    ) -> Result<Matrix2<f64>, KinematicsError> {
        let (x, y) = self.position(t);
        let c = self.robot.at_position(x, y)?;
        operational_stiffness(&c.g_u_a, stiffness)
    }
}

/// A deterministic back-and-forth deflection path of varying amplitude with occasional
/// minor loops, as a hand rotating the output link "back and forth randomly" (paper B §3.2).
pub fn bench_path(n: usize, ts: f64, amplitude: f64, seed: u64) -> Vec<f64> {
    let mut rng = Noise::new(seed);
    let tau = std::f64::consts::TAU;
    let (p1, p2, p3) = (
        tau * rng.uniform(),
        tau * rng.uniform(),
        tau * rng.uniform(),
    );
    (0..n)
        .map(|i| {
            let t = i as f64 * ts;
            let env = 0.6 + 0.3 * (tau * 0.07 * t + p1).sin();
            let main = (tau * 0.5 * t + 0.8 * (tau * 0.13 * t + p2).sin()).sin();
            amplitude * (env * main + 0.12 * (tau * 1.7 * t + p3).sin())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rig_model::planar::FiveBar;

    #[test]
    fn strokes_cycle_x_then_y_and_return_home() {
        let w = StrokeWorld::new(
            PlanarRobot::FiveBar(FiveBar::example()),
            (0.075, 0.2),
            0.006,
            2.0,
        )
        .unwrap();
        let (x, y) = w.position(0.5);
        assert!((x - 0.081).abs() < 1e-12 && (y - 0.2).abs() < 1e-12);
        let (x, y) = w.position(2.5);
        assert!((x - 0.075).abs() < 1e-12 && (y - 0.206).abs() < 1e-12);
        let (x, y) = w.position(4.0);
        assert!((x - 0.075).abs() < 1e-12 && (y - 0.2).abs() < 1e-12);
        let (_, defl) = w.joint(0, 0.0).unwrap();
        assert!(defl.abs() < 1e-12);
        assert!(w.joint(7, 0.0).is_err());
    }
}
