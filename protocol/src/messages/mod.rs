//! The messages of the rig, split by the direction they travel in, and their encoding.
//!
//! - [`joint`]: from and to a joint agent (sample, a board's samples, command, status);
//! - [`estimate`]: from the estimator host (joint and end-effector estimates);
//! - [`allocation`]: to and from the allocator (request, result);
//! - [`sim`]: what only a simulated joint agent knows (the truth).
//!
//! Every value is SI (rad, m, N, N·m, s; times in ns since the UNIX epoch). Optional values
//! travel as a fixed slot plus a presence bit in a `flags` field, so every message but the
//! ones with text or lists has a fixed size. `protocol/WIRE.md` gives each layout as a Python
//! `struct` format. The kinds are listed once, in `table.rs`; [`AnyMessage`] and
//! [`decode_any`] are generated from that table.

pub mod allocation;
pub mod estimate;
pub mod joint;
pub mod sim;

pub use allocation::{AllocationRequest, AllocationResult, AllocationTarget};
pub use estimate::{EeEstimate, JointEstimate};
pub use joint::{BoardSample, JointCommand, JointSample, JointState, JointStatus};
pub use sim::SimTruth;

use crate::codec::{DecodeError, Reader, Writer};
use crate::kind::Kind;
use crate::table::wire_table;
use crate::validation::{Check, ValidationError};

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

/// The joint samples a payload on a `…/sample` key carries: one joint's (kind 1) or a board's
/// tick of several joints (kind 9), in the board's order. Any other kind is an error.
pub fn decode_samples(bytes: &[u8]) -> Result<Vec<JointSample>, DecodeError> {
    match Reader::open(bytes)?.0 {
        Kind::BoardSample => Ok(decode::<BoardSample>(bytes)?.samples),
        _ => Ok(vec![decode::<JointSample>(bytes)?]),
    }
}

pub(crate) fn flag(flags: u16, bit: u16, v: f64) -> Option<f64> {
    (flags & (1 << bit) != 0).then_some(v)
}

pub(crate) fn flags_of(opts: &[Option<f64>]) -> u16 {
    opts.iter()
        .enumerate()
        .fold(0, |f, (i, o)| if o.is_some() { f | (1 << i) } else { f })
}

pub(crate) fn check_flags(flags: u16, known: u16, field: &'static str) -> Result<(), DecodeError> {
    if flags & !known != 0 {
        return Err(DecodeError::BadField {
            field,
            reason: format!("unknown flag bits {:#06x}", flags & !known),
        });
    }
    Ok(())
}

macro_rules! generate_any_message {
    ($($byte:literal $name:ident $direction:ident $format:literal,)*) => {
        /// Any message, as read off the wire (one variant per row of the wire table).
        #[derive(Debug, Clone, PartialEq)]
        pub enum AnyMessage {
            $($name($direction::$name),)*
        }

        /// Decodes whatever message the bytes hold.
        pub fn decode_any(bytes: &[u8]) -> Result<AnyMessage, DecodeError> {
            let (kind, _) = Reader::open(bytes)?;
            Ok(match kind {
                $(Kind::$name => AnyMessage::$name(decode(bytes)?),)*
            })
        }

        impl AnyMessage {
            /// The message's kind.
            pub fn kind(&self) -> Kind {
                match self {
                    $(AnyMessage::$name(_) => Kind::$name,)*
                }
            }
        }

        $(
            impl From<$direction::$name> for AnyMessage {
                fn from(m: $direction::$name) -> Self {
                    AnyMessage::$name(m)
                }
            }

            // A type's `Message::KIND` must be its row's: checked when the crate compiles.
            const _: () = assert!(<$direction::$name as Message>::KIND as u8 == $byte);
        )*
    };
}

wire_table!(generate_any_message);

/// Operational stiffness (k_xx, k_xy, k_yy) [N/m].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "json",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct StiffnessTriple {
    pub xx: f64,
    pub xy: f64,
    pub yy: f64,
}

impl StiffnessTriple {
    pub(crate) fn check(
        &self,
        c: &Check,
        fields: [&'static str; 3],
    ) -> Result<(), ValidationError> {
        c.within(fields[0], self.xx, -1e9, 1e9)?;
        c.within(fields[1], self.xy, -1e9, 1e9)?;
        c.within(fields[2], self.yy, -1e9, 1e9)
    }

    pub(crate) fn write(&self, w: &mut Writer) {
        w.f64(self.xx);
        w.f64(self.xy);
        w.f64(self.yy);
    }

    pub(crate) fn read(r: &mut Reader<'_>, fields: [&'static str; 3]) -> Result<Self, DecodeError> {
        Ok(Self {
            xx: r.f64(fields[0])?,
            xy: r.f64(fields[1])?,
            yy: r.f64(fields[2])?,
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
    fn a_board_message_is_a_count_then_each_samples_kind_1_body_and_names_the_bad_one() {
        let other = JointSample {
            joint: 5,
            ..sample()
        };
        let board = BoardSample {
            samples: vec![sample(), other],
        };
        let bytes = encode(&board).unwrap();
        let one = encode(&sample()).unwrap();
        assert_eq!(bytes.len(), 8 + 2 + 2 * 68);
        assert_eq!(&bytes[0..4], &[b'V', b'R', 1, 9]);
        assert_eq!(u16::from_le_bytes(bytes[8..10].try_into().unwrap()), 2);
        assert_eq!(&bytes[10..78], &one[8..]);
        assert_eq!(decode::<BoardSample>(&bytes).unwrap(), board);
        assert_eq!(decode_samples(&bytes).unwrap(), board.samples);
        assert_eq!(decode_samples(&one).unwrap(), vec![sample()]);
        let status = JointStatus {
            joint: 2,
            state: JointState::Ok,
            seq: 1,
            t_ns: 1,
            text: String::new(),
        };
        assert!(decode_samples(&encode(&status).unwrap()).is_err());

        let e = encode(&BoardSample { samples: vec![] }).unwrap_err();
        assert_eq!((e.message, e.field), ("board_sample", "samples"));
        let e = encode(&BoardSample {
            samples: vec![sample(), sample()],
        })
        .unwrap_err();
        assert!(
            e.reason.contains("samples[1]: joint 2 appears twice"),
            "{e}"
        );
        let e = encode(&BoardSample {
            samples: vec![
                sample(),
                JointSample {
                    deflection_rad: f64::NAN,
                    ..other
                },
            ],
        })
        .unwrap_err();
        assert!(
            e.reason.contains("samples[1]: joint_sample.deflection_rad"),
            "{e}"
        );
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
