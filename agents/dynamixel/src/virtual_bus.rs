//! Virtual servos for tests without hardware: control tables in memory that answer
//! protocol-2.0 instruction packets on one end of a pseudo-terminal pair, while the client
//! (dynamixel2, as on the real bus) talks to the other end. Faults can be injected per servo:
//! dropped replies, corrupt checksums, late replies.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use serial2::SerialPort;

use crate::models::Model;
use crate::protocol1;
use crate::protocol2::{BROADCAST, Packet, Parsed, error, instruction, parse};
use crate::pty::{PtyDevice, Reply};

/// Faults to inject into a servo's next replies.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Faults {
    /// Replies to drop (the servo stays silent, as if missing).
    pub drop_replies: u32,
    /// Replies whose checksum is corrupted.
    pub corrupt_replies: u32,
    /// Delay before each reply.
    pub delay: Duration,
}

/// One virtual servo: its model and control table.
#[derive(Debug, Clone)]
pub struct VirtualServo {
    pub model: Model,
    pub table: Vec<u8>,
    pub faults: Faults,
    /// Instructions received (for tests).
    pub received: u64,
}

impl VirtualServo {
    pub fn new(model: Model, id: u8) -> Self {
        let mut table = vec![0u8; usize::from(model.table_size)];
        let put = |t: &mut Vec<u8>, a: u16, bytes: &[u8]| {
            let a = usize::from(a);
            t[a..a + bytes.len()].copy_from_slice(bytes);
        };
        put(
            &mut table,
            model.model_number.address,
            &model.number.to_le_bytes(),
        );
        put(&mut table, model.firmware.address, &[45]);
        put(&mut table, model.id.address, &[id]);
        Self {
            model,
            table,
            faults: Faults::default(),
            received: 0,
        }
    }

    /// A field's value (little-endian, up to 4 bytes).
    pub fn get(&self, f: crate::models::Field) -> u32 {
        let a = usize::from(f.address);
        let mut b = [0u8; 4];
        b[..usize::from(f.size)].copy_from_slice(&self.table[a..a + usize::from(f.size)]);
        u32::from_le_bytes(b)
    }

    /// Sets a field (the plant side: present position, for instance).
    pub fn set(&mut self, f: crate::models::Field, v: u32) {
        let a = usize::from(f.address);
        let n = usize::from(f.size);
        self.table[a..a + n].copy_from_slice(&v.to_le_bytes()[..n]);
    }

    fn read(&self, address: u16, count: u16) -> Result<Vec<u8>, u8> {
        let (a, n) = (usize::from(address), usize::from(count));
        self.table
            .get(a..a + n)
            .map(<[u8]>::to_vec)
            .ok_or(error::ACCESS)
    }

    fn write(&mut self, address: u16, data: &[u8]) -> Result<(), u8> {
        if !self.model.may_write(address, data.len() as u16) {
            return Err(error::ACCESS);
        }
        let a = usize::from(address);
        self.table[a..a + data.len()].copy_from_slice(data);
        Ok(())
    }
}

/// Servos by ID, shared between the bus thread and the test.
pub type Servos = Arc<Mutex<BTreeMap<u8, VirtualServo>>>;

/// A virtual bus serving servos on one end of a pseudo-terminal pair.
#[derive(Debug)]
pub struct VirtualBus {
    pub servos: Servos,
    device: PtyDevice,
}

impl VirtualBus {
    /// Opens a pseudo-terminal pair, serves `servos` on one end and returns the other end for
    /// the client.
    pub fn start(servos: Vec<VirtualServo>) -> std::io::Result<(Self, SerialPort)> {
        let map: BTreeMap<u8, VirtualServo> = servos
            .into_iter()
            .map(|s| (s.get(s.model.id) as u8, s))
            .collect();
        let servos: Servos = Arc::new(Mutex::new(map));
        let shared = servos.clone();
        let (device, client) = PtyDevice::start(move |buf| {
            let mut replies = Vec::new();
            loop {
                let (request, used) = match parse_any(buf) {
                    Any::Incomplete => break,
                    Any::Skip(n) => (None, n),
                    Any::Request(r, n) => (Some(r), n),
                };
                buf.drain(..used);
                if let Some(r) = request {
                    let mut s = shared.lock().unwrap_or_else(|p| p.into_inner());
                    replies.extend(answer(&mut s, &r));
                }
            }
            replies
        })?;
        Ok((Self { servos, device }, client))
    }

