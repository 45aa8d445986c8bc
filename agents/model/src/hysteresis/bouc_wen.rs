//! Classic Bouc-Wen hysteresis (MODEL.md §2): the simulator's "true" hysteretic joint.
//!
//! ```text
//! τ = a·k·φ + (1 − a)·k·z
//! ż = A·φ̇ − β·|φ̇|·|z|^(n−1)·z − γ·φ̇·|z|^n
//! ```
//!
//! The model is rate-independent: dividing by φ̇ gives
//! `dz/dφ = A − β·s·|z|^(n−1)·z − γ·|z|^n` with `s = sign(φ̇)`, so the state is integrated
//! along the deflection path with RK4 sub-steps in φ. No velocity is ever differentiated.

use thiserror::Error;

/// Parameters of the Bouc-Wen model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoucWenParams {
    /// Elastic stiffness scale k [N·m/rad].
    pub k: f64,
    /// Ratio of the elastic part, a ∈ [0, 1].
    pub a: f64,
    /// Amplitude A of the hysteretic state's slope (dimensionless).
    pub big_a: f64,
    /// Shape β [1/rad^n].
    pub beta: f64,
    /// Shape γ [1/rad^n].
    pub gamma: f64,
    /// Smoothness exponent n ≥ 1.
    pub n: f64,
}

/// Invalid Bouc-Wen parameters.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("invalid Bouc-Wen parameters: {0}")]
pub struct BoucWenError(pub String);

impl BoucWenParams {
    /// Checks the parameters give a bounded, dissipative loop.
    pub fn validate(&self) -> Result<(), BoucWenError> {
        let v = [self.k, self.a, self.big_a, self.beta, self.gamma, self.n];
        if v.iter().any(|x| !x.is_finite()) {
            return Err(BoucWenError("every parameter must be finite".into()));
        }
        if self.k <= 0.0 || self.big_a <= 0.0 {
            return Err(BoucWenError("k and A must be positive".into()));
        }
        if !(0.0..=1.0).contains(&self.a) {
            return Err(BoucWenError(format!("a must be in [0, 1], got {}", self.a)));
        }
        if self.n < 1.0 {
            return Err(BoucWenError(format!("n must be >= 1, got {}", self.n)));
        }
        if self.beta + self.gamma <= 0.0 || self.beta < self.gamma.abs() {
            return Err(BoucWenError(
                "need beta + gamma > 0 and beta >= |gamma| for a bounded, dissipative loop".into(),
            ));
        }
        Ok(())
    }

    /// The largest |z| the state reaches, (A/(β+γ))^(1/n).
    pub fn z_max(&self) -> f64 {
        (self.big_a / (self.beta + self.gamma)).powf(1.0 / self.n)
    }
}

/// A Bouc-Wen element driven by deflection samples.
#[derive(Debug, Clone, PartialEq)]
pub struct BoucWen {
    params: BoucWenParams,
    phi: f64,
    z: f64,
}

