//! The lever VSA joint of paper B §2 (MODEL.md §1).
//!
//! Main joint O, output-link deflection φ, lever axis L on the output link at distance `p`
//! from O, pivot P on the base centre line at distance `d_a = d0 + d` from O. The lever runs
//! from L through P; the torsion spring at L is deformed by the lever angle α.
//!
//! ```text
//! β(φ) = atan2(p·sin φ, p·cos φ − d_a)     absolute lever angle, β = α + φ
//! α(φ) = β(φ) − φ                          spring deformation
//! ℓ(φ) = |L − P|                           pivot-to-lever-axis length (paper's q)
//! G(φ) = dα/dφ = d_a·cos(α + φ)/ℓ          paper eq. 1
//! τ(φ) = G(φ)·k_α·α(φ)                     static restoring torque (virtual work)
//! k_φ  = G²·k_α                            paper eq. 2 (drops k_α·α·dG/dφ)
//! ```
//!
//! All quantities are SI: lengths in metres, angles in radians, torques in N·m.

use thiserror::Error;

/// Errors of the lever model.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LeverError {
    /// The geometry cannot form the mechanism.
    #[error("invalid lever geometry: {0}")]
    Geometry(String),
    /// A requested stiffness cannot be reached inside the pivot travel.
    #[error(
        "joint stiffness {k_nm_per_rad} N·m/rad is outside the reachable range \
         [{k_min_nm_per_rad}, {k_max_nm_per_rad}] N·m/rad (pivot travel {d_min_m}..{d_max_m} m)"
    )]
    StiffnessOutOfRange {
        k_nm_per_rad: f64,
        k_min_nm_per_rad: f64,
        k_max_nm_per_rad: f64,
        d_min_m: f64,
        d_max_m: f64,
    },
    /// A pivot position outside its travel.
    #[error("pivot position {d_m} m is outside the travel [{d_min_m}, {d_max_m}] m")]
    PivotOutOfRange {
        d_m: f64,
        d_min_m: f64,
        d_max_m: f64,
    },
}

/// Geometry and spring of one lever VSA.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeverVsa {
    /// Distance from the main joint to the lever axis [m].
    pub p: f64,
    /// Minimum distance from the main joint to the pivot [m] (paper: 9.6 mm).
    pub d0: f64,
    /// Pivot travel, lower end [m] (paper: 0).
    pub d_min: f64,
    /// Pivot travel, upper end [m] (paper: 18 mm).
    pub d_max: f64,
    /// Torsion spring rate [N·m/rad].
    pub k_alpha: f64,
    /// Spring hard limit on |α| [rad] (paper: 43°).
    pub alpha_max: f64,
}

impl LeverVsa {
    /// Paper B's joint with p = 31.5 mm (MODEL.md: reproduces the measured stiffness range).
    pub fn paper_b() -> Self {
        Self {
            p: 0.0315,
            d0: 0.0096,
            d_min: 0.0,
            d_max: 0.018,
            k_alpha: 0.9788 / 43f64.to_radians(),
            alpha_max: 43f64.to_radians(),
        }
    }

    /// Checks that the numbers form a mechanism: positive finite lengths, the pivot always
    /// strictly between the main joint and the lever axis.
    pub fn validate(&self) -> Result<(), LeverError> {
        let all = [
            self.p,
            self.d0,
            self.d_min,
            self.d_max,
            self.k_alpha,
            self.alpha_max,
        ];
        if all.iter().any(|v| !v.is_finite()) {
            return Err(LeverError::Geometry(
                "every parameter must be finite".into(),
            ));
        }
        if self.p <= 0.0 || self.d0 <= 0.0 || self.k_alpha <= 0.0 || self.alpha_max <= 0.0 {
            return Err(LeverError::Geometry(
                "p, d0, k_alpha and alpha_max must be positive".into(),
            ));
        }
        if self.d_min < 0.0 || self.d_max <= self.d_min {
            return Err(LeverError::Geometry(format!(
                "pivot travel must satisfy 0 <= d_min < d_max, got [{}, {}] m",
                self.d_min, self.d_max
            )));
        }
        if self.d0 + self.d_max >= self.p {
            return Err(LeverError::Geometry(format!(
                "the pivot must stay between the main joint and the lever axis: \
                 d0 + d_max = {} m must be < p = {} m",
                self.d0 + self.d_max,
                self.p
            )));
        }
        Ok(())
    }

