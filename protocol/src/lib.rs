//! # rig-protocol — what travels between the rig's agents
//!
//! - [`keys`]: the key-expression scheme (`rig/<rig>/joint/<j>/sample`, …);
//! - [`codec`]: the versioned binary envelope and its little-endian primitives;
//! - [`messages`]: the message types, their validation and encoding.
//!
//! No Zenoh, no async, no I/O: the runtime's Zenoh edge only moves these bytes. The byte
//! layout is specified in `protocol/WIRE.md` so that any language decodes it with its
//! standard library (Python: `struct.unpack`). Decoding arbitrary bytes never panics; it
//! returns a [`DecodeError`] naming what is wrong.

pub mod codec;
pub mod keys;
pub mod messages;

pub use codec::{DecodeError, Kind, MAGIC, VERSION};
pub use keys::{KeyError, Keys, Topic};
pub use messages::{
    AllocationRequest, AllocationResult, AllocationTarget, AnyMessage, EeEstimate, JointCommand,
    JointEstimate, JointSample, JointState, JointStatus, Message, SimTruth, StiffnessTriple,
    ValidationError, decode, decode_any, encode,
};
