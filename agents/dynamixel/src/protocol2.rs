//! Dynamixel protocol 2.0, device side: instruction packets in, status packets out.
//!
//! ```text
//! FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAM… | CRC_L CRC_H
//! ```
//! LEN counts the bytes after itself (instruction, parameters, CRC). Between the header and
//! the CRC, every `FF FF FD` is followed by a stuffed `FD`. The CRC is CRC-16 with polynomial
//! 0x8005, initial value 0, not reflected, over everything before it (stuffed).

/// The packet header.
pub const HEADER: [u8; 4] = [0xFF, 0xFF, 0xFD, 0x00];
/// The broadcast ID.
pub const BROADCAST: u8 = 0xFE;
/// The instruction byte of a status packet.
pub const STATUS: u8 = 0x55;

/// Instruction codes.
pub mod instruction {
    pub const PING: u8 = 0x01;
    pub const READ: u8 = 0x02;
    pub const WRITE: u8 = 0x03;
    pub const SYNC_READ: u8 = 0x82;
    pub const SYNC_WRITE: u8 = 0x83;
}

/// Error codes of a status packet (the low 7 bits; bit 7 is the hardware alert).
pub mod error {
    pub const INSTRUCTION: u8 = 0x02;
    pub const DATA_LENGTH: u8 = 0x05;
    pub const ACCESS: u8 = 0x07;
}

/// CRC-16 of the protocol.
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    for &b in data {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x8005
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// Adds the stuffing byte after every `FF FF FD`.
pub fn stuff(body: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(body.len() + 4);
    for &b in body {
        out.push(b);
        let n = out.len();
        if n >= 3 && out[n - 3..] == [0xFF, 0xFF, 0xFD] {
            out.push(0xFD);
        }
    }
    out
}

/// Removes the stuffing byte after every `FF FF FD`.
pub fn unstuff(body: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(body.len());
    let mut i = 0;
    while i < body.len() {
        out.push(body[i]);
        let n = out.len();
        if n >= 3 && out[n - 3..] == [0xFF, 0xFF, 0xFD] && body.get(i + 1) == Some(&0xFD) {
            i += 1;
        }
        i += 1;
    }
    out
}

/// A packet: its ID, instruction (or [`STATUS`]) and unstuffed parameters.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Packet {
    pub id: u8,
    pub instruction: u8,
    pub params: Vec<u8>,
}

impl Packet {
    /// The bytes on the wire.
    pub fn encode(&self) -> Vec<u8> {
        let mut body = vec![self.instruction];
        body.extend_from_slice(&self.params);
        let body = stuff(&body);
        let len = (body.len() + 2) as u16;
        let mut out = HEADER.to_vec();
        out.push(self.id);
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&body);
        let crc = crc16(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        out
    }

    /// A status packet: error byte, then the parameters.
    pub fn status(id: u8, error: u8, params: &[u8]) -> Self {
        let mut p = vec![error];
        p.extend_from_slice(params);
        Self {
            id,
            instruction: STATUS,
            params: p,
        }
    }
}

/// What [`parse`] found at the start of a buffer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Parsed {
    /// Not enough bytes yet.
    Incomplete,
    /// A packet and the bytes it used (from the start of the buffer, skipped noise included).
    Packet(Packet, usize),
    /// A complete packet whose CRC is wrong (a real servo ignores it), and the bytes it used.
    BadCrc(usize),
    /// No header: this many leading bytes are noise.
    Noise(usize),
}

/// Finds the first packet in `buf`.
pub fn parse(buf: &[u8]) -> Parsed {
    let Some(start) = buf.windows(4).position(|w| w == HEADER) else {
        // Keep a possible partial header at the end.
        return match buf.len() {
            0..=3 => Parsed::Incomplete,
            n => Parsed::Noise(n - 3),
        };
    };
    let rest = &buf[start..];
    if rest.len() < 7 {
        return Parsed::Incomplete;
    }
    let len = usize::from(u16::from_le_bytes([rest[5], rest[6]]));
    let total = 7 + len;
    if len < 3 {
        return Parsed::BadCrc(start + 7);
    }
    if rest.len() < total {
        return Parsed::Incomplete;
    }
    let crc = u16::from_le_bytes([rest[total - 2], rest[total - 1]]);
    if crc16(&rest[..total - 2]) != crc {
        return Parsed::BadCrc(start + total);
    }
    let body = unstuff(&rest[7..total - 2]);
    Parsed::Packet(
        Packet {
            id: rest[4],
            instruction: body[0],
            params: body[1..].to_vec(),
        },
        start + total,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_matches_the_manuals_ping_example() {
        // ROBOTIS e-manual, protocol 2.0, ping of ID 1: FF FF FD 00 01 03 00 01 19 4E.
        let p = Packet {
            id: 1,
            instruction: instruction::PING,
            params: vec![],
        };
        assert_eq!(
            p.encode(),
            [0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x03, 0x00, 0x01, 0x19, 0x4E]
        );
        // CRC-16/BUYPASS check value.
        assert_eq!(crc16(b"123456789"), 0xFEE8);
    }

    #[test]
    fn stuffing_round_trips_and_parse_skips_noise_and_bad_crcs() {
        let params = vec![0xFF, 0xFF, 0xFD, 0x01, 0xFF, 0xFF, 0xFD];
        assert_eq!(unstuff(&stuff(&params)), params);
        let p = Packet {
            id: 7,
            instruction: instruction::WRITE,
            params,
        };
        let mut wire = vec![0x00, 0x12];
        wire.extend(p.encode());
        match parse(&wire) {
            Parsed::Packet(q, used) => {
                assert_eq!(q, p);
                assert_eq!(used, wire.len());
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(parse(&wire[..wire.len() - 1]), Parsed::Incomplete);
        let n = wire.len();
        wire[n - 1] ^= 1;
        assert_eq!(parse(&wire), Parsed::BadCrc(n));
    }
}
