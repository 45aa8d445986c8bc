//! [`Kind`]: the message kinds of the wire table (`table.rs`), as the header's byte 3.

use thiserror::Error;

use crate::table::wire_table;

/// A header byte that names no message kind of this version.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
#[error("unknown message kind {0}")]
pub struct UnknownKind(pub u8);

macro_rules! generate_kind {
    ($($byte:literal $name:ident $direction:ident $format:literal,)*) => {
        /// Message kinds (byte 3 of the header), generated from the wire table.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        #[repr(u8)]
        pub enum Kind {
            $($name = $byte,)*
        }

        impl Kind {
            /// Every kind, in the order of the table.
            pub const ALL: &'static [Kind] = &[$(Kind::$name,)*];

            /// The message type's name, e.g. `"JointSample"`.
            pub fn name(self) -> &'static str {
                match self {
                    $(Kind::$name => stringify!($name),)*
                }
            }

            /// The body's Python `struct` format, as `WIRE.md` gives it (`+` then the
            /// variable tail, for kinds with text or lists).
            pub fn body_format(self) -> &'static str {
                match self {
                    $(Kind::$name => $format,)*
                }
            }
        }

        impl TryFrom<u8> for Kind {
            type Error = UnknownKind;

            fn try_from(b: u8) -> Result<Self, UnknownKind> {
                match b {
                    $($byte => Ok(Kind::$name),)*
                    _ => Err(UnknownKind(b)),
                }
            }
        }
    };
}

wire_table!(generate_kind);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_round_trips_through_its_byte_and_no_other_byte_is_a_kind() {
        for &k in Kind::ALL {
            assert_eq!(Kind::try_from(k as u8), Ok(k));
        }
        let known = (0..=255u8).filter(|b| Kind::try_from(*b).is_ok()).count();
        assert_eq!(known, Kind::ALL.len());
        assert_eq!(Kind::try_from(0), Err(UnknownKind(0)));
    }
}
