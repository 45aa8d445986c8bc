//! A joint board without hardware: virtual servos and a virtual encoder bridge on
//! pseudo-terminals, whose readings come from the simulated plant. The `dynamixel` backend
//! talks to it exactly as to paper B's U2D2 and Arduino, so the whole hardware path (sync
//! reads, protocol 1.0, goal writes, the bridge's frames, faults) runs in tests and on a laptop
//! (`rig virtual-board`).
//!
//! A thread steps the simulated joints ([`SimJoint`], the same plant the `sim` board
//! uses, at the same world time) every `STEP` and writes what real hardware would show: main
//! servo present positions (the world's motor angles + `main_zero_deg`), encoder counts
//! (the deflection from `zero_counts`), pivot servo present positions (the plant's pivot,
//! which follows the pivot servo's goal at the joint's rate limit while its torque is on), and
//! where the config gives a `[joint.torque_sensor]`, its load cell's conversions (the joint's
//! torque through the config's zero and scale; fresh every step, where a real HX711 converts
//! at 10 or 80 Hz); the main servo's present current is the joint's torque over the model's
//! torque per ampere.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use rig_config::RigConfig;
use rig_dynamixel::encoder::{LoadReading, Reading as Counts, VirtualEncoders};
use rig_dynamixel::models::Model;
use rig_dynamixel::servos::Servo;
use rig_dynamixel::virtual_bus::{VirtualBus, VirtualServo};
use rig_runtime::now_ns;

use crate::board::BoardError;
use crate::hardware::{BoardPlan, PortOverrides, ServoMap};
use crate::sim_board::SimJoint;

/// How often the plant thread updates the virtual hardware.
const STEP: Duration = Duration::from_micros(250);

/// One simulated joint behind its virtual hardware.
struct Joint {
    sim: SimJoint,
    main: Servo,
    pivot: Servo,
    channel: usize,
    zero_counts: u16,
    map: ServoMap,
    /// Its load cell on the bridge, when the config gives one.
    load: Option<rig_config::TorqueSensorConfig>,
}

/// The virtual board; dropping it stops the plant and the devices.
#[derive(Debug)]
pub struct VirtualBoard {
    /// The servo bus's port (give it to `rig-joint --bus`).
    pub bus_path: PathBuf,
    /// The encoder bridge's port (`rig-joint --bridge`).
    pub bridge_path: PathBuf,
    /// The servos' control tables (fault injection, inspection).
    pub bus: VirtualBus,
    pub encoders: VirtualEncoders,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

fn counts(model: &Model, rad: f64) -> u32 {
    model
        .to_counts(rad)
        .unwrap_or(if rad < 0.0 { 0 } else { model.max_position })
}

impl VirtualBoard {
    /// The board of joints `js` (indices into `cfg.joints`, lever joints with a servo
    /// section), its world started at `start_ns` [ns since the UNIX epoch] as the `sim`
    /// backend's, its sensors seeded as the sim backend's with `seed`.
    pub fn start(
        cfg: &RigConfig,
        js: &[usize],
        start_ns: u64,
        seed: u64,
    ) -> Result<Self, BoardError> {
        // The servos, channels and maps of the board the agent will open: the same checks,
        // the ports are ours (made below).
        let placeholder = PortOverrides {
            bus: Some("virtual-bus".into()),
            bridge: Some("virtual-bridge".into()),
        };
        let plan = BoardPlan::from_config(cfg, js, &placeholder)?;
        let mut joints = Vec::new();
        let mut servos = Vec::new();
        for p in &plan.joints {
            let (main, pivot, map) = (p.main, p.pivot, p.map);
            let sim = SimJoint::new(
                cfg,
                p.index,
                seed.wrapping_add(p.index as u64),
                Default::default(),
            )?;
            let mut vm = VirtualServo::new(*main.model, main.id);
            vm.set(main.model.present_position, counts(main.model, 0.0));
            let mut vp = VirtualServo::new(*pivot.model, pivot.id);
            let pivot_counts = counts(pivot.model, map.pivot_servo(sim.actuator()));
            vp.set(pivot.model.present_position, pivot_counts);
            vp.set(pivot.model.goal_position, pivot_counts);
            servos.extend([vm, vp]);
            joints.push(Joint {
                sim,
                main,
                pivot,
                channel: p.channel,
                zero_counts: p.zero_counts,
                map,
                load: p.load,
            });
        }
        let channels = plan
            .bridges
            .iter()
            .map(|(_, n)| usize::from(*n))
            .max()
            .unwrap_or(0);
        let io = BoardError::VirtualBoard;
        let (bus, bus_path) = VirtualBus::start_with_path(servos).map_err(io)?;
        let (encoders, bridge_path) = VirtualEncoders::start_with_path(vec![
            Counts {
                counts: 0,
                error: false,
                magnet: false,
            };
            channels
        ])
        .map_err(io)?;
        // Load cells at their zero until the plant says otherwise.
        encoders
            .state
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .loads = (0..plan.loads.iter().copied().max().unwrap_or(0))
            .map(|c| LoadReading {
                raw: joints
                    .iter()
                    .filter_map(|j: &Joint| j.load)
                    .find(|l| l.channel == c)
                    .map_or(0, |l| l.zero_counts),
                fresh: true,
                missing: false,
            })
            .collect();
        // The servos and encoders read the plant from the first moment, as a real board's
        // do: one step now, before the plant's thread is first scheduled (under load that
        // can be several of the agent's cycles later, and the motor read 0 until then).
        let first = now_ns();
        let t0 = first.saturating_sub(start_ns) as f64 * 1e-9;
        step(&mut joints, &bus.servos, &encoders.state, t0, 0.0);
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (stop, servos, bridge) = (stop.clone(), bus.servos.clone(), encoders.state.clone());
            std::thread::spawn(move || {
                let mut last = first;
                while !stop.load(Ordering::Relaxed) {
                    let now = now_ns();
                    let t = now.saturating_sub(start_ns) as f64 * 1e-9;
                    let dt = now.saturating_sub(last) as f64 * 1e-9;
                    last = now;
                    step(&mut joints, &servos, &bridge, t, dt);
                    std::thread::sleep(STEP);
                }
            })
        };
        Ok(Self {
            bus_path,
            bridge_path,
            bus,
            encoders,
            stop,
            thread: Some(thread),
        })
    }
}