impl BoucWen {
    /// A virgin element (z = 0) at deflection `phi0`.
    pub fn new(params: BoucWenParams, phi0: f64) -> Result<Self, BoucWenError> {
        params.validate()?;
        if !phi0.is_finite() {
            return Err(BoucWenError("initial deflection must be finite".into()));
        }
        Ok(Self {
            params,
            phi: phi0,
            z: 0.0,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &BoucWenParams {
        &self.params
    }

    /// The hysteretic state z [rad].
    pub fn z(&self) -> f64 {
        self.z
    }

    /// The current restoring torque [N·m].
    pub fn torque(&self) -> f64 {
        let p = &self.params;
        p.a * p.k * self.phi + (1.0 - p.a) * p.k * self.z
    }

    /// Moves the element to deflection `phi` and returns the torque there.
    /// A non-finite `phi` leaves the state unchanged.
    pub fn update(&mut self, phi: f64) -> f64 {
        if phi.is_finite() {
            let dphi = phi - self.phi;
            if dphi != 0.0 {
                self.z = self.integrate(self.z, dphi);
                self.phi = phi;
            }
        }
        self.torque()
    }

    fn slope(&self, z: f64, s: f64) -> f64 {
        let p = &self.params;
        let az = z.abs();
        p.big_a - p.beta * s * az.powf(p.n - 1.0) * z - p.gamma * az.powf(p.n)
    }

    fn integrate(&self, z0: f64, dphi: f64) -> f64 {
        let p = &self.params;
        let s = dphi.signum();
        // Sub-step so that h·|∂f/∂z| stays below 0.1 (RK4 is then accurate to ~1e-8).
        let stiff = p.n * (p.beta + p.gamma.abs()) * self.params.z_max().max(1e-12).powf(p.n - 1.0);
        let h_max = 0.1 / stiff.max(1e-12);
        let steps = ((dphi.abs() / h_max).ceil() as usize).clamp(1, 100_000);
        let h = dphi / steps as f64;
        let mut z = z0;
        for _ in 0..steps {
            let k1 = self.slope(z, s);
            let k2 = self.slope(z + 0.5 * h * k1, s);
            let k3 = self.slope(z + 0.5 * h * k2, s);
            let k4 = self.slope(z + h * k3, s);
            z += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
        }
        z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params_n1() -> BoucWenParams {
        BoucWenParams {
            k: 2.0,
            a: 0.3,
            big_a: 1.0,
            beta: 30.0,
            gamma: 10.0,
            n: 1.0,
        }
    }

    #[test]
    fn virgin_loading_matches_closed_form_for_n1() {
        // z' = A − (β+γ)z for z ≥ 0, φ increasing ⇒ z = A/(β+γ)·(1 − e^{−(β+γ)φ}).
        let p = params_n1();
        let mut bw = BoucWen::new(p, 0.0).unwrap();
        let c = p.beta + p.gamma;
        for i in 1..=200 {
            let phi = i as f64 * 5e-4;
            bw.update(phi);
            let z = p.big_a / c * (1.0 - (-c * phi).exp());
            assert!((bw.z() - z).abs() < 1e-9, "phi={phi}: {} vs {z}", bw.z());
        }
    }

    #[test]
    fn unloading_matches_closed_form_for_n1() {
        // From z0 > 0 with φ decreasing: z' = A + (β − γ)z ⇒ z = (z0 + A/c)e^{cΔ} − A/c, c = β − γ.
        let p = params_n1();
        let mut bw = BoucWen::new(p, 0.0).unwrap();
        bw.update(0.1);
        let z0 = bw.z();
        let c = p.beta - p.gamma;
        for i in 1..=100 {
            let delta = -(i as f64) * 1e-4;
            bw.update(0.1 + delta);
            let z = (z0 + p.big_a / c) * (c * delta).exp() - p.big_a / c;
            if z < 0.0 {
                break;
            }
            assert!((bw.z() - z).abs() < 1e-9);
        }
    }

    #[test]
    fn one_big_step_equals_many_small_ones() {
        let p = BoucWenParams {
            n: 2.0,
            ..params_n1()
        };
        let mut a = BoucWen::new(p, 0.0).unwrap();
        let mut b = BoucWen::new(p, 0.0).unwrap();
        a.update(0.08);
        for i in 1..=800 {
            b.update(i as f64 * 1e-4);
        }
        assert!((a.z() - b.z()).abs() < 1e-8);
    }

    #[test]
    fn loop_is_bounded_and_dissipative() {
        let p = BoucWenParams {
            n: 1.5,
            ..params_n1()
        };
        let mut bw = BoucWen::new(p, 0.0).unwrap();
        let mut work = 0.0;
        let mut prev_phi = 0.0;
        let mut prev_tau = 0.0;
        // Three full cycles; the work done over a cycle (∮τ dφ) is the loop area > 0.
        for i in 1..=3000 {
            let phi = 0.2 * (i as f64 * 2.0 * std::f64::consts::PI / 1000.0).sin();
            let tau = bw.update(phi);
            assert!(bw.z().abs() <= p.z_max() * (1.0 + 1e-9));
            if i > 1000 {
                work += 0.5 * (tau + prev_tau) * (phi - prev_phi);
            }
            prev_phi = phi;
            prev_tau = tau;
        }
        assert!(work > 0.0, "loop area {work}");
    }

    #[test]
    fn rejects_bad_parameters_and_ignores_nan() {
        assert!(
            BoucWen::new(
                BoucWenParams {
                    n: 0.5,
                    ..params_n1()
                },
                0.0
            )
            .is_err()
        );
        assert!(
            BoucWen::new(
                BoucWenParams {
                    beta: 1.0,
                    gamma: 5.0,
                    ..params_n1()
                },
                0.0
            )
            .is_err()
        );
        assert!(
            BoucWen::new(
                BoucWenParams {
                    k: f64::NAN,
                    ..params_n1()
                },
                0.0
            )
            .is_err()
        );
        let mut bw = BoucWen::new(params_n1(), 0.0).unwrap();
        bw.update(0.05);
        let before = bw.clone();
        bw.update(f64::NAN);
        assert_eq!(bw, before);
    }
}
