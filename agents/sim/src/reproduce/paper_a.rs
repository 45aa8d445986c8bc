//! Paper A in simulation: the decoupled impedance observer on AWAS (paper A §IV).
//!
//! Both motors are fed sinusoidal torques, the link is free (τ_ext = 0), the stiffness motor
//! moves slowly so that the stiffness really varies. The observer sees the link and motor
//! encoders and the torque sensor between harmonic drive and link — nothing else. Errors are
//! mean relative errors over the second half of each run ("after convergence").

use rig_config::{JointKind, RigConfig};
use rig_model::awas::AwasState;
use rig_model::observer::{DecoupledObserver, EkfConfig, ImpedanceSample};
use serde::Serialize;

use super::{Progress, ReproduceError};
use crate::awas_plant::{AwasInputs, AwasPlant};
use crate::effects::Effects;
use crate::noise::{Noise, quantize};

/// Lengths and sensor quality of the runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperAOptions {
    pub rate_hz: f64,
    pub duration_s: f64,
    /// Link and motor-side encoder resolution in the noisy scenario [rad] (14 bit).
    pub encoder_resolution_rad: f64,
    /// Torque-sensor noise σ in the noisy scenario [N·m].
    pub torque_noise_nm: f64,
    pub seed: u64,
}

impl PaperAOptions {
    pub fn full() -> Self {
        Self {
            rate_hz: 1000.0,
            duration_s: 120.0,
            encoder_resolution_rad: std::f64::consts::TAU / 16384.0,
            torque_noise_nm: 0.05,
            seed: 1,
        }
    }

    pub fn quick() -> Self {
        Self {
            duration_s: 60.0,
            ..Self::full()
        }
    }
}

/// Whose gains.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Tuning {
    /// Paper A's: simulation gains on clean data (Q = R = 1e-3·I, P0 = 1e4·I, α = 2000),
    /// experimental gains on noisy data (P0 = 100·I, α = 8).
    Paper,
    /// Ours: noise covariances matched to the sensors; on noisy data a 60-sample difference
    /// window in the stiffness observer with α = 120.
    Ours,
}

