//! Messages to and from the allocator: a wanted operational stiffness, and the joint
//! stiffnesses and pivot positions that give it.

use super::{Message, StiffnessTriple};
use crate::codec::{DecodeError, Reader, Writer};
use crate::kind::Kind;
use crate::validation::{Check, MAX_JOINTS, ValidationError};

/// What an allocation request asks for.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub enum AllocationTarget {
    /// An explicit operational stiffness [N/m].
    Stiffness(StiffnessTriple),
    /// Paper B's decoupled target: k_xx, k_yy at this percentage of the range, k_xy = 0.
    Percent(f64),
}

/// A request to the allocator.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct AllocationRequest {
    /// Chosen by the requester; echoed in the result.
    pub id: u64,
    /// End-effector position to allocate at [m].
    pub x_m: f64,
    pub y_m: f64,
    pub target: AllocationTarget,
}

impl Message for AllocationRequest {
    const KIND: Kind = Kind::AllocationRequest;

    fn validate(&self) -> Result<(), ValidationError> {
        let c = Check("allocation_request");
        c.within("x_m", self.x_m, -100.0, 100.0)?;
        c.within("y_m", self.y_m, -100.0, 100.0)?;
        match self.target {
            AllocationTarget::Percent(p) => c.within("percent", p, 0.0, 100.0),
            AllocationTarget::Stiffness(k) => {
                k.check(&c, ["kxx_n_per_m", "kxy_n_per_m", "kyy_n_per_m"])?;
                if k.xx < 0.0 || k.yy < 0.0 {
                    return Err(c.err("kxx_n_per_m", "k_xx and k_yy must be >= 0"));
                }
                Ok(())
            }
        }
    }

    fn write_body(&self, w: &mut Writer) {
        w.u64(self.id);
        w.f64(self.x_m);
        w.f64(self.y_m);
        match self.target {
            AllocationTarget::Stiffness(k) => {
                w.u8(0);
                k.write(w);
            }
            AllocationTarget::Percent(p) => {
                w.u8(1);
                StiffnessTriple {
                    xx: p,
                    xy: 0.0,
                    yy: 0.0,
                }
                .write(w);
            }
        }
    }

    fn read_body(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let id = r.u64("id")?;
        let (x_m, y_m) = (r.f64("x_m")?, r.f64("y_m")?);
        let tag = r.u8("target_kind")?;
        let v = StiffnessTriple::read(r, ["target_0", "target_1", "target_2"])?;
        let target = match tag {
            0 => AllocationTarget::Stiffness(v),
            1 => AllocationTarget::Percent(v.xx),
            t => {
                return Err(DecodeError::BadField {
                    field: "target_kind",
                    reason: format!("{t} is not 0 or 1"),
                });
            }
        };
        Ok(Self {
            id,
            x_m,
            y_m,
            target,
        })
    }
}

/// The allocator's answer.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct AllocationResult {
    pub id: u64,
    pub feasible: bool,
    /// ‖S·k − target‖ [N/m].
    pub residual: f64,
    pub target: StiffnessTriple,
    pub achieved: StiffnessTriple,
    /// Joint stiffnesses [N·m/rad] and pivot positions [m], one per actuated joint.
    pub k_joint_nm_per_rad: Vec<f64>,
    pub pivot_m: Vec<f64>,
    /// Empty on success; otherwise why there is no allocation.
    pub error: String,
}

impl Message for AllocationResult {
    const KIND: Kind = Kind::AllocationResult;

    fn validate(&self) -> Result<(), ValidationError> {
        let c = Check("allocation_result");
        c.within("residual", self.residual, 0.0, f64::MAX)?;
        self.target
            .check(&c, ["target_xx", "target_xy", "target_yy"])?;
        self.achieved
            .check(&c, ["achieved_xx", "achieved_xy", "achieved_yy"])?;
        if self.k_joint_nm_per_rad.len() != self.pivot_m.len()
            || self.k_joint_nm_per_rad.len() > MAX_JOINTS
        {
            return Err(c.err(
                "k_joint_nm_per_rad",
                format!("needs one pivot per joint and at most {MAX_JOINTS} joints"),
            ));
        }
        for &k in &self.k_joint_nm_per_rad {
            c.within("k_joint_nm_per_rad", k, 0.0, 1e7)?;
        }
        for &d in &self.pivot_m {
            c.within("pivot_m", d, -1.0, 1.0)?;
        }
        c.text("error", &self.error)
    }

    fn write_body(&self, w: &mut Writer) {
        w.u64(self.id);
        w.u8(u8::from(self.feasible));
        w.f64(self.residual);
        self.target.write(w);
        self.achieved.write(w);
        w.u8(self.k_joint_nm_per_rad.len() as u8);
        for &k in &self.k_joint_nm_per_rad {
            w.f64(k);
        }
        for &d in &self.pivot_m {
            w.f64(d);
        }
        w.str(&self.error);
    }

    fn read_body(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let id = r.u64("id")?;
        let feasible = match r.u8("feasible")? {
            0 => false,
            1 => true,
            v => {
                return Err(DecodeError::BadField {
                    field: "feasible",
                    reason: format!("{v} is not 0 or 1"),
                });
            }
        };
        let residual = r.f64("residual")?;
        let target = StiffnessTriple::read(r, ["target_xx", "target_xy", "target_yy"])?;
        let achieved = StiffnessTriple::read(r, ["achieved_xx", "achieved_xy", "achieved_yy"])?;
        let n = r.u8("joint_count")? as usize;
        if n > MAX_JOINTS {
            return Err(DecodeError::BadField {
                field: "joint_count",
                reason: format!("{n} > {MAX_JOINTS}"),
            });
        }
        let k = (0..n)
            .map(|_| r.f64("k_joint_nm_per_rad"))
            .collect::<Result<Vec<_>, _>>()?;
        let d = (0..n)
            .map(|_| r.f64("pivot_m"))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            id,
            feasible,
            residual,
            target,
            achieved,
            k_joint_nm_per_rad: k,
            pivot_m: d,
            error: r.str("error")?,
        })
    }
}
