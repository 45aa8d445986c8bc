//! The AWAS joint of paper A (eqs. 16–20, MODEL.md §5).
//!
//! Link angle q, position motor θ1, stiffness motor θ2, deflection φ = q − θ1 (this sign is
//! kept everywhere in the project). The spring energy is U = k_s·r²·sin²φ with the lever arm
//! r = r0 − n·θ2 set by a ball screw, so
//!
//! ```text
//! τ_E = ∂U/∂φ  = k_s·r²·sin(2φ)           elastic torque
//! K   = ∂τ_E/∂φ = 2·k_s·r²·cos(2φ)        joint stiffness
//! τ_r = ∂U/∂θ2 = −2·k_s·n·r·sin²φ         load on the stiffness motor
//! ```
//!
//! and the dynamics (paper A eq. 16, gravity neglected as in the paper):
//!
//! ```text
//! I·q̈ + N·q̇ + τ_E = τ_ext
//! B1·θ̈1 + D1·θ̇1 − τ_E = τ1
//! B2·θ̈2 + D2·θ̇2 + τ_r = τ2
//! ```

use thiserror::Error;

/// Errors of the AWAS model.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum AwasError {
    #[error("invalid AWAS parameters: {0}")]
    Invalid(String),
    #[error(
        "stiffness {k_nm_per_rad} N·m/rad is outside the AWAS range [{k_min_nm_per_rad}, {k_max_nm_per_rad}] N·m/rad"
    )]
    StiffnessOutOfRange {
        k_nm_per_rad: f64,
        k_min_nm_per_rad: f64,
        k_max_nm_per_rad: f64,
    },
}

/// The elastic mechanism of AWAS.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Awas {
    /// Spring rate k_s [N/m].
    pub k_s: f64,
    /// Lever arm at θ2 = 0 [m].
    pub r0: f64,
    /// Ball-screw transmission n [m/rad].
    pub n: f64,
    /// Shortest usable lever arm [m].
    pub r_min: f64,
    /// Longest usable lever arm [m] (≤ r0).
    pub r_max: f64,
}

/// Rigid-body parameters of the link and the two motors (scaled to the joint side).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AwasDynamics {
    /// Link inertia I [kg·m²].
    pub link_inertia: f64,
    /// Link damping N [N·m·s/rad].
    pub link_damping: f64,
    /// Position-motor inertia B1 [kg·m²].
    pub b1: f64,
    /// Position-motor damping D1 [N·m·s/rad].
    pub d1: f64,
    /// Stiffness-motor inertia B2 [kg·m²].
    pub b2: f64,
    /// Stiffness-motor damping D2 [N·m·s/rad].
    pub d2: f64,
}

/// Positions and velocities of the three bodies.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AwasState {
    pub q: f64,
    pub q_dot: f64,
    pub theta1: f64,
    pub theta1_dot: f64,
    pub theta2: f64,
    pub theta2_dot: f64,
}

/// Accelerations (q̈, θ̈1, θ̈2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AwasAccel {
    pub q: f64,
    pub theta1: f64,
    pub theta2: f64,
}

impl Awas {
    /// Parameters chosen to match the AWAS spec of paper A (stiffness 30–1500 N·m/rad):
    /// k_s = 1e5 N/m, r from 12.25 mm to 86.6 mm, a 2 mm-lead ball screw. Paper A does not
    /// give these; they are ours, picked to reproduce the published range.
    pub fn paper_a() -> Self {
        let k_s: f64 = 1.0e5;
        let r_max = (1500.0 / (2.0 * k_s)).sqrt();
        Self {
            k_s,
            r0: r_max,
            n: 0.002 / (2.0 * std::f64::consts::PI),
            r_min: (30.0 / (2.0 * k_s)).sqrt(),
            r_max,
        }
    }

    /// Checks positivity and r_min < r_max ≤ r0.
    pub fn validate(&self) -> Result<(), AwasError> {
        let v = [self.k_s, self.r0, self.n, self.r_min, self.r_max];
        if v.iter().any(|x| !x.is_finite() || *x <= 0.0) {
            return Err(AwasError::Invalid(
                "k_s, r0, n, r_min and r_max must be finite and positive".into(),
            ));
        }
        if self.r_min >= self.r_max || self.r_max > self.r0 {
            return Err(AwasError::Invalid(format!(
                "need r_min < r_max <= r0, got r_min = {}, r_max = {}, r0 = {} m",
                self.r_min, self.r_max, self.r0
            )));
        }
        Ok(())
    }

    /// Lever arm r = r0 − n·θ2 [m].
    #[inline]
    pub fn arm(&self, theta2: f64) -> f64 {
        self.r0 - self.n * theta2
    }

    /// Spring energy U = k_s·r²·sin²φ [J].
    pub fn energy(&self, phi: f64, theta2: f64) -> f64 {
        let r = self.arm(theta2);
        self.k_s * r * r * phi.sin().powi(2)
    }

    /// Elastic torque τ_E = k_s·r²·sin 2φ [N·m].
    #[inline]
    pub fn elastic_torque(&self, phi: f64, theta2: f64) -> f64 {
        let r = self.arm(theta2);
        self.k_s * r * r * (2.0 * phi).sin()
    }

    /// Stiffness K = ∂τ_E/∂φ = 2·k_s·r²·cos 2φ [N·m/rad].
    #[inline]
    pub fn stiffness(&self, phi: f64, theta2: f64) -> f64 {
        let r = self.arm(theta2);
        2.0 * self.k_s * r * r * (2.0 * phi).cos()
    }

