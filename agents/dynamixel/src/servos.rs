//! The servos of a joint board's bus: both protocols on one line, bounded retries, and errors
//! that name the bus and the servo. Protocol 2.0 goes through dynamixel2; protocol 1.0 (the
//! AX-12A) through [`crate::protocol1`]. Both clients share the port (each discards stale input
//! before it writes), one transfer at a time.

use std::path::Path;
use std::time::Duration;

use serial2::SerialPort;
use thiserror::Error;

use crate::models::{Field, Model, by_name};
use crate::protocol1::Bus1;

/// A servo on the bus, as the config names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Servo {
    pub id: u8,
    pub model: &'static Model,
}

impl Servo {
    /// The servo of a config entry; the model name must be one this rig has the table of.
    pub fn new(id: u8, model: &str) -> Result<Self, BusError> {
        let model = by_name(model).ok_or_else(|| BusError::UnknownModel(model.to_string()))?;
        Ok(Self { id, model })
    }
}

/// Errors of the bus; each names the bus and, where there is one, the servo.
#[derive(Debug, Error)]
pub enum BusError {
    #[error("{bus}: cannot open at {baud} baud: {source}")]
    Open {
        bus: String,
        baud: u32,
        source: std::io::Error,
    },
    #[error("{bus}: servo {id}: {what} (gave up after {attempts} attempts)")]
    Transfer {
        bus: String,
        id: u8,
        what: String,
        attempts: u32,
    },
    #[error("{bus}: servo {id} is model {found} ({name}); the config says {want}")]
    WrongModel {
        bus: String,
        id: u8,
        found: u16,
        name: String,
        want: &'static str,
    },
    #[error("servo {id}: {rad} rad is outside the {model}'s range")]
    OutOfRange {
        id: u8,
        rad: f64,
        model: &'static str,
    },
    #[error("unknown servo model \"{0}\"; known: XH540-W150, AX-12A")]
    UnknownModel(String),
}

/// Transfers, retries and failures so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BusStats {
    pub transfers: u64,
    pub retries: u64,
    pub failures: u64,
}

/// One serial bus with servos of either protocol.
#[derive(Debug)]
pub struct ServoBus {
    name: String,
    baud: u32,
    p2: dynamixel2::Bus<Vec<u8>, Vec<u8>>,
    p1: Bus1,
    /// Attempts after the first before a transfer fails.
    pub retries: u32,
    pub stats: BusStats,
}

impl ServoBus {
    /// Opens the bus at `path`.
    pub fn open(path: &Path, baud: u32) -> Result<Self, BusError> {
        let name = path.display().to_string();
        let open_err = |source| BusError::Open {
            bus: name.clone(),
            baud,
            source,
        };
        let port = SerialPort::open(path, baud).map_err(open_err)?;
        let mut bus = Self::from_port(port, &name).map_err(open_err)?;
        bus.baud = baud;
        Ok(bus)
    }

    /// The port's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The baud rate it was opened at (0 for a port opened elsewhere).
    pub fn baud(&self) -> u32 {
        self.baud
    }

    /// A bus over an opened port (a virtual bus's client end, for instance).
    pub fn from_port(port: SerialPort, name: &str) -> std::io::Result<Self> {
        let p1 = Bus1::new(port.try_clone()?, Duration::from_millis(10));
        let p2 = dynamixel2::Bus::new(port).map_err(|e| std::io::Error::other(e.to_string()))?;
        Ok(Self {
            name: name.to_string(),
            baud: 0,
            p2,
            p1,
            retries: 2,
            stats: BusStats::default(),
        })
    }

    /// Runs `f` up to 1 + `retries` times; the error names the bus and the servo.
    fn retry<T>(
        &mut self,
        id: u8,
        mut f: impl FnMut(&mut Self) -> Result<T, String>,
    ) -> Result<T, BusError> {
        let attempts = self.retries + 1;
        let mut last = String::new();
        for k in 0..attempts {
            self.stats.transfers += 1;
            if k > 0 {
                self.stats.retries += 1;
            }
            match f(self) {
                Ok(v) => return Ok(v),
                Err(e) => last = e,
            }
        }
        self.stats.failures += 1;
        Err(BusError::Transfer {
            bus: self.name.clone(),
            id,
            what: last,
            attempts,
        })
    }

    fn read_field(&mut self, s: Servo, f: Field) -> Result<u32, BusError> {
        self.retry(s.id, |b| {
            let bytes = if s.model.protocol == 2 {
                b.p2.read(s.id, f.address, f.size)
                    .map(|r| r.data)
                    .map_err(|e| e.to_string())?
            } else {
                b.p1.read(s.id, f.address as u8, f.size as u8)
                    .map_err(|e| e.to_string())?
            };
            let mut v = [0u8; 4];
            let n = bytes.len().min(4);
            v[..n].copy_from_slice(&bytes[..n]);
            Ok(u32::from_le_bytes(v))
        })
    }

