//! The serial 2-link arm (chain 1 of paper B, eqs. 8–10).
//!
//! ```text
//! x = L1·c1 + L2·c12,  y = L1·s1 + L2·s12,  Φ = θ1 + θ2
//! ```

use nalgebra::{DMatrix, Matrix2, Matrix3x2};

use super::{Configuration, Elbow, KinematicsError, Pose};

/// Inverse kinematics of a 2-link chain from its base: (θ_base, θ_elbow) reaching (x, y).
pub fn two_link_ik(
    l1: f64,
    l2: f64,
    x: f64,
    y: f64,
    elbow: Elbow,
    chain: &'static str,
) -> Result<(f64, f64), KinematicsError> {
    let r2 = x * x + y * y;
    let c2 = (r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
    if !(-1.0..=1.0).contains(&c2) {
        let why = format!(
            "distance {:.4} m from its base, reach is [{:.4}, {:.4}] m",
            r2.sqrt(),
            (l1 - l2).abs(),
            l1 + l2
        );
        return Err(KinematicsError::Unreachable {
            chain,
            x_m: x,
            y_m: y,
            why,
        });
    }
    let s2 = elbow.sign() * (1.0 - c2 * c2).sqrt();
    let t2 = s2.atan2(c2);
    let t1 = y.atan2(x) - (l2 * s2).atan2(l1 + l2 * c2);
    Ok((super::wrap_angle(t1), t2))
}

/// A serial 2-link arm with VSA joints θ1, θ2.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialArm {
    pub l1: f64,
    pub l2: f64,
    pub elbow: Elbow,
}

impl SerialArm {
    /// An arm with link lengths `l1`, `l2` [m]; `elbow` picks the inverse-kinematics branch.
    pub fn new(l1: f64, l2: f64, elbow: Elbow) -> Result<Self, KinematicsError> {
        if !(l1.is_finite() && l2.is_finite() && l1 > 0.0 && l2 > 0.0) {
            return Err(KinematicsError::Geometry(format!(
                "link lengths must be positive, got l1 = {l1}, l2 = {l2} m"
            )));
        }
        Ok(Self { l1, l2, elbow })
    }

    /// Forward kinematics.
    pub fn forward(&self, t1: f64, t2: f64) -> Pose {
        Pose {
            x: self.l1 * t1.cos() + self.l2 * (t1 + t2).cos(),
            y: self.l1 * t1.sin() + self.l2 * (t1 + t2).sin(),
            phi: t1 + t2,
        }
    }

    /// The Jacobian 1G (3×2) onto (ẋ, ẏ, Φ̇).
    pub fn jacobian(&self, t1: f64, t2: f64) -> Matrix3x2<f64> {
        let (s1, c1) = t1.sin_cos();
        let (s12, c12) = (t1 + t2).sin_cos();
        Matrix3x2::new(
            -self.l1 * s1 - self.l2 * s12,
            -self.l2 * s12,
            self.l1 * c1 + self.l2 * c12,
            self.l2 * c12,
            1.0,
            1.0,
        )
    }

    /// G_u^a = (rows x, y of 1G)⁻¹, or an error near a singularity (|sin θ2| tiny).
    pub fn g_u_a(&self, t1: f64, t2: f64) -> Result<Matrix2<f64>, KinematicsError> {
        let j = self.jacobian(t1, t2).fixed_rows::<2>(0).into_owned();
        if j.determinant().abs() < 1e-6 * self.l1 * self.l2 {
            return Err(KinematicsError::Singular("chain 1 (θ1, θ2)"));
        }
        j.try_inverse()
            .ok_or(KinematicsError::Singular("chain 1 (θ1, θ2)"))
    }

    /// The configuration at joint angles (θ1, θ2).
    pub fn configuration(&self, t1: f64, t2: f64) -> Result<Configuration, KinematicsError> {
        let g = self.g_u_a(t1, t2)?;
        Ok(Configuration {
            theta: vec![t1, t2],
            pose: self.forward(t1, t2),
            g_u_a: DMatrix::from_fn(2, 2, |r, c| g[(r, c)]),
        })
    }

    /// The configuration with the end effector at (x, y).
    pub fn at_position(&self, x: f64, y: f64) -> Result<Configuration, KinematicsError> {
        let (t1, t2) = two_link_ik(self.l1, self.l2, x, y, self.elbow, "chain 1 (links 1, 2)")?;
        self.configuration(t1, t2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ik_inverts_fk_on_both_branches() {
        for elbow in [Elbow::Positive, Elbow::Negative] {
            let arm = SerialArm::new(0.15, 0.12, elbow).unwrap();
            for &(x, y) in &[(0.1, 0.15), (0.2, 0.05), (-0.05, 0.2)] {
                let c = arm.at_position(x, y).unwrap();
                assert!((c.pose.x - x).abs() < 1e-12 && (c.pose.y - y).abs() < 1e-12);
                assert_eq!(c.theta[1].signum(), elbow.sign());
            }
        }
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let arm = SerialArm::new(0.15, 0.12, Elbow::Positive).unwrap();
        let (t1, t2) = (0.4, 1.2);
        let j = arm.jacobian(t1, t2);
        let h = 1e-7;
        for (col, (d1, d2)) in [(h, 0.0), (0.0, h)].into_iter().enumerate() {
            let p = arm.forward(t1 + d1, t2 + d2);
            let m = arm.forward(t1 - d1, t2 - d2);
            let fd = [
                (p.x - m.x) / (2.0 * h),
                (p.y - m.y) / (2.0 * h),
                (p.phi - m.phi) / (2.0 * h),
            ];
            for row in 0..3 {
                assert!((fd[row] - j[(row, col)]).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn singular_and_unreachable_poses_are_errors() {
        let arm = SerialArm::new(0.15, 0.15, Elbow::Positive).unwrap();
        assert!(matches!(
            arm.configuration(0.3, 0.0),
            Err(KinematicsError::Singular(_))
        ));
        assert!(matches!(
            arm.at_position(0.4, 0.0),
            Err(KinematicsError::Unreachable { .. })
        ));
        assert!(SerialArm::new(-0.1, 0.1, Elbow::Positive).is_err());
    }
}
