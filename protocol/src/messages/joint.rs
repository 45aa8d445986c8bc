//! Messages from and to a joint agent: its samples, the commands it obeys within its limits,
//! and its status.

use super::{Message, check_flags, flag, flags_of};
use crate::codec::{DecodeError, Reader, Writer};
use crate::kind::Kind;
use crate::validation::{Check, MAX_BOARD_JOINTS, MAX_TORQUE_NM, ValidationError};

/// A joint agent's sample: what the joint board read at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct JointSample {
    /// Joint index in the rig config (0-based).
    pub joint: u16,
    /// Sequence number, +1 per sample of this joint; gaps show loss.
    pub seq: u64,
    /// Acquisition time [ns since the UNIX epoch].
    pub t_acq_ns: u64,
    /// Main (position) motor angle θ1 [rad].
    pub motor_rad: f64,
    /// Deflection φ = q − θ1 [rad].
    pub deflection_rad: f64,
    /// Measured pivot position d [m] (lever VSA).
    pub pivot_m: Option<f64>,
    /// Torque-sensor reading [N·m], where one is fitted.
    pub torque_nm: Option<f64>,
    /// Position-motor torque τ1 [N·m] (from current), where known.
    pub motor_torque_nm: Option<f64>,
    /// Stiffness-motor angle θ2 [rad] (AWAS).
    pub stiffness_motor_rad: Option<f64>,
}

impl Message for JointSample {
    const KIND: Kind = Kind::JointSample;

    fn validate(&self) -> Result<(), ValidationError> {
        let c = Check("joint_sample");
        c.time("t_acq_ns", self.t_acq_ns)?;
        c.within("motor_rad", self.motor_rad, -1e6, 1e6)?;
        c.within(
            "deflection_rad",
            self.deflection_rad,
            -std::f64::consts::PI,
            std::f64::consts::PI,
        )?;
        c.opt_within("pivot_m", self.pivot_m, -1.0, 1.0)?;
        c.opt_within("torque_nm", self.torque_nm, -MAX_TORQUE_NM, MAX_TORQUE_NM)?;
        c.opt_within(
            "motor_torque_nm",
            self.motor_torque_nm,
            -MAX_TORQUE_NM,
            MAX_TORQUE_NM,
        )?;
        c.opt_within("stiffness_motor_rad", self.stiffness_motor_rad, -1e6, 1e6)
    }

    fn write_body(&self, w: &mut Writer) {
        w.u16(self.joint);
        w.u16(flags_of(&[
            self.pivot_m,
            self.torque_nm,
            self.motor_torque_nm,
            self.stiffness_motor_rad,
        ]));
        w.u64(self.seq);
        w.u64(self.t_acq_ns);
        w.f64(self.motor_rad);
        w.f64(self.deflection_rad);
        for v in [
            self.pivot_m,
            self.torque_nm,
            self.motor_torque_nm,
            self.stiffness_motor_rad,
        ] {
            w.f64(v.unwrap_or(0.0));
        }
    }

    fn read_body(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let joint = r.u16("joint")?;
        let flags = r.u16("flags")?;
        check_flags(flags, 0b1111, "flags")?;
        Ok(Self {
            joint,
            seq: r.u64("seq")?,
            t_acq_ns: r.u64("t_acq_ns")?,
            motor_rad: r.f64("motor_rad")?,
            deflection_rad: r.f64("deflection_rad")?,
            pivot_m: flag(flags, 0, r.f64("pivot_m")?),
            torque_nm: flag(flags, 1, r.f64("torque_nm")?),
            motor_torque_nm: flag(flags, 2, r.f64("motor_torque_nm")?),
            stiffness_motor_rad: flag(flags, 3, r.f64("stiffness_motor_rad")?),
        })
    }
}

/// One tick of a board serving several joints: each joint's sample, in one message (kind 9,
/// on `rig/<rig>/board/<board>/sample`). A board of one joint publishes kind 1 on its joint's
/// key instead. Each sample keeps its own joint, `seq` and acquisition time, so a reader treats
/// a board message as its samples one after the other.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct BoardSample {
    /// 1 to [`MAX_BOARD_JOINTS`] samples, no joint twice.
    pub samples: Vec<JointSample>,
}

impl Message for BoardSample {
    const KIND: Kind = Kind::BoardSample;

    fn validate(&self) -> Result<(), ValidationError> {
        let c = Check("board_sample");
        let n = self.samples.len();
        if n == 0 || n > MAX_BOARD_JOINTS {
            return Err(c.err(
                "samples",
                format!("{n} samples: a board carries 1 to {MAX_BOARD_JOINTS}"),
            ));
        }
        let mut seen = std::collections::HashSet::with_capacity(n);
        for (i, s) in self.samples.iter().enumerate() {
            s.validate()
                .map_err(|e| c.err("samples", format!("samples[{i}]: {e}")))?;
            if !seen.insert(s.joint) {
                return Err(c.err(
                    "samples",
                    format!("samples[{i}]: joint {} appears twice", s.joint),
                ));
            }
        }
        Ok(())
    }

    fn write_body(&self, w: &mut Writer) {
        w.u16(self.samples.len() as u16);
        for s in &self.samples {
            s.write_body(w);
        }
    }

