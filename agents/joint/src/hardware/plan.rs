//! What a Dynamixel board is made of, from the config alone: [`BoardPlan::from_config`] is
//! pure (no port is touched) and checks everything the config can get wrong — the joint's
//! kind, its servo models and protocols, whether the pivot servo reaches the whole travel, the
//! encoder interface and bits, the ports and one baud per line. [`super::DynamixelBoard::open`]
//! then only does I/O. Tests drive the plan without ports; the virtual board builds its
//! servos from the same plan.
//!
//! Mapping (config `[joint.servo]`, `[joint.encoder]`):
//! - link-side motor angle θ = main servo angle (from its centre) − `main_zero_deg`;
//! - pivot displacement d = (pivot servo angle − `pivot_zero_deg`) · `pivot_mm_per_deg`;
//! - deflection φ = encoder angle from `zero_counts`, wrapped to [−π, π).

use std::path::PathBuf;

use rig_config::{EncoderInterface, JointKind, RigConfig};
use rig_dynamixel::servos::{BusError, Servo};
use thiserror::Error;

/// A config that cannot drive a Dynamixel board: the field (`joint[1] (j2).servo.baud`) and
/// what is wrong with it.
#[derive(Debug, Error)]
pub enum PlanError {
    #[error("{field}: {message}")]
    Field { field: String, message: String },
    #[error("{field}: {source}")]
    Model {
        field: String,
        #[source]
        source: BusError,
    },
}

fn field_err(field: String, message: impl Into<String>) -> PlanError {
    PlanError::Field {
        field,
        message: message.into(),
    }
}

/// How a lever joint's servo angles [rad from each servo's centre] map to the joint: the
/// config's `main_zero_deg`, `pivot_zero_deg`, `pivot_mm_per_deg`. The virtual board shows
/// the plant through the same map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoMap {
    pub main_zero: f64,
    pub pivot_zero: f64,
    /// Rack travel per radian of the pivot servo [m/rad].
    pub m_per_rad: f64,
}

impl ServoMap {
    /// Link-side motor angle θ of a main servo angle.
    pub fn motor_rad(&self, servo: f64) -> f64 {
        servo - self.main_zero
    }

    /// Main servo angle of a link-side motor angle θ.
    pub fn main_servo(&self, motor_rad: f64) -> f64 {
        motor_rad + self.main_zero
    }

    /// Pivot displacement d [m] of a pivot servo angle.
    pub fn pivot_m(&self, servo: f64) -> f64 {
        (servo - self.pivot_zero) * self.m_per_rad
    }

    /// Pivot servo angle of a pivot displacement d [m].
    pub fn pivot_servo(&self, pivot_m: f64) -> f64 {
        self.pivot_zero + pivot_m / self.m_per_rad
    }
}

/// Ports given on the command line instead of the config's (the same for every joint served).
#[derive(Debug, Clone, Default)]
pub struct PortOverrides {
    pub bus: Option<PathBuf>,
    pub bridge: Option<PathBuf>,
}

/// One serial line of the board (a servo bus or an encoder bridge).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Line {
    pub path: String,
    pub baud: u32,
}

/// One joint of the board, as the config gives it.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedJoint {
    /// Index into the config's joints.
    pub index: usize,
    pub main: Servo,
    pub pivot: Servo,
    /// Index into [`BoardPlan::buses`] and [`BoardPlan::bridges`].
    pub bus: usize,
    pub bridge: usize,
    /// Channel on the bridge and the encoder's count at zero deflection.
    pub channel: usize,
    pub zero_counts: u16,
    pub map: ServoMap,
    /// Pivot travel [m] and fastest pivot motion [m/s].
    pub d_min: f64,
    pub d_max: f64,
    pub rate: f64,
    /// The joint's torque reference on its bridge (`[joint.torque_sensor]`), if any.
    pub load: Option<rig_config::TorqueSensorConfig>,
}

/// The board: its lines and joints, checked against the config.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardPlan {
    pub buses: Vec<Line>,
    /// Bridges, each with how many channels it is asked for (the highest channel used + 1).
    pub bridges: Vec<(Line, u8)>,
    /// Per bridge, how many load-cell channels it is asked for (0: none).
    pub loads: Vec<u8>,
    pub joints: Vec<PlannedJoint>,
}

/// Serial lines by port, each at one baud rate; a second baud for one port names both fields.
struct Lines {
    what: &'static str,
    list: Vec<Line>,
    /// The config field that set each line's baud.
    first: Vec<String>,
}

