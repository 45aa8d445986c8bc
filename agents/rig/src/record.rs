//! `rig record` and `rig replay`: every message under `rig/<rig>/**` to an MCAP file and back.
//!
//! Each key is an MCAP channel (topic = the key) in **JSON** (message encoding `json`, schema
//! encoding `jsonschema`, schema `rig.<Kind>` with the kind's JSON Schema), which Foxglove,
//! PlotJuggler and any MCAP reader open without a plugin. The conversion is lossless
//! (`rig_protocol::json`): reading a recording turns each message back into the exact wire
//! bytes, so `rig replay --estimate` is exact. A payload that is not a valid rig message is kept
//! as it came, on a channel of encoding `rig-wire/1` (nothing is lost, and the recording says
//! what arrived); recordings made before JSON (`rig-wire/1` throughout) still read. Records are
//! written unchunked and flushed every 100 ms, so a killed recorder leaves a file whose
//! complete records all read back. `rig replay --estimate` runs the estimator's core offline
//! over the recorded samples and compares with the live estimates in the same file.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::Duration;

use rig_estimator::core::{CoreTiming, EstimatorCore, Output};
use rig_protocol::json::{
    encode_any, from_json, json_schema, kind_of_schema, schema_name, to_json,
};
use rig_protocol::{
    EeEstimate, JointEstimate, JointSample, Keys, Kind, decode, decode_any, decode_samples,
};
use rig_runtime::{NetArgs, RunFor, now_ns, open, tokio_runtime, zenoh_err};

use crate::error::CliError;

/// Message encoding of the channels of valid rig messages (schema encoding `jsonschema`).
pub const JSON: &str = "json";
/// Message encoding of payloads kept as they arrived: the wire bytes (`protocol/WIRE.md`).
pub const WIRE: &str = "rig-wire/1";

/// How one message is written: the kind it is (None: not a valid rig message), its channel's
/// message encoding, and the bytes.
struct Encoded {
    kind: Option<Kind>,
    encoding: &'static str,
    data: Vec<u8>,
}

impl Encoded {
    /// A received payload as it is recorded: JSON when it is a valid rig message, else as it
    /// came.
    fn of(bytes: &[u8]) -> Self {
        match decode_any(bytes) {
            Ok(m) => Encoded {
                kind: Some(m.kind()),
                encoding: JSON,
                data: to_json(&m),
            },
            Err(_) => Encoded {
                kind: None,
                encoding: WIRE,
                data: bytes.to_vec(),
            },
        }
    }

    /// The channel's schema name.
    fn schema_name(&self) -> String {
        self.kind
            .map_or_else(|| "rig.Unreadable".into(), schema_name)
    }

    /// The channel's schema (encoding, data): generated once per schema, when it is added.
    fn schema(&self) -> (&'static str, String) {
        match self.kind {
            Some(kind) => ("jsonschema", json_schema(kind)),
            None => (
                WIRE,
                "payloads that are not valid rig messages, kept as they arrived (protocol/WIRE.md)"
                    .into(),
            ),
        }
    }
}

/// An MCAP file being recorded: one channel per (key, encoding), one schema per kind,
/// records unchunked (so a killed recorder leaves every flushed record readable).
pub struct Recording<W: std::io::Write + std::io::Seek> {
    writer: mcap::Writer<W>,
    schemas: BTreeMap<String, u16>,
    channels: BTreeMap<(String, &'static str), u16>,
    sequence: u32,
}

impl Recording<BufWriter<std::fs::File>> {
    /// A new recording at `path` (replaced if it exists).
    pub fn create(path: &Path) -> Result<Self, CliError> {
        Self::new(BufWriter::new(std::fs::File::create(path)?))
    }
}

impl<W: std::io::Write + std::io::Seek> Recording<W> {
    pub fn new(w: W) -> Result<Self, CliError> {
        Ok(Self {
            writer: mcap::WriteOptions::new()
                .use_chunks(false)
                .profile("rig")
                .create(w)?,
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            sequence: 0,
        })
    }

