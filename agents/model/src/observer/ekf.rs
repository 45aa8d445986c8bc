//! EKF for the link's inertia and damping (paper A eqs. 10–12 and appendix, MODEL.md §5).
//!
//! Link equation I·q̈ + N·q̇ = τ with τ = τ_ext − τ_E. State x = (q, q̇, 1/I, N/I):
//!
//! ```text
//! x1' = x1 + x2·Ts
//! x2' = x2 + (x3·τ − x4·x2)·Ts
//! x3' = x3,  x4' = x4
//! y   = (q, q̇),  H = [I₂ 0]
//! ```
//!
//! The covariance update uses the Joseph form, which stays symmetric and positive
//! semi-definite under round-off.

use nalgebra::{Matrix2, Matrix2x4, Matrix4, Matrix4x2, Vector2, Vector4};

use super::ObserverError;

/// Tuning of the EKF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EkfConfig {
    /// Sample time Ts [s].
    pub ts: f64,
    /// Diagonal of the process noise Q.
    pub q_diag: [f64; 4],
    /// Diagonal of the measurement noise R.
    pub r_diag: [f64; 2],
    /// Diagonal of the initial covariance P0.
    pub p0_diag: [f64; 4],
    /// Initial state x0 = (q, q̇, 1/I, N/I).
    pub x0: [f64; 4],
}

impl EkfConfig {
    /// Paper A's simulation tuning: Q = R = 0.001·I, P0 = 1e4·I, x0 = 0.
    pub fn paper_a_simulation(ts: f64) -> Self {
        Self {
            ts,
            q_diag: [1e-3; 4],
            r_diag: [1e-3; 2],
            p0_diag: [1e4; 4],
            x0: [0.0; 4],
        }
    }

    /// Paper A's experimental tuning: P0 = 100·I (Q, R as in simulation).
    pub fn paper_a_experiment(ts: f64) -> Self {
        Self {
            p0_diag: [100.0; 4],
            ..Self::paper_a_simulation(ts)
        }
    }

    fn validate(&self) -> Result<(), ObserverError> {
        let finite = self
            .q_diag
            .iter()
            .chain(&self.r_diag)
            .chain(&self.p0_diag)
            .chain(&self.x0)
            .all(|v| v.is_finite());
        if !(finite && self.ts.is_finite() && self.ts > 0.0) {
            return Err(ObserverError::Config(
                "EKF: Ts must be positive and every value finite".into(),
            ));
        }
        if self.q_diag.iter().chain(&self.p0_diag).any(|v| *v < 0.0)
            || self.r_diag.iter().any(|v| *v <= 0.0)
        {
            return Err(ObserverError::Config(
                "EKF: Q and P0 must be >= 0 and R > 0".into(),
            ));
        }
        Ok(())
    }
}

/// What the EKF believes about the link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkEstimate {
    /// Inertia I = 1/x3 [kg·m²], once x3 > 0.
    pub inertia: Option<f64>,
    /// Damping N = x4/x3 [N·m·s/rad], once x3 > 0.
    pub damping: Option<f64>,
    /// Variance of I by the delta method [kg²·m⁴].
    pub inertia_var: Option<f64>,
    /// Variance of N by the delta method.
    pub damping_var: Option<f64>,
    /// Filtered link angle [rad] and velocity [rad/s].
    pub q: f64,
    pub q_dot: f64,
}

/// The EKF, stepped once per sample.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkEkf {
    cfg: EkfConfig,
    x: Vector4<f64>,
    p: Matrix4<f64>,
    q: Matrix4<f64>,
    r: Matrix2<f64>,
}

impl LinkEkf {
    /// A filter with the given tuning.
    pub fn new(cfg: EkfConfig) -> Result<Self, ObserverError> {
        cfg.validate()?;
        Ok(Self {
            cfg,
            x: Vector4::from(cfg.x0),
            p: Matrix4::from_diagonal(&Vector4::from(cfg.p0_diag)),
            q: Matrix4::from_diagonal(&Vector4::from(cfg.q_diag)),
            r: Matrix2::from_diagonal(&Vector2::from(cfg.r_diag)),
        })
    }

    /// The state (q, q̇, 1/I, N/I).
    pub fn state(&self) -> Vector4<f64> {
        self.x
    }

    /// The covariance P.
    pub fn covariance(&self) -> Matrix4<f64> {
        self.p
    }

    /// One predict/update: `tau` [N·m] is the net torque on the link over the last interval,
    /// `q` [rad] and `q_dot` [rad/s] the measurements at its end. Non-finite input is refused
    /// and leaves the filter unchanged.
    pub fn step(&mut self, tau: f64, q: f64, q_dot: f64) -> Result<LinkEstimate, ObserverError> {
        if !(tau.is_finite() && q.is_finite() && q_dot.is_finite()) {
            return Err(ObserverError::NonFinite("EKF input (tau, q, q_dot)"));
        }
        let ts = self.cfg.ts;
        let x = self.x;
        // Predict.
        let x_pred = transition(&x, tau, ts);
        let f = transition_jacobian(&x, tau, ts);
        let p_pred = f * self.p * f.transpose() + self.q;
        // Update.
        let h = Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
        let s = h * p_pred * h.transpose() + self.r;
        let s_inv = s
            .try_inverse()
            .ok_or(ObserverError::Singular("EKF innovation covariance"))?;
        let k: Matrix4x2<f64> = p_pred * h.transpose() * s_inv;
        let innovation = Vector2::new(q, q_dot) - h * x_pred;
        let x_new = x_pred + k * innovation;
        let ikh = Matrix4::identity() - k * h;
        let p_new = ikh * p_pred * ikh.transpose() + k * self.r * k.transpose();
        if !(x_new.iter().all(|v| v.is_finite()) && p_new.iter().all(|v| v.is_finite())) {
            return Err(ObserverError::Diverged("EKF"));
        }
        self.x = x_new;
        self.p = 0.5 * (p_new + p_new.transpose());
        Ok(self.estimate())
    }

