//! `rig scan`: list the Dynamixel servos on a bus (ID, model number, model).

use std::path::PathBuf;

use serde_json::json;

use crate::error::CliError;

/// List the Dynamixel servos that answer on a serial bus.
///
/// Protocol 2.0 (XH540 and other X series) is a broadcast ping; protocol 1.0 (AX-12A) pings
/// every ID from 0 to 252 (about 2.5 s). Servos of the other protocol on the same bus stay
/// silent, so scan a mixed bus twice. Exit status 1 when the port cannot be opened or a reply
/// is unreadable.
///
/// Example: rig scan --port /dev/ttyUSB0 --baud 1000000 --protocol 1 --json
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Serial port of the bus (U2D2 or OpenCM bridge), e.g. /dev/ttyUSB0
    #[arg(long, value_name = "PATH")]
    port: PathBuf,
    /// Baud rate of the bus
    #[arg(long, default_value_t = 1_000_000)]
    baud: u32,
    /// Dynamixel protocol: 2 (X series) or 1 (AX-12A)
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u8).range(1..=2))]
    protocol: u8,
    /// Print JSON: [{"id", "model_number", "model"}]
    #[arg(long)]
    json: bool,
}

pub fn run(a: &Args) -> Result<(), CliError> {
    let found = rig_dynamixel::scan::scan(&a.port, a.baud, a.protocol)?;
    if a.json {
        let v: Vec<_> = found
            .iter()
            .map(|f| json!({"id": f.id, "model_number": f.model_number, "model": f.model}))
            .collect();
        println!("{}", serde_json::Value::Array(v));
        return Ok(());
    }
    println!(
        "{}: {} servo(s), protocol {} at {} baud",
        a.port.display(),
        found.len(),
        a.protocol,
        a.baud
    );
    for f in &found {
        println!("  id {:3}  model {:5}  {}", f.id, f.model_number, f.model);
    }
    Ok(())
}
