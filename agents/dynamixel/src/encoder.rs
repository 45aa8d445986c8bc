//! The deflection encoder through a serial bridge (`interface = "serial"` in the config), as
//! paper B reads its AS5048A through an Arduino: the bridge reads the encoders over SPI when
//! asked and answers on a serial line. The frames (our definition, documented here for the
//! bridge's firmware):
//!
//! ```text
//! request   A5 | N                                  read encoders 0..N-1
//! reply     5A | N | (ANGLE_L ANGLE_H FLAGS) × N | CHECKSUM
//! ```
//! ANGLE is the AS5048A's 14-bit angle (0..16383), FLAGS bit 0 its error flag (a parity or
//! framing error on SPI), bit 1 a magnet out of range (the diagnostics register's COMP
//! bits). CHECKSUM = !(sum of every reply byte before it), low byte. Asking per tick keeps
//! the encoder sampled in step with the servos.
//!
//! The bench's torque reference, a load cell through an HX711 amplifier on the same bridge:
//!
//! ```text
//! request   A6 | N                                  read load cells 0..N-1
//! reply     6A | N | (V_0 V_1 V_2 FLAGS) × N | CHECKSUM
//! ```
//! V is the HX711's latest 24-bit conversion, two's complement, low byte first; FLAGS bit 0:
//! a new conversion since the previous reply (the HX711 converts at 10 or 80 Hz: between
//! conversions the bridge repeats the last), bit 1: no HX711 answering (its data line has not
//! gone low for 200 ms). The config gives each channel's zero and scale.

use std::time::{Duration, Instant};

use serial2::SerialPort;
use thiserror::Error;

/// Request and reply markers.
pub const REQUEST: u8 = 0xA5;
pub const REPLY: u8 = 0x5A;
/// AS5048A counts per revolution.
pub const COUNTS: u16 = 16384;
/// Load-cell request and reply markers.
pub const LOAD_REQUEST: u8 = 0xA6;
pub const LOAD_REPLY: u8 = 0x6A;
/// The HX711's range: a 24-bit two's complement conversion.
pub const LOAD_MIN: i32 = -(1 << 23);
pub const LOAD_MAX: i32 = (1 << 23) - 1;

/// One load cell's reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LoadReading {
    /// The amplifier's conversion (24 bits, sign-extended).
    pub raw: i32,
    /// A new conversion since the previous reply.
    pub fresh: bool,
    /// No amplifier answers on this channel.
    pub missing: bool,
}

impl LoadReading {
    /// The conversion that reads `nm` [N·m] with `zero` counts at no load and `nm_per_count`
    /// (to the nearest count, within the 24-bit range).
    pub fn raw_at(nm: f64, zero: i32, nm_per_count: f64) -> i32 {
        let c = (nm / nm_per_count).round() + f64::from(zero);
        c.clamp(f64::from(LOAD_MIN), f64::from(LOAD_MAX)) as i32
    }

    /// The torque [N·m] this conversion reads.
    pub fn nm_from(&self, zero: i32, nm_per_count: f64) -> f64 {
        f64::from(self.raw - zero) * nm_per_count
    }
}

/// The load-cell reply frame for `readings`.
pub fn encode_load_reply(readings: &[LoadReading]) -> Vec<u8> {
    let mut out = vec![LOAD_REPLY, readings.len() as u8];
    for r in readings {
        out.extend_from_slice(&r.raw.clamp(LOAD_MIN, LOAD_MAX).to_le_bytes()[..3]);
        out.push(u8::from(r.fresh) | (u8::from(r.missing) << 1));
    }
    out.push(checksum(&out));
    out
}

/// One channel of a load-cell reply: 3 bytes of value (sign-extended from bit 23) and flags.
fn parse_load(c: &[u8]) -> LoadReading {
    LoadReading {
        raw: i32::from_le_bytes([c[0], c[1], c[2], if c[2] & 0x80 != 0 { 0xFF } else { 0 }]),
        fresh: c[3] & 1 != 0,
        missing: c[3] & 2 != 0,
    }
}

/// One channel of an encoder reply.
fn parse_angle(c: &[u8]) -> Reading {
    Reading {
        counts: u16::from_le_bytes([c[0], c[1]]) & 0x3FFF,
        error: c[2] & 1 != 0,
        magnet: c[2] & 2 != 0,
    }
}

/// A request kind: its markers, each channel's bytes and how to read them.
struct Frame<T> {
    request: u8,
    reply: u8,
    item: usize,
    parse: fn(&[u8]) -> T,
}

const ANGLES: Frame<Reading> = Frame {
    request: REQUEST,
    reply: REPLY,
    item: 3,
    parse: parse_angle,
};

