//! Hysteresis of the VSA joint (paper B §3, MODEL.md §2).
//!
//! - [`bouc_wen`]: the rate-dependent reference, used by the simulator as the "true" joint;
//! - [`restoring`]: paper B's model driven by deflection alone, used by the estimator;
//! - [`fit`]: fitting the latter to measured (φ, τ, d) data.

pub mod bouc_wen;
pub mod fit;
pub mod restoring;

pub use bouc_wen::{BoucWen, BoucWenError, BoucWenParams};
pub use fit::{
    FitError, FitOptions, FitSample, GroupFit, RestoringFit, fit_restoring, fit_restoring_beside,
    replay_curve,
};
pub use restoring::{
    AS5048A_COUNT_RAD, Envelope, RestoringCurve, RestoringParams, RestoringTorqueModel, Reversal,
    ReversalDetector, Segment,
};