    /// Starts the bus and gives the client end's device path (e.g. /dev/pts/3) for another
    /// process to open (see [`PtyDevice::hold_with_path`]).
    pub fn start_with_path(servos: Vec<VirtualServo>) -> std::io::Result<(Self, PathBuf)> {
        let (mut bus, client) = Self::start(servos)?;
        let path = bus.device.hold_with_path(client)?;
        Ok((bus, path))
    }

    /// The servos, locked.
    pub fn lock(&self) -> MutexGuard<'_, BTreeMap<u8, VirtualServo>> {
        self.servos.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// An instruction of either protocol.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Request {
    protocol: u8,
    id: u8,
    instruction: u8,
    params: Vec<u8>,
}

enum Any {
    Incomplete,
    Skip(usize),
    Request(Request, usize),
}

/// The first packet of either protocol (a bus may mix them: 2.0 starts FF FF FD 00).
fn parse_any(buf: &[u8]) -> Any {
    let Some(i) = buf.windows(2).position(|w| w == [0xFF, 0xFF]) else {
        return match buf.len() {
            0 | 1 => Any::Incomplete,
            n => Any::Skip(n - 1),
        };
    };
    let Some(&third) = buf.get(i + 2) else {
        return Any::Incomplete;
    };
    if third == 0xFD {
        match parse(&buf[i..]) {
            Parsed::Incomplete => Any::Incomplete,
            Parsed::Noise(n) | Parsed::BadCrc(n) => Any::Skip(i + n),
            Parsed::Packet(p, n) => Any::Request(
                Request {
                    protocol: 2,
                    id: p.id,
                    instruction: p.instruction,
                    params: p.params,
                },
                i + n,
            ),
        }
    } else {
        match protocol1::parse(&buf[i..]) {
            protocol1::Parsed::Incomplete => Any::Incomplete,
            protocol1::Parsed::Noise(n) | protocol1::Parsed::BadChecksum(n) => Any::Skip(i + n),
            protocol1::Parsed::Frame(f, n) => Any::Request(
                Request {
                    protocol: 1,
                    id: f.id,
                    instruction: f.code,
                    params: f.params,
                },
                i + n,
            ),
        }
    }
}

/// Protocol 1.0's range-error bit (1.0 has no access error).
const P1_RANGE: u8 = 0x08;
const P1_INSTRUCTION: u8 = 0x40;

