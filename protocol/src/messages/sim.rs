//! What only a simulated joint agent knows: the truth its estimates are scored against.

use super::Message;
use crate::codec::{DecodeError, Reader, Writer};
use crate::kind::Kind;
use crate::validation::{Check, MAX_TORQUE_NM, ValidationError};

/// What the simulator knows and no sensor reads: published by simulated joint agents only,
/// so that tests and summaries can score estimates against the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct SimTruth {
    pub joint: u16,
    /// Sequence number and acquisition time of the sample this truth belongs to.
    pub seq: u64,
    pub t_acq_ns: u64,
    /// True (unquantised, unbiased) deflection [rad].
    pub deflection_rad: f64,
    /// True joint torque [N·m].
    pub torque_nm: f64,
    /// True link angle [rad].
    pub link_rad: f64,
    /// True joint stiffness ∂τ/∂φ of the simulated spring at the true pivot (elastic part,
    /// at rest deflection for a lever joint) [N·m/rad].
    pub stiffness_nm_per_rad: f64,
}

impl Message for SimTruth {
    const KIND: Kind = Kind::SimTruth;

    fn validate(&self) -> Result<(), ValidationError> {
        let c = Check("sim_truth");
        c.time("t_acq_ns", self.t_acq_ns)?;
        c.within(
            "deflection_rad",
            self.deflection_rad,
            -std::f64::consts::PI,
            std::f64::consts::PI,
        )?;
        c.within("torque_nm", self.torque_nm, -MAX_TORQUE_NM, MAX_TORQUE_NM)?;
        c.within("link_rad", self.link_rad, -1e6, 1e6)?;
        c.within("stiffness_nm_per_rad", self.stiffness_nm_per_rad, 0.0, 1e7)
    }

    fn write_body(&self, w: &mut Writer) {
        w.u16(self.joint);
        w.u64(self.seq);
        w.u64(self.t_acq_ns);
        w.f64(self.deflection_rad);
        w.f64(self.torque_nm);
        w.f64(self.link_rad);
        w.f64(self.stiffness_nm_per_rad);
    }

    fn read_body(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        Ok(Self {
            joint: r.u16("joint")?,
            seq: r.u64("seq")?,
            t_acq_ns: r.u64("t_acq_ns")?,
            deflection_rad: r.f64("deflection_rad")?,
            torque_nm: r.f64("torque_nm")?,
            link_rad: r.f64("link_rad")?,
            stiffness_nm_per_rad: r.f64("stiffness_nm_per_rad")?,
        })
    }
}