const LOADS: Frame<LoadReading> = Frame {
    request: LOAD_REQUEST,
    reply: LOAD_REPLY,
    item: 4,
    parse: parse_load,
};

/// One encoder's reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reading {
    pub counts: u16,
    /// The sensor flagged an SPI error.
    pub error: bool,
    /// The magnet is too far or too close.
    pub magnet: bool,
}

impl Reading {
    /// The count that reads `rad` from `zero` (the inverse of [`Self::rad_from`], to the
    /// nearest count): what a sensor at that angle shows.
    pub fn counts_at(rad: f64, zero: u16) -> u16 {
        let c = (rad * f64::from(COUNTS) / std::f64::consts::TAU).round() as i64;
        (c + i64::from(zero)).rem_euclid(i64::from(COUNTS)) as u16
    }

    /// The angle [rad] in [−π, π) from `zero` counts.
    pub fn rad_from(&self, zero: u16) -> f64 {
        let d = (i32::from(self.counts) - i32::from(zero)).rem_euclid(i32::from(COUNTS));
        let d = if d >= i32::from(COUNTS) / 2 {
            d - i32::from(COUNTS)
        } else {
            d
        };
        f64::from(d) * std::f64::consts::TAU / f64::from(COUNTS)
    }
}

/// The reply frame for `readings`.
pub fn encode_reply(readings: &[Reading]) -> Vec<u8> {
    let mut out = vec![REPLY, readings.len() as u8];
    for r in readings {
        out.extend_from_slice(&(r.counts & 0x3FFF).to_le_bytes());
        out.push(u8::from(r.error) | (u8::from(r.magnet) << 1));
    }
    out.push(checksum(&out));
    out
}

/// A reply's checksum: the complement of the sum of its bytes before it, low byte.
fn checksum(bytes: &[u8]) -> u8 {
    !bytes.iter().fold(0u8, |s, b| s.wrapping_add(*b))
}

#[derive(Debug, Error)]
pub enum EncoderError {
    #[error("{bridge}: no reply within {timeout_ms} ms (gave up after {attempts} attempts)")]
    Timeout {
        bridge: String,
        timeout_ms: u64,
        attempts: u32,
    },
    #[error("{bridge}: reply with a wrong checksum (gave up after {attempts} attempts)")]
    Checksum { bridge: String, attempts: u32 },
    #[error("{bridge}: encoder {index} reports {what}")]
    Sensor {
        bridge: String,
        index: usize,
        what: &'static str,
    },
    #[error(
        "{bridge}: load cell {index} does not answer (its HX711's data line has not gone low for 200 ms: check its wiring and power)"
    )]
    LoadCell { bridge: String, index: usize },
    #[error("{bridge}: {source}")]
    Io {
        bridge: String,
        source: std::io::Error,
    },
}

/// Why one request failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fail {
    Timeout,
    Checksum,
}

/// The bridge, seen from the joint board.
#[derive(Debug)]
pub struct EncoderBridge {
    name: String,
    baud: u32,
    port: SerialPort,
    timeout: Duration,
    pub retries: u32,
}

impl EncoderBridge {
    pub fn new(port: SerialPort, name: &str, timeout: Duration) -> Self {
        Self {
            name: name.to_string(),
            baud: 0,
            port,
            timeout,
            retries: 2,
        }
    }

    /// Opens the bridge at `path`.
    pub fn open(
        path: &std::path::Path,
        baud: u32,
        timeout: Duration,
    ) -> Result<Self, EncoderError> {
        let name = path.display().to_string();
        let port = SerialPort::open(path, baud).map_err(|source| EncoderError::Io {
            bridge: name.clone(),
            source,
        })?;
        let mut b = Self::new(port, &name, timeout);
        b.baud = baud;
        Ok(b)
    }

    /// The port's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The baud rate it was opened at (0 for a port opened elsewhere).
    pub fn baud(&self) -> u32 {
        self.baud
    }

    /// Reads `n` encoders; a sensor's error or magnet flag is an error naming it.
    pub fn read(&mut self, n: u8) -> Result<Vec<Reading>, EncoderError> {
        let r = self.exchange(&ANGLES, n)?;
        for (index, x) in r.iter().enumerate() {
            let what = if x.error {
                "an SPI error"
            } else if x.magnet {
                "its magnet out of range"
            } else {
                continue;
            };
            return Err(EncoderError::Sensor {
                bridge: self.name.clone(),
                index,
                what,
            });
        }
        Ok(r)
    }

    /// Reads `n` load cells; a channel without an amplifier is an error naming it.
    pub fn read_loads(&mut self, n: u8) -> Result<Vec<LoadReading>, EncoderError> {
        let r = self.exchange(&LOADS, n)?;
        if let Some(index) = r.iter().position(|x| x.missing) {
            return Err(EncoderError::LoadCell {
                bridge: self.name.clone(),
                index,
            });
        }
        Ok(r)
    }

