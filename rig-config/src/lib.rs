//! # rig-config — one TOML file describes the rig
//!
//! Topology, geometry, every joint (servos, encoder, VSA parameters, restoring-torque model,
//! limits), observer gains and Zenoh endpoints. The file uses lab units with the unit in the
//! field name (`l1_mm`, `spring_limit_deg`); [`load`] validates it once and returns SI types.
//!
//! Unknown keys are rejected. Every error names the file, the line and the field, and says
//! what is allowed; all problems of a file are reported together. See
//! `rig-config/examples/*.toml` for commented examples.

mod error;
mod raw;
mod security;
mod validate;

use std::path::{Path, PathBuf};

pub use error::{ConfigError, ConfigErrors, FieldPath, Seg};
use rig_model::awas::{Awas, AwasDynamics};
use rig_model::hysteresis::RestoringCurve;
use rig_model::lever::LeverVsa;
use rig_model::observer::EkfConfig;
use rig_model::planar::{Elbow, FiveBar, FiveBarGeometry, PlanarRobot, SerialArm};
pub use security::{
    Grants, Identity, SecurityConfig, board_identity, board_may_carry, board_name, identities,
};
pub use validate::{check_endpoint, endpoint_reaches, endpoint_security, unreachable_pairs};

/// How the joints are arranged.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Topology {
    /// One joint on a test bench (paper A's AWAS, or a lever VSA).
    Single,
    /// Serial 2-link arm (paper B chain 1).
    Serial,
    /// Five-bar with four VSAs and a passive fifth joint (paper B).
    Parallel,
    /// Independent joints on a test bench, 1 to [`MAX_BENCH_JOINTS`]: no robot, each joint
    /// estimated alone (a spring-characterisation bench, or a throughput test).
    Bench,
}

/// Most joints a bench rig may have: as many as one board message carries (`rig bench
/// throughput` finds where one estimator host saturates below it).
pub const MAX_BENCH_JOINTS: usize = rig_protocol::MAX_BOARD_JOINTS;

impl Topology {
    /// How many joints the topology takes: (fewest, most).
    pub fn joint_count(self) -> (usize, usize) {
        match self {
            Topology::Single => (1, 1),
            Topology::Serial => (2, 2),
            Topology::Parallel => (4, 4),
            Topology::Bench => (1, MAX_BENCH_JOINTS),
        }
    }

    /// Whether the joints form a planar robot (serial or parallel).
    pub fn is_robot(self) -> bool {
        matches!(self, Topology::Serial | Topology::Parallel)
    }

    pub fn name(self) -> &'static str {
        match self {
            Topology::Single => "single",
            Topology::Serial => "serial",
            Topology::Parallel => "parallel",
            Topology::Bench => "bench",
        }
    }
}

/// Planar geometry [m] and inverse-kinematics branches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    pub l1: f64,
    pub l2: f64,
    /// Chain-2 lengths and base offset (parallel only; 0 otherwise).
    pub l3: f64,
    pub l4: f64,
    pub l5: f64,
    pub lb: f64,
    pub elbow1: Elbow,
    pub elbow2: Elbow,
    /// Default end-effector position (x, y) [m].
    pub home: (f64, f64),
}

/// Servo bus and IDs of one joint board.
#[derive(Debug, Clone, PartialEq)]
pub struct ServoConfig {
    pub bus: String,
    pub baud: u32,
    pub main_id: u8,
    pub main_model: String,
    pub main_protocol: u8,
    /// The pivot servo of a lever VSA, the stiffness motor of AWAS.
    pub stiffness_id: u8,
    pub stiffness_model: String,
    pub stiffness_protocol: u8,
    /// Main servo angle (from its centre) at joint angle 0 [rad].
    pub main_zero_rad: f64,
    /// Pivot servo angle (from its centre) at pivot displacement d = 0 [rad].
    pub pivot_zero_rad: f64,
    /// Rack travel per radian of the pivot servo [m/rad] (lever joints driven by the
    /// dynamixel backend need it; `None` where the config leaves it out).
    pub pivot_m_per_rad: Option<f64>,
}

/// How the board reads the deflection encoder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncoderInterface {
    /// SPI through spidev on the joint board.
    Spi,
    /// A serial bridge (paper B's Arduino).
    Serial,
}

