//! Planar robots with VSA joints (paper B §4, MODEL.md §3).
//!
//! Two robots share one interface, [`PlanarRobot`]:
//! - the serial 2-link arm (chain 1: θ1, θ2);
//! - the redundantly actuated five-bar (chain 1 plus chain 2: θ3, θ4 active, θ5 passive,
//!   base offset Lb), closing on the same end-effector point and orientation.
//!
//! Both reduce to one matrix, `G_u^A` (n_actuated × 2): actuated-joint rates from
//! end-effector rates, θ̇_A = G_u^A·u̇. From it, by virtual work and for small loads:
//!
//! ```text
//! F    = (G_u^A)ᵀ·τ_A                 end-effector force from joint torques (eqs. 17, 22)
//! K_uu = (G_u^A)ᵀ·diag(k_A)·G_u^A     operational stiffness (eqs. 24, 27)
//! (k_xx, k_xy, k_yy)ᵀ = S·k_A         column i of S: (g_i1², g_i1·g_i2, g_i2²)   (eq. 29)
//! ```
//!
//! Joint angles are output-link angles (motor angle plus deflection), in radians.

pub mod five_bar;
pub mod serial;

use nalgebra::{DMatrix, Matrix2, Vector2};
use thiserror::Error;

pub use five_bar::{FiveBar, FiveBarGeometry};
pub use serial::{SerialArm, two_link_ik};

/// Errors of the kinematics.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum KinematicsError {
    #[error("invalid geometry: {0}")]
    Geometry(String),
    #[error("the point ({x_m:.4}, {y_m:.4}) m is out of reach of {chain} ({why})")]
    Unreachable {
        chain: &'static str,
        x_m: f64,
        y_m: f64,
        why: String,
    },
    #[error("the pose is at or too near a singularity of {0}: its Jacobian cannot be inverted")]
    Singular(&'static str),
    #[error("expected {expected} joint values, got {got}")]
    Dimension { expected: usize, got: usize },
    #[error("non-finite input: {0}")]
    NonFinite(&'static str),
}

/// Which way an elbow bends: the sign of the elbow joint angle (θ2 for chain 1, θ4 for chain 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Elbow {
    Positive,
    Negative,
}

impl Elbow {
    /// +1 or −1.
    pub fn sign(self) -> f64 {
        match self {
            Elbow::Positive => 1.0,
            Elbow::Negative => -1.0,
        }
    }
}

/// End-effector pose (x, y) [m] and orientation Φ [rad].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    pub phi: f64,
}

/// A solved configuration of a robot.
#[derive(Debug, Clone, PartialEq)]
pub struct Configuration {
    /// All joint angles, θ1… (2 for the serial arm, 5 for the five-bar) [rad].
    pub theta: Vec<f64>,
    /// End-effector pose.
    pub pose: Pose,
    /// G_u^A: actuated-joint rates from (ẋ, ẏ), n_actuated × 2.
    pub g_u_a: DMatrix<f64>,
}

/// A planar robot of the rig.
#[derive(Debug, Clone, PartialEq)]
pub enum PlanarRobot {
    Serial(SerialArm),
    FiveBar(FiveBar),
}

impl PlanarRobot {
    /// Number of actuated (VSA) joints.
    pub fn actuated(&self) -> usize {
        match self {
            PlanarRobot::Serial(_) => 2,
            PlanarRobot::FiveBar(_) => 4,
        }
    }

    /// The configuration that puts the end effector at (x, y) [m].
    pub fn at_position(&self, x: f64, y: f64) -> Result<Configuration, KinematicsError> {
        if !(x.is_finite() && y.is_finite()) {
            return Err(KinematicsError::NonFinite("end-effector position"));
        }
        match self {
            PlanarRobot::Serial(r) => r.at_position(x, y),
            PlanarRobot::FiveBar(r) => r.at_position(x, y),
        }
    }

    /// The robot drawn as polylines [m], one per chain from its base to the end effector
    /// through every joint (serial: base, elbow, end effector; five-bar: chain 1 as the
    /// serial arm, chain 2 from (Lb, 0) through joints 4 and 5).
    pub fn chains(&self, c: &Configuration) -> Vec<Vec<(f64, f64)>> {
        let ee = (c.pose.x, c.pose.y);
        let t = &c.theta;
        match self {
            PlanarRobot::Serial(r) => {
                let elbow = (r.l1 * t[0].cos(), r.l1 * t[0].sin());
                vec![vec![(0.0, 0.0), elbow, ee]]
            }
            PlanarRobot::FiveBar(r) => {
                let g = &r.geometry;
                let elbow1 = (g.l1 * t[0].cos(), g.l1 * t[0].sin());
                let elbow2 = (g.lb + g.l3 * t[2].cos(), g.l3 * t[2].sin());
                let wrist = (
                    elbow2.0 + g.l4 * (t[2] + t[3]).cos(),
                    elbow2.1 + g.l4 * (t[2] + t[3]).sin(),
                );
                vec![
                    vec![(0.0, 0.0), elbow1, ee],
                    vec![(g.lb, 0.0), elbow2, wrist, ee],
                ]
            }
        }
    }