/// The replies (delay, bytes) to one instruction, in bus order. Only servos of the packet's
/// protocol answer.
fn answer(servos: &mut BTreeMap<u8, VirtualServo>, r: &Request) -> Vec<Reply> {
    let p2 = r.protocol == 2;
    // Addresses and counts are 2 bytes in 2.0, 1 byte in 1.0.
    let w = if p2 { 2 } else { 1 };
    let num = |i: usize| -> Option<u16> {
        if p2 {
            Some(u16::from_le_bytes([
                *r.params.get(i)?,
                *r.params.get(i + 1)?,
            ]))
        } else {
            r.params.get(i).map(|b| u16::from(*b))
        }
    };
    let (access, bad_instruction) = if p2 {
        (error::ACCESS, error::INSTRUCTION)
    } else {
        (P1_RANGE, P1_INSTRUCTION)
    };
    let speaks = |s: &VirtualServo| s.model.protocol == r.protocol;
    let mut out: Vec<(u8, Result<Vec<u8>, u8>)> = Vec::new();
    match r.instruction {
        instruction::PING => {
            for (&id, s) in servos.iter() {
                if (r.id == id || r.id == BROADCAST) && speaks(s) {
                    let data = if p2 {
                        let mut d = s.model.number.to_le_bytes().to_vec();
                        d.push(s.get(s.model.firmware) as u8);
                        d
                    } else {
                        vec![]
                    };
                    out.push((id, Ok(data)));
                }
            }
        }
        instruction::READ => {
            if let (Some(s), Some(a), Some(n)) = (servos.get(&r.id), num(0), num(w))
                && speaks(s)
            {
                out.push((r.id, s.read(a, n).map_err(|_| access)));
            }
        }
        instruction::WRITE => {
            if let (Some(s), Some(a)) = (servos.get_mut(&r.id), num(0))
                && s.model.protocol == r.protocol
            {
                let res = s.write(a, &r.params[w..]).map(|()| vec![]);
                out.push((r.id, res.map_err(|_| access)));
            }
        }
        instruction::SYNC_READ if p2 => {
            if let (Some(a), Some(n)) = (num(0), num(2)) {
                for &id in r.params.get(4..).unwrap_or_default() {
                    if let Some(s) = servos.get(&id).filter(|s| speaks(s)) {
                        out.push((id, s.read(a, n)));
                    }
                }
            }
        }
        instruction::SYNC_WRITE => {
            // Broadcast: no replies.
            if let (Some(a), Some(n)) = (num(0), num(w)) {
                let n = usize::from(n);
                for rec in r.params.get(2 * w..).unwrap_or_default().chunks(n + 1) {
                    if rec.len() == n + 1
                        && let Some(s) = servos.get_mut(&rec[0])
                        && s.model.protocol == r.protocol
                    {
                        let _ = s.write(a, &rec[1..]);
                        s.received += 1;
                    }
                }
            }
        }
        _ => {
            if servos.get(&r.id).is_some_and(speaks) {
                out.push((r.id, Err(bad_instruction)));
            }
        }
    }
    let mut replies = Vec::new();
    for (id, res) in out {
        let Some(s) = servos.get_mut(&id) else {
            continue;
        };
        s.received += 1;
        if s.faults.drop_replies > 0 {
            s.faults.drop_replies -= 1;
            continue;
        }
        let (code, params) = match res {
            Ok(params) => (0, params),
            Err(e) => (e, vec![]),
        };
        let mut bytes = if p2 {
            Packet::status(id, code, &params).encode()
        } else {
            protocol1::Frame { id, code, params }.encode()
        };
        if s.faults.corrupt_replies > 0 {
            s.faults.corrupt_replies -= 1;
            let n = bytes.len();
            bytes[n - 1] ^= 0x5A;
        }
        replies.push((s.faults.delay, bytes));
    }
    replies
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::{AX_12A, XH540_W150};
    use dynamixel2::Bus;
    use std::path::Path;

    fn bus(servos: Vec<VirtualServo>) -> (VirtualBus, Bus<Vec<u8>, Vec<u8>>) {
        let (vb, port) = VirtualBus::start(servos).unwrap();
        let bus = Bus::new(port).unwrap();
        (vb, bus)
    }

    #[test]
    fn the_real_client_pings_reads_writes_and_sync_reads_virtual_servos() {
        let (vb, mut bus) = bus(vec![
            VirtualServo::new(XH540_W150, 1),
            VirtualServo::new(XH540_W150, 2),
        ]);
        let p = bus.ping(1).unwrap();
        assert_eq!(p.data.model, 1110);
        let found: Vec<u8> = bus
            .scan()
            .unwrap()
            .into_iter()
            .filter_map(|r| r.ok().map(|r| r.motor_id))
            .collect();
        assert_eq!(found, [1, 2]);
        bus.write_u8(1, XH540_W150.torque_enable.address, 1)
            .unwrap();
        bus.write_u32(1, XH540_W150.goal_position.address, 2500)
            .unwrap();
        assert_eq!(vb.lock()[&1].get(XH540_W150.goal_position), 2500);
        // The plant moves the present positions; one sync read gets both.
        vb.lock()
            .get_mut(&1)
            .unwrap()
            .set(XH540_W150.present_position, 2040);
        vb.lock()
            .get_mut(&2)
            .unwrap()
            .set(XH540_W150.present_position, 1999);
        let r = bus
            .sync_read_u32(&[1, 2], XH540_W150.present_position.address)
            .unwrap();
        let got: Vec<(u8, u32)> = r.into_iter().map(|r| (r.motor_id, r.data)).collect();
        assert_eq!(got, [(1, 2040), (2, 1999)]);
        // The model number is read-only: the servo answers with an access error (0x07).
        let e = bus.write_u16(1, 0, 7).unwrap_err();
        assert!(e.to_string().contains("0x7"), "{e}");
    }

    #[test]
    fn faults_reach_the_client_as_errors_and_a_missing_servo_times_out() {
        let mut s = VirtualServo::new(XH540_W150, 1);
        s.faults.corrupt_replies = 1;
        let (vb, mut bus) = bus(vec![s]);
        let e = bus.ping(1).unwrap_err();
        assert!(e.to_string().to_lowercase().contains("checksum"), "{e}");
        assert_eq!(bus.ping(1).unwrap().data.model, 1110);
        vb.lock().get_mut(&1).unwrap().faults.drop_replies = 1;
        let e = bus.ping(1).unwrap_err();
        assert!(
            e.to_string().to_lowercase().contains("timeout")
                || e.to_string().to_lowercase().contains("timed out"),
            "{e}"
        );
        assert!(bus.ping(9).is_err(), "no servo 9 on the bus");
        assert_eq!(bus.ping(1).unwrap().data.model, 1110);
        // An AX-12A's table is there too (protocol 1.0 on the wire comes with its own bus).
        assert_eq!(VirtualServo::new(AX_12A, 11).get(AX_12A.model_number), 12);
    }

    #[test]
    fn a_mixed_bus_serves_the_ax12a_in_protocol_1_and_the_xh540_in_protocol_2() {
        let (vb, port) = VirtualBus::start(vec![
            VirtualServo::new(XH540_W150, 1),
            VirtualServo::new(AX_12A, 11),
        ])
        .unwrap();
        let mut p1 = crate::protocol1::Bus1::new(port, Duration::from_millis(50));
        assert_eq!(p1.ping(11).unwrap(), 12);
        // The protocol-2.0 servo stays silent to protocol 1.0.
        let e = p1.ping(1).unwrap_err();
        assert!(e.to_string().starts_with("no reply"), "{e}");
        p1.write(
            11,
            AX_12A.goal_position.address as u8,
            &600u16.to_le_bytes(),
        )
        .unwrap();
        assert_eq!(vb.lock()[&11].get(AX_12A.goal_position), 600);
        vb.lock()
            .get_mut(&11)
            .unwrap()
            .set(AX_12A.present_position, 598);
        assert_eq!(
            p1.read_u16(11, AX_12A.present_position.address as u8)
                .unwrap(),
            598
        );
        let e = p1.write(11, 0, &[1, 2]).unwrap_err();
        assert_eq!(e.to_string(), "error status 0x08");
        vb.lock().get_mut(&11).unwrap().faults.corrupt_replies = 1;
        let e = p1.ping(11).unwrap_err();
        assert!(e.to_string().contains("checksum"), "{e}");
        assert_eq!(p1.ping(11).unwrap(), 12);
    }

    #[test]
    fn scans_find_each_protocols_servos_through_a_device_path() {
        let (_vb, path) = VirtualBus::start_with_path(vec![
            VirtualServo::new(XH540_W150, 1),
            VirtualServo::new(XH540_W150, 3),
            VirtualServo::new(AX_12A, 11),
        ])
        .unwrap();
        assert!(path.starts_with("/dev/pts"), "{}", path.display());
        let two = crate::scan::scan(&path, 1_000_000, 2).unwrap();
        let ids: Vec<(u8, &str)> = two.iter().map(|f| (f.id, f.model.as_str())).collect();
        assert_eq!(ids, [(1, "XH540-W150"), (3, "XH540-W150")]);
        let one = crate::scan::scan(&path, 1_000_000, 1).unwrap();
        assert_eq!(one.len(), 1);
        assert_eq!((one[0].id, one[0].model_number), (11, 12));
        let e = crate::scan::scan(Path::new("/dev/no-such-bus"), 57_600, 2).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("/dev/no-such-bus: cannot open at 57600 baud"),
            "{e}"
        );
    }
}
