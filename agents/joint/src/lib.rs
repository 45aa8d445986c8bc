//! # rig-joint — the joint-board agent
//!
//! One per joint board. It reads the joint (backend `sim` today, `dynamixel` with the hardware
//! issue), publishes timestamped samples on `rig/<rig>/joint/<j>/sample`, and accepts commands
//! on `rig/<rig>/joint/<j>/command` only within its own limits ([`guard`]), reporting every
//! refusal, watchdog hold and stop on `rig/<rig>/joint/<j>/status`. Light on purpose: no
//! estimator, no viewer in its dependency tree.

pub mod agent;
pub mod backend;
pub mod guard;