    /// The configuration for the independent joints θ_a = (θ1, θ2) [rad] (loop closure
    /// solves the dependent ones for the five-bar).
    pub fn from_independent(
        &self,
        theta1: f64,
        theta2: f64,
    ) -> Result<Configuration, KinematicsError> {
        if !(theta1.is_finite() && theta2.is_finite()) {
            return Err(KinematicsError::NonFinite("joint angles"));
        }
        match self {
            PlanarRobot::Serial(r) => r.configuration(theta1, theta2),
            PlanarRobot::FiveBar(r) => r.close_loop(theta1, theta2),
        }
    }
}

/// End-effector force from actuated-joint torques, F = (G_u^A)ᵀ·τ_A [N].
pub fn end_effector_force(
    g_u_a: &DMatrix<f64>,
    tau: &[f64],
) -> Result<Vector2<f64>, KinematicsError> {
    check_len(g_u_a, tau.len())?;
    if tau.iter().any(|t| !t.is_finite()) {
        return Err(KinematicsError::NonFinite("joint torques"));
    }
    let mut f = Vector2::zeros();
    for (i, t) in tau.iter().enumerate() {
        f[0] += g_u_a[(i, 0)] * t;
        f[1] += g_u_a[(i, 1)] * t;
    }
    Ok(f)
}

/// Operational stiffness K_uu = (G_u^A)ᵀ·diag(k)·G_u^A [N/m].
pub fn operational_stiffness(
    g_u_a: &DMatrix<f64>,
    k: &[f64],
) -> Result<Matrix2<f64>, KinematicsError> {
    check_len(g_u_a, k.len())?;
    let mut m = Matrix2::zeros();
    for (i, ki) in k.iter().enumerate() {
        let g = Vector2::new(g_u_a[(i, 0)], g_u_a[(i, 1)]);
        m += *ki * g * g.transpose();
    }
    Ok(m)
}

/// The S matrix (3 × n): (k_xx, k_xy, k_yy)ᵀ = S·k_A.
pub fn s_matrix(g_u_a: &DMatrix<f64>) -> DMatrix<f64> {
    let n = g_u_a.nrows();
    DMatrix::from_fn(3, n, |r, i| {
        let (a, b) = (g_u_a[(i, 0)], g_u_a[(i, 1)]);
        match r {
            0 => a * a,
            1 => a * b,
            _ => b * b,
        }
    })
}

fn check_len(g: &DMatrix<f64>, n: usize) -> Result<(), KinematicsError> {
    if g.nrows() != n {
        return Err(KinematicsError::Dimension {
            expected: g.nrows(),
            got: n,
        });
    }
    Ok(())
}

