//! Messages from the estimator host: each joint's estimate and the end effector's.

use super::{Message, StiffnessTriple, check_flags, flag, flags_of};
use crate::codec::{DecodeError, Reader, Writer};
use crate::kind::Kind;
use crate::validation::{Check, MAX_TORQUE_NM, ValidationError};

/// The estimator's view of one joint, for one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct JointEstimate {
    pub joint: u16,
    /// Sequence number of the sample this estimate comes from.
    pub seq: u64,
    /// Acquisition time of that sample [ns].
    pub t_acq_ns: u64,
    /// Restoring torque τ̂ [N·m].
    pub torque_nm: f64,
    /// Joint stiffness k̂ [N·m/rad].
    pub stiffness_nm_per_rad: Option<f64>,
    /// Link inertia Î [kg·m²] and its variance.
    pub inertia_kg_m2: Option<f64>,
    pub inertia_var: Option<f64>,
    /// Link damping N̂ [N·m·s/rad] and its variance.
    pub damping_nms_per_rad: Option<f64>,
    pub damping_var: Option<f64>,
    /// Measured minus modelled torque [N·m], where a torque sensor exists.
    pub residual_nm: Option<f64>,
}

impl JointEstimate {
    fn options(&self) -> [Option<f64>; 6] {
        [
            self.stiffness_nm_per_rad,
            self.inertia_kg_m2,
            self.inertia_var,
            self.damping_nms_per_rad,
            self.damping_var,
            self.residual_nm,
        ]
    }
}

impl Message for JointEstimate {
    const KIND: Kind = Kind::JointEstimate;

    fn validate(&self) -> Result<(), ValidationError> {
        let c = Check("joint_estimate");
        c.time("t_acq_ns", self.t_acq_ns)?;
        c.within("torque_nm", self.torque_nm, -MAX_TORQUE_NM, MAX_TORQUE_NM)?;
        c.opt_within("stiffness_nm_per_rad", self.stiffness_nm_per_rad, -1e7, 1e7)?;
        c.opt_within("inertia_kg_m2", self.inertia_kg_m2, 0.0, 1e6)?;
        c.opt_within("inertia_var", self.inertia_var, 0.0, f64::MAX)?;
        c.opt_within("damping_nms_per_rad", self.damping_nms_per_rad, -1e6, 1e6)?;
        c.opt_within("damping_var", self.damping_var, 0.0, f64::MAX)?;
        c.opt_within(
            "residual_nm",
            self.residual_nm,
            -MAX_TORQUE_NM,
            MAX_TORQUE_NM,
        )
    }

    fn write_body(&self, w: &mut Writer) {
        w.u16(self.joint);
        w.u16(flags_of(&self.options()));
        w.u64(self.seq);
        w.u64(self.t_acq_ns);
        w.f64(self.torque_nm);
        for v in self.options() {
            w.f64(v.unwrap_or(0.0));
        }
    }

    fn read_body(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let joint = r.u16("joint")?;
        let flags = r.u16("flags")?;
        check_flags(flags, 0b11_1111, "flags")?;
        Ok(Self {
            joint,
            seq: r.u64("seq")?,
            t_acq_ns: r.u64("t_acq_ns")?,
            torque_nm: r.f64("torque_nm")?,
            stiffness_nm_per_rad: flag(flags, 0, r.f64("stiffness_nm_per_rad")?),
            inertia_kg_m2: flag(flags, 1, r.f64("inertia_kg_m2")?),
            inertia_var: flag(flags, 2, r.f64("inertia_var")?),
            damping_nms_per_rad: flag(flags, 3, r.f64("damping_nms_per_rad")?),
            damping_var: flag(flags, 4, r.f64("damping_var")?),
            residual_nm: flag(flags, 5, r.f64("residual_nm")?),
        })
    }
}

/// The estimator's view of the end effector.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct EeEstimate {
    pub seq: u64,
    /// Time the estimate refers to (aligned sample time) [ns].
    pub t_ns: u64,
    /// Bit i set: joint i is stale (force and stiffness then absent).
    pub stale_mask: u32,
    pub x_m: f64,
    pub y_m: f64,
    pub phi_rad: f64,
    /// Estimated external force [N].
    pub force_n: Option<(f64, f64)>,
    /// Operational stiffness [N/m].
    pub stiffness_n_per_m: Option<StiffnessTriple>,
}

impl Message for EeEstimate {
    const KIND: Kind = Kind::EeEstimate;

    fn validate(&self) -> Result<(), ValidationError> {
        let c = Check("ee_estimate");
        c.time("t_ns", self.t_ns)?;
        c.within("x_m", self.x_m, -100.0, 100.0)?;
        c.within("y_m", self.y_m, -100.0, 100.0)?;
        c.within("phi_rad", self.phi_rad, -1e3, 1e3)?;
        if let Some((fx, fy)) = self.force_n {
            c.within("fx_n", fx, -1e6, 1e6)?;
            c.within("fy_n", fy, -1e6, 1e6)?;
        }
        if let Some(k) = self.stiffness_n_per_m {
            k.check(&c, ["kxx_n_per_m", "kxy_n_per_m", "kyy_n_per_m"])?;
        }
        Ok(())
    }

    fn write_body(&self, w: &mut Writer) {
        let flags =
            u16::from(self.force_n.is_some()) | (u16::from(self.stiffness_n_per_m.is_some()) << 1);
        w.u16(flags);
        w.u32(self.stale_mask);
        w.u64(self.seq);
        w.u64(self.t_ns);
        w.f64(self.x_m);
        w.f64(self.y_m);
        w.f64(self.phi_rad);
        let (fx, fy) = self.force_n.unwrap_or((0.0, 0.0));
        w.f64(fx);
        w.f64(fy);
        self.stiffness_n_per_m
            .unwrap_or(StiffnessTriple {
                xx: 0.0,
                xy: 0.0,
                yy: 0.0,
            })
            .write(w);
    }

    fn read_body(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let flags = r.u16("flags")?;
        check_flags(flags, 0b11, "flags")?;
        let stale_mask = r.u32("stale_mask")?;
        let seq = r.u64("seq")?;
        let t_ns = r.u64("t_ns")?;
        let (x_m, y_m, phi_rad) = (r.f64("x_m")?, r.f64("y_m")?, r.f64("phi_rad")?);
        let (fx, fy) = (r.f64("fx_n")?, r.f64("fy_n")?);
        let k = StiffnessTriple::read(r, ["kxx_n_per_m", "kxy_n_per_m", "kyy_n_per_m"])?;
        Ok(Self {
            seq,
            t_ns,
            stale_mask,
            x_m,
            y_m,
            phi_rad,
            force_n: (flags & 1 != 0).then_some((fx, fy)),
            stiffness_n_per_m: (flags & 2 != 0).then_some(k),
        })
    }
}