    /// ∂τ_E/∂θ2 = −2·k_s·n·r·sin 2φ: how moving the stiffness motor changes the torque.
    #[inline]
    pub fn dtau_dtheta2(&self, phi: f64, theta2: f64) -> f64 {
        -2.0 * self.k_s * self.n * self.arm(theta2) * (2.0 * phi).sin()
    }

    /// Load on the stiffness motor τ_r = −2·k_s·n·r·sin²φ [N·m].
    #[inline]
    pub fn stiffness_motor_load(&self, phi: f64, theta2: f64) -> f64 {
        -2.0 * self.k_s * self.n * self.arm(theta2) * phi.sin().powi(2)
    }

    /// The rest-stiffness range over the usable arm, (2·k_s·r_min², 2·k_s·r_max²).
    pub fn stiffness_range(&self) -> (f64, f64) {
        (
            2.0 * self.k_s * self.r_min.powi(2),
            2.0 * self.k_s * self.r_max.powi(2),
        )
    }

    /// Stiffness-motor angle θ2 that gives rest stiffness `k`: r = √(k/(2k_s)), θ2 = (r0 − r)/n.
    pub fn theta2_for_stiffness(&self, k: f64) -> Result<f64, AwasError> {
        let (lo, hi) = self.stiffness_range();
        if !k.is_finite() || k < lo * (1.0 - 1e-12) || k > hi * (1.0 + 1e-12) {
            return Err(AwasError::StiffnessOutOfRange {
                k_nm_per_rad: k,
                k_min_nm_per_rad: lo,
                k_max_nm_per_rad: hi,
            });
        }
        let r = (k / (2.0 * self.k_s)).sqrt();
        Ok((self.r0 - r) / self.n)
    }

    /// Accelerations of link and motors for the given state and inputs.
    pub fn accelerations(
        &self,
        dyn_: &AwasDynamics,
        s: &AwasState,
        tau1: f64,
        tau2: f64,
        tau_ext: f64,
    ) -> AwasAccel {
        let phi = s.q - s.theta1;
        let tau_e = self.elastic_torque(phi, s.theta2);
        let tau_r = self.stiffness_motor_load(phi, s.theta2);
        AwasAccel {
            q: (tau_ext - dyn_.link_damping * s.q_dot - tau_e) / dyn_.link_inertia,
            theta1: (tau1 + tau_e - dyn_.d1 * s.theta1_dot) / dyn_.b1,
            theta2: (tau2 - tau_r - dyn_.d2 * s.theta2_dot) / dyn_.b2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fd<F: Fn(f64) -> f64>(f: F, x: f64) -> f64 {
        let h = 1e-6;
        (f(x + h) - f(x - h)) / (2.0 * h)
    }

    #[test]
    fn torques_are_gradients_of_the_energy() {
        let a = Awas::paper_a();
        for &(phi, t2) in &[(0.0, 0.0), (0.1, 30.0), (-0.3, 120.0), (0.5, 200.0)] {
            let te = fd(|x| a.energy(x, t2), phi);
            assert!((te - a.elastic_torque(phi, t2)).abs() < 1e-6 * (1.0 + te.abs()));
            let tr = fd(|x| a.energy(phi, x), t2);
            assert!((tr - a.stiffness_motor_load(phi, t2)).abs() < 1e-6 * (1.0 + tr.abs()));
            let k = fd(|x| a.elastic_torque(x, t2), phi);
            assert!((k - a.stiffness(phi, t2)).abs() < 1e-5 * (1.0 + k.abs()));
            let dt2 = fd(|x| a.elastic_torque(phi, x), t2);
            assert!((dt2 - a.dtau_dtheta2(phi, t2)).abs() < 1e-6 * (1.0 + dt2.abs()));
        }
    }

    #[test]
    fn reproduces_the_published_stiffness_range() {
        let a = Awas::paper_a();
        a.validate().unwrap();
        let (lo, hi) = a.stiffness_range();
        assert!((lo - 30.0).abs() < 1e-9 && (hi - 1500.0).abs() < 1e-9);
        assert!((a.stiffness(0.0, 0.0) - 1500.0).abs() < 1e-9);
        let t2 = a.theta2_for_stiffness(300.0).unwrap();
        assert!((a.stiffness(0.0, t2) - 300.0).abs() < 1e-9);
        assert!(a.theta2_for_stiffness(10.0).is_err());
        assert!(a.theta2_for_stiffness(f64::NAN).is_err());
    }

    #[test]
    fn accelerations_balance_each_equation() {
        let a = Awas::paper_a();
        let d = AwasDynamics {
            link_inertia: 0.05,
            link_damping: 0.4,
            b1: 0.2,
            d1: 1.0,
            b2: 1e-4,
            d2: 1e-3,
        };
        let s = AwasState {
            q: 0.12,
            q_dot: 0.5,
            theta1: 0.1,
            theta1_dot: -0.2,
            theta2: 50.0,
            theta2_dot: 3.0,
        };
        let (t1, t2, te) = (2.0, 0.01, -1.0);
        let acc = a.accelerations(&d, &s, t1, t2, te);
        let phi = s.q - s.theta1;
        let tau_e = a.elastic_torque(phi, s.theta2);
        assert!((d.link_inertia * acc.q + d.link_damping * s.q_dot + tau_e - te).abs() < 1e-12);
        assert!((d.b1 * acc.theta1 + d.d1 * s.theta1_dot - tau_e - t1).abs() < 1e-12);
        let tau_r = a.stiffness_motor_load(phi, s.theta2);
        assert!((d.b2 * acc.theta2 + d.d2 * s.theta2_dot + tau_r - t2).abs() < 1e-12);
    }

    #[test]
    fn validation_catches_inverted_arm_range() {
        let mut a = Awas::paper_a();
        a.r_min = 0.1;
        assert!(a.validate().is_err());
    }
}
