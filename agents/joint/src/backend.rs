//! Where a board's readings come from: `sim` (this module's [`SimBackend`], one per joint) or
//! `dynamixel` ([`crate::hardware::DynamixelBoard`], the whole board's buses at once), behind
//! one [`Board`].
//!
//! The sim backend evaluates the simulated world at each acquisition time: for a robot, the
//! shared [`StrokeWorld`] gives this joint's link angle and deflection and the joint's own
//! plant its torque; on a single-joint bench, the bench path (lever) or the AWAS dynamics.

use rig_config::{JointKind, RigConfig, Topology};
use rig_model::awas::AwasState;
use rig_sim::awas_plant::{AwasInputs, AwasPlant};
use rig_sim::effects::Effects;
use rig_sim::lever_joint::{LeverJointPlant, SpringHysteresis};
use rig_sim::noise::{Noise, quantize};
use rig_sim::reproduce::paper_b::bench_path;
use rig_sim::world::StrokeWorld;
use thiserror::Error;

/// Errors of a backend.
#[derive(Debug, Error)]
pub enum BackendError {
    #[error("joint {0:?} is not in the config (joints: {1})")]
    UnknownJoint(String, String),
    #[error("simulated world: {0}")]
    World(String),
    #[error(transparent)]
    Hardware(#[from] crate::hardware::HardwareError),
}

/// What the simulator knows and a real joint cannot: the true deflection [rad], torque
/// [N·m], link angle [rad] and stiffness [N·m/rad].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    pub deflection_rad: f64,
    pub torque_nm: f64,
    pub link_rad: f64,
    pub stiffness_nm_per_rad: f64,
}

/// One reading of the joint, and (simulated backends only) the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    pub motor_rad: f64,
    pub deflection_rad: f64,
    pub pivot_m: Option<f64>,
    pub torque_nm: Option<f64>,
    pub stiffness_motor_rad: Option<f64>,
    pub truth: Option<Truth>,
}

/// Stroke amplitude and duration of the simulated hand in a running robot rig.
pub const WORLD_STROKE_M: f64 = 0.006;
pub const WORLD_STROKE_S: f64 = 4.0;

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
    },
    Awas {
        plant: AwasPlant,
        t_plant: f64,
    },
}

/// The simulated joint.
pub struct SimBackend {
    sim: Sim,
    effects: Effects,
    noise: Noise,
    resolution: f64,
    torque_noise_nm: f64,
}

impl std::fmt::Debug for SimBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimBackend")
            .field("resolution", &self.resolution)
            .finish_non_exhaustive()
    }
}

