//! The messages of the rig, their validation and their encoding.
//!
//! Every value is SI (rad, m, N, N·m, s; times in ns since the UNIX epoch). Optional values
//! travel as a fixed slot plus a presence bit in a `flags` field, so every message but the
//! ones with text or lists has a fixed size. `protocol/WIRE.md` gives each layout as a Python
//! `struct` format.

use thiserror::Error;

use crate::codec::{DecodeError, Kind, Reader, Writer};

/// A value outside what the protocol accepts.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{message}.{field}: {reason}")]
pub struct ValidationError {
    pub message: &'static str,
    pub field: &'static str,
    pub reason: String,
}

/// Longest text in a status or allocation result, in bytes.
pub const MAX_TEXT: usize = 1024;
/// Most joints in one allocation result.
pub const MAX_JOINTS: usize = 16;
/// Largest |torque| accepted [N·m]: far above any joint of the rig, catches garbage.
pub const MAX_TORQUE_NM: f64 = 1e4;

struct Check(&'static str);

impl Check {
    fn err(&self, field: &'static str, reason: impl Into<String>) -> ValidationError {
        ValidationError {
            message: self.0,
            field,
            reason: reason.into(),
        }
    }

    fn finite(&self, field: &'static str, v: f64) -> Result<(), ValidationError> {
        if v.is_finite() {
            Ok(())
        } else {
            Err(self.err(field, format!("must be a finite number, got {v}")))
        }
    }

    fn within(&self, field: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), ValidationError> {
        self.finite(field, v)?;
        if v < lo || v > hi {
            return Err(self.err(field, format!("{v} is outside [{lo}, {hi}]")));
        }
        Ok(())
    }

    fn opt_within(
        &self,
        field: &'static str,
        v: Option<f64>,
        lo: f64,
        hi: f64,
    ) -> Result<(), ValidationError> {
        v.map_or(Ok(()), |v| self.within(field, v, lo, hi))
    }

    fn time(&self, field: &'static str, t_ns: u64) -> Result<(), ValidationError> {
        if t_ns == 0 {
            Err(self.err(field, "acquisition time is unset (0)"))
        } else {
            Ok(())
        }
    }

    fn text(&self, field: &'static str, s: &str) -> Result<(), ValidationError> {
        if s.len() > MAX_TEXT {
            return Err(self.err(field, format!("{} bytes, at most {MAX_TEXT}", s.len())));
        }
        Ok(())
    }
}

/// A message type with its kind, validation and body layout.
pub trait Message: Sized {
    const KIND: Kind;
    /// Checks every value (finite, in range).
    fn validate(&self) -> Result<(), ValidationError>;
    #[doc(hidden)]
    fn write_body(&self, w: &mut Writer);
    #[doc(hidden)]
    fn read_body(r: &mut Reader<'_>) -> Result<Self, DecodeError>;
}

/// Validates and encodes a message.
pub fn encode<M: Message>(m: &M) -> Result<Vec<u8>, ValidationError> {
    m.validate()?;
    let mut w = Writer::new(M::KIND);
    m.write_body(&mut w);
    Ok(w.finish())
}

/// Decodes and validates a message of a known kind.
pub fn decode<M: Message>(bytes: &[u8]) -> Result<M, DecodeError> {
    let (kind, mut r) = Reader::open(bytes)?;
    if kind != M::KIND {
        return Err(DecodeError::WrongKind {
            expected: M::KIND,
            got: kind,
        });
    }
    let m = M::read_body(&mut r)?;
    r.finish()?;
    m.validate()?;
    Ok(m)
}

/// Any message, as read off the wire.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyMessage {
    JointSample(JointSample),
    JointCommand(JointCommand),
    JointStatus(JointStatus),
    JointEstimate(JointEstimate),
    EeEstimate(EeEstimate),
    AllocationRequest(AllocationRequest),
    AllocationResult(AllocationResult),
    SimTruth(SimTruth),
}

/// Decodes whatever message the bytes hold.
pub fn decode_any(bytes: &[u8]) -> Result<AnyMessage, DecodeError> {
    let (kind, _) = Reader::open(bytes)?;
    Ok(match kind {
        Kind::JointSample => AnyMessage::JointSample(decode(bytes)?),
        Kind::JointCommand => AnyMessage::JointCommand(decode(bytes)?),
        Kind::JointStatus => AnyMessage::JointStatus(decode(bytes)?),
        Kind::JointEstimate => AnyMessage::JointEstimate(decode(bytes)?),
        Kind::EeEstimate => AnyMessage::EeEstimate(decode(bytes)?),
        Kind::AllocationRequest => AnyMessage::AllocationRequest(decode(bytes)?),
        Kind::AllocationResult => AnyMessage::AllocationResult(decode(bytes)?),
        Kind::SimTruth => AnyMessage::SimTruth(decode(bytes)?),
    })
}

fn flag(flags: u16, bit: u16, v: f64) -> Option<f64> {
    (flags & (1 << bit) != 0).then_some(v)
}

fn flags_of(opts: &[Option<f64>]) -> u16 {
    opts.iter()
        .enumerate()
        .fold(0, |f, (i, o)| if o.is_some() { f | (1 << i) } else { f })
}

fn check_flags(flags: u16, known: u16, field: &'static str) -> Result<(), DecodeError> {
    if flags & !known != 0 {
        return Err(DecodeError::BadField {
            field,
            reason: format!("unknown flag bits {:#06x}", flags & !known),
        });
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------

/// A joint agent's sample: what the joint board read at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
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

/// A command to a joint agent. The agent checks it against its own limits.
#[derive(Debug, Clone, Copy, PartialEq)]
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

/// The estimator's view of one joint, for one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
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

/// Operational stiffness (k_xx, k_xy, k_yy) [N/m].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StiffnessTriple {
    pub xx: f64,
    pub xy: f64,
    pub yy: f64,
}

impl StiffnessTriple {
    fn check(&self, c: &Check, fields: [&'static str; 3]) -> Result<(), ValidationError> {
        c.within(fields[0], self.xx, -1e9, 1e9)?;
        c.within(fields[1], self.xy, -1e9, 1e9)?;
        c.within(fields[2], self.yy, -1e9, 1e9)
    }

    fn write(&self, w: &mut Writer) {
        w.f64(self.xx);
        w.f64(self.xy);
        w.f64(self.yy);
    }

    fn read(r: &mut Reader<'_>, fields: [&'static str; 3]) -> Result<Self, DecodeError> {
        Ok(Self {
            xx: r.f64(fields[0])?,
            xy: r.f64(fields[1])?,
            yy: r.f64(fields[2])?,
        })
    }
}

/// The estimator's view of the end effector.
#[derive(Debug, Clone, Copy, PartialEq)]
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

/// What an allocation request asks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AllocationTarget {
    /// An explicit operational stiffness [N/m].
    Stiffness(StiffnessTriple),
    /// Paper B's decoupled target: k_xx, k_yy at this percentage of the range, k_xy = 0.
    Percent(f64),
}

/// A request to the allocator.
#[derive(Debug, Clone, Copy, PartialEq)]
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

/// What the simulator knows and no sensor reads: published by simulated joint agents only,
/// so that tests and summaries can score estimates against the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
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

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn sample() -> JointSample {
        JointSample {
            joint: 2,
            seq: 41,
            t_acq_ns: 1_700_000_000_000_000_000,
            motor_rad: 0.5,
            deflection_rad: -0.01,
            pivot_m: Some(0.009),
            torque_nm: None,
            motor_torque_nm: Some(0.2),
            stiffness_motor_rad: None,
        }
    }

    #[test]
    fn joint_sample_layout_is_fixed_and_documented() {
        // "<2sBBI" header + "<HHQQdddddd" body = 8 + 68 bytes.
        let bytes = encode(&sample()).unwrap();
        assert_eq!(bytes.len(), 8 + 68);
        assert_eq!(&bytes[0..4], &[b'V', b'R', 1, 1]);
        assert_eq!(u32::from_le_bytes(bytes[4..8].try_into().unwrap()), 68);
        assert_eq!(u16::from_le_bytes(bytes[8..10].try_into().unwrap()), 2);
        assert_eq!(
            u16::from_le_bytes(bytes[10..12].try_into().unwrap()),
            0b0101
        );
        assert_eq!(f64::from_le_bytes(bytes[36..44].try_into().unwrap()), -0.01);
        assert_eq!(decode::<JointSample>(&bytes).unwrap(), sample());
    }

    #[test]
    fn validation_names_the_field() {
        let bad = JointSample {
            deflection_rad: f64::NAN,
            ..sample()
        };
        let e = encode(&bad).unwrap_err();
        assert_eq!((e.message, e.field), ("joint_sample", "deflection_rad"));
        let bad = JointSample {
            t_acq_ns: 0,
            ..sample()
        };
        assert_eq!(encode(&bad).unwrap_err().field, "t_acq_ns");
        let bad = AllocationRequest {
            id: 1,
            x_m: 0.1,
            y_m: 0.2,
            target: AllocationTarget::Percent(120.0),
        };
        assert_eq!(encode(&bad).unwrap_err().field, "percent");
    }

    #[test]
    fn decoding_a_nan_written_by_another_client_is_refused() {
        let mut bytes = encode(&sample()).unwrap();
        bytes[36..44].copy_from_slice(&f64::NAN.to_le_bytes());
        assert!(
            matches!(decode::<JointSample>(&bytes), Err(DecodeError::Invalid(e)) if e.field == "deflection_rad")
        );
    }

    #[test]
    fn header_errors_are_specific() {
        let bytes = encode(&sample()).unwrap();
        assert_eq!(
            decode::<JointSample>(&bytes[..5]),
            Err(DecodeError::TooShort(5))
        );
        let mut b = bytes.clone();
        b[2] = 9;
        assert_eq!(
            decode::<JointSample>(&b),
            Err(DecodeError::UnsupportedVersion(9))
        );
        let mut b = bytes.clone();
        b[0] = b'X';
        assert!(matches!(
            decode::<JointSample>(&b),
            Err(DecodeError::BadMagic(_))
        ));
        assert!(matches!(
            decode::<JointCommand>(&bytes),
            Err(DecodeError::WrongKind { .. })
        ));
        assert!(matches!(
            decode::<JointSample>(&bytes[..40]),
            Err(DecodeError::LengthMismatch { .. })
        ));
        let mut b = bytes.clone();
        b[10] = 0xff;
        assert!(matches!(
            decode::<JointSample>(&b),
            Err(DecodeError::BadField { field: "flags", .. })
        ));
    }
}