/// Wraps an angle to (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    let w = a.rem_euclid(two_pi);
    if w > std::f64::consts::PI {
        w - two_pi
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn five_bar() -> PlanarRobot {
        PlanarRobot::FiveBar(FiveBar::example())
    }

    fn serial() -> PlanarRobot {
        PlanarRobot::Serial(SerialArm::new(0.15, 0.15, Elbow::Negative).unwrap())
    }

    /// Finite-difference G_u^A: move the end effector and re-solve the configuration.
    fn g_fd(robot: &PlanarRobot, x: f64, y: f64) -> DMatrix<f64> {
        let n = robot.actuated();
        let h = 1e-7;
        let mut g = DMatrix::zeros(n, 2);
        for (col, (dx, dy)) in [(h, 0.0), (0.0, h)].into_iter().enumerate() {
            let p = robot.at_position(x + dx, y + dy).unwrap();
            let m = robot.at_position(x - dx, y - dy).unwrap();
            for i in 0..n {
                g[(i, col)] = wrap_angle(p.theta[i] - m.theta[i]) / (2.0 * h);
            }
        }
        g
    }

    #[test]
    fn g_u_a_matches_finite_differences_for_both_robots() {
        for robot in [serial(), five_bar()] {
            for &(x, y) in &[(0.075, 0.2), (0.12, 0.17), (0.03, 0.22)] {
                let c = robot.at_position(x, y).unwrap();
                let fd = g_fd(&robot, x, y);
                let err = (&c.g_u_a - &fd).abs().max();
                assert!(
                    err < 1e-5 * c.g_u_a.abs().max(),
                    "({x},{y}): err {err}\n{}\n{}",
                    c.g_u_a,
                    fd
                );
            }
        }
    }

    #[test]
    fn force_satisfies_virtual_work_against_finite_differences() {
        // F·δu = τ_A·δθ_A for a small end-effector displacement, with δθ_A from re-solving.
        let robot = five_bar();
        let (x, y) = (0.075, 0.2);
        let c = robot.at_position(x, y).unwrap();
        let tau = [0.3, -0.2, 0.5, 0.1];
        let f = end_effector_force(&c.g_u_a, &tau).unwrap();
        let fd = g_fd(&robot, x, y);
        for col in 0..2 {
            let work_rate: f64 = (0..4).map(|i| tau[i] * fd[(i, col)]).sum();
            assert!(
                (work_rate - f[col]).abs() < 1e-5 * f.norm(),
                "{work_rate} vs {}",
                f[col]
            );
        }
    }

    #[test]
    fn serial_force_is_the_inverse_transpose_of_the_jacobian() {
        // τ = Jᵀ·F for the classic position Jacobian J (rows x, y).
        let arm = SerialArm::new(0.15, 0.15, Elbow::Negative).unwrap();
        let (t1, t2) = (0.9, -1.1);
        let c = arm.configuration(t1, t2).unwrap();
        let j = arm.jacobian(t1, t2);
        let f_true = Vector2::new(1.5, -0.7);
        let tau = [
            j[(0, 0)] * f_true[0] + j[(1, 0)] * f_true[1],
            j[(0, 1)] * f_true[0] + j[(1, 1)] * f_true[1],
        ];
        let f = end_effector_force(&c.g_u_a, &tau).unwrap();
        assert!((f - f_true).norm() < 1e-12);
    }

    #[test]
    fn operational_stiffness_matches_finite_difference_of_spring_forces() {
        // Joint springs at rest at u0: τ_i = k_i·Δθ_i(u). Then K_uu = ∂F/∂u at u0 (no preload,
        // so the geometric term vanishes).
        let robot = five_bar();
        let (x, y) = (0.075, 0.2);
        let c0 = robot.at_position(x, y).unwrap();
        let k = [5.0, 12.0, 30.0, 2.0];
        let kuu = operational_stiffness(&c0.g_u_a, &k).unwrap();
        let h = 1e-6;
        for (col, (dx, dy)) in [(h, 0.0), (0.0, h)].into_iter().enumerate() {
            let force_at = |sx: f64| {
                let c = robot.at_position(x + sx * dx, y + sx * dy).unwrap();
                let tau: Vec<f64> = (0..4)
                    .map(|i| k[i] * wrap_angle(c.theta[i] - c0.theta[i]))
                    .collect();
                end_effector_force(&c.g_u_a, &tau).unwrap()
            };
            let dfdu = (force_at(1.0) - force_at(-1.0)) / (2.0 * h);
            for row in 0..2 {
                assert!(
                    (dfdu[row] - kuu[(row, col)]).abs() < 1e-4 * kuu.abs().max(),
                    "{dfdu} vs {kuu}"
                );
            }
        }
    }

    #[test]
    fn s_matrix_maps_joint_to_operational_stiffness() {
        let robot = five_bar();
        let c = robot.at_position(0.1, 0.18).unwrap();
        let s = s_matrix(&c.g_u_a);
        let k = [0.258, 0.175, 50.0, 12.0];
        let kuu = operational_stiffness(&c.g_u_a, &k).unwrap();
        let v = &s * nalgebra::DVector::from_row_slice(&k);
        assert!((v[0] - kuu[(0, 0)]).abs() < 1e-9 * kuu.abs().max());
        assert!((v[1] - kuu[(0, 1)]).abs() < 1e-9 * kuu.abs().max());
        assert!((v[2] - kuu[(1, 1)]).abs() < 1e-9 * kuu.abs().max());
        assert!((kuu[(0, 1)] - kuu[(1, 0)]).abs() < 1e-12);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let robot = five_bar();
        let c = robot.at_position(0.075, 0.2).unwrap();
        assert!(matches!(
            end_effector_force(&c.g_u_a, &[1.0, 2.0]),
            Err(KinematicsError::Dimension { .. })
        ));
        assert!(end_effector_force(&c.g_u_a, &[1.0, f64::NAN, 0.0, 0.0]).is_err());
        assert!(robot.at_position(f64::NAN, 0.1).is_err());
        assert!(matches!(
            robot.at_position(1.0, 1.0),
            Err(KinematicsError::Unreachable { .. })
        ));
        assert!(wrap_angle(3.0 * std::f64::consts::PI) - std::f64::consts::PI < 1e-12);
    }

    #[test]
    fn chains_end_at_the_end_effector_with_link_lengths() {
        let robot = PlanarRobot::FiveBar(FiveBar::example());
        let c = robot.at_position(0.075, 0.2).unwrap();
        let chains = robot.chains(&c);
        let g = FiveBar::example().geometry;
        let len = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).hypot(a.1 - b.1);
        assert_eq!(chains.len(), 2);
        for ch in &chains {
            let last = ch[ch.len() - 1];
            assert!(len(last, (0.075, 0.2)) < 1e-12);
        }
        let (c1, c2) = (&chains[0], &chains[1]);
        assert!((len(c1[0], c1[1]) - g.l1).abs() < 1e-12);
        assert!(
            (len(c1[1], c1[2]) - g.l2).abs() < 1e-9,
            "loop closure puts chain 1 on the pose"
        );
        assert!((len(c2[0], c2[1]) - g.l3).abs() < 1e-12);
        assert!((len(c2[1], c2[2]) - g.l4).abs() < 1e-12);
        assert!((len(c2[2], c2[3]) - g.l5).abs() < 1e-9);
    }
}