#[derive(Debug, Clone, Serialize)]
pub struct PaperARow {
    pub name: String,
    pub noisy: bool,
    pub tuning: Tuning,
    pub stiffness_rel_err: f64,
    pub damping_rel_err: f64,
    pub inertia_rel_err: f64,
    /// First time after which all three errors stay below 5 % (None: never).
    pub convergence_s: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct PaperAReport {
    pub scenarios: Vec<PaperARow>,
}

fn observer(
    tuning: Tuning,
    noisy: bool,
    ts: f64,
    o: &PaperAOptions,
) -> Result<DecoupledObserver, ReproduceError> {
    Ok(match (tuning, noisy) {
        (Tuning::Paper, false) => {
            DecoupledObserver::new(EkfConfig::paper_a_simulation(ts), 2000.0, 0.0, None)?
        }
        (Tuning::Paper, true) => {
            DecoupledObserver::new(EkfConfig::paper_a_experiment(ts), 8.0, 0.0, None)?
        }
        (Tuning::Ours, noisy) => {
            // Measurement noise from the sensors: a uniform quantisation error has variance
            // res²/12; the one-sample velocity difference carries 2·res²/12/Ts². Process noise:
            // the torque noise moves q̇ by σ_τ·Ts/I per step (I ≈ 0.05 kg·m² a priori);
            // the parameters are constants, allowed a slow random walk.
            let res = if noisy {
                o.encoder_resolution_rad
            } else {
                1e-6
            };
            let sig_tau = if noisy { o.torque_noise_nm } else { 1e-3 };
            let r_q = res * res / 12.0;
            let r_qd = 2.0 * r_q / (ts * ts);
            let q_v = (sig_tau * ts / 0.05).powi(2);
            let ekf = EkfConfig {
                ts,
                q_diag: [1e-12, q_v, 1e-6, 1e-6],
                r_diag: [r_q, r_qd],
                p0_diag: [1e-4, 1.0, 1e4, 1e4],
                x0: [0.0; 4],
            };
            // α and the window from a grid over α ∈ {10…240}, w ∈ {10…80} on the quick
            // noisy run (seed 1): the optimum is flat around α ≈ 80–160, w ≈ 40–60.
            let (alpha, window) = if noisy { (120.0, 60) } else { (2000.0, 1) };
            DecoupledObserver::new(ekf, alpha, 0.0, None)?.with_window(window)
        }
    })
}

/// Runs one scenario and scores it.
pub fn run_scenario(
    cfg: &RigConfig,
    noisy: bool,
    tuning: Tuning,
    o: &PaperAOptions,
) -> Result<PaperARow, ReproduceError> {
    let Some(JointKind::Awas { awas, dynamics }) = cfg.joints.first().map(|j| &j.kind) else {
        return Err(ReproduceError::Config(
            "paper A needs an AWAS joint (rig-config/examples/awas.toml)".into(),
        ));
    };
    let ts = 1.0 / o.rate_hz;
    let mut plant = AwasPlant::new(
        *awas,
        *dynamics,
        Effects::default(),
        AwasState {
            theta2: 150.0,
            ..Default::default()
        },
    );
    let mut obs = observer(tuning, noisy, ts, o)?;
    let mut noise = Noise::new(o.seed);
    let n = (o.duration_s * o.rate_hz) as usize;
    let w = std::f64::consts::TAU;
    let mut errs: Vec<(f64, f64, f64)> = Vec::with_capacity(n);
    for k in 0..n {
        let t = k as f64 * ts;
        // Sensors read the state at t.
        let res = if noisy { o.encoder_resolution_rad } else { 0.0 };
        let tau_e = plant.elastic_torque(t)
            + if noisy {
                noise.gaussian(o.torque_noise_nm)
            } else {
                0.0
            };
        let sample = ImpedanceSample {
            q: quantize(plant.state.q, res),
            theta1: quantize(plant.state.theta1, res),
            tau_e: Some(tau_e),
            tau1: None,
            tau_ext: 0.0,
        };
        let est = obs.step(&sample)?;
        let k_true = plant.stiffness(t);
        let rel = |a: Option<f64>, b: f64| a.map_or(1.0, |a| ((a - b) / b).abs());
        errs.push((
            ((est.stiffness - k_true) / k_true).abs(),
            rel(est.link.and_then(|l| l.damping), dynamics.link_damping),
            rel(est.link.and_then(|l| l.inertia), dynamics.link_inertia),
        ));
        // Both motors driven by sinusoids (paper A): the position motor near and below the
        // link's resonance, the stiffness motor slowly, so K sweeps ±20 %.
        let u = AwasInputs {
            tau1: 6.0 * (w * 0.7 * t).sin() + 3.0 * (w * 2.3 * t).sin() + 1.5 * (w * 9.0 * t).sin(),
            tau2: 0.004 * (w * 0.05 * t).sin(),
            tau_ext: 0.0,
        };
        plant.step(&u, t, ts, 2);
    }
    let half = &errs[n / 2..];
    let mean = |f: fn(&(f64, f64, f64)) -> f64| half.iter().map(f).sum::<f64>() / half.len() as f64;
    let last_bad = errs
        .iter()
        .rposition(|e| e.0 > 0.05 || e.1 > 0.05 || e.2 > 0.05);
    let convergence_s = match last_bad {
        None => Some(0.0),
        Some(i) if i + 1 < n => Some((i + 1) as f64 * ts),
        Some(_) => None,
    };
    let name = if noisy { "quantised-noisy" } else { "clean" };
    Ok(PaperARow {
        name: name.to_string(),
        noisy,
        tuning,
        stiffness_rel_err: mean(|e| e.0),
        damping_rel_err: mean(|e| e.1),
        inertia_rel_err: mean(|e| e.2),
        convergence_s,
    })
}

/// All four scenarios: clean and quantised-noisy sensors, paper's and our tuning.
pub fn run(
    cfg: &RigConfig,
    o: &PaperAOptions,
    progress: &mut Progress<'_>,
) -> Result<PaperAReport, ReproduceError> {
    let cases = [
        (false, Tuning::Paper),
        (false, Tuning::Ours),
        (true, Tuning::Paper),
        (true, Tuning::Ours),
    ];
    let mut scenarios = Vec::new();
    for (i, (noisy, tuning)) in cases.into_iter().enumerate() {
        progress("paper A: AWAS scenarios", i as u64, cases.len() as u64);
        scenarios.push(run_scenario(cfg, noisy, tuning, o)?);
    }
    progress("paper A: done", 1, 1);
    Ok(PaperAReport { scenarios })
}