    fn read_body(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let n = usize::from(r.u16("n")?);
        if n == 0 || n > MAX_BOARD_JOINTS {
            return Err(DecodeError::BadField {
                field: "n",
                reason: format!("{n} samples: a board carries 1 to {MAX_BOARD_JOINTS}"),
            });
        }
        let samples = (0..n)
            .map(|_| JointSample::read_body(r))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { samples })
    }
}

/// A command to a joint agent. The agent checks it against its own limits.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct JointCommand {
    pub joint: u16,
    pub seq: u64,
    /// When the command was issued [ns since the UNIX epoch].
    pub t_ns: u64,
    /// Goal of the main motor [rad].
    pub motor_goal_rad: Option<f64>,
    /// Goal pivot position [m].
    pub pivot_goal_m: Option<f64>,
    /// Goal of the stiffness motor [rad] (AWAS).
    pub stiffness_motor_goal_rad: Option<f64>,
    /// Torque on (true) or off (false) for the joint's servos.
    pub torque_enable: bool,
}

impl Message for JointCommand {
    const KIND: Kind = Kind::JointCommand;

    fn validate(&self) -> Result<(), ValidationError> {
        let c = Check("joint_command");
        c.time("t_ns", self.t_ns)?;
        c.opt_within("motor_goal_rad", self.motor_goal_rad, -1e6, 1e6)?;
        c.opt_within("pivot_goal_m", self.pivot_goal_m, -1.0, 1.0)?;
        c.opt_within(
            "stiffness_motor_goal_rad",
            self.stiffness_motor_goal_rad,
            -1e6,
            1e6,
        )
    }

    fn write_body(&self, w: &mut Writer) {
        w.u16(self.joint);
        w.u16(flags_of(&[
            self.motor_goal_rad,
            self.pivot_goal_m,
            self.stiffness_motor_goal_rad,
        ]));
        w.u64(self.seq);
        w.u64(self.t_ns);
        for v in [
            self.motor_goal_rad,
            self.pivot_goal_m,
            self.stiffness_motor_goal_rad,
        ] {
            w.f64(v.unwrap_or(0.0));
        }
        w.u8(u8::from(self.torque_enable));
    }

    fn read_body(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let joint = r.u16("joint")?;
        let flags = r.u16("flags")?;
        check_flags(flags, 0b111, "flags")?;
        let seq = r.u64("seq")?;
        let t_ns = r.u64("t_ns")?;
        let motor_goal_rad = flag(flags, 0, r.f64("motor_goal_rad")?);
        let pivot_goal_m = flag(flags, 1, r.f64("pivot_goal_m")?);
        let stiffness_motor_goal_rad = flag(flags, 2, r.f64("stiffness_motor_goal_rad")?);
        let torque_enable = match r.u8("torque_enable")? {
            0 => false,
            1 => true,
            v => {
                return Err(DecodeError::BadField {
                    field: "torque_enable",
                    reason: format!("{v} is not 0 or 1"),
                });
            }
        };
        Ok(Self {
            joint,
            seq,
            t_ns,
            motor_goal_rad,
            pivot_goal_m,
            stiffness_motor_goal_rad,
            torque_enable,
        })
    }
}

/// The state a joint agent reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub enum JointState {
    /// Running normally.
    Ok = 0,
    /// A command was refused; the text names the limit.
    Rejected = 1,
    /// Commands stopped: holding the last safe position (watchdog).
    SafeHold = 2,
    /// A bus or sensor fault; torque is off.
    Fault = 3,
    /// The agent is shutting down; torque is off.
    Stopped = 4,
    /// (Estimator status) the joint's samples stopped; what depends on it is withheld.
    Stale = 5,
}

impl JointState {
    fn from_u8(b: u8) -> Option<Self> {
        Some(match b {
            0 => JointState::Ok,
            1 => JointState::Rejected,
            2 => JointState::SafeHold,
            3 => JointState::Fault,
            4 => JointState::Stopped,
            5 => JointState::Stale,
            _ => return None,
        })
    }
}

/// A joint agent's status.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct JointStatus {
    pub joint: u16,
    pub seq: u64,
    pub t_ns: u64,
    pub state: JointState,
    /// Human-readable detail (≤ 1024 bytes UTF-8).
    pub text: String,
}

impl Message for JointStatus {
    const KIND: Kind = Kind::JointStatus;

    fn validate(&self) -> Result<(), ValidationError> {
        let c = Check("joint_status");
        c.time("t_ns", self.t_ns)?;
        c.text("text", &self.text)
    }

    fn write_body(&self, w: &mut Writer) {
        w.u16(self.joint);
        w.u8(self.state as u8);
        w.u64(self.seq);
        w.u64(self.t_ns);
        w.str(&self.text);
    }

    fn read_body(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let joint = r.u16("joint")?;
        let s = r.u8("state")?;
        let state = JointState::from_u8(s).ok_or_else(|| DecodeError::BadField {
            field: "state",
            reason: format!("unknown state {s}"),
        })?;
        Ok(Self {
            joint,
            state,
            seq: r.u64("seq")?,
            t_ns: r.u64("t_ns")?,
            text: r.str("text")?,
        })
    }
}