    /// One request of kind `f` for `n` channels, retried on a timeout or a bad reply.
    fn exchange<T>(&mut self, f: &Frame<T>, n: u8) -> Result<Vec<T>, EncoderError> {
        let attempts = self.retries + 1;
        let mut last = Fail::Timeout;
        for _ in 0..attempts {
            match self.transfer(f, n)? {
                Ok(r) => return Ok(r),
                Err(e) => last = e,
            }
        }
        if last == Fail::Checksum {
            return Err(EncoderError::Checksum {
                bridge: self.name.clone(),
                attempts,
            });
        }
        Err(EncoderError::Timeout {
            bridge: self.name.clone(),
            timeout_ms: self.timeout.as_millis() as u64,
            attempts,
        })
    }

    /// One request; a timeout or a bad reply is an inner error (retried).
    fn transfer<T>(&mut self, f: &Frame<T>, n: u8) -> Result<Result<Vec<T>, Fail>, EncoderError> {
        let io = |source| EncoderError::Io {
            bridge: self.name.clone(),
            source,
        };
        crate::line::send(&self.port, &[f.request, n]).map_err(io)?;
        let want = 3 + f.item * usize::from(n);
        let mut buf: Vec<u8> = Vec::with_capacity(want);
        let deadline = Instant::now() + self.timeout;
        loop {
            // Skip anything before the reply marker.
            if let Some(k) = buf.iter().position(|b| *b == f.reply) {
                buf.drain(..k);
            } else {
                buf.clear();
            }
            if buf.len() >= want {
                let body = &buf[..want - 1];
                if buf[1] != n || checksum(body) != buf[want - 1] {
                    return Ok(Err(Fail::Checksum));
                }
                return Ok(Ok(body[2..].chunks(f.item).map(f.parse).collect()));
            }
            let in_time =
                crate::line::receive(&mut self.port, &mut buf, deadline).map_err(|source| {
                    EncoderError::Io {
                        bridge: self.name.clone(),
                        source,
                    }
                })?;
            if !in_time {
                return Ok(Err(Fail::Timeout));
            }
        }
    }
}

/// A virtual bridge for tests: answers requests on one end of a pseudo-terminal pair with the
/// readings in [`VirtualState::readings`], with injected faults.
#[derive(Debug)]
pub struct VirtualEncoders {
    pub state: std::sync::Arc<std::sync::Mutex<VirtualState>>,
    device: crate::pty::PtyDevice,
}

/// What the virtual bridge answers.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VirtualState {
    pub readings: Vec<Reading>,
    /// The load cells' readings (none: a bridge without load cells answers N = 0).
    pub loads: Vec<LoadReading>,
    /// Replies to drop, and replies to corrupt, from the next one on.
    pub drop_replies: u32,
    pub corrupt_replies: u32,
}

impl VirtualEncoders {
    /// Starts the bridge; returns it and the client end of the line.
    pub fn start(readings: Vec<Reading>) -> std::io::Result<(Self, SerialPort)> {
        let state = std::sync::Arc::new(std::sync::Mutex::new(VirtualState {
            readings,
            ..Default::default()
        }));
        let shared = state.clone();
        let (device, client) = crate::pty::PtyDevice::start(move |buf| {
            let mut replies = Vec::new();
            while let Some(k) = buf.iter().position(|b| *b == REQUEST || *b == LOAD_REQUEST) {
                if buf.len() < k + 2 {
                    break;
                }
                let (kind, n) = (buf[k], usize::from(buf[k + 1]));
                buf.drain(..k + 2);
                let mut st = shared.lock().unwrap_or_else(|p| p.into_inner());
                if st.drop_replies > 0 {
                    st.drop_replies -= 1;
                    continue;
                }
                let mut reply = if kind == REQUEST {
                    encode_reply(&st.readings.iter().copied().take(n).collect::<Vec<_>>())
                } else if n <= st.loads.len() {
                    // As the firmware: more channels than wired is answered with none.
                    encode_load_reply(&st.loads[..n])
                } else {
                    encode_load_reply(&[])
                };
                if st.corrupt_replies > 0 {
                    st.corrupt_replies -= 1;
                    let last = reply.len() - 1;
                    reply[last] ^= 0x33;
                }
                replies.push((Duration::ZERO, reply));
            }
            replies
        })?;
        Ok((Self { state, device }, client))
    }