    /// Distance main joint → pivot for a pivot position `d` [m].
    #[inline]
    pub fn d_a(&self, d: f64) -> f64 {
        self.d0 + d
    }

    /// Absolute lever angle β(φ) = α + φ.
    #[inline]
    pub fn beta(&self, phi: f64, d: f64) -> f64 {
        let (s, c) = phi.sin_cos();
        (self.p * s).atan2(self.p * c - self.d_a(d))
    }

    /// Spring deformation α(φ).
    #[inline]
    pub fn alpha(&self, phi: f64, d: f64) -> f64 {
        self.beta(phi, d) - phi
    }

    /// Pivot-to-lever-axis length ℓ(φ) (the paper's q).
    #[inline]
    pub fn ell(&self, phi: f64, d: f64) -> f64 {
        let (s, c) = phi.sin_cos();
        (self.p * c - self.d_a(d)).hypot(self.p * s)
    }

    /// Transmission G(φ) = dα/dφ (paper eq. 1).
    #[inline]
    pub fn g(&self, phi: f64, d: f64) -> f64 {
        self.d_a(d) * self.beta(phi, d).cos() / self.ell(phi, d)
    }

    /// dG/dφ, in closed form.
    ///
    /// With β' = G + 1 and ℓ' = d_a·p·sin φ / ℓ:
    /// dG/dφ = −d_a·sin β·β'/ℓ − d_a·cos β·ℓ'/ℓ².
    pub fn dg_dphi(&self, phi: f64, d: f64) -> f64 {
        let da = self.d_a(d);
        let beta = self.beta(phi, d);
        let ell = self.ell(phi, d);
        let g = da * beta.cos() / ell;
        let dell = da * self.p * phi.sin() / ell;
        -da * beta.sin() * (g + 1.0) / ell - da * beta.cos() * dell / (ell * ell)
    }

    /// Static restoring torque at the main joint, τ = G·k_α·α [N·m].
    #[inline]
    pub fn torque(&self, phi: f64, d: f64) -> f64 {
        self.g(phi, d) * self.k_alpha * self.alpha(phi, d)
    }

    /// Joint stiffness as paper eq. 2, k_φ = G²·k_α (drops the k_α·α·dG/dφ term).
    #[inline]
    pub fn stiffness(&self, phi: f64, d: f64) -> f64 {
        let g = self.g(phi, d);
        g * g * self.k_alpha
    }

    /// Exact joint stiffness dτ/dφ = G²·k_α + k_α·α·dG/dφ (the geometric term included).
    pub fn stiffness_exact(&self, phi: f64, d: f64) -> f64 {
        self.stiffness(phi, d) + self.k_alpha * self.alpha(phi, d) * self.dg_dphi(phi, d)
    }

    /// Stiffness at zero deflection, paper eq. 3: (d_a/(p − d_a))²·k_α.
    #[inline]
    pub fn stiffness_at_rest(&self, d: f64) -> f64 {
        let da = self.d_a(d);
        let r = da / (self.p - da);
        r * r * self.k_alpha
    }

    /// The range of rest stiffness over the pivot travel, (k(d_min), k(d_max)).
    pub fn stiffness_range(&self) -> (f64, f64) {
        (
            self.stiffness_at_rest(self.d_min),
            self.stiffness_at_rest(self.d_max),
        )
    }

