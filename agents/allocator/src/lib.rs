//! # rig-allocator — the allocator host
//!
//! [`plan::allocate`] is the whole computation of one allocation (pose → S → bounded least
//! squares → pivots), shared by `rig allocate` and the host; [`core::AllocatorCore`] keeps the
//! goal and re-allocates as the pose changes; [`edge::run`] moves bytes over Zenoh.

pub mod core;
pub mod edge;
pub mod plan;