/// The deflection encoder.
#[derive(Debug, Clone, PartialEq)]
pub struct EncoderConfig {
    pub model: String,
    pub bits: u8,
    pub interface: EncoderInterface,
    /// One count [rad].
    pub resolution_rad: f64,
    /// The serial bridge's port or the spidev device (`None`: only simulated).
    pub device: Option<String>,
    /// Baud rate of the serial bridge.
    pub baud: u32,
    /// This encoder's index on the bridge.
    pub channel: u8,
    /// The count at zero deflection.
    pub zero_counts: u32,
}

/// What kind of VSA a joint is, with its parameters.
#[derive(Debug, Clone)]
pub enum JointKind {
    /// Paper B's lever VSA with its restoring-torque model.
    Lever {
        vsa: LeverVsa,
        restoring: Box<RestoringCurve>,
        dead_band_rad: f64,
    },
    /// Paper A's AWAS.
    Awas { awas: Awas, dynamics: AwasDynamics },
}

/// Limits the joint agent enforces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub motor_min_rad: f64,
    pub motor_max_rad: f64,
    /// Fastest pivot motion [m/s] (lever) or stiffness-motor motion [rad/s] (AWAS).
    pub stiffness_rate: f64,
    /// Joint stiffness bounds for allocation [N·m/rad] (default: the mechanism's range).
    pub k_min: f64,
    pub k_max: f64,
    /// Hold the last safe position when no command came for this long [s].
    pub watchdog_s: f64,
}

/// One joint.
#[derive(Debug, Clone)]
pub struct JointConfig {
    pub name: String,
    /// Position in the file, 0-based (θ1 is joint 0).
    pub index: usize,
    /// Dynamixel servos; `None` for a joint that only runs simulated.
    pub servo: Option<ServoConfig>,
    pub encoder: EncoderConfig,
    pub kind: JointKind,
    pub limits: Limits,
    /// Effects identified on the joint and applied live by the estimator (`[joint.effects]`).
    pub effects: JointEffects,
    /// The joint board's torque reference (`[joint.torque_sensor]`), when it has one.
    pub torque_sensor: Option<TorqueSensorConfig>,
}

/// A load cell through an HX711 amplifier, read by the encoder bridge (its own channels,
/// counted from 0 apart from the encoders'): τ = (conversion − `zero_counts`)·`nm_per_count`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueSensorConfig {
    pub channel: u8,
    /// The conversion at no load (24-bit two's complement).
    pub zero_counts: i32,
    /// Torque per count [N·m] (negative when the cell reads the other way round).
    pub nm_per_count: f64,
}

/// What `rig identify --apply` wrote into `[joint.effects]`: the sensor zeros the estimator
/// takes off each sample before its model sees it, and the effects its lever joint model
/// applies live ([`rig_model::live`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct JointEffects {
    /// The torque sensor reads this much high: subtracted from its readings [N·m].
    pub torque_offset_nm: f64,
    /// The deflection encoder reads this much high: subtracted from φ [rad].
    pub encoder_offset_rad: f64,
    /// Backlash, hard stop, ripple and a sensor lag (lever joints only).
    pub live: rig_model::live::LiveEffects,
}

/// Gains of the impedance observer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverConfig {
    pub alpha: f64,
    pub k0: f64,
    pub q_diag: [f64; 4],
    pub r_diag: [f64; 2],
    pub p0_diag: [f64; 4],
}

impl ObserverConfig {
    /// The EKF tuning at sample time `ts`.
    pub fn ekf(&self, ts: f64) -> EkfConfig {
        EkfConfig {
            ts,
            q_diag: self.q_diag,
            r_diag: self.r_diag,
            p0_diag: self.p0_diag,
            x0: [0.0; 4],
        }
    }
}

/// Zenoh session mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ZenohMode {
    Peer,
    Client,
    Router,
}

/// Zenoh endpoints.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ZenohConfig {
    pub mode: ZenohMode,
    pub listen: Vec<String>,
    pub connect: Vec<String>,
}

/// A role one machine of the plan runs (`[[machine]].roles`).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Role {
    /// The joint agent of the named joint (its board computer).
    Joint(String),
    Estimator,
    Allocator,
    /// `rig record`: every message of the rig into an MCAP file.
    Recorder,
    /// `rig viz`: the Rerun view.
    Viz,
}

