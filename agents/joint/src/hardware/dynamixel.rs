//! The Dynamixel board: one joint board's servos and deflection encoders, opened from a
//! checked [`BoardPlan`] (this module does I/O only).
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
//!
//! Torque goes on at start with every goal at the present position (nothing moves), and off
//! on exit, on the watchdog and on any fault ([`JointBoard::safe_state`]; also on drop).
//! The agent runs this board on a thread that owns it ([`crate::board::BoardRunner`]).

use std::time::Duration;

use rig_dynamixel::encoder::{EncoderBridge, EncoderError};
use rig_dynamixel::servos::{BusError, BusStats, Servo, ServoBus};
use thiserror::Error;

use super::pace;
use super::plan::{BoardPlan, PlannedJoint};
use crate::board::{Applied, BoardError, JointBoard, Reading, SafeState, WatchdogAction};

/// Errors of the hardware, each naming its bus or bridge (and servo).
#[derive(Debug, Error)]
pub enum HardwareError {
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error("encoder bridge {0}")]
    Encoder(#[from] EncoderError),
    #[error("encoder bridge: channel {channel} missing from its reply")]
    MissingChannel { channel: usize },
    #[error("encoder bridge: load cell {channel} missing from its reply")]
    MissingLoadChannel { channel: u8 },
    #[error("encoder bridge: its reading thread failed")]
    BridgeThread,
}

