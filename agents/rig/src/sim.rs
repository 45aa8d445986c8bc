//! `rig sim --scenario FILE --out data.csv|data.mcap`: run a scenario into a sensor stream.
//!
//! A `.csv` gets a header row and one row per sample. A `.mcap` gets the same rows as JSON
//! messages on one channel, topic `sim/<kind>`, schema `rig.sim.<kind>` (a JSON Schema naming
//! each column), log time = the row's `t`: Foxglove and PlotJuggler open it as they open a
//! `rig record` recording, and `rig export --to csv` turns it back into the CSV.

use std::collections::BTreeMap;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use rig_sim::scenario::{self, Scenario};

use crate::error::CliError;
use crate::progress;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario file (TOML), e.g. agents/sim/scenarios/lever-bench.toml
    #[arg(long, value_name = "FILE")]
    scenario: PathBuf,
    /// Output file: .csv (columns documented in agents/sim/SCENARIOS.md) or .mcap (the same
    /// columns as JSON messages, topic sim/<kind>)
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

/// Where the rows go.
enum Sink {
    Csv(Box<csv::Writer<std::fs::File>>),
    Mcap {
        writer: Box<mcap::Writer<BufWriter<std::fs::File>>>,
        kind: String,
        /// The columns, JSON-quoted, once the header is known.
        columns: Vec<String>,
        channel: Option<u16>,
        sequence: u32,
    },
}

impl Sink {
    fn create(out: &Path, kind: &str) -> Result<Self, CliError> {
        match out.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("csv") => Ok(Sink::Csv(Box::new(
                csv::Writer::from_path(out).map_err(|source| CliError::Csv {
                    file: out.display().to_string(),
                    source,
                })?,
            ))),
            Some(e) if e.eq_ignore_ascii_case("mcap") => Ok(Sink::Mcap {
                writer: Box::new(
                    mcap::WriteOptions::new()
                        .profile("rig")
                        .create(BufWriter::new(std::fs::File::create(out)?))?,
                ),
                kind: kind.to_string(),
                columns: Vec::new(),
                channel: None,
                sequence: 0,
            }),
            _ => Err(CliError::Unsupported(format!(
                "{}: --out takes a .csv or an .mcap file",
                out.display()
            ))),
        }
    }

    fn header(&mut self, names: &[String]) -> Result<(), String> {
        match self {
            Sink::Csv(w) => w.write_record(names).map_err(|e| e.to_string()),
            Sink::Mcap {
                writer,
                kind,
                columns,
                channel,
                ..
            } => {
                let name = format!("rig.sim.{kind}");
                let schema = column_schema(&name, names);
                let e = |e: mcap::McapError| e.to_string();
                let id = writer
                    .add_schema(&name, "jsonschema", schema.as_bytes())
                    .map_err(e)?;
                let topic = format!("sim/{kind}");
                *channel = Some(
                    writer
                        .add_channel(id, &topic, crate::record::JSON, &BTreeMap::new())
                        .map_err(e)?,
                );
                *columns = names.iter().map(|n| json_string(n)).collect();
                Ok(())
            }
        }
    }

    fn row(&mut self, values: &[f64]) -> Result<(), String> {
        match self {
            Sink::Csv(w) => w
                .write_record(values.iter().map(|v| format!("{v}")))
                .map_err(|e| e.to_string()),
            Sink::Mcap {
                writer,
                columns,
                channel,
                sequence,
                ..
            } => {
                let channel = channel.ok_or("a row before the header")?;
                let mut json = Vec::with_capacity(24 * values.len());
                json.push(b'{');
                for (i, (name, v)) in columns.iter().zip(values).enumerate() {
                    if i > 0 {
                        json.push(b',');
                    }
                    // Shortest form that reads back to the same f64; a non-finite value null.
                    let v = serde_json::to_string(v).map_err(|e| e.to_string())?;
                    let _ = write!(json, "{name}:{v}");
                }
                json.push(b'}');
                // Every kind's first column is `t`, seconds from the start.
                let t_ns = values
                    .first()
                    .map_or(0, |t| (t * 1e9).round().max(0.0) as u64);
                *sequence = sequence.wrapping_add(1);
                writer
                    .write_to_known_channel(
                        &mcap::records::MessageHeader {
                            channel_id: channel,
                            sequence: *sequence,
                            log_time: t_ns,
                            publish_time: t_ns,
                        },
                        &json,
                    )
                    .map_err(|e| e.to_string())
            }
        }
    }

    fn finish(self) -> Result<(), CliError> {
        match self {
            Sink::Csv(mut w) => Ok(w.flush()?),
            Sink::Mcap { mut writer, .. } => {
                writer.finish()?;
                Ok(())
            }
        }
    }
}

fn json_string(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_else(|_| format!("\"{s}\""))
}

/// A draft-7 JSON Schema of one row: every column a number (null where not finite).
fn column_schema(title: &str, names: &[String]) -> String {
    let properties: serde_json::Map<String, serde_json::Value> = names
        .iter()
        .map(|n| (n.clone(), serde_json::json!({ "type": ["number", "null"] })))
        .collect();
    serde_json::json!({
        "$schema": "http://json-schema.org/draft-07/schema#",
        "title": title,
        "description": "one row of a rig sim scenario; columns in agents/sim/SCENARIOS.md",
        "type": "object",
        "properties": properties,
        "required": names,
    })
    .to_string()
}

pub fn run(args: &Args) -> Result<(), CliError> {
    let s = Scenario::load(&args.scenario)?;
    let w = std::cell::RefCell::new(Sink::create(&args.out, &s.kind)?);
    let pb = progress::bar(
        s.samples(),
        &format!("simulating {} ({} s)", s.kind, s.duration_s),
    );
    let mut rows = 0u64;
    scenario::run(
        &s,
        &mut |h| w.borrow_mut().header(h),
        &mut |r| {
            rows += 1;
            w.borrow_mut().row(r)
        },
        &mut |done| pb.set_position(done),
    )?;
    w.into_inner().finish()?;
    pb.finish_and_clear();
    eprintln!("wrote {rows} samples to {}", args.out.display());
    Ok(())
}
