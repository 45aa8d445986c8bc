//! Scenarios as TOML files: what to simulate, for how long, with which sensors and which
//! undeclared effects. [`run`] turns one into rows of sensor data (plus the truth), handed to
//! a sink one at a time so that any length streams in constant memory.
//!
//! ```toml
//! kind = "lever-bench"        # lever-bench | awas | serial | parallel
//! duration_s = 20.0
//! rate_hz = 1000.0            # default 1000
//! seed = 1                    # default 1
//! config = "rig-config/examples/parallel.toml"   # default: the example of the kind
//!
//! [lever_bench]               # kind = "lever-bench": the joint on paper B's test bench
//! pivot_mm = 9.0
//! amplitude_rad = 0.06
//!
//! [awas]                      # kind = "awas": motor torques as [amplitude N·m, frequency Hz]
//! tau1 = [[6.0, 0.7], [3.0, 2.3], [1.5, 9.0]]
//! tau2 = [[0.004, 0.05]]
//! tau_ext = []
//!
//! [robot]                     # kind = "serial" | "parallel": strokes along guide lines
//! pivot_mm = [9.0, 9.0, 9.0, 9.0]
//! strokes = [["x", 12.0, 2.0], ["y", 12.0, 2.0]]   # axis, amplitude mm, cycles (time shared)
//!
//! [sensors]
//! encoder_bits = 14           # deflection / link encoders
//! torque_noise_nm = 0.003
//! force_noise_n = 0.01
//!
//! [effects]                   # see crate::effects: all off unless set
//! coulomb_friction_nm = 0.01
//! ```
//!
//! Columns (SI, units in the names; lever-bench uses the short names `rig identify` reads):
//! - lever-bench: `t, phi, tau, d` (s, rad, N·m, mm), then `true_phi, true_tau`;
//! - awas: `t, q, theta1, theta2, tau_e, tau, tau1, tau2` (s, rad, N·m; θ2 quantised to
//!   2π/4096; `tau` is the net
//!   torque on the link, τ_ext − τ_E), then `true_stiffness_nm_per_rad, true_q`;
//! - serial/parallel: `t, x_m, y_m, fx_n, fy_n`, per joint `j<i>_motor_rad, j<i>_phi_rad,
//!   j<i>_d_mm`, then `true_fx_n, true_fy_n` and per joint `j<i>_true_tau_nm`.

use std::path::{Path, PathBuf};

use rig_config::{JointKind, RigConfig};
use rig_model::awas::AwasState;
use serde::Deserialize;
use thiserror::Error;

use crate::awas_plant::{AwasInputs, AwasPlant};
use crate::effects::Effects;
use crate::lever_joint::{LeverJointPlant, SpringHysteresis};
use crate::noise::{DelayLine, Noise, quantize};
use crate::planar_rig::{PlanarRigSim, PlanarSensors, Stroke};
use crate::world::bench_path;

/// The stiffness motor's incremental encoder: 4096 counts per revolution of the ball-screw
/// motor (its angle runs over hundreds of radians, so it needs no absolute encoder).
pub const THETA2_RESOLUTION_RAD: f64 = std::f64::consts::TAU / 4096.0;

