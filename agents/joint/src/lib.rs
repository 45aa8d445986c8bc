//! # rig-joint — the joint-board agent
//!
//! One per joint board. It reads the board's joints, publishes timestamped samples on
//! `rig/<rig>/joint/<j>/sample`, and accepts commands on `rig/<rig>/joint/<j>/command` only
//! within its own limits ([`guard`]), reporting every refusal, watchdog hold and stop on
//! `rig/<rig>/joint/<j>/status`. Light on purpose: no estimator, no viewer in its dependency
//! tree, and with `--no-default-features` no simulator either.
//!
//! - [`board`]: the [`board::JointBoard`] trait the agent drives, and the runner that keeps
//!   blocking I/O on a thread of its own;
//! - [`hardware`]: paper B's Dynamixel board — a pure plan from the config, then I/O;
//! - [`sim_board`] and [`virtual_board`] (feature `sim`, default): the simulated joints, and
//!   virtual servos and an encoder bridge on pseudo-terminals fed by them;
//! - [`agent`]: the Zenoh loop.

pub mod agent;
pub mod board;
pub mod guard;
pub mod hardware;
#[cfg(feature = "sim")]
pub mod sim_board;
#[cfg(feature = "sim")]
pub mod virtual_board;
