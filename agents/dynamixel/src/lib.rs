//! # rig-dynamixel — the Dynamixel side of the joint agent
//!
//! What the joint agent's `dynamixel` backend (rig-joint's `hardware` module) stands on:
//! - [`protocol2`]: the device side of Dynamixel protocol 2.0 (the client is dynamixel2);
//! - [`protocol1`]: both sides of protocol 1.0, which paper B's AX-12A pivot servos speak;
//! - [`encoder`]: the deflection encoders through a serial bridge (the frames the bridge's
//!   firmware speaks), and a virtual bridge;
//! - [`models`]: the control tables of the servos paper B's rig uses;
//! - [`servos`]: one bus with servos of both protocols, bounded retries, errors naming the
//!   bus and the servo;
//! - [`scan`]: what answers on a bus (`rig scan`);
//! - [`timing`]: bytes on the wire per transfer, the theoretical limit of a bus cycle;
//! - [`virtual_bus`]: virtual servos on one end of a pseudo-terminal pair, the real client
//!   libraries on the other, with injected faults;
//! - [`pty`]: the pseudo-terminal device those virtual parts (servos, encoder bridge) run on.

pub mod encoder;
mod line;
pub mod models;
pub mod protocol1;
pub mod protocol2;
pub mod pty;
pub mod scan;
pub mod servos;
pub mod timing;
pub mod virtual_bus;
