//! An independent generator of test data for `rig identify`: plants and effects written from
//! MODEL.md §1, §2, §5 and §6.1 alone, sharing no code with `rig_model::identify` or the
//! simulator (its own random numbers, its own Bouc-Wen integration, its own lever formulas).
//! Each effect acts where it physically sits: a gap in series with the spring, a lag on one
//! sensor path, a slip of the encoder's zero, a drift of the spring's stiffness.

#![allow(dead_code)]

use std::f64::consts::TAU;

/// SplitMix64: a small, well-known generator; Gaussian numbers by Box–Muller.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x9E37_79B9_7F4A_7C15)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
    pub fn gauss(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
    }
}

/// The plant a case runs on, with the model `rig identify` is told to start from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Plant {
    /// τ = k·x (declared: linear).
    Linear,
    /// Paper B's lever at a 9 mm pivot with Bouc-Wen friction in the spring (declared:
    /// restoring).
    Lever,
    /// Paper A's link equation I·q̈ + N·q̇ = τ (declared: link).
    Link,
}

impl Plant {
    pub fn name(self) -> &'static str {
        match self {
            Plant::Linear => "linear spring",
            Plant::Lever => "lever + Bouc-Wen",
            Plant::Link => "link equation",
        }
    }
}

/// An effect put at its physical place, sized relative to the plant's own signals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Inject {
    /// Torque-sensor zero: + c.
    TorqueOffset,
    /// A torque-sensor mount that slips: + c after t_j.
    TorqueStep,
    /// The deflection encoder's zero slips by s after t_j: the plant is unchanged, the
    /// reading shifts.
    EncoderSlip,
    /// A gap of half-width r in series with the spring: the spring sees the dead zone.
    Backlash,
    /// Friction inside the spring (Bouc-Wen) on a spring declared linear.
    Hysteresis,
    /// The spring's stiffness grows by a fraction over the run.
    StiffnessDrift,
    /// The spring's stiffness changes by a fraction at t_j (it re-seats in its clamp).
    StiffnessStep,
    /// The torque path lags the angle path by δ.
    TorqueLag,
    /// The angle path lags the torque path by δ.
    AngleLag,
    /// The spring meets a stiffer stop.
    HardStop,
    /// Dry friction where the part moves: F_c·sgn(rate).
    Coulomb,
    /// Viscous friction where the part moves: b·rate.
    Viscous,
    /// Gravity on the link: m·g·l·sin(q + q0).
    Gravity,
    /// A ripple periodic in the angle.
    Ripple,
}

impl Inject {
    /// The name `rig identify` should give it.
    pub fn expected(self) -> &'static str {
        match self {
            Inject::TorqueOffset | Inject::TorqueStep | Inject::EncoderSlip => "offset",
            Inject::Backlash => "backlash",
            Inject::Hysteresis => "hysteresis",
            Inject::StiffnessDrift | Inject::StiffnessStep => "stiffness_drift",
            Inject::TorqueLag | Inject::AngleLag => "sensor_delay",
            Inject::HardStop => "hard_stop",
            Inject::Coulomb => "coulomb_friction",
            Inject::Viscous => "viscous_friction",
            Inject::Gravity => "gravity",
            Inject::Ripple => "periodic_ripple",
        }
    }

    pub fn label(self) -> &'static str {
        match self {
            Inject::TorqueOffset => "torque offset",
            Inject::TorqueStep => "torque offset step",
            Inject::EncoderSlip => "encoder zero slip",
            Inject::Backlash => "backlash",
            Inject::Hysteresis => "hysteresis",
            Inject::StiffnessDrift => "stiffness drift",
            Inject::StiffnessStep => "stiffness step",
            Inject::TorqueLag => "torque lags",
            Inject::AngleLag => "angle lags",
            Inject::HardStop => "hard stop",
            Inject::Coulomb => "Coulomb friction",
            Inject::Viscous => "viscous friction",
            Inject::Gravity => "gravity",
            Inject::Ripple => "periodic ripple",
        }
    }

    /// The effects that make physical sense on a plant (and that its declared model lacks).
    pub fn on(plant: Plant) -> &'static [Inject] {
        match plant {
            Plant::Linear => &[
                Inject::TorqueStep,
                Inject::EncoderSlip,
                Inject::Backlash,
                Inject::Hysteresis,
                Inject::StiffnessDrift,
                Inject::StiffnessStep,
                Inject::TorqueLag,
                Inject::HardStop,
                Inject::Coulomb,
                Inject::Viscous,
                Inject::Ripple,
            ],
            Plant::Lever => &[
                Inject::TorqueOffset,
                Inject::TorqueStep,
                Inject::EncoderSlip,
                Inject::Backlash,
                Inject::StiffnessDrift,
                Inject::StiffnessStep,
                Inject::TorqueLag,
                Inject::HardStop,
                Inject::Viscous,
                Inject::Ripple,
            ],
            Plant::Link => &[
                Inject::TorqueOffset,
                Inject::TorqueStep,
                Inject::AngleLag,
                Inject::TorqueLag,
                Inject::Coulomb,
                Inject::Gravity,
                Inject::Ripple,
            ],
        }
    }
}

