//! The decoupled impedance observer of paper A (MODEL.md §5).
//!
//! - [`stiffness`]: K̂ from the elastic torque and the deflection;
//! - [`ekf`]: inertia and damping of the link from its equation of motion;
//! - [`DecoupledObserver`]: both, fed sample by sample. The elastic torque comes from a
//!   torque sensor when there is one, otherwise from the position motor's equation
//!   τ_E = B1·θ̈1 + D1·θ̇1 − τ1, which needs only the motor's B1, D1 — never I or N. That
//!   is what breaks the loop between the two observers.
//!
//! Sign convention: deflection φ = q − θ1 (link minus motor), everywhere.

pub mod ekf;
pub mod stiffness;

use thiserror::Error;

pub use ekf::{EkfConfig, LinkEkf, LinkEstimate};
pub use stiffness::StiffnessObserver;

/// Errors of the observers.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ObserverError {
    #[error("invalid observer configuration: {0}")]
    Config(String),
    #[error("non-finite {0}: sample refused, state unchanged")]
    NonFinite(&'static str),
    #[error("{0} is singular")]
    Singular(&'static str),
    #[error("{0} diverged (non-finite state); sample refused")]
    Diverged(&'static str),
    #[error(
        "no elastic torque: the sample has neither a torque sensor reading nor a motor torque with motor parameters"
    )]
    NoElasticTorque,
}

/// Position-motor parameters for the motor-side elastic torque.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorParams {
    /// Inertia B1 [kg·m²].
    pub b1: f64,
    /// Damping D1 [N·m·s/rad].
    pub d1: f64,
}

/// One sample for the impedance observer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImpedanceSample {
    /// Link angle q [rad].
    pub q: f64,
    /// Position-motor angle θ1 [rad].
    pub theta1: f64,
    /// Elastic torque from a torque sensor [N·m], if fitted.
    pub tau_e: Option<f64>,
    /// Position-motor torque τ1 [N·m], if known.
    pub tau1: Option<f64>,
    /// External torque on the link [N·m] (0 for a free link, as in paper A).
    pub tau_ext: f64,
}

/// The observer's output for one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImpedanceEstimate {
    /// Stiffness K̂ [N·m/rad].
    pub stiffness: f64,
    /// Elastic torque used [N·m].
    pub tau_e: f64,
    /// The EKF's view of the link (None until it has two samples).
    pub link: Option<LinkEstimate>,
}

/// Stiffness observer plus EKF, decoupled as in paper A §III-B.
#[derive(Debug, Clone)]
pub struct DecoupledObserver {
    ts: f64,
    stiffness: StiffnessObserver,
    ekf: LinkEkf,
    motor: Option<MotorParams>,
    /// Previous (q, θ1, θ̇1^D, τ_link) once known.
    prev: Option<(f64, f64, Option<f64>, f64)>,
}

impl DecoupledObserver {
    /// Builds the observer. `alpha` and `k0` tune the stiffness observer; `motor` enables the
    /// motor-side elastic torque when no torque sensor is fitted.
    pub fn new(
        ekf: EkfConfig,
        alpha: f64,
        k0: f64,
        motor: Option<MotorParams>,
    ) -> Result<Self, ObserverError> {
        if let Some(m) = motor
            && !(m.b1.is_finite() && m.b1 > 0.0 && m.d1.is_finite() && m.d1 >= 0.0)
        {
            return Err(ObserverError::Config(
                "motor parameters: B1 > 0 and D1 >= 0 required".into(),
            ));
        }
        Ok(Self {
            ts: ekf.ts,
            stiffness: StiffnessObserver::new(alpha, ekf.ts, k0)?,
            ekf: LinkEkf::new(ekf)?,
            motor,
            prev: None,
        })
    }

    /// Uses `window`-sample differences in the stiffness observer (see
    /// [`StiffnessObserver::with_window`]).
    pub fn with_window(mut self, window: usize) -> Self {
        self.stiffness = self.stiffness.with_window(window);
        self
    }

