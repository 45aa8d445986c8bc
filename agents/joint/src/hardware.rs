//! The `dynamixel` backend: one joint board's servos and deflection encoders.
//!
//! Paper B's board: one servo bus (U2D2 or OpenCM 9.04) carries every joint's main motor
//! (XH540-W150, protocol 2.0) and pivot servo (AX-12A, protocol 1.0); one serial bridge (an
//! Arduino) reads every joint's AS5048A. Each cycle reads
//! - the main motors of a bus with one sync read (protocol 2.0),
//! - the pivot servos: protocol-2.0 ones in the same sync read, protocol-1.0 ones (no sync
//!   read in 1.0) one per cycle in turn — the pivot moves at a few mm/s, so a 4-joint board
//!   reads each every 4 ms instead of paying 4 extra transfers every cycle,
//! - the encoders of a bridge with one request, on a thread of its own while the buses are
//!   read (the lines are independent),
//!
//! then moves each pivot servo's goal towards the guard's goal at the joint's rate limit.
//! Mapping (config `[joint.servo]`, `[joint.encoder]`):
//! - link-side motor angle θ = main servo angle (from its centre) − `main_zero_deg`;
//! - pivot displacement d = (pivot servo angle − `pivot_zero_deg`) · `pivot_mm_per_deg`;
//! - deflection φ = encoder angle from `zero_counts`, wrapped to [−π, π).
//!
//! Torque goes on at start with every goal at the present position (nothing moves), and off
//! on exit, on the watchdog and on any fault ([`DynamixelBoard::safe_state`]; also on drop).

use std::path::PathBuf;
use std::time::Duration;

use rig_config::{EncoderInterface, JointKind, RigConfig, ServoConfig};
use rig_dynamixel::encoder::{EncoderBridge, EncoderError};
use rig_dynamixel::servos::{BusError, BusStats, Servo, ServoBus};
use rig_model::lever::LeverVsa;
use thiserror::Error;

use crate::backend::Reading;

/// Errors of the hardware: each names the joint's config field, or the bus/bridge and servo.
#[derive(Debug, Error)]
pub enum HardwareError {
    #[error("{field}: {message}")]
    Config { field: String, message: String },
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error("encoder bridge {0}")]
    Encoder(#[from] EncoderError),
}

