//! Dynamixel protocol 1.0, both sides: paper B's AX-12A pivot servos speak it, and the
//! protocol-2.0 client library does not. A small implementation (rustypot speaks it too, but
//! brings a CLI, a logger and regex into the joint agent).
//!
//! ```text
//! FF FF | ID | LEN | INST or ERROR | PARAM… | CHECKSUM
//! ```
//! LEN = parameters + 2; CHECKSUM = !(ID + LEN + INST + Σ PARAM) (low byte). Instruction and
//! status packets share the frame; a status carries the error byte where an instruction has
//! its code. Instructions: PING 0x01, READ 0x02 (address, count), WRITE 0x03 (address, data…).
//! Addresses and counts are one byte. There is no sync read on the AX-12A.

use std::time::{Duration, Instant};

use serial2::SerialPort;
use thiserror::Error;

/// A frame: ID, instruction (or error byte) and parameters.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    pub id: u8,
    pub code: u8,
    pub params: Vec<u8>,
}

/// The checksum over ID, LEN, code and parameters.
pub fn checksum(id: u8, len: u8, code: u8, params: &[u8]) -> u8 {
    let sum = params
        .iter()
        .fold(u32::from(id) + u32::from(len) + u32::from(code), |s, &b| {
            s + u32::from(b)
        });
    !(sum as u8)
}

impl Frame {
    pub fn encode(&self) -> Vec<u8> {
        let len = (self.params.len() + 2) as u8;
        let mut out = vec![0xFF, 0xFF, self.id, len, self.code];
        out.extend_from_slice(&self.params);
        out.push(checksum(self.id, len, self.code, &self.params));
        out
    }
}

/// What [`parse`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Parsed {
    Incomplete,
    /// A frame and the bytes used (from the start of the buffer).
    Frame(Frame, usize),
    /// A complete frame with a wrong checksum, and the bytes used.
    BadChecksum(usize),
    /// Leading bytes that are not a frame.
    Noise(usize),
}

/// Finds the first protocol-1.0 frame in `buf`. A protocol-2.0 header (FF FF FD 00) is not
/// one: on a mixed bus the other protocol's packets are skipped.
pub fn parse(buf: &[u8]) -> Parsed {
    let mut i = 0;
    while i + 1 < buf.len() {
        if buf[i] == 0xFF && buf[i + 1] == 0xFF {
            let Some(&id) = buf.get(i + 2) else {
                return Parsed::Incomplete;
            };
            if id == 0xFF {
                i += 1; // FF FF FF: the header starts one later
                continue;
            }
            if id == 0xFD {
                // Protocol 2.0 (FF FF FD 00): not ours.
                return Parsed::Noise(i + 3);
            }
            let Some(&len) = buf.get(i + 3) else {
                return Parsed::Incomplete;
            };
            if len < 2 {
                return Parsed::Noise(i + 4);
            }
            let total = 4 + usize::from(len);
            if buf.len() < i + total {
                return Parsed::Incomplete;
            }
            let code = buf[i + 4];
            let params = buf[i + 5..i + total - 1].to_vec();
            if checksum(id, len, code, &params) != buf[i + total - 1] {
                return Parsed::BadChecksum(i + total);
            }
            return Parsed::Frame(Frame { id, code, params }, i + total);
        }
        i += 1;
    }
    match buf.len() {
        0 | 1 => Parsed::Incomplete,
        n => Parsed::Noise(n - 1),
    }
}

/// Errors of a protocol-1.0 transfer (the caller names the servo and the bus).
#[derive(Debug, Error)]
pub enum Error {
    #[error("no reply within {timeout_ms} ms")]
    Timeout { timeout_ms: u64 },
    #[error("reply with a wrong checksum")]
    Checksum,
    #[error("reply from servo {from} instead")]
    WrongId { from: u8 },
    #[error("error status 0x{status:02x}")]
    Status { status: u8 },
    #[error("reply of {got} bytes, {want} expected")]
    Length { got: usize, want: usize },
    #[error("serial port: {0}")]
    Io(#[from] std::io::Error),
}

/// A protocol-1.0 client on a serial port.
#[derive(Debug)]
pub struct Bus1 {
    port: SerialPort,
    timeout: Duration,
    buf: Vec<u8>,
}

impl Bus1 {
    /// A client with a per-reply timeout.
    pub fn new(port: SerialPort, timeout: Duration) -> Self {
        Self {
            port,
            timeout,
            buf: Vec::new(),
        }
    }

    fn transfer(&mut self, id: u8, code: u8, params: &[u8], want: usize) -> Result<Vec<u8>, Error> {
        self.buf.clear();
        let request = Frame {
            id,
            code,
            params: params.to_vec(),
        };
        crate::line::send(&self.port, &request.encode())?;
        let deadline = Instant::now() + self.timeout;
        loop {
            match parse(&self.buf) {
                Parsed::Frame(f, n) => {
                    self.buf.drain(..n);
                    if f.id != id {
                        return Err(Error::WrongId { from: f.id });
                    }
                    if f.code & 0x7F != 0 {
                        return Err(Error::Status { status: f.code });
                    }
                    if f.params.len() != want {
                        return Err(Error::Length {
                            got: f.params.len(),
                            want,
                        });
                    }
                    return Ok(f.params);
                }
                Parsed::BadChecksum(_) => return Err(Error::Checksum),
                Parsed::Noise(n) => {
                    self.buf.drain(..n);
                    continue;
                }
                Parsed::Incomplete => {}
            }
            if !crate::line::receive(&mut self.port, &mut self.buf, deadline)? {
                return Err(Error::Timeout {
                    timeout_ms: self.timeout.as_millis() as u64,
                });
            }
        }
    }

    /// Pings a servo; returns its model number (read from the table: a 1.0 ping has no data).
    pub fn ping(&mut self, id: u8) -> Result<u16, Error> {
        self.transfer(id, 0x01, &[], 0)?;
        self.read_u16(id, 0)
    }

    /// Reads `count` bytes at `address`.
    pub fn read(&mut self, id: u8, address: u8, count: u8) -> Result<Vec<u8>, Error> {
        self.transfer(id, 0x02, &[address, count], usize::from(count))
    }

    pub fn read_u16(&mut self, id: u8, address: u8) -> Result<u16, Error> {
        let b = self.read(id, address, 2)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    /// Writes bytes at `address`.
    pub fn write(&mut self, id: u8, address: u8, data: &[u8]) -> Result<(), Error> {
        let mut p = vec![address];
        p.extend_from_slice(data);
        self.transfer(id, 0x03, &p, 0).map(|_| ())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_match_the_manuals_example_and_round_trip() {
        // ROBOTIS e-manual, protocol 1.0: read the internal temperature of ID 1:
        // FF FF 01 04 02 2B 01 CC.
        let f = Frame {
            id: 1,
            code: 0x02,
            params: vec![0x2B, 0x01],
        };
        assert_eq!(f.encode(), [0xFF, 0xFF, 0x01, 0x04, 0x02, 0x2B, 0x01, 0xCC]);
        let mut wire = vec![0x00, 0xFF];
        wire.extend(f.encode());
        assert_eq!(parse(&wire), Parsed::Frame(f, wire.len()));
        // A protocol-2.0 ping is skipped on a mixed bus.
        assert_eq!(
            parse(&[0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x03, 0x00, 0x01, 0x19, 0x4E]),
            Parsed::Noise(3)
        );
        let n = wire.len();
        wire[n - 1] ^= 1;
        assert_eq!(parse(&wire), Parsed::BadChecksum(n));
    }
}
