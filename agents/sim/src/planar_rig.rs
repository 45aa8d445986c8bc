//! Paper B's serial and parallel robots with lever VSA joints, quasi-statically.
//!
//! The motors hold the joint angles of the home pose; a hand moves the end effector along a
//! guide line (paper B §5.2). Each step the end-effector position is prescribed, the joint
//! angles follow from inverse kinematics (and loop closure for the five-bar), each joint's
//! deflection is its angle minus its held motor angle, each joint's true torque comes from its
//! [`LeverJointPlant`], and the force the hand applies — what the force sensor at the end
//! effector reads — is F = (G_u^A)ᵀ·τ (virtual work on massless links, frictionless passive
//! joint).

use nalgebra::Vector2;
use rig_model::planar::{KinematicsError, PlanarRobot, end_effector_force, wrap_angle};

use crate::lever_joint::LeverJointPlant;
use crate::noise::{Noise, quantize};

/// A stroke along a guide line: u(t) = home + A·sin(2π·cycles·t/T) along one axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stroke {
    /// 0 for x, 1 for y.
    pub axis: usize,
    pub amplitude_m: f64,
    pub cycles: f64,
    pub duration_s: f64,
}

impl Stroke {
    /// End-effector offset from home at time `t` into the stroke.
    pub fn offset(&self, t: f64) -> (f64, f64) {
        let s = self.amplitude_m
            * (2.0 * std::f64::consts::PI * self.cycles * t / self.duration_s).sin();
        if self.axis == 0 { (s, 0.0) } else { (0.0, s) }
    }
}

/// Sensor settings of the robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarSensors {
    /// Deflection encoder resolution [rad] (AS5048A: 2π/16384).
    pub encoder_resolution_rad: f64,
    /// Force-sensor noise σ [N].
    pub force_noise_n: f64,
}

/// What the rig's sensors read, plus the simulator's truth.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarSample {
    pub t: f64,
    pub ee_m: (f64, f64),
    pub motor_rad: Vec<f64>,
    /// Measured (quantised, biased) deflections.
    pub deflection_rad: Vec<f64>,
    pub pivot_m: Vec<f64>,
    /// Force-sensor reading [N].
    pub force_n: Vector2<f64>,
    /// Truth: deflections, joint torques and the force without sensor noise.
    pub true_deflection_rad: Vec<f64>,
    pub true_torque_nm: Vec<f64>,
    pub true_force_n: Vector2<f64>,
}

/// A simulated planar robot.
#[derive(Debug, Clone)]
pub struct PlanarRigSim {
    pub robot: PlanarRobot,
    pub joints: Vec<LeverJointPlant>,
    pub motors: Vec<f64>,
    pub home: (f64, f64),
    sensors: PlanarSensors,
    noise: Noise,
    ts: f64,
    t: f64,
}

impl PlanarRigSim {
    /// Motors hold the joint angles of `home`; one joint plant per actuated joint.
    pub fn new(
        robot: PlanarRobot,
        joints: Vec<LeverJointPlant>,
        home: (f64, f64),
        sensors: PlanarSensors,
        seed: u64,
        ts: f64,
    ) -> Result<Self, KinematicsError> {
        if joints.len() != robot.actuated() {
            return Err(KinematicsError::Dimension {
                expected: robot.actuated(),
                got: joints.len(),
            });
        }
        let c = robot.at_position(home.0, home.1)?;
        let motors = c.theta[..joints.len()].to_vec();
        Ok(Self {
            robot,
            joints,
            motors,
            home,
            sensors,
            noise: Noise::new(seed),
            ts,
            t: 0.0,
        })
    }

    /// Moves the end effector to `home + offset` and reads every sensor.
    pub fn step(&mut self, offset: (f64, f64)) -> Result<PlanarSample, KinematicsError> {
        let ee = (self.home.0 + offset.0, self.home.1 + offset.1);
        let c = self.robot.at_position(ee.0, ee.1)?;
        let n = self.joints.len();
        let defl: Vec<f64> = (0..n)
            .map(|i| wrap_angle(c.theta[i] - self.motors[i]))
            .collect();
        let (t, ts) = (self.t, self.ts);
        let torque: Vec<f64> = self
            .joints
            .iter_mut()
            .zip(&defl)
            .map(|(j, &phi)| j.torque(phi, t, ts))
            .collect();
        let force = end_effector_force(&c.g_u_a, &torque)?;
        let res = self.sensors.encoder_resolution_rad;
        let measured: Vec<f64> = self
            .joints
            .iter()
            .zip(&defl)
            .map(|(j, &phi)| quantize(phi + j.effects.encoder_bias(t), res))
            .collect();
        let fs = self.sensors.force_noise_n;
        let force_meas = force + Vector2::new(self.noise.gaussian(fs), self.noise.gaussian(fs));
        let sample = PlanarSample {
            t,
            ee_m: ee,
            motor_rad: self.motors.clone(),
            deflection_rad: measured,
            pivot_m: self.joints.iter().map(|j| j.pivot.d).collect(),
            force_n: force_meas,
            true_deflection_rad: defl,
            true_torque_nm: torque,
            true_force_n: force,
        };
        self.t += self.ts;
        Ok(sample)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::Effects;
    use crate::lever_joint::SpringHysteresis;
    use rig_model::lever::LeverVsa;
    use rig_model::planar::{FiveBar, operational_stiffness};

    #[test]
    fn small_push_gives_k_uu_force_without_hysteresis() {
        let robot = PlanarRobot::FiveBar(FiveBar::example());
        let h = SpringHysteresis {
            a: 1.0,
            ..Default::default()
        };
        let d = [0.006, 0.009, 0.012, 0.015];
        let joints = d
            .iter()
            .map(|&d| {
                LeverJointPlant::new(LeverVsa::paper_b(), h, Effects::default(), d, 0.02).unwrap()
            })
            .collect();
        let sensors = PlanarSensors {
            encoder_resolution_rad: 0.0,
            force_noise_n: 0.0,
        };
        let mut sim =
            PlanarRigSim::new(robot.clone(), joints, (0.075, 0.2), sensors, 1, 1e-3).unwrap();
        let s = sim.step((1e-4, -5e-5)).unwrap();
        let c = robot.at_position(0.075, 0.2).unwrap();
        let k: Vec<f64> = d
            .iter()
            .map(|&d| LeverVsa::paper_b().stiffness_at_rest(d))
            .collect();
        let expected = operational_stiffness(&c.g_u_a, &k).unwrap() * Vector2::new(1e-4, -5e-5);
        assert!(
            (s.true_force_n - expected).norm() < 1e-2 * expected.norm(),
            "{} vs {}",
            s.true_force_n,
            expected
        );
        assert_eq!(s.force_n, s.true_force_n);
    }
}
