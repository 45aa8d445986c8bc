//! Virtual servos for tests without hardware: control tables in memory that answer
//! protocol-2.0 instruction packets on one end of a pseudo-terminal pair, while the client
//! (dynamixel2, as on the real bus) talks to the other end. Faults can be injected per servo:
//! dropped replies, corrupt checksums, late replies.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use serial2::SerialPort;

use crate::models::Model;
use crate::protocol2::{BROADCAST, Packet, Parsed, error, instruction, parse};

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
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl VirtualBus {
    /// Opens a pseudo-terminal pair, serves `servos` on one end and returns the other end for
    /// the client.
    pub fn start(servos: Vec<VirtualServo>) -> std::io::Result<(Self, SerialPort)> {
        let (device, client) = SerialPort::pair()?;
        let mut device = device;
        device.set_read_timeout(Duration::from_millis(20))?;
        let map: BTreeMap<u8, VirtualServo> = servos
            .into_iter()
            .map(|s| (s.get(s.model.id) as u8, s))
            .collect();
        let servos: Servos = Arc::new(Mutex::new(map));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (servos, stop) = (servos.clone(), stop.clone());
            std::thread::spawn(move || serve(device, &servos, &stop))
        };
        Ok((
            Self {
                servos,
                stop,
                thread: Some(thread),
            },
            client,
        ))
    }

    /// The servos, locked.
    pub fn lock(&self) -> MutexGuard<'_, BTreeMap<u8, VirtualServo>> {
        self.servos.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl Drop for VirtualBus {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn serve(port: SerialPort, servos: &Servos, stop: &AtomicBool) {
    let mut buf: Vec<u8> = Vec::new();
    let mut chunk = [0u8; 256];
    while !stop.load(Ordering::Relaxed) {
        match port.read(&mut chunk) {
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => continue,
            Err(_) => return,
        }
        loop {
            match parse(&buf) {
                Parsed::Incomplete => break,
                Parsed::Noise(n) | Parsed::BadCrc(n) => {
                    buf.drain(..n);
                }
                Parsed::Packet(p, n) => {
                    buf.drain(..n);
                    let replies = {
                        let mut s = servos.lock().unwrap_or_else(|p| p.into_inner());
                        answer(&mut s, &p)
                    };
                    for (delay, bytes) in replies {
                        if !delay.is_zero() {
                            std::thread::sleep(delay);
                        }
                        if port.write_all(&bytes).is_err() {
                            return;
                        }
                    }
                }
            }
        }
    }
}

/// The replies (delay, bytes) to one instruction, in bus order.
fn answer(servos: &mut BTreeMap<u8, VirtualServo>, p: &Packet) -> Vec<(Duration, Vec<u8>)> {
    let u16_at = |i: usize| -> Option<u16> {
        Some(u16::from_le_bytes([
            *p.params.get(i)?,
            *p.params.get(i + 1)?,
        ]))
    };
    let mut out: Vec<(u8, Result<Vec<u8>, u8>)> = Vec::new();
    match p.instruction {
        instruction::PING => {
            for (&id, s) in servos.iter() {
                if p.id == id || p.id == BROADCAST {
                    let mut r = s.model.number.to_le_bytes().to_vec();
                    r.push(s.get(s.model.firmware) as u8);
                    out.push((id, Ok(r)));
                }
            }
        }
        instruction::READ => {
            if let (Some(s), Some(a), Some(n)) = (servos.get(&p.id), u16_at(0), u16_at(2)) {
                out.push((p.id, s.read(a, n)));
            }
        }
        instruction::WRITE => {
            if let (Some(s), Some(a)) = (servos.get_mut(&p.id), u16_at(0)) {
                out.push((p.id, s.write(a, &p.params[2..]).map(|()| vec![])));
            }
        }
        instruction::SYNC_READ => {
            if let (Some(a), Some(n)) = (u16_at(0), u16_at(2)) {
                for &id in p.params.get(4..).unwrap_or_default() {
                    if let Some(s) = servos.get(&id) {
                        out.push((id, s.read(a, n)));
                    }
                }
            }
        }
        instruction::SYNC_WRITE => {
            // Broadcast: no replies.
            if let (Some(a), Some(n)) = (u16_at(0), u16_at(2)) {
                let n = usize::from(n);
                for rec in p.params.get(4..).unwrap_or_default().chunks(n + 1) {
                    if rec.len() == n + 1
                        && let Some(s) = servos.get_mut(&rec[0])
                    {
                        let _ = s.write(a, &rec[1..]);
                        s.received += 1;
                    }
                }
            }
        }
        _ => {
            if let Some(s) = servos.get(&p.id) {
                let _ = s;
                out.push((p.id, Err(error::INSTRUCTION)));
            }
        }
    }
    let mut replies = Vec::new();
    for (id, r) in out {
        let Some(s) = servos.get_mut(&id) else {
            continue;
        };
        s.received += 1;
        if s.faults.drop_replies > 0 {
            s.faults.drop_replies -= 1;
            continue;
        }
        let mut bytes = match r {
            Ok(params) => Packet::status(id, 0, &params),
            Err(e) => Packet::status(id, e, &[]),
        }
        .encode();
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
}