    /// The current estimate.
    pub fn estimate(&self) -> LinkEstimate {
        let (x3, x4) = (self.x[2], self.x[3]);
        let p = &self.p;
        let (inertia, damping, inertia_var, damping_var) = if x3 > 0.0 {
            // I = 1/x3: dI/dx3 = −1/x3².  N = x4/x3: ∇N = (−x4/x3², 1/x3).
            let di = -1.0 / (x3 * x3);
            let (dn3, dn4) = (-x4 / (x3 * x3), 1.0 / x3);
            let var_n = dn3 * dn3 * p[(2, 2)] + 2.0 * dn3 * dn4 * p[(2, 3)] + dn4 * dn4 * p[(3, 3)];
            (
                Some(1.0 / x3),
                Some(x4 / x3),
                Some(di * di * p[(2, 2)]),
                Some(var_n.max(0.0)),
            )
        } else {
            (None, None, None, None)
        };
        LinkEstimate {
            inertia,
            damping,
            inertia_var,
            damping_var,
            q: self.x[0],
            q_dot: self.x[1],
        }
    }
}

/// The discrete link model f(x, τ).
fn transition(x: &Vector4<f64>, tau: f64, ts: f64) -> Vector4<f64> {
    Vector4::new(
        x[0] + x[1] * ts,
        x[1] + (x[2] * tau - x[3] * x[1]) * ts,
        x[2],
        x[3],
    )
}

/// F = ∂f/∂x.
#[rustfmt::skip]
fn transition_jacobian(x: &Vector4<f64>, tau: f64, ts: f64) -> Matrix4<f64> {
    Matrix4::new(
        1.0, ts, 0.0, 0.0,
        0.0, 1.0 - x[3] * ts, tau * ts, -x[1] * ts,
        0.0, 0.0, 1.0, 0.0,
        0.0, 0.0, 0.0, 1.0,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Simulates I·q̈ + N·q̇ = τ with the filter's own discretisation, so the truth is exact.
    fn run(i_true: f64, n_true: f64, cfg: EkfConfig, steps: usize) -> LinkEstimate {
        let mut ekf = LinkEkf::new(cfg).unwrap();
        let (mut q, mut qd) = (0.0, 0.0);
        let mut est = ekf.estimate();
        for k in 0..steps {
            let t = k as f64 * cfg.ts;
            let tau = 1.5 * (2.0 * std::f64::consts::PI * 0.7 * t).sin()
                + 0.8 * (2.0 * std::f64::consts::PI * 2.3 * t).sin();
            let q_next = q + qd * cfg.ts;
            let qd_next = qd + (tau / i_true - n_true / i_true * qd) * cfg.ts;
            q = q_next;
            qd = qd_next;
            est = ekf.step(tau, q, qd).unwrap();
        }
        est
    }

    #[test]
    fn converges_to_the_true_inertia_and_damping() {
        let (i, n) = (0.05, 0.4);
        let est = run(i, n, EkfConfig::paper_a_simulation(1e-3), 20_000);
        let (ie, ne) = (est.inertia.unwrap(), est.damping.unwrap());
        assert!((ie - i).abs() < 1e-3 * i, "I = {ie}");
        assert!((ne - n).abs() < 1e-3 * n, "N = {ne}");
        // The delta-method σ is honest: the true values lie within 3σ, and σ is small.
        let (si, sn) = (
            est.inertia_var.unwrap().sqrt(),
            est.damping_var.unwrap().sqrt(),
        );
        assert!((ie - i).abs() <= 3.0 * si && (ne - n).abs() <= 3.0 * sn);
        // Q keeps a random-walk floor under σ (paper A tuning); it is still well below 10 %.
        assert!(si < 0.1 * i && sn < 0.1 * n, "σ_I = {si}, σ_N = {sn}");
    }

    #[test]
    fn refuses_nan_and_bad_tuning() {
        let mut ekf = LinkEkf::new(EkfConfig::paper_a_simulation(1e-3)).unwrap();
        let before = ekf.clone();
        assert!(ekf.step(f64::NAN, 0.0, 0.0).is_err());
        assert_eq!(ekf, before);
        assert!(
            LinkEkf::new(EkfConfig {
                ts: 0.0,
                ..EkfConfig::paper_a_simulation(1e-3)
            })
            .is_err()
        );
        assert!(
            LinkEkf::new(EkfConfig {
                r_diag: [0.0, 1.0],
                ..EkfConfig::paper_a_simulation(1e-3)
            })
            .is_err()
        );
    }

    #[test]
    fn jacobian_matches_finite_differences_of_the_transition() {
        let ts = 1e-3;
        let x = Vector4::new(0.3, -1.2, 20.0, 8.0);
        let tau = 0.7;
        let analytic = transition_jacobian(&x, tau, ts);
        for j in 0..4 {
            let mut e = Vector4::zeros();
            e[j] = 1e-6;
            let col = (transition(&(x + e), tau, ts) - transition(&(x - e), tau, ts)) / 2e-6;
            for i in 0..4 {
                assert!((col[i] - analytic[(i, j)]).abs() < 1e-8);
            }
        }
    }
}