/// The joint's index in the config.
pub fn joint_index(cfg: &RigConfig, name: &str) -> Result<usize, BackendError> {
    cfg.joints
        .iter()
        .position(|j| j.name == name)
        .ok_or_else(|| {
            BackendError::UnknownJoint(
                name.to_string(),
                cfg.joints
                    .iter()
                    .map(|j| j.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            )
        })
}

impl SimBackend {
    /// The simulated joint `j` of `cfg`, seeded.
    /// `effects` are undeclared effects of the simulated joint (none by default).
    pub fn new(
        cfg: &RigConfig,
        j: usize,
        seed: u64,
        effects: Effects,
    ) -> Result<Self, BackendError> {
        let joint = &cfg.joints[j];
        let world = |e: String| BackendError::World(e);
        let sim = match (&joint.kind, cfg.topology) {
            (JointKind::Lever { vsa, .. }, Topology::Serial | Topology::Parallel) => {
                let (robot, g) = cfg
                    .robot()
                    .zip(cfg.geometry)
                    .ok_or_else(|| world("no robot geometry".into()))?;
                let w = StrokeWorld::new(robot, g.home, WORLD_STROKE_M, WORLD_STROKE_S)
                    .map_err(|e| world(e.to_string()))?;
                let d0 = 0.5 * (vsa.d_min + vsa.d_max);
                let plant = LeverJointPlant::new(
                    *vsa,
                    SpringHysteresis::default(),
                    effects,
                    d0,
                    joint.limits.stiffness_rate,
                )
                .map_err(|e| world(e.to_string()))?;
                Sim::Robot { world: w, j, plant }
            }
            (JointKind::Lever { vsa, .. }, Topology::Single | Topology::Bench) => {
                let d0 = 0.5 * (vsa.d_min + vsa.d_max);
                let plant = LeverJointPlant::new(
                    *vsa,
                    SpringHysteresis::default(),
                    effects,
                    d0,
                    joint.limits.stiffness_rate,
                )
                .map_err(|e| world(e.to_string()))?;
                let period = 1.0 / cfg.rate_hz;
                Sim::Bench {
                    path: bench_path((60.0 * cfg.rate_hz) as usize, period, 0.06, seed),
                    period,
                    plant,
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
    pub fn read(&mut self, t: f64, dt: f64) -> Result<Reading, BackendError> {
        let res = self.resolution;
        match &mut self.sim {
            Sim::Robot { world, j, plant } => {
                let (link, defl) = world
                    .joint(*j, t)
                    .map_err(|e| BackendError::World(e.to_string()))?;
                let tau = plant.torque(defl, t, dt);
                Ok(Reading {
                    motor_rad: world.motors[*j],
                    deflection_rad: quantize(defl, res),
                    pivot_m: Some(plant.pivot.d),
                    torque_nm: None,
                    stiffness_motor_rad: None,
                    truth: Some(Truth {
                        deflection_rad: defl,
                        torque_nm: tau,
                        link_rad: link,
                        stiffness_nm_per_rad: plant.rest_stiffness(),
                    }),
                })
            }
            Sim::Bench {
                path,
                period,
                plant,
            } => {
                let k = ((t / *period).round() as usize) % path.len().max(1);
                let defl = path.get(k).copied().unwrap_or(0.0);
                let tau = plant.torque(defl, t, dt);
                let e = &self.effects;
                let sensed = tau + e.ripple(defl) + e.stop(defl) + e.torque_offset_nm;
                Ok(Reading {
                    motor_rad: 0.0,
                    deflection_rad: quantize(defl + e.encoder_bias(t), res),
                    pivot_m: Some(plant.pivot.d),
                    torque_nm: Some(sensed + self.noise.gaussian(self.torque_noise_nm)),
                    stiffness_motor_rad: None,
                    truth: Some(Truth {
                        deflection_rad: defl,
                        torque_nm: tau,
                        link_rad: defl,
                        stiffness_nm_per_rad: plant.rest_stiffness(),
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
                    stiffness_motor_rad: Some(s.theta2),
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

/// The backend of a board serving one or more joints (indices into the board's own list).
#[derive(Debug)]
pub enum Board {
    /// One simulated joint each.
    Sim(Vec<SimBackend>),
    /// The real (or virtual) servos and encoders.
    Dynamixel(Box<crate::hardware::DynamixelBoard>),
}

/// What a board did with a command's motor goal and torque switch.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Applied {
    Done,
    /// The hardware cannot do it; the text says why (the joint goes on as before).
    Refused(String),
}

impl Board {
    /// The backend's name, for statuses.
    pub fn name(&self) -> &'static str {
        match self {
            Board::Sim(_) => "sim",
            Board::Dynamixel(_) => "dynamixel",
        }
    }

    /// Whether ticks missed by a late wake-up can still be read (a simulation can evaluate
    /// the past; hardware reads only now).
    pub fn reads_the_past(&self) -> bool {
        matches!(self, Board::Sim(_))
    }

    /// Every joint's reading at rig time `t` [s], `dt` after the previous reading.
    pub fn read(&mut self, t: f64, dt: f64) -> Result<Vec<Reading>, BackendError> {
        match self {
            Board::Sim(v) => v.iter_mut().map(|b| b.read(t, dt)).collect(),
            Board::Dynamixel(b) => Ok(b.read(dt)?),
        }
    }

    /// Joint `k`'s stiffness actuator position (pivot [m], AWAS stiffness motor [rad]).
    pub fn actuator(&self, k: usize) -> f64 {
        match self {
            Board::Sim(v) => v.get(k).map_or(f64::NAN, SimBackend::actuator),
            Board::Dynamixel(b) => b.actuator(k),
        }
    }

    /// Joint `k`'s stiffness actuator goal (checked by the guard).
    pub fn set_actuator_goal(&mut self, k: usize, goal: f64) {
        match self {
            Board::Sim(v) => {
                if let Some(b) = v.get_mut(k) {
                    b.set_actuator_goal(goal);
                }
            }
            Board::Dynamixel(b) => b.set_actuator_goal(k, goal),
        }
    }

    /// Applies an accepted command's motor goal and torque switch to joint `k`. The
    /// simulated world holds its motors where the world puts them: nothing to do.
    pub fn apply(
        &mut self,
        k: usize,
        motor_goal_rad: Option<f64>,
        torque_enable: bool,
    ) -> Result<Applied, BackendError> {
        let Board::Dynamixel(b) = self else {
            return Ok(Applied::Done);
        };
        if let Some(m) = motor_goal_rad {
            match b.set_motor_goal(k, m) {
                Err(crate::hardware::HardwareError::Bus(
                    e @ rig_dynamixel::servos::BusError::OutOfRange { .. },
                )) => return Ok(Applied::Refused(format!("motor goal refused: {e}"))),
                r => r?,
            }
        }
        b.torque(k, torque_enable)?;
        Ok(Applied::Done)
    }

    /// The watchdog fired on joint `k`: the simulation holds the actuator where it is
    /// (`hold_at`), the hardware turns the joint's torque off.
    pub fn on_watchdog(&mut self, k: usize, hold_at: f64) -> Result<(), BackendError> {
        match self {
            Board::Sim(v) => {
                if let Some(b) = v.get_mut(k) {
                    b.set_actuator_goal(hold_at);
                }
                Ok(())
            }
            Board::Dynamixel(b) => Ok(b.torque(k, false)?),
        }
    }

    /// Torque off everywhere (hardware); the failures, each naming its servo.
    pub fn safe_state(&mut self) -> Vec<String> {
        match self {
            Board::Sim(_) => Vec::new(),
            Board::Dynamixel(b) => b.safe_state(),
        }
    }
}