    /// Records one payload received on `key`: JSON when it is a valid rig message, else
    /// the bytes as they came.
    pub fn write(
        &mut self,
        key: &str,
        payload: &[u8],
        log_time: u64,
        publish_time: u64,
    ) -> Result<(), CliError> {
        let e = Encoded::of(payload);
        let name = e.schema_name();
        let schema = match self.schemas.get(&name) {
            Some(&id) => id,
            None => {
                let (encoding, data) = e.schema();
                let id = self.writer.add_schema(&name, encoding, data.as_bytes())?;
                self.schemas.insert(name, id);
                id
            }
        };
        let channel = match self.channels.get(&(key.to_string(), e.encoding)) {
            Some(&id) => id,
            None => {
                let id = self
                    .writer
                    .add_channel(schema, key, e.encoding, &BTreeMap::new())?;
                self.channels.insert((key.to_string(), e.encoding), id);
                id
            }
        };
        self.sequence = self.sequence.wrapping_add(1);
        self.writer.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: self.sequence,
                log_time,
                publish_time,
            },
            &e.data,
        )?;
        Ok(())
    }

    /// Pushes what is buffered to the file.
    pub fn flush(&mut self) -> Result<(), CliError> {
        Ok(self.writer.flush()?)
    }

    /// Writes the summary and the footer; (messages, channels) recorded.
    pub fn finish(mut self) -> Result<(u32, usize), CliError> {
        self.writer.finish()?;
        Ok((self.sequence, self.channels.len()))
    }
}

#[derive(Debug, clap::Args)]
pub struct RecordArgs {
    /// Output file (.mcap)
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Rig config, for the rig's name and Zenoh endpoints (default: the example parallel robot)
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Zenoh endpoints: `--connect` the running rig's, e.g. the tcp/127.0.0.1:PORT that
    /// `rig up --listen` opened
    #[command(flatten)]
    net: NetArgs,
    #[command(flatten)]
    run_for: RunFor,
}

pub fn record(a: &RecordArgs) -> Result<(), CliError> {
    let cfg = crate::config::load_or_parallel(&a.config)?;
    let rt = tokio_runtime(Some(2))?;
    rt.block_on(async {
        let keys = Keys::new(&cfg.name)?;
        let session = open(&cfg, &a.net.overrides(), &rig_config::Identity::Recorder)
            .await?;
        // A callback into an unbounded channel: the session's receive path never waits on the
        // disk, so nothing is dropped upstream while a write is slow.
        let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
        let _sub = session
            .declare_subscriber(keys.all())
            .callback(move |s| {
                let _ = tx.send(s);
            })
            .await
            .map_err(zenoh_err)?;
        // Up once subscribed, as every role: `rig/<rig>/alive/recorder/<pid>`.
        let _token = session
            .liveliness()
            .declare_token(
                keys.alive("recorder", &std::process::id().to_string())?,
            )
            .await
            .map_err(zenoh_err)?;
        let mut w = Recording::create(&a.out)?;
        let deadline = a.run_for.duration.map(|d| tokio::time::Instant::now() + d);
        let mut flush = tokio::time::interval(Duration::from_millis(100));
        let ctrl_c = tokio::signal::ctrl_c();
        tokio::pin!(ctrl_c);
        eprintln!("rig record: recording {} into {}", keys.all(), a.out.display());
        loop {
            let far = tokio::time::Instant::now() + Duration::from_secs(3600);
            tokio::select! {
                _ = &mut ctrl_c => break,
                _ = tokio::time::sleep_until(deadline.unwrap_or(far)) => break,
                _ = flush.tick() => w.flush()?,
                s = rx.recv() => {
                    let Some(s) = s else { break };
                    let log_time = now_ns();
                    let publish_time = rig_runtime::published_ns(&s).unwrap_or(log_time);
                    w.write(s.key_expr().as_str(), &s.payload().to_bytes(), log_time, publish_time)?;
                }
            }
        }
        let (messages, keys) = w.finish()?;
        let _ = session.close().await;
        eprintln!("rig record: {messages} messages on {keys} keys written to {}", a.out.display());
        Ok(())
    })
}

