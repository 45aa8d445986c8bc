//! Finding the servos on a bus: `rig scan`.

use std::path::Path;
use std::time::Duration;

use serial2::SerialPort;
use thiserror::Error;

use crate::models::by_number;
use crate::protocol1::Bus1;

/// A servo that answered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Found {
    pub id: u8,
    pub model_number: u16,
    /// The model's name, or "unknown" for a model this rig has no table of.
    pub model: String,
}

#[derive(Debug, Error)]
pub enum ScanError {
    #[error("{port}: cannot open at {baud} baud: {source}")]
    Open {
        port: String,
        baud: u32,
        source: std::io::Error,
    },
    #[error("{port}: {message}")]
    Bus { port: String, message: String },
    #[error("protocol must be 1 or 2, got {0}")]
    Protocol(u8),
}

fn found(id: u8, model_number: u16) -> Found {
    Found {
        id,
        model_number,
        model: by_number(model_number).map_or_else(|| "unknown".into(), |m| m.name.into()),
    }
}

/// Scans an opened port: a broadcast ping (protocol 2.0), or a ping of every ID 0–252 with a
/// short timeout (protocol 1.0 has no broadcast reply).
pub fn scan_port(port: SerialPort, name: &str, protocol: u8) -> Result<Vec<Found>, ScanError> {
    let bus_err = |message: String| ScanError::Bus {
        port: name.to_string(),
        message,
    };
    match protocol {
        2 => {
            let mut bus = dynamixel2::Bus::new(port).map_err(|e| bus_err(e.to_string()))?;
            let mut out = Vec::new();
            for r in bus.scan().map_err(|e| bus_err(e.to_string()))? {
                match r {
                    Ok(r) => out.push(found(r.motor_id, r.data.model)),
                    Err(e) => return Err(bus_err(format!("a reply was unreadable: {e}"))),
                }
            }
            Ok(out)
        }
        1 => {
            let mut bus = Bus1::new(port, Duration::from_millis(10));
            let mut out = Vec::new();
            for id in 0..=252u8 {
                match bus.ping(id) {
                    Ok(model) => out.push(found(id, model)),
                    Err(crate::protocol1::Error::Timeout { .. }) => {}
                    Err(e) => return Err(bus_err(format!("servo {id}: {e}"))),
                }
            }
            Ok(out)
        }
        p => Err(ScanError::Protocol(p)),
    }
}

/// Opens `path` at `baud` and scans it.
pub fn scan(path: &Path, baud: u32, protocol: u8) -> Result<Vec<Found>, ScanError> {
    let name = path.display().to_string();
    let port = SerialPort::open(path, baud).map_err(|source| ScanError::Open {
        port: name.clone(),
        baud,
        source,
    })?;
    scan_port(port, &name, protocol)
}
