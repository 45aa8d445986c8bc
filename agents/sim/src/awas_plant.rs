//! The "true" AWAS joint of paper A, integrated with RK4 at a fixed step, with undeclared
//! [`Effects`] on the link (friction, gravity), the spring (drift, backlash) and the sensors.

use rig_model::awas::{Awas, AwasDynamics, AwasState};

use crate::effects::Effects;
use crate::noise::Backlash;

/// Inputs held over one step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AwasInputs {
    pub tau1: f64,
    pub tau2: f64,
    pub tau_ext: f64,
}

/// The simulated AWAS joint.
#[derive(Debug, Clone)]
pub struct AwasPlant {
    pub awas: Awas,
    pub dynamics: AwasDynamics,
    pub effects: Effects,
    pub state: AwasState,
    backlash: Backlash,
    /// Deflection lost in the backlash (encoder deflection minus spring deflection) [rad].
    play: f64,
}

impl AwasPlant {
    pub fn new(awas: Awas, dynamics: AwasDynamics, effects: Effects, state: AwasState) -> Self {
        Self {
            awas,
            dynamics,
            effects,
            state,
            backlash: Backlash::new(effects.backlash_rad),
            play: 0.0,
        }
    }

    /// The spring-side deflection (after backlash; the play is frozen within one step).
    fn spring_deflection(&self, s: &AwasState, play_shift: f64) -> f64 {
        s.q - s.theta1 - play_shift
    }

    /// Elastic torque τ_E at time `t` for the current state (with drift and backlash).
    pub fn elastic_torque(&self, t: f64) -> f64 {
        let phi = self.spring_deflection(&self.state, self.play);
        self.awas.elastic_torque(phi, self.state.theta2) * self.effects.stiffness_scale(t)
    }

    /// True stiffness ∂τ_E/∂φ now.
    pub fn stiffness(&self, t: f64) -> f64 {
        let phi = self.spring_deflection(&self.state, self.play);
        self.awas.stiffness(phi, self.state.theta2) * self.effects.stiffness_scale(t)
    }

    fn derivative(&self, s: &AwasState, u: &AwasInputs, t: f64, shift: f64) -> [f64; 6] {
        let scale = self.effects.stiffness_scale(t);
        let phi = self.spring_deflection(s, shift);
        let tau_e = self.awas.elastic_torque(phi, s.theta2) * scale;
        let tau_r = self.awas.stiffness_motor_load(phi, s.theta2) * scale;
        let d = &self.dynamics;
        let link = u.tau_ext
            - d.link_damping * s.q_dot
            - tau_e
            - self.effects.friction(s.q_dot)
            - self.effects.gravity(s.q);
        [
            s.q_dot,
            link / d.link_inertia,
            s.theta1_dot,
            (u.tau1 + tau_e - d.d1 * s.theta1_dot) / d.b1,
            s.theta2_dot,
            (u.tau2 - tau_r - d.d2 * s.theta2_dot) / d.b2,
        ]
    }

    /// Advances by `dt` with `substeps` RK4 steps, inputs held.
    pub fn step(&mut self, u: &AwasInputs, t: f64, dt: f64, substeps: usize) {
        let n = substeps.max(1);
        let h = dt / n as f64;
        let phi = self.state.q - self.state.theta1;
        self.play = phi - self.backlash.update(phi);
        let shift = self.play;
        let add = |s: &AwasState, k: &[f64; 6], c: f64| AwasState {
            q: s.q + c * k[0],
            q_dot: s.q_dot + c * k[1],
            theta1: s.theta1 + c * k[2],
            theta1_dot: s.theta1_dot + c * k[3],
            theta2: s.theta2 + c * k[4],
            theta2_dot: s.theta2_dot + c * k[5],
        };
        for i in 0..n {
            let ti = t + i as f64 * h;
            let s = self.state;
            let k1 = self.derivative(&s, u, ti, shift);
            let k2 = self.derivative(&add(&s, &k1, 0.5 * h), u, ti + 0.5 * h, shift);
            let k3 = self.derivative(&add(&s, &k2, 0.5 * h), u, ti + 0.5 * h, shift);
            let k4 = self.derivative(&add(&s, &k3, h), u, ti + h, shift);
            let mut k = [0.0; 6];
            for j in 0..6 {
                k[j] = (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]) / 6.0;
            }
            self.state = add(&s, &k, h);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dynamics() -> AwasDynamics {
        AwasDynamics {
            link_inertia: 0.05,
            link_damping: 0.4,
            b1: 0.2,
            d1: 1.5,
            b2: 2e-4,
            d2: 2e-3,
        }
    }

    #[test]
    fn free_link_oscillates_at_the_closed_form_frequency() {
        // Motor locked (huge B1), small deflection: I·q̈ + N·q̇ + K·q = 0 with K = 2·k_s·r².
        let awas = Awas::paper_a();
        let dy = AwasDynamics {
            b1: 1e12,
            link_damping: 0.0,
            ..dynamics()
        };
        let mut p = AwasPlant::new(
            awas,
            dy,
            Effects::default(),
            AwasState {
                q: 1e-3,
                theta2: 0.0,
                ..Default::default()
            },
        );
        let k = awas.stiffness(0.0, 0.0);
        let omega = (k / dy.link_inertia).sqrt();
        let ts = 1e-4;
        let steps = (2.0 * std::f64::consts::PI / omega / ts).round() as usize; // one period
        for i in 0..steps {
            p.step(&AwasInputs::default(), i as f64 * ts, ts, 1);
        }
        // After one period the link is back near q0 (the period rounds to 1e-4 s).
        assert!((p.state.q - 1e-3).abs() < 2e-5, "q = {}", p.state.q);
    }

    #[test]
    fn energy_decays_with_damping_and_gravity_pulls_down() {
        let awas = Awas::paper_a();
        let mut p = AwasPlant::new(
            awas,
            dynamics(),
            Effects::default(),
            AwasState {
                q: 0.05,
                ..Default::default()
            },
        );
        for i in 0..5000 {
            p.step(&AwasInputs::default(), i as f64 * 1e-3, 1e-3, 2);
        }
        assert!((p.state.q - p.state.theta1).abs() < 1e-3);
        let e = Effects {
            gravity_mass_kg: 1.0,
            gravity_com_m: 0.2,
            ..Default::default()
        };
        let dy = AwasDynamics {
            b1: 1e12,
            ..dynamics()
        };
        // A constant external torque: the link settles where τ_E(q) + m·g·l·sin q = τ_ext.
        let settle = |e: Effects| {
            let mut p = AwasPlant::new(
                awas,
                dy,
                e,
                AwasState {
                    theta2: 150.0,
                    ..Default::default()
                },
            );
            let u = AwasInputs {
                tau_ext: 1.0,
                ..Default::default()
            };
            for i in 0..20_000 {
                p.step(&u, i as f64 * 1e-3, 1e-3, 2);
            }
            (p.state.q, p.elastic_torque(0.0))
        };
        let (q, tau_e) = settle(e);
        assert!(
            (tau_e + e.gravity(q) - 1.0).abs() < 1e-6,
            "residual at q = {q}"
        );
        let (q0, _) = settle(Effects::default());
        assert!(q < q0, "gravity must hold the link back: {q} vs {q0}");
    }
}