/// One recorded message, as its wire bytes.
pub struct Recorded {
    pub topic: String,
    pub log_time: u64,
    pub data: Vec<u8>,
}

/// One recorded message as it is stored: its channel's topic, message encoding and schema
/// name, and the bytes.
pub struct Stored {
    pub topic: String,
    pub encoding: String,
    pub schema: String,
    pub sequence: u32,
    pub log_time: u64,
    pub data: Vec<u8>,
}

impl Stored {
    /// The rig message's wire bytes: JSON read back (exactly), or the bytes as kept.
    pub fn wire_bytes(&self) -> Result<Vec<u8>, String> {
        match self.encoding.as_str() {
            JSON => {
                let kind = kind_of_schema(&self.schema).ok_or_else(|| {
                    format!(
                        "JSON channel with schema {:?}, not a rig.<Kind>",
                        self.schema
                    )
                })?;
                let msg = from_json(kind, &self.data).map_err(|e| e.to_string())?;
                encode_any(&msg).map_err(|e| e.to_string())
            }
            WIRE => Ok(self.data.clone()),
            other => Err(format!(
                "message encoding {other:?} (expected {JSON} or {WIRE})"
            )),
        }
    }
}

/// Reads every complete message as stored; a file cut short (killed recorder) ends at its
/// last whole record, which is reported (`true`), not an error.
pub fn read_stored(path: &Path) -> Result<(Vec<Stored>, bool), CliError> {
    let buf = std::fs::read(path)?;
    let stream = mcap::MessageStream::new_with_options(
        &buf,
        enumset::EnumSet::only(mcap::read::Options::IgnoreEndMagic),
    )
    .map_err(|e| CliError::Invalid(format!("{}: not an MCAP recording: {e}", path.display())))?;
    let mut out = Vec::new();
    let mut truncated = false;
    for m in stream {
        match m {
            Ok(m) => out.push(Stored {
                topic: m.channel.topic.clone(),
                encoding: m.channel.message_encoding.clone(),
                schema: m
                    .channel
                    .schema
                    .as_ref()
                    .map_or(String::new(), |s| s.name.clone()),
                sequence: m.sequence,
                log_time: m.log_time,
                data: m.data.into_owned(),
            }),
            Err(e) if out.is_empty() => {
                // Not one complete record: not a recording of ours (random bytes, another
                // format, or cut before its first message).
                return Err(CliError::Invalid(format!(
                    "{}: not an MCAP recording with any complete message: {e}",
                    path.display()
                )));
            }
            Err(_) => {
                // A killed recorder leaves a partial last record: what precedes it is kept.
                truncated = true;
                break;
            }
        }
    }
    Ok((out, truncated))
}

/// Reads every complete rig message, as wire bytes (see [`read_stored`] for a file cut
/// short). A message that is not a rig message is an error naming it.
pub fn read_all(path: &Path) -> Result<(Vec<Recorded>, bool), CliError> {
    let (stored, truncated) = read_stored(path)?;
    let msgs = stored
        .into_iter()
        .map(|m| {
            let data = m.wire_bytes().map_err(|e| {
                CliError::Invalid(format!(
                    "{}: message {} on {}: {e}",
                    path.display(),
                    m.sequence,
                    m.topic
                ))
            })?;
            Ok(Recorded {
                topic: m.topic,
                log_time: m.log_time,
                data,
            })
        })
        .collect::<Result<Vec<_>, CliError>>()?;
    Ok((msgs, truncated))
}

