//! # rig-joint — the joint-board agent
//!
//! One per joint board. It reads the joint (backend `sim`, or `dynamixel`: the servos and the
//! deflection encoders of paper B's board, [`hardware`]; [`virtual_board`] stands in for that
//! hardware on pseudo-terminals), publishes timestamped samples on `rig/<rig>/joint/<j>/sample`, and accepts commands
//! on `rig/<rig>/joint/<j>/command` only within its own limits ([`guard`]), reporting every
//! refusal, watchdog hold and stop on `rig/<rig>/joint/<j>/status`. Light on purpose: no
//! estimator, no viewer in its dependency tree.

pub mod agent;
pub mod backend;
pub mod guard;
pub mod hardware;
pub mod virtual_board;