fn config_err(field: String, message: impl Into<String>) -> HardwareError {
    HardwareError::Config {
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

/// One joint of the board.
#[derive(Debug, Clone)]
struct HwJoint {
    main: Servo,
    pivot: Servo,
    bus: usize,
    bridge: usize,
    channel: usize,
    zero_counts: u16,
    map: ServoMap,
    /// Pivot travel [m] and fastest motion [m/s].
    d_min: f64,
    d_max: f64,
    rate: f64,
    /// Last read pivot displacement [m] and main motor angle [rad].
    pivot_m: f64,
    motor_rad: f64,
    /// The guard's goal, and the ramped goal last written (counts).
    goal_m: f64,
    ramp_m: f64,
    written: Option<u32>,
    /// Torque of this joint's servos.
    torque: bool,
}

/// The average load of one read cycle on one line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WireLoad {
    /// The port.
    pub line: String,
    pub baud: u32,
    /// Bytes of the requests and replies.
    pub bytes: usize,
    /// Status replies (each after the servo's Return Delay Time).
    pub replies: usize,
    /// Request–reply round trips (each pays the USB adapter's latency).
    pub transactions: usize,
    /// An encoder bridge (read at the same time as the buses), or a servo bus.
    pub bridge: bool,
}

/// A bus and the indices of its joints.
#[derive(Debug)]
struct BusOf {
    bus: ServoBus,
    joints: Vec<usize>,
}

/// The joint board: its buses, bridges and joints, in the order they were given.
#[derive(Debug)]
pub struct DynamixelBoard {
    buses: Vec<BusOf>,
    bridges: Vec<(EncoderBridge, u8)>,
    joints: Vec<HwJoint>,
    turn: usize,
}

/// A lever joint's VSA, servo section and servo map: what driving it through Dynamixel
/// servos needs; an error naming the field otherwise.
pub fn lever_servo(
    cfg: &RigConfig,
    j: usize,
) -> Result<(&LeverVsa, &ServoConfig, ServoMap), HardwareError> {
    let joint = &cfg.joints[j];
    let at = |f: &str| format!("joint[{j}] ({}).{f}", joint.name);
    let JointKind::Lever { vsa, .. } = &joint.kind else {
        return Err(config_err(
            at("kind"),
            "Dynamixel boards drive lever VSAs (paper B); paper A's AWAS ran on its own boards",
        ));
    };
    let s = joint.servo.as_ref().ok_or_else(|| {
        config_err(
            at("servo"),
            "missing: a Dynamixel board needs the joint's [joint.servo] section",
        )
    })?;
    let m_per_rad = s.pivot_m_per_rad.ok_or_else(|| {
        config_err(
            at("servo.pivot_mm_per_deg"),
            "missing: the rack travel per degree of the pivot servo (pinion radius × π/180)",
        )
    })?;
    let map = ServoMap {
        main_zero: s.main_zero_rad,
        pivot_zero: s.pivot_zero_rad,
        m_per_rad,
    };
    Ok((vsa, s, map))
}

/// Serial lines (buses or bridges) by port, each opened once at one baud rate.
struct Lines {
    what: &'static str,
    list: Vec<(String, u32)>,
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

    /// The index of the line at `path`, added if new; a second baud for it is an error.
    fn index(&mut self, path: String, baud: u32, field: String) -> Result<usize, HardwareError> {
        match self.list.iter().position(|(p, _)| *p == path) {
            Some(k) if self.list[k].1 != baud => Err(config_err(
                field,
                format!(
                    "{baud} differs from {} of {} on the same {} {path}",
                    self.list[k].1, self.first[k], self.what
                ),
            )),
            Some(k) => Ok(k),
            None => {
                self.list.push((path, baud));
                self.first.push(field);
                Ok(self.list.len() - 1)
            }
        }
    }
}

/// Timeout of one encoder-bridge reply.
const BRIDGE_TIMEOUT: Duration = Duration::from_millis(10);

impl DynamixelBoard {
    /// Opens the buses and bridges of joints `js` (indices into `cfg.joints`), checks every
    /// servo's model, reads where everything is, sets every goal there and turns torque on.
    pub fn open(
        cfg: &RigConfig,
        js: &[usize],
        ports: &PortOverrides,
    ) -> Result<Self, HardwareError> {
        let mut buses = Lines::new("bus");
        let mut bridges = Lines::new("bridge");
        let mut channels: Vec<u8> = Vec::new();
        let mut joints = Vec::new();
        for &j in js {
            let joint = &cfg.joints[j];
            let at = |f: &str| format!("joint[{j}] ({}).{f}", joint.name);
            let (vsa, s, map) = lever_servo(cfg, j)?;
            let main = Servo::new(s.main_id, &s.main_model)
                .map_err(|e| config_err(at("servo.main_model"), e.to_string()))?;
            let pivot = Servo::new(s.stiffness_id, &s.stiffness_model)
                .map_err(|e| config_err(at("servo.stiffness_model"), e.to_string()))?;
            // The pivot servo must reach the whole travel: then every goal the guard lets
            // through is one it can reach.
            let ends = [vsa.d_min, vsa.d_max].map(|d| map.pivot_servo(d));
            if ends.iter().any(|&a| pivot.model.to_counts(a).is_none()) {
                return Err(config_err(
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
                    return Err(config_err(
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
                return Err(config_err(
                    at("encoder.interface"),
                    "\"spi\": this agent reads the encoders through the serial bridge (docs/HARDWARE.md); use interface = \"serial\"",
                ));
            }
            if e.bits != 14 {
                return Err(config_err(
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
                    return Err(config_err(
                        at("encoder.device"),
                        "missing: the encoder bridge's port, e.g. \"/dev/ttyACM0\" (or pass --bridge)",
                    ));
                }
            };
            let bus = buses.index(bus_path, s.baud, at("servo.baud"))?;
            let bridge = bridges.index(bridge_path, e.baud, at("encoder.baud"))?;
            channels.resize(channels.len().max(bridge + 1), 0);
            let n = &mut channels[bridge];
            *n = (*n).max(e.channel.saturating_add(1));
            joints.push(HwJoint {
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
                pivot_m: 0.0,
                motor_rad: 0.0,
                goal_m: 0.0,
                ramp_m: 0.0,
                written: None,
                torque: false,
            });
        }
        let mut bus_list = Vec::new();
        for (k, (path, baud)) in buses.list.iter().enumerate() {
            bus_list.push(BusOf {
                bus: ServoBus::open(std::path::Path::new(path), *baud)?,
                joints: (0..joints.len()).filter(|&i| joints[i].bus == k).collect(),
            });
        }
        let mut bridge_list = Vec::new();
        for ((path, baud), n) in bridges.list.iter().zip(channels) {
            let b = EncoderBridge::open(std::path::Path::new(path), *baud, BRIDGE_TIMEOUT)?;
            bridge_list.push((b, n));
        }
        let mut board = Self {
            buses: bus_list,
            bridges: bridge_list,
            joints,
            turn: 0,
        };
        board.start()?;
        Ok(board)
    }

    /// Checks the models, reads every position, holds it, torque on.
    fn start(&mut self) -> Result<(), HardwareError> {
        for b in &mut self.buses {
            for &k in &b.joints {
                b.bus.check(self.joints[k].main)?;
                b.bus.check(self.joints[k].pivot)?;
            }
            let servos: Vec<Servo> = b
                .joints
                .iter()
                .flat_map(|&k| [self.joints[k].main, self.joints[k].pivot])
                .collect();
            let p = b.bus.positions(&servos)?;
            for (i, &k) in b.joints.iter().enumerate() {
                let j = &mut self.joints[k];
                let (main, pivot) = (p[2 * i], p[2 * i + 1]);
                j.motor_rad = j.map.motor_rad(main);
                j.pivot_m = j.map.pivot_m(pivot);
                // Hold the present pivot position as the goal (clamped into the travel: the
                // ramp then brings an out-of-travel pivot back at the rate limit).
                j.goal_m = j.pivot_m.clamp(j.d_min, j.d_max);
                j.ramp_m = j.pivot_m;
                b.bus.set_goal(j.main, main)?;
                b.bus.set_goal(j.pivot, pivot)?;
                j.written = j.pivot.model.to_counts(pivot);
            }
        }
        self.torque_all(true)?;
        Ok(())
    }

    fn torque_all(&mut self, on: bool) -> Result<(), HardwareError> {
        for k in 0..self.joints.len() {
            self.torque(k, on)?;
        }
        Ok(())
    }

    /// One read cycle, `dt` [s] after the previous one: every joint's reading, in order.
    pub fn read(&mut self, dt: f64) -> Result<Vec<Reading>, HardwareError> {
        let turn = self.turn;
        self.turn = self.turn.wrapping_add(1);
        // The bridges answer on their own lines while the buses are read: a cycle takes the
        // longer of the two, not their sum.
        let (buses, joints, bridges) = (&mut self.buses, &mut self.joints, &mut self.bridges);
        let (servos, counts) = std::thread::scope(|scope| {
            let encoders = scope.spawn(move || {
                bridges
                    .iter_mut()
                    .map(|(bridge, n)| bridge.read(*n))
                    .collect::<Result<Vec<_>, _>>()
            });
            let servos = read_buses(buses, joints, turn);
            (servos, encoders.join())
        });
        servos?;
        let counts = match counts {
            Ok(c) => c?,
            Err(_) => {
                return Err(config_err(
                    "encoder bridge".into(),
                    "the bridge's reading thread failed",
                ));
            }
        };
        self.ramp(dt)?;
        let mut out = Vec::with_capacity(self.joints.len());
        for j in &self.joints {
            // The bridge answered `n` encoders, every channel below `n`: always there (a
            // reading skipped here would shift every later joint's onto the wrong joint).
            let c = counts
                .get(j.bridge)
                .and_then(|c| c.get(j.channel))
                .ok_or_else(|| {
                    config_err(
                        "encoder.channel".into(),
                        format!("channel {} missing from the bridge's reply", j.channel),
                    )
                })?;
            out.push(Reading {
                motor_rad: j.motor_rad,
                deflection_rad: c.rad_from(j.zero_counts),
                pivot_m: Some(j.pivot_m),
                torque_nm: None,
                stiffness_motor_rad: None,
                truth: None,
            });
        }
        Ok(out)
    }

    /// Moves each pivot's written goal towards the guard's goal at the rate limit; writes
    /// only when the goal's count changes.
    fn ramp(&mut self, dt: f64) -> Result<(), HardwareError> {
        for b in &mut self.buses {
            for &k in &b.joints {
                let j = &mut self.joints[k];
                if !j.torque {
                    continue;
                }
                let step = j.rate * dt.max(0.0);
                j.ramp_m += (j.goal_m - j.ramp_m).clamp(-step, step);
                let rad = j.map.pivot_servo(j.ramp_m);
                let c = j.pivot.model.to_counts(rad);
                if c.is_some() && c != j.written {
                    b.bus.set_goal(j.pivot, rad)?;
                    j.written = c;
                }
            }
        }
        Ok(())
    }

    /// Joint `k`'s pivot displacement [m] as last read.
    pub fn actuator(&self, k: usize) -> f64 {
        self.joints[k].pivot_m
    }

    /// Joint `k`'s pivot goal [m] (the guard has checked it); reached at the rate limit.
    pub fn set_actuator_goal(&mut self, k: usize, goal_m: f64) {
        let j = &mut self.joints[k];
        j.goal_m = goal_m.clamp(j.d_min, j.d_max);
    }

    /// Joint `k`'s main motor goal [rad, link side] (the guard has checked its limits).
    pub fn set_motor_goal(&mut self, k: usize, rad: f64) -> Result<(), HardwareError> {
        let j = &self.joints[k];
        let b = &mut self.buses[j.bus].bus;
        b.set_goal(j.main, j.map.main_servo(rad))?;
        Ok(())
    }

    /// Torque of joint `k`'s servos on or off; written only when it changes (every command
    /// carries `torque_enable`: the 10 Hz heartbeats would otherwise cost two bus transfers
    /// each). Switched on, the pivot's goal restarts from where it is.
    pub fn torque(&mut self, k: usize, on: bool) -> Result<(), HardwareError> {
        let j = &mut self.joints[k];
        if j.torque == on {
            return Ok(());
        }
        let b = &mut self.buses[j.bus].bus;
        if on {
            j.ramp_m = j.pivot_m;
            j.goal_m = j.goal_m.clamp(j.d_min, j.d_max);
            j.written = None;
        }
        // Off: flagged first, so a failing write still counts the joint as meant to be limp.
        j.torque = on;
        b.torque(j.main, on)?;
        b.torque(j.pivot, on)?;
        Ok(())
    }

    /// Torque off on every servo, each tried even when another fails; the failures.
    pub fn safe_state(&mut self) -> Vec<String> {
        let mut failed = Vec::new();
        for b in &mut self.buses {
            for &k in &b.joints {
                for s in [self.joints[k].main, self.joints[k].pivot] {
                    if let Err(e) = b.bus.torque(s, false) {
                        failed.push(e.to_string());
                    }
                }
            }
        }
        for j in &mut self.joints {
            j.torque = false;
        }
        failed
    }

    /// What one read cycle puts on each line (bus or bridge), on average: its name, baud
    /// rate, bytes (requests and replies, [`rig_dynamixel::timing`]) and replies (each waits
    /// the servo's Return Delay Time). Protocol-1.0 pivots count once per cycle per bus (they
    /// are read in turn); pivot goal writes, made only while a pivot moves, are left out.
    pub fn wire_per_cycle(&self) -> Vec<WireLoad> {
        use rig_dynamixel::timing::{bridge_bytes, read1_bytes, sync_read_bytes};
        let mut out = Vec::new();
        for b in &self.buses {
            let servos: Vec<Servo> = b
                .joints
                .iter()
                .flat_map(|&k| [self.joints[k].main, self.joints[k].pivot])
                .collect();
            let p2: Vec<&Servo> = servos.iter().filter(|s| s.model.protocol == 2).collect();
            let (mains1, pivots1) = b.joints.iter().fold((0, 0), |(m, p), &k| {
                let j = &self.joints[k];
                (
                    m + usize::from(j.main.model.protocol == 1),
                    p + usize::from(j.pivot.model.protocol == 1),
                )
            });
            let reads1 = mains1 + usize::from(pivots1 > 0);
            let size2 = p2
                .first()
                .map_or(4, |s| usize::from(s.model.present_position.size));
            out.push(WireLoad {
                line: b.bus.name().to_string(),
                baud: b.bus.baud(),
                bytes: sync_read_bytes(p2.len(), size2) + reads1 * read1_bytes(2),
                replies: p2.len() + reads1,
                transactions: usize::from(!p2.is_empty()) + reads1,
                bridge: false,
            });
        }
        for (bridge, n) in &self.bridges {
            out.push(WireLoad {
                line: bridge.name().to_string(),
                baud: bridge.baud(),
                bytes: bridge_bytes(usize::from(*n)),
                replies: 1,
                transactions: 1,
                bridge: true,
            });
        }
        out
    }

    /// Transfers, retries and failures of every bus so far.
    pub fn bus_stats(&self) -> BusStats {
        self.buses
            .iter()
            .fold(BusStats::default(), |a, b| BusStats {
                transfers: a.transfers + b.bus.stats.transfers,
                retries: a.retries + b.bus.stats.retries,
                failures: a.failures + b.bus.stats.failures,
            })
    }
}

/// One cycle's servo reads on every bus: main motors and protocol-2.0 pivots in one sync
/// read, this cycle's protocol-1.0 pivot (in turn by `turn`) alone.
fn read_buses(buses: &mut [BusOf], joints: &mut [HwJoint], turn: usize) -> Result<(), BusError> {
    for b in buses {
        let p1: Vec<usize> = b
            .joints
            .iter()
            .copied()
            .filter(|&k| joints[k].pivot.model.protocol == 1)
            .collect();
        let due = (!p1.is_empty()).then(|| p1[turn % p1.len()]);
        let mut servos = Vec::new();
        let mut slots = Vec::new();
        for &k in &b.joints {
            let j = &joints[k];
            servos.push(j.main);
            slots.push((k, false));
            if j.pivot.model.protocol == 2 || due == Some(k) {
                servos.push(j.pivot);
                slots.push((k, true));
            }
        }
        let p = b.bus.positions(&servos)?;
        for ((k, is_pivot), rad) in slots.into_iter().zip(p) {
            let j = &mut joints[k];
            if is_pivot {
                j.pivot_m = j.map.pivot_m(rad);
            } else {
                j.motor_rad = j.map.motor_rad(rad);
            }
        }
    }
    Ok(())
}

impl Drop for DynamixelBoard {
    /// A board dropped with torque on (an error path) still leaves the servos limp.
    fn drop(&mut self) {
        if self.joints.iter().any(|j| j.torque) {
            let _ = self.safe_state();
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;
    use crate::virtual_board::VirtualBoard;
    use rig_dynamixel::timing::{read1_bytes, sync_read_bytes};

    fn board(cfg: &RigConfig) -> (VirtualBoard, DynamixelBoard) {
        let start = rig_runtime::now_ns();
        let v = VirtualBoard::start(cfg, &[0, 1, 2, 3], start, 1).unwrap();
        let ports = PortOverrides {
            bus: Some(v.bus_path.clone()),
            bridge: Some(v.bridge_path.clone()),
        };
        let b = DynamixelBoard::open(cfg, &[0, 1, 2, 3], &ports).unwrap();
        (v, b)
    }

    #[test]
    fn reads_the_simulated_plant_through_both_protocols_and_the_bridge() {
        let cfg = rig_config::examples::load("parallel").unwrap();
        let (_v, mut b) = board(&cfg);
        let world = rig_sim::world::StrokeWorld::new(
            cfg.robot().unwrap(),
            cfg.geometry.unwrap().home,
            crate::backend::WORLD_STROKE_M,
            crate::backend::WORLD_STROKE_S,
        )
        .unwrap();
        let mut r = Vec::new();
        for _ in 0..8 {
            r = b.read(1e-3).unwrap();
        }
        let xh540 = std::f64::consts::TAU / 4096.0;
        let ax12 = std::f64::consts::TAU / 1228.0;
        for (k, x) in r.iter().enumerate() {
            // The motors where the world holds them, to one XH540 count.
            assert!(
                (x.motor_rad - world.motors[k]).abs() <= 0.5 * xh540 + 1e-12,
                "joint {k}: {} vs {}",
                x.motor_rad,
                world.motors[k]
            );
            // The pivot where the sim starts it (mid-travel, 9 mm), to one AX-12A count.
            let m_per_rad = cfg.joints[k]
                .servo
                .as_ref()
                .unwrap()
                .pivot_m_per_rad
                .unwrap();
            assert!(
                (x.pivot_m.unwrap() - 0.009).abs() <= 0.5 * ax12 * m_per_rad + 1e-12,
                "{:?}",
                x.pivot_m
            );
            // A stroke of 6 mm bends the joints by a few counts to a few degrees.
            assert!(x.deflection_rad.abs() < 0.2, "{}", x.deflection_rad);
        }
        // One sync read of 4 XH540s and one AX-12A in turn, and the bridge's 4 encoders.
        let w = b.wire_per_cycle();
        assert_eq!(w[0].bytes, sync_read_bytes(4, 4) + read1_bytes(2));
        assert_eq!((w[0].replies, w[0].transactions), (5, 2));
        assert_eq!(w[1].bytes, 2 + 3 + 3 * 4);
        assert!(b.safe_state().is_empty());
    }

    #[test]
    fn a_protocol_2_pivot_servo_joins_the_sync_read_and_a_short_pinion_is_refused() {
        let mut cfg = rig_config::examples::load("parallel").unwrap();
        for j in &mut cfg.joints {
            let s = j.servo.as_mut().unwrap();
            s.stiffness_model = "XH540-W150".into();
            s.stiffness_protocol = 2;
        }
        let (_v, mut b) = board(&cfg);
        let w = b.wire_per_cycle();
        assert_eq!(w[0].bytes, sync_read_bytes(8, 4));
        assert_eq!((w[0].replies, w[0].transactions), (8, 1));
        let r = b.read(1e-3).unwrap();
        assert!(r.iter().all(|x| (x.pivot_m.unwrap() - 0.009).abs() < 1e-4));
        drop(b);
        // A pinion so small that the travel needs more than the servo's turn.
        cfg.joints[1].servo.as_mut().unwrap().pivot_m_per_rad =
            Some(0.002e-3 * 180.0 / std::f64::consts::PI);
        let e = DynamixelBoard::open(&cfg, &[1], &PortOverrides::default()).unwrap_err();
        assert!(
            e.to_string().starts_with(
                "joint[1] (j2).servo.pivot_mm_per_deg: with pivot_zero_deg the travel 0.0–18.0 mm"
            ),
            "{e}"
        );
    }
}