    /// Feeds one sample. A sample with non-finite values is refused; state is unchanged.
    pub fn step(&mut self, s: &ImpedanceSample) -> Result<ImpedanceEstimate, ObserverError> {
        let finite = [Some(s.q), Some(s.theta1), s.tau_e, s.tau1, Some(s.tau_ext)]
            .into_iter()
            .flatten()
            .all(f64::is_finite);
        if !finite {
            return Err(ObserverError::NonFinite("impedance sample"));
        }
        let theta1_dot = self.prev.map(|(_, t1, _, _)| (s.theta1 - t1) / self.ts);
        let tau_e = match (s.tau_e, s.tau1, self.motor) {
            (Some(t), _, _) => Some(t),
            (None, Some(tau1), Some(m)) => match (theta1_dot, self.prev.and_then(|p| p.2)) {
                (Some(v), Some(v_prev)) => Some(m.b1 * (v - v_prev) / self.ts + m.d1 * v - tau1),
                _ => None, // needs three samples of θ1 for θ̈1
            },
            (None, _, _) => return Err(ObserverError::NoElasticTorque),
        };
        let phi = s.q - s.theta1;
        let mut link = None;
        let mut k = self.stiffness.stiffness();
        if let Some(tau_e) = tau_e {
            k = self.stiffness.step(tau_e, phi)?;
            if let Some((q_prev, _, _, tau_prev)) = self.prev {
                let q_dot = (s.q - q_prev) / self.ts;
                link = Some(self.ekf.step(tau_prev, s.q, q_dot)?);
            }
        }
        let tau_link = s.tau_ext - tau_e.unwrap_or(0.0);
        self.prev = Some((s.q, s.theta1, theta1_dot, tau_link));
        Ok(ImpedanceEstimate {
            stiffness: k,
            tau_e: tau_e.unwrap_or(f64::NAN),
            link,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::awas::{Awas, AwasDynamics, AwasState};

    struct Outcome {
        stiffness_rel_err: f64,
        inertia: f64,
        damping: f64,
    }

    const I_TRUE: f64 = 0.05;
    const N_TRUE: f64 = 0.4;

    /// A free AWAS link (τ_ext = 0) driven by sinusoidal motor torques, integrated with
    /// semi-implicit Euler at 1 kHz; the observer sees positions and one torque signal only.
    fn run(use_sensor: bool) -> Outcome {
        let awas = Awas::paper_a();
        let dy = AwasDynamics {
            link_inertia: I_TRUE,
            link_damping: N_TRUE,
            b1: 0.2,
            d1: 1.5,
            b2: 2e-4,
            d2: 2e-3,
        };
        let ts = 1e-3;
        let motor = Some(MotorParams {
            b1: dy.b1,
            d1: dy.d1,
        });
        let mut obs =
            DecoupledObserver::new(EkfConfig::paper_a_simulation(ts), 2000.0, 0.0, motor).unwrap();
        let mut s = AwasState {
            theta2: 150.0,
            ..Default::default()
        };
        let (mut k_err, mut n) = (0.0, 0usize);
        let mut last = None;
        for i in 0..60_000 {
            let t = i as f64 * ts;
            let w = 2.0 * std::f64::consts::PI;
            let tau1 = 3.0 * (w * 1.1 * t).sin() + 1.5 * (w * 3.7 * t).sin();
            let tau2 = 0.02 * (w * 0.05 * t).sin();
            let acc = awas.accelerations(&dy, &s, tau1, tau2, 0.0);
            s.q_dot += acc.q * ts;
            s.theta1_dot += acc.theta1 * ts;
            s.theta2_dot += acc.theta2 * ts;
            s.q += s.q_dot * ts;
            s.theta1 += s.theta1_dot * ts;
            s.theta2 += s.theta2_dot * ts;
            let sample = ImpedanceSample {
                q: s.q,
                theta1: s.theta1,
                tau_e: use_sensor.then_some(awas.elastic_torque(s.q - s.theta1, s.theta2)),
                tau1: Some(tau1),
                tau_ext: 0.0,
            };
            let est = obs.step(&sample).unwrap();
            if i > 30_000 {
                let k_true = awas.stiffness(s.q - s.theta1, s.theta2);
                k_err += (est.stiffness - k_true).abs() / k_true;
                n += 1;
            }
            last = est.link;
        }
        let link = last.unwrap();
        Outcome {
            stiffness_rel_err: k_err / n as f64,
            inertia: link.inertia.unwrap(),
            damping: link.damping.unwrap(),
        }
    }

    #[test]
    fn estimates_stiffness_inertia_and_damping_with_a_torque_sensor() {
        let o = run(true);
        assert!(
            o.stiffness_rel_err < 0.01,
            "stiffness mean rel. error {}",
            o.stiffness_rel_err
        );
        assert!(
            (o.inertia - I_TRUE).abs() < 0.02 * I_TRUE,
            "I = {}",
            o.inertia
        );
        assert!(
            (o.damping - N_TRUE).abs() < 0.02 * N_TRUE,
            "N = {}",
            o.damping
        );
    }

    #[test]
    fn estimates_from_the_motor_equation_without_a_torque_sensor() {
        let o = run(false);
        assert!(
            o.stiffness_rel_err < 0.05,
            "stiffness mean rel. error {}",
            o.stiffness_rel_err
        );
        assert!(
            (o.inertia - I_TRUE).abs() < 0.05 * I_TRUE,
            "I = {}",
            o.inertia
        );
        assert!(
            (o.damping - N_TRUE).abs() < 0.05 * N_TRUE,
            "N = {}",
            o.damping
        );
    }

    #[test]
    fn refuses_samples_without_any_torque() {
        let mut obs =
            DecoupledObserver::new(EkfConfig::paper_a_simulation(1e-3), 8.0, 0.0, None).unwrap();
        let s = ImpedanceSample {
            q: 0.0,
            theta1: 0.0,
            tau_e: None,
            tau1: Some(1.0),
            tau_ext: 0.0,
        };
        assert_eq!(obs.step(&s), Err(ObserverError::NoElasticTorque));
        let s = ImpedanceSample {
            q: f64::NAN,
            theta1: 0.0,
            tau_e: Some(0.0),
            tau1: None,
            tau_ext: 0.0,
        };
        assert!(obs.step(&s).is_err());
    }
}