impl Lines {
    fn new(what: &'static str) -> Self {
        Self {
            what,
            list: Vec::new(),
            first: Vec::new(),
        }
    }

    /// The index of the line at `path`, added if new.
    fn index(&mut self, path: String, baud: u32, field: String) -> Result<usize, PlanError> {
        match self.list.iter().position(|l| l.path == path) {
            Some(k) if self.list[k].baud != baud => Err(field_err(
                field,
                format!(
                    "{baud} differs from {} of {} on the same {} {path}",
                    self.list[k].baud, self.first[k], self.what
                ),
            )),
            Some(k) => Ok(k),
            None => {
                self.list.push(Line { path, baud });
                self.first.push(field);
                Ok(self.list.len() - 1)
            }
        }
    }
}

impl BoardPlan {
    /// The board of joints `js` (indices into `cfg.joints`), with the ports of `ports` where
    /// given, else the config's. Every field is checked here; the first problem is returned,
    /// naming its field.
    pub fn from_config(
        cfg: &RigConfig,
        js: &[usize],
        ports: &PortOverrides,
    ) -> Result<Self, PlanError> {
        let mut buses = Lines::new("bus");
        let mut bridges = Lines::new("bridge");
        let mut channels: Vec<u8> = Vec::new();
        let mut loads: Vec<u8> = Vec::new();
        let mut joints = Vec::new();
        for &j in js {
            let joint = &cfg.joints[j];
            let at = |f: &str| format!("joint[{j}] ({}).{f}", joint.name);
            let JointKind::Lever { vsa, .. } = &joint.kind else {
                return Err(field_err(
                    at("kind"),
                    "Dynamixel boards drive lever VSAs (paper B); paper A's AWAS ran on its own boards",
                ));
            };
            let s = joint.servo.as_ref().ok_or_else(|| {
                field_err(
                    at("servo"),
                    "missing: a Dynamixel board needs the joint's [joint.servo] section",
                )
            })?;
            let m_per_rad = s.pivot_m_per_rad.ok_or_else(|| {
                field_err(
                    at("servo.pivot_mm_per_deg"),
                    "missing: the rack travel per degree of the pivot servo (pinion radius × π/180)",
                )
            })?;
            let map = ServoMap {
                main_zero: s.main_zero_rad,
                pivot_zero: s.pivot_zero_rad,
                m_per_rad,
            };
            let model = |field: &str, id: u8, name: &str| {
                Servo::new(id, name).map_err(|source| PlanError::Model {
                    field: at(field),
                    source,
                })
            };
            let main = model("servo.main_model", s.main_id, &s.main_model)?;
            let pivot = model("servo.stiffness_model", s.stiffness_id, &s.stiffness_model)?;
            // The pivot servo must reach the whole travel: then every goal the guard lets
            // through is one it can reach.
            let ends = [vsa.d_min, vsa.d_max].map(|d| map.pivot_servo(d));
            if ends.iter().any(|&a| pivot.model.to_counts(a).is_none()) {
                return Err(field_err(
                    at("servo.pivot_mm_per_deg"),
                    format!(
                        "with pivot_zero_deg the travel {:.1}–{:.1} mm needs the {} at {:.0}° to {:.0}° from its centre, beyond its range",
                        vsa.d_min * 1e3,
                        vsa.d_max * 1e3,
                        pivot.model.name,
                        ends[0].to_degrees(),
                        ends[1].to_degrees()
                    ),
                ));
            }
            for (servo, field, protocol) in [
                (main, "servo.main_protocol", s.main_protocol),
                (pivot, "servo.stiffness_protocol", s.stiffness_protocol),
            ] {
                if servo.model.protocol != protocol {
                    return Err(field_err(
                        at(field),
                        format!(
                            "the {} speaks protocol {}, not {protocol}",
                            servo.model.name, servo.model.protocol
                        ),
                    ));
                }
            }
            let e = &joint.encoder;
            if e.interface != EncoderInterface::Serial {
                return Err(field_err(
                    at("encoder.interface"),
                    "\"spi\": this agent reads the encoders through the serial bridge (docs/HARDWARE.md); use interface = \"serial\"",
                ));
            }
            if e.bits != 14 {
                return Err(field_err(
                    at("encoder.bits"),
                    format!("{}: the bridge reads 14-bit AS5048A encoders", e.bits),
                ));
            }
            let bus_path = match &ports.bus {
                Some(p) => p.display().to_string(),
                None => s.bus.clone(),
            };
            let bridge_path = match (&ports.bridge, &e.device) {
                (Some(p), _) => p.display().to_string(),
                (None, Some(d)) => d.clone(),
                (None, None) => {
                    return Err(field_err(
                        at("encoder.device"),
                        "missing: the encoder bridge's port, e.g. \"/dev/ttyACM0\" (or pass --bridge)",
                    ));
                }
            };
            let bus = buses.index(bus_path, s.baud, at("servo.baud"))?;
            let bridge = bridges.index(bridge_path, e.baud, at("encoder.baud"))?;
            channels.resize(channels.len().max(bridge + 1), 0);
            loads.resize(channels.len(), 0);
            let n = &mut channels[bridge];
            *n = (*n).max(e.channel.saturating_add(1));
            if let Some(t) = &joint.torque_sensor {
                let l = &mut loads[bridge];
                *l = (*l).max(t.channel.saturating_add(1));
            }
            joints.push(PlannedJoint {
                index: j,
                main,
                pivot,
                bus,
                bridge,
                channel: usize::from(e.channel),
                zero_counts: e.zero_counts as u16,
                map,
                d_min: vsa.d_min,
                d_max: vsa.d_max,
                rate: joint.limits.stiffness_rate,
                load: joint.torque_sensor,
            });
        }
        Ok(Self {
            buses: buses.list,
            bridges: bridges.list.into_iter().zip(channels).collect(),
            loads,
            joints,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;

    fn ports() -> PortOverrides {
        PortOverrides {
            bus: Some("/dev/ttyUSB7".into()),
            bridge: Some("/dev/ttyACM7".into()),
        }
    }

    #[test]
    fn the_parallel_example_is_one_bus_and_one_bridge_of_four_joints() {
        let cfg = rig_config::examples::load("parallel").unwrap();
        let p = BoardPlan::from_config(&cfg, &[0, 1, 2, 3], &ports()).unwrap();
        assert_eq!(p.buses.len(), 1);
        assert_eq!(p.buses[0].path, "/dev/ttyUSB7");
        assert_eq!(p.bridges.len(), 1);
        assert_eq!(
            p.bridges[0].1 as usize,
            1 + p.joints.iter().map(|j| j.channel).max().unwrap()
        );
        assert_eq!(
            p.joints.iter().map(|j| j.index).collect::<Vec<_>>(),
            [0, 1, 2, 3]
        );
        for j in &p.joints {
            // The map is its own inverse on both servos.
            assert!((j.map.pivot_m(j.map.pivot_servo(0.0123)) - 0.0123).abs() < 1e-15);
            assert!((j.map.motor_rad(j.map.main_servo(0.4)) - 0.4).abs() < 1e-15);
            assert_eq!((j.main.model.protocol, j.pivot.model.protocol), (2, 1));
        }
    }

    #[test]
    fn each_config_problem_names_its_field_without_touching_a_port() {
        let base = rig_config::examples::load("parallel").unwrap();
        let err = |f: &dyn Fn(&mut RigConfig), js: &[usize], ports: &PortOverrides| {
            let mut cfg = base.clone();
            f(&mut cfg);
            BoardPlan::from_config(&cfg, js, ports)
                .unwrap_err()
                .to_string()
        };
        let e = err(
            &|c| c.joints[1].servo.as_mut().unwrap().main_protocol = 1,
            &[1],
            &ports(),
        );
        assert!(
            e.starts_with("joint[1] (j2).servo.main_protocol: the XH540-W150 speaks protocol 2"),
            "{e}"
        );
        let e = err(
            &|c| c.joints[0].servo.as_mut().unwrap().main_model = "MX-28".into(),
            &[0],
            &ports(),
        );
        assert!(
            e.starts_with("joint[0] (j1).servo.main_model: unknown servo model"),
            "{e}"
        );
        let e = err(&|c| c.joints[2].encoder.bits = 12, &[2], &ports());
        assert!(e.starts_with("joint[2] (j3).encoder.bits: 12"), "{e}");
        let e = err(
            &|c| c.joints[0].encoder.device = None,
            &[0],
            &PortOverrides::default(),
        );
        assert!(
            e.starts_with("joint[0] (j1).encoder.device: missing"),
            "{e}"
        );
        // Two joints on one bus at two bauds: the second names the first.
        let e = err(
            &|c| c.joints[1].servo.as_mut().unwrap().baud = 57_600,
            &[0, 1],
            &ports(),
        );
        assert!(
            e.starts_with("joint[1] (j2).servo.baud: 57600 differs from"),
            "{e}"
        );
        assert!(e.contains("joint[0] (j1).servo.baud"), "{e}");
    }
}