/// The motion imposed on the plant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// A sum of four sines of random frequency and phase.
    MultiSine,
    /// Rest, then ramps to random levels and holds, like the measured springs' tests.
    RampHold,
}

/// One generated case.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Case {
    pub plant: Plant,
    pub inject: Option<Inject>,
    pub motion: Motion,
    /// Sampling rate [Hz].
    pub rate_hz: f64,
    /// Torque noise as a fraction of the peak torque.
    pub noise: f64,
    /// The angle encoder's own noise, rms in counts, before it counts (0: quantisation
    /// only; X_NOISE_COUNTS sets it for stress runs).
    pub encoder_noise: f64,
    /// The angle encoder's counts per turn (0: the plant's, [`PlantParams`]).
    pub counts: f64,
    /// The motion's swing [rad] (0: the plant's, [`PlantParams`]): paper B's lever softens
    /// by 13 % at ±0.15 rad.
    pub amplitude: f64,
    /// The torque noise's colour: the time constant [ms] of the sensor's own first-order
    /// low-pass it passes, at the same rms (0: white; NOISE_TAU_MS sets it for stress runs).
    pub noise_tau_ms: f64,
    /// The multi-sine's highest frequency [Hz] (0: the plant's, [`PlantParams`]).
    pub f_max: f64,
    /// Dry friction's shape (FRICTION=held or tanh sets it for stress runs).
    pub friction: DryFriction,
    pub seed: u64,
}

/// How dry friction F_c behaves where the motion slows and stops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DryFriction {
    /// F_c·sgn(ẋ), sgn 0 = 0: released the moment the motion stops (the simulator's).
    Released,
    /// Kept where the motion stops until it moves again (a stuck contact: a bristle or
    /// elastoplastic model).
    Held,
    /// F_c·tanh(ẋ/v_s), built up over a speed v_s given as a fraction of the plant's rms rate
    /// scale ([`viscous_rate_scale`]): a contact that slides a little before it slips.
    Smooth(f64),
    /// Released at rest, with a Stribeck peak: sgn(ẋ)·(F_c + (F_s − F_c)·exp(−(ẋ/v_s)²)),
    /// breaking away at F_s = 1.5·F_c and falling to F_c over v_s, given as a fraction of the
    /// plant's rms rate scale: a lubricated contact's friction at low speed.
    Stribeck(f64),
}

/// A generated run in SI units: what `rig identify` reads, and the injected size.
#[derive(Debug, Clone)]
pub struct Data {
    pub t: Vec<f64>,
    /// Measured angle: deflection (joints) or link angle (link) [rad].
    pub x: Vec<f64>,
    pub tau: Vec<f64>,
    /// The injected effect's main size (N·m, rad, s, fraction, by effect).
    pub size: f64,
    /// When a torque step, an encoder slip or a stiffness step happens [s] (NaN for the
    /// other effects).
    pub jump_at_s: f64,
}

