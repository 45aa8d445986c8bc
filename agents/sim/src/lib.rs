//! # rig-sim — the rig's stand-in for hardware
//!
//! Fixed-step, deterministic for a seed:
//! - [`lever_joint`]: paper B's lever VSA — exact lever kinematics, Bouc-Wen hysteresis in the
//!   spring, the 43° hard stop, a rate-limited pivot servo;
//! - [`awas_plant`]: paper A's AWAS — link, position motor, stiffness motor, RK4;
//! - [`planar_rig`]: paper B's serial and parallel robots pushed along guide lines;
//! - [`world`]: the world of a running simulated rig, shared by its agents;
//! - [`effects`]: effects a scenario switches on without telling the estimator;
//! - [`noise`]: seeded noise, quantisation, delay, backlash;
//! - [`scenario`]: scenarios as TOML files, run into a sensor stream;
//! - [`reproduce`]: the papers' experiments, estimators fed with sensor data only.

pub mod awas_plant;
pub mod effects;
pub mod lever_joint;
pub mod noise;
pub mod planar_rig;
pub mod reproduce;
pub mod scenario;
pub mod world;