    /// Starts the bridge and gives the client end's device path for another process to open
    /// (see [`crate::pty::PtyDevice::hold_with_path`]).
    pub fn start_with_path(readings: Vec<Reading>) -> std::io::Result<(Self, std::path::PathBuf)> {
        let (mut bridge, client) = Self::start(readings)?;
        let path = bridge.device.hold_with_path(client)?;
        Ok((bridge, path))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(counts: u16) -> Reading {
        Reading {
            counts,
            error: false,
            magnet: false,
        }
    }

    #[test]
    fn angles_wrap_around_the_zero() {
        assert_eq!(at(100).rad_from(100), 0.0);
        let one = std::f64::consts::TAU / 16384.0;
        assert!((at(5).rad_from(16380) - 9.0 * one).abs() < 1e-15);
        assert!((at(16380).rad_from(5) + 9.0 * one).abs() < 1e-15);
        assert!((at(8192).rad_from(0) + std::f64::consts::PI).abs() < 1e-15);
        // The inverse, across the wrap.
        for (rad, zero) in [
            (0.0, 100),
            (9.0 * one, 16380),
            (-9.0 * one, 5),
            (-0.7, 8192),
        ] {
            let c = Reading::counts_at(rad, zero);
            assert!(
                (at(c).rad_from(zero) - rad).abs() <= 0.5 * one,
                "{rad} from {zero}"
            );
        }
        assert_eq!(Reading::counts_at(9.0 * one, 16380), 5);
    }

    #[test]
    fn the_bridge_reads_retries_and_names_what_fails() {
        let (v, port) = VirtualEncoders::start(vec![at(1000), at(16383), at(0)]).unwrap();
        let mut b = EncoderBridge::new(port, "/dev/bridge", Duration::from_millis(30));
        let r = b.read(3).unwrap();
        assert_eq!(
            r.iter().map(|r| r.counts).collect::<Vec<_>>(),
            [1000, 16383, 0]
        );
        v.state.lock().unwrap().drop_replies = 1;
        v.state.lock().unwrap().corrupt_replies = 1;
        assert_eq!(
            b.read(2).unwrap().len(),
            2,
            "one lost and one corrupt reply are retried"
        );
        v.state.lock().unwrap().corrupt_replies = 10;
        let e = b.read(1).unwrap_err().to_string();
        assert_eq!(
            e,
            "/dev/bridge: reply with a wrong checksum (gave up after 3 attempts)"
        );
        v.state.lock().unwrap().corrupt_replies = 0;
        v.state.lock().unwrap().drop_replies = 10;
        let e = b.read(1).unwrap_err().to_string();
        assert_eq!(
            e,
            "/dev/bridge: no reply within 30 ms (gave up after 3 attempts)"
        );
        v.state.lock().unwrap().drop_replies = 0;
        v.state.lock().unwrap().readings[1].magnet = true;
        let e = b.read(3).unwrap_err().to_string();
        assert_eq!(e, "/dev/bridge: encoder 1 reports its magnet out of range");
    }

    #[test]
    fn load_cells_read_signed_24_bit_conversions_and_a_silent_amplifier_is_named() {
        // 0.5 mN·m per count, zero at 1000 counts: ±2 N·m and the ends of the 24-bit range.
        let (zero, scale) = (1000, 5e-4);
        let loads: Vec<LoadReading> = [2.0, -2.0, 1e9, -1e9]
            .iter()
            .map(|&nm| LoadReading {
                raw: LoadReading::raw_at(nm, zero, scale),
                fresh: nm > 0.0,
                missing: false,
            })
            .collect();
        assert_eq!(
            loads.iter().map(|l| l.raw).collect::<Vec<_>>(),
            [5000, -3000, LOAD_MAX, LOAD_MIN]
        );
        let (v, port) = VirtualEncoders::start(vec![at(7)]).unwrap();
        v.state.lock().unwrap().loads = loads.clone();
        let mut b = EncoderBridge::new(port, "/dev/bridge", Duration::from_millis(30));
        let r = b.read_loads(4).unwrap();
        assert_eq!(r, loads, "sign, range and flags survive the frame");
        assert!((r[0].nm_from(zero, scale) - 2.0).abs() < 1e-12);
        assert!((r[1].nm_from(zero, scale) + 2.0).abs() < 1e-12);
        assert_eq!(b.read(1).unwrap()[0].counts, 7, "both kinds on one line");
        v.state.lock().unwrap().corrupt_replies = 1;
        assert_eq!(
            b.read_loads(2).unwrap().len(),
            2,
            "a corrupt reply is retried"
        );
        v.state.lock().unwrap().loads[1].missing = true;
        let e = b.read_loads(2).unwrap_err().to_string();
        assert!(
            e.starts_with("/dev/bridge: load cell 1 does not answer"),
            "{e}"
        );
        // More channels than wired: answered with none, which times out naming the bridge.
        let e = b.read_loads(5).unwrap_err().to_string();
        assert!(e.contains("no reply"), "{e}");
    }
}
