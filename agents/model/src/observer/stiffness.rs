//! Stiffness observer (Grioli & Bicchi; paper A eqs. 6, 13–15, MODEL.md §5).
//!
//! The elastic torque's rate is τ̇_E = K·φ̇ + (∂τ_E/∂θ2)·θ̇2. Predicting it with K̂ and
//! correcting on the error gives, in discrete form,
//!
//! ```text
//! x^D = (x_k − x_{k−1})/Ts
//! τ̃   = τ_E^D − K̂·φ^D
//! K̂  ← K̂ + α·τ̃·sgn(φ^D)·Ts
//! ```
//!
//! With a constant K the error contracts by (1 − α·|φ^D|·Ts) per step; it stays bounded
//! while |θ̇2/φ̇| is bounded. No sample where φ did not move (φ^D = 0) changes K̂, which is
//! what a quantised encoder needs.

use super::ObserverError;

/// The stiffness observer of one joint.
#[derive(Debug, Clone, PartialEq)]
pub struct StiffnessObserver {
    alpha: f64,
    ts: f64,
    k_hat: f64,
    window: usize,
    /// The last `window` + 1 samples of (τ_E, φ).
    history: std::collections::VecDeque<(f64, f64)>,
}

impl StiffnessObserver {
    /// An observer with gain `alpha` [1/rad], sample time `ts` [s] and initial guess `k0`.
    pub fn new(alpha: f64, ts: f64, k0: f64) -> Result<Self, ObserverError> {
        if !(alpha.is_finite() && alpha > 0.0 && ts.is_finite() && ts > 0.0 && k0.is_finite()) {
            return Err(ObserverError::Config(
                "stiffness observer: alpha and Ts must be positive, k0 finite".into(),
            ));
        }
        Ok(Self {
            alpha,
            ts,
            k_hat: k0,
            window: 1,
            history: std::collections::VecDeque::with_capacity(2),
        })
    }

    /// Differences over `window` samples instead of one: x^D = (x_k − x_{k−w})/(w·Ts).
    /// With quantised encoders a one-sample difference of φ is mostly 0 or ±1 count; a
    /// window of w samples resolves w times finer rates, at the price of w/2 samples of lag.
    /// Paper A uses w = 1.
    pub fn with_window(mut self, window: usize) -> Self {
        self.window = window.max(1);
        self.history = std::collections::VecDeque::with_capacity(self.window + 1);
        self
    }

    /// The estimate K̂ [N·m/rad].
    pub fn stiffness(&self) -> f64 {
        self.k_hat
    }

    /// Feeds the elastic torque τ_E [N·m] and the deflection φ [rad] of one sample.
    pub fn step(&mut self, tau_e: f64, phi: f64) -> Result<f64, ObserverError> {
        if !(tau_e.is_finite() && phi.is_finite()) {
            return Err(ObserverError::NonFinite(
                "stiffness observer input (tau_e, phi)",
            ));
        }
        self.history.push_back((tau_e, phi));
        if self.history.len() > self.window + 1 {
            self.history.pop_front();
        }
        if self.history.len() == self.window + 1
            && let Some(&(tau_old, phi_old)) = self.history.front()
        {
            let span = self.window as f64 * self.ts;
            let tau_d = (tau_e - tau_old) / span;
            let phi_d = (phi - phi_old) / span;
            let err = tau_d - self.k_hat * phi_d;
            let sgn = if phi_d > 0.0 {
                1.0
            } else if phi_d < 0.0 {
                -1.0
            } else {
                0.0
            };
            self.k_hat += self.alpha * err * sgn * self.ts;
        }
        Ok(self.k_hat)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_contracts_exactly_as_the_closed_form() {
        // Linear spring τ = K·φ: e_{k+1} = e_k·(1 − α·|Δφ_k|).
        let (k_true, alpha, ts) = (120.0, 2000.0, 1e-3);
        let mut obs = StiffnessObserver::new(alpha, ts, 0.0).unwrap();
        let mut e: f64 = k_true;
        let mut phi_prev = None::<f64>;
        for i in 0..3000 {
            let phi = 0.01 * (i as f64 * 0.01).sin();
            let est = obs.step(k_true * phi, phi).unwrap();
            if let Some(p) = phi_prev {
                e *= 1.0 - alpha * (phi - p).abs();
            }
            phi_prev = Some(phi);
            assert!(((k_true - est) - e).abs() < 1e-9 * k_true, "step {i}");
        }
        assert!(e.abs() < 1e-3, "still {e} off after 3 s");
    }

    #[test]
    fn tracks_a_nonlinear_spring_and_ignores_standstill() {
        // τ = k1·φ + k3·φ³: the observer follows K(φ) = k1 + 3·k3·φ² (slowly varying).
        let (k1, k3) = (50.0, 4000.0);
        let mut obs = StiffnessObserver::new(3000.0, 1e-3, 10.0).unwrap();
        let mut worst_late: f64 = 0.0;
        for i in 0..20_000 {
            let phi = 0.05 * (i as f64 * 2e-3).sin();
            let k = obs.step(k1 * phi + k3 * phi.powi(3), phi).unwrap();
            if i > 10_000 {
                worst_late = worst_late.max((k - (k1 + 3.0 * k3 * phi * phi)).abs() / k1);
            }
        }
        assert!(worst_late < 0.05, "relative tracking error {worst_late}");
        // A standing deflection with a changing torque (a θ2 move) leaves K̂ alone.
        obs.step(1.0, 0.02).unwrap();
        let k_before = obs.stiffness();
        obs.step(1.5, 0.02).unwrap();
        obs.step(2.0, 0.02).unwrap();
        assert_eq!(obs.stiffness(), k_before);
    }

    #[test]
    fn a_window_resolves_slow_rates_through_quantisation() {
        // A quantised encoder (1e-3 rad counts) on a slow sinusoid: one-sample differences
        // are 0 or one count; a 20-sample window recovers K much more closely.
        let k_true = 200.0;
        let run = |window: usize| {
            let mut obs = StiffnessObserver::new(30.0, 1e-3, 150.0)
                .unwrap()
                .with_window(window);
            let mut err = 0.0;
            for i in 0..40_000 {
                let phi = 0.02 * (i as f64 * 2e-3).sin();
                let q = (phi / 1e-3).round() * 1e-3;
                let k = obs.step(k_true * phi, q).unwrap();
                if i >= 20_000 {
                    err += (k - k_true).abs() / k_true / 20_000.0;
                }
            }
            err
        };
        let (one, twenty) = (run(1), run(20));
        assert!(twenty < 0.5 * one, "window 1: {one}, window 20: {twenty}");
    }

    #[test]
    fn refuses_nan_and_bad_gains() {
        let mut obs = StiffnessObserver::new(8.0, 1e-3, 0.0).unwrap();
        assert!(obs.step(f64::NAN, 0.0).is_err());
        assert!(StiffnessObserver::new(-1.0, 1e-3, 0.0).is_err());
        assert!(StiffnessObserver::new(1.0, f64::NAN, 0.0).is_err());
    }
}