#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The recording (.mcap)
    file: PathBuf,
    /// Rig config (default: the example parallel robot)
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Republish as fast as possible instead of in real time
    #[arg(long)]
    as_fast_as_possible: bool,
    /// Do not publish: run the estimator offline over the recorded samples and compare with the
    /// live estimates recorded beside them
    #[arg(long)]
    estimate: bool,
    /// With --estimate: one JSON object
    #[arg(long)]
    json: bool,
    /// With --estimate: compare only after this many seconds. Exact agreement needs the
    /// recording to start before the rig (the models' hysteresis remembers what it saw)
    #[arg(long, default_value_t = 0.0, value_name = "SECONDS")]
    settle: f64,
    /// Zenoh endpoints to republish on
    #[command(flatten)]
    net: NetArgs,
    /// Draw the recording in Rerun instead of republishing it
    #[command(flatten)]
    viz: crate::viz::VizArgs,
}

pub fn replay(a: &ReplayArgs) -> Result<(), CliError> {
    let cfg = crate::config::load_or_parallel(&a.config)?;
    let (msgs, truncated) = read_all(&a.file)?;
    if truncated {
        eprintln!(
            "rig replay: {} ends in a partial record (recorder killed?); replaying its {} complete messages",
            a.file.display(),
            msgs.len()
        );
    }
    if a.estimate {
        return estimate_offline(&cfg, &msgs, a);
    }
    crate::viz::no_viewer_in_connect(&a.net)?;
    if let Some(sink) = a.viz.sink(&cfg, false)? {
        let viz = crate::viz::VizThread::start(&cfg, &sink)?;
        let tx = viz.sender();
        for m in &msgs {
            let _ = tx.send((m.topic.clone(), m.data.clone()));
        }
        drop(tx);
        let s = viz.finish()?;
        eprintln!(
            "rig replay: {} messages drawn ({} log calls after decimation, {} skipped)",
            s.messages, s.logged, s.skipped
        );
        return Ok(());
    }
    if cfg.security.is_some() {
        // Under [security] only a joint's board may publish its samples: a replay onto the
        // network would be a forgery, and every host would rightly drop it.
        return Err(CliError::Invalid(format!(
            "{} has [security]: a replay onto the network would publish other roles' messages and be refused; replay with --estimate (offline), or with a config without [security] on loopback",
            cfg.source.display()
        )));
    }
    let rt = tokio_runtime(Some(2))?;
    rt.block_on(async {
        let session = open(&cfg, &a.net.overrides(), &rig_config::Identity::Operator).await?;
        tokio::time::sleep(Duration::from_millis(500)).await;
        let t0 = msgs.first().map_or(0, |m| m.log_time);
        let start = tokio::time::Instant::now();
        for m in &msgs {
            if !a.as_fast_as_possible {
                tokio::time::sleep_until(
                    start + Duration::from_nanos(m.log_time.saturating_sub(t0)),
                )
                .await;
            }
            session
                .put(m.topic.as_str(), m.data.clone())
                .await
                .map_err(zenoh_err)?;
        }
        let _ = session.close().await;
        eprintln!("rig replay: {} messages republished", msgs.len());
        Ok(())
    })
}

