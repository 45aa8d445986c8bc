//! The simulated board (feature `sim`): one [`SimJoint`] per joint, each evaluating the
//! simulated world at the acquisition time. For a robot, the shared [`StrokeWorld`] gives the
//! joint's link angle and deflection and the joint's own plant its torque; on a single-joint
//! bench, the bench path (a hand rotating the link back and forth) drives the lever plant, and
//! an AWAS joint integrates its dynamics under paper A's drive.
//!
//! The simulator plugs in here only: the hardware path (`hardware`) never names it, and a
//! build without the `sim` feature has no simulator in it (`tests/tests/deps.rs`).

use rig_config::{JointKind, RigConfig, Topology};
use rig_model::awas::AwasState;
use rig_sim::awas_plant::{AwasInputs, AwasPlant};
use rig_sim::effects::Effects;
use rig_sim::lever_joint::{LeverJointPlant, SpringHysteresis};
use rig_sim::noise::{DelayLine, Noise, quantize};
use rig_sim::world::{HAND_STROKE_M, HAND_STROKE_S, StrokeWorld, bench_path};

use crate::board::{Applied, BoardError, JointBoard, Reading, SafeState, Truth, WatchdogAction};

enum Sim {
    Robot {
        world: StrokeWorld,
        j: usize,
        plant: LeverJointPlant,
    },
    Bench {
        path: Vec<f64>,
        period: f64,
        plant: LeverJointPlant,
        /// The torque sensor's lag (`sensor_delay_s`, whole samples).
        lag: DelayLine,
    },
    Awas {
        plant: AwasPlant,
        t_plant: f64,
    },
}

/// One simulated joint.
pub struct SimJoint {
    sim: Sim,
    effects: Effects,
    noise: Noise,
    resolution: f64,
    torque_noise_nm: f64,
}

impl std::fmt::Debug for SimJoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimJoint")
            .field("resolution", &self.resolution)
            .finish_non_exhaustive()
    }
}

impl SimJoint {
    /// The simulated joint `j` of `cfg`, seeded.
    /// `effects` are undeclared effects of the simulated joint (none by default).
    pub fn new(cfg: &RigConfig, j: usize, seed: u64, effects: Effects) -> Result<Self, BoardError> {
        let joint = &cfg.joints[j];
        let world = |e: Box<dyn std::error::Error + Send + Sync>| BoardError::Sim(e);
        // A lever joint's plant: the pivot starts mid-travel.
        let lever_plant = |vsa: &rig_model::lever::LeverVsa| {
            LeverJointPlant::new(
                *vsa,
                SpringHysteresis::default(),
                effects,
                0.5 * (vsa.d_min + vsa.d_max),
                joint.limits.stiffness_rate,
            )
            .map_err(|e| world(e.into()))
        };
        let sim = match (&joint.kind, cfg.topology) {
            (JointKind::Lever { vsa, .. }, Topology::Serial | Topology::Parallel) => {
                let (robot, g) = cfg
                    .robot()
                    .zip(cfg.geometry)
                    .ok_or_else(|| world("the config has no robot geometry".into()))?;
                let w = StrokeWorld::new(robot, g.home, HAND_STROKE_M, HAND_STROKE_S)
                    .map_err(|e| world(e.into()))?;
                Sim::Robot {
                    world: w,
                    j,
                    plant: lever_plant(vsa)?,
                }
            }
            (JointKind::Lever { vsa, .. }, Topology::Single | Topology::Bench) => {
                let period = 1.0 / cfg.rate_hz;
                Sim::Bench {
                    path: bench_path((60.0 * cfg.rate_hz) as usize, period, 0.06, seed),
                    period,
                    plant: lever_plant(vsa)?,
                    lag: DelayLine::new(effects.delay_samples(period)),
                }
            }
            (JointKind::Awas { awas, dynamics }, _) => Sim::Awas {
                plant: AwasPlant::new(
                    *awas,
                    *dynamics,
                    effects,
                    AwasState {
                        theta2: 150.0,
                        ..Default::default()
                    },
                ),
                t_plant: 0.0,
            },
        };
        Ok(Self {
            sim,
            effects,
            noise: Noise::new(seed),
            resolution: joint.encoder.resolution_rad,
            torque_noise_nm: 0.003,
        })
    }

    /// The stiffness actuator's present position (pivot [m] or stiffness motor [rad]).
    pub fn actuator(&self) -> f64 {
        match &self.sim {
            Sim::Robot { plant, .. } | Sim::Bench { plant, .. } => plant.pivot.d,
            Sim::Awas { plant, .. } => plant.state.theta2,
        }
    }

    /// Sets the stiffness actuator's goal (the servo moves there at its rate).
    pub fn set_actuator_goal(&mut self, goal: f64) {
        match &mut self.sim {
            Sim::Robot { plant, .. } | Sim::Bench { plant, .. } => plant.pivot.goal = goal,
            // The AWAS stiffness motor is torque-driven in the simulation; goals are held.
            Sim::Awas { .. } => {}
        }
    }