impl Role {
    /// The role as the config writes it (a joint by its name).
    pub fn name(&self) -> &str {
        match self {
            Role::Joint(j) => j,
            Role::Estimator => "estimator",
            Role::Allocator => "allocator",
            Role::Recorder => "recorder",
            Role::Viz => "viz",
        }
    }
}

/// One machine of the lab's plan (`[[machine]]`): the roles it runs and how it links to the
/// others. `rig launch --machine` runs a Zenoh router on it (the machine's hub: it listens
/// and connects as written here, and forwards between its roles and the other machines'
/// hubs); its roles join the hub on loopback. A config without machines runs everything on
/// one machine (`rig up`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Machine {
    pub name: String,
    pub roles: Vec<Role>,
    /// Endpoints its hub listens on (others connect here).
    pub listen: Vec<String>,
    /// Endpoints of other machines' hubs it connects to.
    pub connect: Vec<String>,
}

/// How far apart the rig's clocks may be (`[clock]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockConfig {
    /// A sample stamped further than this from the receiving host's clock is refused [s].
    pub max_offset_s: f64,
}

impl Default for ClockConfig {
    /// 100 ms: far above a sample's transit on a lab network, far below a wrong clock's hours.
    fn default() -> Self {
        Self { max_offset_s: 0.1 }
    }
}

/// The whole validated rig.
#[derive(Debug, Clone)]
pub struct RigConfig {
    /// The file it came from.
    pub source: PathBuf,
    pub name: String,
    pub topology: Topology,
    /// Joint sample rate [Hz].
    pub rate_hz: f64,
    pub geometry: Option<Geometry>,
    pub joints: Vec<JointConfig>,
    pub observer: ObserverConfig,
    pub zenoh: ZenohConfig,
    pub clock: ClockConfig,
    /// The plan: which machine runs what (empty: all on one machine).
    pub machines: Vec<Machine>,
    /// Mutual TLS and access control (`[security]`); `None`: insecure, for loopback.
    pub security: Option<SecurityConfig>,
}

impl RigConfig {
    /// The machine of the plan called `name`.
    pub fn machine(&self, name: &str) -> Option<&Machine> {
        self.machines.iter().find(|m| m.name == name)
    }

    /// The planar robot, for serial and parallel rigs.
    pub fn robot(&self) -> Option<PlanarRobot> {
        let g = self.geometry?;
        // Geometry was validated, so construction cannot fail; map errors to None anyway.
        match self.topology {
            Topology::Single | Topology::Bench => None,
            Topology::Serial => SerialArm::new(g.l1, g.l2, g.elbow1)
                .ok()
                .map(PlanarRobot::Serial),
            Topology::Parallel => FiveBar::new(
                FiveBarGeometry {
                    l1: g.l1,
                    l2: g.l2,
                    l3: g.l3,
                    l4: g.l4,
                    l5: g.l5,
                    lb: g.lb,
                },
                g.elbow1,
                g.elbow2,
            )
            .ok()
            .map(PlanarRobot::FiveBar),
        }
    }
}

/// The example configs, compiled in so that commands work from any directory.
pub mod examples {
    /// `rig-config/examples/parallel.toml`.
    pub const PARALLEL: &str = include_str!("../examples/parallel.toml");
    /// `rig-config/examples/serial.toml`.
    pub const SERIAL: &str = include_str!("../examples/serial.toml");
    /// `rig-config/examples/awas.toml`.
    pub const AWAS: &str = include_str!("../examples/awas.toml");

    /// Parses one of the examples by name: "parallel", "serial" or "awas".
    pub fn load(name: &str) -> Result<super::RigConfig, super::ConfigErrors> {
        let src = match name {
            "serial" => SERIAL,
            "awas" => AWAS,
            _ => PARALLEL,
        };
        super::parse(
            std::path::Path::new(&format!("rig-config/examples/{name}.toml")),
            src,
        )
    }
}

/// Reads and validates a config file.
pub fn load(path: &Path) -> Result<RigConfig, ConfigErrors> {
    let src = std::fs::read_to_string(path).map_err(|e| {
        ConfigErrors(vec![ConfigError {
            file: path.to_path_buf(),
            line: None,
            field: String::new(),
            message: format!("cannot read the file: {e}"),
        }])
    })?;
    parse(path, &src)
}

/// Validates config text; `path` is used in messages.
pub fn parse(path: &Path, src: &str) -> Result<RigConfig, ConfigErrors> {
    validate::parse(path, src)
}

#[cfg(test)]
mod tests;