    fn write_field(&mut self, s: Servo, f: Field, value: u32) -> Result<(), BusError> {
        let bytes = value.to_le_bytes();
        let data = &bytes[..usize::from(f.size)];
        self.retry(s.id, |b| {
            if s.model.protocol == 2 {
                b.p2.write(s.id, f.address, data)
                    .map(|_| ())
                    .map_err(|e| e.to_string())
            } else {
                b.p1.write(s.id, f.address as u8, data)
                    .map_err(|e| e.to_string())
            }
        })
    }

    /// Checks that the servo answers and is the model the config says.
    pub fn check(&mut self, s: Servo) -> Result<(), BusError> {
        let found = self.read_field(s, s.model.model_number)? as u16;
        if found != s.model.number {
            return Err(BusError::WrongModel {
                bus: self.name.clone(),
                id: s.id,
                found,
                name: crate::models::by_number(found)
                    .map_or_else(|| "unknown here".into(), |m| m.name.to_string()),
                want: s.model.name,
            });
        }
        Ok(())
    }

    /// Present positions [rad from the center], in the order given: one sync read for the
    /// protocol-2.0 servos (each read alone if it fails, to name the culprit), single reads
    /// for the protocol-1.0 ones.
    pub fn positions(&mut self, servos: &[Servo]) -> Result<Vec<f64>, BusError> {
        let mut out = vec![f64::NAN; servos.len()];
        let p2 = protocol2(servos);
        let same_field = p2
            .windows(2)
            .all(|w| w[0].1.model.present_position == w[1].1.model.present_position);
        if p2.len() > 1 && same_field {
            let f = p2[0].1.model.present_position;
            let ids: Vec<u8> = p2.iter().map(|(_, s)| s.id).collect();
            self.stats.transfers += 1;
            if let Ok(r) = self.p2.sync_read_u32(&ids, f.address)
                && r.len() == ids.len()
            {
                for ((k, s), resp) in p2.iter().zip(r) {
                    out[*k] = s.model.to_rad(resp.data);
                }
            }
        }
        self.read_missing(servos, &mut out)?;
        Ok(out)
    }

    /// Reads alone each servo whose position in `out` is still NaN (a failed sync read names
    /// the servo that does not answer; protocol-1.0 servos have no sync read).
    fn read_missing(&mut self, servos: &[Servo], out: &mut [f64]) -> Result<(), BusError> {
        for (k, s) in servos.iter().enumerate() {
            if out[k].is_nan() {
                out[k] = s
                    .model
                    .to_rad(self.read_field(*s, s.model.present_position)?);
            }
        }
        Ok(())
    }

    /// Present positions [rad from the center] and, for the servos that report it, the motor
    /// torque [N·m] from the present current (the model's datasheet torque per ampere), in the
    /// order given. Protocol-2.0 servos whose current and position sit in one block (the
    /// XH540's 126..136) are read with one sync read of the block; otherwise, or if that read
    /// fails, as [`Self::positions`] (torque absent).
    pub fn positions_and_torques(
        &mut self,
        servos: &[Servo],
    ) -> Result<(Vec<f64>, Vec<Option<f64>>), BusError> {
        let mut torque = vec![None; servos.len()];
        let p2 = protocol2(servos);
        let Some((start, count)) = shared_current_block(p2.iter().map(|(_, s)| s)) else {
            return Ok((self.positions(servos)?, torque));
        };
        let ids: Vec<u8> = p2.iter().map(|(_, s)| s.id).collect();
        self.stats.transfers += 1;
        let r = match self.p2.sync_read(&ids, start, count) {
            Ok(r)
                if r.len() == ids.len() && r.iter().all(|x| x.data.len() == usize::from(count)) =>
            {
                r
            }
            _ => return Ok((self.positions(servos)?, torque)),
        };
        let mut out = vec![f64::NAN; servos.len()];
        for ((k, s), x) in p2.iter().zip(r) {
            let d = &x.data;
            let at = usize::from(s.model.present_position.address - start);
            out[*k] = s
                .model
                .to_rad(u32::from_le_bytes([d[at], d[at + 1], d[at + 2], d[at + 3]]));
            let counts = i16::from_le_bytes([d[0], d[1]]);
            torque[*k] = Some(f64::from(counts) * s.model.nm_per_current_count());
        }
        self.read_missing(servos, &mut out)?;
        Ok((out, torque))
    }

    /// Sets a goal position [rad from the center].
    pub fn set_goal(&mut self, s: Servo, rad: f64) -> Result<(), BusError> {
        let counts = s.model.to_counts(rad).ok_or(BusError::OutOfRange {
            id: s.id,
            rad,
            model: s.model.name,
        })?;
        self.write_field(s, s.model.goal_position, counts)
    }

    /// Torque on or off.
    pub fn torque(&mut self, s: Servo, on: bool) -> Result<(), BusError> {
        self.write_field(s, s.model.torque_enable, u32::from(on))
    }
}

