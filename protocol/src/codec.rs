//! The envelope and primitives of the wire format (`protocol/WIRE.md` is the spec). It knows
//! kinds only as [`Kind`] bytes and values only as bytes: no message type is named here.
//!
//! ```text
//! offset size  field
//! 0      2     magic   b"VR"
//! 2      1     version 1
//! 3      1     kind    (see Kind)
//! 4      4     length  of the body in bytes, u32 little-endian
//! 8      ...   body    little-endian fields of the kind
//! ```

use thiserror::Error;

use crate::kind::Kind;
use crate::validation::ValidationError;

/// The first two bytes of every message.
pub const MAGIC: [u8; 2] = *b"VR";
/// The encoding version this crate writes and reads.
pub const VERSION: u8 = 1;
/// Size of the envelope header.
pub const HEADER_LEN: usize = 8;
/// Largest body accepted (1 MiB): a bound on what a malformed length can make us allocate.
pub const MAX_BODY: usize = 1 << 20;

/// Why bytes did not decode to a message.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DecodeError {
    #[error("payload of {0} bytes is shorter than the 8-byte header")]
    TooShort(usize),
    #[error("bad magic {0:02x?}: not a rig message")]
    BadMagic([u8; 2]),
    #[error("encoding version {0} is not supported (this build reads version {VERSION})")]
    UnsupportedVersion(u8),
    #[error("unknown message kind {0}")]
    UnknownKind(u8),
    #[error("expected a {expected:?} message, got {got:?}")]
    WrongKind { expected: Kind, got: Kind },
    #[error("header says the body has {declared} bytes but {actual} follow")]
    LengthMismatch { declared: usize, actual: usize },
    #[error("body too large: {0} bytes (limit {MAX_BODY})")]
    TooLarge(usize),
    #[error("body truncated while reading {field}")]
    Truncated { field: &'static str },
    #[error("{trailing} unexpected bytes after the body")]
    Trailing { trailing: usize },
    #[error("field {field}: {reason}")]
    BadField { field: &'static str, reason: String },
    #[error("invalid message: {0}")]
    Invalid(#[from] ValidationError),
}

/// Appends little-endian fields.
#[derive(Debug, Default)]
pub struct Writer {
    buf: Vec<u8>,
}

impl Writer {
    /// A writer with the header of `kind` reserved.
    pub fn new(kind: Kind) -> Self {
        let mut buf = Vec::with_capacity(128);
        buf.extend_from_slice(&MAGIC);
        buf.push(VERSION);
        buf.push(kind as u8);
        buf.extend_from_slice(&[0; 4]);
        Self { buf }
    }

    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    pub fn u16(&mut self, v: u16) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn u32(&mut self, v: u32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn u64(&mut self, v: u64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn f64(&mut self, v: f64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A string: u16 length, then UTF-8 bytes (the caller has checked the length).
    pub fn str(&mut self, s: &str) {
        let bytes = &s.as_bytes()[..s.len().min(u16::MAX as usize)];
        self.u16(bytes.len() as u16);
        self.buf.extend_from_slice(bytes);
    }

    /// Fills in the body length and returns the bytes.
    pub fn finish(mut self) -> Vec<u8> {
        let body = (self.buf.len() - HEADER_LEN) as u32;
        self.buf[4..8].copy_from_slice(&body.to_le_bytes());
        self.buf
    }
}

/// Reads little-endian fields from a body; every read is bounds-checked.
#[derive(Debug)]
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// Checks the header and returns the message kind and a reader over the body.
    pub fn open(bytes: &'a [u8]) -> Result<(Kind, Self), DecodeError> {
        if bytes.len() < HEADER_LEN {
            return Err(DecodeError::TooShort(bytes.len()));
        }
        let magic = [bytes[0], bytes[1]];
        if magic != MAGIC {
            return Err(DecodeError::BadMagic(magic));
        }
        if bytes[2] != VERSION {
            return Err(DecodeError::UnsupportedVersion(bytes[2]));
        }
        let kind = Kind::try_from(bytes[3]).map_err(|e| DecodeError::UnknownKind(e.0))?;
        let declared = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]) as usize;
        if declared > MAX_BODY {
            return Err(DecodeError::TooLarge(declared));
        }
        let actual = bytes.len() - HEADER_LEN;
        if declared != actual {
            return Err(DecodeError::LengthMismatch { declared, actual });
        }
        Ok((
            kind,
            Self {
                buf: &bytes[HEADER_LEN..],
                pos: 0,
            },
        ))
    }

    fn take(&mut self, n: usize, field: &'static str) -> Result<&'a [u8], DecodeError> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.buf.len())
            .ok_or(DecodeError::Truncated { field })?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], DecodeError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, field)?);
        Ok(a)
    }

    pub fn u8(&mut self, field: &'static str) -> Result<u8, DecodeError> {
        Ok(self.take(1, field)?[0])
    }

    pub fn u16(&mut self, field: &'static str) -> Result<u16, DecodeError> {
        self.array(field).map(u16::from_le_bytes)
    }

    pub fn u32(&mut self, field: &'static str) -> Result<u32, DecodeError> {
        self.array(field).map(u32::from_le_bytes)
    }

    pub fn u64(&mut self, field: &'static str) -> Result<u64, DecodeError> {
        self.array(field).map(u64::from_le_bytes)
    }

    pub fn f64(&mut self, field: &'static str) -> Result<f64, DecodeError> {
        self.array(field).map(f64::from_le_bytes)
    }

    pub fn str(&mut self, field: &'static str) -> Result<String, DecodeError> {
        let n = self.u16(field)? as usize;
        let bytes = self.take(n, field)?;
        String::from_utf8(bytes.to_vec()).map_err(|_| DecodeError::BadField {
            field,
            reason: "not valid UTF-8".into(),
        })
    }

    /// Fails if bytes are left over.
    pub fn finish(self) -> Result<(), DecodeError> {
        let trailing = self.buf.len() - self.pos;
        if trailing == 0 {
            Ok(())
        } else {
            Err(DecodeError::Trailing { trailing })
        }
    }
}
