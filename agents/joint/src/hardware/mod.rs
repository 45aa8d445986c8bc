//! The `dynamixel` board: paper B's servos and deflection encoders.
//!
//! - [`plan`]: [`BoardPlan::from_config`], pure: everything the config can get wrong, checked
//!   without touching a port;
//! - [`dynamixel`]: [`DynamixelBoard::open`] of a plan, then the read cycle, goals, torque and
//!   the safe state — I/O only;
//! - [`pace`]: whether the configured rate fits the read cycle timed at start-up, pure.

pub mod dynamixel;
pub mod pace;
pub mod plan;

pub use dynamixel::{DynamixelBoard, HardwareError, WireLoad, wire_s_per_cycle};
pub use plan::{BoardPlan, Line, PlanError, PlannedJoint, PortOverrides, ServoMap};

impl From<PlanError> for crate::board::BoardError {
    fn from(e: PlanError) -> Self {
        Self::Device(Box::new(e))
    }
}

impl From<HardwareError> for crate::board::BoardError {
    fn from(e: HardwareError) -> Self {
        Self::Device(Box::new(e))
    }
}
