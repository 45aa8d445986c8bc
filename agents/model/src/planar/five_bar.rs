//! The redundantly actuated five-bar (paper B eqs. 11–23, MODEL.md §3).
//!
//! Chain 1 (θ1, θ2) from the origin; chain 2 (θ3, θ4 active, θ5 passive) from (Lb, 0):
//!
//! ```text
//! x = Lb + L3·c3 + L4·c34 + L5·c345,  y = L3·s3 + L4·s34 + L5·s345,  Φ = θ3 + θ4 + θ5
//! ```
//!
//! Both chains end on the same point with the same orientation. θ_a = (θ1, θ2) are the
//! independent joints; loop closure gives θ_p = (θ3, θ4, θ5) in closed form: chain 1 fixes
//! the pose, the wrist of chain 2 is the pose minus L5 along Φ, and a 2-link inverse solves
//! θ3, θ4.
//!
//! ```text
//! G_a^p  = 2G⁻¹·1G                 (3×2)   θ̇_p = G_a^p·θ̇_a
//! pG_a^A = [I₂; rows θ3, θ4 of G_a^p]  (4×2)
//! G_u^a  = (rows x, y of 1G)⁻¹     (2×2)
//! pG_u^A = pG_a^A·G_u^a            (4×2)   θ̇_A = pG_u^A·u̇
//! ```

use nalgebra::{DMatrix, Matrix3, Matrix3x2};

use super::serial::{SerialArm, two_link_ik};
use super::{Configuration, Elbow, KinematicsError, Pose, wrap_angle};

/// Link lengths and base offset of the five-bar [m].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FiveBarGeometry {
    pub l1: f64,
    pub l2: f64,
    pub l3: f64,
    pub l4: f64,
    /// From the passive joint 5 to the end effector, along the end-effector body (may be 0).
    pub l5: f64,
    /// Base offset of chain 2 along x.
    pub lb: f64,
}

/// The five-bar with its two inverse-kinematics branches.
#[derive(Debug, Clone, PartialEq)]
pub struct FiveBar {
    pub geometry: FiveBarGeometry,
    chain1: SerialArm,
    elbow2: Elbow,
}

impl FiveBar {
    /// The robot of `rig-config/examples/parallel.toml` (our choice; paper B gives no lengths):
    /// 150 mm links, the passive joint 50 mm behind the end effector, chain 2's base 150 mm to
    /// the right; θ2 negative, θ4 positive.
    pub fn example() -> Self {
        let geometry = FiveBarGeometry {
            l1: 0.15,
            l2: 0.15,
            l3: 0.15,
            l4: 0.15,
            l5: 0.05,
            lb: 0.15,
        };
        Self {
            geometry,
            chain1: SerialArm {
                l1: 0.15,
                l2: 0.15,
                elbow: Elbow::Negative,
            },
            elbow2: Elbow::Positive,
        }
    }

    /// `elbow1` is the sign of θ2, `elbow2` the sign of θ4.
    pub fn new(
        geometry: FiveBarGeometry,
        elbow1: Elbow,
        elbow2: Elbow,
    ) -> Result<Self, KinematicsError> {
        let g = geometry;
        let all = [g.l1, g.l2, g.l3, g.l4, g.l5, g.lb];
        if all.iter().any(|v| !v.is_finite())
            || [g.l1, g.l2, g.l3, g.l4].iter().any(|v| *v <= 0.0)
            || g.l5 < 0.0
        {
            return Err(KinematicsError::Geometry(
                "l1..l4 must be positive, l5 >= 0 and lb finite".into(),
            ));
        }
        Ok(Self {
            geometry,
            chain1: SerialArm::new(g.l1, g.l2, elbow1)?,
            elbow2,
        })
    }

    /// Forward kinematics of chain 2.
    pub fn chain2_forward(&self, t3: f64, t4: f64, t5: f64) -> Pose {
        let g = &self.geometry;
        Pose {
            x: g.lb + g.l3 * t3.cos() + g.l4 * (t3 + t4).cos() + g.l5 * (t3 + t4 + t5).cos(),
            y: g.l3 * t3.sin() + g.l4 * (t3 + t4).sin() + g.l5 * (t3 + t4 + t5).sin(),
            phi: t3 + t4 + t5,
        }
    }

    /// The Jacobian 2G (3×3) of chain 2 onto (ẋ, ẏ, Φ̇).
    pub fn chain2_jacobian(&self, t3: f64, t4: f64, t5: f64) -> Matrix3<f64> {
        let g = &self.geometry;
        let (s3, c3) = t3.sin_cos();
        let (s34, c34) = (t3 + t4).sin_cos();
        let (s345, c345) = (t3 + t4 + t5).sin_cos();
        #[rustfmt::skip]
        let m = Matrix3::new(
            -g.l3 * s3 - g.l4 * s34 - g.l5 * s345, -g.l4 * s34 - g.l5 * s345, -g.l5 * s345,
            g.l3 * c3 + g.l4 * c34 + g.l5 * c345,  g.l4 * c34 + g.l5 * c345,  g.l5 * c345,
            1.0, 1.0, 1.0,
        );
        m
    }

    /// The Jacobian 1G (3×2) of chain 1.
    pub fn chain1_jacobian(&self, t1: f64, t2: f64) -> Matrix3x2<f64> {
        self.chain1.jacobian(t1, t2)
    }