    /// Pivot position `d` [m] that gives the rest stiffness `k` [N·m/rad].
    ///
    /// From k = (d_a/(p − d_a))²·k_α with r = √(k/k_α): d_a = p·r/(1 + r), d = d_a − d0.
    /// Outside the travel it is an error, never a silent clamp.
    pub fn pivot_for_stiffness(&self, k: f64) -> Result<f64, LeverError> {
        let (k_min, k_max) = self.stiffness_range();
        let out_of_range = || LeverError::StiffnessOutOfRange {
            k_nm_per_rad: k,
            k_min_nm_per_rad: k_min,
            k_max_nm_per_rad: k_max,
            d_min_m: self.d_min,
            d_max_m: self.d_max,
        };
        if !k.is_finite() || k <= 0.0 {
            return Err(out_of_range());
        }
        let r = (k / self.k_alpha).sqrt();
        let d = self.p * r / (1.0 + r) - self.d0;
        // Allow rounding at the ends of the travel (1 nm), nothing more.
        const EPS: f64 = 1e-9;
        if d < self.d_min - EPS || d > self.d_max + EPS {
            return Err(out_of_range());
        }
        Ok(d.clamp(self.d_min, self.d_max))
    }

    /// Whether the spring is inside its hard limit at deflection `phi`.
    pub fn spring_within_limit(&self, phi: f64, d: f64) -> bool {
        self.alpha(phi, d).abs() <= self.alpha_max
    }

    /// The deflection where the lever reaches its dead point: β = 90°, so G = 0 and the
    /// joint stiffness vanishes; φ_dead = acos(d_a/p). Beyond it the joint would snap through.
    pub fn dead_point(&self, d: f64) -> f64 {
        (self.d_a(d) / self.p).clamp(-1.0, 1.0).acos()
    }