/// A run's length (s): 30, or DURATION_S for a stress run.
fn duration() -> f64 {
    static DURATION: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *DURATION.get_or_init(|| env_f64("DURATION_S", 30.0))
}

/// RAMPS=linear: ramp-and-hold motions at constant speed (stress runs).
fn linear_ramps() -> bool {
    std::env::var("RAMPS").is_ok_and(|v| v == "linear")
}

/// LAG=lowpass: a lagging sensor path is a first-order low-pass of time constant δ (a
/// sensor's filter) instead of a pure delay δ (stress runs).
fn lowpass_lags() -> bool {
    std::env::var("LAG").is_ok_and(|v| v == "lowpass")
}

/// FRICTION=held: every case's dry friction held where the motion stops; FRICTION=tanh: built
/// up over TANH_VS (default 0.05) of the rms rate scale; FRICTION=stribeck: a breakaway peak
/// falling to F_c over STRIBECK_VS (default 0.05) of it (stress runs). Else the case's own.
fn friction(c: &Case) -> DryFriction {
    match std::env::var("FRICTION").as_deref() {
        Ok("held") => DryFriction::Held,
        Ok("tanh") => DryFriction::Smooth(env_f64("TANH_VS", 0.05)),
        Ok("stribeck") => DryFriction::Stribeck(env_f64("STRIBECK_VS", 0.05)),
        _ => c.friction,
    }
}

/// The imposed angle and its first two derivatives at time t, from a motion's parameters.
#[derive(Debug, Clone)]
struct Trajectory {
    sines: Vec<(f64, f64, f64)>,
    /// Ramp-and-hold: (start time, duration, from, to) of each ramp.
    ramps: Vec<(f64, f64, f64, f64)>,
}

impl Trajectory {
    fn new(motion: Motion, amplitude: f64, f_max: f64, rng: &mut Rng) -> Self {
        match motion {
            Motion::MultiSine => {
                let mut sines: Vec<(f64, f64, f64)> = (0..4)
                    .map(|_| {
                        let f = rng.range(0.1, f_max);
                        (1.0 / (1.0 + 3.0 * f), TAU * f, rng.range(0.0, TAU))
                    })
                    .collect();
                let peak = (0..3000)
                    .map(|k| {
                        let t = k as f64 * duration() / 3000.0;
                        sines
                            .iter()
                            .map(|(a, w, p)| a * (w * t + p).sin())
                            .sum::<f64>()
                            .abs()
                    })
                    .fold(0.0f64, f64::max);
                for s in &mut sines {
                    s.0 *= amplitude / peak;
                }
                Self {
                    sines,
                    ramps: vec![],
                }
            }
            Motion::RampHold => {
                let mut ramps = Vec::new();
                let mut t = rng.range(2.0, 4.0);
                let mut level = 0.0;
                let mut sign = if rng.uniform() < 0.5 { 1.0 } else { -1.0 };
                while t < duration() - 2.0 {
                    let to = sign * amplitude * rng.range(0.5, 1.0);
                    let dur = rng.range(1.5, 4.0);
                    ramps.push((t, dur, level, to));
                    level = to;
                    sign = -sign;
                    t += dur + rng.range(0.5, 2.5);
                }
                Self {
                    sines: vec![],
                    ramps,
                }
            }
        }
    }