/// The protocol-2.0 servos of `servos`, with their indices.
fn protocol2(servos: &[Servo]) -> Vec<(usize, Servo)> {
    servos
        .iter()
        .copied()
        .enumerate()
        .filter(|(_, s)| s.model.protocol == 2)
        .collect()
}

/// Where a protocol-2.0 servo's present current and position sit in one block of its table
/// (current first, a 4-byte position after it): (start, bytes).
fn current_block(s: &Servo) -> Option<(u16, u16)> {
    let (c, p) = (s.model.present_current?, s.model.present_position);
    (s.model.protocol == 2 && p.size == 4 && p.address >= c.address + c.size)
        .then_some((c.address, p.address + p.size - c.address))
}

/// The block of current and position every one of `servos` (protocol 2.0) has at the same
/// place, which [`ServoBus::positions_and_torques`] reads in one sync read; `None` when one
/// lacks it or they differ (then positions alone are read), or when there are none.
pub fn shared_current_block<'a>(servos: impl IntoIterator<Item = &'a Servo>) -> Option<(u16, u16)> {
    let mut all = servos.into_iter().map(current_block);
    let first = all.next()??;
    all.all(|b| b == Some(first)).then_some(first)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::{AX_12A, XH540_W150};
    use crate::virtual_bus::{VirtualBus, VirtualServo};

    fn rig() -> (VirtualBus, ServoBus, [Servo; 3]) {
        let (vb, port) = VirtualBus::start(vec![
            VirtualServo::new(XH540_W150, 1),
            VirtualServo::new(XH540_W150, 2),
            VirtualServo::new(AX_12A, 11),
        ])
        .unwrap();
        let bus = ServoBus::from_port(port, "/dev/virtual").unwrap();
        let s = [
            Servo::new(1, "XH540-W150").unwrap(),
            Servo::new(2, "XH540-W150").unwrap(),
            Servo::new(11, "AX-12A").unwrap(),
        ];
        (vb, bus, s)
    }

    #[test]
    fn reads_both_protocols_writes_goals_and_checks_models() {
        let (vb, mut bus, s) = rig();
        for x in s {
            bus.check(x).unwrap();
        }
        vb.lock()
            .get_mut(&1)
            .unwrap()
            .set(XH540_W150.present_position, 2048 + 1024);
        vb.lock()
            .get_mut(&2)
            .unwrap()
            .set(XH540_W150.present_position, 2048 - 512);
        vb.lock()
            .get_mut(&11)
            .unwrap()
            .set(AX_12A.present_position, 512);
        let p = bus.positions(&s).unwrap();
        let quarter = std::f64::consts::FRAC_PI_2;
        assert!(
            (p[0] - quarter).abs() < 1e-12 && (p[1] + quarter / 2.0).abs() < 1e-12,
            "{p:?}"
        );
        assert_eq!(p[2], 0.0);
        bus.torque(s[0], true).unwrap();
        bus.set_goal(s[0], -quarter).unwrap();
        assert_eq!(vb.lock()[&1].get(XH540_W150.goal_position), 1024);
        assert_eq!(vb.lock()[&1].get(XH540_W150.torque_enable), 1);
        bus.set_goal(s[2], 0.1).unwrap();
        assert_eq!(vb.lock()[&11].get(AX_12A.goal_position), 512 + 20);
        let e = bus.set_goal(s[2], 3.0).unwrap_err();
        assert!(e.to_string().contains("outside the AX-12A's range"), "{e}");
        // The config names another protocol-2.0 model at ID 1: the model number gives it away.
        static XM430: Model = Model {
            name: "XM430-W350",
            number: 1020,
            ..XH540_W150
        };
        let e = bus
            .check(Servo {
                id: 1,
                model: &XM430,
            })
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "/dev/virtual: servo 1 is model 1110 (XH540-W150); the config says XM430-W350"
        );
        // The config says AX-12A (protocol 1.0) at ID 1: the XH540 there does not answer it.
        let e = bus
            .check(Servo {
                id: 1,
                model: &AX_12A,
            })
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("/dev/virtual: servo 1: no reply"), "{e}");
        assert!(
            Servo::new(3, "MX-28")
                .unwrap_err()
                .to_string()
                .contains("MX-28")
        );
    }

    #[test]
    fn a_lost_or_corrupt_reply_is_retried_and_a_missing_servo_named() {
        let (vb, mut bus, s) = rig();
        vb.lock().get_mut(&2).unwrap().faults.drop_replies = 1;
        vb.lock().get_mut(&11).unwrap().faults.corrupt_replies = 1;
        let p = bus.positions(&s).unwrap();
        assert_eq!(p.len(), 3);
        assert!(bus.stats.retries >= 1, "{:?}", bus.stats);
        // Gone for good: bounded retries, then an error naming bus and servo.
        vb.lock().get_mut(&2).unwrap().faults.drop_replies = 100;
        let e = bus.positions(&s).unwrap_err().to_string();
        assert!(
            e.starts_with("/dev/virtual: servo 2:") && e.contains("after 3 attempts"),
            "{e}"
        );
        assert_eq!(bus.stats.failures, 1);
    }
}