    /// The largest usable |φ| at pivot position `d`: where the spring reaches `alpha_max` or
    /// the lever its dead point, whichever comes first. α(φ) rises monotonically on
    /// [0, φ_dead], so bisection finds the spring limit there.
    pub fn deflection_limit(&self, d: f64) -> f64 {
        let dead = self.dead_point(d);
        if self.alpha(dead, d) <= self.alpha_max {
            return dead;
        }
        let (mut lo, mut hi) = (0.0_f64, dead);
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if self.alpha(mid, d) > self.alpha_max {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        lo
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn central<F: Fn(f64) -> f64>(f: F, x: f64) -> f64 {
        let h = 1e-6;
        (f(x + h) - f(x - h)) / (2.0 * h)
    }

    #[test]
    fn paper_geometry_is_valid() {
        LeverVsa::paper_b().validate().unwrap();
    }

    #[test]
    fn g_is_the_derivative_of_alpha() {
        let v = LeverVsa::paper_b();
        for &d in &[0.0, 0.005, 0.012, 0.018] {
            for &phi in &[-0.3, -0.1, 0.0, 0.02, 0.15, 0.3] {
                let fd = central(|x| v.alpha(x, d), phi);
                let g = v.g(phi, d);
                assert!(
                    (fd - g).abs() < 1e-6 * (1.0 + g.abs()),
                    "d={d} phi={phi}: {fd} vs {g}"
                );
            }
        }
    }

    #[test]
    fn dg_dphi_matches_finite_difference() {
        let v = LeverVsa::paper_b();
        for &d in &[0.0, 0.009, 0.018] {
            for &phi in &[-0.2, -0.05, 0.07, 0.2] {
                let fd = central(|x| v.g(x, d), phi);
                let an = v.dg_dphi(phi, d);
                assert!((fd - an).abs() < 1e-5 * (1.0 + an.abs()), "{fd} vs {an}");
            }
        }
    }

    #[test]
    fn torque_is_the_gradient_of_the_spring_energy() {
        // U(φ) = ½·k_α·α(φ)²  ⇒  τ = dU/dφ = k_α·α·G.
        let v = LeverVsa::paper_b();
        for &d in &[0.0, 0.018] {
            for &phi in &[-0.25, 0.01, 0.25] {
                let fd = central(|x| 0.5 * v.k_alpha * v.alpha(x, d).powi(2), phi);
                assert!((fd - v.torque(phi, d)).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn exact_stiffness_is_dtau_dphi_and_differs_from_eq2_away_from_rest() {
        let v = LeverVsa::paper_b();
        let d = 0.012;
        for &phi in &[-0.2, 0.1, 0.2] {
            let fd = central(|x| v.torque(x, d), phi);
            let ex = v.stiffness_exact(phi, d);
            assert!((fd - ex).abs() < 1e-5 * ex.abs(), "{fd} vs {ex}");
        }
        // At rest α = 0, so the dropped term vanishes.
        assert!((v.stiffness_exact(0.0, d) - v.stiffness(0.0, d)).abs() < 1e-12);
        assert!((v.stiffness_exact(0.2, d) - v.stiffness(0.2, d)).abs() > 1e-3);
    }

    #[test]
    fn rest_values_match_closed_forms() {
        let v = LeverVsa::paper_b();
        for &d in &[0.0, 0.007, 0.018] {
            let da = v.d0 + d;
            assert!(v.alpha(0.0, d).abs() < 1e-15);
            assert!((v.ell(0.0, d) - (v.p - da)).abs() < 1e-15);
            assert!((v.g(0.0, d) - da / (v.p - da)).abs() < 1e-12);
            assert!((v.stiffness(0.0, d) - v.stiffness_at_rest(d)).abs() < 1e-12);
        }
    }

    #[test]
    fn reproduces_paper_b_stiffness_range() {
        // Paper B measured K_A_min = [0.258, 0.175, 0.258, 0.183] and
        // K_A_max = [50, 50, 60, 50] N·m/rad; MODEL.md: p ≈ 31.5 mm gives ≈ 0.25 and 50–65.
        let v = LeverVsa::paper_b();
        let (k_min, k_max) = v.stiffness_range();
        assert!((k_min - 0.2506).abs() < 0.002, "k_min = {k_min}");
        assert!((50.0..=66.0).contains(&k_max), "k_max = {k_max}");
        // k_α from the datasheet: 978.8 N·mm at 43°.
        assert!((v.k_alpha - 1.3042).abs() < 1e-3);
    }

    #[test]
    fn inverse_round_trips_and_refuses_out_of_range() {
        let v = LeverVsa::paper_b();
        for &d in &[0.0, 0.001, 0.0093, 0.018] {
            let k = v.stiffness_at_rest(d);
            let back = v.pivot_for_stiffness(k).unwrap();
            assert!((back - d).abs() < 1e-12, "{d} -> {k} -> {back}");
        }
        let (k_min, k_max) = v.stiffness_range();
        assert!(matches!(
            v.pivot_for_stiffness(k_max * 1.01),
            Err(LeverError::StiffnessOutOfRange { .. })
        ));
        assert!(v.pivot_for_stiffness(k_min * 0.99).is_err());
        assert!(v.pivot_for_stiffness(f64::NAN).is_err());
        assert!(v.pivot_for_stiffness(-1.0).is_err());
    }

    #[test]
    fn deflection_limit_is_the_spring_limit_or_the_dead_point() {
        let v = LeverVsa::paper_b();
        // Stiff end: the 43° spring limit comes first.
        let d = 0.018;
        let lim = v.deflection_limit(d);
        assert!(lim < v.dead_point(d));
        assert!((v.alpha(lim, d) - v.alpha_max).abs() < 1e-9);
        assert!(v.spring_within_limit(0.99 * lim, d));
        assert!(!v.spring_within_limit(1.01 * lim, d));
        // Soft end: α never reaches 43° (its maximum is ≈ 17.7°); the dead point limits.
        let d = 0.0;
        let lim = v.deflection_limit(d);
        assert!((lim - (v.d0 / v.p).acos()).abs() < 1e-12);
        assert!(v.g(lim, d).abs() < 1e-12);
        assert!(v.alpha(lim, d) < v.alpha_max);
    }

    #[test]
    fn validation_rejects_pivot_beyond_lever_axis() {
        let mut v = LeverVsa::paper_b();
        v.d_max = 0.025;
        assert!(v.validate().is_err());
        let mut v = LeverVsa::paper_b();
        v.p = f64::NAN;
        assert!(v.validate().is_err());
    }
}
