//! # rig-dynamixel — the Dynamixel side of the joint agent
//!
//! Work in progress for the hardware issue: so far the device side of Dynamixel protocol 2.0
//! ([`protocol2`]), both sides of protocol 1.0 ([`protocol1`], for the AX-12A), the control tables of the servos paper B's rig uses ([`models`]), and
//! virtual servos that answer on one end of a pseudo-terminal pair while the real client
//! library (dynamixel2) talks to the other ([`virtual_bus`]), with fault injection.

pub mod models;
pub mod protocol1;
pub mod protocol2;
pub mod scan;
pub mod virtual_bus;