    /// G_a^p = 2G⁻¹·1G (3×2) at a closed configuration θ = (θ1..θ5).
    pub fn g_a_p(&self, theta: &[f64; 5]) -> Result<Matrix3x2<f64>, KinematicsError> {
        let j2 = self.chain2_jacobian(theta[2], theta[3], theta[4]);
        // |det 2G| = L3·L4·|sin θ4|: chain 2 stretched or folded.
        if j2.determinant().abs() < 1e-6 * self.geometry.l3 * self.geometry.l4 {
            return Err(KinematicsError::Singular("chain 2 (θ3, θ4, θ5)"));
        }
        let inv = j2
            .try_inverse()
            .ok_or(KinematicsError::Singular("chain 2 (θ3, θ4, θ5)"))?;
        Ok(inv * self.chain1_jacobian(theta[0], theta[1]))
    }

    /// Loop closure: the full configuration from the independent joints (θ1, θ2).
    pub fn close_loop(&self, t1: f64, t2: f64) -> Result<Configuration, KinematicsError> {
        let g = &self.geometry;
        let pose = self.chain1.forward(t1, t2);
        let wx = pose.x - g.l5 * pose.phi.cos() - g.lb;
        let wy = pose.y - g.l5 * pose.phi.sin();
        let (t3, t4) = two_link_ik(g.l3, g.l4, wx, wy, self.elbow2, "chain 2 (links 3, 4)")?;
        let t5 = wrap_angle(pose.phi - t3 - t4);
        let theta = [t1, t2, t3, t4, t5];
        let gap = self.g_a_p(&theta)?;
        let gua = self.chain1.g_u_a(t1, t2)?;
        // pG_a^A = [I₂; rows θ3, θ4 of G_a^p], then pG_u^A = pG_a^A·G_u^a.
        let pga = DMatrix::from_fn(4, 2, |r, c| match r {
            0 | 1 => f64::from(u8::from(r == c)),
            _ => gap[(r - 2, c)],
        });
        let g_u_a = pga * DMatrix::from_fn(2, 2, |r, c| gua[(r, c)]);
        Ok(Configuration {
            theta: theta.to_vec(),
            pose,
            g_u_a,
        })
    }

    /// The configuration with the end effector at (x, y) [m].
    pub fn at_position(&self, x: f64, y: f64) -> Result<Configuration, KinematicsError> {
        let (t1, t2) = two_link_ik(
            self.geometry.l1,
            self.geometry.l2,
            x,
            y,
            self.chain1.elbow,
            "chain 1 (links 1, 2)",
        )?;
        self.close_loop(t1, t2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robot() -> FiveBar {
        FiveBar::example()
    }

    #[test]
    fn loop_closes_on_the_same_pose() {
        let r = robot();
        for &(t1, t2) in &[(1.2, -0.9), (1.0, -1.3), (1.5, -0.6)] {
            let c = r.close_loop(t1, t2).unwrap();
            let p2 = r.chain2_forward(c.theta[2], c.theta[3], c.theta[4]);
            assert!((p2.x - c.pose.x).abs() < 1e-12 && (p2.y - c.pose.y).abs() < 1e-12);
            assert!(wrap_angle(p2.phi - c.pose.phi).abs() < 1e-12);
        }
    }

    #[test]
    fn chain2_jacobian_matches_finite_differences() {
        let r = robot();
        let t = [0.8, 1.1, -0.7];
        let j = r.chain2_jacobian(t[0], t[1], t[2]);
        let h = 1e-7;
        for col in 0..3 {
            let mut p = t;
            let mut m = t;
            p[col] += h;
            m[col] -= h;
            let (a, b) = (
                r.chain2_forward(p[0], p[1], p[2]),
                r.chain2_forward(m[0], m[1], m[2]),
            );
            let fd = [
                (a.x - b.x) / (2.0 * h),
                (a.y - b.y) / (2.0 * h),
                (a.phi - b.phi) / (2.0 * h),
            ];
            for row in 0..3 {
                assert!((fd[row] - j[(row, col)]).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn g_a_p_matches_finite_differences_of_loop_closure() {
        let r = robot();
        let (t1, t2) = (1.2, -0.9);
        let c = r.close_loop(t1, t2).unwrap();
        let theta: [f64; 5] = c.theta.clone().try_into().unwrap();
        let gap = r.g_a_p(&theta).unwrap();
        let h = 1e-7;
        for (col, (d1, d2)) in [(h, 0.0), (0.0, h)].into_iter().enumerate() {
            let p = r.close_loop(t1 + d1, t2 + d2).unwrap();
            let m = r.close_loop(t1 - d1, t2 - d2).unwrap();
            for row in 0..3 {
                let fd = wrap_angle(p.theta[row + 2] - m.theta[row + 2]) / (2.0 * h);
                assert!(
                    (fd - gap[(row, col)]).abs() < 1e-6,
                    "row {row} col {col}: {fd} vs {}",
                    gap[(row, col)]
                );
            }
        }
    }

    #[test]
    fn rejects_bad_geometry() {
        let g = FiveBarGeometry {
            l1: 0.15,
            l2: 0.15,
            l3: -0.15,
            l4: 0.15,
            l5: 0.05,
            lb: 0.15,
        };
        assert!(FiveBar::new(g, Elbow::Negative, Elbow::Positive).is_err());
    }
}