    /// (x, ẋ, ẍ) at t. Ramps are quintic smoothsteps (continuous acceleration).
    fn at(&self, t: f64) -> (f64, f64, f64) {
        if !self.sines.is_empty() {
            return self
                .sines
                .iter()
                .fold((0.0, 0.0, 0.0), |(x, v, a), (amp, w, p)| {
                    let ph = w * t + p;
                    (
                        x + amp * ph.sin(),
                        v + amp * w * ph.cos(),
                        a - amp * w * w * ph.sin(),
                    )
                });
        }
        let mut out = (0.0, 0.0, 0.0);
        for &(t0, dur, from, to) in &self.ramps {
            if t < t0 {
                break;
            }
            let u = ((t - t0) / dur).min(1.0);
            // RAMPS=linear (stress runs): constant-speed ramps with sharp corners, as a
            // spring-test machine drives them.
            let (s, ds, dds) = if linear_ramps() {
                (u, if u < 1.0 { 1.0 / dur } else { 0.0 }, 0.0)
            } else {
                (
                    u * u * u * (10.0 - 15.0 * u + 6.0 * u * u),
                    if u < 1.0 {
                        30.0 * u * u * (1.0 - u) * (1.0 - u) / dur
                    } else {
                        0.0
                    },
                    if u < 1.0 {
                        60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / (dur * dur)
                    } else {
                        0.0
                    },
                )
            };
            out = (from + (to - from) * s, (to - from) * ds, (to - from) * dds);
        }
        out
    }
}

/// The lever plant's pivot position [m] (from its closest point to the main joint, 9.6 mm).
pub const LEVER_PIVOT_M: f64 = 0.009;

/// Paper B's lever (MODEL.md §1) at d_a: exact static torque of the spring through the lever.
pub fn lever_torque(phi: f64) -> f64 {
    lever_torque_at(phi, LEVER_PIVOT_M)
}

/// The same at another pivot position `pivot` [m] (from 9.6 mm).
pub fn lever_torque_at(phi: f64, pivot: f64) -> f64 {
    let (p, d_a, k_alpha) = (0.0315, 0.0096 + pivot, 978.8e-3 / 43f64.to_radians());
    let beta = (p * phi.sin()).atan2(p * phi.cos() - d_a);
    let alpha = beta - phi;
    let l = ((p * phi.cos() - d_a).powi(2) + (p * phi.sin()).powi(2)).sqrt();
    let g = d_a * (alpha + phi).cos() / l;
    g * k_alpha * alpha
}

/// A Bouc-Wen element in deflection space (MODEL.md §2 with A = 1):
/// ż = ẋ·(1 − (β·sgn(ẋ·z) + γ)·|z|ⁿ), with yield z_max = (β + γ)^(−1/n); integrated with
/// substeps. `BW_N` sets n (1 by default; larger n, sharper corners), `BW_GAMMA` the share
/// γ/(β + γ) (½ by default; 0 unloads along a softer, rounder branch).
#[derive(Debug, Clone, Copy)]
struct BoucWen {
    z: f64,
    beta: f64,
    gamma: f64,
    n: f64,
}

impl BoucWen {
    fn new(z_max: f64) -> Self {
        let n = env_f64("BW_N", 1.0);
        let share = env_f64("BW_GAMMA", 0.5);
        let sum = 1.0 / z_max.powf(n);
        Self {
            z: 0.0,
            beta: (1.0 - share) * sum,
            gamma: share * sum,
            n,
        }
    }
    fn step(&mut self, dx: f64) {
        let substeps = 20;
        let h = dx / substeps as f64;
        for _ in 0..substeps {
            let s = if h * self.z >= 0.0 { 1.0 } else { -1.0 };
            self.z += h * (1.0 - (self.beta * s + self.gamma) * self.z.abs().powf(self.n));
        }
    }
}

/// A plant's parameters. The defaults are the tables' plants; stress runs move them:
/// `AMPLITUDE_SCALE` (the joints' ±0.06 rad, the link's ±1 rad), `K_LINEAR` (the linear
/// spring's 2 N·m/rad), `PIVOT_MM` (the lever's pivot, 9 mm from its closest point),
/// `BW_SHARE` (the lever's share through its friction element, 0.2) and `BW_YIELD` (its yield
/// over the amplitude, 0.15), `INERTIA` and `DAMPING` (the link's 0.05 kg·m² and 0.4
/// N·m·s/rad), `COUNTS` (the encoder's counts per turn: 65 536 on a joint's deflection, 16 384
/// on a link's angle) and `F_MAX` (the multi-sine's highest frequency: 1 Hz on a joint, 1.5 Hz
/// on a link).
#[derive(Debug, Clone, Copy)]
pub struct PlantParams {
    pub amplitude: f64,
    pub k_linear: f64,
    pub pivot: f64,
    pub bw_share: f64,
    pub bw_yield: f64,
    pub inertia: f64,
    pub damping: f64,
    pub counts: f64,
    pub f_max: f64,
}

