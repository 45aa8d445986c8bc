//! # rig-estimator — the estimator host
//!
//! [`core::EstimatorCore`] is a plain struct fed with samples (the same maths `rig reproduce`
//! uses); [`edge::run`] only moves bytes between it and Zenoh.

pub mod clock;
pub mod core;
pub mod edge;
pub mod histogram;