fn estimate_offline(
    cfg: &rig_config::RigConfig,
    msgs: &[Recorded],
    a: &ReplayArgs,
) -> Result<(), CliError> {
    let mut core = EstimatorCore::new(cfg, CoreTiming::for_config(cfg))?;
    let ee_key = Keys::new(&cfg.name)?.ee_estimate();
    let mut live: BTreeMap<u64, (f64, f64)> = BTreeMap::new();
    let mut offline: BTreeMap<u64, (f64, f64)> = BTreeMap::new();
    let collect = |outs: Vec<Output>, offline: &mut BTreeMap<u64, (f64, f64)>| {
        for o in outs {
            if let Output::Ee(e) = o
                && let Some(f) = e.force_n
            {
                offline.insert(e.t_ns, f);
            }
        }
    };
    // Samples in acquisition order (the order the live core processes ticks in), each fed
    // at its acquisition time; the core's clock-driven checks run between them.
    let mut samples: Vec<JointSample> = Vec::new();
    let mut used: std::collections::BTreeSet<(u16, u64)> = std::collections::BTreeSet::new();
    for m in msgs {
        if m.topic.contains("/estimate/joint/") {
            if let Ok(e) = decode::<JointEstimate>(&m.data) {
                used.insert((e.joint, e.seq));
            }
        } else if m.topic == ee_key {
            if let Ok(e) = decode::<EeEstimate>(&m.data)
                && let Some(f) = e.force_n
            {
                live.insert(e.t_ns, f);
            }
        } else if m.topic.ends_with("/sample") {
            // A joint's sample, or a board's tick of several joints.
            samples.extend(decode_samples(&m.data).unwrap_or_default());
        }
    }
    samples.sort_by_key(|s| (s.t_acq_ns, s.joint));
    // Feed exactly what the live estimator used: the samples it made a joint estimate from
    // (it drops samples before its first complete tick and any that arrive too late). With
    // the same input in the same tick order, the same code gives the same estimates.
    if !used.is_empty() {
        samples.retain(|s| used.contains(&(s.joint, s.seq)));
    }
    let missing = used.len().saturating_sub(samples.len());
    if missing > 0 {
        let have: std::collections::BTreeSet<(u16, u64)> =
            samples.iter().map(|s| (s.joint, s.seq)).collect();
        let which: Vec<String> = used
            .difference(&have)
            .take(8)
            .map(|(j, q)| format!("joint {j} seq {q}"))
            .collect();
        eprintln!(
            "rig replay: {missing} samples the live estimator used are not in the recording (the recorder lost them): {}{}",
            which.join(", "),
            if missing > which.len() { ", …" } else { "" }
        );
    }
    let t0 = samples.first().map_or(0, |s| s.t_acq_ns);
    let mut next_tick = t0;
    for s in &samples {
        while s.t_acq_ns >= next_tick {
            collect(core.on_tick(next_tick), &mut offline);
            next_tick += 20_000_000;
        }
        collect(core.on_sample(*s, s.t_acq_ns), &mut offline);
    }
    let samples = samples.len();
    let settle_ns = t0 + (a.settle.max(0.0) * 1e9) as u64;
    let (mut matched, mut max_diff) = (0u64, 0.0_f64);
    for (t, f) in live.range(settle_ns..) {
        if let Some(g) = offline.get(t) {
            matched += 1;
            max_diff = max_diff.max((f.0 - g.0).hypot(f.1 - g.1));
        }
    }
    if a.json {
        println!(
            "{{\"samples\": {samples}, \"offline_ee_estimates\": {}, \"live_ee_estimates\": {}, \"matched\": {matched}, \"max_force_diff_n\": {max_diff:e}}}",
            offline.len(),
            live.len()
        );
    } else {
        println!(
            "offline estimator: {samples} samples → {} end-effector estimates",
            offline.len()
        );
        println!(
            "live estimates in the recording: {}; compared after {:.1} s: {matched}, largest force difference {max_diff:.3e} N",
            live.len(),
            a.settle
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rig_protocol::encode;

    fn sample(seq: u64) -> Vec<u8> {
        encode(&JointSample {
            joint: 0,
            seq,
            t_acq_ns: 1_763_776_000_000_000_000 + seq,
            motor_rad: 0.1 / 3.0,
            deflection_rad: -1e-300,
            pivot_m: Some(0.009),
            torque_nm: None,
            motor_torque_nm: Some(f64::MIN_POSITIVE),
            stiffness_motor_rad: None,
        })
        .unwrap()
    }

    fn temp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("rig-record-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    #[test]
    fn valid_messages_are_json_junk_is_kept_as_wire_and_both_read_back_to_the_bytes_received() {
        let path = temp("mixed.mcap");
        let key = "rig/t/joint/j1/sample";
        let junk = vec![0xde, 0xad, 0xbe, 0xef];
        let mut r = Recording::create(&path).unwrap();
        r.write(key, &sample(1), 10, 9).unwrap();
        r.write(key, &junk, 11, 11).unwrap();
        r.write(key, &sample(2), 12, 12).unwrap();
        // One key, two channels: its JSON and its unreadable payloads.
        assert_eq!(r.finish().unwrap(), (3, 2));
        let (stored, truncated) = read_stored(&path).unwrap();
        assert!(!truncated);
        let how: Vec<(&str, &str)> = stored
            .iter()
            .map(|m| (m.encoding.as_str(), m.schema.as_str()))
            .collect();
        assert_eq!(
            how,
            [
                (JSON, "rig.JointSample"),
                (WIRE, "rig.Unreadable"),
                (JSON, "rig.JointSample")
            ]
        );
        let v: serde_json::Value = serde_json::from_slice(&stored[2].data).unwrap();
        assert_eq!(v["seq"], 2);
        let (msgs, _) = read_all(&path).unwrap();
        let bytes: Vec<&[u8]> = msgs.iter().map(|m| m.data.as_slice()).collect();
        assert_eq!(bytes, [&sample(1)[..], &junk[..], &sample(2)[..]]);
        assert_eq!(msgs[0].log_time, 10);
    }

    #[test]
    fn a_recording_of_wire_channels_as_made_before_json_still_reads() {
        let path = temp("wire.mcap");
        let mut w = mcap::WriteOptions::new()
            .use_chunks(false)
            .create(BufWriter::new(std::fs::File::create(&path).unwrap()))
            .unwrap();
        let schema = w
            .add_schema("rig.JointSample", WIRE, b"<python struct layout>")
            .unwrap();
        let ch = w
            .add_channel(schema, "rig/t/joint/j1/sample", WIRE, &BTreeMap::new())
            .unwrap();
        for seq in 1..=3 {
            let header = mcap::records::MessageHeader {
                channel_id: ch,
                sequence: seq,
                log_time: seq.into(),
                publish_time: seq.into(),
            };
            w.write_to_known_channel(&header, &sample(seq.into()))
                .unwrap();
        }
        w.finish().unwrap();
        let (msgs, truncated) = read_all(&path).unwrap();
        assert!(!truncated);
        assert_eq!(msgs.len(), 3);
        assert_eq!(msgs[2].data, sample(3));
    }

    #[test]
    fn a_json_channel_of_an_unknown_schema_or_a_broken_message_is_named() {
        let path = temp("foreign.mcap");
        let mut w = mcap::WriteOptions::new()
            .create(BufWriter::new(std::fs::File::create(&path).unwrap()))
            .unwrap();
        let foreign = w.add_schema("acme.Pose", "jsonschema", b"{}").unwrap();
        let ours = w
            .add_schema("rig.JointSample", "jsonschema", b"{}")
            .unwrap();
        let a = w
            .add_channel(foreign, "acme/pose", JSON, &BTreeMap::new())
            .unwrap();
        let b = w
            .add_channel(ours, "rig/t/joint/j1/sample", JSON, &BTreeMap::new())
            .unwrap();
        let header = |channel_id, sequence| mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time: 1,
            publish_time: 1,
        };
        w.write_to_known_channel(&header(a, 1), b"{\"x\": 1}")
            .unwrap();
        w.write_to_known_channel(&header(b, 2), b"{\"joint\": 0}")
            .unwrap();
        w.finish().unwrap();
        let err = read_all(&path).err().unwrap().to_string();
        assert!(
            err.contains("message 1 on acme/pose") && err.contains("acme.Pose"),
            "{err}"
        );
        // `rig export` still reads both: the foreign one as it is.
        let (stored, _) = read_stored(&path).unwrap();
        assert_eq!(stored.len(), 2);
        let err = stored[1].wire_bytes().unwrap_err();
        assert!(err.contains("JointSample") && err.contains("seq"), "{err}");
    }
}