/// One plant step at world time `t`: the pivot servo's goal drives the plant's pivot (torque
/// on), and the plant's state becomes the servos' and encoders' readings.
fn step(
    joints: &mut [Joint],
    servos: &rig_dynamixel::virtual_bus::Servos,
    bridge: &std::sync::Mutex<rig_dynamixel::encoder::VirtualState>,
    t: f64,
    dt: f64,
) {
    let mut table = servos.lock().unwrap_or_else(|p| p.into_inner());
    let mut enc = bridge.lock().unwrap_or_else(|p| p.into_inner());
    for j in joints.iter_mut() {
        if let Some(p) = table.get(&j.pivot.id)
            && p.get(p.model.torque_enable) == 1
        {
            let goal = p.model.to_rad(p.get(p.model.goal_position));
            j.sim.set_actuator_goal(j.map.pivot_m(goal));
        }
        let Ok(r) = j.sim.read(t, dt.max(1e-6)) else {
            continue;
        };
        // The joint's torque: the bench's sensor (with its noise), else the plant's true one.
        let tau = r.torque_nm.or(r.truth.map(|t| t.torque_nm));
        if let Some(m) = table.get_mut(&j.main.id) {
            m.set(
                m.model.present_position,
                counts(j.main.model, j.map.main_servo(r.motor_rad)),
            );
            // The motor holds the spring: its current is the spring's torque over the model's
            // torque per ampere (statically; the motor's own inertia and friction left out).
            if let (Some(f), Some(tau)) = (m.model.present_current, tau) {
                let per_count = m.model.nm_per_current_count();
                let c = (tau / per_count).round().clamp(-32768.0, 32767.0) as i16;
                m.set(f, u32::from(c as u16));
            }
        }
        if let (Some(p), Some(d)) = (table.get_mut(&j.pivot.id), r.pivot_m) {
            p.set(
                p.model.present_position,
                counts(j.pivot.model, j.map.pivot_servo(d)),
            );
        }
        if let Some(e) = enc.readings.get_mut(j.channel) {
            e.counts = Counts::counts_at(r.deflection_rad, j.zero_counts);
        }
        // The load cell reads the joint's torque.
        if let Some(l) = &j.load
            && let Some(tau) = tau
            && let Some(cell) = enc.loads.get_mut(usize::from(l.channel))
        {
            cell.raw = LoadReading::raw_at(tau, l.zero_counts, l.nm_per_count);
            cell.fresh = true;
        }
    }
}

impl Drop for VirtualBoard {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