impl PlantParams {
    pub fn of(plant: Plant) -> Self {
        let link = plant == Plant::Link;
        Self {
            amplitude: env_f64("AMPLITUDE_SCALE", 1.0) * if link { 1.0 } else { 0.06 },
            k_linear: env_f64("K_LINEAR", 2.0),
            pivot: env_f64("PIVOT_MM", LEVER_PIVOT_M * 1e3) / 1e3,
            bw_share: env_f64("BW_SHARE", 0.2),
            bw_yield: env_f64("BW_YIELD", 0.15),
            inertia: env_f64("INERTIA", 0.05),
            damping: env_f64("DAMPING", 0.4),
            counts: env_f64("COUNTS", if link { 16384.0 } else { 65536.0 }),
            f_max: env_f64("F_MAX", if link { 1.5 } else { 1.0 }),
        }
    }

    /// The plant's parameters with what the case sets itself.
    pub fn for_case(c: &Case) -> Self {
        let mut pp = Self::of(c.plant);
        if c.amplitude > 0.0 {
            pp.amplitude = c.amplitude;
        }
        if c.f_max > 0.0 {
            pp.f_max = c.f_max;
        }
        pp
    }
}

/// The rate viscous friction is sized at (b·rate = the effect's size): a 0.5 Hz swing of the
/// plant's amplitude, its rms rate [rad/s].
pub fn viscous_rate_scale(c: &Case) -> f64 {
    PlantParams::for_case(c).amplitude * TAU * 0.5 / 2f64.sqrt()
}

