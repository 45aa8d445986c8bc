//! # rig-protocol — what travels between the rig's agents
//!
//! - [`keys`]: the key-expression scheme (`rig/<rig>/joint/<j>/sample`, …);
//! - [`codec`]: the versioned binary envelope and its little-endian primitives;
//! - [`messages`]: the message types, split by direction, and their encoding;
//! - [`validation`]: what values each message accepts;
//! - [`Kind`]: the message kinds, generated with `AnyMessage` from one table (`table.rs`).
//!
//! No Zenoh, no async, no I/O: the runtime's Zenoh edge only moves these bytes. The byte
//! layout is specified in `protocol/WIRE.md` so that any language decodes it with its
//! standard library (Python: `struct.unpack`). Decoding arbitrary bytes never panics; it
//! returns a [`DecodeError`] naming what is wrong.

mod table;

pub mod codec;
#[cfg(feature = "json")]
pub mod json;
pub mod keys;
pub mod kind;
pub mod messages;
pub mod validation;

pub use codec::{DecodeError, MAGIC, VERSION};
pub use keys::{KeyError, Keys, Topic};
pub use kind::{Kind, UnknownKind};
pub use messages::{
    AllocationRequest, AllocationResult, AllocationTarget, AnyMessage, BoardSample, EeEstimate,
    JointCommand, JointEstimate, JointSample, JointState, JointStatus, Message, SimTruth,
    StiffnessTriple, decode, decode_any, decode_samples, encode,
};
pub use validation::{MAX_BOARD_JOINTS, MAX_JOINTS, MAX_TEXT, MAX_TORQUE_NM, ValidationError};