/// One joint of the board: its plan and what was last read and written.
#[derive(Debug, Clone)]
struct HwJoint {
    plan: PlannedJoint,
    /// Last read pivot displacement [m] and main motor angle [rad].
    pivot_m: f64,
    motor_rad: f64,
    /// The main motor's torque from its present current [N·m], where it reports it.
    motor_torque: Option<f64>,
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

/// The wire's time for one read cycle [s]: the buses one after the other, the bridges
/// likewise, both groups at once (the bridges are read on their own thread).
pub fn wire_s_per_cycle(loads: &[WireLoad]) -> f64 {
    let group = |bridge: bool| -> f64 {
        loads
            .iter()
            .filter(|l| l.bridge == bridge)
            .map(|l| rig_dynamixel::timing::wire_s(l.bytes, l.baud))
            .sum()
    };
    group(false).max(group(true))
}

/// A bus and the indices of its joints.
#[derive(Debug)]
struct BusOf {
    bus: ServoBus,
    joints: Vec<usize>,
}

/// The joint board: its buses, bridges and joints, in the order of its plan.
#[derive(Debug)]
pub struct DynamixelBoard {
    buses: Vec<BusOf>,
    /// Each bridge with how many encoders and load cells it is asked for.
    bridges: Vec<(EncoderBridge, u8, u8)>,
    joints: Vec<HwJoint>,
    turn: usize,
}

/// Timeout of one encoder-bridge reply.
const BRIDGE_TIMEOUT: Duration = Duration::from_millis(10);

impl DynamixelBoard {
    /// Opens the plan's buses and bridges, checks every servo's model, reads where everything
    /// is, sets every goal there and turns torque on.
    pub fn open(plan: &BoardPlan) -> Result<Self, HardwareError> {
        let joints: Vec<HwJoint> = plan
            .joints
            .iter()
            .map(|p| HwJoint {
                plan: p.clone(),
                pivot_m: 0.0,
                motor_rad: 0.0,
                motor_torque: None,
                goal_m: 0.0,
                ramp_m: 0.0,
                written: None,
                torque: false,
            })
            .collect();
        let mut buses = Vec::new();
        for (k, line) in plan.buses.iter().enumerate() {
            buses.push(BusOf {
                bus: ServoBus::open(std::path::Path::new(&line.path), line.baud)?,
                joints: (0..joints.len())
                    .filter(|&i| joints[i].plan.bus == k)
                    .collect(),
            });
        }
        let mut bridges = Vec::new();
        for (k, (line, n)) in plan.bridges.iter().enumerate() {
            let b =
                EncoderBridge::open(std::path::Path::new(&line.path), line.baud, BRIDGE_TIMEOUT)?;
            bridges.push((b, *n, plan.loads.get(k).copied().unwrap_or(0)));
        }
        let mut board = Self {
            buses,
            bridges,
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
                b.bus.check(self.joints[k].plan.main)?;
                b.bus.check(self.joints[k].plan.pivot)?;
            }
            let servos: Vec<Servo> = b
                .joints
                .iter()
                .flat_map(|&k| [self.joints[k].plan.main, self.joints[k].plan.pivot])
                .collect();
            let p = b.bus.positions(&servos)?;
            for (i, &k) in b.joints.iter().enumerate() {
                let j = &mut self.joints[k];
                let (main, pivot) = (p[2 * i], p[2 * i + 1]);
                j.motor_rad = j.plan.map.motor_rad(main);
                j.pivot_m = j.plan.map.pivot_m(pivot);
                // Hold the present pivot position as the goal (clamped into the travel: the
                // ramp then brings an out-of-travel pivot back at the rate limit).
                j.goal_m = j.pivot_m.clamp(j.plan.d_min, j.plan.d_max);
                j.ramp_m = j.pivot_m;
                b.bus.set_goal(j.plan.main, main)?;
                b.bus.set_goal(j.plan.pivot, pivot)?;
                j.written = j.plan.pivot.model.to_counts(pivot);
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
    pub fn read_cycle(&mut self, dt: f64) -> Result<Vec<Reading>, HardwareError> {
        let turn = self.turn;
        self.turn = self.turn.wrapping_add(1);
        // The bridges answer on their own lines while the buses are read: a cycle takes the
        // longer of the two, not their sum.
        let (buses, joints, bridges) = (&mut self.buses, &mut self.joints, &mut self.bridges);
        let (servos, counts) = std::thread::scope(|scope| {
            let encoders = scope.spawn(move || {
                bridges
                    .iter_mut()
                    .map(|(bridge, n, loads)| {
                        let angles = bridge.read(*n)?;
                        let loads = match *loads {
                            0 => Vec::new(),
                            m => bridge.read_loads(m)?,
                        };
                        Ok::<_, EncoderError>((angles, loads))
                    })
                    .collect::<Result<Vec<_>, _>>()
            });
            let servos = read_buses(buses, joints, turn);
            (servos, encoders.join())
        });
        servos?;
        let counts = counts.map_err(|_| HardwareError::BridgeThread)??;
        self.ramp(dt)?;
        let mut out = Vec::with_capacity(self.joints.len());
        for j in &self.joints {
            // The bridge answered `n` encoders, every channel below `n`: always there (a
            // reading skipped here would shift every later joint's onto the wrong joint).
            let (angles, loads) = counts
                .get(j.plan.bridge)
                .map(|(a, l)| (a.as_slice(), l.as_slice()))
                .unwrap_or_default();
            let c = angles
                .get(j.plan.channel)
                .ok_or(HardwareError::MissingChannel {
                    channel: j.plan.channel,
                })?;
            // The torque reference: the amplifier's latest conversion (held between them).
            let torque_nm = match &j.plan.load {
                Some(t) => {
                    let l = loads
                        .get(usize::from(t.channel))
                        .ok_or(HardwareError::MissingLoadChannel { channel: t.channel })?;
                    Some(l.nm_from(t.zero_counts, t.nm_per_count))
                }
                None => None,
            };
            out.push(Reading {
                motor_rad: j.motor_rad,
                deflection_rad: c.rad_from(j.plan.zero_counts),
                pivot_m: Some(j.pivot_m),
                torque_nm,
                motor_torque_nm: j.motor_torque,
                stiffness_motor_rad: None,
                actuator: j.pivot_m,
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
                let step = j.plan.rate * dt.max(0.0);
                j.ramp_m += (j.goal_m - j.ramp_m).clamp(-step, step);
                let rad = j.plan.map.pivot_servo(j.ramp_m);
                let c = j.plan.pivot.model.to_counts(rad);
                if c.is_some() && c != j.written {
                    b.bus.set_goal(j.plan.pivot, rad)?;
                    j.written = c;
                }
            }
        }
        Ok(())
    }

    /// Joint `k`'s main motor goal [rad, link side] (the guard has checked its limits).
    pub fn set_motor_goal(&mut self, k: usize, rad: f64) -> Result<(), BusError> {
        let j = &self.joints[k];
        let b = &mut self.buses[j.plan.bus].bus;
        b.set_goal(j.plan.main, j.plan.map.main_servo(rad))?;
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
        let b = &mut self.buses[j.plan.bus].bus;
        if on {
            j.ramp_m = j.pivot_m;
            j.goal_m = j.goal_m.clamp(j.plan.d_min, j.plan.d_max);
            j.written = None;
        }
        // Off: flagged first, so a failing write still counts the joint as meant to be limp.
        j.torque = on;
        b.torque(j.plan.main, on)?;
        b.torque(j.plan.pivot, on)?;
        Ok(())
    }

    /// Torque off on every servo, each tried even when another fails; the failures.
    pub fn torque_off_everywhere(&mut self) -> Vec<String> {
        let mut failed = Vec::new();
        for b in &mut self.buses {
            for &k in &b.joints {
                for s in [self.joints[k].plan.main, self.joints[k].plan.pivot] {
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
        use rig_dynamixel::timing::{bridge_bytes, load_bytes, read1_bytes, sync_read_bytes};
        let mut out = Vec::new();
        for b in &self.buses {
            let servos: Vec<Servo> = b
                .joints
                .iter()
                .flat_map(|&k| [self.joints[k].plan.main, self.joints[k].plan.pivot])
                .collect();
            let p2: Vec<&Servo> = servos.iter().filter(|s| s.model.protocol == 2).collect();
            let (mains1, pivots1) = b.joints.iter().fold((0, 0), |(m, p), &k| {
                let j = &self.joints[k];
                (
                    m + usize::from(j.plan.main.model.protocol == 1),
                    p + usize::from(j.plan.pivot.model.protocol == 1),
                )
            });
            let reads1 = mains1 + usize::from(pivots1 > 0);
            // Current and position in one block where every protocol-2.0 servo has it.
            let size2 = match rig_dynamixel::servos::shared_current_block(p2.iter().copied()) {
                Some((_, count)) => usize::from(count),
                None => p2
                    .first()
                    .map_or(4, |s| usize::from(s.model.present_position.size)),
            };
            out.push(WireLoad {
                line: b.bus.name().to_string(),
                baud: b.bus.baud(),
                bytes: sync_read_bytes(p2.len(), size2) + reads1 * read1_bytes(2),
                replies: p2.len() + reads1,
                transactions: usize::from(!p2.is_empty()) + reads1,
                bridge: false,
            });
        }
        for (bridge, n, loads) in &self.bridges {
            let more = usize::from(*loads > 0);
            out.push(WireLoad {
                line: bridge.name().to_string(),
                baud: bridge.baud(),
                bytes: bridge_bytes(usize::from(*n)) + more * load_bytes(usize::from(*loads)),
                replies: 1 + more,
                transactions: 1 + more,
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

impl JointBoard for DynamixelBoard {
    fn name(&self) -> &'static str {
        "dynamixel"
    }

    fn reads_the_past(&self) -> bool {
        false
    }

    /// Hardware reads now: `t` is not used.
    fn read(&mut self, _t: f64, dt: f64) -> Result<Vec<Reading>, BoardError> {
        Ok(self.read_cycle(dt)?)
    }

    /// Times [`pace::TIMED_CYCLES`] read cycles against the tick (and the wire's own time).
    fn pace(&mut self, rate_hz: f64) -> Result<Option<pace::TooFast>, BoardError> {
        let dt = 1.0 / rate_hz;
        let mut cycles = Vec::with_capacity(pace::TIMED_CYCLES);
        for _ in 0..pace::TIMED_CYCLES {
            let t = std::time::Instant::now();
            self.read_cycle(dt)?;
            cycles.push(t.elapsed().as_secs_f64());
        }
        Ok(pace::verdict(
            rate_hz,
            wire_s_per_cycle(&self.wire_per_cycle()),
            &cycles,
        ))
    }

    /// Joint `k`'s pivot displacement [m] as last read.
    fn actuator(&self, k: usize) -> f64 {
        self.joints.get(k).map_or(f64::NAN, |j| j.pivot_m)
    }

    /// Joint `k`'s pivot goal [m] (the guard has checked it); reached at the rate limit.
    fn set_actuator_goal(&mut self, k: usize, goal_m: f64) {
        if let Some(j) = self.joints.get_mut(k) {
            j.goal_m = goal_m.clamp(j.plan.d_min, j.plan.d_max);
        }
    }

    /// A motor goal beyond the servo's range is refused (the joint goes on as before); a
    /// failing bus is an error.
    fn apply(
        &mut self,
        k: usize,
        motor_goal_rad: Option<f64>,
        torque_enable: bool,
    ) -> Result<Applied, BoardError> {
        if let Some(m) = motor_goal_rad {
            match self.set_motor_goal(k, m) {
                Err(e @ BusError::OutOfRange { .. }) => {
                    return Ok(Applied::Refused(format!("motor goal refused: {e}")));
                }
                r => r.map_err(HardwareError::from)?,
            }
        }
        self.torque(k, torque_enable)?;
        Ok(Applied::Done)
    }

    fn on_watchdog(&mut self, k: usize, _hold_at: f64) -> Result<WatchdogAction, BoardError> {
        self.torque(k, false)?;
        Ok(WatchdogAction::TorqueOff)
    }

    fn safe_state(&mut self) -> SafeState {
        let failed = self.torque_off_everywhere();
        if failed.is_empty() {
            SafeState::TorqueOff
        } else {
            SafeState::TorqueOffFailed(failed)
        }
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
            .filter(|&k| joints[k].plan.pivot.model.protocol == 1)
            .collect();
        let due = (!p1.is_empty()).then(|| p1[turn % p1.len()]);
        let mut servos = Vec::new();
        let mut slots = Vec::new();
        for &k in &b.joints {
            let j = &joints[k];
            servos.push(j.plan.main);
            slots.push((k, false));
            if j.plan.pivot.model.protocol == 2 || due == Some(k) {
                servos.push(j.plan.pivot);
                slots.push((k, true));
            }
        }
        let (p, torque) = b.bus.positions_and_torques(&servos)?;
        for (((k, is_pivot), rad), tau) in slots.into_iter().zip(p).zip(torque) {
            let j = &mut joints[k];
            if is_pivot {
                j.pivot_m = j.plan.map.pivot_m(rad);
            } else {
                j.motor_rad = j.plan.map.motor_rad(rad);
                j.motor_torque = tau;
            }
        }
    }
    Ok(())
}

impl Drop for DynamixelBoard {
    /// A board dropped with torque on (an error path) still leaves the servos limp.
    fn drop(&mut self) {
        if self.joints.iter().any(|j| j.torque) {
            let _ = self.torque_off_everywhere();
        }
    }
}

#[cfg(all(test, feature = "sim"))]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;
    use crate::hardware::PortOverrides;
    use crate::virtual_board::VirtualBoard;
    use rig_config::RigConfig;
    use rig_dynamixel::timing::{read1_bytes, sync_read_bytes};

    fn board(cfg: &RigConfig) -> (VirtualBoard, DynamixelBoard) {
        let start = rig_runtime::now_ns();
        let v = VirtualBoard::start(cfg, &[0, 1, 2, 3], start, 1).unwrap();
        let ports = PortOverrides {
            bus: Some(v.bus_path.clone()),
            bridge: Some(v.bridge_path.clone()),
        };
        let plan = BoardPlan::from_config(cfg, &[0, 1, 2, 3], &ports).unwrap();
        let b = DynamixelBoard::open(&plan).unwrap();
        (v, b)
    }

    #[test]
    fn reads_the_simulated_plant_through_both_protocols_and_the_bridge() {
        let cfg = rig_config::examples::load("parallel").unwrap();
        let (_v, mut b) = board(&cfg);
        let world = rig_sim::world::StrokeWorld::new(
            cfg.robot().unwrap(),
            cfg.geometry.unwrap().home,
            rig_sim::world::HAND_STROKE_M,
            rig_sim::world::HAND_STROKE_S,
        )
        .unwrap();
        let mut r = Vec::new();
        for _ in 0..8 {
            r = b.read_cycle(1e-3).unwrap();
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
        // One sync read of 4 XH540s (present current to present position: 10 bytes each) and
        // one AX-12A in turn, and the bridge's 4 encoders.
        let w = b.wire_per_cycle();
        assert_eq!(w[0].bytes, sync_read_bytes(4, 10) + read1_bytes(2));
        assert_eq!((w[0].replies, w[0].transactions), (5, 2));
        assert_eq!(w[1].bytes, 2 + 3 + 3 * 4);
        assert!(b.torque_off_everywhere().is_empty());
    }

    #[test]
    fn a_rate_the_read_cycle_cannot_keep_is_said_with_what_fits() {
        let cfg = rig_config::examples::load("parallel").unwrap();
        let (_v, mut b) = board(&cfg);
        // A 10 µs tick: no cycle of a real bus (pseudo-terminals here) is that short.
        let v = b.pace(100_000.0).unwrap().expect("too fast");
        assert_eq!(v.timed, pace::TIMED_CYCLES);
        assert!(v.cycle_s > 1e-5 && v.sustainable_hz() < 100_000.0, "{v:?}");
        // The wire at the config's baud (the virtual lines have none of their own).
        assert_eq!(v.wire_s, wire_s_per_cycle(&b.wire_per_cycle()));
        assert!(v.to_string().contains("rate_hz = 100000"), "{v}");
        // 1 Hz: any cycle fits.
        assert_eq!(b.pace(1.0).unwrap(), None);
        assert!(b.torque_off_everywhere().is_empty());
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
        assert_eq!(w[0].bytes, sync_read_bytes(8, 10));
        assert_eq!((w[0].replies, w[0].transactions), (8, 1));
        let r = b.read_cycle(1e-3).unwrap();
        assert!(r.iter().all(|x| (x.pivot_m.unwrap() - 0.009).abs() < 1e-4));
        drop(b);
        // A pinion so small that the travel needs more than the servo's turn.
        cfg.joints[1].servo.as_mut().unwrap().pivot_m_per_rad =
            Some(0.002e-3 * 180.0 / std::f64::consts::PI);
        let e = BoardPlan::from_config(&cfg, &[1], &PortOverrides::default()).unwrap_err();
        assert!(
            e.to_string().starts_with(
                "joint[1] (j2).servo.pivot_mm_per_deg: with pivot_zero_deg the travel 0.0–18.0 mm"
            ),
            "{e}"
        );
    }
}
