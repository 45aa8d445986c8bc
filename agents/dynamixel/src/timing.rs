//! What a bus cycle costs on the wire: bytes of each transfer at a baud rate (10 bits a byte:
//! start, 8 data, stop), the theoretical limit a measured cycle is set against.
//!
//! Packet sizes (ROBOTIS e-manual):
//! - protocol 2.0 sync read of `n` servos, `size` bytes each: instruction
//!   `FF FF FD 00 | ID | LEN×2 | INST | ADDR×2 | SIZE×2 | ID×n | CRC×2` = 14 + n bytes, then
//!   one status packet per servo `FF FF FD 00 | ID | LEN×2 | 55 | ERR | DATA×size | CRC×2`
//!   = 11 + size bytes;
//! - protocol 1.0 read: `FF FF | ID | LEN | INST | ADDR | SIZE | CHK` = 8 bytes, status
//!   `FF FF | ID | LEN | ERR | DATA×size | CHK` = 6 + size bytes;
//! - protocol 1.0 write of `size` bytes: 7 + size bytes, status 6 bytes;
//! - the encoder bridge ([`crate::encoder`]): request 2 bytes, reply 3 + 3n bytes.
//!
//! Each status packet also waits the servo's Return Delay Time (2 µs a unit; 250 = 500 µs
//! by default on the XH540 and the AX-12A — set it to 0 on the rig).

/// Bytes on the wire of one protocol-2.0 sync read of `n` servos, `size` bytes each.
pub fn sync_read_bytes(n: usize, size: usize) -> usize {
    if n == 0 { 0 } else { 14 + n + n * (11 + size) }
}

/// Bytes of one protocol-1.0 read of `size` bytes.
pub fn read1_bytes(size: usize) -> usize {
    8 + 6 + size
}

/// Bytes of one protocol-1.0 write of `size` bytes and its status.
pub fn write1_bytes(size: usize) -> usize {
    7 + size + 6
}

/// Bytes of one encoder-bridge request for `n` encoders and its reply.
pub fn bridge_bytes(n: usize) -> usize {
    2 + 3 + 3 * n
}

/// Bytes of one load-cell exchange with the bridge for `n` channels (request 2, reply 3 + 4·n).
pub fn load_bytes(n: usize) -> usize {
    2 + 3 + 4 * n
}

/// Time [s] on the wire of `bytes` at `baud`.
pub fn wire_s(bytes: usize, baud: u32) -> f64 {
    bytes as f64 * 10.0 / f64::from(baud.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol2::{Packet, STATUS, instruction};

    #[test]
    fn sizes_match_the_packets_this_crate_encodes() {
        // A sync-read instruction of 4 IDs as protocol2 builds it, and one status reply.
        let req = Packet {
            id: 0xFE,
            instruction: instruction::SYNC_READ,
            params: vec![132, 0, 4, 0, 1, 2, 3, 4],
        }
        .encode();
        let status = Packet {
            id: 1,
            instruction: STATUS,
            params: vec![0, 1, 2, 3, 4],
        }
        .encode();
        assert_eq!(req.len() + 4 * status.len(), sync_read_bytes(4, 4));
        let f = crate::protocol1::Frame {
            id: 11,
            code: 0x02,
            params: vec![36, 2],
        }
        .encode();
        let s = crate::protocol1::Frame {
            id: 11,
            code: 0,
            params: vec![0, 2],
        }
        .encode();
        assert_eq!(f.len() + s.len(), read1_bytes(2));
        assert_eq!(
            crate::encoder::encode_reply(
                &[crate::encoder::Reading {
                    counts: 0,
                    error: false,
                    magnet: false
                }; 4]
            )
            .len()
                + 2,
            bridge_bytes(4)
        );
        // 94 bytes at 1 Mbaud: 0.94 ms.
        assert!(
            (wire_s(sync_read_bytes(4, 4) + read1_bytes(2), 1_000_000) - 0.94e-3).abs() < 1e-12
        );
    }
}