/// Generates one run of a case. `variant` changes the motion's random draw (0 for the fit
/// run, 1 for the held-out run) but not the plant or the effect's size.
pub fn generate(c: &Case, variant: u64) -> Data {
    let mut rng = Rng::new(c.seed.wrapping_mul(7919).wrapping_add(variant * 104_729));
    let mut size_rng = Rng::new(c.seed.wrapping_mul(31337) ^ 0xA5A5);
    let pp = PlantParams::for_case(c);
    let amplitude = pp.amplitude;
    let traj = Trajectory::new(c.motion, amplitude, pp.f_max, &mut rng);
    // The plant runs on a fine grid (10 kHz), sensors sample it at the case's rate.
    let fine = 10_000.0;
    let n_fine = (duration() * fine) as usize + 1;
    let k_lin = pp.k_linear; // N·m/rad of the linear spring
    let (inertia, damping) = (pp.inertia, pp.damping);
    let lever = |x: f64| lever_torque_at(x, pp.pivot);
    let inject = c.inject;
    // Peak torque of the clean plant, to size effects and noise (fixed per case, so that the
    // fit and held-out runs carry the same effect).
    let peak = match c.plant {
        Plant::Linear => k_lin * amplitude,
        Plant::Lever => lever(amplitude),
        // The same for every run of a case: a 0.5 Hz swing of the link's amplitude.
        Plant::Link => {
            let w = TAU * 0.5;
            inertia * amplitude * w * w + damping * amplitude * w
        }
    };
    let t_jump = duration() * size_rng.range(0.3, 0.7);
    // SIZE_SCALE (stress runs) scales every effect: a larger stop is an earlier one.
    let scale = env_f64("SIZE_SCALE", 1.0);
    let size = match inject {
        None => 0.0,
        Some(Inject::TorqueOffset) => scale * 0.08 * peak * sign(&mut size_rng),
        Some(Inject::TorqueStep) => scale * 0.08 * peak * sign(&mut size_rng),
        Some(Inject::EncoderSlip) => scale * 0.08 * amplitude * sign(&mut size_rng),
        Some(Inject::Backlash) => scale * size_rng.range(0.04, 0.08) * amplitude,
        Some(Inject::Hysteresis) => (scale * 0.3).min(0.9),
        Some(Inject::StiffnessDrift) => scale * size_rng.range(0.15, 0.3),
        Some(Inject::StiffnessStep) => scale * size_rng.range(0.1, 0.25) * sign(&mut size_rng),
        Some(Inject::TorqueLag | Inject::AngleLag) => scale * size_rng.range(0.01, 0.03),
        Some(Inject::HardStop) => {
            (1.0 - scale * (1.0 - size_rng.range(0.6, 0.75))).max(0.1) * amplitude
        }
        Some(Inject::Coulomb) => scale * 0.06 * peak,
        Some(Inject::Viscous) => scale * 0.06 * peak,
        Some(Inject::Gravity) => scale * 0.3 * peak,
        Some(Inject::Ripple) => scale * 0.05 * peak,
    };
    let ripple_period = amplitude / size_rng.range(3.0, 6.0);
    let ripple_phase = size_rng.range(0.0, TAU);
    let q0 = size_rng.range(-0.5, 0.5);
    let rate_rms = viscous_rate_scale(c);
    let friction = friction(c);
    let mut bw = BoucWen::new(pp.bw_yield * amplitude);
    let mut bw_prev_x = 0.0;
    // A lagging sensor reads, at the start of a run, the motion before it: the plant is run
    // from `lead` seconds earlier (else the lagging signal would stand still for its first δ
    // while the other moves — a kink no recording has, worth 3× the clean floor on a link).
    let lead = if matches!(inject, Some(Inject::TorqueLag | Inject::AngleLag)) {
        (20.0 * size).max(0.5)
    } else {
        0.0
    };
    let n_fine = n_fine + (lead * fine) as usize;
    let mut last_sign = 0.0;
    let mut tau_fine = Vec::with_capacity(n_fine);
    let mut x_fine = Vec::with_capacity(n_fine);
    for k in 0..n_fine {
        let t = k as f64 / fine - lead;
        let (x, v, a) = traj.at(t);
        // What the spring sees of the imposed motion.
        let xs = match inject {
            Some(Inject::Backlash) => (x.abs() - size).max(0.0) * x.signum(),
            _ => x,
        };
        let tau = match c.plant {
            Plant::Linear => {
                let mut tau = k_lin * xs;
                if inject == Some(Inject::Hysteresis) {
                    bw.step(xs - bw_prev_x);
                    bw_prev_x = xs;
                    // A share `size` of the stiffness through the friction element: a loop
                    // of about ±size·k·z_max.
                    tau = (1.0 - size) * k_lin * xs + size * k_lin * bw.z;
                }
                tau
            }
            Plant::Lever => {
                bw.step(xs - bw_prev_x);
                bw_prev_x = xs;
                // 80 % elastic through the lever, 20 % through the friction element (by
                // default: BW_SHARE).
                (1.0 - pp.bw_share) * lever(xs)
                    + pp.bw_share * (lever(amplitude) / amplitude) * bw.z
            }
            Plant::Link => inertia * a + damping * v,
        };
        let tau = match inject {
            Some(Inject::StiffnessDrift) => tau * (1.0 + size * t / duration()),
            Some(Inject::StiffnessStep) if t >= t_jump => tau * (1.0 + size),
            Some(Inject::HardStop) => {
                tau + 4.0 * (peak / amplitude) * ((xs.abs() - size).max(0.0) * xs.signum())
            }
            Some(Inject::Coulomb) => match friction {
                DryFriction::Smooth(frac) => tau + size * (v / (frac * rate_rms)).tanh(),
                DryFriction::Stribeck(frac) if v.abs() > 1e-6 => {
                    let peak = 0.5 * (-(v / (frac * rate_rms)).powi(2)).exp();
                    tau + size * v.signum() * (1.0 + peak)
                }
                DryFriction::Stribeck(_) => tau,
                shape => {
                    if v.abs() > 1e-6 {
                        last_sign = v.signum();
                    } else if shape == DryFriction::Released {
                        last_sign = 0.0;
                    }
                    tau + size * last_sign
                }
            },
            Some(Inject::Viscous) => tau + size / rate_rms * v,
            Some(Inject::Gravity) => tau + size * (x + q0).sin(),
            Some(Inject::Ripple) => tau + size * (TAU * x / ripple_period + ripple_phase).sin(),
            _ => tau,
        };
        tau_fine.push(tau);
        x_fine.push(x);
    }
    // A lag as a sensor's first-order filter (LAG=lowpass), run on the fine grid.
    if lowpass_lags() {
        let lowpass = |v: &mut Vec<f64>| {
            let a = 1.0 - (-1.0 / (fine * size)).exp();
            let mut y = v[0];
            for s in v.iter_mut() {
                y += a * (*s - y);
                *s = y;
            }
        };
        match inject {
            Some(Inject::TorqueLag) => lowpass(&mut tau_fine),
            Some(Inject::AngleLag) => lowpass(&mut x_fine),
            _ => {}
        }
    }
    let at = |v: &[f64], t: f64| -> f64 {
        let u = ((t + lead) * fine).clamp(0.0, (n_fine - 1) as f64);
        let i = (u.floor() as usize).min(n_fine - 2);
        let w = u - i as f64;
        v[i] * (1.0 - w) + v[i + 1] * w
    };
    let n = (duration() * c.rate_hz) as usize;
    let resolution = TAU / if c.counts > 0.0 { c.counts } else { pp.counts };
    let mut out = Data {
        t: Vec::with_capacity(n),
        x: Vec::with_capacity(n),
        tau: Vec::with_capacity(n),
        size,
        jump_at_s: match inject {
            Some(Inject::TorqueStep | Inject::EncoderSlip | Inject::StiffnessStep) => t_jump,
            _ => f64::NAN,
        },
    };
    // The torque sensor's noise coloured by its own first-order filter (a bridge amplifier's
    // low-pass), at the same rms: the residual of a clean model is then autocorrelated
    // however right the model.
    let noise_tau = if c.noise_tau_ms > 0.0 {
        c.noise_tau_ms
    } else {
        env_f64("NOISE_TAU_MS", 0.0)
    } / 1e3;
    let (pole, gain) = if noise_tau > 0.0 {
        let a = (-1.0 / (c.rate_hz * noise_tau)).exp();
        (a, (1.0 - a * a).sqrt())
    } else {
        (0.0, 1.0)
    };
    let mut coloured = 0.0;
    for i in 0..n {
        // A little jitter on the sampling instants, as a real bus has.
        let t = (i as f64 + 0.1 * rng.uniform()) / c.rate_hz;
        let (t_tau, t_x) = match inject {
            _ if lowpass_lags() => (t, t),
            Some(Inject::TorqueLag) => (t - size, t),
            Some(Inject::AngleLag) => (t, t - size),
            _ => (t, t),
        };
        let mut x = at(&x_fine, t_x);
        let mut tau = at(&tau_fine, t_tau);
        match inject {
            Some(Inject::TorqueOffset) => tau += size,
            Some(Inject::TorqueStep) if t >= t_jump => tau += size,
            Some(Inject::EncoderSlip) if t >= t_jump => x += size,
            _ => {}
        }
        coloured = pole * coloured + gain * rng.gauss();
        tau += env_f64("NOISE_SCALE", 1.0) * c.noise * peak * coloured;
        // The encoder's own noise, in counts, before it counts.
        let x_noise = if c.encoder_noise > 0.0 {
            c.encoder_noise
        } else {
            env_f64("X_NOISE_COUNTS", 0.0)
        };
        if x_noise > 0.0 {
            x += x_noise * resolution * rng.gauss();
        }
        x = (x / resolution).round() * resolution;
        out.t.push(t);
        out.x.push(x);
        out.tau.push(tau);
    }
    out
}

fn sign(rng: &mut Rng) -> f64 {
    if rng.uniform() < 0.5 { -1.0 } else { 1.0 }
}

fn env_f64(name: &str, default: f64) -> f64 {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}