/// Errors of loading or running a scenario.
#[derive(Debug, Error)]
pub enum ScenarioError {
    #[error("{file}: {message}")]
    Invalid { file: PathBuf, message: String },
    #[error("{0}")]
    Config(#[from] rig_config::ConfigErrors),
    /// The scenario asks for what the simulator does not have (the text says what).
    #[error("simulation: {0}")]
    Sim(String),
    /// A plant could not be built or stepped (its own error as the source).
    #[error("simulation: {0}")]
    Plant(#[source] Box<dyn std::error::Error + Send + Sync>),
    #[error("writing output: {0}")]
    Sink(String),
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub kind: String,
    pub duration_s: f64,
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
    #[serde(default = "default_seed")]
    pub seed: u64,
    pub config: Option<PathBuf>,
    pub lever_bench: Option<LeverBench>,
    pub awas: Option<AwasDrive>,
    pub robot: Option<RobotDrive>,
    #[serde(default)]
    pub sensors: Sensors,
    #[serde(default)]
    pub effects: Effects,
}

fn default_rate() -> f64 {
    1000.0
}

fn default_seed() -> u64 {
    1
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LeverBench {
    pub pivot_mm: f64,
    pub amplitude_rad: f64,
    /// Bouc-Wen hysteresis in the spring (default true); false leaves the exact lever spring.
    #[serde(default = "yes")]
    pub hysteresis: bool,
}

fn yes() -> bool {
    true
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AwasDrive {
    pub tau1: Vec<[f64; 2]>,
    #[serde(default)]
    pub tau2: Vec<[f64; 2]>,
    #[serde(default)]
    pub tau_ext: Vec<[f64; 2]>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotDrive {
    pub pivot_mm: Vec<f64>,
    pub strokes: Vec<(String, f64, f64)>,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Sensors {
    pub encoder_bits: u8,
    pub torque_noise_nm: f64,
    pub force_noise_n: f64,
}

impl Default for Sensors {
    fn default() -> Self {
        Self {
            encoder_bits: 14,
            torque_noise_nm: 0.003,
            force_noise_n: 0.01,
        }
    }
}

impl Sensors {
    fn resolution(&self) -> f64 {
        if self.encoder_bits == 0 {
            0.0
        } else {
            std::f64::consts::TAU / f64::from(1u32 << self.encoder_bits.min(31))
        }
    }
}

impl Scenario {
    /// Reads and checks a scenario file.
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let invalid = |message: String| ScenarioError::Invalid {
            file: path.to_path_buf(),
            message,
        };
        let src = std::fs::read_to_string(path)
            .map_err(|e| invalid(format!("cannot read the file: {e}")))?;
        let s: Scenario = toml::from_str(&src).map_err(|e| {
            let line = e
                .span()
                .map(|sp| src[..sp.start.min(src.len())].matches('\n').count() + 1);
            invalid(format!(
                "line {}: {}",
                line.unwrap_or(0),
                e.message().trim()
            ))
        })?;
        s.check().map_err(invalid)?;
        Ok(s)
    }

    /// Checks values and that the kind's table is present.
    pub fn check(&self) -> Result<(), String> {
        if !(self.duration_s.is_finite() && self.duration_s > 0.0 && self.duration_s <= 86_400.0) {
            return Err(format!(
                "duration_s must be in (0, 86400], got {}",
                self.duration_s
            ));
        }
        if !(self.rate_hz.is_finite() && (1.0..=100_000.0).contains(&self.rate_hz)) {
            return Err(format!(
                "rate_hz must be in [1, 100000], got {}",
                self.rate_hz
            ));
        }
        let s = &self.sensors;
        if !(s.torque_noise_nm.is_finite()
            && s.torque_noise_nm >= 0.0
            && s.force_noise_n.is_finite()
            && s.force_noise_n >= 0.0)
        {
            return Err("sensors: noise levels must be finite and >= 0".into());
        }
        if s.encoder_bits > 31 {
            return Err(format!(
                "sensors.encoder_bits must be at most 31 (0: no quantisation), got {}",
                s.encoder_bits
            ));
        }
        self.effects.validate()?;
        match self.kind.as_str() {
            "lever-bench" => {
                let b = self
                    .lever_bench
                    .as_ref()
                    .ok_or("kind = \"lever-bench\" needs a [lever_bench] table")?;
                if !(b.pivot_mm.is_finite()
                    && b.amplitude_rad.is_finite()
                    && b.amplitude_rad > 0.0
                    && b.amplitude_rad < 1.5)
                {
                    return Err(
                        "lever_bench: pivot_mm must be finite and amplitude_rad in (0, 1.5)".into(),
                    );
                }
            }
            "awas" => {
                let a = self
                    .awas
                    .as_ref()
                    .ok_or("kind = \"awas\" needs an [awas] table")?;
                if a.tau1
                    .iter()
                    .chain(&a.tau2)
                    .chain(&a.tau_ext)
                    .flatten()
                    .any(|v| !v.is_finite())
                {
                    return Err("awas: every amplitude and frequency must be finite".into());
                }
            }
            "serial" | "parallel" => {
                let r = self
                    .robot
                    .as_ref()
                    .ok_or("a robot scenario needs a [robot] table")?;
                if r.strokes.is_empty() {
                    return Err(
                        "robot.strokes needs at least one [axis, amplitude_mm, cycles]".into(),
                    );
                }
                for (axis, amp, cycles) in &r.strokes {
                    if axis != "x" && axis != "y" {
                        return Err(format!(
                            "robot.strokes: axis \"{axis}\" must be \"x\" or \"y\""
                        ));
                    }
                    if !(amp.is_finite() && *amp >= 0.0 && cycles.is_finite() && *cycles > 0.0) {
                        return Err(
                            "robot.strokes: amplitude_mm must be >= 0 and cycles > 0".into()
                        );
                    }
                }
            }
            other => {
                return Err(format!(
                    "kind \"{other}\" is not one of \"lever-bench\", \"awas\", \"serial\", \"parallel\""
                ));
            }
        }
        Ok(())
    }

    /// Samples the scenario produces.
    pub fn samples(&self) -> u64 {
        (self.duration_s * self.rate_hz).round() as u64
    }

    /// The rig config: the named file, or the example of the kind.
    pub fn rig_config(&self) -> Result<RigConfig, ScenarioError> {
        match &self.config {
            Some(p) => Ok(rig_config::load(p)?),
            None => Ok(rig_config::examples::load(match self.kind.as_str() {
                "awas" => "awas",
                "serial" => "serial",
                _ => "parallel",
            })?),
        }
    }
}

fn sines(terms: &[[f64; 2]], t: f64) -> f64 {
    terms
        .iter()
        .map(|[a, f]| a * (std::f64::consts::TAU * f * t).sin())
        .sum()
}

/// Runs the scenario: `header` once, then `row` per sample, `progress(done)` now and then.
pub fn run(
    s: &Scenario,
    header: &mut dyn FnMut(&[String]) -> Result<(), String>,
    row: &mut dyn FnMut(&[f64]) -> Result<(), String>,
    progress: &mut dyn FnMut(u64),
) -> Result<(), ScenarioError> {
    let cfg = s.rig_config()?;
    let ts = 1.0 / s.rate_hz;
    let n = s.samples();
    let sink = |e: String| ScenarioError::Sink(e);
    let sim = |e: String| ScenarioError::Sim(e);
    let mut noise = Noise::new(s.seed ^ 0xA5A5);
    let res = s.sensors.resolution();
    let mut delay = DelayLine::new(s.effects.delay_samples(ts));
    let lever = |cfg: &RigConfig| match cfg.joints.first().map(|j| &j.kind) {
        Some(JointKind::Lever { vsa, .. }) => Ok(*vsa),
        _ => Err(ScenarioError::Sim(format!(
            "rig \"{}\" has no lever joint",
            cfg.name
        ))),
    };
    match s.kind.as_str() {
        "lever-bench" => {
            let b = s
                .lever_bench
                .as_ref()
                .ok_or_else(|| sim("no [lever_bench]".into()))?;
            let vsa = lever(&cfg)?;
            let d = b.pivot_mm * 1e-3;
            let hysteresis = if b.hysteresis {
                SpringHysteresis::default()
            } else {
                SpringHysteresis {
                    a: 1.0,
                    ..SpringHysteresis::default()
                }
            };
            let mut plant = LeverJointPlant::new(vsa, hysteresis, s.effects, d, 1.0)
                .map_err(|e| ScenarioError::Plant(e.into()))?;
            header(&["t", "phi", "tau", "d", "true_phi", "true_tau"].map(String::from))
                .map_err(sink)?;
            let path = bench_path(n as usize, ts, b.amplitude_rad, s.seed);
            for (k, phi) in path.into_iter().enumerate() {
                let t = k as f64 * ts;
                let tau = plant.torque(phi, t, ts)
                    + s.effects.gravity(phi)
                    + s.effects.ripple(phi)
                    + s.effects.stop(phi);
                let tau_meas = delay.push(tau)
                    + s.effects.torque_offset_nm
                    + noise.gaussian(s.sensors.torque_noise_nm);
                let phi_meas = quantize(phi + s.effects.encoder_bias(t), res);
                row(&[t, phi_meas, tau_meas, plant.pivot.d * 1e3, phi, tau]).map_err(sink)?;
                if k % 1000 == 0 {
                    progress(k as u64);
                }
            }
        }
        "awas" => {
            let a = s.awas.as_ref().ok_or_else(|| sim("no [awas]".into()))?;
            let Some(JointKind::Awas { awas, dynamics }) = cfg.joints.first().map(|j| &j.kind)
            else {
                return Err(sim(format!("rig \"{}\" has no AWAS joint", cfg.name)));
            };
            let mut plant = AwasPlant::new(
                *awas,
                *dynamics,
                s.effects,
                AwasState {
                    theta2: 150.0,
                    ..Default::default()
                },
            );
            header(
                &[
                    "t",
                    "q",
                    "theta1",
                    "theta2",
                    "tau_e",
                    "tau",
                    "tau1",
                    "tau2",
                    "true_stiffness_nm_per_rad",
                    "true_q",
                ]
                .map(String::from),
            )
            .map_err(sink)?;
            for k in 0..n {
                let t = k as f64 * ts;
                let u = AwasInputs {
                    tau1: sines(&a.tau1, t),
                    tau2: sines(&a.tau2, t),
                    tau_ext: sines(&a.tau_ext, t),
                };
                let tau_e = delay.push(plant.elastic_torque(t))
                    + s.effects.torque_offset_nm
                    + noise.gaussian(s.sensors.torque_noise_nm);
                let st = plant.state;
                let q = quantize(st.q + s.effects.encoder_bias(t), res);
                row(&[
                    t,
                    q,
                    quantize(st.theta1, res),
                    quantize(st.theta2, THETA2_RESOLUTION_RAD),
                    tau_e,
                    u.tau_ext - tau_e,
                    u.tau1,
                    u.tau2,
                    plant.stiffness(t),
                    st.q,
                ])
                .map_err(sink)?;
                plant.step(&u, t, ts, 2);
                if k % 1000 == 0 {
                    progress(k);
                }
            }
        }
        _ => {
            let r = s.robot.as_ref().ok_or_else(|| sim("no [robot]".into()))?;
            let vsa = lever(&cfg)?;
            let (robot, home) = match (cfg.robot(), cfg.geometry) {
                (Some(robot), Some(g)) => (robot, g.home),
                _ => return Err(sim(format!("rig \"{}\" is not a robot", cfg.name))),
            };
            if r.pivot_mm.len() != robot.actuated() {
                return Err(sim(format!(
                    "robot.pivot_mm needs {} values, one per joint",
                    robot.actuated()
                )));
            }
            let joints = r
                .pivot_mm
                .iter()
                .map(|&d| {
                    LeverJointPlant::new(
                        vsa,
                        SpringHysteresis::default(),
                        s.effects,
                        d * 1e-3,
                        0.02,
                    )
                })
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| ScenarioError::Plant(e.into()))?;
            let sensors = PlanarSensors {
                encoder_resolution_rad: res,
                force_noise_n: s.sensors.force_noise_n,
            };
            let mut rig = PlanarRigSim::new(robot, joints, home, sensors, s.seed, ts)
                .map_err(|e| ScenarioError::Plant(e.into()))?;
            let nj = r.pivot_mm.len();
            let mut cols: Vec<String> = ["t", "x_m", "y_m", "fx_n", "fy_n"]
                .map(String::from)
                .to_vec();
            for j in 1..=nj {
                cols.extend([
                    format!("j{j}_motor_rad"),
                    format!("j{j}_phi_rad"),
                    format!("j{j}_d_mm"),
                ]);
            }
            cols.extend(["true_fx_n".to_string(), "true_fy_n".to_string()]);
            cols.extend((1..=nj).map(|j| format!("j{j}_true_tau_nm")));
            header(&cols).map_err(sink)?;
            let per = n / r.strokes.len() as u64;
            for k in 0..n {
                let i = ((k / per.max(1)) as usize).min(r.strokes.len() - 1);
                let (axis, amp, cycles) = &r.strokes[i];
                let stroke = Stroke {
                    axis: usize::from(axis == "y"),
                    amplitude_m: amp * 1e-3,
                    cycles: *cycles,
                    duration_s: per as f64 * ts,
                };
                let smp = rig
                    .step(stroke.offset((k - i as u64 * per) as f64 * ts))
                    .map_err(|e| ScenarioError::Plant(e.into()))?;
                let mut v = vec![
                    smp.t,
                    smp.ee_m.0,
                    smp.ee_m.1,
                    smp.force_n[0],
                    smp.force_n[1],
                ];
                for j in 0..nj {
                    v.extend([
                        smp.motor_rad[j],
                        smp.deflection_rad[j],
                        smp.pivot_m[j] * 1e3,
                    ]);
                }
                v.extend([smp.true_force_n[0], smp.true_force_n[1]]);
                v.extend(&smp.true_torque_nm);
                row(&v).map_err(sink)?;
                if k % 1000 == 0 {
                    progress(k);
                }
            }
        }
    }
    progress(n);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenario(src: &str) -> Scenario {
        let s: Scenario = toml::from_str(src).unwrap();
        s.check().unwrap();
        s
    }

    fn collect(s: &Scenario) -> (Vec<String>, Vec<Vec<f64>>) {
        let mut head = Vec::new();
        let mut rows = Vec::new();
        run(
            s,
            &mut |h| {
                head = h.to_vec();
                Ok(())
            },
            &mut |r| {
                rows.push(r.to_vec());
                Ok(())
            },
            &mut |_| {},
        )
        .unwrap();
        (head, rows)
    }

    #[test]
    fn lever_bench_offset_delay_and_quantisation_show_in_the_stream() {
        let s = scenario(
            "kind = \"lever-bench\"\nduration_s = 1.0\n[lever_bench]\npivot_mm = 9.0\namplitude_rad = 0.05\n\
             [sensors]\ntorque_noise_nm = 0.0\n[effects]\ntorque_offset_nm = 0.1\nsensor_delay_s = 0.005\n",
        );
        let (head, rows) = collect(&s);
        assert_eq!(head, ["t", "phi", "tau", "d", "true_phi", "true_tau"]);
        assert_eq!(rows.len(), 1000);
        let res = std::f64::consts::TAU / 16384.0;
        for (k, r) in rows.iter().enumerate().skip(5) {
            assert!(
                ((r[1] / res) - (r[1] / res).round()).abs() < 1e-9,
                "phi is quantised"
            );
            assert!(
                (r[2] - (rows[k - 5][5] + 0.1)).abs() < 1e-12,
                "tau is the true torque 5 samples ago + offset"
            );
        }
        // Same seed, same stream.
        assert_eq!(collect(&s).1, rows);
    }

    #[test]
    fn robot_stream_has_documented_columns_and_balances() {
        let s = scenario(
            "kind = \"parallel\"\nduration_s = 0.5\n[robot]\npivot_mm = [9.0, 9.0, 9.0, 9.0]\n\
             strokes = [[\"x\", 5.0, 1.0], [\"y\", 5.0, 1.0]]\n",
        );
        let (head, rows) = collect(&s);
        assert_eq!(head.len(), 5 + 3 * 4 + 2 + 4);
        assert_eq!(head[5], "j1_motor_rad");
        // The y stroke moves y only; the x stroke x only.
        assert!((rows[100][2] - 0.2).abs() < 1e-12 && (rows[100][1] - 0.075).abs() > 1e-4);
        assert!((rows[350][1] - 0.075).abs() < 1e-12 && (rows[350][2] - 0.2).abs() > 1e-4);
    }

    #[test]
    fn awas_stream_runs_and_bad_scenarios_are_refused() {
        let s = scenario("kind = \"awas\"\nduration_s = 0.2\n[awas]\ntau1 = [[6.0, 0.7]]\n");
        let (head, rows) = collect(&s);
        assert_eq!(head[5], "tau");
        assert_eq!(rows.len(), 200);
        for bad in [
            "kind = \"awas\"\nduration_s = 0.2\n",
            "kind = \"lever\"\nduration_s = 1.0\n",
            "kind = \"awas\"\nduration_s = -1.0\n[awas]\ntau1 = []\n",
            "kind = \"awas\"\nduration_s = 1.0\n[awas]\ntau1 = []\n[effects]\nbacklash_rad = -0.1\n",
        ] {
            let s: Scenario = toml::from_str(bad).unwrap();
            assert!(s.check().is_err(), "{bad}");
        }
        assert!(
            toml::from_str::<Scenario>("kind = \"awas\"\nduration_s = 1.0\nspeed = 3\n").is_err()
        );
    }
}