    /// Reads the joint at rig time `t` [s], `dt` after the previous reading.
    pub fn read(&mut self, t: f64, dt: f64) -> Result<Reading, BoardError> {
        let res = self.resolution;
        match &mut self.sim {
            Sim::Robot { world, j, plant } => {
                let (link, defl) = world.joint(*j, t).map_err(|e| BoardError::Sim(e.into()))?;
                let tau = plant.torque(defl, t, dt);
                Ok(Reading {
                    motor_rad: world.motors[*j],
                    deflection_rad: quantize(defl, res),
                    pivot_m: Some(plant.pivot.d),
                    torque_nm: None,
                    motor_torque_nm: None,
                    stiffness_motor_rad: None,
                    actuator: plant.pivot.d,
                    truth: Some(Truth {
                        deflection_rad: defl,
                        torque_nm: tau,
                        link_rad: link,
                        stiffness_nm_per_rad: plant.stiffness(t),
                    }),
                })
            }
            Sim::Bench {
                path,
                period,
                plant,
                lag,
            } => {
                let k = ((t / *period).round() as usize) % path.len().max(1);
                let defl = path.get(k).copied().unwrap_or(0.0);
                let tau = plant.torque(defl, t, dt);
                let e = &self.effects;
                let sensed = lag.push(tau + e.ripple(defl) + e.stop(defl)) + e.torque_offset_nm;
                Ok(Reading {
                    motor_rad: 0.0,
                    deflection_rad: quantize(defl + e.encoder_bias(t), res),
                    pivot_m: Some(plant.pivot.d),
                    torque_nm: Some(sensed + self.noise.gaussian(self.torque_noise_nm)),
                    motor_torque_nm: None,
                    stiffness_motor_rad: None,
                    actuator: plant.pivot.d,
                    truth: Some(Truth {
                        deflection_rad: defl,
                        torque_nm: tau,
                        link_rad: defl,
                        stiffness_nm_per_rad: plant.stiffness(t),
                    }),
                })
            }
            Sim::Awas { plant, t_plant } => {
                // Integrate the dynamics up to t with the paper-A drive.
                let w = std::f64::consts::TAU;
                let h = 1e-3;
                while *t_plant + 0.5 * h < t {
                    let tp = *t_plant;
                    let u = AwasInputs {
                        tau1: 6.0 * (w * 0.7 * tp).sin()
                            + 3.0 * (w * 2.3 * tp).sin()
                            + 1.5 * (w * 9.0 * tp).sin(),
                        tau2: 0.004 * (w * 0.05 * tp).sin(),
                        tau_ext: 0.0,
                    };
                    plant.step(&u, tp, h, 2);
                    *t_plant += h;
                }
                let s = plant.state;
                let tau = plant.elastic_torque(t);
                Ok(Reading {
                    motor_rad: quantize(s.theta1, res),
                    deflection_rad: quantize(s.q, res) - quantize(s.theta1, res),
                    pivot_m: None,
                    torque_nm: Some(tau + self.noise.gaussian(0.05)),
                    motor_torque_nm: None,
                    stiffness_motor_rad: Some(s.theta2),
                    actuator: s.theta2,
                    truth: Some(Truth {
                        deflection_rad: s.q - s.theta1,
                        torque_nm: tau,
                        link_rad: s.q,
                        stiffness_nm_per_rad: plant.stiffness(t),
                    }),
                })
            }
        }
    }
}

/// The simulated joints of one board.
#[derive(Debug)]
pub struct SimBoard {
    joints: Vec<SimJoint>,
}

impl SimBoard {
    /// Joints `js` (indices into `cfg.joints`), joint `j`'s sensors seeded with `seed + j`,
    /// each with the same undeclared `effects` (none by default).
    pub fn new(
        cfg: &RigConfig,
        js: &[usize],
        seed: u64,
        effects: Effects,
    ) -> Result<Self, BoardError> {
        let joints = js
            .iter()
            .map(|&j| SimJoint::new(cfg, j, seed.wrapping_add(j as u64), effects))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { joints })
    }
}

impl JointBoard for SimBoard {
    fn name(&self) -> &'static str {
        "sim"
    }

    fn reads_the_past(&self) -> bool {
        true
    }

    fn read(&mut self, t: f64, dt: f64) -> Result<Vec<Reading>, BoardError> {
        self.joints.iter_mut().map(|j| j.read(t, dt)).collect()
    }

    fn actuator(&self, k: usize) -> f64 {
        self.joints.get(k).map_or(f64::NAN, SimJoint::actuator)
    }

    fn set_actuator_goal(&mut self, k: usize, goal: f64) {
        if let Some(j) = self.joints.get_mut(k) {
            j.set_actuator_goal(goal);
        }
    }

    /// The simulated world holds its motors where the world puts them: nothing to do.
    fn apply(
        &mut self,
        _k: usize,
        _motor: Option<f64>,
        _torque: bool,
    ) -> Result<Applied, BoardError> {
        Ok(Applied::Done)
    }

    /// The simulation holds the actuator where the guard last put its goal.
    fn on_watchdog(&mut self, k: usize, hold_at: f64) -> Result<WatchdogAction, BoardError> {
        self.set_actuator_goal(k, hold_at);
        Ok(WatchdogAction::Held)
    }

    fn safe_state(&mut self) -> SafeState {
        SafeState::NothingToSwitch
    }
}
