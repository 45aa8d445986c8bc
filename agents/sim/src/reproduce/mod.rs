//! The papers' experiments in simulation, with the estimators fed sensor data only.
//!
//! - [`paper_a`]: the decoupled impedance observer on AWAS (paper A §IV);
//! - [`paper_b`]: the restoring-torque model, force estimation and decoupled allocation
//!   (paper B §3, §5).
//!
//! Both are plain functions returning serialisable reports; `rig reproduce` prints them.

pub mod paper_a;
pub mod paper_b;

use thiserror::Error;

/// Reports progress: (stage, done, total).
pub type Progress<'a> = dyn FnMut(&str, u64, u64) + 'a;

/// Errors of a reproduction.
#[derive(Debug, Error)]
pub enum ReproduceError {
    #[error("config: {0}")]
    Config(String),
    #[error("kinematics: {0}")]
    Kinematics(#[from] rig_model::planar::KinematicsError),
    #[error("restoring-torque fit: {0}")]
    Fit(#[from] rig_model::hysteresis::FitError),
    #[error("estimator: {0}")]
    Estimate(#[from] rig_model::estimator::EstimateError),
    #[error("allocation: {0}")]
    Allocation(#[from] rig_model::allocation::AllocationError),
    #[error("lever: {0}")]
    Lever(#[from] rig_model::lever::LeverError),
    #[error("simulated spring: {0}")]
    Spring(#[from] rig_model::hysteresis::BoucWenError),
    #[error("observer: {0}")]
    Observer(#[from] rig_model::observer::ObserverError),
}
