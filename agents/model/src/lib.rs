//! # rig-model — the pure maths of the VSA rig
//!
//! No I/O, no async, no clocks: every part is a plain struct or function that any host,
//! test or benchmark can drive sample by sample. SI units throughout (m, rad, N, N·m, s).
//! The equations are those of `shared/MODEL.md`; each module names its section.
//!
//! | module | what | source |
//! |---|---|---|
//! | [`lever`] | lever VSA kinematics, torque, stiffness, pivot for a stiffness | paper B §2 |
//! | [`hysteresis`] | Bouc-Wen, the restoring-torque model, its fit | paper B §3 |
//! | [`awas`] | the AWAS joint of paper A | paper A eqs. 16–20 |
//! | [`observer`] | EKF for inertia/damping and the stiffness observer | paper A §III |
//! | [`planar`] | serial and five-bar kinematics, Jacobians, force, stiffness, S | paper B §4 |
//! | [`estimator`] | joint samples → torques, end-effector force, K_uu (sans I/O) | paper B §3–4 |
//! | [`allocation`] | bounded least squares for joint stiffnesses, tie-break, pivots | paper B §4.3 |
//! | [`identify`] | residual → missing effect → augmented model, on held-out data | MODEL.md §6 |
//! | [`monitor`] | the live residual monitor of a joint with a torque sensor | MODEL.md §6 |
//! | [`pchip`] | monotone C¹ interpolation (parameters smooth in d) | — |

pub mod allocation;
pub mod awas;
pub mod estimator;
pub mod hysteresis;
pub mod identify;
pub mod lever;
pub mod live;
pub mod monitor;
pub mod observer;
pub mod pchip;
pub mod planar;
